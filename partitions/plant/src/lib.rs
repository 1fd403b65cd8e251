//! The plant the soft-PLC controls: a deterministic simulation of a tank whose level rises
//! with the inflow through a valve and falls with the outflow through a drain, plus a fixed
//! schedule of disturbances. This library is the whole behaviour of the plant partition and
//! is tested on the host: the physics ([`Plant`]), what one release of the partition does
//! with the messages it read ([`Simulator`]: stale-command hold, status lines), and the
//! formats of its messages and of its status line. The partition program (`main.rs`) only
//! moves bytes between the sampling ports and the [`Simulator`].
//!
//! # Model
//!
//! SI units, explicit Euler with a fixed step of [`STEP_MS`]: `A dh/dt = q_in - q_out + q_d`,
//! with the inflow `q_in = valve * q_max` (valve clamped to 0..=1; a NaN or infinite command
//! counts as closed and is counted), the Torricelli outflow `q_out = k sqrt(h)` and the
//! extra inflow `q_d` of the disturbances active at that time (negative: a leak). The level
//! is kept in `[0, height]`; steps at which the tank spills over are counted. With valve `v`
//! held, the level settles at `h = (v q_max / k)^2` ([`Tank::steady_level`]). The constants
//! are [`Tank::DEFAULT`] and [`DISTURBANCES`].
//!
//! # Messages
//!
//! Every port carries one 8-byte little-endian `f64` ([`encode`], [`decode`]): `valve` in
//! (0.0..=1.0), `level` out (metres), `setpoint` in (metres, optional, only shown in the
//! status line). A valve message that is missing, INVALID (older than the port's refresh
//! period) or not 8 bytes long is stale: the last valid command is kept for at most
//! [`HOLD_STEPS`] steps, then the valve closes (the safe state) until a valid message comes.
//!
//! # Status line
//!
//! An interface: scenario tests and plotting tools parse it ([`Status::parse`]). One line
//! per [`STATUS_EVERY_MS`] of simulated time (at the first release whose end reaches the
//! next multiple), all fields space-separated `key=value`:
//!
//! ```text
//! plant: t=<ms>ms level=<m.mmm> valve=<0.000> setpoint=<m.mmm|-> disturbance=<on|off> stale=<n> bad=<n> overflow=<n>
//! ```
//!
//! `t` is the simulated time (ms) after the release, `level` the level then (m), `valve` the
//! command the release applied (after clamping, hold and fall-back), `setpoint` the latest
//! setpoint message (`-` when there is no port, no message yet, or it is not a finite
//! number), `disturbance` whether a disturbance is active at `t`; the counters, all in
//! steps since the start: `stale` steps run without a fresh valid valve message, `bad` steps
//! run with a NaN or infinite command, `overflow` steps at which the tank spilled over.
//!
//! It must stay deterministic and total: the trajectory depends only on the messages and
//! the step counts (no clock, no floating-point function outside this file: [`sqrt`] is
//! ours), and no input, however malformed, panics.
#![cfg_attr(not(test), no_std)]

use core::fmt;

/// Simulated milliseconds per step.
pub const STEP_MS: u64 = 1;
/// Steps a stale valve command is kept before the valve closes (100 ms simulated).
pub const HOLD_STEPS: u64 = 100;
/// Simulated time between status lines.
pub const STATUS_EVERY_MS: u64 = 500;

/// A tank's constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tank {
    /// Cross-section (m²).
    pub area: f64,
    /// Height (m): the level never exceeds it.
    pub height: f64,
    /// Inflow with the valve fully open (m³/s).
    pub inflow_max: f64,
    /// Drain coefficient `k` of `q_out = k sqrt(h)` (m^2.5/s).
    pub drain: f64,
}

impl Tank {
    /// The default tank: 2 m high, 0.01 m² cross-section. The valve fully open fills it from
    /// empty to the top in about 2.1 s (its steady level, 4 m, is above the top); closed,
    /// a full tank empties in about 2.8 s (`sqrt(h)` falls by 0.5 per second). A held valve
    /// of 0.5 settles at 1 m, with a time constant of about 2 s there.
    pub const DEFAULT: Tank = Tank {
        area: 0.01,
        height: 2.0,
        inflow_max: 0.02,
        drain: 0.01,
    };

    /// The level a held valve command settles at (clamped to the tank's height).
    pub fn steady_level(&self, valve: f64) -> f64 {
        let h = valve_command(valve) * self.inflow_max / self.drain;
        (h * h).min(self.height)
    }
}

/// A disturbance: an extra inflow (negative: a leak) during `[start_ms, end_ms)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Disturbance {
    pub start_ms: u64,
    pub end_ms: u64,
    /// m³/s.
    pub inflow: f64,
}

/// The default disturbance schedule, after 20 s in which a controller settles:
/// - 20 s to 25 s, an extra inflow of 0.012 m³/s, more than the drain carries at 1 m
///   (0.01 m³/s): even a closed valve cannot hold 1 m, the level climbs towards 1.44 m (a
///   controller's high-level alarm), and with the valve at 0.5 the tank overflows;
/// - 40 s to 50 s, a leak of 0.004 m³/s: holding 1 m takes the valve at 0.7, and with the
///   valve at 0.5 the level sinks towards 0.36 m.
pub const DISTURBANCES: [Disturbance; 2] = [
    Disturbance {
        start_ms: 20_000,
        end_ms: 25_000,
        inflow: 0.012,
    },
    Disturbance {
        start_ms: 40_000,
        end_ms: 50_000,
        inflow: -0.004,
    },
];

/// A valve command as the model uses it: 0..=1, and closed for NaN or infinity.
pub fn valve_command(valve: f64) -> f64 {
    if valve.is_finite() {
        valve.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// The number in a port message: exactly 8 bytes, little-endian `f64` (any bit pattern,
/// NaN included); `None` for any other length.
pub fn decode(message: &[u8]) -> Option<f64> {
    let bytes: [u8; 8] = message.try_into().ok()?;
    Some(f64::from_le_bytes(bytes))
}

/// The port message carrying `value`.
pub fn encode(value: f64) -> [u8; 8] {
    value.to_le_bytes()
}

/// Square root by Newton's method (`core` has none on stable): within one unit in the
/// last place of the exact root for every non-negative finite input; 0 for anything else.
pub fn sqrt(x: f64) -> f64 {
    if !x.is_finite() || x <= 0.0 {
        return 0.0;
    }
    // Start from a power of two near the root (halve the exponent), then iterate.
    let bits = x.to_bits();
    let mut r = f64::from_bits((bits >> 1) + (0x3ff << 51));
    for _ in 0..8 {
        let next = 0.5 * (r + x / r);
        if next == r {
            break;
        }
        r = next;
    }
    r
}

/// The simulation state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plant {
    pub tank: Tank,
    /// Level (m).
    pub level: f64,
    /// Simulated time (ms).
    pub time_ms: u64,
    /// Step length (ms).
    pub step_ms: u64,
    /// Steps at which the tank was full and the inflow spilled over.
    pub overflows: u64,
    /// Steps run with a NaN or infinite command (treated as closed).
    pub bad_commands: u64,
    /// Volume that came in (m³): valve and disturbances (a leak counts negative).
    pub volume_in: f64,
    /// Volume that left through the drain (m³).
    pub volume_out: f64,
    /// Volume that spilled over the top (m³).
    pub spilled: f64,
    disturbances: &'static [Disturbance],
}

impl Plant {
    /// A tank at `level` at time 0, stepping `step_ms` at a time through `disturbances`.
    pub const fn new(
        tank: Tank,
        level: f64,
        step_ms: u64,
        disturbances: &'static [Disturbance],
    ) -> Self {
        Plant {
            tank,
            level,
            time_ms: 0,
            step_ms,
            overflows: 0,
            bad_commands: 0,
            volume_in: 0.0,
            volume_out: 0.0,
            spilled: 0.0,
            disturbances,
        }
    }

    /// The disturbances active now.
    fn active(&self) -> impl Iterator<Item = &Disturbance> {
        let now = self.time_ms;
        self.disturbances
            .iter()
            .filter(move |d| (d.start_ms..d.end_ms).contains(&now))
    }

    /// The extra inflow of the disturbances active now (m³/s).
    pub fn disturbance(&self) -> f64 {
        self.active().map(|d| d.inflow).sum()
    }

    /// Whether a disturbance is active now.
    pub fn disturbed(&self) -> bool {
        self.active().next().is_some()
    }

    /// Advances one step with valve command `valve`. The volumes keep the balance
    /// `area * (level - initial level) = volume_in - volume_out - spilled`: what a step
    /// would take below empty is taken off the drain's volume.
    pub fn step(&mut self, valve: f64) {
        if !valve.is_finite() {
            self.bad_commands += 1;
        }
        let t = self.tank;
        let dt = self.step_ms as f64 / 1000.0;
        let volume_in = (valve_command(valve) * t.inflow_max + self.disturbance()) * dt;
        let mut volume_out = t.drain * sqrt(self.level) * dt;
        let level = self.level + (volume_in - volume_out) / t.area;
        if level > t.height {
            self.overflows += 1;
            self.spilled += (level - t.height) * t.area;
        } else if level < 0.0 {
            volume_out += level * t.area;
        }
        self.volume_in += volume_in;
        self.volume_out += volume_out;
        self.level = level.clamp(0.0, t.height);
        self.time_ms += self.step_ms;
    }

    /// Advances `steps` steps with the same command.
    pub fn run(&mut self, valve: f64, steps: u64) {
        for _ in 0..steps {
            self.step(valve);
        }
    }
}

/// The valve command the partition applies, from the messages it reads: a fresh valid
/// message sets it; without one the last command is kept for at most [`HOLD_STEPS`] steps,
/// then the valve closes (0.0) until the next valid message.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValveInput {
    /// The command of the last valid message (as sent: may be out of range or NaN; the
    /// plant clamps and counts it).
    last: f64,
    /// Steps run since the last valid message.
    since_valid: u64,
    /// Steps run without a fresh valid message, in all.
    pub stale_steps: u64,
}

impl ValveInput {
    /// Closed until the first valid message.
    pub const fn new() -> Self {
        ValveInput {
            last: 0.0,
            since_valid: 0,
            stale_steps: 0,
        }
    }

    /// The command for the next `steps` steps, given this release's valve message: its
    /// number if it was fresh, valid and 8 bytes long, else `None`.
    pub fn command(&mut self, fresh: Option<f64>, steps: u64) -> f64 {
        match fresh {
            Some(valve) => {
                self.last = valve;
                self.since_valid = 0;
                valve
            }
            None => {
                self.stale_steps = self.stale_steps.saturating_add(steps);
                self.since_valid = self.since_valid.saturating_add(steps);
                if self.since_valid <= HOLD_STEPS {
                    self.last
                } else {
                    0.0
                }
            }
        }
    }
}

impl Default for ValveInput {
    fn default() -> Self {
        Self::new()
    }
}

/// One status line (see the module doc for the format).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Status {
    pub t_ms: u64,
    pub level: f64,
    pub valve: f64,
    pub setpoint: Option<f64>,
    pub disturbance: bool,
    pub stale: u64,
    pub bad: u64,
    pub overflow: u64,
}

impl fmt::Display for Status {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "plant: t={}ms level={:.3} valve={:.3} setpoint=",
            self.t_ms, self.level, self.valve
        )?;
        match self.setpoint {
            Some(setpoint) => write!(f, "{setpoint:.3}")?,
            None => f.write_str("-")?,
        }
        write!(
            f,
            " disturbance={} stale={} bad={} overflow={}",
            if self.disturbance { "on" } else { "off" },
            self.stale,
            self.bad,
            self.overflow
        )
    }
}

impl Status {
    /// The status line in `line` (which may carry a prefix such as the serial log's
    /// `[  1.234567] [plant] `), or `None` if it holds none or a field is malformed.
    pub fn parse(line: &str) -> Option<Status> {
        let (_, rest) = line.split_once("plant: ")?;
        let mut fields = rest.split(' ');
        let mut next = |key: &str| {
            fields
                .next()?
                .strip_prefix(key)?
                .strip_prefix('=')
                .filter(|v| !v.is_empty())
        };
        let t_ms = next("t")?.strip_suffix("ms")?.parse().ok()?;
        let level = next("level")?.parse().ok()?;
        let valve = next("valve")?.parse().ok()?;
        let setpoint = match next("setpoint")? {
            "-" => None,
            v => Some(v.parse().ok()?),
        };
        let disturbance = match next("disturbance")? {
            "on" => true,
            "off" => false,
            _ => return None,
        };
        let stale = next("stale")?.parse().ok()?;
        let bad = next("bad")?.parse().ok()?;
        let overflow = next("overflow")?.parse().ok()?;
        if fields.next().is_some() {
            return None;
        }
        Some(Status {
            t_ms,
            level,
            valve,
            setpoint,
            disturbance,
            stale,
            bad,
            overflow,
        })
    }
}

/// What the plant partition does at each release: the default tank, empty at time 0,
/// with the default disturbances, its valve input and its status-line schedule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Simulator {
    pub plant: Plant,
    pub valve: ValveInput,
    next_status_ms: u64,
}

impl Simulator {
    pub const fn new() -> Self {
        Simulator {
            plant: Plant::new(Tank::DEFAULT, 0.0, STEP_MS, &DISTURBANCES),
            valve: ValveInput::new(),
            next_status_ms: 0,
        }
    }

    /// One release: applies the valve message (`fresh`, see [`ValveInput::command`]) for
    /// `steps` steps and returns the status line if one is due; `setpoint` is only shown.
    pub fn release(
        &mut self,
        fresh: Option<f64>,
        setpoint: Option<f64>,
        steps: u64,
    ) -> Option<Status> {
        let command = self.valve.command(fresh, steps);
        self.plant.run(command, steps);
        let p = &self.plant;
        if p.time_ms < self.next_status_ms {
            return None;
        }
        self.next_status_ms = (p.time_ms / STATUS_EVERY_MS + 1) * STATUS_EVERY_MS;
        Some(Status {
            t_ms: p.time_ms,
            level: p.level,
            valve: valve_command(command),
            setpoint: setpoint.filter(|s| s.is_finite()),
            disturbance: p.disturbed(),
            stale: self.valve.stale_steps,
            bad: p.bad_commands,
            overflow: p.overflows,
        })
    }
}

impl Default for Simulator {
    fn default() -> Self {
        Self::new()
    }
}

/// Steps per release of a partition with period `period_ns` (at least one; a period that
/// is not a whole number of steps loses the remainder: simulated time then runs slow).
pub fn steps_per_release(period_ns: u64) -> u64 {
    (period_ns / (STEP_MS * 1_000_000)).max(1)
}

#[cfg(test)]
mod tests;
