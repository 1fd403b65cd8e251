//! The plant partition: runs the tank simulation of the library part in its own time
//! window, one periodic process released once per major frame. Each release it reads the
//! valve command, advances the simulation by the simulated time of one major frame (1 ms
//! steps), and publishes the level.
//!
//! Ports (the configuration's names; messages are 8-byte little-endian `f64`):
//! `valve` (sampling input, 0.0..=1.0) and `level` (sampling output, metres). A valve
//! message that is missing or invalid (older than the port's refresh period) keeps the last
//! valid command for at most [`HOLD_RELEASES`] releases, then the valve closes (the safe
//! state); every such release is counted.
//!
//! Status line (an interface: tests and plotting tools parse it), every 500 ms simulated:
//! `plant: t=<ms>ms level=<m.mmm> valve=<0.000> setpoint=- disturbance=<on|off> stale=<n>`.
//! It must never panic on a bad message: a short or non-finite command is treated as closed.
#![no_std]
#![no_main]

use apex::Warden;
use apex::a653rs::bindings::ApexPartitionP4;
use apex::a653rs::prelude::*;
use apex::user_rt::println;
use core::str::FromStr;
use core::time::Duration;
use plant::{DISTURBANCES, Plant, Tank, valve_command};

/// Simulated milliseconds per step.
const STEP_MS: u64 = 1;
/// Releases a stale valve command is held before the valve closes.
pub const HOLD_RELEASES: u32 = 3;
/// Simulated time between status lines.
const STATUS_EVERY_MS: u64 = 500;
/// Period if the partition has none (a background partition): 10 ms.
const DEFAULT_PERIOD: Duration = Duration::from_millis(10);

fn name(text: &str) -> Name {
    Name::from_str(text).expect("port names here are short")
}

fn period() -> Duration {
    let status = <Warden as ApexPartitionP4>::get_partition_status();
    match u64::try_from(status.period) {
        Ok(ns) if ns > 0 => Duration::from_nanos(ns),
        _ => DEFAULT_PERIOD,
    }
}

/// The command in a valve message, if it is one.
fn decode_valve(message: &[u8]) -> Option<f64> {
    let bytes: [u8; 8] = message.get(..8)?.try_into().ok()?;
    Some(f64::from_le_bytes(bytes))
}

extern "C" fn simulate() {
    let valve_port = SamplingPortDestination::<Warden>::from_name(name("valve")).expect("valve");
    let level_port = SamplingPortSource::<Warden>::from_name(name("level")).expect("level");
    let steps = (period().as_millis() as u64 / STEP_MS).max(1);
    let mut plant = Plant::new(Tank::DEFAULT, 0.0, STEP_MS, &DISTURBANCES);
    let (mut command, mut held, mut stale) = (0.0, 0u32, 0u64);
    let mut next_status = 0;
    let mut buf = [0u8; 8];
    loop {
        match valve_port.receive(&mut buf) {
            Ok((Validity::Valid, message)) => {
                command = decode_valve(message).map_or(0.0, valve_command);
                held = 0;
            }
            _ => {
                stale += 1;
                held += 1;
                if held > HOLD_RELEASES {
                    command = 0.0;
                }
            }
        }
        plant.run(command, steps);
        let _ = level_port.send(&plant.level.to_le_bytes());
        if plant.time_ms >= next_status {
            next_status += STATUS_EVERY_MS;
            println!(
                "plant: t={}ms level={:.3} valve={:.3} setpoint=- disturbance={} stale={}",
                plant.time_ms,
                plant.level,
                command,
                if plant.disturbance() != 0.0 {
                    "on"
                } else {
                    "off"
                },
                stale
            );
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
        ctx.create_sampling_port_destination(name("valve"), 8, Duration::from_millis(100))
            .expect("CREATE_SAMPLING_PORT valve");
        ctx.create_sampling_port_source(name("level"), 8)
            .expect("CREATE_SAMPLING_PORT level");
        let attributes = ProcessAttribute {
            period: SystemTime::Normal(period()),
            time_capacity: SystemTime::Infinite,
            entry_point: simulate,
            stack_size: 16 * 1024,
            base_priority: 10,
            deadline: Deadline::Soft,
            name: name("simulate"),
        };
        let process = ctx
            .create_process(attributes)
            .expect("CREATE_PROCESS simulate");
        process.start().expect("START simulate");
    }

    fn warm_start(&self, ctx: &mut StartContext<Warden>) {
        self.cold_start(ctx)
    }
}

fn main() {
    PlantPartition.run()
}

apex::partition_entry!(main);
