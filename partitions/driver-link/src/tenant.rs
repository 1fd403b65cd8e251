//! A tenant's end of its link to the NIC partition, for tenants that reach their ports
//! through APEX (the soft-PLC, the IEC 61499 device): the frame ports and, when the
//! configuration gives one, the frame ring (`frame_ring`), the ports then carrying only
//! its wake-ups. The tenant moves frames between the link and its network stack once a
//! pass, a bounded number each way.

use crate::{Link, LinkError};
use apex::a653rs::prelude::*;
use core::time::Duration;

/// The longest frame either way (an Ethernet frame without its FCS).
pub const MTU: usize = frame_ring::MTU;

/// The tenant's ends of its frame ports (`from` the NIC partition, `to` it) and of its
/// frame ring, if any.
pub struct TenantLink {
    ports: Link,
    ring: Option<(frame_ring::Producer, frame_ring::Consumer)>,
    frame: [u8; MTU],
    /// Frames received and sent since the link was opened.
    pub frames_in: u64,
    pub frames_out: u64,
}

impl TenantLink {
    /// Opens the ports the partition created at its start, named `rx` and `tx`, and
    /// attaches the ring `(address, size)` if there is one.
    ///
    /// # Safety
    /// The ring's segment, when given, must be mapped read-write for the partition's life
    /// and shared with its NIC partition only (the configuration tools check both), and
    /// be attached by no one else in this partition.
    #[allow(unsafe_code)]
    pub unsafe fn open(rx: &str, tx: &str, ring: Option<(u64, u64)>) -> Result<Self, LinkError> {
        let ports = crate::open_named(rx, tx)?;
        let ring = match ring {
            None => None,
            Some((address, size)) => {
                let (at, size) = (address as *mut u8, size as usize);
                // SAFETY: this function's contract.
                let ring = unsafe { frame_ring::attach(at, size, frame_ring::Side::Tenant) };
                Some(ring.map_err(LinkError::Ring)?)
            }
        };
        Ok(TenantLink {
            ports,
            ring,
            frame: [0; MTU],
            frames_in: 0,
            frames_out: 0,
        })
    }

    /// Asks syssw to notify the calling process's thread with `bits` whenever a message
    /// (a frame, or the ring's wake-up) arrives from the NIC partition
    /// ([`Link::ring_on_arrival`]), and the NIC partition to notify it with the same bits
    /// itself when a frame goes into the empty ring (the ring's waiter).
    pub fn ring_on_arrival(
        &mut self,
        bits: u64,
    ) -> Result<(), apex::a653rs::bindings::ErrorReturnCode> {
        if let Some((_, from)) = self.ring.as_mut() {
            from.wake_me(apex::user_rt::sys::thread_self().0.0, bits);
        }
        self.ports.ring_on_arrival(bits)
    }

    /// Hands up to `budget` frames from the NIC partition to `deliver`. With a ring, its
    /// wake-ups are drained first and then the ring is read (a frame that comes after
    /// that was pushed into an empty ring and wakes the next pass); a bogus slot the NIC
    /// partition wrote is skipped.
    pub fn receive(&mut self, budget: usize, mut deliver: impl FnMut(&[u8])) {
        let poll = || SystemTime::Normal(Duration::ZERO);
        let Some((_, from)) = self.ring.as_mut() else {
            for _ in 0..budget {
                let Ok((frame, _)) = self.ports.from.receive(&mut self.frame, poll()) else {
                    break;
                };
                deliver(frame);
                self.frames_in += 1;
            }
            return;
        };
        for _ in 0..budget {
            if self.ports.from.receive(&mut self.frame, poll()).is_err() {
                break;
            }
        }
        for _ in 0..budget {
            match from.pop(&mut self.frame) {
                None => break,
                Some(Ok(len)) => deliver(&self.frame[..len]),
                Some(Err(_)) => continue,
            }
            self.frames_in += 1;
        }
    }

    /// Sends up to `budget` frames `take` gives. With a ring, a frame pushed into an empty
    /// ring wakes the NIC partition after them: a notification of the thread the ring
    /// names, else a wake-up on the port (none when the port is full: wake-ups are waiting
    /// there already); a full ring drops the frame, as a full port does.
    pub fn send<F: AsRef<[u8]>>(&mut self, budget: usize, mut take: impl FnMut() -> Option<F>) {
        let poll = || SystemTime::Normal(Duration::ZERO);
        let mut wake = false;
        for _ in 0..budget {
            let Some(frame) = take() else {
                break;
            };
            match self.ring.as_mut() {
                Some((to, _)) => wake |= to.push(frame.as_ref()).is_ok_and(|p| p.first),
                None => {
                    let _ = self.ports.to.send(frame.as_ref(), poll());
                }
            }
            self.frames_out += 1;
        }
        let notified =
            wake && crate::notify_waiter(self.ring.as_ref().and_then(|(to, _)| to.waiter()));
        if wake && !notified {
            let _ = self.ports.to.send(&[0], poll());
        }
    }
}
