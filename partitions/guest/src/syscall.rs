//! The Linux system calls and faults of a process, as a pure function: [`handle`] takes the
//! exception message the kernel sent for one of the process's threads (its registers) and
//! either edits the registers (the call's result in `rax`) for the reply that resumes the
//! thread, or says the process ends. What needs the real system (process memory, mapping
//! pages, the console, the clock, random bytes, the log) goes through [`Host`], which the
//! partition program implements with kernel calls and the tests with a model.
//!
//! Served (x86-64 numbers in [`crate::linux::nr`]): `read`, `write`, `readv`, `writev`
//! (the console, initramfs files, pipes), `sendfile` (from an initramfs file to the
//! console; to a pipe `EINVAL`, so callers fall back to `write`), `pipe`, `pipe2`, `dup`,
//! `dup2`, `dup3`, `open`, `openat`, `close`, `lseek`, `getdents64`, `stat`, `lstat`, `fstat`, `newfstatat`, `access`,
//! `faccessat`, `faccessat2`, `readlink`, `readlinkat`, `getcwd`, `ioctl`, `fcntl`, `brk`,
//! `mmap` (anonymous and file-backed, [`memory`]), `munmap`, `mremap` (in place, or moved
//! with `MREMAP_MAYMOVE`), `mprotect`, `madvise`
//! (`MADV_DONTNEED` drops the pages; other advice is accepted and ignored), `arch_prctl`, `set_tid_address`,
//! `set_robust_list`, the signal and timer calls of [`crate::sigcalls`] (`rt_sigaction`,
//! `rt_sigprocmask`, `rt_sigpending`, `rt_sigreturn`, `rt_sigsuspend`, `pause`,
//! `sigaltstack`, `nanosleep`, `clock_nanosleep`, `alarm`, `getitimer`, `setitimer`), the
//! waits of [`crate::poll`] (`poll`, `ppoll`, `select`, `pselect6`), `prlimit64`, `getrlimit`,
//! `getrandom`, `clock_gettime`, `gettimeofday`, `time`, `uname`, `umask`, `sched_yield`,
//! `prctl` (`PR_SET_NAME`, `PR_GET_NAME`; other options `EINVAL`, logged once),
//! the identity and resource calls of [`crate::info`] (the uid/gid calls, `getrusage`,
//! `times`, `sched_getaffinity`, `sched_setaffinity`, `getpriority`, `setpriority`,
//! `futex`), `sysinfo` (the process table's), the identity calls (`getpid`, `getppid`, `gettid`, `getpgrp`, `getuid`, `geteuid`,
//! `getgid`, `getegid`), `exit`, `exit_group`; `clone`, `fork`, `vfork`, `execve`,
//! `wait4`, `waitid`, `kill`, `tkill`, `tgkill`, `setpgid`, `getpgid`, `setsid` and
//! `getsid` are the process table's ([`crate::system`]). `fcntl` serves `F_DUPFD`,
//! `F_DUPFD_CLOEXEC`, `F_GETFD`, `F_SETFD` (close-on-exec), `F_GETFL` and `F_SETFL`
//! (`O_NONBLOCK` of a pipe descriptor: `EAGAIN` instead of waiting). On the console, `read`
//! takes the terminal's input (waiting for it) and `ioctl` serves the terminal requests
//! of [`crate::tty::ioctl`] when the guest has a terminal ([`Host::tty`]); without one,
//! reading gives end of file and every `ioctl` `ENOTTY`, as on any other file. `rseq` answers `ENOSYS` (as on kernels
//! without it); any other call answers `ENOSYS` and is logged once per number and process.
//! Pages are never writable and executable at once (W^X): `mmap` and `mprotect` asking for
//! both fail with `EACCES`.
//! A page fault inside the process's areas backs (or copies) the page and resumes it; any
//! other CPU exception (a page fault outside its memory or against its rights, an invalid
//! opcode, a division by zero, a general-protection fault) raises the matching signal
//! ([`crate::memory::classify_fault`]): its handler runs if the process has one that is not
//! blocked, else the process dies of it.

use crate::cpio::{Archive, Entry, S_IFCHR, S_IFMT};
use crate::linux::{self, Errno, nr};
use crate::memory::{Fault, PAGE, Rights, USER_TOP, classify_fault};
use crate::pipe::{PIPE_SIZE, Pipes, Transfer};
use crate::poll;
use crate::process::{File, MAX_FILES, Process, Stream};
use crate::sigcalls;
use crate::signal::{self, Info, SIGSEGV};
use crate::tty::{self, Termios, Tty, Winsize};
use crate::vfs;
use abi::ipc::{ExceptionMessage, Registers, VECTOR_INTERRUPT, VECTOR_SYSCALL};
use memory::{brk, fill_file_pages, madvise, mmap, mprotect, mremap, munmap};

mod memory;

/// Lowest address `mmap` places mappings at without a hint.
pub const MMAP_BOTTOM: u64 = 1 << 36;
/// Largest heap (`brk` beyond this fails).
pub const MAX_HEAP: u64 = 1 << 30;
/// Most bytes one `write`/`read`/`getrandom` moves (a short count, as Linux may return).
const MAX_TRANSFER: usize = 1 << 20;
/// Most `iovec`s of one `readv`/`writev` (Linux's `IOV_MAX`).
const IOV_MAX: u64 = 1024;
/// The device numbers of the console (`/dev/console`, 5:1).
const CONSOLE_RDEV: u64 = 5 << 8 | 1;

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
    /// The guest's memory for its processes: total and free bytes.
    fn memory(&mut self) -> (u64, u64);
    /// Copies the FPU/SSE state (FXSAVE image) of the process's thread into `image`.
    fn fpu(&mut self, image: &mut [u8; 512]) -> Result<(), Errno>;
    /// Loads the FPU/SSE state of the process's thread from `image`.
    fn set_fpu(&mut self, image: &[u8; 512]) -> Result<(), Errno>;
    fn random(&mut self, buf: &mut [u8]);
    fn log(&mut self, line: core::fmt::Arguments);
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
    /// The call is one of the process table's ([`crate::system`]): `clone`, `fork`,
    /// `vfork`, `execve`, `wait4`, `waitid`, `kill`, `tkill`, `tgkill`, the process-group
    /// and session calls.
    Process,
    /// A fault raised this signal and the process has a handler for it: the process table
    /// delivers it (the registers are those of the faulting instruction).
    Signal(Info),
}

/// Internal results that are no error number: the call would block, or wrote to a pipe
/// without readers.
pub(crate) const WOULD_BLOCK: Errno = Errno(0xfff0);
const BROKEN_PIPE: Errno = Errno(0xfff1);
/// `O_CLOEXEC` (`open`, `pipe2`, `dup3`).
pub const O_CLOEXEC: u64 = 0o2000000;

/// Serves one exception message of process `p`, whose files live in `fs` and whose pipes
/// are in `pipes`.
pub fn handle<'a>(
    p: &mut Process<'a>,
    pipes: &mut Pipes,
    fs: &Archive<'a>,
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
    let r = &mut m.registers;
    let number = r.rax;
    let args = [r.rdi, r.rsi, r.rdx, r.r10, r.r8, r.r9];
    let result = match number {
        nr::exit | nr::exit_group => {
            let status = args[0] as u8;
            host.log(format_args!(
                "guest: process {} exited with status {status}",
                p.pid
            ));
            return Outcome::Exit(status);
        }
        nr::clone
        | nr::fork
        | nr::vfork
        | nr::execve
        | nr::wait4
        | nr::waitid
        | nr::kill
        | nr::tkill
        | nr::tgkill
        | nr::setpgid
        | nr::getpgid
        | nr::setsid
        | nr::getsid
        | nr::sysinfo => return Outcome::Process,
        nr::rt_sigreturn => {
            return match sigcalls::sigreturn(p, host, m) {
                Some(()) => Outcome::Resume,
                None => {
                    host.log(format_args!(
                        "guest: process {} ({}) killed by signal {SIGSEGV} (SIGSEGV): rt_sigreturn without a readable signal frame",
                        p.pid,
                        p.name()
                    ));
                    Outcome::Killed(SIGSEGV)
                }
            };
        }
        _ => match crate::info::call(p, host, number, args) {
            Some(result) => result,
            None => call(p, pipes, fs, host, number, args, r),
        },
    };
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
        } => match fill_file_pages(p, host, page, PAGE)
            .and_then(|()| host.fault_in(page, rights, write))
        {
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

/// [`check_user`], then the pages of file mappings in the range are filled from their
/// files if they were never touched (before the guest reads or writes them for a call).
pub(crate) fn prepare_user(
    p: &Process,
    host: &mut impl Host,
    address: u64,
    len: usize,
    rights: Rights,
) -> SysResult<()> {
    check_user(p, address, len, rights)?;
    fill_file_pages(p, host, address, len as u64)
}

pub(crate) fn read_user(
    p: &Process,
    host: &mut impl Host,
    address: u64,
    buf: &mut [u8],
) -> SysResult<()> {
    prepare_user(p, host, address, buf.len(), Rights::READ)?;
    host.read_user(address, buf)
}

pub(crate) fn write_user(
    p: &Process,
    host: &mut impl Host,
    address: u64,
    data: &[u8],
) -> SysResult<()> {
    prepare_user(p, host, address, data.len(), Rights::WRITE)?;
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

#[allow(clippy::too_many_arguments)] // the call, its arguments and what it acts on
fn call<'a>(
    p: &mut Process<'a>,
    pipes: &mut Pipes,
    fs: &Archive<'a>,
    host: &mut impl Host,
    number: u64,
    a: [u64; 6],
    regs: &mut Registers,
) -> SysResult<u64> {
    match number {
        nr::read => read(p, pipes, host, a[0], a[1], a[2]),
        nr::write => write(p, pipes, host, a[0], a[1], a[2]),
        nr::sendfile => sendfile(p, host, a[0], a[1], a[2], a[3]),
        nr::readv | nr::writev => vectored(p, pipes, host, number == nr::writev, a[0], a[1], a[2]),
        nr::open => openat(p, fs, host, linux::AT_FDCWD as u64, a[0], a[1]),
        nr::openat => openat(p, fs, host, a[0], a[1], a[2]),
        nr::close => {
            let fd = usize::try_from(a[0]).map_err(|_| Errno::EBADF)?;
            p.file(a[0]).ok_or(Errno::EBADF)?;
            close(p, pipes, fd);
            Ok(0)
        }
        nr::dup => {
            let file = p.file(a[0]).ok_or(Errno::EBADF)?;
            let fd = p.free_fd().ok_or(Errno::EMFILE)?;
            duplicate(p, pipes, file, fd, false);
            Ok(fd as u64)
        }
        nr::dup2 | nr::dup3 => {
            let flags = if number == nr::dup3 { a[2] } else { 0 };
            if flags & !O_CLOEXEC != 0 || (number == nr::dup3 && a[0] == a[1]) {
                return Err(Errno::EINVAL);
            }
            let file = p.file(a[0]).ok_or(Errno::EBADF)?;
            let fd = usize::try_from(a[1])
                .ok()
                .filter(|&fd| fd < MAX_FILES)
                .ok_or(Errno::EBADF)?;
            if a[0] != a[1] {
                close(p, pipes, fd);
                duplicate(p, pipes, file, fd, flags & O_CLOEXEC != 0);
            }
            Ok(fd as u64)
        }
        nr::pipe => pipe(p, pipes, host, a[0], 0),
        nr::pipe2 => pipe(p, pipes, host, a[0], a[1]),
        nr::lseek => lseek(p, a[0], a[1] as i64, a[2]),
        nr::getdents64 => getdents64(p, fs, host, a[0], a[1], a[2]),
        nr::stat | nr::lstat => {
            let follow = number == nr::stat;
            let entry = lookup_at(p, fs, host, linux::AT_FDCWD as u64, a[0], follow)?;
            write_stat(p, host, a[1], &stat_of(Some(&entry)))
        }
        nr::fstat => {
            let st = stat_of_fd(p, a[0])?;
            write_stat(p, host, a[1], &st)
        }
        nr::newfstatat => {
            let (dirfd, path, buf, flags) = (a[0], a[1], a[2], a[3]);
            if flags & linux::AT_EMPTY_PATH != 0 {
                let mut b = [0u8; 1];
                if read_cstr(p, host, path, &mut b).is_ok_and(|s| s.is_empty()) {
                    let st = stat_of_fd(p, dirfd)?;
                    return write_stat(p, host, buf, &st);
                }
            }
            let follow = flags & linux::AT_SYMLINK_NOFOLLOW == 0;
            let entry = lookup_at(p, fs, host, dirfd, path, follow)?;
            write_stat(p, host, buf, &stat_of(Some(&entry)))
        }
        nr::access => access(p, fs, host, linux::AT_FDCWD as u64, a[0], a[1]),
        nr::faccessat | nr::faccessat2 => access(p, fs, host, a[0], a[1], a[2]),
        nr::readlink => readlink(p, fs, host, linux::AT_FDCWD as u64, a[0], a[1], a[2]),
        nr::readlinkat => readlink(p, fs, host, a[0], a[1], a[2], a[3]),
        nr::getcwd => {
            if a[1] < 2 {
                return Err(Errno::ERANGE);
            }
            write_user(p, host, a[0], b"/\0")?;
            Ok(2)
        }
        nr::ioctl => match p.file(a[0]).ok_or(Errno::EBADF)? {
            File::Console(_) => tty_ioctl(p, host, a[1], a[2]),
            _ => Err(Errno::ENOTTY),
        },
        nr::fcntl => fcntl(p, pipes, a[0], a[1], a[2]),
        nr::brk => Ok(brk(p, host, a[0])),
        nr::mmap => mmap(p, host, a),
        nr::munmap => munmap(p, host, a[0], a[1]),
        nr::mprotect => mprotect(p, host, a[0], a[1], a[2]),
        nr::madvise => madvise(p, host, a[0], a[1], a[2]),
        nr::mremap => mremap(p, host, a[0], a[1], a[2], a[3]),
        nr::arch_prctl => arch_prctl(p, host, regs, a[0], a[1]),
        nr::set_tid_address => {
            p.clear_child_tid = a[0];
            Ok(p.pid as u64)
        }
        nr::set_robust_list => {
            // Its one valid length: sizeof(struct robust_list_head).
            if a[1] != 24 {
                return Err(Errno::EINVAL);
            }
            p.robust_list = a[0];
            Ok(0)
        }
        nr::rseq => Err(Errno::ENOSYS),
        nr::rt_sigaction => sigcalls::sigaction(p, host, a[0], a[1], a[2], a[3]),
        nr::rt_sigprocmask => sigcalls::sigprocmask(p, host, a[0], a[1], a[2], a[3]),
        nr::rt_sigpending => sigcalls::sigpending(p, host, a[0], a[1]),
        nr::sigaltstack => sigcalls::sigaltstack(p, host, regs.rsp, a[0], a[1]),
        nr::rt_sigsuspend => sigcalls::sigsuspend(p, host, a[0], a[1]),
        nr::pause => Err(WOULD_BLOCK),
        nr::nanosleep => sigcalls::sleep(p, host, linux::CLOCK_MONOTONIC, 0, a[0]),
        nr::clock_nanosleep => sigcalls::sleep(p, host, a[0], a[1], a[2]),
        nr::alarm => Ok(sigcalls::alarm(p, host, a[0])),
        nr::poll => {
            let timeout = poll::poll_timeout(a[2]);
            poll::poll(p, pipes, host, a[0], a[1], timeout, 0, 0)
        }
        nr::ppoll => {
            let timeout = poll::ppoll_timeout(p, host, a[2])?;
            poll::poll(p, pipes, host, a[0], a[1], timeout, a[3], a[4])
        }
        nr::select => poll::select(p, pipes, host, a, false),
        nr::pselect6 => poll::select(p, pipes, host, a, true),
        nr::getitimer => sigcalls::getitimer(p, host, a[0], a[1]),
        nr::setitimer => sigcalls::setitimer(p, host, a[0], a[1], a[2]),
        nr::prlimit64 => {
            if a[0] != 0 && a[0] != p.pid as u64 {
                return Err(Errno::ESRCH);
            }
            if a[2] != 0 {
                return Err(Errno::EPERM); // the limits are fixed
            }
            rlimit(p, host, a[1], a[3])
        }
        nr::getrlimit => rlimit(p, host, a[0], a[1]),
        nr::getrandom => {
            if a[2] & !7 != 0 {
                return Err(Errno::EINVAL);
            }
            let mut bytes = [0u8; 256];
            let n = (a[1] as usize).min(bytes.len());
            host.random(&mut bytes[..n]);
            write_user(p, host, a[0], &bytes[..n])?;
            Ok(n as u64)
        }
        nr::clock_gettime => {
            // CLOCK_REALTIME .. CLOCK_BOOTTIME; there is no real-time clock yet, so the
            // wall clock starts at the epoch when the guest starts.
            if a[0] > 7 {
                return Err(Errno::EINVAL);
            }
            let ns = host.now_ns();
            let mut ts = [0u8; 16];
            ts[..8].copy_from_slice(&(ns / 1_000_000_000).to_le_bytes());
            ts[8..].copy_from_slice(&(ns % 1_000_000_000).to_le_bytes());
            write_user(p, host, a[1], &ts)?;
            Ok(0)
        }
        nr::gettimeofday => {
            let ns = host.now_ns();
            if a[0] != 0 {
                let mut tv = [0u8; 16];
                tv[..8].copy_from_slice(&(ns / 1_000_000_000).to_le_bytes());
                tv[8..].copy_from_slice(&(ns % 1_000_000_000 / 1000).to_le_bytes());
                write_user(p, host, a[0], &tv)?;
            }
            Ok(0)
        }
        nr::time => {
            let seconds = host.now_ns() / 1_000_000_000;
            if a[0] != 0 {
                write_user(p, host, a[0], &seconds.to_le_bytes())?;
            }
            Ok(seconds)
        }
        nr::uname => {
            let mut u = [0u8; 6 * 65];
            for (i, field) in [
                &b"Linux"[..],
                b"warden",
                b"6.1.0-warden",
                b"#1 Warden paravirtualized guest",
                b"x86_64",
                b"(none)",
            ]
            .iter()
            .enumerate()
            {
                u[i * 65..i * 65 + field.len()].copy_from_slice(field);
            }
            write_user(p, host, a[0], &u)?;
            Ok(0)
        }
        nr::umask => {
            let old = p.umask;
            p.umask = a[0] as u32 & 0o777;
            Ok(old as u64)
        }
        nr::prctl => prctl(p, host, a[0], a[1]),
        nr::sched_yield => Ok(0),
        nr::getpid | nr::gettid => Ok(p.pid as u64),
        nr::getpgrp => Ok(p.pgid as u64),
        nr::getppid => Ok(p.ppid as u64),
        nr::getuid | nr::geteuid | nr::getgid | nr::getegid => Ok(0),
        _ => {
            if p.first_unsupported(number) {
                host.log(format_args!(
                    "guest: process {} ({}): unsupported system call {number} ({}), returning ENOSYS",
                    p.pid,
                    p.name(),
                    linux::syscall_name(number).unwrap_or("unknown")
                ));
            }
            Err(Errno::ENOSYS)
        }
    }
}

/// Closes descriptor `fd` if open (a pipe end counts one descriptor less).
fn close(p: &mut Process, pipes: &mut Pipes, fd: usize) {
    if let Some(File::Pipe { pipe, write, .. }) = p.files.get_mut(fd).and_then(Option::take) {
        pipes.close_end(pipe, write);
    }
    if fd < MAX_FILES {
        p.set_cloexec(fd, false);
    }
}

/// Closes every descriptor of `p` (it ends), or only the close-on-exec ones (`execve`).
pub fn close_files(p: &mut Process, pipes: &mut Pipes, only_cloexec: bool) {
    for fd in 0..MAX_FILES {
        if !only_cloexec || p.is_cloexec(fd) {
            close(p, pipes, fd);
        }
    }
}

/// Another descriptor of every pipe end `p` has open (a forked child's copies).
pub fn share_files(p: &Process, pipes: &mut Pipes) {
    for file in p.files.iter().flatten() {
        if let File::Pipe { pipe, write, .. } = *file {
            pipes.add_end(pipe, write);
        }
    }
}

/// Puts a copy of `file` at the free descriptor `fd`.
fn duplicate<'a>(p: &mut Process<'a>, pipes: &mut Pipes, file: File<'a>, fd: usize, cloexec: bool) {
    if let File::Pipe { pipe, write, .. } = file {
        pipes.add_end(pipe, write);
    }
    p.install(fd, file, cloexec);
}

fn pipe(
    p: &mut Process,
    pipes: &mut Pipes,
    host: &mut impl Host,
    fds: u64,
    flags: u64,
) -> SysResult<u64> {
    if flags & !(O_CLOEXEC | linux::O_NONBLOCK) != 0 {
        return Err(Errno::EINVAL);
    }
    prepare_user(p, host, fds, 8, Rights::WRITE)?;
    let read_fd = p.free_fd().ok_or(Errno::EMFILE)?;
    let write_fd = p.free_fd_from(read_fd + 1).ok_or(Errno::EMFILE)?;
    let index = pipes.open().ok_or(Errno::ENFILE)?;
    let cloexec = flags & O_CLOEXEC != 0;
    for (fd, write) in [(read_fd, false), (write_fd, true)] {
        let end = File::Pipe {
            pipe: index,
            write,
            nonblock: flags & linux::O_NONBLOCK != 0,
        };
        p.install(fd, end, cloexec);
    }
    let mut pair = [0u8; 8];
    pair[..4].copy_from_slice(&(read_fd as u32).to_le_bytes());
    pair[4..].copy_from_slice(&(write_fd as u32).to_le_bytes());
    host.write_user(fds, &pair)?;
    Ok(0)
}

fn read(
    p: &mut Process,
    pipes: &mut Pipes,
    host: &mut impl Host,
    fd: u64,
    buf: u64,
    count: u64,
) -> SysResult<u64> {
    match p.file(fd).ok_or(Errno::EBADF)? {
        File::Console(_) => {
            let n = (count as usize).min(tty::INPUT_MAX);
            check_user(p, buf, n, Rights::WRITE)?;
            let Some(tty) = host.tty() else {
                return Ok(0); // no terminal: end of file
            };
            if tty.session() == p.sid && tty.foreground() != p.pgid {
                // A background job reading its terminal: SIGTTIN stops it, and the read
                // starts again when it is continued (in the foreground); EIO when it
                // would not stop.
                let ttin = signal::SIGTTIN;
                if p.action(ttin).ignores(ttin) || p.sigmask & signal::bit(ttin) != 0 {
                    return Err(Errno::EIO);
                }
                p.raise(Info::kernel(ttin));
                return Err(WOULD_BLOCK);
            }
            let mut bytes = [0u8; tty::INPUT_MAX];
            let n = tty.read(&mut bytes[..n]).ok_or(WOULD_BLOCK)?;
            host.write_user(buf, &bytes[..n])?;
            Ok(n as u64)
        }
        File::Pipe { write: true, .. } => Err(Errno::EBADF),
        File::Pipe { pipe, nonblock, .. } => {
            let n = (count as usize).min(PIPE_SIZE);
            prepare_user(p, host, buf, n, Rights::WRITE)?;
            let mut bytes = [0u8; PIPE_SIZE];
            match pipes.read(pipe, &mut bytes[..n]) {
                Transfer::Done(n) => {
                    host.write_user(buf, &bytes[..n])?;
                    Ok(n as u64)
                }
                Transfer::WouldBlock if nonblock => Err(Errno::EAGAIN),
                Transfer::WouldBlock => Err(WOULD_BLOCK),
                Transfer::Broken => Err(Errno::EBADF),
            }
        }
        File::Initramfs { entry, offset } => {
            if entry.is_dir() {
                return Err(Errno::EISDIR);
            }
            let start = (offset as usize).min(entry.data.len());
            let n = (count as usize)
                .min(entry.data.len() - start)
                .min(MAX_TRANSFER);
            write_user(p, host, buf, &entry.data[start..start + n])?;
            p.files[fd as usize] = Some(File::Initramfs {
                entry,
                offset: offset + n as u64,
            });
            Ok(n as u64)
        }
    }
}

fn write(
    p: &mut Process,
    pipes: &mut Pipes,
    host: &mut impl Host,
    fd: u64,
    buf: u64,
    count: u64,
) -> SysResult<u64> {
    let stream = match p.file(fd).ok_or(Errno::EBADF)? {
        File::Console(stream) => stream,
        File::Initramfs { .. } | File::Pipe { write: false, .. } => return Err(Errno::EBADF),
        File::Pipe { pipe, nonblock, .. } => {
            let n = (count as usize).min(PIPE_SIZE);
            let mut bytes = [0u8; PIPE_SIZE];
            read_user(p, host, buf, &mut bytes[..n])?;
            return match pipes.write(pipe, &bytes[..n]) {
                Transfer::Done(n) => Ok(n as u64),
                Transfer::WouldBlock if nonblock => Err(Errno::EAGAIN),
                Transfer::WouldBlock => Err(WOULD_BLOCK),
                Transfer::Broken => Err(BROKEN_PIPE),
            };
        }
    };
    let total = (count as usize).min(MAX_TRANSFER);
    prepare_user(p, host, buf, total, Rights::READ)?;
    let mut chunk = [0u8; 512];
    let mut done = 0;
    while done < total {
        let n = (total - done).min(chunk.len());
        host.read_user(buf + done as u64, &mut chunk[..n])?;
        host.console_write(p.pid, stream, &chunk[..n]);
        done += n;
    }
    Ok(total as u64)
}

/// The terminal ioctls on a console descriptor ([`crate::tty`]): `ENOTTY` without a
/// terminal or for any other request.
fn tty_ioctl(p: &Process, host: &mut impl Host, request: u64, arg: u64) -> SysResult<u64> {
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

fn sendfile(
    p: &mut Process,
    host: &mut impl Host,
    out_fd: u64,
    in_fd: u64,
    offset_ptr: u64,
    count: u64,
) -> SysResult<u64> {
    let stream = match p.file(out_fd).ok_or(Errno::EBADF)? {
        File::Console(stream) => stream,
        File::Initramfs { .. } => return Err(Errno::EBADF), // opened read-only
        File::Pipe { .. } => return Err(Errno::EINVAL),     // the caller falls back to write
    };
    let File::Initramfs { entry, offset } = p.file(in_fd).ok_or(Errno::EBADF)? else {
        return Err(Errno::EINVAL); // no console input to copy
    };
    if entry.is_dir() {
        return Err(Errno::EINVAL);
    }
    let from = if offset_ptr != 0 {
        read_u64(p, host, offset_ptr)?
    } else {
        offset
    };
    let start = from.min(entry.data.len() as u64) as usize;
    let n = (count as usize)
        .min(entry.data.len() - start)
        .min(MAX_TRANSFER);
    if offset_ptr != 0 {
        write_user(p, host, offset_ptr, &(from + n as u64).to_le_bytes())?;
    } else {
        p.files[in_fd as usize] = Some(File::Initramfs {
            entry,
            offset: from + n as u64,
        });
    }
    host.console_write(p.pid, stream, &entry.data[start..start + n]);
    Ok(n as u64)
}

fn vectored(
    p: &mut Process,
    pipes: &mut Pipes,
    host: &mut impl Host,
    is_write: bool,
    fd: u64,
    iov: u64,
    count: u64,
) -> SysResult<u64> {
    if count > IOV_MAX {
        return Err(Errno::EINVAL);
    }
    p.file(fd).ok_or(Errno::EBADF)?;
    let mut total = 0u64;
    for i in 0..count {
        let base = read_u64(p, host, iov + i * 16)?;
        let len = read_u64(p, host, iov + i * 16 + 8)?;
        if len == 0 {
            continue;
        }
        let n = match if is_write {
            write(p, pipes, host, fd, base, len)
        } else {
            read(p, pipes, host, fd, base, len)
        } {
            Ok(n) => n,
            // What moved already counts; the rest waits for the next call.
            Err(WOULD_BLOCK | BROKEN_PIPE) if total > 0 => break,
            Err(e) => return Err(e),
        };
        total += n;
        if n < len {
            break;
        }
    }
    Ok(total)
}

fn lseek(p: &mut Process, fd: u64, offset: i64, whence: u64) -> SysResult<u64> {
    let File::Initramfs { entry, offset: at } = p.file(fd).ok_or(Errno::EBADF)? else {
        return Err(Errno::ESPIPE);
    };
    let base = match whence {
        0 => 0,
        1 => at as i64,
        2 => entry.data.len() as i64,
        _ => return Err(Errno::EINVAL),
    };
    let new = base
        .checked_add(offset)
        .filter(|&n| n >= 0)
        .ok_or(Errno::EINVAL)?;
    p.files[fd as usize] = Some(File::Initramfs {
        entry,
        offset: new as u64,
    });
    Ok(new as u64)
}

/// Linux's `getdents64`: the directory's entries from its offset (`.`, `..`, then its
/// children in archive order; the offset counts entries) as `struct linux_dirent64`
/// records, as many as fit in `count` bytes.
fn getdents64<'a>(
    p: &mut Process<'a>,
    fs: &Archive<'a>,
    host: &mut impl Host,
    fd: u64,
    buf: u64,
    count: u64,
) -> SysResult<u64> {
    const DT_CHR: u8 = 2;
    const DT_DIR: u8 = 4;
    const DT_REG: u8 = 8;
    const DT_LNK: u8 = 10;
    const HEADER: usize = 19; // d_ino, d_off, d_reclen, d_type
    let File::Initramfs { entry, offset } = p.file(fd).ok_or(Errno::EBADF)? else {
        return Err(Errno::ENOTDIR);
    };
    if !entry.is_dir() {
        return Err(Errno::ENOTDIR);
    }
    let dir = entry.path();
    let mut written = 0usize;
    let mut index = offset;
    let mut record = [0u8; HEADER + 256];
    loop {
        let (ino, kind, name) = match index {
            0 => (entry.ino, DT_DIR, "."),
            1 => {
                let up = fs
                    .get(crate::cpio::parent(dir))
                    .map_or(entry.ino, |e| e.ino);
                (up, DT_DIR, "..")
            }
            i => match fs.children(dir).nth(i as usize - 2) {
                None => break,
                Some(child) => {
                    let kind = match child.file_type() {
                        crate::cpio::S_IFDIR => DT_DIR,
                        crate::cpio::S_IFLNK => DT_LNK,
                        S_IFCHR => DT_CHR,
                        _ => DT_REG,
                    };
                    let path = child.path();
                    (
                        child.ino,
                        kind,
                        &path[path.rfind('/').map_or(0, |at| at + 1)..],
                    )
                }
            },
        };
        let name = &name.as_bytes()[..name.len().min(255)];
        let length = (HEADER + name.len() + 1).next_multiple_of(8);
        if written + length > count as usize {
            if written == 0 {
                return Err(Errno::EINVAL); // the buffer cannot hold one record
            }
            break;
        }
        record[..length].fill(0);
        record[..8].copy_from_slice(&(ino as u64).to_le_bytes());
        record[8..16].copy_from_slice(&(index + 1).to_le_bytes());
        record[16..18].copy_from_slice(&(length as u16).to_le_bytes());
        record[18] = kind;
        record[HEADER..HEADER + name.len()].copy_from_slice(name);
        write_user(p, host, buf + written as u64, &record[..length])?;
        written += length;
        index += 1;
    }
    p.files[fd as usize] = Some(File::Initramfs {
        entry,
        offset: index,
    });
    Ok(written as u64)
}

/// Looks a path of the process up, relative to `dirfd` (only `AT_FDCWD`, `/`, is
/// supported as a base for relative paths).
fn lookup_at<'a>(
    p: &Process<'a>,
    fs: &Archive<'a>,
    host: &mut impl Host,
    dirfd: u64,
    path: u64,
    follow: bool,
) -> SysResult<Entry<'a>> {
    let mut buf = [0u8; 256];
    let path = read_cstr(p, host, path, &mut buf)?;
    if path.first() != Some(&b'/') && dirfd as i64 != linux::AT_FDCWD {
        // Directory descriptors as a base: not yet.
        return Err(if p.file(dirfd).is_some() {
            Errno::ENOTDIR
        } else {
            Errno::EBADF
        });
    }
    vfs::lookup(fs, path, follow).map(|(entry, _)| entry)
}

fn openat<'a>(
    p: &mut Process<'a>,
    fs: &Archive<'a>,
    host: &mut impl Host,
    dirfd: u64,
    path: u64,
    flags: u64,
) -> SysResult<u64> {
    const O_NOFOLLOW: u64 = 0o400000;
    let found = lookup_at(p, fs, host, dirfd, path, flags & O_NOFOLLOW == 0);
    if flags & linux::O_ACCMODE != 0 || flags & (linux::O_CREAT | linux::O_TRUNC) != 0 {
        // The initramfs is read-only.
        return Err(match found {
            Err(Errno::ENOENT) if flags & linux::O_CREAT == 0 => Errno::ENOENT,
            Err(e) if e != Errno::ENOENT => e,
            _ => Errno::EROFS,
        });
    }
    let entry = found?;
    if flags & linux::O_DIRECTORY != 0 && !entry.is_dir() {
        return Err(Errno::ENOTDIR);
    }
    if entry.is_symlink() {
        return Err(Errno::ELOOP); // O_NOFOLLOW on a link
    }
    let fd = p.free_fd().ok_or(Errno::EMFILE)?;
    p.install(
        fd,
        File::Initramfs { entry, offset: 0 },
        flags & O_CLOEXEC != 0,
    );
    Ok(fd as u64)
}

fn access<'a>(
    p: &mut Process<'a>,
    fs: &Archive<'a>,
    host: &mut impl Host,
    dirfd: u64,
    path: u64,
    mode: u64,
) -> SysResult<u64> {
    const W_OK: u64 = 2;
    const X_OK: u64 = 1;
    if mode & !7 != 0 {
        return Err(Errno::EINVAL);
    }
    let entry = lookup_at(p, fs, host, dirfd, path, true)?;
    if mode & W_OK != 0 {
        return Err(Errno::EROFS);
    }
    // Root may execute anything with an execute bit set for someone.
    if mode & X_OK != 0 && entry.mode & 0o111 == 0 {
        return Err(Errno::EACCES);
    }
    Ok(0)
}

#[allow(clippy::too_many_arguments)] // the system call's arguments
fn readlink<'a>(
    p: &mut Process<'a>,
    fs: &Archive<'a>,
    host: &mut impl Host,
    dirfd: u64,
    path: u64,
    buf: u64,
    size: u64,
) -> SysResult<u64> {
    if size as i64 <= 0 {
        return Err(Errno::EINVAL);
    }
    let mut name = [0u8; 256];
    let text = read_cstr(p, host, path, &mut name)?;
    let mut exe = [0u8; 257];
    let target: &[u8] = if text == b"/proc/self/exe" {
        let path = p.exe.as_str().as_bytes();
        exe[0] = b'/';
        exe[1..1 + path.len()].copy_from_slice(path);
        &exe[..1 + path.len()]
    } else {
        let entry = lookup_at(p, fs, host, dirfd, path, false)?;
        if !entry.is_symlink() {
            return Err(Errno::EINVAL);
        }
        entry.data
    };
    let n = target.len().min(size as usize);
    write_user(p, host, buf, &target[..n])?;
    Ok(n as u64)
}

fn fcntl(p: &mut Process, pipes: &mut Pipes, fd: u64, cmd: u64, arg: u64) -> SysResult<u64> {
    const F_DUPFD: u64 = 0;
    const F_GETFD: u64 = 1;
    const F_SETFD: u64 = 2;
    const F_GETFL: u64 = 3;
    const F_SETFL: u64 = 4;
    const F_DUPFD_CLOEXEC: u64 = 1030;
    const FD_CLOEXEC: u64 = 1;
    let file = p.file(fd).ok_or(Errno::EBADF)?;
    let fd = fd as usize;
    match cmd {
        F_DUPFD | F_DUPFD_CLOEXEC => {
            let low = usize::try_from(arg)
                .ok()
                .filter(|&low| low < MAX_FILES)
                .ok_or(Errno::EINVAL)?;
            let new = p.free_fd_from(low).ok_or(Errno::EMFILE)?;
            duplicate(p, pipes, file, new, cmd == F_DUPFD_CLOEXEC);
            Ok(new as u64)
        }
        F_GETFD => Ok(if p.is_cloexec(fd) { FD_CLOEXEC } else { 0 }),
        F_SETFD => {
            p.set_cloexec(fd, arg & FD_CLOEXEC != 0);
            Ok(0)
        }
        // O_NONBLOCK of a pipe end (this descriptor's: Linux shares it with the
        // descriptors dup'ed from it); other flags change nothing (O_APPEND: no writable
        // files).
        F_SETFL => {
            if let File::Pipe { pipe, write, .. } = file {
                let nonblock = arg & linux::O_NONBLOCK != 0;
                p.files[fd] = Some(File::Pipe {
                    pipe,
                    write,
                    nonblock,
                });
            }
            Ok(0)
        }
        F_GETFL => Ok(match file {
            File::Console(_) => linux::O_RDWR,
            File::Initramfs { .. } => 0,
            File::Pipe {
                write, nonblock, ..
            } => {
                let access = if write { linux::O_WRONLY } else { 0 };
                access | if nonblock { linux::O_NONBLOCK } else { 0 }
            }
        }),
        _ => Err(Errno::EINVAL),
    }
}

/// Linux's `struct stat` (x86-64) fields the guest fills.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stat {
    pub ino: u64,
    pub nlink: u64,
    pub mode: u32,
    pub uid: u32,
    pub gid: u32,
    pub rdev: u64,
    pub size: u64,
    pub mtime: u64,
}

impl Stat {
    /// The 144-byte `struct stat`.
    pub fn to_bytes(&self) -> [u8; 144] {
        let mut b = [0u8; 144];
        b[0..8].copy_from_slice(&1u64.to_le_bytes()); // st_dev: the initramfs
        b[8..16].copy_from_slice(&self.ino.to_le_bytes());
        b[16..24].copy_from_slice(&self.nlink.to_le_bytes());
        b[24..28].copy_from_slice(&self.mode.to_le_bytes());
        b[28..32].copy_from_slice(&self.uid.to_le_bytes());
        b[32..36].copy_from_slice(&self.gid.to_le_bytes());
        b[40..48].copy_from_slice(&self.rdev.to_le_bytes());
        b[48..56].copy_from_slice(&self.size.to_le_bytes());
        b[56..64].copy_from_slice(&4096u64.to_le_bytes()); // st_blksize
        b[64..72].copy_from_slice(&self.size.div_ceil(512).to_le_bytes()); // st_blocks
        for at in [72, 88, 104] {
            b[at..at + 8].copy_from_slice(&self.mtime.to_le_bytes());
        }
        b
    }
}

/// The status of an initramfs entry, or of the console (`None`).
fn stat_of(entry: Option<&Entry>) -> Stat {
    match entry {
        Some(e) => Stat {
            ino: e.ino as u64,
            nlink: e.nlink.max(1) as u64,
            mode: e.mode,
            uid: e.uid,
            gid: e.gid,
            rdev: 0,
            size: e.data.len() as u64,
            mtime: e.mtime as u64,
        },
        None => Stat {
            ino: 1,
            nlink: 1,
            mode: S_IFCHR | 0o620,
            rdev: CONSOLE_RDEV,
            ..Stat::default()
        },
    }
}

fn stat_of_fd(p: &Process, fd: u64) -> SysResult<Stat> {
    const S_IFIFO: u32 = 0o010000;
    Ok(match p.file(fd).ok_or(Errno::EBADF)? {
        File::Console(_) => stat_of(None),
        File::Initramfs { entry, .. } => stat_of(Some(&entry)),
        File::Pipe { pipe, .. } => Stat {
            ino: 0x1_0000 + pipe as u64,
            nlink: 1,
            mode: S_IFIFO | 0o600,
            ..Stat::default()
        },
    })
}

fn write_stat(p: &Process, host: &mut impl Host, buf: u64, st: &Stat) -> SysResult<u64> {
    debug_assert!(st.mode & S_IFMT != 0 || st.mode == 0);
    write_user(p, host, buf, &st.to_bytes())?;
    Ok(0)
}

fn arch_prctl(
    p: &Process,
    host: &mut impl Host,
    regs: &mut Registers,
    code: u64,
    address: u64,
) -> SysResult<u64> {
    match code {
        linux::ARCH_SET_FS | linux::ARCH_SET_GS => {
            if address >= abi::syscall::USER_END {
                return Err(Errno::EPERM);
            }
            // The reply that resumes the thread sets its FS/GS base.
            if code == linux::ARCH_SET_FS {
                regs.fs_base = address;
            } else {
                regs.gs_base = address;
            }
            Ok(0)
        }
        linux::ARCH_GET_FS | linux::ARCH_GET_GS => {
            let base = if code == linux::ARCH_GET_FS {
                regs.fs_base
            } else {
                regs.gs_base
            };
            write_user(p, host, address, &base.to_le_bytes())?;
            Ok(0)
        }
        _ => Err(Errno::EINVAL),
    }
}

fn prctl(p: &mut Process, host: &mut impl Host, option: u64, arg: u64) -> SysResult<u64> {
    const PR_SET_NAME: u64 = 15;
    const PR_GET_NAME: u64 = 16;
    match option {
        PR_SET_NAME => {
            let mut buf = [0u8; 16];
            let name = match read_cstr(p, host, arg, &mut buf) {
                Ok(name) => name,
                // Longer names are cut (Linux copies 16 bytes and ends them with a NUL).
                Err(Errno::ENAMETOOLONG) => &buf[..crate::process::NAME_LEN],
                Err(e) => return Err(e),
            };
            let name = core::str::from_utf8(name).unwrap_or("?");
            p.set_name(name);
            Ok(0)
        }
        PR_GET_NAME => {
            let mut buf = [0u8; 16];
            buf[..p.name().len()].copy_from_slice(p.name().as_bytes());
            write_user(p, host, arg, &buf)?;
            Ok(0)
        }
        _ => {
            if p.first_unsupported(nr::prctl) {
                host.log(format_args!(
                    "guest: process {} ({}): unsupported prctl option {option}, returning EINVAL",
                    p.pid,
                    p.name()
                ));
            }
            Err(Errno::EINVAL)
        }
    }
}

fn rlimit(p: &Process, host: &mut impl Host, resource: u64, old: u64) -> SysResult<u64> {
    if resource >= 16 {
        return Err(Errno::EINVAL);
    }
    let (cur, max) = match resource {
        linux::RLIMIT_STACK => (crate::memory::STACK_SIZE, crate::memory::STACK_SIZE),
        linux::RLIMIT_NOFILE => (
            crate::process::MAX_FILES as u64,
            crate::process::MAX_FILES as u64,
        ),
        _ => (linux::RLIM_INFINITY, linux::RLIM_INFINITY),
    };
    if old != 0 {
        let mut b = [0u8; 16];
        b[..8].copy_from_slice(&cur.to_le_bytes());
        b[8..].copy_from_slice(&max.to_le_bytes());
        write_user(p, host, old, &b)?;
    }
    Ok(0)
}
