//! Creating a partition from its configuration, in two steps so that restarts reuse what
//! was allocated at start-up: [`Loader::place`] (once) allocates its memory, loads its image
//! and creates its resource partition (kernel-memory quota); [`Loader::instantiate`] (at
//! start and at every restart) creates the task (abilities, MCP), maps the segments with
//! their rights, its data entry read-only at `DATA_BASE`, its memory pool (partitions with
//! the `map` ability: the rest of its `memory`) read-write at `POOL_BASE` and read-execute at
//! `POOL_EXEC_BASE`, a stack holding the start record, grants I/O ports and interrupts, maps
//! the shared-memory segments and creates the first thread (inactive until started) in
//! the partition's time partition, on its CPU (the threads it creates stay there).
//!
//! The [`Loader`] owns everything this needs that changes (the frame allocator and its
//! scratch window) or that only it reads (the placements): one thread owns it at a time,
//! syssw's main thread at start-up and the restart worker (`crate::restart`) after.

use config::binary::{PartitionView, SystemView};
use config::model::{MAX_PARTITIONS, MAX_SEGMENTS as MAX_SHARED};
use root_task::spawn::{SpawnError, Spawner, map_physical_chunked};
use syssw_core::budget::{self, start_budget};
use user_rt::abi::elf::{LoadSegment as Segment, load_segments};
use user_rt::abi::syscall::{
    Error, PageRights, TaskId, ThreadAttribute, ThreadId, USER_END, USER_MIN,
};
use user_rt::partition::StartInfo;
use user_rt::protocol::layout::{
    DATA_BASE, POOL_BASE, POOL_EXEC_BASE, STACK_TOP, shared_address as layout_address,
};
use user_rt::sys;

const PAGE: u64 = 4096;

/// Why a partition could not be created (with the partition's name, printed by the caller).
#[derive(Debug)]
pub enum LoadError {
    NoImage,
    Image(user_rt::abi::elf::ElfError),
    TooBig {
        needed: u64,
        memory: u64,
    },
    KernelMemory {
        needed: u64,
        quota: u64,
    },
    Spawn(SpawnError),
    Kernel(&'static str, Error),
    /// The CPU it is bound to (`cpus`) is not online: the machine has fewer CPUs than the
    /// configuration uses.
    CpuOffline(u8),
    /// Its PCI devices cannot be granted: only this partition stays stopped.
    Devices(crate::devices::DeviceProblem),
}

impl core::fmt::Display for LoadError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NoImage => write!(f, "its image is not in system.img"),
            Self::Image(e) => write!(f, "its image is not loadable: {e}"),
            Self::TooBig { needed, memory } => write!(
                f,
                "image and stack need {} KiB, more than its memory of {} KiB",
                needed / 1024,
                memory / 1024
            ),
            Self::KernelMemory { needed, quota } => write!(
                f,
                "its page tables need {} KiB of kernel memory, more than its quota of {} KiB",
                needed / 1024,
                quota / 1024
            ),
            Self::Spawn(e) => write!(f, "out of memory or addresses: {e:?}"),
            Self::Kernel(call, e) => write!(f, "{call} failed: {e:?}"),
            Self::CpuOffline(cpu) => write!(
                f,
                "CPU {cpu} is not online (thread_set Cpu failed: InvalidArgument); the machine has fewer CPUs than the configuration's `cpus`"
            ),
            Self::Devices(problem) => write!(f, "{problem}"),
        }
    }
}

fn kernel<T>(call: &'static str, r: Result<T, Error>) -> Result<T, LoadError> {
    r.map_err(|e| LoadError::Kernel(call, e))
}

/// Where a partition's memory lies: its frames are syssw's for good, so a restart maps
/// the same frames again (a cold one reloads them from the image first).
pub struct Placement {
    pub rp: u64,
    entry: u64,
    /// The image's loadable segments (their file bytes stay in system.img, for reloads).
    image: [Option<Segment<'static>>; MAX_SEGMENTS],
    /// Physical base of each loaded segment's frames (in `load_segments` order).
    segments: [u64; MAX_SEGMENTS],
    stack: u64,
    /// Its data entry's frames and length in bytes (length 0: none). Mapped read-only, so
    /// never reloaded.
    data: (u64, u64),
    /// Its memory pool's frames and length in bytes (length 0: none).
    pool: (u64, u64),
    /// Bytes of its memory in use (segments + data + stack).
    pub used: u64,
    /// The unmapped page below the stack: a fault there is a stack overflow.
    pub stack_guard: core::ops::Range<u64>,
    /// Its PCI functions, probed and enabled at boot.
    pub devices: Option<crate::devices::Devices>,
}

const MAX_SEGMENTS: usize = budget::MAX_IMAGE_SEGMENTS;

/// A running instance of a partition.
pub struct Instance {
    pub task: TaskId,
    pub thread: ThreadId,
}

/// What creating and re-creating partitions needs; see the module documentation.
pub struct Loader {
    pub system: SystemView<'static>,
    spawner: Spawner,
    placed: [Option<Placement>; MAX_PARTITIONS],
    /// Physical frames of each shared-memory segment (allocated once, in configuration
    /// order).
    shared: [u64; MAX_SHARED],
    /// syssw's server thread (named in every start record).
    server: ThreadId,
    /// Interrupt lines partitions hold: their `irqs` and their devices' lines so far.
    lines: u32,
    /// The task of each partition's newest instance (a killed one's id stays until the
    /// next: the kernel refuses a stale id).
    tasks: [Option<TaskId>; MAX_PARTITIONS],
}

impl Loader {
    /// Takes the spawner syssw allocates everything from and allocates the shared-memory
    /// segments.
    pub fn new(
        mut spawner: Spawner,
        system: SystemView<'static>,
        server: ThreadId,
    ) -> Result<Self, LoadError> {
        let mut shared = [0; MAX_SHARED];
        for (slot, segment) in shared.iter_mut().zip(system.segments()) {
            *slot = spawner
                .frames(segment.size / PAGE)
                .map_err(LoadError::Spawn)?;
        }
        Ok(Loader {
            system,
            spawner,
            placed: [const { None }; MAX_PARTITIONS],
            shared,
            server,
            lines: system.partitions().fold(0, |m, p| m | p.irqs.0),
            tasks: [None; MAX_PARTITIONS],
        })
    }

    /// The spawner, for syssw's own memory and threads at start-up.
    pub fn spawner(&mut self) -> &mut Spawner {
        &mut self.spawner
    }

    /// [`place`]s partition `p` (once, at start-up).
    pub fn place(
        &mut self,
        p: &PartitionView,
        elf: &'static [u8],
        data: &'static [u8],
    ) -> Result<&Placement, LoadError> {
        let devices = crate::devices::prepare(&mut self.spawner, p, &mut self.lines)
            .map_err(LoadError::Devices)?;
        let placement = place(&mut self.spawner, &self.system, p, elf, data)?;
        Ok(self.placed[p.index].insert(Placement {
            devices,
            ..placement
        }))
    }

    /// A new instance of placed partition `index`; see [`instantiate`]. On an error nothing
    /// of the new instance is left.
    pub fn instantiate(
        &mut self,
        index: usize,
        start: Start,
        condition: u64,
    ) -> Result<Instance, LoadError> {
        let p = self.system.partition(index);
        let placed = self.placed[index].as_ref().ok_or(LoadError::NoImage)?;
        let task = kernel(
            "task_create",
            sys::task_create(p.abilities, p.mcp, placed.rp, p.name),
        )?;
        let instance = instantiate(
            &mut self.spawner,
            &self.system,
            &p,
            placed,
            &self.shared,
            self.server,
            task,
            start,
            condition,
        );
        match &instance {
            Ok(_) => self.let_sharers_notify(index, task),
            Err(_) => {
                let _ = sys::task_kill(task);
            }
        }
        instance
    }

    /// Lets the new task of partition `index` and the tasks of the partitions it shares a
    /// memory segment with notify each other's threads: the wake-up beside what they
    /// exchange in the segment (a frame ring's consumer is woken by its producer), and no
    /// more (no message: `task_allow_notify`).
    fn let_sharers_notify(&mut self, index: usize, task: TaskId) {
        self.tasks[index] = Some(task);
        for (other, peer) in self.tasks.iter().enumerate() {
            let Some(peer) = *peer else { continue };
            if !self.system.share_memory(index, other) {
                continue;
            }
            // A peer's stale id (its partition is stopped) is refused: nothing to grant.
            let _ = sys::task_allow_notify(Some(task), Some(peer));
            let _ = sys::task_allow_notify(Some(peer), Some(task));
        }
    }
}

fn shared_address(system: &SystemView, segment: usize) -> u64 {
    layout_address(system.segments().take(segment).map(|s| s.size))
}

fn segment_pages(s: &Segment) -> (u64, u64) {
    budget::segment_pages(s.vaddr, s.mem_size)
}

/// Copies a segment's file bytes into its (zeroed) frames, chunk by chunk.
fn load(spawner: &mut Spawner, s: &Segment, physical: Option<u64>) -> Result<u64, LoadError> {
    let (first, pages) = segment_pages(s);
    let at = s.vaddr - first;
    let fill = |chunk: &mut [u8], offset: u64| {
        // The file bytes that fall into this chunk of the segment's pages.
        let (lo, hi) = (
            offset.max(at),
            (offset + chunk.len() as u64).min(at + s.file.len() as u64),
        );
        if lo < hi {
            chunk[(lo - offset) as usize..(hi - offset) as usize]
                .copy_from_slice(&s.file[(lo - at) as usize..(hi - at) as usize]);
        }
    };
    match physical {
        None => spawner.filled_frames(pages, fill),
        Some(frames) => spawner.refill_frames(frames, pages, fill).map(|()| frames),
    }
    .map_err(LoadError::Spawn)
}

/// Allocates a partition's memory (zeroed), loads its image and creates its resource
/// partition: everything a partition owns that outlives its restarts.
fn place(
    spawner: &mut Spawner,
    system: &SystemView,
    p: &PartitionView,
    elf: &'static [u8],
    data: &'static [u8],
) -> Result<Placement, LoadError> {
    let (entry, segments) =
        load_segments::<MAX_SEGMENTS>(elf, USER_MIN..DATA_BASE).map_err(LoadError::Image)?;
    // The same budget `cargo xtask` checked when it built the image.
    let budget = start_budget(system, p, elf, data.len() as u64).map_err(LoadError::Image)?;
    if budget.memory > p.memory {
        return Err(LoadError::TooBig {
            needed: budget.memory,
            memory: p.memory,
        });
    }
    if budget.kernel_memory > p.kernel_memory {
        return Err(LoadError::KernelMemory {
            needed: budget.kernel_memory,
            quota: p.kernel_memory,
        });
    }
    let stack_pages = p.stack / PAGE;
    let data_pages = (data.len() as u64).div_ceil(PAGE);
    let rp = kernel(
        "rp_create",
        sys::rp_create(
            p.kernel_tasks as u16,
            p.kernel_threads as u16,
            p.kernel_memory / PAGE,
            p.cpus,
        ),
    )?;
    let mut frames = [0u64; MAX_SEGMENTS];
    for (slot, s) in frames.iter_mut().zip(segments.iter().flatten()) {
        *slot = load(spawner, s, None)?;
    }
    let stack = spawner.frames(stack_pages).map_err(LoadError::Spawn)?;
    let stack_base = STACK_TOP - stack_pages * PAGE;
    let data_frames = if data.is_empty() {
        0
    } else {
        spawner
            .filled_frames(data_pages, |chunk, offset| {
                let from = (offset as usize).min(data.len());
                let to = (from + chunk.len()).min(data.len());
                chunk[..to - from].copy_from_slice(&data[from..to]);
            })
            .map_err(LoadError::Spawn)?
    };
    let pool_frames = if budget.pool == 0 {
        0
    } else {
        spawner
            .frames(budget.pool / PAGE)
            .map_err(LoadError::Spawn)?
    };
    Ok(Placement {
        rp,
        entry,
        image: segments,
        segments: frames,
        stack,
        data: (data_frames, data.len() as u64),
        pool: (pool_frames, budget.pool),
        used: budget.memory,
        stack_guard: stack_base - PAGE..stack_base,
        devices: None,
    })
}

/// How an instance starts: at boot, or restarted (cold: memory reloaded from the image;
/// warm: memory kept as it is).
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Start {
    Boot,
    Cold,
    Warm,
}

/// Fills a partition's new task with its memory, grants and first thread (inactive), for
/// the start condition `condition` (ARINC START_CONDITION, passed in the start record).
#[allow(clippy::too_many_arguments)]
fn instantiate(
    spawner: &mut Spawner,
    system: &SystemView,
    p: &PartitionView,
    placed: &Placement,
    shared: &[u64],
    server: ThreadId,
    task: TaskId,
    start: Start,
    condition: u64,
) -> Result<Instance, LoadError> {
    for (s, &frames) in placed.image.iter().flatten().zip(&placed.segments) {
        if start == Start::Cold {
            load(spawner, s, Some(frames))?;
        }
        let (first, pages) = segment_pages(s);
        map_physical_chunked(Some(task), frames, first, pages, s.rights)
            .map_err(LoadError::Spawn)?;
    }

    // The stack, zeroed, with the start record at its top.
    let info = StartInfo::new(
        p.index as u64,
        p.time_partition as u64,
        server.0,
        condition,
        p.mcp,
        p.priority,
        p.name,
        placed.data.1,
        placed.pool.1,
    );
    let record = info.to_bytes();
    let record_len = record.len() as u64;
    let stack_pages = p.stack / PAGE;
    spawner
        .refill_frames(placed.stack, stack_pages, |chunk, offset| {
            let at = stack_pages * PAGE - record_len;
            if offset <= at && at + record_len <= offset + chunk.len() as u64 {
                let from = (at - offset) as usize;
                chunk[from..from + record.len()].copy_from_slice(&record);
            }
        })
        .map_err(LoadError::Spawn)?;
    map_physical_chunked(
        Some(task),
        placed.stack,
        placed.stack_guard.end,
        stack_pages,
        PageRights::WRITE,
    )
    .map_err(LoadError::Spawn)?;

    let (data_frames, data_len) = placed.data;
    if data_len > 0 {
        map_physical_chunked(
            Some(task),
            data_frames,
            DATA_BASE,
            data_len.div_ceil(PAGE),
            PageRights::empty(),
        )
        .map_err(LoadError::Spawn)?;
    }

    let (pool_frames, pool_len) = placed.pool;
    if pool_len > 0 {
        let pages = pool_len / PAGE;
        // Zeroed at boot by `frames`; a cold restart must not see the last instance's data.
        if start == Start::Cold {
            spawner
                .refill_frames(pool_frames, pages, |_, _| ())
                .map_err(LoadError::Spawn)?;
        }
        map_physical_chunked(Some(task), pool_frames, POOL_BASE, pages, PageRights::WRITE)
            .map_err(LoadError::Spawn)?;
        map_physical_chunked(
            Some(task),
            pool_frames,
            POOL_EXEC_BASE,
            pages,
            PageRights::EXECUTE,
        )
        .map_err(LoadError::Spawn)?;
    }

    for range in p.io_ports() {
        kernel("io_grant", sys::io_grant(task, range.first, range.count()))?;
    }
    for line in p.irqs.lines() {
        kernel("irq_grant", sys::irq_grant(task, line as u64))?;
    }
    if let Some(devices) = &placed.devices {
        if start == Start::Cold {
            crate::devices::clear_dma(spawner, devices).map_err(LoadError::Devices)?;
        }
        crate::devices::grant(devices, task).map_err(LoadError::Devices)?;
    }
    for a in p.shared() {
        let size = system.segment(a.segment).size;
        map_physical_chunked(
            Some(task),
            shared[a.segment],
            shared_address(system, a.segment),
            size / PAGE,
            a.rights.page_rights(),
        )
        .map_err(LoadError::Spawn)?;
    }

    let start_record = STACK_TOP - record_len;
    // 16-byte aligned below the record, minus 8 as if called.
    let sp = (start_record & !15) - 8;
    debug_assert!(sp < USER_END);
    let thread = kernel(
        "thread_create",
        sys::thread_create(Some(task), placed.entry, sp, p.priority, start_record),
    )?;
    kernel(
        "thread_set TimePartition",
        sys::thread_set(
            Some(thread),
            ThreadAttribute::TimePartition,
            p.time_partition as u64,
        ),
    )?;
    // Its first CPU, the last one it is moved to: the threads it creates start there too
    // (a new thread runs on its creator's). Each of its CPUs must be online.
    for cpu in (0..8u8).rev().filter(|c| p.cpus & 1 << c != 0) {
        sys::thread_set(Some(thread), ThreadAttribute::Cpu, cpu.into()).map_err(|e| match e {
            Error::InvalidArgument => LoadError::CpuOffline(cpu),
            e => LoadError::Kernel("thread_set Cpu", e),
        })?;
    }
    Ok(Instance { task, thread })
}
