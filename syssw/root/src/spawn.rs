//! Building blocks for running code of the caller's own image in new tasks and threads:
//!
//! * [`FramePool`]: hands out physical frames from a list of regions (the root task's
//!   [`RootInfo`](abi::root::RootInfo) regions), bump-style, never freed;
//! * [`AddressRange`]: hands out fresh virtual page ranges, each followed by an unmapped
//!   guard page;
//! * [`Spawner`]: combines both to create tasks that execute the caller's image at the same
//!   addresses ([`Spawner::map_image`]: read-only and executable `PT_LOAD` segments are
//!   shared, writable ones are private copies of their current contents), and threads with
//!   a stack and a registered IPC buffer ([`Spawner::thread`]).
//!
//! Everything here is mechanism: which abilities, priorities, partitions and addresses are
//! used is the caller's choice. It needs the `MAP` and `PHYSICAL_MEMORY` abilities (in
//! practice: it runs in the root task), plus `CREATE_TASK` / `CREATE_THREAD` for those calls.
//!
//! Conventions a thread started by [`Spawner::thread`] can rely on: it starts at `entry`
//! as if called (`rsp` = stack top - 8, so the SysV alignment holds) with the argument in
//! `rdi`, and has an IPC buffer registered (its address is in [`Thread::ipc_buffer`]; the
//! thread learns it through its argument if it needs it). Code that runs in a child task
//! sees private copies of the writable segments, so statics are *not* shared with the
//! creator: share memory explicitly ([`Spawner::memory`] with `share_with_root`).

// Frames being filled through scratch mappings, the own ELF headers and memory shared
// with child tasks are raw memory: the reason for `unsafe` in this module.
#![allow(unsafe_code)]

use abi::ipc::IPC_BUFFER_SIZE;
use abi::root::{PhysRegion, ROOT_INFO_MAX_REGIONS};
use abi::syscall::{
    Abilities, Call, Error, MAP_MAX_PAGES, PageRights, TaskId, ThreadAttribute, ThreadId,
};
use core::sync::atomic::AtomicU64;
use user_rt::ipc_buffer::IpcBufferRef;
use user_rt::sys;

pub const PAGE_SIZE: u64 = 4096;
/// Pages an [`IpcBuffer`](abi::ipc::IpcBuffer) needs.
pub const IPC_BUFFER_PAGES: u64 = (IPC_BUFFER_SIZE as u64).div_ceil(PAGE_SIZE);
/// Size of the window the spawner maps frames into to zero or fill them.
const SCRATCH_PAGES: u64 = MAP_MAX_PAGES;

/// Why a spawner operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpawnError {
    /// The frame pool has no run of free frames that long.
    OutOfFrames,
    /// The virtual address range is used up.
    OutOfAddresses,
    /// The running image's ELF headers are not where the linker should have put them.
    BadImage,
    /// A system call failed.
    Kernel(Call, Error),
}

fn kernel<T>(call: Call, result: Result<T, Error>) -> Result<T, SpawnError> {
    result.map_err(|e| SpawnError::Kernel(call, e))
}

/// Physical frames from a fixed list of regions, handed out in order and never returned.
#[derive(Clone, Debug)]
pub struct FramePool {
    regions: [PhysRegion; ROOT_INFO_MAX_REGIONS],
    count: usize,
    /// Region handed out from now, and pages of it already handed out.
    current: usize,
    used: u64,
}

impl FramePool {
    /// A pool over (at most `ROOT_INFO_MAX_REGIONS` of) `regions`, page-aligned.
    pub fn new(regions: &[PhysRegion]) -> Self {
        let mut pool = Self {
            regions: [PhysRegion::default(); ROOT_INFO_MAX_REGIONS],
            count: regions.len().min(ROOT_INFO_MAX_REGIONS),
            current: 0,
            used: 0,
        };
        pool.regions[..pool.count].copy_from_slice(&regions[..pool.count]);
        pool
    }

    /// The regions the kernel handed to the root task. Only valid in the root task.
    pub fn from_root_info() -> Self {
        Self::new(crate::root_info().regions())
    }

    /// `pages` physically contiguous frames (not zeroed). The rest of a region too small
    /// for the request is skipped for good.
    pub fn alloc(&mut self, pages: u64) -> Option<u64> {
        if pages == 0 {
            return None;
        }
        while self.current < self.count {
            let region = self.regions[self.current];
            if region.pages - self.used >= pages {
                let start = region.start + self.used * PAGE_SIZE;
                self.used += pages;
                return Some(start);
            }
            self.current += 1;
            self.used = 0;
        }
        None
    }

    /// Frames not handed out yet (including ones `alloc` may skip).
    pub fn free_pages(&self) -> u64 {
        self.regions[..self.count]
            .iter()
            .enumerate()
            .skip(self.current)
            .map(|(i, r)| {
                if i == self.current {
                    r.pages - self.used
                } else {
                    r.pages
                }
            })
            .sum()
    }
}

/// Fresh virtual page ranges from `[start, end)`, each followed by a guard page that is
/// never handed out.
#[derive(Clone, Debug)]
pub struct AddressRange {
    next: u64,
    end: u64,
}

impl AddressRange {
    /// `start` and `end` page-aligned user addresses.
    pub const fn new(start: u64, end: u64) -> Self {
        Self { next: start, end }
    }

    pub fn take(&mut self, pages: u64) -> Option<u64> {
        let size = pages.checked_add(1)?.checked_mul(PAGE_SIZE)?;
        let start = self.next;
        let after = start.checked_add(size)?;
        if pages == 0 || after > self.end {
            return None;
        }
        self.next = after;
        Some(start)
    }
}

/// An entry point for [`Spawner::thread`]: receives the thread's argument.
pub type ThreadEntry = extern "C" fn(u64) -> !;

/// A thread made by [`Spawner::thread`] (inactive until `thread_start`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Thread {
    pub id: ThreadId,
    /// Top of its stack (exclusive; the thread starts with `rsp` 8 below).
    pub stack_top: u64,
    /// Address of its registered IPC buffer, in its task.
    pub ipc_buffer: u64,
}

/// One `PT_LOAD` segment of the running image, widened to whole pages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Segment {
    pub start: u64,
    pub pages: u64,
    pub rights: PageRights,
}

unsafe extern "C" {
    /// The ELF header; the linker defines this when the header is part of a loaded segment.
    static __ehdr_start: u8;
}

const PT_LOAD: u32 = 1;
const PF_X: u32 = 1;
const PF_W: u32 = 2;

fn image_u64(base: u64, offset: u64) -> u64 {
    // SAFETY: only called for offsets inside the ELF header and program-header table,
    // which lie in the first (readable) loaded segment (checked by `image_segments`).
    unsafe { core::ptr::read_unaligned((base + offset) as *const u64) }
}

/// The `PT_LOAD` segments of the running image (at most 16).
pub fn image_segments() -> Result<([Segment; 16], usize), SpawnError> {
    let base = (&raw const __ehdr_start) as u64;
    // e_ident: magic, ELFCLASS64, little endian.
    if image_u64(base, 0) & 0xffff_ffff_ffff != 0x0102_464c_457f {
        return Err(SpawnError::BadImage);
    }
    // e_phoff at 0x20; e_phentsize (u16) at 0x36; e_phnum (u16) at 0x38.
    let phoff = image_u64(base, 0x20);
    let phentsize = image_u64(base, 0x30) >> 48;
    let phnum = image_u64(base, 0x38) & 0xffff;
    // The table must lie in the header's page, which is certainly mapped.
    if phentsize != 0x38 || phoff == 0 || phoff + phnum * phentsize > PAGE_SIZE {
        return Err(SpawnError::BadImage);
    }
    let mut out = [Segment {
        start: 0,
        pages: 0,
        rights: PageRights::empty(),
    }; 16];
    let mut n = 0;
    for i in 0..phnum {
        let ph = phoff + i * phentsize;
        let type_flags = image_u64(base, ph);
        let (p_type, p_flags) = (type_flags as u32, (type_flags >> 32) as u32);
        let (vaddr, memsz) = (image_u64(base, ph + 16), image_u64(base, ph + 40));
        if p_type != PT_LOAD || memsz == 0 {
            continue;
        }
        if n == out.len() {
            return Err(SpawnError::BadImage);
        }
        let start = vaddr & !(PAGE_SIZE - 1);
        let end = (vaddr + memsz).div_ceil(PAGE_SIZE) * PAGE_SIZE;
        let mut rights = PageRights::empty();
        if p_flags & PF_W != 0 {
            rights |= PageRights::WRITE;
        }
        if p_flags & PF_X != 0 {
            rights |= PageRights::EXECUTE;
        }
        out[n] = Segment {
            start,
            pages: (end - start) / PAGE_SIZE,
            rights,
        };
        n += 1;
    }
    Ok((out, n))
}

/// Creates tasks and threads running the caller's image; see the module documentation.
pub struct Spawner {
    frames: FramePool,
    addresses: AddressRange,
    /// `SCRATCH_PAGES` of the caller's address space, mapped only while zeroing/copying.
    scratch: u64,
}

impl Spawner {
    /// Takes frames from `frames` and the caller's (root task's) virtual addresses for
    /// everything it maps into itself from `addresses`, which must be unused.
    pub fn new(frames: FramePool, mut addresses: AddressRange) -> Result<Self, SpawnError> {
        let scratch = addresses
            .take(SCRATCH_PAGES)
            .ok_or(SpawnError::OutOfAddresses)?;
        Ok(Self {
            frames,
            addresses,
            scratch,
        })
    }

    /// Maps `pages` frames from `physical` at the scratch window one chunk at a time and
    /// calls `fill(chunk_address, first_page_index, chunk_pages)` for each.
    fn through_scratch(
        &mut self,
        physical: u64,
        pages: u64,
        mut fill: impl FnMut(u64, u64, u64),
    ) -> Result<(), SpawnError> {
        let mut done = 0;
        while done < pages {
            let n = (pages - done).min(SCRATCH_PAGES);
            kernel(
                Call::MapPhysical,
                sys::map_physical(
                    None,
                    physical + done * PAGE_SIZE,
                    self.scratch,
                    n,
                    PageRights::WRITE,
                ),
            )?;
            fill(self.scratch, done, n);
            kernel(Call::Unmap, sys::unmap(None, self.scratch, n))?;
            done += n;
        }
        Ok(())
    }

    /// `pages` physically contiguous frames, zeroed, then filled by `fill(chunk, offset)`
    /// chunk by chunk (`chunk` is writable memory of the frames starting `offset` bytes
    /// into them). For loading another program's segments.
    pub fn filled_frames(
        &mut self,
        pages: u64,
        fill: impl FnMut(&mut [u8], u64),
    ) -> Result<u64, SpawnError> {
        let physical = self.frames.alloc(pages).ok_or(SpawnError::OutOfFrames)?;
        self.refill_frames(physical, pages, fill)?;
        Ok(physical)
    }

    /// Zeroes `pages` frames from `physical` that this spawner handed out earlier and
    /// fills them like [`Spawner::filled_frames`] (reloading a restarted program).
    pub fn refill_frames(
        &mut self,
        physical: u64,
        pages: u64,
        mut fill: impl FnMut(&mut [u8], u64),
    ) -> Result<(), SpawnError> {
        self.through_scratch(physical, pages, |va, first, n| {
            // SAFETY: `through_scratch` just mapped `n` pages writable at `va`, in the
            // scratch window nobody else uses; the slice lives only during this call.
            let chunk =
                unsafe { core::slice::from_raw_parts_mut(va as *mut u8, (n * PAGE_SIZE) as usize) };
            chunk.fill(0);
            fill(chunk, first * PAGE_SIZE);
        })
    }

    /// `bytes` (rounded up to pages) of zeroed memory of the caller's own, for good (buffers
    /// a server sizes once at start-up).
    pub fn own_memory(&mut self, bytes: usize) -> Result<&'static mut [u8], SpawnError> {
        let pages = (bytes as u64).div_ceil(PAGE_SIZE).max(1);
        let address = self.memory(None, pages, PageRights::WRITE, false)?;
        // SAFETY: `memory` just mapped these pages writable at a fresh address in this task
        // that nothing else refers to, and they are never unmapped: one exclusive slice.
        Ok(unsafe { core::slice::from_raw_parts_mut(address as *mut u8, bytes) })
    }

    /// `pages` zeroed, physically contiguous frames.
    pub fn frames(&mut self, pages: u64) -> Result<u64, SpawnError> {
        let physical = self.frames.alloc(pages).ok_or(SpawnError::OutOfFrames)?;
        self.through_scratch(physical, pages, |va, _, n| {
            // SAFETY: `through_scratch` just mapped `n` pages writable at `va`, in the
            // scratch window nobody else uses.
            unsafe { core::ptr::write_bytes(va as *mut u8, 0, (n * PAGE_SIZE) as usize) }
        })?;
        Ok(physical)
    }

    /// Frames not handed out yet.
    pub fn free_frames(&self) -> u64 {
        self.frames.free_pages()
    }

    /// A fresh range of `pages` virtual pages (unique across everything this spawner
    /// maps, in any task), followed by an unmapped guard page.
    pub fn addresses(&mut self, pages: u64) -> Result<u64, SpawnError> {
        self.addresses.take(pages).ok_or(SpawnError::OutOfAddresses)
    }

    /// `pages` zeroed pages mapped with `rights` at a fresh address in `task` (`None` = the
    /// caller's); with `share_with_root`, the same frames are also mapped writable at the
    /// same address in the caller's task. Returns the address.
    pub fn memory(
        &mut self,
        task: Option<TaskId>,
        pages: u64,
        rights: PageRights,
        share_with_root: bool,
    ) -> Result<u64, SpawnError> {
        let address = self.addresses(pages)?;
        let physical = self.frames(pages)?;
        map_physical_chunked(task, physical, address, pages, rights)?;
        if share_with_root && task.is_some() {
            map_physical_chunked(None, physical, address, pages, PageRights::WRITE)?;
        }
        Ok(address)
    }

    /// `words` zeroed 64-bit words shared between the caller and `task` (at the same
    /// address in both). The memory stays mapped for good; nobody may unmap it.
    pub fn shared_words(
        &mut self,
        task: Option<TaskId>,
        words: usize,
    ) -> Result<&'static [AtomicU64], SpawnError> {
        let pages = (words as u64 * 8).div_ceil(PAGE_SIZE).max(1);
        let address = self.memory(task, pages, PageRights::WRITE, true)?;
        // SAFETY: just mapped writable in the caller's task, zeroed, never unmapped (this
        // function's contract), and only ever accessed atomically.
        Ok(unsafe { words_at(address, words) })
    }

    /// A child task (`task_create`) with the caller's image mapped ([`Self::map_image`]).
    pub fn create_task(
        &mut self,
        abilities: Abilities,
        mcp: u8,
        rp: u64,
        name: &str,
    ) -> Result<TaskId, SpawnError> {
        let task = kernel(Call::TaskCreate, sys::task_create(abilities, mcp, rp, name))?;
        self.map_image(task)?;
        Ok(task)
    }

    /// Maps the caller's image into `task` at the same addresses: read-only and executable
    /// segments shared with their rights, writable segments as private copies of their
    /// current contents.
    pub fn map_image(&mut self, task: TaskId) -> Result<(), SpawnError> {
        let (segments, count) = image_segments()?;
        for segment in &segments[..count] {
            if segment.rights.contains(PageRights::WRITE) {
                let physical = self
                    .frames
                    .alloc(segment.pages)
                    .ok_or(SpawnError::OutOfFrames)?;
                let source = segment.start;
                self.through_scratch(physical, segment.pages, |va, first, n| {
                    // SAFETY: the segment's pages are mapped readable in the caller (the
                    // kernel loaded them); the scratch window was just mapped writable for
                    // `n` pages; the two never overlap.
                    unsafe {
                        core::ptr::copy_nonoverlapping(
                            (source + first * PAGE_SIZE) as *const u8,
                            va as *mut u8,
                            (n * PAGE_SIZE) as usize,
                        )
                    }
                })?;
                map_physical_chunked(
                    Some(task),
                    physical,
                    segment.start,
                    segment.pages,
                    segment.rights,
                )?;
            } else {
                let mut done = 0;
                while done < segment.pages {
                    let n = (segment.pages - done).min(MAP_MAX_PAGES);
                    let at = segment.start + done * PAGE_SIZE;
                    kernel(Call::Map, sys::map(Some(task), at, at, n, segment.rights))?;
                    done += n;
                }
            }
        }
        Ok(())
    }

    /// An inactive thread of `task` (`None` = the caller's) that will run
    /// `entry(arg)` at `priority` on a fresh stack of `stack_pages` pages, with a fresh IPC
    /// buffer registered. Start it with `thread_start`.
    pub fn thread(
        &mut self,
        task: Option<TaskId>,
        entry: ThreadEntry,
        priority: u8,
        arg: u64,
        stack_pages: u64,
    ) -> Result<Thread, SpawnError> {
        let stack = self.memory(task, stack_pages, PageRights::WRITE, false)?;
        let ipc_buffer = self.memory(task, IPC_BUFFER_PAGES, PageRights::WRITE, false)?;
        let stack_top = stack + stack_pages * PAGE_SIZE;
        let id = kernel(
            Call::ThreadCreate,
            sys::thread_create(
                task,
                entry as *const () as usize as u64,
                stack_top - 8,
                priority,
                arg,
            ),
        )?;
        kernel(
            Call::ThreadSet,
            sys::thread_set(Some(id), ThreadAttribute::IpcBuffer, ipc_buffer),
        )?;
        Ok(Thread {
            id,
            stack_top,
            ipc_buffer,
        })
    }

    /// Maps a fresh IPC buffer into the caller's task and registers it for the calling
    /// thread.
    pub fn own_ipc_buffer(&mut self) -> Result<IpcBufferRef, SpawnError> {
        let address = self.memory(None, IPC_BUFFER_PAGES, PageRights::WRITE, false)?;
        kernel(
            Call::ThreadSet,
            sys::thread_set(None, ThreadAttribute::IpcBuffer, address),
        )?;
        // SAFETY: freshly mapped writable in this task, IPC_BUFFER_PAGES cover
        // IPC_BUFFER_SIZE, page-aligned, never unmapped and only used through the ref.
        Ok(unsafe { IpcBufferRef::new(address) })
    }
}

/// Maps `pages` frames from `physical` at `address` in `task` (any number of pages).
pub fn map_physical_chunked(
    task: Option<TaskId>,
    physical: u64,
    address: u64,
    pages: u64,
    rights: PageRights,
) -> Result<(), SpawnError> {
    let mut done = 0;
    while done < pages {
        let n = (pages - done).min(MAP_MAX_PAGES);
        kernel(
            Call::MapPhysical,
            sys::map_physical(
                task,
                physical + done * PAGE_SIZE,
                address + done * PAGE_SIZE,
                n,
                rights,
            ),
        )?;
        done += n;
    }
    Ok(())
}

/// `count` atomic words at `address`.
///
/// # Safety
/// `address` must be 8-byte aligned and `count * 8` bytes there mapped readable and
/// writable in the calling task for the rest of its life, and accessed only atomically
/// (e.g. memory from [`Spawner::shared_words`], seen from a thread it was shared with).
pub unsafe fn words_at(address: u64, count: usize) -> &'static [AtomicU64] {
    // SAFETY: the caller guarantees the memory is mapped, aligned and atomically used;
    // AtomicU64 has the layout of u64 and any bit pattern is valid.
    unsafe { core::slice::from_raw_parts(address as *const AtomicU64, count) }
}
