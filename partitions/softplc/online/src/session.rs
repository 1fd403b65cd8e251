//! Authenticated online sessions over a byte stream (the online protocol on TCP): a
//! challenge–response with a pre-shared key per client, then every message in a record whose
//! sequence number and body are under an HMAC-SHA-256 tag. An interface; no_std, no
//! allocation, and nothing a peer sends can panic it.
//!
//! Why this design: the keys are configured per client (there is no certificate
//! infrastructure beside a PLC), HMAC-SHA-256 is the standard MAC for that, and a fresh nonce
//! from each side makes every session's key new, so a recorded session cannot be replayed
//! into another; within a session the sequence numbers refuse replayed, dropped or reordered
//! records, and the tag refuses tampered ones. The messages are authenticated, not encrypted:
//! what an online session carries (variable values, a program image) is not secret on a plant
//! network, but who may change it is.
//!
//! # Handshake (integers big-endian)
//!
//! 1. server → client, CHALLENGE ([`CHALLENGE_LEN`] bytes): `"WOS1"`, `version u8` (1),
//!    `server_nonce [16]`.
//! 2. client → server, RESPONSE: `client_nonce [16]`, `name_len u8` (1..=[`MAX_NAME`]),
//!    `name`, `proof [32]` = HMAC(key, `"warden-online client"` ‖ server_nonce ‖
//!    client_nonce ‖ name).
//! 3. server → client, ACCEPT: `status u8` (0), `access u8` (the key's [`Access`]),
//!    `proof [32]` = HMAC(key, `"warden-online server"` ‖ server_nonce ‖ client_nonce ‖
//!    access), which shows the client that the server holds the key too; or REFUSE: `status
//!    u8` (1) alone, after which the server closes the connection. An unknown name and a wrong
//!    proof get the same refusal (a client learns nothing about which names exist).
//!
//! Both sides then hold the session key HMAC(key, `"warden-online session"` ‖ server_nonce ‖
//! client_nonce).
//!
//! # Records
//!
//! `len u16` (the body's length, 1..=[`MAX_MESSAGE`]), `seq u64`, `body` (one online-protocol
//! message), `tag [32]` = HMAC(session key, `direction u8` ‖ seq ‖ len ‖ body), direction 0
//! client → server and 1 server → client. Each direction's first record has seq 1 and every
//! next one the previous plus one; a record with another seq, a bad tag or a bad length ends
//! the session ([`RecordError`]).

use crate::{Access, MAX_MESSAGE};
use hmac::{Hmac, KeyInit, Mac};
use sha2::Sha256;

type HmacSha256 = Hmac<Sha256>;

/// Bytes of a nonce.
pub const NONCE_LEN: usize = 16;
/// Bytes of a tag or proof.
pub const TAG_LEN: usize = 32;
/// Longest client name.
pub const MAX_NAME: usize = 32;
/// Bytes of the CHALLENGE.
pub const CHALLENGE_LEN: usize = 4 + 1 + NONCE_LEN;
/// Longest RESPONSE.
pub const MAX_RESPONSE_LEN: usize = NONCE_LEN + 1 + MAX_NAME + TAG_LEN;
/// Bytes of an ACCEPT.
pub const ACCEPT_LEN: usize = 2 + TAG_LEN;
/// Bytes a record adds to its body.
pub const RECORD_OVERHEAD: usize = 2 + 8 + TAG_LEN;
/// Longest record.
pub const MAX_RECORD: usize = MAX_MESSAGE + RECORD_OVERHEAD;

const MAGIC: &[u8; 4] = b"WOS1";
const VERSION: u8 = 1;
const CLIENT_LABEL: &[u8] = b"warden-online client";
const SERVER_LABEL: &[u8] = b"warden-online server";
const SESSION_LABEL: &[u8] = b"warden-online session";

/// Fewest and most bytes of a pre-shared key.
pub const MIN_KEY: usize = 16;
pub const MAX_KEY: usize = 64;

/// Why a key file's text is no key.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeyFileError {
    NotHex(char),
    OddDigits(usize),
    Length(usize),
}

impl core::fmt::Display for KeyFileError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            KeyFileError::NotHex(c) => write!(f, "holds {c:?}, which is no hex digit"),
            KeyFileError::OddDigits(n) => write!(f, "holds {n} hex digits, an odd count"),
            KeyFileError::Length(n) => {
                write!(f, "holds {n} bytes, outside {MIN_KEY}..={MAX_KEY}")
            }
        }
    }
}

/// The key in a key file's text: the key as hex digits, whitespace around them ignored
/// ([`MIN_KEY`]..=[`MAX_KEY`] bytes). The configuration (`plc.online_tcp`) and `plcctl
/// --key` read the same files. Returns the key's length in `out`.
pub fn parse_key_file(text: &str, out: &mut [u8; MAX_KEY]) -> Result<usize, KeyFileError> {
    let hex = text.trim().as_bytes();
    if let Some(&bad) = hex.iter().find(|b| !b.is_ascii_hexdigit()) {
        return Err(KeyFileError::NotHex(char::from(bad)));
    }
    if !hex.len().is_multiple_of(2) {
        return Err(KeyFileError::OddDigits(hex.len()));
    }
    let len = hex.len() / 2;
    if !(MIN_KEY..=MAX_KEY).contains(&len) {
        return Err(KeyFileError::Length(len));
    }
    let digit = |b: u8| match b {
        b'0'..=b'9' => b - b'0',
        b'a'..=b'f' => b - b'a' + 10,
        _ => b - b'A' + 10,
    };
    for (i, pair) in hex.chunks_exact(2).enumerate() {
        out[i] = digit(pair[0]) << 4 | digit(pair[1]);
    }
    Ok(len)
}

/// A client's pre-shared key as the server holds it.
#[derive(Clone, Copy, Debug)]
pub struct ClientKey<'a> {
    pub name: &'a [u8],
    pub secret: &'a [u8],
    pub access: Access,
}

/// Why a handshake failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HandshakeError {
    /// Not a handshake message of this protocol (length, magic, version, status).
    Malformed,
    /// Unknown name or wrong proof (server side); wrong server proof (client side).
    Refused,
}

impl core::fmt::Display for HandshakeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            HandshakeError::Malformed => "malformed handshake message",
            HandshakeError::Refused => "authentication refused",
        })
    }
}

/// Why a record was refused; the session ends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordError {
    /// The length field is 0 or above [`MAX_MESSAGE`].
    Length(u16),
    /// The sequence number is not the next one (a replayed, dropped or reordered record).
    Sequence { expected: u64, got: u64 },
    /// The tag does not match (a tampered record or the wrong key).
    Tag,
}

impl core::fmt::Display for RecordError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            RecordError::Length(n) => write!(f, "record length {n}, expected 1..={MAX_MESSAGE}"),
            RecordError::Sequence { expected, got } => {
                write!(
                    f,
                    "record sequence {got}, expected {expected} (replayed or reordered)"
                )
            }
            RecordError::Tag => f.write_str("record tag does not match (tampered)"),
        }
    }
}

impl core::error::Error for KeyFileError {}
impl core::error::Error for HandshakeError {}
impl core::error::Error for RecordError {}

fn mac(key: &[u8], parts: &[&[u8]]) -> HmacSha256 {
    // HMAC takes keys of any length; new_from_slice cannot fail for it.
    let mut mac = match HmacSha256::new_from_slice(key) {
        Ok(mac) => mac,
        Err(_) => unreachable!("HMAC accepts every key length"),
    };
    for part in parts {
        mac.update(part);
    }
    mac
}

fn tag(key: &[u8], parts: &[&[u8]]) -> [u8; TAG_LEN] {
    mac(key, parts).finalize().into_bytes().into()
}

/// The CHALLENGE the server sends first.
pub fn challenge(server_nonce: &[u8; NONCE_LEN]) -> [u8; CHALLENGE_LEN] {
    let mut out = [0u8; CHALLENGE_LEN];
    out[..4].copy_from_slice(MAGIC);
    out[4] = VERSION;
    out[5..].copy_from_slice(server_nonce);
    out
}

/// Client side: the server nonce of a CHALLENGE.
pub fn read_challenge(bytes: &[u8]) -> Result<[u8; NONCE_LEN], HandshakeError> {
    match bytes {
        [m0, m1, m2, m3, VERSION, nonce @ ..] if [*m0, *m1, *m2, *m3] == *MAGIC => {
            nonce.try_into().map_err(|_| HandshakeError::Malformed)
        }
        _ => Err(HandshakeError::Malformed),
    }
}

/// Client side: the RESPONSE to a challenge, written into `out`; returns its length.
pub fn response(
    name: &[u8],
    secret: &[u8],
    server_nonce: &[u8; NONCE_LEN],
    client_nonce: &[u8; NONCE_LEN],
    out: &mut [u8; MAX_RESPONSE_LEN],
) -> Result<usize, HandshakeError> {
    if name.is_empty() || name.len() > MAX_NAME {
        return Err(HandshakeError::Malformed);
    }
    out[..NONCE_LEN].copy_from_slice(client_nonce);
    out[NONCE_LEN] = name.len() as u8;
    let name_at = NONCE_LEN + 1;
    out[name_at..name_at + name.len()].copy_from_slice(name);
    let proof = tag(secret, &[CLIENT_LABEL, server_nonce, client_nonce, name]);
    let proof_at = name_at + name.len();
    out[proof_at..proof_at + TAG_LEN].copy_from_slice(&proof);
    Ok(proof_at + TAG_LEN)
}

/// Bytes of the RESPONSE that begins `bytes`, once its name length has arrived.
pub fn response_len(bytes: &[u8]) -> Option<usize> {
    bytes
        .get(NONCE_LEN)
        .map(|&n| NONCE_LEN + 1 + usize::from(n) + TAG_LEN)
}

/// An authenticated session: the session key and both directions' sequence numbers.
#[derive(Clone, Debug)]
pub struct Session {
    key: [u8; TAG_LEN],
    /// 0 on the client, 1 on the server: the direction of the records this side sends.
    sends: u8,
    next_send: u64,
    next_receive: u64,
}

impl Session {
    fn new(secret: &[u8], server_nonce: &[u8], client_nonce: &[u8], sends: u8) -> Self {
        Session {
            key: tag(secret, &[SESSION_LABEL, server_nonce, client_nonce]),
            sends,
            next_send: 1,
            next_receive: 1,
        }
    }

    fn record_mac(&self, direction: u8, seq: u64, body: &[u8]) -> HmacSha256 {
        let len = (body.len() as u16).to_be_bytes();
        mac(&self.key, &[&[direction], &seq.to_be_bytes(), &len, body])
    }

    /// Puts `body` (1..=[`MAX_MESSAGE`] bytes) into the next record, written into `out`;
    /// returns the record's length.
    pub fn seal(&mut self, body: &[u8], out: &mut [u8; MAX_RECORD]) -> Option<usize> {
        if body.is_empty() || body.len() > MAX_MESSAGE {
            return None;
        }
        let seq = self.next_send;
        self.next_send += 1;
        out[..2].copy_from_slice(&(body.len() as u16).to_be_bytes());
        out[2..10].copy_from_slice(&seq.to_be_bytes());
        out[10..10 + body.len()].copy_from_slice(body);
        let t: [u8; TAG_LEN] = self
            .record_mac(self.sends, seq, body)
            .finalize()
            .into_bytes()
            .into();
        out[10 + body.len()..10 + body.len() + TAG_LEN].copy_from_slice(&t);
        Some(body.len() + RECORD_OVERHEAD)
    }

    /// The length of the record that begins `bytes` once its length field has arrived, or
    /// the error of a bad length.
    pub fn record_len(bytes: &[u8]) -> Result<Option<usize>, RecordError> {
        let Some(len) = bytes.first_chunk::<2>().map(|b| u16::from_be_bytes(*b)) else {
            return Ok(None);
        };
        if len == 0 || usize::from(len) > MAX_MESSAGE {
            return Err(RecordError::Length(len));
        }
        Ok(Some(usize::from(len) + RECORD_OVERHEAD))
    }

    /// Checks the whole record `record` from the peer and returns its body.
    pub fn open<'r>(&mut self, record: &'r [u8]) -> Result<&'r [u8], RecordError> {
        let Some(len) = Self::record_len(record)? else {
            return Err(RecordError::Length(0));
        };
        if record.len() != len {
            return Err(RecordError::Length(
                record.len().saturating_sub(RECORD_OVERHEAD) as u16,
            ));
        }
        let seq = u64::from_be_bytes(record[2..10].try_into().map_err(|_| RecordError::Tag)?);
        let body = &record[10..len - TAG_LEN];
        let tag = &record[len - TAG_LEN..];
        // The tag first: a forged record must not learn (or move) the sequence number.
        self.record_mac(1 - self.sends, seq, body)
            .verify_slice(tag)
            .map_err(|_| RecordError::Tag)?;
        if seq != self.next_receive {
            return Err(RecordError::Sequence {
                expected: self.next_receive,
                got: seq,
            });
        }
        self.next_receive += 1;
        Ok(body)
    }
}

/// Server side: checks a whole RESPONSE against the configured keys. On success, the key's
/// index, the ACCEPT to send and the session; on failure, send [`REFUSE`] and close.
pub fn accept(
    keys: &[ClientKey<'_>],
    server_nonce: &[u8; NONCE_LEN],
    response: &[u8],
) -> Result<(usize, [u8; ACCEPT_LEN], Session), HandshakeError> {
    if response_len(response) != Some(response.len()) {
        return Err(HandshakeError::Malformed);
    }
    let client_nonce = &response[..NONCE_LEN];
    let name = &response[NONCE_LEN + 1..response.len() - TAG_LEN];
    let proof = &response[response.len() - TAG_LEN..];
    if name.is_empty() || name.len() > MAX_NAME {
        return Err(HandshakeError::Malformed);
    }
    let Some(index) = keys.iter().position(|k| k.name == name) else {
        return Err(HandshakeError::Refused);
    };
    let key = &keys[index];
    mac(
        key.secret,
        &[CLIENT_LABEL, server_nonce, client_nonce, name],
    )
    .verify_slice(proof)
    .map_err(|_| HandshakeError::Refused)?;
    let access = key.access.code();
    let mut out = [0u8; ACCEPT_LEN];
    out[1] = access;
    out[2..].copy_from_slice(&tag(
        key.secret,
        &[SERVER_LABEL, server_nonce, client_nonce, &[access]],
    ));
    Ok((
        index,
        out,
        Session::new(key.secret, server_nonce, client_nonce, 1),
    ))
}

/// The server's nonces: HMAC(key, counter ‖ time), the key an HMAC of every client's
/// secret and a seed. A client cannot predict the next one without a key, and the counter
/// makes each one new within a run; across runs their freshness rests on the seed and the
/// time (the time-stamp counter on the PLC: there is no entropy device yet).
#[derive(Clone, Debug)]
pub struct NonceSource {
    key: [u8; TAG_LEN],
    counter: u64,
}

const NONCE_LABEL: &[u8] = b"warden-online nonce";

impl NonceSource {
    pub fn new(keys: &[ClientKey<'_>], seed: u64) -> Self {
        let mut m = mac(&seed.to_be_bytes(), &[NONCE_LABEL]);
        for k in keys {
            m.update(&[k.secret.len() as u8]);
            m.update(k.secret);
        }
        NonceSource {
            key: m.finalize().into_bytes().into(),
            counter: 0,
        }
    }

    /// The next nonce, at `now` (any clock).
    pub fn next(&mut self, now: u64) -> [u8; NONCE_LEN] {
        self.counter += 1;
        let t = tag(
            &self.key,
            &[&self.counter.to_be_bytes(), &now.to_be_bytes()],
        );
        let mut nonce = [0u8; NONCE_LEN];
        nonce.copy_from_slice(&t[..NONCE_LEN]);
        nonce
    }
}

/// The server's refusal.
pub const REFUSE: [u8; 1] = [1];

/// Client side: checks the server's ACCEPT (or REFUSE) and returns the granted access and
/// the session.
pub fn read_accept(
    secret: &[u8],
    server_nonce: &[u8; NONCE_LEN],
    client_nonce: &[u8; NONCE_LEN],
    bytes: &[u8],
) -> Result<(Access, Session), HandshakeError> {
    match bytes {
        [1] => Err(HandshakeError::Refused),
        [0, access, proof @ ..] if proof.len() == TAG_LEN => {
            mac(
                secret,
                &[SERVER_LABEL, server_nonce, client_nonce, &[*access]],
            )
            .verify_slice(proof)
            .map_err(|_| HandshakeError::Refused)?;
            let access = Access::from_code(*access).ok_or(HandshakeError::Malformed)?;
            Ok((access, Session::new(secret, server_nonce, client_nonce, 0)))
        }
        _ => Err(HandshakeError::Malformed),
    }
}

#[cfg(test)]
mod tests;
