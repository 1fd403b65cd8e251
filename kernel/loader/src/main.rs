//! UEFI loader: reads `kernel.elf` and `system.img` from the ESP it was started from, builds
//! the kernel's page tables, exits boot services and jumps to the kernel.
//!
//! It must never leave anything in the lower half but its one-page CR3-switch trampoline
//! (which the kernel removes first), never map a segment both writable and executable, and
//! never jump with a half-built state: every failure before the jump is printed on the
//! firmware console as `loader: error: ...` and the loader returns to the firmware.
//! The memory it allocates for the kernel carries OS-defined UEFI memory types
//! ([`MemoryKind::uefi_type`]) so the final memory map already says who owns what.
#![no_std]
#![no_main]

extern crate alloc;

mod paging;

use abi::boot::{
    BOOT_INFO_MAGIC, BOOT_INFO_VERSION, BootInfo, DIRECT_MAP_BASE, KERNEL_BASE, MemoryKind,
    MemoryRegion, PhysRange,
};
use abi::syscall::PageRights;
use abi::sysimg::SystemImage;
use alloc::format;
use alloc::string::String;
use core::fmt::Write;
use paging::{PageFlags, PageTableBuilder};
use uefi::boot::{self, AllocateType, MemoryType};
use uefi::mem::memory_map::MemoryMap;
use uefi::prelude::*;
use uefi::table::cfg::ConfigTableEntry;
use uefi::{CStr16, println};
use xmas_elf::ElfFile;

const PAGE: u64 = 4096;

#[entry]
fn main() -> Status {
    if uefi::helpers::init().is_err() {
        return Status::ABORTED;
    }
    println!("loader: started");
    match load() {
        Ok(never) => match never {},
        Err(message) => {
            println!("loader: error: {message}");
            Status::LOAD_ERROR
        }
    }
}

/// Everything up to the jump; returns only on failure.
#[allow(unsafe_code)] // firmware calls and raw physical memory before the kernel runs
fn load() -> Result<core::convert::Infallible, String> {
    check_cpu()?;
    let mut tables = PageTableBuilder::new()?;

    let (entry, kernel_pages) = {
        let kernel = read_file(cstr16!("kernel.elf"))?;
        load_kernel(&kernel, &mut tables)?
        // The file buffer is dropped here, while boot services can still free it.
    };
    let system_image = {
        let image = read_file(cstr16!("system.img"))?;
        copy_system_image(&image)?
    };
    let rsdp = find_rsdp();
    println!(
        "loader: kernel {} KiB, entry {entry:#x}; system.img {} KiB; ACPI RSDP {rsdp:#x}",
        kernel_pages * 4,
        system_image.len / 1024
    );

    let direct_map_size = direct_map_size()?;
    let memory = IdentityMapped {
        size: direct_map_size,
    };
    let machine = acpi_tables::parse(rsdp, &memory).map_err(|e| format!("ACPI: {e}"))?;
    tables.map_direct(DIRECT_MAP_BASE, direct_map_size)?;

    // The trampoline runs the instruction after `mov cr3` from its physical address, so its
    // page(s) must be identity-mapped in the new tables; the kernel drops them at once.
    let trampoline_start = (enter_kernel as *const () as u64) & !(PAGE - 1);
    let trampoline = PhysRange {
        start: trampoline_start,
        len: 2 * PAGE,
    };
    for page in 0..2 {
        let addr = trampoline_start + page * PAGE;
        tables.map_page(addr, addr, PageFlags::empty())?;
    }

    // Room for the final memory map: today's entry count plus slack for what exit adds.
    let map_now = boot::memory_map(MemoryType::LOADER_DATA)
        .map_err(|e| format!("cannot read the memory map: {e:?}"))?;
    let region_capacity = map_now.len() + 64;
    drop(map_now);
    let info_bytes =
        core::mem::size_of::<BootInfo>() + region_capacity * core::mem::size_of::<MemoryRegion>();
    let info_pages = (info_bytes as u64).div_ceil(PAGE) as usize;
    let info_phys = allocate(MemoryKind::BOOT_INFO, info_pages)?;
    let regions_phys = info_phys + core::mem::size_of::<BootInfo>() as u64;

    let wall_clock = wall_clock();
    let cpus_in_turns = cpus_in_turns();
    println!("loader: exiting boot services");
    // SAFETY: no boot-services object (protocol, pool buffer) is alive past this point: the
    // file system and file buffers were dropped above, and nothing below allocates.
    let final_map = unsafe { boot::exit_boot_services(None) };
    x86_64::instructions::interrupts::disable();

    // SAFETY: `regions_phys` points into BOOT_INFO pages we allocated (identity-mapped by the
    // firmware), big enough for `region_capacity` regions, and nothing else uses them.
    let regions = unsafe {
        core::slice::from_raw_parts_mut(regions_phys as *mut MemoryRegion, region_capacity)
    };
    let region_count = convert_memory_map(&final_map, regions);
    let info = BootInfo {
        magic: BOOT_INFO_MAGIC,
        version: BOOT_INFO_VERSION,
        memory_region_count: region_count as u32,
        memory_regions: regions_phys,
        direct_map_base: DIRECT_MAP_BASE,
        direct_map_size,
        machine,
        system_image,
        trampoline,
        page_table_root: tables.root(),
        tsc_at_handoff: 0,
        wall_clock_at_handoff: wall_clock,
        cpus_in_turns: u32::from(cpus_in_turns),
        _reserved: 0,
    };
    // SAFETY: `info_phys` is the start of our BOOT_INFO allocation, suitably aligned (page).
    unsafe {
        (info_phys as *mut BootInfo).write(BootInfo {
            tsc_at_handoff: rdtsc(),
            ..info
        })
    };
    core::mem::forget(final_map);

    // SAFETY: the kernel relies on NX (non-executable data); EFER.NXE is architectural on
    // every x86_64 CPU and only makes the NX bit of page-table entries effective.
    unsafe {
        x86_64::registers::model_specific::Efer::update(|f| {
            f.insert(x86_64::registers::model_specific::EferFlags::NO_EXECUTE_ENABLE)
        });
    }
    // SAFETY: CR0.WP makes read-only pages read-only in ring 0 too, which the kernel relies
    // on; the loader itself writes no read-only page from here on.
    unsafe {
        x86_64::registers::control::Cr0::update(|f| {
            f.insert(x86_64::registers::control::Cr0Flags::WRITE_PROTECT)
        });
    }
    // SAFETY: the new tables map the trampoline (identity), the kernel segments and the direct
    // map that holds the boot info; the kernel's entry expects exactly these arguments.
    unsafe { enter_kernel(tables.root(), entry, DIRECT_MAP_BASE + info_phys) }
}

/// Switches to the kernel's page tables and jumps to its entry with `rdi` = boot info.
#[allow(unsafe_code)]
#[unsafe(naked)]
unsafe extern "sysv64" fn enter_kernel(pml4: u64, entry: u64, boot_info: u64) -> ! {
    core::arch::naked_asm!("mov cr3, rdi", "mov rdi, rdx", "jmp rsi")
}

#[allow(unsafe_code)] // firmware calls and raw physical memory before the kernel runs
fn rdtsc() -> u64 {
    // SAFETY: RDTSC has no side effects and exists on every x86_64 CPU.
    unsafe { core::arch::x86_64::_rdtsc() }
}

fn check_cpu() -> Result<(), String> {
    let cr4 = x86_64::registers::control::Cr4::read_raw();
    if cr4 & (1 << 12) != 0 {
        return Err(
            "the firmware enabled 5-level paging (CR4.LA57); this kernel needs 4-level paging"
                .into(),
        );
    }
    Ok(())
}

fn read_file(name: &CStr16) -> Result<alloc::vec::Vec<u8>, String> {
    let fs = boot::get_image_file_system(boot::image_handle())
        .map_err(|e| format!("cannot open the boot volume (ESP): {e:?}"))?;
    let mut fs = uefi::fs::FileSystem::new(fs);
    fs.read(name).map_err(|e| match e {
        uefi::fs::Error::Io(io) if io.uefi_error.status() == Status::NOT_FOUND => {
            format!(
                "{name} not found on the ESP (expected next to EFI/BOOT/BOOTX64.EFI's volume root)"
            )
        }
        other => format!("cannot read {name} from the ESP: {other}"),
    })
}

#[allow(unsafe_code)] // firmware calls and raw physical memory before the kernel runs
fn allocate(kind: MemoryKind, pages: usize) -> Result<u64, String> {
    let ptr = boot::allocate_pages(
        AllocateType::AnyPages,
        MemoryType::custom(kind.uefi_type()),
        pages,
    )
    .map_err(|e| {
        format!(
            "out of memory allocating {pages} pages for {}: {e:?}",
            kind.name()
        )
    })?;
    // SAFETY: fresh allocation of `pages` pages, identity-mapped by the firmware.
    unsafe { core::ptr::write_bytes(ptr.as_ptr(), 0, pages * PAGE as usize) };
    Ok(ptr.as_ptr() as u64)
}

/// Copies every `PT_LOAD` segment into fresh KERNEL pages and maps them with their rights.
/// Returns the entry point and the number of pages used.
#[allow(unsafe_code)] // firmware calls and raw physical memory before the kernel runs
fn load_kernel(file: &[u8], tables: &mut PageTableBuilder) -> Result<(u64, u64), String> {
    let elf = ElfFile::new(file).map_err(|e| format!("kernel.elf is not a valid ELF file: {e}"))?;
    let header = &elf.header;
    if header.pt1.class() != xmas_elf::header::Class::SixtyFour
        || header.pt2.machine().as_machine() != xmas_elf::header::Machine::X86_64
    {
        return Err("kernel.elf is not an x86_64 ELF64 file".into());
    }
    if header.pt2.type_().as_type() != xmas_elf::header::Type::Executable {
        return Err("kernel.elf is not a static executable (ET_EXEC); build it with relocation-model=static".into());
    }
    let entry = header.pt2.entry_point();
    let mut pages_used = 0;
    let mut entry_mapped_executable = false;
    let (_, segments) = abi::elf::load_segments::<16>(file, KERNEL_BASE..u64::MAX)
        .map_err(|e| format!("kernel.elf: {e}"))?;
    for segment in segments.iter().flatten() {
        let (vaddr, memsz) = (segment.vaddr, segment.mem_size);
        let first_page = vaddr & !(PAGE - 1);
        let pages = (vaddr + memsz - first_page).div_ceil(PAGE);
        let phys = allocate(MemoryKind::KERNEL, pages as usize)?;
        let in_page = (vaddr - first_page) as usize;
        // SAFETY: `phys` has `pages` zeroed pages; the copy stays inside them because
        // in_page + file.len() <= pages * PAGE (abi::elf checked file.len() <= memsz).
        unsafe {
            core::ptr::copy_nonoverlapping(
                segment.file.as_ptr(),
                (phys as *mut u8).wrapping_add(in_page),
                segment.file.len(),
            );
        }
        let executable = segment.rights.contains(PageRights::EXECUTE);
        let mut rights = PageFlags::GLOBAL;
        if segment.rights.contains(PageRights::WRITE) {
            rights |= PageFlags::WRITABLE;
        }
        if !executable {
            rights |= PageFlags::NO_EXECUTE;
        }
        for page in 0..pages {
            tables.map_page(first_page + page * PAGE, phys + page * PAGE, rights)?;
        }
        if executable && (vaddr..vaddr + memsz).contains(&entry) {
            entry_mapped_executable = true;
        }
        pages_used += pages;
    }
    if !entry_mapped_executable {
        return Err(format!(
            "kernel entry point {entry:#x} is not inside an executable segment"
        ));
    }
    Ok((entry, pages_used))
}

/// Validates `system.img` (so a damaged image is reported here, clearly) and copies it into
/// SYSTEM_IMAGE pages.
#[allow(unsafe_code)] // firmware calls and raw physical memory before the kernel runs
fn copy_system_image(image: &[u8]) -> Result<PhysRange, String> {
    SystemImage::parse(image).map_err(|e| format!("system.img is invalid: {e}"))?;
    let pages = (image.len() as u64).div_ceil(PAGE).max(1);
    let phys = allocate(MemoryKind::SYSTEM_IMAGE, pages as usize)?;
    // SAFETY: `phys` has room for `pages * PAGE >= image.len()` bytes.
    unsafe { core::ptr::copy_nonoverlapping(image.as_ptr(), phys as *mut u8, image.len()) };
    Ok(PhysRange {
        start: phys,
        len: image.len() as u64,
    })
}

/// Physical memory as the firmware maps it while its boot services run (identity-mapped),
/// up to `size` (what the kernel's direct map will cover).
struct IdentityMapped {
    size: u64,
}

impl acpi_tables::PhysMemory for IdentityMapped {
    #[allow(unsafe_code)] // reads firmware tables at their physical addresses
    fn bytes(&self, phys: u64, len: usize) -> Option<&[u8]> {
        if phys == 0 || phys.checked_add(len as u64)? > self.size {
            return None;
        }
        // SAFETY: UEFI identity-maps the memory its map lists, ACPI tables included, and
        // nothing writes them while the loader reads.
        Some(unsafe { core::slice::from_raw_parts(phys as *const u8, len) })
    }
}

fn find_rsdp() -> u64 {
    uefi::system::with_config_table(|entries| {
        let find = |guid| {
            entries
                .iter()
                .find(|e| e.guid == guid)
                .map(|e| e.address as u64)
        };
        find(ConfigTableEntry::ACPI2_GUID)
            .or_else(|| find(ConfigTableEntry::ACPI_GUID))
            .unwrap_or(0)
    })
}

/// Bytes of physical address space to direct-map: everything the memory map lists, and at
/// least 4 GiB so the local APIC, IOAPIC and HPET are reachable; rounded up to 1 GiB.
fn direct_map_size() -> Result<u64, String> {
    let map = boot::memory_map(MemoryType::LOADER_DATA)
        .map_err(|e| format!("cannot read the memory map: {e:?}"))?;
    let highest = map
        .entries()
        .map(|d| d.phys_start + d.page_count * PAGE)
        .max()
        .unwrap_or(0);
    let size = highest.max(4 << 30).div_ceil(1 << 30) << 30;
    // One PML4 slot of direct map per 512 GiB; keep well clear of the kernel image's slot.
    if size > 64 << 40 {
        return Err(format!(
            "physical address space of {size:#x} bytes is larger than the 64 TiB direct map"
        ));
    }
    Ok(size)
}

fn kind_of(ty: MemoryType) -> MemoryKind {
    match ty {
        MemoryType::CONVENTIONAL
        | MemoryType::BOOT_SERVICES_CODE
        | MemoryType::BOOT_SERVICES_DATA => MemoryKind::USABLE,
        MemoryType::LOADER_CODE | MemoryType::LOADER_DATA => MemoryKind::LOADER,
        MemoryType::ACPI_RECLAIM => MemoryKind::ACPI_RECLAIMABLE,
        MemoryType::ACPI_NON_VOLATILE => MemoryKind::ACPI_NVS,
        MemoryType::MMIO | MemoryType::MMIO_PORT_SPACE => MemoryKind::MMIO,
        MemoryType::RUNTIME_SERVICES_CODE | MemoryType::RUNTIME_SERVICES_DATA => {
            MemoryKind::FIRMWARE_RUNTIME
        }
        other => {
            let ours = [
                MemoryKind::KERNEL,
                MemoryKind::PAGE_TABLES,
                MemoryKind::SYSTEM_IMAGE,
                MemoryKind::BOOT_INFO,
            ];
            ours.into_iter()
                .find(|k| k.uefi_type() == other.0)
                .unwrap_or(MemoryKind::RESERVED)
        }
    }
}

/// Converts the final UEFI map into sorted, merged [`MemoryRegion`]s. Runs after boot
/// services are gone, so it neither allocates nor prints (except on COM1 if full).
fn convert_memory_map(map: &impl MemoryMap, out: &mut [MemoryRegion]) -> usize {
    let mut count = 0;
    for desc in map.entries() {
        let region = MemoryRegion {
            start: desc.phys_start,
            pages: desc.page_count,
            kind: kind_of(desc.ty),
            _reserved: 0,
        };
        // Insertion keeps `out` sorted by start; the firmware map is nearly sorted already.
        let mut at = count;
        while at > 0 && out[at - 1].start > region.start {
            at -= 1;
        }
        if count == out.len() {
            halt_with("loader: error: memory map larger than the space reserved for it\r\n");
        }
        out.copy_within(at..count, at + 1);
        out[at] = region;
        count += 1;
    }
    // Merge neighbours of the same kind.
    let mut merged = 0;
    for i in 0..count {
        let r = out[i];
        if merged > 0 && out[merged - 1].kind == r.kind && out[merged - 1].end() == r.start {
            out[merged - 1].pages += r.pages;
        } else {
            out[merged] = r;
            merged += 1;
        }
    }
    merged
}

/// Last-resort report after boot services are gone: raw COM1 output, then halt.
#[allow(unsafe_code)] // firmware calls and raw physical memory before the kernel runs
fn halt_with(message: &str) -> ! {
    struct Com1;
    impl Write for Com1 {
        fn write_str(&mut self, s: &str) -> core::fmt::Result {
            for b in s.bytes() {
                let mut data = x86_64::instructions::port::Port::<u8>::new(0x3f8);
                // SAFETY: COM1 is the firmware-initialised serial port; writing a byte is harmless.
                unsafe { data.write(b) };
            }
            Ok(())
        }
    }
    let _ = Com1.write_str(message);
    loop {
        x86_64::instructions::hlt();
    }
}

/// The firmware's real-time clock as Unix time in ns (UTC), 0 without one.
fn wall_clock() -> u64 {
    let Ok(t) = uefi::runtime::get_time() else {
        return 0;
    };
    let local = abi::boot::unix_ns(
        (t.year(), t.month(), t.day()),
        (t.hour(), t.minute(), t.second()),
        t.nanosecond(),
    );
    // UEFI: local time = UTC - time_zone (minutes); none given means UTC.
    let zone_ns = t.time_zone().unwrap_or(0) as i64 * 60_000_000_000;
    local.map_or(0, |ns| ns.saturating_add_signed(zone_ns))
}

/// Whether the host says the emulator runs the CPUs in turns on one host thread: QEMU's
/// fw_cfg file [`abi::boot::CPUS_IN_TURNS_FILE`] holds "1". Asked only under a hypervisor
/// (CPUID leaf 1, ECX bit 31) whose fw_cfg answers with its "QEMU" signature.
#[allow(unsafe_code)] // QEMU's fw_cfg I/O ports
fn cpus_in_turns() -> bool {
    use x86_64::instructions::port::Port;
    if core::arch::x86_64::__cpuid(1).ecx & (1 << 31) == 0 {
        return false;
    }
    let (mut selector, mut data) = (Port::<u16>::new(0x510), Port::<u8>::new(0x511));
    // Selecting an item and reading its bytes changes nothing else (an unknown item reads
    // as zeros).
    let mut item = |key: u16, len: usize| -> alloc::vec::Vec<u8> {
        // SAFETY: QEMU's fw_cfg selector port.
        unsafe { selector.write(key) };
        // SAFETY: QEMU's fw_cfg data port.
        (0..len).map(|_| unsafe { data.read() }).collect()
    };
    if item(0x0000, 4) != b"QEMU" {
        return false;
    }
    let count = item(0x0019, 4)
        .iter()
        .fold(0usize, |n, &b| n << 8 | usize::from(b));
    let directory = item(0x0019, 4 + 64 * count.min(1024));
    abi::boot::fw_cfg_file(&directory, abi::boot::CPUS_IN_TURNS_FILE)
        .is_some_and(|select| item(select, 1) == b"1")
}
