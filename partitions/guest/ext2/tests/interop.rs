//! Interplay with e2fsprogs beyond the tree test: files written by debugfs read by the
//! crate, hashed (dir_index) directories changed by the crate, refused features, a full
//! disk, read-only mounts and the clean flag.

mod common;

use std::process::Command;

use common::*;
use ext2::{Error, Ext2, FormatOptions, ROOT_INO};

#[test]
fn reads_what_debugfs_wrote() {
    let Some(image) = mkfs_image(&["-b", "1024"], 16 << 20, false) else {
        return;
    };
    let file = TempFile::new("debugfs-image");
    std::fs::write(&file.0, &image).unwrap();
    let small = TempFile::new("small");
    let big = TempFile::new("big");
    let big_data = pattern(3 << 20, 99);
    std::fs::write(&small.0, b"hello from debugfs\n").unwrap();
    std::fs::write(&big.0, &big_data).unwrap();
    let long_target = "t".repeat(200);
    let script = format!(
        "mkdir d\nmkdir d/e\nwrite {} d/small\nwrite {} d/e/big\nsymlink s /d/small\nsymlink l {long_target}\n",
        small.0.display(),
        big.0.display()
    );
    let Some(_) = debugfs(&file.0, &script, true) else {
        return;
    };
    let image = std::fs::read(&file.0).unwrap();
    assert_fsck_clean(&image, "debugfs-written image");
    let mut fs = Ext2::mount(MemDisk::new(image)).unwrap();
    let mut tree = Tree::new();
    tree.insert("d".into(), Node::Dir);
    tree.insert("d/e".into(), Node::Dir);
    tree.insert(
        "d/small".into(),
        Node::File(b"hello from debugfs\n".to_vec()),
    );
    tree.insert("d/e/big".into(), Node::File(big_data));
    tree.insert("s".into(), Node::Symlink(b"/d/small".to_vec()));
    tree.insert("l".into(), Node::Symlink(long_target.into_bytes()));
    verify_with_crate(&mut fs, &tree);
    let d = resolve(&mut fs, "d").unwrap();
    assert_eq!(fs.stat(d).unwrap().nlink, 3);
    // And change what debugfs wrote: e2fsck stays happy.
    fs.set_now(now());
    let big = resolve(&mut fs, "d/e/big").unwrap();
    fs.truncate(big, 1000).unwrap();
    let e = resolve(&mut fs, "d/e").unwrap();
    if let Some(ino) = fs.unlink(e, b"big").unwrap() {
        fs.release(ino).unwrap();
    }
    let image = fs.unmount().unwrap().data;
    assert_fsck_clean(&image, "debugfs image changed by the crate");
}

/// A directory that e2fsck -D indexed (EXT2_INDEX_FL, htree blocks): the crate reads it
/// linearly, and adding or removing entries leaves a valid (linear) directory.
#[test]
fn hashed_directory_stays_valid() {
    let Some(image) = mkfs_image(&["-b", "1024"], 8 << 20, false) else {
        return;
    };
    let mut fs = Ext2::mount(MemDisk::new(image)).unwrap();
    fs.set_now(now());
    let dir = fs.mkdir(ROOT_INO, b"big", 0o755).unwrap();
    for i in 0..200 {
        fs.create(dir, format!("entry-{i}").as_bytes(), 0o644)
            .unwrap();
    }
    let image = fs.unmount().unwrap().data;
    let Some(e2fsck) = tool("e2fsck") else {
        return;
    };
    let file = TempFile::new("htree");
    std::fs::write(&file.0, &image).unwrap();
    let out = Command::new(e2fsck)
        .arg("-fyD")
        .arg(&file.0)
        .output()
        .unwrap();
    assert!(
        out.status.code().is_some_and(|c| c <= 1),
        "e2fsck -fyD: {out:?}"
    );
    let image = std::fs::read(&file.0).unwrap();
    let stat = debugfs(&file.0, "stat /big", false).unwrap();
    assert!(
        String::from_utf8_lossy(&stat).contains("Flags: 0x1000"),
        "not indexed"
    );

    let mut fs = Ext2::mount(MemDisk::new(image)).unwrap();
    fs.set_now(now());
    let dir = resolve(&mut fs, "big").unwrap();
    for i in 0..200 {
        assert!(
            fs.lookup(dir, format!("entry-{i}").as_bytes())
                .unwrap()
                .is_some()
        );
    }
    assert_eq!(list(&mut fs, dir).len(), 202);
    fs.create(dir, b"added", 0o644).unwrap();
    let ino = fs.unlink(dir, b"entry-7").unwrap().unwrap();
    fs.release(ino).unwrap();
    let image = fs.unmount().unwrap().data;
    assert_fsck_clean(&image, "hashed directory changed by the crate");
}

#[test]
fn refuses_unknown_features() {
    let Some(mkfs) = tool("mkfs.ext2") else {
        return;
    };
    let file = TempFile::new("ext4");
    std::fs::write(&file.0, vec![0u8; 16 << 20]).unwrap();
    let out = Command::new(mkfs)
        .args(["-q", "-F", "-t", "ext4"])
        .arg(&file.0)
        .output()
        .unwrap();
    assert!(out.status.success());
    let image = std::fs::read(&file.0).unwrap();
    let error = Ext2::mount(MemDisk::new(image.clone())).err().unwrap();
    assert_eq!(
        error,
        Error::Unsupported("incompat 0x0040 (extents)".into())
    );
    assert_eq!(error.errno(), 22);
    // A journal alone (ext3) is refused too, by name.
    let out = Command::new(tool("mkfs.ext2").unwrap())
        .args(["-q", "-F", "-t", "ext3"])
        .arg(&file.0)
        .output()
        .unwrap();
    assert!(out.status.success());
    let image = std::fs::read(&file.0).unwrap();
    let error = Ext2::mount(MemDisk::new(image)).err().unwrap();
    assert_eq!(
        error,
        Error::Unsupported("compat 0x0004 (has_journal)".into())
    );
}

fn small_formatted(bytes: usize, block_size: u32) -> MemDisk {
    let mut disk = MemDisk::zeroed(bytes);
    let sectors = disk.sectors();
    let options = FormatOptions {
        block_size,
        inode_size: 128,
        bytes_per_inode: 4096,
        now: now(),
        ..FormatOptions::default()
    };
    ext2::format(&mut disk, sectors, &options).unwrap();
    disk
}

/// Filling the disk gives NoSpace (a short write first), and what was written stays
/// consistent: e2fsck is clean, freeing makes room again.
#[test]
fn out_of_space() {
    for block_size in [1024, 4096] {
        let mut fs = Ext2::mount(small_formatted(2 << 20, block_size)).unwrap();
        fs.set_now(now());
        let file = fs.create(ROOT_INO, b"filler", 0o644).unwrap();
        let chunk = pattern(64 * 1024, 5);
        let mut offset = 0u64;
        loop {
            match fs.write(file, offset, &chunk) {
                Ok(n) if n == chunk.len() => offset += n as u64,
                Ok(n) => {
                    offset += n as u64;
                    assert_eq!(fs.write(file, offset, &chunk), Err(Error::NoSpace));
                    break;
                }
                Err(e) => {
                    assert_eq!(e, Error::NoSpace);
                    break;
                }
            }
        }
        assert_eq!(fs.statfs().free_blocks, 0);
        assert_eq!(fs.stat(file).unwrap().size, offset);
        // Directories and symlinks that need a block fail cleanly too.
        assert_eq!(fs.mkdir(ROOT_INO, b"d", 0o755), Err(Error::NoSpace));
        let long = "l".repeat(100);
        assert_eq!(
            fs.symlink(ROOT_INO, b"l", long.as_bytes()),
            Err(Error::NoSpace)
        );
        // Inodes: create until the root directory or the inodes run out.
        let mut created = 0;
        let error = loop {
            match fs.create(ROOT_INO, format!("empty-{created}").as_bytes(), 0o644) {
                Ok(_) => created += 1,
                Err(e) => break e,
            }
        };
        assert_eq!(error, Error::NoSpace);
        let disk = fs.unmount().unwrap();
        assert_fsck_clean(&disk.data, "full disk");
        let mut fs = Ext2::mount(disk).unwrap();
        fs.set_now(now());
        let data = read_all(&mut fs, file);
        assert_eq!(data.len() as u64, offset);
        assert!(data.chunks(chunk.len()).all(|c| c == &chunk[..c.len()]));
        fs.truncate(file, 0).unwrap();
        assert!(fs.mkdir(ROOT_INO, b"d", 0o755).is_ok());
        let disk = fs.unmount().unwrap();
        assert_fsck_clean(&disk.data, "full disk after freeing");
    }
}

#[test]
fn clean_flag_and_read_only() {
    let disk = small_formatted(4 << 20, 1024);
    let state = |data: &[u8]| u16::from_le_bytes([data[1024 + 58], data[1024 + 59]]);
    assert_eq!(state(&disk.data), 1);
    let mut fs = Ext2::mount(disk).unwrap();
    fs.set_now(now());
    let file = fs.create(ROOT_INO, b"f", 0o644).unwrap();
    fs.write(file, 0, b"data").unwrap();
    fs.sync().unwrap();
    fs.write(file, 4, b"more").unwrap();
    let disk = fs.unmount().unwrap();
    assert_eq!(state(&disk.data), 1);
    // While mounted the flag is clear on disk: a crash image asks for a check.
    let fs = Ext2::mount(disk).unwrap();
    let snapshot = fs.unmount().unwrap();
    let mut fs = Ext2::mount(snapshot.clone()).unwrap();
    fs.set_now(now());
    fs.write(file, 0, b"x").unwrap();
    let data = fs.unmount().unwrap().data;
    assert_eq!(state(&data), 1);

    let mut fs = Ext2::mount_read_only(MemDisk::new(data.clone())).unwrap();
    assert_eq!(fs.create(ROOT_INO, b"g", 0o644), Err(Error::ReadOnly));
    assert_eq!(fs.write(file, 0, b"y"), Err(Error::ReadOnly));
    let mut buf = [0u8; 8];
    assert_eq!(fs.read(file, 0, &mut buf).unwrap(), 8);
    assert_eq!(&buf, b"xatamore");
    assert_eq!(fs.unmount().unwrap().data, data);
}

/// The clean flag is cleared on disk by mount (before any change reaches it).
#[test]
fn mount_marks_unclean_on_disk() {
    struct Spy(MemDisk);
    impl slots::BlockDevice for Spy {
        type Error = &'static str;
        fn read(&mut self, s: u64, b: &mut [u8; 512]) -> Result<(), Self::Error> {
            self.0.read(s, b)
        }
        fn write(&mut self, s: u64, d: &[u8; 512]) -> Result<(), Self::Error> {
            self.0.write(s, d)
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            self.0.flush()
        }
    }
    let fs = Ext2::mount(Spy(small_formatted(4 << 20, 1024))).unwrap();
    let crash = fs.abandon();
    assert_eq!(
        u16::from_le_bytes([crash.0.data[1024 + 58], crash.0.data[1024 + 59]]),
        0
    );
}

/// The checks above mean something: e2fsck -fn does flag a wrong count.
#[test]
fn e2fsck_catches_a_wrong_count() {
    let mut image = small_formatted(4 << 20, 1024).data;
    assert_fsck_clean(&image, "fresh image");
    // Group 0's free blocks count, one off.
    image[2048 + 12] ^= 1;
    if let Some((clean, text)) = e2fsck(&image) {
        assert!(!clean, "{text}");
    }
}
