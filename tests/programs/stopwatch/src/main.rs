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
use apex::a653rs::bindings::ApexPartitionP4;
use apex::a653rs::prelude::*;
use apex::user_rt::println;
use core::str::FromStr;
use core::time::Duration;

/// Releases before the run ends: 35 s at a 10 ms major frame.
const FRAMES: u32 = 3_500;

fn name(text: &str) -> Name {
    Name::from_str(text).expect("names here are short")
}

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
        let period = <Warden as ApexPartitionP4>::get_partition_status().period;
        let attributes = ProcessAttribute {
            period: SystemTime::Normal(Duration::from_nanos(period.max(1) as u64)),
            time_capacity: SystemTime::Infinite,
            entry_point: count,
            stack_size: 16 * 1024,
            // Just below the MCP: above any background hog of the scenario.
            base_priority: i32::from(apex::runtime::mcp()).saturating_sub(1).max(1),
            deadline: Deadline::Soft,
            name: name("count"),
        };
        let process = ctx.create_process(attributes).expect("CREATE_PROCESS");
        process.start().expect("START");
    }

    fn warm_start(&self, ctx: &mut StartContext<Warden>) {
        self.cold_start(ctx)
    }
}

fn main() {
    Stopwatch.run()
}

apex::partition_entry!(main);
