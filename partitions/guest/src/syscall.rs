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
//! `getsid` are the process table's ([`crate::system`]). On the console, `read`
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

use crate::arinc;
use crate::linux::{self, Errno, nr};
use crate::memory::{Fault, PAGE, Rights, USER_TOP, classify_fault};
use crate::pipe::Pipes;
use crate::poll;
use crate::process::{File, Process, Stream};
use crate::sigcalls;
use crate::signal::{self, Info, SIGSEGV};
use crate::tty::{self, Termios, Tty, Winsize};
use crate::vfs::Fs;
use crate::vfs::proc::ProcessTable;
use abi::ipc::{ExceptionMessage, Registers, VECTOR_INTERRUPT, VECTOR_SYSCALL};
pub use file::{Files, Target, close_files, share_files};
use memory::{brk, madvise, mmap, mprotect, mremap, munmap};

pub mod file;
mod memory;

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
    /// A call waits for a port (to read or to write, or in `poll`): its messages arrive
    /// without a word to the guest, so the host serves the waiting calls again soon.
    fn port_wait(&mut self) {}
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
/// are in `pipes`; `others` are the other processes (`/proc`).
pub fn handle(
    p: &mut Process,
    pipes: &mut Pipes,
    fs: &mut Fs,
    others: &dyn ProcessTable,
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
            None => {
                let mut files = Files { pipes, fs, others };
                call(p, &mut files, host, number, args, r)
            }
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

#[allow(clippy::too_many_arguments)] // the call, its arguments and what it acts on
fn call(
    p: &mut Process,
    f: &mut Files,
    host: &mut impl Host,
    number: u64,
    a: [u64; 6],
    regs: &mut Registers,
) -> SysResult<u64> {
    const AT_FDCWD: u64 = linux::AT_FDCWD as u64;
    match number {
        nr::read => file::read(p, f, host, a[0], a[1], a[2], None),
        nr::write => file::write(p, f, host, a[0], a[1], a[2], None),
        nr::pread64 => file::read(p, f, host, a[0], a[1], a[2], Some(offset(a[3])?)),
        nr::pwrite64 => file::write(p, f, host, a[0], a[1], a[2], Some(offset(a[3])?)),
        nr::sendfile => file::sendfile(p, f, host, a[0], a[1], a[2], a[3]),
        nr::readv | nr::writev => {
            file::vectored(p, f, host, number == nr::writev, a[0], a[1], a[2])
        }
        nr::open => file::openat(p, f, host, AT_FDCWD, a[0], a[1], a[2]),
        nr::creat => {
            let flags = linux::O_CREAT | linux::O_WRONLY | linux::O_TRUNC;
            file::openat(p, f, host, AT_FDCWD, a[0], flags, a[1])
        }
        nr::openat => file::openat(p, f, host, a[0], a[1], a[2], a[3]),
        nr::close => file::close_fd(p, f, a[0]),
        nr::dup => file::dup(p, f, a[0]),
        nr::dup2 => file::dup3(p, f, a[0], a[1], None),
        nr::dup3 => file::dup3(p, f, a[0], a[1], Some(a[2])),
        nr::pipe => file::pipe(p, f, host, a[0], 0),
        nr::pipe2 => file::pipe(p, f, host, a[0], a[1]),
        nr::lseek => file::lseek(p, f, a[0], a[1] as i64, a[2]),
        nr::ftruncate => file::ftruncate(p, f, host, a[0], a[1]),
        nr::truncate => file::truncate(p, f, host, a[0], a[1]),
        nr::getdents64 => file::getdents64(p, f, host, a[0], a[1], a[2]),
        nr::stat => file::stat(p, f, host, a[0], a[1], true),
        nr::lstat => file::stat(p, f, host, a[0], a[1], false),
        nr::fstat => file::fstat(p, f, host, a[0], a[1]),
        nr::newfstatat => file::newfstatat(p, f, host, a[0], a[1], a[2], a[3]),
        nr::statx => file::statx(p, f, host, a[0], a[1], a[2], a[4]),
        nr::statfs => file::statfs(p, f, host, a[0], None, a[1]),
        nr::fstatfs => file::statfs(p, f, host, 0, Some(a[0]), a[1]),
        nr::access => file::access(p, f, host, AT_FDCWD, a[0], a[1]),
        nr::faccessat | nr::faccessat2 => file::access(p, f, host, a[0], a[1], a[2]),
        nr::readlink => file::readlinkat(p, f, host, AT_FDCWD, a[0], a[1], a[2]),
        nr::readlinkat => file::readlinkat(p, f, host, a[0], a[1], a[2], a[3]),
        nr::mkdir => file::mkdirat(p, f, host, AT_FDCWD, a[0], a[1]),
        nr::mkdirat => file::mkdirat(p, f, host, a[0], a[1], a[2]),
        nr::unlink => file::unlinkat(p, f, host, AT_FDCWD, a[0], 0),
        nr::rmdir => file::unlinkat(p, f, host, AT_FDCWD, a[0], linux::AT_REMOVEDIR),
        nr::unlinkat => file::unlinkat(p, f, host, a[0], a[1], a[2]),
        nr::rename => file::renameat2(p, f, host, AT_FDCWD, a[0], AT_FDCWD, a[1], 0),
        nr::renameat => file::renameat2(p, f, host, a[0], a[1], a[2], a[3], 0),
        nr::renameat2 => file::renameat2(p, f, host, a[0], a[1], a[2], a[3], a[4]),
        nr::symlink => file::symlinkat(p, f, host, a[0], AT_FDCWD, a[1]),
        nr::symlinkat => file::symlinkat(p, f, host, a[0], a[1], a[2]),
        nr::link => file::linkat(p, f, host, AT_FDCWD, a[0], AT_FDCWD, a[1], 0),
        nr::linkat => file::linkat(p, f, host, a[0], a[1], a[2], a[3], a[4]),
        nr::chdir => file::chdir(p, f, host, a[0]),
        nr::fchdir => file::fchdir(p, f, a[0]),
        nr::getcwd => file::getcwd(p, f, host, a[0], a[1]),
        nr::chmod => file::chmod(p, f, host, Target::path(a[0], true), a[1]),
        nr::fchmod => file::chmod(p, f, host, Target::Fd(a[0]), a[1]),
        nr::fchmodat => file::chmod(p, f, host, Target::at(a[0], a[1], a[3]), a[2]),
        nr::chown => file::chown(p, f, host, Target::path(a[0], true)),
        nr::lchown => file::chown(p, f, host, Target::path(a[0], false)),
        nr::fchown => file::chown(p, f, host, Target::Fd(a[0])),
        nr::fchownat => file::chown(p, f, host, Target::at(a[0], a[1], a[4])),
        nr::utimensat => file::utimensat(p, f, host, Target::at(a[0], a[1], a[3]), a[2]),
        nr::utime | nr::utimes => file::chown(p, f, host, Target::path(a[0], true)),
        nr::fsync | nr::fdatasync | nr::syncfs | nr::fadvise64 => file::nothing(p, a[0]),
        nr::sync => Ok(0),
        nr::fcntl => file::fcntl(p, f, a[0], a[1], a[2]),
        nr::ioctl => match p.file(a[0]).ok_or(Errno::EBADF)? {
            File::Console(_) => tty_ioctl(p, host, a[1], a[2]),
            _ => file::port_ioctl(p, f, host, a[0], a[1], a[2]),
        },
        nr::brk => Ok(brk(p, host, a[0])),
        nr::mmap => mmap(p, f.fs, host, a),
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
            poll::poll(p, f, host, a[0], a[1], timeout, 0, 0)
        }
        nr::ppoll => {
            let timeout = poll::ppoll_timeout(p, host, a[2])?;
            poll::poll(p, f, host, a[0], a[1], timeout, a[3], a[4])
        }
        nr::select => poll::select(p, f, host, a, false),
        nr::pselect6 => poll::select(p, f, host, a, true),
        nr::getitimer => sigcalls::getitimer(p, host, a[0], a[1]),
        nr::setitimer => sigcalls::setitimer(p, host, a[0], a[1], a[2]),
        nr::prlimit64 => {
            if a[0] != 0 && a[0] != p.pid as u64 {
                return Err(Errno::ESRCH);
            }
            rlimit(p, host, a[1], a[2], a[3])
        }
        nr::getrlimit => rlimit(p, host, a[0], 0, a[1]),
        nr::setrlimit => rlimit(p, host, a[0], a[1], 0),
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
            // CLOCK_REALTIME .. CLOCK_BOOTTIME: the real-time ones the wall clock, the others
            // the guest's clock.
            if a[0] > 7 {
                return Err(Errno::EINVAL);
            }
            let ns = if is_realtime(a[0]) {
                host.wall_clock_ns()
            } else {
                host.now_ns()
            };
            let mut ts = [0u8; 16];
            ts[..8].copy_from_slice(&(ns / 1_000_000_000).to_le_bytes());
            ts[8..].copy_from_slice(&(ns % 1_000_000_000).to_le_bytes());
            write_user(p, host, a[1], &ts)?;
            Ok(0)
        }
        nr::clock_getres => {
            if a[0] > 7 {
                return Err(Errno::EINVAL);
            }
            // The guest's clock counts nanoseconds (the kernel's, from the TSC).
            if a[1] != 0 {
                let mut ts = [0u8; 16];
                ts[8..].copy_from_slice(&1u64.to_le_bytes());
                write_user(p, host, a[1], &ts)?;
            }
            Ok(0)
        }
        nr::gettimeofday => {
            let ns = host.wall_clock_ns();
            if a[0] != 0 {
                let mut tv = [0u8; 16];
                tv[..8].copy_from_slice(&(ns / 1_000_000_000).to_le_bytes());
                tv[8..].copy_from_slice(&(ns % 1_000_000_000 / 1000).to_le_bytes());
                write_user(p, host, a[0], &tv)?;
            }
            Ok(0)
        }
        nr::time => {
            let seconds = host.wall_clock_ns() / 1_000_000_000;
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

/// Whether clock id `clock` counts wall-clock time (`CLOCK_REALTIME`,
/// `CLOCK_REALTIME_COARSE`).
pub(crate) fn is_realtime(clock: u64) -> bool {
    matches!(clock, 0 | 5)
}

/// A file offset argument (`pread64`, `pwrite64`): negative ones are `EINVAL`.
fn offset(value: u64) -> SysResult<u64> {
    if (value as i64) < 0 {
        Err(Errno::EINVAL)
    } else {
        Ok(value)
    }
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

fn rlimit(
    p: &mut Process,
    host: &mut impl Host,
    resource: u64,
    new: u64,
    old: u64,
) -> SysResult<u64> {
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
        let ceiling = crate::process::default_limits()[index].hard;
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
