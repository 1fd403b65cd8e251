//! Soft-PLC bytecode: image format, verifier and interpreter (no_std, no allocation while running).
//!
//! # Machine model (what the compiler targets)
//!
//! * **Operand stack** of 64-bit cells. Integers are two's-complement `i64` (unsigned values
//!   zero-extended), `REAL` is the f32 bit pattern in the low 32 bits, `LREAL` the f64 bit
//!   pattern, `BOOL` 0/1, `TIME` an `i64` count of **nanoseconds**, addresses unsigned byte
//!   offsets into data memory.
//! * **Data memory**: one byte array of `data_size` bytes (from the image), little-endian.
//!   Initialised from the image's INIT section (rest zero). Typed loads/stores
//!   (`LD_*/ST_*` with a [`isa::MemType`]) sign/zero-extend on load and truncate on store, so
//!   integer arithmetic is done in 64 bits and **integer overflow wraps to the declared width
//!   when stored** (use `SEXT`/`ZEXT` to wrap an intermediate, e.g. before a comparison).
//!   REAL operations round to f32 after each operation, LREAL operations are f64.
//! * **Addressing**: absolute (`LD_ABS addr`, globals and program instances), frame-relative
//!   (`LD_REL off` = `base + off`; `base` is the frame-base register, set by `CALL` to the
//!   callee's data block, i.e. the FB instance or the function's static frame) and indirect
//!   (`LD_IND off` with an address on the stack, for arrays, struct members, VAR_IN_OUT).
//!   Static addresses are checked by the verifier; dynamic ones trap `INVALID_ADDRESS`.
//! * **POUs** (functions, FBs, programs) are entries of the POU table: code range, `frame_size`,
//!   `arg_cells`, `ret_cells`. `CALL p` pops the callee's base address, checks
//!   `base + frame_size <= data_size`, and the top `arg_cells` cells become the callee's stack;
//!   `RET` leaves exactly `ret_cells` cells. Parameters may equally be passed through the
//!   callee's frame (store them with `ST_IND` before the call, use `arg_cells = 0`).
//!   No recursion is needed by IEC, but it works up to the call-frame capacity (`CALL_DEPTH`).
//! * **Tasks**: entries of the task table name a program POU (0 args, 0 results) and its
//!   instance base; one cycle = one call of that POU ended by its final `RET`, with an
//!   instruction budget (watchdog) per cycle. `NOW` pushes the cycle time (constant per cycle).
//! * **Traps** ([`isa::Trap`], stable codes 1..=8) unwind to the innermost try frame of the cycle
//!   (`TRY_BEGIN handler` .. `TRY_END`): the stack is cut back to the depth at `TRY_BEGIN`,
//!   the trap code is pushed and execution continues at `handler` — the compiler stores that
//!   code in the `e : __EXCEPTION` variable (`RETHROW` re-raises it, 0 = none). `WATCHDOG` is
//!   never caught. An uncaught trap ends the cycle with a [`vm::Fault`] (trap, code offset,
//!   source location) and marks the task faulted until [`vm::Machine::reset_task`].
//! * **Builtins** (`CALL_BUILTIN id`, [`isa::Builtin`]): math for REAL/LREAL and STRING functions
//!   working on string variables in data memory (`max_len u16, len u16, bytes[max_len]`).
//! * **Checks**: `CHK_INDEX lo hi` (INDEX_OUT_OF_BOUNDS), `CHK_RANGE_S/U lo hi`
//!   (SUBRANGE_VIOLATION) leave the checked value on the stack; `INDEX lo hi stride` computes an
//!   array element address with the index check in one instruction.
//! * **Fused forms** (`INDEX`, `ADD_IMM`, `JUMP_IF`, `JUMP_IF_NOT` and the superinstructions
//!   `0xC0..=0xD6`: array elements, increments, MIN/MAX, operators and comparisons with
//!   immediate or frame/static operands) exist only to cut dispatches; the builder produces
//!   them from the plain sequences automatically (see [`isa`], "Fused instructions and
//!   superinstructions").
//!
//! # Semantics worth knowing
//!
//! * A trapping instruction has **no effect**: the stack, data memory and `pc` are as before it
//!   (a fault reports that `pc`; a caught trap then unwinds as described above).
//! * The watchdog counts executed instructions; the budget is exact (a cycle of N instructions
//!   needs a budget >= N).
//! * Float division by zero traps DIVISION_BY_ZERO (rather than producing infinity);
//!   float->integer conversions trap NUMERIC_ERROR for NaN, infinities and out-of-range values;
//!   `REAL_TO_INT`-style rounding is to nearest with ties **away from zero** (2.5 -> 3).
//! * Everything is deterministic: the math library ([`fmath`]) uses only IEEE basic operations,
//!   and a NaN that REAL/LREAL `+ - * /` produce is the canonical quiet NaN (which operand's
//!   NaN the hardware would pass on depends on the machine code; [`isa::real_result`]).
//!
//! # Limits
//!
//! | what | limit |
//! |---|---|
//! | operand stack | `Memory::stack.len()` cells (STACK_OVERFLOW); per POU activation at most [`verify::MAX_POU_STACK`] (verifier) |
//! | call depth | `Memory::calls.len()` frames including the task's own (CALL_DEPTH) |
//! | open try blocks | `Memory::tries.len()` (STACK_OVERFLOW); per POU [`verify::MAX_TRY_NESTING`] (verifier) |
//! | tasks | [`verify::MAX_TASKS`] |
//! | string results | [`builtins::MAX_STRING_LEN`] bytes |
//! | data memory | `u32` addresses |
//!
//! # Using it
//!
//! Compiler: `image::ImageBuilder` (feature `alloc`) → bytes. Runtime: [`image::Image::parse`]
//! → `verify::verify` (feature `alloc`) or [`verify::verify_with_scratch`] (no allocation) →
//! [`vm::Machine::new`] with caller-provided memory → [`vm::Machine::run_cycle`]; monitor with
//! [`vm::Machine::read_var`] / [`vm::Machine::write_var`]. The executable reference model is
//! `model::Model` (feature `model`, needs `alloc`), and `testgen` (the same feature) the
//! random verified images of the differential tests. A program translated to native code
//! (crate `plc-native`) runs on the same machine with [`vm::Machine::run_cycle_native`]; its
//! run-time side is [`native`].
//!
//! ```text
//! let image = Image::parse(&bytes)?;
//! let verified = plc_vm::verify::verify(&image)?;
//! let mut data = vec![0u8; image.data_size() as usize];
//! let (mut stack, mut calls, mut tries) = ([0u64; 256], [CallFrame::EMPTY; 32], [TryFrame::EMPTY; 16]);
//! let mut machine = Machine::new(verified, Memory { data: &mut data, stack: &mut stack, calls: &mut calls, tries: &mut tries })?;
//! match machine.run_cycle(0, now_ns) {
//!     Ok(stats) => {}
//!     Err(fault) => { /* set safe outputs; fault.trap, fault.location */ }
//! }
//! ```
#![no_std]
#![warn(missing_docs)]

#[cfg(any(feature = "alloc", test))]
extern crate alloc;
#[cfg(test)]
extern crate std;

pub mod builtins;
pub mod fmath;
pub mod image;
pub mod isa;
pub mod literal;
pub mod located;
pub mod monitor;
pub mod native;
pub mod verify;
pub mod vm;

pub use image::{Image, ImageError};
pub use isa::{Builtin, MemType, Opcode, RoundMode, TimeKind, Trap};
#[cfg(any(feature = "alloc", test))]
pub use verify::verify;
pub use verify::{VerifiedImage, VerifyError, verify_with_scratch};
pub use vm::{CallFrame, CycleStats, Fault, Machine, Memory, TryFrame, Value};
#[cfg(any(feature = "model", test))]
pub mod model;
#[cfg(any(feature = "model", test))]
pub mod testgen;

#[cfg(test)]
mod tests;
