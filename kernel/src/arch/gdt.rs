//! GDT and TSS. Segment order is fixed by SYSCALL/SYSRET (STAR): kernel code, kernel data,
//! user data, user code. The TSS gives the double-fault, NMI and machine-check handlers
//! their own stacks (IST) so they work even on a corrupt kernel stack.

use spin::Lazy;
use x86_64::VirtAddr;
use x86_64::instructions::segmentation::{CS, DS, ES, SS, Segment};
use x86_64::instructions::tables::load_tss;
use x86_64::structures::gdt::{Descriptor, GlobalDescriptorTable, SegmentSelector};
use x86_64::structures::tss::TaskStateSegment;

/// IST slots (1-based in the IDT, 0-based in the TSS array).
pub const DOUBLE_FAULT_IST: u16 = 1;
pub const NMI_IST: u16 = 2;
pub const MACHINE_CHECK_IST: u16 = 3;

const IST_STACK_SIZE: usize = 16 * 1024;

#[repr(C, align(16))]
struct IstStack([u8; IST_STACK_SIZE]);

static mut IST_STACKS: [IstStack; 3] = [const { IstStack([0; IST_STACK_SIZE]) }; 3];

pub struct Selectors {
    pub kernel_code: SegmentSelector,
    pub kernel_data: SegmentSelector,
    pub user_data: SegmentSelector,
    pub user_code: SegmentSelector,
    pub tss: SegmentSelector,
}

static TSS: Lazy<TaskStateSegment> = Lazy::new(|| {
    let mut tss = TaskStateSegment::new();
    for (slot, ist) in [DOUBLE_FAULT_IST, NMI_IST, MACHINE_CHECK_IST]
        .into_iter()
        .enumerate()
    {
        // SAFETY: only the address of the static is taken; the stacks are used exclusively by
        // the CPU when it delivers the corresponding exception.
        let base = unsafe { core::ptr::addr_of!(IST_STACKS[slot]) } as u64;
        tss.interrupt_stack_table[ist as usize - 1] = VirtAddr::new(base + IST_STACK_SIZE as u64);
    }
    // Interrupts and exceptions from ring 3 start on the (one) kernel stack.
    tss.privilege_stack_table[0] = VirtAddr::new(super::stack::top());
    tss
});

static GDT: Lazy<(GlobalDescriptorTable, Selectors)> = Lazy::new(|| {
    let mut gdt = GlobalDescriptorTable::new();
    let kernel_code = gdt.append(Descriptor::kernel_code_segment());
    let kernel_data = gdt.append(Descriptor::kernel_data_segment());
    let user_data = gdt.append(Descriptor::user_data_segment());
    let user_code = gdt.append(Descriptor::user_code_segment());
    let tss = gdt.append(Descriptor::tss_segment(&TSS));
    (
        gdt,
        Selectors {
            kernel_code,
            kernel_data,
            user_data,
            user_code,
            tss,
        },
    )
});

pub fn init() {
    GDT.0.load();
    let s = &GDT.1;
    // SAFETY: the selectors index descriptors of the GDT just loaded, with the right types.
    unsafe {
        CS::set_reg(s.kernel_code);
        SS::set_reg(s.kernel_data);
        DS::set_reg(SegmentSelector(0));
        ES::set_reg(SegmentSelector(0));
        load_tss(s.tss);
    }
}

pub fn selectors() -> &'static Selectors {
    &GDT.1
}
