//! IEC 61499 scenarios: the function-block runtime partition (`partitions/iec61499/partition`)
//! booted from its configured boot file.

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
/// of 10 ms: 100 timers a second) goes on.
fn stops_one_resource(name: &str, fault: &str) {
    let o = boot(name);
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
    );
}

#[test]
fn iec61499_trap() {
    stops_one_resource(
        "iec61499_trap",
        "iec61499: resource FAILING stopped: DIV trapped: ",
    );
}

/// The guest's output lines (stdout and stderr of its processes).
fn output(o: &Outcome) -> Vec<String> {
    o.lines
        .iter()
        .filter_map(|l| l.split_once("[linux] guest: process "))
        .filter_map(|(_, text)| {
            let (_, rest) = text.split_once(' ')?;
            rest.strip_prefix("stdout: ")
                .or_else(|| rest.strip_prefix("stderr: "))
                .map(str::to_string)
        })
        .collect()
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
    let out = output(&o);
    let has = |text: &str| out.iter().any(|l| l.contains(text));
    let expected = [
        // The type compiled in the guest and added.
        "type COUNTDOWN: ",
        // The boot file, line by line.
        "1: <Response ID=\"1\" />",
        "5: <Response ID=\"5\" />",
        // An event through the downloaded type: Q := 300 / 3; its CNF counted by C.
        "<Connection Source=\"100\" Destination=\"\" />",
        "<Port name=\"CV\"><Data value=\"1\" forced=\"false\"/></Port>",
        // Forced, then released.
        "<Connection Source=\"7\" Destination=\"\" />",
        // The damaged package: refused with the reason in the log; the old type runs on
        // (300 / 2).
        "fbctl: type COUNTDOWN: refused: INVALID_OBJECT",
        "damaged type status 1",
        "<Connection Source=\"150\" Destination=\"\" />",
        // The changed type: a new instance computes 600 / 3.
        "<Connection Source=\"200\" Destination=\"\" />",
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
