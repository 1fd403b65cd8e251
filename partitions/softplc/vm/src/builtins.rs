//! The standard-function library behind `CALL_BUILTIN` (math and STRING functions).
//!
//! Shared by the interpreter and the reference model: the model checks *instruction*
//! semantics; this library has its own unit tests.
//!
//! Strings live in data memory as `max_len: u16 LE, cur_len: u16 LE, bytes[max_len]`. A string
//! whose header or bytes fall outside data memory raises INVALID_ADDRESS; `cur_len > max_len`
//! is read as `max_len`. A written text shorter than `max_len` is followed by a NUL byte. Results are assembled in a fixed buffer of [`MAX_STRING_LEN`] bytes
//! (so a result never exceeds that many characters) and then written to `dst` truncated to its
//! `max_len`; a builtin that traps has written nothing.

use crate::fmath;
use crate::isa::{Builtin, Trap, read_u16};
use core::fmt::Write;

/// Longest string a string builtin produces.
pub const MAX_STRING_LEN: usize = 1024;

/// A validated string operand: byte range of its text and its capacity.
#[derive(Clone, Copy)]
struct StrRef {
    addr: usize,
    max: usize,
    len: usize,
}

fn string_at(data: &[u8], address: u64) -> Result<StrRef, Trap> {
    let addr = usize::try_from(address).map_err(|_| Trap::InvalidAddress)?;
    if addr.checked_add(4).is_none_or(|end| end > data.len()) {
        return Err(Trap::InvalidAddress);
    }
    let max = read_u16(data, addr) as usize;
    if addr + 4 + max > data.len() {
        return Err(Trap::InvalidAddress);
    }
    let len = (read_u16(data, addr + 2) as usize).min(max);
    Ok(StrRef { addr, max, len })
}

impl StrRef {
    fn text<'d>(&self, data: &'d [u8]) -> &'d [u8] {
        &data[self.addr + 4..self.addr + 4 + self.len]
    }
}

/// Fixed-capacity result buffer (excess is silently dropped: results are truncated anyway).
struct Buf {
    bytes: [u8; MAX_STRING_LEN],
    len: usize,
}

impl Buf {
    fn new() -> Self {
        Buf {
            bytes: [0; MAX_STRING_LEN],
            len: 0,
        }
    }
    fn push(&mut self, text: &[u8]) {
        let n = text.len().min(MAX_STRING_LEN - self.len);
        self.bytes[self.len..self.len + n].copy_from_slice(&text[..n]);
        self.len += n;
    }
    fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.len]
    }
}

impl Write for Buf {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        self.push(s.as_bytes());
        Ok(())
    }
}

fn write_string(data: &mut [u8], dst: StrRef, text: &[u8]) {
    let n = text.len().min(dst.max);
    data[dst.addr + 2..dst.addr + 4].copy_from_slice(&(n as u16).to_le_bytes());
    data[dst.addr + 4..dst.addr + 4 + n].copy_from_slice(&text[..n]);
    if n < dst.max {
        data[dst.addr + 4 + n] = 0;
    }
}

/// Clamps a signed count to `0..=max`.
fn clamp_count(value: u64, max: usize) -> usize {
    (value as i64).clamp(0, max as i64) as usize
}

fn f32_arg(cell: u64) -> f64 {
    f32::from_bits(cell as u32) as f64
}

fn f32_cell(v: f64) -> u64 {
    (v as f32).to_bits() as u64
}

/// Math builtin on f64 with domain checks; `None` = NUMERIC_ERROR.
fn math(builtin: Builtin, x: f64, y: f64) -> Option<f64> {
    use Builtin::*;
    Some(match builtin {
        SqrtF64 | SqrtF32 => {
            if x < 0.0 {
                return None;
            }
            fmath::sqrt(x)
        }
        LnF64 | LnF32 | LogF64 | LogF32 => {
            if x.is_nan() || x <= 0.0 {
                return None;
            }
            if matches!(builtin, LnF64 | LnF32) {
                fmath::ln(x)
            } else {
                fmath::log10(x)
            }
        }
        ExpF64 | ExpF32 => fmath::exp(x),
        SinF64 | SinF32 => fmath::sin(x),
        CosF64 | CosF32 => fmath::cos(x),
        TanF64 | TanF32 => fmath::tan(x),
        AsinF64 | AsinF32 | AcosF64 | AcosF32 => {
            if !(-1.0..=1.0).contains(&x) {
                return None;
            }
            if matches!(builtin, AsinF64 | AsinF32) {
                fmath::asin(x)
            } else {
                fmath::acos(x)
            }
        }
        AtanF64 | AtanF32 => fmath::atan(x),
        ExptF64 | ExptF32 => fmath::pow(x, y)?,
        AbsF64 | AbsF32 => x.abs(),
        _ => return None,
    })
}

/// Formats a float the IEC way: shortest round-trip decimal, always with a '.'.
fn format_float(buf: &mut Buf, v: impl core::fmt::Display) {
    let start = buf.len;
    let _ = write!(buf, "{v}");
    let text = &buf.bytes[start..buf.len];
    if text.iter().all(|c| c.is_ascii_digit() || *c == b'-') {
        buf.push(b".0");
    }
}

/// Formats TIME nanoseconds as `T#1d2h3m4s5ms6us7ns` (zero components omitted, `T#0s` for 0).
pub fn format_time(buf: &mut impl Write, ns: i64) {
    let _ = buf.write_str("T#");
    if ns == 0 {
        let _ = buf.write_str("0s");
        return;
    }
    if ns < 0 {
        let _ = buf.write_str("-");
    }
    let mut rest = ns.unsigned_abs();
    const UNITS: [(u64, &str); 7] = [
        (86_400_000_000_000, "d"),
        (3_600_000_000_000, "h"),
        (60_000_000_000, "m"),
        (1_000_000_000, "s"),
        (1_000_000, "ms"),
        (1_000, "us"),
        (1, "ns"),
    ];
    for (size, unit) in UNITS {
        let count = rest / size;
        rest %= size;
        if count != 0 {
            let _ = write!(buf, "{count}{unit}");
        }
    }
}

fn parse_int(text: &[u8]) -> Option<i64> {
    let text = core::str::from_utf8(text).ok()?.trim();
    let (negative, digits) = match text.as_bytes().first()? {
        b'-' => (true, &text[1..]),
        b'+' => (false, &text[1..]),
        _ => (false, text),
    };
    if digits.is_empty() || digits.starts_with('_') || digits.ends_with('_') {
        return None;
    }
    let mut value: i128 = 0;
    for c in digits.bytes() {
        match c {
            b'0'..=b'9' => {
                value = value * 10 + (c - b'0') as i128;
                if value > 1 << 63 {
                    return None;
                }
            }
            b'_' => {}
            _ => return None,
        }
    }
    let value = if negative { -value } else { value };
    i64::try_from(value).ok()
}

/// Executes `builtin` on its argument cells (first argument first). Returns the result cell
/// if the builtin has one.
pub fn call(builtin: Builtin, args: &[u64], data: &mut [u8]) -> Result<Option<u64>, Trap> {
    use Builtin::*;
    let arg = |i: usize| args.get(i).copied().unwrap_or(0);
    let f64_math = |b| {
        let y = f64::from_bits(arg(1));
        math(b, f64::from_bits(arg(0)), y)
            .map(|r| Some(r.to_bits()))
            .ok_or(Trap::NumericError)
    };
    let f32_math = |b| {
        let y = f32_arg(arg(1));
        math(b, f32_arg(arg(0)), y)
            .map(|r| Some(f32_cell(r)))
            .ok_or(Trap::NumericError)
    };
    match builtin {
        SqrtF64 | LnF64 | LogF64 | ExpF64 | SinF64 | CosF64 | TanF64 | AsinF64 | AcosF64
        | AtanF64 | ExptF64 | AbsF64 => f64_math(builtin),
        SqrtF32 | LnF32 | LogF32 | ExpF32 | SinF32 | CosF32 | TanF32 | AsinF32 | AcosF32
        | AtanF32 | ExptF32 | AbsF32 => f32_math(builtin),
        StrLen => Ok(Some(string_at(data, arg(0))?.len as u64)),
        StrFind => {
            let (a, b) = (string_at(data, arg(0))?, string_at(data, arg(1))?);
            let (hay, needle) = (a.text(data), b.text(data));
            let position = if needle.is_empty() || needle.len() > hay.len() {
                0
            } else {
                hay.windows(needle.len())
                    .position(|w| w == needle)
                    .map_or(0, |p| p + 1)
            };
            Ok(Some(position as u64))
        }
        StrCompare => {
            let (a, b) = (string_at(data, arg(0))?, string_at(data, arg(1))?);
            Ok(Some(match a.text(data).cmp(b.text(data)) {
                core::cmp::Ordering::Less => -1i64 as u64,
                core::cmp::Ordering::Equal => 0,
                core::cmp::Ordering::Greater => 1,
            }))
        }
        StrToI64 => {
            let s = string_at(data, arg(0))?;
            parse_int(s.text(data))
                .map(|v| Some(v as u64))
                .ok_or(Trap::NumericError)
        }
        StrToF64 => {
            let s = string_at(data, arg(0))?;
            let text = core::str::from_utf8(s.text(data)).map_err(|_| Trap::NumericError)?;
            text.trim()
                .parse::<f64>()
                .map(|v| Some(v.to_bits()))
                .map_err(|_| Trap::NumericError)
        }
        StrSync => {
            let s = string_at(data, arg(0))?;
            let text = &data[s.addr + 4..s.addr + 4 + s.max];
            let len = text.iter().position(|&b| b == 0).unwrap_or(s.max);
            data[s.addr + 2..s.addr + 4].copy_from_slice(&(len as u16).to_le_bytes());
            Ok(None)
        }
        _ => {
            // Builtins writing a string result to the string at arg(0).
            let dst = string_at(data, arg(0))?;
            let mut buf = Buf::new();
            match builtin {
                StrAssign => buf.push(string_at(data, arg(1))?.text(data)),
                StrConcat => {
                    let (a, b) = (string_at(data, arg(1))?, string_at(data, arg(2))?);
                    buf.push(a.text(data));
                    buf.push(b.text(data));
                }
                StrLeft | StrRight => {
                    let a = string_at(data, arg(1))?.text(data);
                    let n = clamp_count(arg(2), a.len());
                    buf.push(if builtin == StrLeft {
                        &a[..n]
                    } else {
                        &a[a.len() - n..]
                    });
                }
                StrMid => {
                    let a = string_at(data, arg(1))?.text(data);
                    let start = clamp_count(arg(3), a.len() + 1).max(1) - 1;
                    let n = clamp_count(arg(2), a.len() - start);
                    buf.push(&a[start..start + n]);
                }
                StrInsert => {
                    let (a, b) = (string_at(data, arg(1))?, string_at(data, arg(2))?);
                    let (a, b) = (a.text(data), b.text(data));
                    let p = clamp_count(arg(3), a.len());
                    buf.push(&a[..p]);
                    buf.push(b);
                    buf.push(&a[p..]);
                }
                StrDelete | StrReplace => {
                    let a = string_at(data, arg(1))?.text(data);
                    let (replacement, n_arg, p_arg) = if builtin == StrReplace {
                        (string_at(data, arg(2))?.text(data), arg(3), arg(4))
                    } else {
                        (&[][..], arg(2), arg(3))
                    };
                    let start = clamp_count(p_arg, a.len() + 1).max(1) - 1;
                    let n = clamp_count(n_arg, a.len() - start);
                    buf.push(&a[..start]);
                    buf.push(replacement);
                    buf.push(&a[start + n..]);
                }
                StrFromI64 => {
                    let _ = write!(buf, "{}", arg(1) as i64);
                }
                StrFromU64 => {
                    let _ = write!(buf, "{}", arg(1));
                }
                StrFromF32 => format_float(&mut buf, f32::from_bits(arg(1) as u32)),
                StrFromF64 => format_float(&mut buf, f64::from_bits(arg(1))),
                StrFromBool => buf.push(if arg(1) != 0 { b"TRUE" } else { b"FALSE" }),
                StrFromTime => format_time(&mut buf, arg(1) as i64),
                _ => unreachable!("all builtins handled"),
            }
            write_string(data, dst, buf.as_bytes());
            Ok(None)
        }
    }
}
