//! The tank of `partitions/plant` under the example controllers (`config/plc/tank.st` on
//! the soft-PLC, `config/iec61499/tank.fboot` on the IEC 61499 device): its trajectory as
//! the plant's status lines show it, and the checks the scenarios make of it.

use crate::check;
use plant::Status;
use xtask::qemu::Outcome;

/// The band around the 1 m setpoint the level must reach and hold (± 10 %).
pub const BAND: f64 = 0.1;
/// Simulated time by which the level is in the band (from an empty tank).
pub const SETTLED_MS: u64 = 8_000;
/// The plant's first disturbance: extra inflow from 20 s to 25 s.
pub const DISTURBANCE_MS: (u64, u64) = (20_000, 25_000);

/// The status lines of every plant in the run, in order.
pub fn status(o: &Outcome) -> Vec<Status> {
    status_of(o, "plant: t=")
}

/// The status lines of the plant in partition `plant`.
pub fn status_of_partition(o: &Outcome, plant: &str) -> Vec<Status> {
    status_of(o, &format!("[{plant}] plant: t="))
}

fn status_of(o: &Outcome, marker: &str) -> Vec<Status> {
    o.lines
        .iter()
        .filter(|l| l.contains(marker))
        .filter_map(|l| Status::parse(l))
        .collect()
}

/// Checks that the run has at least 60 status lines and the level was in the band by
/// [`SETTLED_MS`].
pub fn settles(o: &Outcome, status: &[Status]) {
    check(
        o,
        status.len() >= 60,
        &format!("{} plant status lines", status.len()),
    );
    let settled = status
        .iter()
        .find(|s| (s.level - 1.0).abs() <= BAND)
        .map(|s| s.t_ms);
    check(
        o,
        settled.is_some_and(|t| t <= SETTLED_MS),
        &format!("level in the band at {settled:?} ms, not by {SETTLED_MS} ms"),
    );
}

/// Whether the level reached the band while the valve was open: the loop closed under a
/// remote controller (checked by the event, not by a time, where machines boot apart).
pub fn reaches_band(status: &[Status]) -> bool {
    status
        .iter()
        .any(|s| (s.level - 1.0).abs() <= BAND && s.valve > 0.0)
}

/// Checks every status line at a time `during` accepts: the level in the band, the
/// controller's 1 m setpoint there, and `stale` releases without a fresh valve command
/// (those before the controller's first cycle).
pub fn holds(o: &Outcome, status: &[Status], during: impl Fn(u64) -> bool, stale: u64) {
    for s in status.iter().filter(|s| during(s.t_ms)) {
        check(
            o,
            (s.level - 1.0).abs() <= BAND && s.setpoint == Some(1.0) && s.stale == stale,
            &format!("{s}: out of the band, without the setpoint, or a stale valve"),
        );
    }
}

/// The loop under load: the level settles by [`SETTLED_MS`] and stays in the band with the
/// controller's setpoint from then on, except in the plant's disturbance and the second
/// after it.
pub fn settles_and_holds(o: &Outcome) {
    let status = status(o);
    settles(o, &status);
    holds(
        o,
        &status,
        |t| (SETTLED_MS..DISTURBANCE_MS.0).contains(&t) || t >= DISTURBANCE_MS.1 + 1_000,
        0,
    );
}
