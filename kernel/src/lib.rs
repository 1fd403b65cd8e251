//! The microkernel: the only code in ring 0.
//!
//! What it is for: hardware bring-up (GDT/TSS/IDT, interrupt controllers, timers), the
//! physical frame allocator, and the kernel objects: tasks, threads, abilities, resource
//! partitions, address spaces, synchronous IPC, notifications, exceptions as messages, time
//! partitions, interrupt lines and I/O-port grants (`docs/architecture.md` maps each to its
//! file). What it must never do: hold policy (that belongs to the system software),
//! allocate from a heap (it has none: the loader parses the firmware's tables into the
//! fixed-size `abi::machine::Machine`), panic on anything user space or a validated
//! configuration hands it, or loop without bound over user input.
//!
//! Hardware glue lives in [`arch`]; the pure logic (object operations through the syscall
//! dispatcher, scheduling, time partitions, [`mem::frames`], log formatting) is
//! host-testable with `cargo test -p kernel --lib`. `unsafe` is allowed only where hardware
//! or raw memory demands it: [`arch`], [`mem`], [`boot`] and the functions marked with
//! their own `allow`.
#![cfg_attr(not(test), no_std)]

#[allow(unsafe_code)] // descriptor tables, port and register access, entry stubs
pub mod arch;
#[allow(unsafe_code)] // bring-up: boot information and the image in physical memory
pub mod boot;
pub mod fault;
pub mod io;
pub mod ipc;
pub mod irq;
pub mod log;
#[allow(unsafe_code)] // page tables and frames through the direct map
pub mod mem;
pub mod qemu;
pub mod rp;
pub mod sched;
pub mod state;
pub mod syscall;
pub mod table;
pub mod task;
pub mod thread;
pub mod time;
pub mod timepart;

// Host tests of the object logic through the dispatcher; kept outside `src` so that the
// ring-0 code budget counts only what runs in ring 0.
#[cfg(test)]
#[path = "../host-tests/objects.rs"]
mod tests;

// Test hooks, which only scenario images contain (feature `test-hooks`); outside `src` for
// the same reason as the host tests: the budget counts what the shipped kernel runs.
#[cfg(feature = "test-hooks")]
#[path = "../test-hooks.rs"]
pub mod test_hooks;
