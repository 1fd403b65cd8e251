//! The file system calls of a process: descriptors (`dup*`, `pipe*`, `close`,
//! `close_range`, `fcntl`),
//! reading and writing (`read`, `write`, `readv`, `writev`, `pread64`, `pwrite64`,
//! `sendfile`, `lseek`, `ftruncate`, `truncate`), names (`open`, `openat`, `creat`,
//! `mkdir*`, `unlink*`, `rmdir`, `rename*`, `symlink*`, `link*`, `readlink*`), status
//! (`stat`, `lstat`, `fstat`, `newfstatat`, `statx`, `statfs`, `fstatfs`, `access`,
//! `faccessat*`, `getdents64`), the working directory (`chdir`, `fchdir`, `getcwd`) and
//! attributes (`chmod`, `fchmod*`; `chown*` and `utime*` are accepted, the owner stays
//! root). The file system itself is [`crate::vfs`]; this module copies paths and data
//! between it and the process and never keeps state of its own.

use super::table::Ctx;
use super::{
    BROKEN_PIPE, Host, IOV_MAX, MAX_TRANSFER, O_CLOEXEC, SysResult, WOULD_BLOCK, check_user,
    read_cstr, read_u64, write_user,
};
use crate::arinc;
use crate::events::Events;
use crate::linux::{self, Errno};
use crate::memory::Rights;
use crate::net::Net;
use crate::pipe::{Pipes, Transfer};
use crate::process::{File, Process, Stream};
use crate::signal::{self, Info};
use crate::tty;
use crate::vfs::dev::Device;
use crate::vfs::proc::{self, ProcInfo, ProcessTable, Procs};
use crate::vfs::{self, Fs, Node, PATH_MAX, Remove, Stat};

/// What the file calls act on besides the process: the pipes, the sockets, the file
/// system and the other processes (`/proc`).
pub struct Files<'f, 'a> {
    pub pipes: &'f mut Pipes,
    /// The `eventfd` counters, `timerfd` timers and epoll instances.
    pub events: &'f mut Events,
    pub net: &'f mut Net,
    pub fs: &'f mut Fs<'a>,
    pub others: &'f dyn ProcessTable,
}

/// Bytes moved through the guest per step (a pipe's atomic write: one pipe transfer).
const CHUNK: usize = crate::pipe::PIPE_BUF;
/// `S_IFIFO` (a pipe's `st_mode`).
const S_IFIFO: u32 = 0o010000;
/// `S_IFSOCK` (a socket's).
const S_IFSOCK: u32 = 0o140000;
/// `struct statfs`'s `f_type` of a tmpfs.
const TMPFS_MAGIC: u64 = 0x0102_1994;

/// The processes as the calls of `p` see them. A thread sees itself as its process, as on
/// Linux, where `/proc/self` names the thread group (`getpid`), not the thread: the Go
/// runtime and others compare `/proc/self/stat`'s pid with `getpid`. The calling thread
/// holds its process's shared state (descriptors, areas) while its call is served.
fn procs<'s>(p: &'s Process, f: &'s Files) -> Procs<'s> {
    Procs {
        me: ProcInfo {
            pid: p.tgid,
            ..ProcInfo::of(p, b'R')
        },
        tid: p.pid,
        others: f.others,
        now_ns: 0,
        cpus: 1,
        memory: f.fs.memory(),
        fs_used: f.fs.usage().0 as u64,
        interfaces: f.net.interfaces(),
        gateway: f.net.gateway(),
        mount: f.fs.mount_info(),
    }
}

/// The wall clock in seconds (file times).
fn seconds(host: &mut impl Host) -> u64 {
    host.wall_clock_ns() / 1_000_000_000
}

// ---- descriptors ----

/// Closes descriptor `fd` if open (a pipe end, socket, open file description or event
/// object counts one descriptor less); what it referred to leaves the epoll interest lists
/// when this was its last descriptor, as on Linux.
pub fn close(
    p: &mut Process,
    pipes: &mut Pipes,
    events: &mut Events,
    net: &mut Net,
    fs: &mut Fs,
    fd: usize,
) {
    let Some(file) = p.take_fd(fd) else {
        return;
    };
    let gone = match file {
        File::Pipe { pipe, write, .. } => {
            pipes.close_end(pipe, write);
            !pipes.end_open(pipe, write)
        }
        File::UnixSocket { pair, end, .. } => {
            pipes.close_pair(pair, end);
            !pipes.pair_open(pair, end)
        }
        File::Socket(id) => {
            net.release(id);
            !net.is_open(id)
        }
        File::Open(id) => {
            fs.release(id);
            fs.description(id).is_none()
        }
        // `release` forgets them itself.
        File::Event(_) | File::Timer(_) | File::Epoll(_) => {
            events.release(file);
            false
        }
        File::Console(_) => false,
    };
    if gone {
        events.forget(file);
    }
}

/// Closes every descriptor of `p` and lets its working directory go (it ends), or closes
/// only the close-on-exec ones (`execve`).
pub fn close_files(
    p: &mut Process,
    pipes: &mut Pipes,
    events: &mut Events,
    net: &mut Net,
    fs: &mut Fs,
    only_cloexec: bool,
) {
    for fd in (0..p.files.len()).rev() {
        if !only_cloexec || p.is_cloexec(fd) {
            close(p, pipes, events, net, fs, fd);
        }
    }
    if !only_cloexec {
        fs.unhold(p.cwd);
    }
}

/// Another descriptor of everything `p` has open, and its working directory once more (a
/// forked child's copies).
pub fn share_files(
    p: &Process,
    pipes: &mut Pipes,
    events: &mut Events,
    net: &mut Net,
    fs: &mut Fs,
) {
    fs.hold(p.cwd);
    for &file in p.files.iter().flatten() {
        share(pipes, events, net, fs, file);
    }
}

/// One more descriptor refers to `file`.
fn share(pipes: &mut Pipes, events: &mut Events, net: &mut Net, fs: &mut Fs, file: File) {
    match file {
        File::Pipe { pipe, write, .. } => pipes.add_end(pipe, write),
        File::UnixSocket { pair, end, .. } => pipes.share_pair(pair, end),
        File::Socket(id) => net.share(id),
        File::Open(id) => fs.share(id),
        File::Event(_) | File::Timer(_) | File::Epoll(_) => events.share(file),
        File::Console(_) => {}
    }
}

/// Puts a copy of `file` at the free descriptor `fd`.
fn duplicate(p: &mut Process, f: &mut Files, file: File, fd: usize, cloexec: bool) {
    share(f.pipes, f.events, f.net, f.fs, file);
    p.install(fd, file, cloexec);
}

pub fn close_fd(c: &mut Ctx<'_, '_, impl Host>, fd: u64) -> SysResult<u64> {
    let (p, f, _) = c.parts();
    p.file(fd).ok_or(Errno::EBADF)?;
    close(p, f.pipes, f.events, f.net, f.fs, fd as usize);
    Ok(0)
}

/// `close_range(first, last, flags)`: closes the open descriptors from `first` to `last`,
/// or with `CLOSE_RANGE_CLOEXEC` marks them close-on-exec. `CLOSE_RANGE_UNSHARE` has
/// nothing to do: no two processes share a descriptor table here (`fork` copies it).
pub fn close_range(
    c: &mut Ctx<'_, '_, impl Host>,
    first: u64,
    last: u64,
    flags: u64,
) -> SysResult<u64> {
    const CLOSE_RANGE_UNSHARE: u64 = 1 << 1;
    const CLOSE_RANGE_CLOEXEC: u64 = 1 << 2;
    let (first, last) = (first as u32, last as u32);
    if flags & !(CLOSE_RANGE_UNSHARE | CLOSE_RANGE_CLOEXEC) != 0 || first > last {
        return Err(Errno::EINVAL);
    }
    let (p, f, _) = c.parts();
    let end = (last as usize).saturating_add(1).min(p.files.len());
    // Downwards: closing the highest shrinks the table.
    for fd in ((first as usize).min(end)..end).rev() {
        if p.files.get(fd).is_none_or(Option::is_none) {
            continue;
        }
        if flags & CLOSE_RANGE_CLOEXEC != 0 {
            p.set_cloexec(fd, true);
        } else {
            close(p, f.pipes, f.events, f.net, f.fs, fd);
        }
    }
    Ok(0)
}

pub fn dup(c: &mut Ctx<'_, '_, impl Host>, fd: u64) -> SysResult<u64> {
    let (p, f, _) = c.parts();
    let file = p.file(fd).ok_or(Errno::EBADF)?;
    let new = p.free_fd().ok_or(Errno::EMFILE)?;
    duplicate(p, f, file, new, false);
    Ok(new as u64)
}

/// `dup2` (`flags: None`) and `dup3`.
pub fn dup3(
    c: &mut Ctx<'_, '_, impl Host>,
    old: u64,
    new: u64,
    flags: Option<u64>,
) -> SysResult<u64> {
    let (p, f, _) = c.parts();
    let bits = flags.unwrap_or(0);
    if bits & !O_CLOEXEC != 0 || (flags.is_some() && old == new) {
        return Err(Errno::EINVAL);
    }
    let file = p.file(old).ok_or(Errno::EBADF)?;
    let fd = usize::try_from(new)
        .ok()
        .filter(|&fd| fd < p.max_fd())
        .ok_or(Errno::EBADF)?;
    if old != new {
        close(p, f.pipes, f.events, f.net, f.fs, fd);
        duplicate(p, f, file, fd, bits & O_CLOEXEC != 0);
    }
    Ok(fd as u64)
}

pub fn pipe(c: &mut Ctx<'_, '_, impl Host>, fds: u64, flags: u64) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    if flags & !(O_CLOEXEC | linux::O_NONBLOCK) != 0 {
        return Err(Errno::EINVAL);
    }
    check_user(p, fds, 8, Rights::WRITE)?;
    let read_fd = p.free_fd().ok_or(Errno::EMFILE)?;
    let write_fd = p.free_fd_from(read_fd + 1).ok_or(Errno::EMFILE)?;
    let index = f.pipes.open().ok_or(Errno::ENFILE)?;
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

/// The `ioctl` requests every kind of descriptor takes (Linux serves them above the
/// driver): `FIONBIO` sets or clears `O_NONBLOCK` as `F_SETFL` does, `FIOCLEX`/`FIONCLEX`
/// the close-on-exec flag as `F_SETFD`; `None` for any other request.
pub fn generic_ioctl(
    c: &mut Ctx<'_, '_, impl Host>,
    fd: u64,
    request: u64,
    arg: u64,
) -> Option<SysResult<u64>> {
    const FIONBIO: u64 = 0x5421;
    const FIONCLEX: u64 = 0x5450;
    const FIOCLEX: u64 = 0x5451;
    match request & 0xffff_ffff {
        FIOCLEX => Some(fcntl(c, fd, F_SETFD, 1)),
        FIONCLEX => Some(fcntl(c, fd, F_SETFD, 0)),
        FIONBIO => Some((|| {
            let mut on = [0u8; 4];
            c.read_user(arg, &mut on)?;
            let flags = fcntl(c, fd, F_GETFL, 0)?;
            let flags = if i32::from_le_bytes(on) != 0 {
                flags | linux::O_NONBLOCK
            } else {
                flags & !linux::O_NONBLOCK
            };
            fcntl(c, fd, F_SETFL, flags)
        })()),
        _ => None,
    }
}

const F_GETFD: u64 = 1;
const F_SETFD: u64 = 2;
const F_GETFL: u64 = 3;
const F_SETFL: u64 = 4;

pub fn fcntl(c: &mut Ctx<'_, '_, impl Host>, fd: u64, cmd: u64, arg: u64) -> SysResult<u64> {
    let (p, f, _) = c.parts();
    const F_DUPFD: u64 = 0;
    const F_DUPFD_CLOEXEC: u64 = 1030;
    const FD_CLOEXEC: u64 = 1;
    let file = p.file(fd).ok_or(Errno::EBADF)?;
    let fd = fd as usize;
    match cmd {
        F_DUPFD | F_DUPFD_CLOEXEC => {
            let low = usize::try_from(arg)
                .ok()
                .filter(|&low| low < p.max_fd())
                .ok_or(Errno::EINVAL)?;
            let new = p.free_fd_from(low).ok_or(Errno::EMFILE)?;
            duplicate(p, f, file, new, cmd == F_DUPFD_CLOEXEC);
            Ok(new as u64)
        }
        F_GETFD => Ok(if p.is_cloexec(fd) { FD_CLOEXEC } else { 0 }),
        F_SETFD => {
            p.set_cloexec(fd, arg & FD_CLOEXEC != 0);
            Ok(0)
        }
        // O_NONBLOCK of a pipe end or a socket pair's end (this descriptor's: Linux shares
        // it with the descriptors dup'ed from it); O_APPEND and O_NONBLOCK of an open file
        // description (shared).
        F_SETFL => {
            match file {
                File::Pipe { .. } | File::UnixSocket { .. } => {
                    p.files[fd] = Some(file.with_nonblock(arg & linux::O_NONBLOCK != 0));
                }
                File::Open(id) => {
                    const CHANGEABLE: u64 = linux::O_APPEND | linux::O_NONBLOCK;
                    if let Some(o) = f.fs.description_mut(id) {
                        o.flags = (o.flags & !CHANGEABLE) | (arg & CHANGEABLE);
                    }
                }
                File::Socket(id) => {
                    let nonblock = arg & linux::O_NONBLOCK != 0;
                    let _ = f
                        .net
                        .stack(0)
                        .set_nonblocking(netstack::SocketId(id), nonblock);
                }
                File::Event(i) => {
                    if let Some(c) = f.events.counter(i) {
                        c.nonblock = arg & linux::O_NONBLOCK != 0;
                    }
                }
                File::Timer(i) => {
                    if let Some(t) = f.events.timer(i) {
                        t.nonblock = arg & linux::O_NONBLOCK != 0;
                    }
                }
                File::Console(_) | File::Epoll(_) => {}
            }
            Ok(0)
        }
        F_GETFL => Ok(match file {
            File::Console(_) => linux::O_RDWR,
            File::Socket(id) => {
                let nonblock = f.net.stack(0).is_nonblocking(netstack::SocketId(id));
                linux::O_RDWR
                    | if nonblock == Ok(true) {
                        linux::O_NONBLOCK
                    } else {
                        0
                    }
            }
            File::Open(id) => f.fs.description(id).map_or(0, |o| o.flags),
            File::Pipe {
                write, nonblock, ..
            } => {
                let access = if write { linux::O_WRONLY } else { 0 };
                access | if nonblock { linux::O_NONBLOCK } else { 0 }
            }
            File::UnixSocket { nonblock, .. } => {
                linux::O_RDWR | if nonblock { linux::O_NONBLOCK } else { 0 }
            }
            File::Event(i) => {
                let nonblock = f.events.counter(i).is_some_and(|c| c.nonblock);
                linux::O_RDWR | if nonblock { linux::O_NONBLOCK } else { 0 }
            }
            File::Timer(i) => {
                let nonblock = f.events.timer(i).is_some_and(|t| t.nonblock);
                linux::O_RDWR | if nonblock { linux::O_NONBLOCK } else { 0 }
            }
            File::Epoll(_) => linux::O_RDWR,
        }),
        _ => Err(Errno::EINVAL),
    }
}

// ---- reading and writing ----

/// Reads from `fd` into `buf` (at most one pipe's worth from a pipe), at `at` or (`None`)
/// at the description's offset, which then moves.
fn read_kernel(
    p: &Process,
    f: &mut Files,
    host: &mut impl Host,
    fd: u64,
    buf: &mut [u8],
    at: Option<u64>,
) -> SysResult<usize> {
    match p.file(fd).ok_or(Errno::EBADF)? {
        File::Console(_) if at.is_some() => Err(Errno::ESPIPE),
        File::Console(_) => Ok(0),             // served by `console_read`
        File::Socket(_) => Err(Errno::EINVAL), // `read` serves sockets itself
        File::Pipe { write: true, .. } => Err(Errno::EBADF),
        File::Pipe { .. } if at.is_some() => Err(Errno::ESPIPE),
        File::Pipe { pipe, nonblock, .. } => {
            transferred(f.pipes.read(pipe, buf), nonblock, Errno::EBADF)
        }
        File::UnixSocket { .. } if at.is_some() => Err(Errno::ESPIPE),
        File::UnixSocket {
            pair,
            end,
            nonblock,
        } => transferred(f.pipes.read_pair(pair, end, buf), nonblock, Errno::EBADF),
        File::Event(_) | File::Timer(_) if at.is_some() => Err(Errno::ESPIPE),
        File::Event(i) => super::events::read_counter(f, i, buf),
        File::Timer(i) => super::events::read_timer(f, host, i, buf),
        File::Epoll(_) => Err(Errno::EINVAL),
        File::Open(id) => {
            let o = f.fs.description(id).ok_or(Errno::EBADF)?;
            if o.flags & linux::O_ACCMODE == linux::O_WRONLY {
                return Err(Errno::EBADF);
            }
            let node = o.node;
            if f.fs.is_dir(node) {
                return Err(Errno::EISDIR);
            }
            if let Some((index, port)) = f.fs.port(node) {
                if at.is_some() {
                    return Err(Errno::ESPIPE);
                }
                let nonblock = o.flags & linux::O_NONBLOCK != 0;
                return arinc::read(port, index, host, buf, nonblock);
            }
            match f.fs.device(node) {
                Some(Device::Disk) => {
                    let offset = at.unwrap_or(o.offset);
                    let n = f.fs.disk()?.read(offset, buf)?;
                    return Ok(moved(f, id, at, offset, n));
                }
                Some(Device::Null) => return Ok(0),
                Some(Device::Zero) => {
                    buf.fill(0);
                    return Ok(buf.len());
                }
                Some(Device::Urandom | Device::Random) => {
                    host.random(buf);
                    return Ok(buf.len());
                }
                Some(Device::Console | Device::Tty | Device::Port(_)) | None => {}
            }
            let offset = at.unwrap_or(o.offset);
            if let Node::Mounted(_) = node {
                let n = f.fs.read_mounted(node, offset, buf)?;
                return Ok(moved(f, id, at, offset, n));
            }
            let bytes = match &o.snapshot {
                Some(s) => &s[..],
                None => f.fs.file_bytes(node).ok_or(Errno::EINVAL)?,
            };
            let start = offset.min(bytes.len() as u64) as usize;
            let n = buf.len().min(bytes.len() - start);
            buf[..n].copy_from_slice(&bytes[start..start + n]);
            Ok(moved(f, id, at, offset, n))
        }
    }
}

/// Writes `data` to `fd`, at `at` or (`None`) at the description's offset (its end with
/// `O_APPEND`), which then moves.
fn write_kernel(
    p: &Process,
    f: &mut Files,
    host: &mut impl Host,
    fd: u64,
    data: &[u8],
    at: Option<u64>,
) -> SysResult<usize> {
    match p.file(fd).ok_or(Errno::EBADF)? {
        File::Console(_) if at.is_some() => Err(Errno::ESPIPE),
        File::Console(stream) => {
            host.console_write(p.pid, stream, data);
            Ok(data.len())
        }
        File::Socket(_) if at.is_some() => Err(Errno::ESPIPE),
        // One step (`sendfile`): what the connection takes now, or the wait.
        File::Socket(id) => {
            let now = host.now_ns();
            let stack = f.net.stack(now);
            let id = netstack::SocketId(id);
            let nonblock = stack.is_nonblocking(id).unwrap_or(false);
            match stack.send(id, data, None) {
                Ok(n) => Ok(n),
                Err(netstack::Error::WouldBlock) if nonblock => Err(Errno::EAGAIN),
                Err(netstack::Error::WouldBlock) => Err(WOULD_BLOCK),
                Err(netstack::Error::BrokenPipe) => Err(BROKEN_PIPE),
                Err(e) => Err(crate::net::errno(e)),
            }
        }
        File::Pipe { write: false, .. } => Err(Errno::EBADF),
        File::Pipe { .. } if at.is_some() => Err(Errno::ESPIPE),
        File::Pipe { pipe, nonblock, .. } => {
            transferred(f.pipes.write(pipe, data), nonblock, BROKEN_PIPE)
        }
        File::UnixSocket { .. } if at.is_some() => Err(Errno::ESPIPE),
        File::UnixSocket {
            pair,
            end,
            nonblock,
        } => transferred(f.pipes.write_pair(pair, end, data), nonblock, BROKEN_PIPE),
        File::Event(_) if at.is_some() => Err(Errno::ESPIPE),
        File::Event(i) => super::events::write_counter(f, i, data),
        File::Timer(_) | File::Epoll(_) => Err(Errno::EINVAL),
        File::Open(id) => {
            let o = f.fs.description(id).ok_or(Errno::EBADF)?;
            if o.flags & linux::O_ACCMODE == 0 {
                return Err(Errno::EBADF);
            }
            let node = o.node;
            if let Some((index, port)) = f.fs.port(node) {
                if at.is_some() {
                    return Err(Errno::ESPIPE);
                }
                let nonblock = o.flags & linux::O_NONBLOCK != 0;
                return arinc::write(port, index, host, data, nonblock);
            }
            if f.fs.device(node) == Some(Device::Disk) {
                let (flags, current) = (o.flags, o.offset);
                let disk = f.fs.disk()?;
                // O_APPEND writes at the end: ENOSPC, as on Linux.
                let offset = if flags & linux::O_APPEND != 0 {
                    disk.size()
                } else {
                    at.unwrap_or(current)
                };
                let n = disk.write(offset, data)?;
                return Ok(moved(f, id, at, offset, n));
            }
            if f.fs.device(node).is_some() {
                return Ok(data.len()); // null, zero, random: swallowed
            }
            let offset = if o.flags & linux::O_APPEND != 0 {
                f.fs.stat(node).size
            } else {
                at.unwrap_or(o.offset)
            };
            let now = seconds(host);
            let n = f.fs.write(node, offset, data, now)?;
            Ok(moved(f, id, at, offset, n))
        }
    }
}

/// What a pipe's or a socket pair's transfer gives the caller: the bytes moved, `EAGAIN`
/// or a wait when it would block (`nonblock`: `O_NONBLOCK` or `MSG_DONTWAIT`), `broken`
/// when nobody reads (`BROKEN_PIPE`: `EPIPE` and `SIGPIPE`).
pub fn transferred(t: Transfer, nonblock: bool, broken: Errno) -> SysResult<usize> {
    match t {
        Transfer::Done(n) => Ok(n),
        Transfer::WouldBlock if nonblock => Err(Errno::EAGAIN),
        Transfer::WouldBlock => Err(WOULD_BLOCK),
        Transfer::Broken => Err(broken),
    }
}

/// `n` bytes moved at `offset` through the open file description `id`: unless the call
/// named its offset (`at`, pread/pwrite), the description's offset now follows them.
fn moved(f: &mut Files, id: crate::vfs::OpenId, at: Option<u64>, offset: u64, n: usize) -> usize {
    if at.is_none()
        && let Some(o) = f.fs.description_mut(id)
    {
        o.offset = offset + n as u64;
    }
    n
}

/// A read (`write`: a write) of `fd` failed with `e`: when it had to wait, the file's
/// readiness was used up, and an edge-triggered epoll reports its return
/// ([`crate::events::Epoll::consumed`]).
fn used_up(p: &Process, f: &mut Files, fd: u64, e: Errno, write: bool) {
    if matches!(e, Errno::EAGAIN | WOULD_BLOCK)
        && let Some(file) = p.file(fd)
    {
        super::events::consumed(f, file, write);
    }
}

/// Whether reading or writing `fd` may go on after a full step (files, devices and the
/// console; a pipe moves at most one step per call, what it holds or has room for, and a
/// port one message).
fn streams(p: &Process, f: &Files, fd: u64) -> bool {
    match p.file(fd) {
        Some(
            File::Pipe { .. }
            | File::UnixSocket { .. }
            | File::Socket(_)
            | File::Event(_)
            | File::Timer(_),
        ) => false,
        Some(File::Open(id)) => {
            f.fs.description(id)
                .is_none_or(|o| f.fs.port(o.node).is_none())
        }
        _ => true,
    }
}

/// Whether `fd` is open on the block device `/dev/vda` ([`crate::disk`]).
pub fn is_disk(p: &Process, fs: &Fs, fd: u64) -> bool {
    match p.file(fd) {
        Some(File::Open(id)) => fs
            .description(id)
            .is_some_and(|o| fs.device(o.node) == Some(Device::Disk)),
        _ => false,
    }
}

/// Most bytes one `read` or `write` of `fd` moves: [`crate::disk::MAX_TRANSFER`] on the
/// block device (each of its sectors is a request the guest waits for), else
/// [`MAX_TRANSFER`].
fn transfer_max(p: &Process, fs: &Fs, fd: u64) -> usize {
    if is_disk(p, fs, fd) {
        crate::disk::MAX_TRANSFER
    } else {
        MAX_TRANSFER
    }
}

/// `ioctl` on the block device: the requests of [`crate::disk::ioctl`]; `ENOTTY` for the
/// others.
pub fn disk_ioctl(
    c: &mut Ctx<'_, '_, impl Host>,
    fd: u64,
    request: u64,
    arg: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    if !is_disk(p, f.fs, fd) {
        return Err(Errno::ENOTTY);
    }
    match crate::disk::ioctl(request, f.fs.disk_size()?)? {
        crate::disk::Answer::U64(v) => write_user(p, host, arg, &v.to_le_bytes())?,
        crate::disk::Answer::U32(v) => write_user(p, host, arg, &v.to_le_bytes())?,
        crate::disk::Answer::FlushBuffers => f.fs.disk()?.flush_buffers()?,
    }
    Ok(0)
}

/// `fsync`, `fdatasync` of `fd`, and `syncfs` (`all`) and `sync`: the block device's
/// flush ([`crate::disk`]) when `fd` is open on it, the mounted file system's write-back
/// and flush when `fd` is on it ([`crate::vfs::mounted`]), both for `all`; nothing else
/// needs one (the other files live in memory).
pub fn sync(c: &mut Ctx<'_, '_, impl Host>, fd: Option<u64>, all: bool) -> SysResult<u64> {
    let (p, f, _) = c.parts();
    let node = match fd {
        Some(fd) => {
            let file = p.file(fd).ok_or(Errno::EBADF)?;
            match file {
                _ if all => None,
                File::Open(id) => Some(f.fs.description(id).ok_or(Errno::EBADF)?.node),
                _ => return Ok(0),
            }
        }
        None => None,
    };
    f.fs.sync(node).map(|()| 0)
}

/// `mount(source, target, type, flags)`: the ext2 file system of `/dev/vda` on directory
/// `target` ([`vfs::mounted`]); `MS_RDONLY` mounts it read-only, the flags that only
/// restrict (`nosuid`, `nodev`, `noexec`, `noatime`, `relatime`, `silent`) are accepted;
/// remounts, binds, moves and propagation changes are `EINVAL`. A source that is no block
/// device is `ENOTBLK`, an unknown type `ENODEV`.
pub fn mount(
    c: &mut Ctx<'_, '_, impl Host>,
    source: u64,
    target: u64,
    fstype: u64,
    flags: u64,
) -> SysResult<u64> {
    const MS_RDONLY: u64 = 1;
    // nosuid, nodev, noexec, synchronous, noatime, nodiratime, silent, relatime,
    // strictatime, lazytime, and the old magic number in the high half.
    const HARMLESS: u64 =
        2 | 4 | 8 | 16 | 1024 | 2048 | (1 << 15) | (1 << 21) | (1 << 24) | (1 << 25);
    const MAGIC_MASK: u64 = 0xffff_0000;
    const MAGIC: u64 = 0xc0ed_0000;
    let (p, f, host) = c.parts();
    let flags = if flags & MAGIC_MASK == MAGIC {
        flags & !MAGIC_MASK
    } else {
        flags
    };
    if flags & !(MS_RDONLY | HARMLESS) != 0 {
        return Err(Errno::EINVAL);
    }
    let mut kind = [0u8; 16];
    let kind = read_cstr(p, host, fstype, &mut kind).map_err(|_| Errno::ENODEV)?;
    if !vfs::mounted::TYPES.contains(&kind) {
        return Err(Errno::ENODEV);
    }
    let device = resolve(p, f, host, linux::AT_FDCWD as u64, source, true)?;
    if f.fs.device(device) != Some(Device::Disk) {
        return Err(Errno::ENOTBLK);
    }
    let at = resolve(p, f, host, linux::AT_FDCWD as u64, target, true)?;
    let now = seconds(host);
    match f.fs.mount(at, flags & MS_RDONLY != 0, now) {
        Ok(()) => Ok(0),
        Err((e, why)) => {
            if let Some(why) = why {
                host.log(format_args!(
                    "guest: mount {}: {why}",
                    crate::disk::DEVICE_PATH
                ));
            }
            Err(e)
        }
    }
}

/// `umount2(target, flags)` (busybox's `umount`): `UMOUNT_NOFOLLOW` honoured, the
/// force and lazy flags accepted (a busy file system still answers `EBUSY`).
pub fn umount(c: &mut Ctx<'_, '_, impl Host>, target: u64, flags: u64) -> SysResult<u64> {
    const MNT_FORCE: u64 = 1;
    const MNT_DETACH: u64 = 2;
    const MNT_EXPIRE: u64 = 4;
    const UMOUNT_NOFOLLOW: u64 = 8;
    let (p, f, host) = c.parts();
    if flags & !(MNT_FORCE | MNT_DETACH | MNT_EXPIRE | UMOUNT_NOFOLLOW) != 0 {
        return Err(Errno::EINVAL);
    }
    let follow = flags & UMOUNT_NOFOLLOW == 0;
    let at = resolve(p, f, host, linux::AT_FDCWD as u64, target, follow)?;
    f.fs.umount(at)?;
    Ok(0)
}

/// The ARINC port open at `fd`, with its index ([`crate::arinc`]).
pub fn port_at<'f>(p: &Process, fs: &'f Fs, fd: u64) -> Option<(usize, &'f arinc::Port)> {
    match p.file(fd)? {
        File::Open(id) => fs.port(fs.description(id)?.node),
        _ => None,
    }
}

/// `ioctl` on an ARINC port: [`arinc::IOCTL_VALIDITY`]; any other request is `ENOTTY`.
pub fn port_ioctl(
    c: &mut Ctx<'_, '_, impl Host>,
    fd: u64,
    request: u64,
    arg: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let p = &*p;
    let f = &*f;
    let (index, port) = port_at(p, f.fs, fd).ok_or(Errno::ENOTTY)?;
    if request as u32 as u64 != arinc::IOCTL_VALIDITY {
        return Err(Errno::ENOTTY);
    }
    let valid = arinc::validity(port, index, host)?;
    write_user(p, host, arg, &valid.to_le_bytes())?;
    Ok(0)
}

/// A `read` of the console: the terminal's input ([`crate::tty`]; waits for it), or end of
/// file when the console is the log. A background job reading its terminal gets SIGTTIN,
/// which stops it; the read starts again when it is continued (in the foreground). EIO
/// when that signal would not stop it.
fn console_read(p: &mut Process, host: &mut impl Host, buf: u64, count: u64) -> SysResult<u64> {
    let n = (count as usize).min(tty::INPUT_MAX);
    check_user(p, buf, n, Rights::WRITE)?;
    let Some(tty) = host.tty() else {
        return Ok(0);
    };
    if tty.session() == p.sid && tty.foreground() != p.pgid {
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

/// `read` (`at: None`) and `pread64`.
pub fn read(
    c: &mut Ctx<'_, '_, impl Host>,
    fd: u64,
    buf: u64,
    count: u64,
    at: Option<u64>,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    if at.is_none() && matches!(p.file(fd), Some(File::Console(_))) {
        return console_read(p, host, buf, count);
    }
    if let Some(File::Socket(_)) = p.file(fd) {
        if at.is_some() {
            return Err(Errno::ESPIPE);
        }
        let got = super::socket::recv(c, fd, buf, count.min(MAX_TRANSFER as u64), 0);
        if let Err(e) = got {
            let (p, f, _) = c.parts();
            used_up(p, f, fd, e, false);
        }
        return got;
    }
    let total = (count as usize).min(transfer_max(p, f.fs, fd));
    check_user(p, buf, total, Rights::WRITE)?;
    let mut chunk = [0u8; CHUNK];
    let mut done = 0;
    loop {
        let want = (total - done).min(CHUNK);
        let n = match read_kernel(
            p,
            f,
            host,
            fd,
            &mut chunk[..want],
            at.map(|a| a + done as u64),
        ) {
            Ok(n) => n,
            // What moved already counts (the block device's EIO after some sectors).
            Err(_) if done > 0 => break,
            Err(e) => {
                used_up(p, f, fd, e, false);
                return Err(e);
            }
        };
        host.write_user(buf + done as u64, &chunk[..n])?;
        done += n;
        if n < want || done == total || !streams(p, f, fd) {
            break;
        }
    }
    Ok(done as u64)
}

/// `write` (`at: None`) and `pwrite64`.
pub fn write(
    c: &mut Ctx<'_, '_, impl Host>,
    fd: u64,
    buf: u64,
    count: u64,
    at: Option<u64>,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    if let Some(File::Socket(_)) = p.file(fd) {
        if at.is_some() {
            return Err(Errno::ESPIPE);
        }
        let sent = super::socket::send(c, fd, buf, count, 0, None);
        if let Err(e) = sent {
            let (p, f, _) = c.parts();
            used_up(p, f, fd, e, true);
        }
        return sent;
    }
    if let Some((_, port)) = port_at(p, f.fs, fd)
        && arinc::too_long(port, count)
    {
        return Err(Errno::EMSGSIZE); // not cut into pieces the size of a step
    }
    let total = (count as usize).min(transfer_max(p, f.fs, fd));
    check_user(p, buf, total, Rights::READ)?;
    let file = p.file(fd).ok_or(Errno::EBADF)?;
    if let File::Pipe {
        write: true,
        nonblock: false,
        ..
    } = file
    {
        return pipe_write(p, f, host, fd, buf, total);
    }
    let mut chunk = [0u8; CHUNK];
    let mut done = 0;
    while done < total {
        let want = (total - done).min(CHUNK);
        host.read_user(buf + done as u64, &mut chunk[..want])?;
        let n = match write_kernel(p, f, host, fd, &chunk[..want], at.map(|a| a + done as u64)) {
            Ok(n) => n,
            // What moved already counts.
            Err(_) if done > 0 => break,
            Err(e) => {
                used_up(p, f, fd, e, true);
                return Err(e);
            }
        };
        done += n;
        if n < want || !streams(p, f, fd) {
            break;
        }
    }
    Ok(done as u64)
}

/// A blocking `write` to a pipe: all of it, waiting for room as often as needed (the
/// progress is kept in the process between the serves of its waiting call); a reader that
/// goes away meanwhile ends it with what moved (`EPIPE` and SIGPIPE when nothing did).
fn pipe_write(
    p: &mut Process,
    f: &mut Files,
    host: &mut impl Host,
    fd: u64,
    buf: u64,
    total: usize,
) -> SysResult<u64> {
    let mut chunk = [0u8; CHUNK];
    let mut done = (p.pipe_written as usize).min(total);
    while done < total {
        let want = (total - done).min(CHUNK);
        host.read_user(buf + done as u64, &mut chunk[..want])?;
        match write_kernel(p, f, host, fd, &chunk[..want], None) {
            Ok(n) => done += n,
            Err(WOULD_BLOCK) => {
                p.pipe_written = done as u64;
                return Err(WOULD_BLOCK);
            }
            Err(_) if done > 0 => break,
            Err(e) => {
                p.pipe_written = 0;
                return Err(e);
            }
        }
    }
    p.pipe_written = 0;
    Ok(done as u64)
}

pub fn vectored(
    c: &mut Ctx<'_, '_, impl Host>,
    is_write: bool,
    fd: u64,
    iov: u64,
    count: u64,
) -> SysResult<u64> {
    if count > IOV_MAX {
        return Err(Errno::EINVAL);
    }
    c.p.file(fd).ok_or(Errno::EBADF)?;
    // The block device's bound holds for the whole call.
    let most = if is_disk(c.p, c.f.fs, fd) {
        crate::disk::MAX_TRANSFER as u64
    } else {
        u64::MAX
    };
    let mut total = 0u64;
    for i in 0..count {
        if total >= most {
            break;
        }
        let base = read_u64(c.p, c.host, iov + i * 16)?;
        let len = read_u64(c.p, c.host, iov + i * 16 + 8)?;
        if len == 0 {
            continue;
        }
        let len = len.min(most - total);
        let n = match if is_write {
            write(c, fd, base, len, None)
        } else {
            read(c, fd, base, len, None)
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

/// `sendfile`: from a file (or device) at its offset or at `*offset_ptr`, to any
/// writable descriptor, one step per call (callers loop).
pub fn sendfile(
    c: &mut Ctx<'_, '_, impl Host>,
    out_fd: u64,
    in_fd: u64,
    offset_ptr: u64,
    count: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let writable = match p.file(out_fd).ok_or(Errno::EBADF)? {
        File::Console(_)
        | File::Pipe { write: true, .. }
        | File::UnixSocket { .. }
        | File::Socket(_)
        | File::Event(_) => true,
        File::Pipe { .. } | File::Timer(_) | File::Epoll(_) => false,
        File::Open(id) => {
            f.fs.description(id)
                .is_some_and(|o| o.flags & linux::O_ACCMODE != 0)
        }
    };
    if !writable {
        return Err(Errno::EBADF);
    }
    let File::Open(id) = p.file(in_fd).ok_or(Errno::EBADF)? else {
        return Err(Errno::EINVAL); // pipes and the console cannot be sent from
    };
    let o = f.fs.description(id).ok_or(Errno::EBADF)?;
    if f.fs.is_dir(o.node) {
        return Err(Errno::EINVAL);
    }
    let from = if offset_ptr != 0 {
        read_u64(p, host, offset_ptr)?
    } else {
        o.offset
    };
    let mut chunk = [0u8; CHUNK];
    let want = (count as usize).min(CHUNK);
    // Read without moving the offset: a write that waits leaves everything unchanged.
    let n = read_kernel(p, f, host, in_fd, &mut chunk[..want], Some(from))?;
    if n == 0 {
        return Ok(0);
    }
    let written = write_kernel(p, f, host, out_fd, &chunk[..n], None)?;
    let to = from + written as u64;
    if offset_ptr != 0 {
        write_user(p, host, offset_ptr, &to.to_le_bytes())?;
    } else if let Some(o) = f.fs.description_mut(id) {
        o.offset = to;
    }
    Ok(written as u64)
}

pub fn lseek(c: &mut Ctx<'_, '_, impl Host>, fd: u64, offset: i64, whence: u64) -> SysResult<u64> {
    let (p, f, _) = c.parts();
    let File::Open(id) = p.file(fd).ok_or(Errno::EBADF)? else {
        return Err(Errno::ESPIPE);
    };
    let o = f.fs.description(id).ok_or(Errno::EBADF)?;
    if f.fs.device(o.node) == Some(Device::Disk) {
        let size = f.fs.disk_size()?;
        let new = crate::disk::seek(o.offset, offset, whence, size)?;
        if let Some(o) = f.fs.description_mut(id) {
            o.offset = new;
        }
        return Ok(new);
    }
    let size = match &o.snapshot {
        Some(s) => s.len() as u64,
        None => f.fs.stat(o.node).size,
    };
    let is_dir = f.fs.is_dir(o.node);
    let base = match whence {
        0 => 0,
        1 => o.offset as i64,
        2 => size as i64,
        _ => return Err(Errno::EINVAL),
    };
    let new = base
        .checked_add(offset)
        .filter(|&n| n >= 0)
        .ok_or(Errno::EINVAL)?;
    if is_dir && new != o.offset as i64 && !matches!(o.node, Node::Mounted(_)) {
        // A directory's offset counts entries: only its start can be sought (and where it
        // is, told).
        if new != 0 {
            return Err(Errno::EINVAL);
        }
        f.fs.set_cursor(id, None)?;
    }
    if let Some(o) = f.fs.description_mut(id) {
        o.offset = new as u64;
    }
    Ok(new as u64)
}

/// `ftruncate`.
pub fn ftruncate(c: &mut Ctx<'_, '_, impl Host>, fd: u64, len: u64) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let File::Open(id) = p.file(fd).ok_or(Errno::EBADF)? else {
        return Err(Errno::EINVAL);
    };
    let o = f.fs.description(id).ok_or(Errno::EBADF)?;
    if o.flags & linux::O_ACCMODE == 0 {
        return Err(Errno::EINVAL);
    }
    let node = o.node;
    if (len as i64) < 0 {
        return Err(Errno::EINVAL);
    }
    let now = seconds(host);
    f.fs.truncate(node, len, now)?;
    Ok(0)
}

/// `truncate`.
pub fn truncate(c: &mut Ctx<'_, '_, impl Host>, path: u64, len: u64) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let node = resolve(p, f, host, linux::AT_FDCWD as u64, path, true)?;
    if (len as i64) < 0 {
        return Err(Errno::EINVAL);
    }
    let now = seconds(host);
    f.fs.truncate(node, len, now)?;
    Ok(0)
}

// ---- names ----

/// The directory relative paths of `*at` calls start from: `dirfd`'s, or the working
/// directory (`AT_FDCWD`).
fn base(p: &Process, f: &Files, dirfd: u64, path: &[u8]) -> SysResult<Node> {
    if path.first() == Some(&b'/') || dirfd as u32 as i32 as i64 == linux::AT_FDCWD {
        return Ok(p.cwd);
    }
    match p.file(dirfd).ok_or(Errno::EBADF)? {
        File::Open(id) => {
            let node = f.fs.description(id).ok_or(Errno::EBADF)?.node;
            if f.fs.is_dir(node) {
                Ok(node)
            } else {
                Err(Errno::ENOTDIR)
            }
        }
        _ => Err(Errno::ENOTDIR),
    }
}

/// The node path `path` of the process names, from `dirfd`.
fn resolve(
    p: &Process,
    f: &Files,
    host: &mut impl Host,
    dirfd: u64,
    path: u64,
    follow: bool,
) -> SysResult<Node> {
    let mut buf = [0u8; PATH_MAX];
    let text = read_cstr(p, host, path, &mut buf)?;
    let start = base(p, f, dirfd, text)?;
    f.fs.lookup(&procs(p, f), start, text, follow)
}

/// The directory that holds the last component of `path` (from `dirfd`), and that name
/// (in `buf`).
fn resolve_parent<'b>(
    p: &Process,
    f: &Files,
    host: &mut impl Host,
    dirfd: u64,
    path: u64,
    buf: &'b mut [u8; PATH_MAX],
) -> SysResult<(Node, &'b [u8])> {
    let text = read_cstr(p, host, path, buf)?;
    let start = base(p, f, dirfd, text)?;
    f.fs.lookup_parent(&procs(p, f), start, text)
}

/// `openat` (and `open`, `creat`).
pub fn openat(
    c: &mut Ctx<'_, '_, impl Host>,
    dirfd: u64,
    path: u64,
    flags: u64,
    mode: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    const KEPT: u64 = linux::O_ACCMODE | linux::O_APPEND | linux::O_NONBLOCK;
    let access = flags & linux::O_ACCMODE;
    if access == linux::O_ACCMODE {
        return Err(Errno::EINVAL);
    }
    let fd = p.free_fd().ok_or(Errno::EMFILE)?;
    let mut buf = [0u8; PATH_MAX];
    let text = read_cstr(p, host, path, &mut buf)?;
    let start = base(p, f, dirfd, text)?;
    let create = flags & linux::O_CREAT != 0;
    let exclusive = create && flags & linux::O_EXCL != 0;
    let follow = flags & linux::O_NOFOLLOW == 0 && !exclusive;
    let found = f.fs.lookup(&procs(p, f), start, text, follow);
    let node = match found {
        Ok(_) if exclusive => return Err(Errno::EEXIST),
        Ok(node) => node,
        Err(Errno::ENOENT) if create => {
            if text.last() == Some(&b'/') {
                return Err(Errno::EISDIR);
            }
            let (dir, name) = f.fs.lookup_parent(&procs(p, f), start, text)?;
            if f.fs.get(dir, name).is_some() {
                // A link to a missing file: Linux creates the target; not here.
                return Err(Errno::ENOENT);
            }
            let now = seconds(host);
            let mode = mode as u32 & !p.umask & 0o7777;
            f.fs.create(dir, name, mode, now)?
        }
        Err(e) => return Err(e),
    };
    if let Node::Proc(proc::Node::Fd(pid, n)) = node
        && follow
    {
        // `/proc/<pid>/fd/<n>` of a pipe or the console: what that descriptor has, the
        // pipe's end as the access mode asks (a file resolved to itself in the lookup).
        let file = proc::fd_file(&procs(p, f), pid, n).ok_or(Errno::ENOENT)?;
        let file = match file {
            File::Pipe { pipe, write, .. } => {
                let write = match access {
                    0 => false, // O_RDONLY
                    linux::O_WRONLY => true,
                    _ => write,
                };
                let nonblock = flags & linux::O_NONBLOCK != 0;
                File::Pipe {
                    pipe,
                    write,
                    nonblock,
                }
            }
            File::Console(_) => File::Console(Stream::Stdout),
            // Linux refuses to open a socket through its link.
            // Nor is an event descriptor reopened through it here.
            File::Socket(_)
            | File::UnixSocket { .. }
            | File::Event(_)
            | File::Timer(_)
            | File::Epoll(_) => {
                return Err(Errno::ENXIO);
            }
            File::Open(_) => return Err(Errno::ENOENT),
        };
        duplicate(p, f, file, fd, flags & O_CLOEXEC != 0);
        return Ok(fd as u64);
    }
    if f.fs.is_symlink(node) {
        return Err(Errno::ELOOP); // O_NOFOLLOW on a link
    }
    let is_dir = f.fs.is_dir(node);
    if flags & linux::O_DIRECTORY != 0 && !is_dir {
        return Err(Errno::ENOTDIR);
    }
    if is_dir && access != 0 {
        return Err(Errno::EISDIR);
    }
    let cloexec = flags & O_CLOEXEC != 0;
    if let Some(device) = f.fs.device(node)
        && device.is_console()
    {
        p.install(fd, File::Console(Stream::Stdout), cloexec);
        return Ok(fd as u64);
    }
    let snapshot = match node {
        Node::Proc(n) => {
            if access != 0 {
                return Err(Errno::EACCES);
            }
            if proc::is_dir(n) {
                None
            } else {
                let mut procs = procs(p, f);
                procs.now_ns = host.now_ns();
                procs.cpus = host.cpus();
                Some(proc::contents(n, &procs).ok_or(Errno::ENOENT)?)
            }
        }
        Node::Inode(_) | Node::Mounted(_) => None,
    };
    if flags & linux::O_TRUNC != 0 && access != 0 && f.fs.is_file(node) {
        let now = seconds(host);
        f.fs.truncate(node, 0, now)?;
    }
    let id = f.fs.open(node, flags & KEPT, snapshot)?;
    p.install(fd, File::Open(id), cloexec);
    Ok(fd as u64)
}

pub fn mkdirat(c: &mut Ctx<'_, '_, impl Host>, dirfd: u64, path: u64, mode: u64) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let mut buf = [0u8; PATH_MAX];
    let (dir, name) = match resolve_parent(p, f, host, dirfd, path, &mut buf) {
        Err(Errno::EINVAL | Errno::EBUSY) => return Err(Errno::EEXIST), // ".", "..", "/"
        r => r?,
    };
    let now = seconds(host);
    f.fs.mkdir(dir, name, mode as u32 & !p.umask & 0o7777, now)?;
    Ok(0)
}

/// `unlinkat` (`AT_REMOVEDIR`: `rmdir`), `unlink`, `rmdir`.
pub fn unlinkat(
    c: &mut Ctx<'_, '_, impl Host>,
    dirfd: u64,
    path: u64,
    flags: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    if flags & !linux::AT_REMOVEDIR != 0 {
        return Err(Errno::EINVAL);
    }
    let mut buf = [0u8; PATH_MAX];
    let (dir, name) = resolve_parent(p, f, host, dirfd, path, &mut buf)?;
    let what = if flags & linux::AT_REMOVEDIR != 0 {
        Remove::Dir
    } else {
        Remove::File
    };
    let now = seconds(host);
    f.fs.remove(dir, name, what, now)?;
    Ok(0)
}

/// `renameat2` (`RENAME_NOREPLACE` only), `renameat`, `rename`.
#[allow(clippy::too_many_arguments)] // the call's arguments
pub fn renameat2(
    c: &mut Ctx<'_, '_, impl Host>,
    old_dirfd: u64,
    old: u64,
    new_dirfd: u64,
    new: u64,
    flags: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    const RENAME_NOREPLACE: u64 = 1;
    if flags & !RENAME_NOREPLACE != 0 {
        return Err(Errno::EINVAL);
    }
    let mut from_buf = [0u8; PATH_MAX];
    let mut to_buf = [0u8; PATH_MAX];
    let (from_dir, from) = resolve_parent(p, f, host, old_dirfd, old, &mut from_buf)?;
    let (to_dir, to) = resolve_parent(p, f, host, new_dirfd, new, &mut to_buf)?;
    let now = seconds(host);
    f.fs.rename(
        from_dir,
        from,
        to_dir,
        to,
        flags & RENAME_NOREPLACE != 0,
        now,
    )?;
    Ok(0)
}

pub fn symlinkat(
    c: &mut Ctx<'_, '_, impl Host>,
    target: u64,
    dirfd: u64,
    path: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let mut target_buf = [0u8; PATH_MAX];
    let target = read_cstr(p, host, target, &mut target_buf)?;
    let mut buf = [0u8; PATH_MAX];
    let (dir, name) = resolve_parent(p, f, host, dirfd, path, &mut buf)?;
    let now = seconds(host);
    f.fs.symlink(dir, name, target, now)?;
    Ok(0)
}

/// `linkat` (and `link`: links not followed).
#[allow(clippy::too_many_arguments)] // the call's arguments
pub fn linkat(
    c: &mut Ctx<'_, '_, impl Host>,
    old_dirfd: u64,
    old: u64,
    new_dirfd: u64,
    new: u64,
    flags: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    if flags & !linux::AT_SYMLINK_FOLLOW != 0 {
        return Err(Errno::EINVAL);
    }
    let follow = flags & linux::AT_SYMLINK_FOLLOW != 0;
    let node = resolve(p, f, host, old_dirfd, old, follow)?;
    let mut buf = [0u8; PATH_MAX];
    let (dir, name) = resolve_parent(p, f, host, new_dirfd, new, &mut buf)?;
    let now = seconds(host);
    f.fs.link(node, dir, name, now)?;
    Ok(0)
}

#[allow(clippy::too_many_arguments)] // the system call's arguments
pub fn readlinkat(
    c: &mut Ctx<'_, '_, impl Host>,
    dirfd: u64,
    path: u64,
    buf: u64,
    size: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    if size as i64 <= 0 {
        return Err(Errno::EINVAL);
    }
    let node = resolve(p, f, host, dirfd, path, false)?;
    let mut scratch = [0u8; 280];
    let procs = procs(p, f);
    let target = f.fs.link_target(&procs, node, &mut scratch)?;
    let n = target.len().min(size as usize);
    write_user(p, host, buf, &target[..n])?;
    Ok(n as u64)
}

// ---- status ----

/// The status of what descriptor `fd` refers to.
fn stat_fd(p: &Process, f: &Files, fd: u64) -> SysResult<Stat> {
    Ok(match p.file(fd).ok_or(Errno::EBADF)? {
        File::Console(_) => Stat {
            ino: 0x3000_0001,
            nlink: 1,
            mode: crate::cpio::S_IFCHR | 0o620,
            rdev: Device::Console.rdev(),
            ..Stat::default()
        },
        File::Open(id) => f.fs.stat(f.fs.description(id).ok_or(Errno::EBADF)?.node),
        File::Pipe { pipe, .. } => Stat {
            ino: 0x2000_0000 + pipe as u64,
            nlink: 1,
            mode: S_IFIFO | 0o600,
            ..Stat::default()
        },
        File::UnixSocket { pair, end, .. } => Stat {
            ino: crate::vfs::proc::unix_socket_ino(pair, end),
            nlink: 1,
            mode: S_IFSOCK | 0o777,
            ..Stat::default()
        },
        File::Socket(id) => Stat {
            ino: crate::vfs::proc::SOCKET_INO + id as u64,
            nlink: 1,
            mode: S_IFSOCK | 0o777,
            ..Stat::default()
        },
        // Linux's anonymous inodes: no file type bits, owner read and write.
        File::Event(_) | File::Timer(_) | File::Epoll(_) => Stat {
            ino: crate::vfs::proc::ANON_INO,
            nlink: 1,
            mode: 0o600,
            ..Stat::default()
        },
    })
}

/// The status for `newfstatat` and `statx`: of `path` from `dirfd`, or of `dirfd`
/// itself with `AT_EMPTY_PATH` and an empty path.
fn stat_at(
    p: &Process,
    f: &Files,
    host: &mut impl Host,
    dirfd: u64,
    path: u64,
    flags: u64,
) -> SysResult<Stat> {
    if flags & linux::AT_EMPTY_PATH != 0 {
        let mut b = [0u8; 1];
        if read_cstr(p, host, path, &mut b).is_ok_and(|s| s.is_empty()) {
            return stat_fd(p, f, dirfd);
        }
    }
    let follow = flags & linux::AT_SYMLINK_NOFOLLOW == 0;
    let node = resolve(p, f, host, dirfd, path, follow)?;
    Ok(f.fs.stat(node))
}

/// Writes `st` as a `struct stat` at `buf` (`stat`, `lstat`, `fstat`, `newfstatat`).
fn write_stat(p: &Process, host: &mut impl Host, buf: u64, st: &Stat) -> SysResult<u64> {
    write_user(p, host, buf, &st.to_bytes())?;
    Ok(0)
}

/// `stat` and `lstat`.
pub fn stat(c: &mut Ctx<'_, '_, impl Host>, path: u64, buf: u64, follow: bool) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let node = resolve(p, f, host, linux::AT_FDCWD as u64, path, follow)?;
    let st = f.fs.stat(node);
    write_stat(p, host, buf, &st)
}

pub fn fstat(c: &mut Ctx<'_, '_, impl Host>, fd: u64, buf: u64) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let st = stat_fd(p, f, fd)?;
    write_stat(p, host, buf, &st)
}

pub fn newfstatat(
    c: &mut Ctx<'_, '_, impl Host>,
    dirfd: u64,
    path: u64,
    buf: u64,
    flags: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let st = stat_at(p, f, host, dirfd, path, flags)?;
    write_stat(p, host, buf, &st)
}

pub fn statx(
    c: &mut Ctx<'_, '_, impl Host>,
    dirfd: u64,
    path: u64,
    flags: u64,
    buf: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let st = stat_at(p, f, host, dirfd, path, flags)?;
    write_user(p, host, buf, &st.to_statx())?;
    Ok(0)
}

/// `statfs` (`fd: None`) and `fstatfs`: the mounted ext2's figures for its files, else
/// one tmpfs, its blocks the byte limit.
pub fn statfs(
    c: &mut Ctx<'_, '_, impl Host>,
    path: u64,
    fd: Option<u64>,
    buf: u64,
) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let node = match fd {
        Some(fd) => {
            stat_fd(p, f, fd)?;
            match p.file(fd) {
                Some(File::Open(id)) => f.fs.description(id).map(|o| o.node),
                _ => None,
            }
        }
        None => Some(resolve(p, f, host, linux::AT_FDCWD as u64, path, true)?),
    };
    let figures = node.and_then(|n| f.fs.statfs(n)).unwrap_or_else(|| {
        let (used, limit) = f.fs.usage();
        let free = (limit.saturating_sub(used) / 4096) as u64;
        vfs::FsFigures {
            magic: TMPFS_MAGIC,
            block_size: 4096,
            blocks: (limit / 4096) as u64,
            free_blocks: free,
            available_blocks: free,
            files: 0,
            free_files: 0,
        }
    });
    // f_fsid: the file system's device number.
    let fsid = match node {
        Some(Node::Mounted(_)) => vfs::mounted::DEV,
        _ => vfs::MEMORY_DEV,
    };
    let mut b = [0u8; 120];
    // struct statfs: f_type, f_bsize, f_blocks, f_bfree, f_bavail, f_files, f_ffree,
    // f_fsid, f_namelen, f_frsize (the rest, f_flags and spare, zero).
    for (i, v) in [
        figures.magic,
        figures.block_size,
        figures.blocks,
        figures.free_blocks,
        figures.available_blocks,
        figures.files,
        figures.free_files,
        fsid,
        vfs::NAME_MAX as u64,
        figures.block_size,
    ]
    .into_iter()
    .enumerate()
    {
        b[i * 8..i * 8 + 8].copy_from_slice(&v.to_le_bytes());
    }
    write_user(p, host, buf, &b)?;
    Ok(0)
}

/// `faccessat` (and `access`, `faccessat2`): every process is root, so only existence
/// and, for `X_OK`, an execute bit of a non-directory count.
pub fn access(c: &mut Ctx<'_, '_, impl Host>, dirfd: u64, path: u64, mode: u64) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    const W_OK: u64 = 2;
    const X_OK: u64 = 1;
    if mode & !7 != 0 {
        return Err(Errno::EINVAL);
    }
    let node = resolve(p, f, host, dirfd, path, true)?;
    if mode & W_OK != 0 && matches!(node, Node::Proc(_)) {
        return Err(Errno::EACCES);
    }
    if mode & X_OK != 0 && !f.fs.is_dir(node) && f.fs.mode(node) & 0o111 == 0 {
        return Err(Errno::EACCES);
    }
    Ok(0)
}

/// `getdents64`: the directory's entries from its position (`.`, `..`, then its entries
/// in name order) as `struct linux_dirent64` records, as many as fit in `count` bytes.
pub fn getdents64(c: &mut Ctx<'_, '_, impl Host>, fd: u64, buf: u64, count: u64) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let File::Open(id) = p.file(fd).ok_or(Errno::EBADF)? else {
        return Err(Errno::ENOTDIR);
    };
    let o = f.fs.description(id).ok_or(Errno::EBADF)?;
    let dir = o.node;
    if !f.fs.is_dir(dir) {
        return Err(Errno::ENOTDIR);
    }
    if let Node::Mounted(_) = dir {
        return getdents_mounted(p, f, host, id, buf, count);
    }
    let mut index = o.offset;
    let mut last = [0u8; vfs::NAME_MAX];
    let mut last_len = None;
    if let Some(name) = f.fs.cursor(id) {
        last[..name.len()].copy_from_slice(name);
        last_len = Some(name.len());
    }
    let listing = match dir {
        Node::Proc(n) => proc::entries(n, &procs(p, f)),
        Node::Inode(_) | Node::Mounted(_) => alloc::vec::Vec::new(),
    };
    let mut written = 0usize;
    let mut record = [0u8; DIRENT_HEADER + vfs::NAME_MAX + 1 + 8];
    loop {
        let (name, node): (&[u8], Node) = match (index, dir) {
            (0, _) => (b".", dir),
            (1, _) => (b"..", f.fs.parent(dir)),
            (_, Node::Proc(_)) => match listing.get(index as usize - 2) {
                Some((name, node)) => (name, Node::Proc(*node)),
                None => break,
            },
            (_, Node::Inode(ino)) => match f.fs.next_entry(ino, last_len.map(|l| &last[..l])) {
                Some(e) => e,
                None => break,
            },
            (_, Node::Mounted(_)) => break, // `getdents_mounted`
        };
        let st = f.fs.stat(node);
        // DT_* is the file type's top four bits.
        let kind = (st.mode >> 12) as u8;
        let length = (DIRENT_HEADER + name.len() + 1).next_multiple_of(8);
        if written + length > count as usize {
            if written == 0 {
                return Err(Errno::EINVAL); // the buffer cannot hold one record
            }
            break;
        }
        dirent(&mut record, st.ino, index + 1, kind, name);
        if index >= 2 && matches!(dir, Node::Inode(_)) {
            let n = name.len().min(last.len());
            last[..n].copy_from_slice(&name[..n]);
            last_len = Some(n);
        }
        write_user(p, host, buf + written as u64, &record[..length])?;
        written += length;
        index += 1;
    }
    f.fs.set_cursor(id, last_len.map(|l| &last[..l]))?;
    if let Some(o) = f.fs.description_mut(id) {
        o.offset = index;
    }
    Ok(written as u64)
}

/// The `linux_dirent64` record of an entry into `record`: its length.
fn dirent(record: &mut [u8], ino: u64, next: u64, kind: u8, name: &[u8]) -> usize {
    let length = (DIRENT_HEADER + name.len() + 1).next_multiple_of(8);
    record[..length].fill(0);
    record[..8].copy_from_slice(&ino.to_le_bytes());
    record[8..16].copy_from_slice(&next.to_le_bytes());
    record[16..18].copy_from_slice(&(length as u16).to_le_bytes());
    record[18] = kind;
    record[DIRENT_HEADER..DIRENT_HEADER + name.len()].copy_from_slice(name);
    length
}

/// `linux_dirent64`'s fixed part: d_ino, d_off, d_reclen, d_type.
const DIRENT_HEADER: usize = 19;

/// `getdents64` of a directory of the mounted file system: its entries as stored (`.`
/// and `..` among them), the description's offset the file system's cookie, as on Linux
/// (so `telldir`/`seekdir` work).
fn getdents_mounted(
    p: &Process,
    f: &mut Files,
    host: &mut impl Host,
    id: vfs::OpenId,
    buf: u64,
    count: u64,
) -> SysResult<u64> {
    let o = f.fs.description(id).ok_or(Errno::EBADF)?;
    let (dir, mut cookie) = (o.node, o.offset);
    let mut written = 0usize;
    let mut record = [0u8; DIRENT_HEADER + vfs::NAME_MAX + 1 + 8];
    while let Some(entry) = f.fs.mounted_entry(dir, cookie)? {
        let vfs::MountedEntry {
            name,
            ino,
            kind,
            next,
        } = entry;
        let length = (DIRENT_HEADER + name.len() + 1).next_multiple_of(8);
        if written + length > count as usize {
            if written == 0 {
                return Err(Errno::EINVAL); // the buffer cannot hold one record
            }
            break;
        }
        let length = dirent(&mut record, ino as u64, next, kind, &name);
        write_user(p, host, buf + written as u64, &record[..length])?;
        written += length;
        cookie = next;
    }
    if let Some(o) = f.fs.description_mut(id) {
        o.offset = cookie;
    }
    Ok(written as u64)
}

// ---- the working directory and attributes ----

pub fn chdir(c: &mut Ctx<'_, '_, impl Host>, path: u64) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let node = resolve(p, f, host, linux::AT_FDCWD as u64, path, true)?;
    if !f.fs.is_dir(node) {
        return Err(Errno::ENOTDIR);
    }
    set_cwd(p, f, node);
    Ok(0)
}

pub fn fchdir(c: &mut Ctx<'_, '_, impl Host>, fd: u64) -> SysResult<u64> {
    let (p, f, _) = c.parts();
    let File::Open(id) = p.file(fd).ok_or(Errno::EBADF)? else {
        return Err(Errno::ENOTDIR);
    };
    let node = f.fs.description(id).ok_or(Errno::EBADF)?.node;
    if !f.fs.is_dir(node) {
        return Err(Errno::ENOTDIR);
    }
    set_cwd(p, f, node);
    Ok(0)
}

fn set_cwd(p: &mut Process, f: &mut Files, node: Node) {
    f.fs.hold(node);
    f.fs.unhold(p.cwd);
    p.cwd = node;
}

pub fn getcwd(c: &mut Ctx<'_, '_, impl Host>, buf: u64, size: u64) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let path = f.fs.path_of(p.cwd)?;
    let text = path.as_str().as_bytes();
    let len = text.len() + 2; // the leading '/' and the NUL
    if (size as usize) < len {
        return Err(Errno::ERANGE);
    }
    let mut out = [0u8; 258];
    out[0] = b'/';
    out[1..1 + text.len()].copy_from_slice(text);
    write_user(p, host, buf, &out[..len])?;
    Ok(len as u64)
}

/// `fchmodat` (and `chmod`), or `fchmod` (`fd`).
pub fn chmod(c: &mut Ctx<'_, '_, impl Host>, target: Target, mode: u64) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let node = target.node(p, f, host)?;
    let now = seconds(host);
    f.fs.chmod(node, mode as u32, now)?;
    Ok(0)
}

/// `chown`, `utimensat` and their relatives: the node must exist; the owner stays root.
/// `utimensat` sets the modification time (`times` null: now).
pub fn utimensat(c: &mut Ctx<'_, '_, impl Host>, target: Target, times: u64) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    const UTIME_NOW: u64 = (1 << 30) - 1;
    const UTIME_OMIT: u64 = (1 << 30) - 2;
    let node = target.node(p, f, host)?;
    let mtime = if times == 0 {
        Some(seconds(host))
    } else {
        let seconds_field = read_u64(p, host, times + 16)?;
        match read_u64(p, host, times + 24)? {
            UTIME_OMIT => None,
            UTIME_NOW => Some(seconds(host)),
            _ => Some(seconds_field),
        }
    };
    if let Some(t) = mtime {
        let now = seconds(host);
        f.fs.set_mtime(node, t, now)?;
    }
    Ok(0)
}

/// What an attribute call names: a path from a directory, or a descriptor.
#[derive(Clone, Copy)]
pub enum Target {
    Path { dirfd: u64, path: u64, follow: bool },
    Fd(u64),
}

impl Target {
    /// `*at` calls: a null or (with `AT_EMPTY_PATH`) empty path names `dirfd` itself.
    pub fn at(dirfd: u64, path: u64, flags: u64) -> Self {
        if path == 0 {
            return Target::Fd(dirfd);
        }
        Target::Path {
            dirfd,
            path,
            follow: flags & linux::AT_SYMLINK_NOFOLLOW == 0,
        }
    }

    pub fn path(path: u64, follow: bool) -> Self {
        Target::Path {
            dirfd: linux::AT_FDCWD as u64,
            path,
            follow,
        }
    }

    fn node(self, p: &Process, f: &Files, host: &mut impl Host) -> SysResult<Node> {
        match self {
            Target::Fd(fd) => match p.file(fd).ok_or(Errno::EBADF)? {
                File::Open(id) => Ok(f.fs.description(id).ok_or(Errno::EBADF)?.node),
                _ => Err(Errno::EPERM),
            },
            Target::Path {
                dirfd,
                path,
                follow,
            } => resolve(p, f, host, dirfd, path, follow),
        }
    }
}

/// `fchownat` and relatives: accepted for existing nodes (no owners but root).
pub fn chown(c: &mut Ctx<'_, '_, impl Host>, target: Target) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    target.node(p, f, host)?;
    Ok(0)
}

/// `fsync`, `fdatasync`, `syncfs`, `fadvise64`: nothing to do for a valid descriptor.
pub fn nothing(c: &mut Ctx<'_, '_, impl Host>, fd: u64) -> SysResult<u64> {
    let (p, _, _) = c.parts();
    p.file(fd).ok_or(Errno::EBADF)?;
    Ok(0)
}
