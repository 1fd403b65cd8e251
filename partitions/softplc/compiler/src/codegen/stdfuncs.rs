//! Standard functions of IEC 61131-3 (numeric, selection, bit shifts, type conversions,
//! strings) compiled inline or to `CALL_BUILTIN`.
//!
//! Conventions: REAL->integer conversions round to nearest (ties away from zero), `TRUNC`
//! truncates; TIME<->number conversions count milliseconds; string results go to a static
//! temporary per call site.

use plc_vm::isa::{Builtin, MemType, Opcode, RoundMode};

use crate::ast::*;
use crate::codegen::Gen;
use crate::diagnostics::Span;
use crate::types::*;

/// A date and time function: the typed form of an operator (`ADD_TOD_TIME` is TOD + TIME;
/// the second type of MUL/DIV stands for any number), CONCAT_DATE_TOD, CONCAT_* of numbers
/// giving the type, SPLIT_* of the type into numbers, DAY_OF_WEEK.
#[derive(Debug, Clone, Copy)]
pub(crate) enum TimeFunction {
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
pub(crate) const MAX_TEMP_STRING: u32 = 1024;

/// A standard-function call being compiled: its name, arguments and the type the context
/// expects of literal-only arguments.
pub(crate) struct StdArgs<'e> {
    pub(crate) name: &'e str,
    pub(crate) id: &'e Ident,
    pub(crate) exprs: Vec<&'e Expr>,
    pub(crate) ctx: Option<Type>,
    pub(crate) span: Span,
    /// The type of a typed form (`SQRT_LREAL`, `MAX_DINT`): its typed arguments convert
    /// to it implicitly and it is the result.
    pub(crate) typed: Option<Elem>,
}

impl<'e> StdArgs<'e> {
    /// A call of `name` (of its typed form of type `typed`, if it is one: `SQRT` and
    /// `LREAL` for `SQRT_LREAL`) by `id` with the arguments `exprs` in the order of its
    /// inputs, `ctx` being the numeric type the context asks of literal-only arguments.
    pub(crate) fn new(
        (name, typed): (&'e str, Option<Elem>),
        id: &'e Ident,
        exprs: Vec<&'e Expr>,
        ctx: Option<Type>,
        span: Span,
    ) -> Self {
        StdArgs {
            name,
            id,
            exprs,
            ctx: typed.map(Type::Elem).or(ctx),
            span,
            typed,
        }
    }
}

/// A family of standard functions (a function of its own checks and emits each).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum StdFamily {
    /// SQRT and the other REAL functions, EXPT, ATAN2, ABS, TRUNC and the typed
    /// truncations, __NOW, TIME, LTIME.
    Numeric,
    /// MOVE, SEL, MAX, MIN, LIMIT, MUX.
    Selection,
    /// SHL, SHR, ROL, ROR.
    Bits,
    /// LEN, LEFT, RIGHT, MID, DELETE, INSERT, REPLACE, FIND, CONCAT.
    Strings,
    /// `A_TO_B` (anything else is looked up there).
    Conversion,
}

impl StdFamily {
    /// The family of the standard function `name` (without a typed form's suffix).
    pub(crate) fn of(name: &str) -> StdFamily {
        match name {
            "SQRT" | "LN" | "LOG" | "EXP" | "SIN" | "COS" | "TAN" | "ASIN" | "ACOS" | "ATAN"
            | "EXPT" | "ABS" | "TRUNC" | "__NOW" | "ATAN2" | "TIME" | "LTIME" => StdFamily::Numeric,
            _ if Gen::typed_trunc(name).is_some() => StdFamily::Numeric,
            "MOVE" | "SEL" | "MAX" | "MIN" | "LIMIT" | "MUX" => StdFamily::Selection,
            "SHL" | "SHR" | "ROL" | "ROR" => StdFamily::Bits,
            "LEN" | "LEFT" | "RIGHT" | "MID" | "DELETE" | "INSERT" | "REPLACE" | "FIND"
            | "CONCAT" => StdFamily::Strings,
            _ => StdFamily::Conversion,
        }
    }
}

/// The input and the output targets (one per part of `parts`) of a SPLIT_ call with the
/// arguments `args`, given formally (`YEAR => y`) or in order after the input, and the
/// arguments that are neither (an unknown output, or anything else).
pub(crate) fn split_arguments<'e>(
    parts: &[&str],
    args: &'e [Arg],
) -> (Option<&'e Expr>, Vec<Option<&'e Expr>>, Vec<&'e Arg>) {
    let mut input = None;
    let mut targets = vec![None; parts.len()];
    let mut misfits = Vec::new();
    for (i, a) in args.iter().enumerate() {
        match (&a.name, a.output) {
            (None, _) if i == 0 => input = Some(&a.value),
            (Some(n), false) if n.name == "IN" => input = Some(&a.value),
            (None, _) if i <= parts.len() => targets[i - 1] = Some(&a.value),
            (Some(n), true) => match parts.iter().position(|p| *p == n.name) {
                Some(k) => targets[k] = Some(&a.value),
                None => misfits.push(a),
            },
            _ => misfits.push(a),
        }
    }
    (input, targets, misfits)
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
    pub(crate) fn typed_trunc(name: &str) -> Option<(Option<Elem>, Elem)> {
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
    pub(crate) fn time_function(name: &str) -> Option<TimeFunction> {
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

    /// Emits a call of the standard function `name` (the callee `id`) as the checker
    /// ([`crate::sema::stdcall`]) passed it; `None` if `name` is not a standard function.
    pub(crate) fn std_call(
        &mut self,
        name: &str,
        id: &Ident,
        args: &[Arg],
        expected: Option<&Type>,
        span: Span,
    ) -> Option<Type> {
        let ctx = Self::literal_context(expected);
        if let Some(f) = Self::time_function(name) {
            return Some(self.std_time(f, id, args, expected, span));
        }
        if name == "SIZEOF" {
            return Some(self.std_sizeof(args, expected));
        }
        if let Some(target) = name.strip_prefix("TO_") {
            return self.generic_conversion(target, id, args, span);
        }
        let (name, typed) = match Self::typed_overload(name) {
            Some((base, t)) => (base, Some(t)),
            None => (name, None),
        };
        let Some(exprs) = self.std_arguments(id, args) else {
            return Some(Type::Error);
        };
        let c = StdArgs::new((name, typed), id, exprs, ctx, span);
        match StdFamily::of(name) {
            StdFamily::Numeric => self.std_numeric(&c),
            StdFamily::Selection => self.std_selection(&c),
            StdFamily::Bits => self.std_bits(&c),
            StdFamily::Strings => self.std_string(&c),
            StdFamily::Conversion => self.conversion(name, id, &c.exprs, span),
        }
    }

    /// The numeric type the context `expected` asks of literal-only arguments (they adapt
    /// to it).
    pub(crate) fn literal_context(expected: Option<&Type>) -> Option<Type> {
        expected
            .filter(|t| {
                t.elem().is_some_and(|e| e.is_numeric())
                    && !matches!(t, Type::Enum(_) | Type::Exception)
            })
            .map(|t| Type::Elem(t.elem().unwrap_or(Elem::DInt)))
    }

    /// A typed form of an overloaded standard function (IEC 61131-3: `SQRT_LREAL`,
    /// `ABS_INT`, `MAX_DINT`, `EXPT_REAL`, `SEL_TIME`, ...): (the function, the type).
    pub(crate) fn typed_overload(name: &str) -> Option<(&str, Elem)> {
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

    /// The formal input names of a standard function called with `count` arguments
    /// (IEC 61131-3: `IN`, `IN1`.., `G`, `K`, `MN`, `MX`, `N`, `L`, `P`, `YEAR`, ...).
    pub(crate) fn std_formals(name: &str, count: usize) -> Vec<String> {
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

    /// The argument expressions of a standard function in the order of its inputs, as the
    /// checker placed them ([`crate::typed::StdArguments`]).
    fn std_arguments<'e>(&mut self, id: &Ident, args: &'e [Arg]) -> Option<Vec<&'e Expr>> {
        let Some(order) = self.std_arguments.of(self.cur, id) else {
            self.missing_record(id.span, "placed no arguments for this call");
            return None;
        };
        Some(order.iter().map(|&i| &args[i].value).collect())
    }

    /// `TO_INT(x)`, `TO_STRING(x)`, ... (IEC 61131-3 3rd edition): the conversion from the
    /// argument's type the checker recorded ([`crate::typed::GenericTypes`]).
    fn generic_conversion(
        &mut self,
        target: &str,
        id: &Ident,
        args: &[Arg],
        span: Span,
    ) -> Option<Type> {
        if target != "STRING" && Elem::from_name(target).is_none() {
            return None;
        }
        let inputs = self.std_arguments(id, args)?;
        let [arg] = inputs[..] else {
            self.missing_record(span, "passed a conversion without one argument");
            return Some(Type::Error);
        };
        let Some(source) = self.recorded_generic_type(id) else {
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

    /// Date and time functions (see [`TimeFunction`]).
    fn std_time(
        &mut self,
        f: TimeFunction,
        id: &Ident,
        args: &[Arg],
        expected: Option<&Type>,
        span: Span,
    ) -> Type {
        if let TimeFunction::Split(t) = f {
            return self.std_split(t, args, span);
        }
        let Some(exprs) = self.std_arguments(id, args) else {
            return Type::Error;
        };
        match f {
            TimeFunction::Operator(op, ..) => self.binary(op, exprs[0], exprs[1], expected, span),
            TimeFunction::DateTod(result) => {
                let (date, tod) = Self::date_and_time_of(result);
                self.value_to(exprs[0], &Type::Elem(date));
                self.value_to(exprs[1], &Type::Elem(tod));
                self.op(Opcode::Add);
                Type::Elem(result)
            }
            TimeFunction::Concat(result) => {
                let (date_parts, tod_parts) = Self::concat_parts(result);
                if date_parts > 0 {
                    for e in &exprs[..date_parts] {
                        self.int_arg(e);
                    }
                    self.emit(|b| b.call_builtin(Builtin::DateFromParts));
                }
                if tod_parts > 0 {
                    for e in &exprs[date_parts..] {
                        self.int_arg(e);
                    }
                    self.emit(|b| b.call_builtin(Builtin::TodFromParts));
                }
                if date_parts > 0 && tod_parts > 0 {
                    self.op(Opcode::Add);
                }
                Type::Elem(result)
            }
            TimeFunction::DayOfWeek => {
                self.expr(exprs[0], None);
                self.emit(|b| b.call_builtin(Builtin::DayOfWeek));
                Type::INT
            }
            TimeFunction::Split(_) => unreachable!("handled above"),
        }
    }

    /// The date and the time of day types CONCAT_DATE_TOD (`result` DT) or
    /// CONCAT_DATE_LTOD (LDT) joins.
    pub(crate) fn date_and_time_of(result: Elem) -> (Elem, Elem) {
        if result == Elem::LDt {
            (Elem::LDate, Elem::LTod)
        } else {
            (Elem::Date, Elem::Tod)
        }
    }

    /// How many date parts (year, month, day) and time parts (hour, minute, second,
    /// millisecond) CONCAT_DATE, CONCAT_TOD or CONCAT_DT (its `result` type) takes.
    pub(crate) fn concat_parts(result: Elem) -> (usize, usize) {
        match result.temporal_family() {
            Some(Elem::Date) => (3, 0),
            Some(Elem::Tod) => (0, 4),
            _ => (3, 4),
        }
    }

    /// SIZEOF(variable or type): its size in bytes in data memory, a constant of the
    /// integer type the context wants (UDINT without one).
    fn std_sizeof(&mut self, args: &[Arg], expected: Option<&Type>) -> Type {
        let [arg] = args else {
            return Type::Error;
        };
        let ty = self.sizeof_operand(&arg.value);
        let (size, result) = self.sizeof_value(&ty, expected);
        self.push_int(size as i64);
        Type::Elem(result)
    }

    /// The type SIZEOF measures: of the type named `e`, else of the variable or expression.
    pub(crate) fn sizeof_operand(&mut self, e: &Expr) -> Type {
        match &e.kind {
            ExprKind::Name(n)
                if self.prog.pous[self.cur].var(&n.name).is_none()
                    && self.prog.global(&n.name).is_none() =>
            {
                match self.type_by_name(&n.name) {
                    Some(t) => t,
                    None => self.infer(e),
                }
            }
            _ => self.infer(e),
        }
    }

    /// The size SIZEOF gives for `ty` and its type where `expected` is wanted. A STRING[n]
    /// counts its text and terminator, n + 1 bytes as in CODESYS: what a byte pointer to it
    /// (`ADR(s)`) may walk (its length header is not part of that).
    pub(crate) fn sizeof_value(&self, ty: &Type, expected: Option<&Type>) -> (i128, Elem) {
        let size = match ty {
            Type::String(n) => *n as i128 + 1,
            _ => self.prog.size_align(ty).0 as i128,
        };
        let result = expected
            .and_then(|t| t.elem())
            .filter(|e| {
                e.is_integral()
                    && !matches!(expected, Some(Type::Enum(_)))
                    && e.int_range().1 >= size
            })
            .unwrap_or(Elem::UDInt);
        (size, result)
    }

    /// The data type called `name` (elementary, STRING, a TYPE or a function block).
    pub(crate) fn type_by_name(&self, name: &str) -> Option<Type> {
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

    /// The parts SPLIT_DATE, SPLIT_TOD or SPLIT_DT (splitting `input_type`) gives.
    pub(crate) fn split_parts(input_type: Elem) -> Vec<&'static str> {
        match input_type.temporal_family() {
            Some(Elem::Date) => YEAR_MONTH_DAY.to_vec(),
            Some(Elem::Tod) => HOUR_MINUTE_SECOND_MS.to_vec(),
            _ => YEAR_MONTH_DAY
                .iter()
                .chain(HOUR_MINUTE_SECOND_MS.iter())
                .copied()
                .collect(),
        }
    }

    /// SPLIT_DATE(IN, YEAR, MONTH, DAY), SPLIT_TOD(IN, HOUR, MINUTE, SECOND, MILLISECOND),
    /// SPLIT_DT(IN, YEAR, ..., MILLISECOND): the parts go to the outputs, given formally
    /// (`YEAR => y`) or in order after the input ([`split_arguments`]).
    fn std_split(&mut self, input_type: Elem, args: &[Arg], span: Span) -> Type {
        let parts = Self::split_parts(input_type);
        let (input, targets, _) = split_arguments(&parts, args);
        let Some(input) = input else {
            self.missing_record(span, "passed a SPLIT_ call without its input");
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

    /// Numeric functions: SQRT and the other REAL functions, EXPT, ABS, TRUNC, __NOW.
    pub(super) fn std_numeric(&mut self, c: &StdArgs) -> Option<Type> {
        let t = match c.name {
            "SQRT" | "LN" | "LOG" | "EXP" | "SIN" | "COS" | "TAN" | "ASIN" | "ACOS" | "ATAN" => {
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
                let rt = match self.real_operand(c) {
                    Some(t) => t,
                    None => return Some(Type::Error),
                };
                let t1 = self.infer(c.exprs[1]);
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
                match c.typed {
                    Some(forced) => self.value_to(c.exprs[0], &Type::Elem(forced)),
                    None => {
                        self.expr(c.exprs[0], c.ctx.as_ref());
                    }
                }
                let Some(e) = self.argument_type(c) else {
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
                let (from, target) = Self::trunc_types(c);
                let rt = match from {
                    Some(f) => {
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
                self.op(Opcode::Now);
                Self::clock_type(c.name)
            }
            _ => unreachable!("std_numeric called for {}", c.name),
        };
        Some(t)
    }

    /// The type `__NOW()`, `TIME()` or `LTIME()` (`name`) gives.
    pub(crate) fn clock_type(name: &str) -> Type {
        if name == "LTIME" {
            Type::Elem(Elem::LTime)
        } else {
            Type::TIME
        }
    }

    /// The type TRUNC (or a typed truncation, `REAL_TRUNC_INT`) of the call `c` converts
    /// from (`None`: a REAL or LREAL by its argument) and to: a typed form's, else the
    /// integer type the context wants (IEC: ANY_INT), else DINT.
    pub(crate) fn trunc_types(c: &StdArgs) -> (Option<Elem>, Elem) {
        match Self::typed_trunc(c.name) {
            Some(typed) => typed,
            None => (
                None,
                c.ctx
                    .as_ref()
                    .and_then(|t| t.elem())
                    .filter(|e| e.is_integral())
                    .unwrap_or(Elem::DInt),
            ),
        }
    }

    /// Selection: MOVE, SEL, MAX/MIN, LIMIT, MUX.
    pub(super) fn std_selection(&mut self, c: &StdArgs) -> Option<Type> {
        let t = match c.name {
            "MOVE" => match c.typed {
                Some(forced) => {
                    self.value_to(c.exprs[0], &Type::Elem(forced));
                    Type::Elem(forced)
                }
                None => self.expr(c.exprs[0], None),
            },
            "SEL" => {
                self.value_to(c.exprs[0], &Type::BOOL);
                let t = self.generic_type(c);
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
                let t = self.generic_type(c);
                let Some(e) = t.elem() else {
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
                let t = self.generic_type(c);
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
                self.expr(c.exprs[0], Some(&Type::DINT));
                let n = c.exprs.len() as i64 - 1;
                let k = self.temp_cell();
                self.emit(|b| {
                    b.chk_index(0, n - 1);
                    b.st_abs(MemType::I64, k);
                });
                let t = self.generic_type(c);
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
                self.expr(c.exprs[0], None);
                let Some(e) = self.argument_type(c) else {
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

    /// Compiles the (first) argument of a REAL function in the type the call computes in
    /// and returns it: the typed form's (`SQRT_LREAL`), else the one the checker recorded
    /// ([`crate::typed::GenericTypes`]).
    fn real_operand(&mut self, c: &StdArgs) -> Option<Elem> {
        let e = c.exprs[0];
        if let Some(forced) = c.typed.filter(|t| t.is_real()) {
            self.value_to(e, &Type::Elem(forced));
            return Some(forced);
        }
        let t = self.infer(e);
        let target = self.recorded_generic_type(c.id)?.elem()?;
        self.value_to_any(e, &t, &Type::Elem(target));
        Some(target)
    }

    /// The type the call `c` computes in, as the checker recorded it.
    fn argument_type(&mut self, c: &StdArgs) -> Option<Elem> {
        self.recorded_generic_type(c.id)?.elem()
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

    /// The type a selection function (SEL, MAX, MIN, LIMIT, MUX) is called at: the typed
    /// form's, else the one the checker recorded.
    fn generic_type(&mut self, c: &StdArgs) -> Type {
        match c.typed {
            Some(forced) => Type::Elem(forced),
            None => self.recorded_generic_type(c.id).unwrap_or(Type::Error),
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
