//! The expression checker: the checking pass's walk of an expression, before anything is
//! emitted.
//!
//! It owns the rules of literals (an integer or a character fits the type its context asks
//! for; a typed literal is valid for its type), of bare names (what a name denotes: a
//! variable, a property of the class whose body it is in, an enumeration value, an
//! exception) and of the operators (the type both operands are brought to, and what the
//! operator does by the rules of [`sema::ops`](crate::sema::ops)); it reports what breaks
//! them and records what it decides for emission ([`crate::typed`]). The rest of an
//! expression (variables, members, indices, dereferences, partial accesses, THIS and SUPER,
//! calls, the implicit conversion of a value) is still checked by the code generator's walk
//! in its checking mode ([`Gen`] with `check_only`), which this walk calls for those and
//! which calls back into this walk ([`Gen::expr`]) for every subexpression.
//!
//! The checking pass walks an expression once more with diagnostics off (`Gen::dry`) to
//! infer its type ([`Gen::infer`]); such a walk records only what no real walk has, as the
//! type its context expects may differ.

use crate::ast::{BinOp, Expr, ExprKind, Ident, UnOp};
use crate::codegen::Gen;
use crate::codes::{self, Code};
use crate::diagnostics::Span;
use crate::sema::ops::{self, BinaryRule, Operand, Operation, OperatorError};
use crate::sema::place::{place, this_class};
use crate::sema::{ConstVal, Program, const_eval, single_char};
use crate::typed::Bare;
use crate::types::{Elem, Implicit, NotImplicit, Type, common_numeric, implicit_conversion};
use plc_vm::isa::Trap;

/// Checks `e`, `expected` being the type its context asks for (it types untyped literals);
/// returns its type (the error type after a reported error).
pub(crate) fn check(g: &mut Gen, e: &Expr, expected: Option<&Type>) -> Type {
    match &e.kind {
        ExprKind::Error => Type::Error,
        ExprKind::Int(v) => int_literal(g, *v as i128, expected, e.span),
        ExprKind::Real(_) => Type::Elem(real_literal_type(expected)),
        ExprKind::Bool(_) => Type::BOOL,
        ExprKind::Time(_) => Type::TIME,
        ExprKind::Temporal(elem, _) => Type::Elem(*elem),
        ExprKind::Str(s) if let Some(elem) = char_literal_type(s, expected) => {
            let code = single_char(s).unwrap_or(0);
            if code > elem.int_range().1 {
                let msg = format!("character '{s}' does not fit type {elem}");
                g.error(codes::VALUE_OUT_OF_RANGE, e.span, msg);
            }
            Type::Elem(elem)
        }
        ExprKind::WStr(s) => wstring_literal_type(s),
        ExprKind::Str(s) if matches!(expected, Some(Type::WString(_))) => wstring_literal_type(s),
        ExprKind::Str(s) => string_literal_type(s),
        ExprKind::Typed(ty, inner) => typed_literal(g, ty, inner, e.span),
        ExprKind::Name(n) => bare_name(g, e, n, expected),
        ExprKind::Null => Type::Null,
        ExprKind::Unary(op, x) => unary(g, *op, x, expected, e.span),
        ExprKind::Binary(op, a, b) => binary(g, *op, a, b, expected, e.span),
        ExprKind::This | ExprKind::Super => {
            let superclass = matches!(e.kind, ExprKind::Super);
            match this_class(g, superclass, e.span) {
                Some(class) => Type::Ref(Box::new(Type::Fb(class))),
                None => Type::Error,
            }
        }
        ExprKind::Member(..) if let Some(t) = crate::sema::class::property_read(g, e) => t,
        ExprKind::Member(..)
        | ExprKind::Index(..)
        | ExprKind::Deref(..)
        | ExprKind::Bits { .. } => place(g, e).map_or(Type::Error, |p| p.ty),
        ExprKind::Call { callee, args } => {
            crate::sema::call::call(g, callee, args, expected, e.span)
        }
    }
}

/// The type of `e` where nothing is expected of it, from a walk that reports nothing; it is
/// recorded for emission ([`crate::typed::ExprTypes`]), once.
pub(crate) fn infer(g: &mut Gen, e: &Expr) -> Type {
    if let Some(t) = g.types.of(e) {
        return t.clone();
    }
    let saved = g.dry;
    g.dry = true;
    let t = check(g, e, None);
    g.dry = saved;
    g.types.record(e, t.clone());
    t
}

// ----- literals -----------------------------------------------------------------------------

/// The type an integer literal of value `v` takes where `expected` is wanted: BOOL for 0
/// and 1, a REAL, an integer it must fit; else DINT, LINT or ULINT by its size. `Err` says
/// why it cannot stand there.
pub(crate) fn int_literal_type(v: i128, expected: Option<&Type>) -> Result<Elem, (Code, String)> {
    let expected_elem = expected.and_then(|t| match t {
        Type::Enum(_) | Type::Exception => None,
        t => t.elem(),
    });
    match expected_elem {
        // IEC boolean literals include 0 and 1.
        Some(Elem::Bool) if v == 0 || v == 1 => Ok(Elem::Bool),
        Some(e) if e.is_real() => Ok(e),
        Some(e) if e.is_integral() => {
            let (lo, hi) = e.int_range();
            if v < lo || v > hi {
                let msg = format!("constant {v} does not fit type {e}");
                return Err((codes::VALUE_OUT_OF_RANGE, msg));
            }
            Ok(e)
        }
        _ if v > u64::MAX as i128 || v < i64::MIN as i128 => Err((
            codes::INTEGER_TOO_LARGE,
            "integer constant too large".to_string(),
        )),
        _ if v >= i32::MIN as i128 && v <= i32::MAX as i128 => Ok(Elem::DInt),
        _ if v <= i64::MAX as i128 => Ok(Elem::LInt),
        _ => Ok(Elem::ULInt),
    }
}

fn int_literal(g: &mut Gen, v: i128, expected: Option<&Type>, span: Span) -> Type {
    match int_literal_type(v, expected) {
        Ok(elem) => Type::Elem(elem),
        Err((code, msg)) => {
            g.error(code, span, msg);
            Type::Error
        }
    }
}

/// The type of a real literal where `expected` is wanted: REAL in a REAL context, else LREAL.
pub(crate) fn real_literal_type(expected: Option<&Type>) -> Elem {
    if expected.and_then(|t| t.elem()) == Some(Elem::Real) {
        Elem::Real
    } else {
        Elem::LReal
    }
}

/// The character type a one-character string literal `s` is where `expected` is a CHAR or
/// a WCHAR; `None` where it is a string.
pub(crate) fn char_literal_type(s: &str, expected: Option<&Type>) -> Option<Elem> {
    let elem = expected.and_then(|t| t.elem())?;
    let char_expected = elem.is_char() && !matches!(expected, Some(Type::Enum(_)));
    (char_expected && single_char(s).is_some()).then_some(elem)
}

/// The type of STRING literal `s`.
pub(crate) fn string_literal_type(s: &str) -> Type {
    Type::String(s.len().max(1) as u32)
}

/// The type of WSTRING literal `s` (or of a STRING literal where a WSTRING is expected).
pub(crate) fn wstring_literal_type(s: &str) -> Type {
    Type::WString(s.encode_utf16().count().max(1) as u32)
}

/// The value of the typed literal `elem#inner` (a BOOL value of a non-BOOL type counts as
/// 0 or 1); `None` when `inner` is no constant.
pub(crate) fn typed_literal_value(prog: &Program, elem: Elem, inner: &Expr) -> Option<ConstVal> {
    match (const_eval(prog, &(), inner)?, elem) {
        (ConstVal::Bool(b), e) if e != Elem::Bool => Some(ConstVal::Int(b as i128)),
        (v, _) => Some(v),
    }
}

/// Checks the typed literal `ty#inner`: an elementary type's value must fit it, a
/// `STRING#` literal is its string, an enumeration's value must be one of its values (what
/// it is is recorded, [`Bare::EnumValue`]).
fn typed_literal(g: &mut Gen, ty: &Ident, inner: &Expr, span: Span) -> Type {
    if let Some(elem) = Elem::from_name(&ty.name) {
        let t = Type::Elem(elem);
        let Some(v) = typed_literal_value(g.prog, elem, inner) else {
            let msg = format!("invalid {elem} literal");
            g.error(codes::MALFORMED_LITERAL, inner.span, msg);
            return Type::Error;
        };
        if g.dry {
            return t;
        }
        return match crate::sema::init::const_cell(g, &v, &t, elem, span) {
            Some(_) => t,
            None => Type::Error,
        };
    }
    if ty.name == "STRING" {
        return check(g, inner, None);
    }
    if let (Some((Type::Enum(ei), _)), ExprKind::Name(n)) =
        (g.prog.aliases.get(&ty.name).cloned(), &inner.kind)
    {
        let found = g.prog.enums[ei].values.iter().find(|(vn, _)| *vn == n.name);
        if let Some(&(_, value)) = found {
            g.bare_names
                .record(g.cur, n, Bare::EnumValue { ty: ei, value });
            return Type::Enum(ei);
        }
        let msg = format!("`{}` is not a value of {}", n.text, ty.text);
        g.error(codes::UNKNOWN_ENUMERATION_VALUE, n.span, msg);
        return Type::Error;
    }
    let msg = format!("unknown type `{}` in typed literal", ty.text);
    g.error(codes::UNKNOWN_TYPE, ty.span, msg);
    Type::Error
}

// ----- names --------------------------------------------------------------------------------

/// Checks the bare name `n` (the expression `e`): decides what it denotes and records it.
fn bare_name(g: &mut Gen, e: &Expr, n: &Ident, expected: Option<&Type>) -> Type {
    let bare = resolve_bare(g, n, expected);
    if !g.dry || g.bare_names.of(g.cur, n).is_none() {
        g.bare_names.record(g.cur, n, bare.clone());
    }
    match bare {
        Bare::Property { class, getter } => {
            crate::sema::class::own_property_read(g, class, getter, e)
        }
        Bare::EnumValue { ty, .. } => Type::Enum(ty),
        Bare::Exception(_) => Type::Exception,
        Bare::Variable => {
            sync_if_byte_viewed(g, e);
            place(g, e).map_or(Type::Error, |p| p.ty)
        }
    }
}

/// Checks the place of the STRING variable `e` names when its text is reached through byte
/// pointers (emission re-reads its length before the read): the variable is recorded.
pub(crate) fn sync_if_byte_viewed(g: &mut Gen, e: &Expr) {
    let ExprKind::Name(n) = &e.kind else { return };
    if g.dry || !g.refs.byte_viewed.contains(&n.name) {
        return;
    }
    sync_records(g, n);
}

/// Records the variable `n` (a STRING reached through byte pointers) the way emission
/// re-reads its length: a place of its own, with no further re-reading inside.
pub(crate) fn sync_records(g: &mut Gen, n: &Ident) {
    let saved = std::mem::take(&mut g.refs.byte_viewed);
    let name = Expr {
        kind: ExprKind::Name(n.clone()),
        span: n.span,
    };
    place(g, &name);
    g.refs.byte_viewed = saved;
}

/// What bare name `n` denotes in the POU walked, `expected` being the type its context
/// expects: variables shadow properties, properties shadow enumeration values (of the
/// expected enumeration first) and exception names; an unknown name is taken as a
/// variable (and reported as unknown where it is looked up).
fn resolve_bare(g: &Gen, n: &Ident, expected: Option<&Type>) -> Bare {
    if g.is_visible_var(&n.name) {
        return Bare::Variable;
    }
    if let Some(property) = g.own_property(n) {
        return property;
    }
    if let Some(Type::Enum(ei)) = expected
        && let Some((_, v)) = g.prog.enums[*ei]
            .values
            .iter()
            .find(|(vn, _)| *vn == n.name)
    {
        return Bare::EnumValue { ty: *ei, value: *v };
    }
    if let Some((ty, value)) = g.prog.enum_value(&n.name) {
        return Bare::EnumValue { ty, value };
    }
    if let Some(t) = Trap::ALL.iter().find(|t| t.name() == n.name) {
        return Bare::Exception(t.code() as i64);
    }
    Bare::Variable
}

// ----- operators ----------------------------------------------------------------------------

/// Checks `op x`: decides what it does ([`ops::unary_rule`]) and records it.
fn unary(g: &mut Gen, op: UnOp, x: &Expr, expected: Option<&Type>, span: Span) -> Type {
    // Negative literals are folded so that e.g. INT's -32768 is accepted.
    if op == UnOp::Neg {
        if let ExprKind::Int(v) = x.kind {
            return int_literal(g, -(v as i128), expected, span);
        }
        if let ExprKind::Real(_) = x.kind {
            return check(g, x, expected);
        }
    }
    let t = check(g, x, expected);
    if t.is_error() {
        return Type::Error;
    }
    let symbol = if op == UnOp::Neg { "-" } else { "NOT" };
    let decided = ops::unary_rule(op, &t).map(Operation::Unary);
    match record_operation(g, x, decided, symbol, span) {
        Some(Operation::Unary(rule)) => Type::Elem(rule.result()),
        _ => Type::Error,
    }
}

/// Checks `a op b`: brings the operands to their types ([`operand_types`]), decides what
/// the operator does ([`ops::binary_rule`]), records it and checks each operand where the
/// rule computes it. An operation on references or addresses is checked by the code
/// generator's walk (`Gen::pointer_binary`).
pub(crate) fn binary(
    g: &mut Gen,
    op: BinOp,
    a: &Expr,
    b: &Expr,
    expected: Option<&Type>,
    span: Span,
) -> Type {
    if g.is_pointer_operation(a, b) {
        return crate::sema::refs::pointer_binary(g, op, a, b, expected, span);
    }
    let (ta, tb) = operand_types(g, a, b, expected);
    if ta.is_error() || tb.is_error() {
        check(g, a, None);
        check(g, b, None);
        return Type::Error;
    }
    let decided = ops::binary_rule(op, operand(a, &ta), operand(b, &tb));
    let Some(Operation::Binary(rule)) =
        record_operation(g, a, decided.map(Operation::Binary), op.symbol(), span)
    else {
        return Type::Error;
    };
    match &rule {
        BinaryRule::StringCompare { wide } => {
            let w = Type::WString(crate::types::DEFAULT_STRING_LEN);
            check(g, a, wide.then_some(&w));
            check(g, b, wide.then_some(&w));
        }
        BinaryRule::Compare => {
            check(g, a, Some(&ta));
            check(g, b, Some(&tb));
        }
        // The operands keep their nanoseconds (TIME widens to LTIME implicitly).
        BinaryRule::Temporal { .. } => {
            check(g, a, Some(&ta));
            check(g, b, Some(&tb));
        }
        BinaryRule::Scale {
            duration_first,
            number,
            ..
        } => {
            let (duration, factor) = if *duration_first { (a, b) } else { (b, a) };
            let duration_type = rule.result();
            check(g, duration, Some(&duration_type));
            let computed_in = if number.elem().is_some_and(|e| e.is_real()) {
                Type::LREAL
            } else {
                Type::LINT
            };
            check(
                g,
                factor,
                Some(operand_context(factor, number, &computed_in)),
            );
        }
        BinaryRule::Logic(t) | BinaryRule::NumericCompare(t) | BinaryRule::Arithmetic(t) => {
            let computed_in = Type::Elem(*t);
            check(g, a, Some(operand_context(a, &ta, &computed_in)));
            check(g, b, Some(operand_context(b, &tb, &computed_in)));
        }
        BinaryRule::IntegerPower(_) => {
            check(g, a, Some(operand_context(a, &ta, &Type::LREAL)));
            check(g, b, Some(operand_context(b, &tb, &Type::LREAL)));
        }
    }
    rule.result()
}

/// Records the decision on the operation whose first operand is `first`, or reports why
/// the operator `symbol` is refused.
fn record_operation(
    g: &mut Gen,
    first: &Expr,
    decided: Result<Operation, OperatorError>,
    symbol: &str,
    span: Span,
) -> Option<Operation> {
    let (code, msg) = match decided {
        Ok(operation) => {
            if !g.dry || g.operations.of(first).is_none() {
                g.operations.record(first, operation.clone());
            }
            return Some(operation);
        }
        Err(OperatorError::CharacterIsNoNumber) => (
            codes::CHARACTER_IS_NO_NUMBER,
            "a character is no number: compare it with a character (CHAR#'a') or convert it (CHAR_TO_BYTE)".to_string(),
        ),
        Err(OperatorError::Types { a, b, hint }) => {
            let (a, b) = (g.tname(&a), g.tname(&b));
            let msg = format!("operator {symbol} cannot be applied to {a} and {b}{hint}");
            (codes::OPERATOR_TYPES, msg)
        }
        Err(OperatorError::Operand(t)) => {
            let msg = format!("operator {symbol} cannot be applied to {}", g.tname(&t));
            (codes::OPERATOR_TYPES, msg)
        }
    };
    g.error(code, span, msg);
    None
}

/// Checks the operand `e` of type `from` where a value computed in `to` is wanted (its
/// conversion was decided by the caller's rule).
pub(crate) fn value_to_any(g: &mut Gen, e: &Expr, from: &Type, to: &Type) {
    check(g, e, Some(operand_context(e, from, to)));
}

/// The type an operand `e` of type `from`, computed in `to`, is walked with: `to` when it
/// adapts to its context (an untyped literal), else its own.
pub(crate) fn operand_context<'t>(e: &Expr, from: &'t Type, to: &'t Type) -> &'t Type {
    if is_flexible(e) { to } else { from }
}

/// The types the operands of `a op b` are brought to: each its own, an untyped literal the
/// other's (or a wider one it fits), two untyped literals the numeric type `expected` asks
/// for, else DINT or LREAL.
pub(crate) fn operand_types(
    g: &mut Gen,
    a: &Expr,
    b: &Expr,
    expected: Option<&Type>,
) -> (Type, Type) {
    let (fa, fb) = (is_flexible(a), is_flexible(b));
    let ta = if fa { None } else { Some(g.infer(a)) };
    let tb = if fb { None } else { Some(g.infer(b)) };
    match (ta, tb) {
        (Some(x), Some(y)) => (x, y),
        (Some(x), None) => {
            let y = literal_operand_type(&x, b);
            (x, y)
        }
        (None, Some(y)) => {
            let x = literal_operand_type(&y, a);
            (x, y)
        }
        (None, None) => {
            let num = expected
                .and_then(|t| t.elem())
                .filter(|e| e.is_numeric() && !matches!(expected, Some(Type::Enum(_))));
            let any_real = has_real_literal(a) || has_real_literal(b);
            // Integer literals stay integers (5 / 2 = 2 even when assigned to a REAL);
            // real literals take a REAL context's precision.
            let t = match num {
                Some(e) if e.is_real() == any_real => Type::Elem(e),
                _ if any_real => Type::LREAL,
                _ => Type::DINT,
            };
            (t.clone(), t)
        }
    }
}

/// The type the untyped operand `e` takes beside an operand of type `other`: an integer
/// literal takes `other`, or a wider type when it does not fit it (`int_var * 60000` is a
/// DINT product, as the literal is a DINT); only a plain literal, as arithmetic of literals
/// keeps wrapping in the other operand's type.
fn literal_operand_type(other: &Type, e: &Expr) -> Type {
    if has_real_literal(e) {
        return match other.elem() {
            Some(x) if x.is_real() => other.clone(),
            _ => Type::LREAL,
        };
    }
    let value = match &e.kind {
        ExprKind::Int(v) => Some(*v as i128),
        ExprKind::Unary(UnOp::Neg, x) => match x.kind {
            ExprKind::Int(v) => Some(-(v as i128)),
            _ => None,
        },
        _ => None,
    };
    match (other, value) {
        (Type::Elem(x), Some(v)) if x.is_integral() => {
            let (lo, hi) = x.int_range();
            if lo <= v && v <= hi {
                return other.clone();
            }
            let literal = if i32::try_from(v).is_ok() {
                Elem::DInt
            } else {
                Elem::LInt
            };
            match common_numeric(*x, literal) {
                Some(c) if c.int_range().0 <= v && v <= c.int_range().1 => Type::Elem(c),
                _ => other.clone(),
            }
        }
        _ => other.clone(),
    }
}

/// The expression `e` of type `ty` as the rules of `sema` see an operand: its type and the
/// facts about its form they ask about.
pub(crate) fn operand<'t>(e: &Expr, ty: &'t Type) -> Operand<'t> {
    Operand {
        ty,
        flexible: is_flexible(e),
        string_literal: matches!(e.kind, ExprKind::Str(_)),
        real_literal: has_real_literal(e),
    }
}

/// Whether `e` is built only from untyped numeric literals (it adapts to its context).
pub(crate) fn is_flexible(e: &Expr) -> bool {
    match &e.kind {
        ExprKind::Int(_) | ExprKind::Real(_) => true,
        // TRUNC and SIZEOF give any integer type (IEC: ANY_INT), whatever their argument.
        ExprKind::Call { callee, .. } if matches!(&callee.kind, ExprKind::Name(n) if n.name == "TRUNC" || n.name == "SIZEOF") => {
            true
        }
        // Numeric standard functions of literals are as untyped as the literals.
        ExprKind::Call { callee, args } => match &callee.kind {
            ExprKind::Name(n) => {
                const GENERIC: &[&str] = &[
                    "ABS", "SQRT", "LN", "LOG", "EXP", "SIN", "COS", "TAN", "ASIN", "ACOS", "ATAN",
                    "EXPT", "MAX", "MIN", "LIMIT",
                ];
                GENERIC.contains(&n.name.as_str())
                    && !args.is_empty()
                    && args.iter().all(|a| !a.output && is_flexible(&a.value))
            }
            _ => false,
        },
        ExprKind::Unary(UnOp::Neg, x) => is_flexible(x),
        ExprKind::Binary(op, a, b)
            if !matches!(
                op,
                BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge
            ) =>
        {
            is_flexible(a) && is_flexible(b)
        }
        _ => false,
    }
}

/// Whether `e` holds a real literal that decides its type (a REAL function of literals is
/// a real, ABS, MAX, MIN and LIMIT of integer literals is not; TRUNC and SIZEOF never are).
pub(crate) fn has_real_literal(e: &Expr) -> bool {
    match &e.kind {
        ExprKind::Real(_) => true,
        ExprKind::Call { callee, .. } if matches!(&callee.kind, ExprKind::Name(n) if n.name == "TRUNC" || n.name == "SIZEOF") => {
            false
        }
        ExprKind::Call { callee, args } => {
            matches!(&callee.kind, ExprKind::Name(n) if !["ABS", "MAX", "MIN", "LIMIT"].contains(&n.name.as_str()))
                || args.iter().any(|a| has_real_literal(&a.value))
        }
        ExprKind::Unary(_, x) => has_real_literal(x),
        ExprKind::Binary(_, a, b) => has_real_literal(a) || has_real_literal(b),
        _ => false,
    }
}

// ----- implicit conversions -----------------------------------------------------------------

/// Checks `e` where a value of type `to` is wanted (an assignment's value, an input, an
/// operand): it must convert implicitly ([`coerce`]). The literal 0 is NULL where a
/// reference is wanted; a `REFERENCE TO` parameter is bound to the argument, as `REF=`
/// does.
pub(crate) fn value_to(g: &mut Gen, e: &Expr, to: &Type) {
    if to.is_pointer_like() && matches!(e.kind, ExprKind::Int(0)) {
        return;
    }
    if let Type::Reference(target) = to {
        let as_ref = Type::Ref(target.clone());
        if matches!(e.kind, ExprKind::Null) {
            return;
        }
        let t = crate::sema::refs::make_reference(g, e, Some(&as_ref));
        coerce(g, &t, &as_ref, e);
        return;
    }
    let t = check(g, e, Some(to));
    coerce(g, &t, to, e);
}

/// Decides what the value `e` of type `from` takes where `to` is wanted
/// ([`implicit_conversion`], and the rules of references) and records it
/// ([`crate::typed::Coercions`]), or reports why it cannot stand there.
pub(crate) fn coerce(g: &mut Gen, from: &Type, to: &Type, e: &Expr) {
    if from.is_error() || to.is_error() || from == to {
        return;
    }
    let Some(implicit) = implicit_conversion_at(g, from, to, e.span) else {
        return;
    };
    if !g.dry || g.coercions.of(e).is_none() {
        g.coercions.record(e, implicit);
    }
}

/// What a value of type `from` at `span` takes where `to` is wanted, or `None` when it
/// cannot stand there (reported).
fn implicit_conversion_at(g: &mut Gen, from: &Type, to: &Type, span: Span) -> Option<Implicit> {
    if let Some(decided) = pointer_coercion(g, from, to, span) {
        return decided;
    }
    let (code, msg) = match implicit_conversion(from, to) {
        Ok(implicit) => return Some(implicit),
        // Between numbers an explicit conversion would do.
        Err(NotImplicit::MayLose(f, t)) if f.is_numeric() && t.is_numeric() => {
            let msg = format!("cannot convert {f} to {t} implicitly (use {f}_TO_{t})");
            (codes::IMPLICIT_CONVERSION, msg)
        }
        Err(NotImplicit::MayLose(..)) => {
            (codes::IMPLICIT_CONVERSION, mismatch_message(g, from, to))
        }
        Err(NotImplicit::Mismatch) => (codes::TYPE_MISMATCH, mismatch_message(g, from, to)),
    };
    g.error(code, span, msg);
    None
}

fn mismatch_message(g: &Gen, from: &Type, to: &Type) -> String {
    format!(
        "type mismatch: expected {}, found {}",
        g.tname(to),
        g.tname(from)
    )
}

/// The implicit conversion of a pair of types involving references: `None` when the
/// pair is none of them, `Some(None)` when it is refused (reported).
fn pointer_coercion(g: &mut Gen, from: &Type, to: &Type, span: Span) -> Option<Option<Implicit>> {
    let involved = |t: &Type| t.is_pointer_like() || matches!(t, Type::Reference(_));
    let instance_to_interface = matches!((from, to), (Type::Fb(_), Type::Interface(_)));
    if !(involved(from) || involved(to) || instance_to_interface) {
        return None;
    }
    let mut implicit = Implicit::Nothing;
    let ok = match (from, to) {
        (Type::Null, Type::Ref(_) | Type::Interface(_)) => true,
        (Type::Ref(a), Type::Ref(b)) => {
            if a == b || matches!(**a, Type::Void) {
                true
            } else if matches!(**a, Type::String(_)) && is_byte_view(b) {
                g.error(codes::REFERENCE_CONVERSION,
                    span,
                    "a reference to a STRING cannot become a byte pointer; take REF()/ADR() of the STRING variable itself where the byte pointer is needed",
                );
                return Some(None);
            } else if matches!(**b, Type::String(_)) && is_byte_view(a) {
                g.error(codes::REFERENCE_CONVERSION,
                    span,
                    "a byte pointer cannot become a reference to a STRING: STRINGs here carry a length header in front of their text",
                );
                return Some(None);
            } else if let (Type::Fb(c), Type::Fb(d)) = (&**a, &**b) {
                g.derives_from(*c, *d)
            } else {
                is_plain(g.prog, a) && is_plain(g.prog, b)
            }
        }
        (Type::Ref(target), Type::Elem(e)) => {
            if !matches!(**target, Type::Fb(_)) {
                implicit = Implicit::AddressToInteger;
            }
            e.is_integral() && e.size() >= 4
        }
        (Type::Fb(c), Type::Interface(i)) => g.implements(*c, *i),
        (Type::Ref(target), Type::Interface(i)) => match &**target {
            Type::Fb(c) => g.implements(*c, *i),
            _ => false,
        },
        (Type::Interface(i), Type::Interface(j)) => g.interface_extends(*i, *j),
        (Type::Elem(e), Type::Ref(_) | Type::Interface(_)) if e.is_integral() => {
            let msg = format!(
                "an integer cannot become {}: references come from REF()/ADR() (and moving one by a byte offset), so that every access through them can be checked against the variable they were taken from",
                g.tname(to)
            );
            g.error(codes::REFERENCE_CONVERSION, span, msg);
            return Some(None);
        }
        _ => false,
    };
    if !ok {
        let msg = mismatch_message(g, from, to);
        g.error(codes::TYPE_MISMATCH, span, msg);
        return Some(None);
    }
    Some(Some(implicit))
}

/// Whether values of `ty` are plain data: bytes without references, interface values or
/// function-block instances (so reinterpreting them through another reference type, or
/// walking them with pointer arithmetic, cannot forge a reference).
pub(crate) fn is_plain(prog: &Program, ty: &Type) -> bool {
    match ty {
        Type::Array(a) => is_plain(prog, &a.elem),
        Type::Struct(i) => prog.structs[*i]
            .members
            .iter()
            .all(|m| is_plain(prog, &m.ty)),
        Type::Ref(_)
        | Type::Reference(_)
        | Type::Interface(_)
        | Type::Fb(_)
        | Type::Null
        | Type::Void => false,
        _ => true,
    }
}

/// Whether a reference to `ty` views raw bytes (`BYTE`, `USINT`, `SINT` or arrays of them):
/// what CODESYS code points at a STRING's text with.
pub(crate) fn is_byte_view(ty: &Type) -> bool {
    match ty {
        Type::Elem(e) => matches!(e, Elem::Byte | Elem::USInt | Elem::SInt),
        Type::Array(a) => is_byte_view(&a.elem),
        _ => false,
    }
}
