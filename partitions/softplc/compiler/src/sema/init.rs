//! The initial-value checker: the declared initial values of every variable (globals,
//! program and block instances, the frames of FUNCTIONs and METHODs), before the data image
//! is written.
//!
//! An elementary variable's initial value is a constant expression of a value its type
//! holds, a STRING's or WSTRING's a string literal, an array's `[v1, v2, n(v)]` with no more
//! values than elements, a structure's `(member := value, ...)` and a block instance's
//! `(input := value, ...)` of its own members, a reference's NULL. How a constant is held
//! in a cell ([`constant_cell`]) is one rule for this checker and the code generator, which
//! writes the image from the same values (`codegen::init`).

use crate::ast::{Expr, ExprKind, Ident, Init, PouKind, VarKind};
use crate::codegen::Gen;
use crate::codes::{self, Code};
use crate::diagnostics::Span;
use crate::sema::{ConstVal, Program, VarDef, const_eval};
use crate::types::{Elem, Type, implicit_ok};

/// Checks the initial values of the globals, the program instances and the frames of the
/// POUs whose frame emission lays out with its initial values (a FUNCTION's static frame,
/// the pristine copy a frame is re-initialised from on each call).
pub(crate) fn check_initial_values(g: &mut Gen) {
    for global in g.prog.globals.clone() {
        check_init(g, global.offset, &global.ty, global.init.as_ref(), None);
    }
    for instance in g.prog.instances.clone() {
        check_init(g, instance.addr, &Type::Fb(instance.pou), None, None);
    }
    for pou in 0..g.prog.pous.len() {
        let p = &g.prog.pous[pou];
        if p.kind == PouKind::Function || p.reinit_start < p.frame_size {
            // Where the frame lies is decided by emission; any address checks its values.
            check_init(g, 0, &Type::Fb(pou), None, None);
        }
    }
}

/// Checks the initial value `init` of a variable of type `ty` at `addr` (a constant
/// evaluated in the scope of `scope_pou`'s constants, if any; a variable past the end of
/// data memory is left to the data-size check).
pub(crate) fn check_init(
    g: &mut Gen,
    addr: u32,
    ty: &Type,
    init: Option<&Init>,
    scope_pou: Option<usize>,
) {
    if g.prog.beyond_data(addr, ty) {
        return;
    }
    match ty {
        Type::Elem(_) | Type::Subrange(..) | Type::Enum(_) | Type::Exception => {
            let elem = ty.elem().unwrap_or(Elem::DInt);
            let value = match init {
                Some(Init::Expr(e)) => {
                    let v = match scope_pou {
                        Some(p) => const_eval(g.prog, &g.pou_consts(p), e),
                        None => const_eval(g.prog, &(), e),
                    };
                    match v {
                        Some(v) => v,
                        None => {
                            g.diags.error(
                                codes::NOT_CONSTANT,
                                e.span,
                                "initial value must be a constant expression",
                            );
                            return;
                        }
                    }
                }
                Some(other) => {
                    g.diags.error(
                        codes::INITIAL_VALUE_SHAPE,
                        other.span(),
                        format!(
                            "a value of type {} cannot be initialised with an aggregate",
                            g.tname(ty)
                        ),
                    );
                    return;
                }
                None => match ty {
                    Type::Subrange(_, lo, _) => ConstVal::Int(*lo as i128),
                    Type::Enum(i) => {
                        ConstVal::Int(g.prog.enums[*i].values.first().map_or(0, |v| v.1) as i128)
                    }
                    _ => return,
                },
            };
            let span = init.map(|i| i.span()).unwrap_or_default();
            const_cell(g, &value, ty, elem, span);
        }
        Type::WString(_) => check_text_init(g, "WSTRING", init),
        Type::String(_) => check_text_init(g, "STRING", init),
        Type::Array(_) => check_array_init(g, addr, ty, init, scope_pou),
        Type::Struct(_) => check_struct_init(g, addr, ty, init),
        Type::Fb(_) => check_fb_init(g, addr, ty, init),
        Type::Ref(_) | Type::Reference(_) | Type::Interface(_) | Type::Null => {
            // A reference starts as NULL (the zeroed cell); nothing else is a constant.
            match init {
                None
                | Some(Init::Expr(Expr {
                    kind: ExprKind::Null | ExprKind::Int(0),
                    ..
                })) => {}
                Some(other) => {
                    g.diags.error(codes::REFERENCE_INITIAL_VALUE,
                        other.span(),
                        "the initial value of a reference or interface variable must be NULL (assign REF()/ADR() in the program)",
                    );
                }
            }
        }
        Type::Void | Type::Error => {}
    }
}

/// [`check_init`] of a STRING or (`kind` "WSTRING") a WSTRING: a string literal.
fn check_text_init(g: &mut Gen, kind: &str, init: Option<&Init>) {
    let span = match init {
        Some(Init::Expr(e)) => match const_eval(g.prog, &(), e) {
            Some(ConstVal::Str(_)) => return,
            _ => e.span,
        },
        Some(other) => other.span(),
        None => return,
    };
    let msg = format!("{kind} initial value must be a string literal");
    g.diags.error(codes::STRING_INITIAL_VALUE, span, msg);
}

/// [`check_init`] of an array.
fn check_array_init(
    g: &mut Gen,
    addr: u32,
    ty: &Type,
    init: Option<&Init>,
    scope_pou: Option<usize>,
) {
    let Type::Array(a) = ty else { return };
    let stride = g.prog.stride(&a.elem);
    let count = a.len();
    let values = array_init_values(init, count);
    match init {
        Some(Init::Array(items, span)) => {
            let given: u64 = items.iter().map(|i| i.repeat).sum();
            if given > count {
                g.diags.error(
                    codes::INITIAL_VALUE_SHAPE,
                    *span,
                    format!("too many initial values: the array has {count} elements"),
                );
            }
        }
        Some(Init::Expr(_)) if count == 1 => {}
        Some(other) => {
            g.diags.error(
                codes::INITIAL_VALUE_SHAPE,
                other.span(),
                "array initial value must be written `[v1, v2, n(v)]`",
            );
        }
        None => {}
    }
    let elem = a.elem.clone();
    for i in 0..count {
        let v = values.get(i as usize).copied().flatten();
        // Default elements still need headers (strings) and FB defaults.
        check_init(g, addr + i as u32 * stride, &elem, v, scope_pou);
    }
}

/// [`check_init`] of a structure.
fn check_struct_init(g: &mut Gen, addr: u32, ty: &Type, init: Option<&Init>) {
    let Type::Struct(si) = ty else { return };
    let members = g.prog.structs[*si].members.clone();
    let what = "structure initial value must be written `(member := value, ...)`";
    let fields = init_fields(g, init, what);
    for (n, _) in &fields {
        if !members.iter().any(|m| m.name == n.name) {
            g.diags.error(
                codes::INITIAL_VALUE_MEMBER,
                n.span,
                format!("`{}` is not a member of {}", n.text, g.tname(ty)),
            );
        }
    }
    for m in &members {
        let v = member_init(&fields, m);
        check_init(g, addr + m.offset, &m.ty, v.as_ref(), None);
    }
}

/// [`check_init`] of a function block instance.
fn check_fb_init(g: &mut Gen, addr: u32, ty: &Type, init: Option<&Init>) {
    let Type::Fb(pi) = ty else { return };
    if g.prog.pous[*pi].recursive {
        return;
    }
    let what = "function block initial values must be written `(input := value, ...)`";
    let fields = init_fields(g, init, what);
    let vars = g.prog.pous[*pi].vars.clone();
    for (n, _) in &fields {
        if !vars.iter().any(|m| {
            m.name == n.name && matches!(m.kind, VarKind::Input | VarKind::Output | VarKind::Local)
        }) {
            g.diags.error(
                codes::INITIAL_VALUE_MEMBER,
                n.span,
                format!("`{}` is not a variable of {}", n.text, g.tname(ty)),
            );
        }
    }
    for v in &vars {
        if matches!(v.kind, VarKind::External | VarKind::Global | VarKind::InOut) {
            continue;
        }
        let iv = member_init(&fields, v);
        check_init(g, addr + v.offset, &v.ty, iv.as_ref(), Some(*pi));
    }
}

/// The `(name := value, ...)` of a structure's or a block instance's initial value `init`
/// (reported, as `shape` says, when it is written otherwise).
fn init_fields(g: &mut Gen, init: Option<&Init>, shape: &str) -> Vec<(Ident, Init)> {
    match init {
        Some(Init::Struct(f, _)) => f.clone(),
        Some(other) => {
            g.diags
                .error(codes::INITIAL_VALUE_SHAPE, other.span(), shape);
            Vec::new()
        }
        None => Vec::new(),
    }
}

/// The initial value of member `m` (a structure's member or a block's variable) where
/// `fields` give some: the one given, else its declaration's.
pub(crate) fn member_init(fields: &[(Ident, Init)], m: &VarDef) -> Option<Init> {
    let given = fields.iter().find(|(n, _)| n.name == m.name);
    given.map(|(_, i)| i.clone()).or_else(|| m.init.clone())
}

/// The initial value of each element of an array of `count` elements initialised with
/// `init` (`[v1, v2, n(v)]`, or one value of a one-element array; the values past the
/// last element are left out, `None` where the element keeps its type's default).
pub(crate) fn array_init_values(init: Option<&Init>, count: u64) -> Vec<Option<&Init>> {
    let mut values = Vec::new();
    match init {
        Some(Init::Array(items, _)) => {
            for it in items {
                for _ in 0..it.repeat {
                    if values.len() as u64 >= count {
                        break;
                    }
                    values.push(it.value.as_ref());
                }
            }
        }
        Some(i @ Init::Expr(_)) if count == 1 => values.push(Some(i)),
        _ => {}
    }
    values
}

/// The cell (little-endian bits, as the VM holds a value of `elem`) of the constant `v` as a
/// value of type `ty`; `Err` says why it does not fit (the code and the message).
pub(crate) fn constant_cell(
    prog: &Program,
    v: &ConstVal,
    ty: &Type,
    elem: Elem,
) -> Result<u64, (Code, String)> {
    let bad = || {
        let msg = format!("constant does not fit type {}", prog.type_name(ty));
        Err((codes::VALUE_OUT_OF_RANGE, msg))
    };
    match (v, elem) {
        (ConstVal::Bool(b), Elem::Bool) => Ok(*b as u64),
        (ConstVal::Int(i), Elem::Bool) if *i == 0 || *i == 1 => Ok(*i as u64),
        (ConstVal::Int(i), e) if e.is_integral() => {
            let (lo, hi) = match ty {
                Type::Subrange(_, lo, hi) => (*lo as i128, *hi as i128),
                Type::Enum(_) | Type::Exception => (i32::MIN as i128, i32::MAX as i128),
                _ => e.int_range(),
            };
            if *i < lo || *i > hi {
                return bad();
            }
            Ok(*i as i64 as u64)
        }
        (ConstVal::Int(i), Elem::Real) => Ok((*i as f32).to_bits() as u64),
        (ConstVal::Int(i), Elem::LReal) => Ok((*i as f64).to_bits()),
        (ConstVal::Real(r), Elem::Real) => Ok((*r as f32).to_bits() as u64),
        (ConstVal::Real(r), Elem::LReal) => Ok(r.to_bits()),
        (ConstVal::Time(t), e) if e.is_duration() => Ok(*t as i64 as u64),
        (ConstVal::Temporal(k, t), e) if implicit_ok(*k, e) => Ok(*t as i64 as u64),
        (ConstVal::Int(i), e) if e.is_char() => {
            let (lo, hi) = e.int_range();
            if *i < lo || *i > hi {
                return bad();
            }
            Ok(*i as u64)
        }
        (ConstVal::Str(text), e) if e.is_char() => match crate::sema::single_char(text) {
            Some(c) if c <= e.int_range().1 => Ok(c as u64),
            _ => bad(),
        },
        _ => {
            let msg = format!(
                "initial value has the wrong type for {}",
                prog.type_name(ty)
            );
            Err((codes::INITIAL_VALUE_TYPE, msg))
        }
    }
}

/// [`constant_cell`], reporting at `span` a constant that does not fit.
pub(crate) fn const_cell(
    g: &mut Gen,
    v: &ConstVal,
    ty: &Type,
    elem: Elem,
    span: Span,
) -> Option<u64> {
    match constant_cell(g.prog, v, ty, elem) {
        Ok(cell) => Some(cell),
        Err((code, msg)) => {
            g.diags.error(code, span, msg);
            None
        }
    }
}
