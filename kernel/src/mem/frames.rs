//! Physical frame allocator over the loader's memory map.
//!
//! O(1) in both directions and without a heap: never-used frames are taken from the usable
//! ranges with a bump pointer; freed frames form an intrusive list (each free frame stores
//! the address of the next one in its first 8 bytes, written through [`FrameLinks`], which
//! is the direct map on the target and a table in host tests). Only [`MemoryKind::USABLE`]
//! memory at or above a floor is ever handed out: loader, kernel, page tables, system image,
//! boot info, ACPI and firmware regions stay reserved.

use abi::boot::{MemoryKind, MemoryRegion};

const PAGE: u64 = 4096;

/// At most this many usable ranges are managed; more are reported as ignored.
pub const MAX_RANGES: usize = 64;

/// How the allocator reads and writes the link stored in a free frame.
pub trait FrameLinks {
    fn next(&self, frame: u64) -> u64;
    fn set_next(&mut self, frame: u64, next: u64);
}

#[derive(Clone, Copy, Default, Debug)]
struct Range {
    next: u64,
    end: u64,
}

/// Sentinel for "no frame" in the free list (frame 0 is below every floor we accept).
const NONE: u64 = 0;

#[derive(Debug)]
pub struct FrameAllocator {
    ranges: [Range; MAX_RANGES],
    range_count: usize,
    /// Index of the first range whose bump pointer may still have frames.
    current: usize,
    free_list: u64,
    free_frames: u64,
    total_frames: u64,
    ignored_ranges: usize,
}

impl FrameAllocator {
    /// Manages the usable regions of `regions` above `floor` (page-aligned inward).
    pub fn new(regions: &[MemoryRegion], floor: u64) -> Self {
        let floor = floor.max(PAGE);
        let mut a = FrameAllocator {
            ranges: [Range::default(); MAX_RANGES],
            range_count: 0,
            current: 0,
            free_list: NONE,
            free_frames: 0,
            total_frames: 0,
            ignored_ranges: 0,
        };
        for r in regions.iter().filter(|r| r.kind == MemoryKind::USABLE) {
            let start = r.start.max(floor).next_multiple_of(PAGE);
            let end = r.end() & !(PAGE - 1);
            if start >= end {
                continue;
            }
            if a.range_count == MAX_RANGES {
                a.ignored_ranges += 1;
                continue;
            }
            a.ranges[a.range_count] = Range { next: start, end };
            a.range_count += 1;
            a.total_frames += (end - start) / PAGE;
        }
        a.free_frames = a.total_frames;
        a
    }

    pub fn allocate(&mut self, links: &impl FrameLinks) -> Option<u64> {
        if self.free_list != NONE {
            let frame = self.free_list;
            self.free_list = links.next(frame);
            self.free_frames -= 1;
            return Some(frame);
        }
        while self.current < self.range_count {
            let range = &mut self.ranges[self.current];
            if range.next < range.end {
                let frame = range.next;
                range.next += PAGE;
                self.free_frames -= 1;
                return Some(frame);
            }
            self.current += 1;
        }
        None
    }

    /// Returns a frame previously obtained from [`allocate`](Self::allocate).
    pub fn free(&mut self, frame: u64, links: &mut impl FrameLinks) {
        debug_assert!(frame.is_multiple_of(PAGE) && frame != NONE);
        links.set_next(frame, self.free_list);
        self.free_list = frame;
        self.free_frames += 1;
    }

    /// Keeps the first `keep` never-used frames for the kernel and hands the rest of the
    /// usable memory out as page-aligned `(start, end)` ranges (at most `out.len()`; the
    /// count is returned). Only valid before the first allocation.
    pub fn split_off_beyond(&mut self, keep: u64, out: &mut [(u64, u64)]) -> usize {
        debug_assert!(self.free_frames == self.total_frames && self.current == 0);
        let (mut kept, mut n) = (0, 0);
        for range in &mut self.ranges[..self.range_count] {
            let frames = (range.end - range.next) / PAGE;
            let take = frames.min(keep - kept);
            kept += take;
            let split = range.next + take * PAGE;
            if split < range.end && n < out.len() {
                out[n] = (split, range.end);
                n += 1;
            }
            range.end = split;
        }
        self.total_frames = kept;
        self.free_frames = kept;
        n
    }

    pub fn free_frames(&self) -> u64 {
        self.free_frames
    }

    pub fn total_frames(&self) -> u64 {
        self.total_frames
    }

    pub fn ignored_ranges(&self) -> usize {
        self.ignored_ranges
    }
}

#[cfg(test)]
#[path = "../../host-tests/frames.rs"]
mod tests;
