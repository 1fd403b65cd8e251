//! Key files, and sessions with a fake PLC on 127.0.0.1: a server thread speaking the
//! handshake and records with [`plc_online::session`]'s own server side.

use super::*;
use crate::{Action, Link};
use plc_online::session::{ClientKey, REFUSE, accept, challenge, response_len};
use plc_online::{MAX_MESSAGE, PROTOCOL_VERSION, Request, Status, begin_response, decode_request};
use std::net::TcpListener;
use std::thread::JoinHandle;

const KEY: [u8; 32] = [0x5a; 32];
const TIMEOUT: Duration = Duration::from_secs(5);

#[test]
fn key_files_are_hex_digits() {
    let key = parse_key("  00112233445566778899AaBbCcDdEeFf\n").unwrap();
    assert_eq!(key.len(), 16);
    assert_eq!(key[..3], [0x00, 0x11, 0x22]);
    assert_eq!(key[15], 0xff);
    assert_eq!(parse_key(&"ab".repeat(64)).unwrap(), vec![0xab; 64]);
    assert_eq!(parse_key(&"0".repeat(33)), Err(KeyFileError::OddDigits(33)));
    assert_eq!(
        parse_key(&format!("{}xy", "0".repeat(30))),
        Err(KeyFileError::NotHex('x'))
    );
    // Whitespace between the digits is no hex digit either.
    assert!(matches!(
        parse_key("00112233 44556677 8899aabb ccddeeff"),
        Err(KeyFileError::NotHex(' '))
    ));
    assert_eq!(parse_key(&"0".repeat(30)), Err(KeyFileError::Length(15)));
    assert_eq!(parse_key(""), Err(KeyFileError::Length(0)));
    assert_eq!(parse_key(&"0".repeat(130)), Err(KeyFileError::Length(65)));
}

#[test]
fn a_bad_key_file_is_a_usage_error_naming_the_file() {
    let dir = std::env::temp_dir().join(format!("plcctl-keys-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let good = dir.join("engineering.key");
    std::fs::write(&good, format!("{}\n", "0f".repeat(32))).unwrap();
    assert_eq!(read_key(good.to_str().unwrap()).unwrap(), vec![0x0f; 32]);

    let short = dir.join("short.key");
    std::fs::write(&short, "abcd\n").unwrap();
    let path = short.to_str().unwrap();
    let f = read_key(path).unwrap_err();
    assert_eq!(f.status, 2);
    assert!(
        f.message.starts_with(&format!("key file {path}: ")),
        "{}",
        f.message
    );
    assert!(f.message.contains("holds 2 bytes"), "{}", f.message);
    assert!(f.message.contains("32 to 128 hex digits"), "{}", f.message);

    let missing = dir.join("missing.key");
    let path = missing.to_str().unwrap();
    let f = read_key(path).unwrap_err();
    assert_eq!(f.status, 2);
    assert!(
        f.message
            .starts_with(&format!("key file {path}: cannot read it")),
        "{}",
        f.message
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// What the fake PLC does after the handshake.
#[derive(Clone, Copy, PartialEq)]
enum Behaviour {
    /// Answers every request (VERSION with this protocol's version; what the key's access
    /// does not allow with FORBIDDEN; the rest MALFORMED).
    Answer,
    /// Answers with a record whose body was changed after sealing.
    Tamper,
    /// Sends each answer's record twice.
    Replay,
    /// Closes the connection after the handshake.
    Close,
    /// Accepts with a proof made without the key.
    ForgeAccept,
    /// Accepts the connection and sends nothing.
    Silent,
}

fn read_exact(stream: &mut TcpStream, buf: &mut [u8]) -> Result<bool, String> {
    match stream.read_exact(buf) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == ErrorKind::UnexpectedEof => Ok(false),
        Err(e) => Err(e.to_string()),
    }
}

/// A fake PLC on 127.0.0.1 knowing `engineering` (with [`KEY`] and `access`); its address
/// and its thread, which returns how many requests it answered.
fn plc(access: Access, behaviour: Behaviour) -> (String, JoinHandle<Result<usize, String>>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let address = listener.local_addr().unwrap().to_string();
    let thread = std::thread::spawn(move || {
        let (mut stream, _) = listener.accept().map_err(|e| e.to_string())?;
        stream.set_read_timeout(Some(TIMEOUT)).unwrap();
        if behaviour == Behaviour::Silent {
            // Until the client gives up.
            let _ = stream.read(&mut [0u8; 1]);
            return Ok(0);
        }
        let nonce = [0x17u8; NONCE_LEN];
        stream.write_all(&challenge(&nonce)).unwrap();
        let mut answer = [0u8; MAX_RESPONSE_LEN];
        if !read_exact(&mut stream, &mut answer[..NONCE_LEN + 1])? {
            return Err("no response".into());
        }
        let n = response_len(&answer).unwrap();
        if !read_exact(&mut stream, &mut answer[NONCE_LEN + 1..n])? {
            return Err("a short response".into());
        }
        let keys = [ClientKey {
            name: b"engineering",
            secret: &KEY,
            access,
        }];
        let (_, accepted, mut session) = match accept(&keys, &nonce, &answer[..n]) {
            Ok(a) => a,
            Err(_) => {
                stream.write_all(&REFUSE).unwrap();
                return Ok(0);
            }
        };
        match behaviour {
            Behaviour::ForgeAccept => {
                let mut forged = accepted;
                forged[2..].fill(0);
                stream.write_all(&forged).unwrap();
                let _ = stream.read(&mut [0u8; 1]);
                return Ok(0);
            }
            Behaviour::Close => {
                stream.write_all(&accepted).unwrap();
                return Ok(0);
            }
            _ => stream.write_all(&accepted).unwrap(),
        }
        let mut answered = 0;
        loop {
            let mut record = [0u8; MAX_RECORD];
            if !read_exact(&mut stream, &mut record[..2])? {
                return Ok(answered);
            }
            let len = Session::record_len(&record)
                .map_err(|e| e.to_string())?
                .unwrap();
            if !read_exact(&mut stream, &mut record[2..len])? {
                return Err("a short record".into());
            }
            let body = session.open(&record[..len]).map_err(|e| e.to_string())?;
            let (seq, request) = decode_request(body).map_err(|e| format!("{e:?}"))?;
            let op = request.op();
            let mut message = [0u8; MAX_MESSAGE];
            let n = if op.needs().code() > access.code() {
                begin_response(op.code(), seq, Status::Forbidden, &mut message).len()
            } else if request == Request::Version {
                let mut w = begin_response(op.code(), seq, Status::Ok, &mut message);
                w.put(&PROTOCOL_VERSION.to_le_bytes()).unwrap();
                w.len()
            } else {
                begin_response(op.code(), seq, Status::Malformed, &mut message).len()
            };
            let mut out = [0u8; MAX_RECORD];
            let len = session.seal(&message[..n], &mut out).unwrap();
            if behaviour == Behaviour::Tamper {
                out[10] ^= 0x01;
            }
            // A client that gave up (a bad record) may have closed the connection.
            let copies = if behaviour == Behaviour::Replay { 2 } else { 1 };
            answered += 1;
            for _ in 0..copies {
                if stream.write_all(&out[..len]).is_err() {
                    return Ok(answered);
                }
            }
        }
    });
    (address, thread)
}

fn version(link: &mut Link<TcpSession>) -> Result<Vec<String>, Failure> {
    let mut lines = Vec::new();
    link.run(&Action::Version, &mut |line| lines.push(line.to_string()))?;
    Ok(lines)
}

#[test]
fn the_right_key_opens_a_session_the_commands_run_over() {
    let (address, server) = plc(Access::Monitor, Behaviour::Answer);
    let session = TcpSession::connect(&address, "engineering", &KEY, TIMEOUT).unwrap();
    assert_eq!(session.access(), Access::Monitor);
    let mut link = Link::new(session, TIMEOUT);
    let expected = format!("protocol: plcctl {PROTOCOL_VERSION}, PLC {PROTOCOL_VERSION}");
    for _ in 0..2 {
        assert_eq!(version(&mut link).unwrap(), vec![expected.clone()]);
    }
    // What the key's access does not allow, the PLC forbids.
    let f = link
        .run(&Action::Unforce("valve".into()), &mut |_| {})
        .unwrap_err();
    assert_eq!(f.status, 1);
    assert!(
        f.message.starts_with("UNFORCE valve: FORBIDDEN"),
        "{}",
        f.message
    );
    drop(link);
    assert_eq!(server.join().unwrap(), Ok(3));
}

#[test]
fn a_wrong_key_or_name_is_refused_with_status_1() {
    for (name, key) in [("engineering", [0x5b; 32]), ("operator", KEY)] {
        let (address, server) = plc(Access::Download, Behaviour::Answer);
        let f = TcpSession::connect(&address, name, &key, TIMEOUT).unwrap_err();
        assert_eq!(
            f,
            Failure {
                message: format!(
                    "authentication refused by {address} (unknown name or wrong key for \"{name}\")"
                ),
                status: 1,
            }
        );
        assert_eq!(server.join().unwrap(), Ok(0));
    }
}

#[test]
fn a_server_without_the_key_is_not_trusted() {
    let (address, server) = plc(Access::Monitor, Behaviour::ForgeAccept);
    let f = TcpSession::connect(&address, "engineering", &KEY, TIMEOUT).unwrap_err();
    assert_eq!(f.status, 3);
    assert!(f.message.contains("did not prove"), "{}", f.message);
    server.join().unwrap().unwrap();
}

#[test]
fn a_tampered_record_ends_the_session() {
    let (address, server) = plc(Access::Monitor, Behaviour::Tamper);
    let session = TcpSession::connect(&address, "engineering", &KEY, TIMEOUT).unwrap();
    let mut link = Link::new(session, TIMEOUT);
    let f = version(&mut link).unwrap_err();
    assert_eq!(f.status, 3);
    assert!(
        f.message.contains("a bad record from the PLC") && f.message.contains("tampered"),
        "{}",
        f.message
    );
    // And stays ended.
    assert_eq!(version(&mut link).unwrap_err(), f);
    drop(link);
    server.join().unwrap().unwrap();
}

#[test]
fn a_replayed_record_ends_the_session() {
    let (address, server) = plc(Access::Monitor, Behaviour::Replay);
    let session = TcpSession::connect(&address, "engineering", &KEY, TIMEOUT).unwrap();
    let mut link = Link::new(session, TIMEOUT);
    version(&mut link).unwrap();
    // The copy of the first answer is taken before the second request.
    let f = version(&mut link).unwrap_err();
    assert_eq!(f.status, 3);
    assert!(f.message.contains("replayed"), "{}", f.message);
    drop(link);
    server.join().unwrap().unwrap();
}

#[test]
fn a_closed_connection_is_an_error() {
    let (address, server) = plc(Access::Monitor, Behaviour::Close);
    let session = TcpSession::connect(&address, "engineering", &KEY, TIMEOUT).unwrap();
    server.join().unwrap().unwrap();
    let mut link = Link::new(session, TIMEOUT);
    let f = version(&mut link).unwrap_err();
    assert_eq!(f.status, 3);
    assert!(
        f.message.contains("the PLC closed the connection"),
        "{}",
        f.message
    );
}

#[test]
fn no_plc_or_a_silent_one_is_status_3_naming_the_address() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let address = listener.local_addr().unwrap().to_string();
    drop(listener);
    let f = TcpSession::connect(&address, "engineering", &KEY, TIMEOUT).unwrap_err();
    assert_eq!(f.status, 3);
    assert!(
        f.message
            .starts_with(&format!("cannot connect to {address}: ")),
        "{}",
        f.message
    );

    let (address, server) = plc(Access::Monitor, Behaviour::Silent);
    let began = Instant::now();
    let f =
        TcpSession::connect(&address, "engineering", &KEY, Duration::from_millis(200)).unwrap_err();
    assert!(began.elapsed() < Duration::from_secs(3));
    assert_eq!(
        f,
        Failure {
            message: format!("{address}: no challenge from the PLC within 200 ms"),
            status: 3,
        }
    );
    server.join().unwrap().unwrap();
}
