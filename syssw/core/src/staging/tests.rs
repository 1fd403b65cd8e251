use super::*;
use crate::testsys::{blob, with};
use config::decode;
use proptest::prelude::*;
use std::vec;
use std::vec::Vec;

/// `a` sends a 10,000-byte sampling message and 20,000-byte queuing messages to `b`; `b`
/// also has a short port of its own.
fn system_text() -> std::string::String {
    with(&[
        (
            "# a",
            r#"ports.out = { kind = "sampling", direction = "out", size = 10000 }
ports.tx = { kind = "queuing", direction = "out", size = 20000, depth = 2 }
ports.sin = { kind = "sampling", direction = "in", size = 64 }"#,
        ),
        (
            "# b",
            r#"ports.in = { kind = "sampling", direction = "in", size = 10000 }
ports.rx = { kind = "queuing", direction = "in", size = 20000, depth = 2 }
ports.short = { kind = "sampling", direction = "out", size = 64 }"#,
        ),
        (
            "# tail",
            r#"[[channels]]
kind = "sampling"
from = "a.out"
to = ["b.in"]

[[channels]]
kind = "queuing"
from = "a.tx"
to = "b.rx"

[[channels]]
kind = "sampling"
from = "b.short"
to = ["a.sin"]"#,
        ),
    ])
}

/// Runs `f` on the staging buffers of [`system_text`], all free.
fn with_staging(f: impl FnOnce(&mut Staging<'_>)) {
    let bytes = blob(&system_text());
    let system = decode(&bytes).unwrap();
    let mut arena = vec![0u8; arena_size(&system)];
    f(&mut Staging::new(&system, &mut arena).unwrap());
}

fn message(len: usize, seed: u8) -> Vec<u8> {
    (0..len)
        .map(|i| (i as u8).wrapping_mul(31) ^ seed)
        .collect()
}

#[test]
fn buffers_are_sized_from_the_configuration() {
    let bytes = blob(&system_text());
    let system = decode(&bytes).unwrap();
    let a = (STAGING_RUNNERS) * (HEADER + 20000);
    let b = (STAGING_RUNNERS + MAX_WAITERS) * (HEADER + 20000);
    assert_eq!(arena_size(&system), a + b);
    let mut arena = vec![0u8; arena_size(&system) - 1];
    assert!(Staging::new(&system, &mut arena).is_err());
    // A system whose ports all fit one part needs none.
    let plain = blob(&with(&[]));
    assert_eq!(arena_size(&decode(&plain).unwrap()), 0);
}

#[test]
fn a_long_message_is_staged_in_order_then_assembled() {
    with_staging(|s| {
        let m = message(10000, 7);
        assert_eq!(s.stage(0, 5, 0, &m[..4096]), ReturnCode::NoError);
        // Out of order, or a part from another thread's offset: refused, nothing lost.
        assert_eq!(s.stage(0, 5, 100, &m[..10]), ReturnCode::InvalidParam);
        assert_eq!(s.stage(0, 6, 4096, &m[..10]), ReturnCode::InvalidParam);
        assert_eq!(s.stage(0, 5, 4096, &m[4096..8192]), ReturnCode::NoError);
        assert_eq!(
            s.assemble(0, 5, 4096, &m[8192..]),
            Err(ReturnCode::InvalidParam)
        );
        assert_eq!(s.assemble(0, 5, 8192, &m[8192..]).unwrap(), &m[..]);
        s.release(0, 5);
        assert_eq!(s.assemble(0, 5, 8192, &[1]), Err(ReturnCode::InvalidParam));
        // Longer than the partition's longest port: INVALID_CONFIG, and the buffer is free.
        let long = message(20001, 1);
        assert_eq!(s.stage(0, 5, 0, &long[..16384]), ReturnCode::NoError);
        assert_eq!(
            s.assemble(0, 5, 16384, &long[16384..]),
            Err(ReturnCode::InvalidConfig)
        );
        assert_eq!(s.owned(0, 5), None);
        // A partition without long ports has no buffers.
        let plain = blob(&with(&[]));
        let plain = decode(&plain).unwrap();
        let mut none: Vec<u8> = Vec::new();
        let mut s = Staging::new(&plain, &mut none).unwrap();
        assert_eq!(s.stage(0, 5, 0, &[1]), ReturnCode::InvalidConfig);
    });
}

#[test]
fn runners_are_bounded_and_a_new_message_restarts_the_owners_buffer() {
    with_staging(|s| {
        for token in 0..STAGING_RUNNERS as u64 {
            assert_eq!(s.stage(0, token, 0, &[1; 100]), ReturnCode::NoError);
        }
        assert_eq!(s.stage(0, 99, 0, &[1; 100]), ReturnCode::InvalidConfig);
        // Offset 0 again reuses the caller's own buffer.
        assert_eq!(s.stage(0, 0, 0, &[2; 10]), ReturnCode::NoError);
        assert_eq!(
            s.assemble(0, 0, 10, &[3]).unwrap(),
            &[2, 2, 2, 2, 2, 2, 2, 2, 2, 2, 3]
        );
        s.reset_partition(0);
        assert_eq!(s.stage(0, 99, 0, &[1; 100]), ReturnCode::NoError);
    });
}

#[test]
fn a_received_long_message_is_fetched_in_parts() {
    with_staging(|s| {
        let m = message(10000, 3);
        s.reserve(1, 8).unwrap();
        assert!(s.deliver(8, &m));
        let mut out = [0u8; PART_MAX];
        let mut got = m[..PART_MAX].to_vec();
        assert_eq!(s.fetch(1, 9, 4096, &mut out), Err(ReturnCode::InvalidParam));
        assert_eq!(
            s.fetch(1, 8, 10001, &mut out),
            Err(ReturnCode::InvalidParam)
        );
        let (n, left) = s.fetch(1, 8, 4096, &mut out).unwrap();
        got.extend_from_slice(&out[..n]);
        assert_eq!((n, left), (4096, 10000 - 8192));
        let (n, left) = s.fetch(1, 8, 8192, &mut out).unwrap();
        got.extend_from_slice(&out[..n]);
        assert_eq!((n, left), (10000 - 8192, 0));
        assert_eq!(got, m);
        // The last fetch freed it.
        assert_eq!(s.fetch(1, 8, 8192, &mut out), Err(ReturnCode::InvalidParam));
        // A short message is not held.
        s.reserve(1, 8).unwrap();
        assert!(!s.deliver(8, &m[..100]));
        assert_eq!(s.owned(1, 8), None);
        // Fetching at the length drops the rest.
        s.reserve(1, 8).unwrap();
        assert!(s.deliver(8, &m[..9000]));
        assert_eq!(s.fetch(1, 8, 9000, &mut out), Ok((0, 0)));
        assert_eq!(s.owned(1, 8), None);
    });
}

#[test]
fn a_parked_receiver_gets_its_message_in_its_reservation() {
    with_staging(|s| {
        // As many parked receivers as the port holds, besides the runners.
        for token in 0..(STAGING_RUNNERS + MAX_WAITERS) as u64 {
            s.reserve(1, 100 + token).unwrap();
        }
        assert_eq!(s.reserve(1, 99).err(), Some(ReturnCode::InvalidConfig));
        let m = message(20000, 9);
        assert!(s.deliver(103, &m));
        let mut out = [0u8; PART_MAX];
        assert_eq!(s.fetch(1, 103, 16384, &mut out), Ok((20000 - 16384, 0)));
        assert_eq!(&out[..20000 - 16384], &m[16384..]);
        // A short one frees the reservation; so does a time-out.
        assert!(!s.deliver(104, &[1, 2, 3]));
        assert_eq!(s.owned(1, 104), None);
        s.release_token(105);
        assert_eq!(s.owned(1, 105), None);
        // Nobody reserved: nothing taken.
        assert!(!s.deliver(7, &m));
    });
}

proptest! {
    /// Any sequence of requests from a few threads: never a panic, every buffer the
    /// partition's size, and an assembled message is what its owner staged.
    #[test]
    fn hostile_sequences_never_panic(ops in proptest::collection::vec(
        (0u8..6, 0u64..6, 0u64..24000, 0usize..5000, 0usize..2), 0..200)) {
        let bytes = blob(&system_text());
        let system = decode(&bytes).unwrap();
        let mut arena = vec![0u8; arena_size(&system)];
        let mut s = Staging::new(&system, &mut arena).unwrap();
        let mut out = [0u8; PART_MAX];
        for (op, token, offset, len, partition) in ops {
            let part = message(len, token as u8);
            match op {
                0 => { s.stage(partition, token, offset, &part); }
                1 => {
                    if let Ok(whole) = s.assemble(partition, token, offset, &part) {
                        prop_assert_eq!(whole.len() as u64, offset + len as u64);
                        prop_assert_eq!(&whole[offset as usize..], &part[..]);
                    }
                }
                2 | 3 => { let _ = s.reserve(partition, token); }
                4 => { s.deliver(token, &part); }
                _ => {
                    if let Ok((n, _)) = s.fetch(partition, token, offset, &mut out) {
                        prop_assert!(n <= PART_MAX);
                    }
                }
            }
        }
    }
}
