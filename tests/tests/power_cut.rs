//! Scenario `store_power_cut` (configuration `tests/configs/store_power_cut.toml`): power
//! cuts of the PLC's persistent store. The machine boots again and again on one disk image;
//! each boot is ended by a power cut (QEMU killed with SIGKILL, no shutdown:
//! [`xtask::qemu::run_cut`], ending [`Ending::Cut`]) and the next boot checks what it left.
//!
//! What runs: the PLC saves RETAIN (the counter `Keep.cycles`) every 100 ms (10 releases)
//! while the guest downloads `plc/store_v2.st` (revision 2) and `plc/store_v3.st`
//! (revision 3, a longer image) in turn with plcctl, 200 ms apart; every download becomes
//! the boot project. The guest first reads what the PLC runs and what its store loaded, then
//! prints `power_cut: workload starts`; the cut comes a random delay after that line (0 to
//! 3 s: the downloads, the boot-project saves, the RETAIN saves and the pauses between
//! them), from a seeded generator. A cut counts from the line, not from QEMU's start, as
//! TCG boot times vary with the host's load. A killed QEMU leaves on the disk image every
//! write it had made (the host's page cache outlives it) and none after: a cut tears a save
//! between whole sectors, as a disk that finishes the sector it writes; it does not model
//! a disk losing writes from its cache that were never flushed.
//!
//! What each cut is checked for, on the disk image (read with `slots`, `softplc::persist`
//! and `softplc::store` as the PLC reads it) right after the cut:
//! - every valid slot decodes; a boot project is exactly one of the two downloaded images
//!   (never a mix: the same bytes as `cargo xtask` compiled for the guest), a RETAIN
//!   snapshot holds `Keep.cycles`, and of two snapshots the newer has no lower counter
//!   (equal when taken before the first cycle after a start);
//! - the boot project is the old one (the newest the PLC had logged as loaded or saved
//!   before the cut: the same sequence number and program) or the new one (the next
//!   sequence number, the program of the download in flight), nothing else; a slot torn by
//!   the cut is allowed only where a save of its region may have been in flight;
//! - the RETAIN snapshot is no older than the newest the PLC had logged as saved (every
//!   snapshot reported saved survived the cut) and at most two saves newer (saved, its line
//!   not out yet); with the same sequence number it is the same release.
//!
//! And on the next boot's log: the PLC loads exactly that boot project (or none, and runs
//! its configured program, revision 1) and that RETAIN snapshot, skips exactly the torn
//! slots, and the guest reads the revision of the loaded program and a counter not below
//! the snapshot's (RETAIN goes on from it). Within each boot, RETAIN snapshot sequence
//! numbers go up by one and a snapshot is taken at most [`RETAIN_EVERY`] + [`SAVE_SLACK`]
//! releases after the previous one (or the program's first cycle), or, when the previous
//! one's write took longer than [`RETAIN_EVERY`] releases (it logs its time; on real time
//! a loaded host makes the block-device partition slow), that write's releases +
//! [`SAVE_SLACK`]: a snapshot is not copied while the one before is written. A statistics
//! line of the PLC showing more releases than that since the last logged save is checked
//! against the next snapshot's line: it must come before that snapshot's write ended (+
//! [`SAVE_SLACK`]), the older one being the durable one until then; one the cut leaves
//! without a next snapshot is left to the durability check. So the snapshot a cut leaves is
//! at most the configured interval, or the time of a write, old. The bound is not applied
//! from a download until the first snapshot after its boot project is saved: a snapshot
//! waits for that write (tens of requests to the disk partition), which on real time takes
//! as many releases as the host's load makes it. No partition panics, no save fails, no
//! plcctl command fails.
//!
//! Each cut prints a line: its delay, what it hit (a download, a boot-project or RETAIN
//! save torn or done but not yet logged, or the time between saves) and what the disk held;
//! the end prints the tally. Cuts: 10 (`cargo xtask test store_power_cut`), or
//! `WARDEN_POWER_CUTS=N` (`cargo xtask bench --power-cut` runs 200). The seed is printed
//! first; `WARDEN_POWER_CUT_SEED=<seed>` replays its delays (the same cuts relative to the
//! line; what they hit also depends on TCG's timing, so a replay hits similar, not always
//! identical, moments). After a failure the disk image before and after the failing boot
//! and the log of the boot before it stay in `target/scenarios/store_power_cut/`.
//!
//! The second workload, the guest's file system ([`guest_fs`]): a write-fsync-rename loop
//! on ext2 on its own disk, started in the guest's script before the line the cut counts
//! from; after each cut the file system must be repaired by `e2fsck -y` (as at a Linux
//! boot set to repair, ext2 having no journal) and hold the newest version the guest
//! reported durable, intact.

mod guest_fs;

use slots::{BlockDevice, Corruption, SECTOR, SlotState};
use softplc::persist::Layout;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use xtask::qemu::{self, Com2, Ending, Outcome, PowerCut, RunOptions};
use xtask::scenario::{self, Scenario};

const NAME: &str = "store_power_cut";
/// Cuts of the ordinary run.
const CUTS: u32 = 10;
const CUTS_VAR: &str = "WARDEN_POWER_CUTS";
const SEED_VAR: &str = "WARDEN_POWER_CUT_SEED";
/// The most cuts `WARDEN_POWER_CUTS` may ask for.
const MAX_CUTS: u32 = 10_000;
/// The guest's line the cut counts from (its readings come before it, the workloads after).
const START_LINE: &str = "stdout: power_cut: workload starts";
/// Cuts come 0 to this long after [`START_LINE`].
const CUT_WINDOW_MS: u64 = 3_000;

/// The PLC's virtual disk in the configuration: sectors 2048..4096 of the disk.
const FIRST_SECTOR: u64 = 2048;
const SECTORS: u64 = 2048;
/// The PLC's period in microseconds (a logged write time in releases).
const PERIOD_US: u64 = 10_000;
/// `retain_every = "100ms"` in releases of the PLC's 10 ms period.
const RETAIN_EVERY: u64 = 10;
/// Releases a RETAIN save may come late besides the write it waited for: the control
/// process copies a snapshot only when the store process is not writing, and the store
/// process takes what was copied only at its next period and logs it before it lets go.
const SAVE_SLACK: u64 = 15;
/// The guest's downloads: file, revision, ST source's image (set from the configuration).
const PROGRAMS: [(&str, u32); 2] = [("/root/a.plcb", 2), ("/root/b.plcb", 3)];
/// What the configured program (plc/store_v1.st) has as `Keep.revision`.
const CONFIGURED_REVISION: u32 = 1;

/// One workload of the power-cut loop with its checks: the PLC's store ([`PlcStore`]) and
/// the guest's file system ([`guest_fs::GuestFiles`]).
trait Workload {
    fn name(&self) -> &'static str;
    /// Checks a boot's log: that it found on the disk what [`Workload::after_cut`] saw the
    /// previous cut leave, and how it ran until its own cut; keeps what it reported as
    /// durable for [`Workload::after_cut`].
    fn check_boot(&mut self, boot: &Outcome) -> Result<(), String>;
    /// Checks the whole disk image `image` the cut left against what the boot had reported;
    /// returns what the cut hit (tags for the tally) and what the disk holds (for the line).
    fn after_cut(&mut self, image: &[u8]) -> Result<(Vec<&'static str>, String), String>;
    /// After the last boot: that the cuts met the workload at work (a line for the summary).
    fn finish(&self) -> Result<String, String>;
}

/// The workloads of the scenario.
fn workloads() -> Vec<Box<dyn Workload>> {
    let work = scenario::output_dir().join(NAME);
    vec![
        Box::new(PlcStore::new()),
        Box::new(guest_fs::GuestFiles::new(&work)),
    ]
}

#[test]
fn store_power_cut() {
    let cuts = cuts_from_env();
    let seed = seed_from_env();
    let machine = Machine::new();
    machine.say(&format!(
        "{NAME}: seed {seed:#018x}, {cuts} cuts 0..{CUT_WINDOW_MS} ms after the workload starts (replay: {SEED_VAR}={seed:#x} {CUTS_VAR}={cuts} cargo xtask test {NAME} --scenarios-only)"
    ));
    // The configuration generator's splitmix64: the same seed, the same delays.
    let mut rng = config::generate::Rng(seed);
    let mut workloads = workloads();
    let mut tally: BTreeMap<&'static str, u32> = BTreeMap::new();
    let started = Instant::now();
    // Boot `n` (from 0) checks what cut `n` left and is ended by cut `n + 1`; the last
    // boot only checks (it is cut as soon as the workload starts).
    for n in 0..=cuts {
        let delay = if n == cuts {
            0
        } else {
            rng.range(0, CUT_WINDOW_MS - 1)
        };
        let cut = PowerCut {
            after: START_LINE.into(),
            delay: Duration::from_millis(delay),
        };
        let o = machine.boot(n == 0, &cut);
        let fail = |what: String| -> ! { machine.failed(n, cuts, seed, &o, &what) };
        if o.ending != Ending::Cut {
            fail(format!(
                "boot {n} ended {:?} before its power cut (no {START_LINE:?} line?)",
                o.ending
            ));
        }
        for marker in ["panic at ", "KERNEL PANIC", "EXCEPTION "] {
            if let Some(line) = o.line(marker) {
                fail(format!("boot {n} crashed: {line}"));
            }
        }
        for w in &mut workloads {
            if let Err(e) = w.check_boot(&o) {
                let after = if n == 0 {
                    "on a fresh disk".to_string()
                } else {
                    format!("after cut {n}")
                };
                fail(format!("{}: boot {n} {after}: {e}", w.name()));
            }
        }
        if n == cuts {
            break;
        }
        let image = std::fs::read(&machine.disk)
            .unwrap_or_else(|e| panic!("cannot read {}: {e}", machine.disk.display()));
        let (mut hits, mut found) = (Vec::new(), Vec::new());
        for w in &mut workloads {
            match w.after_cut(&image) {
                Ok((tags, text)) => {
                    hits.extend(tags);
                    found.push(format!("{}: {text}", w.name()));
                }
                Err(e) => fail(format!("{}: cut {}: {e}", w.name(), n + 1)),
            }
        }
        for tag in &hits {
            *tally.entry(tag).or_default() += 1;
        }
        machine.say(&format!(
            "{NAME}: cut {}/{cuts}: {delay} ms after the workload started (boot {:.1} s) hit {}; {}",
            n + 1,
            o.elapsed.as_secs_f64(),
            hits.join(" + "),
            found.join("; ")
        ));
    }
    let mut done = Vec::new();
    for w in &workloads {
        match w.finish() {
            Ok(text) => done.push(format!("{}: {text}", w.name())),
            Err(e) => panic!("{NAME}: {}: {e} (seed {seed:#x})", w.name()),
        }
    }
    let tally: Vec<String> = tally.iter().map(|(k, v)| format!("{k} {v}")).collect();
    machine.say(&format!(
        "{NAME}: {cuts} cuts passed in {:.0} s (seed {seed:#018x}); hit: {}; {}",
        started.elapsed().as_secs_f64(),
        tally.join(", "),
        done.join("; ")
    ));
}

/// The number of cuts: [`CUTS`], or `WARDEN_POWER_CUTS`.
fn cuts_from_env() -> u32 {
    let Some(text) = std::env::var_os(CUTS_VAR) else {
        return CUTS;
    };
    text.to_str()
        .and_then(|t| t.trim().parse().ok())
        .filter(|n| (1..=MAX_CUTS).contains(n))
        .unwrap_or_else(|| {
            panic!("{CUTS_VAR}={text:?}: expected a number of cuts, 1 to {MAX_CUTS}")
        })
}

/// The seed: `WARDEN_POWER_CUT_SEED` (decimal or 0x-hexadecimal), else from the clock.
fn seed_from_env() -> u64 {
    let Some(text) = std::env::var_os(SEED_VAR) else {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        return nanos ^ u64::from(std::process::id()).rotate_left(32);
    };
    let parsed = text.to_str().map(str::trim).and_then(|t| {
        match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
            Some(hex) => u64::from_str_radix(hex, 16).ok(),
            None => t.parse().ok(),
        }
    });
    parsed.unwrap_or_else(|| {
        panic!("{SEED_VAR}={text:?}: expected a 64-bit seed, decimal or 0x-hexadecimal")
    })
}

/// The scenario's machine: its image (built by `cargo xtask test`), QEMU and the disk.
struct Machine {
    scenario: Scenario,
    tools: xtask::tools::Qemu,
    dir: PathBuf,
    disk: PathBuf,
}

impl Machine {
    fn new() -> Machine {
        let manifest = scenario::scenarios_dir().join(format!("{NAME}.toml"));
        let scenario = scenario::load(&manifest).unwrap_or_else(|e| panic!("{e:#}"));
        let dir = scenario::output_dir().join(NAME);
        assert!(
            dir.join("esp").join("system.img").is_file(),
            "no image for scenario {NAME}: run `cargo xtask test {NAME}`"
        );
        let tools = xtask::tools::ensure_qemu().unwrap_or_else(|e| panic!("{e:#}"));
        let disk = scenarios::disk_image(NAME);
        let _ = std::fs::remove_file(dir.join("cuts.log"));
        Machine {
            scenario,
            tools,
            dir,
            disk,
        }
    }

    /// Boots on the disk image (zeroed first when `fresh`) until `cut`; the image as the
    /// boot found it is kept as `disk-before.img`.
    fn boot(&self, fresh: bool, cut: &PowerCut) -> Outcome {
        let sectors = self
            .scenario
            .manifest
            .disk_sectors
            .unwrap_or_else(|| panic!("scenario {NAME} has no disk_sectors"));
        if fresh {
            let file = std::fs::File::create(&self.disk)
                .unwrap_or_else(|e| panic!("cannot create {}: {e}", self.disk.display()));
            file.set_len(sectors * SECTOR as u64)
                .unwrap_or_else(|e| panic!("cannot size {}: {e}", self.disk.display()));
        }
        let before = self.dir.join("disk-before.img");
        std::fs::copy(&self.disk, &before)
            .unwrap_or_else(|e| panic!("cannot copy the disk image to {}: {e}", before.display()));
        let options = RunOptions {
            esp: self.dir.join("esp"),
            timeout: Some(Duration::from_secs(self.scenario.manifest.timeout_secs)),
            echo: false,
            work_dir: self.dir.join("state"),
            deterministic_time: false,
            com2: Com2::Unconnected,
            done_when: Vec::new(),
            extra_args: scenario::with_disk(&self.scenario.manifest.qemu_args, &self.disk),
        };
        // The log of the boot before (what led to the state this one starts from).
        let log = options.work_dir.join("serial.log");
        let _ = std::fs::rename(&log, log.with_file_name("serial-previous.log"));
        qemu::run_cut(&self.tools, &options, cut)
            .unwrap_or_else(|e| panic!("cannot run QEMU: {e:#}"))
    }

    /// Prints `line` at once, straight to the standard error (libtest keeps a passing test's
    /// `println!` to itself; the seed and each cut should show while the run goes on), and
    /// appends it to `cuts.log` in the scenario's directory.
    fn say(&self, line: &str) {
        use std::io::Write;
        let _ = writeln!(std::io::stderr(), "{line}");
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.dir.join("cuts.log"));
        if let Ok(mut log) = log {
            let _ = writeln!(log, "{line}");
        }
    }

    /// Stops the test: what failed, how to replay it, the boot's transcript.
    fn failed(&self, n: u32, cuts: u32, seed: u64, o: &Outcome, what: &str) -> ! {
        panic!(
            "{NAME}: {what}\nseed {seed:#x}, boot {n} of {cuts} cuts; replay the delays: {SEED_VAR}={seed:#x} {CUTS_VAR}={cuts} cargo xtask test {NAME} --scenarios-only; the disk image before this boot: {}, after it: {}; the log of the boot before: {}\n{}",
            self.dir.join("disk-before.img").display(),
            self.disk.display(),
            self.dir.join("state").join("serial-previous.log").display(),
            o.transcript()
        )
    }
}

/// The age bound on a boot's RETAIN snapshots (see the module's doc), fed the ages in
/// releases since the last logged save (or the program's start) in log order.
#[derive(Default)]
struct SaveAges {
    /// Releases the last logged write took (the next snapshot waits for it).
    last_write: u64,
    /// Statistics lines past the bound since the last logged save: (age, line).
    late: Vec<(u64, String)>,
}

impl SaveAges {
    fn bound(&self) -> u64 {
        RETAIN_EVERY.max(self.last_write) + SAVE_SLACK
    }

    /// A snapshot's line: taken `age` releases after the last, written in `written_us`;
    /// `waited_for_boot_write` exempts it (and the statistics lines before it).
    fn saved(
        &mut self,
        age: u64,
        written_us: u64,
        waited_for_boot_write: bool,
    ) -> Result<(), String> {
        let write = written_us.div_ceil(PERIOD_US);
        let late = std::mem::take(&mut self.late);
        let bound = self.bound();
        let previous_write = std::mem::replace(&mut self.last_write, write);
        if waited_for_boot_write {
            return Ok(());
        }
        if age > bound {
            return Err(format!(
                "RETAIN saved {age} releases after the last save (or the program's start), more than {RETAIN_EVERY} (or the {previous_write} the write before took) + {SAVE_SLACK}"
            ));
        }
        // Until this snapshot's write ended, the one before was the durable one.
        match late
            .into_iter()
            .find(|(scan, _)| *scan > age + write + SAVE_SLACK)
        {
            Some((scan, line)) => Err(format!(
                "{scan} releases since the last RETAIN save (or the program's start) at \"{line}\", though the next snapshot came {age} releases after that save and took {write} to write (+ {SAVE_SLACK})"
            )),
            None => Ok(()),
        }
    }

    /// A statistics line `age` releases after the last logged save: past the bound, it is
    /// checked at the next snapshot's line.
    fn statistics(&mut self, age: u64, line: &str) {
        if age > self.bound() {
            self.late.push((age, line.to_string()));
        }
    }
}

#[test]
fn a_snapshot_may_be_as_late_as_the_write_before_it_took() {
    let mut ages = SaveAges::default();
    ages.saved(10 + SAVE_SLACK, 50_000, false).unwrap();
    assert!(ages.saved(11 + SAVE_SLACK, 50_000, false).is_err());
    // A write of just over 280 ms (29 releases, rounded up) makes the next one as late.
    ages.saved(10, 280_001, false).unwrap();
    ages.saved(29 + SAVE_SLACK, 10_000, false).unwrap();
    assert!(ages.saved(11 + SAVE_SLACK, 10_000, false).is_err());
    // After a boot project's write the bound is not applied.
    ages.saved(500, 10_000, true).unwrap();
}

#[test]
fn a_late_statistics_line_is_checked_against_the_next_snapshots_write() {
    let mut ages = SaveAges::default();
    ages.statistics(10 + SAVE_SLACK, "within the bound");
    ages.statistics(40, "the snapshot copied at 12 is still being written");
    // Copied 12 releases after the last, written in 20 releases: durable at 12 + 20 + 1.
    ages.saved(12, 200_000, false).unwrap();
    ages.statistics(40, "no snapshot copied since the last");
    let e = ages.saved(12, 100_000, false).unwrap_err();
    assert!(
        e.contains("40 releases") && e.contains("no snapshot copied"),
        "{e}"
    );
    ages.statistics(500, "before a boot project's write");
    ages.saved(12, 100_000, true).unwrap();
    ages.saved(12, 100_000, false).unwrap();
}

/// The PLC's virtual disk inside a disk image (read-only).
struct PlcDisk<'a>(&'a [u8]);

impl BlockDevice for PlcDisk<'_> {
    type Error = &'static str;
    fn read(&mut self, sector: u64, buf: &mut [u8; SECTOR]) -> Result<(), &'static str> {
        let at = usize::try_from((FIRST_SECTOR + sector) * SECTOR as u64)
            .map_err(|_| "sector out of range")?;
        let bytes = self
            .0
            .get(at..at + SECTOR)
            .ok_or("past the end of the disk image")?;
        buf.copy_from_slice(bytes);
        Ok(())
    }
    fn write(&mut self, _: u64, _: &[u8; SECTOR]) -> Result<(), &'static str> {
        Err("the checks only read")
    }
    fn flush(&mut self) -> Result<(), &'static str> {
        Ok(())
    }
}

/// The store's two regions, as the PLC names them in its log.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Region {
    Boot,
    Retain,
}

impl Region {
    fn label(self) -> &'static str {
        match self {
            Region::Boot => "boot project",
            Region::Retain => "RETAIN",
        }
    }
}

/// A valid boot project on the disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct BootRecord {
    sequence: u64,
    /// The program's bytes (as the PLC logs them).
    len: usize,
    revision: u32,
}

/// A valid RETAIN snapshot on the disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct RetainRecord {
    sequence: u64,
    release: u64,
    cycles: u32,
}

/// What a cut left on the PLC's store, as the next boot must find it.
#[derive(Clone, Debug, Default)]
struct Found {
    boot: Option<BootRecord>,
    retain: Option<RetainRecord>,
    /// Slots that do not check (torn), which the PLC skips.
    corrupt: Vec<(Region, usize, Corruption)>,
}

/// A download of the guest not yet saved as the boot project at the end of the log.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Pending {
    revision: u32,
    /// The PLC swapped it in (its `download: ... verified` line came).
    committed: bool,
}

/// What a boot's log reported, for the check of its cut.
#[derive(Clone, Debug, Default)]
struct Logged {
    /// What the boot loaded.
    loaded: Found,
    /// The newest boot project loaded or saved: (sequence, program bytes).
    boot: Option<(u64, usize)>,
    /// The newest RETAIN snapshot loaded or saved: (sequence, release).
    retain: Option<(u64, u64)>,
    boot_saves: u32,
    retain_saves: u32,
    pending: Option<Pending>,
    /// The revisions the guest began to download since the last boot project the log shows.
    downloaded: Vec<u32>,
    /// The most releases seen since the last RETAIN save (or the program's start).
    worst_age: u64,
}

/// The PLC's persistent store: the boot project and RETAIN across cuts.
struct PlcStore {
    /// (revision, image) of each program the guest downloads.
    programs: Vec<(u32, Vec<u8>)>,
    /// The PLC's watch list as a boot project stores it (a name a line).
    watch: String,
    /// What the last cut left (nothing on the fresh disk of the first boot).
    expected: Found,
    logged: Logged,
    /// Saves logged over all boots: boot projects, RETAIN snapshots.
    saves: (u32, u32),
}

impl PlcStore {
    fn new() -> PlcStore {
        // The images as `cargo xtask` compiles them into the guest (`guest.files`).
        let config = xtask::workspace_root().join("tests/configs/store_power_cut.toml");
        let system = xtask::check_config::load(&config).unwrap_or_else(|e| panic!("{e:#}"));
        let guest = system
            .partitions
            .iter()
            .find_map(|p| p.guest.as_ref())
            .expect("a guest partition in the configuration");
        let watch: String = system
            .partitions
            .iter()
            .find_map(|p| p.plc.as_ref())
            .expect("a PLC partition in the configuration")
            .watch
            .iter()
            .map(|name| format!("{name}\n"))
            .collect();
        let programs = PROGRAMS
            .iter()
            .map(|&(path, revision)| {
                let (_, source) = guest
                    .files
                    .iter()
                    .find(|(p, _)| p == path)
                    .unwrap_or_else(|| panic!("no guest.files {path} in the configuration"));
                let image = xtask::plc::image_of(path, source).unwrap_or_else(|e| panic!("{e:#}"));
                (revision, image)
            })
            .collect();
        PlcStore {
            programs,
            watch,
            expected: Found::default(),
            logged: Logged::default(),
            saves: (0, 0),
        }
    }

    fn revision_of(&self, program: &[u8]) -> Option<u32> {
        self.programs
            .iter()
            .find(|(_, image)| image == program)
            .map(|(r, _)| *r)
    }

    fn len_of(&self, revision: u32) -> usize {
        self.programs
            .iter()
            .find(|(r, _)| *r == revision)
            .map_or(0, |(_, image)| image.len())
    }

    /// Reads and checks the store on `image`.
    fn read(&self, image: &[u8]) -> Result<Found, String> {
        let mut disk = PlcDisk(image);
        let layout = Layout::of(SECTORS).ok_or("no store layout")?;
        let mut found = Found::default();
        let mut payload = vec![0u8; layout.boot.capacity().max(layout.retain.capacity())];
        for (region, at) in [(Region::Boot, layout.boot), (Region::Retain, layout.retain)] {
            let scan = slots::scan(&mut disk, &at)
                .map_err(|e| format!("the {} region does not read: {e:?}", region.label()))?;
            let mut retain = Vec::new();
            for (slot, state) in scan.slots.iter().enumerate() {
                let record = match state {
                    SlotState::Empty => continue,
                    SlotState::Corrupt(c) => {
                        found.corrupt.push((region, slot, *c));
                        continue;
                    }
                    SlotState::Valid(record) => record,
                };
                let what = format!("{} slot {slot} (#{})", region.label(), record.sequence);
                let bytes = &mut payload[..record.len];
                match slots::read(&mut disk, &at, record, bytes) {
                    Ok(Some(_)) => {}
                    other => return Err(format!("{what} does not read again: {other:?}")),
                }
                match region {
                    Region::Boot => {
                        let boot = softplc::store::decode_boot(bytes)
                            .map_err(|e| format!("{what} does not decode: {e}"))?;
                        let revision = self.revision_of(boot.program).ok_or_else(|| {
                            format!(
                                "{what}: its program ({} bytes) is neither downloaded image: a mix",
                                boot.program.len()
                            )
                        })?;
                        if boot.watch != self.watch {
                            return Err(format!(
                                "{what}: its watch list is {:?}, the PLC's {:?}",
                                boot.watch, self.watch
                            ));
                        }
                        let record = BootRecord {
                            sequence: record.sequence,
                            len: boot.program.len(),
                            revision,
                        };
                        if found.boot.is_none_or(|b| b.sequence < record.sequence) {
                            found.boot = Some(record);
                        }
                    }
                    Region::Retain => {
                        let snapshot = softplc::store::decode_retain(bytes)
                            .map_err(|e| format!("{what} does not decode: {e}"))?;
                        let cycles: Vec<u32> = snapshot
                            .values()
                            .filter(|v| v.name == "Keep.cycles")
                            .filter_map(|v| v.bytes.try_into().ok().map(u32::from_le_bytes))
                            .collect();
                        let [cycles] = cycles[..] else {
                            return Err(format!("{what}: no single 4-byte Keep.cycles in it"));
                        };
                        if snapshot.count != 1 {
                            return Err(format!(
                                "{what}: {} variables, 1 expected",
                                snapshot.count
                            ));
                        }
                        retain.push(RetainRecord {
                            sequence: record.sequence,
                            release: snapshot.release,
                            cycles,
                        });
                    }
                }
            }
            retain.sort_by_key(|r| r.sequence);
            // Not below: a snapshot taken before the first cycle after a start holds the
            // restored value.
            if let [older, newer] = retain[..]
                && older.cycles > newer.cycles
            {
                return Err(format!(
                    "RETAIN snapshot #{} holds Keep.cycles {}, the older #{} {}: the counter went back",
                    newer.sequence, newer.cycles, older.sequence, older.cycles
                ));
            }
            if let Some(&newest) = retain.last() {
                found.retain = Some(newest);
            }
        }
        Ok(found)
    }
}

/// The text of partition `partition`'s log line, without the time stamp and prefix.
fn text_of<'a>(line: &'a str, partition: &str) -> Option<&'a str> {
    line.split_once(&format!("[{partition}] "))
        .map(|(_, text)| text)
}

/// What the guest's processes wrote (stdout or stderr) in a log line.
fn guest_text(line: &str) -> Option<&str> {
    let (_, rest) = line.split_once("[linux] guest: process ")?;
    let (_, rest) = rest.split_once(' ')?;
    rest.strip_prefix("stdout: ")
        .or_else(|| rest.strip_prefix("stderr: "))
}

/// The number after `key` in `text`, up to the next space, comma or parenthesis.
fn number_after(text: &str, key: &str) -> Option<u64> {
    let (_, rest) = text.split_once(key)?;
    let end = rest
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(rest.len());
    rest[..end].parse().ok()
}

/// `#<n>` or `none`, as plcctl prints a store record.
fn numbered(sequence: Option<u64>) -> String {
    sequence.map_or("none".into(), |s| format!("#{s}"))
}

impl Workload for PlcStore {
    fn name(&self) -> &'static str {
        "PLC store"
    }

    fn check_boot(&mut self, o: &Outcome) -> Result<(), String> {
        let expected = std::mem::take(&mut self.expected);
        let plc: Vec<&str> = o.lines.iter().filter_map(|l| text_of(l, "plc")).collect();
        let has = |text: &str| plc.iter().any(|l| l.contains(text));
        // What the PLC loaded.
        let boot_line = match expected.boot {
            None => "plc: store: no boot project; the configured program runs".to_string(),
            Some(b) => format!(
                "plc: store: boot project #{} loaded: {} bytes, ",
                b.sequence, b.len
            ),
        };
        let retain_lines = match expected.retain {
            None => vec!["plc: store: no RETAIN snapshot; initial values".to_string()],
            Some(r) => vec![
                format!(
                    "plc: store: RETAIN snapshot #{} loaded: 1 variable(s) of release {}",
                    r.sequence, r.release
                ),
                "plc: store: 1 RETAIN variable(s) restored".to_string(),
            ],
        };
        for line in std::iter::once(&boot_line).chain(&retain_lines) {
            if !has(line) {
                return Err(format!(
                    "the PLC did not load what the disk held: no {line:?} (the disk held {expected:?})"
                ));
            }
        }
        if let Some(line) = plc.iter().find(|l| l.contains(" refused: ")) {
            return Err(format!("the PLC refused a program: {line}"));
        }
        let mut skipped: Vec<(Region, usize)> = plc
            .iter()
            .filter(|l| l.contains(" skipped: "))
            .filter_map(|l| {
                let rest = l.strip_prefix("plc: store: ")?;
                let region = if rest.starts_with("boot project slot ") {
                    Region::Boot
                } else {
                    Region::Retain
                };
                Some((region, number_after(rest, "slot ")? as usize))
            })
            .collect();
        skipped.sort();
        let mut torn: Vec<(Region, usize)> = expected.corrupt.iter().map(|c| (c.0, c.1)).collect();
        torn.sort();
        if skipped != torn {
            return Err(format!(
                "the PLC skipped the slots {skipped:?}, the disk's torn ones are {torn:?}"
            ));
        }
        // What the guest read before the workload started.
        let guest: Vec<&str> = o.lines.iter().filter_map(|l| guest_text(l)).collect();
        let reading = |name: &str| {
            guest
                .iter()
                .find_map(|l| l.strip_prefix(&format!("{name} = ")))
                .and_then(|v| v.trim().parse::<u64>().ok())
        };
        let revision = expected.boot.map_or(CONFIGURED_REVISION, |b| b.revision);
        if reading("Keep.revision") != Some(u64::from(revision)) {
            return Err(format!(
                "the guest read Keep.revision {:?}, the loaded program has {revision}",
                reading("Keep.revision")
            ));
        }
        let cycles = reading("Keep.cycles").ok_or("the guest read no Keep.cycles")?;
        // The restored value, or more once cycles ran (the PLC may answer before its first).
        if let Some(r) = expected.retain
            && cycles < u64::from(r.cycles)
        {
            return Err(format!(
                "the guest read Keep.cycles {cycles}, below the restored snapshot's {}",
                r.cycles
            ));
        }
        let store = format!(
            "store: loaded boot project {}, RETAIN snapshot {}",
            numbered(expected.boot.map(|b| b.sequence)),
            numbered(expected.retain.map(|r| r.sequence))
        );
        if !guest.contains(&store.as_str()) {
            return Err(format!("plcctl store did not print {store:?}"));
        }
        if let Some(line) = guest
            .iter()
            .find(|l| l.starts_with("plcctl:") || l.ends_with(" failed") || l.contains("not found"))
        {
            return Err(format!("a command in the guest failed: {line}"));
        }
        // What the PLC reported durable, in log order.
        let mut logged = Logged {
            loaded: expected.clone(),
            boot: expected.boot.map(|b| (b.sequence, b.len)),
            retain: expected.retain.map(|r| (r.sequence, r.release)),
            ..Logged::default()
        };
        // The release of the running program since which its RETAIN values may differ from
        // the newest snapshot: its last save's, or its start (0), or its first cycle when
        // the PLC logs it (releases may pass while the store loads; the values change from
        // the first cycle on). A download starts the count again; a snapshot copied before
        // it may be written (and logged) after its line, so once a download came a count
        // below the last save's is what tells the new program.
        let mut last_save = 0;
        let mut downloaded = false;
        // From a download until the first snapshot after its boot project's save, which
        // the snapshots wait for: the age bound is not applied (see the module's doc).
        let (mut boot_writing, mut after_boot_write) = (false, false);
        let new_program =
            |release: u64, last_save: u64, downloaded: bool| downloaded && release < last_save;
        let since = |release: u64, last_save: u64, downloaded: bool| {
            if new_program(release, last_save, downloaded) {
                release
            } else {
                release.saturating_sub(last_save)
            }
        };
        let mut committed_len = None;
        let mut ages = SaveAges::default();
        for line in &o.lines {
            if let Some(text) = guest_text(line) {
                if let Some(file) = text.strip_prefix("power_cut: download ") {
                    let revision = match file {
                        "a" => PROGRAMS[0].1,
                        "b" => PROGRAMS[1].1,
                        other => return Err(format!("a download of {other:?}?")),
                    };
                    logged.pending = Some(Pending {
                        revision,
                        committed: false,
                    });
                    logged.downloaded.push(revision);
                }
                continue;
            }
            let Some(text) = text_of(line, "plc") else {
                continue;
            };
            if text.contains(" not saved: ") {
                return Err(format!("a save failed: {text}"));
            } else if let Some(rest) = text.strip_prefix("plc: first cycle done (release ") {
                // Releases may pass before the first cycle (while the store loads): the
                // values change from the first cycle on.
                let first = number_after(rest, "").ok_or("a first cycle line?")?;
                last_save = last_save.max(first);
            } else if text.starts_with("plc: download: ") {
                let len = number_after(text, "plc: download: ").ok_or("a download line?")?;
                committed_len = Some(len as usize);
                downloaded = true;
                boot_writing = true;
                if let Some(p) = logged.pending.as_mut() {
                    p.committed = true;
                }
            } else if let Some(rest) = text.strip_prefix("plc: store: boot project #")
                && rest.contains(" saved (")
            {
                let sequence = number_after(rest, "").ok_or("a boot project line?")?;
                let previous = logged.boot.map_or(0, |b| b.0);
                if sequence != previous + 1 {
                    return Err(format!(
                        "boot project #{sequence} saved after #{previous}: {text}"
                    ));
                }
                let len = committed_len.ok_or("a boot project saved before any download")?;
                logged.boot = Some((sequence, len));
                logged.boot_saves += 1;
                (boot_writing, after_boot_write) = (false, true);
                logged.pending = None;
                logged.downloaded.clear();
            } else if let Some(rest) = text.strip_prefix("plc: store: RETAIN snapshot #")
                && rest.contains(" saved (")
            {
                let sequence = number_after(rest, "").ok_or("a RETAIN line?")?;
                let release = number_after(rest, "(release ").ok_or("a RETAIN line?")?;
                let previous = logged.retain.map_or(0, |r| r.0);
                if sequence != previous + 1 {
                    return Err(format!(
                        "RETAIN snapshot #{sequence} saved after #{previous}: {text}"
                    ));
                }
                let written_us = number_after(rest, "written in ").ok_or("a RETAIN line?")?;
                let age = since(release, last_save, downloaded);
                let waited_for_boot_write = boot_writing || after_boot_write;
                after_boot_write = false;
                ages.saved(age, written_us, waited_for_boot_write)
                    .map_err(|e| format!("{e}: {text}"))?;
                logged.retain = Some((sequence, release));
                logged.retain_saves += 1;
                logged.worst_age = logged.worst_age.max(age);
                if new_program(release, last_save, downloaded) {
                    downloaded = false;
                    last_save = release;
                } else {
                    last_save = last_save.max(release);
                }
            } else if text.contains(" scan releases=") {
                let releases = number_after(text, " scan releases=").ok_or("a scan line?")?;
                let age = since(releases, last_save, downloaded);
                logged.worst_age = logged.worst_age.max(age);
                if !boot_writing && !after_boot_write {
                    ages.statistics(age, text);
                }
            }
        }
        self.saves.0 += logged.boot_saves;
        self.saves.1 += logged.retain_saves;
        self.logged = logged;
        Ok(())
    }

    fn finish(&self) -> Result<String, String> {
        let (boot, retain) = self.saves;
        if boot == 0 || retain == 0 {
            return Err(format!(
                "{boot} boot-project and {retain} RETAIN saves logged over all boots: the cuts never met the workload"
            ));
        }
        Ok(format!(
            "{boot} boot-project and {retain} RETAIN saves logged over all boots"
        ))
    }

    fn after_cut(&mut self, image: &[u8]) -> Result<(Vec<&'static str>, String), String> {
        let found = self.read(image)?;
        let logged = &self.logged;
        let mut hits = Vec::new();
        // The boot project: the old one or the new one.
        let old = logged.boot.map_or(0, |b| b.0);
        let boot = match (logged.boot, found.boot) {
            (None, None) => "no boot project".to_string(),
            (Some((sequence, len)), Some(b)) if b.sequence == sequence => {
                if b.len != len {
                    return Err(format!(
                        "boot project #{sequence} holds {} bytes of program, the PLC had {len}",
                        b.len
                    ));
                }
                format!(
                    "boot project #{} (revision {}, old)",
                    b.sequence, b.revision
                )
            }
            (_, Some(b)) if b.sequence == old + 1 => {
                // The download in flight, or an earlier one whose save's line is not out
                // (a download commits before its save).
                if logged.pending.is_none() {
                    return Err(format!(
                        "boot project #{} on the disk, but no download was in flight",
                        b.sequence
                    ));
                }
                if !logged.downloaded.contains(&b.revision) || b.len != self.len_of(b.revision) {
                    return Err(format!(
                        "boot project #{} is revision {}, the guest began to download {:?} since the last save",
                        b.sequence, b.revision, logged.downloaded
                    ));
                }
                hits.push("boot-project save (done, its line not out)");
                format!(
                    "boot project #{} (revision {}, new)",
                    b.sequence, b.revision
                )
            }
            (_, b) => {
                return Err(format!(
                    "the boot project on the disk is {b:?}; the PLC had logged #{old} (and a new one would be #{})",
                    old + 1
                ));
            }
        };
        // The RETAIN snapshot: the last one logged or newer.
        let retain = match (logged.retain, found.retain) {
            (None, None) => "no RETAIN snapshot".to_string(),
            (Some((sequence, _)), None) => {
                return Err(format!(
                    "RETAIN snapshot #{sequence} was logged, none is valid on the disk"
                ));
            }
            (Some((sequence, release)), Some(r)) if r.sequence == sequence => {
                if r.release != release {
                    return Err(format!(
                        "RETAIN snapshot #{sequence} is of release {}, the PLC saved it at {release}",
                        r.release
                    ));
                }
                format!(
                    "RETAIN #{} (release {}, Keep.cycles {}, the last logged)",
                    r.sequence, r.release, r.cycles
                )
            }
            (logged_retain, Some(r)) => {
                let last = logged_retain.map_or(0, |l| l.0);
                if r.sequence < last || r.sequence > last + 2 {
                    return Err(format!(
                        "RETAIN snapshot #{} on the disk, the PLC had logged #{last} (at most two saves may not be logged yet)",
                        r.sequence
                    ));
                }
                hits.push("RETAIN save (done, its line not out)");
                format!(
                    "RETAIN #{} (release {}, Keep.cycles {}, newer than the logged #{last})",
                    r.sequence, r.release, r.cycles
                )
            }
        };
        if let (Some(before), Some(now)) = (logged.loaded.retain, found.retain)
            && now.sequence > before.sequence
            && now.cycles < before.cycles
        {
            return Err(format!(
                "RETAIN snapshot #{} holds Keep.cycles {}, below #{}'s {} it started from",
                now.sequence, now.cycles, before.sequence, before.cycles
            ));
        }
        // Torn slots: only where a save may have been in flight.
        for &(region, slot, corruption) in &found.corrupt {
            let inherited = logged
                .loaded
                .corrupt
                .iter()
                .any(|c| c.0 == region && c.1 == slot);
            let (saves, in_flight) = match region {
                Region::Boot => (logged.boot_saves, logged.pending.is_some()),
                Region::Retain => (logged.retain_saves, true),
            };
            if inherited && saves == 0 {
                continue;
            }
            if !in_flight {
                return Err(format!(
                    "{} slot {slot} is torn ({corruption}), but no save of it was in flight",
                    region.label()
                ));
            }
            hits.push(match region {
                Region::Boot => "boot-project save (torn)",
                Region::Retain => "RETAIN save (torn)",
            });
        }
        if !hits.iter().any(|h| h.starts_with("boot-project")) {
            match logged.pending {
                Some(Pending {
                    committed: true, ..
                }) => hits.push("download committed, boot project not saved"),
                Some(_) => hits.push("download"),
                None => {}
            }
        }
        if hits.is_empty() {
            hits.push("between saves");
        }
        let torn = if found.corrupt.is_empty() {
            String::new()
        } else {
            let slots: Vec<String> = found
                .corrupt
                .iter()
                .map(|(r, s, _)| format!("{} slot {s}", r.label()))
                .collect();
            format!(", torn: {}", slots.join(", "))
        };
        let text = format!(
            "{boot}, {retain}{torn}; {} boot-project and {} RETAIN saves logged, at most {} releases between saves",
            logged.boot_saves, logged.retain_saves, logged.worst_age
        );
        self.expected = found;
        Ok((hits, text))
    }
}
