//! The variable map (names -> typed data addresses) and IEC literal formatting/parsing of
//! values, used by `plcc run --print/--set` and written into the image's VARS section.

use plc_vm::image::VarType;
use plc_vm::isa::Trap;

use crate::sema::Program;
use crate::types::{Elem, Type};
use ast_kind::*;

mod ast_kind {
    pub use crate::ast::VarKind;
}

/// How a monitored value is interpreted.
#[derive(Debug, Clone, PartialEq)]
pub enum ValueKind {
    Elem(Elem),
    /// STRING with its maximum length.
    String(u32),
    /// WSTRING with its maximum length (not in the image's variable map).
    WString(u32),
    /// Enumeration: value names with their numbers.
    Enum(Vec<(String, i64)>),
    /// `__EXCEPTION`: a trap code.
    Exception,
}

impl ValueKind {
    /// Type recorded in the image's variable map.
    pub fn var_type(&self) -> Option<VarType> {
        Some(match self {
            ValueKind::Elem(e) => match e {
                Elem::Bool => VarType::Bool,
                Elem::SInt => VarType::SInt,
                Elem::Int => VarType::Int,
                Elem::DInt => VarType::DInt,
                Elem::LInt => VarType::LInt,
                Elem::USInt => VarType::USInt,
                Elem::UInt => VarType::UInt,
                Elem::UDInt => VarType::UDInt,
                Elem::ULInt => VarType::ULInt,
                Elem::Byte => VarType::Byte,
                Elem::Word => VarType::Word,
                Elem::DWord => VarType::DWord,
                Elem::LWord => VarType::LWord,
                Elem::Real => VarType::Real,
                Elem::LReal => VarType::LReal,
                // The image's variable map has no date types (yet): durations and times of
                // day show as TIME, dates as their nanoseconds since 1970, characters as
                // their codes.
                Elem::Time | Elem::LTime | Elem::Tod | Elem::LTod => VarType::Time,
                Elem::Date | Elem::LDate | Elem::Dt | Elem::LDt => VarType::LInt,
                Elem::Char => VarType::Byte,
                Elem::WChar => VarType::Word,
            },
            ValueKind::String(_) => VarType::String,
            ValueKind::WString(_) => return None,
            ValueKind::Enum(_) | ValueKind::Exception => VarType::DInt,
        })
    }

    fn elem(&self) -> Elem {
        match self {
            ValueKind::Elem(e) => *e,
            _ => Elem::DInt,
        }
    }
}

/// One printable variable.
#[derive(Debug, Clone, PartialEq)]
pub struct MonitorVar {
    pub name: String,
    pub kind: ValueKind,
    pub addr: u32,
    pub size: u32,
    pub constant: bool,
    /// RETAIN: kept across a warm restart.
    pub retain: bool,
}

/// Upper bound on map entries contributed by one array (huge arrays are only partly listed).
const MAX_ELEMENTS: u64 = 4096;

/// Builds the variable map: globals by plain name, program instance variables as
/// `instance.var`, with `.member`, `[i]` / `[i,j]` for structure members and array elements.
pub fn variable_map(prog: &Program) -> Vec<MonitorVar> {
    let mut out = Vec::new();
    for g in &prog.globals {
        flatten(
            prog,
            &g.text,
            &g.ty,
            g.offset,
            (g.constant, g.retain),
            &mut out,
        );
    }
    for inst in &prog.instances {
        for v in &prog.pous[inst.pou].vars {
            if matches!(v.kind, VarKind::External | VarKind::Global | VarKind::InOut) {
                continue;
            }
            flatten(
                prog,
                &format!("{}.{}", inst.name, v.text),
                &v.ty,
                inst.addr + v.offset,
                (v.constant, v.retain),
                &mut out,
            );
        }
    }
    out
}

fn flatten(
    prog: &Program,
    name: &str,
    ty: &Type,
    addr: u32,
    // CONSTANT and RETAIN, inherited by members and elements.
    attrs: (bool, bool),
    out: &mut Vec<MonitorVar>,
) {
    let kind = match ty {
        Type::Elem(e) | Type::Subrange(e, ..) => ValueKind::Elem(*e),
        Type::Enum(i) => {
            let e = &prog.enums[*i];
            ValueKind::Enum(
                e.display
                    .iter()
                    .zip(&e.values)
                    .map(|(d, (_, v))| (d.clone(), *v))
                    .collect(),
            )
        }
        Type::Exception => ValueKind::Exception,
        Type::String(n) => ValueKind::String(*n),
        Type::WString(n) => ValueKind::WString(*n),
        Type::Struct(i) => {
            for m in &prog.structs[*i].members {
                flatten(
                    prog,
                    &format!("{name}.{}", m.text),
                    &m.ty,
                    addr + m.offset,
                    attrs,
                    out,
                );
            }
            return;
        }
        Type::Fb(pi) => {
            for v in &prog.pous[*pi].vars {
                if matches!(v.kind, VarKind::External | VarKind::Global | VarKind::InOut) {
                    continue;
                }
                flatten(
                    prog,
                    &format!("{name}.{}", v.text),
                    &v.ty,
                    addr + v.offset,
                    (attrs.0 || v.constant, attrs.1 || v.retain),
                    out,
                );
            }
            return;
        }
        Type::Array(a) => {
            let stride = prog.stride(&a.elem);
            let count = a.len().min(MAX_ELEMENTS);
            for flat in 0..count {
                // Row-major: decompose the flat index into one index per dimension.
                let mut rest = flat;
                let mut idx = vec![0i64; a.dims.len()];
                for d in (0..a.dims.len()).rev() {
                    let (lo, hi) = a.dims[d];
                    let n = (hi - lo + 1) as u64;
                    idx[d] = lo + (rest % n) as i64;
                    rest /= n;
                }
                let text: Vec<String> = idx.iter().map(|i| i.to_string()).collect();
                flatten(
                    prog,
                    &format!("{name}[{}]", text.join(",")),
                    &a.elem,
                    addr + flat as u32 * stride,
                    attrs,
                    out,
                );
            }
            return;
        }
        // References and interface values are not monitored (an address means nothing
        // outside this program build).
        Type::Ref(_)
        | Type::Reference(_)
        | Type::Interface(_)
        | Type::Null
        | Type::Void
        | Type::Error => return,
    };
    let size = match &kind {
        ValueKind::String(n) => 4 + n,
        ValueKind::WString(n) => 4 + 2 * n,
        k => k.elem().size(),
    };
    out.push(MonitorVar {
        name: name.to_string(),
        kind,
        addr,
        size,
        constant: attrs.0,
        retain: attrs.1,
    });
}

/// Finds a variable by name, ignoring case and blanks around indices.
pub fn find<'v>(vars: &'v [MonitorVar], name: &str) -> Option<&'v MonitorVar> {
    let norm: String = name.chars().filter(|c| !c.is_whitespace()).collect();
    vars.iter().find(|v| v.name.eq_ignore_ascii_case(&norm))
}

/// Reads the cell of an elementary value from data memory.
fn read_cell(kind: &ValueKind, data: &[u8], addr: u32) -> u64 {
    let e = kind.elem();
    let mt = crate::codegen::mem_type(e);
    let a = addr as usize;
    let w = mt.width();
    match data.get(a..a + w) {
        Some(bytes) => mt.cell_from_le(bytes),
        None => 0,
    }
}

/// Formats a variable's current value as an IEC literal.
pub fn format_value(var: &MonitorVar, data: &[u8]) -> String {
    match &var.kind {
        ValueKind::String(_) => {
            let a = var.addr as usize;
            let len = data
                .get(a + 2..a + 4)
                .map_or(0, |b| u16::from_le_bytes([b[0], b[1]]) as usize);
            let bytes = data.get(a + 4..a + 4 + len).unwrap_or(&[]);
            format_string(bytes)
        }
        ValueKind::WString(_) => {
            let a = var.addr as usize;
            let len = data
                .get(a + 2..a + 4)
                .map_or(0, |b| u16::from_le_bytes([b[0], b[1]]) as usize);
            let units: Vec<u16> = data
                .get(a + 4..a + 4 + 2 * len)
                .unwrap_or(&[])
                .chunks_exact(2)
                .map(|u| u16::from_le_bytes([u[0], u[1]]))
                .collect();
            format_wstring(&units)
        }
        ValueKind::Enum(values) => {
            let v = read_cell(&var.kind, data, var.addr) as i64;
            match values.iter().find(|(_, x)| *x == v) {
                Some((n, _)) => n.clone(),
                None => v.to_string(),
            }
        }
        ValueKind::Exception => {
            let v = read_cell(&var.kind, data, var.addr);
            match Trap::from_u64(v) {
                Some(t) => t.name().to_string(),
                None => v.to_string(),
            }
        }
        ValueKind::Elem(e) => format_cell(*e, read_cell(&var.kind, data, var.addr)),
    }
}

/// Formats an elementary value held in a cell.
pub fn format_cell(e: Elem, cell: u64) -> String {
    match e {
        Elem::Bool => if cell != 0 { "TRUE" } else { "FALSE" }.to_string(),
        Elem::Real => format_real(f32::from_bits(cell as u32) as f64, true),
        Elem::LReal => format_real(f64::from_bits(cell), false),
        Elem::Time => format_time(cell as i64),
        e if e.is_temporal() => {
            let mut s = String::new();
            if let Some(kind) = e.time_kind() {
                plc_vm::builtins::format_date_time(&mut s, kind, cell as i64);
            }
            s
        }
        Elem::Char => format_string(&[cell as u8]),
        Elem::WChar => match char::from_u32(cell as u32) {
            Some(c) if c != '"' && c != '$' && !c.is_control() => format!("\"{c}\""),
            _ => format!("\"${:04X}\"", cell),
        },
        e if e.is_signed_int() => (cell as i64).to_string(),
        _ => cell.to_string(),
    }
}

/// Shortest round-trip decimal, always with a `.` (`4.0`, `0.1`).
pub fn format_real(v: f64, single: bool) -> String {
    if !v.is_finite() {
        return if v.is_nan() {
            "NaN".into()
        } else if v > 0.0 {
            "INF".into()
        } else {
            "-INF".into()
        };
    }
    let mut s = if single {
        format!("{}", v as f32)
    } else {
        format!("{v}")
    };
    if !s.contains('.') {
        s.push_str(".0");
    }
    s
}

/// `T#1s500ms` style duration; `T#0s` for zero; negative as `T#-1s`.
pub fn format_time(ns: i64) -> String {
    if ns == 0 {
        return "T#0s".into();
    }
    let mut rest = ns.unsigned_abs();
    let mut s = String::from(if ns < 0 { "T#-" } else { "T#" });
    const UNITS: [(&str, u64); 7] = [
        ("d", 86_400_000_000_000),
        ("h", 3_600_000_000_000),
        ("m", 60_000_000_000),
        ("s", 1_000_000_000),
        ("ms", 1_000_000),
        ("us", 1_000),
        ("ns", 1),
    ];
    for (unit, scale) in UNITS {
        let n = rest / scale;
        rest %= scale;
        if n > 0 {
            s.push_str(&format!("{n}{unit}"));
        }
    }
    s
}

/// `'text'` with `$` escapes for quotes, dollars and control characters.
pub fn format_string(bytes: &[u8]) -> String {
    let mut s = String::from("'");
    for &b in bytes {
        match b {
            b'\'' => s.push_str("$'"),
            b'$' => s.push_str("$$"),
            b'\n' => s.push_str("$N"),
            b'\r' => s.push_str("$R"),
            b'\t' => s.push_str("$T"),
            0x0c => s.push_str("$P"),
            0x20..=0x7e => s.push(b as char),
            _ => s.push_str(&format!("${b:02X}")),
        }
    }
    s.push('\'');
    s
}

/// `"text"` with `$` escapes (`$"`, `$$`, `$N`, ...; other control characters and unpaired
/// surrogates as `$NNNN`).
pub fn format_wstring(units: &[u16]) -> String {
    let mut s = String::from("\"");
    for c in char::decode_utf16(units.iter().copied()) {
        match c {
            Ok('"') => s.push_str("$\""),
            Ok('$') => s.push_str("$$"),
            Ok('\n') => s.push_str("$N"),
            Ok('\r') => s.push_str("$R"),
            Ok('\t') => s.push_str("$T"),
            Ok(c) if !c.is_control() => s.push(c),
            Ok(c) => s.push_str(&format!("${:04X}", c as u32)),
            Err(e) => s.push_str(&format!("${:04X}", e.unpaired_surrogate())),
        }
    }
    s.push('"');
    s
}

/// Parses a `--set` value for `var` and writes it into data memory.
pub fn write_value(var: &MonitorVar, text: &str, data: &mut [u8]) -> Result<(), String> {
    if var.constant {
        return Err(format!("`{}` is a CONSTANT", var.name));
    }
    let text = text.trim();
    let cell: u64 = match &var.kind {
        ValueKind::String(n) => {
            // Shells strip quotes, so an unquoted value is taken literally.
            let s = match text.strip_prefix('\'').and_then(|t| t.strip_suffix('\'')) {
                Some(inner) => {
                    let mut diags = Vec::new();
                    let toks = crate::lexer::lex(0, &format!("'{inner}'"), &mut diags);
                    match toks.first().map(|t| &t.tok) {
                        Some(crate::lexer::Tok::Str(s)) if diags.is_empty() => s.clone(),
                        _ => return Err(format!("invalid string literal `{text}`")),
                    }
                }
                None => text.to_string(),
            };
            let bytes = s.as_bytes();
            let len = bytes.len().min(*n as usize);
            let a = var.addr as usize;
            data[a + 2..a + 4].copy_from_slice(&(len as u16).to_le_bytes());
            data[a + 4..a + 4 + len].copy_from_slice(&bytes[..len]);
            if len < *n as usize {
                // The terminator the VM keeps after a shorter text.
                data[a + 4 + len] = 0;
            }
            return Ok(());
        }
        ValueKind::WString(n) => {
            // `"text"` (IEC escapes) or bare text.
            let s = match text.strip_prefix('"').and_then(|t| t.strip_suffix('"')) {
                Some(inner) => {
                    let mut diags = Vec::new();
                    let toks = crate::lexer::lex(0, &format!("\"{inner}\""), &mut diags);
                    match toks.first().map(|t| &t.tok) {
                        Some(crate::lexer::Tok::WStr(s)) if diags.is_empty() => s.clone(),
                        _ => return Err(format!("invalid WSTRING literal `{text}`")),
                    }
                }
                None => text.to_string(),
            };
            let units: Vec<u16> = s.encode_utf16().take(*n as usize).collect();
            let a = var.addr as usize;
            data[a + 2..a + 4].copy_from_slice(&(units.len() as u16).to_le_bytes());
            for (i, u) in units.iter().enumerate() {
                data[a + 4 + 2 * i..a + 6 + 2 * i].copy_from_slice(&u.to_le_bytes());
            }
            return Ok(());
        }
        ValueKind::Enum(values) => {
            let bare = text.rsplit('#').next().unwrap_or(text);
            match values.iter().find(|(n, _)| n.eq_ignore_ascii_case(bare)) {
                Some((_, v)) => *v as u64,
                None => bare
                    .parse::<i64>()
                    .map_err(|_| format!("`{text}` is not a value of the enumeration"))?
                    as u64,
            }
        }
        ValueKind::Exception => {
            text.parse::<i64>()
                .map_err(|_| format!("invalid exception code `{text}`"))? as u64
        }
        ValueKind::Elem(e) => parse_elem(*e, text)?,
    };
    let mt = crate::codegen::mem_type(var.kind.elem());
    let a = var.addr as usize;
    let w = mt.width();
    data[a..a + w].copy_from_slice(&cell.to_le_bytes()[..w]);
    Ok(())
}

pub(crate) fn parse_elem(e: Elem, text: &str) -> Result<u64, String> {
    let bad = || format!("`{text}` is not a valid {e} value");
    // Accept typed literals like INT#5 by dropping a leading type prefix.
    let body = match text.split_once('#') {
        Some((p, rest)) if Elem::from_name(&p.to_ascii_uppercase()).is_some() => rest,
        _ => text,
    };
    match e {
        Elem::Bool => match body.to_ascii_uppercase().as_str() {
            "TRUE" | "1" => Ok(1),
            "FALSE" | "0" => Ok(0),
            _ => Err(bad()),
        },
        Elem::Real => body
            .parse::<f32>()
            .map(|v| v.to_bits() as u64)
            .map_err(|_| bad()),
        Elem::LReal => body.parse::<f64>().map(|v| v.to_bits()).map_err(|_| bad()),
        e if e.is_temporal() && e != Elem::Time => e
            .time_kind()
            .and_then(|kind| plc_vm::builtins::parse_date_time(text.as_bytes(), kind))
            .map(|v| v as u64)
            .ok_or_else(bad),
        e if e.is_char() => {
            let quoted = body
                .strip_prefix(['\'', '"'])
                .and_then(|t| t.strip_suffix(['\'', '"']));
            let code = match quoted {
                Some(inner) if inner.chars().count() == 1 => inner.chars().next().map(|c| c as u32),
                Some(_) => None,
                None => body.parse::<u32>().ok(),
            };
            match code {
                Some(c) if (c as i128) <= e.int_range().1 => Ok(c as u64),
                _ => Err(bad()),
            }
        }
        Elem::Time => {
            let mut diags = Vec::new();
            let toks = crate::lexer::lex(0, text, &mut diags);
            match toks.first().map(|t| &t.tok) {
                Some(crate::lexer::Tok::Time(ns)) if diags.is_empty() && toks.len() == 2 => {
                    Ok(*ns as i64 as u64)
                }
                _ => Err(bad()),
            }
        }
        e => {
            let mut diags = Vec::new();
            let (neg, digits) = match body.strip_prefix('-') {
                Some(d) => (true, d),
                None => (false, body),
            };
            let toks = crate::lexer::lex(0, digits, &mut diags);
            let v: i128 = match toks.first().map(|t| &t.tok) {
                Some(crate::lexer::Tok::Int(v)) if diags.is_empty() && toks.len() == 2 => {
                    *v as i128
                }
                _ => return Err(bad()),
            };
            let v = if neg { -v } else { v };
            let (lo, hi) = e.int_range();
            if v < lo || v > hi {
                return Err(format!("{v} does not fit type {e}"));
            }
            Ok(v as i64 as u64)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats() {
        assert_eq!(format_real(4.0, false), "4.0");
        assert_eq!(format_real(0.1f32 as f64, true), "0.1");
        assert_eq!(format_time(1_500_000_000), "T#1s500ms");
        assert_eq!(format_time(-1_000_000_000), "T#-1s");
        assert_eq!(format_time(0), "T#0s");
        assert_eq!(format_time(90_061_001_001_001), "T#1d1h1m1s1ms1us1ns");
        assert_eq!(format_string(b"it's"), "'it$'s'");
        assert_eq!(format_cell(Elem::Date, 86_400_000_000_000), "D#1970-01-02");
        assert_eq!(format_cell(Elem::LTod, 1), "LTOD#00:00:00.000000001");
        assert_eq!(format_cell(Elem::Char, 97), "'a'");
        assert_eq!(format_cell(Elem::WChar, 0x20AC), "\"€\"");
        assert_eq!(
            parse_elem(Elem::Dt, "DT#1970-01-01-00:00:01"),
            Ok(1_000_000_000)
        );
        assert_eq!(parse_elem(Elem::Char, "'a'"), Ok(97));
        assert!(parse_elem(Elem::Char, "'ab'").is_err());
    }
}
