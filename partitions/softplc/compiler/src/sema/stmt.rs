//! The statement checker: the rules of a body's statements, checked in a walk of their own
//! before anything is emitted.
//!
//! It owns every rule that belongs to a statement: a condition of IF, WHILE and REPEAT is
//! BOOL; EXIT stands inside a loop; a CASE selector is an integer or an enumeration and its
//! labels are constants of that type, no range empty, none overlapping (their values are
//! recorded for emission); a FOR control variable is a plain integer variable and a constant
//! step is not zero; an assignment's target is writable, its value assignable (a STRING to a
//! STRING, an aggregate to one of its own type, never a function block instance) and no
//! reference to temporary storage escapes into it; a `REF=` target is a `REFERENCE TO`
//! variable; a `__CATCH` variable is an `__EXCEPTION`. Expressions are checked (and their
//! types, callees and names recorded, see [`crate::typed`]) by the expression checker
//! ([`crate::sema::expr`] and the checkers it calls), which this walk calls for each
//! expression in the order the statement evaluates them, so the diagnostics come in source
//! order as the emitter meets the expressions. The emitter's statement walk
//! ([`crate::codegen`]) checks nothing: it runs only on a body this walk passed.

use plc_vm::isa::Trap;

use crate::ast::{CaseArm, CaseLabel, Expr, ExprKind, Ident, Stmt, StmtKind};
use crate::codegen::{Gen, Loc, Place};
use crate::codes;
use crate::diagnostics::Span;
use crate::sema::ConstVal;
use crate::sema::expr::{check, coerce, sync_records, value_to};
use crate::sema::place::place;
use crate::sema::refs::{check_escape, make_reference, reference_to, scan_temporary_references};
use crate::types::Type;

/// Checks the statements of the body of the POU `g` is at (`g` in its checking mode).
pub(crate) fn check_body(g: &mut Gen, body: &[Stmt]) {
    BodyChecker { g, loops: 0 }.stmts(body);
}

/// Checks the body of POU `pou` (and records what emission needs of it).
pub(crate) fn check_pou(g: &mut Gen, pou: usize) {
    g.cur = pou;
    let unit = g.unit;
    let body = crate::classes::pou_source(unit, &g.prog.pous[pou]).body;
    g.scan_byte_views(body);
    scan_temporary_references(g, body);
    check_body(g, body);
    // Emission re-reads the length of the strings written through byte pointers on return.
    for name in g.refs.byte_viewed.clone() {
        let id = Ident {
            text: name.clone(),
            name,
            span: Span::default(),
        };
        sync_records(g, &id);
    }
}

/// Checks storing `value` into `p`: an assignment's value or a function block's input.
pub(crate) fn check_store(g: &mut Gen, p: &Place, value: &Expr, span: Span) {
    match &p.ty {
        Type::String(_) | Type::WString(_) => {
            let t = check(g, value, Some(&p.ty));
            let wide = p.ty.is_wstring();
            let text = t.is_string() || t.is_wstring();
            if (t.is_wstring() != wide || !text) && !t.is_error() {
                let hint = match (wide, text) {
                    (true, true) => " (use STRING_TO_WSTRING)",
                    (false, true) => " (use WSTRING_TO_STRING)",
                    _ => "",
                };
                let msg = format!("cannot assign {} to {}{hint}", g.tname(&t), g.tname(&p.ty));
                g.error(codes::ASSIGN_TYPE, value.span, msg);
            }
        }
        Type::Array(_) | Type::Struct(_) | Type::Fb(_) => {
            let t = check(g, value, Some(&p.ty));
            if t != p.ty && !t.is_error() {
                let msg = format!("cannot assign {} to {}", g.tname(&t), g.tname(&p.ty));
                g.error(codes::ASSIGN_TYPE, value.span, msg);
            }
            if matches!(p.ty, Type::Fb(_)) {
                g.error(
                    codes::ASSIGN_FB_INSTANCE,
                    span,
                    "function block instances cannot be assigned",
                );
            }
        }
        Type::Error | Type::Void => {
            g.infer(value);
        }
        ty => value_to(g, value, &ty.clone()),
    }
}

struct BodyChecker<'g, 'a> {
    g: &'g mut Gen<'a>,
    /// How many loops enclose the statement checked (EXIT needs one).
    loops: usize,
}

impl BodyChecker<'_, '_> {
    fn stmts(&mut self, list: &[Stmt]) {
        for s in list {
            self.stmt(s);
        }
    }

    fn stmt(&mut self, s: &Stmt) {
        match &s.kind {
            StmtKind::Empty | StmtKind::Return => {}
            StmtKind::Assign { target, value } => self.assign(target, value),
            StmtKind::RefAssign { target, value } => self.ref_assign(target, value),
            StmtKind::Call(e) => {
                check(self.g, e, None);
            }
            StmtKind::If {
                branches,
                else_body,
            } => {
                for (cond, body) in branches {
                    self.condition(cond);
                    self.stmts(body);
                }
                if let Some(b) = else_body {
                    self.stmts(b);
                }
            }
            StmtKind::Case {
                selector,
                arms,
                else_body,
            } => {
                let st = check(self.g, selector, None);
                self.case_labels(selector, &st, arms);
                if let Some(e) = else_body {
                    self.stmts(e);
                }
                for arm in arms {
                    self.stmts(&arm.body);
                }
            }
            StmtKind::For {
                var,
                from,
                to,
                by,
                body,
            } => self.for_loop(var, from, to, by.as_ref(), body),
            // The emitter tests the condition after the body (a rotated loop): so does this
            // walk, for the same order of diagnostics.
            StmtKind::While { cond, body } => {
                self.loop_body(body);
                self.condition(cond);
            }
            StmtKind::Repeat { body, until } => {
                self.loop_body(body);
                self.condition(until);
            }
            StmtKind::Exit => {
                if self.loops == 0 {
                    self.g
                        .error(codes::EXIT_OUTSIDE_LOOP, s.span, "EXIT outside of a loop");
                }
            }
            StmtKind::Try {
                body,
                catch_var,
                catch_body,
                finally_body,
            } => {
                self.stmts(body);
                if let Some(v) = catch_var {
                    self.catch_variable(v);
                }
                self.stmts(catch_body);
                self.stmts(finally_body);
            }
        }
    }

    fn loop_body(&mut self, body: &[Stmt]) {
        self.loops += 1;
        self.stmts(body);
        self.loops -= 1;
    }

    fn condition(&mut self, e: &Expr) {
        let t = check(self.g, e, Some(&Type::BOOL));
        if !t.is_error() && t != Type::BOOL {
            let msg = format!("condition must be BOOL, found {}", self.g.tname(&t));
            self.g.error(codes::TYPE_MISMATCH, e.span, msg);
        }
    }

    fn catch_variable(&mut self, v: &Ident) {
        let e = Expr {
            kind: ExprKind::Name(v.clone()),
            span: v.span,
        };
        let Some(p) = place(self.g, &e) else { return };
        if !matches!(p.ty, Type::Exception) && !p.ty.elem().is_some_and(|e| e.is_integral()) {
            let msg = format!(
                "exception variable must be declared `: __EXCEPTION`, not {}",
                self.g.tname(&p.ty)
            );
            self.g.error(codes::EXCEPTION_VARIABLE, v.span, msg);
        }
    }

    /// The selector's type, each label's value (recorded for emission), no empty range, no
    /// overlap.
    fn case_labels(&mut self, selector: &Expr, st: &Type, arms: &[CaseArm]) {
        let ok = matches!(st, Type::Enum(_) | Type::Exception | Type::Error)
            || st.elem().is_some_and(|e| e.is_integral());
        if !ok {
            let msg = format!(
                "CASE selector must be an integer or enumeration, found {}",
                self.g.tname(st)
            );
            self.g.error(codes::CASE_SELECTOR, selector.span, msg);
        }
        let mut seen: Vec<(i128, i128)> = Vec::new();
        for lab in arms.iter().flat_map(|arm| &arm.labels) {
            let (lo_e, hi_e) = match lab {
                CaseLabel::Value(v) => (v, v),
                CaseLabel::Range(a, b) => (a, b),
            };
            let lo = self.label_value(lo_e, st);
            let hi = self.label_value(hi_e, st);
            let (Some(lo), Some(hi)) = (lo, hi) else {
                continue;
            };
            self.g.case_labels.record(lo_e, lo);
            self.g.case_labels.record(hi_e, hi);
            if lo > hi {
                self.g.error(
                    codes::CASE_LABEL,
                    lo_e.span.to(hi_e.span),
                    "empty CASE range (lower bound exceeds upper bound)",
                );
            }
            if seen.iter().any(|(a, b)| lo <= *b && *a <= hi) {
                self.g.error(
                    codes::CASE_LABEL,
                    lo_e.span,
                    "CASE label overlaps an earlier label",
                );
            }
            seen.push((lo, hi));
        }
    }

    /// A CASE label's value: a constant integer, a value name of the selector's enumeration
    /// or an exception name.
    fn label_value(&mut self, e: &Expr, sel: &Type) -> Option<i128> {
        if let (Type::Enum(ei), ExprKind::Name(n)) = (sel, &e.kind)
            && let Some((_, v)) = self.g.prog.enums[*ei]
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
        match self.g.const_value(e) {
            Some(ConstVal::Int(v)) => Some(v),
            _ => {
                self.g.error(
                    codes::CASE_LABEL,
                    e.span,
                    "CASE label must be a constant integer or enumeration value",
                );
                None
            }
        }
    }

    fn for_loop(&mut self, var: &Ident, from: &Expr, to: &Expr, by: Option<&Expr>, body: &[Stmt]) {
        let Some(vty) = self.for_control_variable(var) else {
            return;
        };
        value_to(self.g, from, &vty);
        let step = match by {
            None => Some(ConstVal::Int(1)),
            Some(e) => self.g.const_value(e),
        };
        if matches!(step, Some(ConstVal::Int(0))) {
            self.g.error(
                codes::FOR_STEP_ZERO,
                by.map_or(var.span, |e| e.span),
                "FOR step must not be zero",
            );
        }
        value_to(self.g, to, &vty);
        if let Some(e) = by
            && !matches!(step, Some(ConstVal::Int(_)))
        {
            value_to(self.g, e, &vty);
        }
        self.loop_body(body);
    }

    /// The type of a FOR loop's control variable; reported unless it is a plain integer
    /// variable.
    fn for_control_variable(&mut self, var: &Ident) -> Option<Type> {
        let ve = Expr {
            kind: ExprKind::Name(var.clone()),
            span: var.span,
        };
        let vp = place(self.g, &ve)?;
        if !vp.ty.elem().is_some_and(|e| e.is_integral()) || matches!(vp.ty, Type::Enum(_)) {
            let msg = format!(
                "FOR control variable must be an integer, found {}",
                self.g.tname(&vp.ty)
            );
            self.g.error(codes::FOR_VARIABLE, var.span, msg);
            return None;
        }
        if !matches!(vp.loc, Loc::Abs(_) | Loc::Rel(_)) || vp.window.is_some() {
            self.g.error(
                codes::FOR_VARIABLE,
                var.span,
                "FOR control variable must be a plain variable",
            );
            return None;
        }
        Some(vp.ty)
    }

    fn assign(&mut self, target: &Expr, value: &Expr) {
        if crate::sema::class::property_write(self.g, target, value) {
            return;
        }
        let Some(p) = place(self.g, target) else {
            self.g.infer(value);
            return;
        };
        if !p.writable {
            self.g.error(
                codes::ASSIGN_TO_READ_ONLY,
                target.span,
                "cannot assign to a constant or an input of another POU",
            );
        }
        if p.ty.is_pointer_like() {
            check_escape(self.g, Some(target), value, "this variable");
        }
        check_store(self.g, &p, value, target.span);
    }

    /// `r REF= x`: `r` is a `REFERENCE TO` variable, `x` something it may be bound to (or
    /// NULL).
    fn ref_assign(&mut self, target: &Expr, value: &Expr) {
        let saved = std::mem::replace(&mut self.g.refs.keep_reference, true);
        let p = place(self.g, target);
        self.g.refs.keep_reference = saved;
        let Some(p) = p else {
            self.g.infer(value);
            return;
        };
        let Type::Reference(t) = p.ty else {
            if !p.ty.is_error() {
                let msg = format!(
                    "`REF=` binds a REFERENCE TO variable, not {}",
                    self.g.tname(&p.ty)
                );
                self.g.error(codes::REF_ASSIGN_TARGET, target.span, msg);
            }
            self.g.infer(value);
            return;
        };
        if matches!(value.kind, ExprKind::Null | ExprKind::Int(0)) {
            return;
        }
        let as_ref = reference_to(value);
        check_escape(self.g, Some(target), &as_ref, "this variable");
        let ty = Type::Ref(t);
        let rt = make_reference(self.g, value, Some(&ty));
        coerce(self.g, &rt, &ty, value);
    }
}
