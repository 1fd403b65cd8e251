//! The guest's frames behind its processes' pages: which pool page ([`crate::pool`]) backs
//! which process page ([`crate::backing`]), and the kernel mappings that make them real
//! (through [`Mapper`], which the partition program implements with `map`, `unmap` and
//! `protect` and the tests with a model).
//!
//! - **Demand paging.** A page is backed when it is first touched: the page fault (or the
//!   guest writing into it for a system call) gives it a zeroed frame, or one filled by
//!   the caller ([`Frames::fill_in`], a file mapping's page). Only a program's image is
//!   backed and mapped at once ([`Frames::back_image`]).
//! - **Copy-on-write.** `fork` ([`Frames::share`]) gives the child the parent's frames, one
//!   more reference each, mapped read-only in both; the first write of either faults and
//!   gets a copy of its own ([`Frames::fault_in`]), or the frame itself made writable
//!   when the other side already let go of it. The guest's own writes into a process
//!   ([`Frames::write`]) copy a shared frame first, so no write ever reaches a frame that
//!   another process still sees.
//! - **Writes a fork foresees.** A process's children of one program write the same pages
//!   first (a forking server's children: their stack, libc's data); each such write is a
//!   fault, a round trip to the guest. The pages a process and its children copied on
//!   write ([`ForkWrites`], kept by the caller) are copied at its next fork instead
//!   ([`Frames::share`]): the child gets them writable, and the parent keeps its frame
//!   writable when no one else shares it.
//! - **Image cache.** The pages of a program's image ([`Frames::back_image`]) are kept
//!   after their first load, keyed by the image and address, and every process that runs
//!   the program shares them copy-on-write: a later `execve` of it copies nothing. Pages
//!   only the cache holds are given back when the pool runs out.
//!
//! It never decides whether an access is allowed: the caller checked the process's areas
//! ([`crate::memory`]) and passes the rights the page gets.

use crate::backing::Backing;
use crate::linux::Errno;
use crate::memory::{PAGE, Rights};
use crate::pool::PagePool;

/// The kernel calls on a process's address space.
pub trait Mapper {
    /// Maps frames `frame..frame + pages` at `start` in process `pid`: executable (and
    /// read-only) when `rights` has EXECUTE, else writable when it has WRITE, else read-only.
    fn map(
        &mut self,
        pid: u32,
        frame: usize,
        start: u64,
        pages: u64,
        rights: Rights,
    ) -> Result<(), Errno>;
    /// Unmaps the pages `start..start + pages` of process `pid` (unmapped ones are skipped).
    fn unmap(&mut self, pid: u32, start: u64, pages: u64);
    /// Makes the pages `start..start + pages` of process `pid` read-only, or unmaps them
    /// (a page mapped read-only, or not at all, faults on the next write either way).
    fn write_protect(&mut self, pid: u32, start: u64, pages: u64);
}

/// The backing table's key of page `page` of process `pid` (user addresses are below
/// 2^47: the pid takes the 16 bits above; pids stay below [`crate::system::PID_MAX`]).
const fn key(pid: u32, page: u64) -> u64 {
    ((pid & 0xffff) as u64) << 48 | page
}

/// Above every user address, below the next pid's keys.
const ADDRESS_END: u64 = 1 << 47;

/// The pid the image cache's pages are kept under: none of a process (init is 1), and
/// first in the table, so inserting a process's pages never moves the cache's entries.
const CACHE: u32 = 0;
/// Image ids the cache takes (below this).
pub const MAX_IMAGE_ID: u32 = 1 << 13;

/// The backing table's key of the cached page at `page` of image `image`.
const fn cache_key(image: u32, page: u64) -> u64 {
    key(CACHE, (image as u64) << 35 | page >> 12)
}

const SIZE: usize = PAGE as usize;

/// The frames, their pool and their backing table.
pub struct Frames<'p> {
    /// Frame `i` is `memory[i * PAGE..(i + 1) * PAGE]`.
    memory: &'p mut [u8],
    pool: PagePool,
    backing: Backing<'p>,
}

impl<'p> Frames<'p> {
    /// The frames in `memory` (whole pages), with their backing table in `table`.
    pub fn new(memory: &'p mut [u8], table: &'p mut [u8]) -> Self {
        let pages = memory.len() / SIZE;
        Self {
            memory,
            pool: PagePool::new(pages),
            backing: Backing::new(table),
        }
    }

    pub fn free_frames(&self) -> usize {
        self.pool.free_pages()
    }

    /// How many frames there are.
    pub fn total_frames(&self) -> usize {
        self.memory.len() / SIZE
    }

    /// The frame backing `page` of process `pid` and its references.
    pub fn frame_of(&self, pid: u32, page: u64) -> Option<(usize, u8)> {
        let frame = self.backing.get(key(pid, page))?;
        Some((frame, self.pool.references(frame)))
    }

    /// A run of `count` free frames (one reference each); when the pool has none, the
    /// image cache first gives back the pages no process uses.
    fn alloc(&mut self, count: usize) -> Option<usize> {
        self.pool.alloc(count).or_else(|| {
            self.evict_cache();
            self.pool.alloc(count)
        })
    }

    /// Frees the image cache's pages that no process shares.
    fn evict_cache(&mut self) {
        let mut at = key(CACHE, 0);
        while let Some((k, frame)) = self.backing.first_from(at)
            && k < key(CACHE + 1, 0)
        {
            if self.pool.references(frame) == 1 {
                self.backing.remove(k);
                self.pool.free(frame);
                at = k;
            } else {
                at = k + 1;
            }
        }
    }

    fn frame(&mut self, frame: usize) -> &mut [u8] {
        &mut self.memory[frame * SIZE..(frame + 1) * SIZE]
    }

    /// A zeroed frame that backs `page` of `pid` (unmapped).
    fn back_page(&mut self, pid: u32, page: u64) -> Result<usize, Errno> {
        let frame = self.alloc(1).ok_or(Errno::ENOMEM)?;
        self.frame(frame).fill(0);
        if self.backing.insert(key(pid, page), frame).is_err() {
            self.pool.free(frame);
            return Err(Errno::ENOMEM);
        }
        Ok(frame)
    }

    /// A frame of its own for `page` of `pid`, a copy of the shared `frame` (whose
    /// reference it drops).
    fn copy_page(&mut self, pid: u32, page: u64, frame: usize) -> Result<usize, Errno> {
        let copy = self.alloc(1).ok_or(Errno::ENOMEM)?;
        self.memory
            .copy_within(frame * SIZE..(frame + 1) * SIZE, copy * SIZE);
        // Replacing the entry cannot fail: it exists.
        let _ = self.backing.insert(key(pid, page), copy);
        self.pool.free(frame);
        Ok(copy)
    }

    /// Backs `pages` pages at `start` of `pid` with frames `fill(address, frame)` writes in
    /// full (their old contents are undefined) and maps them with `rights` (one contiguous
    /// run of frames if the pool has one, else page by page). On an error the pages backed
    /// so far stay: the caller releases them ([`Frames::release`]).
    pub fn back(
        &mut self,
        m: &mut impl Mapper,
        pid: u32,
        start: u64,
        pages: u64,
        rights: Rights,
        mut fill: impl FnMut(u64, &mut [u8]),
    ) -> Result<(), Errno> {
        if let Some(run) = self.alloc(pages as usize) {
            for i in 0..pages {
                let frame = run + i as usize;
                let page = start + i * PAGE;
                fill(page, self.frame(frame));
                if self.backing.insert(key(pid, page), frame).is_err() {
                    for j in i..pages {
                        self.pool.free(run + j as usize);
                    }
                    return Err(Errno::ENOMEM);
                }
            }
            return m.map(pid, run, start, pages, rights);
        }
        for i in 0..pages {
            let page = start + i * PAGE;
            let frame = self.back_page(pid, page)?;
            fill(page, self.frame(frame));
            m.map(pid, frame, page, 1, rights)?;
        }
        Ok(())
    }

    /// [`Frames::back`] for the pages of a program's image `image` (an id below
    /// [`MAX_IMAGE_ID`] that names what `fill` writes: the same id and address always give
    /// the same bytes): the pages come from the image cache, filled on their first use,
    /// and are shared with it copy-on-write (mapped without WRITE; a write copies). Other
    /// ids are not cached.
    #[allow(clippy::too_many_arguments)] // `back`'s, and the image
    pub fn back_image(
        &mut self,
        m: &mut impl Mapper,
        pid: u32,
        start: u64,
        pages: u64,
        rights: Rights,
        image: u32,
        mut fill: impl FnMut(u64, &mut [u8]),
    ) -> Result<(), Errno> {
        if image >= MAX_IMAGE_ID {
            return self.back(m, pid, start, pages, rights, fill);
        }
        let rights = rights.without(Rights::WRITE);
        let cached = |f: &Self, i: u64| f.backing.get(cache_key(image, start + i * PAGE));
        // The run being collected for one `map`: first page, first frame, pages.
        let mut run: Option<(u64, usize, u64)> = None;
        for i in 0..pages {
            let page = start + i * PAGE;
            let frame = match cached(self, i) {
                Some(frame) => frame,
                None => {
                    // Fill the missing pages from here on, as one run if the pool has one.
                    let missing = (i..pages)
                        .take_while(|&j| cached(self, j).is_none())
                        .count();
                    let (first, n) = match self.alloc(missing) {
                        Some(first) => (first, missing),
                        None => (self.alloc(1).ok_or(Errno::ENOMEM)?, 1),
                    };
                    for j in 0..n {
                        let at = page + j as u64 * PAGE;
                        fill(at, self.frame(first + j));
                        if self
                            .backing
                            .insert(cache_key(image, at), first + j)
                            .is_err()
                        {
                            for k in j..n {
                                self.pool.free(first + k);
                            }
                            return Err(Errno::ENOMEM);
                        }
                    }
                    first
                }
            };
            if !self.pool.share(frame) {
                return Err(Errno::EAGAIN);
            }
            if self.backing.insert(key(pid, page), frame).is_err() {
                self.pool.free(frame);
                return Err(Errno::ENOMEM);
            }
            run = match run {
                Some((s, f, n)) if f + n as usize == frame => Some((s, f, n + 1)),
                Some((s, f, n)) => {
                    m.map(pid, f, s, n, rights)?;
                    Some((page, frame, 1))
                }
                None => Some((page, frame, 1)),
            };
        }
        match run {
            Some((s, f, n)) => m.map(pid, f, s, n, rights),
            None => Ok(()),
        }
    }

    /// Makes `page` of `pid` accessible with `rights` after a page fault (`write`: the
    /// access was a write): backs it with a zeroed frame if nothing backs it yet, copies a
    /// frame it shares if it writes (or takes the frame over when the other references
    /// are gone), and maps it; a frame it still shares is mapped read-only. Returns the
    /// shared frame it copied, if it did (a write [`Frames::foreseers`] learn from).
    pub fn fault_in(
        &mut self,
        m: &mut impl Mapper,
        pid: u32,
        page: u64,
        rights: Rights,
        write: bool,
    ) -> Result<Option<usize>, Errno> {
        let frame = match self.backing.get(key(pid, page)) {
            Some(frame) => frame,
            None => self.back_page(pid, page)?,
        };
        self.map_backed(m, pid, page, frame, rights, write)
    }

    /// [`Frames::fault_in`] of a page `frame` backs.
    fn map_backed(
        &mut self,
        m: &mut impl Mapper,
        pid: u32,
        page: u64,
        frame: usize,
        rights: Rights,
        write: bool,
    ) -> Result<Option<usize>, Errno> {
        let mut copied = None;
        let frame = if write && self.pool.references(frame) > 1 {
            copied = Some(frame);
            self.copy_page(pid, page, frame)?
        } else {
            frame
        };
        let rights = if self.pool.references(frame) > 1 {
            rights.without(Rights::WRITE)
        } else {
            rights
        };
        // It may be mapped already (a read-only copy-on-write page that is written).
        m.unmap(pid, page, 1);
        m.map(pid, frame, page, 1, rights)?;
        Ok(copied)
    }

    /// Whose [`ForkWrites`] learn of `pid`'s copy of `page` from the shared frame `copied`
    /// ([`Frames::fault_in`]): its `parent`'s when the parent still has that frame (the
    /// parent's next child will write the page too), and its own when one of its forked
    /// `children` still has it (its own next child will). A frame of the image cache, or
    /// of a parent that executed since, teaches no one.
    pub fn foreseers(
        &self,
        pid: u32,
        page: u64,
        copied: usize,
        parent: Option<u32>,
        mut children: impl Iterator<Item = u32>,
    ) -> [Option<u32>; 2] {
        let has = |other: u32| self.backing.get(key(other, page)) == Some(copied);
        [parent.filter(|&p| has(p)), children.any(has).then_some(pid)]
    }

    /// Backs `page` of `pid` with a frame `fill` fills (zeroed before), unmapped, unless a
    /// frame backs it already.
    pub fn fill_in(
        &mut self,
        pid: u32,
        page: u64,
        fill: impl FnOnce(&mut [u8]),
    ) -> Result<(), Errno> {
        if self.backing.get(key(pid, page)).is_none() {
            let frame = self.back_page(pid, page)?;
            fill(self.frame(frame));
        }
        Ok(())
    }

    /// Copies the memory of `pid` at `address` into `buf`; pages not backed read as zeros.
    pub fn read(&self, pid: u32, address: u64, buf: &mut [u8]) {
        let mut done = 0;
        while done < buf.len() {
            let at = address + done as u64;
            let page = at & !(PAGE - 1);
            let offset = (at - page) as usize;
            let n = (SIZE - offset).min(buf.len() - done);
            match self.backing.get(key(pid, page)) {
                Some(frame) => buf[done..done + n].copy_from_slice(
                    &self.memory[frame * SIZE + offset..frame * SIZE + offset + n],
                ),
                None => buf[done..done + n].fill(0),
            }
            done += n;
        }
    }

    /// Copies `data` into the memory of `pid` at `address`: a page not backed yet gets a
    /// zeroed frame (mapped on its first fault), a shared one a copy of its own (its old
    /// mapping goes, the next access maps the copy).
    pub fn write(
        &mut self,
        m: &mut impl Mapper,
        pid: u32,
        address: u64,
        data: &[u8],
    ) -> Result<(), Errno> {
        let mut done = 0;
        while done < data.len() {
            let at = address + done as u64;
            let page = at & !(PAGE - 1);
            let offset = (at - page) as usize;
            let n = (SIZE - offset).min(data.len() - done);
            let frame = match self.backing.get(key(pid, page)) {
                None => self.back_page(pid, page)?,
                Some(frame) if self.pool.references(frame) > 1 => {
                    let copy = self.copy_page(pid, page, frame)?;
                    m.unmap(pid, page, 1);
                    copy
                }
                Some(frame) => frame,
            };
            self.frame(frame)[offset..offset + n].copy_from_slice(&data[done..done + n]);
            done += n;
        }
        Ok(())
    }

    /// The backed pages of `pid` in `start..end`, as runs of consecutive pages: calls
    /// `run(first page, pages)` for each (at most one call per backed page).
    fn backed_runs(&self, pid: u32, start: u64, end: u64, mut run: impl FnMut(u64, u64)) {
        let mut at = key(pid, start);
        let stop = key(pid, end);
        while let Some((k, _)) = self.backing.first_from(at)
            && k < stop
        {
            let mut pages = 1;
            while k + pages * PAGE < stop && self.backing.get(k + pages * PAGE).is_some() {
                pages += 1;
            }
            run(k - key(pid, 0), pages);
            at = k + pages * PAGE;
        }
    }

    /// Unmaps the pages of `pid` in `start..start + pages` and drops its references to
    /// their frames (`munmap`).
    pub fn release(&mut self, m: &mut impl Mapper, pid: u32, start: u64, pages: u64) {
        let end = start
            .saturating_add(pages.saturating_mul(PAGE))
            .min(ADDRESS_END);
        self.backed_runs(pid, start, end, |first, n| m.unmap(pid, first, n));
        let pool = &mut self.pool;
        self.backing
            .remove_range(key(pid, start), key(pid, end), |_, frame| {
                pool.free(frame);
            });
    }

    /// Unmaps the pages of `pid` in `start..start + pages` but keeps their contents: the
    /// next access faults them in again, with the rights the areas have then (`mprotect`).
    pub fn unmap(&mut self, m: &mut impl Mapper, pid: u32, start: u64, pages: u64) {
        let end = start
            .saturating_add(pages.saturating_mul(PAGE))
            .min(ADDRESS_END);
        self.backed_runs(pid, start, end, |first, n| m.unmap(pid, first, n));
    }

    /// Moves the backed pages of `pid` in `from..from + pages` to `to..` (a range nothing
    /// backs): their frames go along, the old mappings go (the next access maps the new
    /// addresses).
    pub fn move_pages(&mut self, m: &mut impl Mapper, pid: u32, from: u64, to: u64, pages: u64) {
        let end = from
            .saturating_add(pages.saturating_mul(PAGE))
            .min(ADDRESS_END);
        self.backed_runs(pid, from, end, |first, n| m.unmap(pid, first, n));
        let mut at = key(pid, from);
        while let Some((k, frame)) = self.backing.first_from(at)
            && k < key(pid, end)
        {
            self.backing.remove(k);
            let page = k - key(pid, from);
            // Cannot be full: an entry was just removed.
            let _ = self.backing.insert(key(pid, to + page), frame);
            at = k;
        }
    }

    /// Drops every reference of `pid` (its task and mappings are gone).
    pub fn release_all(&mut self, pid: u32) {
        let pool = &mut self.pool;
        self.backing
            .remove_range(key(pid, 0), key(pid + 1, 0), |_, frame| {
                pool.free(frame);
            });
    }

    /// `fork`: `child` (a new task, nothing mapped) gets every page `parent` has backed,
    /// sharing its frame; `rights(page)` says what the page's area allows (`None`: no
    /// area, or `PROT_NONE`: left unmapped). A writable page becomes read-only in both,
    /// but for the pages of `foreseen` ([`ForkWrites::pages`]): the child gets a copy of
    /// those, writable, and the parent its frame back writable unless someone else shares
    /// it (when the pool has no frame for a copy, the page stays shared). Returns how many
    /// pages are shared or copied; on an error the caller releases the child.
    pub fn share(
        &mut self,
        m: &mut impl Mapper,
        parent: u32,
        child: u32,
        rights: impl Fn(u64) -> Option<Rights>,
        foreseen: &[u64],
    ) -> Result<u64, Errno> {
        let (from, to) = (key(parent, 0), key(parent + 1, 0));
        // The child's entries in one move: the table's order is the parent's (the pid
        // changes, the pages keep their order).
        let shared = self
            .backing
            .copy_range(from, to, key(child, 0))
            .map_err(|_| Errno::ENOMEM)?;
        // The parent's entries moved if the child's went before them.
        let positions = self.backing.positions(from, to);
        for i in positions.clone() {
            if !self.pool.share(self.backing.at(i).1) {
                // Every frame takes one more reference, or none does.
                for j in positions.start..i {
                    self.pool.free(self.backing.at(j).1);
                }
                self.backing
                    .remove_range(key(child, 0), key(child + 1, 0), |_, _| {});
                return Err(Errno::EAGAIN);
            }
        }
        // Map each run: consecutive pages on consecutive frames with the same rights.
        let mut i = positions.start;
        while i < positions.end {
            let (k, first) = self.backing.at(i);
            let start = k - from;
            let area_rights = rights(start);
            let mut pages = 1;
            while i + (pages as usize) < positions.end
                && self.backing.at(i + pages as usize) == (k + pages * PAGE, first + pages as usize)
                && rights(start + pages * PAGE) == area_rights
            {
                pages += 1;
            }
            if let Some(r) = area_rights.filter(|r| r.accessible()) {
                if r.contains(Rights::WRITE) {
                    m.write_protect(parent, start, pages);
                }
                m.map(child, first, start, pages, r.without(Rights::WRITE))?;
            }
            i += pages as usize;
        }
        // The writes both would fault on at once, made now: no round trip for them.
        for &page in foreseen {
            let Some(r) = rights(page).filter(|r| r.accessible() && r.contains(Rights::WRITE))
            else {
                continue;
            };
            // Not backed: nothing to copy (the child's fault backs it).
            let Some(frame) = self.backing.get(key(child, page)) else {
                continue;
            };
            if self.map_backed(m, child, page, frame, r, true).is_err() {
                continue;
            }
            // When its mapping fails the page is left unmapped: the parent's next access
            // faults and maps it again.
            if let Some((frame, 1)) = self.frame_of(parent, page) {
                let _ = self.map_backed(m, parent, page, frame, r, true);
            }
        }
        Ok(shared as u64)
    }
}

/// The pages a process and its children copied on write, the newest [`ForkWrites::MAX`],
/// oldest first (what its next fork copies at once: [`Frames::share`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ForkWrites {
    pages: [u64; ForkWrites::MAX],
    len: usize,
}

impl ForkWrites {
    /// Pages kept: a busybox httpd child writes 9 (its stack and libc's data), and each
    /// costs a copy at every fork.
    pub const MAX: usize = 16;

    /// A write of `page` (kept once; when full, the oldest gives way).
    pub fn record(&mut self, page: u64) {
        if self.pages().contains(&page) {
            return;
        }
        if self.len == Self::MAX {
            self.pages.copy_within(1.., 0);
            self.len -= 1;
        }
        self.pages[self.len] = page;
        self.len += 1;
    }

    /// The pages in `start..end` are gone (unmapped, or the program replaced).
    pub fn forget(&mut self, start: u64, end: u64) {
        let mut kept = 0;
        for i in 0..self.len {
            if !(start..end).contains(&self.pages[i]) {
                self.pages[kept] = self.pages[i];
                kept += 1;
            }
        }
        self.len = kept;
    }

    pub fn pages(&self) -> &[u64] {
        &self.pages[..self.len]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    /// The kernel's page tables: (pid, page) to (frame, rights).
    #[derive(Default)]
    struct Tables {
        mapped: BTreeMap<(u32, u64), (usize, Rights)>,
        calls: usize,
    }

    impl Mapper for Tables {
        fn map(
            &mut self,
            pid: u32,
            frame: usize,
            start: u64,
            pages: u64,
            rights: Rights,
        ) -> Result<(), Errno> {
            self.calls += 1;
            for i in 0..pages {
                let old = self
                    .mapped
                    .insert((pid, start + i * PAGE), (frame + i as usize, rights));
                assert!(old.is_none(), "mapped twice");
            }
            Ok(())
        }
        fn unmap(&mut self, pid: u32, start: u64, pages: u64) {
            self.calls += 1;
            for i in 0..pages {
                self.mapped.remove(&(pid, start + i * PAGE));
            }
        }
        fn write_protect(&mut self, pid: u32, start: u64, pages: u64) {
            self.calls += 1;
            for i in 0..pages {
                if let Some(e) = self.mapped.get_mut(&(pid, start + i * PAGE)) {
                    e.1 = Rights::READ;
                }
            }
        }
    }

    const RW: Rights = Rights::READ.with(Rights::WRITE);
    const RX: Rights = Rights::READ.with(Rights::EXECUTE);

    fn setup(frames: usize) -> (Vec<u8>, Vec<u8>) {
        (vec![0xee; frames * SIZE], vec![0; frames * 2 * 16])
    }

    fn byte(f: &Frames, pid: u32, at: u64) -> u8 {
        let mut b = [0];
        f.read(pid, at, &mut b);
        b[0]
    }

    #[test]
    fn pages_are_backed_zeroed_on_their_first_fault() {
        let (mut mem, mut table) = setup(4);
        let mut f = Frames::new(&mut mem, &mut table);
        let mut t = Tables::default();
        assert_eq!(byte(&f, 1, 0x1234), 0, "unbacked reads as zero");
        assert_eq!(f.free_frames(), 4);
        f.fault_in(&mut t, 1, 0x1000, RW, false).unwrap();
        let (frame, refs) = f.frame_of(1, 0x1000).unwrap();
        assert_eq!(refs, 1);
        assert_eq!(t.mapped[&(1, 0x1000)], (frame, RW));
        assert_eq!(byte(&f, 1, 0x1fff), 0, "the frame was zeroed");
        // Faulting it in again maps it again (no double mapping, no new frame).
        f.fault_in(&mut t, 1, 0x1000, RW, true).unwrap();
        assert_eq!(f.free_frames(), 3);
        // The guest writing into a page not backed yet backs it, unmapped.
        f.write(&mut t, 1, 0x2ffe, b"abcd").unwrap();
        assert_eq!(f.free_frames(), 1);
        assert!(!t.mapped.contains_key(&(1, 0x2000)));
        assert_eq!(byte(&f, 1, 0x3001), b'd');
        f.fault_in(&mut t, 1, 0x4000, RW, false).unwrap();
        assert_eq!(
            f.fault_in(&mut t, 1, 0x5000, RW, false),
            Err(Errno::ENOMEM),
            "the pool is out"
        );
        f.release(&mut t, 1, 0x1000, 3);
        assert_eq!(f.free_frames(), 3);
        assert!(!t.mapped.contains_key(&(1, 0x1000)));
        assert!(t.mapped.contains_key(&(1, 0x4000)));
        f.release_all(1);
        assert_eq!(f.free_frames(), 4);
    }

    #[test]
    fn fork_shares_frames_and_the_first_write_copies() {
        let (mut mem, mut table) = setup(16);
        let mut f = Frames::new(&mut mem, &mut table);
        let mut t = Tables::default();
        // Parent 1: a read-execute image (3 pages, one run), two written heap pages.
        f.back(&mut t, 1, 0x40_0000, 3, RX, |at, page| {
            page.fill((at >> 12) as u8)
        })
        .unwrap();
        assert_eq!(byte(&f, 1, 0x40_2fff), 0x02, "filled");
        f.fault_in(&mut t, 1, 0x80_0000, RW, true).unwrap();
        f.fault_in(&mut t, 1, 0x80_1000, RW, true).unwrap();
        f.write(&mut t, 1, 0x80_0000, b"parent").unwrap();
        let areas = |page: u64| match page {
            0x40_0000..0x40_3000 => Some(RX),
            _ => Some(RW),
        };
        t.calls = 0;
        assert_eq!(f.share(&mut t, 1, 2, areas, &[]), Ok(5));
        assert!(t.calls <= 4, "one map per run: {}", t.calls);
        assert_eq!(f.free_frames(), 11, "nothing copied");
        for pid in [1, 2] {
            assert_eq!(t.mapped[&(pid, 0x80_0000)].1, Rights::READ);
            assert_eq!(t.mapped[&(pid, 0x40_1000)].1, RX);
            assert_eq!(f.frame_of(pid, 0x80_0000).unwrap().1, 2);
        }
        // The child writes: it gets a copy, the parent keeps the original (still
        // read-only until it writes too: then it takes its frame over, no copy).
        f.fault_in(&mut t, 2, 0x80_0000, RW, true).unwrap();
        assert_eq!(f.free_frames(), 10);
        assert_eq!(t.mapped[&(2, 0x80_0000)].1, RW);
        f.write(&mut t, 2, 0x80_0000, b"child").unwrap();
        assert_eq!(byte(&f, 1, 0x80_0000), b'p');
        assert_eq!(byte(&f, 2, 0x80_0000), b'c');
        assert_eq!(byte(&f, 2, 0x80_0005), b't', "the copy kept the rest");
        f.fault_in(&mut t, 1, 0x80_0000, RW, true).unwrap();
        assert_eq!(f.free_frames(), 10);
        assert_eq!(t.mapped[&(1, 0x80_0000)].1, RW);
        // A read fault of a still shared page maps it read-only.
        t.unmap(1, 0x80_1000, 1);
        f.fault_in(&mut t, 1, 0x80_1000, RW, false).unwrap();
        assert_eq!(t.mapped[&(1, 0x80_1000)].1, Rights::READ);
        // The guest writing into a shared page (a `read` into it) copies it first and
        // drops the stale mapping.
        f.write(&mut t, 1, 0x80_1000, b"x").unwrap();
        assert!(!t.mapped.contains_key(&(1, 0x80_1000)));
        assert_eq!(byte(&f, 2, 0x80_1000), 0);
        assert_eq!(f.free_frames(), 9);
        // The child exits: its references go; the image frames are the parent's alone.
        f.release_all(2);
        assert_eq!(f.free_frames(), 11);
        assert_eq!(f.frame_of(1, 0x40_0000).unwrap().1, 1);
        f.release_all(1);
        assert_eq!(f.free_frames(), 16);
    }

    #[test]
    fn a_fork_copies_the_foreseen_writes_at_once() {
        let (mut mem, mut table) = setup(16);
        let mut f = Frames::new(&mut mem, &mut table);
        let mut t = Tables::default();
        f.back(&mut t, 1, 0x40_0000, 1, RX, |_, page| page.fill(7))
            .unwrap();
        for page in [0x80_0000, 0x80_1000, 0x80_2000] {
            assert_eq!(
                f.fault_in(&mut t, 1, page, RW, true),
                Ok(None),
                "zeroed, not copied"
            );
        }
        f.write(&mut t, 1, 0x80_0000, b"parent").unwrap();
        let areas = |page: u64| match page {
            0x40_0000 => Some(RX),
            0x80_2000 => None, // unmapped since (a PROT_NONE area)
            _ => Some(RW),
        };
        // Foreseen: a written page, the image's (not writable), one not backed, one of no
        // area: only the first is copied.
        let foreseen = [0x80_0000, 0x40_0000, 0x90_0000, 0x80_2000];
        assert_eq!(f.share(&mut t, 1, 2, areas, &foreseen), Ok(4));
        assert_eq!(f.free_frames(), 11, "one copy");
        for pid in [1, 2] {
            assert_eq!(t.mapped[&(pid, 0x80_0000)].1, RW, "writable in both");
            assert_eq!(f.frame_of(pid, 0x80_0000).unwrap().1, 1);
            assert_eq!(t.mapped[&(pid, 0x80_1000)].1, Rights::READ, "shared");
            assert_eq!(t.mapped[&(pid, 0x40_0000)].1, RX);
        }
        assert!(!t.mapped.contains_key(&(2, 0x90_0000)));
        assert_eq!(byte(&f, 2, 0x80_0005), b't', "the child's copy");
        f.write(&mut t, 2, 0x80_0000, b"child").unwrap();
        assert_eq!(byte(&f, 1, 0x80_0000), b'p');
        // A write of a page still shared is a copy: what the next fork foresees.
        let (shared, _) = f.frame_of(2, 0x80_1000).unwrap();
        assert_eq!(f.fault_in(&mut t, 2, 0x80_1000, RW, true), Ok(Some(shared)));
        // A page another child still shares stays read-only in the parent.
        assert_eq!(f.share(&mut t, 1, 3, areas, &[0x80_1000]), Ok(4));
        assert_eq!(t.mapped[&(3, 0x80_1000)].1, RW);
        assert_eq!(
            t.mapped[&(1, 0x80_1000)].1,
            RW,
            "the parent's frame is its own again"
        );
        assert_eq!(
            t.mapped[&(1, 0x80_0000)].1,
            Rights::READ,
            "shared with child 3"
        );
    }

    #[test]
    fn a_copy_teaches_the_processes_whose_next_fork_writes_it() {
        let (mut mem, mut table) = setup(8);
        let mut f = Frames::new(&mut mem, &mut table);
        let mut t = Tables::default();
        let rw = |_| Some(RW);
        let (a, b) = (0x80_0000, 0x80_1000);
        for page in [a, b] {
            f.fault_in(&mut t, 1, page, RW, true).unwrap();
        }
        f.share(&mut t, 1, 2, rw, &[]).unwrap();
        // Child 2 writes a page its parent still has: the parent's next child will too.
        let copied = f.fault_in(&mut t, 2, a, RW, true).unwrap().unwrap();
        let none = std::iter::empty();
        assert_eq!(f.foreseers(2, a, copied, Some(1), none), [Some(1), None]);
        // 2 forks 3 and writes the page again: its parent has another frame now, its
        // child this one.
        f.share(&mut t, 2, 3, rw, &[]).unwrap();
        let copied = f.fault_in(&mut t, 2, a, RW, true).unwrap().unwrap();
        let children = [3].into_iter();
        assert_eq!(
            f.foreseers(2, a, copied, Some(1), children),
            [None, Some(2)]
        );
        // The parent executed (its memory gone): the copy teaches no one.
        f.release_all(1);
        f.release_all(3);
        f.share(&mut t, 2, 4, rw, &[]).unwrap();
        let copied = f.fault_in(&mut t, 4, b, RW, true).unwrap().unwrap();
        let none = std::iter::empty();
        assert_eq!(f.foreseers(4, b, copied, Some(1), none), [None, None]);
    }

    #[test]
    fn fork_writes_keep_the_newest_pages_once_each() {
        let mut w = ForkWrites::default();
        w.record(0x1000);
        w.record(0x1000);
        assert_eq!(w.pages(), [0x1000]);
        for i in 1..=ForkWrites::MAX as u64 {
            w.record(0x1000 * (i + 1));
        }
        assert_eq!(w.pages().len(), ForkWrites::MAX);
        assert_eq!(w.pages()[0], 0x2000, "the oldest gave way");
        assert_eq!(
            w.pages()[ForkWrites::MAX - 1],
            0x1000 * (ForkWrites::MAX as u64 + 1)
        );
        w.forget(0x3000, 0x5000);
        assert_eq!(w.pages().len(), ForkWrites::MAX - 2);
        assert_eq!(w.pages()[..2], [0x2000, 0x5000], "the order kept");
        w.record(0x3000);
        assert_eq!(w.pages().last(), Some(&0x3000));
    }

    #[test]
    fn a_fork_past_a_frames_last_reference_changes_nothing() {
        let (mut mem, mut table) = setup(4);
        let mut f = Frames::new(&mut mem, &mut table);
        let mut t = Tables::default();
        f.fault_in(&mut t, 1, 0x1000, RW, true).unwrap();
        f.fault_in(&mut t, 1, 0x2000, RW, true).unwrap();
        let (full, _) = f.frame_of(1, 0x2000).unwrap();
        while f.pool.share(full) {}
        let rw = |_| Some(RW);
        assert_eq!(f.share(&mut t, 1, 2, rw, &[]), Err(Errno::EAGAIN));
        assert_eq!(
            f.frame_of(1, 0x1000).unwrap().1,
            1,
            "its reference given back"
        );
        assert_eq!(f.frame_of(2, 0x1000), None, "no entry of the child left");
        assert_eq!(
            f.frame_of(1, 0x2000).unwrap().1,
            crate::pool::MAX_REFERENCES
        );
    }

    #[test]
    fn fork_leaves_inaccessible_pages_unmapped_and_stops_when_out_of_table() {
        let (mut mem, mut table) = setup(4);
        // A table of 5 entries: the parent's 3 pages and not all of the child's.
        let mut f = Frames::new(&mut mem, &mut table[..5 * 16]);
        let mut t = Tables::default();
        f.fault_in(&mut t, 1, 0x1000, RW, true).unwrap();
        f.fault_in(&mut t, 1, 0x2000, RW, true).unwrap();
        f.fault_in(&mut t, 1, 0x9000, RW, true).unwrap();
        let none_at_2 = |page: u64| (page != 0x2000).then_some(RW);
        assert_eq!(f.share(&mut t, 1, 2, none_at_2, &[]), Err(Errno::ENOMEM));
        // The child's task goes, with its mappings.
        f.release_all(2);
        t.mapped.retain(|k, _| k.0 != 2);
        assert_eq!(f.frame_of(1, 0x1000).unwrap().1, 1, "references given back");
        assert_eq!(f.free_frames(), 1);
        f.release(&mut t, 1, 0x9000, 1);
        assert_eq!(f.share(&mut t, 1, 2, none_at_2, &[]), Ok(2));
        assert!(t.mapped.contains_key(&(2, 0x1000)));
        assert!(
            !t.mapped.contains_key(&(2, 0x2000)),
            "PROT_NONE stays unmapped"
        );
    }

    #[test]
    fn images_are_loaded_once_and_shared_copy_on_write() {
        let (mut mem, mut table) = setup(8);
        let mut f = Frames::new(&mut mem, &mut table);
        let mut t = Tables::default();
        let fills = std::cell::Cell::new(0);
        let fill = |at: u64, page: &mut [u8]| {
            fills.set(fills.get() + 1);
            page.fill((at >> 12) as u8);
        };
        f.back_image(&mut t, 1, 0x40_0000, 3, RW, 7, &fill).unwrap();
        f.back_image(&mut t, 2, 0x40_0000, 3, RW, 7, &fill).unwrap();
        assert_eq!(fills.get(), 3, "filled once");
        assert_eq!(f.free_frames(), 5);
        assert_eq!(t.calls, 2, "one map per process");
        assert_eq!(t.mapped[&(2, 0x40_1000)].1, Rights::READ);
        assert_eq!(f.frame_of(1, 0x40_1000).unwrap().1, 3);
        // A write copies; the cache keeps the loaded bytes for the next process.
        f.fault_in(&mut t, 1, 0x40_1000, RW, true).unwrap();
        f.write(&mut t, 1, 0x40_1000, b"w").unwrap();
        f.release_all(2);
        f.back_image(&mut t, 3, 0x40_0000, 3, RW, 7, &fill).unwrap();
        assert_eq!(
            (fills.get(), byte(&f, 3, 0x40_1000), byte(&f, 1, 0x40_1000)),
            (3, 1, b'w')
        );
        // Out of frames: the pages only the cache holds are given back.
        f.release_all(1);
        f.release_all(3);
        assert_eq!(f.free_frames(), 5);
        for page in 0..8 {
            f.fault_in(&mut t, 4, 0x1000 * (page + 1), RW, true)
                .unwrap();
        }
        assert_eq!(f.free_frames(), 0);
        assert!(f.fault_in(&mut t, 4, 0x10_0000, RW, true).is_err());
        // Images with ids the cache does not take are loaded as they are.
        f.release_all(4);
        f.back_image(&mut t, 5, 0x40_0000, 1, RW, MAX_IMAGE_ID, &fill)
            .unwrap();
        assert_eq!((fills.get(), f.frame_of(5, 0x40_0000).unwrap().1), (4, 1));
    }

    #[test]
    fn moved_pages_keep_their_frames() {
        let (mut mem, mut table) = setup(4);
        let mut f = Frames::new(&mut mem, &mut table);
        let mut t = Tables::default();
        f.fault_in(&mut t, 1, 0x1000, RW, true).unwrap();
        f.write(&mut t, 1, 0x3000, b"z").unwrap();
        let frame = f.frame_of(1, 0x1000).unwrap().0;
        f.move_pages(&mut t, 1, 0x1000, 0x9000, 3);
        assert!(t.mapped.is_empty() && f.frame_of(1, 0x1000).is_none());
        assert_eq!(f.frame_of(1, 0x9000).unwrap().0, frame);
        assert_eq!(byte(&f, 1, 0xb000), b'z');
        assert_eq!(f.free_frames(), 2);
    }

    #[test]
    fn fill_in_backs_a_page_once() {
        let (mut mem, mut table) = setup(2);
        let mut f = Frames::new(&mut mem, &mut table);
        let mut t = Tables::default();
        f.fill_in(1, 0x1000, |b| b[..2].copy_from_slice(b"hi"))
            .unwrap();
        f.fill_in(1, 0x1000, |_| panic!("filled twice")).unwrap();
        assert!(t.mapped.is_empty());
        assert_eq!((byte(&f, 1, 0x1001), byte(&f, 1, 0x1002)), (b'i', 0));
        f.fault_in(&mut t, 1, 0x1000, Rights::READ, false).unwrap();
        assert_eq!(byte(&f, 1, 0x1000), b'h');
        assert_eq!(f.free_frames(), 1);
    }

    #[test]
    fn unmap_keeps_contents_for_the_next_fault() {
        let (mut mem, mut table) = setup(4);
        let mut f = Frames::new(&mut mem, &mut table);
        let mut t = Tables::default();
        f.fault_in(&mut t, 1, 0x1000, RW, true).unwrap();
        f.write(&mut t, 1, 0x1000, b"kept").unwrap();
        f.unmap(&mut t, 1, 0, 16);
        assert!(t.mapped.is_empty());
        f.fault_in(&mut t, 1, 0x1000, Rights::READ, false).unwrap();
        assert_eq!(t.mapped[&(1, 0x1000)].1, Rights::READ);
        assert_eq!(byte(&f, 1, 0x1000), b'k');
        // Ranges to the end of the address space stay within the process.
        for pid in [2, 3] {
            f.fault_in(&mut t, pid, 0x1000, RW, true).unwrap();
        }
        f.release(&mut t, 2, 0, u64::MAX);
        f.unmap(&mut t, 2, 0, u64::MAX);
        assert!(f.frame_of(2, 0x1000).is_none());
        assert!(f.frame_of(1, 0x1000).is_some() && f.frame_of(3, 0x1000).is_some());
        assert!(t.mapped.contains_key(&(3, 0x1000)));
    }
}
