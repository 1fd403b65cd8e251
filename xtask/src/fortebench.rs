//! The IEC 61499 benchmark of `cargo xtask bench` (alone with `--iec61499`): the same
//! applications on this system's IEC 61499 partition and on 4diac FORTE, the reference
//! runtime, side by side in the same emulator, each timed by the device itself with 4diac's
//! E_STOPWATCH (FORTE's reads `NOW_MONOTONIC()`, ours the partition's clock), so the
//! figures are the devices' own, without the network between the host and them, and follow
//! the bench's time mode (real, or virtual with `--deterministic-time`).
//!
//! - **The applications** (`tests/configs/iec61499/`), each its own resource:
//!   - `bench_loop.fboot`, resource LOOP: an E_CTU `C` (PV 4000) and an E_SWITCH `SW` in a
//!     loop (C.RO and C.CUO to SW.EI with C.Q as G, SW.EO0 back to C.CU) and an E_CTU `N`
//!     counting the loops (SW.EO1 to N.CU); an E_SPLIT `T` starts the watch `W` and then
//!     the loop (C.R), N.CUO stops it. One event triggered at T.EI runs one loop, all in
//!     one event chain: 2·PV + 4 events delivered while the watch runs.
//!   - `bench_chain.fboot`, resource CHAIN: an E_SPLIT `S` starts the watch `W` and then a
//!     chain of 10 E_CTU (C1.CUO to C2.CU, ..., each CV to the next PV), whose last CUO
//!     stops the watch: the time of an event through 10 FBs with their data.
//!   - `bench_cycle.fboot`, resource CYCLE: E_CYCLE `CY` at T#1ms; each of its events
//!     stops the watch `W` (TD: the interval since the event before) and starts it again;
//!     F_MAX `HI` keeps the longest interval and F_MAX `LO` twice the period less the
//!     shortest (through F_SUB `SB`), each fed back through a TIME2TIME (`HT`, `ST`, `LT`:
//!     FORTE types a generic connection only from a typed end); E_CTU `N` counts the
//!     intervals.
//! - **Our leg** boots `tests/configs/bench_iec61499.toml`: the IEC 61499 partition booted
//!   with the loop (the whole frame its window) and its interface on the NIC partition's
//!   switch (the NIC partition in the background), serving 4diac's management protocol on
//!   port 61499.
//! - **FORTE's leg** boots Debian's stock kernel ([`crate::native`], the busybox initramfs
//!   of the network benchmark's guest) with a statically linked `forte` of the same sources
//!   and options as the publish/subscribe tests' ([`crate::forte::static_binary`]),
//!   listening on port 61499 at the same address; the host deploys the same files to it
//!   through the protocol, line by line.
//! - Both legs get the same QEMU network (VT-d, virtio-net on QEMU's user network): a port
//!   of 127.0.0.1 forwarded to 61499, and for FORTE's leg a second one to a port where
//!   busybox `nc` waits for the host's word to end the run.
//! - **The host** ([`measure`]) triggers with 4diac's `WRITE $e` request and reads with
//!   READ: a loop at a time until N.CV counts it, then W.TD, [`LOOPS`] loops a round,
//!   [`ROUNDS`] rounds (a first loop to warm up); a chain at a time until C10.CV counts it,
//!   then W.TD, [`CHAINS`] chains (and one to warm up); CY.START, nothing for
//!   [`CYCLE_QUIET`] (3 s on the host's clock), HT.OUT and LT.OUT for the quiet phase's
//!   extremes, then every 20 ms the last interval (W.TD) until N.CV counts [`CYCLES`]
//!   more, CY.STOP, and HT.OUT and LT.OUT again for the whole run's extremes. (Loops triggered back to back are no measure:
//!   FORTE puts an event from outside into the chain that runs, so a second trigger would
//!   restart the counting loop while it counts.)
//!
//! Metrics: `iec61499_loop_events` (events a second of each round: its loops' events over
//! their watch's times), `iec61499_chain_latency` (us, each chain), `iec61499_cycle_jitter`
//! (us, how far from 1 ms each interval the host sampled was), `iec61499_cycle_jitter_max`
//! (us, how far the farthest interval of the quiet phase was) and
//! `iec61499_cycle_jitter_max_polled` (the same over the whole run: a device that serves
//! a management request between chains delays a timer due meanwhile); FORTE's as
//! `forte_*`; `iec61499_ratio_loop_events` and `iec61499_ratio_chain_latency` (ours over
//! FORTE's, [`crate::native::ratios`]'s arithmetic: above 1 ours has more events a second,
//! below 1 ours is quicker through the chain). Without FORTE's sources (see
//! [`crate::forte::HOW_TO_GET`]) only our leg runs and says so.

use crate::bench::Metric;
use crate::native::Native;
use crate::qemu::{self, Outcome, RunOptions};
use anyhow::{Context, Result, bail};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// Our leg's system description (relative to the workspace).
pub const CONFIG: &str = "tests/configs/bench_iec61499.toml";
/// The three applications, each its own resource (relative to the workspace): our leg
/// boots the loop (the configuration's `iec61499.boot`), the host deploys the others; on
/// FORTE's leg the host deploys all three.
pub const LOOP_BOOT: &str = "tests/configs/iec61499/bench_loop.fboot";
pub const CHAIN_BOOT: &str = "tests/configs/iec61499/bench_chain.fboot";
pub const CYCLE_BOOT: &str = "tests/configs/iec61499/bench_cycle.fboot";
/// The resources of the three applications.
const LOOP: &str = "LOOP";
const CHAIN: &str = "CHAIN";
const CYCLE: &str = "CYCLE";
/// E_CYCLE's period in [`CYCLE_BOOT`] (ns).
pub const CYCLE_PERIOD_NS: i64 = 1_000_000;
/// The address of both legs on QEMU's user network, the management port, and the port of
/// FORTE's leg where `nc` waits for the end.
const ADDRESS: &str = "10.0.2.15";
const MGMT_PORT: u16 = 61499;
const END_PORT: u16 = 5002;
/// Loops a round, and rounds.
pub const LOOPS: u64 = 10;
pub const ROUNDS: usize = 5;
/// Chains timed.
pub const CHAINS: u64 = 50;
/// How long E_CYCLE runs with the host quiet (on the host's clock), the intervals it runs
/// then while the host samples, and the pause between two of the host's samples.
const CYCLE_QUIET: Duration = Duration::from_secs(3);
pub const CYCLES: u64 = 2_000;
/// The fewest intervals a quiet phase must have to count.
const MIN_QUIET_INTERVALS: u64 = 500;
const CYCLE_SAMPLE_PAUSE: Duration = Duration::from_millis(20);
/// The network benchmark's description, whose guest's busybox initramfs FORTE's leg boots.
const INITRAMFS_OF: &str = "tests/configs/bench_net.toml";
/// The pause between two reads of a count not yet reached.
const POLL_PAUSE: Duration = Duration::from_micros(200);
/// Longest wait for one response, one loop or chain, or the cycle's run.
const IO_TIMEOUT: Duration = Duration::from_secs(60);
/// The longest run of a leg.
const LEG_TIMEOUT: Duration = Duration::from_secs(900);
/// The line our leg's partition prints when the host has measured (the test FB it creates
/// then: `iec61499_mgmt::types`'s TEST_CONDITION), which ends its run.
const OUR_END: &str = "TEST_CONDITION_PASSED LOOP.BENCH_END passed";

/// The loop's counting limit, C.PV, as [`LOOP_BOOT`] writes it.
pub fn loop_limit(boot: &str) -> Option<u64> {
    boot.lines()
        .find(|l| l.contains("Destination=\"C.PV\""))?
        .split("Source=\"")
        .nth(1)?
        .split('"')
        .next()?
        .parse()
        .ok()
}

/// Events one loop delivers while its watch runs: C.R, C.RO, PV times C.CU and C.CUO,
/// SW.EO1 and N.CUO.
pub fn events_per_loop(limit: u64) -> u64 {
    2 * limit + 4
}

/// The value a READ answers (`<Connection Source="N.CV" Destination="UINT#5" />`, FORTE's
/// form and ours), as written there.
pub fn read_text(answer: &str) -> Option<&str> {
    answer.split("Destination=\"").nth(1)?.split('"').next()
}

/// A count a READ answers, without its type prefix.
pub fn read_value(answer: &str) -> Option<u64> {
    read_text(answer)?.rsplit('#').next()?.parse().ok()
}

/// A TIME a READ answers (`T#1.686ms` from FORTE, `T#1000ns` from ours), in ns.
pub fn read_time(answer: &str) -> Option<i64> {
    let spec = iec61499_runtime::VarSpec {
        name: String::new(),
        ty: iec61499_runtime::DataType::Time,
        array: None,
    };
    match iec61499_mgmt::literal::parse(read_text(answer)?, &spec) {
        Ok(iec61499_runtime::Value::Time(ns)) => Some(ns),
        _ => None,
    }
}

/// QEMU's network for a leg: `ports[0]` forwarded to the management port, `ports[1]` to
/// [`END_PORT`], on 127.0.0.1 only.
fn qemu_args(ports: [u16; 2]) -> Vec<String> {
    let [mgmt, end] = ports;
    let mut args = qemu::iommu();
    args.extend(qemu::nic_on(&format!(
        "user,hostfwd=tcp:127.0.0.1:{mgmt}-{ADDRESS}:{MGMT_PORT},hostfwd=tcp:127.0.0.1:{end}-{ADDRESS}:{END_PORT}"
    )));
    args
}

/// A management connection: 4diac's framing ([`iec61499_mgmt::tcp`]), one request at a
/// time.
struct Client {
    stream: TcpStream,
    received: Vec<u8>,
    id: u32,
}

impl Client {
    fn connect(port: u16) -> Result<Client> {
        let stream = TcpStream::connect(("127.0.0.1", port))?;
        stream.set_read_timeout(Some(IO_TIMEOUT))?;
        stream.set_nodelay(true)?;
        Ok(Client {
            stream,
            received: Vec::new(),
            id: 0,
        })
    }

    /// Sends `<Request ID=.. Action=action>object</Request>` to `destination` and returns
    /// the response.
    fn ask(&mut self, destination: &str, action: &str, object: &str) -> Result<String> {
        self.id += 1;
        let request = format!(
            "<Request ID=\"{}\" Action=\"{action}\">{object}</Request>",
            self.id
        );
        self.send(destination, &request)
    }

    fn send(&mut self, destination: &str, request: &str) -> Result<String> {
        self.stream
            .write_all(&iec61499_mgmt::tcp::encode_request(destination, request))?;
        loop {
            if let Some((text, used)) = iec61499_mgmt::tcp::read_response(&self.received)
                .map_err(|e| anyhow::anyhow!("not a response: {e:?}"))?
            {
                let text = String::from_utf8_lossy(text).into_owned();
                self.received.drain(..used);
                return Ok(text);
            }
            let mut buf = [0u8; 4096];
            let n = self.stream.read(&mut buf).context("reading a response")?;
            if n == 0 {
                bail!("the device closed the connection");
            }
            self.received.extend_from_slice(&buf[..n]);
        }
    }

    /// Carries out `request`, an error naming it when it is refused.
    fn must(&mut self, destination: &str, request: &str) -> Result<String> {
        let answer = self.send(destination, request)?;
        if answer.contains("Reason=") {
            bail!("{destination};{request} refused: {answer}");
        }
        Ok(answer)
    }

    /// The value of `path` in `resource`, as the READ answers it.
    fn read(&mut self, resource: &str, path: &str) -> Result<String> {
        let object = format!("<Connection Source=\"{path}\" Destination=\"\"/>");
        self.ask(resource, "READ", &object)
    }

    fn count(&mut self, resource: &str, path: &str) -> Result<u64> {
        let answer = self.read(resource, path)?;
        read_value(&answer).with_context(|| format!("READ {resource}.{path}: {answer}"))
    }

    fn time(&mut self, resource: &str, path: &str) -> Result<i64> {
        let answer = self.read(resource, path)?;
        read_time(&answer).with_context(|| format!("READ {resource}.{path}: {answer}"))
    }

    fn trigger(&mut self, resource: &str, path: &str) -> Result<()> {
        let object = format!("<Connection Source=\"$e\" Destination=\"{path}\"/>");
        let answer = self.ask(resource, "WRITE", &object)?;
        if answer.contains("Reason=") {
            bail!("triggering {resource}.{path} refused: {answer}");
        }
        Ok(())
    }

    /// Triggers `trigger` and waits until `counter` reaches `count`. Ours answers the
    /// trigger after its chain, FORTE at once, running the chain on its own thread:
    /// reading all the while would take the emulated CPU from it, so after a first read
    /// the reads start at nine tenths of the time the last run took (`last`) and then come
    /// [`POLL_PAUSE`] apart.
    fn run_once(
        &mut self,
        resource: &str,
        [trigger, counter]: [&str; 2],
        count: u64,
        last: &mut Duration,
    ) -> Result<()> {
        let start = Instant::now();
        self.trigger(resource, trigger)?;
        if self.count(resource, counter)? < count {
            std::thread::sleep((*last * 9 / 10).saturating_sub(start.elapsed()));
        }
        while self.count(resource, counter)? < count {
            if start.elapsed() > IO_TIMEOUT {
                bail!("{resource}.{counter} did not reach {count} within {IO_TIMEOUT:?}");
            }
            std::thread::sleep(POLL_PAUSE);
        }
        *last = start.elapsed();
        Ok(())
    }
}

/// Waits until the device on `port` answers, stopping when `ended` (QEMU ended).
fn connect_when_ready(port: u16, ended: &AtomicBool) -> Result<Client> {
    qemu::when_answering("the device", ended, || {
        Ok(Client::connect(port).ok().and_then(|mut c| {
            c.ask("", "QUERY", "<FB Name=\"*\" Type=\"*\"/>")
                .is_ok()
                .then_some(c)
        }))
    })
}

/// What the host measured on a leg, each from the device's own E_STOPWATCH (the time
/// inside the device, on the leg's clock: real or virtual).
#[derive(Debug, Default)]
pub struct Measured {
    /// Events a second of each round of [`LOOPS`] loops.
    pub loop_events: Vec<f64>,
    /// The time of each chain of 10 FBs (us).
    pub chain_latency: Vec<f64>,
    /// How far from E_CYCLE's period the last interval was at each of the host's samples
    /// (us).
    pub cycle_jitter: Vec<f64>,
    /// How far from the period the farthest interval of the quiet phase was (us).
    pub cycle_jitter_max: f64,
    /// How many intervals the quiet phase had.
    pub cycle_quiet_intervals: u64,
    /// How far from the period the farthest interval of the whole run was (us): the quiet
    /// phase and [`CYCLES`] more while the host read every [`CYCLE_SAMPLE_PAUSE`].
    pub cycle_jitter_max_polled: f64,
}

/// The host side of a leg: deploys `deploy` (boot files' texts), then times the loop, the
/// chain and the cycle, one after the other.
pub fn measure(port: u16, deploy: &[String], ended: &AtomicBool) -> Result<Measured> {
    let boot = std::fs::read_to_string(crate::workspace_root().join(LOOP_BOOT))?;
    let limit = loop_limit(&boot).context("the loop's boot file writes no C.PV")?;
    let mut c = connect_when_ready(port, ended)?;
    for text in deploy {
        for line in iec61499_mgmt::fboot::lines(text).map_err(|e| anyhow::anyhow!("{e}"))? {
            c.must(line.destination, line.request)?;
        }
    }
    let mut measured = Measured::default();
    // The loop: a first one to warm up, then the rounds.
    let mut counted = c.count(LOOP, "N.CV")?;
    let mut last = Duration::ZERO;
    counted += 1;
    c.run_once(LOOP, ["T.EI", "N.CV"], counted, &mut last)?;
    for _ in 0..ROUNDS {
        let mut ns = 0;
        for _ in 0..LOOPS {
            counted += 1;
            c.run_once(LOOP, ["T.EI", "N.CV"], counted, &mut last)?;
            ns += c.time(LOOP, "W.TD")?;
        }
        let events = (LOOPS * events_per_loop(limit)) as f64;
        measured.loop_events.push(events / (ns.max(1) as f64 / 1e9));
    }
    // The chain, likewise.
    let mut last = Duration::ZERO;
    let done = c.count(CHAIN, "C10.CV")?;
    for k in 0..=CHAINS {
        c.run_once(CHAIN, ["S.EI", "C10.CV"], done + k + 1, &mut last)?;
        if k > 0 {
            measured
                .chain_latency
                .push(c.time(CHAIN, "W.TD")? as f64 / 1e3);
        }
    }
    // The cycle: first quiet (the host reads nothing, then the extremes), then sampled
    // while it runs, the extremes again at the end (over both).
    let farthest = |c: &mut Client| -> Result<f64> {
        // HT.OUT is the longest interval, LT.OUT twice the period less the shortest; read
        // first, before the reads that follow can delay an interval.
        let far = c.time(CYCLE, "HT.OUT")?.max(c.time(CYCLE, "LT.OUT")?);
        Ok((far - CYCLE_PERIOD_NS) as f64 / 1e3)
    };
    c.trigger(CYCLE, "CY.START")?;
    std::thread::sleep(CYCLE_QUIET);
    measured.cycle_jitter_max = farthest(&mut c)?;
    measured.cycle_quiet_intervals = c.count(CYCLE, "N.CV")?;
    eprintln!(
        "xtask: E_CYCLE with the host quiet for {CYCLE_QUIET:?}: {} intervals",
        measured.cycle_quiet_intervals
    );
    if measured.cycle_quiet_intervals < MIN_QUIET_INTERVALS {
        bail!(
            "E_CYCLE ran {} intervals in {CYCLE_QUIET:?}, fewer than {MIN_QUIET_INTERVALS}",
            measured.cycle_quiet_intervals
        );
    }
    let start = Instant::now();
    let until = measured.cycle_quiet_intervals + CYCLES;
    loop {
        std::thread::sleep(CYCLE_SAMPLE_PAUSE);
        let intervals = c.count(CYCLE, "N.CV")?;
        let interval = c.time(CYCLE, "W.TD")?;
        let off = (interval - CYCLE_PERIOD_NS).abs();
        measured.cycle_jitter.push(off as f64 / 1e3);
        if intervals >= until {
            break;
        }
        if start.elapsed() > IO_TIMEOUT {
            bail!("{intervals} of {until} cycles within {IO_TIMEOUT:?}");
        }
    }
    c.trigger(CYCLE, "CY.STOP")?;
    measured.cycle_jitter_max_polled = farthest(&mut c)?;
    Ok(measured)
}

/// One leg: `boot` runs QEMU with two free host ports while `host` measures from here and
/// then ends the run; what it measured, or an error with QEMU's transcript.
fn leg(
    name: &str,
    boot: impl FnOnce([u16; 2]) -> Result<Outcome>,
    host: impl FnOnce([u16; 2], &AtomicBool) -> Result<Measured> + Send,
) -> Result<Measured> {
    let ports = crate::scenario::free_host_ports(2)?;
    let ports = [ports[0], ports[1]];
    let (outcome, measured) = qemu::with_host(|| boot(ports), |ended| host(ports, ended));
    let outcome = outcome?;
    match measured {
        Ok(measured) => Ok(measured),
        Err(e) => bail!(
            "the IEC 61499 benchmark's {name} leg failed: {e:#}\n{}",
            outcome.transcript()
        ),
    }
}

/// The texts of boot files (relative to the workspace).
fn texts(files: &[&str]) -> Result<Vec<String>> {
    files
        .iter()
        .map(|f| {
            let path = crate::workspace_root().join(f);
            std::fs::read_to_string(&path)
                .with_context(|| format!("cannot read {}", path.display()))
        })
        .collect()
}

/// A leg's metrics, named `<prefix>iec61499_<name>`.
fn metrics(prefix: &str, m: &Measured) -> Vec<Metric> {
    let line = |name: &str, unit: &str, samples: &[f64]| {
        crate::bench::summary(&format!("{prefix}iec61499_{name}"), unit, samples)
    };
    vec![
        line("loop_events", "events/s", &m.loop_events),
        line("chain_latency", "us", &m.chain_latency),
        line("cycle_jitter", "us", &m.cycle_jitter),
        line("cycle_jitter_max", "us", &[m.cycle_jitter_max]),
        line(
            "cycle_jitter_max_polled",
            "us",
            &[m.cycle_jitter_max_polled],
        ),
    ]
}

/// Runs both legs (ours alone without FORTE's sources) and returns the metrics. `system`
/// is the Warden build our leg boots; each leg's files go under `dir/iec61499/<leg>`.
pub fn run(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    dir: &Path,
    deterministic_time: bool,
) -> Result<Vec<Metric>> {
    let dir = dir.join("iec61499");
    let config = crate::workspace_root().join(CONFIG);
    let mode = if deterministic_time {
        "virtual"
    } else {
        "real"
    };
    let ours = leg(
        "ours",
        |ports| {
            let entries = crate::esp::standard_entries(system, Some(&config))?;
            let esp = crate::esp::assemble(&dir.join("ours/esp"), system, &entries)?;
            eprintln!("xtask: booting the IEC 61499 benchmark system ({mode} time)");
            qemu::run(
                qemu,
                &RunOptions {
                    esp,
                    timeout: Some(LEG_TIMEOUT),
                    echo: false,
                    work_dir: dir.join("ours/state"),
                    deterministic_time,
                    com2: qemu::Com2::Unconnected,
                    done_when: vec![OUR_END.into()],
                    extra_args: qemu_args(ports),
                },
            )
        },
        |ports, ended| {
            let measured = measure(ports[0], &texts(&[CHAIN_BOOT, CYCLE_BOOT])?, ended)?;
            // The end: a test FB whose passing line stops the run.
            let mut c = Client::connect(ports[0])?;
            let fb = "<FB Name=\"BENCH_END\" Type=\"TEST_CONDITION\"/>";
            c.ask(LOOP, "CREATE", fb)?;
            let object = "<Connection Source=\"TRUE\" Destination=\"BENCH_END.check\"/>";
            c.ask(LOOP, "WRITE", object)?;
            // The run ends as the FB passes, perhaps before its answer comes.
            let _ = c.trigger(LOOP, "BENCH_END.REQ");
            Ok(measured)
        },
    )?;
    let mut lines = metrics("guest_", &ours);
    match crate::forte::static_binary()? {
        Some(forte) => {
            let theirs = forte_leg(qemu, &dir, &forte, deterministic_time)?;
            lines.extend(metrics("native_", &theirs));
            // Ratios of the throughput and the latency; the jitter's aim is absolute (and
            // FORTE's may be 0 at its microsecond resolution).
            let compared: Vec<Metric> = lines
                .iter()
                .filter(|m| m.name.ends_with("loop_events") || m.name.ends_with("chain_latency"))
                .cloned()
                .collect();
            lines.extend(crate::native::ratios(&compared)?);
        }
        None => eprintln!(
            "xtask: note: no FORTE for the IEC 61499 benchmark's other leg ({})",
            crate::forte::HOW_TO_GET
        ),
    }
    Ok(lines
        .into_iter()
        .map(|m| Metric {
            name: m
                .name
                .replace("guest_ratio_iec61499_", "iec61499_ratio_")
                .replace("guest_iec61499_", "iec61499_")
                .replace("native_iec61499_", "forte_"),
            ..m
        })
        .collect())
}

/// FORTE's leg on Debian's stock kernel.
fn forte_leg(
    qemu: &crate::tools::Qemu,
    dir: &Path,
    forte: &Path,
    deterministic_time: bool,
) -> Result<Measured> {
    let boots = texts(&[LOOP_BOOT, CHAIN_BOOT, CYCLE_BOOT])?;
    let initramfs_of = crate::workspace_root().join(INITRAMFS_OF);
    leg(
        "FORTE",
        |ports| {
            let kernel = crate::native::ensure_kernel()?;
            let (mut extra_files, modules) =
                crate::netbench::module_files_for(&kernel, crate::netbench::DRIVERS)?;
            let binary =
                std::fs::read(forte).with_context(|| format!("cannot read {}", forte.display()))?;
            extra_files.push(("forte".into(), crate::guest::S_IFREG | 0o755, binary));
            // FORTE in the background; nc ends the run when the host connects.
            let command = format!(
                "/forte -c 0.0.0.0:{MGMT_PORT} >/dev/null 2>&1 & nc -l -p {END_PORT} >/dev/null; kill $!"
            );
            let native = Native {
                init: crate::native::script(
                    &["/bin/sh".into(), "-c".into(), command],
                    &["PATH=/bin".into()],
                    &crate::netbench::native_setup(&modules),
                    &[],
                ),
                extra_files,
                qemu_args: qemu_args(ports),
                timeout: LEG_TIMEOUT,
            };
            let (outcome, _status) = crate::native::boot(
                qemu,
                &initramfs_of,
                &dir.join("forte"),
                deterministic_time,
                native,
            )?;
            Ok(outcome)
        },
        |ports, ended| {
            let measured = measure(ports[0], &boots, ended)?;
            let _ = TcpStream::connect(("127.0.0.1", ports[1]));
            Ok(measured)
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use iec61499_mgmt::device::Device;

    #[test]
    fn reads_of_either_runtime_are_understood() {
        let answer = |value: &str| {
            format!(
                "<Response ID=\"3\">\n  <Connection Source=\"N.CV\" Destination=\"{value}\" />\n</Response>"
            )
        };
        assert_eq!(read_value(&answer("UINT#17")), Some(17));
        assert_eq!(read_value(&answer("17")), Some(17));
        assert_eq!(
            read_value("<Response ID=\"3\" Reason=\"NO_SUCH_OBJECT\" />"),
            None
        );
        // FORTE shows microseconds as decimals of ms, ours whole units.
        assert_eq!(read_time(&answer("T#1.686ms")), Some(1_686_000));
        assert_eq!(read_time(&answer("T#1000ns")), Some(1_000));
        assert_eq!(read_time(&answer("T#7ms")), Some(7_000_000));
    }

    /// Sends `text` to `resource` of `d` at `now`; its answer, which must be no refusal.
    fn ask(d: &mut Device, resource: &str, text: &str, now: i64) -> String {
        let answer = d.execute(resource, text, now);
        assert!(!answer.contains("Reason"), "{resource};{text}: {answer}");
        answer
    }

    fn trigger(d: &mut Device, resource: &str, path: &str, now: i64) {
        let text = format!(
            "<Request ID=\"1\" Action=\"WRITE\"><Connection Source=\"$e\" Destination=\"{path}\"/></Request>"
        );
        ask(d, resource, &text, now);
    }

    fn read(d: &mut Device, resource: &str, path: &str) -> String {
        let text = format!(
            "<Request ID=\"1\" Action=\"READ\"><Connection Source=\"{path}\" Destination=\"\"/></Request>"
        );
        ask(d, resource, &text, 0)
    }

    /// The three boot files deploy on our device (on the host: the stopwatches measure the
    /// chains' instants) and do what the host side expects of them.
    #[test]
    fn the_boot_files_deploy_and_measure() {
        let mut d = Device::new(iec61499_runtime::Limits::default(), 4);
        for text in texts(&[LOOP_BOOT, CHAIN_BOOT, CYCLE_BOOT]).unwrap() {
            for line in iec61499_mgmt::fboot::lines(&text).unwrap() {
                ask(&mut d, line.destination, line.request, 0);
            }
        }
        let boot = std::fs::read_to_string(crate::workspace_root().join(LOOP_BOOT)).unwrap();
        let limit = loop_limit(&boot).unwrap();
        assert_eq!(limit, 4000);
        // One chain: below the resource's limit of events a chain may deliver.
        assert!(events_per_loop(limit) < iec61499_runtime::Limits::default().chain_events as u64);
        trigger(&mut d, LOOP, "T.EI", 5);
        assert_eq!(read_value(&read(&mut d, LOOP, "N.CV")), Some(1));
        assert_eq!(read_time(&read(&mut d, LOOP, "W.TD")), Some(0));
        trigger(&mut d, CHAIN, "S.EI", 5);
        trigger(&mut d, CHAIN, "S.EI", 6);
        assert_eq!(read_value(&read(&mut d, CHAIN, "C10.CV")), Some(2));
        // The cycle: its first event starts the watch, each later one measures an interval.
        trigger(&mut d, CYCLE, "CY.START", 0);
        for k in 1..=5 {
            d.advance(k * CYCLE_PERIOD_NS);
        }
        assert_eq!(read_value(&read(&mut d, CYCLE, "N.CV")), Some(4));
        for path in ["W.TD", "HT.OUT", "LT.OUT"] {
            assert_eq!(
                read_time(&read(&mut d, CYCLE, path)),
                Some(CYCLE_PERIOD_NS),
                "{path}"
            );
        }
    }
}
