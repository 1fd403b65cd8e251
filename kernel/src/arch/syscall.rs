//! `syscall`/`sysret` entry. Single CPU, interrupts masked on entry (SFMASK), so the user
//! stack pointer can be parked in a static while the stub switches to the kernel stack.

use super::stack::{KERNEL_STACK, KERNEL_STACK_SIZE};
use core::arch::naked_asm;
use x86_64::registers::model_specific::Msr;

/// User registers at `syscall`, lowest address first. `rcx` holds the user RIP and `r11`
/// the user RFLAGS (the CPU put them there).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct SyscallFrame {
    pub r15: u64,
    pub r14: u64,
    pub r13: u64,
    pub r12: u64,
    pub r11: u64,
    pub r10: u64,
    pub r9: u64,
    pub r8: u64,
    pub rbp: u64,
    pub rdi: u64,
    pub rsi: u64,
    pub rdx: u64,
    pub rcx: u64,
    pub rbx: u64,
    pub rax: u64,
    pub user_rsp: u64,
}

static mut USER_RSP: u64 = 0;

const IA32_STAR: u32 = 0xc000_0081;
const IA32_LSTAR: u32 = 0xc000_0082;
const IA32_FMASK: u32 = 0xc000_0084;
/// RFLAGS bits cleared on entry: TF, IF, DF, AC, NT.
const ENTRY_RFLAGS_MASK: u64 = (1 << 8) | (1 << 9) | (1 << 10) | (1 << 18) | (1 << 14);

#[unsafe(naked)]
unsafe extern "sysv64" fn syscall_entry() {
    naked_asm!(
        "mov [rip + {user_rsp}], rsp",
        "lea rsp, [rip + {stack} + {size}]",
        "push qword ptr [rip + {user_rsp}]",
        "push rax", "push rbx", "push rcx", "push rdx", "push rsi", "push rdi", "push rbp",
        "push r8", "push r9", "push r10", "push r11", "push r12", "push r13", "push r14", "push r15",
        "mov rdi, rsp",
        "cld",
        "call {dispatch}",
        "pop r15", "pop r14", "pop r13", "pop r12", "pop r11", "pop r10", "pop r9", "pop r8",
        "pop rbp", "pop rdi", "pop rsi", "pop rdx", "pop rcx", "pop rbx", "pop rax",
        "pop rsp",
        "sysretq",
        user_rsp = sym USER_RSP,
        stack = sym KERNEL_STACK,
        size = const KERNEL_STACK_SIZE,
        dispatch = sym dispatch,
    )
}

extern "sysv64" fn dispatch(frame: &mut SyscallFrame) {
    crate::syscall::dispatch(frame);
    // SYSRET to a non-canonical RIP would fault in ring 0 on Intel CPUs: never allow it.
    if frame.rcx >= abi::syscall::USER_END {
        panic!("syscall return to non-user RIP {:#x}", frame.rcx);
    }
}

pub fn init() {
    let selectors = super::gdt::selectors();
    // SYSRET loads CS = STAR[63:48] + 16 and SS = STAR[63:48] + 8 (user code follows user data).
    let sysret_base = selectors.user_data.0 as u64 - 8;
    let star = (sysret_base << 48) | ((selectors.kernel_code.0 as u64) << 32);
    // SAFETY: the selectors match the GDT layout SYSCALL/SYSRET expect (gdt.rs), and LSTAR
    // points to the entry stub above; EFER.SCE only enables the instruction.
    unsafe {
        Msr::new(IA32_STAR).write(star);
        Msr::new(IA32_LSTAR).write(syscall_entry as *const () as u64);
        Msr::new(IA32_FMASK).write(ENTRY_RFLAGS_MASK);
        x86_64::registers::model_specific::Efer::update(|f| {
            f.insert(x86_64::registers::model_specific::EferFlags::SYSTEM_CALL_EXTENSIONS)
        });
    }
}
