//! The bounded heap: a fixed arena, first fit, and its lock. An allocation that does not
//! fit returns null, and the allocation-error handler panics (reported as
//! APPLICATION_ERROR).
//!
//! # The heap's lock (the MCP lent on contention)
//!
//! A program allocates far more often than it calls the runtime's services, so the heap
//! has a lock of its own that costs no system call while it is free, where the runtime
//! lock ([`Critical`](crate::runtime::Critical)) raises its holder to the MCP and back.
//! A thread takes the heap at its own priority. Threads of a task have fixed priorities
//! on the one CPU and nothing inside the heap waits, so a thread that finds the heap
//! taken has preempted its holder: it lends the holder the MCP and yields; the holder
//! finishes its operation, leaves the heap, drops back to its own priority (the one the
//! runtime last gave it, [`runtime::own_priority`]) and the thread takes the heap. The
//! runtime never suspends or stops a thread inside the heap: it lends it the MCP until
//! it has left ([`leave`]). A holder that no longer exists (a bug) panics the thread
//! that finds it instead of waiting for ever.

// The heap's arena and the global allocator are raw memory: the reason for `unsafe` here.
#![allow(unsafe_code)]

use crate::runtime;
use core::alloc::{GlobalAlloc, Layout};
use core::cell::UnsafeCell;
use core::ptr::NonNull;
use core::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use linked_list_allocator::Heap;
use user_rt::abi::syscall::{ThreadAttribute, ThreadId};
use user_rt::sys;

/// The thread inside the heap (its id), 0 when none: the lock.
static OWNER: AtomicU64 = AtomicU64::new(0);
/// The owner was lent the MCP: it drops back to its own priority as it leaves.
static LENT: AtomicBool = AtomicBool::new(false);
/// How often a thread found the heap taken (statistics).
static LENDS: AtomicU32 = AtomicU32::new(0);
/// Whether the heap has been laid over its arena.
static READY: AtomicBool = AtomicBool::new(false);

struct Arena(UnsafeCell<Heap>);

// SAFETY: the heap is reached only through a `Guard`, which exists only in the thread
// whose id `OWNER` holds (or in `restart`, when no other thread of the partition exists).
unsafe impl Sync for Arena {}

static HEAP: Arena = Arena(UnsafeCell::new(Heap::empty()));

/// The heap, taken.
struct Guard;

impl Guard {
    fn take() -> Self {
        let me = runtime::thread_id();
        loop {
            match OWNER.compare_exchange(0, me, Ordering::Acquire, Ordering::Relaxed) {
                Ok(_) => return Guard,
                // An allocation never allocates.
                Err(owner) if owner == me => panic!("the heap entered twice by one thread"),
                Err(owner) => lend(owner),
            }
        }
    }

    fn heap(&mut self) -> &mut Heap {
        // SAFETY: this thread owns the heap (`OWNER`) until the guard drops, and it makes
        // one guard at a time.
        unsafe { &mut *HEAP.0.get() }
    }
}

impl Drop for Guard {
    fn drop(&mut self) {
        OWNER.store(0, Ordering::Release);
        if LENT.swap(false, Ordering::Relaxed)
            && let Some(index) = runtime::own_index()
        {
            let own = runtime::own_priority(index);
            let _ = sys::thread_set(None, ThreadAttribute::Priority, u64::from(own));
        }
    }
}

/// Lends `owner`, inside the heap, the MCP and yields to it, so that it leaves the heap.
fn lend(owner: u64) {
    LENDS.fetch_add(1, Ordering::Relaxed);
    LENT.store(true, Ordering::Relaxed);
    let mcp = u64::from(runtime::mcp());
    if sys::thread_set(Some(ThreadId(owner)), ThreadAttribute::Priority, mcp).is_err() {
        panic!("the heap is held by a thread that died inside it");
    }
    // A thread at the MCP itself (the watchdog, the error handler) is not preempted by an
    // equal priority.
    sys::yield_now();
}

/// How often a thread of the partition found the heap taken and lent its holder the MCP
/// (since the program was loaded).
pub fn lends() -> u32 {
    LENDS.load(Ordering::Relaxed)
}

/// Before the runtime suspends or stops `thread`: if it is inside the heap, lends it the
/// MCP until it has left (the caller holds the runtime lock at the MCP and yields to it).
pub fn leave(thread: u64) {
    while OWNER.load(Ordering::Acquire) == thread {
        lend(thread);
    }
}

/// At a (re)start, when no other thread of the partition exists: lays a new heap over the
/// arena (`size` bytes at `arena`) unless one is there and no thread of the run before
/// was stopped inside it (after a warm restart the memory is as it was).
pub fn restart(arena: usize, size: usize) {
    let held = OWNER.swap(0, Ordering::Acquire) != 0;
    LENT.store(false, Ordering::Relaxed);
    if READY.load(Ordering::Relaxed) && !held {
        return;
    }
    // The only thread of the partition: the heap is free (`OWNER` is 0).
    let mut guard = Guard;
    let heap = guard.heap();
    *heap = Heap::empty();
    if size > 0 {
        // SAFETY: the arena is a static of the program used by nothing but this heap
        // (`runtime::start`'s contract); after a restart with the heap taken, the old
        // heap's blocks are abandoned with it (no thread that owned them exists any more).
        unsafe { heap.init(arena as *mut u8, size) };
    }
    READY.store(true, Ordering::Relaxed);
}

/// The global allocator over the heap.
pub struct BoundedHeap;

// SAFETY: allocations come from the linked-list heap over the static arena, under the
// heap's lock; it returns blocks of the requested layout or null.
unsafe impl GlobalAlloc for BoundedHeap {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        Guard::take()
            .heap()
            .allocate_first_fit(layout)
            .map_or(core::ptr::null_mut(), |block| block.as_ptr())
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if let Some(block) = NonNull::new(ptr) {
            // SAFETY: the caller guarantees `ptr` came from `alloc` with this `layout`.
            unsafe { Guard::take().heap().deallocate(block, layout) };
        }
    }
}
