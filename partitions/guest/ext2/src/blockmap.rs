//! The block map of an inode: twelve direct pointers, then single, double and triple
//! indirect blocks. Lookup, allocation along a path, and freeing from a logical block on.
//! Every pointer read from the disk is range-checked before it is followed; the depth is
//! at most three, so walks are bounded.

use alloc::vec::Vec;

use slots::BlockDevice;

use crate::Error;
use crate::bytes::{get32, put32};
use crate::cache::Kind;
use crate::fs::Ext2;
use crate::inode::{DIRECT_BLOCKS, Inode};

/// Where a logical block's pointer lies: the `i_block` slot, then the index in each
/// indirect block down to the data block (`depth` of them).
struct MapPath {
    depth: usize,
    indexes: [usize; 4],
}

impl<D: BlockDevice> Ext2<D> {
    fn map_path(&self, logical: u64) -> Result<MapPath, Error> {
        let p = u64::from(self.geo.pointers_per_block());
        let direct = DIRECT_BLOCKS as u64;
        let path = |depth, indexes: [u64; 4]| MapPath {
            depth,
            indexes: indexes.map(|i| i as usize),
        };
        if logical < direct {
            return Ok(path(0, [logical, 0, 0, 0]));
        }
        let l = logical - direct;
        if l < p {
            return Ok(path(1, [12, l, 0, 0]));
        }
        let l = l - p;
        if l < p * p {
            return Ok(path(2, [13, l / p, l % p, 0]));
        }
        let l = l - p * p;
        if l < p * p * p {
            return Ok(path(3, [14, l / (p * p), (l / p) % p, l % p]));
        }
        Err(Error::TooBig)
    }

    /// The block holding logical block `logical` of the inode, `None` in a hole.
    pub(crate) fn map_block(&mut self, inode: &Inode, logical: u64) -> Result<Option<u32>, Error> {
        let path = self.map_path(logical)?;
        let mut block = inode.block(path.indexes[0]);
        for level in 1..=path.depth {
            if block == 0 {
                return Ok(None);
            }
            self.check_data_block(block)?;
            block = get32(self.disk.read(block)?, path.indexes[level] * 4);
        }
        if block == 0 {
            return Ok(None);
        }
        self.check_data_block(block)?;
        Ok(Some(block))
    }

    /// The block of logical block `logical`, allocated (zero-filled, with the indirect
    /// blocks on its path) if it is a hole. Checks first that the free blocks suffice for
    /// the whole path, so that running out never leaves a half-built path.
    pub(crate) fn map_or_allocate(
        &mut self,
        inode: &mut Inode,
        logical: u64,
    ) -> Result<u32, Error> {
        let path = self.map_path(logical)?;
        // Pass one: how far the path exists.
        let mut block = inode.block(path.indexes[0]);
        let mut present = 0;
        while block != 0 && present < path.depth {
            self.check_data_block(block)?;
            present += 1;
            block = get32(self.disk.read(block)?, path.indexes[present] * 4);
        }
        if block != 0 {
            self.check_data_block(block)?;
            return Ok(block);
        }
        let needed = (path.depth + 1 - present) as u64;
        if self.free_block_count() < needed {
            return Err(Error::NoSpace);
        }
        // Pass two: allocate the missing blocks near the inode's other blocks.
        let goal = self.allocation_goal(inode, logical)?;
        let kind_at = |level: usize| {
            if level == path.depth {
                Kind::Data
            } else {
                Kind::BlockMap
            }
        };
        let mut parent = None;
        let mut block = inode.block(path.indexes[0]);
        for level in 0..=path.depth {
            if level > 0 {
                let parent_block = block;
                block = get32(self.disk.read(parent_block)?, path.indexes[level] * 4);
                parent = Some(parent_block);
            }
            if block != 0 {
                continue;
            }
            let new = self.allocate_block(goal)?;
            self.disk.zeroed(new, kind_at(level))?;
            match parent {
                None => inode.set_block(path.indexes[0], new),
                Some(parent) => put32(
                    self.disk.modify(parent, Kind::BlockMap)?,
                    path.indexes[level] * 4,
                    new,
                ),
            }
            inode.set_sectors(inode.sectors().saturating_add(self.geo.block_size / 512));
            block = new;
        }
        Ok(block)
    }

    /// Where to look for a new block: after the block before `logical`, else the start of
    /// the inode's group.
    fn allocation_goal(&mut self, inode: &Inode, logical: u64) -> Result<u32, Error> {
        if logical > 0
            && let Some(previous) = self.map_block(inode, logical - 1)?
        {
            return Ok(previous + 1);
        }
        let group = self.geo.group_of_inode(inode.ino);
        Ok(self.geo.group_first_block(group))
    }

    /// Frees every block of the inode from logical block `first` on, with the indirect
    /// blocks that become empty; `i_blocks` follows.
    pub(crate) fn free_blocks_from(&mut self, inode: &mut Inode, first: u64) -> Result<(), Error> {
        let sectors_per_block = self.geo.block_size / 512;
        for index in (first.min(DIRECT_BLOCKS as u64) as usize)..DIRECT_BLOCKS {
            let block = inode.block(index);
            if block != 0 {
                self.free_block(block)?;
                inode.set_block(index, 0);
                inode.set_sectors(inode.sectors().saturating_sub(sectors_per_block));
            }
        }
        let p = u64::from(self.geo.pointers_per_block());
        let mut base = DIRECT_BLOCKS as u64;
        for (depth, span) in [(1u32, p), (2, p * p), (3, p * p * p)] {
            let slot = DIRECT_BLOCKS + depth as usize - 1;
            let block = inode.block(slot);
            if block != 0 && first < base + span {
                let from = first.saturating_sub(base);
                let mut freed = 0u32;
                let empty = self.free_subtree(block, depth, from, &mut freed);
                inode.set_sectors(inode.sectors().saturating_sub(freed * sectors_per_block));
                if empty? {
                    self.free_block(block)?;
                    inode.set_block(slot, 0);
                    inode.set_sectors(inode.sectors().saturating_sub(sectors_per_block));
                }
            }
            base += span;
        }
        Ok(())
    }

    /// Frees the blocks under indirect block `block` (of `depth` levels) from relative
    /// logical block `from` on, counting them in `freed`; returns whether `block` holds no
    /// pointer any more (the caller frees it then).
    fn free_subtree(
        &mut self,
        block: u32,
        depth: u32,
        from: u64,
        freed: &mut u32,
    ) -> Result<bool, Error> {
        self.check_data_block(block)?;
        let child_span = u64::from(self.geo.pointers_per_block()).pow(depth - 1);
        let pointers: Vec<u32> = self
            .disk
            .read(block)?
            .chunks_exact(4)
            .map(|c| get32(c, 0))
            .collect();
        let mut empty = true;
        let mut cleared = Vec::new();
        for (index, &child) in pointers.iter().enumerate() {
            if child == 0 {
                continue;
            }
            let start = index as u64 * child_span;
            let free_child = if start + child_span <= from {
                false
            } else if depth == 1 {
                true
            } else {
                self.free_subtree(child, depth - 1, from.saturating_sub(start), freed)?
            };
            if free_child {
                self.free_block(child)?;
                *freed += 1;
                cleared.push(index);
            } else {
                empty = false;
            }
        }
        if !empty && !cleared.is_empty() {
            let buf = self.disk.modify(block, Kind::BlockMap)?;
            for index in cleared {
                put32(buf, index * 4, 0);
            }
        }
        Ok(empty)
    }
}
