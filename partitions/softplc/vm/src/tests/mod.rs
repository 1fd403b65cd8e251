//! In-crate tests (they need the builder and the model, which are compiled for tests).

pub(crate) mod differential;
mod dispatch;
mod fuzz;
mod library;
mod ops;
mod refs;
mod traps;
mod verifier;

use crate::image::{Image, ImageBuilder, PouId, TaskDef, TaskKind};
use crate::model::{Model, ModelCycle};
use crate::verify::verify;
use crate::vm::{CallFrame, CycleStats, Fault, Machine, Memory, TryFrame};
use alloc::vec;
use alloc::vec::Vec;

/// The test programs' data layout and the test machines' limits (shared with the
/// differential tests of other tiers).
pub use crate::testgen::{CALLS, DATA, MAIN_BASE, MAIN_FRAME, STACK, TRIES};
/// Address `eval` stores its result at.
pub const RESULT: u32 = 0;

/// A builder with data memory, one program POU "Main" and a task running it; `body`
/// emits Main's code (a RET is appended).
pub fn program_with(budget: u32, body: impl FnOnce(&mut ImageBuilder, PouId)) -> Vec<u8> {
    let mut b = ImageBuilder::new();
    b.reserve_data(DATA);
    let main = b.declare_pou("Main", 0, 0, MAIN_FRAME);
    b.add_task(&TaskDef {
        name: "T".into(),
        kind: TaskKind::Cyclic,
        priority: 0,
        pou: main,
        instance_base: MAIN_BASE,
        interval_ns: 10_000_000,
        watchdog_budget: budget,
    });
    b.begin_pou(main);
    body(&mut b, main);
    b.ret();
    b.end_pou(main);
    b.build().expect("build")
}

/// Outcome of running a program on both the VM and the model (asserted equal).
pub struct Outcome {
    pub result: Result<CycleStats, Fault>,
    pub data: Vec<u8>,
    pub stack: Vec<u64>,
}

/// Memory for one machine of [`STACK`] cells, [`CALLS`] call and [`TRIES`] try frames.
pub struct VmMemory {
    data: Vec<u8>,
    stack: [u64; STACK],
    calls: [CallFrame; CALLS],
    tries: [TryFrame; TRIES],
}

impl VmMemory {
    /// Memory for `bytes`' image (its data size).
    pub fn for_image(bytes: &[u8]) -> Self {
        let image = Image::parse(bytes).expect("parse");
        Self {
            data: vec![0u8; image.data_size() as usize],
            stack: [0; STACK],
            calls: [CallFrame::EMPTY; CALLS],
            tries: [TryFrame::EMPTY; TRIES],
        }
    }

    /// A machine running the verified `bytes` in this memory.
    pub fn machine<'a>(&'a mut self, bytes: &'a [u8]) -> Machine<'a, 'a> {
        let image = Image::parse(bytes).expect("parse");
        let verified = verify(&image).unwrap_or_else(|e| panic!("verify: {e}"));
        Machine::new(
            verified,
            Memory {
                data: &mut self.data,
                stack: &mut self.stack,
                calls: &mut self.calls,
                tries: &mut self.tries,
            },
        )
        .expect("machine")
    }
}

/// Runs `cycles` cycles of task 0 on the VM and the model, asserting identical state after
/// every cycle; returns the last cycle's outcome.
pub fn run_both(bytes: &[u8], cycles: usize) -> Outcome {
    let image = Image::parse(bytes).expect("parse");
    let verified = verify(&image).unwrap_or_else(|e| panic!("verify: {e}"));
    let mut data = vec![0u8; image.data_size() as usize];
    let mut stack = [0u64; STACK];
    let mut calls = [CallFrame::EMPTY; CALLS];
    let mut tries = [TryFrame::EMPTY; TRIES];
    let mut vm = Machine::new(
        verified,
        Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        },
    )
    .expect("machine");
    let mut model = Model::new(&verified, STACK, CALLS, TRIES);
    let mut last = None;
    for cycle in 0..cycles {
        let now = cycle as i64 * 10_000_000;
        let result = vm.run_cycle(0, now);
        let expected = model.run_cycle(0, now, None);
        compare(&vm, &model, &result, &expected);
        last = Some(result);
    }
    Outcome {
        result: last.expect("at least one cycle"),
        data: vm.data().to_vec(),
        stack: vm.stack().to_vec(),
    }
}

/// Asserts VM and model agree on a cycle's result and the complete state.
pub fn compare(
    vm: &Machine<'_, '_>,
    model: &Model<'_>,
    result: &Result<CycleStats, Fault>,
    expected: &ModelCycle,
) {
    match (result, expected) {
        (
            Ok(stats),
            ModelCycle::Completed {
                instructions,
                caught,
            },
        ) => {
            assert_eq!(stats.instructions, *instructions, "instruction count");
            assert_eq!(stats.caught_traps, *caught, "caught traps");
        }
        (Err(fault), ModelCycle::Faulted { trap, pc }) if !fault.refused => {
            assert_eq!(fault.trap, *trap, "trap");
            assert_eq!(fault.code_offset, *pc, "trap pc");
        }
        (Err(fault), ModelCycle::Refused) if fault.refused => {}
        other => panic!("VM and model disagree: {other:?}"),
    }
    assert_eq!(vm.data(), model.data(), "data memory");
    assert_eq!(vm.stack(), model.stack(), "operand stack");
    assert_eq!(vm.pc(), model.pc(), "pc");
    assert_eq!(vm.call_depth(), model.call_depth(), "call depth");
    assert_eq!(vm.try_depth(), model.try_depth(), "try depth");
}

/// Evaluates `body` (which must push exactly one cell), stores it at RESULT and returns it.
pub fn eval(body: impl FnOnce(&mut ImageBuilder)) -> u64 {
    let bytes = program_with(10_000, |b, _| {
        body(b);
        b.st_abs(crate::isa::MemType::U64, RESULT);
    });
    let out = run_both(&bytes, 1);
    if let Err(fault) = out.result {
        panic!("unexpected trap {}", fault.trap);
    }
    u64::from_le_bytes(
        out.data[RESULT as usize..RESULT as usize + 8]
            .try_into()
            .unwrap(),
    )
}

/// Runs `body` (net stack effect 0 apart from the trap) and returns the uncaught trap.
pub fn trap_of(body: impl FnOnce(&mut ImageBuilder)) -> Fault {
    let bytes = program_with(10_000, |b, _| {
        body(b);
    });
    match run_both(&bytes, 1).result {
        Err(fault) => fault,
        Ok(_) => panic!("expected a trap"),
    }
}
