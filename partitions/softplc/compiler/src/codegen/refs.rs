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

use std::collections::HashSet;

use plc_vm::isa::{Builtin, Opcode};

use crate::ast::*;
use crate::codegen::{Gen, Loc, Place};
use crate::diagnostics::Span;
use crate::sema::align_up;
use crate::sema::expr::{has_real_literal, is_byte_view, is_flexible, is_plain};
use crate::typed::Root;
use crate::types::*;

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
    /// temporary storage (see [`crate::sema::refs::check_escape`]).
    pub(crate) tainted: HashSet<String>,
    /// ... or one of a FUNCTION's borrowed reference inputs.
    pub(crate) borrowed: HashSet<String>,
}

/// An operation on references or addresses, by the types of its operands (`None`: an
/// untyped integer literal, which takes the other operand's part: an offset or an address).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum PointerOperation {
    /// `ref + n`, `n + ref`, `ref - n`: the address moves by n bytes, as CODESYS does.
    Move { reference_first: bool },
    /// `ref - ref`: the distance in bytes.
    Distance,
    /// A comparison of references, interface values and addresses (by address; `NULL` and
    /// 0 are the address 0).
    Compare,
}

impl PointerOperation {
    /// The operation `op` is on operands of types `ta` and `tb` ([`Gen::pointer_operand_type`]);
    /// `None` when references allow no such operation.
    pub(crate) fn of(op: BinOp, ta: &Option<Type>, tb: &Option<Type>) -> Option<Self> {
        let is_ref = |t: &Option<Type>| matches!(t, Some(Type::Ref(_)));
        match op {
            BinOp::Add | BinOp::Sub
                if is_ref(ta) && !is_ref(tb) || op == BinOp::Add && is_ref(tb) && !is_ref(ta) =>
            {
                Some(PointerOperation::Move {
                    reference_first: is_ref(ta),
                })
            }
            BinOp::Sub if is_ref(ta) && is_ref(tb) => Some(PointerOperation::Distance),
            BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge => {
                Some(PointerOperation::Compare)
            }
            _ => None,
        }
    }
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

    /// `REF(x)`, `ADR(x)`, `__ISVALIDREF(r)`, as the checker passed them
    /// ([`crate::sema::refs::ref_function`]).
    pub(crate) fn ref_function(
        &mut self,
        id: &Ident,
        args: &[Arg],
        expected: Option<&Type>,
        span: Span,
    ) -> Type {
        let [arg] = args else {
            self.missing_record(span, "passed a reference function without one argument");
            return Type::Error;
        };
        let arg = &arg.value;
        if id.name != "__ISVALIDREF" {
            return self.make_reference(arg, expected);
        }
        let saved = std::mem::replace(&mut self.refs.keep_reference, true);
        self.expr(arg, None);
        self.refs.keep_reference = saved;
        self.emit(|b| {
            b.push_i32(0);
            b.op(Opcode::Ne);
        });
        Type::BOOL
    }

    /// `REF(x)` / `ADR(x)`: a reference to variable `x` (for a function-block instance, its
    /// address). `expected` is the reference type the context wants: a byte pointer made
    /// from a STRING points at its text ([`crate::sema::refs::make_reference`]).
    pub(crate) fn make_reference(&mut self, arg: &Expr, expected: Option<&Type>) -> Type {
        let root = self.roots.of(arg).cloned();
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
                        // Not found by the scan (e.g. inside an expression the scan does
                        // not see): still consistent from here on.
                        if let ExprKind::Name(v) = &arg.kind
                            && !self.refs.byte_viewed.contains(&v.name)
                        {
                            self.refs.byte_viewed.push(v.name.clone());
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

    fn record_root(&mut self, root: Option<Root>) {
        if let Some(r) = root {
            self.refs.roots.push(r);
        }
    }

    /// Records a `VAR_IN_OUT` argument (for the object table): the variable it is part of,
    /// as the checker found it ([`crate::typed::Roots`]).
    pub(crate) fn record_inout(&mut self, callee: usize, param: &str, arg: &Expr) {
        if let Some(root) = self.roots.of(arg).cloned() {
            self.refs.inout_args.push((callee, param.to_string(), root));
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
    pub(crate) fn pointer_operand_type(&mut self, e: &Expr) -> Option<Type> {
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

    /// Emits an operation on references or addresses ([`PointerOperation`]), as the checker
    /// passed it ([`crate::sema::refs::pointer_binary`]).
    pub(crate) fn pointer_binary(
        &mut self,
        op: BinOp,
        a: &Expr,
        b: &Expr,
        expected: Option<&Type>,
        span: Span,
    ) -> Type {
        let (ta, tb) = (self.pointer_operand_type(a), self.pointer_operand_type(b));
        let ref_expected = expected.filter(|t| matches!(t, Type::Ref(_)));
        match PointerOperation::of(op, &ta, &tb) {
            Some(PointerOperation::Move { reference_first }) => {
                let rt = if reference_first {
                    let rt = self.expr(a, ref_expected);
                    self.expr(b, Some(&Type::LINT));
                    rt
                } else {
                    self.expr(a, Some(&Type::LINT));
                    let rt = self.expr(b, ref_expected);
                    self.op(Opcode::Swap);
                    rt
                };
                // `[ref n] -> [ref ± n]`
                if op == BinOp::Sub {
                    self.op(Opcode::Neg);
                }
                self.op(Opcode::RefAdd);
                rt
            }
            Some(PointerOperation::Distance) => {
                self.address_operand(a);
                self.address_operand(b);
                self.emit(|bb| {
                    bb.op(Opcode::Sub);
                    bb.op_width(Opcode::Sext, 32);
                });
                Type::DINT
            }
            Some(PointerOperation::Compare) => {
                self.address_operand(a);
                self.address_operand(b);
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
            None => {
                self.missing_record(span, "passed an operation references do not allow");
                Type::Error
            }
        }
    }

    /// Pushes the address an operand of a comparison stands for: a reference's address,
    /// an instance or interface value (already an address) or an integer.
    fn address_operand(&mut self, e: &Expr) {
        let t = self.expr(e, Some(&Type::ULINT));
        if let Type::Ref(target) = &t
            && !matches!(**target, Type::Fb(_))
        {
            self.emit(|b| b.op_width(Opcode::Zext, 32));
        }
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
