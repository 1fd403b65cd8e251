//! The reference checker: the checking pass's rules of references (`REF()`, `ADR()`,
//! `__ISVALIDREF`, pointer arithmetic and comparisons, and references to temporary storage
//! that must not escape), before anything is emitted.
//!
//! It checks `REF()`/`ADR()` of a variable (not of an array of instances, a byte pointer only
//! to a STRING variable's text), `__ISVALIDREF` of a reference, the operands of pointer
//! arithmetic (a reference to plain data moved by an integer number of bytes) and of
//! comparisons of references; it records the variable each `REF()`/`ADR()` and each
//! VAR_IN_OUT argument is part of ([`crate::typed::Roots`], for the object table emission
//! writes) and rejects a reference to temporary storage stored where it outlives the call.
//! How references are represented is the code generator's ([`crate::codegen`]'s `refs`).

use crate::ast::{Arg, BinOp, Expr, ExprKind, Ident, PouKind, Stmt, StmtKind, VarKind};
use crate::codegen::{Gen, PointerOperation};
use crate::codes;
use crate::diagnostics::Span;
use crate::sema::expr::{check, is_byte_view, is_plain};
use crate::sema::place::place;
use crate::typed::Root;
use crate::types::Type;

/// Checks `REF(x)`, `ADR(x)` or `__ISVALIDREF(r)` (the callee `id`) with the arguments
/// `args`, `expected` being the type the context asks for.
pub(crate) fn ref_function(
    g: &mut Gen,
    id: &Ident,
    args: &[Arg],
    expected: Option<&Type>,
    span: Span,
) -> Type {
    let [arg] = args else {
        return wrong_arguments(g, id, args, span);
    };
    if arg.name.is_some() || arg.output {
        return wrong_arguments(g, id, args, span);
    }
    let arg = &arg.value;
    if id.name != "__ISVALIDREF" {
        return make_reference(g, arg, expected);
    }
    let saved = std::mem::replace(&mut g.refs.keep_reference, true);
    let t = check(g, arg, None);
    g.refs.keep_reference = saved;
    if !matches!(
        t,
        Type::Ref(_) | Type::Reference(_) | Type::Interface(_) | Type::Error
    ) {
        let msg = format!(
            "__ISVALIDREF needs a reference or interface, found {}",
            g.tname(&t)
        );
        g.error(codes::REF_OPERAND, arg.span, msg);
    }
    Type::BOOL
}

fn wrong_arguments(g: &mut Gen, id: &Ident, args: &[Arg], span: Span) -> Type {
    let msg = format!("{} takes one argument", id.text);
    g.error(codes::ARGUMENT_COUNT, span, msg);
    for a in args {
        g.infer(&a.value);
    }
    Type::Error
}

/// Checks `REF(x)` / `ADR(x)`: a reference to variable `x` (for a function-block instance,
/// its address); records the variable it is part of. `expected` is the reference type the
/// context wants: a byte pointer (`REF_TO BYTE`, `POINTER TO ARRAY[..] OF BYTE`, ...) made
/// from a STRING points at its text.
pub(crate) fn make_reference(g: &mut Gen, arg: &Expr, expected: Option<&Type>) -> Type {
    if let Some(root) = root_of(g, arg) {
        g.roots.record(arg, root);
    }
    let Some(p) = place(g, arg) else {
        return Type::Error;
    };
    match &p.ty {
        Type::Error => Type::Error,
        Type::Fb(pi) => Type::Ref(Box::new(Type::Fb(*pi))),
        Type::Array(a) if holds_instances(&a.elem) => {
            g.error(codes::REF_OPERAND,
                arg.span,
                "REF()/ADR() of an array of function block instances is not supported; take the address of one element",
            );
            Type::Error
        }
        Type::String(n) => {
            let view = match expected {
                Some(Type::Ref(t)) if is_byte_view(t) => Some((**t).clone()),
                _ => None,
            };
            let Some(target) = view else {
                return Type::Ref(Box::new(Type::String(*n)));
            };
            match &arg.kind {
                // Not found by the scan (e.g. inside an expression the scan does not see):
                // still consistent from here on.
                ExprKind::Name(v) if !g.refs.byte_viewed.contains(&v.name) => {
                    g.refs.byte_viewed.push(v.name.clone());
                }
                ExprKind::Name(_) => {}
                _ => {
                    g.error(codes::REF_OPERAND,
                        arg.span,
                        "a byte pointer to the text of a STRING can be taken of a STRING variable or parameter only (its length is re-read from the terminator there)",
                    );
                }
            }
            Type::Ref(Box::new(target))
        }
        t => Type::Ref(Box::new(t.clone())),
    }
}

/// Whether `ty` is or contains function-block instances.
fn holds_instances(ty: &Type) -> bool {
    match ty {
        Type::Fb(_) => true,
        Type::Array(a) => holds_instances(&a.elem),
        _ => false,
    }
}

/// Records the variable the VAR_IN_OUT argument `arg` is part of (for the object table).
pub(crate) fn record_in_out_root(g: &mut Gen, arg: &Expr) {
    if g.dry {
        return;
    }
    if let Some(root) = root_of(g, arg) {
        g.roots.record(arg, root);
    }
}

/// The variable a place expression is part of (`None` when it is reached through a
/// reference, whose object already bounds it).
fn root_of(g: &mut Gen, e: &Expr) -> Option<Root> {
    match &e.kind {
        ExprKind::Name(n) => {
            if let Some(v) = g.prog.pous[g.cur].var(&n.name) {
                return Some(match v.kind {
                    VarKind::External => Root::Global(n.name.clone()),
                    VarKind::InOut => Root::InOut(g.cur, n.name.clone()),
                    _ => Root::Var(g.cur, n.name.clone()),
                });
            }
            if let Some(owner) = g.var_owner(&n.name) {
                return Some(Root::Var(owner, n.name.clone()));
            }
            g.prog.global(&n.name).map(|_| Root::Global(n.name.clone()))
        }
        ExprKind::Member(base, m) => match g.infer(base) {
            Type::Fb(pi) => Some(Root::Var(pi, m.name.clone())),
            _ => root_of(g, base),
        },
        ExprKind::Index(base, _) => root_of(g, base),
        _ => None,
    }
}

// ----- pointer arithmetic and comparisons ------------------------------------------------

/// Checks an operation on references or addresses ([`PointerOperation`]): pointer
/// arithmetic (`ref + n`, `n + ref`, `ref - n`; `ref - ref`) and comparisons of references,
/// interface values and addresses.
pub(crate) fn pointer_binary(
    g: &mut Gen,
    op: BinOp,
    a: &Expr,
    b: &Expr,
    expected: Option<&Type>,
    span: Span,
) -> Type {
    let (ta, tb) = (g.pointer_operand_type(a), g.pointer_operand_type(b));
    let ref_expected = expected.filter(|t| matches!(t, Type::Ref(_)));
    match PointerOperation::of(op, &ta, &tb) {
        Some(PointerOperation::Move { reference_first }) => {
            let (r, n) = if reference_first { (a, b) } else { (b, a) };
            let rt = if reference_first {
                let rt = check(g, r, ref_expected);
                offset_operand(g, n);
                rt
            } else {
                offset_operand(g, n);
                check(g, r, ref_expected)
            };
            match &rt {
                Type::Ref(target) if !is_plain(g.prog, target) => {
                    let msg = format!(
                        "pointer arithmetic on {} is not allowed: it could reach a reference or instance stored there (only references to plain data can be moved)",
                        g.tname(&rt)
                    );
                    g.error(codes::POINTER_ARITHMETIC, span, msg);
                    Type::Error
                }
                Type::Ref(_) | Type::Error => rt,
                other => {
                    let msg = format!(
                        "pointer arithmetic needs a reference, found {}",
                        g.tname(other)
                    );
                    g.error(codes::POINTER_ARITHMETIC, span, msg);
                    Type::Error
                }
            }
        }
        Some(PointerOperation::Distance) => {
            address_operand(g, a);
            address_operand(g, b);
            Type::DINT
        }
        Some(PointerOperation::Compare) => {
            address_operand(g, a);
            address_operand(g, b);
            Type::BOOL
        }
        None => {
            let name = |g: &Gen, t: &Option<Type>| match t {
                Some(t) => g.tname(t),
                None => "an integer".into(),
            };
            let msg = format!(
                "operator {} cannot be applied to {} and {} (references allow `+`/`-` of a byte offset, the difference of two references and comparisons)",
                op.symbol(),
                name(g, &ta),
                name(g, &tb)
            );
            g.error(codes::POINTER_ARITHMETIC, span, msg);
            Type::Error
        }
    }
}

/// Checks an integer byte offset for pointer arithmetic.
fn offset_operand(g: &mut Gen, e: &Expr) {
    let t = check(g, e, Some(&Type::LINT));
    if !t.is_error() && !t.elem().is_some_and(|x| x.is_integral()) {
        let msg = format!(
            "a reference moves by an integer number of bytes, not by {}",
            g.tname(&t)
        );
        g.error(codes::POINTER_ARITHMETIC, e.span, msg);
    }
}

/// Checks an operand of a comparison of addresses: a reference, an instance or interface
/// value, or an integer.
fn address_operand(g: &mut Gen, e: &Expr) {
    let t = check(g, e, Some(&Type::ULINT));
    match &t {
        Type::Ref(_) | Type::Interface(_) | Type::Null | Type::Fb(_) | Type::Error => {}
        t if t.elem().is_some_and(|x| x.is_integral()) => {}
        other => {
            let msg = format!(
                "a reference can be compared with a reference, an interface or an address, not with {}",
                g.tname(other)
            );
            g.error(codes::REFERENCE_COMPARISON, e.span, msg);
        }
    }
}

// ----- references to temporary storage -------------------------------------------------
//
// Every variable has a static home in this VM, so no reference can ever dangle into
// freed memory; but a FUNCTION's (or METHOD's) variables and a VAR_TEMP are re-initialised
// by the next call, so a reference to them that outlives the call would silently see
// another call's data. The compiler rejects the ways such a reference can leave the call:
// stored anywhere but in a temporary variable of the same POU (a global, a variable of an
// instance, an output or the function's result, through a dereference or a VAR_IN_OUT),
// or passed to a FUNCTION_BLOCK or METHOD input (which may keep it). Passing it to a
// FUNCTION input is allowed: a FUNCTION's reference inputs are *borrowed* in turn: the
// function may return them (as its result or an output) but not keep them, and its
// caller treats the result as derived from the references it passed in. Temporary
// reference variables that are assigned such a reference anywhere in the POU count as
// holding one everywhere.

/// Where a reference value may point, for the checks of references to temporaries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Taint {
    /// Nowhere temporary.
    None,
    /// Into what the caller of the current FUNCTION passed (its reference inputs).
    Borrowed,
    /// Into the current POU's temporary storage.
    Local,
}

/// Whether `name` is temporary storage of the current POU.
fn is_temporary_var(g: &Gen, name: &str) -> bool {
    let pou = &g.prog.pous[g.cur];
    let Some(v) = pou.var(name) else {
        return false;
    };
    let function_like = matches!(pou.kind, PouKind::Function) || g.is_method(g.cur);
    let is_result = pou.return_type.is_some() && pou.vars.first().is_some_and(|r| r.name == v.name);
    match v.kind {
        VarKind::Temp => true,
        VarKind::Local | VarKind::Input => function_like && !is_result,
        _ => false,
    }
}

/// Whether `name` is what a FUNCTION hands back to its caller: its result or an output.
fn is_function_output(g: &Gen, name: &str) -> bool {
    let pou = &g.prog.pous[g.cur];
    pou.kind == PouKind::Function
        && !g.is_method(g.cur)
        && pou.var(name).is_some_and(|v| v.kind == VarKind::Output)
}

/// Whether `e` may evaluate to a reference to temporary storage of the current POU
/// (`Local`), or to one of a FUNCTION's borrowed reference inputs (`Borrowed`).
fn temp_derived(g: &mut Gen, e: &Expr) -> Taint {
    match &e.kind {
        ExprKind::Call { callee, args } => {
            let ExprKind::Name(f) = &callee.kind else {
                return Taint::None;
            };
            if matches!(f.name.as_str(), "REF" | "ADR") {
                return match args.as_slice() {
                    [a] if place_is_temporary(g, &a.value) => Taint::Local,
                    [a] => deref_taint(g, &a.value),
                    _ => Taint::None,
                };
            }
            // A function's result may be one of the references passed to it.
            let Some(&pi) = g.prog.pou_by_name.get(&f.name) else {
                return Taint::None;
            };
            if g.prog.pous[pi].kind != PouKind::Function {
                return Taint::None;
            }
            args.iter()
                .filter(|a| !a.output)
                .map(|a| temp_derived(g, &a.value))
                .max()
                .unwrap_or(Taint::None)
        }
        ExprKind::Name(n) => {
            if g.refs.tainted.contains(&n.name) {
                return Taint::Local;
            }
            if g.refs.borrowed.contains(&n.name) {
                return Taint::Borrowed;
            }
            // A FUNCTION's reference inputs, and a reference read from any POU's
            // VAR_IN_OUT, may point to the caller's temporaries.
            let pou = &g.prog.pous[g.cur];
            let function = pou.kind == PouKind::Function && !g.is_method(g.cur);
            let borrowed = pou.var(&n.name).is_some_and(|v| {
                matches!(v.ty, Type::Ref(_) | Type::Interface(_))
                    && (v.kind == VarKind::InOut || function && v.kind == VarKind::Input)
            });
            if borrowed {
                Taint::Borrowed
            } else {
                Taint::None
            }
        }
        ExprKind::Binary(BinOp::Add | BinOp::Sub, a, b) => {
            temp_derived(g, a).max(temp_derived(g, b))
        }
        _ => Taint::None,
    }
}

/// The taint of the reference a place expression is reached through, if any.
fn deref_taint(g: &mut Gen, e: &Expr) -> Taint {
    match &e.kind {
        ExprKind::Member(b, _) | ExprKind::Index(b, _) => deref_taint(g, b),
        ExprKind::Deref(r) => temp_derived(g, r),
        _ => Taint::None,
    }
}

/// Whether place expression `e` lies in temporary storage of the current POU.
fn place_is_temporary(g: &mut Gen, e: &Expr) -> bool {
    match &e.kind {
        ExprKind::Name(n) => is_temporary_var(g, &n.name),
        ExprKind::Member(b, _) | ExprKind::Index(b, _) => place_is_temporary(g, b),
        ExprKind::Deref(r) => temp_derived(g, r) == Taint::Local,
        _ => false,
    }
}

/// Finds the temporary reference variables of the current POU that may hold a reference
/// to its temporary storage or a borrowed one (assignments anywhere in `body`, to a
/// fixpoint).
pub(crate) fn scan_temporary_references(g: &mut Gen, body: &[Stmt]) {
    g.refs.tainted.clear();
    g.refs.borrowed.clear();
    let mut assigns: Vec<(Ident, Expr)> = Vec::new();
    for s in body {
        collect_assignments(s, &mut assigns);
    }
    loop {
        let mut changed = false;
        for (target, value) in &assigns {
            if !is_temporary_var(g, &target.name) {
                continue;
            }
            let taint = temp_derived(g, value);
            let set = match taint {
                Taint::Local => &mut g.refs.tainted,
                Taint::Borrowed => &mut g.refs.borrowed,
                Taint::None => continue,
            };
            if set.insert(target.name.clone()) {
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
}

/// Rejects storing `value`, a reference that may point to temporary storage of the
/// current POU, into `target` (`None`: a destination that outlives the call, named by
/// `what`) unless `target` is itself temporary storage of this POU (or, for a borrowed
/// reference, the result or an output of the FUNCTION it was passed to).
pub(crate) fn check_escape(g: &mut Gen, target: Option<&Expr>, value: &Expr, what: &str) {
    if g.dry {
        return;
    }
    let taint = temp_derived(g, value);
    if taint == Taint::None {
        return;
    }
    if let Some(t) = target
        && let ExprKind::Name(n) = &t.kind
        && (is_temporary_var(g, &n.name)
            || taint == Taint::Borrowed && is_function_output(g, &n.name))
    {
        return;
    }
    let pou = g.prog.pous[g.cur].text.clone();
    let msg = match taint {
        Taint::Borrowed => format!(
            "this reference came from the caller of `{pou}` (a FUNCTION's reference input or a VAR_IN_OUT) and may point to the caller's temporary variables; a FUNCTION may return it (as its result or an output) but it cannot be stored in {what}, which outlives the call"
        ),
        _ => format!(
            "this reference may point to a temporary variable of `{pou}` (a FUNCTION's or METHOD's variables, a VAR_TEMP), which the next call re-initialises; it cannot be stored in {what}, which outlives the call"
        ),
    };
    g.error(codes::REFERENCE_ESCAPE, value.span, msg);
}

/// The expression `REF(e)`.
pub(crate) fn reference_to(e: &Expr) -> Expr {
    let id = Ident {
        name: "REF".into(),
        text: "REF".into(),
        span: e.span,
    };
    Expr {
        kind: ExprKind::Call {
            callee: Box::new(Expr {
                kind: ExprKind::Name(id),
                span: e.span,
            }),
            args: vec![Arg {
                name: None,
                output: false,
                value: e.clone(),
                span: e.span,
            }],
        },
        span: e.span,
    }
}

/// Every `name := value` / `name REF= value` to a plain variable in `s`.
fn collect_assignments(s: &Stmt, out: &mut Vec<(Ident, Expr)>) {
    let body = |b: &[Stmt], out: &mut Vec<(Ident, Expr)>| {
        b.iter().for_each(|s| collect_assignments(s, out))
    };
    match &s.kind {
        StmtKind::Assign { target, value } | StmtKind::RefAssign { target, value } => {
            if let ExprKind::Name(n) = &target.kind {
                out.push((n.clone(), value.clone()));
            }
        }
        StmtKind::If {
            branches,
            else_body,
        } => {
            for (_, b) in branches {
                body(b, out);
            }
            if let Some(b) = else_body {
                body(b, out);
            }
        }
        StmtKind::Case {
            arms, else_body, ..
        } => {
            for a in arms {
                body(&a.body, out);
            }
            if let Some(b) = else_body {
                body(b, out);
            }
        }
        StmtKind::For { body: b, .. }
        | StmtKind::While { body: b, .. }
        | StmtKind::Repeat { body: b, .. } => body(b, out),
        StmtKind::Try {
            body: b,
            catch_body,
            finally_body,
            ..
        } => {
            body(b, out);
            body(catch_body, out);
            body(finally_body, out);
        }
        _ => {}
    }
}
