//! The event descriptor calls: `eventfd`/`eventfd2`, `timerfd_create`/`_settime`/`_gettime`
//! and `epoll_create`/`epoll_create1`/`epoll_ctl`/`epoll_wait`/`epoll_pwait`/
//! `epoll_pwait2`. The objects are [`crate::events`]'s; this module checks the arguments,
//! copies them between the process and those objects, and waits the way `poll` does
//! ([`crate::poll`]: a call with nothing to return yet is served again later).

use super::table::Ctx;
use super::{Host, O_CLOEXEC, SysResult, WOULD_BLOCK, check_user, read_user, write_user};
use crate::events::{self, EPOLLEXCLUSIVE, Ready, WouldBlock};
use crate::linux::{self, Errno};
use crate::memory::Rights;
use crate::poll;
use crate::process::File;
use crate::syscall::file::Files;
use crate::vfs::dev::Device;
use alloc::vec::Vec;

/// `EFD_SEMAPHORE` (`EFD_CLOEXEC` and `EFD_NONBLOCK` are `O_CLOEXEC` and `O_NONBLOCK`, as
/// `TFD_*` and `EPOLL_CLOEXEC` are).
const EFD_SEMAPHORE: u64 = 1;
const TFD_TIMER_ABSTIME: u64 = 1;
/// Accepted and not acted on: the guest's wall clock is never set.
const TFD_TIMER_CANCEL_ON_SET: u64 = 2;
const CLOCK_BOOTTIME: u64 = 7;
const EPOLL_CTL_ADD: u64 = 1;
const EPOLL_CTL_DEL: u64 = 2;
const EPOLL_CTL_MOD: u64 = 3;
/// Bytes of a `struct epoll_event` (packed on x86-64: `u32` events, `u64` data).
const EPOLL_EVENT_SIZE: usize = 12;
/// Most events one `epoll_wait` returns (Linux's `EP_MAX_EVENTS`).
const EP_MAX_EVENTS: u64 = i32::MAX as u64 / EPOLL_EVENT_SIZE as u64;

/// Puts a new object's descriptor in the lowest free slot; without one, the object goes
/// again (`EMFILE`).
fn install_new(c: &mut Ctx<'_, '_, impl Host>, file: File, cloexec: bool) -> SysResult<u64> {
    let (p, f, _) = c.parts();
    let Some(fd) = p.free_fd() else {
        f.events.release(file);
        return Err(Errno::EMFILE);
    };
    p.install(fd, file, cloexec);
    Ok(fd as u64)
}

// ---- eventfd ----

/// `eventfd2(initval, flags)` (`eventfd` is it with no flags).
pub fn eventfd(c: &mut Ctx<'_, '_, impl Host>, initval: u64, flags: u64) -> SysResult<u64> {
    if flags & !(EFD_SEMAPHORE | O_CLOEXEC | linux::O_NONBLOCK) != 0 {
        return Err(Errno::EINVAL);
    }
    c.p.free_fd().ok_or(Errno::EMFILE)?;
    let nonblock = flags & linux::O_NONBLOCK != 0;
    // The C `unsigned int`: the register's high half is not the caller's.
    let index =
        c.f.events
            .open_counter(initval as u32 as u64, flags & EFD_SEMAPHORE != 0, nonblock)?;
    install_new(c, File::Event(index), flags & O_CLOEXEC != 0)
}

/// A read of counter `index` into `buf`: 8 bytes or `EINVAL`.
pub fn read_counter(f: &mut Files, index: usize, buf: &mut [u8]) -> SysResult<usize> {
    let c = f.events.counter(index).ok_or(Errno::EBADF)?;
    let Some(out) = buf.get_mut(..8) else {
        return Err(Errno::EINVAL);
    };
    match c.read() {
        Ok(value) => {
            out.copy_from_slice(&value.to_le_bytes());
            Ok(8)
        }
        Err(WouldBlock) if c.nonblock => Err(Errno::EAGAIN),
        Err(WouldBlock) => Err(WOULD_BLOCK),
    }
}

/// A write of `data` (8 bytes or `EINVAL`) to counter `index`.
pub fn write_counter(f: &mut Files, index: usize, data: &[u8]) -> SysResult<usize> {
    let c = f.events.counter(index).ok_or(Errno::EBADF)?;
    let Some(bytes) = data.get(..8) else {
        return Err(Errno::EINVAL);
    };
    let add = u64::from_le_bytes(bytes.try_into().unwrap_or([0; 8]));
    match c.write(add)? {
        Ok(()) => Ok(8),
        Err(WouldBlock) if c.nonblock => Err(Errno::EAGAIN),
        Err(WouldBlock) => Err(WOULD_BLOCK),
    }
}

// ---- timerfd ----

/// `timerfd_create(clockid, flags)`.
pub fn timerfd_create(c: &mut Ctx<'_, '_, impl Host>, clock: u64, flags: u64) -> SysResult<u64> {
    let clock = clock as u32 as u64;
    if !matches!(
        clock,
        linux::CLOCK_REALTIME | linux::CLOCK_MONOTONIC | CLOCK_BOOTTIME
    ) || flags & !(O_CLOEXEC | linux::O_NONBLOCK) != 0
    {
        return Err(Errno::EINVAL);
    }
    c.p.free_fd().ok_or(Errno::EMFILE)?;
    let realtime = clock == linux::CLOCK_REALTIME;
    let index =
        c.f.events
            .open_timer(realtime, flags & linux::O_NONBLOCK != 0)?;
    install_new(c, File::Timer(index), flags & O_CLOEXEC != 0)
}

/// The timer descriptor `fd` refers to (`EBADF` closed, `EINVAL` another kind).
fn timer_index(c: &Ctx<'_, '_, impl Host>, fd: u64) -> SysResult<usize> {
    match c.p.file(fd).ok_or(Errno::EBADF)? {
        File::Timer(index) => Ok(index),
        _ => Err(Errno::EINVAL),
    }
}

/// A `struct itimerspec` of an interval and a value (ns).
fn itimerspec(interval: u64, value: u64) -> [u8; 32] {
    let mut b = [0u8; 32];
    b[..16].copy_from_slice(&linux::timespec(interval));
    b[16..].copy_from_slice(&linux::timespec(value));
    b
}

/// `timerfd_settime(fd, flags, new, old)`.
pub fn timerfd_settime(
    c: &mut Ctx<'_, '_, impl Host>,
    fd: u64,
    flags: u64,
    new: u64,
    old: u64,
) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    let interval = crate::sigcalls::read_time(p, host, new, false)?;
    let value = crate::sigcalls::read_time(p, host, new.wrapping_add(16), false)?;
    if flags & !(TFD_TIMER_ABSTIME | TFD_TIMER_CANCEL_ON_SET) != 0 {
        return Err(Errno::EINVAL);
    }
    let index = timer_index(c, fd)?;
    let (p, f, host) = c.parts();
    let now = host.now_ns();
    let wall = host.wall_clock_ns();
    let t = f.events.timer(index).ok_or(Errno::EBADF)?;
    let (left, old_interval) = t.remaining(now);
    let at = match value {
        0 => None,
        // A wall-clock time, on the guest's clock.
        _ if flags & TFD_TIMER_ABSTIME != 0 && t.realtime => {
            Some(value.saturating_sub(wall.saturating_sub(now)))
        }
        _ if flags & TFD_TIMER_ABSTIME != 0 => Some(value),
        _ => Some(now.saturating_add(value)),
    };
    t.set(at, interval);
    if old != 0 {
        write_user(p, host, old, &itimerspec(old_interval, left))?;
    }
    Ok(0)
}

/// `timerfd_gettime(fd, cur)`.
pub fn timerfd_gettime(c: &mut Ctx<'_, '_, impl Host>, fd: u64, cur: u64) -> SysResult<u64> {
    let index = timer_index(c, fd)?;
    let (p, f, host) = c.parts();
    let now = host.now_ns();
    let t = f.events.timer(index).ok_or(Errno::EBADF)?;
    let (left, interval) = t.remaining(now);
    write_user(p, host, cur, &itimerspec(interval, left))?;
    Ok(0)
}

/// A read of timer `index` into `buf`: 8 bytes (the expirations) or `EINVAL`.
pub fn read_timer(
    f: &mut Files,
    host: &mut impl Host,
    index: usize,
    buf: &mut [u8],
) -> SysResult<usize> {
    let now = host.now_ns();
    let t = f.events.timer(index).ok_or(Errno::EBADF)?;
    let Some(out) = buf.get_mut(..8) else {
        return Err(Errno::EINVAL);
    };
    match t.read(now) {
        Ok(count) => {
            out.copy_from_slice(&count.to_le_bytes());
            Ok(8)
        }
        Err(WouldBlock) if t.nonblock => Err(Errno::EAGAIN),
        Err(WouldBlock) => Err(WOULD_BLOCK),
    }
}

// ---- epoll ----

/// `epoll_create(size)`: `size` must be positive and means nothing else.
pub fn epoll_create(c: &mut Ctx<'_, '_, impl Host>, size: i32) -> SysResult<u64> {
    if size <= 0 {
        return Err(Errno::EINVAL);
    }
    epoll_create1(c, 0)
}

/// `epoll_create1(flags)`.
pub fn epoll_create1(c: &mut Ctx<'_, '_, impl Host>, flags: u64) -> SysResult<u64> {
    if flags & !O_CLOEXEC != 0 {
        return Err(Errno::EINVAL);
    }
    c.p.free_fd().ok_or(Errno::EMFILE)?;
    let index = c.f.events.open_epoll()?;
    install_new(c, File::Epoll(index), flags & O_CLOEXEC != 0)
}

/// Whether `file` has readiness to watch (Linux's `EPERM` for files without `poll`:
/// regular files, directories and most devices).
fn pollable(f: &Files, file: File) -> bool {
    let File::Open(id) = file else {
        return true;
    };
    let Some(node) = f.fs.description(id).map(|o| o.node) else {
        return false;
    };
    f.fs.port(node).is_some() || matches!(f.fs.device(node), Some(Device::Random | Device::Urandom))
}

/// `epoll_ctl(epfd, op, fd, event)`.
pub fn epoll_ctl(
    c: &mut Ctx<'_, '_, impl Host>,
    epfd: u64,
    op: u64,
    fd: u64,
    event: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let mut bytes = [0u8; EPOLL_EVENT_SIZE];
    if op != EPOLL_CTL_DEL {
        read_user(p, host, event, &mut bytes)?;
    }
    let events = u32::from_le_bytes(bytes[..4].try_into().unwrap_or([0; 4]));
    let data = u64::from_le_bytes(bytes[4..].try_into().unwrap_or([0; 8]));
    let epoll = p.file(epfd).ok_or(Errno::EBADF)?;
    let target = p.file(fd).ok_or(Errno::EBADF)?;
    if !pollable(f, target) {
        return Err(Errno::EPERM);
    }
    let File::Epoll(index) = epoll else {
        return Err(Errno::EINVAL);
    };
    if epfd == fd {
        return Err(Errno::EINVAL);
    }
    // `EPOLLEXCLUSIVE` only with ADD, and not for an epoll descriptor.
    if events & EPOLLEXCLUSIVE != 0
        && (op == EPOLL_CTL_MOD || (op == EPOLL_CTL_ADD && matches!(target, File::Epoll(_))))
    {
        return Err(Errno::EINVAL);
    }
    // One level of nesting: an instance that watches instances is not watched itself,
    // so there is never a loop (Linux allows deeper nests, and `ELOOP` for loops).
    if op == EPOLL_CTL_ADD
        && let File::Epoll(inner) = target
    {
        let nests = |i: usize, f: &mut Files| {
            f.events
                .epoll(i)
                .is_some_and(|e| e.files().any(|x| matches!(x, File::Epoll(_))))
        };
        if nests(inner, f) || f.events.watched_by_epoll(File::Epoll(index)) {
            return Err(Errno::ELOOP);
        }
    }
    let fd = fd as i32;
    let e = f.events.epoll(index).ok_or(Errno::EBADF)?;
    match op {
        EPOLL_CTL_ADD => e.add(fd, target, events, data)?,
        EPOLL_CTL_MOD => e.modify(fd, target, events, data)?,
        EPOLL_CTL_DEL => e.remove(fd, target)?,
        _ => return Err(Errno::EINVAL),
    }
    Ok(0)
}

/// The readiness of instance `index`'s files, in list order (an instance it watches: at
/// level, its own instances not looked into).
fn readiness(
    f: &mut Files,
    host: &mut impl Host,
    console: u16,
    index: usize,
    nested: bool,
) -> Vec<u16> {
    let files: Vec<File> = f
        .events
        .epoll(index)
        .map(|e| e.files().collect())
        .unwrap_or_default();
    files
        .into_iter()
        .map(|file| match file {
            File::Epoll(_) if nested => 0,
            File::Epoll(inner) => {
                let ready = readiness(f, host, console, inner, true);
                match f.events.epoll(inner) {
                    Some(e) if e.any_ready(&ready) => poll::POLLIN,
                    _ => 0,
                }
            }
            file => poll::file_events(f, host, console, file),
        })
        .collect()
}

/// The `poll` events of epoll instance `index`: readable while an item is ready.
pub fn epoll_events(f: &mut Files, host: &mut impl Host, console: u16, index: usize) -> u16 {
    let ready = readiness(f, host, console, index, false);
    match f.events.epoll(index) {
        Some(e) if e.any_ready(&ready) => poll::POLLIN,
        Some(_) => 0,
        None => poll::POLLERR,
    }
}

/// `epoll_wait(epfd, events, maxevents, timeout_ms)`, and with a signal mask to wait with
/// (`mask`, `mask_size`: `epoll_pwait`, `epoll_pwait2`).
pub fn epoll_wait(
    c: &mut Ctx<'_, '_, impl Host>,
    epfd: u64,
    out: u64,
    maxevents: i32,
    timeout_ns: Option<u64>,
    mask: u64,
    mask_size: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    if maxevents <= 0 || maxevents as u64 > EP_MAX_EVENTS {
        return Err(Errno::EINVAL);
    }
    check_user(p, out, maxevents as usize * EPOLL_EVENT_SIZE, Rights::WRITE)?;
    let File::Epoll(index) = p.file(epfd).ok_or(Errno::EBADF)? else {
        return Err(Errno::EINVAL);
    };
    f.events.epoll(index).ok_or(Errno::EBADF)?;
    poll::wait_mask(p, host, mask, mask_size)?;
    let console = poll::console_events(host);
    let ready = readiness(f, host, console, index, false);
    let Some(e) = f.events.epoll(index) else {
        poll::finish(p);
        return Err(Errno::EBADF);
    };
    let max = (maxevents as usize).min(e.len());
    let mut reports: Vec<Ready> = Vec::new();
    if reports.try_reserve_exact(max).is_err() {
        poll::finish(p);
        return Err(Errno::ENOMEM);
    }
    e.collect(&ready, max, &mut reports);
    let deadline = poll::deadline(p, host, timeout_ns);
    if reports.is_empty() && !poll::timed_out(host, deadline) {
        return Err(WOULD_BLOCK);
    }
    poll::finish(p);
    let mut bytes = [0u8; EPOLL_EVENT_SIZE];
    for (i, r) in reports.iter().enumerate() {
        bytes[..4].copy_from_slice(&r.events.to_le_bytes());
        bytes[4..].copy_from_slice(&r.data.to_le_bytes());
        write_user(p, host, out + (i * EPOLL_EVENT_SIZE) as u64, &bytes)?;
    }
    Ok(reports.len() as u64)
}

/// `EPOLLET`: a read (`write`: a write) of `file` had to wait, so its readiness was used
/// up and comes back as a new edge.
pub fn consumed(f: &mut Files, file: File, write: bool) {
    let bits = if write {
        events::EPOLLOUT
    } else {
        events::EPOLLIN
    };
    f.events.consumed(file, bits);
}
