//! CLIENT and SERVER, 4diac's interfaces, between partitions on one machine over a pair of
//! ARINC 653 queuing ports (the network comes later), as [`crate::pubsub`] does for
//! PUBLISH/SUBSCRIBE: a message is the FBDK ASN.1 encoding of the data (`fbdk`).
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
//! **ID** names the two queuing ports, requests first: `'requests,responses'` (port names
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
    DATA, ID, INIT, MAX_DATA, PER_POLL, QI, QO, STATUS, UNTYPED, decode, encode, wire_type,
};
use crate::sifb::Io;
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
    };
    Some(Box::new(ClientServer {
        interface,
        client,
        sd: alloc::vec![None; sd],
        rd: alloc::vec![None; rd],
        io: io.clone(),
        ports: None,
    }))
}

/// The open ports: each name and message size.
#[derive(Clone)]
struct Ports {
    output: (String, usize),
    input: (String, usize),
}

struct ClientServer {
    interface: Interface,
    client: bool,
    /// Each SD's and RD's type once known.
    sd: Vec<Option<DataType>>,
    rd: Vec<Option<DataType>>,
    io: Io,
    ports: Option<Ports>,
}

impl ClientServer {
    fn init(&mut self, inputs: &[Value]) -> (bool, String) {
        self.ports = None;
        if !inputs[QI].as_bool() {
            return (false, "OK".into());
        }
        let id = match &inputs[ID] {
            Value::String(s) => s.as_str(),
            _ => "",
        };
        let (requests, responses) = match parse_id(id) {
            Ok(ports) => ports,
            Err(why) => return (false, why),
        };
        let (output, input) = if self.client {
            (requests, responses)
        } else {
            (responses, requests)
        };
        let io = self.io.borrow();
        let Some(output_size) = io.io.queue_size(&output, false) else {
            return (false, format!("no queuing output port {output}"));
        };
        let Some(input_size) = io.io.queue_size(&input, true) else {
            return (false, format!("no queuing input port {input}"));
        };
        drop(io);
        self.ports = Some(Ports {
            output: (output, output_size),
            input: (input, input_size),
        });
        (true, "OK".into())
    }

    /// Sends SD_1..SD_m: `None` when sent, else why not.
    fn send(&mut self, inputs: &[Value]) -> Option<String> {
        let Some(Ports {
            output: (port, size),
            ..
        }) = self.ports.clone()
        else {
            return Some("not initialised".into());
        };
        if !inputs[QI].as_bool() {
            return Some("QI is FALSE".into());
        }
        let message = match encode(&self.sd, &inputs[DATA..], size) {
            Ok(m) => m,
            Err(why) => return Some(why),
        };
        if self.io.borrow_mut().io.send(&port, &message) {
            None
        } else {
            Some("port full".into())
        }
    }
}

impl FunctionBlock for ClientServer {
    fn interface(&self) -> &Interface {
        &self.interface
    }

    fn event(&mut self, event: usize, inputs: &[Value], ctx: &mut Context<'_>) {
        let (qo, status) = if event == INIT {
            self.init(inputs)
        } else {
            match self.send(inputs) {
                // Sent: the answer is the other side's message, polled.
                None => return,
                Some(why) => (false, why),
            }
        };
        ctx.set(QO, Value::Bool(qo));
        ctx.set(STATUS, Value::String(status));
        ctx.send(if event == INIT { INIT } else { DATA_EVENT });
    }

    fn polls(&self) -> bool {
        self.ports.is_some()
    }

    fn poll(&mut self, _inputs: &[Value], ctx: &mut Context<'_>) {
        let Some(Ports {
            input: (port, size),
            ..
        }) = self.ports.clone()
        else {
            return;
        };
        let mut buf = alloc::vec![0u8; size];
        for _ in 0..PER_POLL {
            let Some(len) = self.io.borrow_mut().io.receive(&port, &mut buf) else {
                break;
            };
            let (qo, status) = match decode(&self.rd, &buf[..len.min(size)]) {
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
    }

    fn reset(&mut self) {
        self.ports = None;
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

#[cfg(test)]
mod tests;
