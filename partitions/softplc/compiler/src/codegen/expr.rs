//! Expressions: inference, implicit conversions, literals and unary operators.

use super::*;
use crate::sema::expr::{
    char_literal_type, int_literal_type, real_literal_type, string_literal_type,
    typed_literal_value, wstring_literal_type,
};
use crate::sema::ops::{Operation, UnaryRule};

impl Gen<'_> {
    /// Type of an expression without emitting code or reporting errors: the record of it
    /// (a missing one is an internal error). The lookups both passes share (a receiver, a
    /// string's length, SIZEOF's operand, a reference operation's operands) ask here; in the
    /// checking pass the expression checker infers the type ([`crate::sema::expr::infer`]).
    pub(crate) fn infer(&mut self, e: &Expr) -> Type {
        if self.check_only {
            return crate::sema::expr::infer(self, e);
        }
        if let Some(t) = self.types.of(e) {
            return t.clone();
        }
        self.missing_record(e.span, "recorded no type for this expression");
        Type::Error
    }

    /// Compiles `e` and converts the result to `to` (implicit conversions only, as the
    /// expression checker passed them: [`crate::sema::expr::value_to`]).
    pub(crate) fn value_to(&mut self, e: &Expr, to: &Type) {
        if to.is_pointer_like() && matches!(e.kind, ExprKind::Int(0)) {
            // The literal 0 is NULL.
            self.push_int(0);
            return;
        }
        if let Type::Reference(target) = to {
            // A REFERENCE TO parameter is bound to the argument (as `REF=` does).
            let as_ref = Type::Ref(target.clone());
            if matches!(e.kind, ExprKind::Null) {
                self.push_int(0);
                return;
            }
            let t = self.make_reference(e, Some(&as_ref));
            self.coerce(&t, &as_ref, e);
            return;
        }
        let t = self.expr(e, Some(to));
        self.coerce(&t, to, e);
    }

    /// Emits the implicit conversion of `e` from `from` to `to` the checker decided
    /// ([`crate::typed::Coercions`]; [`crate::sema::expr::coerce`]).
    pub(crate) fn coerce(&mut self, from: &Type, to: &Type, e: &Expr) {
        if from.is_error() || to.is_error() || from == to {
            return;
        }
        let implicit = match self.coercions.of(e) {
            Some(implicit) => *implicit,
            None => {
                return self
                    .missing_record(e.span, "decided no implicit conversion for this value");
            }
        };
        match implicit {
            Implicit::Nothing => {}
            Implicit::Convert(f, t) => self.convert(f, t),
            Implicit::AddressToInteger => self.emit(|b| b.op_width(Opcode::Zext, 32)),
        }
    }

    /// Emits the conversion of an elementary value (explicit conversions use this too).
    pub(crate) fn convert(&mut self, f: Elem, t: Elem) {
        if f == t {
            return;
        }
        if f.is_temporal() || t.is_temporal() {
            self.convert_temporal(f, t);
            return;
        }
        // Characters convert like the unsigned integers of their size.
        let as_int = |e: Elem| match e {
            Elem::Char => Elem::USInt,
            Elem::WChar => Elem::UInt,
            e => e,
        };
        if f.is_char() || t.is_char() {
            self.convert(as_int(f), as_int(t));
            return;
        }
        match (f.is_real(), t.is_real()) {
            (false, false) => {
                if t == Elem::Bool {
                    self.emit(|b| {
                        b.push_i32(0);
                        b.op(Opcode::Ne);
                    });
                } else if t.size() < f.size() || t.signed_storage() != f.signed_storage() {
                    self.wrap(t);
                }
            }
            (false, true) => {
                let signed = !(f.is_unsigned_int() || f.is_bits() && f.size() == 8);
                let op = match (t, signed) {
                    (Elem::Real, true) => Opcode::IToF32S,
                    (Elem::Real, false) => Opcode::IToF32U,
                    (_, true) => Opcode::IToF64S,
                    (_, false) => Opcode::IToF64U,
                };
                self.op(op);
            }
            (true, true) => self.op(if f == Elem::Real {
                Opcode::F32ToF64
            } else {
                Opcode::F64ToF32
            }),
            (true, false) => {
                let op = if f == Elem::Real {
                    Opcode::F32ToInt
                } else {
                    Opcode::F64ToInt
                };
                if t == Elem::Bool {
                    let zero_op = if f == Elem::Real {
                        Opcode::NeF32
                    } else {
                        Opcode::NeF64
                    };
                    self.emit(|b| {
                        if f == Elem::Real {
                            b.push_f32(0.0)
                        } else {
                            b.push_f64(0.0)
                        }
                        b.op(zero_op);
                    });
                } else {
                    self.emit(|b| b.float_to_int(op, mem_type(t), RoundMode::NearestTiesAway));
                }
            }
        }
    }

    /// Conversions to, from and between the date/time types. All hold nanoseconds; as
    /// numbers (CODESYS's conventions) TIME and TOD count milliseconds, DATE and DT seconds,
    /// the long forms nanoseconds. A DATE result is the midnight of its day, a TOD result
    /// lies within its day.
    pub(super) fn convert_temporal(&mut self, f: Elem, t: Elem) {
        fn unit(e: Elem) -> i64 {
            match e {
                Elem::Time | Elem::Tod => 1_000_000,
                Elem::Date | Elem::Dt => 1_000_000_000,
                _ => 1,
            }
        }
        if f.is_temporal() && !t.is_temporal() {
            let n = unit(f);
            if t == Elem::Bool {
                self.emit(|b| {
                    b.push_i32(0);
                    b.op(Opcode::Ne);
                });
            } else if t.is_real() {
                self.op(Opcode::IToF64S);
                if n != 1 {
                    self.emit(|b| {
                        b.push_f64(n as f64);
                        b.op(Opcode::DivF64);
                    });
                }
                if t == Elem::Real {
                    self.op(Opcode::F64ToF32);
                }
            } else {
                if n != 1 {
                    self.emit(|b| {
                        b.push_int(n);
                        b.op(Opcode::DivS);
                    });
                }
                let as_int = match t {
                    Elem::Char => Elem::USInt,
                    Elem::WChar => Elem::UInt,
                    e => e,
                };
                self.wrap(as_int);
            }
            return;
        }
        if !f.is_temporal() {
            let n = unit(t);
            if f.is_real() {
                if f == Elem::Real {
                    self.op(Opcode::F32ToF64);
                }
                self.emit(|b| {
                    b.push_f64(n as f64);
                    b.op(Opcode::MulF64);
                    b.float_to_int(Opcode::F64ToInt, MemType::I64, RoundMode::NearestTiesAway);
                });
            } else if n != 1 {
                self.emit(|b| {
                    b.push_int(n);
                    b.op(Opcode::Mul);
                });
            }
        }
        // Into the day: a DATE is a midnight, a TOD a time within its day.
        match t.temporal_family() {
            Some(Elem::Date) if f.temporal_family() != Some(Elem::Date) => {
                self.emit(|b| b.call_builtin(Builtin::DateOf))
            }
            Some(Elem::Tod) if f.temporal_family() != Some(Elem::Tod) => {
                self.emit(|b| b.call_builtin(Builtin::TodOf))
            }
            _ => {}
        }
    }

    /// Wraps the 64-bit cell on top of the stack to the width of `e`.
    pub(crate) fn wrap(&mut self, e: Elem) {
        let w = (e.size() * 8) as u8;
        if e == Elem::Bool {
            self.emit(|b| {
                b.push_i32(1);
                b.op(Opcode::And);
            });
        } else if w < 64 && !e.is_real() {
            let op = if e.is_signed_int() {
                Opcode::Sext
            } else {
                Opcode::Zext
            };
            self.emit(|b| b.op_width(op, w));
        }
    }

    /// Compiles an expression; `expected` guides the typing of untyped literals (as the
    /// expression checker typed them: [`crate::sema::expr`]).
    pub(crate) fn expr(&mut self, e: &Expr, expected: Option<&Type>) -> Type {
        match &e.kind {
            ExprKind::Error => Type::Error,
            ExprKind::Int(v) => self.int_literal(*v as i128, expected, e.span),
            ExprKind::Real(r) => {
                let elem = real_literal_type(expected);
                let r = *r;
                if elem == Elem::Real {
                    self.emit(|b| b.push_f32(r as f32));
                } else {
                    self.emit(|b| b.push_f64(r));
                }
                Type::Elem(elem)
            }
            ExprKind::Bool(v) => {
                self.push_int(*v as i64);
                Type::BOOL
            }
            ExprKind::Time(t) => {
                self.push_int(*t as i64);
                Type::TIME
            }
            ExprKind::Temporal(elem, t) => {
                self.push_int(*t as i64);
                Type::Elem(*elem)
            }
            // A one-character string literal where a CHAR or WCHAR is expected.
            ExprKind::Str(s) if let Some(elem) = char_literal_type(s, expected) => {
                let code = crate::sema::single_char(s).unwrap_or(0);
                self.push_int(code as i64);
                Type::Elem(elem)
            }
            ExprKind::WStr(s) => {
                let a = self.wstring_literal(s);
                self.emit(|b| b.push_u32(a));
                wstring_literal_type(s)
            }
            // A STRING literal where a WSTRING is expected is that WSTRING.
            ExprKind::Str(s) if matches!(expected, Some(Type::WString(_))) => {
                let a = self.wstring_literal(s);
                self.emit(|b| b.push_u32(a));
                wstring_literal_type(s)
            }
            ExprKind::Str(s) => {
                let a = self.string_literal(s);
                self.emit(|b| b.push_u32(a));
                string_literal_type(s)
            }
            ExprKind::Typed(ty, inner) => self.typed_literal(ty, inner, e.span),
            ExprKind::Name(n) => match self.bare_name(n) {
                Some(Bare::Property { class, getter }) => self.own_property_read(class, getter, e),
                Some(Bare::EnumValue { ty, value }) => {
                    self.push_int(value);
                    Type::Enum(ty)
                }
                Some(Bare::Exception(code)) => {
                    self.push_int(code);
                    Type::Exception
                }
                Some(Bare::Variable) => {
                    self.sync_if_byte_viewed(e);
                    match self.place(e) {
                        Some(p) => {
                            self.load(&p);
                            p.ty
                        }
                        None => Type::Error,
                    }
                }
                None => Type::Error,
            },
            ExprKind::Null => {
                self.push_int(0);
                Type::Null
            }
            ExprKind::Unary(op, x) => self.unary(*op, x, expected, e.span),
            ExprKind::Binary(op, a, b) => self.binary(*op, a, b, expected, e.span),
            ExprKind::This => self.this_expr(false, e.span),
            ExprKind::Super => self.this_expr(true, e.span),
            ExprKind::Member(..) if let Some(t) = self.property_read(e) => t,
            ExprKind::Call { callee, args } => self.call(callee, args, expected, e.span),
            ExprKind::Member(..)
            | ExprKind::Index(..)
            | ExprKind::Deref(..)
            | ExprKind::Bits { .. } => match self.place(e) {
                Some(p) => {
                    self.load(&p);
                    p.ty
                }
                None => Type::Error,
            },
        }
    }

    /// What bare name `n` denotes, as the checker recorded it.
    fn bare_name(&mut self, n: &Ident) -> Option<Bare> {
        let bare = self.bare_names.of(self.cur, n).cloned();
        if bare.is_none() {
            self.missing_record(n.span, "resolved no meaning for this name");
        }
        bare
    }

    /// Pushes the integer literal `v` in the type it takes where `expected` is wanted
    /// ([`int_literal_type`]).
    fn int_literal(&mut self, v: i128, expected: Option<&Type>, span: Span) -> Type {
        let Ok(elem) = int_literal_type(v, expected) else {
            self.missing_record(span, "passed an integer literal that does not fit its type");
            return Type::Error;
        };
        match elem {
            Elem::Real => self.emit(|b| b.push_f32(v as f32)),
            Elem::LReal => self.emit(|b| b.push_f64(v as f64)),
            _ => self.push_int(v as i64),
        }
        Type::Elem(elem)
    }

    /// Pushes the typed literal `ty#inner`: an elementary value, a `STRING#` literal, or the
    /// enumeration value the checker recorded.
    fn typed_literal(&mut self, ty: &Ident, inner: &Expr, span: Span) -> Type {
        if let Some(elem) = Elem::from_name(&ty.name) {
            let t = Type::Elem(elem);
            let Some(v) = typed_literal_value(self.prog, elem, inner) else {
                self.missing_record(inner.span, "passed an invalid typed literal");
                return Type::Error;
            };
            return match self.const_cell(&v, &t, elem, span) {
                Some(cell) => {
                    self.emit(|b| b.push_i64(cell as i64));
                    t
                }
                None => Type::Error,
            };
        }
        if ty.name == "STRING" {
            return self.expr(inner, None);
        }
        if let ExprKind::Name(n) = &inner.kind
            && let Some(Bare::EnumValue { ty, value }) = self.bare_names.of(self.cur, n)
        {
            let (ty, value) = (*ty, *value);
            self.push_int(value);
            return Type::Enum(ty);
        }
        self.missing_record(inner.span, "resolved no enumeration value for this literal");
        Type::Error
    }

    /// Emits `op x` as the checker decided it ([`crate::typed::Operations`]).
    fn unary(&mut self, op: UnOp, x: &Expr, expected: Option<&Type>, span: Span) -> Type {
        // Negative literals are folded so that e.g. INT's -32768 is accepted.
        if op == UnOp::Neg {
            if let ExprKind::Int(v) = x.kind {
                return self.int_literal(-(v as i128), expected, span);
            }
            if let ExprKind::Real(_) = x.kind {
                let t = self.expr(x, expected);
                self.op(if t == Type::REAL {
                    Opcode::NegF32
                } else {
                    Opcode::NegF64
                });
                return t;
            }
        }
        self.expr(x, expected);
        let rule = match self.operations.of(x) {
            Some(Operation::Unary(rule)) => *rule,
            _ => return self.no_operation(span),
        };
        match (op, rule) {
            (UnOp::Neg, UnaryRule::Same(Elem::Real)) => self.op(Opcode::NegF32),
            (UnOp::Neg, UnaryRule::Same(Elem::LReal)) => self.op(Opcode::NegF64),
            (UnOp::Neg, UnaryRule::Same(e)) => {
                self.op(Opcode::Neg);
                self.wrap(e);
            }
            (UnOp::Not, UnaryRule::Same(Elem::Bool)) => self.op(Opcode::NotBool),
            (UnOp::Not, UnaryRule::Same(e)) => {
                self.op(Opcode::Not);
                self.wrap(e);
            }
            (_, UnaryRule::NegateWidened(_)) => self.op(Opcode::Neg),
        }
        Type::Elem(rule.result())
    }
}
