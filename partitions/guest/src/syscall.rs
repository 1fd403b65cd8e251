//! The Linux system calls and faults of a process, as a pure function: [`handle`] takes the
//! exception message the kernel sent for one of the process's threads (its registers) and
//! either edits the registers (the call's result in `rax`) for the reply that resumes the
//! thread, or says the process ends. What needs the real system (process memory, mapping
//! pages, the console, the clock, random bytes, the log) goes through [`Host`], which the
//! partition program implements with kernel calls and the tests with a model.
//!
//! Served (x86-64 numbers in [`crate::linux::nr`]): the file calls of [`file`] (the
//! descriptors, reading and writing, names, status, the working directory), `ioctl`, `brk`,
//! `mmap` (anonymous and file-backed, [`memory`]), `munmap`, `mremap` (in place, or moved
//! with `MREMAP_MAYMOVE`), `mprotect`, `madvise`
//! (`MADV_DONTNEED` drops the pages; other advice is accepted and ignored), the memory
//! locks (`mlock`, `mlock2`, `munlock`, `mlockall`, `munlockall`, against
//! `RLIMIT_MEMLOCK`), `arch_prctl`, `set_tid_address`,
//! `set_robust_list`, the signal and timer calls of [`crate::sigcalls`] (`rt_sigaction`,
//! `rt_sigprocmask`, `rt_sigpending`, `rt_sigreturn`, `rt_sigsuspend`, `pause`,
//! `sigaltstack`, `nanosleep`, `clock_nanosleep`, `alarm`, `getitimer`, `setitimer`), the
//! waits of [`crate::poll`] (`poll`, `ppoll`, `select`, `pselect6`), the socket calls of
//! [`socket`] (`socket`, `socketpair`, `bind`, `listen`, `accept`, `accept4`, `connect`,
//! `sendto`, `recvfrom`, `sendmsg`, `recvmsg`, `shutdown`, `getsockname`, `getpeername`,
//! `setsockopt`, `getsockopt`; `read`, `write`, `ioctl` and `fcntl` of a socket), `prlimit64`, `getrlimit`,
//! `getrandom`, `clock_gettime`, `gettimeofday`, `time`, `uname`, `umask`, `sched_yield`,
//! `prctl` (`PR_SET_NAME`, `PR_GET_NAME`; other options `EINVAL`, logged once),
//! the identity and resource calls of [`crate::info`] (the uid/gid calls, `getrusage`,
//! `times`, `getpriority`, `setpriority`), `getcpu`, `sched_getaffinity`, `sysinfo` and
//! `sched_setaffinity` (the process table's: [`crate::system`]), the identity calls (`getpid`, `getppid`, `gettid`, `getpgrp`, `getuid`, `geteuid`,
//! `getgid`, `getegid`), `exit`, `exit_group`; `clone`, `fork`, `vfork`, `execve`,
//! `wait4`, `waitid`, `kill`, `tkill`, `tgkill`, `futex`, `setpgid`, `getpgid`, `setsid` and
//! `getsid` are the process table's ([`crate::system`]). On the console, `read`
//! takes the terminal's input (waiting for it) and `ioctl` serves the terminal requests
//! of [`crate::tty::ioctl`] when the guest has a terminal ([`Host::tty`]); without one,
//! reading gives end of file and every `ioctl` `ENOTTY`, as on any other file. `rseq` answers `ENOSYS` (as on kernels
//! without it); any other call answers `ENOSYS` and is logged by its Linux name
//! ([`crate::linux::syscall_name`]) once per number and guest ([`Reported`]).
//! Pages are never writable and executable at once (W^X): `mmap` and `mprotect` asking for
//! both fail with `EACCES`.
//! A page fault inside the process's areas backs (or copies) the page and resumes it; any
//! other CPU exception (a page fault outside its memory or against its rights, an invalid
//! opcode, a division by zero, a general-protection fault) raises the matching signal
//! ([`crate::memory::classify_fault`]): its handler runs if the process has one that is not
//! blocked, else the process dies of it.

use crate::arinc;
use crate::linux::{self, Errno};
use crate::memory::{Fault, PAGE, Rights, USER_TOP, classify_fault};
use crate::process::{Process, Stream};
use crate::signal::{self, Info};
use crate::tty::{self, Termios, Tty, Winsize};
use abi::ipc::{ExceptionMessage, VECTOR_INTERRUPT, VECTOR_SYSCALL};
pub use file::{Files, Target, close_files, share_files};
use table::{Args, Ctx};

pub mod events;
pub mod file;
mod handlers;
mod memory;
pub mod socket;
pub mod table;

/// Lowest address `mmap` places mappings at without a hint.
pub const MMAP_BOTTOM: u64 = 1 << 36;
/// Largest heap (`brk` beyond this fails).
pub const MAX_HEAP: u64 = 1 << 30;
/// Most bytes one `write`/`read`/`getrandom` moves (a short count, as Linux may return).
const MAX_TRANSFER: usize = 1 << 20;
/// Most `iovec`s of one `readv`/`writev` (Linux's `IOV_MAX`).
const IOV_MAX: u64 = 1024;

/// What the guest's environment provides to the system calls.
pub trait Host {
    /// Copies the process's memory at `address` into `buf` (the caller checked that the
    /// range lies in readable areas; pages not backed yet read as zeros).
    fn read_user(&mut self, address: u64, buf: &mut [u8]) -> Result<(), Errno>;
    /// Copies `data` into the process's memory at `address` (the caller checked writable
    /// areas, or it is a program being loaded): a page not backed yet is backed, a page
    /// shared with another process (after `fork`) copied first (`ENOMEM` when the guest is
    /// out of memory).
    fn write_user(&mut self, address: u64, data: &[u8]) -> Result<(), Errno>;
    /// Backs `pages` pages at `start` of program image `image` with memory `fill(address,
    /// page)` writes in full (the page's previous contents are undefined) and maps them
    /// with `rights` at once (`ENOMEM` when the guest is out of memory, `EACCES` for rights
    /// it never grants, such as writable and executable at once). `image` names the
    /// contents: the same image and address always give the same bytes (an initramfs
    /// file's inode), so the host may keep the pages and share them copy-on-write with
    /// every process that runs the image ([`crate::frames`]).
    fn map_image(
        &mut self,
        start: u64,
        pages: u64,
        rights: Rights,
        image: u32,
        fill: &mut dyn FnMut(u64, &mut [u8]),
    ) -> Result<(), Errno>;
    /// Unmaps `pages` pages at `start` and drops the process's memory there (pages never
    /// backed are skipped).
    fn unmap(&mut self, start: u64, pages: u64);
    /// The pages at `start` get new rights (their areas changed): the contents stay, the
    /// next access maps them as the areas then allow ([`Host::fault_in`]).
    fn protect(&mut self, start: u64, pages: u64, rights: Rights) -> Result<(), Errno>;
    /// Moves the `pages` pages at `from` to `to` (a free range): their contents go along,
    /// the old addresses are left unmapped (`mremap`).
    fn move_pages(&mut self, from: u64, to: u64, pages: u64);
    /// Backs `page` with the bytes `fill` writes into a zeroed page, unless something backs
    /// it already (a file mapping's page, before its first use; `ENOMEM` when the guest is
    /// out of memory).
    fn fill_in(&mut self, page: u64, fill: &mut dyn FnMut(&mut [u8])) -> Result<(), Errno>;
    /// Makes `page` accessible with `rights` after a page fault its area allows (`write`:
    /// the access writes): backs it with zeroed memory the first time, copies it if it is
    /// shared and written, and maps it (`ENOMEM` when the guest is out of memory).
    fn fault_in(&mut self, page: u64, rights: Rights, write: bool) -> Result<(), Errno>;
    /// Output of process `pid` on the console.
    fn console_write(&mut self, pid: u32, stream: Stream, bytes: &[u8]);
    /// The console's terminal, when the guest has one (COM2): then the console reads its
    /// input and answers the terminal ioctls. Without one, reading the console gives end
    /// of file and the terminal ioctls `ENOTTY`.
    fn tty(&mut self) -> Option<&mut Tty> {
        None
    }
    /// Nanoseconds since the guest started.
    fn now_ns(&mut self) -> u64;
    /// Unix time in ns: the firmware's clock at boot plus the kernel's clock (without a
    /// clock, time since the guest started, as if it started at the epoch).
    fn wall_clock_ns(&mut self) -> u64;
    /// The guest's memory for its processes: total and free bytes.
    fn memory(&mut self) -> (u64, u64);
    /// Copies the FPU/SSE state (FXSAVE image) of the process's thread into `image`.
    fn fpu(&mut self, image: &mut [u8; 512]) -> Result<(), Errno>;
    /// Loads the FPU/SSE state of the process's thread from `image`.
    fn set_fpu(&mut self, image: &[u8; 512]) -> Result<(), Errno>;
    /// From now on `pid`'s thread gets `result` for its call `number` without a message:
    /// the kernel answers it (a result fixed for the thread, such as `getpid`'s). A host
    /// that cannot do so (the default) has the guest serve every call, as before.
    fn answer_always(&mut self, pid: u32, number: u64, result: u32) {
        let _ = (pid, number, result);
    }
    fn random(&mut self, buf: &mut [u8]);
    fn log(&mut self, line: core::fmt::Arguments);
    /// Sends `message` (at most the port's size) on port `port` (an index into the port
    /// table, [`crate::arinc`]) without waiting: `EAGAIN` when its queue is full, `ENXIO`
    /// when the port could not be created.
    fn port_send(&mut self, port: usize, message: &[u8]) -> Result<(), Errno> {
        let _ = (port, message);
        Err(Errno::ENXIO)
    }
    /// Takes a message of port `port` into `buf` (as large as the port's size) without
    /// waiting: `EAGAIN` when there is none.
    fn port_receive(&mut self, port: usize, buf: &mut [u8]) -> Result<arinc::Received, Errno> {
        let _ = (port, buf);
        Err(Errno::ENXIO)
    }
    /// Notifies kernel thread `thread` (of a partition this one shares memory with) with
    /// `bits`: `false` when the kernel refuses, or the host cannot.
    fn notify(&mut self, thread: u64, bits: u64) -> bool {
        let _ = (thread, bits);
        false
    }
    /// A call waits for a port (to read or to write, or in `poll`): its messages arrive
    /// without a word to the guest, so the host serves the waiting calls again soon.
    fn port_wait(&mut self) {}
    /// The guest's CPUs (bit n: CPU n): those its partition's threads may run on. A host
    /// that does not say has CPU 0 alone.
    fn cpus(&mut self) -> u64 {
        1
    }
    /// What port `port` could do now.
    fn port_readiness(&mut self, port: usize) -> arinc::Readiness {
        let _ = port;
        arinc::Readiness {
            readable: false,
            writable: false,
            valid: false,
        }
    }
}

/// How the process goes on after [`handle`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Resume the thread with the (edited) registers of the message.
    Resume,
    /// The process exited with this status (`exit_group`).
    Exit(u8),
    /// The process was killed by this signal.
    Killed(u32),
    /// The call waits for another process (an empty or full pipe): nothing changed; serve
    /// the same message again when something happened, and only then reply.
    Block,
    /// The call is one of the process table's ([`crate::system`]), decoded; the registers
    /// are unchanged.
    Process(ProcessCall),
    /// A fault raised this signal and the process has a handler for it: the process table
    /// delivers it (the registers are those of the faulting instruction).
    Signal(Info),
}

/// A call the process table serves ([`crate::system`]), its arguments decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProcessCall {
    /// `clone`, `fork` (`SIGCHLD`), `vfork` (`CLONE_VM | CLONE_VFORK | SIGCHLD`): `args`
    /// are `clone`'s stack, parent and child tid addresses and TLS base.
    Clone {
        flags: u64,
        args: [u64; 4],
    },
    /// `exit` of a thread that is not its process's first.
    ExitThread,
    /// `futex` with its six arguments.
    Futex {
        args: [u64; 6],
    },
    /// `tkill`, `tgkill`: a signal to one thread.
    KillThread {
        tgid: Option<u32>,
        tid: u32,
        signal: u64,
    },
    Execve {
        path: u64,
        argv: u64,
        envp: u64,
    },
    Wait4 {
        pid: i32,
        status: u64,
        options: u64,
        rusage: u64,
    },
    Waitid {
        idtype: u64,
        id: u64,
        info: u64,
        options: u64,
    },
    /// `kill`, `tkill`, `tgkill`: `target` as `kill` reads it (a pid, 0, -1 or -group).
    Kill {
        target: i64,
        signal: u64,
    },
    SetPgid {
        pid: u64,
        pgid: u64,
    },
    /// `getpgid`, `getsid` (`session`).
    GroupOf {
        pid: u64,
        session: bool,
    },
    SetSid,
    /// `sysinfo`, writing its record at `record`.
    Sysinfo {
        record: u64,
    },
    /// `sched_setaffinity` of thread `pid` (0: the caller): the mask of `len` bytes at
    /// `mask`.
    SetAffinity {
        pid: u64,
        len: u64,
        mask: u64,
    },
}

/// The system calls the guest has logged as unsupported (and `prctl`, for its unsupported
/// options): each is logged once per guest, not once per process, so a loop starting
/// processes that make an unknown call does not flood the log. Numbers 0..511 have a bit
/// each; 511 stands for every number from 511 up.
#[derive(Debug, Default)]
pub struct Reported([u64; 8]);

impl Reported {
    /// Whether `number` is reported for the first time (then it is logged).
    pub fn first(&mut self, number: u64) -> bool {
        let number = number.min(511);
        let word = &mut self.0[(number / 64) as usize];
        let bit = 1 << (number % 64);
        let first = *word & bit == 0;
        *word |= bit;
        first
    }
}

/// Internal results that are no error number: the call would block, or wrote to a pipe
/// without readers.
pub(crate) const WOULD_BLOCK: Errno = Errno(0xfff0);
pub(crate) const BROKEN_PIPE: Errno = Errno(0xfff1);
/// `O_CLOEXEC` (`open`, `pipe2`, `dup3`).
pub const O_CLOEXEC: u64 = 0o2000000;

/// Serves one exception message of process `p`, whose files (the file system, pipes,
/// sockets, and the other processes for `/proc`) are `f`. A system call goes to its
/// handler in [`table`]; a number without one answers `ENOSYS`, logged once per number and
/// guest (`reported`).
pub fn handle(
    p: &mut Process,
    f: Files<'_, '_>,
    reported: &mut Reported,
    host: &mut impl Host,
    m: &mut ExceptionMessage,
) -> Outcome {
    if m.vector == VECTOR_INTERRUPT {
        // Stopped in user code to take a signal ([`crate::system`]): it goes on as it was.
        return Outcome::Resume;
    }
    if m.vector != VECTOR_SYSCALL {
        return fault(p, host, m);
    }
    let number = m.registers.rax;
    let args = Args::of(m);
    let Some(entry) = table::lookup(number) else {
        let e = unsupported(p, reported, host, number);
        return reply(p, m, Err(e));
    };
    let mut ctx = Ctx::new(p, f, reported, host, m);
    let result = (entry.handler)(&mut ctx, args);
    if let Some(outcome) = ctx.outcome {
        return outcome;
    }
    reply(p, m, result)
}

/// Whether serving `m` of process `p` can end no other call's wait, changing only `p`'s
/// state or adding to it: an exception (a page fault maps the sender's memory; any other
/// signals the sender), a call of [`table::CALLER_ONLY`], a `close`, `dup2` or `dup3`
/// that closes no file another call could wait on (the descriptor it closes or replaces
/// is free, the console or a file of the file system), or a `fork`, `vfork` or `clone`
/// (a new process or thread: a `wait4` never waits for a child not yet made). A signal's
/// interruption (`VECTOR_INTERRUPT`) is not: the signal may stop or end the process.
pub fn touches_only_caller(p: &Process, m: &ExceptionMessage) -> bool {
    use crate::process::File;
    let closes_nothing_waited_on =
        |fd: u64| matches!(p.file(fd), None | Some(File::Console(_) | File::Open(_)));
    match m.vector {
        VECTOR_SYSCALL => match m.registers.rax {
            linux::nr::close => closes_nothing_waited_on(m.registers.rdi),
            linux::nr::dup2 | linux::nr::dup3 => closes_nothing_waited_on(m.registers.rsi),
            linux::nr::fork | linux::nr::vfork | linux::nr::clone | linux::nr::clone3 => true,
            number => table::caller_only(number),
        },
        VECTOR_INTERRUPT => false,
        _ => true,
    }
}

/// What a waiting call waits for, as far as the guest's network goes: after the stack's
/// sockets alone changed, [`crate::system`] serves again only the calls that may have
/// become able to finish.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Waits {
    /// A call on one socket of the stack (its id): a read, write, send, receive, accept
    /// or connect of it (and the calls that never wait but change it alone: its `bind`,
    /// `listen`, `shutdown`, options, names, `close`, a `sendfile` to it).
    Socket(usize),
    /// Not on the stack: a child, a futex, a sleep, a signal, or a descriptor that is no
    /// socket of the stack (a pipe, the terminal, an `AF_UNIX` pair).
    Elsewhere,
    /// Possibly on any socket (`poll`, `select`, `epoll_wait`), or a call not known here.
    Anything,
}

/// What the call in `m` of process `p` waits for when it cannot finish, and so what it
/// changes when it does ([`crate::system`]): a call of one socket of the stack changes
/// that socket only (its `close` the socket at most, `sendfile` the socket it writes).
pub fn waits_on(p: &Process, m: &ExceptionMessage) -> Waits {
    use linux::nr;
    if m.vector != VECTOR_SYSCALL {
        return Waits::Anything;
    }
    match m.registers.rax {
        nr::read
        | nr::readv
        | nr::write
        | nr::writev
        | nr::recvfrom
        | nr::sendto
        | nr::recvmsg
        | nr::sendmsg
        | nr::accept
        | nr::accept4
        | nr::connect
        | nr::bind
        | nr::listen
        | nr::shutdown
        | nr::setsockopt
        | nr::getsockopt
        | nr::getsockname
        | nr::getpeername
        | nr::sendfile
        | nr::close => match p.file(m.registers.rdi) {
            Some(crate::process::File::Socket(id)) => Waits::Socket(id),
            _ => Waits::Elsewhere,
        },
        nr::wait4
        | nr::waitid
        | nr::nanosleep
        | nr::clock_nanosleep
        | nr::futex
        | nr::pause
        | nr::rt_sigsuspend
        | nr::rt_sigtimedwait => Waits::Elsewhere,
        _ => Waits::Anything,
    }
}

/// A call the guest does not serve: `ENOSYS`, logged, with its Linux name, the first time
/// a process of the guest makes it.
fn unsupported(p: &Process, reported: &mut Reported, host: &mut impl Host, number: u64) -> Errno {
    if reported.first(number) {
        host.log(format_args!(
            "guest: process {} ({}): unsupported system call {number} ({}), returning ENOSYS",
            p.pid,
            p.name(),
            linux::syscall_name(number).unwrap_or("unknown")
        ));
    }
    Errno::ENOSYS
}

/// Puts the call's `result` in the registers of the reply, or blocks the call.
fn reply(p: &mut Process, m: &mut ExceptionMessage, result: SysResult<u64>) -> Outcome {
    let r = &mut m.registers;
    r.rax = match result {
        Ok(value) => value,
        Err(WOULD_BLOCK) => return Outcome::Block,
        Err(BROKEN_PIPE) => {
            // Delivered (by default: the end of the process) before the call returns.
            p.raise(Info::kernel(signal::SIGPIPE));
            Errno::EPIPE.result()
        }
        Err(e) => e.result(),
    };
    // What the `syscall` instruction leaves in them on Linux.
    r.rcx = r.rip;
    r.r11 = r.rflags;
    Outcome::Resume
}

/// A CPU exception of process `p`: a page fault its areas allow is resolved (the page
/// backed or copied, [`crate::memory::classify_fault`]) and the process resumes; any other
/// raises the matching signal (`SIGBUS` when the guest is out of memory for the page, as
/// Linux when a fault cannot get one), which goes to the process's handler when it has one
/// that the mask does not block ([`Outcome::Signal`]); else the process dies with it (Linux
/// forces the default action of a blocked or ignored fault signal).
fn fault(p: &Process, host: &mut impl Host, m: &ExceptionMessage) -> Outcome {
    let (sig, code) = match classify_fault(&p.areas, m.vector, m.error_code, m.fault_address) {
        Fault::Resolve {
            page,
            rights,
            write,
        } => match host.fault_in(page, rights, write) {
            Ok(()) => return Outcome::Resume,
            Err(_) => (signal::SIGBUS, signal::BUS_ADRERR),
        },
        Fault::Signal { signal, code } => (signal, code),
    };
    let caught = p.action(sig).handler > signal::SIG_IGN && p.sigmask & signal::bit(sig) == 0;
    if caught {
        return Outcome::Signal(Info {
            signal: sig,
            code,
            pid: 0,
            status: 0,
            address: if m.vector == 14 {
                m.fault_address
            } else {
                m.registers.rip
            },
        });
    }
    host.log(format_args!(
        "guest: process {} ({}) killed by signal {sig} ({}): vector {} error {:#x} address {:#x} rip {:#x}",
        p.pid,
        p.name(),
        signal::name(sig),
        m.vector,
        m.error_code,
        m.fault_address,
        m.registers.rip
    ));
    Outcome::Killed(sig)
}

pub(crate) type SysResult<T> = Result<T, Errno>;

/// Whether `address..address + len` lies in areas with `rights`.
pub(crate) fn check_user(p: &Process, address: u64, len: usize, rights: Rights) -> SysResult<()> {
    if len == 0 {
        return Ok(());
    }
    let end = address.checked_add(len as u64).ok_or(Errno::EFAULT)?;
    if end > USER_TOP {
        return Err(Errno::EFAULT);
    }
    let mut at = address;
    while at < end {
        let a = p.areas.find(at).ok_or(Errno::EFAULT)?;
        if !a.rights.contains(rights) || !a.rights.accessible() {
            return Err(Errno::EFAULT);
        }
        at = a.end;
    }
    Ok(())
}

pub(crate) fn read_user(
    p: &Process,
    host: &mut impl Host,
    address: u64,
    buf: &mut [u8],
) -> SysResult<()> {
    check_user(p, address, buf.len(), Rights::READ)?;
    host.read_user(address, buf)
}

pub(crate) fn write_user(
    p: &Process,
    host: &mut impl Host,
    address: u64,
    data: &[u8],
) -> SysResult<()> {
    check_user(p, address, data.len(), Rights::WRITE)?;
    host.write_user(address, data)
}

pub(crate) fn read_u64(p: &Process, host: &mut impl Host, address: u64) -> SysResult<u64> {
    let mut b = [0u8; 8];
    read_user(p, host, address, &mut b)?;
    Ok(u64::from_le_bytes(b))
}

/// A NUL-terminated string of the process (at most `buf.len() - 1` bytes).
pub(crate) fn read_cstr<'b>(
    p: &Process,
    host: &mut impl Host,
    address: u64,
    buf: &'b mut [u8],
) -> SysResult<&'b [u8]> {
    let mut len = 0;
    while len < buf.len() {
        // Up to the end of the page, so no unmapped byte after the NUL is touched.
        let at = address.checked_add(len as u64).ok_or(Errno::EFAULT)?;
        let chunk = ((PAGE - at % PAGE) as usize).min(buf.len() - len);
        read_user(p, host, at, &mut buf[len..len + chunk])?;
        if let Some(nul) = buf[len..len + chunk].iter().position(|&b| b == 0) {
            return Ok(&buf[..len + nul]);
        }
        len += chunk;
    }
    Err(Errno::ENAMETOOLONG)
}

/// Whether clock id `clock` counts wall-clock time (`CLOCK_REALTIME`,
/// `CLOCK_REALTIME_COARSE`).
pub(crate) fn is_realtime(clock: u64) -> bool {
    matches!(clock, 0 | 5)
}

/// The terminal ioctls on a console descriptor ([`crate::tty`]): `ENOTTY` without a
/// terminal or for any other request.
pub(super) fn tty_ioctl(c: &mut Ctx<'_, '_, impl Host>, request: u64, arg: u64) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    use tty::ioctl::*;
    let tty = host.tty().ok_or(Errno::ENOTTY)?;
    match request {
        TCGETS => {
            let bytes = tty.termios().to_bytes();
            write_user(p, host, arg, &bytes)?;
        }
        TCSETS | TCSETSW | TCSETSF => {
            let mut bytes = [0u8; tty::TERMIOS_SIZE];
            read_user(p, host, arg, &mut bytes)?;
            let termios = Termios::from_bytes(&bytes);
            host.tty()
                .ok_or(Errno::ENOTTY)?
                .set_termios(termios, request == TCSETSF);
        }
        TIOCGWINSZ => {
            let bytes = tty.winsize().to_bytes();
            write_user(p, host, arg, &bytes)?;
        }
        TIOCSWINSZ => {
            let mut bytes = [0u8; tty::WINSIZE_SIZE];
            read_user(p, host, arg, &mut bytes)?;
            let size = Winsize::from_bytes(&bytes);
            host.tty().ok_or(Errno::ENOTTY)?.set_winsize(size);
        }
        TIOCGPGRP => {
            let group = tty.foreground();
            write_user(p, host, arg, &group.to_le_bytes())?;
        }
        TIOCSPGRP => {
            let mut bytes = [0u8; 4];
            read_user(p, host, arg, &mut bytes)?;
            let group = i32::from_le_bytes(bytes);
            host.tty().ok_or(Errno::ENOTTY)?.set_foreground(group)?;
        }
        FIONREAD => {
            let n = tty.available() as u32;
            write_user(p, host, arg, &n.to_le_bytes())?;
        }
        TCFLSH => match arg {
            TCIFLUSH | TCIOFLUSH => tty.flush_input(),
            1 => {} // TCOFLUSH: output never waits, nothing to discard
            _ => return Err(Errno::EINVAL),
        },
        // A session leader makes the console its controlling terminal (every process has
        // it as init's session's); output is never stopped.
        TIOCSCTTY => {
            if p.sid == p.pid {
                tty.set_session(p.sid, p.pgid);
            }
        }
        TCXONC => {}
        _ => return Err(Errno::ENOTTY),
    }
    Ok(0)
}
