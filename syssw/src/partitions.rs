//! Creating a partition from its configuration: resource partition (kernel-memory quota),
//! task (abilities, MCP), the image's segments in fresh zeroed memory with their rights, a
//! stack holding the start record, I/O-port and interrupt grants, shared-memory segments,
//! and the first thread (inactive until the schedule is installed).

use config::binary::{PartitionView, SystemView};
use user_rt::abi::elf::load_segments;
use user_rt::abi::syscall::{
    Error, PageRights, TaskId, ThreadAttribute, ThreadId, USER_END, USER_MIN,
};
use user_rt::partition::StartInfo;
use user_rt::spawn::{SpawnError, Spawner, map_physical_chunked};
use user_rt::sys;

const PAGE: u64 = 4096;
/// Top of a partition's stack (its start record is at the very top).
pub const STACK_TOP: u64 = 0x0000_7ff0_0000_0000;
/// Where shared-memory segments appear, in configuration order (same address everywhere).
pub const SHARED_BASE: u64 = 0x0000_6000_0000_0000;

/// Why a partition could not be created (with the partition's name, printed by the caller).
#[derive(Debug)]
pub enum LoadError {
    NoImage,
    Image(user_rt::abi::elf::ElfError),
    TooBig { needed: u64, memory: u64 },
    Spawn(SpawnError),
    Kernel(&'static str, Error),
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
            Self::Spawn(e) => write!(f, "out of memory or addresses: {e:?}"),
            Self::Kernel(call, e) => write!(f, "{call} failed: {e:?}"),
        }
    }
}

fn kernel<T>(call: &'static str, r: Result<T, Error>) -> Result<T, LoadError> {
    r.map_err(|e| LoadError::Kernel(call, e))
}

/// A created partition.
pub struct Partition {
    pub task: TaskId,
    pub thread: ThreadId,
    /// Bytes of its memory in use (segments + stack).
    pub used: u64,
}

/// Physical frames of each shared-memory segment (allocated once, in configuration order).
pub fn shared_segments(
    spawner: &mut Spawner,
    system: &SystemView,
    out: &mut [u64],
) -> Result<(), LoadError> {
    for (slot, segment) in out.iter_mut().zip(system.segments()) {
        *slot = spawner
            .frames(segment.size / PAGE)
            .map_err(LoadError::Spawn)?;
    }
    Ok(())
}

fn shared_address(system: &SystemView, segment: usize) -> u64 {
    // Each segment gets its size rounded to 1 GiB plus a guard, so addresses never move.
    SHARED_BASE
        + system
            .segments()
            .take(segment)
            .map(|s| (s.size >> 30) + 1)
            .sum::<u64>()
            * (2 << 30)
}

pub fn create(
    spawner: &mut Spawner,
    system: &SystemView,
    p: &PartitionView,
    elf: &[u8],
    shared: &[u64],
    server: ThreadId,
) -> Result<Partition, LoadError> {
    let (entry, segments) =
        load_segments::<16>(elf, USER_MIN..SHARED_BASE).map_err(LoadError::Image)?;
    let image_pages: u64 = segments
        .iter()
        .flatten()
        .map(|s| (s.vaddr + s.mem_size).div_ceil(PAGE) - s.vaddr / PAGE)
        .sum();
    let stack_pages = p.stack / PAGE;
    let needed = (image_pages + stack_pages) * PAGE;
    if needed > p.memory {
        return Err(LoadError::TooBig {
            needed,
            memory: p.memory,
        });
    }
    let rp = kernel(
        "rp_create",
        sys::rp_create(
            p.kernel_tasks as u16,
            p.kernel_threads as u16,
            p.kernel_memory / PAGE,
        ),
    )?;
    let task = kernel(
        "task_create",
        sys::task_create(p.abilities, p.mcp, rp, p.name),
    )?;
    for s in segments.iter().flatten() {
        let first = s.vaddr / PAGE * PAGE;
        let pages = (s.vaddr + s.mem_size).div_ceil(PAGE) - first / PAGE;
        let at = s.vaddr - first;
        let frames = spawner
            .filled_frames(pages, |chunk, offset| {
                // The file bytes that fall into this chunk of the segment's pages.
                let (lo, hi) = (
                    offset.max(at),
                    (offset + chunk.len() as u64).min(at + s.file.len() as u64),
                );
                if lo < hi {
                    chunk[(lo - offset) as usize..(hi - offset) as usize]
                        .copy_from_slice(&s.file[(lo - at) as usize..(hi - at) as usize]);
                }
            })
            .map_err(LoadError::Spawn)?;
        map_physical_chunked(Some(task), frames, first, pages, s.rights)
            .map_err(LoadError::Spawn)?;
    }

    // The stack, with the start record at its top.
    let info = StartInfo::new(p.index as u64, p.time_partition as u64, server.0, 0, p.name);
    let record = info.to_bytes();
    let record_len = record.len() as u64;
    let stack = spawner
        .filled_frames(stack_pages, |chunk, offset| {
            let at = stack_pages * PAGE - record_len;
            if offset <= at && at + record_len <= offset + chunk.len() as u64 {
                let from = (at - offset) as usize;
                chunk[from..from + record.len()].copy_from_slice(&record);
            }
        })
        .map_err(LoadError::Spawn)?;
    let stack_base = STACK_TOP - stack_pages * PAGE;
    map_physical_chunked(
        Some(task),
        stack,
        stack_base,
        stack_pages,
        PageRights::WRITE,
    )
    .map_err(LoadError::Spawn)?;

    for range in p.io_ports() {
        kernel("io_grant", sys::io_grant(task, range.first, range.count()))?;
    }
    for line in p.irqs.lines() {
        kernel("irq_grant", sys::irq_grant(task, line as u64))?;
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
        sys::thread_create(Some(task), entry, sp, p.priority, start_record),
    )?;
    kernel(
        "thread_set TimePartition",
        sys::thread_set(
            Some(thread),
            ThreadAttribute::TimePartition,
            p.time_partition as u64,
        ),
    )?;
    Ok(Partition {
        task,
        thread,
        used: needed,
    })
}
