//! Power cuts: after an fsync, more changes run on a disk that stops writing after a random
//! number of sector writes (as a cut would). e2fsck -fy must repair whatever the cut left,
//! e2fsck -fn must then be clean, and the fsync'ed file must read back whole.

mod common;

use std::process::Command;

use common::*;
use ext2::{Ext2, FormatOptions, ROOT_INO};
use proptest::prelude::*;
use slots::BlockDevice;

/// Keeps the first `writes_left` sector writes, drops the rest.
struct CutDisk {
    disk: MemDisk,
    writes_left: u32,
}

impl BlockDevice for CutDisk {
    type Error = &'static str;
    fn read(&mut self, sector: u64, buf: &mut [u8; 512]) -> Result<(), Self::Error> {
        self.disk.read(sector, buf)
    }
    fn write(&mut self, sector: u64, data: &[u8; 512]) -> Result<(), Self::Error> {
        if self.writes_left == 0 {
            return Ok(());
        }
        self.writes_left -= 1;
        self.disk.write(sector, data)
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// Changes after the fsync: files created, grown, removed, renamed, a directory tree.
fn churn(fs: &mut Ext2<CutDisk>, seed: u32) {
    let _ = (|| -> Result<(), ext2::Error> {
        let dir = fs.mkdir(ROOT_INO, b"dir", 0o755)?;
        for i in 0..12u32 {
            let name = format!("f{i}");
            let ino = fs.create(dir, name.as_bytes(), 0o644)?;
            fs.write(ino, 0, &pattern(((seed + i) % 7) as usize * 9000 + 10, i))?;
        }
        fs.sync()?;
        for i in (0..12u32).step_by(2) {
            if let Some(ino) = fs.unlink(dir, format!("f{i}").as_bytes())? {
                fs.release(ino)?;
            }
        }
        fs.rename(dir, b"f1", ROOT_INO, b"moved")?;
        let sub = fs.mkdir(dir, b"sub", 0o755)?;
        fs.rename(ROOT_INO, b"dir", ROOT_INO, b"renamed")?;
        let big = fs.create(sub, b"big", 0o644)?;
        fs.write(big, 0, &pattern(300_000, seed))?;
        fs.truncate(big, 1000)?;
        fs.symlink(sub, b"link", "z".repeat(100).as_bytes())?;
        fs.sync()
    })();
}

/// A fresh ext2 of `bytes` with `block_size` blocks on a disk that keeps every write.
fn formatted(bytes: usize, block_size: u32) -> Ext2<CutDisk> {
    let mut disk = MemDisk::zeroed(bytes);
    let sectors = disk.sectors();
    let options = FormatOptions {
        block_size,
        inode_size: 128,
        now: now(),
        ..FormatOptions::default()
    };
    ext2::format(&mut disk, sectors, &options).unwrap();
    Ext2::mount(CutDisk {
        disk,
        writes_left: u32::MAX,
    })
    .unwrap()
}

/// `fs` mounted again on its disk, which from here on keeps only `writes` more sector
/// writes.
fn cut_after(fs: Ext2<CutDisk>, writes: u32) -> Ext2<CutDisk> {
    let mut dev = fs.abandon();
    dev.writes_left = writes;
    Ext2::mount(dev).unwrap()
}

fn crash_case(block_size: u32, writes: u32, seed: u32) {
    let Some(e2fsck) = tool("e2fsck") else {
        return;
    };
    let mut fs = formatted(4 << 20, block_size);
    fs.set_now(now());
    let keep_data = pattern(50_000, seed);
    let keep = fs.create(ROOT_INO, b"keep", 0o644).unwrap();
    fs.write(keep, 0, &keep_data).unwrap();
    fs.fsync(keep).unwrap();
    let mut fs = cut_after(fs, writes);
    fs.set_now(now());
    churn(&mut fs, seed);
    let crashed = fs.abandon().disk;

    let file = TempFile::new("crash");
    std::fs::write(&file.0, &crashed.data).unwrap();
    let repair = Command::new(&e2fsck)
        .arg("-fy")
        .arg(&file.0)
        .output()
        .unwrap();
    let code = repair.status.code().unwrap_or(99);
    assert!(
        code <= 2,
        "e2fsck -fy could not repair (exit {code}): {repair:?}"
    );
    let repaired = std::fs::read(&file.0).unwrap();
    assert_fsck_clean(&repaired, "repaired crash image");
    let mut fs = Ext2::mount(MemDisk::new(repaired)).unwrap();
    let ino = fs
        .lookup(ROOT_INO, b"keep")
        .unwrap()
        .expect("the fsync'ed file is gone");
    assert!(
        read_all(&mut fs, ino) == keep_data,
        "the fsync'ed file changed"
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn cut_after_fsync_is_repairable_1k(writes in 0u32..3000, seed in 0u32..100) {
        crash_case(1024, writes, seed);
    }

    #[test]
    fn cut_after_fsync_is_repairable_4k(writes in 0u32..3000, seed in 0u32..100) {
        crash_case(4096, writes, seed);
    }
}

/// A file replaced as applications do it (write a new file, fsync it, rename it over the
/// old one, sync), cut after every number of sector writes of the rename and its sync:
/// after e2fsck -fy the name holds the old or the new contents whole, never nothing (the
/// directory entry leaves the disk before the replaced inode is freed).
#[test]
fn a_file_replaced_by_rename_survives_a_cut_anywhere() {
    let Some(e2fsck) = tool("e2fsck") else {
        return;
    };
    let (old, new) = (pattern(3000, 1), pattern(2000, 2));
    let mut writes = 0;
    loop {
        let mut fs = formatted(1 << 20, 1024);
        let f = fs.create(ROOT_INO, b"f", 0o644).unwrap();
        fs.write(f, 0, &old).unwrap();
        fs.sync().unwrap();
        let tmp = fs.create(ROOT_INO, b"f.tmp", 0o644).unwrap();
        fs.write(tmp, 0, &new).unwrap();
        fs.fsync(tmp).unwrap();
        let mut fs = cut_after(fs, writes);
        fs.set_now(now());
        let replaced = fs.rename(ROOT_INO, b"f.tmp", ROOT_INO, b"f");
        if let Ok(Some(ino)) = replaced {
            let _ = fs.release(ino);
        }
        let _ = fs.sync();
        let cut = fs.abandon();
        let finished = cut.writes_left > 0;
        let file = TempFile::new("replace");
        std::fs::write(&file.0, &cut.disk.data).unwrap();
        let repair = Command::new(&e2fsck)
            .arg("-fy")
            .arg(&file.0)
            .output()
            .unwrap();
        assert!(repair.status.code().unwrap_or(99) <= 2, "{repair:?}");
        let mut fs = Ext2::mount(MemDisk::new(std::fs::read(&file.0).unwrap())).unwrap();
        let ino = fs
            .lookup(ROOT_INO, b"f")
            .unwrap()
            .unwrap_or_else(|| panic!("f is gone after a cut at write {writes}"));
        let got = read_all(&mut fs, ino);
        assert!(
            got == old || got == new,
            "f is neither version after a cut at write {writes} ({} bytes)",
            got.len()
        );
        if finished {
            assert!(got == new, "the whole rename and sync ran: f must be new");
            break;
        }
        writes += 1;
    }
}
