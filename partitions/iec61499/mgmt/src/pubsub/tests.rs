//! PUBLISH/SUBSCRIBE between two devices over a loopback of queuing ports (a channel per
//! port name), as two partitions joined by the configuration's channels.

extern crate std;

use super::*;
use crate::Device;
use crate::sifb::ProcessIo;
use iec61499_runtime::Limits;

fn device(bus: &Loopback) -> Device {
    let mut d = Device::new(Limits::default(), 2);
    d.set_io(Box::new(bus.clone()));
    d
}

fn line(dst: &str, action: &str, object: &str) -> String {
    format!("{dst};<Request ID=\"1\" Action=\"{action}\">{object}</Request>\n")
}

fn read(d: &mut Device, path: &str) -> String {
    let answer = d.execute(
        "R",
        &format!("<Request ID=\"1\" Action=\"READ\"><Connection Source=\"{path}\" Destination=\"\"/></Request>"),
        0,
    );
    answer
        .split("Source=\"")
        .nth(1)
        .and_then(|s| s.split('"').next())
        .unwrap_or(&answer)
        .replace("&apos;", "'")
}

/// A publisher of an E_CTU's count and a LREAL on port `counts`, a subscriber of them.
fn pair(bus: &Loopback) -> (Device, Device) {
    let mut publisher = device(bus);
    let boot: String = [
        line("", "CREATE", "<FB Name=\"R\" Type=\"EMB_RES\"/>"),
        line("R", "CREATE", "<FB Name=\"C\" Type=\"E_CTU\"/>"),
        line("R", "CREATE", "<FB Name=\"P\" Type=\"PUBLISH_2\"/>"),
        line(
            "R",
            "WRITE",
            "<Connection Source=\"1\" Destination=\"P.QI\"/>",
        ),
        line(
            "R",
            "WRITE",
            "<Connection Source=\"counts\" Destination=\"P.ID\"/>",
        ),
        line(
            "R",
            "WRITE",
            "<Connection Source=\"LREAL#2.5\" Destination=\"P.SD_2\"/>",
        ),
        line(
            "R",
            "CREATE",
            "<Connection Source=\"START.COLD\" Destination=\"P.INIT\"/>",
        ),
        line(
            "R",
            "CREATE",
            "<Connection Source=\"C.CUO\" Destination=\"P.REQ\"/>",
        ),
        line(
            "R",
            "CREATE",
            "<Connection Source=\"C.CV\" Destination=\"P.SD_1\"/>",
        ),
        line("R", "START", ""),
    ]
    .concat();
    publisher.boot(&boot, 0).unwrap();
    let mut subscriber = device(bus);
    let boot: String = [
        line("", "CREATE", "<FB Name=\"R\" Type=\"EMB_RES\"/>"),
        line("R", "CREATE", "<FB Name=\"S\" Type=\"SUBSCRIBE_2\"/>"),
        line("R", "CREATE", "<FB Name=\"N\" Type=\"E_CTU\"/>"),
        line("R", "CREATE", "<FB Name=\"V\" Type=\"UINT2UINT\"/>"),
        line("R", "CREATE", "<FB Name=\"X\" Type=\"LREAL2LREAL\"/>"),
        line(
            "R",
            "WRITE",
            "<Connection Source=\"1\" Destination=\"S.QI\"/>",
        ),
        line(
            "R",
            "WRITE",
            "<Connection Source=\"counts\" Destination=\"S.ID\"/>",
        ),
        line(
            "R",
            "CREATE",
            "<Connection Source=\"START.COLD\" Destination=\"S.INIT\"/>",
        ),
        line(
            "R",
            "CREATE",
            "<Connection Source=\"S.IND\" Destination=\"N.CU\"/>",
        ),
        line(
            "R",
            "CREATE",
            "<Connection Source=\"S.IND\" Destination=\"V.REQ\"/>",
        ),
        line(
            "R",
            "CREATE",
            "<Connection Source=\"S.IND\" Destination=\"X.REQ\"/>",
        ),
        line(
            "R",
            "CREATE",
            "<Connection Source=\"S.RD_1\" Destination=\"V.IN\"/>",
        ),
        line(
            "R",
            "CREATE",
            "<Connection Source=\"S.RD_2\" Destination=\"X.IN\"/>",
        ),
        line("R", "START", ""),
    ]
    .concat();
    subscriber.boot(&boot, 0).unwrap();
    (publisher, subscriber)
}

fn count(publisher: &mut Device) -> String {
    publisher.execute(
        "R",
        "<Request ID=\"1\" Action=\"WRITE\"><Connection Source=\"$e\" Destination=\"C.CU\"/></Request>",
        0,
    )
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
    let boot: String = [
        line("", "CREATE", "<FB Name=\"R\" Type=\"EMB_RES\"/>"),
        line("R", "CREATE", "<FB Name=\"P\" Type=\"PUBLISH_0\"/>"),
        line(
            "R",
            "WRITE",
            "<Connection Source=\"1\" Destination=\"P.QI\"/>",
        ),
        line(
            "R",
            "WRITE",
            "<Connection Source=\"nowhere\" Destination=\"P.ID\"/>",
        ),
        line(
            "R",
            "CREATE",
            "<Connection Source=\"START.COLD\" Destination=\"P.INIT\"/>",
        ),
        line("R", "START", ""),
    ]
    .concat();
    d.boot(&boot, 0).unwrap();
    assert_eq!(read(&mut d, "P.QO"), "FALSE");
    assert_eq!(read(&mut d, "P.STATUS"), "'no queuing output port nowhere'");
    // A REQ before a good INIT sends nothing.
    d.execute(
        "R",
        "<Request ID=\"1\" Action=\"WRITE\"><Connection Source=\"$e\" Destination=\"P.REQ\"/></Request>",
        0,
    );
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
