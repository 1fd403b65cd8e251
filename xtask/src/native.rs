//! The native leg of the guest benchmark (`cargo xtask bench`, `--guest`, `--native`): the
//! same `linux-bench` run on Debian's stock Linux kernel in the same QEMU, as the reference
//! the guest partition's figures are divided by.
//!
//! - The kernel is the newest `/boot/vmlinuz-*` of Debian's `linux-image-amd64` (installed
//!   with apt-get when missing and running as root; otherwise the error says the command).
//! - The initramfs is the guest's own ([`crate::guest::entries`] of the guest partition of
//!   `tests/configs/bench_guest.toml`: the same busybox, applet links and `linux-bench`
//!   binary), with `/init` replaced by [`init_script`]: it mounts proc, sysfs and devtmpfs,
//!   runs the guest's command (`guest.init`, in the environment `guest.env` only, from `/`)
//!   with `--prefix native_`, prints `native-bench: exit <status>` and ends QEMU through the
//!   isa-debug-exit device as the Warden systems do (0x10: exit 33, success; 0x11: exit
//!   35), with `poweroff -f` behind it.
//! - QEMU runs the same machine as every Warden run ([`crate::qemu::MACHINE`]: q35, the
//!   `qemu64` CPU model, 512 MiB, TCG; real time, or virtual time when the guest leg runs on
//!   it) under the same OVMF firmware, which boots the kernel from `-kernel`/`-initrd`
//!   through its EFI stub.
//!
//! [`ratios`] turns a `guest_<metric>` and a `native_<metric>` into `guest_ratio_<metric>`.
//! This module never changes the benchmark program or its arguments: both legs run what the
//! guest partition's description says.

use crate::bench::Metric;
use crate::qemu::{self, LinuxBoot, RunOptions};
use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The Debian package of the stock kernel.
pub const KERNEL_PACKAGE: &str = "linux-image-amd64";
/// The kernel command line: the console on COM1, quiet, and a panic (an `/init` that
/// ended) ends QEMU at once (`-no-reboot`).
pub const COMMAND_LINE: &str = "console=ttyS0 quiet panic=-1";
/// The prefix of the native run's metrics.
pub const PREFIX: &str = "native_";
/// The line `/init` prints when the benchmark ended, before the status.
const EXIT_LINE: &str = "native-bench: exit ";
/// The longest native run: its loops take a few minutes under TCG.
const TIMEOUT: Duration = Duration::from_secs(1800);

/// The newest `vmlinuz-<version>` in `dir`, by version (numeric parts compared as numbers).
pub fn newest_kernel(dir: &Path) -> Option<PathBuf> {
    let version_key = |name: &str| -> Vec<(u64, String)> {
        name.split(['.', '-', '+', '~'])
            .map(|part| (part.parse().unwrap_or(0), part.to_string()))
            .collect()
    };
    std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter_map(|name| name.strip_prefix("vmlinuz-").map(str::to_string))
        .max_by_key(|version| version_key(version))
        .map(|version| dir.join(format!("vmlinuz-{version}")))
}

/// Debian's stock kernel, installing `linux-image-amd64` first if `/boot` has none.
pub fn ensure_kernel() -> Result<PathBuf> {
    let boot = Path::new("/boot");
    if let Some(kernel) = newest_kernel(boot) {
        return Ok(kernel);
    }
    crate::tools::install_packages(
        &[KERNEL_PACKAGE],
        "a Linux kernel in /boot (Debian package linux-image-amd64) is",
    )?;
    newest_kernel(boot).context("still no /boot/vmlinuz-* after installing linux-image-amd64")
}

/// The native `/init`: runs `init` (the guest's command and arguments) in the environment
/// `env` only, from `/`, with `--prefix native_`, then ends QEMU with its status.
pub fn init_script(init: &[String], env: &[String]) -> String {
    let args = ["--prefix".to_string(), PREFIX.to_string()];
    script(init, env, "", &args)
}

/// A native `/init`: mounts proc, sysfs and devtmpfs, brings up `lo`, runs the shell lines
/// `setup`, then `init` with `args` appended in the environment `env` only, from `/`, and
/// ends QEMU with its status.
pub fn script(init: &[String], env: &[String], setup: &str, args: &[String]) -> String {
    let command: Vec<String> = env
        .iter()
        .chain(init)
        .map(|s| crate::guest::quote(s))
        .chain(args.iter().cloned())
        .collect();
    format!(
        "#!/bin/sh
# The native leg of `cargo xtask bench` (xtask/src/native.rs), as PID 1 of a stock kernel.
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t devtmpfs devtmpfs /dev
# The loopback (the TCP metrics), up as in the guest.
ifconfig lo 127.0.0.1 up
{setup}cd /
env -i {command}
status=$?
echo \"{EXIT_LINE}$status\"
# isa-debug-exit (port 0xf4): 0x10 ends QEMU with 33 (success), 0x11 with 35.
if [ $status = 0 ]; then code='\\020'; else code='\\021'; fi
printf \"$code\" | dd of=/dev/port bs=1 seek=244 count=1 2>/dev/null
poweroff -f
",
        command = command.join(" ")
    )
}

/// The initramfs of the native run: the guest's (`guest`) with `init` as `/init`, a
/// `/sys` to mount, and `extra` (path without the leading `/`, mode, contents) added.
pub fn initramfs(
    busybox: &[u8],
    applets: &[String],
    guest: &config::system::Guest,
    init: &str,
    extra: Vec<(String, u32, Vec<u8>)>,
) -> Result<Vec<u8>> {
    let mut entries = crate::guest::entries(busybox, applets, guest, &[])?;
    let init = (
        "init".to_string(),
        crate::guest::S_IFREG | 0o755,
        init.as_bytes().to_vec(),
    );
    match entries.iter_mut().find(|e| e.0 == "init") {
        Some(existing) => *existing = init,
        None => entries.push(init),
    }
    if !entries.iter().any(|e| e.0 == "sys") {
        entries.push(("sys".to_string(), crate::guest::S_IFDIR | 0o755, Vec::new()));
    }
    entries.extend(extra);
    crate::guest::archive(entries)
}

/// The guest of the first guest partition of the description `config`.
pub fn guest_of(config: &Path) -> Result<config::system::Guest> {
    crate::check_config::load(config)?
        .partitions
        .into_iter()
        .find_map(|p| p.guest)
        .with_context(|| format!("{} has no guest partition", config.display()))
}

/// How a native run boots besides the kernel: its `/init`, more initramfs files, more
/// QEMU arguments, and how long it may take.
pub struct Native {
    pub init: String,
    pub extra_files: Vec<(String, u32, Vec<u8>)>,
    pub qemu_args: Vec<String>,
    pub timeout: Duration,
}

/// Boots the stock kernel with the guest partition of `config`'s initramfs made native by
/// `native` under `dir` (on virtual time with `deterministic_time`) and returns what it
/// printed with its `/init`'s exit status (`None`: not printed).
pub fn boot(
    qemu: &crate::tools::Qemu,
    config: &Path,
    dir: &Path,
    deterministic_time: bool,
    native: Native,
) -> Result<(qemu::Outcome, Option<String>)> {
    let kernel = ensure_kernel()?;
    // QEMU only says it cannot load it; some distributions keep /boot root-only.
    std::fs::File::open(&kernel).with_context(|| format!("cannot read {}", kernel.display()))?;
    let guest = guest_of(config)?;
    let (busybox, applets) = crate::guest::busybox()?;
    std::fs::create_dir_all(dir)?;
    let initrd = dir.join("initramfs.cpio");
    let archive = initramfs(&busybox, &applets, &guest, &native.init, native.extra_files)?;
    std::fs::write(&initrd, archive)
        .with_context(|| format!("cannot write {}", initrd.display()))?;
    eprintln!(
        "xtask: booting {} with the native benchmark initramfs",
        kernel.display()
    );
    let outcome = qemu::run_linux(
        qemu,
        &LinuxBoot {
            kernel,
            initrd,
            command_line: COMMAND_LINE.to_string(),
        },
        &RunOptions {
            esp: PathBuf::new(),
            timeout: Some(native.timeout),
            echo: false,
            work_dir: dir.join("state"),
            deterministic_time,
            com2: qemu::Com2::Unconnected,
            done_when: Vec::new(),
            extra_args: native.qemu_args,
        },
    )?;
    let status = outcome
        .lines
        .iter()
        .find_map(|l| Some(l[l.find(EXIT_LINE)? + EXIT_LINE.len()..].trim().to_string()));
    if status.is_some() && !outcome.succeeded() {
        eprintln!(
            "xtask: note: the native run ended with {:?}, not through isa-debug-exit",
            outcome.ending
        );
    }
    Ok((outcome, status))
}

/// Boots the stock kernel with the native initramfs of the guest partition of `config` under
/// `dir` (on virtual time with `deterministic_time`, as the guest leg) and returns the
/// `native_*` metrics it printed; an error unless the benchmark ended with status 0.
pub fn metrics(
    qemu: &crate::tools::Qemu,
    config: &Path,
    dir: &Path,
    deterministic_time: bool,
) -> Result<Vec<Metric>> {
    let guest = guest_of(config)?;
    let native = Native {
        init: init_script(&guest.init, &guest.env),
        extra_files: Vec::new(),
        qemu_args: Vec::new(),
        timeout: TIMEOUT,
    };
    let (outcome, status) = boot(qemu, config, dir, deterministic_time, native)?;
    let metrics: Vec<Metric> = outcome
        .lines
        .iter()
        .filter_map(|l| crate::bench::parse_line(l))
        .filter(|m| m.name.starts_with(PREFIX))
        .collect();
    if status.as_deref() != Some("0") || metrics.is_empty() {
        bail!(
            "the native benchmark failed (exit status {})\n{}",
            status.as_deref().unwrap_or("not printed"),
            outcome.transcript()
        );
    }
    Ok(metrics)
}

/// `guest_ratio_<metric>` for each `guest_<metric>` in `metrics` from it and its
/// `native_<metric>`: the guest's median over the native one; `min` is the guest's minimum
/// over the native maximum and `max` the guest's maximum over the native minimum (the
/// extremes the two sample ranges allow); `samples` the fewer of the two. An error names the
/// guest metrics without a native one to divide by (a native line lost or garbled on the
/// console, or a unit that differs).
pub fn ratios(metrics: &[Metric]) -> Result<Vec<Metric>> {
    let mut out = Vec::new();
    let mut unmatched = Vec::new();
    for guest in metrics {
        let Some(name) = guest.name.strip_prefix("guest_") else {
            continue;
        };
        let native = metrics.iter().find(|m| {
            m.name.strip_prefix(PREFIX) == Some(name) && m.unit == guest.unit && m.min > 0.0
        });
        let Some(native) = native else {
            unmatched.push(guest.name.as_str());
            continue;
        };
        out.push(Metric {
            name: format!("guest_ratio_{name}"),
            median: round(guest.median / native.median),
            min: round(guest.min / native.max),
            max: round(guest.max / native.min),
            unit: "ratio".to_string(),
            samples: guest.samples.min(native.samples),
        });
    }
    if !unmatched.is_empty() {
        bail!("no native figure to compare {} with", unmatched.join(", "));
    }
    Ok(out)
}

/// `x` to three decimals (the figures are medians of five rounds, no finer).
fn round(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use guest::cpio::Archive;

    fn metric(name: &str, median: f64, min: f64, max: f64, samples: u64) -> Metric {
        Metric {
            name: name.to_string(),
            median,
            min,
            max,
            unit: "cycles".to_string(),
            samples,
        }
    }

    #[test]
    fn ratios_divide_the_guest_by_the_native_figures() {
        let metrics = [
            metric("host_getpid", 100.0, 90.0, 110.0, 5),
            metric("guest_getpid", 3000.0, 2800.0, 3600.0, 5),
            metric("native_getpid", 1000.0, 900.0, 1200.0, 5),
            metric("native_gzip_4mib", 1.0, 1.0, 1.0, 5),
            metric("native_pipe_roundtrip", 2.0, 2.0, 2.0, 3),
            metric("guest_pipe_roundtrip", 4.0, 3.0, 5.0, 5),
        ];
        let r = ratios(&metrics).unwrap();
        assert_eq!(r.len(), 2, "{r:?}");
        assert_eq!(r[0].name, "guest_ratio_getpid");
        assert_eq!((r[0].median, r[0].min, r[0].max), (3.0, 2.333, 4.0));
        assert_eq!((r[0].unit.as_str(), r[0].samples), ("ratio", 5));
        assert_eq!(r[1].name, "guest_ratio_pipe_roundtrip");
        assert_eq!((r[1].median, r[1].samples), (2.0, 3));
        let line = crate::bench::format_line(&r[0]);
        assert_eq!(crate::bench::parse_line(&line).as_ref(), Some(&r[0]));
        let mut lost = metrics.to_vec();
        lost.push(metric("guest_fork_exit", 9.0, 9.0, 9.0, 5));
        lost.push(metric("guest_vfork_exit", 9.0, 9.0, 9.0, 5));
        lost.push(Metric {
            unit: "ns".to_string(),
            ..metric("native_vfork_exit", 9.0, 9.0, 9.0, 5)
        });
        let err = ratios(&lost).unwrap_err().to_string();
        assert_eq!(
            err,
            "no native figure to compare guest_fork_exit, guest_vfork_exit with"
        );
    }

    #[test]
    fn the_newest_kernel_is_found_by_version() {
        let dir = std::env::temp_dir().join(format!("xtask-native-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        assert_eq!(newest_kernel(&dir), None);
        for name in [
            "vmlinuz-6.1.0-9-amd64",
            "vmlinuz-6.1.0-56-amd64",
            "config-6.1.0-60-amd64",
        ] {
            std::fs::write(dir.join(name), b"").unwrap();
        }
        assert_eq!(
            newest_kernel(&dir),
            Some(dir.join("vmlinuz-6.1.0-56-amd64"))
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_native_init_runs_the_guests_command_and_ends_qemu() {
        let guest = config::system::Guest {
            init: vec!["/bin/linux-bench".into(), "--loops".into(), "1000".into()],
            env: vec!["A=it's".into()],
            files: Vec::new(),
            console_com2: false,
            programs: Vec::new(),
            net: None,
            disk: None,
        };
        let script = init_script(&guest.init, &guest.env);
        assert!(
            script.contains(
                "\nenv -i 'A=it'\\''s' '/bin/linux-bench' '--loops' '1000' --prefix native_\n"
            ),
            "{script}"
        );
        assert!(script.contains("mount -t devtmpfs devtmpfs /dev\n"));
        assert!(script.contains("dd of=/dev/port bs=1 seek=244"));
        let applets = vec!["bin/sh".to_string()];
        let bytes = initramfs(b"\x7fELF-busybox", &applets, &guest, &script, Vec::new()).unwrap();
        let fs = Archive::new(&bytes).unwrap();
        let init = fs.get("/init").unwrap();
        assert_eq!(init.data, script.as_bytes());
        assert_eq!(init.mode, crate::guest::S_IFREG | 0o755);
        assert_eq!(fs.entries().filter(|e| e.path() == "init").count(), 1);
        assert!(fs.get("/sys").unwrap().is_dir());
        assert!(fs.get("/proc").unwrap().is_dir());
        assert_eq!(fs.get("/bin/busybox").unwrap().data, b"\x7fELF-busybox");
        // The guest's own files stay: the same archive but for /init and /sys.
        let guest_bytes =
            crate::guest::initramfs(b"\x7fELF-busybox", &applets, &guest, &[]).unwrap();
        let guest_fs = Archive::new(&guest_bytes).unwrap();
        for e in guest_fs.entries().filter(|e| e.path() != "init") {
            let path = format!("/{}", e.path());
            assert_eq!(fs.get(&path).unwrap().data, e.data, "{path}");
        }
    }
}
