//! The PLC network benchmark of `cargo xtask bench`: the soft-PLC's services on its own
//! interface, timed from the host, always on real time (what is timed is a round trip
//! through QEMU's network on the host's clock). It boots `tests/configs/net_modbus.toml`
//! (the tank PLC with `plc.net`, Modbus/TCP on port 502 and the online protocol on TCP port
//! 1202) with both ports forwarded from free ports of 127.0.0.1, then:
//!
//! 1. waits [`QUIET`] with no traffic (the quiet seconds);
//! 2. polls as a SCADA system does: pymodbus (tests/scripts/modbus_bench.py, from the venv
//!    target/pymodbus-venv, made here when missing) reads 10 holding registers
//!    [`MODBUS_READS`] times at [`POLL_HZ`] Hz over [`POLL_CONNECTIONS`] connections (a
//!    round trip takes about two PLC periods, so one connection cannot ask 100 times a
//!    second);
//! 3. reads the level [`ONLINE_READS`] times over an authenticated online session
//!    (plcctl's [`plcctl::tcp::TcpSession`], key tests/configs/keys/engineering.key).
//!
//! Metrics: `plc_net_modbus_read10` (us, the round trips' median, minimum, maximum) and
//! `plc_net_modbus_read10_p99` (us, their 99th percentile), `plc_net_online_read` and
//! `plc_net_online_read_p99` (the same for the online READ), and
//! `plc_net_lateness_quiet` and `plc_net_lateness_polled` (us, the PLC's release lateness:
//! over the seconds without a request and the seconds of the poll, each second's maximum
//! from the PLC's period lines; median, minimum and maximum over those seconds).

use crate::bench::Metric;
use crate::qemu::{self, RunOptions};
use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// The benchmark's system description (relative to the workspace).
pub const CONFIG: &str = "tests/configs/net_modbus.toml";
/// The PLC's address and ports in [`CONFIG`].
const PLC: &str = "10.0.2.15";
const MODBUS_PORT: u16 = 502;
const ONLINE_PORT: u16 = 1202;
/// How long the quiet part lasts.
const QUIET: Duration = Duration::from_secs(10);
/// The SCADA poll: requests and their rate.
const MODBUS_READS: usize = 1_000;
const POLL_HZ: u32 = 100;
const POLL_CONNECTIONS: usize = 4;
/// Online READs, one after another.
const ONLINE_READS: usize = 300;
/// The longest run (QEMU is stopped then).
const RUN_TIMEOUT: Duration = Duration::from_secs(600);
/// What pymodbus the venv gets (as .ci/run installs it).
const PYMODBUS: &str = "pymodbus>=3,<4";

/// The venv's python with pymodbus, made when missing.
pub fn ensure_pymodbus() -> Result<PathBuf> {
    let venv = crate::target_dir().join("pymodbus-venv");
    let python = venv.join("bin").join("python");
    let has = |python: &Path| {
        std::process::Command::new(python)
            .args(["-c", "import pymodbus"])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if has(&python) {
        return Ok(python);
    }
    eprintln!("xtask: making {} with {PYMODBUS} from PyPI", venv.display());
    let status = std::process::Command::new("python3")
        .args(["-m", "venv"])
        .arg(&venv)
        .status()
        .context("cannot run python3 (install python3 and python3-venv)")?;
    if !status.success() {
        bail!(
            "python3 -m venv {} failed (install python3-venv)",
            venv.display()
        );
    }
    let status = std::process::Command::new(venv.join("bin").join("pip"))
        .args(["install", "-q", PYMODBUS])
        .status()
        .context("cannot run the venv's pip")?;
    if !status.success() || !has(&python) {
        bail!("pip install '{PYMODBUS}' into {} failed", venv.display());
    }
    Ok(python)
}

/// Boots the system and measures; the metrics, or an error with QEMU's transcript.
pub fn run(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    dir: &Path,
) -> Result<Vec<Metric>> {
    let python = ensure_pymodbus()?;
    let config = crate::workspace_root().join(CONFIG);
    let dir = dir.join("plc_net");
    let ports = crate::scenario::free_host_ports(2)?;
    let (modbus, online) = (ports[0], ports[1]);
    let entries = crate::esp::standard_entries(system, Some(&config))?;
    let esp = crate::esp::assemble(&dir.join("esp"), system, &entries)?;
    eprintln!("xtask: booting the PLC network benchmark system (real time)");
    let boot = || {
        qemu::run(
            qemu,
            &RunOptions {
                esp,
                timeout: Some(RUN_TIMEOUT),
                echo: false,
                work_dir: dir.join("state"),
                deterministic_time: false,
                com2: qemu::Com2::Unconnected,
                done_when: vec![" malformed=1 ".into()],
                extra_args: [
                    qemu::iommu(),
                    qemu::nic(&[(modbus, PLC, MODBUS_PORT), (online, PLC, ONLINE_PORT)]),
                ]
                .concat(),
            },
        )
    };
    let (outcome, measured) =
        qemu::with_host(boot, |ended| measure(&python, modbus, online, ended));
    let outcome = outcome?;
    let mut metrics = match measured {
        Ok(m) => m,
        Err(e) => bail!(
            "the PLC network benchmark failed: {e:#}\n{}",
            outcome.transcript()
        ),
    };
    let (quiet, polled) = lateness_by_polling(&outcome.lines, POLL_HZ as u64 / 2);
    if quiet.is_empty() || polled.is_empty() {
        bail!(
            "the PLC network benchmark has {} quiet and {} polled seconds of period lines\n{}",
            quiet.len(),
            polled.len(),
            outcome.transcript()
        );
    }
    metrics.push(crate::bench::summary(
        "plc_net_lateness_quiet",
        "us",
        &quiet,
    ));
    metrics.push(crate::bench::summary(
        "plc_net_lateness_polled",
        "us",
        &polled,
    ));
    Ok(metrics)
}

/// The host side: the quiet wait, the SCADA poll, the online READs.
fn measure(python: &Path, modbus: u16, online: u16, ended: &AtomicBool) -> Result<Vec<Metric>> {
    qemu::when_answering("the PLC's Modbus server", ended, || {
        poll(python, modbus, 1, 1)
    })?;
    std::thread::sleep(QUIET);
    let modbus_trips = poll(python, modbus, MODBUS_READS, POLL_CONNECTIONS)?
        .context("pymodbus's poll failed (its output above)")?;
    let key = crate::workspace_root().join("tests/configs/keys/engineering.key");
    let key = plcctl::tcp::read_key(&key.display().to_string())
        .map_err(|f| anyhow::anyhow!(f.message))?;
    let session = plcctl::tcp::TcpSession::connect(
        &format!("127.0.0.1:{online}"),
        "engineering",
        &key,
        Duration::from_secs(10),
    )
    .map_err(|f| anyhow::anyhow!(f.message))?;
    let mut link = plcctl::Link::new(session, Duration::from_secs(10));
    let mut online_trips = Vec::with_capacity(ONLINE_READS);
    for _ in 0..ONLINE_READS {
        let start = Instant::now();
        let (status, _) = link
            .ask(&plc_online::Request::Read { name: "level" })
            .map_err(|f| anyhow::anyhow!(f.message))?;
        if status != plc_online::Status::Ok {
            bail!("online READ level: {status:?}");
        }
        online_trips.push(start.elapsed().as_secs_f64() * 1e6);
    }
    // A malformed frame: the PLC counts it (`malformed=1` in its statistics line), which
    // ends the run.
    let _ = std::net::TcpStream::connect(("127.0.0.1", modbus)).and_then(|mut s| {
        use std::io::Write;
        s.write_all(&[0, 1, 0, 1, 0, 6, 1, 3, 0, 0, 0, 1])
    });
    let mut metrics = Vec::new();
    for (name, trips) in [
        ("plc_net_modbus_read10", &modbus_trips),
        ("plc_net_online_read", &online_trips),
    ] {
        metrics.push(crate::bench::summary(name, "us", trips));
        let p99 = crate::bench::percentile(trips, 99.0);
        metrics.push(Metric {
            name: format!("{name}_p99"),
            median: p99,
            min: p99,
            max: p99,
            unit: "us".into(),
            samples: trips.len() as u64,
        });
    }
    Ok(metrics)
}

/// `count` Modbus reads of 10 holding registers by pymodbus at [`POLL_HZ`] over
/// `connections`: each round trip (us), or `None` when pymodbus failed.
fn poll(python: &Path, port: u16, count: usize, connections: usize) -> Result<Option<Vec<f64>>> {
    let script = crate::workspace_root().join("tests/scripts/modbus_bench.py");
    let out = std::process::Command::new(python)
        .arg(script)
        .args([
            port.to_string(),
            count.to_string(),
            POLL_HZ.to_string(),
            connections.to_string(),
        ])
        .output()
        .context("cannot run pymodbus")?;
    if !out.status.success() {
        if count > 1 {
            eprintln!(
                "xtask: pymodbus: {}{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
        }
        return Ok(None);
    }
    Ok(Some(
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter_map(|l| l.strip_prefix("roundtrip_us ")?.parse().ok())
            .collect(),
    ))
}

/// The PLC's release lateness (us, each period line's maximum) in the seconds without
/// requests and in those with at least `polled` requests, telling them apart by the
/// communication process's statistics lines (`plc: t=<ms>ms net ... requests=<n>`, written
/// each second in which something changed).
pub fn lateness_by_polling(lines: &[String], polled: u64) -> (Vec<f64>, Vec<f64>) {
    let field = |line: &str, key: &str| -> Option<u64> {
        let at = line.find(key)? + key.len();
        line[at..]
            .split(|c: char| !c.is_ascii_digit())
            .next()?
            .parse()
            .ok()
    };
    // Requests per second of PLC time, by the second the statistics line closes.
    let mut requests = std::collections::BTreeMap::new();
    let mut last = 0;
    for line in lines.iter().filter(|l| l.contains("ms net open=")) {
        if let (Some(t), Some(n)) = (field(line, "plc: t="), field(line, " requests=")) {
            requests.insert(t / 1000, n.saturating_sub(last));
            last = n;
        }
    }
    let (mut quiet, mut loud) = (Vec::new(), Vec::new());
    let first_request = requests.keys().next().copied().unwrap_or(u64::MAX);
    for line in lines {
        let Some(("plc", period)) = crate::plot::period_line(line) else {
            continue;
        };
        let second = period.t_ms / 1000;
        let late = period.lateness_ns.2 as f64 / 1000.0;
        match requests.get(&second) {
            Some(&n) if n >= polled => loud.push(late),
            // Quiet: no statistics line that second, after the first request (the boot's
            // first seconds are neither).
            None if second > first_request => quiet.push(late),
            _ => {}
        }
    }
    (quiet, loud)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_are_quiet_or_polled_by_the_requests_the_plc_counted() {
        let net = |t: u64, n: u64| {
            format!(
                "[   1.0] [plc] plc: t={t}ms net open=1 accepted=1 refused=0 malformed=0 requests={n} responses={n} denied=0 rejected=0 frames_in=1 frames_out=1"
            )
        };
        let period = |t: u64, max: u64| {
            format!(
                "[   1.0] [plc] plc: t={t}ms period releases=100 lateness_ns=1/2/{max} histogram_ns=1-2:100"
            )
        };
        let lines: Vec<String> = vec![
            period(1009, 9_000), // before the first request: neither
            net(2009, 1),
            period(2009, 5_000), // the probe's second: 1 request, neither
            period(3009, 6_000), // quiet
            period(4009, 7_000), // quiet
            net(5009, 101),
            period(5009, 8_000), // 100 requests: polled
            net(6009, 120),
            period(6009, 9_000), // 19: neither
        ];
        let (quiet, polled) = lateness_by_polling(&lines, 50);
        assert_eq!(quiet, [6.0, 7.0]);
        assert_eq!(polled, [8.0]);
    }
}
