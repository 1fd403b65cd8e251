//! `syscall`/`sysret` set-up (the entry stub itself is in [`entry`](super::entry)).

use x86_64::registers::model_specific::Msr;

const IA32_STAR: u32 = 0xc000_0081;
const IA32_LSTAR: u32 = 0xc000_0082;
const IA32_FMASK: u32 = 0xc000_0084;
/// RFLAGS bits cleared on entry: TF, IF, DF, AC, NT (the kernel runs with interrupts off).
const ENTRY_RFLAGS_MASK: u64 = (1 << 8) | (1 << 9) | (1 << 10) | (1 << 18) | (1 << 14);

/// Sets up `syscall` on this CPU, entry block `cpu` with its kernel stack's top and its
/// TSS (the entry stubs' per-CPU data, `entry::init_cpu`).
pub fn init(cpu: usize, kernel_stack_top: u64, tss: *mut super::gdt::TssBlock) {
    super::entry::init_cpu(cpu, kernel_stack_top, tss);
    let selectors = super::gdt::selectors();
    // SYSRET loads CS = STAR[63:48] + 16 and SS = STAR[63:48] + 8 (user code follows user data).
    let sysret_base = selectors.user_data.0 as u64 - 8;
    let star = (sysret_base << 48) | ((selectors.kernel_code.0 as u64) << 32);
    // SAFETY: the selectors match the GDT layout SYSCALL/SYSRET expect (gdt.rs).
    unsafe { Msr::new(IA32_STAR).write(star) };
    // SAFETY: LSTAR points to the entry stub.
    unsafe { Msr::new(IA32_LSTAR).write(super::entry::syscall_entry as *const () as u64) };
    // SAFETY: the flags cleared on entry (interrupts off, DF clear, ...).
    unsafe { Msr::new(IA32_FMASK).write(ENTRY_RFLAGS_MASK) };
    // SAFETY: EFER.SCE only enables the instruction, whose MSRs are set above.
    unsafe {
        x86_64::registers::model_specific::Efer::update(|f| {
            f.insert(x86_64::registers::model_specific::EferFlags::SYSTEM_CALL_EXTENSIONS)
        })
    };
}
