//! Expressions: precedence climbing over the IEC operator table, primaries and literals.

use super::*;

impl Parser<'_> {
    pub(crate) fn expr(&mut self) -> PResult<Expr> {
        self.guarded("expression", |p| p.binary(0))
    }

    pub(super) fn binop(&self) -> Option<(BinOp, u8)> {
        let op = match self.tok() {
            Tok::Ident(u, _) => match u.as_str() {
                "OR" => BinOp::Or,
                "XOR" => BinOp::Xor,
                "AND" => BinOp::And,
                "MOD" => BinOp::Mod,
                _ => return None,
            },
            Tok::Amp => BinOp::And,
            Tok::Eq => BinOp::Eq,
            Tok::Ne => BinOp::Ne,
            Tok::Lt => BinOp::Lt,
            Tok::Le => BinOp::Le,
            Tok::Gt => BinOp::Gt,
            Tok::Ge => BinOp::Ge,
            Tok::Plus => BinOp::Add,
            Tok::Minus => BinOp::Sub,
            Tok::Star => BinOp::Mul,
            Tok::Slash => BinOp::Div,
            Tok::Power => BinOp::Pow,
            _ => return None,
        };
        let prec = match op {
            BinOp::Or => 1,
            BinOp::Xor => 2,
            BinOp::And => 3,
            BinOp::Eq | BinOp::Ne => 4,
            BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge => 5,
            BinOp::Add | BinOp::Sub => 6,
            BinOp::Mul | BinOp::Div | BinOp::Mod => 7,
            BinOp::Pow => 9,
        };
        Some((op, prec))
    }

    /// Precedence climbing; all binary operators are left-associative (IEC 61131-3 table 71).
    pub(super) fn binary(&mut self, min_prec: u8) -> PResult<Expr> {
        let mut lhs = self.unary()?;
        while let Some((op, prec)) = self.binop() {
            if prec < min_prec {
                break;
            }
            self.bump();
            let rhs = if op == BinOp::Pow {
                self.power_operand()?
            } else {
                self.binary(prec + 1)?
            };
            let span = lhs.span.to(rhs.span);
            lhs = Expr {
                kind: ExprKind::Binary(op, Box::new(lhs), Box::new(rhs)),
                span,
            };
        }
        Ok(lhs)
    }

    /// Right operand of `**`: binds tighter than unary minus, but `2 ** -1` is accepted.
    pub(super) fn power_operand(&mut self) -> PResult<Expr> {
        if matches!(self.tok(), Tok::Minus) || self.is_kw("NOT") {
            return self.unary();
        }
        self.postfix()
    }

    pub(super) fn unary(&mut self) -> PResult<Expr> {
        let start = self.span();
        let op = if matches!(self.tok(), Tok::Minus) {
            Some(UnOp::Neg)
        } else if self.is_kw("NOT") {
            Some(UnOp::Not)
        } else if matches!(self.tok(), Tok::Plus) {
            self.bump();
            return self.guarded("expression", |p| p.unary());
        } else {
            None
        };
        if let Some(op) = op {
            self.bump();
            // The operand of a unary operator may itself be a power expression: -2**2 = -(2**2).
            let mut operand = self.guarded("expression", |p| p.unary())?;
            while matches!(self.tok(), Tok::Power) {
                self.bump();
                let rhs = self.power_operand()?;
                let span = operand.span.to(rhs.span);
                operand = Expr {
                    kind: ExprKind::Binary(BinOp::Pow, Box::new(operand), Box::new(rhs)),
                    span,
                };
            }
            let span = start.to(operand.span);
            return Ok(Expr {
                kind: ExprKind::Unary(op, Box::new(operand)),
                span,
            });
        }
        self.postfix()
    }

    pub(super) fn postfix(&mut self) -> PResult<Expr> {
        let mut e = self.primary()?;
        loop {
            if matches!(self.tok(), Tok::Caret) {
                let span = e.span.to(self.span());
                self.bump();
                e = Expr {
                    kind: ExprKind::Deref(Box::new(e)),
                    span,
                };
            } else if matches!(self.tok(), Tok::Dot) {
                self.bump();
                if let Some((width, index)) = self.partial_access()? {
                    let span = e.span.to(self.prev_span());
                    e = Expr {
                        kind: ExprKind::Bits {
                            base: Box::new(e),
                            width,
                            index,
                        },
                        span,
                    };
                    continue;
                }
                let member = self.ident()?;
                let span = e.span.to(member.span);
                e = Expr {
                    kind: ExprKind::Member(Box::new(e), member),
                    span,
                };
            } else if matches!(self.tok(), Tok::LBracket) {
                self.bump();
                let mut idx = vec![self.expr()?];
                while self.eat(&Tok::Comma) {
                    idx.push(self.expr()?);
                }
                self.expect(Tok::RBracket)?;
                let span = e.span.to(self.prev_span());
                e = Expr {
                    kind: ExprKind::Index(Box::new(e), idx),
                    span,
                };
            } else if matches!(self.tok(), Tok::LParen)
                && matches!(
                    e.kind,
                    ExprKind::Name(_)
                        | ExprKind::Member(..)
                        | ExprKind::Index(..)
                        | ExprKind::Deref(..)
                )
            {
                self.bump();
                let mut args = Vec::new();
                if !matches!(self.tok(), Tok::RParen) {
                    loop {
                        args.push(self.arg()?);
                        if !self.eat(&Tok::Comma) {
                            break;
                        }
                    }
                }
                self.expect(Tok::RParen)?;
                let span = e.span.to(self.prev_span());
                e = Expr {
                    kind: ExprKind::Call {
                        callee: Box::new(e),
                        args,
                    },
                    span,
                };
            } else {
                return Ok(e);
            }
        }
    }

    /// After a `.`: a partial access `N` (bit N) or `%X3`, `%B1`, `%W0`, `%D1`, `%L0`, as
    /// (width in bits, index); `None` when a member name follows instead.
    pub(super) fn partial_access(&mut self) -> PResult<Option<(u8, u32)>> {
        let (width, index) = match self.tok().clone() {
            Tok::Int(n) => (1, n),
            Tok::Direct(text) => {
                let width = match text.as_bytes().first() {
                    Some(b'X') => 1,
                    Some(b'B') => 8,
                    Some(b'W') => 16,
                    Some(b'D') => 32,
                    Some(b'L') => 64,
                    _ => 0,
                };
                match text.get(1..).unwrap_or("").parse::<u128>() {
                    Ok(n) if width != 0 => (width, n),
                    _ => {
                        return Err(self.error_here(
                            "a partial access such as `%X3`, `%B1`, `%W0`, `%D1` or `%L0`",
                        ));
                    }
                }
            }
            _ => return Ok(None),
        };
        let Ok(index) = u32::try_from(index) else {
            return Err(self.error_here("a bit number that fits the variable"));
        };
        self.bump();
        Ok(Some((width, index)))
    }

    pub(super) fn arg(&mut self) -> PResult<Arg> {
        let start = self.span();
        if let Tok::Ident(..) = self.tok()
            && matches!(self.tok_at(1), Tok::Assign | Tok::Arrow)
        {
            let output = matches!(self.tok_at(1), Tok::Arrow);
            let name = self.ident()?;
            self.bump();
            let value = self.expr()?;
            return Ok(Arg {
                name: Some(name),
                output,
                value,
                span: start.to(self.prev_span()),
            });
        }
        let value = self.expr()?;
        Ok(Arg {
            name: None,
            output: false,
            span: value.span,
            value,
        })
    }

    pub(super) fn primary(&mut self) -> PResult<Expr> {
        let span = self.span();
        let kind = match self.tok().clone() {
            Tok::Int(v) => ExprKind::Int(v),
            Tok::Real(v) => ExprKind::Real(v),
            Tok::Time(v) => ExprKind::Time(v),
            Tok::Temporal(e, v) => ExprKind::Temporal(e, v),
            Tok::Str(s) => ExprKind::Str(s),
            Tok::WStr(s) => ExprKind::WStr(s),
            Tok::LParen => {
                self.bump();
                let e = self.expr()?;
                self.expect(Tok::RParen)?;
                return Ok(Expr {
                    kind: e.kind,
                    span: span.to(self.prev_span()),
                });
            }
            Tok::TypePrefix(u, o) => {
                self.bump();
                let ty = Ident {
                    name: u,
                    text: o,
                    span,
                };
                let neg = self.eat(&Tok::Minus);
                let vspan = self.span();
                let mut value = match self.tok().clone() {
                    Tok::Int(v) => Expr {
                        kind: ExprKind::Int(v),
                        span: vspan,
                    },
                    Tok::Real(v) => Expr {
                        kind: ExprKind::Real(v),
                        span: vspan,
                    },
                    Tok::Str(s) => Expr {
                        kind: ExprKind::Str(s),
                        span: vspan,
                    },
                    Tok::WStr(s) => Expr {
                        kind: ExprKind::WStr(s),
                        span: vspan,
                    },
                    Tok::Ident(u, _) if u == "TRUE" => Expr {
                        kind: ExprKind::Bool(true),
                        span: vspan,
                    },
                    Tok::Ident(u, _) if u == "FALSE" => Expr {
                        kind: ExprKind::Bool(false),
                        span: vspan,
                    },
                    Tok::Ident(u, o) if !neg && !RESERVED.contains(&u.as_str()) => Expr {
                        kind: ExprKind::Name(Ident {
                            name: u,
                            text: o,
                            span: vspan,
                        }),
                        span: vspan,
                    },
                    _ => return Err(self.error_here("a literal after the type prefix")),
                };
                self.bump();
                if neg {
                    value = Expr {
                        kind: ExprKind::Unary(UnOp::Neg, Box::new(value)),
                        span: vspan,
                    };
                }
                let full = span.to(self.prev_span());
                return Ok(Expr {
                    kind: ExprKind::Typed(ty, Box::new(value)),
                    span: full,
                });
            }
            Tok::Ident(u, o) => match u.as_str() {
                "TRUE" => ExprKind::Bool(true),
                "FALSE" => ExprKind::Bool(false),
                "NULL" => ExprKind::Null,
                "THIS" => ExprKind::This,
                "SUPER" => ExprKind::Super,
                _ if RESERVED.contains(&u.as_str()) => return Err(self.error_here("an expression")),
                _ => ExprKind::Name(Ident {
                    name: u,
                    text: o,
                    span,
                }),
            },
            _ => return Err(self.error_here("an expression")),
        };
        self.bump();
        Ok(Expr { kind, span })
    }
}
