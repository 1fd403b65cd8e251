//! The calls that report on or set a process's identity and resources, where the guest
//! has one user (root) and no accounting: the user and group ids, `getrusage`, `times`,
//! the scheduling priority, plus `sysinfo`'s record ([`sysinfo_record`]). `futex` and the
//! scheduling affinity are the process table's ([`crate::system`]).

use crate::linux::Errno;
use crate::syscall::table::Ctx;
use crate::syscall::{Host, SysResult, read_user, write_user};

/// Clock ticks per second (`sysconf(_SC_CLK_TCK)`, `times`).
pub(crate) const TICKS_PER_S: u64 = 100;
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

/// `prlimit64` of the process itself, `getrlimit`, `setrlimit`: sets the limit of `resource`
/// from `new` and reports the old one at `old` (each when not 0).
pub(crate) fn rlimit(
    c: &mut Ctx<'_, '_, impl Host>,
    resource: u64,
    new: u64,
    old: u64,
) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    let index = usize::try_from(resource)
        .ok()
        .filter(|&r| r < crate::process::LIMITS)
        .ok_or(Errno::EINVAL)?;
    let replacement = if new != 0 {
        let mut b = [0u8; 16];
        read_user(p, host, new, &mut b)?;
        let soft = u64::from_le_bytes(b[..8].try_into().unwrap_or([0; 8]));
        let hard = u64::from_le_bytes(b[8..].try_into().unwrap_or([0; 8]));
        if soft > hard {
            return Err(Errno::EINVAL);
        }
        // Root may raise a hard limit, but not beyond what the guest has (descriptors,
        // the stack's fixed size).
        let ceiling = crate::process::ceiling(index);
        if hard > ceiling {
            return Err(Errno::EPERM);
        }
        Some(crate::process::Limit { soft, hard })
    } else {
        None
    };
    if old != 0 {
        let limit = p.limits[index];
        let mut b = [0u8; 16];
        b[..8].copy_from_slice(&limit.soft.to_le_bytes());
        b[8..].copy_from_slice(&limit.hard.to_le_bytes());
        write_user(p, host, old, &b)?;
    }
    if let Some(limit) = replacement {
        p.limits[index] = limit;
    }
    Ok(0)
}
