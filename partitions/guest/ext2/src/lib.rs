//! A Linux-compatible ext2 file system over any [`slots::BlockDevice`]: the Linux guest
//! mounts it at `/data` over a virtual disk. `no_std` with a heap; one caller at a time (the
//! guest's VFS wraps it and does path walks, permissions and open-file bookkeeping).
//!
//! # What is supported
//!
//! * Revision 0 and 1 file systems with 1024-, 2048- or 4096-byte blocks and inodes of 128
//!   bytes or more (a power of two up to the block size).
//! * Regular files with direct, single, double and triple indirect blocks, sparse holes
//!   (unallocated blocks read as zero), files over 2 GiB with `large_file`.
//! * Directories (linear; see `dir_index` below), fast (< 60 bytes, in the inode) and slow
//!   (one block) symbolic links, hard links, rename with Linux semantics.
//! * [`format`] makes a fresh revision 1 file system (1024- or 4096-byte blocks, 128- or
//!   256-byte inodes, `sparse_super`, `filetype`, `large_file`).
//!
//! # On-disk features
//!
//! Accepted: compat `ext_attr`, `resize_inode`, `dir_index`; incompat `filetype`; ro_compat
//! `sparse_super`, `large_file`. They stay set. Extended-attribute blocks are never created,
//! but the reference of a file that has one is dropped (and the block freed at the last
//! reference) when the file goes. The reserved GDT blocks of `resize_inode` are never touched.
//! A hashed (`dir_index`) directory is read linearly, which its on-disk layout allows (the
//! index blocks look like empty entries); adding or removing an entry clears the
//! directory's `EXT2_INDEX_FL`, so it stays a valid linear directory that e2fsck accepts
//! (e2fsck -D or Linux may index it again). Any other feature is refused at mount with
//! [`Error::Unsupported`] naming it, e.g. `incompat 0x0040 (extents)`.
//!
//! Every on-disk number used as an index or a length is range-checked first: a corrupt or
//! hostile image gives [`Error::Corrupt`], never a panic, an out-of-bounds access or an
//! endless loop (directory walks are bounded by the directory's size, which is bounded by
//! its allocated blocks; block maps by their depth of three; the walk up a directory tree
//! to refuse moving a directory into itself by 65536 steps; freeing a block twice is an
//! error, which ends a walk over a block map with loops). Allocation refuses to hand out a
//! block of the superblock, group descriptors, bitmaps or inode tables, whatever the
//! bitmap says. A corrupt image may still take long on a huge corrupt directory whose
//! block map points many times at the same valid block; it ends.
//!
//! # Writing back and crash ordering
//!
//! Blocks go through a small bounded write-back cache ([`CACHE_BLOCKS`] blocks). All dirty
//! blocks leave it through one function that first writes the file data and then the
//! metadata, ordered: indirect (block-map) blocks, superblock, group descriptors and bitmaps,
//! inode tables, directory blocks (a journal can later be placed in front of that
//! function); consecutive blocks of one kind go to the device as one run of sectors
//! ([`slots::BlockDevice::write_sectors`]), a block read as one too. This happens on
//! [`Ext2::sync`], [`Ext2::fsync`] (which syncs everything, as ext2 has no per-file
//! metadata tracking), [`Ext2::unmount`], and whenever the cache is
//! full of dirty blocks.
//!
//! * Mounting read-write clears `EXT2_VALID_FS` on disk at once (and flushes), so a cut
//!   leaves a file system that asks to be checked. `sync`/`unmount` write everything, flush,
//!   then set `EXT2_VALID_FS` again (if it was set at mount: a file system mounted unclean
//!   stays unclean until e2fsck checks it, as on Linux) and flush. The first change after a
//!   sync clears the flag on disk again before anything else is written.
//! * `fsync`: file data first, then the metadata (bitmaps, inode table, directory blocks),
//!   then `flush`.
//! * `rename`: the new directory entry is written (and flushed) before the old one is
//!   removed, when they lie in different blocks (in one block, both changes are a single
//!   block write). A cut in between leaves the file reachable under both names with a link
//!   count one too low; e2fsck fixes the count ("Inode N ref count is 1, should be 2"). A
//!   replaced target whose entry was already overwritten keeps its old link count: e2fsck
//!   lowers it, or moves the inode to `lost+found` if no name is left.
//! * Within one write-back pass, inodes go before directory blocks, so a new inode reaches
//!   the disk no later than its entry. Otherwise, as with Linux's ext2 without a journal, a
//!   cut between syncs may leave bitmap, free-count, link-count or unattached-inode
//!   differences that e2fsck repairs; the clear `EXT2_VALID_FS` makes sure it runs.
//!   [`Ext2::abandon`] leaves the disk as such a cut would (for tests).
//!
//! # Unlinked open files
//!
//! [`Ext2::unlink`], [`Ext2::rmdir`] and [`Ext2::rename`] (when it replaces a target) return
//! the inode number whose last link went. That inode stays readable and writable (an
//! "orphan") until the caller calls [`Ext2::release`] when the last open handle closes;
//! [`Ext2::unmount`] frees the orphans left. A cut before that leaves an inode with no link
//! that e2fsck frees (ext2 has no orphan list). A removed directory's blocks are freed at
//! once: it reads as empty.
//!
//! # Use
//!
//! [`Ext2::mount`] a device (or [`format`] it first), [`Ext2::set_now`] the time, then work
//! with inode numbers as Linux's VFS does: [`Ext2::lookup`] one name at a time from
//! [`ROOT_INO`], [`Ext2::readdir`] with cookies, [`Ext2::stat`], [`Ext2::read`] /
//! [`Ext2::write`] / [`Ext2::truncate`], [`Ext2::create`], [`Ext2::mkdir`],
//! [`Ext2::symlink`], [`Ext2::readlink`], [`Ext2::link`], [`Ext2::unlink`],
//! [`Ext2::rmdir`], [`Ext2::rename`], [`Ext2::set_times`], [`Ext2::chmod`],
//! [`Ext2::chown`], [`Ext2::statfs`]; [`Ext2::fsync`] / [`Ext2::sync`], and
//! [`Ext2::unmount`] to get the device back. Errors map to Linux errnos through
//! [`Error::errno`].
//!
//! # Limits
//!
//! * No journal, no extended attributes written, no access-time updates (like `noatime`),
//!   no device nodes, FIFOs or sockets created (existing ones are listed and stat'ed).
//! * Reserved blocks (`s_r_blocks_count`) are not held back: the caller is trusted like root.
//! * Timestamps come from the caller ([`Ext2::set_now`]); the crate has no clock.
//! * Ownership, permissions and inode flags (immutable, append-only) are stored, not
//!   enforced: that is the VFS's part. New files belong to 0:0 until [`Ext2::chown`].
//! * Largest file: 2 GiB - 1 without `large_file`; with it, what the block map and the
//!   32-bit `i_blocks` address (16 GiB at 1 KiB blocks, almost 2 TiB at 4 KiB).
//! * At most 32000 links per inode (as Linux ext2), names up to 255 bytes.

#![no_std]

extern crate alloc;

mod alloc_map;
mod blockmap;
mod bytes;
mod cache;
mod dir;
mod format;
mod fs;
mod inode;
mod layout;
mod namespace;

use alloc::string::String;
use alloc::vec::Vec;

pub use cache::CACHE_BLOCKS;
pub use format::{FormatOptions, format};
pub use fs::Ext2;

/// The inode number of the root directory.
pub const ROOT_INO: u32 = 2;
/// Longest name of a directory entry, in bytes.
pub const NAME_MAX: usize = 255;
/// Most links an inode may have (Linux ext2's `EXT2_LINK_MAX`).
pub const LINK_MAX: u16 = 32000;

/// File type bits of a mode.
pub const S_IFMT: u16 = 0o170000;
/// Regular file.
pub const S_IFREG: u16 = 0o100000;
/// Directory.
pub const S_IFDIR: u16 = 0o040000;
/// Symbolic link.
pub const S_IFLNK: u16 = 0o120000;

/// What can go wrong; [`Error::errno`] maps each onto a Linux errno.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Error {
    /// No such entry or inode (ENOENT).
    NotFound,
    /// The name exists already (EEXIST).
    Exists,
    /// A directory was needed (ENOTDIR).
    NotDir,
    /// A directory was not allowed (EISDIR).
    IsDir,
    /// The directory is not empty (ENOTEMPTY).
    NotEmpty,
    /// No free block or inode (ENOSPC).
    NoSpace,
    /// A name longer than [`NAME_MAX`] or a symlink target longer than a block
    /// (ENAMETOOLONG).
    NameTooLong,
    /// Beyond the largest file size (EFBIG).
    TooBig,
    /// An invalid argument: an empty name, a `/` or NUL in it, `.` or `..` where they cannot
    /// be changed, an inode of the wrong kind, a directory moved into itself (EINVAL).
    Invalid,
    /// Hard links to directories (EPERM).
    NotPermitted,
    /// More than [`LINK_MAX`] links (EMLINK).
    TooManyLinks,
    /// Mounted read-only (EROFS).
    ReadOnly,
    /// A feature this crate cannot handle; the text names it (EINVAL, as Linux's mount).
    Unsupported(String),
    /// The on-disk structure is inconsistent; the text says what (EUCLEAN, Linux's
    /// EFSCORRUPTED).
    Corrupt(&'static str),
    /// The device failed; its error, formatted (EIO).
    Io(String),
}

impl Error {
    /// The Linux errno for this error.
    pub fn errno(&self) -> i32 {
        match self {
            Error::NotFound => 2,
            Error::Io(_) => 5,
            Error::NotPermitted => 1,
            Error::Exists => 17,
            Error::NotDir => 20,
            Error::IsDir => 21,
            Error::Invalid | Error::Unsupported(_) => 22,
            Error::TooBig => 27,
            Error::NoSpace => 28,
            Error::ReadOnly => 30,
            Error::TooManyLinks => 31,
            Error::NameTooLong => 36,
            Error::NotEmpty => 39,
            Error::Corrupt(_) => 117,
        }
    }
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Error::Unsupported(what) => write!(f, "unsupported feature: {what}"),
            Error::Corrupt(what) => write!(f, "corrupt file system: {what}"),
            Error::Io(what) => write!(f, "device error: {what}"),
            other => write!(f, "{other:?} (errno {})", other.errno()),
        }
    }
}

/// An inode's attributes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stat {
    pub ino: u32,
    /// Type and permission bits.
    pub mode: u16,
    pub nlink: u16,
    pub uid: u32,
    pub gid: u32,
    pub size: u64,
    pub atime: u32,
    pub mtime: u32,
    pub ctime: u32,
    /// Allocated space in 512-byte units, indirect blocks included.
    pub blocks: u64,
}

/// The type of a directory entry's inode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum FileType {
    // The discriminants are the `file_type` codes of directory entries.
    Unknown = 0,
    Regular = 1,
    Directory = 2,
    CharDevice = 3,
    BlockDevice = 4,
    Fifo = 5,
    Socket = 6,
    Symlink = 7,
}

impl FileType {
    /// From the type bits of a mode.
    pub fn from_mode(mode: u16) -> FileType {
        match mode & S_IFMT {
            S_IFREG => FileType::Regular,
            S_IFDIR => FileType::Directory,
            0o020000 => FileType::CharDevice,
            0o060000 => FileType::BlockDevice,
            0o010000 => FileType::Fifo,
            0o140000 => FileType::Socket,
            S_IFLNK => FileType::Symlink,
            _ => FileType::Unknown,
        }
    }

    /// The `file_type` byte of a directory entry.
    pub(crate) fn code(self) -> u8 {
        self as u8
    }

    pub(crate) fn from_code(code: u8) -> FileType {
        match code {
            1 => FileType::Regular,
            2 => FileType::Directory,
            3 => FileType::CharDevice,
            4 => FileType::BlockDevice,
            5 => FileType::Fifo,
            6 => FileType::Socket,
            7 => FileType::Symlink,
            _ => FileType::Unknown,
        }
    }
}

/// Sizes and free space of the file system (for `statfs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FsStat {
    pub block_size: u32,
    pub blocks: u64,
    pub free_blocks: u64,
    /// Blocks Linux holds back for root (`s_r_blocks_count`; not enforced here).
    pub reserved_blocks: u64,
    pub inodes: u64,
    pub free_inodes: u64,
}

/// One entry of a directory, as [`Ext2::readdir`] returns it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DirEntry {
    pub name: Vec<u8>,
    pub ino: u32,
    /// From the entry with `filetype`, else [`FileType::Unknown`] (stat the inode).
    pub file_type: FileType,
}
