//! PUBLISH/SUBSCRIBE over UDP between devices, each with its own stack (the management
//! server's, as the partition has it) and endpoints, their interfaces on one simulated
//! Ethernet segment (every frame reaches every other stack, which takes what is its own).

extern crate std;

use super::*;
use crate::Device;
use crate::serve::Access;
use crate::sifb::ProcessIo;
use crate::tcp::server::{Server, Settings};
use alloc::boxed::Box;
use alloc::rc::Rc;
use alloc::string::ToString;
use core::cell::RefCell;
use std::format;
use std::string::String;

/// The partition's side of the endpoints, as its `ProcessIo` hands them over.
struct NetIo(Rc<RefCell<Endpoints>>);

impl ProcessIo for NetIo {
    fn udp_open(&mut self, at: UdpAddr, subscribe: bool) -> Result<usize, String> {
        self.0.borrow_mut().open(at, subscribe)
    }
    fn udp_send(&mut self, endpoint: usize, datagram: &[u8]) -> Result<(), String> {
        self.0.borrow_mut().send(endpoint, datagram)
    }
    fn udp_receive(&mut self, endpoint: usize, buf: &mut [u8]) -> Option<usize> {
        self.0.borrow_mut().receive(endpoint, buf)
    }
    fn udp_close(&mut self, endpoint: usize) {
        self.0.borrow_mut().close(endpoint)
    }
}

struct Node {
    device: Device,
    server: Server,
    udp: Rc<RefCell<Endpoints>>,
    /// Whether the device takes its datagrams at each step.
    polling: bool,
}

struct Segment {
    nodes: std::vec::Vec<Node>,
    now_ns: u64,
}

const GROUP: &str = "239.0.0.1:61500";

fn ip(last: u8) -> [u8; 4] {
    [10, 0, 2, last]
}

impl Segment {
    /// Devices at 10.0.2.<last> for each of `lasts`.
    fn new(lasts: &[u8]) -> Self {
        let nodes = lasts
            .iter()
            .map(|&last| {
                let settings = Settings {
                    mac: [0x52, 0x54, 0, 0x12, 0x34, last],
                    address: ip(last),
                    prefix: 24,
                    gateway: None,
                    port: crate::tcp::PORT,
                    connections: 1,
                    access: Access::Monitor,
                };
                let udp = Rc::new(RefCell::new(Endpoints::new()));
                let mut device = Device::new(iec61499_runtime::Limits::default(), 4);
                device.set_io(Box::new(NetIo(udp.clone())));
                Node {
                    device,
                    server: Server::new(&settings, 0).unwrap(),
                    udp,
                    polling: true,
                }
            })
            .collect();
        Segment { nodes, now_ns: 0 }
    }

    /// One millisecond: each node's timers, network pass (server, endpoints) and
    /// subscribers, then every frame to every other node.
    fn step(&mut self) {
        self.now_ns += 1_000_000;
        let now = self.now_ns;
        let mut frames = std::vec::Vec::new();
        for (i, n) in self.nodes.iter_mut().enumerate() {
            n.device.advance(now as i64);
            n.server.run(now, &mut n.device);
            n.udp.borrow_mut().pump(&mut n.server.stack);
            n.server.stack.poll((now / 1000) as i64);
            if n.polling {
                n.device.poll(now as i64);
            }
            while let Some(f) = n.server.stack.device.take() {
                frames.push((i, f));
            }
        }
        for (from, f) in frames {
            for (i, n) in self.nodes.iter_mut().enumerate() {
                if i != from {
                    n.server.stack.device.deliver(&f);
                }
            }
        }
    }

    fn steps(&mut self, n: usize) {
        for _ in 0..n {
            self.step();
        }
    }
}

fn line(dst: &str, action: &str, object: &str) -> String {
    format!("{dst};<Request ID=\"1\" Action=\"{action}\">{object}</Request>\n")
}

fn write(value: &str, to: &str) -> String {
    line(
        "R",
        "WRITE",
        &format!("<Connection Source=\"{value}\" Destination=\"{to}\"/>"),
    )
}

fn connect(from: &str, to: &str) -> String {
    line(
        "R",
        "CREATE",
        &format!("<Connection Source=\"{from}\" Destination=\"{to}\"/>"),
    )
}

fn fb(name: &str, ty: &str) -> String {
    line(
        "R",
        "CREATE",
        &format!("<FB Name=\"{name}\" Type=\"{ty}\"/>"),
    )
}

/// A publisher `P` of an E_CTU's count `C.CV` and LREAL 2.5 to `id`.
fn publisher(id: &str) -> String {
    [
        fb("C", "E_CTU"),
        fb("P", "PUBLISH_2"),
        write("1", "P.QI"),
        write(id, "P.ID"),
        write("LREAL#2.5", "P.SD_2"),
        connect("START.COLD", "P.INIT"),
        connect("C.CUO", "P.REQ"),
        connect("C.CV", "P.SD_1"),
    ]
    .concat()
}

/// A subscriber `S<k>` of `id`: `N<k>.CV` counts its INDs, `V<k>.OUT` the last count,
/// `X<k>.OUT` the last LREAL.
fn subscriber(k: usize, id: &str) -> String {
    [
        fb(&format!("S{k}"), "SUBSCRIBE_2"),
        fb(&format!("N{k}"), "E_CTU"),
        fb(&format!("V{k}"), "UINT2UINT"),
        fb(&format!("X{k}"), "LREAL2LREAL"),
        write("1", &format!("S{k}.QI")),
        write(id, &format!("S{k}.ID")),
        connect("START.COLD", &format!("S{k}.INIT")),
        connect(&format!("S{k}.IND"), &format!("N{k}.CU")),
        connect(&format!("S{k}.IND"), &format!("V{k}.REQ")),
        connect(&format!("S{k}.IND"), &format!("X{k}.REQ")),
        connect(&format!("S{k}.RD_1"), &format!("V{k}.IN")),
        connect(&format!("S{k}.RD_2"), &format!("X{k}.IN")),
    ]
    .concat()
}

fn boot(n: &mut Node, parts: &[String]) {
    let text = [line("", "CREATE", "<FB Name=\"R\" Type=\"EMB_RES\"/>")]
        .into_iter()
        .chain(parts.iter().cloned())
        .chain([line("R", "START", "")])
        .collect::<String>();
    n.device.boot(&text, 0).unwrap();
}

fn read(n: &mut Node, path: &str) -> String {
    crate::pubsub::tests::read(&mut n.device, path)
}

fn count(n: &mut Node) {
    n.device.execute(
        "R",
        "<Request ID=\"1\" Action=\"WRITE\"><Connection Source=\"$e\" Destination=\"C.CU\"/></Request>",
        0,
    );
}

#[test]
fn multicast_reaches_every_subscriber_of_the_group_each_datagram_once() {
    let mut seg = Segment::new(&[15, 16, 17]);
    // The publisher subscribes to its own group too (looped back, as Linux does).
    boot(&mut seg.nodes[0], &[publisher(GROUP), subscriber(1, GROUP)]);
    boot(&mut seg.nodes[1], &[subscriber(1, GROUP)]);
    boot(
        &mut seg.nodes[2],
        &[subscriber(1, &format!("fbdk[].ip[{GROUP}]"))],
    );
    for n in seg.nodes.iter_mut() {
        assert_eq!(read(n, "S1.QO"), "TRUE");
    }
    assert_eq!(read(&mut seg.nodes[0], "P.STATUS"), "'OK'");
    seg.steps(5);
    for k in 1..=20 {
        count(&mut seg.nodes[0]);
        seg.steps(3);
        assert_eq!(read(&mut seg.nodes[0], "P.STATUS"), "'OK'", "send {k}");
    }
    seg.steps(5);
    for (i, n) in seg.nodes.iter_mut().enumerate() {
        assert_eq!(read(n, "N1.CV"), "20", "node {i}");
        assert_eq!(read(n, "V1.OUT"), "20", "node {i}");
        assert_eq!(read(n, "X1.OUT"), "2.5", "node {i}");
        assert_eq!(read(n, "S1.STATUS"), "'OK'", "node {i}");
        let s = n.udp.borrow().stats;
        assert_eq!((s.dropped, s.errors), (0, 0), "node {i}");
    }
    assert_eq!(seg.nodes[0].udp.borrow().stats.sent, 20);
    assert_eq!(seg.nodes[1].udp.borrow().stats.received, 20);
}

#[test]
fn unicast_reaches_the_addressed_device_only() {
    let mut seg = Segment::new(&[15, 16, 17]);
    boot(&mut seg.nodes[0], &[publisher("10.0.2.16:61501")]);
    // Both bind the port (FORTE's subscriber binds every address of its port).
    boot(
        &mut seg.nodes[1],
        &[subscriber(1, "fbdk[].ip[10.0.2.16:61501]")],
    );
    boot(&mut seg.nodes[2], &[subscriber(1, "10.0.2.17:61501")]);
    seg.steps(5);
    for _ in 0..10 {
        count(&mut seg.nodes[0]);
        seg.steps(3);
    }
    seg.steps(5);
    // The first datagram waits for ARP's answer; none is lost.
    assert_eq!(read(&mut seg.nodes[1], "N1.CV"), "10");
    assert_eq!(read(&mut seg.nodes[1], "V1.OUT"), "10");
    assert_eq!(read(&mut seg.nodes[2], "N1.CV"), "0");
}

#[test]
fn a_datagram_that_does_not_decode_is_an_ind_with_qo_false() {
    let mut seg = Segment::new(&[15, 16]);
    boot(&mut seg.nodes[1], &[subscriber(1, GROUP)]);
    seg.steps(3);
    // A raw datagram from the other stack: a NULL where a UINT and a LREAL belong.
    let stack = &mut seg.nodes[0].server.stack;
    let s = stack
        .socket(linux::AF_INET, linux::SOCK_DGRAM | linux::SOCK_NONBLOCK, 0)
        .unwrap();
    let to = SocketAddr::new(Ipv4Address::new(239, 0, 0, 1), 61500);
    stack.send(s, &[fbdk::NULL], Some(to)).unwrap();
    seg.steps(3);
    let n = &mut seg.nodes[1];
    assert_eq!(read(n, "N1.CV"), "1");
    assert_eq!(read(n, "S1.QO"), "FALSE");
    assert!(read(n, "S1.STATUS").starts_with("'bad message: RD_1"));
    // Then a good one: QO TRUE again.
    let mut buf = [0u8; 64];
    let mut w = fbdk::Writer::new(&mut buf);
    w.value(&fbdk::Value::Fixed(fbdk::Type::UInt, 7)).unwrap();
    w.value(&fbdk::Value::Fixed(fbdk::Type::LReal, 0.5f64.to_bits()))
        .unwrap();
    let len = w.len();
    let stack = &mut seg.nodes[0].server.stack;
    stack.send(s, &buf[..len], Some(to)).unwrap();
    seg.steps(2);
    let n = &mut seg.nodes[1];
    assert_eq!(read(n, "S1.QO"), "TRUE");
    assert_eq!(read(n, "V1.OUT"), "7");
    assert_eq!(read(n, "X1.OUT"), "0.5");
    // Longer than MAX_DATAGRAM: cut, so it does not decode.
    let stack = &mut seg.nodes[0].server.stack;
    stack.send(s, &[0x55; MAX_DATAGRAM + 10], Some(to)).unwrap();
    seg.steps(2);
    let n = &mut seg.nodes[1];
    assert_eq!(read(n, "N1.CV"), "3");
    assert_eq!(read(n, "S1.QO"), "FALSE");
    assert_eq!(read(n, "V1.OUT"), "7");
}

#[test]
fn a_subscriber_queues_a_few_datagrams_and_counts_the_rest() {
    let mut seg = Segment::new(&[15, 16]);
    boot(&mut seg.nodes[0], &[publisher(GROUP)]);
    boot(&mut seg.nodes[1], &[subscriber(1, GROUP)]);
    seg.steps(3);
    seg.nodes[1].polling = false;
    for _ in 0..12 {
        count(&mut seg.nodes[0]);
    }
    assert_eq!(read(&mut seg.nodes[0], "P.STATUS"), "'OK'");
    seg.steps(10);
    seg.nodes[1].polling = true;
    seg.steps(1);
    let n = &mut seg.nodes[1];
    let s = n.udp.borrow().stats;
    assert_eq!(s.received, 12, "{s:?}");
    assert_eq!(s.dropped, 12 - UDP_DEPTH as u64, "{s:?}");
    assert_eq!(read(n, "N1.CV"), UDP_DEPTH.to_string());
    // The first ones, in order.
    assert_eq!(read(n, "V1.OUT"), UDP_DEPTH.to_string());
}

#[test]
fn the_send_queue_is_bounded_and_endpoints_are_limited() {
    let mut e = Endpoints::new();
    let at = |ip: [u8; 4], port| UdpAddr { ip, port };
    let p = e.open(at([239, 0, 0, 1], 1000), false).unwrap();
    for _ in 0..OUT_DEPTH {
        e.send(p, b"x").unwrap();
    }
    assert_eq!(e.send(p, b"x"), Err("send queue full".into()));
    assert!(e.send(p, &[0; MAX_DATAGRAM + 1]).is_err());
    assert!(e.open(at([0; 4], 1000), false).is_err());
    for k in 0..MAX_GROUPS as u8 {
        e.open(at([239, 0, 0, k], 2000), true).unwrap();
    }
    assert!(
        e.open(at([239, 0, 0, 9], 2000), true)
            .unwrap_err()
            .contains("groups")
    );
    for port in 1..MAX_PORTS as u16 {
        e.open(at([10, 0, 2, 1], 3000 + port), true).unwrap();
    }
    assert!(
        e.open(at([10, 0, 2, 1], 4000), true)
            .unwrap_err()
            .contains("ports")
    );
    // A port closed by its last subscriber makes room again at the next pump.
    let last = e.open(at([10, 0, 2, 1], 3001), true).unwrap();
    e.close(last);
    assert!(e.receive(last, &mut [0; 8]).is_none());
    assert!(e.send(last, b"x").is_err());
}
