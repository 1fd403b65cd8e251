use super::*;

const T: Tank = Tank::DEFAULT;

fn empty() -> Plant {
    Plant::new(T, 0.0, STEP_MS, &[])
}

/// Distance in units in the last place.
fn ulps(a: f64, b: f64) -> u64 {
    a.to_bits().abs_diff(b.to_bits())
}

#[test]
fn sqrt_is_within_one_ulp_of_std() {
    let mut x = 1e-300;
    while x < 1e300 {
        for v in [x, x * 1.1, x * 2.7, x * 3.9] {
            assert!(
                ulps(sqrt(v), v.sqrt()) <= 1,
                "{v}: {} vs {}",
                sqrt(v),
                v.sqrt()
            );
        }
        x *= 7.3;
    }
    for i in 1..20_000 {
        let v = i as f64 * 1e-4;
        assert!(ulps(sqrt(v), v.sqrt()) <= 1, "{v}");
    }
    assert_eq!(sqrt(1.0), 1.0);
    assert_eq!(sqrt(4.0), 2.0);
    assert_eq!(sqrt(0.0), 0.0);
    assert_eq!(sqrt(-1.0), 0.0);
    assert_eq!(sqrt(f64::NAN), 0.0);
    assert_eq!(sqrt(f64::INFINITY), 0.0);
}

#[test]
fn a_held_valve_settles_at_the_analytic_level() {
    assert_eq!(T.steady_level(0.5), 1.0);
    for valve in [0.25, 0.5, 0.7] {
        let mut p = empty();
        p.run(valve, 60_000);
        // h = (v q_max / k)^2, from q_in = q_out at rest.
        let want = (valve * T.inflow_max / T.drain).powi(2);
        assert!((T.steady_level(valve) - want).abs() < 1e-12);
        assert!(
            (p.level - want).abs() < 1e-6,
            "{valve}: {} vs {want}",
            p.level
        );
        assert_eq!(p.overflows, 0);
    }
    assert_eq!(T.steady_level(1.0), T.height, "above the top: full");
}

#[test]
fn the_default_constants_fill_and_empty_in_seconds() {
    let mut p = empty();
    p.run(1.0, 2_000);
    assert!(p.level < T.height, "not full after 2 s: {}", p.level);
    p.run(1.0, 100);
    assert_eq!(p.level, T.height, "full after 2.1 s");
    let mut q = Plant::new(T, T.height, STEP_MS, &[]);
    q.run(0.0, 2_700);
    assert!(q.level > 0.0, "not empty after 2.7 s");
    q.run(0.0, 200);
    assert_eq!(q.level, 0.0, "empty after 2.9 s");
}

#[test]
fn mass_balance_over_a_run() {
    // Filling, overflow, both disturbances, running dry: the volumes account for the level.
    let mut p = Plant::new(T, 0.3, STEP_MS, &DISTURBANCES);
    let mut dry = false;
    for ms in 0..60_000u64 {
        let valve = match ms {
            0..10_000 => 0.5,
            10_000..15_000 => 1.0,
            15_000..45_000 => 0.5,
            _ => 0.0,
        };
        p.step(valve);
        dry |= p.level == 0.0;
        let balance = p.volume_in - p.volume_out - p.spilled;
        assert!(
            (T.area * (p.level - 0.3) - balance).abs() < 1e-12,
            "at {ms} ms: {} vs {balance}",
            T.area * (p.level - 0.3)
        );
    }
    assert!(p.overflows > 0 && p.spilled > 0.0 && dry);
}

#[test]
fn mass_balance_of_one_step() {
    let mut p = Plant::new(T, 0.64, 10, &[]);
    p.step(0.25);
    let expected = 0.64 + (0.25 * T.inflow_max - T.drain * 0.8) / T.area * 0.01;
    assert!((p.level - expected).abs() < 1e-12);
}

#[test]
fn commands_and_level_are_clamped() {
    let (mut over, mut open) = (empty(), empty());
    for _ in 0..3_000 {
        over.step(7.0);
        open.step(1.0);
        assert_eq!(over.level.to_bits(), open.level.to_bits());
        assert!(over.level <= T.height);
    }
    assert_eq!(over.level, T.height, "full");
    assert!(over.overflows > 500, "full after about 2 s");
    let (mut under, mut closed) = (over, over);
    for _ in 0..5_000 {
        under.step(-3.0);
        closed.step(0.0);
        assert_eq!(under.level.to_bits(), closed.level.to_bits());
        assert!(under.level >= 0.0);
    }
    assert_eq!(under.level, 0.0, "empty");
    assert_eq!(valve_command(0.25), 0.25);
}

#[test]
fn nan_and_infinite_commands_close_the_valve_and_are_counted() {
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let (mut p, mut closed) = (Plant::new(T, 1.0, 1, &[]), Plant::new(T, 1.0, 1, &[]));
        p.run(bad, 100);
        closed.run(0.0, 100);
        assert_eq!(p.level.to_bits(), closed.level.to_bits());
        assert_eq!((p.bad_commands, closed.bad_commands), (100, 0));
    }
}

#[test]
fn disturbances_act_only_in_their_interval() {
    let mut p = Plant::new(T, 1.0, 1, &DISTURBANCES);
    p.run(0.5, 19_999);
    assert!(!p.disturbed());
    let steady = p.level;
    assert!((steady - 1.0).abs() < 1e-9);
    p.step(0.5);
    assert_eq!(p.level, steady, "the step that ends at 20 s is undisturbed");
    assert!(p.disturbed() && p.disturbance() == 0.012);
    p.step(0.5);
    assert!(p.level > steady);
    p.run(0.5, 4_999);
    assert_eq!(p.time_ms, 25_000);
    assert!(!p.disturbed());
    assert_eq!(p.level, T.height, "valve 0.5 plus the inflow overflows");
    let mut closed = Plant::new(T, 1.0, 1, &DISTURBANCES);
    closed.run(0.5, 20_000);
    closed.run(0.0, 5_000);
    assert!(
        closed.level > 1.3 && closed.level < 1.44,
        "{}",
        closed.level
    );
    p.run(0.5, 15_000);
    assert_eq!(p.time_ms, 40_000);
    assert!(
        p.disturbed() && p.disturbance() == -0.004,
        "the leak at 40 s"
    );
    p.run(0.5, 9_999);
    assert!(p.disturbed());
    assert!(
        (p.level - 0.36).abs() < 0.01,
        "sinking with the leak: {}",
        p.level
    );
    p.step(0.5);
    assert!(!p.disturbed());
    p.run(0.5, 30_000);
    assert!(
        (p.level - steady).abs() < 1e-6,
        "back at {steady}: {}",
        p.level
    );
}

#[test]
fn messages_are_eight_little_endian_bytes() {
    assert_eq!(encode(0.5), [0, 0, 0, 0, 0, 0, 0xe0, 0x3f]);
    for v in [0.0, 0.5, 1.0, -2.5, 1e300, f64::INFINITY] {
        assert_eq!(decode(&encode(v)), Some(v));
    }
    assert!(decode(&encode(f64::NAN)).is_some_and(f64::is_nan));
    for len in [0, 1, 7, 9, 16] {
        assert_eq!(decode(&[0; 16][..len]), None, "{len} bytes");
    }
}

#[test]
fn a_stale_command_is_held_for_hold_steps_then_the_valve_closes() {
    let mut v = ValveInput::new();
    assert_eq!(v.command(None, 10), 0.0, "closed before the first message");
    assert_eq!(v.command(Some(0.8), 10), 0.8);
    for _ in 0..HOLD_STEPS / 10 {
        assert_eq!(v.command(None, 10), 0.8, "held");
    }
    assert_eq!(v.command(None, 10), 0.0, "closed after {HOLD_STEPS} steps");
    assert_eq!(v.command(None, 10), 0.0);
    assert_eq!(
        v.command(Some(0.3), 10),
        0.3,
        "a valid message opens it again"
    );
    assert_eq!(v.stale_steps, 10 + HOLD_STEPS + 20);
    // A single release longer than the hold closes at once.
    assert_eq!(v.command(None, HOLD_STEPS + 1), 0.0);
    let mut long = ValveInput::new();
    long.command(Some(1.0), 1);
    for _ in 0..1_000 {
        long.command(None, u64::MAX / 100);
    }
    assert_eq!(long.stale_steps, u64::MAX, "saturates");
}

const LINE: &str = "plant: t=1500ms level=0.615 valve=0.500 setpoint=1.000 disturbance=off stale=0 bad=0 overflow=0";

#[test]
fn the_status_line_format() {
    let s = Status {
        t_ms: 1500,
        level: 0.61549,
        valve: 0.5,
        setpoint: Some(1.0),
        disturbance: false,
        stale: 0,
        bad: 0,
        overflow: 0,
    };
    assert_eq!(s.to_string(), LINE);
    let other = Status {
        t_ms: 20_000,
        level: 2.0,
        valve: 0.0,
        setpoint: None,
        disturbance: true,
        stale: 120,
        bad: 3,
        overflow: 4_000,
    };
    let line = "plant: t=20000ms level=2.000 valve=0.000 setpoint=- disturbance=on stale=120 bad=3 overflow=4000";
    assert_eq!(other.to_string(), line);
    assert_eq!(
        Status::parse(&format!("[  1.219451] [plant] {line}")),
        Some(other)
    );
    let parsed = Status::parse(LINE).unwrap();
    assert_eq!((parsed.level, parsed.setpoint), (0.615, Some(1.0)));
}

#[test]
fn malformed_status_lines_parse_to_none() {
    for len in 0..LINE.len() {
        assert_eq!(Status::parse(&LINE[..len]), None, "{:?}", &LINE[..len]);
    }
    for bad in [
        "plant: t=15ms level=x valve=0.5 setpoint=- disturbance=off stale=0 bad=0 overflow=0",
        "plant: t=15 level=1 valve=0.5 setpoint=- disturbance=off stale=0 bad=0 overflow=0",
        "plant: t=15ms level=1 valve=0.5 setpoint=- disturbance=maybe stale=0 bad=0 overflow=0",
        "plant: t=15ms level=1 valve=0.5 setpoint=- disturbance=off stale=-1 bad=0 overflow=0",
        "plant: t=15ms valve=0.5 level=1 setpoint=- disturbance=off stale=0 bad=0 overflow=0",
        "plant: t=15ms level=1 valve=0.5 setpoint=- disturbance=off stale=0 bad=0 overflow=0 x=1",
        "plant: t=15ms  level=1 valve=0.5 setpoint=- disturbance=off stale=0 bad=0 overflow=0",
        "plant: held",
        "\u{1F4A7} plant: t=ms",
    ] {
        assert_eq!(Status::parse(bad), None, "{bad}");
    }
}

#[test]
fn the_simulator_prints_at_the_first_release_past_each_500_ms() {
    for (steps, want) in [
        (10, &[10, 500, 1_000, 1_500, 2_000, 2_500, 3_000][..]),
        (7, &[7, 504, 1_001, 1_505, 2_002, 2_506]),
        (500, &[500, 1_000, 1_500, 2_000, 2_500, 3_000]),
        (1_000, &[1_000, 2_000, 3_000]),
    ] {
        let mut sim = Simulator::new();
        let times: Vec<u64> = (0..3_000 / steps)
            .filter_map(|_| sim.release(Some(0.5), None, steps))
            .map(|s| s.t_ms)
            .collect();
        assert_eq!(times, want, "{steps} steps per release");
    }
}

#[test]
fn the_simulator_reports_what_it_applied() {
    let mut sim = Simulator::new();
    let s = sim.release(Some(0.5), Some(1.0), 10).unwrap();
    assert_eq!(
        (s.t_ms, s.valve, s.setpoint, s.stale),
        (10, 0.5, Some(1.0), 0)
    );
    assert!(s.level > 0.0 && !s.disturbance);
    // Stale releases: held, then closed; a NaN setpoint shows as none.
    let mut last = s;
    for _ in 0..49 {
        if let Some(s) = sim.release(None, Some(f64::NAN), 10) {
            last = s;
        }
    }
    assert_eq!((last.t_ms, last.valve, last.setpoint), (500, 0.0, None));
    assert_eq!(last.stale, 490);
    // NaN and out-of-range commands: shown as applied, NaN counted per step.
    for _ in 0..50 {
        if let Some(s) = sim.release(Some(f64::NAN), None, 10) {
            last = s;
        }
    }
    assert_eq!((last.t_ms, last.valve, last.bad), (1_000, 0.0, 500));
    for _ in 0..50 {
        if let Some(s) = sim.release(Some(9.0), None, 10) {
            last = s;
        }
    }
    assert_eq!((last.valve, last.bad, last.stale), (1.0, 500, 490));
}

#[test]
fn runs_are_bit_identical() {
    let run = || {
        let mut sim = Simulator::new();
        let mut lines = Vec::new();
        for i in 0..10_000u64 {
            let fresh = match i % 13 {
                0 => None,
                1 => Some(f64::NAN),
                n => Some(n as f64 / 10.0 - 0.1),
            };
            if let Some(s) = sim.release(fresh, Some(1.0), 10) {
                lines.push(s.to_string());
            }
        }
        (sim, lines)
    };
    let (a, lines_a) = run();
    let (b, lines_b) = run();
    assert_eq!(a.plant.level.to_bits(), b.plant.level.to_bits());
    assert_eq!(a.plant.volume_out.to_bits(), b.plant.volume_out.to_bits());
    assert_eq!(lines_a, lines_b);
    assert_eq!((lines_a.len(), a.plant.time_ms), (201, 100_000));
}

#[test]
fn steps_per_release_of_a_period() {
    assert_eq!(steps_per_release(10_000_000), 10);
    assert_eq!(steps_per_release(1_500_000), 1);
    assert_eq!(steps_per_release(0), 1);
    assert_eq!(steps_per_release(u64::MAX), u64::MAX / 1_000_000);
}
