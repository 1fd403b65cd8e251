//! The kernel's initial 4-level page tables, built while the firmware's identity mapping is
//! still active (so a table's physical address is also where the loader writes it).

use crate::{PAGE, allocate};
use abi::boot::MemoryKind;
use alloc::format;
use alloc::string::String;

/// Rights of a leaf entry beyond "present".
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct PageFlags(u64);

impl PageFlags {
    pub const WRITABLE: Self = Self(1 << 1);
    pub const GLOBAL: Self = Self(1 << 8);
    pub const NO_EXECUTE: Self = Self(1 << 63);

    pub const fn empty() -> Self {
        Self(0)
    }
}

impl core::ops::BitOr for PageFlags {
    type Output = Self;
    fn bitor(self, rhs: Self) -> Self {
        Self(self.0 | rhs.0)
    }
}

impl core::ops::BitOrAssign for PageFlags {
    fn bitor_assign(&mut self, rhs: Self) {
        self.0 |= rhs.0;
    }
}

const PRESENT: u64 = 1 << 0;
const WRITABLE: u64 = 1 << 1;
const HUGE: u64 = 1 << 7;
const ADDRESS_MASK: u64 = 0x000f_ffff_ffff_f000;
const HUGE_PAGE: u64 = 2 << 20;

pub struct PageTableBuilder {
    root: Table,
}

/// A page-table page this builder allocated (and zeroed). Only this module makes one, from
/// `allocate` or from an entry it wrote itself, which is what makes [`Table::entries`] safe.
#[derive(Clone, Copy)]
struct Table(u64);

impl Table {
    fn new() -> Result<Self, String> {
        Ok(Self(allocate(MemoryKind::PAGE_TABLES, 1)?))
    }

    #[allow(unsafe_code)] // a raw physical page: the tables are built before paging switches
    fn entries(self) -> &'static mut [u64; 512] {
        // SAFETY: a `Table` is a PAGE_TABLES page we allocated and zeroed; the firmware
        // identity-maps it and the builder, which holds no other reference into it while
        // an entry is written, is its only user.
        unsafe { &mut *(self.0 as *mut [u64; 512]) }
    }
}

fn index(virt: u64, level: u32) -> usize {
    ((virt >> (12 + 9 * level)) & 511) as usize
}

impl PageTableBuilder {
    pub fn new() -> Result<Self, String> {
        Ok(Self {
            root: Table::new()?,
        })
    }

    pub fn root(&self) -> u64 {
        self.root.0
    }

    /// Returns the table one level below `entry`, creating it. Intermediate entries are
    /// permissive (writable, executable); the leaf decides the rights.
    fn next(entry: &mut u64) -> Result<Table, String> {
        if *entry & PRESENT == 0 {
            *entry = Table::new()?.0 | PRESENT | WRITABLE;
        } else if *entry & HUGE != 0 {
            return Err("page-table conflict: a 4 KiB mapping inside a huge page".into());
        }
        Ok(Table(*entry & ADDRESS_MASK))
    }

    /// Maps one 4 KiB page.
    pub fn map_page(&mut self, virt: u64, phys: u64, flags: PageFlags) -> Result<(), String> {
        let mut t = self.root;
        for level in (1..4).rev() {
            t = Self::next(&mut t.entries()[index(virt, level)])?;
        }
        let leaf = &mut t.entries()[index(virt, 0)];
        if *leaf & PRESENT != 0 {
            return Err(format!(
                "page {virt:#x} mapped twice (overlapping kernel segments?)"
            ));
        }
        *leaf = phys | PRESENT | flags.0;
        Ok(())
    }

    /// Maps `[0, size)` physical at `base` with 2 MiB pages: read/write, never executable.
    pub fn map_direct(&mut self, base: u64, size: u64) -> Result<(), String> {
        let mut phys = 0;
        while phys < size {
            let virt = base + phys;
            let mut t = self.root;
            for level in (2..4).rev() {
                t = Self::next(&mut t.entries()[index(virt, level)])?;
            }
            t.entries()[index(virt, 1)] =
                phys | PRESENT | WRITABLE | HUGE | PageFlags::GLOBAL.0 | PageFlags::NO_EXECUTE.0;
            phys += HUGE_PAGE;
        }
        Ok(())
    }
}

const _: () = assert!(PAGE == 4096);
