//! What the kernel tells the root task at start: the physical memory it may hand out with
//! `map_physical`, and the kernel-memory quota of the root resource partition. One
//! read-only page at [`ROOT_INFO_BASE`](crate::syscall::ROOT_INFO_BASE).

/// "WRDNROOT".
pub const ROOT_INFO_MAGIC: u64 = u64::from_le_bytes(*b"WRDNROOT");
pub const ROOT_INFO_VERSION: u32 = 1;
/// Most physical ranges listed.
pub const ROOT_INFO_MAX_REGIONS: usize = 32;

/// A range of physical RAM the root task may map (page-aligned).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PhysRegion {
    pub start: u64,
    pub pages: u64,
}

#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RootInfo {
    pub magic: u64,
    pub version: u32,
    pub region_count: u32,
    /// TSC frequency the kernel calibrated (Hz).
    pub tsc_hz: u64,
    /// Quota of the root resource partition (kernel memory for page tables and objects).
    pub kernel_pages: u64,
    pub kernel_threads: u64,
    pub kernel_tasks: u64,
    pub regions: [PhysRegion; ROOT_INFO_MAX_REGIONS],
}

impl RootInfo {
    pub fn regions(&self) -> &[PhysRegion] {
        &self.regions[..(self.region_count as usize).min(ROOT_INFO_MAX_REGIONS)]
    }

    /// True if `[start, start + pages * 4096)` lies inside one listed region.
    pub fn contains(&self, start: u64, pages: u64) -> bool {
        regions_contain(self.regions(), start, pages)
    }
}

/// True if `[start, start + pages * 4096)` lies inside one of `regions` (the kernel's check
/// for `map_physical` and the root task's own use the same rule).
pub fn regions_contain(regions: &[PhysRegion], start: u64, pages: u64) -> bool {
    let Some(end) = pages
        .checked_mul(4096)
        .and_then(|len| start.checked_add(len))
    else {
        return false;
    };
    regions
        .iter()
        .any(|r| start >= r.start && end <= r.start + r.pages * 4096)
}

const _: () = assert!(core::mem::size_of::<RootInfo>() <= 4096);
