//! I/O-port partitioning: each task's permission bitmap (two frames, 65,536 bits, a clear
//! bit grants the port), granted down the task tree with `io_grant` and loaded into the TSS
//! by the entry glue when a thread of another task runs. A task without grants has no
//! bitmap (every port denied, nothing charged).

use crate::mem::PAGE_SIZE;
use crate::state::Kernel;
use crate::table::TaskIdx;
use abi::syscall::{Error, TaskId};

/// What a CPU's `io_loaded` says when its TSS holds a bitmap that is no longer any task's
/// (no task has this id: it is not a valid id).
pub const IO_STALE: TaskId = TaskId(u64::MAX);

/// The words of an I/O bitmap (two frames of 512 words, 64 ports a word, a clear bit
/// grants the port) that hold ports `first..end` (`end` <= 0x10000): for each frame, the
/// index of its first and last such word and the ports' bits in those two. Ports are
/// checked and granted a word at a time, whole words in a plain loop: a grant of the whole
/// port space looks at 1,024 words.
fn words(first: u64, end: u64) -> impl Iterator<Item = (usize, usize, usize, u64, u64)> {
    (0..2).filter_map(move |half| {
        let base = half as u64 * 32768;
        let (lo, hi) = (first.max(base), end.min(base + 32768));
        (lo < hi).then(|| {
            let (a, b) = (lo - base, hi - 1 - base);
            let first_mask = u64::MAX << (a % 64);
            let last_mask = u64::MAX >> (63 - b % 64);
            (
                half,
                (a / 64) as usize,
                (b / 64) as usize,
                first_mask,
                last_mask,
            )
        })
    })
}

/// Frame `frame` of an I/O bitmap as its 512 words.
///
/// # Safety
/// `frame` must be a task's live bitmap frame (allocated by `io_grant`, not yet freed), and
/// no other reference into it may live while this one does.
#[allow(unsafe_code)] // the bitmap is a raw frame
unsafe fn bitmap_words(frame: u64) -> &'static mut [u64; 512] {
    // SAFETY: the caller's contract; the direct map covers the frame.
    unsafe { &mut *(crate::mem::phys_to_virt(frame) as *mut [u64; 512]) }
}

impl Kernel {
    /// True if `task` may use every port of `first..end` (the root: every port but the
    /// kernel's).
    #[allow(unsafe_code)] // reads the task's bitmap frames
    pub fn holds_ports(&self, task: TaskIdx, first: u64, end: u64) -> bool {
        if task == TaskIdx::ROOT {
            return !abi::syscall::KERNEL_PORTS
                .iter()
                .any(|&(lo, hi)| first <= u64::from(hi) && u64::from(lo) < end);
        }
        let bitmap = self.tasks[task].io_bitmap();
        bitmap[0] != 0
            && words(first, end).all(|(half, a, b, first_mask, last_mask)| {
                // SAFETY: the task's own bitmap frame (non-zero: allocated), read only here.
                let w = unsafe { bitmap_words(bitmap[half]) };
                let (head, tail) = if a == b {
                    (first_mask & last_mask, 0)
                } else {
                    (first_mask, last_mask)
                };
                w[a] & head == 0
                    && w[b] & tail == 0
                    && w[a + 1..b.max(a + 1)].iter().all(|&x| x == 0)
            })
    }

    /// Grants ports `first..first + count` of `caller` to the descendant `target`.
    #[allow(unsafe_code)] // the bitmap is a raw frame
    pub fn io_grant(
        &mut self,
        caller: TaskIdx,
        target: TaskIdx,
        first: u64,
        count: u64,
    ) -> Result<(), Error> {
        let end = first
            .checked_add(count)
            .filter(|&e| count > 0 && e <= 0x1_0000);
        let end = end.ok_or(Error::InvalidArgument)?;
        if target == caller || !self.is_within(target, caller) {
            return Err(Error::NotPermitted);
        }
        if !self.holds_ports(caller, first, end) {
            return Err(Error::NotPermitted);
        }
        if self.tasks[target].io_bitmap()[0] == 0 {
            self.charge_pages(target, 2)?;
            let frames = [
                crate::mem::alloc_zeroed_frame(),
                crate::mem::alloc_zeroed_frame(),
            ];
            let [Some(a), Some(b)] = frames else {
                // Cannot happen within the reserved pool; undo and refuse.
                for frame in frames.into_iter().flatten() {
                    // SAFETY: just allocated above and referenced nowhere.
                    unsafe { crate::mem::free_frame(frame) };
                }
                self.release_pages(target, 2);
                return Err(Error::OutOfResources);
            };
            for frame in [a, b] {
                // SAFETY: a fresh frame, direct-mapped, 4 KiB: "every port denied".
                unsafe {
                    core::ptr::write_bytes(
                        crate::mem::phys_to_virt(frame) as *mut u8,
                        0xff,
                        PAGE_SIZE as usize,
                    )
                };
            }
            self.tasks[target].set_io_bitmap([a, b]);
        }
        let bitmap = self.tasks[target].io_bitmap();
        for (half, a, b, first_mask, last_mask) in words(first, end) {
            // SAFETY: the target's bitmap frame (allocated above if it had none), only
            // written through this reference.
            let w = unsafe { bitmap_words(bitmap[half]) };
            w[a + 1..b.max(a + 1)].fill(0);
            w[a] &= !first_mask | if a == b { !last_mask } else { 0 };
            w[b] &= !last_mask | if a == b { !first_mask } else { 0 };
        }
        self.forget_io_bitmap(target);
        Ok(())
    }

    /// Frees `task`'s bitmap frames (when it dies); returns how many there were.
    #[allow(unsafe_code)] // the bitmap frames go back to the allocator
    pub fn release_io_bitmap(&mut self, task: TaskIdx) -> u64 {
        let mut freed = 0;
        for frame in self.tasks[task].take_io_bitmap() {
            if frame != 0 {
                // SAFETY: the task's own bitmap frame, allocated by `io_grant`; the task is
                // dying and the TSS stops using it below (`io_loaded`).
                unsafe { crate::mem::free_frame(frame) };
                freed += 1;
            }
        }
        self.forget_io_bitmap(task);
        freed
    }

    /// Every CPU whose TSS holds `task`'s bitmap must load a bitmap again before a thread
    /// runs there (its own, changed, or none: [`IO_STALE`] is no task's, and a task without
    /// ports then gets "no port" loaded, not the stale bitmap).
    fn forget_io_bitmap(&mut self, task: TaskIdx) {
        let id = self.task_id(task);
        for core in self.cores.iter_mut().filter(|c| c.io_loaded == id) {
            core.io_loaded = IO_STALE;
        }
    }
}
