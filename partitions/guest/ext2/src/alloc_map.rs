//! Block and inode allocation: the bitmaps, with the group descriptors' free counts (and,
//! through them, the superblock's) changed in step.

use slots::BlockDevice;

use crate::Error;
use crate::cache::Kind;
use crate::fs::Ext2;

/// The first clear bit of `bitmap` in `start..end`, then in `0..start`.
fn find_clear_bit(bitmap: &[u8], start: u32, end: u32) -> Option<u32> {
    let clear = |bit: u32| bitmap[(bit / 8) as usize] & (1 << (bit % 8)) == 0;
    let scan = |from: u32, to: u32| {
        let mut bit = from;
        while bit < to {
            if bit.is_multiple_of(8) && to - bit >= 8 && bitmap[(bit / 8) as usize] == 0xFF {
                bit += 8;
                continue;
            }
            if clear(bit) {
                return Some(bit);
            }
            bit += 1;
        }
        None
    };
    scan(start.min(end), end).or_else(|| scan(0, start.min(end)))
}

impl<D: BlockDevice> Ext2<D> {
    /// Whether `block` may be a file's or directory's block: inside the file system and
    /// none of the superblock copies, descriptors, bitmaps or inode tables.
    pub(crate) fn is_data_block(&self, block: u32) -> bool {
        if block < self.geo.first_data_block || block >= self.geo.blocks_count {
            return false;
        }
        let group = self.geo.group_of_block(block);
        let offset = block - self.geo.group_first_block(group);
        offset >= self.geo.super_overhead(group)
            && !self.groups[group as usize].holds_metadata(&self.geo, block)
    }

    pub(crate) fn check_data_block(&self, block: u32) -> Result<(), Error> {
        if self.is_data_block(block) {
            Ok(())
        } else {
            Err(Error::Corrupt("block number out of range"))
        }
    }

    pub(crate) fn free_block_count(&self) -> u64 {
        self.free_counts().0
    }

    /// Allocates a block, the first free one at or after `goal` in its group, else in the
    /// next groups with free blocks. The caller fills it (see `Disk::zeroed`).
    pub(crate) fn allocate_block(&mut self, goal: u32) -> Result<u32, Error> {
        let goal = if goal >= self.geo.first_data_block && goal < self.geo.blocks_count {
            goal
        } else {
            self.geo.first_data_block
        };
        let first_group = self.geo.group_of_block(goal);
        let count = self.geo.group_count;
        for step in 0..count {
            let group = (first_group + step) % count;
            if self.groups[group as usize].free_blocks == 0 {
                continue;
            }
            let start = if step == 0 {
                goal - self.geo.group_first_block(group)
            } else {
                0
            };
            let bits = self.geo.group_blocks(group);
            let bitmap_block = self.groups[group as usize].block_bitmap;
            let bitmap = self.disk.read(bitmap_block)?;
            let Some(bit) = find_clear_bit(bitmap, start, bits) else {
                return Err(Error::Corrupt("group free block count above its bitmap"));
            };
            let block = self.geo.group_first_block(group) + bit;
            if !self.is_data_block(block) {
                return Err(Error::Corrupt("bitmap marks a metadata block free"));
            }
            self.disk.modify(bitmap_block, Kind::Bitmap)?[(bit / 8) as usize] |= 1 << (bit % 8);
            self.groups[group as usize].free_blocks -= 1;
            return Ok(block);
        }
        Err(Error::NoSpace)
    }

    /// Frees a data block (and forgets its cached contents).
    pub(crate) fn free_block(&mut self, block: u32) -> Result<(), Error> {
        self.check_data_block(block)?;
        let group = self.geo.group_of_block(block);
        let bit = block - self.geo.group_first_block(group);
        let bitmap_block = self.groups[group as usize].block_bitmap;
        let byte = &mut self.disk.modify(bitmap_block, Kind::Bitmap)?[(bit / 8) as usize];
        if *byte & (1 << (bit % 8)) == 0 {
            return Err(Error::Corrupt("freeing a free block"));
        }
        *byte &= !(1 << (bit % 8));
        let limit = self.geo.group_blocks(group);
        let group = &mut self.groups[group as usize];
        group.free_blocks = (group.free_blocks + 1).min(limit);
        self.disk.forget(block);
        Ok(())
    }

    /// Allocates an inode: a directory goes to the group with the most free inodes
    /// (spreading directories, like Linux's Orlov allocator in its simplest form), anything
    /// else to its parent directory's group, or the next one with a free inode.
    pub(crate) fn allocate_inode(&mut self, parent: u32, is_dir: bool) -> Result<u32, Error> {
        let count = self.geo.group_count;
        let first_group = if is_dir {
            (0..count)
                .max_by_key(|&g| {
                    let group = &self.groups[g as usize];
                    (group.free_inodes, group.free_blocks, core::cmp::Reverse(g))
                })
                .unwrap_or(0)
        } else {
            self.geo.group_of_inode(parent)
        };
        for step in 0..count {
            let group = (first_group + step) % count;
            if self.groups[group as usize].free_inodes == 0 {
                continue;
            }
            let bitmap_block = self.groups[group as usize].inode_bitmap;
            let bitmap = self.disk.read(bitmap_block)?;
            let Some(bit) = find_clear_bit(bitmap, 0, self.geo.inodes_per_group) else {
                return Err(Error::Corrupt("group free inode count above its bitmap"));
            };
            let ino = group * self.geo.inodes_per_group + bit + 1;
            if ino < self.geo.first_ino {
                return Err(Error::Corrupt("bitmap marks a reserved inode free"));
            }
            self.disk.modify(bitmap_block, Kind::Bitmap)?[(bit / 8) as usize] |= 1 << (bit % 8);
            let group = &mut self.groups[group as usize];
            group.free_inodes -= 1;
            if is_dir {
                group.used_dirs += 1;
            }
            return Ok(ino);
        }
        Err(Error::NoSpace)
    }

    /// Clears `ino`'s bit in the inode bitmap.
    pub(crate) fn free_inode(&mut self, ino: u32, is_dir: bool) -> Result<(), Error> {
        if ino < self.geo.first_ino || ino > self.geo.inodes_count {
            return Err(Error::Corrupt("freeing a reserved inode"));
        }
        let group = self.geo.group_of_inode(ino);
        let bit = (ino - 1) % self.geo.inodes_per_group;
        let bitmap_block = self.groups[group as usize].inode_bitmap;
        let byte = &mut self.disk.modify(bitmap_block, Kind::Bitmap)?[(bit / 8) as usize];
        if *byte & (1 << (bit % 8)) == 0 {
            return Err(Error::Corrupt("freeing a free inode"));
        }
        *byte &= !(1 << (bit % 8));
        let inodes_per_group = self.geo.inodes_per_group;
        let group = &mut self.groups[group as usize];
        group.free_inodes = (group.free_inodes + 1).min(inodes_per_group);
        if is_dir {
            group.used_dirs = group.used_dirs.saturating_sub(1);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::find_clear_bit;

    #[test]
    fn clear_bits_are_found_from_the_goal_then_wrapping() {
        let mut bitmap = [0xFFu8; 8];
        assert_eq!(find_clear_bit(&bitmap, 0, 64), None);
        bitmap[1] = 0b1110_1111; // bit 12
        bitmap[6] = 0b0111_1111; // bit 55
        assert_eq!(find_clear_bit(&bitmap, 0, 64), Some(12));
        assert_eq!(find_clear_bit(&bitmap, 13, 64), Some(55));
        assert_eq!(find_clear_bit(&bitmap, 56, 64), Some(12));
        // Bits at and after `end` do not count.
        assert_eq!(find_clear_bit(&bitmap, 13, 50), Some(12));
        assert_eq!(find_clear_bit(&bitmap, 0, 12), None);
    }
}
