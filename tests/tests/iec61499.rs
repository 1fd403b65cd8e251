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
