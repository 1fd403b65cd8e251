//! Binary records described once: a [`Field`] is an offset and a width inside a record,
//! and each record type of a binary format (the system image here, the binary
//! configuration in `config::binary`) lists its fields once as constants. Writers, checks,
//! views and tests all go through them, so no offset is written twice.
//!
//! Integers are little-endian; names are fixed-size fields of UTF-8, NUL-padded. The
//! accessors are `#[inline]`: with a field's constant width the copy becomes a plain load
//! in the crates that use them (syssw reads configuration records on every request).

/// A field of a record: its offset and width in bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    pub at: usize,
    pub len: usize,
}

impl Field {
    #[inline]
    pub const fn new(at: usize, len: usize) -> Self {
        Self { at, len }
    }

    /// The field's bytes in `record` (which must hold the whole field).
    #[inline]
    pub fn bytes(self, record: &[u8]) -> &[u8] {
        &record[self.at..self.at + self.len]
    }

    /// The field's bytes, for writing.
    #[inline]
    pub fn bytes_mut(self, record: &mut [u8]) -> &mut [u8] {
        &mut record[self.at..self.at + self.len]
    }

    /// The field as a little-endian unsigned integer (fields of 1 to 8 bytes).
    #[inline]
    pub fn get(self, record: &[u8]) -> u64 {
        let mut raw = [0u8; 8];
        raw[..self.len].copy_from_slice(self.bytes(record));
        u64::from_le_bytes(raw)
    }

    #[inline]
    pub fn u8(self, record: &[u8]) -> u8 {
        self.get(record) as u8
    }

    /// A 16-bit count or index.
    #[inline]
    pub fn u16(self, record: &[u8]) -> usize {
        self.get(record) as usize
    }

    #[inline]
    pub fn u32(self, record: &[u8]) -> u32 {
        self.get(record) as u32
    }

    /// Writes `value` little-endian into the field (`value` must fit its width).
    #[inline]
    pub fn set(self, record: &mut [u8], value: u64) {
        debug_assert!(
            self.len == 8 || value >> (8 * self.len) == 0,
            "value too wide"
        );
        let raw = value.to_le_bytes();
        self.bytes_mut(record).copy_from_slice(&raw[..self.len]);
    }

    /// The text of a name field: non-empty UTF-8, only NULs after it; `None` otherwise.
    #[inline]
    pub fn name(self, record: &[u8]) -> Option<&str> {
        let raw = self.bytes(record);
        let len = raw.iter().position(|&b| b == 0).unwrap_or(raw.len());
        if len == 0 || raw[len..].iter().any(|&b| b != 0) {
            return None;
        }
        core::str::from_utf8(&raw[..len]).ok()
    }

    /// Whether every byte of the field is zero (reserved fields).
    #[inline]
    pub fn is_zero(self, record: &[u8]) -> bool {
        self.bytes(record).iter().all(|&b| b == 0)
    }
}

/// Checks that `fields` cover `0..size` in order without gap or overlap (for the tests of
/// each format: the field table and the record size agree).
pub fn tiles(fields: &[Field], size: usize) -> Result<(), usize> {
    let mut next = 0;
    for f in fields {
        if f.at != next {
            return Err(f.at);
        }
        next = f.at + f.len;
    }
    if next == size { Ok(()) } else { Err(next) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_read_and_write_little_endian() {
        let mut record = [0u8; 16];
        let f = Field::new(2, 4);
        f.set(&mut record, 0x0102_0304);
        assert_eq!(record[2..6], [4, 3, 2, 1]);
        assert_eq!(f.get(&record), 0x0102_0304);
        assert_eq!(Field::new(2, 2).u16(&record), 0x0304);
        assert!(Field::new(6, 10).is_zero(&record));
    }

    #[test]
    fn names_are_nul_padded_utf8() {
        let f = Field::new(0, 8);
        assert_eq!(f.name(b"abc\0\0\0\0\0"), Some("abc"));
        assert_eq!(f.name(b"abcdefgh"), Some("abcdefgh"));
        assert_eq!(f.name(b"\0\0\0\0\0\0\0\0"), None);
        assert_eq!(f.name(b"ab\0c\0\0\0\0"), None);
        assert_eq!(f.name(b"\xff\0\0\0\0\0\0\0"), None);
    }

    #[test]
    fn tiling() {
        let fields = [Field::new(0, 2), Field::new(2, 6)];
        assert_eq!(tiles(&fields, 8), Ok(()));
        assert_eq!(tiles(&fields, 9), Err(8));
        assert_eq!(tiles(&[Field::new(0, 2), Field::new(3, 1)], 4), Err(3));
    }
}
