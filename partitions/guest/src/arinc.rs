//! The guest's ARINC 653 ports as devices: each sampling or queuing port of the guest
//! partition's configuration (`ports.*`) is the character device `/dev/arinc/<name>`
//! ([`crate::vfs::dev::Device::Port`], device number [`MAJOR`]:index).
//!
//! The port table reaches the guest in its initramfs, [`PORTS_PATH`] (written by
//! `cargo xtask` from the partition's `ports.*` keys), one port a line:
//! `<name> <sampling|queuing> <in|out> <size> <refresh ns|depth>` (a sampling port's
//! refresh period, 0 for none or a source, or a queuing port's depth). The partition
//! program creates the ports through syssw at start and moves their messages
//! ([`crate::syscall::Host::port_send`], [`crate::syscall::Host::port_receive`], never
//! waiting); this module decides what a Linux call on such a device means:
//!
//! - `read` of a destination (`in`) port takes one message (a queuing port's next one,
//!   a sampling port's current one, which stays) and returns its length; a buffer smaller
//!   than the port's message size is `EMSGSIZE` (nothing is taken). With nothing to read
//!   (an empty queue, a sampling port never written) it waits (the host then serves the
//!   waiting calls again soon, [`crate::syscall::Host::port_wait`]: no message tells the
//!   guest of an arrival), or gives `EAGAIN` with `O_NONBLOCK`. Reading a source (`out`) port is `EINVAL`.
//! - `write` to a source port sends the bytes as one message; more than the port's size is
//!   `EMSGSIZE`, 0 bytes send nothing and return 0. A full queue waits, or gives `EAGAIN`
//!   with `O_NONBLOCK`. Writing a destination port is `EINVAL`.
//! - `readv` and `writev` move one message per buffer.
//! - `poll`: `POLLIN` when a read would not wait, `POLLOUT` when a write would not.
//! - The validity of a sampling port's message (ARINC's `VALIDITY`: younger than the
//!   port's refresh period) is the `ioctl` [`IOCTL_VALIDITY`]: it stores an `int`, 1 for
//!   valid and 0 for invalid (or no message), at its argument; on any other port it is
//!   `ENOTTY`.
//!
//! This module never talks to syssw and never trusts a table line: a bad line is an error
//! that names it.

use crate::linux::Errno;
use crate::poll::{POLLIN, POLLOUT};
use crate::syscall::{Host, SysResult, WOULD_BLOCK};
use alloc::string::String;
use alloc::vec::Vec;

/// Where the port table is in the initramfs.
pub const PORTS_PATH: &str = "/etc/guest/ports";
/// The directory of the port devices.
pub const DEVICE_DIR: &str = "/dev/arinc";
/// The devices' major number (Linux's first one for local use).
pub const MAJOR: u64 = 240;
/// Most ports a guest has devices for.
pub const MAX_PORTS: usize = 64;
/// Largest message a port device moves (what one system call copies at once).
pub const MAX_MESSAGE: u32 = 4096;
/// `ioctl(fd, IOCTL_VALIDITY, int *valid)`: `_IOR('A', 1, int)`.
pub const IOCTL_VALIDITY: u64 = 0x8004_4101;

/// ARINC 653 port kinds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Sampling,
    Queuing,
}

/// Direction seen from the guest: `In` is a destination (read), `Out` a source (write).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    In,
    Out,
}

/// One configured port.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Port {
    pub name: String,
    pub kind: Kind,
    pub direction: Direction,
    /// Largest message, bytes.
    pub size: u32,
    /// A sampling port's refresh period (ns, 0 = none) or a queuing port's depth.
    pub refresh_or_depth: u64,
}

/// A bad line of the port table: its number (from 1) and what is wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TableError {
    pub line: usize,
    pub reason: &'static str,
}

/// The ports of a table ([`PORTS_PATH`]'s format); empty lines are skipped.
pub fn parse(text: &[u8]) -> Result<Vec<Port>, TableError> {
    let mut ports: Vec<Port> = Vec::new();
    for (i, line) in text.split(|&b| b == b'\n').enumerate() {
        let fail = |reason| TableError {
            line: i + 1,
            reason,
        };
        let line = core::str::from_utf8(line).map_err(|_| fail("not UTF-8"))?;
        let mut words = line.split_ascii_whitespace();
        let Some(name) = words.next() else {
            continue;
        };
        if ports.len() == MAX_PORTS {
            return Err(fail("more ports than a guest has devices for"));
        }
        if name == "." || name == ".." || name.contains('/') || name.len() > 255 {
            return Err(fail("the name is no file name"));
        }
        if ports.iter().any(|p| p.name == name) {
            return Err(fail("a port of that name is listed already"));
        }
        let kind = match words.next() {
            Some("sampling") => Kind::Sampling,
            Some("queuing") => Kind::Queuing,
            _ => return Err(fail("the kind is neither sampling nor queuing")),
        };
        let direction = match words.next() {
            Some("in") => Direction::In,
            Some("out") => Direction::Out,
            _ => return Err(fail("the direction is neither in nor out")),
        };
        let size = words
            .next()
            .and_then(|w| w.parse::<u32>().ok())
            .filter(|&s| (1..=MAX_MESSAGE).contains(&s))
            .ok_or(fail("the size is no number from 1 to 4096"))?;
        let refresh_or_depth = words
            .next()
            .and_then(|w| w.parse::<u64>().ok())
            .ok_or(fail("the refresh period or depth is no number"))?;
        if words.next().is_some() {
            return Err(fail("more than five fields"));
        }
        ports.push(Port {
            name: name.into(),
            kind,
            direction,
            size,
            refresh_or_depth,
        });
    }
    Ok(ports)
}

/// A message the host took from a port.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Received {
    pub len: usize,
    /// A sampling message's validity (always true for a queuing one).
    pub valid: bool,
}

/// What a port could do now, as the host sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Readiness {
    /// A read would not wait (a message is there).
    pub readable: bool,
    /// A write would not wait (a source with room).
    pub writable: bool,
    /// The sampling message there is valid.
    pub valid: bool,
}

/// `read` of port `index` into `buf` (the caller's count, at most one chunk).
pub fn read(
    port: &Port,
    index: usize,
    host: &mut impl Host,
    buf: &mut [u8],
    nonblock: bool,
) -> SysResult<usize> {
    if port.direction != Direction::In {
        return Err(Errno::EINVAL);
    }
    if buf.len() < port.size as usize {
        return Err(Errno::EMSGSIZE);
    }
    match host.port_receive(index, &mut buf[..port.size as usize]) {
        Ok(r) => Ok(r.len.min(port.size as usize)),
        Err(Errno::EAGAIN) if !nonblock => {
            host.port_wait();
            Err(WOULD_BLOCK)
        }
        Err(e) => Err(e),
    }
}

/// `write` of `data` to port `index` as one message.
pub fn write(
    port: &Port,
    index: usize,
    host: &mut impl Host,
    data: &[u8],
    nonblock: bool,
) -> SysResult<usize> {
    if port.direction != Direction::Out {
        return Err(Errno::EINVAL);
    }
    if too_long(port, data.len() as u64) {
        return Err(Errno::EMSGSIZE);
    }
    if data.is_empty() {
        return Ok(0);
    }
    match host.port_send(index, data) {
        Ok(()) => Ok(data.len()),
        Err(Errno::EAGAIN) if !nonblock => {
            host.port_wait();
            Err(WOULD_BLOCK)
        }
        Err(e) => Err(e),
    }
}

/// Whether `len` bytes are too many for one message of source port `port`.
pub fn too_long(port: &Port, len: u64) -> bool {
    port.direction == Direction::Out && len > u64::from(port.size)
}

/// The `poll` events of port `index` (a port that is not ready may be waited for:
/// [`Host::port_wait`]).
pub fn events(port: &Port, index: usize, host: &mut impl Host) -> u16 {
    let now = host.port_readiness(index);
    match port.direction {
        Direction::In if now.readable => POLLIN,
        Direction::Out if now.writable => POLLOUT,
        _ => {
            host.port_wait();
            0
        }
    }
}

/// The [`IOCTL_VALIDITY`] answer of port `index`: 1 valid, 0 not (`ENOTTY` on a port
/// that is no sampling destination).
pub fn validity(port: &Port, index: usize, host: &mut impl Host) -> SysResult<u32> {
    if port.kind != Kind::Sampling || port.direction != Direction::In {
        return Err(Errno::ENOTTY);
    }
    Ok(u32::from(host.port_readiness(index).valid))
}
