//! The place checker: the checking pass's walk of a place (a variable, a member, an array
//! element, what a reference refers to, `THIS^`, a partial access), before anything is
//! emitted.
//!
//! It owns the rules of places: a name is a variable of the POU, of the block that owns a
//! METHOD or action, or a global (a VAR_EXTERNAL matching its VAR_GLOBAL); a member exists
//! (a structure's field, an instance's input or output, every variable of `THIS^`); an
//! indexed value is an array, with as many indices as dimensions, constant ones within
//! the bounds and computed ones integers; `^` dereferences a reference that is not NULL;
//! `THIS` and `SUPER` stand for an instance; a partial access lies within an integer or a
//! bit string. It records what each name and member denotes ([`crate::typed::Variables`],
//! [`crate::typed::Members`]) and gives the statement and expression checkers the place
//! (its type, whether it may be written, where it lies) that code generation will use:
//! the layout is [`Place`]'s, one for both passes.

use crate::ast::{Expr, ExprKind, Ident, VarKind};
use crate::codegen::{Gen, Place, element_offsets};
use crate::codes;
use crate::diagnostics::Span;
use crate::sema::expr::check;
use crate::typed::{Member, Variable};
use crate::types::Type;

/// Checks the place `e`; `None` after a reported error.
pub(crate) fn place(g: &mut Gen, e: &Expr) -> Option<Place> {
    Some(place_inner(g, e)?.finalized())
}

/// [`place`] as a base of a member or an element: a place reached through a reference stays
/// one (its members and elements are checked for their own bytes).
fn place_inner(g: &mut Gen, e: &Expr) -> Option<Place> {
    let p = match &e.kind {
        ExprKind::Name(n) => name_place(g, n),
        ExprKind::Deref(inner) if matches!(inner.kind, ExprKind::This | ExprKind::Super) => {
            let class = this_class(g, matches!(inner.kind, ExprKind::Super), e.span)?;
            Some(Place::instance(class))
        }
        ExprKind::Deref(inner) => deref_place(g, inner, e.span),
        ExprKind::Member(base, m) => member_place(g, base, m),
        ExprKind::Index(base, idx) => index_place(g, e, base, idx),
        ExprKind::Bits { base, width, index } => partial_place(g, e, base, *width, *index),
        _ => {
            g.error(codes::EXPECTED_VARIABLE, e.span, "expected a variable");
            None
        }
    }?;
    // A `REFERENCE TO` place stands for the variable it refers to (but where `REF=` or
    // `__ISVALIDREF` asks for the reference itself).
    Some(match &p.ty {
        Type::Reference(target) if !g.refs.keep_reference => Place::referred((**target).clone()),
        _ => p,
    })
}

/// The class `THIS` (or, with `superclass`, `SUPER`) stands for at `span`; `None` where
/// there is none (reported).
pub(crate) fn this_class(g: &mut Gen, superclass: bool, span: Span) -> Option<usize> {
    match g.this_class(superclass) {
        Ok(class) => Some(class),
        Err(msg) => {
            g.error(codes::NO_INSTANCE, span, msg);
            None
        }
    }
}

/// The place of the variable named `n`: resolved and recorded.
fn name_place(g: &mut Gen, n: &Ident) -> Option<Place> {
    let var = resolve_variable(g, n)?;
    g.variables.record(g.cur, n, var.clone());
    Some(g.variable_place(&var))
}

/// The variable `n` denotes in the POU walked: its own, its owner's (for a METHOD or
/// action) or a global (directly or through VAR_EXTERNAL).
fn resolve_variable(g: &mut Gen, n: &Ident) -> Option<Variable> {
    let pou = &g.prog.pous[g.cur];
    let (v, own) = match pou.var(&n.name).cloned() {
        Some(v) => (Some(v), true),
        None => (
            g.var_owner(&n.name)
                .and_then(|o| g.prog.pous[o].var(&n.name).cloned()),
            false,
        ),
    };
    let global = g.prog.globals.iter().position(|gl| gl.name == n.name);
    match (v, global) {
        (Some(v), _) if v.kind != VarKind::External => Some(Variable::Frame { var: v, own }),
        (Some(v), Some(index)) => {
            let gl = &g.prog.globals[index];
            if gl.ty != v.ty && !v.ty.is_error() && !gl.ty.is_error() {
                let msg = format!(
                    "VAR_EXTERNAL `{}` declared as {} but the global is {}",
                    v.text,
                    g.tname(&v.ty),
                    g.tname(&gl.ty)
                );
                g.error(codes::VAR_EXTERNAL, v.span, msg);
            }
            let writable = !g.prog.globals[index].constant && !v.constant;
            Some(Variable::Global { index, writable })
        }
        (Some(v), None) => {
            let msg = format!("VAR_EXTERNAL `{}` has no matching VAR_GLOBAL", v.text);
            g.error(codes::VAR_EXTERNAL, n.span, msg);
            None
        }
        (None, Some(index)) => Some(Variable::Global {
            index,
            writable: !g.prog.globals[index].constant,
        }),
        (None, None) => {
            let msg = format!("unknown variable `{}`", n.text);
            g.error(codes::UNKNOWN_VARIABLE, n.span, msg);
            None
        }
    }
}

/// `base.m`: a member of a structure or an input or output of a function block instance,
/// resolved and recorded.
fn member_place(g: &mut Gen, base: &Expr, m: &Ident) -> Option<Place> {
    let bp = place_inner(g, base)?;
    let member = resolve_member(g, base, &bp.ty, m)?;
    g.members.record(g.cur, m, member.clone());
    match member {
        Member::OwnInOut => name_place(g, m),
        member => Place::member(&bp, &member),
    }
}

/// What `m` of `base.m` denotes, `base` being of type `base_ty` (reports a wrong member).
fn resolve_member(g: &mut Gen, base: &Expr, base_ty: &Type, m: &Ident) -> Option<Member> {
    match base_ty {
        Type::Struct(si) => {
            let Some(mem) = g.prog.structs[*si]
                .members
                .iter()
                .find(|x| x.name == m.name)
                .cloned()
            else {
                let msg = format!("{} has no member `{}`", g.tname(base_ty), m.text);
                g.error(codes::NO_SUCH_MEMBER, m.span, msg);
                return None;
            };
            Some(Member::Field {
                offset: mem.offset,
                ty: mem.ty,
            })
        }
        Type::Fb(pi) => {
            let pi = *pi;
            let v = g.prog.pous[pi].param(&m.name).cloned();
            // `THIS^.x` / `SUPER^.x`: the block's own variables, all of them.
            let own = matches!(&base.kind, ExprKind::Deref(i) if matches!(i.kind, ExprKind::This | ExprKind::Super));
            match v {
                Some(v) if own && !matches!(v.kind, VarKind::External | VarKind::Global) => {
                    if v.kind == VarKind::InOut {
                        return Some(Member::OwnInOut);
                    }
                    Some(Member::Var {
                        offset: v.offset,
                        ty: v.ty,
                        writable: !v.constant,
                    })
                }
                // Outputs are read-only from outside; inputs may be set before a call.
                Some(v) if matches!(v.kind, VarKind::Input | VarKind::Output) => {
                    Some(Member::Var {
                        offset: v.offset,
                        ty: v.ty,
                        writable: v.kind == VarKind::Input,
                    })
                }
                Some(_) => {
                    let msg = format!(
                        "`{}` is not an input or output of {}",
                        m.text, g.prog.pous[pi].text
                    );
                    g.error(codes::NO_SUCH_MEMBER, m.span, msg);
                    None
                }
                None => {
                    let msg = format!(
                        "{} has no input or output `{}`",
                        g.prog.pous[pi].text, m.text
                    );
                    g.error(codes::NO_SUCH_MEMBER, m.span, msg);
                    None
                }
            }
        }
        Type::Error => None,
        other => {
            let msg = format!("{} has no members (`.{}`)", g.tname(other), m.text);
            g.error(codes::NO_SUCH_MEMBER, m.span, msg);
            None
        }
    }
}

/// `base[i, ...]` (the expression `e`): an element of an array.
fn index_place(g: &mut Gen, e: &Expr, base: &Expr, idx: &[Expr]) -> Option<Place> {
    let bp = place_inner(g, base)?;
    let Type::Array(arr) = bp.ty.clone() else {
        if !bp.ty.is_error() {
            let msg = format!("{} is not an array", g.tname(&bp.ty));
            g.error(codes::NOT_AN_ARRAY, base.span, msg);
        }
        for i in idx {
            g.infer(i);
        }
        return None;
    };
    if idx.len() != arr.dims.len() {
        let msg = format!(
            "array has {} dimension(s) but {} index(es) given",
            arr.dims.len(),
            idx.len()
        );
        g.error(codes::NOT_AN_ARRAY, e.span, msg);
        return None;
    }
    let consts = g.constant_indices(idx);
    for ((c, &(lo, hi)), i) in consts.iter().zip(&arr.dims).zip(idx) {
        if let Some(v) = c
            && (*v < lo as i128 || *v > hi as i128)
        {
            let msg = format!("index {v} is outside the array bounds {lo}..{hi}");
            g.error(codes::INDEX_OUT_OF_BOUNDS, i.span, msg);
        }
    }
    for (c, i) in consts.iter().zip(idx) {
        if c.is_none() {
            let t = check(g, i, Some(&Type::DINT));
            check_index_type(g, &t, i);
        }
    }
    let (_, static_offset) = element_offsets(g.prog, &arr, &consts);
    let computed = consts.iter().any(Option::is_none);
    Some(Place::element(
        &bp,
        arr.elem.clone(),
        static_offset,
        computed,
    ))
}

/// Reports an array index `index` of type `t` that is no integer.
pub(crate) fn check_index_type(g: &mut Gen, t: &Type, index: &Expr) {
    if !t.is_error() && !t.is_integral() {
        let msg = format!("array index must be an integer, found {}", g.tname(t));
        g.error(codes::INDEX_NOT_INTEGER, index.span, msg);
    }
}

/// The place `inner^`: the variable a reference refers to.
fn deref_place(g: &mut Gen, inner: &Expr, span: Span) -> Option<Place> {
    match check(g, inner, None) {
        Type::Ref(target) if !matches!(*target, Type::Void | Type::Null) => {
            Some(Place::referred(*target))
        }
        Type::Ref(_) | Type::Null => {
            g.error(codes::NULL_DEREFERENCE, span, "NULL cannot be dereferenced");
            None
        }
        Type::Error => None,
        other => {
            let msg = format!(
                "`^` dereferences a reference (REF_TO, POINTER TO), not {}",
                g.tname(&other)
            );
            g.error(codes::DEREFERENCE_NON_REFERENCE, span, msg);
            None
        }
    }
}

/// `base.N`, `base.%B1`, ... (the expression `e`): the bits of an integer or bit-string
/// variable (or of such a partial access).
fn partial_place(g: &mut Gen, e: &Expr, base: &Expr, width: u8, index: u32) -> Option<Place> {
    let bp = place(g, base)?;
    let Some((container, shift, bits)) = bp.bits() else {
        if !bp.ty.is_error() {
            let msg = format!(
                "partial access `.{}` needs a bit string or integer variable, found {}",
                index,
                g.tname(&bp.ty)
            );
            g.error(codes::PARTIAL_ACCESS, e.span, msg);
        }
        return None;
    };
    let width = width as u32;
    if (index as u64 + 1) * width as u64 > bits as u64 {
        let unit = match width {
            1 => "bit",
            8 => "byte",
            16 => "word",
            32 => "double word",
            _ => "long word",
        };
        let msg = format!(
            "{unit} {index} is outside the variable ({} bits: {unit}s 0..{})",
            bits,
            (bits / width).saturating_sub(1)
        );
        g.error(codes::PARTIAL_ACCESS, e.span, msg);
        return None;
    }
    Some(Place::partial(&bp, container, shift, width, index))
}
