//! Ends a scenario after a fixed amount of partition time: one periodic process, released
//! once per major frame, counts [`FRAMES`] releases, prints `stopwatch: <n> frames` and
//! raises an application error the scenario's configuration maps to `shutdown_success`.
//! For scenarios whose partitions run forever (the PLC and the plant): on virtual time the
//! run then always covers the same simulated span.
//!
//! A test program: it must never be needed by anything but its scenarios.
#![no_std]
#![no_main]

use apex::Warden;
use apex::a653rs::prelude::*;
use apex::main_process::{self, Release};
use apex::user_rt::println;

/// Releases before the run ends: 35 s at a 10 ms major frame.
const FRAMES: u32 = 3_500;

extern "C" fn count() {
    for _ in 0..FRAMES {
        <Warden as ApexTimeP4Ext>::periodic_wait().expect("PERIODIC_WAIT");
    }
    println!("stopwatch: {FRAMES} frames");
    let _ = <Warden as ApexErrorP4Ext>::raise_application_error(b"done");
}

struct Stopwatch;

impl Partition<Warden> for Stopwatch {
    fn cold_start(&self, ctx: &mut StartContext<Warden>) {
        main_process::start(ctx, "count", count, 16 * 1024, Release::PartitionPeriod)
            .unwrap_or_else(|e| panic!("{e}"));
    }

    fn warm_start(&self, ctx: &mut StartContext<Warden>) {
        self.cold_start(ctx)
    }
}

fn main() {
    Stopwatch.run()
}

apex::partition_entry!(main);
