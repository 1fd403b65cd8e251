//! `plcctl`: the soft-PLC's online protocol ([`plc_online`]) from a Linux process, over a
//! pair of message devices (in the guest partition the ARINC queuing ports
//! `/dev/arinc/plc-request` and `/dev/arinc/plc-response`, connected by channels to the
//! PLC's `plc.online` ports), or over TCP to the PLC's authenticated online service
//! (`--connect`, [`tcp::TcpSession`]). This library is the tool without its files: the
//! command line ([`Command::parse`]), values typed as text ([`parse_value`]), the exchanges
//! of each command over a [`Link`] and the lines it prints, the TCP session and its key file
//! ([`tcp`]); `main.rs` only opens the devices or the connection.
//!
//! plcctl builds for the host too, where it reaches a PLC over TCP:
//! `cargo run -p plcctl -- --connect 127.0.0.1:PORT --key FILE list`.
//!
//! # Commands and output (stdout; errors on stderr as `plcctl: <what>`)
//!
//! | command | prints |
//! |---|---|
//! | `plcctl list` | `<name> <TYPE>` per variable (`TYPE` as IEC names it: `BOOL`, `LREAL`, `TOD`, `WSTRING`, `REF_TO`, ...) |
//! | `plcctl read NAME...` | `<name> = <value>` per name (IEC literal: `TRUE`, `42`, `0.5`, `T#20ms`, `D#2024-06-15`, `TOD#12:30:00`, `DT#2024-06-15-12:30:00`, `LT#1ms`, `'a'`, `"€"`, `'text'`, `"text"`, `REF(Main.x)`, `NULL`) |
//! | `plcctl watch NAME... [--interval T] [--count N]` | `t=<ms> <name>=<value> ...` every `T` (default 1s; `500ms`, `2s` or a number of ms), `N` times (default: until stopped) |
//! | `plcctl write NAME=VALUE` | `wrote <name> = <value>`: the variable takes the value once, between cycles, and the program may change it from then on (the value is parsed as the variable's type, which a READ tells: an IEC literal as `read` shows it, with or without its prefix; a STRING or WSTRING also unquoted) |
//! | `plcctl force NAME=VALUE` | `forced <name> = <value>`: the variable keeps the value (the program's writes to it have no effect) until `unforce`; the value as for `write` |
//! | `plcctl unforce NAME` | `unforced <name>` |
//! | `plcctl stats` | `task <name> stopped=<bool> cycles=<n> last_us=.. min_us=.. mean_us=.. max_us=.. last_jitter_us=.. max_jitter_us=.. overruns=<n> faults=<n>` per task |
//! | `plcctl stop [TASK...]` | `stopped task <name>` per task: it runs no more and its outputs take their safe values (every task without a name: the PLC goes to STOP, and a Modbus write is answered with exception 4) |
//! | `plcctl start [TASK...]` | `started task <name>` per task: a stopped task (by `stop`, a trap or its watchdog) runs again from its next release, its data kept (every task without a name) |
//! | `plcctl download FILE.plcb` | `downloaded FILE: <n> bytes, running from release <r>` |
//! | `plcctl store` | `store: loaded boot project #<n>, RETAIN snapshot #<m>` (what the PLC's persistent store, `plc.store`, loaded at its last cold start; `none` for the configured program or initial values) and `store: saved boot project #<n>, RETAIN snapshot #<m>` (the last saves), or `store: none (the PLC has no plc.store)` |
//! | `plcctl version` | `protocol: plcctl <n>, PLC <m>`: the online protocol versions plcctl and the PLC speak (a PLC of version 1 does not know the question: `PLC 1`) |
//!
//! Options before or after the command: `--request PATH`, `--response PATH` (the devices;
//! defaults [`DEFAULT_REQUEST`], [`DEFAULT_RESPONSE`]), `--timeout MS` (how long to wait
//! for each answer, and over TCP for the connection and each step of the handshake; default
//! 2000).
//!
//! # Over TCP
//!
//! `--connect HOST:PORT` talks to the PLC's online service on TCP instead of the devices
//! (`--request` and `--response` are then unused), authenticated with a pre-shared key
//! ([`plc_online::session`]: a challenge and response with HMAC-SHA-256, the PLC's proof
//! that it holds the key too, then every message in a record under a tag and a sequence
//! number). `--key FILE` is required with it: the key as hex text, 32 to 128 hex digits (an
//! even count: 16 to 64 bytes), whitespace and newlines around them ignored, e.g. made by
//! `od -An -tx1 -N32 /dev/urandom | tr -d ' \n' > engineering.key`; the PLC's configuration
//! holds the same file under the same name. `--name NAME` (1 to 32 bytes) is the name the
//! key is known by, by default the key file's name without its extension
//! (`keys/engineering.key`: `engineering`). `--key` and `--name` without `--connect` are
//! usage errors. The commands and their output are the same as over the devices; what the
//! key's access (`monitor`, `force`, `download`) does not allow, the PLC answers FORBIDDEN.
//! A refused authentication prints `plcctl: authentication refused by 127.0.0.1:1202
//! (unknown name or wrong key for "engineering")` (status 1); a bad key file, `plcctl: key
//! file <FILE>: <why>` (status 2); no connection, `plcctl: cannot connect to <HOST:PORT>:
//! <why>` (status 3); a tampered or replayed record from the PLC, or the connection closed,
//! ends the session (status 3).
//!
//! # Refusals and exit status
//!
//! A PLC that refuses prints `plcctl: <OP> <name>: <STATUS> (<reason>)`, e.g. `plcctl: FORCE valve: FORBIDDEN (the
//! client's access in the PLC's configuration does not allow it)`; a reference is never forced
//! (`plcctl: FORCE p: READ_ONLY (...)`, without asking). A value that is none of the
//! variable's type prints ``plcctl: FORCE <name>: `<text>` is not a TOD literal (expected
//! ...)`` or ``... is out of the range of INT (-32768 to 32767)``. Exit status: 0 done, 1 the
//! PLC refused (a request or the authentication), 2 a usage error (also a malformed value
//! or key file), 3 no answer, a device error or a connection error.

use plc_online::session::MAX_NAME;
use plc_online::{
    MAX_CHUNK, MAX_MESSAGE, PROTOCOL_VERSION, Reader, Request, Status, crc32, decode_response,
    encode_request, read_stats, read_store_status,
};
use plc_vm::image::VarType;
use plc_vm::literal::{self, LiteralError};
use plc_vm::vm::Value;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Duration;

pub mod tcp;

pub const DEFAULT_REQUEST: &str = "/dev/arinc/plc-request";
pub const DEFAULT_RESPONSE: &str = "/dev/arinc/plc-response";
/// How long each answer is waited for by default.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_millis(2000);

pub const USAGE: &str = "usage: plcctl [--request PATH] [--response PATH] [--timeout MS] \
[--connect HOST:PORT --key FILE [--name NAME]] list | read NAME... | watch NAME... [--interval T] [--count N] | write NAME=VALUE | \
force NAME=VALUE | unforce NAME | stats | store | download FILE.plcb | version";

/// What the command line asks.
#[derive(Clone, Debug, PartialEq)]
pub struct Command {
    pub request: String,
    pub response: String,
    pub timeout: Duration,
    /// `--connect`: over TCP instead of the devices.
    pub connect: Option<Connect>,
    pub action: Action,
}

/// The PLC's online service on TCP and the key to authenticate with (`--connect`, `--key`,
/// `--name`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Connect {
    /// `HOST:PORT`.
    pub address: String,
    /// The key file's path ([`tcp::read_key`] reads it).
    pub key_file: String,
    /// The name the key is known by: `--name`, or the key file's name without its
    /// extension.
    pub name: String,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    List,
    Read(Vec<String>),
    Watch {
        names: Vec<String>,
        interval: Duration,
        count: Option<u64>,
    },
    /// WRITE (`force` false) or FORCE (`force` true).
    Set {
        name: String,
        value: String,
        force: bool,
    },
    Unforce(String),
    Stats,
    /// STOP (`run` false) or START (`run` true) of the named tasks, or of every task.
    Run {
        tasks: Vec<String>,
        run: bool,
    },
    Store,
    Download(String),
    Version,
}

/// A duration as `500ms`, `2s` or a number of milliseconds.
pub fn parse_duration(text: &str) -> Option<Duration> {
    if let Some(ms) = text.strip_suffix("ms") {
        return ms.parse().ok().map(Duration::from_millis);
    }
    if let Some(s) = text.strip_suffix('s') {
        return s.parse().ok().map(Duration::from_secs);
    }
    text.parse().ok().map(Duration::from_millis)
}

impl Command {
    /// The command of `args` (without the program name), or the usage error.
    pub fn parse(args: &[String]) -> Result<Command, String> {
        let mut request = DEFAULT_REQUEST.to_string();
        let mut response = DEFAULT_RESPONSE.to_string();
        let mut timeout = DEFAULT_TIMEOUT;
        let mut interval = Duration::from_secs(1);
        let mut count = None;
        let (mut connect, mut key, mut name) = (None, None, None);
        let mut words = Vec::new();
        let mut it = args.iter();
        while let Some(arg) = it.next() {
            let mut value = |what: &str| {
                it.next()
                    .cloned()
                    .ok_or_else(|| format!("{arg} needs {what}"))
            };
            match arg.as_str() {
                "--request" => request = value("a path")?,
                "--connect" => connect = Some(value("HOST:PORT")?),
                "--key" => key = Some(value("a key file")?),
                "--name" => name = Some(value("a name")?),
                "--response" => response = value("a path")?,
                "--timeout" => {
                    timeout = parse_duration(&value("a time")?)
                        .ok_or_else(|| format!("{arg}: not a time"))?
                }
                "--interval" => {
                    interval = parse_duration(&value("a time")?)
                        .filter(|d| !d.is_zero())
                        .ok_or_else(|| format!("{arg}: not a time above 0"))?
                }
                "--count" => {
                    count = Some(
                        value("a number")?
                            .parse()
                            .map_err(|_| format!("{arg}: not a number"))?,
                    )
                }
                flag if flag.starts_with("--") => return Err(format!("unknown option {flag}")),
                word => words.push(word.to_string()),
            }
        }
        let connect = match (connect, key) {
            (Some(address), Some(key_file)) => {
                if !address
                    .rsplit_once(':')
                    .is_some_and(|(host, port)| !host.is_empty() && port.parse::<u16>().is_ok())
                {
                    return Err(format!("--connect {address}: not HOST:PORT"));
                }
                let name = name.unwrap_or_else(|| default_name(&key_file));
                if name.is_empty() || name.len() > MAX_NAME {
                    return Err(format!(
                        "the name {name:?} is no client name (1 to {MAX_NAME} bytes; --name NAME)"
                    ));
                }
                Some(Connect {
                    address,
                    key_file,
                    name,
                })
            }
            (Some(_), None) => return Err("--connect needs --key FILE".into()),
            (None, Some(_)) => return Err("--key goes with --connect HOST:PORT".into()),
            (None, None) if name.is_some() => {
                return Err("--name goes with --connect HOST:PORT".into());
            }
            (None, None) => None,
        };
        let (verb, rest) = words.split_first().ok_or("no command")?;
        let one = |what: &str| match rest {
            [one] => Ok(one.clone()),
            _ => Err(format!("{verb} takes one {what}")),
        };
        let some = |rest: &[String]| {
            if rest.is_empty() {
                Err(format!("{verb} needs at least one name"))
            } else {
                Ok(rest.to_vec())
            }
        };
        let action = match verb.as_str() {
            "list" if rest.is_empty() => Action::List,
            "stats" if rest.is_empty() => Action::Stats,
            "store" if rest.is_empty() => Action::Store,
            "version" if rest.is_empty() => Action::Version,
            "read" => Action::Read(some(rest)?),
            "watch" => Action::Watch {
                names: some(rest)?,
                interval,
                count,
            },
            "write" | "force" => {
                let pair = one("NAME=VALUE")?;
                let (name, value) = pair
                    .split_once('=')
                    .filter(|(n, v)| !n.is_empty() && !v.is_empty())
                    .ok_or(format!("{verb} takes NAME=VALUE"))?;
                Action::Set {
                    name: name.into(),
                    value: value.into(),
                    force: verb == "force",
                }
            }
            "unforce" => Action::Unforce(one("NAME")?),
            "stop" | "start" => Action::Run {
                tasks: rest.to_vec(),
                run: verb == "start",
            },
            "download" => Action::Download(one("FILE")?),
            "list" | "stats" | "store" | "version" => {
                return Err(format!("{verb} takes no arguments"));
            }
            other => return Err(format!("unknown command {other}")),
        };
        Ok(Command {
            request,
            response,
            timeout,
            connect,
            action,
        })
    }
}

/// The name a key file's key is known by unless `--name` says: the file's name without its
/// extension (`keys/engineering.key`: `engineering`).
pub fn default_name(key_file: &str) -> String {
    Path::new(key_file)
        .file_stem()
        .map(|stem| stem.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Most bytes a typed STRING or WSTRING may take: what a FORCE or WRITE message carries
/// besides its head, the value's type and length and a one-byte name.
pub const MAX_TEXT: usize = MAX_MESSAGE - 2 - 3 - 1;

/// `text` as a value of a variable of type `ty` (the type a READ of it tells), parsed as
/// the PLC's monitors parse values ([`plc_vm::literal`]): `TRUE`/`FALSE` (or 1/0),
/// integers (`-5`, `16#FF`, `INT#7`), reals, `T#1s500ms`, `LT#2ms`, `D#2024-06-15`,
/// `TOD#12:30:00.5`, `DT#2024-06-15-12:30:00`, `'a'` or `a` or `97` for a CHAR, `"€"` for
/// a WCHAR, `'text'` or bare text for a STRING and `"text"` for a WSTRING (into `buf`); or
/// why it is none. A reference is never parsed ([`LiteralError::ReadOnly`]).
pub fn parse_value<'b>(
    text: &str,
    ty: VarType,
    buf: &'b mut [u8],
) -> Result<Value<'b>, LiteralError> {
    literal::parse(text, ty, buf)
}

/// Why a PLC refuses, for people.
pub fn reason(status: Status) -> &'static str {
    match status {
        Status::Ok => "done",
        Status::Malformed => "the PLC could not decode the request",
        Status::UnknownName => "no variable of that name",
        Status::TypeMismatch => "the value does not fit the variable's type",
        Status::Constant => "the variable is CONSTANT",
        Status::Forbidden => "the client's access in the PLC's configuration does not allow it",
        Status::TooManyForces => "every force slot is in use",
        Status::NoSuchTask => "no task of that number",
        Status::Unsupported => "not supported for this variable",
        Status::BadOffset => "a download chunk out of order",
        Status::TooLarge => "the program is larger than the PLC's download buffer",
        Status::ChecksumMismatch => "the program arrived damaged (CRC-32)",
        Status::Refused => "the PLC's checks refused the program; its log says why",
        Status::NoDownload => "no download in progress",
        Status::Incomplete => "not every byte of the program arrived",
        Status::ReadOnly => {
            "a reference is read-only online: a written address could make the program reach another variable than the one it referenced, or trap"
        }
    }
}

/// A failed command: its message (for stderr) and the exit status.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Failure {
    pub message: String,
    pub status: i32,
}

impl Failure {
    fn refused(what: &str, status: Status) -> Self {
        Failure {
            message: format!("{what}: {} ({})", status.name(), reason(status)),
            status: 1,
        }
    }

    fn device(message: String) -> Self {
        Failure { message, status: 3 }
    }
}

pub use port_devices::Transport;

/// Requests and their answers, matched by sequence number (answers to earlier requests,
/// which timed out, are dropped).
pub struct Link<T: Transport> {
    pub transport: T,
    pub timeout: Duration,
    seq: u8,
}

/// How often a missing answer is looked for.
const POLL: Duration = Duration::from_millis(2);

impl<T: Transport> Link<T> {
    pub fn new(transport: T, timeout: Duration) -> Self {
        Link {
            transport,
            timeout,
            seq: 0,
        }
    }

    /// Sends `r` and returns the answer's status and its whole message.
    pub fn ask(&mut self, r: &Request) -> Result<(Status, Vec<u8>), Failure> {
        self.seq = self.seq.wrapping_add(1);
        let mut message = [0u8; MAX_MESSAGE];
        let n = encode_request(r, self.seq, &mut message).ok_or_else(|| {
            Failure::device(format!("{}: too long for one message", r.op().name()))
        })?;
        let mut answer = [0u8; MAX_MESSAGE];
        // Answers still queued from an earlier run are not this one's.
        while self
            .transport
            .try_receive(&mut answer)
            .map_err(Failure::device)?
            .is_some()
        {}
        self.transport
            .send(&message[..n])
            .map_err(Failure::device)?;
        let mut waited = Duration::ZERO;
        loop {
            if let Some(len) = self
                .transport
                .try_receive(&mut answer)
                .map_err(Failure::device)?
                && let Some((_, seq, status, _)) = decode_response(&answer[..len])
                && seq == self.seq
            {
                return Ok((status, answer[..len].to_vec()));
            }
            if waited >= self.timeout {
                return Err(Failure::device(format!(
                    "{}: no answer from the PLC within {} ms",
                    r.op().name(),
                    self.timeout.as_millis()
                )));
            }
            self.transport.pause(POLL);
            waited += POLL;
        }
    }

    /// [`Link::ask`], a refusal as a [`Failure`] naming `what`; the answer's result.
    fn ok(&mut self, r: &Request, what: &str) -> Result<Vec<u8>, Failure> {
        match self.ask(r)? {
            (Status::Ok, message) => Ok(message),
            (status, _) => Err(Failure::refused(what, status)),
        }
    }

    /// The value of `name`: its type and its IEC literal.
    fn read(&mut self, name: &str) -> Result<(VarType, String), Failure> {
        let message = self.ok(&Request::Read { name }, &format!("READ {name}"))?;
        result(&message)
            .and_then(|mut r| r.typed_value())
            .map(|(ty, value)| (ty, value.to_string()))
            .ok_or_else(|| Failure::device(format!("READ {name}: a malformed answer")))
    }

    /// Runs `action`, writing its lines to `out`.
    pub fn run(&mut self, action: &Action, out: &mut dyn FnMut(&str)) -> Result<(), Failure> {
        match action {
            Action::List => self.list(out),
            Action::Read(names) => {
                for name in names {
                    let (_, value) = self.read(name)?;
                    out(&format!("{name} = {value}"));
                }
                Ok(())
            }
            Action::Watch {
                names,
                interval,
                count,
            } => {
                let mut round = 0u64;
                let mut at = Duration::ZERO;
                while count.is_none_or(|c| round < c) {
                    let mut line = format!("t={}", at.as_millis());
                    for name in names {
                        let (_, value) = self.read(name)?;
                        let _ = write!(line, " {name}={value}");
                    }
                    out(&line);
                    round += 1;
                    if count.is_none_or(|c| round < c) {
                        self.transport.pause(*interval);
                        at += *interval;
                    }
                }
                Ok(())
            }
            Action::Set { name, value, force } => {
                let (ty, _) = self.read(name)?;
                let what = format!("{} {name}", if *force { "FORCE" } else { "WRITE" });
                let mut buf = [0u8; MAX_TEXT];
                let parsed = match parse_value(value, ty, &mut buf) {
                    Ok(parsed) => parsed,
                    Err(LiteralError::ReadOnly) => {
                        return Err(Failure::refused(&what, Status::ReadOnly));
                    }
                    Err(e) => {
                        return Err(Failure {
                            message: format!("{what}: `{value}` is {e}"),
                            status: 2,
                        });
                    }
                };
                let (request, done) = if *force {
                    let value = parsed;
                    (Request::Force { name, value }, "forced")
                } else {
                    let value = parsed;
                    (Request::Write { name, value }, "wrote")
                };
                self.ok(&request, &what)?;
                out(&format!("{done} {name} = {parsed}"));
                Ok(())
            }
            Action::Unforce(name) => {
                self.ok(&Request::Unforce { name }, &format!("UNFORCE {name}"))?;
                out(&format!("unforced {name}"));
                Ok(())
            }
            Action::Stats => self.stats(out),
            Action::Run { tasks, run } => self.stop_or_start(tasks, *run, out),
            Action::Store => {
                let s = match self.ask(&Request::Store)? {
                    (Status::Ok, message) => result(&message)
                        .and_then(|mut r| read_store_status(&mut r))
                        .ok_or_else(|| Failure::device("STORE: a malformed answer".into()))?,
                    // A PLC of protocol version 2 or older does not know the question.
                    (Status::Malformed, _) => {
                        return Err(Failure::device(
                            "STORE: the PLC's online protocol is older than version 3".into(),
                        ));
                    }
                    (status, _) => return Err(Failure::refused("STORE", status)),
                };
                if !s.configured {
                    out("store: none (the PLC has no plc.store)");
                    return Ok(());
                }
                let n = |seq: u64| {
                    if seq == 0 {
                        "none".to_string()
                    } else {
                        format!("#{seq}")
                    }
                };
                out(&format!(
                    "store: loaded boot project {}, RETAIN snapshot {}",
                    n(s.boot_loaded),
                    n(s.retain_loaded)
                ));
                out(&format!(
                    "store: saved boot project {}, RETAIN snapshot {}",
                    n(s.boot_saved),
                    n(s.retain_saved)
                ));
                Ok(())
            }
            Action::Version => {
                let plc = match self.ask(&Request::Version)? {
                    (Status::Ok, message) => result(&message)
                        .and_then(|mut r| r.u16())
                        .ok_or_else(|| Failure::device("VERSION: a malformed answer".into()))?,
                    // A version 1 PLC does not know the question.
                    (Status::Malformed, _) => 1,
                    (status, _) => return Err(Failure::refused("VERSION", status)),
                };
                out(&format!("protocol: plcctl {PROTOCOL_VERSION}, PLC {plc}"));
                Ok(())
            }
            Action::Download(_) => Err(Failure {
                message: "download: the file is read by the program".into(),
                status: 2,
            }),
        }
    }

    fn list(&mut self, out: &mut dyn FnMut(&str)) -> Result<(), Failure> {
        let mut from = 0u16;
        loop {
            let message = self.ok(&Request::List { from }, "LIST")?;
            let malformed = || Failure::device("LIST: a malformed answer".into());
            let mut r = result(&message).ok_or_else(malformed)?;
            let total = r.u16().ok_or_else(malformed)?;
            let count = r.u8().ok_or_else(malformed)?;
            for _ in 0..count {
                let ty = r.u8().ok_or_else(malformed)?;
                let name = r.short_str().ok_or_else(malformed)?;
                match VarType::from_code(ty) {
                    Some(ty) => out(&format!("{name} {}", ty.name())),
                    // A type of a later protocol version.
                    None => out(&format!("{name} ?{ty}")),
                }
            }
            from = from.saturating_add(u16::from(count));
            if count == 0 || from >= total {
                return Ok(());
            }
        }
    }

    /// Each task's statistics, task 0 first, as STATS tells them.
    fn each_task(
        &mut self,
        mut each: impl FnMut(&plc_online::TaskStats<'_>),
    ) -> Result<(), Failure> {
        for task in 0..=u8::MAX {
            let message = match self.ask(&Request::Stats { task })? {
                (Status::Ok, message) => message,
                (Status::NoSuchTask, _) if task > 0 => break,
                (status, _) => return Err(Failure::refused("STATS", status)),
            };
            let s = result(&message)
                .and_then(|mut r| read_stats(&mut r))
                .ok_or_else(|| Failure::device("STATS: a malformed answer".into()))?;
            each(&s);
        }
        Ok(())
    }

    fn stats(&mut self, out: &mut dyn FnMut(&str)) -> Result<(), Failure> {
        self.each_task(|s| {
            let [
                count,
                last,
                min,
                mean,
                max,
                last_jitter,
                max_jitter,
                overruns,
                faults,
            ] = s.figures;
            out(&format!(
                "task {} stopped={} cycles={count} last_us={} min_us={} mean_us={} max_us={} last_jitter_us={} max_jitter_us={} overruns={overruns} faults={faults}",
                s.name,
                s.stopped,
                last / 1000,
                min / 1000,
                mean / 1000,
                max / 1000,
                last_jitter / 1000,
                max_jitter / 1000
            ));
        })
    }

    /// The PLC's tasks by number: their names, as STATS tells them.
    fn task_names(&mut self) -> Result<Vec<String>, Failure> {
        let mut names = Vec::new();
        self.each_task(|s| names.push(s.name.to_string()))?;
        Ok(names)
    }

    /// STOP or START of the tasks named (every task when none is), each name checked
    /// before any task is touched.
    fn stop_or_start(
        &mut self,
        tasks: &[String],
        run: bool,
        out: &mut dyn FnMut(&str),
    ) -> Result<(), Failure> {
        let names = self.task_names()?;
        let chosen = if tasks.is_empty() {
            (0..names.len()).collect::<Vec<_>>()
        } else {
            let mut chosen = Vec::new();
            for task in tasks {
                let i = names
                    .iter()
                    .position(|n| n.eq_ignore_ascii_case(task))
                    .ok_or_else(|| Failure {
                        message: format!(
                            "no task {task} in the PLC (its tasks: {})",
                            names.join(", ")
                        ),
                        status: 1,
                    })?;
                chosen.push(i);
            }
            chosen
        };
        let (what, done) = if run {
            ("START", "started")
        } else {
            ("STOP", "stopped")
        };
        for i in chosen {
            // At most 256 tasks: STATS numbers them with a byte.
            let task = i as u8;
            let request = if run {
                Request::Start { task }
            } else {
                Request::Stop { task }
            };
            self.ok(&request, &format!("{what} {}", names[i]))?;
            out(&format!("{done} task {}", names[i]));
        }
        Ok(())
    }

    /// Downloads `image` (a `.plcb` file's bytes) named `file`: BEGIN, the chunks,
    /// COMMIT.
    pub fn download(
        &mut self,
        file: &str,
        image: &[u8],
        out: &mut dyn FnMut(&str),
    ) -> Result<(), Failure> {
        let size = u32::try_from(image.len()).map_err(|_| Failure {
            message: format!("{file}: too large"),
            status: 2,
        })?;
        let begin = Request::DownloadBegin {
            size,
            crc32: crc32(image),
        };
        self.ok(&begin, "DOWNLOAD_BEGIN")?;
        for (i, bytes) in image.chunks(MAX_CHUNK).enumerate() {
            let offset = (i * MAX_CHUNK) as u32;
            self.ok(&Request::DownloadChunk { offset, bytes }, "DOWNLOAD_CHUNK")?;
        }
        let message = self.ok(&Request::DownloadCommit, "DOWNLOAD_COMMIT")?;
        let release = result(&message)
            .and_then(|mut r| r.u64())
            .ok_or_else(|| Failure::device("DOWNLOAD_COMMIT: a malformed answer".into()))?;
        out(&format!(
            "downloaded {file}: {} bytes, running from release {release}",
            image.len()
        ));
        Ok(())
    }
}

/// The result part of an OK answer.
fn result(message: &[u8]) -> Option<Reader<'_>> {
    decode_response(message).map(|(_, _, _, r)| r)
}

#[cfg(test)]
mod tests;

/// Runs `command` as the `plcctl` program does: over the request and response devices, or
/// with `--connect` after reading the key file and authenticating over TCP ([`tcp`]); each
/// line of output to `out`.
pub fn execute(command: &Command, out: &mut dyn FnMut(&str)) -> Result<(), Failure> {
    let image = match &command.action {
        Action::Download(file) => Some(std::fs::read(file).map_err(|e| Failure {
            message: format!("cannot read {file}: {e}"),
            status: 2,
        })?),
        _ => None,
    };
    match &command.connect {
        Some(c) => {
            let key = tcp::read_key(&c.key_file)?;
            let session = tcp::TcpSession::connect(&c.address, &c.name, &key, command.timeout)?;
            run_over(command, session, image, out)
        }
        None => {
            let devices = port_devices::Devices::open(&command.request, &command.response)
                .map_err(|message| Failure { message, status: 3 })?;
            run_over(command, devices, image, out)
        }
    }
}

/// Runs `command`'s action over `transport`, `image` the file to download.
fn run_over<T: Transport>(
    command: &Command,
    transport: T,
    image: Option<Vec<u8>>,
    out: &mut dyn FnMut(&str),
) -> Result<(), Failure> {
    let mut link = Link::new(transport, command.timeout);
    match (&command.action, image) {
        (Action::Download(file), Some(image)) => link.download(file, &image, out),
        (action, _) => link.run(action, out),
    }
}
