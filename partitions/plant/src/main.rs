//! The plant partition: runs the tank simulation of the library part ([`plant::Simulator`])
//! in its own time window, one periodic process released once per major frame (the
//! partition's period, from GET_PARTITION_STATUS). Each release reads the valve command,
//! advances the simulation by the simulated time of one period (1 ms steps), publishes the
//! level and, every 500 ms simulated, prints the status line documented in the library
//! (it appears on the serial log as `[<partition>] plant: t=...`).
//!
//! Ports it creates (messages are 8-byte little-endian `f64`; the configuration must give
//! these sizes and refresh periods exactly, or the partition stops at its start):
//! - `valve`: sampling in, size 8, refresh 100 ms: the valve command, 0.0..=1.0;
//! - `level`: sampling out, size 8: the level in metres;
//! - `setpoint` (optional): sampling in, size 8, refresh 100 ms: only shown in the status
//!   line (`setpoint=-` without the port).
//!
//! This file is glue only: it must never interpret a message itself (the library decides
//! what a missing, invalid or malformed one means) and never panic on one.
#![no_std]
#![no_main]

use apex::Warden;
use apex::a653rs::bindings::ApexPartitionP4;
use apex::a653rs::prelude::*;
use apex::main_process::{self, Release};
use apex::user_rt::println;
use core::str::FromStr;
use core::time::Duration;
use plant::{Simulator, decode, encode, steps_per_release};

/// Refresh period of the input ports (must match the configuration's `refresh`).
const REFRESH: Duration = Duration::from_millis(100);
/// Period if the partition has none (a background partition).
const DEFAULT_PERIOD: Duration = Duration::from_millis(10);

fn name(text: &str) -> Name {
    Name::from_str(text).expect("port names here are short")
}

/// The partition's period (its major frame), from GET_PARTITION_STATUS.
fn period() -> Duration {
    let status = <Warden as ApexPartitionP4>::get_partition_status();
    match u64::try_from(status.period) {
        Ok(ns) if ns > 0 => Duration::from_nanos(ns),
        _ => DEFAULT_PERIOD,
    }
}

extern "C" fn simulate() {
    let valve = SamplingPortDestination::<Warden>::from_name(name("valve")).expect("valve");
    let level = SamplingPortSource::<Warden>::from_name(name("level")).expect("level");
    let setpoint = SamplingPortDestination::<Warden>::from_name(name("setpoint")).ok();
    let steps = steps_per_release(u64::try_from(period().as_nanos()).unwrap_or(u64::MAX));
    let mut sim = Simulator::new();
    let mut buf = [0u8; 8];
    loop {
        let fresh = match valve.receive(&mut buf) {
            Ok((Validity::Valid, message)) => decode(message),
            _ => None,
        };
        // The setpoint is only shown: the latest message, however old.
        let shown = setpoint
            .as_ref()
            .and_then(|port| port.receive(&mut buf).ok())
            .and_then(|(_, message)| decode(message));
        let status = sim.release(fresh, shown, steps);
        let _ = level.send(&encode(sim.plant.level));
        if let Some(status) = status {
            println!("{status}");
        }
        if <Warden as ApexTimeP4Ext>::periodic_wait().is_err() {
            println!("plant: PERIODIC_WAIT failed; stopping");
            return;
        }
    }
}

struct PlantPartition;

impl Partition<Warden> for PlantPartition {
    fn cold_start(&self, ctx: &mut StartContext<Warden>) {
        ctx.create_sampling_port_destination(name("valve"), 8, REFRESH)
            .expect("CREATE_SAMPLING_PORT valve");
        ctx.create_sampling_port_source(name("level"), 8)
            .expect("CREATE_SAMPLING_PORT level");
        if let Err(e) = ctx.create_sampling_port_destination(name("setpoint"), 8, REFRESH) {
            println!("plant: no setpoint port ({e:?}); status lines show setpoint=-");
        }
        main_process::start(
            ctx,
            "simulate",
            simulate,
            16 * 1024,
            Release::Every(period()),
        )
        .unwrap_or_else(|e| panic!("{e}"));
    }

    fn warm_start(&self, ctx: &mut StartContext<Warden>) {
        self.cold_start(ctx)
    }
}

fn main() {
    PlantPartition.run()
}

apex::partition_entry!(main);
