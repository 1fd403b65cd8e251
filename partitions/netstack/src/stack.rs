//! The stack: interfaces, smoltcp's sockets and the Linux-style socket table over them.

use crate::SocketAddr;
use crate::error::Error;
use crate::queues::Queues;
use alloc::vec;
use alloc::vec::Vec;
use smoltcp::iface::{Config as IfaceConfig, Interface, SocketHandle, SocketSet};
use smoltcp::phy::{Loopback, Medium};
use smoltcp::socket::{tcp, udp};
use smoltcp::time::{Duration, Instant};
use smoltcp::wire::{
    EthernetAddress, HardwareAddress, IpAddress, IpCidr, IpEndpoint, IpListenEndpoint, Ipv4Address,
    Ipv4Cidr,
};

/// Linux's socket constants the calls take.
pub mod linux {
    pub const AF_INET: i32 = 2;
    pub const AF_INET6: i32 = 10;
    pub const SOCK_STREAM: i32 = 1;
    pub const SOCK_DGRAM: i32 = 2;
    pub const SOCK_NONBLOCK: i32 = 0o4000;
    pub const SOCK_CLOEXEC: i32 = 0o2000000;
    pub const IPPROTO_TCP: i32 = 6;
    pub const IPPROTO_UDP: i32 = 17;
    pub const SOL_SOCKET: i32 = 1;
    pub const SO_REUSEADDR: i32 = 2;
    pub const SO_TYPE: i32 = 3;
    pub const SO_ERROR: i32 = 4;
    pub const SO_BROADCAST: i32 = 6;
    pub const SO_SNDBUF: i32 = 7;
    pub const SO_RCVBUF: i32 = 8;
    pub const SO_KEEPALIVE: i32 = 9;
    pub const SO_LINGER: i32 = 13;
    pub const SO_REUSEPORT: i32 = 15;
    pub const TCP_NODELAY: i32 = 1;
    pub const SHUT_RD: i32 = 0;
    pub const SHUT_WR: i32 = 1;
    pub const SHUT_RDWR: i32 = 2;
}

/// Sizes and counts, from the configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Sockets at once (listening backlogs, lingering closes included).
    pub sockets: usize,
    /// Bytes of a TCP socket's receive and of its send buffer.
    pub tcp_buffer: usize,
    /// Datagrams a UDP socket buffers each way, and their bytes.
    pub udp_packets: usize,
    pub udp_buffer: usize,
    /// Largest listen backlog.
    pub backlog: usize,
    /// Frames queued each way between the stack and the rings.
    pub frames: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            sockets: 64,
            tcp_buffer: 64 * 1024,
            udp_packets: 32,
            udp_buffer: 64 * 1024,
            backlog: 16,
            frames: 64,
        }
    }
}

/// The interface's address, from the configuration; an unspecified `address` (as
/// [`Config::loopback_only`] makes) means the partition has no `eth0`, only `lo`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Config {
    pub mac: [u8; 6],
    pub address: Ipv4Address,
    pub prefix: u8,
    pub gateway: Option<Ipv4Address>,
    pub limits: Limits,
}

impl Config {
    /// A stack with `lo` alone (a partition without a network interface).
    pub const fn loopback_only(limits: Limits) -> Self {
        Config {
            mac: [0; 6],
            address: Ipv4Address::UNSPECIFIED,
            prefix: 0,
            gateway: None,
            limits,
        }
    }

    /// Whether the partition has `eth0`.
    pub fn has_eth(&self) -> bool {
        !self.address.is_unspecified()
    }
}

/// A socket of the table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct SocketId(pub usize);

/// TCP or UDP.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SocketKind {
    Tcp,
    Udp,
}

/// What `poll`/`select` see of a socket.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Readiness {
    pub readable: bool,
    pub writable: bool,
    pub hangup: bool,
    pub error: bool,
}

/// Which interface a smoltcp socket is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    Eth,
    Lo,
}

#[derive(Clone, Debug)]
enum TcpState {
    Fresh,
    Listening {
        listeners: Vec<(Side, SocketHandle)>,
        /// Backlog places of these sides not listening: an accepted connection's place
        /// is taken by a new listener only when the socket limit allows it ([`Stack::room`]).
        missing: Vec<Side>,
    },
    Connecting {
        side: Side,
        handle: SocketHandle,
        since: Instant,
    },
    Connected {
        side: Side,
        handle: SocketHandle,
        peer_closed: bool,
    },
    /// After a failed connect or a reset: the error SO_ERROR reports once.
    Failed(Error),
}

#[derive(Clone, Debug)]
struct Sock {
    kind: SocketKind,
    nonblocking: bool,
    reuse_address: bool,
    keep_alive: bool,
    no_delay: bool,
    broadcast: bool,
    /// The bound address (for getsockname), and whether it holds the port (an accepted
    /// socket shares its listener's).
    bound: Option<SocketAddr>,
    owns_port: bool,
    tcp: TcpState,
    /// UDP: the smoltcp sockets (one per interface the bound address covers).
    udp: Vec<(Side, SocketHandle)>,
    /// UDP: the connected peer; TCP: the peer once connected.
    peer: Option<SocketAddr>,
    shut_read: bool,
    shut_write: bool,
    /// A pending error for SO_ERROR.
    error: Option<Error>,
}

/// How long a connect may take before it fails with ETIMEDOUT.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(75);
const KEEP_ALIVE: Duration = Duration::from_secs(75);
const EPHEMERAL: core::ops::RangeInclusive<u16> = 49_152..=65_535;

/// The stack of a partition.
pub struct Stack {
    config: Config,
    eth: Interface,
    lo: Interface,
    /// `eth0`'s frames.
    pub device: Queues,
    loopback: Loopback,
    eth_set: SocketSet<'static>,
    lo_set: SocketSet<'static>,
    table: Vec<Option<Sock>>,
    /// Closed TCP connections finishing in the background.
    lingering: Vec<(Side, SocketHandle)>,
    /// The sockets a poll changed since [`Stack::take_changed`] last took them.
    changed: Vec<SocketId>,
    next_port: u16,
    now: Instant,
}

impl Stack {
    /// A stack with `eth0` as configured and `lo`, at instant `now_us`.
    pub fn new(config: Config, now_us: i64) -> Self {
        let now = Instant::from_micros(now_us);
        let mut device = Queues::new(config.limits.frames);
        let mut eth = Interface::new(
            IfaceConfig::new(HardwareAddress::Ethernet(EthernetAddress(config.mac))),
            &mut device,
            now,
        );
        if config.has_eth() {
            eth.update_ip_addrs(|addrs| {
                let _ = addrs.push(IpCidr::Ipv4(Ipv4Cidr::new(config.address, config.prefix)));
            });
        }
        if let Some(gateway) = config.gateway {
            let _ = eth.routes_mut().add_default_ipv4_route(gateway);
        }
        let mut loopback = Loopback::new(Medium::Ip);
        let mut lo = Interface::new(IfaceConfig::new(HardwareAddress::Ip), &mut loopback, now);
        lo.update_ip_addrs(|addrs| {
            let _ = addrs.push(IpCidr::Ipv4(Ipv4Cidr::new(
                Ipv4Address::new(127, 0, 0, 1),
                8,
            )));
        });
        Stack {
            config,
            eth,
            lo,
            device,
            loopback,
            eth_set: SocketSet::new(Vec::new()),
            lo_set: SocketSet::new(Vec::new()),
            table: Vec::new(),
            lingering: Vec::new(),
            changed: Vec::new(),
            next_port: *EPHEMERAL.start(),
            now,
        }
    }

    pub fn config(&self) -> &Config {
        &self.config
    }

    fn set(&mut self, side: Side) -> &mut SocketSet<'static> {
        match side {
            Side::Eth => &mut self.eth_set,
            Side::Lo => &mut self.lo_set,
        }
    }

    fn tcp(&mut self, side: Side, handle: SocketHandle) -> &mut tcp::Socket<'static> {
        self.set(side).get_mut::<tcp::Socket>(handle)
    }

    fn udp_socket(&mut self, side: Side, handle: SocketHandle) -> &mut udp::Socket<'static> {
        self.set(side).get_mut::<udp::Socket>(handle)
    }

    /// smoltcp sockets in use (each listener of a backlog, lingering closes included), at
    /// most [`Limits::sockets`].
    pub fn sockets_in_use(&self) -> usize {
        self.in_use()
    }

    /// smoltcp sockets in use (each listener of a backlog, lingering closes included).
    fn in_use(&self) -> usize {
        self.eth_set.iter().count() + self.lo_set.iter().count()
    }

    /// Whether `more` sockets fit; closed connections waiting in TIME-WAIT give their
    /// places first, oldest first (as Linux recycles them beyond `tcp_max_tw_buckets`):
    /// a server closing many short connections must not run out of sockets for the
    /// TIME-WAIT's 10 s.
    fn room(&mut self, more: usize) -> Result<(), Error> {
        let limit = self.config.limits.sockets;
        let mut i = 0;
        while self.in_use() + more > limit && i < self.lingering.len() {
            let (side, handle) = self.lingering[i];
            if self.tcp(side, handle).state() == tcp::State::TimeWait {
                self.lingering.remove(i);
                self.set(side).remove(handle);
            } else {
                i += 1;
            }
        }
        if self.in_use() + more > limit {
            return Err(Error::NoBuffers);
        }
        Ok(())
    }

    /// A TCP socket with its two buffers; `NoBuffers` when the heap has no room for them
    /// (an error for the call, never an abort of the partition).
    fn new_tcp(&mut self, side: Side) -> Result<SocketHandle, Error> {
        let size = self.config.limits.tcp_buffer;
        let buffer = || {
            let mut bytes = Vec::new();
            bytes
                .try_reserve_exact(size)
                .map_err(|_| Error::NoBuffers)?;
            bytes.resize(size, 0);
            Ok::<_, Error>(tcp::SocketBuffer::new(bytes))
        };
        let mut socket = tcp::Socket::new(buffer()?, buffer()?);
        socket.set_timeout(None);
        if side == Side::Lo {
            // Nothing to save on the loopback: an ACK costs no wire time.
            socket.set_ack_delay(None);
        }
        Ok(self.set(side).add(socket))
    }

    fn sock(&self, id: SocketId) -> Result<&Sock, Error> {
        self.table
            .get(id.0)
            .and_then(Option::as_ref)
            .ok_or(Error::BadDescriptor)
    }

    fn sock_mut(&mut self, id: SocketId) -> Result<&mut Sock, Error> {
        self.table
            .get_mut(id.0)
            .and_then(Option::as_mut)
            .ok_or(Error::BadDescriptor)
    }

    fn insert(&mut self, sock: Sock) -> SocketId {
        match self.table.iter().position(Option::is_none) {
            Some(i) => {
                self.table[i] = Some(sock);
                SocketId(i)
            }
            None => {
                self.table.push(Some(sock));
                SocketId(self.table.len() - 1)
            }
        }
    }

    /// The side of a local or remote address.
    fn side_of(ip: Ipv4Address) -> Side {
        if ip.octets()[0] == 127 {
            Side::Lo
        } else {
            Side::Eth
        }
    }

    fn is_local(&self, ip: Ipv4Address) -> bool {
        ip.is_unspecified()
            || ip.octets()[0] == 127
            || (self.config.has_eth() && ip == self.config.address)
    }

    /// `socket(domain, type, protocol)`.
    pub fn socket(&mut self, domain: i32, ty: i32, protocol: i32) -> Result<SocketId, Error> {
        use linux::*;
        if domain == AF_INET6 {
            return Err(Error::AddressFamilyNotSupported);
        }
        if domain != AF_INET {
            return Err(Error::AddressFamilyNotSupported);
        }
        let kind = match (ty & !(SOCK_NONBLOCK | SOCK_CLOEXEC), protocol) {
            (SOCK_STREAM, 0 | IPPROTO_TCP) => SocketKind::Tcp,
            (SOCK_DGRAM, 0 | IPPROTO_UDP) => SocketKind::Udp,
            (SOCK_STREAM | SOCK_DGRAM, _) => return Err(Error::ProtocolNotSupported),
            _ => return Err(Error::SocketTypeNotSupported),
        };
        if self.table.iter().flatten().count() >= self.config.limits.sockets {
            return Err(Error::NoBuffers);
        }
        Ok(self.insert(Sock {
            kind,
            nonblocking: ty & SOCK_NONBLOCK != 0,
            reuse_address: false,
            keep_alive: false,
            no_delay: false,
            broadcast: false,
            bound: None,
            owns_port: false,
            tcp: TcpState::Fresh,
            udp: Vec::new(),
            peer: None,
            shut_read: false,
            shut_write: false,
            error: None,
        }))
    }

    /// The socket's kind.
    pub fn kind(&self, id: SocketId) -> Result<SocketKind, Error> {
        Ok(self.sock(id)?.kind)
    }

    pub fn set_nonblocking(&mut self, id: SocketId, on: bool) -> Result<(), Error> {
        self.sock_mut(id)?.nonblocking = on;
        Ok(())
    }

    pub fn is_nonblocking(&self, id: SocketId) -> Result<bool, Error> {
        Ok(self.sock(id)?.nonblocking)
    }

    /// Whether `port` is taken for `kind` at `ip` (by another socket than `except`).
    fn port_taken(
        &self,
        kind: SocketKind,
        ip: Ipv4Address,
        port: u16,
        reuse: bool,
        except: SocketId,
    ) -> bool {
        self.table
            .iter()
            .enumerate()
            .filter_map(|(i, s)| s.as_ref().map(|s| (i, s)))
            .any(|(i, s)| {
                i != except.0
                    && s.kind == kind
                    && s.owns_port
                    && s.bound.is_some_and(|b| {
                        b.port == port
                            && (b.ip == ip || b.ip.is_unspecified() || ip.is_unspecified())
                            && !(reuse
                                && s.reuse_address
                                && !matches!(s.tcp, TcpState::Listening { .. }))
                    })
            })
    }

    fn ephemeral(&mut self, kind: SocketKind, ip: Ipv4Address) -> Result<u16, Error> {
        let span = (*EPHEMERAL.end() - *EPHEMERAL.start()) as usize + 1;
        for _ in 0..span {
            let port = self.next_port;
            self.next_port = if port == *EPHEMERAL.end() {
                *EPHEMERAL.start()
            } else {
                port + 1
            };
            let in_lingering = kind == SocketKind::Tcp
                && self.lingering.clone().into_iter().any(|(side, h)| {
                    self.tcp(side, h)
                        .local_endpoint()
                        .is_some_and(|e| e.port == port)
                });
            if !self.port_taken(kind, ip, port, false, SocketId(usize::MAX)) && !in_lingering {
                return Ok(port);
            }
        }
        Err(Error::AddressInUse)
    }

    /// `bind(addr)`; port 0 picks a free one.
    pub fn bind(&mut self, id: SocketId, addr: SocketAddr) -> Result<(), Error> {
        let sock = self.sock(id)?;
        if sock.bound.is_some() || !matches!(sock.tcp, TcpState::Fresh) {
            return Err(Error::Invalid);
        }
        if !self.is_local(addr.ip) {
            return Err(Error::AddressNotAvailable);
        }
        let (kind, reuse) = (sock.kind, sock.reuse_address);
        let port = match addr.port {
            0 => self.ephemeral(kind, addr.ip)?,
            p if self.port_taken(kind, addr.ip, p, reuse, id) => return Err(Error::AddressInUse),
            p => p,
        };
        let sock = self.sock_mut(id)?;
        sock.bound = Some(SocketAddr::new(addr.ip, port));
        sock.owns_port = true;
        if kind == SocketKind::Udp {
            // A bound UDP socket receives from now on.
            if let Err(e) = self.ensure_udp(id) {
                let sock = self.sock_mut(id)?;
                sock.bound = None;
                sock.owns_port = false;
                return Err(e);
            }
        }
        Ok(())
    }

    fn ensure_bound(&mut self, id: SocketId, towards: Ipv4Address) -> Result<SocketAddr, Error> {
        if let Some(b) = self.sock(id)?.bound {
            return Ok(b);
        }
        let ip = if towards.octets()[0] == 127 {
            Ipv4Address::new(127, 0, 0, 1)
        } else {
            Ipv4Address::UNSPECIFIED
        };
        self.bind(id, SocketAddr::new(ip, 0))?;
        self.sock(id)?.bound.ok_or(Error::Invalid)
    }

    fn listen_on(&mut self, side: Side, bound: SocketAddr) -> Result<SocketHandle, Error> {
        let handle = self.new_tcp(side)?;
        let addr = (!bound.ip.is_unspecified()).then_some(IpAddress::Ipv4(bound.ip));
        if self
            .tcp(side, handle)
            .listen(IpListenEndpoint {
                addr,
                port: bound.port,
            })
            .is_err()
        {
            self.set(side).remove(handle);
            return Err(Error::Invalid);
        }
        Ok(handle)
    }

    /// `listen(backlog)`.
    pub fn listen(&mut self, id: SocketId, backlog: i32) -> Result<(), Error> {
        let sock = self.sock(id)?;
        if sock.kind != SocketKind::Tcp {
            return Err(Error::OperationNotSupported);
        }
        if !matches!(sock.tcp, TcpState::Fresh) {
            return Err(Error::Invalid);
        }
        let backlog = (backlog.max(1) as usize).min(self.config.limits.backlog);
        let bound = self.ensure_bound(id, Ipv4Address::UNSPECIFIED)?;
        if self.port_taken(SocketKind::Tcp, bound.ip, bound.port, false, id) {
            return Err(Error::AddressInUse);
        }
        let sides: Vec<Side> = if bound.ip.is_unspecified() {
            vec![Side::Eth, Side::Lo]
        } else {
            vec![Self::side_of(bound.ip)]
        };
        self.room(backlog * sides.len())?;
        let mut listeners = Vec::new();
        for _ in 0..backlog {
            for &side in &sides {
                match self.listen_on(side, bound) {
                    Ok(handle) => listeners.push((side, handle)),
                    Err(e) => {
                        for (side, handle) in listeners {
                            self.set(side).remove(handle);
                        }
                        return Err(e);
                    }
                }
            }
        }
        self.sock_mut(id)?.tcp = TcpState::Listening {
            listeners,
            missing: Vec::new(),
        };
        Ok(())
    }

    fn configure(&mut self, side: Side, handle: SocketHandle, keep_alive: bool, no_delay: bool) {
        let s = self.tcp(side, handle);
        s.set_keep_alive(keep_alive.then_some(KEEP_ALIVE));
        s.set_nagle_enabled(!no_delay);
    }

    /// `accept`: a connection that completed, with its peer.
    pub fn accept(&mut self, id: SocketId) -> Result<(SocketId, SocketAddr), Error> {
        let sock = self.sock(id)?;
        let TcpState::Listening { listeners, missing } = &sock.tcp else {
            return Err(Error::Invalid);
        };
        let (keep_alive, no_delay, bound) = (sock.keep_alive, sock.no_delay, sock.bound);
        let (mut listeners, mut missing) = (listeners.clone(), missing.clone());
        let bound = bound.ok_or(Error::Invalid)?;
        // Places left empty by earlier accepts listen again where the limit and the heap
        // now allow.
        while let Some(&side) = missing.last() {
            let Ok(handle) = self.room(1).and_then(|()| self.listen_on(side, bound)) else {
                break;
            };
            listeners.push((side, handle));
            missing.pop();
        }
        let ready = listeners.iter().position(|&(side, h)| {
            let s = self.tcp(side, h);
            !matches!(
                s.state(),
                tcp::State::Listen | tcp::State::SynReceived | tcp::State::Closed
            )
        });
        let Some(index) = ready else {
            if let TcpState::Listening {
                listeners: l,
                missing: m,
            } = &mut self.sock_mut(id)?.tcp
            {
                (*l, *m) = (listeners, missing);
            }
            return Err(Error::WouldBlock);
        };
        let (side, handle) = listeners[index];
        let peer = self.tcp(side, handle).remote_endpoint().map(endpoint_addr);
        let local = self.tcp(side, handle).local_endpoint().map(endpoint_addr);
        // A new listener takes the accepted one's place if the socket limit and the heap
        // allow it (closed connections in TIME-WAIT give theirs first); else the place
        // waits.
        match self.room(1).and_then(|()| self.listen_on(side, bound)) {
            Ok(new) => listeners[index] = (side, new),
            Err(_) => {
                listeners.swap_remove(index);
                missing.push(side);
            }
        }
        if let TcpState::Listening {
            listeners: l,
            missing: m,
        } = &mut self.sock_mut(id)?.tcp
        {
            (*l, *m) = (listeners, missing);
        }
        self.configure(side, handle, keep_alive, no_delay);
        let peer = peer.ok_or(Error::ConnectionReset)?;
        let new = self.insert(Sock {
            kind: SocketKind::Tcp,
            nonblocking: false,
            reuse_address: false,
            keep_alive,
            no_delay,
            broadcast: false,
            bound: local,
            owns_port: false,
            tcp: TcpState::Connected {
                side,
                handle,
                peer_closed: false,
            },
            udp: Vec::new(),
            peer: Some(peer),
            shut_read: false,
            shut_write: false,
            error: None,
        });
        Ok((new, peer))
    }

    /// `connect(addr)`.
    pub fn connect(&mut self, id: SocketId, addr: SocketAddr) -> Result<(), Error> {
        let sock = self.sock(id)?;
        if sock.kind == SocketKind::Udp {
            if addr.ip.is_unspecified() && addr.port == 0 {
                self.sock_mut(id)?.peer = None;
                return Ok(());
            }
            self.ensure_bound(id, addr.ip)?;
            self.ensure_udp(id)?;
            self.sock_mut(id)?.peer = Some(addr);
            return Ok(());
        }
        match sock.tcp {
            TcpState::Connecting { .. } => return Err(Error::Already),
            TcpState::Connected { .. } => return Err(Error::IsConnected),
            TcpState::Listening { .. } => return Err(Error::Invalid),
            TcpState::Fresh | TcpState::Failed(_) => {}
        }
        if addr.port == 0 || addr.ip.is_unspecified() {
            return Err(Error::ConnectionRefused);
        }
        let side = Self::side_of(addr.ip);
        if side == Side::Eth && !self.reachable(addr.ip) {
            return Err(Error::NetworkUnreachable);
        }
        let (keep_alive, no_delay, nonblocking) =
            (sock.keep_alive, sock.no_delay, sock.nonblocking);
        self.room(1)?;
        let local = self.ensure_bound(id, addr.ip)?;
        let handle = self.new_tcp(side)?;
        self.configure(side, handle, keep_alive, no_delay);
        let local_ip = (!local.ip.is_unspecified()).then_some(IpAddress::Ipv4(local.ip));
        let remote = IpEndpoint::new(IpAddress::Ipv4(addr.ip), addr.port);
        let iface = match side {
            Side::Eth => &mut self.eth,
            Side::Lo => &mut self.lo,
        };
        let set = match side {
            Side::Eth => &mut self.eth_set,
            Side::Lo => &mut self.lo_set,
        };
        let result = set.get_mut::<tcp::Socket>(handle).connect(
            iface.context(),
            remote,
            IpListenEndpoint {
                addr: local_ip,
                port: local.port,
            },
        );
        if result.is_err() {
            self.set(side).remove(handle);
            return Err(Error::AddressNotAvailable);
        }
        let now = self.now;
        let sock = self.sock_mut(id)?;
        sock.tcp = TcpState::Connecting {
            side,
            handle,
            since: now,
        };
        sock.peer = Some(addr);
        sock.error = None;
        self.poll(now.total_micros());
        Err(if nonblocking {
            Error::InProgress
        } else {
            Error::WouldBlock
        })
    }

    /// Whether `eth0` has a route to `ip`.
    fn reachable(&self, ip: Ipv4Address) -> bool {
        if !self.config.has_eth() {
            return false;
        }
        let cidr = Ipv4Cidr::new(self.config.address, self.config.prefix);
        cidr.contains_addr(&ip)
            || self.config.gateway.is_some()
            || ip.is_broadcast()
            || ip.is_multicast()
    }

    /// The outcome of a connect under way: `Ok` once connected, its error once failed
    /// (then the socket is fresh again), [`Error::WouldBlock`] while it goes on.
    pub fn connect_result(&mut self, id: SocketId) -> Result<(), Error> {
        self.update(id);
        match &self.sock(id)?.tcp {
            TcpState::Connected { .. } => Ok(()),
            TcpState::Connecting { .. } => Err(Error::WouldBlock),
            TcpState::Failed(e) => Err(*e),
            _ => Err(Error::NotConnected),
        }
    }

    /// Moves a socket's state along with its smoltcp socket's.
    fn update(&mut self, id: SocketId) {
        let Ok(sock) = self.sock(id) else { return };
        let next = match sock.tcp {
            TcpState::Connecting {
                side,
                handle,
                since,
            } => {
                let state = self.tcp(side, handle).state();
                match state {
                    tcp::State::SynSent | tcp::State::SynReceived => {
                        if self.now - since >= CONNECT_TIMEOUT {
                            self.set(side).remove(handle);
                            Some(TcpState::Failed(Error::TimedOut))
                        } else {
                            None
                        }
                    }
                    tcp::State::Closed => {
                        self.set(side).remove(handle);
                        Some(TcpState::Failed(Error::ConnectionRefused))
                    }
                    _ => Some(TcpState::Connected {
                        side,
                        handle,
                        peer_closed: false,
                    }),
                }
            }
            TcpState::Connected {
                side,
                handle,
                peer_closed: false,
            } => {
                let s = self.tcp(side, handle);
                let fin = matches!(
                    s.state(),
                    tcp::State::CloseWait
                        | tcp::State::LastAck
                        | tcp::State::Closing
                        | tcp::State::TimeWait
                ) || (!s.may_recv() && s.state() != tcp::State::Closed);
                fin.then_some(TcpState::Connected {
                    side,
                    handle,
                    peer_closed: true,
                })
            }
            _ => None,
        };
        if let (Some(next), Ok(sock)) = (next, self.sock_mut(id)) {
            if let TcpState::Failed(e) = next {
                sock.error = Some(e);
            }
            sock.tcp = next;
        }
    }

    /// The smoltcp UDP sockets of a bound UDP socket, made on first use: one on each
    /// interface its address covers (both for 0.0.0.0).
    fn ensure_udp(&mut self, id: SocketId) -> Result<(), Error> {
        let sock = self.sock(id)?;
        if !sock.udp.is_empty() {
            return Ok(());
        }
        let bound = sock.bound.ok_or(Error::Invalid)?;
        let sides = if bound.ip.is_unspecified() {
            vec![Side::Eth, Side::Lo]
        } else {
            vec![Self::side_of(bound.ip)]
        };
        self.room(sides.len())?;
        let limits = self.config.limits;
        let mut handles = Vec::new();
        for side in sides {
            let buffer = || {
                udp::PacketBuffer::new(
                    vec![udp::PacketMetadata::EMPTY; limits.udp_packets],
                    vec![0; limits.udp_buffer],
                )
            };
            let mut socket = udp::Socket::new(buffer(), buffer());
            let addr = (!bound.ip.is_unspecified()).then_some(IpAddress::Ipv4(bound.ip));
            socket
                .bind(IpListenEndpoint {
                    addr,
                    port: bound.port,
                })
                .map_err(|_| Error::Invalid)?;
            handles.push((side, self.set(side).add(socket)));
        }
        self.sock_mut(id)?.udp = handles;
        Ok(())
    }

    /// `send`/`sendto`: bytes taken (TCP: as many as fit; UDP: the whole datagram).
    pub fn send(
        &mut self,
        id: SocketId,
        data: &[u8],
        to: Option<SocketAddr>,
    ) -> Result<usize, Error> {
        self.update(id);
        let sock = self.sock(id)?;
        if sock.kind == SocketKind::Udp {
            let to = to.or(sock.peer).ok_or(Error::DestinationRequired)?;
            if to.ip.is_broadcast() && !sock.broadcast {
                return Err(Error::Invalid);
            }
            if data.len() > self.config.limits.udp_buffer || data.len() > 65_507 {
                return Err(Error::MessageTooLong);
            }
            self.ensure_bound(id, to.ip)?;
            self.ensure_udp(id)?;
            let want = Self::side_of(to.ip);
            if want == Side::Eth && !self.reachable(to.ip) {
                return Err(Error::NetworkUnreachable);
            }
            let Some(&(side, handle)) = self.sock(id)?.udp.iter().find(|(s, _)| *s == want) else {
                return Err(Error::NetworkUnreachable);
            };
            let endpoint = IpEndpoint::new(IpAddress::Ipv4(to.ip), to.port);
            return match self.udp_socket(side, handle).send_slice(data, endpoint) {
                Ok(()) => Ok(data.len()),
                Err(udp::SendError::BufferFull) => Err(Error::WouldBlock),
                Err(udp::SendError::Unaddressable) => Err(Error::NetworkUnreachable),
            };
        }
        if sock.shut_write {
            return Err(Error::BrokenPipe);
        }
        match sock.tcp {
            TcpState::Connected { side, handle, .. } => {
                let s = self.tcp(side, handle);
                if !s.may_send() {
                    return Err(if s.state() == tcp::State::Closed {
                        Error::ConnectionReset
                    } else {
                        Error::BrokenPipe
                    });
                }
                match s.send_slice(data) {
                    Ok(0) if !data.is_empty() => Err(Error::WouldBlock),
                    Ok(n) => Ok(n),
                    Err(_) => Err(Error::BrokenPipe),
                }
            }
            TcpState::Connecting { .. } => Err(Error::WouldBlock),
            TcpState::Failed(e) => Err(e),
            _ => Err(Error::NotConnected),
        }
    }

    /// `recv`/`recvfrom`: bytes read (0: end of file) and, for UDP, the sender. A datagram
    /// longer than `buf` is cut, as Linux does.
    pub fn recv(
        &mut self,
        id: SocketId,
        buf: &mut [u8],
    ) -> Result<(usize, Option<SocketAddr>), Error> {
        self.update(id);
        let sock = self.sock(id)?;
        if sock.kind == SocketKind::Udp {
            let (handles, peer) = (sock.udp.clone(), sock.peer);
            for (side, handle) in handles {
                // A connected UDP socket takes datagrams from its peer only; others are
                // dropped (bounded by the buffer's datagrams).
                for _ in 0..=self.config.limits.udp_packets {
                    match self.udp_socket(side, handle).recv() {
                        Ok((datagram, meta)) => {
                            let from = endpoint_addr(meta.endpoint);
                            if peer.is_some_and(|p| p != from) {
                                continue;
                            }
                            let n = datagram.len().min(buf.len());
                            buf[..n].copy_from_slice(&datagram[..n]);
                            return Ok((n, Some(from)));
                        }
                        Err(udp::RecvError::Truncated) => continue,
                        Err(udp::RecvError::Exhausted) => break,
                    }
                }
            }
            return Err(Error::WouldBlock);
        }
        if sock.shut_read {
            return Ok((0, None));
        }
        match sock.tcp {
            TcpState::Connected {
                side,
                handle,
                peer_closed,
            } => {
                let s = self.tcp(side, handle);
                if s.can_recv() {
                    return s
                        .recv_slice(buf)
                        .map(|n| (n, None))
                        .map_err(|_| Error::ConnectionReset);
                }
                if peer_closed || !s.may_recv() {
                    if s.state() == tcp::State::Closed && !peer_closed {
                        return Err(Error::ConnectionReset);
                    }
                    return Ok((0, None));
                }
                Err(Error::WouldBlock)
            }
            TcpState::Connecting { .. } => Err(Error::WouldBlock),
            TcpState::Failed(e) => Err(e),
            _ => Err(Error::NotConnected),
        }
    }

    /// `shutdown(how)`.
    pub fn shutdown(&mut self, id: SocketId, how: i32) -> Result<(), Error> {
        use linux::*;
        if !(SHUT_RD..=SHUT_RDWR).contains(&how) {
            return Err(Error::Invalid);
        }
        self.update(id);
        let sock = self.sock(id)?;
        let handle = match sock.tcp {
            TcpState::Connected { side, handle, .. } => Some((side, handle)),
            _ if sock.kind == SocketKind::Udp && sock.peer.is_some() => None,
            _ => return Err(Error::NotConnected),
        };
        let sock = self.sock_mut(id)?;
        if how != SHUT_WR {
            sock.shut_read = true;
        }
        if how != SHUT_RD {
            sock.shut_write = true;
            if let Some((side, handle)) = handle {
                self.tcp(side, handle).close();
            }
        }
        Ok(())
    }

    /// Joins the IPv4 multicast `group` on the Ethernet interface: datagrams to it are
    /// received from then on (and IGMP reports tell routers so).
    pub fn join_multicast(&mut self, group: Ipv4Address) -> Result<(), Error> {
        if !group.is_multicast() {
            return Err(Error::Invalid);
        }
        self.eth
            .join_multicast_group(IpAddress::Ipv4(group))
            .map_err(|_| Error::NoBuffers)
    }

    /// Leaves the IPv4 multicast `group` on the Ethernet interface (IGMP tells routers so):
    /// datagrams to it are no longer received. Leaving a group not joined does nothing.
    pub fn leave_multicast(&mut self, group: Ipv4Address) -> Result<(), Error> {
        if !group.is_multicast() {
            return Err(Error::Invalid);
        }
        self.eth
            .leave_multicast_group(IpAddress::Ipv4(group))
            .map_err(|_| Error::NoBuffers)
    }

    /// `close`: the socket is gone; a connection finishes in the background, the
    /// connections a listener did not accept are reset.
    pub fn close(&mut self, id: SocketId) -> Result<(), Error> {
        let sock = self
            .table
            .get_mut(id.0)
            .and_then(Option::take)
            .ok_or(Error::BadDescriptor)?;
        for (side, handle) in sock.udp {
            self.set(side).remove(handle);
        }
        match sock.tcp {
            TcpState::Listening { listeners, .. } => {
                for (side, handle) in listeners {
                    self.tcp(side, handle).abort();
                    self.lingering.push((side, handle));
                }
            }
            TcpState::Connected { side, handle, .. }
            | TcpState::Connecting { side, handle, .. } => {
                self.tcp(side, handle).close();
                self.lingering.push((side, handle));
            }
            _ => {}
        }
        Ok(())
    }

    /// `getsockname`.
    pub fn local_addr(&self, id: SocketId) -> Result<SocketAddr, Error> {
        let sock = self.sock(id)?;
        let mut addr = sock
            .bound
            .unwrap_or(SocketAddr::new(Ipv4Address::UNSPECIFIED, 0));
        // A connected socket bound to 0.0.0.0 reports the address it uses.
        if addr.ip.is_unspecified()
            && sock.peer.is_some()
            && !matches!(sock.tcp, TcpState::Fresh | TcpState::Listening { .. })
        {
            addr.ip = match sock.peer.map(|p| Self::side_of(p.ip)) {
                Some(Side::Lo) => Ipv4Address::new(127, 0, 0, 1),
                _ => self.config.address,
            };
        }
        Ok(addr)
    }

    /// `getpeername`.
    pub fn peer_addr(&mut self, id: SocketId) -> Result<SocketAddr, Error> {
        self.update(id);
        let sock = self.sock(id)?;
        match (&sock.tcp, sock.kind) {
            (TcpState::Connected { .. }, _) | (_, SocketKind::Udp) => {
                sock.peer.ok_or(Error::NotConnected)
            }
            _ => Err(Error::NotConnected),
        }
    }

    /// `setsockopt` with an integer value.
    pub fn set_option(
        &mut self,
        id: SocketId,
        level: i32,
        name: i32,
        value: i32,
    ) -> Result<(), Error> {
        use linux::*;
        let sock = self.sock_mut(id)?;
        let on = value != 0;
        match (level, name) {
            (SOL_SOCKET, SO_REUSEADDR | SO_REUSEPORT) => sock.reuse_address = on,
            (SOL_SOCKET, SO_KEEPALIVE) => sock.keep_alive = on,
            (SOL_SOCKET, SO_BROADCAST) => sock.broadcast = on,
            // Buffer sizes are the configuration's; LINGER is accepted (see the crate docs).
            (SOL_SOCKET, SO_SNDBUF | SO_RCVBUF | SO_LINGER) => {}
            (IPPROTO_TCP, TCP_NODELAY) if sock.kind == SocketKind::Tcp => sock.no_delay = on,
            _ => return Err(Error::NoProtocolOption),
        }
        if let TcpState::Connected { side, handle, .. } = sock.tcp {
            let (keep_alive, no_delay) = (sock.keep_alive, sock.no_delay);
            self.configure(side, handle, keep_alive, no_delay);
        }
        Ok(())
    }

    /// `getsockopt` of an integer option (SO_ERROR clears the pending error).
    pub fn option(&mut self, id: SocketId, level: i32, name: i32) -> Result<i32, Error> {
        use linux::*;
        self.update(id);
        let buffer = self.config.limits.tcp_buffer as i32;
        let sock = self.sock_mut(id)?;
        Ok(match (level, name) {
            (SOL_SOCKET, SO_REUSEADDR | SO_REUSEPORT) => i32::from(sock.reuse_address),
            (SOL_SOCKET, SO_KEEPALIVE) => i32::from(sock.keep_alive),
            (SOL_SOCKET, SO_BROADCAST) => i32::from(sock.broadcast),
            (SOL_SOCKET, SO_TYPE) => match sock.kind {
                SocketKind::Tcp => SOCK_STREAM,
                SocketKind::Udp => SOCK_DGRAM,
            },
            (SOL_SOCKET, SO_ERROR) => {
                let e = sock.error.take().map_or(0, Error::errno);
                if matches!(sock.tcp, TcpState::Failed(_)) {
                    sock.tcp = TcpState::Fresh;
                }
                e
            }
            (SOL_SOCKET, SO_SNDBUF | SO_RCVBUF) => buffer,
            (SOL_SOCKET, SO_LINGER) => 0,
            (IPPROTO_TCP, TCP_NODELAY) if sock.kind == SocketKind::Tcp => i32::from(sock.no_delay),
            _ => return Err(Error::NoProtocolOption),
        })
    }

    /// What `poll` sees of the socket now.
    pub fn readiness(&mut self, id: SocketId) -> Result<Readiness, Error> {
        self.update(id);
        let sock = self.sock(id)?.clone();
        let mut r = Readiness::default();
        if sock.kind == SocketKind::Udp {
            r.writable = true;
            for (side, handle) in sock.udp {
                let s = self.udp_socket(side, handle);
                r.readable |= s.can_recv();
                r.writable &= s.can_send();
            }
            return Ok(r);
        }
        match sock.tcp {
            TcpState::Listening { listeners, .. } => {
                r.readable = listeners.iter().any(|&(side, h)| {
                    !matches!(
                        self.tcp(side, h).state(),
                        tcp::State::Listen | tcp::State::SynReceived | tcp::State::Closed
                    )
                });
            }
            TcpState::Connected {
                side,
                handle,
                peer_closed,
            } => {
                let s = self.tcp(side, handle);
                let reset = s.state() == tcp::State::Closed && !peer_closed;
                r.readable = s.can_recv() || peer_closed || !s.may_recv() || sock.shut_read;
                r.writable = s.can_send() && !sock.shut_write;
                r.hangup = (peer_closed && (sock.shut_write || !s.may_send())) || reset;
                r.error = reset;
            }
            TcpState::Failed(_) => {
                r.error = true;
                r.hangup = true;
                r.writable = true;
            }
            TcpState::Connecting { .. } => {}
            TcpState::Fresh => r.hangup = true,
        }
        Ok(r)
    }

    /// Runs both interfaces at `now_us`: frames in and out, timers, retransmissions; then
    /// frees lingering connections that have finished. Returns whether a socket may have
    /// changed (frames came or went, a timer fired): otherwise no call waiting for one
    /// can have become ready. Which sockets changed, [`Stack::take_changed`] tells.
    pub fn poll(&mut self, now_us: i64) -> bool {
        let now = Instant::from_micros(now_us);
        self.now = self.now.max(now);
        let now = self.now;
        let before: Vec<Option<u64>> = (0..self.table.len()).map(|i| self.digest(i)).collect();
        use smoltcp::iface::PollResult::SocketStateChanged as Changed;
        // One poll of eth takes in every frame its device holds and sends what the
        // sockets answer; the loopback's frames go round (what one poll sends, the next
        // takes in: SYN, SYN-ACK, ACK), so it runs until it is quiet.
        let mut changed = self.eth.poll(now, &mut self.device, &mut self.eth_set) == Changed;
        for _ in 0..8 {
            if self.lo.poll(now, &mut self.loopback, &mut self.lo_set) != Changed {
                break;
            }
            changed = true;
        }
        // A connect's time-out is the stack's own timer, which no frame shows: it fails
        // here, so that a call waiting on it learns of it.
        for i in 0..self.table.len() {
            if let Some(Sock {
                tcp: TcpState::Connecting { since, .. },
                ..
            }) = self.table[i]
                && now - since >= CONNECT_TIMEOUT
            {
                self.update(SocketId(i));
                changed = true;
            }
        }
        if changed {
            for (i, digest) in before.into_iter().enumerate() {
                let id = SocketId(i);
                if digest.is_some() && self.digest(i) != digest && !self.changed.contains(&id) {
                    self.changed.push(id);
                }
            }
        }
        let lingering = core::mem::take(&mut self.lingering);
        for (side, handle) in lingering {
            if self.tcp(side, handle).state() == tcp::State::Closed {
                self.set(side).remove(handle);
            } else {
                self.lingering.push((side, handle));
            }
        }
        changed
    }

    /// The sockets the polls changed since the last take, in no order: a call waiting on
    /// another socket cannot have become able to finish through them (what the calls
    /// themselves change, their callers know).
    pub fn take_changed(&mut self) -> Vec<SocketId> {
        core::mem::take(&mut self.changed)
    }

    /// A digest of what the calls on the socket at `index` can see of it, if it is open:
    /// its state and each of its smoltcp sockets' state and queues. A poll that leaves it
    /// as it was cannot have made a call waiting on the socket able to finish. (Each
    /// value is folded in by a bijection, so a poll that changes one of them always
    /// changes the digest.)
    fn digest(&self, index: usize) -> Option<u64> {
        let sock = self.table.get(index)?.as_ref()?;
        let fold = |digest: u64, value: u64| (digest ^ value).wrapping_mul(0x0000_0100_0000_01b3);
        let set = |side| match side {
            Side::Eth => &self.eth_set,
            Side::Lo => &self.lo_set,
        };
        let tcp = |digest: u64, (side, handle): (Side, SocketHandle)| {
            let s = set(side).get::<tcp::Socket>(handle);
            [
                s.state() as u64,
                s.recv_queue() as u64,
                s.send_queue() as u64,
            ]
            .into_iter()
            .fold(digest, fold)
        };
        let flags = u64::from(sock.shut_read) | u64::from(sock.shut_write) << 1;
        let digest = fold(
            0xcbf2_9ce4_8422_2325,
            flags | u64::from(sock.error.is_some()) << 2,
        );
        Some(match &sock.tcp {
            TcpState::Listening { listeners, .. } => listeners.iter().copied().fold(digest, tcp),
            TcpState::Connecting { side, handle, .. } => tcp(fold(digest, 1), (*side, *handle)),
            TcpState::Connected {
                side,
                handle,
                peer_closed,
            } => tcp(
                fold(digest, 2 | u64::from(*peer_closed) << 8),
                (*side, *handle),
            ),
            TcpState::Fresh | TcpState::Failed(_) => {
                sock.udp.iter().fold(digest, |d, &(side, h)| {
                    let s = set(side).get::<udp::Socket>(h);
                    [
                        s.recv_queue() as u64,
                        s.send_queue() as u64,
                        u64::from(s.can_recv()) | u64::from(s.can_send()) << 1,
                    ]
                    .into_iter()
                    .fold(d, fold)
                })
            }
        })
    }

    /// When the stack must be polled next (microseconds), if it has a timer.
    pub fn poll_at(&mut self) -> Option<i64> {
        let now = self.now;
        let at = [
            self.eth.poll_at(now, &self.eth_set),
            self.lo.poll_at(now, &self.lo_set),
        ];
        at.into_iter().flatten().map(|i| i.total_micros()).min()
    }
}

fn endpoint_addr(e: IpEndpoint) -> SocketAddr {
    let IpAddress::Ipv4(ip) = e.addr;
    SocketAddr::new(ip, e.port)
}
