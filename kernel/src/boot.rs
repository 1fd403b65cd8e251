//! The boot sequence, from the loader's hand-off to "ready". Each step logs what it found so
//! the serial log doubles as a hardware report.

use crate::arch::{cpu, gdt, hpet::Hpet, idt, ioapic::IoApic, lapic, pic, pit};
use crate::mem::frames::{FrameAllocator, FrameLinks};
use crate::mem::{PAGE_SIZE, phys_to_virt};
use crate::table::RpIdx;
use crate::{kprintln, time};
use abi::boot::{BootInfo, MemoryKind, MemoryRegion};
use abi::root::{PhysRegion, ROOT_INFO_MAX_REGIONS};
use abi::sysimg::SystemImage;
use spin::{Mutex, Once};

pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// Frames handed out by the kernel. Low memory (< 1 MiB) is never used.
pub static FRAMES: Once<Mutex<FrameAllocator>> = Once::new();
const FRAME_FLOOR: u64 = 0x10_0000;

/// Frame links through the direct map.
pub struct DirectMapLinks;

impl FrameLinks for DirectMapLinks {
    fn next(&self, frame: u64) -> u64 {
        // SAFETY: `frame` is a free frame owned by the allocator, mapped by the direct map.
        unsafe { (phys_to_virt(frame) as *const u64).read() }
    }
    fn set_next(&mut self, frame: u64, next: u64) {
        // SAFETY: as above; the frame is free, so nothing else reads or writes it.
        unsafe { (phys_to_virt(frame) as *mut u64).write(next) }
    }
}

/// The loader's identity-mapped trampoline is the only lower-half mapping; dropping the whole
/// lower half of the PML4 leaves user space an empty half.
fn drop_lower_half() {
    let (frame, _) = x86_64::registers::control::Cr3::read();
    let pml4 = phys_to_virt(frame.start_address().as_u64()) as *mut u64;
    for slot in 0..256 {
        // SAFETY: `pml4` is the live top-level table (through the direct map); clearing
        // lower-half slots only unmaps the trampoline, which is no longer executing.
        unsafe { pml4.wrapping_add(slot).write(0) };
    }
    x86_64::instructions::tlb::flush_all();
}

pub fn start(boot_info: u64) -> ! {
    let entry_tsc = cpu::rdtsc();
    drop_lower_half();
    time::set_boot_tsc(entry_tsc);
    crate::log::init();
    // A first TSC estimate from the PIT so that every log line carries a real timestamp.
    match pit::tsc_ticks_for_ms(10) {
        Some(ticks) => time::set_tsc_hz(ticks * 100),
        None => panic!("PIT did not count: no reference clock to calibrate the TSC"),
    }
    kprintln!("Warden partitioning microkernel {VERSION} (x86_64, UEFI)");

    // SAFETY: the loader passes the direct-map address of a BootInfo it filled in.
    let info: &BootInfo = unsafe { &*(boot_info as *const BootInfo) };
    if let Err(why) = info.check() {
        panic!("boot info rejected: {why}");
    }
    kprintln!(
        "boot: loader handed over {} us before entry; lower half unmapped",
        time::ticks_to_ns(entry_tsc.wrapping_sub(info.tsc_at_handoff), time::tsc_hz()) / 1000
    );
    time::set_wall_clock(info.wall_clock_at_handoff, info.tsc_at_handoff);

    gdt::init();
    idt::init();
    kprintln!("cpu: GDT, TSS (IST for #DF, NMI, #MC) and IDT loaded");

    // SAFETY: the loader placed `memory_region_count` regions at `memory_regions` (physical),
    // inside BOOT_INFO memory that stays reserved and unmodified.
    let regions: &[MemoryRegion] = unsafe {
        core::slice::from_raw_parts(
            phys_to_virt(info.memory_regions) as *const MemoryRegion,
            info.memory_region_count as usize,
        )
    };
    log_memory_summary(regions);
    crate::mem::MEMORY_MAP.call_once(|| regions);
    let mut user_memory = [PhysRegion::default(); ROOT_INFO_MAX_REGIONS];
    let mut frames = FrameAllocator::new(regions, FRAME_FLOOR);
    // The kernel keeps a pool for page tables (1/8 of RAM, 16..128 MiB); the rest is user
    // memory the root task hands out.
    let keep = (frames.total_frames() / 8).clamp(4096, 32768);
    let mut ranges = [(0u64, 0u64); ROOT_INFO_MAX_REGIONS];
    let count = frames.split_off_beyond(keep, &mut ranges);
    for (slot, &(start, end)) in user_memory.iter_mut().zip(&ranges[..count]) {
        *slot = PhysRegion {
            start,
            pages: (end - start) / PAGE_SIZE,
        };
    }
    let user_pages: u64 = user_memory[..count].iter().map(|r| r.pages).sum();
    kprintln!(
        "memory: kernel pool {} frames ({} MiB); user memory {} MiB in {count} range(s){}",
        frames.total_frames(),
        (frames.total_frames() * PAGE_SIZE) >> 20,
        (user_pages * PAGE_SIZE) >> 20,
        if frames.ignored_ranges() > 0 {
            " (some ranges ignored: too many)"
        } else {
            ""
        }
    );
    let user_memory_count = count;
    FRAMES.call_once(|| Mutex::new(frames));

    pic::remap_and_mask();
    let machine = &info.machine;
    kprintln!(
        "acpi: revision {}, {} CPU(s), {} IOAPIC(s), {} ISA override(s), HPET {}{}",
        machine.acpi_revision,
        machine.cpu_apic_ids().len(),
        machine.io_apics().len(),
        machine.overrides().len(),
        if machine.hpet_address != 0 {
            "present"
        } else {
            "absent"
        },
        if machine.entries_ignored > 0 {
            "; IOAPIC or override entries beyond the loader's lists ignored"
        } else {
            ""
        }
    );
    let (apic_id, apic_version) = lapic::init(machine.local_apic_address);
    kprintln!(
        "apic: local APIC id {apic_id} version {apic_version:#x} at {:#x}; legacy PIC masked",
        machine.local_apic_address
    );
    for io in machine.io_apics() {
        // SAFETY: the address comes from the MADT's IOAPIC entry.
        let ioapic = unsafe { IoApic::new(io.address) };
        ioapic.mask_all();
        let (id, address, first, lines) = (io.id, io.address, io.gsi_base, ioapic.line_count());
        kprintln!(
            "apic: IOAPIC id {id} at {address:#x}, GSI {first}..{}, all lines masked",
            first + lines - 1
        );
        if io.gsi_base == 0 {
            crate::arch::ioapic::install(ioapic, apic_id, machine.overrides());
        }
    }

    let apic_timer_hz = calibrate((machine.hpet_address != 0).then_some(machine.hpet_address));
    prove_timer(apic_timer_hz);
    if lapic::has_tsc_deadline() {
        lapic::use_tsc_deadline();
        kprintln!("timer: one-shot in TSC-deadline mode");
    } else {
        kprintln!("timer: one-shot count mode (no TSC-deadline mode)");
    }

    // SAFETY: the loader copied system.img to SYSTEM_IMAGE frames that stay reserved; the
    // direct map covers them.
    let image_bytes = unsafe {
        core::slice::from_raw_parts(
            phys_to_virt(info.system_image.start) as *const u8,
            info.system_image.len as usize,
        )
    };
    let image = SystemImage::parse(image_bytes).unwrap_or_else(|e| panic!("system.img: {e}"));
    kprintln!("sysimg: {} bytes, {} entries", image.size(), image.len());
    for entry in image.entries() {
        kprintln!("sysimg:   {:<24} {:>8} bytes", entry.name, entry.data.len());
    }

    let dma = (machine.dma_base != 0).then_some(machine.dma_base).and_then(|base| {
        // SAFETY: the address comes from the ACPI DMAR table's one remapping unit.
        let unit = unsafe { crate::arch::vtd::Vtd::new(base) }?;
        let tables = crate::mem::iommu::DmaTables::new(unit.levels, unit.domains)?;
        if !unit.enable(tables.root()) {
            kprintln!("iommu: the DMA remapping unit at {base:#x} did not answer; not used");
            return None;
        }
        let mut endpoints = [None; crate::state::DMA_ENDPOINTS];
        for (slot, &id) in endpoints.iter_mut().zip(machine.dma_endpoints()) {
            *slot = Some(id);
        }
        kprintln!(
            "iommu: DMA remapping on (VT-d at {base:#x}, {}-level tables, bus address = physical, {}): a device reaches only the DMA region syssw confines it to",
            unit.levels,
            if machine.dma_all != 0 { "every PCI function" } else { "the functions the DMAR lists" }
        );
        Some(crate::state::Dma {
            unit,
            tables,
            all: machine.dma_all != 0,
            endpoints,
        })
    });
    if dma.is_none() {
        kprintln!("iommu: none (no usable ACPI DMAR): devices' DMA is not confined");
    }

    let Some(syssw) = image.find("syssw") else {
        panic!("system.img has no 'syssw' entry (the root task)")
    };
    crate::arch::cpu::enable_sse_for_user();
    crate::arch::syscall::init(0, crate::arch::stack::top(), crate::arch::gdt::boot_tss());
    let online = crate::arch::smp::start_application_processors(machine, apic_id, regions);
    // An emulator that runs the CPUs in turns on one host thread ends a turn only at the
    // machine's next timer deadline: a turn clock bounds how long a busy CPU keeps the
    // others waiting. CPUs side by side need none (and an emulator's would cost them).
    if online > 1 && info.cpus_in_turns != 0 {
        pit::TURNS.store(true, core::sync::atomic::Ordering::Relaxed);
        kprintln!(
            "smp: the CPUs run in turns: PIT turn clock every {} us once a thread is on another CPU than CPU 0",
            pit::TURN_NS / 1000
        );
    }
    {
        let mut k = crate::arch::entry::KERNEL.lock();
        (k.dma, k.online) = (dma, online);
        let entry = crate::task::create_root(
            &mut k,
            syssw.data,
            info.system_image.start,
            info.system_image.len,
            &user_memory[..user_memory_count],
        )
        .unwrap_or_else(|e| panic!("cannot create the root task from 'syssw': {e:?}"));
        kprintln!(
            "task: root task 'syssw' loaded, entry {entry:#x}; root partition quota {} pages, {} threads, {} tasks",
            k.rps[RpIdx::ROOT].quota.pages,
            k.rps[RpIdx::ROOT].quota.threads,
            k.rps[RpIdx::ROOT].quota.tasks
        );
    }

    kprintln!("kernel: ready");

    #[cfg(feature = "test-hooks")]
    crate::test_hooks::run(&image, apic_timer_hz);

    crate::arch::entry::enter_user_mode()
}

fn log_memory_summary(regions: &[MemoryRegion]) {
    // Firmware "reserved" ranges include address space that is not RAM (e.g. PCIe ECAM).
    let ram: u64 = regions
        .iter()
        .filter(|r| r.kind != MemoryKind::MMIO && r.kind != MemoryKind::RESERVED)
        .map(|r| r.pages)
        .sum();
    kprintln!(
        "memory: {} regions, {} MiB of RAM",
        regions.len(),
        (ram * PAGE_SIZE) >> 20
    );
    for kind in MemoryKind::ALL {
        let pages: u64 = regions
            .iter()
            .filter(|r| r.kind == kind)
            .map(|r| r.pages)
            .sum();
        if pages > 0 {
            kprintln!(
                "memory:   {:<16} {:>8} KiB",
                kind.name(),
                pages * PAGE_SIZE / 1024
            );
        }
    }
    let unknown = regions
        .iter()
        .filter(|r| r.kind.name() == "unknown")
        .count();
    if unknown > 0 {
        kprintln!("memory:   {unknown} region(s) of unknown kind treated as reserved");
    }
}

/// Measures TSC and APIC-timer frequencies over 20 ms of a reference clock (HPET if ACPI
/// lists one, else the PIT). Returns APIC timer ticks per second (after its divider).
fn calibrate(hpet_address: Option<u64>) -> u64 {
    const WINDOW_MS: u64 = 20;
    // SAFETY: the address comes from the ACPI HPET table.
    let hpet = hpet_address.and_then(|a| unsafe { Hpet::new(a) });
    let (reference, tsc_ticks, apic_ticks) = match &hpet {
        Some(hpet) => {
            let wait = hpet.frequency_hz() * WINDOW_MS / 1000;
            lapic::start_calibration_count();
            let (h0, t0) = (hpet.counter(), cpu::rdtsc());
            hpet.wait_until(h0, wait);
            let (t1, a1) = (cpu::rdtsc(), lapic::calibration_ticks());
            ("HPET", t1 - t0, a1)
        }
        None => {
            lapic::start_calibration_count();
            let tsc =
                pit::tsc_ticks_for_ms(WINDOW_MS).unwrap_or_else(|| panic!("PIT did not count"));
            ("PIT", tsc, lapic::calibration_ticks())
        }
    };
    lapic::stop_timer();
    let tsc_hz = tsc_ticks * 1000 / WINDOW_MS;
    let apic_hz = apic_ticks * 1000 / WINDOW_MS;
    time::set_tsc_hz(tsc_hz);
    lapic::set_timer_hz(apic_hz);
    kprintln!(
        "timer: calibrated against {reference} over {WINDOW_MS} ms: TSC {}.{:03} MHz, APIC timer {}.{:03} MHz (bus {} MHz / {})",
        tsc_hz / 1_000_000,
        tsc_hz / 1000 % 1000,
        apic_hz / 1_000_000,
        apic_hz / 1000 % 1000,
        apic_hz * lapic::TIMER_DIVISOR / 1_000_000,
        lapic::TIMER_DIVISOR
    );
    if apic_hz == 0 {
        panic!("APIC timer did not count during calibration");
    }
    apic_hz
}

/// Runs the APIC timer at `rate_hz` until `count` interrupts arrived; returns the elapsed ns.
/// Panics if they do not arrive within a generous bound, so a dead timer cannot go unnoticed.
pub fn count_timer_interrupts(apic_timer_hz: u64, rate_hz: u64, count: u64) -> u64 {
    let start_count = time::timer_interrupts();
    let start = time::since_boot_ns();
    let deadline = start + 2_000_000_000 + count * 20_000_000_000 / rate_hz;
    lapic::start_periodic(idt::TIMER_VECTOR, (apic_timer_hz / rate_hz) as u32);
    while time::timer_interrupts() - start_count < count {
        // Enable interrupts and halt atomically (sti; hlt) so no tick is lost in between.
        x86_64::instructions::interrupts::enable_and_hlt();
        x86_64::instructions::interrupts::disable();
        if time::since_boot_ns() > deadline {
            panic!(
                "timer interrupts stopped: {} of {count} arrived",
                time::timer_interrupts() - start_count
            );
        }
    }
    lapic::stop_timer();
    time::since_boot_ns() - start
}

fn prove_timer(apic_timer_hz: u64) {
    const TICKS: u64 = 10;
    let ns = count_timer_interrupts(apic_timer_hz, 1000, TICKS);
    kprintln!(
        "timer: {TICKS} interrupts at 1 kHz took {}.{:03} ms",
        ns / 1_000_000,
        ns / 1000 % 1000
    );
}
