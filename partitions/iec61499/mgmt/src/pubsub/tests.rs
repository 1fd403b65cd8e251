//! PUBLISH/SUBSCRIBE between two devices over a loopback of queuing ports (a channel per
//! port name), as two partitions joined by the configuration's channels.

extern crate std;

use super::*;
use crate::Device;
use crate::segment::{boot, connect, fb, read, set, trigger, write};
use crate::sifb::ProcessIo;
use iec61499_runtime::Limits;

fn device(bus: &Loopback) -> Device {
    let mut d = Device::new(Limits::default(), 2);
    d.set_io(Box::new(bus.clone()));
    d
}

/// A publisher of an E_CTU's count and a LREAL on port `counts`, a subscriber of them.
fn pair(bus: &Loopback) -> (Device, Device) {
    let mut publisher = device(bus);
    boot(
        &mut publisher,
        &[
            fb("C", "E_CTU"),
            fb("P", "PUBLISH_2"),
            write("1", "P.QI"),
            write("counts", "P.ID"),
            write("LREAL#2.5", "P.SD_2"),
            connect("START.COLD", "P.INIT"),
            connect("C.CUO", "P.REQ"),
            connect("C.CV", "P.SD_1"),
        ],
    );
    let mut subscriber = device(bus);
    boot(
        &mut subscriber,
        &[
            fb("S", "SUBSCRIBE_2"),
            fb("N", "E_CTU"),
            fb("V", "UINT2UINT"),
            fb("X", "LREAL2LREAL"),
            write("1", "S.QI"),
            write("counts", "S.ID"),
            connect("START.COLD", "S.INIT"),
            connect("S.IND", "N.CU"),
            connect("S.IND", "V.REQ"),
            connect("S.IND", "X.REQ"),
            connect("S.RD_1", "V.IN"),
            connect("S.RD_2", "X.IN"),
        ],
    );
    (publisher, subscriber)
}

fn count(publisher: &mut Device) -> String {
    trigger(publisher, "C.CU")
}

#[test]
fn a_subscriber_gets_each_message_with_its_values() {
    let bus = Loopback::default();
    let (mut publisher, mut subscriber) = pair(&bus);
    assert_eq!(read(&mut publisher, "P.QO"), "TRUE");
    assert_eq!(read(&mut subscriber, "S.QO"), "TRUE");
    assert!(subscriber.polls() && !publisher.polls());
    for _ in 0..3 {
        count(&mut publisher);
    }
    assert_eq!(read(&mut publisher, "P.STATUS"), "'OK'");
    subscriber.poll(0);
    // Three INDs, each with its own count: the last one left 3 in V.
    assert_eq!(read(&mut subscriber, "N.CV"), "3");
    assert_eq!(read(&mut subscriber, "V.OUT"), "3");
    assert_eq!(read(&mut subscriber, "X.OUT"), "2.5");
    // The port holds 4 messages: the fifth send is refused with its reason.
    for _ in 0..5 {
        count(&mut publisher);
    }
    assert_eq!(read(&mut publisher, "P.QO"), "FALSE");
    assert_eq!(read(&mut publisher, "P.STATUS"), "'port full'");
    subscriber.poll(0);
    assert_eq!(read(&mut subscriber, "N.CV"), "7");
    assert_eq!(read(&mut subscriber, "V.OUT"), "7");
}

#[test]
fn a_bad_message_or_a_missing_port_is_reported() {
    let bus = Loopback::with_ports(&["counts"]);
    let (_, mut subscriber) = pair(&bus);
    // A message of other types: IND with QO FALSE, RD unchanged.
    bus.clone().send("counts", &[fbdk::NULL]);
    subscriber.poll(0);
    assert_eq!(read(&mut subscriber, "S.QO"), "FALSE");
    assert!(read(&mut subscriber, "S.STATUS").starts_with("'bad message: RD_1"));
    assert_eq!(read(&mut subscriber, "N.CV"), "1");
    // INIT on a port the partition does not have.
    let mut d = device(&bus);
    boot(
        &mut d,
        &[
            fb("P", "PUBLISH_0"),
            write("1", "P.QI"),
            write("nowhere", "P.ID"),
            connect("START.COLD", "P.INIT"),
        ],
    );
    assert_eq!(read(&mut d, "P.QO"), "FALSE");
    assert_eq!(read(&mut d, "P.STATUS"), "'no queuing output port nowhere'");
    // A REQ before a good INIT sends nothing.
    trigger(&mut d, "P.REQ");
    assert_eq!(read(&mut d, "P.STATUS"), "'not initialised'");
    assert!(bus.clone().receive("nowhere", &mut [0; 64]).is_none());
}

#[test]
fn values_cross_the_encoding_unchanged() {
    use iec61499_runtime::DataType as T;
    for (ty, v) in [
        (T::Bool, Value::Bool(true)),
        (T::SInt, Value::Int(-5)),
        (T::DInt, Value::Int(-70_000)),
        (T::UDInt, Value::UInt(4_000_000_000)),
        (T::Real, Value::Real(0.5)),
        (T::LReal, Value::Real(-1.25e300)),
        (T::Time, Value::Time(1_500_000)),
        (T::String, Value::String("tank".into())),
        (T::Word, Value::UInt(0xBEEF)),
    ] {
        let mut buf = [0u8; 64];
        let mut w = fbdk::Writer::new(&mut buf);
        w.value(&to_wire(ty, &v).unwrap()).unwrap();
        let len = w.len();
        let mut r = fbdk::Reader::new(&buf[..len]);
        let back = from_wire(ty, r.value(wire_type(ty).unwrap()).unwrap());
        assert_eq!(back, v, "{ty:?}");
    }
}

#[test]
fn ip_ids_are_forte_s_and_other_ids_name_ports() {
    let at = |ip, port| {
        Some(Ok(IpId {
            layer: Layer::Fbdk,
            at: NetAddr { ip, port },
        }))
    };
    assert_eq!(ip_id("239.0.0.1:61500"), at([239, 0, 0, 1], 61500));
    assert_eq!(ip_id(" 10.0.2.16:5000 "), at([10, 0, 2, 16], 5000));
    assert_eq!(
        ip_id("fbdk[].ip[239.192.0.2:61499]"),
        at([239, 192, 0, 2], 61499)
    );
    assert_eq!(
        ip_id("raw[].ip[10.0.2.2:7]"),
        Some(Ok(IpId {
            layer: Layer::Raw,
            at: NetAddr {
                ip: [10, 0, 2, 2],
                port: 7
            }
        }))
    );
    assert!(ip_id("239.0.0.1:61500").unwrap().unwrap().at.is_multicast());
    assert!(!ip_id("10.0.0.1:1").unwrap().unwrap().at.is_multicast());
    assert_eq!(
        ip_id("fbdk[].ip[239.0.0.1:61500]")
            .unwrap()
            .unwrap()
            .at
            .to_string(),
        "239.0.0.1:61500"
    );
    // Shaped as an address but not one: why, not a port name.
    for bad in [
        "256.0.0.1:1",
        "1.2.3:5",
        "1.2.3.4.5:5",
        "1.2.3.4:0",
        "1.2.3.4:65536",
        "1..3.4:5",
        "fbdk[].ip[host:5]",
        "fbdk[].ip[1.2.3.4]",
        "fbdk[].ip[1.2.3.4:5",
        "raw[].ip[1.2.3.4]",
    ] {
        assert!(matches!(ip_id(bad), Some(Err(_))), "{bad}");
    }
    // Queuing ports' names, as before.
    for name in ["counts", "rpc", "a:b", "", "eth-rx", "WSTRIGN#x", "1234"] {
        assert_eq!(ip_id(name), None, "{name}");
    }
}

/// A device whose resource has `P` (PUBLISH_1) and `S` (SUBSCRIBE_1) on `id`.
fn pub_and_sub(io: Box<dyn ProcessIo>, id: &str) -> Device {
    let mut d = Device::new(Limits::default(), 2);
    d.set_io(io);
    boot(
        &mut d,
        &[
            fb("P", "PUBLISH_1"),
            fb("S", "SUBSCRIBE_1"),
            fb("N", "E_CTU"),
            write("1", "P.QI"),
            write("1", "S.QI"),
            write("DINT#-3", "P.SD_1"),
            write(id, "P.ID"),
            write(id, "S.ID"),
            fb("V", "DINT2DINT"),
            connect("START.COLD", "P.INIT"),
            connect("P.INITO", "S.INIT"),
            connect("S.IND", "N.CU"),
            connect("S.IND", "V.REQ"),
            connect("S.RD_1", "V.IN"),
        ],
    );
    d
}

fn publish(d: &mut Device) {
    trigger(d, "P.REQ");
}

#[test]
fn without_a_network_interface_an_ip_id_does_not_open() {
    let mut d = pub_and_sub(Box::new(crate::sifb::NoPorts), "fbdk[].ip[239.0.0.1:61500]");
    for fb in ["P", "S"] {
        assert_eq!(read(&mut d, &format!("{fb}.QO")), "FALSE");
        assert_eq!(
            read(&mut d, &format!("{fb}.STATUS")),
            "'no network interface'"
        );
    }
    assert!(!d.polls());
    publish(&mut d);
    assert_eq!(read(&mut d, "P.STATUS"), "'not initialised'");
    // A bad address says why, before the interface matters.
    let mut d = pub_and_sub(Box::new(crate::sifb::NoPorts), "1.2.3.4:99999");
    assert!(read(&mut d, "P.STATUS").starts_with("'bad IP address 1.2.3.4:99999"));
}

#[test]
fn the_loopback_carries_udp_as_a_network_multicast_and_unicast() {
    let bus = Loopback::default();
    // Two devices on a group: each gets the other's and its own datagrams.
    let mut a = pub_and_sub(Box::new(bus.end_at([10, 0, 0, 1])), "239.1.1.1:7000");
    let mut b = pub_and_sub(Box::new(bus.end_at([10, 0, 0, 2])), "239.1.1.1:7000");
    assert_eq!(read(&mut a, "S.STATUS"), "'OK'");
    publish(&mut a);
    publish(&mut b);
    a.poll(0);
    b.poll(0);
    assert_eq!(read(&mut a, "N.CV"), "2");
    assert_eq!(read(&mut b, "N.CV"), "2");
    assert_eq!(read(&mut b, "V.OUT"), "-3");
    // Unicast to 10.0.0.2's port: only b's subscriber of that port.
    let mut c = pub_and_sub(Box::new(bus.end_at([10, 0, 0, 1])), "10.0.0.2:7001");
    let mut d = pub_and_sub(Box::new(bus.end_at([10, 0, 0, 2])), "10.0.0.2:7001");
    publish(&mut c);
    c.poll(0);
    d.poll(0);
    assert_eq!(read(&mut c, "N.CV"), "0");
    assert_eq!(read(&mut d, "N.CV"), "1");
    // A datagram that does not decode: IND, QO FALSE, why.
    bus.udp_inject(
        NetAddr {
            ip: [10, 0, 0, 2],
            port: 7001,
        },
        &[0xFF, 0x00],
    );
    d.poll(0);
    assert_eq!(read(&mut d, "N.CV"), "2");
    assert_eq!(read(&mut d, "S.QO"), "FALSE");
    assert!(read(&mut d, "S.STATUS").starts_with("'bad message: "));
    // Never waiting: more than a queue's worth is dropped and counted; the sends succeed.
    for _ in 0..UDP_DEPTH + 3 {
        publish(&mut c);
        assert_eq!(read(&mut c, "P.STATUS"), "'OK'");
    }
    assert_eq!(bus.udp_dropped(), 3);
    d.poll(0);
    assert_eq!(read(&mut d, "N.CV"), (2 + UDP_DEPTH).to_string());
    // INIT without QI closes: nothing more arrives.
    set(&mut d, "0", "S.QI");
    trigger(&mut d, "S.INIT");
    assert!(!d.polls());
    publish(&mut c);
    assert_eq!(bus.udp_dropped(), 3);
}

proptest::proptest! {
    /// Any ID parses to an address, a reason or a port name; any datagram decodes or says
    /// why: never a panic.
    #[test]
    fn any_id_or_datagram_is_an_answer(
        id in ".{0,40}",
        digits in "[0-9.:]{0,24}",
        bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..64),
    ) {
        let _ = ip_id(&id);
        let _ = ip_id(&digits);
        let _ = ip_id(&format!("fbdk[].ip[{digits}]"));
        use iec61499_runtime::DataType as T;
        let _ = decode(&[Some(T::UInt), Some(T::String), Some(T::LReal)], &bytes);
        let bus = Loopback::default();
        let mut d = pub_and_sub(Box::new(bus.end()), "239.1.1.1:7000");
        bus.udp_inject(NetAddr { ip: [239, 1, 1, 1], port: 7000 }, &bytes);
        d.poll(0);
    }
}

#[test]
fn a_stream_of_messages_cut_anywhere_decodes_into_the_same_messages() {
    let types = [
        Some(DataType::UInt),
        Some(DataType::String),
        Some(DataType::LReal),
    ];
    let messages: Vec<Vec<Value>> = (0..3u16)
        .map(|k| {
            alloc::vec![
                Value::UInt(u64::from(k)),
                Value::String("x".repeat(usize::from(k) * 7)),
                Value::Real(f64::from(k) / 3.0),
            ]
        })
        .collect();
    let stream: Vec<u8> = messages
        .iter()
        .flat_map(|m| encode(&types, m, 256).unwrap())
        .collect();
    // Each prefix gives the whole messages it holds, then asks for more.
    for cut in 0..=stream.len() {
        let mut rest = &stream[..cut];
        let mut got = Vec::new();
        while let Some((values, used)) = decode_first(&types, rest).unwrap() {
            got.push(values);
            rest = &rest[used..];
        }
        assert!(messages.starts_with(&got), "cut {cut}");
        assert_eq!(got.len() == 3, cut == stream.len(), "cut {cut}");
    }
    // A wrong tag is an error, not a wait; no types: a message is one NULL.
    assert!(decode_first(&types, &[0xff]).is_err());
    assert_eq!(
        decode_first(&[], &[fbdk::NULL, fbdk::NULL]),
        Ok(Some((Vec::new(), 1)))
    );
    assert_eq!(decode_first(&[], &[]), Ok(None));
    assert!(decode_first(&[], &[1]).is_err());
}
