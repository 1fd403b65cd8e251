//! The tree test: images made by mkfs.ext2 (1 KiB and 4 KiB blocks, 128- and 256-byte
//! inodes, default features), busybox mke2fs and this crate's `format` get a tree of files
//! of every block-map depth, sparse files, deep and large directories, symlinks, hard
//! links, renames, removals and truncations; then e2fsck -fn must find nothing and debugfs
//! must read the same bytes and names.

mod common;

use common::*;
use ext2::{Error, Ext2, FormatOptions, ROOT_INO};

fn create_file(fs: &mut Ext2<MemDisk>, tree: &mut Tree, path: &str, data: &[u8]) -> u32 {
    let (dir, name) = parent(fs, path).unwrap();
    let ino = fs.create(dir, name.as_bytes(), 0o644).unwrap();
    // In pieces of odd sizes, to cross block boundaries at every offset.
    let mut done = 0;
    for (i, chunk) in data.chunks(4093).enumerate() {
        let n = fs.write(ino, done as u64, chunk).unwrap();
        assert_eq!(n, chunk.len(), "chunk {i}");
        done += n;
    }
    tree.insert(path.to_string(), Node::File(data.to_vec()));
    ino
}

fn mkdir(fs: &mut Ext2<MemDisk>, tree: &mut Tree, path: &str) -> u32 {
    let (dir, name) = parent(fs, path).unwrap();
    let ino = fs.mkdir(dir, name.as_bytes(), 0o755).unwrap();
    tree.insert(path.to_string(), Node::Dir);
    ino
}

/// Builds the tree on a mounted file system, recording it in the model.
fn build_tree(fs: &mut Ext2<MemDisk>) -> Tree {
    let mut tree = Tree::new();
    tree.insert(String::new(), Node::Dir);
    let block = fs.block_size() as usize;
    for (name, len) in [
        ("empty", 0),
        ("one", 1),
        ("b1023", 1023),
        ("b1024", 1024),
        ("k12", 12 * 1024),
        ("k70", 70 * 1024),
        ("m5", 5 << 20),
        ("victim", 3000),
        ("trunc-down", 70 * 1024),
        ("trunc-up", 10),
    ] {
        create_file(fs, &mut tree, name, &pattern(len, len as u32));
    }
    // A sparse file: data, a hole of many blocks (beyond the direct ones), data.
    let sparse = fs.create(ROOT_INO, b"sparse", 0o600).unwrap();
    fs.write(sparse, 0, b"start").unwrap();
    fs.write(sparse, 300_000, &pattern(5000, 7)).unwrap();
    let mut expected = vec![0u8; 305_000];
    expected[..5].copy_from_slice(b"start");
    expected[300_000..].copy_from_slice(&pattern(5000, 7));
    tree.insert("sparse".into(), Node::File(expected));
    let sectors = fs.stat(sparse).unwrap().blocks;
    assert!(
        sectors * 512 < 40_000,
        "the hole is not allocated: {sectors} sectors"
    );

    mkdir(fs, &mut tree, "a");
    mkdir(fs, &mut tree, "a/b");
    mkdir(fs, &mut tree, "a/b/c");
    create_file(fs, &mut tree, "a/b/c/deep.txt", b"deep inside");
    mkdir(fs, &mut tree, "many");
    for i in 0..300 {
        let path = format!("many/file-with-a-longish-name-{i:03}");
        create_file(fs, &mut tree, &path, path.as_bytes());
    }
    let many = resolve(fs, "many").unwrap();
    assert!(fs.stat(many).unwrap().size >= block as u64 * 3);

    // Symlinks: fast and slow.
    fs.symlink(ROOT_INO, b"short", b"a/b/c/deep.txt").unwrap();
    tree.insert("short".into(), Node::Symlink(b"a/b/c/deep.txt".to_vec()));
    let long = "x".repeat(100) + "/target";
    fs.symlink(ROOT_INO, b"long", long.as_bytes()).unwrap();
    tree.insert("long".into(), Node::Symlink(long.into_bytes()));

    // Hard links.
    let k12 = resolve(fs, "k12").unwrap();
    fs.link(ROOT_INO, b"hard", k12).unwrap();
    tree.insert("hard".into(), tree["k12"].clone());
    let a = resolve(fs, "a").unwrap();
    let one = resolve(fs, "one").unwrap();
    fs.link(a, b"hard2", one).unwrap();
    tree.insert("a/hard2".into(), tree["one"].clone());
    assert_eq!(fs.stat(k12).unwrap().nlink, 2);
    assert_eq!(fs.link(ROOT_INO, b"dirlink", a), Err(Error::NotPermitted));

    // Renames: over an existing file, across directories, a directory to a new parent,
    // a directory over an empty directory.
    let replaced = fs.rename(ROOT_INO, b"k70", ROOT_INO, b"victim").unwrap();
    assert!(replaced.is_some());
    fs.release(replaced.unwrap()).unwrap();
    let k70 = tree.remove("k70").unwrap();
    tree.insert("victim".into(), k70);
    let b = resolve(fs, "a/b").unwrap();
    assert_eq!(fs.rename(ROOT_INO, b"one", b, b"moved-one").unwrap(), None);
    let one = tree.remove("one").unwrap();
    tree.insert("a/b/moved-one".into(), one);
    let c = resolve(fs, "a/b/c").unwrap();
    fs.rename(b, b"c", ROOT_INO, b"c2").unwrap();
    for key in ["a/b/c", "a/b/c/deep.txt"] {
        let node = tree.remove(key).unwrap();
        tree.insert(key.replace("a/b/c", "c2"), node);
    }
    assert_eq!(fs.lookup(c, b"..").unwrap(), Some(ROOT_INO));
    assert_eq!(fs.rename(ROOT_INO, b"a", b, b"inside"), Err(Error::Invalid));
    let empty = mkdir(fs, &mut tree, "empty-dir");
    let orphan = fs.rename(ROOT_INO, b"a", ROOT_INO, b"empty-dir").unwrap();
    assert_eq!(orphan, Some(empty));
    fs.release(empty).unwrap();
    let moved: Vec<(String, Node)> = tree
        .iter()
        .filter(|(k, _)| *k == "a" || k.starts_with("a/"))
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    for (key, node) in moved {
        tree.remove(&key);
        tree.insert(key.replacen('a', "empty-dir", 1), node);
    }
    assert_eq!(
        fs.rename(ROOT_INO, b"c2", ROOT_INO, b"many"),
        Err(Error::NotEmpty)
    );
    assert_eq!(
        fs.rename(ROOT_INO, b"k12", ROOT_INO, b"many"),
        Err(Error::IsDir)
    );
    assert_eq!(
        fs.rename(ROOT_INO, b"many", ROOT_INO, b"k12"),
        Err(Error::NotDir)
    );

    // Removals: unlink a third of the big directory, rmdir, ENOTEMPTY.
    let many = resolve(fs, "many").unwrap();
    for i in (0..300).step_by(3) {
        let path = format!("many/file-with-a-longish-name-{i:03}");
        let ino = fs
            .unlink(many, &path.as_bytes()["many/".len()..])
            .unwrap()
            .unwrap();
        fs.release(ino).unwrap();
        tree.remove(&path);
    }
    assert_eq!(fs.rmdir(ROOT_INO, b"many"), Err(Error::NotEmpty));
    mkdir(fs, &mut tree, "many/sub");
    let sub = fs.rmdir(many, b"sub").unwrap();
    fs.release(sub).unwrap();
    tree.remove("many/sub");
    assert_eq!(fs.unlink(ROOT_INO, b"many"), Err(Error::IsDir));
    assert_eq!(fs.rmdir(ROOT_INO, b"k12"), Err(Error::NotDir));
    // An unlinked file stays readable until released.
    let gone = fs.unlink(ROOT_INO, b"b1023").unwrap().unwrap();
    assert_eq!(
        read_all(fs, gone),
        tree.remove("b1023")
            .map(|n| match n {
                Node::File(d) => d,
                _ => unreachable!(),
            })
            .unwrap()
    );
    fs.release(gone).unwrap();

    // Truncations.
    let down = resolve(fs, "trunc-down").unwrap();
    fs.truncate(down, 3000).unwrap();
    fs.truncate(down, 5000).unwrap();
    let mut data = pattern(70 * 1024, 70 * 1024)[..3000].to_vec();
    data.resize(5000, 0);
    tree.insert("trunc-down".into(), Node::File(data));
    let up = resolve(fs, "trunc-up").unwrap();
    fs.truncate(up, 200_000).unwrap();
    let mut data = pattern(10, 10);
    data.resize(200_000, 0);
    tree.insert("trunc-up".into(), Node::File(data));
    let m5 = resolve(fs, "m5").unwrap();
    fs.truncate(m5, 100_000).unwrap();
    tree.insert(
        "m5".into(),
        Node::File(pattern(5 << 20, 5 << 20)[..100_000].to_vec()),
    );
    tree
}

/// Mounts, builds, checks, unmounts, then e2fsck and debugfs, then mounts again and checks.
fn tree_test(image: Vec<u8>, what: &str) {
    let mut fs = Ext2::mount(MemDisk::new(image)).unwrap();
    fs.set_now(now());
    let tree = build_tree(&mut fs);
    verify_with_crate(&mut fs, &tree);
    let image = fs.unmount().unwrap().data;
    assert_fsck_clean(&image, what);
    verify_with_debugfs(&image, &tree);
    let mut fs = Ext2::mount(MemDisk::new(image)).unwrap();
    verify_with_crate(&mut fs, &tree);
    let image = fs.unmount().unwrap().data;
    assert_fsck_clean(&image, what);
}

const IMAGE_BYTES: usize = 24 << 20;

#[test]
fn mkfs_1k_blocks_128_inodes() {
    if let Some(image) = mkfs_image(&["-b", "1024", "-I", "128"], IMAGE_BYTES, false) {
        tree_test(image, "mkfs -b 1024 -I 128");
    }
}

#[test]
fn mkfs_4k_blocks_256_inodes() {
    if let Some(image) = mkfs_image(&["-b", "4096", "-I", "256"], IMAGE_BYTES, false) {
        tree_test(image, "mkfs -b 4096 -I 256");
    }
}

#[test]
fn mkfs_4k_blocks_128_inodes() {
    if let Some(image) = mkfs_image(&["-b", "4096", "-I", "128"], IMAGE_BYTES, false) {
        tree_test(image, "mkfs -b 4096 -I 128");
    }
}

#[test]
fn mkfs_1k_blocks_256_inodes() {
    if let Some(image) = mkfs_image(&["-b", "1024", "-I", "256"], IMAGE_BYTES, false) {
        tree_test(image, "mkfs -b 1024 -I 256");
    }
}

/// Revision 0: no features at all (no file types in entries, 128-byte inodes, 2 GiB limit).
#[test]
fn mkfs_revision_0() {
    if let Some(image) = mkfs_image(&["-r", "0", "-b", "1024"], IMAGE_BYTES, false) {
        tree_test(image, "mkfs -r 0");
    }
}

#[test]
fn busybox_mke2fs() {
    if let Some(image) = mkfs_image(&[], IMAGE_BYTES, true) {
        tree_test(image, "busybox mke2fs");
    }
}

fn formatted(block_size: u32, inode_size: u16) -> Vec<u8> {
    let mut disk = MemDisk::zeroed(IMAGE_BYTES);
    let sectors = disk.sectors();
    let options = FormatOptions {
        block_size,
        inode_size,
        now: now(),
        uuid: *b"warden-ext2-test",
        ..FormatOptions::default()
    };
    ext2::format(&mut disk, sectors, &options).unwrap();
    disk.data
}

#[test]
fn format_1k_blocks_128_inodes() {
    let image = formatted(1024, 128);
    assert_fsck_clean(&image, "format 1024/128");
    tree_test(image, "format 1024/128");
}

#[test]
fn format_4k_blocks_256_inodes() {
    let image = formatted(4096, 256);
    assert_fsck_clean(&image, "format 4096/256");
    tree_test(image, "format 4096/256");
}
