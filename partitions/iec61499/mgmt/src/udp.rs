//! The UDP endpoints of PUBLISH_n/SUBSCRIBE_n with a UDP ID (`crate::pubsub`) on the
//! partition's own TCP/IP stack ([`netstack`], the interface of `iec61499.net`), as FORTE's
//! `ip` layer has them: a publisher sends each REQ's message as one datagram to its
//! address (a multicast group or a unicast address) from an ephemeral port; a subscriber
//! binds its port on every address and, for a multicast address, joins the group.
//!
//! The FBs never touch the stack: [`Endpoints`] is the table between them and it. The
//! partition's `ProcessIo` hands `udp_open`/`udp_send`/`udp_receive`/`udp_close` to it,
//! which only check and queue; [`Endpoints::pump`], which the partition program calls in
//! its network pass (between event chains, with the frames in and before the frames out),
//! creates and closes the sockets, joins the groups, sends what waits and fans what
//! arrived out to the subscribers' queues. So a device never waits for the network and the
//! stack is never borrowed twice.
//!
//! As with Linux sockets bound to `0.0.0.0:port` (FORTE's `SO_REUSEADDR` receive ports),
//! every subscriber of a port gets every datagram that reaches the port: one socket a port,
//! shared. A multicast datagram sent to a group this partition joined is also delivered to
//! its own subscribers of that port (Linux's default `IP_MULTICAST_LOOP`). A group is left
//! at the pump after its last subscriber closed (as Linux leaves when the last socket that
//! joined it closes).
//!
//! Bounds: [`MAX_ENDPOINTS`] endpoints, [`MAX_PORTS`] subscribed ports and [`MAX_GROUPS`]
//! groups (the stack's) at once, refused at `open` with the reason; [`OUT_DEPTH`] datagrams
//! waiting to be sent (a send beyond: `send queue full`); [`crate::pubsub::UDP_DEPTH`]
//! datagrams queued a subscriber (more are dropped and counted in [`UdpStats::dropped`]);
//! [`PER_PUMP`] datagrams taken from each port a pump; datagrams of at most
//! [`crate::pubsub::MAX_DATAGRAM`] bytes (longer ones arrive cut, so they do not decode).

use crate::pubsub::{MAX_DATAGRAM, NetAddr, UDP_DEPTH};
use alloc::collections::VecDeque;
use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;
use netstack::{Error, Ipv4Address, SocketAddr, SocketId, Stack, linux};

/// Publishers and subscribers at once.
pub const MAX_ENDPOINTS: usize = 32;
/// UDP ports subscribed at once (a socket each).
pub const MAX_PORTS: usize = 8;
/// Multicast groups joined at once (the stack's interface holds no more).
pub const MAX_GROUPS: usize = 4;
/// Datagrams waiting to be sent.
pub const OUT_DEPTH: usize = 16;
/// Datagrams taken from one port's socket per pump.
pub const PER_PUMP: usize = 16;
/// Errors kept between two [`Endpoints::take_errors`] (more are counted only).
pub const MAX_ERRORS: usize = 4;
/// Sockets of the stack the endpoints use at most: each port's and the sender's.
pub const SOCKETS: usize = MAX_PORTS + 1;

/// Counters the partition logs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UdpStats {
    /// Datagrams handed to the stack.
    pub sent: u64,
    /// Datagrams received on the subscribed ports.
    pub received: u64,
    /// Datagrams not queued for a subscriber whose queue was full.
    pub dropped: u64,
    /// Datagrams the stack refused to send (each also an error).
    pub send_failed: u64,
    /// Failures of the stack: a socket, a bind, a group join, a send.
    pub errors: u64,
}

struct Endpoint {
    at: NetAddr,
    /// A subscriber's datagrams; `None` for a publisher.
    queue: Option<VecDeque<Vec<u8>>>,
}

struct Port {
    port: u16,
    /// The socket once [`Endpoints::pump`] opened it.
    socket: Option<SocketId>,
    /// Opening it failed: no retry while it is subscribed.
    failed: bool,
}

/// The endpoints of one partition (see the module).
#[derive(Default)]
pub struct Endpoints {
    endpoints: Vec<Option<Endpoint>>,
    ports: Vec<Port>,
    /// Groups to join or joined, and whether the join was tried (a group no subscriber has
    /// any more is left and forgotten at the next pump).
    groups: Vec<([u8; 4], bool)>,
    sender: Option<SocketId>,
    out: VecDeque<(NetAddr, Vec<u8>)>,
    errors: Vec<String>,
    errors_dropped: u64,
    pub stats: UdpStats,
}

impl Endpoints {
    pub fn new() -> Self {
        Self::default()
    }

    /// `ProcessIo::udp_open`: a publisher to `at`, or a subscriber of `at`'s port (and
    /// group); its number, or why not.
    pub fn open(&mut self, at: NetAddr, subscribe: bool) -> Result<usize, String> {
        let free = self.endpoints.iter().position(Option::is_none);
        if free.is_none() && self.endpoints.len() >= MAX_ENDPOINTS {
            return Err(format!("too many UDP endpoints (at most {MAX_ENDPOINTS})"));
        }
        if subscribe {
            let new_group = at.is_multicast() && !self.groups.iter().any(|(g, _)| *g == at.ip);
            if new_group && self.groups.len() >= MAX_GROUPS {
                return Err(format!("too many multicast groups (at most {MAX_GROUPS})"));
            }
            if let Some(p) = self.ports.iter_mut().find(|p| p.port == at.port) {
                // A new subscriber tries a port that failed once more.
                p.failed = false;
            } else {
                if self.ports.len() >= MAX_PORTS {
                    return Err(format!(
                        "too many UDP ports subscribed (at most {MAX_PORTS})"
                    ));
                }
                self.ports.push(Port {
                    port: at.port,
                    socket: None,
                    failed: false,
                });
            }
            if new_group {
                self.groups.push((at.ip, false));
            }
        } else if at.ip == [0; 4] {
            return Err(format!("{at} is no destination"));
        }
        let endpoint = Endpoint {
            at,
            queue: subscribe.then(VecDeque::new),
        };
        Ok(match free {
            Some(i) => {
                self.endpoints[i] = Some(endpoint);
                i
            }
            None => {
                self.endpoints.push(Some(endpoint));
                self.endpoints.len() - 1
            }
        })
    }

    /// `ProcessIo::udp_send`: queues `datagram` for the next pump, or why not.
    pub fn send(&mut self, endpoint: usize, datagram: &[u8]) -> Result<(), String> {
        let to = match self.endpoints.get(endpoint) {
            Some(Some(e)) if e.queue.is_none() => e.at,
            _ => return Err("no such UDP publisher".into()),
        };
        if datagram.len() > MAX_DATAGRAM {
            return Err(format!("the datagram is longer than {MAX_DATAGRAM} bytes"));
        }
        if self.out.len() >= OUT_DEPTH {
            return Err("send queue full".into());
        }
        self.out.push_back((to, datagram.to_vec()));
        Ok(())
    }

    /// `ProcessIo::udp_receive`: the next datagram queued for subscriber `endpoint`.
    pub fn receive(&mut self, endpoint: usize, buf: &mut [u8]) -> Option<usize> {
        let queue = self.endpoints.get_mut(endpoint)?.as_mut()?.queue.as_mut()?;
        let datagram = queue.pop_front()?;
        let len = datagram.len().min(buf.len());
        buf[..len].copy_from_slice(&datagram[..len]);
        Some(len)
    }

    /// `ProcessIo::udp_close`: the endpoint is gone (its port's socket closes at the next
    /// pump when no other subscriber has the port).
    pub fn close(&mut self, endpoint: usize) {
        if let Some(slot) = self.endpoints.get_mut(endpoint) {
            *slot = None;
        }
    }

    /// Endpoints open now.
    pub fn open_count(&self) -> usize {
        self.endpoints.iter().flatten().count()
    }

    /// Whether datagrams wait to be sent.
    pub fn sending(&self) -> bool {
        !self.out.is_empty()
    }

    /// The stack's failures since the last call (sockets, binds, joins, sends), oldest
    /// first; at most [`MAX_ERRORS`], the rest counted in [`Endpoints::errors_dropped`].
    pub fn take_errors(&mut self) -> impl Iterator<Item = String> + '_ {
        self.errors.drain(..)
    }

    pub fn errors_dropped(&self) -> u64 {
        self.errors_dropped
    }

    fn error(&mut self, text: String) {
        self.stats.errors += 1;
        if self.errors.len() < MAX_ERRORS {
            self.errors.push(text);
        } else {
            self.errors_dropped += 1;
        }
    }

    /// Does on `stack` what the endpoints need: sockets for new ports (closed for ports no
    /// longer subscribed), the groups joined, the waiting datagrams sent (as many as the
    /// stack takes), the datagrams received fanned out to the subscribers. The caller
    /// polls the stack before (frames in) and after (frames out).
    pub fn pump(&mut self, stack: &mut Stack) {
        self.ports_and_groups(stack);
        self.send_waiting(stack);
        self.take_received(stack);
    }

    fn subscribed(&self, port: u16) -> bool {
        self.endpoints
            .iter()
            .flatten()
            .any(|e| e.queue.is_some() && e.at.port == port)
    }

    fn ports_and_groups(&mut self, stack: &mut Stack) {
        let mut g = 0;
        while g < self.groups.len() {
            let (group, tried) = self.groups[g];
            let member = self
                .endpoints
                .iter()
                .flatten()
                .any(|e| e.queue.is_some() && e.at.ip == group);
            if member {
                g += 1;
                continue;
            }
            self.groups.remove(g);
            let [a, b, c, d] = group;
            if tried && let Err(e) = stack.leave_multicast(Ipv4Address::new(a, b, c, d)) {
                self.error(format!("cannot leave {a}.{b}.{c}.{d}: {e:?}"));
            }
        }
        let mut i = 0;
        while i < self.ports.len() {
            if self.subscribed(self.ports[i].port) {
                i += 1;
                continue;
            }
            if let Some(socket) = self.ports.remove(i).socket {
                let _ = stack.close(socket);
            }
        }
        for i in 0..self.ports.len() {
            let p = &self.ports[i];
            if p.socket.is_some() || p.failed {
                continue;
            }
            let port = p.port;
            match bound(stack, port) {
                Ok(socket) => self.ports[i].socket = Some(socket),
                Err(e) => {
                    self.ports[i].failed = true;
                    self.error(format!("cannot receive on udp port {port}: {e:?}"));
                }
            }
        }
        for i in 0..self.groups.len() {
            let (group, tried) = self.groups[i];
            if tried {
                continue;
            }
            self.groups[i].1 = true;
            let [a, b, c, d] = group;
            if let Err(e) = stack.join_multicast(Ipv4Address::new(a, b, c, d)) {
                self.error(format!("cannot join {a}.{b}.{c}.{d}: {e:?}"));
            }
        }
    }

    fn send_waiting(&mut self, stack: &mut Stack) {
        if self.out.is_empty() {
            return;
        }
        let sender = match self.sender {
            Some(s) => s,
            None => match bound(stack, 0) {
                Ok(s) => *self.sender.insert(s),
                Err(e) => {
                    let dropped = self.out.len() as u64;
                    self.out.clear();
                    self.stats.send_failed += dropped;
                    return self.error(format!("cannot open a udp socket to send: {e:?}"));
                }
            },
        };
        while let Some((to, datagram)) = self.out.front() {
            let [a, b, c, d] = to.ip;
            let addr = SocketAddr::new(Ipv4Address::new(a, b, c, d), to.port);
            match stack.send(sender, datagram, Some(addr)) {
                // The socket's buffer is full: the rest goes at the next pump.
                Err(Error::WouldBlock) => break,
                Ok(_) => {
                    self.stats.sent += 1;
                    if to.is_multicast() && self.groups.iter().any(|(g, _)| *g == to.ip) {
                        let (to, datagram) = (*to, datagram.clone());
                        self.fan_out(to.port, Some(to.ip), &datagram);
                    }
                }
                Err(e) => {
                    self.stats.send_failed += 1;
                    let to = *to;
                    self.error(format!("cannot send to {to}: {e:?}"));
                }
            }
            self.out.pop_front();
        }
    }

    fn take_received(&mut self, stack: &mut Stack) {
        let mut buf = alloc::vec![0u8; MAX_DATAGRAM];
        for i in 0..self.ports.len() {
            let (port, Some(socket)) = (self.ports[i].port, self.ports[i].socket) else {
                continue;
            };
            for _ in 0..PER_PUMP {
                let Ok((n, _)) = stack.recv(socket, &mut buf) else {
                    break;
                };
                self.stats.received += 1;
                self.fan_out(port, None, &buf[..n]);
            }
        }
    }

    /// Queues `datagram` for every subscriber of `port` (of `group` only, for one looped
    /// back), counting the full queues.
    fn fan_out(&mut self, port: u16, group: Option<[u8; 4]>, datagram: &[u8]) {
        for e in self.endpoints.iter_mut().flatten() {
            let Some(queue) = e.queue.as_mut() else {
                continue;
            };
            if e.at.port != port || group.is_some_and(|g| g != e.at.ip) {
                continue;
            }
            if queue.len() < UDP_DEPTH {
                queue.push_back(datagram.to_vec());
            } else {
                self.stats.dropped += 1;
            }
        }
    }
}

/// A non-blocking UDP socket bound to `port` (0: an ephemeral one) of every address.
fn bound(stack: &mut Stack, port: u16) -> Result<SocketId, Error> {
    let s = stack.socket(linux::AF_INET, linux::SOCK_DGRAM | linux::SOCK_NONBLOCK, 0)?;
    if let Err(e) = stack.bind(s, SocketAddr::new(Ipv4Address::UNSPECIFIED, port)) {
        let _ = stack.close(s);
        return Err(e);
    }
    Ok(s)
}

#[cfg(test)]
mod tests;
