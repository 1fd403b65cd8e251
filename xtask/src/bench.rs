//! `cargo xtask bench`: boots the kernel benchmark system, the port benchmark system
//! (`tests/configs/bench_ports.toml`), the soft-PLC benchmark system on virtual time
//! (`tests/configs/bench_plc.toml`: `plc_release_jitter`, `plc_cycle_overhead`,
//! `plc_online_read`) and the attack systems whose victim measures its window starts on
//! virtual time (`window_lateness_hostile*`) and the soak system on virtual time
//! (`tests/configs/soak.toml`: `soak_window_lateness`, `soak_missed_windows`,
//! `soak_window_drift`; alone with `--soak`) and the guest benchmark
//! (`tests/configs/bench_guest.toml`: `linux-bench` as `guest_*`, on the host as `host_*`,
//! on Debian's stock kernel in the same QEMU as `native_*` with `guest_ratio_*`, see
//! [`crate::native`]; alone with `--guest`), runs the host benchmarks, prints one line per
//! metric and writes `target/bench/report.json`.
//!
//! The network benchmark (`tests/configs/bench_net.toml`, guest and native, timed from the
//! host: `guest_net_*`, `native_net_*`, `net_ratio_*`; alone with `--net`) is
//! [`crate::netbench`].
//!
//! The disk benchmark (`tests/configs/bench_disk.toml` and the PLC's store: `guest_disk_*`,
//! `native_disk_*`, `disk_ratio_*`, `plc_retain_*`, `plc_boot_*`; alone with `--disk`) is
//! [`crate::diskbench`].
//!
//! Line format (an interface): `bench <name> median=<n> min=<n> max=<n> unit=<cycles|ns|us|ms|ratio|count|MB/s|requests/s> samples=<n>`.

use anyhow::{Context, Result, bail};
use serde::Serialize;

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Metric {
    pub name: String,
    pub median: f64,
    pub min: f64,
    pub max: f64,
    pub unit: String,
    pub samples: u64,
}

/// `name` over `samples` (median, minimum, maximum), to three significant places.
pub fn summary(name: &str, unit: &str, samples: &[f64]) -> Metric {
    let mut sorted = samples.to_vec();
    sorted.sort_by(f64::total_cmp);
    let at = |i: usize| sorted.get(i).copied().map_or(f64::NAN, significant);
    Metric {
        name: name.to_string(),
        median: at(sorted.len() / 2),
        min: at(0),
        max: at(sorted.len().saturating_sub(1)),
        unit: unit.to_string(),
        samples: samples.len() as u64,
    }
}

/// The `p`th percentile of `samples` (nearest rank), to three significant places.
pub fn percentile(samples: &[f64], p: f64) -> f64 {
    let mut sorted = samples.to_vec();
    sorted.sort_by(f64::total_cmp);
    let rank = ((p / 100.0) * sorted.len() as f64).ceil() as usize;
    sorted
        .get(rank.clamp(1, sorted.len().max(1)) - 1)
        .copied()
        .map_or(f64::NAN, significant)
}

/// `x` to three significant places.
fn significant(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let digits = 2 - x.abs().log10().floor() as i32;
    // Dividing by a power of ten above one, not multiplying by its inexact inverse, keeps
    // a large count whole (1.3e7, not 12999999.999999998).
    if digits >= 0 {
        let scale = 10f64.powi(digits);
        (x * scale).round() / scale
    } else {
        let scale = 10f64.powi(-digits);
        (x / scale).round() * scale
    }
}

/// Parses the `bench ...` part of a line (anything before `bench ` is ignored, so kernel-log
/// prefixes do not matter). `None` for lines that are not metrics.
pub fn parse_line(line: &str) -> Option<Metric> {
    let rest = &line[line.find("bench ")? + "bench ".len()..];
    let mut words = rest.split_whitespace();
    let name = words.next()?.to_string();
    let mut m = Metric {
        name,
        median: f64::NAN,
        min: f64::NAN,
        max: f64::NAN,
        unit: String::new(),
        samples: 0,
    };
    for word in words {
        let (key, value) = word.split_once('=')?;
        match key {
            "median" => m.median = value.parse().ok()?,
            "min" => m.min = value.parse().ok()?,
            "max" => m.max = value.parse().ok()?,
            "unit" => m.unit = value.to_string(),
            "samples" => m.samples = value.parse().ok()?,
            _ => return None,
        }
    }
    let complete = !m.median.is_nan()
        && !m.min.is_nan()
        && !m.max.is_nan()
        && !m.unit.is_empty()
        && m.samples > 0;
    complete.then_some(m)
}

/// The window-start lateness (ns) from an attack victim's last line (`victim: lateness
/// windows=<n> min=<ns> median=<ns> max=<ns> missed=<n> drift=<n>`, tests/programs/attack)
/// as metric `name`.
pub fn parse_victim_lateness(line: &str, name: &str) -> Option<Metric> {
    let field = |key| victim_field(line, key);
    Some(Metric {
        name: name.to_string(),
        median: field("median")? as f64,
        min: field("min")? as f64,
        max: field("max")? as f64,
        unit: "ns".to_string(),
        samples: field("windows")?,
    })
}

/// The soak's metrics from its victim's last line: `soak_window_lateness` (ns), and as
/// counts over all its windows `soak_missed_windows` (windows the victim did not run in)
/// and `soak_window_drift` (window starts the kernel reported off the ideal sequence, the
/// first start plus whole major frames).
pub fn parse_soak(line: &str) -> Option<[Metric; 3]> {
    let lateness = parse_victim_lateness(line, "soak_window_lateness")?;
    let windows = lateness.samples;
    let count = |name: &str, key| {
        let n = victim_field(line, key)? as f64;
        Some(Metric {
            name: name.to_string(),
            median: n,
            min: n,
            max: n,
            unit: "count".to_string(),
            samples: windows,
        })
    };
    Some([
        count("soak_missed_windows", "missed")?,
        count("soak_window_drift", "drift")?,
        lateness,
    ])
}

/// Field `key` of a victim's `victim: lateness ...` line.
fn victim_field(line: &str, key: &str) -> Option<u64> {
    let rest = &line[line.find("victim: lateness ")? + "victim: lateness ".len()..];
    rest.split_whitespace()
        .find_map(|w| w.strip_prefix(key)?.strip_prefix('='))
        .and_then(|v| v.parse().ok())
}

/// `plc_release_jitter` and `plc_cycle_overhead` (ns) from a soft-PLC statistics line
/// (`plc: t=<ms>ms scan releases=<n> lateness_ns=<min>/<median>/<max>
/// overhead_ns=<min>/<median>/<max> ...`, partitions/softplc/runtime/src/main.rs).
pub fn parse_plc_scan(line: &str) -> Option<[Metric; 2]> {
    let rest = &line[line.find(" scan releases=")? + " scan releases=".len()..];
    let mut words = rest.split_whitespace();
    let releases: u64 = words.next()?.parse().ok()?;
    let triple = |word: Option<&str>, key: &str, name: &str| {
        let values: Vec<f64> = word?
            .strip_prefix(key)?
            .split('/')
            .map(|v| v.parse().ok())
            .collect::<Option<_>>()?;
        let [min, median, max] = values[..] else {
            return None;
        };
        Some(Metric {
            name: name.to_string(),
            median,
            min,
            max,
            unit: "ns".to_string(),
            samples: releases,
        })
    };
    Some([
        triple(words.next(), "lateness_ns=", "plc_release_jitter")?,
        triple(words.next(), "overhead_ns=", "plc_cycle_overhead")?,
    ])
}

pub fn format_line(m: &Metric) -> String {
    format!(
        "bench {} median={} min={} max={} unit={} samples={}",
        m.name, m.median, m.min, m.max, m.unit, m.samples
    )
}

/// Runs the host-side benchmarks: the soft-PLC suite (`plc-bench-suite`) on the interpreter
/// (`plc-bench`: `plc_vm_*`), on the native execution tier (`plc-native-bench`:
/// `plc_native_*`) and, when `IRONPLC` names an IronPLC checkout (or its ironplcc), on
/// IronPLC's VM (`plc-ironplc-bench`: `plc_ironplc_*`; else its `skipped: ...` lines go to
/// stderr), each program as ns per cycle and as a ratio to the same algorithm in
/// hand-written Rust; then [`versus_ironplc`]. The legs' diagnostics go to stderr.
pub fn host_metrics() -> Result<Vec<Metric>> {
    let mut metrics = Vec::new();
    for (package, bin) in [
        ("plc-compiler", "plc-bench"),
        ("plc-native", "plc-native-bench"),
        ("plc-bench-suite", "plc-ironplc-bench"),
    ] {
        let out = crate::artifacts::cargo()
            .args(["run", "--quiet", "--release", "-p", package, "--bin", bin])
            .output()
            .with_context(|| format!("cannot run {bin}"))?;
        eprint!("{}", String::from_utf8_lossy(&out.stderr));
        if !out.status.success() {
            bail!("{bin} failed");
        }
        metrics.extend(
            String::from_utf8_lossy(&out.stdout)
                .lines()
                .filter_map(parse_line),
        );
    }
    let versus = versus_ironplc(&metrics);
    metrics.extend(versus);
    Ok(metrics)
}

/// How many times faster the interpreter runs each program than IronPLC's VM:
/// `plc_vm_<name>_vs_ironplc` (unit ratio; median = IronPLC's median over ours, min = its
/// min over our max, max = its max over our min) for every program both legs measured, and
/// `plc_vm_vs_ironplc_geomean` (the geometric mean of the medians, min and max likewise;
/// samples = programs).
pub fn versus_ironplc(metrics: &[Metric]) -> Vec<Metric> {
    let find = |name: &str| metrics.iter().find(|m| m.name == name);
    let mut out = Vec::new();
    for vm in metrics {
        let Some(program) = vm.name.strip_prefix("plc_vm_") else {
            continue;
        };
        if program.ends_with("_ratio") || vm.unit != "ns" {
            continue;
        }
        let Some(ironplc) = find(&format!("plc_ironplc_{program}")) else {
            continue;
        };
        out.push(Metric {
            name: format!("plc_vm_{program}_vs_ironplc"),
            median: ironplc.median / vm.median,
            min: ironplc.min / vm.max,
            max: ironplc.max / vm.min,
            unit: "ratio".to_string(),
            samples: vm.samples.min(ironplc.samples),
        });
    }
    if !out.is_empty() {
        let geomean = |f: fn(&Metric) -> f64| {
            (out.iter().map(|m| f(m).ln()).sum::<f64>() / out.len() as f64).exp()
        };
        let mean = Metric {
            name: "plc_vm_vs_ironplc_geomean".to_string(),
            median: geomean(|m| m.median),
            min: geomean(|m| m.min),
            max: geomean(|m| m.max),
            unit: "ratio".to_string(),
            samples: out.len() as u64,
        };
        out.push(mean);
    }
    out
}

pub fn write_report(metrics: &[Metric]) -> Result<std::path::PathBuf> {
    write_report_as(metrics, "report.json")
}

/// Writes `metrics` to `target/bench/<file>`.
pub fn write_report_as(metrics: &[Metric], file: &str) -> Result<std::path::PathBuf> {
    let dir = crate::target_dir().join("bench");
    std::fs::create_dir_all(&dir)?;
    let path = dir.join(file);
    std::fs::write(&path, serde_json::to_string_pretty(metrics)?)?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summaries_and_percentiles_round_to_three_places() {
        let samples: Vec<f64> = (1..=1000).map(f64::from).collect();
        let m = summary("x", "us", &samples);
        assert_eq!(
            (m.median, m.min, m.max, m.samples),
            (501.0, 1.0, 1000.0, 1000)
        );
        assert_eq!(percentile(&samples, 99.0), 990.0);
        assert_eq!(percentile(&[1234.5], 99.0), 1230.0);
        assert!(percentile(&[], 99.0).is_nan());
        // Large counts stay whole; small values keep three places.
        assert_eq!(significant(12_999_999.9), 13_000_000.0);
        assert_eq!(significant(7_153_210.0), 7_150_000.0);
        assert_eq!(significant(0.012345), 0.0123);
        assert_eq!(significant(-2_345.0), -2_350.0);
    }

    #[test]
    fn parses_metric_lines_with_any_prefix() {
        let m = parse_line("[   1.0] [syssw] bench null_syscall median=1200 min=900 max=40000 unit=cycles samples=10000").unwrap();
        assert_eq!(m.name, "null_syscall");
        assert_eq!(
            (m.median, m.min, m.max, m.samples),
            (1200.0, 900.0, 40000.0, 10000)
        );
        assert_eq!(m.unit, "cycles");
        assert_eq!(
            format_line(&m),
            "bench null_syscall median=1200 min=900 max=40000 unit=cycles samples=10000"
        );
        let r =
            parse_line("bench plc_vm_pid_ratio median=2.5 min=2.1 max=3.75 unit=ratio samples=50")
                .unwrap();
        assert_eq!(r.median, 2.5);
    }

    #[test]
    fn reads_the_victims_lateness() {
        let m = parse_victim_lateness(
            "[   5.1] [victim-1000] victim: lateness windows=999 min=1838 median=2850 max=44559",
            "window_lateness_hostile_restart_loop",
        )
        .unwrap();
        assert_eq!(m.name, "window_lateness_hostile_restart_loop");
        assert_eq!((m.min, m.median, m.max), (1838.0, 2850.0, 44559.0));
        assert_eq!((m.unit.as_str(), m.samples), ("ns", 999));
        assert!(parse_victim_lateness("victim: windows=100 missed=0", "x").is_none());
    }

    #[test]
    fn reads_the_soak() {
        let line = "[  60.2] [victim-100000] victim: lateness windows=99999 min=1838 median=2850 max=9559 missed=2 drift=0";
        let [missed, drift, lateness] = parse_soak(line).unwrap();
        assert_eq!(
            (missed.name.as_str(), missed.max),
            ("soak_missed_windows", 2.0)
        );
        assert_eq!((drift.name.as_str(), drift.max), ("soak_window_drift", 0.0));
        assert_eq!(missed.unit, "count");
        assert_eq!(lateness.name, "soak_window_lateness");
        assert_eq!(
            (lateness.median, lateness.max, lateness.samples),
            (2850.0, 9559.0, 99999)
        );
        // A line without the counts (an older victim) is no soak result.
        assert!(parse_soak("victim: lateness windows=9 min=1 median=2 max=3").is_none());
    }

    #[test]
    fn reads_the_plc_scan_statistics() {
        let line = "[  12.000001] [plc] plc: t=12000ms scan releases=11999 lateness_ns=10900/11500/13100 overhead_ns=4000/4125/9000 forced=0";
        let [jitter, overhead] = parse_plc_scan(line).unwrap();
        assert_eq!(
            (jitter.name.as_str(), jitter.min, jitter.median, jitter.max),
            ("plc_release_jitter", 10_900.0, 11_500.0, 13_100.0)
        );
        assert_eq!((jitter.samples, jitter.unit.as_str()), (11_999, "ns"));
        assert_eq!(
            (overhead.name.as_str(), overhead.median),
            ("plc_cycle_overhead", 4_125.0)
        );
        assert!(parse_plc_scan("[plc] plc: t=1ms scan releases=3 lateness_ns=1/2").is_none());
        assert!(parse_plc_scan("[plc] plc: t=1ms watch x=1").is_none());
    }

    #[test]
    fn compares_the_interpreter_with_ironplc() {
        let lines = [
            "bench plc_vm_pid median=10 min=8 max=20 unit=ns samples=25",
            "bench plc_vm_pid_ratio median=5 min=4 max=6 unit=ratio samples=25",
            "bench plc_ironplc_pid median=20 min=16 max=40 unit=ns samples=25",
            "bench plc_vm_fib median=100 min=100 max=100 unit=ns samples=25",
            "bench plc_ironplc_fib median=800 min=800 max=800 unit=ns samples=25",
            "bench plc_vm_string median=100 min=100 max=100 unit=ns samples=25",
        ];
        let metrics: Vec<Metric> = lines.iter().filter_map(|l| parse_line(l)).collect();
        let versus = versus_ironplc(&metrics);
        let names: Vec<&str> = versus.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "plc_vm_pid_vs_ironplc",
                "plc_vm_fib_vs_ironplc",
                "plc_vm_vs_ironplc_geomean"
            ]
        );
        assert_eq!(
            (versus[0].median, versus[0].min, versus[0].max),
            (2.0, 0.8, 5.0)
        );
        assert!((versus[2].median - 4.0).abs() < 1e-12);
        assert_eq!(versus[2].samples, 2);
        assert!(versus_ironplc(&metrics[..2]).is_empty());
    }

    #[test]
    fn ignores_other_lines_and_incomplete_metrics() {
        assert!(parse_line("kernel: ready").is_none());
        assert!(parse_line("bench x median=1 unit=ns").is_none());
        assert!(parse_line("bench x median=1 min=1 max=1 unit=ns samples=1 bogus=2").is_none());
    }
}
