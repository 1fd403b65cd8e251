//! The plant partition (`partitions/plant`) under syssw, driven open loop.

use scenarios::{boot, check};
use xtask::qemu::Outcome;

/// The value of `key=` in a status line (`plant: t=...ms level=... valve=... ...`).
fn field<'a>(line: &'a str, key: &str) -> Option<&'a str> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(key)?.strip_prefix('='))
}

fn status_lines(o: &Outcome) -> Vec<&str> {
    o.lines
        .iter()
        .filter_map(|l| l.split_once("plant: t=").map(|_| l.as_str()))
        .collect()
}

#[test]
fn plant_open_loop() {
    let o = boot("plant_open_loop");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the valve driver ends the run",
    );
    check(
        &o,
        o.line("valve: held 0.5 for 1500 frames").is_some(),
        "the driver did not finish",
    );
    let lines = status_lines(&o);
    // One line per 500 ms simulated: 15 s of frames give about 30.
    check(
        &o,
        lines.len() >= 25,
        &format!("{} status lines", lines.len()),
    );
    let level = |l: &str| -> f64 {
        field(l, "level")
            .and_then(|v| v.parse().ok())
            .unwrap_or(-1.0)
    };
    let last = lines.last().copied().unwrap_or("");
    // Steady state of the model with the valve at 0.5: h = (0.5 * q_max / k)^2 = 1 m.
    let want = plant::Tank::DEFAULT.steady_level(0.5);
    check(
        &o,
        (level(last) - want).abs() < 0.01,
        &format!("level did not settle at {want} m: {last:?}"),
    );
    check(
        &o,
        field(last, "valve") == Some("0.500"),
        &format!("valve in {last:?}"),
    );
    // Rising monotonically from empty towards the steady level.
    let levels: Vec<f64> = lines.iter().map(|l| level(l)).collect();
    check(
        &o,
        levels.windows(2).all(|w| w[1] >= w[0] - 1e-9),
        &format!("level not monotonic: {levels:?}"),
    );
    check(
        &o,
        field(last, "disturbance") == Some("off"),
        "no disturbance before 30 s",
    );
}
