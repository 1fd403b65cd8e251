//! The scaling benchmark of `cargo xtask bench --scaling`: N soft-PLC partitions on N CPUs
//! (N = 1 to [`MAX_CPUS`]), each alone on its CPU in a window as long as the 10 ms major
//! frame, all running the same CPU-bound program (`tests/configs/plc/scaling.st`). The
//! measure is FBBeam's case study's: the total of their executions in 60 s, the tasks
//! running cycle after cycle (freewheeling). From 5 s to 65 s after its first cycle each
//! execution of the program is longer than its interval, so its task is released again at
//! once; the program counts them (`Scaling.measured`), and the PLC's watch line after 65
//! s, when its executions are short again and its control process prints, gives the count.
//!
//! Always on real time: QEMU's deterministic time runs the CPUs one after another on one
//! host thread, so every N would get the same total by construction; on real time each
//! CPU is a host thread, and the host's own cores bound the scaling (the table says how
//! many it has).
//!
//! Metrics: `scaling_executions_<n>cpu` (executions in 60 s; median, minimum, maximum over
//! the N partitions), `scaling_total_<n>cpu` (their sum) and `scaling_speedup_<n>cpu`
//! (the total over the total on one CPU).

use crate::bench::Metric;
use crate::qemu::{self, Ending, RunOptions};
use anyhow::{Context, Result, bail};
use std::path::Path;
use std::time::Duration;

/// The program every partition runs (relative to the workspace).
const PROGRAM: &str = "tests/configs/plc/scaling.st";
/// The most CPUs measured (the kernel's QEMU machine takes up to 8).
pub const MAX_CPUS: usize = 4;
/// The program counts its executions from [`WARM_UP_MS`] after its first cycle for
/// [`MEASURED_MS`] (its own constants; these say when the count is final).
const WARM_UP_MS: u64 = 5_000;
const MEASURED_MS: u64 = 60_000;
/// The variable the program counts them in, on the PLC's watch list.
const COUNT: &str = "Scaling.measured";
/// How long a run lasts (the boot, a few seconds, included); QEMU is stopped then.
const RUN_TIME: Duration = Duration::from_secs(80);

/// The system of N partitions on N CPUs, as `tests/configs` would hold it.
pub fn config(cpus: usize) -> String {
    let mut text = format!(
        "# `cargo xtask bench --scaling` with {cpus} CPU(s), written by xtask/src/scalingbench.rs.\n\
         [system]\nmemory = \"512MiB\"\ncpus = {cpus}\n\n[[schedules]]\nmajor_frame = \"10ms\"\n"
    );
    for cpu in 0..cpus {
        text.push_str(&format!(
            "\n[[schedules.windows]]\npartition = \"plc{cpu}\"\noffset = \"0us\"\nduration = \"10ms\"\n"
        ));
    }
    for cpu in 0..cpus {
        text.push_str(&format!(
            "\n[partitions.plc{cpu}]\nimage = \"softplc\"\nmemory = \"4MiB\"\n\
             kernel_memory = \"512KiB\"\nmax_priority = 100\n\
             abilities = [\"debug_log\", \"create_thread\"]\ncpus = [{cpu}]\n\
             plc.program = [\"plc/scaling.st\"]\nplc.watch = [\"{COUNT}\"]\n"
        ));
    }
    text
}

/// Boots the N-CPU systems one after another and reads their executions.
pub fn run(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    dir: &Path,
) -> Result<Vec<Metric>> {
    let dir = dir.join("scaling");
    std::fs::create_dir_all(dir.join("plc"))?;
    std::fs::copy(
        crate::workspace_root().join(PROGRAM),
        dir.join("plc/scaling.st"),
    )
    .with_context(|| format!("cannot copy {PROGRAM}"))?;
    let host_cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut metrics = Vec::new();
    let mut one_cpu = None;
    for cpus in 1..=MAX_CPUS {
        eprintln!(
            "xtask: booting {cpus} PLC partition(s) on {cpus} CPU(s) for {} s (real time, {host_cores} host cores)",
            (WARM_UP_MS + MEASURED_MS) / 1000
        );
        let boot = (format!("cpus{cpus}"), self::config(cpus));
        let outcome = boot_real_time(qemu, system, &dir, boot, RUN_TIME, Vec::new())?;
        if outcome.ending != Ending::TimedOut {
            bail!(
                "the {cpus}-CPU scaling system ended before its time ({:?})\n{}",
                outcome.ending,
                outcome.transcript()
            );
        }
        let per_partition: Vec<f64> = match (0..cpus)
            .map(|cpu| executions(&outcome.lines, &format!("plc{cpu}")))
            .collect::<Result<_, _>>()
        {
            Ok(executions) => executions,
            Err(e) => bail!(
                "the {cpus}-CPU scaling system: {e}\n{}",
                outcome.transcript()
            ),
        };
        let total: f64 = per_partition.iter().sum();
        let base = *one_cpu.get_or_insert(total);
        metrics.push(crate::bench::summary(
            &format!("scaling_executions_{cpus}cpu"),
            "count",
            &per_partition,
        ));
        metrics.push(crate::bench::summary(
            &format!("scaling_total_{cpus}cpu"),
            "count",
            &[total],
        ));
        metrics.push(crate::bench::summary(
            &format!("scaling_speedup_{cpus}cpu"),
            "ratio",
            &[total / base],
        ));
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

/// `partition`'s executions in 60 s: its last watch line's count (`[<partition>] plc:
/// t=<ms>ms watch Scaling.measured=<n>`), from at least a second after the count ended;
/// `Err` with what is missing.
fn executions(lines: &[String], partition: &str) -> Result<f64, String> {
    let tag = format!("[{partition}] plc: t=");
    let key = format!("{COUNT}=");
    let last = lines.iter().rev().find_map(|l| {
        let rest = &l[l.find(&tag)? + tag.len()..];
        let ms: u64 = rest.split("ms").next()?.parse().ok()?;
        let count: u64 = rest
            .split_whitespace()
            .find_map(|w| w.strip_prefix(key.as_str()))?
            .parse()
            .ok()?;
        Some((ms, count))
    });
    let end = WARM_UP_MS + MEASURED_MS + 1_000;
    match last {
        Some((ms, count)) if ms >= end && count > 0 => Ok(count as f64),
        Some((ms, count)) => Err(format!(
            "{partition}'s last watch line is at {ms} ms with {count} executions (wanted one at {end} ms or later, with some)"
        )),
        None => Err(format!("{partition} printed no watch line with {COUNT}")),
    }
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
        assert_eq!(executions(&lines, "plc1"), Ok(4_000.0));
        // The count was not final yet.
        assert!(executions(&lines, "plc0").unwrap_err().contains("64009 ms"));
        assert!(executions(&lines, "plc2").is_err());
    }

    #[test]
    fn every_system_is_valid() {
        for cpus in 1..=MAX_CPUS {
            // Beside tests/configs/plc/scaling.st, as the bench puts it beside its copy.
            let name = crate::workspace_root()
                .join(format!("tests/configs/scaling{cpus}.toml"))
                .display()
                .to_string();
            let text = config(cpus);
            let source = config::text(&name, text.as_bytes()).unwrap();
            if let Err(d) = config::load_with_warnings(&name, source, &|_| true) {
                panic!("{cpus} CPUs: {d:?}");
            }
        }
    }
}
