//! The microkernel: the only code in ring 0.
//!
//! What it is for: hardware bring-up (GDT/TSS/IDT, interrupt controllers, timers), the
//! physical frame allocator, and (in later stages) tasks, threads, IPC and time partitions.
//! What it must never do: hold policy (that belongs to the system software), allocate from a
//! heap after boot ([`heap::BootHeap`] refuses), or loop without bound over user input.
//!
//! Hardware glue lives in [`arch`]; the pure logic ([`mem::frames`], [`acpi`] parsing, log
//! formatting) is host-testable with `cargo test -p kernel --lib`.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_op_in_unsafe_fn)]

pub mod acpi;
pub mod arch;
pub mod boot;
pub mod fault;
pub mod heap;
pub mod ipc;
pub mod irq;
pub mod log;
pub mod mem;
pub mod qemu;
pub mod rp;
pub mod sched;
pub mod state;
pub mod syscall;
pub mod task;
pub mod thread;
pub mod time;
pub mod timepart;

#[cfg(test)]
mod tests;

#[cfg(feature = "test-hooks")]
pub mod test_hooks;
