//! Task control blocks and loading the root task from syssw's ELF.

use crate::mem::paging::{AddressSpace, MapError};
use crate::mem::{PAGE_SIZE, alloc_zeroed_frame, phys_to_virt};
use crate::rp::Amount;
use crate::state::{Kernel, MAX_TASKS, MAX_THREADS, slot_of};
use crate::table::{RpIdx, Slot, TaskIdx, ThreadIdx};

/// `task`'s bit in the `send_to` masks.
pub(crate) fn bit(task: TaskIdx) -> u64 {
    1 << task.position()
}
use abi::root::{PhysRegion, ROOT_INFO_MAGIC, ROOT_INFO_MAX_REGIONS, ROOT_INFO_VERSION, RootInfo};
use abi::syscall::{
    Abilities, MAX_PRIORITY, PageRights, ROOT_INFO_BASE, ROOT_PRIORITY, ROOT_STACK_SIZE,
    ROOT_STACK_TOP, ROOT_SYSTEM_IMAGE_BASE, USER_END, USER_MIN,
};
use abi::syscall::{Error, TASK_NAME_MAX, TaskId, make_id};

/// A task control block. Its fields change only here, through methods that keep them
/// consistent: abilities and MCP within the parent's, the pages charged to its resource
/// partition with what its page tables and I/O bitmap hold ([`Kernel::charge_pages`]).
#[derive(Clone, Copy)]
pub struct Task {
    in_use: bool,
    generation: u16,
    name: [u8; 16],
    name_len: u8,
    parent: Option<TaskIdx>,
    abilities: Abilities,
    mcp: u8,
    /// Resource partition slot it belongs to and is charged to.
    rp: RpIdx,
    space: AddressSpace,
    /// Bit i set: threads of this task may send to threads of task slot i.
    send_to: u64,
    /// Bit i set: threads of this task may notify threads of task slot i (as sending may).
    notify_to: u64,
    /// Page-table and I/O-bitmap frames charged to the resource partition (returned when
    /// it dies).
    pages_charged: u64,
    /// The two frames of its I/O permission bitmap (0: no ports).
    io_bitmap: [u64; 2],
    /// Bit n: the task may attach interrupt line n.
    irq_lines: u32,
    /// Stopped (`task_stop`) or being destroyed by a `task_kill` that is not finished: its
    /// threads never run again and no call but `task_kill` and `task_stop` can name it
    /// (see [`Kernel::stop_task`]).
    dying: bool,
}

impl Task {
    pub const FREE: Self = Self {
        in_use: false,
        generation: 0,
        name: [0; 16],
        name_len: 0,
        parent: None,
        abilities: Abilities::empty(),
        mcp: 0,
        rp: RpIdx::ROOT,
        space: AddressSpace::NONE,
        send_to: 0,
        notify_to: 0,
        pages_charged: 0,
        io_bitmap: [0; 2],
        irq_lines: 0,
        dying: false,
    };

    /// A root task named `name` (at most 16 bytes) in `space`: every ability, the highest
    /// MCP, the root resource partition, every interrupt line but the kernel's.
    pub fn root(space: AddressSpace, name: &str) -> Self {
        let mut task = Task {
            in_use: true,
            abilities: Abilities::all(),
            mcp: MAX_PRIORITY,
            rp: RpIdx::ROOT,
            space,
            send_to: 1,
            irq_lines: crate::irq::root_lines(),
            ..Task::FREE
        };
        task.name[..name.len()].copy_from_slice(name.as_bytes());
        task.name_len = name.len() as u8;
        task
    }

    pub fn name(&self) -> &str {
        core::str::from_utf8(&self.name[..self.name_len as usize]).unwrap_or("?")
    }

    #[inline(always)]
    pub fn in_use(&self) -> bool {
        self.in_use
    }

    #[inline(always)]
    pub fn is_dying(&self) -> bool {
        self.dying
    }

    #[inline(always)]
    pub fn parent(&self) -> Option<TaskIdx> {
        self.parent
    }

    #[inline(always)]
    pub fn abilities(&self) -> Abilities {
        self.abilities
    }

    #[inline(always)]
    pub fn mcp(&self) -> u8 {
        self.mcp
    }

    #[inline(always)]
    pub fn rp(&self) -> RpIdx {
        self.rp
    }

    #[inline(always)]
    pub fn space(&self) -> &AddressSpace {
        &self.space
    }

    #[inline(always)]
    pub fn pages_charged(&self) -> u64 {
        self.pages_charged
    }

    #[inline(always)]
    pub fn io_bitmap(&self) -> [u64; 2] {
        self.io_bitmap
    }

    #[inline(always)]
    pub fn irq_lines(&self) -> u32 {
        self.irq_lines
    }

    /// Maps a page (its page tables charged before: [`Kernel::charge_pages`]).
    pub fn map_page(&mut self, virt: u64, frame: u64, rights: PageRights) -> Result<(), MapError> {
        self.space.map(virt, frame, rights)
    }

    pub fn map_device_page(
        &mut self,
        virt: u64,
        frame: u64,
        rights: PageRights,
    ) -> Result<(), MapError> {
        self.space.map_device(virt, frame, rights)
    }

    pub fn unmap_page(&mut self, virt: u64) -> Option<u64> {
        self.space.unmap(virt)
    }

    pub fn set_page_rights(&mut self, virt: u64, rights: PageRights) -> bool {
        self.space.set_rights(virt, rights)
    }

    /// Frees its page tables, for host tests' clean-up.
    #[cfg(test)]
    pub fn destroy_space(&mut self) {
        self.space.destroy_some(&mut u64::MAX.clone());
    }

    /// Its I/O bitmap frames (charged before: [`Kernel::charge_pages`]).
    pub fn set_io_bitmap(&mut self, frames: [u64; 2]) {
        self.io_bitmap = frames;
    }

    /// Takes its I/O bitmap frames away (they are freed and released by the caller).
    pub fn take_io_bitmap(&mut self) -> [u64; 2] {
        core::mem::take(&mut self.io_bitmap)
    }

    pub fn grant_irq_line(&mut self, line: usize) {
        self.irq_lines |= 1 << line;
    }
}

/// Why the root task could not be created.
#[derive(Debug)]
pub enum LoadError {
    Elf(abi::elf::ElfError),
    Segment(u64, &'static str),
    Map(MapError),
}

impl From<MapError> for LoadError {
    fn from(e: MapError) -> Self {
        Self::Map(e)
    }
}

/// Loads the `PT_LOAD` segments of `elf` (checked by `abi::elf`) into fresh frames mapped
/// in `space` with their rights; returns the entry point.
#[allow(unsafe_code)] // fills fresh frames through the direct map
pub fn load_elf(elf: &[u8], space: &mut AddressSpace) -> Result<u64, LoadError> {
    let (entry, segments) =
        abi::elf::load_segments::<16>(elf, USER_MIN..USER_END).map_err(LoadError::Elf)?;
    for segment in segments.iter().flatten() {
        let (vaddr, end) = (segment.vaddr, segment.vaddr + segment.mem_size);
        let file_end = vaddr + segment.file.len() as u64;
        let mut page = vaddr & !(PAGE_SIZE - 1);
        while page < end {
            let frame = alloc_zeroed_frame().ok_or(MapError::OutOfMemory)?;
            // Copy the part of the file image that falls into this page.
            let (lo, hi) = (page.max(vaddr), (page + PAGE_SIZE).min(file_end));
            if lo < hi {
                let src = &segment.file[(lo - vaddr) as usize..(hi - vaddr) as usize];
                // SAFETY: fresh frame, direct-mapped; lo - page + len <= PAGE_SIZE.
                unsafe {
                    core::ptr::copy_nonoverlapping(
                        src.as_ptr(),
                        (phys_to_virt(frame) + (lo - page)) as *mut u8,
                        src.len(),
                    )
                };
            }
            space
                .map(page, frame, segment.rights)
                .map_err(|e| match e {
                    MapError::AlreadyMapped => {
                        LoadError::Segment(vaddr, "shares a page with another segment")
                    }
                    other => LoadError::Map(other),
                })?;
            page += PAGE_SIZE;
        }
    }
    Ok(entry)
}

/// Creates the root task (slot 0) in resource partition 0 from syssw's ELF: the system
/// image (`image_phys`, `image_len` bytes) read-only at `ROOT_SYSTEM_IMAGE_BASE`, the
/// [`RootInfo`] page listing `user_memory`, a zeroed stack, and its first thread, ready.
/// The root partition's quota is all kernel memory left afterwards.
#[allow(unsafe_code)] // writes the RootInfo page through the direct map
pub fn create_root(
    k: &mut crate::state::Kernel,
    syssw: &[u8],
    image_phys: u64,
    image_len: u64,
    user_memory: &[PhysRegion],
) -> Result<u64, LoadError> {
    use crate::rp::{Amount, ResourcePartition};
    let mut space = AddressSpace::new()?;
    let entry = load_elf(syssw, &mut space)?;
    for offset in (0..image_len.max(1)).step_by(PAGE_SIZE as usize) {
        space.map(
            ROOT_SYSTEM_IMAGE_BASE + offset,
            image_phys + offset,
            PageRights::empty(),
        )?;
    }
    let mut info = RootInfo {
        magic: ROOT_INFO_MAGIC,
        version: ROOT_INFO_VERSION,
        region_count: user_memory.len().min(ROOT_INFO_MAX_REGIONS) as u32,
        tsc_hz: crate::time::tsc_hz(),
        kernel_pages: 0,
        kernel_threads: MAX_THREADS as u64,
        kernel_tasks: MAX_TASKS as u64,
        regions: [PhysRegion::default(); ROOT_INFO_MAX_REGIONS],
    };
    for (slot, region) in info.regions.iter_mut().zip(user_memory) {
        *slot = *region;
    }
    for page in (ROOT_STACK_TOP - ROOT_STACK_SIZE..ROOT_STACK_TOP).step_by(PAGE_SIZE as usize) {
        let frame = alloc_zeroed_frame().ok_or(MapError::OutOfMemory)?;
        space.map(page, frame, PageRights::WRITE)?;
    }
    let info_frame = alloc_zeroed_frame().ok_or(MapError::OutOfMemory)?;
    space.map(ROOT_INFO_BASE, info_frame, PageRights::empty())?;
    // Everything the root task itself needed is allocated: the rest is the root quota.
    info.kernel_pages = crate::mem::free_frames();
    // SAFETY: a fresh frame (direct-mapped, 4 KiB) and RootInfo fits in a page.
    unsafe { (phys_to_virt(info_frame) as *mut RootInfo).write(info) };

    k.user_memory_count = info.region_count as usize;
    k.user_memory = info.regions;
    k.rps[RpIdx::ROOT] = ResourcePartition::new(
        TaskIdx::ROOT,
        Amount {
            tasks: MAX_TASKS as u64,
            threads: MAX_THREADS as u64,
            pages: info.kernel_pages,
        },
    );
    k.rps[RpIdx::ROOT]
        .charge(Amount::tasks(1))
        .expect("fresh quota");
    let task = Task::root(space, "syssw");
    k.tasks[TaskIdx::ROOT] = task;
    let thread = k
        .create_thread(
            TaskIdx::ROOT,
            entry,
            ROOT_STACK_TOP - 8,
            ROOT_PRIORITY,
            0,
            ROOT_SYSTEM_IMAGE_BASE,
        )
        .expect("fresh tables");
    k.threads[thread].set_start_registers(image_len, ROOT_INFO_BASE);
    k.set_state(thread, crate::thread::State::Ready);
    Ok(entry)
}

impl Kernel {
    pub fn task_id(&self, t: TaskIdx) -> TaskId {
        TaskId(make_id(t.position(), self.tasks[t].generation))
    }

    /// The live task `id` names (a dying one is gone for every call but `task_kill`).
    pub fn task(&self, id: TaskId) -> Result<TaskIdx, Error> {
        slot_of(&self.tasks, id.0, |t| {
            (t.in_use && !t.dying).then_some(t.generation)
        })
    }

    /// The task `id` names, live or dying (`task_kill` goes on destroying a dying one).
    pub fn task_to_kill(&self, id: TaskId) -> Result<TaskIdx, Error> {
        slot_of(&self.tasks, id.0, |t| t.in_use.then_some(t.generation))
    }

    /// True if `task` is `ancestor` or one of its descendants.
    pub fn is_within(&self, task: TaskIdx, ancestor: TaskIdx) -> bool {
        let mut at = Some(task);
        // The tree has at most MAX_TASKS levels.
        for _ in 0..MAX_TASKS {
            match at {
                Some(t) if t == ancestor => return true,
                Some(t) => at = self.tasks[t].parent,
                None => return false,
            }
        }
        false
    }

    /// The task named by `id` (0 = `caller`'s own), if the caller controls it.
    pub fn controlled_task(&self, caller: TaskIdx, id: TaskId) -> Result<TaskIdx, Error> {
        let task = match id.named() {
            None => caller,
            Some(id) => self.task(id)?,
        };
        if self.is_within(task, caller) {
            Ok(task)
        } else {
            Err(Error::NotPermitted)
        }
    }

    /// Charges `pages` kernel pages of `task` (page tables, I/O bitmap) to its resource
    /// partition.
    pub fn charge_pages(&mut self, task: TaskIdx, pages: u64) -> Result<(), Error> {
        self.rps[self.tasks[task].rp].charge(Amount::pages(pages))?;
        self.tasks[task].pages_charged += pages;
        Ok(())
    }

    /// Returns `pages` kernel pages of `task` (freed) to its resource partition.
    pub fn release_pages(&mut self, task: TaskIdx, pages: u64) {
        self.tasks[task].pages_charged -= pages;
        self.rps[self.tasks[task].rp].release(Amount::pages(pages));
    }

    /// Lets threads of `from` send to threads of `to`, or only notify them.
    pub fn allow_send(&mut self, from: TaskIdx, to: TaskIdx, notify_only: bool) {
        let task = &mut self.tasks[from];
        *if notify_only {
            &mut task.notify_to
        } else {
            &mut task.send_to
        } |= bit(to);
    }

    pub fn may_notify(&self, from_task: TaskIdx, to_task: TaskIdx) -> bool {
        (self.tasks[from_task].send_to | self.tasks[from_task].notify_to) & bit(to_task) != 0
    }

    pub fn may_send(&self, from_task: TaskIdx, to_task: TaskIdx) -> bool {
        self.tasks[from_task].send_to & bit(to_task) != 0
    }

    pub fn require(&self, task: TaskIdx, ability: Abilities) -> Result<(), Error> {
        if self.tasks[task].abilities.contains(ability) {
            Ok(())
        } else {
            Err(Error::AbilityDenied)
        }
    }

    /// Creates a child task of `parent`. Checks abilities ⊆ parent's and MCP ≤ parent's.
    pub fn create_task(
        &mut self,
        parent: TaskIdx,
        abilities: Abilities,
        mcp: u8,
        rp: RpIdx,
        name: &str,
    ) -> Result<TaskIdx, Error> {
        let p = &self.tasks[parent];
        if !p.abilities.contains(abilities) {
            return Err(Error::AbilityDenied);
        }
        if mcp > p.mcp {
            return Err(Error::McpExceeded);
        }
        if name.len() as u64 > TASK_NAME_MAX {
            return Err(Error::InvalidArgument);
        }
        if !self.rps[rp].in_use {
            return Err(Error::NoSuchObject);
        }
        let slot = self.tasks.find(|t| !t.in_use).ok_or(Error::QuotaExceeded)?;
        let cost = Amount {
            tasks: 1,
            threads: 0,
            pages: 1,
        };
        self.rps[rp].charge(cost)?;
        let Ok(space) = AddressSpace::new() else {
            self.rps[rp].release(cost);
            return Err(Error::OutOfResources);
        };
        let generation = self.tasks[slot].generation;
        let mut task = Task {
            in_use: true,
            generation,
            parent: Some(parent),
            abilities,
            mcp,
            rp,
            space,
            // Itself and its parent; the parent may send to it.
            send_to: bit(slot) | bit(parent),
            pages_charged: 1,
            ..Task::FREE
        };
        task.name[..name.len()].copy_from_slice(name.as_bytes());
        task.name_len = name.len() as u8;
        self.tasks[slot] = task;
        self.tasks[parent].send_to |= bit(slot);
        Ok(slot)
    }

    /// The task slots of `task` and all its descendants, as a set of bits ([`bit`]).
    pub fn subtree(&self, task: TaskIdx) -> u64 {
        let mut children = [0u64; MAX_TASKS];
        for (slot, t) in self.tasks.iter() {
            if let (true, Some(parent)) = (t.in_use, t.parent) {
                children[parent.position()] |= bit(slot);
            }
        }
        let (mut set, mut todo) = (bit(task), bit(task));
        while todo != 0 {
            let next = children[todo.trailing_zeros() as usize] & !set;
            todo = (todo & (todo - 1)) | next;
            set |= next;
        }
        set
    }

    /// Stops `task` and its whole subtree at once (bounded: a look at every task and
    /// thread slot): every task of it is dying (no call can name it but `task_kill`), every
    /// thread suspended and out of the run queues, the I/O bitmaps freed.
    pub fn stop_task(&mut self, task: TaskIdx) {
        let set = self.subtree(task);
        for slot in TaskIdx::all().filter(|&t| set & bit(t) != 0) {
            self.tasks[slot].dying = true;
            let freed = self.release_io_bitmap(slot);
            self.release_pages(slot, freed);
        }
        for t in ThreadIdx::all() {
            if !self.threads[t].is_free() && set & bit(self.threads[t].task()) != 0 {
                self.set_suspended(t, true);
            }
        }
    }

    /// Destroys `task` and its whole subtree (threads, address spaces, I/O bitmaps, send
    /// rights), doing at most about `budget` units of work (a thread slot looked at;
    /// [`KILL_COST`] a thread killed, [`ENTRY_COST`] a page-table entry done with): true
    /// when all is gone, false when it must be called again (`task_kill` restarts itself,
    /// so a window boundary can come in between). The first call stops the whole subtree
    /// ([`Self::stop_task`]).
    pub fn destroy_task(&mut self, task: TaskIdx, mut budget: u64) -> bool {
        if !self.tasks[task].dying {
            self.stop_task(task);
            budget = budget.saturating_sub(MAX_THREADS as u64);
        }
        let set = self.subtree(task);
        let member = |t: TaskIdx| set & bit(t) != 0;
        budget = budget.saturating_sub(MAX_THREADS as u64);
        for t in ThreadIdx::all() {
            if !self.threads[t].is_free() && member(self.threads[t].task()) {
                if budget < KILL_COST {
                    return false;
                }
                self.kill_thread(t);
                budget -= KILL_COST;
            }
        }
        let mut entries = budget / ENTRY_COST;
        for slot in TaskIdx::all().filter(|&t| member(t)) {
            // No other CPU may walk the tables while they are freed.
            crate::arch::smp::release_space(self.tasks[slot].space.root(), true);
            let freed = self.tasks[slot].space.destroy_some(&mut entries);
            self.release_pages(slot, freed);
            if !self.tasks[slot].space.is_destroyed() {
                return false;
            }
        }
        for slot in TaskIdx::all().filter(|&t| member(t)) {
            debug_assert_eq!(self.tasks[slot].pages_charged, 0);
            self.rps[self.tasks[slot].rp].release(Amount::tasks(1));
            let generation = self.tasks[slot].generation.wrapping_add(1);
            self.tasks[slot] = Task {
                generation,
                ..Task::FREE
            };
        }
        for (_, other) in self.tasks.iter_mut() {
            other.send_to &= !set;
            other.notify_to &= !set;
        }
        true
    }
}

/// What killing one thread costs in [`Kernel::destroy_task`]'s units (it looks at every
/// thread slot for threads waiting on it, each look about twice a plain one).
pub const KILL_COST: u64 = 2 * MAX_THREADS as u64;

/// What a page-table entry costs in [`Kernel::destroy_task`]'s units (measured on virtual
/// time: about three looks at a thread slot).
pub const ENTRY_COST: u64 = 3;

/// The work one `task_kill` call does at most before it restarts itself, about 10 us of
/// virtual time (measured, scenario `attack_kill`: a call killing a thread and one freeing
/// page tables each take 9-11 us; one call of 760 tables and 127 threads took 6 ms).
/// Every call makes progress: after stopping the subtree and looking at the thread table
/// it can still kill a thread, and each page-table entry looked at is progress
/// (`AddressSpace::destroy_some`).
pub const KILL_BUDGET: u64 = 1024;
const _: () = assert!(KILL_BUDGET >= 2 * MAX_THREADS as u64 + KILL_COST);
