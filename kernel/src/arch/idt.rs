//! The IDT and the interrupt/exception entry stubs (stable-Rust naked functions).
//!
//! Every stub pushes a uniform [`TrapFrame`] (a dummy error code where the CPU pushes none,
//! then the vector) and calls [`dispatch`]. CPU exceptions in the kernel are fatal: they are
//! reported (vector name, error code, RIP, RSP, CR2 for #PF, all registers) and the run ends
//! with the failure exit.

use super::gdt;
use super::ioapic::LINE_VECTOR_BASE;
use crate::kprintln;
use core::arch::naked_asm;
use spin::Lazy;
use x86_64::VirtAddr;
use x86_64::instructions::tables::lidt;
use x86_64::structures::DescriptorTablePointer;

/// Vector of the local APIC timer.
pub const TIMER_VECTOR: u8 = 0x30;
/// Another CPU changed this one's state (`arch::smp::send_reschedule`).
pub const RESCHEDULE_VECTOR: u8 = 0x31;
/// Another CPU asks this one to flush or leave an address space (`arch::smp`).
pub const SPACE_VECTOR: u8 = 0x32;
/// Vector the local APIC uses for spurious interrupts (must end in 0xf on old CPUs).
pub const SPURIOUS_VECTOR: u8 = 0xff;

/// Defines [`TrapFrame`] and its all-zero value from one list of its fields.
macro_rules! trap_frame {
    ($($field:ident)*) => {
        /// Register state saved by the entry stubs, lowest address first (the last five
        /// words, from `rip`, pushed by the CPU). A thread's saved context is one, and the
        /// CPU pushes those five words of an interrupt from ring 3 right into it, at the
        /// 16-byte-aligned stack top it is given (hence the alignment).
        #[repr(C, align(16))]
        #[derive(Clone, Copy, Debug)]
        pub struct TrapFrame { $(pub $field: u64,)* }
        impl TrapFrame {
            /// Every register zero (a const, for the static thread table).
            pub const ZERO: Self = Self { $($field: 0,)* };
        }
    };
}
trap_frame! {
    r15 r14 r13 r12 r11 r10 r9 r8 rbp rdi rsi rdx rcx rbx rax vector error_code
    rip cs rflags rsp ss
}

/// Short mnemonic and description of each architectural exception vector.
pub fn exception_name(vector: u64) -> (&'static str, &'static str) {
    const NAMES: [(&str, &str); 32] = [
        ("#DE", "divide error"),
        ("#DB", "debug"),
        ("NMI", "non-maskable interrupt"),
        ("#BP", "breakpoint"),
        ("#OF", "overflow"),
        ("#BR", "bound range exceeded"),
        ("#UD", "invalid opcode"),
        ("#NM", "device not available"),
        ("#DF", "double fault"),
        ("#CSO", "coprocessor segment overrun"),
        ("#TS", "invalid TSS"),
        ("#NP", "segment not present"),
        ("#SS", "stack-segment fault"),
        ("#GP", "general protection fault"),
        ("#PF", "page fault"),
        ("#15", "reserved"),
        ("#MF", "x87 floating-point error"),
        ("#AC", "alignment check"),
        ("#MC", "machine check"),
        ("#XM", "SIMD floating-point exception"),
        ("#VE", "virtualization exception"),
        ("#CP", "control protection"),
        ("#22", "reserved"),
        ("#23", "reserved"),
        ("#24", "reserved"),
        ("#25", "reserved"),
        ("#26", "reserved"),
        ("#27", "reserved"),
        ("#HV", "hypervisor injection"),
        ("#VC", "VMM communication"),
        ("#SX", "security exception"),
        ("#31", "reserved"),
    ];
    NAMES
        .get(vector as usize)
        .copied()
        .unwrap_or(("#??", "not an exception"))
}

#[unsafe(naked)]
unsafe extern "sysv64" fn common_entry() {
    naked_asm!(
        "push rax", "push rbx", "push rcx", "push rdx", "push rsi", "push rdi", "push rbp",
        "push r8", "push r9", "push r10", "push r11", "push r12", "push r13", "push r14", "push r15",
        "mov rdi, rsp",
        "cld",
        // From ring 3 the frame is the running thread's context (entry.rs): the code runs
        // on the CPU's kernel stack and returns through the thread then active, GS swapped
        // on the way in and out. From ring 0 (the halt loop) it stays where it is.
        "test qword ptr [rsp + {cs}], 3",
        "jz 2f",
        "swapgs",
        "mov rsp, gs:[{stack}]",
        "call {dispatch}",
        "mov rsp, gs:[{active}]",
        "jmp 3f",
        "2:",
        "call {dispatch}",
        "3:",
        "pop r15", "pop r14", "pop r13", "pop r12", "pop r11", "pop r10", "pop r9", "pop r8",
        "pop rbp", "pop rdi", "pop rsi", "pop rdx", "pop rcx", "pop rbx", "pop rax",
        "add rsp, 16",
        // Back to ring 3 (the CS of the frame returned through): GS as the thread had it.
        "test qword ptr [rsp + 8], 3",
        "jz 4f",
        "swapgs",
        "4:",
        "iretq",
        dispatch = sym dispatch,
        cs = const core::mem::offset_of!(TrapFrame, cs),
        active = const core::mem::offset_of!(super::entry::CpuEntry, active_frame),
        stack = const core::mem::offset_of!(super::entry::CpuEntry, stack_top),
    )
}

macro_rules! stub {
    ($name:ident, $vector:expr, error_code) => {
        #[unsafe(naked)]
        unsafe extern "sysv64" fn $name() {
            naked_asm!("push {v}", "jmp {c}", v = const $vector, c = sym common_entry)
        }
    };
    ($name:ident, $vector:expr) => {
        #[unsafe(naked)]
        unsafe extern "sysv64" fn $name() {
            naked_asm!("push 0", "push {v}", "jmp {c}", v = const $vector, c = sym common_entry)
        }
    };
}

stub!(vec0, 0);
stub!(vec1, 1);
stub!(vec2, 2);
stub!(vec3, 3);
stub!(vec4, 4);
stub!(vec5, 5);
stub!(vec6, 6);
stub!(vec7, 7);
stub!(vec8, 8, error_code);
stub!(vec9, 9);
stub!(vec10, 10, error_code);
stub!(vec11, 11, error_code);
stub!(vec12, 12, error_code);
stub!(vec13, 13, error_code);
stub!(vec14, 14, error_code);
stub!(vec15, 15);
stub!(vec16, 16);
stub!(vec17, 17, error_code);
stub!(vec18, 18);
stub!(vec19, 19);
stub!(vec20, 20);
stub!(vec21, 21, error_code);
stub!(vec22, 22);
stub!(vec23, 23);
stub!(vec24, 24);
stub!(vec25, 25);
stub!(vec26, 26);
stub!(vec27, 27);
stub!(vec28, 28);
stub!(vec29, 29, error_code);
stub!(vec30, 30, error_code);
stub!(vec31, 31);
stub!(legacy_pic, super::pic::VECTOR_BASE);
stub!(timer, TIMER_VECTOR);
stub!(reschedule, RESCHEDULE_VECTOR);
stub!(space_request, SPACE_VECTOR);

/// Entry stubs of the user interrupt lines (vector LINE_VECTOR_BASE + n).
macro_rules! line_stubs {
    ($($name:ident = $line:expr),* $(,)?) => {
        $(stub!($name, LINE_VECTOR_BASE as u64 + $line);)*
        const LINE_STUBS: [Stub; crate::irq::LINES] = [$($name),*];
    };
}
line_stubs!(
    line0 = 0,
    line1 = 1,
    line2 = 2,
    line3 = 3,
    line4 = 4,
    line5 = 5,
    line6 = 6,
    line7 = 7,
    line8 = 8,
    line9 = 9,
    line10 = 10,
    line11 = 11,
    line12 = 12,
    line13 = 13,
    line14 = 14,
    line15 = 15,
    line16 = 16,
    line17 = 17,
    line18 = 18,
    line19 = 19,
    line20 = 20,
    line21 = 21,
    line22 = 22,
    line23 = 23,
);
stub!(spurious, SPURIOUS_VECTOR);

type Stub = unsafe extern "sysv64" fn();

const EXCEPTION_STUBS: [Stub; 32] = [
    vec0, vec1, vec2, vec3, vec4, vec5, vec6, vec7, vec8, vec9, vec10, vec11, vec12, vec13, vec14,
    vec15, vec16, vec17, vec18, vec19, vec20, vec21, vec22, vec23, vec24, vec25, vec26, vec27,
    vec28, vec29, vec30, vec31,
];

/// One 16-byte interrupt-gate descriptor.
#[repr(C)]
#[derive(Clone, Copy, Default)]
struct Gate {
    offset_low: u16,
    selector: u16,
    ist: u8,
    attributes: u8,
    offset_mid: u16,
    offset_high: u32,
    reserved: u32,
}

impl Gate {
    /// Present, DPL 0, 64-bit interrupt gate (interrupts stay off in the handler).
    fn interrupt(handler: Stub, ist: u16) -> Self {
        Self::with_dpl(handler, ist, 0)
    }

    /// `dpl` 3 lets user code raise the vector with `int n` (breakpoint, overflow).
    fn with_dpl(handler: Stub, ist: u16, dpl: u8) -> Self {
        let addr = handler as *const () as u64;
        Gate {
            offset_low: addr as u16,
            selector: gdt::selectors().kernel_code.0,
            ist: ist as u8,
            attributes: 0x8e | (dpl << 5),
            offset_mid: (addr >> 16) as u16,
            offset_high: (addr >> 32) as u32,
            reserved: 0,
        }
    }
}

#[repr(C, align(16))]
struct Idt([Gate; 256]);

static IDT: Lazy<Idt> = Lazy::new(|| {
    let mut idt = Idt([Gate::default(); 256]);
    for (vector, stub) in EXCEPTION_STUBS.into_iter().enumerate() {
        let ist = match vector {
            2 => gdt::NMI_IST,
            8 => gdt::DOUBLE_FAULT_IST,
            18 => gdt::MACHINE_CHECK_IST,
            _ => 0,
        };
        let dpl = if vector == 3 || vector == 4 { 3 } else { 0 };
        idt.0[vector] = Gate::with_dpl(stub, ist, dpl);
    }
    for v in 0..16 {
        idt.0[(super::pic::VECTOR_BASE + v) as usize] = Gate::interrupt(legacy_pic, 0);
    }
    idt.0[TIMER_VECTOR as usize] = Gate::interrupt(timer, 0);
    idt.0[RESCHEDULE_VECTOR as usize] = Gate::interrupt(reschedule, 0);
    idt.0[SPACE_VECTOR as usize] = Gate::interrupt(space_request, 0);
    for (line, stub) in LINE_STUBS.into_iter().enumerate() {
        idt.0[LINE_VECTOR_BASE as usize + line] = Gate::interrupt(stub, 0);
    }
    idt.0[SPURIOUS_VECTOR as usize] = Gate::interrupt(spurious, 0);
    idt
});

pub fn init() {
    let idt: &'static Idt = &IDT;
    let pointer = DescriptorTablePointer {
        limit: (core::mem::size_of::<Idt>() - 1) as u16,
        base: VirtAddr::new(idt as *const Idt as u64),
    };
    // SAFETY: the IDT is a static that lives forever and every present gate points to a stub.
    unsafe { lidt(&pointer) };
}

extern "sysv64" fn dispatch(frame: &mut TrapFrame) {
    let from_user = frame.cs & 3 == 3;
    match frame.vector {
        // NMI, double fault, machine check: hardware trouble, never a thread's business.
        2 | 8 | 18 => fatal_exception(frame),
        0..=31 if from_user => super::entry::on_user_exception(frame.vector, frame.error_code),
        0..=31 => fatal_exception(frame),
        v if v == TIMER_VECTOR as u64 => {
            crate::time::on_timer_interrupt();
            super::lapic::end_of_interrupt();
            super::entry::on_timer(from_user);
        }
        v if (LINE_VECTOR_BASE as u64..LINE_VECTOR_BASE as u64 + crate::irq::LINES as u64)
            .contains(&v) =>
        {
            let line = (v - LINE_VECTOR_BASE as u64) as usize;
            // Closed before the EOI, so the line cannot fire again until acknowledged.
            super::ioapic::set_line_masked(line, true);
            super::lapic::end_of_interrupt();
            super::entry::on_line_interrupt(line, from_user);
        }
        v if v == RESCHEDULE_VECTOR as u64 => {
            super::lapic::end_of_interrupt();
            super::entry::on_reschedule(from_user);
        }
        v if v == SPACE_VECTOR as u64 => {
            super::lapic::end_of_interrupt();
            // A thread whose space this CPU left is gone: choose another.
            if super::smp::serve_space_request() && from_user {
                super::entry::on_reschedule(true);
            }
        }
        // Masked legacy PIC: only spurious IRQ 7/15 can arrive; they need no EOI.
        v if v == super::pic::VECTOR_BASE as u64 => {}
        v if v == SPURIOUS_VECTOR as u64 => {}
        other => panic!("unexpected interrupt vector {other:#x}"),
    }
}

fn fatal_exception(frame: &TrapFrame) -> ! {
    crate::log::force_unlock();
    let (mnemonic, description) = exception_name(frame.vector);
    let mode = if frame.cs & 3 == 3 { "user" } else { "kernel" };
    kprintln!(
        "EXCEPTION {mnemonic} ({description}, vector {}) error={:#x} in {mode} mode",
        frame.vector,
        frame.error_code
    );
    let cr2 = x86_64::registers::control::Cr2::read_raw();
    kprintln!(
        "  rip={:#018x} rsp={:#018x} cr2={cr2:#018x} rflags={:#x}",
        frame.rip,
        frame.rsp,
        frame.rflags
    );
    log_registers(frame);
    kprintln!("kernel: fatal exception, halting with failure");
    crate::qemu::exit(crate::qemu::ExitCode::Failure)
}

/// Logs the general registers of a frame (four lines).
pub fn log_registers(frame: &TrapFrame) {
    kprintln!(
        "  rax={:#018x} rbx={:#018x} rcx={:#018x} rdx={:#018x}",
        frame.rax,
        frame.rbx,
        frame.rcx,
        frame.rdx
    );
    kprintln!(
        "  rsi={:#018x} rdi={:#018x} rbp={:#018x} r8 ={:#018x}",
        frame.rsi,
        frame.rdi,
        frame.rbp,
        frame.r8
    );
    kprintln!(
        "  r9 ={:#018x} r10={:#018x} r11={:#018x} r12={:#018x}",
        frame.r9,
        frame.r10,
        frame.r11,
        frame.r12
    );
    kprintln!(
        "  r13={:#018x} r14={:#018x} r15={:#018x}",
        frame.r13,
        frame.r14,
        frame.r15
    );
}
