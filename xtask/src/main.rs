//! `cargo xtask` — build, run and test the system. See docs/commands.md for the commands.
//!
//! Exit codes: 0 success; 1 failure (build error, failed test, crashed or hung system).

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;
use xtask::artifacts::{self, KernelVariant};
use xtask::qemu::{self, Ending, RunOptions};
use xtask::{esp, scenario, tools};

#[derive(Parser)]
#[command(
    name = "cargo xtask",
    about = "Build, run and test the partitioning system"
)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Build the loader, the kernel and the system software.
    Build {
        #[arg(long)]
        release: bool,
    },
    /// Build everything and boot it under QEMU: COM1 on this terminal, or, when a guest's
    /// console is COM2, COM2 on this terminal and COM1 in a file whose path is printed.
    Run {
        /// System description to put in system.img.
        #[arg(long, default_value = "config/systems/plc-guest.toml")]
        config: PathBuf,
        /// Stop after SECS; exit 0 only if the system reached "ready" and was still running
        /// without a crash.
        #[arg(long, value_name = "SECS")]
        timeout: Option<u64>,
        #[arg(long)]
        release: bool,
    },
    /// Run the benchmarks (kernel, ports, soft-PLC, attack, soak, guest, disk and network
    /// systems under QEMU, the guest, disk and network benchmarks' native references, the
    /// soft-PLC suite on the host: VM,
    /// native tier, IronPLC with IRONPLC set); writes target/bench/report.json.
    Bench {
        /// Boot the QEMU benchmarks on deterministic virtual time (-icount): their cycle
        /// counts then follow the instructions executed, not the host's load, so two
        /// builds can be compared exactly (the figures are not real-time costs).
        #[arg(long)]
        deterministic_time: bool,
        /// Run only the soak (tests/configs/soak.toml, virtual time; also part of the full
        /// bench): every partition busy for FRAMES major frames of 50 us; reports
        /// `soak_window_lateness`, `soak_missed_windows` and `soak_window_drift` and writes
        /// target/bench/soak.json.
        #[arg(long)]
        soak: bool,
        /// Major frames of the soak.
        #[arg(long, value_name = "FRAMES", default_value_t = SOAK_FRAMES, requires = "soak")]
        frames: u64,
        /// Run only the attack systems (virtual time; also part of the full bench): each
        /// hostile loop beside a victim that logs its window starts; reports
        /// `window_lateness_hostile_<attack>` and `window_lateness_hostile` and writes
        /// target/bench/hostile.json.
        #[arg(long, conflicts_with = "soak")]
        hostile: bool,
        /// Run only the guest benchmark (tests/configs/bench_guest.toml: linux-bench in a
        /// guest partition, on the host as `host_*`, and natively on Debian's stock kernel
        /// in the same QEMU as `native_*`, with `guest_ratio_*` = guest / native; also part
        /// of the full bench); writes target/bench/guest.json.
        #[arg(long, conflicts_with_all = ["soak", "hostile"])]
        guest: bool,
        /// Run only the native leg of the guest benchmark (linux-bench on Debian's stock
        /// kernel, `native_*`); writes target/bench/native.json.
        #[arg(long, conflicts_with_all = ["soak", "guest", "hostile"])]
        native: bool,
        /// Run only the host soft-PLC benchmarks (also part of the full bench): the suite of
        /// `partitions/softplc/bench` on the interpreter (`plc_vm_*`), on the native
        /// execution tier (`plc_native_*`), each with its ratio over hand-written Rust, and,
        /// with IRONPLC=<an IronPLC checkout or its ironplcc>, on IronPLC's VM
        /// (`plc_ironplc_*`, `plc_vm_*_vs_ironplc`); writes target/bench/plc.json.
        #[arg(long, conflicts_with_all = ["soak", "guest", "hostile", "native"])]
        plc: bool,
        /// Run only the module-schedule switch bench (tests/configs/bench_schedules.toml,
        /// virtual time; also part of the full bench): `schedule_switch_latency`,
        /// `schedule_switch_window_lateness` and `schedule_steady_window_lateness`; writes
        /// target/bench/schedules.json.
        #[arg(long, conflicts_with_all = ["soak", "guest", "hostile", "native", "plc"])]
        schedules: bool,
        /// Run only the network benchmarks, timed from the host on real time (also part of
        /// the full bench): the PLC's Modbus/TCP poll, online READ over TCP and release
        /// lateness quiet and polled (tests/configs/net_modbus.toml: `plc_net_*`), then TCP,
        /// UDP and busybox httpd of the guest through the NIC partition and the same on
        /// Debian's stock kernel with the same virtio-net (tests/configs/bench_net.toml:
        /// `guest_net_*`, `native_net_*`, `net_ratio_*`); writes target/bench/net.json.
        #[arg(long, conflicts_with_all = ["soak", "guest", "hostile", "native", "plc", "schedules"])]
        net: bool,
        /// Run only the port benchmark systems (tests/configs/bench_ports.toml and
        /// bench_ports_smp.toml; also part of the full bench): the queuing-port round trips
        /// (64 bytes, a 1514-byte frame, 64 bytes from CPU 0 to CPU 1 and back), the frame
        /// through a shared-memory ring, the APEX intra-partition objects; writes
        /// target/bench/ports.json.
        #[arg(long, conflicts_with_all = ["soak", "guest", "hostile", "native", "plc", "schedules", "net"])]
        ports: bool,
        /// Run only the kernel micro-benchmarks (tests/programs/bench as the root task; also
        /// part of the full bench): `null_syscall`, `ipc_roundtrip`, `exception_roundtrip`,
        /// `window_switch`, `window_jitter`; writes target/bench/kernel.json.
        #[arg(long, conflicts_with_all = ["soak", "guest", "hostile", "native", "plc", "schedules", "net", "ports"])]
        kernel: bool,
        /// Run only the disk benchmark (also part of the full bench): linux-bench's disk
        /// metrics on an ext2 file system of the guest's /dev/vda over the block-device
        /// partition (tests/configs/bench_disk.toml, `guest_disk_*`) and on Debian's stock
        /// kernel with the same virtio-blk (`native_disk_*`, `disk_ratio_*`), the PLC's
        /// RETAIN save times (4 KiB, 64 KiB) and boot time to its first cycle with a boot
        /// project (`plc_retain_*`, `plc_boot_*`; the disk legs always on real time, the
        /// PLC's boots on virtual time with --deterministic-time); writes
        /// target/bench/disk.json.
        #[arg(long, conflicts_with_all = ["soak", "guest", "hostile", "native", "plc", "schedules", "net", "ports", "kernel"])]
        disk: bool,
        /// Run only the IEC 61499 benchmark (also part of the full bench; virtual time with
        /// --deterministic-time): three applications on the IEC 61499 partition
        /// (tests/configs/bench_iec61499.toml) and on 4diac FORTE on Debian's stock kernel
        /// in the same QEMU, each timed by the device's own E_STOPWATCH: the event loop of
        /// tests/configs/iec61499/bench_loop.fboot (`iec61499_loop_events`), a chain of 10
        /// FBs (bench_chain.fboot, `iec61499_chain_latency`) and E_CYCLE at 1 ms
        /// (bench_cycle.fboot, `iec61499_cycle_jitter`, `iec61499_cycle_jitter_max`,
        /// `iec61499_cycle_jitter_max_polled`);
        /// FORTE's as `forte_*`, the ratios as `iec61499_ratio_*`; writes
        /// target/bench/iec61499.json.
        #[arg(long, conflicts_with_all = ["soak", "guest", "hostile", "native", "plc", "schedules", "net", "ports", "kernel", "disk"])]
        iec61499: bool,
        /// Run only the multicore scaling benchmark (not part of the full bench, about 11
        /// minutes; always real time): N soft-PLC partitions on N CPUs, N = 1 to 4, each
        /// running tests/configs/plc/scaling.st freewheeling; their executions in 60 s
        /// (`scaling_executions_<n>cpu` per partition, `scaling_total_<n>cpu`) and the
        /// speedup over one CPU (`scaling_speedup_<n>cpu`); then N IEC 61499 devices
        /// running the event chains of tests/configs/iec61499/scaling.fboot one after
        /// another (`iec61499_scaling_chains_<n>cpu`, `_total_`, `_speedup_`); writes
        /// target/bench/scaling.json.
        #[arg(long, conflicts_with_all = ["soak", "guest", "hostile", "native", "plc", "schedules", "net", "ports", "kernel", "disk", "deterministic_time", "iec61499"])]
        scaling: bool,
        /// Run only the guest's multicore benchmark (not part of the full bench, about 3
        /// minutes; always real time): one guest gzips 8 files with `xargs -P2 -n1 gzip`
        /// (tests/configs/guest/gzip_bench.sh), 5 rounds, bound to one CPU and then to two
        /// of a two-CPU machine; ms a round (`guest_gzip_p2_1cpu`, `guest_gzip_p2_2cpu`)
        /// and their ratio (`guest_gzip_p2_speedup`); writes target/bench/guest-smp.json.
        #[arg(long, conflicts_with_all = ["soak", "guest", "hostile", "native", "plc", "schedules", "net", "ports", "kernel", "disk", "deterministic_time", "iec61499", "scaling"])]
        guest_smp: bool,
        /// Run only the long power-cut test (not part of the full bench): scenario
        /// `store_power_cut` with CUTS random power cuts instead of the ordinary run's 20
        /// (`cargo xtask test store_power_cut --scenarios-only` with WARDEN_POWER_CUTS=CUTS;
        /// WARDEN_POWER_CUT_SEED replays a seed); prints each cut and the seed.
        #[arg(long, conflicts_with_all = ["soak", "guest", "hostile", "native", "plc", "schedules", "net", "ports", "kernel", "disk", "deterministic_time", "iec61499", "scaling", "guest_smp"])]
        power_cut: bool,
        /// Power cuts of `--power-cut`.
        #[arg(
            long,
            value_name = "CUTS",
            default_value_t = 200,
            requires = "power_cut"
        )]
        cuts: u32,
    },
    /// Run all host unit tests, then the QEMU scenarios whose name contains a FILTER (all
    /// without one).
    Test {
        filter: Vec<String>,
        /// Run only the QEMU scenarios (skip the host unit tests).
        #[arg(long)]
        scenarios_only: bool,
        /// Give every QEMU run of the scenarios at least N CPUs (sets WARDEN_SMP=N; a
        /// system that uses more gets its own). Default 2: the scenarios run on two CPUs,
        /// as the default system does, whether their system uses the second or not.
        #[arg(long, value_name = "N", default_value_t = 2, value_parser = clap::value_parser!(u8).range(1..=8))]
        smp: u8,
    },
    /// The lint gate of CI: cargo fmt --check, and clippy -D warnings on the host crates,
    /// the kernel, the loader and every user-mode program.
    Lint,
    /// The OSCAT BASIC library check: compile the library text as one project and one POU at
    /// a time; print how many POUs compile and why the others do not. FILE defaults to
    /// $OSCAT_ST, else target/oscat/oscat.st; without it the check is skipped (exit 0).
    Oscat {
        file: Option<PathBuf>,
        /// Also write the figures and the failure list into the generated section of
        /// partitions/softplc/compiler/STATUS.md.
        #[arg(long)]
        write_status: bool,
    },
    /// Draw a run's serial log as an SVG: the plant's level, setpoint and valve over time,
    /// the PLC's release-lateness histogram and each second's lateness.
    Plot {
        /// The serial log (COM1), e.g. target/esp/run-state/com1.log of `cargo xtask run`.
        log: PathBuf,
        /// The picture to write (*.svg); default: LOG with the extension .svg.
        #[arg(short, long, value_name = "OUT")]
        output: Option<PathBuf>,
        /// The soft-PLC partition whose lateness to draw (default: the first by name).
        #[arg(long, value_name = "NAME")]
        plc: Option<String>,
    },
    /// Convert a system description of DLR's a653rs-linux hypervisor (YAML) into Warden's
    /// TOML, validated; what has no equivalent is reported as file:line:col (exit 1).
    ImportA653rs {
        file: PathBuf,
        /// Write the TOML here (default: print it).
        #[arg(short, long, value_name = "OUT")]
        output: Option<PathBuf>,
        /// Rename a partition (a name longer than Warden's 15 bytes, say): OLD=NEW; repeatable.
        #[arg(long, value_name = "OLD=NEW")]
        rename: Vec<String>,
        /// The refresh period of a sampling destination port (the program's, which the YAML
        /// does not carry): PARTITION.PORT=DURATION; repeatable.
        #[arg(long, value_name = "PARTITION.PORT=DURATION")]
        refresh: Vec<String>,
    },
    /// Build DLR's a653rs-linux example partitions for Warden from a checkout
    /// ($A653RS_LINUX or target/a653rs-linux), import the YAML of those that run, and report
    /// what ports and why the rest does not.
    A653rsExamples,
    /// Validate a system description and print its diagnostics (exit 1 if any).
    CheckConfig {
        file: PathBuf,
        /// Accept any partition image name (default: the workspace's user programs).
        #[arg(long)]
        any_image: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Cmd::Build { release } => artifacts::build(release, KernelVariant::Production).map(|a| {
            println!(
                "loader: {}\nkernel: {}\nsyssw:  {}",
                a.loader.display(),
                a.kernel.display(),
                a.syssw.display()
            );
            true
        }),
        Cmd::Run {
            config,
            timeout,
            release,
        } => run(config, timeout, release),
        Cmd::Bench {
            soak: true, frames, ..
        } => soak(frames),
        Cmd::Bench { hostile: true, .. } => hostile(),
        Cmd::Bench { scaling: true, .. } => scaling_bench(),
        Cmd::Bench {
            guest_smp: true, ..
        } => guest_smp_bench(),
        Cmd::Bench {
            power_cut: true,
            cuts,
            ..
        } => power_cut_bench(cuts),
        Cmd::Bench { plc: true, .. } => plc_bench(),
        Cmd::Bench {
            schedules: true, ..
        } => schedules_bench(),
        Cmd::Bench { net: true, .. } => net_bench(),
        Cmd::Bench {
            iec61499: true,
            deterministic_time,
            ..
        } => iec61499_bench(deterministic_time),
        Cmd::Bench {
            ports: true,
            deterministic_time,
            ..
        } => ports_bench(deterministic_time),
        Cmd::Bench {
            guest: true,
            deterministic_time,
            ..
        } => guest_bench(deterministic_time),
        Cmd::Bench {
            native: true,
            deterministic_time,
            ..
        } => native_bench(deterministic_time),
        Cmd::Bench {
            disk: true,
            deterministic_time,
            ..
        } => disk_bench(deterministic_time),
        Cmd::Bench {
            kernel: true,
            deterministic_time,
            ..
        } => kernel_bench(deterministic_time),
        Cmd::Bench {
            deterministic_time, ..
        } => bench(deterministic_time),
        Cmd::Test {
            filter,
            scenarios_only,
            smp,
        } => test(&filter, scenarios_only, smp),
        Cmd::Lint => xtask::lint::run(),
        Cmd::Oscat { file, write_status } => xtask::oscat::run(file.as_deref(), write_status),
        Cmd::Plot { log, output, plc } => xtask::plot::run(&log, output.as_deref(), plc.as_deref()),
        Cmd::CheckConfig { file, any_image } => xtask::check_config::run(&file, any_image),
        Cmd::A653rsExamples => xtask::a653rs_examples::run(),
        Cmd::ImportA653rs {
            file,
            output,
            rename,
            refresh,
        } => xtask::a653rs::run(&file, output.as_deref(), &rename, &refresh),
    };
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("xtask: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Markers of a crash in the kernel log.
const CRASH_MARKERS: &[&str] = &["KERNEL PANIC", "EXCEPTION "];
const READY_MARKER: &str = "kernel: ready";

fn run(config: PathBuf, timeout: Option<u64>, release: bool) -> Result<bool> {
    let qemu = tools::ensure_qemu()?;
    let config = xtask::workspace_root().join(config);
    if !config.is_file() {
        bail!("configuration file {} not found", config.display());
    }
    let artifacts = artifacts::build(release, KernelVariant::Production)?;
    let esp_dir = xtask::target_dir().join("esp").join("run");
    let work_dir = xtask::target_dir().join("esp").join("run-state");
    // A guest with a console on COM2 gets this terminal; the kernel log then goes to a file.
    let console = xtask::check_config::load(&config)?
        .partitions
        .iter()
        .find(|p| p.guest.as_ref().is_some_and(|g| g.console_com2))
        .map(|p| p.name.clone());
    esp::assemble(
        &esp_dir,
        &artifacts,
        &esp::standard_entries(&artifacts, Some(&config))?,
    )?;
    eprintln!(
        "xtask: booting {} under QEMU{}",
        esp_dir.display(),
        match (timeout, &console) {
            (Some(t), _) => format!(" for {t} s"),
            (None, None) => " (stop with Ctrl-C)".into(),
            (None, Some(_)) => " (stop with Ctrl-A X)".into(),
        }
    );
    let forwards: Vec<String> = qemu::RUN_FORWARDS
        .iter()
        .map(|(host, address, port)| format!("127.0.0.1:{host} -> {address}:{port}"))
        .collect();
    eprintln!(
        "xtask: NIC: virtio-net at PCI 00:03.0 on QEMU's user network, TCP forwarded (host only): {}",
        forwards.join(", ")
    );
    if let Some(partition) = &console {
        eprintln!(
            "xtask: this terminal is the console of guest `{partition}` (COM2; Ctrl-A X quits QEMU, Ctrl-A C its monitor); the kernel log (COM1) goes to {}",
            work_dir.join("com1.log").display()
        );
    }
    let outcome = qemu::run(
        &qemu,
        &RunOptions {
            esp: esp_dir.clone(),
            timeout: timeout.map(Duration::from_secs),
            echo: true,
            work_dir,
            deterministic_time: false,
            com2: if console.is_some() {
                qemu::Com2::Terminal
            } else {
                qemu::Com2::Unconnected
            },
            done_when: Vec::new(),
            extra_args: [qemu::iommu(), qemu::nic(qemu::RUN_FORWARDS)].concat(),
        },
    )?;
    let crashed = outcome
        .lines
        .iter()
        .any(|l| CRASH_MARKERS.iter().any(|m| l.contains(m)));
    let ready = outcome.line(READY_MARKER).is_some();
    let verdict = match &outcome.ending {
        Ending::Exited(qemu::EXIT_SUCCESS) => Ok("the system exited with success"),
        Ending::Exited(qemu::EXIT_FAILURE) => Err("the system exited with failure".to_string()),
        // Ctrl-A X on the guest's console.
        Ending::Exited(0) if console.is_some() => Ok("QEMU was quit"),
        Ending::TimedOut if crashed => Err("the system crashed".to_string()),
        Ending::TimedOut if !ready => Err(format!(
            "the system did not reach '{READY_MARKER}' (hung at boot)"
        )),
        Ending::TimedOut => Ok("the system was still running at the timeout"),
        Ending::Aborted(line) => Err(format!("boot failed: {line}")),
        Ending::Exited(code) => Err(format!(
            "QEMU exited with {code} (triple fault or QEMU error)\n{}",
            outcome.stderr
        )),
        Ending::Killed => Err("QEMU was killed".to_string()),
        Ending::Done => unreachable!("`run` waits for no text"),
        Ending::Cut => unreachable!("`run` cuts no power"),
        Ending::Stopped => unreachable!("`run` has no stop flag"),
    };
    match verdict {
        Ok(msg) => {
            eprintln!("xtask: {msg}");
            Ok(true)
        }
        Err(msg) => {
            eprintln!("xtask: FAILED: {msg}");
            Ok(false)
        }
    }
}

fn cargo_test(args: &[&str]) -> Result<bool> {
    cargo_test_with(args, &[])
}

/// `cargo test ARGS` with the environment variables `env` set.
fn cargo_test_with(args: &[&str], env: &[(&str, String)]) -> Result<bool> {
    let mut cmd = artifacts::cargo();
    cmd.arg("test").args(args);
    cmd.envs(env.iter().map(|(k, v)| (k, v)));
    let shown: Vec<String> = env.iter().map(|(k, v)| format!("{k}={v} ")).collect();
    eprintln!("xtask: {}cargo test {}", shown.concat(), args.join(" "));
    Ok(cmd.status()?.success())
}

fn test(filters: &[String], scenarios_only: bool, smp: u8) -> Result<bool> {
    tools::ensure_qemu_deterministic()?;
    // Host unit tests: the host crates (the workspace's default members), plus the pure
    // logic of the kernel, the APEX runtime, the plant, the PLC runtime, the guest and the
    // user-mode runtime (their library parts), and the Linux-side checks (tests/linux) on the host Linux.
    let host_ok = scenarios_only
        || (cargo_test(&[])?
            & cargo_test(&["-p", "kernel", "--lib"])?
            & cargo_test(&["-p", "apex", "--no-default-features", "--lib"])?
            & cargo_test(&["-p", "plant", "--no-default-features", "--lib"])?
            & cargo_test(&["-p", "softplc", "--no-default-features", "--lib"])?
            & cargo_test(&["-p", "guest", "--no-default-features", "--lib"])?
            & cargo_test(&["-p", "user-rt", "--lib"])?
            & cargo_test(&["-p", "a653rs-compat", "--no-default-features", "--lib"])?
            & xtask::linux::host_check()?);
    if !host_ok {
        eprintln!("xtask: host tests failed; QEMU scenarios not run");
        return Ok(false);
    }

    let scenarios = scenario::all(filters)?;
    if scenarios.is_empty() {
        bail!("no QEMU scenario matches any of {filters:?}");
    }
    let artifacts = artifacts::build(false, KernelVariant::TestHooks)?;
    let mut programs: Vec<String> = scenarios
        .iter()
        .filter_map(|s| s.manifest.root_task.clone())
        .collect();
    programs.sort();
    programs.dedup();
    artifacts::build_user_programs(&programs)?;
    for s in &scenarios {
        let mut artifacts = artifacts.clone();
        if let Some(program) = &s.manifest.root_task {
            artifacts.syssw = xtask::target_dir().join("user").join(program);
        }
        let mut config = s
            .manifest
            .config
            .as_ref()
            .map(|c| xtask::workspace_root().join(c));
        if let Some(name) = &s.manifest.a653rs_example {
            let esp_dir = scenario::output_dir().join(&s.name).join("esp");
            let _ = std::fs::remove_dir_all(&esp_dir);
            let Some(root) = xtask::a653rs_examples::sources() else {
                eprintln!(
                    "xtask: scenario {}: no a653rs-linux checkout ($A653RS_LINUX, target/a653rs-linux); {}; skipped",
                    s.name,
                    xtask::a653rs_examples::HOW_TO_GET
                );
                continue;
            };
            let example = xtask::a653rs_examples::EXAMPLES
                .iter()
                .find(|e| e.name == name)
                .with_context(|| format!("scenario {}: no a653rs example {name}", s.name))?;
            config = Some(xtask::a653rs_examples::prepare(&root, example)?);
        }
        s.manifest.prepare(&s.name)?;
        let mut entries = esp::standard_entries(&artifacts, config.as_deref())?;
        if let Some(hook) = &s.manifest.hook {
            entries.push(esp::ImageEntry::Bytes {
                name: "test/hook".into(),
                data: hook.clone().into_bytes(),
            });
        }
        for (name, text) in &s.manifest.entries {
            entries.push(esp::ImageEntry::Bytes {
                name: name.clone(),
                data: text.clone().into_bytes(),
            });
        }
        let esp_dir = esp::assemble(
            &scenario::output_dir().join(&s.name).join("esp"),
            &artifacts,
            &entries,
        )?;
        s.manifest.damage(&esp_dir)?;
    }
    let mut args = vec!["-p", "scenarios", "--"];
    args.extend(filters.iter().map(String::as_str));
    cargo_test_with(&args, &[("WARDEN_SMP", smp.to_string())])
}

/// `cargo xtask bench --power-cut`: scenario `store_power_cut` with `cuts` power cuts, run
/// as `cargo xtask test store_power_cut --scenarios-only` by this program with
/// `WARDEN_POWER_CUTS` set (the test reads it).
fn power_cut_bench(cuts: u32) -> Result<bool> {
    if cuts == 0 {
        bail!("--cuts must be at least 1");
    }
    let me = std::env::current_exe().context("cannot find this program to run the test")?;
    eprintln!("xtask: scenario store_power_cut with {cuts} power cuts");
    let status = std::process::Command::new(me)
        .args(["test", "store_power_cut", "--scenarios-only"])
        .env("WARDEN_POWER_CUTS", cuts.to_string())
        .status()
        .context("cannot run `cargo xtask test store_power_cut`")?;
    Ok(status.success())
}

/// Assembles the ESP of a benchmark system under `dir` (the root task of `artifacts`, with
/// the description `config` if any), boots it with `timeout` and returns what it printed;
/// an error unless it ended with success.
fn boot_bench_system(
    qemu: &tools::Qemu,
    artifacts: &artifacts::Artifacts,
    config: Option<&std::path::Path>,
    dir: &std::path::Path,
    what: &str,
    deterministic_time: bool,
    timeout: Duration,
) -> Result<qemu::Outcome> {
    let entries = esp::standard_entries(artifacts, config)?;
    boot_bench_image(
        qemu,
        artifacts,
        entries,
        dir,
        what,
        deterministic_time,
        timeout,
        &[],
    )
}

/// Boots an image of `artifacts` with `entries` (see [`boot_bench_system`]), with
/// `extra_args` for QEMU.
#[allow(clippy::too_many_arguments)]
fn boot_bench_image(
    qemu: &tools::Qemu,
    artifacts: &artifacts::Artifacts,
    entries: Vec<esp::ImageEntry>,
    dir: &std::path::Path,
    what: &str,
    deterministic_time: bool,
    timeout: Duration,
    extra_args: &[&str],
) -> Result<qemu::Outcome> {
    let esp_dir = esp::assemble(&dir.join("esp"), artifacts, &entries)?;
    eprintln!(
        "xtask: booting the {what}{}",
        if deterministic_time {
            " (virtual time)"
        } else {
            ""
        }
    );
    let outcome = qemu::run(
        qemu,
        &RunOptions {
            esp: esp_dir,
            timeout: Some(timeout),
            echo: false,
            work_dir: dir.join("state"),
            deterministic_time,
            com2: qemu::Com2::Unconnected,
            done_when: Vec::new(),
            extra_args: extra_args.iter().map(|a| a.to_string()).collect(),
        },
    )?;
    if !outcome.succeeded() {
        bail!(
            "the {what} did not finish cleanly\n{}",
            outcome.transcript()
        );
    }
    Ok(outcome)
}

/// An attack system whose victim measures its window starts: a configuration of
/// tests/configs (syssw starts its partitions), or the attack program as the root task in
/// a mode (system-image entry `test/mode`, as scenario `attack_root_paths`).
enum Hostile {
    Config(&'static str),
    Root(&'static str),
}

/// The attack systems with the name of their metric: `window_lateness_hostile_<name>`.
const HOSTILE_SYSTEMS: [(Hostile, &str); 10] = [
    (Hostile::Config("syscall_fuzz"), "fuzz"),
    (Hostile::Config("attack_floods"), "floods"),
    (Hostile::Config("attack_partitions"), "restart_loop"),
    (Hostile::Config("attack_map"), "map"),
    (Hostile::Config("attack_io"), "io"),
    (Hostile::Config("attack_kill"), "kill"),
    (Hostile::Config("attack_reach"), "reach"),
    (Hostile::Config("attack_restart"), "restart_background"),
    (Hostile::Root("paths"), "root_paths"),
    (Hostile::Config("smp_isolation"), "other_cpu"),
];

/// Boots each attack system on virtual time (the lateness is a property of the kernel and
/// syssw, not of the host) and reads its victim's window-start lateness; the worst of them
/// is also reported as `window_lateness_hostile`.
fn hostile_lateness(
    qemu: &tools::Qemu,
    system: &artifacts::Artifacts,
    dir: &std::path::Path,
) -> Result<Vec<xtask::bench::Metric>> {
    let mut metrics = Vec::new();
    for (hostile, name) in HOSTILE_SYSTEMS {
        let config = match hostile {
            Hostile::Config(config) | Hostile::Root(config) => config,
        };
        let what = format!("attack system {config}");
        let timeout = Duration::from_secs(900);
        let outcome = match hostile {
            Hostile::Config(_) => {
                let path = xtask::workspace_root().join(format!("tests/configs/{config}.toml"));
                boot_bench_system(
                    qemu,
                    system,
                    Some(&path),
                    &dir.join(config),
                    &what,
                    true,
                    timeout,
                )?
            }
            Hostile::Root(mode) => {
                let mut root = system.clone();
                root.syssw = artifacts::build_user_programs(&["attack".to_string()])?.remove(0);
                let mut entries = esp::standard_entries(&root, None)?;
                entries.push(esp::ImageEntry::Bytes {
                    name: "test/mode".into(),
                    data: mode.as_bytes().to_vec(),
                });
                boot_bench_image(
                    qemu,
                    &root,
                    entries,
                    &dir.join(config),
                    &what,
                    true,
                    timeout,
                    &[],
                )?
            }
        };
        let name = format!("window_lateness_hostile_{name}");
        metrics.push(victim_lateness(&outcome, "", &name, &what)?);
    }
    if let Some(worst) = metrics
        .iter()
        .max_by(|a, b| a.max.total_cmp(&b.max))
        .cloned()
    {
        metrics.push(xtask::bench::Metric {
            name: "window_lateness_hostile".to_string(),
            ..worst
        });
    }
    Ok(metrics)
}

/// Boots the soft-PLC benchmark system (tests/configs/bench_plc.toml) on virtual time (the
/// release lateness is the kernel's and the runtime's, not the host's) and reads the PLC's
/// last statistics line (`plc_release_jitter`, `plc_cycle_overhead` over all its releases)
/// and the client's `plc_online_read`.
/// The module-schedule switch bench (`tests/configs/bench_schedules.toml`), always on
/// virtual time: its figures are the schedule's and the kernel's, not QEMU's.
fn schedule_switch_metrics(
    qemu: &tools::Qemu,
    system: &artifacts::Artifacts,
    dir: &std::path::Path,
) -> Result<Vec<xtask::bench::Metric>> {
    let config = xtask::workspace_root().join("tests/configs/bench_schedules.toml");
    let outcome = boot_bench_system(
        qemu,
        system,
        Some(&config),
        &dir.join("schedules"),
        "module-schedule benchmark system",
        true,
        Duration::from_secs(1800),
    )?;
    let metrics: Vec<_> = outcome
        .lines
        .iter()
        .filter_map(|l| xtask::bench::parse_line(l))
        .collect();
    if metrics.len() != 3 {
        bail!(
            "the module-schedule benchmark system printed {} bench lines, not 3\n{}",
            metrics.len(),
            outcome.transcript()
        );
    }
    Ok(metrics)
}

fn plc_metrics(
    qemu: &tools::Qemu,
    system: &artifacts::Artifacts,
    dir: &std::path::Path,
) -> Result<Vec<xtask::bench::Metric>> {
    let config = xtask::workspace_root().join("tests/configs/bench_plc.toml");
    let outcome = boot_bench_system(
        qemu,
        system,
        Some(&config),
        &dir.join("plc"),
        "soft-PLC benchmark system",
        true,
        Duration::from_secs(1800),
    )?;
    let scan = outcome
        .lines
        .iter()
        .rev()
        .find_map(|l| xtask::bench::parse_plc_scan(l));
    let read = outcome
        .lines
        .iter()
        .find_map(|l| xtask::bench::parse_line(l));
    match (scan, read) {
        (Some(scan), Some(read)) => Ok(scan.into_iter().chain([read]).collect()),
        _ => bail!(
            "the soft-PLC benchmark system printed no scan statistics or no plc_online_read\n{}",
            outcome.transcript()
        ),
    }
}

/// `cargo xtask bench --guest`: only the guest benchmark; writes `target/bench/guest.json`.
fn guest_bench(deterministic_time: bool) -> Result<bool> {
    let qemu = tools::ensure_qemu_deterministic()?;
    let system = artifacts::build(true, KernelVariant::Production)?;
    let metrics = guest_metrics(
        &qemu,
        &system,
        &xtask::target_dir().join("bench"),
        deterministic_time,
    )?;
    print_and_write(&metrics, "guest.json")
}

/// `cargo xtask bench --ports`: only the port benchmark system; writes
/// `target/bench/ports.json`.
fn ports_bench(deterministic_time: bool) -> Result<bool> {
    let qemu = tools::ensure_qemu_deterministic()?;
    let system = artifacts::build(true, KernelVariant::Production)?;
    let dir = xtask::target_dir().join("bench");
    let metrics = ports_metrics(&qemu, &system, &dir, deterministic_time)?;
    print_and_write(&metrics, "ports.json")
}

/// The port benchmark systems (`tests/configs/bench_ports.toml`, an APEX partition under
/// the real syssw, and `bench_ports_smp.toml`, two on two CPUs): their `bench` lines.
fn ports_metrics(
    qemu: &tools::Qemu,
    system: &artifacts::Artifacts,
    dir: &std::path::Path,
    deterministic_time: bool,
) -> Result<Vec<xtask::bench::Metric>> {
    let mut metrics = Vec::new();
    // The one-CPU system, then the cross-CPU one (tests/configs/bench_ports_smp.toml).
    for (file, name) in [("bench_ports", "ports"), ("bench_ports_smp", "ports_smp")] {
        let config = xtask::workspace_root().join(format!("tests/configs/{file}.toml"));
        let outcome = boot_bench_system(
            qemu,
            system,
            Some(&config),
            &dir.join(name),
            "ports benchmark system",
            deterministic_time,
            bench_timeout(deterministic_time),
        )?;
        metrics.extend(
            outcome
                .lines
                .iter()
                .filter_map(|l| xtask::bench::parse_line(l)),
        );
    }
    Ok(metrics)
}

/// How long the kernel and port benchmark systems may run: virtual time runs slower than
/// real time under TCG, so 10 s of window measurements take minutes.
fn bench_timeout(deterministic_time: bool) -> Duration {
    Duration::from_secs(if deterministic_time { 1800 } else { 300 })
}

/// `cargo xtask bench --net`: only the network benchmarks (the guest's,
/// [`xtask::netbench`], and the PLC's, [`xtask::plcnetbench`] and
/// [`xtask::pubsubbench`], always on real time); writes
/// `target/bench/net.json`.
fn net_bench() -> Result<bool> {
    let qemu = tools::ensure_qemu_deterministic()?;
    let system = artifacts::build(true, KernelVariant::Production)?;
    let dir = xtask::target_dir().join("bench");
    let mut metrics = xtask::plcnetbench::run(&qemu, &system, &dir)?;
    metrics.extend(xtask::pubsubbench::run(&qemu, &system, &dir)?);
    metrics.extend(xtask::netbench::run(&qemu, &system, &dir)?);
    print_and_write(&metrics, "net.json")
}

/// `cargo xtask bench --iec61499`: only the IEC 61499 benchmark ([`xtask::fortebench`]);
/// writes `target/bench/iec61499.json`.
fn iec61499_bench(deterministic_time: bool) -> Result<bool> {
    let qemu = tools::ensure_qemu_deterministic()?;
    let system = artifacts::build(true, KernelVariant::Production)?;
    let dir = xtask::target_dir().join("bench");
    let metrics = xtask::fortebench::run(&qemu, &system, &dir, deterministic_time)?;
    print_and_write(&metrics, "iec61499.json")
}

/// `cargo xtask bench --native`: only the native leg; writes `target/bench/native.json`.
fn native_bench(deterministic_time: bool) -> Result<bool> {
    let qemu = tools::ensure_qemu_deterministic()?;
    tools::ensure_bash_static()?;
    let config = xtask::workspace_root().join("tests/configs/bench_guest.toml");
    let metrics = xtask::native::metrics(
        &qemu,
        &config,
        &xtask::target_dir().join("bench/native"),
        deterministic_time,
    )?;
    print_and_write(&metrics, "native.json")
}

/// The guest benchmark: `linux-bench` (tests/linux/bench.c) on the host Linux (`host_*`,
/// the same loops, for comparison), then in the guest partition of
/// tests/configs/bench_guest.toml (`guest_*`, on real time: the cycles are what the
/// guest's calls cost under QEMU, host load included), then natively on Debian's stock
/// kernel in the same QEMU (`native_*`, [`xtask::native`]), and `guest_ratio_*` (guest /
/// native). With `deterministic_time` both QEMU legs run on virtual time: their cycles
/// then follow the instructions executed, the same from run to run.
fn guest_metrics(
    qemu: &tools::Qemu,
    system: &artifacts::Artifacts,
    dir: &std::path::Path,
    deterministic_time: bool,
) -> Result<Vec<xtask::bench::Metric>> {
    // The macro workloads run `/bin/busybox` (gzip, sh) on the host leg as in the guest;
    // bash's is the host's bash there, Debian's bash-static in the guest and natively.
    // Installed first: the configuration names them as the guest's files.
    tools::ensure_busybox()?;
    tools::ensure_bash_static()?;
    let config = xtask::workspace_root().join("tests/configs/bench_guest.toml");
    let described = xtask::check_config::load(&config)?;
    let args: Vec<String> = described
        .partitions
        .iter()
        .find_map(|p| p.guest.as_ref())
        .map(|g| g.init.iter().skip(1).cloned().collect())
        .unwrap_or_default();
    let program = xtask::linux::build("linux-bench")?;
    eprintln!("xtask: running linux-bench on the host");
    let out = std::process::Command::new(&program)
        .args(&args)
        .args(["--prefix", "host_"])
        .current_dir("/")
        .output()
        .with_context(|| format!("cannot run {}", program.display()))?;
    let host_text = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        bail!(
            "linux-bench failed on the host ({}):\n{host_text}",
            out.status
        );
    }
    let mut metrics: Vec<_> = host_text
        .lines()
        .filter_map(xtask::bench::parse_line)
        .collect();
    let outcome = boot_bench_system(
        qemu,
        system,
        Some(&config),
        &dir.join("guest"),
        "guest benchmark system",
        deterministic_time,
        Duration::from_secs(3600),
    )?;
    let errors: Vec<&String> = outcome
        .lines
        .iter()
        .filter(|l| l.contains("bench-error") || l.contains("killed by signal"))
        .collect();
    let guest: Vec<_> = outcome
        .lines
        .iter()
        .filter_map(|l| xtask::bench::parse_line(l))
        .filter(|m| m.name.starts_with("guest_"))
        .collect();
    if !errors.is_empty() || guest.is_empty() {
        bail!(
            "the guest benchmark failed: {errors:?}\n{}",
            outcome.transcript()
        );
    }
    for note in outcome.lines.iter().filter(|l| l.contains("stdout: note ")) {
        eprintln!("xtask: {note}");
    }
    metrics.extend(guest);
    metrics.extend(xtask::native::metrics(
        qemu,
        &config,
        &dir.join("native"),
        deterministic_time,
    )?);
    let ratios = xtask::native::ratios(&metrics)?;
    metrics.extend(ratios);
    Ok(metrics)
}

/// Major frames of `cargo xtask bench --soak` by default.
const SOAK_FRAMES: u64 = 1_000_000;

/// `bench --plc`: only the host soft-PLC benchmarks (`xtask::bench::host_metrics`).
fn plc_bench() -> Result<bool> {
    let metrics = xtask::bench::host_metrics()?;
    print_and_write(&metrics, "plc.json")
}

/// `bench --schedules`: only the module-schedule switch bench.
fn schedules_bench() -> Result<bool> {
    let qemu = tools::ensure_qemu_deterministic()?;
    let system = artifacts::build(true, KernelVariant::Production)?;
    let dir = xtask::target_dir().join("bench");
    let metrics = schedule_switch_metrics(&qemu, &system, &dir)?;
    print_and_write(&metrics, "schedules.json")
}

/// `bench --scaling`: only the multicore scaling benchmark (`xtask::scalingbench`).
fn scaling_bench() -> Result<bool> {
    let qemu = tools::ensure_qemu()?;
    let system = artifacts::build(true, KernelVariant::Production)?;
    let metrics = xtask::scalingbench::run(&qemu, &system, &xtask::target_dir().join("bench"))?;
    print_and_write(&metrics, "scaling.json")
}

/// `bench --guest-smp`: only the guest's multicore benchmark (`xtask::guestsmpbench`).
fn guest_smp_bench() -> Result<bool> {
    let qemu = tools::ensure_qemu()?;
    let system = artifacts::build(true, KernelVariant::Production)?;
    let metrics = xtask::guestsmpbench::run(&qemu, &system, &xtask::target_dir().join("bench"))?;
    print_and_write(&metrics, "guest-smp.json")
}

/// `bench --hostile`: only the attack systems (see [`hostile_lateness`]).
fn hostile() -> Result<bool> {
    let qemu = tools::ensure_qemu_deterministic()?;
    let system = artifacts::build(true, KernelVariant::Production)?;
    let metrics = hostile_lateness(&qemu, &system, &xtask::target_dir().join("bench"))?;
    print_and_write(&metrics, "hostile.json")
}

/// `cargo xtask bench --soak`: only the soak; writes `target/bench/soak.json`.
fn soak(frames: u64) -> Result<bool> {
    let qemu = tools::ensure_qemu_deterministic()?;
    let system = artifacts::build(true, KernelVariant::Production)?;
    let metrics = soak_metrics(&qemu, &system, &xtask::target_dir().join("bench"), frames)?;
    print_and_write(&metrics, "soak.json")
}

/// Boots the soak system (tests/configs/soak.toml, its victim renamed to log `frames`
/// windows, one per major frame) on virtual time and reads its victim's last line:
/// `soak_missed_windows`, `soak_window_drift`, `soak_window_lateness`.
fn soak_metrics(
    qemu: &tools::Qemu,
    system: &artifacts::Artifacts,
    dir: &std::path::Path,
    frames: u64,
) -> Result<Vec<xtask::bench::Metric>> {
    if !(2..=99_999_999_999).contains(&frames) {
        bail!(
            "--frames {frames}: the soak needs 2 to 99999999999 frames (the victim's name holds the count)"
        );
    }
    let dir = dir.join("soak");
    std::fs::create_dir_all(&dir)?;
    let text = std::fs::read_to_string(xtask::workspace_root().join("tests/configs/soak.toml"))?;
    let victim = format!("victim-{SOAK_FRAMES}");
    if !text.contains(&victim) {
        bail!("tests/configs/soak.toml has no partition {victim}");
    }
    let config = dir.join("soak.toml");
    std::fs::write(&config, text.replace(&victim, &format!("victim-{frames}")))?;
    let started = std::time::Instant::now();
    let outcome = boot_bench_system(
        qemu,
        system,
        Some(&config),
        &dir,
        &format!("soak system ({frames} major frames)"),
        true,
        // Measured: 10^6 frames take about 150 s of host time under TCG.
        Duration::from_secs(600 + frames / 1_000),
    )?;
    eprintln!(
        "xtask: the soak of {frames} major frames took {:.0} s of host time",
        started.elapsed().as_secs_f64()
    );
    match outcome
        .lines
        .iter()
        .rev()
        .find_map(|l| xtask::bench::parse_soak(l))
    {
        Some(metrics) => Ok(metrics.into()),
        None => bail!(
            "the soak system printed no victim summary\n{}",
            outcome.transcript()
        ),
    }
}

/// Prints the `bench` lines of a part of the bench and writes them to
/// `target/bench/<file>`.
fn print_and_write(metrics: &[xtask::bench::Metric], file: &str) -> Result<bool> {
    for m in metrics {
        println!("{}", xtask::bench::format_line(m));
    }
    let report = xtask::bench::write_report_as(metrics, file)?;
    eprintln!("xtask: wrote {}", report.display());
    Ok(true)
}

/// `cargo xtask bench --disk`: only the disk benchmark ([`xtask::diskbench`]); writes
/// `target/bench/disk.json`.
fn disk_bench(deterministic_time: bool) -> Result<bool> {
    let qemu = tools::ensure_qemu_deterministic()?;
    let system = artifacts::build(true, KernelVariant::Production)?;
    let dir = xtask::target_dir().join("bench");
    let metrics = xtask::diskbench::run(&qemu, &system, &dir, deterministic_time)?;
    print_and_write(&metrics, "disk.json")
}

/// `cargo xtask bench --kernel`: only the kernel micro-benchmarks; writes
/// `target/bench/kernel.json`.
fn kernel_bench(deterministic_time: bool) -> Result<bool> {
    let qemu = tools::ensure_qemu_deterministic()?;
    let system = artifacts::build(true, KernelVariant::Production)?;
    let metrics = kernel_metrics(
        &qemu,
        &system,
        &xtask::target_dir().join("bench"),
        deterministic_time,
    )?;
    print_and_write(&metrics, "kernel.json")
}

/// The kernel micro-benchmarks: `tests/programs/bench` as the root task, no syssw.
fn kernel_metrics(
    qemu: &tools::Qemu,
    system: &artifacts::Artifacts,
    dir: &std::path::Path,
    deterministic_time: bool,
) -> Result<Vec<xtask::bench::Metric>> {
    let mut kernel_bench = system.clone();
    kernel_bench.syssw = artifacts::build_user_programs(&["bench-kernel".to_string()])?.remove(0);
    let entries = esp::standard_entries(&kernel_bench, None)?;
    let outcome = boot_bench_image(
        qemu,
        &kernel_bench,
        entries,
        &dir.join("kernel"),
        "kernel benchmark system",
        deterministic_time,
        bench_timeout(deterministic_time),
        // A second CPU for `ipc_roundtrip_cross_cpu`.
        &["-smp", "2"],
    )?;
    let mut metrics: Vec<_> = outcome
        .lines
        .iter()
        .filter_map(|l| xtask::bench::parse_line(l))
        .collect();
    // Each CPU's window starts while the other CPU spins (tests/configs/bench_smp_lateness.toml).
    let config = xtask::workspace_root().join("tests/configs/bench_smp_lateness.toml");
    let outcome = boot_bench_system(
        qemu,
        system,
        Some(&config),
        &dir.join("smp_lateness"),
        "per-CPU window-start lateness system",
        deterministic_time,
        bench_timeout(deterministic_time),
    )?;
    for cpu in 0..2 {
        let name = format!("window_lateness_cpu{cpu}");
        let what = format!("the per-CPU lateness system's CPU {cpu}");
        metrics.push(victim_lateness(
            &outcome,
            &format!("[victim{cpu}-"),
            &name,
            &what,
        )?);
    }
    Ok(metrics)
}

/// Metric `name` from the first victim lateness summary on a log line that contains
/// `victim` (a partition's tag where several victims log; "" for any line); an error
/// naming `what` without one.
fn victim_lateness(
    outcome: &qemu::Outcome,
    victim: &str,
    name: &str,
    what: &str,
) -> Result<xtask::bench::Metric> {
    let metric = outcome
        .lines
        .iter()
        .filter(|l| l.contains(victim))
        .find_map(|l| xtask::bench::parse_victim_lateness(l, name));
    match metric {
        Some(m) => Ok(m),
        None => bail!(
            "{what}: its victim printed no lateness\n{}",
            outcome.transcript()
        ),
    }
}

fn bench(deterministic_time: bool) -> Result<bool> {
    let qemu = tools::ensure_qemu_deterministic()?;
    let system = artifacts::build(true, KernelVariant::Production)?;
    let dir = xtask::target_dir().join("bench");
    // The kernel benchmarks run as the root task; the port benchmark is an APEX partition
    // under the real syssw (`tests/configs/bench_ports.toml`).
    let mut metrics = kernel_metrics(&qemu, &system, &dir, deterministic_time)?;
    metrics.extend(ports_metrics(&qemu, &system, &dir, deterministic_time)?);
    metrics.extend(schedule_switch_metrics(&qemu, &system, &dir)?);
    metrics.extend(plc_metrics(&qemu, &system, &dir)?);
    metrics.extend(hostile_lateness(&qemu, &system, &dir)?);
    metrics.extend(soak_metrics(&qemu, &system, &dir, SOAK_FRAMES)?);
    metrics.extend(guest_metrics(&qemu, &system, &dir, deterministic_time)?);
    metrics.extend(xtask::diskbench::run(
        &qemu,
        &system,
        &dir,
        deterministic_time,
    )?);
    metrics.extend(xtask::fortebench::run(
        &qemu,
        &system,
        &dir,
        deterministic_time,
    )?);
    // Timed from the host: always real time.
    metrics.extend(xtask::netbench::run(&qemu, &system, &dir)?);
    metrics.extend(xtask::plcnetbench::run(&qemu, &system, &dir)?);
    metrics.extend(xtask::pubsubbench::run(&qemu, &system, &dir)?);
    eprintln!("xtask: running the host benchmarks");
    metrics.extend(xtask::bench::host_metrics()?);
    for m in &metrics {
        println!("{}", xtask::bench::format_line(m));
    }
    let report = xtask::bench::write_report(&metrics)?;
    eprintln!("xtask: wrote {}", report.display());
    Ok(true)
}
