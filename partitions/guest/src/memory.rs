//! A Linux process's address space as the guest keeps it: the list of its mapped areas
//! (Linux's VMAs) with their rights, kept sorted and disjoint. This is bookkeeping only;
//! which guest frame backs which page, and the `map` calls that make the pages real, are
//! the partition program's ([`crate::syscall::Host`]).
//!
//! The layout of a process (x86-64 Linux's, so programs find what they expect):
//!
//! | what | where |
//! |---|---|
//! | the executable's segments, then the heap (`brk`) | link addresses (static PIE: [`crate::elf::PIE_BASE`]) |
//! | anonymous `mmap`s | top-down below [`MMAP_TOP`] |
//! | the stack, [`STACK_SIZE`] bytes | below [`STACK_TOP`] |
//!
//! Pages are backed when first touched ([`crate::frames`]): a CPU exception of a process
//! is judged by [`classify_fault`], a pure function of the areas and what the kernel
//! reported, which says either which page to fault in with which rights, or which signal
//! (and `si_code`) the process gets.

use crate::signal::{
    self, BUS_ADRALN, FPE_INTDIV, ILL_ILLOPN, SEGV_ACCERR, SEGV_MAPERR, SI_KERNEL, TRAP_BRKPT,
};

/// Page size.
pub const PAGE: u64 = 4096;
/// End of the user half of the address space (exclusive, page-aligned).
pub const USER_TOP: u64 = 0x0000_7fff_ffff_f000;
/// Top of the initial stack (exclusive).
pub const STACK_TOP: u64 = 0x0000_7fff_fff0_0000;
/// Size of the stack (mapped in full when the process starts).
pub const STACK_SIZE: u64 = 256 * 1024;
/// Anonymous mappings are placed below this address, highest first; one unmapped page
/// separates it from the stack's lowest possible growth.
pub const MMAP_TOP: u64 = STACK_TOP - 64 * 1024 * 1024;
/// Most areas a process may have.
pub const MAX_AREAS: usize = 64;

pub const fn page_down(a: u64) -> u64 {
    a & !(PAGE - 1)
}

/// `a` rounded up to a page (saturating at the last page of the address range).
pub const fn page_up(a: u64) -> u64 {
    match a.checked_add(PAGE - 1) {
        Some(x) => x & !(PAGE - 1),
        None => !(PAGE - 1),
    }
}

/// Access rights of an area (Linux's `PROT_*` bits, same values).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Rights(u8);

impl Rights {
    pub const NONE: Self = Self(0);
    pub const READ: Self = Self(1);
    pub const WRITE: Self = Self(2);
    pub const EXECUTE: Self = Self(4);

    pub const fn all() -> Self {
        Self(7)
    }
    /// From `PROT_*` bits (`None` if others are set).
    pub const fn from_prot(prot: u64) -> Option<Self> {
        if prot & !7 != 0 {
            None
        } else {
            Some(Self(prot as u8))
        }
    }
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }
    /// These rights and `other`'s.
    pub const fn with(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }
    /// These rights without `other`'s.
    pub const fn without(self, other: Self) -> Self {
        Self(self.0 & !other.0)
    }
    pub const fn bits(self) -> u8 {
        self.0
    }
    /// Writable and executable at once: the guest never maps such a page (W^X), so
    /// `mmap` and `mprotect` asking for it fail with `EACCES`.
    pub const fn writable_and_executable(self) -> bool {
        self.contains(Self::WRITE) && self.contains(Self::EXECUTE)
    }
    /// Whether pages with these rights can be mapped (every mapped page is readable on
    /// x86-64; `PROT_NONE` areas stay unmapped).
    pub const fn accessible(self) -> bool {
        self.0 != 0
    }
}

impl core::ops::BitOr for Rights {
    type Output = Self;
    fn bitor(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }
}

impl core::ops::BitOrAssign for Rights {
    fn bitor_assign(&mut self, other: Self) {
        self.0 |= other.0;
    }
}

/// What an area holds (for diagnostics and `brk`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Kind {
    #[default]
    Image,
    Heap,
    Stack,
    Anonymous,
    /// A mapping of a file (its pages filled from the file when it was mapped).
    File,
}

/// A mapped area: pages `start..end`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Area {
    pub start: u64,
    pub end: u64,
    pub rights: Rights,
    pub kind: Kind,
}

/// Why an area cannot be added.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AreaError {
    /// Unaligned, empty or outside user space.
    Invalid,
    /// It overlaps an existing area.
    Overlaps,
    /// [`MAX_AREAS`] reached.
    TooMany,
}

/// The ranges of a process locked in memory (`mlock`, `mlockall`): sorted, disjoint and
/// never adjacent (a lock next to another joins it). The guest never pages memory out, so
/// a lock only counts against `RLIMIT_MEMLOCK`. As many ranges as areas: `mlockall` of
/// every area always fits.
#[derive(Clone, Copy, Debug)]
pub struct Locks {
    ranges: [(u64, u64); MAX_AREAS],
    count: usize,
}

impl Default for Locks {
    fn default() -> Self {
        Self {
            ranges: [(0, 0); MAX_AREAS],
            count: 0,
        }
    }
}

/// More separate locked ranges than [`Locks`] holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TooManyLocks;

impl Locks {
    /// The locked bytes.
    pub fn bytes(&self) -> u64 {
        self.iter().map(|(s, e)| e - s).sum()
    }

    fn iter(&self) -> impl Iterator<Item = (u64, u64)> + '_ {
        self.ranges[..self.count].iter().copied()
    }

    /// The bytes of `start..end` not locked yet.
    pub fn unlocked_in(&self, start: u64, end: u64) -> u64 {
        let locked: u64 = self
            .iter()
            .map(|(s, e)| e.min(end).saturating_sub(s.max(start)))
            .sum();
        (end - start) - locked
    }

    /// Locks `start..end` (`start < end`).
    pub fn lock(&mut self, start: u64, end: u64) -> Result<(), TooManyLocks> {
        let (mut s, mut e) = (start, end);
        let mut kept = [(0, 0); MAX_AREAS + 1];
        let mut n = 0;
        for (rs, re) in self.iter() {
            if re < s || rs > e {
                kept[n] = (rs, re);
                n += 1;
            } else {
                (s, e) = (s.min(rs), e.max(re));
            }
        }
        kept[n] = (s, e);
        self.replace(&mut kept[..n + 1])
    }

    /// Unlocks `start..end` (`start < end`): a range around it is cut in two.
    pub fn unlock(&mut self, start: u64, end: u64) -> Result<(), TooManyLocks> {
        let mut kept = [(0, 0); MAX_AREAS + 2];
        let mut n = 0;
        for (rs, re) in self.iter() {
            for (ps, pe) in [(rs, re.min(start)), (rs.max(end), re)] {
                if ps < pe {
                    kept[n] = (ps, pe);
                    n += 1;
                }
            }
        }
        self.replace(&mut kept[..n])
    }

    fn replace(&mut self, ranges: &mut [(u64, u64)]) -> Result<(), TooManyLocks> {
        if ranges.len() > MAX_AREAS {
            return Err(TooManyLocks);
        }
        ranges.sort_unstable();
        self.ranges[..ranges.len()].copy_from_slice(ranges);
        self.count = ranges.len();
        Ok(())
    }
}

/// The areas of one process, sorted by address, disjoint.
#[derive(Clone, Debug)]
pub struct Areas {
    areas: [Area; MAX_AREAS],
    count: usize,
}

impl Default for Areas {
    fn default() -> Self {
        Self::new()
    }
}

impl Areas {
    pub const fn new() -> Self {
        Self {
            areas: [Area {
                start: 0,
                end: 0,
                rights: Rights::NONE,
                kind: Kind::Image,
            }; MAX_AREAS],
            count: 0,
        }
    }

    pub fn iter(&self) -> impl Iterator<Item = &Area> {
        self.areas[..self.count].iter()
    }

    /// The area holding `address`.
    pub fn find(&self, address: u64) -> Option<&Area> {
        self.iter().find(|a| a.start <= address && address < a.end)
    }

    /// Whether any area overlaps `start..end`.
    pub fn overlaps(&self, start: u64, end: u64) -> bool {
        self.iter().any(|a| a.start < end && start < a.end)
    }

    fn valid(start: u64, end: u64) -> bool {
        start.is_multiple_of(PAGE)
            && end.is_multiple_of(PAGE)
            && start < end
            && end <= USER_TOP
            && start > 0
    }

    /// Adds the area `start..end` (page-aligned, free).
    pub fn insert(&mut self, area: Area) -> Result<(), AreaError> {
        if !Self::valid(area.start, area.end) {
            return Err(AreaError::Invalid);
        }
        if self.overlaps(area.start, area.end) {
            return Err(AreaError::Overlaps);
        }
        if self.count == MAX_AREAS {
            return Err(AreaError::TooMany);
        }
        let at = self
            .iter()
            .position(|a| a.start > area.start)
            .unwrap_or(self.count);
        self.areas.copy_within(at..self.count, at + 1);
        self.areas[at] = area;
        self.count += 1;
        Ok(())
    }

    /// Splits areas so that `start` and `end` are area boundaries (fails only if that needs
    /// more than [`MAX_AREAS`] areas; then nothing changed).
    fn split_at(&mut self, start: u64, end: u64) -> Result<(), AreaError> {
        let splits = [start, end]
            .iter()
            .filter(|&&x| self.iter().any(|a| a.start < x && x < a.end))
            .count();
        if self.count + splits > MAX_AREAS {
            return Err(AreaError::TooMany);
        }
        for x in [start, end] {
            let inside = self.iter().position(|a| a.start < x && x < a.end);
            if let Some(i) = inside {
                let mut upper = self.areas[i];
                upper.start = x;
                self.areas[i].end = x;
                self.areas.copy_within(i + 1..self.count, i + 2);
                self.areas[i + 1] = upper;
                self.count += 1;
            }
        }
        Ok(())
    }

    /// Removes every page of `start..end` from the areas (splitting them as needed) and
    /// returns the removed parts through `removed` (as Linux's `munmap`).
    pub fn remove(
        &mut self,
        start: u64,
        end: u64,
        mut removed: impl FnMut(Area),
    ) -> Result<(), AreaError> {
        if !Self::valid(start, end) {
            return Err(AreaError::Invalid);
        }
        self.split_at(start, end)?;
        let mut i = 0;
        while i < self.count {
            let a = self.areas[i];
            if start <= a.start && a.end <= end {
                removed(a);
                self.areas.copy_within(i + 1..self.count, i);
                self.count -= 1;
            } else {
                i += 1;
            }
        }
        Ok(())
    }

    /// Sets the rights of every page of `start..end`, which must all be mapped (Linux's
    /// `mprotect`); `changed` sees each affected part with its old rights.
    pub fn protect(
        &mut self,
        start: u64,
        end: u64,
        rights: Rights,
        mut changed: impl FnMut(Area),
    ) -> Result<(), AreaError> {
        if !Self::valid(start, end) {
            return Err(AreaError::Invalid);
        }
        if !self.covers(start, end) {
            return Err(AreaError::Invalid);
        }
        self.split_at(start, end)?;
        for a in &mut self.areas[..self.count] {
            if start <= a.start && a.end <= end {
                changed(*a);
                a.rights = rights;
            }
        }
        Ok(())
    }

    /// Whether every page of `start..end` is in some area.
    pub fn covers(&self, start: u64, end: u64) -> bool {
        let mut at = start;
        for a in self.iter() {
            if a.start <= at && at < a.end {
                at = a.end;
            }
        }
        at >= end
    }

    /// Moves the end of the area ending at `old_end` to `new_end` (the heap's `brk`).
    pub fn resize(&mut self, old_end: u64, new_end: u64) -> Result<(), AreaError> {
        let i = self
            .iter()
            .position(|a| a.end == old_end)
            .ok_or(AreaError::Invalid)?;
        let a = self.areas[i];
        if new_end <= a.start || !new_end.is_multiple_of(PAGE) || new_end > USER_TOP {
            return Err(AreaError::Invalid);
        }
        if new_end > old_end && self.overlaps(old_end, new_end) {
            return Err(AreaError::Overlaps);
        }
        self.areas[i].end = new_end;
        Ok(())
    }

    /// The highest free range of `len` bytes (page multiple) that ends at or below `top`
    /// and starts at or above `bottom`.
    pub fn free_below(&self, top: u64, bottom: u64, len: u64) -> Option<u64> {
        let mut end = top;
        loop {
            let start = end.checked_sub(len)?;
            if start < bottom {
                return None;
            }
            // The highest area overlapping the candidate forces it below that area.
            match self
                .iter()
                .filter(|a| a.start < end && start < a.end)
                .map(|a| a.start)
                .min()
            {
                None => return Some(start),
                Some(blocker) => end = blocker,
            }
        }
    }
}

/// Bits of the page-fault error code (as the CPU pushes it; the kernel passes it on in
/// the exception message).
pub const PF_PRESENT: u64 = 1;
pub const PF_WRITE: u64 = 2;
pub const PF_USER: u64 = 4;
pub const PF_RESERVED: u64 = 8;
pub const PF_FETCH: u64 = 16;
/// The page-fault vector.
pub const VECTOR_PAGE_FAULT: u64 = 14;

/// What a CPU exception of a process comes to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// A page fault the process's areas allow: back (or copy) `page` and map it with
    /// `rights`, then resume the process at the same instruction.
    Resolve {
        page: u64,
        rights: Rights,
        write: bool,
    },
    /// The process gets `signal` with `si_code` `code` (the fault address is what the
    /// kernel reported).
    Signal { signal: u32, code: i32 },
}

/// The decision for CPU exception `vector` (with `error_code` and, for a page fault,
/// `address`) of a process with `areas`: Linux's mapping of exceptions to signals, and
/// for a page fault, whether the access is one the areas allow (then the page is backed on
/// demand, or a shared page copied). An access outside every area (kernel addresses, the
/// guard page below the stack, a stray pointer) is `SIGSEGV`/`SEGV_MAPERR`; one the
/// area's rights forbid (a write to a read-only page, a fetch from a non-executable one,
/// any access to `PROT_NONE`) `SIGSEGV`/`SEGV_ACCERR`.
pub fn classify_fault(areas: &Areas, vector: u64, error_code: u64, address: u64) -> Fault {
    let raise = |signal, code| Fault::Signal { signal, code };
    match vector {
        0 => raise(signal::SIGFPE, FPE_INTDIV),
        16 | 19 => raise(signal::SIGFPE, 0),
        1 | 3 => raise(signal::SIGTRAP, TRAP_BRKPT),
        6 => raise(signal::SIGILL, ILL_ILLOPN),
        17 => raise(signal::SIGBUS, BUS_ADRALN),
        VECTOR_PAGE_FAULT => {
            let Some(area) = areas.find(address).filter(|_| address < USER_TOP) else {
                return raise(signal::SIGSEGV, SEGV_MAPERR);
            };
            let write = error_code & PF_WRITE != 0;
            let fetch = error_code & PF_FETCH != 0;
            let allowed = area.rights.accessible()
                && error_code & PF_RESERVED == 0
                && (!write || area.rights.contains(Rights::WRITE))
                && (!fetch || area.rights.contains(Rights::EXECUTE));
            if allowed {
                Fault::Resolve {
                    page: page_down(address),
                    rights: area.rights,
                    write,
                }
            } else {
                raise(signal::SIGSEGV, SEGV_ACCERR)
            }
        }
        // A general-protection fault (a privileged instruction, an I/O port the process
        // has no access to, a non-canonical address) and the rest.
        _ => raise(signal::SIGSEGV, SI_KERNEL),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_resolve_inside_areas_with_their_rights_only() {
        let mut a = Areas::new();
        let rw = Rights::READ | Rights::WRITE;
        let rx = Rights::READ | Rights::EXECUTE;
        a.insert(area(0x40_0000, 0x40_2000, rx)).unwrap();
        a.insert(area(0x60_0000, 0x60_1000, Rights::READ)).unwrap();
        a.insert(area(0x70_0000, 0x70_1000, Rights::NONE)).unwrap();
        a.insert(Area {
            kind: Kind::Stack,
            ..area(STACK_TOP - STACK_SIZE, STACK_TOP, rw)
        })
        .unwrap();
        let pf = |error, address| classify_fault(&a, VECTOR_PAGE_FAULT, error, address);
        let user = PF_USER;
        let segv = |code| Fault::Signal {
            signal: signal::SIGSEGV,
            code,
        };
        // Demand paging: the stack's pages, the image's code.
        assert_eq!(
            pf(user | PF_WRITE, STACK_TOP - 8),
            Fault::Resolve {
                page: STACK_TOP - PAGE,
                rights: rw,
                write: true
            }
        );
        assert_eq!(
            pf(user | PF_FETCH, 0x40_1234),
            Fault::Resolve {
                page: 0x40_1000,
                rights: rx,
                write: false
            }
        );
        // Copy-on-write: a write to a present page of a writable area.
        assert!(matches!(
            pf(user | PF_PRESENT | PF_WRITE, STACK_TOP - 8),
            Fault::Resolve { write: true, .. }
        ));
        // Outside every area: the guard page below the stack, null, kernel addresses.
        assert_eq!(
            pf(user | PF_WRITE, STACK_TOP - STACK_SIZE - 8),
            segv(SEGV_MAPERR)
        );
        assert_eq!(pf(user, 0), segv(SEGV_MAPERR));
        assert_eq!(
            pf(user | PF_PRESENT, 0xffff_8000_0000_0000),
            segv(SEGV_MAPERR)
        );
        assert_eq!(pf(user, USER_TOP), segv(SEGV_MAPERR));
        // Rights: writes to read-only pages, fetches from data, PROT_NONE.
        assert_eq!(
            pf(user | PF_PRESENT | PF_WRITE, 0x40_0000),
            segv(SEGV_ACCERR)
        );
        assert_eq!(pf(user | PF_WRITE, 0x60_0000), segv(SEGV_ACCERR));
        assert_eq!(pf(user | PF_FETCH, 0x60_0000), segv(SEGV_ACCERR));
        assert_eq!(pf(user, 0x70_0000), segv(SEGV_ACCERR));
        assert_eq!(pf(user | PF_RESERVED, 0x60_0000), segv(SEGV_ACCERR));
        // Other exceptions: Linux's signals.
        let signal_of = |vector| match classify_fault(&a, vector, 0, 0) {
            Fault::Signal { signal, .. } => signal,
            Fault::Resolve { .. } => 0,
        };
        assert_eq!(signal_of(0), signal::SIGFPE);
        assert_eq!(signal_of(6), signal::SIGILL);
        assert_eq!(signal_of(13), signal::SIGSEGV);
        assert_eq!(signal_of(3), signal::SIGTRAP);
        assert_eq!(signal_of(17), signal::SIGBUS);
    }

    fn area(start: u64, end: u64, rights: Rights) -> Area {
        Area {
            start,
            end,
            rights,
            kind: Kind::Anonymous,
        }
    }

    fn ranges(a: &Areas) -> Vec<(u64, u64, u8)> {
        a.iter()
            .map(|a| (a.start, a.end, a.rights.bits()))
            .collect()
    }

    #[test]
    fn inserts_sorted_and_refuses_overlaps() {
        let mut a = Areas::new();
        a.insert(area(0x5000, 0x6000, Rights::READ)).unwrap();
        a.insert(area(0x1000, 0x2000, Rights::READ)).unwrap();
        assert_eq!(
            a.insert(area(0x1000, 0x3000, Rights::READ)),
            Err(AreaError::Overlaps)
        );
        assert_eq!(
            a.insert(area(0x1001, 0x3000, Rights::READ)),
            Err(AreaError::Invalid)
        );
        assert_eq!(
            a.insert(area(0x3000, 0x3000, Rights::READ)),
            Err(AreaError::Invalid)
        );
        assert_eq!(
            a.insert(area(0, 0x1000, Rights::READ)),
            Err(AreaError::Invalid)
        );
        assert_eq!(ranges(&a), [(0x1000, 0x2000, 1), (0x5000, 0x6000, 1)]);
        assert_eq!(a.find(0x5fff).unwrap().start, 0x5000);
        assert!(a.find(0x2000).is_none());
    }

    #[test]
    fn remove_splits_areas() {
        let mut a = Areas::new();
        a.insert(area(0x1000, 0x9000, Rights::READ | Rights::WRITE))
            .unwrap();
        let mut gone = Vec::new();
        a.remove(0x3000, 0x5000, |r| gone.push((r.start, r.end)))
            .unwrap();
        assert_eq!(gone, [(0x3000, 0x5000)]);
        assert_eq!(ranges(&a), [(0x1000, 0x3000, 3), (0x5000, 0x9000, 3)]);
        // Removing a range that is partly unmapped is fine (as munmap).
        gone.clear();
        a.remove(0x2000, 0x6000, |r| gone.push((r.start, r.end)))
            .unwrap();
        assert_eq!(gone, [(0x2000, 0x3000), (0x5000, 0x6000)]);
        assert_eq!(ranges(&a), [(0x1000, 0x2000, 3), (0x6000, 0x9000, 3)]);
    }

    #[test]
    fn protect_needs_every_page_mapped() {
        let mut a = Areas::new();
        a.insert(area(0x1000, 0x4000, Rights::READ | Rights::WRITE))
            .unwrap();
        a.insert(area(0x4000, 0x5000, Rights::READ)).unwrap();
        let mut seen = Vec::new();
        a.protect(0x2000, 0x5000, Rights::READ, |r| {
            seen.push((r.start, r.rights.bits()))
        })
        .unwrap();
        assert_eq!(seen, [(0x2000, 3), (0x4000, 1)]);
        assert_eq!(
            ranges(&a),
            [
                (0x1000, 0x2000, 3),
                (0x2000, 0x4000, 1),
                (0x4000, 0x5000, 1)
            ]
        );
        assert_eq!(
            a.protect(0x4000, 0x6000, Rights::READ, |_| ()),
            Err(AreaError::Invalid)
        );
    }

    #[test]
    fn the_table_never_overflows() {
        let mut a = Areas::new();
        for i in 0..MAX_AREAS as u64 {
            a.insert(area(
                0x10_0000 + i * 0x2000,
                0x10_1000 + i * 0x2000,
                Rights::READ,
            ))
            .unwrap();
        }
        assert_eq!(
            a.insert(area(0x1000, 0x2000, Rights::READ)),
            Err(AreaError::TooMany)
        );
        // A split that needs a new slot is refused and changes nothing.
        let mut b = Areas::new();
        b.insert(area(0x1000, 0x1000 + 4 * PAGE, Rights::READ))
            .unwrap();
        for i in 1..MAX_AREAS as u64 {
            b.insert(area(
                0x100_0000 + i * 0x2000,
                0x100_1000 + i * 0x2000,
                Rights::READ,
            ))
            .unwrap();
        }
        let before = ranges(&b);
        assert_eq!(b.remove(0x2000, 0x3000, |_| ()), Err(AreaError::TooMany));
        assert_eq!(
            b.protect(0x2000, 0x3000, Rights::NONE, |_| ()),
            Err(AreaError::TooMany)
        );
        assert_eq!(ranges(&b), before);
    }

    #[test]
    fn resize_moves_the_heap_end() {
        let mut a = Areas::new();
        a.insert(area(0x10000, 0x11000, Rights::READ)).unwrap();
        a.insert(area(0x20000, 0x30000, Rights::READ)).unwrap();
        a.resize(0x11000, 0x15000).unwrap();
        assert_eq!(a.resize(0x15000, 0x21000), Err(AreaError::Overlaps));
        assert_eq!(a.resize(0x15000, 0x10000), Err(AreaError::Invalid));
        a.resize(0x15000, 0x12000).unwrap();
        assert_eq!(ranges(&a)[0], (0x10000, 0x12000, 1));
    }

    #[test]
    fn free_below_finds_the_highest_hole() {
        let mut a = Areas::new();
        a.insert(area(0x8000, 0xa000, Rights::READ)).unwrap();
        a.insert(area(0x5000, 0x7000, Rights::READ)).unwrap();
        assert_eq!(a.free_below(0x10000, 0x1000, 0x2000), Some(0xe000));
        assert_eq!(a.free_below(0xa000, 0x1000, 0x1000), Some(0x7000));
        assert_eq!(a.free_below(0xa000, 0x1000, 0x2000), Some(0x3000));
        assert_eq!(a.free_below(0xa000, 0x4000, 0x2000), None);
        assert_eq!(a.free_below(0x1000, 0, 0x2000), None);
    }
}
