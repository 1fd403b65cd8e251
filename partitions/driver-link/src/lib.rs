//! A tenant's pair of queuing ports on a driver partition's side (the NIC's, the block
//! device's): created in the partition's start from the tenant table's [`PortSpec`]s,
//! opened again by the driver's process. The tenant's side of a NIC link is [`tenant`].
#![no_std]

pub mod tenant;

use apex::Warden;
use apex::a653rs::prelude::*;
use core::str::FromStr;
use driver_table::PortSpec;

/// Notifies the thread a frame ring's consumer named ([`frame_ring::Producer::waiter`]);
/// `false` when it named none or the kernel refused (wake it through the port then).
pub fn notify_waiter(waiter: Option<(u64, u64)>) -> bool {
    waiter.is_some_and(|(thread, bits)| {
        let thread = apex::user_rt::abi::syscall::ThreadId(thread);
        apex::user_rt::sys::notify_signal(thread, bits).is_ok()
    })
}

/// The driver's ends of a tenant's link: the tenant's messages come in on `from`, the
/// driver's go out on `to`.
pub struct Link {
    pub from: QueuingPortReceiver<Warden>,
    pub to: QueuingPortSender<Warden>,
}

impl Link {
    /// Asks syssw to notify the calling process's thread with `bits` whenever the tenant's
    /// messages arrive ([`apex::runtime::port_doorbell`]), so that the driver waits for
    /// them with its device's interrupt instead of polling.
    pub fn ring_on_arrival(
        &self,
        bits: u64,
    ) -> Result<(), apex::a653rs::bindings::ErrorReturnCode> {
        apex::runtime::port_doorbell(self.from.id(), bits)
    }
}

/// Why a tenant's ports are unusable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkError {
    /// A port name is longer than an ARINC 653 name (32 bytes).
    NameTooLong,
    /// The APEX runtime refused to create the ports (the configuration has no such ports,
    /// or other sizes).
    NotCreated,
    /// The ports were not created in the partition's start.
    NotOpen,
    /// The frame ring's segment cannot hold a ring.
    Ring(frame_ring::SegmentError),
}

impl core::fmt::Display for LinkError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::NameTooLong => "a port name is too long",
            Self::NotCreated => "its ports cannot be created",
            Self::NotOpen => "its ports were not created",
            Self::Ring(e) => return write!(f, "{e}"),
        })
    }
}

fn names(from: &str, to: &str) -> Result<(Name, Name), LinkError> {
    let name = |n: &str| Name::from_str(n).map_err(|_| LinkError::NameTooLong);
    Ok((name(from)?, name(to)?))
}

/// Creates the pair (in COLD_START or WARM_START), FIFO both.
pub fn create(
    ctx: &mut StartContext<Warden>,
    from: &PortSpec<'_>,
    to: &PortSpec<'_>,
) -> Result<(), LinkError> {
    let (from_name, to_name) = names(from.name, to.name)?;
    let fifo = QueuingDiscipline::Fifo;
    ctx.create_queuing_port_receiver(from_name, from.size, from.depth, fifo)
        .map_err(|_| LinkError::NotCreated)?;
    ctx.create_queuing_port_sender(to_name, to.size, to.depth, fifo)
        .map_err(|_| LinkError::NotCreated)?;
    Ok(())
}

/// Opens the pair [`create`] made (in a process).
pub fn open(from: &PortSpec<'_>, to: &PortSpec<'_>) -> Result<Link, LinkError> {
    open_named(from.name, to.name)
}

/// Opens the ports named `from` (a receiver) and `to` (a sender) that the partition
/// created at its start.
pub fn open_named(from: &str, to: &str) -> Result<Link, LinkError> {
    let (from_name, to_name) = names(from, to)?;
    Ok(Link {
        from: QueuingPortReceiver::from_name(from_name).map_err(|_| LinkError::NotOpen)?,
        to: QueuingPortSender::from_name(to_name).map_err(|_| LinkError::NotOpen)?,
    })
}
