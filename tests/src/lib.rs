//! QEMU scenario harness: boots the ESP that `cargo xtask test` assembled for a scenario
//! (from `tests/scenarios/NAME.toml`) and hands the outcome to the test's assertions.
//! Run the scenarios through `cargo xtask test [FILTER]`, which builds the images first.

pub mod browser;
pub mod tank;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use xtask::qemu::{self, Outcome, RunOptions};
use xtask::scenario;

/// Boots scenario `name` and returns what happened (its disk image, if it has
/// `disk_sectors`, zeroed first).
pub fn boot(name: &str) -> Outcome {
    boot_beside(name, |_, _| ()).0
}

/// Boots scenario `name` again on the disk image the last boot left (a reset of the
/// machine with the same disk).
pub fn boot_again(name: &str) -> Outcome {
    boot_with(name, false, false, |_, _| ()).0
}

/// Scenario `name`'s disk image (`disk_sectors`), for a test to read or damage between
/// boots.
pub fn disk_image(name: &str) -> std::path::PathBuf {
    scenario::output_dir().join(name).join("disk.img")
}

/// Boots scenario `name` with `host` running on this machine meanwhile (a client of what
/// the system serves through QEMU's `hostfwd`): it gets the ports the scenario's
/// `host_ports` chose (in `{host_port<i>}` order) and a flag set once QEMU has ended, and
/// should return soon after.
pub fn boot_beside<R: Send>(
    name: &str,
    host: impl FnOnce(&[u16], &AtomicBool) -> R + Send,
) -> (Outcome, R) {
    boot_with(name, true, false, host)
}

/// Boots scenario `name` with `host` beside it as [`boot_beside`] does, and stops the
/// system ([`xtask::qemu::Ending::Stopped`]) once `host` has returned and the log has shown
/// the manifest's `done_when` texts: the run lasts as long as the host's part and the
/// virtual time the checks need (bounded by the scenario's timeout), not a fixed time.
pub fn boot_while<R: Send>(
    name: &str,
    host: impl FnOnce(&[u16], &AtomicBool) -> R + Send,
) -> (Outcome, R) {
    boot_with(name, true, true, host)
}

/// Boots scenarios `a` and `b` at once, as two machines: both get the same free host
/// ports (as many as the larger `host_ports`), so that `-netdev dgram` in their manifests
/// can join them on 127.0.0.1 (`{host_port0}` local on one, remote on the other).
pub fn boot_pair(a: &str, b: &str) -> (Outcome, Outcome) {
    let load = |name: &str| {
        let manifest = scenario::scenarios_dir().join(format!("{name}.toml"));
        let s = scenario::load(&manifest).unwrap_or_else(|e| panic!("{e:#}"));
        let dir = scenario::output_dir().join(name);
        assert!(
            dir.join("esp").join("system.img").is_file(),
            "no image for scenario {name}: run `cargo xtask test {name}`"
        );
        (s, dir)
    };
    let ((sa, dir_a), (sb, dir_b)) = (load(a), load(b));
    let tools = xtask::tools::ensure_qemu().unwrap_or_else(|e| panic!("{e:#}"));
    let ports = scenario::free_host_ports(sa.manifest.host_ports.max(sb.manifest.host_ports))
        .unwrap_or_else(|e| panic!("scenarios {a}, {b}: {e:#}"));
    std::thread::scope(|scope| {
        let other = scope.spawn(|| run(&sb, &dir_b, dir_b.join("esp"), &tools, &ports, None));
        let first = run(&sa, &dir_a, dir_a.join("esp"), &tools, &ports, None);
        let second = other
            .join()
            .unwrap_or_else(|_| panic!("booting {b} panicked"));
        (
            first.unwrap_or_else(|e| panic!("cannot run QEMU: {e:#}")),
            second.unwrap_or_else(|e| panic!("cannot run QEMU: {e:#}")),
        )
    })
}

fn boot_with<R: Send>(
    name: &str,
    fresh_disk: bool,
    stop_with_host: bool,
    host: impl FnOnce(&[u16], &AtomicBool) -> R + Send,
) -> (Outcome, R) {
    let manifest = scenario::scenarios_dir().join(format!("{name}.toml"));
    let s = scenario::load(&manifest).unwrap_or_else(|e| panic!("{e:#}"));
    let dir = scenario::output_dir().join(name);
    let esp = dir.join("esp");
    assert!(
        esp.join("system.img").is_file(),
        "no image for scenario {name}: run `cargo xtask test {name}`"
    );
    let tools = xtask::tools::ensure_qemu().unwrap_or_else(|e| panic!("{e:#}"));
    let ports = scenario::free_host_ports(s.manifest.host_ports)
        .unwrap_or_else(|e| panic!("scenario {name}: {e:#}"));
    if let Some(sectors) = s.manifest.disk_sectors {
        let image = disk_image(name);
        if fresh_disk || !image.is_file() {
            let file = std::fs::File::create(&image)
                .unwrap_or_else(|e| panic!("cannot create {}: {e}", image.display()));
            file.set_len(sectors * 512)
                .unwrap_or_else(|e| panic!("cannot size {}: {e}", image.display()));
        }
    }
    let ended = AtomicBool::new(false);
    let host_returned = AtomicBool::new(false);
    std::thread::scope(|scope| {
        let client = scope.spawn(|| {
            let result = host(&ports, &ended);
            host_returned.store(true, Ordering::SeqCst);
            result
        });
        // The flag is set whatever happened, so the host side ends before a panic here.
        let outcome = run(
            &s,
            &dir,
            esp,
            &tools,
            &ports,
            stop_with_host.then_some(&host_returned),
        );
        ended.store(true, Ordering::SeqCst);
        let result = client.join();
        let outcome = outcome.unwrap_or_else(|e| panic!("cannot run QEMU: {e:#}"));
        let result = result.unwrap_or_else(|_| panic!("the host side of {name} panicked"));
        (outcome, result)
    })
}

fn run(
    s: &scenario::Scenario,
    dir: &std::path::Path,
    esp: std::path::PathBuf,
    tools: &xtask::tools::Qemu,
    ports: &[u16],
    stop: Option<&AtomicBool>,
) -> anyhow::Result<Outcome> {
    let options = RunOptions {
        esp,
        timeout: Some(Duration::from_secs(s.manifest.timeout_secs)),
        echo: false,
        work_dir: dir.join("state"),
        deterministic_time: s.manifest.deterministic_time,
        done_when: s.manifest.done_when.clone(),
        extra_args: scenario::with_disk(
            &scenario::with_host_ports(&s.manifest.qemu_args, ports),
            &dir.join("disk.img"),
        ),
        com2: if s.manifest.console_input.is_empty() {
            qemu::Com2::Unconnected
        } else {
            qemu::Com2::Scripted {
                start: s.manifest.console_start.clone(),
                input: s.manifest.console_input.clone(),
            }
        },
    };
    match stop {
        Some(flag) => qemu::run_until(tools, &options, flag),
        None => qemu::run(tools, &options),
    }
}

/// Panics with the full transcript unless `cond` holds.
pub fn check(outcome: &Outcome, cond: bool, what: &str) {
    assert!(cond, "{what}\n{}", outcome.transcript());
}

/// Boots scenario `name`, whose root task is the user-mode test program in `mode`, and
/// asserts: success exit, no failed check, no panic, each of `checks` as a `check ok:`
/// line, and the mode's final `all <mode> checks passed` line.
pub fn passes(name: &str, mode: &str, checks: &[&str]) -> Outcome {
    let o = boot(name);
    check(
        &o,
        o.line("check FAILED").is_none(),
        "a check failed (see `check FAILED` in the log)",
    );
    check(&o, o.line("panic at ").is_none(), "a user-mode panic");
    check(&o, o.succeeded(), "expected success exit (33)");
    for what in checks {
        let line = format!("check ok: {what}");
        check(&o, o.line(&line).is_some(), &format!("missing {line:?}"));
    }
    let last = format!("all {mode} checks passed");
    check(&o, o.line(&last).is_some(), &format!("missing {last:?}"));
    o
}

/// The text of partition `partition`'s log lines that contain `needle`, without the
/// kernel's time stamp and the partition prefix, in log order.
pub fn partition_lines(o: &Outcome, partition: &str, needle: &str) -> Vec<String> {
    let prefix = format!("[{partition}] ");
    o.lines
        .iter()
        .filter_map(|l| l.split_once(&prefix).map(|(_, text)| text.to_string()))
        .filter(|text| text.contains(needle))
        .collect()
}

/// What the processes of guest partition `partition` wrote to standard output (their
/// `guest: process <pid> stdout: ...` log lines), line by line in log order.
pub fn guest_stdout(o: &Outcome, partition: &str) -> Vec<String> {
    let prefix = format!("[{partition}] guest: process ");
    o.lines
        .iter()
        .filter_map(|l| l.split_once(&prefix).map(|(_, text)| text))
        .filter_map(|text| text.split_once(" stdout: ").map(|(_, t)| t.to_string()))
        .collect()
}

/// What the processes of the guest partition `linux` wrote (its `guest: process <pid>
/// stdout: ...` and `stderr: ...` log lines), in order.
pub fn guest_output(o: &Outcome) -> Vec<String> {
    o.lines
        .iter()
        .filter_map(|l| l.split_once("[linux] guest: process "))
        .filter_map(|(_, text)| {
            let (_, rest) = text.split_once(' ')?;
            rest.strip_prefix("stdout: ")
                .or_else(|| rest.strip_prefix("stderr: "))
                .map(str::to_string)
        })
        .collect()
}

/// One HTTP/1.0 GET of `path` from 127.0.0.1:`port` (a port QEMU forwards to a guest):
/// the status line and the body, or `None` when the connection failed or was closed
/// without an answer (QEMU accepts on the forwarded port before the guest listens, then
/// closes).
pub fn http_get(port: u16, path: &str) -> Option<(String, String)> {
    let mut stream =
        TcpStream::connect_timeout(&([127, 0, 0, 1], port).into(), Duration::from_secs(5)).ok()?;
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .ok()?;
    stream
        .set_write_timeout(Some(Duration::from_secs(10)))
        .ok()?;
    write!(stream, "GET {path} HTTP/1.0\r\nHost: guest\r\n\r\n").ok()?;
    let mut answer = Vec::new();
    stream.read_to_end(&mut answer).ok()?;
    let answer = String::from_utf8_lossy(&answer).into_owned();
    // The head ends at the first empty line (a CGI script's own header lines end in a
    // bare "\n", which busybox httpd passes on).
    let end = ["\r\n\r\n", "\n\n", "\r\n\n"]
        .iter()
        .filter_map(|sep| answer.find(sep).map(|at| (at, at + sep.len())))
        .min()?;
    let (head, body) = (&answer[..end.0], &answer[end.1..]);
    Some((head.lines().next()?.to_string(), body.to_string()))
}

/// One Modbus/TCP request ADU to 127.0.0.1:`port` (a port QEMU forwards to the PLC) on a
/// new connection: the response's bytes (empty when the PLC closed the connection).
pub fn modbus_exchange(port: u16, adu: &[u8]) -> std::io::Result<Vec<u8>> {
    let mut s = TcpStream::connect_timeout(&([127, 0, 0, 1], port).into(), Duration::from_secs(5))?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    s.write_all(adu)?;
    let mut out = vec![0u8; 260];
    let n = s.read(&mut out)?;
    out.truncate(n);
    Ok(out)
}

/// The tank's level (`%IL0`: input registers 0..3, unit 1) read over Modbus/TCP with our
/// own frame, or `None` without an answer.
pub fn modbus_level(port: u16) -> Option<f64> {
    let r = modbus_exchange(port, &[0, 1, 0, 0, 0, 6, 1, 4, 0, 0, 0, 4]).ok()?;
    if r.len() != 9 + 8 || r[7] != 4 || r[8] != 8 {
        return None;
    }
    let mut bytes = [0u8; 8];
    for i in 0..4 {
        // Each register big-endian on the wire, the image's words little-endian.
        bytes[2 * i] = r[9 + 2 * i + 1];
        bytes[2 * i + 1] = r[9 + 2 * i];
    }
    Some(f64::from_le_bytes(bytes))
}

/// The kernel's time stamp of a log line, `[SSSS.UUUUUU] ...`, in seconds.
pub fn kernel_seconds(line: &str) -> Option<f64> {
    line.strip_prefix('[')?
        .split_once(']')?
        .0
        .trim()
        .parse()
        .ok()
}

/// The PLC's worst release lateness (ns) of each second, split by how many frames the NIC
/// took from the wire then.
#[derive(Debug, Default)]
pub struct LatenessByLoad {
    /// Seconds with at least `loud` frames.
    pub loud: Vec<u64>,
    /// Seconds with at most `quiet` frames, once the tank has settled.
    pub quiet: Vec<u64>,
    /// The most frames the NIC took in a second.
    pub peak: u64,
}

/// The PLC (partition `plc`, a 10 ms task) kept every cycle: each of its period lines
/// after the first second counts a release per 10 ms frame.
pub fn plc_kept_every_cycle(o: &Outcome) {
    for line in &o.lines {
        if let Some(("plc", period)) = xtask::plot::period_line(line)
            && period.t_ms > 1_000
        {
            check(
                o,
                period.releases >= 99,
                &format!("{line}: a cycle was missed (one per 10 ms frame)"),
            );
        }
    }
}

/// Each PLC period line (covering the second before it) goes with the NIC's uplink counter
/// line nearest in kernel time: loud (at least `loud` frames that second), quiet (at most
/// `quiet`, after [`tank::SETTLED_MS`]), or neither (a storm's edges).
pub fn plc_lateness_by_load(o: &Outcome, loud: u64, quiet: u64) -> LatenessByLoad {
    let uplink_in = |line: &str| -> Option<u64> {
        let at = line.find(" uplink in=")? + " uplink in=".len();
        line[at..].split(' ').next()?.parse().ok()
    };
    let mut rates = Vec::new();
    let mut last = 0;
    for line in &o.lines {
        if let (Some(at), Some(n)) = (kernel_seconds(line), uplink_in(line)) {
            rates.push((at, n - last.min(n)));
            last = n;
        }
    }
    let mut split = LatenessByLoad {
        peak: rates.iter().map(|r| r.1).max().unwrap_or(0),
        ..LatenessByLoad::default()
    };
    for line in &o.lines {
        let (Some(at), Some(("plc", period))) =
            (kernel_seconds(line), xtask::plot::period_line(line))
        else {
            continue;
        };
        let Some(&(_, rate)) = rates
            .iter()
            .min_by(|a, b| (a.0 - at).abs().total_cmp(&(b.0 - at).abs()))
        else {
            continue;
        };
        if rate >= loud {
            split.loud.push(period.lateness_ns.2);
        } else if rate <= quiet && period.t_ms >= tank::SETTLED_MS {
            split.quiet.push(period.lateness_ns.2);
        }
    }
    split
}

/// A real program in the guest against the same program on this machine: runs `host`
/// (which must succeed), boots `scenario`, and checks that the guest partition `partition`
/// printed the same lines on standard output and nothing on standard error, that no
/// partition panicked, no system call was unsupported and no process was killed by a
/// signal, that the guest's init exited with status 0 and the run ended with success.
/// Returns the run and the host's lines.
pub fn same_output_as_host(
    scenario: &str,
    partition: &str,
    host: &mut std::process::Command,
) -> (Outcome, Vec<String>) {
    let ran = host
        .output()
        .unwrap_or_else(|e| panic!("running {host:?}: {e}"));
    assert!(ran.status.success(), "on the host: {host:?}: {ran:?}");
    let expected: Vec<String> = String::from_utf8_lossy(&ran.stdout)
        .lines()
        .map(str::to_string)
        .collect();
    let o = boot(scenario);
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    let printed = guest_stdout(&o, partition);
    check(
        &o,
        printed == expected,
        &format!("the guest printed {printed:#?}, the host {expected:#?}"),
    );
    for needle in ["unsupported system call", "killed by signal", " stderr: "] {
        let found = partition_lines(&o, partition, needle);
        check(&o, found.is_empty(), &format!("{needle:?}: {found:?}"));
    }
    check(
        &o,
        !partition_lines(&o, partition, "guest: init exited with status 0").is_empty(),
        "the guest's init did not exit with status 0",
    );
    check(&o, o.succeeded(), "expected success exit (33)");
    (o, expected)
}
