//! References: `REF_TO T`, CODESYS `POINTER TO T` and `REFERENCE TO T`, `REF()`, `ADR()`,
//! `NULL`, `^`, pointer arithmetic and comparisons, and the object table that
//! bounds every reference (the VM's "References" in `plc_vm::isa`).
//!
//! A reference to data is a checked cell `address | object << 32`: `REF()` makes it with
//! `REF_MAKE` for the bytes of the referenced variable (or part of a variable), arithmetic
//! moves only its address (`REF_ADD`) and every access through it is checked with
//! `REF_CHECK` for exactly the bytes accessed, so `pt^[i]` with a declared
//! `REF_TO ARRAY[0..32767] OF BYTE` works on any buffer and traps at the first byte outside
//! the variable the reference was taken from. A reference to a function-block instance (and
//! an interface value) is the instance's address, checked for NULL.
//!
//! The object table lists, for every instance and frame, the variables whose address the
//! program takes (`REF()`/`ADR()`, or passing them to a `VAR_IN_OUT` whose address the
//! callee takes): the variable, and for a STRING its header and its text (the bytes a
//! CODESYS byte pointer may walk, terminator included) as separate parts, and for a
//! structure or array holding STRINGs or references each member/element as a part of its
//! own. `REF_MAKE` picks the smallest part, so a byte pointer into a STRING's text cannot
//! overwrite its length header, and a pointer to a plain member of a structure holding
//! references cannot overwrite them.
//!
//! Never here: an integer becoming a reference (an address could name any variable; only
//! `REF()`/`ADR()` and arithmetic on a reference make references).

use crate::codes;
use std::collections::HashSet;

use plc_vm::isa::{Builtin, Opcode};

use crate::ast::*;
use crate::codegen::{Gen, Loc, Place};
use crate::diagnostics::Span;
use crate::sema::align_up;
use crate::sema::expr::{has_real_literal, is_byte_view, is_flexible, is_plain};
use crate::types::*;

/// A variable whose address a program takes: what the object table must list.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(crate) enum Root {
    /// A global variable (upper-case name).
    Global(String),
    /// A variable of a POU (in every instance or frame of it).
    Var(usize, String),
    /// A `VAR_IN_OUT` parameter of a POU: the caller's variable.
    InOut(usize, String),
}

/// What code generation learns about references (see [`Gen::build_objects`]).
#[derive(Debug, Default)]
pub(crate) struct RefState {
    /// Roots of every `REF()`/`ADR()`.
    roots: Vec<Root>,
    /// `VAR_IN_OUT` arguments: (callee, parameter, the argument's root).
    inout_args: Vec<(usize, String, Root)>,
    /// STRING variables of the POU being compiled whose text is reached through a byte
    /// pointer: their length is taken from the terminator when read and on return.
    pub(crate) byte_viewed: Vec<String>,
    /// Set while resolving the target of `REF=` or `__ISVALIDREF`: a `REFERENCE TO` is not
    /// dereferenced.
    pub(crate) keep_reference: bool,
    /// Temporary variables of the POU being compiled that may hold a reference to its
    /// temporary storage (see [`Gen::check_escape`]).
    tainted: HashSet<String>,
    /// ... or one of a FUNCTION's borrowed reference inputs.
    borrowed: HashSet<String>,
}

/// Where a reference value may point, for the checks of references to temporaries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Taint {
    /// Nowhere temporary.
    None,
    /// Into what the caller of the current FUNCTION passed (its reference inputs).
    Borrowed,
    /// Into the current POU's temporary storage.
    Local,
}

/// Deepest object nesting the VM accepts (`plc_vm::image::MAX_OBJECT_DEPTH`).
const MAX_DEPTH: usize = plc_vm::image::MAX_OBJECT_DEPTH;

/// Whether an object of `ty` is listed part by part (it holds STRINGs, references or
/// interface values).
fn split(prog: &crate::sema::Program, ty: &Type) -> bool {
    match ty {
        Type::String(_) => true,
        Type::Array(a) => split(prog, &a.elem) || !is_plain(prog, &a.elem),
        Type::Struct(i) => prog.structs[*i]
            .members
            .iter()
            .any(|m| split(prog, &m.ty) || !is_plain(prog, &m.ty)),
        _ => false,
    }
}

impl Gen<'_> {
    /// Whether `name` is one of the reference functions handled here.
    pub(crate) fn is_ref_function(name: &str) -> bool {
        matches!(name, "REF" | "ADR" | "__ISVALIDREF")
    }

    /// `REF(x)`, `ADR(x)`, `__ISVALIDREF(r)`.
    pub(crate) fn ref_function(
        &mut self,
        id: &Ident,
        args: &[Arg],
        expected: Option<&Type>,
        span: Span,
    ) -> Type {
        if self.check_only && (args.len() != 1 || args[0].name.is_some() || args[0].output) {
            self.error(
                codes::ARGUMENT_COUNT,
                span,
                format!("{} takes one argument", id.text),
            );
            for a in args {
                self.infer(&a.value);
            }
            return Type::Error;
        }
        let arg = &args[0].value;
        match id.name.as_str() {
            "__ISVALIDREF" => {
                let saved = std::mem::replace(&mut self.refs.keep_reference, true);
                let t = self.expr(arg, None);
                self.refs.keep_reference = saved;
                if self.check_only
                    && !matches!(
                        t,
                        Type::Ref(_) | Type::Reference(_) | Type::Interface(_) | Type::Error
                    )
                {
                    let msg = format!(
                        "__ISVALIDREF needs a reference or interface, found {}",
                        self.tname(&t)
                    );
                    self.error(codes::REF_OPERAND, arg.span, msg);
                }
                self.emit(|b| {
                    b.push_i32(0);
                    b.op(Opcode::Ne);
                });
                Type::BOOL
            }
            _ => self.make_reference(arg, expected),
        }
    }

    /// `REF(x)` / `ADR(x)`: a reference to variable `x` (for a function-block instance, its
    /// address). `expected` is the reference type the context wants: a byte pointer
    /// (`REF_TO BYTE`, `POINTER TO ARRAY[..] OF BYTE`, ...) made from a STRING points at its
    /// text.
    pub(crate) fn make_reference(&mut self, arg: &Expr, expected: Option<&Type>) -> Type {
        let root = self.root_of(arg);
        let Some(p) = self.place(arg) else {
            return Type::Error;
        };
        match &p.ty {
            Type::Error => {
                self.drop_loaded(&p);
                Type::Error
            }
            Type::Fb(pi) => {
                let pi = *pi;
                self.addr_of(&p);
                Type::Ref(Box::new(Type::Fb(pi)))
            }
            Type::Array(a) if self.check_only && self.holds_instances(&a.elem) => {
                self.error(codes::REF_OPERAND,
                    arg.span,
                    "REF()/ADR() of an array of function block instances is not supported; take the address of one element",
                );
                self.drop_loaded(&p);
                Type::Error
            }
            Type::String(n) => {
                let n = *n;
                let view = match expected {
                    Some(Type::Ref(t)) if is_byte_view(t) => Some((**t).clone()),
                    _ => None,
                };
                self.record_root(root);
                self.addr_of(&p);
                match view {
                    Some(target) => {
                        match &arg.kind {
                            // Not found by the scan (e.g. inside an expression the scan
                            // does not see): still consistent from here on.
                            ExprKind::Name(v) if !self.refs.byte_viewed.contains(&v.name) => {
                                self.refs.byte_viewed.push(v.name.clone());
                            }
                            ExprKind::Name(_) => {}
                            _ if self.check_only => {
                                self.error(codes::REF_OPERAND,
                                    arg.span,
                                    "a byte pointer to the text of a STRING can be taken of a STRING variable or parameter only (its length is re-read from the terminator there)",
                                );
                            }
                            _ => {}
                        }
                        self.emit(|b| {
                            b.push_i32(4);
                            b.op(Opcode::Add);
                            b.ref_make(1);
                        });
                        Type::Ref(Box::new(target))
                    }
                    None => {
                        self.emit(|b| b.ref_make(4));
                        Type::Ref(Box::new(Type::String(n)))
                    }
                }
            }
            t => {
                let t = t.clone();
                let size = self.prog.size_align(&t).0;
                self.record_root(root);
                self.addr_of(&p);
                self.emit(|b| b.ref_make(size));
                Type::Ref(Box::new(t))
            }
        }
    }

    fn drop_loaded(&mut self, p: &Place) {
        if matches!(p.loc, Loc::Ind(_) | Loc::Ref(_)) {
            self.op(Opcode::Drop);
        }
    }

    /// Whether `ty` is or contains function-block instances.
    fn holds_instances(&self, ty: &Type) -> bool {
        match ty {
            Type::Fb(_) => true,
            Type::Array(a) => self.holds_instances(&a.elem),
            _ => false,
        }
    }

    fn record_root(&mut self, root: Option<Root>) {
        if let Some(r) = root {
            self.refs.roots.push(r);
        }
    }

    /// Records a `VAR_IN_OUT` argument (for the object table).
    pub(crate) fn record_inout(&mut self, callee: usize, param: &str, arg: &Expr) {
        if self.dry {
            return;
        }
        if let Some(root) = self.root_of(arg) {
            self.refs.inout_args.push((callee, param.to_string(), root));
        }
    }

    /// The variable a place expression is part of (`None` when it is reached through a
    /// reference, whose object already bounds it).
    pub(crate) fn root_of(&mut self, e: &Expr) -> Option<Root> {
        match &e.kind {
            ExprKind::Name(n) => {
                if let Some(v) = self.prog.pous[self.cur].var(&n.name) {
                    return Some(match v.kind {
                        VarKind::External => Root::Global(n.name.clone()),
                        VarKind::InOut => Root::InOut(self.cur, n.name.clone()),
                        _ => Root::Var(self.cur, n.name.clone()),
                    });
                }
                if let Some(owner) = self.var_owner(&n.name) {
                    return Some(Root::Var(owner, n.name.clone()));
                }
                self.prog
                    .global(&n.name)
                    .map(|_| Root::Global(n.name.clone()))
            }
            ExprKind::Member(base, m) => match self.infer(base) {
                Type::Fb(pi) => Some(Root::Var(pi, m.name.clone())),
                _ => self.root_of(base),
            },
            ExprKind::Index(base, _) => self.root_of(base),
            _ => None,
        }
    }

    /// The place `inner^`: the variable a reference refers to (pushes the reference).
    pub(crate) fn deref_place(&mut self, inner: &Expr, span: Span) -> Option<Place> {
        match self.expr(inner, None) {
            Type::Ref(target) if !matches!(*target, Type::Void | Type::Null) => {
                Some(self.referred_place(*target))
            }
            _ => {
                self.missing_record(span, "passed a dereference of no reference");
                None
            }
        }
    }

    /// What the reference on the stack refers to, as [`Place::referred`] says (an instance
    /// is checked for NULL here).
    fn referred_place(&mut self, target: Type) -> Place {
        let place = Place::referred(target);
        if matches!(place.ty, Type::Fb(_)) {
            self.op(Opcode::ChkNull);
        }
        place
    }

    /// A `REFERENCE TO` place stands for the variable it refers to.
    pub(crate) fn auto_deref(&mut self, p: Place) -> Place {
        let Type::Reference(target) = &p.ty else {
            return p;
        };
        if self.refs.keep_reference {
            return p;
        }
        let target = (**target).clone();
        let cell = self.finalize_place(Place {
            ty: Type::Ref(Box::new(target.clone())),
            ..p
        });
        self.load(&cell);
        self.referred_place(target)
    }

    /// Checks a place reached through a reference for the bytes of its type and turns it
    /// into a plain indirect place.
    pub(crate) fn finalize_place(&mut self, p: Place) -> Place {
        let Loc::Ref(offset) = p.loc else {
            return p;
        };
        if offset != 0 {
            self.emit(|b| {
                b.push_u32(offset);
                b.ref_add();
            });
        }
        // A STRING through a reference: its header (builtins keep to the text it describes).
        let size = match &p.ty {
            Type::String(_) => 4,
            t => self.prog.size_align(t).0,
        };
        self.emit(|b| b.ref_check(size));
        p.finalized()
    }

    /// The computed indices `idx` of an array reached through a reference (the reference
    /// cell is on the stack): they move the reference (`REF_ADD`); the element is checked
    /// when it is accessed.
    pub(crate) fn index_through_reference(
        &mut self,
        arr: &ArrayType,
        idx: &[Expr],
        consts: &[Option<i128>],
        strides: &[i64],
    ) {
        for (d, c) in consts.iter().enumerate() {
            if c.is_some() {
                continue;
            }
            let (lo, hi) = arr.dims[d];
            self.expr(&idx[d], Some(&Type::DINT));
            let stride = strides[d];
            self.emit(|b| {
                b.chk_index(lo, hi);
                if lo != 0 {
                    b.push_int(lo);
                    b.op(Opcode::Sub);
                }
                if stride != 1 {
                    b.push_int(stride);
                    b.op(Opcode::Mul);
                }
                b.ref_add();
            });
        }
    }

    /// The type of an operand of a reference operation; `None` for an untyped integer
    /// literal (it takes the other operand's part: an offset or an address).
    fn pointer_operand_type(&mut self, e: &Expr) -> Option<Type> {
        if is_flexible(e) && !has_real_literal(e) {
            None
        } else {
            Some(self.infer(e))
        }
    }

    /// Whether [`Gen::pointer_binary`] handles `a op b`.
    pub(crate) fn is_pointer_operation(&mut self, a: &Expr, b: &Expr) -> bool {
        let pointerish = |t: &Option<Type>| {
            t.as_ref()
                .is_some_and(|t| t.is_pointer_like() || matches!(t, Type::Reference(_)))
        };
        let (ta, tb) = (self.pointer_operand_type(a), self.pointer_operand_type(b));
        pointerish(&ta) || pointerish(&tb)
    }

    /// Pointer arithmetic (`ref + n`, `n + ref`, `ref - n`: the address moves by n bytes, as
    /// CODESYS does; `ref - ref`: the distance in bytes) and comparisons of references,
    /// interface values and addresses (by address; `NULL` and 0 are the address 0).
    pub(crate) fn pointer_binary(
        &mut self,
        op: BinOp,
        a: &Expr,
        b: &Expr,
        expected: Option<&Type>,
        span: Span,
    ) -> Type {
        let ta = self.pointer_operand_type(a);
        let tb = self.pointer_operand_type(b);
        let is_ref = |t: &Option<Type>| matches!(t, Some(Type::Ref(_)));
        let ref_expected = expected.filter(|t| matches!(t, Type::Ref(_)));
        match op {
            BinOp::Add | BinOp::Sub
                if is_ref(&ta) && !is_ref(&tb)
                    || op == BinOp::Add && is_ref(&tb) && !is_ref(&ta) =>
            {
                let ref_first = is_ref(&ta);
                let (r, n) = if ref_first { (a, b) } else { (b, a) };
                if ref_first {
                    let rt = self.expr(r, ref_expected);
                    self.offset_operand(n);
                    self.finish_pointer_arithmetic(op, rt, span)
                } else {
                    self.offset_operand(n);
                    let rt = self.expr(r, ref_expected);
                    self.op(Opcode::Swap);
                    self.finish_pointer_arithmetic(op, rt, span)
                }
            }
            BinOp::Sub if is_ref(&ta) && is_ref(&tb) => {
                self.address_operand(a);
                self.address_operand(b);
                self.emit(|bb| {
                    bb.op(Opcode::Sub);
                    bb.op_width(Opcode::Sext, 32);
                });
                Type::DINT
            }
            BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge => {
                for e in [a, b] {
                    self.address_operand(e);
                }
                self.op(match op {
                    BinOp::Eq => Opcode::Eq,
                    BinOp::Ne => Opcode::Ne,
                    BinOp::Lt => Opcode::LtU,
                    BinOp::Le => Opcode::LeU,
                    BinOp::Gt => Opcode::GtU,
                    _ => Opcode::GeU,
                });
                Type::BOOL
            }
            _ => {
                let name = |g: &mut Self, t: &Option<Type>| match t {
                    Some(t) => g.tname(t),
                    None => "an integer".into(),
                };
                let msg = format!(
                    "operator {} cannot be applied to {} and {} (references allow `+`/`-` of a byte offset, the difference of two references and comparisons)",
                    op.symbol(),
                    name(self, &ta),
                    name(self, &tb)
                );
                self.error(codes::POINTER_ARITHMETIC, span, msg);
                Type::Error
            }
        }
    }

    /// `[ref n] -> [ref ± n]` after checking the reference may be moved.
    fn finish_pointer_arithmetic(&mut self, op: BinOp, rt: Type, span: Span) -> Type {
        if op == BinOp::Sub {
            self.op(Opcode::Neg);
        }
        self.op(Opcode::RefAdd);
        match &rt {
            Type::Ref(target) if self.check_only && !is_plain(self.prog, target) => {
                let msg = format!(
                    "pointer arithmetic on {} is not allowed: it could reach a reference or instance stored there (only references to plain data can be moved)",
                    self.tname(&rt)
                );
                self.error(codes::POINTER_ARITHMETIC, span, msg);
                Type::Error
            }
            Type::Ref(_) | Type::Error => rt,
            other => {
                let msg = format!(
                    "pointer arithmetic needs a reference, found {}",
                    self.tname(other)
                );
                self.error(codes::POINTER_ARITHMETIC, span, msg);
                Type::Error
            }
        }
    }

    /// An integer byte offset for pointer arithmetic.
    fn offset_operand(&mut self, e: &Expr) {
        let t = self.expr(e, Some(&Type::LINT));
        if self.check_only && !t.is_error() && !t.elem().is_some_and(|x| x.is_integral()) {
            let msg = format!(
                "a reference moves by an integer number of bytes, not by {}",
                self.tname(&t)
            );
            self.error(codes::POINTER_ARITHMETIC, e.span, msg);
        }
    }

    /// Pushes the address an operand of a comparison stands for: a reference's address,
    /// an instance or interface value (already an address) or an integer.
    fn address_operand(&mut self, e: &Expr) {
        let t = self.expr(e, Some(&Type::ULINT));
        match &t {
            Type::Ref(target) if !matches!(**target, Type::Fb(_)) => {
                self.emit(|b| b.op_width(Opcode::Zext, 32))
            }
            Type::Ref(_) | Type::Interface(_) | Type::Null | Type::Fb(_) | Type::Error => {}
            t if t.elem().is_some_and(|x| x.is_integral()) => {}
            other => {
                let msg = format!(
                    "a reference can be compared with a reference, an interface or an address, not with {}",
                    self.tname(other)
                );
                self.error(codes::REFERENCE_COMPARISON, e.span, msg);
            }
        }
    }

    // ----- references to temporary storage -------------------------------------------------
    //
    // Every variable has a static home in this VM, so no reference can ever dangle into
    // freed memory; but a FUNCTION's (or METHOD's) variables and a VAR_TEMP are re-initialised
    // by the next call, so a reference to them that outlives the call would silently see
    // another call's data. The compiler rejects the ways such a reference can leave the call:
    // stored anywhere but in a temporary variable of the same POU (a global, a variable of an
    // instance, an output or the function's result, through a dereference or a VAR_IN_OUT),
    // or passed to a FUNCTION_BLOCK or METHOD input (which may keep it). Passing it to a
    // FUNCTION input is allowed: a FUNCTION's reference inputs are *borrowed* in turn: the
    // function may return them (as its result or an output) but not keep them, and its
    // caller treats the result as derived from the references it passed in. Temporary
    // reference variables that are assigned such a reference anywhere in the POU count as
    // holding one everywhere.

    /// Whether `name` is temporary storage of the current POU.
    fn is_temporary_var(&self, name: &str) -> bool {
        let pou = &self.prog.pous[self.cur];
        let Some(v) = pou.var(name) else {
            return false;
        };
        let function_like = matches!(pou.kind, PouKind::Function) || self.is_method(self.cur);
        let is_result =
            pou.return_type.is_some() && pou.vars.first().is_some_and(|r| r.name == v.name);
        match v.kind {
            VarKind::Temp => true,
            VarKind::Local | VarKind::Input => function_like && !is_result,
            _ => false,
        }
    }

    /// Whether `name` is what a FUNCTION hands back to its caller: its result or an output.
    fn is_function_output(&self, name: &str) -> bool {
        let pou = &self.prog.pous[self.cur];
        pou.kind == PouKind::Function
            && !self.is_method(self.cur)
            && pou.var(name).is_some_and(|v| v.kind == VarKind::Output)
    }

    /// Whether `e` may evaluate to a reference to temporary storage of the current POU
    /// (`Local`), or to one of a FUNCTION's borrowed reference inputs (`Borrowed`).
    fn temp_derived(&mut self, e: &Expr) -> Taint {
        match &e.kind {
            ExprKind::Call { callee, args } => {
                let ExprKind::Name(f) = &callee.kind else {
                    return Taint::None;
                };
                if matches!(f.name.as_str(), "REF" | "ADR") {
                    return match args.as_slice() {
                        [a] if self.place_is_temporary(&a.value) => Taint::Local,
                        [a] => self.deref_taint(&a.value),
                        _ => Taint::None,
                    };
                }
                // A function's result may be one of the references passed to it.
                let Some(&pi) = self.prog.pou_by_name.get(&f.name) else {
                    return Taint::None;
                };
                if self.prog.pous[pi].kind != PouKind::Function {
                    return Taint::None;
                }
                args.iter()
                    .filter(|a| !a.output)
                    .map(|a| self.temp_derived(&a.value))
                    .max()
                    .unwrap_or(Taint::None)
            }
            ExprKind::Name(n) => {
                if self.refs.tainted.contains(&n.name) {
                    return Taint::Local;
                }
                if self.refs.borrowed.contains(&n.name) {
                    return Taint::Borrowed;
                }
                // A FUNCTION's reference inputs, and a reference read from any POU's
                // VAR_IN_OUT, may point to the caller's temporaries.
                let pou = &self.prog.pous[self.cur];
                let function = pou.kind == PouKind::Function && !self.is_method(self.cur);
                let borrowed = pou.var(&n.name).is_some_and(|v| {
                    matches!(v.ty, Type::Ref(_) | Type::Interface(_))
                        && (v.kind == VarKind::InOut || function && v.kind == VarKind::Input)
                });
                if borrowed {
                    Taint::Borrowed
                } else {
                    Taint::None
                }
            }
            ExprKind::Binary(BinOp::Add | BinOp::Sub, a, b) => {
                self.temp_derived(a).max(self.temp_derived(b))
            }
            _ => Taint::None,
        }
    }

    /// The taint of the reference a place expression is reached through, if any.
    fn deref_taint(&mut self, e: &Expr) -> Taint {
        match &e.kind {
            ExprKind::Member(b, _) | ExprKind::Index(b, _) => self.deref_taint(b),
            ExprKind::Deref(r) => self.temp_derived(r),
            _ => Taint::None,
        }
    }

    /// Whether place expression `e` lies in temporary storage of the current POU.
    fn place_is_temporary(&mut self, e: &Expr) -> bool {
        match &e.kind {
            ExprKind::Name(n) => self.is_temporary_var(&n.name),
            ExprKind::Member(b, _) | ExprKind::Index(b, _) => self.place_is_temporary(b),
            ExprKind::Deref(r) => self.temp_derived(r) == Taint::Local,
            _ => false,
        }
    }

    /// Finds the temporary reference variables of the current POU that may hold a reference
    /// to its temporary storage or a borrowed one (assignments anywhere in `body`, to a
    /// fixpoint).
    pub(crate) fn scan_temporary_references(&mut self, body: &[Stmt]) {
        self.refs.tainted.clear();
        self.refs.borrowed.clear();
        let mut assigns: Vec<(Ident, Expr)> = Vec::new();
        for s in body {
            collect_assignments(s, &mut assigns);
        }
        loop {
            let mut changed = false;
            for (target, value) in &assigns {
                if !self.is_temporary_var(&target.name) {
                    continue;
                }
                let taint = self.temp_derived(value);
                let set = match taint {
                    Taint::Local => &mut self.refs.tainted,
                    Taint::Borrowed => &mut self.refs.borrowed,
                    Taint::None => continue,
                };
                if set.insert(target.name.clone()) {
                    changed = true;
                }
            }
            if !changed {
                break;
            }
        }
    }

    /// Rejects storing `value`, a reference that may point to temporary storage of the
    /// current POU, into `target` (`None`: a destination that outlives the call, named by
    /// `what`) unless `target` is itself temporary storage of this POU (or, for a borrowed
    /// reference, the result or an output of the FUNCTION it was passed to).
    pub(crate) fn check_escape(&mut self, target: Option<&Expr>, value: &Expr, what: &str) {
        if self.dry {
            return;
        }
        let taint = self.temp_derived(value);
        if taint == Taint::None {
            return;
        }
        if let Some(t) = target
            && let ExprKind::Name(n) = &t.kind
            && (self.is_temporary_var(&n.name)
                || taint == Taint::Borrowed && self.is_function_output(&n.name))
        {
            return;
        }
        let pou = self.prog.pous[self.cur].text.clone();
        let msg = match taint {
            Taint::Borrowed => format!(
                "this reference came from the caller of `{pou}` (a FUNCTION's reference input or a VAR_IN_OUT) and may point to the caller's temporary variables; a FUNCTION may return it (as its result or an output) but it cannot be stored in {what}, which outlives the call"
            ),
            _ => format!(
                "this reference may point to a temporary variable of `{pou}` (a FUNCTION's or METHOD's variables, a VAR_TEMP), which the next call re-initialises; it cannot be stored in {what}, which outlives the call"
            ),
        };
        self.error(codes::REFERENCE_ESCAPE, value.span, msg);
    }

    // ----- STRING byte views ------------------------------------------------------------

    /// Finds the STRING variables of the current POU whose text the body reaches through a
    /// byte pointer (`REF(s)`/`ADR(s)` where a byte pointer is expected): their length is
    /// re-read from the terminator before each use and when the POU returns.
    pub(crate) fn scan_byte_views(&mut self, body: &[Stmt]) {
        self.refs.byte_viewed.clear();
        let mut names = Vec::new();
        for s in body {
            collect_ref_args_stmt(s, &mut names);
        }
        for n in names {
            let is_string = match self.prog.pous[self.cur].var(&n.name) {
                Some(v) if v.kind == VarKind::External => {
                    self.prog.global(&n.name).is_some_and(|g| g.ty.is_string())
                }
                Some(v) => v.ty.is_string(),
                None => self
                    .owner_var_type(&n.name)
                    .or_else(|| self.prog.global(&n.name).map(|g| g.ty.clone()))
                    .is_some_and(|t| t.is_string()),
            };
            if is_string && !self.refs.byte_viewed.contains(&n.name) {
                self.refs.byte_viewed.push(n.name);
            }
        }
    }

    /// Before a STRING variable reached through byte pointers is read: take its length from
    /// its terminator.
    pub(crate) fn sync_if_byte_viewed(&mut self, e: &Expr) {
        let ExprKind::Name(n) = &e.kind else { return };
        if !self.refs.byte_viewed.contains(&n.name) || self.dry {
            return;
        }
        self.sync_string(n);
    }

    fn sync_string(&mut self, n: &Ident) {
        let saved = std::mem::take(&mut self.refs.byte_viewed);
        if let Some(p) = self.place(&Expr {
            kind: ExprKind::Name(n.clone()),
            span: n.span,
        }) {
            if p.ty.is_string() {
                self.addr_of(&p);
                self.emit(|b| b.call_builtin(Builtin::StrSync));
            } else {
                self.drop_loaded(&p);
            }
        }
        self.refs.byte_viewed = saved;
    }

    /// At the return of a POU: the strings it wrote through byte pointers get their length.
    pub(crate) fn sync_byte_views_on_return(&mut self) {
        for name in self.refs.byte_viewed.clone() {
            let id = Ident {
                text: name.clone(),
                name,
                span: Span::default(),
            };
            self.sync_string(&id);
        }
    }

    // ----- the object table -------------------------------------------------------------

    /// Emits the OBJECTS table: for every instance and frame, the variables whose address
    /// the program takes, split into parts where needed (see the module doc).
    pub(crate) fn build_objects(&mut self) {
        let refs = std::mem::take(&mut self.refs);
        // VAR_IN_OUT parameters whose address the callee takes, directly or by passing them
        // on to such a parameter.
        let mut exposed: HashSet<(usize, String)> = refs
            .roots
            .iter()
            .filter_map(|r| match r {
                Root::InOut(p, n) => Some((*p, n.clone())),
                _ => None,
            })
            .collect();
        loop {
            let mut changed = false;
            for (callee, param, root) in &refs.inout_args {
                if let Root::InOut(p, n) = root
                    && exposed.contains(&(*callee, param.clone()))
                    && exposed.insert((*p, n.clone()))
                {
                    changed = true;
                }
            }
            if !changed {
                break;
            }
        }
        let mut marked: HashSet<Root> = refs
            .roots
            .iter()
            .filter(|r| !matches!(r, Root::InOut(..)))
            .cloned()
            .collect();
        for (callee, param, root) in &refs.inout_args {
            if !matches!(root, Root::InOut(..)) && exposed.contains(&(*callee, param.clone())) {
                marked.insert(root.clone());
            }
        }
        if marked.is_empty() {
            return;
        }
        let mut spans: Vec<(u32, u32)> = Vec::new();
        let prog = &*self.prog;
        for g in &prog.globals {
            if marked.contains(&Root::Global(g.name.clone())) {
                object_tree(prog, g.offset, &g.ty, 0, &mut spans);
            }
            walk_instances(prog, &marked, g.offset, &g.ty, &mut spans);
        }
        for inst in &prog.instances {
            walk_pou(prog, &marked, inst.pou, inst.addr, &mut spans);
        }
        for (pi, frame) in self.static_frames() {
            walk_pou(prog, &marked, pi, frame, &mut spans);
        }
        spans.sort_by(|a, b| a.0.cmp(&b.0).then(b.1.cmp(&a.1)));
        spans.dedup();
        // Parents: the innermost enclosing span still open (the spans nest).
        let mut open: Vec<(u32, u32, u32)> = Vec::new(); // (index, start, end)
        for (start, len) in spans {
            let end = start + len;
            while open
                .last()
                .is_some_and(|&(_, s, e)| !(s <= start && end <= e))
            {
                open.pop();
            }
            if open.len() >= MAX_DEPTH {
                // Deeper parts are covered by their enclosing span.
                continue;
            }
            let parent = open.last().map(|&(i, _, _)| i);
            let index = self.b.add_object(start, len, parent);
            open.push((index, start, end));
        }
    }
}

/// The expression `REF(e)`.
pub(crate) fn reference_to(e: &Expr) -> Expr {
    let id = Ident {
        name: "REF".into(),
        text: "REF".into(),
        span: e.span,
    };
    Expr {
        kind: ExprKind::Call {
            callee: Box::new(Expr {
                kind: ExprKind::Name(id),
                span: e.span,
            }),
            args: vec![Arg {
                name: None,
                output: false,
                value: e.clone(),
                span: e.span,
            }],
        },
        span: e.span,
    }
}

/// Pushes the spans of the object of type `ty` at `addr` (and of its parts).
fn object_tree(
    prog: &crate::sema::Program,
    addr: u32,
    ty: &Type,
    depth: usize,
    out: &mut Vec<(u32, u32)>,
) {
    if let Type::String(n) = ty {
        out.push((addr, 4));
        out.push((addr + 4, n + 1));
        return;
    }
    let size = prog.size_align(ty).0;
    if size == 0 {
        return;
    }
    out.push((addr, size));
    if depth + 2 >= MAX_DEPTH || !split(prog, ty) {
        return;
    }
    match ty {
        Type::Array(a) => {
            let stride = align_up(prog.size_align(&a.elem).0, prog.size_align(&a.elem).1);
            for i in 0..a.len() as u32 {
                object_tree(prog, addr + i * stride, &a.elem, depth + 1, out);
            }
        }
        Type::Struct(si) => {
            for m in &prog.structs[*si].members {
                object_tree(prog, addr + m.offset, &m.ty, depth + 1, out);
            }
        }
        _ => {}
    }
}

/// Visits the function-block instances inside a variable of type `ty` at `addr`.
fn walk_instances(
    prog: &crate::sema::Program,
    marked: &HashSet<Root>,
    addr: u32,
    ty: &Type,
    out: &mut Vec<(u32, u32)>,
) {
    match ty {
        Type::Fb(pi) => walk_pou(prog, marked, *pi, addr, out),
        Type::Array(a) if matches!(a.elem, Type::Fb(_) | Type::Array(_)) => {
            let stride = prog.stride(&a.elem);
            for i in 0..a.len() as u32 {
                walk_instances(prog, marked, addr + i * stride, &a.elem, out);
            }
        }
        _ => {}
    }
}

/// Lists the marked variables of one instance (or frame) of POU `pi` at `base`.
fn walk_pou(
    prog: &crate::sema::Program,
    marked: &HashSet<Root>,
    pi: usize,
    base: u32,
    out: &mut Vec<(u32, u32)>,
) {
    for v in &prog.pous[pi].vars {
        if matches!(v.kind, VarKind::External | VarKind::Global | VarKind::InOut) {
            continue;
        }
        if marked.contains(&Root::Var(pi, v.name.clone())) {
            object_tree(prog, base + v.offset, &v.ty, 0, out);
        }
        walk_instances(prog, marked, base + v.offset, &v.ty, out);
    }
}

/// Every `name := value` / `name REF= value` to a plain variable in `s`.
fn collect_assignments(s: &Stmt, out: &mut Vec<(Ident, Expr)>) {
    let body = |b: &[Stmt], out: &mut Vec<(Ident, Expr)>| {
        b.iter().for_each(|s| collect_assignments(s, out))
    };
    match &s.kind {
        StmtKind::Assign { target, value } | StmtKind::RefAssign { target, value } => {
            if let ExprKind::Name(n) = &target.kind {
                out.push((n.clone(), value.clone()));
            }
        }
        StmtKind::If {
            branches,
            else_body,
        } => {
            for (_, b) in branches {
                body(b, out);
            }
            if let Some(b) = else_body {
                body(b, out);
            }
        }
        StmtKind::Case {
            arms, else_body, ..
        } => {
            for a in arms {
                body(&a.body, out);
            }
            if let Some(b) = else_body {
                body(b, out);
            }
        }
        StmtKind::For { body: b, .. }
        | StmtKind::While { body: b, .. }
        | StmtKind::Repeat { body: b, .. } => body(b, out),
        StmtKind::Try {
            body: b,
            catch_body,
            finally_body,
            ..
        } => {
            body(b, out);
            body(catch_body, out);
            body(finally_body, out);
        }
        _ => {}
    }
}

fn collect_ref_args_stmt(s: &Stmt, out: &mut Vec<Ident>) {
    let e = |x: &Expr, out: &mut Vec<Ident>| collect_ref_args(x, out);
    match &s.kind {
        StmtKind::Assign { target, value } | StmtKind::RefAssign { target, value } => {
            e(target, out);
            e(value, out);
        }
        StmtKind::Call(x) => e(x, out),
        StmtKind::If {
            branches,
            else_body,
        } => {
            for (c, b) in branches {
                e(c, out);
                b.iter().for_each(|s| collect_ref_args_stmt(s, out));
            }
            if let Some(b) = else_body {
                b.iter().for_each(|s| collect_ref_args_stmt(s, out));
            }
        }
        StmtKind::Case {
            selector,
            arms,
            else_body,
        } => {
            e(selector, out);
            for a in arms {
                a.body.iter().for_each(|s| collect_ref_args_stmt(s, out));
            }
            if let Some(b) = else_body {
                b.iter().for_each(|s| collect_ref_args_stmt(s, out));
            }
        }
        StmtKind::For {
            from, to, by, body, ..
        } => {
            e(from, out);
            e(to, out);
            if let Some(b) = by {
                e(b, out);
            }
            body.iter().for_each(|s| collect_ref_args_stmt(s, out));
        }
        StmtKind::While { cond, body } | StmtKind::Repeat { body, until: cond } => {
            e(cond, out);
            body.iter().for_each(|s| collect_ref_args_stmt(s, out));
        }
        StmtKind::Try {
            body,
            catch_body,
            finally_body,
            ..
        } => {
            for b in [body, catch_body, finally_body] {
                b.iter().for_each(|s| collect_ref_args_stmt(s, out));
            }
        }
        StmtKind::Exit | StmtKind::Return | StmtKind::Empty => {}
    }
}

/// The plain names given to `REF()`/`ADR()` anywhere in `e`.
fn collect_ref_args(e: &Expr, out: &mut Vec<Ident>) {
    match &e.kind {
        ExprKind::Call { callee, args } => {
            if let ExprKind::Name(f) = &callee.kind
                && matches!(f.name.as_str(), "REF" | "ADR")
                && let [a] = args.as_slice()
                && let ExprKind::Name(n) = &a.value.kind
            {
                out.push(n.clone());
            }
            collect_ref_args(callee, out);
            for a in args {
                collect_ref_args(&a.value, out);
            }
        }
        ExprKind::Member(b, _) | ExprKind::Deref(b) | ExprKind::Typed(_, b) => {
            collect_ref_args(b, out)
        }
        ExprKind::Index(b, idx) => {
            collect_ref_args(b, out);
            idx.iter().for_each(|i| collect_ref_args(i, out));
        }
        ExprKind::Unary(_, x) => collect_ref_args(x, out),
        ExprKind::Binary(_, a, b) => {
            collect_ref_args(a, out);
            collect_ref_args(b, out);
        }
        _ => {}
    }
}
