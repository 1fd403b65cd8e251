//! The Linux system calls and faults of a process, as a pure function: [`handle`] takes the
//! exception message the kernel sent for one of the process's threads (its registers) and
//! either edits the registers (the call's result in `rax`) for the reply that resumes the
//! thread, or says the process ends. What needs the real system (process memory, mapping
//! pages, the console, the clock, random bytes, the log) goes through [`Host`], which the
//! partition program implements with kernel calls and the tests with a model.
//!
//! Served (x86-64 numbers in [`crate::linux::nr`]): the file calls of [`file`] (the
//! descriptors, reading and writing, names, status, the working directory), `ioctl`,
//! `brk`, `mmap` (anonymous), `munmap`, `mprotect`, `madvise`, `arch_prctl`,
//! `set_tid_address`, `set_robust_list`, `rt_sigaction`, `rt_sigprocmask`, `prlimit64`,
//! `getrlimit`, `getrandom`, `clock_gettime`, `gettimeofday`, `time`, `uname`, `umask`,
//! `sched_yield`, `prctl` (`PR_SET_NAME`, `PR_GET_NAME`; other options `EINVAL`, logged
//! once), the identity calls (`getpid`, `getppid`, `gettid`, `getpgrp`, `getuid`,
//! `geteuid`, `getgid`, `getegid`), `exit`, `exit_group`; `clone`, `fork`, `vfork`,
//! `execve` and `wait4` are the process table's ([`crate::system`]). `rseq` answers
//! `ENOSYS` (as on kernels without it); any other call answers `ENOSYS` and is logged once
//! per number and process.
//! Pages are never writable and executable at once (W^X): `mmap` and `mprotect` asking for
//! both fail with `EACCES`.
//! A CPU exception (page fault outside the process's memory, invalid opcode, ...) kills the
//! process with the matching signal: no signal handler is delivered yet.

pub mod file;

use crate::linux::{self, Errno, nr};
use crate::memory::{Area, AreaError, Kind, PAGE, Rights, USER_TOP, page_up};
use crate::pipe::Pipes;
use crate::process::{Process, Stream};
use crate::vfs::Fs;
use crate::vfs::proc::ProcessTable;
use abi::ipc::{ExceptionMessage, Registers, VECTOR_SYSCALL};
pub use file::{Files, Target, close_files, share_files};

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
    /// range lies in readable areas).
    fn read_user(&mut self, address: u64, buf: &mut [u8]) -> Result<(), Errno>;
    /// Copies `data` into the process's memory at `address` (checked writable areas).
    fn write_user(&mut self, address: u64, data: &[u8]) -> Result<(), Errno>;
    /// Backs `pages` pages at `start` with zeroed memory and maps them with `rights`
    /// (`ENOMEM` when the guest is out of memory, `EACCES` for rights it never grants, such
    /// as writable and executable at once; then nothing is mapped).
    fn map_zeroed(&mut self, start: u64, pages: u64, rights: Rights) -> Result<(), Errno>;
    /// Unmaps `pages` pages at `start` and frees their memory (pages never backed are
    /// skipped).
    fn unmap(&mut self, start: u64, pages: u64);
    /// Gives the pages at `start` the `rights` (none: unmapped, contents kept); pages not
    /// backed yet are backed with zeroed memory.
    fn protect(&mut self, start: u64, pages: u64, rights: Rights) -> Result<(), Errno>;
    /// Output of process `pid` on the console.
    fn console_write(&mut self, pid: u32, stream: Stream, bytes: &[u8]);
    /// Nanoseconds since the guest started.
    fn now_ns(&mut self) -> u64;
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
    /// `vfork`, `execve`, `wait4`.
    Process,
}

/// Internal results that are no error number: the call would block, or wrote to a pipe
/// without readers.
const WOULD_BLOCK: Errno = Errno(0xfff0);
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
        nr::clone | nr::fork | nr::vfork | nr::execve | nr::wait4 => return Outcome::Process,
        _ => {
            let mut files = Files { pipes, fs, others };
            call(p, &mut files, host, number, args, r)
        }
    };
    r.rax = match result {
        Ok(value) => value,
        Err(WOULD_BLOCK) => return Outcome::Block,
        Err(BROKEN_PIPE) => {
            if p.sigactions[linux::SIGPIPE as usize - 1][0] != linux::SIG_IGN {
                host.log(format_args!(
                    "guest: process {} ({}) killed by signal {} (SIGPIPE): wrote to a pipe without readers",
                    p.pid,
                    p.name(),
                    linux::SIGPIPE
                ));
                return Outcome::Killed(linux::SIGPIPE);
            }
            Errno::EPIPE.result()
        }
        Err(e) => e.result(),
    };
    // What the `syscall` instruction leaves in them on Linux.
    r.rcx = r.rip;
    r.r11 = r.rflags;
    Outcome::Resume
}

/// The signal a CPU exception kills with (Linux's mapping).
fn fault_signal(vector: u64) -> u32 {
    match vector {
        0 | 16 | 19 => linux::SIGFPE,
        1 | 3 => linux::SIGTRAP,
        6 => linux::SIGILL,
        17 => linux::SIGBUS,
        _ => linux::SIGSEGV,
    }
}

fn fault(p: &Process, host: &mut impl Host, m: &ExceptionMessage) -> Outcome {
    let signal = fault_signal(m.vector);
    host.log(format_args!(
        "guest: process {} ({}) killed by signal {signal} ({}): vector {} error {:#x} address {:#x} rip {:#x}",
        p.pid,
        p.name(),
        linux::signal_name(signal),
        m.vector,
        m.error_code,
        m.fault_address,
        m.registers.rip
    ));
    Outcome::Killed(signal)
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
        nr::ioctl => {
            // No terminal yet: the console is not a tty (TCGETS and the rest: ENOTTY).
            p.file(a[0]).ok_or(Errno::EBADF)?;
            Err(Errno::ENOTTY)
        }
        nr::brk => Ok(brk(p, host, a[0])),
        nr::mmap => mmap(p, host, a[0], a[1], a[2], a[3]),
        nr::munmap => munmap(p, host, a[0], a[1]),
        nr::mprotect => mprotect(p, host, a[0], a[1], a[2]),
        nr::madvise => Ok(0),
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
        nr::rt_sigaction => sigaction(p, host, a[0], a[1], a[2], a[3]),
        nr::rt_sigprocmask => sigprocmask(p, host, a[0], a[1], a[2], a[3]),
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
        nr::getpid | nr::gettid | nr::getpgrp => Ok(p.pid as u64),
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

/// A file offset argument (`pread64`, `pwrite64`): negative ones are `EINVAL`.
fn offset(value: u64) -> SysResult<u64> {
    if (value as i64) < 0 {
        Err(Errno::EINVAL)
    } else {
        Ok(value)
    }
}

/// Linux's `brk`: returns the new break, or the old one if it cannot move there.
fn brk(p: &mut Process, host: &mut impl Host, requested: u64) -> u64 {
    if requested < p.brk_start || requested - p.brk_start > MAX_HEAP {
        return p.brk;
    }
    let (old_end, new_end) = (page_up(p.brk), page_up(requested));
    if new_end > old_end {
        let grown = if old_end == p.brk_start {
            p.areas.insert(Area {
                start: p.brk_start,
                end: new_end,
                rights: Rights::READ | Rights::WRITE,
                kind: Kind::Heap,
            })
        } else {
            p.areas.resize(old_end, new_end)
        };
        if grown.is_err() {
            return p.brk;
        }
        let pages = (new_end - old_end) / PAGE;
        if host
            .map_zeroed(old_end, pages, Rights::READ | Rights::WRITE)
            .is_err()
        {
            let _ = if old_end == p.brk_start {
                p.areas.remove(p.brk_start, new_end, |_| ())
            } else {
                p.areas.resize(new_end, old_end)
            };
            return p.brk;
        }
    } else if new_end < old_end {
        host.unmap(new_end, (old_end - new_end) / PAGE);
        let _ = if new_end == p.brk_start {
            p.areas.remove(p.brk_start, old_end, |_| ())
        } else {
            p.areas.resize(old_end, new_end)
        };
    }
    p.brk = requested;
    requested
}

fn area_error(e: AreaError) -> Errno {
    match e {
        AreaError::Invalid => Errno::EINVAL,
        AreaError::Overlaps => Errno::EEXIST,
        AreaError::TooMany => Errno::ENOMEM,
    }
}

fn mmap(
    p: &mut Process,
    host: &mut impl Host,
    hint: u64,
    len: u64,
    prot: u64,
    flags: u64,
) -> SysResult<u64> {
    let rights = Rights::from_prot(prot).ok_or(Errno::EINVAL)?;
    if rights.writable_and_executable() {
        return Err(Errno::EACCES);
    }
    if len == 0 || flags & (linux::MAP_SHARED | linux::MAP_PRIVATE) == 0 {
        return Err(Errno::EINVAL);
    }
    if flags & linux::MAP_ANONYMOUS == 0 {
        return Err(Errno::ENODEV); // file mappings: not yet
    }
    let len = len.checked_add(PAGE - 1).ok_or(Errno::ENOMEM)? & !(PAGE - 1);
    let fixed = flags & (linux::MAP_FIXED | linux::MAP_FIXED_NOREPLACE) != 0;
    let start = if fixed {
        let end = hint.checked_add(len).ok_or(Errno::ENOMEM)?;
        if !hint.is_multiple_of(PAGE) || hint == 0 || end > USER_TOP {
            return Err(Errno::EINVAL);
        }
        if p.areas.overlaps(hint, end) {
            if flags & linux::MAP_FIXED_NOREPLACE != 0 {
                return Err(Errno::EEXIST);
            }
            munmap(p, host, hint, len)?;
        }
        hint
    } else {
        let hinted = hint.is_multiple_of(PAGE)
            && hint >= MMAP_BOTTOM
            && hint
                .checked_add(len)
                .is_some_and(|end| end <= crate::memory::MMAP_TOP && !p.areas.overlaps(hint, end));
        if hinted {
            hint
        } else {
            p.areas
                .free_below(crate::memory::MMAP_TOP, MMAP_BOTTOM, len)
                .ok_or(Errno::ENOMEM)?
        }
    };
    p.areas
        .insert(Area {
            start,
            end: start + len,
            rights,
            kind: Kind::Anonymous,
        })
        .map_err(area_error)?;
    if rights.accessible()
        && let Err(e) = host.map_zeroed(start, len / PAGE, rights)
    {
        let _ = p.areas.remove(start, start + len, |_| ());
        return Err(e);
    }
    Ok(start)
}

fn munmap(p: &mut Process, host: &mut impl Host, start: u64, len: u64) -> SysResult<u64> {
    if !start.is_multiple_of(PAGE) || len == 0 {
        return Err(Errno::EINVAL);
    }
    let end = start
        .checked_add(page_up(len))
        .filter(|&e| e <= USER_TOP)
        .ok_or(Errno::EINVAL)?;
    let mut parts = [(0u64, 0u64); crate::memory::MAX_AREAS + 2];
    let mut n = 0;
    p.areas
        .remove(start, end, |a| {
            if n < parts.len() {
                parts[n] = (a.start, a.end);
                n += 1;
            }
        })
        .map_err(area_error)?;
    for &(s, e) in &parts[..n] {
        host.unmap(s, (e - s) / PAGE);
    }
    Ok(0)
}

fn mprotect(
    p: &mut Process,
    host: &mut impl Host,
    start: u64,
    len: u64,
    prot: u64,
) -> SysResult<u64> {
    let rights = Rights::from_prot(prot).ok_or(Errno::EINVAL)?;
    if rights.writable_and_executable() {
        return Err(Errno::EACCES);
    }
    if !start.is_multiple_of(PAGE) {
        return Err(Errno::EINVAL);
    }
    if len == 0 {
        return Ok(0);
    }
    let end = start
        .checked_add(page_up(len))
        .filter(|&e| e <= USER_TOP)
        .ok_or(Errno::ENOMEM)?;
    if !p.areas.covers(start, end) {
        return Err(Errno::ENOMEM);
    }
    host.protect(start, (end - start) / PAGE, rights)?;
    p.areas
        .protect(start, end, rights, |_| ())
        .map_err(area_error)?;
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

fn sigaction(
    p: &mut Process,
    host: &mut impl Host,
    signal: u64,
    act: u64,
    old: u64,
    size: u64,
) -> SysResult<u64> {
    if size != 8 || signal == 0 || signal > 64 {
        return Err(Errno::EINVAL);
    }
    if act != 0 && (signal == linux::SIGKILL || signal == linux::SIGSTOP) {
        return Err(Errno::EINVAL);
    }
    let index = signal as usize - 1;
    let mut new = [0u64; 4];
    if act != 0 {
        for (i, word) in new.iter_mut().enumerate() {
            *word = read_u64(p, host, act + 8 * i as u64)?;
        }
    }
    if old != 0 {
        let mut bytes = [0u8; 32];
        for (chunk, word) in bytes.chunks_exact_mut(8).zip(p.sigactions[index]) {
            chunk.copy_from_slice(&word.to_le_bytes());
        }
        write_user(p, host, old, &bytes)?;
    }
    if act != 0 {
        p.sigactions[index] = new;
    }
    Ok(0)
}

fn sigprocmask(
    p: &mut Process,
    host: &mut impl Host,
    how: u64,
    set: u64,
    old: u64,
    size: u64,
) -> SysResult<u64> {
    const UNBLOCKABLE: u64 = 1 << (linux::SIGKILL - 1) | 1 << (linux::SIGSTOP - 1);
    if size != 8 {
        return Err(Errno::EINVAL);
    }
    let new = if set != 0 {
        let bits = read_u64(p, host, set)?;
        Some(match how {
            0 => p.sigmask | bits,
            1 => p.sigmask & !bits,
            2 => bits,
            _ => return Err(Errno::EINVAL),
        })
    } else {
        None
    };
    if old != 0 {
        write_user(p, host, old, &p.sigmask.to_le_bytes())?;
    }
    if let Some(mask) = new {
        p.sigmask = mask & !UNBLOCKABLE;
    }
    Ok(0)
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
