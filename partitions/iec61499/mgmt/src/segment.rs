//! Test support: devices on one simulated Ethernet segment, each with its own stack (the
//! management server's, as the partition has it), UDP endpoints ([`crate::udp`]) and TCP
//! links ([`crate::tcplink`]) handed to it through a `ProcessIo` as the partition program
//! hands them; every frame reaches every other stack, which takes what is its own. And the
//! boot-file lines the tests build their devices from, and the requests they send them.

extern crate std;

use crate::Device;
use crate::pubsub::NetAddr;
use crate::serve::Access;
use crate::sifb::{ProcessIo, TcpState};
use crate::tcp::server::{Server, Settings};
use crate::tcplink::TcpLinks;
use crate::udp::Endpoints;
use alloc::boxed::Box;
use alloc::rc::Rc;
use core::cell::RefCell;
use std::format;
use std::string::String;
use std::vec::Vec;

/// The partition's side of the endpoints and links, as its `ProcessIo` hands them over.
struct NetIo {
    udp: Rc<RefCell<Endpoints>>,
    tcp: Rc<RefCell<TcpLinks>>,
}

impl ProcessIo for NetIo {
    fn udp_open(&mut self, at: NetAddr, subscribe: bool) -> Result<usize, String> {
        self.udp.borrow_mut().open(at, subscribe)
    }
    fn udp_send(&mut self, endpoint: usize, datagram: &[u8]) -> Result<(), String> {
        self.udp.borrow_mut().send(endpoint, datagram)
    }
    fn udp_receive(&mut self, endpoint: usize, buf: &mut [u8]) -> Option<usize> {
        self.udp.borrow_mut().receive(endpoint, buf)
    }
    fn udp_close(&mut self, endpoint: usize) {
        self.udp.borrow_mut().close(endpoint)
    }
    fn tcp_open(&mut self, at: NetAddr, server: bool) -> Result<usize, String> {
        self.tcp.borrow_mut().open(at, server)
    }
    fn tcp_state(&self, link: usize) -> TcpState {
        self.tcp.borrow().state(link)
    }
    fn tcp_send(&mut self, link: usize, bytes: &[u8]) -> Result<(), String> {
        self.tcp.borrow_mut().send(link, bytes)
    }
    fn tcp_receive(&mut self, link: usize, buf: &mut [u8]) -> usize {
        self.tcp.borrow_mut().receive(link, buf)
    }
    fn tcp_close(&mut self, link: usize) {
        self.tcp.borrow_mut().close(link)
    }
}

pub struct Node {
    pub device: Device,
    pub server: Server,
    pub udp: Rc<RefCell<Endpoints>>,
    pub tcp: Rc<RefCell<TcpLinks>>,
    /// Whether the device takes what arrived at each step.
    pub polling: bool,
    /// Whether the node's frames reach the segment (a pulled cable: false).
    pub wired: bool,
}

pub struct Segment {
    pub nodes: Vec<Node>,
    pub now_ns: u64,
}

pub fn ip(last: u8) -> [u8; 4] {
    [10, 0, 2, last]
}

impl Segment {
    /// Devices at 10.0.2.<last> for each of `lasts`.
    pub fn new(lasts: &[u8]) -> Self {
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
                let tcp = Rc::new(RefCell::new(TcpLinks::new()));
                let mut device = Device::new(iec61499_runtime::Limits::default(), 4);
                device.set_io(Box::new(NetIo {
                    udp: udp.clone(),
                    tcp: tcp.clone(),
                }));
                Node {
                    device,
                    server: Server::new(&settings, 0).unwrap(),
                    udp,
                    tcp,
                    polling: true,
                    wired: true,
                }
            })
            .collect();
        Segment { nodes, now_ns: 0 }
    }

    /// One millisecond: each node's timers, network pass (server, endpoints, links) and
    /// polled FBs, then every frame to every other node.
    pub fn step(&mut self) {
        self.now_ns += 1_000_000;
        let now = self.now_ns;
        let mut frames = Vec::new();
        for (i, n) in self.nodes.iter_mut().enumerate() {
            n.device.advance(now as i64);
            n.server.run(now, &mut n.device);
            n.udp.borrow_mut().pump(&mut n.server.stack);
            n.tcp.borrow_mut().pump(&mut n.server.stack);
            n.server.stack.poll((now / 1000) as i64);
            if n.polling {
                n.device.poll(now as i64);
            }
            while let Some(f) = n.server.stack.device.take() {
                if n.wired {
                    frames.push((i, f));
                }
            }
        }
        for (from, f) in frames {
            for (i, n) in self.nodes.iter_mut().enumerate() {
                if i != from && n.wired {
                    n.server.stack.device.deliver(&f);
                }
            }
        }
    }

    pub fn steps(&mut self, n: usize) {
        for _ in 0..n {
            self.step();
        }
    }
}

/// A management request line of a boot file for resource `dst`.
pub fn line(dst: &str, action: &str, object: &str) -> String {
    format!("{dst};<Request ID=\"1\" Action=\"{action}\">{object}</Request>\n")
}

/// Writes `value` (a literal) to `to` in resource R.
pub fn write(value: &str, to: &str) -> String {
    line(
        "R",
        "WRITE",
        &format!("<Connection Source=\"{value}\" Destination=\"{to}\"/>"),
    )
}

/// Connects `from` to `to` in resource R.
pub fn connect(from: &str, to: &str) -> String {
    line(
        "R",
        "CREATE",
        &format!("<Connection Source=\"{from}\" Destination=\"{to}\"/>"),
    )
}

/// Creates FB `name` of type `ty` in resource R.
pub fn fb(name: &str, ty: &str) -> String {
    line(
        "R",
        "CREATE",
        &format!("<FB Name=\"{name}\" Type=\"{ty}\"/>"),
    )
}

/// Boots `d` with resource R (an EMB_RES) made of `parts`, started.
pub fn boot(d: &mut impl AsMut<Device>, parts: &[String]) {
    let text = [line("", "CREATE", "<FB Name=\"R\" Type=\"EMB_RES\"/>")]
        .into_iter()
        .chain(parts.iter().cloned())
        .chain([line("R", "START", "")])
        .collect::<String>();
    d.as_mut().boot(&text, 0).unwrap();
}

/// A device or a node's device: what the requests below go to.
impl AsMut<Device> for Device {
    fn as_mut(&mut self) -> &mut Device {
        self
    }
}

impl AsMut<Device> for Node {
    fn as_mut(&mut self) -> &mut Device {
        &mut self.device
    }
}

/// The value of `path` (`FB.PORT`) in resource R as a READ request answers it: an IEC
/// literal.
pub fn read(d: &mut impl AsMut<Device>, path: &str) -> String {
    let answer = d.as_mut().execute(
        "R",
        &format!("<Request ID=\"1\" Action=\"READ\"><Connection Source=\"{path}\" Destination=\"\"/></Request>"),
        0,
    );
    answer
        .split("Destination=\"")
        .nth(1)
        .and_then(|s| s.split('"').next())
        .unwrap_or(&answer)
        .replace("&apos;", "'")
}

/// Sets `to` in resource R to the literal `value` while it runs (a WRITE request); the
/// device's answer.
pub fn set(d: &mut impl AsMut<Device>, value: &str, to: &str) -> String {
    d.as_mut().execute(
        "R",
        &format!("<Request ID=\"1\" Action=\"WRITE\"><Connection Source=\"{value}\" Destination=\"{to}\"/></Request>"),
        0,
    )
}

/// Triggers event input `to` (`FB.EVENT`) in resource R: a WRITE of `$e`.
pub fn trigger(d: &mut impl AsMut<Device>, to: &str) -> String {
    set(d, "$e", to)
}
