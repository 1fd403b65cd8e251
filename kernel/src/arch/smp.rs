//! Application-processor (AP) bring-up: each CPU the MADT lists besides the boot CPU is
//! started with INIT-SIPI-SIPI through a trampoline in a low page (real mode -> protected
//! mode -> long mode), gets its own GDT, TSS, IST stacks and kernel stack from frames
//! reserved at boot, takes on the boot CPU's control registers and page tables, and, while
//! it waits, beats its own local APIC timer ([`heartbeat`]). Nothing is scheduled on it yet
//! (docs/status.md).

use super::{gdt, idt, lapic};
use crate::boot::{DirectMapLinks, FRAMES};
use crate::kprintln;
use crate::mem::{PAGE_SIZE, phys_to_virt};
use abi::boot::{MemoryKind, MemoryRegion};
use abi::machine::Machine;
use core::sync::atomic::{AtomicUsize, Ordering};
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
    tss: TaskStateSegment,
    ist: [Stack<IST_SIZE>; 3],
    stack: Stack<STACK_SIZE>,
}

const BLOCK_PAGES: u64 = (core::mem::size_of::<CpuBlock>() as u64).div_ceil(PAGE_SIZE);

/// CPUs that reported online, the boot CPU included.
static ONLINE: AtomicUsize = AtomicUsize::new(1);

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
            "smp: {} processor entr(y/ies) of the MADT ignored (beyond the {} CPUs supported, repeated, x2APIC-only or malformed)",
            machine.cpus_ignored,
            abi::machine::MAX_CPUS
        );
    }
    let aps = || {
        machine
            .cpu_apic_ids()
            .iter()
            .filter(|&&a| u32::from(a) != boot_apic)
    };
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
    let (pml4, _) = Cr3::read();
    let pml4 = pml4.start_address().as_u64();
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
        "smp: {online} of {} CPUs online; the application processors beat their own timers (nothing is scheduled on them yet)",
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
        b.tss.interrupt_stack_table[ist as usize - 1] = VirtAddr::new(top);
    }
    let stack_top = b.stack.0.as_ptr() as u64 + STACK_SIZE as u64;
    b.tss.privilege_stack_table[0] = VirtAddr::new(stack_top);
    // No I/O bitmap: every port is denied in ring 3.
    b.tss.iomap_base = core::mem::size_of::<TaskStateSegment>() as u16;
    let CpuBlock { gdt, tss, .. } = b;
    *gdt = GlobalDescriptorTable::new();
    // The boot CPU's selector layout, so that SYSCALL/SYSRET (STAR) work the same here.
    let code = gdt.append(Descriptor::kernel_code_segment());
    let data = gdt.append(Descriptor::kernel_data_segment());
    gdt.append(Descriptor::user_data_segment());
    gdt.append(Descriptor::user_code_segment());
    let tss = gdt.append(Descriptor::tss_segment(tss));
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
    super::syscall::init(number as usize, stack_top);
    let (apic, _) = lapic::init(lapic_phys);
    kprintln!("cpu {number} online (apic {apic})");
    ONLINE.fetch_add(1, Ordering::Release);
    heartbeat(number)
}

/// Beats a second of an AP's local APIC timer while it waits.
const HEARTBEAT_HZ: u64 = 100;

/// An AP's wait: its own local APIC timer beats [`HEARTBEAT_HZ`] times a second
/// (periodic, vector [`idt::HEARTBEAT_VECTOR`]) and each second the AP logs `cpu <n>:
/// heartbeat <beats> longest_gap_us=<us>`: the proof that each core takes its own timer's
/// interrupts on time.
/// The AP touches no kernel object, so it never takes the kernel's lock.
fn heartbeat(number: u64) -> ! {
    let ticks = lapic::timer_hz() / HEARTBEAT_HZ;
    lapic::start_periodic(idt::HEARTBEAT_VECTOR, ticks as u32);
    let (mut beats, mut last, mut longest) = (0u64, crate::time::since_boot_ns(), 0);
    loop {
        x86_64::instructions::interrupts::enable_and_hlt();
        x86_64::instructions::interrupts::disable();
        let now = crate::time::since_boot_ns();
        (beats, longest, last) = (beats + 1, longest.max(now - last), now);
        if beats.is_multiple_of(HEARTBEAT_HZ) {
            let gap_us = core::mem::take(&mut longest) / 1000;
            kprintln!("cpu {number}: heartbeat {beats} longest_gap_us={gap_us}");
        }
    }
}

#[cfg(test)]
#[path = "../../host-tests/smp.rs"]
mod tests;
