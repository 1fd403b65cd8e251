//! Application-processor (AP) bring-up: each CPU the MADT lists besides the boot CPU is
//! started with INIT-SIPI-SIPI through a trampoline in a low page (real mode -> protected
//! mode -> long mode), gets its own GDT, TSS, IST stacks and kernel stack from frames
//! reserved at boot, takes on the boot CPU's control registers and page tables, and then
//! runs the threads put on it in its own windows, as the boot CPU does
//! (`entry::enter_user_mode`).
//!
//! Also the CPUs' messages to each other: the reschedule interrupt ([`send_reschedule`])
//! and address-space requests ([`release_space`]): a CPU that changed or is about to free
//! the page tables of an address space another CPU has loaded makes that CPU flush its
//! TLB or leave the space, and waits for the answer before it goes on.

use super::{gdt, idt, lapic};
use crate::boot::{DirectMapLinks, FRAMES};
use crate::kprintln;
use crate::mem::{PAGE_SIZE, phys_to_virt};
use abi::boot::{MemoryKind, MemoryRegion};
use abi::machine::Machine;
use core::sync::atomic::{AtomicU8, AtomicU64, AtomicUsize, Ordering};
use x86_64::VirtAddr;
use x86_64::registers::control::{Cr0, Cr3, Cr4};
use x86_64::registers::model_specific::Efer;
use x86_64::structures::gdt::{Descriptor, GlobalDescriptorTable};
use x86_64::structures::tss::TaskStateSegment;

// The trampoline, copied to a low page at `base` (SIPI vector = base >> 12, so the AP starts
// at CS = base >> 4, IP = 0). The boot CPU fills the data words at offsets 8..40 and the GDT
// pointer's base before each start; the code keeps `base` in EBX/RBX and addresses
// everything relative to it, so it runs wherever it is copied.
core::arch::global_asm!(
    r#"
    .section .text.ap_trampoline, "ax"
    .balign 16
    .code16
    .global ap_trampoline_start
ap_trampoline_start:
    jmp .Lap16
    .balign 8
    /* 8: low PML4 (identity-maps this page, kernel half); 16: RSP; 24: entry; 32: RDI */
    .quad 0, 0, 0, 0
    /* 40: GDT: null, 32-bit code, data, 64-bit code; 72: its pointer (base filled in) */
    .quad 0, 0x00cf9a000000ffff, 0x00cf92000000ffff, 0x00af9a000000ffff
    .word 31
    .long 0
.Lap16:
    cli; cld
    mov %cs, %ax; mov %ax, %ds; mov %ax, %ss; mov $0x1000, %sp
    movzwl %ax, %ebx; shl $4, %ebx
    lgdtl 72
    mov %cr0, %eax; or $1, %eax; mov %eax, %cr0               /* protected mode */
    lea (.Lap32 - ap_trampoline_start)(%ebx), %eax
    pushl $8; pushl %eax; lretl
    .code32
.Lap32:
    mov $16, %ax; mov %ax, %ds; mov %ax, %es; mov %ax, %ss; lea 0x1000(%ebx), %esp
    mov %cr4, %eax; or $0x20, %eax; mov %eax, %cr4            /* PAE */
    mov 8(%ebx), %eax; mov %eax, %cr3
    mov $0xc0000080, %ecx; rdmsr; or $0x900, %eax; wrmsr      /* EFER.LME, NXE */
    mov %cr0, %eax; or $0x80000001, %eax; mov %eax, %cr0      /* paging */
    lea (.Lap64 - ap_trampoline_start)(%ebx), %eax
    pushl $24; pushl %eax; lret
    .code64
.Lap64:
    mov %ebx, %ebx; mov 16(%rbx), %rsp; mov 32(%rbx), %rdi; jmp *24(%rbx)
    .global ap_trampoline_end
ap_trampoline_end:
    .text
"#,
    options(att_syntax)
);

unsafe extern "C" {
    static ap_trampoline_start: u8;
    static ap_trampoline_end: u8;
}

/// Low pages: the trampoline, then the PML4, PDPT and page directory it starts with.
const LOW_PAGES: u64 = 4;
const IST_SIZE: usize = 8 * 1024;
const STACK_SIZE: usize = 32 * 1024;

#[repr(C, align(16))]
struct Stack<const N: usize>([u8; N]);

/// Everything one AP owns, in contiguous frames reserved at boot.
#[repr(C, align(4096))]
struct CpuBlock {
    number: u64,
    /// The boot CPU's control registers and local APIC, which the AP takes on.
    cr0: u64,
    cr3: u64,
    cr4: u64,
    efer: u64,
    lapic: u64,
    gdt: GlobalDescriptorTable,
    tss: gdt::TssBlock,
    ist: [Stack<IST_SIZE>; 3],
    stack: Stack<STACK_SIZE>,
}

const BLOCK_PAGES: u64 = (core::mem::size_of::<CpuBlock>() as u64).div_ceil(PAGE_SIZE);

/// CPUs that reported online, the boot CPU included.
static ONLINE: AtomicUsize = AtomicUsize::new(1);

const MAX_CPUS: usize = abi::machine::MAX_CPUS;

/// Each CPU's local APIC ID, by CPU number.
static APIC_IDS: [AtomicU8; MAX_CPUS] = [const { AtomicU8::new(0) }; MAX_CPUS];

/// The root table of the address space each CPU has loaded (written by that CPU, under
/// the kernel lock or when it leaves a space on request).
static LOADED_SPACE: [AtomicU64; MAX_CPUS] = [const { AtomicU64::new(0) }; MAX_CPUS];

/// A request to each CPU: the root table of the space to flush (low bit clear) or to leave
/// (low bit set; roots are page-aligned); 0 once answered.
static SPACE_REQUEST: [AtomicU64; MAX_CPUS] = [const { AtomicU64::new(0) }; MAX_CPUS];
const LEAVE: u64 = 1;

/// An IPI's command word: fixed delivery, level assert (with the vector in the low byte).
const FIXED: u32 = 0x4000;

/// The boot page tables: the kernel half only, which a CPU loads when it leaves a space.
static KERNEL_SPACE: AtomicU64 = AtomicU64::new(0);

/// The first `LOW_PAGES` page-aligned pages of usable memory between 4 KiB and 1 MiB (a
/// SIPI vector names a page below 1 MiB; page 0 holds the real-mode vectors).
pub fn trampoline_pages(regions: &[MemoryRegion]) -> Option<u64> {
    regions
        .iter()
        .filter(|r| r.kind == MemoryKind::USABLE)
        .map(|r| (r.start.max(PAGE_SIZE).next_multiple_of(PAGE_SIZE), r.end()))
        .find(|&(start, end)| start + LOW_PAGES * PAGE_SIZE <= end.min(0x10_0000))
        .map(|(start, _)| start)
}

/// Starts every AP the MADT lists, one at a time; returns the number of CPUs online. A
/// machine with one CPU passes through without a change or a log line.
pub fn start_application_processors(
    machine: &Machine,
    boot_apic: u32,
    regions: &[MemoryRegion],
) -> usize {
    if machine.cpus_ignored > 0 {
        kprintln!(
            "smp: {} processor entr(y/ies) of the MADT ignored (beyond the {MAX_CPUS} CPUs supported, repeated, x2APIC-only or malformed)",
            machine.cpus_ignored
        );
    }
    let aps = || {
        machine
            .cpu_apic_ids()
            .iter()
            .filter(|&&a| u32::from(a) != boot_apic)
    };
    let pml4 = Cr3::read().0.start_address().as_u64();
    KERNEL_SPACE.store(pml4, Ordering::Relaxed);
    LOADED_SPACE[0].store(pml4, Ordering::Relaxed);
    APIC_IDS[0].store(boot_apic as u8, Ordering::Relaxed);
    if aps().next().is_none() {
        return 1;
    }
    let Some(base) = trampoline_pages(regions) else {
        kprintln!("smp: no 16 KiB of free memory below 1 MiB for the AP trampoline; one CPU");
        return 1;
    };
    let start = &raw const ap_trampoline_start as usize;
    let end = &raw const ap_trampoline_end as usize;
    // SAFETY: the trampoline's bytes lie between its two symbols in the kernel's text.
    let code = unsafe { core::slice::from_raw_parts(start as *const u8, end - start) };
    // SAFETY: the live top-level table, through the direct map; only read.
    let kernel_half = unsafe { core::slice::from_raw_parts(phys_to_virt(pml4) as *const u64, 512) };
    let low_len = (LOW_PAGES * PAGE_SIZE) as usize;
    // SAFETY: usable RAM below 1 MiB, which nothing else uses (the frame allocator starts at
    // 1 MiB), mapped by the direct map; no AP runs while the boot CPU writes it.
    let low = unsafe { core::slice::from_raw_parts_mut(phys_to_virt(base) as *mut u8, low_len) };
    low.fill(0);
    low[..code.len()].copy_from_slice(code);
    put(low, 8, base + PAGE_SIZE);
    put(low, 24, ap_entry as *const () as u64);
    low[74..78].copy_from_slice(&(base as u32 + 40).to_le_bytes());
    // Identity map of the first 2 MiB (one large page); the kernel half as the boot CPU's.
    put(low, 0x1000, (base + 0x2000) | 3);
    put(low, 0x2000, (base + 0x3000) | 3);
    put(low, 0x3000, 0x83);
    for (slot, &entry) in kernel_half.iter().enumerate().skip(256) {
        put(low, 0x1000 + slot * 8, entry);
    }
    for (number, &apic) in (1..).zip(aps()) {
        let Some(block) = contiguous_frames(BLOCK_PAGES) else {
            kprintln!("smp: no contiguous frames for cpu {number}'s stacks; not started");
            break;
        };
        let words = (BLOCK_PAGES * PAGE_SIZE / 8) as usize;
        // SAFETY: fresh frames of the kernel pool, mapped by the direct map, given to this AP.
        let block =
            unsafe { core::slice::from_raw_parts_mut(phys_to_virt(block) as *mut u64, words) };
        block.fill(0);
        // SAFETY: the frames are big and aligned enough (test `a_cpu_block_fits_its_
        // reserved_frames`), and all zeros is a CpuBlock (numbers, an empty GDT, a TSS).
        let cpu = unsafe { &mut *(block.as_mut_ptr() as *mut CpuBlock) };
        (cpu.number, cpu.cr3, cpu.lapic) = (number, pml4, machine.local_apic_address);
        (cpu.cr0, cpu.cr4, cpu.efer) = (Cr0::read_raw(), Cr4::read_raw(), Efer::read_raw());
        put(low, 16, cpu.stack.0.as_ptr() as u64 + STACK_SIZE as u64 - 8);
        put(low, 32, cpu as *mut CpuBlock as u64);
        let vector = (base >> 12) as u32;
        APIC_IDS[number as usize].store(apic, Ordering::Relaxed);
        LOADED_SPACE[number as usize].store(pml4, Ordering::Relaxed);
        let sent = lapic::send_ipi(apic, 0x4500)
            && wait_ns(10_000_000)
            && lapic::send_ipi(apic, 0x4600 | vector)
            && wait_ns(200_000)
            && lapic::send_ipi(apic, 0x4600 | vector);
        let until = crate::time::since_boot_ns() + 500_000_000;
        let waiting = || ONLINE.load(Ordering::Acquire) as u64 == number;
        while sent && waiting() && crate::time::since_boot_ns() < until {
            core::hint::spin_loop();
        }
        if waiting() {
            // A late AP would find the next AP's stack in the trampoline: start no more.
            kprintln!("smp: cpu {number} (apic {apic}) did not come online; no more started");
            break;
        }
    }
    let online = ONLINE.load(Ordering::Acquire);
    kprintln!(
        "smp: {online} of {} CPUs online; each runs the threads put on it in its own windows",
        aps().count() + 1
    );
    online
}

/// Writes `value` at byte `at` of the trampoline's pages.
fn put(low: &mut [u8], at: usize, value: u64) {
    low[at..at + 8].copy_from_slice(&value.to_le_bytes());
}

/// Busy-waits `ns` nanoseconds; always true (to chain the start sequence).
fn wait_ns(ns: u64) -> bool {
    let until = crate::time::since_boot_ns() + ns;
    while crate::time::since_boot_ns() < until {
        core::hint::spin_loop();
    }
    true
}

/// `pages` physically contiguous frames of the kernel pool (at boot the allocator hands
/// out ascending frames, so this fails only across a gap in RAM).
fn contiguous_frames(pages: u64) -> Option<u64> {
    let mut frames = FRAMES.get()?.lock();
    let first = frames.allocate(&DirectMapLinks)?;
    for page in 1..pages {
        if frames.allocate(&DirectMapLinks)? != first + page * PAGE_SIZE {
            return None;
        }
    }
    Some(first)
}

/// Where the trampoline jumps, on the AP's own stack in its block.
extern "sysv64" fn ap_entry(block: *mut CpuBlock) -> ! {
    // SAFETY: the boot CPU handed this block to this AP alone; it lives for ever. The GDT
    // and TSS in it are borrowed for ever below, once set, and nothing else is.
    let b: &'static mut CpuBlock = unsafe { &mut *block };
    // SAFETY: the boot CPU's EFER, CR4, page tables and CR0: the kernel half maps as in the
    // trampoline's tables, and these are the features the kernel relies on (NX, write
    // protection, SSE state, syscall).
    unsafe {
        core::arch::asm!(
            "wrmsr", "mov cr4, {cr4}", "mov cr3, {cr3}", "mov cr0, {cr0}",
            in("ecx") 0xc000_0080u32, in("eax") b.efer as u32, in("edx") (b.efer >> 32) as u32,
            cr4 = in(reg) b.cr4, cr3 = in(reg) b.cr3, cr0 = in(reg) b.cr0, options(nostack)
        );
    }
    let (number, lapic_phys) = (b.number, b.lapic);
    let ists = [gdt::DOUBLE_FAULT_IST, gdt::NMI_IST, gdt::MACHINE_CHECK_IST];
    for (stack, ist) in b.ist.iter().zip(ists) {
        let top = stack.0.as_ptr() as u64 + IST_SIZE as u64;
        b.tss.tss.interrupt_stack_table[ist as usize - 1] = VirtAddr::new(top);
    }
    let stack_top = b.stack.0.as_ptr() as u64 + STACK_SIZE as u64;
    b.tss.tss.privilege_stack_table[0] = VirtAddr::new(stack_top);
    // The descriptor checks that the bitmap follows the TSS (`iomap_base` pointing at it);
    // every port is denied below until a task's bitmap is loaded (`entry`).
    b.tss.iomap.fill(0xff);
    b.tss.tss.iomap_base = core::mem::size_of::<TaskStateSegment>() as u16;
    // The entry path moves the TSS's ring-0 stack with the running thread and loads the
    // running task's I/O bitmap, as on the boot CPU (the CPU reads the TSS only on
    // entries from ring 3 and port accesses there).
    let tss_at = &raw mut b.tss;
    let CpuBlock { gdt, tss, .. } = b;
    *gdt = GlobalDescriptorTable::new();
    // The boot CPU's selector layout, so that SYSCALL/SYSRET (STAR) work the same here.
    let code = gdt.append(Descriptor::kernel_code_segment());
    let data = gdt.append(Descriptor::kernel_data_segment());
    gdt.append(Descriptor::user_data_segment());
    gdt.append(Descriptor::user_code_segment());
    let tss = gdt.append(
        Descriptor::tss_segment_with_iomap(&tss.tss, &tss.iomap)
            .expect("bitmap directly follows the TSS"),
    );
    // SAFETY: this CPU's block; the descriptor only recorded its address.
    unsafe { gdt::load_io_bitmap(tss_at, None) };
    let gdt: &'static GlobalDescriptorTable = gdt;
    gdt.load();
    // SAFETY: the selectors index descriptors of the GDT just loaded, with the right types
    // (null for DS/ES is valid in 64-bit mode); the TSS descriptor is loaded once.
    unsafe {
        core::arch::asm!(
            "push {code}", "lea {tmp}, [rip + 2f]", "push {tmp}", "retfq", "2:",
            "mov ss, {data:x}", "mov ds, {null:x}", "mov es, {null:x}", "ltr {tss:x}",
            code = in(reg) u64::from(code.0), data = in(reg) data.0, null = in(reg) 0u16,
            tss = in(reg) tss.0, tmp = out(reg) _,
        );
    }
    idt::init();
    super::syscall::init(number as usize, stack_top, tss_at);
    let (apic, _) = lapic::init(lapic_phys);
    kprintln!("cpu {number} online (apic {apic})");
    ONLINE.fetch_add(1, Ordering::Release);
    super::entry::enter_user_mode()
}

/// Makes `cpu` look at its state again (`entry::on_reschedule`).
pub fn send_reschedule(cpu: usize) {
    let apic = APIC_IDS[cpu].load(Ordering::Relaxed);
    lapic::send_ipi(apic, FIXED | u32::from(idt::RESCHEDULE_VECTOR));
}

/// `cpu` loaded the address space with root table `root` (under the kernel lock).
pub fn set_loaded_space(cpu: usize, root: u64) {
    LOADED_SPACE[cpu].store(root, Ordering::Release);
}

/// Before the page tables of the space with root table `root` lose entries (`leave`:
/// before they are freed), every other CPU that has it loaded flushes its TLB (or loads
/// the kernel's tables); returns once all have answered. Called under the kernel lock.
#[cfg(not(test))]
pub fn release_space(root: u64, leave: bool) {
    // An answer takes at most this long (every kernel path is bounded and a CPU waiting for
    // the lock answers while it waits): past it the machine is broken, and the kernel
    // stops rather than free tables a CPU may still walk.
    const ANSWER_WITHIN_NS: u64 = 100_000_000;
    let me = super::entry::this_cpu();
    let online = ONLINE.load(Ordering::Acquire);
    let mut waiting = 0u64;
    for cpu in (0..online).filter(|&c| c != me) {
        if LOADED_SPACE[cpu].load(Ordering::Acquire) == root {
            SPACE_REQUEST[cpu].store(root | if leave { LEAVE } else { 0 }, Ordering::Release);
            let apic = APIC_IDS[cpu].load(Ordering::Relaxed);
            lapic::send_ipi(apic, FIXED | u32::from(idt::SPACE_VECTOR));
            waiting |= 1 << cpu;
        }
    }
    let until = crate::time::since_boot_ns() + ANSWER_WITHIN_NS;
    while waiting != 0 {
        let cpu = waiting.trailing_zeros() as usize;
        if SPACE_REQUEST[cpu].load(Ordering::Acquire) == 0 {
            waiting &= !(1 << cpu);
        } else if crate::time::since_boot_ns() > until {
            panic!("cpu {cpu} did not answer an address-space request within 100 ms");
        }
        core::hint::spin_loop();
    }
}

/// Host tests have one CPU.
#[cfg(test)]
pub fn release_space(_root: u64, _leave: bool) {}

/// Answers this CPU's address-space request, if any (from its interrupt, or while it waits
/// for the kernel lock); true if it left the space it ran in (then it must not return to
/// the thread it interrupted: that thread is gone).
pub fn serve_space_request() -> bool {
    let me = super::entry::this_cpu();
    let request = SPACE_REQUEST[me].load(Ordering::Acquire);
    if request == 0 {
        return false;
    }
    let root = request & !LEAVE;
    let (loaded, flags) = Cr3::read_raw();
    let mut left = false;
    if loaded.start_address().as_u64() == root {
        let next = if request & LEAVE != 0 {
            left = true;
            let kernel = KERNEL_SPACE.load(Ordering::Relaxed);
            LOADED_SPACE[me].store(kernel, Ordering::Release);
            x86_64::structures::paging::PhysFrame::containing_address(x86_64::PhysAddr::new(kernel))
        } else {
            loaded
        };
        // SAFETY: the kernel's boot tables or the loaded ones (a reload flushes the TLB);
        // both map the kernel half this code runs in.
        unsafe { Cr3::write_raw(next, flags) };
    }
    SPACE_REQUEST[me].store(0, Ordering::Release);
    left
}

#[cfg(test)]
#[path = "../../host-tests/smp.rs"]
mod tests;
