//! Expressions: inference, implicit conversions, literals and unary operators.

use super::*;
use crate::sema::ops::UnaryRule;

impl Gen<'_> {
    /// Type of an expression without emitting code or reporting errors. The checking pass
    /// infers it (a walk of the expression with nothing emitted nor reported) and records
    /// it; the emission pass only reads the record: a missing one is an internal error.
    pub(crate) fn infer(&mut self, e: &Expr) -> Type {
        if let Some(t) = self.types.of(e) {
            return t.clone();
        }
        if !self.check_only {
            self.missing_record(e.span, "recorded no type for this expression");
            return Type::Error;
        }
        let saved = self.dry;
        self.dry = true;
        let t = self.expr(e, None);
        self.dry = saved;
        self.types.record(e, t.clone());
        t
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
                        "ABS", "SQRT", "LN", "LOG", "EXP", "SIN", "COS", "TAN", "ASIN", "ACOS",
                        "ATAN", "EXPT", "MAX", "MIN", "LIMIT",
                    ];
                    GENERIC.contains(&n.name.as_str())
                        && !args.is_empty()
                        && args
                            .iter()
                            .all(|a| !a.output && Self::is_flexible(&a.value))
                }
                _ => false,
            },
            ExprKind::Unary(UnOp::Neg, x) => Self::is_flexible(x),
            ExprKind::Binary(op, a, b)
                if !matches!(
                    op,
                    BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge
                ) =>
            {
                Self::is_flexible(a) && Self::is_flexible(b)
            }
            _ => false,
        }
    }

    /// The expression `e` of type `ty` as the rules of `sema` see an operand: its type and
    /// the facts about its form they ask about.
    pub(crate) fn operand<'t>(e: &Expr, ty: &'t Type) -> crate::sema::ops::Operand<'t> {
        crate::sema::ops::Operand {
            ty,
            flexible: Self::is_flexible(e),
            string_literal: matches!(e.kind, ExprKind::Str(_)),
            real_literal: Self::has_real_literal(e),
        }
    }

    pub(crate) fn has_real_literal(e: &Expr) -> bool {
        match &e.kind {
            ExprKind::Real(_) => true,
            ExprKind::Call { callee, .. } if matches!(&callee.kind, ExprKind::Name(n) if n.name == "TRUNC" || n.name == "SIZEOF") => {
                false
            }
            ExprKind::Call { callee, args } => {
                matches!(&callee.kind, ExprKind::Name(n) if !["ABS", "MAX", "MIN", "LIMIT"].contains(&n.name.as_str()))
                    || args.iter().any(|a| Self::has_real_literal(&a.value))
            }
            ExprKind::Unary(_, x) => Self::has_real_literal(x),
            ExprKind::Binary(_, a, b) => Self::has_real_literal(a) || Self::has_real_literal(b),
            _ => false,
        }
    }

    /// Compiles `e` and converts the result to `to` (implicit conversions only).
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
            let id = Ident {
                name: "REF".into(),
                text: "REF".into(),
                span: e.span,
            };
            let args = [Arg {
                name: None,
                output: false,
                value: e.clone(),
                span: e.span,
            }];
            let t = self.ref_function(&id, &args, Some(&as_ref), e.span);
            self.coerce(&t, &as_ref, e);
            return;
        }
        let t = self.expr(e, Some(to));
        self.coerce(&t, to, e);
    }

    /// Emits an implicit conversion from `from` to `to` ([`implicit_conversion`]), or
    /// reports a type mismatch.
    pub(crate) fn coerce(&mut self, from: &Type, to: &Type, e: &Expr) {
        if from.is_error() || to.is_error() || from == to {
            return;
        }
        let implicit = if self.check_only {
            let Some(implicit) = self.implicit_conversion(from, to, e.span) else {
                return;
            };
            if !self.dry || self.coercions.of(e).is_none() {
                self.coercions.record(e, implicit);
            }
            implicit
        } else {
            match self.coercions.of(e) {
                Some(implicit) => *implicit,
                None => {
                    return self
                        .missing_record(e.span, "decided no implicit conversion for this value");
                }
            }
        };
        match implicit {
            Implicit::Nothing => {}
            Implicit::Convert(f, t) => self.convert(f, t),
            Implicit::AddressToInteger => self.emit(|b| b.op_width(Opcode::Zext, 32)),
        }
    }

    /// What a value of type `from` at `span` takes where `to` is wanted, or `None` when it
    /// cannot stand there (reported).
    fn implicit_conversion(&mut self, from: &Type, to: &Type, span: Span) -> Option<Implicit> {
        if let Some(decided) = self.pointer_coercion(from, to, span) {
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
                (codes::IMPLICIT_CONVERSION, self.mismatch_message(from, to))
            }
            Err(NotImplicit::Mismatch) => (codes::TYPE_MISMATCH, self.mismatch_message(from, to)),
        };
        self.error(code, span, msg);
        None
    }

    fn mismatch_message(&self, from: &Type, to: &Type) -> String {
        format!(
            "type mismatch: expected {}, found {}",
            self.tname(to),
            self.tname(from)
        )
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

    /// Compiles an expression; `expected` guides the typing of untyped literals.
    pub(crate) fn expr(&mut self, e: &Expr, expected: Option<&Type>) -> Type {
        match &e.kind {
            ExprKind::Error => Type::Error,
            ExprKind::Int(v) => self.int_literal(*v as i128, expected, e.span),
            ExprKind::Real(r) => {
                if expected.and_then(|t| t.elem()) == Some(Elem::Real) {
                    let r = *r as f32;
                    self.emit(|b| b.push_f32(r));
                    Type::REAL
                } else {
                    let r = *r;
                    self.emit(|b| b.push_f64(r));
                    Type::LREAL
                }
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
            ExprKind::Str(s)
                if expected
                    .and_then(|t| t.elem())
                    .is_some_and(|e| e.is_char() && !matches!(expected, Some(Type::Enum(_))))
                    && crate::sema::single_char(s).is_some() =>
            {
                let elem = expected.and_then(|t| t.elem()).unwrap_or(Elem::Char);
                let code = crate::sema::single_char(s).unwrap_or(0);
                if self.check_only && code > elem.int_range().1 {
                    let msg = format!("character '{s}' does not fit type {elem}");
                    self.error(codes::VALUE_OUT_OF_RANGE, e.span, msg);
                }
                self.push_int(code as i64);
                Type::Elem(elem)
            }
            ExprKind::WStr(s) => {
                let a = self.wstring_literal(s);
                self.emit(|b| b.push_u32(a));
                Type::WString(s.encode_utf16().count().max(1) as u32)
            }
            // A STRING literal where a WSTRING is expected is that WSTRING.
            ExprKind::Str(s) if matches!(expected, Some(Type::WString(_))) => {
                let a = self.wstring_literal(s);
                self.emit(|b| b.push_u32(a));
                Type::WString(s.encode_utf16().count().max(1) as u32)
            }
            ExprKind::Str(s) => {
                let a = self.string_literal(s);
                self.emit(|b| b.push_u32(a));
                Type::String(s.len().max(1) as u32)
            }
            ExprKind::Typed(ty, inner) => self.typed_literal(ty, inner, e.span),
            ExprKind::Name(n) => match self.bare_name(n, expected) {
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
            ExprKind::This => self.this_expr(false, e.span),
            ExprKind::Super => self.this_expr(true, e.span),
            ExprKind::Member(..) if let Some(t) = self.property_read(e) => t,
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
            ExprKind::Call { callee, args } => self.call(callee, args, expected, e.span),
            ExprKind::Unary(op, x) => self.unary(*op, x, expected, e.span),
            ExprKind::Binary(op, a, b) => self.binary(*op, a, b, expected, e.span),
        }
    }

    /// What bare name `n` denotes. The checking pass decides it and records it ([`Bare`]; a
    /// walk for inference records only what no real walk has, as the expected type may
    /// differ); emission reads the record.
    fn bare_name(&mut self, n: &Ident, expected: Option<&Type>) -> Option<Bare> {
        if !self.check_only {
            let bare = self.bare_names.of(self.cur, n).cloned();
            if bare.is_none() {
                self.missing_record(n.span, "resolved no meaning for this name");
            }
            return bare;
        }
        let bare = self.resolve_bare(n, expected);
        if !self.dry || self.bare_names.of(self.cur, n).is_none() {
            self.bare_names.record(self.cur, n, bare.clone());
        }
        Some(bare)
    }

    /// What bare name `n` denotes in the current POU, `expected` being the type its context
    /// expects.
    fn resolve_bare(&self, n: &Ident, expected: Option<&Type>) -> Bare {
        if self.is_visible_var(&n.name) {
            return Bare::Variable;
        }
        if let Some(property) = self.own_property(n) {
            return property;
        }
        if let Some(Type::Enum(ei)) = expected
            && let Some((_, v)) = self.prog.enums[*ei]
                .values
                .iter()
                .find(|(vn, _)| *vn == n.name)
        {
            return Bare::EnumValue { ty: *ei, value: *v };
        }
        if let Some((ty, value)) = self.prog.enum_value(&n.name) {
            return Bare::EnumValue { ty, value };
        }
        if let Some(t) = Trap::ALL.iter().find(|t| t.name() == n.name) {
            return Bare::Exception(t.code() as i64);
        }
        Bare::Variable
    }

    /// Pushes the integer literal `v` in the type `expected` asks for (BOOL for 0 and 1, a
    /// REAL, an integer it must fit), else in DINT, LINT or ULINT by its size; the checking
    /// pass reports a literal that does not fit.
    pub(crate) fn int_literal(&mut self, v: i128, expected: Option<&Type>, span: Span) -> Type {
        let exp_elem = expected.and_then(|t| match t {
            Type::Enum(_) | Type::Exception => None,
            t => t.elem(),
        });
        match exp_elem {
            // IEC boolean literals include 0 and 1.
            Some(Elem::Bool) if v == 0 || v == 1 => {
                self.push_int(v as i64);
                Type::BOOL
            }
            Some(e) if e.is_real() => {
                if e == Elem::Real {
                    self.emit(|b| b.push_f32(v as f32));
                } else {
                    self.emit(|b| b.push_f64(v as f64));
                }
                Type::Elem(e)
            }
            Some(e) if e.is_integral() => {
                let (lo, hi) = e.int_range();
                if self.check_only && (v < lo || v > hi) {
                    let msg = format!("constant {v} does not fit type {e}");
                    self.error(codes::VALUE_OUT_OF_RANGE, span, msg);
                    return Type::Error;
                }
                self.push_int(v as i64);
                Type::Elem(e)
            }
            _ => {
                if self.check_only && (v > u64::MAX as i128 || v < i64::MIN as i128) {
                    self.error(codes::INTEGER_TOO_LARGE, span, "integer constant too large");
                    return Type::Error;
                }
                self.push_int(v as i64);
                if v >= i32::MIN as i128 && v <= i32::MAX as i128 {
                    Type::DINT
                } else if v <= i64::MAX as i128 {
                    Type::LINT
                } else {
                    Type::Elem(Elem::ULInt)
                }
            }
        }
    }

    pub(super) fn typed_literal(&mut self, ty: &Ident, inner: &Expr, span: Span) -> Type {
        if let Some(elem) = Elem::from_name(&ty.name) {
            let t = Type::Elem(elem);
            let v = match const_eval(self.prog, &(), inner) {
                Some(v) => v,
                None => {
                    self.error(
                        codes::MALFORMED_LITERAL,
                        inner.span,
                        format!("invalid {} literal", elem),
                    );
                    return Type::Error;
                }
            };
            let v = match (v, elem) {
                (ConstVal::Bool(b), e) if e != Elem::Bool => ConstVal::Int(b as i128),
                (v, _) => v,
            };
            if self.dry {
                return t;
            }
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
        // `Enum#value`: the checking pass resolves it and records it ([`Bare`]); emission
        // reads the record.
        if !self.check_only {
            if let ExprKind::Name(n) = &inner.kind
                && let Some(Bare::EnumValue { ty, value }) = self.bare_names.of(self.cur, n)
            {
                let (ty, value) = (*ty, *value);
                self.push_int(value);
                return Type::Enum(ty);
            }
            self.missing_record(inner.span, "resolved no enumeration value for this literal");
            return Type::Error;
        }
        if let (Some((Type::Enum(ei), _)), ExprKind::Name(n)) =
            (self.prog.aliases.get(&ty.name).cloned(), &inner.kind)
        {
            if let Some((_, v)) = self.prog.enums[ei]
                .values
                .iter()
                .find(|(vn, _)| *vn == n.name)
            {
                let value = *v;
                self.bare_names
                    .record(self.cur, n, Bare::EnumValue { ty: ei, value });
                self.push_int(value);
                return Type::Enum(ei);
            }
            let msg = format!("`{}` is not a value of {}", n.text, ty.text);
            self.error(codes::UNKNOWN_ENUMERATION_VALUE, n.span, msg);
            return Type::Error;
        }
        self.error(
            codes::UNKNOWN_TYPE,
            ty.span,
            format!("unknown type `{}` in typed literal", ty.text),
        );
        Type::Error
    }

    pub(super) fn unary(
        &mut self,
        op: UnOp,
        x: &Expr,
        expected: Option<&Type>,
        span: Span,
    ) -> Type {
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
        let t = self.expr(x, expected);
        if t.is_error() {
            return Type::Error;
        }
        match self.unary_rule(op, x, &t, span) {
            Some(UnaryRule::Same(e)) => {
                match (op, e) {
                    (UnOp::Neg, Elem::Real) => self.op(Opcode::NegF32),
                    (UnOp::Neg, Elem::LReal) => self.op(Opcode::NegF64),
                    (UnOp::Neg, e) => {
                        self.op(Opcode::Neg);
                        self.wrap(e);
                    }
                    (UnOp::Not, Elem::Bool) => self.op(Opcode::NotBool),
                    (UnOp::Not, e) => {
                        self.op(Opcode::Not);
                        self.wrap(e);
                    }
                }
                Type::Elem(e)
            }
            Some(UnaryRule::NegateWidened(signed)) => {
                self.op(Opcode::Neg);
                Type::Elem(signed)
            }
            None => Type::Error,
        }
    }

    /// Type both operands are brought to.
    pub(super) fn operand_type(
        &mut self,
        a: &Expr,
        b: &Expr,
        expected: Option<&Type>,
    ) -> (Type, Type) {
        let fa = Self::is_flexible(a);
        let fb = Self::is_flexible(b);
        let ta = if fa { None } else { Some(self.infer(a)) };
        let tb = if fb { None } else { Some(self.infer(b)) };
        // Only a plain literal: arithmetic of literals keeps wrapping in the other operand's
        // type as it always did.
        let int_value = |e: &Expr| match &e.kind {
            ExprKind::Int(v) => Some(*v as i128),
            ExprKind::Unary(UnOp::Neg, x) => match x.kind {
                ExprKind::Int(v) => Some(-(v as i128)),
                _ => None,
            },
            _ => None,
        };
        let (va, vb) = (int_value(a), int_value(b));
        // An integer literal takes the other operand's type, or a wider one when it does not
        // fit it (`int_var * 60000` is a DINT product, as the literal is a DINT).
        let flex_type = |other: &Type, e: &Expr, value: Option<i128>| -> Type {
            if Self::has_real_literal(e) {
                return match other.elem() {
                    Some(x) if x.is_real() => other.clone(),
                    _ => Type::LREAL,
                };
            }
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
        };
        match (ta, tb) {
            (Some(x), Some(y)) => (x, y),
            (Some(x), None) => {
                let y = flex_type(&x, b, vb);
                (x, y)
            }
            (None, Some(y)) => {
                let x = flex_type(&y, a, va);
                (x, y)
            }
            (None, None) => {
                let num = expected
                    .and_then(|t| t.elem())
                    .filter(|e| e.is_numeric() && !matches!(expected, Some(Type::Enum(_))));
                let any_real = Self::has_real_literal(a) || Self::has_real_literal(b);
                // Integer literals stay integers (5 / 2 = 2 even when assigned to a REAL);
                // real literals take a REAL context's precision.
                let t = match num {
                    Some(e) if e.is_real() == any_real => Type::Elem(e),
                    _ => {
                        if Self::has_real_literal(a) || Self::has_real_literal(b) {
                            Type::LREAL
                        } else {
                            Type::DINT
                        }
                    }
                };
                (t.clone(), t)
            }
        }
    }
}
