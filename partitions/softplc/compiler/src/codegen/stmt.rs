//! Statements: assignments, IF, CASE, loops, EXIT/RETURN and exception blocks. Their rules
//! are the statement checker's ([`crate::sema::stmt`]): this walk emits a checked body.

use super::*;

impl Gen<'_> {
    pub(super) fn stmts(&mut self, list: &[Stmt]) {
        for s in list {
            self.stmt(s);
        }
    }

    pub(super) fn stmt(&mut self, s: &Stmt) {
        self.set_location(s.span);
        match &s.kind {
            StmtKind::Empty => {}
            StmtKind::Assign { target, value } => self.assign(target, value),
            StmtKind::RefAssign { target, value } => self.ref_assign(target, value),
            StmtKind::Call(e) => {
                let t = self.expr(e, None);
                if !matches!(t, Type::Void | Type::Error) {
                    self.op(Opcode::Drop);
                }
            }
            StmtKind::If {
                branches,
                else_body,
            } => {
                let end = self.label();
                for (k, (cond, body)) in branches.iter().enumerate() {
                    let next = self.label();
                    self.condition(cond);
                    self.emit(|b| b.jz(next));
                    self.stmts(body);
                    // The last branch without ELSE falls through to the end.
                    if k + 1 < branches.len() || else_body.is_some() {
                        self.emit(|b| b.jmp(end));
                    }
                    self.bind(next);
                }
                if let Some(b) = else_body {
                    self.stmts(b);
                }
                self.bind(end);
            }
            StmtKind::Case {
                selector,
                arms,
                else_body,
            } => self.case(selector, arms, else_body.as_deref()),
            StmtKind::For {
                var,
                from,
                to,
                by,
                body,
            } => self.for_loop(var, from, to, by.as_ref(), body),
            StmtKind::While { cond, body } => {
                // Rotated: the condition is tested after the body (one jump per iteration).
                let top = self.label();
                let test = self.label();
                let exit = self.label();
                self.emit(|b| b.jmp(test));
                self.bind(top);
                self.loops.push(LoopCtx {
                    exit,
                    try_depth: self.try_depth,
                });
                self.stmts(body);
                self.loops.pop();
                self.bind(test);
                self.set_location(s.span);
                self.condition(cond);
                self.emit(|b| b.jnz(top));
                self.bind(exit);
            }
            StmtKind::Repeat { body, until } => {
                let top = self.label();
                let exit = self.label();
                self.bind(top);
                self.loops.push(LoopCtx {
                    exit,
                    try_depth: self.try_depth,
                });
                self.stmts(body);
                self.loops.pop();
                self.set_location(until.span);
                self.condition(until);
                self.emit(|b| b.jz(top));
                self.bind(exit);
            }
            StmtKind::Exit => {
                // The checker let no EXIT outside a loop through.
                if let Some(l) = self.loops.last() {
                    let exit = l.exit;
                    for _ in l.try_depth..self.try_depth {
                        self.emit(|b| b.try_end());
                    }
                    self.emit(|b| b.jmp(exit));
                }
            }
            StmtKind::Return => {
                for _ in 0..self.try_depth {
                    self.emit(|b| b.try_end());
                }
                if let Some(r) = self.return_label {
                    self.emit(|b| b.jmp(r));
                }
            }
            StmtKind::Try {
                body,
                catch_var,
                catch_body,
                finally_body,
            } => self.try_stmt(body, catch_var.as_ref(), catch_body, finally_body),
        }
    }

    pub(super) fn try_stmt(
        &mut self,
        body: &[Stmt],
        catch_var: Option<&Ident>,
        catch_body: &[Stmt],
        finally_body: &[Stmt],
    ) {
        let has_catch = catch_var.is_some() || !catch_body.is_empty();
        let handler = self.label();
        let finally = self.label();
        let pending = self.temp_cell();
        self.emit(|b| b.try_begin(handler));
        self.try_depth += 1;
        self.stmts(body);
        self.try_depth -= 1;
        self.emit(|b| {
            b.try_end();
            b.push_i32(0);
            b.jmp(finally);
            b.bind(handler);
        });
        // The trap code is on the stack here.
        if has_catch {
            let catch_place = catch_var.and_then(|v| {
                self.place(&Expr {
                    kind: ExprKind::Name(v.clone()),
                    span: v.span,
                })
            });
            match catch_place {
                Some(p) => self.store_top(&p),
                None => self.op(Opcode::Drop),
            }
            self.stmts(catch_body);
            self.emit(|b| b.push_i32(0));
        }
        self.bind(finally);
        self.emit(|b| b.st_abs(MemType::I64, pending));
        self.stmts(finally_body);
        if !has_catch {
            // No handler: the trap continues to the next enclosing __TRY (or ends the cycle).
            self.emit(|b| {
                b.ld_abs(MemType::I64, pending);
                b.rethrow();
            });
        }
    }

    /// Stores the top of stack into a place whose address part (if any) is below it...
    /// only valid for static places (`Abs`/`Rel`).
    pub(super) fn store_top(&mut self, p: &Place) {
        if p.window.is_some() {
            self.store_checked(p);
            return;
        }
        let Some(mt) = scalar_mem(&p.ty) else { return };
        match p.loc {
            Loc::Abs(a) => self.emit(|b| b.st_abs(mt, a)),
            Loc::Rel(o) => self.emit(|b| b.st_rel(mt, o)),
            Loc::Ind(_) | Loc::Ref(_) => {
                // The address was pushed before the value; not used for catch variables.
                self.op(Opcode::Drop);
                self.op(Opcode::Drop);
            }
        }
    }

    /// A condition's value (BOOL).
    pub(super) fn condition(&mut self, e: &Expr) {
        self.expr(e, Some(&Type::BOOL));
    }

    pub(super) fn case(&mut self, selector: &Expr, arms: &[CaseArm], else_body: Option<&[Stmt]>) {
        let st = self.expr(selector, None);
        let signed = st
            .elem()
            .is_none_or(|e| e.signed_storage() || !e.is_integral() || e.size() < 8);
        let end = self.label();
        let mut arm_labels = Vec::new();
        for arm in arms {
            let l = self.label();
            arm_labels.push(l);
            for lab in &arm.labels {
                let (lo_e, hi_e) = match lab {
                    CaseLabel::Value(v) => (v, v),
                    CaseLabel::Range(a, b) => (a, b),
                };
                let (Some(lo), Some(hi)) = (self.checked_label(lo_e), self.checked_label(hi_e))
                else {
                    continue;
                };
                if lo == hi {
                    self.emit(|b| {
                        b.dup();
                        b.push_int(lo as i64);
                        b.op(Opcode::Eq);
                        b.jnz(l);
                    });
                } else {
                    let (ge, le) = if signed {
                        (Opcode::GeS, Opcode::LeS)
                    } else {
                        (Opcode::GeU, Opcode::LeU)
                    };
                    self.emit(|b| {
                        b.dup();
                        b.push_int(lo as i64);
                        b.op(ge);
                        b.over();
                        b.push_int(hi as i64);
                        b.op(le);
                        b.op(Opcode::And);
                        b.jnz(l);
                    });
                }
            }
        }
        self.op(Opcode::Drop);
        if let Some(e) = else_body {
            self.stmts(e);
        }
        self.emit(|b| b.jmp(end));
        for (arm, l) in arms.iter().zip(arm_labels) {
            self.bind(l);
            self.op(Opcode::Drop);
            self.stmts(&arm.body);
            self.emit(|b| b.jmp(end));
        }
        self.bind(end);
    }

    /// A CASE label's value as the checker recorded it.
    fn checked_label(&mut self, e: &Expr) -> Option<i128> {
        let v = self.case_labels.of(e).copied();
        if v.is_none() {
            self.missing_record(e.span, "recorded no value for this CASE label");
        }
        v
    }

    pub(super) fn for_loop(
        &mut self,
        var: &Ident,
        from: &Expr,
        to: &Expr,
        by: Option<&Expr>,
        body: &[Stmt],
    ) {
        let ve = Expr {
            kind: ExprKind::Name(var.clone()),
            span: var.span,
        };
        // The checker passed only a plain integer variable.
        let Some(vp) = self.place(&ve) else { return };
        let Some(elem) = vp.ty.elem() else { return };
        let vty = vp.ty.clone();
        // i := from
        self.value_to(from, &vty);
        self.store_checked(&vp);
        let step_const = match by {
            None => Some(1i128),
            Some(e) => match self.const_value(e) {
                Some(ConstVal::Int(v)) => Some(v),
                _ => None,
            },
        };
        // The end value is evaluated once into a hidden temporary; the loop tests compare
        // with the constant instead when `to` is one that fits the control variable's type.
        let end_const = match self.const_value(to) {
            Some(ConstVal::Int(v)) if type_holds(elem, v) && i32::try_from(v).is_ok() => {
                Some(v as i64)
            }
            _ => None,
        };
        let end_slot = self.temp_cell();
        self.value_to(to, &vty);
        self.emit(|b| b.st_abs(MemType::I64, end_slot));
        let step_slot = self.temp_cell();
        if step_const.is_none() {
            if let Some(e) = by {
                self.value_to(e, &vty);
            }
            self.emit(|b| b.st_abs(MemType::I64, step_slot));
        }
        let signed = elem.signed_storage() || elem.size() < 8;
        let (le, ge) = if signed {
            (Opcode::LeS, Opcode::GeS)
        } else {
            (Opcode::LeU, Opcode::GeU)
        };
        let top = self.label();
        let exit = self.label();
        let mt = mem_type(elem);
        let load_var = |g: &mut Self| match vp.loc {
            Loc::Abs(a) => g.emit(|b| b.ld_abs(mt, a)),
            Loc::Rel(o) => g.emit(|b| b.ld_rel(mt, o)),
            Loc::Ind(_) | Loc::Ref(_) => {}
        };
        let load_end = |g: &mut Self| match end_const {
            Some(v) => g.push_int(v),
            None => g.emit(|b| b.ld_abs(MemType::I64, end_slot)),
        };
        // The loop test `i <= end` (`>=` for a negative step; both, chosen by the step's sign,
        // for a computed step): jumps to `target` when it holds (`when`) or when it does not.
        let test = |g: &mut Self, when: bool, target: Label| match step_const {
            Some(s) => {
                load_var(g);
                load_end(g);
                g.op(if s > 0 { le } else { ge });
                g.emit(|b| if when { b.jnz(target) } else { b.jz(target) });
            }
            None => {
                let neg = g.label();
                let done = g.label();
                g.emit(|b| {
                    b.ld_abs(MemType::I64, step_slot);
                    b.push_i32(0);
                    b.op(Opcode::LtS);
                    b.jnz(neg);
                });
                load_var(g);
                load_end(g);
                g.op(le);
                g.emit(|b| {
                    if when {
                        b.jnz(target);
                    } else {
                        b.jz(target);
                    }
                    b.jmp(done);
                    b.bind(neg);
                });
                load_var(g);
                load_end(g);
                g.op(ge);
                g.emit(|b| {
                    if when {
                        b.jnz(target);
                    } else {
                        b.jz(target);
                    }
                    b.bind(done);
                });
            }
        };
        // Rotated: tested once before the first iteration, then after each increment (one
        // jump per iteration).
        test(self, false, exit);
        self.bind(top);
        self.loops.push(LoopCtx {
            exit,
            try_depth: self.try_depth,
        });
        self.stmts(body);
        self.loops.pop();
        load_var(self);
        match step_const {
            Some(s) => self.push_int(s as i64),
            None => self.emit(|b| b.ld_abs(MemType::I64, step_slot)),
        }
        self.op(Opcode::Add);
        self.wrap(elem);
        match vp.loc {
            Loc::Abs(a) => self.emit(|b| b.st_abs(mt, a)),
            Loc::Rel(o) => self.emit(|b| b.st_rel(mt, o)),
            Loc::Ind(_) | Loc::Ref(_) => {}
        }
        test(self, true, top);
        self.bind(exit);
    }

    pub(super) fn assign(&mut self, target: &Expr, value: &Expr) {
        if self.property_write(target, value) {
            return;
        }
        if let Some(p) = self.place(target) {
            self.store_expr(&p, value);
        }
    }

    /// `r REF= x`: binds the `REFERENCE TO` variable `r` to `x` (or to NULL).
    pub(super) fn ref_assign(&mut self, target: &Expr, value: &Expr) {
        let saved = std::mem::replace(&mut self.refs.keep_reference, true);
        let p = self.place(target);
        self.refs.keep_reference = saved;
        let Some(p) = p else { return };
        let Type::Reference(t) = p.ty.clone() else {
            return;
        };
        let cell = Place {
            ty: Type::Ref(t.clone()),
            ..p
        };
        match &value.kind {
            ExprKind::Null | ExprKind::Int(0) => self.push_int(0),
            _ => {
                let rt = self.make_reference(value, Some(&Type::Ref(t.clone())));
                self.coerce(&rt, &Type::Ref(t), value);
            }
        }
        self.store_checked(&cell);
    }

    /// Evaluates `value` and stores it into `p` (whose address, for `Ind`, is already on the
    /// stack); the checker's [`check_store`](crate::sema::stmt::check_store) passed it.
    pub(crate) fn store_expr(&mut self, p: &Place, value: &Expr) {
        match &p.ty {
            Type::String(_) | Type::WString(_) => {
                self.addr_of(p);
                self.expr(value, Some(&p.ty));
                let wide = p.ty.is_wstring();
                self.emit(|b| {
                    b.call_builtin(if wide {
                        Builtin::WStrAssign
                    } else {
                        Builtin::StrAssign
                    })
                });
            }
            Type::Array(_) | Type::Struct(_) | Type::Fb(_) => {
                self.addr_of(p);
                self.expr(value, Some(&p.ty));
                let (size, _) = self.prog.size_align(&p.ty);
                self.emit(|b| b.copy(size));
            }
            Type::Error | Type::Void => {
                if matches!(p.loc, Loc::Ind(_)) {
                    self.op(Opcode::Drop);
                }
                self.infer(value);
            }
            _ => {
                self.value_to(value, &p.ty.clone());
                self.store_checked(p);
            }
        }
    }

    /// Stores the elementary value on top of the stack into `p`, checking subranges.
    pub(crate) fn store_checked(&mut self, p: &Place) {
        if let Some(w) = p.window {
            // Read, modify, write the variable: (old AND NOT m) OR (v << shift).
            let mt = mem_type(w.container);
            let keep = !(w.mask() << w.shift) as i64;
            self.emit(|b| {
                if w.width < 64 {
                    b.push_int(w.mask() as i64);
                    b.op(Opcode::And);
                }
                if w.shift != 0 {
                    b.push_i32(w.shift as i32);
                    b.op(Opcode::Shl);
                }
            });
            match p.loc {
                Loc::Abs(a) => self.emit(|b| {
                    b.ld_abs(mt, a);
                    b.push_int(keep);
                    b.op(Opcode::And);
                    b.op(Opcode::Or);
                    b.st_abs(mt, a);
                }),
                Loc::Rel(o) => self.emit(|b| {
                    b.ld_rel(mt, o);
                    b.push_int(keep);
                    b.op(Opcode::And);
                    b.op(Opcode::Or);
                    b.st_rel(mt, o);
                }),
                Loc::Ind(o) => self.emit(|b| {
                    b.over();
                    b.ld_ind(mt, o);
                    b.push_int(keep);
                    b.op(Opcode::And);
                    b.op(Opcode::Or);
                    b.st_ind(mt, o);
                }),
                Loc::Ref(_) => unreachable!("places are finalized"),
            }
            return;
        }
        if let Type::Subrange(e, lo, hi) = p.ty {
            if e.signed_storage() || e.size() < 8 {
                self.emit(|b| b.chk_range_s(lo, hi));
            } else {
                self.emit(|b| b.chk_range_u(lo as u64, hi as u64));
            }
        }
        let Some(mt) = scalar_mem(&p.ty) else { return };
        match p.loc {
            Loc::Abs(a) => self.emit(|b| b.st_abs(mt, a)),
            Loc::Rel(o) => self.emit(|b| b.st_rel(mt, o)),
            Loc::Ind(o) => self.emit(|b| b.st_ind(mt, o)),
            Loc::Ref(_) => unreachable!("places are finalized"),
        }
    }
}
