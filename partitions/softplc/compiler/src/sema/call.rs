//! The call checker: the checking pass's walk of a call of a user FUNCTION or of a function
//! block instance's body, before anything is emitted.
//!
//! It owns the rules of calls: what a called name is (a FUNCTION, with or without its
//! namespace, never a type; a function block instance, never a CLASS; a standard function;
//! `REF`/`ADR`; a METHOD or action), how the arguments bind to the parameters (positional
//! ones first and not too many, named ones known, inputs by `:=` and outputs by `=>`, none
//! twice, every VAR_IN_OUT connected), that an input fits its parameter, that an in-out
//! argument is a whole variable of the parameter's type and that an output's target is a
//! writable place its value converts to. It records the callee ([`crate::typed::Callees`])
//! and the binding ([`crate::typed::Bindings`]) and the calls between user POUs (on which
//! [`crate::sema::body`] judges the recursion rule). The calls of METHODs, standard
//! functions and `REF`/`ADR` are still checked by the code generator's walk in its checking
//! mode ([`Gen`] with `check_only`), which this walk calls for them.

use crate::ast::{Arg, Expr, ExprKind, Ident, PouKind, VarKind};
use crate::codegen::{Bound, Gen, Loc, Place, instance_callee, scalar_mem};
use crate::codes;
use crate::diagnostics::Span;
use crate::sema::VarDef;
use crate::sema::expr::{check, coerce, value_to};
use crate::sema::place::place;
use crate::sema::refs::{check_escape, record_in_out_root, reference_to};
use crate::typed::{Binding, Callee};
use crate::types::Type;

/// Checks the call `callee(args)` at `span`, `expected` being the type its context asks
/// for; returns its type.
pub(crate) fn call(
    g: &mut Gen,
    callee: &Expr,
    args: &[Arg],
    expected: Option<&Type>,
    span: Span,
) -> Type {
    let target = match callee_of(g, callee, args) {
        Ok(target) => target,
        Err(ty) => return ty,
    };
    g.callees.record(callee, target.clone());
    match &target {
        Callee::RefFunction(n) => crate::sema::refs::ref_function(g, n, args, expected, span),
        Callee::Method(method) => crate::sema::class::method_call(g, method, callee, args, span),
        Callee::Function(pi) => static_call(g, *pi, args, span),
        Callee::Standard(n) => {
            if let Some(t) = crate::sema::stdcall::std_call(g, &n.name, n, args, expected, span) {
                return t;
            }
            let msg = format!("unknown function `{}`", n.text);
            g.error(codes::UNKNOWN_FUNCTION, n.span, msg);
            for a in args {
                g.infer(&a.value);
            }
            Type::Error
        }
        Callee::Instance(name) => {
            let instance = instance_callee(name.as_ref(), callee);
            instance_call(g, &instance, args, span)
        }
    }
}

/// What `callee` calls. `Err` is the call's type when the callee is wrong (reported).
fn callee_of(g: &mut Gen, callee: &Expr, args: &[Arg]) -> Result<Callee, Type> {
    if let ExprKind::Name(n) = &callee.kind
        && Gen::is_ref_function(&n.name)
        && !g.prog.pou_by_name.contains_key(&n.name)
    {
        return Ok(Callee::RefFunction(n.clone()));
    }
    if let Some(method) = crate::sema::class::resolve_method(g, callee, args)? {
        return Ok(Callee::Method(method));
    }
    // `Lib.F(...)`: a function qualified by a namespace (ours or a library's).
    let name = match &callee.kind {
        ExprKind::Member(base, f)
            if let ExprKind::Name(ns) = &base.kind
                && !g.is_visible_var(&ns.name) =>
        {
            Ident {
                name: format!("{}.{}", ns.name, f.name),
                text: format!("{}.{}", ns.text, f.text),
                span: callee.span,
            }
        }
        ExprKind::Name(n) => n.clone(),
        _ => return Ok(Callee::Instance(None)),
    };
    let n = if g.is_visible_var(&name.name) {
        name
    } else {
        function_name(g, &name)
    };
    // A variable is only callable when it is an FB instance; otherwise the name refers to a
    // function even if a variable happens to have the same name.
    let var_ty = match g.prog.pous[g.cur].var(&n.name) {
        Some(v) => Some(v.ty.clone()),
        None => g
            .owner_var_type(&n.name)
            .or_else(|| g.prog.global(&n.name).map(|gl| gl.ty.clone())),
    };
    let is_fb_var = matches!(var_ty, Some(Type::Fb(_)));
    let is_function = g.prog.pou_by_name.contains_key(&n.name) || Gen::is_std_function(&n.name);
    if !is_fb_var && (var_ty.is_none() || is_function) {
        if let Some(&pi) = g.prog.pou_by_name.get(&n.name) {
            return match g.prog.pous[pi].kind {
                PouKind::Function => Ok(Callee::Function(pi)),
                _ => {
                    let msg = format!("`{}` is a type; call an instance of it", n.text);
                    g.error(codes::NOT_CALLABLE, n.span, msg);
                    Err(Type::Error)
                }
            };
        }
        return Ok(Callee::Standard(n));
    }
    // A qualified or completed name stands for the instance instead of the callee.
    let renamed = !matches!(&callee.kind, ExprKind::Name(m) if m.name == n.name);
    Ok(Callee::Instance(renamed.then_some(n)))
}

/// The declared POU (or standard function) a called name refers to, with or without its
/// namespace (see [`crate::sema::qualified`]); the name itself when there is none.
fn function_name(g: &mut Gen, n: &Ident) -> Ident {
    if g.prog.pou_by_name.contains_key(&n.name) {
        return n.clone();
    }
    match crate::sema::qualified(&n.name, g.prog.pou_by_name.keys()) {
        Ok(Some(full)) => Ident {
            name: full,
            ..n.clone()
        },
        Err(candidates) => {
            let msg = crate::sema::ambiguous(&n.text, &candidates);
            g.error(codes::AMBIGUOUS_NAME, n.span, msg);
            n.clone()
        }
        Ok(None) => match n.name.rsplit_once('.') {
            // `Standard.CONCAT`: a standard function under a library's name.
            Some((_, last)) if Gen::is_std_function(last) || Gen::is_ref_function(last) => Ident {
                name: last.to_string(),
                text: n
                    .text
                    .rsplit_once('.')
                    .map_or(n.text.clone(), |t| t.1.to_string()),
                span: n.span,
            },
            _ => n.clone(),
        },
    }
}

/// Checks a call of the body of the function block instance `callee` (reports a callee that
/// is no instance).
fn instance_call(g: &mut Gen, callee: &Expr, args: &[Arg], span: Span) -> Type {
    let Some(p) = place(g, callee) else {
        return Type::Error;
    };
    match p.ty.clone() {
        Type::Fb(pi) => {
            if g.unit.pous[g.prog.pous[pi].ast].is_class {
                let msg = format!(
                    "`{}` is a CLASS: it has no body to call; call its methods",
                    g.prog.pous[pi].text
                );
                g.error(codes::NOT_CALLABLE, callee.span, msg);
            }
            instance_body_call(g, &p, pi, args, span);
            Type::Void
        }
        Type::Error => Type::Error,
        other => {
            let msg = format!("{} is not callable", g.tname(&other));
            g.error(codes::NOT_CALLABLE, callee.span, msg);
            Type::Error
        }
    }
}

/// Checks the arguments of a call of the body of block `pi` on the instance `inst`.
fn instance_body_call(g: &mut Gen, inst: &Place, pi: usize, args: &[Arg], span: Span) {
    g.calls.push((g.cur, pi, span));
    // Where a variable of the instance lies (a dynamic instance's address is parked).
    let member = |offset: u32| match inst.loc {
        Loc::Abs(a) => Loc::Abs(a + offset),
        Loc::Rel(o) => Loc::Rel(o + offset),
        Loc::Ind(_) | Loc::Ref(_) => Loc::Ind(offset),
    };
    let bound = bind_args(g, pi, args, span);
    for a in bound.iter().filter(|a| !a.output) {
        if a.param.kind == VarKind::InOut {
            record_in_out_root(g, a.value);
            in_out_argument(g, a.value, &a.param.ty);
            continue;
        }
        let p = Place {
            loc: member(a.param.offset),
            ty: a.param.ty.clone(),
            writable: true,
            window: None,
        };
        if p.ty.is_pointer_like() {
            check_escape(g, None, a.value, "an input of a function block instance");
        }
        if matches!(p.ty, Type::Reference(_)) {
            let r = reference_to(a.value);
            check_escape(g, None, &r, "an input of a function block instance");
        }
        crate::sema::stmt::check_store(g, &p, a.value, a.value.span);
    }
    outputs(g, &bound, member);
}

/// Checks a call of FUNCTION, METHOD or property accessor `pi` (parameters through its
/// static frame); returns its type.
pub(crate) fn static_call(g: &mut Gen, pi: usize, args: &[Arg], span: Span) -> Type {
    g.calls.push((g.cur, pi, span));
    let bound = bind_args(g, pi, args, span);
    for a in bound.iter().filter(|a| !a.output) {
        match a.param.kind {
            VarKind::InOut => {
                record_in_out_root(g, a.value);
                in_out_argument(g, a.value, &a.param.ty)
            }
            _ => input_value(g, a.value, &a.param.ty, None),
        }
    }
    // The outputs are in the callee's static frame.
    outputs(g, &bound, Loc::Abs);
    g.prog.pous[pi].return_type.clone().unwrap_or(Type::Void)
}

/// Binds the arguments of a call of `pi` at `span` (see [`bind`]).
fn bind_args<'e>(g: &mut Gen, pi: usize, args: &'e [Arg], span: Span) -> Vec<Bound<'e>> {
    let pou = &g.prog.pous[pi];
    let pou_name = pou.text.clone();
    let vars = pou.vars.clone();
    // The result variable (a function's, method's or getter's) is no output.
    let result = pou.return_type.as_ref().map(|_| pou.vars[0].name.clone());
    bind(
        g,
        Some(pi),
        &pou_name,
        &vars,
        result.as_deref(),
        (args, span),
    )
}

/// Binds the arguments `args` of a call at `span` to the parameters `vars` (in frame order)
/// of `pou_name` (the POU `pou`, if it is one): positional ones in declaration order of the
/// inputs and in-outs, named ones by name. Reports what is wrong (left out of the binding)
/// and each VAR_IN_OUT left unconnected, and records the binding ([`Binding`]).
pub(crate) fn bind<'e>(
    g: &mut Gen,
    pou: Option<usize>,
    pou_name: &str,
    vars: &[VarDef],
    result: Option<&str>,
    (args, span): (&'e [Arg], Span),
) -> Vec<Bound<'e>> {
    let binding = resolve_binding(g, pou, pou_name, vars, result, args);
    for (i, v) in vars.iter().enumerate() {
        if v.kind == VarKind::InOut && !binding.iter().any(|b| b.param == i) {
            let msg = format!("VAR_IN_OUT parameter `{}` must be connected", v.text);
            g.error(codes::MISSING_ARGUMENT, span, msg);
        }
    }
    if let Some(first) = args.first() {
        g.bindings.record(g.cur, first.span, binding.clone());
    }
    Bound::all(&binding, vars, args)
}

/// Which argument of `args` binds to which of the parameters `vars` of `pou_name`
/// (reported when wrong; what is wrong is left out).
fn resolve_binding(
    g: &mut Gen,
    pou: Option<usize>,
    pou_name: &str,
    vars: &[VarDef],
    result: Option<&str>,
    args: &[Arg],
) -> Vec<Binding> {
    let params: Vec<VarDef> = vars
        .iter()
        .filter(|v| matches!(v.kind, VarKind::Input | VarKind::InOut))
        .cloned()
        .collect();
    let mut out: Vec<Binding> = Vec::new();
    let mut named_seen = false;
    for (i, a) in args.iter().enumerate() {
        let param = match &a.name {
            Some(n) => {
                named_seen = true;
                let v = match pou {
                    // The POU's own lookup knows the CODESYS aliases of some parameters.
                    Some(pi) => g.prog.pous[pi].param(&n.name).cloned(),
                    None => vars.iter().find(|v| v.name == n.name).cloned(),
                };
                match v {
                    Some(v)
                        if a.output
                            && v.kind == VarKind::Output
                            && Some(v.name.as_str()) != result =>
                    {
                        v
                    }
                    Some(v) if !a.output && matches!(v.kind, VarKind::Input | VarKind::InOut) => v,
                    Some(_) => {
                        let msg = if a.output {
                            format!(
                                "`{}` is not an output of {pou_name} (use `:=` for inputs)",
                                n.text
                            )
                        } else {
                            format!(
                                "`{}` is not an input of {pou_name} (use `=>` for outputs)",
                                n.text
                            )
                        };
                        g.error(codes::UNKNOWN_PARAMETER, n.span, msg);
                        continue;
                    }
                    None => {
                        let msg = format!("{pou_name} has no parameter `{}`", n.text);
                        g.error(codes::UNKNOWN_PARAMETER, n.span, msg);
                        continue;
                    }
                }
            }
            None => {
                if named_seen {
                    g.error(
                        codes::ARGUMENT_ORDER,
                        a.span,
                        "positional arguments must come before named ones",
                    );
                    continue;
                }
                match params.get(i) {
                    Some(p) => p.clone(),
                    None => {
                        let msg = format!("too many arguments: {pou_name} takes {}", params.len());
                        g.error(codes::ARGUMENT_COUNT, a.span, msg);
                        continue;
                    }
                }
            }
        };
        let Some(index) = vars.iter().position(|v| v.name == param.name) else {
            continue;
        };
        if out.iter().any(|b| b.param == index) {
            let msg = format!("parameter `{}` given twice", param.text);
            g.error(codes::DUPLICATE_ARGUMENT, a.span, msg);
            continue;
        }
        out.push(Binding {
            param: index,
            arg: i,
            output: a.output,
        });
    }
    out
}

/// Checks the input argument `e` for a parameter of type `ty`: a STRING, WSTRING or
/// aggregate of its kind, else a value that converts implicitly. A reference passed to a
/// callee that may keep it (`kept_by` says which, `None` for a FUNCTION, which only borrows
/// it) must not be one to temporary storage.
pub(crate) fn input_value(g: &mut Gen, e: &Expr, ty: &Type, kept_by: Option<&str>) {
    match ty {
        Type::String(_) | Type::WString(_) | Type::Array(_) | Type::Struct(_) => {
            let t = check(g, e, Some(ty));
            let fits = match ty {
                Type::String(_) => t.is_string(),
                Type::WString(_) => t.is_wstring(),
                _ => t == *ty,
            };
            if !fits && !t.is_error() {
                let expected = match ty {
                    Type::String(_) => "STRING".to_string(),
                    Type::WString(_) => "WSTRING".to_string(),
                    _ => g.tname(ty),
                };
                let msg = format!("type mismatch: expected {expected}, found {}", g.tname(&t));
                g.error(codes::TYPE_MISMATCH, e.span, msg);
            }
        }
        ty => {
            if let Some(keeper) = kept_by
                && ty.is_pointer_like()
            {
                check_escape(g, None, e, keeper);
            }
            value_to(g, e, ty);
        }
    }
}

/// Checks the in-out argument `e` for a parameter of type `ty`: a whole variable of that
/// type.
pub(crate) fn in_out_argument(g: &mut Gen, e: &Expr, ty: &Type) {
    crate::sema::expr::sync_if_byte_viewed(g, e);
    let Some(p) = place(g, e) else {
        return;
    };
    if p.window.is_some() {
        g.error(
            codes::IN_OUT_ARGUMENT,
            e.span,
            "a partial access (`x.3`, `x.%B1`) cannot be passed to a VAR_IN_OUT",
        );
    } else if p.ty != *ty && !p.ty.is_error() && !ty.is_error() {
        let msg = format!(
            "VAR_IN_OUT argument must be a {} variable, found {}",
            g.tname(ty),
            g.tname(&p.ty)
        );
        g.error(codes::IN_OUT_ARGUMENT, e.span, msg);
    }
}

/// Checks the outputs `param => target` of a call whose arguments are bound as `bound`, each
/// output lying where `loc` says by its offset in the callee's frame.
pub(crate) fn outputs(g: &mut Gen, bound: &[Bound], loc: impl Fn(u32) -> Loc) {
    for a in bound.iter().filter(|a| a.output) {
        let src = Place {
            loc: loc(a.param.offset),
            ty: a.param.ty.clone(),
            writable: false,
            window: None,
        };
        output(g, &src, a.value);
    }
}

/// Checks `param => target` after a call, `src` being the output.
pub(crate) fn output(g: &mut Gen, src: &Place, target: &Expr) {
    let Some(dst) = place(g, target) else {
        return;
    };
    // A dynamic source address is pushed before the target's; the order stays valid only
    // when one of them is static.
    if let (Loc::Ind(_), Loc::Ind(_)) = (&src.loc, &dst.loc) {
        g.error(codes::OUTPUT_TARGET, target.span, "output of an FB array element into an array element with a computed index is not supported; use a temporary variable");
        return;
    }
    check_output_writable(g, &dst, target);
    match &dst.ty {
        Type::String(_) | Type::WString(_)
            if src.ty.is_wstring() != dst.ty.is_wstring() && !src.ty.is_error() =>
        {
            let msg = format!(
                "type mismatch: the output is {}, its target {}",
                g.tname(&src.ty),
                g.tname(&dst.ty)
            );
            g.error(codes::TYPE_MISMATCH, target.span, msg);
        }
        Type::String(_) | Type::WString(_) => {}
        t if scalar_mem(t).is_some() => coerce(g, &src.ty, t, target),
        _ => {}
    }
}

/// Reports an output's target `target` (the place `dst`) that cannot be written.
pub(crate) fn check_output_writable(g: &mut Gen, dst: &Place, target: &Expr) {
    if !dst.writable {
        g.error(
            codes::ASSIGN_TO_READ_ONLY,
            target.span,
            "output target is not writable",
        );
    }
}
