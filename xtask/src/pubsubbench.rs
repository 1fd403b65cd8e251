//! The publish/subscribe benchmark of `cargo xtask bench`: the loop of test
//! `net_pubsub_machines` closed over the network between two machines, always on real
//! time (two QEMUs side by side on the host's clock). Machine A
//! (`tests/configs/net_pubsub_a.toml`: the plant and the field PLC) publishes the level and
//! its cycle count; machine B (`tests/configs/net_pubsub_b.toml`: the controller PLC)
//! subscribes, and publishes the valve command with the count it last received; A's
//! program turns the count that comes back into `loop_ms`, the loop's round trip in its
//! 10 ms cycles, in its once-a-second watch line. The machines are joined by QEMU's
//! `-netdev dgram` on two free ports of 127.0.0.1. The run ends when B's controller stops
//! (by design, at 30 s of its time) and A's subscription lapses.
//!
//! Metrics: `plc_pubsub_loop` (ms, the round trips A → B → A from A's first valid
//! subscription to the lapse: median, minimum, maximum) and `plc_pubsub_one_way` (ms, half
//! of each; each leg includes the subscriber's wait for its next release, up to one
//! 10 ms period, and the NIC partition's wait for its 2 ms window of the 10 ms frame).

use crate::bench::Metric;
use crate::qemu::{self, RunOptions};
use anyhow::{Result, bail};
use std::path::Path;
use std::time::Duration;

/// The two machines' system descriptions (relative to the workspace).
pub const CONFIGS: [&str; 2] = [
    "tests/configs/net_pubsub_a.toml",
    "tests/configs/net_pubsub_b.toml",
];
/// The longest run of either machine (QEMU is stopped then).
const RUN_TIMEOUT: Duration = Duration::from_secs(300);

/// The loop's round trips (ms) in the field PLC's watch lines (`[field] plc: t=<ms>ms
/// watch ... loop_ms=<ms>`) from `from_ms` to `to_ms` of its time.
pub fn loop_round_trips(lines: &[String], from_ms: u64, to_ms: u64) -> Vec<i64> {
    lines
        .iter()
        .filter(|l| l.contains("[field] plc: t=") && l.contains(" loop_ms="))
        .filter_map(|l| {
            let t: u64 = l
                .split("plc: t=")
                .nth(1)?
                .split("ms")
                .next()?
                .parse()
                .ok()?;
            let ms: i64 = l
                .split(" loop_ms=")
                .nth(1)?
                .split(' ')
                .next()?
                .parse()
                .ok()?;
            (from_ms..to_ms).contains(&t).then_some(ms)
        })
        .collect()
}

/// The `-netdev dgram` link between the machines: this machine's port, the other's.
fn link(local: u16, remote: u16) -> Vec<String> {
    [
        qemu::iommu(),
        qemu::nic_on(&format!(
            "dgram,local.type=inet,local.host=127.0.0.1,local.port={local},remote.type=inet,remote.host=127.0.0.1,remote.port={remote}"
        )),
    ]
    .concat()
}

/// Boots both machines and measures; the metrics, or an error with the transcripts.
pub fn run(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    dir: &Path,
) -> Result<Vec<Metric>> {
    let ports = crate::scenario::free_host_ports(2)?;
    let machine = |i: usize, done_when: &str| -> Result<RunOptions> {
        let config = crate::workspace_root().join(CONFIGS[i]);
        let dir = dir.join(format!("plc_pubsub_{}", ["a", "b"][i]));
        let entries = crate::esp::standard_entries(system, Some(&config))?;
        Ok(RunOptions {
            esp: crate::esp::assemble(&dir.join("esp"), system, &entries)?,
            timeout: Some(RUN_TIMEOUT),
            echo: false,
            work_dir: dir.join("state"),
            deterministic_time: false,
            com2: qemu::Com2::Unconnected,
            done_when: vec![done_when.into()],
            extra_args: link(ports[i], ports[1 - i]),
        })
    };
    let a = machine(0, "[field] plc: subscription lapsed")?;
    let b = machine(1, " stopped: DIVISION_BY_ZERO")?;
    eprintln!("xtask: booting the two publish/subscribe benchmark machines (real time)");
    let (a, b) = std::thread::scope(|scope| {
        let other = scope.spawn(|| qemu::run(qemu, &b));
        let first = qemu::run(qemu, &a);
        (first, other.join())
    });
    let a = a?;
    let b = b.unwrap_or_else(|_| Err(anyhow::anyhow!("booting machine B panicked")))?;
    // The watch lines from the first valid subscription to the lapse.
    let at = |needle: &str| a.lines.iter().position(|l| l.contains(needle));
    let (Some(from), Some(to)) = (
        at("[field] plc: subscription valid"),
        at("[field] plc: subscription lapsed"),
    ) else {
        bail!(
            "the publish/subscribe loop never closed and lapsed\nmachine A:\n{}\nmachine B:\n{}",
            a.transcript(),
            b.transcript()
        );
    };
    let loops: Vec<f64> = loop_round_trips(&a.lines[from..to.max(from)], 0, u64::MAX)
        .into_iter()
        .filter(|&ms| ms > 0)
        .map(|ms| ms as f64)
        .collect();
    if loops.is_empty() {
        bail!(
            "no loop round trip in machine A's watch lines\n{}",
            a.transcript()
        );
    }
    let halves: Vec<f64> = loops.iter().map(|ms| ms / 2.0).collect();
    Ok(vec![
        crate::bench::summary("plc_pubsub_loop", "ms", &loops),
        crate::bench::summary("plc_pubsub_one_way", "ms", &halves),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_are_read_from_the_field_plcs_watch_lines_in_the_span() {
        let lines = [
            "[   1.7] [field] plc: t=1008ms watch level=0.97 valve=0.83 valve_ok=TRUE loop_ms=70",
            "[   2.7] [ctl] plc: t=2000ms watch loop_ms=50",
            "[   2.7] [field] plc: t=2000ms watch level=0.99 valve=0.50 valve_ok=TRUE loop_ms=60",
            "[   3.7] [field] plc: t=3008ms watch level=1.0 valve=0.5 valve_ok=TRUE loop_ms=80",
        ]
        .map(String::from);
        assert_eq!(loop_round_trips(&lines, 1_500, 3_000), vec![60]);
        assert_eq!(loop_round_trips(&lines, 0, 10_000), vec![70, 60, 80]);
    }
}
