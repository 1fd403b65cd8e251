//! Files at the edges: triple indirect blocks, sizes over 4 GiB (`i_size_high`), the size
//! limit without `large_file`, attributes, errors and their errnos.

mod common;

use common::*;
use ext2::{Error, Ext2, FormatOptions, ROOT_INO, S_IFMT, S_IFREG};

fn formatted(bytes: usize, block_size: u32) -> MemDisk {
    let mut disk = MemDisk::zeroed(bytes);
    let sectors = disk.sectors();
    let options = FormatOptions {
        block_size,
        inode_size: 256,
        now: now(),
        ..FormatOptions::default()
    };
    ext2::format(&mut disk, sectors, &options).unwrap();
    disk
}

/// Writes a few bytes far out (triple indirect at both block sizes; past 4 GiB at 4 KiB
/// blocks), reads them and the hole back, shrinks, and e2fsck agrees throughout.
#[test]
fn triple_indirect_and_large_sizes() {
    for (block_size, far) in [(1024u32, 70u64 << 20), (4096, 5u64 << 30)] {
        let mut fs = Ext2::mount(formatted(8 << 20, block_size)).unwrap();
        fs.set_now(now());
        let ino = fs.create(ROOT_INO, b"far", 0o644).unwrap();
        fs.write(ino, 0, b"head").unwrap();
        fs.write(ino, far, b"tail").unwrap();
        assert_eq!(fs.stat(ino).unwrap().size, far + 4);
        // Data, triple, double and single indirect block: 4 blocks beyond the first.
        assert_eq!(
            fs.stat(ino).unwrap().blocks,
            5 * u64::from(block_size / 512)
        );
        let mut buf = [9u8; 8];
        assert_eq!(fs.read(ino, far - 4, &mut buf).unwrap(), 8);
        assert_eq!(&buf, b"\0\0\0\0tail");
        let disk = fs.unmount().unwrap();
        assert_fsck_clean(&disk.data, "far file");
        if block_size == 1024 {
            let tree = Tree::from([(
                String::from("far"),
                Node::File({
                    let mut data = vec![0u8; far as usize + 4];
                    data[..4].copy_from_slice(b"head");
                    data[far as usize..].copy_from_slice(b"tail");
                    data
                }),
            )]);
            verify_with_debugfs(&disk.data, &tree);
        }
        let mut fs = Ext2::mount(disk).unwrap();
        fs.set_now(now());
        fs.truncate(ino, 4).unwrap();
        assert_eq!(fs.stat(ino).unwrap().blocks, u64::from(block_size / 512));
        assert_eq!(fs.read(ino, 0, &mut buf).unwrap(), 4);
        assert_eq!(&buf[..4], b"head");
        let disk = fs.unmount().unwrap();
        assert_fsck_clean(&disk.data, "far file truncated");
    }
}

#[test]
fn size_limit_without_large_file() {
    // mke2fs sets large_file whatever it is told: clear it in the superblock.
    let mut image = formatted(8 << 20, 4096).data;
    image[1024 + 100] &= !0x02;
    let mut fs = Ext2::mount(MemDisk::new(image)).unwrap();
    let ino = fs.create(ROOT_INO, b"f", 0o644).unwrap();
    assert_eq!(fs.write(ino, 1 << 31, b"x"), Err(Error::TooBig));
    assert_eq!(fs.write(ino, (1 << 31) - 2, b"xyz").unwrap(), 1);
    assert_eq!(fs.stat(ino).unwrap().size, (1 << 31) - 1);
    assert_eq!(fs.truncate(ino, 1 << 31), Err(Error::TooBig));
    let disk = fs.unmount().unwrap();
    assert_fsck_clean(&disk.data, "2 GiB - 1 file");
}

#[test]
fn attributes() {
    let mut fs = Ext2::mount(formatted(4 << 20, 1024)).unwrap();
    fs.set_now(1_700_000_000);
    let ino = fs.create(ROOT_INO, b"f", 0o640).unwrap();
    let stat = fs.stat(ino).unwrap();
    assert_eq!(stat.mode, S_IFREG | 0o640);
    assert_eq!(
        (stat.nlink, stat.size, stat.blocks, stat.ctime),
        (1, 0, 0, 1_700_000_000)
    );
    fs.chmod(ino, 0o4755).unwrap();
    fs.chown(ino, Some(100_000), Some(70_000)).unwrap();
    fs.set_times(ino, Some(11), Some(22)).unwrap();
    let stat = fs.stat(ino).unwrap();
    assert_eq!(stat.mode, S_IFREG | 0o4755);
    assert_eq!(
        (stat.uid, stat.gid, stat.atime, stat.mtime),
        (100_000, 70_000, 11, 22)
    );
    fs.chown(ino, None, Some(5)).unwrap();
    assert_eq!(fs.stat(ino).unwrap().uid, 100_000);
    fs.fsync(ino).unwrap();
    let disk = fs.unmount().unwrap();
    assert_fsck_clean(&disk.data, "attributes");
    let mut fs = Ext2::mount(disk).unwrap();
    let stat = fs.stat(ino).unwrap();
    assert_eq!(
        (stat.uid, stat.gid, stat.mode & !S_IFMT),
        (100_000, 5, 0o4755)
    );
}

#[test]
fn errors_and_errnos() {
    let mut fs = Ext2::mount(formatted(4 << 20, 1024)).unwrap();
    let f = fs.create(ROOT_INO, b"f", 0o644).unwrap();
    let long = vec![b'n'; 256];
    assert_eq!(fs.create(ROOT_INO, &long, 0o644), Err(Error::NameTooLong));
    assert!(fs.create(ROOT_INO, &long[..255], 0o644).is_ok());
    assert_eq!(fs.create(ROOT_INO, b"f", 0o644), Err(Error::Exists));
    assert_eq!(fs.create(ROOT_INO, b"a/b", 0o644), Err(Error::Invalid));
    assert_eq!(fs.create(ROOT_INO, b"", 0o644), Err(Error::Invalid));
    assert_eq!(fs.create(ROOT_INO, b"..", 0o644), Err(Error::Invalid));
    assert_eq!(fs.create(f, b"x", 0o644), Err(Error::NotDir));
    assert_eq!(fs.lookup(ROOT_INO, b"missing"), Ok(None));
    assert_eq!(fs.unlink(ROOT_INO, b"missing"), Err(Error::NotFound));
    assert_eq!(fs.read(ROOT_INO, 0, &mut [0u8; 4]), Err(Error::IsDir));
    assert_eq!(fs.readlink(f), Err(Error::Invalid));
    assert_eq!(fs.stat(0), Err(Error::Invalid));
    assert_eq!(fs.stat(20), Err(Error::NotFound));
    assert_eq!(
        fs.symlink(ROOT_INO, b"s", &vec![b't'; 1024]),
        Err(Error::NameTooLong)
    );
    assert_eq!(fs.lookup(ROOT_INO, b"."), Ok(Some(ROOT_INO)));
    assert_eq!(fs.lookup(ROOT_INO, b".."), Ok(Some(ROOT_INO)));
    let expected = [
        (Error::NotFound, 2),
        (Error::Io(String::new()), 5),
        (Error::Exists, 17),
        (Error::NotDir, 20),
        (Error::IsDir, 21),
        (Error::Invalid, 22),
        (Error::TooBig, 27),
        (Error::NoSpace, 28),
        (Error::ReadOnly, 30),
        (Error::TooManyLinks, 31),
        (Error::NameTooLong, 36),
        (Error::NotEmpty, 39),
        (Error::Corrupt("x"), 117),
        (Error::NotPermitted, 1),
    ];
    for (error, errno) in expected {
        assert_eq!(error.errno(), errno, "{error:?}");
    }
    let disk = fs.unmount().unwrap();
    assert_fsck_clean(&disk.data, "after errors");
}

/// A cut between writing the new entry and removing the old one of a rename leaves the
/// file under both names; e2fsck sees only a link count to fix.
#[test]
fn rename_cut_leaves_both_names() {
    let mut fs = Ext2::mount(formatted(4 << 20, 1024)).unwrap();
    fs.set_now(now());
    let a = fs.mkdir(ROOT_INO, b"a", 0o755).unwrap();
    let f = fs.create(ROOT_INO, b"f", 0o644).unwrap();
    fs.write(f, 0, b"contents").unwrap();
    fs.sync().unwrap();
    // Run the rename on a device that stops writing after the barrier's flush.
    struct CutAfterFlushes {
        disk: MemDisk,
        flushes_left: u32,
    }
    impl slots::BlockDevice for CutAfterFlushes {
        type Error = &'static str;
        fn read(&mut self, s: u64, b: &mut [u8; 512]) -> Result<(), Self::Error> {
            self.disk.read(s, b)
        }
        fn write(&mut self, s: u64, d: &[u8; 512]) -> Result<(), Self::Error> {
            if self.flushes_left == 0 {
                return Ok(()); // lost
            }
            self.disk.write(s, d)
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            self.flushes_left = self.flushes_left.saturating_sub(1);
            Ok(())
        }
    }
    let disk = fs.unmount().unwrap();
    let mut fs = Ext2::mount(CutAfterFlushes {
        disk,
        flushes_left: 2,
    })
    .unwrap();
    fs.set_now(now());
    // Flush 1 was mount's; flush 2 is the rename's barrier; nothing after it lands.
    fs.rename(ROOT_INO, b"f", a, b"g").unwrap();
    let crashed = fs.abandon().disk;
    let mut fs = Ext2::mount_read_only(crashed.clone()).unwrap();
    assert_eq!(fs.lookup(ROOT_INO, b"f").unwrap(), Some(f));
    assert_eq!(fs.lookup(a, b"g").unwrap(), Some(f));
    if let Some((clean, text)) = e2fsck(&crashed.data) {
        assert!(!clean);
        assert!(text.contains("ref count is 1, should be 2"), "{text}");
    }
}

/// `rm -rf` style: removing each entry readdir returned, while reading on with the cookie,
/// visits every entry exactly once.
#[test]
fn readdir_while_removing() {
    let mut fs = Ext2::mount(formatted(4 << 20, 1024)).unwrap();
    fs.set_now(now());
    let dir = fs.mkdir(ROOT_INO, b"d", 0o755).unwrap();
    for i in 0..150 {
        fs.create(dir, format!("name-{i}").as_bytes(), 0o644)
            .unwrap();
    }
    let mut seen = std::collections::BTreeSet::new();
    let mut cookie = 0;
    while let Some((entry, next)) = fs.readdir(dir, cookie).unwrap() {
        cookie = next;
        if entry.name == b"." || entry.name == b".." {
            continue;
        }
        assert!(seen.insert(entry.name.clone()), "twice: {:?}", entry.name);
        let orphan = fs.unlink(dir, &entry.name).unwrap().unwrap();
        fs.release(orphan).unwrap();
    }
    assert_eq!(seen.len(), 150);
    let orphan = fs.rmdir(ROOT_INO, b"d").unwrap();
    fs.release(orphan).unwrap();
    let disk = fs.unmount().unwrap();
    assert_fsck_clean(&disk.data, "after rm -rf");
}

/// A file read whole after a remount (its blocks not cached) equals what was written, also
/// where some of its blocks were changed since and are only in the cache, and across a
/// hole, at an offset that is not a block's, and into a buffer longer than the file.
#[test]
fn whole_block_reads_from_the_disk_and_the_cache_agree() {
    let disk = formatted(4 << 20, 1024);
    let mut fs = Ext2::mount(disk).unwrap();
    let ino = fs.create(ROOT_INO, b"f", 0o644).unwrap();
    let mut want: Vec<u8> = (0..200 * 1024u32).map(|i| (i * 7 % 253) as u8).collect();
    assert_eq!(fs.write(ino, 0, &want), Ok(want.len()));
    // A hole of three blocks, then more data.
    let tail = vec![9u8; 5000];
    let at = want.len() + 3 * 1024;
    assert_eq!(fs.write(ino, at as u64, &tail), Ok(tail.len()));
    want.resize(at, 0);
    want.extend_from_slice(&tail);
    let mut fs = Ext2::mount(fs.unmount().unwrap()).unwrap();
    // Changed blocks in the middle, cached and dirty.
    for (i, b) in want[50 * 1024..53 * 1024 + 10].iter_mut().enumerate() {
        *b = i as u8 ^ 0x5a;
    }
    let changed = want[50 * 1024..53 * 1024 + 10].to_vec();
    assert_eq!(fs.write(ino, 50 * 1024, &changed), Ok(changed.len()));
    let mut back = vec![0xffu8; want.len() + 4096];
    assert_eq!(fs.read(ino, 0, &mut back), Ok(want.len()));
    assert!(back[..want.len()] == want[..], "the whole file");
    let mut part = vec![0u8; 70 * 1024];
    assert_eq!(fs.read(ino, 300, &mut part), Ok(part.len()));
    assert!(
        part[..] == want[300..300 + part.len()],
        "from an offset inside a block"
    );
    let image = fs.unmount().unwrap();
    assert_fsck_clean(&image.data, "after the reads");
}
