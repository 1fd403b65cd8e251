//! Binary operators: arithmetic, comparisons, bit logic and the date/time arithmetic.

use super::*;

impl Gen<'_> {
    pub(crate) fn binary(
        &mut self,
        op: BinOp,
        a: &Expr,
        b: &Expr,
        expected: Option<&Type>,
        span: Span,
    ) -> Type {
        if self.is_pointer_operation(a, b) {
            return self.pointer_binary(op, a, b, expected, span);
        }
        let (ta, tb) = self.operand_type(a, b, expected);
        if ta.is_error() || tb.is_error() {
            self.expr(a, None);
            self.expr(b, None);
            return Type::Error;
        }
        let is_cmp = matches!(
            op,
            BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge
        );
        let mismatch = |g: &mut Self| {
            let msg = format!(
                "operator {} cannot be applied to {} and {}",
                op.symbol(),
                g.tname(&ta),
                g.tname(&tb)
            );
            g.error(codes::OPERATOR_TYPES, span, msg);
            Type::Error
        };
        // Strings: comparisons only (STRING with STRING, WSTRING with WSTRING).
        if ta.is_string() || tb.is_string() || ta.is_wstring() || tb.is_wstring() {
            return self
                .string_compare(op, a, b, &ta, &tb)
                .unwrap_or_else(|| mismatch(self));
        }
        // Enumerations (and exceptions): equality/ordering within the same type.
        let enumish = |t: &Type| matches!(t, Type::Enum(_) | Type::Exception);
        if enumish(&ta) || enumish(&tb) {
            if ta != tb || !is_cmp {
                return mismatch(self);
            }
            self.expr(a, Some(&ta));
            self.expr(b, Some(&tb));
            self.op(cmp_op(op, true));
            return Type::BOOL;
        }
        let (Some(ea), Some(eb)) = (ta.elem(), tb.elem()) else {
            return mismatch(self);
        };
        if ea.is_temporal() || eb.is_temporal() {
            return self.temporal_binary(op, (a, &ta, ea), (b, &tb, eb), span);
        }
        // Characters: comparisons within CHAR/WCHAR.
        if ea.is_char() || eb.is_char() {
            if Self::is_flexible(a) || Self::is_flexible(b) {
                self.error(codes::CHARACTER_IS_NO_NUMBER,
                    span,
                    "a character is no number: compare it with a character (CHAR#'a') or convert it (CHAR_TO_BYTE)",
                );
                return Type::Error;
            }
            if !(is_cmp && ea.is_char() && eb.is_char()) {
                return mismatch(self);
            }
            self.expr(a, Some(&ta));
            self.expr(b, Some(&tb));
            self.op(cmp_op(op, true));
            return Type::BOOL;
        }
        // Booleans and bit strings: logic operators.
        if matches!(op, BinOp::And | BinOp::Or | BinOp::Xor) {
            let t = if ea == Elem::Bool && eb == Elem::Bool {
                Elem::Bool
            } else if ea.is_integral() && eb.is_integral() {
                match common_numeric(ea, eb) {
                    Some(t) => t,
                    None => return mismatch(self),
                }
            } else {
                return mismatch(self);
            };
            let tt = Type::Elem(t);
            self.value_to_any(a, &ta, &tt);
            self.value_to_any(b, &tb, &tt);
            self.op(match op {
                BinOp::And => Opcode::And,
                BinOp::Or => Opcode::Or,
                _ => Opcode::Xor,
            });
            return tt;
        }
        if ea == Elem::Bool || eb == Elem::Bool {
            if ea == eb && matches!(op, BinOp::Eq | BinOp::Ne) {
                self.expr(a, Some(&ta));
                self.expr(b, Some(&tb));
                self.op(cmp_op(op, true));
                return Type::BOOL;
            }
            return mismatch(self);
        }
        let Some(mut ct) = common_numeric(ea, eb) else {
            return mismatch(self);
        };
        if op == BinOp::Pow && !ct.is_real() {
            // Integer ** integer: computed in LREAL, rounded back.
            let rt = Type::Elem(ct);
            self.value_to_any(a, &ta, &Type::LREAL);
            self.value_to_any(b, &tb, &Type::LREAL);
            self.emit(|bb| {
                bb.call_builtin(Builtin::ExptF64);
                bb.float_to_int(Opcode::F64ToInt, mem_type(ct), RoundMode::NearestTiesAway);
            });
            return rt;
        }
        if op == BinOp::Pow {
            ct = if ct == Elem::Real {
                Elem::Real
            } else {
                Elem::LReal
            };
        }
        let tt = Type::Elem(ct);
        self.value_to_any(a, &ta, &tt);
        self.value_to_any(b, &tb, &tt);
        if is_cmp {
            self.op(numeric_cmp_op(op, ct));
            return Type::BOOL;
        }
        if !self.numeric_arithmetic(op, ct) {
            return mismatch(self);
        }
        tt
    }

    /// A comparison of two STRINGs or two WSTRINGs (a STRING literal adapts to a WSTRING);
    /// `None` if the operator or the operand types do not allow it.
    fn string_compare(
        &mut self,
        op: BinOp,
        a: &Expr,
        b: &Expr,
        ta: &Type,
        tb: &Type,
    ) -> Option<Type> {
        let is_cmp = matches!(
            op,
            BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge
        );
        let wide = ta.is_wstring() || tb.is_wstring();
        let same_kind = (ta.is_string() && tb.is_string()) || (ta.is_wstring() && tb.is_wstring());
        // A STRING literal compared with a WSTRING is a WSTRING literal.
        let literal = |e: &Expr| matches!(e.kind, ExprKind::Str(_));
        let adapts = wide && (literal(a) && tb.is_wstring() || literal(b) && ta.is_wstring());
        if !((same_kind || adapts) && is_cmp) {
            return None;
        }
        let w = Type::WString(DEFAULT_STRING_LEN);
        self.expr(a, wide.then_some(&w));
        self.expr(b, wide.then_some(&w));
        self.emit(|bb| {
            bb.call_builtin(if wide {
                Builtin::WStrCompare
            } else {
                Builtin::StrCompare
            });
            bb.push_i32(0);
        });
        self.op(cmp_op(op, true));
        Some(Type::BOOL)
    }

    /// Emits the arithmetic operator `op` on two values of the numeric type `ct` (already on
    /// the stack); `false` if `op` is not an arithmetic operator of `ct`.
    fn numeric_arithmetic(&mut self, op: BinOp, ct: Elem) -> bool {
        match ct {
            Elem::Real => self.op(match op {
                BinOp::Add => Opcode::AddF32,
                BinOp::Sub => Opcode::SubF32,
                BinOp::Mul => Opcode::MulF32,
                BinOp::Div => Opcode::DivF32,
                BinOp::Pow => {
                    self.emit(|bb| bb.call_builtin(Builtin::ExptF32));
                    return true;
                }
                _ => return false,
            }),
            Elem::LReal => self.op(match op {
                BinOp::Add => Opcode::AddF64,
                BinOp::Sub => Opcode::SubF64,
                BinOp::Mul => Opcode::MulF64,
                BinOp::Div => Opcode::DivF64,
                BinOp::Pow => {
                    self.emit(|bb| bb.call_builtin(Builtin::ExptF64));
                    return true;
                }
                _ => return false,
            }),
            _ => {
                let signed = ct.is_signed_int();
                self.op(match op {
                    BinOp::Add => Opcode::Add,
                    BinOp::Sub => Opcode::Sub,
                    BinOp::Mul => Opcode::Mul,
                    BinOp::Div => {
                        if signed {
                            Opcode::DivS
                        } else {
                            Opcode::DivU
                        }
                    }
                    BinOp::Mod => {
                        if signed {
                            Opcode::ModS
                        } else {
                            Opcode::ModU
                        }
                    }
                    _ => return false,
                });
                self.wrap(ct);
            }
        }
        true
    }

    /// Date and time arithmetic (IEC 61131-3 table of time operations): TIME +/- TIME,
    /// TOD +/- TIME (wrapping within the day), DT +/- TIME, DATE - DATE, TOD - TOD, DT - DT
    /// (giving TIME), TIME * and / numbers, comparisons within one family. The long forms
    /// follow the same rules; an operation with a long operand gives the long result.
    pub(super) fn temporal_binary(
        &mut self,
        op: BinOp,
        (a, ta, ea): (&Expr, &Type, Elem),
        (b, tb, eb): (&Expr, &Type, Elem),
        span: Span,
    ) -> Type {
        // A literal factor is a number, not a duration (`T#1s * 2`).
        let literal_type = |e: &Expr| {
            if Self::has_real_literal(e) {
                Type::LREAL
            } else {
                Type::LINT
            }
        };
        let (ta, ea) = if Self::is_flexible(a) && matches!(op, BinOp::Mul) {
            let t = literal_type(a);
            let e = t.elem().unwrap_or(Elem::LInt);
            (&t.clone(), e)
        } else {
            (ta, ea)
        };
        let (tb, eb) = if Self::is_flexible(b) && matches!(op, BinOp::Mul | BinOp::Div) {
            let t = literal_type(b);
            let e = t.elem().unwrap_or(Elem::LInt);
            (&t.clone(), e)
        } else {
            (tb, eb)
        };
        let fa = ea.temporal_family();
        let fb = eb.temporal_family();
        let long = ea.is_long_temporal() || eb.is_long_temporal();
        let pick = |short: Elem| -> Elem {
            match (short, long) {
                (Elem::Time, true) => Elem::LTime,
                (Elem::Tod, true) => Elem::LTod,
                (Elem::Dt, true) => Elem::LDt,
                (Elem::Date, true) => Elem::LDate,
                (e, _) => e,
            }
        };
        let is_cmp = matches!(
            op,
            BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge
        );
        let time = Some(Elem::Time);
        // (result, whether a TOD result wraps into its day)
        let result = match op {
            _ if is_cmp && fa == fb => Some((Elem::Bool, false)),
            BinOp::Add if fa == time && fb == time => Some((pick(Elem::Time), false)),
            BinOp::Add
                if fa == Some(Elem::Tod) && fb == time || fa == time && fb == Some(Elem::Tod) =>
            {
                Some((pick(Elem::Tod), true))
            }
            BinOp::Add
                if fa == Some(Elem::Dt) && fb == time || fa == time && fb == Some(Elem::Dt) =>
            {
                Some((pick(Elem::Dt), false))
            }
            BinOp::Sub if fa == fb && fa != Some(Elem::Dt) && fa != Some(Elem::Tod) => {
                // TIME - TIME, DATE - DATE
                Some((pick(Elem::Time), false))
            }
            BinOp::Sub if fa == fb => Some((pick(Elem::Time), false)),
            BinOp::Sub if fa == Some(Elem::Tod) && fb == time => Some((pick(Elem::Tod), true)),
            BinOp::Sub if fa == Some(Elem::Dt) && fb == time => Some((pick(Elem::Dt), false)),
            BinOp::Mul | BinOp::Div
                if fa == time && eb.is_numeric()
                    || op == BinOp::Mul && fb == time && ea.is_numeric() =>
            {
                Some((if fa == time { ea } else { eb }, false))
            }
            _ => None,
        };
        let Some((result, wraps)) = result else {
            let hint = match (op, fa, fb) {
                (BinOp::Add | BinOp::Sub, Some(Elem::Date), Some(Elem::Time)) => {
                    " (a DATE is a day: use DATE_TO_DT or CONCAT_DATE_TOD for a point in time)"
                }
                (BinOp::Add, Some(x), Some(y)) if x == y && x != Elem::Time => {
                    " (two points in time cannot be added; subtract them for a TIME)"
                }
                _ => "",
            };
            let msg = format!(
                "operator {} cannot be applied to {} and {}{hint}",
                op.symbol(),
                self.tname(ta),
                self.tname(tb)
            );
            self.error(codes::OPERATOR_TYPES, span, msg);
            return Type::Error;
        };
        if matches!(op, BinOp::Mul | BinOp::Div) {
            let (duration, number, number_type) = if fa == time { (a, b, tb) } else { (b, a, ta) };
            let duration_type = Type::Elem(result);
            if number_type.elem().is_some_and(|e| e.is_real()) {
                // TIME * REAL: computed in LREAL nanoseconds, rounded.
                self.value_to_any(duration, &duration_type, &duration_type);
                self.op(Opcode::IToF64S);
                self.value_to_any(number, number_type, &Type::LREAL);
                self.op(if op == BinOp::Mul {
                    Opcode::MulF64
                } else {
                    Opcode::DivF64
                });
                self.emit(|bb| {
                    bb.float_to_int(Opcode::F64ToInt, MemType::I64, RoundMode::NearestTiesAway)
                });
            } else {
                self.value_to_any(duration, &duration_type, &duration_type);
                self.value_to_any(number, number_type, &Type::LINT);
                self.op(if op == BinOp::Mul {
                    Opcode::Mul
                } else {
                    Opcode::DivS
                });
            }
            return Type::Elem(result);
        }
        // The operands keep their nanoseconds (TIME widens to LTIME implicitly).
        self.value_to_any(a, ta, ta);
        self.value_to_any(b, tb, tb);
        self.op(match op {
            BinOp::Add => Opcode::Add,
            BinOp::Sub => Opcode::Sub,
            _ => cmp_op(op, true),
        });
        if wraps {
            self.emit(|bb| bb.call_builtin(Builtin::TodOf));
        }
        Type::Elem(result)
    }

    /// Compiles `e` (whose type was inferred as `from`) and converts to `to` without the
    /// implicit-conversion restriction (used for operands already checked by the caller).
    pub(crate) fn value_to_any(&mut self, e: &Expr, from: &Type, to: &Type) {
        let t = self.expr(e, Some(if Self::is_flexible(e) { to } else { from }));
        if let (Some(f), Some(t2)) = (t.elem(), to.elem()) {
            self.convert(f, t2);
        }
    }
}

/// The comparison opcode of a numeric common type.
fn numeric_cmp_op(op: BinOp, ct: Elem) -> Opcode {
    if ct == Elem::Real {
        match op {
            BinOp::Eq => Opcode::EqF32,
            BinOp::Ne => Opcode::NeF32,
            BinOp::Lt => Opcode::LtF32,
            BinOp::Le => Opcode::LeF32,
            BinOp::Gt => Opcode::GtF32,
            _ => Opcode::GeF32,
        }
    } else if ct == Elem::LReal {
        match op {
            BinOp::Eq => Opcode::EqF64,
            BinOp::Ne => Opcode::NeF64,
            BinOp::Lt => Opcode::LtF64,
            BinOp::Le => Opcode::LeF64,
            BinOp::Gt => Opcode::GtF64,
            _ => Opcode::GeF64,
        }
    } else {
        // Only 64-bit unsigned values can exceed i64; narrower ones are zero-extended.
        cmp_op(op, ct.size() != 8 || ct.is_signed_int())
    }
}
