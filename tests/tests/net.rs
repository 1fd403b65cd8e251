//! The network: the NIC partition's virtio-net driver and switch (scenarios `net_nic`, with
//! a flooding tenant, `net_nic_quiet`, without, and `net_nic_ring`, with a hostile tenant
//! on a frame ring; partitions of `partitions/nic/partition` and `tests/programs/net-echo`).

use scenarios::{boot_beside, check};
use std::net::UdpSocket;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Datagrams timed one at a time, and those sent back to back for the rate.
const PINGS: usize = 200;
const BURST: usize = 500;

/// What the host saw.
#[derive(Debug, Default)]
struct Host {
    /// Round trips of the datagrams echoed, in order.
    round_trips: Vec<Duration>,
    /// Of the burst: echoes back, and the time from the first send to the last echo.
    burst_back: usize,
    burst_time: Duration,
    /// Echoes whose payload was not what was sent.
    wrong: usize,
    /// Whether the first echo ever came.
    reached: bool,
}

/// Sends datagrams to the forwarded port and checks the echoes: first until one comes
/// back (the system boots meanwhile), then [`PINGS`] one at a time, then a burst of
/// [`BURST`]; then says `done`, which ends the run.
fn client(port: u16, ended: &AtomicBool) -> Host {
    let mut host = Host::default();
    let socket = UdpSocket::bind(("127.0.0.1", 0)).expect("a UDP socket");
    socket.connect(("127.0.0.1", port)).expect("connect");
    let mut buf = [0u8; 2048];
    // Whether `payload` came back within `wait` (a late echo of an earlier datagram is
    // skipped; anything that is no echo of ours is counted as wrong).
    let mut wrong = 0;
    let mut exchange = |socket: &UdpSocket, payload: &[u8], wait: Duration, buf: &mut [u8]| {
        let _ = socket.send(payload);
        let deadline = Instant::now() + wait;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            socket.set_read_timeout(Some(left)).unwrap();
            match socket.recv(buf) {
                Ok(n) if &buf[..n] == payload => return true,
                Ok(n)
                    if [&b"hello"[..], b"ping ", b"done"]
                        .iter()
                        .any(|p| buf[..n].starts_with(p)) => {}
                Ok(_) => wrong += 1,
                Err(_) => return false,
            }
        }
    };
    while !ended.load(Ordering::SeqCst) {
        if exchange(&socket, b"hello", Duration::from_millis(500), &mut buf) {
            host.reached = true;
            break;
        }
    }
    if !host.reached {
        return host;
    }
    for i in 0..PINGS {
        let payload = format!("ping {i:04} {}", "x".repeat(i % 64));
        let start = Instant::now();
        if exchange(
            &socket,
            payload.as_bytes(),
            Duration::from_secs(2),
            &mut buf,
        ) {
            host.round_trips.push(start.elapsed());
        }
    }
    // The burst: all sent, then the echoes counted (stale pings may still come).
    socket
        .set_read_timeout(Some(Duration::from_secs(3)))
        .unwrap();
    let start = Instant::now();
    for i in 0..BURST {
        let _ = socket.send(format!("burst {i:04}").as_bytes());
    }
    while let Ok(n) = socket.recv(&mut buf) {
        if buf[..n].starts_with(b"burst ") {
            host.burst_back += 1;
            host.burst_time = start.elapsed();
            if host.burst_back == BURST {
                break;
            }
        }
    }
    while !ended.load(Ordering::SeqCst) {
        let _ = exchange(&socket, b"done", Duration::from_millis(500), &mut buf);
    }
    host.wrong = wrong;
    host
}

/// The value of `key=` in `line`.
fn field(line: &str, key: &str) -> Option<u64> {
    let at = line.find(&format!(" {key}="))? + key.len() + 2;
    line[at..].split(' ').next()?.parse().ok()
}

#[test]
fn net_nic() {
    echoes("net_nic", "flood");
}

#[test]
fn net_nic_quiet() {
    echoes("net_nic_quiet", "idle");
}

/// The second tenant floods its frame ring and writes random bytes over its segment:
/// the switch counts its bogus slots and goes on, the echo tenant keeps every round trip.
#[test]
fn net_nic_ring() {
    echoes("net_nic_ring", "scribble");
}

/// Scenario `name`: every datagram timed one at a time comes back, beside the second
/// tenant `other` (flooding or idle).
fn echoes(name: &str, other: &str) {
    let (o, host) = boot_beside(name, |ports, ended| client(ports[0], ended));
    for line in [
        "nic: virtio-net 00:03.0 MAC 52:54:00:12:34:56, 64 descriptors a queue, line 23, 2 tenant(s)",
        "nic: tenant echo MAC 52:54:00:12:34:56 from echo-tx to echo-rx",
        &format!("nic: tenant {other} MAC 52:54:00:12:34:57 from {other}-tx to {other}-rx"),
        "echo: the host is done",
    ] {
        check(&o, o.line(line).is_some(), &format!("missing {line:?}"));
    }
    check(&o, host.reached, "no echo ever came back to the host");
    let mut sorted = host.round_trips.clone();
    sorted.sort();
    let pct = |p: usize| sorted[(sorted.len() - 1) * p / 100];
    println!(
        "{name}: {} of {PINGS} datagrams echoed beside tenant {other}; round trip min {:?} median {:?} p99 {:?} max {:?}; burst: {} of {BURST} back in {:?} ({:.0} echoes/s)",
        sorted.len(),
        sorted[0],
        pct(50),
        pct(99),
        sorted[sorted.len() - 1],
        host.burst_back,
        host.burst_time,
        host.burst_back as f64 / host.burst_time.as_secs_f64().max(1e-9)
    );
    check(&o, host.wrong == 0, "an echo differed from its datagram");
    check(
        &o,
        sorted.len() >= PINGS * 98 / 100,
        &format!(
            "only {} of {PINGS} datagrams echoed beside tenant {other}",
            sorted.len()
        ),
    );
    let last = |prefix: &str| {
        o.lines
            .iter()
            .rev()
            .find(|l| l.contains(prefix))
            .map(String::as_str)
    };
    let echo = last(" tenant echo ").unwrap_or("");
    let uplink = last(" uplink in=").unwrap_or("");
    println!("{name}: {echo}\n{name}: {uplink}");
    // The echo tenant's port overflows only in the host's burst (its own traffic).
    check(
        &o,
        field(echo, "spoofed") == Some(0) && field(echo, "in").is_some_and(|n| n > PINGS as u64),
        "the echo tenant's frames",
    );
    check(
        &o,
        field(uplink, "bogus") == Some(0) && field(uplink, "malformed") == Some(0),
        "the device wrote nothing bogus",
    );
    if other == "scribble" {
        let scribble = last("scribble: t=").unwrap_or("");
        let scribbled = last(" tenant scribble ").unwrap_or("");
        println!("{name}: {scribble}\n{name}: {scribbled}");
        check(
            &o,
            field(scribble, "scribbled").is_some_and(|n| n > 1000),
            "the hostile tenant wrote little over its segment",
        );
        check(
            &o,
            field(scribbled, "in").is_some_and(|n| n > 100)
                && field(scribbled, "malformed").is_some_and(|n| n > 0),
            "the switch took few of the hostile ring's frames or found nothing bogus in it",
        );
    }
    if other != "flood" {
        return;
    }
    // The flood went on all the while: the flooder lost frames at its own full port, and
    // the switch took its frames within its budget.
    let flood = last("flood: t=").unwrap_or("");
    let flooded = last(" tenant flood ").unwrap_or("");
    println!("{name}: {flood}\n{name}: {flooded}");
    check(
        &o,
        field(flood, "refused").is_some_and(|n| n > 0),
        "the flooder's port never filled",
    );
    check(
        &o,
        field(flooded, "in").is_some_and(|n| n > 1000),
        "the switch took few of the flood's frames",
    );
    check(
        &o,
        field(flooded, "limited").is_some_and(|n| n > 0),
        "the flood's broadcasts were never limited",
    );
}
