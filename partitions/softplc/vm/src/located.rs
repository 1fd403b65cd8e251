//! Directly represented (located) variables, IEC 61131-3 §6.5.5: `%IX0.3`, `%QW2`, `%MD1`,
//! and the process-image copies that connect them to the areas.
//!
//! # Addresses (an interface: the configuration's port mappings use the same byte offsets)
//!
//! `%` area size address: area `I` (inputs), `Q` (outputs), `M` (markers); size `X` (bit,
//! the default when omitted), `B` (byte), `W` (word, 2 bytes), `D` (double word, 4 bytes),
//! `L` (long word, 8 bytes). As in CODESYS, a bit address is `byte.bit` (bit 0..=7) and any
//! other address counts in units of its own size: `%IW1` is bytes 2..=3 of the input area,
//! `%QD2` bytes 8..=11, so `%IX2.0` is the lowest bit of `%IB2`, which is the low byte of
//! `%IW1`. Areas are little-endian byte arrays of at most [`MAX_AREA`] bytes.
//!
//! # Read–execute–write
//!
//! A located variable also has ordinary storage in data memory (its address in the image's
//! LOCATED record). Before each scan cycle the runtime copies every `%I` and `%M` variable in
//! from its area ([`copy_in`]); after the cycle it copies every `%Q` and `%M` variable out
//! ([`copy_out`]). During a cycle the program therefore sees one consistent input image, and
//! overlapping declarations meet only at cycle boundaries (outputs: the later declaration in
//! the image wins).

use crate::image::VarType;

/// Largest area (bytes) an address may reach into.
pub const MAX_AREA: u32 = 4096;

codes::code_enum! {
    /// The area a located variable lives in.
    pub enum Area: u8 {
        /// `%I`: inputs, copied in from ports before the cycle.
        Input = 0 => "I",
        /// `%Q`: outputs, copied out to ports after the cycle.
        Output = 1 => "Q",
        /// `%M`: markers, the runtime's own memory.
        Memory = 2 => "M",
    }
}

codes::code_enum! {
    /// The size of a located variable.
    pub enum Width: u8 {
        /// `X`: one bit.
        Bit = 0 => "X",
        /// `B`: 1 byte.
        Byte = 1 => "B",
        /// `W`: 2 bytes.
        Word = 2 => "W",
        /// `D`: 4 bytes.
        DWord = 3 => "D",
        /// `L`: 8 bytes.
        LWord = 4 => "L",
    }
}

impl Width {
    /// Bytes of the area it covers (a bit covers its byte).
    pub const fn bytes(self) -> u32 {
        match self {
            Width::Bit | Width::Byte => 1,
            Width::Word => 2,
            Width::DWord => 4,
            Width::LWord => 8,
        }
    }

    /// Whether a variable of type `ty` may be located at this width.
    pub fn fits(self, ty: VarType) -> bool {
        use VarType::*;
        match self {
            Width::Bit => ty == Bool,
            Width::Byte => matches!(ty, Byte | SInt | USInt | Char),
            Width::Word => matches!(ty, Word | Int | UInt | WChar),
            Width::DWord => matches!(ty, DWord | DInt | UDInt | Real),
            Width::LWord => matches!(ty, LWord | LInt | ULInt | LReal) || ty.time_kind().is_some(),
        }
    }
}

/// A parsed address such as `%IX0.3`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Location {
    /// `I`, `Q` or `M`.
    pub area: Area,
    /// `X`, `B`, `W`, `D` or `L`.
    pub width: Width,
    /// First byte in the area.
    pub byte: u32,
    /// Bit within `byte` (0 unless `width` is [`Width::Bit`]).
    pub bit: u8,
}

/// Why an address was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LocationError {
    /// Not `%I`, `%Q` or `%M`.
    Area,
    /// A size letter other than X, B, W, D, L.
    Width,
    /// The number is missing or not decimal, or a bit address lacks `.bit` (or a byte
    /// address has one).
    Syntax,
    /// The bit number is above 7.
    Bit,
    /// The variable would reach beyond [`MAX_AREA`].
    Range,
}

impl core::fmt::Display for LocationError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            LocationError::Area => "the area must be I (input), Q (output) or M (marker)",
            LocationError::Width => "the size must be X (bit), B, W, D or L",
            LocationError::Syntax => {
                "expected `byte.bit` for a bit (e.g. %IX0.3) and one number otherwise (e.g. %QW2)"
            }
            LocationError::Bit => "a bit number is 0..=7",
            LocationError::Range => "the address lies beyond the 4096-byte area",
        })
    }
}

fn number(text: &str) -> Result<u32, LocationError> {
    if text.is_empty() || !text.bytes().all(|b| b.is_ascii_digit()) {
        return Err(LocationError::Syntax);
    }
    text.parse().map_err(|_| LocationError::Range)
}

impl Location {
    /// Parses the text after `%` (case-insensitive), e.g. `IX0.3`, `qw2`, `M0.1`.
    pub fn parse(text: &str) -> Result<Self, LocationError> {
        let mut chars = text.chars();
        let area = match chars.next().map(|c| c.to_ascii_uppercase()) {
            Some('I') => Area::Input,
            Some('Q') => Area::Output,
            Some('M') => Area::Memory,
            _ => return Err(LocationError::Area),
        };
        let rest = chars.as_str();
        let (width, address) = match rest.chars().next().map(|c| c.to_ascii_uppercase()) {
            Some('X') => (Width::Bit, &rest[1..]),
            Some('B') => (Width::Byte, &rest[1..]),
            Some('W') => (Width::Word, &rest[1..]),
            Some('D') => (Width::DWord, &rest[1..]),
            Some('L') => (Width::LWord, &rest[1..]),
            Some(c) if c.is_ascii_digit() => (Width::Bit, rest),
            Some(c) if c.is_ascii_alphabetic() => return Err(LocationError::Width),
            _ => return Err(LocationError::Syntax),
        };
        let (byte, bit) = match (width, address.split_once('.')) {
            (Width::Bit, Some((byte, bit))) => {
                let bit = number(bit)?;
                if bit > 7 {
                    return Err(LocationError::Bit);
                }
                (number(byte)?, bit as u8)
            }
            (Width::Bit, None) => return Err(LocationError::Syntax),
            (_, Some(_)) => return Err(LocationError::Syntax),
            (_, None) => {
                let unit = number(address)?;
                (
                    unit.checked_mul(width.bytes())
                        .ok_or(LocationError::Range)?,
                    0,
                )
            }
        };
        let location = Location {
            area,
            width,
            byte,
            bit,
        };
        if location.end() > MAX_AREA {
            return Err(LocationError::Range);
        }
        Ok(location)
    }

    /// One past the last area byte it covers.
    pub fn end(&self) -> u32 {
        self.byte.saturating_add(self.width.bytes())
    }
}

impl core::fmt::Display for Location {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "%{}{}", self.area.name(), self.width.name())?;
        match self.width {
            Width::Bit => write!(f, "{}.{}", self.byte, self.bit),
            w => write!(f, "{}", self.byte / w.bytes()),
        }
    }
}

/// A located variable as the image records it: where it is in the area and in data memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Located {
    /// Where in its area.
    pub location: Location,
    /// Data-memory address of the variable's own storage.
    pub address: u32,
}

/// Copies `vars` of `area` from `image` (the area's bytes) into data memory. Variables
/// reaching past `image` read zeros there. Addresses must lie in `data` (the verifier
/// checked them); one that does not is skipped.
pub fn copy_in<'a>(
    vars: impl Iterator<Item = Located> + 'a,
    area: Area,
    image: &[u8],
    data: &mut [u8],
) {
    for v in vars.filter(|v| v.location.area == area) {
        let l = v.location;
        let at = v.address as usize;
        let Some(target) = data.get_mut(at..at + l.width.bytes() as usize) else {
            continue;
        };
        let from = l.byte as usize;
        match l.width {
            Width::Bit => {
                let byte = image.get(from).copied().unwrap_or(0);
                target[0] = (byte >> l.bit) & 1;
            }
            _ => {
                for (i, t) in target.iter_mut().enumerate() {
                    *t = image.get(from + i).copied().unwrap_or(0);
                }
            }
        }
    }
}

/// Copies `vars` of `area` from data memory into `image` (the area's bytes). Bytes past
/// `image` are dropped; a BOOL sets its bit from its stored value (non-zero = TRUE).
pub fn copy_out<'a>(
    vars: impl Iterator<Item = Located> + 'a,
    area: Area,
    data: &[u8],
    image: &mut [u8],
) {
    for v in vars.filter(|v| v.location.area == area) {
        let l = v.location;
        let at = v.address as usize;
        let Some(source) = data.get(at..at + l.width.bytes() as usize) else {
            continue;
        };
        let to = l.byte as usize;
        match l.width {
            Width::Bit => {
                if let Some(byte) = image.get_mut(to) {
                    let mask = 1u8 << l.bit;
                    *byte = if source[0] != 0 {
                        *byte | mask
                    } else {
                        *byte & !mask
                    };
                }
            }
            _ => {
                for (i, s) in source.iter().enumerate() {
                    if let Some(b) = image.get_mut(to + i) {
                        *b = *s;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(text: &str) -> Location {
        Location::parse(text).unwrap()
    }

    #[test]
    fn addresses_count_in_units_of_their_size() {
        assert_eq!(
            at("IX2.3"),
            Location {
                area: Area::Input,
                width: Width::Bit,
                byte: 2,
                bit: 3
            }
        );
        assert_eq!(at("QW1").byte, 2);
        assert_eq!(at("md2").byte, 8);
        assert_eq!(at("IL1").byte, 8);
        assert_eq!(at("IB7").byte, 7);
        assert_eq!(at("M0.7").width, Width::Bit, "no size letter is a bit");
        extern crate alloc;
        for text in ["IX2.3", "QW1", "MD2", "IL1", "IB7"] {
            assert_eq!(alloc::format!("{}", at(text)), alloc::format!("%{text}"));
        }
    }

    #[test]
    fn bad_addresses_say_why() {
        assert_eq!(Location::parse("Z0"), Err(LocationError::Area));
        assert_eq!(Location::parse(""), Err(LocationError::Area));
        assert_eq!(Location::parse("IY0"), Err(LocationError::Width));
        assert_eq!(Location::parse("IX0"), Err(LocationError::Syntax));
        assert_eq!(Location::parse("IW0.1"), Err(LocationError::Syntax));
        assert_eq!(Location::parse("IX0.8"), Err(LocationError::Bit));
        assert_eq!(Location::parse("IW"), Err(LocationError::Syntax));
        assert_eq!(Location::parse("IX.1"), Err(LocationError::Syntax));
        assert_eq!(Location::parse("ID1024"), Err(LocationError::Range));
        assert_eq!(Location::parse("IL99999999999"), Err(LocationError::Range));
        assert!(Location::parse("ID1023").is_ok());
    }

    #[test]
    fn widths_take_their_types() {
        assert!(Width::Bit.fits(VarType::Bool));
        assert!(!Width::Byte.fits(VarType::Bool));
        assert!(Width::DWord.fits(VarType::Real));
        assert!(Width::LWord.fits(VarType::LReal));
        assert!(!Width::Word.fits(VarType::DInt));
        assert!(!Width::LWord.fits(VarType::String));
        // The date/time types are 64-bit, the characters a byte and a word; never a
        // reference or a WSTRING.
        assert!(Width::LWord.fits(VarType::Tod) && Width::LWord.fits(VarType::LDt));
        assert!(Width::Byte.fits(VarType::Char) && Width::Word.fits(VarType::WChar));
        assert!(!Width::LWord.fits(VarType::Ref) && !Width::LWord.fits(VarType::WString));
    }

    #[test]
    fn copies_follow_the_layout() {
        let vars = [
            Located {
                location: at("IX1.2"),
                address: 0,
            },
            Located {
                location: at("IW1"),
                address: 2,
            },
            Located {
                location: at("QD0"),
                address: 4,
            },
            Located {
                location: at("QX4.1"),
                address: 8,
            },
            Located {
                // Past the 8-byte image: reads zero, writes nothing.
                location: at("IW8"),
                address: 10,
            },
        ];
        let input = [0x00, 0x04, 0x34, 0x12, 0, 0, 0, 0];
        let mut data = [0xffu8; 12];
        copy_in(vars.iter().copied(), Area::Input, &input, &mut data);
        assert_eq!(data[0], 1, "bit 2 of byte 1");
        assert_eq!(&data[2..4], &[0x34, 0x12]);
        assert_eq!(&data[10..12], &[0, 0]);
        assert_eq!(&data[4..8], &[0xff; 4], "outputs are not copied in");
        data[4..8].copy_from_slice(&0xdead_beefu32.to_le_bytes());
        data[8] = 1;
        let mut output = [0u8; 6];
        copy_out(vars.iter().copied(), Area::Output, &data, &mut output);
        assert_eq!(output, [0xef, 0xbe, 0xad, 0xde, 0x02, 0]);
        data[8] = 0;
        copy_out(vars.iter().copied(), Area::Output, &data, &mut output);
        assert_eq!(output[4], 0, "a FALSE clears its bit");
    }
}
