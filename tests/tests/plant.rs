//! The plant partition (`partitions/plant`) under syssw, driven open loop by
//! `tests/programs/valve-driver` (configuration `tests/configs/plant_open_loop.toml`).

use plant::{DISTURBANCES, HOLD_STEPS, Simulator, Status, Tank};
use scenarios::{boot, check};

/// The configuration's major frame: simulated milliseconds per plant release.
const FRAME_MS: u64 = 10;
/// The driver's valve command and setpoint (tests/programs/valve-driver).
const VALVE: f64 = 0.5;
const SETPOINT: f64 = 1.0;
/// Simulated time the driver writes them: its 2800 frames.
const DRIVEN_MS: u64 = 2_800 * FRAME_MS;

#[test]
fn plant_open_loop() {
    let o = boot("plant_open_loop");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the driver ends the run",
    );
    check(
        &o,
        o.line("driver: silent for 150 frames").is_some(),
        "the driver did not finish",
    );
    let lines: Vec<&String> = o.lines.iter().filter(|l| l.contains("plant: t=")).collect();
    let status: Vec<Status> = lines.iter().filter_map(|l| Status::parse(l)).collect();
    check(
        &o,
        status.len() == lines.len(),
        "a status line does not parse (format in partitions/plant/src/lib.rs)",
    );
    // One line per 500 ms simulated: 28 s driven and 1.5 s silent give about 60.
    check(
        &o,
        status.len() >= 55,
        &format!("{} status lines", status.len()),
    );

    // While driven (28 s): the host model, fed the same command at every release, predicts
    // every line (within a frame of the fast rise: the first release may miss the command).
    let driven: Vec<&Status> = status.iter().filter(|s| s.t_ms <= DRIVEN_MS).collect();
    let mut model = Simulator::new();
    let mut predicted = Vec::new();
    while model.plant.time_ms < DRIVEN_MS {
        predicted.extend(model.release(Some(VALVE), None, FRAME_MS));
    }
    for s in &driven {
        let p = predicted.iter().find(|p| p.t_ms == s.t_ms);
        check(
            &o,
            p.is_some_and(|p| (p.level - s.level).abs() < 0.02 && p.disturbance == s.disturbance),
            &format!("{s} vs the model's {p:?}"),
        );
        check(
            &o,
            (s.valve, s.setpoint, s.bad) == (VALVE, Some(SETPOINT), 0) && s.stale <= FRAME_MS,
            &format!("valve, setpoint, stale or bad commands in {s}"),
        );
    }
    check(
        &o,
        driven.len() >= 50,
        &format!("{} driven lines", driven.len()),
    );

    // Before the disturbance the level has settled at the analytic steady state for valve
    // 0.5: q_in = q_out, v q_max = k sqrt(h), h = (v q_max / k)^2 = 1 m.
    let tank = Tank::DEFAULT;
    let steady = (VALVE * tank.inflow_max / tank.drain).powi(2);
    let start = DISTURBANCES[0].start_ms;
    let end = DISTURBANCES[0].end_ms;
    let before = driven.iter().rfind(|s| s.t_ms < start).unwrap();
    check(
        &o,
        (before.level - steady).abs() < 0.01 && before.overflow == 0,
        &format!("not settled at {steady} m before the disturbance: {before}"),
    );
    // The disturbance shows in its interval only, and pushes the level to the top.
    for s in &driven {
        check(
            &o,
            s.disturbance == (start..end).contains(&s.t_ms),
            &format!("disturbance flag at {s}"),
        );
    }
    let peak = driven.iter().map(|s| s.level).fold(0.0, f64::max);
    let after = driven.last().unwrap();
    check(
        &o,
        peak == tank.height && after.overflow > 0 && after.t_ms >= end,
        &format!("the disturbance did not fill the tank: peak {peak}, {after}"),
    );

    // The driver read the level back over its channel.
    let read = o.line("driver: held valve 0.5 for 2800 frames; level ");
    let read_level = read
        .and_then(|l| l.split("; level ").nth(1))
        .and_then(|r| r.strip_suffix(" m Valid"))
        .and_then(|v| v.parse::<f64>().ok());
    check(
        &o,
        read_level.is_some_and(|l| (l - after.level).abs() < 0.05),
        &format!("driver's level read {read:?} vs {after}"),
    );

    // Silent driver: the valve message goes stale, is held at most HOLD_STEPS, then the
    // valve closes and the level falls.
    let last = status.last().unwrap();
    check(
        &o,
        last.valve == 0.0 && last.stale > HOLD_STEPS && last.level < after.level - 0.1,
        &format!("valve not closed after the driver fell silent: {last}"),
    );
    check(
        &o,
        last.stale <= 1_500 + FRAME_MS,
        &format!("stale longer than the driver's silence: {last}"),
    );
}
