//! The guest's file system: the initramfs's contents in a writable in-memory file system
//! (regular files, directories, symbolic links, hard links), the devices of `/dev`
//! ([`dev`]) and `/proc` ([`proc`], made from the process table when read), and the table
//! of open file descriptions the descriptors of every process point to.
//!
//! **Data.** A file of the initramfs keeps borrowing its bytes from the archive until it
//! is first written or truncated (busybox, 2 MB, is never copied); then they are copied
//! into memory of the guest's heap. Every byte the file system holds in the heap (file
//! capacity, names, link targets, a fixed cost per inode) counts against its byte limit:
//! beyond it, calls fail with `ENOSPC`, and a heap allocation of file data that fails gives
//! `ENOMEM` (file data grows with `try_reserve`), never an abort of the guest. The limit
//! is below the heap's size so the tables around the data fit too.
//!
//! **Inodes** are numbered by their slot; one lives while a directory entry names it, an
//! open file description refers to it or it is a working directory (an unlinked file stays
//! readable through open descriptors). Permission bits are kept and shown but not enforced: every process is
//! root. Timestamps are one: `mtime`, in seconds since the guest started.
//!
//! **Open file descriptions** ([`Open`]) carry the offset, flags and the node; descriptors
//! of one or several processes share one through `dup` and `fork` (reference counted, as
//! Linux shares them), so the offset moves for all of them.
//!
//! **Paths**: absolute or relative to a directory (the working directory, or a descriptor
//! of `*at` calls), `.` and `..`, symbolic links (at most [`MAX_LINKS`] in one lookup, as
//! Linux's `ELOOP` limit), components up to [`NAME_MAX`] bytes. This module never reads
//! process memory: the system calls copy the paths in ([`crate::syscall`]).

pub mod cpuinfo;
pub mod dev;
pub mod mounted;
pub mod proc;

use crate::cpio::{Archive, S_IFBLK, S_IFCHR, S_IFDIR, S_IFLNK, S_IFMT, S_IFREG};
use crate::linux::Errno;
use crate::process::File;
use alloc::boxed::Box;
use alloc::collections::BTreeMap;
use alloc::vec::Vec;
use dev::Device;
use mounted::Mount;
use proc::Procs;

/// Longest path (Linux's `PATH_MAX`).
pub const PATH_MAX: usize = 4096;
/// Longest name of a directory entry.
pub const NAME_MAX: usize = 255;
/// Most symbolic links followed in one lookup.
pub const MAX_LINKS: usize = 8;
/// Most open file descriptions of the guest (over all processes; `ENFILE` beyond): as
/// many as one process may have descriptors.
pub const MAX_OPEN: usize = crate::process::MAX_FILES;
/// Longest normalised path the guest keeps for an executable (`/proc/<pid>/exe`).
const MAX_PATH: usize = 256;
/// What an inode costs against the byte limit beside its data: its slot and its
/// directory entry.
const INODE_COST: usize = 96;
/// Most bytes a file's capacity grows by at once (doubling up to it: appending stays
/// linear without reserving much more than is written).
const MAX_GROWTH: usize = 1 << 20;
/// Largest file (Linux's `EFBIG` beyond).
pub const MAX_FILE: u64 = 1 << 32;

/// An inode number of the file system (its slot).
pub type Ino = u32;
/// The root directory.
pub const ROOT: Ino = 0;

/// A node a path names: an inode of the file system, a node of `/proc`, or an inode of
/// the file system mounted from the disk ([`mounted`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Node {
    Inode(Ino),
    Proc(proc::Node),
    Mounted(u32),
}

/// `st_dev` of the in-memory file system's files.
pub const MEMORY_DEV: u64 = 1;

/// A file's bytes: borrowed from the initramfs until first changed.
#[derive(Debug)]
enum Data<'a> {
    Borrowed(&'a [u8]),
    Owned(Vec<u8>),
}

impl Data<'_> {
    fn bytes(&self) -> &[u8] {
        match self {
            Data::Borrowed(b) => b,
            Data::Owned(v) => v,
        }
    }
    /// Bytes of the heap it holds.
    fn cost(&self) -> usize {
        match self {
            Data::Borrowed(_) => 0,
            Data::Owned(v) => v.capacity(),
        }
    }
}

#[derive(Debug)]
enum Body<'a> {
    File(Data<'a>),
    Dir {
        parent: Ino,
        entries: BTreeMap<Box<[u8]>, Ino>,
    },
    Symlink(Data<'a>),
    Device(Device),
}

#[derive(Debug)]
struct Inode<'a> {
    /// File type and permission bits.
    mode: u32,
    /// Directory entries naming it.
    nlink: u32,
    /// Open file descriptions referring to it.
    opened: u32,
    mtime: u64,
    body: Body<'a>,
}

/// Linux's `struct stat` fields the guest fills.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stat {
    /// The file system's device number ([`MEMORY_DEV`], [`mounted::DEV`]).
    pub dev: u64,
    pub ino: u64,
    pub nlink: u64,
    pub mode: u32,
    pub uid: u32,
    pub gid: u32,
    pub rdev: u64,
    pub size: u64,
    /// Space allocated, in 512-byte units.
    pub blocks: u64,
    pub mtime: u64,
}

impl Stat {
    /// The 144-byte `struct stat` (x86-64).
    pub fn to_bytes(&self) -> [u8; 144] {
        let mut b = [0u8; 144];
        b[0..8].copy_from_slice(&self.dev.to_le_bytes());
        b[8..16].copy_from_slice(&self.ino.to_le_bytes());
        b[16..24].copy_from_slice(&self.nlink.to_le_bytes());
        b[24..28].copy_from_slice(&self.mode.to_le_bytes());
        b[28..32].copy_from_slice(&self.uid.to_le_bytes());
        b[32..36].copy_from_slice(&self.gid.to_le_bytes());
        b[40..48].copy_from_slice(&self.rdev.to_le_bytes());
        b[48..56].copy_from_slice(&self.size.to_le_bytes());
        b[56..64].copy_from_slice(&4096u64.to_le_bytes()); // st_blksize
        b[64..72].copy_from_slice(&self.blocks.to_le_bytes());
        for at in [72, 88, 104] {
            b[at..at + 8].copy_from_slice(&self.mtime.to_le_bytes());
        }
        b
    }

    /// The 256-byte `struct statx` (every basic field valid).
    pub fn to_statx(&self) -> [u8; 256] {
        const STATX_BASIC_STATS: u32 = 0x7ff;
        let mut b = [0u8; 256];
        b[0..4].copy_from_slice(&STATX_BASIC_STATS.to_le_bytes());
        b[4..8].copy_from_slice(&4096u32.to_le_bytes()); // stx_blksize
        b[16..20].copy_from_slice(&(self.nlink as u32).to_le_bytes());
        b[20..24].copy_from_slice(&self.uid.to_le_bytes());
        b[24..28].copy_from_slice(&self.gid.to_le_bytes());
        b[28..30].copy_from_slice(&(self.mode as u16).to_le_bytes());
        b[32..40].copy_from_slice(&self.ino.to_le_bytes());
        b[40..48].copy_from_slice(&self.size.to_le_bytes());
        b[48..56].copy_from_slice(&self.blocks.to_le_bytes());
        for at in [64, 80, 96, 112] {
            // atime, btime, ctime, mtime: seconds (nanoseconds stay 0)
            b[at..at + 8].copy_from_slice(&self.mtime.to_le_bytes());
        }
        b[128..132].copy_from_slice(&((self.rdev >> 8) as u32).to_le_bytes());
        b[132..136].copy_from_slice(&((self.rdev & 0xff) as u32).to_le_bytes());
        b[136..140].copy_from_slice(&((self.dev >> 8) as u32).to_le_bytes());
        b[140..144].copy_from_slice(&((self.dev & 0xff) as u32).to_le_bytes());
        b
    }

    pub fn is_dir(&self) -> bool {
        self.mode & S_IFMT == S_IFDIR
    }
}

/// An open file description.
#[derive(Clone, Debug)]
pub struct Open {
    pub node: Node,
    pub offset: u64,
    /// The `open` flags it keeps (access mode, `O_APPEND`, `O_NONBLOCK`).
    pub flags: u64,
    refs: u32,
    /// A directory's position: the last name listed (entries removed or added meanwhile
    /// do not make it skip others).
    cursor: Option<Box<[u8]>>,
    /// A `/proc` file's contents, made when it was opened.
    pub snapshot: Option<Vec<u8>>,
}

/// An open file description's index ([`Fs::open`]).
pub type OpenId = usize;

/// A file system's `statfs` figures (`struct statfs`'s first fields, blocks counted in
/// `block_size`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FsFigures {
    /// `f_type`: the file system's magic number.
    pub magic: u64,
    pub block_size: u64,
    pub blocks: u64,
    pub free_blocks: u64,
    /// Free blocks an unprivileged process may use.
    pub available_blocks: u64,
    /// Inodes, and free inodes (0 where the file system has no fixed number).
    pub files: u64,
    pub free_files: u64,
}

/// What a node is, for a path walk ([`Fs::kind`]).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Dir,
    Symlink,
    Other,
}

/// The file system.
#[derive(Debug)]
pub struct Fs<'a> {
    inodes: Vec<Option<Inode<'a>>>,
    /// Free slots of `inodes`.
    free: Vec<Ino>,
    /// Heap bytes it holds, and the most it may.
    used: usize,
    limit: usize,
    /// The directory `/proc` stands on.
    proc_dir: Option<Ino>,
    opens: Vec<Option<Open>>,
    /// Bytes of the guest's memory (`/proc/meminfo`).
    memory: u64,
    /// The partition's ARINC ports, `/dev/arinc/<name>` ([`crate::arinc`]).
    ports: Vec<crate::arinc::Port>,
    /// `/dev/vda`'s disk ([`crate::disk`]), while it is not mounted.
    disk: Option<crate::disk::Volume>,
    /// The file system mounted from it.
    mount: Option<Mount>,
}

/// An entry of a mounted directory ([`Fs::mounted_entry`]).
pub struct MountedEntry {
    pub name: Vec<u8>,
    pub ino: u32,
    /// Its `d_type`.
    pub kind: u8,
    /// The cookie of the entry after it.
    pub next: u64,
}

/// A directory of one of the two file systems.
enum Dir {
    Memory(Ino),
    Mounted(u32),
}

/// What the removal of a directory entry removes.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Remove {
    /// A non-directory (`unlink`).
    File,
    /// An empty directory (`rmdir`).
    Dir,
}

impl<'a> Fs<'a> {
    /// The file system of `archive`'s contents (their data borrowed from it), holding at
    /// most `limit` heap bytes, with the devices in `/dev`, and `/proc`, `/tmp` and
    /// `/dev` created if the archive lacks them.
    pub fn new(archive: &Archive<'a>, limit: usize) -> Result<Self, Errno> {
        let mut fs = Fs {
            inodes: Vec::new(),
            free: Vec::new(),
            used: 0,
            limit,
            proc_dir: None,
            opens: Vec::new(),
            memory: 0,
            ports: Vec::new(),
            disk: None,
            mount: None,
        };
        fs.add(
            S_IFDIR | 0o755,
            Body::Dir {
                parent: ROOT,
                entries: BTreeMap::new(),
            },
            0,
        )?;
        for entry in archive.entries() {
            let path = entry.path();
            if path.is_empty() {
                if let Some(Some(root)) = fs.inodes.first_mut() {
                    root.mode = S_IFDIR | (entry.mode & 0o7777);
                }
                continue;
            }
            let (dir, name) = match path.rfind('/') {
                Some(at) => (fs.mkdir_all(&path[..at])?, &path[at + 1..]),
                None => (ROOT, path),
            };
            let name = name.as_bytes();
            let mtime = entry.mtime as u64;
            if fs.entry(dir, name).is_some() {
                continue; // a directory made for an earlier entry, or a repeated name
            }
            let body = match entry.file_type() {
                S_IFDIR => Body::Dir {
                    parent: dir,
                    entries: BTreeMap::new(),
                },
                S_IFLNK => Body::Symlink(Data::Borrowed(entry.data)),
                _ => Body::File(Data::Borrowed(entry.data)),
            };
            let mode = match entry.file_type() {
                S_IFDIR | S_IFLNK => entry.mode,
                _ => S_IFREG | (entry.mode & 0o7777),
            };
            let ino = fs.add(mode, body, mtime)?;
            fs.link_entry(dir, name, ino)?;
        }
        let dev = fs.mkdir_all("dev")?;
        for (name, device) in Device::ALL {
            if fs.entry(dev, name.as_bytes()).is_none() {
                let ino = fs.add(S_IFCHR | 0o666, Body::Device(device), 0)?;
                fs.link_entry(dev, name.as_bytes(), ino)?;
            }
        }
        if fs.entry(dev, b"fd").is_none() {
            // Bash's process substitution names `/dev/fd/<n>`.
            let target = Body::Symlink(Data::Borrowed(b"/proc/self/fd"));
            let ino = fs.add(S_IFLNK | 0o777, target, 0)?;
            fs.link_entry(dev, b"fd", ino)?;
        }
        fs.mkdir_all("tmp")?;
        fs.proc_dir = Some(fs.mkdir_all("proc")?);
        Ok(fs)
    }

    /// Gives the guest its ARINC ports: `/dev/arinc/<name>` for each (device
    /// [`Device::Port`] of its index in `ports`; names that exist already are skipped).
    pub fn set_ports(&mut self, ports: Vec<crate::arinc::Port>) -> Result<(), Errno> {
        if !ports.is_empty() {
            let dir = self.mkdir_all(crate::arinc::DEVICE_DIR)?;
            for (i, port) in ports.iter().enumerate() {
                let name = port.name.as_bytes();
                if self.entry(dir, name).is_none() {
                    let device = Body::Device(Device::Port(i as u16));
                    let ino = self.add(S_IFCHR | 0o666, device, 0)?;
                    self.link_entry(dir, name, ino)?;
                }
            }
        }
        self.ports = ports;
        Ok(())
    }

    /// Gives the guest its block device, `/dev/vda` ([`Device::Disk`], [`crate::disk`]).
    pub fn set_disk(&mut self, disk: Box<dyn crate::disk::BlockFile>) -> Result<(), Errno> {
        let dev = self.mkdir_all("dev")?;
        if self.entry(dev, b"vda").is_none() {
            let ino = self.add(S_IFBLK | 0o660, Body::Device(Device::Disk), 0)?;
            self.link_entry(dev, b"vda", ino)?;
        }
        self.disk = Some(crate::disk::Volume(disk));
        Ok(())
    }

    /// `/dev/vda`'s disk for reading and writing it as a file: `ENXIO` without one, `EBUSY`
    /// while a file system is mounted from it.
    pub fn disk(&mut self) -> Result<&mut dyn crate::disk::BlockFile, Errno> {
        match (&mut self.disk, &self.mount) {
            (Some(volume), _) => Ok(&mut *volume.0),
            (None, Some(_)) => Err(Errno::EBUSY),
            (None, None) => Err(Errno::ENXIO),
        }
    }

    /// `/dev/vda`'s size in bytes, mounted or not (`ENXIO` without a disk).
    pub fn disk_size(&self) -> Result<u64, Errno> {
        match (&self.disk, &self.mount) {
            (Some(volume), _) => Ok(volume.0.size()),
            (None, Some(m)) => Ok(m.disk_size()),
            (None, None) => Err(Errno::ENXIO),
        }
    }

    /// Mounts the disk's ext2 file system on directory `at` ([`mounted`]); the error says
    /// why a file system was refused (for the log).
    pub fn mount(
        &mut self,
        at: Node,
        read_only: bool,
        now: u64,
    ) -> Result<(), (Errno, Option<ext2::Error>)> {
        let Node::Inode(dir) = at else {
            // Only a directory of the in-memory file system takes a mount.
            return Err((Errno::EBUSY, None));
        };
        if !self.is_dir(at) {
            return Err((Errno::ENOTDIR, None));
        }
        if dir == ROOT || Some(dir) == self.proc_dir || self.mount.is_some() {
            return Err((Errno::EBUSY, None));
        }
        let path = self.path_of(at).map_err(|e| (e, None))?;
        let Some(volume) = self.disk.take() else {
            return Err((Errno::ENXIO, None));
        };
        match Mount::new(dir, path, volume, read_only, now) {
            Ok(mount) => {
                // The covered directory stays while the mount is on it.
                self.hold(at);
                self.mount = Some(mount);
                Ok(())
            }
            Err((error, volume)) => {
                self.disk = Some(volume);
                Err((mounted::errno(&error), Some(error)))
            }
        }
    }

    /// Unmounts the file system whose root is `at` (or the directory it covers): written
    /// back, marked clean, the disk free again. `EINVAL` if nothing is mounted there,
    /// `EBUSY` while a descriptor or working directory is on it.
    pub fn umount(&mut self, at: Node) -> Result<(), Errno> {
        let mount = self.mount.as_ref().ok_or(Errno::EINVAL)?;
        let root = Node::Mounted(ext2::ROOT_INO);
        if at != root && at != Node::Inode(mount.at) {
            return Err(Errno::EINVAL);
        }
        if mount.busy() {
            return Err(Errno::EBUSY);
        }
        let mount = self.mount.take().ok_or(Errno::EINVAL)?;
        let covered = Node::Inode(mount.at);
        match mount.unmount() {
            Ok(volume) => {
                self.disk = Some(volume);
                self.unhold(covered);
                Ok(())
            }
            Err((e, mount)) => {
                self.mount = Some(*mount);
                Err(e)
            }
        }
    }

    /// The mounted file system (`ENOENT` when a node of one that is gone is asked for).
    fn mounted(&self) -> Result<&Mount, Errno> {
        self.mount.as_ref().ok_or(Errno::ENOENT)
    }

    fn mounted_mut(&mut self) -> Result<&mut Mount, Errno> {
        self.mount.as_mut().ok_or(Errno::ENOENT)
    }

    /// The file system mounted from the disk, if any (`/proc/mounts`).
    pub fn mount_info(&self) -> Option<&Mount> {
        self.mount.as_ref()
    }

    /// `fsync` and `fdatasync` of `node`, `syncfs` and `sync` (`node: None`): the mounted
    /// file system's changes written back and flushed, or the raw disk flushed.
    pub fn sync(&mut self, node: Option<Node>) -> Result<(), Errno> {
        let disk = node.is_none() || node.is_some_and(|n| self.device(n) == Some(Device::Disk));
        let mounted = node.is_none() || matches!(node, Some(Node::Mounted(_)));
        if mounted && let Some(m) = &mut self.mount {
            m.sync()?;
        }
        if disk && let Some(v) = &mut self.disk {
            v.0.sync()?;
        }
        Ok(())
    }

    /// `statfs` of the file system `node` is on: the mounted one's figures, or `None` for
    /// the in-memory one.
    pub fn statfs(&self, node: Node) -> Option<FsFigures> {
        match node {
            Node::Mounted(_) => self.mount.as_ref().map(Mount::statfs),
            _ => None,
        }
    }

    /// Removes `/dev/arinc/<name>`: a port the guest itself uses (`/dev/vda`'s link), which
    /// no process may reach (the port stays in the table, its index unchanged).
    pub fn hide_port(&mut self, name: &str) {
        let Some(dir) = self
            .mkdir_all(crate::arinc::DEVICE_DIR)
            .ok()
            .filter(|_| self.ports.iter().any(|p| p.name == name))
        else {
            return;
        };
        if let Some(ino) = self.entry(dir, name.as_bytes())
            && self.device(Node::Inode(ino)).is_some()
        {
            self.unlink_entry(dir, name.as_bytes());
        }
    }

    /// The ARINC ports ([`Fs::set_ports`]).
    pub fn ports(&self) -> &[crate::arinc::Port] {
        &self.ports
    }

    /// The port `node` is a device of, with its index.
    pub fn port(&self, node: Node) -> Option<(usize, &crate::arinc::Port)> {
        match self.device(node)? {
            Device::Port(i) => self.ports.get(i as usize).map(|p| (i as usize, p)),
            _ => None,
        }
    }

    /// The guest's CPUs (bit n: CPU n) where the C libraries and `nproc --all` look:
    /// `/sys/devices/system/cpu/` with `online`, `possible` and `present` (Linux's list:
    /// `1-2`) and a directory `cpu<n>` for each. Plain read-only files of the in-memory
    /// file system, written once: the set never changes while the guest runs.
    pub fn set_cpus(&mut self, cpus: u64) -> Result<(), Errno> {
        use core::fmt::Write;
        let dir = self.mkdir_all("sys/devices/system/cpu")?;
        let mut list = alloc::string::String::new();
        let _ = proc::write_cpu_list(&mut list, cpus);
        list.push('\n');
        for name in ["online", "possible", "present"] {
            let node = match self.get(Node::Inode(dir), name.as_bytes()) {
                Some(node) => node,
                None => self.create(Node::Inode(dir), name.as_bytes(), 0o444, 0)?,
            };
            self.truncate(node, 0, 0)?;
            self.write(node, 0, list.as_bytes(), 0)?;
        }
        let mut path = alloc::string::String::new();
        for cpu in (0..64).filter(|&c| cpus >> c & 1 != 0) {
            path.clear();
            let _ = write!(path, "sys/devices/system/cpu/cpu{cpu}");
            self.mkdir_all(&path)?;
        }
        Ok(())
    }

    /// Records the guest's memory size (what `/proc/meminfo` shows as total).
    pub fn set_memory(&mut self, bytes: u64) {
        self.memory = bytes;
    }

    pub fn memory(&self) -> u64 {
        self.memory
    }

    /// Heap bytes in use, and the limit.
    pub fn usage(&self) -> (usize, usize) {
        (self.used, self.limit)
    }

    fn charge(&mut self, bytes: usize) -> Result<(), Errno> {
        let total = self.used.checked_add(bytes).ok_or(Errno::ENOSPC)?;
        if total > self.limit {
            return Err(Errno::ENOSPC);
        }
        self.used = total;
        Ok(())
    }

    fn refund(&mut self, bytes: usize) {
        self.used = self.used.saturating_sub(bytes);
    }

    fn add(&mut self, mode: u32, body: Body<'a>, mtime: u64) -> Result<Ino, Errno> {
        self.charge(INODE_COST)?;
        let inode = Inode {
            mode,
            nlink: 0,
            opened: 0,
            mtime,
            body,
        };
        if let Some(ino) = self.free.pop() {
            self.inodes[ino as usize] = Some(inode);
            return Ok(ino);
        }
        if self.inodes.try_reserve(1).is_err() {
            self.refund(INODE_COST);
            return Err(Errno::ENOMEM);
        }
        self.inodes.push(Some(inode));
        Ok((self.inodes.len() - 1) as Ino)
    }

    fn inode(&self, ino: Ino) -> Option<&Inode<'a>> {
        self.inodes.get(ino as usize)?.as_ref()
    }

    fn inode_mut(&mut self, ino: Ino) -> Option<&mut Inode<'a>> {
        self.inodes.get_mut(ino as usize)?.as_mut()
    }

    /// Directory `dir`'s entry `name`.
    fn entry(&self, dir: Ino, name: &[u8]) -> Option<Ino> {
        match &self.inode(dir)?.body {
            Body::Dir { entries, .. } => entries.get(name).copied(),
            _ => None,
        }
    }

    /// Adds entry `name` for `ino` to directory `dir` (which lacks it).
    fn link_entry(&mut self, dir: Ino, name: &[u8], ino: Ino) -> Result<(), Errno> {
        if name.len() > NAME_MAX {
            return Err(Errno::ENAMETOOLONG);
        }
        self.charge(name.len())?;
        let key: Box<[u8]> = name.into();
        match self.inode_mut(dir).map(|d| &mut d.body) {
            Some(Body::Dir { entries, .. }) => {
                entries.insert(key, ino);
            }
            _ => {
                self.refund(name.len());
                return Err(Errno::ENOTDIR);
            }
        }
        if let Some(i) = self.inode_mut(ino) {
            i.nlink += 1;
            if let Body::Dir { parent, .. } = &mut i.body {
                *parent = dir;
            }
        }
        Ok(())
    }

    /// Removes entry `name` of `dir` (one link less for its inode; freed when nothing
    /// refers to it any more).
    fn unlink_entry(&mut self, dir: Ino, name: &[u8]) {
        let removed = match self.inode_mut(dir).map(|d| &mut d.body) {
            Some(Body::Dir { entries, .. }) => entries.remove(name),
            _ => None,
        };
        if let Some(ino) = removed {
            self.refund(name.len());
            if let Some(i) = self.inode_mut(ino) {
                i.nlink = i.nlink.saturating_sub(1);
            }
            self.free_if_unused(ino);
        }
    }

    fn free_if_unused(&mut self, ino: Ino) {
        let unused = self
            .inode(ino)
            .is_some_and(|i| i.nlink == 0 && i.opened == 0);
        if unused && ino != ROOT {
            if let Some(inode) = self.inodes[ino as usize].take() {
                let data = match &inode.body {
                    Body::File(d) | Body::Symlink(d) => d.cost(),
                    _ => 0,
                };
                self.refund(INODE_COST + data);
            }
            self.free.push(ino);
        }
    }

    /// The directory at `path` (relative to the root, no links or `..`), made with its
    /// parents where missing.
    fn mkdir_all(&mut self, path: &str) -> Result<Ino, Errno> {
        let mut dir = ROOT;
        for part in path.split('/').filter(|p| !p.is_empty()) {
            dir = match self.entry(dir, part.as_bytes()) {
                Some(ino) => ino,
                None => {
                    let ino = self.add(
                        S_IFDIR | 0o755,
                        Body::Dir {
                            parent: dir,
                            entries: BTreeMap::new(),
                        },
                        0,
                    )?;
                    self.link_entry(dir, part.as_bytes(), ino)?;
                    ino
                }
            };
        }
        Ok(dir)
    }

    // ---- nodes ----

    pub fn is_dir(&self, node: Node) -> bool {
        match node {
            Node::Inode(ino) => self
                .inode(ino)
                .is_some_and(|i| matches!(i.body, Body::Dir { .. })),
            Node::Proc(n) => proc::is_dir(n),
            Node::Mounted(i) => self.mount.as_ref().is_some_and(|m| m.is_dir(i)),
        }
    }

    /// Whether `node` is a regular file (of either file system).
    pub fn is_file(&self, node: Node) -> bool {
        match node {
            Node::Mounted(i) => self.mount.as_ref().is_some_and(|m| m.is_file(i)),
            _ => self.file_bytes(node).is_some(),
        }
    }

    /// What `node` is, as far as a path walk needs to know: one look at a mounted inode
    /// where `is_dir` and `is_symlink` would take two.
    fn kind(&self, node: Node) -> Kind {
        let mounted = |i| self.mount.as_ref().map(|m| m.mode(i) & crate::cpio::S_IFMT);
        match node {
            Node::Mounted(i) => match mounted(i) {
                Some(crate::cpio::S_IFDIR) => Kind::Dir,
                Some(crate::cpio::S_IFLNK) => Kind::Symlink,
                _ => Kind::Other,
            },
            _ if self.is_dir(node) => Kind::Dir,
            _ if self.is_symlink(node) => Kind::Symlink,
            _ => Kind::Other,
        }
    }

    pub fn is_symlink(&self, node: Node) -> bool {
        match node {
            Node::Inode(ino) => self
                .inode(ino)
                .is_some_and(|i| matches!(i.body, Body::Symlink(_))),
            Node::Proc(n) => proc::is_link(n),
            Node::Mounted(i) => self.mount.as_ref().is_some_and(|m| m.is_symlink(i)),
        }
    }

    /// The device `node` is.
    pub fn device(&self, node: Node) -> Option<Device> {
        match self.inode(self.ino(node)?)?.body {
            Body::Device(d) => Some(d),
            _ => None,
        }
    }

    fn ino(&self, node: Node) -> Option<Ino> {
        match node {
            Node::Inode(ino) => Some(ino),
            Node::Proc(_) | Node::Mounted(_) => None,
        }
    }

    /// The inode of a regular file that still holds the initramfs's bytes (never written
    /// since the guest started): its contents are those of the archive's entry.
    pub fn archive_ino(&self, node: Node) -> Option<Ino> {
        let ino = self.ino(node)?;
        match &self.inode(ino)?.body {
            Body::File(Data::Borrowed(_)) => Some(ino),
            _ => None,
        }
    }

    /// A regular file's bytes (`None`: not a regular file of the file system).
    pub fn file_bytes(&self, node: Node) -> Option<&[u8]> {
        match &self.inode(self.ino(node)?)?.body {
            Body::File(d) => Some(d.bytes()),
            _ => None,
        }
    }

    /// Its `st_mode`: file type and permission bits.
    pub fn mode(&self, node: Node) -> u32 {
        self.stat(node).mode
    }

    pub fn stat(&self, node: Node) -> Stat {
        let ino = match node {
            Node::Inode(ino) => ino,
            Node::Proc(n) => return proc::stat(n),
            Node::Mounted(i) => {
                return self.mount.as_ref().map(|m| m.stat(i)).unwrap_or_default();
            }
        };
        let Some(i) = self.inode(ino) else {
            return Stat::default();
        };
        let (size, nlink, rdev) = match &i.body {
            Body::File(d) | Body::Symlink(d) => (d.bytes().len() as u64, i.nlink, 0),
            Body::Dir { entries, .. } => {
                let subdirs = entries
                    .values()
                    .filter(|&&c| self.is_dir(Node::Inode(c)))
                    .count();
                (4096, 2 + subdirs as u32, 0)
            }
            Body::Device(d) => (0, i.nlink, d.rdev()),
        };
        Stat {
            dev: MEMORY_DEV,
            ino: ino as u64 + 1,
            nlink: nlink as u64,
            mode: i.mode,
            uid: 0,
            gid: 0,
            rdev,
            size,
            blocks: size.div_ceil(512),
            mtime: i.mtime,
        }
    }

    fn node_of(&self, ino: Ino) -> Node {
        if Some(ino) == self.proc_dir {
            Node::Proc(proc::Node::Root)
        } else if self.mount.as_ref().is_some_and(|m| m.at == ino) {
            Node::Mounted(ext2::ROOT_INO)
        } else {
            Node::Inode(ino)
        }
    }

    /// The directory above `node` (the root's is the root).
    pub fn parent(&self, node: Node) -> Node {
        match node {
            Node::Inode(ino) => match self.inode(ino).map(|i| &i.body) {
                Some(Body::Dir { parent, .. }) => self.node_of(*parent),
                _ => Node::Inode(ROOT),
            },
            Node::Proc(n) => match proc::parent(n) {
                Some(up) => Node::Proc(up),
                None => self.parent(Node::Inode(self.proc_dir.unwrap_or(ROOT))),
            },
            Node::Mounted(i) => match &self.mount {
                // Out of the mounted file system at its root.
                Some(m) if i == ext2::ROOT_INO => self.parent(Node::Inode(m.at)),
                Some(m) => m.lookup(i, b"..").map_or(Node::Inode(ROOT), Node::Mounted),
                None => Node::Inode(ROOT),
            },
        }
    }

    // ---- lookup ----

    /// Looks `path` up from directory `start`; `follow_last` follows a symbolic link in
    /// the last component (`stat` does, `lstat` and `readlink` do not).
    pub fn lookup(
        &self,
        procs: &Procs,
        start: Node,
        path: &[u8],
        follow_last: bool,
    ) -> Result<Node, Errno> {
        if path.is_empty() {
            return Err(Errno::ENOENT);
        }
        if path.len() >= PATH_MAX {
            return Err(Errno::ENAMETOOLONG);
        }
        let mut links = 0;
        self.walk(procs, start, path, follow_last, &mut links)
    }

    fn walk(
        &self,
        procs: &Procs,
        base: Node,
        path: &[u8],
        follow_last: bool,
        links: &mut usize,
    ) -> Result<Node, Errno> {
        let mut at = if path.first() == Some(&b'/') {
            Node::Inode(ROOT)
        } else {
            base
        };
        let trailing_slash = path.last() == Some(&b'/');
        let mut parts = path
            .split(|&b| b == b'/')
            .filter(|p| !p.is_empty())
            .peekable();
        // What `at` is, looked at once per node (a mounted node's is an inode read).
        let mut at_kind = self.kind(at);
        while let Some(part) = parts.next() {
            if at_kind != Kind::Dir {
                return Err(Errno::ENOTDIR);
            }
            if part.len() > NAME_MAX {
                return Err(Errno::ENAMETOOLONG);
            }
            let next = match part {
                b"." => continue,
                b".." => {
                    at = self.parent(at);
                    at_kind = Kind::Dir;
                    continue;
                }
                _ => self.child(procs, at, part).ok_or(Errno::ENOENT)?,
            };
            let last = parts.peek().is_none();
            if let Node::Proc(proc::Node::Fd(pid, fd)) = next
                && (!last || follow_last || trailing_slash)
            {
                // A magic link: to the descriptor's file itself (even unlinked); a pipe
                // or the console is no directory, and only `open` can follow to it.
                at = match proc::fd_file(procs, pid, fd) {
                    Some(File::Open(id)) => self.description(id).ok_or(Errno::ENOENT)?.node,
                    Some(_) if last => next,
                    Some(_) => return Err(Errno::ENOTDIR),
                    None => return Err(Errno::ENOENT),
                };
                at_kind = self.kind(at);
                continue;
            }
            let next_kind = self.kind(next);
            if next_kind == Kind::Symlink && (!last || follow_last || trailing_slash) {
                *links += 1;
                if *links > MAX_LINKS {
                    return Err(Errno::ELOOP);
                }
                let mut buf = [0u8; 280];
                let target = self.link_target(procs, next, &mut buf)?;
                at = self.walk(procs, at, target, true, links)?;
                at_kind = self.kind(at);
            } else {
                (at, at_kind) = (next, next_kind);
            }
        }
        if trailing_slash && at_kind != Kind::Dir {
            return Err(Errno::ENOTDIR);
        }
        Ok(at)
    }

    fn child(&self, procs: &Procs, dir: Node, name: &[u8]) -> Option<Node> {
        match dir {
            Node::Inode(ino) => self.entry(ino, name).map(|c| self.node_of(c)),
            Node::Proc(n) => proc::child(n, name, procs).map(Node::Proc),
            Node::Mounted(i) => self.mount.as_ref()?.lookup(i, name).map(Node::Mounted),
        }
    }

    /// A symbolic link's target (`EINVAL`: not a link).
    pub fn link_target<'b>(
        &'b self,
        procs: &Procs,
        node: Node,
        buf: &'b mut [u8; 280],
    ) -> Result<&'b [u8], Errno> {
        match node {
            Node::Inode(ino) => match self.inode(ino).map(|i| &i.body) {
                Some(Body::Symlink(d)) => Ok(d.bytes()),
                _ => Err(Errno::EINVAL),
            },
            Node::Proc(proc::Node::Fd(pid, fd)) => match proc::fd_file(procs, pid, fd) {
                Some(File::Open(id)) => {
                    let node = self.description(id).ok_or(Errno::ENOENT)?.node;
                    let path = self.path_of(node)?;
                    let len = (path.as_str().len() + 1).min(buf.len());
                    buf[0] = b'/';
                    buf[1..len].copy_from_slice(&path.as_str().as_bytes()[..len - 1]);
                    Ok(&buf[..len])
                }
                _ => proc::link(proc::Node::Fd(pid, fd), procs, buf).ok_or(Errno::ENOENT),
            },
            Node::Proc(n) if proc::is_link(n) => proc::link(n, procs, buf).ok_or(Errno::ENOENT),
            Node::Proc(_) => Err(Errno::EINVAL),
            Node::Mounted(i) if self.is_symlink(node) => self.mounted()?.readlink(i, buf),
            Node::Mounted(_) => Err(Errno::EINVAL),
        }
    }

    /// The directory that is to hold `path`'s last component, and that name (for calls
    /// that create or remove an entry). `.` and `..` as the last name are `EINVAL`; in
    /// `/proc` nothing can be created (`EACCES`).
    pub fn lookup_parent<'p>(
        &self,
        procs: &Procs,
        start: Node,
        path: &'p [u8],
    ) -> Result<(Node, &'p [u8]), Errno> {
        if path.len() >= PATH_MAX {
            return Err(Errno::ENAMETOOLONG);
        }
        let end = path
            .iter()
            .rposition(|&b| b != b'/')
            .ok_or(if path.is_empty() {
                Errno::ENOENT
            } else {
                Errno::EBUSY // the root itself
            })?;
        let path = &path[..=end];
        let (dir_path, name): (&[u8], &[u8]) = match path.iter().rposition(|&b| b == b'/') {
            Some(at) => (&path[..=at], &path[at + 1..]),
            None => (b".", path),
        };
        if name == b"." || name == b".." {
            return Err(Errno::EINVAL);
        }
        if name.len() > NAME_MAX {
            return Err(Errno::ENAMETOOLONG);
        }
        match self.lookup(procs, start, dir_path, true)? {
            Node::Proc(_) => Err(Errno::EACCES),
            dir if self.is_dir(dir) => Ok((dir, name)),
            _ => Err(Errno::ENOTDIR),
        }
    }

    /// The node entry `name` of `dir` names (links not followed).
    pub fn get(&self, dir: Node, name: &[u8]) -> Option<Node> {
        match dir {
            Node::Inode(d) => self.entry(d, name).map(|c| self.node_of(c)),
            Node::Mounted(d) => self.mount.as_ref()?.lookup(d, name).map(Node::Mounted),
            Node::Proc(_) => None,
        }
    }

    /// `node`'s absolute path (`ENOENT` for an unlinked node; `ENAMETOOLONG` past
    /// [`MAX_PATH`] bytes). A file linked more than once has one of its paths.
    pub fn path_of(&self, node: Node) -> Result<PathBuf, Errno> {
        if let Node::Mounted(i) = node {
            let m = self.mounted()?;
            let mut out = self.path_of(Node::Inode(m.at))?;
            for part in m.path_parts(i)?.iter().rev() {
                out.push(part)?;
            }
            return Ok(out);
        }
        let mut parts: Vec<&[u8]> = Vec::new();
        let mut proc_tail = [0u8; 32];
        let mut tail_len = 0;
        let mut at = match node {
            Node::Proc(n) => {
                let mut w = SliceWriter {
                    buf: &mut proc_tail,
                    len: 0,
                };
                match n {
                    proc::Node::Root => {}
                    proc::Node::Process(pid) => {
                        let _ = core::fmt::Write::write_fmt(&mut w, format_args!("{pid}"));
                    }
                    proc::Node::Fds(pid) => {
                        let _ = core::fmt::Write::write_fmt(&mut w, format_args!("{pid}/fd"));
                    }
                    _ => return Err(Errno::ENOENT), // only directories are asked for
                }
                tail_len = w.len;
                self.proc_dir.ok_or(Errno::ENOENT)?
            }
            Node::Inode(ino) => ino,
            Node::Mounted(_) => return Err(Errno::ENOENT), // handled above
        };
        let mut file_name: Option<&[u8]> = None;
        if !self.is_dir(Node::Inode(at)) {
            // A file has no parent of its own: the first directory that names it.
            let (dir, name) = self
                .inodes
                .iter()
                .enumerate()
                .find_map(|(d, i)| match i.as_ref().map(|i| &i.body) {
                    Some(Body::Dir { entries, .. }) => entries
                        .iter()
                        .find(|(_, c)| **c == at)
                        .map(|(n, _)| (d as Ino, &**n)),
                    _ => None,
                })
                .ok_or(Errno::ENOENT)?;
            file_name = Some(name);
            at = dir;
        }
        let mut steps = 0;
        while at != ROOT {
            let Some(Body::Dir { parent, .. }) = self.inode(at).map(|i| &i.body) else {
                return Err(Errno::ENOENT);
            };
            let name = match &self.inode(*parent).map(|i| &i.body) {
                Some(Body::Dir { entries, .. }) => entries
                    .iter()
                    .find(|(_, c)| **c == at)
                    .map(|(n, _)| &**n)
                    .ok_or(Errno::ENOENT)?,
                _ => return Err(Errno::ENOENT),
            };
            parts.push(name);
            at = *parent;
            steps += 1;
            if steps > PATH_MAX {
                return Err(Errno::ELOOP);
            }
        }
        let mut out = PathBuf::root();
        for part in parts.iter().rev() {
            out.push(part)?;
        }
        if tail_len > 0 {
            out.push(&proc_tail[..tail_len])?;
        }
        if let Some(name) = file_name {
            out.push(name)?;
        }
        Ok(out)
    }

    // ---- changes ----

    /// Which file system directory `dir` is in (`EACCES` in `/proc`).
    fn directory(dir: Node) -> Result<Dir, Errno> {
        match dir {
            Node::Inode(d) => Ok(Dir::Memory(d)),
            Node::Mounted(d) => Ok(Dir::Mounted(d)),
            Node::Proc(_) => Err(Errno::EACCES),
        }
    }

    /// Creates a regular file `name` in `dir` with permission bits `mode`.
    pub fn create(&mut self, dir: Node, name: &[u8], mode: u32, now: u64) -> Result<Node, Errno> {
        let dir = match Self::directory(dir)? {
            Dir::Memory(d) => d,
            Dir::Mounted(d) => {
                return self
                    .mounted_mut()?
                    .create(d, name, mode & 0o7777, now)
                    .map(Node::Mounted);
            }
        };
        self.new_entry(
            dir,
            name,
            S_IFREG | (mode & 0o7777),
            Body::File(Data::Owned(Vec::new())),
            now,
        )
        .map(Node::Inode)
    }

    pub fn mkdir(&mut self, dir: Node, name: &[u8], mode: u32, now: u64) -> Result<Node, Errno> {
        let dir = match Self::directory(dir)? {
            Dir::Memory(d) => d,
            Dir::Mounted(d) => {
                return self
                    .mounted_mut()?
                    .mkdir(d, name, mode & 0o7777, now)
                    .map(Node::Mounted);
            }
        };
        self.new_entry(
            dir,
            name,
            S_IFDIR | (mode & 0o7777),
            Body::Dir {
                parent: dir,
                entries: BTreeMap::new(),
            },
            now,
        )
        .map(Node::Inode)
    }

    pub fn symlink(
        &mut self,
        dir: Node,
        name: &[u8],
        target: &[u8],
        now: u64,
    ) -> Result<Node, Errno> {
        if target.is_empty() {
            return Err(Errno::ENOENT);
        }
        if target.len() >= PATH_MAX {
            return Err(Errno::ENAMETOOLONG);
        }
        let dir = match Self::directory(dir)? {
            Dir::Memory(d) => d,
            Dir::Mounted(d) => {
                return self
                    .mounted_mut()?
                    .symlink(d, name, target, now)
                    .map(Node::Mounted);
            }
        };
        self.charge(target.len())?;
        let mut data = Vec::new();
        if data.try_reserve_exact(target.len()).is_err() {
            self.refund(target.len());
            return Err(Errno::ENOMEM);
        }
        data.extend_from_slice(target);
        let extra = data.capacity() - target.len();
        self.used += extra;
        let made = self.new_entry(
            dir,
            name,
            S_IFLNK | 0o777,
            Body::Symlink(Data::Owned(data)),
            now,
        );
        if made.is_err() {
            self.refund(target.len() + extra);
        }
        made.map(Node::Inode)
    }

    fn new_entry(
        &mut self,
        dir: Ino,
        name: &[u8],
        mode: u32,
        body: Body<'a>,
        now: u64,
    ) -> Result<Ino, Errno> {
        if !self.is_dir(Node::Inode(dir)) {
            return Err(Errno::ENOTDIR);
        }
        // The root has no entry naming it (no link), and is never removed.
        if dir != ROOT && self.inode(dir).is_some_and(|d| d.nlink == 0) {
            return Err(Errno::ENOENT); // removed, still someone's working directory
        }
        if self.entry(dir, name).is_some() {
            return Err(Errno::EEXIST);
        }
        let ino = self.add(mode, body, now)?;
        if let Err(e) = self.link_entry(dir, name, ino) {
            self.free_if_unused(ino);
            return Err(e);
        }
        self.touch(dir, now);
        Ok(ino)
    }

    fn touch(&mut self, ino: Ino, now: u64) {
        if let Some(i) = self.inode_mut(ino) {
            i.mtime = now;
        }
    }

    /// Another entry `name` in `dir` for the non-directory `node` (`link`).
    pub fn link(&mut self, node: Node, dir: Node, name: &[u8], now: u64) -> Result<(), Errno> {
        let dir = match (Self::directory(dir)?, node) {
            (Dir::Memory(d), _) => d,
            (Dir::Mounted(d), Node::Mounted(i)) => {
                return self.mounted_mut()?.link(i, d, name, now);
            }
            (Dir::Mounted(_), _) => return Err(Errno::EXDEV),
        };
        let ino = self.ino(node).ok_or(Errno::EXDEV)?;
        if self.is_dir(node) {
            return Err(Errno::EPERM);
        }
        if self.entry(dir, name).is_some() {
            return Err(Errno::EEXIST);
        }
        self.link_entry(dir, name, ino)?;
        self.touch(dir, now);
        Ok(())
    }

    /// Removes entry `name` of `dir`: a non-directory or an empty directory, as `what`
    /// says.
    pub fn remove(&mut self, dir: Node, name: &[u8], what: Remove, now: u64) -> Result<(), Errno> {
        let dir = match Self::directory(dir)? {
            Dir::Memory(d) => d,
            Dir::Mounted(d) => {
                return self
                    .mounted_mut()?
                    .remove(d, name, what == Remove::Dir, now);
            }
        };
        let ino = self.entry(dir, name).ok_or(Errno::ENOENT)?;
        let is_dir = self.is_dir(Node::Inode(ino));
        match what {
            Remove::File if is_dir => return Err(Errno::EISDIR),
            Remove::Dir if !is_dir => return Err(Errno::ENOTDIR),
            Remove::Dir => {
                if self.covered(ino) {
                    return Err(Errno::EBUSY);
                }
                if let Some(Body::Dir { entries, .. }) = self.inode(ino).map(|i| &i.body)
                    && !entries.is_empty()
                {
                    return Err(Errno::ENOTEMPTY);
                }
            }
            Remove::File => {}
        }
        self.unlink_entry(dir, name);
        self.touch(dir, now);
        Ok(())
    }

    /// Renames entry `from` of `from_dir` to `to` of `to_dir`, replacing what `to` named
    /// (a non-directory by a non-directory, an empty directory by a directory) unless
    /// `no_replace`.
    pub fn rename(
        &mut self,
        from_dir: Node,
        from: &[u8],
        to_dir: Node,
        to: &[u8],
        no_replace: bool,
        now: u64,
    ) -> Result<(), Errno> {
        let (from_dir, to_dir) = match (Self::directory(from_dir)?, Self::directory(to_dir)?) {
            (Dir::Memory(a), Dir::Memory(b)) => (a, b),
            (Dir::Mounted(a), Dir::Mounted(b)) => {
                return self.mounted_mut()?.rename(a, from, b, to, no_replace, now);
            }
            _ => return Err(Errno::EXDEV),
        };
        let ino = self.entry(from_dir, from).ok_or(Errno::ENOENT)?;
        if !self.is_dir(Node::Inode(to_dir)) {
            return Err(Errno::ENOTDIR);
        }
        let moving_dir = self.is_dir(Node::Inode(ino));
        if self.covered(ino) {
            return Err(Errno::EBUSY);
        }
        if moving_dir {
            // Not into itself or below it.
            let mut at = to_dir;
            for _ in 0..self.inodes.len() {
                if at == ino {
                    return Err(Errno::EINVAL);
                }
                if at == ROOT {
                    break;
                }
                at = match self.inode(at).map(|i| &i.body) {
                    Some(Body::Dir { parent, .. }) => *parent,
                    _ => ROOT,
                };
            }
        }
        if let Some(old) = self.entry(to_dir, to) {
            if old == ino {
                return Ok(()); // the same file: nothing to do
            }
            if no_replace {
                return Err(Errno::EEXIST);
            }
            let old_is_dir = self.is_dir(Node::Inode(old));
            let to_node = Node::Inode(to_dir);
            match (moving_dir, old_is_dir) {
                (true, false) => return Err(Errno::ENOTDIR),
                (false, true) => return Err(Errno::EISDIR),
                (true, true) => self.remove(to_node, to, Remove::Dir, now)?,
                (false, false) => self.remove(to_node, to, Remove::File, now)?,
            }
        }
        // The new entry first (it may fail for the limit), then the old one goes.
        self.link_entry(to_dir, to, ino)?;
        if let Some(i) = self.inode_mut(ino) {
            i.nlink += 1; // held while the old entry goes
        }
        self.unlink_entry(from_dir, from);
        if let Some(i) = self.inode_mut(ino) {
            i.nlink -= 1;
            if let Body::Dir { parent, .. } = &mut i.body {
                *parent = to_dir;
            }
        }
        self.touch(from_dir, now);
        self.touch(to_dir, now);
        Ok(())
    }

    /// Whether in-memory directory `ino` stands under something else (`/proc`, a
    /// mount): it cannot be removed or renamed.
    fn covered(&self, ino: Ino) -> bool {
        Some(ino) == self.proc_dir || self.mount.as_ref().is_some_and(|m| m.at == ino)
    }

    /// Sets the permission bits.
    pub fn chmod(&mut self, node: Node, mode: u32, now: u64) -> Result<(), Errno> {
        if let Node::Mounted(i) = node {
            return self.mounted_mut()?.chmod(i, mode, now);
        }
        let ino = self.ino(node).ok_or(Errno::EPERM)?;
        let i = self.inode_mut(ino).ok_or(Errno::ENOENT)?;
        i.mode = (i.mode & S_IFMT) | (mode & 0o7777);
        Ok(())
    }

    pub fn set_mtime(&mut self, node: Node, mtime: u64, now: u64) -> Result<(), Errno> {
        if let Node::Mounted(i) = node {
            return self.mounted_mut()?.set_mtime(i, mtime, now);
        }
        if let Some(ino) = self.ino(node) {
            self.touch(ino, mtime);
        }
        Ok(())
    }

    /// The file's data as owned bytes (copied from the initramfs on the first change).
    fn owned(&mut self, ino: Ino) -> Result<&mut Vec<u8>, Errno> {
        let borrowed = match self.inode(ino).map(|i| &i.body) {
            Some(Body::File(Data::Borrowed(b))) => Some(*b),
            Some(Body::File(Data::Owned(_))) => None,
            Some(Body::Dir { .. }) => return Err(Errno::EISDIR),
            _ => return Err(Errno::EINVAL),
        };
        if let Some(bytes) = borrowed {
            self.charge(bytes.len())?;
            let mut v = Vec::new();
            if v.try_reserve_exact(bytes.len()).is_err() {
                self.refund(bytes.len());
                return Err(Errno::ENOMEM);
            }
            v.extend_from_slice(bytes);
            self.used += v.capacity() - bytes.len();
            if let Some(i) = self.inode_mut(ino) {
                i.body = Body::File(Data::Owned(v));
            }
        }
        match self.inode_mut(ino).map(|i| &mut i.body) {
            Some(Body::File(Data::Owned(v))) => Ok(v),
            _ => Err(Errno::EINVAL),
        }
    }

    /// Makes room for `len` bytes in file `ino` (growing its capacity, counted against the
    /// limit).
    fn reserve(&mut self, ino: Ino, len: usize) -> Result<(), Errno> {
        let capacity = self.owned(ino)?.capacity();
        if len <= capacity {
            return Ok(());
        }
        let wanted = len.max(capacity + capacity.min(MAX_GROWTH)).max(64);
        // Within the limit: the doubling if it fits, else exactly what is needed.
        let room = self.limit.saturating_sub(self.used);
        let target = if wanted - capacity <= room {
            wanted
        } else if len - capacity <= room {
            len
        } else {
            return Err(Errno::ENOSPC);
        };
        let v = self.owned(ino)?;
        v.try_reserve_exact(target - v.len())
            .map_err(|_| Errno::ENOMEM)?;
        let grown = v.capacity() - capacity;
        self.used += grown;
        Ok(())
    }

    /// Writes `data` at `offset` of regular file `node` (a hole before it reads zeros);
    /// returns how many bytes.
    pub fn write(
        &mut self,
        node: Node,
        offset: u64,
        data: &[u8],
        now: u64,
    ) -> Result<usize, Errno> {
        if let Node::Mounted(i) = node {
            return self.mounted_mut()?.write(i, offset, data, now);
        }
        let ino = self.ino(node).ok_or(Errno::EINVAL)?;
        let end = offset
            .checked_add(data.len() as u64)
            .filter(|&e| e <= MAX_FILE)
            .ok_or(Errno::EFBIG)?;
        if data.is_empty() {
            return Ok(0);
        }
        self.reserve(ino, end as usize)?;
        let v = self.owned(ino)?;
        let at = offset as usize;
        if v.len() < at {
            v.resize(at, 0);
        }
        let overlap = (v.len() - at).min(data.len());
        v[at..at + overlap].copy_from_slice(&data[..overlap]);
        v.extend_from_slice(&data[overlap..]);
        self.touch(ino, now);
        Ok(data.len())
    }

    /// Sets regular file `node`'s length (cut, or zeros added).
    pub fn truncate(&mut self, node: Node, len: u64, now: u64) -> Result<(), Errno> {
        if let Node::Mounted(i) = node {
            return self.mounted_mut()?.truncate(i, len, now);
        }
        let ino = self.ino(node).ok_or(Errno::EINVAL)?;
        if len > MAX_FILE {
            return Err(Errno::EFBIG);
        }
        let len = len as usize;
        if self.file_bytes(node).is_some_and(|b| b.len() == len) {
            return Ok(());
        }
        if len == 0 {
            // Drop the data at once (`O_TRUNC`, the most common case).
            let cost = match self.inode(ino).map(|i| &i.body) {
                Some(Body::File(d)) => d.cost(),
                Some(Body::Dir { .. }) => return Err(Errno::EISDIR),
                _ => return Err(Errno::EINVAL),
            };
            self.refund(cost);
            if let Some(i) = self.inode_mut(ino) {
                i.body = Body::File(Data::Owned(Vec::new()));
                i.mtime = now;
            }
            return Ok(());
        }
        self.reserve(ino, len)?;
        let v = self.owned(ino)?;
        v.resize(len, 0);
        self.touch(ino, now);
        Ok(())
    }

    /// Reads mounted file `node` at `offset` (in-memory files are read from
    /// [`Fs::file_bytes`]).
    pub fn read_mounted(&self, node: Node, offset: u64, buf: &mut [u8]) -> Result<usize, Errno> {
        match node {
            Node::Mounted(i) => self.mounted()?.read(i, offset, buf),
            _ => Err(Errno::EINVAL),
        }
    }

    /// Mounted directory `dir`'s entry at or after `cookie` (`.` and `..` as stored).
    pub fn mounted_entry(&self, dir: Node, cookie: u64) -> Result<Option<MountedEntry>, Errno> {
        let Node::Mounted(d) = dir else {
            return Err(Errno::ENOTDIR);
        };
        Ok(self
            .mounted()?
            .readdir(d, cookie)?
            .map(|(e, next)| MountedEntry {
                kind: mounted::dirent_type(e.file_type),
                ino: e.ino,
                name: e.name,
                next,
            }))
    }

    /// Directory `dir`'s first entry after `after` (in name order; `None`: from the start).
    pub fn next_entry(&self, dir: Ino, after: Option<&[u8]>) -> Option<(&[u8], Node)> {
        let Some(Body::Dir { entries, .. }) = self.inode(dir).map(|i| &i.body) else {
            return None;
        };
        let mut range = match after {
            None => entries.range::<[u8], _>(..),
            Some(name) => entries.range::<[u8], _>((
                core::ops::Bound::Excluded(name),
                core::ops::Bound::Unbounded,
            )),
        };
        range.next().map(|(n, &c)| (&**n, self.node_of(c)))
    }

    // ---- open file descriptions ----

    /// A new open file description of `node` with `flags` (its only reference).
    pub fn open(
        &mut self,
        node: Node,
        flags: u64,
        snapshot: Option<Vec<u8>>,
    ) -> Result<OpenId, Errno> {
        let description = Open {
            node,
            offset: 0,
            flags,
            refs: 1,
            cursor: None,
            snapshot,
        };
        let id = match self.opens.iter().position(Option::is_none) {
            Some(id) => id,
            None if self.opens.len() < MAX_OPEN => {
                self.opens.try_reserve(1).map_err(|_| Errno::ENOMEM)?;
                self.opens.push(None);
                self.opens.len() - 1
            }
            None => return Err(Errno::ENFILE),
        };
        self.opens[id] = Some(description);
        self.hold(node);
        Ok(id)
    }

    pub fn description(&self, id: OpenId) -> Option<&Open> {
        self.opens.get(id)?.as_ref()
    }

    pub fn description_mut(&mut self, id: OpenId) -> Option<&mut Open> {
        self.opens.get_mut(id)?.as_mut()
    }

    /// One more descriptor refers to description `id` (`dup`, `fork`).
    pub fn share(&mut self, id: OpenId) {
        if let Some(o) = self.description_mut(id) {
            o.refs += 1;
        }
    }

    /// One descriptor less refers to description `id`; the last one closes it.
    pub fn release(&mut self, id: OpenId) {
        let Some(o) = self.description_mut(id) else {
            return;
        };
        o.refs -= 1;
        if o.refs > 0 {
            return;
        }
        let node = o.node;
        self.opens[id] = None;
        if let (Node::Mounted(i), Some(m)) = (node, &mut self.mount) {
            m.closed(i);
        }
        if let Some(ino) = self.ino(node) {
            if let Some(i) = self.inode_mut(ino) {
                i.opened = i.opened.saturating_sub(1);
            }
            self.free_if_unused(ino);
        }
    }

    /// `node` is in use beyond its directory entries (a working directory): it lives while
    /// held, as while open.
    pub fn hold(&mut self, node: Node) {
        if let (Node::Mounted(i), Some(m)) = (node, &mut self.mount) {
            m.opened(i);
        }
        if let Some(i) = self.ino(node).and_then(|ino| self.inode_mut(ino)) {
            i.opened += 1;
        }
    }

    /// The end of a [`Fs::hold`].
    pub fn unhold(&mut self, node: Node) {
        if let (Node::Mounted(i), Some(m)) = (node, &mut self.mount) {
            m.closed(i);
        }
        if let Some(ino) = self.ino(node) {
            if let Some(i) = self.inode_mut(ino) {
                i.opened = i.opened.saturating_sub(1);
            }
            self.free_if_unused(ino);
        }
    }

    /// How many open file descriptions exist.
    pub fn open_count(&self) -> usize {
        self.opens.iter().flatten().count()
    }

    /// Directory description `id`'s position: the last name it listed.
    pub fn cursor(&self, id: OpenId) -> Option<&[u8]> {
        self.description(id)?.cursor.as_deref()
    }

    /// Sets it (`None`: from the start again; the offset restarts too).
    pub fn set_cursor(&mut self, id: OpenId, name: Option<&[u8]>) -> Result<(), Errno> {
        let cursor = match name {
            Some(n) => {
                let mut v = Vec::new();
                v.try_reserve_exact(n.len()).map_err(|_| Errno::ENOMEM)?;
                v.extend_from_slice(n);
                Some(v.into_boxed_slice())
            }
            None => None,
        };
        if let Some(o) = self.description_mut(id) {
            o.cursor = cursor;
        }
        Ok(())
    }
}

/// Formats into a byte buffer (an error when it is full).
pub(crate) struct SliceWriter<'b> {
    pub buf: &'b mut [u8],
    pub len: usize,
}

impl core::fmt::Write for SliceWriter<'_> {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let end = self.len + s.len();
        if end > self.buf.len() {
            return Err(core::fmt::Error);
        }
        self.buf[self.len..end].copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

/// A normalised absolute path without the leading `/` (`"bin/sh"`; `""` is the root).
#[derive(Clone, Copy)]
pub struct PathBuf {
    bytes: [u8; MAX_PATH],
    len: usize,
}

impl core::fmt::Debug for PathBuf {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "/{}", self.as_str())
    }
}

impl PathBuf {
    pub const fn root() -> Self {
        Self {
            bytes: [0; MAX_PATH],
            len: 0,
        }
    }
    pub fn as_str(&self) -> &str {
        core::str::from_utf8(&self.bytes[..self.len]).unwrap_or("")
    }
    fn push(&mut self, part: &[u8]) -> Result<(), Errno> {
        let extra = part.len() + usize::from(self.len > 0);
        if self.len + extra > MAX_PATH {
            return Err(Errno::ENAMETOOLONG);
        }
        if self.len > 0 {
            self.bytes[self.len] = b'/';
            self.len += 1;
        }
        self.bytes[self.len..self.len + part.len()].copy_from_slice(part);
        self.len += part.len();
        Ok(())
    }
}

#[cfg(test)]
mod tests;
