//! A process's threads (`clone(CLONE_THREAD)`), their ends, the signals sent to one thread
//! and `futex`.
//!
//! **Threads.** Each Linux thread is a slot of the process table of its own (its thread id
//! is its slot's `pid`, its process's pid its `tgid`) and a kernel thread in its process's
//! task ([`Tasks::borrow`], as a vfork child's): the guest's scheduler sees every thread.
//! What the threads of a process share (memory areas, descriptors, dispositions, ...:
//! [`Process::swap_shared`]) stays in the slot of its first thread and is lent to another
//! thread's slot while one of that thread's calls is served ([`System::lend`]), so every
//! call reads and changes the one state of the process; the threads keep copies of what
//! others ask about them ([`Process::share_from`]). A thread's `exit` ends it alone
//! (clearing its `CLONE_CHILD_CLEARTID` word and waking its waiter, marking the robust
//! futexes it held `FUTEX_OWNER_DIED`); `exit_group`, a fatal signal or `execve` end the
//! other threads too.
//!
//! **Futex.** A wait is a blocked call ([`crate::process::FutexWait`]) served again after
//! each event: it returns when a wake chose it, when its timeout passed (`ETIMEDOUT`) or
//! when a signal interrupts it (`EINTR`). Wakes, requeues and waits match by address among
//! the threads of the caller's process (private and shared futexes alike: processes share
//! no writable memory in the guest).

use super::*;
use crate::process::FutexWait;

const CLONE_FS: u64 = 0x200;
const CLONE_FILES: u64 = 0x400;
const CLONE_SIGHAND: u64 = 0x800;
const CLONE_THREAD: u64 = 0x1_0000;
const CLONE_SYSVSEM: u64 = 0x4_0000;
const CLONE_SETTLS: u64 = 0x8_0000;
/// Ignored by Linux since 2.6.
const CLONE_DETACHED: u64 = 0x40_0000;
/// What a thread shares with its process, in every `clone` that makes one: the guest has
/// no other way to share.
const THREAD_SHARES: u64 = CLONE_VM | CLONE_FS | CLONE_FILES | CLONE_SIGHAND | CLONE_THREAD;

const FUTEX_WAIT: u64 = 0;
const FUTEX_WAKE: u64 = 1;
const FUTEX_REQUEUE: u64 = 3;
const FUTEX_CMP_REQUEUE: u64 = 4;
const FUTEX_WAIT_BITSET: u64 = 9;
const FUTEX_WAKE_BITSET: u64 = 10;
const FUTEX_PRIVATE: u64 = 128;
const FUTEX_CLOCK_REALTIME: u64 = 256;
/// A robust futex word: its owner's thread id, and whether others wait.
const FUTEX_TID_MASK: u32 = 0x3fff_ffff;
const FUTEX_WAITERS: u32 = 0x8000_0000;
const FUTEX_OWNER_DIED: u32 = 0x4000_0000;
/// Most entries of a robust list walked at a thread's end (Linux's `ROBUST_LIST_LIMIT`).
const ROBUST_LIST_LIMIT: usize = 2048;

/// Whether `clone` flags ask for a thread.
pub(super) fn is_thread_clone(flags: u64) -> bool {
    flags & CLONE_THREAD != 0
}

impl System {
    /// Lends the shared state of the process of slot `i` to it, if it is a thread other
    /// than the first, while one of its calls is served ([`System::give_back`] ends it).
    pub(super) fn lend(&mut self, i: usize) {
        self.give_back();
        let Some(tgid) = self.slots[i]
            .as_ref()
            .filter(|s| s.process.is_thread())
            .map(|s| s.process.tgid)
        else {
            return;
        };
        if let Some(first) = self.index(tgid) {
            self.swap_shared(first, i);
            self.lent = Some((first, i));
        }
    }

    /// Gives the lent state back to the process's first thread and updates its threads'
    /// copies (after any call, which may have changed dispositions or the process group).
    pub(super) fn give_back(&mut self) {
        if let Some((first, i)) = self.lent.take() {
            self.swap_shared(first, i);
        }
    }

    /// Updates the copies the threads of process `tgid` keep of its state.
    pub(super) fn share_group(&mut self, tgid: u32) {
        let Some(first) = self.index(tgid) else {
            return;
        };
        let (before, rest) = self.slots.split_at_mut(first);
        let Some((Some(leader), after)) = rest.split_first_mut() else {
            return;
        };
        for s in before.iter_mut().chain(after).flatten() {
            if s.process.tgid == tgid && s.process.is_thread() {
                s.process.share_from(&leader.process);
            }
        }
    }

    fn swap_shared(&mut self, a: usize, b: usize) {
        if a == b {
            return;
        }
        let (low, high) = (a.min(b), a.max(b));
        let (left, right) = self.slots.split_at_mut(high);
        if let (Some(x), Some(y)) = (left[low].as_mut(), right[0].as_mut()) {
            x.process.swap_shared(&mut y.process);
        }
    }

    /// `clone(CLONE_THREAD | ...)` by the thread in slot `i` (its process's state lent):
    /// a new thread of its process, starting with `registers` as the call returns
    /// (`rax` 0) on `stack`, with the TLS base `tls` when `CLONE_SETTLS` asks.
    pub(super) fn spawn_thread(
        &mut self,
        i: usize,
        k: &mut impl Tasks,
        flags: u64,
        [stack, parent_tid, child_tid, tls]: [u64; 4],
        registers: &Registers,
    ) -> SysResult<u64> {
        const KNOWN: u64 = THREAD_SHARES
            | CLONE_SYSVSEM
            | CLONE_SETTLS
            | CLONE_PARENT_SETTID
            | CLONE_CHILD_CLEARTID
            | CLONE_CHILD_SETTID
            | CLONE_DETACHED;
        if flags & !KNOWN != 0 || flags & THREAD_SHARES != THREAD_SHARES {
            return Err(Errno::EINVAL);
        }
        let free = self.free_slot()?;
        let mut tid = self.next_pid;
        while self.index(tid).is_some() || tid == 0 {
            tid = next_pid(tid);
        }
        let cpu = self.place_new(i, k);
        let caller = &self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process;
        let mut thread = caller.thread(tid);
        thread.cpu = cpu;
        if flags & CLONE_CHILD_CLEARTID != 0 {
            thread.clear_child_tid = child_tid;
        }
        k.borrow(tid, caller.pid, cpu)?;
        // The thread runs in the caller's memory: both tid words are written there.
        for (flag, at) in [
            (CLONE_PARENT_SETTID, parent_tid),
            (CLONE_CHILD_SETTID, child_tid),
        ] {
            if flags & flag != 0 {
                let _ = syscall::write_user(caller, k, at, &tid.to_le_bytes());
            }
        }
        let mut start = *registers;
        start.rax = 0;
        start.rcx = registers.rip;
        start.r11 = registers.rflags;
        if stack != 0 {
            start.rsp = stack;
        }
        if flags & CLONE_SETTLS != 0 {
            start.fs_base = tls;
        }
        self.slots[free] = Some(Slot {
            process: thread,
            state: State::Starting(start),
            stopped: false,
            report: None,
            waited: false,
        });
        self.next_pid = next_pid(tid);
        Ok(tid as u64)
    }

    /// `exit` of the thread in slot `i` (its process's state lent): its
    /// `CLONE_CHILD_CLEARTID` word becomes 0 and one waiter on it wakes (`pthread_join`),
    /// the robust futexes it holds are marked, and its slot and kernel thread go.
    pub(super) fn exit_thread(&mut self, i: usize, k: &mut impl Tasks) {
        let Some(slot) = self.slots[i].as_ref() else {
            return;
        };
        let p = &slot.process;
        let (tid, tgid) = (p.pid, p.tgid);
        k.select(tid);
        let mut wakes = [0u64; 1 + ROBUST_WAKES];
        let mut n = 0;
        if p.clear_child_tid != 0
            && syscall::write_user(p, k, p.clear_child_tid, &0u32.to_le_bytes()).is_ok()
        {
            wakes[n] = p.clear_child_tid;
            n += 1;
        }
        n += robust_list_release(p, k, &mut wakes[n..]);
        self.give_back();
        for &address in &wakes[..n] {
            self.futex_wake(tgid, address, u32::MAX, 1);
        }
        k.release(tid);
        self.slots[i] = None;
    }

    /// Ends the threads of process `tgid` other than its first (it ends, or executes).
    pub(super) fn end_threads(&mut self, tgid: u32, k: &mut impl Tasks) {
        // Its state goes back to its first thread if one of its threads had it.
        if let Some((first, _)) = self.lent
            && self.slots[first]
                .as_ref()
                .is_some_and(|s| s.process.pid == tgid)
        {
            self.give_back();
        }
        for j in 0..self.slots.len() {
            let thread = self.slots[j]
                .as_ref()
                .is_some_and(|s| s.process.tgid == tgid && s.process.is_thread());
            if thread && let Some(s) = self.slots[j].take() {
                k.release(s.process.pid);
            }
        }
    }

    /// `tkill(tid, sig)` / `tgkill(tgid, tid, sig)` by the thread in slot `i`.
    pub(super) fn kill_thread(
        &mut self,
        i: usize,
        fs: &mut Fs,
        k: &mut impl Tasks,
        (tgid, tid): (Option<u32>, u32),
        sig: u64,
    ) -> SysResult<u64> {
        if sig > signal::NSIG as u64 {
            return Err(Errno::EINVAL);
        }
        let me = self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process.tgid;
        let j = self
            .index(tid)
            .filter(|&j| {
                self.slots[j].as_ref().is_some_and(|s| {
                    !matches!(s.state, State::Zombie(_)) && tgid.is_none_or(|g| s.process.tgid == g)
                })
            })
            .ok_or(Errno::ESRCH)?;
        if sig == 0 {
            return Ok(0);
        }
        let mut info = Info::user(sig as u32, me);
        info.code = signal::SI_TKILL;
        if let Some(ended) = self.send(j, Some(i), info, fs, k) {
            self.ended = Some(ended);
        }
        Ok(0)
    }

    /// The thread of process slot `j` a process-directed `sig` goes to: the first thread
    /// that does not block it, else the process's first thread (as Linux picks one).
    pub(super) fn receiver(&self, j: usize, sig: u32) -> usize {
        let Some(first) = self.slots[j].as_ref().map(|s| &s.process) else {
            return j;
        };
        let blocks = |p: &Process| p.sigmask & signal::bit(sig) & !signal::UNBLOCKABLE != 0;
        if !blocks(first) {
            return j;
        }
        (0..self.slots.len())
            .find(|&t| {
                self.slots[t].as_ref().is_some_and(|s| {
                    s.process.tgid == first.pid
                        && s.process.is_thread()
                        && !matches!(s.state, State::Zombie(_))
                        && !blocks(&s.process)
                })
            })
            .unwrap_or(j)
    }

    /// `futex(address, op, value, timeout or value2, address2, value3)` of the thread in
    /// slot `i`: `Ok(None)` when it waits.
    pub(super) fn futex(
        &mut self,
        i: usize,
        k: &mut impl Tasks,
        [address, op, value, timeout, address2, value3]: [u64; 6],
    ) -> SysResult<Option<u64>> {
        let command = op & !(FUTEX_PRIVATE | FUTEX_CLOCK_REALTIME);
        let p = &mut self.slots[i].as_mut().ok_or(Errno::ESRCH)?.process;
        let tgid = p.tgid;
        let bitset = match command {
            FUTEX_WAIT_BITSET | FUTEX_WAKE_BITSET => value3 as u32,
            _ => u32::MAX,
        };
        if bitset == 0 || address % 4 != 0 {
            return Err(Errno::EINVAL);
        }
        let word = |p: &Process, k: &mut dyn FnMut(&Process, &mut [u8]) -> SysResult<()>| {
            let mut bytes = [0u8; 4];
            k(p, &mut bytes).map(|()| u32::from_le_bytes(bytes))
        };
        match command {
            FUTEX_WAIT | FUTEX_WAIT_BITSET => {
                if let Some(wait) = p.futex {
                    // Served again: woken, timed out, or still waiting.
                    let now = k.now_ns();
                    if wait.woken {
                        (p.futex, p.wake_at) = (None, None);
                        return Ok(Some(0));
                    }
                    if p.wake_at.is_some_and(|at| now >= at) {
                        (p.futex, p.wake_at) = (None, None);
                        return Err(Errno::ETIMEDOUT);
                    }
                    return Ok(None);
                }
                let current = word(p, &mut |p, b| syscall::read_user(p, k, address, b))?;
                if current != value as u32 {
                    return Err(Errno::EAGAIN);
                }
                p.wake_at = if timeout == 0 {
                    None
                } else {
                    let ns = crate::sigcalls::read_timespec(p, k, timeout)?;
                    let now = k.now_ns();
                    Some(match command {
                        // FUTEX_WAIT's timeout is relative, the bitset form's absolute.
                        FUTEX_WAIT => now.saturating_add(ns),
                        _ if op & FUTEX_CLOCK_REALTIME != 0 => {
                            let wall = k.wall_clock_ns();
                            ns.saturating_sub(wall.saturating_sub(now))
                        }
                        _ => ns,
                    })
                };
                p.futex = Some(FutexWait {
                    address,
                    bitset,
                    woken: false,
                });
                Ok(None)
            }
            FUTEX_WAKE | FUTEX_WAKE_BITSET => {
                Ok(Some(self.futex_wake(tgid, address, bitset, value as u32)))
            }
            FUTEX_REQUEUE | FUTEX_CMP_REQUEUE => {
                if command == FUTEX_CMP_REQUEUE {
                    let current = word(p, &mut |p, b| syscall::read_user(p, k, address, b))?;
                    if current != value3 as u32 {
                        return Err(Errno::EAGAIN);
                    }
                }
                if address2 % 4 != 0 {
                    return Err(Errno::EINVAL);
                }
                let woken = self.futex_wake(tgid, address, u32::MAX, value as u32);
                let mut moved = 0;
                for s in self.slots.iter_mut().flatten() {
                    if moved >= timeout as u32 {
                        break;
                    }
                    if s.process.tgid == tgid
                        && let Some(w) = s.process.futex.as_mut()
                        && w.address == address
                        && !w.woken
                    {
                        w.address = address2;
                        moved += 1;
                    }
                }
                Ok(Some(woken + moved as u64))
            }
            _ => Err(Errno::ENOSYS),
        }
    }

    /// Wakes at most `count` threads of process `tgid` waiting on `address` with a bitset
    /// meeting `bitset`; returns how many.
    fn futex_wake(&mut self, tgid: u32, address: u64, bitset: u32, count: u32) -> u64 {
        let mut woken = 0;
        for s in self.slots.iter_mut().flatten() {
            if woken >= count.min(i32::MAX as u32) {
                break;
            }
            if s.process.tgid == tgid
                && matches!(s.state, State::Blocked(_))
                && let Some(w) = s.process.futex.as_mut()
                && w.address == address
                && w.bitset & bitset != 0
                && !w.woken
            {
                w.woken = true;
                woken += 1;
            }
        }
        woken as u64
    }
}

/// Most robust futexes an ending thread's waiters are woken for (more are still marked).
const ROBUST_WAKES: usize = 16;

/// Marks the futexes on the robust list of thread `p` (`set_robust_list`) it still owns
/// `FUTEX_OWNER_DIED`, as Linux does when a thread ends; writes into `wakes` the
/// addresses of those with waiters and returns how many.
fn robust_list_release(p: &Process, k: &mut impl Tasks, wakes: &mut [u64]) -> usize {
    let head = p.robust_list;
    if head == 0 {
        return 0;
    }
    // struct robust_list_head { next, futex_offset, list_op_pending }.
    let (Ok(first), Ok(offset), Ok(pending)) = (
        syscall::read_u64(p, k, head),
        syscall::read_u64(p, k, head + 8),
        syscall::read_u64(p, k, head + 16),
    ) else {
        return 0;
    };
    let mut n = 0;
    let mut release = |k: &mut _, entry: u64| {
        let address = entry.wrapping_add(offset);
        let mut b = [0u8; 4];
        if syscall::read_user(p, k, address, &mut b).is_err() {
            return;
        }
        let word = u32::from_le_bytes(b);
        if word & FUTEX_TID_MASK != p.pid {
            return;
        }
        let marked = (word & FUTEX_WAITERS) | FUTEX_OWNER_DIED;
        if syscall::write_user(p, k, address, &marked.to_le_bytes()).is_ok()
            && word & FUTEX_WAITERS != 0
            && n < wakes.len()
        {
            wakes[n] = address;
            n += 1;
        }
    };
    let mut entry = first;
    let mut walked = 0;
    while entry != head && entry != 0 && walked < ROBUST_LIST_LIMIT {
        // The next entry first: once released, another thread may reuse this one.
        let next = syscall::read_u64(p, k, entry);
        if entry != pending {
            release(k, entry);
        }
        walked += 1;
        match next {
            Ok(next) => entry = next,
            Err(_) => break,
        }
    }
    if pending != 0 {
        release(k, pending);
    }
    n
}
