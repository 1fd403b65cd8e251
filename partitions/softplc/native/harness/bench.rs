//! The native tier's leg of the soft-PLC benchmark suite (`plc-bench-suite`), the program
//! `plc-native-bench` builds around the translated suite (library `programs`) and runs: for
//! each program, checks that the native code computes what the hand-written Rust reference
//! computes, measures both and prints `bench plc_native_<name>` (ns per cycle) and
//! `bench plc_native_<name>_ratio` (over the reference). The machine has the PLC
//! partition's limits (256 stack cells, 32 call frames, 16 try frames) and the default
//! instruction budget; a cycle is `Machine::run_cycle_native`, with everything the runtime
//! pays per cycle (forces, the task's fault state, the budget).

use plc_bench_suite::{check_outputs, measure, measure_reference, number, report};
use plc_vm::image::Image;
use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame};
use std::hint::black_box;

fn main() {
    let mut failed = false;
    for program in plc_bench_suite::selected() {
        let Some((_, native)) = programs::BY_NAME.iter().find(|(n, _)| *n == program.name) else {
            eprintln!("plc-native-bench: {} was not translated", program.name);
            failed = true;
            continue;
        };
        let (reference, outputs) = measure_reference(program, program.cycles);
        let image = Image::parse(native.image).expect("image");
        let verified = plc_vm::verify::verify(&image).expect("verified");
        let mut data = vec![0u8; image.data_size() as usize];
        let mut stack = vec![0u64; 256];
        let mut calls = vec![CallFrame::EMPTY; 32];
        let mut tries = vec![TryFrame::EMPTY; 16];
        let mut m = Machine::new(
            verified,
            Memory {
                data: &mut data,
                stack: &mut stack,
                calls: &mut calls,
                tries: &mut tries,
            },
        )
        .expect("machine");
        let mut now = 0i64;
        let mut broken = None;
        for _ in 0..program.cycles {
            now += 10_000_000;
            if let Err(f) = m.run_cycle_native(0, now, || false, native) {
                broken = Some(format!("{}: trap {}", program.file, f.trap));
                break;
            }
        }
        let checked = match broken {
            Some(e) => Err(e),
            None => check_outputs(program, &outputs, |name| {
                m.read_var(name).ok().map(|v| number(&v))
            }),
        };
        if let Err(e) = checked {
            eprintln!("plc-native-bench: {e}");
            failed = true;
            continue;
        }
        let samples = measure(
            || {
                now += 10_000_000;
                let _ = m.run_cycle_native(0, black_box(now), || false, native);
            },
            program.cycles,
        );
        for line in report("native", program.name, &samples, &reference) {
            println!("{line}");
        }
    }
    if failed {
        std::process::exit(1);
    }
}
