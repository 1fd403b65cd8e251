//! The plant the soft-PLC controls: a deterministic simulation of a tank whose level rises
//! with the inflow through a valve and falls with the outflow through a drain, plus a fixed
//! schedule of disturbances. Pure and `no_std` (host-tested); the partition program
//! (`main.rs`) feeds it the valve command and publishes the level over sampling ports.
//!
//! Model (SI units, explicit Euler with a fixed step): `A dh/dt = q_in - q_out + q_d`, with
//! the inflow `q_in = valve * q_max` (valve 0..1; a NaN or infinite command counts as closed),
//! the Torricelli outflow `q_out = k sqrt(h)`, and the disturbance inflow `q_d` of the
//! disturbances active at that time. The level is kept in `[0, height]`; steps that would
//! overflow are counted. With valve `v` held, the level settles at `h = (v q_max / k)^2`.
//!
//! It must stay deterministic: the trajectory depends only on the commands and the step
//! count (no clock, no floating-point function outside this file: `sqrt` is ours).
#![cfg_attr(not(test), no_std)]

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
    /// The default tank: 2 m high; the valve fully open fills it at up to 2 m/s; a held
    /// valve of 0.5 settles at 1 m with a time constant of about 2 s.
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

/// The default disturbance schedule: a strong extra inflow from 30 s to 35 s that pushes
/// the level high (the controller's high-level alarm), then a leak from 50 s to 60 s.
pub const DISTURBANCES: [Disturbance; 2] = [
    Disturbance {
        start_ms: 30_000,
        end_ms: 35_000,
        inflow: 0.015,
    },
    Disturbance {
        start_ms: 50_000,
        end_ms: 60_000,
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

/// Square root by Newton's method (`core` has none on stable): exact to the last bit or
/// one below for every non-negative finite input; 0 for anything else.
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
    /// Commands that were NaN or infinite (treated as closed).
    pub bad_commands: u64,
    disturbances: &'static [Disturbance],
}

impl Plant {
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
            disturbances,
        }
    }

    /// The extra inflow of the disturbances active now (m³/s).
    pub fn disturbance(&self) -> f64 {
        self.disturbances
            .iter()
            .filter(|d| (d.start_ms..d.end_ms).contains(&self.time_ms))
            .map(|d| d.inflow)
            .sum()
    }

    /// Advances one step with valve command `valve`.
    pub fn step(&mut self, valve: f64) {
        if !valve.is_finite() {
            self.bad_commands += 1;
        }
        let t = &self.tank;
        let inflow = valve_command(valve) * t.inflow_max + self.disturbance();
        let outflow = t.drain * sqrt(self.level);
        let dt = self.step_ms as f64 / 1000.0;
        let level = self.level + (inflow - outflow) / t.area * dt;
        if level > t.height {
            self.overflows += 1;
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn plant() -> Plant {
        Plant::new(Tank::DEFAULT, 0.0, 1, &[])
    }

    #[test]
    fn sqrt_matches_std() {
        for x in [1e-300, 1e-9, 0.25, 1.0, 2.0, 3.0, 10.0, 12345.678, 1e300] {
            let (ours, std) = (sqrt(x), x.sqrt());
            assert!(
                (ours - std).abs() <= std * 2.0 * f64::EPSILON,
                "{x}: {ours} vs {std}"
            );
        }
        assert_eq!(sqrt(0.0), 0.0);
        assert_eq!(sqrt(-1.0), 0.0);
        assert_eq!(sqrt(f64::NAN), 0.0);
        assert_eq!(sqrt(f64::INFINITY), 0.0);
    }

    #[test]
    fn a_held_valve_settles_at_the_analytic_level() {
        let mut p = plant();
        p.run(0.5, 30_000);
        let want = Tank::DEFAULT.steady_level(0.5);
        assert!((want - 1.0).abs() < 1e-12);
        assert!((p.level - want).abs() < 1e-3, "{} vs {want}", p.level);
        assert_eq!(p.overflows, 0);
    }

    #[test]
    fn a_closed_valve_drains_the_tank() {
        let mut p = Plant::new(Tank::DEFAULT, 1.5, 1, &[]);
        p.run(0.0, 60_000);
        assert!(p.level < 0.01, "{}", p.level);
    }

    #[test]
    fn mass_balance_over_one_step() {
        let mut p = Plant::new(Tank::DEFAULT, 0.64, 10, &[]);
        let before = p.level;
        p.step(0.25);
        let t = Tank::DEFAULT;
        let expected = before + (0.25 * t.inflow_max - t.drain * 0.8) / t.area * 0.01;
        assert!((p.level - expected).abs() < 1e-12);
    }

    #[test]
    fn commands_and_level_are_clamped() {
        let mut p = plant();
        p.run(7.0, 5_000);
        assert_eq!(p.level, Tank::DEFAULT.height, "full");
        assert!(p.overflows > 0);
        let mut q = plant();
        q.run(f64::NAN, 100);
        assert_eq!((q.level, q.bad_commands), (0.0, 100));
        q.run(-3.0, 100);
        assert_eq!(q.level, 0.0);
    }

    #[test]
    fn disturbances_act_only_in_their_interval() {
        let mut p = Plant::new(Tank::DEFAULT, 1.0, 1, &DISTURBANCES);
        p.run(0.5, 29_999);
        assert_eq!(p.disturbance(), 0.0);
        let steady = p.level;
        p.run(0.5, 2);
        assert!(p.disturbance() > 0.0);
        p.run(0.5, 4_998);
        assert!(p.level > steady + 0.3, "pushed high: {}", p.level);
        p.run(0.5, 15_001);
        assert_eq!(p.time_ms, 50_000);
        assert!(p.disturbance() < 0.0, "the leak at 50 s");
        p.run(0.5, 40_000);
        assert!(
            (p.level - steady).abs() < 1e-3,
            "back at {steady}: {}",
            p.level
        );
    }

    #[test]
    fn runs_are_bit_identical() {
        let mut a = Plant::new(Tank::DEFAULT, 0.3, 10, &DISTURBANCES);
        let mut b = a;
        for i in 0..10_000u64 {
            let valve = (i % 7) as f64 / 6.0;
            a.step(valve);
            b.step(valve);
        }
        assert_eq!(a.level.to_bits(), b.level.to_bits());
    }
}
