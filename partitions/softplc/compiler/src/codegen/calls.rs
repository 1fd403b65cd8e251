//! Calls of user FUNCTIONs and function block instances (argument binding, parameter
//! passing through the callee's frame, outputs `=>`).

use crate::codes;
use plc_vm::isa::{Builtin, MemType, Opcode};

use crate::ast::*;
use crate::codegen::{Gen, Loc, Place, scalar_mem};
use crate::diagnostics::Span;
use crate::sema::VarDef;
use crate::typed::{Binding, Callee};
use crate::types::*;

/// One argument bound to a parameter.
pub(crate) struct Bound<'e> {
    pub param: VarDef,
    pub value: &'e Expr,
    pub output: bool,
}

/// What a called FUNCTION or METHOD runs on (its frame base).
#[derive(Clone, Copy)]
pub(crate) enum CallBase {
    /// A FUNCTION: its own static frame.
    Frame,
    /// A METHOD or action on an instance at a static place.
    Instance(Loc),
    /// A METHOD or action on an instance whose address is in a static temporary.
    Parked(u32),
}

impl Gen<'_> {
    /// A call. The checking pass resolves the callee (reporting what is wrong with it) and
    /// records it ([`Callee`]); emission reads the record and resolves nothing.
    pub(crate) fn call(
        &mut self,
        callee: &Expr,
        args: &[Arg],
        expected: Option<&Type>,
        span: Span,
    ) -> Type {
        let target = if self.check_only {
            match self.resolve_callee(callee, args) {
                Ok(target) => target,
                Err(ty) => return ty,
            }
        } else {
            match self.callees.of(callee) {
                Some(target) => target.clone(),
                None => {
                    self.missing_record(callee.span, "resolved no callee for this call");
                    return Type::Error;
                }
            }
        };
        self.call_resolved(&target, callee, args, expected, span)
    }

    /// What `callee` calls, recorded for emission. `Err` is the call's type when the callee
    /// is wrong (reported).
    fn resolve_callee(&mut self, callee: &Expr, args: &[Arg]) -> Result<Callee, Type> {
        let target = self.callee_of(callee, args)?;
        self.callees.record(callee, target.clone());
        Ok(target)
    }

    fn callee_of(&mut self, callee: &Expr, args: &[Arg]) -> Result<Callee, Type> {
        if let ExprKind::Name(n) = &callee.kind
            && Self::is_ref_function(&n.name)
            && !self.prog.pou_by_name.contains_key(&n.name)
        {
            return Ok(Callee::RefFunction(n.clone()));
        }
        if let Some(method) = self.resolve_method(callee, args)? {
            return Ok(Callee::Method(method));
        }
        // `Lib.F(...)`: a function qualified by a namespace (ours or a library's).
        let name = match &callee.kind {
            ExprKind::Member(base, f)
                if let ExprKind::Name(ns) = &base.kind
                    && !self.is_visible_var(&ns.name) =>
            {
                Ident {
                    name: format!("{}.{}", ns.name, f.name),
                    text: format!("{}.{}", ns.text, f.text),
                    span: callee.span,
                }
            }
            ExprKind::Name(n) => n.clone(),
            _ => return Ok(Callee::Instance(None)),
        };
        let n = if self.is_visible_var(&name.name) {
            name
        } else {
            self.function_name(&name)
        };
        // A variable is only callable when it is an FB instance; otherwise the name refers
        // to a function even if a variable happens to have the same name.
        let var_ty = match self.prog.pous[self.cur].var(&n.name) {
            Some(v) => Some(v.ty.clone()),
            None => self
                .owner_var_type(&n.name)
                .or_else(|| self.prog.global(&n.name).map(|g| g.ty.clone())),
        };
        let is_fb_var = matches!(var_ty, Some(Type::Fb(_)));
        let is_function =
            self.prog.pou_by_name.contains_key(&n.name) || Self::is_std_function(&n.name);
        if !is_fb_var && (var_ty.is_none() || is_function) {
            if let Some(&pi) = self.prog.pou_by_name.get(&n.name) {
                return match self.prog.pous[pi].kind {
                    PouKind::Function => Ok(Callee::Function(pi)),
                    _ => {
                        let msg = format!("`{}` is a type; call an instance of it", n.text);
                        self.error(codes::NOT_CALLABLE, n.span, msg);
                        Err(Type::Error)
                    }
                };
            }
            return Ok(Callee::Standard(n));
        }
        // A qualified or completed name stands for the instance instead of the callee.
        let renamed = !matches!(&callee.kind, ExprKind::Name(m) if m.name == n.name);
        Ok(Callee::Instance(renamed.then_some(n)))
    }

    /// Makes a call whose callee is resolved.
    fn call_resolved(
        &mut self,
        target: &Callee,
        callee: &Expr,
        args: &[Arg],
        expected: Option<&Type>,
        span: Span,
    ) -> Type {
        match target {
            Callee::RefFunction(n) => self.ref_function(n, args, expected, span),
            Callee::Method(method) => self.call_method(method, callee, args, span),
            Callee::Function(pi) => self.call_function(*pi, args, span),
            Callee::Standard(n) => {
                if let Some(t) = self.std_call(&n.name, n, args, expected, span) {
                    return t;
                }
                let msg = format!("unknown function `{}`", n.text);
                self.error(codes::UNKNOWN_FUNCTION, n.span, msg);
                for a in args {
                    self.infer(&a.value);
                }
                Type::Error
            }
            Callee::Instance(name) => {
                let named;
                let instance = match name {
                    Some(n) => {
                        named = Expr {
                            kind: ExprKind::Name(n.clone()),
                            span: callee.span,
                        };
                        &named
                    }
                    None => callee,
                };
                self.call_instance(instance, args, span)
            }
        }
    }

    /// Calls the body of the function block instance `callee` (reports a callee that is no
    /// instance).
    fn call_instance(&mut self, callee: &Expr, args: &[Arg], span: Span) -> Type {
        let Some(p) = self.place(callee) else {
            return Type::Error;
        };
        match p.ty.clone() {
            Type::Fb(pi) => {
                if self.check_only && self.unit.pous[self.prog.pous[pi].ast].is_class {
                    let msg = format!(
                        "`{}` is a CLASS: it has no body to call; call its methods",
                        self.prog.pous[pi].text
                    );
                    self.error(codes::NOT_CALLABLE, callee.span, msg);
                }
                self.call_fb(p, pi, args, span);
                Type::Void
            }
            Type::Error => Type::Error,
            other => {
                let msg = format!("{} is not callable", self.tname(&other));
                self.error(codes::NOT_CALLABLE, callee.span, msg);
                if matches!(p.loc, Loc::Ind(_)) {
                    self.op(Opcode::Drop);
                }
                Type::Error
            }
        }
    }

    /// The declared POU (or standard function) a called name refers to, with or without
    /// its namespace (see [`crate::sema::qualified`]); the name itself when there is none.
    fn function_name(&mut self, n: &Ident) -> Ident {
        if self.prog.pou_by_name.contains_key(&n.name) {
            return n.clone();
        }
        match crate::sema::qualified(&n.name, self.prog.pou_by_name.keys()) {
            Ok(Some(full)) => Ident {
                name: full,
                ..n.clone()
            },
            Err(candidates) => {
                let msg = crate::sema::ambiguous(&n.text, &candidates);
                self.error(codes::AMBIGUOUS_NAME, n.span, msg);
                n.clone()
            }
            Ok(None) => match n.name.rsplit_once('.') {
                // `Standard.CONCAT`: a standard function under a library's name.
                Some((_, last)) if Self::is_std_function(last) || Self::is_ref_function(last) => {
                    Ident {
                        name: last.to_string(),
                        text: n
                            .text
                            .rsplit_once('.')
                            .map_or(n.text.clone(), |t| t.1.to_string()),
                        span: n.span,
                    }
                }
                _ => n.clone(),
            },
        }
    }

    /// Binds call arguments to parameters: positional ones in declaration order of the
    /// inputs and in-outs, named ones by name.
    fn bind_args<'e>(&mut self, pi: usize, args: &'e [Arg], span: Span) -> Vec<Bound<'e>> {
        let pou = &self.prog.pous[pi];
        let pou_name = pou.text.clone();
        let vars = pou.vars.clone();
        // The result variable (a function's, method's or getter's) is no output.
        let result = pou.return_type.as_ref().map(|_| pou.vars[0].name.clone());
        self.bind_to(Some(pi), &pou_name, &vars, result.as_deref(), (args, span))
    }

    /// [`Gen::bind_args`] for the parameters `vars` of `pou_name` (in frame order), called
    /// at `span`. The checking pass binds (reporting what is wrong, and each VAR_IN_OUT left
    /// unconnected) and records the binding ([`Binding`]); emission reads the record.
    pub(crate) fn bind_to<'e>(
        &mut self,
        pou: Option<usize>,
        pou_name: &str,
        vars: &[VarDef],
        result: Option<&str>,
        (args, span): (&'e [Arg], Span),
    ) -> Vec<Bound<'e>> {
        let binding = if self.check_only {
            let binding = self.resolve_binding(pou, pou_name, vars, result, args);
            for (i, v) in vars.iter().enumerate() {
                if v.kind == VarKind::InOut && !binding.iter().any(|b| b.param == i) {
                    let msg = format!("VAR_IN_OUT parameter `{}` must be connected", v.text);
                    self.error(codes::MISSING_ARGUMENT, span, msg);
                }
            }
            if let Some(first) = args.first() {
                self.bindings.record(self.cur, first.span, binding.clone());
            }
            binding
        } else {
            let Some(first) = args.first() else {
                return Vec::new();
            };
            match self.bindings.of(self.cur, first.span) {
                Some(binding) => binding.to_vec(),
                None => {
                    self.missing_record(first.span, "bound no arguments for this call");
                    return Vec::new();
                }
            }
        };
        binding
            .iter()
            .map(|b| Bound {
                param: vars[b.param].clone(),
                value: &args[b.arg].value,
                output: b.output,
            })
            .collect()
    }

    /// Which argument `args` binds to which of the parameters `vars` of `pou_name` (reported
    /// when wrong; what is wrong is left out).
    fn resolve_binding(
        &mut self,
        pou: Option<usize>,
        pou_name: &str,
        vars: &[VarDef],
        result: Option<&str>,
        args: &[Arg],
    ) -> Vec<Binding> {
        let params: Vec<VarDef> = vars
            .iter()
            .filter(|v| matches!(v.kind, VarKind::Input | VarKind::InOut))
            .cloned()
            .collect();
        let mut out: Vec<Binding> = Vec::new();
        let mut named_seen = false;
        for (i, a) in args.iter().enumerate() {
            let param = match &a.name {
                Some(n) => {
                    named_seen = true;
                    let v = match pou {
                        // The POU's own lookup knows the CODESYS aliases of some parameters.
                        Some(pi) => self.prog.pous[pi].param(&n.name).cloned(),
                        None => vars.iter().find(|v| v.name == n.name).cloned(),
                    };
                    match v {
                        Some(v)
                            if a.output
                                && v.kind == VarKind::Output
                                && Some(v.name.as_str()) != result =>
                        {
                            v
                        }
                        Some(v)
                            if !a.output && matches!(v.kind, VarKind::Input | VarKind::InOut) =>
                        {
                            v
                        }
                        Some(_) => {
                            let msg = if a.output {
                                format!(
                                    "`{}` is not an output of {pou_name} (use `:=` for inputs)",
                                    n.text
                                )
                            } else {
                                format!(
                                    "`{}` is not an input of {pou_name} (use `=>` for outputs)",
                                    n.text
                                )
                            };
                            self.error(codes::UNKNOWN_PARAMETER, n.span, msg);
                            continue;
                        }
                        None => {
                            let msg = format!("{pou_name} has no parameter `{}`", n.text);
                            self.error(codes::UNKNOWN_PARAMETER, n.span, msg);
                            continue;
                        }
                    }
                }
                None => {
                    if named_seen {
                        self.error(
                            codes::ARGUMENT_ORDER,
                            a.span,
                            "positional arguments must come before named ones",
                        );
                        continue;
                    }
                    match params.get(i) {
                        Some(p) => p.clone(),
                        None => {
                            let msg =
                                format!("too many arguments: {pou_name} takes {}", params.len());
                            self.error(codes::ARGUMENT_COUNT, a.span, msg);
                            continue;
                        }
                    }
                }
            };
            let Some(index) = vars.iter().position(|v| v.name == param.name) else {
                continue;
            };
            if out.iter().any(|b| b.param == index) {
                let msg = format!("parameter `{}` given twice", param.text);
                self.error(codes::DUPLICATE_ARGUMENT, a.span, msg);
                continue;
            }
            out.push(Binding {
                param: index,
                arg: i,
                output: a.output,
            });
        }
        out
    }

    pub(crate) fn call_fb(&mut self, inst: Place, pi: usize, args: &[Arg], span: Span) {
        self.calls.push((self.cur, pi, span));
        // A dynamic instance address is parked in a static temporary while arguments are stored.
        let base = match inst.loc {
            Loc::Ind(o) => {
                let t = self.temp_cell();
                if o != 0 {
                    self.emit(|b| {
                        b.push_u32(o);
                        b.op(Opcode::Add);
                    });
                }
                self.emit(|b| b.st_abs(MemType::U32, t));
                Err(t)
            }
            l => Ok(l),
        };
        let member = |g: &mut Self, off: u32| -> Loc {
            match base {
                Ok(Loc::Abs(a)) => Loc::Abs(a + off),
                Ok(Loc::Rel(o)) => Loc::Rel(o + off),
                Ok(Loc::Ind(_) | Loc::Ref(_)) => unreachable!("dynamic bases are parked"),
                Err(t) => {
                    g.emit(|b| b.ld_abs(MemType::U32, t));
                    Loc::Ind(off)
                }
            }
        };
        let bound = self.bind_args(pi, args, span);
        for a in bound.iter().filter(|a| !a.output) {
            if a.param.kind == VarKind::InOut {
                let loc = member(self, a.param.offset);
                self.record_inout(pi, &a.param.name, a.value);
                self.inout_address(a.value, &a.param.ty);
                let p = Place {
                    loc,
                    ty: Type::Elem(Elem::UDInt),
                    writable: true,
                    window: None,
                };
                self.store_checked(&p);
            } else {
                let loc = member(self, a.param.offset);
                let p = Place {
                    loc,
                    ty: a.param.ty.clone(),
                    writable: true,
                    window: None,
                };
                if !self.check_only {
                    self.store_expr(&p, a.value);
                    continue;
                }
                if p.ty.is_pointer_like() {
                    self.check_escape(None, a.value, "an input of a function block instance");
                }
                if matches!(p.ty, Type::Reference(_)) {
                    let r = crate::codegen::refs::reference_to(a.value);
                    self.check_escape(None, &r, "an input of a function block instance");
                }
                crate::sema::stmt::check_store(self, &p, a.value, a.value.span);
            }
        }
        match base {
            Ok(Loc::Abs(a)) => self.emit(|b| b.push_u32(a)),
            Ok(Loc::Rel(o)) => self.emit(|b| b.lea_rel(o)),
            Ok(Loc::Ind(_) | Loc::Ref(_)) => {}
            Err(t) => self.emit(|b| b.ld_abs(MemType::U32, t)),
        }
        let id = self.pou_ids[pi];
        self.emit(|b| b.call(id));
        for a in bound.iter().filter(|a| a.output) {
            let src = member(self, a.param.offset);
            let src = Place {
                loc: src,
                ty: a.param.ty.clone(),
                writable: false,
                window: None,
            };
            self.copy_out(src, a.value);
        }
    }

    /// Pushes the address of an in-out argument (which must be a variable of the same type).
    pub(crate) fn inout_address(&mut self, e: &Expr, ty: &Type) {
        self.sync_if_byte_viewed(e);
        let Some(p) = self.place(e) else {
            return self.emit(|b| b.push_i32(0));
        };
        if self.check_only {
            self.check_in_out_argument(&p, e, ty);
        }
        self.addr_of(&p);
    }

    /// Reports an in-out argument `e` (the place `p`) that is no variable of the parameter's
    /// type `ty` (the checking pass asks).
    fn check_in_out_argument(&mut self, p: &Place, e: &Expr, ty: &Type) {
        if p.window.is_some() {
            self.error(
                codes::IN_OUT_ARGUMENT,
                e.span,
                "a partial access (`x.3`, `x.%B1`) cannot be passed to a VAR_IN_OUT",
            );
        } else if p.ty != *ty && !p.ty.is_error() && !ty.is_error() {
            let msg = format!(
                "VAR_IN_OUT argument must be a {} variable, found {}",
                self.tname(ty),
                self.tname(&p.ty)
            );
            self.error(codes::IN_OUT_ARGUMENT, e.span, msg);
        }
    }

    /// `param => target` after a call: copies the output `src` into the target variable.
    pub(crate) fn copy_out(&mut self, src: Place, target: &Expr) {
        let Some(dst) = self.place(target) else {
            if matches!(src.loc, Loc::Ind(_)) {
                self.op(Opcode::Drop);
            }
            return;
        };
        if self.check_only && !self.check_output_target(&src, &dst, target) {
            return;
        }
        match &dst.ty {
            Type::String(_) | Type::WString(_) => {
                self.aggregate_operands(&src, &dst);
                let assign = if dst.ty.is_wstring() {
                    Builtin::WStrAssign
                } else {
                    Builtin::StrAssign
                };
                self.emit(|b| b.call_builtin(assign));
            }
            t if scalar_mem(t).is_some() => {
                let st = src.ty.clone();
                self.load(&src);
                self.coerce(&st, &dst.ty.clone(), target);
                if let Loc::Ind(_) = src.loc {
                    // value computed from a dynamic source; target is static here.
                }
                self.store_checked(&dst);
            }
            _ => {
                self.aggregate_operands(&src, &dst);
                let (size, _) = self.prog.size_align(&dst.ty);
                self.emit(|b| b.copy(size));
            }
        }
    }

    /// Reports what is wrong with `target` (the place `dst`) as the target of the output
    /// `src` (the checking pass asks); `false` when the output cannot be copied there at all.
    fn check_output_target(&mut self, src: &Place, dst: &Place, target: &Expr) -> bool {
        // A dynamic source address is pushed before the target's; the order stays valid
        // only when one of them is static.
        if let (Loc::Ind(_), Loc::Ind(_)) = (&src.loc, &dst.loc) {
            self.error(codes::OUTPUT_TARGET, target.span, "output of an FB array element into an array element with a computed index is not supported; use a temporary variable");
            return false;
        }
        self.check_output_writable(dst, target);
        if matches!(dst.ty, Type::String(_) | Type::WString(_))
            && src.ty.is_wstring() != dst.ty.is_wstring()
            && !src.ty.is_error()
        {
            let msg = format!(
                "type mismatch: the output is {}, its target {}",
                self.tname(&src.ty),
                self.tname(&dst.ty)
            );
            self.error(codes::TYPE_MISMATCH, target.span, msg);
        }
        true
    }

    /// Reports an output's target `target` (the place `dst`) that cannot be written.
    pub(super) fn check_output_writable(&mut self, dst: &Place, target: &Expr) {
        if !dst.writable {
            self.error(
                codes::ASSIGN_TO_READ_ONLY,
                target.span,
                "output target is not writable",
            );
        }
    }

    /// Pushes `[dst_addr src_addr]` for a string assignment or block copy, whichever of the
    /// two has its base address already on the stack.
    fn aggregate_operands(&mut self, src: &Place, dst: &Place) {
        if matches!(src.loc, Loc::Ind(_)) {
            self.addr_of(src);
            self.addr_of(dst);
            self.op(Opcode::Swap);
        } else {
            self.addr_of(dst);
            self.addr_of(src);
        }
    }

    fn call_function(&mut self, pi: usize, args: &[Arg], span: Span) -> Type {
        self.call_static(pi, args, span, CallBase::Frame)
    }

    /// Calls FUNCTION, METHOD or property accessor `pi` (parameters through its static
    /// frame) on `base`.
    pub(crate) fn call_static(
        &mut self,
        pi: usize,
        args: &[Arg],
        span: Span,
        base: CallBase,
    ) -> Type {
        self.calls.push((self.cur, pi, span));
        let (frame, pristine) = self.frames.get(pi).copied().unwrap_or((Some(0), Some(0)));
        let (frame, pristine) = (frame.unwrap_or(0), pristine.unwrap_or(0));
        let bound = self.bind_args(pi, args, span);
        let inputs: Vec<&Bound> = bound.iter().filter(|b| !b.output).collect();
        // Evaluate all inputs first: a nested call of the same function must not clobber
        // parameters already stored in the shared static frame.
        for a in &inputs {
            match a.param.kind {
                VarKind::InOut => {
                    self.record_inout(pi, &a.param.name, a.value);
                    self.inout_address(a.value, &a.param.ty)
                }
                _ => self.input_value(a.value, &a.param.ty, None),
            }
        }
        for a in inputs.iter().rev() {
            let addr = frame + a.param.offset;
            match (&a.param.kind, &a.param.ty) {
                (VarKind::InOut, _) => self.emit(|b| b.st_abs(MemType::U32, addr)),
                (_, Type::String(_)) => self.emit(|b| {
                    b.push_u32(addr);
                    b.swap();
                    b.call_builtin(Builtin::StrAssign);
                }),
                (_, Type::WString(_)) => self.emit(|b| {
                    b.push_u32(addr);
                    b.swap();
                    b.call_builtin(Builtin::WStrAssign);
                }),
                (_, Type::Array(_) | Type::Struct(_)) => {
                    let (size, _) = self.prog.size_align(&a.param.ty);
                    self.emit(|b| {
                        b.push_u32(addr);
                        b.swap();
                        b.copy(size);
                    });
                }
                (_, ty) => {
                    if let Some(mt) = scalar_mem(ty) {
                        self.emit(|b| b.st_abs(mt, addr));
                    } else {
                        self.op(Opcode::Drop);
                    }
                }
            }
        }
        // Unconnected inputs get their declared initial values.
        let vars = self.prog.pous[pi].vars.clone();
        for v in &vars {
            if v.kind == VarKind::Input && !bound.iter().any(|b| b.param.name == v.name) {
                let (size, _) = self.prog.size_align(&v.ty);
                self.emit(|b| {
                    b.push_u32(frame + v.offset);
                    b.push_u32(pristine + v.offset);
                    b.copy(size);
                });
            }
        }
        let id = self.pou_ids[pi];
        match base {
            CallBase::Frame => self.emit(|b| b.push_u32(frame)),
            CallBase::Instance(Loc::Abs(a)) => self.emit(|b| b.push_u32(a)),
            CallBase::Instance(Loc::Rel(o)) => self.emit(|b| b.lea_rel(o)),
            CallBase::Instance(_) => unreachable!("dynamic instances are parked"),
            CallBase::Parked(t) => self.emit(|b| b.ld_abs(MemType::U32, t)),
        }
        self.emit(|b| b.call(id));
        for a in bound.iter().filter(|a| a.output) {
            let src = Place {
                loc: Loc::Abs(frame + a.param.offset),
                ty: a.param.ty.clone(),
                writable: false,
                window: None,
            };
            self.copy_out(src, a.value);
        }
        let rt = self.prog.pous[pi].return_type.clone().unwrap_or(Type::Void);
        let ret_off = self.prog.pous[pi].vars.first().map_or(0, |v| v.offset);
        let addr = frame + ret_off;
        self.push_result_copy(&rt, addr);
        rt
    }

    /// Pushes the value of the input argument `e` for a parameter of type `ty` (a string's
    /// or an aggregate's address). A reference passed to a callee that may keep it (`kept_by`
    /// says which, `None` for a FUNCTION, which only borrows it) must not be one to
    /// temporary storage.
    pub(crate) fn input_value(&mut self, e: &Expr, ty: &Type, kept_by: Option<&str>) {
        match ty {
            Type::String(_) | Type::WString(_) | Type::Array(_) | Type::Struct(_) => {
                let t = self.expr(e, Some(ty));
                let fits = match ty {
                    Type::String(_) => t.is_string(),
                    Type::WString(_) => t.is_wstring(),
                    _ => t == *ty,
                };
                if self.check_only && !fits && !t.is_error() {
                    let expected = match ty {
                        Type::String(_) => "STRING".to_string(),
                        Type::WString(_) => "WSTRING".to_string(),
                        _ => self.tname(ty),
                    };
                    let msg = format!(
                        "type mismatch: expected {expected}, found {}",
                        self.tname(&t)
                    );
                    self.error(codes::TYPE_MISMATCH, e.span, msg);
                }
            }
            ty => {
                if let Some(keeper) = kept_by
                    && self.check_only
                    && ty.is_pointer_like()
                {
                    self.check_escape(None, e, keeper);
                }
                self.value_to(e, ty);
                if let Type::Subrange(_, lo, hi) = *ty {
                    self.emit(|b| b.chk_range_s(lo, hi));
                }
            }
        }
    }

    /// Pushes a function's (method's) result from its static frame at `addr`: aggregates
    /// are copied to a temporary first, so that a second call in the same expression cannot
    /// overwrite them.
    pub(crate) fn push_result_copy(&mut self, rt: &Type, addr: u32) {
        match rt {
            Type::String(_) | Type::WString(_) => {
                // Copy so that a second call in the same expression cannot overwrite it.
                let t = self.temp_string_like(rt);
                let assign = if rt.is_wstring() {
                    Builtin::WStrAssign
                } else {
                    Builtin::StrAssign
                };
                self.emit(|b| {
                    b.push_u32(t);
                    b.push_u32(addr);
                    b.call_builtin(assign);
                    b.push_u32(t);
                });
            }
            Type::Array(_) | Type::Struct(_) => {
                let (size, al) = self.prog.size_align(rt);
                let t = self.alloc_static(size, al);
                self.emit(|b| {
                    b.push_u32(t);
                    b.push_u32(addr);
                    b.copy(size);
                    b.push_u32(t);
                });
            }
            Type::Void | Type::Error => {}
            t => {
                if let Some(mt) = scalar_mem(t) {
                    self.emit(|b| b.ld_abs(mt, addr));
                }
            }
        }
    }
}
