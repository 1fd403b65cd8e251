//! The PLC on the network (`tests/scenarios/net_modbus.toml`, `net_plc_online.toml`, `net_plc_flood.toml`,
//! `net_pubsub.toml`, `net_pubsub_machines_{a,b}.toml`): the soft-PLC's own
//! interface on the NIC partition's switch and its Modbus/TCP server, reached from the host
//! through QEMU's `hostfwd`. The client is pymodbus (tests/scripts/modbus_client.py) in the
//! venv `target/pymodbus-venv` (`.ci/run` makes it); without it that part is skipped with
//! a message, and only our own raw frames below are sent. The online protocol on TCP
//! (`plc.online_tcp`, scenario `net_plc_online`) is driven by plcctl's own code ([`plcctl::execute`]) with the keys
//! in tests/configs/keys, and by raw sessions of [`plc_online::session`] to replay a record.

use scenarios::tank::{self, DISTURBANCE_MS, SETTLED_MS};
use scenarios::{boot_beside, boot_while, check, modbus_exchange, modbus_level};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use xtask::pubsubbench::loop_round_trips;
use xtask::qemu::{Ending, Outcome};

/// The venv's python with pymodbus, if there is one.
fn pymodbus_python() -> Option<PathBuf> {
    let python = xtask::target_dir()
        .join("pymodbus-venv")
        .join("bin")
        .join("python");
    python.is_file().then_some(python)
}

#[derive(Debug, Default)]
struct Client {
    level: Option<f64>,
    /// pymodbus's output and whether it passed; `None` when skipped.
    pymodbus: Option<(String, bool)>,
    /// plcctl's STOP over the online port, pymodbus's checks while stopped (as above),
    /// plcctl's START; `None` when pymodbus was skipped.
    stopped: Option<(Said, (String, bool), Said)>,
    /// The connection after a malformed frame was closed without an answer.
    malformed_closed: bool,
}

/// What the host saw of the online protocol on TCP (scenario net_plc_online).
#[derive(Debug, Default)]
struct Online {
    /// What each plcctl command over TCP printed, or its failure.
    commands: Vec<(String, Said)>,
    /// The same for the download: list, read, refused and done download, read.
    download: Vec<(String, Said)>,
    /// A replayed record: (the first got its answer, the replay closed the connection).
    replay: Option<(bool, bool)>,
}

/// A plcctl command's lines, or its failure (exit status, message).
type Said = Result<Vec<String>, (i32, String)>;

/// `plcctl --connect 127.0.0.1:PORT --key tests/configs/keys/KEY.key --name NAME ARGS...`.
fn plcctl(port: u16, key: &str, name: &str, args: &str) -> Said {
    let key = xtask::workspace_root().join(format!("tests/configs/keys/{key}.key"));
    let mut words: Vec<String> = vec![
        "--connect".into(),
        format!("127.0.0.1:{port}"),
        "--key".into(),
        key.display().to_string(),
        "--name".into(),
        name.into(),
        "--timeout".into(),
        "10000".into(),
    ];
    words.extend(args.split(' ').map(String::from));
    let command = plcctl::Command::parse(&words).map_err(|e| (2, e))?;
    let mut lines = Vec::new();
    plcctl::execute(&command, &mut |line| lines.push(line.to_string()))
        .map(|()| lines)
        .map_err(|f| (f.status, f.message))
}

/// A connection to the online port authenticated as `name` with tests/configs/keys/KEY.key:
/// the stream and the session, or no session when the PLC refused.
fn authenticate(
    port: u16,
    key: &str,
    name: &str,
) -> std::io::Result<(TcpStream, Option<plc_online::session::Session>)> {
    use plc_online::session;
    let text = std::fs::read_to_string(
        xtask::workspace_root().join(format!("tests/configs/keys/{key}.key")),
    )?;
    let mut key = [0u8; session::MAX_KEY];
    let len = session::parse_key_file(&text, &mut key).map_err(std::io::Error::other)?;
    let key = &key[..len];
    let mut s = TcpStream::connect_timeout(&([127, 0, 0, 1], port).into(), Duration::from_secs(5))?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    let mut challenge = [0u8; session::CHALLENGE_LEN];
    s.read_exact(&mut challenge)?;
    let server_nonce = session::read_challenge(&challenge).map_err(std::io::Error::other)?;
    let client_nonce = [0x42; session::NONCE_LEN];
    let mut response = [0u8; session::MAX_RESPONSE_LEN];
    let n = session::response(
        name.as_bytes(),
        key,
        &server_nonce,
        &client_nonce,
        &mut response,
    )
    .map_err(std::io::Error::other)?;
    s.write_all(&response[..n])?;
    let mut answer = [0u8; session::ACCEPT_LEN];
    s.read_exact(&mut answer[..1])?;
    if answer[..1] == session::REFUSE {
        return Ok((s, None));
    }
    s.read_exact(&mut answer[1..])?;
    let (_, session) = session::read_accept(key, &server_nonce, &client_nonce, &answer)
        .map_err(std::io::Error::other)?;
    Ok((s, Some(session)))
}

/// A raw session as `engineering`: one VERSION request answered, then the same record
/// again. Returns (answered, then closed without an answer).
fn replay(port: u16) -> std::io::Result<(bool, bool)> {
    use plc_online::session::{MAX_RECORD, Session};
    let (mut s, session) = authenticate(port, "engineering", "engineering")?;
    let mut session = session.ok_or_else(|| std::io::Error::other("refused"))?;
    let mut request = [0u8; plc_online::MAX_MESSAGE];
    let n = plc_online::encode_request(&plc_online::Request::Version, 1, &mut request)
        .ok_or_else(|| std::io::Error::other("VERSION does not encode"))?;
    let mut record = [0u8; MAX_RECORD];
    let len = session.seal(&request[..n], &mut record).unwrap_or(0);
    let mut answer = [0u8; MAX_RECORD];
    let mut read_record = |s: &mut TcpStream| -> std::io::Result<usize> {
        s.read_exact(&mut answer[..2])?;
        let total = Session::record_len(&answer[..2])
            .ok()
            .flatten()
            .ok_or_else(|| std::io::Error::other("bad record length"))?;
        s.read_exact(&mut answer[2..total])?;
        Ok(total)
    };
    s.write_all(&record[..len])?;
    let answered = read_record(&mut s).is_ok_and(|total| total > 0);
    s.write_all(&record[..len])?;
    let mut rest = [0u8; 64];
    let closed = matches!(s.read(&mut rest), Ok(0) | Err(_)) && rest == [0u8; 64];
    Ok((answered, closed))
}

/// The changed controller `online` downloads: a new variable, and the alarm limit lower.
fn changed_program() -> anyhow::Result<std::path::PathBuf> {
    let root = xtask::workspace_root();
    let source = std::fs::read_to_string(root.join("tests/configs/plc/tank_modbus.st"))?
        .replace(
            "  setpoint : LREAL;\n",
            "  setpoint : LREAL;\n  generation : INT := 2;\n",
        )
        .replace("level > 1.3;", "level > 1.25;");
    let dir = xtask::target_dir().join("net_plc_online");
    std::fs::create_dir_all(&dir)?;
    let st = dir.join("tank_changed.st");
    std::fs::write(&st, source)?;
    let file = config::system::SourceFile {
        name: "tank_changed.st".into(),
        path: st.display().to_string(),
    };
    let plcb = dir.join("tank_changed.plcb");
    std::fs::write(&plcb, xtask::plc::image_of("net_plc_online", &file)?)?;
    Ok(plcb)
}

/// The online protocol on TCP through `port` once the PLC answers: each key's rights, a
/// download with RETAIN kept, a wrong key, a replay.
fn online(port: u16, ended: &AtomicBool) -> Online {
    let mut c = Online::default();
    while !ended.load(Ordering::SeqCst)
        && plcctl(port, "engineering", "engineering", "version").is_err()
    {
        std::thread::sleep(Duration::from_millis(500));
    }
    let plcb = match changed_program() {
        Ok(path) => path.display().to_string(),
        Err(e) => format!("(not built: {e})"),
    };
    for (key, name, args) in [
        ("engineering", "engineering", "list".to_string()),
        ("engineering", "engineering", "read tank.cycles".into()),
        ("hmi", "hmi", format!("download {plcb}")),
        ("engineering", "engineering", format!("download {plcb}")),
        (
            "engineering",
            "engineering",
            "read tank.cycles tank.generation".into(),
        ),
    ] {
        let what = format!("{name} ({key}.key): {args}");
        c.download.push((what, plcctl(port, key, name, &args)));
    }
    for (key, name, args) in [
        ("engineering", "engineering", "version"),
        ("engineering", "engineering", "read level setpoint_mm"),
        ("engineering", "engineering", "force alarm=TRUE"),
        ("engineering", "engineering", "read alarm"),
        ("engineering", "engineering", "unforce alarm"),
        ("hmi", "hmi", "read level"),
        ("hmi", "hmi", "force alarm=TRUE"),
        ("wrong", "engineering", "read level"),
        ("hmi", "nobody", "read level"),
    ] {
        let what = format!("{name} ({key}.key): {args}");
        c.commands.push((what, plcctl(port, key, name, args)));
    }
    c.replay = replay(port).ok();
    c
}

fn client(ports: &[u16], ended: &AtomicBool) -> Client {
    let port = ports[0];
    let mut c = Client::default();
    while !ended.load(Ordering::SeqCst) && c.level.is_none() {
        c.level = modbus_level(port);
        if c.level.is_none() {
            std::thread::sleep(Duration::from_millis(500));
        }
    }
    if c.level.is_none() {
        return c;
    }
    match pymodbus_python() {
        Some(python) => {
            let script = xtask::workspace_root().join("tests/scripts/modbus_client.py");
            let pymodbus = |mode: &[&str]| match std::process::Command::new(&python)
                .arg(&script)
                .arg(port.to_string())
                .args(mode)
                .output()
            {
                Ok(out) => {
                    let text = String::from_utf8_lossy(&out.stdout).to_string()
                        + &String::from_utf8_lossy(&out.stderr);
                    (text, out.status.success())
                }
                Err(e) => (format!("cannot run pymodbus: {e}"), false),
            };
            c.pymodbus = Some(pymodbus(&[]));
            // Every task stopped over the online service (engineering key): a write gets
            // exception 4; then the PLC runs again.
            let stop = plcctl(ports[1], "engineering", "engineering", "stop");
            let stopped = pymodbus(&["stopped"]);
            let start = plcctl(ports[1], "engineering", "engineering", "start");
            c.stopped = Some((stop, stopped, start));
        }
        None => println!(
            "net_modbus: pymodbus skipped: no venv at {} (.ci/run makes it: python3 -m venv target/pymodbus-venv && target/pymodbus-venv/bin/pip install 'pymodbus>=3,<4')",
            xtask::target_dir().join("pymodbus-venv").display()
        ),
    }
    // A protocol id other than 0: not Modbus/TCP, the connection closes (and the PLC's
    // counter of such connections, which ends the run, goes to 1).
    c.malformed_closed = modbus_exchange(port, &[0, 2, 0, 1, 0, 6, 1, 3, 0, 0, 0, 1])
        .map(|r| r.is_empty())
        .unwrap_or(true);
    c
}

#[test]
fn net_modbus() {
    let (o, c) = boot_beside("net_modbus", client);
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.line("plc: net 10.0.2.15/24 mac 52:54:00:12:34:56 connections=4")
            .is_some()
            && o.line("plc: modbus on port 502 unit 1 writable=markers")
                .is_some(),
        "the PLC did not report its interface and Modbus server",
    );
    check(
        &o,
        c.level.is_some_and(|l| (0.0..2.0).contains(&l)),
        &format!("the level read over Modbus/TCP: {:?}", c.level),
    );
    if let Some((text, passed)) = &c.pymodbus {
        println!("net_modbus: pymodbus said:\n{text}");
        check(&o, *passed, "pymodbus's checks failed (its lines above)");
    }
    if let Some((stop, (text, passed), start)) = &c.stopped {
        println!(
            "net_modbus: plcctl stop: {stop:?}; pymodbus said:\n{text}plcctl start: {start:?}"
        );
        check(
            &o,
            stop.as_ref()
                .is_ok_and(|l| !l.is_empty() && l.iter().all(|l| l.starts_with("stopped task "))),
            &format!("plcctl stop over the online port: {stop:?}"),
        );
        check(
            &o,
            *passed,
            &format!("pymodbus's checks with the PLC stopped failed:\n{text}"),
        );
        check(
            &o,
            start
                .as_ref()
                .is_ok_and(|l| !l.is_empty() && l.iter().all(|l| l.starts_with("started task "))),
            &format!("plcctl start over the online port: {start:?}"),
        );
        check(
            &o,
            o.line(" stopped online; outputs safe").is_some()
                && o.line(" started online").is_some(),
            "the PLC did not log the task's stop and start",
        );
    }
    check(
        &o,
        c.malformed_closed,
        "a malformed frame was answered, not closed",
    );
    check(
        &o,
        o.line(" malformed=1 ").is_some(),
        "the PLC did not count the malformed connection",
    );
}

#[test]
fn net_plc_online() {
    let (o, c) = boot_beside("net_plc_online", |ports, ended| online(ports[0], ended));
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    for (what, result) in &c.commands {
        println!("net_plc_online: plcctl {what} -> {result:?}");
    }
    let said = |i: usize| c.commands.get(i).map(|(_, r)| r.clone());
    let ok_line = |i: usize, start: &str| {
        said(i).is_some_and(|r| r.is_ok_and(|lines| lines.iter().any(|l| l.starts_with(start))))
    };
    let failed = |i: usize, status: i32, text: &str| {
        said(i).is_some_and(|r| r.is_err_and(|(s, m)| s == status && m.contains(text)))
    };
    check(
        &o,
        ok_line(0, "protocol: plcctl ")
            && ok_line(1, "level = ")
            && ok_line(1, "setpoint_mm = ")
            && ok_line(2, "forced alarm = TRUE")
            && ok_line(3, "alarm = TRUE")
            && ok_line(4, "unforced alarm")
            && ok_line(5, "level = "),
        "plcctl over TCP with the engineering and hmi keys (its lines above)",
    );
    check(
        &o,
        failed(6, 1, "FORBIDDEN"),
        "FORCE with the monitor key was not refused FORBIDDEN",
    );
    check(
        &o,
        failed(7, 1, "authentication refused") && failed(8, 1, "authentication refused"),
        "a wrong key or an unknown name was not refused",
    );
    for (what, result) in &c.download {
        println!("net_plc_online: plcctl {what} -> {result:?}");
    }
    let said = |i: usize| c.download.get(i).map(|(_, r)| r.clone());
    let cycles = |i: usize| {
        said(i)
            .and_then(|r| r.ok())
            .and_then(|lines| lines.first().cloned())
            .and_then(|l| l.strip_prefix("tank.cycles = ")?.parse::<u64>().ok())
    };
    check(
        &o,
        said(0).is_some_and(|r| {
            r.is_ok_and(|l| l.iter().any(|l| l == "tank.cycles UDINT") && l.len() > 5)
        }),
        "LIST over TCP did not show tank.cycles",
    );
    check(
        &o,
        said(2).is_some_and(|r| r.is_err_and(|(s, m)| s == 1 && m.contains("FORBIDDEN"))),
        "a download with the monitor key was not refused FORBIDDEN",
    );
    check(
        &o,
        said(3).is_some_and(|r| r.is_ok_and(|l| l.iter().any(|l| l.starts_with("downloaded ")))),
        "the download with the engineering key failed",
    );
    check(
        &o,
        cycles(1).is_some_and(|before| cycles(4).is_some_and(|after| after >= before))
            && said(4)
                .is_some_and(|r| r.is_ok_and(|l| l.iter().any(|l| l == "tank.generation = 2")))
            && o.line("plc: download: ").is_some(),
        "the downloaded program does not run with RETAIN cycles kept",
    );
    check(
        &o,
        c.replay == Some((true, true)),
        &format!("a replayed record: {:?} (answered, then closed)", c.replay),
    );
    check(
        &o,
        o.line("plc: online on port 1202 clients=engineering:download,hmi:monitor")
            .is_some()
            && o.line("plc: online: engineering authenticated from 10.0.2.2:")
                .is_some()
            && o.line("plc: online: hmi authenticated from 10.0.2.2:")
                .is_some()
            && o.line("plc: online: refused 10.0.2.2:").is_some()
            && o.line("ended: record sequence 1, expected 2 (replayed or reordered)")
                .is_some(),
        "the PLC's log lines of the online sessions",
    );
}

/// The flood's bounds (scenario `net_plc_flood`): how long (real time) and how many of each.
const FLOOD: Duration = Duration::from_secs(20);
const HELD: usize = 100;
const CHURN: u64 = 2_000;
const MALFORMED: u64 = 2_000;
const READS: u64 = 100_000;
/// The online port's part after the Modbus flood: how long and how many attempts at most.
const ONLINE_FLOOD: Duration = Duration::from_secs(10);
const ONLINE_ATTEMPTS: u64 = 1_000;
/// How much later than in the quiet seconds a release may be in the flood's.
const FLOOD_BOUND_NS: u64 = 50_000;
/// Frames a second from the wire above which a second is part of the flood, at most which
/// it is quiet. Any traffic counts: how many frames a second of virtual time gets depends
/// on how fast virtual time runs against the host's clock (6 times faster on a loaded
/// 2-core host, when the flood's seconds carried 40 to 90 frames each).
const QUIET: u64 = 10;

#[derive(Debug, Default)]
struct Flood {
    reached: bool,
    held: usize,
    churned: u64,
    malformed: u64,
    reads: u64,
    answered: u64,
    after: Option<f64>,
    /// Online handshakes with a wrong key, how many the PLC refused, replayed records.
    wrong_keys: u64,
    refused: u64,
    replays: u64,
    /// An authenticated read after it all.
    online_after: Option<Vec<String>>,
}

/// The malformed frame number `i`: a protocol id other than 0, an MBAP length of 0 or
/// beyond 254, a request cut short, or bytes that are no frame at all.
fn malformed(i: u64) -> Vec<u8> {
    match i % 4 {
        0 => vec![0, 1, 0, 7, 0, 6, 1, 3, 0, 0, 0, 1],
        1 => vec![0, 1, 0, 0, 0, 0, 1],
        2 => vec![0, 1, 0, 0, 0x01, 0x2c, 1, 3, 0, 0],
        _ => (0..40).map(|b| (b * 37 + i) as u8).collect(),
    }
}

/// Waits until the PLC answers, lets the system run quietly for 5 s, then floods for
/// [`FLOOD`]; then reads the level once more and lets the system run quietly for 5 s (the
/// run ends then).
fn flood(ports: &[u16], ended: &AtomicBool) -> Flood {
    let (port, online_port) = (ports[0], ports[1]);
    let mut f = Flood::default();
    while !ended.load(Ordering::SeqCst) && !f.reached {
        f.reached = modbus_level(port).is_some();
        if !f.reached {
            std::thread::sleep(Duration::from_millis(500));
        }
    }
    if !f.reached {
        return f;
    }
    std::thread::sleep(Duration::from_secs(5));
    let until = Instant::now() + FLOOD;
    let going = || Instant::now() < until && !ended.load(Ordering::SeqCst);
    let connect =
        || TcpStream::connect_timeout(&([127, 0, 0, 1], port).into(), Duration::from_secs(1)).ok();
    std::thread::scope(|scope| {
        let churn = scope.spawn(|| {
            let mut held = Vec::new();
            while held.len() < HELD && going() {
                if let Some(s) = connect() {
                    held.push(s);
                }
            }
            let mut churned = 0;
            while churned < CHURN && going() {
                churned += 1;
                drop(connect());
            }
            (held.len(), churned)
        });
        let bad = scope.spawn(|| {
            let mut sent = 0;
            while sent < MALFORMED && going() {
                if let Some(mut s) = connect() {
                    let _ = s.write_all(&malformed(sent));
                }
                sent += 1;
            }
            sent
        });
        let (mut reads, mut answered) = (0, 0);
        let mut stream = None;
        while reads < READS && going() {
            if stream.is_none() {
                stream = connect();
            }
            let Some(s) = stream.as_mut() else {
                continue;
            };
            let _ = s.set_read_timeout(Some(Duration::from_secs(2)));
            reads += 1;
            let t = (reads as u16).to_be_bytes();
            let mut answer = [0u8; 17];
            let ok = s
                .write_all(&[t[0], t[1], 0, 0, 0, 6, 1, 4, 0, 0, 0, 4])
                .and_then(|()| s.read_exact(&mut answer))
                .is_ok();
            if ok && answer[..2] == t {
                answered += 1;
            } else {
                stream = None;
            }
        }
        f.reads = reads;
        f.answered = answered;
        f.malformed = bad.join().unwrap_or(0);
        (f.held, f.churned) = churn.join().unwrap_or((0, 0));
    });
    // Then the online port: wrong keys and replayed records (bounded in count and time).
    let until = Instant::now() + ONLINE_FLOOD;
    while f.wrong_keys + f.replays < ONLINE_ATTEMPTS
        && Instant::now() < until
        && !ended.load(Ordering::SeqCst)
    {
        // The first of every ten: a slow host that gets through few attempts in the time
        // still checks a replay.
        if f.wrong_keys % 10 == 0 {
            f.replays += 1;
            let _ = replay(online_port);
        }
        f.wrong_keys += 1;
        if let Ok((_, None)) = authenticate(online_port, "wrong", "engineering") {
            f.refused += 1;
        }
    }
    f.online_after = plcctl(online_port, "engineering", "engineering", "read level").ok();
    for _ in 0..20 {
        f.after = modbus_level(port);
        if f.after.is_some() || ended.load(Ordering::SeqCst) {
            break;
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    // Quiet seconds after it all, and the PLC's counters line of the last of them.
    if !ended.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_secs(5));
    }
    f
}

#[test]
fn net_plc_flood() {
    let (o, f) = boot_while("net_plc_flood", flood);
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        matches!(o.ending, Ending::Stopped),
        "expected the system to run until the host's flood and the quiet after it were over",
    );
    check(
        &o,
        f.reached,
        "the PLC's Modbus server never answered the host",
    );
    // Any traffic from the wire makes a second part of the flood.
    let split = scenarios::plc_lateness_by_load(&o, QUIET + 1, QUIET);
    let (quiet, flooded, peak) = (split.quiet, split.loud, split.peak);
    let (quiet_max, flood_max) = (
        quiet.iter().copied().max().unwrap_or(0),
        flooded.iter().copied().max().unwrap_or(0),
    );
    println!(
        "net_plc_flood: the host held {} connections, opened and dropped {}, sent {} malformed frames, {} reads ({} answered) in {FLOOD:?}; the NIC took up to {peak} frames a second from the wire; PLC release lateness (virtual time): max {quiet_max} ns over {} quiet seconds, max {flood_max} ns over {} flooded seconds; level afterwards {:?}",
        f.held,
        f.churned,
        f.malformed,
        f.reads,
        f.answered,
        quiet.len(),
        flooded.len(),
        f.after
    );
    let last_net = o
        .lines
        .iter()
        .rev()
        .find(|l| l.contains(" net open="))
        .cloned()
        .unwrap_or_default();
    println!("net_plc_flood: the PLC's last counters: {last_net}");
    println!(
        "net_plc_flood: online port: {} handshakes with a wrong key ({} refused), {} replayed records; an authenticated read afterwards: {:?}",
        f.wrong_keys, f.refused, f.replays, f.online_after
    );
    let counter = |name: &str| {
        last_net
            .split(' ')
            .find_map(|w| w.strip_prefix(name)?.parse::<u64>().ok())
            .unwrap_or(0)
    };
    check(
        &o,
        f.refused > 0
            && counter("denied=") >= f.refused
            && counter("rejected=") > 0
            && f.online_after
                .as_ref()
                .is_some_and(|l| l.iter().any(|l| l.starts_with("level = "))),
        "the online port's wrong keys and replays were not all refused, or it stopped serving",
    );
    check(
        &o,
        flooded.len() >= 3 && quiet.len() >= 3,
        &format!(
            "{} flooded and {} quiet seconds of PLC period lines",
            flooded.len(),
            quiet.len()
        ),
    );
    check(
        &o,
        flood_max <= quiet_max + FLOOD_BOUND_NS,
        "a release in the flood later than 50 us beyond the quiet seconds' latest",
    );
    check(
        &o,
        f.answered > 0 && f.after.is_some(),
        "the server stopped answering valid reads",
    );
    scenarios::plc_kept_every_cycle(&o);
    tank::settles_and_holds(&o);
}

/// When the controller PLC of net_pubsub stops publishing (its task traps after 3,000
/// cycles of 10 ms).
const CONTROLLER_STOPS_MS: u64 = 30_000;

#[test]
fn net_pubsub() {
    let o = scenarios::boot("net_pubsub");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.line("[field] plc: publish to 239.0.0.1:61499 vars=level,level_ok,stamp")
            .is_some()
            && o.line("[field] plc: subscribe on port 61499 vars=valve,echo valid=valve_ok timeout_ms=100")
                .is_some()
            && o.line("[ctl] plc: publish to 10.0.0.1:61499 vars=valve,echo").is_some()
            && o.line("[ctl] plc: subscribe on port 61499 group=239.0.0.1 vars=level,level_ok,stamp valid=link_ok timeout_ms=100")
                .is_some(),
        "the PLCs did not report their publications and subscriptions",
    );
    check(
        &o,
        o.line("[field] plc: subscription valid").is_some()
            && o.line("[ctl] plc: subscription valid").is_some(),
        "a subscription never became valid",
    );
    // The loop closed over the network: settled, and held through the disturbance.
    let status = tank::status(&o);
    tank::settles(&o, &status);
    tank::holds(
        &o,
        &status,
        |t| {
            (SETTLED_MS..DISTURBANCE_MS.0).contains(&t)
                || (DISTURBANCE_MS.1 + 1_000..CONTROLLER_STOPS_MS).contains(&t)
        },
        0,
    );
    // Then the controller stops; the field PLC's subscription lapses and the valve closes.
    check(
        &o,
        o.lines
            .iter()
            .any(|l| l.contains("[ctl] plc: task ") && l.contains(" stopped: ")),
        "the controller's task did not stop",
    );
    let lapsed = o.line("[field] plc: subscription lapsed");
    check(
        &o,
        lapsed.is_some(),
        "the field PLC's subscription did not lapse",
    );
    let closed = status
        .iter()
        .filter(|s| s.t_ms >= CONTROLLER_STOPS_MS + 1_000)
        .collect::<Vec<_>>();
    check(
        &o,
        !closed.is_empty() && closed.iter().all(|s| s.valve == 0.0),
        &format!(
            "the valve did not close after the controller stopped: {:?}",
            closed.first()
        ),
    );
    let counts = o
        .lines
        .iter()
        .rev()
        .find(|l| l.contains("[field] plc: t=") && l.contains(" subscription good="))
        .cloned()
        .unwrap_or_default();
    println!("net_pubsub: {counts}");
    // The loop's round trip (field → controller → field), from the field PLC's watch lines
    // while both run.
    let loops = loop_round_trips(&o.lines, SETTLED_MS, CONTROLLER_STOPS_MS);
    println!(
        "net_pubsub: loop round trip (virtual time, field → controller → field, in the field PLC's 10 ms cycles): {loops:?} ms"
    );
    check(
        &o,
        !loops.is_empty() && loops.iter().all(|&ms| (10..=50).contains(&ms)),
        "the loop's round trip is not 10..=50 ms",
    );
    println!("net_pubsub: {}", lapsed.unwrap_or_default());
}

#[test]
fn net_pubsub_machines() {
    let (a, b) = scenarios::boot_pair("net_pubsub_machines_a", "net_pubsub_machines_b");
    for o in [&a, &b] {
        check(o, o.line("panic at ").is_none(), "a partition panicked");
    }
    check(
        &a,
        a.line("[field] plc: subscription valid").is_some(),
        "machine A's subscription never became valid",
    );
    check(
        &b,
        b.line("[ctl] plc: subscription valid").is_some(),
        "machine B's subscription never became valid",
    );
    // The loop closed across the machines: the level reaches the band. (Not by a fixed
    // time: on real time under load one machine may boot seconds after the other.)
    let status = tank::status(&a);
    let lapsed_at = a
        .lines
        .iter()
        .position(|l| l.contains("[field] plc: subscription lapsed"));
    check(
        &a,
        tank::reaches_band(&status),
        "the level never reached the band under the remote controller",
    );
    let loops = loop_round_trips(&a.lines, SETTLED_MS, CONTROLLER_STOPS_MS);
    println!(
        "net_pubsub_machines: loop round trip (real time, machine A → B → A, in the field PLC's 10 ms cycles): {loops:?} ms"
    );
    check(
        &a,
        !loops.is_empty(),
        "no loop round trip in machine A's watch lines",
    );
    // Machine B's controller stops; machine A's subscription lapses and the valve closes.
    check(
        &b,
        b.lines
            .iter()
            .any(|l| l.contains("[ctl] plc: task ") && l.contains(" stopped: ")),
        "the controller's task did not stop",
    );
    check(
        &a,
        a.line("[field] plc: subscription lapsed").is_some(),
        "machine A's subscription did not lapse",
    );
    let last = status.last();
    check(
        &a,
        last.is_some_and(|s| s.valve == 0.0)
            && lapsed_at.is_some_and(|at| at < a.lines.len().saturating_sub(1)),
        &format!("the valve did not close: {last:?}"),
    );
    println!("net_pubsub_machines: A {:?}, B {:?}", a.ending, b.ending);
    for l in b
        .lines
        .iter()
        .rev()
        .filter(|l| l.contains("[ctl] plc: t="))
        .take(2)
    {
        println!("net_pubsub_machines: B: {l}");
    }
    for line in netbench_counters(&a)
        .iter()
        .chain(netbench_counters(&b).iter())
    {
        println!("net_pubsub_machines: {line}");
    }
}

/// A machine's NIC partition's last counters.
fn netbench_counters(o: &Outcome) -> Vec<String> {
    xtask::netbench::last_nic_counters(&o.lines)
        .into_iter()
        .map(String::from)
        .collect()
}
