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
//!   (SUBRANGE_VIOLATION) leave the checked value on the stack.
//!
//! # Using it
//!
//! Compiler: [`image::ImageBuilder`] (feature `alloc`) → bytes. Runtime: [`image::Image::parse`]
//! → [`verify::verify`] → [`vm::Machine::new`] with caller-provided memory → `run_cycle`.
//! The executable reference model is [`model`] (feature `model`, needs `alloc`).
#![no_std]
#![forbid(unsafe_op_in_unsafe_fn)]
#![deny(unsafe_code)]
#![warn(missing_docs)]

#[cfg(any(feature = "alloc", test))]
extern crate alloc;
#[cfg(test)]
extern crate std;

pub mod image;
pub mod isa;
pub mod verify;
pub mod builtins;
pub mod fmath;
pub mod vm;

pub use image::{Image, ImageError};
pub use isa::{Builtin, MemType, Opcode, RoundMode, Trap};
pub use verify::{VerifiedImage, VerifyError, verify_with_scratch};
#[cfg(any(feature = "alloc", test))]
pub use verify::verify;
pub use vm::{CallFrame, CycleStats, Fault, Machine, Memory, TryFrame, Value};
#[cfg(any(feature = "model", test))]
pub mod model;
