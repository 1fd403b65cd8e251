//! x86_64 hardware glue: the only place with privileged instructions and MMIO.
//! Keep each file thin; decisions belong to the portable modules.

pub mod cpu;
pub mod entry;
pub mod fpu;
pub mod gdt;
pub mod hpet;
pub mod idt;
pub mod ioapic;
pub mod lapic;
pub mod pci;
pub mod pic;
pub mod pit;
pub mod serial;
pub mod smp;
pub mod stack;
pub mod syscall;
pub mod vtd;
