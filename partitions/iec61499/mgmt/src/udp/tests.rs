//! PUBLISH/SUBSCRIBE over UDP between devices on one simulated Ethernet segment
//! ([`crate::segment`]).

extern crate std;

use super::*;
use crate::segment::{Node, Segment, boot, connect, fb, read, trigger, write};
use alloc::string::ToString;
use std::format;
use std::string::String;

const GROUP: &str = "239.0.0.1:61500";

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

fn count(n: &mut Node) {
    trigger(n, "C.CU");
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
    let at = |ip: [u8; 4], port| NetAddr { ip, port };
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

#[test]
fn a_group_is_left_when_its_last_subscriber_goes_and_its_place_serves_another() {
    let mut seg = Segment::new(&[15]);
    let at = |k: u8| NetAddr {
        ip: [239, 0, 0, k],
        port: 2000,
    };
    let subscribers: std::vec::Vec<usize> = (1..=MAX_GROUPS as u8)
        .map(|k| seg.nodes[0].udp.borrow_mut().open(at(k), true).unwrap())
        .collect();
    seg.steps(2);
    // The stack's group table is full: a group it was not asked to leave stays.
    assert_eq!(seg.nodes[0].udp.borrow().stats.errors, 0);
    seg.nodes[0].udp.borrow_mut().close(subscribers[0]);
    seg.steps(2);
    seg.nodes[0].udp.borrow_mut().open(at(9), true).unwrap();
    seg.steps(2);
    let udp = seg.nodes[0].udp.borrow();
    assert_eq!(udp.stats.errors, 0, "{:?}", udp.errors);
    assert_eq!(udp.groups.len(), MAX_GROUPS);
    assert!(!udp.groups.iter().any(|(g, _)| *g == at(1).ip));
}

#[test]
fn the_raw_layer_sends_and_receives_a_string_s_bytes_as_they_are() {
    let mut seg = Segment::new(&[15, 16]);
    let id = "raw[].ip[10.0.2.16:61700]";
    boot(
        &mut seg.nodes[0],
        &[
            fb("P", "PUBLISH_1"),
            write("1", "P.QI"),
            write(id, "P.ID"),
            write("'hello, plain peer'", "P.SD_1"),
            connect("START.COLD", "P.INIT"),
            // A raw publisher of a DINT: refused at INIT, with the reason.
            fb("Q", "PUBLISH_1"),
            write("1", "Q.QI"),
            write(id, "Q.ID"),
            write("DINT#5", "Q.SD_1"),
            connect("START.COLD", "Q.INIT"),
        ],
    );
    boot(
        &mut seg.nodes[1],
        &[
            fb("S", "SUBSCRIBE_1"),
            fb("T", "STRING2STRING"),
            write("1", "S.QI"),
            write(id, "S.ID"),
            connect("START.COLD", "S.INIT"),
            connect("S.IND", "T.REQ"),
            connect("S.RD_1", "T.IN"),
        ],
    );
    assert_eq!(read(&mut seg.nodes[0], "P.QO"), "TRUE");
    assert_eq!(read(&mut seg.nodes[0], "Q.QO"), "FALSE");
    assert!(read(&mut seg.nodes[0], "Q.STATUS").contains("the raw layer carries one STRING"));
    seg.steps(5);
    trigger(&mut seg.nodes[0], "P.REQ");
    seg.steps(5);
    assert_eq!(read(&mut seg.nodes[1], "T.OUT"), "'hello, plain peer'");
    // A datagram from a peer that speaks no IEC 61499 encoding: its bytes are the STRING.
    let plain = seg.nodes[0]
        .udp
        .borrow_mut()
        .open(
            NetAddr {
                ip: [10, 0, 2, 16],
                port: 61700,
            },
            false,
        )
        .unwrap();
    seg.nodes[0]
        .udp
        .borrow_mut()
        .send(plain, b"T=21.5C")
        .unwrap();
    seg.steps(5);
    assert_eq!(read(&mut seg.nodes[1], "T.OUT"), "'T=21.5C'");
    assert_eq!(read(&mut seg.nodes[1], "S.STATUS"), "'OK'");
}
