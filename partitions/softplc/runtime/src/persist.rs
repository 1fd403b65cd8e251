//! The PLC's persistent store on its virtual disk (a tenant's range of the block-device
//! partition, reached as a `slots::BlockDevice`): where the boot project and the RETAIN
//! snapshots live ([`Layout`]), what start finds ([`load`]: the newest valid record of
//! each region; a torn or corrupt slot skipped and reported, never loaded) and the saves
//! ([`Store::save_boot`], [`Store::save_retain`]). The payloads are [`crate::store`]'s,
//! the crash-consistent slots `slots`'s. Called by the control process between releases,
//! never on the scan path.
//!
//! Disk layout (sectors of the PLC's virtual disk, an interface): the RETAIN region is the
//! last quarter (at most [`RETAIN_MAX_SECTORS`], an even count), the boot-project region
//! everything before it (an even count); each region is two alternating slots
//! (`common/slots`: a header sector, then the payload). A virtual disk of fewer than 8
//! sectors holds no store. Zeroing the virtual disk (or deleting the disk image) resets
//! both: the PLC then starts its configured program with initial values.

use crate::store::{self, StoreError};
use core::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use plc_online::StoreStatus;
use plc_vm::image::Image;
use slots::{BlockDevice, Corruption, Record, Region, Scan, SlotState};

/// What the store loaded at the last cold start and saved since (the online service's
/// STORE answers it): the partition's store glue sets it, sequence numbers, 0 for none.
pub static STATUS: StatusCell = StatusCell::new();

/// [`StoreStatus`] shared between the store process and the control process.
pub struct StatusCell {
    configured: AtomicBool,
    /// boot loaded, RETAIN loaded, boot saved, RETAIN saved.
    numbers: [AtomicU64; 4],
}

impl StatusCell {
    pub const fn new() -> Self {
        StatusCell {
            configured: AtomicBool::new(false),
            numbers: [const { AtomicU64::new(0) }; 4],
        }
    }

    /// A cold start with a store: nothing loaded or saved yet.
    pub fn cold_start(&self) {
        self.configured.store(true, Ordering::Release);
        for n in &self.numbers {
            n.store(0, Ordering::Release);
        }
    }

    pub fn boot_loaded(&self, sequence: u64) {
        self.numbers[0].store(sequence, Ordering::Release);
    }

    pub fn retain_loaded(&self, sequence: u64) {
        self.numbers[1].store(sequence, Ordering::Release);
    }

    pub fn boot_saved(&self, sequence: u64) {
        self.numbers[2].store(sequence, Ordering::Release);
    }

    pub fn retain_saved(&self, sequence: u64) {
        self.numbers[3].store(sequence, Ordering::Release);
    }

    pub fn get(&self) -> StoreStatus {
        let n = |i: usize| self.numbers[i].load(Ordering::Acquire);
        StoreStatus {
            configured: self.configured.load(Ordering::Acquire),
            boot_loaded: n(0),
            retain_loaded: n(1),
            boot_saved: n(2),
            retain_saved: n(3),
        }
    }
}

impl Default for StatusCell {
    fn default() -> Self {
        Self::new()
    }
}

/// The kinds in the slots' headers.
pub const BOOT_KIND: u16 = 1;
pub const RETAIN_KIND: u16 = 2;
/// The most sectors the RETAIN region takes (256 KiB).
pub const RETAIN_MAX_SECTORS: u64 = 512;

/// Where the two kinds of record live.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    pub boot: Region,
    pub retain: Region,
}

impl Layout {
    /// The layout of a virtual disk of `sectors` sectors; `None` under 8.
    pub fn of(sectors: u64) -> Option<Layout> {
        if sectors < 8 {
            return None;
        }
        let retain = (sectors / 4).clamp(4, RETAIN_MAX_SECTORS) & !1;
        let boot = (sectors - retain) & !1;
        Some(Layout {
            boot: Region {
                first: 0,
                sectors: boot,
                kind: BOOT_KIND,
            },
            retain: Region {
                first: boot,
                sectors: retain,
                kind: RETAIN_KIND,
            },
        })
    }
}

/// Why the store could not do something.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PersistError<E> {
    /// The disk (the link to the block-device partition) failed.
    Disk(slots::Error<E>),
    /// The payload could not be encoded (too large for the buffer).
    Encode(StoreError),
}

impl<E: core::fmt::Debug> core::fmt::Display for PersistError<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Disk(slots::Error::Device(e)) => write!(f, "disk: {e:?}"),
            Self::Disk(slots::Error::TooLarge { len, capacity }) => {
                write!(f, "{len} bytes, the region's slots hold {capacity}")
            }
            Self::Disk(slots::Error::Region) => write!(f, "the region is under 4 sectors"),
            Self::Encode(e) => write!(f, "{e}"),
        }
    }
}

/// What start found in one region.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Found {
    /// The record loaded (its payload in the caller's buffer, `len` bytes), if any.
    pub loaded: Option<Record>,
    /// Slots skipped: corrupt or torn (for the health monitor and the log).
    pub skipped: [Option<(usize, Corruption)>; 2],
}

/// The store after start: each region's state, so that saves need no new scan.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Store {
    pub layout: Layout,
    boot: Scan,
    retain: Scan,
}

/// Reads `region`: the newest valid record's payload into `out`. A record whose payload
/// no longer checks when read (the disk changed since the scan) is skipped too, and the
/// other valid one, if any, is taken.
fn load_region<D: BlockDevice>(
    dev: &mut D,
    region: &Region,
    out: &mut [u8],
) -> Result<(Scan, Found), slots::Error<D::Error>> {
    let scan = slots::scan(dev, region)?;
    let mut found = Found {
        loaded: None,
        skipped: [None, None],
    };
    for (slot, state) in scan.slots.iter().enumerate() {
        if let SlotState::Corrupt(c) = state {
            found.skipped[slot] = Some((slot, *c));
        }
    }
    let mut valid: [Option<Record>; 2] = [None, None];
    for (i, state) in scan.slots.iter().enumerate() {
        if let SlotState::Valid(r) = state {
            valid[i] = Some(*r);
        }
    }
    valid.sort_unstable_by_key(|r| core::cmp::Reverse(r.map(|r| r.sequence)));
    for record in valid.into_iter().flatten() {
        match slots::read(dev, region, &record, out) {
            Ok(Some(_)) => {
                found.loaded = Some(record);
                break;
            }
            Ok(None) => {
                found.skipped[record.slot] = Some((
                    record.slot,
                    Corruption::Payload {
                        sequence: record.sequence,
                    },
                ));
            }
            // Larger than the buffer: not loadable by this runtime; skipped.
            Err(slots::Error::TooLarge { len, .. }) => {
                found.skipped[record.slot] = Some((
                    record.slot,
                    Corruption::Length {
                        len: len.try_into().unwrap_or(u32::MAX),
                    },
                ));
            }
            Err(e) => return Err(e),
        }
    }
    Ok((scan, found))
}

/// Start: both regions of `layout` read; the newest valid boot project into `boot_out`,
/// the newest valid RETAIN snapshot into `retain_out`. The caller decodes them
/// ([`store::decode_boot`], [`store::decode_retain`]) and verifies the program as it
/// verifies a download.
pub fn load<D: BlockDevice>(
    dev: &mut D,
    layout: Layout,
    boot_out: &mut [u8],
    retain_out: &mut [u8],
) -> Result<(Store, Found, Found), PersistError<D::Error>> {
    let (boot, boot_found) =
        load_region(dev, &layout.boot, boot_out).map_err(PersistError::Disk)?;
    let (retain, retain_found) =
        load_region(dev, &layout.retain, retain_out).map_err(PersistError::Disk)?;
    Ok((
        Store {
            layout,
            boot,
            retain,
        },
        boot_found,
        retain_found,
    ))
}

impl Store {
    /// Saves the boot project (a committed download: its program and watch list, from
    /// `release`), `buf` the encoding space. The previous boot project stays valid until
    /// this one is whole on the disk.
    pub fn save_boot<D: BlockDevice>(
        &mut self,
        dev: &mut D,
        release: u64,
        program: &[u8],
        watch: &str,
        buf: &mut [u8],
    ) -> Result<Record, PersistError<D::Error>> {
        let n = store::encode_boot(release, program, watch, buf).map_err(PersistError::Encode)?;
        self.write_boot(dev, &buf[..n])
    }

    /// Writes an encoded boot project ([`store::encode_boot`]: the partition's control
    /// process encodes, its store process writes).
    pub fn write_boot<D: BlockDevice>(
        &mut self,
        dev: &mut D,
        payload: &[u8],
    ) -> Result<Record, PersistError<D::Error>> {
        let record = slots::write(dev, &self.layout.boot, &self.boot, payload)
            .map_err(PersistError::Disk)?;
        self.boot = self.boot.after(record);
        Ok(record)
    }

    /// Writes an encoded RETAIN snapshot ([`store::encode_retain`]).
    pub fn write_retain<D: BlockDevice>(
        &mut self,
        dev: &mut D,
        payload: &[u8],
    ) -> Result<Record, PersistError<D::Error>> {
        let record = slots::write(dev, &self.layout.retain, &self.retain, payload)
            .map_err(PersistError::Disk)?;
        self.retain = self.retain.after(record);
        Ok(record)
    }

    /// Saves a RETAIN snapshot of `data` (the running program `image`, whose bytecode
    /// has CRC-32 `program_crc`) taken at `release`.
    pub fn save_retain<D: BlockDevice>(
        &mut self,
        dev: &mut D,
        image: &Image,
        program_crc: u32,
        data: &[u8],
        release: u64,
        buf: &mut [u8],
    ) -> Result<Record, PersistError<D::Error>> {
        let n = store::encode_retain(image, program_crc, data, release, buf)
            .map_err(PersistError::Encode)?;
        self.write_retain(dev, &buf[..n])
    }
}

/// The releases between two RETAIN saves: `every_ns` (`plc.store`'s `retain_every`) in
/// partition periods of `period_ns`, at least 1.
pub fn retain_every_releases(every_ns: u64, period_ns: u64) -> u64 {
    every_ns.div_ceil(period_ns.max(1)).max(1)
}

#[cfg(test)]
mod tests;
