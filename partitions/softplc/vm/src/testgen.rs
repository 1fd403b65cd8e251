//! Random verified images for differential testing (feature `model`): the generator of the
//! VM's own differential test (`tests/differential.rs`, compiled here too), so that another
//! execution tier (the native tier, crate `plc-native`) is checked against the reference
//! model on exactly the programs, data layout and limits the VM is checked on.
//!
//! Test support only: nothing here runs in a partition.

/// Data size of the test programs.
pub const DATA: u32 = 512;
/// Where the test program's instance frame starts.
pub const MAIN_BASE: u32 = 256;
/// The test program's frame size.
pub const MAIN_FRAME: u32 = 64;

/// Operand-stack cells of the test machines (small, so STACK_OVERFLOW is reachable).
pub const STACK: usize = 32;
/// Call frames of the test machines.
pub const CALLS: usize = 8;
/// Try frames of the test machines.
pub const TRIES: usize = 4;

#[cfg(not(test))]
use crate::image::{Image, ImageBuilder, PouId, TaskDef, TaskKind};
#[cfg(not(test))]
use crate::verify::verify;
#[cfg(not(test))]
use crate::vm::{CallFrame, Machine, Memory, TryFrame};
#[cfg(not(test))]
use alloc::vec;
#[cfg(not(test))]
use alloc::vec::Vec;

#[cfg(not(test))]
#[allow(dead_code)] // its tests and their helpers are the VM's
#[path = "tests/differential.rs"]
mod differential;

#[cfg(not(test))]
pub use differential::{random_program, random_program_with};

#[cfg(test)]
pub use crate::tests::differential::{random_program, random_program_with};
