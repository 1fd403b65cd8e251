//! The state the guest keeps for one Linux process: identity, address-space areas and
//! heap, open files, signal dispositions, and what the C library registered
//! (`set_tid_address`, `set_robust_list`). The system calls change it
//! ([`crate::syscall::handle`]); the partition program owns one per process.

use crate::linux;
use crate::memory::{Area, AreaError, Areas, Kind, STACK_SIZE, STACK_TOP};
use crate::signal::{Action, AltStack, Info};
use crate::vfs::{self, Node, OpenId, PathBuf};
use alloc::vec::Vec;

/// Most descriptors a process may have: the highest `RLIMIT_NOFILE` root may set. The
/// table grows with the highest descriptor in use, so a process pays only for those.
pub const MAX_FILES: usize = 4096;
/// The soft `RLIMIT_NOFILE` a process starts with (Linux's).
pub const DEFAULT_FILES: u64 = 1024;
/// Most bytes of arguments `/proc/<pid>/cmdline` shows (Linux shows them all; `ps`
/// reads one page).
pub const CMDLINE_MAX: usize = 4096;
/// Resource limits (`RLIMIT_*`, 0..16): soft and hard.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limit {
    pub soft: u64,
    pub hard: u64,
}

/// Linux's resource limits of a process (`RLIMIT_*` indices) and what the guest can give:
/// the stack and the descriptors have fixed sizes, the rest no limit of its own.
pub const LIMITS: usize = 16;

/// The limits a process starts with.
pub fn default_limits() -> [Limit; LIMITS] {
    let mut limits = [Limit {
        soft: linux::RLIM_INFINITY,
        hard: linux::RLIM_INFINITY,
    }; LIMITS];
    let fixed = |n: u64| Limit { soft: n, hard: n };
    limits[linux::RLIMIT_STACK as usize] = fixed(crate::memory::STACK_SIZE);
    limits[linux::RLIMIT_NOFILE as usize] = Limit {
        soft: DEFAULT_FILES,
        hard: MAX_FILES as u64,
    };
    limits[linux::RLIMIT_CORE as usize] = fixed(0);
    // Linux's default since 5.16.
    limits[linux::RLIMIT_MEMLOCK as usize] = fixed(8 << 20);
    limits
}

/// The highest hard limit of `resource` root may set: what the guest has for the stack and
/// the descriptors (their fixed sizes), no core dumps; the rest has no limit of its own.
pub fn ceiling(resource: usize) -> u64 {
    match resource as u64 {
        linux::RLIMIT_STACK | linux::RLIMIT_NOFILE | linux::RLIMIT_CORE => {
            default_limits()[resource].hard
        }
        _ => linux::RLIM_INFINITY,
    }
}

/// Longest process name (Linux's `TASK_COMM_LEN` without the NUL).
pub const NAME_LEN: usize = 15;

/// Which console stream a terminal descriptor writes to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stream {
    Stdout,
    Stderr,
}

/// What a descriptor refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum File {
    /// The console: the terminal on COM2 ([`crate::tty`]) or, without one, the log
    /// (reading gives end of file; the stream names the log line). `/dev/console` and
    /// `/dev/tty` open it as `Console(Stream::Stdout)`.
    Console(Stream),
    /// An open file description of the file system ([`crate::vfs::Fs::description`]):
    /// a file, directory, device or `/proc` file with its offset, shared by the
    /// descriptors `dup` and `fork` made of it.
    Open(OpenId),
    /// One end of pipe `pipe` ([`crate::pipe::Pipes`]); `nonblock`: `O_NONBLOCK` (calls
    /// that would wait fail with `EAGAIN`).
    Pipe {
        pipe: usize,
        write: bool,
        nonblock: bool,
    },
    /// End `end` (0 or 1) of a connected pair of `AF_UNIX` stream sockets (`socketpair`,
    /// [`crate::pipe::Pipes::pair`]); `nonblock` as for a pipe end.
    UnixSocket {
        pair: usize,
        end: usize,
        nonblock: bool,
    },
    /// A socket of the guest's stack ([`crate::net`], by its `netstack::SocketId`); its
    /// `O_NONBLOCK` is the socket's, shared by every descriptor of it.
    Socket(usize),
    /// An `eventfd` counter ([`crate::events::Events`], by index); its `O_NONBLOCK` is the
    /// counter's, shared by every descriptor of it.
    Event(usize),
    /// A `timerfd` timer ([`crate::events::Events`]), `O_NONBLOCK` as for `Event`.
    Timer(usize),
    /// An epoll instance ([`crate::events::Events`]).
    Epoll(usize),
}

impl File {
    /// The same file with this descriptor's own `O_NONBLOCK` (a pipe end's, a socket
    /// pair end's); any other file keeps its flags where they live (its description, its
    /// socket, its counter), so it comes back as it is.
    pub fn with_nonblock(self, nonblock: bool) -> File {
        match self {
            File::Pipe { pipe, write, .. } => File::Pipe {
                pipe,
                write,
                nonblock,
            },
            File::UnixSocket { pair, end, .. } => File::UnixSocket {
                pair,
                end,
                nonblock,
            },
            other => other,
        }
    }
}

/// A `futex` wait of a thread: the word's address (in its process's memory), the
/// `FUTEX_WAIT_BITSET` mask, and whether a wake chose it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FutexWait {
    pub address: u64,
    pub bitset: u32,
    pub woken: bool,
}

/// One Linux thread: a process's first thread (the process's state) or one of its other
/// threads ([`Process::thread`]).
#[derive(Clone, Debug)]
pub struct Process {
    /// Its thread id: the pid of a process's first thread, another id for each thread
    /// `clone(CLONE_THREAD)` adds ([`Process::thread`]).
    pub pid: u32,
    /// The thread group (the process's pid, `getpid`): `pid` for a process's first thread.
    pub tgid: u32,
    pub ppid: u32,
    name: [u8; NAME_LEN],
    name_len: usize,
    /// The executable's normalised path (`/proc/self/exe`).
    pub exe: PathBuf,
    /// Its arguments, each NUL-terminated (`/proc/<pid>/cmdline`; at most
    /// [`CMDLINE_MAX`] bytes).
    pub cmdline: Vec<u8>,
    /// The working directory.
    pub cwd: Node,
    pub areas: Areas,
    /// Start of the heap (after the executable) and the current program break.
    pub brk_start: u64,
    pub brk: u64,
    /// The descriptors, as many as the highest one in use (at most [`MAX_FILES`]).
    pub files: Vec<Option<File>>,
    /// Close-on-exec, one bit per descriptor.
    cloexec: Vec<u64>,
    /// Process group and session.
    pub pgid: u32,
    pub sid: u32,
    /// Whether it executed a program since it was forked (`setpgid` on it then fails).
    pub executed: bool,
    /// The disposition of each signal 1..=64 (index `signal - 1`).
    pub sigactions: [Action; 64],
    pub sigmask: u64,
    /// Signals sent and not delivered yet, with what their `siginfo` says (the first of
    /// each kind: standard signals do not queue).
    pub pending: u64,
    pub pending_info: [Info; 64],
    /// The mask to restore after a handler when a call (`rt_sigsuspend`) replaced it only
    /// while it waited.
    pub saved_mask: Option<u64>,
    pub alt_stack: AltStack,
    /// When a `nanosleep` (or a waiting call with a timeout) ends, in the guest's clock.
    pub wake_at: Option<u64>,
    /// When `alarm`/`setitimer(ITIMER_REAL)` raises SIGALRM, and its reload interval.
    pub alarm_at: Option<u64>,
    pub alarm_interval: u64,
    /// Resource limits (`prlimit64`); the descriptor limit bounds new descriptors.
    pub limits: [Limit; LIMITS],
    /// Bytes a blocking pipe `write` moved before it had to wait (it goes on from there
    /// when served again, and returns the whole count, as Linux's blocking writes do).
    pub pipe_written: u64,
    /// The socket whose blocking `connect` the process waits in (served again, the call
    /// asks how the connect went instead of starting another).
    pub connecting: Option<usize>,
    pub umask: u32,
    pub clear_child_tid: u64,
    pub robust_list: u64,
    /// The futex its thread waits on (a `futex` wait kept as a blocked call).
    pub futex: Option<FutexWait>,
    /// Its ranges locked in memory (`mlock`; not inherited by `fork`, gone with `execve`).
    pub locks: crate::memory::Locks,
    /// `mlockall(MCL_FUTURE)` is in force (recorded; new mappings are not counted).
    pub lock_future: bool,
    /// The CPU its thread runs on (one of the guest's: [`crate::system`] places it).
    pub cpu: u32,
    /// The CPUs `sched_setaffinity` allows it (bit n: CPU n; all at first), inherited by
    /// the processes and threads it creates and kept by `execve`, as on Linux.
    pub affinity: u64,
}

impl Process {
    /// A process `pid` running executable `exe` (its name is the last path component),
    /// with the console on descriptors 0, 1 and 2 and no memory yet.
    pub fn new(pid: u32, ppid: u32, exe: PathBuf) -> Self {
        let base = exe.as_str().rsplit('/').next().unwrap_or("").as_bytes();
        let name_len = base.len().min(NAME_LEN);
        let mut name = [0u8; NAME_LEN];
        name[..name_len].copy_from_slice(&base[..name_len]);
        let files = alloc::vec![
            Some(File::Console(Stream::Stdout)),
            Some(File::Console(Stream::Stdout)),
            Some(File::Console(Stream::Stderr)),
        ];
        Self {
            pid,
            tgid: pid,
            ppid,
            name,
            name_len,
            exe,
            cmdline: Vec::new(),
            cwd: Node::Inode(vfs::ROOT),
            areas: Areas::new(),
            brk_start: 0,
            brk: 0,
            files,
            cloexec: Vec::new(),
            pgid: pid,
            sid: pid,
            executed: false,
            sigactions: [Action::DEFAULT; 64],
            sigmask: 0,
            pending: 0,
            pending_info: [Info::default(); 64],
            saved_mask: None,
            alt_stack: AltStack::NONE,
            wake_at: None,
            alarm_at: None,
            alarm_interval: 0,
            limits: default_limits(),
            pipe_written: 0,
            connecting: None,
            umask: 0o022,
            clear_child_tid: 0,
            robust_list: 0,
            futex: None,
            locks: Default::default(),
            lock_future: false,
            cpu: 0,
            affinity: u64::MAX,
        }
    }

    /// Whether it is a thread `clone(CLONE_THREAD)` added (not a process's first thread).
    pub fn is_thread(&self) -> bool {
        self.pid != self.tgid
    }

    /// Thread `tid` of this process (`clone(CLONE_THREAD)`): the caller's signal mask,
    /// nothing pending, and none of the process's shared state. That state (memory,
    /// descriptors, dispositions, ...: [`Process::swap_shared`]) stays with the process's
    /// first thread and is lent to a thread while one of its calls is served.
    pub fn thread(&self, tid: u32) -> Self {
        Self {
            ppid: self.ppid,
            pgid: self.pgid,
            sid: self.sid,
            sigmask: self.sigmask,
            sigactions: self.sigactions,
            tgid: self.tgid,
            name: self.name,
            name_len: self.name_len,
            cpu: self.cpu,
            affinity: self.affinity,
            ..Self::new(tid, self.ppid, self.exe)
        }
    }

    /// Exchanges with `other` everything the threads of a process share (Linux's
    /// `CLONE_VM | CLONE_FILES | CLONE_FS | CLONE_SIGHAND` and the process's own state):
    /// memory areas and heap, descriptors, working directory, dispositions, limits,
    /// umask, memory locks, the alarm, the identity. What is each thread's own stays: its
    /// id, name (`comm`: a thread starts with its creator's, `PR_SET_NAME` renames only
    /// itself, as on Linux), signal mask and pending thread-directed signals, alternate
    /// stack, sleep, futex wait, tid addresses, robust list, CPU and affinity.
    pub fn swap_shared(&mut self, other: &mut Self) {
        use core::mem::swap;
        swap(&mut self.ppid, &mut other.ppid);
        swap(&mut self.exe, &mut other.exe);
        swap(&mut self.cmdline, &mut other.cmdline);
        swap(&mut self.cwd, &mut other.cwd);
        swap(&mut self.areas, &mut other.areas);
        swap(&mut self.brk_start, &mut other.brk_start);
        swap(&mut self.brk, &mut other.brk);
        swap(&mut self.files, &mut other.files);
        swap(&mut self.cloexec, &mut other.cloexec);
        swap(&mut self.pgid, &mut other.pgid);
        swap(&mut self.sid, &mut other.sid);
        swap(&mut self.executed, &mut other.executed);
        swap(&mut self.sigactions, &mut other.sigactions);
        swap(&mut self.alarm_at, &mut other.alarm_at);
        swap(&mut self.alarm_interval, &mut other.alarm_interval);
        swap(&mut self.limits, &mut other.limits);
        swap(&mut self.umask, &mut other.umask);
        swap(&mut self.locks, &mut other.locks);
        swap(&mut self.lock_future, &mut other.lock_future);
    }

    /// Copies from the process's first thread what a thread answers about its process
    /// without a call of its own being served (who is its parent, its group, how it takes
    /// a signal): after the process's state changed.
    pub fn share_from(&mut self, first: &Self) {
        self.ppid = first.ppid;
        self.pgid = first.pgid;
        self.sid = first.sid;
        self.sigactions = first.sigactions;
    }

    /// Records its arguments (`/proc/<pid>/cmdline`), cut at [`CMDLINE_MAX`] bytes; with
    /// no memory for them, none.
    pub fn set_cmdline(&mut self, argv: &[&[u8]]) {
        let len: usize = argv.iter().map(|a| a.len() + 1).sum();
        let len = len.min(CMDLINE_MAX);
        let mut cmdline = Vec::new();
        if cmdline.try_reserve_exact(len).is_err() {
            return;
        }
        for a in argv {
            cmdline.extend_from_slice(a);
            cmdline.push(0);
        }
        cmdline.truncate(len);
        self.cmdline = cmdline;
    }

    /// Sets the name (`prctl(PR_SET_NAME)`; cut to [`NAME_LEN`] bytes).
    pub fn set_name(&mut self, name: &str) {
        let mut len = name.len().min(NAME_LEN);
        while !name.is_char_boundary(len) {
            len -= 1;
        }
        self.name = [0; NAME_LEN];
        self.name[..len].copy_from_slice(&name.as_bytes()[..len]);
        self.name_len = len;
    }

    pub fn name(&self) -> &str {
        core::str::from_utf8(&self.name[..self.name_len]).unwrap_or("?")
    }

    /// Records the executable's areas (one per page run) and where the heap starts.
    pub fn set_image(
        &mut self,
        runs: &[crate::elf::PageRun],
        brk_start: u64,
    ) -> Result<(), AreaError> {
        for r in runs {
            self.areas.insert(Area {
                start: r.start,
                end: r.start + r.pages * crate::memory::PAGE,
                rights: r.rights,
                kind: Kind::Image,
            })?;
        }
        self.brk_start = brk_start;
        self.brk = brk_start;
        Ok(())
    }

    /// The stack's area (`STACK_TOP - STACK_SIZE .. STACK_TOP`), recorded.
    pub fn add_stack(&mut self) -> Result<Area, AreaError> {
        let area = Area {
            start: STACK_TOP - STACK_SIZE,
            end: STACK_TOP,
            rights: crate::memory::Rights::READ | crate::memory::Rights::WRITE,
            kind: Kind::Stack,
        };
        self.areas.insert(area)?;
        Ok(area)
    }

    /// The lowest free descriptor.
    pub fn free_fd(&self) -> Option<usize> {
        self.free_fd_from(0)
    }

    /// The lowest free descriptor from `low` on.
    pub fn free_fd_from(&self, low: usize) -> Option<usize> {
        (low..self.max_fd()).find(|&fd| self.files.get(fd).is_none_or(Option::is_none))
    }

    /// One more than the highest descriptor it may open (`RLIMIT_NOFILE`).
    pub fn max_fd(&self) -> usize {
        let soft = self.limits[crate::linux::RLIMIT_NOFILE as usize].soft;
        usize::try_from(soft).unwrap_or(MAX_FILES).min(MAX_FILES)
    }

    /// Puts `file` at descriptor `fd` (below [`MAX_FILES`], free or closed by the caller
    /// before), with its close-on-exec flag.
    pub fn install(&mut self, fd: usize, file: File, cloexec: bool) {
        if fd >= self.files.len() {
            self.files.resize(fd + 1, None);
        }
        self.files[fd] = Some(file);
        self.set_cloexec(fd, cloexec);
    }

    /// Takes descriptor `fd` out of the table (closing it is the caller's); the table
    /// shrinks to the highest descriptor left.
    pub fn take_fd(&mut self, fd: usize) -> Option<File> {
        let file = self.files.get_mut(fd).and_then(Option::take);
        self.set_cloexec(fd, false);
        while self.files.last() == Some(&None) {
            self.files.pop();
        }
        file
    }

    pub fn set_cloexec(&mut self, fd: usize, on: bool) {
        let (word, bit) = (fd / 64, 1 << (fd % 64));
        if on {
            if word >= self.cloexec.len() {
                self.cloexec.resize(word + 1, 0);
            }
            self.cloexec[word] |= bit;
        } else if let Some(w) = self.cloexec.get_mut(word) {
            *w &= !bit;
        }
    }

    pub fn is_cloexec(&self, fd: usize) -> bool {
        self.cloexec
            .get(fd / 64)
            .is_some_and(|w| w & (1 << (fd % 64)) != 0)
    }

    /// No descriptor is close-on-exec any more (`execve` closed them).
    pub fn clear_cloexec(&mut self) {
        self.cloexec = Vec::new();
    }

    pub fn file(&self, fd: u64) -> Option<File> {
        self.files.get(usize::try_from(fd).ok()?).copied().flatten()
    }

    pub fn action(&self, signal: u32) -> Action {
        self.sigactions[signal as usize - 1]
    }

    /// Makes `info.signal` pending (a standard signal already pending stays as it is).
    pub fn raise(&mut self, info: Info) {
        let bit = crate::signal::bit(info.signal);
        if self.pending & bit == 0 {
            self.pending |= bit;
            self.pending_info[info.signal as usize - 1] = info;
        }
    }

    /// The pending signals its mask does not block.
    pub fn deliverable(&self) -> u64 {
        self.pending & !(self.sigmask & !crate::signal::UNBLOCKABLE)
    }

    /// The signal delivered next: the lowest deliverable one, SIGKILL and SIGSTOP first.
    pub fn next_signal(&self) -> Option<u32> {
        let ready = self.deliverable();
        let first = ready & crate::signal::UNBLOCKABLE;
        let bits = if first != 0 { first } else { ready };
        (bits != 0).then(|| bits.trailing_zeros() + 1)
    }

    /// Takes [`Process::next_signal`] off the pending set.
    pub fn take_signal(&mut self) -> Option<Info> {
        let signal = self.next_signal()?;
        self.pending &= !crate::signal::bit(signal);
        Some(self.pending_info[signal as usize - 1])
    }
}
