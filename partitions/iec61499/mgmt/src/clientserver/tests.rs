//! CLIENT/SERVER between two devices over a loopback of queuing ports (`req` carries the
//! requests, `rsp` the responses), as two partitions joined by two channels.

extern crate std;

use super::*;
use crate::Device;
use crate::pubsub::{Loopback, encode};
use crate::segment::{connect, fb, read, set, trigger, write};
use crate::sifb::ProcessIo;
use iec61499_runtime::Limits;

fn device(io: Loopback) -> Device {
    let mut d = Device::new(Limits::default(), 2);
    d.set_io(Box::new(io));
    d
}

fn boot(io: Loopback, parts: &[String]) -> Device {
    let mut d = device(io);
    crate::segment::boot(&mut d, parts);
    d
}

/// A client that sends a DINT and a STRING and receives a DINT, a STRING and an LREAL, each
/// CNF counted by N and its values copied into V, W, X.
fn client(io: Loopback, id: &str) -> Device {
    boot(
        io,
        &[
            fb("C", "CLIENT_2_3"),
            fb("N", "E_CTU"),
            fb("V", "DINT2DINT"),
            fb("W", "STRING2STRING"),
            fb("X", "LREAL2LREAL"),
            write("1", "C.QI"),
            write(id, "C.ID"),
            write("DINT#-7", "C.SD_1"),
            write("'tank'", "C.SD_2"),
            connect("START.COLD", "C.INIT"),
            connect("C.CNF", "N.CU"),
            connect("C.CNF", "V.REQ"),
            connect("C.CNF", "W.REQ"),
            connect("C.CNF", "X.REQ"),
            connect("C.RD_1", "V.IN"),
            connect("C.RD_2", "W.IN"),
            connect("C.RD_3", "X.IN"),
        ],
    )
}

/// A server that answers each request with its DINT plus 100, its STRING and an LREAL
/// 2.5, each request counted by N.
fn server(io: Loopback, id: &str) -> Device {
    boot(
        io,
        &[
            fb("S", "SERVER_3_2"),
            fb("N", "E_CTU"),
            fb("A", "F_ADD"),
            fb("B", "STRING2STRING"),
            write("1", "S.QI"),
            write(id, "S.ID"),
            write("LREAL#2.5", "S.SD_3"),
            write("DINT#100", "A.IN2"),
            connect("START.COLD", "S.INIT"),
            // Only a request (QO TRUE) is answered: a refused RSP is an IND with QO
            // FALSE, which would otherwise answer itself again.
            fb("P", "E_PERMIT"),
            connect("S.IND", "P.EI"),
            connect("S.QO", "P.PERMIT"),
            connect("P.EO", "N.CU"),
            connect("P.EO", "A.REQ"),
            connect("A.CNF", "B.REQ"),
            connect("B.CNF", "S.RSP"),
            connect("S.RD_1", "A.IN1"),
            connect("A.OUT", "S.SD_1"),
            connect("S.RD_2", "B.IN"),
            connect("B.OUT", "S.SD_2"),
        ],
    )
}

#[test]
fn a_request_gets_its_response_with_every_value() {
    let bus = Loopback::with_ports(&["req", "rsp"]);
    let mut c = client(bus.end(), "req,rsp");
    let mut s = server(bus.end(), "req,rsp");
    assert_eq!(read(&mut c, "C.QO"), "TRUE");
    assert_eq!(read(&mut c, "C.STATUS"), "'OK'");
    assert_eq!(read(&mut s, "S.QO"), "TRUE");
    assert!(c.polls() && s.polls());
    // Sent without an event: CNF comes with the response.
    trigger(&mut c, "C.REQ");
    assert_eq!(read(&mut c, "N.CV"), "0");
    s.poll(0);
    assert_eq!(read(&mut s, "N.CV"), "1");
    assert_eq!(read(&mut s, "S.RD_1"), "-7");
    assert_eq!(read(&mut s, "S.RD_2"), "'tank'");
    c.poll(0);
    assert_eq!(read(&mut c, "N.CV"), "1");
    assert_eq!(read(&mut c, "C.QO"), "TRUE");
    assert_eq!(read(&mut c, "C.STATUS"), "'OK'");
    assert_eq!(read(&mut c, "V.OUT"), "93");
    assert_eq!(read(&mut c, "W.OUT"), "'tank'");
    assert_eq!(read(&mut c, "X.OUT"), "2.5");
    // New data, two requests: two responses in order, each its own CNF.
    set(&mut c, "DINT#1", "C.SD_1");
    trigger(&mut c, "C.REQ");
    set(&mut c, "'pump'", "C.SD_2");
    trigger(&mut c, "C.REQ");
    s.poll(0);
    c.poll(0);
    assert_eq!(read(&mut s, "N.CV"), "3");
    assert_eq!(read(&mut c, "N.CV"), "3");
    assert_eq!(read(&mut c, "V.OUT"), "101");
    assert_eq!(read(&mut c, "W.OUT"), "'pump'");
}

#[test]
fn an_id_without_a_comma_names_a_pair() {
    let bus = Loopback::with_ports(&["tank_req", "tank_rsp"]);
    let mut c = client(bus.end(), "tank");
    let mut s = server(bus.end(), "tank");
    trigger(&mut c, "C.REQ");
    s.poll(0);
    c.poll(0);
    assert_eq!(read(&mut c, "V.OUT"), "93");
    // A server INITed on ports the partition lacks: QO FALSE, the port named.
    let mut lost = server(bus.end(), "req,rsp");
    assert_eq!(read(&mut lost, "S.QO"), "FALSE");
    assert_eq!(read(&mut lost, "S.STATUS"), "'no queuing output port rsp'");
    assert!(!lost.polls());
}

#[test]
fn a_message_that_does_not_decode_is_reported() {
    let bus = Loopback::with_ports(&["req", "rsp"]);
    let mut c = client(bus.end(), "req,rsp");
    let mut s = server(bus.end(), "req,rsp");
    trigger(&mut c, "C.REQ");
    s.poll(0);
    c.poll(0);
    assert_eq!(read(&mut c, "V.OUT"), "93");
    // A response of other types (an empty message): CNF with QO FALSE, RD unchanged.
    let mut other = bus.end();
    assert!(other.send("rsp", &[fbdk::NULL]));
    c.poll(0);
    assert_eq!(read(&mut c, "N.CV"), "2");
    assert_eq!(read(&mut c, "C.QO"), "FALSE");
    assert!(read(&mut c, "C.STATUS").starts_with("'bad message: RD_1"));
    assert_eq!(read(&mut c, "C.RD_1"), "93");
    // A request with bytes after its values: IND with QO FALSE.
    let mut message = encode(
        &[Some(DataType::DInt), Some(DataType::String)],
        &[Value::Int(5), Value::String("x".into())],
        64,
    )
    .unwrap();
    message.push(fbdk::NULL);
    assert!(other.send("req", &message));
    s.poll(0);
    assert_eq!(read(&mut s, "S.QO"), "FALSE");
    assert!(read(&mut s, "S.STATUS").starts_with("'bad message: "));
    assert_eq!(read(&mut s, "S.RD_1"), "-7");
    // A good one after it is taken as usual.
    assert!(other.send("req", &message[..message.len() - 1]));
    s.poll(0);
    assert_eq!(read(&mut s, "S.QO"), "TRUE");
    assert_eq!(read(&mut s, "S.RD_1"), "5");
}

#[test]
fn nothing_is_sent_before_init() {
    let bus = Loopback::with_ports(&["req", "rsp"]);
    // No INIT: REQ gives CNF with QO FALSE and sends nothing.
    let mut c = boot(
        bus.end(),
        &[
            fb("C", "CLIENT_1"),
            write("1", "C.QI"),
            write("DINT#3", "C.SD_1"),
        ],
    );
    let mut spy = bus.end();
    assert!(spy.queue_size("req", true).is_some());
    trigger(&mut c, "C.REQ");
    assert_eq!(read(&mut c, "C.QO"), "FALSE");
    assert_eq!(read(&mut c, "C.STATUS"), "'not initialised'");
    assert!(spy.receive("req", &mut [0; 64]).is_none());
    assert!(!c.polls());
    // INIT, then REQ with QI FALSE: refused as well.
    trigger(&mut c, "C.INIT");
    assert_eq!(read(&mut c, "C.QO"), "FALSE");
    assert_eq!(
        read(&mut c, "C.STATUS"),
        "'no ID (requests,responses or NAME)'"
    );
    set(&mut c, "req,rsp", "C.ID");
    trigger(&mut c, "C.INIT");
    assert_eq!(read(&mut c, "C.QO"), "TRUE");
    set(&mut c, "0", "C.QI");
    trigger(&mut c, "C.REQ");
    assert_eq!(read(&mut c, "C.STATUS"), "'QI is FALSE'");
    assert!(spy.receive("req", &mut [0; 64]).is_none());
    // A server's RSP before INIT: IND with QO FALSE.
    let mut s = boot(bus.end(), &[fb("S", "SERVER_0"), write("1", "S.QI")]);
    trigger(&mut s, "S.RSP");
    assert_eq!(read(&mut s, "S.QO"), "FALSE");
    assert_eq!(read(&mut s, "S.STATUS"), "'not initialised'");
}

#[test]
fn a_full_port_refuses_the_message() {
    let bus = Loopback::with_ports(&["req", "rsp"]);
    let mut c = client(bus.end(), "req,rsp");
    let mut s = server(bus.end(), "req,rsp");
    // The port holds Loopback::DEPTH requests: the next REQ is a CNF with QO FALSE.
    for _ in 0..Loopback::DEPTH {
        trigger(&mut c, "C.REQ");
    }
    assert_eq!(read(&mut c, "N.CV"), "0");
    trigger(&mut c, "C.REQ");
    assert_eq!(read(&mut c, "N.CV"), "1");
    assert_eq!(read(&mut c, "C.QO"), "FALSE");
    assert_eq!(read(&mut c, "C.STATUS"), "'port full'");
    // The server answers the four; its fifth response finds the client's port full.
    s.poll(0);
    assert_eq!(read(&mut s, "N.CV"), "4");
    assert_eq!(read(&mut s, "S.QO"), "TRUE");
    trigger(&mut s, "S.RSP");
    assert_eq!(read(&mut s, "N.CV"), "4");
    assert_eq!(read(&mut s, "S.QO"), "FALSE");
    assert_eq!(read(&mut s, "S.STATUS"), "'port full'");
    c.poll(0);
    assert_eq!(read(&mut c, "N.CV"), "5");
    assert_eq!(read(&mut c, "C.QO"), "TRUE");
    assert_eq!(read(&mut c, "V.OUT"), "93");
}

#[test]
fn init_without_qi_closes() {
    let bus = Loopback::with_ports(&["req", "rsp"]);
    let mut c = client(bus.end(), "req,rsp");
    let mut s = server(bus.end(), "req,rsp");
    set(&mut s, "0", "S.QI");
    trigger(&mut s, "S.INIT");
    assert_eq!(read(&mut s, "S.QO"), "FALSE");
    assert_eq!(read(&mut s, "S.STATUS"), "'OK'");
    assert!(!s.polls());
    // Closed: RSP sends nothing even with QI again; a request waits in the port.
    set(&mut s, "1", "S.QI");
    trigger(&mut s, "S.RSP");
    assert_eq!(read(&mut s, "S.STATUS"), "'not initialised'");
    trigger(&mut c, "C.REQ");
    s.poll(0);
    assert_eq!(read(&mut s, "N.CV"), "0");
    // INIT with QI opens again and takes it.
    trigger(&mut s, "S.INIT");
    assert!(s.polls());
    s.poll(0);
    assert_eq!(read(&mut s, "N.CV"), "1");
    assert_eq!(read(&mut s, "S.RD_1"), "-7");
    // The client closed: its CNF no longer comes.
    set(&mut c, "0", "C.QI");
    trigger(&mut c, "C.INIT");
    assert_eq!(read(&mut c, "C.QO"), "FALSE");
    assert!(!c.polls());
    c.poll(0);
    assert_eq!(read(&mut c, "N.CV"), "0");
}

#[test]
fn names_and_ids() {
    assert_eq!(parse_name("CLIENT_0"), Some((true, 0, 0)));
    assert_eq!(parse_name("CLIENT_2_3"), Some((true, 2, 3)));
    assert_eq!(parse_name("SERVER_8"), Some((false, 8, 8)));
    assert_eq!(parse_name("SERVER_0_8"), Some((false, 0, 8)));
    for bad in [
        "CLIENT",
        "CLIENT_",
        "CLIENT_9",
        "CLIENT_1_9",
        "CLIENT_1_",
        "CLIENT__1",
        "CLIENT_+1",
        "CLIENT_1_2_3",
        "SERVER_a",
        "PUBLISH_1",
        "CLIENT_1 ",
    ] {
        assert_eq!(parse_name(bad), None, "{bad}");
    }
    let io = crate::sifb::share(Box::new(crate::sifb::NoPorts));
    let c = create("CLIENT_2_3", &io).unwrap();
    let i = c.interface();
    let names = |v: &[VarSpec]| v.iter().map(|v| v.name.clone()).collect::<Vec<_>>();
    assert_eq!(names(&i.inputs), ["QI", "ID", "SD_1", "SD_2"]);
    assert_eq!(names(&i.outputs), ["QO", "STATUS", "RD_1", "RD_2", "RD_3"]);
    assert_eq!(i.event_inputs[1].name, "REQ");
    assert_eq!(i.event_outputs[1].name, "CNF");
    assert_eq!(i.event_outputs[1].with, [QO, STATUS, 2, 3, 4]);
    let s = create("SERVER_1_0", &io).unwrap();
    let i = s.interface();
    assert_eq!(names(&i.inputs), ["QI", "ID", "SD_1"]);
    assert_eq!(names(&i.outputs), ["QO", "STATUS"]);
    assert_eq!(i.event_inputs[1].name, "RSP");
    assert_eq!(i.event_inputs[1].with, [QI, 2]);
    assert_eq!(i.event_outputs[1].name, "IND");
    assert_eq!(
        parse_id(" req , rsp "),
        Ok(("req".to_string(), "rsp".to_string()))
    );
    assert_eq!(
        parse_id("tank"),
        Ok(("tank_req".to_string(), "tank_rsp".to_string()))
    );
    for bad in ["", " ", "a,", ",b", "a,b,c"] {
        assert!(parse_id(bad).is_err(), "{bad}");
    }
}

#[test]
fn a_refusal_answered_by_itself_is_an_event_loop_fault() {
    // IND straight to RSP without looking at QO: the refused RSP's IND asks for another
    // RSP, refused again, until the resource's chain limit stops it as a fault.
    let bus = Loopback::with_ports(&["req", "rsp"]);
    let mut s = boot(
        bus.end(),
        &[
            fb("S", "SERVER_0"),
            write("1", "S.QI"),
            connect("S.IND", "S.RSP"),
        ],
    );
    assert_eq!(s.report().faults, 0);
    trigger(&mut s, "S.RSP");
    assert_eq!(s.report().faults, 1);
    assert_eq!(read(&mut s, "S.STATUS"), "'not initialised'");
}
