//! The online protocol on TCP ([`plc_online::session`]): [`TcpSession`] authenticates to the
//! PLC with a pre-shared key (CHALLENGE, RESPONSE, ACCEPT or REFUSE) and then carries each
//! message in a sealed record, as a [`Transport`] a [`crate::Link`] runs commands over; and
//! [`read_key`], the key file `--key` names. Plain `std` (the guest's static musl build has
//! `std::net` too).

use crate::{Failure, Transport};
use plc_online::Access;
use plc_online::session::{
    self, ACCEPT_LEN, CHALLENGE_LEN, HandshakeError, KeyFileError, MAX_KEY, MAX_RECORD,
    MAX_RESPONSE_LEN, NONCE_LEN, Session,
};
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};

/// Where the client nonce comes from.
const RANDOM: &str = "/dev/urandom";

/// The key in a key file's text: hex digits (32..=128, an even count: 16..=64 bytes),
/// whitespace and newlines around them ignored; the same format the PLC's configuration
/// reads ([`session::parse_key_file`]).
pub fn parse_key(text: &str) -> Result<Vec<u8>, KeyFileError> {
    let mut key = [0u8; MAX_KEY];
    let len = session::parse_key_file(text, &mut key)?;
    Ok(key[..len].to_vec())
}

/// The key in the key file `path`, or a usage error (status 2) naming the file and why.
pub fn read_key(path: &str) -> Result<Vec<u8>, Failure> {
    let fail = |why: String| Failure {
        message: format!("key file {path}: {why}"),
        status: 2,
    };
    let text = std::fs::read_to_string(path).map_err(|e| fail(format!("cannot read it: {e}")))?;
    parse_key(&text).map_err(|e| {
        fail(format!(
            "{e} (a key file holds the key as {} to {} hex digits)",
            2 * session::MIN_KEY,
            2 * MAX_KEY
        ))
    })
}

/// An authenticated online session with the PLC over TCP.
pub struct TcpSession {
    stream: TcpStream,
    session: Session,
    access: Access,
    /// The address as given, for messages.
    address: String,
    /// How long a sent record may wait for room in the socket.
    timeout: Duration,
    /// Bytes received and not yet taken as a record.
    received: Vec<u8>,
    /// Why the session ended (a bad record, the connection closed), once it did.
    ended: Option<String>,
}

impl std::fmt::Debug for TcpSession {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TcpSession")
            .field("address", &self.address)
            .field("access", &self.access)
            .finish_non_exhaustive()
    }
}

/// A failure to reach or talk to the PLC (status 3).
fn unreachable(message: String) -> Failure {
    Failure { message, status: 3 }
}

/// Sixteen bytes from [`RANDOM`].
fn nonce() -> Result<[u8; NONCE_LEN], Failure> {
    let mut nonce = [0u8; NONCE_LEN];
    std::fs::File::open(RANDOM)
        .and_then(|mut f| f.read_exact(&mut nonce))
        .map_err(|e| unreachable(format!("cannot read a session nonce from {RANDOM}: {e}")))?;
    Ok(nonce)
}

/// Reads exactly `buf.len()` bytes before `deadline`; `what` names them for errors.
fn read_before(
    stream: &mut TcpStream,
    buf: &mut [u8],
    deadline: Instant,
    address: &str,
    what: &str,
    timeout: Duration,
) -> Result<(), Failure> {
    let mut at = 0;
    while at < buf.len() {
        let left = deadline.saturating_duration_since(Instant::now());
        let late = || {
            unreachable(format!(
                "{address}: no {what} from the PLC within {} ms",
                timeout.as_millis()
            ))
        };
        if left.is_zero() {
            return Err(late());
        }
        stream
            .set_read_timeout(Some(left))
            .map_err(|e| unreachable(format!("{address}: {e}")))?;
        match stream.read(&mut buf[at..]) {
            Ok(0) => {
                return Err(unreachable(format!(
                    "{address}: the PLC closed the connection during the handshake (waiting for its {what})"
                )));
            }
            Ok(n) => at += n,
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                return Err(late());
            }
            Err(e) => return Err(unreachable(format!("{address}: {e}"))),
        }
    }
    Ok(())
}

impl TcpSession {
    /// Connects to `address` (`HOST:PORT`) and authenticates as `name` with `key`; the
    /// connection and each step of the handshake wait at most `timeout`. A refusal (unknown
    /// name or wrong key) has status 1; no connection, no or a malformed handshake, or a
    /// server that does not prove it holds the key, status 3.
    pub fn connect(
        address: &str,
        name: &str,
        key: &[u8],
        timeout: Duration,
    ) -> Result<TcpSession, Failure> {
        // A zero duration is no timeout to the socket calls.
        let timeout = timeout.max(Duration::from_millis(1));
        let addrs: Vec<SocketAddr> = address
            .to_socket_addrs()
            .map_err(|e| unreachable(format!("cannot resolve {address}: {e}")))?
            .collect();
        let mut last = None;
        let mut stream = None;
        for addr in &addrs {
            match TcpStream::connect_timeout(addr, timeout) {
                Ok(s) => {
                    stream = Some(s);
                    break;
                }
                Err(e) => last = Some(e),
            }
        }
        let mut stream = stream.ok_or_else(|| {
            unreachable(match last {
                Some(e) => format!("cannot connect to {address}: {e}"),
                None => format!("cannot connect to {address}: no address"),
            })
        })?;
        let _ = stream.set_nodelay(true);
        let io = |e: std::io::Error| unreachable(format!("{address}: {e}"));
        stream.set_write_timeout(Some(timeout)).map_err(io)?;

        let deadline = Instant::now() + timeout;
        let mut challenge = [0u8; session::CHALLENGE_LEN];
        read_before(
            &mut stream,
            &mut challenge,
            deadline,
            address,
            "challenge",
            timeout,
        )?;
        let server_nonce = session::read_challenge(&challenge[..CHALLENGE_LEN]).map_err(|_| {
            unreachable(format!(
                "{address}: not the PLC's online service on TCP (a malformed challenge)"
            ))
        })?;
        let client_nonce = nonce()?;
        let mut response = [0u8; MAX_RESPONSE_LEN];
        let n = session::response(
            name.as_bytes(),
            key,
            &server_nonce,
            &client_nonce,
            &mut response,
        )
        .map_err(|_| Failure {
            message: format!(
                "the name {name:?} is no client name (1 to {} bytes)",
                session::MAX_NAME
            ),
            status: 2,
        })?;
        stream.write_all(&response[..n]).map_err(io)?;

        let deadline = Instant::now() + timeout;
        let mut answer = [0u8; ACCEPT_LEN];
        read_before(
            &mut stream,
            &mut answer[..1],
            deadline,
            address,
            "answer",
            timeout,
        )?;
        let answer: &[u8] = if answer[0] == session::REFUSE[0] {
            &answer[..1]
        } else {
            read_before(
                &mut stream,
                &mut answer[1..],
                deadline,
                address,
                "answer",
                timeout,
            )?;
            &answer
        };
        let (access, session) = match session::read_accept(
            key,
            &server_nonce,
            &client_nonce,
            answer,
        ) {
            Ok(accepted) => accepted,
            Err(_) if answer == session::REFUSE => {
                return Err(Failure {
                    message: format!(
                        "authentication refused by {address} (unknown name or wrong key for {name:?})"
                    ),
                    status: 1,
                });
            }
            Err(HandshakeError::Refused) => {
                return Err(unreachable(format!(
                    "{address} accepted, but did not prove that it holds the key for {name:?} (not the PLC?)"
                )));
            }
            Err(HandshakeError::Malformed) => {
                return Err(unreachable(format!(
                    "{address}: a malformed answer to the authentication"
                )));
            }
        };
        stream.set_nonblocking(true).map_err(io)?;
        Ok(TcpSession {
            stream,
            session,
            access,
            address: address.to_string(),
            timeout,
            received: Vec::new(),
            ended: None,
        })
    }

    /// What the PLC grants this session's key.
    pub fn access(&self) -> Access {
        self.access
    }

    /// Ends the session with `why`, which every later call returns.
    fn end(&mut self, why: String) -> String {
        self.ended = Some(why.clone());
        why
    }

    /// The next whole record in `received`, opened into `buf`.
    fn take_record(&mut self, buf: &mut [u8]) -> Result<Option<usize>, String> {
        let len = match Session::record_len(&self.received) {
            Ok(Some(len)) if self.received.len() >= len => len,
            Ok(_) => return Ok(None),
            Err(e) => {
                return Err(self.end(format!("{}: a bad record from the PLC: {e}", self.address)));
            }
        };
        let body = match self.session.open(&self.received[..len]) {
            Ok(body) => body,
            Err(e) => {
                return Err(self.end(format!("{}: a bad record from the PLC: {e}", self.address)));
            }
        };
        let Some(out) = buf.get_mut(..body.len()) else {
            return Err(format!(
                "{}: a message of {} bytes, longer than {}",
                self.address,
                body.len(),
                buf.len()
            ));
        };
        out.copy_from_slice(body);
        let n = body.len();
        self.received.drain(..len);
        Ok(Some(n))
    }
}

impl Transport for TcpSession {
    fn send(&mut self, message: &[u8]) -> Result<(), String> {
        if let Some(why) = &self.ended {
            return Err(why.clone());
        }
        let mut record = [0u8; MAX_RECORD];
        let n = self
            .session
            .seal(message, &mut record)
            .ok_or_else(|| format!("a message of {} bytes fits no record", message.len()))?;
        // The socket does not block: wait for room, at most the timeout.
        let deadline = Instant::now() + self.timeout;
        let mut at = 0;
        while at < n {
            match self.stream.write(&record[at..n]) {
                Ok(0) => {
                    return Err(
                        self.end(format!("{}: the PLC closed the connection", self.address))
                    );
                }
                Ok(k) => at += k,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) if e.kind() == ErrorKind::WouldBlock && Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(1));
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => {
                    return Err(self.end(format!(
                        "{}: the PLC takes no request within {} ms",
                        self.address,
                        self.timeout.as_millis()
                    )));
                }
                Err(e) => return Err(self.end(format!("{}: {e}", self.address))),
            }
        }
        Ok(())
    }

    fn try_receive(&mut self, buf: &mut [u8]) -> Result<Option<usize>, String> {
        if let Some(why) = &self.ended {
            return Err(why.clone());
        }
        let mut chunk = [0u8; MAX_RECORD];
        loop {
            if let Some(n) = self.take_record(buf)? {
                return Ok(Some(n));
            }
            match self.stream.read(&mut chunk) {
                Ok(0) => {
                    return Err(
                        self.end(format!("{}: the PLC closed the connection", self.address))
                    );
                }
                Ok(n) => self.received.extend_from_slice(&chunk[..n]),
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) if e.kind() == ErrorKind::WouldBlock => return Ok(None),
                Err(e) => return Err(self.end(format!("{}: {e}", self.address))),
            }
        }
    }

    fn pause(&mut self, time: Duration) {
        std::thread::sleep(time);
    }
}

#[cfg(test)]
mod tests;
