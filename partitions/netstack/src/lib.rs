//! TCP/IP for a partition: smoltcp's interfaces driven on the partition's clock, with
//! sockets that behave as Linux's do (the guest hands its processes' socket calls to
//! [`Stack`] and turns the answers into Linux's). no_std with `alloc` (the sockets' buffers
//! come from the partition's bounded heap, within [`Limits`]); host-tested; nothing a frame
//! from the wire or a socket call can do panics it.
//!
//! # Interfaces
//!
//! `eth0` is the partition's virtual interface on the NIC partition's switch: its frames
//! go through [`Queues`], which the partition empties into and fills from its rings. `lo`
//! is the loopback, 127.0.0.1/8, inside the stack. A socket lives on the interface its
//! address says: bound to or connecting to 127.x, `lo`; else `eth0`; a listener bound to
//! 0.0.0.0 listens on both.
//!
//! # Socket semantics (Linux's, where smoltcp lets us)
//!
//! - `listen(backlog)` keeps `backlog` (at least 1, at most [`Limits::backlog`]) listening
//!   sockets on the port: that many connections can be completing or waiting for
//!   `accept` at once; one more is refused by the stack as Linux refuses on a full queue.
//! - A call that cannot finish now answers [`Error::WouldBlock`]: the guest answers EAGAIN
//!   to a non-blocking descriptor and otherwise waits for [`Stack::readiness`] to change.
//!   A non-blocking `connect` answers [`Error::InProgress`]; its outcome is then
//!   [`Stack::connect_result`] (SO_ERROR).
//! - `close` of a connected TCP socket sends FIN and lets the connection finish in the
//!   background (bounded: at most [`Limits::sockets`] sockets in all, lingering ones
//!   included; when none is left, connections waiting in TIME-WAIT give their places,
//!   oldest first); closing a listener resets the connections nobody accepted.
//! - Not there: IPv6 (`socket(AF_INET6)` is EAFNOSUPPORT, so programs fall back to IPv4),
//!   raw sockets, urgent data, `SO_LINGER` with a timeout (accepted, not honoured).

#![no_std]

extern crate alloc;

mod error;
mod queues;
mod stack;

pub use error::Error;
pub use queues::{Counters, MTU, Queues};
pub use smoltcp::wire::Ipv4Address;
pub use stack::{Config, Limits, Readiness, SocketId, SocketKind, Stack, linux};

/// An IPv4 socket address.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SocketAddr {
    pub ip: Ipv4Address,
    pub port: u16,
}

impl SocketAddr {
    pub const fn new(ip: Ipv4Address, port: u16) -> Self {
        SocketAddr { ip, port }
    }
}

#[cfg(test)]
mod tests;
