//! The guest's processes together: the process table (pids, parents, zombies), the calls
//! that act on more than one process (`clone`/`fork`/`vfork`, `execve`, `wait4`, the end
//! of a process) and the deferred replies.
//!
//! **Deferred replies.** A process's system call arrives as an exception message its
//! thread sent as a `call`: the thread waits until the guest replies, and the guest may
//! reply at any later time. A call that has to wait (`wait4` for a running child, `read`
//! from an empty pipe, `write` to a full one) changes nothing and leaves the process
//! [`State::Blocked`] with its message kept; after every message the guest serves, it
//! serves the kept messages again, in table order, until none makes progress, and replies
//! to each call that completes. So a waiting process never stops the guest from serving
//! the others, and the order of events decides nothing but who runs first.
//!
//! **Fork.** The child is a new task with an eager copy of the parent's pages (the
//! partition program copies them; [`Tasks::fork`]) and a thread started at address 0:
//! its first exception message (the fetch fault) is answered with the parent's registers
//! and `rax = 0`, the child's half of the `fork`. `vfork` and `clone(CLONE_VM |
//! CLONE_VFORK)` are served the same way (a copy, not shared memory; a child that only
//! `execve`s or `_exit`s cannot tell), and the parent waits, as on Linux, until the child
//! executes or ends ([`State::Vforked`]).
//!
//! A parent that ignores `SIGCHLD` (or set `SA_NOCLDWAIT`) leaves no zombies: its
//! children are reaped when they end, and its `wait4` waits until none is left (`ECHILD`).
//!
//! **Limits.** At most [`MAX_PROCESSES`] processes, zombies included, and at most as many
//! as the partition's task quota (`kernel_tasks` minus the guest's own task) lets it create:
//! beyond either, `fork` fails with `EAGAIN`.

use crate::exec::{self, ARG_MAX, ExecError};
use crate::linux::{self, Errno, nr};
use crate::memory::{Areas, PAGE};
use crate::pipe::Pipes;
use crate::process::Process;
use crate::stack::MAX_STRINGS;
use crate::syscall::{self, Host, Outcome, SysResult, close_files, share_files};
use crate::vfs::Fs;
use crate::vfs::proc::{ProcInfo, ProcessTable};
use abi::ipc::{ExceptionMessage, Registers};

/// Most processes of a guest (the default and the ceiling of its process limit).
pub const MAX_PROCESSES: usize = 16;
/// The pid of the first process; orphans become its children.
pub const INIT_PID: u32 = 1;

const CLONE_VM: u64 = 0x100;
const CLONE_VFORK: u64 = 0x4000;
const CLONE_PARENT_SETTID: u64 = 0x10_0000;
const CLONE_CHILD_CLEARTID: u64 = 0x20_0000;
const CLONE_CHILD_SETTID: u64 = 0x100_0000;
const WNOHANG: u64 = 1;
/// Bytes of `struct rusage` (`wait4` fills it with zeros: no accounting yet).
const RUSAGE_SIZE: usize = 144;

/// What the partition program does for the process table, beyond [`Host`] (whose memory
/// calls act on the process [`Tasks::select`] chose last).
pub trait Tasks: Host {
    /// Makes `pid` the process the memory calls of [`Host`] act on.
    fn select(&mut self, pid: u32);
    /// Creates process `child`: a task with a copy of the selected process's memory (the
    /// pages of `areas`, with their rights) and a thread that starts at address 0 with this
    /// guest as its exception handler. Returns how many pages it copied; `EAGAIN` when no
    /// task or thread can be created, `ENOMEM` when the pool is out of pages (then nothing
    /// of the child is left).
    fn fork(&mut self, child: u32, areas: &Areas) -> Result<u64, Errno>;
    /// Ends process `pid`: its task, its memory and its pending console output.
    fn release(&mut self, pid: u32);
    /// Replies to the waiting exception message of `pid`'s thread: it resumes with the
    /// registers of `m`.
    fn resume(&mut self, pid: u32, m: &ExceptionMessage);
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

#[derive(Clone, Debug)]
struct Slot {
    process: Process,
    state: State,
}

/// The wait status of a process that exited with `code`.
pub const fn exit_status(code: u8) -> u32 {
    (code as u32) << 8
}

/// The process table of a guest.
pub struct System {
    slots: [Option<Slot>; MAX_PROCESSES],
    pub pipes: Pipes,
    next_pid: u32,
    /// `AT_HWCAP` for the programs `execve` starts.
    hwcap: u64,
}

impl System {
    /// A table holding `init`, already loaded and running.
    pub fn new(init: Process, hwcap: u64) -> Self {
        let mut slots = [const { None }; MAX_PROCESSES];
        let next_pid = init.pid + 1;
        slots[0] = Some(Slot {
            process: init,
            state: State::Running,
        });
        Self {
            slots,
            pipes: Pipes::new(),
            next_pid,
            hwcap,
        }
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
        let slot = self.slots[i].as_mut()?;
        let ended = match slot.state {
            State::Starting(registers) => {
                slot.state = State::Running;
                m.registers = registers;
                k.resume(pid, &m);
                None
            }
            State::Running => self.run(i, fs, k, m),
            // A blocked or ended process has no thread that could send.
            State::Blocked(_) | State::Vforked { .. } | State::Zombie(_) => None,
        };
        ended.or_else(|| self.wake(fs, k))
    }

    /// Serves the kept messages of blocked processes until none completes.
    fn wake(&mut self, fs: &mut Fs, k: &mut impl Tasks) -> Option<Outcome> {
        loop {
            let mut progress = false;
            for i in 0..MAX_PROCESSES {
                let Some(Slot {
                    state: State::Blocked(m),
                    ..
                }) = self.slots[i]
                else {
                    continue;
                };
                if let Some(slot) = self.slots[i].as_mut() {
                    slot.state = State::Running;
                }
                let ended = self.run(i, fs, k, m);
                if ended.is_some() {
                    return ended;
                }
                progress |= !matches!(
                    self.slots[i],
                    Some(Slot {
                        state: State::Blocked(_),
                        ..
                    })
                );
            }
            if !progress {
                return None;
            }
        }
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
        match syscall::handle(&mut slot.process, &mut self.pipes, fs, &others, k, &mut m) {
            Outcome::Resume => {
                k.resume(pid, &m);
                None
            }
            Outcome::Block => {
                slot.state = State::Blocked(kept);
                None
            }
            Outcome::Exit(code) => self.end(i, exit_status(code), fs, k),
            Outcome::Killed(signal) => self.end(i, signal, fs, k),
            Outcome::Process => {
                let r = &mut m.registers;
                let args = [r.rdi, r.rsi, r.rdx, r.r10, r.r8];
                let (flags, vfork_flags) = (args[0], CLONE_VM | CLONE_VFORK | linux::SIGCHLD);
                let vfork = r.rax == nr::vfork || (r.rax == nr::clone && flags & CLONE_VFORK != 0);
                let result = match r.rax {
                    nr::clone => self.fork(i, fs, k, flags, [args[1], args[2], args[3]], r),
                    nr::fork => self.fork(i, fs, k, linux::SIGCHLD, [0; 3], r),
                    nr::vfork => self.fork(i, fs, k, vfork_flags, [0; 3], r),
                    nr::wait4 => match self.wait(i, k, args[0] as i32, args[1], args[2], args[3]) {
                        Ok(None) => {
                            if let Some(slot) = self.slots[i].as_mut() {
                                slot.state = State::Blocked(kept);
                            }
                            return None;
                        }
                        result => result.map(|pid| pid.unwrap_or(0)),
                    },
                    _ => match self.execve(i, fs, k, args[0], args[1], args[2]) {
                        Ok(Some((entry, sp))) => {
                            m.registers = Registers {
                                rip: entry,
                                rsp: sp,
                                rflags: m.registers.rflags,
                                ..Registers::default()
                            };
                            k.resume(pid, &m);
                            self.release_vfork_parent(pid, k);
                            return None;
                        }
                        // The old image is gone and the new one did not load.
                        Ok(None) => return self.end(i, linux::SIGSEGV, fs, k),
                        Err(e) => Err(e),
                    },
                };
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
                        }
                    }
                    _ => k.resume(pid, &m),
                }
                None
            }
        }
    }

    /// The parent that vforked `child` goes on (the child executed or ended).
    fn release_vfork_parent(&mut self, child: u32, k: &mut impl Tasks) {
        for slot in self.slots.iter_mut().flatten() {
            if let State::Vforked { child: c, reply } = slot.state
                && c == child
            {
                slot.state = State::Running;
                k.resume(slot.process.pid, &reply);
            }
        }
    }

    /// `clone` with fork semantics: a new process with a copy of the caller's memory,
    /// files and registers; `[stack, parent_tid, child_tid]` are `clone`'s arguments.
    fn fork(
        &mut self,
        i: usize,
        fs: &mut Fs,
        k: &mut impl Tasks,
        flags: u64,
        [stack, parent_tid, child_tid]: [u64; 3],
        registers: &Registers,
    ) -> SysResult<u64> {
        const KNOWN: u64 = CLONE_VM
            | CLONE_VFORK
            | CLONE_PARENT_SETTID
            | CLONE_CHILD_CLEARTID
            | CLONE_CHILD_SETTID
            | 0xff;
        let signal = flags & 0xff;
        if flags & !KNOWN != 0 || (signal != linux::SIGCHLD && signal != 0) {
            return Err(Errno::EINVAL); // threads, namespaces, other exit signals
        }
        if flags & CLONE_VM != 0 && flags & CLONE_VFORK == 0 {
            return Err(Errno::EINVAL); // shared memory without vfork: threads
        }
        let free = self
            .slots
            .iter()
            .position(Option::is_none)
            .ok_or(Errno::EAGAIN)?;
        let mut pid = self.next_pid;
        while self.index(pid).is_some() || pid == 0 {
            pid = pid.checked_add(1).unwrap_or(INIT_PID + 1);
        }
        let parent = &self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process;
        let mut child = parent.clone();
        child.pid = pid;
        child.ppid = parent.pid;
        child.clear_child_tid = if flags & CLONE_CHILD_CLEARTID != 0 {
            child_tid
        } else {
            0
        };
        let started = k.now_ns();
        let pages = k.fork(pid, &parent.areas)?;
        let took = k.now_ns().saturating_sub(started);
        share_files(&child, &mut self.pipes, fs);
        k.log(format_args!(
            "guest: process {pid} ({}) forked from {}: {pages} pages copied in {} us",
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
        });
        self.next_pid = pid.checked_add(1).unwrap_or(INIT_PID + 1);
        Ok(pid as u64)
    }

    /// `wait4`: the reaped child's pid (0: none yet, `WNOHANG`), `None` when the caller
    /// has to wait.
    fn wait(
        &mut self,
        i: usize,
        k: &mut impl Tasks,
        which: i32,
        status: u64,
        options: u64,
        rusage: u64,
    ) -> SysResult<Option<u64>> {
        let caller = self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process.pid;
        // No process groups yet: 0 and -pgid wait for any child, as -1 does.
        let matches =
            |s: &Slot| s.process.ppid == caller && (which <= 0 || s.process.pid == which as u32);
        if !self.slots.iter().flatten().any(matches) {
            return Err(Errno::ECHILD);
        }
        let zombie = self.slots.iter().position(|s| {
            s.as_ref()
                .is_some_and(|s| matches(s) && matches!(s.state, State::Zombie(_)))
        });
        let Some(z) = zombie else {
            return Ok((options & WNOHANG != 0).then_some(0));
        };
        let Some(Slot {
            process: child,
            state: State::Zombie(word),
        }) = &self.slots[z]
        else {
            return Err(Errno::ECHILD);
        };
        let (pid, word) = (child.pid, *word);
        let p = &self.slots[i].as_ref().ok_or(Errno::ESRCH)?.process;
        if status != 0 {
            syscall::write_user(p, k, status, &word.to_le_bytes())?;
        }
        if rusage != 0 {
            syscall::write_user(p, k, rusage, &[0; RUSAGE_SIZE])?;
        }
        self.slots[z] = None;
        Ok(Some(pid as u64))
    }

    /// `execve`: `Ok(Some((entry, stack pointer)))` with the new image loaded, `Ok(None)`
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
    ) -> SysResult<Option<(u64, u64)>> {
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
        let (pid, cwd) = (p.pid, p.cwd);
        let (data, _) = exec::find(fs, pid, cwd, file).map_err(exec_errno)?;
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
        let (data, _) = exec::find(fs, pid, cwd, file).map_err(exec_errno)?;
        crate::elf::LoadPlan::new(data).map_err(|_| Errno::ENOEXEC)?;
        if argv.len() + env.len() > MAX_STRINGS {
            return Err(Errno::E2BIG);
        }

        // No return from here: the old image goes.
        let old = &mut slot.process;
        for area in old.areas.iter() {
            k.unmap(area.start, (area.end - area.start) / PAGE);
        }
        close_files(old, &mut self.pipes, fs, true);
        let ids = (old.pid, old.ppid);
        match exec::load_file(fs, k, ids, cwd, file, argv, env, self.hwcap) {
            Ok(loaded) => {
                let mut new = loaded.process;
                new.files = old.files;
                new.cloexec = 0;
                new.sigmask = old.sigmask;
                new.umask = old.umask;
                // Handlers are gone with the image; ignored signals stay ignored.
                for (n, action) in new.sigactions.iter_mut().enumerate() {
                    if old.sigactions[n][0] == linux::SIG_IGN {
                        *action = [linux::SIG_IGN, 0, 0, 0];
                    }
                }
                k.log(format_args!(
                    "guest: process {} ({}) started: {}",
                    new.pid,
                    new.name(),
                    Joined(argv)
                ));
                slot.process = new;
                Ok(Some((loaded.entry, loaded.sp)))
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
        let slot = self.slots[i].as_mut()?;
        let pid = slot.process.pid;
        close_files(&mut slot.process, &mut self.pipes, fs, false);
        k.release(pid);
        self.release_vfork_parent(pid, k);
        let slot = self.slots[i].as_mut()?;
        slot.state = State::Zombie(word);
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
        const SA_NOCLDWAIT: u64 = 2;
        let reaped = self.process(parent).is_none_or(|p| {
            let [handler, flags, ..] = p.sigactions[linux::SIGCHLD as usize - 1];
            handler == linux::SIG_IGN || flags & SA_NOCLDWAIT != 0
        });
        if reaped {
            self.slots[i] = None;
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
                close_files(&mut process, &mut self.pipes, fs, false);
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
