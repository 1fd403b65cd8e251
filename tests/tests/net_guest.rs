//! The outside and the guest through the NIC partition (configurations
//! `tests/configs/net_guest_httpd.toml` and `net_guest_wget.toml`): the guest's `eth0` is
//! the tenant of the NIC partition, which drives QEMU's virtio-net on its user network;
//! its frames go through a frame ring in shared memory in the first, through the ports in
//! the second.
//! The host side of each scenario is plain std networking on 127.0.0.1.

use scenarios::{boot_beside, check, guest_stdout, http_get};
use sha2::{Digest, Sha256};
use std::io::{Read, Write};
use std::net::TcpListener;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// What the host saw of the guest's httpd.
#[derive(Debug, Default)]
struct Fetched {
    page: Option<(String, String)>,
    cgi: Option<(String, String)>,
    /// Of the timed requests: how many answered 200 with the page, and how long they took.
    timed_ok: usize,
    timed: Duration,
    finished: bool,
}

/// Requests timed one after another (each a new connection), for the rate.
const TIMED: usize = 100;

/// The host side of `net_guest_httpd`: waits for the page (the system boots meanwhile),
/// fetches the CGI result, times [`TIMED`] more pages, then asks for /cgi-bin/finish.
fn browse(port: u16, ended: &AtomicBool) -> Fetched {
    let mut f = Fetched::default();
    while !ended.load(Ordering::SeqCst) {
        if let Some(page) = http_get(port, "/") {
            f.page = Some(page);
            break;
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    if f.page.is_none() {
        return f;
    }
    f.cgi = http_get(port, "/cgi-bin/hello?from=host");
    let start = Instant::now();
    for _ in 0..TIMED {
        if http_get(port, "/index.html").is_some_and(|(status, body)| {
            status.contains(" 200") && body.contains("served by the guest")
        }) {
            f.timed_ok += 1;
        }
    }
    f.timed = start.elapsed();
    while !ended.load(Ordering::SeqCst) && !f.finished {
        f.finished = http_get(port, "/cgi-bin/finish").is_some();
    }
    f
}

#[test]
fn net_guest_httpd() {
    let (o, f) = boot_beside("net_guest_httpd", |ports, ended| browse(ports[0], ended));
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.line("nic: tenant linux MAC 52:54:00:12:34:56 from linux-tx to linux-rx, frames in a ring of 16 slots each way at 0x600000000000")
            .is_some(),
        "the NIC partition did not attach the guest through its frame ring",
    );
    check(
        &o,
        o.line("guest: eth0 frames in a ring of 16 slots each way at 0x600000000000")
            .is_some(),
        "the guest's eth0 does not use its frame ring",
    );
    let (status, body) = f.page.clone().unwrap_or_default();
    check(
        &o,
        status.contains(" 200") && body == "<h1>served by the guest</h1>\n",
        &format!("the page: {status:?} {body:?}"),
    );
    let (status, body) = f.cgi.clone().unwrap_or_default();
    check(
        &o,
        status.contains(" 200") && body == "cgi in the guest says from=host\n",
        &format!("the CGI result: {status:?} {body:?}"),
    );
    println!(
        "net_guest_httpd: {} of {TIMED} pages through hostfwd in {:?} ({:.1} requests/s, one connection at a time, real time)",
        f.timed_ok,
        f.timed,
        f.timed_ok as f64 / f.timed.as_secs_f64().max(1e-9)
    );
    check(
        &o,
        f.timed_ok == TIMED,
        &format!("only {} of {TIMED} timed pages came", f.timed_ok),
    );
    check(&o, f.finished, "the finishing request got no answer");
    let lines = guest_stdout(&o, "linux");
    check(
        &o,
        lines == ["serving", "eth0 received frames", "finished"],
        &format!("the guest printed {lines:?}"),
    );
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the guest's init ends the run",
    );
}

/// The file the test serves to the guest: 256 KiB of a fixed pseudo-random sequence.
fn payload() -> Vec<u8> {
    let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
    (0..256 * 1024)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 32) as u8
        })
        .collect()
}

/// What the test's server saw.
#[derive(Debug, Default)]
struct Served {
    /// Request lines received, in order.
    requests: Vec<String>,
    /// Time from the last payload request to its last byte written.
    took: Duration,
}

/// The host side of `net_guest_wget`: an HTTP/1.0 server on 127.0.0.1:`port` serving
/// `body` at /payload (404 elsewhere), one connection at a time, until QEMU ends or 20
/// connections. QEMU's `guestfwd` connects when it starts and again after each connection
/// ends; a connection that carries no request yet is waited on.
fn serve(port: u16, body: &[u8], ended: &AtomicBool) -> Served {
    let mut served = Served::default();
    let listener = TcpListener::bind(("127.0.0.1", port)).expect("the test's HTTP port");
    listener.set_nonblocking(true).unwrap();
    let mut connections = 0;
    while !ended.load(Ordering::SeqCst) && connections < 20 {
        let mut stream = match listener.accept() {
            Ok((stream, _)) => stream,
            Err(_) => {
                std::thread::sleep(Duration::from_millis(50));
                continue;
            }
        };
        connections += 1;
        stream.set_nonblocking(false).unwrap();
        stream
            .set_read_timeout(Some(Duration::from_millis(500)))
            .unwrap();
        let mut request = Vec::new();
        let mut buf = [0u8; 1024];
        // Until the request's head is complete, the peer closes, or QEMU ends.
        while !request.windows(4).any(|w| w == b"\r\n\r\n") && request.len() < 8192 {
            match stream.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => request.extend_from_slice(&buf[..n]),
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    if ended.load(Ordering::SeqCst) {
                        break;
                    }
                }
                Err(_) => break,
            }
        }
        let request = String::from_utf8_lossy(&request).into_owned();
        let Some(line) = request.lines().next().filter(|l| !l.is_empty()) else {
            continue;
        };
        served.requests.push(line.to_string());
        let start = Instant::now();
        let _ = if line.starts_with("GET /payload ") {
            write!(
                stream,
                "HTTP/1.0 200 OK\r\nContent-Type: application/octet-stream\r\nContent-Length: {}\r\n\r\n",
                body.len()
            )
            .and_then(|()| stream.write_all(body))
        } else {
            stream.write_all(b"HTTP/1.0 404 Not Found\r\nContent-Length: 0\r\n\r\n")
        };
        served.took = start.elapsed();
    }
    served
}

#[test]
fn net_guest_wget() {
    let body = payload();
    let digest: String = Sha256::digest(&body)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    let (o, served) = boot_beside("net_guest_wget", |ports, ended| {
        serve(ports[0], &body, ended)
    });
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.line("frames in a ring").is_none(),
        "this guest's frames go through its ports, not a ring",
    );
    println!(
        "net_guest_wget: the server saw {:?}; the payload's {} bytes written in {:?} (real time)",
        served.requests,
        body.len(),
        served.took
    );
    check(
        &o,
        served
            .requests
            .iter()
            .any(|r| r.starts_with("GET /payload HTTP/1.")),
        "the guest never asked for /payload",
    );
    let lines = guest_stdout(&o, "linux");
    let expected = [
        format!("{digest}  /tmp/fetched"),
        body.len().to_string(),
        "done".to_string(),
    ];
    check(
        &o,
        lines == expected,
        &format!("the guest printed {lines:?}, expected {expected:?}"),
    );
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the guest's init ends the run",
    );
}
