//! The soft-PLC benchmark suite: Structured Text programs (`programs/*.st`: the PID over
//! arrays, bubble sort, string building, and our own programs of the algorithms of the
//! public IronPLC benchmark suite) with the same algorithm hand-written in Rust
//! ([`Reference`]), which every execution tier is compared with, and the measuring and
//! reporting both legs share.
//!
//! A leg (the interpreter: `plc-bench` in `plc-compiler`; the native tier:
//! `plc-native-bench` in `plc-native`; IronPLC's VM: `plc-ironplc-bench` here, see
//! [`ironplc`]) compiles each [`Program`], runs it, checks that it
//! computes what its reference computes ([`Program::outputs`], [`check_outputs`]), measures
//! both with [`measure`] and prints [`report`]'s two lines per program:
//! `bench plc_<tier>_<name>` (ns per cycle) and `bench plc_<tier>_<name>_ratio` (its cycle
//! time over the reference's, sample by sample). A new leg (another tier, another PLC)
//! only needs a way to run a cycle.

use plc_vm::vm::Value;
use std::hint::black_box;
use std::time::Instant;

pub mod ironplc;
mod reference;

/// Samples per metric (unless the environment variable `PLC_BENCH_SAMPLES` says otherwise,
/// e.g. 1 for a run under `valgrind --tool=callgrind`).
pub const SAMPLES: usize = 25;

/// The samples per metric: `PLC_BENCH_SAMPLES` or [`SAMPLES`].
pub fn samples() -> usize {
    std::env::var("PLC_BENCH_SAMPLES")
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|&n| n > 0)
        .unwrap_or(SAMPLES)
}

/// A hand-written Rust implementation of a program's algorithm: its state and one cycle.
pub trait Reference {
    /// One cycle (the program's body once).
    fn cycle(&mut self);
    /// The values of [`Program::outputs`], in that order.
    fn outputs(&self) -> Vec<f64>;
}

/// One benchmark program.
pub struct Program {
    /// The metric's name part: `plc_<tier>_<name>`.
    pub name: &'static str,
    /// File name (for diagnostics).
    pub file: &'static str,
    /// The ST source (one PROGRAM, run by one task).
    pub source: &'static str,
    /// Cycles per sample.
    pub cycles: u32,
    /// Variables (monitor names) that must equal the reference's outputs after the warm-up.
    pub outputs: &'static [&'static str],
    /// A fresh reference state.
    pub reference: fn() -> Box<dyn Reference>,
}

macro_rules! program {
    ($name:literal, $cycles:expr, [$($out:literal),*], $reference:expr) => {
        Program {
            name: $name,
            file: concat!($name, ".st"),
            source: include_str!(concat!("../programs/", $name, ".st")),
            cycles: $cycles,
            outputs: &[$($out),*],
            reference: || Box::new($reference),
        }
    };
}

/// The suite, in report order.
pub const PROGRAMS: &[Program] = &[
    program!(
        "pid",
        200,
        ["Pid.out[0]", "Pid.pv[99]", "Pid.integ[5]"],
        reference::Pid::default()
    ),
    program!(
        "bubble_sort",
        20,
        [
            "BubbleSort.a[0]",
            "BubbleSort.a[50]",
            "BubbleSort.a[99]",
            "BubbleSort.seed"
        ],
        reference::BubbleSort::default()
    ),
    program!(
        "string",
        200,
        ["StringBuild.n"],
        reference::StringBuild::default()
    ),
    program!(
        "arithmetic",
        2000,
        [
            "Arithmetic.sum",
            "Arithmetic.difference",
            "Arithmetic.product",
            "Arithmetic.quotient",
            "Arithmetic.remainder"
        ],
        reference::Arithmetic::default()
    ),
    program!(
        "blinky",
        2000,
        ["Blinky.lamp"],
        reference::Blinky::default()
    ),
    program!(
        "case_state",
        2000,
        [
            "CaseState.step",
            "CaseState.fill",
            "CaseState.heat",
            "CaseState.stir",
            "CaseState.drain"
        ],
        reference::CaseState::default()
    ),
    program!(
        "counter_up",
        2000,
        ["CounterUp.ticks", "CounterUp.wrapped"],
        reference::CounterUp::default()
    ),
    program!(
        "for_loop",
        1000,
        ["ForLoop.total"],
        reference::ForLoop::default()
    ),
    program!("binom", 1000, ["Binom.result"], reference::Binom::default()),
    program!("expn", 1000, ["Expn.result"], reference::Expn::default()),
    program!("fib", 1000, ["Fib.result"], reference::Fib::default()),
    program!("gcd", 1000, ["Gcd.result"], reference::Gcd::default()),
    program!(
        "lambert_w",
        500,
        ["Lambert.result"],
        reference::Lambert::default()
    ),
    program!(
        "linear_int",
        1000,
        ["LinearInt.result"],
        reference::LinearInt::default()
    ),
    program!(
        "polynom_int",
        1000,
        ["PolynomInt.result"],
        reference::PolynomInt::default()
    ),
    program!(
        "real_to_frac",
        1000,
        ["RealToFrac.num", "RealToFrac.den"],
        reference::RealToFrac::default()
    ),
];

/// The programs to run: all of [`PROGRAMS`], or those whose name contains the text of the
/// environment variable `PLC_BENCH_FILTER`.
pub fn selected() -> impl Iterator<Item = &'static Program> {
    let filter = std::env::var("PLC_BENCH_FILTER").unwrap_or_default();
    PROGRAMS
        .iter()
        .filter(move |p| p.name.contains(filter.as_str()))
}

/// `samples` measurements of `cycle` in ns per cycle, `cycles` cycles each, after as many
/// cycles of warm-up.
pub fn measure(mut cycle: impl FnMut(), cycles: u32) -> Vec<f64> {
    for _ in 0..cycles {
        cycle();
    }
    (0..samples())
        .map(|_| {
            let t = Instant::now();
            for _ in 0..cycles {
                cycle();
            }
            t.elapsed().as_nanos() as f64 / cycles as f64
        })
        .collect()
}

/// Measures `program`'s reference (after `warm_up` cycles, the count the PLC leg ran before
/// it compared outputs) and returns its samples and its outputs at that point.
pub fn measure_reference(program: &Program, warm_up: u32) -> (Vec<f64>, Vec<f64>) {
    let mut state = (program.reference)();
    for _ in 0..warm_up {
        black_box(&mut state).cycle();
    }
    let outputs = state.outputs();
    let samples = measure(|| black_box(&mut state).cycle(), program.cycles);
    (samples, outputs)
}

/// A monitor value as a number (TRUE = 1).
pub fn number(value: &Value<'_>) -> f64 {
    match *value {
        Value::Bool(b) => b as u8 as f64,
        Value::Int(v) | Value::Time(v) => v as f64,
        Value::UInt(v) => v as f64,
        Value::Real(v) => v as f64,
        Value::LReal(v) => v,
        Value::String(s) => s.len() as f64,
        Value::Temporal(_, v) => v as f64,
        Value::Char(c) => c as f64,
        Value::WChar(c) => c as f64,
        Value::WString(units) => (units.len() / 2) as f64,
        Value::Ref { address, .. } => address.map_or(0.0, |a| a as f64),
    }
}

/// `Err` naming the first output whose PLC value (`read(name)`) differs from the
/// reference's.
pub fn check_outputs(
    program: &Program,
    reference: &[f64],
    mut read: impl FnMut(&str) -> Option<f64>,
) -> Result<(), String> {
    for (name, want) in program.outputs.iter().zip(reference) {
        match read(name) {
            Some(got) if got == *want => {}
            Some(got) => {
                return Err(format!(
                    "{}: {name} = {got} but the Rust reference computes {want}",
                    program.file
                ));
            }
            None => return Err(format!("{}: no variable {name}", program.file)),
        }
    }
    Ok(())
}

/// (median, min, max).
pub fn stats(v: &[f64]) -> (f64, f64, f64) {
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    (s[s.len() / 2], s[0], s[s.len() - 1])
}

/// `bench plc_<tier>_<name>` for ns-per-cycle `samples` (median, min, max).
pub fn metric_line(tier: &str, name: &str, samples: &[f64]) -> String {
    let (med, min, max) = stats(samples);
    format!(
        "bench plc_{tier}_{name} median={med:.1} min={min:.1} max={max:.1} unit=ns samples={}",
        samples.len()
    )
}

/// The two lines of a program on a tier: `bench plc_<tier>_<name>` (ns per cycle) and
/// `bench plc_<tier>_<name>_ratio` (over the reference, sample by sample).
pub fn report(tier: &str, name: &str, plc: &[f64], reference: &[f64]) -> [String; 2] {
    let time = metric_line(tier, name, plc);
    let ratios: Vec<f64> = plc
        .iter()
        .zip(reference)
        .map(|(a, b)| a / b.max(0.001))
        .collect();
    let (med, min, max) = stats(&ratios);
    let ratio = format!(
        "bench plc_{tier}_{name}_ratio median={med:.2} min={min:.2} max={max:.2} unit=ratio samples={}",
        ratios.len()
    );
    [time, ratio]
}
