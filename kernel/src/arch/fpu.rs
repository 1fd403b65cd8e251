//! Per-thread FPU/SSE state and FS/GS bases. The kernel itself is soft-float and never
//! touches these registers, so they hold the running thread's values until a switch.

use crate::thread::FpuState;
use core::arch::asm;
use x86_64::registers::model_specific::Msr;

const IA32_FS_BASE: u32 = 0xc000_0100;
/// The thread's GS base while the kernel runs (`swapgs` makes it GS's on the way to ring 3;
/// the kernel's own is its CPU's entry block, `entry::init_cpu`).
const IA32_KERNEL_GS_BASE: u32 = 0xc000_0102;

pub fn save(area: &mut FpuState) {
    // SAFETY: FXSAVE writes 512 bytes to a 16-byte-aligned area, which FpuState is.
    unsafe { asm!("fxsave64 [{}]", in(reg) area.0.as_mut_ptr(), options(nostack)) };
}

pub fn restore(area: &FpuState) {
    // SAFETY: the area holds an FXSAVE image (from `save` or `FpuState::initial`, whose
    // reserved bits are zero and MXCSR valid), so FXRSTOR cannot fault.
    unsafe { asm!("fxrstor64 [{}]", in(reg) area.0.as_ptr(), options(nostack, readonly)) };
}

/// Loads a thread's FS and GS bases (canonical user addresses, checked by the callers).
pub fn set_bases(fs: u64, gs: u64) {
    // SAFETY: writing the base MSR only changes what user-mode FS accesses address; the
    // kernel does not use FS.
    unsafe { Msr::new(IA32_FS_BASE).write(fs) };
    // SAFETY: likewise for GS in user mode; the kernel's GS base is not this MSR.
    unsafe { Msr::new(IA32_KERNEL_GS_BASE).write(gs) };
}
