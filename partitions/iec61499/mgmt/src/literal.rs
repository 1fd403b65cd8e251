//! IEC 61131-3 literals as 4diac writes them in WRITE requests and boot files, read into a
//! value of the destination's type (`TRUE`, `UINT#5`, `16#FF`, `-3`, `1.5E3`, `T#1s500ms`,
//! `'text $'quoted$''`, `[T#1s, T#2s]`), and values shown back as literals.

use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
use iec61499_runtime::{DataType, Value, VarSpec, type_named, zero};

/// Reads `text` as a value for a port declared as `spec`.
pub fn parse(text: &str, spec: &VarSpec) -> Result<Value, String> {
    let text = text.trim();
    match spec.array {
        None => scalar(text, spec.ty),
        Some(n) => {
            let inner = text
                .strip_prefix('[')
                .and_then(|t| t.strip_suffix(']'))
                .ok_or_else(|| format!("`{text}`: an array literal is [a, b, ...]"))?;
            let parts = split_top(inner);
            if parts.len() > n {
                return Err(format!(
                    "`{text}`: {} elements for an array of {n}",
                    parts.len()
                ));
            }
            let mut values: Vec<Value> = parts
                .iter()
                .map(|p| scalar(p.trim(), spec.ty))
                .collect::<Result<_, _>>()?;
            values.resize(n, zero(spec.ty));
            Ok(Value::Array(values))
        }
    }
}

/// The type a literal names itself (`DINT#26`, `T#1s`, `TRUE`, a quoted string), for a
/// generic port without a type yet; `None` for an untyped number.
pub fn type_of(text: &str) -> Option<DataType> {
    let text = text.trim();
    if text.eq_ignore_ascii_case("TRUE") || text.eq_ignore_ascii_case("FALSE") {
        return Some(DataType::Bool);
    }
    if text.starts_with('\'') {
        return Some(DataType::String);
    }
    let (prefix, _) = text.split_once('#')?;
    if prefix.eq_ignore_ascii_case("T") || prefix.eq_ignore_ascii_case("TIME") {
        return Some(DataType::Time);
    }
    type_named(prefix)
}

/// `inner` split at the commas outside quotes.
fn split_top(inner: &str) -> Vec<&str> {
    if inner.trim().is_empty() {
        return Vec::new();
    }
    let mut parts = Vec::new();
    let (mut start, mut quoted) = (0, false);
    for (i, c) in inner.char_indices() {
        match c {
            '\'' => quoted = !quoted,
            ',' if !quoted => {
                parts.push(&inner[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&inner[start..]);
    parts
}

fn range(ty: DataType) -> Option<(i128, i128)> {
    use DataType::*;
    Some(match ty {
        SInt => (-128, 127),
        Int => (-32_768, 32_767),
        DInt => (i32::MIN as i128, i32::MAX as i128),
        LInt => (i64::MIN as i128, i64::MAX as i128),
        USInt | Byte => (0, 255),
        UInt | Word => (0, 65_535),
        UDInt | DWord => (0, u32::MAX as i128),
        ULInt | LWord => (0, u64::MAX as i128),
        _ => return None,
    })
}

/// Strips a `TYPE#` prefix, checking that the type may be given to `ty`.
fn untyped(text: &str, ty: DataType) -> Result<&str, String> {
    match text.split_once('#') {
        Some((prefix, rest)) if type_named(prefix).is_some() => {
            let named = type_named(prefix).unwrap_or(ty);
            // A literal of a narrower type is taken as of the port's (USINT#5 for an INT).
            if !iec61499_runtime::widens(named, ty) {
                return Err(format!("`{text}` is a {prefix}, not a {ty:?}"));
            }
            Ok(rest)
        }
        Some((prefix, rest))
            if ty == DataType::Time
                && (prefix.eq_ignore_ascii_case("T") || prefix.eq_ignore_ascii_case("TIME")) =>
        {
            Ok(rest)
        }
        _ => Ok(text),
    }
}

fn integer(text: &str) -> Option<i128> {
    let cleaned: String = text.chars().filter(|c| *c != '_').collect();
    let (negative, digits) = match cleaned.strip_prefix('-') {
        Some(d) => (true, d),
        None => (false, cleaned.strip_prefix('+').unwrap_or(&cleaned)),
    };
    let (base, digits) = match digits.split_once('#') {
        Some(("16", d)) => (16, d),
        Some(("8", d)) => (8, d),
        Some(("2", d)) => (2, d),
        Some(_) => return None,
        None => (10, digits),
    };
    if digits.is_empty() {
        return None;
    }
    let value = i128::from_str_radix(digits, base).ok()?;
    Some(if negative { -value } else { value })
}

fn scalar(text: &str, ty: DataType) -> Result<Value, String> {
    let body = untyped(text, ty)?;
    let bad = || format!("`{text}` is no {ty:?} literal");
    Ok(match ty {
        DataType::Bool => match body.to_ascii_uppercase().as_str() {
            "TRUE" | "1" => Value::Bool(true),
            "FALSE" | "0" => Value::Bool(false),
            _ => return Err(bad()),
        },
        DataType::Real | DataType::LReal => {
            let cleaned: String = body.chars().filter(|c| *c != '_').collect();
            Value::Real(cleaned.parse::<f64>().map_err(|_| bad())?)
        }
        DataType::Time => Value::Time(duration(body).ok_or_else(bad)?),
        DataType::String | DataType::WString => Value::String(string(body).ok_or_else(bad)?),
        _ => {
            let v = integer(body).ok_or_else(bad)?;
            let (lo, hi) = range(ty).ok_or_else(bad)?;
            if !(lo..=hi).contains(&v) {
                return Err(format!("`{text}` is outside {ty:?} ({lo}..={hi})"));
            }
            match ty {
                DataType::SInt | DataType::Int | DataType::DInt | DataType::LInt => {
                    Value::Int(v as i64)
                }
                _ => Value::UInt(v as u64),
            }
        }
    })
}

/// A duration such as `1d2h3m4s5ms6us7ns`, `1.5s` or `-250ms`, in nanoseconds.
fn duration(text: &str) -> Option<i64> {
    let cleaned: String = text
        .chars()
        .filter(|c| *c != '_')
        .collect::<String>()
        .to_ascii_lowercase();
    let (negative, mut rest) = match cleaned.strip_prefix('-') {
        Some(r) => (true, r),
        None => (false, cleaned.as_str()),
    };
    if rest.is_empty() {
        return None;
    }
    let mut total: f64 = 0.0;
    while !rest.is_empty() {
        let end = rest.find(|c: char| !(c.is_ascii_digit() || c == '.'))?;
        let number: f64 = rest[..end].parse().ok()?;
        rest = &rest[end..];
        let (unit, scale) = [
            ("ms", 1e6),
            ("us", 1e3),
            ("ns", 1.0),
            ("d", 86_400e9),
            ("h", 3_600e9),
            ("m", 60e9),
            ("s", 1e9),
        ]
        .into_iter()
        .find(|(u, _)| rest.starts_with(u))?;
        rest = &rest[unit.len()..];
        total += number * scale;
    }
    if total > i64::MAX as f64 {
        return None;
    }
    let ns = total as i64;
    Some(if negative { -ns } else { ns })
}

/// A quoted string with `$` escapes, or (as FORTE accepts for string parameters) the text
/// itself when it is not quoted.
fn string(text: &str) -> Option<String> {
    let Some(inner) = text.strip_prefix('\'') else {
        return Some(text.to_string());
    };
    let inner = inner.strip_suffix('\'')?;
    let mut out = String::new();
    let mut chars = inner.chars();
    while let Some(c) = chars.next() {
        if c != '$' {
            out.push(c);
            continue;
        }
        match chars.next()? {
            '$' => out.push('$'),
            '\'' => out.push('\''),
            'L' | 'l' | 'N' | 'n' => out.push('\n'),
            'P' | 'p' => out.push('\x0c'),
            'R' | 'r' => out.push('\r'),
            'T' | 't' => out.push('\t'),
            h1 => {
                let h2 = chars.next()?;
                let byte = u8::from_str_radix(&format!("{h1}{h2}"), 16).ok()?;
                out.push(char::from(byte));
            }
        }
    }
    Some(out)
}

/// A value as an IEC literal (for READ responses).
pub fn show(value: &Value) -> String {
    match value {
        Value::Bool(b) => (if *b { "TRUE" } else { "FALSE" }).into(),
        Value::Int(i) => i.to_string(),
        Value::UInt(u) => u.to_string(),
        Value::Real(r) => format!("{r:?}"),
        Value::Time(ns) if ns % 1_000_000 == 0 => format!("T#{}ms", ns / 1_000_000),
        Value::Time(ns) => format!("T#{ns}ns"),
        Value::String(s) => {
            let mut out = String::from("'");
            for c in s.chars() {
                match c {
                    '$' => out.push_str("$$"),
                    '\'' => out.push_str("$'"),
                    '\n' => out.push_str("$N"),
                    '\r' => out.push_str("$R"),
                    '\t' => out.push_str("$T"),
                    c if (c as u32) < 0x20 => out.push_str(&format!("${:02X}", c as u32)),
                    c => out.push(c),
                }
            }
            out.push('\'');
            out
        }
        Value::Array(items) => {
            let parts: Vec<String> = items.iter().map(show).collect();
            format!("[{}]", parts.join(", "))
        }
    }
}
