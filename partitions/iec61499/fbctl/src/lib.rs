//! `fbctl`: 4diac's management requests to the IEC 61499 partition from Linux, over the
//! partition's management ports (`iec61499.mgmt`, devices `/dev/arinc/<port>` in the
//! guest), one request a message as `iec61499_mgmt::serve` defines them, or with `--tcp
//! ADDRESS:PORT` over TCP as 4diac IDE speaks the protocol (`iec61499_mgmt::tcp`'s
//! framing): to a partition's port 61499 (`iec61499.net`) or to a FORTE device.
//!
//! ```text
//! fbctl [--request PATH] [--response PATH] [--tcp ADDRESS:PORT] [--timeout MS]
//!       [--adapter FILE.adp]... COMMAND
//!   send DEST REQUEST   one request (DEST empty for the device); prints the response
//!   boot FILE           every line of a boot file (.fboot); prints each response, stops
//!                       at the first refusal
//!   type FILE           sends a basic or composite FB type in parts: a `.fbt` is compiled here
//!                       (outside the real-time partition), any other file is taken as a
//!                       compiled package (`compile`'s output) and sent as it is; the
//!                       device checks it whole and refuses it with the reason in its log
//!   compile FILE.fbt OUT   writes the type's package to OUT
//!   --adapter FILE.adp  an adapter type the compiled type's plugs and sockets may be of
//!                       (once per type)
//! ```
//!
//! Output (an interface): `send` prints the response as the device wrote it; `boot` prints
//! `<line>: <response>` per line; `type` prints `type <NAME>: <n> bytes in <k> part(s),
//! added` or the refusal; `compile` prints `type <NAME>: <n> bytes written to <OUT>`. Exit status: 0 done, 1 refused by the device (the response
//! names the reason), 2 bad usage or file (compile errors as `file:line:col`), 3 no
//! answer, a port device error or a connection that failed.

use iec61499_mgmt::serve::type_messages;
use iec61499_mgmt::tcp::{encode_request, read_response};
use std::io::{Read, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};

/// The ports' message size (`iec61499.mgmt` ports have `size = 4096`).
pub const MAX_MESSAGE: usize = 4096;
pub const DEFAULT_REQUEST: &str = "/dev/arinc/fb-request";
pub const DEFAULT_RESPONSE: &str = "/dev/arinc/fb-response";
pub const USAGE: &str = "usage: fbctl [--request PATH] [--response PATH] [--tcp ADDRESS:PORT] [--timeout MS] [--adapter FILE.adp]... (send DEST REQUEST | boot FILE.fboot | type FILE | compile FILE.fbt OUT)";
/// The longest response read (a TCP response may be longer than a port's message).
const MAX_RESPONSE: usize = iec61499_mgmt::tcp::MAX_RESPONSE;

/// How a command ended badly: the message and the exit status.
#[derive(Debug, PartialEq, Eq)]
pub struct Failure {
    pub message: String,
    pub status: u8,
}

impl Failure {
    fn usage(message: String) -> Self {
        Failure { message, status: 2 }
    }
    fn refused(message: String) -> Self {
        Failure { message, status: 1 }
    }
    fn link(message: String) -> Self {
        Failure { message, status: 3 }
    }
}

/// What to do.
#[derive(Debug, PartialEq, Eq)]
pub enum Action {
    Send {
        destination: String,
        request: String,
    },
    Boot(String),
    Type(String),
    Compile {
        fbt: String,
        out: String,
    },
}

/// A parsed command line.
#[derive(Debug, PartialEq, Eq)]
pub struct Command {
    pub request: String,
    pub response: String,
    /// `--tcp`: the device's management address instead of the ports.
    pub tcp: Option<String>,
    pub timeout: Duration,
    /// `--adapter`: adapter type files for `type` and `compile`.
    pub adapters: Vec<String>,
    pub action: Action,
}

impl Command {
    pub fn parse(args: &[String]) -> Result<Command, String> {
        let mut request = DEFAULT_REQUEST.to_string();
        let mut response = DEFAULT_RESPONSE.to_string();
        let mut tcp = None;
        let mut ports_named = false;
        let mut timeout = Duration::from_secs(2);
        let mut adapters = Vec::new();
        let mut rest = args;
        while let [flag, value, tail @ ..] = rest {
            match flag.as_str() {
                "--request" => (request, ports_named) = (value.clone(), true),
                "--response" => (response, ports_named) = (value.clone(), true),
                "--tcp" => tcp = Some(value.clone()),
                "--adapter" => adapters.push(value.clone()),
                "--timeout" => {
                    let ms: u64 = value
                        .parse()
                        .map_err(|_| format!("--timeout {value}: not a number of milliseconds"))?;
                    timeout = Duration::from_millis(ms);
                }
                _ => break,
            }
            rest = tail;
        }
        let action = match rest {
            [c, d, r] if c == "send" => Action::Send {
                destination: d.clone(),
                request: r.clone(),
            },
            [c, f] if c == "boot" => Action::Boot(f.clone()),
            [c, f] if c == "type" => Action::Type(f.clone()),
            [c, f, o] if c == "compile" => Action::Compile {
                fbt: f.clone(),
                out: o.clone(),
            },
            [] => return Err("no command".into()),
            [c, ..] => return Err(format!("unknown command or arguments: {c}")),
        };
        if tcp.is_some() && ports_named {
            return Err("--tcp and --request/--response name two ways to the device".into());
        }
        Ok(Command {
            request,
            response,
            tcp,
            timeout,
            adapters,
            action,
        })
    }
}

pub use port_devices::Transport;

/// The management protocol on a TCP connection (`--tcp`): each message `DEST;REQUEST` goes
/// as 4diac IDE frames it, each response comes as one STRING.
pub struct TcpTransport {
    stream: TcpStream,
    /// Bytes of responses not yet whole.
    received: Vec<u8>,
}

impl TcpTransport {
    /// Connects to `address` (`host:port`), waiting at most `timeout`.
    pub fn connect(address: &str, timeout: Duration) -> Result<Self, String> {
        let peer = address
            .to_socket_addrs()
            .map_err(|e| format!("--tcp {address}: {e}"))?
            .next()
            .ok_or_else(|| format!("--tcp {address}: no address"))?;
        let stream = TcpStream::connect_timeout(&peer, timeout)
            .map_err(|e| format!("cannot connect to {address}: {e}"))?;
        stream
            .set_nonblocking(true)
            .and_then(|()| stream.set_nodelay(true))
            .map_err(|e| format!("{address}: {e}"))?;
        Ok(TcpTransport {
            stream,
            received: Vec::new(),
        })
    }
}

impl Transport for TcpTransport {
    fn send(&mut self, message: &[u8]) -> Result<(), String> {
        let text = std::str::from_utf8(message).map_err(|_| "a request that is not UTF-8")?;
        let (destination, request) = text.split_once(';').unwrap_or(("", text));
        let frame = encode_request(destination, request);
        // The socket does not block: a full send buffer is waited out (bounded by the
        // stream's progress; the device reads its requests whole).
        let mut sent = 0;
        while sent < frame.len() {
            match self.stream.write(&frame[sent..]) {
                Ok(0) => return Err("the device closed the connection".into()),
                Ok(n) => sent += n,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => std::thread::sleep(POLL),
                Err(e) => return Err(format!("sending: {e}")),
            }
        }
        Ok(())
    }

    fn try_receive(&mut self, buf: &mut [u8]) -> Result<Option<usize>, String> {
        let mut chunk = [0u8; 4096];
        while self.received.len() < MAX_RESPONSE + 3 {
            match self.stream.read(&mut chunk) {
                Ok(0) if self.received.is_empty() => {
                    return Err("the device closed the connection".into());
                }
                Ok(0) => break,
                Ok(n) => self.received.extend_from_slice(&chunk[..n]),
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break,
                Err(e) => return Err(format!("receiving: {e}")),
            }
        }
        match read_response(&self.received) {
            Ok(Some((xml, used))) => {
                let n = xml.len().min(buf.len());
                buf[..n].copy_from_slice(&xml[..n]);
                self.received.drain(..used);
                Ok(Some(n))
            }
            Ok(None) => Ok(None),
            Err(e) => Err(format!("not a response of the management protocol: {e}")),
        }
    }

    fn pause(&mut self, time: Duration) {
        std::thread::sleep(time);
    }
}

/// How often a missing response is looked for.
const POLL: Duration = Duration::from_millis(2);

/// The `ID` attribute of a request or response.
fn id_of(text: &str) -> Option<&str> {
    text.split("ID=\"").nth(1)?.split('"').next()
}

/// Requests and their responses, matched by ID (responses to earlier requests that timed
/// out are dropped).
pub struct Link<T: Transport> {
    pub transport: T,
    pub timeout: Duration,
    /// The adapter types a compiled type's plugs and sockets may be of.
    pub adapters: Vec<iec61499_build::AdapterType>,
}

impl<T: Transport> Link<T> {
    /// Sends `destination;request` and returns the response.
    pub fn ask(&mut self, destination: &str, request: &str) -> Result<String, Failure> {
        let message = format!("{destination};{request}");
        if message.len() > MAX_MESSAGE {
            return Err(Failure::usage(format!(
                "the request is {} bytes; a message holds {MAX_MESSAGE}",
                message.len()
            )));
        }
        let mut buf = vec![0u8; MAX_RESPONSE];
        while self
            .transport
            .try_receive(&mut buf)
            .map_err(Failure::link)?
            .is_some()
        {}
        self.transport
            .send(message.as_bytes())
            .map_err(Failure::link)?;
        let id = id_of(request).unwrap_or("");
        let start = Instant::now();
        loop {
            if let Some(n) = self
                .transport
                .try_receive(&mut buf)
                .map_err(Failure::link)?
            {
                let text = String::from_utf8_lossy(&buf[..n]).into_owned();
                if id_of(&text) == Some(id) {
                    return Ok(text);
                }
                continue;
            }
            if start.elapsed() >= self.timeout {
                return Err(Failure::link(format!(
                    "no response within {} ms",
                    self.timeout.as_millis()
                )));
            }
            self.transport.pause(POLL);
        }
    }

    /// Runs `action` (its file already read: `file`), printing through `out`; `compile`
    /// returns the package to write, the others nothing.
    pub fn run(
        &mut self,
        action: &Action,
        file: &[u8],
        out: &mut dyn FnMut(&str),
    ) -> Result<Option<Vec<u8>>, Failure> {
        match action {
            Action::Send {
                destination,
                request,
            } => {
                let answer = self.ask(destination, request)?;
                out(&answer);
                match refused(&answer) {
                    Some(reason) => Err(Failure::refused(format!("refused: {reason}"))),
                    None => Ok(None),
                }
            }
            Action::Boot(name) => {
                let text = text_of(name, file)?;
                let lines = iec61499_mgmt::fboot::lines(text)
                    .map_err(|e| Failure::usage(format!("{name}: {e}")))?;
                for line in lines {
                    let answer = self.ask(line.destination, line.request)?;
                    out(&format!("{}: {answer}", line.number));
                    if let Some(reason) = refused(&answer) {
                        return Err(Failure::refused(format!(
                            "{name}:{}: refused: {reason}",
                            line.number
                        )));
                    }
                }
                Ok(None)
            }
            Action::Type(name) => {
                let (ty, package) = if name.ends_with(".fbt") {
                    compile(name, file, &self.adapters)?
                } else {
                    let ty = package_name(file).ok_or_else(|| {
                        Failure::usage(format!("{name}: neither a .fbt file nor a type package"))
                    })?;
                    (ty, file.to_vec())
                };
                let parts = type_messages(&ty, &package, MAX_MESSAGE, 1);
                for part in &parts {
                    let (destination, request) = part.split_once(';').unwrap_or(("", part));
                    let answer = self.ask(destination, request)?;
                    if let Some(reason) = refused(&answer) {
                        return Err(Failure::refused(format!(
                            "type {ty}: refused: {reason} (the partition's log says why)"
                        )));
                    }
                }
                out(&format!(
                    "type {ty}: {} bytes in {} part(s), added",
                    package.len(),
                    parts.len()
                ));
                Ok(None)
            }
            Action::Compile { fbt, out: to } => {
                let (ty, package) = compile(fbt, file, &self.adapters)?;
                out(&format!(
                    "type {ty}: {} bytes written to {to}",
                    package.len()
                ));
                Ok(Some(package))
            }
        }
    }
}

fn text_of<'a>(name: &str, file: &'a [u8]) -> Result<&'a str, Failure> {
    std::str::from_utf8(file).map_err(|_| Failure::usage(format!("{name}: not UTF-8 text")))
}

/// Compiles the `.fbt` text `file`: the type's name and package.
fn compile(
    name: &str,
    file: &[u8],
    adapters: &[iec61499_build::AdapterType],
) -> Result<(String, Vec<u8>), Failure> {
    let t = iec61499_build::compile_any(name, text_of(name, file)?, adapters)
        .map_err(|errors| Failure::usage(errors.join("\n")))?;
    Ok((t.name().to_string(), t.package()))
}

/// Reads the adapter type files `paths` (`--adapter`).
pub fn read_adapters(paths: &[String]) -> Result<Vec<iec61499_build::AdapterType>, Failure> {
    paths
        .iter()
        .map(|path| {
            let text = std::fs::read(path)
                .map_err(|e| Failure::usage(format!("cannot read {path}: {e}")))?;
            iec61499_build::read_adp(path, text_of(path, &text)?)
                .map_err(|e| Failure::usage(e.to_string()))
        })
        .collect()
}

/// The type name a package says it holds (its name record; nothing else is checked here:
/// the device checks the package whole).
pub fn package_name(package: &[u8]) -> Option<String> {
    // A basic type's name is a u8-counted record after a u16 count, a composite's a
    // u16-counted text (`iec61499_runtime::package`, `::composite`).
    let (start, len) = match package.get(..4)? {
        b"W61T" => (15, usize::from(*package.get(14)?)),
        b"W61N" => (
            14,
            usize::from(u16::from_le_bytes([*package.get(12)?, *package.get(13)?])),
        ),
        _ => return None,
    };
    let name = std::str::from_utf8(package.get(start..start + len)?).ok()?;
    Some(name.to_string())
}

/// The reason of a refusal, `None` when the request was done.
pub fn refused(response: &str) -> Option<&str> {
    response.split("Reason=\"").nth(1)?.split('"').next()
}

#[cfg(test)]
mod tests;
