//! The boot-information block: what the UEFI loader tells the kernel.
//!
//! The loader fills one [`BootInfo`] (plus the array of [`MemoryRegion`]s it points to) in
//! memory it marks [`MemoryKind::BOOT_INFO`], builds the kernel's page tables and jumps to
//! the kernel's ELF entry point with the block's *virtual* address (in the direct map) in
//! `rdi`, interrupts disabled.
//!
//! Address-space layout at entry:
//! - `KERNEL_BASE` (top 2 GiB): the kernel ELF's `PT_LOAD` segments with their own rights
//!   (W^X, non-executable data);
//! - `DIRECT_MAP_BASE`: all physical memory (at least the first 4 GiB, so that the local
//!   APIC, IOAPIC and HPET are reachable), read/write, never executable;
//! - the lower half is empty except for one or two identity-mapped pages holding the
//!   loader's CR3-switch trampoline ([`BootInfo::trampoline`]); the kernel removes them
//!   before anything else, so user space owns the whole lower half.

/// Virtual address where the loader maps physical address 0 (PML4 slot 256, the first
/// kernel-half slot). `virt = DIRECT_MAP_BASE + phys` for all mapped physical memory.
pub const DIRECT_MAP_BASE: u64 = 0xffff_8000_0000_0000;

/// Lowest virtual address of the kernel image (the top 2 GiB, for `code-model=kernel`).
pub const KERNEL_BASE: u64 = 0xffff_ffff_8000_0000;

/// `BootInfo::magic`: "PKBOOTIN".
pub const BOOT_INFO_MAGIC: u64 = u64::from_le_bytes(*b"PKBOOTIN");

/// Bumped on every incompatible change of [`BootInfo`] or [`MemoryRegion`].
pub const BOOT_INFO_VERSION: u32 = 4;

/// A physical address range, `[start, start + len)`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PhysRange {
    pub start: u64,
    pub len: u64,
}

impl PhysRange {
    pub const fn end(&self) -> u64 {
        self.start + self.len
    }
}

/// What a physical memory region holds. A newtype over `u32` rather than an enum so that
/// an unknown value from a newer loader is representable (the kernel treats it as reserved).
#[repr(transparent)]
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct MemoryKind(pub u32);

impl MemoryKind {
    /// Free RAM the kernel may hand out.
    pub const USABLE: Self = Self(1);
    /// Firmware-reserved, unusable or unknown.
    pub const RESERVED: Self = Self(2);
    /// ACPI tables; kept because the kernel reads them.
    pub const ACPI_RECLAIMABLE: Self = Self(3);
    /// ACPI non-volatile storage; never touched.
    pub const ACPI_NVS: Self = Self(4);
    /// Memory-mapped I/O listed by the firmware.
    pub const MMIO: Self = Self(5);
    /// The loader's own code and data (incl. the trampoline).
    pub const LOADER: Self = Self(6);
    /// The kernel's `PT_LOAD` segments.
    pub const KERNEL: Self = Self(7);
    /// The page tables the loader built for the kernel.
    pub const PAGE_TABLES: Self = Self(8);
    /// The system image (`system.img`).
    pub const SYSTEM_IMAGE: Self = Self(9);
    /// This block and its memory-region array.
    pub const BOOT_INFO: Self = Self(10);
    /// UEFI runtime services code/data; must stay untouched.
    pub const FIRMWARE_RUNTIME: Self = Self(11);

    /// Every kind, in the order the kernel's memory summary lists them.
    pub const ALL: [Self; 11] = [
        Self::USABLE,
        Self::LOADER,
        Self::KERNEL,
        Self::PAGE_TABLES,
        Self::SYSTEM_IMAGE,
        Self::BOOT_INFO,
        Self::ACPI_RECLAIMABLE,
        Self::ACPI_NVS,
        Self::FIRMWARE_RUNTIME,
        Self::MMIO,
        Self::RESERVED,
    ];

    /// Short name for logs.
    pub const fn name(self) -> &'static str {
        match self {
            Self::USABLE => "usable",
            Self::RESERVED => "reserved",
            Self::ACPI_RECLAIMABLE => "acpi",
            Self::ACPI_NVS => "acpi-nvs",
            Self::MMIO => "mmio",
            Self::LOADER => "loader",
            Self::KERNEL => "kernel",
            Self::PAGE_TABLES => "page-tables",
            Self::SYSTEM_IMAGE => "system-image",
            Self::BOOT_INFO => "boot-info",
            Self::FIRMWARE_RUNTIME => "firmware-runtime",
            _ => "unknown",
        }
    }

    /// The UEFI memory type (an OS-defined value, 0x8000_0000 and up) the loader allocates
    /// memory of this kind with, so that the final UEFI memory map already says who owns it.
    pub const fn uefi_type(self) -> u32 {
        0x8000_0000 | self.0
    }
}

impl core::fmt::Debug for MemoryKind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}({})", self.name(), self.0)
    }
}

/// One entry of the physical memory map: `pages` 4 KiB pages from `start`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryRegion {
    pub start: u64,
    pub pages: u64,
    pub kind: MemoryKind,
    pub _reserved: u32,
}

impl MemoryRegion {
    pub const fn end(&self) -> u64 {
        self.start + self.pages * 4096
    }
}

/// The block the loader passes to the kernel entry point.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct BootInfo {
    /// [`BOOT_INFO_MAGIC`].
    pub magic: u64,
    /// [`BOOT_INFO_VERSION`].
    pub version: u32,
    /// Number of [`MemoryRegion`]s at `memory_regions`.
    pub memory_region_count: u32,
    /// Physical address of the memory-region array, sorted by `start`, non-overlapping.
    pub memory_regions: u64,
    /// [`DIRECT_MAP_BASE`], repeated so the kernel can check it.
    pub direct_map_base: u64,
    /// Bytes of physical address space covered by the direct map.
    pub direct_map_size: u64,
    /// Where `system.img` was loaded (page-aligned, marked [`MemoryKind::SYSTEM_IMAGE`]).
    pub system_image: PhysRange,
    /// Physical page(s) of the loader trampoline, identity-mapped; the kernel unmaps them.
    pub trampoline: PhysRange,
    /// Physical address of the PML4 the loader built (the kernel's CR3 at entry).
    pub page_table_root: u64,
    /// TSC value read just before the jump, so the kernel can report loader-to-kernel time.
    pub tsc_at_handoff: u64,
    /// The firmware's real-time clock when the loader read it, just before the handoff, as
    /// nanoseconds since the Unix epoch (UTC; a clock without a time zone is taken as UTC);
    /// 0 when the firmware has no clock.
    pub wall_clock_at_handoff: u64,
    /// 1 when the emulator runs the CPUs in turns on one host thread (QEMU's fw_cfg file
    /// [`CPUS_IN_TURNS_FILE`] holds "1"), else 0: the kernel then bounds every turn with a
    /// timer (docs/architecture.md, "Multicore").
    pub cpus_in_turns: u32,
    pub _reserved: u32,
    /// The CPUs, interrupt controllers, HPET and DMA remapping unit the firmware's ACPI
    /// tables list (the loader parsed them).
    pub machine: crate::machine::Machine,
}

/// The QEMU fw_cfg file by which the host says the emulator runs the CPUs in turns on one
/// host thread (`-fw_cfg name=opt/warden/cpus-in-turns,string=1`: `-icount`, or TCG with
/// `thread=single`), which the machine cannot tell from CPUs a loaded host holds back.
pub const CPUS_IN_TURNS_FILE: &[u8] = b"opt/warden/cpus-in-turns";

/// The selector of file `name` in a QEMU fw_cfg file directory (item 0x19: a big-endian
/// count, then 64-byte entries of big-endian size, selector, reserved and a
/// NUL-padded name), or `None`.
pub fn fw_cfg_file(directory: &[u8], name: &[u8]) -> Option<u16> {
    let count = u32::from_be_bytes(directory.get(..4)?.try_into().ok()?) as usize;
    let entries = directory.get(4..)?.chunks_exact(64).take(count);
    entries
        .filter(|e| e[8..].split(|&b| b == 0).next() == Some(name))
        .map(|e| u16::from_be_bytes([e[4], e[5]]))
        .next()
}

/// Nanoseconds since 1970-01-01T00:00:00Z of a calendar date and time (UTC), or `None`
/// for an impossible one (month 1..=12, day 1..=31, year from 1970; leap seconds are not
/// counted, as Unix time does not).
pub fn unix_ns(
    (year, month, day): (u16, u8, u8),
    (hour, minute, second): (u8, u8, u8),
    nanosecond: u32,
) -> Option<u64> {
    if year < 1970 || !(1..=12).contains(&month) || !(1..=31).contains(&day) {
        return None;
    }
    if hour > 23 || minute > 59 || second > 60 || nanosecond >= 1_000_000_000 {
        return None;
    }
    // Days from the epoch to the date (the proleptic Gregorian calendar, years counted
    // from March so that the leap day comes last).
    let (y, m) = if month <= 2 {
        (year as i64 - 1, month as i64 + 9)
    } else {
        (year as i64, month as i64 - 3)
    };
    let era = y.div_euclid(400);
    let year_of_era = y - era * 400;
    let day_of_year = (153 * m + 2) / 5 + day as i64 - 1;
    let day_of_era = year_of_era * 365 + year_of_era / 4 - year_of_era / 100 + day_of_year;
    let days = era * 146_097 + day_of_era - 719_468;
    let seconds = days * 86_400 + hour as i64 * 3600 + minute as i64 * 60 + second as i64;
    u64::try_from(seconds)
        .ok()?
        .checked_mul(1_000_000_000)?
        .checked_add(nanosecond as u64)
}

impl BootInfo {
    /// Checks what the kernel relies on before it reads anything else.
    pub fn check(&self) -> Result<(), &'static str> {
        if self.magic != BOOT_INFO_MAGIC {
            return Err("bad boot-info magic");
        }
        if self.version != BOOT_INFO_VERSION {
            return Err("boot-info version mismatch between loader and kernel");
        }
        if self.direct_map_base != DIRECT_MAP_BASE {
            return Err("loader used a different direct-map base");
        }
        if self.memory_region_count == 0 {
            return Err("empty memory map");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_stable() {
        // Loader and kernel are built separately: these sizes are part of the contract.
        assert_eq!(core::mem::size_of::<MemoryRegion>(), 24);
        assert_eq!(core::mem::size_of::<BootInfo>(), 488);
        assert_eq!(core::mem::size_of::<crate::machine::Machine>(), 384);
        assert_eq!(core::mem::size_of::<PhysRange>(), 16);
    }

    #[test]
    fn custom_uefi_types_are_in_the_os_range() {
        assert_eq!(MemoryKind::KERNEL.uefi_type(), 0x8000_0007);
        assert!(MemoryKind::BOOT_INFO.uefi_type() >= 0x8000_0000);
    }

    #[test]
    fn calendar_dates_become_unix_time() {
        assert_eq!(unix_ns((1970, 1, 1), (0, 0, 0), 0), Some(0));
        assert_eq!(
            unix_ns((2000, 3, 1), (0, 0, 1), 5),
            Some(951_868_801_000_000_005)
        );
        // 2024-02-29 (a leap day) 12:34:56 UTC.
        assert_eq!(
            unix_ns((2024, 2, 29), (12, 34, 56), 0),
            Some(1_709_210_096_000_000_000)
        );
        assert_eq!(unix_ns((2026, 13, 1), (0, 0, 0), 0), None);
        assert_eq!(unix_ns((1969, 12, 31), (23, 59, 59), 0), None);
    }

    #[test]
    fn fw_cfg_files_by_name() {
        let entry = |size: u32, select: u16, name: &[u8]| {
            let mut e = [0u8; 64];
            e[..4].copy_from_slice(&size.to_be_bytes());
            e[4..6].copy_from_slice(&select.to_be_bytes());
            e[8..8 + name.len()].copy_from_slice(name);
            e
        };
        let mut directory = 2u32.to_be_bytes().to_vec();
        directory.extend(entry(4, 0x20, b"etc/boot-fail-wait"));
        directory.extend(entry(1, 0x2a, CPUS_IN_TURNS_FILE));
        assert_eq!(fw_cfg_file(&directory, CPUS_IN_TURNS_FILE), Some(0x2a));
        assert_eq!(fw_cfg_file(&directory, b"etc/boot-fail"), None);
        // A count beyond the entries read, a short or empty directory.
        directory[..4].copy_from_slice(&9u32.to_be_bytes());
        assert_eq!(fw_cfg_file(&directory, CPUS_IN_TURNS_FILE), Some(0x2a));
        assert_eq!(fw_cfg_file(&directory[..70], CPUS_IN_TURNS_FILE), None);
        assert_eq!(fw_cfg_file(&[], CPUS_IN_TURNS_FILE), None);
    }

    #[test]
    fn check_rejects_mismatches() {
        let good = BootInfo {
            magic: BOOT_INFO_MAGIC,
            version: BOOT_INFO_VERSION,
            memory_region_count: 1,
            memory_regions: 0x1000,
            direct_map_base: DIRECT_MAP_BASE,
            direct_map_size: 1 << 32,
            machine: crate::machine::Machine::EMPTY,
            system_image: PhysRange::default(),
            trampoline: PhysRange::default(),
            page_table_root: 0,
            tsc_at_handoff: 0,
            wall_clock_at_handoff: 0,
            cpus_in_turns: 0,
            _reserved: 0,
        };
        assert!(good.check().is_ok());
        assert!(BootInfo { magic: 0, ..good }.check().is_err());
        assert!(
            BootInfo {
                version: 99,
                ..good
            }
            .check()
            .is_err()
        );
        assert!(
            BootInfo {
                direct_map_base: 0,
                ..good
            }
            .check()
            .is_err()
        );
        assert!(
            BootInfo {
                memory_region_count: 0,
                ..good
            }
            .check()
            .is_err()
        );
    }
}
