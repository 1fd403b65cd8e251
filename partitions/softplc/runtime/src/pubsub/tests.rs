//! Publications decode as FORTE's SUBSCRIBE would read them, and subscriptions take
//! messages whole or not at all.

use super::*;
use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame};
use std::string::ToString;
use std::vec;
use std::vec::Vec;

const PROGRAM: &str = "PROGRAM Main
VAR
  level : LREAL;
  valve : REAL;
  alarm : BOOL;
  count : DINT;
  mode : STRING[8];
  since : TIME;
  ptr : REF_TO INT;
END_VAR
END_PROGRAM";

/// The image, the data after the test's writes, and the data as the program starts.
fn setup() -> (Vec<u8>, Vec<u8>, Vec<u8>) {
    let files = [("p.st".to_string(), PROGRAM.to_string())];
    let image = plc_compiler::compile(&files, &plc_compiler::Options::default())
        .unwrap()
        .0
        .image;
    let parsed = Image::parse(&image).unwrap();
    let verified = plc_vm::verify::verify(&parsed).unwrap();
    let mut data = vec![0u8; parsed.data_size() as usize];
    let (mut s, mut c, mut t) = ([0u64; 16], [CallFrame::EMPTY; 4], [TryFrame::EMPTY; 2]);
    let mut m = Machine::new(
        verified,
        Memory {
            data: &mut data,
            stack: &mut s,
            calls: &mut c,
            tries: &mut t,
        },
    )
    .unwrap();
    let initial = m.data().to_vec();
    m.write_var("Main.level", Value::LReal(0.75)).unwrap();
    m.write_var("Main.valve", Value::Real(0.5)).unwrap();
    m.write_var("Main.alarm", Value::Bool(true)).unwrap();
    m.write_var("Main.count", Value::Int(-3)).unwrap();
    m.write_var("Main.mode", Value::String(b"auto")).unwrap();
    m.write_var("Main.since", Value::Time(2_000_000)).unwrap();
    let data = m.data().to_vec();
    (image, data, initial)
}

const NAMES: [&str; 6] = [
    "Main.level",
    "Main.valve",
    "Main.alarm",
    "Main.count",
    "Main.mode",
    "Main.since",
];

#[test]
fn a_publication_is_fbdk() {
    let (image, data, _) = setup();
    let image = Image::parse(&image).unwrap();
    let mut out = [0u8; 128];
    let n = publish(&image, &data, &NAMES, &mut out).unwrap();
    let mut expected = vec![0x4B];
    expected.extend_from_slice(&0.75f64.to_bits().to_be_bytes());
    expected.push(0x4A);
    expected.extend_from_slice(&0.5f32.to_bits().to_be_bytes());
    expected.push(0x41);
    expected.extend_from_slice(&[0x44, 0xFF, 0xFF, 0xFF, 0xFD]);
    expected.extend_from_slice(&[0x50, 0, 4, b'a', b'u', b't', b'o']);
    expected.extend_from_slice(&[0x4C, 0, 0, 0, 0, 0, 0, 0x07, 0xD0]); // 2 ms = 2000 us
    assert_eq!(&out[..n], &expected[..]);
    assert_eq!(publish(&image, &data, &[], &mut out), Ok(1));
    assert_eq!(out[0], fbdk::NULL);
    assert_eq!(
        publish(&image, &data, &NAMES, &mut [0u8; 10]),
        Err(PubSubError::TooLong)
    );
}

#[test]
fn a_subscription_takes_a_message_whole_or_not_at_all() {
    let (image_bytes, data, initial) = setup();
    let image = Image::parse(&image_bytes).unwrap();
    let mut message = [0u8; 128];
    let n = publish(&image, &data, &NAMES, &mut message).unwrap();
    let mut target = initial.clone();
    subscribe(&image, &mut target, &NAMES, &message[..n]).unwrap();
    let mut again = [0u8; 128];
    assert_eq!(publish(&image, &target, &NAMES, &mut again), Ok(n));
    assert_eq!(&again[..n], &message[..n]);
    // Every truncation and a message of other types: nothing is written.
    for cut in 0..n {
        let mut untouched = vec![0u8; data.len()];
        assert!(subscribe(&image, &mut untouched, &NAMES, &message[..cut]).is_err());
        assert!(
            untouched.iter().all(|&b| b == 0),
            "cut at {cut} wrote something"
        );
    }
    let mut wrong = message;
    wrong[0] = 0x45; // an LINT where an LREAL is expected
    assert!(matches!(
        subscribe(&image, &mut target, &NAMES, &wrong[..n]),
        Err(PubSubError::Message(_))
    ));
}

#[test]
fn setup_errors_and_validity() {
    let (image, _, _) = setup();
    let image = Image::parse(&image).unwrap();
    assert_eq!(check(&image, &NAMES), Ok(()));
    assert_eq!(
        check(&image, &["Main.nope"]),
        Err(PubSubError::Unknown("Main.nope"))
    );
    assert_eq!(
        check(&image, &["Main.ptr"]),
        Err(PubSubError::Type("Main.ptr"))
    );
    let mut v = Validity::new(100);
    assert!(!v.valid(0));
    v.received(10);
    assert!(v.valid(109) && !v.valid(110));
}

#[test]
fn an_endpoint_publishes_while_running_and_its_subscription_lapses_to_zero() {
    use crate::package::{PubSub, Subscription};
    let (image, data, initial) = setup();
    let parsed = Image::parse(&image).unwrap();
    let publisher = PubSub {
        publish: Some(([10, 0, 0, 2], 61499, "Main.level\nMain.count")),
        subscribe: None,
    };
    let subscriber = PubSub {
        publish: None,
        subscribe: Some(Subscription {
            port: 61499,
            group: None,
            timeout_ns: 100,
            names: "Main.level\nMain.count",
            valid: Some("Main.alarm"),
        }),
    };
    let mut a = Endpoint::new(&parsed, &publisher).unwrap();
    let mut b = Endpoint::new(&parsed, &subscriber).unwrap();
    let mut a_data = data.clone();
    let mut b_data = initial.clone();
    let mut message = [0u8; 64];
    let (n, change) = a.between_releases(&parsed, &mut a_data, 0, true, None, &mut message);
    assert!(n > 0 && change.is_none());
    assert_eq!(
        a.between_releases(&parsed, &mut a_data, 0, false, None, &mut [0u8; 64]),
        (0, None),
        "a stopped PLC publishes nothing"
    );
    let got = |d: &[u8], name: &str| {
        let v = parsed.find_var(name).unwrap();
        d[v.addr as usize..(v.addr + v.size) as usize].to_vec()
    };
    assert_eq!(
        b.between_releases(&parsed, &mut b_data, 10, true, Some(&message[..n]), &mut []),
        (0, Some(Change::Valid))
    );
    assert_eq!(got(&b_data, "Main.level"), got(&data, "Main.level"));
    assert_eq!(got(&b_data, "Main.alarm"), [1]);
    // A bad message is refused whole; the subscription stays valid until its timeout.
    assert_eq!(
        b.between_releases(&parsed, &mut b_data, 50, true, Some(&[0x43]), &mut []),
        (0, None)
    );
    assert_eq!((b.good, b.bad), (1, 1));
    assert_eq!(
        b.between_releases(&parsed, &mut b_data, 110, true, None, &mut []),
        (0, Some(Change::Lapsed))
    );
    assert_eq!(got(&b_data, "Main.level"), [0; 8]);
    assert_eq!(got(&b_data, "Main.count"), [0; 4]);
    assert_eq!(got(&b_data, "Main.alarm"), [0]);
    // Names the program does not have, a validity variable that is no BOOL.
    let unknown = PubSub {
        publish: Some(([10, 0, 0, 2], 1, "Main.nothing")),
        subscribe: None,
    };
    assert_eq!(
        Endpoint::new(&parsed, &unknown).unwrap_err(),
        PubSubError::Unknown("Main.nothing")
    );
    let not_bool = PubSub {
        publish: None,
        subscribe: Some(Subscription {
            valid: Some("Main.count"),
            ..subscriber.subscribe.unwrap()
        }),
    };
    assert_eq!(
        Endpoint::new(&parsed, &not_bool).unwrap_err(),
        PubSubError::Type("Main.count")
    );
}
