//! The interpreter: runs verified images in caller-provided memory, one task cycle at a time.
//!
//! Limits come from the memory the runtime hands in ([`Memory`]): `stack.len()` cells of
//! operand stack (push beyond → STACK_OVERFLOW), `calls.len()` call frames including the task's
//! own activation (CALL beyond → CALL_DEPTH), `tries.len()` open try frames (TRY_BEGIN beyond →
//! STACK_OVERFLOW). Nothing is allocated; every data access is bounds-checked.
//!
//! Determinism: the result of a cycle depends only on the image, data memory, the task and
//! `now_ns` (float ops are IEEE-754 with the math builtins implemented in [`crate::fmath`]).

use crate::builtins;
use crate::image::{Image, SourceLocation, VAR_FLAG_CONSTANT, Var, VarType};
use crate::isa::{MemType, Opcode, RoundMode, Trap, read_u16, read_u32, read_u64};
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

/// A typed variable value for the monitor API.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value<'s> {
    /// BOOL.
    Bool(bool),
    /// Signed integers (SINT..LINT).
    Int(i64),
    /// Unsigned integers and bit strings (USINT..ULINT, BYTE..LWORD).
    UInt(u64),
    /// REAL.
    Real(f32),
    /// LREAL.
    LReal(f64),
    /// TIME in nanoseconds.
    Time(i64),
    /// STRING bytes.
    String(&'s [u8]),
}

impl core::fmt::Display for Value<'_> {
    /// IEC literal style: `TRUE`, `-3`, `0.5`, `T#20ms`, `'text'`.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Value::Bool(b) => f.write_str(if b { "TRUE" } else { "FALSE" }),
            Value::Int(v) => write!(f, "{v}"),
            Value::UInt(v) => write!(f, "{v}"),
            Value::Real(v) => write!(f, "{v}"),
            Value::LReal(v) => write!(f, "{v}"),
            Value::Time(ns) if ns % 1_000_000 == 0 => write!(f, "T#{}ms", ns / 1_000_000),
            Value::Time(ns) if ns % 1_000 == 0 => write!(f, "T#{}us", ns / 1_000),
            Value::Time(ns) => write!(f, "T#{ns}ns"),
            Value::String(bytes) => match core::str::from_utf8(bytes) {
                Ok(text) => write!(f, "'{text}'"),
                Err(_) => write!(f, "'<{} bytes>'", bytes.len()),
            },
        }
    }
}

/// Why a monitor access failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VarError {
    /// No variable of that name.
    UnknownName,
    /// Value kind does not fit the variable type.
    TypeMismatch,
    /// The variable is CONSTANT.
    Constant,
    /// STRING variables can be written but not forced.
    NotForceable,
    /// All [`MAX_FORCES`] force slots are in use.
    TooManyForces,
}

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

/// Internal control-flow outcome of one instruction.
enum Flow {
    Next,
    EndOfCycle,
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
        let mut stats = CycleStats::default();
        let code: &'a [u8] = self.image.code();
        loop {
            if stats.instructions >= budget {
                return Err(self.fault(task, Trap::Watchdog));
            }
            if stats.instructions % DEADLINE_CHECK_EVERY == DEADLINE_CHECK_EVERY - 1 && expired() {
                return Err(self.fault(task, Trap::Deadline));
            }
            stats.instructions += 1;
            // A trapping instruction has no effect: its pops are undone (pops never overwrite
            // cells, and no instruction pushes before it can still trap).
            let sp_before = self.sp;
            match self.step(code) {
                Ok(Flow::Next) => {}
                Ok(Flow::EndOfCycle) => {
                    self.apply_forces();
                    return Ok(stats);
                }
                Err(trap) => {
                    self.sp = sp_before;
                    if !self.catch(trap) {
                        return Err(self.fault(task, trap));
                    }
                    stats.caught_traps += 1;
                }
            }
        }
    }

    /// The start of a cycle of `task` at `now_ns`: refused for an unknown or faulted task;
    /// else the forces applied, the registers set for the task's POU, its budget returned.
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

    #[inline(always)]
    fn pop(&mut self) -> u64 {
        // The verifier guarantees the depth; a defensive 0 keeps an impossible underflow panic-free.
        if self.sp == 0 {
            return 0;
        }
        self.sp -= 1;
        self.stack[self.sp]
    }

    #[inline(always)]
    fn pop2(&mut self) -> (u64, u64) {
        let b = self.pop();
        let a = self.pop();
        (a, b)
    }

    #[inline(always)]
    fn load(&self, ty: MemType, address: u64) -> Result<u64, Trap> {
        let start = usize::try_from(address).map_err(|_| Trap::InvalidAddress)?;
        let bytes = start
            .checked_add(ty.width())
            .and_then(|end| self.data.get(start..end))
            .ok_or(Trap::InvalidAddress)?;
        Ok(ty.cell_from_le(bytes))
    }

    #[inline(always)]
    fn store(&mut self, ty: MemType, address: u64, value: u64) -> Result<(), Trap> {
        fn put<const N: usize>(data: &mut [u8], start: usize, value: u64) -> Result<(), Trap> {
            let end = start.checked_add(N).ok_or(Trap::InvalidAddress)?;
            let bytes = data.get_mut(start..end).ok_or(Trap::InvalidAddress)?;
            let mut raw = [0u8; N];
            raw.copy_from_slice(&value.to_le_bytes()[..N]);
            bytes.copy_from_slice(&raw);
            Ok(())
        }
        let start = usize::try_from(address).map_err(|_| Trap::InvalidAddress)?;
        match ty.width() {
            1 => put::<1>(self.data, start, value),
            2 => put::<2>(self.data, start, value),
            4 => put::<4>(self.data, start, value),
            _ => put::<8>(self.data, start, value),
        }
    }

    /// Executes the instruction at `pc`. On error `pc` still points at the instruction.
    #[inline(always)]
    fn step(&mut self, code: &'a [u8]) -> Result<Flow, Trap> {
        let pc = self.pc as usize;
        let op = Opcode::from_u8(code[pc]).expect("verified opcode");
        let imm = pc + 1;
        let next = (pc + op.size()) as u32;
        let f32_of = |cell: u64| f32::from_bits(cell as u32);
        let f64_of = f64::from_bits;
        let cell_f32 = |v: f32| v.to_bits() as u64;
        let cell_bool = |b: bool| b as u64;
        use Opcode::*;
        match op {
            Nop => {}
            PushI32 => self.push(read_u32(code, imm) as i32 as i64 as u64)?,
            PushU32 => self.push(read_u32(code, imm) as u64)?,
            PushI64 => self.push(read_u64(code, imm))?,
            PushConst => self.push(
                self.image
                    .constant(read_u16(code, imm) as usize)
                    .expect("verified"),
            )?,
            Drop => {
                self.pop();
            }
            Dup => {
                let a = self.pop();
                self.push(a)?;
                self.push(a)?;
            }
            Swap => {
                let (a, b) = self.pop2();
                self.push(b)?;
                self.push(a)?;
            }
            Over => {
                let (a, b) = self.pop2();
                self.push(a)?;
                self.push(b)?;
                self.push(a)?;
            }
            LdAbs | LdRel | StAbs | StRel => {
                let ty = MemType::from_code(code[imm]).expect("verified");
                let mut address = read_u32(code, imm + 1) as u64;
                if matches!(op, LdRel | StRel) {
                    address += self.base as u64;
                }
                if matches!(op, LdAbs | LdRel) {
                    let v = self.load(ty, address)?;
                    self.push(v)?;
                } else {
                    let v = self.pop();
                    self.store(ty, address, v)?;
                }
            }
            LdInd => {
                let ty = MemType::from_code(code[imm]).expect("verified");
                let address = self
                    .pop()
                    .checked_add(read_u32(code, imm + 1) as u64)
                    .ok_or(Trap::InvalidAddress)?;
                let v = self.load(ty, address)?;
                self.push(v)?;
            }
            StInd => {
                let ty = MemType::from_code(code[imm]).expect("verified");
                let (address, v) = self.pop2();
                let address = address
                    .checked_add(read_u32(code, imm + 1) as u64)
                    .ok_or(Trap::InvalidAddress)?;
                self.store(ty, address, v)?;
            }
            LeaRel => self.push(self.base as u64 + read_u32(code, imm) as u64)?,
            Copy => {
                let len = read_u32(code, imm) as u64;
                let (dst, src) = self.pop2();
                let in_data = |a: u64| {
                    a.checked_add(len)
                        .is_some_and(|end| end <= self.data.len() as u64)
                };
                if !in_data(dst) || !in_data(src) {
                    return Err(Trap::InvalidAddress);
                }
                let (dst, src, len) = (dst as usize, src as usize, len as usize);
                self.data.copy_within(src..src + len, dst);
            }
            Now => self.push(self.now_ns as u64)?,
            Add | Sub | Mul | And | Or | Xor | Shl | ShrU | ShrS | Eq | Ne | LtS | LeS | GtS
            | GeS | LtU | LeU | GtU | GeU => {
                let (a, b) = self.pop2();
                let (sa, sb) = (a as i64, b as i64);
                let r = match op {
                    Add => a.wrapping_add(b),
                    Sub => a.wrapping_sub(b),
                    Mul => a.wrapping_mul(b),
                    And => a & b,
                    Or => a | b,
                    Xor => a ^ b,
                    Shl => a.checked_shl(b.min(64) as u32).unwrap_or(0),
                    ShrU => a.checked_shr(b.min(64) as u32).unwrap_or(0),
                    ShrS => (sa >> b.min(63)) as u64,
                    Eq => cell_bool(a == b),
                    Ne => cell_bool(a != b),
                    LtS => cell_bool(sa < sb),
                    LeS => cell_bool(sa <= sb),
                    GtS => cell_bool(sa > sb),
                    GeS => cell_bool(sa >= sb),
                    LtU => cell_bool(a < b),
                    LeU => cell_bool(a <= b),
                    GtU => cell_bool(a > b),
                    _ => cell_bool(a >= b),
                };
                self.push(r)?;
            }
            DivS | DivU | ModS | ModU => {
                let (a, b) = self.pop2();
                if b == 0 {
                    return Err(Trap::DivisionByZero);
                }
                let r = match op {
                    DivS => (a as i64).wrapping_div(b as i64) as u64,
                    DivU => a / b,
                    ModS => (a as i64).wrapping_rem(b as i64) as u64,
                    _ => a % b,
                };
                self.push(r)?;
            }
            Neg | AbsS | Not | NotBool => {
                let a = self.pop();
                let r = match op {
                    Neg => (a as i64).wrapping_neg() as u64,
                    AbsS => (a as i64).wrapping_abs() as u64,
                    Not => !a,
                    _ => cell_bool(a == 0),
                };
                self.push(r)?;
            }
            Rol | Ror => {
                let width = code[imm] as u32;
                let (a, n) = self.pop2();
                let r = rotate(a, n, width, op == Rol);
                self.push(r)?;
            }
            Sext | Zext => {
                let width = code[imm] as u32;
                let a = self.pop();
                let shift = 64 - width;
                let r = if op == Sext {
                    (((a << shift) as i64) >> shift) as u64
                } else {
                    (a << shift) >> shift
                };
                self.push(r)?;
            }
            Sel => {
                let b = self.pop();
                let a = self.pop();
                let g = self.pop();
                self.push(if g != 0 { b } else { a })?;
            }
            AddF32 | SubF32 | MulF32 | DivF32 | EqF32 | NeF32 | LtF32 | LeF32 | GtF32 | GeF32 => {
                let (a, b) = self.pop2();
                let (x, y) = (f32_of(a), f32_of(b));
                let r = match op {
                    AddF32 => cell_f32(x + y),
                    SubF32 => cell_f32(x - y),
                    MulF32 => cell_f32(x * y),
                    DivF32 => {
                        if y == 0.0 {
                            return Err(Trap::DivisionByZero);
                        }
                        cell_f32(x / y)
                    }
                    EqF32 => cell_bool(x == y),
                    NeF32 => cell_bool(x != y),
                    LtF32 => cell_bool(x < y),
                    LeF32 => cell_bool(x <= y),
                    GtF32 => cell_bool(x > y),
                    _ => cell_bool(x >= y),
                };
                self.push(r)?;
            }
            AddF64 | SubF64 | MulF64 | DivF64 | EqF64 | NeF64 | LtF64 | LeF64 | GtF64 | GeF64 => {
                let (a, b) = self.pop2();
                let (x, y) = (f64_of(a), f64_of(b));
                let r = match op {
                    AddF64 => (x + y).to_bits(),
                    SubF64 => (x - y).to_bits(),
                    MulF64 => (x * y).to_bits(),
                    DivF64 => {
                        if y == 0.0 {
                            return Err(Trap::DivisionByZero);
                        }
                        (x / y).to_bits()
                    }
                    EqF64 => cell_bool(x == y),
                    NeF64 => cell_bool(x != y),
                    LtF64 => cell_bool(x < y),
                    LeF64 => cell_bool(x <= y),
                    GtF64 => cell_bool(x > y),
                    _ => cell_bool(x >= y),
                };
                self.push(r)?;
            }
            NegF32 => {
                let a = self.pop();
                self.push(cell_f32(-f32_of(a)))?;
            }
            NegF64 => {
                let a = self.pop();
                self.push((-f64_of(a)).to_bits())?;
            }
            IToF32S | IToF32U | IToF64S | IToF64U | F32ToF64 | F64ToF32 => {
                let a = self.pop();
                let r = match op {
                    IToF32S => cell_f32(a as i64 as f32),
                    IToF32U => cell_f32(a as f32),
                    IToF64S => (a as i64 as f64).to_bits(),
                    IToF64U => (a as f64).to_bits(),
                    F32ToF64 => (f32_of(a) as f64).to_bits(),
                    _ => cell_f32(f64_of(a) as f32),
                };
                self.push(r)?;
            }
            F32ToInt | F64ToInt => {
                let target = MemType::from_code(code[imm]).expect("verified");
                let mode = RoundMode::from_code(code[imm + 1]).expect("verified");
                let a = self.pop();
                let x = if op == F32ToInt {
                    f32_of(a) as f64
                } else {
                    f64_of(a)
                };
                match crate::fmath::float_to_int(x, target, mode) {
                    Some(r) => self.push(r)?,
                    None => {
                        return Err(Trap::NumericError);
                    }
                }
            }
            Jmp => {
                self.pc = read_u32(code, imm);
                return Ok(Flow::Next);
            }
            Jz | Jnz => {
                let c = self.pop();
                if (c == 0) == (op == Jz) {
                    self.pc = read_u32(code, imm);
                    return Ok(Flow::Next);
                }
            }
            Call => {
                let callee = self
                    .image
                    .pou(read_u16(code, imm) as usize)
                    .expect("verified");
                let base = self.stack[self.sp - 1];
                if self.call_depth >= self.calls.len() {
                    return Err(Trap::CallDepth);
                }
                if base
                    .checked_add(callee.frame_size as u64)
                    .is_none_or(|end| end > self.data.len() as u64)
                {
                    return Err(Trap::InvalidAddress);
                }
                self.pop();
                self.calls[self.call_depth] = CallFrame {
                    return_pc: next,
                    saved_base: self.base,
                };
                self.call_depth += 1;
                self.base = base as u32;
                self.pc = callee.code_start;
                return Ok(Flow::Next);
            }
            Ret => {
                self.call_depth -= 1;
                let frame = self.calls[self.call_depth];
                if self.call_depth == 0 {
                    return Ok(Flow::EndOfCycle);
                }
                self.pc = frame.return_pc;
                self.base = frame.saved_base;
                return Ok(Flow::Next);
            }
            CallBuiltin => {
                let builtin = crate::isa::Builtin::from_u16(read_u16(code, imm)).expect("verified");
                let argc = builtin.args();
                let args_start = self.sp - argc;
                let mut args = [0u64; 8];
                args[..argc].copy_from_slice(&self.stack[args_start..self.sp]);
                let result = builtins::call(builtin, &args[..argc], self.data)?;
                self.sp = args_start;
                if let Some(r) = result {
                    self.push(r)?;
                }
            }
            ChkIndex | ChkRangeS | ChkRangeU => {
                let v = self.stack[self.sp - 1];
                let (lo, hi) = (read_u64(code, imm), read_u64(code, imm + 8));
                let ok = if op == ChkRangeU {
                    lo <= v && v <= hi
                } else {
                    (lo as i64) <= (v as i64) && (v as i64) <= (hi as i64)
                };
                if !ok {
                    return Err(if op == ChkIndex {
                        Trap::IndexOutOfBounds
                    } else {
                        Trap::SubrangeViolation
                    });
                }
            }
            AddImm => {
                let a = self.pop();
                self.push(a.wrapping_add(read_u32(code, imm) as i32 as i64 as u64))?;
            }
            JumpIf | JumpIfNot => {
                let cmp = Opcode::from_u8(code[imm]).expect("verified");
                let (a, b) = self.pop2();
                if crate::isa::compare(cmp, a, b) == (op == JumpIf) {
                    self.pc = read_u32(code, imm + 1);
                    return Ok(Flow::Next);
                }
            }
            Index => {
                let (lo, hi) = (read_u64(code, imm) as i64, read_u64(code, imm + 8) as i64);
                let stride = read_u32(code, imm + 16) as u64;
                let (base, i) = self.pop2();
                if (i as i64) < lo || (i as i64) > hi {
                    return Err(Trap::IndexOutOfBounds);
                }
                let offset = (i as i64).wrapping_sub(lo) as u64;
                self.push(base.wrapping_add(offset.wrapping_mul(stride)))?;
            }
            TryBegin => {
                let slot = self
                    .tries
                    .get_mut(self.try_depth)
                    .ok_or(Trap::StackOverflow)?;
                *slot = TryFrame {
                    handler: read_u32(code, imm),
                    stack_depth: self.sp as u32,
                    call_depth: self.call_depth as u32,
                    base: self.base,
                };
                self.try_depth += 1;
            }
            TryEnd => self.try_depth = self.try_depth.saturating_sub(1),
            Throw => return Err(Trap::from_u64(code[imm] as u64).expect("verified")),
            Rethrow => {
                let c = self.pop();
                if c != 0 {
                    return Err(match Trap::from_u64(c) {
                        Some(trap) if trap.is_catchable() => trap,
                        _ => Trap::NumericError,
                    });
                }
            }
        }
        self.pc = next;
        Ok(Flow::Next)
    }

    // ---- monitor ----

    /// Reads a variable by name.
    pub fn read_var(&self, name: &str) -> Result<Value<'_>, VarError> {
        let var = self.image.find_var(name).ok_or(VarError::UnknownName)?;
        Ok(self.read_entry(&var))
    }

    /// Reads a variable-map entry (verified to lie inside data memory).
    pub fn read_entry(&self, var: &Var<'_>) -> Value<'_> {
        let ty = VarType::from_code(var.ty).expect("verified");
        let at = var.addr as usize;
        let Some(mem) = ty.mem_type() else {
            let bytes = &self.data[at..at + var.size as usize];
            let capacity = var.size as usize - 4;
            let len = (read_u16(bytes, 2) as usize)
                .min(capacity)
                .min(read_u16(bytes, 0) as usize);
            return Value::String(&bytes[4..4 + len]);
        };
        let cell = mem.cell_from_le(&self.data[at..at + mem.width()]);
        match ty {
            VarType::Bool => Value::Bool(cell != 0),
            VarType::SInt | VarType::Int | VarType::DInt | VarType::LInt => Value::Int(cell as i64),
            VarType::Time => Value::Time(cell as i64),
            VarType::Real => Value::Real(f32::from_bits(cell as u32)),
            VarType::LReal => Value::LReal(f64::from_bits(cell)),
            _ => Value::UInt(cell),
        }
    }

    /// Writes a variable by name (once; the program may change it again). Integers are
    /// truncated to the variable's width; strings to its capacity. `Int`/`UInt` are accepted
    /// for any integer type, `Int` also for TIME.
    pub fn write_var(&mut self, name: &str, value: Value<'_>) -> Result<(), VarError> {
        let var = self.image.find_var(name).ok_or(VarError::UnknownName)?;
        if var.flags & VAR_FLAG_CONSTANT != 0 {
            return Err(VarError::Constant);
        }
        let ty = VarType::from_code(var.ty).expect("verified");
        let at = var.addr as usize;
        if ty.mem_type().is_none() {
            let Value::String(text) = value else {
                return Err(VarError::TypeMismatch);
            };
            let capacity = (var.size as usize - 4).min(read_u16(self.data, at) as usize);
            let len = text.len().min(capacity);
            self.data[at + 2..at + 4].copy_from_slice(&(len as u16).to_le_bytes());
            self.data[at + 4..at + 4 + len].copy_from_slice(&text[..len]);
            return Ok(());
        }
        let forced = Self::encode_scalar(&var, ty, value)?;
        self.write_forced(&forced);
        Ok(())
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
        if ty.mem_type().is_none() {
            return Err(VarError::NotForceable);
        }
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
        let mem = ty.mem_type().ok_or(VarError::NotForceable)?;
        if var.flags & VAR_FLAG_CONSTANT != 0 {
            return Err(VarError::Constant);
        }
        if bytes.len() != mem.width() {
            return Err(VarError::TypeMismatch);
        }
        let mut cell = [0u8; 8];
        cell[..bytes.len()].copy_from_slice(bytes);
        let value = u64::from_le_bytes(cell);
        let value = match ty {
            VarType::Bool => Value::Bool(value != 0),
            VarType::Real => Value::Real(f32::from_bits(value as u32)),
            VarType::LReal => Value::LReal(f64::from_bits(value)),
            VarType::Time => Value::Time(value as i64),
            _ => Value::UInt(value),
        };
        self.force_var(name, value)
    }

    /// Ends all forcing.
    pub fn clear_forces(&mut self) {
        self.forces = [None; MAX_FORCES];
        self.any_forced = false;
    }

    fn encode_scalar(var: &Var<'_>, ty: VarType, value: Value<'_>) -> Result<Forced, VarError> {
        let mem = ty.mem_type().ok_or(VarError::NotForceable)?;
        let cell = match (ty, value) {
            (VarType::Bool, Value::Bool(b)) => b as u64,
            (VarType::Real, Value::Real(r)) => r.to_bits() as u64,
            (VarType::LReal, Value::LReal(r)) => r.to_bits(),
            (VarType::Time, Value::Time(t) | Value::Int(t)) => t as u64,
            (VarType::Bool | VarType::Real | VarType::LReal | VarType::Time, _) => {
                return Err(VarError::TypeMismatch);
            }
            (_, Value::Int(i)) => i as u64,
            (_, Value::UInt(u)) => u,
            _ => return Err(VarError::TypeMismatch),
        };
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

    fn apply_forces(&mut self) {
        if !self.any_forced {
            return;
        }
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
