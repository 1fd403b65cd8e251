//! The guest's processes together: the process table (pids, parents, zombies), the calls
//! that act on more than one process (`clone`/`fork`/`vfork`, `execve`, `wait4`, the end
//! of a process) and the deferred replies.
//!
//! **Deferred replies.** A process's system call arrives as an exception message its
//! thread sent as a `call`: the thread waits until the guest replies, and the guest may
//! reply at any later time. A call that has to wait (`wait4` for a running child, `read`
//! from an empty pipe, `write` to a full one) changes nothing and leaves the process
//! [`State::Blocked`] with its message kept; after every message the guest serves (and
//! when console input arrives: [`System::retry_blocked`]), it serves the kept messages
//! again, in table order, until none makes progress, and replies to each call that
//! completes. So a waiting process never stops the guest from serving the others, and the
//! order of events decides nothing but who runs first. Not after a message that changed
//! only its sender, which runs on (a page fault; a call of
//! [`crate::syscall::table::CALLER_ONLY`]: `getpid`, `mmap`, `rt_sigaction`, `stat`, ...):
//! that ends nobody's wait. And only some after a change of the network's sockets alone
//! ([`Woken::Sockets`]: frames came, a timer of the stack alone was due, or a call on
//! one socket whose caller runs on or waits): the calls waiting on those sockets, and
//! those that may watch any socket (`poll`, `select`, ...), not a `wait4`, a pipe's
//! `read` or an `accept` of a socket nothing happened to ([`crate::syscall::waits_on`]).
//!
//! **Fork.** The child is a new task sharing the parent's pages copy-on-write (the
//! partition program maps them; [`Tasks::fork`]) and a thread started at address 0:
//! its first exception message (the fetch fault) is answered with the parent's registers
//! and `rax = 0`, the child's half of the `fork`. `vfork` and `clone(CLONE_VM |
//! CLONE_VFORK)` make the child a thread in the parent's task instead ([`Tasks::borrow`]):
//! it runs in its parent's memory, as on Linux, until it executes (then it gets a task of
//! its own, [`Tasks::own`]) or ends; the parent waits meanwhile ([`State::Vforked`]).
//!
//! A parent that ignores `SIGCHLD` (or set `SA_NOCLDWAIT`) leaves no zombies: its
//! children are reaped when they end, and its `wait4` waits until none is left (`ECHILD`).
//!
//! **Threads** of a process are slots of their own ([`threads`]).
//!
//! **CPUs.** Each thread runs on one of the guest's CPUs: placed when it is created, moved
//! when its affinity no longer allows it and perhaps when it wakes ([`cpus`]: the rule and
//! why).
//!
//! **Limits.** At most [`MAX_PROCESSES`] processes and threads, zombies included, and at most as many
//! as the partition's task quota (`kernel_tasks` minus the guest's own task) and thread quota
//! (`kernel_threads`) let it create: beyond either, `fork` and `clone` fail with `EAGAIN`. The
//! table grows as they come (on the heap), so a guest pays for the processes it runs.

use crate::events::Events;
use crate::exec::{self, ARG_MAX, ExecError};
use crate::linux::Errno;
use crate::memory::{Areas, PAGE};
use crate::net::Net;
use crate::pipe::Pipes;
use crate::process::Process;
use crate::sigcalls;
use crate::signal::{self, Action, Default, Info, SIGCHLD, SIGSEGV};
use crate::stack::MAX_STRINGS;
use crate::syscall::{self, Host, Outcome, ProcessCall, SysResult, close_files, share_files};
use crate::vfs::Fs;
use crate::vfs::proc::{ProcInfo, ProcessTable};
use abi::ipc::{ExceptionMessage, Registers};
use alloc::vec::Vec;

mod cpus;
mod threads;

pub use cpus::CPUMASK_SIZE;

/// Most processes and threads of a guest (the configuration's quotas may allow fewer).
pub const MAX_PROCESSES: usize = 64;
/// The pid of the first process; orphans become its children.
pub const INIT_PID: u32 = 1;
/// Pids are below this (Linux's default `pid_max`); then they start again above init's.
/// The guest's frame bookkeeping keys pages by pid in 16 bits ([`crate::frames`]).
pub const PID_MAX: u32 = 32768;

/// The pid after `pid`.
fn next_pid(pid: u32) -> u32 {
    if pid + 1 >= PID_MAX {
        INIT_PID + 1
    } else {
        pid + 1
    }
}

pub(crate) const CLONE_VM: u64 = 0x100;
pub(crate) const CLONE_VFORK: u64 = 0x4000;
const CLONE_PARENT_SETTID: u64 = 0x10_0000;
const CLONE_CHILD_CLEARTID: u64 = 0x20_0000;
const CLONE_CHILD_SETTID: u64 = 0x100_0000;
const WNOHANG: u64 = 1;
const WUNTRACED: u64 = 2;
const WEXITED: u64 = 4;
const WCONTINUED: u64 = 8;
const WNOWAIT: u64 = 0x0100_0000;
/// `__WNOTHREAD`, `__WALL`, `__WCLONE`: accepted; every thread of a process waits for
/// its children, and no child ends with another signal than `SIGCHLD`.
const WTHREAD_FLAGS: u64 = 0xe000_0000;
/// Bytes of `struct rusage` (`wait4` fills it with zeros: no accounting yet).
const RUSAGE_SIZE: usize = 144;

/// What the partition program does for the process table, beyond [`Host`] (whose memory
/// calls act on the process [`Tasks::select`] chose last).
pub trait Tasks: Host {
    /// Makes `pid` the process the memory calls of [`Host`] act on.
    fn select(&mut self, pid: u32);
    /// Creates process `child`: a task with the selected process's memory, shared
    /// copy-on-write (each page it has backed, with the rights of its area in `areas`,
    /// read-only in both until one of them writes it: [`crate::frames`]) and a thread that
    /// starts at address 0 with this guest as its exception handler. Returns how many pages
    /// it shares; `EAGAIN` when no task or thread can be created, `ENOMEM` when the guest
    /// is out of memory for its bookkeeping (then nothing of the child is left).
    /// Its thread runs on CPU `cpu` (one of [`Host::cpus`]) from its start.
    fn fork(&mut self, child: u32, areas: &Areas, cpu: u32) -> Result<u64, Errno>;
    /// Creates process `child` of a `vfork`: a thread in the selected process's task
    /// (`parent`'s), starting at address 0 like a forked child's, so the child runs in its
    /// parent's memory until it executes or ends, as Linux's vfork child does; also a
    /// thread of `clone(CLONE_THREAD)`. It runs on CPU `cpu` from its start.
    fn borrow(&mut self, child: u32, parent: u32, cpu: u32) -> Result<(), Errno>;
    /// Gives process `pid`, if it runs in its parent's memory (a vfork child), a task and
    /// memory of its own and a new thread that starts at address 0 on CPU `cpu` (its old
    /// thread is gone): `Ok(true)`; `Ok(false)` for a process that has them already.
    fn own(&mut self, pid: u32, cpu: u32) -> Result<bool, Errno>;
    /// Moves `pid`'s thread to CPU `cpu` (one of [`Host::cpus`]). Asked while the thread
    /// waits for the guest (its message is being served, or its call waits); for a
    /// thread that may be running on another CPU (`sched_setaffinity` of another thread)
    /// the host moves it at its next message.
    fn set_cpu(&mut self, pid: u32, cpu: u32);
    /// Ends process `pid`: its task (a vfork child's thread), its memory and its pending
    /// console output.
    fn release(&mut self, pid: u32);
    /// Replies to the waiting exception message of `pid`'s thread: it resumes with the
    /// registers of `m`.
    fn resume(&mut self, pid: u32, m: &ExceptionMessage);
    /// Suspends (`stop`) or resumes `pid`'s thread (`SIGSTOP`, `SIGCONT`).
    fn suspend(&mut self, pid: u32, stop: bool);
    /// Makes `pid`'s thread, if it is running user code, send an exception message now
    /// (vector `VECTOR_INTERRUPT`), so a caught signal is delivered without waiting for
    /// its next system call.
    fn interrupt(&mut self, pid: u32);
}

/// Where a process is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum State {
    /// Running, or its message is being served.
    Running,
    /// A forked child whose thread has not reported yet: its first exception message is
    /// answered with these registers.
    Starting(Registers),
    /// Its call waits: this message is served again when something happened.
    Blocked(ExceptionMessage),
    /// It vforked `child` and waits until the child executes or ends; then `reply` (the
    /// child's pid in `rax`) resumes it.
    Vforked { child: u32, reply: ExceptionMessage },
    /// It ended and its parent has not reaped it: its wait status.
    Zombie(u32),
}

/// Why the kept messages of blocked processes are served again.
#[derive(Debug)]
enum Woken {
    /// Anything may have changed: every one is.
    Anything,
    /// Only these sockets of the stack changed (by id; the stack's runs add the ones they
    /// change): only the calls waiting on them, or possibly on any socket, are.
    Sockets(Vec<usize>),
}

impl Woken {
    /// Whether a call that waits for `waits` is served again.
    fn serves(&self, waits: syscall::Waits) -> bool {
        match (self, waits) {
            (Woken::Anything, _) => true,
            (Woken::Sockets(ids), syscall::Waits::Socket(id)) => ids.contains(&id),
            (Woken::Sockets(ids), syscall::Waits::Anything) => !ids.is_empty(),
            (Woken::Sockets(_), syscall::Waits::Elsewhere) => false,
        }
    }

    /// Adds what `other` says changed.
    fn add(&mut self, other: Woken) {
        match (self, other) {
            (Woken::Anything, _) => {}
            (this, Woken::Anything) => *this = Woken::Anything,
            (Woken::Sockets(ids), Woken::Sockets(more)) => ids.extend(more),
        }
    }
}

/// A process and its state, displayed as [`System::describe`] says.
pub struct Described<'a>(&'a Process, State);

impl core::fmt::Display for Described<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let Described(process, state) = self;
        write!(f, "{} ({}) ", process.pid, process.name())?;
        match state {
            State::Running => f.write_str("running"),
            State::Starting(_) => f.write_str("forked, never ran"),
            State::Blocked(call) if call.vector == abi::ipc::VECTOR_SYSCALL => {
                write!(f, "waiting in system call {}", call.registers.rax)
            }
            State::Blocked(call) => write!(f, "waiting on exception {}", call.vector),
            State::Vforked { child, .. } => write!(f, "vforked {child}"),
            State::Zombie(status) => write!(f, "zombie {status:#x}"),
        }
    }
}

#[derive(Clone, Debug)]
struct Slot {
    process: Process,
    state: State,
    /// Stopped by a signal: its thread is suspended.
    stopped: bool,
    /// A stop (`0x7f | signal << 8`) or continue (`0xffff`) its parent has not waited for.
    report: Option<u32>,
    /// Its call waited (blocked, or a vfork parent): when it is answered, its thread is
    /// woken and may move to a CPU with fewer threads ([`System::rebalance`]).
    waited: bool,
}

/// Which children a wait is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Which {
    Any,
    Pid(u32),
    /// A process group (0: the caller's).
    Group(u32),
}

/// A `wait4` or `waitid` request.
#[derive(Clone, Copy, Debug)]
struct Wait {
    which: Which,
    options: u64,
    /// `waitid`: report a `siginfo`, not a status word.
    siginfo: bool,
}

impl Wait {
    fn wait4(pid: i32, options: u64) -> Self {
        let which = match pid {
            -1 => Which::Any,
            0 => Which::Group(0),
            p if p < 0 => Which::Group(p.unsigned_abs()),
            p => Which::Pid(p as u32),
        };
        Self {
            which,
            options: (options & !WTHREAD_FLAGS) | WEXITED,
            siginfo: false,
        }
    }

    fn waitid(idtype: u64, id: u64, options: u64) -> SysResult<Self> {
        let which = match idtype {
            0 => Which::Any,
            1 => Which::Pid(u32::try_from(id).map_err(|_| Errno::EINVAL)?),
            2 => Which::Group(u32::try_from(id).map_err(|_| Errno::EINVAL)?),
            _ => return Err(Errno::EINVAL),
        };
        let options = options & !WTHREAD_FLAGS;
        let known = WNOHANG | WUNTRACED | WEXITED | WCONTINUED | WNOWAIT;
        if options & !known != 0 || options & (WUNTRACED | WEXITED | WCONTINUED) == 0 {
            return Err(Errno::EINVAL);
        }
        Ok(Self {
            which,
            options,
            siginfo: true,
        })
    }
}

/// The `siginfo` `waitid` reports for child `pid` with wait status `word`.
fn child_info(pid: u32, word: u32) -> Info {
    let (code, status) = match word {
        0xffff => (signal::CLD_CONTINUED, signal::SIGCONT as i32),
        w if w & 0xff == 0x7f => (signal::CLD_STOPPED, (w >> 8 & 0xff) as i32),
        w if w & 0x7f != 0 => (signal::CLD_KILLED, (w & 0x7f) as i32),
        w => (signal::CLD_EXITED, (w >> 8 & 0xff) as i32),
    };
    Info {
        signal: signal::SIGCHLD,
        code,
        pid,
        status,
        address: 0,
    }
}

/// The wait status of a process that exited with `code`.
pub const fn exit_status(code: u8) -> u32 {
    (code as u32) << 8
}

/// The process table of a guest.
pub struct System {
    /// Grown as processes and threads come, up to [`MAX_PROCESSES`]; a slot's index stays
    /// its own while it is used.
    slots: Vec<Option<Slot>>,
    pub pipes: Pipes,
    /// The `eventfd` counters, `timerfd` timers and epoll instances.
    pub events: Events,
    /// The sockets and their stack.
    pub net: Net,
    /// The unsupported calls logged so far.
    reported: syscall::Reported,
    next_pid: u32,
    /// How init ended, when a call of another process ended it.
    ended: Option<Outcome>,
    /// `AT_HWCAP` for the programs `execve` starts.
    hwcap: u64,
    /// The slots (a process's first thread, another of its threads) whose shared state is
    /// lent to the second while its call is served ([`System::lend`]).
    lent: Option<(usize, usize)>,
    /// `fork`s refused with `EAGAIN` so far (the first are logged).
    refusals: u32,
    /// Kept messages served again so far, and how many of them finished (the rest waited
    /// on: a retry for nothing, each a whole call).
    pub served_again: u64,
    pub finished_again: u64,
}

/// How many refused `fork`s [`System`] logs.
pub const REFUSALS_LOGGED: u32 = 8;

impl System {
    /// A table holding `init`, already loaded and running.
    pub fn new(init: Process, hwcap: u64) -> Self {
        let next_pid = init.pid + 1;
        let slots = alloc::vec![Some(Slot {
            process: init,
            state: State::Running,
            stopped: false,
            report: None,
            waited: false,
        })];
        Self {
            slots,
            pipes: Pipes::new(),
            events: Events::new(),
            net: Net::new(None),
            reported: syscall::Reported::default(),
            next_pid,
            ended: None,
            hwcap,
            lent: None,
            refusals: 0,
            served_again: 0,
            finished_again: 0,
        }
    }

    /// Logs that a `fork` of the process in slot `i` was refused for want of a task, a
    /// thread or a slot (`EAGAIN`), the first [`REFUSALS_LOGGED`] times.
    fn refused(&mut self, i: usize, k: &mut impl Host) {
        self.refusals = self.refusals.saturating_add(1);
        if self.refusals > REFUSALS_LOGGED {
            return;
        }
        let processes = self.slots.iter().flatten().count();
        let more = match self.refusals == REFUSALS_LOGGED {
            true => "; further refusals are not logged",
            false => "",
        };
        if let Some(slot) = self.slots[i].as_ref() {
            k.log(format_args!(
                "guest: fork by {} ({}) refused: no task, thread or slot left \
                 ({processes} processes and threads){more}",
                slot.process.pid,
                slot.process.name(),
            ));
        }
    }

    /// A slot for a new process or thread: a free one, or one more while there are fewer
    /// than [`MAX_PROCESSES`] and the heap has room for it.
    fn free_slot(&mut self) -> Result<usize, Errno> {
        if let Some(free) = self.slots.iter().position(Option::is_none) {
            return Ok(free);
        }
        if self.slots.len() == MAX_PROCESSES || self.slots.try_reserve(1).is_err() {
            return Err(Errno::EAGAIN);
        }
        self.slots.push(None);
        Ok(self.slots.len() - 1)
    }

    fn index(&self, pid: u32) -> Option<usize> {
        self.slots
            .iter()
            .position(|s| s.as_ref().is_some_and(|s| s.process.pid == pid))
    }

    pub fn process(&self, pid: u32) -> Option<&Process> {
        Some(&self.slots[self.index(pid)?].as_ref()?.process)
    }

    pub fn state(&self, pid: u32) -> Option<State> {
        Some(self.slots[self.index(pid)?].as_ref()?.state)
    }

    /// Process `pid` as a log line says it: `<pid> (<name>) <what it does>` (see
    /// `guest: left:` in the crate's log lines).
    pub fn describe(&self, pid: u32) -> Option<Described<'_>> {
        let slot = self.slots[self.index(pid)?].as_ref()?;
        Some(Described(&slot.process, slot.state))
    }

    /// The pids in the table (zombies included), in slot order.
    pub fn pids(&self) -> impl Iterator<Item = u32> + '_ {
        self.slots.iter().flatten().map(|s| s.process.pid)
    }

    /// Serves one exception message of process `pid`'s thread, then the waiting calls
    /// that can now complete. Returns how init ended when it did (the guest then ends:
    /// [`System::release_all`]).
    pub fn serve(
        &mut self,
        pid: u32,
        fs: &mut Fs,
        k: &mut impl Tasks,
        mut m: ExceptionMessage,
    ) -> Option<Outcome> {
        let i = self.index(pid)?;
        let tgid = self.slots[i].as_ref()?.process.tgid;
        self.lend(i);
        let slot = self.slots[i].as_mut()?;
        // A new process's first message starts it: nobody else's wait ends with that.
        let only_caller = match slot.state {
            State::Running => syscall::touches_only_caller(&slot.process, &m),
            State::Starting(_) => true,
            _ => false,
        };
        let waits = match slot.state {
            State::Running => syscall::waits_on(&slot.process, &m),
            _ => syscall::Waits::Anything,
        };
        let ended = match slot.state {
            State::Starting(registers) => {
                slot.state = State::Running;
                m.registers = registers;
                self.resume(i, fs, k, m, None)
            }
            State::Running => self.run(i, fs, k, m),
            // A blocked or ended process has no thread that could send.
            State::Blocked(_) | State::Vforked { .. } | State::Zombie(_) => None,
        };
        self.give_back();
        self.share_group(tgid);
        // What changed only its sender, which runs on, ends nobody's wait: the blocked
        // calls are not served again (each retry is a whole call: a `poll` of all its
        // descriptors, an `accept`; most of a forked child's messages are its page faults
        // and such calls).
        let runs_on = matches!(self.caller_state(i, pid), Some(State::Running));
        if ended.is_none() && only_caller && runs_on {
            return None;
        }
        if ended.is_some() {
            return ended;
        }
        let woken = self.changed_by(i, pid, waits);
        self.wake(fs, k, woken)
    }

    /// What the kept call `m` of slot `i` waits for ([`syscall::waits_on`]), read in its
    /// process's descriptor table: a thread's is its first thread's while none of its
    /// calls is served ([`System::lend`]).
    fn waits_of(&self, i: usize, m: &ExceptionMessage) -> syscall::Waits {
        let Some(slot) = self.slots[i].as_ref() else {
            return syscall::Waits::Anything;
        };
        let lent_to_it = self.lent.is_some_and(|(_, to)| to == i);
        let table = match self.index(slot.process.tgid) {
            Some(first) if slot.process.is_thread() && !lent_to_it => self.slots[first].as_ref(),
            _ => Some(slot),
        };
        table.map_or(syscall::Waits::Anything, |s| {
            syscall::waits_on(&s.process, m)
        })
    }

    /// The state of process `pid` after one of its calls was served, if it is still in
    /// slot `i` and not stopped.
    fn caller_state(&self, i: usize, pid: u32) -> Option<&State> {
        match self.slots.get(i) {
            Some(Some(s)) if s.process.pid == pid && !s.stopped => Some(&s.state),
            _ => None,
        }
    }

    /// What a call of process `pid` in slot `i` that waited for `waits` changed, now that
    /// it was served: a call kept to be served again changed nothing ([`Outcome::Block`]:
    /// only what the stack's run then changes serves others, a blocking `connect`'s SYN),
    /// unless it moved part of a blocking write into a pipe before it had to wait
    /// (`pipe_written`: a reader can go on) or raised a signal its caller must now take (a
    /// background read of the terminal: SIGTTIN to its group); a call on one socket whose
    /// caller runs on changed that socket only (a read made room, a write queued bytes,
    /// an accept took a connection); any other call, or a caller that stopped or ended,
    /// anything.
    fn changed_by(&self, i: usize, pid: u32, waits: syscall::Waits) -> Woken {
        let changed_nothing = || {
            self.slots[i]
                .as_ref()
                .is_some_and(|s| s.process.pipe_written == 0 && s.process.deliverable() == 0)
        };
        match (self.caller_state(i, pid), waits) {
            (Some(State::Blocked(_)), _) if changed_nothing() => Woken::Sockets(Vec::new()),
            (Some(State::Running), syscall::Waits::Socket(id)) => Woken::Sockets(alloc::vec![id]),
            _ => Woken::Anything,
        }
    }

    /// Serves the kept messages of blocked processes again, after something outside the
    /// processes happened (console input arrived). Returns how init ended when it did.
    pub fn retry_blocked(&mut self, fs: &mut Fs, k: &mut impl Tasks) -> Option<Outcome> {
        self.wake(fs, k, Woken::Anything)
    }

    /// Frames came to `eth0`: the stack takes them in, and the kept messages waiting on
    /// the sockets they changed are served again (none when it took no frame and no socket
    /// may have changed: a wake-up for frames an earlier run already took changes
    /// nothing). Returns how init ended when it did.
    pub fn frames_came(&mut self, fs: &mut Fs, k: &mut impl Tasks) -> Option<Outcome> {
        if !self.net.run(k) {
            return None;
        }
        self.wake(fs, k, Woken::Sockets(Vec::new()))
    }

    /// Whether a process waits in a call (a kept message).
    pub fn any_blocked(&self) -> bool {
        self.slots
            .iter()
            .flatten()
            .any(|s| matches!(s.state, State::Blocked(_)))
    }

    /// The time the next sleeping call, alarm or timer of the network stack is due (the
    /// guest's clock), if any.
    pub fn next_timer(&mut self) -> Option<u64> {
        let net = self.net.poll_at_ns();
        // A timerfd's expiry matters only to a waiting call (a read, poll or epoll_wait of
        // it); an unwatched interval timer does not wake the guest.
        // (Asked in that order: the blocked calls are a few slots, the timers a table.)
        let timerfd = self
            .any_blocked()
            .then(|| self.events.next_expiry())
            .flatten();
        let alarms = self
            .slots
            .iter()
            .flatten()
            .filter(|s| !matches!(s.state, State::Zombie(_)))
            .filter_map(|s| s.process.alarm_at);
        self.sleeps().chain(alarms).chain(net).chain(timerfd).min()
    }

    /// When the sleeps and time-outs of the blocked calls end (the guest's clock).
    fn sleeps(&self) -> impl Iterator<Item = u64> + '_ {
        self.slots
            .iter()
            .flatten()
            .filter(|s| matches!(s.state, State::Blocked(_)))
            .filter_map(|s| s.process.wake_at)
    }

    /// Raises the alarms that are due and completes the sleeps that ended (called when the
    /// time [`System::next_timer`] named has come, or the partition's ports had news:
    /// `ports`, the calls waiting for a port are served again too). When only the stack's
    /// timers were due (a retransmission, a delayed ACK), only the calls waiting on the
    /// sockets its run changed are served again ([`Woken::Sockets`]).
    pub fn tick(&mut self, fs: &mut Fs, k: &mut impl Tasks, ports: bool) -> Option<Outcome> {
        let now = k.now_ns();
        let mut processes_due = ports || self.events.next_expiry().is_some_and(|at| at <= now);
        // Expired timers are counted now, so that none stays due (the calls served
        // again below read them).
        self.events.advance_timers(now);
        for j in 0..self.slots.len() {
            let due = match self.slots[j].as_mut() {
                Some(s) if !matches!(s.state, State::Zombie(_)) => {
                    sigcalls::alarm_due(&mut s.process, now)
                }
                _ => false,
            };
            processes_due |= due;
            if due && let Some(ended) = self.send(j, None, Info::kernel(signal::SIGALRM), fs, k) {
                return Some(ended);
            }
        }
        processes_due |= self.sleeps().any(|at| at <= now);
        let woken = if processes_due {
            Woken::Anything
        } else {
            Woken::Sockets(Vec::new())
        };
        self.wake(fs, k, woken)
    }

    /// Serves the kept messages of blocked processes until none completes; a blocked
    /// process with a signal to act on is interrupted instead.
    fn wake(&mut self, fs: &mut Fs, k: &mut impl Tasks, mut woken: Woken) -> Option<Outcome> {
        loop {
            // Frames and timers first: what the calls just sent reaches its sockets.
            self.net.run(k);
            let changed = self.net.take_changed();
            if let Woken::Sockets(ids) = &mut woken {
                ids.extend(changed);
            }
            // What the calls served now change, for the next round.
            let mut next = Woken::Sockets(Vec::new());
            let mut progress = false;
            for i in 0..self.slots.len() {
                let Some(Slot {
                    state: State::Blocked(m),
                    stopped: false,
                    ..
                }) = self.slots[i]
                else {
                    continue;
                };
                let waits = self.waits_of(i, &m);
                if !woken.serves(waits) {
                    continue;
                }
                let Some(slot) = self.slots[i].as_mut() else {
                    continue;
                };
                slot.state = State::Running;
                let (pid, tgid) = (slot.process.pid, slot.process.tgid);
                self.served_again += 1;
                self.lend(i);
                let ended = match self.interrupting(i) {
                    Some(restart) => {
                        let p = &mut self.slots[i].as_mut()?.process;
                        k.select(p.pid);
                        p.futex = None;
                        let m = sigcalls::interrupted(p, k, m, restart);
                        self.resume(i, fs, k, m, None)
                    }
                    None => self.run(i, fs, k, m),
                };
                self.give_back();
                self.share_group(tgid);
                if ended.is_some() {
                    return ended;
                }
                let finished = !matches!(
                    self.slots[i],
                    Some(Slot {
                        state: State::Blocked(_),
                        ..
                    })
                );
                if finished {
                    self.finished_again += 1;
                    progress = true;
                    next.add(self.changed_by(i, pid, waits));
                }
            }
            if !progress {
                return None;
            }
            woken = next;
        }
    }

    /// Whether the blocked process in slot `i` has a signal that interrupts its call, and
    /// then whether the call restarts after it (a handler with `SA_RESTART`, or a stop).
    /// Deliverable signals it ignores are dropped on the way.
    fn interrupting(&mut self, i: usize) -> Option<bool> {
        let p = &mut self.slots[i].as_mut()?.process;
        loop {
            let sig = p.next_signal()?;
            let action = p.action(sig);
            if sig != signal::SIGKILL && sig != signal::SIGSTOP && action.ignores(sig) {
                p.pending &= !signal::bit(sig);
                continue;
            }
            let handled = sig != signal::SIGKILL && action.handler > signal::SIG_IGN;
            let stops = !handled && signal::bit(sig) & signal::STOP_SIGNALS != 0;
            return Some(stops || handled && action.flags & signal::SA_RESTART != 0);
        }
    }

    /// Resumes the process in slot `i` with message `m` (a completed call, or the fault
    /// `trap` with its vector, error code and address), delivering its pending signals
    /// first: an ignored one is dropped, a fatal one ends it, a stop signal stops it, and
    /// a caught one runs its handler (one per resumption: the next goes when the handler
    /// returns with `rt_sigreturn`, a system call).
    fn resume(
        &mut self,
        i: usize,
        fs: &mut Fs,
        k: &mut impl Tasks,
        mut m: ExceptionMessage,
        trap: Option<(u64, u64, u64)>,
    ) -> Option<Outcome> {
        self.rebalance(i, k);
        loop {
            let slot = self.slots[i].as_mut()?;
            let p = &mut slot.process;
            let pid = p.pid;
            let Some(info) = p.take_signal() else {
                k.resume(pid, &m);
                return None;
            };
            let sig = info.signal;
            let action = p.action(sig);
            let caught = sig != signal::SIGKILL && sig != signal::SIGSTOP;
            if caught && action.handler == signal::SIG_IGN {
                continue;
            }
            if !caught || action.handler == signal::SIG_DFL {
                match signal::default_action(sig) {
                    Default::Ignore | Default::Continue => continue,
                    Default::Stop => {
                        self.stop(i, sig, k);
                        continue;
                    }
                    Default::Terminate | Default::Core => {
                        k.log(format_args!(
                            "guest: process {} ({}) killed by signal {sig} ({})",
                            p.tgid,
                            p.name(),
                            signal::name(sig)
                        ));
                        return self.end(i, sig, fs, k);
                    }
                }
            }
            let (vector, error, cr2) = trap.unwrap_or_default();
            let at = signal::Interrupted {
                registers: m.registers,
                mask: p.saved_mask.take().unwrap_or(p.sigmask),
                trap: vector,
                error,
                cr2,
            };
            k.select(pid);
            let mut image = [0u8; signal::FPU_SIZE];
            let written = signal::frame(&action, &info, &at, &p.alt_stack).filter(|f| {
                k.fpu(&mut image).is_ok()
                    && syscall::write_user(p, k, f.fpu, &image).is_ok()
                    && syscall::write_user(p, k, f.frame, &f.bytes).is_ok()
            });
            let Some(frame) = written else {
                k.log(format_args!(
                    "guest: process {pid} ({}) killed by signal {SIGSEGV} (SIGSEGV): no room for the frame of signal {sig} ({}) at rsp {:#x}",
                    p.name(),
                    signal::name(sig),
                    m.registers.rsp
                ));
                return self.end(i, SIGSEGV, fs, k);
            };
            p.sigmask |= action.mask;
            if action.flags & signal::SA_NODEFER == 0 {
                p.sigmask |= signal::bit(sig);
            }
            p.sigmask &= !signal::UNBLOCKABLE;
            if action.flags & signal::SA_RESETHAND != 0 {
                p.sigactions[sig as usize - 1] = Action::DEFAULT;
            }
            m.registers = frame.registers;
            k.resume(pid, &m);
            return None;
        }
    }

    /// Stops the process in slot `i` (signal `sig`): its thread is suspended (a reply it
    /// waits for still arrives, and it runs on after `SIGCONT`), its parent is told.
    fn stop(&mut self, i: usize, sig: u32, k: &mut impl Tasks) {
        let Some(slot) = self.slots[i].as_mut() else {
            return;
        };
        if slot.stopped {
            return;
        }
        slot.stopped = true;
        slot.report = Some(0x7f | sig << 8);
        let (pid, parent) = (slot.process.pid, slot.process.ppid);
        k.suspend(pid, true);
        self.notify_parent(parent, pid, signal::CLD_STOPPED, sig as i32);
    }

    /// Continues a stopped process in slot `i`.
    fn cont(&mut self, i: usize, k: &mut impl Tasks) {
        let Some(slot) = self.slots[i].as_mut() else {
            return;
        };
        if !slot.stopped {
            return;
        }
        slot.stopped = false;
        slot.report = Some(0xffff);
        let (pid, parent) = (slot.process.pid, slot.process.ppid);
        k.suspend(pid, false);
        self.notify_parent(parent, pid, signal::CLD_CONTINUED, signal::SIGCONT as i32);
    }

    /// `SIGCHLD` for `parent` about child `child` (unless the parent ignores it, or asked
    /// with `SA_NOCLDSTOP` not to hear of stops and continues).
    fn notify_parent(&mut self, parent: u32, child: u32, code: i32, status: i32) {
        let Some(j) = self.index(parent) else {
            return;
        };
        let Some(slot) = self.slots[j].as_mut() else {
            return;
        };
        let p = &mut slot.process;
        let stop_event = code == signal::CLD_STOPPED || code == signal::CLD_CONTINUED;
        if stop_event && p.action(signal::SIGCHLD).flags & signal::SA_NOCLDSTOP != 0 {
            return;
        }
        let info = Info {
            signal: signal::SIGCHLD,
            code,
            pid: child,
            status,
            address: 0,
        };
        Self::post(p, info);
    }

    /// Makes `info.signal` pending for `p` unless it would do nothing (then Linux discards
    /// it at once, if it is not blocked); `SIGCONT` and the stop signals cancel each other.
    fn post(p: &mut Process, info: Info) -> bool {
        let sig = info.signal;
        if sig == signal::SIGCONT || sig == signal::SIGKILL {
            p.pending &= !signal::STOP_SIGNALS;
        } else if signal::bit(sig) & signal::STOP_SIGNALS != 0 {
            p.pending &= !signal::bit(signal::SIGCONT);
        }
        // Init gets only the signals it has a handler for (Linux protects it so).
        if p.pid == INIT_PID && p.action(sig).handler == signal::SIG_DFL {
            return false;
        }
        let blocked = p.sigmask & signal::bit(sig) & !signal::UNBLOCKABLE != 0;
        if !blocked
            && sig != signal::SIGKILL
            && sig != signal::SIGSTOP
            && p.action(sig).ignores(sig)
        {
            return false;
        }
        p.raise(info);
        true
    }

    /// Sends `info` to the process in slot `j`, on behalf of the process in slot `sender`
    /// (whose call is being served: it sees its own signals when the call returns). A
    /// process running user code is interrupted to run a caught signal's handler; one the
    /// signal ends, stops or continues is ended, stopped or continued at once.
    fn send(
        &mut self,
        j: usize,
        sender: Option<usize>,
        info: Info,
        fs: &mut Fs,
        k: &mut impl Tasks,
    ) -> Option<Outcome> {
        let sig = info.signal;
        let slot = self.slots[j].as_mut()?;
        if matches!(slot.state, State::Zombie(_)) {
            return None;
        }
        if sig == signal::SIGCONT || sig == signal::SIGKILL {
            self.cont(j, k);
        }
        let slot = self.slots[j].as_mut()?;
        if !Self::post(&mut slot.process, info) || sender == Some(j) {
            return None;
        }
        let p = &slot.process;
        let acts_now = matches!(
            slot.state,
            State::Running | State::Starting(_) | State::Vforked { .. }
        ) && p.deliverable() & signal::bit(sig) != 0
            && (sig == signal::SIGKILL
                || sig == signal::SIGSTOP
                || p.action(sig).handler == signal::SIG_DFL);
        let vforked = matches!(slot.state, State::Vforked { .. });
        let caught = p.deliverable() & signal::bit(sig) != 0 && !acts_now;
        if caught && matches!(slot.state, State::Running) {
            // Its handler runs at once, not at the next system call.
            k.interrupt(p.pid);
        }
        if !acts_now || (vforked && sig != signal::SIGKILL) {
            return None; // blocked calls are interrupted by `wake`
        }
        match signal::default_action(sig) {
            Default::Terminate | Default::Core => {
                let slot = self.slots[j].as_mut()?;
                slot.process.pending &= !signal::bit(sig);
                k.log(format_args!(
                    "guest: process {} ({}) killed by signal {sig} ({})",
                    slot.process.tgid,
                    slot.process.name(),
                    signal::name(sig)
                ));
                self.end(j, sig, fs, k)
            }
            Default::Stop => {
                if let Some(slot) = self.slots[j].as_mut() {
                    slot.process.pending &= !signal::bit(sig);
                }
                self.stop(j, sig, k);
                None
            }
            Default::Ignore | Default::Continue => None,
        }
    }

    /// Sends signal `sig` (from process `from`, 0 for the guest) to every process of group
    /// `pgid` (the terminal's `SIGINT`, `SIGQUIT`, `SIGTSTP`, a `kill` of a group); `false`
    /// when the group has no process.
    pub fn signal_group(
        &mut self,
        pgid: u32,
        sig: u32,
        fs: &mut Fs,
        k: &mut impl Tasks,
    ) -> Option<Outcome> {
        for j in 0..self.slots.len() {
            let member = self.slots[j]
                .as_ref()
                .is_some_and(|s| s.process.pgid == pgid && !matches!(s.state, State::Zombie(_)));
            if member && let Some(ended) = self.send(j, None, Info::kernel(sig), fs, k) {
                return Some(ended);
            }
        }
        None
    }

    /// `kill(pid, sig)` by the process in slot `i` (`tkill`/`tgkill`: one process, as every
    /// process has one thread).
    fn kill(
        &mut self,
        i: usize,
        fs: &mut Fs,
        k: &mut impl Tasks,
        target: i64,
        sig: u64,
    ) -> SysResult<u64> {
        if sig > signal::NSIG as u64 {
            return Err(Errno::EINVAL);
        }
        let caller = &self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process;
        let (me, my_group) = (caller.tgid, caller.pgid);
        // A process is its first thread's slot; `kill` of another thread's id signals it.
        let hits = |s: &Slot| match target {
            _ if s.process.is_thread() => target > 0 && target == s.process.pid as i64,
            -1 => s.process.pid != INIT_PID && s.process.pid != me,
            0 => s.process.pgid == my_group,
            t if t < 0 => t.checked_neg() == Some(s.process.pgid as i64),
            t => t == s.process.pid as i64,
        };
        let targets: [bool; MAX_PROCESSES] =
            core::array::from_fn(|j| self.slots.get(j).and_then(Option::as_ref).is_some_and(hits));
        if !targets.contains(&true) {
            return Err(Errno::ESRCH);
        }
        if sig == 0 {
            return Ok(0);
        }
        for (j, _) in targets.iter().enumerate().filter(|(_, t)| **t) {
            // The caller's own end, if it killed itself, comes when its call returns.
            let j = self.receiver(j, sig as u32);
            if let Some(ended) = self.send(j, Some(i), Info::user(sig as u32, me), fs, k) {
                self.ended = Some(ended);
            }
        }
        Ok(0)
    }

    /// `setpgid(pid, pgid)`.
    fn setpgid(&mut self, i: usize, pid: u64, pgid: u64) -> SysResult<u64> {
        let caller = &self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process;
        let (me, my_sid) = (caller.pid, caller.sid);
        let pid = if pid == 0 {
            me
        } else {
            u32::try_from(pid).map_err(|_| Errno::ESRCH)?
        };
        let pgid = if pgid == 0 {
            pid
        } else {
            u32::try_from(pgid).map_err(|_| Errno::EINVAL)?
        };
        if pgid > i32::MAX as u32 {
            return Err(Errno::EINVAL);
        }
        let j = self.index(pid).ok_or(Errno::ESRCH)?;
        let target = &self.slots[j].as_ref().ok_or(Errno::ESRCH)?.process;
        if pid != me && target.ppid != me {
            return Err(Errno::ESRCH);
        }
        if pid != me && target.executed {
            return Err(Errno::EACCES);
        }
        if target.sid != my_sid || target.sid == target.pid {
            return Err(Errno::EPERM);
        }
        let group_exists = self
            .slots
            .iter()
            .flatten()
            .any(|s| s.process.pgid == pgid && s.process.sid == my_sid);
        if pgid != pid && !group_exists {
            return Err(Errno::EPERM);
        }
        self.slots[j].as_mut().ok_or(Errno::ESRCH)?.process.pgid = pgid;
        Ok(0)
    }

    /// `getpgid(pid)` / `getsid(pid)` (`pid` 0: the caller).
    fn group_of(&self, i: usize, pid: u64, session: bool) -> SysResult<u64> {
        let caller = &self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process;
        let pid = if pid == 0 {
            caller.pid
        } else {
            u32::try_from(pid).map_err(|_| Errno::ESRCH)?
        };
        let p = self.process(pid).ok_or(Errno::ESRCH)?;
        Ok(if session { p.sid } else { p.pgid } as u64)
    }

    /// `setsid()`: a new session and group led by the caller (`EPERM` for a group leader).
    fn setsid(&mut self, i: usize) -> SysResult<u64> {
        let me = self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process.pid;
        if self.slots.iter().flatten().any(|s| s.process.pgid == me) {
            return Err(Errno::EPERM);
        }
        let p = &mut self.slots[i].as_mut().ok_or(Errno::ESRCH)?.process;
        p.sid = me;
        p.pgid = me;
        Ok(me as u64)
    }

    /// Serves message `m` of the running process in slot `i`.
    fn run(
        &mut self,
        i: usize,
        fs: &mut Fs,
        k: &mut impl Tasks,
        mut m: ExceptionMessage,
    ) -> Option<Outcome> {
        let (before, rest) = self.slots.split_at_mut(i);
        let (slot, after) = rest.split_first_mut()?;
        let slot = slot.as_mut()?;
        let others = Others { before, after };
        let pid = slot.process.pid;
        k.select(pid);
        let kept = m;
        let files = syscall::Files {
            pipes: &mut self.pipes,
            events: &mut self.events,
            net: &mut self.net,
            fs,
            others: &others,
        };
        match syscall::handle(&mut slot.process, files, &mut self.reported, k, &mut m) {
            Outcome::Resume => self.resume(i, fs, k, m, None),
            Outcome::Block => {
                slot.state = State::Blocked(kept);
                slot.waited = true;
                None
            }
            Outcome::Exit(code) => self.end(i, exit_status(code), fs, k),
            Outcome::Killed(signal) => self.end(i, signal, fs, k),
            Outcome::Signal(info) => {
                slot.process.raise(info);
                let trap = (m.vector, m.error_code, m.fault_address);
                self.resume(i, fs, k, m, Some(trap))
            }
            Outcome::Process(call) => {
                let vfork =
                    matches!(call, ProcessCall::Clone { flags, .. } if flags & CLONE_VFORK != 0);
                let result = match call {
                    ProcessCall::Clone { flags, args } if threads::is_thread_clone(flags) => {
                        self.spawn_thread(i, k, flags, args, &m.registers)
                    }
                    ProcessCall::Clone { flags, args } => {
                        let forked = self.fork(i, fs, k, flags, args, &m.registers);
                        if forked == Err(Errno::EAGAIN) {
                            self.refused(i, k);
                        }
                        forked
                    }
                    ProcessCall::ExitThread => {
                        self.exit_thread(i, k);
                        return None;
                    }
                    ProcessCall::Futex { args } => match self.futex(i, k, args) {
                        Ok(None) => return self.block(i, kept),
                        result => result.map(|n| n.unwrap_or(0)),
                    },
                    ProcessCall::Kill { target, signal } => self.kill(i, fs, k, target, signal),
                    ProcessCall::KillThread { tgid, tid, signal } => {
                        self.kill_thread(i, fs, k, (tgid, tid), signal)
                    }
                    ProcessCall::SetPgid { pid, pgid } => self.setpgid(i, pid, pgid),
                    ProcessCall::GroupOf { pid, session } => self.group_of(i, pid, session),
                    ProcessCall::SetSid => self.setsid(i),
                    ProcessCall::Sysinfo { record } => self.sysinfo(i, k, record),
                    ProcessCall::SetAffinity { pid, len, mask } => {
                        self.set_affinity(i, k, pid, len, mask)
                    }
                    ProcessCall::Wait4 {
                        pid,
                        status,
                        options,
                        rusage,
                    } => {
                        let waited = self.wait(i, k, Wait::wait4(pid, options), status, rusage);
                        match waited {
                            Ok(None) => return self.block(i, kept),
                            result => result.map(|pid| pid.unwrap_or(0)),
                        }
                    }
                    ProcessCall::Waitid {
                        idtype,
                        id,
                        info,
                        options,
                    } => {
                        let waited = Wait::waitid(idtype, id, options)
                            .and_then(|w| self.wait(i, k, w, info, 0));
                        match waited {
                            Ok(None) => return self.block(i, kept),
                            // waitid returns 0 and reports the pid in the siginfo.
                            result => result.map(|_| 0),
                        }
                    }
                    ProcessCall::Execve { path, argv, envp } => {
                        match self.execve(i, fs, k, path, argv, envp) {
                            Ok(Some((entry, sp, new_thread))) => {
                                m.registers = Registers {
                                    rip: entry,
                                    rsp: sp,
                                    rflags: m.registers.rflags,
                                    ..Registers::default()
                                };
                                let ended = if new_thread {
                                    // Its new thread reports first (a fault at address 0).
                                    if let Some(slot) = self.slots[i].as_mut() {
                                        slot.state = State::Starting(m.registers);
                                    }
                                    None
                                } else {
                                    self.resume(i, fs, k, m, None)
                                };
                                return ended.or_else(|| self.release_vfork_parent(pid, fs, k));
                            }
                            // The old image is gone and the new one did not load.
                            Ok(None) => return self.end(i, SIGSEGV, fs, k),
                            Err(e) => Err(e),
                        }
                    }
                };
                if let Some(ended) = self.ended.take() {
                    return Some(ended);
                }
                let r = &mut m.registers;
                r.rax = result.unwrap_or_else(|e| e.result());
                r.rcx = r.rip;
                r.r11 = r.rflags;
                match result {
                    // The vfork parent waits until its child executes or ends.
                    Ok(child) if vfork => {
                        if let Some(slot) = self.slots[i].as_mut() {
                            slot.state = State::Vforked {
                                child: child as u32,
                                reply: m,
                            };
                            slot.waited = true;
                        }
                        None
                    }
                    // Killed itself (or its group): the signal acts before the call returns.
                    _ if self.slots[i].is_none() => None,
                    _ => self.resume(i, fs, k, m, None),
                }
            }
        }
    }

    /// The call of the process in slot `i` waits: message `m` is served again later.
    fn block(&mut self, i: usize, m: ExceptionMessage) -> Option<Outcome> {
        if let Some(slot) = self.slots[i].as_mut() {
            slot.state = State::Blocked(m);
            slot.waited = true;
        }
        None
    }

    /// `sysinfo` of the process in slot `i`: its record at `record`.
    fn sysinfo(&mut self, i: usize, k: &mut impl Tasks, record: u64) -> SysResult<u64> {
        let (total, free) = k.memory();
        let count = self.pids().count() as u16;
        let bytes = crate::info::sysinfo_record(k.now_ns(), total, free, count);
        let p = &self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process;
        syscall::write_user(p, k, record, &bytes).map(|()| 0)
    }

    /// The parent that vforked `child` goes on (the child executed or ended).
    fn release_vfork_parent(
        &mut self,
        child: u32,
        fs: &mut Fs,
        k: &mut impl Tasks,
    ) -> Option<Outcome> {
        for i in 0..self.slots.len() {
            if let Some(slot) = self.slots[i].as_mut()
                && let State::Vforked { child: c, reply } = slot.state
                && c == child
            {
                slot.state = State::Running;
                // A thread that vforked resumes with its process's state.
                let lend = self.lent.is_none();
                if lend {
                    self.lend(i);
                }
                let ended = self.resume(i, fs, k, reply, None);
                if lend {
                    self.give_back();
                }
                if let Some(ended) = ended {
                    return Some(ended);
                }
            }
        }
        None
    }

    /// `clone` with fork semantics: a new process with a copy of the caller's memory,
    /// files and registers; `[stack, parent_tid, child_tid]` are `clone`'s arguments.
    fn fork(
        &mut self,
        i: usize,
        fs: &mut Fs,
        k: &mut impl Tasks,
        flags: u64,
        [stack, parent_tid, child_tid, _]: [u64; 4],
        registers: &Registers,
    ) -> SysResult<u64> {
        const KNOWN: u64 = CLONE_VM
            | CLONE_VFORK
            | CLONE_PARENT_SETTID
            | CLONE_CHILD_CLEARTID
            | CLONE_CHILD_SETTID
            | 0xff;
        let signal = flags & 0xff;
        if flags & !KNOWN != 0 || (signal != SIGCHLD as u64 && signal != 0) {
            return Err(Errno::EINVAL); // threads, namespaces, other exit signals
        }
        if flags & CLONE_VM != 0 && flags & CLONE_VFORK == 0 {
            return Err(Errno::EINVAL); // shared memory without vfork: threads
        }
        let free = self.free_slot()?;
        let mut pid = self.next_pid;
        while self.index(pid).is_some() || pid == 0 {
            pid = next_pid(pid);
        }
        let cpu = self.place_new(i, k);
        let parent = &self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process;
        let mut child = parent.clone();
        child.cpu = cpu;
        child.pid = pid;
        child.tgid = pid;
        child.ppid = parent.tgid;
        child.futex = None;
        // Linux: no pending signals, alarms or sleeps are inherited.
        child.pending = 0;
        child.alarm_at = None;
        child.alarm_interval = 0;
        child.wake_at = None;
        child.saved_mask = None;
        child.executed = false;
        // Memory locks are not inherited (mlock(2)).
        child.locks = crate::memory::Locks::default();
        child.lock_future = false;
        child.clear_child_tid = if flags & CLONE_CHILD_CLEARTID != 0 {
            child_tid
        } else {
            0
        };
        let started = k.now_ns();
        let pages = if flags & CLONE_VM != 0 {
            k.borrow(pid, parent.pid, cpu)?;
            0
        } else {
            k.fork(pid, &parent.areas, cpu)?
        };
        let took = k.now_ns().saturating_sub(started);
        share_files(&child, &mut self.pipes, &mut self.events, &mut self.net, fs);
        k.log(format_args!(
            "guest: process {pid} ({}) forked from {}: {pages} pages shared in {} us",
            child.name(),
            parent.pid,
            took / 1000
        ));
        if flags & CLONE_PARENT_SETTID != 0 {
            let _ = syscall::write_user(parent, k, parent_tid, &pid.to_le_bytes());
        }
        if flags & CLONE_CHILD_SETTID != 0 {
            k.select(pid);
            let _ = syscall::write_user(&child, k, child_tid, &pid.to_le_bytes());
            k.select(parent.pid);
        }
        let mut child_registers = *registers;
        child_registers.rax = 0;
        child_registers.rcx = registers.rip;
        child_registers.r11 = registers.rflags;
        if stack != 0 {
            child_registers.rsp = stack;
        }
        self.slots[free] = Some(Slot {
            process: child,
            state: State::Starting(child_registers),
            stopped: false,
            report: None,
            waited: false,
        });
        self.next_pid = next_pid(pid);
        Ok(pid as u64)
    }

    /// `wait4`/`waitid` of the process in slot `i`: the pid of the child it reports (0:
    /// none yet, `WNOHANG`), `None` when the caller has to wait. `status` receives the
    /// wait status (`wait4`) or the `siginfo` (`waitid`); `rusage` zeros.
    fn wait(
        &mut self,
        i: usize,
        k: &mut impl Tasks,
        w: Wait,
        status: u64,
        rusage: u64,
    ) -> SysResult<Option<u64>> {
        let caller = &self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process;
        // The children of any of its process's threads.
        let (me, my_group) = (caller.tgid, caller.pgid);
        let matches = |s: &Slot| {
            s.process.ppid == me
                && match w.which {
                    Which::Any => true,
                    Which::Pid(pid) => s.process.pid == pid,
                    Which::Group(0) => s.process.pgid == my_group,
                    Which::Group(g) => s.process.pgid == g,
                }
        };
        if !self.slots.iter().flatten().any(matches) {
            return Err(Errno::ECHILD);
        }
        // An ended child first, then a stop or continue to report.
        let event = |s: &Slot| match s.state {
            State::Zombie(word) if w.options & WEXITED != 0 => Some((word, true)),
            _ => match s.report {
                Some(word) if word == 0xffff && w.options & WCONTINUED != 0 => Some((word, false)),
                Some(word) if word != 0xffff && s.stopped && w.options & WUNTRACED != 0 => {
                    Some((word, false))
                }
                _ => None,
            },
        };
        let found = (0..self.slots.len()).find_map(|z| {
            let s = self.slots[z].as_ref()?;
            matches(s).then(|| event(s)).flatten().map(|e| (z, e))
        });
        let Some((z, (word, ended))) = found else {
            return Ok((w.options & WNOHANG != 0).then_some(0));
        };
        let pid = self.slots[z].as_ref().ok_or(Errno::ECHILD)?.process.pid;
        let p = &self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process;
        if status != 0 {
            if w.siginfo {
                syscall::write_user(p, k, status, &child_info(pid, word).to_bytes())?;
            } else {
                syscall::write_user(p, k, status, &word.to_le_bytes())?;
            }
        }
        if rusage != 0 {
            syscall::write_user(p, k, rusage, &[0; RUSAGE_SIZE])?;
        }
        if w.options & WNOWAIT == 0 {
            if ended {
                self.slots[z] = None;
            } else if let Some(s) = self.slots[z].as_mut() {
                s.report = None;
            }
        }
        Ok(Some(pid as u64))
    }

    /// `execve`: `Ok(Some((entry, stack pointer, new thread)))` with the new image loaded
    /// (a new thread when a vfork child left its parent's memory), `Ok(None)`
    /// when the old image is gone but the new one did not load (the process dies), an
    /// error when the old image is intact.
    fn execve(
        &mut self,
        i: usize,
        fs: &mut Fs,
        k: &mut impl Tasks,
        path: u64,
        argv: u64,
        envp: u64,
    ) -> SysResult<Option<(u64, u64, bool)>> {
        let slot = self.slots[i].as_mut().ok_or(Errno::ESRCH)?;
        let p = &slot.process;
        // The strings are copied out before the old image goes: path, argv, envp.
        let mut copied = Strings {
            bytes: [0; ARG_MAX],
            spans: [(0, 0); MAX_STRINGS + 1],
            used: 0,
            count: 0,
        };
        copied.push(p, k, path)?;
        let mut lists = [0usize; 2];
        for (list, base) in [argv, envp].into_iter().enumerate() {
            // A null list is an empty one (as Linux allows).
            let mut n = 0;
            let mut at = if base == 0 {
                0
            } else {
                syscall::read_u64(p, k, base)?
            };
            while at != 0 {
                copied.push(p, k, at)?;
                n += 1;
                let next = base.checked_add(8 * n).ok_or(Errno::EFAULT)?;
                at = syscall::read_u64(p, k, next)?;
            }
            lists[list] = n as usize;
        }
        let count = copied.count;
        let mut strings = [&b""[..]; MAX_STRINGS + 1];
        for (s, &(at, len)) in strings.iter_mut().zip(&copied.spans[..count]) {
            *s = &copied.bytes[at..at + len];
        }
        let (path, rest) = strings[..count].split_at(1);
        let (args, env) = rest.split_at(lists[0]);
        let mut script = [&b""[..]; MAX_STRINGS + 2];
        let mut file = path[0];
        let mut argv: &[&[u8]] = args;
        let (pid, cwd, cpu) = (p.pid, p.cwd, p.cpu);
        let data = exec::find(fs, pid, cwd, file).map_err(exec_errno)?.bytes;
        // The `#!` line, copied: the file may go before the interpreter loads (as a
        // close-on-exec descriptor closes).
        let mut first_line = [0u8; 256];
        let shebang = data.strip_prefix(b"#!").map(|line| {
            let line = line.split(|&b| b == b'\n').next().unwrap_or_default();
            let n = line.len().min(first_line.len());
            first_line[..n].copy_from_slice(&line[..n]);
            n
        });
        if let Some(n) = shebang {
            // A script: its interpreter runs with the script's path after its argument.
            let line = &first_line[..n];
            let mut words = line
                .split(|&b| b == b' ' || b == b'\t')
                .filter(|w| !w.is_empty());
            let interpreter = words.next().ok_or(Errno::ENOEXEC)?;
            let mut n = 0;
            script[n] = interpreter;
            n += 1;
            if let Some(arg) = words.next() {
                script[n] = arg;
                n += 1;
            }
            script[n] = file;
            n += 1;
            for &a in args.iter().skip(1) {
                if n == script.len() {
                    return Err(Errno::E2BIG);
                }
                script[n] = a;
                n += 1;
            }
            file = interpreter;
            argv = &script[..n];
        }
        let data = exec::find(fs, pid, cwd, file).map_err(exec_errno)?.bytes;
        crate::elf::LoadPlan::new(data).map_err(|_| Errno::ENOEXEC)?;
        if argv.len() + env.len() > MAX_STRINGS {
            return Err(Errno::E2BIG);
        }

        // Its other threads end (Linux: before the new image loads).
        if p.is_thread() {
            return Err(Errno::EINVAL); // only a process's first thread may execute
        }
        self.end_threads(pid, k);
        let slot = self.slots[i].as_mut().ok_or(Errno::ESRCH)?;
        // A vfork child gets memory of its own first (the old image is its parent's).
        k.select(pid);
        let borrowed = k.own(pid, cpu)?;
        // No return from here: the old image goes.
        let old = &mut slot.process;
        if !borrowed {
            for area in old.areas.iter() {
                k.unmap(area.start, (area.end - area.start) / PAGE);
            }
        }
        close_files(
            old,
            &mut self.pipes,
            &mut self.events,
            &mut self.net,
            fs,
            true,
        );
        let ids = (old.pid, old.ppid);
        match exec::load_file(fs, k, ids, cwd, file, argv, env, self.hwcap) {
            Ok(loaded) => {
                let mut new = loaded.process;
                new.files = core::mem::take(&mut old.files);
                new.clear_cloexec();
                new.sigmask = old.sigmask;
                new.pending = old.pending;
                new.pending_info = old.pending_info;
                new.umask = old.umask;
                new.limits = old.limits;
                (new.cpu, new.affinity) = (old.cpu, old.affinity);
                (new.pgid, new.sid, new.executed) = (old.pgid, old.sid, true);
                (new.alarm_at, new.alarm_interval) = (old.alarm_at, old.alarm_interval);
                // Handlers are gone with the image; ignored signals stay ignored.
                for (n, action) in new.sigactions.iter_mut().enumerate() {
                    if old.sigactions[n].handler == signal::SIG_IGN {
                        *action = Action::IGNORE;
                    }
                }
                k.log(format_args!(
                    "guest: process {} ({}) started: {}",
                    new.pid,
                    new.name(),
                    Joined(argv)
                ));
                slot.process = new;
                Ok(Some((loaded.entry, loaded.sp, borrowed)))
            }
            Err(e) => {
                k.log(format_args!(
                    "guest: process {} cannot execute {}: {e}",
                    old.pid,
                    Joined(&[file])
                ));
                Ok(None)
            }
        }
    }

    /// Process in slot `i` ended with wait status `word`: its files close, its task and
    /// memory go, its children become init's, and it stays a zombie for its parent.
    fn end(&mut self, i: usize, word: u32, fs: &mut Fs, k: &mut impl Tasks) -> Option<Outcome> {
        // A thread's end by a signal or `exit_group` is its process's: all its threads.
        let tgid = self.slots[i].as_ref()?.process.tgid;
        self.end_threads(tgid, k);
        let i = self.index(tgid)?;
        let slot = self.slots[i].as_mut()?;
        let pid = slot.process.pid;
        // A vfork child runs in this process's memory, which goes now: it goes too.
        let borrower = match slot.state {
            State::Vforked { child, .. } => self.index(child),
            _ => None,
        };
        if let Some(j) = borrower
            && let Some(ended) = self.end(j, signal::SIGKILL, fs, k)
        {
            return Some(ended);
        }
        let slot = self.slots[i].as_mut()?;
        close_files(
            &mut slot.process,
            &mut self.pipes,
            &mut self.events,
            &mut self.net,
            fs,
            false,
        );
        k.release(pid);
        let slot = self.slots[i].as_mut()?;
        slot.state = State::Zombie(word);
        slot.stopped = false;
        slot.report = None;
        if pid != INIT_PID
            && let Some(ended) = self.release_vfork_parent(pid, fs, k)
        {
            return Some(ended);
        }
        let slot = self.slots[i].as_mut()?;
        let parent = slot.process.ppid;
        for s in self.slots.iter_mut().flatten() {
            if s.process.ppid == pid {
                s.process.ppid = INIT_PID;
            }
        }
        if pid == INIT_PID {
            return Some(if word & 0x7f != 0 {
                Outcome::Killed(word & 0x7f)
            } else {
                Outcome::Exit((word >> 8) as u8)
            });
        }
        // Nobody waits for it without a parent, or with one that ignores SIGCHLD or set
        // SA_NOCLDWAIT (Linux reaps such children at once).
        let reaped = self.process(parent).is_none_or(|p| {
            let action = p.action(SIGCHLD);
            action.handler == signal::SIG_IGN || action.flags & signal::SA_NOCLDWAIT != 0
        });
        if reaped {
            self.slots[i] = None;
        } else {
            let info = child_info(pid, word);
            self.notify_parent(parent, pid, info.code, info.status);
        }
        None
    }

    /// Ends every process (the guest ends).
    pub fn release_all(&mut self, fs: &mut Fs, k: &mut impl Tasks) {
        for slot in self.slots.iter_mut() {
            if let Some(s) = slot.take()
                && !matches!(s.state, State::Zombie(_))
            {
                let mut process = s.process;
                close_files(
                    &mut process,
                    &mut self.pipes,
                    &mut self.events,
                    &mut self.net,
                    fs,
                    false,
                );
                k.release(process.pid);
            }
        }
    }
}

/// The processes other than the one a call is served for, as `/proc` sees them.
struct Others<'s> {
    before: &'s [Option<Slot>],
    after: &'s [Option<Slot>],
}

impl Others<'_> {
    fn slots(&self) -> impl Iterator<Item = &Slot> {
        self.before.iter().chain(self.after).flatten()
    }
}

impl ProcessTable for Others<'_> {
    fn find(&self, pid: u32) -> Option<ProcInfo<'_>> {
        let slot = self.slots().find(|s| s.process.pid == pid)?;
        let state = match slot.state {
            State::Running | State::Starting(_) => b'R',
            State::Blocked(_) | State::Vforked { .. } => b'S',
            State::Zombie(_) => b'Z',
        };
        Some(ProcInfo::of(&slot.process, state))
    }

    fn each_pid(&self, f: &mut dyn FnMut(u32)) {
        for s in self.slots() {
            f(s.process.pid);
        }
    }
}

/// The strings `execve` copies out of the process: NUL-separated in `bytes`.
struct Strings {
    bytes: [u8; ARG_MAX],
    spans: [(usize, usize); MAX_STRINGS + 1],
    used: usize,
    count: usize,
}

impl Strings {
    fn push(&mut self, p: &Process, k: &mut impl Host, address: u64) -> SysResult<()> {
        if self.count == self.spans.len() {
            return Err(Errno::E2BIG);
        }
        let s = syscall::read_cstr(p, k, address, &mut self.bytes[self.used..]).map_err(|e| {
            if e == Errno::ENAMETOOLONG {
                Errno::E2BIG
            } else {
                e
            }
        })?;
        let len = s.len();
        self.spans[self.count] = (self.used, len);
        self.used += len + 1;
        self.count += 1;
        Ok(())
    }
}

/// The errno `execve` returns for a program it cannot start.
fn exec_errno(e: ExecError) -> Errno {
    match e {
        ExecError::Lookup(e) => e,
        ExecError::NotAFile | ExecError::NotExecutable => Errno::EACCES,
        ExecError::Memory(e) => e,
        _ => Errno::ENOEXEC,
    }
}

/// Arguments separated by spaces (invalid UTF-8 shown as `?`).
pub struct Joined<'s>(pub &'s [&'s [u8]]);

impl core::fmt::Display for Joined<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        for (i, a) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(" ")?;
            }
            for chunk in a.utf8_chunks() {
                f.write_str(chunk.valid())?;
                for b in chunk.invalid() {
                    write!(f, "\\x{b:02x}")?;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pids_wrap_below_pid_max() {
        assert_eq!(next_pid(2), 3);
        assert_eq!(next_pid(PID_MAX - 2), PID_MAX - 1);
        assert_eq!(next_pid(PID_MAX - 1), INIT_PID + 1);
    }
}
