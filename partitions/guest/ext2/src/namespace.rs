//! The namespace operations: lookup, readdir, create, mkdir, symlink, readlink, link,
//! unlink, rmdir and rename, with Linux's semantics and link counts.

use alloc::vec::Vec;

use slots::BlockDevice;

use crate::cache::Kind;
use crate::dir::Found;
use crate::fs::Ext2;
use crate::inode::{FAST_SYMLINK_MAX, Inode};
use crate::{DirEntry, Error, FileType, LINK_MAX, NAME_MAX, ROOT_INO, S_IFDIR, S_IFLNK, S_IFREG};

/// Refuses names no entry may have: empty, too long, with `/` or NUL.
fn check_name(name: &[u8]) -> Result<(), Error> {
    if name.len() > NAME_MAX {
        return Err(Error::NameTooLong);
    }
    if name.is_empty() || name.contains(&b'/') || name.contains(&0) {
        return Err(Error::Invalid);
    }
    Ok(())
}

/// Refuses also `.` and `..`, which only the file system itself changes.
fn check_new_name(name: &[u8]) -> Result<(), Error> {
    check_name(name)?;
    if name == b"." || name == b".." {
        return Err(Error::Invalid);
    }
    Ok(())
}

impl<D: BlockDevice> Ext2<D> {
    /// A directory inode, or [`Error::NotDir`].
    fn directory(&mut self, ino: u32) -> Result<Inode, Error> {
        let inode = self.live_inode(ino)?;
        if !inode.is_dir() {
            return Err(Error::NotDir);
        }
        Ok(inode)
    }

    /// The inode named `name` in directory `dir`, if any (`.` and `..` included).
    pub fn lookup(&mut self, dir: u32, name: &[u8]) -> Result<Option<u32>, Error> {
        check_name(name)?;
        let dir = self.directory(dir)?;
        Ok(self.find_entry(&dir, name)?.map(|found| found.entry.ino))
    }

    /// The first entry of `dir` at or after `cookie` (0 for the first) and the cookie of
    /// the one after it; `None` at the end. Cookies are byte positions in the directory,
    /// stable while entries are added and removed.
    pub fn readdir(&mut self, dir: u32, cookie: u64) -> Result<Option<(DirEntry, u64)>, Error> {
        let dir = self.directory(dir)?;
        self.next_entry(&dir, cookie)
    }

    /// A parent directory that may take a new entry `name`.
    fn parent_for_new(&mut self, dir: u32, name: &[u8]) -> Result<Inode, Error> {
        self.begin_change()?;
        check_new_name(name)?;
        let parent = self.directory(dir)?;
        if parent.links() == 0 {
            return Err(Error::NotFound);
        }
        if self.find_entry(&parent, name)?.is_some() {
            return Err(Error::Exists);
        }
        Ok(parent)
    }

    /// Allocates and writes a fresh inode, then links it into `dir` (the inode reaches the
    /// disk before the entry does); undoes the allocation if the entry cannot be added.
    fn add_new_inode(
        &mut self,
        dir: u32,
        name: &[u8],
        mut build: impl FnMut(&mut Self, &mut Inode) -> Result<(), Error>,
        mode: u16,
    ) -> Result<u32, Error> {
        let is_dir = mode & crate::S_IFMT == S_IFDIR;
        let ino = self.allocate_inode(dir, is_dir)?;
        let mut inode = Inode::new(ino, self.geo.inode_size as usize, mode, self.now);
        let result = build(self, &mut inode).and_then(|()| self.store_inode(&inode));
        let result = result.and_then(|()| {
            self.add_entry(dir, name, ino, FileType::from_mode(mode))
                .map(|_| ())
        });
        if let Err(error) = result {
            if !self.is_fast_symlink(&inode) {
                self.free_blocks_from(&mut inode, 0)?;
            }
            inode.set_links(0);
            inode.set_dtime(self.now.max(1));
            self.store_inode(&inode)?;
            self.free_inode(ino, is_dir)?;
            return Err(error);
        }
        Ok(ino)
    }

    /// Creates an empty regular file `name` in `dir` with permissions `mode & 0o7777`
    /// (owner 0:0; see [`Ext2::chown`]).
    pub fn create(&mut self, dir: u32, name: &[u8], mode: u16) -> Result<u32, Error> {
        self.parent_for_new(dir, name)?;
        self.add_new_inode(dir, name, |_, _| Ok(()), S_IFREG | (mode & 0o7777))
    }

    /// Creates the directory `name` in `dir`, with `.` and `..`.
    pub fn mkdir(&mut self, dir: u32, name: &[u8], mode: u16) -> Result<u32, Error> {
        let parent = self.parent_for_new(dir, name)?;
        if parent.links() >= LINK_MAX {
            return Err(Error::TooManyLinks);
        }
        if self.free_block_count() == 0 {
            return Err(Error::NoSpace);
        }
        let build = |fs: &mut Self, inode: &mut Inode| {
            let block = fs.map_or_allocate(inode, 0)?;
            fs.init_dir_block(block, inode.ino, dir)?;
            inode.set_links(2);
            inode.set_size(u64::from(fs.geo.block_size));
            Ok(())
        };
        let ino = self.add_new_inode(dir, name, build, S_IFDIR | (mode & 0o7777))?;
        let mut parent = self.live_inode(dir)?;
        parent.set_links(parent.links() + 1);
        self.store_inode(&parent)?;
        Ok(ino)
    }

    /// Creates the symbolic link `name` in `dir` pointing at `target`: a fast symlink (in
    /// the inode) under 60 bytes, else one block.
    pub fn symlink(&mut self, dir: u32, name: &[u8], target: &[u8]) -> Result<u32, Error> {
        if target.is_empty() || target.contains(&0) {
            return Err(Error::Invalid);
        }
        if target.len() >= self.geo.block_size as usize {
            return Err(Error::NameTooLong);
        }
        self.parent_for_new(dir, name)?;
        let build = |fs: &mut Self, inode: &mut Inode| {
            if target.len() <= FAST_SYMLINK_MAX {
                inode.block_bytes_mut()[..target.len()].copy_from_slice(target);
            } else {
                let block = fs.map_or_allocate(inode, 0)?;
                fs.disk.modify(block, Kind::Data)?[..target.len()].copy_from_slice(target);
            }
            inode.set_size(target.len() as u64);
            Ok(())
        };
        self.add_new_inode(dir, name, build, S_IFLNK | 0o777)
    }

    /// The target of a symbolic link.
    pub fn readlink(&mut self, ino: u32) -> Result<Vec<u8>, Error> {
        let inode = self.live_inode(ino)?;
        if !inode.is_symlink() {
            return Err(Error::Invalid);
        }
        let size = inode.size() as usize;
        if self.is_fast_symlink(&inode) {
            // Fast: the target is in i_block.
            if size > FAST_SYMLINK_MAX {
                return Err(Error::Corrupt("fast symlink length"));
            }
            return Ok(inode.block_bytes()[..size].to_vec());
        }
        if size >= self.geo.block_size as usize {
            return Err(Error::Corrupt("symlink length"));
        }
        let block = self
            .map_block(&inode, 0)?
            .ok_or(Error::Corrupt("symlink without a block"))?;
        Ok(self.disk.read(block)?[..size].to_vec())
    }

    /// Adds the name `name` in `dir` for the existing inode `ino` (not a directory).
    pub fn link(&mut self, dir: u32, name: &[u8], ino: u32) -> Result<(), Error> {
        self.parent_for_new(dir, name)?;
        let inode = self.live_inode(ino)?;
        if inode.is_dir() {
            return Err(Error::NotPermitted);
        }
        if inode.links() >= LINK_MAX {
            return Err(Error::TooManyLinks);
        }
        if inode.links() == 0 {
            return Err(Error::NotFound);
        }
        self.add_entry(dir, name, ino, FileType::from_mode(inode.mode()))?;
        let mut inode = self.live_inode(ino)?;
        inode.set_links(inode.links() + 1);
        inode.set_ctime(self.now);
        self.store_inode(&inode)
    }

    /// A named entry of `dir` that may be removed, with its inode.
    fn existing(&mut self, dir: u32, name: &[u8]) -> Result<(Found, Inode), Error> {
        self.begin_change()?;
        check_new_name(name)?;
        let parent = self.directory(dir)?;
        let found = self.find_entry(&parent, name)?.ok_or(Error::NotFound)?;
        let inode = self
            .live_inode(found.entry.ino)
            .map_err(|_| Error::Corrupt("directory entry for a free inode"))?;
        Ok((found, inode))
    }

    /// Removes the name `name` (not a directory) from `dir`. Returns the inode number when
    /// that was its last link: the inode lives on until [`Ext2::release`].
    pub fn unlink(&mut self, dir: u32, name: &[u8]) -> Result<Option<u32>, Error> {
        let (found, inode) = self.existing(dir, name)?;
        if inode.is_dir() {
            return Err(Error::IsDir);
        }
        self.remove_entry(dir, &found)?;
        Ok(self.drop_link(inode.ino)?.then_some(inode.ino))
    }

    /// Drops one link of a non-directory; returns whether it was the last (the inode is an
    /// orphan then).
    fn drop_link(&mut self, ino: u32) -> Result<bool, Error> {
        let mut inode = self.live_inode(ino)?;
        let links = inode.links().saturating_sub(1);
        if links == 0 {
            self.entry_gone_first()?;
        }
        inode.set_links(links);
        inode.set_ctime(self.now);
        self.store_inode(&inode)?;
        if links == 0 {
            self.add_orphan(ino);
        }
        Ok(links == 0)
    }

    /// Removes the empty directory `name` from `dir`. Its blocks are freed at once; the
    /// inode (returned) lives on, empty, until [`Ext2::release`].
    pub fn rmdir(&mut self, dir: u32, name: &[u8]) -> Result<u32, Error> {
        let (found, inode) = self.existing(dir, name)?;
        if !inode.is_dir() {
            return Err(Error::NotDir);
        }
        if !self.dir_is_empty(&inode)? {
            return Err(Error::NotEmpty);
        }
        self.remove_entry(dir, &found)?;
        self.empty_removed_dir(inode.ino)?;
        let mut parent = self.live_inode(dir)?;
        parent.set_links(parent.links().saturating_sub(1));
        self.store_inode(&parent)?;
        Ok(inode.ino)
    }

    /// Writes back what is dirty (the directory block that no longer names an inode among
    /// it) before the inode's last link and its blocks go: one write-back pass orders what
    /// a block points to before the pointer ([`crate::cache::Kind`]), right for a new
    /// inode but wrong for a freed one, whose entry must leave the disk first. Without
    /// this, a power cut between the two could leave an entry (a file replaced by `rename`)
    /// naming a freed inode, which `e2fsck` then removes.
    fn entry_gone_first(&mut self) -> Result<(), Error> {
        self.disk.write_back()
    }

    /// A directory whose entry went: no links, no blocks, an orphan.
    fn empty_removed_dir(&mut self, ino: u32) -> Result<(), Error> {
        self.entry_gone_first()?;
        let mut inode = self.live_inode(ino)?;
        inode.set_links(0);
        inode.set_ctime(self.now);
        let result = self.free_blocks_from(&mut inode, 0);
        inode.set_size(0);
        self.store_inode(&inode)?;
        self.add_orphan(ino);
        result
    }

    /// Whether `ino` is `ancestor` or lies below it, walking up through `..` (bounded, so a
    /// corrupt loop of `..` entries ends).
    fn is_within(&mut self, ino: u32, ancestor: u32) -> Result<bool, Error> {
        let mut current = ino;
        for _ in 0..self.geo.inodes_count.min(1 << 16) {
            if current == ancestor {
                return Ok(true);
            }
            if current == ROOT_INO {
                return Ok(false);
            }
            let dir = self.directory(current)?;
            current = self
                .find_entry(&dir, b"..")?
                .ok_or(Error::Corrupt("directory without .."))?
                .entry
                .ino;
        }
        Err(Error::Corrupt("loop of .. entries"))
    }

    /// Renames `old_dir/old_name` to `new_dir/new_name` as Linux does: an existing target
    /// is replaced (a file by a non-directory, an empty directory by a directory), a
    /// directory cannot move into itself, `..` and the parents' link counts follow a moved
    /// directory. The new entry reaches the disk before the old one goes. Returns the
    /// replaced inode when that was its last link (see [`Ext2::release`]).
    pub fn rename(
        &mut self,
        old_dir: u32,
        old_name: &[u8],
        new_dir: u32,
        new_name: &[u8],
    ) -> Result<Option<u32>, Error> {
        let (old_found, source) = self.existing(old_dir, old_name)?;
        check_new_name(new_name)?;
        let target_parent = self.directory(new_dir)?;
        let target = self.find_entry(&target_parent, new_name)?;
        if target.is_some_and(|t| t.entry.ino == source.ino) {
            return Ok(None);
        }
        let moving_dir = source.is_dir();
        if moving_dir && old_dir != new_dir && self.is_within(new_dir, source.ino)? {
            return Err(Error::Invalid);
        }
        let file_type = FileType::from_mode(source.mode());
        let replaced = match target {
            Some(found) => {
                let victim = self.live_inode(found.entry.ino)?;
                match (moving_dir, victim.is_dir()) {
                    (true, false) => return Err(Error::NotDir),
                    (false, true) => return Err(Error::IsDir),
                    (true, true) if !self.dir_is_empty(&victim)? => return Err(Error::NotEmpty),
                    _ => {}
                }
                self.retarget_entry(new_dir, &found, source.ino, file_type)?;
                if found.block != old_found.block {
                    self.write_barrier()?;
                }
                Some(victim)
            }
            None => {
                if moving_dir && old_dir != new_dir && target_parent.links() >= LINK_MAX {
                    return Err(Error::TooManyLinks);
                }
                let block = self.add_entry(new_dir, new_name, source.ino, file_type)?;
                if block != old_found.block {
                    self.write_barrier()?;
                }
                None
            }
        };
        // The new entry may have been carved out of the old entry's block: find it again.
        let old_parent = self.directory(old_dir)?;
        let old_found = self
            .find_entry(&old_parent, old_name)?
            .ok_or(Error::Corrupt("renamed entry vanished"))?;
        self.remove_entry(old_dir, &old_found)?;
        let mut moved = self.live_inode(source.ino)?;
        moved.set_ctime(self.now);
        self.store_inode(&moved)?;
        if moving_dir && old_dir != new_dir {
            let dotdot = self
                .find_entry(&moved, b"..")?
                .ok_or(Error::Corrupt("directory without .."))?;
            self.retarget_entry(source.ino, &dotdot, new_dir, FileType::Directory)?;
            self.add_links(old_dir, -1)?;
            self.add_links(new_dir, 1)?;
        }
        let Some(victim) = replaced else {
            return Ok(None);
        };
        if victim.is_dir() {
            self.empty_removed_dir(victim.ino)?;
            self.add_links(new_dir, -1)?;
            Ok(Some(victim.ino))
        } else {
            Ok(self.drop_link(victim.ino)?.then_some(victim.ino))
        }
    }

    fn add_links(&mut self, ino: u32, delta: i32) -> Result<(), Error> {
        let mut inode = self.live_inode(ino)?;
        let links = (i32::from(inode.links()) + delta).clamp(0, i32::from(u16::MAX));
        inode.set_links(links as u16);
        inode.set_ctime(self.now);
        self.store_inode(&inode)
    }

    /// Everything changed so far reaches the disk before anything after.
    fn write_barrier(&mut self) -> Result<(), Error> {
        self.disk.write_back()?;
        self.disk.flush()
    }
}
