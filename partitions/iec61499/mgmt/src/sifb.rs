//! The process image of an IEC 61499 device: service-interface FBs bound to the
//! partition's ARINC 653 sampling ports, shaped like 4diac's IO FBs (IX, QX, ...).
//!
//! | type | data | reads or writes |
//! |---|---|---|
//! | `PORT_IN_BOOL`, `PORT_IN_DINT`, `PORT_IN_LREAL` | output `IN` | a value of an input port |
//! | `PORT_OUT_BOOL`, `PORT_OUT_DINT`, `PORT_OUT_LREAL` | input `OUT` | a value of an output port |
//!
//! Every one has the inputs `QI : BOOL` and `PARAMS : STRING`, the outputs `QO : BOOL` and
//! `STATUS : STRING`, the input events `INIT` (with QI, PARAMS) and `REQ` (with QI, and OUT
//! for the output FBs) and the output events `INITO` (with QO, STATUS) and `CNF` (with QO,
//! STATUS, and IN for the input FBs). `PARAMS` names the port and the byte offset of the
//! value in its message, `'level'` or `'status:8'`; values are little-endian, BOOL one byte
//! (non-zero is TRUE), DINT four, LREAL eight (the plant's ports carry one LREAL each).
//!
//! INIT with QI checks that the port exists in the right direction and holds the value at
//! that offset: QO TRUE and STATUS `'OK'`, else QO FALSE and STATUS why. REQ with QI on an
//! input FB reads the port's latest message: QO TRUE and STATUS `'OK'` when it is fresh
//! (within the port's refresh period), QO FALSE with STATUS `'stale'` (IN is the stale
//! value) or `'no message'`; on an output FB it writes OUT into the port's message (the
//! other bytes as last written) and sends it. A REQ before a good INIT, or without QI, gives
//! QO FALSE and STATUS `'not initialised'` and touches no port.

use crate::pubsub::NetAddr;
use alloc::boxed::Box;
use alloc::format;
use alloc::rc::Rc;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
use core::cell::RefCell;
use iec61499_runtime::fb::{Context, EventDecl, Interface};
use iec61499_runtime::{DataType, FunctionBlock, Value};

/// The partition's ports as the process-image FBs use them, and the UDP endpoints of
/// PUBLISH/SUBSCRIBE when it has a network interface. Every method's default answers as a
/// partition without that port (or without a network interface).
pub trait ProcessIo {
    /// The message size of sampling port `port` in direction `input` (true: the partition
    /// receives on it), if the partition has it.
    fn size(&self, _port: &str, _input: bool) -> Option<usize> {
        None
    }
    /// The latest message of input port `port` into `buf` (its message size): `Some(fresh)`,
    /// or `None` when none has arrived.
    fn read(&mut self, _port: &str, _buf: &mut [u8]) -> Option<bool> {
        None
    }
    /// Sends `message` on output port `port`.
    fn write(&mut self, _port: &str, _message: &[u8]) -> bool {
        false
    }

    /// The message size of queuing port `port` in direction `input` (true: the partition
    /// receives on it), if the partition has it (for PUBLISH/SUBSCRIBE, `crate::pubsub`).
    fn queue_size(&self, _port: &str, _input: bool) -> Option<usize> {
        None
    }
    /// The next message of input queuing port `port` into `buf` without waiting: its
    /// length, or `None` when none is queued.
    fn receive(&mut self, _port: &str, _buf: &mut [u8]) -> Option<usize> {
        None
    }
    /// Queues `message` on output queuing port `port` without waiting; false when the
    /// port is full or missing.
    fn send(&mut self, _port: &str, _message: &[u8]) -> bool {
        false
    }

    /// Opens a UDP endpoint (for PUBLISH/SUBSCRIBE with a UDP ID, `crate::pubsub`): with
    /// `subscribe`, one that receives the datagrams to `at`'s port (and joins `at`'s group
    /// when it is a multicast address); without, one that sends to `at`. Its number, or why
    /// not; the default: the partition has no network interface.
    fn udp_open(&mut self, _at: NetAddr, _subscribe: bool) -> Result<usize, String> {
        Err(NO_NETWORK.into())
    }
    /// Sends `datagram` from publishing endpoint `endpoint` without waiting, or why not.
    fn udp_send(&mut self, _endpoint: usize, _datagram: &[u8]) -> Result<(), String> {
        Err(NO_NETWORK.into())
    }
    /// The next datagram subscribing endpoint `endpoint` received, into `buf` (cut to its
    /// length): its length, or `None` when none is queued.
    fn udp_receive(&mut self, _endpoint: usize, _buf: &mut [u8]) -> Option<usize> {
        None
    }
    /// Closes `endpoint` (what it had queued is dropped).
    fn udp_close(&mut self, _endpoint: usize) {}

    /// Opens a TCP link (for CLIENT/SERVER with an IP ID, `crate::clientserver`): with
    /// `server`, one that listens on `at`'s port for a client; without, one that connects
    /// to `at`. Its number, or why not; the default: the partition has no network
    /// interface. The connection is made later (`tcp_state` says when).
    fn tcp_open(&mut self, _at: NetAddr, _server: bool) -> Result<usize, String> {
        Err(NO_NETWORK.into())
    }
    /// What link `link` is doing.
    fn tcp_state(&self, _link: usize) -> TcpState {
        TcpState::Down(NO_NETWORK.into())
    }
    /// Queues `bytes` to send on `link` without waiting, or why not.
    fn tcp_send(&mut self, _link: usize, _bytes: &[u8]) -> Result<(), String> {
        Err(NO_NETWORK.into())
    }
    /// Bytes `link` received (a stream), into `buf`: how many (0 when none wait).
    fn tcp_receive(&mut self, _link: usize, _buf: &mut [u8]) -> usize {
        0
    }
    /// Closes `link` (what waited either way is dropped).
    fn tcp_close(&mut self, _link: usize) {}
    /// The partition's monotonic clock now (ns), for FBs that measure the time passing
    /// inside an event chain (E_STOPWATCH); the default: no clock (they measure the chains'
    /// instants instead, which is what a test on the host wants).
    fn clock(&self) -> Option<i64> {
        None
    }
}

/// What a TCP link (`ProcessIo::tcp_open`) is doing, for its FB.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum TcpState {
    /// A client whose connection is not up yet, or a server not listening yet.
    Opening,
    /// A server listening, without a client.
    Listening,
    /// Connected to `peer` (a server: to its client of the moment).
    Connected { peer: NetAddr },
    /// A client whose connection failed or ended, or a server that cannot listen: why.
    /// Nothing more happens on the link but the bytes that came before the end; the FB
    /// closes it.
    Down(String),
}

/// Bytes that may wait each way on a TCP link: the longest message a CLIENT or SERVER
/// sends or receives over TCP.
pub const TCP_BUFFER: usize = 4096;

/// Why an IP ID cannot open on a partition without a network interface.
pub const NO_NETWORK: &str = "no network interface";

/// A device without ports (the host's boot check): every INIT says which port is missing.
pub struct NoPorts;

impl ProcessIo for NoPorts {}

/// The ports, shared by a device's process-image FBs, with each output port's message as
/// last written (so FBs writing different offsets of one message keep each other's bytes).
pub struct SharedIo {
    pub(crate) io: Box<dyn ProcessIo>,
    outputs: Vec<(String, Vec<u8>)>,
}

pub type Io = Rc<RefCell<SharedIo>>;

/// Shares `io` between the FBs of a device.
pub fn share(io: Box<dyn ProcessIo>) -> Io {
    Rc::new(RefCell::new(SharedIo {
        io,
        outputs: Vec::new(),
    }))
}

const TYPES: [(&str, bool, DataType); 6] = [
    ("PORT_IN_BOOL", true, DataType::Bool),
    ("PORT_IN_DINT", true, DataType::DInt),
    ("PORT_IN_LREAL", true, DataType::LReal),
    ("PORT_OUT_BOOL", false, DataType::Bool),
    ("PORT_OUT_DINT", false, DataType::DInt),
    ("PORT_OUT_LREAL", false, DataType::LReal),
];

/// A new process-image FB of type `ty`, or `None` if `ty` is none of them.
pub fn create(ty: &str, io: &Io) -> Option<Box<dyn FunctionBlock>> {
    let &(_, input, data) = TYPES.iter().find(|(name, _, _)| *name == ty)?;
    let (value, cnf_with, req_with): (&str, &[&str], &[&str]) = if input {
        ("IN", &["QO", "STATUS", "IN"], &["QI"])
    } else {
        ("OUT", &["QO", "STATUS"], &["QI", "OUT"])
    };
    let out_events: [EventDecl<'_>; 2] = [("INITO", &["QO", "STATUS"]), ("CNF", cnf_with)];
    let events_in: [EventDecl<'_>; 2] = [("INIT", &["QI", "PARAMS"]), ("REQ", req_with)];
    let mut inputs = alloc::vec![
        ("QI", DataType::Bool, None),
        ("PARAMS", DataType::String, None)
    ];
    let mut outputs = alloc::vec![
        ("QO", DataType::Bool, None),
        ("STATUS", DataType::String, None)
    ];
    if input {
        outputs.push((value, data, None));
    } else {
        inputs.push((value, data, None));
    }
    let interface = Interface::build(&events_in, &out_events, &inputs, &outputs).ok()?;
    Some(Box::new(PortFb {
        interface,
        input,
        data,
        io: io.clone(),
        bound: None,
    }))
}

/// Where a process-image FB's value lies: port and byte offset.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Binding {
    port: String,
    offset: usize,
}

struct PortFb {
    interface: Interface,
    input: bool,
    data: DataType,
    io: Io,
    bound: Option<Binding>,
}

// Inputs and outputs by index, as `create` declares them.
const QI: usize = 0;
const PARAMS: usize = 1;
const OUT: usize = 2;
const QO: usize = 0;
const STATUS: usize = 1;
const IN: usize = 2;
const INIT: usize = 0;

fn width(data: DataType) -> usize {
    match data {
        DataType::Bool => 1,
        DataType::DInt => 4,
        _ => 8,
    }
}

impl PortFb {
    fn bind(&self, params: &str) -> Result<Binding, String> {
        let (port, offset) = match params.split_once(':') {
            None => (params, 0),
            Some((port, offset)) => (
                port,
                offset
                    .trim()
                    .parse()
                    .map_err(|_| format!("offset {offset} is not a number"))?,
            ),
        };
        let port = port.trim();
        let direction = if self.input { "input" } else { "output" };
        let size = self
            .io
            .borrow()
            .io
            .size(port, self.input)
            .ok_or_else(|| format!("no sampling {direction} port {port}"))?;
        if offset + width(self.data) > size {
            return Err(format!(
                "port {port} has {size}-byte messages: no {}-byte value at offset {offset}",
                width(self.data)
            ));
        }
        Ok(Binding {
            port: port.to_string(),
            offset,
        })
    }

    fn decode(&self, bytes: &[u8]) -> Value {
        let mut raw = [0u8; 8];
        raw[..bytes.len()].copy_from_slice(bytes);
        match self.data {
            DataType::Bool => Value::Bool(raw[0] != 0),
            DataType::DInt => Value::Int(i64::from(i32::from_le_bytes([
                raw[0], raw[1], raw[2], raw[3],
            ]))),
            _ => Value::Real(f64::from_le_bytes(raw)),
        }
    }

    fn encode(&self, value: &Value) -> Vec<u8> {
        match (self.data, value) {
            (DataType::Bool, v) => alloc::vec![u8::from(v.as_bool())],
            (DataType::DInt, Value::Int(i)) => (*i as i32).to_le_bytes().to_vec(),
            (_, Value::Real(r)) => r.to_le_bytes().to_vec(),
            (_, Value::Int(i)) => (*i as f64).to_le_bytes().to_vec(),
            _ => alloc::vec![0; width(self.data)],
        }
    }

    /// Reads or writes the bound value: QO and STATUS.
    fn request(&mut self, inputs: &[Value], ctx: &mut Context<'_>) -> (bool, String) {
        let Some(b) = self.bound.clone().filter(|_| inputs[QI].as_bool()) else {
            return (false, "not initialised".into());
        };
        let mut shared = self.io.borrow_mut();
        let size = shared.io.size(&b.port, self.input).unwrap_or(0);
        let range = b.offset..b.offset + width(self.data);
        if self.input {
            let mut buf = alloc::vec![0u8; size];
            match shared.io.read(&b.port, &mut buf) {
                None => (false, "no message".into()),
                Some(fresh) => {
                    let Some(bytes) = buf.get(range) else {
                        return (false, "message too short".into());
                    };
                    ctx.set(IN, self.decode(bytes));
                    if fresh {
                        (true, "OK".into())
                    } else {
                        (false, "stale".into())
                    }
                }
            }
        } else {
            let bytes = self.encode(&inputs[OUT]);
            let SharedIo { io, outputs } = &mut *shared;
            let at = match outputs.iter().position(|(p, _)| *p == b.port) {
                Some(at) => at,
                None => {
                    outputs.push((b.port.clone(), alloc::vec![0; size]));
                    outputs.len() - 1
                }
            };
            let message = &mut outputs[at].1;
            if let Some(slot) = message.get_mut(range) {
                slot.copy_from_slice(&bytes);
            }
            if io.write(&b.port, message) {
                (true, "OK".into())
            } else {
                (false, "send failed".into())
            }
        }
    }
}

impl FunctionBlock for PortFb {
    fn interface(&self) -> &Interface {
        &self.interface
    }

    fn event(&mut self, event: usize, inputs: &[Value], ctx: &mut Context<'_>) {
        let (qo, status) = if event == INIT {
            let params = match &inputs[PARAMS] {
                Value::String(s) => s.clone(),
                _ => String::new(),
            };
            self.bound = None;
            if inputs[QI].as_bool() {
                match self.bind(&params) {
                    Ok(b) => {
                        self.bound = Some(b);
                        (true, "OK".to_string())
                    }
                    Err(why) => (false, why),
                }
            } else {
                (false, "OK".to_string())
            }
        } else {
            self.request(inputs, ctx)
        };
        ctx.set(QO, Value::Bool(qo));
        ctx.set(STATUS, Value::String(status));
        ctx.send(event);
    }

    fn reset(&mut self) {
        self.bound = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Device;
    use iec61499_runtime::Limits;

    /// Ports `level` (in, 8 bytes) and `out` (out, 16 bytes), with what was written.
    #[derive(Clone, Default)]
    struct Fake {
        level: Rc<RefCell<Option<(f64, bool)>>>,
        written: Rc<RefCell<Vec<Vec<u8>>>>,
    }

    impl ProcessIo for Fake {
        fn size(&self, port: &str, input: bool) -> Option<usize> {
            match (port, input) {
                ("level", true) => Some(8),
                ("out", false) => Some(16),
                _ => None,
            }
        }
        fn read(&mut self, _: &str, buf: &mut [u8]) -> Option<bool> {
            let (v, fresh) = (*self.level.borrow())?;
            buf[..8].copy_from_slice(&v.to_le_bytes());
            Some(fresh)
        }
        fn write(&mut self, _: &str, message: &[u8]) -> bool {
            self.written.borrow_mut().push(message.to_vec());
            true
        }
    }

    fn run(d: &mut Device, lines: &[&str]) -> Vec<String> {
        lines
            .iter()
            .enumerate()
            .map(|(i, l)| {
                let (dst, req) = l.split_once(';').unwrap();
                let req = req.replace("ID=\"0\"", &format!("ID=\"{i}\""));
                d.execute(dst, &req, 0)
            })
            .collect()
    }

    fn read(d: &mut Device, port: &str) -> String {
        let r = d.execute(
            "R",
            &format!("<Request ID=\"9\" Action=\"READ\"><Connection Source=\"{port}\" Destination=\"\"/></Request>"),
            0,
        );
        let raw = r
            .split("Destination=\"")
            .nth(1)
            .unwrap()
            .split('"')
            .next()
            .unwrap();
        raw.replace("&apos;", "'").replace("&quot;", "\"")
    }

    #[test]
    fn values_go_between_ports_and_fbs_with_their_validity() {
        let fake = Fake::default();
        let mut d = Device::new(Limits::default(), 4);
        d.set_io(Box::new(fake.clone()));
        let answers = run(
            &mut d,
            &[
                ";<Request ID=\"0\" Action=\"CREATE\"><FB Name=\"R\" Type=\"EMB_RES\"/></Request>",
                "R;<Request ID=\"0\" Action=\"CREATE\"><FB Name=\"I\" Type=\"PORT_IN_LREAL\"/></Request>",
                "R;<Request ID=\"0\" Action=\"CREATE\"><FB Name=\"O\" Type=\"PORT_OUT_LREAL\"/></Request>",
                "R;<Request ID=\"0\" Action=\"CREATE\"><FB Name=\"B\" Type=\"PORT_OUT_BOOL\"/></Request>",
                "R;<Request ID=\"0\" Action=\"CREATE\"><FB Name=\"X\" Type=\"PORT_IN_DINT\"/></Request>",
                "R;<Request ID=\"0\" Action=\"WRITE\"><Connection Source=\"TRUE\" Destination=\"I.QI\"/></Request>",
                "R;<Request ID=\"0\" Action=\"WRITE\"><Connection Source=\"'level'\" Destination=\"I.PARAMS\"/></Request>",
                "R;<Request ID=\"0\" Action=\"WRITE\"><Connection Source=\"TRUE\" Destination=\"O.QI\"/></Request>",
                "R;<Request ID=\"0\" Action=\"WRITE\"><Connection Source=\"'out'\" Destination=\"O.PARAMS\"/></Request>",
                "R;<Request ID=\"0\" Action=\"WRITE\"><Connection Source=\"TRUE\" Destination=\"B.QI\"/></Request>",
                "R;<Request ID=\"0\" Action=\"WRITE\"><Connection Source=\"'out:8'\" Destination=\"B.PARAMS\"/></Request>",
                "R;<Request ID=\"0\" Action=\"WRITE\"><Connection Source=\"TRUE\" Destination=\"X.QI\"/></Request>",
                "R;<Request ID=\"0\" Action=\"WRITE\"><Connection Source=\"'level:6'\" Destination=\"X.PARAMS\"/></Request>",
                "R;<Request ID=\"0\" Action=\"CREATE\"><Connection Source=\"START.COLD\" Destination=\"I.INIT\"/></Request>",
                "R;<Request ID=\"0\" Action=\"CREATE\"><Connection Source=\"I.INITO\" Destination=\"O.INIT\"/></Request>",
                "R;<Request ID=\"0\" Action=\"CREATE\"><Connection Source=\"O.INITO\" Destination=\"B.INIT\"/></Request>",
                "R;<Request ID=\"0\" Action=\"CREATE\"><Connection Source=\"B.INITO\" Destination=\"X.INIT\"/></Request>",
                "R;<Request ID=\"0\" Action=\"CREATE\"><Connection Source=\"I.CNF\" Destination=\"O.REQ\"/></Request>",
                "R;<Request ID=\"0\" Action=\"CREATE\"><Connection Source=\"I.IN\" Destination=\"O.OUT\"/></Request>",
                "R;<Request ID=\"0\" Action=\"CREATE\"><Connection Source=\"I.QO\" Destination=\"B.OUT\"/></Request>",
                "R;<Request ID=\"0\" Action=\"CREATE\"><Connection Source=\"O.CNF\" Destination=\"B.REQ\"/></Request>",
                "R;<Request ID=\"0\" Action=\"START\"/>",
            ],
        );
        assert!(answers.iter().all(|a| !a.contains("Reason")), "{answers:?}");
        assert_eq!(read(&mut d, "I.STATUS"), "'OK'");
        assert_eq!(read(&mut d, "O.STATUS"), "'OK'");
        assert_eq!(read(&mut d, "X.QO"), "FALSE");
        assert_eq!(
            read(&mut d, "X.STATUS"),
            "'port level has 8-byte messages: no 4-byte value at offset 6'"
        );
        let trigger = "<Request ID=\"8\" Action=\"WRITE\"><Connection Source=\"$e\" Destination=\"I.REQ\"/></Request>";
        // No message yet: QO FALSE, the output still written (with IN's default).
        d.execute("R", trigger, 0);
        assert_eq!(read(&mut d, "I.STATUS"), "'no message'");
        *fake.level.borrow_mut() = Some((1.25, true));
        d.execute("R", trigger, 0);
        assert_eq!(read(&mut d, "I.IN"), "1.25");
        assert_eq!(read(&mut d, "I.QO"), "TRUE");
        let last = fake.written.borrow().last().unwrap().clone();
        assert_eq!(f64::from_le_bytes(last[..8].try_into().unwrap()), 1.25);
        assert_eq!(last[8], 1, "B wrote QO = TRUE at offset 8, O's bytes kept");
        *fake.level.borrow_mut() = Some((2.5, false));
        d.execute("R", trigger, 0);
        assert_eq!(read(&mut d, "I.STATUS"), "'stale'");
        assert_eq!(read(&mut d, "I.IN"), "2.5");
        let last = fake.written.borrow().last().unwrap().clone();
        assert_eq!(
            (f64::from_le_bytes(last[..8].try_into().unwrap()), last[8]),
            (2.5, 0)
        );
    }

    #[test]
    fn unknown_ports_and_requests_before_init_are_statuses_not_faults() {
        let mut d = Device::new(Limits::default(), 4);
        run(
            &mut d,
            &[
                ";<Request ID=\"0\" Action=\"CREATE\"><FB Name=\"R\" Type=\"EMB_RES\"/></Request>",
                "R;<Request ID=\"0\" Action=\"CREATE\"><FB Name=\"I\" Type=\"PORT_IN_BOOL\"/></Request>",
                "R;<Request ID=\"0\" Action=\"WRITE\"><Connection Source=\"TRUE\" Destination=\"I.QI\"/></Request>",
                "R;<Request ID=\"0\" Action=\"WRITE\"><Connection Source=\"'nope:x'\" Destination=\"I.PARAMS\"/></Request>",
                "R;<Request ID=\"0\" Action=\"START\"/>",
                "R;<Request ID=\"0\" Action=\"WRITE\"><Connection Source=\"$e\" Destination=\"I.REQ\"/></Request>",
            ],
        );
        assert_eq!(read(&mut d, "I.STATUS"), "'not initialised'");
        d.execute("R", "<Request ID=\"8\" Action=\"WRITE\"><Connection Source=\"$e\" Destination=\"I.INIT\"/></Request>", 0);
        assert_eq!(read(&mut d, "I.STATUS"), "'offset x is not a number'");
        d.execute("R", "<Request ID=\"8\" Action=\"WRITE\"><Connection Source=\"'nope'\" Destination=\"I.PARAMS\"/></Request>", 0);
        d.execute("R", "<Request ID=\"8\" Action=\"WRITE\"><Connection Source=\"$e\" Destination=\"I.INIT\"/></Request>", 0);
        assert_eq!(read(&mut d, "I.STATUS"), "'no sampling input port nope'");
        assert!(d.report().faults == 0);
    }
}
