//! The signal and timer system calls that concern one process only: `rt_sigaction`,
//! `rt_sigprocmask`, `rt_sigpending`, `sigaltstack`, `rt_sigreturn`, `nanosleep`,
//! `clock_nanosleep`, `alarm`, `setitimer`/`getitimer` (`ITIMER_REAL`), `pause`,
//! `rt_sigsuspend`; and what a waiting call returns when a signal interrupts it
//! ([`interrupted`]). Sending signals and delivering them is the process table's
//! ([`crate::system`]).

use crate::linux::{self, Errno, nr};
use crate::process::Process;
use crate::signal::{self, Action, AltStack, FPU_SIZE, FRAME_SIZE, UNBLOCKABLE};
use crate::syscall::table::Ctx;
use crate::syscall::{Host, SysResult, WOULD_BLOCK, read_user, write_user};
use abi::ipc::ExceptionMessage;

const TIMER_ABSTIME: u64 = 1;
const ITIMER_REAL: u64 = 0;
const NS_PER_S: u64 = 1_000_000_000;

pub fn sigaction(
    c: &mut Ctx<'_, '_, impl Host>,
    number: u64,
    act: u64,
    old: u64,
    size: u64,
) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    if size != 8 || number == 0 || number > signal::NSIG as u64 {
        return Err(Errno::EINVAL);
    }
    let sig = number as u32;
    if act != 0 && signal::bit(sig) & UNBLOCKABLE != 0 {
        return Err(Errno::EINVAL);
    }
    let new = if act != 0 {
        let mut b = [0u8; 32];
        read_user(p, host, act, &mut b)?;
        Some(Action::from_bytes(&b))
    } else {
        None
    };
    if old != 0 {
        write_user(p, host, old, &p.action(sig).to_bytes())?;
    }
    if let Some(mut action) = new {
        action.mask &= !UNBLOCKABLE;
        p.sigactions[sig as usize - 1] = action;
        // A pending signal that is now ignored is discarded (POSIX).
        if action.ignores(sig) {
            p.pending &= !signal::bit(sig);
        }
    }
    Ok(0)
}

pub fn sigprocmask(
    c: &mut Ctx<'_, '_, impl Host>,
    how: u64,
    set: u64,
    old: u64,
    size: u64,
) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    if size != 8 {
        return Err(Errno::EINVAL);
    }
    let new = if set != 0 {
        let mut b = [0u8; 8];
        read_user(p, host, set, &mut b)?;
        let bits = u64::from_le_bytes(b);
        Some(match how {
            0 => p.sigmask | bits,
            1 => p.sigmask & !bits,
            2 => bits,
            _ => return Err(Errno::EINVAL),
        })
    } else {
        None
    };
    if old != 0 {
        write_user(p, host, old, &p.sigmask.to_le_bytes())?;
    }
    if let Some(mask) = new {
        p.sigmask = mask & !UNBLOCKABLE;
    }
    Ok(0)
}

pub fn sigpending(c: &mut Ctx<'_, '_, impl Host>, set: u64, size: u64) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    if size > 8 {
        return Err(Errno::EINVAL);
    }
    write_user(
        p,
        host,
        set,
        &(p.pending & p.sigmask).to_le_bytes()[..size as usize],
    )?;
    Ok(0)
}

/// `sigaltstack(new, old)` of a process whose stack pointer is `sp`.
pub fn sigaltstack(c: &mut Ctx<'_, '_, impl Host>, sp: u64, new: u64, old: u64) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    let on_it = p.alt_stack.contains(sp);
    let replacement = if new != 0 {
        let mut b = [0u8; 24];
        read_user(p, host, new, &mut b)?;
        let word = |at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap_or([0; 8]));
        let flags = u32::from_le_bytes(b[8..12].try_into().unwrap_or([0; 4]));
        if on_it {
            return Err(Errno::EPERM);
        }
        Some(if flags & signal::SS_DISABLE != 0 {
            AltStack::NONE
        } else if flags & !signal::SS_ONSTACK != 0 {
            return Err(Errno::EINVAL);
        } else if word(16) < signal::MIN_ALT_STACK {
            return Err(Errno::ENOMEM);
        } else {
            let (base, size) = (word(0), word(16));
            base.checked_add(size).ok_or(Errno::EINVAL)?;
            AltStack {
                base,
                size,
                flags: 0,
            }
        })
    } else {
        None
    };
    if old != 0 {
        write_user(p, host, old, &p.alt_stack.to_bytes(sp))?;
    }
    if let Some(stack) = replacement {
        p.alt_stack = stack;
    }
    Ok(0)
}

/// `rt_sigreturn`: the registers, mask and FPU state the frame below the stack pointer
/// saved; `None` when the frame is unreadable (the process then dies with SIGSEGV).
pub fn sigreturn(c: &mut Ctx<'_, '_, impl Host>) -> Option<()> {
    let (p, host, m) = (&mut *c.p, &mut *c.host, &mut *c.m);
    // The handler's `ret` popped the return address: the frame starts 8 bytes below.
    let frame = m.registers.rsp.checked_sub(8)?;
    let mut bytes = [0u8; FRAME_SIZE];
    read_user(p, host, frame, &mut bytes).ok()?;
    let restored = signal::restore(&bytes, &m.registers);
    if restored.fpu != 0 {
        let mut image = [0u8; FPU_SIZE];
        read_user(p, host, restored.fpu, &mut image).ok()?;
        host.set_fpu(&image).ok()?;
    }
    p.sigmask = restored.mask;
    m.registers = restored.registers;
    Some(())
}

/// A `struct timespec` at `address`, in ns (`EINVAL` for a negative or denormal one).
pub(crate) fn read_timespec(p: &Process, host: &mut impl Host, address: u64) -> SysResult<u64> {
    read_time(p, host, address, false)
}

/// A `struct timespec` (`micro`: a `struct timeval`) at `address`, in ns.
pub(crate) fn read_time(
    p: &Process,
    host: &mut impl Host,
    address: u64,
    micro: bool,
) -> SysResult<u64> {
    let mut b = [0u8; 16];
    read_user(p, host, address, &mut b)?;
    time_ns(&b, micro)
}

/// The ns of the 16 bytes of a `struct timespec` (`micro`: a `struct timeval`): `EINVAL`
/// for negative seconds or a fraction out of range.
fn time_ns(b: &[u8; 16], micro: bool) -> SysResult<u64> {
    let sec = i64::from_le_bytes(b[..8].try_into().unwrap_or([0; 8]));
    let frac = i64::from_le_bytes(b[8..].try_into().unwrap_or([0; 8]));
    let (limit, unit) = if micro {
        (1_000_000, 1000)
    } else {
        (NS_PER_S as i64, 1)
    };
    if sec < 0 || !(0..limit).contains(&frac) {
        return Err(Errno::EINVAL);
    }
    Ok((sec as u64)
        .saturating_mul(NS_PER_S)
        .saturating_add(frac as u64 * unit))
}

/// `nanosleep(req, rem)` and `clock_nanosleep(clock, flags, req, rem)`: the first time
/// served, records when the call ends and waits; served again, ends once that time came.
pub fn sleep(
    c: &mut Ctx<'_, '_, impl Host>,
    clock: u64,
    flags: u64,
    request: u64,
) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    let now = host.now_ns();
    if let Some(at) = p.wake_at {
        if now >= at {
            p.wake_at = None;
            return Ok(0);
        }
        return Err(WOULD_BLOCK);
    }
    // The guest has one clock (since it started): REALTIME, MONOTONIC, BOOTTIME and the
    // CPU-time clocks all read it.
    if clock > 7 || flags & !TIMER_ABSTIME != 0 {
        return Err(Errno::EINVAL);
    }
    let ns = read_timespec(p, host, request)?;
    let at = if flags & TIMER_ABSTIME != 0 && crate::syscall::is_realtime(clock) {
        // A wall-clock deadline, on the guest's clock.
        ns.saturating_sub(host.wall_clock_ns().saturating_sub(now))
    } else if flags & TIMER_ABSTIME != 0 {
        ns
    } else {
        now.saturating_add(ns)
    };
    if at <= now {
        return Ok(0);
    }
    p.wake_at = Some(at);
    Err(WOULD_BLOCK)
}

/// `alarm(seconds)`: the seconds left of the previous alarm (rounded up).
pub fn alarm(c: &mut Ctx<'_, '_, impl Host>, seconds: u64) -> u64 {
    let (p, _, host) = c.parts();
    let now = host.now_ns();
    let left = p
        .alarm_at
        .map_or(0, |at| at.saturating_sub(now).div_ceil(NS_PER_S));
    p.alarm_interval = 0;
    p.alarm_at = (seconds != 0).then(|| now.saturating_add(seconds.saturating_mul(NS_PER_S)));
    left
}

/// `struct itimerval` (interval, value) of the real-time timer.
fn itimer(p: &Process, now: u64) -> [u8; 32] {
    let left = p.alarm_at.map_or(0, |at| at.saturating_sub(now).max(1));
    let mut b = [0u8; 32];
    b[..16].copy_from_slice(&linux::timeval(p.alarm_interval));
    b[16..].copy_from_slice(&linux::timeval(left));
    b
}

pub fn getitimer(c: &mut Ctx<'_, '_, impl Host>, which: u64, value: u64) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    if which != ITIMER_REAL {
        return Err(Errno::EINVAL);
    }
    let now = host.now_ns();
    write_user(p, host, value, &itimer(p, now))?;
    Ok(0)
}

pub fn setitimer(c: &mut Ctx<'_, '_, impl Host>, which: u64, new: u64, old: u64) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    if which != ITIMER_REAL {
        return Err(Errno::EINVAL);
    }
    let now = host.now_ns();
    let mut b = [0u8; 32];
    if new != 0 {
        read_user(p, host, new, &mut b)?;
    }
    let timeval = |at: usize| time_ns(b[at..at + 16].try_into().unwrap_or(&[0; 16]), true);
    let (interval, value) = (timeval(0)?, timeval(16)?);
    if old != 0 {
        write_user(p, host, old, &itimer(p, now))?;
    }
    if new != 0 {
        p.alarm_interval = interval;
        p.alarm_at = (value != 0).then(|| now.saturating_add(value));
    }
    Ok(0)
}

/// Whether the alarm is due at `now`; then it is re-armed with its interval (or disarmed).
pub fn alarm_due(p: &mut Process, now: u64) -> bool {
    match p.alarm_at {
        Some(at) if at <= now => {
            p.alarm_at = (p.alarm_interval != 0).then(|| now.saturating_add(p.alarm_interval));
            true
        }
        _ => false,
    }
}

/// `rt_sigsuspend(mask)`: waits with `mask` until a signal is delivered; the old mask comes
/// back when the handler returns (the frame saves it).
pub fn sigsuspend(c: &mut Ctx<'_, '_, impl Host>, set: u64, size: u64) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    wait_with_mask(p, host, set, size)?;
    Err(WOULD_BLOCK)
}

/// Installs the mask at `set` (`size` bytes) that a waiting call (`rt_sigsuspend`, `ppoll`,
/// `pselect6`) waits with, saving the caller's for when the wait ends; once: the call is
/// served again while it waits.
pub(crate) fn wait_with_mask(
    p: &mut Process,
    host: &mut impl Host,
    set: u64,
    size: u64,
) -> SysResult<()> {
    if p.saved_mask.is_some() {
        return Ok(());
    }
    if size != 8 {
        return Err(Errno::EINVAL);
    }
    let mut b = [0u8; 8];
    read_user(p, host, set, &mut b)?;
    p.saved_mask = Some(p.sigmask);
    p.sigmask = u64::from_le_bytes(b) & !UNBLOCKABLE;
    Ok(())
}

/// Whether a waiting call continues after a handler with `SA_RESTART` (`signal(7)`: reads,
/// writes and waits do; sleeps, polls and the signal waits never do).
pub fn restartable(number: u64) -> bool {
    matches!(
        number,
        nr::read | nr::write | nr::readv | nr::writev | nr::wait4 | nr::waitid | nr::ioctl
    )
}

/// What the waiting call of message `m` returns when a signal interrupts it: `EINTR`
/// (`nanosleep` also stores the time left), or, when `restart`, the registers that make the
/// thread issue the same call again after the handler. Clears what the call was waiting
/// for.
pub fn interrupted(
    p: &mut Process,
    host: &mut impl Host,
    mut m: ExceptionMessage,
    restart: bool,
) -> ExceptionMessage {
    let r = &mut m.registers;
    let number = r.rax;
    let wake_at = p.wake_at.take();
    // A write that moved some bytes before it waited returns them, restart or not.
    let written = core::mem::take(&mut p.pipe_written);
    if number == nr::write && written > 0 {
        r.rax = written;
        r.rcx = r.rip;
        r.r11 = r.rflags;
        return m;
    }
    if restart && restartable(number) {
        // Back to the `syscall` instruction (2 bytes) with the call number in rax.
        r.rip = r.rip.wrapping_sub(2);
        return m;
    }
    let remaining = match (number, wake_at) {
        (nr::nanosleep, Some(at)) => Some((r.rsi, at)),
        (nr::clock_nanosleep, Some(at)) if r.rsi & TIMER_ABSTIME == 0 => Some((r.r10, at)),
        _ => None,
    };
    if let Some((rem, at)) = remaining
        && rem != 0
    {
        let left = at.saturating_sub(host.now_ns());
        let _ = write_user(p, host, rem, &linux::timespec(left));
    }
    r.rax = Errno::EINTR.result();
    r.rcx = r.rip;
    r.r11 = r.rflags;
    m
}
