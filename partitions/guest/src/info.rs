//! The calls that report on or set a process's identity and resources, where the guest
//! has one user (root), one CPU and no accounting: the user and group ids, `getrusage`,
//! `times`, the scheduling affinity and priority, and `futex` (one thread per process: a
//! wait can only end by its timeout or a signal, a wake finds nobody), plus `sysinfo`'s
//! record ([`sysinfo_record`]).

use crate::linux::{Errno, nr};
use crate::process::Process;
use crate::syscall::{Host, SysResult, WOULD_BLOCK, read_user, write_user};

/// Clock ticks per second (`sysconf(_SC_CLK_TCK)`, `times`).
const TICKS_PER_S: u64 = 100;
const FUTEX_WAIT: u64 = 0;
const FUTEX_WAKE: u64 = 1;
const FUTEX_WAIT_BITSET: u64 = 9;
const FUTEX_WAKE_BITSET: u64 = 10;
const FUTEX_PRIVATE: u64 = 128;
const FUTEX_CLOCK_REALTIME: u64 = 256;

/// Serves `number` if it is one of this module's calls.
pub fn call(
    p: &mut Process,
    host: &mut impl Host,
    number: u64,
    a: [u64; 6],
) -> Option<SysResult<u64>> {
    let only_root = |ids: &[u64]| {
        // -1 keeps an id; 0 is the only one there is.
        if ids
            .iter()
            .all(|&id| id as u32 == 0 || id as u32 == u32::MAX)
        {
            Ok(0)
        } else {
            Err(Errno::EPERM)
        }
    };
    Some(match number {
        nr::setuid | nr::setgid => only_root(&a[..1]),
        nr::setreuid | nr::setregid => only_root(&a[..2]),
        nr::setresuid | nr::setresgid => only_root(&a[..3]),
        nr::getresuid | nr::getresgid => (|| {
            for at in &a[..3] {
                write_user(p, host, *at, &0u32.to_le_bytes())?;
            }
            Ok(0)
        })(),
        // No supplementary groups; root may set (and so drop) them.
        nr::getgroups if (a[0] as i32) < 0 => Err(Errno::EINVAL),
        nr::getgroups => Ok(0),
        nr::setgroups if a[0] > 65536 => Err(Errno::EINVAL),
        nr::setgroups => Ok(0),
        nr::getrusage => match a[0] as i32 {
            // RUSAGE_SELF, RUSAGE_CHILDREN, RUSAGE_THREAD
            -1..=1 => write_user(p, host, a[1], &[0; 144]).map(|()| 0),
            _ => Err(Errno::EINVAL),
        },
        nr::times => {
            if a[0] != 0
                && let Err(e) = write_user(p, host, a[0], &[0; 32])
            {
                return Some(Err(e));
            }
            Ok(host.now_ns() / (1_000_000_000 / TICKS_PER_S))
        }
        nr::sched_getaffinity => match a[1] {
            len if len < 8 || len % 8 != 0 => Err(Errno::EINVAL),
            _ => write_user(p, host, a[2], &1u64.to_le_bytes()).map(|()| 8),
        },
        nr::sched_setaffinity => {
            let mut mask = [0u8; 8];
            match a[1] {
                len if len < 8 => Err(Errno::EINVAL),
                _ => read_user(p, host, a[2], &mut mask).and_then(|()| {
                    if u64::from_le_bytes(mask) & 1 == 0 {
                        Err(Errno::EINVAL)
                    } else {
                        Ok(0)
                    }
                }),
            }
        }
        // Nice 0 for everyone (the raw call returns 20 - nice); only root sets it, and
        // the guest schedules its processes alike anyway.
        nr::getpriority if a[0] > 2 => Err(Errno::EINVAL),
        nr::getpriority => Ok(20),
        nr::setpriority if a[0] > 2 => Err(Errno::EINVAL),
        nr::setpriority => Ok(0),
        nr::futex => futex(p, host, a),
        _ => return None,
    })
}

fn futex(p: &mut Process, host: &mut impl Host, a: [u64; 6]) -> SysResult<u64> {
    let op = a[1] & !(FUTEX_PRIVATE | FUTEX_CLOCK_REALTIME);
    match op {
        FUTEX_WAKE | FUTEX_WAKE_BITSET => Ok(0),
        FUTEX_WAIT | FUTEX_WAIT_BITSET => {
            if p.wake_at.is_none() {
                let mut word = [0u8; 4];
                read_user(p, host, a[0], &mut word)?;
                if u32::from_le_bytes(word) != a[2] as u32 {
                    return Err(Errno::EAGAIN);
                }
                if a[3] == 0 {
                    return Err(WOULD_BLOCK); // until a signal
                }
                let ns = crate::sigcalls::read_timespec(p, host, a[3])?;
                // FUTEX_WAIT's timeout is relative, the bitset form's absolute.
                let now = host.now_ns();
                p.wake_at = Some(if op == FUTEX_WAIT {
                    now.saturating_add(ns)
                } else {
                    ns
                });
            }
            if p.wake_at.is_some_and(|at| host.now_ns() >= at) {
                p.wake_at = None;
                return Err(Errno::ETIMEDOUT);
            }
            Err(WOULD_BLOCK)
        }
        _ => Err(Errno::ENOSYS),
    }
}

/// `struct sysinfo` for a guest up `uptime_ns`, with `total`/`free` bytes of memory and
/// `processes` processes.
pub fn sysinfo_record(uptime_ns: u64, total: u64, free: u64, processes: u16) -> [u8; 112] {
    let mut b = [0u8; 112];
    b[0..8].copy_from_slice(&(uptime_ns / 1_000_000_000).to_le_bytes());
    // loads[3] at 8..32 stay 0.
    b[32..40].copy_from_slice(&total.to_le_bytes());
    b[40..48].copy_from_slice(&free.to_le_bytes());
    b[80..82].copy_from_slice(&processes.to_le_bytes());
    b[104..108].copy_from_slice(&1u32.to_le_bytes()); // mem_unit
    b
}
