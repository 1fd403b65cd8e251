//! The interpreter: runs verified images in caller-provided memory, one task cycle at a time.
//!
//! Limits come from the memory the runtime hands in ([`Memory`]): `stack.len()` cells of
//! operand stack (push beyond → STACK_OVERFLOW), `calls.len()` call frames including the task's
//! own activation (CALL beyond → CALL_DEPTH), `tries.len()` open try frames (TRY_BEGIN beyond →
//! STACK_OVERFLOW). Nothing is allocated; every data access is bounds-checked.
//!
//! Determinism: the result of a cycle depends only on the image, data memory, the task and
//! `now_ns` (float ops are IEEE-754 with the math builtins implemented in [`crate::fmath`]).
//!
//! How it runs (for speed, without `unsafe`): `Machine::interpret` keeps the registers (`pc`,
//! `sp`, the frame base) and the slices of code, data and stack in locals and dispatches on
//! the raw opcode byte (one jump table); immediates are read from one bounds-checked
//! fixed-size slice per instruction. The watchdog budget and the deadline checks share one
//! down-counter ("fuel": the instructions left before the next check is due, a watchdog at
//! the budget or a clock question every [`DEADLINE_CHECK_EVERY`] instructions), so an
//! instruction costs one decrement and test for both, and both fire before exactly the
//! instruction they would stop with a count per instruction. Every arm checks before it
//! writes, so a trapping instruction leaves no trace (its `pc` and the stack as before it).

use crate::builtins;
use crate::image::{Image, SourceLocation, VAR_FLAG_CONSTANT, Var, VarType};
use crate::isa::{MemType, Opcode, RoundMode, Trap, lreal_result, real_result};
use crate::verify::{MAX_TASKS, VerifiedImage};

/// A saved caller context.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CallFrame {
    return_pc: u32,
    saved_base: u32,
}

impl CallFrame {
    /// An empty frame, to initialise runtime-provided arrays.
    pub const EMPTY: CallFrame = CallFrame {
        return_pc: 0,
        saved_base: 0,
    };
}

/// An open `TRY_BEGIN`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TryFrame {
    pub(crate) handler: u32,
    pub(crate) stack_depth: u32,
    pub(crate) call_depth: u32,
    pub(crate) base: u32,
}

impl TryFrame {
    /// An empty frame, to initialise runtime-provided arrays.
    pub const EMPTY: TryFrame = TryFrame {
        handler: 0,
        stack_depth: 0,
        call_depth: 0,
        base: 0,
    };
}

/// Memory the runtime provides.
pub struct Memory<'m> {
    /// Data memory; at least the image's `data_size` bytes (only that prefix is used).
    pub data: &'m mut [u8],
    /// Operand stack; its length is the stack limit.
    pub stack: &'m mut [u64],
    /// Call frames; its length is the call-depth limit (the task activation uses one).
    pub calls: &'m mut [CallFrame],
    /// Try frames; its length is the limit of simultaneously open try blocks.
    pub tries: &'m mut [TryFrame],
}

/// Why a machine could not be created.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SetupError {
    /// `data` shorter than the image's data size.
    DataTooSmall {
        /// Bytes needed.
        needed: u32,
        /// Bytes given.
        given: usize,
    },
    /// `stack` or `calls` is empty.
    NoStackOrFrames,
}

/// An uncaught trap (or a refused cycle).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fault {
    /// The trap.
    pub trap: Trap,
    /// Task index.
    pub task: usize,
    /// Code offset of the trapping instruction.
    pub code_offset: u32,
    /// Source location of that instruction, if the image has one.
    pub location: Option<SourceLocation>,
    /// True when this cycle was refused because the task was already faulted (the fields
    /// describe the original fault) or the task index does not exist (`trap` is then
    /// INVALID_ADDRESS and `code_offset` 0).
    pub refused: bool,
}

/// Statistics of a completed cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CycleStats {
    /// Instructions executed (what the watchdog counts).
    pub instructions: u32,
    /// Traps caught by try frames.
    pub caught_traps: u32,
}

pub use crate::monitor::{Value, VarError};

/// Instructions between two deadline checks of [`Machine::run_cycle_until`] (a few
/// microseconds of interpretation: the check's clock read stays below 1 % of the work).
pub const DEADLINE_CHECK_EVERY: u32 = 1024;

/// How many variables can be forced at the same time.
pub const MAX_FORCES: usize = 16;

/// A forced scalar: its bytes are re-written at the start and at the end of every cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Forced {
    addr: u32,
    len: u8,
    bytes: [u8; 8],
}

/// Why [`Machine::interpret`] returned.
enum Exit {
    /// The task POU's final RET (`pc` at it).
    End,
    /// The instruction at `pc` trapped (and had no effect).
    Trap(Trap),
    /// The fuel ran out before the instruction at `pc`: a watchdog or deadline check is due.
    Event,
}

/// A machine executing one verified image in runtime-provided memory.
pub struct Machine<'a, 'm> {
    image: Image<'a>,
    data: &'m mut [u8],
    stack: &'m mut [u64],
    calls: &'m mut [CallFrame],
    tries: &'m mut [TryFrame],
    sp: usize,
    call_depth: usize,
    try_depth: usize,
    pc: u32,
    base: u32,
    now_ns: i64,
    faults: [Option<Fault>; MAX_TASKS],
    budget_override: [Option<u32>; MAX_TASKS],
    forces: [Option<Forced>; MAX_FORCES],
    /// Whether any slot of `forces` is in use (the common case, none, costs one test).
    any_forced: bool,
    /// Each task's start (from the task and POU tables, read once).
    starts: [Option<TaskStart>; MAX_TASKS],
}

/// Where a task's cycle starts: its POU's first instruction, its instance base and the
/// task table's instruction budget.
#[derive(Clone, Copy, Debug)]
struct TaskStart {
    code_start: u32,
    instance_base: u32,
    budget: u32,
}

impl<'a, 'm> Machine<'a, 'm> {
    /// Creates a machine and initialises data memory from the image.
    pub fn new(image: VerifiedImage<'a>, memory: Memory<'m>) -> Result<Self, SetupError> {
        let image = *image.image();
        let needed = image.data_size();
        if memory.data.len() < needed as usize {
            return Err(SetupError::DataTooSmall {
                needed,
                given: memory.data.len(),
            });
        }
        if memory.stack.is_empty() || memory.calls.is_empty() {
            return Err(SetupError::NoStackOrFrames);
        }
        let mut machine = Machine {
            image,
            data: &mut memory.data[..needed as usize],
            stack: memory.stack,
            calls: memory.calls,
            tries: memory.tries,
            sp: 0,
            call_depth: 0,
            try_depth: 0,
            pc: 0,
            base: 0,
            now_ns: 0,
            faults: [None; MAX_TASKS],
            budget_override: [None; MAX_TASKS],
            forces: [None; MAX_FORCES],
            any_forced: false,
            starts: [None; MAX_TASKS],
        };
        for (task, start) in machine.starts.iter_mut().enumerate() {
            *start = image.task(task).map(|entry| TaskStart {
                code_start: image
                    .pou(entry.pou as usize)
                    .expect("verified task POU")
                    .code_start,
                instance_base: entry.instance_base,
                budget: entry.budget(),
            });
        }
        machine.reset();
        Ok(machine)
    }

    /// Cold restart: re-initialises data memory, clears all faults and registers (forced
    /// variables stay forced and are re-applied at the next cycle).
    pub fn reset(&mut self) {
        let init = self.image.init_data();
        self.data[..init.len()].copy_from_slice(init);
        self.data[init.len()..].fill(0);
        self.faults = [None; MAX_TASKS];
        self.sp = 0;
        self.call_depth = 0;
        self.try_depth = 0;
        self.pc = 0;
        self.base = 0;
    }

    /// The image being run.
    pub fn image(&self) -> &Image<'a> {
        &self.image
    }

    /// Data memory.
    pub fn data(&self) -> &[u8] {
        self.data
    }

    /// Data memory, writable (e.g. for a runtime mapping I/O).
    pub fn data_mut(&mut self) -> &mut [u8] {
        self.data
    }

    /// The live operand stack (empty after a completed cycle; as left by the trap after a fault).
    pub fn stack(&self) -> &[u64] {
        &self.stack[..self.sp]
    }

    /// Program counter: after a fault the trapping instruction, after a cycle the final RET.
    pub fn pc(&self) -> u32 {
        self.pc
    }

    /// Current call depth (0 after a completed cycle).
    pub fn call_depth(&self) -> usize {
        self.call_depth
    }

    /// Current number of open try frames.
    pub fn try_depth(&self) -> usize {
        self.try_depth
    }

    /// The fault that stopped `task`, if any.
    pub fn task_fault(&self, task: usize) -> Option<Fault> {
        self.faults.get(task).copied().flatten()
    }

    /// Clears the faulted state of `task` so it runs again (data memory is kept).
    pub fn reset_task(&mut self, task: usize) {
        if let Some(slot) = self.faults.get_mut(task) {
            *slot = None;
        }
    }

    /// Overrides the task's instruction budget per cycle (`None` = the task table's value).
    pub fn set_watchdog_budget(&mut self, task: usize, budget: Option<u32>) {
        if let Some(slot) = self.budget_override.get_mut(task) {
            *slot = budget;
        }
    }

    /// Runs one cycle of `task` at time `now_ns` (TIME, nanoseconds).
    pub fn run_cycle(&mut self, task: usize, now_ns: i64) -> Result<CycleStats, Fault> {
        self.run_cycle_until(task, now_ns, || false)
    }

    /// [`run_cycle`](Self::run_cycle) with a time deadline: every [`DEADLINE_CHECK_EVERY`]
    /// instructions it asks `expired` (the runtime reads its clock there) and ends the cycle
    /// with the uncatchable trap DEADLINE when it says so. The instruction budget still
    /// applies; whichever comes first stops the task.
    pub fn run_cycle_until(
        &mut self,
        task: usize,
        now_ns: i64,
        mut expired: impl FnMut() -> bool,
    ) -> Result<CycleStats, Fault> {
        let budget = self.start_cycle(task, now_ns)?;
        let mut caught_traps = 0;
        // The interpreter counts instructions down from `limit` (the count at which the next
        // watchdog or deadline check is due) in `fuel`: `limit - fuel` have been executed.
        let mut limit = budget.min(DEADLINE_CHECK_EVERY - 1);
        let mut fuel = limit;
        loop {
            match self.interpret(&mut fuel) {
                Exit::Event => {
                    let executed = limit;
                    if executed >= budget {
                        return Err(self.fault(task, Trap::Watchdog));
                    }
                    // Not the budget, so a deadline check point (count % EVERY == EVERY - 1).
                    if expired() {
                        return Err(self.fault(task, Trap::Deadline));
                    }
                    limit = budget.min(executed.saturating_add(DEADLINE_CHECK_EVERY));
                    fuel = limit - executed;
                }
                Exit::End => {
                    self.apply_forces();
                    return Ok(CycleStats {
                        instructions: limit - fuel,
                        caught_traps,
                    });
                }
                Exit::Trap(trap) => {
                    if !self.catch(trap) {
                        return Err(self.fault(task, trap));
                    }
                    caught_traps += 1;
                }
            }
        }
    }

    /// The start of a cycle of `task` at `now_ns`: refused for an unknown or faulted task;
    /// else the forces applied, the registers set for the task's POU, its budget returned.
    #[inline]
    fn start_cycle(&mut self, task: usize, now_ns: i64) -> Result<u32, Fault> {
        let Some(start) = self.starts.get(task).copied().flatten() else {
            return Err(Fault {
                trap: Trap::InvalidAddress,
                task,
                code_offset: 0,
                location: None,
                refused: true,
            });
        };
        if let Some(fault) = self.faults[task] {
            return Err(Fault {
                refused: true,
                ..fault
            });
        }
        let budget = self.budget_override[task].unwrap_or(start.budget);
        self.apply_forces();
        self.now_ns = now_ns;
        self.sp = 0;
        self.try_depth = 0;
        self.calls[0] = CallFrame {
            return_pc: u32::MAX,
            saved_base: 0,
        };
        self.call_depth = 1;
        self.base = start.instance_base;
        self.pc = start.code_start;
        Ok(budget)
    }

    /// [`run_cycle_until`](Self::run_cycle_until) on the native execution tier: runs `program`,
    /// the translation of this machine's image ([`crate::native`]; the caller checks
    /// [`NativeProgram::is_translation_of`](crate::native::NativeProgram::is_translation_of)),
    /// instead of interpreting it. Everything observable is the interpreter's: the result,
    /// the instruction count, the traps at the same instructions (the deadline checks at the
    /// same instruction counts), and afterwards data memory, the operand stack, `pc`, call
    /// and try depth, the task's fault and the forces.
    pub fn run_cycle_native(
        &mut self,
        task: usize,
        now_ns: i64,
        mut expired: impl FnMut() -> bool,
        program: &crate::native::NativeProgram,
    ) -> Result<CycleStats, Fault> {
        let budget = self.start_cycle(task, now_ns)?;
        let mut cycle = crate::native::Cycle::new(
            &self.image,
            self.stack,
            self.calls.len(),
            self.tries,
            &mut expired,
            now_ns,
            budget,
        );
        let result = (program.run)(&mut cycle, self.data, task);
        let end = cycle.end();
        self.try_depth = end.try_depth as usize;
        match (result, end.fault) {
            (Ok(()), _) => {
                self.pc = end.ret_pc;
                self.sp = 0;
                self.call_depth = 0;
                self.apply_forces();
                Ok(CycleStats {
                    instructions: end.executed,
                    caught_traps: end.caught,
                })
            }
            (Err(_), fault) => {
                let fault = fault.unwrap_or(crate::native::NativeFault {
                    trap: Trap::InvalidAddress,
                    pc: self.pc,
                    sp: 0,
                    call_depth: 1,
                });
                self.sp = fault.sp as usize;
                self.pc = fault.pc;
                self.call_depth = fault.call_depth as usize;
                Err(self.fault(task, fault.trap))
            }
        }
    }

    fn fault(&mut self, task: usize, trap: Trap) -> Fault {
        self.apply_forces();
        let fault = Fault {
            trap,
            task,
            code_offset: self.pc,
            location: self.image.source_location(self.pc),
            refused: false,
        };
        self.faults[task] = Some(fault);
        fault
    }

    /// Unwinds to the innermost try frame; false when the trap is not caught. A trap raised
    /// while delivering (no room for the trap code) goes to the next outer frame.
    fn catch(&mut self, mut trap: Trap) -> bool {
        loop {
            if !trap.is_catchable() || self.try_depth == 0 {
                return false;
            }
            self.try_depth -= 1;
            let frame = self.tries[self.try_depth];
            self.sp = frame.stack_depth as usize;
            self.call_depth = frame.call_depth as usize;
            self.base = frame.base;
            match self.push(trap.code() as u64) {
                Ok(()) => {
                    self.pc = frame.handler;
                    return true;
                }
                Err(again) => trap = again,
            }
        }
    }

    #[inline(always)]
    fn push(&mut self, value: u64) -> Result<(), Trap> {
        let slot = self.stack.get_mut(self.sp).ok_or(Trap::StackOverflow)?;
        *slot = value;
        self.sp += 1;
        Ok(())
    }

    /// Runs instructions from `pc` until the task's final RET, a trap or the fuel (the
    /// instructions left before the next watchdog/deadline check) running out; counts every
    /// instruction it starts, a trapping one too. Registers (`pc`, `sp`, `base`) live in
    /// locals here and are written back on the way out: after a trap `pc` is the trapping
    /// instruction and the stack is as before it (every arm checks before it writes).
    ///
    /// Data accesses and stack pushes are checked (INVALID_ADDRESS, STACK_OVERFLOW); stack
    /// reads rely on the verifier's depths and fall back to 0 rather than panic.
    #[inline(never)]
    fn interpret(&mut self, fuel: &mut u32) -> Exit {
        use crate::isa::byte as op;
        let image = &self.image;
        let code: &[u8] = image.code();
        let data: &mut [u8] = self.data;
        let stack: &mut [u64] = self.stack;
        let mut pc = self.pc as usize;
        let mut sp = self.sp;
        let mut base = self.base as u64;
        let mut left = *fuel;

        macro_rules! trap {
            ($trap:expr) => {
                break Exit::Trap($trap)
            };
        }
        // Cell `$k` from the top (1 = top).
        macro_rules! cell {
            ($k:expr) => {
                stack.get(sp.wrapping_sub($k)).copied().unwrap_or(0)
            };
        }
        macro_rules! set_cell {
            ($k:expr, $v:expr) => {{
                let v = $v;
                if let Some(slot) = stack.get_mut(sp.wrapping_sub($k)) {
                    *slot = v;
                }
            }};
        }
        macro_rules! push {
            ($v:expr) => {{
                let v = $v;
                match stack.get_mut(sp) {
                    Some(slot) => {
                        *slot = v;
                        sp += 1;
                    }
                    None => trap!(Trap::StackOverflow),
                }
            }};
        }
        // `[a b] -> [f(a, b)]`.
        macro_rules! binary {
            (|$a:ident, $b:ident| $e:expr) => {{
                let ($a, $b) = (cell!(2), cell!(1));
                set_cell!(2, $e);
                sp -= 1;
            }};
        }
        // `[a] -> [f(a)]`.
        macro_rules! unary {
            (|$a:ident| $e:expr) => {{
                let $a = cell!(1);
                set_cell!(1, $e);
            }};
        }
        macro_rules! next {
            ($name:ident) => {
                pc += const { Opcode::$name.size() }
            };
        }
        // The instruction's immediates (`Opcode::$name.size() - 1` bytes, complete in
        // verified code): one check, then constant offsets into a fixed-size array.
        macro_rules! imm {
            ($name:ident) => {
                match code
                    .get(pc + 1..)
                    .and_then(<[u8]>::first_chunk::<{ Opcode::$name.size() - 1 }>)
                {
                    Some(imm) => imm,
                    None => trap!(Trap::InvalidAddress),
                }
            };
        }
        macro_rules! load {
            ($ty:expr, $addr:expr) => {
                match load_typed(data, $ty, $addr) {
                    Some(v) => v,
                    None => trap!(Trap::InvalidAddress),
                }
            };
        }
        macro_rules! store {
            ($ty:expr, $addr:expr, $v:expr) => {
                if store_typed(data, $ty, $addr, $v).is_none() {
                    trap!(Trap::InvalidAddress)
                }
            };
        }
        let f32_of = |cell: u64| f32::from_bits(cell as u32);
        let cell_f32 = |v: f32| v.to_bits() as u64;

        let exit = loop {
            if left == 0 {
                break Exit::Event;
            }
            left -= 1;
            let Some(&byte) = code.get(pc) else {
                // Unreachable for verified code (every path ends in RET or a jump).
                trap!(Trap::InvalidAddress)
            };
            match byte {
                op::Nop => next!(Nop),
                op::PushI32 => {
                    let imm = imm!(PushI32);
                    push!(u32_at(imm, 0) as i32 as i64 as u64);
                    next!(PushI32);
                }
                op::PushU32 => {
                    let imm = imm!(PushU32);
                    push!(u32_at(imm, 0) as u64);
                    next!(PushU32);
                }
                op::PushI64 => {
                    let imm = imm!(PushI64);
                    push!(u64_at(imm, 0));
                    next!(PushI64);
                }
                op::PushConst => {
                    let imm = imm!(PushConst);
                    push!(image.constant(u16_at(imm, 0) as usize).unwrap_or(0));
                    next!(PushConst);
                }
                op::Drop => {
                    sp -= 1;
                    next!(Drop);
                }
                op::Dup => {
                    push!(cell!(1));
                    next!(Dup);
                }
                op::Swap => {
                    let (a, b) = (cell!(2), cell!(1));
                    set_cell!(2, b);
                    set_cell!(1, a);
                    next!(Swap);
                }
                op::Over => {
                    push!(cell!(2));
                    next!(Over);
                }
                op::LdAbs => {
                    let imm = imm!(LdAbs);
                    push!(load!(imm[0], u32_at(imm, 1) as u64));
                    next!(LdAbs);
                }
                op::LdRel => {
                    let imm = imm!(LdRel);
                    push!(load!(imm[0], base + u32_at(imm, 1) as u64));
                    next!(LdRel);
                }
                op::StAbs => {
                    let imm = imm!(StAbs);
                    store!(imm[0], u32_at(imm, 1) as u64, cell!(1));
                    sp -= 1;
                    next!(StAbs);
                }
                op::StRel => {
                    let imm = imm!(StRel);
                    store!(imm[0], base + u32_at(imm, 1) as u64, cell!(1));
                    sp -= 1;
                    next!(StRel);
                }
                op::LdInd => {
                    let imm = imm!(LdInd);
                    let address = cell!(1).checked_add(u32_at(imm, 1) as u64);
                    let v = load!(imm[0], address.unwrap_or(u64::MAX));
                    set_cell!(1, v);
                    next!(LdInd);
                }
                op::StInd => {
                    let imm = imm!(StInd);
                    let address = cell!(2).checked_add(u32_at(imm, 1) as u64);
                    store!(imm[0], address.unwrap_or(u64::MAX), cell!(1));
                    sp -= 2;
                    next!(StInd);
                }
                op::LeaRel => {
                    let imm = imm!(LeaRel);
                    push!(base + u32_at(imm, 0) as u64);
                    next!(LeaRel);
                }
                op::Copy => {
                    let imm = imm!(Copy);
                    let len = u32_at(imm, 0) as u64;
                    let (dst, src) = (cell!(2), cell!(1));
                    let in_data = |a: u64| {
                        a.checked_add(len)
                            .is_some_and(|end| end <= data.len() as u64)
                    };
                    if !in_data(dst) || !in_data(src) {
                        trap!(Trap::InvalidAddress);
                    }
                    let (dst, src, len) = (dst as usize, src as usize, len as usize);
                    data.copy_within(src..src + len, dst);
                    sp -= 2;
                    next!(Copy);
                }
                op::Now => {
                    push!(self.now_ns as u64);
                    next!(Now);
                }
                op::Add => {
                    binary!(|a, b| a.wrapping_add(b));
                    next!(Add);
                }
                op::Sub => {
                    binary!(|a, b| a.wrapping_sub(b));
                    next!(Sub);
                }
                op::Mul => {
                    binary!(|a, b| a.wrapping_mul(b));
                    next!(Mul);
                }
                op::DivS | op::DivU | op::ModS | op::ModU => {
                    let (a, b) = (cell!(2), cell!(1));
                    if b == 0 {
                        trap!(Trap::DivisionByZero);
                    }
                    let r = match byte {
                        op::DivS => (a as i64).wrapping_div(b as i64) as u64,
                        op::DivU => a / b,
                        op::ModS => (a as i64).wrapping_rem(b as i64) as u64,
                        _ => a % b,
                    };
                    set_cell!(2, r);
                    sp -= 1;
                    next!(DivS);
                }
                op::Neg => {
                    unary!(|a| (a as i64).wrapping_neg() as u64);
                    next!(Neg);
                }
                op::AbsS => {
                    unary!(|a| (a as i64).wrapping_abs() as u64);
                    next!(AbsS);
                }
                op::And => {
                    binary!(|a, b| a & b);
                    next!(And);
                }
                op::Or => {
                    binary!(|a, b| a | b);
                    next!(Or);
                }
                op::Xor => {
                    binary!(|a, b| a ^ b);
                    next!(Xor);
                }
                op::Not => {
                    unary!(|a| !a);
                    next!(Not);
                }
                op::NotBool => {
                    unary!(|a| (a == 0) as u64);
                    next!(NotBool);
                }
                op::Shl => {
                    binary!(|a, b| a.checked_shl(b.min(64) as u32).unwrap_or(0));
                    next!(Shl);
                }
                op::ShrU => {
                    binary!(|a, b| a.checked_shr(b.min(64) as u32).unwrap_or(0));
                    next!(ShrU);
                }
                op::ShrS => {
                    binary!(|a, b| ((a as i64) >> b.min(63)) as u64);
                    next!(ShrS);
                }
                op::Rol | op::Ror => {
                    let imm = imm!(Rol);
                    let width = imm[0] as u32;
                    binary!(|a, n| rotate(a, n, width, byte == op::Rol));
                    next!(Rol);
                }
                op::Sext => {
                    let imm = imm!(Sext);
                    let shift = 64 - imm[0] as u32;
                    unary!(|a| (((a << shift) as i64) >> shift) as u64);
                    next!(Sext);
                }
                op::Zext => {
                    let imm = imm!(Zext);
                    let shift = 64 - imm[0] as u32;
                    unary!(|a| (a << shift) >> shift);
                    next!(Zext);
                }
                op::Eq => {
                    binary!(|a, b| (a == b) as u64);
                    next!(Eq);
                }
                op::Ne => {
                    binary!(|a, b| (a != b) as u64);
                    next!(Ne);
                }
                op::LtS => {
                    binary!(|a, b| ((a as i64) < (b as i64)) as u64);
                    next!(LtS);
                }
                op::LeS => {
                    binary!(|a, b| ((a as i64) <= (b as i64)) as u64);
                    next!(LeS);
                }
                op::GtS => {
                    binary!(|a, b| ((a as i64) > (b as i64)) as u64);
                    next!(GtS);
                }
                op::GeS => {
                    binary!(|a, b| ((a as i64) >= (b as i64)) as u64);
                    next!(GeS);
                }
                op::LtU => {
                    binary!(|a, b| (a < b) as u64);
                    next!(LtU);
                }
                op::LeU => {
                    binary!(|a, b| (a <= b) as u64);
                    next!(LeU);
                }
                op::GtU => {
                    binary!(|a, b| (a > b) as u64);
                    next!(GtU);
                }
                op::GeU => {
                    binary!(|a, b| (a >= b) as u64);
                    next!(GeU);
                }
                op::Sel => {
                    let (g, a, b) = (cell!(3), cell!(2), cell!(1));
                    set_cell!(3, if g != 0 { b } else { a });
                    sp -= 2;
                    next!(Sel);
                }
                op::AddF32 => {
                    binary!(|a, b| real_result(f32_of(a) + f32_of(b)));
                    next!(AddF32);
                }
                op::SubF32 => {
                    binary!(|a, b| real_result(f32_of(a) - f32_of(b)));
                    next!(SubF32);
                }
                op::MulF32 => {
                    binary!(|a, b| real_result(f32_of(a) * f32_of(b)));
                    next!(MulF32);
                }
                op::DivF32 => {
                    let y = f32_of(cell!(1));
                    if y == 0.0 {
                        trap!(Trap::DivisionByZero);
                    }
                    binary!(|a, _b| real_result(f32_of(a) / y));
                    next!(DivF32);
                }
                op::NegF32 => {
                    unary!(|a| cell_f32(-f32_of(a)));
                    next!(NegF32);
                }
                op::AddF64 => {
                    binary!(|a, b| lreal_result(f64::from_bits(a) + f64::from_bits(b)));
                    next!(AddF64);
                }
                op::SubF64 => {
                    binary!(|a, b| lreal_result(f64::from_bits(a) - f64::from_bits(b)));
                    next!(SubF64);
                }
                op::MulF64 => {
                    binary!(|a, b| lreal_result(f64::from_bits(a) * f64::from_bits(b)));
                    next!(MulF64);
                }
                op::DivF64 => {
                    let y = f64::from_bits(cell!(1));
                    if y == 0.0 {
                        trap!(Trap::DivisionByZero);
                    }
                    binary!(|a, _b| lreal_result(f64::from_bits(a) / y));
                    next!(DivF64);
                }
                op::NegF64 => {
                    unary!(|a| (-f64::from_bits(a)).to_bits());
                    next!(NegF64);
                }
                op::EqF32
                | op::NeF32
                | op::LtF32
                | op::LeF32
                | op::GtF32
                | op::GeF32
                | op::EqF64
                | op::NeF64
                | op::LtF64
                | op::LeF64
                | op::GtF64
                | op::GeF64 => {
                    binary!(|a, b| compare_byte(byte, a, b) as u64);
                    next!(EqF32);
                }
                op::IToF32S => {
                    unary!(|a| cell_f32(a as i64 as f32));
                    next!(IToF32S);
                }
                op::IToF32U => {
                    unary!(|a| cell_f32(a as f32));
                    next!(IToF32U);
                }
                op::IToF64S => {
                    unary!(|a| (a as i64 as f64).to_bits());
                    next!(IToF64S);
                }
                op::IToF64U => {
                    unary!(|a| (a as f64).to_bits());
                    next!(IToF64U);
                }
                op::F32ToF64 => {
                    unary!(|a| (f32_of(a) as f64).to_bits());
                    next!(F32ToF64);
                }
                op::F64ToF32 => {
                    unary!(|a| cell_f32(f64::from_bits(a) as f32));
                    next!(F64ToF32);
                }
                op::F32ToInt | op::F64ToInt => {
                    let imm = imm!(F32ToInt);
                    let (Some(target), Some(mode)) =
                        (MemType::from_code(imm[0]), RoundMode::from_code(imm[1]))
                    else {
                        trap!(Trap::NumericError)
                    };
                    let a = cell!(1);
                    let x = if byte == op::F32ToInt {
                        f32_of(a) as f64
                    } else {
                        f64::from_bits(a)
                    };
                    match crate::fmath::float_to_int(x, target, mode) {
                        Some(r) => set_cell!(1, r),
                        None => trap!(Trap::NumericError),
                    }
                    next!(F32ToInt);
                }
                op::Jmp => {
                    let imm = imm!(Jmp);
                    pc = u32_at(imm, 0) as usize;
                }
                op::Jz | op::Jnz => {
                    let imm = imm!(Jz);
                    let c = cell!(1);
                    sp -= 1;
                    if (c == 0) == (byte == op::Jz) {
                        pc = u32_at(imm, 0) as usize;
                    } else {
                        next!(Jz);
                    }
                }
                op::JumpIf | op::JumpIfNot => {
                    let imm = imm!(JumpIf);
                    let holds = compare_byte(imm[0], cell!(2), cell!(1));
                    sp -= 2;
                    if holds == (byte == op::JumpIf) {
                        pc = u32_at(imm, 1) as usize;
                    } else {
                        next!(JumpIf);
                    }
                }
                op::Call => {
                    let imm = imm!(Call);
                    let Some((code_start, frame_size)) = image.pou_entry(u16_at(imm, 0) as usize)
                    else {
                        trap!(Trap::InvalidAddress)
                    };
                    let frame_base = cell!(1);
                    if self.call_depth >= self.calls.len() {
                        trap!(Trap::CallDepth);
                    }
                    if frame_base
                        .checked_add(frame_size as u64)
                        .is_none_or(|end| end > data.len() as u64)
                    {
                        trap!(Trap::InvalidAddress);
                    }
                    sp -= 1;
                    self.calls[self.call_depth] = CallFrame {
                        return_pc: (pc + const { Opcode::Call.size() }) as u32,
                        saved_base: base as u32,
                    };
                    self.call_depth += 1;
                    base = frame_base;
                    pc = code_start as usize;
                }
                op::Ret => {
                    self.call_depth -= 1;
                    let frame = self.calls[self.call_depth];
                    if self.call_depth == 0 {
                        break Exit::End;
                    }
                    pc = frame.return_pc as usize;
                    base = frame.saved_base as u64;
                }
                op::CallBuiltin => {
                    let imm = imm!(CallBuiltin);
                    let Some(builtin) = crate::isa::Builtin::from_u16(u16_at(imm, 0)) else {
                        trap!(Trap::NumericError)
                    };
                    let argc = builtin.args();
                    let args_start = sp - argc;
                    let mut args = [0u64; 8];
                    args[..argc].copy_from_slice(&stack[args_start..sp]);
                    match builtins::call(builtin, &args[..argc], data) {
                        Err(trap) => trap!(trap),
                        Ok(result) => {
                            sp = args_start;
                            if let Some(r) = result {
                                push!(r);
                            }
                        }
                    }
                    next!(CallBuiltin);
                }
                op::ChkIndex | op::ChkRangeS | op::ChkRangeU => {
                    let imm = imm!(ChkIndex);
                    let v = cell!(1);
                    let (lo, hi) = (u64_at(imm, 0), u64_at(imm, 8));
                    let ok = if byte == op::ChkRangeU {
                        lo <= v && v <= hi
                    } else {
                        (lo as i64) <= (v as i64) && (v as i64) <= (hi as i64)
                    };
                    if !ok {
                        trap!(if byte == op::ChkIndex {
                            Trap::IndexOutOfBounds
                        } else {
                            Trap::SubrangeViolation
                        });
                    }
                    next!(ChkIndex);
                }
                op::Index => {
                    let imm = imm!(Index);
                    let (lo, hi) = (u64_at(imm, 0) as i64, u64_at(imm, 8) as i64);
                    let stride = u32_at(imm, 16) as u64;
                    let (array, i) = (cell!(2), cell!(1));
                    if (i as i64) < lo || (i as i64) > hi {
                        trap!(Trap::IndexOutOfBounds);
                    }
                    let offset = (i as i64).wrapping_sub(lo) as u64;
                    set_cell!(2, array.wrapping_add(offset.wrapping_mul(stride)));
                    sp -= 1;
                    next!(Index);
                }
                op::AddImm => {
                    let imm = imm!(AddImm);
                    unary!(|a| a.wrapping_add(u32_at(imm, 0) as i32 as i64 as u64));
                    next!(AddImm);
                }
                op::TryBegin => {
                    let imm = imm!(TryBegin);
                    let Some(slot) = self.tries.get_mut(self.try_depth) else {
                        trap!(Trap::StackOverflow)
                    };
                    *slot = TryFrame {
                        handler: u32_at(imm, 0),
                        stack_depth: sp as u32,
                        call_depth: self.call_depth as u32,
                        base: base as u32,
                    };
                    self.try_depth += 1;
                    next!(TryBegin);
                }
                op::TryEnd => {
                    self.try_depth = self.try_depth.saturating_sub(1);
                    next!(TryEnd);
                }
                op::Throw => {
                    let imm = imm!(Throw);
                    trap!(Trap::from_u64(imm[0] as u64).unwrap_or(Trap::NumericError))
                }
                op::Rethrow => {
                    let c = cell!(1);
                    if c != 0 {
                        trap!(match Trap::from_u64(c) {
                            Some(trap) if trap.is_catchable() => trap,
                            _ => Trap::NumericError,
                        });
                    }
                    sp -= 1;
                    next!(Rethrow);
                }
                op::ElemRel | op::ElemAbs => {
                    let imm = imm!(ElemRel);
                    match element(imm, 0, byte == op::ElemRel, base, cell!(1)) {
                        Some(address) => set_cell!(1, address),
                        None => trap!(Trap::IndexOutOfBounds),
                    }
                    next!(ElemRel);
                }
                op::LdElemRel | op::LdElemAbs => {
                    let imm = imm!(LdElemRel);
                    let Some(address) = element(imm, 1, byte == op::LdElemRel, base, cell!(1))
                    else {
                        trap!(Trap::IndexOutOfBounds)
                    };
                    set_cell!(1, load!(imm[0], address));
                    next!(LdElemRel);
                }
                op::StElemRel | op::StElemAbs => {
                    let imm = imm!(StElemRel);
                    let Some(address) = element(imm, 1, byte == op::StElemRel, base, cell!(2))
                    else {
                        trap!(Trap::IndexOutOfBounds)
                    };
                    store!(imm[0], address, cell!(1));
                    sp -= 2;
                    next!(StElemRel);
                }
                op::IncRel | op::IncAbs => {
                    let imm = imm!(IncRel);
                    let address = if byte == op::IncRel {
                        base + u32_at(imm, 1) as u64
                    } else {
                        u32_at(imm, 1) as u64
                    };
                    let v = load!(imm[0], address);
                    store!(
                        imm[0],
                        address,
                        v.wrapping_add(u32_at(imm, 5) as i32 as i64 as u64)
                    );
                    next!(IncRel);
                }
                op::SelIf => {
                    let imm = imm!(SelIf);
                    binary!(|a, b| if compare_byte(imm[0], a, b) { b } else { a });
                    next!(SelIf);
                }
                op::JumpIfImm | op::JumpIfNotImm => {
                    let imm = imm!(JumpIfImm);
                    let holds = compare_byte(imm[0], cell!(1), u32_at(imm, 1) as i32 as i64 as u64);
                    sp -= 1;
                    if holds == (byte == op::JumpIfImm) {
                        pc = u32_at(imm, 5) as usize;
                    } else {
                        next!(JumpIfImm);
                    }
                }
                op::OpImm => {
                    let imm = imm!(OpImm);
                    match binary_op(imm[0], cell!(1), u32_at(imm, 1) as i32 as i64 as u64) {
                        Ok(r) => set_cell!(1, r),
                        Err(trap) => trap!(trap),
                    }
                    next!(OpImm);
                }
                op::OpRel | op::OpAbs => {
                    let imm = imm!(OpRel);
                    let address = if byte == op::OpRel {
                        base + u32_at(imm, 2) as u64
                    } else {
                        u32_at(imm, 2) as u64
                    };
                    let v = load!(imm[1], address);
                    match binary_op(imm[0], cell!(1), v) {
                        Ok(r) => set_cell!(1, r),
                        Err(trap) => trap!(trap),
                    }
                    next!(OpRel);
                }
                op::RefMake => {
                    let imm = imm!(RefMake);
                    let address = cell!(1);
                    let Some(object) = image.object_containing(address, u32_at(imm, 0) as u64)
                    else {
                        trap!(Trap::InvalidReference)
                    };
                    set_cell!(1, address | ((object as u64 + 1) << 32));
                    next!(RefMake);
                }
                op::RefCheck => {
                    let imm = imm!(RefCheck);
                    let reference = cell!(1);
                    let address = reference & 0xFFFF_FFFF;
                    let size = u32_at(imm, 0) as u64;
                    let inside = (reference >> 32)
                        .checked_sub(1)
                        .and_then(|index| image.object(index as usize))
                        .is_some_and(|(start, len)| {
                            start as u64 <= address && address + size <= start as u64 + len as u64
                        });
                    if !inside {
                        trap!(Trap::InvalidReference);
                    }
                    set_cell!(1, address);
                    next!(RefCheck);
                }
                op::RefAdd => {
                    binary!(|reference, n| {
                        let address = (reference as u32).wrapping_add(n as u32);
                        (reference & !0xFFFF_FFFF) | address as u64
                    });
                    next!(RefAdd);
                }
                op::ChkNull => {
                    if cell!(1) == 0 {
                        trap!(Trap::InvalidReference);
                    }
                    next!(ChkNull);
                }
                op::CallVirt | op::VirtFrame => {
                    let imm = imm!(CallVirt);
                    let instance = cell!(1);
                    let method = match method(image, data, instance, u16_at(imm, 0)) {
                        Ok(method) => method,
                        Err(trap) => trap!(trap),
                    };
                    if byte == op::VirtFrame {
                        set_cell!(1, method.frame as u64);
                        next!(VirtFrame);
                    } else {
                        let Some((code_start, frame_size)) = image.pou_entry(method.pou as usize)
                        else {
                            trap!(Trap::InvalidAddress)
                        };
                        if self.call_depth >= self.calls.len() {
                            trap!(Trap::CallDepth);
                        }
                        if instance + frame_size as u64 > data.len() as u64 {
                            trap!(Trap::InvalidAddress);
                        }
                        sp -= 1;
                        self.calls[self.call_depth] = CallFrame {
                            return_pc: (pc + const { Opcode::CallVirt.size() }) as u32,
                            saved_base: base as u32,
                        };
                        self.call_depth += 1;
                        base = instance;
                        pc = code_start as usize;
                    }
                }
                op::OpRelRel => {
                    let imm = imm!(OpRelRel);
                    // As its first load would: no room, no operation.
                    if sp >= stack.len() {
                        trap!(Trap::StackOverflow);
                    }
                    let a = load!(imm[1], base + u32_at(imm, 2) as u64);
                    let b = load!(imm[6], base + u32_at(imm, 7) as u64);
                    match binary_op(imm[0], a, b) {
                        Ok(r) => push!(r),
                        Err(trap) => trap!(trap),
                    }
                    next!(OpRelRel);
                }
                op::JumpIfRelImm | op::JumpIfNotRelImm => {
                    let imm = imm!(JumpIfRelImm);
                    let v = load!(imm[1], base + u32_at(imm, 2) as u64);
                    let holds = compare_byte(imm[0], v, u32_at(imm, 6) as i32 as i64 as u64);
                    if holds == (byte == op::JumpIfRelImm) {
                        pc = u32_at(imm, 10) as usize;
                    } else {
                        next!(JumpIfRelImm);
                    }
                }
                op::ElemRelAt | op::ElemAbsAt => {
                    let imm = imm!(ElemRelAt);
                    if sp >= stack.len() {
                        trap!(Trap::StackOverflow);
                    }
                    let i = load!(imm[24], base + u32_at(imm, 25) as u64);
                    match element(imm, 0, byte == op::ElemRelAt, base, i) {
                        Some(address) => push!(address),
                        None => trap!(Trap::IndexOutOfBounds),
                    }
                    next!(ElemRelAt);
                }
                op::LdElemRelAt | op::LdElemAbsAt => {
                    let imm = imm!(LdElemRelAt);
                    if sp >= stack.len() {
                        trap!(Trap::StackOverflow);
                    }
                    let i = load!(imm[25], base + u32_at(imm, 26) as u64);
                    let Some(address) = element(imm, 1, byte == op::LdElemRelAt, base, i) else {
                        trap!(Trap::IndexOutOfBounds)
                    };
                    push!(load!(imm[0], address));
                    next!(LdElemRelAt);
                }
                op::StElemRelAt | op::StElemAbsAt => {
                    let imm = imm!(StElemRelAt);
                    let i = load!(imm[25], base + u32_at(imm, 26) as u64);
                    let Some(address) = element(imm, 1, byte == op::StElemRelAt, base, i) else {
                        trap!(Trap::IndexOutOfBounds)
                    };
                    store!(imm[0], address, cell!(1));
                    sp -= 1;
                    next!(StElemRelAt);
                }
                // Unassigned bytes: the verifier accepts none.
                _ => trap!(Trap::InvalidAddress),
            }
        };
        self.pc = pc as u32;
        self.sp = sp;
        self.base = base as u32;
        *fuel = left;
        exit
    }

    // ---- monitor ----

    /// Reads a variable by name.
    pub fn read_var(&self, name: &str) -> Result<Value<'_>, VarError> {
        let var = self.image.find_var(name).ok_or(VarError::UnknownName)?;
        Ok(self.read_entry(&var))
    }

    /// Reads a variable-map entry (verified to lie inside data memory); a reference's
    /// target is named by the first variable of the map it is the start of.
    pub fn read_entry(&self, var: &Var<'_>) -> Value<'_> {
        let ty = VarType::from_code(var.ty).expect("verified");
        let at = var.addr as usize;
        match Value::load(ty, &self.data[at..at + var.size as usize]).expect("verified") {
            Value::Ref { address, .. } => Value::Ref {
                address,
                target: address.and_then(|a| self.image.var_at(a)).map(|v| v.name),
            },
            value => value,
        }
    }

    /// Writes a variable by name (once; the program may change it again), as
    /// [`Value::store`] does: integers truncated to the variable's width, texts to its
    /// capacity, references never ([`VarError::ReadOnly`]).
    pub fn write_var(&mut self, name: &str, value: Value<'_>) -> Result<(), VarError> {
        let var = self.image.find_var(name).ok_or(VarError::UnknownName)?;
        self.write_entry(&var, value)
    }

    /// Writes a variable-map entry of this machine's image, as [`Machine::write_var`] does.
    pub fn write_entry(&mut self, var: &Var<'_>, value: Value<'_>) -> Result<(), VarError> {
        if var.flags & VAR_FLAG_CONSTANT != 0 {
            return Err(VarError::Constant);
        }
        // An entry of another image is refused rather than trusted.
        let ty = VarType::from_code(var.ty).ok_or(VarError::UnknownName)?;
        let at = var.addr as usize;
        let cell = self
            .data
            .get_mut(at..at + var.size as usize)
            .ok_or(VarError::UnknownName)?;
        value.store(ty, cell)
    }

    /// Forces a scalar variable: writes it now and re-writes it at the start and at the end
    /// of every cycle until [`Machine::unforce_var`] (so the program sees the forced value and
    /// so does the monitor after the cycle). Re-forcing a forced variable replaces the value.
    pub fn force_var(&mut self, name: &str, value: Value<'_>) -> Result<(), VarError> {
        let var = self.image.find_var(name).ok_or(VarError::UnknownName)?;
        if var.flags & VAR_FLAG_CONSTANT != 0 {
            return Err(VarError::Constant);
        }
        let ty = VarType::from_code(var.ty).expect("verified");
        let forced = Self::encode_scalar(&var, ty, value)?;
        let slot = match self
            .forces
            .iter()
            .position(|f| f.is_some_and(|f| f.addr == var.addr))
        {
            Some(existing) => existing,
            None => self
                .forces
                .iter()
                .position(Option::is_none)
                .ok_or(VarError::TooManyForces)?,
        };
        self.forces[slot] = Some(forced);
        self.any_forced = true;
        self.write_forced(&forced);
        Ok(())
    }

    /// Ends forcing of a variable (its current value stays). Not forced: no effect.
    pub fn unforce_var(&mut self, name: &str) -> Result<(), VarError> {
        let var = self.image.find_var(name).ok_or(VarError::UnknownName)?;
        for slot in &mut self.forces {
            if slot.is_some_and(|f| f.addr == var.addr) {
                *slot = None;
            }
        }
        self.any_forced = self.forces.iter().any(Option::is_some);
        Ok(())
    }

    /// The forced variables: each one's data address and forced bytes (little-endian).
    pub fn forced(&self) -> impl Iterator<Item = (u32, &[u8])> + '_ {
        self.forces
            .iter()
            .flatten()
            .map(|f| (f.addr, &f.bytes[..f.len as usize]))
    }

    /// Forces scalar variable `name` to `bytes`, its raw little-endian value as
    /// [`Machine::forced`] gives it (so a force can follow a variable into another program
    /// by name); the width must be the variable's.
    pub fn force_bytes(&mut self, name: &str, bytes: &[u8]) -> Result<(), VarError> {
        let var = self.image.find_var(name).ok_or(VarError::UnknownName)?;
        let ty = VarType::from_code(var.ty).ok_or(VarError::TypeMismatch)?;
        let mem = ty.mem_type().ok_or(match ty {
            VarType::Ref => VarError::ReadOnly,
            _ => VarError::NotForceable,
        })?;
        if var.flags & VAR_FLAG_CONSTANT != 0 {
            return Err(VarError::Constant);
        }
        if bytes.len() != mem.width() {
            return Err(VarError::TypeMismatch);
        }
        let value = Value::of_cell(ty, mem.cell_from_le(bytes)).ok_or(VarError::TypeMismatch)?;
        self.force_var(name, value)
    }

    /// Ends all forcing.
    pub fn clear_forces(&mut self) {
        self.forces = [None; MAX_FORCES];
        self.any_forced = false;
    }

    fn encode_scalar(var: &Var<'_>, ty: VarType, value: Value<'_>) -> Result<Forced, VarError> {
        let cell = value.to_cell(ty)?;
        let mem = ty.mem_type().ok_or(VarError::NotForceable)?;
        Ok(Forced {
            addr: var.addr,
            len: mem.width() as u8,
            bytes: cell.to_le_bytes(),
        })
    }

    fn write_forced(&mut self, forced: &Forced) {
        let at = forced.addr as usize;
        let len = forced.len as usize;
        self.data[at..at + len].copy_from_slice(&forced.bytes[..len]);
    }

    #[inline]
    fn apply_forces(&mut self) {
        if self.any_forced {
            self.write_forces();
        }
    }

    #[cold]
    fn write_forces(&mut self) {
        for slot in 0..MAX_FORCES {
            if let Some(forced) = self.forces[slot] {
                self.write_forced(&forced);
            }
        }
    }
}

/// Rotates the low `width` bits of `value` by `amount mod width`; the result is zero-extended.
pub(crate) fn rotate(value: u64, amount: u64, width: u32, left: bool) -> u64 {
    let mask = if width == 64 {
        u64::MAX
    } else {
        (1u64 << width) - 1
    };
    let v = value & mask;
    let n = (amount % width as u64) as u32;
    if n == 0 {
        return v;
    }
    let r = if left {
        (v << n) | (v >> (width - n))
    } else {
        (v >> n) | (v << (width - n))
    };
    r & mask
}

/// The little-endian `u16` at `at` of an instruction's immediates.
#[inline(always)]
fn u16_at<const N: usize>(imm: &[u8; N], at: usize) -> u16 {
    u16::from_le_bytes([imm[at], imm[at + 1]])
}

/// The little-endian `u32` at `at` of an instruction's immediates.
#[inline(always)]
fn u32_at<const N: usize>(imm: &[u8; N], at: usize) -> u32 {
    u32::from_le_bytes([imm[at], imm[at + 1], imm[at + 2], imm[at + 3]])
}

/// The little-endian `u64` at `at` of an instruction's immediates.
#[inline(always)]
fn u64_at<const N: usize>(imm: &[u8; N], at: usize) -> u64 {
    let mut bytes = [0u8; 8];
    bytes.copy_from_slice(&imm[at..at + 8]);
    u64::from_le_bytes(bytes)
}

/// `N` bytes of data memory at `address`, if they lie inside it.
#[inline(always)]
fn chunk<const N: usize>(data: &[u8], address: u64) -> Option<&[u8; N]> {
    data.get(usize::try_from(address).ok()?..)?
        .first_chunk::<N>()
}

/// A typed load (a [`MemType`] code byte): the cell, sign- or zero-extended; `None` outside
/// data memory.
#[inline(always)]
fn load_typed(data: &[u8], ty: u8, address: u64) -> Option<u64> {
    use crate::isa::mem_type_byte as t;
    Some(match ty {
        t::I8 => chunk::<1>(data, address)?[0] as i8 as i64 as u64,
        t::U8 => chunk::<1>(data, address)?[0] as u64,
        t::I16 => i16::from_le_bytes(*chunk(data, address)?) as i64 as u64,
        t::U16 => u16::from_le_bytes(*chunk(data, address)?) as u64,
        t::I32 => i32::from_le_bytes(*chunk(data, address)?) as i64 as u64,
        t::U32 | t::F32 => u32::from_le_bytes(*chunk(data, address)?) as u64,
        _ => u64::from_le_bytes(*chunk(data, address)?),
    })
}

/// A typed store: the low bytes of `value` (truncation to the type's width); `None` (and
/// nothing written) outside data memory.
#[inline(always)]
fn store_typed(data: &mut [u8], ty: u8, address: u64, value: u64) -> Option<()> {
    use crate::isa::mem_type_byte as t;
    let tail = data.get_mut(usize::try_from(address).ok()?..)?;
    match ty {
        t::I8 | t::U8 => *tail.first_chunk_mut()? = (value as u8).to_le_bytes(),
        t::I16 | t::U16 => *tail.first_chunk_mut()? = (value as u16).to_le_bytes(),
        t::I32 | t::U32 | t::F32 => *tail.first_chunk_mut()? = (value as u32).to_le_bytes(),
        _ => *tail.first_chunk_mut()? = value.to_le_bytes(),
    }
    Some(())
}

/// The method instance `instance`'s class runs for `slot` (see `CALL_VIRT`).
fn method(
    image: &Image<'_>,
    data: &[u8],
    instance: u64,
    slot: u16,
) -> Result<crate::image::Dispatch, Trap> {
    if instance == 0 {
        return Err(Trap::InvalidReference);
    }
    let class = load_typed(data, MemType::U32 as u8, instance).ok_or(Trap::InvalidReference)?;
    image
        .lookup_method(class, slot)
        .ok_or(Trap::InvalidReference)
}

/// The address of element `i` of the array that an ELEM-family immediate describes from
/// byte `at` on (`isa`: the array's address, u32, frame-relative when `relative`; its
/// bounds `lo..=hi`, i64 each; the element stride, u32), as INDEX computes it (wrapping);
/// `None` when `i` is outside the bounds.
#[inline(always)]
fn element<const N: usize>(
    imm: &[u8; N],
    at: usize,
    relative: bool,
    base: u64,
    i: u64,
) -> Option<u64> {
    let array = u32_at(imm, at) as u64;
    let array = if relative { base + array } else { array };
    let (i, lo, hi) = (
        i as i64,
        u64_at(imm, at + 4) as i64,
        u64_at(imm, at + 12) as i64,
    );
    if i < lo || i > hi {
        return None;
    }
    let stride = u32_at(imm, at + 20) as u64;
    Some(array.wrapping_add((i.wrapping_sub(lo) as u64).wrapping_mul(stride)))
}

/// A binary operator (an opcode byte for which [`Opcode::is_binary`] holds) applied to `a`
/// and `b` as the plain instruction does: OP_IMM, OP_REL, OP_ABS and OP_REL_REL.
#[inline(always)]
fn binary_op(op: u8, a: u64, b: u64) -> Result<u64, Trap> {
    use crate::isa::byte as op;
    let f32_of = |cell: u64| f32::from_bits(cell as u32);
    let f64_of = f64::from_bits;
    Ok(match op {
        op::Add => a.wrapping_add(b),
        op::Sub => a.wrapping_sub(b),
        op::Mul => a.wrapping_mul(b),
        op::DivS | op::DivU | op::ModS | op::ModU if b == 0 => return Err(Trap::DivisionByZero),
        op::DivS => (a as i64).wrapping_div(b as i64) as u64,
        op::DivU => a / b,
        op::ModS => (a as i64).wrapping_rem(b as i64) as u64,
        op::ModU => a % b,
        op::And => a & b,
        op::Or => a | b,
        op::Xor => a ^ b,
        op::Shl => a.checked_shl(b.min(64) as u32).unwrap_or(0),
        op::ShrU => a.checked_shr(b.min(64) as u32).unwrap_or(0),
        op::ShrS => ((a as i64) >> b.min(63)) as u64,
        op::AddF32 => real_result(f32_of(a) + f32_of(b)),
        op::SubF32 => real_result(f32_of(a) - f32_of(b)),
        op::MulF32 => real_result(f32_of(a) * f32_of(b)),
        op::DivF32 if f32_of(b) == 0.0 => return Err(Trap::DivisionByZero),
        op::DivF32 => real_result(f32_of(a) / f32_of(b)),
        op::AddF64 => lreal_result(f64_of(a) + f64_of(b)),
        op::SubF64 => lreal_result(f64_of(a) - f64_of(b)),
        op::MulF64 => lreal_result(f64_of(a) * f64_of(b)),
        op::DivF64 if f64_of(b) == 0.0 => return Err(Trap::DivisionByZero),
        op::DivF64 => lreal_result(f64_of(a) / f64_of(b)),
        cmp => compare_byte(cmp, a, b) as u64,
    })
}

/// [`crate::isa::compare`] on a comparison opcode byte (`false` for other bytes).
#[inline(always)]
fn compare_byte(cmp: u8, a: u64, b: u64) -> bool {
    use crate::isa::byte as op;
    let (sa, sb) = (a as i64, b as i64);
    let (fa, fb) = (f32::from_bits(a as u32), f32::from_bits(b as u32));
    let (da, db) = (f64::from_bits(a), f64::from_bits(b));
    match cmp {
        op::Eq => a == b,
        op::Ne => a != b,
        op::LtS => sa < sb,
        op::LeS => sa <= sb,
        op::GtS => sa > sb,
        op::GeS => sa >= sb,
        op::LtU => a < b,
        op::LeU => a <= b,
        op::GtU => a > b,
        op::GeU => a >= b,
        op::EqF32 => fa == fb,
        op::NeF32 => fa != fb,
        op::LtF32 => fa < fb,
        op::LeF32 => fa <= fb,
        op::GtF32 => fa > fb,
        op::GeF32 => fa >= fb,
        op::EqF64 => da == db,
        op::NeF64 => da != db,
        op::LtF64 => da < db,
        op::LeF64 => da <= db,
        op::GtF64 => da > db,
        op::GeF64 => da >= db,
        _ => false,
    }
}
