//! User address spaces: a PML4 per task whose kernel half (slots 256..511) is shared with
//! the kernel's and supervisor-only; user mappings get the U bit and their own rights.
//! Page-table frames come from the kernel allocator; the caller charges them to a resource
//! partition *before* mapping ([`AddressSpace::tables_needed`]), so a map never fails half
//! way for lack of memory.

use super::{PAGE_SIZE, alloc_zeroed_frame, free_frame, phys_to_virt};
use abi::syscall::{PageRights, USER_END, USER_MIN};

const PRESENT: u64 = 1;
const WRITABLE: u64 = 1 << 1;
const USER: u64 = 1 << 2;
const WRITE_THROUGH: u64 = 1 << 3;
const CACHE_DISABLE: u64 = 1 << 4;
const HUGE: u64 = 1 << 7;
/// Software bit: the page is a device's registers (`map_device`), never RAM. `translate`
/// does not see it, so the kernel never reads or writes it for user space and it is never
/// the source of another mapping.
const DEVICE: u64 = 1 << 9;
const NO_EXECUTE: u64 = 1 << 63;
const ADDRESS: u64 = 0x000f_ffff_ffff_f000;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapError {
    OutOfMemory,
    NotUserAddress,
    AlreadyMapped,
}

/// A task's address space (by its top-level table); 0 = none.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct AddressSpace {
    root: u64,
    /// How far [`AddressSpace::destroy_some`] got: every table below this user address
    /// is freed.
    destroyed_below: u64,
}

/// The page table in frame `phys`, through the direct map.
///
/// # Safety
/// `phys` must be a page-table frame: the root of a live address space or the frame of a
/// present non-leaf entry of one (or the active CR3 root), and the caller must not hold
/// another reference into that table while it uses this one (the non-preemptible kernel
/// walks one table at a time).
unsafe fn table(phys: u64) -> &'static mut [u64; 512] {
    // SAFETY: the caller's contract; the direct map covers every frame.
    unsafe { &mut *(phys_to_virt(phys) as *mut [u64; 512]) }
}

fn index(virt: u64, level: u32) -> usize {
    ((virt >> (12 + 9 * level)) & 511) as usize
}

/// True if `[start, start + pages pages)` is page-aligned user space (never the kernel half).
pub fn is_user_range(start: u64, pages: u64) -> bool {
    start.is_multiple_of(PAGE_SIZE)
        && start >= USER_MIN
        && pages
            .checked_mul(PAGE_SIZE)
            .and_then(|len| start.checked_add(len))
            .is_some_and(|end| end <= USER_END)
}

fn leaf_bits(rights: PageRights) -> u64 {
    PRESENT
        | USER
        | if rights.contains(PageRights::WRITE) {
            WRITABLE
        } else {
            0
        }
        | if rights.contains(PageRights::EXECUTE) {
            0
        } else {
            NO_EXECUTE
        }
}

impl AddressSpace {
    pub const NONE: Self = Self {
        root: 0,
        destroyed_below: 0,
    };

    /// Its top-level table's frame (0: none), for the host tests' checks of every table.
    #[cfg(test)]
    pub(crate) fn root_frame(&self) -> u64 {
        self.root
    }

    /// A new, empty user half sharing the kernel half.
    pub fn new() -> Result<Self, MapError> {
        let root = alloc_zeroed_frame().ok_or(MapError::OutOfMemory)?;
        #[cfg(not(test))]
        {
            let (current, _) = x86_64::registers::control::Cr3::read();
            // SAFETY: the active root table, only read here.
            let kernel = unsafe { table(current.start_address().as_u64()) };
            // SAFETY: the new root, a fresh frame nobody else references.
            let new_root = unsafe { table(root) };
            new_root[256..].copy_from_slice(&kernel[256..]);
        }
        Ok(Self {
            root,
            destroyed_below: 0,
        })
    }

    pub fn root(&self) -> u64 {
        self.root
    }

    pub fn is_none(&self) -> bool {
        self.root == 0
    }

    /// The leaf entry of `virt`, creating missing tables if `create`.
    fn leaf(&self, virt: u64, create: bool) -> Result<Option<&'static mut u64>, MapError> {
        let mut t = self.root;
        for level in (1..4).rev() {
            // SAFETY: the root or a present non-leaf entry's frame (the walk below).
            let entry = &mut unsafe { table(t) }[index(virt, level)];
            if *entry & PRESENT == 0 {
                if !create {
                    return Ok(None);
                }
                *entry =
                    alloc_zeroed_frame().ok_or(MapError::OutOfMemory)? | PRESENT | WRITABLE | USER;
            }
            t = *entry & ADDRESS;
        }
        // SAFETY: the last non-leaf entry's frame.
        Ok(Some(&mut unsafe { table(t) }[index(virt, 0)]))
    }

    /// The leaf table of `virt` (its frame), or the level of the first entry missing on
    /// the way there.
    fn leaf_table(&self, virt: u64) -> Result<u64, u32> {
        let mut t = self.root;
        for level in (1..4).rev() {
            if t == 0 {
                return Err(level);
            }
            // SAFETY: the root or a present non-leaf entry's frame.
            let entry = unsafe { table(t) }[index(virt, level)];
            if entry & PRESENT == 0 {
                return Err(level);
            }
            t = entry & ADDRESS;
        }
        Ok(t)
    }

    /// Page-table frames a map of `pages` pages at `virt` would allocate, or `None` if one
    /// of those pages is mapped already. One walk per 2 MiB, not per page.
    pub fn tables_needed(&self, virt: u64, pages: u64) -> Option<u64> {
        let mut needed = 0;
        // The last table (by level and covering range) counted as "to be created".
        let mut counted = [u64::MAX; 4];
        let mut walked = (u64::MAX, Err(0));
        for page in 0..pages {
            let at = virt + page * PAGE_SIZE;
            if walked.0 != at >> 21 {
                walked = (at >> 21, self.leaf_table(at));
            }
            match walked.1 {
                // SAFETY: a present non-leaf entry's frame (the walk above).
                Ok(leaf) if unsafe { table(leaf) }[index(at, 0)] & PRESENT != 0 => return None,
                Ok(_) => {}
                // Each missing level below the first missing one is missing too.
                Err(level) => {
                    for l in (1..=level).rev() {
                        let span = at >> (12 + 9 * l);
                        if counted[l as usize] != span {
                            counted[l as usize] = span;
                            needed += 1;
                        }
                    }
                }
            }
        }
        Some(needed)
    }

    /// Maps the user page `virt` to frame `phys`.
    pub fn map(&mut self, virt: u64, phys: u64, rights: PageRights) -> Result<(), MapError> {
        self.map_leaf(virt, phys, leaf_bits(rights))
    }

    /// Maps the user page `virt` to device registers at `phys`, uncached (PCD | PWT: PAT
    /// entry 3, UC, which the kernel leaves as the CPU resets it).
    pub fn map_device(&mut self, virt: u64, phys: u64, rights: PageRights) -> Result<(), MapError> {
        let bits = leaf_bits(rights) | DEVICE | CACHE_DISABLE | WRITE_THROUGH;
        self.map_leaf(virt, phys, bits)
    }

    fn map_leaf(&mut self, virt: u64, phys: u64, bits: u64) -> Result<(), MapError> {
        if !is_user_range(virt, 1) {
            return Err(MapError::NotUserAddress);
        }
        let leaf = self.leaf(virt, true)?.expect("created");
        if *leaf & PRESENT != 0 {
            return Err(MapError::AlreadyMapped);
        }
        *leaf = (phys & ADDRESS) | bits;
        Ok(())
    }

    /// Removes the mapping of `virt`; returns the frame it mapped.
    pub fn unmap(&mut self, virt: u64) -> Option<u64> {
        let leaf = self.leaf(virt, false).ok()??;
        if *leaf & PRESENT == 0 {
            return None;
        }
        let frame = *leaf & ADDRESS;
        *leaf = 0;
        self.flush(virt);
        Some(frame)
    }

    /// Changes the rights of a mapped page.
    pub fn set_rights(&mut self, virt: u64, rights: PageRights) -> bool {
        let Ok(Some(leaf)) = self.leaf(virt, false) else {
            return false;
        };
        if *leaf & PRESENT == 0 {
            return false;
        }
        *leaf = (*leaf & ADDRESS) | leaf_bits(rights);
        self.flush(virt);
        true
    }

    /// The frame and rights behind user address `virt`, if it is a present user page of
    /// memory (device registers are not: the kernel never accesses them for user space).
    pub fn translate(&self, virt: u64) -> Option<(u64, PageRights)> {
        let entry = self.user_leaf(virt).filter(|e| e & DEVICE == 0)?;
        let mut rights = PageRights::empty();
        rights.set(PageRights::WRITE, entry & WRITABLE != 0);
        rights.set(PageRights::EXECUTE, entry & NO_EXECUTE == 0);
        Some((entry & ADDRESS, rights))
    }

    /// The present user leaf entry of `virt`.
    fn user_leaf(&self, virt: u64) -> Option<u64> {
        if self.root == 0 || !(USER_MIN..USER_END).contains(&virt) {
            return None;
        }
        let mut t = self.root;
        for level in (0..4).rev() {
            // SAFETY: the root or a present non-leaf entry's frame.
            let entry = unsafe { table(t) }[index(virt, level)];
            if entry & (PRESENT | USER) != PRESENT | USER || entry & HUGE != 0 {
                return None;
            }
            if level == 0 {
                return Some(entry);
            }
            t = entry & ADDRESS;
        }
        None
    }

    /// Calls `f(kernel_address, len)` for each page-bounded piece of the user range,
    /// checking rights first; `false` (and no call at all) if any page is missing.
    fn pieces(&self, ptr: u64, len: usize, write: bool, mut f: impl FnMut(u64, usize)) -> bool {
        if !self.accessible(ptr, len, write) {
            return false;
        }
        let mut done = 0;
        while done < len {
            let at = ptr + done as u64;
            let (frame, _) = self.translate(at & !(PAGE_SIZE - 1)).expect("checked");
            let offset = at % PAGE_SIZE;
            let n = ((PAGE_SIZE - offset) as usize).min(len - done);
            f(phys_to_virt(frame) + offset, n);
            done += n;
        }
        true
    }

    /// True if every byte of `[ptr, ptr + len)` is mapped user memory (writable if `write`).
    pub fn accessible(&self, ptr: u64, len: usize, write: bool) -> bool {
        let Some(end) = ptr.checked_add(len as u64) else {
            return false;
        };
        if len == 0 {
            return true;
        }
        let mut page = ptr & !(PAGE_SIZE - 1);
        while page < end {
            match self.translate(page) {
                Some((_, r)) if !write || r.contains(PageRights::WRITE) => {}
                _ => return false,
            }
            page += PAGE_SIZE;
        }
        true
    }

    /// Copies user memory at `ptr` into `out`; `false` if any byte is not a present user page.
    pub fn copy_from_user(&self, ptr: u64, out: &mut [u8]) -> bool {
        let mut done = 0;
        self.pieces(ptr, out.len(), false, |src, n| {
            // SAFETY: `src..src + n` lies inside one present user frame (direct map).
            let s = unsafe { core::slice::from_raw_parts(src as *const u8, n) };
            out[done..done + n].copy_from_slice(s);
            done += n;
        })
    }

    /// Copies `data` to user memory at `ptr`; `false` (nothing written) unless all of it is
    /// writable user memory.
    pub fn copy_to_user(&self, ptr: u64, data: &[u8]) -> bool {
        let mut done = 0;
        self.pieces(ptr, data.len(), true, |dst, n| {
            // SAFETY: `dst..dst + n` lies inside one present, writable user frame.
            let d = unsafe { core::slice::from_raw_parts_mut(dst as *mut u8, n) };
            d.copy_from_slice(&data[done..done + n]);
            done += n;
        })
    }

    /// The `N` words of user memory at `ptr`, after writing `write`'s there if given: in
    /// place, with one page-table walk, when they lie 8-byte aligned in one page (a message
    /// at the start of an IPC buffer does), else through the byte copies. `None` (nothing
    /// written) unless all of them are mapped user memory, writable if written.
    pub fn words<const N: usize>(&self, ptr: u64, write: Option<&[u64; N]>) -> Option<[u64; N]> {
        let in_page = ptr.is_multiple_of(8) && ptr % PAGE_SIZE + 8 * N as u64 <= PAGE_SIZE;
        match self.translate(ptr & !(PAGE_SIZE - 1)) {
            Some((frame, rights))
                if in_page && (write.is_none() || rights.contains(PageRights::WRITE)) =>
            {
                // SAFETY: the words lie aligned in one present user frame (direct map); the
                // kernel runs alone and holds no other reference into it.
                let words =
                    unsafe { &mut *((phys_to_virt(frame) + ptr % PAGE_SIZE) as *mut [u64; N]) };
                if let Some(w) = write {
                    *words = *w;
                }
                Some(*words)
            }
            _ => {
                let mut bytes = write.map_or([[0; 8]; N], |w| w.map(u64::to_ne_bytes));
                let done = match write {
                    Some(_) => self.copy_to_user(ptr, bytes.as_flattened()),
                    None => self.copy_from_user(ptr, bytes.as_flattened_mut()),
                };
                done.then(|| bytes.map(u64::from_ne_bytes))
            }
        }
    }

    /// Copies `len` bytes from `src` in `self` to `dst` in `to` (both checked first).
    pub fn copy_to_space(&self, src: u64, to: &AddressSpace, dst: u64, len: usize) -> bool {
        if !self.accessible(src, len, false) || !to.accessible(dst, len, true) {
            return false;
        }
        let mut chunk = [0u8; 256];
        let mut done = 0;
        while done < len {
            let n = chunk.len().min(len - done);
            let ok = self.copy_from_user(src + done as u64, &mut chunk[..n])
                && to.copy_to_user(dst + done as u64, &chunk[..n]);
            debug_assert!(ok, "checked above");
            done += n;
        }
        true
    }

    /// Frees the page-table frames of the user half and then the top-level table, doing at
    /// most `budget` units of work (an entry done with; `budget` is reduced by what was
    /// done); returns how many frames were freed. The space is gone
    /// ([`Self::is_destroyed`]) once a call got through; until then a later call goes on
    /// where this one stopped, so every unit is progress. Mapped frames themselves are not
    /// the kernel's and stay.
    pub fn destroy_some(&mut self, budget: &mut u64) -> u64 {
        /// Frees table `t` of `level` (0: a page table, whose entries are user frames),
        /// which maps the user addresses from `base`, and the tables below it that map
        /// addresses from `*below` on, clearing each entry whose table it freed. Returns the
        /// frames freed; `*below` says how far it got (past the table: all of it).
        fn free_level(t: u64, level: u32, base: u64, below: &mut u64, budget: &mut u64) -> u64 {
            let span = 1u64 << (12 + 9 * level);
            let entries = if level == 3 { 256 } else { 512 };
            let mut freed = 0;
            if level > 0 {
                // SAFETY: a table of this space; entries are cleared as their tables go.
                let table = unsafe { table(t) };
                // A plain index loop: this is where a large teardown spends its time.
                let mut i = (below.saturating_sub(base) / span) as usize;
                while i < entries {
                    let at = base + i as u64 * span;
                    if *budget == 0 {
                        *below = (*below).max(at);
                        return freed;
                    }
                    let entry = table[i];
                    if entry & PRESENT != 0 {
                        *below = (*below).max(at);
                        freed += free_level(entry & ADDRESS, level - 1, at, below, budget);
                        if *below < at + span {
                            return freed;
                        }
                        table[i] = 0;
                    }
                    // An entry is paid for once it is done with (the way down to the
                    // first undone one is at most three tables, whatever the budget).
                    *budget = budget.saturating_sub(1);
                    i += 1;
                }
            }
            // SAFETY: a table of this space, no longer referenced: its parent's entry is
            // cleared right after, or it is the root, which the space forgets.
            unsafe { free_frame(t) };
            *below = base + entries as u64 * span;
            freed + 1
        }
        if self.root == 0 {
            return 0;
        }
        let freed = free_level(self.root, 3, 0, &mut self.destroyed_below, budget);
        if self.destroyed_below >= USER_END {
            self.root = 0;
        }
        freed
    }

    /// True once [`Self::destroy_some`] freed the whole space (or it never had tables).
    pub fn is_destroyed(&self) -> bool {
        self.root == 0
    }

    pub fn is_active(&self) -> bool {
        #[cfg(not(test))]
        {
            let (current, _) = x86_64::registers::control::Cr3::read();
            current.start_address().as_u64() == self.root
        }
        #[cfg(test)]
        false
    }

    fn flush(&self, virt: u64) {
        if self.is_active() {
            #[cfg(not(test))]
            x86_64::instructions::tlb::flush(x86_64::VirtAddr::new(virt));
        }
        let _ = virt;
    }

    pub fn activate(&self) {
        #[cfg(not(test))]
        // SAFETY: the root maps the kernel half identically to the current tables.
        unsafe {
            x86_64::registers::control::Cr3::write(
                x86_64::structures::paging::PhysFrame::containing_address(x86_64::PhysAddr::new(
                    self.root,
                )),
                x86_64::registers::control::Cr3Flags::empty(),
            )
        };
    }
}

#[cfg(test)]
#[path = "../../host-tests/paging.rs"]
mod tests;
