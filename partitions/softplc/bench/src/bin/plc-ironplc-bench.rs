//! `plc-ironplc-bench`: the IronPLC leg of the soft-PLC benchmark suite (see
//! `plc_bench_suite::ironplc`): with `IRONPLC` set, compiles each program with IronPLC's
//! `ironplcc`, checks that IronPLC's VM computes what the Rust reference computes, and
//! measures both. Prints two lines per program (`bench plc_ironplc_<name>`, ns per cycle,
//! and `bench plc_ironplc_<name>_ratio`, over the reference), the line format of
//! `cargo xtask bench`. Without `IRONPLC`, and for a program ironplcc does not accept or
//! IronPLC computes differently, it says `skipped: <why>` on stderr and prints no metric.

use plc_bench_suite::ironplc::IronPlc;
use plc_bench_suite::{check_outputs, measure_reference, report};

fn main() {
    let ironplc = match IronPlc::from_env() {
        Ok(Some(ironplc)) => ironplc,
        Ok(None) => {
            eprintln!(
                "plc-ironplc-bench: skipped: IRONPLC is not set (an IronPLC checkout, or the ironplcc built in one)"
            );
            return;
        }
        Err(e) => {
            eprintln!("plc-ironplc-bench: {e}");
            std::process::exit(1);
        }
    };
    for program in plc_bench_suite::selected() {
        let container = match ironplc.compile(program) {
            Ok(container) => container,
            Err(e) => {
                eprintln!("plc-ironplc-bench: {}: skipped: {e}", program.file);
                continue;
            }
        };
        let (reference, outputs) = measure_reference(program, program.cycles);
        let run = match ironplc.run(&container, program) {
            Ok(run) => run,
            Err(e) => {
                eprintln!("plc-ironplc-bench: {}: skipped: {e}", program.file);
                continue;
            }
        };
        let checked = check_outputs(program, &outputs, |name| {
            let at = program.outputs.iter().position(|n| *n == name)?;
            run.outputs.get(at).copied().filter(|v| !v.is_nan())
        });
        if let Err(e) = checked {
            eprintln!(
                "plc-ironplc-bench: {}: skipped: on IronPLC {e}",
                program.file
            );
            continue;
        }
        for line in report("ironplc", program.name, &run.samples, &reference) {
            println!("{line}");
        }
    }
}
