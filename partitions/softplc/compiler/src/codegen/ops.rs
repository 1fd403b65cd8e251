//! Operators: the expression checker ([`crate::sema::expr`]) decides what each does by the
//! rules of [`crate::sema::ops`] and records it; emission reads the record and emits the
//! binary operations here (arithmetic, comparisons, bit logic, date/time arithmetic; the
//! unary ones in `expr.rs`).

use super::*;
use crate::sema::expr::{operand_context, operand_types};
use crate::sema::ops::{BinaryRule, Operation};

impl Gen<'_> {
    /// Emits `a op b` as the expression checker decided it ([`crate::typed::Operations`];
    /// [`crate::sema::expr::binary`]).
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
        let (ta, tb) = operand_types(self, a, b, expected);
        let rule = match self.operations.of(a) {
            Some(Operation::Binary(rule)) => rule.clone(),
            _ => return self.no_operation(span),
        };
        self.emit_binary(op, &rule, (a, &ta), (b, &tb))
    }

    /// Reports that emission found no record of the operator at `span` (of its kind): the
    /// checker missed it.
    pub(super) fn no_operation(&mut self, span: Span) -> Type {
        self.missing_record(span, "decided no operation for this operator");
        Type::Error
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
        let t = self.expr(e, Some(operand_context(e, from, to)));
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
