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
        let mut sector = [0u8; SECTOR];
        for (i, chunk) in out.chunks_mut(SECTOR).enumerate() {
            self.dev
                .read(first + i as u64, &mut sector)
                .map_err(device_error)?;
            chunk.copy_from_slice(&sector[..chunk.len()]);
        }
        Ok(())
    }

    /// Writes `data` (a multiple of [`SECTOR`] bytes) from sector `first`, bypassing the
    /// cache (the formatter and the write-back use it).
    pub(crate) fn write_sectors(&mut self, first: u64, data: &[u8]) -> Result<(), Error> {
        let mut sector = [0u8; SECTOR];
        for (i, chunk) in data.chunks(SECTOR).enumerate() {
            sector.fill(0);
            sector[..chunk.len()].copy_from_slice(chunk);
            self.dev
                .write(first + i as u64, &sector)
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
        for (_, block) in dirty {
            self.write_now(block)?;
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
    }

    fn disk(blocks: usize) -> Disk<Recorder> {
        let recorder = Recorder {
            data: vec![0; blocks * 1024],
            writes: Vec::new(),
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

    #[test]
    fn forgotten_blocks_are_not_written() {
        let mut disk = disk(4);
        disk.modify(2, Kind::Data).unwrap()[0] = 7;
        disk.forget(2);
        disk.write_back().unwrap();
        assert!(disk.dev.writes.is_empty());
    }
}
