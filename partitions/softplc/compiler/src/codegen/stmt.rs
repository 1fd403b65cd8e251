//! Statements: assignments, IF, CASE, loops, EXIT/RETURN and exception blocks.

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
            StmtKind::Exit => match self.loops.last() {
                Some(l) => {
                    let exit = l.exit;
                    for _ in l.try_depth..self.try_depth {
                        self.emit(|b| b.try_end());
                    }
                    self.emit(|b| b.jmp(exit));
                }
                None if self.check_only => {
                    self.error(codes::EXIT_OUTSIDE_LOOP, s.span, "EXIT outside of a loop")
                }
                None => self.diags.error(
                    codes::INTERNAL_ERROR,
                    s.span,
                    "internal error: EXIT outside of a loop passed the checker",
                ),
            },
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
            match catch_var {
                Some(v) => {
                    let e = Expr {
                        kind: ExprKind::Name(v.clone()),
                        span: v.span,
                    };
                    match self.place(&e) {
                        Some(p)
                            if matches!(p.ty, Type::Exception)
                                || p.ty.elem().is_some_and(|e| e.is_integral()) =>
                        {
                            self.store_top(&p)
                        }
                        Some(p) => {
                            let msg = format!(
                                "exception variable must be declared `: __EXCEPTION`, not {}",
                                self.tname(&p.ty)
                            );
                            self.error(codes::EXCEPTION_VARIABLE, v.span, msg);
                            self.op(Opcode::Drop);
                        }
                        None => self.op(Opcode::Drop),
                    }
                }
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

    /// A condition's value; the checking pass requires it to be BOOL.
    pub(super) fn condition(&mut self, e: &Expr) {
        let t = self.expr(e, Some(&Type::BOOL));
        if self.check_only && !t.is_error() && t != Type::BOOL {
            let msg = format!("condition must be BOOL, found {}", self.tname(&t));
            self.error(codes::TYPE_MISMATCH, e.span, msg);
        }
    }

    pub(super) fn case(&mut self, selector: &Expr, arms: &[CaseArm], else_body: Option<&[Stmt]>) {
        let st = self.expr(selector, None);
        if self.check_only {
            self.check_case(selector, &st, arms);
        }
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

    /// The checking pass's rules for a CASE: the selector's type, each label's value (recorded
    /// for emission), no empty range, no overlap.
    fn check_case(&mut self, selector: &Expr, st: &Type, arms: &[CaseArm]) {
        let ok = matches!(st, Type::Enum(_) | Type::Exception | Type::Error)
            || st.elem().is_some_and(|e| e.is_integral());
        if !ok {
            let msg = format!(
                "CASE selector must be an integer or enumeration, found {}",
                self.tname(st)
            );
            self.error(codes::CASE_SELECTOR, selector.span, msg);
        }
        let mut seen: Vec<(i128, i128)> = Vec::new();
        for lab in arms.iter().flat_map(|arm| &arm.labels) {
            let (lo_e, hi_e) = match lab {
                CaseLabel::Value(v) => (v, v),
                CaseLabel::Range(a, b) => (a, b),
            };
            let lo = self.case_label_value(lo_e, st);
            let hi = self.case_label_value(hi_e, st);
            let (Some(lo), Some(hi)) = (lo, hi) else {
                continue;
            };
            self.case_labels.record(lo_e, lo);
            self.case_labels.record(hi_e, hi);
            if lo > hi {
                self.error(
                    codes::CASE_LABEL,
                    lo_e.span.to(hi_e.span),
                    "empty CASE range (lower bound exceeds upper bound)",
                );
            }
            if seen.iter().any(|(a, b)| lo <= *b && *a <= hi) {
                self.error(
                    codes::CASE_LABEL,
                    lo_e.span,
                    "CASE label overlaps an earlier label",
                );
            }
            seen.push((lo, hi));
        }
    }

    /// A CASE label's value as the checking pass recorded it (none for a label it rejected,
    /// which only the checking pass can meet).
    fn checked_label(&mut self, e: &Expr) -> Option<i128> {
        let v = self.case_labels.of(e).copied();
        if v.is_none() && !self.check_only {
            self.diags.error(
                codes::INTERNAL_ERROR,
                e.span,
                "internal error: the checker recorded no value for this CASE label",
            );
        }
        v
    }

    pub(super) fn case_label_value(&mut self, e: &Expr, sel: &Type) -> Option<i128> {
        // Enumeration labels may be bare value names of the selector's enumeration.
        if let (Type::Enum(ei), ExprKind::Name(n)) = (sel, &e.kind)
            && let Some((_, v)) = self.prog.enums[*ei]
                .values
                .iter()
                .find(|(vn, _)| *vn == n.name)
        {
            return Some(*v as i128);
        }
        if let (Type::Exception, ExprKind::Name(n)) = (sel, &e.kind)
            && let Some(t) = Trap::ALL.iter().find(|t| t.name() == n.name)
        {
            return Some(t.code() as i128);
        }
        match self.const_value(e) {
            Some(ConstVal::Int(v)) => Some(v),
            _ => {
                self.error(
                    codes::CASE_LABEL,
                    e.span,
                    "CASE label must be a constant integer or enumeration value",
                );
                None
            }
        }
    }

    /// The control variable of a FOR loop and its integer type; reported unless it is a plain
    /// integer variable.
    fn for_control_variable(&mut self, var: &Ident) -> Option<(Place, Elem)> {
        let ve = Expr {
            kind: ExprKind::Name(var.clone()),
            span: var.span,
        };
        let vp = self.place(&ve)?;
        let Some(elem) = vp
            .ty
            .elem()
            .filter(|e| e.is_integral() && !matches!(vp.ty, Type::Enum(_)))
        else {
            let msg = format!(
                "FOR control variable must be an integer, found {}",
                self.tname(&vp.ty)
            );
            self.error(codes::FOR_VARIABLE, var.span, msg);
            return None;
        };
        if !matches!(vp.loc, Loc::Abs(_) | Loc::Rel(_)) || vp.window.is_some() {
            self.error(
                codes::FOR_VARIABLE,
                var.span,
                "FOR control variable must be a plain variable",
            );
            return None;
        }
        Some((vp, elem))
    }

    pub(super) fn for_loop(
        &mut self,
        var: &Ident,
        from: &Expr,
        to: &Expr,
        by: Option<&Expr>,
        body: &[Stmt],
    ) {
        let Some((vp, elem)) = self.for_control_variable(var) else {
            return;
        };
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
        if self.check_only && step_const == Some(0) {
            self.error(
                codes::FOR_STEP_ZERO,
                by.map_or(var.span, |e| e.span),
                "FOR step must not be zero",
            );
        }
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
        let Some(p) = self.place(target) else {
            // Still check the value for errors.
            self.infer(value);
            return;
        };
        if self.check_only && !p.writable {
            self.error(
                codes::ASSIGN_TO_READ_ONLY,
                target.span,
                "cannot assign to a constant or an input of another POU",
            );
        }
        if p.ty.is_pointer_like() {
            self.check_escape(Some(target), value, "this variable");
        }
        self.store_expr(&p, value, target.span);
    }

    /// `r REF= x`: binds the `REFERENCE TO` variable `r` to `x` (or to NULL).
    pub(super) fn ref_assign(&mut self, target: &Expr, value: &Expr) {
        let saved = std::mem::replace(&mut self.refs.keep_reference, true);
        let p = self.place(target);
        self.refs.keep_reference = saved;
        let Some(p) = p else {
            self.infer(value);
            return;
        };
        let Type::Reference(t) = p.ty.clone() else {
            if self.check_only && !p.ty.is_error() {
                let msg = format!(
                    "`REF=` binds a REFERENCE TO variable, not {}",
                    self.tname(&p.ty)
                );
                self.error(codes::REF_ASSIGN_TARGET, target.span, msg);
            }
            self.drop_place_value(&p);
            self.infer(value);
            return;
        };
        let cell = Place {
            ty: Type::Ref(t.clone()),
            ..p
        };
        match &value.kind {
            ExprKind::Null | ExprKind::Int(0) => self.push_int(0),
            _ => {
                let args = [Arg {
                    name: None,
                    output: false,
                    value: value.clone(),
                    span: value.span,
                }];
                let id = Ident {
                    name: "REF".into(),
                    text: "REF".into(),
                    span: value.span,
                };
                let as_ref = Expr {
                    kind: ExprKind::Call {
                        callee: Box::new(Expr {
                            kind: ExprKind::Name(id.clone()),
                            span: value.span,
                        }),
                        args: args.to_vec(),
                    },
                    span: value.span,
                };
                self.check_escape(Some(target), &as_ref, "this variable");
                let rt = self.ref_function(&id, &args, Some(&Type::Ref(t.clone())), value.span);
                self.coerce(&rt, &Type::Ref(t), value.span);
            }
        }
        self.store_checked(&cell);
    }

    pub(super) fn drop_place_value(&mut self, p: &Place) {
        if matches!(p.loc, Loc::Ind(_) | Loc::Ref(_)) {
            self.op(Opcode::Drop);
        }
    }

    /// Evaluates `value` and stores it into `p` (whose address, for `Ind`, is already on the stack).
    pub(crate) fn store_expr(&mut self, p: &Place, value: &Expr, span: Span) {
        match &p.ty {
            Type::String(_) | Type::WString(_) => {
                self.addr_of(p);
                let t = self.expr(value, Some(&p.ty));
                let wide = p.ty.is_wstring();
                let text = t.is_string() || t.is_wstring();
                if self.check_only && (t.is_wstring() != wide || !text) && !t.is_error() {
                    let hint = match (wide, text) {
                        (true, true) => " (use STRING_TO_WSTRING)",
                        (false, true) => " (use WSTRING_TO_STRING)",
                        _ => "",
                    };
                    let msg = format!(
                        "cannot assign {} to {}{hint}",
                        self.tname(&t),
                        self.tname(&p.ty)
                    );
                    self.error(codes::ASSIGN_TYPE, value.span, msg);
                }
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
                let t = self.expr(value, Some(&p.ty));
                if self.check_only && t != p.ty && !t.is_error() {
                    let msg = format!("cannot assign {} to {}", self.tname(&t), self.tname(&p.ty));
                    self.error(codes::ASSIGN_TYPE, value.span, msg);
                }
                if self.check_only && matches!(p.ty, Type::Fb(_)) {
                    self.error(
                        codes::ASSIGN_FB_INSTANCE,
                        span,
                        "function block instances cannot be assigned",
                    );
                }
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
