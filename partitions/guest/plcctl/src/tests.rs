//! The commands against a model PLC answering through the online protocol's own encoder.

use super::*;
use plc_online::{Access, TaskStats, begin_response, decode_request, put_stats};
use plc_vm::isa::TimeKind;
use std::collections::VecDeque;

fn args(text: &str) -> Vec<String> {
    text.split_whitespace().map(String::from).collect()
}

/// A PLC with `valve` (LREAL), `alarm` (BOOL), `tank.count` (DINT), `start` (TOD), `label`
/// (WSTRING) and `p` (a reference to `tank.count`), one task, and an access level; answers
/// go into a queue `try_receive` takes from.
struct Plc {
    access: Access,
    valve: f64,
    forced: Option<f64>,
    /// The forced TOD's nanoseconds.
    start: Option<i64>,
    /// Its task is stopped (STOP, START).
    stopped: bool,
    /// Answers VERSION as protocol version 1 did (MALFORMED).
    version_1: bool,
    answers: VecDeque<Vec<u8>>,
    paused: Duration,
    requests: usize,
    image: Vec<u8>,
}

impl Plc {
    fn new(access: Access) -> Self {
        Plc {
            access,
            valve: 0.5,
            forced: None,
            start: None,
            stopped: false,
            version_1: false,
            answers: VecDeque::new(),
            paused: Duration::ZERO,
            requests: 0,
            image: Vec::new(),
        }
    }
}

const VARS: [(&str, VarType); 6] = [
    ("valve", VarType::LReal),
    ("alarm", VarType::Bool),
    ("tank.count", VarType::DInt),
    ("start", VarType::Tod),
    ("label", VarType::WString),
    ("p", VarType::Ref),
];

/// "Grüße" in UTF-16.
const LABEL: [u8; 10] = [b'G', 0, b'r', 0, 0xfc, 0, 0xdf, 0, b'e', 0];

impl Transport for Plc {
    fn send(&mut self, message: &[u8]) -> Result<(), String> {
        self.requests += 1;
        let mut buf = [0u8; MAX_MESSAGE];
        let (seq, request) = decode_request(message).map_err(|e| format!("{e:?}"))?;
        let op = request.op();
        if op.needs().code() > self.access.code() {
            let w = begin_response(op.code(), seq, Status::Forbidden, &mut buf);
            let n = w.len();
            self.answers.push_back(buf[..n].to_vec());
            return Ok(());
        }
        let mut w = begin_response(op.code(), seq, Status::Ok, &mut buf);
        let start = self.start.unwrap_or(6 * 3600 * 1_000_000_000);
        let value = |name: &str, valve: f64| match name {
            "valve" => Some(Value::LReal(valve)),
            "alarm" => Some(Value::Bool(false)),
            "tank.count" => Some(Value::Int(7)),
            "start" => Some(Value::Temporal(TimeKind::Tod, start)),
            "label" => Some(Value::WString(&LABEL)),
            "p" => Some(Value::Ref {
                address: Some(8),
                target: Some("tank.count"),
            }),
            _ => None,
        };
        if self.version_1 && request == Request::Version {
            let n = begin_response(op.code(), seq, Status::Malformed, &mut buf).len();
            self.answers.push_back(buf[..n].to_vec());
            return Ok(());
        }
        let mut status = Status::Ok;
        match request {
            Request::List { from } => {
                // Two a message, to page.
                let rest = &VARS[(from as usize).min(VARS.len())..];
                let page = &rest[..rest.len().min(2)];
                w.put(&(VARS.len() as u16).to_le_bytes()).unwrap();
                w.put(&[page.len() as u8]).unwrap();
                for (name, ty) in page {
                    w.put(&[ty.code(), name.len() as u8]).unwrap();
                    w.put(name.as_bytes()).unwrap();
                }
            }
            Request::Read { name } => match value(name, self.forced.unwrap_or(self.valve)) {
                Some(v) => {
                    let ty = VARS.iter().find(|(n, _)| *n == name).unwrap().1;
                    w.typed_value(ty, &v).unwrap()
                }
                None => status = Status::UnknownName,
            },
            Request::Force { name, value: v } => match (name, v) {
                ("valve", Value::LReal(x)) => self.forced = Some(x),
                ("start", Value::Temporal(TimeKind::Tod, ns)) => self.start = Some(ns),
                ("p", _) => status = Status::ReadOnly,
                ("label", _) => status = Status::Unsupported,
                ("valve" | "start", _) => status = Status::TypeMismatch,
                _ => status = Status::UnknownName,
            },
            Request::Write { name, value: v } => match (name, v) {
                ("valve", Value::LReal(x)) => self.valve = x,
                _ => status = Status::UnknownName,
            },
            Request::Version => w.put(&PROTOCOL_VERSION.to_le_bytes()).unwrap(),
            Request::Store => plc_online::put_store_status(
                &mut w,
                &plc_online::StoreStatus {
                    configured: true,
                    boot_loaded: 2,
                    retain_loaded: 0,
                    boot_saved: 3,
                    retain_saved: 19,
                },
            )
            .unwrap(),
            Request::Unforce { .. } => self.forced = None,
            Request::Stats { task: 0 } => put_stats(
                &mut w,
                &TaskStats {
                    name: "CYCLE.tank",
                    stopped: self.stopped,
                    figures: [10, 12_000, 9_000, 11_000, 86_000, 1_000, 99_000, 0, 0],
                },
            )
            .unwrap(),
            Request::Stats { .. } => status = Status::NoSuchTask,
            Request::Stop { task: 0 } => self.stopped = true,
            Request::Start { task: 0 } => self.stopped = false,
            Request::Stop { .. } | Request::Start { .. } => status = Status::NoSuchTask,
            Request::DownloadBegin { .. } => self.image.clear(),
            Request::DownloadChunk { bytes, .. } => self.image.extend_from_slice(bytes),
            Request::DownloadCommit => w.put(&42u64.to_le_bytes()).unwrap(),
        }
        let n = if status == Status::Ok {
            w.len()
        } else {
            begin_response(op.code(), seq, status, &mut buf).len()
        };
        self.answers.push_back(buf[..n].to_vec());
        Ok(())
    }

    fn try_receive(&mut self, buf: &mut [u8]) -> Result<Option<usize>, String> {
        Ok(self.answers.pop_front().map(|a| {
            buf[..a.len()].copy_from_slice(&a);
            a.len()
        }))
    }

    fn pause(&mut self, time: Duration) {
        self.paused += time;
    }
}

fn run(plc: Plc, command: &str) -> (Result<(), Failure>, Vec<String>, Plc) {
    let c = Command::parse(&args(command)).unwrap();
    let mut link = Link::new(plc, c.timeout);
    let mut lines = Vec::new();
    let r = link.run(&c.action, &mut |l| lines.push(l.to_string()));
    (r, lines, link.transport)
}

#[test]
fn the_command_line() {
    let c = Command::parse(&args("--request /dev/arinc/cmd read a b --timeout 500ms")).unwrap();
    assert_eq!(c.request, "/dev/arinc/cmd");
    assert_eq!(c.response, DEFAULT_RESPONSE);
    assert_eq!(c.timeout, Duration::from_millis(500));
    assert_eq!(c.action, Action::Read(vec!["a".into(), "b".into()]));
    let c = Command::parse(&args("watch level --interval 2s --count 3")).unwrap();
    assert_eq!(
        c.action,
        Action::Watch {
            names: vec!["level".into()],
            interval: Duration::from_secs(2),
            count: Some(3)
        }
    );
    for bad in [
        "",
        "read",
        "list x",
        "force valve",
        "force =1",
        "unforce a b",
        "frobnicate",
        "--bogus list",
        "read a --timeout",
        "watch a --interval 0",
    ] {
        assert!(Command::parse(&args(bad)).is_err(), "{bad}");
    }
}

#[test]
fn values_are_parsed_as_the_variable_is_typed() {
    let parsed = |text: &str, ty| {
        let mut buf = [0u8; MAX_TEXT];
        parse_value(text, ty, &mut buf).map(|v| v.to_string())
    };
    assert_eq!(parsed("true", VarType::Bool), Ok("TRUE".into()));
    assert_eq!(parsed("0", VarType::Bool), Ok("FALSE".into()));
    assert_eq!(parsed("-3", VarType::DInt), Ok("-3".into()));
    assert_eq!(parsed("16#FF", VarType::Byte), Ok("255".into()));
    assert_eq!(parsed("0.25", VarType::LReal), Ok("0.25".into()));
    assert_eq!(parsed("T#20ms", VarType::Time), Ok("T#20ms".into()));
    assert_eq!(parsed("2s", VarType::Time), Ok("T#2s".into()));
    assert_eq!(parsed("T#1s500ms", VarType::Time), Ok("T#1s500ms".into()));
    assert_eq!(parsed("LT#5us", VarType::LTime), Ok("LT#5us".into()));
    assert_eq!(
        parsed("D#2024-06-15", VarType::Date),
        Ok("D#2024-06-15".into())
    );
    assert_eq!(parsed("12:30", VarType::Tod), Ok("TOD#12:30:00".into()));
    assert_eq!(
        parsed("DT#2024-06-15-12:30:00", VarType::Dt),
        Ok("DT#2024-06-15-12:30:00".into())
    );
    assert_eq!(parsed("a", VarType::Char), Ok("'a'".into()));
    assert_eq!(parsed("\"€\"", VarType::WChar), Ok("\"€\"".into()));
    assert_eq!(parsed("'a b'", VarType::String), Ok("'a b'".into()));
    assert_eq!(parsed("Grüße", VarType::WString), Ok("\"Grüße\"".into()));
    assert_eq!(
        parsed("x", VarType::Int),
        Err(LiteralError::Syntax(VarType::Int))
    );
    assert_eq!(
        parsed("-1", VarType::UInt),
        Err(LiteralError::OutOfRange(VarType::UInt))
    );
    assert_eq!(
        parsed("TOD#25:00:00", VarType::Tod),
        Err(LiteralError::Syntax(VarType::Tod))
    );
    assert_eq!(parsed("NULL", VarType::Ref), Err(LiteralError::ReadOnly));
}

#[test]
fn the_new_types_are_read_forced_and_refused() {
    let (r, lines, _) = run(Plc::new(Access::Monitor), "list");
    assert_eq!(r, Ok(()));
    assert_eq!(&lines[3..], ["start TOD", "label WSTRING", "p REF_TO"]);
    let (r, lines, _) = run(Plc::new(Access::Monitor), "read start label p");
    assert_eq!(r, Ok(()));
    assert_eq!(
        lines,
        [
            "start = TOD#06:00:00",
            "label = \"Grüße\"",
            "p = REF(tank.count)"
        ]
    );
    let (r, lines, plc) = run(Plc::new(Access::Force), "force start=TOD#12:30:00.5");
    assert_eq!(r, Ok(()));
    assert_eq!(lines, ["forced start = TOD#12:30:00.5"]);
    assert_eq!(plc.start, Some(45_000_500_000_000));
    // A malformed literal: a usage error naming what was expected, nothing sent.
    let (r, _, plc) = run(Plc::new(Access::Force), "force start=25:00");
    let f = r.unwrap_err();
    assert_eq!(f.status, 2);
    assert_eq!(
        f.message,
        "FORCE start: `25:00` is not a TOD literal (expected a time of day such as TOD#12:30:00 or TOD#12:30:00.25 (hours 0 to 23))"
    );
    assert_eq!((plc.requests, plc.start), (1, None), "only the READ");
    // A reference: refused with the reason, without asking the PLC to change it.
    let (r, _, plc) = run(Plc::new(Access::Force), "force p=NULL");
    let f = r.unwrap_err();
    assert_eq!(f.status, 1);
    assert!(
        f.message
            .starts_with("FORCE p: READ_ONLY (a reference is read-only online"),
        "{}",
        f.message
    );
    assert_eq!(plc.requests, 1, "only the READ");
    // A WSTRING is read, not forced: the PLC says so.
    let (r, _, _) = run(Plc::new(Access::Force), "force label=x");
    assert_eq!(
        r.unwrap_err().message,
        "FORCE label: UNSUPPORTED (not supported for this variable)"
    );
}

#[test]
fn version_tells_both_protocols() {
    let (r, lines, _) = run(Plc::new(Access::Monitor), "version");
    assert_eq!(
        (r, lines),
        (Ok(()), vec!["protocol: plcctl 3, PLC 3".to_string()])
    );
    let mut old = Plc::new(Access::Monitor);
    old.version_1 = true;
    let (r, lines, _) = run(old, "version");
    assert_eq!(
        (r, lines),
        (Ok(()), vec!["protocol: plcctl 3, PLC 1".to_string()])
    );
    assert!(Command::parse(&args("version x")).is_err());
}

#[test]
fn list_read_watch_force_unforce_and_stats() {
    let (r, lines, _) = run(Plc::new(Access::Force), "list");
    assert_eq!(r, Ok(()));
    assert_eq!(
        &lines[..3],
        ["valve LREAL", "alarm BOOL", "tank.count DINT"]
    );
    let (r, lines, _) = run(Plc::new(Access::Monitor), "read valve alarm tank.count");
    assert_eq!(r, Ok(()));
    assert_eq!(lines, ["valve = 0.5", "alarm = FALSE", "tank.count = 7"]);
    let (r, lines, plc) = run(
        Plc::new(Access::Monitor),
        "watch valve --interval 100 --count 3",
    );
    assert_eq!(r, Ok(()));
    assert_eq!(
        lines,
        ["t=0 valve=0.5", "t=100 valve=0.5", "t=200 valve=0.5"]
    );
    assert_eq!(plc.paused, Duration::from_millis(200));
    let (r, lines, plc) = run(Plc::new(Access::Force), "force valve=0.25");
    assert_eq!(r, Ok(()));
    assert_eq!(lines, ["forced valve = 0.25"]);
    assert_eq!(plc.forced, Some(0.25));
    let (r, lines, _) = run(Plc::new(Access::Force), "unforce valve");
    assert_eq!((r, lines), (Ok(()), vec!["unforced valve".to_string()]));
    let (r, lines, _) = run(Plc::new(Access::Monitor), "store");
    assert_eq!(r, Ok(()));
    assert_eq!(
        lines,
        [
            "store: loaded boot project #2, RETAIN snapshot none",
            "store: saved boot project #3, RETAIN snapshot #19"
        ]
    );
    let (r, lines, plc) = run(Plc::new(Access::Force), "write valve=0.75");
    assert_eq!((r, lines), (Ok(()), vec!["wrote valve = 0.75".to_string()]));
    assert_eq!((plc.valve, plc.forced), (0.75, None));
    let (r, lines, _) = run(Plc::new(Access::Monitor), "stats");
    assert_eq!(r, Ok(()));
    assert_eq!(
        lines,
        [
            "task CYCLE.tank stopped=false cycles=10 last_us=12 min_us=9 mean_us=11 max_us=86 last_jitter_us=1 max_jitter_us=99 overruns=0 faults=0"
        ]
    );
}

#[test]
fn stop_and_start_name_tasks_or_take_them_all() {
    let (r, lines, plc) = run(Plc::new(Access::Force), "stop");
    assert_eq!(
        (r, lines),
        (Ok(()), vec!["stopped task CYCLE.tank".to_string()])
    );
    assert!(plc.stopped);
    let mut plc = Plc::new(Access::Force);
    plc.stopped = true;
    let (r, lines, plc) = run(plc, "start cycle.tank");
    assert_eq!(
        (r, lines),
        (Ok(()), vec!["started task CYCLE.tank".to_string()])
    );
    assert!(!plc.stopped);
    // An unknown name touches no task.
    let (r, lines, plc) = run(Plc::new(Access::Force), "stop CYCLE.tank fast");
    assert!(lines.is_empty() && !plc.stopped);
    assert_eq!(
        r.unwrap_err().message,
        "no task fast in the PLC (its tasks: CYCLE.tank)"
    );
    let (r, _, plc) = run(Plc::new(Access::Monitor), "stop");
    assert!(!plc.stopped);
    assert_eq!(
        r.unwrap_err().message,
        "STOP CYCLE.tank: FORBIDDEN (the client's access in the PLC's configuration does not allow it)"
    );
    assert_eq!(
        Command::parse(&args("start a b")).unwrap().action,
        Action::Run {
            tasks: vec!["a".into(), "b".into()],
            run: true
        }
    );
}

#[test]
fn refusals_say_why() {
    let (r, lines, _) = run(Plc::new(Access::Monitor), "force valve=0.25");
    assert!(lines.is_empty());
    let f = r.unwrap_err();
    assert_eq!(f.status, 1);
    assert_eq!(
        f.message,
        "FORCE valve: FORBIDDEN (the client's access in the PLC's configuration does not allow it)"
    );
    let (r, _, _) = run(Plc::new(Access::Monitor), "read nothing");
    assert_eq!(
        r.unwrap_err().message,
        "READ nothing: UNKNOWN_NAME (no variable of that name)"
    );
    let (r, _, _) = run(Plc::new(Access::Force), "force valve=open");
    assert_eq!(r.unwrap_err().status, 2);
    let c = Command::parse(&args("download x.plcb")).unwrap();
    let mut link = Link::new(Plc::new(Access::Force), c.timeout);
    let r = link.download("x.plcb", &[1; 600], &mut |_| {});
    assert_eq!(
        r.unwrap_err().message.split(':').next(),
        Some("DOWNLOAD_BEGIN")
    );
}

#[test]
fn a_download_goes_in_chunks_and_reports_the_release() {
    let mut link = Link::new(Plc::new(Access::Download), DEFAULT_TIMEOUT);
    let image: Vec<u8> = (0..600u32).map(|i| i as u8).collect();
    let mut lines = Vec::new();
    let r = link.download("new.plcb", &image, &mut |l| lines.push(l.to_string()));
    assert_eq!(r, Ok(()));
    assert_eq!(
        lines,
        ["downloaded new.plcb: 600 bytes, running from release 42"]
    );
    assert_eq!(link.transport.image, image);
    // BEGIN, three chunks, COMMIT.
    assert_eq!(link.transport.requests, 5);
}

/// A PLC that never answers; and stale answers are dropped.
#[test]
fn no_answer_times_out_and_stale_answers_are_dropped() {
    struct Silent(Duration);
    impl Transport for Silent {
        fn send(&mut self, _: &[u8]) -> Result<(), String> {
            Ok(())
        }
        fn try_receive(&mut self, _: &mut [u8]) -> Result<Option<usize>, String> {
            Ok(None)
        }
        fn pause(&mut self, time: Duration) {
            self.0 += time;
        }
    }
    let mut link = Link::new(Silent(Duration::ZERO), Duration::from_millis(100));
    let f = link.run(&Action::Stats, &mut |_| {}).unwrap_err();
    assert_eq!(f.status, 3);
    assert!(f.message.contains("no answer"), "{}", f.message);
    assert!(link.transport.0 >= Duration::from_millis(100));
    let mut plc = Plc::new(Access::Monitor);
    plc.answers.push_back(vec![2, 9, 0]);
    let (r, lines, _) = run(plc, "read valve");
    assert_eq!((r, lines), (Ok(()), vec!["valve = 0.5".to_string()]));
}

#[test]
fn the_tcp_options() {
    let c = Command::parse(&args(
        "--connect 127.0.0.1:1202 --key keys/engineering.key list",
    ))
    .unwrap();
    assert_eq!(
        c.connect,
        Some(Connect {
            address: "127.0.0.1:1202".into(),
            key_file: "keys/engineering.key".into(),
            name: "engineering".into(),
        })
    );
    assert_eq!(c.action, Action::List);
    let c = Command::parse(&args(
        "read x --name operator --connect plc.local:1202 --key /etc/k --timeout 500",
    ))
    .unwrap();
    let connect = c.connect.unwrap();
    assert_eq!(connect.name, "operator");
    assert_eq!(connect.address, "plc.local:1202");
    assert_eq!(connect.key_file, "/etc/k");
    assert_eq!(c.timeout, Duration::from_millis(500));
    assert_eq!(
        Command::parse(&args("--connect [::1]:1202 --key a.b.key version"))
            .unwrap()
            .connect
            .unwrap()
            .name,
        "a.b"
    );
    assert_eq!(Command::parse(&args("list")).unwrap().connect, None);
    assert_eq!(default_name("engineering"), "engineering");
    assert_eq!(default_name("keys/engineering.key"), "engineering");

    for (bad, why) in [
        (
            "--connect 127.0.0.1:1202 list",
            "--connect needs --key FILE",
        ),
        ("--key k.key list", "--key goes with --connect HOST:PORT"),
        ("--name n list", "--name goes with --connect HOST:PORT"),
        (
            "--key k.key --name n list",
            "--key goes with --connect HOST:PORT",
        ),
        (
            "--connect plc --key k.key list",
            "--connect plc: not HOST:PORT",
        ),
        (
            "--connect plc:http --key k.key list",
            "--connect plc:http: not HOST:PORT",
        ),
        ("list --connect", "--connect needs HOST:PORT"),
        ("list --connect x:1 --key", "--key needs a key file"),
    ] {
        assert_eq!(Command::parse(&args(bad)), Err(why.to_string()), "{bad}");
    }
    let long = format!("--connect x:1 --key k --name {} list", "n".repeat(33));
    assert!(
        Command::parse(&args(&long))
            .unwrap_err()
            .contains("is no client name")
    );
    assert!(Command::parse(&args("--connect x:1 --key k list extra")).is_err());
}
