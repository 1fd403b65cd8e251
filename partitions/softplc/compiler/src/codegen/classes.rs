//! Code generation for the object-oriented extensions (declarations: [`crate::classes`]):
//! calls of methods and actions, property accesses, `THIS` and `SUPER`, interface values,
//! dynamic dispatch and the image's class tables.
//!
//! A method runs with the frame base register on its instance; its own parameters and
//! variables live in its static frame (absolute addresses), the instance's variables are
//! frame-relative as in the block's body. A call is static when the instance's exact type
//! is known (a function-block variable holds exactly its declared type) or no derived
//! block overrides the method; otherwise (through `^`, `THIS`, a REFERENCE TO or an
//! interface) it goes through the method's slot: `VIRT_FRAME` gives the frame of the
//! method the instance's class runs, the caller stores the arguments there, `CALL_VIRT`
//! calls it.

use std::rc::Rc;

use crate::codes;
use plc_vm::isa::{Builtin, MemType, Opcode};

use crate::ast::*;
use crate::codegen::calls::CallBase;
use crate::codegen::{Gen, Loc, Place, scalar_mem};
use crate::diagnostics::Span;
use crate::sema::{MemberKind, VarDef};
use crate::typed::{Accessor, Bare, Method, PropertyAccess, Receiver};
use crate::types::*;

/// A method as a dynamic call sees it: its slot and signature.
pub(crate) struct Dynamic {
    pub slot: u16,
    pub label: String,
    /// Parameters (and outputs) in frame order.
    pub params: Vec<VarDef>,
    /// Result type and its offset in the method frame.
    pub result: Option<(Type, u32)>,
    /// The methods the call may run (for the recursion check).
    pub targets: Vec<usize>,
}

impl Gen<'_> {
    /// The function block (or program) whose instance the current POU runs on: the POU
    /// itself for a body, the owner for a method or action; `None` in a FUNCTION.
    pub(crate) fn context_class(&self) -> Option<usize> {
        let p = &self.prog.pous[self.cur];
        match &p.member {
            Some(m) => Some(m.owner),
            None if p.kind != PouKind::Function => Some(self.cur),
            None => None,
        }
    }

    /// The owner of the current method or action when `name` is one of the owner's
    /// variables (and not one of the POU's own).
    pub(crate) fn var_owner(&self, name: &str) -> Option<usize> {
        let p = &self.prog.pous[self.cur];
        let owner = p.member.as_ref()?.owner;
        if p.var(name).is_some() {
            return None;
        }
        self.prog.pous[owner].var(name).map(|_| owner)
    }

    /// The type of variable `name` of the current POU's owner.
    pub(crate) fn owner_var_type(&self, name: &str) -> Option<Type> {
        let owner = self.var_owner(name)?;
        self.prog.pous[owner].var(name).map(|v| v.ty.clone())
    }

    /// Whether POU `pi` is a METHOD or a property accessor.
    pub(crate) fn is_method(&self, pi: usize) -> bool {
        self.prog.pous[pi]
            .member
            .as_ref()
            .is_some_and(|m| m.kind != MemberKind::Action)
    }

    /// The static frame of the current POU when it is a method (its own variables live
    /// there; the frame base register points at the instance).
    pub(crate) fn method_frame(&self) -> Option<u32> {
        if self.is_method(self.cur) {
            Some(self.frames.get(self.cur).and_then(|f| f.0).unwrap_or(0))
        } else {
            None
        }
    }

    pub(crate) fn derives_from(&self, class: usize, base: usize) -> bool {
        self.prog.derives_from(class, base)
    }

    pub(crate) fn implements(&self, class: usize, interface: usize) -> bool {
        self.prog.implements(class, interface)
    }

    pub(crate) fn interface_extends(&self, a: usize, b: usize) -> bool {
        self.prog.interface_extends(a, b)
    }

    // ----- THIS and SUPER --------------------------------------------------------------

    /// The class `THIS` (or, with `superclass`, `SUPER`) stands for here; `Err` says why
    /// there is none.
    pub(crate) fn this_class(&self, superclass: bool) -> Result<usize, String> {
        let Some(c) = self
            .context_class()
            .filter(|&c| self.prog.pous[c].kind == PouKind::FunctionBlock)
        else {
            let what = if superclass { "SUPER" } else { "THIS" };
            return Err(format!(
                "{what} is the instance a function block's body, method or action runs on; there is none here"
            ));
        };
        if !superclass {
            return Ok(c);
        }
        let pou = &self.prog.pous[c];
        pou.base.ok_or_else(|| {
            format!(
                "`{}` extends no function block: there is no SUPER",
                pou.text
            )
        })
    }

    /// The class `THIS` (or `SUPER`) at `span` stands for, as the checker found it.
    fn checked_this_class(&mut self, superclass: bool, span: Span) -> Option<usize> {
        let class = self.this_class(superclass).ok();
        if class.is_none() {
            self.missing_record(span, "passed a THIS or SUPER where there is no instance");
        }
        class
    }

    /// `THIS` / `SUPER`: a reference to the instance (the frame base).
    pub(crate) fn this_expr(&mut self, superclass: bool, span: Span) -> Type {
        match self.checked_this_class(superclass, span) {
            Some(c) => {
                self.emit(|b| b.lea_rel(0));
                Type::Ref(Box::new(Type::Fb(c)))
            }
            None => Type::Error,
        }
    }

    /// `THIS^` / `SUPER^`: the instance itself.
    pub(crate) fn this_place(&mut self, superclass: bool, span: Span) -> Option<Place> {
        Some(Place::instance(self.checked_this_class(superclass, span)?))
    }

    // ----- receivers and lookups ---------------------------------------------------------

    /// What `base` in `base.m(...)` is, when it is an instance or an interface value.
    pub(crate) fn receiver(&mut self, base: &Expr) -> Option<Receiver> {
        match self.infer(base) {
            Type::Fb(class) => Some(Receiver::Instance {
                class,
                exact: self.is_exact_instance(base),
                superclass: matches!(&base.kind, ExprKind::Deref(i) if matches!(i.kind, ExprKind::Super)),
            }),
            Type::Interface(i) => Some(Receiver::Interface(i)),
            _ => None,
        }
    }

    /// Whether the instance `e` names is exactly of its static type: a function-block
    /// variable, member or element is; what a reference, `THIS` or a REFERENCE TO refers
    /// to may be an instance of a derived block.
    fn is_exact_instance(&mut self, e: &Expr) -> bool {
        match &e.kind {
            ExprKind::Deref(_) | ExprKind::This | ExprKind::Super => false,
            ExprKind::Name(n) => !self.is_reference_var(&n.name),
            _ => true,
        }
    }

    fn is_reference_var(&self, name: &str) -> bool {
        let own = self.prog.pous[self.cur].var(name).map(|v| v.ty.clone());
        let ty = own
            .or_else(|| self.owner_var_type(name))
            .or_else(|| self.prog.global(name).map(|g| g.ty.clone()));
        matches!(ty, Some(Type::Reference(_)))
    }

    /// Whether `name` is a variable visible in the current POU.
    pub(crate) fn is_visible_var(&self, name: &str) -> bool {
        self.prog.pous[self.cur].var(name).is_some()
            || self.var_owner(name).is_some()
            || self.prog.global(name).is_some()
    }

    /// The methods a call of `member` on an instance of static type `class` may run: the
    /// implementations of `class` and of the blocks derived from it.
    pub(crate) fn possible_targets(&self, class: usize, member: usize) -> Vec<usize> {
        let Some(m) = &self.prog.pous[member].member else {
            return vec![member];
        };
        let mut out = vec![member];
        for d in self.prog.derived_classes(class) {
            if let Some(p) = self.prog.find_member(d, &m.name, m.kind)
                && !out.contains(&p)
            {
                out.push(p);
            }
        }
        out
    }

    /// The dynamic view of method POU `member` (called through its class slot).
    pub(crate) fn dynamic_of(&self, member: usize, targets: Vec<usize>) -> Option<Dynamic> {
        let slot = *self.prog.slots.get(&member)?;
        let p = &self.prog.pous[member];
        let result = p
            .return_type
            .clone()
            .map(|t| (t, p.vars.first().map_or(0, |v| v.offset)));
        let params = self.prog.signature(member).into_iter().cloned().collect();
        Some(Dynamic {
            slot,
            label: p.text.clone(),
            params,
            result,
            targets,
        })
    }

    // ----- calls -------------------------------------------------------------------------

    /// Calls the resolved method or action `method` of `callee`.
    pub(crate) fn call_method(
        &mut self,
        method: &Method,
        callee: &Expr,
        args: &[Arg],
        span: Span,
    ) -> Type {
        let base = match &callee.kind {
            ExprKind::Member(base, _) => Some(&**base),
            _ => None,
        };
        match (method, base) {
            (Method::Own(member), _) => {
                let recv = self.own_receiver(self.context_class().unwrap_or(self.cur));
                self.call_member(None, recv, *member, args, span)
            }
            (Method::OfInterface(i, im), Some(base)) => {
                let dynamic = self.interface_dynamic(*i, im);
                self.call_dynamic(Some(base), dynamic, args, span)
            }
            (Method::OfInstance(member), Some(base)) if let Some(recv) = self.receiver(base) => {
                self.call_member(Some(base), recv, *member, args, span)
            }
            _ => {
                self.diags.error(
                    codes::INTERNAL_ERROR,
                    callee.span,
                    "internal error: the checker's method has no receiver here",
                );
                Type::Error
            }
        }
    }

    /// The dynamic view of interface member `im` of interface `i`.
    pub(crate) fn interface_dynamic(&self, i: usize, im: &crate::sema::InterfaceMember) -> Dynamic {
        let targets = self
            .prog
            .classes
            .iter()
            .filter(|c| c.interfaces.contains(&i))
            .filter_map(|c| c.dispatch.iter().find(|d| d.0 == im.slot).map(|d| d.1))
            .collect();
        // The result lies after the parameters, where an implementing method puts it.
        let result = im.return_type.clone().map(|t| {
            let end = im
                .params
                .iter()
                .filter(|v| matches!(v.kind, VarKind::Input | VarKind::InOut))
                .map(|v| {
                    v.offset
                        + if v.kind == VarKind::InOut {
                            4
                        } else {
                            self.prog.size_align(&v.ty).0
                        }
                })
                .max()
                .unwrap_or(0);
            let (_, al) = self.prog.size_align(&t);
            let off = crate::sema::align_up(crate::sema::align_up(end, 8), al);
            (t, off)
        });
        Dynamic {
            slot: im.slot,
            label: format!("{}.{}", self.prog.interfaces[i].text, im.text),
            params: im.params.clone(),
            result,
            targets,
        }
    }

    /// Calls member `member` (method, accessor or action) on the instance `base` (`None`:
    /// the current instance).
    fn call_member(
        &mut self,
        base: Option<&Expr>,
        recv: Receiver,
        member: usize,
        args: &[Arg],
        span: Span,
    ) -> Type {
        let Receiver::Instance {
            class,
            exact,
            superclass,
        } = recv
        else {
            unreachable!("interfaces have no static members")
        };
        let kind = self.prog.pous[member].member.as_ref().map(|m| m.kind);
        if kind == Some(MemberKind::Action) {
            self.calls.push((self.cur, member, span));
            let id = self.pou_ids[member];
            match base {
                None => self.emit(|b| b.lea_rel(0)),
                Some(e) => {
                    let Some(p) = self.place(e) else {
                        return Type::Error;
                    };
                    self.addr_of(&p);
                }
            }
            self.emit(|b| b.call(id));
            return Type::Void;
        }
        let targets = self.possible_targets(class, member);
        if !exact && !superclass && targets.len() > 1 {
            let dynamic = self.dynamic_of(member, targets);
            if let Some(d) = dynamic {
                return self.call_dynamic(base, d, args, span);
            }
        }
        // A static call on the instance.
        let call_base = match base {
            None => CallBase::Instance(Loc::Rel(0)),
            Some(e) => {
                let Some(p) = self.place(e) else {
                    for a in args {
                        self.infer(&a.value);
                    }
                    return Type::Error;
                };
                match p.loc {
                    Loc::Abs(_) | Loc::Rel(_) => CallBase::Instance(p.loc),
                    _ => {
                        let t = self.temp_cell();
                        self.addr_of(&p);
                        self.emit(|b| b.st_abs(MemType::U32, t));
                        CallBase::Parked(t)
                    }
                }
            }
        };
        self.call_static(member, args, span, call_base)
    }

    /// A dynamic call: the instance (`base`'s value, or the current instance), then the
    /// arguments into the frame `VIRT_FRAME` names, then `CALL_VIRT`.
    fn call_dynamic(&mut self, base: Option<&Expr>, d: Dynamic, args: &[Arg], span: Span) -> Type {
        for &t in &d.targets {
            self.calls.push((self.cur, t, span));
        }
        // The instance, parked.
        let instance = self.temp_cell();
        match base {
            None => self.emit(|b| b.lea_rel(0)),
            Some(e) => {
                let t = self.expr(e, None);
                if t.is_error() {
                    self.op(Opcode::Drop);
                    for a in args {
                        self.infer(&a.value);
                    }
                    return Type::Error;
                }
            }
        }
        self.emit(|b| b.st_abs(MemType::U64, instance));
        let bound = self.bind_to(&d.params, args);
        let inputs: Vec<&crate::codegen::calls::Bound> =
            bound.iter().filter(|b| !b.output).collect();
        for a in &inputs {
            match a.param.kind {
                VarKind::InOut => {
                    for &t in &d.targets {
                        self.record_inout(t, &a.param.name, a.value);
                    }
                    self.inout_address(a.value)
                }
                _ => self.input_value(a.value, &a.param.ty),
            }
        }
        let frame = self.temp_cell();
        let slot = d.slot;
        self.emit(|b| {
            b.ld_abs(MemType::U64, instance);
            b.virt_frame(slot);
            b.st_abs(MemType::U32, frame);
        });
        for a in inputs.iter().rev() {
            self.store_into_frame(frame, &a.param, a.param.kind == VarKind::InOut);
        }
        for v in &d.params {
            if v.kind == VarKind::Input && !bound.iter().any(|b| b.param.name == v.name) {
                self.default_into_frame(frame, v);
            }
        }
        self.emit(|b| {
            b.ld_abs(MemType::U64, instance);
            b.call_virt(slot);
        });
        for a in bound.iter().filter(|a| a.output) {
            self.emit(|b| b.ld_abs(MemType::U32, frame));
            let src = Place {
                loc: Loc::Ind(a.param.offset),
                ty: a.param.ty.clone(),
                writable: false,
                window: None,
            };
            self.copy_out(src, a.value);
        }
        match d.result {
            None => Type::Void,
            Some((t, off)) => {
                self.emit(|b| b.ld_abs(MemType::U32, frame));
                self.push_result_from_stack(&t, off);
                t
            }
        }
    }

    /// Stores the value on top of the stack into parameter `v` of the frame whose address is
    /// in the temporary `frame`.
    fn store_into_frame(&mut self, frame: u32, v: &VarDef, inout: bool) {
        let off = v.offset;
        self.emit(|b| {
            b.ld_abs(MemType::U32, frame);
            if off != 0 {
                b.add_imm(off as i32);
            }
            b.swap();
        });
        if inout {
            self.emit(|b| b.st_ind(MemType::U32, 0));
            return;
        }
        match &v.ty {
            Type::String(_) => self.emit(|b| b.call_builtin(Builtin::StrAssign)),
            Type::Array(_) | Type::Struct(_) => {
                let (size, _) = self.prog.size_align(&v.ty);
                self.emit(|b| b.copy(size));
            }
            t => match scalar_mem(t) {
                Some(mt) => self.emit(|b| b.st_ind(mt, 0)),
                None => {
                    self.op(Opcode::Drop);
                    self.op(Opcode::Drop);
                }
            },
        }
    }

    /// An unconnected input of a dynamic call gets its declared initial value (or zero).
    fn default_into_frame(&mut self, frame: u32, v: &VarDef) {
        match (&v.ty, &v.init) {
            (Type::String(_), init) => {
                let text = match init {
                    Some(Init::Expr(e)) => match self.const_value(e) {
                        Some(crate::sema::ConstVal::Str(s)) => s,
                        _ => String::new(),
                    },
                    _ => String::new(),
                };
                let e = Expr {
                    kind: ExprKind::Str(text),
                    span: v.span,
                };
                self.expr(&e, None);
            }
            (t, _) if scalar_mem(t).is_some() => {
                let cell = self.default_cell(v);
                match t.elem() {
                    Some(Elem::Real) => self.emit(|b| b.push_f32(f32::from_bits(cell as u32))),
                    Some(Elem::LReal) => self.emit(|b| b.push_f64(f64::from_bits(cell))),
                    _ => self.push_int(cell as i64),
                }
            }
            (t, _) => {
                let (size, al) = self.prog.size_align(t);
                let zero = self.alloc_static(size, al);
                self.emit(|b| b.push_u32(zero));
            }
        }
        self.store_into_frame(frame, v, false);
    }

    /// The cell a parameter `v` of a scalar type starts with when a dynamic call leaves it
    /// unconnected: its declared initial value (a constant, as the checker found it), else
    /// 0 (for a reference: NULL).
    fn default_cell(&mut self, v: &VarDef) -> u64 {
        let (Some(Init::Expr(e)), Some(elem)) = (&v.init, v.ty.elem()) else {
            return 0;
        };
        let value = self.const_value(e);
        value
            .and_then(|value| self.const_cell(&value, &v.ty, elem, e.span))
            .unwrap_or(0)
    }

    /// Pushes a method's result from the frame whose address is on the stack (`off` into
    /// it); aggregates are copied to a temporary first.
    fn push_result_from_stack(&mut self, t: &Type, off: u32) {
        match t {
            Type::String(n) => {
                let tmp = self.temp_string(*n);
                self.emit(|b| {
                    if off != 0 {
                        b.add_imm(off as i32);
                    }
                    b.push_u32(tmp);
                    b.swap();
                    b.call_builtin(Builtin::StrAssign);
                    b.push_u32(tmp);
                });
            }
            Type::Array(_) | Type::Struct(_) => {
                let (size, al) = self.prog.size_align(t);
                let tmp = self.alloc_static(size, al);
                self.emit(|b| {
                    if off != 0 {
                        b.add_imm(off as i32);
                    }
                    b.push_u32(tmp);
                    b.swap();
                    b.copy(size);
                    b.push_u32(tmp);
                });
            }
            t => match scalar_mem(t) {
                Some(mt) => self.emit(|b| b.ld_ind(mt, off)),
                None => self.op(Opcode::Drop),
            },
        }
    }

    // ----- properties --------------------------------------------------------------------

    /// `e` as a property access: the instance expression (`None`: the current instance),
    /// the property and its name, as the checker recorded it ([`crate::typed::Properties`]).
    fn property_target<'e>(
        &mut self,
        e: &'e Expr,
    ) -> Option<(Option<&'e Expr>, PropertyAccess, &'e Ident)> {
        let (base, name) = match &e.kind {
            ExprKind::Name(n) => (None, n),
            ExprKind::Member(base, m) => (Some(&**base), m),
            _ => return None,
        };
        let Some(property) = self.properties.of(self.cur, name).cloned() else {
            self.missing_record(name.span, "did not decide whether this is a property");
            return None;
        };
        Some((base, property?, name))
    }

    /// The argument list of the SET accessor a write of `value` into a property calls: the
    /// one the checking pass made ([`crate::typed::SetterArguments`]).
    pub(crate) fn setter_arguments(&mut self, value: &Expr) -> Rc<[Arg; 1]> {
        if let Some(args) = self.setter_arguments.of(value) {
            return args.clone();
        }
        let args = Rc::new([Arg {
            name: None,
            output: false,
            value: value.clone(),
            span: value.span,
        }]);
        self.setter_arguments.record(value, args.clone());
        args
    }

    /// The property bare name `n` denotes in the class whose body is walked, if it names one
    /// (a variable of that name shadows it: the caller asks first).
    pub(crate) fn own_property(&self, n: &Ident) -> Option<Bare> {
        let class = self.context_class()?;
        let getter = self.prog.find_member(class, &n.name, MemberKind::Getter);
        let setter = self.prog.find_member(class, &n.name, MemberKind::Setter);
        (getter.is_some() || setter.is_some()).then_some(Bare::Property { class, getter })
    }

    /// The receiver of a member of `class` named bare in its own body.
    pub(crate) fn own_receiver(&self, class: usize) -> Receiver {
        Receiver::Instance {
            class,
            exact: self.prog.pous[class].kind == PouKind::Program,
            superclass: false,
        }
    }

    /// Reads property `e` (a bare name) of `class`, the class whose body is walked, through
    /// its GET accessor `getter`.
    pub(crate) fn own_property_read(
        &mut self,
        class: usize,
        getter: Option<usize>,
        e: &Expr,
    ) -> Type {
        let Some(getter) = getter else {
            self.missing_record(e.span, "passed a read of a property without GET accessor");
            return Type::Error;
        };
        self.call_member(None, self.own_receiver(class), getter, &[], e.span)
    }

    /// Reads a property through its GET accessor; `None` when `e` is no property.
    pub(crate) fn property_read(&mut self, e: &Expr) -> Option<Type> {
        let (base, property, name) = self.property_target(e)?;
        Some(self.accessor_call(base, &property, name, MemberKind::Getter, &[], e.span))
    }

    /// Writes a property through its SET accessor; `false` when `target` is no property.
    pub(crate) fn property_write(&mut self, target: &Expr, value: &Expr) -> bool {
        let Some((base, property, name)) = self.property_target(target) else {
            return false;
        };
        let args = self.setter_arguments(value);
        self.accessor_call(
            base,
            &property,
            name,
            MemberKind::Setter,
            &args[..],
            target.span,
        );
        true
    }

    fn accessor_call(
        &mut self,
        base: Option<&Expr>,
        property: &PropertyAccess,
        name: &Ident,
        kind: MemberKind,
        args: &[Arg],
        span: Span,
    ) -> Type {
        let accessor = match kind {
            MemberKind::Getter => &property.getter,
            _ => &property.setter,
        };
        match (property.recv, accessor) {
            (recv @ Receiver::Instance { .. }, Some(Accessor::Pou(m))) => {
                self.call_member(base, recv, *m, args, span)
            }
            (Receiver::Interface(i), Some(Accessor::Interface(im))) => {
                let d = self.interface_dynamic(i, im);
                self.call_dynamic(base, d, args, span)
            }
            _ => {
                self.missing_record(name.span, "passed a property access without its accessor");
                Type::Error
            }
        }
    }

    // ----- the image's class tables --------------------------------------------------------

    /// The CLASSES and DISPATCH tables: for each class (in class-id order) the method and
    /// method frame it runs for each slot.
    pub(crate) fn build_classes(&mut self) {
        for k in 0..self.prog.classes.len() {
            let class = &self.prog.classes[k];
            let name = self.prog.pous[class.pou].text.clone();
            let methods: Vec<(u16, plc_vm::image::PouId, u32)> = class
                .dispatch
                .iter()
                .map(|&(slot, p)| {
                    (
                        slot,
                        self.pou_ids[p],
                        self.frames.get(p).and_then(|f| f.0).unwrap_or(0),
                    )
                })
                .collect();
            self.b.add_class(&name, &methods);
        }
    }
}
