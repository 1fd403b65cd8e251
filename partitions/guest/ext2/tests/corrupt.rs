//! Hostile images: random bytes of a valid image changed in the superblock, the group
//! descriptors, the bitmaps, the inode table or directory blocks. Mounting and every
//! operation must return Ok or an error: never panic, never hang (each case runs under a
//! deadline).

mod common;

use std::sync::OnceLock;
use std::sync::mpsc;
use std::time::Duration;

use common::*;
use ext2::{Ext2, FormatOptions, ROOT_INO};
use proptest::prelude::*;

/// A valid image with files of every block-map depth, directories, symlinks; and the byte
/// ranges of its metadata.
struct Base {
    image: Vec<u8>,
    regions: Vec<(usize, usize)>,
}

fn base() -> &'static Base {
    static BASE: OnceLock<Base> = OnceLock::new();
    BASE.get_or_init(|| {
        let mut disk = MemDisk::zeroed(2 << 20);
        let sectors = disk.sectors();
        let options = FormatOptions {
            block_size: 1024,
            inode_size: 128,
            bytes_per_inode: 8192,
            now: now(),
            ..FormatOptions::default()
        };
        ext2::format(&mut disk, sectors, &options).unwrap();
        let mut fs = Ext2::mount(disk).unwrap();
        let d = fs.mkdir(ROOT_INO, b"d", 0o755).unwrap();
        let e = fs.mkdir(d, b"e", 0o755).unwrap();
        for (i, len) in [0usize, 100, 5000, 80_000, 300_000].into_iter().enumerate() {
            let f = fs
                .create(
                    if i % 2 == 0 { d } else { ROOT_INO },
                    format!("f{i}").as_bytes(),
                    0o644,
                )
                .unwrap();
            fs.write(f, 0, &pattern(len, i as u32)).unwrap();
        }
        for i in 0..40 {
            fs.create(e, format!("entry-{i}").as_bytes(), 0o644)
                .unwrap();
        }
        fs.symlink(ROOT_INO, b"s", b"d/f0").unwrap();
        fs.symlink(d, b"l", "x".repeat(80).as_bytes()).unwrap();
        let image = fs.unmount().unwrap().data;
        let regions = metadata_regions(&image);
        Base { image, regions }
    })
}

/// The byte ranges worth corrupting, found from the image itself: the superblock's
/// fields, group 0's descriptor and bitmaps, the used part of the inode table, and every
/// directory and indirect block of the inodes in use.
fn metadata_regions(image: &[u8]) -> Vec<(usize, usize)> {
    let word = |at: usize| u32::from_le_bytes(image[at..at + 4].try_into().unwrap()) as usize;
    let block = |b: usize| (b * 1024, b * 1024 + 1024);
    let inode_table = word(2048 + 8) * 1024;
    let mut regions = vec![
        (1024, 1024 + 112),
        (1024 + 200, 1024 + 212),
        (2048, 2048 + 32),
        block(word(2048)),
        block(word(2048 + 4)),
        (inode_table, inode_table + 64 * 128),
    ];
    for index in 0..64 {
        let inode = inode_table + index * 128;
        let mode = u16::from_le_bytes([image[inode], image[inode + 1]]);
        let is_dir = mode & 0o170000 == 0o040000;
        let is_file = mode & 0o170000 == 0o100000;
        for slot in 0..15 {
            let b = word(inode + 40 + 4 * slot);
            if b != 0 && (is_dir || (is_file && slot >= 12)) {
                regions.push(block(b));
            }
        }
    }
    regions
}

/// Walks the tree (bounded), reads and stats everything, then changes things; all results
/// are ignored: only panics and hangs count.
fn exercise<D: slots::BlockDevice>(dev: D) {
    let Ok(mut fs) = Ext2::mount(dev) else {
        return;
    };
    let mut dirs = vec![ROOT_INO];
    let mut seen = 0;
    while let Some(dir) = dirs.pop() {
        let mut cookie = 0;
        while let Ok(Some((entry, next))) = fs.readdir(dir, cookie) {
            seen += 1;
            if seen > 2000 {
                break;
            }
            cookie = next;
            if entry.name == b"." || entry.name == b".." {
                continue;
            }
            let _ = fs.lookup(dir, &entry.name);
            if let Ok(stat) = fs.stat(entry.ino) {
                match stat.mode & ext2::S_IFMT {
                    ext2::S_IFDIR if dirs.len() < 50 => dirs.push(entry.ino),
                    ext2::S_IFLNK => drop(fs.readlink(entry.ino)),
                    _ => {
                        let mut buf = vec![0u8; 4096];
                        for offset in [0, 5000, 70_000, 290_000, stat.size.saturating_sub(10)] {
                            let _ = fs.read(entry.ino, offset, &mut buf);
                        }
                        let _ = fs.write(entry.ino, 100, b"changed");
                        let _ = fs.truncate(entry.ino, 50);
                    }
                }
            }
        }
    }
    let _ = fs
        .create(ROOT_INO, b"new", 0o644)
        .map(|ino| fs.write(ino, 0, &[1u8; 20_000]));
    let _ = fs.mkdir(ROOT_INO, b"newdir", 0o755);
    let _ = fs.symlink(ROOT_INO, b"newlink", "y".repeat(90).as_bytes());
    let _ = fs.rename(ROOT_INO, b"d", ROOT_INO, b"newdir");
    let _ = fs.rename(ROOT_INO, b"f1", ROOT_INO, b"f3");
    if let Ok(Some(d)) = fs.lookup(ROOT_INO, b"d") {
        let _ = fs.rename(d, b"e", ROOT_INO, b"e2");
        let _ = fs.unlink(d, b"f0").map(|o| o.map(|ino| fs.release(ino)));
        let _ = fs.rmdir(d, b"e");
    }
    let _ = fs
        .unlink(ROOT_INO, b"f1")
        .map(|o| o.map(|ino| fs.release(ino)));
    let _ = fs.rmdir(ROOT_INO, b"d");
    let _ = fs.link(ROOT_INO, b"hard", 12);
    for ino in 1..40 {
        let _ = fs.stat(ino);
        let _ = fs.release(ino);
    }
    let _ = fs.sync();
    let _ = fs.unmount();
}

/// Runs `exercise` in a thread with a deadline, so that an endless loop fails the test.
fn exercise_with_deadline(image: Vec<u8>) {
    exercise_device_with_deadline(MemDisk::new(image));
}

fn exercise_device_with_deadline<D: slots::BlockDevice + Send + 'static>(dev: D) {
    let (done, wait) = mpsc::channel();
    let worker = std::thread::spawn(move || {
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| exercise(dev)));
        let _ = done.send(result.is_ok());
    });
    match wait.recv_timeout(Duration::from_secs(20)) {
        Ok(true) => {
            worker.join().unwrap();
        }
        Ok(false) => panic!("the file system panicked on a corrupt image"),
        Err(_) => panic!("the file system hung on a corrupt image"),
    }
}

#[test]
fn the_base_image_is_clean() {
    assert_fsck_clean(&base().image, "corruption base image");
    exercise_with_deadline(base().image.clone());
}

/// A device that fails every request after a number of them (a disk that died).
struct DyingDisk {
    disk: MemDisk,
    requests_left: u32,
}

impl slots::BlockDevice for DyingDisk {
    type Error = &'static str;
    fn read(&mut self, sector: u64, buf: &mut [u8; 512]) -> Result<(), Self::Error> {
        self.requests_left = self.requests_left.checked_sub(1).ok_or("dead")?;
        self.disk.read(sector, buf)
    }
    fn write(&mut self, sector: u64, data: &[u8; 512]) -> Result<(), Self::Error> {
        self.requests_left = self.requests_left.checked_sub(1).ok_or("dead")?;
        self.disk.write(sector, data)
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        self.requests_left = self.requests_left.checked_sub(1).ok_or("dead")?;
        Ok(())
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn corrupt_metadata_never_panics(
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<prop::sample::Index>(), any::<u8>()), 1..6),
    ) {
        let base = base();
        let mut image = base.image.clone();
        for (region, at, value) in flips {
            let (start, end) = base.regions[region.index(base.regions.len())];
            image[start + at.index(end - start)] = value;
        }
        exercise_with_deadline(image);
    }

    #[test]
    fn corrupt_bytes_anywhere_never_panic(
        flips in prop::collection::vec((0usize..(64 << 10), any::<u8>()), 1..16),
    ) {
        let mut image = base().image.clone();
        for (at, value) in flips {
            image[at] = value;
        }
        exercise_with_deadline(image);
    }

    /// Device errors at any point give errors, never a panic or a hang.
    #[test]
    fn device_errors_never_panic(requests in 0u32..6000) {
        let disk = MemDisk::new(base().image.clone());
        exercise_device_with_deadline(DyingDisk { disk, requests_left: requests });
    }
}
