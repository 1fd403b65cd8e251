//! The bounded kernel heap, usable only while booting.
//!
//! Boot code may use `alloc` (e.g. to collect ACPI tables); once [`BootHeap::seal`] runs,
//! any further allocation is a kernel bug and panics, so the kernel provably allocates
//! nothing on its run-time paths. Freeing stays allowed.

use core::alloc::{GlobalAlloc, Layout};
use core::ptr::NonNull;
use core::sync::atomic::{AtomicBool, Ordering};
use linked_list_allocator::Heap;
use spin::Mutex;

pub const BOOT_HEAP_SIZE: usize = 256 * 1024;

#[repr(C, align(4096))]
struct Storage([u8; BOOT_HEAP_SIZE]);

static mut STORAGE: Storage = Storage([0; BOOT_HEAP_SIZE]);

pub struct BootHeap {
    heap: Mutex<Heap>,
    sealed: AtomicBool,
}

impl Default for BootHeap {
    fn default() -> Self {
        Self::new()
    }
}

impl BootHeap {
    pub const fn new() -> Self {
        Self {
            heap: Mutex::new(Heap::empty()),
            sealed: AtomicBool::new(false),
        }
    }

    /// Hands the static storage to the allocator. Called once, first thing at boot.
    pub fn init(&self) {
        let mut heap = self.heap.lock();
        if heap.size() == 0 {
            let storage = core::ptr::addr_of_mut!(STORAGE) as *mut u8;
            // SAFETY: STORAGE is used by nothing else; this runs once (size() == 0 guard).
            unsafe { heap.init(storage, BOOT_HEAP_SIZE) };
        }
    }

    /// Ends the boot phase: from now on allocating panics.
    pub fn seal(&self) {
        self.sealed.store(true, Ordering::SeqCst);
    }

    pub fn used(&self) -> usize {
        self.heap.lock().used()
    }
}

// SAFETY: allocation and deallocation go through the locked linked-list heap, which returns
// blocks of at least the requested size and alignment or null.
unsafe impl GlobalAlloc for BootHeap {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if self.sealed.load(Ordering::Relaxed) {
            panic!(
                "kernel heap allocation of {} bytes after boot",
                layout.size()
            );
        }
        self.heap
            .lock()
            .allocate_first_fit(layout)
            .map_or(core::ptr::null_mut(), |p| p.as_ptr())
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if let Some(ptr) = NonNull::new(ptr) {
            // SAFETY: the caller passes a block this allocator returned, with its layout.
            unsafe { self.heap.lock().deallocate(ptr, layout) }
        }
    }
}
