//! The socket calls of a process ([`crate::net`]: the stack and its sockets): `socket`,
//! `bind`, `listen`, `accept`, `accept4`, `connect` (blocking, or non-blocking with
//! `EINPROGRESS`), `sendto`, `recvfrom`, `sendmsg`, `recvmsg` (and `read`/`write` of a
//! socket, [`send`]/[`recv`]), `shutdown`, `getsockname`, `getpeername`, `setsockopt`
//! (with `IP_ADD_MEMBERSHIP` and `IP_DROP_MEMBERSHIP`: IPv4 multicast groups on `eth0`),
//! `getsockopt`, and the interface requests of `ioctl` (`SIOCGIF*`; `FIONBIO` through
//! `file::generic_ioctl`). A call that cannot finish now waits (its reply deferred, see
//! [`crate::system`]) unless the socket is non-blocking or the call says `MSG_DONTWAIT`:
//! then `EAGAIN`. `socket` makes `AF_INET` sockets only: `AF_INET6`, `AF_UNIX`,
//! `AF_NETLINK` and others are `EAFNOSUPPORT`, so programs fall back to IPv4.
//! `socketpair` makes a connected pair of `AF_UNIX` stream sockets (two pipes,
//! [`crate::pipe::Pipes::pair`]), whose ends the send, receive, `shutdown`, name and
//! option calls serve too (an `AF_INET`-only call on one is `EOPNOTSUPP`).

use super::table::{Args, Ctx};
use super::{BROKEN_PIPE, Host, MAX_TRANSFER, SysResult, WOULD_BLOCK, read_u64};
use crate::linux::Errno;
use crate::net::{self, Interface, SOCKADDR_IN_LEN, errno, parse_sockaddr, sockaddr_bytes};
use crate::pipe::{PIPE_CAPACITY, Shut, Transfer};
use crate::process::{File, Process};
use alloc::vec::Vec;
use netstack::linux::*;
use netstack::{Error, SocketAddr, SocketId, SocketKind};

type Result = SysResult<u64>;

const MSG_PEEK: u64 = 0x2;
const MSG_DONTWAIT: u64 = 0x40;
const MSG_NOSIGNAL: u64 = 0x4000;
const SOL_IP: i32 = 0;
const AF_UNIX: i32 = 1;
const SO_ACCEPTCONN: i32 = 30;
const SO_DOMAIN: i32 = 39;
const IP_ADD_MEMBERSHIP: i32 = 35;
const IP_DROP_MEMBERSHIP: i32 = 36;
/// `struct ip_mreq` (the group, the interface's address) and `struct ip_mreqn` (the
/// group, the interface's address, its index).
const IP_MREQ_LEN: usize = 8;
const IP_MREQN_LEN: usize = 12;
const SO_PRIORITY: i32 = 12;
const SO_RCVTIMEO: i32 = 20;
const SO_SNDTIMEO: i32 = 21;
const TCP_KEEPIDLE: i32 = 4;
const TCP_KEEPINTVL: i32 = 5;
const TCP_KEEPCNT: i32 = 6;
/// Bytes of a datagram at most, and of a `recv`.
const MAX_MESSAGE: usize = 65_536;
/// Bytes a TCP `send` hands the stack at a time.
const TCP_STEP: usize = 16 * 1024;

/// The socket at `fd` (`ENOTSOCK` for another file).
pub fn socket_at(p: &Process, fd: u64) -> SysResult<usize> {
    match p.file(fd).ok_or(Errno::EBADF)? {
        File::Socket(id) => Ok(id),
        // What only an `AF_INET` socket does (bind, listen, connect, its options).
        File::UnixSocket { .. } => Err(Errno::EOPNOTSUPP),
        _ => Err(Errno::ENOTSOCK),
    }
}

/// The socket pair end `fd` is (its pair, its end, its `O_NONBLOCK`), if it is one.
fn pair_end(p: &Process, fd: u64) -> Option<(usize, usize, bool)> {
    match p.file(fd)? {
        File::UnixSocket {
            pair,
            end,
            nonblock,
        } => Some((pair, end, nonblock)),
        _ => None,
    }
}

/// Sends `data` at a socket pair's end (`send`, `sendto`, `sendmsg`): as much as the
/// peer's buffer takes; `EISCONN` for an address (`to`), as a connected socket answers.
fn send_on_pair(
    c: &mut Ctx<'_, '_, impl Host>,
    (pair, end, nonblock): (usize, usize, bool),
    data: &[u8],
    flags: u64,
    to: Option<SocketAddr>,
) -> Result {
    if to.is_some() {
        return Err(Errno::EISCONN);
    }
    let sent = c.f.pipes.write_pair(pair, end, data);
    pair_result(sent, nonblock || flags & MSG_DONTWAIT != 0, flags)
}

/// What a pair's transfer gives the caller ([`super::file::transferred`]; `MSG_NOSIGNAL`:
/// no `SIGPIPE`).
fn pair_result(t: Transfer, nonblock: bool, flags: u64) -> Result {
    let broken = if flags & MSG_NOSIGNAL != 0 {
        Errno::EPIPE
    } else {
        BROKEN_PIPE
    };
    super::file::transferred(t, nonblock, broken).map(|n| n as u64)
}

/// A would-block answer as the caller gets it: `EAGAIN` when it must not wait.
fn waits(e: Error, nonblock: bool) -> Errno {
    match e {
        Error::WouldBlock if nonblock => Errno::EAGAIN,
        Error::WouldBlock => WOULD_BLOCK,
        e => errno(e),
    }
}

/// `len` zero bytes from the guest's heap (`ENOMEM` when it has no room).
fn zeroed(len: usize) -> SysResult<Vec<u8>> {
    let mut bytes = Vec::new();
    bytes.try_reserve_exact(len).map_err(|_| Errno::ENOMEM)?;
    bytes.resize(len, 0);
    Ok(bytes)
}

/// The address a call passes (`address`, `len` bytes).
fn read_addr(c: &mut Ctx<'_, '_, impl Host>, address: u64, len: u64) -> SysResult<SocketAddr> {
    // A `socklen_t`: more than a `struct sockaddr_storage` is EINVAL, as on Linux.
    let len = u64::from(len as u32);
    if len > 128 {
        return Err(Errno::EINVAL);
    }
    let mut buf = [0u8; 128];
    let buf = &mut buf[..len as usize];
    c.read_user(address, buf)?;
    parse_sockaddr(buf)
}

/// Writes `addr` where a call wants it: at most `*len_at` bytes at `address`, and its
/// whole length into `*len_at` (as Linux: the caller sees when it was cut).
fn write_addr(
    c: &mut Ctx<'_, '_, impl Host>,
    address: u64,
    len_at: u64,
    addr: SocketAddr,
) -> SysResult<()> {
    if address == 0 || len_at == 0 {
        return Ok(());
    }
    let mut len = [0u8; 4];
    c.read_user(len_at, &mut len)?;
    let room = i32::from_le_bytes(len);
    if room < 0 {
        return Err(Errno::EINVAL);
    }
    let bytes = sockaddr_bytes(addr);
    let n = (room as usize).min(SOCKADDR_IN_LEN);
    c.write_user(address, &bytes[..n])?;
    c.write_user(len_at, &(SOCKADDR_IN_LEN as u32).to_le_bytes())
}

pub fn socket<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (domain, ty, protocol) = (a.i32(0), a.i32(1), a.i32(2));
    if ty & !(0xf | SOCK_NONBLOCK | SOCK_CLOEXEC) != 0 {
        return Err(Errno::EINVAL);
    }
    let fd = c.p.free_fd().ok_or(Errno::EMFILE)?;
    let now = c.host.now_ns();
    let id =
        c.f.net
            .stack(now)
            .socket(domain, ty, protocol)
            .map_err(errno)?;
    c.f.net.opened(id);
    c.p.install(fd, File::Socket(id.0), ty & SOCK_CLOEXEC != 0);
    Ok(fd as u64)
}

/// `socketpair`: a connected pair of `AF_UNIX` stream sockets ([`crate::pipe::Pipes::pair`]),
/// with `SOCK_NONBLOCK` and `SOCK_CLOEXEC`. `AF_UNIX` datagram and sequenced-packet pairs
/// are `EOPNOTSUPP`, as is an `AF_INET` pair (Linux's answer); other families
/// `EAFNOSUPPORT`.
pub fn socketpair<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (domain, ty, protocol, fds) = (a.i32(0), a.i32(1), a.i32(2), a.ptr(3));
    match domain {
        AF_UNIX => {}
        AF_INET => return Err(Errno::EOPNOTSUPP),
        _ => return Err(Errno::EAFNOSUPPORT),
    }
    if ty & !(0xf | SOCK_NONBLOCK | SOCK_CLOEXEC) != 0 {
        return Err(Errno::EINVAL);
    }
    if protocol != 0 && protocol != AF_UNIX {
        return Err(Errno::EPROTONOSUPPORT);
    }
    if ty & 0xf != SOCK_STREAM {
        return Err(Errno::EOPNOTSUPP);
    }
    super::check_user(c.p, fds, 8, crate::memory::Rights::WRITE)?;
    let first = c.p.free_fd().ok_or(Errno::EMFILE)?;
    let second = c.p.free_fd_from(first + 1).ok_or(Errno::EMFILE)?;
    let pair = c.f.pipes.pair().ok_or(Errno::ENFILE)?;
    for (end, fd) in [first, second].into_iter().enumerate() {
        let file = File::UnixSocket {
            pair,
            end,
            nonblock: ty & SOCK_NONBLOCK != 0,
        };
        c.p.install(fd, file, ty & SOCK_CLOEXEC != 0);
    }
    let mut both = [0u8; 8];
    both[..4].copy_from_slice(&(first as u32).to_le_bytes());
    both[4..].copy_from_slice(&(second as u32).to_le_bytes());
    c.write_user(fds, &both)?;
    Ok(0)
}

pub fn bind<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let id = socket_at(c.p, a.fd(0))?;
    let addr = read_addr(c, a.ptr(1), a.usize(2))?;
    let now = c.host.now_ns();
    let stack = c.f.net.stack(now);
    stack.bind(SocketId(id), addr).map_err(errno)?;
    Ok(0)
}

pub fn listen<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let id = socket_at(c.p, a.fd(0))?;
    let now = c.host.now_ns();
    let stack = c.f.net.stack(now);
    stack.listen(SocketId(id), a.i32(1)).map_err(errno)?;
    stack.poll((now / 1000) as i64);
    Ok(0)
}

pub fn accept<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    accept_with(c, a.fd(0), a.ptr(1), a.ptr(2), 0)
}

pub fn accept4<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    accept_with(c, a.fd(0), a.ptr(1), a.ptr(2), a.flags(3))
}

fn accept_with(c: &mut Ctx<'_, '_, impl Host>, fd: u64, addr: u64, len: u64, flags: u64) -> Result {
    let (nonblock_flag, cloexec) = (SOCK_NONBLOCK as u64, SOCK_CLOEXEC as u64);
    if flags & !(nonblock_flag | cloexec) != 0 {
        return Err(Errno::EINVAL);
    }
    let id = SocketId(socket_at(c.p, fd)?);
    let new_fd = c.p.free_fd().ok_or(Errno::EMFILE)?;
    let now = c.host.now_ns();
    let stack = c.f.net.stack(now);
    if stack.kind(id).map_err(errno)? != SocketKind::Tcp {
        return Err(Errno::EOPNOTSUPP);
    }
    let nonblock = stack.is_nonblocking(id).map_err(errno)?;
    let (new, peer) = stack.accept(id).map_err(|e| waits(e, nonblock))?;
    let _ = stack.set_nonblocking(new, flags & nonblock_flag != 0);
    c.f.net.opened(new);
    c.p.install(new_fd, File::Socket(new.0), flags & cloexec != 0);
    write_addr(c, addr, len, peer)?;
    Ok(new_fd as u64)
}

pub fn connect<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let id = SocketId(socket_at(c.p, a.fd(0))?);
    let addr = read_addr(c, a.ptr(1), a.usize(2))?;
    let now = c.host.now_ns();
    let stack = c.f.net.stack(now);
    if c.p.connecting == Some(id.0) {
        // Served again while it waits: how the connect went.
        return match stack.connect_result(id) {
            Err(Error::WouldBlock) => Err(WOULD_BLOCK),
            result => {
                c.p.connecting = None;
                if result.is_err() {
                    // Taken as the call's error, not left for SO_ERROR.
                    let _ = stack.option(id, SOL_SOCKET, SO_ERROR);
                }
                result.map(|()| 0).map_err(errno)
            }
        };
    }
    match stack.connect(id, addr) {
        Ok(()) => Ok(0),
        Err(Error::WouldBlock) => {
            c.p.connecting = Some(id.0);
            Err(WOULD_BLOCK)
        }
        Err(e) => Err(errno(e)),
    }
}

/// Sends `len` bytes at `buf` (`write`, `send`, `sendto`): a datagram whole, or on a
/// connection as much as fits; a blocking connection takes all of it, waiting for room
/// (the progress kept in the process between the serves of the waiting call).
pub fn send(
    c: &mut Ctx<'_, '_, impl Host>,
    fd: u64,
    buf: u64,
    len: u64,
    flags: u64,
    to: Option<SocketAddr>,
) -> Result {
    if let Some(pair) = pair_end(c.p, fd) {
        let mut data = zeroed((len as usize).min(MAX_TRANSFER).min(PIPE_CAPACITY))?;
        c.read_user(buf, &mut data)?;
        return send_on_pair(c, pair, &data, flags, to);
    }
    let id = SocketId(socket_at(c.p, fd)?);
    let now = c.host.now_ns();
    let stack = c.f.net.stack(now);
    let kind = stack.kind(id).map_err(errno)?;
    let nonblock = stack.is_nonblocking(id).map_err(errno)? || flags & MSG_DONTWAIT != 0;
    if kind == SocketKind::Udp {
        if len as usize > MAX_MESSAGE {
            return Err(Errno::EMSGSIZE);
        }
        let mut data = zeroed(len as usize)?;
        c.read_user(buf, &mut data)?;
        return match c.f.net.stack(now).send(id, &data, to) {
            Ok(n) => Ok(n as u64),
            Err(e) => Err(waits(e, nonblock)),
        };
    }
    let total = (len as usize).min(MAX_TRANSFER);
    super::check_user(c.p, buf, total, crate::memory::Rights::READ)?;
    let mut chunk = zeroed(total.min(TCP_STEP))?;
    let mut done = if nonblock {
        0
    } else {
        (c.p.pipe_written as usize).min(total)
    };
    let mut ran = false;
    let result = loop {
        if done == total {
            break Ok(done as u64);
        }
        let want = (total - done).min(chunk.len());
        c.read_user(buf + done as u64, &mut chunk[..want])?;
        let stack = c.f.net.stack(now);
        match stack.send(id, &chunk[..want], to) {
            Ok(n) => done += n,
            Err(Error::WouldBlock) if nonblock && done == 0 => break Err(Errno::EAGAIN),
            Err(Error::WouldBlock) if nonblock => break Ok(done as u64),
            // Run the stack once now: a peer on the loopback takes what went in.
            Err(Error::WouldBlock) if !ran => {
                ran = true;
                stack.poll((now / 1000) as i64);
            }
            Err(Error::WouldBlock) => {
                c.p.pipe_written = done as u64;
                return Err(WOULD_BLOCK);
            }
            Err(_) if done > 0 => break Ok(done as u64),
            Err(Error::BrokenPipe) if flags & MSG_NOSIGNAL != 0 => break Err(Errno::EPIPE),
            Err(Error::BrokenPipe) => break Err(BROKEN_PIPE),
            Err(e) => break Err(errno(e)),
        }
    };
    c.p.pipe_written = 0;
    result
}

/// Receives at most `len` bytes into `buf` (`read`, `recv`, `recvfrom`): what the
/// connection has (0: end of file), or one datagram (cut to `len`); with the sender and
/// the datagram's whole length.
fn receive(
    c: &mut Ctx<'_, '_, impl Host>,
    fd: u64,
    len: u64,
    flags: u64,
) -> SysResult<(Vec<u8>, Option<SocketAddr>)> {
    if flags & MSG_PEEK != 0 {
        return Err(Errno::EOPNOTSUPP);
    }
    if let Some((pair, end, nonblock)) = pair_end(c.p, fd) {
        let mut data = zeroed((len as usize).min(MAX_MESSAGE))?;
        let got = c.f.pipes.read_pair(pair, end, &mut data);
        let n = pair_result(got, nonblock || flags & MSG_DONTWAIT != 0, 0)?;
        data.truncate(n as usize);
        return Ok((data, None));
    }
    let id = SocketId(socket_at(c.p, fd)?);
    let now = c.host.now_ns();
    let stack = c.f.net.stack(now);
    let nonblock = stack.is_nonblocking(id).map_err(errno)? || flags & MSG_DONTWAIT != 0;
    let mut data = zeroed((len as usize).min(MAX_MESSAGE))?;
    let (n, from) = stack.recv(id, &mut data).map_err(|e| waits(e, nonblock))?;
    data.truncate(n);
    // A read moves the window: tell the peer now.
    stack.poll((now / 1000) as i64);
    Ok((data, from))
}

/// `read` of a socket, `recv`.
pub fn recv(c: &mut Ctx<'_, '_, impl Host>, fd: u64, buf: u64, len: u64, flags: u64) -> Result {
    super::check_user(c.p, buf, len as usize, crate::memory::Rights::WRITE)?;
    let (data, _) = receive(c, fd, len, flags)?;
    c.write_user(buf, &data)?;
    Ok(data.len() as u64)
}

pub fn sendto<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let to = match a.ptr(4) {
        0 => None,
        at => Some(read_addr(c, at, a.usize(5))?),
    };
    send(c, a.fd(0), a.ptr(1), a.usize(2), a.flags(3), to)
}

pub fn recvfrom<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (fd, buf, len, flags) = (a.fd(0), a.ptr(1), a.usize(2), a.flags(3));
    super::check_user(c.p, buf, len as usize, crate::memory::Rights::WRITE)?;
    let (data, from) = receive(c, fd, len, flags)?;
    c.write_user(buf, &data)?;
    if let Some(from) = from {
        write_addr(c, a.ptr(4), a.ptr(5), from)?;
    } else if a.ptr(5) != 0 {
        // A connection's peer is no datagram's sender: no address.
        c.write_user(a.ptr(5), &0u32.to_le_bytes())?;
    }
    Ok(data.len() as u64)
}

/// A `struct msghdr`: name and its length, the iovecs, their count.
struct MsgHdr {
    name: u64,
    name_len: u64,
    iov: u64,
    iov_len: u64,
}

fn read_msghdr(c: &mut Ctx<'_, '_, impl Host>, at: u64) -> SysResult<MsgHdr> {
    let (p, host) = (&*c.p, &mut *c.host);
    let h = MsgHdr {
        name: read_u64(p, host, at)?,
        name_len: read_u64(p, host, at + 8)? & 0xffff_ffff,
        iov: read_u64(p, host, at + 16)?,
        iov_len: read_u64(p, host, at + 24)?,
    };
    if h.iov_len > super::IOV_MAX {
        return Err(Errno::EMSGSIZE);
    }
    Ok(h)
}

/// The iovecs of a message: (base, length) each.
fn iovecs(c: &mut Ctx<'_, '_, impl Host>, h: &MsgHdr) -> SysResult<Vec<(u64, u64)>> {
    let mut out = Vec::new();
    for i in 0..h.iov_len {
        let base = read_u64(c.p, c.host, h.iov + i * 16)?;
        let len = read_u64(c.p, c.host, h.iov + i * 16 + 8)?;
        out.push((base, len));
    }
    Ok(out)
}

pub fn sendmsg<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (fd, flags) = (a.fd(0), a.flags(2));
    let pair = pair_end(c.p, fd);
    if pair.is_none() {
        socket_at(c.p, fd)?;
    }
    let h = read_msghdr(c, a.ptr(1))?;
    let to = match h.name {
        0 => None,
        at => Some(read_addr(c, at, h.name_len)?),
    };
    // The pieces gathered into one message, then sent as `sendto` sends.
    let mut data = Vec::new();
    for (base, len) in iovecs(c, &h)? {
        let len = (len as usize).min(MAX_MESSAGE + 1 - data.len().min(MAX_MESSAGE));
        let start = data.len();
        data.try_reserve(len).map_err(|_| Errno::ENOMEM)?;
        data.resize(start + len, 0);
        c.read_user(base, &mut data[start..])?;
    }
    if let Some(pair) = pair {
        return send_on_pair(c, pair, &data, flags, to);
    }
    let now = c.host.now_ns();
    let stack = c.f.net.stack(now);
    let id = SocketId(socket_at(c.p, fd)?);
    let nonblock = stack.is_nonblocking(id).map_err(errno)? || flags & MSG_DONTWAIT != 0;
    if stack.kind(id).map_err(errno)? == SocketKind::Udp && data.len() > MAX_MESSAGE {
        return Err(Errno::EMSGSIZE);
    }
    match stack.send(id, &data, to) {
        Ok(n) => Ok(n as u64),
        Err(Error::BrokenPipe) if flags & MSG_NOSIGNAL != 0 => Err(Errno::EPIPE),
        Err(Error::BrokenPipe) => Err(BROKEN_PIPE),
        Err(e) => Err(waits(e, nonblock)),
    }
}

pub fn recvmsg<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let (fd, at, flags) = (a.fd(0), a.ptr(1), a.flags(2));
    if pair_end(c.p, fd).is_none() {
        socket_at(c.p, fd)?;
    }
    let h = read_msghdr(c, at)?;
    let pieces = iovecs(c, &h)?;
    let room: u64 = pieces.iter().map(|&(_, len)| len).sum();
    let (data, from) = receive(c, fd, room, flags)?;
    let mut done = 0;
    for (base, len) in pieces {
        let n = (len as usize).min(data.len() - done);
        c.write_user(base, &data[done..done + n])?;
        done += n;
    }
    if let Some(from) = from
        && h.name != 0
    {
        let bytes = sockaddr_bytes(from);
        let n = (h.name_len as usize).min(SOCKADDR_IN_LEN);
        c.write_user(h.name, &bytes[..n])?;
    }
    let name_len = if from.is_some() { SOCKADDR_IN_LEN } else { 0 } as u32;
    c.write_user(at + 8, &name_len.to_le_bytes())?;
    // No control messages; msg_flags clear.
    c.write_user(at + 40, &0u64.to_le_bytes())?;
    c.write_user(at + 48, &0u32.to_le_bytes())?;
    Ok(done as u64)
}

pub fn shutdown<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    if let Some((pair, end, _)) = pair_end(c.p, a.fd(0)) {
        let (read, write) = match a.i32(1) {
            SHUT_RD => (true, false),
            SHUT_WR => (false, true),
            SHUT_RDWR => (true, true),
            _ => return Err(Errno::EINVAL),
        };
        c.f.pipes.shutdown(pair, end, Shut { read, write });
        return Ok(0);
    }
    let id = SocketId(socket_at(c.p, a.fd(0))?);
    let now = c.host.now_ns();
    let stack = c.f.net.stack(now);
    stack.shutdown(id, a.i32(1)).map_err(errno)?;
    stack.poll((now / 1000) as i64);
    Ok(0)
}

/// The address of a socket pair's end, as Linux's unnamed `AF_UNIX` socket: its family
/// alone (2 bytes).
fn unnamed_address(c: &mut Ctx<'_, '_, impl Host>, address: u64, len_at: u64) -> Result {
    let mut room = [0u8; 4];
    c.read_user(len_at, &mut room)?;
    let room = i32::from_le_bytes(room);
    if room < 0 {
        return Err(Errno::EINVAL);
    }
    let family = (AF_UNIX as u16).to_le_bytes();
    c.write_user(address, &family[..(room as usize).min(2)])?;
    c.write_user(len_at, &2u32.to_le_bytes())?;
    Ok(0)
}

pub fn getsockname<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    if pair_end(c.p, a.fd(0)).is_some() {
        return unnamed_address(c, a.ptr(1), a.ptr(2));
    }
    let id = SocketId(socket_at(c.p, a.fd(0))?);
    let now = c.host.now_ns();
    let addr = c.f.net.stack(now).local_addr(id).map_err(errno)?;
    write_addr(c, a.ptr(1), a.ptr(2), addr)?;
    Ok(0)
}

pub fn getpeername<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    if pair_end(c.p, a.fd(0)).is_some() {
        return unnamed_address(c, a.ptr(1), a.ptr(2));
    }
    let id = SocketId(socket_at(c.p, a.fd(0))?);
    let now = c.host.now_ns();
    let addr = c.f.net.stack(now).peer_addr(id).map_err(errno)?;
    write_addr(c, a.ptr(1), a.ptr(2), addr)?;
    Ok(0)
}

pub fn setsockopt<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    if pair_end(c.p, a.fd(0)).is_some() {
        // A pair's socket-level options (buffer sizes, timeouts) are accepted, not
        // honoured; it has no protocol options.
        return match a.i32(1) {
            SOL_SOCKET => Ok(0),
            _ => Err(Errno::ENOPROTOOPT),
        };
    }
    let id = SocketId(socket_at(c.p, a.fd(0))?);
    let (level, name, at, len) = (a.i32(1), a.i32(2), a.ptr(3), a.usize(4));
    if level == SOL_IP && matches!(name, IP_ADD_MEMBERSHIP | IP_DROP_MEMBERSHIP) {
        return membership(c, id, name == IP_ADD_MEMBERSHIP, at, len);
    }
    if (len as i32) < 4 && !(level == SOL_IP && len >= 1) {
        return Err(Errno::EINVAL);
    }
    let mut value = [0u8; 4];
    c.read_user(at, &mut value[..(len as usize).min(4)])?;
    let value = i32::from_le_bytes(value);
    match (level, name) {
        // Accepted, not honoured: timeouts, priorities, the IP header's fields, the
        // keep-alive's timing (smoltcp's interval is the stack's).
        (SOL_SOCKET, SO_RCVTIMEO | SO_SNDTIMEO | SO_PRIORITY)
        | (SOL_IP, _)
        | (IPPROTO_TCP, TCP_KEEPIDLE | TCP_KEEPINTVL | TCP_KEEPCNT) => return Ok(0),
        _ => {}
    }
    let now = c.host.now_ns();
    c.f.net
        .stack(now)
        .set_option(id, level, name, value)
        .map_err(errno)?;
    Ok(0)
}

/// `IP_ADD_MEMBERSHIP` (`join`) or `IP_DROP_MEMBERSHIP` with an `ip_mreq` or `ip_mreqn`
/// at `at`: the group on `eth0`, the only interface with multicast (its address, its
/// index or "any" name it; another is `ENODEV`).
fn membership<H: Host>(c: &mut Ctx<H>, id: SocketId, join: bool, at: u64, len: u64) -> Result {
    if len < IP_MREQ_LEN as u64 {
        return Err(Errno::EINVAL);
    }
    let mut mreq = [0u8; IP_MREQN_LEN];
    let len = len.min(IP_MREQN_LEN as u64) as usize;
    c.read_user(at, &mut mreq[..len])?;
    let group = net::Ipv4Address::new(mreq[0], mreq[1], mreq[2], mreq[3]);
    let address = net::Ipv4Address::new(mreq[4], mreq[5], mreq[6], mreq[7]);
    let index = u32::from_le_bytes([mreq[8], mreq[9], mreq[10], mreq[11]]);
    let eth0 = c.f.net.interfaces().into_iter().find(|i| i.name == "eth0");
    let names_eth0 = eth0.is_some_and(|e| {
        (address.is_unspecified() || address == e.address) && (index == 0 || index == e.index)
    });
    if !names_eth0 {
        return Err(Errno::ENODEV);
    }
    let now = c.host.now_ns();
    if join {
        c.f.net.join(now, id.0, group)?;
    } else {
        c.f.net.leave(now, id.0, group)?;
    }
    Ok(0)
}

pub fn getsockopt<H: Host>(c: &mut Ctx<H>, a: Args) -> Result {
    let fd = a.fd(0);
    let (level, name, at, len_at) = (a.i32(1), a.i32(2), a.ptr(3), a.ptr(4));
    let mut len = [0u8; 4];
    c.read_user(len_at, &mut len)?;
    let room = i32::from_le_bytes(len);
    if room < 0 {
        return Err(Errno::EINVAL);
    }
    if pair_end(c.p, fd).is_some() {
        let value: i32 = match (level, name) {
            (SOL_SOCKET, SO_TYPE) => SOCK_STREAM,
            (SOL_SOCKET, SO_DOMAIN) => AF_UNIX,
            (SOL_SOCKET, SO_ERROR | SO_ACCEPTCONN) => 0,
            _ => return Err(Errno::ENOPROTOOPT),
        };
        let n = (room as usize).min(4);
        c.write_user(at, &value.to_le_bytes()[..n])?;
        c.write_user(len_at, &(n as u32).to_le_bytes())?;
        return Ok(0);
    }
    let id = SocketId(socket_at(c.p, fd)?);
    let now = c.host.now_ns();
    let stack = c.f.net.stack(now);
    let mut bytes = [0u8; 16];
    let size = match (level, name) {
        (SOL_SOCKET, SO_LINGER) => 8,
        (SOL_SOCKET, SO_RCVTIMEO | SO_SNDTIMEO) => 16,
        _ => {
            let value = stack.option(id, level, name).map_err(errno)?;
            bytes[..4].copy_from_slice(&value.to_le_bytes());
            4
        }
    };
    let n = (room as usize).min(size);
    c.write_user(at, &bytes[..n])?;
    c.write_user(len_at, &(n as u32).to_le_bytes())?;
    Ok(0)
}

/// What `poll` sees of socket `id`.
pub fn events(net: &mut net::Net, now_ns: u64, id: usize) -> u16 {
    use crate::poll::{POLLERR, POLLHUP, POLLIN, POLLOUT};
    let Ok(r) = net.stack(now_ns).readiness(SocketId(id)) else {
        return POLLERR;
    };
    (if r.readable { POLLIN } else { 0 })
        | (if r.writable { POLLOUT } else { 0 })
        | (if r.hangup { POLLHUP } else { 0 })
        | (if r.error { POLLERR } else { 0 })
}

// ---- ioctl: the interface requests ----

const SIOCGIFNAME: u64 = 0x8910;
const SIOCGIFCONF: u64 = 0x8912;
const SIOCGIFFLAGS: u64 = 0x8913;
const SIOCGIFADDR: u64 = 0x8915;
const SIOCGIFDSTADDR: u64 = 0x8917;
const SIOCGIFBRDADDR: u64 = 0x8919;
const SIOCGIFNETMASK: u64 = 0x891b;
const SIOCGIFMETRIC: u64 = 0x891d;
const SIOCGIFMTU: u64 = 0x8921;
const SIOCGIFHWADDR: u64 = 0x8927;
const SIOCGIFINDEX: u64 = 0x8933;
const SIOCGIFTXQLEN: u64 = 0x8942;
const SIOCGIFMAP: u64 = 0x8970;
/// `struct ifreq`: the name (16 bytes), then the request's union (24).
const IFREQ_LEN: usize = 40;
const ARPHRD_ETHER: u16 = 1;
const ARPHRD_LOOPBACK: u16 = 772;

/// The union of `struct ifreq` answering `request` about interface `i` (`None`: not
/// an interface request this guest answers).
pub fn ifreq_answer(request: u64, i: &Interface) -> Option<[u8; 24]> {
    let mut u = [0u8; 24];
    let addr = |ip| sockaddr_bytes(SocketAddr::new(ip, 0));
    match request {
        SIOCGIFFLAGS => u[..2].copy_from_slice(&i.flags.to_le_bytes()),
        SIOCGIFADDR | SIOCGIFDSTADDR => u[..16].copy_from_slice(&addr(i.address)),
        SIOCGIFBRDADDR => {
            let broadcast = if i.flags & net::IFF_BROADCAST != 0 {
                i.broadcast()
            } else {
                netstack::Ipv4Address::UNSPECIFIED
            };
            u[..16].copy_from_slice(&addr(broadcast));
        }
        SIOCGIFNETMASK => u[..16].copy_from_slice(&addr(i.netmask())),
        SIOCGIFMETRIC => {}
        SIOCGIFMTU => u[..4].copy_from_slice(&i.mtu.to_le_bytes()),
        SIOCGIFHWADDR => {
            let family = if i.flags & net::IFF_LOOPBACK != 0 {
                ARPHRD_LOOPBACK
            } else {
                ARPHRD_ETHER
            };
            u[..2].copy_from_slice(&family.to_le_bytes());
            u[2..8].copy_from_slice(&i.mac);
        }
        SIOCGIFINDEX => u[..4].copy_from_slice(&i.index.to_le_bytes()),
        SIOCGIFTXQLEN => u[..4].copy_from_slice(&1000u32.to_le_bytes()),
        SIOCGIFMAP => {}
        _ => return None,
    }
    Some(u)
}

/// `ioctl` on a socket: the interface requests; others `ENOTTY` (`FIONBIO` is every
/// descriptor's, `file::generic_ioctl`).
pub fn socket_ioctl(c: &mut Ctx<'_, '_, impl Host>, fd: u64, request: u64, arg: u64) -> Result {
    socket_at(c.p, fd)?;
    let request = request & 0xffff_ffff;
    let interfaces = c.f.net.interfaces();
    if request == SIOCGIFCONF {
        // struct ifconf: the buffer's length, then its address.
        let len = read_u64(c.p, c.host, arg)? as i32;
        let buf = read_u64(c.p, c.host, arg + 8)?;
        let whole = (interfaces.len() * IFREQ_LEN) as i32;
        if buf == 0 {
            c.write_user(arg, &whole.to_le_bytes())?;
            return Ok(0);
        }
        let fit = (len.max(0) as usize / IFREQ_LEN).min(interfaces.len());
        for (n, i) in interfaces.iter().take(fit).enumerate() {
            let mut req = [0u8; IFREQ_LEN];
            req[..i.name.len()].copy_from_slice(i.name.as_bytes());
            req[16..32].copy_from_slice(&sockaddr_bytes(SocketAddr::new(i.address, 0)));
            c.write_user(buf + (n * IFREQ_LEN) as u64, &req)?;
        }
        c.write_user(arg, &((fit * IFREQ_LEN) as i32).to_le_bytes())?;
        return Ok(0);
    }
    let mut req = [0u8; IFREQ_LEN];
    c.read_user(arg, &mut req)?;
    let interface = if request == SIOCGIFNAME {
        let index = u32::from_le_bytes([req[16], req[17], req[18], req[19]]);
        interfaces.iter().find(|i| i.index == index)
    } else {
        let name = req[..16].split(|&b| b == 0).next().unwrap_or(&[]);
        interfaces.iter().find(|i| i.name.as_bytes() == name)
    };
    let Some(i) = interface else {
        return Err(if (0x8900..0x8a00).contains(&request) {
            Errno::ENODEV
        } else {
            Errno::ENOTTY
        });
    };
    if request == SIOCGIFNAME {
        let mut name = [0u8; 16];
        name[..i.name.len()].copy_from_slice(i.name.as_bytes());
        c.write_user(arg, &name)?;
        return Ok(0);
    }
    match ifreq_answer(request, i) {
        Some(u) => {
            c.write_user(arg + 16, &u)?;
            Ok(0)
        }
        // Setting an interface (SIOCSIF*): its addresses are the configuration's.
        None if (0x8900..0x8a00).contains(&request) => Err(Errno::EPERM),
        None => Err(Errno::ENOTTY),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use netstack::Ipv4Address;

    #[test]
    fn interface_requests_answer_as_linux() {
        let net = net::Net::new(Some(net::NetConfig {
            mac: [0x52, 0x54, 0, 0x12, 0x34, 0x56],
            address: Ipv4Address::new(10, 0, 2, 15),
            prefix: 24,
            gateway: None,
        }));
        let interfaces = net.interfaces();
        let (lo, eth) = (&interfaces[0], &interfaces[1]);
        let flags = ifreq_answer(SIOCGIFFLAGS, lo).unwrap();
        assert_eq!(u16::from_le_bytes([flags[0], flags[1]]), 0x49);
        let mask = ifreq_answer(SIOCGIFNETMASK, eth).unwrap();
        assert_eq!(&mask[..8], &[2, 0, 0, 0, 255, 255, 255, 0]);
        let hw = ifreq_answer(SIOCGIFHWADDR, eth).unwrap();
        assert_eq!(&hw[..8], &[1, 0, 0x52, 0x54, 0, 0x12, 0x34, 0x56]);
        let brd = ifreq_answer(SIOCGIFBRDADDR, lo).unwrap();
        assert_eq!(&brd[4..8], &[0, 0, 0, 0], "lo has no broadcast");
        assert_eq!(
            ifreq_answer(0x8914, lo),
            None,
            "SIOCSIFFLAGS is no question"
        );
    }
}
