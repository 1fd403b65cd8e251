//! The IEC 61499 "FBDK" ASN.1 encoding of data values (the compliance profile for
//! feasibility demonstrations), which PUBLISH_n/SUBSCRIBE_n and CLIENT_n/SERVER_n of 4diac
//! FORTE and the FBDK put on the wire: a message is the encodings of its data inputs one
//! after another, and a message of no data is the ASN.1 NULL (one byte 0x05). An interface;
//! no_std, no allocation, and decoding never panics: bytes that do not encode the expected
//! type are a [`DecodeError`].
//!
//! # Encoding (integers big-endian)
//!
//! A value is a tag byte, 0x40 (ASN.1 application class) plus the type's number
//! ([`Type`]), then its bytes:
//!
//! | type | tag | bytes |
//! |---|---|---|
//! | BOOL | 0x40 FALSE, 0x41 TRUE | none (the value is in the tag) |
//! | SINT, INT, DINT, LINT | 0x42-0x45 | 1, 2, 4, 8: two's complement |
//! | USINT, UINT, UDINT, ULINT | 0x46-0x49 | 1, 2, 4, 8 |
//! | REAL, LREAL | 0x4A, 0x4B | 4, 8: IEEE 754 bits |
//! | TIME | 0x4C | 8: microseconds (signed) |
//! | STRING | 0x50 | `length u16`, the bytes |
//! | BYTE, WORD, DWORD, LWORD | 0x51-0x54 | 1, 2, 4, 8 |
//! | WSTRING | 0x55 | `length u16` (UTF-16 code units), the units big-endian |
//! | ARRAY | 0x76 (0x40 + constructed 0x20 + 22) | `count u16`, then for BOOL elements each element's tag, for the other types the element tag once and each element's bytes |
//!
//! Our TIME counts nanoseconds; the wire counts microseconds, so a sent TIME loses its
//! sub-microsecond part (truncated toward zero) and a received one beyond ±2^63 ns is an
//! error. DATE, TIME_OF_DAY, DATE_AND_TIME and structures are not encoded yet.

#![no_std]

codes::code_enum! {
    /// The elementary types of the encoding, by their ASN.1 application tag number.
    pub enum Type: u8 {
        Bool = 1 => "BOOL",
        SInt = 2 => "SINT",
        Int = 3 => "INT",
        DInt = 4 => "DINT",
        LInt = 5 => "LINT",
        USInt = 6 => "USINT",
        UInt = 7 => "UINT",
        UDInt = 8 => "UDINT",
        ULInt = 9 => "ULINT",
        Real = 10 => "REAL",
        LReal = 11 => "LREAL",
        Time = 12 => "TIME",
        String = 16 => "STRING",
        Byte = 17 => "BYTE",
        Word = 18 => "WORD",
        DWord = 19 => "DWORD",
        LWord = 20 => "LWORD",
        WString = 21 => "WSTRING",
    }
}

/// ASN.1 application class, primitive.
const APPLICATION: u8 = 0x40;
/// The tag of an array (application class, constructed, number 22).
pub const ARRAY_TAG: u8 = 0x40 | 0x20 | 22;
/// The ASN.1 NULL: a message without data.
pub const NULL: u8 = 0x05;

impl Type {
    /// Bytes after the tag of a fixed-size value (0 for BOOL; `None` for the strings).
    pub const fn fixed_size(self) -> Option<usize> {
        Some(match self {
            Type::Bool => 0,
            Type::SInt | Type::USInt | Type::Byte => 1,
            Type::Int | Type::UInt | Type::Word => 2,
            Type::DInt | Type::UDInt | Type::DWord | Type::Real => 4,
            Type::LInt | Type::ULInt | Type::LWord | Type::LReal | Type::Time => 8,
            Type::String | Type::WString => return None,
        })
    }

    /// The tag of a value of this type (BOOL: the tag of TRUE).
    pub const fn tag(self) -> u8 {
        APPLICATION | self.code()
    }
}

/// A value of one of the encoding's types. Integers and bit strings carry their bits
/// (zero- or sign-extended to 64), REAL/LREAL their IEEE bits; TIME nanoseconds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value<'a> {
    /// A fixed-size value: its type and its bits.
    Fixed(Type, u64),
    /// STRING: its bytes.
    String(&'a [u8]),
    /// WSTRING: its UTF-16 code units, big-endian, two bytes each (an odd last byte is not
    /// part of any unit and is not sent).
    WString(&'a [u8]),
}

impl Value<'_> {
    pub fn bool(on: bool) -> Self {
        Value::Fixed(Type::Bool, u64::from(on))
    }

    pub fn ty(&self) -> Type {
        match self {
            Value::Fixed(ty, _) => *ty,
            Value::String(_) => Type::String,
            Value::WString(_) => Type::WString,
        }
    }
}

/// Why bytes were not decoded as the expected value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecodeError {
    /// The message ends inside a value.
    Truncated { at: usize },
    /// The tag at `at` is not the expected type's.
    Tag {
        at: usize,
        expected: Type,
        found: u8,
    },
    /// The value at `at` does not fit ours (a TIME beyond ±2^63 ns, an odd WSTRING).
    Range { at: usize },
    /// Bytes are left after the last expected value.
    Trailing { at: usize },
}

impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            DecodeError::Truncated { at } => {
                write!(f, "message ends inside the value at byte {at}")
            }
            DecodeError::Tag {
                at,
                expected,
                found,
            } => write!(
                f,
                "byte {at}: tag {found:#04x} where a {expected} (tag {:#04x}) was expected",
                expected.tag()
            ),
            DecodeError::Range { at } => write!(f, "byte {at}: value out of range"),
            DecodeError::Trailing { at } => write!(f, "{at} bytes and more after the last value"),
        }
    }
}

/// The output buffer is full.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Full;

/// Writes a message into a buffer.
pub struct Writer<'b> {
    buf: &'b mut [u8],
    len: usize,
}

impl<'b> Writer<'b> {
    pub fn new(buf: &'b mut [u8]) -> Self {
        Writer { buf, len: 0 }
    }

    /// The message so far.
    pub fn bytes(&self) -> &[u8] {
        &self.buf[..self.len]
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    fn put(&mut self, bytes: &[u8]) -> Result<(), Full> {
        let end = self.len.checked_add(bytes.len()).ok_or(Full)?;
        self.buf
            .get_mut(self.len..end)
            .ok_or(Full)?
            .copy_from_slice(bytes);
        self.len = end;
        Ok(())
    }

    fn length(&mut self, n: usize) -> Result<(), Full> {
        let n = u16::try_from(n).map_err(|_| Full)?;
        self.put(&n.to_be_bytes())
    }

    /// Runs `write`; if it fails, the message is as before it (no partial value).
    fn whole(&mut self, write: impl FnOnce(&mut Self) -> Result<(), Full>) -> Result<(), Full> {
        let before = self.len;
        write(self).inspect_err(|_| self.len = before)
    }

    /// A value with its tag (on [`Full`], nothing of it is written).
    pub fn value(&mut self, value: &Value<'_>) -> Result<(), Full> {
        self.whole(|w| w.tagged(value))
    }

    fn tagged(&mut self, value: &Value<'_>) -> Result<(), Full> {
        match value {
            Value::Fixed(Type::Bool, bits) => self.put(&[APPLICATION | u8::from(*bits != 0)]),
            _ => {
                self.put(&[value.ty().tag()])?;
                self.content(value)
            }
        }
    }

    /// A value's bytes without its tag (array elements after the first tag).
    fn content(&mut self, value: &Value<'_>) -> Result<(), Full> {
        match *value {
            Value::Fixed(Type::Time, ns) => self.put(&((ns as i64) / 1_000).to_be_bytes()),
            Value::Fixed(ty, bits) => {
                let size = ty.fixed_size().unwrap_or(0);
                self.put(&bits.to_be_bytes()[8 - size..])
            }
            Value::String(bytes) => {
                self.length(bytes.len())?;
                self.put(bytes)
            }
            Value::WString(units) => {
                self.length(units.len() / 2)?;
                self.put(&units[..units.len() / 2 * 2])
            }
        }
    }

    /// An array of `elements`, all of type `element` (a value of another type is written
    /// as the element type's bits, so callers pass one type).
    pub fn array<'v>(
        &mut self,
        element: Type,
        elements: impl ExactSizeIterator<Item = Value<'v>>,
    ) -> Result<(), Full> {
        self.whole(|w| {
            w.put(&[ARRAY_TAG])?;
            w.length(elements.len())?;
            if element == Type::Bool {
                for e in elements {
                    w.tagged(&e)?;
                }
                return Ok(());
            }
            w.put(&[element.tag()])?;
            for e in elements {
                w.content(&e)?;
            }
            Ok(())
        })
    }

    /// The message of no data (the ASN.1 NULL), when nothing else was written.
    pub fn null(&mut self) -> Result<(), Full> {
        self.put(&[NULL])
    }
}

/// Reads the values of a message, each as the type the reader expects (the encoding does
/// not describe itself beyond the tag).
pub struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        Reader { bytes, at: 0 }
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        let at = self.at;
        let end = at.checked_add(n).ok_or(DecodeError::Truncated { at })?;
        let bytes = self
            .bytes
            .get(at..end)
            .ok_or(DecodeError::Truncated { at })?;
        self.at = end;
        Ok(bytes)
    }

    fn length(&mut self) -> Result<usize, DecodeError> {
        let b = self.take(2)?;
        Ok(usize::from(u16::from_be_bytes([b[0], b[1]])))
    }

    fn tag(&mut self, expected: Type, tag: u8) -> Result<(), DecodeError> {
        let at = self.at;
        let found = self.take(1)?[0];
        if found == tag {
            Ok(())
        } else {
            Err(DecodeError::Tag {
                at,
                expected,
                found,
            })
        }
    }

    /// The next value, of type `expected`.
    pub fn value(&mut self, expected: Type) -> Result<Value<'a>, DecodeError> {
        if expected == Type::Bool {
            let at = self.at;
            let found = self.take(1)?[0];
            return match found {
                0x40 | 0x41 => Ok(Value::bool(found == 0x41)),
                _ => Err(DecodeError::Tag {
                    at,
                    expected,
                    found,
                }),
            };
        }
        self.tag(expected, expected.tag())?;
        self.content(expected)
    }

    fn content(&mut self, ty: Type) -> Result<Value<'a>, DecodeError> {
        let at = self.at;
        match ty {
            Type::String => {
                let n = self.length()?;
                Ok(Value::String(self.take(n)?))
            }
            Type::WString => {
                let n = self.length()?;
                Ok(Value::WString(self.take(2 * n)?))
            }
            Type::Bool => {
                // Inside a BOOL array every element carries its own tag.
                self.at = at;
                self.value(Type::Bool)
            }
            _ => {
                let size = ty.fixed_size().unwrap_or(0);
                let bytes = self.take(size)?;
                let mut word = [0u8; 8];
                word[8 - size..].copy_from_slice(bytes);
                let raw = u64::from_be_bytes(word);
                let signed = matches!(ty, Type::SInt | Type::Int | Type::DInt | Type::LInt);
                let bits = if signed && size < 8 {
                    let shift = 64 - 8 * size as u32;
                    (((raw << shift) as i64) >> shift) as u64
                } else {
                    raw
                };
                if ty == Type::Time {
                    let ns = (bits as i64)
                        .checked_mul(1_000)
                        .ok_or(DecodeError::Range { at })?;
                    return Ok(Value::Fixed(ty, ns as u64));
                }
                Ok(Value::Fixed(ty, bits))
            }
        }
    }

    /// An array of `element`s: the number of elements, then [`Reader::element`] that many
    /// times.
    pub fn array(&mut self, element: Type) -> Result<usize, DecodeError> {
        self.tag(element, ARRAY_TAG)?;
        let count = self.length()?;
        if element != Type::Bool {
            self.tag(element, element.tag())?;
        }
        Ok(count)
    }

    /// The next element of an array begun with [`Reader::array`].
    pub fn element(&mut self, element: Type) -> Result<Value<'a>, DecodeError> {
        self.content(element)
    }

    /// Whether the message is the ASN.1 NULL (no data).
    pub fn is_null(&self) -> bool {
        self.bytes == [NULL]
    }

    /// The bytes read so far (where the next value starts).
    pub fn position(&self) -> usize {
        self.at
    }

    /// Ends the message: no bytes may be left.
    pub fn finish(self) -> Result<(), DecodeError> {
        if self.at == self.bytes.len() {
            Ok(())
        } else {
            Err(DecodeError::Trailing { at: self.at })
        }
    }
}

#[cfg(test)]
mod tests;
