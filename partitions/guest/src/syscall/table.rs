//! The guest's Linux system calls: one line per x86-64 number ([`crate::linux::nr`]) naming
//! the handler that serves it ([`super::handlers`]). A number without a line answers
//! `ENOSYS` ([`super::handle`]). Adding a call is one line here plus its handler, a
//! `fn(&mut Ctx, Args) -> SysResult<u64>`.
//!
//! The table expands to a `match` on the number (a jump table, as cheap as the hand-written
//! match it replaced) that yields the handler, and to [`NUMBERS`], the numbers it serves.

use super::handlers::*;
use super::socket::*;
use super::{Host, Reported, SysResult};
use crate::linux::nr;
use crate::process::Process;
use crate::syscall::Outcome;
use crate::syscall::file::Files;
use abi::ipc::ExceptionMessage;

/// What a handler works with: the calling process, its files (descriptors, pipes, the file
/// system, the other processes for `/proc`), the guest's services and the exception
/// message of the call (its registers, for the calls that read or set them).
pub struct Ctx<'c, 'a, H> {
    pub p: &'c mut Process,
    pub f: Files<'c, 'a>,
    pub host: &'c mut H,
    pub m: &'c mut ExceptionMessage,
    /// What the guest has logged as unsupported (once per guest).
    pub reported: &'c mut Reported,
    /// Set by the calls that do not simply return a value: the process ends, is given to
    /// the process table, or resumes with registers the call restored.
    pub outcome: Option<Outcome>,
}

impl<'c, 'a, H: Host> Ctx<'c, 'a, H> {
    pub fn new(
        p: &'c mut Process,
        f: Files<'c, 'a>,
        reported: &'c mut Reported,
        host: &'c mut H,
        m: &'c mut ExceptionMessage,
    ) -> Ctx<'c, 'a, H> {
        Ctx {
            p,
            f,
            host,
            m,
            reported,
            outcome: None,
        }
    }

    /// The process, its files and the host at once, for a handler that works with all three.
    pub fn parts(&mut self) -> (&mut Process, &mut Files<'c, 'a>, &mut H) {
        (&mut *self.p, &mut self.f, &mut *self.host)
    }

    /// Copies the process's memory at `address` into `buf` (`EFAULT` outside its readable
    /// areas).
    pub fn read_user(&mut self, address: u64, buf: &mut [u8]) -> SysResult<()> {
        super::read_user(self.p, self.host, address, buf)
    }

    /// Copies `data` into the process's memory at `address` (`EFAULT` outside its writable
    /// areas).
    pub fn write_user(&mut self, address: u64, data: &[u8]) -> SysResult<()> {
        super::write_user(self.p, self.host, address, data)
    }

    /// The NUL-terminated string at `address` (at most `buf.len() - 1` bytes).
    pub fn read_cstr<'b>(&mut self, address: u64, buf: &'b mut [u8]) -> SysResult<&'b [u8]> {
        super::read_cstr(self.p, self.host, address, buf)
    }

    /// The call ends with `outcome` instead of a return value in `rax`.
    pub fn finish(&mut self, outcome: Outcome) -> SysResult<u64> {
        self.outcome = Some(outcome);
        Ok(0)
    }
}

/// The six argument registers of a call (`rdi`, `rsi`, `rdx`, `r10`, `r8`, `r9`), read as
/// what the call means by them.
#[derive(Clone, Copy, Debug)]
pub struct Args(pub [u64; 6]);

impl Args {
    pub fn of(m: &ExceptionMessage) -> Self {
        let r = &m.registers;
        Args([r.rdi, r.rsi, r.rdx, r.r10, r.r8, r.r9])
    }
    /// Argument `i` as the register holds it.
    pub fn raw(self, i: usize) -> u64 {
        self.0[i]
    }
    /// A file descriptor.
    pub fn fd(self, i: usize) -> u64 {
        self.0[i]
    }
    /// An address in the process.
    pub fn ptr(self, i: usize) -> u64 {
        self.0[i]
    }
    /// A length or count.
    pub fn usize(self, i: usize) -> u64 {
        self.0[i]
    }
    /// A C `int` (the register's low half, sign and all).
    pub fn i32(self, i: usize) -> i32 {
        self.0[i] as i32
    }
    /// Flags, a mode or an option.
    pub fn flags(self, i: usize) -> u64 {
        self.0[i]
    }
    /// A file offset (`pread64`, `pwrite64`): negative ones are `EINVAL`.
    pub fn offset(self, i: usize) -> SysResult<u64> {
        if (self.0[i] as i64) < 0 {
            Err(crate::linux::Errno::EINVAL)
        } else {
            Ok(self.0[i])
        }
    }
}

/// A handler of one or more system calls.
pub type Handler<H> = fn(&mut Ctx<'_, '_, H>, Args) -> SysResult<u64>;

/// The table's line for a number: the call's name and its handler's.
pub struct Entry<H> {
    pub name: &'static str,
    pub handler_name: &'static str,
    pub handler: Handler<H>,
}

macro_rules! table {
    ($($name:ident => $handler:ident,)*) => {
        /// The line of `number`, if the guest serves it.
        #[inline]
        pub fn lookup<H: Host>(number: u64) -> Option<Entry<H>> {
            match number {
                $(nr::$name => Some(Entry {
                    name: stringify!($name),
                    handler_name: stringify!($handler),
                    handler: $handler::<H>,
                }),)*
                _ => None,
            }
        }

        /// Every number the table serves.
        #[cfg_attr(not(test), allow(dead_code))]
        pub const NUMBERS: &[u64] = &[$(nr::$name),*];
    };
}

table! {
    // Files: descriptors, reading and writing ([`super::file`]).
    read => read,
    write => write,
    pread64 => pread64,
    pwrite64 => pwrite64,
    readv => readv,
    writev => writev,
    sendfile => sendfile,
    open => open,
    creat => creat,
    openat => openat,
    close => close,
    close_range => close_range,
    dup => dup,
    dup2 => dup2,
    dup3 => dup3,
    pipe => pipe,
    pipe2 => pipe2,
    lseek => lseek,
    ftruncate => ftruncate,
    truncate => truncate,
    getdents64 => getdents64,
    fcntl => fcntl,
    ioctl => ioctl,
    fsync => fsync,
    fdatasync => fsync,
    syncfs => syncfs,
    fadvise64 => sync_fd,
    sync => sync,
    mount => mount,
    umount2 => umount2,
    // Names and status.
    stat => stat,
    lstat => lstat,
    fstat => fstat,
    newfstatat => newfstatat,
    statx => statx,
    statfs => statfs,
    fstatfs => fstatfs,
    access => access,
    faccessat => faccessat,
    faccessat2 => faccessat,
    readlink => readlink,
    readlinkat => readlinkat,
    mkdir => mkdir,
    mkdirat => mkdirat,
    unlink => unlink,
    rmdir => rmdir,
    unlinkat => unlinkat,
    rename => rename,
    renameat => renameat,
    renameat2 => renameat2,
    symlink => symlink,
    symlinkat => symlinkat,
    link => link,
    linkat => linkat,
    chdir => chdir,
    fchdir => fchdir,
    getcwd => getcwd,
    chmod => chmod,
    fchmod => fchmod,
    fchmodat => fchmodat,
    chown => chown,
    lchown => lchown,
    fchown => fchown,
    fchownat => fchownat,
    utimensat => utimensat,
    utime => utimes,
    utimes => utimes,
    umask => umask,
    // Memory ([`super::memory`]).
    brk => brk,
    mmap => mmap,
    munmap => munmap,
    mprotect => mprotect,
    madvise => madvise,
    mremap => mremap,
    mlock => mlock,
    mlock2 => mlock2,
    munlock => munlock,
    mlockall => mlockall,
    munlockall => munlockall,
    // The thread.
    arch_prctl => arch_prctl,
    set_tid_address => set_tid_address,
    set_robust_list => set_robust_list,
    rseq => no_rseq,
    prctl => prctl,
    futex => futex,
    // Signals and timers ([`crate::sigcalls`]).
    rt_sigaction => rt_sigaction,
    rt_sigprocmask => rt_sigprocmask,
    rt_sigpending => rt_sigpending,
    rt_sigreturn => rt_sigreturn,
    sigaltstack => sigaltstack,
    rt_sigsuspend => rt_sigsuspend,
    pause => pause,
    nanosleep => nanosleep,
    clock_nanosleep => clock_nanosleep,
    alarm => alarm,
    getitimer => getitimer,
    setitimer => setitimer,
    // Sockets ([`super::socket`]).
    socket => socket,
    socketpair => socketpair,
    bind => bind,
    listen => listen,
    accept => accept,
    accept4 => accept4,
    connect => connect,
    sendto => sendto,
    recvfrom => recvfrom,
    sendmsg => sendmsg,
    recvmsg => recvmsg,
    shutdown => shutdown,
    getsockname => getsockname,
    getpeername => getpeername,
    setsockopt => setsockopt,
    getsockopt => getsockopt,
    // Waiting for descriptors ([`crate::poll`]).
    poll => poll,
    ppoll => ppoll,
    select => select,
    pselect6 => pselect6,
    // Event descriptors ([`super::events`]).
    eventfd => eventfd,
    eventfd2 => eventfd2,
    timerfd_create => timerfd_create,
    timerfd_settime => timerfd_settime,
    timerfd_gettime => timerfd_gettime,
    epoll_create => epoll_create,
    epoll_create1 => epoll_create1,
    epoll_ctl => epoll_ctl,
    epoll_wait => epoll_wait,
    epoll_pwait => epoll_pwait,
    epoll_pwait2 => epoll_pwait2,
    // Time, randomness, the system.
    clock_gettime => clock_gettime,
    clock_getres => clock_getres,
    gettimeofday => gettimeofday,
    time => time,
    getrandom => getrandom,
    uname => uname,
    sched_yield => nothing,
    // Limits and resources ([`crate::info`]).
    prlimit64 => prlimit64,
    getrlimit => getrlimit,
    setrlimit => setrlimit,
    getrusage => getrusage,
    times => times,
    sched_getaffinity => sched_getaffinity,
    getcpu => getcpu,
    getpriority => getpriority,
    setpriority => setpriority,
    // Identity: one user (root).
    getpid => getpid,
    gettid => gettid,
    getppid => getppid,
    getpgrp => getpgrp,
    getuid => root_id,
    geteuid => root_id,
    getgid => root_id,
    getegid => root_id,
    setuid => setuid,
    setgid => setuid,
    setreuid => setreuid,
    setregid => setreuid,
    setresuid => setresuid,
    setresgid => setresuid,
    getresuid => getresuid,
    getresgid => getresuid,
    getgroups => getgroups,
    setgroups => setgroups,
    // The process table's ([`crate::system`]).
    exit => exit,
    exit_group => exit_group,
    clone => clone,
    fork => fork,
    vfork => vfork,
    execve => execve,
    wait4 => wait4,
    waitid => waitid,
    kill => kill,
    tkill => tkill,
    tgkill => tgkill,
    setpgid => setpgid,
    getpgid => getpgid,
    setsid => setsid,
    getsid => getsid,
    sysinfo => sysinfo,
    sched_setaffinity => sched_setaffinity,
}

/// The calls that change nothing but their caller's own state (what it learns, its memory
/// map, its signal dispositions and mask, its own timers): serving one cannot end another
/// process's wait, so the process table does not serve the blocked calls again after it
/// ([`super::touches_only_caller`], [`crate::system`]). Each is a line of the table above.
pub const CALLER_ONLY: &[u64] = &[
    nr::getpid,
    nr::gettid,
    nr::getppid,
    nr::getpgrp,
    nr::getuid,
    nr::geteuid,
    nr::getgid,
    nr::getegid,
    nr::getresuid,
    nr::getresgid,
    nr::getgroups,
    nr::getrlimit,
    nr::getrusage,
    nr::times,
    nr::sched_getaffinity,
    nr::getcpu,
    nr::getpriority,
    nr::uname,
    nr::clock_gettime,
    nr::clock_getres,
    nr::gettimeofday,
    nr::time,
    nr::getrandom,
    nr::brk,
    nr::mmap,
    nr::mprotect,
    nr::madvise,
    nr::arch_prctl,
    nr::set_tid_address,
    nr::set_robust_list,
    nr::rseq,
    nr::rt_sigaction,
    nr::rt_sigprocmask,
    nr::rt_sigpending,
    nr::sigaltstack,
    nr::alarm,
    nr::getitimer,
    nr::setitimer,
    nr::stat,
    nr::lstat,
    nr::fstat,
    nr::newfstatat,
    nr::statx,
    nr::statfs,
    nr::fstatfs,
    nr::access,
    nr::faccessat,
    nr::faccessat2,
    nr::readlink,
    nr::readlinkat,
    nr::getcwd,
    nr::umask,
    nr::lseek,
    // The guest has no FIFO or terminal whose opening another call waits for.
    nr::open,
    nr::openat,
    // Another descriptor of an open file: nothing is closed.
    nr::dup,
];

/// [`CALLER_ONLY`] as one bit per number, for a lookup per message (every number is below
/// 512: a larger one fails the build here).
const CALLER_ONLY_BITS: [u64; 8] = {
    let mut bits = [0u64; 8];
    let mut i = 0;
    while i < CALLER_ONLY.len() {
        let number = CALLER_ONLY[i] as usize;
        bits[number / 64] |= 1 << (number % 64);
        i += 1;
    }
    bits
};

/// Whether `number` is one of [`CALLER_ONLY`].
pub fn caller_only(number: u64) -> bool {
    number < 512 && CALLER_ONLY_BITS[(number / 64) as usize] & (1 << (number % 64)) != 0
}
