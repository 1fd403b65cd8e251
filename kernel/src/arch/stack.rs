//! The kernel stack. The kernel is non-preemptible and runs with interrupts off, so one
//! stack per CPU suffices (docs/architecture.md, kernel model): the code of every entry from
//! user mode (syscall, interrupt, exception) starts at its top, once the entry stub saved the
//! user registers in the thread's context (arch::entry), and the boot path that first used
//! it never returns. No per-thread kernel stacks means no kernel memory per thread for stacks.

pub const KERNEL_STACK_SIZE: usize = 64 * 1024;

#[repr(C, align(16))]
pub struct KernelStack(pub [u8; KERNEL_STACK_SIZE]);

pub static mut KERNEL_STACK: KernelStack = KernelStack([0; KERNEL_STACK_SIZE]);

pub fn top() -> u64 {
    core::ptr::addr_of!(KERNEL_STACK) as u64 + KERNEL_STACK_SIZE as u64
}
