//! Waiting for descriptors: `poll`, `ppoll`, `select` and `pselect6`. Each file kind says
//! which events it has now ([`events`]); a call with nothing ready waits (its message is
//! served again whenever something happened, see [`crate::system`]) until a descriptor is
//! ready, its timeout passed (the process's `wake_at`), or a signal interrupts it.
//! `ppoll` and `pselect6` wait with the signal mask they were given and restore the
//! caller's afterwards.

use crate::arinc;
use crate::linux::Errno;
use crate::process::{File, Process};
use crate::syscall::file::Files;
use crate::syscall::table::Ctx;
use crate::syscall::{Host, SysResult, WOULD_BLOCK, read_user, write_user};

pub const POLLIN: u16 = 0x1;
pub const POLLPRI: u16 = 0x2;
pub const POLLOUT: u16 = 0x4;
pub const POLLERR: u16 = 0x8;
pub const POLLHUP: u16 = 0x10;
pub const POLLNVAL: u16 = 0x20;
pub const POLLRDNORM: u16 = 0x40;
pub const POLLWRNORM: u16 = 0x100;

/// The events descriptor `fd` of `p` has now (`POLLNVAL` for a closed one), the console's
/// being `console` ([`console_events`]). `POLLERR` and `POLLHUP` are reported whether
/// asked for or not.
pub fn events(p: &Process, f: &mut Files, host: &mut impl Host, console: u16, fd: u64) -> u16 {
    match p.file(fd) {
        None => POLLNVAL,
        Some(file) => file_events(f, host, console, file),
    }
}

/// The events of what a descriptor refers to ([`events`]; an epoll interest list keeps
/// the file, not the descriptor).
pub fn file_events(f: &mut Files, host: &mut impl Host, console: u16, file: File) -> u16 {
    let ready = match file {
        File::Pipe { pipe, write, .. } => f.pipes.poll(pipe, write),
        File::UnixSocket { pair, end, .. } => f.pipes.poll_pair(pair, end),
        File::Socket(id) => crate::syscall::socket::events(f.net, host.now_ns(), id),
        File::Console(_) => console,
        File::Open(id) if let Some((index, port)) = port_of(f.fs, id) => {
            arinc::events(port, index, host)
        }
        File::Event(i) => f.events.counter(i).map_or(POLLERR, |c| c.poll()),
        File::Timer(i) => {
            let now = host.now_ns();
            f.events.timer(i).map_or(POLLERR, |t| t.poll(now))
        }
        File::Epoll(i) => crate::syscall::events::epoll_events(f, host, console, i),
        // Regular files never wait.
        File::Open(_) => POLLIN | POLLOUT,
    };
    let normal = if ready & POLLIN != 0 { POLLRDNORM } else { 0 }
        | if ready & POLLOUT != 0 { POLLWRNORM } else { 0 };
    ready | normal
}

/// The ARINC port open file description `id` is of, with its index.
fn port_of<'f>(fs: &'f crate::vfs::Fs, id: crate::vfs::OpenId) -> Option<(usize, &'f arinc::Port)> {
    fs.port(fs.description(id)?.node)
}

/// The console's events: its terminal's input readiness ([`crate::tty::Tty::readable`]),
/// or, without a terminal, always readable (end of file); always writable.
pub fn console_events(host: &mut impl Host) -> u16 {
    let readable = host.tty().is_none_or(|t| t.readable());
    (if readable { POLLIN } else { 0 }) | POLLOUT
}

/// The deadline of a wait: `None` (forever), `Some(0)` (do not wait), or when it ends on
/// the guest's clock. Set on the first serve of the call, kept in `p.wake_at` after.
pub(crate) fn deadline(
    p: &mut Process,
    host: &mut impl Host,
    timeout_ns: Option<u64>,
) -> Option<u64> {
    match timeout_ns {
        None => None,
        Some(0) => Some(0),
        Some(ns) => Some(
            *p.wake_at
                .get_or_insert_with(|| host.now_ns().saturating_add(ns)),
        ),
    }
}

/// Whether the wait is over without anything ready: its deadline passed.
pub(crate) fn timed_out(host: &mut impl Host, deadline: Option<u64>) -> bool {
    match deadline {
        None => false,
        Some(0) => true,
        Some(at) => host.now_ns() >= at,
    }
}

/// Ends a wait: the process's timer and temporary mask go.
pub(crate) fn finish(p: &mut Process) {
    p.wake_at = None;
    if let Some(mask) = p.saved_mask.take() {
        p.sigmask = mask;
    }
}

/// Installs the mask `ppoll`/`pselect6` wait with, if they were given one.
pub(crate) fn wait_mask(
    p: &mut Process,
    host: &mut impl Host,
    set: u64,
    size: u64,
) -> SysResult<()> {
    if set == 0 {
        return Ok(());
    }
    crate::sigcalls::wait_with_mask(p, host, set, size)
}

/// A `struct timespec` (`ppoll`, `pselect6`) in ns; `None` for a null pointer.
fn read_timeout(p: &Process, host: &mut impl Host, at: u64, micro: bool) -> SysResult<Option<u64>> {
    if at == 0 {
        return Ok(None);
    }
    crate::sigcalls::read_time(p, host, at, micro).map(Some)
}

/// `len` zero bytes from the guest's heap (`ENOMEM` when it has no room).
fn zeroed(len: usize) -> SysResult<alloc::vec::Vec<u8>> {
    let mut bytes = alloc::vec::Vec::new();
    bytes.try_reserve_exact(len).map_err(|_| Errno::ENOMEM)?;
    bytes.resize(len, 0);
    Ok(bytes)
}

/// `poll(fds, nfds, timeout_ms)` and `ppoll(fds, nfds, timeout, sigmask, size)`.
#[allow(clippy::too_many_arguments)] // the calls' arguments
pub fn poll(
    c: &mut Ctx<'_, '_, impl Host>,
    fds: u64,
    nfds: u64,
    timeout_ns: Option<u64>,
    mask: u64,
    mask_size: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    // As many as it may have descriptors (`RLIMIT_NOFILE`), as Linux.
    if nfds > p.max_fd() as u64 {
        return Err(Errno::EINVAL);
    }
    let mut table = zeroed(nfds as usize * 8)?;
    let table = &mut table[..];
    read_user(p, host, fds, table)?;
    wait_mask(p, host, mask, mask_size)?;
    let console = console_events(host);
    let mut ready = 0;
    for entry in table.chunks_exact_mut(8) {
        let fd = i32::from_le_bytes(entry[..4].try_into().unwrap_or([0; 4]));
        let asked = u16::from_le_bytes([entry[4], entry[5]]);
        let got = if fd < 0 {
            0
        } else {
            events(p, f, host, console, fd as u64) & (asked | POLLERR | POLLHUP | POLLNVAL)
        };
        entry[6..8].copy_from_slice(&got.to_le_bytes());
        ready += u64::from(got != 0);
    }
    let deadline = deadline(p, host, timeout_ns);
    if ready == 0 && !timed_out(host, deadline) {
        return Err(WOULD_BLOCK);
    }
    finish(p);
    write_user(p, host, fds, table)?;
    Ok(ready)
}

/// `poll`'s timeout in ms (negative: forever) as ns.
pub fn poll_timeout(ms: u64) -> Option<u64> {
    let ms = ms as i32;
    (ms >= 0).then(|| ms as u64 * 1_000_000)
}

/// `ppoll`'s (and `epoll_pwait2`'s) timeout: a `struct timespec` (null: forever).
pub fn ppoll_timeout(c: &mut Ctx<'_, '_, impl Host>, at: u64) -> SysResult<Option<u64>> {
    let (p, _, host) = c.parts();
    read_timeout(p, host, at, false)
}

/// `select(nfds, readfds, writefds, exceptfds, timeval)` and `pselect6(..., timespec,
/// {sigmask, size})`.
pub fn select(c: &mut Ctx<'_, '_, impl Host>, a: [u64; 6], pselect: bool) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let [nfds, sets @ .., timeout] = [a[0], a[1], a[2], a[3], a[4]];
    if nfds > p.max_fd() as u64 {
        return Err(Errno::EINVAL);
    }
    let timeout_ns = read_timeout(p, host, timeout, !pselect)?;
    if pselect && a[5] != 0 {
        let mut b = [0u8; 16];
        read_user(p, host, a[5], &mut b)?;
        let set = u64::from_le_bytes(b[..8].try_into().unwrap_or([0; 8]));
        let size = u64::from_le_bytes(b[8..].try_into().unwrap_or([0; 8]));
        wait_mask(p, host, set, size)?;
    }
    // The three sets (read, write, except) as bytes, `bytes` each: one bit a descriptor.
    let bytes = (nfds as usize).div_ceil(64) * 8;
    let mut asked = zeroed(3 * bytes)?;
    for (set, &at) in asked.chunks_exact_mut(bytes.max(1)).zip(&sets) {
        if at != 0 {
            read_user(p, host, at, &mut set[..bytes])?;
        }
    }
    let bit = |set: &[u8], fd: usize| set[fd / 8] & (1 << (fd % 8)) != 0;
    let console = console_events(host);
    let mut got = zeroed(3 * bytes)?;
    let mut ready = 0u64;
    for fd in 0..nfds as usize {
        let wanted = [0, 1, 2].map(|s| bit(&asked[s * bytes..], fd));
        if wanted == [false; 3] {
            continue;
        }
        let ev = events(p, f, host, console, fd as u64);
        if ev & POLLNVAL != 0 {
            return Err(Errno::EBADF);
        }
        let has = [
            ev & (POLLIN | POLLHUP | POLLERR) != 0,
            ev & (POLLOUT | POLLERR) != 0,
            ev & POLLPRI != 0,
        ];
        for s in 0..3 {
            if wanted[s] && has[s] {
                got[s * bytes + fd / 8] |= 1 << (fd % 8);
                ready += 1;
            }
        }
    }
    let deadline = deadline(p, host, timeout_ns);
    if ready == 0 && !timed_out(host, deadline) {
        return Err(WOULD_BLOCK);
    }
    finish(p);
    for (set, &at) in got.chunks_exact(bytes.max(1)).zip(&sets) {
        if at != 0 {
            write_user(p, host, at, &set[..bytes])?;
        }
    }
    Ok(ready)
}
