//! CLIENT/SERVER over TCP between devices on one simulated Ethernet segment
//! ([`crate::segment`]).

extern crate std;

use super::*;
use crate::segment::{Segment, boot, connect, fb, read, set, trigger, write};
use proptest::prelude::*;
use std::string::String;
use std::vec::Vec;

const SERVER: &str = "10.0.2.15:61600";

/// An echo server `S` on `id`: every IND's RD_1 (a UINT) goes back as RSP's SD_1;
/// `M.CV` counts the INDs.
fn echo_server(id: &str) -> Vec<String> {
    alloc::vec![
        fb("S", "SERVER_1_1"),
        fb("V", "UINT2UINT"),
        fb("M", "E_CTU"),
        write("1", "S.QI"),
        write(id, "S.ID"),
        connect("START.COLD", "S.INIT"),
        connect("S.IND", "V.REQ"),
        connect("S.IND", "M.CU"),
        connect("S.RD_1", "V.IN"),
        connect("V.CNF", "S.RSP"),
        connect("V.OUT", "S.SD_1"),
    ]
}

/// A client `CL` of `id` sending an E_CTU's count `C.CV` at each count; `N.CV` counts its
/// CNFs, `V.OUT` holds the last count that came back.
fn counting_client(id: &str) -> Vec<String> {
    alloc::vec![
        fb("C", "E_CTU"),
        fb("CL", "CLIENT_1_1"),
        fb("N", "E_CTU"),
        fb("V", "UINT2UINT"),
        write("1", "CL.QI"),
        write(id, "CL.ID"),
        connect("START.COLD", "CL.INIT"),
        connect("C.CUO", "CL.REQ"),
        connect("C.CV", "CL.SD_1"),
        connect("CL.CNF", "N.CU"),
        connect("CL.CNF", "V.REQ"),
        connect("CL.RD_1", "V.IN"),
    ]
}

/// A server node (10.0.2.15) and client nodes (10.0.2.16, ...), connected.
fn served(clients: usize) -> Segment {
    let lasts: Vec<u8> = (15..16 + clients as u8).collect();
    let mut seg = Segment::new(&lasts);
    boot(&mut seg.nodes[0], &echo_server(SERVER));
    for n in seg.nodes[1..].iter_mut() {
        boot(n, &counting_client(SERVER));
    }
    seg.steps(20);
    seg
}

#[test]
fn a_client_and_an_echo_server_exchange_every_message_in_order() {
    let mut seg = served(1);
    assert_eq!(read(&mut seg.nodes[0], "S.QO"), "TRUE");
    assert_eq!(read(&mut seg.nodes[1], "CL.QO"), "TRUE");
    assert_eq!(read(&mut seg.nodes[1], "CL.STATUS"), "'OK'");
    // Several requests before the server answers any: a stream of messages each way.
    for k in 1..=30 {
        trigger(&mut seg.nodes[1], "C.CU");
        if k % 3 == 0 {
            seg.steps(2);
        }
    }
    seg.steps(20);
    assert_eq!(read(&mut seg.nodes[0], "M.CV"), "30");
    assert_eq!(read(&mut seg.nodes[1], "N.CV"), "30");
    assert_eq!(read(&mut seg.nodes[1], "V.OUT"), "30");
    assert_eq!(read(&mut seg.nodes[1], "CL.STATUS"), "'OK'");
    let (server, client) = (
        seg.nodes[0].tcp.borrow().stats,
        seg.nodes[1].tcp.borrow().stats,
    );
    assert_eq!((server.connected, client.connected), (1, 1));
    // A UINT is 3 bytes in FBDK's encoding.
    assert_eq!((client.bytes_out, server.bytes_in), (90, 90));
    assert_eq!((server.bytes_out, client.bytes_in), (90, 90));
}

#[test]
fn a_server_talks_to_one_client_and_refuses_a_second_at_once() {
    let mut seg = served(2);
    // Both clients connected at the same moment; the server kept the first it accepted.
    let qos: Vec<String> = (1..=2).map(|i| read(&mut seg.nodes[i], "CL.QO")).collect();
    let statuses: Vec<String> = (1..=2)
        .map(|i| read(&mut seg.nodes[i], "CL.STATUS"))
        .collect();
    let kept = qos
        .iter()
        .position(|q| q == "TRUE")
        .expect("one client kept");
    let refused = 1 - kept;
    assert_eq!(qos[refused], "FALSE", "{statuses:?}");
    assert!(
        statuses[refused].contains("closed by the peer"),
        "{statuses:?}"
    );
    assert_eq!(seg.nodes[0].tcp.borrow().stats.refused, 1);
    trigger(&mut seg.nodes[kept + 1], "C.CU");
    seg.steps(10);
    assert_eq!(read(&mut seg.nodes[kept + 1], "N.CV"), "1");
    // The refused client's REQ is refused by its FB: it is not initialised.
    trigger(&mut seg.nodes[refused + 1], "C.CU");
    assert_eq!(
        read(&mut seg.nodes[refused + 1], "CL.STATUS"),
        "'not initialised'"
    );
}

#[test]
fn when_its_client_goes_the_server_listens_for_the_next() {
    let mut seg = served(2);
    let kept = if read(&mut seg.nodes[1], "CL.QO") == "TRUE" {
        1
    } else {
        2
    };
    let other = 3 - kept;
    trigger(&mut seg.nodes[kept], "C.CU");
    seg.steps(10);
    // The kept client closes (INIT with QI FALSE); the other connects again.
    set(&mut seg.nodes[kept], "FALSE", "CL.QI");
    trigger(&mut seg.nodes[kept], "CL.INIT");
    assert_eq!(read(&mut seg.nodes[kept], "CL.QO"), "FALSE");
    assert_eq!(read(&mut seg.nodes[kept], "CL.STATUS"), "'OK'");
    seg.steps(20);
    trigger(&mut seg.nodes[other], "CL.INIT");
    seg.steps(20);
    assert_eq!(read(&mut seg.nodes[other], "CL.QO"), "TRUE");
    for _ in 0..3 {
        trigger(&mut seg.nodes[other], "C.CU");
    }
    seg.steps(20);
    assert_eq!(read(&mut seg.nodes[other], "N.CV"), "3");
    assert_eq!(read(&mut seg.nodes[0], "M.CV"), "4");
    assert_eq!(seg.nodes[0].tcp.borrow().stats.connected, 2);
    assert_eq!(read(&mut seg.nodes[0], "S.QO"), "TRUE");
}

#[test]
fn a_client_learns_why_it_has_no_connection() {
    let mut seg = Segment::new(&[15, 16]);
    // Nobody listens on 10.0.2.15:61600: the connection is refused.
    boot(&mut seg.nodes[1], &counting_client(SERVER));
    seg.steps(20);
    assert_eq!(read(&mut seg.nodes[1], "CL.QO"), "FALSE");
    assert!(
        read(&mut seg.nodes[1], "CL.STATUS").contains("cannot connect to 10.0.2.15:61600"),
        "{}",
        read(&mut seg.nodes[1], "CL.STATUS")
    );
    assert_eq!(seg.nodes[1].tcp.borrow().open_count(), 0);
    // A server that goes away ends its client's link: INITO with QO FALSE.
    let mut seg = served(1);
    set(&mut seg.nodes[0], "FALSE", "S.QI");
    trigger(&mut seg.nodes[0], "S.INIT");
    seg.steps(20);
    assert_eq!(read(&mut seg.nodes[1], "CL.QO"), "FALSE");
    assert!(read(&mut seg.nodes[1], "CL.STATUS").contains("closed by the peer"));
}

#[test]
fn a_message_of_other_types_is_a_cnf_with_qo_false_and_the_stream_goes_on() {
    let mut seg = Segment::new(&[15, 16]);
    // A server that answers with a STRING where the client expects a UINT.
    boot(
        &mut seg.nodes[0],
        &[
            fb("S", "SERVER_1_1"),
            fb("V", "UINT2UINT"),
            fb("T", "STRING2STRING"),
            write("1", "S.QI"),
            write(SERVER, "S.ID"),
            write("'wrong'", "T.IN"),
            connect("START.COLD", "S.INIT"),
            connect("S.IND", "V.REQ"),
            connect("S.RD_1", "V.IN"),
            connect("V.CNF", "T.REQ"),
            connect("T.CNF", "S.RSP"),
            connect("T.OUT", "S.SD_1"),
        ],
    );
    boot(&mut seg.nodes[1], &counting_client(SERVER));
    seg.steps(20);
    trigger(&mut seg.nodes[1], "C.CU");
    seg.steps(20);
    assert_eq!(read(&mut seg.nodes[1], "CL.QO"), "FALSE");
    assert!(read(&mut seg.nodes[1], "CL.STATUS").starts_with("'bad message: RD_1"));
    assert_eq!(read(&mut seg.nodes[1], "N.CV"), "1");
    // The link stays up: the next answer is reported too.
    trigger(&mut seg.nodes[1], "C.CU");
    seg.steps(20);
    assert_eq!(read(&mut seg.nodes[1], "N.CV"), "2");
    assert_eq!(seg.nodes[1].tcp.borrow().open_count(), 1);
}

#[test]
fn links_are_bounded_and_checked_at_open() {
    let mut links = TcpLinks::new();
    let at = |ip, port| NetAddr { ip, port };
    for k in 0..MAX_LINKS {
        links
            .open(at([10, 0, 2, 1], 1000 + k as u16), k % 2 == 0)
            .unwrap();
    }
    let err = links.open(at([10, 0, 2, 1], 999), false).unwrap_err();
    assert!(err.contains("at most 8"), "{err}");
    links.close(3);
    assert_eq!(links.open(at([10, 0, 2, 1], 999), false), Ok(3));
    let err = links.open(at([10, 0, 2, 1], 1000), true);
    let mut fresh = TcpLinks::new();
    fresh.open(at([0, 0, 0, 0], 1000), true).unwrap();
    assert!(
        fresh
            .open(at([10, 0, 0, 1], 1000), true)
            .unwrap_err()
            .contains("port 1000")
    );
    assert!(err.is_err());
    for bad in [[0, 0, 0, 0], [239, 0, 0, 1], [255, 255, 255, 255]] {
        assert!(
            fresh
                .open(at(bad, 80), false)
                .unwrap_err()
                .contains("no server address")
        );
    }
    // Nothing connected yet: no send; unknown links are refused, not a panic.
    assert_eq!(fresh.send(0, b"x"), Err("not connected yet".into()));
    assert!(fresh.send(7, b"x").is_err());
    assert_eq!(fresh.receive(7, &mut [0; 4]), 0);
    assert!(matches!(fresh.state(7), TcpState::Down(_)));
    fresh.close(7);
}

#[test]
fn the_send_buffer_is_bounded() {
    let seg = served(1);
    let mut links = seg.nodes[1].tcp.borrow_mut();
    let link = (0..MAX_LINKS)
        .find(|&l| matches!(links.state(l), TcpState::Connected { .. }))
        .unwrap();
    links.send(link, &[0; BUFFER]).unwrap();
    assert_eq!(links.send(link, &[0]), Err("send buffer full".into()));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Whatever bytes a client sends, cut anyhow, the server's device takes them without
    /// a panic and keeps serving: a well-formed request afterwards from a new client is
    /// answered.
    #[test]
    fn any_bytes_from_a_client_leave_the_server_serving(
        chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..300), 0..6)
    ) {
        let mut seg = Segment::new(&[15, 16, 17]);
        boot(&mut seg.nodes[0], &echo_server(SERVER));
        let raw = seg.nodes[1]
            .tcp
            .borrow_mut()
            .open(NetAddr { ip: [10, 0, 2, 15], port: 61600 }, false)
            .unwrap();
        seg.steps(20);
        for chunk in &chunks {
            let _ = seg.nodes[1].tcp.borrow_mut().send(raw, chunk);
            seg.steps(3);
        }
        seg.nodes[1].tcp.borrow_mut().close(raw);
        seg.steps(20);
        boot(&mut seg.nodes[2], &counting_client(SERVER));
        seg.steps(20);
        trigger(&mut seg.nodes[2], "C.CU");
        seg.steps(20);
        prop_assert_eq!(read(&mut seg.nodes[2], "N.CV"), "1");
        prop_assert_eq!(read(&mut seg.nodes[2], "V.OUT"), "1");
    }
}

#[test]
fn the_raw_layer_carries_a_string_s_bytes_over_tcp_both_ways() {
    let mut seg = Segment::new(&[15, 16]);
    let id = "raw[].ip[10.0.2.15:61601]";
    // An echo server of raw strings, and a client of them.
    boot(
        &mut seg.nodes[0],
        &[
            fb("S", "SERVER_1_1"),
            fb("T", "STRING2STRING"),
            write("1", "S.QI"),
            write(id, "S.ID"),
            connect("START.COLD", "S.INIT"),
            connect("S.IND", "T.REQ"),
            connect("S.RD_1", "T.IN"),
            connect("T.CNF", "S.RSP"),
            connect("T.OUT", "S.SD_1"),
        ],
    );
    boot(
        &mut seg.nodes[1],
        &[
            fb("CL", "CLIENT_1_1"),
            fb("V", "STRING2STRING"),
            write("1", "CL.QI"),
            write(id, "CL.ID"),
            write("'GET level'", "CL.SD_1"),
            connect("START.COLD", "CL.INIT"),
            connect("CL.CNF", "V.REQ"),
            connect("CL.RD_1", "V.IN"),
        ],
    );
    seg.steps(20);
    assert_eq!(read(&mut seg.nodes[1], "CL.QO"), "TRUE");
    trigger(&mut seg.nodes[1], "CL.REQ");
    seg.steps(20);
    assert_eq!(read(&mut seg.nodes[0], "T.OUT"), "'GET level'");
    assert_eq!(read(&mut seg.nodes[1], "V.OUT"), "'GET level'");
    // The bytes on the wire are the string's, nothing else.
    assert_eq!(seg.nodes[1].tcp.borrow().stats.bytes_out, 9);
}
