//! The on-disk inode: its fields, read and written in place in the raw bytes so that the
//! fields this crate does not use (and the extra space of large inodes) are kept.

use alloc::vec::Vec;

use crate::bytes::{get16, get32, put16, put32};
use crate::{S_IFDIR, S_IFLNK, S_IFMT, S_IFREG};

/// Direct block pointers; `i_block[12..15]` are the single, double and triple indirect ones.
pub(crate) const DIRECT_BLOCKS: usize = 12;
/// `i_flags`: the directory is hashed (`dir_index`).
pub(crate) const INDEX_FL: u32 = 0x1000;
/// Bytes of `i_block`, where a fast symlink keeps its target.
pub(crate) const FAST_SYMLINK_MAX: usize = 59;
pub(crate) const I_BLOCK: usize = 40;
/// Bytes of the classic inode; larger inodes have `i_extra_isize` next.
pub(crate) const GOOD_OLD_INODE_SIZE: usize = 128;

const I_MODE: usize = 0;
const I_UID: usize = 2;
const I_SIZE: usize = 4;
const I_ATIME: usize = 8;
const I_CTIME: usize = 12;
const I_MTIME: usize = 16;
const I_DTIME: usize = 20;
const I_GID: usize = 24;
const I_LINKS: usize = 26;
const I_BLOCKS: usize = 28;
const I_FLAGS: usize = 32;
const I_FILE_ACL: usize = 104;
const I_SIZE_HIGH: usize = 108;
const I_UID_HIGH: usize = 120;
const I_GID_HIGH: usize = 122;
const I_EXTRA_ISIZE: usize = 128;
const I_CTIME_EXTRA: usize = 132;
const I_MTIME_EXTRA: usize = 136;
const I_ATIME_EXTRA: usize = 140;
const I_CRTIME: usize = 144;

#[derive(Clone, Debug)]
pub(crate) struct Inode {
    pub ino: u32,
    pub raw: Vec<u8>,
}

impl Inode {
    pub(crate) fn mode(&self) -> u16 {
        get16(&self.raw, I_MODE)
    }
    pub(crate) fn set_mode(&mut self, mode: u16) {
        put16(&mut self.raw, I_MODE, mode);
    }
    pub(crate) fn is_dir(&self) -> bool {
        self.mode() & S_IFMT == S_IFDIR
    }
    pub(crate) fn is_regular(&self) -> bool {
        self.mode() & S_IFMT == S_IFREG
    }
    pub(crate) fn is_symlink(&self) -> bool {
        self.mode() & S_IFMT == S_IFLNK
    }
    pub(crate) fn uid(&self) -> u32 {
        u32::from(get16(&self.raw, I_UID)) | u32::from(get16(&self.raw, I_UID_HIGH)) << 16
    }
    pub(crate) fn set_uid(&mut self, uid: u32) {
        put16(&mut self.raw, I_UID, uid as u16);
        put16(&mut self.raw, I_UID_HIGH, (uid >> 16) as u16);
    }
    pub(crate) fn gid(&self) -> u32 {
        u32::from(get16(&self.raw, I_GID)) | u32::from(get16(&self.raw, I_GID_HIGH)) << 16
    }
    pub(crate) fn set_gid(&mut self, gid: u32) {
        put16(&mut self.raw, I_GID, gid as u16);
        put16(&mut self.raw, I_GID_HIGH, (gid >> 16) as u16);
    }
    /// The size; `i_size_high` counts for regular files only (for directories it is
    /// revision 0's `i_dir_acl`).
    pub(crate) fn size(&self) -> u64 {
        let low = u64::from(get32(&self.raw, I_SIZE));
        if self.is_regular() {
            low | u64::from(get32(&self.raw, I_SIZE_HIGH)) << 32
        } else {
            low
        }
    }
    pub(crate) fn set_size(&mut self, size: u64) {
        put32(&mut self.raw, I_SIZE, size as u32);
        if self.is_regular() {
            put32(&mut self.raw, I_SIZE_HIGH, (size >> 32) as u32);
        }
    }
    pub(crate) fn atime(&self) -> u32 {
        get32(&self.raw, I_ATIME)
    }
    pub(crate) fn ctime(&self) -> u32 {
        get32(&self.raw, I_CTIME)
    }
    pub(crate) fn mtime(&self) -> u32 {
        get32(&self.raw, I_MTIME)
    }
    pub(crate) fn set_atime(&mut self, t: u32) {
        put32(&mut self.raw, I_ATIME, t);
        self.clear_extra_time(I_ATIME_EXTRA);
    }
    pub(crate) fn set_ctime(&mut self, t: u32) {
        put32(&mut self.raw, I_CTIME, t);
        self.clear_extra_time(I_CTIME_EXTRA);
    }
    pub(crate) fn set_mtime(&mut self, t: u32) {
        put32(&mut self.raw, I_MTIME, t);
        self.clear_extra_time(I_MTIME_EXTRA);
    }

    /// A large inode may hold nanoseconds and epoch bits of a time beside it (if
    /// `i_extra_isize` covers them); a time set here has neither, so they are cleared
    /// rather than left to alter it.
    fn clear_extra_time(&mut self, offset: usize) {
        if self.raw.len() >= offset + 4 {
            let extra_end = GOOD_OLD_INODE_SIZE + usize::from(get16(&self.raw, I_EXTRA_ISIZE));
            if offset + 4 <= extra_end {
                put32(&mut self.raw, offset, 0);
            }
        }
    }
    pub(crate) fn set_dtime(&mut self, t: u32) {
        put32(&mut self.raw, I_DTIME, t);
    }
    pub(crate) fn links(&self) -> u16 {
        get16(&self.raw, I_LINKS)
    }
    pub(crate) fn set_links(&mut self, links: u16) {
        put16(&mut self.raw, I_LINKS, links);
    }
    /// `i_blocks`: 512-byte units.
    pub(crate) fn sectors(&self) -> u32 {
        get32(&self.raw, I_BLOCKS)
    }
    pub(crate) fn set_sectors(&mut self, sectors: u32) {
        put32(&mut self.raw, I_BLOCKS, sectors);
    }
    pub(crate) fn flags(&self) -> u32 {
        get32(&self.raw, I_FLAGS)
    }
    pub(crate) fn set_flags(&mut self, flags: u32) {
        put32(&mut self.raw, I_FLAGS, flags);
    }
    pub(crate) fn file_acl(&self) -> u32 {
        get32(&self.raw, I_FILE_ACL)
    }
    pub(crate) fn set_file_acl(&mut self, block: u32) {
        put32(&mut self.raw, I_FILE_ACL, block);
    }
    /// `i_block[index]`, `index < 15`.
    pub(crate) fn block(&self, index: usize) -> u32 {
        get32(&self.raw, I_BLOCK + 4 * index)
    }
    pub(crate) fn set_block(&mut self, index: usize, block: u32) {
        put32(&mut self.raw, I_BLOCK + 4 * index, block);
    }
    /// The 60 bytes of `i_block`.
    pub(crate) fn block_bytes(&self) -> &[u8] {
        &self.raw[I_BLOCK..I_BLOCK + 60]
    }
    pub(crate) fn block_bytes_mut(&mut self) -> &mut [u8] {
        &mut self.raw[I_BLOCK..I_BLOCK + 60]
    }

    /// A fresh inode: everything zero but the mode, one link and the times (and, in a
    /// large inode, `i_extra_isize` covering the extra time fields, as Linux writes it).
    pub(crate) fn new(ino: u32, inode_size: usize, mode: u16, now: u32) -> Inode {
        let mut inode = Inode {
            ino,
            raw: alloc::vec![0; inode_size],
        };
        inode.set_mode(mode);
        inode.set_links(1);
        inode.set_atime(now);
        inode.set_ctime(now);
        inode.set_mtime(now);
        if inode_size >= GOOD_OLD_INODE_SIZE + 32 {
            put16(&mut inode.raw, I_EXTRA_ISIZE, 32);
            put32(&mut inode.raw, I_CRTIME, now);
        }
        inode
    }
}
