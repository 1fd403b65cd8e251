//! Partition `heap` (scenario `apex_heap`): the heap's lock under preemption. `churn`
//! (priority 10) allocates and frees all the time, checking the bytes of each block;
//! `burst` (priority 50) wakes every millisecond, preempting it (mostly inside the heap),
//! allocates and checks too, SUSPENDs churn every 10th wake-up and RESUMEs it at the
//! next, and after 2 s STOPs it and allocates once more: the heap was never left taken,
//! no block was damaged, and a thread found it taken (and lent its holder the MCP) more
//! than once.
//!
//! Every line starts with `heap:`.

use alloc::vec::Vec;
use apex::Warden;
use apex::a653rs::bindings::{self as b, ApexErrorP4, ApexProcessP1, ApexTimeP1, ApexTimeP4};
use apex::codes::apex_name;
use apex::user_rt::println;
use core::sync::atomic::{AtomicU32, Ordering};

const MS: i64 = 1_000_000;
/// How long `burst` runs before it stops `churn`.
const RUN_NS: i64 = 2_000 * MS;

static CHURNED: AtomicU32 = AtomicU32::new(0);
static DAMAGED: AtomicU32 = AtomicU32::new(0);

pub fn create() {
    crate::start_aperiodic("churn", churn, 10);
    crate::start_aperiodic("burst", burst, 50);
}

/// Allocates `len` bytes filled with `fill`, and checks them.
fn block(len: usize, fill: u8) -> Vec<u8> {
    let v = alloc::vec![fill; len];
    if v.iter().any(|&b| b != fill) {
        DAMAGED.fetch_add(1, Ordering::Relaxed);
    }
    v
}

fn check(blocks: &[Vec<u8>]) {
    for v in blocks {
        let fill = v.first().copied().unwrap_or(0);
        if v.iter().any(|&b| b != fill) {
            DAMAGED.fetch_add(1, Ordering::Relaxed);
        }
    }
}

extern "C" fn churn() {
    let mut blocks: Vec<Vec<u8>> = Vec::with_capacity(64);
    let mut n: usize = 0;
    loop {
        n = n.wrapping_add(1);
        let len = 16 + (n * 37) % 700;
        blocks.push(block(len, n as u8));
        if blocks.len() == 48 {
            check(&blocks);
            // Free every other one: the free list stays long and fragmented.
            let mut i = 0;
            blocks.retain(|_| {
                i += 1;
                i % 2 == 0
            });
        }
        if blocks.len() > 40 {
            blocks.clear();
        }
        CHURNED.fetch_add(1, Ordering::Relaxed);
    }
}

extern "C" fn burst() {
    let churn = <Warden as ApexProcessP1>::get_process_id(apex_name("churn")).expect("churn");
    let start = <Warden as ApexTimeP4>::get_time();
    let (mut wakes, mut suspended) = (0u32, 0u32);
    while <Warden as ApexTimeP4>::get_time() - start < RUN_NS {
        let _ = <Warden as ApexTimeP1>::timed_wait(MS);
        wakes += 1;
        let blocks: Vec<Vec<u8>> = (0..8).map(|i| block(24 + i * 50, 0xa5)).collect();
        check(&blocks);
        drop(blocks);
        if wakes % 10 == 0 {
            if <Warden as ApexProcessP1>::suspend(churn).is_ok() {
                suspended += 1;
            }
        } else if wakes % 10 == 1 && wakes > 1 {
            let _ = <Warden as ApexProcessP1>::resume(churn);
        }
    }
    let _ = <Warden as ApexProcessP1>::resume(churn);
    let stopped = <Warden as ApexProcessP1>::stop(churn);
    let after = block(4096, 0x5a);
    let churned = CHURNED.load(Ordering::Relaxed);
    println!(
        "heap: churn {} {}, burst woke {} times, suspended churn {} times, stopped it: {:?}; a block after: {} bytes; damaged {}; heap found taken {}",
        if churned > 1000 { "ran" } else { "starved" },
        if churned > 1000 {
            "> 1000 allocations"
        } else {
            ""
        },
        if wakes > 1000 { "> 1000" } else { "<= 1000" },
        if suspended > 50 { "> 50" } else { "<= 50" },
        stopped,
        after.len(),
        DAMAGED.load(Ordering::Relaxed),
        if apex::heap::lends() > 1 {
            "more than once"
        } else {
            "at most once"
        },
    );
    // The counts themselves (they follow the emulator's timing, so the check above takes
    // bounds).
    println!(
        "heap: counts: churn {churned} allocations, burst {wakes} wake-ups, {suspended} suspensions, heap found taken {} times",
        apex::heap::lends()
    );
    let _ = <Warden as ApexErrorP4>::raise_application_error(
        b::ErrorCode::ApplicationError,
        b"heap done",
    );
}
