//! `plc-bench`: the interpreter's leg of the soft-PLC benchmark suite (`plc-bench-suite`):
//! compiles each program, checks that the VM computes what the hand-written Rust reference
//! computes, and measures both. Prints three lines per program (`bench plc_vm_<name>`, ns per
//! cycle, `bench plc_vm_<name>_ratio`, over the reference, and `bench plc_rust_<name>`, the
//! reference's ns per cycle):
//! `bench <name> median=<n> min=<n> max=<n> unit=<ns|ratio> samples=<n>`.

use std::hint::black_box;

use plc_bench_suite::{Program, check_outputs, measure, measure_reference, number, report};
use plc_compiler::run::{CALL_FRAMES, STACK_CELLS, TRY_FRAMES};
use plc_compiler::{Options, compile};
use plc_vm::image::Image;
use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame};

/// The program's samples on the VM, after checking its outputs against the reference's.
fn bench_vm(program: &Program, reference: &[f64]) -> Result<Vec<f64>, String> {
    let (c, _) = compile(
        &[(program.file.to_string(), program.source.to_string())],
        &Options::default(),
    )
    .map_err(|(d, map)| {
        format!(
            "bench program does not compile:\n{}",
            plc_compiler::diagnostics::render(&map, &d, false)
        )
    })?;
    let image = Image::parse(&c.image).map_err(|e| e.to_string())?;
    let verified = plc_vm::verify::verify(&image).map_err(|e| e.to_string())?;
    let mut data = vec![0u8; image.data_size() as usize];
    let mut stack = vec![0u64; STACK_CELLS];
    let mut calls = vec![CallFrame::EMPTY; CALL_FRAMES];
    let mut tries = vec![TryFrame::EMPTY; TRY_FRAMES];
    let memory = Memory {
        data: &mut data,
        stack: &mut stack,
        calls: &mut calls,
        tries: &mut tries,
    };
    let mut m = Machine::new(verified, memory).map_err(|e| format!("{e:?}"))?;
    let mut now = 0i64;
    let mut instructions = 0;
    for _ in 0..program.cycles {
        now += 10_000_000;
        instructions = m
            .run_cycle(0, now)
            .map_err(|f| format!("{}: trap {}", program.file, f.trap))?
            .instructions;
    }
    check_outputs(program, reference, |name| {
        m.read_var(name).ok().map(|v| number(&v))
    })?;
    // Diagnostic only (stdout carries exactly the metric lines).
    eprintln!(
        "plc-bench: {}: {instructions} VM instructions per cycle",
        program.name
    );
    Ok(measure(
        || {
            now += 10_000_000;
            let _ = m.run_cycle(0, black_box(now));
        },
        program.cycles,
    ))
}

fn main() {
    let mut failed = false;
    for program in plc_bench_suite::selected() {
        let (reference, outputs) = measure_reference(program, program.cycles);
        match bench_vm(program, &outputs) {
            Ok(vm) => {
                for line in report("vm", program.name, &vm, &reference) {
                    println!("{line}");
                }
                println!(
                    "{}",
                    plc_bench_suite::metric_line("rust", program.name, &reference)
                );
            }
            Err(e) => {
                eprintln!("plc-bench: {e}");
                failed = true;
            }
        }
    }
    if failed {
        std::process::exit(1);
    }
}
