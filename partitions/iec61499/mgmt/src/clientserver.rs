//! CLIENT and SERVER, 4diac's interfaces, over TCP on the partition's network interface
//! (FORTE's `ip` layer) or between partitions on one machine over a pair of ARINC 653
//! queuing ports, as [`crate::pubsub`] does for PUBLISH/SUBSCRIBE: a message is the FBDK
//! ASN.1 encoding of the data (`fbdk`).
//!
//! | type | events in | events out | data |
//! |---|---|---|---|
//! | `CLIENT_m_n` | INIT (QI, ID), REQ (QI, SD_1..SD_m) | INITO (QO, STATUS), CNF (QO, STATUS, RD_1..RD_n) | inputs QI, ID, SD_1..SD_m; outputs QO, STATUS, RD_1..RD_n |
//! | `SERVER_m_n` | INIT (QI, ID), RSP (QI, SD_1..SD_m) | INITO (QO, STATUS), IND (QO, STATUS, RD_1..RD_n) | inputs QI, ID, SD_1..SD_m; outputs QO, STATUS, RD_1..RD_n |
//!
//! m and n are 0 to [`MAX_DATA`]. As in FORTE (`CCommFB::createInterfaceSpec`) the first
//! number is the count of SD (what the FB sends), the second of RD (what it receives), on
//! both sides, so `CLIENT_m_n` talks to `SERVER_n_m`; `CLIENT_n` and `SERVER_n` are
//! `CLIENT_n_n` and `SERVER_n_n`. SD_i and RD_i are generic, typed by their first typed
//! connection or literal, as PUBLISH/SUBSCRIBE's.
//!
//! **ID** with an IP address, FORTE's `a.b.c.d:port` or `fbdk[].ip[a.b.c.d:port]`
//! ([`crate::pubsub::ip_id`]), is a TCP connection (`ProcessIo::tcp_open`, on the stack:
//! `crate::tcplink`): a client connects to the address, a server listens on the port (of
//! every address; the address part is not checked) and talks to one client at a time, as
//! FORTE's: a second client is accepted and closed at once; when its client goes the
//! server listens again and the next client starts afresh. INIT with QI answers INITO when
//! the network has: QO TRUE and STATUS `OK` once the server listens or the client is
//! connected, QO FALSE and why (`cannot connect to ...: ConnectionRefused`, `cannot listen
//! on port ...`) else. The stream carries the messages one after the other, nothing
//! between them (as FORTE's): the FB takes each whole message from it as it arrives, in
//! any pieces; a message that cannot decode gives the event with QO FALSE and STATUS `bad
//! message: ...` and drops what the stream held (it cannot be followed past it); a message
//! may be [`TCP_BUFFER`] bytes long. A client whose connection ends (the server closed it,
//! or it failed) gets, after the messages that came before the end, INITO with QO FALSE
//! and STATUS why; it is no longer initialised. A REQ before the connection is up, or an
//! RSP while the server has no client, gives CNF/IND with QO FALSE (`not initialised`, `no
//! client connected`); a send that does not fit what waits to go: `send buffer full`.
//! Without a network interface such an INIT answers `no network interface`. With
//! `raw[].ip[a.b.c.d:port]` (FORTE's raw layer, for a peer that speaks no IEC 61499
//! encoding) a client's one STRING SD goes as its bytes and what arrives between two polls
//! is one message, the bytes of the one STRING RD; a raw client must send one STRING, a
//! raw server receive one (INIT refuses other data with why), as FORTE's.
//!
//! **ID** otherwise names the two queuing ports, requests first: `'requests,responses'` (port names
//! have no comma). The client sends on its output port `requests` and receives on its
//! input port `responses`; the server receives on its input port `requests` and sends on
//! its output port `responses`; two channels of the configuration join them. Both sides
//! write the same ID when the partitions name their ports alike. An ID without a comma,
//! `'NAME'`, is short for `'NAME_req,NAME_rsp'`.
//!
//! INIT with QI opens both ports (QO TRUE, STATUS `OK`; else QO FALSE and STATUS why, e.g.
//! `no queuing output port NAME`, none opened); INIT without QI closes them (QO FALSE,
//! STATUS `OK`), as PUBLISH/SUBSCRIBE's INIT (FORTE says `TERMINATED`). REQ (client) or RSP
//! (server) with QI sends SD_1..SD_m as one message without waiting and, as FORTE, gives
//! no event when it is sent; when it is not, CNF (client) or IND (server) with QO FALSE and
//! STATUS why: `port full`, `not initialised`, `QI is FALSE`, an SD without a type the
//! encoding has, a message longer than the port's. Both are polled by their resource as a
//! SUBSCRIBE is (at least every [`crate::pubsub::POLL_NS`]): each message on the input port
//! is one CNF (client) or IND (server) with QO TRUE, STATUS `OK` and its RD values; a
//! message that does not decode as the RD types gives the event with QO FALSE and STATUS
//! `bad message: ...`, RD unchanged. As in FORTE a client does not pair responses with
//! requests: every response is one CNF. Nothing queues in the FBs: the ports' depth bounds
//! what waits, and a poll takes at most 16 messages.
//!
//! A network that answers every IND with RSP (or every CNF with REQ) should let only QO
//! TRUE through (an E_PERMIT on QO): a refused RSP's IND otherwise asks for another RSP,
//! refused again, an event loop that faults the resource (FORTE's semantics, the same
//! hazard).

use crate::pubsub::{
    DATA, ID, INIT, IpId, Layer, MAX_DATA, NetAddr, PER_POLL, QI, QO, STATUS, UNTYPED, decode,
    decode_as, decode_first, encode_as, ip_id, raw_fits, wire_type,
};
use crate::sifb::{Io, TCP_BUFFER, TcpState};
use alloc::boxed::Box;
use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
use iec61499_runtime::fb::{Context, EventSpec, Interface, VarSpec};
use iec61499_runtime::{DataType, FunctionBlock, Value};

// Events: in INIT, REQ/RSP; out INITO, CNF/IND (the variables as PUBLISH/SUBSCRIBE's).
const DATA_EVENT: usize = 1;

/// `(client, SD count, RD count)` of a type name `CLIENT_m_n`, `CLIENT_n`, `SERVER_m_n` or
/// `SERVER_n`; `None` for another name or a count over [`MAX_DATA`].
pub fn parse_name(ty: &str) -> Option<(bool, usize, usize)> {
    let (client, counts) = match ty.strip_prefix("CLIENT_") {
        Some(rest) => (true, rest),
        None => (false, ty.strip_prefix("SERVER_")?),
    };
    let count = |s: &str| {
        if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        s.parse::<usize>().ok().filter(|n| *n <= MAX_DATA)
    };
    let (sd, rd) = match counts.split_once('_') {
        Some((m, n)) => (count(m)?, count(n)?),
        None => {
            let n = count(counts)?;
            (n, n)
        }
    };
    Some((client, sd, rd))
}

/// The ports an ID names: `(requests, responses)`, or why it names none.
pub fn parse_id(id: &str) -> Result<(String, String), String> {
    let id = id.trim();
    let (requests, responses) = match id.split_once(',') {
        Some((a, b)) => (a.trim().to_string(), b.trim().to_string()),
        None => (format!("{id}_req"), format!("{id}_rsp")),
    };
    if id.is_empty() {
        return Err("no ID (requests,responses or NAME)".into());
    }
    let bad = |s: &str| s.is_empty() || s.contains(',');
    if bad(&requests) || bad(&responses) {
        return Err(format!("ID {id} is not requests,responses or NAME"));
    }
    Ok((requests, responses))
}

/// A new CLIENT or SERVER (names as [`parse_name`]), or `None` for another name.
pub fn create(ty: &str, io: &Io) -> Option<Box<dyn FunctionBlock>> {
    let (client, sd, rd) = parse_name(ty)?;
    let var = |name: String, ty| VarSpec {
        name,
        ty,
        array: None,
    };
    let event = |name: &str, with: Vec<usize>| EventSpec {
        name: name.into(),
        with,
    };
    let with_data = |fixed: Vec<usize>, n: usize| fixed.into_iter().chain(DATA..DATA + n).collect();
    let (send, receive) = if client {
        ("REQ", "CNF")
    } else {
        ("RSP", "IND")
    };
    let interface = Interface {
        event_inputs: alloc::vec![
            event("INIT", alloc::vec![QI, ID]),
            event(send, with_data(alloc::vec![QI], sd)),
        ],
        event_outputs: alloc::vec![
            event("INITO", alloc::vec![QO, STATUS]),
            event(receive, with_data(alloc::vec![QO, STATUS], rd)),
        ],
        inputs: [
            var("QI".into(), DataType::Bool),
            var("ID".into(), DataType::WString),
        ]
        .into_iter()
        .chain((1..=sd).map(|i| var(format!("SD_{i}"), UNTYPED)))
        .collect(),
        outputs: [
            var("QO".into(), DataType::Bool),
            var("STATUS".into(), DataType::WString),
        ]
        .into_iter()
        .chain((1..=rd).map(|i| var(format!("RD_{i}"), UNTYPED)))
        .collect(),
        adapters: Vec::new(),
    };
    Some(Box::new(ClientServer {
        interface,
        client,
        sd: alloc::vec![None; sd],
        rd: alloc::vec![None; rd],
        io: io.clone(),
        link: None,
    }))
}

/// The open ports: each name and message size.
#[derive(Clone)]
struct Ports {
    output: (String, usize),
    input: (String, usize),
}

/// A TCP link of the partition's network interface (`ProcessIo::tcp_open`) as the FB sees
/// it.
struct Tcp {
    link: usize,
    layer: Layer,
    /// INITO was sent (the link listens or connected).
    up: bool,
    /// A server's client of the moment: a new one starts a new stream.
    peer: Option<NetAddr>,
    /// Received bytes not yet a whole message (at most [`TCP_BUFFER`]).
    stream: Vec<u8>,
}

/// What INIT opened.
enum Link {
    Ports(Ports),
    Tcp(Tcp),
}

struct ClientServer {
    interface: Interface,
    client: bool,
    /// Each SD's and RD's type once known.
    sd: Vec<Option<DataType>>,
    rd: Vec<Option<DataType>>,
    io: Io,
    link: Option<Link>,
}

impl ClientServer {
    /// INIT: QO and STATUS, or `None` when INITO comes later (a TCP link being opened).
    fn init(&mut self, inputs: &[Value]) -> Option<(bool, String)> {
        self.close();
        if !inputs[QI].as_bool() {
            return Some((false, "OK".into()));
        }
        let id = match &inputs[ID] {
            Value::String(s) => s.as_str(),
            _ => "",
        };
        if let Some(ip) = ip_id(id) {
            let opened = ip.and_then(|IpId { layer, at }| {
                // As FORTE's raw layer: what a client sends, what a server receives.
                if self.client {
                    raw_fits(layer, &self.sd, "SD")?;
                } else {
                    raw_fits(layer, &self.rd, "RD")?;
                }
                let link = self.io.borrow_mut().io.tcp_open(at, !self.client)?;
                Ok((link, layer))
            });
            return match opened {
                Ok((link, layer)) => {
                    self.link = Some(Link::Tcp(Tcp {
                        link,
                        layer,
                        up: false,
                        peer: None,
                        stream: Vec::new(),
                    }));
                    None
                }
                Err(why) => Some((false, why)),
            };
        }
        let (requests, responses) = match parse_id(id) {
            Ok(ports) => ports,
            Err(why) => return Some((false, why)),
        };
        let (output, input) = if self.client {
            (requests, responses)
        } else {
            (responses, requests)
        };
        let io = self.io.borrow();
        let Some(output_size) = io.io.queue_size(&output, false) else {
            return Some((false, format!("no queuing output port {output}")));
        };
        let Some(input_size) = io.io.queue_size(&input, true) else {
            return Some((false, format!("no queuing input port {input}")));
        };
        drop(io);
        self.link = Some(Link::Ports(Ports {
            output: (output, output_size),
            input: (input, input_size),
        }));
        Some((true, "OK".into()))
    }

    /// Closes the TCP link, if one is open; forgets the link.
    fn close(&mut self) {
        if let Some(Link::Tcp(tcp)) = self.link.take()
            && let Ok(mut io) = self.io.try_borrow_mut()
        {
            io.io.tcp_close(tcp.link);
        }
    }

    /// Sends SD_1..SD_m: `None` when sent, else why not.
    fn send(&mut self, inputs: &[Value]) -> Option<String> {
        let (link, size, layer) = match &self.link {
            Some(Link::Ports(p)) => (None, p.output.1, Layer::Fbdk),
            Some(Link::Tcp(t)) if t.up => (Some(t.link), TCP_BUFFER, t.layer),
            _ => return Some("not initialised".into()),
        };
        if !inputs[QI].as_bool() {
            return Some("QI is FALSE".into());
        }
        let message = match encode_as(layer, &self.sd, &inputs[DATA..], size) {
            Ok(m) => m,
            Err(why) => return Some(why),
        };
        let mut io = self.io.borrow_mut();
        match (link, &self.link) {
            (Some(link), _) => io.io.tcp_send(link, &message).err(),
            (None, Some(Link::Ports(p))) => {
                (!io.io.send(&p.output.0, &message)).then(|| "port full".into())
            }
            (None, _) => Some("not initialised".into()),
        }
    }

    /// One CNF (client) or IND (server) with QO, STATUS and (when QO) the RD values.
    fn deliver(ctx: &mut Context<'_>, received: Result<Vec<Value>, String>) {
        let (qo, status) = match received {
            Ok(values) => {
                for (k, v) in values.into_iter().enumerate() {
                    ctx.set(DATA + k, v);
                }
                (true, String::from("OK"))
            }
            Err(why) => (false, format!("bad message: {why}")),
        };
        ctx.set(QO, Value::Bool(qo));
        ctx.set(STATUS, Value::String(status));
        ctx.send(DATA_EVENT);
    }

    fn poll_ports(&mut self, ports: &Ports, ctx: &mut Context<'_>) {
        let (port, size) = (&ports.input.0, ports.input.1);
        let mut buf = alloc::vec![0u8; size];
        for _ in 0..PER_POLL {
            let Some(len) = self.io.borrow_mut().io.receive(port, &mut buf) else {
                break;
            };
            Self::deliver(ctx, decode(&self.rd, &buf[..len.min(size)]));
        }
    }

    /// A TCP link: INITO once it listens or connected (or failed), then each whole message
    /// of the stream one CNF/IND; a client whose connection ended gets INITO with QO FALSE
    /// after the messages that came before the end.
    fn poll_tcp(&mut self, ctx: &mut Context<'_>) {
        let Some(Link::Tcp(mut tcp)) = self.link.take() else {
            return;
        };
        let state = self.io.borrow().io.tcp_state(tcp.link);
        if !tcp.up {
            match &state {
                TcpState::Opening => {
                    self.link = Some(Link::Tcp(tcp));
                    return;
                }
                TcpState::Down(why) => {
                    self.io.borrow_mut().io.tcp_close(tcp.link);
                    return Self::init_answer(ctx, false, why.clone());
                }
                TcpState::Listening | TcpState::Connected { .. } => {
                    tcp.up = true;
                    Self::init_answer(ctx, true, "OK".into());
                }
            }
        }
        let peer = match &state {
            TcpState::Connected { peer } => Some(*peer),
            _ => None,
        };
        if !self.client && peer != tcp.peer {
            // A server's client left or another came: what the last one left is dropped.
            tcp.stream.clear();
            tcp.peer = peer;
        }
        let mut buf = [0u8; 512];
        // Whether the link has nothing more to give now (not stopped by a full stream).
        let mut drained = false;
        while tcp.stream.len() < TCP_BUFFER {
            let room = (TCP_BUFFER - tcp.stream.len()).min(buf.len());
            let n = self
                .io
                .borrow_mut()
                .io
                .tcp_receive(tcp.link, &mut buf[..room]);
            if n == 0 {
                drained = true;
                break;
            }
            tcp.stream.extend_from_slice(&buf[..n]);
        }
        if tcp.layer == Layer::Raw && !tcp.stream.is_empty() {
            // Raw: what arrived since the last poll is one message, as FORTE's raw layer
            // takes each read of the socket.
            let bytes = core::mem::take(&mut tcp.stream);
            Self::deliver(ctx, decode_as(Layer::Raw, &self.rd, &bytes));
        }
        for _ in 0..PER_POLL {
            if tcp.layer == Layer::Raw {
                break;
            }
            match decode_first(&self.rd, &tcp.stream) {
                Ok(Some((values, used))) => {
                    tcp.stream.drain(..used);
                    Self::deliver(ctx, Ok(values));
                }
                Ok(None) if tcp.stream.len() >= TCP_BUFFER => {
                    tcp.stream.clear();
                    let why = format!("a message longer than {} bytes", TCP_BUFFER);
                    Self::deliver(ctx, Err(why));
                    break;
                }
                Ok(None) => break,
                Err(why) => {
                    // The stream cannot be followed past it: what came with it is dropped.
                    tcp.stream.clear();
                    Self::deliver(ctx, Err(why));
                    break;
                }
            }
        }
        // Down once every byte before the end was taken and every whole message in them
        // delivered (the rest of an incomplete one is dropped).
        if let TcpState::Down(why) = state
            && drained
            && (tcp.layer == Layer::Raw
                || decode_first(&self.rd, &tcp.stream).ok().flatten().is_none())
        {
            self.io.borrow_mut().io.tcp_close(tcp.link);
            return Self::init_answer(ctx, false, why);
        }
        self.link = Some(Link::Tcp(tcp));
    }

    fn init_answer(ctx: &mut Context<'_>, qo: bool, status: String) {
        ctx.set(QO, Value::Bool(qo));
        ctx.set(STATUS, Value::String(status));
        ctx.send(INIT);
    }
}

impl FunctionBlock for ClientServer {
    fn interface(&self) -> &Interface {
        &self.interface
    }

    fn event(&mut self, event: usize, inputs: &[Value], ctx: &mut Context<'_>) {
        if event == INIT {
            if let Some((qo, status)) = self.init(inputs) {
                Self::init_answer(ctx, qo, status);
            }
            return;
        }
        // Sent: the answer is the other side's message, polled.
        if let Some(why) = self.send(inputs) {
            ctx.set(QO, Value::Bool(false));
            ctx.set(STATUS, Value::String(why));
            ctx.send(DATA_EVENT);
        }
    }

    fn polls(&self) -> bool {
        self.link.is_some()
    }

    fn poll(&mut self, _inputs: &[Value], ctx: &mut Context<'_>) {
        match &self.link {
            Some(Link::Ports(ports)) => {
                let ports = ports.clone();
                self.poll_ports(&ports, ctx);
            }
            Some(Link::Tcp(_)) => self.poll_tcp(ctx),
            None => {}
        }
    }

    fn reset(&mut self) {
        self.close();
    }

    fn untyped(&self, output: bool, index: usize) -> bool {
        let types = if output { &self.rd } else { &self.sd };
        index >= DATA && types.get(index - DATA).is_some_and(Option::is_none)
    }

    fn bind_generic(&mut self, output: bool, index: usize, ty: DataType) -> bool {
        if !self.untyped(output, index) || wire_type(ty).is_none() {
            return false;
        }
        let (types, vars) = if output {
            (&mut self.rd, &mut self.interface.outputs)
        } else {
            (&mut self.sd, &mut self.interface.inputs)
        };
        types[index - DATA] = Some(ty);
        vars[index].ty = ty;
        true
    }
}

impl Drop for ClientServer {
    fn drop(&mut self) {
        self.close();
    }
}

#[cfg(test)]
mod tests;
