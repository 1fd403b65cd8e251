//! Differential test on generated programs: random well-typed ST programs (integer, REAL,
//! BOOL, arrays, bit access, dates and times, references with pointer arithmetic, method
//! calls through an interface on two classes, IF/CASE/FOR/__TRY, possible traps) must
//! compile, and the VM and the VM's
//! reference model must agree on the complete data memory, stack and outcome after every
//! cycle.

use plc_compiler::run::{CALL_FRAMES, STACK_CELLS, TRY_FRAMES};
use plc_compiler::{Options, compile};
use plc_vm::image::Image;
use plc_vm::model::{Model, ModelCycle};
use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame};

#[path = "support/random_st.rs"]
mod random_st;

use random_st::program;

/// Runs one generated program on both machines; returns the uncaught trap that ended it,
/// if one did.
fn run_both(seed: u64) -> Result<Option<plc_vm::isa::Trap>, String> {
    let src = program(seed);
    let (c, _) =
        compile(&[("gen.st".into(), src.clone())], &Options::default()).map_err(|(d, m)| {
            format!(
                "seed {seed}: generated program rejected:\n{}\n{src}",
                plc_compiler::diagnostics::render(&m, &d, false)
            )
        })?;
    let image = Image::parse(&c.image).unwrap();
    let verified = plc_vm::verify::verify(&image).unwrap();
    let mut model = Model::new(&verified, STACK_CELLS, CALL_FRAMES, TRY_FRAMES);
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
    let mut vm = Machine::new(verified, memory).unwrap();
    for k in 0..4i64 {
        let now = k * 10_000_000;
        let a = vm.run_cycle(0, now);
        let b = model.run_cycle(0, now, None);
        let same = match (&a, &b) {
            (
                Ok(s),
                ModelCycle::Completed {
                    instructions,
                    caught,
                },
            ) => s.instructions == *instructions && s.caught_traps == *caught,
            (Err(f), ModelCycle::Faulted { trap, pc }) => f.trap == *trap && f.code_offset == *pc,
            _ => false,
        };
        if !same || vm.data() != model.data() || vm.stack() != model.stack() {
            return Err(format!(
                "seed {seed} cycle {k}: VM {a:?} vs model {b:?} (data equal: {})\n{src}",
                vm.data() == model.data()
            ));
        }
        if let Err(f) = a {
            return Ok(Some(f.trap));
        }
    }
    Ok(None)
}

#[test]
fn vm_and_model_agree_on_generated_programs() {
    let cases: u64 = std::env::var("PLC_RANDOM_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1000);
    let mut invalid_references = 0;
    let mut completed = 0;
    for seed in 0..cases {
        match run_both(seed) {
            Err(e) => panic!("{e}"),
            Ok(Some(plc_vm::isa::Trap::InvalidReference)) => invalid_references += 1,
            Ok(None) => completed += 1,
            Ok(Some(_)) => {}
        }
    }
    // The generator reaches both checked references and dynamic calls that fail.
    assert!(
        invalid_references * 100 >= cases && completed * 4 >= cases,
        "{invalid_references} INVALID_REFERENCE, {completed} completed of {cases}"
    );
}
