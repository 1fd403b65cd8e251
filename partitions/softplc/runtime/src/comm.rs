//! The PLC's communication process: its own TCP/IP stack ([`netstack`]) on its interface
//! of the NIC partition's switch (`plc.net`), and the network services on it — the
//! Modbus/TCP server (`plc.modbus`, [`plc_modbus`]), the online protocol on TCP
//! (`plc.online_tcp`, authenticated sessions of [`plc_online::session`]) and PLC-to-PLC
//! publish/subscribe over UDP (`plc.publish`, `plc.subscribe`: the datagrams only; what
//! they carry is [`crate::pubsub`]'s). It runs below
//! every IEC task and the control process and never touches the process image or the
//! program: a complete request goes into the [`Exchange`], which the control process
//! serves between cycles ([`serve_modbus`], [`crate::online::serve_exchange`]) and whose
//! answers this process then sends. So the scan never waits for the network, and a flood
//! of connections or requests costs only this process's time.
//!
//! Limits (the network block, [`crate::package::Net`]): `connections` TCP connections at
//! once over both services (one more is accepted and closed at once), `buffer` bytes of
//! each connection's receive and send buffer, `requests_per_second` requests taken from
//! each connection (more wait in its TCP buffer, which then closes the client's window;
//! an online handshake's response counts as one), at most one request of a connection in
//! the exchange at a time (answers come in order), and at most [`EXCHANGE_SLOTS`]
//! requests served per cycle. An online client has [`HANDSHAKE_NS`] to authenticate.
//!
//! A byte stream that is not Modbus/TCP (a bad MBAP protocol id or length) closes its
//! connection ([`plc_modbus::FrameError`]); everything else gets a response or an
//! exception response. On the online port, a failed handshake gets the refusal and is
//! closed, and a record that does not open (bad length, sequence or tag) closes the
//! session; each is an [`Event`] the process logs.

use crate::package::{Modbus, Net};
use crate::scan::Areas;
use alloc::vec::Vec;
use netstack::{Config, Error, Ipv4Address, Limits, SocketAddr, SocketId, Stack, linux};
use plc_modbus::{Frame, MAX_ADU, ProcessImage, Server, Writable, respond, split_frame};
use plc_online::session::{
    self, ClientKey, HandshakeError, MAX_RECORD, MAX_RESPONSE_LEN, NONCE_LEN, NonceSource,
    RecordError, Session,
};
use plc_online::{Access, MAX_MESSAGE};
use plc_vm::located::Area;

/// Requests waiting for, or answered by, the control process at once.
pub const EXCHANGE_SLOTS: usize = 8;
/// Frames taken from or given to the link per run, each way.
pub const FRAMES_PER_RUN: usize = 32;
/// How long an online client has from its connection to a complete handshake (ns).
pub const HANDSHAKE_NS: u64 = 5_000_000_000;
/// Events kept for the log between two [`Comm::take_events`] (more are counted only).
pub const MAX_EVENTS: usize = 16;

/// Bytes of a slot: a Modbus ADU or an online message.
pub const SLOT_BYTES: usize = max(MAX_ADU, MAX_MESSAGE);
/// Bytes of a connection's receive and send buffer: a whole ADU, handshake message or
/// record.
const UNIT_BYTES: usize = max(max(MAX_ADU, MAX_RECORD), MAX_RESPONSE_LEN);

const fn max(a: usize, b: usize) -> usize {
    if a > b { a } else { b }
}

/// A slot of the exchange.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlotState {
    Free,
    /// A request for the control process.
    Request,
    /// Its response, for the communication process to send.
    Response,
}

/// Which service a request is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Service {
    /// A Modbus/TCP ADU.
    Modbus,
    /// An online-protocol message of a client authenticated with this access.
    Online(Access),
}

/// One request/response in the exchange, tagged with the connection it came from.
#[derive(Clone, Copy)]
pub struct Slot {
    pub state: SlotState,
    pub service: Service,
    /// The connection: its index and its generation (a reused index is a new connection).
    pub connection: (usize, u32),
    pub len: usize,
    pub bytes: [u8; SLOT_BYTES],
}

/// Bytes of a publish/subscribe datagram at most.
pub const MAX_DATAGRAM: usize = 512;

/// One datagram waiting in the exchange (`len` 0: none).
#[derive(Clone, Copy)]
pub struct Datagram {
    pub len: usize,
    pub bytes: [u8; MAX_DATAGRAM],
}

impl Datagram {
    const EMPTY: Datagram = Datagram {
        len: 0,
        bytes: [0; MAX_DATAGRAM],
    };
}

/// What passes between the communication and the control process (under a lock the
/// control process only ever tries: it never waits for it).
pub struct Exchange {
    pub slots: [Slot; EXCHANGE_SLOTS],
    /// The control process's latest publication, for the communication process to send.
    pub publication: Datagram,
    /// The latest datagram received on the subscription's port, not yet taken (a newer
    /// one replaces it: subscribers want the latest values).
    pub subscription: Datagram,
}

impl Exchange {
    pub const fn new() -> Self {
        Exchange {
            publication: Datagram::EMPTY,
            subscription: Datagram::EMPTY,
            slots: [Slot {
                state: SlotState::Free,
                service: Service::Modbus,
                connection: (0, 0),
                len: 0,
                bytes: [0; SLOT_BYTES],
            }; EXCHANGE_SLOTS],
        }
    }
}

impl Default for Exchange {
    fn default() -> Self {
        Self::new()
    }
}

impl ProcessImage for Areas {
    fn area(&self, area: Area) -> &[u8] {
        Areas::area(self, area)
    }

    fn area_mut(&mut self, area: Area) -> &mut [u8] {
        Areas::area_mut(self, area)
    }
}

/// The control process's part, between cycles: answers every waiting Modbus request on
/// `areas` (`running`: whether any task of the program runs; writes are refused when
/// none does), calling `wrote` with the area and bytes of each write carried out (the
/// caller puts them into the program's variables: [`crate::scan::take_written`]).
/// Returns how many it answered.
pub fn serve_modbus(
    exchange: &mut Exchange,
    modbus: &Modbus,
    running: bool,
    areas: &mut Areas,
    mut wrote: impl FnMut(Area, core::ops::Range<usize>, &Areas),
) -> usize {
    let server = Server {
        unit: modbus.unit,
        writable: Writable {
            outputs: modbus.write_outputs,
            markers: modbus.write_markers,
        },
        running,
    };
    let mut served = 0;
    for slot in exchange.slots.iter_mut() {
        if slot.state != SlotState::Request || slot.service != Service::Modbus {
            continue;
        }
        let mut out = [0u8; MAX_ADU];
        // The communication process put a whole ADU here; anything else is answered as
        // a closed connection would be (nothing sent).
        let len = match split_frame(&slot.bytes[..slot.len.min(SLOT_BYTES)]) {
            Ok(Frame::Complete { header, pdu, .. }) => {
                let len = respond(&server, header, pdu, areas, &mut out);
                // A response without the exception bit (the function code's high bit,
                // right after the MBAP header): a write was carried out.
                if len > plc_modbus::MBAP_LEN
                    && out[plc_modbus::MBAP_LEN] & 0x80 == 0
                    && let Some((area, bytes)) = plc_modbus::written(pdu)
                {
                    wrote(area, bytes, areas);
                }
                len
            }
            _ => 0,
        };
        slot.bytes[..MAX_ADU].copy_from_slice(&out);
        slot.len = len;
        slot.state = SlotState::Response;
        served += 1;
    }
    served
}

/// Counters the communication process logs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CommStats {
    pub accepted: u64,
    /// Connections closed at once because `connections` were open.
    pub refused: u64,
    /// Connections closed for a stream that is not Modbus/TCP.
    pub malformed: u64,
    pub requests: u64,
    pub responses: u64,
    /// Online handshakes refused (unknown name, wrong key, malformed, too slow).
    pub denied: u64,
    /// Online sessions ended by a record that did not open (tampered, replayed, bad
    /// length).
    pub rejected: u64,
    /// Publications sent, and datagrams received on the subscription's port.
    pub published: u64,
    pub received: u64,
}

/// Something the communication process logs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Event {
    /// An online client authenticated: the index of its key in the configuration.
    Authenticated {
        client: usize,
        access: Access,
        peer: SocketAddr,
    },
    /// An online handshake was refused (`None`: not completed in [`HANDSHAKE_NS`]).
    Denied {
        peer: SocketAddr,
        why: Option<HandshakeError>,
    },
    /// An online session's record did not open; the connection closed.
    Rejected {
        client: usize,
        peer: SocketAddr,
        why: RecordError,
    },
}

/// Where a connection is in its service's protocol.
enum Phase {
    Modbus,
    /// The CHALLENGE is sent; its RESPONSE is due by `deadline_ns`.
    Handshake {
        nonce: [u8; NONCE_LEN],
        deadline_ns: u64,
    },
    /// Authenticated: the key's index and access, and the session.
    Online {
        client: usize,
        access: Access,
        session: Session,
    },
}

/// An open connection.
struct Connection {
    socket: SocketId,
    peer: SocketAddr,
    generation: u32,
    phase: Phase,
    received: [u8; UNIT_BYTES],
    filled: usize,
    /// A request of this connection is in the exchange.
    in_flight: bool,
    /// A response not yet (wholly) taken by the socket.
    sending: [u8; UNIT_BYTES],
    to_send: usize,
    sent: usize,
    /// The earliest time (ns) its next request is taken (the rate limit).
    next_request_ns: u64,
    /// The peer closed or the stream broke: close once nothing is left to send.
    closing: bool,
}

/// How much of a connection's received bytes its next unit needs.
enum Unit {
    /// This many bytes in all (more than it has).
    Need(usize),
    /// A whole unit of this many bytes.
    Complete(usize),
}

impl Connection {
    /// The next unit of its protocol in `received`, or why the stream is broken.
    fn unit(&self) -> Result<Unit, Broken> {
        let bytes = &self.received[..self.filled];
        let whole = |len: usize| {
            if self.filled >= len {
                Unit::Complete(len)
            } else {
                Unit::Need(len)
            }
        };
        match &self.phase {
            Phase::Modbus => match split_frame(bytes) {
                Ok(Frame::Incomplete { need }) => Ok(Unit::Need(need)),
                Ok(Frame::Complete { len, .. }) => Ok(Unit::Complete(len)),
                Err(_) => Err(Broken::NotModbus),
            },
            Phase::Handshake { .. } => Ok(match session::response_len(bytes) {
                Some(len) => whole(len),
                None => Unit::Need(NONCE_LEN + 1),
            }),
            Phase::Online { .. } => match Session::record_len(bytes) {
                Ok(Some(len)) => Ok(whole(len)),
                Ok(None) => Ok(Unit::Need(2)),
                Err(e) => Err(Broken::Record(e)),
            },
        }
    }
}

/// Why a connection's stream cannot go on.
enum Broken {
    NotModbus,
    Record(RecordError),
}

/// The communication process's state: the stack, the listeners and the connections.
pub struct Comm<'k> {
    pub stack: Stack,
    modbus: Option<(Modbus, SocketId)>,
    online: Option<SocketId>,
    /// The publication's socket and destination; the subscription's socket.
    publish: Option<(SocketId, SocketAddr)>,
    subscribe: Option<SocketId>,
    keys: Vec<ClientKey<'k>>,
    nonces: NonceSource,
    connections: Vec<Option<Connection>>,
    generation: u32,
    request_gap_ns: u64,
    log: EventLog,
    pub stats: CommStats,
}

impl<'k> Comm<'k> {
    /// The stack on the configured interface, listening on the services' ports; `seed`
    /// feeds the online handshake's nonces ([`NonceSource`]).
    pub fn new(net: &Net<'k>, now_ns: u64, seed: u64) -> Result<Self, Error> {
        let connections = usize::from(net.connections);
        let listeners = usize::from(net.modbus.is_some()) + usize::from(net.online.is_some());
        let limits = Limits {
            // The listeners' backlogs (on eth0 and lo), the connections, and as many
            // closing in the background.
            sockets: 2 * listeners * connections + 2 * connections + 4,
            tcp_buffer: net.buffer as usize,
            udp_packets: 4,
            udp_buffer: 4 * MAX_DATAGRAM,
            backlog: connections,
            frames: 2 * FRAMES_PER_RUN,
        };
        let [a, b, c, d] = net.address;
        let config = Config {
            mac: net.mac,
            address: Ipv4Address::new(a, b, c, d),
            prefix: net.prefix,
            gateway: net.gateway.map(|[a, b, c, d]| Ipv4Address::new(a, b, c, d)),
            limits,
        };
        let mut stack = Stack::new(config, (now_ns / 1000) as i64);
        let modbus = match net.modbus {
            Some(m) => {
                let listener = listen(&mut stack, m.port, connections)?;
                Some((m, listener))
            }
            None => None,
        };
        let (online, keys) = match net.online {
            Some(o) => (
                Some(listen(&mut stack, o.port, connections)?),
                o.clients().collect(),
            ),
            None => (None, Vec::new()),
        };
        let pubsub = net.pubsub.unwrap_or(crate::package::PubSub {
            publish: None,
            subscribe: None,
        });
        let publish = match pubsub.publish {
            Some(([a, b, c, d], port, _)) => {
                let s = udp(&mut stack, 0)?;
                Some((s, SocketAddr::new(Ipv4Address::new(a, b, c, d), port)))
            }
            None => None,
        };
        let subscribe = match pubsub.subscribe {
            Some(sub) => {
                if let Some([a, b, c, d]) = sub.group {
                    stack.join_multicast(Ipv4Address::new(a, b, c, d))?;
                }
                Some(udp(&mut stack, sub.port)?)
            }
            None => None,
        };
        let mut slots = Vec::new();
        slots.resize_with(connections, || None);
        Ok(Comm {
            stack,
            modbus,
            online,
            publish,
            subscribe,
            nonces: NonceSource::new(&keys, seed),
            keys,
            connections: slots,
            generation: 0,
            request_gap_ns: 1_000_000_000 / u64::from(net.requests_per_second.max(1)),
            log: EventLog {
                events: Vec::with_capacity(MAX_EVENTS),
                dropped: 0,
            },
            stats: CommStats::default(),
        })
    }

    /// One run at `now_ns`: the frames already delivered to [`Stack::device`] in, new
    /// connections, requests into the exchange, its responses out, and the stack's timers;
    /// the frames to send are then in [`Stack::device`].
    pub fn run(&mut self, now_ns: u64, exchange: &mut Exchange) {
        let now_us = (now_ns / 1000) as i64;
        self.stack.poll(now_us);
        if let Some((_, listener)) = self.modbus {
            self.accept(listener, now_ns, false);
        }
        if let Some(listener) = self.online {
            self.accept(listener, now_ns, true);
        }
        self.collect_responses(exchange);
        for i in 0..self.connections.len() {
            self.service(i, now_ns, exchange);
        }
        self.datagrams(exchange);
        self.stack.poll(now_us);
    }

    /// Sends the waiting publication; takes the datagrams received for the subscription,
    /// the latest into the exchange (bounded: what the socket holds).
    fn datagrams(&mut self, exchange: &mut Exchange) {
        if let Some((socket, to)) = self.publish
            && exchange.publication.len > 0
        {
            let p = &exchange.publication;
            if self.stack.send(socket, &p.bytes[..p.len], Some(to)).is_ok() {
                self.stats.published += 1;
            }
            exchange.publication.len = 0;
        }
        if let Some(socket) = self.subscribe {
            let mut buf = [0u8; MAX_DATAGRAM];
            for _ in 0..FRAMES_PER_RUN {
                let Ok((n, _)) = self.stack.recv(socket, &mut buf) else {
                    break;
                };
                self.stats.received += 1;
                let d = &mut exchange.subscription;
                d.bytes[..n].copy_from_slice(&buf[..n]);
                d.len = n;
            }
        }
    }

    /// The events since the last call, oldest first.
    pub fn take_events(&mut self) -> impl Iterator<Item = Event> + '_ {
        self.log.events.drain(..)
    }

    /// Events not kept because [`MAX_EVENTS`] were waiting.
    pub fn events_dropped(&self) -> u64 {
        self.log.dropped
    }

    /// The name of the configured client `client` (as its key has it).
    pub fn client_name(&self, client: usize) -> &'k [u8] {
        self.keys.get(client).map_or(b"?", |k| k.name)
    }

    /// Takes the completed connections of `listener`: into free places, else closed at
    /// once. An online one gets its CHALLENGE.
    fn accept(&mut self, listener: SocketId, now_ns: u64, online: bool) {
        // Bounded: the backlog holds at most `connections` completed connections.
        for _ in 0..=self.connections.len() {
            let Ok((socket, peer)) = self.stack.accept(listener) else {
                return;
            };
            let _ = self.stack.set_nonblocking(socket, true);
            let Some(i) = self.connections.iter().position(Option::is_none) else {
                let _ = self.stack.close(socket);
                self.stats.refused += 1;
                continue;
            };
            self.generation = self.generation.wrapping_add(1);
            let mut c = Connection {
                socket,
                peer,
                generation: self.generation,
                phase: Phase::Modbus,
                received: [0; UNIT_BYTES],
                filled: 0,
                in_flight: false,
                sending: [0; UNIT_BYTES],
                to_send: 0,
                sent: 0,
                next_request_ns: 0,
                closing: false,
            };
            if online {
                let nonce = self.nonces.next(now_ns);
                c.phase = Phase::Handshake {
                    nonce,
                    deadline_ns: now_ns.saturating_add(HANDSHAKE_NS),
                };
                let challenge = session::challenge(&nonce);
                c.sending[..challenge.len()].copy_from_slice(&challenge);
                c.to_send = challenge.len();
            }
            self.connections[i] = Some(c);
            self.stats.accepted += 1;
        }
    }

    /// The control process's answers to their connections (dropped if it has gone).
    fn collect_responses(&mut self, exchange: &mut Exchange) {
        for slot in exchange.slots.iter_mut() {
            if slot.state != SlotState::Response {
                continue;
            }
            slot.state = SlotState::Free;
            let (index, generation) = slot.connection;
            let Some(Some(c)) = self.connections.get_mut(index) else {
                continue;
            };
            if c.generation != generation {
                continue;
            }
            c.in_flight = false;
            let body = &slot.bytes[..slot.len.min(SLOT_BYTES)];
            c.to_send = match &mut c.phase {
                Phase::Online { session, .. } => {
                    let mut record = [0u8; MAX_RECORD];
                    let len = session.seal(body, &mut record).unwrap_or(0);
                    c.sending[..len].copy_from_slice(&record[..len]);
                    len
                }
                _ => {
                    c.sending[..body.len()].copy_from_slice(body);
                    body.len()
                }
            };
            c.sent = 0;
            self.stats.responses += 1;
        }
    }

    /// Sends what connection `i` has to send, reads its bytes, takes a whole unit (a
    /// request into the exchange, or a handshake's response), closes it when it is done.
    fn service(&mut self, i: usize, now_ns: u64, exchange: &mut Exchange) {
        let Some(c) = self.connections[i].as_mut() else {
            return;
        };
        while c.sent < c.to_send {
            match self
                .stack
                .send(c.socket, &c.sending[c.sent..c.to_send], None)
            {
                Ok(n) => c.sent += n,
                Err(Error::WouldBlock) => break,
                Err(_) => {
                    c.closing = true;
                    c.to_send = 0;
                    break;
                }
            }
        }
        if c.sent >= c.to_send {
            c.to_send = 0;
            c.sent = 0;
        }
        if let Phase::Handshake { deadline_ns, .. } = c.phase
            && now_ns >= deadline_ns
            && !c.closing
        {
            c.closing = true;
            let peer = c.peer;
            self.stats.denied += 1;
            self.log.push(Event::Denied { peer, why: None });
            return self.close_if_done(i);
        }
        // Read only what completes the next unit: the rest stays in the socket (its
        // window closes), so a fast client waits for its answers.
        while !c.closing && !c.in_flight && c.to_send == 0 {
            let need = match c.unit() {
                Ok(Unit::Need(need)) => need.min(UNIT_BYTES),
                Ok(Unit::Complete(len)) => {
                    if now_ns < c.next_request_ns {
                        break;
                    }
                    let taken = take(
                        c,
                        i,
                        len,
                        exchange,
                        &self.keys,
                        &mut self.stats,
                        &mut self.log,
                    );
                    if taken {
                        c.received.copy_within(len..c.filled, 0);
                        c.filled -= len;
                        c.next_request_ns = now_ns.max(c.next_request_ns) + self.request_gap_ns;
                    }
                    break;
                }
                Err(broken) => {
                    c.closing = true;
                    c.filled = 0;
                    match (broken, &c.phase) {
                        (Broken::Record(why), Phase::Online { client, .. }) => {
                            let (client, peer) = (*client, c.peer);
                            self.stats.rejected += 1;
                            self.log.push(Event::Rejected { client, peer, why });
                        }
                        _ => self.stats.malformed += 1,
                    }
                    break;
                }
            };
            match self.stack.recv(c.socket, &mut c.received[c.filled..need]) {
                Ok((0, _)) => c.closing = true,
                Ok((n, _)) => c.filled += n,
                Err(Error::WouldBlock) => break,
                Err(_) => c.closing = true,
            }
        }
        self.close_if_done(i);
    }

    /// Closes connection `i` if it is closing and nothing is left to send or answer.
    fn close_if_done(&mut self, i: usize) {
        if let Some(c) = &self.connections[i]
            && c.closing
            && c.to_send == 0
            && !c.in_flight
        {
            let _ = self.stack.close(c.socket);
            self.connections[i] = None;
        }
    }

    /// Connections open now.
    pub fn open(&self) -> usize {
        self.connections.iter().flatten().count()
    }

    /// When the stack wants to run next (ns), if it has timers.
    pub fn poll_at_ns(&mut self) -> Option<u64> {
        self.stack
            .poll_at()
            .map(|us| (us.max(0) as u64).saturating_mul(1000))
    }
}

/// Takes connection `c`'s (index `i`) whole unit of `len` bytes: a request into a free
/// slot of the exchange (false when there is none: it waits, unopened), or a handshake's
/// response answered at once (the ACCEPT, or the refusal and the connection closing). A
/// record that does not open closes the connection. Returns whether the unit was consumed.
fn take(
    c: &mut Connection,
    i: usize,
    len: usize,
    exchange: &mut Exchange,
    keys: &[ClientKey<'_>],
    stats: &mut CommStats,
    log: &mut EventLog,
) -> bool {
    let peer = c.peer;
    let free = exchange
        .slots
        .iter()
        .position(|s| s.state == SlotState::Free);
    let (service, body) = match &mut c.phase {
        Phase::Handshake { nonce, .. } => {
            match session::accept(keys, nonce, &c.received[..len]) {
                Ok((client, accept, session)) => {
                    let access = keys[client].access;
                    c.sending[..accept.len()].copy_from_slice(&accept);
                    c.to_send = accept.len();
                    c.phase = Phase::Online {
                        client,
                        access,
                        session,
                    };
                    log.push(Event::Authenticated {
                        client,
                        access,
                        peer,
                    });
                }
                Err(why) => {
                    c.sending[..session::REFUSE.len()].copy_from_slice(&session::REFUSE);
                    c.to_send = session::REFUSE.len();
                    c.closing = true;
                    stats.denied += 1;
                    log.push(Event::Denied {
                        peer,
                        why: Some(why),
                    });
                }
            }
            return true;
        }
        // A record is opened only when its request has a slot: opening takes its
        // sequence number.
        _ if free.is_none() => return false,
        Phase::Modbus => (Service::Modbus, &c.received[..len]),
        Phase::Online {
            client,
            access,
            session,
        } => match session.open(&c.received[..len]) {
            Ok(body) => (Service::Online(*access), body),
            Err(why) => {
                let client = *client;
                c.closing = true;
                stats.rejected += 1;
                log.push(Event::Rejected { client, peer, why });
                return true;
            }
        },
    };
    let Some(slot) = free.and_then(|f| exchange.slots.get_mut(f)) else {
        return false;
    };
    slot.bytes[..body.len()].copy_from_slice(body);
    slot.len = body.len();
    slot.service = service;
    slot.connection = (i, c.generation);
    slot.state = SlotState::Request;
    c.in_flight = true;
    stats.requests += 1;
    true
}

/// The events kept for the log, and how many were not.
struct EventLog {
    events: Vec<Event>,
    dropped: u64,
}

impl EventLog {
    fn push(&mut self, event: Event) {
        if self.events.len() < MAX_EVENTS {
            self.events.push(event);
        } else {
            self.dropped += 1;
        }
    }
}

/// A non-blocking UDP socket on `port` of every address (0: any free port).
fn udp(stack: &mut Stack, port: u16) -> Result<SocketId, Error> {
    let s = stack.socket(linux::AF_INET, linux::SOCK_DGRAM | linux::SOCK_NONBLOCK, 0)?;
    stack.bind(s, SocketAddr::new(Ipv4Address::UNSPECIFIED, port))?;
    Ok(s)
}

/// A non-blocking listener on `port` of every address with `backlog`.
fn listen(stack: &mut Stack, port: u16, backlog: usize) -> Result<SocketId, Error> {
    let s = stack.socket(linux::AF_INET, linux::SOCK_STREAM | linux::SOCK_NONBLOCK, 0)?;
    stack.bind(s, SocketAddr::new(Ipv4Address::UNSPECIFIED, port))?;
    stack.listen(s, backlog as i32)?;
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    use plc_online::session::{CHALLENGE_LEN, read_accept, read_challenge, response};
    extern crate std;

    const PLC_IP: [u8; 4] = [10, 0, 2, 15];
    const ONLINE_PORT: u16 = 1202;
    const SECRET: &[u8] = b"engineering secret, 32 bytes....";

    fn records() -> &'static [u8] {
        static RECORDS: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
        RECORDS.get_or_init(|| {
            let clients = [
                ClientKey {
                    name: b"engineering",
                    secret: SECRET,
                    access: Access::Download,
                },
                ClientKey {
                    name: b"hmi",
                    secret: b"hmi secret of 16",
                    access: Access::Monitor,
                },
            ];
            crate::package::OnlineTcp::records(&clients)
        })
    }

    fn net(connections: u8, requests_per_second: u32) -> Net<'static> {
        Net {
            mac: [0x52, 0x54, 0, 0x12, 0x34, 0x56],
            address: PLC_IP,
            prefix: 24,
            gateway: None,
            rx: 0,
            tx: 1,
            connections,
            buffer: 1024,
            requests_per_second,
            modbus: Some(Modbus {
                port: 502,
                unit: 1,
                write_outputs: false,
                write_markers: true,
            }),
            online: crate::package::OnlineTcp::new(ONLINE_PORT, records()),
            pubsub: None,
            ring: None,
        }
    }

    /// The PLC and a client on one wire, the PLC's control process serving between runs.
    struct Wire {
        plc: Comm<'static>,
        client: Stack,
        exchange: Exchange,
        areas: Areas,
        now_ns: u64,
    }

    impl Wire {
        fn new(connections: u8, requests_per_second: u32) -> Self {
            let client = Stack::new(
                Config {
                    mac: [0x52, 0x54, 0, 0x12, 0x34, 0x99],
                    address: Ipv4Address::new(10, 0, 2, 2),
                    prefix: 24,
                    gateway: None,
                    limits: Limits::default(),
                },
                0,
            );
            let net = net(connections, requests_per_second);
            Wire {
                plc: Comm::new(&net, 0, 0).unwrap(),
                client,
                exchange: Exchange::new(),
                areas: Areas::new(),
                now_ns: 0,
            }
        }

        /// One period: frames both ways, the PLC's run, the control process's turn.
        fn step(&mut self) {
            self.now_ns += 1_000_000;
            self.client.poll((self.now_ns / 1000) as i64);
            while let Some(f) = self.client.device.take() {
                self.plc.stack.device.deliver(&f);
            }
            self.plc.run(self.now_ns, &mut self.exchange);
            let modbus = net(1, 1).modbus.unwrap();
            serve_modbus(
                &mut self.exchange,
                &modbus,
                true,
                &mut self.areas,
                |_, _, _| {},
            );
            // The online requests, answered by an echo that says the access it saw.
            for slot in self.exchange.slots.iter_mut() {
                if let (SlotState::Request, Service::Online(access)) = (slot.state, slot.service) {
                    slot.bytes[slot.len] = access.code();
                    slot.len += 1;
                    slot.state = SlotState::Response;
                }
            }
            while let Some(f) = self.plc.stack.device.take() {
                self.client.device.deliver(&f);
            }
            self.client.poll((self.now_ns / 1000) as i64);
        }

        fn connect(&mut self) -> SocketId {
            self.connect_to(502)
        }

        fn connect_to(&mut self, port: u16) -> SocketId {
            let s = self
                .client
                .socket(linux::AF_INET, linux::SOCK_STREAM | linux::SOCK_NONBLOCK, 0)
                .unwrap();
            let [a, b, c, d] = PLC_IP;
            let _ = self
                .client
                .connect(s, SocketAddr::new(Ipv4Address::new(a, b, c, d), port));
            for _ in 0..50 {
                self.step();
                if self.client.readiness(s).unwrap().writable {
                    break;
                }
            }
            s
        }

        /// Sends `bytes` and collects what comes back within `steps` periods (until the
        /// connection closes).
        fn ask(&mut self, s: SocketId, bytes: &[u8], steps: usize) -> (Vec<u8>, bool) {
            self.client.send(s, bytes, None).unwrap();
            let mut got = Vec::new();
            let mut closed = false;
            for _ in 0..steps {
                self.step();
                let mut buf = [0u8; 600];
                loop {
                    match self.client.recv(s, &mut buf) {
                        Ok((0, _)) => {
                            closed = true;
                            break;
                        }
                        Ok((n, _)) => got.extend_from_slice(&buf[..n]),
                        Err(_) => break,
                    }
                }
                if closed {
                    break;
                }
            }
            (got, closed)
        }
    }

    #[test]
    fn reads_and_writes_the_image_between_cycles() {
        let mut w = Wire::new(4, 1000);
        w.areas.input[..2].copy_from_slice(&0x1234u16.to_le_bytes());
        let s = w.connect();
        let (r, _) = w.ask(s, &[0, 7, 0, 0, 0, 6, 1, 4, 0, 0, 0, 1], 10);
        assert_eq!(r, [0, 7, 0, 0, 0, 5, 1, 4, 2, 0x12, 0x34]);
        // Holding register 0x3000 = %MW0.
        let (r, _) = w.ask(s, &[0, 8, 0, 0, 0, 6, 1, 6, 0x30, 0, 0x02, 0x58], 10);
        assert_eq!(r, [0, 8, 0, 0, 0, 6, 1, 6, 0x30, 0, 0x02, 0x58]);
        assert_eq!(w.areas.memory[..2], 600u16.to_le_bytes());
        // The outputs are not writable here: exception 2.
        let (r, _) = w.ask(s, &[0, 9, 0, 0, 0, 6, 1, 6, 0, 0, 0, 1], 10);
        assert_eq!(r, [0, 9, 0, 0, 0, 3, 1, 0x86, 2]);
        assert_eq!(w.plc.stats.requests, 3);
        assert_eq!(w.plc.stats.responses, 3);
    }

    #[test]
    fn two_requests_in_one_segment_are_answered_in_order() {
        let mut w = Wire::new(4, 1000);
        let s = w.connect();
        let mut two = [0u8; 24];
        two[..12].copy_from_slice(&[0, 1, 0, 0, 0, 6, 1, 4, 0, 0, 0, 1]);
        two[12..].copy_from_slice(&[0, 2, 0, 0, 0, 6, 1, 4, 0, 1, 0, 1]);
        let (r, _) = w.ask(s, &two, 20);
        assert_eq!(r.len(), 22);
        assert_eq!((r[1], r[12]), (1, 2));
    }

    #[test]
    fn a_stream_that_is_not_modbus_closes_its_connection() {
        let mut w = Wire::new(4, 1000);
        let s = w.connect();
        let (r, closed) = w.ask(s, &[0, 1, 0, 1, 0, 6, 1, 4, 0, 0, 0, 1], 20);
        assert!(r.is_empty() && closed);
        assert_eq!(w.plc.stats.malformed, 1);
        assert_eq!(w.plc.open(), 0);
        // An oversized length too.
        let s = w.connect();
        let (r, closed) = w.ask(s, &[0, 1, 0, 0, 1, 0, 1, 4], 20);
        assert!(r.is_empty() && closed);
        assert_eq!(w.plc.stats.malformed, 2);
    }

    #[test]
    fn connections_beyond_the_limit_are_closed_at_once() {
        let mut w = Wire::new(2, 1000);
        let a = w.connect();
        let b = w.connect();
        let c = w.connect();
        for _ in 0..10 {
            w.step();
        }
        assert_eq!(w.plc.open(), 2);
        assert!(w.plc.stats.refused >= 1);
        let mut buf = [0u8; 16];
        assert!(
            matches!(
                w.client.recv(c, &mut buf),
                Ok((0, _)) | Err(Error::ConnectionReset)
            ),
            "the third connection was closed"
        );
        let (r, _) = w.ask(a, &[0, 1, 0, 0, 0, 6, 1, 4, 0, 0, 0, 1], 10);
        assert_eq!(r.len(), 11);
        let (r, _) = w.ask(b, &[0, 1, 0, 0, 0, 6, 1, 4, 0, 0, 0, 1], 10);
        assert_eq!(r.len(), 11);
    }

    #[test]
    fn the_rate_limit_spaces_a_connections_requests() {
        // 100 requests a second: one every 10 ms, while a period here is 1 ms.
        let mut w = Wire::new(1, 100);
        let s = w.connect();
        let mut many = Vec::new();
        for t in 0..5u8 {
            many.extend_from_slice(&[0, t, 0, 0, 0, 6, 1, 4, 0, 0, 0, 1]);
        }
        let (r, _) = w.ask(s, &many, 25);
        assert_eq!(r.len(), 3 * 11, "three answers in 25 ms");
        let (r, _) = w.ask(s, &[], 30);
        assert_eq!(r.len(), 2 * 11);
    }

    #[test]
    fn an_exchange_slot_of_garbage_gets_no_answer_and_no_panic() {
        let mut exchange = Exchange::new();
        exchange.slots[0].state = SlotState::Request;
        exchange.slots[0].len = 5;
        let mut areas = Areas::new();
        let modbus = net(1, 1).modbus.unwrap();
        assert_eq!(
            serve_modbus(&mut exchange, &modbus, true, &mut areas, |_, _, _| {
                panic!("garbage wrote")
            }),
            1
        );
        assert_eq!(exchange.slots[0].state, SlotState::Response);
        assert_eq!(exchange.slots[0].len, 0);
    }

    /// An online client's connection after a handshake as `name` with `secret`: the
    /// session, or the server's answer to a refused handshake.
    fn handshake(w: &mut Wire, name: &[u8], secret: &[u8]) -> (SocketId, Result<Session, Vec<u8>>) {
        let s = w.connect_to(ONLINE_PORT);
        let (challenge, _) = w.ask(s, &[], 5);
        assert_eq!(challenge.len(), CHALLENGE_LEN);
        let server_nonce = read_challenge(&challenge).unwrap();
        let client_nonce = [0x5a; NONCE_LEN];
        let mut out = [0u8; MAX_RESPONSE_LEN];
        let n = response(name, secret, &server_nonce, &client_nonce, &mut out).unwrap();
        let (answer, _) = w.ask(s, &out[..n], 10);
        match read_accept(secret, &server_nonce, &client_nonce, &answer) {
            Ok((access, session)) => {
                assert_eq!(access, Access::Download);
                (s, Ok(session))
            }
            Err(_) => (s, Err(answer)),
        }
    }

    #[test]
    fn an_authenticated_client_gets_answers_with_its_access() {
        let mut w = Wire::new(4, 1000);
        let (s, session) = handshake(&mut w, b"engineering", SECRET);
        let mut session = session.expect("accepted");
        for body in [&b"first"[..], b"second"] {
            let mut record = [0u8; MAX_RECORD];
            let n = session.seal(body, &mut record).unwrap();
            let (answer, closed) = w.ask(s, &record[..n], 10);
            assert!(!closed);
            let mut expected = body.to_vec();
            expected.push(Access::Download.code());
            assert_eq!(session.open(&answer).unwrap(), &expected[..]);
        }
        let events: Vec<_> = w.plc.take_events().collect();
        assert!(matches!(
            events[..],
            [Event::Authenticated {
                client: 0,
                access: Access::Download,
                ..
            }]
        ));
        assert_eq!(w.plc.client_name(0), b"engineering");
        assert_eq!((w.plc.stats.requests, w.plc.stats.denied), (2, 0));
        // Modbus still answers beside it.
        let m = w.connect();
        let (r, _) = w.ask(m, &[0, 7, 0, 0, 0, 6, 1, 4, 0, 0, 0, 1], 10);
        assert_eq!(r.len(), 11);
    }

    #[test]
    fn a_wrong_key_or_an_unknown_name_gets_the_refusal_and_a_log_event() {
        let mut w = Wire::new(4, 1000);
        for (name, secret) in [
            (&b"engineering"[..], &b"a guessed secret"[..]),
            (b"nobody", SECRET),
        ] {
            let (s, session) = handshake(&mut w, name, secret);
            assert_eq!(session.unwrap_err(), session::REFUSE);
            let (_, closed) = w.ask(s, &[], 5);
            assert!(closed);
        }
        assert_eq!(w.plc.stats.denied, 2);
        assert_eq!(w.plc.stats.requests, 0);
        let events: Vec<_> = w.plc.take_events().collect();
        assert!(
            events.iter().all(|e| matches!(
                e,
                Event::Denied {
                    why: Some(HandshakeError::Refused),
                    ..
                }
            )) && events.len() == 2,
            "{events:?}"
        );
        assert_eq!(w.plc.open(), 0);
    }

    #[test]
    fn a_replayed_or_tampered_record_ends_the_session_unanswered() {
        let mut w = Wire::new(4, 1000);
        for tamper in [false, true] {
            let (s, session) = handshake(&mut w, b"engineering", SECRET);
            let mut session = session.unwrap();
            let mut record = [0u8; MAX_RECORD];
            let n = session.seal(b"read", &mut record).unwrap();
            let (answer, _) = w.ask(s, &record[..n], 10);
            assert!(session.open(&answer).is_ok());
            if tamper {
                let n = session.seal(b"force", &mut record).unwrap();
                record[11] ^= 1;
                let (answer, closed) = w.ask(s, &record[..n], 10);
                assert!(answer.is_empty() && closed);
            } else {
                // The same record again.
                let (answer, closed) = w.ask(s, &record[..n], 10);
                assert!(answer.is_empty() && closed);
            }
        }
        assert_eq!((w.plc.stats.rejected, w.plc.stats.requests), (2, 2));
        let why: Vec<_> = w
            .plc
            .take_events()
            .filter_map(|e| match e {
                Event::Rejected { why, .. } => Some(why),
                _ => None,
            })
            .collect();
        assert_eq!(
            why,
            [
                RecordError::Sequence {
                    expected: 2,
                    got: 1
                },
                RecordError::Tag
            ]
        );
    }

    #[test]
    fn a_silent_online_client_is_closed_after_the_handshake_time() {
        let mut w = Wire::new(1, 1000);
        let s = w.connect_to(ONLINE_PORT);
        let (challenge, _) = w.ask(s, &[], 5);
        assert_eq!(challenge.len(), CHALLENGE_LEN);
        w.now_ns += HANDSHAKE_NS;
        let (_, closed) = w.ask(s, &[], 5);
        assert!(closed);
        assert_eq!(w.plc.open(), 0);
        assert!(matches!(
            w.plc.take_events().last(),
            Some(Event::Denied { why: None, .. })
        ));
        // Its place is free again.
        let (_, session) = handshake(&mut w, b"engineering", SECRET);
        assert!(session.is_ok());
    }

    #[test]
    fn many_short_connections_keep_the_sockets_within_the_limit() {
        // Each refused client leaves a closed connection in TIME-WAIT for 10 s; accepting
        // the next must recycle those rather than add sockets (the partition's heap is
        // fixed).
        let mut w = Wire::new(4, 1000);
        let limit = w.plc.stack.config().limits.sockets;
        for _ in 0..200 {
            let (s, session) = handshake(&mut w, b"engineering", b"a guessed secret");
            assert!(session.is_err());
            let _ = w.ask(s, &[], 3);
            let _ = w.client.close(s);
            assert!(w.plc.stack.sockets_in_use() <= limit);
        }
        for _ in 0..200 {
            let s = w.connect();
            let _ = w.ask(s, &[0, 1, 0, 1, 0, 6, 1, 4, 0, 0, 0, 1], 3);
            let _ = w.client.close(s);
            assert!(w.plc.stack.sockets_in_use() <= limit);
        }
        assert_eq!(w.plc.stats.denied, 200);
        // And both services still answer.
        let (_, session) = handshake(&mut w, b"engineering", SECRET);
        assert!(session.is_ok());
        let m = w.connect();
        let (r, _) = w.ask(m, &[0, 7, 0, 0, 0, 6, 1, 4, 0, 0, 0, 1], 10);
        assert_eq!(r.len(), 11);
    }

    #[test]
    fn a_publication_reaches_the_subscriber_and_the_latest_datagram_wins() {
        // Unicast, and to a multicast group the subscriber joined; not to another group.
        for (to, group, arrives) in [
            ([10, 0, 0, 2], None, true),
            ([239, 0, 0, 7], Some([239, 0, 0, 7]), true),
            ([239, 0, 0, 8], Some([239, 0, 0, 7]), false),
        ] {
            publication_reaches_the_subscriber(to, group, arrives);
        }
    }

    fn publication_reaches_the_subscriber(to: [u8; 4], group: Option<[u8; 4]>, arrives: bool) {
        use crate::package::{PubSub, Subscription};
        let plc = |ip: [u8; 4], mac: u8, pubsub: PubSub<'static>| {
            let net = Net {
                address: ip,
                mac: [0x52, 0x54, 0, 0, 0, mac],
                modbus: None,
                online: None,
                pubsub: Some(pubsub),
                ..net(1, 100)
            };
            Comm::new(&net, 0, 0).unwrap()
        };
        let mut a = plc(
            [10, 0, 0, 1],
            1,
            PubSub {
                publish: Some((to, 61499, "x")),
                subscribe: None,
            },
        );
        let mut b = plc(
            [10, 0, 0, 2],
            2,
            PubSub {
                publish: None,
                subscribe: Some(Subscription {
                    port: 61499,
                    group,
                    timeout_ns: 1,
                    names: "x",
                    valid: None,
                }),
            },
        );
        let (mut xa, mut xb) = (Exchange::new(), Exchange::new());
        let mut now = 0;
        let mut run = |a: &mut Comm, b: &mut Comm, xa: &mut Exchange, xb: &mut Exchange| {
            now += 1_000_000;
            a.run(now, xa);
            while let Some(f) = a.stack.device.take() {
                b.stack.device.deliver(&f);
            }
            b.run(now, xb);
            while let Some(f) = b.stack.device.take() {
                a.stack.device.deliver(&f);
            }
        };
        // Until ARP is resolved a publication may wait in the socket; then each arrives.
        for i in 0..20u8 {
            xa.publication.bytes[0] = i;
            xa.publication.len = 1;
            run(&mut a, &mut b, &mut xa, &mut xb);
        }
        assert_eq!(xa.publication.len, 0);
        if !arrives {
            assert_eq!((b.stats.received, xb.subscription.len), (0, 0), "{to:?}");
            return;
        }
        assert!(
            a.stats.published >= 19 && b.stats.received >= 1,
            "{to:?}: {:?} {:?}",
            a.stats,
            b.stats
        );
        assert_eq!(xb.subscription.len, 1);
        assert_eq!(xb.subscription.bytes[0], 19, "the latest datagram: {to:?}");
    }
}
