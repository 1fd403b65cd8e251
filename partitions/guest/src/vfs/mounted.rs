//! The file system `mount` puts on the disk: ext2 on `/dev/vda` (the `ext2` crate, over
//! [`crate::disk::Volume`]), whose inodes are the VFS's [`super::Node::Mounted`] nodes.
//!
//! - **What mounts.** `mount -t ext2 /dev/vda DIR` (`ext2`, `ext3` without a journal
//!   needed, or `auto`), `MS_RDONLY` for read-only: `DIR` is a directory of the in-memory
//!   file system other than `/` and `/proc`; one mount at a time. The disk is the mount's
//!   while mounted: `/dev/vda` itself answers `EBUSY` (its size and ioctls still answer).
//!   A file system the crate refuses (another type, a feature it lacks, a corrupt
//!   superblock) gives `EINVAL` (`EUCLEAN` for corruption) and a log line naming why, as
//!   Linux's `dmesg` would.
//! - **Durability** follows ext2 on Linux with `sync` semantics at the calls that ask:
//!   `fsync`, `fdatasync`, `syncfs` and `sync` write every changed block back (data
//!   before metadata) and flush the disk; `umount` also marks the file system clean. Between
//!   them changes sit in the crate's bounded write-back cache ([`ext2::CACHE_BLOCKS`]
//!   blocks). `rename` writes the new name before it removes the old, so after a cut
//!   the file is reachable by one name or both, never neither (see the crate's docs).
//! - **Unlinked open files** stay readable and writable until their last descriptor
//!   closes, then their blocks are freed; `umount` is `EBUSY` while a descriptor or a
//!   working directory is on the file system.
//! - **Limits.** Symbolic-link targets longer than 279 bytes cannot be followed
//!   (`ENAMETOOLONG`); `getcwd` and `/proc/<pid>/fd` name directories, not files
//!   (`ENOENT`); its files cannot be executed (`EACCES`) or mapped (`ENODEV`): they are
//!   not in memory as the initramfs's are; new files are root's (`chown` is accepted and
//!   not stored: every process is root). When the guest ends (its init exits), the file
//!   system is unmounted as at a shutdown.

use super::{Ino, PathBuf, Stat};
use crate::disk::Volume;
use crate::linux::Errno;
use alloc::boxed::Box;
use alloc::collections::{BTreeMap, BTreeSet};
use alloc::vec::Vec;
use core::cell::RefCell;
use ext2::Ext2;

/// `statfs`'s `f_type` of ext2.
pub const EXT2_SUPER_MAGIC: u64 = 0xef53;
/// `st_dev` of its files: the disk's device number (`MAJOR:MINOR` as Linux encodes it).
pub const DEV: u64 = (crate::disk::MAJOR << 8) | crate::disk::MINOR;
/// File system types `mount` accepts for it.
pub const TYPES: [&[u8]; 4] = [b"ext2", b"ext3", b"ext4", b"auto"];

/// A Linux errno for an error of the crate.
pub fn errno(e: &ext2::Error) -> Errno {
    Errno(e.errno() as u16)
}

/// The mounted file system.
pub struct Mount {
    /// The in-memory directory it covers.
    pub(super) at: Ino,
    /// That directory's path (`/proc/mounts`).
    path: PathBuf,
    fs: RefCell<Ext2<Volume>>,
    read_only: bool,
    /// The disk's size in bytes.
    disk_size: u64,
    /// Open file descriptions and working directories on each inode.
    users: BTreeMap<u32, u32>,
    /// Inodes whose last link went while they were open: freed at their last close.
    orphans: BTreeSet<u32>,
}

impl core::fmt::Debug for Mount {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Mount")
            .field("at", &self.at)
            .field("path", &self.path)
            .field("read_only", &self.read_only)
            .finish_non_exhaustive()
    }
}

impl Mount {
    /// Mounts the disk at directory `at` (path `path`); a failure hands the disk back.
    pub fn new(
        at: Ino,
        path: PathBuf,
        volume: Volume,
        read_only: bool,
        now: u64,
    ) -> Result<Self, (ext2::Error, Volume)> {
        let disk_size = volume.0.size();
        let mut fs = Ext2::mount_with(volume, read_only)?;
        fs.set_now(now.min(u32::MAX as u64) as u32);
        Ok(Mount {
            at,
            path,
            fs: RefCell::new(fs),
            read_only,
            disk_size,
            users: BTreeMap::new(),
            orphans: BTreeSet::new(),
        })
    }

    /// Writes everything back, marks the file system clean and hands the disk back; on a
    /// failure it stays mounted.
    pub fn unmount(self) -> Result<Volume, (Errno, Box<Self>)> {
        let Mount {
            at,
            path,
            fs,
            read_only,
            disk_size,
            users,
            orphans,
        } = self;
        fs.into_inner().unmount().map_err(|(e, fs)| {
            let mount = Box::new(Mount {
                at,
                path,
                fs: RefCell::new(*fs),
                read_only,
                disk_size,
                users,
                orphans,
            });
            (errno(&e), mount)
        })
    }

    /// The `/proc/mounts` line.
    pub fn describe(&self, w: &mut dyn core::fmt::Write) -> core::fmt::Result {
        let mode = if self.read_only { "ro" } else { "rw" };
        writeln!(
            w,
            "{} /{} ext2 {mode},relatime 0 0",
            crate::disk::DEVICE_PATH,
            self.path.as_str()
        )
    }

    /// The directory it is mounted on.
    pub fn path(&self) -> PathBuf {
        self.path
    }

    /// The disk's size in bytes.
    pub fn disk_size(&self) -> u64 {
        self.disk_size
    }

    /// Whether a descriptor or working directory is on it.
    pub fn busy(&self) -> bool {
        !self.users.is_empty()
    }

    fn with<R>(
        &self,
        op: impl FnOnce(&mut Ext2<Volume>) -> Result<R, ext2::Error>,
    ) -> Result<R, Errno> {
        op(&mut self.fs.borrow_mut()).map_err(|e| errno(&e))
    }

    /// A change at time `now` (seconds since the epoch).
    fn change<R>(
        &mut self,
        now: u64,
        op: impl FnOnce(&mut Ext2<Volume>) -> Result<R, ext2::Error>,
    ) -> Result<R, Errno> {
        let fs = self.fs.get_mut();
        fs.set_now(now.min(u32::MAX as u64) as u32);
        op(fs).map_err(|e| errno(&e))
    }

    pub fn stat(&self, ino: u32) -> Stat {
        match self.with(|fs| fs.stat(ino)) {
            Ok(s) => Stat {
                dev: DEV,
                ino: s.ino as u64,
                nlink: s.nlink as u64,
                mode: s.mode as u32,
                uid: s.uid,
                gid: s.gid,
                rdev: 0,
                size: s.size,
                blocks: s.blocks,
                mtime: s.mtime as u64,
            },
            Err(_) => Stat::default(),
        }
    }

    /// The inode's mode (type and permission bits; 0 when it cannot be read).
    pub fn mode(&self, ino: u32) -> u32 {
        self.stat(ino).mode
    }

    pub fn is_dir(&self, ino: u32) -> bool {
        self.mode(ino) & crate::cpio::S_IFMT == crate::cpio::S_IFDIR
    }

    pub fn is_symlink(&self, ino: u32) -> bool {
        self.mode(ino) & crate::cpio::S_IFMT == crate::cpio::S_IFLNK
    }

    pub fn is_file(&self, ino: u32) -> bool {
        self.mode(ino) & crate::cpio::S_IFMT == crate::cpio::S_IFREG
    }

    /// Entry `name` of directory `dir` (`..` of the root is the root: the VFS steps out).
    pub fn lookup(&self, dir: u32, name: &[u8]) -> Option<u32> {
        self.with(|fs| fs.lookup(dir, name)).ok().flatten()
    }

    /// A symbolic link's target, copied into `buf` (`ENAMETOOLONG` if it does not fit).
    pub fn readlink<'b>(&self, ino: u32, buf: &'b mut [u8]) -> Result<&'b [u8], Errno> {
        let target = self.with(|fs| fs.readlink(ino))?;
        let out = buf.get_mut(..target.len()).ok_or(Errno::ENAMETOOLONG)?;
        out.copy_from_slice(&target);
        Ok(out)
    }

    pub fn read(&self, ino: u32, offset: u64, buf: &mut [u8]) -> Result<usize, Errno> {
        self.with(|fs| fs.read(ino, offset, buf))
    }

    pub fn write(&mut self, ino: u32, offset: u64, data: &[u8], now: u64) -> Result<usize, Errno> {
        self.change(now, |fs| fs.write(ino, offset, data))
    }

    pub fn truncate(&mut self, ino: u32, len: u64, now: u64) -> Result<(), Errno> {
        self.change(now, |fs| fs.truncate(ino, len))
    }

    pub fn create(&mut self, dir: u32, name: &[u8], mode: u32, now: u64) -> Result<u32, Errno> {
        self.change(now, |fs| fs.create(dir, name, mode as u16))
    }

    pub fn mkdir(&mut self, dir: u32, name: &[u8], mode: u32, now: u64) -> Result<u32, Errno> {
        self.change(now, |fs| fs.mkdir(dir, name, mode as u16))
    }

    pub fn symlink(
        &mut self,
        dir: u32,
        name: &[u8],
        target: &[u8],
        now: u64,
    ) -> Result<u32, Errno> {
        self.change(now, |fs| fs.symlink(dir, name, target))
    }

    pub fn link(&mut self, ino: u32, dir: u32, name: &[u8], now: u64) -> Result<(), Errno> {
        self.change(now, |fs| fs.link(dir, name, ino))
    }

    /// Removes entry `name` of `dir` (a directory when `dir_wanted`); an inode whose last
    /// link went is freed now unless it is open (then at its last close).
    pub fn remove(
        &mut self,
        dir: u32,
        name: &[u8],
        dir_wanted: bool,
        now: u64,
    ) -> Result<(), Errno> {
        let gone = self.change(now, |fs| {
            if dir_wanted {
                fs.rmdir(dir, name).map(Some)
            } else {
                fs.unlink(dir, name)
            }
        })?;
        self.released(gone)
    }

    /// Renames as Linux does (`no_replace`: `EEXIST` if `to` exists).
    pub fn rename(
        &mut self,
        from_dir: u32,
        from: &[u8],
        to_dir: u32,
        to: &[u8],
        no_replace: bool,
        now: u64,
    ) -> Result<(), Errno> {
        if no_replace && self.lookup(to_dir, to).is_some() {
            return Err(Errno::EEXIST);
        }
        let gone = self.change(now, |fs| fs.rename(from_dir, from, to_dir, to))?;
        self.released(gone)
    }

    /// Frees inode `gone` (whose last link went) if nobody has it open, else at its last
    /// close.
    fn released(&mut self, gone: Option<u32>) -> Result<(), Errno> {
        match gone {
            Some(ino) if self.users.contains_key(&ino) => {
                self.orphans.insert(ino);
                Ok(())
            }
            Some(ino) => self.with(|fs| fs.release(ino)),
            None => Ok(()),
        }
    }

    pub fn chmod(&mut self, ino: u32, mode: u32, now: u64) -> Result<(), Errno> {
        self.change(now, |fs| fs.chmod(ino, mode as u16))
    }

    pub fn set_mtime(&mut self, ino: u32, mtime: u64, now: u64) -> Result<(), Errno> {
        let mtime = mtime.min(u32::MAX as u64) as u32;
        self.change(now, |fs| fs.set_times(ino, None, Some(mtime)))
    }

    /// Directory `dir`'s entry at or after `cookie` (`.` and `..` included, as stored) and
    /// the cookie after it.
    pub fn readdir(&self, dir: u32, cookie: u64) -> Result<Option<(ext2::DirEntry, u64)>, Errno> {
        self.with(|fs| fs.readdir(dir, cookie))
    }

    /// A descriptor or working directory now refers to `ino`.
    pub fn opened(&mut self, ino: u32) {
        *self.users.entry(ino).or_insert(0) += 1;
    }

    /// One fewer refers to it: at the last, an unlinked inode is freed.
    pub fn closed(&mut self, ino: u32) {
        let Some(count) = self.users.get_mut(&ino) else {
            return;
        };
        *count -= 1;
        if *count == 0 {
            self.users.remove(&ino);
            if self.orphans.remove(&ino) {
                // A failure leaves an unattached inode that e2fsck frees.
                let _ = self.with(|fs| fs.release(ino));
            }
        }
    }

    /// `fsync`, `fdatasync`, `syncfs`, `sync`: everything written back and flushed.
    pub fn sync(&mut self) -> Result<(), Errno> {
        if self.read_only {
            return Ok(());
        }
        self.with(|fs| fs.sync())
    }

    /// The `statfs` figures of the file system.
    pub fn statfs(&self) -> super::FsFigures {
        let s = self.fs.borrow().statfs();
        super::FsFigures {
            magic: EXT2_SUPER_MAGIC,
            block_size: s.block_size as u64,
            blocks: s.blocks,
            free_blocks: s.free_blocks,
            available_blocks: s.free_blocks.saturating_sub(s.reserved_blocks),
            files: s.inodes,
            free_files: s.free_inodes,
        }
    }

    /// The directory names from `dir` up to the root (its path within the file system,
    /// last component first); `ENOENT` for a file.
    pub fn path_parts(&self, dir: u32) -> Result<Vec<Vec<u8>>, Errno> {
        let mut parts = Vec::new();
        let mut at = dir;
        for _ in 0..super::PATH_MAX {
            if at == ext2::ROOT_INO {
                return Ok(parts);
            }
            if !self.is_dir(at) {
                return Err(Errno::ENOENT);
            }
            let up = self.lookup(at, b"..").ok_or(Errno::ENOENT)?;
            let mut cookie = 0;
            let name = loop {
                let Some((entry, next)) = self.readdir(up, cookie)? else {
                    return Err(Errno::ENOENT);
                };
                if entry.ino == at && entry.name != b"." && entry.name != b".." {
                    break entry.name;
                }
                cookie = next;
            };
            parts.push(name);
            at = up;
        }
        Err(Errno::ELOOP)
    }
}

/// `d_type` of a directory entry of its type.
pub fn dirent_type(t: ext2::FileType) -> u8 {
    use ext2::FileType::*;
    match t {
        Unknown => 0,
        Fifo => 1,
        CharDevice => 2,
        Directory => 4,
        BlockDevice => 6,
        Regular => 8,
        Symlink => 10,
        Socket => 12,
    }
}
