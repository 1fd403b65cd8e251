//! Helpers of the integration tests: an in-memory block device, the host's e2fsprogs
//! (skipped with a note when absent), and a model of a tree to build and check.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU32, Ordering};

use ext2::{Error, Ext2, FileType, ROOT_INO};
use slots::{BlockDevice, SECTOR};

/// A disk in memory; reads and writes past its end fail.
#[derive(Clone)]
pub struct MemDisk {
    pub data: Vec<u8>,
    pub flushes: u32,
}

impl MemDisk {
    pub fn new(data: Vec<u8>) -> Self {
        MemDisk { data, flushes: 0 }
    }
    pub fn zeroed(bytes: usize) -> Self {
        MemDisk::new(vec![0; bytes])
    }
    pub fn sectors(&self) -> u64 {
        (self.data.len() / SECTOR) as u64
    }
}

impl BlockDevice for MemDisk {
    type Error = &'static str;
    fn read(&mut self, sector: u64, buf: &mut [u8; SECTOR]) -> Result<(), Self::Error> {
        let at = usize::try_from(sector)
            .map_err(|_| "range")?
            .checked_mul(SECTOR)
            .ok_or("range")?;
        let part = self.data.get(at..at + SECTOR).ok_or("beyond the end")?;
        buf.copy_from_slice(part);
        Ok(())
    }
    fn write(&mut self, sector: u64, data: &[u8; SECTOR]) -> Result<(), Self::Error> {
        let at = usize::try_from(sector)
            .map_err(|_| "range")?
            .checked_mul(SECTOR)
            .ok_or("range")?;
        let part = self.data.get_mut(at..at + SECTOR).ok_or("beyond the end")?;
        part.copy_from_slice(data);
        Ok(())
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        self.flushes += 1;
        Ok(())
    }
}

pub fn now() -> u32 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() as u32)
}

/// A fresh path in the temporary directory (removed by [`TempFile`]'s drop).
pub struct TempFile(pub PathBuf);

impl TempFile {
    pub fn new(tag: &str) -> Self {
        static COUNTER: AtomicU32 = AtomicU32::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let name = format!("ext2-test-{}-{tag}-{n}", std::process::id());
        TempFile(std::env::temp_dir().join(name))
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// The path of an e2fsprogs/busybox tool, or `None` (with a note) when the host lacks it.
pub fn tool(name: &str) -> Option<PathBuf> {
    for dir in ["/usr/sbin", "/sbin", "/usr/bin", "/bin"] {
        let path = Path::new(dir).join(name);
        if path.exists() {
            return Some(path);
        }
    }
    eprintln!("note: {name} not found; skipping the part of the test that needs it");
    None
}

/// An image of `bytes` made by `mkfs.ext2 <args>`, or by `busybox mke2fs` when `busybox`.
pub fn mkfs_image(args: &[&str], bytes: usize, busybox: bool) -> Option<Vec<u8>> {
    let file = TempFile::new("mkfs");
    std::fs::write(&file.0, vec![0u8; bytes]).unwrap();
    let status = if busybox {
        Command::new(tool("busybox")?)
            .arg("mke2fs")
            .arg("-F")
            .args(args)
            .arg(&file.0)
            .arg((bytes / 1024).to_string())
            .output()
            .unwrap()
    } else {
        Command::new(tool("mkfs.ext2")?)
            .args(["-q", "-F"])
            .args(args)
            .arg(&file.0)
            .output()
            .unwrap()
    };
    assert!(status.status.success(), "mkfs failed: {status:?}");
    Some(std::fs::read(&file.0).unwrap())
}

/// Runs `e2fsck -fn` on the image: `None` without e2fsck, else (clean, output).
pub fn e2fsck(image: &[u8]) -> Option<(bool, String)> {
    let e2fsck = tool("e2fsck")?;
    let file = TempFile::new("fsck");
    std::fs::write(&file.0, image).unwrap();
    let out = Command::new(e2fsck)
        .arg("-fn")
        .arg(&file.0)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    Some((out.status.code() == Some(0), text))
}

/// Asserts that e2fsck finds nothing to fix (when e2fsck is present).
pub fn assert_fsck_clean(image: &[u8], what: &str) {
    if let Some((clean, text)) = e2fsck(image) {
        assert!(clean, "e2fsck -fn of {what} found problems:\n{text}");
    }
}

/// Runs one debugfs command (`-R`) on an image file, returning stdout; with `write`, a
/// script of commands (one per line, `-w -f`).
pub fn debugfs(path: &Path, commands: &str, write: bool) -> Option<Vec<u8>> {
    let debugfs = tool("debugfs")?;
    let script = TempFile::new("debugfs-cmds");
    let mut command = Command::new(debugfs);
    if write {
        std::fs::write(&script.0, commands).unwrap();
        command.arg("-w").arg("-f").arg(&script.0);
    } else {
        command.arg("-R").arg(commands.trim_end());
    }
    let out = command.arg(path).output().unwrap();
    assert!(out.status.success(), "debugfs failed: {out:?}");
    Some(out.stdout)
}

/// What a path holds in a model tree.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Node {
    File(Vec<u8>),
    Dir,
    Symlink(Vec<u8>),
}

pub type Tree = BTreeMap<String, Node>;

/// The inode at `path` ("" is the root).
pub fn resolve<D: BlockDevice>(fs: &mut Ext2<D>, path: &str) -> Result<u32, Error> {
    let mut ino = ROOT_INO;
    for name in path.split('/').filter(|n| !n.is_empty()) {
        ino = fs.lookup(ino, name.as_bytes())?.ok_or(Error::NotFound)?;
    }
    Ok(ino)
}

/// The parent directory's inode and the last name of `path`.
pub fn parent<'a, D: BlockDevice>(
    fs: &mut Ext2<D>,
    path: &'a str,
) -> Result<(u32, &'a str), Error> {
    let (dir, name) = path.rsplit_once('/').unwrap_or(("", path));
    let dir = resolve(fs, dir)?;
    if fs.stat(dir)?.mode & ext2::S_IFMT != ext2::S_IFDIR {
        return Err(Error::NotDir);
    }
    Ok((dir, name))
}

pub fn read_all<D: BlockDevice>(fs: &mut Ext2<D>, ino: u32) -> Vec<u8> {
    let size = fs.stat(ino).unwrap().size as usize;
    let mut buf = vec![0u8; size];
    let mut done = 0;
    while done < size {
        let n = fs.read(ino, done as u64, &mut buf[done..]).unwrap();
        assert!(n > 0);
        done += n;
    }
    buf
}

/// Reads every entry of a directory through readdir.
pub fn list<D: BlockDevice>(fs: &mut Ext2<D>, dir: u32) -> Vec<(String, u32)> {
    let mut out = Vec::new();
    let mut cookie = 0;
    while let Some((entry, next)) = fs.readdir(dir, cookie).unwrap() {
        // The entry's type, when the file system records it, is the inode's.
        let mode = fs.stat(entry.ino).unwrap().mode;
        if entry.file_type != FileType::Unknown {
            assert_eq!(entry.file_type, FileType::from_mode(mode));
        }
        out.push((String::from_utf8(entry.name).unwrap(), entry.ino));
        assert!(next > cookie);
        cookie = next;
    }
    out
}

/// Checks the crate reads the same tree as the model: every path, and no extra names.
/// The names directly in directory `path` ("" for the root) of `tree`, sorted.
fn children(tree: &Tree, path: &str) -> Vec<String> {
    let prefix = if path.is_empty() {
        String::new()
    } else {
        format!("{path}/")
    };
    let mut names: Vec<String> = tree
        .keys()
        .filter_map(|p| p.strip_prefix(&prefix))
        .filter(|rest| !rest.is_empty() && !rest.contains('/'))
        .map(str::to_string)
        .collect();
    names.sort();
    names
}

pub fn verify_with_crate<D: BlockDevice>(fs: &mut Ext2<D>, tree: &Tree) {
    for (path, node) in tree {
        let ino = resolve(fs, path).unwrap_or_else(|e| panic!("{path}: {e:?}"));
        match node {
            Node::File(data) => assert!(read_all(fs, ino) == *data, "{path}: contents differ"),
            Node::Symlink(target) => assert_eq!(fs.readlink(ino).unwrap(), *target, "{path}"),
            Node::Dir => {
                let mut names: Vec<String> = list(fs, ino)
                    .into_iter()
                    .map(|(n, _)| n)
                    .filter(|n| n != "." && n != ".." && n != "lost+found")
                    .collect();
                names.sort();
                let expected = children(tree, path);
                assert_same_names(&names, &expected, &format!("readdir /{path}"));
            }
        }
    }
}

/// Checks debugfs reads the same tree: file bytes through `cat`, names through `ls -p`,
/// fast symlinks through `stat`.
pub fn verify_with_debugfs(image: &[u8], tree: &Tree) {
    if tool("debugfs").is_none() {
        return;
    }
    let file = TempFile::new("verify");
    std::fs::write(&file.0, image).unwrap();
    for (path, node) in tree {
        match node {
            Node::File(data) => {
                let out = debugfs(&file.0, &format!("cat /{path}\n"), false).unwrap();
                assert!(
                    out == *data,
                    "debugfs cat /{path}: {} bytes, expected {}",
                    out.len(),
                    data.len()
                );
            }
            Node::Symlink(target) => {
                let out = debugfs(&file.0, &format!("stat /{path}\n"), false).unwrap();
                let text = String::from_utf8_lossy(&out);
                let cat = debugfs(&file.0, &format!("cat /{path}\n"), false).unwrap();
                let quoted = format!("\"{}\"", String::from_utf8_lossy(target));
                assert!(
                    text.contains(&quoted) || cat == *target,
                    "debugfs symlink /{path}: {text}"
                );
            }
            Node::Dir => {
                let out = debugfs(&file.0, &format!("ls -p /{path}\n"), false).unwrap();
                let text = String::from_utf8_lossy(&out);
                let mut names: Vec<String> = text
                    .lines()
                    // `/ino/mode/uid/gid/name/size/`; entries with inode 0 are empty slots.
                    .filter(|l| l.split('/').nth(1).is_some_and(|ino| ino != "0"))
                    .filter_map(|l| l.split('/').nth(5).map(str::to_string))
                    .filter(|n| !n.is_empty() && n != "." && n != ".." && n != "lost+found")
                    .collect();
                names.sort();
                let expected = children(tree, path);
                assert_same_names(&names, &expected, &format!("debugfs ls /{path}"));
            }
        }
    }
}

/// Deterministic bytes of a file (so a mix-up of blocks shows).
pub fn pattern(len: usize, seed: u32) -> Vec<u8> {
    let mut x = seed.wrapping_mul(2654435761).wrapping_add(1);
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as u8
        })
        .collect()
}

/// Compares two sorted name lists, showing only the differences.
pub fn assert_same_names(found: &[String], expected: &[String], what: &str) {
    let extra: Vec<&String> = found.iter().filter(|n| !expected.contains(n)).collect();
    let missing: Vec<&String> = expected.iter().filter(|n| !found.contains(n)).collect();
    assert!(
        extra.is_empty() && missing.is_empty() && found.len() == expected.len(),
        "{what}: extra {extra:?}, missing {missing:?}"
    );
}
