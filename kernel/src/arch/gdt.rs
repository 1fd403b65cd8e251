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

/// Bytes of the I/O permission bitmap (one bit per port, 0 = allowed).
pub const IOMAP_BYTES: usize = 8192;

/// A CPU's TSS followed directly by its I/O permission bitmap (and the 0xff terminator the
/// CPU may read past the last byte).
#[repr(C, align(16))]
pub struct TssBlock {
    pub tss: TaskStateSegment,
    pub iomap: [u8; IOMAP_BYTES + 1],
}

static mut TSS_BLOCK: TssBlock = TssBlock {
    tss: TaskStateSegment::new(),
    iomap: [0xff; IOMAP_BYTES + 1],
};

/// `iomap_base` that makes the CPU deny every port (beyond the TSS limit).
pub const IOMAP_DISABLED: u16 = (core::mem::size_of::<TaskStateSegment>() + IOMAP_BYTES + 1) as u16;

fn tss_block() -> *mut TssBlock {
    core::ptr::addr_of_mut!(TSS_BLOCK)
}

fn init_tss() {
    let block = tss_block();
    // SAFETY: called once from `init` before the TSS is loaded; nothing else uses it yet.
    let tss = unsafe { &mut (*block).tss };
    for (slot, ist) in [DOUBLE_FAULT_IST, NMI_IST, MACHINE_CHECK_IST]
        .into_iter()
        .enumerate()
    {
        // SAFETY: only the address of the static is taken; the stacks are used exclusively by
        // the CPU when it delivers the corresponding exception.
        let base = unsafe { core::ptr::addr_of!(IST_STACKS[slot]) } as u64;
        tss.interrupt_stack_table[ist as usize - 1] = VirtAddr::new(base + IST_STACK_SIZE as u64);
    }
    // Until the first thread runs; then just past the running thread's context (entry.rs).
    tss.privilege_stack_table[0] = VirtAddr::new(super::stack::top());
    tss.iomap_base = IOMAP_DISABLED;
}

/// The boot CPU's TSS block (the entry path points its ring-0 stack just past the running
/// thread's saved context and loads the running task's I/O bitmap, `arch::entry`).
pub fn boot_tss() -> *mut TssBlock {
    tss_block()
}

/// Loads the running task's I/O permission bitmap into this CPU's TSS `block`, given as
/// its two 4 KiB halves (`None`: no port allowed, O(1)).
///
/// # Safety
/// `block` is this CPU's TSS block, and no reference to it lives meanwhile (the CPU reads
/// the TSS only on privilege changes and port accesses from ring 3, never while the
/// kernel, interrupts off, updates it).
pub unsafe fn load_io_bitmap(block: *mut TssBlock, bitmap: Option<[&[u8]; 2]>) {
    // SAFETY: as the caller promises.
    let block = unsafe { &mut *block };
    match bitmap {
        Some([low, high]) => {
            block.iomap[..IOMAP_BYTES / 2].copy_from_slice(low);
            block.iomap[IOMAP_BYTES / 2..IOMAP_BYTES].copy_from_slice(high);
            block.tss.iomap_base = core::mem::size_of::<TaskStateSegment>() as u16;
        }
        None => block.tss.iomap_base = IOMAP_DISABLED,
    }
}

static GDT: Lazy<(GlobalDescriptorTable, Selectors)> = Lazy::new(|| {
    init_tss();
    let block = tss_block();
    let mut gdt = GlobalDescriptorTable::new();
    let kernel_code = gdt.append(Descriptor::kernel_code_segment());
    let kernel_data = gdt.append(Descriptor::kernel_data_segment());
    let user_data = gdt.append(Descriptor::user_data_segment());
    let user_code = gdt.append(Descriptor::user_code_segment());
    // The descriptor checks that the bitmap follows the TSS; iomap_base is set to it for
    // the check and back to "disabled" right after (no task owns ports at boot).
    // SAFETY: the block is a static; nothing runs in ring 3 yet and no reference into the
    // block exists.
    unsafe { (*block).tss.iomap_base = core::mem::size_of::<TaskStateSegment>() as u16 };
    // SAFETY: the block is a static that lives forever; the descriptor only records its
    // address and the limit covering TSS and bitmap.
    let block = unsafe { &*block };
    let tss = gdt.append(
        Descriptor::tss_segment_with_iomap(&block.tss, &block.iomap)
            .expect("bitmap directly follows the TSS"),
    );
    // SAFETY: the boot CPU's block, no longer borrowed.
    unsafe { load_io_bitmap(tss_block(), None) };
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
    // The selectors index descriptors of the GDT just loaded, with the right types:
    // SAFETY: kernel code descriptor.
    unsafe { CS::set_reg(s.kernel_code) };
    // SAFETY: kernel data descriptor.
    unsafe { SS::set_reg(s.kernel_data) };
    // SAFETY: the null selector is valid for DS/ES in 64-bit mode.
    unsafe { DS::set_reg(SegmentSelector(0)) };
    // SAFETY: as for DS.
    unsafe { ES::set_reg(SegmentSelector(0)) };
    // SAFETY: the TSS descriptor of this GDT, loaded once.
    unsafe { load_tss(s.tss) };
}

pub fn selectors() -> &'static Selectors {
    &GDT.1
}
