//! The guest's block device `/dev/vda` ([`crate::vfs::dev::Device::Disk`], device number
//! [`MAJOR`]:[`MINOR`]): the guest partition's virtual disk of a block-device partition
//! (`guest.disk` in the configuration; its `blk.tenants.<guest>` range), reached over the
//! block-device link (`blk_core::client::Client`: up to four sectors a request, CRC-checked).
//!
//! The configuration reaches the guest in its initramfs, [`DISK_PATH`] (written by
//! `cargo xtask` from `guest.disk` and the tenant's `sectors`): `key=value` lines,
//! `request` and `response` (the guest's queuing ports of the link) and `sectors` (the
//! disk's size in sectors of 512 bytes). Without the file there is no `/dev/vda`
//! (`ENOENT`, as on a Linux without the disk).
//!
//! What a Linux call on the device means, as for a Linux block device file (the calls in
//! [`crate::syscall::file`], the device itself, [`Disk`], here):
//!
//! - `read`, `pread64`, `readv` at any offset and length: up to the disk's end (0 at or
//!   past it); `write`, `pwrite64`, `writev` too, a part of a sector read, changed and
//!   written back; a write that starts at or past the end fails with `ENOSPC`, one that
//!   crosses it writes up to it. At most [`MAX_TRANSFER`] bytes a call (a short count: a
//!   request waits for the block-device partition, and the guest serves nobody else
//!   meanwhile).
//! - `lseek`: `SEEK_END` is the disk's size; an offset past it is `EINVAL`, as Linux's
//!   fixed-size seek has it. `stat` shows a block device (`S_IFBLK`, size 0 as on Linux).
//! - `fsync`, `fdatasync`, `syncfs`, `sync` and the ioctl `BLKFLSBUF` send the link's
//!   flush: every write before it is on the disk's stable storage.
//! - ioctls ([`ioctl`]): `BLKGETSIZE64` (bytes), `BLKGETSIZE` (sectors), `BLKSSZGET` and
//!   `BLKPBSZGET` (512), `BLKROGET` (0), `BLKDISCARDZEROES` (0), `BLKFLSBUF`; others
//!   `ENOTTY`.
//!
//! Writes go through to the disk at once (a `write` returns when the driver has it);
//! [`Disk`] keeps the last [`CACHE_SECTORS`] sectors read or written, so reading them again
//! and the read half of a partial-sector write cost no request. A request that fails (the
//! link's CRC, tag or status, no answer) makes the call fail with `EIO` and is logged
//! (`guest: /dev/vda: <read|write|flush> of sector <n> failed: <why>`, at most
//! [`MAX_LOGGED`] lines, then one saying the rest are not); the failed sector leaves the
//! cache. No sector outside the disk is ever asked for (and the driver refuses requests
//! outside the tenant's range itself).

use crate::linux::Errno;
use alloc::boxed::Box;
use alloc::vec::Vec;

/// Where the guest finds `/dev/vda`'s configuration in the initramfs.
pub const DISK_PATH: &str = "/etc/guest/disk";
/// The device's path.
pub const DEVICE_PATH: &str = "/dev/vda";
/// Its device number: Linux's virtio-blk (the first dynamic block major), disk 0.
pub const MAJOR: u64 = 254;
pub const MINOR: u64 = 0;
/// Bytes of a sector.
pub const SECTOR: usize = 512;
/// Sectors kept in the cache.
pub const CACHE_SECTORS: usize = 64;
/// Most bytes one `read` or `write` call moves.
pub const MAX_TRANSFER: usize = 64 * 1024;
/// Most error lines logged.
pub const MAX_LOGGED: u32 = 16;

/// `ioctl` requests (x86-64 numbers).
pub const BLKROGET: u64 = 0x125e;
pub const BLKGETSIZE: u64 = 0x1260;
pub const BLKFLSBUF: u64 = 0x1261;
pub const BLKSSZGET: u64 = 0x1268;
pub const BLKGETSIZE64: u64 = 0x8008_1272;
pub const BLKPBSZGET: u64 = 0x127b;
pub const BLKDISCARDZEROES: u64 = 0x127c;

/// `/dev/vda`'s configuration, from the file at [`DISK_PATH`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DiskFile<'a> {
    pub request: &'a str,
    pub response: &'a str,
    pub sectors: u64,
}

/// Parses the file at [`DISK_PATH`]; the error names the line and what is wrong.
pub fn parse_disk_file(text: &str) -> Result<DiskFile<'_>, (usize, &'static str)> {
    let (mut request, mut response, mut sectors) = (None, None, None);
    for setting in crate::settings(text) {
        let (at, key, value) = setting?;
        match key {
            "request" => request = Some(value),
            "response" => response = Some(value),
            "sectors" => {
                let s = value
                    .parse::<u64>()
                    .ok()
                    // Its size in bytes fits an `i64` (`lseek`).
                    .filter(|&s| s > 0 && s <= (i64::MAX as u64) / SECTOR as u64)
                    .ok_or((at, "sectors is no number of sectors"))?;
                sectors = Some(s);
            }
            _ => return Err((at, "unknown key")),
        }
    }
    let last = text.lines().count();
    Ok(DiskFile {
        request: request.ok_or((last, "no request port"))?,
        response: response.ok_or((last, "no response port"))?,
        sectors: sectors.ok_or((last, "no sectors"))?,
    })
}

/// What a request of the device is, for the log.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Op {
    Read,
    Write,
    Flush,
}

impl Op {
    fn name(self) -> &'static str {
        match self {
            Op::Read => "read",
            Op::Write => "write",
            Op::Flush => "flush",
        }
    }
}

/// A cached sector.
struct Slot {
    /// [`EMPTY`] for a slot that holds none.
    sector: u64,
    /// When it was last used ([`Disk::clock`]).
    used: u64,
    data: Box<[u8; SECTOR]>,
}

/// A cache slot's sector when it holds none (no disk has that many sectors).
const EMPTY: u64 = u64::MAX;

/// The virtual disk as a file: byte offsets and lengths onto whole sectors of `device`
/// (`sectors` of them), with a write-through cache of [`CACHE_SECTORS`] sectors (allocated
/// at once: serving a call allocates nothing).
pub struct Disk<D> {
    device: D,
    sectors: u64,
    cache: Vec<Slot>,
    clock: u64,
    /// Error lines logged so far.
    logged: u32,
    log: fn(core::fmt::Arguments),
}

impl<D: slots::BlockDevice> Disk<D>
where
    D::Error: core::fmt::Display,
{
    /// The disk of `sectors` sectors on `device`; `log` writes a log line.
    pub fn new(device: D, sectors: u64, log: fn(core::fmt::Arguments)) -> Self {
        Disk {
            device,
            sectors,
            cache: (0..CACHE_SECTORS)
                .map(|_| Slot {
                    sector: EMPTY,
                    used: 0,
                    data: Box::new([0; SECTOR]),
                })
                .collect(),
            clock: 0,
            logged: 0,
            log,
        }
    }

    /// Its size in bytes.
    pub fn size(&self) -> u64 {
        self.sectors * SECTOR as u64
    }

    /// The device (tests).
    pub fn device_mut(&mut self) -> &mut D {
        &mut self.device
    }

    /// A failed request: logged (within [`MAX_LOGGED`]) and `EIO`.
    fn failed(&mut self, op: Op, sector: u64, why: &D::Error) -> Errno {
        if self.logged < MAX_LOGGED {
            (self.log)(format_args!(
                "guest: {DEVICE_PATH}: {} of sector {sector} failed: {why}",
                op.name()
            ));
        } else if self.logged == MAX_LOGGED {
            (self.log)(format_args!(
                "guest: {DEVICE_PATH}: more requests failed, not logged"
            ));
        }
        self.logged = self.logged.saturating_add(1);
        Errno::EIO
    }

    fn cached(&mut self, sector: u64) -> Option<usize> {
        let i = self.cache.iter().position(|s| s.sector == sector)?;
        self.clock += 1;
        self.cache[i].used = self.clock;
        Some(i)
    }

    /// Keeps `data` as sector `sector`'s (in its slot, else in an empty one, else in the
    /// least recently used).
    fn keep(&mut self, sector: u64, data: &[u8; SECTOR]) {
        self.clock += 1;
        let used = self.clock;
        let slot = match self.cache.iter().position(|s| s.sector == sector) {
            Some(i) => self.cache.get_mut(i),
            // Empty slots were last used at 0: the least recently used.
            None => self.cache.iter_mut().min_by_key(|s| s.used),
        };
        if let Some(slot) = slot {
            slot.sector = sector;
            slot.used = used;
            *slot.data = *data;
        }
    }

    fn forget(&mut self, sector: u64) {
        for slot in self.cache.iter_mut().filter(|s| s.sector == sector) {
            (slot.sector, slot.used) = (EMPTY, 0);
        }
    }

    /// Sectors in the cache (tests).
    pub fn cached_sectors(&self) -> usize {
        self.cache.iter().filter(|s| s.sector != EMPTY).count()
    }

    /// Sectors from `first` on (inside the disk) into `buf` (whole sectors): from the cache
    /// when it holds them all, else as one run from the device (then kept). When the run
    /// fails, its sectors are read one at a time to find the one that does: the error
    /// comes with the bytes read before it (logged for that sector).
    fn read_run(&mut self, first: u64, buf: &mut [u8]) -> Result<(), (usize, Errno)> {
        let count = (buf.len() / SECTOR) as u64;
        debug_assert!(first + count <= self.sectors);
        // One look-up per sector: a miss stops the copying and the device reads the run.
        let mut all_cached = true;
        for (i, chunk) in buf.as_chunks_mut::<SECTOR>().0.iter_mut().enumerate() {
            match self.cached(first + i as u64) {
                Some(slot) => *chunk = *self.cache[slot].data,
                None => {
                    all_cached = false;
                    break;
                }
            }
        }
        if all_cached {
            return Ok(());
        }
        let whole = self.device.read_sectors(first, buf).is_ok();
        for (i, chunk) in buf.as_chunks_mut::<SECTOR>().0.iter_mut().enumerate() {
            let sector = first + i as u64;
            if !whole && let Err(e) = self.device.read(sector, chunk) {
                return Err((i * SECTOR, self.failed(Op::Read, sector, &e)));
            }
            self.keep(sector, chunk);
        }
        Ok(())
    }

    /// Writes the sectors from `first` on (inside the disk) through to the device, as one
    /// run; when it fails, one at a time (writing a sector again is harmless) to find the
    /// one that does: the error comes with the bytes written before it.
    fn write_run(&mut self, first: u64, data: &[u8]) -> Result<(), (usize, Errno)> {
        let whole = self.device.write_sectors(first, data).is_ok();
        for (i, chunk) in data.as_chunks::<SECTOR>().0.iter().enumerate() {
            let sector = first + i as u64;
            if !whole && let Err(e) = self.device.write(sector, chunk) {
                // What the disk holds from there on is unknown now.
                for later in sector..first + (data.len() / SECTOR) as u64 {
                    self.forget(later);
                }
                return Err((i * SECTOR, self.failed(Op::Write, sector, &e)));
            }
            self.keep(sector, chunk);
        }
        Ok(())
    }

    /// Whether sectors `first..first + count` lie inside the disk.
    fn inside(&self, first: u64, count: u64) -> bool {
        first
            .checked_add(count)
            .is_some_and(|end| end <= self.sectors)
    }

    /// `read` at byte `offset`: the bytes up to the disk's end (0 at or past it; at most
    /// [`MAX_TRANSFER`]). A failure after some bytes were read returns those.
    pub fn read(&mut self, offset: u64, buf: &mut [u8]) -> Result<usize, Errno> {
        let size = self.size();
        if offset >= size {
            return Ok(0);
        }
        let len = (buf.len() as u64)
            .min(size - offset)
            .min(MAX_TRANSFER as u64) as usize;
        let mut done = 0;
        let mut sector_buf = [0u8; SECTOR];
        while done < len {
            let at = offset + done as u64;
            let sector = at / SECTOR as u64;
            let within = (at % SECTOR as u64) as usize;
            let whole = if within == 0 {
                (len - done) / SECTOR * SECTOR
            } else {
                0
            };
            let (n, step) = if whole > 0 {
                (whole, self.read_run(sector, &mut buf[done..done + whole]))
            } else {
                let n = (SECTOR - within).min(len - done);
                let step = self.read_run(sector, &mut sector_buf);
                if step.is_ok() {
                    buf[done..done + n].copy_from_slice(&sector_buf[within..within + n]);
                }
                (n, step.map_err(|(_, e)| (0, e)))
            };
            if let Err((part, e)) = step {
                done += part;
                return if done > 0 { Ok(done) } else { Err(e) };
            }
            done += n;
        }
        Ok(done)
    }

    /// `write` at byte `offset`: up to the disk's end (`ENOSPC` at or past it; at most
    /// [`MAX_TRANSFER`]); a partial sector is read, changed and written. A failure after
    /// some bytes were written returns those.
    pub fn write(&mut self, offset: u64, data: &[u8]) -> Result<usize, Errno> {
        let size = self.size();
        if data.is_empty() {
            return Ok(0);
        }
        if offset >= size {
            return Err(Errno::ENOSPC);
        }
        let len = (data.len() as u64)
            .min(size - offset)
            .min(MAX_TRANSFER as u64) as usize;
        let mut done = 0;
        let mut sector_buf = [0u8; SECTOR];
        while done < len {
            let at = offset + done as u64;
            let sector = at / SECTOR as u64;
            let within = (at % SECTOR as u64) as usize;
            let whole = if within == 0 {
                (len - done) / SECTOR * SECTOR
            } else {
                0
            };
            let (n, step) = if whole > 0 {
                (whole, self.write_run(sector, &data[done..done + whole]))
            } else {
                let n = (SECTOR - within).min(len - done);
                let step = (|| {
                    if n < SECTOR {
                        self.read_run(sector, &mut sector_buf)?;
                    }
                    sector_buf[within..within + n].copy_from_slice(&data[done..done + n]);
                    self.write_run(sector, &sector_buf)
                })();
                (n, step.map_err(|(_, e)| (0, e)))
            };
            if let Err((part, e)) = step {
                done += part;
                return if done > 0 { Ok(done) } else { Err(e) };
            }
            done += n;
        }
        Ok(done)
    }

    /// `fsync` and the other syncs: the link's flush (the writes are on the device
    /// already: the cache is write-through).
    pub fn sync(&mut self) -> Result<(), Errno> {
        self.device
            .flush()
            .map_err(|e| self.failed(Op::Flush, 0, &e))
    }

    /// `BLKFLSBUF`: the flush, then the cache is dropped (the next reads ask the device).
    pub fn flush_buffers(&mut self) -> Result<(), Errno> {
        self.sync()?;
        for slot in &mut self.cache {
            (slot.sector, slot.used) = (EMPTY, 0);
        }
        Ok(())
    }
}

/// The disk as the system calls use it (the file system holds it: [`crate::vfs::Fs::disk`]),
/// and, whole sectors at a time, as the file system mounted on it does ([`Volume`]).
pub trait BlockFile {
    /// Its size in bytes.
    fn size(&self) -> u64;
    /// The sectors from `first` on into `buf`, whole sectors (`EIO` past the end).
    fn read_sectors(&mut self, first: u64, buf: &mut [u8]) -> Result<(), Errno>;
    /// Writes the sectors from `first` on through to the device, whole sectors (`EIO` past
    /// the end).
    fn write_sectors(&mut self, first: u64, data: &[u8]) -> Result<(), Errno>;
    /// [`Disk::read`].
    fn read(&mut self, offset: u64, buf: &mut [u8]) -> Result<usize, Errno>;
    /// [`Disk::write`].
    fn write(&mut self, offset: u64, data: &[u8]) -> Result<usize, Errno>;
    /// [`Disk::sync`].
    fn sync(&mut self) -> Result<(), Errno>;
    /// [`Disk::flush_buffers`].
    fn flush_buffers(&mut self) -> Result<(), Errno>;
}

impl<D: slots::BlockDevice> BlockFile for Disk<D>
where
    D::Error: core::fmt::Display,
{
    fn size(&self) -> u64 {
        Disk::size(self)
    }
    fn read_sectors(&mut self, first: u64, buf: &mut [u8]) -> Result<(), Errno> {
        let whole = buf.len() / SECTOR * SECTOR;
        if !self.inside(first, (whole / SECTOR) as u64) {
            return Err(Errno::EIO);
        }
        self.read_run(first, &mut buf[..whole]).map_err(|(_, e)| e)
    }
    fn write_sectors(&mut self, first: u64, data: &[u8]) -> Result<(), Errno> {
        let whole = data.len() / SECTOR * SECTOR;
        if !self.inside(first, (whole / SECTOR) as u64) {
            return Err(Errno::EIO);
        }
        self.write_run(first, &data[..whole]).map_err(|(_, e)| e)
    }
    fn read(&mut self, offset: u64, buf: &mut [u8]) -> Result<usize, Errno> {
        Disk::read(self, offset, buf)
    }
    fn write(&mut self, offset: u64, data: &[u8]) -> Result<usize, Errno> {
        Disk::write(self, offset, data)
    }
    fn sync(&mut self) -> Result<(), Errno> {
        Disk::sync(self)
    }
    fn flush_buffers(&mut self) -> Result<(), Errno> {
        Disk::flush_buffers(self)
    }
}

/// The disk under a mounted file system ([`crate::vfs::mounted`]): its sectors as a
/// [`slots::BlockDevice`] (through the disk's sector cache, runs of sectors as runs of
/// requests; failures are logged by the disk and come back as `EIO`).
pub struct Volume(pub Box<dyn BlockFile>);

impl core::fmt::Debug for Volume {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "Volume({} bytes)", self.0.size())
    }
}

impl slots::BlockDevice for Volume {
    type Error = Errno;
    fn read(&mut self, sector: u64, buf: &mut [u8; SECTOR]) -> Result<(), Errno> {
        self.0.read_sectors(sector, buf)
    }
    fn write(&mut self, sector: u64, data: &[u8; SECTOR]) -> Result<(), Errno> {
        self.0.write_sectors(sector, data)
    }
    fn flush(&mut self) -> Result<(), Errno> {
        self.0.sync()
    }
    fn read_sectors(&mut self, first: u64, buf: &mut [u8]) -> Result<(), Errno> {
        self.0.read_sectors(first, buf)
    }
    fn write_sectors(&mut self, first: u64, data: &[u8]) -> Result<(), Errno> {
        self.0.write_sectors(first, data)
    }
}

/// What an `ioctl` of the device answers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Answer {
    /// Store this 8-byte value at the argument.
    U64(u64),
    /// Store this 4-byte value at the argument.
    U32(u32),
    /// `BLKFLSBUF`: flush, then drop the cache ([`Disk::flush_buffers`]).
    FlushBuffers,
}

/// The answer to `ioctl(request)` on a disk of `size` bytes (`ENOTTY` for requests a
/// block device does not know here).
pub fn ioctl(request: u64, size: u64) -> Result<Answer, Errno> {
    match request & 0xffff_ffff {
        BLKGETSIZE64 => Ok(Answer::U64(size)),
        BLKGETSIZE => Ok(Answer::U64(size / SECTOR as u64)),
        BLKSSZGET | BLKPBSZGET => Ok(Answer::U32(SECTOR as u32)),
        BLKROGET | BLKDISCARDZEROES => Ok(Answer::U32(0)),
        BLKFLSBUF => Ok(Answer::FlushBuffers),
        _ => Err(Errno::ENOTTY),
    }
}

/// The offset `lseek(offset, whence)` gives on a disk of `size` bytes whose description is
/// at `current`: `EINVAL` before 0 or past the end (Linux's fixed-size seek).
pub fn seek(current: u64, offset: i64, whence: u64, size: u64) -> Result<u64, Errno> {
    let base = match whence {
        0 => 0,
        1 => current as i64,
        2 => size as i64,
        _ => return Err(Errno::EINVAL),
    };
    base.checked_add(offset)
        .filter(|&n| n >= 0 && n as u64 <= size)
        .map(|n| n as u64)
        .ok_or(Errno::EINVAL)
}

#[cfg(test)]
mod tests;
