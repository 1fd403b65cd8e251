//! Handshake and records: the good path, every refusal, and hostile bytes.

extern crate std;

use super::*;
use proptest::prelude::*;
use std::vec::Vec;

const KEYS: [ClientKey<'static>; 2] = [
    ClientKey {
        name: b"scada",
        secret: b"monitor-only secret",
        access: Access::Monitor,
    },
    ClientKey {
        name: b"engineer",
        secret: b"0123456789abcdef0123456789abcdef",
        access: Access::Download,
    },
];
const SERVER_NONCE: [u8; NONCE_LEN] = [7; NONCE_LEN];
const CLIENT_NONCE: [u8; NONCE_LEN] = [9; NONCE_LEN];

/// A client and a server session for `name` with `secret`, through the whole handshake.
fn handshake(name: &[u8], secret: &[u8]) -> Result<(Access, Session, Session), HandshakeError> {
    let nonce = read_challenge(&challenge(&SERVER_NONCE))?;
    let mut buf = [0u8; MAX_RESPONSE_LEN];
    let n = response(name, secret, &nonce, &CLIENT_NONCE, &mut buf)?;
    assert_eq!(response_len(&buf[..n]), Some(n));
    let (_, accept_msg, server) = accept(&KEYS, &SERVER_NONCE, &buf[..n])?;
    let (access, client) = read_accept(secret, &SERVER_NONCE, &CLIENT_NONCE, &accept_msg)?;
    Ok((access, client, server))
}

#[test]
fn a_known_key_gets_its_access_and_records_flow_both_ways() {
    let (access, mut client, mut server) = handshake(b"engineer", KEYS[1].secret).unwrap();
    assert_eq!(access, Access::Download);
    let mut out = [0u8; MAX_RECORD];
    for round in 0..3u8 {
        let n = client.seal(&[1, round, 0], &mut out).unwrap();
        assert_eq!(Session::record_len(&out[..2]), Ok(Some(n)));
        assert_eq!(server.open(&out[..n]), Ok(&[1, round, 0][..]));
        let n = server.seal(&[1, round, 0, 42], &mut out).unwrap();
        assert_eq!(client.open(&out[..n]), Ok(&[1, round, 0, 42][..]));
    }
}

#[test]
fn wrong_keys_and_unknown_names_are_refused_alike() {
    assert_eq!(
        handshake(b"engineer", b"guess").err(),
        Some(HandshakeError::Refused)
    );
    assert_eq!(
        handshake(b"nobody", b"guess").err(),
        Some(HandshakeError::Refused)
    );
    assert_eq!(handshake(b"", b"x").err(), Some(HandshakeError::Malformed));
    assert_eq!(
        handshake(&[b'a'; MAX_NAME + 1], b"x").err(),
        Some(HandshakeError::Malformed)
    );
    assert_eq!(
        read_accept(b"x", &SERVER_NONCE, &CLIENT_NONCE, &REFUSE).err(),
        Some(HandshakeError::Refused)
    );
}

#[test]
fn a_server_without_the_key_is_not_believed() {
    let mut buf = [0u8; MAX_RESPONSE_LEN];
    let n = response(
        b"scada",
        KEYS[0].secret,
        &SERVER_NONCE,
        &CLIENT_NONCE,
        &mut buf,
    )
    .unwrap();
    let (_, mut accept_msg, _) = accept(&KEYS, &SERVER_NONCE, &buf[..n]).unwrap();
    accept_msg[1] = Access::Download.code(); // a forged grant
    let forged = read_accept(KEYS[0].secret, &SERVER_NONCE, &CLIENT_NONCE, &accept_msg);
    assert_eq!(forged.err(), Some(HandshakeError::Refused));
}

#[test]
fn a_response_for_another_challenge_is_refused() {
    // A recorded handshake replayed against a new challenge.
    let mut buf = [0u8; MAX_RESPONSE_LEN];
    let n = response(
        b"scada",
        KEYS[0].secret,
        &SERVER_NONCE,
        &CLIENT_NONCE,
        &mut buf,
    )
    .unwrap();
    let fresh = [8; NONCE_LEN];
    assert_eq!(
        accept(&KEYS, &fresh, &buf[..n]).err(),
        Some(HandshakeError::Refused)
    );
}

#[test]
fn replayed_reordered_and_tampered_records_are_refused() {
    let (_, mut client, mut server) = handshake(b"scada", KEYS[0].secret).unwrap();
    let mut first = [0u8; MAX_RECORD];
    let n1 = client.seal(b"\x02\x01level", &mut first).unwrap();
    let mut second = [0u8; MAX_RECORD];
    let n2 = client.seal(b"\x02\x02valve", &mut second).unwrap();
    // Reordered: the second before the first.
    assert_eq!(
        server.open(&second[..n2]),
        Err(RecordError::Sequence {
            expected: 1,
            got: 2
        })
    );
    assert_eq!(server.open(&first[..n1]), Ok(&b"\x02\x01level"[..]));
    // Replayed.
    assert_eq!(
        server.open(&first[..n1]),
        Err(RecordError::Sequence {
            expected: 2,
            got: 1
        })
    );
    // Tampered: body, sequence number, tag; a record of the other direction reflected back.
    for at in [3, 10, n2 - 1] {
        let mut bad = second;
        bad[at] ^= 1;
        assert_eq!(server.open(&bad[..n2]), Err(RecordError::Tag), "byte {at}");
    }
    assert_eq!(client.open(&second[..n2]), Err(RecordError::Tag));
    assert_eq!(server.open(&second[..n2]), Ok(&b"\x02\x02valve"[..]));
    // Bad lengths.
    assert_eq!(Session::record_len(&[0, 0]), Err(RecordError::Length(0)));
    assert_eq!(Session::record_len(&[1, 1]), Err(RecordError::Length(257)));
    assert_eq!(Session::record_len(&[0]), Ok(None));
    assert!(server.open(&second[..n2 - 1]).is_err());
    assert!(client.seal(&[], &mut first).is_none());
    assert!(client.seal(&[0; MAX_MESSAGE + 1], &mut first).is_none());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3_000))]

    /// Random bytes as a challenge, a response, an accept or a record: an error value,
    /// never a panic, never an accepted handshake or record.
    #[test]
    fn hostile_bytes_are_refused(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let _ = read_challenge(&bytes);
        prop_assert!(accept(&KEYS, &SERVER_NONCE, &bytes).is_err());
        prop_assert!(read_accept(KEYS[0].secret, &SERVER_NONCE, &CLIENT_NONCE, &bytes).is_err());
        let (_, _, mut server) = handshake(b"scada", KEYS[0].secret).unwrap();
        let _ = Session::record_len(&bytes);
        prop_assert!(server.open(&bytes).is_err());
        let _: Vec<u8> = Vec::new();
    }
}

#[test]
fn key_files_hold_hex() {
    let mut key = [0u8; MAX_KEY];
    let text = " 000102030405060708090a0B0c0D0e0F\n";
    assert_eq!(parse_key_file(text, &mut key), Ok(16));
    assert_eq!(key[..16], core::array::from_fn::<u8, 16, _>(|i| i as u8));
    assert_eq!(
        parse_key_file("00112233445566778899aabbccddeeffg0", &mut key),
        Err(KeyFileError::NotHex('g'))
    );
    assert_eq!(
        parse_key_file("00112233445566778899aabbccddeef", &mut key),
        Err(KeyFileError::OddDigits(31))
    );
    assert_eq!(
        parse_key_file("0011", &mut key),
        Err(KeyFileError::Length(2))
    );
    assert_eq!(
        parse_key_file(&"ab".repeat(65), &mut key),
        Err(KeyFileError::Length(65))
    );
}

#[test]
fn nonces_differ_by_call_seed_and_keys() {
    let mut a = NonceSource::new(&KEYS, 1);
    let mut b = NonceSource::new(&KEYS, 2);
    let mut c = NonceSource::new(&KEYS[..1], 1);
    let first = a.next(0);
    assert_ne!(first, a.next(0), "the counter");
    assert_ne!(first, b.next(0), "the seed");
    assert_ne!(first, c.next(0), "the keys");
    assert_eq!(first, NonceSource::new(&KEYS, 1).next(0));
}
