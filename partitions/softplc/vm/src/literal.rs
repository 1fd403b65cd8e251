//! The IEC 61131-3 literals of monitored values, written once for every monitor: how a
//! variable's value is shown (`TRUE`, `-3`, `0.5`, `T#1s500ms`, `D#2024-06-15`,
//! `TOD#12:30:00`, `DT#2024-06-15-12:30:00`, `LT#2ms`, `'text'`, `'a'`, `"wide"`, `"€"`,
//! `REF(Main.x)`, `NULL`) and how a text typed for a variable of a given [`VarType`] becomes
//! a [`Value`], or why it is none ([`LiteralError`]). `plcc run --print/--set`, the PLC's
//! watch lines and the online protocol's clients (`plcctl`, client partitions) use it.
//!
//! no_std and no allocation: a STRING or WSTRING text is parsed into a buffer the caller
//! gives. Never here: what a program computes (the STRING conversions of the builtins are
//! [`crate::builtins`]' own, part of the VM's semantics).

use core::fmt::{self, Write};

use crate::builtins::{format_date_time, parse_date_time};
use crate::image::{Storage, VarType};
use crate::isa::TimeKind;
use crate::vm::Value;

/// Writes `value` as an IEC literal.
pub fn write_value(f: &mut impl Write, value: &Value) -> fmt::Result {
    match *value {
        Value::Bool(b) => f.write_str(if b { "TRUE" } else { "FALSE" }),
        Value::Int(v) => write!(f, "{v}"),
        Value::UInt(v) => write!(f, "{v}"),
        Value::Real(v) => write_real(f, v as f64, true),
        Value::LReal(v) => write_real(f, v, false),
        Value::Time(ns) => write_date_time(f, TimeKind::Time, ns),
        Value::Temporal(kind, ns) => write_date_time(f, kind, ns),
        Value::String(bytes) => write_string(f, bytes),
        Value::Char(c) => write_string(f, &[c]),
        Value::WString(bytes) => write_wstring(f, units(bytes)),
        Value::WChar(unit) => write_wstring(f, [unit]),
        Value::Ref { address: None, .. } => f.write_str("NULL"),
        Value::Ref {
            target: Some(name), ..
        } => write!(f, "REF({name})"),
        Value::Ref {
            address: Some(address),
            target: None,
        } => write!(f, "16#{address:08X}"),
    }
}

/// The UTF-16 code units of little-endian byte pairs (an odd last byte is ignored).
pub fn units(bytes: &[u8]) -> impl Iterator<Item = u16> + '_ {
    bytes
        .chunks_exact(2)
        .map(|u| u16::from_le_bytes([u[0], u[1]]))
}

/// A date/time value: `T#1s500ms`, `LT#2ms`, `D#2024-06-15`, `TOD#12:30:00.5`,
/// `DT#2024-06-15-12:30:00`, `LD#...`, `LTOD#...`, `LDT#...`.
pub fn write_date_time(f: &mut impl Write, kind: TimeKind, ns: i64) -> fmt::Result {
    let mut out = Tracked::new(f);
    format_date_time(&mut out, kind, ns);
    out.result
}

/// A REAL/LREAL: the shortest decimal that reads back as the same value, always with a `.`
/// (`4.0`, `0.1`), `NaN`, `INF`, `-INF`. `single`: `v` is a REAL's value.
pub fn write_real(f: &mut impl Write, v: f64, single: bool) -> fmt::Result {
    if v.is_nan() {
        return f.write_str("NaN");
    }
    if v.is_infinite() {
        return f.write_str(if v > 0.0 { "INF" } else { "-INF" });
    }
    let mut out = Tracked::new(f);
    if single {
        write!(out, "{}", v as f32)?;
    } else {
        write!(out, "{v}")?;
    }
    if !out.dot {
        out.write_str(".0")?;
    }
    out.result
}

/// A STRING (or a CHAR, one byte): `'text'`, with `$'`, `$$`, `$N`, `$R`, `$T`, `$P` and
/// `$hh` for every other byte outside printable ASCII (also a space stays a space).
pub fn write_string(f: &mut impl Write, bytes: &[u8]) -> fmt::Result {
    f.write_char('\'')?;
    for &b in bytes {
        match b {
            b'\'' => f.write_str("$'")?,
            b'$' => f.write_str("$$")?,
            b'\n' => f.write_str("$N")?,
            b'\r' => f.write_str("$R")?,
            b'\t' => f.write_str("$T")?,
            0x0c => f.write_str("$P")?,
            0x20..=0x7e => f.write_char(b as char)?,
            _ => write!(f, "${b:02X}")?,
        }
    }
    f.write_char('\'')
}

/// A WSTRING (or a WCHAR, one unit): `"text"`, with `$"`, `$$`, `$N`, `$R`, `$T`, and
/// `$hhhh` for other control characters and unpaired surrogates.
pub fn write_wstring(f: &mut impl Write, units: impl IntoIterator<Item = u16>) -> fmt::Result {
    f.write_char('"')?;
    for c in char::decode_utf16(units) {
        match c {
            Ok('"') => f.write_str("$\"")?,
            Ok('$') => f.write_str("$$")?,
            Ok('\n') => f.write_str("$N")?,
            Ok('\r') => f.write_str("$R")?,
            Ok('\t') => f.write_str("$T")?,
            Ok(c) if !c.is_control() => f.write_char(c)?,
            Ok(c) => write!(f, "${:04X}", c as u32)?,
            Err(e) => write!(f, "${:04X}", e.unpaired_surrogate())?,
        }
    }
    f.write_char('"')
}

/// A writer that remembers its first error and whether a `.` went through it.
struct Tracked<'w, W: Write> {
    inner: &'w mut W,
    dot: bool,
    result: fmt::Result,
}

impl<'w, W: Write> Tracked<'w, W> {
    fn new(inner: &'w mut W) -> Self {
        Self {
            inner,
            dot: false,
            result: Ok(()),
        }
    }
}

impl<W: Write> Write for Tracked<'_, W> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        self.dot |= s.contains('.');
        if self.result.is_ok() {
            self.result = self.inner.write_str(s);
        }
        self.result
    }
}

/// Why a text is no value of a variable's type. Its `Display` reads after "`TEXT` is ".
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LiteralError {
    /// Not a literal of the type.
    Syntax(VarType),
    /// A number or character outside the type's range.
    OutOfRange(VarType),
    /// A STRING or WSTRING longer than the buffer it is parsed into.
    TooLong {
        /// The buffer's bytes.
        max_bytes: usize,
    },
    /// A reference: never written by a monitor.
    ReadOnly,
}

impl fmt::Display for LiteralError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            LiteralError::Syntax(ty) => {
                write!(f, "not a {} literal (expected {})", ty.name(), form(ty))
            }
            LiteralError::OutOfRange(ty) => {
                write!(f, "out of the range of {}", ty.name())?;
                match ty.int_range() {
                    Some((lo, hi)) => write!(f, " ({lo} to {hi})"),
                    None => Ok(()),
                }
            }
            LiteralError::TooLong { max_bytes } => {
                write!(
                    f,
                    "longer than {max_bytes} bytes, the most that can be sent"
                )
            }
            LiteralError::ReadOnly => f.write_str(
                "not writable: a reference is read-only online (a written address could make \
                 the program reach another variable than the one it referenced, or trap)",
            ),
        }
    }
}

/// What a literal of `ty` looks like, for [`LiteralError::Syntax`].
fn form(ty: VarType) -> &'static str {
    use VarType::*;
    match ty {
        Bool => "TRUE or FALSE",
        SInt | Int | DInt | LInt => "a whole number such as -5, 16#FF or 2#1010",
        USInt | UInt | UDInt | ULInt | Byte | Word | DWord | LWord => {
            "a whole number such as 5, 16#FF or 2#1010"
        }
        Real | LReal => "a number such as 0.5 or -1.5E3",
        Time => "a duration such as T#1h2m3s4ms5us6ns or T#-2.5s",
        LTime => "a duration such as LT#1h2m3s4ms5us6ns",
        Date => "a date such as D#2024-06-15",
        LDate => "a date such as LD#2024-06-15",
        Tod => "a time of day such as TOD#12:30:00 or TOD#12:30:00.25 (hours 0 to 23)",
        LTod => "a time of day such as LTOD#12:30:00.000000001 (hours 0 to 23)",
        Dt => "a date and time such as DT#2024-06-15-12:30:00",
        LDt => "a date and time such as LDT#2024-06-15-12:30:00",
        Char => "one character such as 'a' or '$41', or its code 0 to 255",
        WChar => "one character such as \"a\" or \"$20AC\", or its code 0 to 65535",
        String => "text, quoted as 'text' with $ escapes ($$, $', $N, $R, $T, $P, $hh)",
        WString => "text, quoted as \"text\" with $ escapes ($$, $\", $N, $R, $T, $P, $hhhh)",
        Ref => "nothing: references are read-only",
    }
}

/// Parses `text` as a value for a variable of type `ty`: a literal with or without its type
/// prefix (`INT#5`, `T#20ms`, `TOD#12:30:00`, `D#2024-06-15`; integers also `16#FF`, `2#1010`,
/// `8#17` with `_` separators; BOOL `TRUE`/`FALSE`/`1`/`0`). A STRING or WSTRING is quoted
/// (`'...'`, `"..."`, IEC `$` escapes) or, unquoted, taken as it is (shells strip quotes);
/// its bytes (WSTRING: UTF-16 little-endian) go into `buf`. A CHAR or WCHAR is one quoted
/// or bare character, or its number. A reference is never parsed ([`LiteralError::ReadOnly`]).
pub fn parse<'b>(text: &str, ty: VarType, buf: &'b mut [u8]) -> Result<Value<'b>, LiteralError> {
    let text = text.trim();
    let syntax = LiteralError::Syntax(ty);
    if let Some(kind) = ty.time_kind() {
        let ns = parse_date_time(text.as_bytes(), kind).ok_or(syntax)?;
        return Ok(Value::temporal(kind, ns));
    }
    match ty.storage() {
        Storage::Reference => Err(LiteralError::ReadOnly),
        Storage::String | Storage::WString => {
            let wide = ty == VarType::WString;
            let quote = if wide { '"' } else { '\'' };
            // `'text'`, `STRING#'text'`, or (unquoted) the text as it is.
            let typed = text
                .split_once('#')
                .filter(|(p, rest)| {
                    (p.eq_ignore_ascii_case("STRING") || p.eq_ignore_ascii_case("WSTRING"))
                        && quoted(rest, quote).is_some()
                })
                .map_or(text, |(_, rest)| rest);
            let n = match (quoted(typed, quote), wide) {
                (Some(inner), false) => decode(inner, quote, Piece::push_byte_text, &mut *buf)?,
                (Some(inner), true) => decode(inner, quote, Piece::push_wide, &mut *buf)?,
                (None, false) => Out {
                    buf: &mut *buf,
                    len: 0,
                }
                .push(text.as_bytes())?,
                (None, true) => {
                    let mut out = Out {
                        buf: &mut *buf,
                        len: 0,
                    };
                    for c in text.chars() {
                        Piece::Char(c).push_wide(&mut out)?;
                    }
                    out.len
                }
            };
            let text: &'b [u8] = buf;
            Ok(if wide {
                Value::WString(&text[..n])
            } else {
                Value::String(&text[..n])
            })
        }
        Storage::Scalar(_) => match (ty, without_type_prefix(text)) {
            (VarType::Bool, body) => match body {
                b if b.eq_ignore_ascii_case("TRUE") || b == "1" => Ok(Value::Bool(true)),
                b if b.eq_ignore_ascii_case("FALSE") || b == "0" => Ok(Value::Bool(false)),
                _ => Err(syntax),
            },
            (VarType::Real, body) => body.parse().map(Value::Real).map_err(|_| syntax),
            (VarType::LReal, body) => body.parse().map(Value::LReal).map_err(|_| syntax),
            (VarType::Char | VarType::WChar, body) => {
                let code = character(body, ty).ok_or(syntax)?;
                let (_, hi) = ty.int_range().unwrap_or((0, 0));
                if code as i128 > hi {
                    return Err(LiteralError::OutOfRange(ty));
                }
                Ok(if ty == VarType::Char {
                    Value::Char(code as u8)
                } else {
                    Value::WChar(code as u16)
                })
            }
            (ty, body) => {
                let (lo, hi) = ty.int_range().ok_or(syntax)?;
                let v = integer(body).ok_or(syntax)?;
                if v < lo || v > hi {
                    return Err(LiteralError::OutOfRange(ty));
                }
                Ok(if ty.is_signed_int() {
                    Value::Int(v as i64)
                } else {
                    Value::UInt(v as u64)
                })
            }
        },
    }
}

/// `text` without a leading `TYPE#` naming a scalar type (`INT#5` -> `5`); a number base
/// (`16#FF`) is no type.
fn without_type_prefix(text: &str) -> &str {
    match text.split_once('#') {
        Some((prefix, rest))
            if VarType::ALL
                .iter()
                .any(|t| t.mem_type().is_some() && t.name().eq_ignore_ascii_case(prefix)) =>
        {
            rest
        }
        _ => text,
    }
}

/// The inside of `text` when it is enclosed in `quote`s.
fn quoted(text: &str, quote: char) -> Option<&str> {
    text.strip_prefix(quote)?.strip_suffix(quote)
}

/// An integer: `[+|-]digits`, `[+|-]2#bits`, `8#...`, `16#...`, `_` between digits.
fn integer(text: &str) -> Option<i128> {
    let (negative, rest) = match text.as_bytes().first()? {
        b'-' => (true, &text[1..]),
        b'+' => (false, &text[1..]),
        _ => (false, text),
    };
    let (radix, digits) = match rest.split_once('#') {
        Some(("2", d)) => (2, d),
        Some(("8", d)) => (8, d),
        Some(("16", d)) => (16, d),
        Some(_) => return None,
        None => (10, rest),
    };
    if digits.starts_with('_') || digits.ends_with('_') {
        return None;
    }
    let mut value: i128 = 0;
    let mut any = false;
    for c in digits.chars() {
        if c == '_' {
            continue;
        }
        // Beyond every type's range the value stays just above ULINT's (out of range, not
        // a syntax error).
        value = (value * radix as i128 + c.to_digit(radix)? as i128).min(u64::MAX as i128 + 1);
        any = true;
    }
    any.then_some(if negative { -value } else { value })
}

/// A CHAR's or WCHAR's code: one quoted character or escape (`'a'`, `'$41'`, `"$20AC"`), a
/// number, or one bare character.
fn character(text: &str, ty: VarType) -> Option<u32> {
    let inner = quoted(text, '\'')
        .map(|i| (i, '\''))
        .or_else(|| quoted(text, '"').map(|i| (i, '"')));
    if let Some((inner, quote)) = inner {
        let mut pieces = Pieces {
            rest: inner,
            quote,
            wide: ty == VarType::WChar || quote == '"',
        };
        let piece = pieces.next()?.ok()?;
        if pieces.next().is_some() {
            return None;
        }
        return Some(match piece {
            Piece::Byte(b) => b as u32,
            Piece::Unit(u) => u as u32,
            Piece::Char(c) => c as u32,
        });
    }
    if let Some(code) = integer(text) {
        return u32::try_from(code).ok();
    }
    let mut chars = text.chars();
    match (chars.next(), chars.next()) {
        (Some(c), None) => Some(c as u32),
        _ => None,
    }
}

/// One character of a quoted literal: an escaped byte (`$hh`, STRING), an escaped code
/// unit (`$hhhh`, WSTRING) or a character.
#[derive(Clone, Copy)]
enum Piece {
    Byte(u8),
    Unit(u16),
    Char(char),
}

/// A buffer being filled.
struct Out<'b> {
    buf: &'b mut [u8],
    len: usize,
}

impl Out<'_> {
    fn push(&mut self, bytes: &[u8]) -> Result<usize, LiteralError> {
        let end = self.len + bytes.len();
        let max_bytes = self.buf.len();
        self.buf
            .get_mut(self.len..end)
            .ok_or(LiteralError::TooLong { max_bytes })?
            .copy_from_slice(bytes);
        self.len = end;
        Ok(end)
    }
}

impl Piece {
    /// Appends the piece to a STRING's bytes (a character in UTF-8).
    fn push_byte_text(self, out: &mut Out) -> Result<usize, LiteralError> {
        match self {
            Piece::Byte(b) => out.push(&[b]),
            Piece::Unit(u) => out.push(&u.to_le_bytes()[..1]),
            Piece::Char(c) => out.push(c.encode_utf8(&mut [0; 4]).as_bytes()),
        }
    }

    /// Appends the piece to a WSTRING's UTF-16 little-endian bytes.
    fn push_wide(self, out: &mut Out) -> Result<usize, LiteralError> {
        match self {
            Piece::Byte(b) => out.push(&u16::from(b).to_le_bytes()),
            Piece::Unit(u) => out.push(&u.to_le_bytes()),
            Piece::Char(c) => {
                let mut pair = [0u16; 2];
                let mut end = out.len;
                for unit in c.encode_utf16(&mut pair) {
                    end = out.push(&unit.to_le_bytes())?;
                }
                Ok(end)
            }
        }
    }
}

/// The characters of a quoted literal's inside, `$` escapes decoded as the compiler does.
struct Pieces<'t> {
    rest: &'t str,
    quote: char,
    wide: bool,
}

impl Iterator for Pieces<'_> {
    type Item = Result<Piece, ()>;

    fn next(&mut self) -> Option<Self::Item> {
        let mut chars = self.rest.chars();
        let c = chars.next()?;
        if c != '$' {
            self.rest = chars.as_str();
            // An unescaped quote would have ended the literal.
            return Some(if c == self.quote {
                Err(())
            } else {
                Ok(Piece::Char(c))
            });
        }
        let after = chars.as_str();
        let hex = |n: usize| {
            let digits = after.get(..n)?;
            digits
                .bytes()
                .all(|b| b.is_ascii_hexdigit())
                .then(|| u32::from_str_radix(digits, 16).ok())
                .flatten()
        };
        let (piece, used) = if self.wide && hex(4).is_some() {
            (Piece::Unit(hex(4).unwrap_or(0) as u16), 4)
        } else if !self.wide && hex(2).is_some() {
            (Piece::Byte(hex(2).unwrap_or(0) as u8), 2)
        } else {
            let e = match chars.next() {
                Some(e) => e,
                None => return Some(Err(())),
            };
            let piece = match e.to_ascii_uppercase() {
                '$' => '$',
                '\'' => '\'',
                '"' => '"',
                'L' | 'N' => '\n',
                'P' => '\x0c',
                'R' => '\r',
                'T' => '\t',
                _ => return Some(Err(())),
            };
            (Piece::Char(piece), e.len_utf8())
        };
        self.rest = &after[used..];
        Some(Ok(piece))
    }
}

/// Decodes a quoted literal's inside into `buf` with `push`; returns the bytes written.
fn decode(
    inner: &str,
    quote: char,
    push: fn(Piece, &mut Out) -> Result<usize, LiteralError>,
    buf: &mut [u8],
) -> Result<usize, LiteralError> {
    let wide = quote == '"';
    let ty = if wide {
        VarType::WString
    } else {
        VarType::String
    };
    let mut out = Out { buf, len: 0 };
    for piece in (Pieces {
        rest: inner,
        quote,
        wide,
    }) {
        push(piece.map_err(|()| LiteralError::Syntax(ty))?, &mut out)?;
    }
    Ok(out.len)
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::string::{String, ToString};
    use alloc::vec::Vec;

    fn shown(v: Value) -> String {
        v.to_string()
    }

    fn parsed(text: &str, ty: VarType) -> Result<String, LiteralError> {
        let mut buf = [0u8; 64];
        parse(text, ty, &mut buf).map(shown)
    }

    #[test]
    fn every_kind_is_shown_as_its_literal() {
        assert_eq!(shown(Value::Bool(true)), "TRUE");
        assert_eq!(shown(Value::Int(-3)), "-3");
        assert_eq!(shown(Value::UInt(u64::MAX)), "18446744073709551615");
        assert_eq!(shown(Value::Real(0.1)), "0.1");
        assert_eq!(shown(Value::Real(4.0)), "4.0");
        assert_eq!(shown(Value::LReal(-2.5e-7)), "-0.00000025");
        assert_eq!(shown(Value::LReal(f64::NAN)), "NaN");
        assert_eq!(shown(Value::Real(f32::NEG_INFINITY)), "-INF");
        assert_eq!(shown(Value::Time(1_500_000_000)), "T#1s500ms");
        assert_eq!(shown(Value::Time(-20_000_000)), "T#-20ms");
        assert_eq!(shown(Value::Time(0)), "T#0s");
        let day = crate::builtins::NS_PER_DAY;
        let date = crate::builtins::date_from_parts(2024, 6, 15).unwrap();
        let half_past = (12 * 3600 + 30 * 60) * 1_000_000_000;
        for (kind, ns, text) in [
            (TimeKind::LTime, 2_000_001, "LT#2ms1ns"),
            (TimeKind::Date, date, "D#2024-06-15"),
            (TimeKind::LDate, -day, "LD#1969-12-31"),
            (TimeKind::Tod, half_past, "TOD#12:30:00"),
            (TimeKind::LTod, half_past + 1, "LTOD#12:30:00.000000001"),
            (TimeKind::Dt, date + half_past, "DT#2024-06-15-12:30:00"),
            (
                TimeKind::LDt,
                date + 500_000_000,
                "LDT#2024-06-15-00:00:00.5",
            ),
        ] {
            assert_eq!(shown(Value::Temporal(kind, ns)), text);
        }
        assert_eq!(shown(Value::String(b"it's $5\n\xff")), "'it$'s $$5$N$FF'");
        assert_eq!(shown(Value::Char(b'a')), "'a'");
        assert_eq!(shown(Value::Char(b'\'')), "'$''");
        let wide: Vec<u8> = "Grüße €\""
            .encode_utf16()
            .flat_map(u16::to_le_bytes)
            .collect();
        assert_eq!(shown(Value::WString(&wide)), "\"Grüße €$\"\"");
        assert_eq!(
            shown(Value::WString(&[0x00, 0xd8])),
            "\"$D800\"",
            "unpaired"
        );
        assert_eq!(shown(Value::WChar(0x20ac)), "\"€\"");
        assert_eq!(shown(Value::WChar(7)), "\"$0007\"");
        let null = Value::Ref {
            address: None,
            target: None,
        };
        assert_eq!(shown(null), "NULL");
        let named = Value::Ref {
            address: Some(16),
            target: Some("Main.x"),
        };
        assert_eq!(shown(named), "REF(Main.x)");
        let unnamed = Value::Ref {
            address: Some(0x12c),
            target: None,
        };
        assert_eq!(shown(unnamed), "16#0000012C");
    }

    #[test]
    fn what_is_shown_parses_back_to_the_same_value() {
        let wide: Vec<u8> = "Grüße €\"$\n𝄞"
            .encode_utf16()
            .flat_map(u16::to_le_bytes)
            .collect();
        let date = crate::builtins::date_from_parts(2024, 6, 15).unwrap();
        let values = [
            (VarType::Bool, Value::Bool(false)),
            (VarType::SInt, Value::Int(-128)),
            (VarType::LInt, Value::Int(i64::MIN)),
            (VarType::ULInt, Value::UInt(u64::MAX)),
            (VarType::Real, Value::Real(0.1)),
            (VarType::LReal, Value::LReal(-1.0e300)),
            (VarType::Time, Value::Time(90_061_001_001_001)),
            (VarType::LTime, Value::Temporal(TimeKind::LTime, -1)),
            (VarType::Date, Value::Temporal(TimeKind::Date, date)),
            (
                VarType::Tod,
                Value::Temporal(TimeKind::Tod, 45_296_789_000_000),
            ),
            (VarType::Dt, Value::Temporal(TimeKind::Dt, date + 1)),
            (VarType::LDt, Value::Temporal(TimeKind::LDt, -1)),
            (VarType::Char, Value::Char(b'$')),
            (VarType::Char, Value::Char(0xe9)),
            (VarType::WChar, Value::WChar(0x20ac)),
            (VarType::WChar, Value::WChar(b'"' as u16)),
            (VarType::String, Value::String(b"a 'b' $c\t\x01")),
            (VarType::WString, Value::WString(&wide)),
        ];
        for (ty, value) in values {
            let text = value.to_string();
            let mut buf = [0u8; 64];
            assert_eq!(parse(&text, ty, &mut buf), Ok(value), "{ty:?} {text}");
        }
    }

    #[test]
    fn typed_text_is_parsed_the_iec_way() {
        assert_eq!(parsed("true", VarType::Bool), Ok("TRUE".into()));
        assert_eq!(parsed("BOOL#0", VarType::Bool), Ok("FALSE".into()));
        assert_eq!(parsed("INT#-5", VarType::Int), Ok("-5".into()));
        assert_eq!(parsed("16#FF", VarType::Byte), Ok("255".into()));
        assert_eq!(parsed("BYTE#2#1010_1010", VarType::Byte), Ok("170".into()));
        assert_eq!(parsed("8#17", VarType::UInt), Ok("15".into()));
        assert_eq!(parsed("1_000", VarType::DInt), Ok("1000".into()));
        assert_eq!(parsed("-1.5E3", VarType::LReal), Ok("-1500.0".into()));
        assert_eq!(parsed("T#1.5s", VarType::Time), Ok("T#1s500ms".into()));
        assert_eq!(parsed("2s", VarType::Time), Ok("T#2s".into()));
        assert_eq!(parsed("LTIME#1h", VarType::LTime), Ok("LT#1h".into()));
        assert_eq!(
            parsed("DATE#2024-2-29", VarType::Date),
            Ok("D#2024-02-29".into())
        );
        assert_eq!(
            parsed("TIME_OF_DAY#7:05", VarType::Tod),
            Ok("TOD#07:05:00".into())
        );
        assert_eq!(
            parsed("DT#2024-06-15-12:30:00.25", VarType::Dt),
            Ok("DT#2024-06-15-12:30:00.25".into())
        );
        assert_eq!(
            parsed("LTOD#23:59:59.999999999", VarType::LTod),
            Ok("LTOD#23:59:59.999999999".into())
        );
        assert_eq!(
            parsed("INT#5", VarType::String),
            Ok("'INT#5'".into()),
            "unquoted"
        );
        assert_eq!(parsed("'a'", VarType::Char), Ok("'a'".into()));
        assert_eq!(parsed("a", VarType::Char), Ok("'a'".into()), "bare");
        assert_eq!(parsed("65", VarType::Char), Ok("'A'".into()), "a code");
        assert_eq!(parsed("'$41'", VarType::Char), Ok("'A'".into()));
        assert_eq!(parsed("\"$20AC\"", VarType::WChar), Ok("\"€\"".into()));
        assert_eq!(parsed("€", VarType::WChar), Ok("\"€\"".into()));
        assert_eq!(parsed("'it$'s'", VarType::String), Ok("'it$'s'".into()));
        assert_eq!(
            parsed("plain text", VarType::String),
            Ok("'plain text'".into())
        );
        assert_eq!(parsed("STRING#'x'", VarType::String), Ok("'x'".into()));
        assert_eq!(
            parsed("\"Zoë $N\"", VarType::WString),
            Ok("\"Zoë $N\"".into())
        );
        assert_eq!(
            parsed("Zoë", VarType::WString),
            Ok("\"Zoë\"".into()),
            "bare"
        );
        assert_eq!(parsed("\"\"", VarType::WString), Ok("\"\"".into()));
    }

    #[test]
    fn malformed_text_gets_its_reason() {
        use LiteralError::*;
        for (text, ty, want) in [
            ("maybe", VarType::Bool, Syntax(VarType::Bool)),
            ("", VarType::Int, Syntax(VarType::Int)),
            ("12a", VarType::Int, Syntax(VarType::Int)),
            ("3#12", VarType::Int, Syntax(VarType::Int)),
            ("_1", VarType::Int, Syntax(VarType::Int)),
            (
                "99999999999999999999999",
                VarType::LInt,
                OutOfRange(VarType::LInt),
            ),
            ("STRING#5", VarType::Int, Syntax(VarType::Int)),
            ("32768", VarType::Int, OutOfRange(VarType::Int)),
            ("-1", VarType::UDInt, OutOfRange(VarType::UDInt)),
            ("256", VarType::Char, OutOfRange(VarType::Char)),
            ("'€'", VarType::Char, OutOfRange(VarType::Char)),
            ("'𝄞'", VarType::WChar, OutOfRange(VarType::WChar)),
            ("'ab'", VarType::Char, Syntax(VarType::Char)),
            ("''", VarType::Char, Syntax(VarType::Char)),
            ("ab", VarType::Char, Syntax(VarType::Char)),
            ("x.5", VarType::Real, Syntax(VarType::Real)),
            ("T#5", VarType::Time, Syntax(VarType::Time)),
            ("TOD#12:00", VarType::Time, Syntax(VarType::Time)),
            ("TOD#24:00:00", VarType::Tod, Syntax(VarType::Tod)),
            ("TOD#12:60", VarType::Tod, Syntax(VarType::Tod)),
            ("D#2023-02-29", VarType::Date, Syntax(VarType::Date)),
            ("D#2024-06-15-12:00", VarType::Date, Syntax(VarType::Date)),
            ("DT#2024-06-15", VarType::Dt, Syntax(VarType::Dt)),
            ("'it's'", VarType::String, Syntax(VarType::String)),
            ("'bad $Q'", VarType::String, Syntax(VarType::String)),
            ("'dangling $'", VarType::String, Syntax(VarType::String)),
            ("\"$12\"", VarType::WString, Syntax(VarType::WString)),
            ("REF(x)", VarType::Ref, ReadOnly),
            ("NULL", VarType::Ref, ReadOnly),
        ] {
            assert_eq!(parsed(text, ty), Err(want), "{text:?} as {ty:?}");
        }
        let mut small = [0u8; 3];
        assert_eq!(
            parse("'abcd'", VarType::String, &mut small),
            Err(TooLong { max_bytes: 3 })
        );
        assert_eq!(
            parse("ab", VarType::WString, &mut small),
            Err(TooLong { max_bytes: 3 })
        );
        assert_eq!(
            Syntax(VarType::Tod).to_string(),
            "not a TOD literal (expected a time of day such as TOD#12:30:00 or TOD#12:30:00.25 (hours 0 to 23))"
        );
        assert_eq!(
            OutOfRange(VarType::USInt).to_string(),
            "out of the range of USINT (0 to 255)"
        );
    }
}
