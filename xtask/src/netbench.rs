//! The network benchmark of `cargo xtask bench` (alone with `--net`): the guest's TCP/IP
//! through the NIC partition against Debian's stock kernel on the same emulated NIC.
//!
//! - **The guest leg** boots `tests/configs/bench_net.toml` (the NIC partition and its one
//!   tenant, the guest, whose `/etc/net_bench.sh` starts busybox `httpd` on port 80 and
//!   `linux-netserve`, `tests/linux/netserve.c`, on port [`SERVE_PORT`]).
//! - **The native leg** boots Debian's stock kernel ([`crate::native`]) with the same
//!   guest partition's initramfs, the virtio-net driver's modules from
//!   `/lib/modules/<version>` ([`DRIVERS`] and what they need) loaded by `/init`, `eth0` at the guest's
//!   address and default route, and the same script.
//! - Both legs get the same machine and network ([`qemu_args`]): the benchmark system's
//!   CPUs (`[system] cpus` of [`CONFIG`]: the NIC partition on CPU 0, the guest on CPU 1,
//!   as in the default system; the stock kernel gets as many), VT-d, QEMU's virtio-net
//!   with the modern PCI transport only and `iommu_platform=on` at 00:03.0, on QEMU's
//!   user network with two ports of 127.0.0.1 (free ones,
//!   [`crate::scenario::free_host_ports`]) forwarded to the guest: TCP and UDP to
//!   [`SERVE_PORT`], TCP to port 80. Nothing listens on another interface of the host.
//! - The host side ([`measure`], std::net) times everything on the host's clock, so the
//!   legs always run on real time (QEMU's own network code on the host runs on it anyway):
//!   bulk TCP both ways in 64 KiB writes, a 64-byte TCP request/response, a 64-byte UDP
//!   datagram and its echo, and busybox httpd serving a 1 KiB page, each over a bounded
//!   count. Its last request ends `linux-netserve` and with it the run.
//!
//! The legs run in [`PAIRS`] pairs, a guest leg then a native leg. Metrics (`<leg>` is
//! `guest` or `native`; each the median of the pairs' medians over their rounds, and the
//! least minimum and greatest maximum): `<leg>_net_tcp_to_host` and
//! `<leg>_net_tcp_from_host` (MB/s, 10^6 bytes a second), `<leg>_net_tcp_roundtrip` and
//! `<leg>_net_udp_roundtrip` (us, a round's mean), `<leg>_net_httpd` (requests/s, one
//! connection at a time), and `net_ratio_<metric>` (guest / native within each pair,
//! [`crate::native::ratios`]'s arithmetic, then the median of the pairs': for the
//! throughputs and the request rate below 1 the guest is slower, for the round trips above
//! 1).

use crate::bench::Metric;
use crate::native::Native;
use crate::qemu::{self, Outcome, RunOptions};
use anyhow::{Context, Result, bail};
use std::io::{Read, Write};
use std::net::{Shutdown, TcpStream, UdpSocket};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// The benchmark's system description (relative to the workspace).
pub const CONFIG: &str = "tests/configs/bench_net.toml";
/// `linux-netserve`'s TCP and UDP port in the guest.
pub const SERVE_PORT: u16 = 5001;
/// busybox httpd's port in the guest.
pub const HTTP_PORT: u16 = 80;
/// The guest's address on QEMU's user network (`guest.net` of [`CONFIG`]; the native
/// leg's `eth0` gets the same).
pub const GUEST_ADDRESS: &str = "10.0.2.15";
/// QEMU's user-network gateway.
pub const GATEWAY: &str = "10.0.2.2";
/// The stock kernel's modules that drive QEMU's virtio-net (Debian builds them as
/// modules); [`load_order`] adds what they depend on from the kernel's `modules.dep`.
pub const DRIVERS: &[&str] = &["virtio_pci", "virtio_net"];

/// The size of every bulk write (and of the guest's).
const BLOCK: usize = 64 * 1024;
/// Blocks of a bulk transfer (32 MiB: half a second or more here, so that the figure is
/// the stream's rate, not its first round trips; 4 MiB took under 0.1 s and gave the
/// guest two thirds of its rate), and transfers a direction.
const BULK_BLOCKS: u32 = 512;
const BULK_ROUNDS: usize = 3;
/// Round trips a round, and rounds, of the TCP and UDP round trips.
const TRIPS: usize = 100;
const TRIP_ROUNDS: usize = 5;
/// The size of a request and of its answer.
const MESSAGE: usize = 64;
/// Pairs of legs (a guest leg, then a native leg): the host's load moves the real-time
/// figures of one leg by a factor of 2 or more within minutes, so a ratio is taken within
/// each pair and the pairs' median reported.
const PAIRS: usize = 3;
/// Page requests a round, and rounds.
const REQUESTS: usize = 30;
const REQUEST_ROUNDS: usize = 3;
/// The page busybox httpd serves (tests/configs/guest/net_bench.sh writes it).
const PAGE: &str = "/page.html";
const PAGE_BYTES: usize = 1024;
/// Longest wait for one socket operation.
const IO_TIMEOUT: Duration = Duration::from_secs(60);
/// Longest wait for a UDP echo before the datagram counts as lost.
const UDP_TIMEOUT: Duration = Duration::from_secs(1);
/// The longest run of a leg (QEMU is stopped then; also what a leg whose host side failed
/// costs, as the host side cannot stop QEMU itself).
const LEG_TIMEOUT: Duration = Duration::from_secs(600);

/// QEMU's arguments for the machine and network of both legs: `cpus` CPUs, `ports[0]`
/// (TCP and UDP) forwarded to [`SERVE_PORT`], `ports[1]` (TCP) to [`HTTP_PORT`], on
/// 127.0.0.1 only.
pub fn qemu_args(ports: [u16; 2], cpus: u8) -> Vec<String> {
    let [serve, http] = ports;
    let mut args = qemu::iommu();
    args.extend(qemu::nic_on(&format!(
        "user,hostfwd=tcp:127.0.0.1:{serve}-{GUEST_ADDRESS}:{SERVE_PORT},hostfwd=udp:127.0.0.1:{serve}-{GUEST_ADDRESS}:{SERVE_PORT},hostfwd=tcp:127.0.0.1:{http}-{GUEST_ADDRESS}:{HTTP_PORT}"
    )));
    args.extend(["-smp".to_string(), cpus.to_string()]);
    args
}

/// The shell lines of the native `/init` that bring up `eth0` as the guest's: the
/// modules `modules` (file names in `/modules`, in load order), the address and the
/// default route.
pub fn native_setup(modules: &[String]) -> String {
    let mut lines = String::from("# eth0: the virtio-net driver and the guest's address.\n");
    for module in modules {
        lines.push_str(&format!("insmod /modules/{module}\n"));
    }
    lines.push_str(&format!(
        "ifconfig eth0 {GUEST_ADDRESS} netmask 255.255.255.0 up\nroute add default gw {GATEWAY}\n"
    ));
    lines
}

/// A module's name from its path in `modules.dep` (`kernel/drivers/net/virtio_net.ko.xz`:
/// `virtio_net`).
fn module_name(path: &str) -> &str {
    let file = path.rsplit('/').next().unwrap_or(path);
    file.split_once(".ko").map_or(file, |(name, _)| name)
}

/// The paths of `modules_dep` (the text of a kernel's `modules.dep`) that `drivers` need,
/// each after the modules it depends on, each once. A driver `modules.dep` does not name
/// is left out (built into that kernel).
pub fn load_order(modules_dep: &str, drivers: &[&str]) -> Vec<String> {
    let table: Vec<(&str, Vec<&str>)> = modules_dep
        .lines()
        .filter_map(|line| {
            let (path, deps) = line.split_once(':')?;
            Some((path.trim(), deps.split_whitespace().collect()))
        })
        .collect();
    let find = |name: &str| table.iter().find(|(path, _)| module_name(path) == name);
    let mut order: Vec<String> = Vec::new();
    for driver in drivers {
        let Some((path, deps)) = find(driver) else {
            continue;
        };
        // modules.dep lists every module a module needs, directly or not; each of them
        // after its own dependencies.
        let mut needed: Vec<&str> = deps.iter().rev().copied().collect();
        needed.push(path);
        for path in needed {
            if !order.iter().any(|p| p == path) {
                order.push(path.to_string());
            }
        }
    }
    order
}

/// An initramfs entry: path without the leading `/`, mode, contents.
pub type InitramfsFile = (String, u32, Vec<u8>);

/// The modules of `kernel` (`/boot/vmlinuz-<version>`) that [`DRIVERS`] need, as
/// initramfs entries under `modules/` (`.ko`, uncompressed; an `.xz` one through `xz -dc`),
/// and their file names in load order.
fn module_files(kernel: &Path) -> Result<(Vec<InitramfsFile>, Vec<String>)> {
    module_files_for(kernel, DRIVERS)
}

/// [`module_files`] for the modules `drivers` (and what they need).
pub fn module_files_for(
    kernel: &Path,
    drivers: &[&str],
) -> Result<(Vec<InitramfsFile>, Vec<String>)> {
    let name = kernel
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default();
    let version = name
        .strip_prefix("vmlinuz-")
        .with_context(|| format!("{}: not a vmlinuz-<version>", kernel.display()))?;
    let dir = PathBuf::from("/lib/modules").join(version);
    let dep = dir.join("modules.dep");
    let dep = std::fs::read_to_string(&dep).with_context(|| {
        format!(
            "cannot read {} (the native legs load the stock kernel's virtio modules)",
            dep.display()
        )
    })?;
    let mut files = vec![(
        "modules".to_string(),
        crate::guest::S_IFDIR | 0o755,
        Vec::new(),
    )];
    let mut names = Vec::new();
    for module in load_order(&dep, drivers) {
        let path = dir.join(&module);
        let bytes = if module.ends_with(".ko") {
            std::fs::read(&path).with_context(|| format!("cannot read {}", path.display()))?
        } else if module.ends_with(".ko.xz") {
            let out = std::process::Command::new("xz")
                .arg("-dc")
                .arg(&path)
                .output()
                .with_context(|| format!("cannot run xz -dc {}", path.display()))?;
            if !out.status.success() {
                bail!("xz -dc {} failed", path.display());
            }
            out.stdout
        } else {
            bail!(
                "{}: a compressed module busybox insmod cannot load (only .ko and .ko.xz are read)",
                path.display()
            );
        };
        let file = format!("{}.ko", module_name(&module));
        files.push((
            format!("modules/{file}"),
            crate::guest::S_IFREG | 0o644,
            bytes,
        ));
        names.push(file);
    }
    Ok((files, names))
}

/// Runs [`PAIRS`] pairs of legs and returns their metrics and the ratios over the pairs
/// ([`over_pairs`]). `system` is the Warden build the guest leg boots; each leg's files go
/// under `dir/net/<leg>`.
pub fn run(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    dir: &Path,
) -> Result<Vec<Metric>> {
    let mut pairs = Vec::new();
    for pair in 1..=PAIRS {
        eprintln!("xtask: network benchmark, pair {pair} of {PAIRS} (guest leg, native leg)");
        let metrics = run_pair(qemu, system, dir)?;
        for m in metrics.iter().filter(|m| m.name.starts_with("net_ratio_")) {
            eprintln!("xtask: pair {pair}: {}", crate::bench::format_line(m));
        }
        pairs.push(metrics);
    }
    Ok(over_pairs(&pairs))
}

/// Each metric over the pairs: the median of the pairs' medians (a ratio's is the median
/// of the pairs' ratios, each of a guest leg and the native leg run right after it), the
/// least minimum and the greatest maximum, and every round.
fn over_pairs(pairs: &[Vec<Metric>]) -> Vec<Metric> {
    let Some(first) = pairs.first() else {
        return Vec::new();
    };
    first
        .iter()
        .map(|m| {
            let same: Vec<&Metric> = pairs
                .iter()
                .filter_map(|p| p.iter().find(|x| x.name == m.name))
                .collect();
            let medians: Vec<f64> = same.iter().map(|x| x.median).collect();
            Metric {
                median: crate::bench::summary(&m.name, &m.unit, &medians).median,
                min: same.iter().map(|x| x.min).fold(f64::INFINITY, f64::min),
                max: same.iter().map(|x| x.max).fold(f64::NEG_INFINITY, f64::max),
                samples: same.iter().map(|x| x.samples).sum(),
                ..m.clone()
            }
        })
        .collect()
}

/// One guest leg, then one native leg: their metrics and the ratios.
fn run_pair(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    dir: &Path,
) -> Result<Vec<Metric>> {
    let config = crate::workspace_root().join(CONFIG);
    let cpus = crate::check_config::load(&config)?.cpus;
    let dir = dir.join("net");
    let mut metrics = leg("guest", |ports| {
        let entries = crate::esp::standard_entries(system, Some(&config))?;
        let esp = crate::esp::assemble(&dir.join("guest/esp"), system, &entries)?;
        eprintln!("xtask: booting the network benchmark system (real time)");
        qemu::run(
            qemu,
            &RunOptions {
                esp,
                timeout: Some(LEG_TIMEOUT),
                echo: false,
                work_dir: dir.join("guest/state"),
                deterministic_time: false,
                com2: qemu::Com2::Unconnected,
                done_when: Vec::new(),
                extra_args: qemu_args(ports, cpus),
            },
        )
    })?;
    metrics.extend(leg("native", |ports| {
        let kernel = crate::native::ensure_kernel()?;
        let guest = crate::native::guest_of(&config)?;
        let (extra_files, modules) = module_files(&kernel)?;
        let native = Native {
            init: crate::native::script(&guest.init, &guest.env, &native_setup(&modules), &[]),
            extra_files,
            qemu_args: qemu_args(ports, cpus),
            timeout: LEG_TIMEOUT,
        };
        let (outcome, _status) =
            crate::native::boot(qemu, &config, &dir.join("native"), false, native)?;
        Ok(outcome)
    })?);
    let ratios = crate::native::ratios(&metrics)?;
    metrics.extend(ratios.into_iter().map(|r| Metric {
        name: r.name.replace("guest_ratio_net_", "net_ratio_"),
        ..r
    }));
    Ok(metrics)
}

/// One leg: `boot` runs QEMU with two free host ports while [`measure`] times it from here;
/// the leg's metrics, or an error with QEMU's transcript.
fn leg(name: &str, boot: impl FnOnce([u16; 2]) -> Result<Outcome>) -> Result<Vec<Metric>> {
    let ports = crate::scenario::free_host_ports(2)?;
    let ports = [ports[0], ports[1]];
    let prefix = format!("{name}_net_");
    let (outcome, measured) =
        qemu::with_host(|| boot(ports), |ended| measure(ports, &prefix, ended));
    let outcome = outcome?;
    for line in last_nic_counters(&outcome.lines) {
        eprintln!("xtask: {name}: {line}");
    }
    // The processes the guest's init left behind (one still waiting shows where), and
    // how often waiting calls were served again.
    for at in ["guest: left: ", "guest: waiting calls served again: "] {
        for line in outcome.lines.iter().filter(|l| l.contains(at)) {
            let from = line.find(at).unwrap_or(0);
            eprintln!("xtask: {name}: {}", &line[from..]);
        }
    }
    match measured {
        Ok(metrics) => {
            // On stderr at once: a later leg's failure must not lose them.
            for m in &metrics {
                eprintln!("xtask: {}", crate::bench::format_line(m));
            }
            Ok(metrics)
        }
        Err(e) => bail!(
            "the network benchmark's {name} leg failed: {e:#}\n{}",
            outcome.transcript()
        ),
    }
}

/// The NIC partition's last counter lines (`nic: t=<ms>ms uplink ...`, `... tenant ...`):
/// what went through the switch, and what it dropped.
pub fn last_nic_counters(lines: &[String]) -> Vec<&str> {
    let Some(last) = lines.iter().rposition(|l| l.contains("nic: t=")) else {
        return Vec::new();
    };
    let stamp = |l: &str| {
        l.find("nic: t=")
            .map(|at| l[at..].split_whitespace().nth(1).unwrap_or("").to_string())
    };
    let when = stamp(&lines[last]);
    lines
        .iter()
        .filter(|l| l.contains("nic: t=") && stamp(l) == when)
        .map(|l| &l[l.find("nic: ").unwrap_or(0)..])
        .collect()
}

/// The host side of a leg: waits until `linux-netserve` answers, runs every measurement,
/// then asks it to end. Stops waiting when `ended` (QEMU ended) is set.
pub fn measure(ports: [u16; 2], prefix: &str, ended: &AtomicBool) -> Result<Vec<Metric>> {
    let [serve, http] = ports;
    qemu::when_answering(&format!("{prefix}: linux-netserve"), ended, || {
        Ok(ping(serve).is_ok().then_some(()))
    })?;
    let result = measure_all(serve, http, prefix);
    // Whatever happened: end the run (else QEMU runs until the leg's timeout).
    let quit = quit(serve);
    let metrics = result?;
    quit.context("linux-netserve did not confirm the end")?;
    Ok(metrics)
}

/// Every measurement, in order, on a server that answers.
fn measure_all(serve: u16, http: u16, prefix: &str) -> Result<Vec<Metric>> {
    let mut metrics = Vec::new();
    let bytes = BULK_BLOCKS as usize * BLOCK;
    let to = rounds(BULK_ROUNDS, || from_host(serve, bytes))?;
    metrics.push(metric(prefix, "tcp_from_host", "MB/s", &to));
    let from = rounds(BULK_ROUNDS, || to_host(serve, BULK_BLOCKS))?;
    metrics.push(metric(prefix, "tcp_to_host", "MB/s", &from));
    let tcp = rounds(TRIP_ROUNDS, || tcp_roundtrip(serve, TRIPS))?;
    metrics.push(metric(prefix, "tcp_roundtrip", "us", &tcp));
    let mut lost = 0;
    let udp = rounds(TRIP_ROUNDS, || {
        let (us, l) = udp_roundtrip(serve, TRIPS)?;
        lost += l;
        Ok(us)
    })?;
    if lost > 0 {
        eprintln!(
            "xtask: {prefix}: {lost} of {} UDP datagrams got no echo within {UDP_TIMEOUT:?} (not counted)",
            TRIPS * TRIP_ROUNDS
        );
    }
    metrics.push(metric(prefix, "udp_roundtrip", "us", &udp));
    let pages = rounds(REQUEST_ROUNDS, || httpd(http, REQUESTS))?;
    metrics.push(metric(prefix, "httpd", "requests/s", &pages));
    Ok(metrics)
}

/// `f` run `n` times.
fn rounds(n: usize, mut f: impl FnMut() -> Result<f64>) -> Result<Vec<f64>> {
    (0..n).map(|_| f()).collect()
}

/// `prefix<name>` over `samples` ([`crate::bench::summary`]).
fn metric(prefix: &str, name: &str, unit: &str, samples: &[f64]) -> Metric {
    crate::bench::summary(&format!("{prefix}{name}"), unit, samples)
}

fn connect(port: u16) -> Result<TcpStream> {
    let stream = TcpStream::connect_timeout(&([127, 0, 0, 1], port).into(), IO_TIMEOUT)?;
    stream.set_read_timeout(Some(IO_TIMEOUT))?;
    stream.set_write_timeout(Some(IO_TIMEOUT))?;
    Ok(stream)
}

/// A command byte and its one-byte answer. QEMU accepts a forwarded connection before the
/// guest listens (and then closes it), so only the answer says the server is up.
fn ask(port: u16, command: u8, answer: u8) -> Result<()> {
    let mut stream = connect(port)?;
    stream.set_read_timeout(Some(Duration::from_secs(5)))?;
    stream.write_all(&[command])?;
    let mut got = [0u8; 1];
    stream.read_exact(&mut got)?;
    if got[0] != answer {
        bail!("answer {:?} to {:?}", got[0] as char, command as char);
    }
    Ok(())
}

fn ping(port: u16) -> Result<()> {
    ask(port, b'P', b'p')
}

fn quit(port: u16) -> Result<()> {
    ask(port, b'Q', b'q')
}

fn megabytes_per_second(bytes: usize, took: Duration) -> f64 {
    bytes as f64 / 1e6 / took.as_secs_f64().max(1e-9)
}

/// Host to guest: `bytes` in 64 KiB writes, timed until the guest's count came back.
fn from_host(port: u16, bytes: usize) -> Result<f64> {
    let mut stream = connect(port)?;
    let block = vec![b'h'; BLOCK];
    let start = Instant::now();
    stream.write_all(b"R")?;
    for _ in 0..bytes / BLOCK {
        stream.write_all(&block)?;
    }
    stream.shutdown(Shutdown::Write)?;
    let mut answer = String::new();
    stream.read_to_string(&mut answer)?;
    let took = start.elapsed();
    if answer.trim() != bytes.to_string() {
        bail!("the guest counted {:?} of {bytes} bytes", answer.trim());
    }
    Ok(megabytes_per_second(bytes, took))
}

/// Guest to host: `blocks` 64 KiB writes, timed until the guest closed.
fn to_host(port: u16, blocks: u32) -> Result<f64> {
    let mut stream = connect(port)?;
    let mut buf = vec![0u8; BLOCK];
    let start = Instant::now();
    stream.write_all(b"S")?;
    stream.write_all(&blocks.to_le_bytes())?;
    let mut got = 0;
    loop {
        match stream.read(&mut buf)? {
            0 => break,
            n => got += n,
        }
    }
    let took = start.elapsed();
    let bytes = blocks as usize * BLOCK;
    if got != bytes {
        bail!("the guest sent {got} of {bytes} bytes");
    }
    Ok(megabytes_per_second(bytes, took))
}

/// The mean of `trips` 64-byte TCP request/response round trips (us), after one untimed.
fn tcp_roundtrip(port: u16, trips: usize) -> Result<f64> {
    let mut stream = connect(port)?;
    stream.set_nodelay(true)?;
    stream.write_all(b"E")?;
    let mut message = [0u8; MESSAGE];
    let mut answer = [0u8; MESSAGE];
    let mut trip = |i: usize| -> Result<()> {
        message[..8].copy_from_slice(&(i as u64).to_le_bytes());
        stream.write_all(&message)?;
        stream.read_exact(&mut answer)?;
        if answer != message {
            bail!("TCP round trip {i}: a different answer");
        }
        Ok(())
    };
    trip(usize::MAX)?;
    let start = Instant::now();
    for i in 0..trips {
        trip(i)?;
    }
    Ok(start.elapsed().as_secs_f64() * 1e6 / trips as f64)
}

/// The mean of `trips` 64-byte UDP round trips (us) and how many got no echo within
/// [`UDP_TIMEOUT`] (not in the mean). Three untimed datagrams first (the guest's ARP).
fn udp_roundtrip(port: u16, trips: usize) -> Result<(f64, usize)> {
    let socket = UdpSocket::bind(("127.0.0.1", 0))?;
    socket.connect(("127.0.0.1", port))?;
    socket.set_read_timeout(Some(UDP_TIMEOUT))?;
    let mut answer = [0u8; 2048];
    let mut trip = |seq: u64| -> Result<Option<Duration>> {
        let mut message = [0u8; MESSAGE];
        message[..8].copy_from_slice(&seq.to_le_bytes());
        let start = Instant::now();
        socket.send(&message)?;
        // A late echo of an earlier datagram is skipped.
        while start.elapsed() < UDP_TIMEOUT {
            match socket.recv(&mut answer) {
                Ok(n) if answer[..n] == message => return Ok(Some(start.elapsed())),
                Ok(_) => continue,
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    return Ok(None);
                }
                Err(e) => return Err(e.into()),
            }
        }
        Ok(None)
    };
    for seq in 0..3 {
        trip(u64::MAX - seq)?;
    }
    let (mut total, mut answered) = (Duration::ZERO, 0);
    for seq in 0..trips {
        if let Some(took) = trip(seq as u64)? {
            total += took;
            answered += 1;
        }
    }
    if answered == 0 {
        bail!("no UDP datagram of {trips} got an echo");
    }
    Ok((
        total.as_secs_f64() * 1e6 / answered as f64,
        trips - answered,
    ))
}

/// busybox httpd: `requests` GETs of the 1 KiB page one after another, each a new
/// connection, as requests a second.
fn httpd(port: u16, requests: usize) -> Result<f64> {
    let start = Instant::now();
    for i in 0..requests {
        let mut stream = connect(port)?;
        write!(stream, "GET {PAGE} HTTP/1.0\r\nHost: guest\r\n\r\n")?;
        let mut answer = Vec::new();
        stream.read_to_end(&mut answer)?;
        let text = String::from_utf8_lossy(&answer);
        let body = text.split_once("\r\n\r\n").map_or("", |(_, b)| b);
        if !text.starts_with("HTTP/1.") || !text.contains(" 200 ") || body.len() != PAGE_BYTES {
            bail!(
                "request {i}: not the page ({} bytes: {:?})",
                answer.len(),
                text.lines().next()
            );
        }
    }
    Ok(requests as f64 / start.elapsed().as_secs_f64().max(1e-9))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_legs_forward_the_same_ports_on_the_loopback_only() {
        let args = qemu_args([40001, 40002], 2);
        assert_eq!(args[..2], ["-device", "intel-iommu"]);
        assert_eq!(args[2], "-netdev");
        let forwards: Vec<&str> = args[3]
            .split(',')
            .filter_map(|a| a.strip_prefix("hostfwd="))
            .collect();
        assert_eq!(
            forwards,
            [
                "tcp:127.0.0.1:40001-10.0.2.15:5001",
                "udp:127.0.0.1:40001-10.0.2.15:5001",
                "tcp:127.0.0.1:40002-10.0.2.15:80"
            ]
        );
        assert_eq!(
            args[5],
            "virtio-net-pci,netdev=net0,addr=03.0,disable-legacy=on,iommu_platform=on"
        );
        assert_eq!(args[6..], ["-smp", "2"]);
    }

    #[test]
    fn the_native_setup_loads_the_driver_then_configures_eth0() {
        let modules = ["virtio.ko".to_string(), "virtio_net.ko".to_string()];
        let setup = native_setup(&modules);
        let lines: Vec<&str> = setup.lines().skip(1).collect();
        assert_eq!(
            lines,
            [
                "insmod /modules/virtio.ko",
                "insmod /modules/virtio_net.ko",
                "ifconfig eth0 10.0.2.15 netmask 255.255.255.0 up",
                "route add default gw 10.0.2.2"
            ]
        );
        let script = crate::native::script(&["/bin/sh".into()], &[], &setup, &[]);
        assert!(
            script.contains("ifconfig lo 127.0.0.1 up\n# eth0:"),
            "{script}"
        );
        assert!(script.contains("\nenv -i '/bin/sh'\n"), "{script}");
    }

    #[test]
    fn modules_load_after_what_they_need() {
        // Debian 6.1's modules.dep, its lines for the virtio-net driver.
        let dep = "\
kernel/drivers/virtio/virtio_pci.ko: kernel/drivers/virtio/virtio_pci_legacy_dev.ko kernel/drivers/virtio/virtio_pci_modern_dev.ko kernel/drivers/virtio/virtio.ko kernel/drivers/virtio/virtio_ring.ko
kernel/drivers/virtio/virtio_ring.ko:
kernel/drivers/net/virtio_net.ko: kernel/drivers/net/net_failover.ko kernel/net/core/failover.ko kernel/drivers/virtio/virtio.ko kernel/drivers/virtio/virtio_ring.ko
kernel/drivers/virtio/virtio.ko: kernel/drivers/virtio/virtio_ring.ko
kernel/net/core/failover.ko:
";
        let order = load_order(dep, DRIVERS);
        let names: Vec<&str> = order.iter().map(|p| module_name(p)).collect();
        assert_eq!(
            names,
            [
                "virtio_ring",
                "virtio",
                "virtio_pci_modern_dev",
                "virtio_pci_legacy_dev",
                "virtio_pci",
                "failover",
                "net_failover",
                "virtio_net"
            ]
        );
        // Compressed names, and a driver built into the kernel (not in modules.dep).
        let xz = "kernel/drivers/net/virtio_net.ko.xz: kernel/drivers/virtio/virtio.ko.xz\n";
        assert_eq!(
            load_order(xz, DRIVERS),
            [
                "kernel/drivers/virtio/virtio.ko.xz",
                "kernel/drivers/net/virtio_net.ko.xz"
            ]
        );
        assert_eq!(module_name("a/b/virtio_net.ko.xz"), "virtio_net");
        assert!(load_order("", DRIVERS).is_empty());
    }

    #[test]
    fn the_guest_description_matches_the_native_setup() {
        let config = crate::workspace_root().join(CONFIG);
        let guest = crate::native::guest_of(&config).unwrap();
        let net = guest.net.expect("the benchmark's guest has eth0");
        assert_eq!(net.address, [10, 0, 2, 15]);
        assert_eq!(guest.programs, ["linux-netserve"]);
    }

    #[test]
    fn pairs_give_the_median_of_their_medians_and_the_extremes() {
        let pair = |median, min, max| {
            vec![Metric {
                name: "net_ratio_httpd".into(),
                median,
                min,
                max,
                unit: "ratio".into(),
                samples: 3,
            }]
        };
        let m = &over_pairs(&[
            pair(0.9, 0.5, 1.2),
            pair(0.4, 0.3, 0.6),
            pair(0.7, 0.6, 0.8),
        ])[0];
        assert_eq!((m.median, m.min, m.max, m.samples), (0.7, 0.3, 1.2, 9));
        assert_eq!(
            (m.name.as_str(), m.unit.as_str()),
            ("net_ratio_httpd", "ratio")
        );
        assert!(over_pairs(&[]).is_empty());
    }

    #[test]
    fn metrics_take_the_median_and_the_extremes() {
        let m = metric("guest_net_", "httpd", "requests/s", &[30.0, 10.123, 20.0]);
        assert_eq!(m.name, "guest_net_httpd");
        assert_eq!((m.median, m.min, m.max), (20.0, 10.1, 30.0));
        assert_eq!((m.unit.as_str(), m.samples), ("requests/s", 3));
        let line = crate::bench::format_line(&m);
        assert_eq!(crate::bench::parse_line(&line), Some(m));
    }

    #[test]
    fn the_last_nic_counters_are_found() {
        let lines: Vec<String> = [
            "[nic] nic: t=1000ms uplink in=1 out=1 overflow=0 unknown=0 malformed=0 bogus=0",
            "[nic] nic: t=1000ms tenant linux in=1 out=1 overflow=0 spoofed=0 malformed=0 limited=0",
            "[nic] nic: t=2000ms uplink in=9 out=8 overflow=0 unknown=0 malformed=0 bogus=0",
            "[linux] guest: something",
            "[nic] nic: t=2000ms tenant linux in=8 out=9 overflow=2 spoofed=0 malformed=0 limited=0",
        ]
        .map(String::from)
        .to_vec();
        let last = last_nic_counters(&lines);
        assert_eq!(last.len(), 2);
        assert!(last[0].starts_with("nic: t=2000ms uplink in=9"));
        assert!(last[1].contains("overflow=2"));
        assert!(last_nic_counters(&lines[3..4]).is_empty());
    }
}
