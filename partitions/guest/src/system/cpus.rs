//! Where each Linux thread runs when the guest has several CPUs, and `sched_setaffinity`
//! (`sched_getaffinity` and `getcpu` only read [`Process::affinity`] and
//! [`Process::cpu`]: [`crate::syscall`]).
//!
//! **Placement.** Every thread has a CPU of the guest's ([`Host::cpus`]) and of its
//! affinity ([`Process::affinity`]). A new one (`fork`, `vfork`, `clone` of a process or a
//! thread) goes to the allowed CPU with the fewest runnable threads (running or ready:
//! not waiting in a call, not stopped, not a zombie), not counting its creator, and of
//! equals to its creator's CPU ([`crate::sched::place`]); `execve` keeps it. Not counting
//! the creator is what a parent that then waits needs: `xargs -P2 gzip` puts the first
//! gzip on its own CPU and the second on the other while it waits, and a shell's
//! `a & b &` runs `a` and `b` side by side; a parent that goes on running loses nothing
//! either, its child joins the least loaded CPU. Ties stay on the creator's CPU so that a
//! guest with one busy CPU and an idle one fills the idle one only when the busy one has
//! more than the newcomer.
//!
//! **Rebalancing.** A thread whose call waited (a pipe, a sleep, `wait4`, a futex, a
//! vfork parent) is placed again by the same rule (of equals, its own CPU) when it is
//! answered, before its reply: it does not run then, so the kernel can move it, and a
//! wake-up is when load changes. Without it, two threads placed while the others slept
//! could share a CPU for ever beside an idle one (each spinner placed on CPU 1 because
//! CPU 2's thread was runnable then, which later ended). A thread that never waits (a
//! pure spinner) is never moved: the guest could only move it by interrupting it, and
//! moving running threads to even out a 2-against-1 split would only trade which one has
//! a CPU to itself. A one-CPU guest has no choice to make and skips all of it.

use super::*;
use crate::sched::{Load, MAX_CPUS, place};

/// Bytes of Linux's CPU mask on x86-64 with up to 64 CPUs (`cpumask_size()`): what
/// `sched_getaffinity` writes and its `len` must reach.
pub const CPUMASK_SIZE: usize = 8;

/// Whether CPU mask `mask` has `cpu`.
fn allows(mask: u64, cpu: u32) -> bool {
    mask.checked_shr(cpu).is_some_and(|m| m & 1 != 0)
}

impl System {
    /// The runnable threads on each CPU but the one in slot `except`.
    fn load(&self, except: usize) -> Load {
        let mut load: Load = [0; MAX_CPUS];
        for (j, slot) in self.slots.iter().enumerate() {
            let Some(s) = slot.as_ref().filter(|_| j != except) else {
                continue;
            };
            let runnable = matches!(s.state, State::Running | State::Starting(_)) && !s.stopped;
            if runnable && let Some(n) = load.get_mut(s.process.cpu as usize) {
                *n += 1;
            }
        }
        load
    }

    /// The CPU of a thread or process that the thread in slot `i` creates now.
    pub(super) fn place_new(&self, i: usize, k: &mut impl Host) -> u32 {
        let Some(creator) = self.slots[i].as_ref().map(|s| &s.process) else {
            return k.cpus().trailing_zeros();
        };
        let allowed = creator.affinity & k.cpus();
        if allowed.count_ones() <= 1 {
            return if allowed == 0 {
                creator.cpu
            } else {
                allowed.trailing_zeros()
            };
        }
        place(allowed, creator.cpu, &self.load(i))
    }

    /// The thread in slot `i` is answered: after a wait, it may move to a CPU with fewer
    /// runnable threads (see the module's doc).
    pub(super) fn rebalance(&mut self, i: usize, k: &mut impl Tasks) {
        let Some(slot) = self.slots[i].as_mut() else {
            return;
        };
        if !core::mem::take(&mut slot.waited) {
            return;
        }
        let allowed = slot.process.affinity & k.cpus();
        if allowed.count_ones() <= 1 && allows(allowed, slot.process.cpu) {
            return;
        }
        let cpu = place(allowed, slot.process.cpu, &self.load(i));
        self.move_to(i, cpu, k);
    }

    /// Puts the thread in slot `i` on `cpu`.
    fn move_to(&mut self, i: usize, cpu: u32, k: &mut impl Tasks) {
        let Some(slot) = self.slots[i].as_mut() else {
            return;
        };
        if slot.process.cpu == cpu {
            return;
        }
        slot.process.cpu = cpu;
        if !matches!(slot.state, State::Zombie(_)) {
            k.set_cpu(slot.process.pid, cpu);
        }
    }

    /// `sched_setaffinity(pid, len, mask)` of the thread in slot `i`, as Linux: `pid` 0
    /// is the caller, any other a thread id (`ESRCH` without one); reads `len` bytes (a
    /// shorter mask's other CPUs are not allowed, a longer one's excess is ignored), keeps
    /// what the guest has of it (`EINVAL` for none of its CPUs) and moves the thread if
    /// its CPU is no longer allowed. (`sched_getaffinity` reads the masks:
    /// [`crate::syscall`].)
    pub(super) fn set_affinity(
        &mut self,
        i: usize,
        k: &mut impl Tasks,
        pid: u64,
        len: u64,
        mask: u64,
    ) -> SysResult<u64> {
        let caller = &self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process;
        let mut bytes = [0u8; CPUMASK_SIZE];
        let n = usize::try_from(len)
            .unwrap_or(CPUMASK_SIZE)
            .min(CPUMASK_SIZE);
        syscall::read_user(caller, k, mask, &mut bytes[..n])?;
        let j = match pid as i32 {
            0 => i,
            tid if tid < 0 => return Err(Errno::ESRCH),
            tid => self.index(tid as u32).ok_or(Errno::ESRCH)?,
        };
        let allowed = u64::from_le_bytes(bytes) & k.cpus();
        if allowed == 0 {
            return Err(Errno::EINVAL);
        }
        let target = &mut self.slots[j].as_mut().ok_or(Errno::ESRCH)?.process;
        target.affinity = allowed;
        if !allows(allowed, target.cpu) {
            let cpu = place(allowed, target.cpu, &self.load(j));
            self.move_to(j, cpu, k);
        }
        Ok(0)
    }
}
