//! The handlers of the table ([`super::table`]): each decodes its call's arguments and
//! serves it, mostly through the modules that own the state it acts on.

use super::table::{Args, Ctx};
use super::{Host, Outcome, ProcessCall, SysResult, Target, WOULD_BLOCK, events, file, memory};
use crate::linux::{self, Errno, nr};
use crate::process::File;
use crate::signal::SIGSEGV;
use crate::{info, poll, sigcalls};

/// `AT_FDCWD` as a descriptor argument.
const AT_FDCWD: u64 = linux::AT_FDCWD as u64;

type Result = SysResult<u64>;

// Files: descriptors, reading and writing.

pub fn read<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::read(c, a.fd(0), a.ptr(1), a.usize(2), None)
}
pub fn write<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::write(c, a.fd(0), a.ptr(1), a.usize(2), None)
}
pub fn pread64<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let at = Some(a.offset(3)?);
    file::read(c, a.fd(0), a.ptr(1), a.usize(2), at)
}
pub fn pwrite64<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let at = Some(a.offset(3)?);
    file::write(c, a.fd(0), a.ptr(1), a.usize(2), at)
}
pub fn readv<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::vectored(c, false, a.fd(0), a.ptr(1), a.usize(2))
}
pub fn writev<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::vectored(c, true, a.fd(0), a.ptr(1), a.usize(2))
}
pub fn sendfile<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::sendfile(c, a.fd(0), a.fd(1), a.ptr(2), a.usize(3))
}
pub fn open<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::openat(c, AT_FDCWD, a.ptr(0), a.flags(1), a.flags(2))
}
pub fn creat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let flags = linux::O_CREAT | linux::O_WRONLY | linux::O_TRUNC;
    file::openat(c, AT_FDCWD, a.ptr(0), flags, a.flags(1))
}
pub fn openat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::openat(c, a.fd(0), a.ptr(1), a.flags(2), a.flags(3))
}
pub fn close<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::close_fd(c, a.fd(0))
}
pub fn close_range<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::close_range(c, a.fd(0), a.fd(1), a.flags(2))
}
pub fn dup<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::dup(c, a.fd(0))
}
pub fn dup2<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::dup3(c, a.fd(0), a.fd(1), None)
}
pub fn dup3<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::dup3(c, a.fd(0), a.fd(1), Some(a.flags(2)))
}
pub fn pipe<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::pipe(c, a.ptr(0), 0)
}
pub fn pipe2<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::pipe(c, a.ptr(0), a.flags(1))
}
pub fn lseek<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::lseek(c, a.fd(0), a.raw(1) as i64, a.flags(2))
}
pub fn ftruncate<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::ftruncate(c, a.fd(0), a.raw(1))
}
pub fn truncate<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::truncate(c, a.ptr(0), a.raw(1))
}
pub fn getdents64<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::getdents64(c, a.fd(0), a.ptr(1), a.usize(2))
}
pub fn fcntl<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::fcntl(c, a.fd(0), a.flags(1), a.raw(2))
}
/// The requests of every descriptor ([`file::generic_ioctl`]), the terminal requests on
/// the console ([`tty_ioctl`]), the socket requests on a socket, the port requests on a port.
pub fn ioctl<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let file = c.p.file(a.fd(0)).ok_or(Errno::EBADF)?;
    if let Some(done) = file::generic_ioctl(c, a.fd(0), a.flags(1), a.raw(2)) {
        return done;
    }
    match file {
        File::Console(_) => super::tty_ioctl(c, a.flags(1), a.raw(2)),
        File::Socket(_) => super::socket::socket_ioctl(c, a.fd(0), a.flags(1), a.raw(2)),
        _ if file::is_disk(c.p, c.f.fs, a.fd(0)) => {
            file::disk_ioctl(c, a.fd(0), a.flags(1), a.raw(2))
        }
        _ => file::port_ioctl(c, a.fd(0), a.flags(1), a.raw(2)),
    }
}
/// `fadvise64`: the files live in memory.
pub fn sync_fd<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::nothing(c, a.fd(0))
}
/// `fsync`, `fdatasync`: the block device's flush on `/dev/vda`, the write-back of the
/// file system mounted from it for its files, nothing for the others (in memory).
pub fn fsync<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::sync(c, Some(a.fd(0)), false)
}
/// `syncfs`: the mounted file system's write-back and the block device's flush.
pub fn syncfs<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::sync(c, Some(a.fd(0)), true)
}
/// `sync`: the mounted file system's write-back and the block device's flush (an error is
/// not reported: `sync` returns nothing).
pub fn sync<H: Host>(c: &mut Ctx<H>, _: Args) -> Result {
    let _ = file::sync(c, None, true);
    Ok(0)
}
/// `mount`: the disk's ext2 on a directory.
pub fn mount<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::mount(c, a.raw(0), a.raw(1), a.raw(2), a.flags(3))
}
/// `umount2`.
pub fn umount2<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::umount(c, a.raw(0), a.flags(1))
}
/// Calls with nothing to do (`sched_yield`).
pub fn nothing<H: Host>(_: &mut Ctx<H>, _: Args) -> Result {
    Ok(0)
}

// Names and status.

pub fn stat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::stat(c, a.ptr(0), a.ptr(1), true)
}
pub fn lstat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::stat(c, a.ptr(0), a.ptr(1), false)
}
pub fn fstat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::fstat(c, a.fd(0), a.ptr(1))
}
pub fn newfstatat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::newfstatat(c, a.fd(0), a.ptr(1), a.ptr(2), a.flags(3))
}
pub fn statx<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::statx(c, a.fd(0), a.ptr(1), a.flags(2), a.ptr(4))
}
pub fn statfs<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::statfs(c, a.ptr(0), None, a.ptr(1))
}
pub fn fstatfs<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::statfs(c, 0, Some(a.fd(0)), a.ptr(1))
}
pub fn access<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::access(c, AT_FDCWD, a.ptr(0), a.flags(1))
}
/// `faccessat`, `faccessat2`.
pub fn faccessat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::access(c, a.fd(0), a.ptr(1), a.flags(2))
}
pub fn readlink<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::readlinkat(c, AT_FDCWD, a.ptr(0), a.ptr(1), a.usize(2))
}
pub fn readlinkat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::readlinkat(c, a.fd(0), a.ptr(1), a.ptr(2), a.usize(3))
}
pub fn mkdir<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::mkdirat(c, AT_FDCWD, a.ptr(0), a.flags(1))
}
pub fn mkdirat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::mkdirat(c, a.fd(0), a.ptr(1), a.flags(2))
}
pub fn unlink<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::unlinkat(c, AT_FDCWD, a.ptr(0), 0)
}
pub fn rmdir<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let flags = linux::AT_REMOVEDIR;
    file::unlinkat(c, AT_FDCWD, a.ptr(0), flags)
}
pub fn unlinkat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::unlinkat(c, a.fd(0), a.ptr(1), a.flags(2))
}
pub fn rename<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (from, to) = (a.ptr(0), a.ptr(1));
    file::renameat2(c, AT_FDCWD, from, AT_FDCWD, to, 0)
}
pub fn renameat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (from, to) = (a.ptr(1), a.ptr(3));
    file::renameat2(c, a.fd(0), from, a.fd(2), to, 0)
}
pub fn renameat2<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (from, to, flags) = (a.ptr(1), a.ptr(3), a.flags(4));
    file::renameat2(c, a.fd(0), from, a.fd(2), to, flags)
}
pub fn symlink<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::symlinkat(c, a.ptr(0), AT_FDCWD, a.ptr(1))
}
pub fn symlinkat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::symlinkat(c, a.ptr(0), a.fd(1), a.ptr(2))
}
pub fn link<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (from, to) = (a.ptr(0), a.ptr(1));
    file::linkat(c, AT_FDCWD, from, AT_FDCWD, to, 0)
}
pub fn linkat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (from, to, flags) = (a.ptr(1), a.ptr(3), a.flags(4));
    file::linkat(c, a.fd(0), from, a.fd(2), to, flags)
}
pub fn chdir<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::chdir(c, a.ptr(0))
}
pub fn fchdir<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::fchdir(c, a.fd(0))
}
pub fn getcwd<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::getcwd(c, a.ptr(0), a.usize(1))
}
pub fn chmod<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::chmod(c, Target::path(a.ptr(0), true), a.flags(1))
}
pub fn fchmod<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::chmod(c, Target::Fd(a.fd(0)), a.flags(1))
}
pub fn fchmodat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let target = Target::at(a.fd(0), a.ptr(1), a.flags(3));
    file::chmod(c, target, a.flags(2))
}
pub fn chown<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::chown(c, Target::path(a.ptr(0), true))
}
pub fn lchown<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::chown(c, Target::path(a.ptr(0), false))
}
pub fn fchown<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::chown(c, Target::Fd(a.fd(0)))
}
pub fn fchownat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let target = Target::at(a.fd(0), a.ptr(1), a.flags(4));
    file::chown(c, target)
}
pub fn utimensat<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let target = Target::at(a.fd(0), a.ptr(1), a.flags(3));
    file::utimensat(c, target, a.ptr(2))
}
/// `utime`, `utimes`: the file must exist (its times are not kept), as `chown` checks.
pub fn utimes<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    file::chown(c, Target::path(a.ptr(0), true))
}
pub fn umask<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let old = c.p.umask;
    c.p.umask = a.flags(0) as u32 & 0o777;
    Ok(old as u64)
}

// Memory.

pub fn brk<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    Ok(memory::brk(c, a.ptr(0)))
}
pub fn mmap<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    memory::mmap(c, a.0)
}
pub fn munmap<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    memory::munmap(c, a.ptr(0), a.usize(1))
}
pub fn mprotect<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    memory::mprotect(c, a.ptr(0), a.usize(1), a.flags(2))
}
pub fn madvise<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    memory::madvise(c, a.ptr(0), a.usize(1), a.flags(2))
}
pub fn mremap<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    memory::mremap(c, a.ptr(0), a.usize(1), a.usize(2), a.flags(3))
}
pub fn mlock<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    memory::mlock(c, a.ptr(0), a.usize(1), 0)
}
pub fn mlock2<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    memory::mlock(c, a.ptr(0), a.usize(1), a.flags(2))
}
pub fn munlock<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    memory::munlock(c, a.ptr(0), a.usize(1))
}
pub fn mlockall<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    memory::mlockall(c, a.flags(0))
}
pub fn munlockall<H: Host>(c: &mut Ctx<H>, _: Args) -> Result {
    memory::munlockall(c)
}

// The thread.

pub fn arch_prctl<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (code, address) = (a.flags(0), a.ptr(1));
    let regs = &mut c.m.registers;
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
            c.write_user(address, &base.to_le_bytes())?;
            Ok(0)
        }
        _ => Err(Errno::EINVAL),
    }
}
pub fn set_tid_address<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    c.p.clear_child_tid = a.ptr(0);
    Ok(c.p.pid as u64) // the caller's thread id
}
pub fn set_robust_list<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    // Its one valid length: sizeof(struct robust_list_head).
    if a.usize(1) != 24 {
        return Err(Errno::EINVAL);
    }
    c.p.robust_list = a.ptr(0);
    Ok(0)
}
/// `rseq`: as on kernels without it (the C library goes on without).
pub fn no_rseq<H: Host>(_: &mut Ctx<H>, _: Args) -> Result {
    Err(Errno::ENOSYS)
}
pub fn prctl<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    const PR_SET_NAME: u64 = 15;
    const PR_GET_NAME: u64 = 16;
    let (option, arg) = (a.flags(0), a.ptr(1));
    match option {
        PR_SET_NAME => {
            let mut buf = [0u8; 16];
            let name = match c.read_cstr(arg, &mut buf) {
                Ok(name) => name,
                // Longer names are cut (Linux copies 16 bytes and ends them with a NUL).
                Err(Errno::ENAMETOOLONG) => &buf[..crate::process::NAME_LEN],
                Err(e) => return Err(e),
            };
            let name = core::str::from_utf8(name).unwrap_or("?");
            c.p.set_name(name);
            Ok(0)
        }
        PR_GET_NAME => {
            let mut buf = [0u8; 16];
            buf[..c.p.name().len()].copy_from_slice(c.p.name().as_bytes());
            c.write_user(arg, &buf)?;
            Ok(0)
        }
        _ => {
            if c.reported.first(nr::prctl) {
                c.host.log(format_args!(
                    "guest: process {} ({}): unsupported prctl option {option}, returning EINVAL",
                    c.p.pid,
                    c.p.name()
                ));
            }
            Err(Errno::EINVAL)
        }
    }
}
/// `futex`: the process table's, as a wake acts on other threads' waits.
pub fn futex<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    to_process_table(c, ProcessCall::Futex { args: a.0 })
}

// Signals and timers.

pub fn rt_sigaction<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    sigcalls::sigaction(c, a.raw(0), a.ptr(1), a.ptr(2), a.usize(3))
}
pub fn rt_sigprocmask<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    sigcalls::sigprocmask(c, a.flags(0), a.ptr(1), a.ptr(2), a.usize(3))
}
pub fn rt_sigpending<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    sigcalls::sigpending(c, a.ptr(0), a.usize(1))
}
/// Restores the registers the signal frame saved: the thread resumes with them, not with
/// a return value.
pub fn rt_sigreturn<H: Host>(c: &mut Ctx<H>, _: Args) -> Result {
    if sigcalls::sigreturn(c).is_some() {
        return c.finish(Outcome::Resume);
    }
    c.host.log(format_args!(
        "guest: process {} ({}) killed by signal {SIGSEGV} (SIGSEGV): rt_sigreturn without a readable signal frame",
        c.p.pid,
        c.p.name()
    ));
    c.finish(Outcome::Killed(SIGSEGV))
}
pub fn sigaltstack<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let sp = c.m.registers.rsp;
    sigcalls::sigaltstack(c, sp, a.ptr(0), a.ptr(1))
}
pub fn rt_sigsuspend<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    sigcalls::sigsuspend(c, a.ptr(0), a.usize(1))
}
/// Waits until a signal.
pub fn pause<H: Host>(_: &mut Ctx<H>, _: Args) -> Result {
    Err(WOULD_BLOCK)
}
pub fn nanosleep<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    sigcalls::sleep(c, linux::CLOCK_MONOTONIC, 0, a.ptr(0))
}
pub fn clock_nanosleep<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    sigcalls::sleep(c, a.raw(0), a.flags(1), a.ptr(2))
}
pub fn alarm<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    Ok(sigcalls::alarm(c, a.raw(0)))
}
pub fn getitimer<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    sigcalls::getitimer(c, a.raw(0), a.ptr(1))
}
pub fn setitimer<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    sigcalls::setitimer(c, a.raw(0), a.ptr(1), a.ptr(2))
}

// Waiting for descriptors.

pub fn poll<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let timeout = poll::poll_timeout(a.raw(2));
    poll::poll(c, a.ptr(0), a.usize(1), timeout, 0, 0)
}
pub fn ppoll<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let timeout = poll::ppoll_timeout(c, a.ptr(2))?;
    let (mask, size) = (a.ptr(3), a.usize(4));
    poll::poll(c, a.ptr(0), a.usize(1), timeout, mask, size)
}
pub fn select<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    poll::select(c, a.0, false)
}
pub fn pselect6<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    poll::select(c, a.0, true)
}

// Event descriptors ([`super::events`]).

pub fn eventfd<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    events::eventfd(c, a.raw(0), 0)
}
pub fn eventfd2<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    events::eventfd(c, a.raw(0), a.flags(1))
}
pub fn timerfd_create<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    events::timerfd_create(c, a.raw(0), a.flags(1))
}
pub fn timerfd_settime<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    events::timerfd_settime(c, a.fd(0), a.flags(1), a.ptr(2), a.ptr(3))
}
pub fn timerfd_gettime<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    events::timerfd_gettime(c, a.fd(0), a.ptr(1))
}
pub fn epoll_create<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    events::epoll_create(c, a.i32(0))
}
pub fn epoll_create1<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    events::epoll_create1(c, a.flags(0))
}
pub fn epoll_ctl<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    events::epoll_ctl(c, a.fd(0), a.raw(1) as u32 as u64, a.fd(2), a.ptr(3))
}
pub fn epoll_wait<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let timeout = poll::poll_timeout(a.raw(3));
    events::epoll_wait(c, a.fd(0), a.ptr(1), a.i32(2), timeout, 0, 0)
}
pub fn epoll_pwait<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let timeout = poll::poll_timeout(a.raw(3));
    let (mask, size) = (a.ptr(4), a.usize(5));
    events::epoll_wait(c, a.fd(0), a.ptr(1), a.i32(2), timeout, mask, size)
}
pub fn epoll_pwait2<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let timeout = poll::ppoll_timeout(c, a.ptr(3))?;
    let (mask, size) = (a.ptr(4), a.usize(5));
    events::epoll_wait(c, a.fd(0), a.ptr(1), a.i32(2), timeout, mask, size)
}

// Time, randomness, the system.

pub fn clock_gettime<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    // CLOCK_REALTIME .. CLOCK_BOOTTIME: the real-time ones the wall clock, the others the
    // guest's clock.
    let clock = a.raw(0);
    if clock > 7 {
        return Err(Errno::EINVAL);
    }
    let ns = if super::is_realtime(clock) {
        c.host.wall_clock_ns()
    } else {
        c.host.now_ns()
    };
    c.write_user(a.ptr(1), &linux::timespec(ns))?;
    Ok(0)
}
pub fn clock_getres<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    if a.raw(0) > 7 {
        return Err(Errno::EINVAL);
    }
    // The guest's clock counts nanoseconds (the kernel's, from the TSC).
    if a.ptr(1) != 0 {
        c.write_user(a.ptr(1), &linux::timespec(1))?;
    }
    Ok(0)
}
pub fn gettimeofday<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let ns = c.host.wall_clock_ns();
    if a.ptr(0) != 0 {
        c.write_user(a.ptr(0), &linux::timeval(ns))?;
    }
    Ok(0)
}
pub fn time<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let seconds = c.host.wall_clock_ns() / 1_000_000_000;
    if a.ptr(0) != 0 {
        c.write_user(a.ptr(0), &seconds.to_le_bytes())?;
    }
    Ok(seconds)
}
pub fn getrandom<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    if a.flags(2) & !7 != 0 {
        return Err(Errno::EINVAL);
    }
    let mut bytes = [0u8; 256];
    let n = (a.usize(1) as usize).min(bytes.len());
    c.host.random(&mut bytes[..n]);
    c.write_user(a.ptr(0), &bytes[..n])?;
    Ok(n as u64)
}
pub fn uname<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let mut u = [0u8; 6 * 65];
    let fields: [&[u8]; 6] = [
        b"Linux",
        b"warden",
        b"6.1.0-warden",
        b"#1 Warden paravirtualized guest",
        b"x86_64",
        b"(none)",
    ];
    for (i, field) in fields.iter().enumerate() {
        u[i * 65..i * 65 + field.len()].copy_from_slice(field);
    }
    c.write_user(a.ptr(0), &u)?;
    Ok(0)
}

// Limits and resources.

pub fn prlimit64<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    if a.raw(0) != 0 && a.raw(0) != c.p.pid as u64 {
        return Err(Errno::ESRCH);
    }
    info::rlimit(c, a.raw(1), a.ptr(2), a.ptr(3))
}
pub fn getrlimit<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    info::rlimit(c, a.raw(0), 0, a.ptr(1))
}
pub fn setrlimit<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    info::rlimit(c, a.raw(0), a.ptr(1), 0)
}
pub fn getrusage<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    match a.i32(0) {
        // RUSAGE_SELF, RUSAGE_CHILDREN, RUSAGE_THREAD
        -1..=1 => c.write_user(a.ptr(1), &[0; 144]).map(|()| 0),
        _ => Err(Errno::EINVAL),
    }
}
pub fn times<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    if a.ptr(0) != 0 {
        c.write_user(a.ptr(0), &[0; 32])?;
    }
    Ok(c.host.now_ns() / (1_000_000_000 / info::TICKS_PER_S))
}
/// `sched_getaffinity(pid, len, mask)`: the CPUs thread `pid` (0: the caller) may run
/// on, of the guest's ([`Host::cpus`]), as Linux: `len` must be a whole number of words
/// reaching its mask's size (`EINVAL`), `ESRCH` without such a thread; writes and returns
/// that size.
pub fn sched_getaffinity<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    const CPUMASK_SIZE: u64 = crate::system::CPUMASK_SIZE as u64;
    let len = a.usize(1);
    if len < CPUMASK_SIZE || !len.is_multiple_of(CPUMASK_SIZE) {
        return Err(Errno::EINVAL);
    }
    let affinity = match a.raw(0) as i32 {
        0 => c.p.affinity,
        tid if tid as u32 == c.p.pid => c.p.affinity,
        tid if tid < 0 => return Err(Errno::ESRCH),
        tid => c.f.others.find(tid as u32).ok_or(Errno::ESRCH)?.affinity,
    };
    let allowed = affinity & c.host.cpus();
    c.write_user(a.ptr(2), &allowed.to_le_bytes())?;
    Ok(CPUMASK_SIZE)
}
/// The process table's: the thread may be another than the caller ([`crate::system`]).
pub fn sched_setaffinity<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (pid, len, mask) = (a.raw(0), a.usize(1), a.ptr(2));
    to_process_table(c, ProcessCall::SetAffinity { pid, len, mask })
}
/// `getcpu(cpu, node, cache)`: the caller's CPU ([`crate::system`] placed it) and node 0
/// (the guest has one memory node); either pointer may be null.
pub fn getcpu<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    if a.ptr(0) != 0 {
        let cpu = c.p.cpu;
        c.write_user(a.ptr(0), &cpu.to_le_bytes())?;
    }
    if a.ptr(1) != 0 {
        c.write_user(a.ptr(1), &0u32.to_le_bytes())?;
    }
    Ok(0)
}
// Nice 0 for everyone (the raw call returns 20 - nice); only root sets it, and the guest
// schedules its processes alike anyway.
pub fn getpriority<H: Host>(_: &mut Ctx<H>, a: Args) -> Result {
    einval_unless(a.raw(0) <= 2, 20)
}
pub fn setpriority<H: Host>(_: &mut Ctx<H>, a: Args) -> Result {
    einval_unless(a.raw(0) <= 2, 0)
}

/// `value` when the arguments are `valid`, else `EINVAL`.
fn einval_unless(valid: bool, value: u64) -> Result {
    if valid { Ok(value) } else { Err(Errno::EINVAL) }
}

// Identity: one user, root, and one thread per process.

/// A thread's process id never changes (an `execve` keeps it), so after the first call
/// the kernel answers it: a Linux `getpid` costs a kernel entry, not a message.
pub fn getpid<H: Host>(c: &mut Ctx<H>, _: Args) -> Result {
    c.host.answer_always(c.p.pid, nr::getpid, c.p.tgid);
    Ok(c.p.tgid as u64)
}
pub fn gettid<H: Host>(c: &mut Ctx<H>, _: Args) -> Result {
    Ok(c.p.pid as u64)
}
pub fn getppid<H: Host>(c: &mut Ctx<H>, _: Args) -> Result {
    Ok(c.p.ppid as u64)
}
pub fn getpgrp<H: Host>(c: &mut Ctx<H>, _: Args) -> Result {
    Ok(c.p.pgid as u64)
}
/// `getuid`, `geteuid`, `getgid`, `getegid`.
pub fn root_id<H: Host>(_: &mut Ctx<H>, _: Args) -> Result {
    Ok(0)
}
/// Setting ids: -1 keeps an id; 0 is the only one there is.
fn only_root(ids: &[u64]) -> Result {
    if ids
        .iter()
        .all(|&id| id as u32 == 0 || id as u32 == u32::MAX)
    {
        Ok(0)
    } else {
        Err(Errno::EPERM)
    }
}
/// `setuid`, `setgid`.
pub fn setuid<H: Host>(_: &mut Ctx<H>, a: Args) -> Result {
    only_root(&a.0[..1])
}
/// `setreuid`, `setregid`.
pub fn setreuid<H: Host>(_: &mut Ctx<H>, a: Args) -> Result {
    only_root(&a.0[..2])
}
/// `setresuid`, `setresgid`.
pub fn setresuid<H: Host>(_: &mut Ctx<H>, a: Args) -> Result {
    only_root(&a.0[..3])
}
/// `getresuid`, `getresgid`.
pub fn getresuid<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    for i in 0..3 {
        c.write_user(a.ptr(i), &0u32.to_le_bytes())?;
    }
    Ok(0)
}
/// No supplementary groups.
pub fn getgroups<H: Host>(_: &mut Ctx<H>, a: Args) -> Result {
    einval_unless(a.i32(0) >= 0, 0)
}
/// Root may set (and so drop) the supplementary groups.
pub fn setgroups<H: Host>(_: &mut Ctx<H>, a: Args) -> Result {
    einval_unless(a.usize(0) <= 65536, 0)
}

// The process table's: decoded here, served by [`crate::system`].

/// Hands the decoded `call` to the process table.
fn to_process_table<H: Host>(c: &mut Ctx<H>, call: ProcessCall) -> Result {
    c.finish(Outcome::Process(call))
}

/// `exit_group`: the process ends, all its threads.
pub fn exit_group<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let status = a.raw(0) as u8;
    c.host.log(format_args!(
        "guest: process {} exited with status {status}",
        c.p.tgid
    ));
    c.finish(Outcome::Exit(status))
}
/// `exit`: the calling thread ends; a process's first thread ends the process (Linux
/// would keep it a zombie thread until the others end: the guest ends them with it).
pub fn exit<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    if c.p.is_thread() {
        return to_process_table(c, ProcessCall::ExitThread);
    }
    exit_group(c, a)
}
pub fn clone<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (flags, stack, parent_tid, child_tid, tls) =
        (a.flags(0), a.ptr(1), a.ptr(2), a.ptr(3), a.ptr(4));
    to_process_table(
        c,
        ProcessCall::Clone {
            flags,
            args: [stack, parent_tid, child_tid, tls],
        },
    )
}
pub fn fork<H: Host>(c: &mut Ctx<H>, _: Args) -> Result {
    let flags = crate::signal::SIGCHLD as u64;
    to_process_table(
        c,
        ProcessCall::Clone {
            flags,
            args: [0; 4],
        },
    )
}
pub fn vfork<H: Host>(c: &mut Ctx<H>, _: Args) -> Result {
    let flags =
        crate::system::CLONE_VM | crate::system::CLONE_VFORK | crate::signal::SIGCHLD as u64;
    to_process_table(
        c,
        ProcessCall::Clone {
            flags,
            args: [0; 4],
        },
    )
}
pub fn execve<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (path, argv, envp) = (a.ptr(0), a.ptr(1), a.ptr(2));
    to_process_table(c, ProcessCall::Execve { path, argv, envp })
}
pub fn wait4<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (pid, status, options, rusage) = (a.i32(0), a.ptr(1), a.flags(2), a.ptr(3));
    to_process_table(
        c,
        ProcessCall::Wait4 {
            pid,
            status,
            options,
            rusage,
        },
    )
}
pub fn waitid<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (idtype, id, info, options) = (a.raw(0), a.raw(1), a.ptr(2), a.flags(3));
    to_process_table(
        c,
        ProcessCall::Waitid {
            idtype,
            id,
            info,
            options,
        },
    )
}
/// Sends `signal` to `target` (a pid, or a group as `kill` encodes it).
fn send<H: Host>(c: &mut Ctx<H>, target: i64, signal: u64) -> Result {
    to_process_table(c, ProcessCall::Kill { target, signal })
}
pub fn kill<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    send(c, a.i32(0) as i64, a.raw(1))
}
/// Sends `signal` to thread `tid` (of process `tgid`, when given).
fn send_thread<H: Host>(c: &mut Ctx<H>, tgid: Option<u32>, tid: i32, signal: u64) -> Result {
    let tid = u32::try_from(tid)
        .ok()
        .filter(|&t| t > 0)
        .ok_or(Errno::EINVAL)?;
    to_process_table(c, ProcessCall::KillThread { tgid, tid, signal })
}
pub fn tkill<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    send_thread(c, None, a.i32(0), a.raw(1))
}
pub fn tgkill<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let tgid = u32::try_from(a.i32(0))
        .ok()
        .filter(|&g| g > 0)
        .ok_or(Errno::EINVAL)?;
    send_thread(c, Some(tgid), a.i32(1), a.raw(2))
}
pub fn setpgid<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (pid, pgid) = (a.raw(0), a.raw(1));
    to_process_table(c, ProcessCall::SetPgid { pid, pgid })
}
pub fn getpgid<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let pid = a.raw(0);
    to_process_table(
        c,
        ProcessCall::GroupOf {
            pid,
            session: false,
        },
    )
}
pub fn getsid<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let pid = a.raw(0);
    to_process_table(c, ProcessCall::GroupOf { pid, session: true })
}
pub fn setsid<H: Host>(c: &mut Ctx<H>, _: Args) -> Result {
    to_process_table(c, ProcessCall::SetSid)
}
/// The process count is the process table's.
pub fn sysinfo<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let record = a.ptr(0);
    to_process_table(c, ProcessCall::Sysinfo { record })
}
