//! The IEC 61499 benchmark of `cargo xtask bench` (alone with `--iec61499`): the same
//! application on this system's IEC 61499 partition and on 4diac FORTE, the reference
//! runtime, side by side in the same emulator, always on real time (timed from the host).
//!
//! - **The application** is `tests/configs/iec61499/bench_loop.fboot`: resource LOOP with an
//!   E_CTU `C` (PV 4000) and an E_SWITCH `SW` in a loop (C.RO and C.CUO to SW.EI with C.Q as
//!   G, SW.EO0 back to C.CU) and an E_CTU `N` counting the loops (SW.EO1 to N.CU). One
//!   event triggered at C.R runs one loop: 2·PV + 3 events delivered, all in one event
//!   chain.
//! - **Our leg** boots `tests/configs/bench_iec61499.toml`: the IEC 61499 partition booted
//!   with that file (8 ms of every 10 ms) and its interface on the NIC partition's switch,
//!   serving 4diac's management protocol on port 61499.
//! - **FORTE's leg** boots Debian's stock kernel ([`crate::native`], the busybox initramfs
//!   of the network benchmark's guest) with a statically linked `forte` of the same sources
//!   and options as the publish/subscribe tests' ([`crate::forte::static_binary`]),
//!   listening on port 61499 at the same address; the host deploys the same file to it
//!   through the protocol, line by line.
//! - Both legs get the same QEMU network (VT-d, virtio-net on QEMU's user network): a port
//!   of 127.0.0.1 forwarded to 61499, and for FORTE's leg a second one to a port where
//!   busybox `nc` waits for the host's word to end the run.
//! - **The host** ([`measure`]) triggers C.R with 4diac's `WRITE $e` request and reads
//!   N.CV until the loop is counted, [`LOOPS`] loops one after the other a round,
//!   [`ROUNDS`] rounds, and divides the events by the round's time. Ours answers the
//!   trigger after its chain, FORTE at once, running the chain on its own thread: reading
//!   all the while would take the emulated CPU from it, so after a first read the reads
//!   start at nine tenths of the loop before and then come 0.2 ms apart. A loop's time thus holds a round trip
//!   through the NIC partition on our leg, and up to 0.2 ms more and a few round trips of
//!   reads on FORTE's. (Loops triggered back to back are no measure: FORTE puts an event
//!   from outside into the chain that runs, so a second C.R restarts the counting loop
//!   while it counts.)
//!
//! Metrics (each median, minimum and maximum over the rounds): `iec61499_loop_events` and
//! `forte_loop_events` (events a second) and `iec61499_ratio_loop_events` (ours over
//! FORTE's; [`crate::native::ratios`]'s arithmetic: above 1 ours is faster). Without FORTE's
//! sources (see [`crate::forte::HOW_TO_GET`]) only our leg runs and says so.

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
/// The application both legs run.
pub const BOOT: &str = "tests/configs/iec61499/bench_loop.fboot";
/// The resource, the loop's trigger and its counter in [`BOOT`].
const RESOURCE: &str = "LOOP";
const TRIGGER: &str = "C.R";
const COUNTED: &str = "N.CV";
/// The address of both legs on QEMU's user network, the management port, and the port of
/// FORTE's leg where `nc` waits for the end.
const ADDRESS: &str = "10.0.2.15";
const MGMT_PORT: u16 = 61499;
const END_PORT: u16 = 5002;
/// Loops a round, and rounds.
pub const LOOPS: u64 = 10;
pub const ROUNDS: usize = 5;
/// The network benchmark's description, whose guest's busybox initramfs FORTE's leg boots.
const INITRAMFS_OF: &str = "tests/configs/bench_net.toml";
/// How long a leg may take to answer its first request (booting under TCG).
/// The pause between two reads of a loop not yet counted.
const POLL_PAUSE: Duration = Duration::from_micros(200);
/// Longest wait for one response.
const IO_TIMEOUT: Duration = Duration::from_secs(60);
/// The longest run of a leg.
const LEG_TIMEOUT: Duration = Duration::from_secs(900);
/// The line our leg's partition prints when the host has measured (the test FB it creates
/// then: `iec61499_mgmt::types`'s TEST_CONDITION), which ends its run.
const OUR_END: &str = "TEST_CONDITION_PASSED LOOP.BENCH_END passed";

/// The loop's counting limit, C.PV, as [`BOOT`] writes it.
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

/// Events one loop delivers: the trigger, C.RO, PV times C.CU and C.CUO, SW.EO1.
pub fn events_per_loop(limit: u64) -> u64 {
    2 * limit + 3
}

/// A value as a READ answers it (`<Connection Source="N.CV" Destination="UINT#5" />`,
/// FORTE's form and ours), without its type prefix.
pub fn read_value(answer: &str) -> Option<u64> {
    let value = answer.split("Destination=\"").nth(1)?.split('"').next()?;
    let digits = value.rsplit('#').next()?;
    digits.parse().ok()
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

    fn loops(&mut self) -> Result<u64> {
        let object = format!("<Connection Source=\"{COUNTED}\" Destination=\"\"/>");
        let answer = self.ask(RESOURCE, "READ", &object)?;
        read_value(&answer).with_context(|| format!("READ {COUNTED}: {answer}"))
    }

    fn trigger(&mut self, path: &str) -> Result<()> {
        let object = format!("<Connection Source=\"$e\" Destination=\"{path}\"/>");
        let answer = self.ask(RESOURCE, "WRITE", &object)?;
        if answer.contains("Reason=") {
            bail!("triggering {path} refused: {answer}");
        }
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

/// The host side of a leg: deploys `deploy` (a boot file's text) when given, runs a loop
/// to warm up, then the rounds; the rate of each round (events a second).
pub fn measure(port: u16, deploy: Option<&str>, ended: &AtomicBool) -> Result<Vec<f64>> {
    let boot = std::fs::read_to_string(crate::workspace_root().join(BOOT))?;
    let limit = loop_limit(&boot).context("the boot file writes no C.PV")?;
    let mut c = connect_when_ready(port, ended)?;
    if let Some(text) = deploy {
        for line in iec61499_mgmt::fboot::lines(text).map_err(|e| anyhow::anyhow!("{e}"))? {
            c.must(line.destination, line.request)?;
        }
    }
    let mut counted = c.loops()?;
    // The last loop's time: the next one's reads start at nine tenths of it.
    let mut last = Duration::ZERO;
    let mut one_loop = |c: &mut Client| -> Result<()> {
        let start = Instant::now();
        c.trigger(TRIGGER)?;
        counted += 1;
        if c.loops()? < counted {
            std::thread::sleep((last * 9 / 10).saturating_sub(start.elapsed()));
        }
        while c.loops()? < counted {
            if start.elapsed() > IO_TIMEOUT {
                bail!("loop {counted} not counted within {IO_TIMEOUT:?}");
            }
            std::thread::sleep(POLL_PAUSE);
        }
        last = start.elapsed();
        Ok(())
    };
    one_loop(&mut c)?;
    let mut rates = Vec::new();
    for _ in 0..ROUNDS {
        let start = Instant::now();
        for _ in 0..LOOPS {
            one_loop(&mut c)?;
        }
        let seconds = start.elapsed().as_secs_f64();
        rates.push((LOOPS * events_per_loop(limit)) as f64 / seconds);
    }
    Ok(rates)
}

/// One leg: `boot` runs QEMU with two free host ports while `host` measures from here and
/// then ends the run; the rates, or an error with QEMU's transcript.
fn leg(
    name: &str,
    boot: impl FnOnce([u16; 2]) -> Result<Outcome>,
    host: impl FnOnce([u16; 2], &AtomicBool) -> Result<Vec<f64>> + Send,
) -> Result<Vec<f64>> {
    let ports = crate::scenario::free_host_ports(2)?;
    let ports = [ports[0], ports[1]];
    let (outcome, measured) = qemu::with_host(|| boot(ports), |ended| host(ports, ended));
    let outcome = outcome?;
    match measured {
        Ok(rates) => Ok(rates),
        Err(e) => bail!(
            "the IEC 61499 benchmark's {name} leg failed: {e:#}\n{}",
            outcome.transcript()
        ),
    }
}

/// Runs both legs (ours alone without FORTE's sources) and returns the metrics. `system`
/// is the Warden build our leg boots; each leg's files go under `dir/iec61499/<leg>`.
pub fn run(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    dir: &Path,
) -> Result<Vec<Metric>> {
    let dir = dir.join("iec61499");
    let config = crate::workspace_root().join(CONFIG);
    let ours = leg(
        "ours",
        |ports| {
            let entries = crate::esp::standard_entries(system, Some(&config))?;
            let esp = crate::esp::assemble(&dir.join("ours/esp"), system, &entries)?;
            eprintln!("xtask: booting the IEC 61499 benchmark system (real time)");
            qemu::run(
                qemu,
                &RunOptions {
                    esp,
                    timeout: Some(LEG_TIMEOUT),
                    echo: false,
                    work_dir: dir.join("ours/state"),
                    deterministic_time: false,
                    com2: qemu::Com2::Unconnected,
                    done_when: vec![OUR_END.into()],
                    extra_args: qemu_args(ports),
                },
            )
        },
        |ports, ended| {
            let rates = measure(ports[0], None, ended)?;
            // The end: a test FB whose passing line stops the run.
            let mut c = Client::connect(ports[0])?;
            let fb = "<FB Name=\"BENCH_END\" Type=\"TEST_CONDITION\"/>";
            c.ask(RESOURCE, "CREATE", fb)?;
            let object = "<Connection Source=\"TRUE\" Destination=\"BENCH_END.check\"/>";
            c.ask(RESOURCE, "WRITE", object)?;
            // The run ends as the FB passes, perhaps before its answer comes.
            let _ = c.trigger("BENCH_END.REQ");
            Ok(rates)
        },
    )?;
    let mut metrics = vec![crate::bench::summary(
        "guest_iec61499_loop_events",
        "events/s",
        &ours,
    )];
    match crate::forte::static_binary()? {
        Some(forte) => {
            let theirs = forte_leg(qemu, &dir, &forte)?;
            metrics.push(crate::bench::summary(
                "native_iec61499_loop_events",
                "events/s",
                &theirs,
            ));
            metrics.extend(crate::native::ratios(&metrics)?);
        }
        None => eprintln!(
            "xtask: note: no FORTE for the IEC 61499 benchmark's other leg ({})",
            crate::forte::HOW_TO_GET
        ),
    }
    Ok(metrics
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
fn forte_leg(qemu: &crate::tools::Qemu, dir: &Path, forte: &Path) -> Result<Vec<f64>> {
    let boot = std::fs::read_to_string(crate::workspace_root().join(BOOT))?;
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
            let (outcome, _status) =
                crate::native::boot(qemu, &initramfs_of, &dir.join("forte"), false, native)?;
            Ok(outcome)
        },
        |ports, ended| {
            let rates = measure(ports[0], Some(&boot), ended)?;
            let _ = TcpStream::connect(("127.0.0.1", ports[1]));
            Ok(rates)
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_boot_files_loop_and_reads_of_either_runtime_are_understood() {
        let boot = std::fs::read_to_string(crate::workspace_root().join(BOOT)).unwrap();
        let limit = loop_limit(&boot).unwrap();
        assert_eq!(limit, 4000);
        // One chain: below the resource's limit of events a chain may deliver.
        assert!(events_per_loop(limit) < iec61499_runtime::Limits::default().chain_events as u64);
        assert_eq!(
            read_value(
                "<Response ID=\"3\">\n  <Connection Source=\"N.CV\" Destination=\"UINT#17\" />\n</Response>"
            ),
            Some(17)
        );
        assert_eq!(
            read_value(
                "<Response ID=\"3\">\n  <Connection Source=\"N.CV\" Destination=\"17\" />\n</Response>"
            ),
            Some(17)
        );
        assert_eq!(
            read_value("<Response ID=\"3\" Reason=\"NO_SUCH_OBJECT\" />"),
            None
        );
    }
}
