//! The plant's open-loop driver (scenario `plant_open_loop`): a partition that stands where
//! the soft-PLC will, writing the plant's valve command and setpoint and reading its level
//! over sampling ports, written against the a653rs traits like any APEX partition.
//!
//! One periodic process, released once per major frame: for [`DRIVE_FRAMES`] frames it
//! writes [`VALVE`] to `valve` and [`SETPOINT`] to `setpoint` (8-byte little-endian `f64`,
//! the plant's format), then prints
//! `driver: held valve <v> for <n> frames; level <m.mmm> m <Validity>` with the level it
//! last read from `level`; then it writes nothing for [`SILENT_FRAMES`] frames (the plant's
//! valve input goes stale and must close), prints `driver: silent for <n> frames` and ends
//! the run with an application error the configuration maps to `shutdown_success`.
//!
//! A test program: it must never be needed by anything but its scenario.
#![no_std]
#![no_main]

use apex::Warden;
use apex::a653rs::bindings::ApexPartitionP4;
use apex::a653rs::prelude::*;
use apex::user_rt::println;
use core::str::FromStr;
use core::time::Duration;

/// The valve command held.
const VALVE: f64 = 0.5;
/// The setpoint written (the plant's steady level for [`VALVE`]; the plant only shows it).
const SETPOINT: f64 = 1.0;
/// Frames the command is written: 28 s at the scenario's 10 ms frame, through the plant's
/// first disturbance (20 s to 25 s) and some of the recovery.
const DRIVE_FRAMES: u32 = 2_800;
/// Frames without a write afterwards: 1.5 s, past the plant's refresh and hold times.
const SILENT_FRAMES: u32 = 150;

fn name(text: &str) -> Name {
    Name::from_str(text).expect("names here are short")
}

fn periodic_wait() {
    <Warden as ApexTimeP4Ext>::periodic_wait().expect("PERIODIC_WAIT of a periodic process");
}

extern "C" fn drive() {
    let valve = SamplingPortSource::<Warden>::from_name(name("valve")).expect("valve");
    let setpoint = SamplingPortSource::<Warden>::from_name(name("setpoint")).expect("setpoint");
    let level = SamplingPortDestination::<Warden>::from_name(name("level")).expect("level");
    for _ in 0..DRIVE_FRAMES {
        valve
            .send(&plant::encode(VALVE))
            .expect("WRITE_SAMPLING_MESSAGE valve");
        setpoint
            .send(&plant::encode(SETPOINT))
            .expect("WRITE_SAMPLING_MESSAGE setpoint");
        periodic_wait();
    }
    let mut buf = [0u8; 8];
    match level.receive(&mut buf) {
        Ok((validity, message)) => match plant::decode(message) {
            Some(m) => println!(
                "driver: held valve {VALVE} for {DRIVE_FRAMES} frames; level {m:.3} m {validity:?}"
            ),
            None => println!("driver: level message of {} bytes", message.len()),
        },
        Err(e) => println!("driver: level port: {e:?}"),
    }
    for _ in 0..SILENT_FRAMES {
        periodic_wait();
    }
    println!("driver: silent for {SILENT_FRAMES} frames");
    let _ = <Warden as ApexErrorP4Ext>::raise_application_error(b"done");
}

struct Driver;

impl Partition<Warden> for Driver {
    fn cold_start(&self, ctx: &mut StartContext<Warden>) {
        for port in ["valve", "setpoint"] {
            ctx.create_sampling_port_source(name(port), 8)
                .expect("CREATE_SAMPLING_PORT");
        }
        ctx.create_sampling_port_destination(name("level"), 8, Duration::from_millis(100))
            .expect("CREATE_SAMPLING_PORT level");
        let period = <Warden as ApexPartitionP4>::get_partition_status().period;
        let attributes = ProcessAttribute {
            period: SystemTime::Normal(Duration::from_nanos(period.max(1) as u64)),
            time_capacity: SystemTime::Infinite,
            entry_point: drive,
            stack_size: 16 * 1024,
            base_priority: 10,
            deadline: Deadline::Soft,
            name: name("drive"),
        };
        let process = ctx
            .create_process(attributes)
            .expect("CREATE_PROCESS drive");
        process.start().expect("START drive");
    }

    fn warm_start(&self, ctx: &mut StartContext<Warden>) {
        self.cold_start(ctx)
    }
}

fn main() {
    Driver.run()
}

apex::partition_entry!(main);
