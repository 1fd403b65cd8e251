//! Directory blocks: entries (`inode`, `rec_len`, `name_len`, `file_type`, name), validated
//! as Linux's `ext2_check_page` does, and finding, adding, changing and removing them with
//! the `rec_len` rules kept: 4-byte aligned, no entry crosses a block, the last entry of a
//! block reaches its end, a block with no live entry keeps one with inode 0 spanning it.

use alloc::vec::Vec;

use slots::BlockDevice;

use crate::bytes::{get16, get32, put16, put32};
use crate::cache::Kind;
use crate::fs::Ext2;
use crate::inode::{INDEX_FL, Inode};
use crate::{DirEntry, Error, FileType};

/// Bytes an entry with a name of `name_len` bytes needs.
pub(crate) fn entry_len(name_len: usize) -> usize {
    (8 + name_len + 3) & !3
}

/// One parsed, validated entry of a directory block.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RawEntry {
    pub offset: usize,
    pub ino: u32,
    pub rec_len: usize,
    pub name_len: usize,
    pub file_type: u8,
}

impl RawEntry {
    pub(crate) fn name<'a>(&self, block: &'a [u8]) -> &'a [u8] {
        &block[self.offset + 8..self.offset + 8 + self.name_len]
    }
}

/// Where an entry was found: the directory block (physical and logical), and the entry
/// with the offset of the one before it in the block.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Found {
    pub block: u32,
    pub entry: RawEntry,
    pub previous: Option<usize>,
}

/// Parses every entry of a directory block, checking each and that they tile the block.
pub(crate) fn parse_block(
    block: &[u8],
    inodes_count: u32,
    filetype: bool,
) -> Result<Vec<RawEntry>, Error> {
    let mut entries = Vec::new();
    let mut offset = 0;
    while offset < block.len() {
        if offset + 8 > block.len() {
            return Err(Error::Corrupt("directory entry crosses the block end"));
        }
        let ino = get32(block, offset);
        let rec_len = usize::from(get16(block, offset + 4));
        let (name_len, file_type) = if filetype {
            (usize::from(block[offset + 6]), block[offset + 7])
        } else {
            (usize::from(get16(block, offset + 6)), 0)
        };
        if rec_len < entry_len(1)
            || !rec_len.is_multiple_of(4)
            || rec_len < entry_len(name_len)
            || offset + rec_len > block.len()
        {
            return Err(Error::Corrupt("directory entry length"));
        }
        if ino > inodes_count || (ino != 0 && name_len == 0) {
            return Err(Error::Corrupt("directory entry"));
        }
        entries.push(RawEntry {
            offset,
            ino,
            rec_len,
            name_len,
            file_type,
        });
        offset += rec_len;
    }
    Ok(entries)
}

/// Writes an entry's header and name at `offset`.
fn write_entry(block: &mut [u8], offset: usize, ino: u32, rec_len: usize, name: &[u8], ft: u8) {
    put32(block, offset, ino);
    put16(block, offset + 4, rec_len as u16);
    block[offset + 6] = name.len() as u8;
    block[offset + 7] = ft;
    block[offset + 8..offset + 8 + name.len()].copy_from_slice(name);
}

impl<D: BlockDevice> Ext2<D> {
    fn entry_type(&self, file_type: FileType) -> u8 {
        if self.geo.filetype {
            file_type.code()
        } else {
            0
        }
    }

    /// Blocks of a directory; its size must be whole blocks and no more than it has
    /// allocated (which bounds every walk over it).
    pub(crate) fn dir_block_count(&self, dir: &Inode) -> Result<u64, Error> {
        let size = dir.size();
        let block_size = u64::from(self.geo.block_size);
        if !size.is_multiple_of(block_size) || size > u64::from(dir.sectors()) * 512 {
            return Err(Error::Corrupt("directory size"));
        }
        Ok(size / block_size)
    }

    fn dir_block(&mut self, dir: &Inode, logical: u64) -> Result<u32, Error> {
        self.map_block(dir, logical)?
            .ok_or(Error::Corrupt("hole in a directory"))
    }

    fn dir_entries(&mut self, block: u32) -> Result<Vec<RawEntry>, Error> {
        let inodes = self.geo.inodes_count;
        let filetype = self.geo.filetype;
        parse_block(self.disk.read(block)?, inodes, filetype)
    }

    /// Finds the live entry `name` in `dir`.
    pub(crate) fn find_entry(&mut self, dir: &Inode, name: &[u8]) -> Result<Option<Found>, Error> {
        for logical in 0..self.dir_block_count(dir)? {
            let block = self.dir_block(dir, logical)?;
            let entries = self.dir_entries(block)?;
            let data = self.disk.read(block)?;
            let mut previous = None;
            for entry in entries {
                if entry.ino != 0 && entry.name(data) == name {
                    return Ok(Some(Found {
                        block,
                        entry,
                        previous,
                    }));
                }
                previous = Some(entry.offset);
            }
        }
        Ok(None)
    }

    /// The first live entry at or after byte position `cookie` of `dir`, with the position
    /// after it. A cookie inside an entry (the directory changed) moves to the next one.
    pub(crate) fn next_entry(
        &mut self,
        dir: &Inode,
        cookie: u64,
    ) -> Result<Option<(DirEntry, u64)>, Error> {
        let block_size = u64::from(self.geo.block_size);
        for logical in cookie / block_size..self.dir_block_count(dir)? {
            let block = self.dir_block(dir, logical)?;
            let entries = self.dir_entries(block)?;
            let data = self.disk.read(block)?;
            let from = if logical == cookie / block_size {
                (cookie % block_size) as usize
            } else {
                0
            };
            if let Some(entry) = entries.iter().find(|e| e.offset >= from && e.ino != 0) {
                let found = DirEntry {
                    name: entry.name(data).to_vec(),
                    ino: entry.ino,
                    file_type: FileType::from_code(entry.file_type),
                };
                let next = logical * block_size + (entry.offset + entry.rec_len) as u64;
                return Ok(Some((found, next)));
            }
        }
        Ok(None)
    }

    /// Whether `dir` holds nothing but `.` and `..`.
    pub(crate) fn dir_is_empty(&mut self, dir: &Inode) -> Result<bool, Error> {
        for logical in 0..self.dir_block_count(dir)? {
            let block = self.dir_block(dir, logical)?;
            let entries = self.dir_entries(block)?;
            let data = self.disk.read(block)?;
            for entry in entries {
                let name = entry.name(data);
                if entry.ino != 0 && name != b"." && name != b".." {
                    return Ok(false);
                }
            }
        }
        Ok(true)
    }

    /// Adds the entry `name` → `ino` to directory `dir_ino` (the caller checked that the
    /// name is new), in the first gap big enough or in a new block; stores the directory
    /// inode. Returns the block the entry went to.
    pub(crate) fn add_entry(
        &mut self,
        dir_ino: u32,
        name: &[u8],
        ino: u32,
        file_type: FileType,
    ) -> Result<u32, Error> {
        let mut dir = self.live_inode(dir_ino)?;
        let needed = entry_len(name.len());
        let ft = self.entry_type(file_type);
        let block_count = self.dir_block_count(&dir)?;
        for logical in 0..block_count {
            let block = self.dir_block(&dir, logical)?;
            for entry in self.dir_entries(block)? {
                let used = if entry.ino == 0 {
                    0
                } else {
                    entry_len(entry.name_len)
                };
                if entry.rec_len - used < needed {
                    continue;
                }
                let buf = self.disk.modify(block, Kind::Directory)?;
                if used == 0 {
                    write_entry(buf, entry.offset, ino, entry.rec_len, name, ft);
                } else {
                    put16(buf, entry.offset + 4, used as u16);
                    let at = entry.offset + used;
                    write_entry(buf, at, ino, entry.rec_len - used, name, ft);
                }
                self.touch_dir(&mut dir)?;
                return Ok(block);
            }
        }
        // No room: a new block at the end, the entry spanning it.
        let block = self.map_or_allocate(&mut dir, block_count)?;
        let block_size = self.geo.block_size as usize;
        let buf = self.disk.zeroed(block, Kind::Directory)?;
        write_entry(buf, 0, ino, block_size, name, ft);
        dir.set_size(dir.size() + block_size as u64);
        self.touch_dir(&mut dir)?;
        Ok(block)
    }

    /// Stamps a changed directory, drops its hash index flag (it stays a valid linear
    /// directory) and stores it.
    fn touch_dir(&mut self, dir: &mut Inode) -> Result<(), Error> {
        dir.set_flags(dir.flags() & !INDEX_FL);
        dir.set_mtime(self.now);
        dir.set_ctime(self.now);
        self.store_inode(dir)
    }

    /// Removes a found entry of `dir_ino`: merged into the entry before it, or, first in its
    /// block, made an empty entry (inode 0).
    pub(crate) fn remove_entry(&mut self, dir_ino: u32, found: &Found) -> Result<(), Error> {
        let mut dir = self.live_inode(dir_ino)?;
        let buf = self.disk.modify(found.block, Kind::Directory)?;
        match found.previous {
            Some(previous) => {
                let merged = usize::from(get16(buf, previous + 4)) + found.entry.rec_len;
                put16(buf, previous + 4, merged as u16);
            }
            None => put32(buf, found.entry.offset, 0),
        }
        self.touch_dir(&mut dir)
    }

    /// Points a found entry of `dir_ino` at another inode (rename over a target, `..`).
    pub(crate) fn retarget_entry(
        &mut self,
        dir_ino: u32,
        found: &Found,
        ino: u32,
        file_type: FileType,
    ) -> Result<(), Error> {
        let mut dir = self.live_inode(dir_ino)?;
        let ft = self.entry_type(file_type);
        let buf = self.disk.modify(found.block, Kind::Directory)?;
        put32(buf, found.entry.offset, ino);
        if self.geo.filetype {
            buf[found.entry.offset + 7] = ft;
        }
        self.touch_dir(&mut dir)
    }

    /// Fills a new directory's first block with `.` and `..`.
    pub(crate) fn init_dir_block(
        &mut self,
        block: u32,
        ino: u32,
        parent: u32,
    ) -> Result<(), Error> {
        let block_size = self.geo.block_size as usize;
        let ft = self.entry_type(FileType::Directory);
        let buf = self.disk.zeroed(block, Kind::Directory)?;
        write_entry(buf, 0, ino, 12, b".", ft);
        write_entry(buf, 12, parent, block_size - 12, b"..", ft);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn block_with(entries: &[(u32, usize, &[u8])]) -> Vec<u8> {
        let mut block = alloc::vec![0u8; 1024];
        let mut offset = 0;
        for &(ino, rec_len, name) in entries {
            write_entry(&mut block, offset, ino, rec_len, name, 1);
            offset += rec_len;
        }
        block
    }

    #[test]
    fn a_valid_block_parses() {
        let block = block_with(&[(2, 12, b"."), (2, 12, b".."), (0, 1000, b"")]);
        let entries = parse_block(&block, 100, true).unwrap();
        assert_eq!(entries.len(), 3);
        assert_eq!(entries[1].name(&block), b"..");
    }

    #[test]
    fn bad_entries_are_corrupt() {
        // Short of the block end, too short for its name, past the end, misaligned, an
        // inode out of range, a zero rec_len (which would loop).
        for block in [
            block_with(&[(2, 12, b"."), (2, 12, b"..")]),
            block_with(&[(2, 12, b"long-name"), (0, 1012, b"")]),
            block_with(&[(2, 12, b"."), (2, 1016, b"..")]),
            block_with(&[(2, 14, b"."), (2, 1010, b"..")]),
            block_with(&[(2000, 1024, b"x")]),
            block_with(&[(2, 0, b"x")]),
        ] {
            assert!(matches!(
                parse_block(&block, 100, true),
                Err(Error::Corrupt(_))
            ));
        }
    }

    #[test]
    fn entry_lengths_are_aligned() {
        assert_eq!(entry_len(1), 12);
        assert_eq!(entry_len(4), 12);
        assert_eq!(entry_len(5), 16);
        assert_eq!(entry_len(255), 264);
    }
}
