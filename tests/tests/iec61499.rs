//! IEC 61499 scenarios: the function-block runtime partition (`partitions/iec61499/partition`)
//! booted from its configured boot file.

use scenarios::tank::{self, DISTURBANCE_MS, SETTLED_MS};
use scenarios::{boot, check};
use xtask::qemu::{Ending, Outcome};

/// The health-monitor lines for `partition`'s application errors whose detail text starts
/// with `detail` (the line escapes its spaces, `syssw_core::health`).
fn reported(o: &Outcome, partition: &str, detail: &str) -> usize {
    let detail = detail.replace(' ', "\\x20");
    let wanted = format!("partition={partition} error=application_error detail=\"{detail}");
    o.lines
        .iter()
        .filter(|l| l.contains("health: t=") && l.contains(&wanted))
        .count()
}

/// The `timers=` counts of the statistics lines after the line containing `after`.
fn timers_after(o: &Outcome, after: &str) -> Vec<u64> {
    let Some(start) = o.lines.iter().position(|l| l.contains(after)) else {
        return Vec::new();
    };
    o.lines[start..]
        .iter()
        .filter_map(|l| l.split("iec61499: t=").nth(1))
        .filter_map(|rest| rest.split("timers=").nth(1))
        .filter_map(|rest| rest.split(' ').next()?.parse().ok())
        .collect()
}

/// A fault stops the named resource, is reported once, and the other resource (an E_CYCLE
/// of 10 ms: 100 timers a second) goes on; the lines `expected` are in the log.
fn stops_one_resource(name: &str, fault: &str, expected: &[&str]) {
    let o = boot(name);
    for line in expected {
        check(&o, o.line(line).is_some(), &format!("missing {line:?}"));
    }
    check(
        &o,
        o.ending == Ending::Done,
        "expected the run to reach its done_when lines",
    );
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.line("iec61499: booted: ").is_some(),
        "missing the boot line",
    );
    let stopped = o.line(fault);
    check(&o, stopped.is_some(), &format!("missing {fault:?}"));
    let detail = fault.trim_start_matches("iec61499: ");
    check(
        &o,
        reported(&o, "fb", detail) == 1,
        "the fault is reported to the health monitor once",
    );
    let after = timers_after(&o, fault);
    check(
        &o,
        after.len() >= 2 && after[1..].iter().all(|&n| n == 100),
        &format!("STEADY ticks 100 times a second after the fault: {after:?}"),
    );
}

#[test]
fn iec61499_overflow() {
    stops_one_resource(
        "iec61499_overflow",
        "iec61499: resource FLOOD stopped: event queue full",
        &[],
    );
}

#[test]
fn iec61499_trap() {
    stops_one_resource(
        "iec61499_trap",
        "iec61499: resource FAILING stopped: DIV trapped: ",
        &[
            "iec61499: resource STEADY runs in process r:STEADY at priority 50, the device process at 49",
        ],
    );
}

#[test]
fn iec61499_deploy() {
    let o = boot("iec61499_deploy");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the end of the guest's script ends the run",
    );
    check(
        &o,
        o.line("[linux] guest: init exited with status 0").is_some(),
        "the script ended with status 0",
    );
    check(
        &o,
        o.line("iec61499: management on req/resp, access Download")
            .is_some(),
        "the partition serves its management ports",
    );
    let out = scenarios::guest_output(&o);
    let has = |text: &str| out.iter().any(|l| l.contains(text));
    let expected = [
        // The type compiled in the guest and added.
        "type COUNTDOWN: ",
        // The boot file, line by line.
        "1: <Response ID=\"1\" />",
        "5: <Response ID=\"5\" />",
        // An event through the downloaded type: Q := 300 / 3; its CNF counted by C.
        "<Connection Source=\"D.Q\" Destination=\"100\" />",
        "<Port name=\"CV\"><Data value=\"1\" forced=\"false\"/></Port>",
        // Forced, then released.
        "<Connection Source=\"D.Q\" Destination=\"7\" />",
        // The damaged package: refused with the reason in the log; the old type runs on
        // (300 / 2).
        "fbctl: type COUNTDOWN: refused: INVALID_OBJECT",
        "damaged type status 1",
        "<Connection Source=\"D.Q\" Destination=\"150\" />",
        // The changed type: a new instance computes 600 / 3.
        "<Connection Source=\"D2.Q\" Destination=\"200\" />",
        "duplicate status 1",
        "bad resource status 1",
        "done",
    ];
    for text in expected {
        check(
            &o,
            has(text),
            &format!("missing {text:?} in the guest's output"),
        );
    }
    check(
        &o,
        o.line("iec61499: type COUNTDOWN refused: ").is_some(),
        "the device logs why it refused the damaged package",
    );
    check(
        &o,
        o.lines
            .iter()
            .filter(|l| l.contains("iec61499: type COUNTDOWN added: "))
            .count()
            == 2,
        "the type was added twice (the original, the changed one)",
    );
}

/// The `watch` values of the fb partition: `(t in ms, name, value)`.
fn watches(o: &Outcome) -> Vec<(u64, String, String)> {
    let mut out = Vec::new();
    for l in &o.lines {
        let Some(rest) = l.split_once("[fb] iec61499: t=").map(|(_, r)| r) else {
            continue;
        };
        let Some((t, values)) = rest.split_once("ms watch ") else {
            continue;
        };
        let Ok(t) = t.parse::<u64>() else { continue };
        for pair in values.split(' ') {
            if let Some((name, value)) = pair.split_once('=') {
                out.push((t, name.to_string(), value.to_string()));
            }
        }
    }
    out
}

#[test]
fn iec61499_tank() {
    let o = boot("iec61499_tank");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the stopwatch ends the run",
    );
    check(
        &o,
        o.line("[fb] iec61499: booted: 2 type(s), ").is_some(),
        "the device booted with its two FB types",
    );
    let status = tank::status(&o);
    tank::settles(&o, &status);
    // The plant counts the releases that found no fresh valve command; those before the
    // device's first cycle (while it boots) are the only ones.
    let stale_at_start = status
        .iter()
        .find(|s| s.t_ms >= 1_000)
        .map_or(0, |s| s.stale);
    tank::holds(
        &o,
        &status,
        |t| (SETTLED_MS..DISTURBANCE_MS.0).contains(&t),
        stale_at_start,
    );
    let alarm: Vec<(u64, bool)> = watches(&o)
        .into_iter()
        .filter(|(_, name, _)| name == "TANK.ALARM.ALARM")
        .map(|(t, _, v)| (t, v == "TRUE"))
        .collect();
    check(
        &o,
        alarm.len() >= 30,
        &format!("{} alarm watch values", alarm.len()),
    );
    check(
        &o,
        alarm.iter().all(|&(t, on)| t >= DISTURBANCE_MS.0 || !on),
        "the alarm was raised before the disturbance",
    );
    check(
        &o,
        alarm
            .iter()
            .any(|&(t, on)| on && (DISTURBANCE_MS.0..=DISTURBANCE_MS.1 + 2_000).contains(&t)),
        "the alarm was not raised during the disturbance",
    );
    // 100 cycles a second: one timer wake-up each, none lost.
    let timers: Vec<u64> = o
        .lines
        .iter()
        .filter_map(|l| {
            l.split_once("[fb] iec61499: t=")?
                .1
                .split_once(" timers=")?
                .1
                .split(' ')
                .next()?
                .parse()
                .ok()
        })
        .collect();
    check(
        &o,
        timers.len() >= 30 && timers[1..].iter().all(|&n| n == 100),
        &format!("the E_CYCLE fires 100 times a second: {timers:?}"),
    );
}

#[test]
fn iec61499_system() {
    let o = boot("iec61499_system");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        matches!(o.ending, Ending::TimedOut),
        "expected the system to run until the timeout",
    );
    // Both tanks get their controller's setpoint: each controller runs and reaches its plant.
    for plant in ["plant", "plant2"] {
        let status = tank::status_of_partition(&o, plant);
        check(
            &o,
            status
                .iter()
                .any(|s| s.setpoint == Some(1.0) && s.level > 0.5),
            &format!("{plant}: no status line with the setpoint 1.0 and a rising level"),
        );
    }
    let console = o.console_lines();
    check(
        &o,
        console
            .iter()
            .any(|l| l.starts_with("Warden: two tanks, two PLC models")),
        "console: no banner",
    );
    check(
        &o,
        console
            .iter()
            .any(|l| l.contains("<Port name=\"IN\"><Data value=\"")),
        "console: fbctl did not read the device's watches",
    );
    check(
        &o,
        console.iter().any(|l| l.contains("refused: ACCESS_DENIED"))
            && console.contains(&"type status 1"),
        "console: a monitor client's type download was not refused",
    );
}

/// The value of `NAME=` in a watch line.
fn watched<'l>(line: &'l str, name: &str) -> Option<&'l str> {
    line.split(' ')
        .find_map(|part| part.strip_prefix(name)?.strip_prefix('='))
}

#[test]
fn iec61499_pubsub() {
    let o = boot("iec61499_pubsub");
    check(
        &o,
        o.ending == Ending::Done,
        "expected the run to reach its done_when lines",
    );
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    let Some(sub) = o.line("iec61499: t=3000ms watch SUB.") else {
        return check(&o, false, "no subscriber watch line at 3 s");
    };
    eprintln!("{sub}");
    let count = |name| watched(sub, name).and_then(|v| v.parse::<u64>().ok());
    let (received, last) = (count("SUB.N.CV"), count("SUB.V.OUT"));
    // A message every 100 ms from the publisher's start: about 30 by 3 s, none lost (each
    // IND carries the publisher's count, which equals the number received).
    check(
        &o,
        received.is_some_and(|n| (25..=31).contains(&n)) && last == received,
        &format!("subscriber at 3 s: {received:?} INDs, last value {last:?}"),
    );
    check(
        &o,
        watched(sub, "SUB.X.OUT") == Some("1.5") && watched(sub, "SUB.S.STATUS") == Some("'OK'"),
        &format!("subscriber's LREAL and status: {sub}"),
    );
    let publisher = o.line("watch PUB.TICK.CV=");
    check(
        &o,
        publisher.is_some_and(|l| watched(l, "PUB.P.STATUS") == Some("'OK'")),
        &format!("publisher's status: {publisher:?}"),
    );
    // CLIENT/SERVER: each count the client sent came back from the server's echo, in
    // order and none lost (the responses counted equal the last count echoed), at most
    // the last request still on its way.
    let Some(client) = o.line("iec61499: t=3000ms watch PUB.") else {
        return check(&o, false, "no publisher watch line at 3 s");
    };
    let number = |name| watched(client, name).and_then(|v| v.parse::<u64>().ok());
    let (sent, responses, echoed) = (
        number("PUB.TICK.CV"),
        number("PUB.RC.CV"),
        number("PUB.Q.OUT"),
    );
    check(
        &o,
        sent.is_some_and(|n| (20..=31).contains(&n))
            && responses
                .zip(sent)
                .is_some_and(|(r, s)| r + 1 >= s && r <= s)
            && echoed == responses,
        &format!("client at 3 s: {sent:?} requests, {responses:?} responses, last echo {echoed:?}"),
    );
    check(
        &o,
        watched(client, "PUB.C.STATUS") == Some("'OK'")
            && watched(sub, "SUB.SV.STATUS") == Some("'OK'"),
        &format!("client's and server's status: {client} / {sub}"),
    );
}

/// Every `NAME=value` of the watch lines of partition `partition` at `t` (a device's
/// watches may take several lines).
fn watch_at(o: &Outcome, partition: &str, t: &str) -> String {
    let prefix = format!("[{partition}] iec61499: t={t} watch");
    o.lines
        .iter()
        .filter_map(|l| l.split(&prefix).nth(1))
        .collect::<Vec<_>>()
        .join("")
}

#[test]
fn iec61499_ip() {
    let o = boot("iec61499_ip");
    check(
        &o,
        o.ending == Ending::Done,
        "expected the run to reach its done_when lines",
    );
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    let sub = watch_at(&o, "sub", "5000ms");
    let publisher = watch_at(&o, "pub", "5000ms");
    eprintln!("sub:{sub}\npub:{publisher}");
    let number = |line: &str, name| watched(line, name).and_then(|v| v.parse::<u64>().ok());
    let sent = number(&publisher, "PUB.COUNT.CV");
    // A count every 100 ms from about 1 s after the boot: about 30 by 5 s.
    check(
        &o,
        sent.is_some_and(|n| (20..=45).contains(&n)),
        &format!("publisher at 5 s: {sent:?} counts"),
    );
    check(
        &o,
        watched(&publisher, "PUB.M.STATUS") == Some("'OK'")
            && watched(&publisher, "PUB.U.STATUS") == Some("'OK'"),
        &format!("publisher's statuses: {publisher}"),
    );
    // Multicast and unicast: each IND carries the publisher's count, which equals the
    // number received (none lost). (The two devices' watch lines at "5000ms" are of
    // their own clocks, printed at their first timer after it: not the same instant.)
    let mut counts = Vec::new();
    for (what, received, last) in [
        ("multicast", "SUB.N.CV", "SUB.V.OUT"),
        ("unicast", "SUB.NU.CV", "SUB.VU.OUT"),
    ] {
        let (received, last) = (number(&sub, received), number(&sub, last));
        check(
            &o,
            received.is_some_and(|n| (20..=45).contains(&n)) && last == received,
            &format!("{what} at 5 s: {received:?} INDs, last count {last:?}"),
        );
        counts.extend(received);
    }
    check(
        &o,
        counts.len() == 2 && counts[0].abs_diff(counts[1]) <= 1,
        &format!("multicast and unicast INDs differ: {counts:?}"),
    );
    check(
        &o,
        watched(&sub, "SUB.X.OUT") == Some("1.5")
            && watched(&sub, "SUB.S.STATUS") == Some("'OK'")
            && watched(&sub, "SUB.T.STATUS") == Some("'OK'"),
        &format!("subscriber's LREAL and statuses: {sub}"),
    );
    // Nothing dropped or failed on either side; what the publisher sent arrived (its
    // statistics line and the subscriber's come 3 ms apart, in the same major frame).
    // A partition's last statistics line of a kind (` udp `, ` tcp `).
    let last_stats = |partition: &str, kind: &str| {
        let needle = format!("[{partition}] iec61499: t=");
        o.lines
            .iter()
            .rfind(|l| l.contains(&needle) && l.contains(kind))
            .map(String::as_str)
    };
    let udp = |partition: &str| last_stats(partition, " udp ");
    let stat = |line: Option<&str>, name: &str| {
        line.and_then(|l| watched(l.trim_end(), name))
            .and_then(|v| v.parse::<u64>().ok())
    };
    let (p, s) = (udp("pub"), udp("sub"));
    for line in [p, s] {
        check(
            &o,
            stat(line, "dropped") == Some(0)
                && stat(line, "send_failed") == Some(0)
                && stat(line, "errors") == Some(0),
            &format!("udp statistics: {line:?}"),
        );
    }
    let (sent, received) = (stat(p, "sent"), stat(s, "received"));
    check(
        &o,
        sent.zip(received)
            .is_some_and(|(sent, received)| sent >= 40 && received <= sent && received + 2 >= sent),
        &format!("datagrams sent {sent:?}, received {received:?}"),
    );
    // CLIENT/SERVER over TCP: the client's requests (a count every 100 ms from about 1 s)
    // all reached the server and came back in order (the last answer's count is the
    // number of answers), on one connection each side, none refused or ended.
    let (client, server) = (watch_at(&o, "pub", "5000ms"), watch_at(&o, "sub", "5000ms"));
    let (requests, answers, last) = (
        number(&client, "CLI.C.CV"),
        number(&client, "CLI.N.CV"),
        number(&client, "CLI.V.OUT"),
    );
    check(
        &o,
        requests.is_some_and(|n| (20..=45).contains(&n))
            && answers
                .zip(requests)
                .is_some_and(|(a, r)| a <= r && a + 2 >= r)
            && last == answers
            && watched(&client, "CLI.CL.STATUS") == Some("'OK'"),
        &format!(
            "client at 5 s: {requests:?} requests, {answers:?} answers, last {last:?}: {client}"
        ),
    );
    let served = number(&server, "SRV.M.CV");
    check(
        &o,
        served.is_some_and(|n| (20..=45).contains(&n))
            && watched(&server, "SRV.S.STATUS") == Some("'OK'"),
        &format!("server at 5 s: {served:?} requests: {server}"),
    );
    for line in [last_stats("pub", " tcp "), last_stats("sub", " tcp ")] {
        check(
            &o,
            stat(line, "connected") == Some(1)
                && stat(line, "refused") == Some(0)
                && stat(line, "ended") == Some(0)
                && stat(line, "bytes_in").is_some_and(|n| n >= 60),
            &format!("tcp statistics: {line:?}"),
        );
    }
}
