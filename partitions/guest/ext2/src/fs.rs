//! The mounted file system: mount, write-back, the inode table and the file operations
//! (stat, read, write, truncate, attributes). Namespace operations are in `namespace.rs`.

use alloc::boxed::Box;
use alloc::collections::BTreeSet;
use alloc::vec;
use alloc::vec::Vec;

use slots::BlockDevice;

use crate::bytes::{get16, get32, put16, put32};
use crate::cache::{Disk, Kind};
use crate::inode::Inode;
use crate::layout::{
    self, Geometry, Group, SB_FREE_BLOCKS, SB_FREE_INODES, SB_MNT_COUNT, SB_MTIME,
    SB_R_BLOCKS_COUNT, SB_STATE, SB_WTIME, STATE_VALID, SUPERBLOCK_LEN, SUPERBLOCK_OFFSET,
};
use crate::{Error, FsStat, Stat};

/// Most whole blocks one direct read of a file moves ([`Ext2::read`]).
const MAX_DIRECT_BLOCKS: usize = 64;

/// A mounted ext2 file system over the device `D`.
pub struct Ext2<D: BlockDevice> {
    pub(crate) disk: Disk<D>,
    pub(crate) geo: Geometry,
    /// The primary superblock as read, with the fields this crate keeps up to date.
    sb: Vec<u8>,
    /// The raw group descriptor table (all its blocks).
    gdt: Vec<u8>,
    pub(crate) groups: Vec<Group>,
    pub(crate) now: u32,
    read_only: bool,
    /// `EXT2_VALID_FS` was set at mount: sync may set it again.
    mounted_clean: bool,
    /// The superblock on disk says `EXT2_VALID_FS`; the next change clears it first.
    clean_on_disk: bool,
    mtime_written: bool,
    /// Inodes whose last link went but which the caller may still have open.
    orphans: BTreeSet<u32>,
}

impl<D: BlockDevice> core::fmt::Debug for Ext2<D> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Ext2")
            .field("block_size", &self.geo.block_size)
            .field("blocks", &self.geo.blocks_count)
            .field("groups", &self.geo.group_count)
            .field("read_only", &self.read_only)
            .field("orphans", &self.orphans.len())
            .finish_non_exhaustive()
    }
}

impl<D: BlockDevice> Ext2<D> {
    /// Mounts read-write: validates the superblock and group descriptors and marks the file
    /// system not clean on disk (flushed) until [`Ext2::sync`] or [`Ext2::unmount`].
    pub fn mount(dev: D) -> Result<Self, Error> {
        Self::mount_with(dev, false).map_err(|(error, _)| error)
    }

    /// Mounts read-only: nothing is ever written; every change gives [`Error::ReadOnly`].
    pub fn mount_read_only(dev: D) -> Result<Self, Error> {
        Self::mount_with(dev, true).map_err(|(error, _)| error)
    }

    /// [`Ext2::mount`] or [`Ext2::mount_read_only`]; a failure hands the device back with
    /// the error (a caller that owns one disk keeps it).
    pub fn mount_with(dev: D, read_only: bool) -> Result<Self, (Error, D)> {
        let mut disk = Disk::new(dev, 1024);
        let opened = Self::open(&mut disk);
        let (geo, sb, gdt, groups) = match opened {
            Ok(parts) => parts,
            Err(error) => return Err((error, disk.into_device())),
        };
        let mounted_clean = get16(&sb, SB_STATE) & STATE_VALID != 0;
        let mut fs = Ext2 {
            disk,
            geo,
            sb,
            gdt,
            groups,
            now: 0,
            read_only,
            mounted_clean,
            clean_on_disk: mounted_clean,
            mtime_written: false,
            orphans: BTreeSet::new(),
        };
        if read_only {
            return Ok(fs);
        }
        let count = get16(&fs.sb, SB_MNT_COUNT).wrapping_add(1);
        put16(&mut fs.sb, SB_MNT_COUNT, count);
        fs.clean_on_disk = true;
        match fs.begin_change() {
            Ok(()) => Ok(fs),
            Err(error) => Err((error, fs.abandon())),
        }
    }

    /// Reads and checks the superblock and the group descriptors.
    #[allow(clippy::type_complexity)] // the parts of a mounted file system, once
    fn open(disk: &mut Disk<D>) -> Result<(Geometry, Vec<u8>, Vec<u8>, Vec<Group>), Error> {
        let mut sb = vec![0u8; SUPERBLOCK_LEN];
        disk.read_sectors((SUPERBLOCK_OFFSET / 512) as u64, &mut sb)?;
        let geo = Geometry::parse(&sb)?;
        disk.set_block_size(geo.block_size as usize);
        // The device must hold the whole file system: its last sector must read.
        let last = u64::from(geo.blocks_count) * geo.block_sectors() - 1;
        disk.read_sectors(last, &mut [0u8; 512])
            .map_err(|_| Error::Corrupt("file system larger than the device"))?;
        let mut gdt = vec![0u8; (geo.gdt_blocks * geo.block_size) as usize];
        let first = disk.first_sector(geo.first_data_block + 1);
        disk.read_sectors(first, &mut gdt)?;
        let groups = layout::parse_groups(&geo, &gdt)?;
        Ok((geo, sb, gdt, groups))
    }

    /// Sets the time (seconds since the epoch) stamped on changed inodes and the superblock.
    pub fn set_now(&mut self, seconds: u32) {
        self.now = seconds;
    }

    /// Block size in bytes.
    pub fn block_size(&self) -> u32 {
        self.geo.block_size
    }

    /// Sizes and free space.
    pub fn statfs(&self) -> FsStat {
        let (free_blocks, free_inodes) = self.free_counts();
        FsStat {
            block_size: self.geo.block_size,
            blocks: u64::from(self.geo.blocks_count - self.geo.first_data_block),
            free_blocks,
            reserved_blocks: u64::from(get32(&self.sb, SB_R_BLOCKS_COUNT)),
            inodes: u64::from(self.geo.inodes_count),
            free_inodes,
        }
    }

    /// Free blocks and free inodes, summed from the group descriptors.
    pub(crate) fn free_counts(&self) -> (u64, u64) {
        let blocks = self.groups.iter().map(|g| u64::from(g.free_blocks)).sum();
        let inodes = self.groups.iter().map(|g| u64::from(g.free_inodes)).sum();
        (blocks, inodes)
    }

    /// Called before every change: refuses it when read-only, and clears `EXT2_VALID_FS` on
    /// disk (written and flushed) before the first change after a clean sync.
    pub(crate) fn begin_change(&mut self) -> Result<(), Error> {
        if self.read_only {
            return Err(Error::ReadOnly);
        }
        if self.clean_on_disk {
            let state = get16(&self.sb, SB_STATE) & !STATE_VALID;
            put16(&mut self.sb, SB_STATE, state);
            let block = self.store_superblock()?;
            self.disk.write_now(block)?;
            self.disk.flush()?;
            self.clean_on_disk = false;
        }
        Ok(())
    }

    /// Copies the superblock (free counts summed from the groups, times) into its cached
    /// block, marked dirty; returns that block.
    fn store_superblock(&mut self) -> Result<u32, Error> {
        let (free_blocks, free_inodes) = self.free_counts();
        put32(&mut self.sb, SB_FREE_BLOCKS, free_blocks as u32);
        put32(&mut self.sb, SB_FREE_INODES, free_inodes as u32);
        if self.now != 0 {
            put32(&mut self.sb, SB_WTIME, self.now);
            if !self.mtime_written {
                put32(&mut self.sb, SB_MTIME, self.now);
                self.mtime_written = true;
            }
        }
        // With 1 KiB blocks the superblock is block 1; otherwise bytes 1024.. of block 0.
        let block = (SUPERBLOCK_OFFSET as u32) / self.geo.block_size;
        let offset = SUPERBLOCK_OFFSET % self.geo.block_size as usize;
        let sb = &self.sb;
        self.disk.modify(block, Kind::Bitmap)?[offset..offset + SUPERBLOCK_LEN].copy_from_slice(sb);
        Ok(block)
    }

    fn store_group_descriptors(&mut self) -> Result<(), Error> {
        for (index, group) in self.groups.iter().enumerate() {
            layout::store_group(&mut self.gdt, index as u32, group);
        }
        let block_size = self.geo.block_size as usize;
        for i in 0..self.geo.gdt_blocks {
            let part = &self.gdt[i as usize * block_size..(i as usize + 1) * block_size];
            let block = self.geo.first_data_block + 1 + i;
            // Whole blocks from the table read at mount: nothing to read first.
            self.disk.zeroed(block, Kind::Bitmap)?.copy_from_slice(part);
        }
        Ok(())
    }

    /// Writes everything back (data, then metadata), flushes, then marks the file system
    /// clean (if it was at mount) and flushes again.
    pub fn sync(&mut self) -> Result<(), Error> {
        if self.read_only {
            return Ok(());
        }
        self.store_group_descriptors()?;
        self.store_superblock()?;
        self.disk.write_back()?;
        self.disk.flush()?;
        if self.mounted_clean && !self.clean_on_disk {
            let state = get16(&self.sb, SB_STATE) | STATE_VALID;
            put16(&mut self.sb, SB_STATE, state);
            let block = self.store_superblock()?;
            self.disk.write_now(block)?;
            self.disk.flush()?;
            self.clean_on_disk = true;
        }
        Ok(())
    }

    /// Makes `ino`'s data and metadata stable: its data blocks are written first, then the
    /// metadata, then the device is flushed. (Everything dirty is written: ext2 keeps no
    /// per-file list of metadata.)
    pub fn fsync(&mut self, ino: u32) -> Result<(), Error> {
        self.live_inode(ino)?;
        self.sync()
    }

    /// Frees the orphans left, writes everything back, marks the file system clean and
    /// hands the device back. On an error the file system comes back with it, to retry or
    /// [`Ext2::abandon`]. (Dropping an `Ext2` without this loses what is not yet written.)
    pub fn unmount(mut self) -> Result<D, (Error, Box<Self>)> {
        if let Err(error) = self.finish() {
            return Err((error, Box::new(self)));
        }
        Ok(self.disk.into_device())
    }

    fn finish(&mut self) -> Result<(), Error> {
        if self.read_only {
            return Ok(());
        }
        let orphans: Vec<u32> = self.orphans.iter().copied().collect();
        for ino in orphans {
            self.release(ino)?;
        }
        self.sync()
    }

    /// Hands the device back without writing anything more: the disk is left as a power
    /// cut at this moment would leave it (for crash tests, or after a fatal device error).
    pub fn abandon(self) -> D {
        self.disk.into_device()
    }

    /// Where inode `ino` lies: its inode-table block and the byte offset in it.
    fn inode_place(&self, ino: u32) -> Result<(u32, usize), Error> {
        if ino == 0 || ino > self.geo.inodes_count {
            return Err(Error::Invalid);
        }
        let group = &self.groups[self.geo.group_of_inode(ino) as usize];
        let index = (ino - 1) % self.geo.inodes_per_group;
        let byte = u64::from(index) * u64::from(self.geo.inode_size);
        let block = group.inode_table + (byte / u64::from(self.geo.block_size)) as u32;
        Ok((block, (byte % u64::from(self.geo.block_size)) as usize))
    }

    /// Reads inode `ino` (any state).
    pub(crate) fn load_inode(&mut self, ino: u32) -> Result<Inode, Error> {
        let (block, offset) = self.inode_place(ino)?;
        let size = self.geo.inode_size as usize;
        let raw = self.disk.read(block)?[offset..offset + size].to_vec();
        Ok(Inode { ino, raw })
    }

    pub(crate) fn store_inode(&mut self, inode: &Inode) -> Result<(), Error> {
        let (block, offset) = self.inode_place(inode.ino)?;
        let size = self.geo.inode_size as usize;
        self.disk.modify(block, Kind::InodeTable)?[offset..offset + size]
            .copy_from_slice(&inode.raw);
        Ok(())
    }

    /// Reads an inode that is in use: [`Error::NotFound`] for a free one.
    pub(crate) fn live_inode(&mut self, ino: u32) -> Result<Inode, Error> {
        let inode = self.load_inode(ino)?;
        if inode.mode() == 0 {
            return Err(Error::NotFound);
        }
        Ok(inode)
    }

    /// The attributes of `ino`.
    pub fn stat(&mut self, ino: u32) -> Result<Stat, Error> {
        let inode = self.live_inode(ino)?;
        Ok(Stat {
            ino,
            mode: inode.mode(),
            nlink: inode.links(),
            uid: inode.uid(),
            gid: inode.gid(),
            size: inode.size(),
            atime: inode.atime(),
            mtime: inode.mtime(),
            ctime: inode.ctime(),
            blocks: u64::from(inode.sectors()),
        })
    }

    /// Reads from a regular file at `offset`; returns the bytes read (0 at or after the
    /// end). Holes read as zero.
    pub fn read(&mut self, ino: u32, offset: u64, buf: &mut [u8]) -> Result<usize, Error> {
        let inode = self.live_inode(ino)?;
        regular(&inode)?;
        let size = inode.size();
        if offset >= size {
            return Ok(0);
        }
        let len = (buf.len() as u64).min(size - offset) as usize;
        let block_size = u64::from(self.geo.block_size);
        let mut done = 0;
        while done < len {
            let pos = offset + done as u64;
            let within = (pos % block_size) as usize;
            let chunk = (block_size as usize - within).min(len - done);
            let logical = pos / block_size;
            let mapped = self.map_block(&inode, logical)?;
            if let Some(first) = mapped
                && within == 0
                && chunk == block_size as usize
                && !self.disk.holds(first)
            {
                // Whole blocks on consecutive disk blocks that the cache does not hold go
                // straight from the disk into `buf`, as one run (a device may move several
                // sectors a request); the cache keeps what was read before.
                let most = ((len - done) / chunk).min(MAX_DIRECT_BLOCKS);
                let mut count = 1;
                while count < most {
                    let next = first.checked_add(count as u32);
                    if next.is_none()
                        || self.map_block(&inode, logical + count as u64)? != next
                        || next.is_some_and(|b| self.disk.holds(b))
                    {
                        break;
                    }
                    count += 1;
                }
                let bytes = count * chunk;
                let sector = self.disk.first_sector(first);
                self.disk
                    .read_sectors(sector, &mut buf[done..done + bytes])?;
                done += bytes;
                continue;
            }
            let out = &mut buf[done..done + chunk];
            match mapped {
                None => out.fill(0),
                Some(block) => out.copy_from_slice(&self.disk.read(block)?[within..within + chunk]),
            }
            done += chunk;
        }
        Ok(len)
    }

    /// Writes to a regular file at `offset`, allocating blocks (a gap before `offset`
    /// stays a hole). Returns the bytes written: fewer than `data.len()` when the disk
    /// fills or the file reaches its largest size after some bytes were written;
    /// [`Error::NoSpace`] / [`Error::TooBig`] when none could be.
    pub fn write(&mut self, ino: u32, offset: u64, data: &[u8]) -> Result<usize, Error> {
        self.begin_change()?;
        let mut inode = self.live_inode(ino)?;
        regular(&inode)?;
        if data.is_empty() {
            return Ok(0);
        }
        let max = self.geo.max_file_size();
        if offset >= max {
            return Err(Error::TooBig);
        }
        let len = (data.len() as u64).min(max - offset) as usize;
        let (written, error) = self.write_blocks(&mut inode, offset, &data[..len]);
        let end = offset + written as u64;
        if end > inode.size() {
            inode.set_size(end);
        }
        if written > 0 {
            inode.set_mtime(self.now);
            inode.set_ctime(self.now);
        }
        // Stored in every case: blocks allocated before an error are the inode's.
        self.store_inode(&inode)?;
        match error {
            Some(error) if written == 0 => Err(error),
            Some(Error::NoSpace) | None => Ok(written),
            Some(error) => Err(error),
        }
    }

    /// Copies `data` into the file's blocks from `offset`; returns the bytes written and
    /// the error that stopped it early.
    fn write_blocks(
        &mut self,
        inode: &mut Inode,
        offset: u64,
        data: &[u8],
    ) -> (usize, Option<Error>) {
        let block_size = u64::from(self.geo.block_size);
        let mut done = 0;
        while done < data.len() {
            let pos = offset + done as u64;
            let within = (pos % block_size) as usize;
            let chunk = (block_size as usize - within).min(data.len() - done);
            let block = match self.map_or_allocate(inode, pos / block_size) {
                Ok(block) => block,
                Err(error) => return (done, Some(error)),
            };
            // A whole block is overwritten without being read first.
            let buf = if chunk == block_size as usize {
                self.disk.zeroed(block, Kind::Data)
            } else {
                self.disk.modify(block, Kind::Data)
            };
            match buf {
                Ok(buf) => buf[within..within + chunk].copy_from_slice(&data[done..done + chunk]),
                Err(error) => return (done, Some(error)),
            }
            done += chunk;
        }
        (done, None)
    }

    /// Sets the size of a regular file: shrinking frees the blocks past the end and zeroes
    /// the rest of the last block; growing leaves a hole.
    pub fn truncate(&mut self, ino: u32, len: u64) -> Result<(), Error> {
        self.begin_change()?;
        let mut inode = self.live_inode(ino)?;
        regular(&inode)?;
        if len > self.geo.max_file_size() {
            return Err(Error::TooBig);
        }
        if len < inode.size() {
            let block_size = u64::from(self.geo.block_size);
            let result = self.free_blocks_from(&mut inode, len.div_ceil(block_size));
            if let Err(error) = result {
                self.store_inode(&inode)?;
                return Err(error);
            }
            let within = (len % block_size) as usize;
            if within != 0
                && let Some(block) = self.map_block(&inode, len / block_size)?
            {
                self.disk.modify(block, Kind::Data)?[within..].fill(0);
            }
        }
        inode.set_size(len);
        inode.set_mtime(self.now);
        inode.set_ctime(self.now);
        self.store_inode(&inode)
    }

    /// Sets the access and/or modification time; the change time becomes now.
    pub fn set_times(
        &mut self,
        ino: u32,
        atime: Option<u32>,
        mtime: Option<u32>,
    ) -> Result<(), Error> {
        self.begin_change()?;
        let mut inode = self.live_inode(ino)?;
        if let Some(t) = atime {
            inode.set_atime(t);
        }
        if let Some(t) = mtime {
            inode.set_mtime(t);
        }
        inode.set_ctime(self.now);
        self.store_inode(&inode)
    }

    /// Sets the permission bits (`mode & 0o7777`); the type stays.
    pub fn chmod(&mut self, ino: u32, mode: u16) -> Result<(), Error> {
        self.begin_change()?;
        let mut inode = self.live_inode(ino)?;
        inode.set_mode((inode.mode() & crate::S_IFMT) | (mode & 0o7777));
        inode.set_ctime(self.now);
        self.store_inode(&inode)
    }

    /// Sets the owner and/or group.
    pub fn chown(&mut self, ino: u32, uid: Option<u32>, gid: Option<u32>) -> Result<(), Error> {
        self.begin_change()?;
        let mut inode = self.live_inode(ino)?;
        if let Some(uid) = uid {
            inode.set_uid(uid);
        }
        if let Some(gid) = gid {
            inode.set_gid(gid);
        }
        inode.set_ctime(self.now);
        self.store_inode(&inode)
    }

    /// Frees `ino` if its last link went (an orphan from [`Ext2::unlink`], [`Ext2::rmdir`]
    /// or [`Ext2::rename`]): call it when the last open handle closes. A linked inode is
    /// left alone.
    pub fn release(&mut self, ino: u32) -> Result<(), Error> {
        self.begin_change()?;
        // The root and the reserved inodes are never freed.
        if ino == crate::ROOT_INO {
            return Ok(());
        }
        if ino < self.geo.first_ino {
            return Err(Error::Invalid);
        }
        let mut inode = self.load_inode(ino)?;
        if inode.mode() == 0 || inode.links() != 0 {
            self.orphans.remove(&ino);
            return Ok(());
        }
        // A fast symlink's i_block holds its target, not block numbers.
        if !self.is_fast_symlink(&inode) {
            self.free_blocks_from(&mut inode, 0)?;
        }
        self.drop_xattr_block(&mut inode)?;
        inode.set_size(0);
        inode.set_dtime(self.now.max(1));
        let is_dir = inode.is_dir();
        self.store_inode(&inode)?;
        self.free_inode(ino, is_dir)?;
        self.orphans.remove(&ino);
        Ok(())
    }

    /// Whether the inode is a symlink with its target in `i_block` (as Linux decides it: no
    /// block but an extended-attribute block).
    pub(crate) fn is_fast_symlink(&self, inode: &Inode) -> bool {
        let xattr_sectors = if inode.file_acl() != 0 {
            self.geo.block_size / 512
        } else {
            0
        };
        inode.is_symlink() && inode.sectors() == xattr_sectors
    }

    pub(crate) fn add_orphan(&mut self, ino: u32) {
        self.orphans.insert(ino);
    }

    /// Drops the inode's reference to its extended-attribute block, freeing the block at its
    /// last reference.
    fn drop_xattr_block(&mut self, inode: &mut Inode) -> Result<(), Error> {
        const XATTR_MAGIC: u32 = 0xEA02_0000;
        let block = inode.file_acl();
        if block == 0 {
            return Ok(());
        }
        self.check_data_block(block)?;
        let buf = self.disk.read(block)?;
        if get32(buf, 0) != XATTR_MAGIC {
            return Err(Error::Corrupt("extended attribute block"));
        }
        let refs = get32(buf, 4);
        if refs > 1 {
            put32(self.disk.modify(block, Kind::BlockMap)?, 4, refs - 1);
        } else {
            self.free_block(block)?;
        }
        inode.set_file_acl(0);
        let sectors = inode.sectors().saturating_sub(self.geo.block_size / 512);
        inode.set_sectors(sectors);
        Ok(())
    }
}

fn regular(inode: &Inode) -> Result<(), Error> {
    if inode.is_dir() {
        Err(Error::IsDir)
    } else if !inode.is_regular() {
        Err(Error::Invalid)
    } else {
        Ok(())
    }
}
