//! PUBLISH_n and SUBSCRIBE_n (n = 0 to [`MAX_DATA`]), 4diac's interfaces, between
//! partitions on one machine over ARINC 653 queuing ports, or over UDP as 4diac FORTE's
//! when the partition has a network interface. A message is the FBDK ASN.1 encoding of the
//! data (`fbdk`, the encoding FORTE puts on UDP), the same bytes on a port and in a
//! datagram (`encode`, `decode` below).
//!
//! | type | events in | events out | data |
//! |---|---|---|---|
//! | `PUBLISH_n` | INIT (QI, ID), REQ (QI, SD_1..SD_n) | INITO (QO, STATUS), CNF (QO, STATUS) | inputs QI, ID, SD_1..SD_n |
//! | `SUBSCRIBE_n` | INIT (QI, ID), RSP (QI) | INITO (QO, STATUS), IND (QO, STATUS, RD_1..RD_n) | outputs QO, STATUS, RD_1..RD_n |
//!
//! # ID
//!
//! - A UDP address ([`ip_id`]), FORTE's forms: `a.b.c.d:port` or `fbdk[].ip[a.b.c.d:port]`
//!   (FORTE reads an ID without `]` as `fbdk[].ip[ID]`; its `ip` layer is what these do),
//!   or `raw[].ip[a.b.c.d:port]`: FORTE's raw layer, for a peer that speaks no IEC 61499
//!   encoding, where a PUBLISH_1's one STRING SD goes as its bytes and a SUBSCRIBE_1's one
//!   STRING RD is a datagram's bytes (other data: INIT refuses with why; [`Layer`]).
//!   PUBLISH sends each REQ's message as one datagram to that address, a multicast group
//!   (224.0.0.0/4) or a unicast address; SUBSCRIBE binds the port on every address of the
//!   partition's interface and, for a multicast address, joins the group (FORTE binds
//!   `INADDR_ANY:port` and tries `IP_ADD_MEMBERSHIP` the same way), and each datagram that
//!   arrives is one IND. Datagrams of at most [`MAX_DATAGRAM`] bytes; [`UDP_DEPTH`] queued
//!   per subscriber, more dropped and counted (nothing waits: a publisher's CNF says only
//!   that the datagram is on its way). The endpoints are the partition's
//!   (`sifb::ProcessIo::udp_open` and the rest; on its stack: `crate::udp`); without a
//!   network interface INIT gives QO FALSE and STATUS `no network interface`.
//! - Any other ID names a queuing port: an output port of the publisher's partition, an
//!   input port of the subscriber's, joined by a channel of the configuration.
//!
//! # Events
//!
//! SD_i and RD_i are generic: each takes the type of its first typed connection or literal
//! (`iec61499_runtime::functions` explains how). INIT with QI opens what ID names (QO
//! TRUE, STATUS `OK`; else QO FALSE and STATUS why: no such port, a UDP address that does
//! not parse, no network interface, too many endpoints); INIT without QI closes it (QO
//! FALSE), as does a reset or the FB's deletion. REQ with QI sends SD_1..SD_n as one
//! message without waiting: CNF with QO TRUE, or QO FALSE and STATUS why (`port full`,
//! `send queue full`, a value without a type, not initialised). A subscriber is polled by
//! its resource (the partition polls at least every [`POLL_NS`] while it has one): each
//! message queued is one IND, its RD values decoded; a message that does not decode as
//! the RD types gives IND with QO FALSE and STATUS why (`bad message: ...`), RD unchanged.
//! RSP does nothing (publish/subscribe has no reply).

use crate::sifb::{Io, ProcessIo};
use alloc::boxed::Box;
use alloc::collections::VecDeque;
use alloc::format;
use alloc::rc::Rc;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
use core::cell::RefCell;
use iec61499_runtime::fb::{Context, EventSpec, Interface, VarSpec};
use iec61499_runtime::{DataType, FunctionBlock, Value};

/// The most data a PUBLISH or SUBSCRIBE (or a CLIENT or SERVER each way) carries.
pub const MAX_DATA: usize = 8;
/// The longest a subscriber's message waits to be taken, as the partition polls.
pub const POLL_NS: i64 = 10_000_000;
/// The most messages one poll takes from a port.
pub(crate) const PER_POLL: usize = 16;
/// The longest datagram a UDP PUBLISH sends or a UDP SUBSCRIBE takes (longer ones are cut,
/// so they do not decode): one Ethernet frame's UDP payload holds it unfragmented.
pub const MAX_DATAGRAM: usize = 1024;
/// The datagrams queued for one UDP subscriber at most; more are dropped and counted.
pub const UDP_DEPTH: usize = 4;

// Fixed variables of the communication FBs (here and `crate::clientserver`), before the
// data: inputs QI, ID; outputs QO, STATUS; event INIT in, INITO out.
pub(crate) const QI: usize = 0;
pub(crate) const ID: usize = 1;
pub(crate) const QO: usize = 0;
pub(crate) const STATUS: usize = 1;
pub(crate) const DATA: usize = 2;
pub(crate) const INIT: usize = 0;

/// The placeholder type of data without a type yet.
pub(crate) const UNTYPED: DataType = DataType::LWord;

/// A new PUBLISH_n or SUBSCRIBE_n, or `None` for another name.
pub fn create(ty: &str, io: &Io) -> Option<Box<dyn FunctionBlock>> {
    let (publish, n) = match ty.strip_prefix("PUBLISH_") {
        Some(n) => (true, n),
        None => (false, ty.strip_prefix("SUBSCRIBE_")?),
    };
    let n: usize = n.parse().ok().filter(|n| *n <= MAX_DATA)?;
    let var = |name: String, ty| VarSpec {
        name,
        ty,
        array: None,
    };
    let fixed_in = [
        var("QI".into(), DataType::Bool),
        var("ID".into(), DataType::WString),
    ];
    let fixed_out = [
        var("QO".into(), DataType::Bool),
        var("STATUS".into(), DataType::WString),
    ];
    let data = (1..=n).map(|i| {
        var(
            format!("{}_{i}", if publish { "SD" } else { "RD" }),
            UNTYPED,
        )
    });
    let event = |name: &str, with: Vec<usize>| EventSpec {
        name: name.into(),
        with,
    };
    let with_data = |fixed: Vec<usize>| fixed.into_iter().chain(DATA..DATA + n).collect();
    let interface = if publish {
        Interface {
            event_inputs: alloc::vec![
                event("INIT", alloc::vec![QI, ID]),
                event("REQ", with_data(alloc::vec![QI])),
            ],
            event_outputs: alloc::vec![
                event("INITO", alloc::vec![QO, STATUS]),
                event("CNF", alloc::vec![QO, STATUS]),
            ],
            inputs: fixed_in.into_iter().chain(data).collect(),
            outputs: fixed_out.into(),
            adapters: Vec::new(),
        }
    } else {
        Interface {
            event_inputs: alloc::vec![
                event("INIT", alloc::vec![QI, ID]),
                event("RSP", alloc::vec![QI]),
            ],
            event_outputs: alloc::vec![
                event("INITO", alloc::vec![QO, STATUS]),
                event("IND", with_data(alloc::vec![QO, STATUS])),
            ],
            inputs: fixed_in.into(),
            outputs: fixed_out.into_iter().chain(data).collect(),
            adapters: Vec::new(),
        }
    };
    Some(Box::new(PubSub {
        interface,
        publish,
        types: alloc::vec![None; n],
        io: io.clone(),
        link: None,
    }))
}

struct PubSub {
    interface: Interface,
    publish: bool,
    /// Each datum's type once known.
    types: Vec<Option<DataType>>,
    io: Io,
    /// What INIT opened.
    link: Option<Link>,
}

/// What a PUBLISH or SUBSCRIBE sends or receives on.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Link {
    /// A queuing port: its name and message size.
    Queue(String, usize),
    /// A UDP endpoint of the partition's network interface (`ProcessIo::udp_open`) and
    /// the layer above it.
    Udp(usize, Layer),
}

impl Link {
    /// The largest message the link carries, and how data becomes its bytes.
    fn framing(&self) -> (usize, Layer) {
        match self {
            Link::Queue(_, size) => (*size, Layer::Fbdk),
            Link::Udp(_, layer) => (MAX_DATAGRAM, *layer),
        }
    }
}

/// FORTE's layer above `ip` in an IP ID: how the data becomes the bytes of a datagram or of
/// a TCP stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layer {
    /// `fbdk[]`: the FBDK ASN.1 encoding of every SD/RD (FORTE's default).
    Fbdk,
    /// `raw[]`: the bytes of the one STRING SD (or into the one STRING RD) as they are,
    /// for a peer that speaks no IEC 61499 encoding.
    Raw,
}

/// What an IP ID says: the layer and the address.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IpId {
    pub layer: Layer,
    pub at: NetAddr,
}

/// The address of an IP ID (UDP for PUBLISH/SUBSCRIBE, TCP for CLIENT/SERVER): IPv4
/// address and port.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NetAddr {
    pub ip: [u8; 4],
    pub port: u16,
}

impl NetAddr {
    /// A multicast group (224.0.0.0/4).
    pub fn is_multicast(&self) -> bool {
        self.ip[0] & 0xF0 == 0xE0
    }
}

impl core::fmt::Display for NetAddr {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let [a, b, c, d] = self.ip;
        write!(f, "{a}.{b}.{c}.{d}:{}", self.port)
    }
}

/// Whether `id` (trimmed) selects the network (UDP for PUBLISH/SUBSCRIBE, TCP for
/// CLIENT/SERVER), its layer and its address: FORTE's layered IDs `fbdk[].ip[a.b.c.d:port]`
/// (the FBDK encoding over its `ip` layer) and `raw[].ip[a.b.c.d:port]` (the bytes of one
/// STRING as they are), or the short form `a.b.c.d:port` (FORTE reads an ID without `]` as
/// `fbdk[].ip[ID]`); `Some(Err(why))` when such an ID's address does not parse (four
/// decimal octets, a port 1..=65535); `None` for any other ID, the name of a queuing port.
pub fn ip_id(id: &str) -> Option<Result<IpId, String>> {
    let id = id.trim();
    let layered = [("fbdk[].ip[", Layer::Fbdk), ("raw[].ip[", Layer::Raw)]
        .into_iter()
        .find_map(|(prefix, layer)| Some((id.strip_prefix(prefix)?, layer)));
    let (address, layer) = match layered {
        Some((rest, layer)) => match rest.strip_suffix(']') {
            Some(address) => (address.trim(), layer),
            None => return Some(Err(format!("no ']' closing the ip layer of ID {id}"))),
        },
        None => {
            let (host, port) = id.rsplit_once(':')?;
            let shaped = host.contains('.')
                && host.bytes().all(|b| b.is_ascii_digit() || b == b'.')
                && !port.is_empty()
                && port.bytes().all(|b| b.is_ascii_digit());
            if !shaped {
                return None;
            }
            (id, Layer::Fbdk)
        }
    };
    Some(
        parse_addr(address)
            .map(|at| IpId { layer, at })
            .ok_or_else(|| {
                format!("bad IP address {address}: not a.b.c.d:port with a port 1..65535")
            }),
    )
}

fn parse_addr(text: &str) -> Option<NetAddr> {
    let (host, port) = text.rsplit_once(':')?;
    let mut ip = [0u8; 4];
    let mut octets = host.split('.');
    for octet in ip.iter_mut() {
        let part = octets.next()?;
        if part.is_empty() || part.len() > 3 || !part.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        *octet = part.parse().ok()?;
    }
    if octets.next().is_some() || port.is_empty() || !port.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let port: u16 = port.parse().ok().filter(|p| *p != 0)?;
    Some(NetAddr { ip, port })
}

/// The wire type of `ty`, if the encoding has it.
pub(crate) fn wire_type(ty: DataType) -> Option<fbdk::Type> {
    fbdk::Type::from_name(ty.name())
}

/// `v` of type `ty` as the encoding's value.
fn to_wire(ty: DataType, v: &Value) -> Option<fbdk::Value<'_>> {
    let wire = wire_type(ty)?;
    Some(match v {
        Value::String(s) => match wire {
            fbdk::Type::String => fbdk::Value::String(s.as_bytes()),
            _ => return None,
        },
        Value::Bool(b) => fbdk::Value::bool(*b),
        Value::Int(i) => fbdk::Value::Fixed(wire, *i as u64),
        Value::UInt(u) => fbdk::Value::Fixed(wire, *u),
        Value::Time(t) => fbdk::Value::Fixed(wire, *t as u64),
        Value::Real(r) if ty == DataType::Real => {
            fbdk::Value::Fixed(wire, u64::from((*r as f32).to_bits()))
        }
        Value::Real(r) => fbdk::Value::Fixed(wire, r.to_bits()),
        Value::Array(_) => return None,
    })
}

/// The encoding's value `v` as ours of type `ty`.
fn from_wire(ty: DataType, v: fbdk::Value<'_>) -> Value {
    use DataType::*;
    match v {
        fbdk::Value::String(bytes) | fbdk::Value::WString(bytes) => {
            Value::String(alloc::string::String::from_utf8_lossy(bytes).into_owned())
        }
        fbdk::Value::Fixed(_, bits) => match ty {
            Bool => Value::Bool(bits != 0),
            SInt | Int | DInt | LInt => Value::Int(bits as i64),
            Real => Value::Real(f64::from(f32::from_bits(bits as u32))),
            LReal => Value::Real(f64::from_bits(bits)),
            Time => Value::Time(bits as i64),
            _ => Value::UInt(bits),
        },
    }
}

impl PubSub {
    fn init(&mut self, inputs: &[Value]) -> (bool, String) {
        self.close();
        if !inputs[QI].as_bool() {
            return (false, "OK".into());
        }
        let id = match &inputs[ID] {
            Value::String(s) => s.trim().to_string(),
            _ => String::new(),
        };
        if let Some(ip) = ip_id(&id) {
            let opened = ip.and_then(|IpId { layer, at }| {
                if self.publish && (at.ip == [0; 4]) {
                    return Err(format!("{at} is no destination"));
                }
                let side = if self.publish { "SD" } else { "RD" };
                raw_fits(layer, &self.types, side)?;
                let endpoint = self.io.borrow_mut().io.udp_open(at, !self.publish)?;
                Ok((endpoint, layer))
            });
            return match opened {
                Ok((endpoint, layer)) => {
                    self.link = Some(Link::Udp(endpoint, layer));
                    (true, "OK".into())
                }
                Err(why) => (false, why),
            };
        }
        let (what, input) = if self.publish {
            ("output", false)
        } else {
            ("input", true)
        };
        match self.io.borrow().io.queue_size(&id, input) {
            Some(size) => {
                self.link = Some(Link::Queue(id, size));
                (true, "OK".into())
            }
            None => (false, format!("no queuing {what} port {id}")),
        }
    }

    /// Closes the UDP endpoint, if one is open; forgets the link.
    fn close(&mut self) {
        if let Some(Link::Udp(endpoint, _)) = self.link.take()
            && let Ok(mut io) = self.io.try_borrow_mut()
        {
            io.io.udp_close(endpoint);
        }
    }

    fn publish(&mut self, inputs: &[Value]) -> (bool, String) {
        let Some(link) = self.link.clone().filter(|_| inputs[QI].as_bool()) else {
            return (false, "not initialised".into());
        };
        let (size, layer) = link.framing();
        let message = match encode_as(layer, &self.types, &inputs[DATA..], size) {
            Ok(m) => m,
            Err(why) => return (false, why),
        };
        let mut io = self.io.borrow_mut();
        match link {
            Link::Queue(port, _) if io.io.send(&port, &message) => (true, "OK".into()),
            Link::Queue(..) => (false, "port full".into()),
            Link::Udp(endpoint, _) => match io.io.udp_send(endpoint, &message) {
                Ok(()) => (true, "OK".into()),
                Err(why) => (false, why),
            },
        }
    }

    /// Decodes a message into the RD outputs.
    fn take(&self, layer: Layer, message: &[u8], ctx: &mut Context<'_>) -> Result<(), String> {
        for (k, v) in decode_as(layer, &self.types, message)?
            .into_iter()
            .enumerate()
        {
            ctx.set(DATA + k, v);
        }
        Ok(())
    }
}

/// The message carrying `values` (SD_1.., typed `types`) in at most `size` bytes: the FBDK
/// encoding of each value in turn, or a NULL when there are none; else why not.
pub(crate) fn encode(
    types: &[Option<DataType>],
    values: &[Value],
    size: usize,
) -> Result<Vec<u8>, String> {
    let mut buf = alloc::vec![0u8; size];
    let mut w = fbdk::Writer::new(&mut buf);
    if types.is_empty() {
        w.null()
            .map_err(|_| "port messages too small".to_string())?;
    } else {
        for (k, ty) in types.iter().enumerate() {
            let value = ty
                .zip(values.get(k))
                .and_then(|(ty, v)| to_wire(ty, v))
                .ok_or_else(|| format!("SD_{} has no type the encoding has", k + 1))?;
            w.value(&value)
                .map_err(|_| format!("the message is longer than {size} bytes"))?;
        }
    }
    let len = w.len();
    buf.truncate(len);
    Ok(buf)
}

/// The values RD_1.. (typed `types`) that `message` carries, or why it does not decode.
pub(crate) fn decode(types: &[Option<DataType>], message: &[u8]) -> Result<Vec<Value>, String> {
    if types.is_empty() {
        return if message == [fbdk::NULL] {
            Ok(Vec::new())
        } else {
            Err("not an empty message".into())
        };
    }
    let mut r = fbdk::Reader::new(message);
    let values = read_values(types, &mut r).map_err(|(_, why)| why)?;
    r.finish().map_err(|e| format!("{e:?}"))?;
    Ok(values)
}

/// The values of `types` from `r`, or whether the bytes ended inside one and why not.
fn read_values(
    types: &[Option<DataType>],
    r: &mut fbdk::Reader<'_>,
) -> Result<Vec<Value>, (bool, String)> {
    let mut values = Vec::new();
    for (k, ty) in types.iter().enumerate() {
        let ty = ty.ok_or_else(|| (false, format!("RD_{} has no type", k + 1)))?;
        let wire =
            wire_type(ty).ok_or_else(|| (false, format!("RD_{} is not encodable", k + 1)))?;
        let v = r.value(wire).map_err(|e| {
            let truncated = matches!(e, fbdk::DecodeError::Truncated { .. });
            (truncated, format!("RD_{}: {e:?}", k + 1))
        })?;
        values.push(from_wire(ty, v));
    }
    Ok(values)
}

/// The first message of a stream of messages (a TCP connection's, FORTE sends them one
/// after the other): its values and its length, or `None` when `stream` ends inside it
/// (more bytes are needed); an error when it cannot be one (a wrong tag, a value out of
/// range). With no types a message is one NULL.
pub(crate) fn decode_first(
    types: &[Option<DataType>],
    stream: &[u8],
) -> Result<Option<(Vec<Value>, usize)>, String> {
    if types.is_empty() {
        return match stream.first() {
            None => Ok(None),
            Some(&fbdk::NULL) => Ok(Some((Vec::new(), 1))),
            Some(_) => Err("not an empty message".into()),
        };
    }
    let mut r = fbdk::Reader::new(stream);
    match read_values(types, &mut r) {
        Ok(values) => Ok(Some((values, r.position()))),
        Err((true, _)) => Ok(None),
        Err((false, why)) => Err(why),
    }
}

/// Whether data typed `types` (the SDs or RDs, `side`) can go over `layer`: the raw layer
/// carries exactly one STRING.
pub(crate) fn raw_fits(layer: Layer, types: &[Option<DataType>], side: &str) -> Result<(), String> {
    if layer == Layer::Raw && types != [Some(DataType::String)] {
        return Err(format!(
            "the raw layer carries one STRING: {side}_1 only, a STRING"
        ));
    }
    Ok(())
}

/// The message of `values` for `layer`: [`encode`], or the one STRING's bytes as they are.
pub(crate) fn encode_as(
    layer: Layer,
    types: &[Option<DataType>],
    values: &[Value],
    size: usize,
) -> Result<Vec<u8>, String> {
    match (layer, values) {
        (Layer::Fbdk, _) => encode(types, values, size),
        (Layer::Raw, [Value::String(s), ..]) if s.len() <= size => Ok(s.as_bytes().to_vec()),
        (Layer::Raw, [Value::String(_), ..]) => {
            Err(format!("the message is longer than {size} bytes"))
        }
        (Layer::Raw, _) => Err("the raw layer carries one STRING".into()),
    }
}

/// The values `message` carries for `layer`: [`decode`], or its bytes as the one STRING
/// (bytes that are not UTF-8 replaced, as the FBDK decoding does; without RDs, none, as
/// FORTE's raw layer drops them).
pub(crate) fn decode_as(
    layer: Layer,
    types: &[Option<DataType>],
    message: &[u8],
) -> Result<Vec<Value>, String> {
    match (layer, types) {
        (Layer::Fbdk, _) => decode(types, message),
        (Layer::Raw, []) => Ok(Vec::new()),
        (Layer::Raw, [Some(DataType::String)]) => Ok(alloc::vec![Value::String(
            String::from_utf8_lossy(message).into_owned()
        )]),
        (Layer::Raw, _) => Err("the raw layer carries one STRING: RD_1 only, a STRING".into()),
    }
}

impl FunctionBlock for PubSub {
    fn interface(&self) -> &Interface {
        &self.interface
    }

    fn event(&mut self, event: usize, inputs: &[Value], ctx: &mut Context<'_>) {
        let (qo, status) = match (event, self.publish) {
            (INIT, _) => self.init(inputs),
            (_, true) => self.publish(inputs),
            // RSP: nothing to answer.
            (_, false) => return,
        };
        ctx.set(QO, Value::Bool(qo));
        ctx.set(STATUS, Value::String(status));
        ctx.send(event);
    }

    fn polls(&self) -> bool {
        !self.publish && self.link.is_some()
    }

    fn poll(&mut self, _inputs: &[Value], ctx: &mut Context<'_>) {
        let Some(link) = self.link.clone() else {
            return;
        };
        let (size, layer) = link.framing();
        let mut buf = alloc::vec![0u8; size];
        for _ in 0..PER_POLL {
            let received = {
                let mut io = self.io.borrow_mut();
                match &link {
                    Link::Queue(port, _) => io.io.receive(port, &mut buf),
                    Link::Udp(endpoint, _) => io.io.udp_receive(*endpoint, &mut buf),
                }
            };
            let Some(len) = received else {
                break;
            };
            let (qo, status) = match self.take(layer, &buf[..len.min(size)], ctx) {
                Ok(()) => (true, String::from("OK")),
                Err(why) => (false, format!("bad message: {why}")),
            };
            ctx.set(QO, Value::Bool(qo));
            ctx.set(STATUS, Value::String(status));
            ctx.send(1);
        }
    }

    fn reset(&mut self) {
        self.close();
    }

    fn untyped(&self, output: bool, index: usize) -> bool {
        output != self.publish
            && index >= DATA
            && self.types.get(index - DATA).is_some_and(Option::is_none)
    }

    fn bind_generic(&mut self, output: bool, index: usize, ty: DataType) -> bool {
        if !self.untyped(output, index) || wire_type(ty).is_none() {
            return false;
        }
        self.types[index - DATA] = Some(ty);
        let var = if output {
            &mut self.interface.outputs[index]
        } else {
            &mut self.interface.inputs[index]
        };
        var.ty = ty;
        true
    }
}

impl Drop for PubSub {
    fn drop(&mut self) {
        self.close();
    }
}

/// Ports on the host, by name, for running devices that publish and subscribe without
/// partitions (tests, FORTE's multi-device system tests): a message sent on `NAME` reaches
/// every subscriber that opened `NAME`, as UDP multicast does (a channel of the
/// configuration has one). Each subscriber's queue holds [`Loopback::DEPTH`] messages of up
/// to [`Loopback::SIZE`] bytes, a send that finds one full is refused; no sampling ports.
/// Clones share the ports and are one subscriber; [`Loopback::end`] is another.
///
/// It is also a simulated UDP network for UDP IDs ([`ip_id`]), as the partition's
/// interface is (`crate::udp`): a datagram to a multicast group reaches every subscriber
/// (of any end, the sender's too, as Linux loops multicast back by default) of that group
/// and port; one to a unicast address the subscribers of that port on the ends with that
/// address ([`Loopback::end_at`]; an end without one takes unicast to every address).
/// Each subscriber queues [`UDP_DEPTH`] datagrams, more are dropped and counted
/// ([`Loopback::udp_dropped`]), and the send succeeds, as UDP's does.
#[derive(Clone, Default)]
pub struct Loopback {
    bus: Rc<RefCell<Bus>>,
    /// Which subscriber this end is.
    end: usize,
    /// The ports that exist; every name when empty.
    ports: Vec<String>,
}

#[derive(Default)]
struct Bus {
    ends: usize,
    /// `(end, port, queue)` of every opened input port.
    queues: Vec<(usize, String, VecDeque<Vec<u8>>)>,
    /// Each end's UDP address, if it has one.
    addresses: Vec<(usize, [u8; 4])>,
    /// The UDP endpoints by number.
    udp: Vec<Option<UdpEnd>>,
    udp_dropped: u64,
}

/// A UDP endpoint of end `end`: a publisher to `at` (no queue) or a subscriber of it.
struct UdpEnd {
    end: usize,
    at: NetAddr,
    queue: Option<VecDeque<Vec<u8>>>,
}

impl Loopback {
    pub const DEPTH: usize = 4;
    pub const SIZE: usize = 256;

    /// A loopback with only the ports `names`.
    pub fn with_ports(names: &[&str]) -> Self {
        Loopback {
            ports: names.iter().map(|n| String::from(*n)).collect(),
            ..Loopback::default()
        }
    }

    /// Another subscriber on the same ports (another device).
    pub fn end(&self) -> Self {
        let mut bus = self.bus.borrow_mut();
        bus.ends += 1;
        Loopback {
            bus: self.bus.clone(),
            end: bus.ends,
            ports: self.ports.clone(),
        }
    }

    /// Another end (another device) whose UDP address is `ip`.
    pub fn end_at(&self, ip: [u8; 4]) -> Self {
        let end = self.end();
        end.bus.borrow_mut().addresses.push((end.end, ip));
        end
    }

    /// UDP datagrams dropped because a subscriber's queue was full.
    pub fn udp_dropped(&self) -> u64 {
        self.bus.borrow().udp_dropped
    }

    /// Sends `datagram` to `to` as from another machine (tests: what arrives off the net).
    pub fn udp_inject(&self, to: NetAddr, datagram: &[u8]) {
        self.bus.borrow_mut().deliver(to, datagram);
    }

    fn has(&self, port: &str) -> bool {
        self.ports.is_empty() || self.ports.iter().any(|p| p == port)
    }
}

impl Bus {
    fn deliver(&mut self, to: NetAddr, datagram: &[u8]) {
        let Bus {
            addresses,
            udp,
            udp_dropped,
            ..
        } = self;
        for e in udp.iter_mut().flatten() {
            let reaches = e.at.port == to.port
                && if to.is_multicast() {
                    e.at.ip == to.ip
                } else {
                    addresses
                        .iter()
                        .find(|(end, _)| *end == e.end)
                        .is_none_or(|(_, ip)| *ip == to.ip)
                };
            match e.queue.as_mut() {
                Some(q) if reaches && q.len() < UDP_DEPTH => q.push_back(datagram.to_vec()),
                Some(_) if reaches => *udp_dropped += 1,
                _ => {}
            }
        }
    }
}

impl ProcessIo for Loopback {
    fn queue_size(&self, port: &str, input: bool) -> Option<usize> {
        if !self.has(port) {
            return None;
        }
        let mut bus = self.bus.borrow_mut();
        if input
            && !bus
                .queues
                .iter()
                .any(|(e, p, _)| *e == self.end && p == port)
        {
            bus.queues.push((self.end, port.into(), VecDeque::new()));
        }
        Some(Self::SIZE)
    }
    fn receive(&mut self, port: &str, buf: &mut [u8]) -> Option<usize> {
        let mut bus = self.bus.borrow_mut();
        let (_, _, queue) = bus
            .queues
            .iter_mut()
            .find(|(e, p, _)| *e == self.end && p == port)?;
        let message = queue.pop_front()?;
        let len = message.len().min(buf.len());
        buf[..len].copy_from_slice(&message[..len]);
        Some(len)
    }
    fn send(&mut self, port: &str, message: &[u8]) -> bool {
        if !self.has(port) || message.len() > Self::SIZE {
            return false;
        }
        let mut bus = self.bus.borrow_mut();
        let mut queues = bus.queues.iter_mut().filter(|(_, p, _)| p == port);
        if queues.any(|(_, _, q)| q.len() >= Self::DEPTH) {
            return false;
        }
        for (_, _, q) in bus.queues.iter_mut().filter(|(_, p, _)| p == port) {
            q.push_back(message.to_vec());
        }
        true
    }

    fn udp_open(&mut self, at: NetAddr, subscribe: bool) -> Result<usize, String> {
        let mut bus = self.bus.borrow_mut();
        let end = UdpEnd {
            end: self.end,
            at,
            queue: subscribe.then(VecDeque::new),
        };
        match bus.udp.iter().position(Option::is_none) {
            Some(free) => {
                bus.udp[free] = Some(end);
                Ok(free)
            }
            None => {
                bus.udp.push(Some(end));
                Ok(bus.udp.len() - 1)
            }
        }
    }

    fn udp_send(&mut self, endpoint: usize, datagram: &[u8]) -> Result<(), String> {
        let mut bus = self.bus.borrow_mut();
        let to = match bus.udp.get(endpoint) {
            Some(Some(e)) if e.end == self.end && e.queue.is_none() => e.at,
            _ => return Err("no such UDP endpoint".into()),
        };
        if datagram.len() > MAX_DATAGRAM {
            return Err(format!("the datagram is longer than {MAX_DATAGRAM} bytes"));
        }
        bus.deliver(to, datagram);
        Ok(())
    }

    fn udp_receive(&mut self, endpoint: usize, buf: &mut [u8]) -> Option<usize> {
        let mut bus = self.bus.borrow_mut();
        let e = bus.udp.get_mut(endpoint)?.as_mut()?;
        if e.end != self.end {
            return None;
        }
        let datagram = e.queue.as_mut()?.pop_front()?;
        let len = datagram.len().min(buf.len());
        buf[..len].copy_from_slice(&datagram[..len]);
        Some(len)
    }

    fn udp_close(&mut self, endpoint: usize) {
        let mut bus = self.bus.borrow_mut();
        if let Some(slot) = bus.udp.get_mut(endpoint)
            && slot.as_ref().is_some_and(|e| e.end == self.end)
        {
            *slot = None;
        }
    }
}

#[cfg(test)]
pub(crate) mod tests;
