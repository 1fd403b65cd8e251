//! Host tests of the AP bring-up's pure logic (`kernel/src/arch/smp.rs`).

use super::*;

fn region(start: u64, pages: u64, kind: MemoryKind) -> MemoryRegion {
    MemoryRegion {
        start,
        pages,
        kind,
        _reserved: 0,
    }
}

#[test]
fn trampoline_takes_four_usable_pages_below_1_mib_never_page_0() {
    let map = [
        region(0, 2, MemoryKind::USABLE),
        region(0x2000, 1, MemoryKind::LOADER),
        region(0x3000, 0x9c, MemoryKind::USABLE),
        region(0x10_0000, 0x1000, MemoryKind::USABLE),
    ];
    assert_eq!(trampoline_pages(&map), Some(0x3000));
    // Page 0 alone is never used; a region crossing 1 MiB counts only below it.
    let map = [
        region(0, 5, MemoryKind::USABLE),
        region(0xfe000, 100, MemoryKind::USABLE),
    ];
    assert_eq!(trampoline_pages(&map), Some(0x1000));
    let map = [region(0xfd000, 100, MemoryKind::USABLE)];
    assert_eq!(trampoline_pages(&map), None);
    let map = [region(0x1000, 100, MemoryKind::RESERVED)];
    assert_eq!(trampoline_pages(&map), None);
    assert_eq!(trampoline_pages(&[]), None);
}

#[test]
fn a_cpu_block_fits_its_reserved_frames() {
    const {
        assert!(BLOCK_PAGES * PAGE_SIZE >= core::mem::size_of::<CpuBlock>() as u64);
        assert!(core::mem::align_of::<CpuBlock>() as u64 <= PAGE_SIZE);
        assert!(BLOCK_PAGES <= 18);
    }
}
