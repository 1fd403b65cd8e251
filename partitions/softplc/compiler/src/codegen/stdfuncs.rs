//! Standard functions of IEC 61131-3 (numeric, selection, bit shifts, type conversions,
//! strings) compiled inline or to `CALL_BUILTIN`.
//!
//! Conventions: REAL->integer conversions round to nearest (ties away from zero), `TRUNC`
//! truncates; TIME<->number conversions count milliseconds; string results go to a static
//! temporary per call site.

use crate::codes;
use plc_vm::isa::{Builtin, MemType, Opcode, RoundMode};

use crate::ast::*;
use crate::codegen::{Gen, Place};
use crate::diagnostics::Span;
use crate::sema::expr::{has_real_literal, is_flexible, operand};
use crate::sema::stdfuncs as rules;
use crate::types::*;

/// A date and time function: the typed form of an operator (`ADD_TOD_TIME` is TOD + TIME;
/// the second type of MUL/DIV stands for any number), CONCAT_DATE_TOD, CONCAT_* of numbers
/// giving the type, SPLIT_* of the type into numbers, DAY_OF_WEEK.
#[derive(Debug, Clone, Copy)]
pub(super) enum TimeFunction {
    Operator(BinOp, Elem, Elem),
    DateTod(Elem),
    Concat(Elem),
    Split(Elem),
    DayOfWeek,
}

/// The parts of a date or time of day: (name, how to get it as a number from the value).
const YEAR_MONTH_DAY: [&str; 3] = ["YEAR", "MONTH", "DAY"];
const HOUR_MINUTE_SECOND_MS: [&str; 4] = ["HOUR", "MINUTE", "SECOND", "MILLISECOND"];

/// Maximum length of the temporaries that hold string function results.
pub(super) const MAX_TEMP_STRING: u32 = 1024;

/// A standard-function call being compiled: its name, arguments and the type the context
/// expects of literal-only arguments.
pub(super) struct StdArgs<'e> {
    pub(super) name: &'e str,
    pub(super) id: &'e Ident,
    pub(super) exprs: Vec<&'e Expr>,
    pub(super) ctx: Option<Type>,
    pub(super) span: Span,
    /// The type of a typed form (`SQRT_LREAL`, `MAX_DINT`): its typed arguments convert
    /// to it implicitly and it is the result.
    pub(super) typed: Option<Elem>,
}

impl Gen<'_> {
    /// Compiles a standard function call; `None` if `name` is not a standard function.
    /// Whether `name` is a standard function handled here.
    pub(crate) fn is_std_function(name: &str) -> bool {
        const NAMES: &[&str] = &[
            "SQRT", "LN", "LOG", "EXP", "SIN", "COS", "TAN", "ASIN", "ACOS", "ATAN", "EXPT", "ABS",
            "TRUNC", "__NOW", "MOVE", "SEL", "MAX", "MIN", "LIMIT", "MUX", "SHL", "SHR", "ROL",
            "ROR", "LEN", "LEFT", "RIGHT", "MID", "DELETE", "INSERT", "REPLACE", "FIND", "CONCAT",
            "ATAN2", "TIME", "LTIME", "SIZEOF",
        ];
        NAMES.contains(&name)
            || name.contains("_TO_")
            || name.starts_with("TO_")
            || Self::time_function(name).is_some()
            || Self::typed_trunc(name).is_some()
            || Self::typed_overload(name).is_some()
    }

    /// `TRUNC_INT` and `REAL_TRUNC_INT`-style forms: (argument type if given, result type).
    pub(super) fn typed_trunc(name: &str) -> Option<(Option<Elem>, Elem)> {
        let (from, to) = match name.split_once("TRUNC_")? {
            ("", to) => (None, to),
            (from, to) => (Some(Elem::from_name(from.strip_suffix('_')?)?), to),
        };
        let to = Elem::from_name(to).filter(|e| e.is_integral())?;
        match from {
            Some(f) if !f.is_real() => None,
            f => Some((f, to)),
        }
    }

    /// The date and time functions of IEC 61131-3 (3rd edition, tables 35 and 36).
    pub(super) fn time_function(name: &str) -> Option<TimeFunction> {
        use Elem::*;
        use TimeFunction::*;
        let op = |op, a, b| Some(Operator(op, a, b));
        match name {
            "ADD_TIME" => op(BinOp::Add, Time, Time),
            "ADD_LTIME" => op(BinOp::Add, LTime, LTime),
            "ADD_TOD_TIME" => op(BinOp::Add, Tod, Time),
            "ADD_LTOD_LTIME" => op(BinOp::Add, LTod, LTime),
            "ADD_DT_TIME" => op(BinOp::Add, Dt, Time),
            "ADD_LDT_LTIME" => op(BinOp::Add, LDt, LTime),
            "SUB_TIME" => op(BinOp::Sub, Time, Time),
            "SUB_LTIME" => op(BinOp::Sub, LTime, LTime),
            "SUB_DATE_DATE" => op(BinOp::Sub, Date, Date),
            "SUB_LDATE_LDATE" => op(BinOp::Sub, LDate, LDate),
            "SUB_TOD_TIME" => op(BinOp::Sub, Tod, Time),
            "SUB_LTOD_LTIME" => op(BinOp::Sub, LTod, LTime),
            "SUB_TOD_TOD" => op(BinOp::Sub, Tod, Tod),
            "SUB_LTOD_LTOD" => op(BinOp::Sub, LTod, LTod),
            "SUB_DT_TIME" => op(BinOp::Sub, Dt, Time),
            "SUB_LDT_LTIME" => op(BinOp::Sub, LDt, LTime),
            "SUB_DT_DT" => op(BinOp::Sub, Dt, Dt),
            "SUB_LDT_LDT" => op(BinOp::Sub, LDt, LDt),
            "MUL_TIME" | "MULTIME" => op(BinOp::Mul, Time, LReal),
            "MUL_LTIME" => op(BinOp::Mul, LTime, LReal),
            "DIV_TIME" | "DIVTIME" => op(BinOp::Div, Time, LReal),
            "DIV_LTIME" => op(BinOp::Div, LTime, LReal),
            "CONCAT_DATE_TOD" => Some(DateTod(Dt)),
            "CONCAT_DATE_LTOD" => Some(DateTod(LDt)),
            "CONCAT_DATE" => Some(Concat(Date)),
            "CONCAT_TOD" => Some(Concat(Tod)),
            "CONCAT_LTOD" => Some(Concat(LTod)),
            "CONCAT_DT" => Some(Concat(Dt)),
            "CONCAT_LDT" => Some(Concat(LDt)),
            "SPLIT_DATE" => Some(Split(Date)),
            "SPLIT_TOD" => Some(Split(Tod)),
            "SPLIT_LTOD" => Some(Split(LTod)),
            "SPLIT_DT" => Some(Split(Dt)),
            "SPLIT_LDT" => Some(Split(LDt)),
            "DAY_OF_WEEK" => Some(DayOfWeek),
            _ => None,
        }
    }

    pub(crate) fn std_call(
        &mut self,
        name: &str,
        id: &Ident,
        args: &[Arg],
        expected: Option<&Type>,
        span: Span,
    ) -> Option<Type> {
        // Literal-only arguments adapt to the numeric type the context expects.
        let ctx = expected
            .filter(|t| {
                t.elem().is_some_and(|e| e.is_numeric())
                    && !matches!(t, Type::Enum(_) | Type::Exception)
            })
            .map(|t| Type::Elem(t.elem().unwrap_or(Elem::DInt)));
        if let Some(f) = Self::time_function(name) {
            return Some(self.std_time(f, id, args, expected, span));
        }
        if name == "SIZEOF" {
            return Some(self.std_sizeof(id, args, expected, span));
        }
        if self.check_only {
            self.check_no_outputs(id, args);
        }
        if let Some(target) = name.strip_prefix("TO_") {
            return self.generic_conversion(target, id, args, span);
        }
        let (name, typed) = match Self::typed_overload(name) {
            Some((base, t)) => (base, Some(t)),
            None => (name, None),
        };
        let Some(exprs) = self.std_arguments(name, id, args) else {
            return Some(Type::Error);
        };
        let c = StdArgs {
            name,
            id,
            exprs,
            ctx: typed.map(Type::Elem).or(ctx),
            span,
            typed,
        };
        if let Some(t) = typed
            && self.check_only
            && !self.typed_arguments(&c, t)
        {
            return Some(Type::Error);
        }
        match name {
            "SQRT" | "LN" | "LOG" | "EXP" | "SIN" | "COS" | "TAN" | "ASIN" | "ACOS" | "ATAN"
            | "EXPT" | "ABS" | "TRUNC" | "__NOW" | "ATAN2" | "TIME" | "LTIME" => {
                self.std_numeric(&c)
            }
            _ if Self::typed_trunc(name).is_some() => self.std_numeric(&c),
            "MOVE" | "SEL" | "MAX" | "MIN" | "LIMIT" | "MUX" => self.std_selection(&c),
            "SHL" | "SHR" | "ROL" | "ROR" => self.std_bits(&c),
            "LEN" | "LEFT" | "RIGHT" | "MID" | "DELETE" | "INSERT" | "REPLACE" | "FIND"
            | "CONCAT" => self.std_string(&c),
            _ => self.conversion(name, id, &c.exprs, span),
        }
    }

    /// A typed form of an overloaded standard function (IEC 61131-3: `SQRT_LREAL`,
    /// `ABS_INT`, `MAX_DINT`, `EXPT_REAL`, `SEL_TIME`, ...): (the function, the type).
    pub(super) fn typed_overload(name: &str) -> Option<(&str, Elem)> {
        let (base, ty) = name.rsplit_once('_')?;
        let t = Elem::from_name(ty)?;
        let fits = match base {
            "SQRT" | "LN" | "LOG" | "EXP" | "SIN" | "COS" | "TAN" | "ASIN" | "ACOS" | "ATAN"
            | "ATAN2" | "EXPT" => t.is_real(),
            "ABS" => t.is_numeric(),
            "MAX" | "MIN" | "LIMIT" => t.is_numeric() || t.is_temporal() || t.is_char(),
            "SEL" | "MUX" | "MOVE" => true,
            _ => false,
        };
        fits.then_some((base, t))
    }

    /// Checks that the arguments of a typed form convert to its type implicitly (SEL's
    /// selector, MUX's index and EXPT's exponent are not typed). False after reporting one
    /// that does not.
    /// Reports an output argument (`=>`) of the standard function `id`, which has none (the
    /// checking pass asks).
    fn check_no_outputs(&mut self, id: &Ident, args: &[Arg]) {
        if let Some(a) = args.iter().find(|a| a.output) {
            self.error(
                codes::UNKNOWN_PARAMETER,
                a.span,
                format!("{} has no outputs", id.text),
            );
            self.surface(&a.value);
        }
    }

    /// Reports what is wrong with `target` (the place `place`) as the output `part` of a
    /// SPLIT_ function (the checking pass asks); `false` when it takes no integer.
    fn check_split_output(&mut self, part: &str, place: &Place, target: &Expr) -> bool {
        if !place.ty.is_integral() {
            if !place.ty.is_error() {
                let msg = format!(
                    "the output {part} is an integer, not {}",
                    self.tname(&place.ty)
                );
                self.error(codes::OUTPUT_TARGET, target.span, msg);
            }
            return false;
        }
        crate::sema::call::check_output_writable(self, place, target);
        true
    }

    pub(super) fn typed_arguments(&mut self, c: &StdArgs, t: Elem) -> bool {
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
            let at = self.infer(e);
            let fits = !matches!(at, Type::Enum(_) | Type::Exception)
                && at.elem().is_some_and(|x| implicit_ok(x, t));
            if !fits {
                if at.is_error() {
                    self.surface(e);
                } else {
                    let msg = format!(
                        "{} takes {t} arguments, found {} (convert it with {}_TO_{t})",
                        c.id.text,
                        self.tname(&at),
                        self.tname(&at)
                    );
                    self.error(codes::IMPLICIT_CONVERSION, e.span, msg);
                }
                ok = false;
            }
        }
        ok
    }

    /// The formal input names of a standard function called with `count` arguments
    /// (IEC 61131-3: `IN`, `IN1`.., `G`, `K`, `MN`, `MX`, `N`, `L`, `P`, `YEAR`, ...).
    pub(super) fn std_formals(name: &str, count: usize) -> Vec<String> {
        let numbered = |first: usize, n: usize| (first..first + n).map(|i| format!("IN{i}"));
        let fixed: &[&str] = match name {
            "MAX" | "MIN" | "CONCAT" => return numbered(1, count).collect(),
            "MUX" => {
                return std::iter::once("K".to_string())
                    .chain(numbered(0, count.saturating_sub(1)))
                    .collect();
            }
            "EXPT" | "ATAN2" | "FIND" => &["IN1", "IN2"],
            "SEL" => &["G", "IN0", "IN1"],
            "LIMIT" => &["MN", "IN", "MX"],
            "SHL" | "SHR" | "ROL" | "ROR" => &["IN", "N"],
            "LEFT" | "RIGHT" => &["IN", "L"],
            "MID" | "DELETE" => &["IN", "L", "P"],
            "INSERT" => &["IN1", "IN2", "P"],
            "REPLACE" => &["IN1", "IN2", "L", "P"],
            "CONCAT_DATE" => &["YEAR", "MONTH", "DAY"],
            "CONCAT_TOD" | "CONCAT_LTOD" => &["HOUR", "MINUTE", "SECOND", "MILLISECOND"],
            "CONCAT_DT" | "CONCAT_LDT" => &[
                "YEAR",
                "MONTH",
                "DAY",
                "HOUR",
                "MINUTE",
                "SECOND",
                "MILLISECOND",
            ],
            _ if Self::time_function(name).is_some_and(|f| {
                matches!(f, TimeFunction::Operator(..) | TimeFunction::DateTod(_))
            }) =>
            {
                &["IN1", "IN2"]
            }
            _ => &["IN"],
        };
        fixed.iter().map(|s| s.to_string()).collect()
    }

    /// The argument expressions of a standard function in the order of its inputs: the
    /// positional ones first, the formal ones (`IN2 := x`) put in their place. `None` after
    /// reporting a misplaced, unknown, repeated or missing one.
    /// The checking pass places them (reporting what is wrong) and records the order
    /// ([`crate::typed::StdArguments`]); emission reads the record.
    pub(super) fn std_arguments<'e>(
        &mut self,
        name: &str,
        id: &Ident,
        args: &'e [Arg],
    ) -> Option<Vec<&'e Expr>> {
        let order = if self.check_only {
            let order = self.place_std_arguments(name, id, args)?;
            self.std_arguments.record(self.cur, id, order.clone());
            order
        } else {
            let Some(order) = self.std_arguments.of(self.cur, id) else {
                self.missing_record(id.span, "placed no arguments for this call");
                return None;
            };
            order.clone()
        };
        Some(order.into_iter().map(|i| &args[i].value).collect())
    }

    /// The index in `args` of each argument of standard function `name` in the order of its
    /// inputs (see [`Gen::std_arguments`]).
    fn place_std_arguments(&mut self, name: &str, id: &Ident, args: &[Arg]) -> Option<Vec<usize>> {
        let inputs: Vec<(usize, &Arg)> =
            args.iter().enumerate().filter(|(_, a)| !a.output).collect();
        if inputs.iter().all(|(_, a)| a.name.is_none()) {
            return Some(inputs.iter().map(|(i, _)| *i).collect());
        }
        let formals = Self::std_formals(name, inputs.len());
        let mut slots: Vec<Option<usize>> = vec![None; formals.len().max(inputs.len())];
        let mut ok = true;
        let mut named_seen = false;
        for (i, &(index, a)) in inputs.iter().enumerate() {
            let slot = match &a.name {
                None if named_seen => {
                    self.error(
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
                            self.error(codes::UNKNOWN_PARAMETER, n.span, msg);
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
                self.error(codes::DUPLICATE_ARGUMENT, a.span, msg);
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
            self.error(codes::MISSING_ARGUMENT, id.span, msg);
            ok = false;
        }
        if !ok {
            for a in args {
                self.surface(&a.value);
            }
            return None;
        }
        Some(slots.into_iter().flatten().collect())
    }

    /// `TO_INT(x)`, `TO_STRING(x)`, ... (IEC 61131-3 3rd edition): the conversion from the
    /// argument's type.
    pub(super) fn generic_conversion(
        &mut self,
        target: &str,
        id: &Ident,
        args: &[Arg],
        span: Span,
    ) -> Option<Type> {
        if target != "STRING" && Elem::from_name(target).is_none() {
            return None;
        }
        let inputs = self.std_arguments(&id.name, id, args)?;
        let [arg] = inputs[..] else {
            self.error(
                codes::ARGUMENT_COUNT,
                span,
                format!("{} takes 1 argument, {} given", id.text, inputs.len()),
            );
            for e in inputs {
                self.surface(e);
            }
            return Some(Type::Error);
        };
        let Some(source) = self.conversion_source(id, arg) else {
            return Some(Type::Error);
        };
        let source = match source {
            Type::String(_) => "STRING".to_string(),
            t => self.tname(&t),
        };
        if source == target {
            let t = self.expr(arg, None);
            return Some(t);
        }
        self.conversion(&format!("{source}_TO_{target}"), id, &[arg], span)
    }

    /// The type `TO_...(arg)` converts from ([`rules::conversion_source`]): decided and
    /// recorded by the checking pass ([`crate::typed::GenericTypes`]), read by emission.
    fn conversion_source(&mut self, id: &Ident, arg: &Expr) -> Option<Type> {
        if !self.check_only {
            return self.recorded_generic_type(id);
        }
        let t = self.infer(arg);
        if t.is_error() {
            self.surface(arg);
            return None;
        }
        let Some(source) = rules::conversion_source(operand(arg, &t)) else {
            self.bad_inferred_arg(arg, &t, "an elementary value");
            return None;
        };
        self.record_generic_type(id, source.clone());
        Some(source)
    }

    /// Date and time functions (see [`TimeFunction`]).
    pub(super) fn std_time(
        &mut self,
        f: TimeFunction,
        id: &Ident,
        args: &[Arg],
        expected: Option<&Type>,
        span: Span,
    ) -> Type {
        if let TimeFunction::Split(t) = f {
            return self.std_split(t, id, args, span);
        }
        if self.check_only {
            self.check_no_outputs(id, args);
        }
        let Some(exprs) = self.std_arguments(&id.name, id, args) else {
            return Type::Error;
        };
        let c = StdArgs {
            name: &id.name,
            id,
            exprs,
            ctx: None,
            span,
            typed: None,
        };
        match f {
            TimeFunction::Operator(op, ta, tb) => {
                if !self.arity(&c, 2) {
                    return Type::Error;
                }
                if self.check_only && !self.time_operands_fit(&c, [ta, tb]) {
                    return Type::Error;
                }
                self.binary(op, c.exprs[0], c.exprs[1], expected, span)
            }
            TimeFunction::DateTod(result) => {
                if !self.arity(&c, 2) {
                    return Type::Error;
                }
                let (date, tod) = if result == Elem::LDt {
                    (Type::Elem(Elem::LDate), Type::Elem(Elem::LTod))
                } else {
                    (Type::Elem(Elem::Date), Type::Elem(Elem::Tod))
                };
                self.value_to(c.exprs[0], &date);
                self.value_to(c.exprs[1], &tod);
                self.op(Opcode::Add);
                Type::Elem(result)
            }
            TimeFunction::Concat(result) => {
                let family = result.temporal_family();
                let n = match family {
                    Some(Elem::Date) => 3,
                    Some(Elem::Tod) => 4,
                    _ => 7,
                };
                if !self.arity(&c, n) {
                    return Type::Error;
                }
                let (date_args, tod_args) = match family {
                    Some(Elem::Date) => (&c.exprs[..3], &c.exprs[..0]),
                    Some(Elem::Tod) => (&c.exprs[..0], &c.exprs[..4]),
                    _ => (&c.exprs[..3], &c.exprs[3..]),
                };
                if !date_args.is_empty() {
                    for e in date_args {
                        self.int_arg(e);
                    }
                    self.emit(|b| b.call_builtin(Builtin::DateFromParts));
                }
                if !tod_args.is_empty() {
                    for e in tod_args {
                        self.int_arg(e);
                    }
                    self.emit(|b| b.call_builtin(Builtin::TodFromParts));
                }
                if !date_args.is_empty() && !tod_args.is_empty() {
                    self.op(Opcode::Add);
                }
                Type::Elem(result)
            }
            TimeFunction::DayOfWeek => {
                if !self.arity(&c, 1) {
                    return Type::Error;
                }
                let t = self.infer(c.exprs[0]);
                if self.check_only && !rules::is_date(&t) {
                    return self.bad_inferred_arg(c.exprs[0], &t, "a DATE");
                }
                self.expr(c.exprs[0], None);
                self.emit(|b| b.call_builtin(Builtin::DayOfWeek));
                Type::INT
            }
            TimeFunction::Split(_) => unreachable!("handled above"),
        }
    }

    /// Whether the two arguments of the date and time operator `c` fit the operands `want`
    /// ([`rules::time_operand_fits`]); reports the first that does not (the checking pass
    /// asks).
    fn time_operands_fit(&mut self, c: &StdArgs, want: [Elem; 2]) -> bool {
        let types: Vec<Type> = c.exprs.iter().map(|e| self.infer(e)).collect();
        if types.iter().any(Type::is_error) {
            for (e, _) in c.exprs.iter().zip(&types).filter(|(_, t)| t.is_error()) {
                self.surface(e);
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
                self.bad_arg(e, t, &what);
                return false;
            }
        }
        true
    }

    /// SIZEOF(variable or type): its size in bytes in data memory, a constant of the
    /// integer type the context wants (UDINT without one).
    pub(super) fn std_sizeof(
        &mut self,
        id: &Ident,
        args: &[Arg],
        expected: Option<&Type>,
        span: Span,
    ) -> Type {
        let [arg] = args else {
            self.error(
                codes::ARGUMENT_COUNT,
                span,
                format!("{} takes 1 argument, {} given", id.text, args.len()),
            );
            return Type::Error;
        };
        let ty = match &arg.value.kind {
            ExprKind::Name(n)
                if self.prog.pous[self.cur].var(&n.name).is_none()
                    && self.prog.global(&n.name).is_none() =>
            {
                match self.type_by_name(&n.name) {
                    Some(t) => t,
                    None => self.infer(&arg.value),
                }
            }
            _ => self.infer(&arg.value),
        };
        if ty.is_error() {
            // Report why (the dry inference reported nothing).
            self.expr(&arg.value, None);
            return Type::Error;
        }
        // A STRING[n] counts its text and terminator, n + 1 bytes as in CODESYS: what a byte
        // pointer to it (`ADR(s)`) may walk (its length header is not part of that).
        let size = match ty {
            Type::String(n) => n as i128 + 1,
            _ => self.prog.size_align(&ty).0 as i128,
        };
        let result = expected
            .and_then(|t| t.elem())
            .filter(|e| {
                e.is_integral()
                    && !matches!(expected, Some(Type::Enum(_)))
                    && e.int_range().1 >= size
            })
            .unwrap_or(Elem::UDInt);
        self.push_int(size as i64);
        Type::Elem(result)
    }

    /// The data type called `name` (elementary, STRING, a TYPE or a function block).
    pub(super) fn type_by_name(&self, name: &str) -> Option<Type> {
        if let Some(e) = Elem::from_name(name) {
            return Some(Type::Elem(e));
        }
        if name == "STRING" {
            return Some(Type::String(DEFAULT_STRING_LEN));
        }
        if let Some((t, _)) = self.prog.aliases.get(name) {
            return Some(t.clone());
        }
        let &pi = self.prog.pou_by_name.get(name)?;
        (self.prog.pous[pi].kind == PouKind::FunctionBlock).then_some(Type::Fb(pi))
    }

    /// SPLIT_DATE(IN, YEAR, MONTH, DAY), SPLIT_TOD(IN, HOUR, MINUTE, SECOND, MILLISECOND),
    /// SPLIT_DT(IN, YEAR, ..., MILLISECOND): the parts go to the outputs, given formally
    /// (`YEAR => y`) or in order after the input.
    pub(super) fn std_split(
        &mut self,
        input_type: Elem,
        id: &Ident,
        args: &[Arg],
        span: Span,
    ) -> Type {
        let family = input_type.temporal_family();
        let parts: Vec<&str> = match family {
            Some(Elem::Date) => YEAR_MONTH_DAY.to_vec(),
            Some(Elem::Tod) => HOUR_MINUTE_SECOND_MS.to_vec(),
            _ => YEAR_MONTH_DAY
                .iter()
                .chain(HOUR_MINUTE_SECOND_MS.iter())
                .copied()
                .collect(),
        };
        let mut input: Option<&Expr> = None;
        let mut targets: Vec<Option<&Expr>> = vec![None; parts.len()];
        for (i, a) in args.iter().enumerate() {
            match (&a.name, a.output) {
                (None, _) if i == 0 => input = Some(&a.value),
                (Some(n), false) if n.name == "IN" => input = Some(&a.value),
                (None, _) if i <= parts.len() => targets[i - 1] = Some(&a.value),
                (Some(n), true) => match parts.iter().position(|p| *p == n.name) {
                    Some(k) => targets[k] = Some(&a.value),
                    None if self.check_only => {
                        let msg = format!(
                            "{} has no output `{}` (its outputs: {})",
                            id.text,
                            n.text,
                            parts.join(", ")
                        );
                        self.error(codes::UNKNOWN_PARAMETER, n.span, msg);
                    }
                    None => {}
                },
                _ if self.check_only => {
                    let msg = format!("{} takes IN and the outputs {}", id.text, parts.join(", "));
                    self.error(codes::UNKNOWN_PARAMETER, a.span, msg);
                }
                _ => {}
            }
        }
        let input_type_ok = input.filter(|e| {
            !self.check_only
                || self
                    .infer(e)
                    .value_elem()
                    .is_some_and(|e| e.temporal_family() == family)
        });
        let Some(input) = input_type_ok else {
            match input {
                None => self.error(
                    codes::MISSING_ARGUMENT,
                    span,
                    format!("{} needs its input IN", id.text),
                ),
                Some(e) => {
                    let t = self.infer(e);
                    self.bad_inferred_arg(e, &t, &format!("a {input_type}"));
                }
            }
            // The outputs still say what is wrong with them.
            for target in targets.into_iter().flatten() {
                if let Some(p) = self.place(target) {
                    self.drop_place(&p);
                }
            }
            return Type::Error;
        };
        let value = self.temp_cell();
        self.expr(input, None);
        self.emit(|b| b.st_abs(MemType::I64, value));
        for (part, target) in parts.iter().zip(targets) {
            let Some(target) = target else { continue };
            let Some(place) = self.place(target) else {
                continue;
            };
            if self.check_only && !self.check_split_output(part, &place, target) {
                continue;
            }
            let te = place.ty.value_elem().unwrap_or(Elem::LInt);
            self.emit(|b| b.ld_abs(MemType::I64, value));
            match *part {
                "YEAR" | "MONTH" | "DAY" => {
                    self.emit(|b| b.call_builtin(Builtin::DateSplit));
                    match *part {
                        "YEAR" => self.emit(|b| {
                            b.push_i32(16);
                            b.op(Opcode::ShrS);
                        }),
                        "MONTH" => self.emit(|b| {
                            b.push_i32(8);
                            b.op(Opcode::ShrU);
                            b.push_i32(0xff);
                            b.op(Opcode::And);
                        }),
                        _ => self.emit(|b| {
                            b.push_i32(0xff);
                            b.op(Opcode::And);
                        }),
                    }
                }
                _ => {
                    let (unit, modulo): (i64, i64) = match *part {
                        "HOUR" => (3_600_000_000_000, 0),
                        "MINUTE" => (60_000_000_000, 60),
                        "SECOND" => (1_000_000_000, 60),
                        _ => (1_000_000, 1000),
                    };
                    self.emit(|b| {
                        b.call_builtin(Builtin::TodOf);
                        b.push_int(unit);
                        b.op(Opcode::DivS);
                        if modulo != 0 {
                            b.push_int(modulo);
                            b.op(Opcode::ModS);
                        }
                    });
                }
            }
            self.convert(Elem::LInt, te);
            self.store_checked(&place);
        }
        Type::Void
    }

    /// False (after reporting it and type-checking the arguments) unless the call has
    /// exactly `n` arguments (the checking pass asks; emission takes the count as checked).
    pub(super) fn arity(&mut self, c: &StdArgs, n: usize) -> bool {
        if !self.check_only || c.exprs.len() == n {
            return true;
        }
        self.error(
            codes::ARGUMENT_COUNT,
            c.span,
            format!(
                "{} takes {} argument(s), {} given",
                c.id.text,
                n,
                c.exprs.len()
            ),
        );
        for e in &c.exprs {
            self.surface(e);
        }
        false
    }

    /// Numeric functions: SQRT and the other REAL functions, EXPT, ABS, TRUNC, __NOW.
    pub(super) fn std_numeric(&mut self, c: &StdArgs) -> Option<Type> {
        let t = match c.name {
            "SQRT" | "LN" | "LOG" | "EXP" | "SIN" | "COS" | "TAN" | "ASIN" | "ACOS" | "ATAN" => {
                if !self.arity(c, 1) {
                    return Some(Type::Error);
                }
                let rt = match self.real_operand(c) {
                    Some(t) => t,
                    None => return Some(Type::Error),
                };
                let single = rt == Elem::Real;
                use Builtin::*;
                let b = match (c.name, single) {
                    ("SQRT", true) => SqrtF32,
                    ("SQRT", false) => SqrtF64,
                    ("LN", true) => LnF32,
                    ("LN", false) => LnF64,
                    ("LOG", true) => LogF32,
                    ("LOG", false) => LogF64,
                    ("EXP", true) => ExpF32,
                    ("EXP", false) => ExpF64,
                    ("SIN", true) => SinF32,
                    ("SIN", false) => SinF64,
                    ("COS", true) => CosF32,
                    ("COS", false) => CosF64,
                    ("TAN", true) => TanF32,
                    ("TAN", false) => TanF64,
                    ("ASIN", true) => AsinF32,
                    ("ASIN", false) => AsinF64,
                    ("ACOS", true) => AcosF32,
                    ("ACOS", false) => AcosF64,
                    ("ATAN", true) => AtanF32,
                    _ => AtanF64,
                };
                self.emit(|bb| bb.call_builtin(b));
                Type::Elem(rt)
            }
            "EXPT" | "ATAN2" => {
                if !self.arity(c, 2) {
                    return Some(Type::Error);
                }
                let rt = match self.real_operand(c) {
                    Some(t) => t,
                    None => return Some(Type::Error),
                };
                let t1 = self.infer(c.exprs[1]);
                if !t1.elem().is_some_and(|e| e.is_numeric()) || matches!(t1, Type::Enum(_)) {
                    return Some(self.bad_inferred_arg(c.exprs[1], &t1, "a number"));
                }
                self.value_to_any(c.exprs[1], &t1, &Type::Elem(rt));
                let single = rt == Elem::Real;
                let builtin = match (c.name, single) {
                    ("EXPT", true) => Builtin::ExptF32,
                    ("EXPT", false) => Builtin::ExptF64,
                    (_, true) => Builtin::Atan2F32,
                    _ => Builtin::Atan2F64,
                };
                self.emit(|bb| bb.call_builtin(builtin));
                Type::Elem(rt)
            }
            "ABS" => {
                if !self.arity(c, 1) {
                    return Some(Type::Error);
                }
                let t = match c.typed {
                    Some(forced) => {
                        self.value_to(c.exprs[0], &Type::Elem(forced));
                        Type::Elem(forced)
                    }
                    None => self.expr(c.exprs[0], c.ctx.as_ref()),
                };
                let Some(e) = self.argument_type(c, &t, rules::abs_type, "a number") else {
                    return Some(Type::Error);
                };
                match e {
                    Elem::Real => self.emit(|b| b.call_builtin(Builtin::AbsF32)),
                    Elem::LReal => self.emit(|b| b.call_builtin(Builtin::AbsF64)),
                    e if e.is_signed_int() || e.is_duration() => {
                        self.op(Opcode::AbsS);
                        self.wrap(e);
                    }
                    _ => {}
                }
                Type::Elem(e)
            }
            // TRUNC gives the integer type the context wants (IEC: ANY_INT), else DINT;
            // TRUNC_INT, REAL_TRUNC_INT, ... a fixed one. NUMERIC_ERROR when it does not fit.
            name if name == "TRUNC" || Self::typed_trunc(name).is_some() => {
                if !self.arity(c, 1) {
                    return Some(Type::Error);
                }
                let (from, target) = match Self::typed_trunc(name) {
                    Some(typed) => typed,
                    None => (
                        None,
                        c.ctx
                            .as_ref()
                            .and_then(|t| t.elem())
                            .filter(|e| e.is_integral())
                            .unwrap_or(Elem::DInt),
                    ),
                };
                let rt = match from {
                    Some(f) => {
                        let t = self.infer(c.exprs[0]);
                        if !(t.elem().is_some_and(|e| implicit_ok(e, f)) || is_flexible(c.exprs[0]))
                        {
                            return Some(self.bad_inferred_arg(c.exprs[0], &t, &format!("a {f}")));
                        }
                        self.value_to(c.exprs[0], &Type::Elem(f));
                        f
                    }
                    None => match self.real_operand(c) {
                        Some(t) => t,
                        None => return Some(Type::Error),
                    },
                };
                let op = if rt == Elem::Real {
                    Opcode::F32ToInt
                } else {
                    Opcode::F64ToInt
                };
                self.emit(|b| {
                    b.float_to_int(op, crate::codegen::mem_type(target), RoundMode::Truncate)
                });
                Type::Elem(target)
            }
            // `TIME()` (CODESYS): the time since the PLC started, here the cycle time.
            "__NOW" | "TIME" | "LTIME" => {
                if !self.arity(c, 0) {
                    return Some(Type::Error);
                }
                self.op(Opcode::Now);
                if c.name == "LTIME" {
                    Type::Elem(Elem::LTime)
                } else {
                    Type::TIME
                }
            }
            _ => unreachable!("std_numeric called for {}", c.name),
        };
        Some(t)
    }

    /// Selection: MOVE, SEL, MAX/MIN, LIMIT, MUX.
    pub(super) fn std_selection(&mut self, c: &StdArgs) -> Option<Type> {
        let t = match c.name {
            "MOVE" => {
                if !self.arity(c, 1) {
                    return Some(Type::Error);
                }
                match c.typed {
                    Some(forced) => {
                        self.value_to(c.exprs[0], &Type::Elem(forced));
                        Type::Elem(forced)
                    }
                    None => self.expr(c.exprs[0], None),
                }
            }
            "SEL" => {
                if !self.arity(c, 3) {
                    return Some(Type::Error);
                }
                self.value_to(c.exprs[0], &Type::BOOL);
                let t = match c.typed {
                    Some(forced) => Type::Elem(forced),
                    None => self.generic_type(c, 1),
                };
                if t.is_error() {
                    return Some(t);
                }
                for e in &c.exprs[1..] {
                    let et = self.infer(e);
                    self.value_to_any(e, &et, &t);
                }
                self.op(Opcode::Sel);
                t
            }
            "MAX" | "MIN" => {
                if self.check_only && c.exprs.len() < 2 {
                    self.error(
                        codes::ARGUMENT_COUNT,
                        c.span,
                        format!("{} needs at least 2 arguments", c.id.text),
                    );
                    c.exprs.iter().for_each(|e| self.surface(e));
                    return Some(Type::Error);
                }
                let t = match c.typed {
                    Some(forced) => Type::Elem(forced),
                    None => self.generic_type(c, 0),
                };
                let Some(e) = t.elem() else {
                    if !t.is_error() {
                        let msg = format!(
                            "{} needs numeric, TIME or enumeration arguments, found {}",
                            c.id.text,
                            self.tname(&t)
                        );
                        self.error(codes::INCOMPATIBLE_ARGUMENTS, c.span, msg);
                    }
                    return Some(Type::Error);
                };
                let first_t = self.infer(c.exprs[0]);
                self.value_to_any(c.exprs[0], &first_t, &t);
                for x in &c.exprs[1..] {
                    let xt = self.infer(x);
                    self.value_to_any(x, &xt, &t);
                    self.select_min_max(c.name == "MAX", e);
                }
                t
            }
            "LIMIT" => {
                if !self.arity(c, 3) {
                    return Some(Type::Error);
                }
                let t = match c.typed {
                    Some(forced) => Type::Elem(forced),
                    None => self.generic_type(c, 0),
                };
                let Some(e) = t.elem() else {
                    return Some(Type::Error);
                };
                let it = self.infer(c.exprs[1]);
                self.value_to_any(c.exprs[1], &it, &t);
                let mt = self.infer(c.exprs[0]);
                self.value_to_any(c.exprs[0], &mt, &t);
                self.select_min_max(true, e);
                let xt = self.infer(c.exprs[2]);
                self.value_to_any(c.exprs[2], &xt, &t);
                self.select_min_max(false, e);
                t
            }
            "MUX" => {
                if self.check_only && c.exprs.len() < 2 {
                    self.error(
                        codes::ARGUMENT_COUNT,
                        c.span,
                        "MUX needs a selector and at least one input",
                    );
                    c.exprs.iter().for_each(|e| self.surface(e));
                    return Some(Type::Error);
                }
                let kt = self.expr(c.exprs[0], Some(&Type::DINT));
                if self.check_only && !kt.elem().is_some_and(|e| e.is_integral()) && !kt.is_error()
                {
                    return Some(self.bad_arg(c.exprs[0], &kt, "an integer selector"));
                }
                let n = c.exprs.len() as i64 - 1;
                let k = self.temp_cell();
                self.emit(|b| {
                    b.chk_index(0, n - 1);
                    b.st_abs(MemType::I64, k);
                });
                let t = match c.typed {
                    Some(forced) => Type::Elem(forced),
                    None => self.generic_type(c, 1),
                };
                let end = self.label();
                for (i, x) in c.exprs[1..].iter().enumerate() {
                    let next = self.label();
                    self.emit(|b| {
                        b.ld_abs(MemType::I64, k);
                        b.push_int(i as i64);
                        b.op(Opcode::Eq);
                        b.jz(next);
                    });
                    let xt = self.infer(x);
                    self.value_to_any(x, &xt, &t);
                    self.emit(|b| {
                        b.jmp(end);
                        b.bind(next);
                    });
                }
                // Unreachable after CHK_INDEX, but keeps the stack depth equal on all paths.
                self.push_int(0);
                self.bind(end);
                t
            }
            _ => unreachable!("std_selection called for {}", c.name),
        };
        Some(t)
    }

    /// Bit shifts and rotations: SHL, SHR, ROL, ROR.
    pub(super) fn std_bits(&mut self, c: &StdArgs) -> Option<Type> {
        let t = match c.name {
            "SHL" | "SHR" | "ROL" | "ROR" => {
                if !self.arity(c, 2) {
                    return Some(Type::Error);
                }
                let t = self.expr(c.exprs[0], None);
                let what = "a bit string or integer";
                let Some(e) = self.argument_type(c, &t, rules::shift_type, what) else {
                    return Some(Type::Error);
                };
                // The count may be of any integer type (IEC: ANY_INT).
                self.int_arg(c.exprs[1]);
                let w = (e.size() * 8) as u8;
                match c.name {
                    "SHL" => self.op(Opcode::Shl),
                    "SHR" => self.op(if e.is_signed_int() {
                        Opcode::ShrS
                    } else {
                        Opcode::ShrU
                    }),
                    "ROL" => self.emit(|b| b.op_width(Opcode::Rol, w)),
                    _ => self.emit(|b| b.op_width(Opcode::Ror, w)),
                }
                self.wrap(e);
                Type::Elem(e)
            }
            _ => unreachable!("std_bits called for {}", c.name),
        };
        Some(t)
    }

    pub(super) fn bad_arg(&mut self, e: &Expr, t: &Type, what: &str) -> Type {
        if !t.is_error() {
            let msg = format!("expected {what}, found {}", self.tname(t));
            self.error(codes::TYPE_MISMATCH, e.span, msg);
        }
        Type::Error
    }

    /// [`Self::bad_arg`] for an argument so far only inferred: an erroneous one is compiled
    /// for its own diagnostics.
    pub(super) fn bad_inferred_arg(&mut self, e: &Expr, t: &Type, what: &str) -> Type {
        if t.is_error() {
            self.surface(e);
        }
        self.bad_arg(e, t, what)
    }

    /// Compiles an expression whose inference failed, for the diagnostics saying why (the
    /// code does not matter: the compilation fails).
    pub(super) fn surface(&mut self, e: &Expr) {
        if !self.dry {
            self.expr(e, None);
        }
    }

    /// Compiles the (first) argument of a REAL function in the type the call computes in
    /// and returns it: the typed form's (`SQRT_LREAL`: its argument was checked), else as
    /// [`rules::real_function_type`] decides, which the checking pass records
    /// ([`crate::typed::GenericTypes`]) and emission reads.
    pub(super) fn real_operand(&mut self, c: &StdArgs) -> Option<Elem> {
        let e = c.exprs[0];
        if let Some(forced) = c.typed.filter(|t| t.is_real()) {
            self.value_to(e, &Type::Elem(forced));
            return Some(forced);
        }
        let t = self.infer(e);
        let target = if self.check_only {
            let real_context = c.ctx.as_ref().and_then(|c| c.elem()) == Some(Elem::Real);
            let Some(target) = rules::real_function_type(operand(e, &t), real_context) else {
                self.bad_inferred_arg(e, &t, "a number");
                return None;
            };
            self.record_generic_type(c.id, Type::Elem(target));
            target
        } else {
            self.recorded_generic_type(c.id)?.elem()?
        };
        self.value_to_any(e, &t, &Type::Elem(target));
        Some(target)
    }

    /// The type the call `c` computes in for its first argument of type `t` (compiled): the
    /// checking pass decides it by `rule` (reporting an argument that is not `what`) and
    /// records it; emission reads the record.
    fn argument_type(
        &mut self,
        c: &StdArgs,
        t: &Type,
        rule: fn(&Type) -> Option<Elem>,
        what: &str,
    ) -> Option<Elem> {
        if !self.check_only {
            return self.recorded_generic_type(c.id)?.elem();
        }
        let Some(e) = rule(t) else {
            self.bad_arg(c.exprs[0], t, what);
            return None;
        };
        self.record_generic_type(c.id, Type::Elem(e));
        Some(e)
    }

    /// The type the checking pass recorded for the generic standard-function call `id` (for
    /// emission: a missing record is an internal error).
    pub(super) fn recorded_generic_type(&mut self, id: &Ident) -> Option<Type> {
        let t = self.generic_types.of(self.cur, id).cloned();
        if t.is_none() {
            self.missing_record(id.span, "decided no type for this call");
        }
        t
    }

    /// Records the type the generic standard-function call `id` is called at (a walk for
    /// inference records only what no real walk has, as the expected type may differ).
    pub(super) fn record_generic_type(&mut self, id: &Ident, t: Type) {
        if !self.dry || self.generic_types.of(self.cur, id).is_none() {
            self.generic_types.record(self.cur, id, t);
        }
    }

    /// The type a generic selection function (SEL, MAX, MIN, LIMIT, MUX) is called at: the
    /// common type of its arguments from the `from`th. The checking pass decides it
    /// ([`Gen::common_of`]) and records it ([`crate::typed::GenericTypes`]; a walk for
    /// inference records only what no real walk has, as the expected type may differ);
    /// emission reads the record.
    fn generic_type(&mut self, c: &StdArgs, from: usize) -> Type {
        if !self.check_only {
            return self.recorded_generic_type(c.id).unwrap_or(Type::Error);
        }
        let t = self.common_of(&c.exprs[from..], c.ctx.as_ref());
        self.record_generic_type(c.id, t.clone());
        t
    }

    /// Common type of several arguments (for SEL/MAX/MIN/LIMIT/MUX).
    pub(super) fn common_of(&mut self, exprs: &[&Expr], ctx: Option<&Type>) -> Type {
        let mut acc: Option<Type> = None;
        for e in exprs {
            if is_flexible(e) {
                continue;
            }
            let t = self.infer(e);
            if t.is_error() {
                self.surface(e);
                return Type::Error;
            }
            acc = Some(match acc {
                None => t,
                Some(a) if a == t => a,
                Some(a) => match (a.elem(), t.elem()) {
                    (Some(x), Some(y))
                        if !matches!(a, Type::Enum(_)) && !matches!(t, Type::Enum(_)) =>
                    {
                        match common_numeric(x, y) {
                            Some(c) => Type::Elem(c),
                            None => {
                                let msg = format!(
                                    "arguments of incompatible types {} and {}",
                                    self.tname(&a),
                                    self.tname(&t)
                                );
                                self.error(codes::INCOMPATIBLE_ARGUMENTS, e.span, msg);
                                return Type::Error;
                            }
                        }
                    }
                    _ if a.is_string() && t.is_string() || a.is_wstring() && t.is_wstring() => a,
                    _ => {
                        let msg = format!(
                            "arguments of incompatible types {} and {}",
                            self.tname(&a),
                            self.tname(&t)
                        );
                        self.error(codes::INCOMPATIBLE_ARGUMENTS, e.span, msg);
                        return Type::Error;
                    }
                },
            });
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
                    !exprs.iter().any(|e| has_real_literal(e))
                        || c.elem().is_some_and(|x| x.is_real())
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

    /// `[acc x] -> [max(acc, x)]` (or min) using two static temporaries.
    /// `[a b] -> [MAX(a, b)]` (`max`) or `[MIN(a, b)]`: SEL_IF takes `b` when `a < b`
    /// (MAX) or `a > b` (MIN), in the type's order (NaN compares false: `a` is kept).
    pub(super) fn select_min_max(&mut self, max: bool, e: Elem) {
        let (lt, gt) = match e {
            Elem::Real => (Opcode::LtF32, Opcode::GtF32),
            Elem::LReal => (Opcode::LtF64, Opcode::GtF64),
            e if e.is_unsigned_int() || e.is_bits() || e.is_char() => (Opcode::LtU, Opcode::GtU),
            _ => (Opcode::LtS, Opcode::GtS),
        };
        self.emit(|b| b.sel_if(if max { lt } else { gt }));
    }
}
