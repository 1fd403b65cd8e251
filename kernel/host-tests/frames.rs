//! Host tests of the frame allocator (`kernel/src/mem/frames.rs`); kept outside `src` so that the
//! ring-0 code budget counts only what runs in ring 0.

use super::*;
use std::collections::HashMap;

#[derive(Default)]
struct FakeLinks(HashMap<u64, u64>);

impl FrameLinks for FakeLinks {
    fn next(&self, frame: u64) -> u64 {
        self.0[&frame]
    }
    fn set_next(&mut self, frame: u64, next: u64) {
        self.0.insert(frame, next);
    }
}

fn region(start: u64, pages: u64, kind: MemoryKind) -> MemoryRegion {
    MemoryRegion {
        start,
        pages,
        kind,
        _reserved: 0,
    }
}

#[test]
fn hands_out_only_usable_frames_above_the_floor() {
    let map = [
        region(0, 16, MemoryKind::USABLE),        // below the 1 MiB floor
        region(0x10_0000, 2, MemoryKind::USABLE), // 2 frames
        region(0x10_2000, 4, MemoryKind::KERNEL), // reserved
        region(0x20_0000, 1, MemoryKind::SYSTEM_IMAGE),
        region(0x30_0000, 3, MemoryKind::USABLE), // 3 frames
        region(0x40_0000, 8, MemoryKind::ACPI_RECLAIMABLE),
    ];
    let mut a = FrameAllocator::new(&map, 0x10_0000);
    assert_eq!(a.total_frames(), 5);
    let links = FakeLinks::default();
    let got: Vec<u64> = std::iter::from_fn(|| a.allocate(&links)).collect();
    assert_eq!(
        got,
        vec![0x10_0000, 0x10_1000, 0x30_0000, 0x30_1000, 0x30_2000]
    );
    assert_eq!(a.free_frames(), 0);
    assert_eq!(a.allocate(&links), None);
}

#[test]
fn freed_frames_are_reused_last_in_first_out() {
    let map = [region(0x10_0000, 4, MemoryKind::USABLE)];
    let mut a = FrameAllocator::new(&map, 0x10_0000);
    let mut links = FakeLinks::default();
    let f1 = a.allocate(&links).unwrap();
    let f2 = a.allocate(&links).unwrap();
    a.free(f1, &mut links);
    a.free(f2, &mut links);
    assert_eq!(a.free_frames(), 4);
    assert_eq!(a.allocate(&links), Some(f2));
    assert_eq!(a.allocate(&links), Some(f1));
    assert_eq!(a.allocate(&links), Some(0x10_2000));
}

#[test]
fn split_keeps_the_first_frames_and_hands_out_the_rest() {
    let map = [
        region(0x10_0000, 4, MemoryKind::USABLE),
        region(0x30_0000, 4, MemoryKind::USABLE),
    ];
    let mut a = FrameAllocator::new(&map, 0x10_0000);
    let mut out = [(0, 0); 4];
    let n = a.split_off_beyond(5, &mut out);
    assert_eq!(&out[..n], &[(0x30_1000, 0x30_4000)]);
    assert_eq!(a.total_frames(), 5);
    let links = FakeLinks::default();
    let got: Vec<u64> = std::iter::from_fn(|| a.allocate(&links)).collect();
    assert_eq!(got.len(), 5);
    assert_eq!(got[4], 0x30_0000);
}

#[test]
fn unaligned_regions_are_trimmed_inward() {
    let map = [region(0x10_0800, 3, MemoryKind::USABLE)]; // 0x100800..0x103800
    let a = FrameAllocator::new(&map, 0);
    assert_eq!(a.total_frames(), 2); // 0x101000, 0x102000
}

#[test]
fn too_many_ranges_are_counted_not_lost_silently() {
    let map: Vec<MemoryRegion> = (0..MAX_RANGES as u64 + 3)
        .map(|i| region(0x100_0000 + i * 0x2000, 1, MemoryKind::USABLE))
        .collect();
    let a = FrameAllocator::new(&map, 0);
    assert_eq!(a.ignored_ranges(), 3);
    assert_eq!(a.total_frames(), MAX_RANGES as u64);
}
