//! Known encodings, round trips of every type, and hostile bytes.

extern crate std;

use super::*;
use proptest::prelude::*;
use std::vec::Vec;

fn encode(values: &[Value<'_>]) -> Vec<u8> {
    let mut buf = [0u8; 512];
    let mut w = Writer::new(&mut buf);
    for v in values {
        w.value(v).unwrap();
    }
    w.bytes().to_vec()
}

#[test]
fn known_encodings() {
    assert_eq!(
        encode(&[Value::bool(false), Value::bool(true)]),
        [0x40, 0x41]
    );
    assert_eq!(
        encode(&[Value::Fixed(Type::Int, (-2i64) as u64)]),
        [0x43, 0xFF, 0xFE]
    );
    assert_eq!(
        encode(&[Value::Fixed(Type::UDInt, 0x0102_0304)]),
        [0x48, 1, 2, 3, 4]
    );
    assert_eq!(
        encode(&[Value::Fixed(Type::Real, u64::from(1.5f32.to_bits()))]),
        [0x4A, 0x3F, 0xC0, 0, 0]
    );
    assert_eq!(
        encode(&[Value::Fixed(Type::LReal, 1.0f64.to_bits())]),
        [0x4B, 0x3F, 0xF0, 0, 0, 0, 0, 0, 0]
    );
    // T#1s = 1,000,000 us.
    assert_eq!(
        encode(&[Value::Fixed(Type::Time, 1_000_000_000)]),
        [0x4C, 0, 0, 0, 0, 0, 0x0F, 0x42, 0x40]
    );
    assert_eq!(encode(&[Value::String(b"Hi")]), [0x50, 0, 2, b'H', b'i']);
    assert_eq!(
        encode(&[Value::WString(&[0, b'H', 0x20, 0xAC])]),
        [0x55, 0, 2, 0, b'H', 0x20, 0xAC]
    );
    assert_eq!(
        encode(&[Value::Fixed(Type::Word, 0xBEEF)]),
        [0x52, 0xBE, 0xEF]
    );
    let mut buf = [0u8; 32];
    let mut w = Writer::new(&mut buf);
    let ints = [1u64, 2, 3].map(|v| Value::Fixed(Type::Int, v));
    w.array(Type::Int, ints.into_iter()).unwrap();
    let bools = [true, false].map(Value::bool);
    w.array(Type::Bool, bools.into_iter()).unwrap();
    assert_eq!(
        w.bytes(),
        [0x76, 0, 3, 0x43, 0, 1, 0, 2, 0, 3, 0x76, 0, 2, 0x41, 0x40]
    );
    let mut w = Writer::new(&mut buf);
    w.null().unwrap();
    assert_eq!(w.bytes(), [NULL]);
    assert!(Reader::new(&[NULL]).is_null());
}

#[test]
fn decoding_checks_tags_lengths_and_the_end() {
    let bytes = encode(&[
        Value::Fixed(Type::DInt, (-5i64) as u64),
        Value::String(b"abc"),
    ]);
    let mut r = Reader::new(&bytes);
    assert_eq!(
        r.value(Type::DInt),
        Ok(Value::Fixed(Type::DInt, (-5i64) as u64))
    );
    assert_eq!(r.value(Type::String), Ok(Value::String(b"abc")));
    assert_eq!(r.finish(), Ok(()));

    let mut r = Reader::new(&bytes);
    assert_eq!(
        r.value(Type::Int),
        Err(DecodeError::Tag {
            at: 0,
            expected: Type::Int,
            found: 0x44
        })
    );
    let mut r = Reader::new(&bytes[..7]);
    r.value(Type::DInt).unwrap();
    assert_eq!(r.value(Type::String), Err(DecodeError::Truncated { at: 6 }));
    let mut r = Reader::new(&bytes);
    r.value(Type::DInt).unwrap();
    assert_eq!(r.finish(), Err(DecodeError::Trailing { at: 5 }));
    // A TIME beyond what nanoseconds hold.
    let far = [0x4C, 0x7F, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF];
    assert_eq!(
        Reader::new(&far).value(Type::Time),
        Err(DecodeError::Range { at: 1 })
    );

    let mut buf = [0u8; 32];
    let mut w = Writer::new(&mut buf);
    let reals = [0.5f32, -2.0].map(|x| Value::Fixed(Type::Real, u64::from(x.to_bits())));
    w.array(Type::Real, reals.into_iter()).unwrap();
    let bytes = w.bytes().to_vec();
    let mut r = Reader::new(&bytes);
    assert_eq!(r.array(Type::Real), Ok(2));
    assert_eq!(r.element(Type::Real), Ok(reals[0]));
    assert_eq!(r.element(Type::Real), Ok(reals[1]));
    assert_eq!(r.finish(), Ok(()));
}

#[test]
fn a_full_buffer_is_an_error() {
    let mut buf = [0u8; 4];
    let mut w = Writer::new(&mut buf);
    assert_eq!(w.value(&Value::String(b"four")), Err(Full));
    assert_eq!(w.value(&Value::Fixed(Type::DInt, 1)), Err(Full));
    assert_eq!(w.value(&Value::Fixed(Type::Int, 1)), Ok(()));
    assert_eq!(w.len(), 3);
}

fn any_value() -> impl Strategy<Value = (Type, u64)> {
    (proptest::sample::select(&Type::ALL[..]), any::<u64>()).prop_map(|(ty, bits)| {
        let bits = match ty.fixed_size() {
            Some(0) => bits & 1,
            Some(8) | None => bits,
            Some(n) => {
                let shift = 64 - 8 * n as u32;
                let signed = matches!(ty, Type::SInt | Type::Int | Type::DInt);
                if signed {
                    (((bits << shift) as i64) >> shift) as u64
                } else {
                    bits >> shift
                }
            }
        };
        // TIME: whole microseconds survive the trip.
        let bits = if ty == Type::Time {
            ((bits as i64) / 1_000_000 * 1_000) as u64
        } else {
            bits
        };
        (ty, bits)
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(5_000))]

    #[test]
    fn every_type_round_trips(values in proptest::collection::vec(any_value(), 1..8), text in "[a-zA-Z0-9 ]{0,40}") {
        let units: Vec<u8> = text.encode_utf16().flat_map(u16::to_be_bytes).collect();
        let values: Vec<Value<'_>> = values
            .iter()
            .map(|&(ty, bits)| match ty {
                Type::String => Value::String(text.as_bytes()),
                Type::WString => Value::WString(&units),
                _ => Value::Fixed(ty, bits),
            })
            .collect();
        let bytes = encode(&values);
        let mut r = Reader::new(&bytes);
        for v in &values {
            prop_assert_eq!(r.value(v.ty()), Ok(*v));
        }
        prop_assert_eq!(r.finish(), Ok(()));
    }

    /// Random bytes read as any sequence of types: an error value or values, never a panic.
    #[test]
    fn hostile_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..64),
                                 types in proptest::collection::vec(proptest::sample::select(&Type::ALL[..]), 1..6)) {
        let mut r = Reader::new(&bytes);
        for ty in types {
            if r.value(ty).is_err() {
                break;
            }
        }
        let mut r = Reader::new(&bytes);
        if let Ok(n) = r.array(Type::DInt) {
            for _ in 0..n {
                if r.element(Type::DInt).is_err() {
                    break;
                }
            }
        }
    }
}
