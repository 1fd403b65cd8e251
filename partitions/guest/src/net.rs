//! The guest's network: the TCP/IP stack its processes' sockets live in ([`netstack`]:
//! smoltcp with Linux's socket semantics), how many descriptors share each socket (a
//! socket closes when the last one does: `dup`, `fork`), the socket addresses as the
//! calls pass them (`struct sockaddr_in`), and the interfaces as `ifconfig`, `route` and
//! `/proc/net` show them.
//!
//! The stack runs on the guest's clock: [`crate::system`] polls it before it serves the
//! waiting calls again, so a byte one process writes reaches the process waiting to read
//! it, and the partition program wakes at [`Net::poll_at_ns`] for smoltcp's timers
//! (retransmissions, delayed ACKs, keep-alives, `TIME-WAIT`). `lo` (127.0.0.1/8) is always
//! there; `eth0` only with `guest.net` in the configuration ([`NetConfig`]), its frames
//! carried between the stack and the partition's ports, or, when the NIC partition's
//! tenant entry names one, a frame ring in shared memory (`frame_ring`), the ports then
//! carrying only its wake-ups.

use crate::linux::Errno;
use alloc::vec::Vec;
pub use netstack::Ipv4Address;
use netstack::{Config, Counters, Limits, SocketAddr, SocketId, Stack};
use nic_core::switch::Mac;

/// `AF_INET` and the length of its `struct sockaddr_in`.
pub const AF_INET: u16 = 2;
pub const SOCKADDR_IN_LEN: usize = 16;

/// What the guest's stack may take of its heap: sockets (each backlog's listeners
/// count), and their buffers (a TCP socket's as [`ring_tcp_buffer`] says when `eth0` has a
/// frame ring).
pub const LIMITS: Limits = Limits {
    sockets: 48,
    tcp_buffer: 32 * 1024,
    udp_packets: 32,
    udp_buffer: 32 * 1024,
    backlog: 8,
    frames: 64,
};

/// The bytes of TCP data a full Ethernet frame carries (1500 bytes of IP, less the IPv4
/// and TCP headers).
pub const SEGMENT: usize = 1460;

/// A TCP socket's buffers when `eth0`'s frames go through a ring of `slots` slots each way:
/// as many full segments as the ring holds (a window the peer sends at once lands in the
/// ring without loss; a larger one overflowed it and cost retransmissions), in whole KiB
/// and within 16 to 64 KiB (TCP's largest window without window scaling is a byte less).
pub fn ring_tcp_buffer(slots: u32) -> usize {
    (slots as usize * SEGMENT / 1024 * 1024).clamp(16 * 1024, 64 * 1024)
}

/// The shortest time between two runs of the stack for its timers.
pub const MIN_POLL_GAP_NS: u64 = 200_000;
/// How often the guest looks for frames on `eth0`'s port when nothing else wakes it (the
/// port's doorbell does, when frames come).
pub const RX_POLL_NS: u64 = 2_000_000;
/// How often it looks while serving calls (each look is a call to syssw), unless the
/// last look found frames.
pub const RX_LOOK_NS: u64 = 500_000;

/// `eth0` as the configuration gives it (`guest.net`, written by `cargo xtask` to
/// [`NET_PATH`] in the initramfs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NetConfig {
    pub mac: [u8; 6],
    pub address: Ipv4Address,
    pub prefix: u8,
    pub gateway: Option<Ipv4Address>,
}

/// Where the guest finds `eth0`'s configuration: `key=value` lines (`mac`, `address`
/// as `a.b.c.d/prefix`, `gateway`, `rx`, `tx`: the ports of the frames; `ring` as
/// `address,size`: the frame ring's segment, if any).
pub const NET_PATH: &str = "/etc/guest/net";

/// `eth0`'s configuration and its ports' names, from the file at [`NET_PATH`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NetFile<'a> {
    pub config: NetConfig,
    pub rx: &'a str,
    pub tx: &'a str,
    /// The frame ring's segment: address and size.
    pub ring: Option<(u64, usize)>,
}

/// Parses the file at [`NET_PATH`]; the error names the line and what is wrong.
pub fn parse_net_file(text: &str) -> Result<NetFile<'_>, (usize, &'static str)> {
    let (mut mac, mut address, mut gateway, mut rx, mut tx) = (None, None, None, None, None);
    let mut ring = None;
    for setting in crate::settings(text) {
        let (at, key, value) = setting?;
        match key {
            "mac" => mac = Some(Mac::parse(value).ok_or((at, "bad MAC address"))?.0),
            "address" => {
                let (ip, prefix) = value.split_once('/').ok_or((at, "expected a.b.c.d/n"))?;
                let ip = parse_ipv4(ip).ok_or((at, "bad IPv4 address"))?;
                let prefix = prefix
                    .parse::<u8>()
                    .ok()
                    .filter(|&p| (1..=32).contains(&p))
                    .ok_or((at, "bad prefix length"))?;
                address = Some((ip, prefix));
            }
            "gateway" => gateway = Some(parse_ipv4(value).ok_or((at, "bad gateway address"))?),
            "rx" => rx = Some(value),
            "tx" => tx = Some(value),
            "ring" => {
                let bad = (at, "expected the ring as 0xADDRESS,SIZE");
                let (address, size) = value.split_once(',').ok_or(bad)?;
                let address = address.strip_prefix("0x").ok_or(bad)?;
                let address = u64::from_str_radix(address, 16).map_err(|_| bad)?;
                ring = Some((address, size.parse().map_err(|_| bad)?));
            }
            _ => return Err((at, "unknown key")),
        }
    }
    let last = text.lines().count();
    let (address, prefix) = address.ok_or((last, "no address"))?;
    Ok(NetFile {
        config: NetConfig {
            mac: mac.ok_or((last, "no mac"))?,
            address,
            prefix,
            gateway,
        },
        rx: rx.ok_or((last, "no rx port"))?,
        tx: tx.ok_or((last, "no tx port"))?,
        ring,
    })
}

/// `a.b.c.d`.
pub fn parse_ipv4(text: &str) -> Option<Ipv4Address> {
    let mut octets = [0u8; 4];
    let mut parts = text.split('.');
    for o in &mut octets {
        *o = parts.next()?.parse().ok()?;
    }
    parts
        .next()
        .is_none()
        .then(|| Ipv4Address::from_octets(octets))
}

/// A `struct sockaddr_in` (family, port in network order, address): `EINVAL` when
/// shorter, `EAFNOSUPPORT` for another family.
pub fn parse_sockaddr(bytes: &[u8]) -> Result<SocketAddr, Errno> {
    if bytes.len() < 2 {
        return Err(Errno::EINVAL);
    }
    if u16::from_le_bytes([bytes[0], bytes[1]]) != AF_INET {
        return Err(Errno::EAFNOSUPPORT);
    }
    if bytes.len() < SOCKADDR_IN_LEN {
        return Err(Errno::EINVAL);
    }
    Ok(SocketAddr::new(
        Ipv4Address::new(bytes[4], bytes[5], bytes[6], bytes[7]),
        u16::from_be_bytes([bytes[2], bytes[3]]),
    ))
}

/// The `struct sockaddr_in` of `addr`.
pub fn sockaddr_bytes(addr: SocketAddr) -> [u8; SOCKADDR_IN_LEN] {
    let mut b = [0u8; SOCKADDR_IN_LEN];
    b[..2].copy_from_slice(&AF_INET.to_le_bytes());
    b[2..4].copy_from_slice(&addr.port.to_be_bytes());
    b[4..8].copy_from_slice(&addr.ip.octets());
    b
}

/// A socket call's error as Linux's errno.
pub fn errno(e: netstack::Error) -> Errno {
    Errno(e.errno() as u16)
}

/// An interface as `ifconfig` and `/proc/net/dev` show it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Interface {
    pub name: &'static str,
    pub index: u32,
    pub mac: [u8; 6],
    pub address: Ipv4Address,
    pub prefix: u8,
    /// `IFF_*`.
    pub flags: u16,
    pub mtu: u32,
    pub counters: Counters,
}

pub const IFF_UP: u16 = 0x1;
pub const IFF_BROADCAST: u16 = 0x2;
pub const IFF_LOOPBACK: u16 = 0x8;
pub const IFF_RUNNING: u16 = 0x40;
pub const IFF_MULTICAST: u16 = 0x1000;

impl Interface {
    pub fn netmask(&self) -> Ipv4Address {
        let bits = u32::MAX
            .checked_shl(32 - u32::from(self.prefix))
            .unwrap_or(0);
        Ipv4Address::from_octets(bits.to_be_bytes())
    }

    pub fn broadcast(&self) -> Ipv4Address {
        let mask = u32::from_be_bytes(self.netmask().octets());
        let ip = u32::from_be_bytes(self.address.octets());
        Ipv4Address::from_octets((ip | !mask).to_be_bytes())
    }
}

/// The guest's network.
pub struct Net {
    /// Made on the first socket (or frame), at that instant.
    stack: Option<Stack>,
    eth: Option<NetConfig>,
    /// Descriptors of each socket, by [`SocketId`].
    refs: Vec<u32>,
    /// When it last ran.
    polled_ns: u64,
    /// `eth0`'s ports (indices into the port table, [`crate::arinc`]): received frames,
    /// frames to send (with a ring: its wake-ups each way).
    link: Option<(usize, usize)>,
    /// `eth0`'s frame ring: frames to send, received frames.
    ring: Option<(frame_ring::Producer, frame_ring::Consumer)>,
    /// Frames the `tx` port or ring had no room for (lost, as on a full ring; TCP sends
    /// again).
    pub tx_dropped: u64,
    /// Ring slots with no frame in them (a bogus length or index the NIC partition wrote).
    pub rx_bad: u64,
    /// When the `rx` port (or ring) was last looked at, and whether frames came then.
    rx_looked_ns: u64,
    rx_busy: bool,
    /// The NIC partition notifies the guest's doorbell thread when a frame goes into the
    /// empty ring ([`Net::wake_on_frames`]): then no look at the ring is timed.
    ring_notifies: bool,
    /// The last run left frames in the ring (a run takes at most [`LIMITS`]`.frames`):
    /// no notification comes for them (the ring is not empty), so the next run is due.
    ring_left: bool,
    /// The IPv4 multicast groups each socket joined on `eth0` (`IP_ADD_MEMBERSHIP`, by
    /// [`SocketId`]): the interface is in a group while a socket is.
    memberships: Vec<(usize, Ipv4Address)>,
}

/// Groups one socket may join (Linux's `igmp_max_memberships`).
pub const MAX_MEMBERSHIPS: usize = 20;

impl Default for Net {
    fn default() -> Self {
        Self::new(None)
    }
}

impl Net {
    /// The network with `lo`, and `eth0` when configured.
    pub const fn new(eth: Option<NetConfig>) -> Self {
        Net {
            stack: None,
            eth,
            refs: Vec::new(),
            polled_ns: 0,
            link: None,
            ring: None,
            tx_dropped: 0,
            rx_bad: 0,
            rx_looked_ns: 0,
            rx_busy: false,
            ring_notifies: false,
            ring_left: false,
            memberships: Vec::new(),
        }
    }

    /// Messages arrived at a port (the partition's doorbell): the next run looks at
    /// `eth0`'s `rx` port whenever it last did.
    pub fn messages_came(&mut self) {
        self.rx_busy = true;
    }

    /// `eth0`'s frames go through ports `rx` and `tx` (indices of the port table).
    pub fn link(&mut self, rx: usize, tx: usize) {
        self.link = Some((rx, tx));
    }

    /// `eth0`'s frames go through `ring` instead, its ports carrying the wake-ups.
    pub fn link_ring(&mut self, ring: (frame_ring::Producer, frame_ring::Consumer)) {
        self.ring = Some(ring);
    }

    /// The NIC partition is to wake kernel thread `thread` with `bits` when a frame goes
    /// into `eth0`'s empty ring, rather than send a wake-up to its `rx` port.
    pub fn wake_on_frames(&mut self, thread: u64, bits: u64) {
        if let Some((_, from)) = self.ring.as_mut() {
            from.wake_me(thread, bits);
            self.ring_notifies = true;
        }
    }

    /// Runs the stack at the host's time: `eth0`'s received frames in from the `rx`
    /// port (or ring), timers, then the frames to send out to the `tx` port (or ring).
    /// Returns whether a socket may have changed ([`Stack::poll`]).
    pub fn run(&mut self, host: &mut impl crate::syscall::Host) -> bool {
        let Some((rx, tx)) = self.link else {
            return self.stack.is_some() && self.poll(host.now_ns());
        };
        let now = host.now_ns();
        if self.ring.is_some() {
            return self.run_ring(host, now, rx, tx);
        }
        // A look at the port is a call to syssw: after every served call only while
        // frames come, else every RX_LOOK_NS.
        if self.rx_busy || now >= self.rx_looked_ns.saturating_add(RX_LOOK_NS) {
            self.rx_looked_ns = now;
            let mut frame = [0u8; netstack::MTU];
            let mut got = 0;
            while got < LIMITS.frames {
                let Ok(r) = host.port_receive(rx, &mut frame) else {
                    break;
                };
                let len = r.len.min(frame.len());
                self.stack(now).device.deliver(&frame[..len]);
                got += 1;
            }
            self.rx_busy = got > 0;
        }
        let changed = self.poll(now) || self.rx_busy;
        let mut dropped = 0;
        let stack = self.stack(now);
        while let Some(out) = stack.device.take() {
            if host.port_send(tx, &out).is_err() {
                dropped += 1;
            }
        }
        self.tx_dropped += dropped;
        changed
    }

    /// [`Net::run`] with a frame ring: a look at it costs no call to syssw, so it is
    /// looked at on every run; the `rx` port's wake-ups are drained (before the ring is
    /// read: one that comes after is left for the next run) when the doorbell rang, and
    /// the NIC partition is woken when a frame goes into an empty ring: notified as the
    /// ring names it, else through `tx`.
    fn run_ring(
        &mut self,
        host: &mut impl crate::syscall::Host,
        now: u64,
        rx: usize,
        tx: usize,
    ) -> bool {
        if core::mem::take(&mut self.rx_busy) {
            let mut kick = [0u8; 1];
            for _ in 0..LIMITS.frames {
                if host.port_receive(rx, &mut kick).is_err() {
                    break;
                }
            }
        }
        // Taking what the ring holds is the look (no call to syssw).
        self.rx_looked_ns = now;
        let mut frame = [0u8; frame_ring::MTU];
        let mut took = false;
        for _ in 0..LIMITS.frames {
            let Some((_, from)) = self.ring.as_mut() else {
                return false;
            };
            match from.pop(&mut frame) {
                None => break,
                Some(Ok(len)) => {
                    self.stack(now).device.deliver(&frame[..len]);
                    took = true;
                }
                Some(Err(_)) => self.rx_bad += 1,
            }
        }
        self.ring_left = self.ring.as_ref().is_some_and(|(_, from)| !from.is_empty());
        let changed = self.poll(now) || took;
        let (mut dropped, mut kick) = (0, false);
        let Some(stack) = self.stack.as_mut() else {
            return changed;
        };
        let Some((to, _)) = self.ring.as_mut() else {
            return changed;
        };
        while let Some(out) = stack.device.take() {
            match to.push(&out) {
                Ok(pushed) => kick |= pushed.first,
                Err(_) => dropped += 1,
            }
        }
        let notified = kick
            && to
                .waiter()
                .is_some_and(|(thread, bits)| host.notify(thread, bits));
        // A full port means wake-ups are already waiting there.
        if kick && !notified {
            let _ = host.port_send(tx, &[0]);
        }
        self.tx_dropped += dropped;
        changed
    }

    /// The stack at `now_ns` (made on first use).
    pub fn stack(&mut self, now_ns: u64) -> &mut Stack {
        let eth = self.eth;
        self.stack.get_or_insert_with(|| {
            let limits = match &self.ring {
                Some((to, from)) => Limits {
                    tcp_buffer: ring_tcp_buffer(to.slots().min(from.slots())),
                    ..LIMITS
                },
                None => LIMITS,
            };
            let config = match eth {
                Some(e) => Config {
                    mac: e.mac,
                    address: e.address,
                    prefix: e.prefix,
                    gateway: e.gateway,
                    limits,
                },
                None => Config::loopback_only(limits),
            };
            Stack::new(config, (now_ns / 1000) as i64)
        })
    }

    /// The stack if a socket was ever made.
    pub fn existing(&mut self) -> Option<&mut Stack> {
        self.stack.as_mut()
    }

    /// A new socket's first descriptor.
    pub fn opened(&mut self, id: SocketId) {
        if self.refs.len() <= id.0 {
            self.refs.resize(id.0 + 1, 0);
        }
        self.refs[id.0] = 1;
    }

    /// One more descriptor of socket `id` (`dup`, `fork`).
    pub fn share(&mut self, id: usize) {
        if let Some(r) = self.refs.get_mut(id) {
            *r += 1;
        }
    }

    /// Whether socket `id` still has a descriptor.
    pub fn is_open(&self, id: usize) -> bool {
        self.refs.get(id).is_some_and(|&r| r > 0)
    }

    /// A descriptor of socket `id` closed: the socket closes with its last, and leaves
    /// its multicast groups.
    pub fn release(&mut self, id: usize) {
        let Some(r) = self.refs.get_mut(id) else {
            return;
        };
        *r = r.saturating_sub(1);
        if *r > 0 {
            return;
        }
        while let Some(&(_, group)) = self.memberships.iter().find(|m| m.0 == id) {
            let _ = self.leave(self.polled_ns, id, group);
        }
        if let Some(stack) = self.stack.as_mut() {
            let _ = stack.close(SocketId(id));
        }
    }

    /// `IP_ADD_MEMBERSHIP`: socket `id` joins the multicast `group` on `eth0`, whose
    /// datagrams to the socket's port then reach it. `EINVAL` for an address that is no
    /// group, `ENODEV` without `eth0`, `EADDRINUSE` when the socket is in the group
    /// already, `ENOBUFS` beyond [`MAX_MEMBERSHIPS`] or the interface's table (4 groups).
    pub fn join(&mut self, now_ns: u64, id: usize, group: Ipv4Address) -> Result<(), Errno> {
        if !group.is_multicast() {
            return Err(Errno::EINVAL);
        }
        if self.eth.is_none() {
            return Err(Errno::ENODEV);
        }
        if self.memberships.contains(&(id, group)) {
            return Err(Errno::EADDRINUSE);
        }
        if self.memberships.iter().filter(|m| m.0 == id).count() >= MAX_MEMBERSHIPS {
            return Err(Errno::ENOBUFS);
        }
        if !self.memberships.iter().any(|m| m.1 == group) {
            self.stack(now_ns).join_multicast(group).map_err(errno)?;
        }
        self.memberships.push((id, group));
        Ok(())
    }

    /// `IP_DROP_MEMBERSHIP`: socket `id` leaves `group` (the interface with the last
    /// socket in it); `EADDRNOTAVAIL` when it was not in the group.
    pub fn leave(&mut self, now_ns: u64, id: usize, group: Ipv4Address) -> Result<(), Errno> {
        let Some(at) = self.memberships.iter().position(|&m| m == (id, group)) else {
            return Err(Errno::EADDRNOTAVAIL);
        };
        self.memberships.swap_remove(at);
        if !self.memberships.iter().any(|m| m.1 == group) {
            let _ = self.stack(now_ns).leave_multicast(group);
        }
        Ok(())
    }

    /// Sockets open (descriptors' sockets).
    pub fn open_count(&self) -> usize {
        self.refs.iter().filter(|&&r| r > 0).count()
    }

    /// Runs the stack at `now_ns`: frames in and out, timers. Returns whether a socket
    /// may have changed ([`Stack::poll`]).
    pub fn poll(&mut self, now_ns: u64) -> bool {
        self.polled_ns = now_ns;
        self.stack
            .as_mut()
            .is_some_and(|stack| stack.poll((now_ns / 1000) as i64))
    }

    /// The sockets (by id) the stack's runs changed since the last take
    /// ([`Stack::take_changed`]).
    pub fn take_changed(&mut self) -> Vec<usize> {
        let changed = self.stack.as_mut().map(Stack::take_changed);
        changed.into_iter().flatten().map(|id| id.0).collect()
    }

    /// When the stack must run next (the guest's clock, ns): never sooner than
    /// [`MIN_POLL_GAP_NS`] after it last ran (a stack that wants to run at once, e.g.
    /// with frames the ports have no room for yet, must not keep the guest from serving
    /// its processes).
    pub fn poll_at_ns(&mut self) -> Option<u64> {
        // The port's doorbell tells of frames ([`Net::messages_came`]); look every
        // [`RX_POLL_NS`] too, in case it could not be set. The ring's notification needs
        // no such look: the NIC partition notifies whenever the ring was empty, and
        // kicks the `rx` port (the doorbell) if the kernel refuses; frames a run left in
        // it are due at once.
        let rx = match self.ring_left {
            true => Some(0),
            false => self
                .link
                .filter(|_| !self.ring_notifies)
                .map(|_| self.rx_looked_ns + RX_POLL_NS),
        };
        let at = self.stack.as_mut().and_then(|s| s.poll_at());
        let at = at.map(|at| (at.max(0) as u64).saturating_mul(1000));
        let at = match (at, rx) {
            (Some(a), Some(r)) => Some(a.min(r)),
            (a, r) => a.or(r),
        }?;
        Some(at.max(self.polled_ns + MIN_POLL_GAP_NS))
    }

    /// `eth0`'s frames: those to send, and room for those received.
    pub fn frames(&mut self, now_ns: u64) -> Option<&mut netstack::Queues> {
        self.eth?;
        Some(&mut self.stack(now_ns).device)
    }

    /// The interfaces, `lo` first.
    pub fn interfaces(&self) -> Vec<Interface> {
        let mut out = Vec::new();
        out.push(Interface {
            name: "lo",
            index: 1,
            mac: [0; 6],
            address: Ipv4Address::new(127, 0, 0, 1),
            prefix: 8,
            flags: IFF_UP | IFF_LOOPBACK | IFF_RUNNING,
            mtu: 65536,
            counters: Counters::default(),
        });
        if let Some(e) = self.eth {
            out.push(Interface {
                name: "eth0",
                index: 2,
                mac: e.mac,
                address: e.address,
                prefix: e.prefix,
                flags: IFF_UP | IFF_BROADCAST | IFF_RUNNING | IFF_MULTICAST,
                mtu: 1500,
                counters: self
                    .stack
                    .as_ref()
                    .map_or(Counters::default(), |s| s.device.counters),
            });
        }
        out
    }

    /// `eth0`'s default route, if configured.
    pub fn gateway(&self) -> Option<Ipv4Address> {
        self.eth?.gateway
    }
}

/// `/proc/net/dev`.
pub fn proc_net_dev(interfaces: &[Interface], out: &mut impl core::fmt::Write) {
    let _ = out.write_str(
        "Inter-|   Receive                                                |  Transmit\n face |bytes    packets errs drop fifo frame compressed multicast|bytes    packets errs drop fifo colls carrier compressed\n",
    );
    for i in interfaces {
        let c = i.counters;
        let _ = writeln!(
            out,
            "{:>6}: {:>7} {:>7}    0    0    0     0          0         0 {:>8} {:>7}    0    0    0     0       0          0",
            i.name, c.rx_bytes, c.rx_frames, c.tx_bytes, c.tx_frames
        );
    }
}

/// `/proc/net/route`: `eth0`'s subnet and its default route (addresses in the host's
/// byte order, as Linux writes them).
pub fn proc_net_route(
    interfaces: &[Interface],
    gateway: Option<Ipv4Address>,
    out: &mut impl core::fmt::Write,
) {
    let hex = |ip: Ipv4Address| u32::from_le_bytes(ip.octets());
    let _ = out.write_str(
        "Iface\tDestination\tGateway \tFlags\tRefCnt\tUse\tMetric\tMask\t\tMTU\tWindow\tIRTT\n",
    );
    for i in interfaces.iter().filter(|i| i.flags & IFF_LOOPBACK == 0) {
        if let Some(g) = gateway {
            let _ = writeln!(
                out,
                "{}\t00000000\t{:08X}\t0003\t0\t0\t0\t00000000\t0\t0\t0",
                i.name,
                hex(g)
            );
        }
        let mask = i.netmask();
        let net = Ipv4Address::from_octets(
            (u32::from_be_bytes(i.address.octets()) & u32::from_be_bytes(mask.octets()))
                .to_be_bytes(),
        );
        let _ = writeln!(
            out,
            "{}\t{:08X}\t00000000\t0001\t0\t0\t0\t{:08X}\t0\t0\t0",
            i.name,
            hex(net),
            hex(mask)
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::string::String;
    use alloc::vec::Vec;

    #[test]
    fn socket_addresses_both_ways() {
        let addr = SocketAddr::new(Ipv4Address::new(127, 0, 0, 1), 8080);
        let bytes = sockaddr_bytes(addr);
        assert_eq!(&bytes[..8], &[2, 0, 0x1f, 0x90, 127, 0, 0, 1]);
        assert_eq!(parse_sockaddr(&bytes), Ok(addr));
        assert_eq!(parse_sockaddr(&bytes[..8]), Err(Errno::EINVAL));
        let mut v6 = [0u8; 28];
        v6[0] = 10;
        assert_eq!(parse_sockaddr(&v6), Err(Errno::EAFNOSUPPORT));
        assert_eq!(parse_sockaddr(&[]), Err(Errno::EINVAL));
    }

    #[test]
    fn tcp_buffers_follow_the_frame_ring() {
        // The segments of the configurations: each half is one direction's ring.
        let buffer = |segment: usize| ring_tcp_buffer(frame_ring::slots_in(segment / 2));
        assert_eq!(buffer(frame_ring::MIN_SEGMENT), 16 * 1024);
        assert_eq!(buffer(64 * 1024), 22 * 1024);
        assert_eq!(buffer(128 * 1024), 45 * 1024);
        assert_eq!(buffer(256 * 1024), 64 * 1024);
        assert_eq!(buffer(1024 * 1024), 64 * 1024);
        // Above the floor, a full window of full segments fits the ring.
        for slots in [16, 32, 44, 64] {
            assert!(ring_tcp_buffer(slots).div_ceil(SEGMENT) <= slots as usize);
        }
    }

    #[test]
    fn net_file_and_its_errors() {
        let text = "mac=52:54:00:12:34:56\naddress=10.0.2.15/24\ngateway=10.0.2.2\nrx=net_in\ntx=net_out\n";
        let f = parse_net_file(text).unwrap();
        assert_eq!(f.config.mac, [0x52, 0x54, 0, 0x12, 0x34, 0x56]);
        assert_eq!(f.config.address, Ipv4Address::new(10, 0, 2, 15));
        assert_eq!(f.config.prefix, 24);
        assert_eq!(f.config.gateway, Some(Ipv4Address::new(10, 0, 2, 2)));
        assert_eq!((f.rx, f.tx), ("net_in", "net_out"));
        assert_eq!(
            parse_net_file("mac=52:54:00:12:34\n").unwrap_err(),
            (1, "bad MAC address")
        );
        assert_eq!(
            parse_net_file("mac=52:54:00:12:34:56\naddress=10.0.2.15/33\n").unwrap_err(),
            (2, "bad prefix length")
        );
        assert_eq!(
            parse_net_file("colour=red").unwrap_err(),
            (1, "unknown key")
        );
        assert!(parse_ipv4("1.2.3").is_none() && parse_ipv4("1.2.3.4.5").is_none());
    }

    #[test]
    fn proc_files_name_the_interfaces_and_routes() {
        let net = Net::new(Some(NetConfig {
            mac: [2, 0, 0, 0, 0, 1],
            address: Ipv4Address::new(10, 0, 2, 15),
            prefix: 24,
            gateway: Some(Ipv4Address::new(10, 0, 2, 2)),
        }));
        let interfaces = net.interfaces();
        assert_eq!(interfaces[1].netmask(), Ipv4Address::new(255, 255, 255, 0));
        assert_eq!(interfaces[1].broadcast(), Ipv4Address::new(10, 0, 2, 255));
        let mut dev = String::new();
        proc_net_dev(&interfaces, &mut dev);
        assert!(dev.lines().nth(2).unwrap().starts_with("    lo:"));
        assert!(dev.lines().nth(3).unwrap().starts_with("  eth0:"));
        let mut route = String::new();
        proc_net_route(&interfaces, net.gateway(), &mut route);
        let lines: Vec<&str> = route.lines().collect();
        assert_eq!(
            lines[1],
            "eth0\t00000000\t0202000A\t0003\t0\t0\t0\t00000000\t0\t0\t0"
        );
        assert_eq!(
            lines[2],
            "eth0\t0002000A\t00000000\t0001\t0\t0\t0\t00FFFFFF\t0\t0\t0"
        );
        assert_eq!(Net::default().interfaces().len(), 1, "lo alone");
    }

    #[test]
    fn a_socket_closes_with_its_last_descriptor() {
        let mut net = Net::default();
        let stack = net.stack(0);
        let id = stack.socket(2, 1, 0).unwrap();
        net.opened(id);
        net.share(id.0);
        net.release(id.0);
        assert_eq!(net.open_count(), 1);
        assert!(net.stack(0).kind(id).is_ok(), "one descriptor left");
        net.release(id.0);
        assert_eq!(net.open_count(), 0);
        assert!(net.stack(0).kind(id).is_err(), "closed with the last");
    }
}
