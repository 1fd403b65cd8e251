//! I/O-port partitioning: each task's permission bitmap (two frames, 65,536 bits, a clear
//! bit grants the port), granted down the task tree with `io_grant` and loaded into the TSS
//! by the entry glue when a thread of another task runs. A task without grants has no
//! bitmap (every port denied, nothing charged).

use crate::mem::PAGE_SIZE;
use crate::rp::Amount;
use crate::state::Kernel;
use crate::table::TaskIdx;
use abi::syscall::Error;

/// Byte `index` of an I/O bitmap frame.
///
/// # Safety
/// `frame` must be a live bitmap frame of a task (allocated by `io_grant`, not yet freed)
/// and `index` < 4096.
#[allow(unsafe_code)] // the bitmap is a raw frame
unsafe fn io_byte(frame: u64, index: usize) -> u8 {
    // SAFETY: the caller's contract; the direct map covers the frame.
    unsafe { *((crate::mem::phys_to_virt(frame) + index as u64) as *const u8) }
}

impl Kernel {
    /// True if `task` may use `port` (the root: every port but the kernel's).
    #[allow(unsafe_code)] // reads the task's bitmap frame
    pub fn holds_port(&self, task: TaskIdx, port: u16) -> bool {
        if task == TaskIdx::ROOT {
            return !abi::syscall::KERNEL_PORTS
                .iter()
                .any(|&(lo, hi)| (lo..=hi).contains(&port));
        }
        let frame = self.tasks[task].io_bitmap[port as usize / 32768];
        frame != 0 && {
            let bit = port as usize % 32768;
            // SAFETY: the task's own bitmap frame (non-zero: allocated), and bit / 8 < 4096.
            (unsafe { io_byte(frame, bit / 8) }) & (1 << (bit % 8)) == 0
        }
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
        if count == 0 || first.checked_add(count).is_none_or(|end| end > 0x1_0000) {
            return Err(Error::InvalidArgument);
        }
        if target == caller || !self.is_within(target, caller) {
            return Err(Error::NotPermitted);
        }
        let ports = first as u16..=(first + count - 1) as u16;
        if !ports.clone().all(|p| self.holds_port(caller, p)) {
            return Err(Error::NotPermitted);
        }
        if self.tasks[target].io_bitmap[0] == 0 {
            self.rps[self.tasks[target].rp].charge(Amount::pages(2))?;
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
                self.rps[self.tasks[target].rp].release(Amount::pages(2));
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
            self.tasks[target].io_bitmap = [a, b];
            self.tasks[target].pages_charged += 2;
        }
        for port in ports {
            let frame = self.tasks[target].io_bitmap[port as usize / 32768];
            let bit = port as usize % 32768;
            let byte = crate::mem::phys_to_virt(frame) + (bit / 8) as u64;
            // SAFETY: inside the task's bitmap frame (bit / 8 < 4096), direct-mapped.
            unsafe { *(byte as *mut u8) &= !(1 << (bit % 8)) };
        }
        if self.io_loaded == self.task_id(target) {
            self.io_loaded = 0;
        }
        Ok(())
    }

    /// Frees `task`'s bitmap frames (when it dies); returns how many there were.
    #[allow(unsafe_code)] // the bitmap frames go back to the allocator
    pub fn release_io_bitmap(&mut self, task: TaskIdx) -> u64 {
        let mut freed = 0;
        for frame in core::mem::take(&mut self.tasks[task].io_bitmap) {
            if frame != 0 {
                // SAFETY: the task's own bitmap frame, allocated by `io_grant`; the task is
                // dying and the TSS stops using it below (`io_loaded`).
                unsafe { crate::mem::free_frame(frame) };
                freed += 1;
            }
        }
        if self.io_loaded == self.task_id(task) {
            self.io_loaded = 0;
        }
        freed
    }
}
