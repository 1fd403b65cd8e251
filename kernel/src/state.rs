//! The kernel's state: one [`Kernel`] value holding every object in fixed tables (no heap),
//! its construction, the choice of the next thread, and the address-space changes (map,
//! unmap, protect). The operations on each kind of object live with it: tasks and
//! abilities in `task.rs`, threads, their states and time-outs in `thread.rs`, resource
//! partitions in `rp.rs`, I/O-port bitmaps in `io.rs`, windows and CPU accounting in
//! `timepart.rs`, send queues in `ipc.rs`.
//!
//! None of it touches hardware directly: the entry glue (`arch::entry`) saves the
//! interrupted thread's registers into its [`Thread`], calls in here, and loads whichever
//! thread [`Kernel::choose`] names. That keeps every decision host-testable.

use crate::mem::PAGE_SIZE;
use crate::mem::paging::is_user_range;
use crate::rp::ResourcePartition;
use crate::sched::{RunQueues, TIME_PARTITIONS};
use crate::table::{RpIdx, Slot, Table, TaskIdx, ThreadIdx};
use crate::task::Task;
use crate::thread::{NEVER, Thread};
use crate::timepart::TimeTable;
use abi::root::{PhysRegion, ROOT_INFO_MAX_REGIONS};
use abi::syscall::{Error, MAP_MAX_PAGES, PageRights, TaskId, ThreadId};

/// The slot an object identifier names, if that slot holds a live object (`live` gives its
/// generation) of the identifier's generation: a stale id never names a successor.
pub(crate) fn slot_of<S: Slot, T, const N: usize>(
    table: &Table<S, T, N>,
    id: u64,
    live: impl Fn(&T) -> Option<u16>,
) -> Result<S, Error> {
    let (index, generation) = abi::syscall::split_id(id).ok_or(Error::NoSuchObject)?;
    let slot = table.slot(index).ok_or(Error::NoSuchObject)?;
    (live(&table[slot]) == Some(generation))
        .then_some(slot)
        .ok_or(Error::NoSuchObject)
}

pub const MAX_THREADS: usize = 256;
pub const MAX_TASKS: usize = 64;
pub const MAX_RPS: usize = 16;

/// User code and stack selectors (GDT layout, see `arch::gdt`), RPL 3.
pub const USER_CS: u64 = 0x23;
pub const USER_SS: u64 = 0x1b;
/// RFLAGS of user threads: IF and the reserved bit 1.
pub const USER_RFLAGS: u64 = 0x202;

/// Where a map takes its frames from.
#[derive(Clone, Copy, Debug)]
pub enum Source {
    /// Pages of the caller's address space.
    Virtual(u64),
    /// Physical memory handed to the root task.
    Physical(u64),
    /// A device's registers ([`crate::mem::is_device_memory`]), mapped uncached.
    Device(u64),
}

pub struct Kernel {
    pub(crate) threads: Table<ThreadIdx, Thread, MAX_THREADS>,
    pub(crate) tasks: Table<TaskIdx, Task, MAX_TASKS>,
    pub(crate) rps: Table<RpIdx, ResourcePartition, MAX_RPS>,
    pub(crate) run: RunQueues<MAX_THREADS>,
    /// The thread whose registers and FPU state are loaded (or were, before idling).
    pub(crate) current: Option<ThreadIdx>,
    /// The active window's time partition (none until a schedule exists).
    pub(crate) active_partition: Option<u8>,
    /// The root task's health monitor ([`ThreadId::OWN`] = none).
    pub(crate) health_monitor: ThreadId,
    /// Physical memory the root task may map.
    pub(crate) user_memory: [PhysRegion; ROOT_INFO_MAX_REGIONS],
    pub(crate) user_memory_count: usize,
    /// Earliest deadline of any blocked thread (maybe stale-early after a wake-up).
    pub(crate) next_deadline: u64,
    /// Set when `next_deadline` moved earlier and the timer must be reprogrammed.
    pub(crate) timer_dirty: bool,
    /// The running thread's FS/GS base changed and must be reloaded on exit.
    pub(crate) reload_bases: bool,
    /// Schedules of time windows.
    pub(crate) time: TimeTable,
    /// Absolute time of the next window boundary (`NEVER` without a schedule).
    pub(crate) next_boundary: u64,
    /// CPU time per time partition and time with nothing to run, in TSC ticks.
    pub(crate) cpu_ticks: [u64; TIME_PARTITIONS],
    pub(crate) idle_ticks: u64,
    /// Time partition of the thread that ran since `last_account` (None: idle).
    pub(crate) running_partition: Option<u8>,
    pub(crate) last_account: u64,
    /// The task whose I/O bitmap is in the TSS ([`TaskId::OWN`]: ports disabled).
    pub(crate) io_loaded: TaskId,
    /// Interrupt lines attached to threads.
    pub(crate) irqs: crate::irq::Irqs,
    /// The IOMMU, when the machine has one the kernel programs (translation on).
    pub(crate) dma: Option<Dma>,
}

/// Functions a remapping unit's device scopes may name (more count as not covered).
pub const DMA_ENDPOINTS: usize = abi::machine::MAX_DMA_ENDPOINTS;

/// The DMA remapping unit and its tables.
pub struct Dma {
    pub unit: crate::arch::vtd::Vtd,
    pub tables: crate::mem::iommu::DmaTables,
    /// The functions the unit translates: all, or those of `endpoints` (routing ids).
    pub all: bool,
    pub endpoints: [Option<u16>; DMA_ENDPOINTS],
}

impl Dma {
    pub fn covers(&self, source: u16) -> bool {
        self.all || self.endpoints.contains(&Some(source))
    }
}

impl Default for Kernel {
    fn default() -> Self {
        Self::new()
    }
}

impl Kernel {
    pub const fn new() -> Self {
        Self {
            threads: Table::new([Thread::FREE; MAX_THREADS]),
            tasks: Table::new([Task::FREE; MAX_TASKS]),
            rps: Table::new([ResourcePartition::FREE; MAX_RPS]),
            run: RunQueues::new(),
            current: None,
            active_partition: None,
            health_monitor: ThreadId::OWN,
            user_memory: [PhysRegion { start: 0, pages: 0 }; ROOT_INFO_MAX_REGIONS],
            user_memory_count: 0,
            next_deadline: NEVER,
            timer_dirty: false,
            reload_bases: false,
            time: TimeTable::new(),
            next_boundary: NEVER,
            cpu_ticks: [0; TIME_PARTITIONS],
            idle_ticks: 0,
            running_partition: None,
            last_account: 0,
            io_loaded: TaskId::OWN,
            irqs: crate::irq::Irqs::new(),
            dma: None,
        }
    }

    /// The thread to run next.
    pub fn choose(&self) -> Option<ThreadIdx> {
        self.run.choose(self.active_partition).map(ThreadIdx::at)
    }

    /// True if the physical range was handed to the root task at boot.
    pub fn is_user_memory(&self, start: u64, pages: u64) -> bool {
        abi::root::regions_contain(&self.user_memory[..self.user_memory_count], start, pages)
    }

    /// Maps `pages` pages from `source` into `target` at `destination`. All-or-nothing:
    /// everything is checked and the page tables are charged before anything changes.
    pub fn map(
        &mut self,
        caller: TaskIdx,
        target: TaskIdx,
        source: Source,
        destination: u64,
        pages: u64,
        rights: PageRights,
    ) -> Result<(), Error> {
        if pages == 0 || pages > MAP_MAX_PAGES || !is_user_range(destination, pages) {
            return Err(Error::InvalidArgument);
        }
        let frame_of = |k: &Self, i: u64| -> Result<u64, Error> {
            match source {
                Source::Virtual(base) => {
                    match k.tasks[caller].space().translate(base + i * PAGE_SIZE) {
                        Some((frame, have)) if have.contains(rights) => Ok(frame),
                        _ => Err(Error::BadAddress),
                    }
                }
                Source::Physical(base) | Source::Device(base) => Ok(base + i * PAGE_SIZE),
            }
        };
        match source {
            Source::Virtual(base) if !is_user_range(base, pages) => {
                return Err(Error::InvalidArgument);
            }
            Source::Physical(base) | Source::Device(base) if base % PAGE_SIZE != 0 => {
                return Err(Error::InvalidArgument);
            }
            Source::Physical(base) if !self.is_user_memory(base, pages) => {
                return Err(Error::BadAddress);
            }
            Source::Device(base) if !crate::mem::is_device_memory(base, pages) => {
                return Err(Error::BadAddress);
            }
            _ => {}
        }
        for i in 0..pages {
            frame_of(self, i)?;
        }
        self.charge_tables(target, destination, pages)?;
        for i in 0..pages {
            let (frame, at) = (frame_of(self, i)?, destination + i * PAGE_SIZE);
            let task = &mut self.tasks[target];
            match source {
                Source::Device(_) => task.map_device_page(at, frame, rights),
                _ => task.map_page(at, frame, rights),
            }
            .expect("checked and charged");
        }
        Ok(())
    }

    /// Charges the page tables a map of `pages` at `at` in `task` will need (`AlreadyMapped`
    /// if one of the pages is).
    pub fn charge_tables(&mut self, task: TaskIdx, at: u64, pages: u64) -> Result<(), Error> {
        let space = self.tasks[task].space();
        let needed = space.tables_needed(at, pages).ok_or(Error::AlreadyMapped)?;
        if needed > crate::mem::free_frames() {
            // Cannot happen while quotas stay within the reserved pool; refuse anyway.
            return Err(Error::OutOfResources);
        }
        self.charge_pages(task, needed)
    }

    pub fn unmap(&mut self, target: TaskIdx, address: u64, pages: u64) -> Result<(), Error> {
        if pages == 0 || pages > MAP_MAX_PAGES || !is_user_range(address, pages) {
            return Err(Error::InvalidArgument);
        }
        for i in 0..pages {
            self.tasks[target].unmap_page(address + i * PAGE_SIZE);
        }
        Ok(())
    }

    pub fn protect(
        &mut self,
        target: TaskIdx,
        address: u64,
        pages: u64,
        rights: PageRights,
    ) -> Result<(), Error> {
        if pages == 0 || pages > MAP_MAX_PAGES || !is_user_range(address, pages) {
            return Err(Error::InvalidArgument);
        }
        let space = *self.tasks[target].space();
        for i in 0..pages {
            match space.translate(address + i * PAGE_SIZE) {
                Some((_, have)) if have.contains(rights) => {}
                _ => return Err(Error::BadAddress),
            }
        }
        for i in 0..pages {
            self.tasks[target].set_page_rights(address + i * PAGE_SIZE, rights);
        }
        Ok(())
    }
}
