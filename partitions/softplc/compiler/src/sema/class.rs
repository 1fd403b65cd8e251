//! The class checker: the checking pass's walk of the object-oriented parts of an
//! expression (declarations: [`crate::classes`]), before anything is emitted.
//!
//! It owns the rules of calls of METHODs and actions and of property accesses: a called
//! method exists (of the class whose body is walked, of an instance, of an interface), the
//! caller may use it (PRIVATE, PROTECTED), an action takes no arguments, an ABSTRACT method
//! is only called where the call is dispatched, a property read has a GET accessor and a
//! property written a SET accessor. It records the property each access reaches
//! ([`crate::typed::Properties`]) and, through the call checker ([`crate::sema::call`]),
//! each call's binding; the methods a dispatched call may run go into the call graph. What
//! a call may reach (its receiver, the implementations it may dispatch to, an interface
//! method's frame layout) is looked up by the code generator's helpers, one for both
//! passes.

use crate::ast::{Arg, Expr, ExprKind, Ident, Init, VarKind};
use crate::codegen::{Dynamic, Gen, Loc, scalar_mem};
use crate::codes;
use crate::diagnostics::Span;
use crate::sema::call::{bind, in_out_argument, input_value, outputs, static_call};
use crate::sema::expr::check;
use crate::sema::init::const_cell;
use crate::sema::place::place;
use crate::sema::refs::record_in_out_root;
use crate::sema::{Access, Member, MemberKind};
use crate::typed::{Accessor, Bare, Method, PropertyAccess, Receiver};
use crate::types::Type;

/// The method or action `callee` calls: `m(...)` inside a block, `inst.m(...)`,
/// `p^.m(...)`, `itf.m(...)`, `SUPER^.m(...)`; `Ok(None)` when `callee` is no such call,
/// `Err` with the call's type when the method is unknown (reported).
pub(crate) fn resolve_method(
    g: &mut Gen,
    callee: &Expr,
    args: &[Arg],
) -> Result<Option<Method>, Type> {
    match &callee.kind {
        ExprKind::Name(n) => {
            if g.is_visible_var(&n.name) {
                return Ok(None);
            }
            let Some(ctx) = g.context_class() else {
                return Ok(None);
            };
            Ok(g.prog
                .find_member(ctx, &n.name, MemberKind::Method)
                .or_else(|| g.prog.find_member(ctx, &n.name, MemberKind::Action))
                .map(Method::Own))
        }
        ExprKind::Member(base, m) => match g.receiver(base) {
            Some(Receiver::Interface(i)) => {
                let Some(im) = g
                    .prog
                    .interface_member(i, &m.name, MemberKind::Method)
                    .cloned()
                else {
                    let msg = format!(
                        "interface `{}` has no method `{}`",
                        g.prog.interfaces[i].text, m.text
                    );
                    g.error(codes::UNKNOWN_METHOD, m.span, msg);
                    for a in args {
                        g.infer(&a.value);
                    }
                    return Err(Type::Error);
                };
                Ok(Some(Method::OfInterface(i, Box::new(im))))
            }
            Some(Receiver::Instance { class, .. }) => Ok(g
                .prog
                .find_member(class, &m.name, MemberKind::Method)
                .or_else(|| g.prog.find_member(class, &m.name, MemberKind::Action))
                .map(Method::OfInstance)),
            None => Ok(None),
        },
        _ => Ok(None),
    }
}

/// Checks the call of the resolved method or action `method` of `callee`.
pub(crate) fn method_call(
    g: &mut Gen,
    method: &Method,
    callee: &Expr,
    args: &[Arg],
    span: Span,
) -> Type {
    let base = match &callee.kind {
        ExprKind::Member(base, _) => Some(&**base),
        _ => None,
    };
    match (method, base) {
        (Method::Own(member), _) => {
            let recv = g.own_receiver(g.context_class().unwrap_or(g.cur));
            member_call(g, None, recv, *member, args, span)
        }
        (Method::OfInterface(i, im), Some(base)) => {
            let dynamic = g.interface_dynamic(*i, im);
            dynamic_call(g, Some(base), dynamic, args, span)
        }
        (Method::OfInstance(member), Some(base)) if let Some(recv) = g.receiver(base) => {
            member_call(g, Some(base), recv, *member, args, span)
        }
        _ => {
            g.diags.error(
                codes::INTERNAL_ERROR,
                callee.span,
                "internal error: the checker's method has no receiver here",
            );
            Type::Error
        }
    }
}

/// Checks a call of member `member` (method, accessor or action) on the instance `base`
/// (`None`: the current instance), received as `recv`.
fn member_call(
    g: &mut Gen,
    base: Option<&Expr>,
    recv: Receiver,
    member: usize,
    args: &[Arg],
    span: Span,
) -> Type {
    let Receiver::Instance {
        class,
        exact,
        superclass,
    } = recv
    else {
        unreachable!("interfaces have no static members")
    };
    check_member_call(g, member, exact || superclass, args, span);
    let kind = g.prog.pous[member].member.as_ref().map(|m| m.kind);
    if kind == Some(MemberKind::Action) {
        g.calls.push((g.cur, member, span));
        if let Some(e) = base
            && place(g, e).is_none()
        {
            return Type::Error;
        }
        return Type::Void;
    }
    let targets = g.possible_targets(class, member);
    if !exact
        && !superclass
        && targets.len() > 1
        && let Some(d) = g.dynamic_of(member, targets)
    {
        return dynamic_call(g, base, d, args, span);
    }
    // A static call on the instance.
    if let Some(e) = base
        && place(g, e).is_none()
    {
        for a in args {
            g.infer(&a.value);
        }
        return Type::Error;
    }
    static_call(g, member, args, span)
}

/// Checks a dynamic call: the instance (`base`'s value, or the current instance), the
/// arguments bound to the parameters of `d`, its outputs.
fn dynamic_call(g: &mut Gen, base: Option<&Expr>, d: Dynamic, args: &[Arg], span: Span) -> Type {
    for &t in &d.targets {
        g.calls.push((g.cur, t, span));
    }
    if let Some(e) = base
        && check(g, e, None).is_error()
    {
        for a in args {
            g.infer(&a.value);
        }
        return Type::Error;
    }
    let bound = bind(g, None, &d.label, &d.params, None, (args, span));
    for a in bound.iter().filter(|b| !b.output) {
        match a.param.kind {
            VarKind::InOut => {
                record_in_out_root(g, a.value);
                in_out_argument(g, a.value, &a.param.ty)
            }
            _ => input_value(g, a.value, &a.param.ty, Some("an input of a method")),
        }
    }
    // An unconnected input starts with its declared initial value, which the call gives.
    for v in &d.params {
        if v.kind == VarKind::Input
            && !bound.iter().any(|b| b.param.name == v.name)
            && scalar_mem(&v.ty).is_some()
            && !g.dry
            && let Some(Init::Expr(e)) = &v.init
            && let Some(elem) = v.ty.elem()
        {
            match g.const_value(e) {
                Some(value) => {
                    const_cell(g, &value, &v.ty, elem, e.span);
                }
                None => {
                    let msg = "initial value must be a constant expression";
                    g.error(codes::NOT_CONSTANT, e.span, msg);
                }
            }
        }
    }
    outputs(g, &bound, Loc::Ind);
    d.result.map_or(Type::Void, |(t, _)| t)
}

/// Reports what is wrong with a call of the method or action `member` at `span` (the
/// checking pass asks): a member the caller may not use, arguments to an action, an
/// ABSTRACT method called where the call is not dispatched (`undispatched`: on an
/// instance of exactly its block, or through SUPER).
fn check_member_call(g: &mut Gen, member: usize, undispatched: bool, args: &[Arg], span: Span) {
    let Some(m) = g.prog.pous[member].member.clone() else {
        return;
    };
    check_access(g, &m, member, span);
    if m.kind == MemberKind::Action
        && let Some(a) = args.first()
    {
        g.error(
            codes::ARGUMENT_COUNT,
            a.span,
            "an action takes no arguments",
        );
    }
    if m.is_abstract && undispatched {
        let msg = format!(
            "`{}` is ABSTRACT: it has no implementation to call",
            g.prog.pous[member].text
        );
        g.error(codes::ABSTRACT_INSTANCE, span, msg);
    }
}

/// Reports a call of the PRIVATE or PROTECTED member `m` (the POU `member`) from where it
/// may not be called.
fn check_access(g: &mut Gen, m: &Member, member: usize, span: Span) {
    let ctx = g.context_class();
    let allowed = match m.access {
        Access::Private => ctx == Some(m.owner),
        Access::Protected => ctx.is_some_and(|c| g.prog.derives_from(c, m.owner)),
        Access::Public | Access::Internal => true,
    };
    if !allowed {
        let owner = g.prog.pous[m.owner].text.clone();
        let who = if m.access == Access::Private {
            format!("only `{owner}` itself may use it")
        } else {
            format!("only `{owner}` and blocks derived from it may use it")
        };
        let msg = format!(
            "`{}` is {}: {who}",
            g.prog.pous[member].text,
            m.access.keyword()
        );
        g.error(codes::ACCESS_DENIED, span, msg);
    }
}

// ----- properties ------------------------------------------------------------------------

/// `e` as a property access: the instance expression (`None`: the current instance), the
/// property and its name; resolved, and recorded with whether `e` is one at all.
fn property_target<'e>(
    g: &mut Gen,
    e: &'e Expr,
) -> Option<(Option<&'e Expr>, PropertyAccess, &'e Ident)> {
    let (base, name) = match &e.kind {
        ExprKind::Name(n) => (None, n),
        ExprKind::Member(base, m) => (Some(&**base), m),
        _ => return None,
    };
    let property = resolve_property(g, base, name);
    g.properties.record(g.cur, name, property.clone());
    Some((base, property?, name))
}

/// The property `base.name` (`name` alone when `base` is `None`) denotes, if it is one: a
/// variable of that name shadows a property of the current instance.
fn resolve_property(g: &mut Gen, base: Option<&Expr>, name: &Ident) -> Option<PropertyAccess> {
    let Some(base) = base else {
        if g.is_visible_var(&name.name) {
            return None;
        }
        let Bare::Property { class, getter } = g.own_property(name)? else {
            return None;
        };
        let setter = g.prog.find_member(class, &name.name, MemberKind::Setter);
        return Some(PropertyAccess {
            recv: g.own_receiver(class),
            getter: getter.map(Accessor::Pou),
            setter: setter.map(Accessor::Pou),
        });
    };
    let recv = g.receiver(base)?;
    let (getter, setter) = match recv {
        Receiver::Instance { class, .. } => {
            let find = |kind| {
                g.prog
                    .find_member(class, &name.name, kind)
                    .map(Accessor::Pou)
            };
            (find(MemberKind::Getter), find(MemberKind::Setter))
        }
        Receiver::Interface(i) => {
            let find = |kind| {
                g.prog
                    .interface_member(i, &name.name, kind)
                    .map(|im| Accessor::Interface(Box::new(im.clone())))
            };
            (find(MemberKind::Getter), find(MemberKind::Setter))
        }
    };
    (getter.is_some() || setter.is_some()).then_some(PropertyAccess {
        recv,
        getter,
        setter,
    })
}

/// Checks a read of property `e` (a bare name) of `class`, the class whose body is walked,
/// through its GET accessor `getter` (reported when it has none).
pub(crate) fn own_property_read(
    g: &mut Gen,
    class: usize,
    getter: Option<usize>,
    e: &Expr,
) -> Type {
    let ExprKind::Name(name) = &e.kind else {
        return Type::Error;
    };
    let Some(getter) = getter else {
        let msg = format!(
            "property `{}` is write-only (it has no GET accessor)",
            name.text
        );
        g.error(codes::PROPERTY_ACCESS, name.span, msg);
        return Type::Error;
    };
    let recv = g.own_receiver(class);
    member_call(g, None, recv, getter, &[], e.span)
}

/// Checks a read of a property through its GET accessor; `None` when `e` is no property.
pub(crate) fn property_read(g: &mut Gen, e: &Expr) -> Option<Type> {
    let (base, property, name) = property_target(g, e)?;
    Some(accessor_call(
        g,
        base,
        &property,
        name,
        MemberKind::Getter,
        &[],
        e.span,
    ))
}

/// Checks a write of `value` into a property through its SET accessor; `false` when
/// `target` is no property.
pub(crate) fn property_write(g: &mut Gen, target: &Expr, value: &Expr) -> bool {
    let Some((base, property, name)) = property_target(g, target) else {
        return false;
    };
    let args = g.setter_arguments(value);
    accessor_call(
        g,
        base,
        &property,
        name,
        MemberKind::Setter,
        &args[..],
        target.span,
    );
    true
}

/// Checks a call of the `kind` accessor of `property` (reported when it has none).
fn accessor_call(
    g: &mut Gen,
    base: Option<&Expr>,
    property: &PropertyAccess,
    name: &Ident,
    kind: MemberKind,
    args: &[Arg],
    span: Span,
) -> Type {
    let accessor = match kind {
        MemberKind::Getter => &property.getter,
        _ => &property.setter,
    };
    match (property.recv, accessor) {
        (recv @ Receiver::Instance { .. }, Some(Accessor::Pou(m))) => {
            member_call(g, base, recv, *m, args, span)
        }
        (Receiver::Interface(i), Some(Accessor::Interface(im))) => {
            let d = g.interface_dynamic(i, im);
            dynamic_call(g, base, d, args, span)
        }
        _ => {
            let what = if kind == MemberKind::Getter {
                "is write-only (it has no GET accessor)"
            } else {
                "is read-only (it has no SET accessor)"
            };
            let msg = format!("property `{}` {what}", name.text);
            g.error(codes::PROPERTY_ACCESS, name.span, msg);
            for a in args {
                g.infer(&a.value);
            }
            Type::Error
        }
    }
}
