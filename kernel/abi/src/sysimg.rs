//! The system image (`system.img`): one archive holding everything the kernel and the
//! system software need besides the kernel itself (binary configuration, the syssw ELF,
//! partition ELFs, data files such as PLC bytecode).
//!
//! Format, version 1 (all integers little-endian):
//!
//! ```text
//! offset  size  field
//! 0       8     magic "PKSYSIMG"
//! 8       4     version (1)
//! 12      4     entry count N (at most MAX_ENTRIES)
//! 16      8     total size in bytes (header + table + data, incl. padding)
//! 24      4     CRC-32 (IEEE) of bytes [32, total size)
//! 28      4     reserved, zero
//! 32      64*N  entry table; entry = name (48 bytes UTF-8, NUL-padded, non-empty, unique),
//!               offset u64 (from the start of the image), size u64
//! ...           entry data, each starting on a 4 KiB boundary so it can be mapped page-wise;
//!               entries are stored in table order and never overlap; padding is zero
//! ```
//!
//! Entry names are paths by convention: `config` (binary configuration), `syssw`,
//! `partition/<name>`, `data/<name>`; the kernel relies only on `syssw`.

use crate::crc32::crc32;

pub const MAGIC: [u8; 8] = *b"PKSYSIMG";
pub const VERSION: u32 = 1;
pub const HEADER_SIZE: usize = header::SIZE;
pub const ENTRY_SIZE: usize = entry::SIZE;
pub const NAME_SIZE: usize = entry::NAME.len;
pub const MAX_ENTRIES: usize = 256;
/// Alignment of every entry's data.
pub const DATA_ALIGN: usize = 4096;

/// Header fields (the table above as code: the one place that states them).
pub mod header {
    use crate::layout::Field;
    pub const MAGIC: Field = Field::new(0, 8);
    pub const VERSION: Field = Field::new(8, 4);
    pub const ENTRY_COUNT: Field = Field::new(12, 4);
    pub const TOTAL_SIZE: Field = Field::new(16, 8);
    pub const CRC: Field = Field::new(24, 4);
    pub const RESERVED: Field = Field::new(28, 4);
    pub const SIZE: usize = 32;
    pub const FIELDS: [Field; 6] = [MAGIC, VERSION, ENTRY_COUNT, TOTAL_SIZE, CRC, RESERVED];
}

/// Entry-table record fields.
pub mod entry {
    use crate::layout::Field;
    pub const NAME: Field = Field::new(0, 48);
    pub const OFFSET: Field = Field::new(48, 8);
    pub const DATA_SIZE: Field = Field::new(56, 8);
    pub const SIZE: usize = 64;
    pub const FIELDS: [Field; 3] = [NAME, OFFSET, DATA_SIZE];
}

/// Why an image was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SysImgError {
    TooShort,
    BadMagic,
    UnsupportedVersion(u32),
    TooManyEntries(u32),
    SizeMismatch { declared: u64, actual: u64 },
    ChecksumMismatch { stored: u32, computed: u32 },
    BadEntryName(usize),
    DuplicateName(usize),
    EntryOutOfBounds(usize),
    EntryMisaligned(usize),
    EntriesOverlap(usize),
}

impl core::fmt::Display for SysImgError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::TooShort => write!(f, "shorter than its header and entry table"),
            Self::BadMagic => write!(f, "bad magic (not a system image)"),
            Self::UnsupportedVersion(v) => {
                write!(f, "unsupported version {v} (expected {VERSION})")
            }
            Self::TooManyEntries(n) => write!(f, "{n} entries (at most {MAX_ENTRIES})"),
            Self::SizeMismatch { declared, actual } => {
                write!(f, "header says {declared} bytes but {actual} are present")
            }
            Self::ChecksumMismatch { stored, computed } => {
                write!(
                    f,
                    "checksum mismatch (stored {stored:#010x}, computed {computed:#010x}): image is damaged"
                )
            }
            Self::BadEntryName(i) => write!(f, "entry {i}: name is empty or not UTF-8"),
            Self::DuplicateName(i) => write!(f, "entry {i}: duplicate name"),
            Self::EntryOutOfBounds(i) => write!(f, "entry {i}: data lies outside the image"),
            Self::EntryMisaligned(i) => {
                write!(f, "entry {i}: data not aligned to {DATA_ALIGN} bytes")
            }
            Self::EntriesOverlap(i) => write!(
                f,
                "entry {i}: data overlaps the table or the previous entry"
            ),
        }
    }
}

/// One named entry of a parsed image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Entry<'a> {
    pub name: &'a str,
    /// Byte offset of the data from the image start (a multiple of [`DATA_ALIGN`]).
    pub offset: usize,
    pub data: &'a [u8],
}

/// A validated system image (zero-copy view).
#[derive(Clone, Copy, Debug)]
pub struct SystemImage<'a> {
    bytes: &'a [u8],
    count: usize,
}

impl<'a> SystemImage<'a> {
    /// Validates everything (header, checksum, every entry) so that later accesses cannot fail.
    /// `bytes` may be longer than the image (e.g. rounded up to pages).
    pub fn parse(bytes: &'a [u8]) -> Result<Self, SysImgError> {
        if bytes.len() < HEADER_SIZE {
            return Err(SysImgError::TooShort);
        }
        if header::MAGIC.bytes(bytes) != MAGIC {
            return Err(SysImgError::BadMagic);
        }
        let version = header::VERSION.u32(bytes);
        if version != VERSION {
            return Err(SysImgError::UnsupportedVersion(version));
        }
        let count = header::ENTRY_COUNT.u32(bytes);
        if count as usize > MAX_ENTRIES {
            return Err(SysImgError::TooManyEntries(count));
        }
        let count = count as usize;
        let total = header::TOTAL_SIZE.get(bytes);
        let table_end = HEADER_SIZE + count * ENTRY_SIZE;
        if total > bytes.len() as u64 || (total as usize) < table_end {
            return Err(SysImgError::SizeMismatch {
                declared: total,
                actual: bytes.len() as u64,
            });
        }
        let bytes = &bytes[..total as usize];
        let stored = header::CRC.u32(bytes);
        let computed = crc32(&bytes[HEADER_SIZE..]);
        if stored != computed {
            return Err(SysImgError::ChecksumMismatch { stored, computed });
        }
        let image = SystemImage { bytes, count };
        let mut previous_end = table_end;
        for i in 0..count {
            let raw = image.raw_entry(i);
            let name = entry::NAME.name(raw).ok_or(SysImgError::BadEntryName(i))?;
            if (0..i).any(|j| entry::NAME.name(image.raw_entry(j)) == Some(name)) {
                return Err(SysImgError::DuplicateName(i));
            }
            let offset = entry::OFFSET.get(raw);
            let size = entry::DATA_SIZE.get(raw);
            let end = offset
                .checked_add(size)
                .ok_or(SysImgError::EntryOutOfBounds(i))?;
            if end > total {
                return Err(SysImgError::EntryOutOfBounds(i));
            }
            if !(offset as usize).is_multiple_of(DATA_ALIGN) {
                return Err(SysImgError::EntryMisaligned(i));
            }
            if (offset as usize) < previous_end {
                return Err(SysImgError::EntriesOverlap(i));
            }
            previous_end = end as usize;
        }
        Ok(image)
    }

    fn raw_entry(&self, i: usize) -> &'a [u8] {
        let at = HEADER_SIZE + i * ENTRY_SIZE;
        &self.bytes[at..at + ENTRY_SIZE]
    }

    /// Total size of the image in bytes.
    pub fn size(&self) -> usize {
        self.bytes.len()
    }

    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The `i`-th entry (panics if `i >= len()`; `parse` validated every entry).
    pub fn entry(&self, i: usize) -> Entry<'a> {
        let raw = self.raw_entry(i);
        let name = entry::NAME.name(raw).unwrap_or("");
        let offset = entry::OFFSET.get(raw) as usize;
        let size = entry::DATA_SIZE.get(raw) as usize;
        Entry {
            name,
            offset,
            data: &self.bytes[offset..offset + size],
        }
    }

    pub fn entries(&self) -> impl Iterator<Item = Entry<'a>> + '_ {
        (0..self.count).map(|i| self.entry(i))
    }

    pub fn find(&self, name: &str) -> Option<Entry<'a>> {
        self.entries().find(|e| e.name == name)
    }
}

/// Host-side writer.
#[cfg(feature = "std")]
pub mod builder {
    use super::*;
    use std::string::{String, ToString};
    use std::vec::Vec;
    use std::{format, vec};

    /// Collects named entries and writes a version-1 image.
    #[derive(Default)]
    pub struct SystemImageBuilder {
        entries: Vec<(String, Vec<u8>)>,
    }

    impl SystemImageBuilder {
        pub fn new() -> Self {
            Self::default()
        }

        /// Adds an entry; names must be 1..=47 bytes, unique, without NUL.
        pub fn add(&mut self, name: &str, data: Vec<u8>) -> Result<&mut Self, String> {
            if name.is_empty() || name.len() >= NAME_SIZE || name.contains('\0') {
                return Err(format!(
                    "system image entry name {name:?} must be 1..{NAME_SIZE} bytes without NUL"
                ));
            }
            if self.entries.iter().any(|(n, _)| n == name) {
                return Err(format!("system image entry {name:?} added twice"));
            }
            if self.entries.len() == MAX_ENTRIES {
                return Err(format!("system image holds at most {MAX_ENTRIES} entries"));
            }
            self.entries.push((name.to_string(), data));
            Ok(self)
        }

        pub fn build(&self) -> Vec<u8> {
            let align = |n: usize| n.div_ceil(DATA_ALIGN) * DATA_ALIGN;
            let table_end = HEADER_SIZE + self.entries.len() * ENTRY_SIZE;
            let mut out = vec![0u8; table_end];
            let mut offset = align(table_end);
            for (i, (name, data)) in self.entries.iter().enumerate() {
                let record = &mut out[HEADER_SIZE + i * ENTRY_SIZE..][..ENTRY_SIZE];
                entry::NAME.bytes_mut(record)[..name.len()].copy_from_slice(name.as_bytes());
                entry::OFFSET.set(record, offset as u64);
                entry::DATA_SIZE.set(record, data.len() as u64);
                out.resize(offset, 0);
                out.extend_from_slice(data);
                offset = align(out.len());
            }
            header::MAGIC.bytes_mut(&mut out).copy_from_slice(&MAGIC);
            header::VERSION.set(&mut out, u64::from(VERSION));
            header::ENTRY_COUNT.set(&mut out, self.entries.len() as u64);
            let total = out.len() as u64;
            header::TOTAL_SIZE.set(&mut out, total);
            let crc = crc32(&out[HEADER_SIZE..]);
            header::CRC.set(&mut out, u64::from(crc));
            out
        }
    }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::builder::SystemImageBuilder;
    use super::*;
    use std::vec;
    use std::vec::Vec;

    fn sample() -> Vec<u8> {
        let mut b = SystemImageBuilder::new();
        b.add("config", b"abc".to_vec()).unwrap();
        b.add("syssw", vec![7u8; 5000]).unwrap();
        b.add("data/empty", Vec::new()).unwrap();
        b.build()
    }

    /// Rewrites the checksum after a deliberate edit, so the test reaches the check behind it.
    fn reseal(bytes: &mut [u8]) {
        let crc = crc32(&bytes[HEADER_SIZE..]);
        header::CRC.set(bytes, u64::from(crc));
    }

    #[test]
    fn round_trip() {
        let bytes = sample();
        let img = SystemImage::parse(&bytes).unwrap();
        assert_eq!(img.len(), 3);
        assert_eq!(img.find("config").unwrap().data, b"abc");
        let syssw = img.find("syssw").unwrap();
        assert_eq!(syssw.data.len(), 5000);
        assert_eq!(syssw.offset % DATA_ALIGN, 0);
        assert_eq!(img.find("data/empty").unwrap().data, b"");
        assert!(img.find("missing").is_none());
        // Trailing bytes (page rounding) are ignored.
        let mut longer = bytes.clone();
        longer.extend_from_slice(&[0; 100]);
        assert_eq!(SystemImage::parse(&longer).unwrap().len(), 3);
    }

    #[test]
    fn rejects_damage() {
        let good = sample();
        assert_eq!(
            SystemImage::parse(&good[..10]).unwrap_err(),
            SysImgError::TooShort
        );
        let mut b = good.clone();
        header::MAGIC.bytes_mut(&mut b)[0] = b'X';
        assert_eq!(SystemImage::parse(&b).unwrap_err(), SysImgError::BadMagic);
        let mut b = good.clone();
        header::VERSION.set(&mut b, 2);
        assert_eq!(
            SystemImage::parse(&b).unwrap_err(),
            SysImgError::UnsupportedVersion(2)
        );
        let mut b = good.clone();
        let last = b.len() - 1;
        b[last] ^= 1;
        assert!(matches!(
            SystemImage::parse(&b).unwrap_err(),
            SysImgError::ChecksumMismatch { .. }
        ));
        assert!(matches!(
            SystemImage::parse(&good[..good.len() - 1]).unwrap_err(),
            SysImgError::SizeMismatch { .. }
        ));
        let mut b = good.clone();
        header::ENTRY_COUNT.set(&mut b, 1000);
        assert_eq!(
            SystemImage::parse(&b).unwrap_err(),
            SysImgError::TooManyEntries(1000)
        );
    }

    #[test]
    fn rejects_bad_entries() {
        let good = sample();
        let at = |i: usize| HEADER_SIZE + i * ENTRY_SIZE;
        // Duplicate name.
        let mut b = good.clone();
        entry::NAME.bytes_mut(&mut b[at(1)..])[..7].copy_from_slice(b"config\0");
        reseal(&mut b);
        assert_eq!(
            SystemImage::parse(&b).unwrap_err(),
            SysImgError::DuplicateName(1)
        );
        // Empty name.
        let mut b = good.clone();
        entry::NAME.bytes_mut(&mut b[at(0)..]).fill(0);
        reseal(&mut b);
        assert_eq!(
            SystemImage::parse(&b).unwrap_err(),
            SysImgError::BadEntryName(0)
        );
        // Data beyond the end.
        let mut b = good.clone();
        entry::DATA_SIZE.set(&mut b[at(1)..], u64::MAX);
        reseal(&mut b);
        assert_eq!(
            SystemImage::parse(&b).unwrap_err(),
            SysImgError::EntryOutOfBounds(1)
        );
        // Misaligned data.
        let mut b = good.clone();
        entry::OFFSET.set(&mut b[at(0)..], 4097);
        reseal(&mut b);
        assert_eq!(
            SystemImage::parse(&b).unwrap_err(),
            SysImgError::EntryMisaligned(0)
        );
        // Second entry starting inside the first.
        let mut b = good.clone();
        let first = entry::OFFSET.get(&b[at(0)..]);
        entry::OFFSET.set(&mut b[at(1)..], first);
        reseal(&mut b);
        assert_eq!(
            SystemImage::parse(&b).unwrap_err(),
            SysImgError::EntriesOverlap(1)
        );
    }

    #[test]
    fn fields_tile_their_records() {
        assert_eq!(crate::layout::tiles(&header::FIELDS, header::SIZE), Ok(()));
        assert_eq!(crate::layout::tiles(&entry::FIELDS, entry::SIZE), Ok(()));
    }

    #[test]
    fn builder_rejects_bad_names() {
        let mut b = SystemImageBuilder::new();
        assert!(b.add("", vec![]).is_err());
        assert!(b.add(&"x".repeat(NAME_SIZE), vec![]).is_err());
        b.add("a", vec![]).unwrap();
        assert!(b.add("a", vec![]).is_err());
    }
}
