//! The guest benchmark of `cargo xtask bench --guest-smp`: one paravirtualized guest
//! gzips 8 files two at a time (`xargs -P2 -n1 gzip`, script
//! `tests/configs/guest/gzip_bench.sh`), bound to one CPU (`cpus = [0]`) and then to two
//! (`cpus = [0, 1]`), on the same two-CPU machine, in the background of its CPUs with no
//! other partition. The script times each of its [`ROUNDS`] rounds with `/proc/uptime`.
//!
//! Always on real time, as `--scaling` (`xtask::scalingbench`): QEMU's deterministic time
//! runs the CPUs one after another on one host thread, so two CPUs would do no more work
//! in a second than one by construction; on real time each CPU is a host thread, and the
//! host's cores bound the gain.
//!
//! Metrics: `guest_gzip_p2_1cpu` and `guest_gzip_p2_2cpu` (ms a round; median, minimum,
//! maximum over the rounds) and `guest_gzip_p2_speedup` (the medians' ratio).

use crate::bench::Metric;
use crate::qemu::Ending;
use anyhow::{Context, Result, bail};
use std::path::Path;
use std::time::Duration;

/// The script the guest runs (relative to the workspace).
const SCRIPT: &str = "tests/configs/guest/gzip_bench.sh";
/// Rounds the script times (its own constant).
pub const ROUNDS: usize = 5;
/// The script's last line: the run ends there.
const DONE: &str = "gzip bench done";
/// The longest a run may take (boot included).
const RUN_TIME: Duration = Duration::from_secs(600);

/// The two-CPU system with the guest on `cpus` (a TOML list's items, `0` or `0, 1`).
pub fn config(cpus: &str) -> String {
    format!(
        "# `cargo xtask bench --guest-smp`, the guest on CPUs [{cpus}], written by xtask/src/guestsmpbench.rs.\n\
         [system]\nmemory = \"512MiB\"\ncpus = 2\n\n\
         [partitions.shell]\nimage = \"guest\"\nmemory = \"256MiB\"\nkernel_memory = \"2MiB\"\n\
         stack = \"1MiB\"\nkernel_tasks = 17\nkernel_threads = 20\nmax_priority = 20\n\
         abilities = [\"create_task\", \"create_thread\", \"map\", \"debug_log\"]\n\
         time = \"background\"\ncpus = [{cpus}]\n\
         guest.init = [\"/bin/sh\", \"/etc/gzip_bench.sh\"]\n\
         guest.env = [\"PATH=/bin:/usr/bin:/sbin:/usr/sbin\", \"HOME=/root\"]\n\
         guest.files = {{ \"/etc/gzip_bench.sh\" = \"gzip_bench.sh\" }}\n"
    )
}

/// Boots the guest on one CPU, then on two, and reads the rounds' times.
pub fn run(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    dir: &Path,
) -> Result<Vec<Metric>> {
    let dir = dir.join("guest-smp");
    std::fs::create_dir_all(&dir)?;
    std::fs::copy(
        crate::workspace_root().join(SCRIPT),
        dir.join("gzip_bench.sh"),
    )
    .with_context(|| format!("cannot copy {SCRIPT}"))?;
    let host_cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut metrics = Vec::new();
    let mut medians = Vec::new();
    for (n, cpus) in [(1, "0"), (2, "0, 1")] {
        eprintln!(
            "xtask: the guest gzips 8 files with xargs -P2 on {n} CPU(s), {ROUNDS} rounds (real time, {host_cores} host cores)"
        );
        let boot = (format!("cpus{n}"), self::config(cpus));
        let done = vec![DONE.to_string()];
        let outcome =
            crate::scalingbench::boot_real_time(qemu, system, &dir, boot, RUN_TIME, done)?;
        if outcome.ending != Ending::Done {
            bail!(
                "the guest on {n} CPU(s) did not finish ({:?})\n{}",
                outcome.ending,
                outcome.transcript()
            );
        }
        let rounds = match round_times(&outcome.lines) {
            Ok(rounds) => rounds,
            Err(e) => bail!("the guest on {n} CPU(s): {e}\n{}", outcome.transcript()),
        };
        let metric = crate::bench::summary(&format!("guest_gzip_p2_{n}cpu"), "ms", &rounds);
        medians.push(metric.median);
        metrics.push(metric);
    }
    metrics.push(crate::bench::summary(
        "guest_gzip_p2_speedup",
        "ratio",
        &[medians[0] / medians[1]],
    ));
    Ok(metrics)
}

/// The rounds' times in ms from the script's `round <n> cs <centiseconds>` lines (as the
/// guest logs its processes' output); `Err` unless there are [`ROUNDS`].
fn round_times(lines: &[String]) -> Result<Vec<f64>, String> {
    let times: Vec<f64> = lines
        .iter()
        .filter_map(|l| {
            let rest = &l[l.find(" stdout: round ")? + " stdout: round ".len()..];
            let cs: u64 = rest.split(" cs ").nth(1)?.trim().parse().ok()?;
            Some(cs as f64 * 10.0)
        })
        .collect();
    if times.len() == ROUNDS {
        Ok(times)
    } else {
        Err(format!("{} round lines, wanted {ROUNDS}", times.len()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounds_from_the_guests_output() {
        let line =
            |n: u32, cs: u32| format!("[  9.1] [shell] guest: process 5 stdout: round {n} cs {cs}");
        let mut lines = vec![
            line(1, 412),
            "[  9.2] [shell] guest: process 5 stdout: files 9 bytes".into(),
        ];
        lines.extend((2..ROUNDS as u32).map(|n| line(n, 400)));
        let short = format!("{} round lines", ROUNDS - 1);
        assert!(round_times(&lines).unwrap_err().contains(&short));
        lines.push(line(ROUNDS as u32, 398));
        let times = round_times(&lines).unwrap();
        assert_eq!(
            (times[0], times[1], times[ROUNDS - 1]),
            (4120.0, 4000.0, 3980.0)
        );
    }

    #[test]
    fn both_systems_are_valid() {
        for cpus in ["0", "0, 1"] {
            let name = crate::workspace_root()
                .join("tests/configs/guest/gzip_bench.toml")
                .display()
                .to_string();
            let text = config(cpus);
            let source = config::text(&name, text.as_bytes()).unwrap();
            if let Err(d) = config::load_with_warnings(&name, source, &|_| true) {
                panic!("CPUs [{cpus}]: {d:?}");
            }
        }
    }
}
