//! Crash-consistent records on a block device: two alternating slots, each a header sector
//! and the payload, with sequence numbers and CRC-32s, so that a power cut at any moment
//! leaves either the previous record or the new one readable, never a mix. The PLC's boot
//! project and its RETAIN snapshots are such records. An interface (the on-disk format);
//! no_std, no allocation; a corrupt slot is reported, never loaded.
//!
//! # Format
//!
//! A region of the disk (`first`, `sectors`, at least 4 sectors of [`SECTOR`] bytes) is cut
//! into two slots of `sectors / 2` sectors. A slot's first sector is its header, the rest
//! its payload (at most [`Region::capacity`] bytes). Header, little-endian:
//!
//! | offset | field |
//! |---|---|
//! | 0 | magic `"WSLT"` |
//! | 4 | version `u16` (1) |
//! | 6 | kind `u16` (what the record is: a region holds one kind) |
//! | 8 | sequence `u64` (1 for the first record, each next one the newest plus one) |
//! | 16 | payload length `u32` |
//! | 20 | payload CRC-32 `u32` |
//! | 24 | header CRC-32 `u32` (of bytes 0..24) |
//!
//! The rest of the header sector is zero.
//!
//! # Writing and reading
//!
//! A write goes to the slot that does not hold the newest valid record: payload sectors,
//! flush, header sector, flush. The newest record is never touched, and a cut anywhere in
//! the write leaves the target slot either with a header and payload that match (its old
//! record, or the new one once its header landed) or with a CRC that fails (the slot reads
//! as corrupt and is skipped): the CRCs, not the order of the writes, keep records from
//! mixing. The flush before the header means a header that reached the disk never
//! describes a payload still in the disk's write-back cache; the flush after it, that the
//! record is on stable storage when `write` returns.
//!
//! [`scan`] reads both slots and checks both CRCs; the newest valid one wins. A slot that
//! was never written reads as [`SlotState::Empty`]; one whose header or payload does not
//! check is [`SlotState::Corrupt`] with the reason, for the health monitor.

#![no_std]

use abi::crc32::Crc32;

/// Bytes of a sector.
pub const SECTOR: usize = 512;
const MAGIC: &[u8; 4] = b"WSLT";
const VERSION: u16 = 1;
const HEADER_LEN: usize = 28;
/// Sectors a scan reads at once.
const RUN_SECTORS: usize = 4;

/// The sector-addressed disk the records live on.
pub trait BlockDevice {
    type Error: core::fmt::Debug;
    fn read(&mut self, sector: u64, buf: &mut [u8; SECTOR]) -> Result<(), Self::Error>;
    fn write(&mut self, sector: u64, data: &[u8; SECTOR]) -> Result<(), Self::Error>;
    /// Returns once every write before it is on stable storage.
    fn flush(&mut self) -> Result<(), Self::Error>;

    /// Reads the sectors from `first` on into `buf` (whole sectors: a length that is no
    /// multiple of [`SECTOR`] reads nothing past the last whole one). A device that moves
    /// several sectors in one request says so here; by default, one at a time.
    fn read_sectors(&mut self, first: u64, buf: &mut [u8]) -> Result<(), Self::Error> {
        for (i, chunk) in buf.as_chunks_mut::<SECTOR>().0.iter_mut().enumerate() {
            self.read(first + i as u64, chunk)?;
        }
        Ok(())
    }

    /// Writes `data` to the sectors from `first` on (whole sectors, as
    /// [`BlockDevice::read_sectors`]). As with single writes, a cut may leave any of them
    /// written or not, and a sector torn.
    fn write_sectors(&mut self, first: u64, data: &[u8]) -> Result<(), Self::Error> {
        for (i, chunk) in data.as_chunks::<SECTOR>().0.iter().enumerate() {
            self.write(first + i as u64, chunk)?;
        }
        Ok(())
    }
}

/// Where a kind of record lives on the disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    pub first: u64,
    pub sectors: u64,
    /// What the records are (stored in each header; a header of another kind is corrupt).
    pub kind: u16,
}

impl Region {
    /// Sectors of one slot.
    fn slot_sectors(&self) -> u64 {
        self.sectors / 2
    }

    fn header_sector(&self, slot: usize) -> u64 {
        self.first + slot as u64 * self.slot_sectors()
    }

    /// Largest payload (0 for a region under 4 sectors).
    pub fn capacity(&self) -> usize {
        (self.slot_sectors().saturating_sub(1) as usize).saturating_mul(SECTOR)
    }
}

/// A valid record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Record {
    pub slot: usize,
    pub sequence: u64,
    pub len: usize,
    pub crc: u32,
}

/// Why a slot does not hold a valid record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Corruption {
    /// The header's CRC, magic, version or kind does not check.
    Header,
    /// The header is fine but claims more payload than the slot holds.
    Length { len: u32 },
    /// The header is fine but the payload does not match its CRC (a torn write).
    Payload { sequence: u64 },
}

impl core::fmt::Display for Corruption {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Corruption::Header => {
                f.write_str("header does not check (CRC, magic, version or kind)")
            }
            Corruption::Length { len } => {
                write!(f, "header claims {len} bytes, more than the slot holds")
            }
            Corruption::Payload { sequence } => {
                write!(
                    f,
                    "payload of record {sequence} does not match its CRC (torn write)"
                )
            }
        }
    }
}

/// What a slot holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlotState {
    /// Never written (no magic).
    Empty,
    Valid(Record),
    Corrupt(Corruption),
}

/// Both slots of a region as [`scan`] found them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Scan {
    pub slots: [SlotState; 2],
    /// The highest sequence number any readable header carries (valid or not), so that a
    /// new record is numbered above every earlier one.
    highest: u64,
}

impl Scan {
    /// The region's state once `record`, just returned by [`write`] for this scan, is on
    /// the disk (so the next write needs no new scan).
    pub fn after(&self, record: Record) -> Scan {
        let mut next = *self;
        if let Some(slot) = next.slots.get_mut(record.slot) {
            *slot = SlotState::Valid(record);
        }
        next.highest = next.highest.max(record.sequence);
        next
    }

    /// The newest valid record.
    pub fn newest(&self) -> Option<Record> {
        self.slots
            .iter()
            .filter_map(|s| match s {
                SlotState::Valid(r) => Some(*r),
                _ => None,
            })
            .max_by_key(|r| r.sequence)
    }
}

/// A failure of the disk or a payload that does not fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error<E> {
    Device(E),
    /// The payload is larger than the region's slots hold.
    TooLarge {
        len: usize,
        capacity: usize,
    },
    /// The region is under 4 sectors.
    Region,
}

fn device<E>(e: E) -> Error<E> {
    Error::Device(e)
}

fn crc(bytes: &[u8]) -> u32 {
    let mut c = Crc32::new();
    c.update(bytes);
    c.finish()
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// The header fields of a sector, if it is a header of `kind`: (sequence, len, payload crc).
fn parse_header(sector: &[u8; SECTOR], kind: u16) -> Option<(u64, u32, u32)> {
    let h = &sector[..HEADER_LEN];
    let ok = &h[..4] == MAGIC
        && u16::from_le_bytes([h[4], h[5]]) == VERSION
        && u16::from_le_bytes([h[6], h[7]]) == kind
        && u32_at(h, 24) == crc(&h[..24]);
    let mut sequence = [0u8; 8];
    sequence.copy_from_slice(&h[8..16]);
    ok.then(|| (u64::from_le_bytes(sequence), u32_at(h, 16), u32_at(h, 20)))
}

/// Reads both slots of `region`, checking every header and payload.
pub fn scan<D: BlockDevice>(dev: &mut D, region: &Region) -> Result<Scan, Error<D::Error>> {
    if region.sectors < 4 {
        return Err(Error::Region);
    }
    let mut buf = [0u8; SECTOR];
    let mut slots = [SlotState::Empty; 2];
    let mut highest = 0;
    for (slot, state) in slots.iter_mut().enumerate() {
        let header = region.header_sector(slot);
        dev.read(header, &mut buf).map_err(device)?;
        let Some((sequence, len, payload_crc)) = parse_header(&buf, region.kind) else {
            if &buf[..4] == MAGIC {
                *state = SlotState::Corrupt(Corruption::Header);
            }
            continue;
        };
        highest = highest.max(sequence);
        if len as usize > region.capacity() {
            *state = SlotState::Corrupt(Corruption::Length { len });
            continue;
        }
        let mut c = Crc32::new();
        let mut left = len as usize;
        let mut sector = header + 1;
        let mut run = [0u8; RUN_SECTORS * SECTOR];
        while left > 0 {
            let sectors = left.div_ceil(SECTOR).min(RUN_SECTORS);
            let run = &mut run[..sectors * SECTOR];
            dev.read_sectors(sector, run).map_err(device)?;
            let n = left.min(run.len());
            c.update(&run[..n]);
            left -= n;
            sector += sectors as u64;
        }
        *state = if c.finish() == payload_crc {
            SlotState::Valid(Record {
                slot,
                sequence,
                len: len as usize,
                crc: payload_crc,
            })
        } else {
            SlotState::Corrupt(Corruption::Payload { sequence })
        };
    }
    Ok(Scan { slots, highest })
}

/// Reads `record`'s payload into `out` (at least `record.len` bytes); returns the length.
/// The CRC is checked again, so a disk that changed since the scan is noticed.
pub fn read<D: BlockDevice>(
    dev: &mut D,
    region: &Region,
    record: &Record,
    out: &mut [u8],
) -> Result<Option<usize>, Error<D::Error>> {
    let Some(out) = out.get_mut(..record.len) else {
        return Err(Error::TooLarge {
            len: record.len,
            capacity: out.len(),
        });
    };
    let first = region.header_sector(record.slot) + 1;
    let whole = out.len() / SECTOR * SECTOR;
    dev.read_sectors(first, &mut out[..whole]).map_err(device)?;
    if whole < out.len() {
        let mut buf = [0u8; SECTOR];
        dev.read(first + (whole / SECTOR) as u64, &mut buf)
            .map_err(device)?;
        let rest = out.len() - whole;
        out[whole..].copy_from_slice(&buf[..rest]);
    }
    Ok((crc(out) == record.crc).then_some(record.len))
}

/// Writes `payload` as the new newest record of `region` (the other slot than the newest
/// valid one of `scan`, which must be the region's current state), and returns it.
pub fn write<D: BlockDevice>(
    dev: &mut D,
    region: &Region,
    scan: &Scan,
    payload: &[u8],
) -> Result<Record, Error<D::Error>> {
    if region.sectors < 4 {
        return Err(Error::Region);
    }
    if payload.len() > region.capacity() {
        return Err(Error::TooLarge {
            len: payload.len(),
            capacity: region.capacity(),
        });
    }
    let slot = scan.newest().map_or(0, |r| 1 - r.slot);
    let header = region.header_sector(slot);
    // The whole sectors as one run (a device may move several a request), then the last,
    // zero-padded.
    let whole = payload.len() / SECTOR * SECTOR;
    dev.write_sectors(header + 1, &payload[..whole])
        .map_err(device)?;
    if whole < payload.len() {
        let mut buf = [0u8; SECTOR];
        buf[..payload.len() - whole].copy_from_slice(&payload[whole..]);
        dev.write(header + 1 + (whole / SECTOR) as u64, &buf)
            .map_err(device)?;
    }
    dev.flush().map_err(device)?;
    let record = Record {
        slot,
        sequence: scan.highest + 1,
        len: payload.len(),
        crc: crc(payload),
    };
    let mut buf = [0u8; SECTOR];
    buf[..4].copy_from_slice(MAGIC);
    buf[4..6].copy_from_slice(&VERSION.to_le_bytes());
    buf[6..8].copy_from_slice(&region.kind.to_le_bytes());
    buf[8..16].copy_from_slice(&record.sequence.to_le_bytes());
    buf[16..20].copy_from_slice(&(payload.len() as u32).to_le_bytes());
    buf[20..24].copy_from_slice(&record.crc.to_le_bytes());
    let header_crc = crc(&buf[..24]);
    buf[24..28].copy_from_slice(&header_crc.to_le_bytes());
    dev.write(header, &buf).map_err(device)?;
    dev.flush().map_err(device)?;
    Ok(record)
}

#[cfg(test)]
mod tests;
