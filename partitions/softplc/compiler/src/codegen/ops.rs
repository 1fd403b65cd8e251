//! Operators: the checking pass decides what each does by the rules of [`crate::sema::ops`]
//! and records it; emission reads the record and emits the binary operations here
//! (arithmetic, comparisons, bit logic, date/time arithmetic; the unary ones in `expr.rs`).

use super::*;
use crate::sema::ops::{self, BinaryRule, Operation, OperatorError, UnaryRule};

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
        match self.binary_rule(op, (a, &ta), (b, &tb), span) {
            Some(rule) => self.emit_binary(op, &rule, (a, &ta), (b, &tb)),
            None => Type::Error,
        }
    }

    /// What `a op b` does: the checking pass decides it ([`ops::binary_rule`], reporting a
    /// refusal) and records it ([`crate::typed::Operations`]; a walk for inference records
    /// only what no real walk has, as the expected type may differ); emission reads the
    /// record.
    fn binary_rule(
        &mut self,
        op: BinOp,
        (a, ta): (&Expr, &Type),
        (b, tb): (&Expr, &Type),
        span: Span,
    ) -> Option<BinaryRule> {
        if !self.check_only {
            return match self.operations.of(a) {
                Some(Operation::Binary(rule)) => Some(rule.clone()),
                _ => self.no_operation(span),
            };
        }
        let decided = ops::binary_rule(op, Self::operand(a, ta), Self::operand(b, tb));
        match self.record_operation(a, decided.map(Operation::Binary), op.symbol(), span) {
            Some(Operation::Binary(rule)) => Some(rule),
            _ => None,
        }
    }

    /// What `op x` does (`t`: the type of `x`, not the error type), as [`Gen::binary_rule`]
    /// decides and records it.
    pub(super) fn unary_rule(
        &mut self,
        op: UnOp,
        x: &Expr,
        t: &Type,
        span: Span,
    ) -> Option<UnaryRule> {
        let symbol = if op == UnOp::Neg { "-" } else { "NOT" };
        if !self.check_only {
            return match self.operations.of(x) {
                Some(Operation::Unary(rule)) => Some(*rule),
                _ => self.no_operation(span),
            };
        }
        let decided = ops::unary_rule(op, t).map(Operation::Unary);
        match self.record_operation(x, decided, symbol, span) {
            Some(Operation::Unary(rule)) => Some(rule),
            _ => None,
        }
    }

    /// Reports that emission found no record of the operator at `span` (of its kind): the
    /// checker missed it.
    fn no_operation<T>(&mut self, span: Span) -> Option<T> {
        self.missing_record(span, "decided no operation for this operator");
        None
    }

    /// Records the checker's decision on the operation whose first operand is `first`, or
    /// reports why the operator `symbol` is refused.
    fn record_operation(
        &mut self,
        first: &Expr,
        decided: Result<Operation, OperatorError>,
        symbol: &str,
        span: Span,
    ) -> Option<Operation> {
        match decided {
            Ok(operation) => {
                if !self.dry || self.operations.of(first).is_none() {
                    self.operations.record(first, operation.clone());
                }
                Some(operation)
            }
            Err(OperatorError::CharacterIsNoNumber) => {
                self.error(
                    codes::CHARACTER_IS_NO_NUMBER,
                    span,
                    "a character is no number: compare it with a character (CHAR#'a') or convert it (CHAR_TO_BYTE)",
                );
                None
            }
            Err(OperatorError::Types { a, b, hint }) => {
                let msg = format!(
                    "operator {symbol} cannot be applied to {} and {}{hint}",
                    self.tname(&a),
                    self.tname(&b)
                );
                self.error(codes::OPERATOR_TYPES, span, msg);
                None
            }
            Err(OperatorError::Operand(t)) => {
                let msg = format!("operator {symbol} cannot be applied to {}", self.tname(&t));
                self.error(codes::OPERATOR_TYPES, span, msg);
                None
            }
        }
    }

    /// Emits `a op b` as `rule` says; returns its type.
    fn emit_binary(
        &mut self,
        op: BinOp,
        rule: &BinaryRule,
        (a, ta): (&Expr, &Type),
        (b, tb): (&Expr, &Type),
    ) -> Type {
        match *rule {
            BinaryRule::StringCompare { wide } => {
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
                Type::BOOL
            }
            BinaryRule::Compare => {
                self.expr(a, Some(ta));
                self.expr(b, Some(tb));
                self.op(cmp_op(op, true));
                Type::BOOL
            }
            BinaryRule::Logic(t) => {
                let tt = Type::Elem(t);
                self.operands_as(a, ta, b, tb, &tt);
                self.op(match op {
                    BinOp::And => Opcode::And,
                    BinOp::Or => Opcode::Or,
                    _ => Opcode::Xor,
                });
                tt
            }
            BinaryRule::IntegerPower(ct) => {
                self.operands_as(a, ta, b, tb, &Type::LREAL);
                self.emit(|bb| {
                    bb.call_builtin(Builtin::ExptF64);
                    bb.float_to_int(Opcode::F64ToInt, mem_type(ct), RoundMode::NearestTiesAway);
                });
                Type::Elem(ct)
            }
            BinaryRule::NumericCompare(ct) => {
                let tt = Type::Elem(ct);
                self.operands_as(a, ta, b, tb, &tt);
                self.op(numeric_cmp_op(op, ct));
                Type::BOOL
            }
            BinaryRule::Arithmetic(ct) => {
                let tt = Type::Elem(ct);
                self.operands_as(a, ta, b, tb, &tt);
                self.numeric_arithmetic(op, ct);
                tt
            }
            BinaryRule::Temporal { result, wraps } => {
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
            BinaryRule::Scale {
                result,
                duration_first,
                ref number,
            } => {
                let (duration, factor) = if duration_first { (a, b) } else { (b, a) };
                let duration_type = Type::Elem(result);
                self.value_to_any(duration, &duration_type, &duration_type);
                if number.elem().is_some_and(|e| e.is_real()) {
                    // TIME * REAL: computed in LREAL nanoseconds, rounded.
                    self.op(Opcode::IToF64S);
                    self.value_to_any(factor, number, &Type::LREAL);
                    self.op(if op == BinOp::Mul {
                        Opcode::MulF64
                    } else {
                        Opcode::DivF64
                    });
                    self.emit(|bb| {
                        bb.float_to_int(Opcode::F64ToInt, MemType::I64, RoundMode::NearestTiesAway)
                    });
                } else {
                    self.value_to_any(factor, number, &Type::LINT);
                    self.op(if op == BinOp::Mul {
                        Opcode::Mul
                    } else {
                        Opcode::DivS
                    });
                }
                Type::Elem(result)
            }
        }
    }

    /// Emits the arithmetic operator `op` on two values of the numeric type `ct` (already on
    /// the stack), as [`BinaryRule::Arithmetic`] allows it.
    fn numeric_arithmetic(&mut self, op: BinOp, ct: Elem) {
        let real = |f32_op, f64_op| if ct == Elem::Real { f32_op } else { f64_op };
        match (op, ct.is_real()) {
            (BinOp::Add, true) => self.op(real(Opcode::AddF32, Opcode::AddF64)),
            (BinOp::Sub, true) => self.op(real(Opcode::SubF32, Opcode::SubF64)),
            (BinOp::Mul, true) => self.op(real(Opcode::MulF32, Opcode::MulF64)),
            (BinOp::Div, true) => self.op(real(Opcode::DivF32, Opcode::DivF64)),
            (_, true) => {
                let expt = if ct == Elem::Real {
                    Builtin::ExptF32
                } else {
                    Builtin::ExptF64
                };
                self.emit(|bb| bb.call_builtin(expt));
            }
            (_, false) => {
                let signed = ct.is_signed_int();
                self.op(match op {
                    BinOp::Add => Opcode::Add,
                    BinOp::Sub => Opcode::Sub,
                    BinOp::Mul => Opcode::Mul,
                    BinOp::Div if signed => Opcode::DivS,
                    BinOp::Div => Opcode::DivU,
                    BinOp::Mod if signed => Opcode::ModS,
                    _ => Opcode::ModU,
                });
                self.wrap(ct);
            }
        }
    }

    /// Compiles `e` (whose type was inferred as `from`) and converts to `to` without the
    /// implicit-conversion restriction (used for operands already checked by the caller).
    pub(crate) fn value_to_any(&mut self, e: &Expr, from: &Type, to: &Type) {
        let t = self.expr(e, Some(if Self::is_flexible(e) { to } else { from }));
        if let (Some(f), Some(t2)) = (t.elem(), to.elem()) {
            self.convert(f, t2);
        }
    }

    /// Compiles a binary operator's two operands, each converted to `to` (the type the rule
    /// computes in).
    fn operands_as(&mut self, a: &Expr, ta: &Type, b: &Expr, tb: &Type, to: &Type) {
        self.value_to_any(a, ta, to);
        self.value_to_any(b, tb, to);
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
