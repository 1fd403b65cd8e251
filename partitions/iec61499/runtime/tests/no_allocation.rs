//! Delivering events allocates nothing once the resource's buffers have grown: in the
//! partition every allocation takes the APEX runtime's lock (system calls each time), so
//! an allocation per event made a chain several times slower.

use iec61499_runtime::{Limits, Resource, Value, stdlib};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// The system allocator, counting the allocations of this thread (the test harness's
/// threads allocate too, at times of their own).
struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

#[allow(unsafe_code)]
// SAFETY: every call is passed on to the system allocator unchanged.
unsafe impl GlobalAlloc for Counting {
    #[allow(unsafe_code)]
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
        // SAFETY: the caller's guarantees for `alloc` are the system allocator's.
        unsafe { System.alloc(layout) }
    }

    #[allow(unsafe_code)]
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `alloc` above, that is from the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static COUNTING: Counting = Counting;

#[test]
fn a_chain_of_events_allocates_nothing() {
    // The IEC 61499 benchmark's loop (tests/configs/iec61499/bench_loop.fboot): 8,003
    // events a chain, with WITH data, fan-in and a counter's outputs sent each time.
    let mut r = Resource::new(Limits::default());
    for (name, ty) in [("C", "E_CTU"), ("SW", "E_SWITCH"), ("N", "E_CTU")] {
        r.create(name, stdlib::create(ty).unwrap()).unwrap();
    }
    r.write("C.PV", Value::UInt(4000)).unwrap();
    r.write("N.PV", Value::UInt(65535)).unwrap();
    for (from, to) in [
        ("C.RO", "SW.EI"),
        ("C.CUO", "SW.EI"),
        ("SW.EO0", "C.CU"),
        ("SW.EO1", "N.CU"),
    ] {
        r.connect_event(from, to).unwrap();
    }
    r.connect_data("C.Q", "SW.G").unwrap();
    r.trigger("C.R", 0).unwrap();
    let before = ALLOCATIONS.with(Cell::get);
    for _ in 0..10 {
        r.trigger("C.R", 0).unwrap();
    }
    assert_eq!(ALLOCATIONS.with(Cell::get) - before, 0);
    assert_eq!(r.read("N.CV"), Some(&Value::UInt(11)));
}
