//! The IronPLC leg's timing harness (built by `plc-bench-suite`'s `ironplc` module into a
//! stand-alone crate under `target/plc-ironplc-bench/`, against the `ironplc-vm` and
//! `ironplc-container` crates of an IronPLC checkout; never part of this repository's
//! build). It times IronPLC's VM exactly as `plc-bench` times ours: a container compiled by
//! `ironplcc` runs `cycles` scan rounds of warm-up, then `samples` batches of `cycles`
//! rounds, each batch timed as a whole (ns per round), the simulated clock advancing 10 ms a
//! round so a cyclic task is due every round.
//!
//! Usage: `harness <container.iplc> <cycles> <samples> [<variable>...]`. Prints
//! `outputs <v>...` (each named variable after the warm-up, as a number; `nan` when unknown)
//! and `samples <ns>...`. A variable is a name of the program (`result`) or an element of a
//! one-dimensional array whose first index is 0 (`a[50]`): IronPLC keeps array elements in
//! 8-byte slots in its data region and the array variable holds the region offset.

use ironplc_container::debug_format::build_var_debug_map;
use ironplc_container::{Container, VarIndex};
use ironplc_vm::{Vm, VmBuffers};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        eprintln!("usage: harness <container.iplc> <cycles> <samples> [<variable>...]");
        std::process::exit(2);
    }
    let cycles: u64 = args[2].parse().expect("cycles");
    let samples: usize = args[3].parse().expect("samples");
    let mut file = std::fs::File::open(&args[1]).expect("open container");
    let container = Container::read_from(&mut file).expect("read container");
    let debug = build_var_debug_map(&container);
    let mut buffers = VmBuffers::from_container(&container);
    let mut vm = match Vm::new().load(&container, &mut buffers).start() {
        Ok(vm) => vm,
        Err(fault) => {
            eprintln!("harness: start: {:?}", fault.trap);
            std::process::exit(1);
        }
    };
    let mut now_us = 0u64;
    let mut round = |vm: &mut ironplc_vm::VmRunning<'_>| {
        now_us += 10_000;
        if let Err(fault) = vm.run_round(std::hint::black_box(now_us)) {
            eprintln!("harness: trap {:?}", fault.trap);
            std::process::exit(1);
        }
    };
    for _ in 0..cycles {
        round(&mut vm);
    }
    let value = |name: &str| -> f64 {
        let (var, element) = match name.split_once('[') {
            Some((var, rest)) => (var, rest.trim_end_matches(']').parse::<usize>().ok()),
            None => (name, None),
        };
        let Some((&index, info)) = debug
            .iter()
            .find(|(_, info)| info.name.eq_ignore_ascii_case(var))
        else {
            return f64::NAN;
        };
        let Ok(raw) = vm.read_variable_raw(VarIndex::new(index)) else {
            return f64::NAN;
        };
        let (raw, type_name) = match element {
            None => (raw, info.type_name.to_ascii_uppercase()),
            Some(k) => {
                let at = raw as usize + 8 * k;
                let Some(slot) = vm.data_region().get(at..at + 8) else {
                    return f64::NAN;
                };
                let element_type = info.type_name.to_ascii_uppercase();
                let element_type = element_type.rsplit(" OF ").next().unwrap_or("").trim();
                (
                    u64::from_le_bytes(slot.try_into().expect("8 bytes")),
                    element_type.to_string(),
                )
            }
        };
        match type_name.as_str() {
            "BOOL" => (raw & 1) as f64,
            "REAL" => f32::from_bits(raw as u32) as f64,
            "LREAL" => f64::from_bits(raw),
            "SINT" => raw as i8 as f64,
            "INT" => raw as i16 as f64,
            "DINT" => raw as i32 as f64,
            "LINT" => raw as i64 as f64,
            "USINT" | "BYTE" => raw as u8 as f64,
            "UINT" | "WORD" => raw as u16 as f64,
            "UDINT" | "DWORD" => raw as u32 as f64,
            _ => raw as f64,
        }
    };
    let outputs: Vec<String> = args[4..].iter().map(|n| format!("{}", value(n))).collect();
    println!("outputs {}", outputs.join(" "));
    let mut times = Vec::with_capacity(samples);
    for _ in 0..samples {
        let started = Instant::now();
        for _ in 0..cycles {
            round(&mut vm);
        }
        times.push(format!(
            "{:.1}",
            started.elapsed().as_nanos() as f64 / cycles as f64
        ));
    }
    println!("samples {}", times.join(" "));
}
