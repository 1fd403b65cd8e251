//! What a partition needs to start: bytes of its memory (image, data entry, stack, DMA region) and bytes
//! of its kernel-memory quota (the page tables of everything syssw maps for it, its top-level
//! table and, with I/O ports, its I/O permission bitmap), and the memory pool a partition
//! with the `map` ability gets (the rest of its `memory`, `protocol::layout::POOL_BASE`). One computation for both users:
//! syssw refuses a partition that does not fit before it builds anything, and `cargo xtask`
//! refuses to build a system image with such a partition, naming the configuration key, so a
//! validated system never fails at boot for want of memory.
//!
//! The page-table count is exact for a fresh address space, as the kernel charges it
//! (`kernel/src/mem/paging.rs`, `tables_needed`): one table per level per covered span, the
//! top level charged once at `task_create`; the I/O bitmap is 2 pages (`io_grant`). What the
//! partition maps itself later comes on top.

use abi::elf::{ElfError, load_segments};
use abi::syscall::{Abilities, USER_MIN};
use config::binary::{PartitionView, SystemView};
use protocol::layout::{
    DATA_BASE, DEVICES_BASE, DMA_BASE, POOL_BASE, POOL_EXEC_BASE, STACK_TOP, shared_address,
};

const PAGE: u64 = 4096;
/// Loadable segments an image may have (syssw's limit).
pub const MAX_IMAGE_SEGMENTS: usize = 16;
/// Regions mapped at start: image segments, stack, data entry, device page, DMA region,
/// shared segments.
const MAX_REGIONS: usize = MAX_IMAGE_SEGMENTS + 4 + config::model::MAX_SEGMENTS;
/// Pages of the top-level table (charged by `task_create`) and of the I/O bitmap.
const TOP_TABLE_PAGES: u64 = 1;
const IO_BITMAP_PAGES: u64 = 2;

/// A partition's needs at start, in bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StartBudget {
    /// Of its `memory`: image pages, data-entry pages, the stack and the DMA region.
    pub memory: u64,
    /// Of its `kernel_memory` quota (including the page tables of the pool).
    pub kernel_memory: u64,
    /// Its memory pool: what `memory` leaves after `memory` above, for a partition with
    /// the `map` ability (0 otherwise, or when nothing is left).
    pub pool: u64,
}

/// The pages of an image segment: first page address and count.
pub fn segment_pages(vaddr: u64, mem_size: u64) -> (u64, u64) {
    let first = vaddr / PAGE * PAGE;
    (first, (vaddr + mem_size).div_ceil(PAGE) - first / PAGE)
}

/// What partition `p` of `system` needs to start with image `elf` and a data entry of
/// `data_len` bytes.
pub fn start_budget(
    system: &SystemView,
    p: &PartitionView,
    elf: &[u8],
    data_len: u64,
) -> Result<StartBudget, ElfError> {
    let (_, segments) = load_segments::<MAX_IMAGE_SEGMENTS>(elf, USER_MIN..DATA_BASE)?;
    let mut regions = Regions::new();
    let mut image_pages = 0;
    for s in segments.iter().flatten() {
        let (first, pages) = segment_pages(s.vaddr, s.mem_size);
        image_pages += pages;
        regions.add(first, pages);
    }
    let stack_pages = p.stack / PAGE;
    regions.add(STACK_TOP - stack_pages * PAGE, stack_pages);
    let data_pages = data_len.div_ceil(PAGE);
    regions.add(DATA_BASE, data_pages);
    for a in p.shared() {
        let address = shared_address(system.segments().take(a.segment).map(|s| s.size));
        regions.add(address, system.segment(a.segment).size / PAGE);
    }
    let dma_pages = p.dma / PAGE;
    regions.add(DMA_BASE, dma_pages);
    let used = image_pages + data_pages + stack_pages + dma_pages;
    let pool_pages = if p.abilities.contains(Abilities::MAP) {
        (p.memory / PAGE).saturating_sub(used)
    } else {
        0
    };
    if p.devices().next().is_some() {
        // The device page; memory BARs whose page tables go beyond it are known only at
        // boot (syssw then refuses the partition if its quota falls short).
        regions.add(DEVICES_BASE, 1);
    }
    regions.add(POOL_BASE, pool_pages);
    regions.add(POOL_EXEC_BASE, pool_pages);
    let io = if p.io_ports().next().is_some() {
        IO_BITMAP_PAGES
    } else {
        0
    };
    Ok(StartBudget {
        memory: used * PAGE,
        kernel_memory: (TOP_TABLE_PAGES + regions.page_tables() + io) * PAGE,
        pool: pool_pages * PAGE,
    })
}

/// The page runs mapped at start (first page address, count).
struct Regions {
    runs: [(u64, u64); MAX_REGIONS],
    count: usize,
}

impl Regions {
    fn new() -> Self {
        Regions {
            runs: [(0, 0); MAX_REGIONS],
            count: 0,
        }
    }

    fn add(&mut self, first: u64, pages: u64) {
        if pages > 0 && self.count < MAX_REGIONS {
            self.runs[self.count] = (first, pages);
            self.count += 1;
        }
    }

    /// Tables below the top level that cover the runs: per level, the distinct spans the
    /// runs touch (a table at level `l` covers `512^l` pages).
    fn page_tables(&self) -> u64 {
        let mut total = 0;
        for shift in [21u32, 30, 39] {
            let mut spans = [(0u64, 0u64); MAX_REGIONS];
            for (slot, &(first, pages)) in spans.iter_mut().zip(&self.runs[..self.count]) {
                let last = first + (pages - 1) * PAGE;
                *slot = (first >> shift, last >> shift);
            }
            let spans = &mut spans[..self.count];
            spans.sort_unstable();
            // Count the indices the (sorted) spans cover, each once.
            let mut covered_to = None;
            for &(from, to) in spans.iter() {
                let from = match covered_to {
                    Some(end) if from <= end => end + 1,
                    _ => from,
                };
                if from <= to {
                    total += to - from + 1;
                }
                covered_to = Some(covered_to.map_or(to, |end: u64| end.max(to)));
            }
        }
        total
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testsys::elf;

    fn tables(runs: &[(u64, u64)]) -> u64 {
        let mut r = Regions::new();
        for &(first, pages) in runs {
            r.add(first, pages);
        }
        r.page_tables()
    }

    #[test]
    fn one_page_needs_one_table_per_level() {
        assert_eq!(tables(&[(0x20_0000, 1)]), 3);
    }

    #[test]
    fn runs_share_tables_they_have_in_common() {
        // Two pages in one 2 MiB span: still one table per level.
        assert_eq!(tables(&[(0x20_0000, 1), (0x20_1000, 1)]), 3);
        // A run across a 2 MiB boundary needs two last-level tables.
        assert_eq!(tables(&[(0x1f_f000, 2)]), 4);
        // Far apart (different 512 GiB spans): nothing shared.
        assert_eq!(tables(&[(0x20_0000, 1), (STACK_TOP - PAGE, 1)]), 6);
        // Nested runs count once.
        assert_eq!(tables(&[(0x20_0000, 512), (0x20_1000, 1)]), 3);
    }

    #[test]
    fn a_partitions_start_budget() {
        let blob = crate::testsys::blob(&crate::testsys::with(&[
            (
                "# a",
                "io_ports = [\"0x2f8-0x2ff\"]\nshared = { s = \"rw\" }",
            ),
            ("# tail", "[[shared_memory]]\nname = \"s\"\nsize = \"8KiB\""),
        ]));
        let system = config::decode(&blob).unwrap();
        let a = system.partition(0);
        // 3 image pages at 2 MiB, the default 64 KiB stack, a 5000-byte data entry, 2 shared
        // pages at SHARED_BASE.
        let budget = start_budget(&system, &a, &elf(0x20_0000, 3 * PAGE), 5000).unwrap();
        assert_eq!(budget.memory, (3 + 16 + 2) * PAGE);
        // Last-level tables: image, stack, data, shared (4, all far apart); one level up: 4;
        // the 512 GiB spans: image (0), data (0xa0), shared (0xc0), stack (0xff): 4. Plus
        // the top-level table and the I/O bitmap.
        assert_eq!(budget.kernel_memory, (4 + 4 + 4 + 1 + 2) * PAGE);
        assert_eq!(budget.pool, 0, "no `map` ability, no pool");
        assert!(start_budget(&system, &a, b"not an elf", 0).is_err());
    }

    #[test]
    fn a_partition_with_map_gets_the_rest_of_its_memory_as_pool() {
        let blob = crate::testsys::blob(&crate::testsys::with(&[("# a", "abilities = [\"map\"]")]));
        let system = config::decode(&blob).unwrap();
        let a = system.partition(0);
        let without = start_budget(&system, &a, &elf(0x20_0000, 3 * PAGE), 0).unwrap();
        assert_eq!(without.memory, (3 + 16) * PAGE);
        assert_eq!(without.pool, a.memory - without.memory);
        // The pool's page tables, for each of its two mappings (in their own 512 GiB
        // spans, 0xb0 and 0xb8): one table per level for each 2 MiB / 1 GiB / 512 GiB.
        let pool_pages = without.pool / PAGE;
        let tables = 2 * (pool_pages.div_ceil(512) + pool_pages.div_ceil(512 * 512) + 1);
        let mut no_pool = Regions::new();
        no_pool.add(0x20_0000, 3);
        no_pool.add(STACK_TOP - 16 * PAGE, 16);
        assert_eq!(
            without.kernel_memory,
            (TOP_TABLE_PAGES + no_pool.page_tables() + tables) * PAGE
        );
    }

    #[test]
    fn the_device_page_of_a_partition_with_devices_costs_its_page_tables() {
        let budget = |edit: &str| {
            let blob = crate::testsys::blob(&crate::testsys::with(&[("# a", edit)]));
            let system = config::decode(&blob).unwrap();
            let a = system.partition(0);
            start_budget(&system, &a, &elf(0x20_0000, 3 * PAGE), 0).unwrap()
        };
        let without = budget("abilities = [\"irq\"]");
        let with = budget("abilities = [\"irq\"]\ndevices = [\"00:03.0\"]");
        // DEVICES_BASE has a 512 GiB span of its own: one table per level.
        assert_eq!(with.kernel_memory, without.kernel_memory + 3 * PAGE);
        assert_eq!(
            with.memory, without.memory,
            "syssw's page, not the partition's memory"
        );
    }

    #[test]
    fn the_dma_region_is_partition_memory_and_costs_its_page_tables() {
        let budget = |edit: &str| {
            let blob = crate::testsys::blob(&crate::testsys::with(&[("# a", edit)]));
            let system = config::decode(&blob).unwrap();
            let a = system.partition(0);
            start_budget(&system, &a, &elf(0x20_0000, 3 * PAGE), 0).unwrap()
        };
        let devices = "abilities = [\"irq\"]\ndevices = [\"00:03.0\"]";
        let without = budget(devices);
        let with = budget(&std::format!("{devices}\ndma = \"8KiB\""));
        assert_eq!(with.memory, without.memory + 2 * PAGE);
        // DMA_BASE has a 512 GiB span of its own: one table per level.
        assert_eq!(with.kernel_memory, without.kernel_memory + 3 * PAGE);
    }

    #[test]
    fn a_gigabyte_run() {
        // 1 GiB aligned: 512 last-level tables, one of each level above.
        assert_eq!(tables(&[(1 << 30, 512 * 512)]), 512 + 1 + 1);
    }
}
