//! The standard-function call checker: the checking pass's walk of a call of a standard
//! function (numeric, selection, bit shifts, conversions, strings, dates and times,
//! SIZEOF), before anything is emitted.
//!
//! It places the arguments (positional, then formal ones by name: none unknown, repeated,
//! misplaced or missing; no outputs but a SPLIT_ function's), checks their count and types
//! by the rules of [`sema::stdfuncs`](crate::sema::stdfuncs) and records what emission
//! needs ([`crate::typed`]): the order of the arguments, the type each generic function is
//! called at, how each conversion takes its argument. Which standard functions there are
//! and their formal inputs are the code generator's tables (`codegen::stdfuncs`), one for
//! both passes.

use crate::ast::{Arg, Expr, ExprKind, Ident};
use crate::codegen::{Gen, MAX_TEMP_STRING, StdArgs, StdFamily, TimeFunction, split_arguments};
use crate::codes;
use crate::diagnostics::Span;
use crate::sema::call::check_output_writable;
use crate::sema::expr::{
    binary, check, has_real_literal, is_flexible, operand, value_to, value_to_any,
};
use crate::sema::place::place;
use crate::sema::stdfuncs::{self as rules, ConversionArgument};
use crate::types::{DEFAULT_STRING_LEN, Elem, Type, common_numeric, implicit_ok};

/// Checks a call of the standard function `name` (the callee `id`) with the arguments
/// `args` at `span`, `expected` being the type the context asks for; `None` when `name` is
/// no standard function.
pub(crate) fn std_call(
    g: &mut Gen,
    name: &str,
    id: &Ident,
    args: &[Arg],
    expected: Option<&Type>,
    span: Span,
) -> Option<Type> {
    let ctx = Gen::literal_context(expected);
    if let Some(f) = Gen::time_function(name) {
        return Some(std_time(g, f, id, args, expected, span));
    }
    if name == "SIZEOF" {
        return Some(std_sizeof(g, id, args, expected, span));
    }
    check_no_outputs(g, id, args);
    if let Some(target) = name.strip_prefix("TO_") {
        return generic_conversion(g, target, id, args, span);
    }
    let (name, typed) = match Gen::typed_overload(name) {
        Some((base, t)) => (base, Some(t)),
        None => (name, None),
    };
    let Some(exprs) = std_arguments(g, name, id, args) else {
        return Some(Type::Error);
    };
    let c = StdArgs::new((name, typed), id, exprs, ctx, span);
    if let Some(t) = typed
        && !typed_arguments(g, &c, t)
    {
        return Some(Type::Error);
    }
    match StdFamily::of(name) {
        StdFamily::Numeric => std_numeric(g, &c),
        StdFamily::Selection => std_selection(g, &c),
        StdFamily::Bits => std_bits(g, &c),
        StdFamily::Strings => std_string(g, &c),
        StdFamily::Conversion => conversion(g, name, id, &c.exprs, span),
    }
}

/// Reports an output argument (`=>`) of the standard function `id`, which has none.
fn check_no_outputs(g: &mut Gen, id: &Ident, args: &[Arg]) {
    if let Some(a) = args.iter().find(|a| a.output) {
        let msg = format!("{} has no outputs", id.text);
        g.error(codes::UNKNOWN_PARAMETER, a.span, msg);
        surface(g, &a.value);
    }
}

/// Checks that the arguments of a typed form convert to its type implicitly (SEL's
/// selector, MUX's index and EXPT's exponent are not typed). False after reporting one
/// that does not.
fn typed_arguments(g: &mut Gen, c: &StdArgs, t: Elem) -> bool {
    let untyped = match c.name {
        "SEL" | "MUX" => 1,
        _ => 0,
    };
    let typed_count = match c.name {
        "EXPT" => 1,
        _ => c.exprs.len(),
    };
    let mut ok = true;
    for e in c.exprs.iter().take(typed_count).skip(untyped) {
        if is_flexible(e) {
            continue;
        }
        let at = g.infer(e);
        let fits = !matches!(at, Type::Enum(_) | Type::Exception)
            && at.elem().is_some_and(|x| implicit_ok(x, t));
        if !fits {
            if at.is_error() {
                surface(g, e);
            } else {
                let msg = format!(
                    "{} takes {t} arguments, found {} (convert it with {}_TO_{t})",
                    c.id.text,
                    g.tname(&at),
                    g.tname(&at)
                );
                g.error(codes::IMPLICIT_CONVERSION, e.span, msg);
            }
            ok = false;
        }
    }
    ok
}

/// The argument expressions of a standard function in the order of its inputs: the
/// positional ones first, the formal ones (`IN2 := x`) put in their place; the order is
/// recorded ([`crate::typed::StdArguments`]). `None` after reporting a misplaced, unknown,
/// repeated or missing one.
fn std_arguments<'e>(
    g: &mut Gen,
    name: &str,
    id: &Ident,
    args: &'e [Arg],
) -> Option<Vec<&'e Expr>> {
    let order = place_std_arguments(g, name, id, args)?;
    g.std_arguments.record(g.cur, id, order.clone());
    Some(order.into_iter().map(|i| &args[i].value).collect())
}

/// The index in `args` of each argument of standard function `name` in the order of its
/// inputs (see [`std_arguments`]).
fn place_std_arguments(g: &mut Gen, name: &str, id: &Ident, args: &[Arg]) -> Option<Vec<usize>> {
    let inputs: Vec<(usize, &Arg)> = args.iter().enumerate().filter(|(_, a)| !a.output).collect();
    if inputs.iter().all(|(_, a)| a.name.is_none()) {
        return Some(inputs.iter().map(|(i, _)| *i).collect());
    }
    let formals = Gen::std_formals(name, inputs.len());
    let mut slots: Vec<Option<usize>> = vec![None; formals.len().max(inputs.len())];
    let mut ok = true;
    let mut named_seen = false;
    for (i, &(index, a)) in inputs.iter().enumerate() {
        let slot = match &a.name {
            None if named_seen => {
                g.error(
                    codes::ARGUMENT_ORDER,
                    a.span,
                    "positional arguments must come before named ones",
                );
                ok = false;
                continue;
            }
            None => i,
            Some(n) => {
                named_seen = true;
                match formals.iter().position(|f| *f == n.name) {
                    Some(k) => k,
                    None => {
                        let msg = format!(
                            "{} has no input `{}` (its inputs: {})",
                            id.text,
                            n.text,
                            formals.join(", ")
                        );
                        g.error(codes::UNKNOWN_PARAMETER, n.span, msg);
                        ok = false;
                        continue;
                    }
                }
            }
        };
        if slots[slot].is_some() {
            let msg = format!(
                "input `{}` given twice",
                formals.get(slot).map_or("?", |f| f)
            );
            g.error(codes::DUPLICATE_ARGUMENT, a.span, msg);
            ok = false;
            continue;
        }
        slots[slot] = Some(index);
    }
    let given = slots
        .iter()
        .rposition(Option::is_some)
        .map_or(0, |last| last + 1);
    if let Some(missing) = slots[..given].iter().position(Option::is_none) {
        let msg = format!(
            "{} needs its input `{}`",
            id.text,
            formals.get(missing).map_or("?", |f| f)
        );
        g.error(codes::MISSING_ARGUMENT, id.span, msg);
        ok = false;
    }
    if !ok {
        for a in args {
            surface(g, &a.value);
        }
        return None;
    }
    Some(slots.into_iter().flatten().collect())
}

/// False (after reporting it and checking the arguments) unless the call has exactly `n`
/// arguments.
fn arity(g: &mut Gen, c: &StdArgs, n: usize) -> bool {
    if c.exprs.len() == n {
        return true;
    }
    let msg = format!(
        "{} takes {} argument(s), {} given",
        c.id.text,
        n,
        c.exprs.len()
    );
    g.error(codes::ARGUMENT_COUNT, c.span, msg);
    for e in &c.exprs {
        surface(g, e);
    }
    false
}

/// Reports that the argument `e` of type `t` is not `what` (unless `t` is the error type).
fn bad_arg(g: &mut Gen, e: &Expr, t: &Type, what: &str) -> Type {
    if !t.is_error() {
        let msg = format!("expected {what}, found {}", g.tname(t));
        g.error(codes::TYPE_MISMATCH, e.span, msg);
    }
    Type::Error
}

/// [`bad_arg`] for an argument so far only inferred: an erroneous one is checked for its
/// own diagnostics.
fn bad_inferred_arg(g: &mut Gen, e: &Expr, t: &Type, what: &str) -> Type {
    if t.is_error() {
        surface(g, e);
    }
    bad_arg(g, e, t, what)
}

/// Checks an expression whose inference failed, for the diagnostics saying why.
fn surface(g: &mut Gen, e: &Expr) {
    if !g.dry {
        check(g, e, None);
    }
}

/// Records the type the generic standard-function call `id` is called at (a walk for
/// inference records only what no real walk has, as the expected type may differ).
fn record_generic_type(g: &mut Gen, id: &Ident, t: Type) {
    if !g.dry || g.generic_types.of(g.cur, id).is_none() {
        g.generic_types.record(g.cur, id, t);
    }
}

// ----- conversions --------------------------------------------------------------------------

/// `TO_INT(x)`, `TO_STRING(x)`, ... (IEC 61131-3 3rd edition): the conversion from the
/// argument's type, which is recorded ([`crate::typed::GenericTypes`]).
fn generic_conversion(
    g: &mut Gen,
    target: &str,
    id: &Ident,
    args: &[Arg],
    span: Span,
) -> Option<Type> {
    if target != "STRING" && Elem::from_name(target).is_none() {
        return None;
    }
    let inputs = std_arguments(g, &id.name, id, args)?;
    let [arg] = inputs[..] else {
        let msg = format!("{} takes 1 argument, {} given", id.text, inputs.len());
        g.error(codes::ARGUMENT_COUNT, span, msg);
        for e in inputs {
            surface(g, e);
        }
        return Some(Type::Error);
    };
    let t = g.infer(arg);
    if t.is_error() {
        surface(g, arg);
        return Some(Type::Error);
    }
    let Some(source) = rules::conversion_source(operand(arg, &t)) else {
        bad_inferred_arg(g, arg, &t, "an elementary value");
        return Some(Type::Error);
    };
    record_generic_type(g, id, source.clone());
    let source = match source {
        Type::String(_) => "STRING".to_string(),
        t => g.tname(&t),
    };
    if source == target {
        return Some(check(g, arg, None));
    }
    conversion(g, &format!("{source}_TO_{target}"), id, &[arg], span)
}

/// Checks `A_TO_B` (see `Gen::conversion`); `None` when `name` is no conversion.
fn conversion(g: &mut Gen, name: &str, id: &Ident, exprs: &[&Expr], span: Span) -> Option<Type> {
    let (from, to) = name.split_once("_TO_")?;
    let (Some(ft), Some(tt)) = (Gen::conversion_type(from), Gen::conversion_type(to)) else {
        return None;
    };
    let &[arg] = exprs else {
        let msg = format!("{} takes 1 argument, {} given", id.text, exprs.len());
        g.error(codes::ARGUMENT_COUNT, span, msg);
        for e in exprs {
            surface(g, e);
        }
        return Some(Type::Error);
    };
    match (&ft, &tt) {
        (Type::String(_), Type::String(_)) => {
            string_arg_of(g, arg, false);
            Some(Type::String(DEFAULT_STRING_LEN))
        }
        (Type::WString(_), Type::WString(_)) => {
            string_arg_of(g, arg, true);
            Some(Type::WString(DEFAULT_STRING_LEN))
        }
        (Type::String(_), Type::WString(_)) => {
            let len = g.string_len_of(arg);
            string_arg_of(g, arg, false);
            Some(Type::WString(len))
        }
        (Type::WString(_), Type::String(_)) => {
            // Up to three UTF-8 bytes a unit.
            let len = (g.string_len_of(arg) * 3).min(MAX_TEMP_STRING);
            string_arg_of(g, arg, true);
            Some(Type::String(len))
        }
        (Type::WString(_), Type::Elem(Elem::WChar)) => {
            string_arg_of(g, arg, true);
            Some(tt)
        }
        (Type::Elem(Elem::WChar), Type::WString(_)) => {
            value_to(g, arg, &ft);
            Some(Type::WString(1))
        }
        // Other WSTRING conversions go through STRING.
        (Type::WString(_), Type::Elem(_)) => {
            g.string_len_of(arg);
            string_arg_of(g, arg, true);
            Some(tt)
        }
        (Type::Elem(_), Type::WString(_)) => {
            let text = conversion(g, &format!("{from}_TO_STRING"), id, exprs, span)?;
            Some(if text.is_error() {
                text
            } else {
                Type::WString(40)
            })
        }
        (Type::String(_), Type::Elem(_)) => {
            string_arg_of(g, arg, false);
            Some(tt)
        }
        (Type::Elem(f), Type::String(_)) => {
            value_to(g, arg, &ft);
            Some(Type::String(if f.is_char() { 1 } else { 40 }))
        }
        (Type::Elem(f), Type::Elem(t)) => {
            let Some(route) = conversion_argument(g, id, (*f, *t), exprs) else {
                return Some(Type::Error);
            };
            match route {
                ConversionArgument::Implicit => value_to(g, arg, &ft),
                ConversionArgument::FromNumber => {
                    let at = g.infer(arg);
                    value_to_any(g, arg, &at, &ft);
                }
            }
            Some(tt)
        }
        _ => None,
    }
}

/// How the argument `exprs[0]` of the conversion `id` from `from` to `to` reaches `from`
/// ([`rules::conversion_exists`], [`rules::conversion_argument`]): reports a conversion
/// that does not exist or an argument that does not fit, and records it
/// ([`crate::typed::ConversionArguments`]). `None`: the call is in error.
fn conversion_argument(
    g: &mut Gen,
    id: &Ident,
    (from, to): (Elem, Elem),
    exprs: &[&Expr],
) -> Option<ConversionArgument> {
    if !rules::conversion_exists(from, to) {
        let msg = format!("there is no conversion from {from} to {to}");
        g.error(codes::NO_CONVERSION, id.span, msg);
        for e in exprs {
            g.infer(e);
        }
        return None;
    }
    let arg = exprs[0];
    let at = g.infer(arg);
    if at.is_error() {
        surface(g, arg);
        return None;
    }
    let Some(route) = rules::conversion_argument(from, operand(arg, &at)) else {
        let msg = format!(
            "{} expects a {} argument, found {}",
            id.text,
            from,
            g.tname(&at)
        );
        g.error(codes::TYPE_MISMATCH, arg.span, msg);
        return None;
    };
    if !g.dry || g.conversion_arguments.of(g.cur, id).is_none() {
        g.conversion_arguments.record(g.cur, id, route);
    }
    Some(route)
}

// ----- dates and times, SIZEOF ---------------------------------------------------------------

/// Checks a date and time function (see [`TimeFunction`]).
fn std_time(
    g: &mut Gen,
    f: TimeFunction,
    id: &Ident,
    args: &[Arg],
    expected: Option<&Type>,
    span: Span,
) -> Type {
    if let TimeFunction::Split(t) = f {
        return std_split(g, t, id, args, span);
    }
    check_no_outputs(g, id, args);
    let Some(exprs) = std_arguments(g, &id.name, id, args) else {
        return Type::Error;
    };
    let c = StdArgs::new((&id.name, None), id, exprs, None, span);
    match f {
        TimeFunction::Operator(op, ta, tb) => {
            if !arity(g, &c, 2) || !time_operands_fit(g, &c, [ta, tb]) {
                return Type::Error;
            }
            binary(g, op, c.exprs[0], c.exprs[1], expected, span)
        }
        TimeFunction::DateTod(result) => {
            if !arity(g, &c, 2) {
                return Type::Error;
            }
            let (date, tod) = Gen::date_and_time_of(result);
            value_to(g, c.exprs[0], &Type::Elem(date));
            value_to(g, c.exprs[1], &Type::Elem(tod));
            Type::Elem(result)
        }
        TimeFunction::Concat(result) => {
            let (date_parts, tod_parts) = Gen::concat_parts(result);
            if !arity(g, &c, date_parts + tod_parts) {
                return Type::Error;
            }
            for e in &c.exprs {
                int_arg(g, e);
            }
            Type::Elem(result)
        }
        TimeFunction::DayOfWeek => {
            if !arity(g, &c, 1) {
                return Type::Error;
            }
            let t = g.infer(c.exprs[0]);
            if !rules::is_date(&t) {
                return bad_inferred_arg(g, c.exprs[0], &t, "a DATE");
            }
            check(g, c.exprs[0], None);
            Type::INT
        }
        TimeFunction::Split(_) => unreachable!("handled above"),
    }
}

/// Whether the two arguments of the date and time operator `c` fit the operands `want`
/// ([`rules::time_operand_fits`]); reports the first that does not.
fn time_operands_fit(g: &mut Gen, c: &StdArgs, want: [Elem; 2]) -> bool {
    let types: Vec<Type> = c.exprs.iter().map(|e| g.infer(e)).collect();
    if types.iter().any(Type::is_error) {
        for (e, _) in c.exprs.iter().zip(&types).filter(|(_, t)| t.is_error()) {
            surface(g, e);
        }
        return false;
    }
    for ((e, t), want) in c.exprs.iter().zip(&types).zip(want) {
        if !rules::time_operand_fits(want, operand(e, t)) {
            let what = if want == Elem::LReal {
                "a number".to_string()
            } else {
                format!("a {want}")
            };
            bad_arg(g, e, t, &what);
            return false;
        }
    }
    true
}

/// Checks SIZEOF(variable or type).
fn std_sizeof(g: &mut Gen, id: &Ident, args: &[Arg], expected: Option<&Type>, span: Span) -> Type {
    let [arg] = args else {
        let msg = format!("{} takes 1 argument, {} given", id.text, args.len());
        g.error(codes::ARGUMENT_COUNT, span, msg);
        return Type::Error;
    };
    let ty = g.sizeof_operand(&arg.value);
    if ty.is_error() {
        // Report why (the dry inference reported nothing).
        check(g, &arg.value, None);
        return Type::Error;
    }
    Type::Elem(g.sizeof_value(&ty, expected).1)
}

/// Checks SPLIT_DATE, SPLIT_TOD, SPLIT_DT (`input_type` is the type they split): an input
/// of that type, known outputs whose targets are writable integers.
fn std_split(g: &mut Gen, input_type: Elem, id: &Ident, args: &[Arg], span: Span) -> Type {
    let parts = Gen::split_parts(input_type);
    let (input, targets, misfits) = split_arguments(&parts, args);
    for a in misfits {
        match &a.name {
            Some(n) if a.output => {
                let msg = format!(
                    "{} has no output `{}` (its outputs: {})",
                    id.text,
                    n.text,
                    parts.join(", ")
                );
                g.error(codes::UNKNOWN_PARAMETER, n.span, msg);
            }
            _ => {
                let msg = format!("{} takes IN and the outputs {}", id.text, parts.join(", "));
                g.error(codes::UNKNOWN_PARAMETER, a.span, msg);
            }
        }
    }
    let family = input_type.temporal_family();
    let input_type_ok = input.filter(|e| {
        g.infer(e)
            .value_elem()
            .is_some_and(|e| e.temporal_family() == family)
    });
    let Some(input) = input_type_ok else {
        match input {
            None => {
                let msg = format!("{} needs its input IN", id.text);
                g.error(codes::MISSING_ARGUMENT, span, msg);
            }
            Some(e) => {
                let t = g.infer(e);
                bad_inferred_arg(g, e, &t, &format!("a {input_type}"));
            }
        }
        // The outputs still say what is wrong with them.
        for target in targets.into_iter().flatten() {
            place(g, target);
        }
        return Type::Error;
    };
    check(g, input, None);
    for (part, target) in parts.iter().zip(targets) {
        let Some(target) = target else { continue };
        let Some(p) = place(g, target) else {
            continue;
        };
        if !p.ty.is_integral() {
            if !p.ty.is_error() {
                let msg = format!("the output {part} is an integer, not {}", g.tname(&p.ty));
                g.error(codes::OUTPUT_TARGET, target.span, msg);
            }
            continue;
        }
        check_output_writable(g, &p, target);
    }
    Type::Void
}

// ----- numeric, selection, bits ---------------------------------------------------------------

/// Checks a numeric function: SQRT and the other REAL functions, EXPT, ABS, TRUNC, __NOW.
fn std_numeric(g: &mut Gen, c: &StdArgs) -> Option<Type> {
    let t = match c.name {
        "SQRT" | "LN" | "LOG" | "EXP" | "SIN" | "COS" | "TAN" | "ASIN" | "ACOS" | "ATAN" => {
            if !arity(g, c, 1) {
                return Some(Type::Error);
            }
            match real_operand(g, c) {
                Some(t) => Type::Elem(t),
                None => return Some(Type::Error),
            }
        }
        "EXPT" | "ATAN2" => {
            if !arity(g, c, 2) {
                return Some(Type::Error);
            }
            let Some(rt) = real_operand(g, c) else {
                return Some(Type::Error);
            };
            let t1 = g.infer(c.exprs[1]);
            if !t1.elem().is_some_and(|e| e.is_numeric()) || matches!(t1, Type::Enum(_)) {
                return Some(bad_inferred_arg(g, c.exprs[1], &t1, "a number"));
            }
            value_to_any(g, c.exprs[1], &t1, &Type::Elem(rt));
            Type::Elem(rt)
        }
        "ABS" => {
            if !arity(g, c, 1) {
                return Some(Type::Error);
            }
            let t = match c.typed {
                Some(forced) => {
                    value_to(g, c.exprs[0], &Type::Elem(forced));
                    Type::Elem(forced)
                }
                None => check(g, c.exprs[0], c.ctx.as_ref()),
            };
            let Some(e) = argument_type(g, c, &t, rules::abs_type, "a number") else {
                return Some(Type::Error);
            };
            Type::Elem(e)
        }
        name if name == "TRUNC" || Gen::typed_trunc(name).is_some() => {
            if !arity(g, c, 1) {
                return Some(Type::Error);
            }
            let (from, target) = Gen::trunc_types(c);
            match from {
                Some(f) => {
                    let t = g.infer(c.exprs[0]);
                    if !(t.elem().is_some_and(|e| implicit_ok(e, f)) || is_flexible(c.exprs[0])) {
                        return Some(bad_inferred_arg(g, c.exprs[0], &t, &format!("a {f}")));
                    }
                    value_to(g, c.exprs[0], &Type::Elem(f));
                }
                None => {
                    if real_operand(g, c).is_none() {
                        return Some(Type::Error);
                    }
                }
            }
            Type::Elem(target)
        }
        "__NOW" | "TIME" | "LTIME" => {
            if !arity(g, c, 0) {
                return Some(Type::Error);
            }
            Gen::clock_type(c.name)
        }
        _ => unreachable!("std_numeric called for {}", c.name),
    };
    Some(t)
}

/// The type the REAL function call `c` computes in, its (first) argument checked in it:
/// the typed form's (`SQRT_LREAL`), else as [`rules::real_function_type`] decides, which is
/// recorded ([`crate::typed::GenericTypes`]).
fn real_operand(g: &mut Gen, c: &StdArgs) -> Option<Elem> {
    let e = c.exprs[0];
    if let Some(forced) = c.typed.filter(|t| t.is_real()) {
        value_to(g, e, &Type::Elem(forced));
        return Some(forced);
    }
    let t = g.infer(e);
    let real_context = c.ctx.as_ref().and_then(|c| c.elem()) == Some(Elem::Real);
    let Some(target) = rules::real_function_type(operand(e, &t), real_context) else {
        bad_inferred_arg(g, e, &t, "a number");
        return None;
    };
    record_generic_type(g, c.id, Type::Elem(target));
    value_to_any(g, e, &t, &Type::Elem(target));
    Some(target)
}

/// The type the call `c` computes in for its first argument of type `t` (checked), as
/// `rule` decides it (reporting an argument that is not `what`); recorded.
fn argument_type(
    g: &mut Gen,
    c: &StdArgs,
    t: &Type,
    rule: fn(&Type) -> Option<Elem>,
    what: &str,
) -> Option<Elem> {
    let Some(e) = rule(t) else {
        bad_arg(g, c.exprs[0], t, what);
        return None;
    };
    record_generic_type(g, c.id, Type::Elem(e));
    Some(e)
}

/// Checks a selection: MOVE, SEL, MAX/MIN, LIMIT, MUX.
fn std_selection(g: &mut Gen, c: &StdArgs) -> Option<Type> {
    let t = match c.name {
        "MOVE" => {
            if !arity(g, c, 1) {
                return Some(Type::Error);
            }
            match c.typed {
                Some(forced) => {
                    value_to(g, c.exprs[0], &Type::Elem(forced));
                    Type::Elem(forced)
                }
                None => check(g, c.exprs[0], None),
            }
        }
        "SEL" => {
            if !arity(g, c, 3) {
                return Some(Type::Error);
            }
            value_to(g, c.exprs[0], &Type::BOOL);
            let t = selection_type(g, c, 1);
            if t.is_error() {
                return Some(t);
            }
            selection_arguments(g, &c.exprs[1..], &t);
            t
        }
        "MAX" | "MIN" => {
            if c.exprs.len() < 2 {
                let msg = format!("{} needs at least 2 arguments", c.id.text);
                g.error(codes::ARGUMENT_COUNT, c.span, msg);
                c.exprs.iter().for_each(|e| surface(g, e));
                return Some(Type::Error);
            }
            let t = selection_type(g, c, 0);
            if t.elem().is_none() {
                if !t.is_error() {
                    let msg = format!(
                        "{} needs numeric, TIME or enumeration arguments, found {}",
                        c.id.text,
                        g.tname(&t)
                    );
                    g.error(codes::INCOMPATIBLE_ARGUMENTS, c.span, msg);
                }
                return Some(Type::Error);
            }
            selection_arguments(g, &c.exprs, &t);
            t
        }
        "LIMIT" => {
            if !arity(g, c, 3) {
                return Some(Type::Error);
            }
            let t = selection_type(g, c, 0);
            if t.elem().is_none() {
                return Some(Type::Error);
            }
            // In the order emission evaluates them: IN, MN, MX.
            let order = [c.exprs[1], c.exprs[0], c.exprs[2]];
            selection_arguments(g, &order, &t);
            t
        }
        "MUX" => {
            if c.exprs.len() < 2 {
                let msg = "MUX needs a selector and at least one input";
                g.error(codes::ARGUMENT_COUNT, c.span, msg);
                c.exprs.iter().for_each(|e| surface(g, e));
                return Some(Type::Error);
            }
            let kt = check(g, c.exprs[0], Some(&Type::DINT));
            if !kt.elem().is_some_and(|e| e.is_integral()) && !kt.is_error() {
                return Some(bad_arg(g, c.exprs[0], &kt, "an integer selector"));
            }
            let t = selection_type(g, c, 1);
            selection_arguments(g, &c.exprs[1..], &t);
            t
        }
        _ => unreachable!("std_selection called for {}", c.name),
    };
    Some(t)
}

/// Checks each of `exprs` brought to the type `t` a selection is called at.
fn selection_arguments(g: &mut Gen, exprs: &[&Expr], t: &Type) {
    for e in exprs {
        let et = g.infer(e);
        value_to_any(g, e, &et, t);
    }
}

/// The type a selection function is called at: the typed form's, else the common type of
/// its arguments from the `from`th ([`common_of`]), which is recorded
/// ([`crate::typed::GenericTypes`]).
fn selection_type(g: &mut Gen, c: &StdArgs, from: usize) -> Type {
    if let Some(forced) = c.typed {
        return Type::Elem(forced);
    }
    let t = common_of(g, &c.exprs[from..], c.ctx.as_ref());
    record_generic_type(g, c.id, t.clone());
    t
}

/// The common type of several arguments (of SEL, MAX, MIN, LIMIT, MUX), `ctx` being the
/// type the context asks of untyped literals.
fn common_of(g: &mut Gen, exprs: &[&Expr], ctx: Option<&Type>) -> Type {
    let mut acc: Option<Type> = None;
    for e in exprs {
        if is_flexible(e) {
            continue;
        }
        let t = g.infer(e);
        if t.is_error() {
            surface(g, e);
            return Type::Error;
        }
        let common = match acc {
            None => Some(t.clone()),
            Some(ref a) if *a == t => Some(t.clone()),
            Some(ref a) => match (a.elem(), t.elem()) {
                (Some(x), Some(y))
                    if !matches!(a, Type::Enum(_)) && !matches!(t, Type::Enum(_)) =>
                {
                    common_numeric(x, y).map(Type::Elem)
                }
                _ if a.is_string() && t.is_string() || a.is_wstring() && t.is_wstring() => {
                    Some(a.clone())
                }
                _ => None,
            },
        };
        let Some(common) = common else {
            let a = acc.unwrap_or(Type::Error);
            let msg = format!(
                "arguments of incompatible types {} and {}",
                g.tname(&a),
                g.tname(&t)
            );
            g.error(codes::INCOMPATIBLE_ARGUMENTS, e.span, msg);
            return Type::Error;
        };
        acc = Some(common);
    }
    match acc {
        Some(Type::Subrange(e, ..)) => Type::Elem(e),
        Some(t) => {
            if exprs.iter().any(|e| is_flexible(e) && has_real_literal(e))
                && !t.elem().is_some_and(|x| x.is_real())
            {
                Type::LREAL
            } else {
                t
            }
        }
        None => {
            if let Some(c) = ctx.filter(|c| {
                !exprs.iter().any(|e| has_real_literal(e)) || c.elem().is_some_and(|x| x.is_real())
            }) {
                c.clone()
            } else if exprs.iter().any(|e| has_real_literal(e)) {
                Type::LREAL
            } else {
                Type::DINT
            }
        }
    }
}

/// Checks a bit shift or rotation: SHL, SHR, ROL, ROR.
fn std_bits(g: &mut Gen, c: &StdArgs) -> Option<Type> {
    if !arity(g, c, 2) {
        return Some(Type::Error);
    }
    let t = check(g, c.exprs[0], None);
    let what = "a bit string or integer";
    let Some(e) = argument_type(g, c, &t, rules::shift_type, what) else {
        return Some(Type::Error);
    };
    // The count may be of any integer type (IEC: ANY_INT).
    int_arg(g, c.exprs[1]);
    Some(Type::Elem(e))
}

// ----- strings --------------------------------------------------------------------------------

/// Checks a string function: LEN, LEFT/RIGHT, MID/DELETE, INSERT, REPLACE, FIND, CONCAT,
/// on STRINGs or on WSTRINGs (the first string argument decides; STRING literals adapt).
fn std_string(g: &mut Gen, c: &StdArgs) -> Option<Type> {
    let first = c.exprs.iter().find(|e| !matches!(e.kind, ExprKind::Str(_)));
    let first = first.map(|e| g.infer(e));
    let kind = rules::string_kind(first.as_ref());
    record_generic_type(g, c.id, kind.clone());
    let wide = kind.is_wstring();
    let (strings, integers, count) = match c.name {
        "LEN" => (1, 0, 1),
        "LEFT" | "RIGHT" => (1, 1, 2),
        "MID" | "DELETE" => (1, 2, 3),
        "INSERT" => (2, 1, 3),
        "REPLACE" => (2, 2, 4),
        "FIND" => (2, 0, 2),
        "CONCAT" => {
            if c.exprs.is_empty() {
                g.error(codes::ARGUMENT_COUNT, c.span, "CONCAT needs arguments");
                return Some(Type::Error);
            }
            (c.exprs.len(), 0, c.exprs.len())
        }
        _ => unreachable!("std_string called for {}", c.name),
    };
    if !arity(g, c, count) {
        return Some(Type::Error);
    }
    let result = g.string_result(c, wide);
    for e in &c.exprs[..strings] {
        string_arg_of(g, e, wide);
    }
    for e in &c.exprs[strings..strings + integers] {
        int_arg(g, e);
    }
    Some(result)
}

/// Checks a STRING (or, `wide`, a WSTRING; a STRING literal then is one) argument.
fn string_arg_of(g: &mut Gen, e: &Expr, wide: bool) {
    let want = if wide {
        Type::WString(DEFAULT_STRING_LEN)
    } else {
        Type::String(DEFAULT_STRING_LEN)
    };
    let t = check(g, e, Some(&want));
    let fits = if wide { t.is_wstring() } else { t.is_string() };
    if !fits && !t.is_error() {
        let msg = format!(
            "expected a {}, found {}",
            if wide { "WSTRING" } else { "STRING" },
            g.tname(&t)
        );
        g.error(codes::TYPE_MISMATCH, e.span, msg);
    }
}

/// Checks an integer argument (of any integer type).
fn int_arg(g: &mut Gen, e: &Expr) {
    let t = g.infer(e);
    if !t.is_integral() {
        if !t.is_error() {
            let msg = format!("expected an integer, found {}", g.tname(&t));
            g.error(codes::TYPE_MISMATCH, e.span, msg);
        }
        check(g, e, None);
        return;
    }
    value_to_any(g, e, &t, &Type::LINT);
}
