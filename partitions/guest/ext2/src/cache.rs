//! The device below the file system: sector I/O and a small, bounded write-back cache of
//! blocks. Every dirty block leaves through [`Disk::write_back`] (file data first, then
//! the metadata in [`Kind`] order), the one place a journal would go later.

use alloc::collections::BTreeMap;
use alloc::format;
use alloc::vec;
use alloc::vec::Vec;

use slots::{BlockDevice, SECTOR};

use crate::Error;

/// Blocks the cache holds at most.
pub const CACHE_BLOCKS: usize = 64;

/// What a cached block holds; dirty metadata is written back in this order, after the file
/// data, so that what a block points to reaches the disk before the pointer (as far as one
/// pass can order it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Kind {
    /// File contents and slow-symlink targets.
    Data,
    /// Indirect blocks of a block map.
    BlockMap,
    /// Superblock, group descriptors, block and inode bitmaps.
    Bitmap,
    /// Inode tables.
    InodeTable,
    /// Directory blocks.
    Directory,
}

struct Entry {
    data: Vec<u8>,
    dirty: bool,
    kind: Kind,
    last_use: u64,
}

/// Most bytes one write-back run moves.
const MAX_RUN_BYTES: usize = 64 * 1024;

pub(crate) struct Disk<D> {
    dev: D,
    block_size: usize,
    entries: BTreeMap<u32, Entry>,
    /// Counts accesses, for least-recently-used eviction.
    clock: u64,
    capacity: usize,
}

pub(crate) fn device_error<E: core::fmt::Debug>(error: E) -> Error {
    Error::Io(format!("{error:?}"))
}

impl<D: BlockDevice> Disk<D> {
    pub(crate) fn new(dev: D, block_size: usize) -> Self {
        Disk {
            dev,
            block_size,
            entries: BTreeMap::new(),
            clock: 0,
            capacity: CACHE_BLOCKS,
        }
    }

    /// Only while the cache is empty (at mount, once the superblock is read).
    pub(crate) fn set_block_size(&mut self, block_size: usize) {
        debug_assert!(self.entries.is_empty());
        self.block_size = block_size;
    }

    pub(crate) fn into_device(self) -> D {
        self.dev
    }

    /// Reads sectors from `first` into `out` (a multiple of [`SECTOR`] bytes, or less for
    /// the last one), bypassing the cache.
    pub(crate) fn read_sectors(&mut self, first: u64, out: &mut [u8]) -> Result<(), Error> {
        // The whole sectors as one run (a device may move several a request), then the
        // part of the last one.
        let whole = out.len() / SECTOR * SECTOR;
        self.dev
            .read_sectors(first, &mut out[..whole])
            .map_err(device_error)?;
        if whole < out.len() {
            let mut sector = [0u8; SECTOR];
            self.dev
                .read(first + (whole / SECTOR) as u64, &mut sector)
                .map_err(device_error)?;
            let rest = out.len() - whole;
            out[whole..].copy_from_slice(&sector[..rest]);
        }
        Ok(())
    }

    /// Writes `data` (a multiple of [`SECTOR`] bytes) from sector `first`, bypassing the
    /// cache (the formatter and the write-back use it).
    pub(crate) fn write_sectors(&mut self, first: u64, data: &[u8]) -> Result<(), Error> {
        let whole = data.len() / SECTOR * SECTOR;
        self.dev
            .write_sectors(first, &data[..whole])
            .map_err(device_error)?;
        if whole < data.len() {
            // A last partial sector: zero-padded.
            let mut sector = [0u8; SECTOR];
            sector[..data.len() - whole].copy_from_slice(&data[whole..]);
            self.dev
                .write(first + (whole / SECTOR) as u64, &sector)
                .map_err(device_error)?;
        }
        Ok(())
    }

    pub(crate) fn flush(&mut self) -> Result<(), Error> {
        self.dev.flush().map_err(device_error)
    }

    pub(crate) fn first_sector(&self, block: u32) -> u64 {
        u64::from(block) * (self.block_size / SECTOR) as u64
    }

    /// The cached entry of `block`, read from the disk if `load` (else zero-filled).
    fn entry(&mut self, block: u32, load: bool) -> Result<&mut Entry, Error> {
        self.clock += 1;
        if !self.entries.contains_key(&block) {
            self.make_room()?;
            let mut data = vec![0u8; self.block_size];
            if load {
                let first = self.first_sector(block);
                self.read_sectors(first, &mut data)?;
            }
            self.entries.insert(
                block,
                Entry {
                    data,
                    dirty: false,
                    kind: Kind::Data,
                    last_use: 0,
                },
            );
        }
        let clock = self.clock;
        let entry = self
            .entries
            .get_mut(&block)
            .ok_or(Error::Corrupt("block cache"))?;
        entry.last_use = clock;
        Ok(entry)
    }

    /// Drops the least recently used clean block when the cache is full, writing every
    /// dirty block back first when none is clean.
    fn make_room(&mut self) -> Result<(), Error> {
        if self.entries.len() < self.capacity {
            return Ok(());
        }
        if self.entries.values().all(|e| e.dirty) {
            self.write_back()?;
        }
        let victim = self
            .entries
            .iter()
            .filter(|(_, e)| !e.dirty)
            .min_by_key(|(_, e)| e.last_use)
            .map(|(block, _)| *block);
        if let Some(block) = victim {
            self.entries.remove(&block);
        }
        Ok(())
    }

    /// Whether `block` is in the cache (its contents there may be newer than the disk's).
    pub(crate) fn holds(&self, block: u32) -> bool {
        self.entries.contains_key(&block)
    }

    /// The contents of `block`.
    pub(crate) fn read(&mut self, block: u32) -> Result<&[u8], Error> {
        Ok(&self.entry(block, true)?.data)
    }

    /// The contents of `block`, to change; it is written back as `kind`.
    pub(crate) fn modify(&mut self, block: u32, kind: Kind) -> Result<&mut [u8], Error> {
        let entry = self.entry(block, true)?;
        entry.dirty = true;
        entry.kind = kind;
        Ok(&mut entry.data)
    }

    /// `block` zero-filled without reading it (a newly allocated block), to fill.
    pub(crate) fn zeroed(&mut self, block: u32, kind: Kind) -> Result<&mut [u8], Error> {
        let entry = self.entry(block, false)?;
        entry.data.fill(0);
        entry.dirty = true;
        entry.kind = kind;
        Ok(&mut entry.data)
    }

    /// Forgets a freed block, so that stale contents are never written.
    pub(crate) fn forget(&mut self, block: u32) {
        self.entries.remove(&block);
    }

    /// Writes every dirty block: file data first, then [`Disk::write_back_metadata`]. No
    /// flush: the callers decide where the barriers go.
    pub(crate) fn write_back(&mut self) -> Result<(), Error> {
        self.write_dirty(|kind| kind == Kind::Data)?;
        self.write_back_metadata()
    }

    /// Writes every dirty metadata block, in [`Kind`] order and block order within a kind.
    /// All metadata leaves through here: the place for a journal.
    pub(crate) fn write_back_metadata(&mut self) -> Result<(), Error> {
        self.write_dirty(|kind| kind != Kind::Data)
    }

    fn write_dirty(&mut self, which: impl Fn(Kind) -> bool) -> Result<(), Error> {
        let mut dirty: Vec<(Kind, u32)> = self
            .entries
            .iter()
            .filter(|(_, e)| e.dirty && which(e.kind))
            .map(|(block, e)| (e.kind, *block))
            .collect();
        dirty.sort_unstable();
        // Runs of consecutive blocks of one kind leave in one call (a device may move
        // several sectors a request); the order stays that of `dirty`.
        let mut at = 0;
        while at < dirty.len() {
            let (kind, first) = dirty[at];
            let most = (MAX_RUN_BYTES / self.block_size).max(1);
            let mut len = 1;
            while at + len < dirty.len()
                && len < most
                && dirty[at + len] == (kind, first + len as u32)
            {
                len += 1;
            }
            if len == 1 {
                self.write_now(first)?;
            } else {
                self.write_run(first, len)?;
            }
            at += len;
        }
        Ok(())
    }

    /// Writes the `len` dirty cached blocks from `first` on as one run.
    fn write_run(&mut self, first: u32, len: usize) -> Result<(), Error> {
        let mut run = Vec::new();
        run.try_reserve_exact(len * self.block_size)
            .map_err(|_| Error::Io("no memory for a write-back run".into()))?;
        for block in first..first + len as u32 {
            match self.entries.get(&block) {
                Some(entry) => run.extend_from_slice(&entry.data),
                None => return Err(Error::Corrupt("a dirty block left the cache")),
            }
        }
        self.write_sectors(self.first_sector(first), &run)?;
        for block in first..first + len as u32 {
            if let Some(entry) = self.entries.get_mut(&block) {
                entry.dirty = false;
            }
        }
        Ok(())
    }

    /// Writes `block` now if it is dirty.
    pub(crate) fn write_now(&mut self, block: u32) -> Result<(), Error> {
        let first = self.first_sector(block);
        let Some(entry) = self.entries.get_mut(&block) else {
            return Ok(());
        };
        if !entry.dirty {
            return Ok(());
        }
        entry.dirty = false;
        let data = core::mem::take(&mut entry.data);
        let result = self.write_sectors(first, &data);
        if let Some(entry) = self.entries.get_mut(&block) {
            entry.data = data;
            if result.is_err() {
                entry.dirty = true;
            }
        }
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A disk in memory that records the order of block writes.
    struct Recorder {
        data: Vec<u8>,
        writes: Vec<u64>,
        /// (first sector, sectors) of each `write_sectors`.
        runs: Vec<(u64, usize)>,
    }

    impl BlockDevice for Recorder {
        type Error = ();
        fn read(&mut self, sector: u64, buf: &mut [u8; SECTOR]) -> Result<(), ()> {
            let at = sector as usize * SECTOR;
            buf.copy_from_slice(self.data.get(at..at + SECTOR).ok_or(())?);
            Ok(())
        }
        fn write(&mut self, sector: u64, data: &[u8; SECTOR]) -> Result<(), ()> {
            let at = sector as usize * SECTOR;
            self.data
                .get_mut(at..at + SECTOR)
                .ok_or(())?
                .copy_from_slice(data);
            self.writes.push(sector);
            Ok(())
        }
        fn flush(&mut self) -> Result<(), ()> {
            Ok(())
        }
        fn write_sectors(&mut self, first: u64, data: &[u8]) -> Result<(), ()> {
            self.runs.push((first, data.len() / SECTOR));
            for (i, sector) in data.as_chunks::<SECTOR>().0.iter().enumerate() {
                self.write(first + i as u64, sector)?;
            }
            Ok(())
        }
    }

    fn disk(blocks: usize) -> Disk<Recorder> {
        let recorder = Recorder {
            data: vec![0; blocks * 1024],
            writes: Vec::new(),
            runs: Vec::new(),
        };
        Disk::new(recorder, 1024)
    }

    #[test]
    fn stays_bounded_and_loses_nothing() {
        let mut disk = disk(300);
        for block in 0..300u32 {
            disk.modify(block, Kind::Data).unwrap()[0] = block as u8;
            assert!(disk.entries.len() <= CACHE_BLOCKS);
        }
        disk.write_back().unwrap();
        let device = disk.into_device();
        assert!((0..300).all(|b| device.data[b * 1024] == b as u8));
    }

    #[test]
    fn data_goes_out_before_metadata_in_kind_order() {
        let mut disk = disk(16);
        disk.modify(1, Kind::Directory).unwrap()[0] = 1;
        disk.modify(2, Kind::InodeTable).unwrap()[0] = 1;
        disk.modify(3, Kind::Bitmap).unwrap()[0] = 1;
        disk.modify(4, Kind::BlockMap).unwrap()[0] = 1;
        disk.zeroed(5, Kind::Data).unwrap()[0] = 1;
        disk.write_back().unwrap();
        let first_sectors: Vec<u64> = disk.dev.writes.iter().step_by(2).copied().collect();
        assert_eq!(first_sectors, [10, 8, 6, 4, 2]);
        // Nothing is written twice.
        disk.write_back().unwrap();
        assert_eq!(disk.dev.writes.len(), 10);
    }

    /// Consecutive dirty blocks of one kind leave as one run, in order; a gap or another
    /// kind starts a new one.
    #[test]
    fn consecutive_blocks_leave_as_runs() {
        let mut disk = disk(16);
        for block in [3, 4, 5, 7] {
            disk.modify(block, Kind::Data).unwrap()[0] = block as u8;
        }
        disk.modify(6, Kind::InodeTable).unwrap()[0] = 6;
        disk.write_back().unwrap();
        assert_eq!(disk.dev.runs, [(6, 6), (14, 2), (12, 2)]);
        let device = disk.into_device();
        assert!(
            [3, 4, 5, 6, 7]
                .iter()
                .all(|&b| device.data[b * 1024] == b as u8)
        );
    }

    #[test]
    fn forgotten_blocks_are_not_written() {
        let mut disk = disk(4);
        disk.modify(2, Kind::Data).unwrap()[0] = 7;
        disk.forget(2);
        disk.write_back().unwrap();
        assert!(disk.dev.writes.is_empty());
    }
}
