//! Making a fresh file system: revision 1, `sparse_super`, `filetype`, `large_file`, a root
//! directory and `lost+found`, laid out as mke2fs does for ext2 without `resize_inode`.

use alloc::vec;
use alloc::vec::Vec;

use slots::{BlockDevice, SECTOR};

use crate::bytes::{put16, put32};
use crate::cache::device_error;
use crate::inode::Inode;
use crate::layout::{self, Geometry, Group};
use crate::layout::{
    INCOMPAT_FILETYPE, MAGIC, RO_COMPAT_LARGE_FILE, RO_COMPAT_SPARSE_SUPER, SB_BLOCK_GROUP_NR,
    SB_BLOCKS_COUNT, SB_BLOCKS_PER_GROUP, SB_ERRORS, SB_FEATURE_INCOMPAT, SB_FEATURE_RO_COMPAT,
    SB_FIRST_DATA_BLOCK, SB_FIRST_INO, SB_FRAGS_PER_GROUP, SB_FREE_BLOCKS, SB_FREE_INODES,
    SB_INODE_SIZE, SB_INODES_COUNT, SB_INODES_PER_GROUP, SB_LASTCHECK, SB_LOG_BLOCK_SIZE,
    SB_LOG_FRAG_SIZE, SB_MAGIC, SB_MAX_MNT_COUNT, SB_MIN_EXTRA_ISIZE, SB_MKFS_TIME,
    SB_R_BLOCKS_COUNT, SB_REV_LEVEL, SB_STATE, SB_UUID, SB_VOLUME_NAME, SB_WANT_EXTRA_ISIZE,
    SB_WTIME, STATE_VALID, SUPERBLOCK_LEN, SUPERBLOCK_OFFSET,
};
use crate::{Error, ROOT_INO, S_IFDIR};

/// The choices of [`format`].
#[derive(Clone, Debug)]
pub struct FormatOptions {
    /// 1024, 2048 or 4096.
    pub block_size: u32,
    /// 128 or 256 (any power of two from 128 to the block size).
    pub inode_size: u16,
    /// One inode per this many bytes of the device (at least one block's worth).
    pub bytes_per_inode: u32,
    /// Blocks held back for root, in percent (mke2fs's `-m`; this crate does not enforce
    /// them, Linux does).
    pub reserved_percent: u32,
    pub uuid: [u8; 16],
    /// The volume name, NUL-padded.
    pub label: [u8; 16],
    /// Seconds since the epoch, for the inodes' and superblock's times.
    pub now: u32,
}

impl Default for FormatOptions {
    fn default() -> Self {
        FormatOptions {
            block_size: 4096,
            inode_size: 256,
            bytes_per_inode: 16384,
            reserved_percent: 5,
            uuid: [0; 16],
            label: [0; 16],
            now: 0,
        }
    }
}

/// The inode of `lost+found`.
const LOST_FOUND_INO: u32 = 11;
/// Smallest last group worth keeping beyond its metadata (as mke2fs).
const MIN_LAST_GROUP_DATA: u32 = 50;

/// The superblock of a fresh file system of `blocks` blocks, before the free counts.
fn new_superblock(options: &FormatOptions, blocks: u32, inodes_per_group: u32) -> Vec<u8> {
    let bs = options.block_size;
    let first_data_block = u32::from(bs == 1024);
    let groups = (blocks - first_data_block).div_ceil(bs * 8);
    let mut sb = vec![0u8; SUPERBLOCK_LEN];
    put32(&mut sb, SB_INODES_COUNT, groups * inodes_per_group);
    put32(&mut sb, SB_BLOCKS_COUNT, blocks);
    put32(
        &mut sb,
        SB_R_BLOCKS_COUNT,
        (u64::from(blocks) * u64::from(options.reserved_percent.min(50)) / 100) as u32,
    );
    put32(&mut sb, SB_FIRST_DATA_BLOCK, first_data_block);
    put32(&mut sb, SB_LOG_BLOCK_SIZE, bs.trailing_zeros() - 10);
    put32(&mut sb, SB_LOG_FRAG_SIZE, bs.trailing_zeros() - 10);
    put32(&mut sb, SB_BLOCKS_PER_GROUP, bs * 8);
    put32(&mut sb, SB_FRAGS_PER_GROUP, bs * 8);
    put32(&mut sb, SB_INODES_PER_GROUP, inodes_per_group);
    put32(&mut sb, SB_WTIME, options.now);
    put16(&mut sb, SB_MAX_MNT_COUNT, 0xFFFF);
    put16(&mut sb, SB_MAGIC, MAGIC);
    put16(&mut sb, SB_STATE, STATE_VALID);
    put16(&mut sb, SB_ERRORS, 1);
    put32(&mut sb, SB_LASTCHECK, options.now);
    put32(&mut sb, SB_REV_LEVEL, 1);
    put32(&mut sb, SB_FIRST_INO, LOST_FOUND_INO);
    put16(&mut sb, SB_INODE_SIZE, options.inode_size);
    put32(&mut sb, SB_FEATURE_INCOMPAT, INCOMPAT_FILETYPE);
    put32(
        &mut sb,
        SB_FEATURE_RO_COMPAT,
        RO_COMPAT_SPARSE_SUPER | RO_COMPAT_LARGE_FILE,
    );
    sb[SB_UUID..SB_UUID + 16].copy_from_slice(&options.uuid);
    sb[SB_VOLUME_NAME..SB_VOLUME_NAME + 16].copy_from_slice(&options.label);
    put32(&mut sb, SB_MKFS_TIME, options.now);
    if options.inode_size >= 160 {
        put16(&mut sb, SB_MIN_EXTRA_ISIZE, 32);
        put16(&mut sb, SB_WANT_EXTRA_ISIZE, 32);
    }
    sb
}

/// Picks the block count and inodes per group, dropping a last group too small to be
/// worth its metadata; returns the validated geometry and the superblock.
fn plan(options: &FormatOptions, sectors: u64) -> Result<(Geometry, Vec<u8>), Error> {
    let bs = options.block_size;
    let isz = u32::from(options.inode_size);
    if !matches!(bs, 1024 | 2048 | 4096) || isz < 128 || isz > bs || !isz.is_power_of_two() {
        return Err(Error::Invalid);
    }
    let mut blocks = (sectors * SECTOR as u64 / u64::from(bs)).min(u64::from(u32::MAX)) as u32;
    let first_data_block = u32::from(bs == 1024);
    if blocks < 64 {
        return Err(Error::Invalid);
    }
    loop {
        let groups = (blocks - first_data_block).div_ceil(bs * 8);
        let wanted = u64::from(blocks) * u64::from(bs) / u64::from(options.bytes_per_inode.max(bs));
        let per_block = bs / isz;
        // Whole inode-table blocks, a multiple of 8 bits, at least lost+found's and a few.
        let step = per_block.max(8);
        let inodes_per_group = (wanted.div_ceil(u64::from(groups)) as u32)
            .max(16)
            .div_ceil(step)
            .saturating_mul(step)
            .min(bs * 8);
        let sb = new_superblock(options, blocks, inodes_per_group);
        let geo = Geometry::parse(&sb)?;
        let last = groups - 1;
        let last_overhead = geo.super_overhead(last) + 2 + geo.inode_table_blocks;
        if groups > 1 && geo.group_blocks(last) < last_overhead + MIN_LAST_GROUP_DATA {
            blocks -= geo.group_blocks(last);
            continue;
        }
        if geo.group_blocks(0) < geo.super_overhead(0) + 2 + geo.inode_table_blocks + 2 {
            return Err(Error::Invalid);
        }
        return Ok((geo, sb));
    }
}

fn write_block<D: BlockDevice>(dev: &mut D, bs: u32, block: u32, data: &[u8]) -> Result<(), Error> {
    let first = u64::from(block) * u64::from(bs / SECTOR as u32);
    let mut sector = [0u8; SECTOR];
    for i in 0..(bs as usize / SECTOR) {
        sector.fill(0);
        let part = data.get(i * SECTOR..).unwrap_or(&[]);
        let len = part.len().min(SECTOR);
        sector[..len].copy_from_slice(&part[..len]);
        dev.write(first + i as u64, &sector).map_err(device_error)?;
    }
    Ok(())
}

fn set_bits(bitmap: &mut [u8], range: core::ops::Range<u32>) {
    for bit in range {
        bitmap[(bit / 8) as usize] |= 1 << (bit % 8);
    }
}

/// A directory block with `.` and `..`.
fn dir_block(bs: u32, ino: u32, parent: u32) -> Vec<u8> {
    let mut block = vec![0u8; bs as usize];
    put32(&mut block, 0, ino);
    put16(&mut block, 4, 12);
    block[6] = 1;
    block[7] = 2;
    block[8] = b'.';
    put32(&mut block, 12, parent);
    put16(&mut block, 16, (bs - 12) as u16);
    block[18] = 2;
    block[19] = 2;
    block[20..22].copy_from_slice(b"..");
    block
}

/// Makes a fresh ext2 file system on the first `sectors` sectors of `dev`, which e2fsck
/// accepts and Linux mounts. Everything is written (the inode tables zeroed) and flushed.
pub fn format<D: BlockDevice>(
    dev: &mut D,
    sectors: u64,
    options: &FormatOptions,
) -> Result<(), Error> {
    let (geo, mut sb) = plan(options, sectors)?;
    let bs = geo.block_size;
    let itb = geo.inode_table_blocks;
    // Group 0's first two data blocks: the root directory and lost+found.
    let group0_data = geo.group_first_block(0) + geo.super_overhead(0) + 2 + itb;
    let (root_block, lost_found_block) = (group0_data, group0_data + 1);
    let mut groups = Vec::new();
    let mut gdt = vec![0u8; (geo.gdt_blocks * bs) as usize];
    let zero = vec![0u8; bs as usize];
    for g in 0..geo.group_count {
        let meta = geo.group_first_block(g) + geo.super_overhead(g);
        let used = geo.super_overhead(g) + 2 + itb + if g == 0 { 2 } else { 0 };
        let group = Group {
            block_bitmap: meta,
            inode_bitmap: meta + 1,
            inode_table: meta + 2,
            free_blocks: geo.group_blocks(g) - used,
            free_inodes: geo.inodes_per_group - if g == 0 { LOST_FOUND_INO } else { 0 },
            used_dirs: if g == 0 { 2 } else { 0 },
        };
        let mut block_bitmap = vec![0u8; bs as usize];
        set_bits(&mut block_bitmap, 0..used);
        set_bits(&mut block_bitmap, geo.group_blocks(g)..bs * 8);
        write_block(dev, bs, group.block_bitmap, &block_bitmap)?;
        let mut inode_bitmap = vec![0u8; bs as usize];
        set_bits(
            &mut inode_bitmap,
            0..if g == 0 { LOST_FOUND_INO } else { 0 },
        );
        set_bits(&mut inode_bitmap, geo.inodes_per_group..bs * 8);
        write_block(dev, bs, group.inode_bitmap, &inode_bitmap)?;
        for i in 0..itb {
            write_block(dev, bs, group.inode_table + i, &zero)?;
        }
        layout::store_group(&mut gdt, g, &group);
        groups.push(group);
    }
    let lost_found = dir_block(bs, LOST_FOUND_INO, ROOT_INO);
    // Root's block: `.`, `..`, then lost+found spanning the rest.
    let mut root = dir_block(bs, ROOT_INO, ROOT_INO);
    put16(&mut root, 16, 12);
    put32(&mut root, 24, LOST_FOUND_INO);
    put16(&mut root, 28, (bs - 24) as u16);
    root[30] = 10;
    root[31] = 2;
    root[32..42].copy_from_slice(b"lost+found");
    write_block(dev, bs, root_block, &root)?;
    write_block(dev, bs, lost_found_block, &lost_found)?;

    // The two directory inodes, in group 0's inode table.
    let isz = geo.inode_size as usize;
    let inodes = [
        (ROOT_INO, 0o755, 3, root_block),
        (LOST_FOUND_INO, 0o700, 2, lost_found_block),
    ];
    let mut table = vec![0u8; (itb * bs) as usize];
    for (ino, perm, links, block) in inodes {
        let mut inode = Inode::new(ino, isz, S_IFDIR | perm, options.now);
        inode.set_links(links);
        inode.set_size(u64::from(bs));
        inode.set_sectors(bs / 512);
        inode.set_block(0, block);
        let at = (ino as usize - 1) * isz;
        table[at..at + isz].copy_from_slice(&inode.raw);
    }
    for i in 0..(LOST_FOUND_INO as usize * isz).div_ceil(bs as usize) {
        let part = &table[i * bs as usize..(i + 1) * bs as usize];
        write_block(dev, bs, groups[0].inode_table + i as u32, part)?;
    }

    let free_blocks: u32 = groups.iter().map(|g| g.free_blocks).sum();
    let free_inodes: u32 = groups.iter().map(|g| g.free_inodes).sum();
    put32(&mut sb, SB_FREE_BLOCKS, free_blocks);
    put32(&mut sb, SB_FREE_INODES, free_inodes);
    for g in (0..geo.group_count).filter(|&g| geo.has_super(g)) {
        put16(&mut sb, SB_BLOCK_GROUP_NR, g as u16);
        let first = geo.group_first_block(g);
        if g == 0 {
            let sector = (SUPERBLOCK_OFFSET / SECTOR) as u64;
            for (i, part) in sb.chunks(SECTOR).enumerate() {
                let mut buf = [0u8; SECTOR];
                buf.copy_from_slice(part);
                dev.write(sector + i as u64, &buf).map_err(device_error)?;
            }
        } else {
            write_block(dev, bs, first, &sb)?;
        }
        for i in 0..geo.gdt_blocks {
            let part = &gdt[(i * bs) as usize..((i + 1) * bs) as usize];
            write_block(dev, bs, first + 1 + i, part)?;
        }
    }
    dev.flush().map_err(device_error)
}
