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
use crate::sched::{CPUS, RunQueues, TIME_PARTITIONS};
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
    /// What each CPU runs and where its schedule stands; `cpu` names the one whose entry
    /// holds the lock ([`Kernel::core`]).
    pub(crate) cores: [Core; CPUS],
    /// The CPU that entered the kernel (set whenever the lock is taken).
    pub(crate) cpu: usize,
    /// CPUs online (the boot CPU and the application processors that came up).
    pub(crate) online: usize,
    /// The root task's health monitor ([`ThreadId::OWN`] = none).
    pub(crate) health_monitor: ThreadId,
    /// Physical memory the root task may map.
    pub(crate) user_memory: [PhysRegion; ROOT_INFO_MAX_REGIONS],
    pub(crate) user_memory_count: usize,
    /// Schedules of time windows.
    pub(crate) time: TimeTable,
    /// CPU time per time partition (all CPUs), in TSC ticks.
    pub(crate) cpu_ticks: [u64; TIME_PARTITIONS],
    /// Interrupt lines attached to threads.
    pub(crate) irqs: crate::irq::Irqs,
    /// The IOMMU, when the machine has one the kernel programs (translation on).
    pub(crate) dma: Option<Dma>,
}

/// One CPU's part of the kernel state.
#[derive(Clone, Copy, Debug)]
pub struct Core {
    /// The thread whose FPU state the CPU's registers hold: the one it runs or ran until
    /// this kernel entry (None while it idles); its slot is not reused while it is
    /// ([`Kernel::free_thread_slot`]).
    pub current: Option<ThreadIdx>,
    /// The thread the CPU runs (None: it idles).
    pub running: Option<ThreadIdx>,
    /// Its active window's time partition (none until a schedule exists).
    pub active_partition: Option<u8>,
    /// Absolute time of its next window boundary (`NEVER` without a schedule).
    pub next_boundary: u64,
    /// Earliest deadline of a blocked thread on it (maybe stale-early after a wake-up).
    pub next_deadline: u64,
    /// Its timer must be programmed again before it runs on.
    pub timer_dirty: bool,
    /// Its running thread's FS/GS base changed and must be reloaded.
    pub reload_bases: bool,
    /// Time partition of the thread that ran since `last_account` (None: idle).
    pub running_partition: Option<u8>,
    pub last_account: u64,
    /// Its time with nothing to run, in TSC ticks.
    pub idle_ticks: u64,
    /// The task whose I/O bitmap is in its TSS ([`TaskId::OWN`]: ports disabled).
    pub io_loaded: TaskId,
    /// An interrupt was sent to make it look at its state again, not taken yet.
    pub kicked: bool,
}

impl Core {
    pub const IDLE: Core = Core {
        current: None,
        running: None,
        active_partition: None,
        next_boundary: NEVER,
        next_deadline: NEVER,
        timer_dirty: false,
        reload_bases: false,
        running_partition: None,
        last_account: 0,
        idle_ticks: 0,
        io_loaded: TaskId::OWN,
        kicked: false,
    };
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
            cores: [Core::IDLE; CPUS],
            cpu: 0,
            online: 1,
            health_monitor: ThreadId::OWN,
            user_memory: [PhysRegion { start: 0, pages: 0 }; ROOT_INFO_MAX_REGIONS],
            user_memory_count: 0,
            time: TimeTable::new(),
            cpu_ticks: [0; TIME_PARTITIONS],
            irqs: crate::irq::Irqs::new(),
            dma: None,
        }
    }

    /// The state of the CPU that entered the kernel.
    pub fn core(&self) -> &Core {
        &self.cores[self.cpu]
    }

    pub fn core_mut(&mut self) -> &mut Core {
        &mut self.cores[self.cpu]
    }

    /// The thread to run next on `cpu`.
    pub fn choose_on(&self, cpu: usize) -> Option<ThreadIdx> {
        let active = self.cores[cpu].active_partition;
        self.run.choose(cpu, active).map(ThreadIdx::at)
    }

    /// The thread to run next on the CPU that entered the kernel.
    pub fn choose(&self) -> Option<ThreadIdx> {
        self.choose_on(self.cpu)
    }

    /// The other CPUs that must look at their state again: the thread they should run is
    /// not the one they run, or their timer or running thread's bases changed. Each is
    /// marked kicked (it clears the mark when it enters the kernel), so an interrupt is
    /// sent to it once.
    pub fn cpus_to_kick(&mut self) -> u64 {
        let mut kick = 0;
        for cpu in (0..self.online).filter(|&c| c != self.cpu) {
            let chosen = self.choose_on(cpu);
            let core = &mut self.cores[cpu];
            let stale = chosen != core.running || core.timer_dirty || core.reload_bases;
            if stale && !core.kicked {
                core.kicked = true;
                kick |= 1 << cpu;
            }
        }
        kick
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
        crate::arch::smp::release_space(self.tasks[target].space().root(), false);
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
        crate::arch::smp::release_space(self.tasks[target].space().root(), false);
        Ok(())
    }
}
