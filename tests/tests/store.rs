//! The PLC's persistent store on a virtual disk of the block-device partition
//! (configuration `tests/configs/store.toml`), across a reset of the machine with the same
//! disk image.
//!
//! `store_boot_project`: the first boot downloads a changed program (revision 2) with
//! plcctl; it becomes the boot project and RETAIN snapshots are saved. The second boot
//! (same disk) starts the boot project, restores the newest snapshot (the RETAIN counter
//! goes on from its value) and the guest finds revision 2 running without a download;
//! the guest then makes it trap, and after the health monitor's warm restart revision 2
//! runs again, its counter going on from RAM's value.
//!
//! `store_corrupt`: as above, but the newest RETAIN slot's header is damaged on the disk
//! image between the boots: the PLC skips it (logged, reported to the health monitor) and
//! restores the older snapshot. When the end of the first run tore a save (QEMU stops
//! while the store process writes), that torn slot is the one skipped.
//!
//! `store_guest_fs` (configuration `tests/configs/store_guest.toml`): the guest's block
//! device `/dev/vda` on its virtual disk and the ext2 file system on it at `/data`. The
//! first boot makes the file system with busybox mke2fs and writes bytes at an offset of
//! the raw device with dd, mounts it, replaces a file 20 times by write, fsync and rename,
//! writes 300 KiB with its checksum, changes a directory and unmounts it; the second (same
//! disk) reads the bytes and the files back. After each, Debian's e2fsck.static in the
//! guest and the host's e2fsck on the guest's range of the disk image find the file system
//! clean.

use scenarios::{boot, boot_again, check, disk_image};
use slots::{BlockDevice, SECTOR, SlotState};
use softplc::persist::Layout;
use xtask::qemu::Outcome;

/// The PLC's virtual disk in the configuration: sectors 2048..4096 of the disk.
const FIRST_SECTOR: u64 = 2048;
const SECTORS: u64 = 2048;

/// The PLC's virtual disk inside the disk image file.
struct Image(Vec<u8>);

impl BlockDevice for Image {
    type Error = ();
    fn read(&mut self, sector: u64, buf: &mut [u8; SECTOR]) -> Result<(), ()> {
        let at = ((FIRST_SECTOR + sector) as usize) * SECTOR;
        buf.copy_from_slice(self.0.get(at..at + SECTOR).ok_or(())?);
        Ok(())
    }
    fn write(&mut self, sector: u64, data: &[u8; SECTOR]) -> Result<(), ()> {
        let at = ((FIRST_SECTOR + sector) as usize) * SECTOR;
        self.0
            .get_mut(at..at + SECTOR)
            .ok_or(())?
            .copy_from_slice(data);
        Ok(())
    }
    fn flush(&mut self) -> Result<(), ()> {
        Ok(())
    }
}

/// The RETAIN slots on the disk image: (slot, sequence, `Keep.cycles`) of each valid one.
fn retain_records(disk: &mut Image) -> Vec<(usize, u64, u32)> {
    let region = Layout::of(SECTORS).expect("a store").retain;
    let scan = slots::scan(disk, &region).expect("the RETAIN region reads");
    let mut out = Vec::new();
    for state in scan.slots {
        if let SlotState::Valid(record) = state {
            let mut payload = vec![0u8; record.len];
            let read = slots::read(disk, &region, &record, &mut payload);
            assert_eq!(read, Ok(Some(record.len)), "slot {} reads", record.slot);
            let snapshot = softplc::store::decode_retain(&payload).expect("a RETAIN snapshot");
            let cycles = snapshot
                .values()
                .find(|v| v.name == "Keep.cycles")
                .and_then(|v| v.bytes.try_into().ok())
                .map(u32::from_le_bytes)
                .expect("Keep.cycles in the snapshot");
            out.push((record.slot, record.sequence, cycles));
        }
    }
    out.sort_by_key(|r| r.1);
    out
}

/// The value of `Keep.cycles` in the first watch line of `o`.
fn first_cycles(o: &Outcome) -> Option<u64> {
    o.lines
        .iter()
        .filter(|l| l.contains("[plc] plc: t=") && l.contains(" watch "))
        .find_map(|l| {
            let (_, v) = l.split_once("Keep.cycles=")?;
            let v = v.split_whitespace().next()?;
            v.rsplit('#').next()?.parse().ok()
        })
}

/// The first boot (a fresh disk): the download and the saves.
fn first_boot(name: &str) -> Outcome {
    let o = boot(name);
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit: the guest's script ends the run",
    );
    let out = scenarios::guest_output(&o);
    check(
        &o,
        out.iter().any(|l| l == "Keep.revision = 2"),
        &format!("the downloaded program runs: {out:?}"),
    );
    // plcctl tells what the store loaded (nothing on a fresh disk) and saved.
    check(
        &o,
        out.iter()
            .any(|l| l == "store: loaded boot project none, RETAIN snapshot none")
            && out
                .iter()
                .any(|l| l.starts_with("store: saved boot project #1, RETAIN snapshot #")),
        &format!("plcctl store after the first boot: {out:?}"),
    );
    for line in [
        "[plc] plc: store: no boot project; the configured program runs",
        "[plc] plc: store: no RETAIN snapshot; initial values",
        "[plc] plc: store: boot project #1 saved",
        "[plc] plc: store: RETAIN snapshot #2 saved",
    ] {
        check(&o, o.line(line).is_some(), &format!("missing {line:?}"));
    }
    // The control process's cost of a save: the copy between releases.
    for line in o
        .lines
        .iter()
        .filter(|l| l.contains("plc: store: RETAIN snapshot #"))
    {
        println!("{name}: {line}");
    }
    o
}

/// The second boot's common checks: the boot project runs, no download; after the warm
/// restart the guest's trap caused, it runs again with RAM's RETAIN values.
fn second_boot_runs_the_boot_project(o: &Outcome) {
    check(o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        o,
        o.succeeded(),
        "expected success exit: the guest's script ends the run",
    );
    let out = scenarios::guest_output(o);
    check(
        o,
        out.iter().any(|l| l == "boot project runs")
            && out.iter().any(|l| l == "Keep.revision = 2"),
        &format!("the boot project runs after the reset: {out:?}"),
    );
    check(
        o,
        out.iter().any(|l| {
            l.starts_with("store: loaded boot project #1, RETAIN snapshot #")
                && !l.ends_with("none")
        }),
        &format!("plcctl store after the reset: {out:?}"),
    );
    for line in [
        "[plc] plc: store: boot project #1 loaded: ",
        "[plc] plc: store: 1 RETAIN variable(s) restored",
        "[plc] plc: warm restart: 1 RETAIN variable(s) kept",
    ] {
        check(o, o.line(line).is_some(), &format!("missing {line:?}"));
    }
    // The trap's warm restart runs the boot project again (revision 2 read after it, above)
    // with RAM's RETAIN counter: it never goes back.
    let loads = o
        .lines
        .iter()
        .filter(|l| l.contains("[plc] plc: store: boot project #1 loaded: "))
        .count();
    check(
        o,
        loads == 2,
        &format!("the boot project loaded {loads} times, not 2 (cold, warm)"),
    );
    let counts: Vec<u64> = out
        .iter()
        .filter_map(|l| l.strip_prefix("Keep.cycles = ")?.trim().parse().ok())
        .collect();
    check(
        o,
        counts.len() == 3 && counts.windows(2).all(|w| w[0] < w[1]),
        &format!("Keep.cycles before the trap, after the warm restart and later: {counts:?}"),
    );
}

#[test]
fn store_boot_project() {
    let first = first_boot("store_boot_project");
    let mut disk = Image(std::fs::read(disk_image("store_boot_project")).expect("the disk image"));
    let records = retain_records(&mut disk);
    let &(_, newest, cycles) = records.last().expect("a RETAIN snapshot on the disk");
    println!("store_boot_project: RETAIN snapshot #{newest} on the disk, Keep.cycles = {cycles}");
    let o = boot_again("store_boot_project");
    second_boot_runs_the_boot_project(&o);
    let line = format!("[plc] plc: store: RETAIN snapshot #{newest} loaded: 1 variable(s)");
    check(&o, o.line(&line).is_some(), &format!("missing {line:?}"));
    // The counter goes on from the snapshot (a fresh one would be near 100 after a second).
    let after = first_cycles(&o);
    check(
        &o,
        after.is_some_and(|c| c > u64::from(cycles)),
        &format!("Keep.cycles at the first watch line {after:?} > the snapshot's {cycles}"),
    );
    drop(first);
}

#[test]
fn store_corrupt() {
    let _first = first_boot("store_corrupt");
    let path = disk_image("store_corrupt");
    let mut disk = Image(std::fs::read(&path).expect("the disk image"));
    let records = retain_records(&mut disk);
    let (slot, older, older_cycles) = match records[..] {
        [(_, older, older_cycles), (slot, newest, _)] => {
            // Damage the newest slot's header (its sequence number): its CRC fails.
            let region = Layout::of(SECTORS).expect("a store").retain;
            let header = region.first + slot as u64 * (region.sectors / 2);
            let mut sector = [0u8; SECTOR];
            disk.read(header, &mut sector).expect("the header");
            sector[8] ^= 0xff;
            disk.write(header, &sector).expect("the header");
            std::fs::write(&path, &disk.0).expect("the damaged disk image");
            println!("store_corrupt: RETAIN slot {slot} (#{newest}) damaged, #{older} below it");
            (slot, older, older_cycles)
        }
        // The machine stopped in the middle of a save: the other slot is torn already.
        [(valid, older, older_cycles)] => {
            println!(
                "store_corrupt: RETAIN slot {} torn by the end of the run, #{older} in the other",
                1 - valid
            );
            (1 - valid, older, older_cycles)
        }
        _ => panic!("RETAIN snapshots on the disk: {records:?}"),
    };
    let o = boot_again("store_corrupt");
    second_boot_runs_the_boot_project(&o);
    for line in [
        format!("[plc] plc: store: RETAIN slot {slot} skipped: "),
        format!("[plc] plc: store: RETAIN snapshot #{older} loaded: 1 variable(s)"),
    ] {
        check(&o, o.line(&line).is_some(), &format!("missing {line:?}"));
    }
    let after = first_cycles(&o);
    check(
        &o,
        after.is_some_and(|c| c > u64::from(older_cycles)),
        &format!(
            "Keep.cycles at the first watch line {after:?} > the older snapshot's {older_cycles}"
        ),
    );
}

/// The guest's virtual disk in `tests/configs/store_guest.toml`: sectors 2048..6144.
const GUEST_FIRST_SECTOR: usize = 2048;
const GUEST_SECTORS: usize = 4096;

/// The host's `e2fsck -fn` on the guest's range of scenario `name`'s disk image: its exit
/// status and output.
fn host_e2fsck(name: &str) -> (Option<i32>, String) {
    let image = std::fs::read(disk_image(name)).expect("the disk image");
    let range = image
        .get(GUEST_FIRST_SECTOR * SECTOR..(GUEST_FIRST_SECTOR + GUEST_SECTORS) * SECTOR)
        .expect("the guest's range in the disk image");
    let path = disk_image(name).with_file_name("vda.img");
    std::fs::write(&path, range).expect("the guest's disk as a file");
    let e2fsck = ["/sbin/e2fsck", "/usr/sbin/e2fsck"]
        .into_iter()
        .find(|p| std::path::Path::new(p).is_file())
        .unwrap_or("e2fsck");
    let ran = std::process::Command::new(e2fsck)
        .arg("-fn")
        .arg(&path)
        .output()
        .expect("the host's e2fsck (e2fsprogs) runs");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&ran.stdout),
        String::from_utf8_lossy(&ran.stderr)
    );
    (ran.status.code(), text)
}

/// The checks of both boots: the device as the guest sees it, e2fsck clean in the guest
/// and on the host, no failed request.
fn guest_disk_boot(o: &Outcome, name: &str, expected: &[&str]) -> Vec<String> {
    check(o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        o,
        o.succeeded(),
        "expected success exit: the guest's script ends the run",
    );
    let line = "[linux] guest: /dev/vda 4096 sectors through ports vda-req and vda-resp";
    check(o, o.line(line).is_some(), &format!("missing {line:?}"));
    check(
        o,
        o.line("guest: /dev/vda: ").is_none(),
        "a request of /dev/vda failed",
    );
    let out = scenarios::guest_output(o);
    for want in [
        "vda: block special file fe:0 size 0",
        "blockdev: 2097152 bytes, 4096 sectors of 512",
        "ports: 0 in /dev/arinc",
        "past the end: 0 bytes read",
        "past the end: No space left on device",
    ]
    .iter()
    .chain(expected)
    {
        check(
            o,
            out.iter()
                .any(|l| l == want || l.starts_with(&format!("{want} in "))),
            &format!("no {want:?} in the guest's output: {out:#?}"),
        );
    }
    for l in out
        .iter()
        .filter(|l| l.contains(" status ") || l.contains(" in ") || l.starts_with("df: "))
    {
        println!("{name}: {l}");
    }
    let (status, text) = host_e2fsck(name);
    assert_eq!(
        status,
        Some(0),
        "the host's e2fsck -fn on the guest's range:\n{text}"
    );
    out
}

#[test]
fn store_guest_fs() {
    let name = "store_guest_fs";
    // Both boots: mounted at /data (listed in /proc/mounts), busy while the shell is in
    // it, unmounted, clean.
    let mounted = [
        "mount status 0",
        "/dev/vda /data ext2 rw,relatime 0 0",
        "umount while in /data: refused",
        "umount status 0",
        "e2fsck status 0",
    ];
    let first = boot(name);
    let out = guest_disk_boot(
        &first,
        name,
        &[
            &[
                "first boot",
                "mke2fs status 0",
                "dd status 0",
                "synced",
                "state: version 19",
                "dir: changed",
            ][..],
            &mounted[..],
        ]
        .concat(),
    );
    check(
        &first,
        !out.iter().any(|l| l.ends_with(" failed")),
        &format!("a replace failed: {out:#?}"),
    );
    let second = boot_again(name);
    guest_disk_boot(
        &second,
        name,
        &[
            &[
                "second boot: marker read back",
                "state: version 19",
                "big: intact",
                "dir: a c a",
            ][..],
            &mounted[..],
        ]
        .concat(),
    );
}
