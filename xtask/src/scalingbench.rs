//! The scaling benchmark of `cargo xtask bench --scaling`: N partitions on N CPUs (N = 1
//! to [`MAX_CPUS`]), each alone on its CPU in a window as long as the 10 ms major frame,
//! all running the same CPU-bound work, in two legs ([`Leg`]): soft-PLC partitions and
//! IEC 61499 devices. The measure is FBBeam's case study's: the total of their
//! executions in 60 s, each partition's work started again as soon as it ends.
//!
//! - **The soft-PLC** (`tests/configs/plc/scaling.st`): from 5 s to 65 s after its first
//!   cycle each execution of the program is longer than its interval, so its task is
//!   released again at once (freewheeling); the program counts them (`Scaling.measured`),
//!   and the PLC's watch line after 65 s, when its executions are short again and its
//!   control process prints, gives the count.
//! - **IEC 61499** (`tests/configs/iec61499/scaling.fboot`): one resource whose event
//!   chain is the IEC 61499 benchmark's loop (an E_CTU `C` and an E_SWITCH `SW` counting
//!   to 20 and back) followed by the E_DELAY `D` (DT = 0) that starts the next chain, 45
//!   events in all, counted by the E_CTUs `N` (chains, to 1000) and `M` (thousands). The
//!   device process runs the chains one after another (a resource's timers fire at their
//!   own instants, so D's are all due at once: at most 10,000 chains a pass, a tenth to a
//!   quarter of a second, then the process looks at its clock and prints its watches
//!   each second). The count is 1000·M + N from the watch lines 5 s and 65 s after the
//!   first.
//!   The resources of one device share the device (one chain at a time, under the device
//!   mutex; `partitions/iec61499/partition/src/main.rs`), so the IEC 61499 runtime scales
//!   by devices: one partition with its resource on each CPU.
//!
//! Always on real time: QEMU's deterministic time runs the CPUs one after another on one
//! host thread, so every N would get the same total by construction; on real time each
//! CPU is a host thread, and the host's own cores bound the scaling (the table says how
//! many it has).
//!
//! Metrics: `scaling_executions_<n>cpu` (the PLC program's executions in 60 s; median,
//! minimum, maximum over the N partitions), `scaling_total_<n>cpu` (their sum) and
//! `scaling_speedup_<n>cpu` (the total over the total on one CPU); for IEC 61499 the
//! same as `iec61499_scaling_chains_<n>cpu`, `iec61499_scaling_total_<n>cpu` and
//! `iec61499_scaling_speedup_<n>cpu`.

use crate::bench::Metric;
use crate::qemu::{self, Ending, RunOptions};
use anyhow::{Context, Result, bail};
use std::path::Path;
use std::time::Duration;

/// The most CPUs measured (the kernel's QEMU machine takes up to 8).
pub const MAX_CPUS: usize = 4;
/// The soft-PLC counts its executions from [`WARM_UP_MS`] after its first cycle for
/// [`MEASURED_MS`] (the program's own constants; these say when the count is final); the
/// IEC 61499 leg takes its counts that far after its first watch line.
const WARM_UP_MS: u64 = 5_000;
const MEASURED_MS: u64 = 60_000;
/// The variable the PLC program counts its executions in, on the PLC's watch list.
const PLC_COUNT: &str = "Scaling.measured";
/// The IEC 61499 device's chain counters (watched by its boot file): chains and thousands.
const CHAINS: &str = "LOOP.N.CV";
const THOUSANDS: &str = "LOOP.M.CV";
/// How long a run lasts (the boot, a few seconds, included); QEMU is stopped then.
const RUN_TIME: Duration = Duration::from_secs(80);

/// What every partition of a run is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Leg {
    /// A soft-PLC running `tests/configs/plc/scaling.st`.
    Plc,
    /// An IEC 61499 device booting `tests/configs/iec61499/scaling.fboot`.
    Iec61499,
}

impl Leg {
    pub const ALL: [Leg; 2] = [Leg::Plc, Leg::Iec61499];

    /// The file each partition runs: (relative to the workspace, relative to the config).
    fn file(self) -> (&'static str, &'static str) {
        match self {
            Leg::Plc => ("tests/configs/plc/scaling.st", "plc/scaling.st"),
            Leg::Iec61499 => (
                "tests/configs/iec61499/scaling.fboot",
                "iec61499/scaling.fboot",
            ),
        }
    }

    /// The name of the partition on `cpu`.
    fn partition(self, cpu: usize) -> String {
        match self {
            Leg::Plc => format!("plc{cpu}"),
            Leg::Iec61499 => format!("fb{cpu}"),
        }
    }

    /// The metrics' names: `<prefix>_<per partition>_<n>cpu`, `<prefix>_total_<n>cpu`...
    fn metrics(self) -> (&'static str, &'static str) {
        match self {
            Leg::Plc => ("scaling", "executions"),
            Leg::Iec61499 => ("iec61499_scaling", "chains"),
        }
    }

    /// The system of N partitions on N CPUs, as `tests/configs` would hold it.
    pub fn config(self, cpus: usize) -> String {
        let mut text = format!(
            "# `cargo xtask bench --scaling` ({self:?}) with {cpus} CPU(s), written by xtask/src/scalingbench.rs.\n\
             [system]\nmemory = \"512MiB\"\ncpus = {cpus}\n\n[[schedules]]\nmajor_frame = \"10ms\"\n"
        );
        for cpu in 0..cpus {
            text.push_str(&format!(
                "\n[[schedules.windows]]\npartition = \"{}\"\noffset = \"0us\"\nduration = \"10ms\"\n",
                self.partition(cpu)
            ));
        }
        let file = self.file().1;
        for cpu in 0..cpus {
            let name = self.partition(cpu);
            text.push_str(&match self {
                Leg::Plc => format!(
                    "\n[partitions.{name}]\nimage = \"softplc\"\nmemory = \"4MiB\"\n\
                     kernel_memory = \"512KiB\"\nmax_priority = 100\n\
                     abilities = [\"debug_log\", \"create_thread\"]\ncpus = [{cpu}]\n\
                     plc.program = [\"{file}\"]\nplc.watch = [\"{PLC_COUNT}\"]\n"
                ),
                Leg::Iec61499 => format!(
                    "\n[partitions.{name}]\nimage = \"iec61499\"\nmemory = \"8MiB\"\n\
                     kernel_memory = \"512KiB\"\nmax_priority = 100\n\
                     abilities = [\"debug_log\", \"create_thread\"]\ncpus = [{cpu}]\n\
                     iec61499.boot = \"{file}\"\n"
                ),
            });
        }
        text
    }

    /// `partition`'s executions in 60 s from the run's lines.
    fn executions(self, lines: &[String], partition: &str) -> Result<f64, String> {
        match self {
            Leg::Plc => plc_executions(lines, partition),
            Leg::Iec61499 => iec61499_chains(lines, partition),
        }
    }
}

/// Boots the N-CPU systems of each leg one after another and reads their executions.
pub fn run(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    dir: &Path,
) -> Result<Vec<Metric>> {
    let dir = dir.join("scaling");
    let host_cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut metrics = Vec::new();
    for leg in Leg::ALL {
        let (source, copy) = leg.file();
        let copy = dir.join(copy);
        std::fs::create_dir_all(copy.parent().unwrap_or(&dir))?;
        std::fs::copy(crate::workspace_root().join(source), &copy)
            .with_context(|| format!("cannot copy {source}"))?;
        let (prefix, each) = leg.metrics();
        let mut one_cpu = None;
        for cpus in 1..=MAX_CPUS {
            eprintln!(
                "xtask: booting {cpus} {leg:?} partition(s) on {cpus} CPU(s) for {} s (real time, {host_cores} host cores)",
                RUN_TIME.as_secs()
            );
            let boot = (format!("{prefix}{cpus}"), leg.config(cpus));
            let outcome = boot_real_time(qemu, system, &dir, boot, RUN_TIME, Vec::new())?;
            if outcome.ending != Ending::TimedOut {
                bail!(
                    "the {cpus}-CPU {leg:?} scaling system ended before its time ({:?})\n{}",
                    outcome.ending,
                    outcome.transcript()
                );
            }
            let per_partition: Vec<f64> = match (0..cpus)
                .map(|cpu| leg.executions(&outcome.lines, &leg.partition(cpu)))
                .collect::<Result<_, _>>()
            {
                Ok(executions) => executions,
                Err(e) => bail!(
                    "the {cpus}-CPU {leg:?} scaling system: {e}\n{}",
                    outcome.transcript()
                ),
            };
            let total: f64 = per_partition.iter().sum();
            let base = *one_cpu.get_or_insert(total);
            metrics.push(crate::bench::summary(
                &format!("{prefix}_{each}_{cpus}cpu"),
                "count",
                &per_partition,
            ));
            metrics.push(crate::bench::summary(
                &format!("{prefix}_total_{cpus}cpu"),
                "count",
                &[total],
            ));
            metrics.push(crate::bench::summary(
                &format!("{prefix}_speedup_{cpus}cpu"),
                "ratio",
                &[total / base],
            ));
        }
    }
    Ok(metrics)
}

/// Boots the system of configuration `text` (written to `dir/<name>.toml`, beside the
/// files it names; its ESP and state in `dir/<name>/`) on real time until `done_when` has
/// appeared or `timeout` passed: the runs of the multicore benchmarks.
pub(crate) fn boot_real_time(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    dir: &Path,
    (name, text): (String, String),
    timeout: Duration,
    done_when: Vec<String>,
) -> Result<qemu::Outcome> {
    let config = dir.join(format!("{name}.toml"));
    std::fs::write(&config, text)?;
    let entries = crate::esp::standard_entries(system, Some(&config))?;
    let run_dir = dir.join(&name);
    let esp = crate::esp::assemble(&run_dir.join("esp"), system, &entries)?;
    qemu::run(
        qemu,
        &RunOptions {
            esp,
            timeout: Some(timeout),
            echo: false,
            work_dir: run_dir.join("state"),
            deterministic_time: false,
            com2: qemu::Com2::Unconnected,
            done_when,
            extra_args: Vec::new(),
        },
    )
}

/// PLC `partition`'s executions in 60 s: its last watch line's count (`[<partition>] plc:
/// t=<ms>ms watch Scaling.measured=<n>`), from at least a second after the count ended;
/// `Err` with what is missing.
fn plc_executions(lines: &[String], partition: &str) -> Result<f64, String> {
    let tag = format!("[{partition}] plc: t=");
    let last = lines.iter().rev().find_map(|l| {
        let (ms, words) = timed_line(l, &tag)?;
        Some((ms, word_value(words, PLC_COUNT)?))
    });
    let end = WARM_UP_MS + MEASURED_MS + 1_000;
    match last {
        Some((ms, count)) if ms >= end && count > 0 => Ok(count as f64),
        Some((ms, count)) => Err(format!(
            "{partition}'s last watch line is at {ms} ms with {count} executions (wanted one at {end} ms or later, with some)"
        )),
        None => Err(format!(
            "{partition} printed no watch line with {PLC_COUNT}"
        )),
    }
}

/// IEC 61499 device `partition`'s chains in 60 s: 1000·M + N (its watch lines `[<partition>]
/// iec61499: t=<ms>ms watch LOOP.N.CV=<n> LOOP.M.CV=<m>`, one a second) from the line
/// [`WARM_UP_MS`] after its first to the one [`MEASURED_MS`] later (scaled to 60 s if
/// that line is later); `Err` with what is missing.
fn iec61499_chains(lines: &[String], partition: &str) -> Result<f64, String> {
    let tag = format!("[{partition}] iec61499: t=");
    let counts: Vec<(u64, u64)> = lines
        .iter()
        .filter_map(|l| {
            let (ms, words) = timed_line(l, &tag)?;
            Some((
                ms,
                1000 * word_value(words, THOUSANDS)? + word_value(words, CHAINS)?,
            ))
        })
        .collect();
    let Some(&(first, _)) = counts.first() else {
        return Err(format!(
            "{partition} printed no watch line with {CHAINS} and {THOUSANDS}"
        ));
    };
    let at_least = |ms: u64| counts.iter().find(|(t, _)| *t >= ms).copied();
    let from = at_least(first + WARM_UP_MS);
    match from.and_then(|(t, _)| Some((from?, at_least(t + MEASURED_MS)?))) {
        Some(((t0, c0), (t1, c1))) if c1 > c0 => {
            Ok(((c1 - c0) as f64 * MEASURED_MS as f64 / (t1 - t0) as f64).round())
        }
        _ => Err(format!(
            "{partition}'s watch lines from {first} ms to {} ms do not span {} s of chains after {} s",
            counts.last().map_or(first, |c| c.0),
            MEASURED_MS / 1000,
            WARM_UP_MS / 1000
        )),
    }
}

/// The time (ms) and the rest of a status line `...<tag><ms>ms <words>`, if `line` is one.
fn timed_line<'l>(line: &'l str, tag: &str) -> Option<(u64, &'l str)> {
    let rest = &line[line.find(tag)? + tag.len()..];
    Some((rest.split("ms").next()?.parse().ok()?, rest))
}

/// The number of word `<key>=<n>` among `words`.
fn word_value(words: &str, key: &str) -> Option<u64> {
    words
        .split_whitespace()
        .find_map(|w| w.strip_prefix(key)?.strip_prefix('='))?
        .parse()
        .ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn executions_from_watch_lines() {
        let line = |partition: &str, ms: u64, count: u64| {
            format!("[   9.1] [{partition}] plc: t={ms}ms watch Scaling.measured={count}")
        };
        let lines = vec![
            line("plc1", 64_009, 3_900),
            line("plc1", 66_009, 4_000),
            line("plc0", 64_009, 4_100),
            "[   9.2] [plc2] plc: t=66009ms task=__MAIN.Scaling cycles=9".to_string(),
            line("plc1", 67_009, 4_000),
        ];
        assert_eq!(plc_executions(&lines, "plc1"), Ok(4_000.0));
        // The count was not final yet.
        assert!(
            plc_executions(&lines, "plc0")
                .unwrap_err()
                .contains("64009 ms")
        );
        assert!(plc_executions(&lines, "plc2").is_err());
    }

    #[test]
    fn chains_from_watch_lines() {
        let line = |partition: &str, ms: u64, chains: u64| {
            format!(
                "[   9.1] [{partition}] iec61499: t={ms}ms watch LOOP.N.CV={} LOOP.M.CV={}",
                chains % 1000,
                chains / 1000
            )
        };
        let mut lines =
            vec!["[   9.0] [fb1] iec61499: t=2000ms timers=3 lateness_ns=1/2/3".to_string()];
        for s in 2..=70 {
            lines.push(line("fb1", s * 1000, s * 5_500));
            // fb0 skips a second at 67 s: its count is scaled to 60 s.
            if s != 67 {
                lines.push(line("fb0", s * 1000, s * 6_100));
            }
        }
        assert_eq!(iec61499_chains(&lines, "fb1"), Ok(330_000.0));
        assert_eq!(iec61499_chains(&lines, "fb0"), Ok(366_000.0));
        // fb0's lines end before 67 s: no count over 60 s from 7 s.
        let short: Vec<String> = (2..67).map(|s| line("fb0", s * 1000, s * 6_100)).collect();
        assert!(
            iec61499_chains(&short, "fb0")
                .unwrap_err()
                .contains("do not span")
        );
        assert!(iec61499_chains(&lines, "fb2").is_err());
    }

    /// The IEC 61499 leg's boot file deploys, and every pass of the device process runs
    /// [`iec61499_runtime::Limits::chain_events`] chains of it, counted 1000·M + N.
    #[test]
    fn the_iec61499_chains_count_themselves() {
        let text =
            std::fs::read_to_string(crate::workspace_root().join(Leg::Iec61499.file().0)).unwrap();
        let limits = iec61499_runtime::Limits::default();
        let mut device = iec61499_mgmt::device::Device::new(limits, 1);
        device.boot(&text, 0).unwrap();
        let count = |d: &iec61499_mgmt::device::Device| {
            let watched = d.watched();
            let value = |name: &str| -> u64 {
                watched
                    .iter()
                    .find(|(n, _)| n == name)
                    .unwrap()
                    .1
                    .parse()
                    .unwrap()
            };
            1000 * value(THOUSANDS) + value(CHAINS)
        };
        assert_eq!(count(&device), 0);
        for pass in 1..=3u64 {
            device.advance(pass as i64);
            assert_eq!(count(&device), pass * limits.chain_events as u64);
        }
        assert_eq!(device.report().faults, 0);
    }

    #[test]
    fn every_system_is_valid() {
        for cpus in 1..=MAX_CPUS {
            // Beside tests/configs/plc/ and iec61499/, as the bench puts the files' copies.
            let name = crate::workspace_root()
                .join(format!("tests/configs/scaling{cpus}.toml"))
                .display()
                .to_string();
            for leg in Leg::ALL {
                let text = leg.config(cpus);
                let source = config::text(&name, text.as_bytes()).unwrap();
                if let Err(d) = config::load_with_warnings(&name, source, &|_| true) {
                    panic!("{leg:?} on {cpus} CPUs: {d:?}");
                }
            }
        }
    }
}
