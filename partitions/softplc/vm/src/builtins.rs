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
use crate::isa::{Builtin, TimeKind, Trap, read_u16};
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
        Atan2F64 | Atan2F32 => fmath::atan2(x, y),
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
    format_duration(buf, "T#", ns);
}

/// A duration after `prefix` (`T#` or `LT#`).
fn format_duration(buf: &mut impl Write, prefix: &str, ns: i64) {
    let _ = buf.write_str(prefix);
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

/// Nanoseconds in a day.
pub const NS_PER_DAY: i64 = 86_400_000_000_000;

/// Days from 1970-01-01 to `year-month-day` in the proleptic Gregorian calendar (any month
/// and day numbers; callers check them). `year` must be within a few million.
pub fn days_from_civil(year: i64, month: u32, day: u32) -> i64 {
    // Years start in March so that the leap day is the last day of a year.
    let m = month as i64;
    let y = if m <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let year_of_era = y - era * 400;
    let day_of_year = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + day as i64 - 1;
    let day_of_era = year_of_era * 365 + year_of_era / 4 - year_of_era / 100 + day_of_year;
    era * 146_097 + day_of_era - 719_468
}

/// The date `(year, month, day)` that is `days` days after 1970-01-01.
pub fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let day_of_era = z - era * 146_097;
    let year_of_era =
        (day_of_era - day_of_era / 1460 + day_of_era / 36_524 - day_of_era / 146_096) / 365;
    let day_of_year = day_of_era - (365 * year_of_era + year_of_era / 4 - year_of_era / 100);
    let mp = (5 * day_of_year + 2) / 153;
    let day = (day_of_year - (153 * mp + 2) / 5 + 1) as u32;
    let month = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let year = year_of_era + era * 400 + (month <= 2) as i64;
    (year, month, day)
}

/// Days of `month` (1..=12) in `year`.
pub fn days_in_month(year: i64, month: u32) -> u32 {
    match month {
        4 | 6 | 9 | 11 => 30,
        2 if year % 4 == 0 && (year % 100 != 0 || year % 400 == 0) => 29,
        2 => 28,
        _ => 31,
    }
}

/// The nanosecond value of a valid date, `None` if the date is invalid or outside `i64`.
pub fn date_from_parts(year: i64, month: i64, day: i64) -> Option<i64> {
    if !(1..=12).contains(&month) || !(-1_000_000..=1_000_000).contains(&year) {
        return None;
    }
    if day < 1 || day > days_in_month(year, month as u32) as i64 {
        return None;
    }
    days_from_civil(year, month as u32, day as u32).checked_mul(NS_PER_DAY)
}

/// The nanosecond value of a valid time of day (`ns_fraction` below one second).
fn tod_from_parts(hour: i64, minute: i64, second: i64, ns_fraction: i64) -> Option<i64> {
    if !(0..24).contains(&hour)
        || !(0..60).contains(&minute)
        || !(0..60).contains(&second)
        || !(0..1_000_000_000).contains(&ns_fraction)
    {
        return None;
    }
    Some(((hour * 60 + minute) * 60 + second) * 1_000_000_000 + ns_fraction)
}

/// `HH:MM:SS` and the fraction of a second (digits without trailing zeros, none when zero).
fn format_tod(buf: &mut impl Write, tod: i64) {
    let seconds = tod / 1_000_000_000;
    let _ = write!(
        buf,
        "{:02}:{:02}:{:02}",
        seconds / 3600,
        seconds / 60 % 60,
        seconds % 60
    );
    let mut fraction = tod % 1_000_000_000;
    if fraction != 0 {
        let mut digits = 9;
        while fraction % 10 == 0 {
            fraction /= 10;
            digits -= 1;
        }
        let _ = write!(buf, ".{fraction:0digits$}");
    }
}

fn format_date(buf: &mut impl Write, days: i64) {
    let (year, month, day) = civil_from_days(days);
    let _ = write!(buf, "{year:04}-{month:02}-{day:02}");
}

/// The IEC literal of a date/time value of `kind` (see [`Builtin::StrFromDateTime`]).
pub fn format_date_time(buf: &mut impl Write, kind: TimeKind, ns: i64) {
    let days = ns.div_euclid(NS_PER_DAY);
    let tod = ns.rem_euclid(NS_PER_DAY);
    match kind {
        TimeKind::Time | TimeKind::LTime => format_duration(buf, kind.prefix(), ns),
        TimeKind::Date | TimeKind::LDate => {
            let _ = buf.write_str(kind.prefix());
            format_date(buf, days);
        }
        TimeKind::Tod | TimeKind::LTod => {
            let _ = buf.write_str(kind.prefix());
            format_tod(buf, tod);
        }
        TimeKind::Dt | TimeKind::LDt => {
            let _ = buf.write_str(kind.prefix());
            format_date(buf, days);
            let _ = buf.write_str("-");
            format_tod(buf, tod);
        }
    }
}

/// Literal prefixes (upper case, with `#`) accepted before a value of each kind.
fn prefixes(kind: TimeKind) -> &'static [&'static [u8]] {
    match kind {
        TimeKind::Time | TimeKind::LTime => &[b"T#", b"TIME#", b"LT#", b"LTIME#"],
        TimeKind::Date | TimeKind::LDate => &[b"D#", b"DATE#", b"LD#", b"LDATE#"],
        TimeKind::Tod | TimeKind::LTod => &[b"TOD#", b"TIME_OF_DAY#", b"LTOD#", b"LTIME_OF_DAY#"],
        TimeKind::Dt | TimeKind::LDt => &[b"DT#", b"DATE_AND_TIME#", b"LDT#", b"LDATE_AND_TIME#"],
    }
}

/// A run of decimal digits at the start of `text`: (value, digit count, rest).
fn digits(text: &[u8]) -> Option<(i64, usize, &[u8])> {
    let n = text.iter().take_while(|c| c.is_ascii_digit()).count();
    if n == 0 || n > 18 {
        return None;
    }
    let value = text[..n]
        .iter()
        .fold(0i64, |v, c| v * 10 + (c - b'0') as i64);
    Some((value, n, &text[n..]))
}

/// `YYYY-MM-DD` at the start of `text`: (nanoseconds, rest).
fn parse_date(text: &[u8]) -> Option<(i64, &[u8])> {
    let (year, _, rest) = digits(text)?;
    let (month, _, rest) = digits(rest.strip_prefix(b"-")?)?;
    let (day, _, rest) = digits(rest.strip_prefix(b"-")?)?;
    Some((date_from_parts(year, month, day)?, rest))
}

/// `HH:MM[:SS[.fraction]]` (all of `text`).
fn parse_tod(text: &[u8]) -> Option<i64> {
    let (hour, _, rest) = digits(text)?;
    let (minute, _, mut rest) = digits(rest.strip_prefix(b":")?)?;
    let (mut second, mut fraction) = (0, 0);
    if let Some(after) = rest.strip_prefix(b":") {
        let (s, _, after) = digits(after)?;
        second = s;
        rest = after;
        if let Some(after) = rest.strip_prefix(b".") {
            let n = after.iter().take_while(|c| c.is_ascii_digit()).count();
            if n == 0 {
                return None;
            }
            // Nanoseconds: the first nine digits (further digits are cut off).
            for k in 0..9 {
                let digit = after[..n].get(k).map_or(0, |c| c - b'0');
                fraction = fraction * 10 + digit as i64;
            }
            rest = &after[n..];
        }
    }
    if !rest.is_empty() {
        return None;
    }
    tod_from_parts(hour, minute, second, fraction)
}

/// `[-]` then components `1d2h3m4s5ms6us7ns` (each optionally fractional, `_` between).
fn parse_duration(text: &[u8]) -> Option<i64> {
    let (negative, mut rest) = match text.strip_prefix(b"-") {
        Some(r) => (true, r),
        None => (false, text),
    };
    let mut total: i128 = 0;
    let mut any = false;
    while !rest.is_empty() {
        if let Some(r) = rest.strip_prefix(b"_") {
            rest = r;
            continue;
        }
        let (whole, _, r) = digits(rest)?;
        rest = r;
        let (mut fraction, mut scale_down) = (0i128, 1i128);
        if let Some(r) = rest.strip_prefix(b".") {
            let n = r.iter().take_while(|c| c.is_ascii_digit()).count();
            if n == 0 || n > 18 {
                return None;
            }
            for c in &r[..n] {
                fraction = fraction * 10 + (c - b'0') as i128;
                scale_down *= 10;
            }
            rest = &r[n..];
        }
        let unit_len = rest.iter().take_while(|c| c.is_ascii_alphabetic()).count();
        let unit = &rest[..unit_len];
        rest = &rest[unit_len..];
        const UNITS: [(&[u8], i128); 7] = [
            (b"d", 86_400_000_000_000),
            (b"h", 3_600_000_000_000),
            (b"m", 60_000_000_000),
            (b"s", 1_000_000_000),
            (b"ms", 1_000_000),
            (b"us", 1_000),
            (b"ns", 1),
        ];
        let (_, scale) = *UNITS.iter().find(|(u, _)| unit.eq_ignore_ascii_case(u))?;
        // Fractions round to the nearest nanosecond, halves away from zero.
        total += whole as i128 * scale + (fraction * scale * 2 + scale_down) / (scale_down * 2);
        any = true;
    }
    let total = if negative { -total } else { total };
    if !any {
        return None;
    }
    i64::try_from(total).ok()
}

/// Parses a date/time literal of `kind`, with or without its prefix (see
/// [`Builtin::StrToDateTime`]); `None` when it is not one.
pub fn parse_date_time(text: &[u8], kind: TimeKind) -> Option<i64> {
    let text = text.trim_ascii();
    let upper_prefix = |p: &[u8]| text.len() >= p.len() && text[..p.len()].eq_ignore_ascii_case(p);
    let body = match prefixes(kind).iter().find(|p| upper_prefix(p)) {
        Some(p) => &text[p.len()..],
        None => text,
    };
    match kind {
        TimeKind::Time | TimeKind::LTime => parse_duration(body),
        TimeKind::Date | TimeKind::LDate => match parse_date(body)? {
            (date, []) => Some(date),
            _ => None,
        },
        TimeKind::Tod | TimeKind::LTod => parse_tod(body),
        TimeKind::Dt | TimeKind::LDt => {
            let (date, rest) = parse_date(body)?;
            date.checked_add(parse_tod(rest.strip_prefix(b"-")?)?)
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
        | AtanF64 | ExptF64 | AbsF64 | Atan2F64 => f64_math(builtin),
        SqrtF32 | LnF32 | LogF32 | ExpF32 | SinF32 | CosF32 | TanF32 | AsinF32 | AcosF32
        | AtanF32 | ExptF32 | AbsF32 | Atan2F32 => f32_math(builtin),
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
        DateFromParts => date_from_parts(arg(0) as i64, arg(1) as i64, arg(2) as i64)
            .map(|v| Some(v as u64))
            .ok_or(Trap::NumericError),
        TodFromParts => {
            let ms = arg(3) as i64;
            if !(0..1000).contains(&ms) {
                return Err(Trap::NumericError);
            }
            tod_from_parts(arg(0) as i64, arg(1) as i64, arg(2) as i64, ms * 1_000_000)
                .map(|v| Some(v as u64))
                .ok_or(Trap::NumericError)
        }
        DateSplit => {
            let (year, month, day) = civil_from_days((arg(0) as i64).div_euclid(NS_PER_DAY));
            Ok(Some(((year << 16) as u64) | (month << 8 | day) as u64))
        }
        DateOf => (arg(0) as i64)
            .div_euclid(NS_PER_DAY)
            .checked_mul(NS_PER_DAY)
            .map(|v| Some(v as u64))
            .ok_or(Trap::NumericError),
        TodOf => Ok(Some((arg(0) as i64).rem_euclid(NS_PER_DAY) as u64)),
        // 1970-01-01 was a Thursday.
        DayOfWeek => Ok(Some(
            ((arg(0) as i64).div_euclid(NS_PER_DAY) + 4).rem_euclid(7) as u64,
        )),
        StrToDateTime => {
            let s = string_at(data, arg(0))?;
            let kind = TimeKind::from_u64(arg(1)).ok_or(Trap::NumericError)?;
            parse_date_time(s.text(data), kind)
                .map(|v| Some(v as u64))
                .ok_or(Trap::NumericError)
        }
        WStrLen | WStrAssign | WStrConcat | WStrLeft | WStrRight | WStrMid | WStrInsert
        | WStrDelete | WStrReplace | WStrFind | WStrCompare | WStrFromStr | StrFromWStr => {
            wide(builtin, args, data)
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
                StrFromDateTime => {
                    let kind = TimeKind::from_u64(arg(2)).ok_or(Trap::NumericError)?;
                    format_date_time(&mut buf, kind, arg(1) as i64);
                }
                _ => unreachable!("all builtins handled"),
            }
            write_string(data, dst, buf.as_bytes());
            Ok(None)
        }
    }
}

/// A validated WSTRING operand: byte range of its code units and its capacity in units.
#[derive(Clone, Copy)]
struct WStrRef {
    addr: usize,
    max: usize,
    len: usize,
}

fn wstring_at(data: &[u8], address: u64) -> Result<WStrRef, Trap> {
    let addr = usize::try_from(address).map_err(|_| Trap::InvalidAddress)?;
    if addr.checked_add(4).is_none_or(|end| end > data.len()) {
        return Err(Trap::InvalidAddress);
    }
    let max = read_u16(data, addr) as usize;
    if addr + 4 + 2 * max > data.len() {
        return Err(Trap::InvalidAddress);
    }
    let len = (read_u16(data, addr + 2) as usize).min(max);
    Ok(WStrRef { addr, max, len })
}

impl WStrRef {
    /// Its text: `2 * len` bytes, units little-endian.
    fn bytes<'d>(&self, data: &'d [u8]) -> &'d [u8] {
        &data[self.addr + 4..self.addr + 4 + 2 * self.len]
    }
}

fn units(bytes: &[u8]) -> impl Iterator<Item = u16> + '_ {
    bytes
        .chunks_exact(2)
        .map(|u| u16::from_le_bytes([u[0], u[1]]))
}

/// A WSTRING result being assembled: up to [`MAX_STRING_LEN`] units (little-endian bytes).
struct WBuf {
    bytes: [u8; 2 * MAX_STRING_LEN],
    len: usize,
}

impl WBuf {
    fn push(&mut self, text: &[u8]) {
        let n = text.len().min(self.bytes.len() - self.len) & !1;
        self.bytes[self.len..self.len + n].copy_from_slice(&text[..n]);
        self.len += n;
    }
    fn push_unit(&mut self, unit: u16) {
        self.push(&unit.to_le_bytes());
    }
}

/// The WSTRING builtins (ids 140-152).
fn wide(builtin: Builtin, args: &[u64], data: &mut [u8]) -> Result<Option<u64>, Trap> {
    use Builtin::*;
    let arg = |i: usize| args.get(i).copied().unwrap_or(0);
    match builtin {
        WStrLen => return Ok(Some(wstring_at(data, arg(0))?.len as u64)),
        WStrFind => {
            let (a, b) = (wstring_at(data, arg(0))?, wstring_at(data, arg(1))?);
            let (hay, needle) = (a.bytes(data), b.bytes(data));
            let position = if needle.is_empty() || needle.len() > hay.len() {
                0
            } else {
                (0..=hay.len() - needle.len())
                    .step_by(2)
                    .position(|at| &hay[at..at + needle.len()] == needle)
                    .map_or(0, |p| p + 1)
            };
            return Ok(Some(position as u64));
        }
        WStrCompare => {
            let (a, b) = (wstring_at(data, arg(0))?, wstring_at(data, arg(1))?);
            return Ok(Some(match units(a.bytes(data)).cmp(units(b.bytes(data))) {
                core::cmp::Ordering::Less => -1i64 as u64,
                core::cmp::Ordering::Equal => 0,
                core::cmp::Ordering::Greater => 1,
            }));
        }
        StrFromWStr => {
            let dst = string_at(data, arg(0))?;
            let src = wstring_at(data, arg(1))?;
            let room = dst.max.min(MAX_STRING_LEN);
            let mut buf = Buf::new();
            for c in char::decode_utf16(units(src.bytes(data))) {
                let mut utf8 = [0u8; 4];
                let encoded = c
                    .unwrap_or(char::REPLACEMENT_CHARACTER)
                    .encode_utf8(&mut utf8);
                if buf.len + encoded.len() > room {
                    break;
                }
                buf.push(encoded.as_bytes());
            }
            write_string(data, dst, buf.as_bytes());
            return Ok(None);
        }
        _ => {}
    }
    // Builtins writing a WSTRING result to the WSTRING at arg(0).
    let dst = wstring_at(data, arg(0))?;
    let mut buf = WBuf {
        bytes: [0; 2 * MAX_STRING_LEN],
        len: 0,
    };
    // Unit counts and positions, clamped as for STRING; `a` is in bytes (2 per unit).
    let count = |cell: u64, max_units: usize| 2 * clamp_count(cell, max_units);
    match builtin {
        WStrAssign => buf.push(wstring_at(data, arg(1))?.bytes(data)),
        WStrConcat => {
            let (a, b) = (wstring_at(data, arg(1))?, wstring_at(data, arg(2))?);
            buf.push(a.bytes(data));
            buf.push(b.bytes(data));
        }
        WStrLeft | WStrRight => {
            let a = wstring_at(data, arg(1))?.bytes(data);
            let n = count(arg(2), a.len() / 2);
            buf.push(if builtin == WStrLeft {
                &a[..n]
            } else {
                &a[a.len() - n..]
            });
        }
        WStrMid => {
            let a = wstring_at(data, arg(1))?.bytes(data);
            let start = (clamp_count(arg(3), a.len() / 2 + 1).max(1) - 1) * 2;
            let n = count(arg(2), (a.len() - start) / 2);
            buf.push(&a[start..start + n]);
        }
        WStrInsert => {
            let (a, b) = (wstring_at(data, arg(1))?, wstring_at(data, arg(2))?);
            let (a, b) = (a.bytes(data), b.bytes(data));
            let p = count(arg(3), a.len() / 2);
            buf.push(&a[..p]);
            buf.push(b);
            buf.push(&a[p..]);
        }
        WStrDelete | WStrReplace => {
            let a = wstring_at(data, arg(1))?.bytes(data);
            let (replacement, n_arg, p_arg) = if builtin == WStrReplace {
                (wstring_at(data, arg(2))?.bytes(data), arg(3), arg(4))
            } else {
                (&[][..], arg(2), arg(3))
            };
            let start = (clamp_count(p_arg, a.len() / 2 + 1).max(1) - 1) * 2;
            let n = count(n_arg, (a.len() - start) / 2);
            buf.push(&a[..start]);
            buf.push(replacement);
            buf.push(&a[start + n..]);
        }
        WStrFromStr => {
            let s = string_at(data, arg(1))?;
            for chunk in s.text(data).utf8_chunks() {
                for c in chunk.valid().chars() {
                    let mut pair = [0u16; 2];
                    for unit in c.encode_utf16(&mut pair) {
                        buf.push_unit(*unit);
                    }
                }
                for &byte in chunk.invalid() {
                    buf.push_unit(byte as u16);
                }
            }
        }
        _ => unreachable!("all WSTRING builtins handled"),
    }
    let n = (buf.len / 2).min(dst.max);
    data[dst.addr + 2..dst.addr + 4].copy_from_slice(&(n as u16).to_le_bytes());
    data[dst.addr + 4..dst.addr + 4 + 2 * n].copy_from_slice(&buf.bytes[..2 * n]);
    Ok(None)
}
