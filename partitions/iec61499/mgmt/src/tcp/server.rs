//! The management protocol's TCP server on the partition's own TCP/IP stack ([`netstack`]
//! on its interface of the NIC partition's switch): it listens on the configured port,
//! reassembles each connection's requests ([`super::next_request`]) and answers them with
//! [`crate::serve::serve_parts`] on the device, in [`Server::run`], which the device's
//! process calls between event chains. Nothing here waits: a connection whose request is
//! incomplete keeps its bytes until the rest comes (or [`REQUEST_TIMEOUT_NS`] passes) and
//! the event chains go on meanwhile.
//!
//! The stack also carries PUBLISH/SUBSCRIBE's UDP endpoints ([`crate::udp`]): its limits
//! leave room for their sockets, and the partition pumps them beside [`Server::run`].
//!
//! Bounds: `connections` connections at once (one more is accepted and closed at once),
//! each with a request buffer of [`MAX_REQUEST`] bytes and a response buffer of
//! [`MAX_RESPONSE`] + 3, allocated once; per [`Server::run`] at most one request of each
//! connection is served and at most [`FRAMES_PER_RUN`] frames go each way in the caller.
//! Only the bytes that complete the request at hand are read: the rest waits in the
//! connection's TCP buffer (its window closes), so a fast client waits for its answers. A
//! connection that holds an incomplete request or an unsent response and makes no progress
//! (no byte in, none out) for [`REQUEST_TIMEOUT_NS`] is closed, so a stalled client gives
//! its place back.

use super::{FrameError, MAX_REQUEST, MAX_RESPONSE, Next, next_request, push_string};
use crate::request::Reason;
use crate::serve::{Access, DeviceAccess, refusal, serve_parts};
use alloc::vec;
use alloc::vec::Vec;
use netstack::{Config, Error, Ipv4Address, Limits, SocketAddr, SocketId, Stack, linux};

/// Frames the caller takes from or gives to the link per run, each way.
pub const FRAMES_PER_RUN: usize = 32;
/// Bytes of each socket's receive and send buffer.
pub const TCP_BUFFER: usize = 4096;
/// How long a connection may hold an incomplete request or an unsent response without
/// progress before it is closed (ns).
pub const REQUEST_TIMEOUT_NS: u64 = 10_000_000_000;
/// Events kept between two [`Server::take_events`] (more are counted only).
pub const MAX_EVENTS: usize = 16;
/// The most connections at once.
pub const MAX_CONNECTIONS: usize = 8;

/// The server's interface and what it allows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Settings {
    pub mac: [u8; 6],
    pub address: [u8; 4],
    pub prefix: u8,
    pub gateway: Option<[u8; 4]>,
    /// The TCP port it listens on (4diac's is [`super::PORT`]).
    pub port: u16,
    /// Connections at once, 1..=[`MAX_CONNECTIONS`].
    pub connections: usize,
    /// What every client may do: the protocol has no identities.
    pub access: Access,
}

/// Counters the partition logs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stats {
    pub accepted: u64,
    /// Connections closed at once because `connections` were open.
    pub refused: u64,
    pub requests: u64,
    /// Connections closed for a stream that is not requests (a wrong tag, too long).
    pub malformed: u64,
    /// Connections closed for an incomplete request or unsent response without progress.
    pub timed_out: u64,
}

/// Something the partition logs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Event {
    Accepted(SocketAddr),
    /// Closed at once: all connections were in use.
    Refused(SocketAddr),
    /// Answered with a refusal and closed: the stream is not requests.
    Malformed(SocketAddr, FrameError),
    /// Closed: no progress for [`REQUEST_TIMEOUT_NS`] with `received` bytes of a request
    /// and `unsent` bytes of a response.
    TimedOut {
        peer: SocketAddr,
        received: usize,
        unsent: usize,
    },
}

/// A connection slot: its buffers (allocated once) and the connection using it.
struct Slot {
    received: Vec<u8>,
    sending: Vec<u8>,
    connection: Option<Connection>,
}

struct Connection {
    socket: SocketId,
    peer: SocketAddr,
    filled: usize,
    sent: usize,
    /// When the last byte came in or went out (ns).
    last_progress_ns: u64,
    /// The peer closed or the stream broke: close once the response is sent.
    closing: bool,
}

/// The stack, the listener and the connections.
pub struct Server {
    pub stack: Stack,
    listener: SocketId,
    access: Access,
    slots: Vec<Slot>,
    events: Vec<Event>,
    dropped: u64,
    pub stats: Stats,
}

impl Server {
    /// The stack on the interface, listening on `settings.port` of every address.
    pub fn new(settings: &Settings, now_ns: u64) -> Result<Self, Error> {
        let connections = settings.connections.clamp(1, MAX_CONNECTIONS);
        let limits = Limits {
            // The listener's backlogs (on eth0 and lo), the connections, and as many
            // closing in the background; PUBLISH/SUBSCRIBE's UDP sockets (`crate::udp`,
            // each on eth0 and lo); CLIENT/SERVER's TCP links (`crate::tcplink`).
            sockets: 4 * connections + 4 + 2 * crate::udp::SOCKETS + crate::tcplink::SOCKETS,
            tcp_buffer: TCP_BUFFER,
            // A subscriber's port holds as many datagrams as its queue until the next
            // pump takes them.
            udp_packets: crate::pubsub::UDP_DEPTH,
            udp_buffer: crate::pubsub::UDP_DEPTH * crate::pubsub::MAX_DATAGRAM,
            // The management listener asks for `connections`; a CLIENT/SERVER server for
            // its own.
            backlog: connections.max(crate::tcplink::BACKLOG),
            frames: 2 * FRAMES_PER_RUN,
        };
        let [a, b, c, d] = settings.address;
        let config = Config {
            mac: settings.mac,
            address: Ipv4Address::new(a, b, c, d),
            prefix: settings.prefix,
            gateway: settings
                .gateway
                .map(|[a, b, c, d]| Ipv4Address::new(a, b, c, d)),
            limits,
        };
        let mut stack = Stack::new(config, (now_ns / 1000) as i64);
        let listener =
            stack.socket(linux::AF_INET, linux::SOCK_STREAM | linux::SOCK_NONBLOCK, 0)?;
        stack.bind(
            listener,
            SocketAddr::new(Ipv4Address::UNSPECIFIED, settings.port),
        )?;
        stack.listen(listener, connections as i32)?;
        let slots = (0..connections)
            .map(|_| Slot {
                received: vec![0; MAX_REQUEST],
                sending: Vec::with_capacity(MAX_RESPONSE + 3),
                connection: None,
            })
            .collect();
        Ok(Server {
            stack,
            listener,
            access: settings.access,
            slots,
            events: Vec::with_capacity(MAX_EVENTS),
            dropped: 0,
            stats: Stats::default(),
        })
    }

    /// One run at `now_ns`: the frames already delivered to [`Stack::device`] in, new
    /// connections, at most one request of each connection answered on `device`, the
    /// responses out; the frames to send are then in [`Stack::device`].
    pub fn run(&mut self, now_ns: u64, device: &mut impl DeviceAccess) {
        let now_us = (now_ns / 1000) as i64;
        self.stack.poll(now_us);
        self.accept(now_ns);
        for i in 0..self.slots.len() {
            self.service(i, now_ns, device);
        }
        self.stack.poll(now_us);
    }

    /// Connections open now.
    pub fn open(&self) -> usize {
        self.slots.iter().filter(|s| s.connection.is_some()).count()
    }

    /// The events since the last call, oldest first.
    pub fn take_events(&mut self) -> impl Iterator<Item = Event> + '_ {
        self.events.drain(..)
    }

    /// Events not kept because [`MAX_EVENTS`] were waiting.
    pub fn events_dropped(&self) -> u64 {
        self.dropped
    }

    /// When the stack wants to run next (ns), if it has timers.
    pub fn poll_at_ns(&mut self) -> Option<u64> {
        self.stack
            .poll_at()
            .map(|us| (us.max(0) as u64).saturating_mul(1000))
    }

    fn log(&mut self, event: Event) {
        if self.events.len() < MAX_EVENTS {
            self.events.push(event);
        } else {
            self.dropped += 1;
        }
    }

    /// Takes the completed connections: into free slots, else closed at once.
    fn accept(&mut self, now_ns: u64) {
        // Bounded: the backlog holds at most `connections` completed connections.
        for _ in 0..=self.slots.len() {
            let Ok((socket, peer)) = self.stack.accept(self.listener) else {
                return;
            };
            let _ = self.stack.set_nonblocking(socket, true);
            let Some(slot) = self.slots.iter_mut().find(|s| s.connection.is_none()) else {
                let _ = self.stack.close(socket);
                self.stats.refused += 1;
                self.log(Event::Refused(peer));
                continue;
            };
            slot.sending.clear();
            slot.connection = Some(Connection {
                socket,
                peer,
                filled: 0,
                sent: 0,
                last_progress_ns: now_ns,
                closing: false,
            });
            self.stats.accepted += 1;
            self.log(Event::Accepted(peer));
        }
    }

    /// Sends what slot `i`'s connection has to send; reads what completes its request and
    /// answers it; closes the connection when it is done.
    fn service(&mut self, i: usize, now_ns: u64, device: &mut impl DeviceAccess) {
        self.send(i, now_ns);
        let mut event = None;
        let slot = &mut self.slots[i];
        let Some(c) = slot.connection.as_mut() else {
            return;
        };
        let unsent = slot.sending.len() - c.sent.min(slot.sending.len());
        if (c.filled > 0 || unsent > 0)
            && !c.closing
            && now_ns.saturating_sub(c.last_progress_ns) >= REQUEST_TIMEOUT_NS
        {
            c.closing = true;
            // Nothing more goes to a client that does not take it.
            slot.sending.clear();
            c.sent = 0;
            self.stats.timed_out += 1;
            event = Some(Event::TimedOut {
                peer: c.peer,
                received: c.filled,
                unsent,
            });
        }
        while !c.closing && slot.sending.is_empty() {
            let need = match next_request(&slot.received[..c.filled], MAX_REQUEST) {
                Ok(Next::Need(need)) => need.min(MAX_REQUEST),
                Ok(Next::Request {
                    destination,
                    request,
                    ..
                }) => {
                    let answer = serve_parts(
                        device,
                        &slot.received[destination],
                        &slot.received[request],
                        self.access,
                        MAX_RESPONSE,
                        now_ns as i64,
                    );
                    push_string(&mut slot.sending, answer.as_bytes());
                    c.filled = 0;
                    c.sent = 0;
                    self.stats.requests += 1;
                    break;
                }
                Err(why) => {
                    let reason = match why {
                        FrameError::Tag { .. } => Reason::BadParams,
                        FrameError::TooLong { .. } => Reason::Overflow,
                    };
                    push_string(&mut slot.sending, refusal(reason).as_bytes());
                    c.filled = 0;
                    c.sent = 0;
                    c.closing = true;
                    self.stats.malformed += 1;
                    event = Some(Event::Malformed(c.peer, why));
                    break;
                }
            };
            match self
                .stack
                .recv(c.socket, &mut slot.received[c.filled..need])
            {
                Ok((0, _)) => c.closing = true,
                Ok((n, _)) => {
                    c.filled += n;
                    c.last_progress_ns = now_ns;
                }
                Err(Error::WouldBlock) => break,
                Err(_) => c.closing = true,
            }
        }
        if let Some(event) = event {
            self.log(event);
        }
        self.send(i, now_ns);
        self.close_if_done(i);
    }

    /// Hands slot `i`'s response to its socket, as much as fits.
    fn send(&mut self, i: usize, now_ns: u64) {
        let slot = &mut self.slots[i];
        let Some(c) = slot.connection.as_mut() else {
            return;
        };
        while c.sent < slot.sending.len() {
            match self.stack.send(c.socket, &slot.sending[c.sent..], None) {
                Ok(0) | Err(Error::WouldBlock) => break,
                Ok(n) => {
                    c.sent += n;
                    c.last_progress_ns = now_ns;
                }
                Err(_) => {
                    // The peer is gone: nothing more to send or to read.
                    c.closing = true;
                    c.sent = slot.sending.len();
                }
            }
        }
        if c.sent >= slot.sending.len() {
            slot.sending.clear();
            c.sent = 0;
        }
    }

    /// Closes slot `i`'s connection if it is closing and its response is sent.
    fn close_if_done(&mut self, i: usize) {
        let slot = &mut self.slots[i];
        if let Some(c) = &slot.connection
            && c.closing
            && slot.sending.is_empty()
        {
            // The stack sends what the socket still holds, then FIN.
            let _ = self.stack.close(c.socket);
            slot.connection = None;
        }
    }
}

#[cfg(test)]
mod tests;
