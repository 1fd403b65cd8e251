//! What the PLC keeps across a power cut: the boot project (the program of the last
//! committed download, with its watch list) and RETAIN snapshots (the RETAIN variables'
//! values at the end of a release), each a record in its own region of the partition's
//! disk, written crash-consistently by the `slots` format (two alternating slots: the newest
//! valid record wins, a torn one is detected and skipped). This module is the records'
//! payload formats and the restore rules; an interface, all integers little-endian, and
//! decoding never panics: a damaged payload is a [`StoreError`] naming the offset.
//!
//! ```text
//! boot project                          RETAIN snapshot
//! 0  4 magic "WBPJ"                     0  4 magic "WRET"
//! 4  2 version (1)                      4  2 version (1)
//! 6  2 reserved (0)                     6  2 variable count N
//! 8  8 release of the download          8  8 release the values are from
//! 16 4 program length P                 16 4 CRC-32 of the program they were taken in
//! 20 4 watch list length W              20    N variables:
//! 24 P the program (bytecode image)           1 type (VarType code), 1 name length L,
//! .. W the watch list (names, `\n`)           2 value length V, L name (UTF-8), V bytes
//! ```
//!
//! Restoring a snapshot into a program (the boot project's, or the configured one) follows
//! the rules of an online download's RETAIN hand-over ([`crate::scan::carry_value`]): a
//! RETAIN variable of the program gets the snapshot's value of the variable with the same
//! name and type; a STRING keeps its text cut to its capacity; a reference only when the
//! program is the one the snapshot was taken in (same CRC). The saving is the control
//! process's, between releases (never on the scan path): every [`RetainSchedule`]
//! interval, and at every STOP and download.

use crate::scan::carry_value;
use plc_vm::image::{Image, VAR_FLAG_RETAIN, VarType};

const BOOT_MAGIC: &[u8; 4] = b"WBPJ";
const RETAIN_MAGIC: &[u8; 4] = b"WRET";
const VERSION: u16 = 1;
const BOOT_HEADER: usize = 24;
const RETAIN_HEADER: usize = 20;

/// Why a record's payload was refused, or could not be written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StoreError {
    /// Not this kind of record.
    Magic,
    /// A version this runtime does not read.
    Version(u16),
    /// The payload ends before the field at this offset.
    Truncated { at: usize },
    /// The field at this offset is not valid (`what`).
    Invalid { at: usize, what: &'static str },
    /// The output buffer holds fewer than `needed` bytes.
    TooSmall { needed: usize },
}

impl core::fmt::Display for StoreError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            StoreError::Magic => f.write_str("not a record of this kind (magic)"),
            StoreError::Version(v) => write!(f, "version {v}, this runtime reads 1"),
            StoreError::Truncated { at } => write!(f, "ends inside the field at byte {at}"),
            StoreError::Invalid { at, what } => write!(f, "byte {at}: {what}"),
            StoreError::TooSmall { needed } => write!(f, "needs {needed} bytes of buffer"),
        }
    }
}

fn le16(b: &[u8], at: usize) -> Result<u16, StoreError> {
    b.get(at..at + 2)
        .map(|s| u16::from_le_bytes([s[0], s[1]]))
        .ok_or(StoreError::Truncated { at })
}

fn le32(b: &[u8], at: usize) -> Result<u32, StoreError> {
    b.get(at..at + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
        .ok_or(StoreError::Truncated { at })
}

fn le64(b: &[u8], at: usize) -> Result<u64, StoreError> {
    let s = b.get(at..at + 8).ok_or(StoreError::Truncated { at })?;
    let mut w = [0u8; 8];
    w.copy_from_slice(s);
    Ok(u64::from_le_bytes(w))
}

fn header(bytes: &[u8], magic: &[u8; 4]) -> Result<(), StoreError> {
    if bytes.get(..4).ok_or(StoreError::Truncated { at: 0 })? != magic {
        return Err(StoreError::Magic);
    }
    match le16(bytes, 4)? {
        VERSION => Ok(()),
        v => Err(StoreError::Version(v)),
    }
}

/// A boot project read from its record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BootProject<'a> {
    pub release: u64,
    /// The bytecode image (verified by the runtime before it runs, as a download is).
    pub program: &'a [u8],
    pub watch: &'a str,
}

/// Writes a boot project's payload into `out`; returns its length.
pub fn encode_boot(
    release: u64,
    program: &[u8],
    watch: &str,
    out: &mut [u8],
) -> Result<usize, StoreError> {
    let needed = BOOT_HEADER + program.len() + watch.len();
    let out = out
        .get_mut(..needed)
        .ok_or(StoreError::TooSmall { needed })?;
    out[..4].copy_from_slice(BOOT_MAGIC);
    out[4..6].copy_from_slice(&VERSION.to_le_bytes());
    out[6..8].fill(0);
    out[8..16].copy_from_slice(&release.to_le_bytes());
    out[16..20].copy_from_slice(&(program.len() as u32).to_le_bytes());
    out[20..24].copy_from_slice(&(watch.len() as u32).to_le_bytes());
    out[BOOT_HEADER..BOOT_HEADER + program.len()].copy_from_slice(program);
    out[BOOT_HEADER + program.len()..].copy_from_slice(watch.as_bytes());
    Ok(needed)
}

/// Reads a boot project's payload.
pub fn decode_boot(bytes: &[u8]) -> Result<BootProject<'_>, StoreError> {
    header(bytes, BOOT_MAGIC)?;
    let release = le64(bytes, 8)?;
    let program_len = le32(bytes, 16)? as usize;
    let watch_len = le32(bytes, 20)? as usize;
    let program_end = BOOT_HEADER
        .checked_add(program_len)
        .ok_or(StoreError::Invalid {
            at: 16,
            what: "program length",
        })?;
    let end = program_end
        .checked_add(watch_len)
        .ok_or(StoreError::Invalid {
            at: 20,
            what: "watch list length",
        })?;
    if end != bytes.len() {
        return Err(if end > bytes.len() {
            StoreError::Truncated { at: bytes.len() }
        } else {
            StoreError::Invalid {
                at: end,
                what: "bytes after the watch list",
            }
        });
    }
    let watch =
        core::str::from_utf8(&bytes[program_end..end]).map_err(|_| StoreError::Invalid {
            at: program_end,
            what: "watch list is not UTF-8",
        })?;
    Ok(BootProject {
        release,
        program: &bytes[BOOT_HEADER..program_end],
        watch,
    })
}

/// A RETAIN snapshot read (and checked whole) from its record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RetainSnapshot<'a> {
    pub release: u64,
    /// CRC-32 of the program the values were taken in.
    pub program_crc: u32,
    pub count: u16,
    entries: &'a [u8],
}

/// One variable of a snapshot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RetainValue<'a> {
    pub ty: VarType,
    pub name: &'a str,
    pub bytes: &'a [u8],
}

impl<'a> RetainSnapshot<'a> {
    /// The variables, in the order they were written.
    pub fn values(&self) -> impl Iterator<Item = RetainValue<'a>> + 'a {
        let mut rest = self.entries;
        core::iter::from_fn(move || {
            let (value, len) = entry(rest, 0).ok()?;
            rest = &rest[len..];
            Some(value)
        })
    }
}

/// The entry at the start of `b` (whose offset in the payload is `base`) and its length.
fn entry(b: &[u8], base: usize) -> Result<(RetainValue<'_>, usize), StoreError> {
    let &[ty, name_len, v0, v1, ..] = b else {
        return Err(StoreError::Truncated { at: base });
    };
    let ty = VarType::from_code(ty).ok_or(StoreError::Invalid {
        at: base,
        what: "unknown variable type",
    })?;
    let (name_len, value_len) = (name_len as usize, u16::from_le_bytes([v0, v1]) as usize);
    let name = b
        .get(4..4 + name_len)
        .ok_or(StoreError::Truncated { at: base + 4 })?;
    let name = core::str::from_utf8(name).map_err(|_| StoreError::Invalid {
        at: base + 4,
        what: "name is not UTF-8",
    })?;
    let bytes = b
        .get(4 + name_len..4 + name_len + value_len)
        .ok_or(StoreError::Truncated {
            at: base + 4 + name_len,
        })?;
    Ok((RetainValue { ty, name, bytes }, 4 + name_len + value_len))
}

/// Writes a RETAIN snapshot of `data` (the memory of `image`, whose bytes have CRC
/// `program_crc`) at `release` into `out`; returns its length.
pub fn encode_retain(
    image: &Image,
    program_crc: u32,
    data: &[u8],
    release: u64,
    out: &mut [u8],
) -> Result<usize, StoreError> {
    let mut at = RETAIN_HEADER;
    let mut count: u16 = 0;
    for i in 0..image.var_count() {
        let Some(var) = image.var(i).filter(|v| v.flags & VAR_FLAG_RETAIN != 0) else {
            continue;
        };
        let Some(value) = data.get(var.addr as usize..(var.addr + var.size) as usize) else {
            continue;
        };
        if var.name.len() > u8::MAX as usize || value.len() > u16::MAX as usize {
            continue;
        }
        let needed = at + 4 + var.name.len() + value.len();
        let slot = out
            .get_mut(at..needed)
            .ok_or(StoreError::TooSmall { needed })?;
        slot[0] = var.ty;
        slot[1] = var.name.len() as u8;
        slot[2..4].copy_from_slice(&(value.len() as u16).to_le_bytes());
        slot[4..4 + var.name.len()].copy_from_slice(var.name.as_bytes());
        slot[4 + var.name.len()..].copy_from_slice(value);
        at = needed;
        count = count.saturating_add(1);
    }
    let head = out.get_mut(..RETAIN_HEADER).ok_or(StoreError::TooSmall {
        needed: RETAIN_HEADER,
    })?;
    head[..4].copy_from_slice(RETAIN_MAGIC);
    head[4..6].copy_from_slice(&VERSION.to_le_bytes());
    head[6..8].copy_from_slice(&count.to_le_bytes());
    head[8..16].copy_from_slice(&release.to_le_bytes());
    head[16..20].copy_from_slice(&program_crc.to_le_bytes());
    Ok(at)
}

/// Reads a RETAIN snapshot's payload, checking every entry.
pub fn decode_retain(bytes: &[u8]) -> Result<RetainSnapshot<'_>, StoreError> {
    header(bytes, RETAIN_MAGIC)?;
    let count = le16(bytes, 6)?;
    let release = le64(bytes, 8)?;
    let program_crc = le32(bytes, 16)?;
    let mut at = RETAIN_HEADER;
    for _ in 0..count {
        let (_, len) = entry(&bytes[at..], at)?;
        at += len;
    }
    if at != bytes.len() {
        return Err(StoreError::Invalid {
            at,
            what: "bytes after the last variable",
        });
    }
    Ok(RetainSnapshot {
        release,
        program_crc,
        count,
        entries: &bytes[RETAIN_HEADER..],
    })
}

/// Gives `image`'s RETAIN variables (in `data`) the snapshot's values by name and type;
/// `program_crc` is the image's, to tell whether references may be carried. Returns how
/// many variables got a value.
pub fn restore_retain(
    snapshot: &RetainSnapshot<'_>,
    image: &Image,
    program_crc: u32,
    data: &mut [u8],
) -> usize {
    let same_program = snapshot.program_crc == program_crc;
    let mut restored = 0;
    for value in snapshot.values() {
        let Some(var) = image
            .find_var(value.name)
            .filter(|v| v.flags & VAR_FLAG_RETAIN != 0 && v.ty == value.ty.code())
        else {
            continue;
        };
        let Some(dst) = data.get_mut(var.addr as usize..(var.addr + var.size) as usize) else {
            continue;
        };
        restored += carry_value(value.ty, same_program, value.bytes, dst) as usize;
    }
    restored
}

/// When RETAIN is saved: every `every` releases (the configuration's interval), and
/// whenever [`RetainSchedule::force`] asks (a STOP, a download).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RetainSchedule {
    every: u64,
    next: u64,
    forced: bool,
}

impl RetainSchedule {
    /// Saving every `every` releases (at least 1), the first after `every`.
    pub fn new(every: u64) -> Self {
        let every = every.max(1);
        RetainSchedule {
            every,
            next: every,
            forced: false,
        }
    }

    /// A save is due at release `release`.
    pub fn due(&self, release: u64) -> bool {
        self.forced || release >= self.next
    }

    /// The next release must save (STOP, download).
    pub fn force(&mut self) {
        self.forced = true;
    }

    /// A save of release `release` is on the disk.
    pub fn saved(&mut self, release: u64) {
        self.forced = false;
        self.next = release.saturating_add(self.every);
    }
}

#[cfg(test)]
mod tests;
