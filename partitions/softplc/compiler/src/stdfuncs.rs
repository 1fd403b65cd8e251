//! Standard functions of IEC 61131-3 (numeric, selection, bit shifts, type conversions,
//! strings) compiled inline or to `CALL_BUILTIN`.
//!
//! Conventions: REAL->integer conversions round to nearest (ties away from zero), `TRUNC`
//! truncates; TIME<->number conversions count milliseconds; string results go to a static
//! temporary per call site.

use plc_vm::isa::{Builtin, MemType, Opcode, RoundMode};

use crate::ast::*;
use crate::codegen::{Gen, mem_type};
use crate::diagnostics::Span;
use crate::types::*;

/// Maximum length of the temporaries that hold string function results.
const MAX_TEMP_STRING: u32 = 1024;

/// A standard-function call being compiled: its name, arguments and the type the context
/// expects of literal-only arguments.
struct StdArgs<'e> {
    name: &'e str,
    id: &'e Ident,
    exprs: Vec<&'e Expr>,
    ctx: Option<Type>,
    span: Span,
}

impl Gen<'_> {
    /// Compiles a standard function call; `None` if `name` is not a standard function.
    /// Whether `name` is a standard function handled here.
    pub(crate) fn is_std_function(name: &str) -> bool {
        const NAMES: &[&str] = &[
            "SQRT", "LN", "LOG", "EXP", "SIN", "COS", "TAN", "ASIN", "ACOS", "ATAN", "EXPT", "ABS",
            "TRUNC", "__NOW", "MOVE", "SEL", "MAX", "MIN", "LIMIT", "MUX", "SHL", "SHR", "ROL",
            "ROR", "LEN", "LEFT", "RIGHT", "MID", "DELETE", "INSERT", "REPLACE", "FIND", "CONCAT",
        ];
        NAMES.contains(&name) || name.contains("_TO_")
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
        // Standard functions take their arguments in order; formal names are accepted but
        // not reordered.
        if let Some(a) = args.iter().find(|a| a.output) {
            self.error(a.span, format!("{} has no outputs", id.text));
        }
        let c = StdArgs {
            name,
            id,
            exprs: args.iter().map(|a| &a.value).collect(),
            ctx,
            span,
        };
        match name {
            "SQRT" | "LN" | "LOG" | "EXP" | "SIN" | "COS" | "TAN" | "ASIN" | "ACOS" | "ATAN"
            | "EXPT" | "ABS" | "TRUNC" | "__NOW" => self.std_numeric(&c),
            "MOVE" | "SEL" | "MAX" | "MIN" | "LIMIT" | "MUX" => self.std_selection(&c),
            "SHL" | "SHR" | "ROL" | "ROR" => self.std_bits(&c),
            "LEN" | "LEFT" | "RIGHT" | "MID" | "DELETE" | "INSERT" | "REPLACE" | "FIND"
            | "CONCAT" => self.std_string(&c),
            _ => self.conversion(name, id, &c.exprs, span),
        }
    }

    /// False (after reporting it and type-checking the arguments) unless the call has
    /// exactly `n` arguments.
    fn arity(&mut self, c: &StdArgs, n: usize) -> bool {
        if c.exprs.len() == n {
            return true;
        }
        self.error(
            c.span,
            format!(
                "{} takes {} argument(s), {} given",
                c.id.text,
                n,
                c.exprs.len()
            ),
        );
        for e in &c.exprs {
            self.infer(e);
        }
        false
    }

    /// Numeric functions: SQRT and the other REAL functions, EXPT, ABS, TRUNC, __NOW.
    fn std_numeric(&mut self, c: &StdArgs) -> Option<Type> {
        let t = match c.name {
            "SQRT" | "LN" | "LOG" | "EXP" | "SIN" | "COS" | "TAN" | "ASIN" | "ACOS" | "ATAN" => {
                if !self.arity(c, 1) {
                    return Some(Type::Error);
                }
                let rt = self.real_operand(c.exprs[0], c.ctx.as_ref())?;
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
            "EXPT" => {
                if !self.arity(c, 2) {
                    return Some(Type::Error);
                }
                let rt = self.real_operand(c.exprs[0], c.ctx.as_ref())?;
                let t1 = self.infer(c.exprs[1]);
                self.value_to_any(c.exprs[1], &t1, &Type::Elem(rt));
                self.emit(|bb| {
                    bb.call_builtin(if rt == Elem::Real {
                        Builtin::ExptF32
                    } else {
                        Builtin::ExptF64
                    })
                });
                Type::Elem(rt)
            }
            "ABS" => {
                if !self.arity(c, 1) {
                    return Some(Type::Error);
                }
                let t = self.expr(c.exprs[0], c.ctx.as_ref());
                match t.elem() {
                    Some(Elem::Real) => self.emit(|b| b.call_builtin(Builtin::AbsF32)),
                    Some(Elem::LReal) => self.emit(|b| b.call_builtin(Builtin::AbsF64)),
                    Some(e)
                        if (e.is_signed_int() || e == Elem::Time)
                            && !matches!(t, Type::Enum(_) | Type::Exception) =>
                    {
                        self.op(Opcode::AbsS);
                        self.wrap(e);
                    }
                    Some(e) if e.is_integral() && !matches!(t, Type::Enum(_) | Type::Exception) => {
                    }
                    _ => return Some(self.bad_arg(c.exprs[0], &t, "a number")),
                }
                match t {
                    Type::Subrange(e, ..) => Type::Elem(e),
                    t => t,
                }
            }
            "TRUNC" => {
                if !self.arity(c, 1) {
                    return Some(Type::Error);
                }
                let rt = self.real_operand(c.exprs[0], c.ctx.as_ref())?;
                let op = if rt == Elem::Real {
                    Opcode::F32ToInt
                } else {
                    Opcode::F64ToInt
                };
                self.emit(|b| b.float_to_int(op, MemType::I32, RoundMode::Truncate));
                Type::DINT
            }
            "__NOW" => {
                if !self.arity(c, 0) {
                    return Some(Type::Error);
                }
                self.op(Opcode::Now);
                Type::TIME
            }
            _ => unreachable!("std_numeric called for {}", c.name),
        };
        Some(t)
    }

    /// Selection: MOVE, SEL, MAX/MIN, LIMIT, MUX.
    fn std_selection(&mut self, c: &StdArgs) -> Option<Type> {
        let t = match c.name {
            "MOVE" => {
                if !self.arity(c, 1) {
                    return Some(Type::Error);
                }
                self.expr(c.exprs[0], None)
            }
            "SEL" => {
                if !self.arity(c, 3) {
                    return Some(Type::Error);
                }
                self.value_to(c.exprs[0], &Type::BOOL);
                let t = self.common_of(&c.exprs[1..], c.ctx.as_ref());
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
                if c.exprs.len() < 2 {
                    self.error(c.span, format!("{} needs at least 2 arguments", c.id.text));
                    return Some(Type::Error);
                }
                let t = self.common_of(&c.exprs, c.ctx.as_ref());
                let Some(e) = t.elem() else {
                    if !t.is_error() {
                        let msg = format!(
                            "{} needs numeric, TIME or enumeration arguments, found {}",
                            c.id.text,
                            self.tname(&t)
                        );
                        self.error(c.span, msg);
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
                let t = self.common_of(&c.exprs, c.ctx.as_ref());
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
                if c.exprs.len() < 2 {
                    self.error(c.span, "MUX needs a selector and at least one input");
                    return Some(Type::Error);
                }
                let kt = self.expr(c.exprs[0], Some(&Type::DINT));
                if !kt.elem().is_some_and(|e| e.is_integral()) && !kt.is_error() {
                    return Some(self.bad_arg(c.exprs[0], &kt, "an integer selector"));
                }
                let n = c.exprs.len() as i64 - 1;
                let k = self.temp_cell();
                self.emit(|b| {
                    b.chk_index(0, n - 1);
                    b.st_abs(MemType::I64, k);
                });
                let t = self.common_of(&c.exprs[1..], c.ctx.as_ref());
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
    fn std_bits(&mut self, c: &StdArgs) -> Option<Type> {
        let t = match c.name {
            "SHL" | "SHR" | "ROL" | "ROR" => {
                if !self.arity(c, 2) {
                    return Some(Type::Error);
                }
                let t = self.expr(c.exprs[0], None);
                let Some(e) = t
                    .elem()
                    .filter(|e| e.is_integral() && !matches!(t, Type::Enum(_) | Type::Exception))
                else {
                    return Some(self.bad_arg(c.exprs[0], &t, "a bit string or integer"));
                };
                self.value_to(c.exprs[1], &Type::LINT);
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

    /// String functions: LEN, LEFT/RIGHT, MID/DELETE, INSERT, REPLACE, FIND, CONCAT.
    fn std_string(&mut self, c: &StdArgs) -> Option<Type> {
        let t = match c.name {
            "LEN" => {
                if !self.arity(c, 1) {
                    return Some(Type::Error);
                }
                self.string_arg(c.exprs[0]);
                self.emit(|b| b.call_builtin(Builtin::StrLen));
                Type::INT
            }
            "LEFT" | "RIGHT" => {
                if !self.arity(c, 2) {
                    return Some(Type::Error);
                }
                let len = self.string_len_of(c.exprs[0]);
                let dst = self.temp_string(len);
                self.emit(|b| b.push_u32(dst));
                self.string_arg(c.exprs[0]);
                self.int_arg(c.exprs[1]);
                self.emit(|b| {
                    b.call_builtin(if c.name == "LEFT" {
                        Builtin::StrLeft
                    } else {
                        Builtin::StrRight
                    })
                });
                self.emit(|b| b.push_u32(dst));
                Type::String(len)
            }
            "MID" | "DELETE" => {
                if !self.arity(c, 3) {
                    return Some(Type::Error);
                }
                let len = self.string_len_of(c.exprs[0]);
                let dst = self.temp_string(len);
                self.emit(|b| b.push_u32(dst));
                self.string_arg(c.exprs[0]);
                self.int_arg(c.exprs[1]);
                self.int_arg(c.exprs[2]);
                self.emit(|b| {
                    b.call_builtin(if c.name == "MID" {
                        Builtin::StrMid
                    } else {
                        Builtin::StrDelete
                    })
                });
                self.emit(|b| b.push_u32(dst));
                Type::String(len)
            }
            "INSERT" => {
                if !self.arity(c, 3) {
                    return Some(Type::Error);
                }
                let len = (self.string_len_of(c.exprs[0]) + self.string_len_of(c.exprs[1]))
                    .min(MAX_TEMP_STRING);
                let dst = self.temp_string(len);
                self.emit(|b| b.push_u32(dst));
                self.string_arg(c.exprs[0]);
                self.string_arg(c.exprs[1]);
                self.int_arg(c.exprs[2]);
                self.emit(|b| {
                    b.call_builtin(Builtin::StrInsert);
                    b.push_u32(dst);
                });
                Type::String(len)
            }
            "REPLACE" => {
                if !self.arity(c, 4) {
                    return Some(Type::Error);
                }
                let len = (self.string_len_of(c.exprs[0]) + self.string_len_of(c.exprs[1]))
                    .min(MAX_TEMP_STRING);
                let dst = self.temp_string(len);
                self.emit(|b| b.push_u32(dst));
                self.string_arg(c.exprs[0]);
                self.string_arg(c.exprs[1]);
                self.int_arg(c.exprs[2]);
                self.int_arg(c.exprs[3]);
                self.emit(|b| {
                    b.call_builtin(Builtin::StrReplace);
                    b.push_u32(dst);
                });
                Type::String(len)
            }
            "FIND" => {
                if !self.arity(c, 2) {
                    return Some(Type::Error);
                }
                self.string_arg(c.exprs[0]);
                self.string_arg(c.exprs[1]);
                self.emit(|b| b.call_builtin(Builtin::StrFind));
                Type::INT
            }
            "CONCAT" => {
                if c.exprs.is_empty() {
                    self.error(c.span, "CONCAT needs arguments");
                    return Some(Type::Error);
                }
                let len = c
                    .exprs
                    .iter()
                    .map(|e| self.string_len_of(e))
                    .sum::<u32>()
                    .clamp(1, MAX_TEMP_STRING);
                let dst = self.temp_string(len);
                // dst := first; then dst := CONCAT(dst, next) for the rest.
                self.emit(|b| b.push_u32(dst));
                self.string_arg(c.exprs[0]);
                self.emit(|b| b.call_builtin(Builtin::StrAssign));
                for x in &c.exprs[1..] {
                    self.emit(|b| {
                        b.push_u32(dst);
                        b.push_u32(dst);
                    });
                    self.string_arg(x);
                    self.emit(|b| b.call_builtin(Builtin::StrConcat));
                }
                self.emit(|b| b.push_u32(dst));
                Type::String(len)
            }

            _ => unreachable!("std_string called for {}", c.name),
        };
        Some(t)
    }

    fn bad_arg(&mut self, e: &Expr, t: &Type, what: &str) -> Type {
        if !t.is_error() {
            let msg = format!("expected {what}, found {}", self.tname(t));
            self.error(e.span, msg);
        }
        Type::Error
    }

    /// Compiles a numeric argument of a REAL function: REAL stays REAL, everything else LREAL.
    fn real_operand(&mut self, e: &Expr, ctx: Option<&Type>) -> Option<Elem> {
        let t = self.infer(e);
        let literal_in_real_context =
            Self::is_flexible(e) && ctx.and_then(|c| c.elem()) == Some(Elem::Real);
        let target = if t.elem() == Some(Elem::Real) || literal_in_real_context {
            Elem::Real
        } else {
            Elem::LReal
        };
        match t.elem() {
            Some(x) if x.is_numeric() && !matches!(t, Type::Enum(_) | Type::Exception) => {
                self.value_to_any(e, &t, &Type::Elem(target));
                Some(target)
            }
            _ => {
                if !t.is_error() {
                    let msg = format!("expected a number, found {}", self.tname(&t));
                    self.error(e.span, msg);
                }
                None
            }
        }
    }

    /// Common type of several arguments (for SEL/MAX/MIN/LIMIT/MUX).
    fn common_of(&mut self, exprs: &[&Expr], ctx: Option<&Type>) -> Type {
        let mut acc: Option<Type> = None;
        for e in exprs {
            if Self::is_flexible(e) {
                continue;
            }
            let t = self.infer(e);
            if t.is_error() {
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
                                self.error(e.span, msg);
                                return Type::Error;
                            }
                        }
                    }
                    _ if a.is_string() && t.is_string() => a,
                    _ => {
                        let msg = format!(
                            "arguments of incompatible types {} and {}",
                            self.tname(&a),
                            self.tname(&t)
                        );
                        self.error(e.span, msg);
                        return Type::Error;
                    }
                },
            });
        }
        match acc {
            Some(Type::Subrange(e, ..)) => Type::Elem(e),
            Some(t) => {
                if exprs
                    .iter()
                    .any(|e| Self::is_flexible(e) && Self::has_real_literal(e))
                    && !t.elem().is_some_and(|x| x.is_real())
                {
                    Type::LREAL
                } else {
                    t
                }
            }
            None => {
                if let Some(c) = ctx.filter(|c| {
                    !exprs.iter().any(|e| Self::has_real_literal(e))
                        || c.elem().is_some_and(|x| x.is_real())
                }) {
                    c.clone()
                } else if exprs.iter().any(|e| Self::has_real_literal(e)) {
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
    fn select_min_max(&mut self, max: bool, e: Elem) {
        let (lt, gt) = match e {
            Elem::Real => (Opcode::LtF32, Opcode::GtF32),
            Elem::LReal => (Opcode::LtF64, Opcode::GtF64),
            e if e.is_unsigned_int() || e.is_bits() => (Opcode::LtU, Opcode::GtU),
            _ => (Opcode::LtS, Opcode::GtS),
        };
        self.emit(|b| b.sel_if(if max { lt } else { gt }));
    }

    fn string_arg(&mut self, e: &Expr) {
        let t = self.expr(e, None);
        if !t.is_string() && !t.is_error() {
            let msg = format!("expected a STRING, found {}", self.tname(&t));
            self.error(e.span, msg);
        }
    }

    fn int_arg(&mut self, e: &Expr) {
        let t = self.infer(e);
        if !t.elem().is_some_and(|x| x.is_integral())
            || matches!(t, Type::Enum(_) | Type::Exception)
        {
            if !t.is_error() {
                let msg = format!("expected an integer, found {}", self.tname(&t));
                self.error(e.span, msg);
            }
            self.expr(e, None);
            return;
        }
        self.value_to_any(e, &t, &Type::LINT);
    }

    fn string_len_of(&mut self, e: &Expr) -> u32 {
        match self.infer(e) {
            Type::String(n) => n,
            _ => DEFAULT_STRING_LEN,
        }
    }

    /// `A_TO_B` conversions (and `TO_B` is not supported).
    fn conversion(&mut self, name: &str, id: &Ident, exprs: &[&Expr], span: Span) -> Option<Type> {
        let (from, to) = name.split_once("_TO_")?;
        let parse = |s: &str| -> Option<Type> {
            if s == "STRING" {
                Some(Type::String(DEFAULT_STRING_LEN))
            } else {
                Elem::from_name(s).map(Type::Elem)
            }
        };
        let (Some(ft), Some(tt)) = (parse(from), parse(to)) else {
            return None;
        };
        if exprs.len() != 1 {
            self.error(
                span,
                format!("{} takes 1 argument, {} given", id.text, exprs.len()),
            );
            return Some(Type::Error);
        }
        let arg = exprs[0];
        match (&ft, &tt) {
            (Type::String(_), Type::String(_)) => {
                self.string_arg(arg);
                Some(Type::String(DEFAULT_STRING_LEN))
            }
            (Type::String(_), Type::Elem(t)) => {
                self.string_arg(arg);
                if t.is_real() {
                    self.emit(|b| b.call_builtin(Builtin::StrToF64));
                    self.convert(Elem::LReal, *t);
                } else if *t == Elem::Time {
                    self.error(span, "STRING_TO_TIME is not supported");
                    return Some(Type::Error);
                } else {
                    self.emit(|b| b.call_builtin(Builtin::StrToI64));
                    if *t == Elem::Bool {
                        self.convert(Elem::LInt, Elem::Bool);
                    } else {
                        self.wrap(*t);
                    }
                }
                Some(tt)
            }
            (Type::Elem(f), Type::String(_)) => {
                let f = *f;
                let dst = self.temp_string(40);
                self.emit(|b| b.push_u32(dst));
                self.value_to(arg, &ft);
                let bi = match f {
                    Elem::Real => Builtin::StrFromF32,
                    Elem::LReal => Builtin::StrFromF64,
                    Elem::Bool => Builtin::StrFromBool,
                    Elem::Time => Builtin::StrFromTime,
                    e if e.is_signed_int() => Builtin::StrFromI64,
                    _ => Builtin::StrFromU64,
                };
                self.emit(|b| {
                    b.call_builtin(bi);
                    b.push_u32(dst);
                });
                Some(Type::String(40))
            }
            (Type::Elem(f), Type::Elem(t)) => {
                let (f, t) = (*f, *t);
                let at = self.infer(arg);
                if at.is_error() {
                    return Some(Type::Error);
                }
                match at.elem() {
                    Some(ae)
                        if !matches!(at, Type::Enum(_) | Type::Exception)
                            && (ae == f || implicit_ok(ae, f)) => {}
                    _ if Self::is_flexible(arg) => {}
                    _ => {
                        let msg = format!(
                            "{} expects a {} argument, found {}",
                            id.text,
                            f,
                            self.tname(&at)
                        );
                        self.error(arg.span, msg);
                        return Some(Type::Error);
                    }
                }
                self.value_to(arg, &ft);
                self.convert(f, t);
                let _ = mem_type(t);
                Some(tt)
            }
            _ => None,
        }
    }
}
