//! The PLC's communication process: its own TCP/IP stack ([`netstack`]) on its interface
//! of the NIC partition's switch (`plc.net`), and the network services on it — the
//! Modbus/TCP server (`plc.modbus`, [`plc_modbus`]). It runs below every IEC task and the
//! control process and never touches the process image: a complete request goes into the
//! [`Exchange`], which the control process serves between cycles ([`serve_modbus`]) and
//! whose answers this process then sends. So the scan never waits for the network, and a
//! flood of connections or requests costs only this process's time.
//!
//! Limits (the network block, [`crate::package::Net`]): `connections` TCP connections at
//! once (one more is accepted and closed at once), `buffer` bytes of each connection's
//! receive and send buffer, `requests_per_second` requests taken from each connection
//! (more wait in its TCP buffer, which then closes the client's window), at most one
//! request of a connection in the exchange at a time (answers come in order), and at
//! most [`EXCHANGE_SLOTS`] requests served per cycle.
//!
//! A byte stream that is not Modbus/TCP (a bad MBAP protocol id or length) closes its
//! connection ([`plc_modbus::FrameError`]); everything else gets a response or an
//! exception response.

use crate::package::{Modbus, Net};
use crate::scan::Areas;
use alloc::vec::Vec;
use netstack::{Config, Error, Ipv4Address, Limits, SocketAddr, SocketId, Stack, linux};
use plc_modbus::{Frame, MAX_ADU, ProcessImage, Server, Writable, respond, split_frame};
use plc_vm::located::Area;

/// Requests waiting for, or answered by, the control process at once.
pub const EXCHANGE_SLOTS: usize = 8;
/// Frames taken from or given to the link per run, each way.
pub const FRAMES_PER_RUN: usize = 32;

/// A slot of the exchange.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlotState {
    Free,
    /// A request for the control process.
    Request,
    /// Its response, for the communication process to send.
    Response,
}

/// One request/response in the exchange, tagged with the connection it came from.
#[derive(Clone, Copy)]
pub struct Slot {
    pub state: SlotState,
    /// The connection: its index and its generation (a reused index is a new connection).
    pub connection: (usize, u32),
    pub len: usize,
    pub bytes: [u8; MAX_ADU],
}

/// What passes between the communication and the control process (under a lock the
/// control process only ever tries: it never waits for it).
pub struct Exchange {
    pub slots: [Slot; EXCHANGE_SLOTS],
}

impl Exchange {
    pub const fn new() -> Self {
        Exchange {
            slots: [Slot {
                state: SlotState::Free,
                connection: (0, 0),
                len: 0,
                bytes: [0; MAX_ADU],
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
        match area {
            Area::Input => &self.input,
            Area::Output => &self.output,
            Area::Memory => &self.memory,
        }
    }

    fn area_mut(&mut self, area: Area) -> &mut [u8] {
        match area {
            Area::Input => &mut self.input,
            Area::Output => &mut self.output,
            Area::Memory => &mut self.memory,
        }
    }
}

/// The control process's part, between cycles: answers every waiting Modbus request on
/// `areas` (`running`: whether any task of the program runs; writes are refused when
/// none does). Returns how many it answered.
pub fn serve_modbus(
    exchange: &mut Exchange,
    modbus: &Modbus,
    running: bool,
    areas: &mut Areas,
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
        if slot.state != SlotState::Request {
            continue;
        }
        let mut out = [0u8; MAX_ADU];
        // The communication process put a whole ADU here; anything else is answered as
        // a closed connection would be (nothing sent).
        let len = match split_frame(&slot.bytes[..slot.len]) {
            Ok(Frame::Complete { header, pdu, .. }) => {
                respond(&server, header, pdu, areas, &mut out)
            }
            _ => 0,
        };
        slot.bytes = out;
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
}

/// An open connection.
struct Connection {
    socket: SocketId,
    generation: u32,
    received: [u8; MAX_ADU],
    filled: usize,
    /// A request of this connection is in the exchange.
    in_flight: bool,
    /// A response not yet (wholly) taken by the socket.
    sending: [u8; MAX_ADU],
    to_send: usize,
    sent: usize,
    /// The earliest time (ns) its next request is taken (the rate limit).
    next_request_ns: u64,
    /// The peer closed or the stream broke: close once nothing is left to send.
    closing: bool,
}

/// The communication process's state: the stack, the listener and the connections.
pub struct Comm {
    pub stack: Stack,
    modbus: Option<(Modbus, SocketId)>,
    connections: Vec<Option<Connection>>,
    generation: u32,
    request_gap_ns: u64,
    pub stats: CommStats,
}

impl Comm {
    /// The stack on the configured interface, listening on the services' ports.
    pub fn new(net: &Net, now_ns: u64) -> Result<Self, Error> {
        let connections = usize::from(net.connections);
        let limits = Limits {
            // The listeners' backlog (on eth0 and lo), the connections, and as many
            // closing in the background.
            sockets: 4 * connections + 4,
            tcp_buffer: net.buffer as usize,
            udp_packets: 1,
            udp_buffer: 512,
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
        let mut slots = Vec::new();
        slots.resize_with(connections, || None);
        Ok(Comm {
            stack,
            modbus,
            connections: slots,
            generation: 0,
            request_gap_ns: 1_000_000_000 / u64::from(net.requests_per_second.max(1)),
            stats: CommStats::default(),
        })
    }

    /// One run at `now_ns`: the frames already delivered to [`Stack::device`] in, new
    /// connections, requests into the exchange, its responses out, and the stack's timers;
    /// the frames to send are then in [`Stack::device`].
    pub fn run(&mut self, now_ns: u64, exchange: &mut Exchange) {
        let now_us = (now_ns / 1000) as i64;
        self.stack.poll(now_us);
        self.accept();
        self.collect_responses(exchange);
        for i in 0..self.connections.len() {
            self.service(i, now_ns, exchange);
        }
        self.stack.poll(now_us);
    }

    /// Takes the completed connections: into free places, else closed at once.
    fn accept(&mut self) {
        let Some((_, listener)) = self.modbus else {
            return;
        };
        // Bounded: the backlog holds at most `connections` completed connections.
        for _ in 0..=self.connections.len() {
            let Ok((socket, _peer)) = self.stack.accept(listener) else {
                return;
            };
            let _ = self.stack.set_nonblocking(socket, true);
            match self.connections.iter().position(Option::is_none) {
                Some(i) => {
                    self.generation = self.generation.wrapping_add(1);
                    self.connections[i] = Some(Connection {
                        socket,
                        generation: self.generation,
                        received: [0; MAX_ADU],
                        filled: 0,
                        in_flight: false,
                        sending: [0; MAX_ADU],
                        to_send: 0,
                        sent: 0,
                        next_request_ns: 0,
                        closing: false,
                    });
                    self.stats.accepted += 1;
                }
                None => {
                    let _ = self.stack.close(socket);
                    self.stats.refused += 1;
                }
            }
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
            c.sending[..slot.len].copy_from_slice(&slot.bytes[..slot.len]);
            c.to_send = slot.len;
            c.sent = 0;
            self.stats.responses += 1;
        }
    }

    /// Sends what connection `i` has to send, reads its bytes, hands a whole request to
    /// the exchange, closes it when it is done.
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
        // Read only what completes the next request: the rest stays in the socket (its
        // window closes), so a fast client waits for its answers.
        while !c.closing && !c.in_flight && c.to_send == 0 {
            let need = match split_frame(&c.received[..c.filled]) {
                Ok(Frame::Incomplete { need }) => need,
                Ok(Frame::Complete { len, .. }) => {
                    if now_ns < c.next_request_ns {
                        break;
                    }
                    let Some(slot) = exchange
                        .slots
                        .iter_mut()
                        .find(|s| s.state == SlotState::Free)
                    else {
                        break;
                    };
                    slot.bytes[..len].copy_from_slice(&c.received[..len]);
                    slot.len = len;
                    slot.connection = (i, c.generation);
                    slot.state = SlotState::Request;
                    c.received.copy_within(len..c.filled, 0);
                    c.filled -= len;
                    c.in_flight = true;
                    c.next_request_ns = now_ns.max(c.next_request_ns) + self.request_gap_ns;
                    self.stats.requests += 1;
                    break;
                }
                Err(_) => {
                    self.stats.malformed += 1;
                    c.closing = true;
                    c.filled = 0;
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
        if c.closing && c.to_send == 0 && !c.in_flight {
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

    const PLC_IP: [u8; 4] = [10, 0, 2, 15];

    fn net(connections: u8, requests_per_second: u32) -> Net {
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
        }
    }

    /// The PLC and a client on one wire, the PLC's control process serving between runs.
    struct Wire {
        plc: Comm,
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
                plc: Comm::new(&net, 0).unwrap(),
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
            serve_modbus(&mut self.exchange, &modbus, true, &mut self.areas);
            while let Some(f) = self.plc.stack.device.take() {
                self.client.device.deliver(&f);
            }
            self.client.poll((self.now_ns / 1000) as i64);
        }

        fn connect(&mut self) -> SocketId {
            let s = self
                .client
                .socket(linux::AF_INET, linux::SOCK_STREAM | linux::SOCK_NONBLOCK, 0)
                .unwrap();
            let [a, b, c, d] = PLC_IP;
            let _ = self
                .client
                .connect(s, SocketAddr::new(Ipv4Address::new(a, b, c, d), 502));
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
        assert_eq!(serve_modbus(&mut exchange, &modbus, true, &mut areas), 1);
        assert_eq!(exchange.slots[0].state, SlotState::Response);
        assert_eq!(exchange.slots[0].len, 0);
    }
}
