//! 4diac's management protocol on TCP (scenario `iec61499_tcp`): the IEC 61499 partition's
//! own interface on the NIC partition's switch (`iec61499.net`), reached from the host
//! through QEMU's `hostfwd` as 4diac IDE reaches FORTE on port 61499. The client here is
//! written from FORTE's framing (a request is two ASN.1 STRINGs, tag 0x50 and a big-endian
//! u16 length, the destination and the request's XML; a response is one STRING), not from
//! the partition's code.

use scenarios::{boot_beside, check};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use xtask::qemu::Ending;

/// How long the host waits for the partition to answer its first request.
const BOOT: Duration = Duration::from_secs(240);

fn string(out: &mut Vec<u8>, text: &str) {
    out.push(0x50);
    out.extend_from_slice(&(text.len() as u16).to_be_bytes());
    out.extend_from_slice(text.as_bytes());
}

fn request(destination: &str, xml: &str) -> Vec<u8> {
    let mut out = Vec::new();
    string(&mut out, destination);
    string(&mut out, xml);
    out
}

/// One response: a STRING.
fn response(s: &mut TcpStream) -> std::io::Result<String> {
    let mut header = [0u8; 3];
    s.read_exact(&mut header)?;
    if header[0] != 0x50 {
        return Err(std::io::Error::other(format!(
            "a response starts with {:#04x}, not a STRING's tag",
            header[0]
        )));
    }
    let mut text = vec![0u8; usize::from(u16::from_be_bytes([header[1], header[2]]))];
    s.read_exact(&mut text)?;
    String::from_utf8(text).map_err(std::io::Error::other)
}

fn ask(s: &mut TcpStream, destination: &str, xml: &str) -> std::io::Result<String> {
    s.write_all(&request(destination, xml))?;
    response(s)
}

/// A connection the partition answered (a QUERY of the device), once it is up.
fn connect(port: u16, ended: &AtomicBool) -> std::io::Result<TcpStream> {
    let started = Instant::now();
    loop {
        let attempt = (|| {
            let mut s =
                TcpStream::connect_timeout(&([127, 0, 0, 1], port).into(), Duration::from_secs(5))?;
            s.set_read_timeout(Some(Duration::from_secs(20)))?;
            s.set_nodelay(true)?;
            ask(
                &mut s,
                "",
                "<Request ID=\"0\" Action=\"QUERY\"><FB Name=\"*\" Type=\"*\"/></Request>",
            )?;
            Ok::<_, std::io::Error>(s)
        })();
        match attempt {
            Ok(s) => return Ok(s),
            Err(e) if ended.load(Ordering::SeqCst) || started.elapsed() > BOOT => return Err(e),
            Err(_) => std::thread::sleep(Duration::from_millis(500)),
        }
    }
}

/// What the host saw.
#[derive(Debug, Default)]
struct Client {
    /// The deployment's requests and their responses, in order.
    deploy: Vec<(String, String)>,
    /// The watched counter's value, read twice 2 s apart.
    counts: Vec<Option<u64>>,
    query: String,
    /// A malformed request's response, and a READ's afterwards.
    malformed: String,
    after: String,
    /// A stream that is not requests: the response, then whether the connection closed.
    not_requests: Option<(String, bool)>,
    /// The first failure, if any.
    error: Option<String>,
}

const DEPLOY: [(&str, &str); 8] = [
    (
        "",
        "<Request ID=\"1\" Action=\"CREATE\"><FB Name=\"APP\" Type=\"EMB_RES\"/></Request>",
    ),
    (
        "APP",
        "<Request ID=\"2\" Action=\"CREATE\"><FB Name=\"CYCLE\" Type=\"E_CYCLE\"/></Request>",
    ),
    (
        "APP",
        "<Request ID=\"3\" Action=\"WRITE\"><Connection Source=\"T#100ms\" Destination=\"CYCLE.DT\"/></Request>",
    ),
    (
        "APP",
        "<Request ID=\"4\" Action=\"CREATE\"><FB Name=\"C\" Type=\"E_CTU\"/></Request>",
    ),
    (
        "APP",
        "<Request ID=\"5\" Action=\"CREATE\"><Connection Source=\"START.COLD\" Destination=\"CYCLE.START\"/></Request>",
    ),
    (
        "APP",
        "<Request ID=\"6\" Action=\"CREATE\"><Connection Source=\"CYCLE.EO\" Destination=\"C.CU\"/></Request>",
    ),
    ("APP", "<Request ID=\"7\" Action=\"START\"/>"),
    (
        "APP",
        "<Request ID=\"8\" Action=\"CREATE\"><Watch Source=\"C.CV\" Destination=\"*\"/></Request>",
    ),
];

const READ_WATCHES: &str =
    "<Request ID=\"9\" Action=\"READ\"><Watch Source=\"*\" Destination=\"*\"/></Request>";

/// The CV in a READ of the watches.
fn count(answer: &str) -> Option<u64> {
    answer
        .split("<Port name=\"CV\"><Data value=\"")
        .nth(1)?
        .split('"')
        .next()?
        .parse()
        .ok()
}

fn client(port: u16, ended: &AtomicBool) -> Client {
    let mut c = Client::default();
    // Kept open (and silent) until the run ends: the partition closes it.
    let stalled = match session(port, ended, &mut c) {
        Ok(stalled) => Some(stalled),
        Err(e) => {
            c.error = Some(e.to_string());
            None
        }
    };
    // The run ends once the partition logged the stalled connection's timeout.
    while !ended.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(200));
    }
    drop(stalled);
    c
}

/// Everything but the end: returns the stalled connection.
fn session(port: u16, ended: &AtomicBool, c: &mut Client) -> std::io::Result<TcpStream> {
    // A connection that stops in the middle of a request, and stays open.
    let mut stalled = connect(port, ended)?;
    let half = request("APP", READ_WATCHES);
    stalled.write_all(&half[..half.len() / 2])?;
    let mut s = connect(port, ended)?;
    for (destination, xml) in DEPLOY {
        let answer = ask(&mut s, destination, xml)?;
        c.deploy.push((xml.to_string(), answer));
    }
    c.counts.push(count(&ask(&mut s, "APP", READ_WATCHES)?));
    std::thread::sleep(Duration::from_secs(2));
    c.counts.push(count(&ask(&mut s, "APP", READ_WATCHES)?));
    c.query = ask(
        &mut s,
        "APP",
        "<Request ID=\"10\" Action=\"QUERY\"><FB Name=\"*\" Type=\"*\"/></Request>",
    )?;
    c.malformed = ask(
        &mut s,
        "APP",
        "<Request ID=\"11\" Action=\"CREATE\"><FB Name=",
    )?;
    c.after = ask(
        &mut s,
        "APP",
        "<Request ID=\"12\" Action=\"READ\"><Connection Source=\"C.CV\" Destination=\"\"/></Request>",
    )?;
    // Not 4diac's framing at all: one refusal, then the connection closes.
    let mut other = connect(port, ended)?;
    other.write_all(b"GET / HTTP/1.0\r\n\r\n")?;
    let refusal = response(&mut other)?;
    let mut rest = [0u8; 16];
    let closed = matches!(other.read(&mut rest), Ok(0) | Err(_));
    c.not_requests = Some((refusal, closed));
    Ok(stalled)
}

#[test]
fn iec61499_tcp() {
    let (o, c) = boot_beside("iec61499_tcp", |ports, ended| client(ports[0], ended));
    println!("iec61499_tcp: the host saw {c:#?}");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.ending == Ending::Done,
        "expected the run to reach its done_when lines",
    );
    check(
        &o,
        o.line("[fb] iec61499: net 10.0.2.15/24 mac 52:54:00:12:34:56: management on tcp port 61499, connections 3, access Download")
            .is_some(),
        "the partition serves the management protocol on tcp port 61499",
    );
    check(&o, c.error.is_none(), &format!("the client failed: {c:#?}"));
    check(
        &o,
        c.deploy.len() == DEPLOY.len()
            && c.deploy
                .iter()
                .enumerate()
                .all(|(i, (_, a))| a == &format!("<Response ID=\"{}\" />", i + 1)),
        &format!("every deployment request is done: {:#?}", c.deploy),
    );
    check(
        &o,
        matches!(c.counts[..], [Some(a), Some(b)] if b >= a + 10),
        &format!(
            "the E_CYCLE (100 ms) counts into C.CV while a connection is stalled: {:?}",
            c.counts
        ),
    );
    check(
        &o,
        c.query.contains("<FB Name=\"CYCLE\" Type=\"E_CYCLE\" />")
            && c.query.contains("<FB Name=\"C\" Type=\"E_CTU\" />"),
        &format!("QUERY lists the FBs: {}", c.query),
    );
    check(
        &o,
        c.malformed == "<Response ID=\"\" Reason=\"BAD_PARAMS\" />",
        &format!("the malformed request is refused: {}", c.malformed),
    );
    check(
        &o,
        c.after.starts_with("<Response ID=\"12\">") && c.after.contains("<Connection Source=\""),
        &format!(
            "the device answers after the malformed request: {}",
            c.after
        ),
    );
    check(
        &o,
        c.not_requests.as_ref().is_some_and(|(r, closed)| {
            r == "<Response ID=\"\" Reason=\"BAD_PARAMS\" />" && *closed
        }),
        &format!(
            "a stream that is not requests gets a refusal and is closed: {:?}",
            c.not_requests
        ),
    );
    check(
        &o,
        o.lines.iter().any(|l| {
            l.contains("iec61499: tcp: closed ") && l.contains("not an ASN.1 STRING's tag")
        }),
        "the partition logs why it closed the connection",
    );
    check(
        &o,
        o.lines.iter().any(|l| {
            l.contains("iec61499: tcp: closed ")
                && l.contains(": no progress for 10 s (")
                && l.contains(" bytes of a request received, 0 bytes of a response unsent)")
        }),
        "the stalled connection is closed after 10 s",
    );
    // The boot file's E_CYCLE (10 ms) ran on through it all: every statistics line counts
    // wake-ups for its timers.
    let timers: Vec<u64> = o
        .lines
        .iter()
        .filter_map(|l| l.split("[fb] iec61499: t=").nth(1))
        .filter_map(|rest| rest.split("timers=").nth(1))
        .filter_map(|rest| rest.split(' ').next()?.parse().ok())
        .collect();
    check(
        &o,
        timers.len() >= 3 && timers[1..].iter().all(|&n| n > 0),
        &format!("the resources' timers fire on: {timers:?}"),
    );
}

/// Scenario `iec61499_fbctl`: `fbctl --tcp` in the guest against the device's port 61499.
#[test]
fn iec61499_fbctl() {
    let o = scenarios::boot("iec61499_fbctl");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected the guest's script to end the run",
    );
    let out = scenarios::guest_output(&o).join("\n");
    let has = |text: &str| out.contains(text);
    check(
        &o,
        has("<Response ID=\"1\"") && has("read status 0"),
        &format!("fbctl read the counter over TCP: {out}"),
    );
    check(
        &o,
        has("<Response ID=\"2\"") && has("COUNT") && has("query status 0"),
        &format!("fbctl queried the FBs: {out}"),
    );
    check(
        &o,
        has("ACCESS_DENIED") && has("create status 1"),
        &format!("the monitor access refused the CREATE: {out}"),
    );
    check(
        &o,
        has("fbctl: cannot connect to 10.0.2.15:61498") && has("closed port status 3"),
        &format!("a port nobody listens on: {out}"),
    );
}
