//! The variable map (names -> typed data addresses), written into the image's VARS section
//! and used by `plcc run --print/--set`. Values are shown and parsed as the PLC's monitors
//! show and parse them ([`plc_vm::literal`]); only what the image's map cannot say is
//! here: enumeration value names and trap names.

use plc_vm::image::VarType;
use plc_vm::isa::Trap;
use plc_vm::vm::Value;

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
    /// WSTRING with its maximum length.
    WString(u32),
    /// Enumeration: value names with their numbers.
    Enum(Vec<(String, i64)>),
    /// `__EXCEPTION`: a trap code.
    Exception,
    /// A reference (`REF_TO`, `POINTER TO`, `REFERENCE TO`), an interface value or a
    /// reference to a function-block instance.
    Ref,
}

impl ValueKind {
    /// Type recorded in the image's variable map.
    pub fn var_type(&self) -> Option<VarType> {
        Some(match self {
            // The elementary types have the map's names.
            ValueKind::Elem(e) => VarType::from_name(e.name())?,
            ValueKind::String(_) => VarType::String,
            ValueKind::WString(_) => VarType::WString,
            ValueKind::Enum(_) | ValueKind::Exception => VarType::DInt,
            ValueKind::Ref => VarType::Ref,
        })
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
        // Shown as their target's address (a variable's name when it is one's start).
        Type::Ref(_) | Type::Reference(_) | Type::Interface(_) => ValueKind::Ref,
        Type::Null | Type::Void | Type::Error => return,
    };
    let size = match &kind {
        ValueKind::String(n) => 4 + n,
        ValueKind::WString(n) => 4 + 2 * n,
        ValueKind::Ref => 8,
        ValueKind::Elem(e) => e.size(),
        ValueKind::Enum(_) | ValueKind::Exception => Elem::DInt.size(),
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

/// The bytes of `var` in data memory (empty when outside it, which the compiler never makes).
fn bytes_of<'d>(var: &MonitorVar, data: &'d [u8]) -> &'d [u8] {
    let at = var.addr as usize;
    data.get(at..at + var.size as usize).unwrap_or(&[])
}

/// Formats a variable's current value as an IEC literal (as the PLC's monitors do; a
/// reference's target named from `vars`, the variable map).
pub fn format_value(var: &MonitorVar, vars: &[MonitorVar], data: &[u8]) -> String {
    let Some(ty) = var.kind.var_type() else {
        return "?".into();
    };
    let value = match Value::load(ty, bytes_of(var, data)) {
        Some(Value::Ref { address, .. }) => Value::Ref {
            address,
            target: address
                .and_then(|a| vars.iter().find(|v| v.addr == a))
                .map(|v| v.name.as_str()),
        },
        Some(value) => value,
        None => return "?".into(),
    };
    match (&var.kind, value) {
        (ValueKind::Enum(values), Value::Int(v)) => match values.iter().find(|(_, x)| *x == v) {
            Some((n, _)) => n.clone(),
            None => v.to_string(),
        },
        (ValueKind::Exception, Value::Int(v)) => match Trap::from_u64(v as u64) {
            Some(t) => t.name().to_string(),
            None => v.to_string(),
        },
        (_, value) => value.to_string(),
    }
}

/// Formats an elementary value held in a cell.
pub fn format_cell(e: Elem, cell: u64) -> String {
    match VarType::from_name(e.name()).and_then(|ty| Value::of_cell(ty, cell)) {
        Some(value) => value.to_string(),
        None => cell.to_string(),
    }
}

/// `T#1s500ms` style duration; `T#0s` for zero; negative as `T#-1s`.
pub fn format_time(ns: i64) -> String {
    Value::Time(ns).to_string()
}

/// Most bytes a `--set` text may take in data memory (a WSTRING's at most 65,535 units).
const MAX_SET_BYTES: usize = 2 * u16::MAX as usize;

/// Parses a `--set` value for `var` and writes it into data memory.
pub fn write_value(var: &MonitorVar, text: &str, data: &mut [u8]) -> Result<(), String> {
    if var.constant {
        return Err(format!("`{}` is a CONSTANT", var.name));
    }
    let text = text.trim();
    let ty = var
        .kind
        .var_type()
        .ok_or_else(|| format!("`{}` cannot be set", var.name))?;
    let mut buf = vec![0u8; MAX_SET_BYTES];
    let value = match &var.kind {
        ValueKind::Enum(values) => {
            let bare = text.rsplit('#').next().unwrap_or(text);
            match values.iter().find(|(n, _)| n.eq_ignore_ascii_case(bare)) {
                Some((_, v)) => Value::Int(*v),
                None => Value::Int(
                    bare.parse::<i64>()
                        .map_err(|_| format!("`{text}` is not a value of the enumeration"))?,
                ),
            }
        }
        ValueKind::Exception => Value::Int(
            text.parse::<i64>()
                .map_err(|_| format!("invalid exception code `{text}`"))?,
        ),
        _ => plc_vm::literal::parse(text, ty, &mut buf).map_err(|e| format!("`{text}` is {e}"))?,
    };
    let at = var.addr as usize;
    let bytes = data
        .get_mut(at..at + var.size as usize)
        .ok_or_else(|| format!("`{}` lies outside data memory", var.name))?;
    value
        .store(ty, bytes)
        .map_err(|e| format!("`{text}` cannot be written to `{}`: {e:?}", var.name))
}

/// The cell of a value of `e` typed as `text` (an IEC literal, see [`plc_vm::literal`]).
pub(crate) fn parse_elem(e: Elem, text: &str) -> Result<u64, String> {
    let ty = VarType::from_name(e.name()).ok_or_else(|| format!("{e} has no literal"))?;
    let value =
        plc_vm::literal::parse(text, ty, &mut []).map_err(|why| format!("`{text}` is {why}"))?;
    value
        .to_cell(ty)
        .map_err(|_| format!("`{text}` is not a valid {e} value"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats() {
        assert_eq!(format_time(1_500_000_000), "T#1s500ms");
        assert_eq!(format_time(-1_000_000_000), "T#-1s");
        assert_eq!(format_time(0), "T#0s");
        assert_eq!(format_time(90_061_001_001_001), "T#1d1h1m1s1ms1us1ns");
        assert_eq!(format_cell(Elem::LReal, 4.0f64.to_bits()), "4.0");
        assert_eq!(format_cell(Elem::Real, 0.1f32.to_bits() as u64), "0.1");
        assert_eq!(format_cell(Elem::Date, 86_400_000_000_000), "D#1970-01-02");
        assert_eq!(format_cell(Elem::LTod, 1), "LTOD#00:00:00.000000001");
        assert_eq!(format_cell(Elem::Char, 97), "'a'");
        assert_eq!(format_cell(Elem::WChar, 0x20AC), "\"€\"");
        assert_eq!(format_cell(Elem::SInt, -3i64 as u64), "-3");
        assert_eq!(
            parse_elem(Elem::Dt, "DT#1970-01-01-00:00:01"),
            Ok(1_000_000_000)
        );
        assert_eq!(parse_elem(Elem::Char, "'a'"), Ok(97));
        assert_eq!(parse_elem(Elem::Int, "-5"), Ok(-5i64 as u64));
        assert!(parse_elem(Elem::Char, "'ab'").is_err());
        assert_eq!(
            parse_elem(Elem::USInt, "300"),
            Err("`300` is out of the range of USINT (0 to 255)".into())
        );
    }
}
