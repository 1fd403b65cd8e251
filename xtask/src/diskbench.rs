//! The disk benchmark of `cargo xtask bench` (alone with `--disk`): the guest's file system
//! on the block-device partition against Debian's stock kernel on the same emulated disk,
//! and the soft-PLC's persistent store.
//!
//! - **The guest leg** boots [`GUEST_CONFIG`] (the block-device partition driving QEMU's
//!   virtio-blk and its one tenant, the guest, whose `/dev/vda` is an 8 MiB range of the
//!   disk): `tests/configs/guest/disk_bench.sh` makes an ext2 file system with busybox
//!   `mke2fs`, mounts it at `/data` and runs `linux-bench`'s disk metrics there
//!   (`tests/linux/bench.c`: `--dir /data --remount /dev/vda`).
//! - **The native leg** boots Debian's stock kernel ([`crate::native`]) with the same
//!   guest partition's initramfs (the same busybox, `linux-bench` and script), the
//!   virtio-blk, crc32c and ext4 modules (ext4 also mounts ext2) from `/lib/modules/<version>`
//!   ([`DRIVERS`]) loaded by `/init`, on a disk of the same 8 MiB.
//! - Both get the same QEMU disk ([`qemu_args`]): VT-d, virtio-blk at 00:04.0 with the
//!   modern PCI transport only and `iommu_platform=on` on a fresh raw image under
//!   `target/bench/disk/` with `cache=writeback`.
//! - **The PLC** ([`plc_metrics`]): three boots of a PLC with its store on its virtual
//!   disk. The first ([`PLC_CONFIG`], a fresh disk) runs a program with 4 KiB of RETAIN
//!   values, saved every 500 ms, while a guest downloads a new revision (the boot project);
//!   the second ([`BOOT_CONFIG`], the same disk, no guest) starts that boot project, and is
//!   stopped at its first cycle; the third ([`BOOT_CONFIG`] on a fresh disk) starts its
//!   configured program with 64 KiB of RETAIN values and is stopped after
//!   [`SAVES_64KIB`] saves.
//!
//! Metrics (each median, minimum and maximum over its samples). The guest and native legs
//! always run on real time: QEMU's block layer completes requests on the host's clock,
//! and on virtual time, whose idle stretches jump to the next timer, a wait for the disk
//! takes any length (a `--deterministic-time` run of both legs gave the native leg's
//! write 0.5 to 37 MB/s in one run). The PLC's boots run on virtual time with
//! `--deterministic-time`, else on real time:
//! - `<leg>_disk_write_seq`, `<leg>_disk_read_seq` (MB/s = 10^6 bytes a second, a 1 MiB
//!   file in 64 KiB writes and fsync'd, read back after an umount and mount, 3 rounds) and
//!   `<leg>_disk_fsync` (us per call of a 4 KiB write + fsync, the mean of 20 a round,
//!   3 rounds), `<leg>` `guest` or `native`; `disk_ratio_<metric>` (guest / native,
//!   [`crate::native::ratios`]'s arithmetic: below 1 the guest's throughput is lower,
//!   above 1 its fsync slower);
//! - `plc_retain_save_4kib`, `plc_retain_save_64kib` (us: the store process's time for a
//!   save, its first sector write to its last flush, the `written in` of `plc: store:
//!   RETAIN snapshot #<n> saved`, over every save of the boot) and `plc_retain_copy_4kib`,
//!   `plc_retain_copy_64kib` (us: the control process's copy of the snapshot between
//!   releases, the `copied in`: what a save costs the scan);
//! - `plc_boot_first_cycle` (ms: from the kernel's first timestamped log line to the
//!   PLC's `plc: first cycle done` when it starts a boot project and its RETAIN snapshot
//!   from the disk, on the kernel's clock), `plc_boot_first_cycle_qemu` (ms: the same line
//!   from QEMU's start on the host's clock, firmware and loader included) and
//!   `plc_boot_first_cycle_empty_store` (ms, as the first: the configured program on an
//!   empty store).

use crate::bench::Metric;
use crate::native::Native;
use crate::qemu::{self, Outcome, RunOptions};
use anyhow::{Context, Result, bail};
use std::path::Path;
use std::time::Duration;

/// The guest leg's system description (relative to the workspace).
pub const GUEST_CONFIG: &str = "tests/configs/bench_disk.toml";
/// The PLC's first boot: the 4 KiB saves and the download of the boot project.
pub const PLC_CONFIG: &str = "tests/configs/bench_disk_plc.toml";
/// The PLC's timed boots.
pub const BOOT_CONFIG: &str = "tests/configs/bench_disk_boot.toml";
/// The stock kernel's modules for the disk and the file system (ext4 mounts ext2 in
/// Debian's kernel); [`crate::netbench::load_order`] adds what they depend on.
pub const DRIVERS: &[&str] = &["virtio_pci", "virtio_blk", "crc32c_generic", "ext4"];
/// The guest's virtual disk: its first sector and size (`blk.tenants.linux` of
/// [`GUEST_CONFIG`]); the native leg's disk is as large.
const GUEST_FIRST_SECTOR: u64 = 2048;
const GUEST_SECTORS: u64 = 16384;
/// The PLC's disk image (its tenant range is sectors 2048..4096).
const PLC_SECTORS: u64 = 8192;
/// The 64 KiB saves the third PLC boot waits for.
const SAVES_64KIB: u32 = 5;
/// The longest run of a disk leg (QEMU is stopped then).
const LEG_TIMEOUT: Duration = Duration::from_secs(900);
/// The longest run of a PLC boot.
const PLC_TIMEOUT: Duration = Duration::from_secs(600);
/// The line the PLC prints after its first cycle.
const FIRST_CYCLE: &str = "plc: first cycle done";

/// QEMU's arguments for the disk of both legs and of the PLC: VT-d, virtio-blk (modern
/// PCI only, `iommu_platform=on`) at 00:04.0 on the raw image `image`, `cache=writeback`.
pub fn qemu_args(image: &Path) -> Vec<String> {
    let mut args = qemu::iommu();
    args.extend([
        "-drive".to_string(),
        format!(
            "file={},if=none,id=disk0,format=raw,cache=writeback",
            image.display()
        ),
        "-device".to_string(),
        "virtio-blk-pci,drive=disk0,addr=04.0,disable-legacy=on,iommu_platform=on".to_string(),
    ]);
    args
}

/// A fresh zeroed raw image of `sectors` sectors of 512 bytes at `path`.
fn fresh_image(path: &Path, sectors: u64) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let _ = std::fs::remove_file(path);
    let file =
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    file.set_len(sectors * 512)?;
    Ok(())
}

/// The shell lines of the native `/init` that load the disk's and the file system's
/// modules (file names in `/modules`, in load order) and wait (at most 5 s) for `/dev/vda`.
pub fn native_setup(modules: &[String]) -> String {
    let mut lines = String::from("# /dev/vda: the virtio-blk driver and ext4 (for ext2).\n");
    for module in modules {
        lines.push_str(&format!("insmod /modules/{module}\n"));
    }
    lines.push_str(
        "i=0\nwhile [ ! -b /dev/vda ] && [ $i -lt 50 ]; do sleep 0.1; i=$((i + 1)); done\n",
    );
    lines
}

/// Runs the guest and native legs and the PLC's boots under `dir/disk`; returns their
/// metrics and the guest/native ratios.
pub fn run(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    dir: &Path,
    deterministic_time: bool,
) -> Result<Vec<Metric>> {
    let dir = dir.join("disk");
    // QEMU's block layer completes requests on the host's clock: on virtual time (whose
    // idle stretches jump to the next timer) a wait for the disk takes any length, so the
    // disk legs always run on real time.
    let mut metrics = disk_metrics(qemu, system, &dir)?;
    metrics.extend(plc_metrics(qemu, system, &dir, deterministic_time)?);
    Ok(metrics)
}

/// `guest_disk_*`, `native_disk_*` and `disk_ratio_*`, both legs on real time.
fn disk_metrics(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    dir: &Path,
) -> Result<Vec<Metric>> {
    let deterministic_time = false;
    let config = crate::workspace_root().join(GUEST_CONFIG);
    let image = dir.join("guest/disk.img");
    fresh_image(&image, GUEST_FIRST_SECTOR + GUEST_SECTORS)?;
    let entries = crate::esp::standard_entries(system, Some(&config))?;
    let esp = crate::esp::assemble(&dir.join("guest/esp"), system, &entries)?;
    eprintln!("xtask: booting the disk benchmark system (real time, as the native leg)");
    let outcome = qemu::run(
        qemu,
        &RunOptions {
            esp,
            timeout: Some(LEG_TIMEOUT),
            echo: false,
            work_dir: dir.join("guest/state"),
            deterministic_time,
            com2: qemu::Com2::Unconnected,
            done_when: Vec::new(),
            extra_args: qemu_args(&image),
        },
    )?;
    let mut metrics = leg_metrics(&outcome, "guest_", "the guest disk benchmark")?;

    let kernel = crate::native::ensure_kernel()?;
    let guest = crate::native::guest_of(&config)?;
    let (extra_files, modules) = crate::netbench::module_files_for(&kernel, DRIVERS)?;
    let image = dir.join("native/disk.img");
    fresh_image(&image, GUEST_SECTORS)?;
    let args = ["--prefix".to_string(), crate::native::PREFIX.to_string()];
    let native = Native {
        init: crate::native::script(&guest.init, &guest.env, &native_setup(&modules), &args),
        extra_files,
        qemu_args: qemu_args(&image),
        timeout: LEG_TIMEOUT,
    };
    let (outcome, status) = crate::native::boot(
        qemu,
        &config,
        &dir.join("native"),
        deterministic_time,
        native,
    )?;
    if status.as_deref() != Some("0") {
        bail!(
            "the native disk benchmark failed (exit status {})\n{}",
            status.as_deref().unwrap_or("not printed"),
            outcome.transcript()
        );
    }
    metrics.extend(leg_metrics(
        &outcome,
        crate::native::PREFIX,
        "the native disk benchmark",
    )?);
    let ratios = crate::native::ratios(&metrics)?;
    metrics.extend(ratios.into_iter().map(|r| Metric {
        name: r.name.replace("guest_ratio_disk_", "disk_ratio_"),
        ..r
    }));
    Ok(metrics)
}

/// The `<prefix>disk_*` lines of a leg (its notes to stderr); an error when a metric is
/// missing or the benchmark reported one.
fn leg_metrics(outcome: &Outcome, prefix: &str, what: &str) -> Result<Vec<Metric>> {
    let errors: Vec<&String> = outcome
        .lines
        .iter()
        .filter(|l| {
            l.contains("bench-error") || (l.contains("disk-bench: ") && l.contains("failed"))
        })
        .collect();
    let metrics: Vec<Metric> = outcome
        .lines
        .iter()
        .filter_map(|l| crate::bench::parse_line(l))
        .filter(|m| m.name.starts_with(prefix))
        .collect();
    for note in outcome
        .lines
        .iter()
        .filter(|l| (l.contains("note ") && l.contains("disk_")) || l.contains("disk-bench: "))
    {
        // From the note itself on (a native console line may begin with the firmware's
        // escape sequences).
        let at = ["note ", "disk-bench: "]
            .iter()
            .filter_map(|key| note.find(key))
            .min()
            .unwrap_or(0);
        eprintln!("xtask: {}", note[at..].trim());
    }
    if !errors.is_empty() || metrics.len() != 3 {
        bail!(
            "{what} failed ({} metrics): {errors:?}\n{}",
            metrics.len(),
            outcome.transcript()
        );
    }
    Ok(metrics)
}

fn time_mode(deterministic_time: bool) -> &'static str {
    if deterministic_time {
        " (virtual time)"
    } else {
        ""
    }
}

/// One boot of the PLC: its description, where its files go, when to stop it, what it is.
struct PlcBoot<'a> {
    config: &'a str,
    dir: &'a Path,
    done_when: Vec<String>,
    what: &'a str,
}

/// Boots `boot.config` on the disk image `image` under `boot.dir` until the system ends or
/// the log has shown each of `boot.done_when`.
fn boot_plc(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    image: &Path,
    deterministic_time: bool,
    boot: PlcBoot<'_>,
) -> Result<Outcome> {
    let PlcBoot {
        config,
        dir,
        done_when,
        what,
    } = boot;
    let config = crate::workspace_root().join(config);
    let entries = crate::esp::standard_entries(system, Some(&config))?;
    let esp = crate::esp::assemble(&dir.join("esp"), system, &entries)?;
    eprintln!("xtask: booting {what}{}", time_mode(deterministic_time));
    let outcome = qemu::run(
        qemu,
        &RunOptions {
            esp,
            timeout: Some(PLC_TIMEOUT),
            echo: false,
            work_dir: dir.join("state"),
            deterministic_time,
            com2: qemu::Com2::Unconnected,
            done_when,
            extra_args: qemu_args(image),
        },
    )?;
    if outcome.line("panic at ").is_some() || outcome.line("KERNEL PANIC").is_some() {
        bail!("{what}: a panic\n{}", outcome.transcript());
    }
    Ok(outcome)
}

/// The PLC's boots (see the module documentation): `plc_retain_*` and `plc_boot_*`.
fn plc_metrics(
    qemu: &crate::tools::Qemu,
    system: &crate::artifacts::Artifacts,
    dir: &Path,
    deterministic_time: bool,
) -> Result<Vec<Metric>> {
    let dir = dir.join("plc");
    let image = dir.join("disk.img");
    fresh_image(&image, PLC_SECTORS)?;
    // 1. 4 KiB saves; a guest downloads the boot project.
    let first = boot_plc(
        qemu,
        system,
        &image,
        deterministic_time,
        PlcBoot {
            config: PLC_CONFIG,
            dir: &dir.join("first"),
            done_when: Vec::new(),
            what: "the PLC store benchmark system (4 KiB of RETAIN, a download)",
        },
    )?;
    if !first.succeeded() || first.line("plc: store: boot project #1 saved").is_none() {
        bail!(
            "the PLC's first boot did not save the downloaded boot project\n{}",
            first.transcript()
        );
    }
    let mut metrics = retain_metrics(&first.lines, "4kib")?;
    // 2. The boot project from the disk, to its first cycle.
    let boot = boot_plc(
        qemu,
        system,
        &image,
        deterministic_time,
        PlcBoot {
            config: BOOT_CONFIG,
            dir: &dir.join("boot"),
            done_when: vec![FIRST_CYCLE.to_string()],
            what: "the PLC with its boot project",
        },
    )?;
    if boot.line("plc: store: boot project #1 loaded").is_none()
        || boot.ending != qemu::Ending::Done
    {
        bail!(
            "the PLC did not start its boot project to a first cycle\n{}",
            boot.transcript()
        );
    }
    let ms = boot_ms(&boot.lines).context("no timestamp on the first-cycle line")?;
    metrics.push(single("plc_boot_first_cycle", ms, "ms"));
    let qemu_ms = (boot.elapsed.as_secs_f64() * 1000.0).round();
    metrics.push(single("plc_boot_first_cycle_qemu", qemu_ms, "ms"));
    // 3. The configured program with 64 KiB of RETAIN on an empty store.
    fresh_image(&image, PLC_SECTORS)?;
    let last = format!("plc: store: RETAIN snapshot #{SAVES_64KIB} saved");
    let large = boot_plc(
        qemu,
        system,
        &image,
        deterministic_time,
        PlcBoot {
            config: BOOT_CONFIG,
            dir: &dir.join("large"),
            done_when: vec![FIRST_CYCLE.to_string(), last],
            what: "the PLC with 64 KiB of RETAIN on an empty store",
        },
    )?;
    if large.ending != qemu::Ending::Done
        || large
            .line("plc: store: no boot project; the configured program runs")
            .is_none()
    {
        bail!(
            "the PLC with 64 KiB of RETAIN did not save {SAVES_64KIB} snapshots\n{}",
            large.transcript()
        );
    }
    let ms = boot_ms(&large.lines).context("no timestamp on the first-cycle line")?;
    metrics.push(single("plc_boot_first_cycle_empty_store", ms, "ms"));
    metrics.extend(retain_metrics(&large.lines, "64kib")?);
    Ok(metrics)
}

fn single(name: &str, value: f64, unit: &str) -> Metric {
    Metric {
        name: name.to_string(),
        median: value,
        min: value,
        max: value,
        unit: unit.to_string(),
        samples: 1,
    }
}

/// The kernel's timestamp (seconds) at the start of a log line (`[   2.094403] ...`).
pub fn timestamp(line: &str) -> Option<f64> {
    let rest = line.trim_start().strip_prefix('[')?;
    let (number, _) = rest.split_once(']')?;
    number.trim().parse().ok()
}

/// Milliseconds from the first timestamped line of `lines` to the first-cycle line.
pub fn boot_ms(lines: &[String]) -> Option<f64> {
    let start = lines.iter().find_map(|l| timestamp(l))?;
    let cycle = lines
        .iter()
        .find(|l| l.contains(FIRST_CYCLE))
        .and_then(|l| timestamp(l))?;
    Some(((cycle - start) * 1000.0 * 10.0).round() / 10.0)
}

/// A save line's snapshot bytes, copy and write times (us): `plc: store: RETAIN snapshot
/// #<n> saved (release <r>, <n> bytes, copied in <us> us, written in <us> us)`.
pub fn parse_save(line: &str) -> Option<(u64, u64, u64)> {
    let rest = &line[line.find("plc: store: RETAIN snapshot #")?..];
    let rest = &rest[rest.find(" saved (release ")?..];
    let number_before = |key: &str| -> Option<u64> {
        let end = rest.find(key)?;
        rest[..end].rsplit([' ', '(']).next()?.parse().ok()
    };
    let number_after = |key: &str| -> Option<u64> {
        let start = rest.find(key)? + key.len();
        rest[start..].split(' ').next()?.parse().ok()
    };
    Some((
        number_before(" bytes,")?,
        number_after("copied in ")?,
        number_after("written in ")?,
    ))
}

/// `plc_retain_save_<size>` and `plc_retain_copy_<size>` (us) over every save in `lines`.
fn retain_metrics(lines: &[String], size: &str) -> Result<Vec<Metric>> {
    let saves: Vec<(u64, u64, u64)> = lines.iter().filter_map(|l| parse_save(l)).collect();
    if saves.is_empty() {
        bail!("no RETAIN save with its times in the log ({size})");
    }
    let bytes: Vec<u64> = saves.iter().map(|s| s.0).collect();
    eprintln!(
        "xtask: {} RETAIN saves of {}..{} bytes ({size})",
        saves.len(),
        bytes.iter().min().unwrap_or(&0),
        bytes.iter().max().unwrap_or(&0)
    );
    let written: Vec<f64> = saves.iter().map(|s| s.2 as f64).collect();
    let copied: Vec<f64> = saves.iter().map(|s| s.1 as f64).collect();
    Ok(vec![
        crate::bench::summary(&format!("plc_retain_save_{size}"), "us", &written),
        crate::bench::summary(&format!("plc_retain_copy_{size}"), "us", &copied),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_save_and_boot_lines() {
        let line = "[  12.300001] [plc] plc: store: RETAIN snapshot #7 saved (release 1200, 4149 bytes, copied in 12 us, written in 140321 us)";
        assert_eq!(parse_save(line), Some((4149, 12, 140_321)));
        assert_eq!(
            parse_save(
                "[plc] plc: store: RETAIN snapshot #7 saved (release 1, 9 bytes, copied in 1 us)"
            ),
            None
        );
        let lines: Vec<String> = [
            "BdsDxe: loading Boot0002",
            "[   0.010162] Warden partitioning microkernel",
            "[   2.512349] [plc] plc: first cycle done (release 0)",
        ]
        .iter()
        .map(|l| l.to_string())
        .collect();
        assert_eq!(timestamp(&lines[1]), Some(0.010162));
        assert_eq!(timestamp(&lines[0]), None);
        assert_eq!(boot_ms(&lines), Some(2502.2));
    }

    #[test]
    fn both_legs_get_the_same_disk() {
        let args = qemu_args(Path::new("/t/disk.img"));
        assert_eq!(args[..2], ["-device", "intel-iommu"]);
        assert_eq!(
            args[3],
            "file=/t/disk.img,if=none,id=disk0,format=raw,cache=writeback"
        );
        assert!(args[5].starts_with("virtio-blk-pci,drive=disk0,addr=04.0"));
        let setup = native_setup(&["virtio_blk.ko".to_string()]);
        assert!(setup.contains("insmod /modules/virtio_blk.ko\n"));
        assert!(setup.contains("[ ! -b /dev/vda ]"));
    }
}
