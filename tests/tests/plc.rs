//! The soft-PLC partition (`partitions/softplc/runtime`) running the example controller
//! `config/plc/tank.st` against the plant (configuration `tests/configs/plc_tank.toml`).

use plant::Status;
use scenarios::{boot, check};

/// The band around the 1 m setpoint the level must reach and hold (± 10 %).
const BAND: f64 = 0.1;
/// Simulated time by which the level is in the band (from an empty tank).
const SETTLED_MS: u64 = 8_000;
/// The plant's first disturbance (partitions/plant: extra inflow from 20 s to 25 s).
const DISTURBANCE_MS: (u64, u64) = (20_000, 25_000);

#[test]
fn plc_tank() {
    let o = boot("plc_tank");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the stopwatch ends the run",
    );
    check(
        &o,
        o.line("plc: program verified:").is_some(),
        "the runtime did not verify the program",
    );
    let status: Vec<Status> = o
        .lines
        .iter()
        .filter(|l| l.contains("plant: t="))
        .filter_map(|l| Status::parse(l))
        .collect();
    check(
        &o,
        status.len() >= 60,
        &format!("{} plant status lines", status.len()),
    );
    let settled = status
        .iter()
        .find(|s| (s.level - 1.0).abs() <= BAND)
        .map(|s| s.t_ms);
    check(
        &o,
        settled.is_some_and(|t| t <= SETTLED_MS),
        &format!("level in the band at {settled:?} ms, not by {SETTLED_MS} ms"),
    );
    for s in status
        .iter()
        .filter(|s| (SETTLED_MS..DISTURBANCE_MS.0).contains(&s.t_ms))
    {
        check(
            &o,
            (s.level - 1.0).abs() <= BAND && s.setpoint == Some(1.0) && s.stale == 0,
            &format!("{s}: out of the band, without the PLC's setpoint, or a stale valve"),
        );
    }
    // The PLC logs its watched variables once a second: the alarm is raised during the
    // disturbance and was not before it.
    let watch: Vec<(u64, bool)> = o
        .lines
        .iter()
        .filter_map(|l| {
            let rest = &l[l.find("plc: t=")? + "plc: t=".len()..];
            let (t, rest) = rest.split_once("ms watch ")?;
            let alarm = rest
                .split_whitespace()
                .find_map(|w| w.strip_prefix("alarm="))?;
            Some((t.parse().ok()?, alarm == "TRUE"))
        })
        .collect();
    check(
        &o,
        watch.len() >= 30,
        &format!("{} watch lines", watch.len()),
    );
    check(
        &o,
        watch
            .iter()
            .all(|&(t, alarm)| t >= DISTURBANCE_MS.0 || !alarm),
        "the alarm was raised before the disturbance",
    );
    check(
        &o,
        watch
            .iter()
            .any(|&(t, alarm)| (DISTURBANCE_MS.0..DISTURBANCE_MS.1 + 2_000).contains(&t) && alarm),
        "the disturbance did not raise the alarm",
    );
    // One scan per major frame, no overrun, no fault.
    let stats = o
        .lines
        .iter()
        .filter(|l| l.contains("plc: t=") && l.contains(" task="))
        .last();
    check(&o, stats.is_some(), "no PLC statistics line");
    if let Some(line) = stats {
        let field = |name: &str| {
            line.split_whitespace()
                .find_map(|w| w.strip_prefix(name))
                .and_then(|v| v.parse::<u64>().ok())
        };
        let t = line
            .split("plc: t=")
            .nth(1)
            .and_then(|r| r.split("ms").next())
            .and_then(|t| t.parse::<u64>().ok());
        let cycles = field("cycles=");
        check(
            &o,
            matches!((t, cycles), (Some(t), Some(c)) if c + 2 >= t / 10 && c <= t / 10 + 2),
            &format!("{line}: not one cycle per 10 ms frame"),
        );
        check(
            &o,
            field("overruns=") == Some(0) && field("faults=") == Some(0),
            &format!("{line}: overruns or faults"),
        );
    }
}
