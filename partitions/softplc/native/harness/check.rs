//! The program of the native tier's differential test (`tests/differential.rs` writes it,
//! with the case table in `programs.rs` and the translated cases in the libraries
//! `cases_<k>`, into a workspace under `target/` and runs it).
//!
//! Every case is an image, its translation, the machine's limits, data-memory patches applied
//! before the first cycle, and a list of task activations. Three passes per case:
//! 1. native vs the reference model: the complete state (result, instruction and catch
//!    counts, data memory, operand stack, pc, call and try depth) after every activation;
//! 2. native vs model vs VM with an instruction budget that varies per activation (watchdogs
//!    at every kind of instruction position);
//! 3. native vs VM with a deadline check that says "expired" at the n-th question (the model
//!    has no clock): the DEADLINE trap at the same instruction.
//!
//! Prints `FAIL <case>: <what>` per failing case and a summary line, exits 1 on any failure.

#![allow(clippy::all)]

mod programs;

use plc_vm::image::Image;
use plc_vm::isa::Trap;
use plc_vm::model::{Model, ModelCycle};
use plc_vm::native::NativeProgram;
use plc_vm::vm::{CallFrame, CycleStats, Fault, Machine, Memory, TryFrame};

/// One case (see the module documentation).
pub struct Case {
    pub name: &'static str,
    pub program: &'static NativeProgram,
    pub stack: usize,
    pub calls: usize,
    pub tries: usize,
    /// `(address, bytes)` written into data memory before the first cycle.
    pub patches: &'static [(u32, &'static [u8])],
    /// `(task, now_ns)` per activation.
    pub steps: &'static [(usize, i64)],
    /// After a fault: restart the task (reset it) and go on, or stop.
    pub reset_after_fault: bool,
}

struct Mem {
    data: Vec<u8>,
    stack: Vec<u64>,
    calls: Vec<CallFrame>,
    tries: Vec<TryFrame>,
}

impl Mem {
    fn new(case: &Case, data_size: usize) -> Self {
        Mem {
            data: vec![0; data_size],
            stack: vec![0; case.stack],
            calls: vec![CallFrame::EMPTY; case.calls],
            tries: vec![TryFrame::EMPTY; case.tries],
        }
    }

    fn machine<'a>(&'a mut self, image: &Image<'a>, case: &Case) -> Machine<'a, 'a> {
        let verified = plc_vm::verify::verify(image).expect("verified");
        let mut m = Machine::new(
            verified,
            Memory {
                data: &mut self.data,
                stack: &mut self.stack,
                calls: &mut self.calls,
                tries: &mut self.tries,
            },
        )
        .expect("machine");
        patch(m.data_mut(), case);
        m
    }
}

fn patch(data: &mut [u8], case: &Case) {
    for (at, bytes) in case.patches {
        data[*at as usize..*at as usize + bytes.len()].copy_from_slice(bytes);
    }
}

/// Model and machine agree on a cycle and the complete state.
fn against_model(
    native: &Machine<'_, '_>,
    model: &Model<'_>,
    got: &Result<CycleStats, Fault>,
    want: &ModelCycle,
) -> Result<(), String> {
    let same = match (got, want) {
        (
            Ok(s),
            ModelCycle::Completed {
                instructions,
                caught,
            },
        ) => s.instructions == *instructions && s.caught_traps == *caught,
        (Err(f), ModelCycle::Faulted { trap, pc }) => {
            !f.refused && f.trap == *trap && f.code_offset == *pc
        }
        (Err(f), ModelCycle::Refused) => f.refused,
        _ => false,
    };
    if !same {
        return Err(format!("native {got:?} vs model {want:?}"));
    }
    state("model", native, model.data(), model.stack(), model.pc(), model.call_depth(), model.try_depth())
}

fn state(
    what: &str,
    native: &Machine<'_, '_>,
    data: &[u8],
    stack: &[u64],
    pc: u32,
    call_depth: usize,
    try_depth: usize,
) -> Result<(), String> {
    if native.data() != data {
        let at = native
            .data()
            .iter()
            .zip(data)
            .position(|(a, b)| a != b)
            .unwrap_or(0);
        return Err(format!("data memory differs from the {what}'s at byte {at}"));
    }
    if native.stack() != stack {
        return Err(format!(
            "operand stack {:?} vs the {what}'s {:?}",
            native.stack(),
            stack
        ));
    }
    if native.pc() != pc || native.call_depth() != call_depth || native.try_depth() != try_depth {
        return Err(format!(
            "pc/call depth/try depth {}/{}/{} vs the {what}'s {pc}/{call_depth}/{try_depth}",
            native.pc(),
            native.call_depth(),
            native.try_depth()
        ));
    }
    Ok(())
}

/// Machine (VM) and machine (native) agree on a cycle and the complete state.
fn against_vm(
    native: &Machine<'_, '_>,
    vm: &Machine<'_, '_>,
    got: &Result<CycleStats, Fault>,
    want: &Result<CycleStats, Fault>,
) -> Result<(), String> {
    if got != want {
        return Err(format!("native {got:?} vs VM {want:?}"));
    }
    state("VM", native, vm.data(), vm.stack(), vm.pc(), vm.call_depth(), vm.try_depth())
}

#[derive(Default)]
struct Tally {
    cycles: usize,
    completed: usize,
    traps: [usize; 16],
    deadlines: usize,
    watchdogs: usize,
}

impl Tally {
    fn count(&mut self, r: &Result<CycleStats, Fault>) {
        self.cycles += 1;
        match r {
            Ok(_) => self.completed += 1,
            Err(f) if !f.refused => self.traps[f.trap.code() as usize] += 1,
            Err(_) => {}
        }
    }
}

/// A small deterministic mix of a case number and a step (no dependencies).
fn mix(a: u64, b: u64) -> u64 {
    let mut x = a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_add(0x632B_E59B_D9B4_E019);
    x ^= x >> 29;
    x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^ (x >> 32)
}

fn check(index: usize, case: &Case, tally: &mut Tally) -> Result<(), String> {
    let program = case.program;
    let image = Image::parse(program.image).map_err(|e| format!("image: {e}"))?;
    let verified = plc_vm::verify::verify(&image).map_err(|e| format!("verify: {e}"))?;
    let size = image.data_size() as usize;

    // 1. native vs model.
    let mut mem = Mem::new(case, size);
    let mut native = mem.machine(&image, case);
    let mut model = Model::new(&verified, case.stack, case.calls, case.tries);
    patch(model.data_mut(), case);
    for (step, &(task, now)) in case.steps.iter().enumerate() {
        let got = native.run_cycle_native(task, now, || false, program);
        let want = model.run_cycle(task, now, None);
        against_model(&native, &model, &got, &want)
            .map_err(|e| format!("activation {step} (task {task}): {e}"))?;
        tally.count(&got);
        if matches!(got, Err(f) if !f.refused) {
            if !case.reset_after_fault {
                break;
            }
            native.reset_task(task);
            model.reset_task(task);
        }
    }
    drop(native);

    // 2. a budget per activation: native vs model and VM.
    let mut mem = Mem::new(case, size);
    let mut native = mem.machine(&image, case);
    let mut vm_mem = Mem::new(case, size);
    let mut vm = vm_mem.machine(&image, case);
    let mut model = Model::new(&verified, case.stack, case.calls, case.tries);
    patch(model.data_mut(), case);
    for (step, &(task, now)) in case.steps.iter().enumerate() {
        let budget = 1 + (mix(index as u64, step as u64) % 2500) as u32;
        native.set_watchdog_budget(task, Some(budget));
        vm.set_watchdog_budget(task, Some(budget));
        let got = native.run_cycle_native(task, now, || false, program);
        let want = model.run_cycle(task, now, Some(budget));
        let vm_got = vm.run_cycle(task, now);
        against_model(&native, &model, &got, &want)
            .and_then(|()| against_vm(&native, &vm, &got, &vm_got))
            .map_err(|e| format!("budget {budget}, activation {step} (task {task}): {e}"))?;
        if matches!(got, Err(f) if f.trap == Trap::Watchdog && !f.refused) {
            tally.watchdogs += 1;
        }
        if matches!(got, Err(f) if !f.refused) {
            if !case.reset_after_fault {
                break;
            }
            native.reset_task(task);
            vm.reset_task(task);
            model.reset_task(task);
        }
    }
    drop(native);
    drop(vm);

    // 3. a deadline check that expires at its n-th question: native vs VM.
    let mut mem = Mem::new(case, size);
    let mut native = mem.machine(&image, case);
    let mut vm_mem = Mem::new(case, size);
    let mut vm = vm_mem.machine(&image, case);
    for (step, &(task, now)) in case.steps.iter().enumerate() {
        let n = 1 + mix(index as u64, 1000 + step as u64) % 3;
        let budget = 1500 + (mix(index as u64, 2000 + step as u64) % 4000) as u32;
        native.set_watchdog_budget(task, Some(budget));
        vm.set_watchdog_budget(task, Some(budget));
        let (mut asked_native, mut asked_vm) = (0u64, 0u64);
        let got = native.run_cycle_native(
            task,
            now,
            || {
                asked_native += 1;
                asked_native == n
            },
            program,
        );
        let want = vm.run_cycle_until(task, now, || {
            asked_vm += 1;
            asked_vm == n
        });
        against_vm(&native, &vm, &got, &want)
            .and_then(|()| {
                (asked_native == asked_vm).then_some(()).ok_or(format!(
                    "the clock was asked {asked_native} times, by the VM {asked_vm} times"
                ))
            })
            .map_err(|e| format!("deadline at question {n}, activation {step} (task {task}): {e}"))?;
        if matches!(got, Err(f) if f.trap == Trap::Deadline && !f.refused) {
            tally.deadlines += 1;
        }
        if matches!(got, Err(f) if !f.refused) {
            if !case.reset_after_fault {
                break;
            }
            native.reset_task(task);
            vm.reset_task(task);
        }
    }
    Ok(())
}

fn main() {
    let mut tally = Tally::default();
    let mut failed = 0;
    for (index, case) in programs::CASES.iter().enumerate() {
        if let Err(e) = check(index, case, &mut tally) {
            failed += 1;
            println!("FAIL {}: {e}", case.name);
        }
    }
    let traps: Vec<String> = Trap::ALL
        .iter()
        .map(|t| format!("{}={}", t.name(), tally.traps[t.code() as usize]))
        .collect();
    println!(
        "checked {} cases: {} activations compared with the model ({} completed; uncaught traps {}), {} budget watchdogs and {} deadlines compared with the VM, {failed} failed",
        programs::CASES.len(),
        tally.cycles,
        tally.completed,
        traps.join(" "),
        tally.watchdogs,
        tally.deadlines
    );
    std::process::exit(if failed == 0 { 0 } else { 1 });
}
