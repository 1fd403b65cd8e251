//! The superblock and the group descriptors: parsing, validation against each other, and
//! the geometry derived from them (where each group, bitmap and inode table lies).

use alloc::format;
use alloc::vec::Vec;

use crate::Error;
use crate::bytes::{get16, get32, put16, put32};

/// Byte offset of the superblock on the device (and its length).
pub(crate) const SUPERBLOCK_OFFSET: usize = 1024;
pub(crate) const SUPERBLOCK_LEN: usize = 1024;
pub(crate) const MAGIC: u16 = 0xEF53;
/// `s_state`: unmounted cleanly.
pub(crate) const STATE_VALID: u16 = 1;
pub(crate) const GROUP_DESC_LEN: usize = 32;
const MIN_BLOCKS_PER_GROUP: u32 = 256;
const MAX_GROUPS: u32 = 1 << 19;

// Superblock field offsets.
pub(crate) const SB_INODES_COUNT: usize = 0;
pub(crate) const SB_BLOCKS_COUNT: usize = 4;
pub(crate) const SB_R_BLOCKS_COUNT: usize = 8;
pub(crate) const SB_FREE_BLOCKS: usize = 12;
pub(crate) const SB_FREE_INODES: usize = 16;
pub(crate) const SB_FIRST_DATA_BLOCK: usize = 20;
pub(crate) const SB_LOG_BLOCK_SIZE: usize = 24;
pub(crate) const SB_LOG_FRAG_SIZE: usize = 28;
pub(crate) const SB_BLOCKS_PER_GROUP: usize = 32;
pub(crate) const SB_FRAGS_PER_GROUP: usize = 36;
pub(crate) const SB_INODES_PER_GROUP: usize = 40;
pub(crate) const SB_MTIME: usize = 44;
pub(crate) const SB_WTIME: usize = 48;
pub(crate) const SB_MNT_COUNT: usize = 52;
pub(crate) const SB_MAX_MNT_COUNT: usize = 54;
pub(crate) const SB_MAGIC: usize = 56;
pub(crate) const SB_STATE: usize = 58;
pub(crate) const SB_ERRORS: usize = 60;
pub(crate) const SB_LASTCHECK: usize = 64;
pub(crate) const SB_REV_LEVEL: usize = 76;
pub(crate) const SB_FIRST_INO: usize = 84;
pub(crate) const SB_INODE_SIZE: usize = 88;
pub(crate) const SB_BLOCK_GROUP_NR: usize = 90;
pub(crate) const SB_FEATURE_COMPAT: usize = 92;
pub(crate) const SB_FEATURE_INCOMPAT: usize = 96;
pub(crate) const SB_FEATURE_RO_COMPAT: usize = 100;
pub(crate) const SB_UUID: usize = 104;
pub(crate) const SB_VOLUME_NAME: usize = 120;
pub(crate) const SB_RESERVED_GDT_BLOCKS: usize = 206;
pub(crate) const SB_MKFS_TIME: usize = 264;
pub(crate) const SB_MIN_EXTRA_ISIZE: usize = 348;
pub(crate) const SB_WANT_EXTRA_ISIZE: usize = 350;

pub(crate) const COMPAT_EXT_ATTR: u32 = 0x0008;
pub(crate) const COMPAT_RESIZE_INODE: u32 = 0x0010;
pub(crate) const COMPAT_DIR_INDEX: u32 = 0x0020;
pub(crate) const INCOMPAT_FILETYPE: u32 = 0x0002;
pub(crate) const RO_COMPAT_SPARSE_SUPER: u32 = 0x0001;
pub(crate) const RO_COMPAT_LARGE_FILE: u32 = 0x0002;

const COMPAT_SUPPORTED: u32 = COMPAT_EXT_ATTR | COMPAT_RESIZE_INODE | COMPAT_DIR_INDEX;
const INCOMPAT_SUPPORTED: u32 = INCOMPAT_FILETYPE;
const RO_COMPAT_SUPPORTED: u32 = RO_COMPAT_SPARSE_SUPER | RO_COMPAT_LARGE_FILE;

const COMPAT_NAMES: &[(u32, &str)] = &[
    (0x0001, "dir_prealloc"),
    (0x0002, "imagic_inodes"),
    (0x0004, "has_journal"),
    (0x0040, "lazy_bg"),
    (0x0080, "snapshot_bitmap"),
    (0x0100, "exclude_bitmap"),
    (0x0200, "sparse_super2"),
    (0x0400, "fast_commit"),
    (0x0800, "stable_inodes"),
    (0x1000, "orphan_file"),
];
const INCOMPAT_NAMES: &[(u32, &str)] = &[
    (0x0001, "compression"),
    (0x0004, "needs_recovery"),
    (0x0008, "journal_dev"),
    (0x0010, "meta_bg"),
    (0x0040, "extents"),
    (0x0080, "64bit"),
    (0x0100, "mmp"),
    (0x0200, "flex_bg"),
    (0x0400, "ea_inode"),
    (0x1000, "dirdata"),
    (0x2000, "metadata_csum_seed"),
    (0x4000, "large_dir"),
    (0x8000, "inline_data"),
    (0x10000, "encrypt"),
    (0x20000, "casefold"),
];
const RO_COMPAT_NAMES: &[(u32, &str)] = &[
    (0x0004, "btree_dir"),
    (0x0008, "huge_file"),
    (0x0010, "uninit_bg"),
    (0x0020, "dir_nlink"),
    (0x0040, "extra_isize"),
    (0x0080, "snapshot"),
    (0x0100, "quota"),
    (0x0200, "bigalloc"),
    (0x0400, "metadata_csum"),
    (0x0800, "replica"),
    (0x1000, "read-only"),
    (0x2000, "project"),
    (0x4000, "shared_blocks"),
    (0x8000, "verity"),
    (0x10000, "orphan_present"),
];

/// Refuses the first feature bit this crate does not handle, naming it.
fn check_feature_set(
    class: &str,
    present: u32,
    supported: u32,
    names: &[(u32, &str)],
) -> Result<(), Error> {
    let unknown = present & !supported;
    if unknown == 0 {
        return Ok(());
    }
    let bit = unknown & unknown.wrapping_neg();
    let name = names
        .iter()
        .find(|(b, _)| *b == bit)
        .map_or("unknown", |(_, n)| n);
    Err(Error::Unsupported(format!("{class} 0x{bit:04x} ({name})")))
}

/// The fixed shape of a mounted file system, validated.
#[derive(Clone, Debug)]
pub(crate) struct Geometry {
    pub block_size: u32,
    pub blocks_count: u32,
    pub first_data_block: u32,
    pub blocks_per_group: u32,
    pub inodes_per_group: u32,
    pub inodes_count: u32,
    pub inode_size: u32,
    pub first_ino: u32,
    pub group_count: u32,
    pub inode_table_blocks: u32,
    pub gdt_blocks: u32,
    pub reserved_gdt_blocks: u32,
    pub filetype: bool,
    pub large_file: bool,
    pub sparse_super: bool,
}

impl Geometry {
    /// Validates the superblock (magic, revision, features, sizes and counts) and derives
    /// the geometry.
    pub(crate) fn parse(sb: &[u8]) -> Result<Geometry, Error> {
        if sb.len() < SUPERBLOCK_LEN || get16(sb, SB_MAGIC) != MAGIC {
            return Err(Error::Corrupt("bad superblock magic"));
        }
        let rev = get32(sb, SB_REV_LEVEL);
        if rev > 1 {
            return Err(Error::Unsupported(format!("revision {rev}")));
        }
        let (compat, incompat, ro_compat) = if rev == 0 {
            (0, 0, 0)
        } else {
            (
                get32(sb, SB_FEATURE_COMPAT),
                get32(sb, SB_FEATURE_INCOMPAT),
                get32(sb, SB_FEATURE_RO_COMPAT),
            )
        };
        check_feature_set("incompat", incompat, INCOMPAT_SUPPORTED, INCOMPAT_NAMES)?;
        check_feature_set("ro_compat", ro_compat, RO_COMPAT_SUPPORTED, RO_COMPAT_NAMES)?;
        check_feature_set("compat", compat, COMPAT_SUPPORTED, COMPAT_NAMES)?;

        let log = get32(sb, SB_LOG_BLOCK_SIZE);
        if log > 2 {
            return Err(Error::Corrupt("block size"));
        }
        let block_size = 1024u32 << log;
        let blocks_count = get32(sb, SB_BLOCKS_COUNT);
        let first_data_block = get32(sb, SB_FIRST_DATA_BLOCK);
        if first_data_block != u32::from(block_size == 1024) {
            return Err(Error::Corrupt("first data block"));
        }
        let blocks_per_group = get32(sb, SB_BLOCKS_PER_GROUP);
        // mke2fs makes at least 256 blocks per group; fewer would only multiply groups.
        if blocks_per_group < MIN_BLOCKS_PER_GROUP
            || blocks_per_group > block_size * 8
            || !blocks_per_group.is_multiple_of(8)
        {
            return Err(Error::Corrupt("blocks per group"));
        }
        let inodes_per_group = get32(sb, SB_INODES_PER_GROUP);
        if inodes_per_group == 0 || inodes_per_group > block_size * 8 {
            return Err(Error::Corrupt("inodes per group"));
        }
        let (inode_size, first_ino) = if rev == 0 {
            (128, 11)
        } else {
            (u32::from(get16(sb, SB_INODE_SIZE)), get32(sb, SB_FIRST_INO))
        };
        if inode_size < 128 || inode_size > block_size || !inode_size.is_power_of_two() {
            return Err(Error::Corrupt("inode size"));
        }
        if blocks_count <= first_data_block + 1 {
            return Err(Error::Corrupt("blocks count"));
        }
        let group_count = (blocks_count - first_data_block).div_ceil(blocks_per_group);
        let inodes_count = get32(sb, SB_INODES_COUNT);
        if u64::from(inodes_count) != u64::from(group_count) * u64::from(inodes_per_group) {
            return Err(Error::Corrupt("inodes count"));
        }
        if first_ino < 11 || first_ino >= inodes_count {
            return Err(Error::Corrupt("first inode"));
        }
        // At most 2^32 blocks in groups of 8 * block size: 2^19 groups. Beyond is corrupt
        // (and would make the descriptor table huge).
        if group_count > MAX_GROUPS {
            return Err(Error::Corrupt("group count"));
        }
        let gdt_blocks = (group_count * GROUP_DESC_LEN as u32).div_ceil(block_size);
        let reserved_gdt_blocks = if compat & COMPAT_RESIZE_INODE != 0 {
            u32::from(get16(sb, SB_RESERVED_GDT_BLOCKS))
        } else {
            0
        };
        let inode_table_blocks = (inodes_per_group * inode_size).div_ceil(block_size);
        let geometry = Geometry {
            block_size,
            blocks_count,
            first_data_block,
            blocks_per_group,
            inodes_per_group,
            inodes_count,
            inode_size,
            first_ino,
            group_count,
            inode_table_blocks,
            gdt_blocks,
            reserved_gdt_blocks,
            filetype: incompat & INCOMPAT_FILETYPE != 0,
            large_file: ro_compat & RO_COMPAT_LARGE_FILE != 0,
            sparse_super: ro_compat & RO_COMPAT_SPARSE_SUPER != 0,
        };
        // Group 0 must hold its superblock, descriptors, bitmaps and inode table.
        let overhead = u64::from(geometry.super_overhead(0)) + 2 + u64::from(inode_table_blocks);
        if overhead >= u64::from(geometry.group_blocks(0)) {
            return Err(Error::Corrupt("group too small for its metadata"));
        }
        Ok(geometry)
    }

    pub(crate) fn block_sectors(&self) -> u64 {
        u64::from(self.block_size) / 512
    }

    /// Block pointers in an indirect block.
    pub(crate) fn pointers_per_block(&self) -> u32 {
        self.block_size / 4
    }

    pub(crate) fn group_first_block(&self, group: u32) -> u32 {
        self.first_data_block + group * self.blocks_per_group
    }

    /// Blocks in `group` (the last one may be shorter).
    pub(crate) fn group_blocks(&self, group: u32) -> u32 {
        let first = self.group_first_block(group);
        (self.blocks_count - first).min(self.blocks_per_group)
    }

    pub(crate) fn group_of_block(&self, block: u32) -> u32 {
        (block - self.first_data_block) / self.blocks_per_group
    }

    pub(crate) fn group_of_inode(&self, ino: u32) -> u32 {
        (ino - 1) / self.inodes_per_group
    }

    /// Whether `group` holds a copy of the superblock and descriptors.
    pub(crate) fn has_super(&self, group: u32) -> bool {
        if group <= 1 || !self.sparse_super {
            return true;
        }
        [3u32, 5, 7].iter().any(|&base| {
            let mut power = base;
            while power < group {
                power = power.saturating_mul(base);
            }
            power == group
        })
    }

    /// Blocks at the start of `group` taken by the superblock copy, the descriptors and
    /// the reserved descriptor blocks.
    pub(crate) fn super_overhead(&self, group: u32) -> u32 {
        if self.has_super(group) {
            1 + self.gdt_blocks + self.reserved_gdt_blocks
        } else {
            0
        }
    }

    /// Largest file size: what the block map and the 32-bit `i_blocks` can address, and
    /// 2 GiB - 1 without `large_file`.
    pub(crate) fn max_file_size(&self) -> u64 {
        let p = u64::from(self.pointers_per_block());
        let map_blocks = 12 + p + p * p + p * p * p;
        let sectors_per_block = u64::from(self.block_size / 512);
        let by_i_blocks = u64::from(u32::MAX) / sectors_per_block;
        // Leave room for the indirect blocks, which i_blocks counts too.
        let by_i_blocks = by_i_blocks - by_i_blocks / (p - 1) - 3;
        let bytes = map_blocks.min(by_i_blocks) * u64::from(self.block_size);
        if self.large_file {
            bytes
        } else {
            bytes.min((1 << 31) - 1)
        }
    }
}

/// One group descriptor; the other bytes of the descriptor are kept as read.
#[derive(Clone, Debug)]
pub(crate) struct Group {
    pub block_bitmap: u32,
    pub inode_bitmap: u32,
    pub inode_table: u32,
    pub free_blocks: u32,
    pub free_inodes: u32,
    pub used_dirs: u32,
}

impl Group {
    /// Whether `block` is one of this group's bitmaps or inode-table blocks.
    pub(crate) fn holds_metadata(&self, geo: &Geometry, block: u32) -> bool {
        block == self.block_bitmap
            || block == self.inode_bitmap
            || (block >= self.inode_table && block - self.inode_table < geo.inode_table_blocks)
    }
}

/// Parses and validates the descriptors: each group's bitmaps and inode table inside the
/// group, clear of its superblock copy, free counts within the group.
pub(crate) fn parse_groups(geo: &Geometry, table: &[u8]) -> Result<Vec<Group>, Error> {
    let mut groups = Vec::new();
    for g in 0..geo.group_count {
        let at = g as usize * GROUP_DESC_LEN;
        let raw = table
            .get(at..at + GROUP_DESC_LEN)
            .ok_or(Error::Corrupt("group descriptor table"))?;
        let group = Group {
            block_bitmap: get32(raw, 0),
            inode_bitmap: get32(raw, 4),
            inode_table: get32(raw, 8),
            free_blocks: u32::from(get16(raw, 12)),
            free_inodes: u32::from(get16(raw, 14)),
            used_dirs: u32::from(get16(raw, 16)),
        };
        let first = geo.group_first_block(g) + geo.super_overhead(g);
        let end = geo.group_first_block(g) + geo.group_blocks(g);
        let inside = |block: u32, len: u32| block >= first && block.saturating_add(len) <= end;
        if !inside(group.block_bitmap, 1) {
            return Err(Error::Corrupt("block bitmap outside its group"));
        }
        if !inside(group.inode_bitmap, 1) {
            return Err(Error::Corrupt("inode bitmap outside its group"));
        }
        if !inside(group.inode_table, geo.inode_table_blocks) {
            return Err(Error::Corrupt("inode table outside its group"));
        }
        if group.free_blocks > geo.group_blocks(g)
            || group.free_inodes > geo.inodes_per_group
            || group.used_dirs > geo.inodes_per_group
        {
            return Err(Error::Corrupt("group descriptor counts"));
        }
        groups.push(group);
    }
    Ok(groups)
}

/// Writes the counts of `group` back into its raw descriptor.
pub(crate) fn store_group(table: &mut [u8], index: u32, group: &Group) {
    let at = index as usize * GROUP_DESC_LEN;
    let raw = &mut table[at..at + GROUP_DESC_LEN];
    put32(raw, 0, group.block_bitmap);
    put32(raw, 4, group.inode_bitmap);
    put32(raw, 8, group.inode_table);
    // The counts fit: validated at mount and kept within the group since.
    put16(raw, 12, group.free_blocks as u16);
    put16(raw, 14, group.free_inodes as u16);
    put16(raw, 16, group.used_dirs as u16);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn geometry(blocks: u32, sparse: bool) -> Geometry {
        let mut sb = alloc::vec![0u8; SUPERBLOCK_LEN];
        put32(&mut sb, SB_INODES_COUNT, 2048 * (blocks - 1).div_ceil(8192));
        put32(&mut sb, SB_BLOCKS_COUNT, blocks);
        put32(&mut sb, SB_FIRST_DATA_BLOCK, 1);
        put32(&mut sb, SB_BLOCKS_PER_GROUP, 8192);
        put32(&mut sb, SB_INODES_PER_GROUP, 2048);
        put16(&mut sb, SB_MAGIC, MAGIC);
        put32(&mut sb, SB_REV_LEVEL, 1);
        put32(&mut sb, SB_FIRST_INO, 11);
        put16(&mut sb, SB_INODE_SIZE, 128);
        if sparse {
            put32(&mut sb, SB_FEATURE_RO_COMPAT, RO_COMPAT_SPARSE_SUPER);
        }
        Geometry::parse(&sb).unwrap()
    }

    #[test]
    fn sparse_super_groups() {
        let geo = geometry(8192 * 60 + 1, true);
        let with: alloc::vec::Vec<u32> = (0..60).filter(|&g| geo.has_super(g)).collect();
        assert_eq!(with, [0, 1, 3, 5, 7, 9, 25, 27, 49]);
        let geo = geometry(8192 * 4 + 1, false);
        assert!((0..4).all(|g| geo.has_super(g)));
    }

    #[test]
    fn last_group_is_shorter() {
        let geo = geometry(8192 * 2 + 1 + 100, false);
        assert_eq!(geo.group_count, 3);
        assert_eq!(geo.group_blocks(2), 100);
        assert_eq!(geo.group_of_block(8192 * 2 + 1), 2);
    }

    #[test]
    fn features_are_named() {
        let error = check_feature_set("incompat", 0x2 | 0x200 | 0x40, 0x2, INCOMPAT_NAMES);
        assert_eq!(
            error,
            Err(Error::Unsupported("incompat 0x0040 (extents)".into()))
        );
        let error = check_feature_set("ro_compat", 0x8000_0000, 0, RO_COMPAT_NAMES);
        assert_eq!(
            error,
            Err(Error::Unsupported("ro_compat 0x80000000 (unknown)".into()))
        );
    }
}
