//! Calls of user FUNCTIONs and function block instances (parameter passing through the
//! callee's frame, outputs `=>`), as the call checker ([`crate::sema::call`]) resolved and
//! bound them.

use std::borrow::Cow;

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

impl<'e> Bound<'e> {
    /// The arguments `args` bound to the parameters `vars` as `binding` says.
    pub(crate) fn all(binding: &[Binding], vars: &[VarDef], args: &'e [Arg]) -> Vec<Bound<'e>> {
        binding
            .iter()
            .map(|b| Bound {
                param: vars[b.param].clone(),
                value: &args[b.arg].value,
                output: b.output,
            })
            .collect()
    }
}

/// The instance a call of a block's body calls: `callee` itself, or the instance `name` it
/// stands for (a namespace-qualified or completed name, [`Callee::Instance`]).
pub(crate) fn instance_callee<'e>(name: Option<&Ident>, callee: &'e Expr) -> Cow<'e, Expr> {
    match name {
        Some(n) => Cow::Owned(Expr {
            kind: ExprKind::Name(n.clone()),
            span: callee.span,
        }),
        None => Cow::Borrowed(callee),
    }
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
    /// A call, of the callee the call checker recorded ([`Callee`];
    /// [`crate::sema::call::call`]).
    pub(crate) fn call(
        &mut self,
        callee: &Expr,
        args: &[Arg],
        expected: Option<&Type>,
        span: Span,
    ) -> Type {
        let Some(target) = self.callees.of(callee).cloned() else {
            self.missing_record(callee.span, "resolved no callee for this call");
            return Type::Error;
        };
        match &target {
            Callee::RefFunction(n) => self.ref_function(n, args, expected, span),
            Callee::Method(method) => self.call_method(method, callee, args, span),
            Callee::Function(pi) => self.call_static(*pi, args, span, CallBase::Frame),
            Callee::Standard(n) => match self.std_call(&n.name, n, args, expected, span) {
                Some(t) => t,
                None => {
                    self.missing_record(n.span, "passed a call of an unknown function");
                    Type::Error
                }
            },
            Callee::Instance(name) => {
                let instance = instance_callee(name.as_ref(), callee);
                self.call_instance(&instance, args, span)
            }
        }
    }

    /// Calls the body of the function block instance `callee`.
    fn call_instance(&mut self, callee: &Expr, args: &[Arg], span: Span) -> Type {
        let Some(p) = self.place(callee) else {
            return Type::Error;
        };
        match p.ty.clone() {
            Type::Fb(pi) => {
                self.call_fb(p, pi, args, span);
                Type::Void
            }
            _ => {
                self.missing_record(callee.span, "passed a call of what is no instance");
                Type::Error
            }
        }
    }

    /// The arguments of a call of `pi`, bound to its parameters (see
    /// [`Gen::bind_to`]).
    fn bind_args<'e>(&mut self, pi: usize, args: &'e [Arg]) -> Vec<Bound<'e>> {
        let vars = self.prog.pous[pi].vars.clone();
        self.bind_to(&vars, args)
    }

    /// The arguments `args` of a call bound to the parameters `vars` (in frame
    /// order) as the call checker recorded ([`Binding`]; [`crate::sema::call::bind`]).
    pub(crate) fn bind_to<'e>(&mut self, vars: &[VarDef], args: &'e [Arg]) -> Vec<Bound<'e>> {
        let Some(first) = args.first() else {
            return Vec::new();
        };
        let Some(binding) = self
            .bindings
            .of(self.cur, first.span)
            .map(<[Binding]>::to_vec)
        else {
            self.missing_record(first.span, "bound no arguments for this call");
            return Vec::new();
        };
        Bound::all(&binding, vars, args)
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
        let bound = self.bind_args(pi, args);
        for a in bound.iter().filter(|a| !a.output) {
            if a.param.kind == VarKind::InOut {
                let loc = member(self, a.param.offset);
                self.record_inout(pi, &a.param.name, a.value);
                self.inout_address(a.value);
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
                self.store_expr(&p, a.value);
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

    /// Pushes the address of an in-out argument (a variable of the parameter's type, as the
    /// call checker found it: [`crate::sema::call::in_out_argument`]).
    pub(crate) fn inout_address(&mut self, e: &Expr) {
        self.sync_if_byte_viewed(e);
        let Some(p) = self.place(e) else {
            return self.emit(|b| b.push_i32(0));
        };
        self.addr_of(&p);
    }

    /// `param => target` after a call: copies the output `src` into the target variable (as
    /// the call checker passed it: [`crate::sema::call::output`]).
    pub(crate) fn copy_out(&mut self, src: Place, target: &Expr) {
        let Some(dst) = self.place(target) else {
            if matches!(src.loc, Loc::Ind(_)) {
                self.op(Opcode::Drop);
            }
            return;
        };
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
                self.store_checked(&dst);
            }
            _ => {
                self.aggregate_operands(&src, &dst);
                let (size, _) = self.prog.size_align(&dst.ty);
                self.emit(|b| b.copy(size));
            }
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

    /// Calls FUNCTION, METHOD or property accessor `pi` (parameters through its static
    /// frame) on `base` (as the call checker passed the call:
    /// [`crate::sema::call::static_call`]).
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
        let bound = self.bind_args(pi, args);
        let inputs: Vec<&Bound> = bound.iter().filter(|b| !b.output).collect();
        // Evaluate all inputs first: a nested call of the same function must not clobber
        // parameters already stored in the shared static frame.
        for a in &inputs {
            match a.param.kind {
                VarKind::InOut => {
                    self.record_inout(pi, &a.param.name, a.value);
                    self.inout_address(a.value)
                }
                _ => self.input_value(a.value, &a.param.ty),
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
    /// or an aggregate's address), as the call checker passed it
    /// ([`crate::sema::call::input_value`]).
    pub(crate) fn input_value(&mut self, e: &Expr, ty: &Type) {
        match ty {
            Type::String(_) | Type::WString(_) | Type::Array(_) | Type::Struct(_) => {
                self.expr(e, Some(ty));
            }
            ty => {
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
