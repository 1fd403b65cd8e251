//! Declarations of the IEC 61131-3 3rd edition object features (as CODESYS has them):
//! methods, properties, actions, interfaces and function-block inheritance.
//!
//! Every method, property accessor (`GET`/`SET`) and action becomes a POU of its own that
//! runs on an instance of its owner: the frame base register points at the instance, so
//! the owner's variables are frame-relative as in its body. Methods and accessors also have
//! a static frame for their parameters and variables, like a FUNCTION (no recursion, which
//! is checked), re-initialised on every call. A derived function block's frame starts with
//! its base's frame, so every method of the base works on instances of the derived block.
//!
//! Dynamic dispatch: a function block that implements interfaces, extends another or is
//! extended is a *class*; its instances hold the class id in their first bytes
//! ([`CLASS_HEADER`]). Every method that can be called without knowing the instance's exact
//! type (interface methods, methods a derived block may override) has a *slot*; each class
//! lists the method it runs for each slot ([`ClassDef::dispatch`]), which becomes the
//! image's CLASSES/DISPATCH tables for `CALL_VIRT`. Methods of the same slot have the same
//! signature (checked here), so they lay out their parameters alike and the caller can store
//! the arguments without knowing which one runs.

use crate::codes;
use std::collections::HashMap;

use crate::ast::*;
use crate::diagnostics::Span;
use crate::sema::{
    ClassDef, InterfaceDef, InterfaceMember, LayoutState, Member, MemberKind, MemberSource, PouDef,
    Program, Sema, VarDef, frame_layout,
};
use crate::types::Type;

/// Where a POU's declaration parts are in the unit.
pub(crate) struct PouSource<'u> {
    /// The POU's name, or the method's / property's / action's.
    pub name: &'u Ident,
    pub return_type: Option<&'u TypeRef>,
    pub var_blocks: &'u [VarBlock],
    pub body: &'u [Stmt],
}

/// The declaration parts of POU `pou`.
pub(crate) fn pou_source<'u>(unit: &'u Unit, pou: &PouDef) -> PouSource<'u> {
    let Some(member) = &pou.member else {
        let ast = &unit.pous[pou.ast];
        return PouSource {
            name: &ast.name,
            return_type: ast.return_type.as_ref(),
            var_blocks: &ast.var_blocks,
            body: &ast.body,
        };
    };
    match member.source {
        MemberSource::Method(p, k) => {
            let m = &unit.pous[p].methods[k];
            PouSource {
                name: &m.name,
                return_type: m.return_type.as_ref(),
                var_blocks: &m.var_blocks,
                body: &m.body,
            }
        }
        MemberSource::Property(p, k) => {
            let prop = &unit.pous[p].properties[k];
            let accessor = if member.kind == MemberKind::Getter {
                prop.get.as_ref()
            } else {
                prop.set.as_ref()
            };
            let (var_blocks, body) = match accessor {
                Some(a) => (&a.var_blocks[..], &a.body[..]),
                None => (&[][..], &[][..]),
            };
            PouSource {
                name: &prop.name,
                return_type: (member.kind == MemberKind::Getter).then_some(&prop.ty),
                var_blocks,
                body,
            }
        }
        MemberSource::Action(p, k) => {
            let a = &unit.pous[p].actions[k];
            PouSource {
                name: &a.name,
                return_type: None,
                var_blocks: &[],
                body: &a.body,
            }
        }
        MemberSource::UnitAction(k) => {
            let a = &unit.actions[k].1;
            PouSource {
                name: &a.name,
                return_type: None,
                var_blocks: &[],
                body: &a.body,
            }
        }
    }
}

impl Program {
    /// The member `name` of kind `kind` that instances of `pou` have: its own or the
    /// nearest base's.
    pub fn find_member(&self, pou: usize, name: &str, kind: MemberKind) -> Option<usize> {
        let mut cur = Some(pou);
        let mut guard = 0;
        while let Some(c) = cur {
            if let Some(&m) = self.members.get(&(c, name.to_string(), kind)) {
                return Some(m);
            }
            cur = self.pous[c].base;
            guard += 1;
            if guard > self.pous.len() {
                return None;
            }
        }
        None
    }

    /// Whether function block `class` is `base` or derived from it.
    pub fn derives_from(&self, class: usize, base: usize) -> bool {
        let mut cur = Some(class);
        let mut guard = 0;
        while let Some(c) = cur {
            if c == base {
                return true;
            }
            cur = self.pous[c].base;
            guard += 1;
            if guard > self.pous.len() {
                return false;
            }
        }
        false
    }

    /// Whether interface `a` is `b` or extends it (directly or not).
    pub fn interface_extends(&self, a: usize, b: usize) -> bool {
        let mut todo = vec![a];
        let mut seen = vec![false; self.interfaces.len()];
        while let Some(i) = todo.pop() {
            if i == b {
                return true;
            }
            if !std::mem::replace(&mut seen[i], true) {
                todo.extend(self.interfaces[i].extends.iter().copied());
            }
        }
        false
    }

    /// Interface `i` and every interface it extends.
    pub fn interface_closure(&self, i: usize) -> Vec<usize> {
        let mut out = Vec::new();
        let mut todo = vec![i];
        while let Some(k) = todo.pop() {
            if !out.contains(&k) {
                out.push(k);
                todo.extend(self.interfaces[k].extends.iter().copied());
            }
        }
        out
    }

    /// The member `name` (of `kind`) of interface `i` or of an interface it extends.
    pub fn interface_member(
        &self,
        i: usize,
        name: &str,
        kind: MemberKind,
    ) -> Option<&InterfaceMember> {
        self.interface_closure(i).into_iter().find_map(|k| {
            self.interfaces[k]
                .members
                .iter()
                .find(|m| m.name == name && m.kind == kind)
        })
    }

    /// Whether function block `class` implements interface `i`.
    pub fn implements(&self, class: usize, i: usize) -> bool {
        self.pous[class]
            .class
            .is_some_and(|c| self.classes[c].interfaces.contains(&i))
    }

    /// The function blocks derived from `pou` (not `pou` itself).
    pub fn derived_classes(&self, pou: usize) -> impl Iterator<Item = usize> + '_ {
        (0..self.pous.len()).filter(move |&c| c != pou && self.derives_from(c, pou))
    }

    /// The parameters of a method POU in frame order (inputs, in-outs, outputs; without its
    /// result and its other variables): what a signature compares.
    pub fn signature(&self, pou: usize) -> Vec<&VarDef> {
        let p = &self.pous[pou];
        p.vars
            .iter()
            .filter(|v| {
                matches!(v.kind, VarKind::Input | VarKind::InOut | VarKind::Output)
                    && !(v.kind == VarKind::Output
                        && v.name == p.vars[0].name
                        && p.return_type.is_some())
            })
            .collect()
    }
}

/// `(kind, name, type)` of each parameter, for signature comparisons.
fn shape<'v>(params: impl IntoIterator<Item = &'v VarDef>) -> Vec<(VarKind, String, Type)> {
    params
        .into_iter()
        .map(|v| (v.kind, v.name.clone(), v.ty.clone()))
        .collect()
}

impl Sema<'_> {
    /// Registers the methods, property accessors and actions of every function block and
    /// program as POUs, resolves `EXTENDS` and finds the classes.
    pub(crate) fn declare_members(&mut self) {
        let unit = self.unit;
        let top: Vec<usize> = (0..self.prog.pous.len()).collect();
        for i in top {
            let ast_index = self.prog.pous[i].ast;
            let ast = &unit.pous[ast_index];
            let owner_kind = ast.kind;
            if owner_kind == PouKind::Function {
                continue;
            }
            for (k, m) in ast.methods.iter().enumerate() {
                self.add_member(
                    i,
                    MemberKind::Method,
                    &m.name,
                    m.modifiers,
                    MemberSource::Method(ast_index, k),
                );
            }
            for (k, p) in ast.properties.iter().enumerate() {
                if p.get.is_some() {
                    self.add_member(
                        i,
                        MemberKind::Getter,
                        &p.name,
                        p.modifiers,
                        MemberSource::Property(ast_index, k),
                    );
                }
                if p.set.is_some() {
                    self.add_member(
                        i,
                        MemberKind::Setter,
                        &p.name,
                        p.modifiers,
                        MemberSource::Property(ast_index, k),
                    );
                }
            }
            for (k, a) in ast.actions.iter().enumerate() {
                self.add_member(
                    i,
                    MemberKind::Action,
                    &a.name,
                    Modifiers::default(),
                    MemberSource::Action(ast_index, k),
                );
            }
        }
        for (k, (pou, a)) in unit.actions.iter().enumerate() {
            match self.prog.pou_by_name.get(&pou.name) {
                Some(&i) if self.prog.pous[i].kind != PouKind::Function => {
                    self.add_member(
                        i,
                        MemberKind::Action,
                        &a.name,
                        Modifiers::default(),
                        MemberSource::UnitAction(k),
                    );
                }
                Some(_) => self.diags.error(
                    codes::MISPLACED_POU_ELEMENT,
                    pou.span,
                    format!(
                        "`{}` is a FUNCTION: actions belong to a FUNCTION_BLOCK or a PROGRAM",
                        pou.text
                    ),
                ),
                None => self.diags.error(
                    codes::UNKNOWN_POU,
                    pou.span,
                    format!("unknown POU `{}`", pou.text),
                ),
            }
        }
        // EXTENDS, and which blocks are classes (their instances carry a class id).
        let mut is_class = vec![false; self.prog.pous.len()];
        for i in 0..self.prog.pous.len() {
            if self.prog.pous[i].member.is_some() {
                continue;
            }
            let ast = &unit.pous[self.prog.pous[i].ast];
            if !ast.implements.is_empty() {
                is_class[i] = true;
            }
            let Some(base) = &ast.extends else { continue };
            let found = crate::sema::qualified(&base.name, self.prog.pou_by_name.keys())
                .ok()
                .flatten();
            match found.and_then(|n| self.prog.pou_by_name.get(&n)) {
                Some(&b) if self.prog.pous[b].kind == PouKind::FunctionBlock && b != i => {
                    if self.prog.pous[b].is_final {
                        self.diags.error(
                            codes::INVALID_EXTENDS,
                            base.span,
                            format!("`{}` is FINAL and cannot be extended", base.text),
                        );
                    }
                    self.prog.pous[i].base = Some(b);
                    is_class[i] = true;
                    is_class[b] = true;
                }
                Some(_) => self.diags.error(
                    codes::INVALID_EXTENDS,
                    base.span,
                    format!("`{}` is not a function block to extend", base.text),
                ),
                None => self.diags.error(
                    codes::INVALID_EXTENDS,
                    base.span,
                    format!("unknown function block `{}`", base.text),
                ),
            }
        }
        for (i, class) in is_class.into_iter().enumerate() {
            if class {
                self.prog.pous[i].class = Some(self.prog.classes.len());
                self.prog.classes.push(ClassDef {
                    pou: i,
                    interfaces: Vec::new(),
                    dispatch: Vec::new(),
                });
            }
        }
    }

    fn add_member(
        &mut self,
        owner: usize,
        kind: MemberKind,
        name: &Ident,
        modifiers: Modifiers,
        source: MemberSource,
    ) {
        let owner_name = self.prog.pous[owner].text.clone();
        let clash = [
            MemberKind::Method,
            MemberKind::Getter,
            MemberKind::Setter,
            MemberKind::Action,
        ]
        .iter()
        .filter(|&&k| {
            // A getter and a setter of one property share its name.
            !(matches!(kind, MemberKind::Getter | MemberKind::Setter)
                && matches!(k, MemberKind::Getter | MemberKind::Setter)
                && k != kind)
        })
        .any(|&k| {
            self.prog
                .members
                .contains_key(&(owner, name.name.clone(), k))
        });
        if clash {
            self.diags.error(
                codes::DUPLICATE_VARIABLE,
                name.span,
                format!("`{owner_name}` already has a member `{}`", name.text),
            );
            return;
        }
        let owner_kind = self.prog.pous[owner].kind;
        let (kind_of_pou, label) = match kind {
            MemberKind::Method => (PouKind::Function, name.text.clone()),
            MemberKind::Getter => (PouKind::Function, format!("{}.GET", name.text)),
            MemberKind::Setter => (PouKind::Function, format!("{}.SET", name.text)),
            MemberKind::Action => (owner_kind, name.text.clone()),
        };
        let index = self.prog.pous.len();
        self.prog
            .members
            .insert((owner, name.name.clone(), kind), index);
        let ast = self.prog.pous[owner].ast;
        self.prog.pous.push(PouDef {
            kind: kind_of_pou,
            name: format!(
                "{}.{}",
                self.prog.pous[owner].name,
                label.to_ascii_uppercase()
            ),
            text: format!("{owner_name}.{label}"),
            span: name.span,
            ast,
            vars: Vec::new(),
            return_type: None,
            frame_size: 0,
            reinit_start: 0,
            builtin: self.prog.pous[owner].builtin,
            state: LayoutState::NotStarted,
            recursive: false,
            member: Some(Member {
                owner,
                kind,
                name: name.name.clone(),
                text: name.text.clone(),
                access: modifiers.access,
                is_abstract: modifiers.is_abstract,
                is_final: modifiers.is_final,
                source,
            }),
            base: None,
            class: None,
            is_abstract: false,
            is_final: false,
        });
    }

    /// Registers the INTERFACEs (their members are resolved in [`Sema::finish_classes`]).
    pub(crate) fn declare_interfaces(&mut self) {
        for (k, i) in self.unit.interfaces.iter().enumerate() {
            let taken = self.prog.pou_by_name.contains_key(&i.name.name)
                || self.prog.interface_by_name.contains_key(&i.name.name)
                || self.unit.types.iter().any(|t| t.name.name == i.name.name);
            if taken {
                self.diags.error(
                    codes::DUPLICATE_DEFINITION,
                    i.name.span,
                    format!("`{}` is already defined", i.name.text),
                );
                continue;
            }
            self.prog
                .interface_by_name
                .insert(i.name.name.clone(), self.prog.interfaces.len());
            self.prog.interfaces.push(InterfaceDef {
                name: i.name.name.clone(),
                text: i.name.text.clone(),
                span: i.name.span,
                ast: k,
                extends: Vec::new(),
                members: Vec::new(),
            });
        }
    }

    /// The interface `name` (possibly namespace-qualified) refers to.
    fn interface_named(&self, name: &str) -> Option<&usize> {
        let full = crate::sema::qualified(name, self.prog.interface_by_name.keys())
            .ok()
            .flatten()?;
        self.prog.interface_by_name.get(&full)
    }

    /// The type of the property a getter or setter belongs to.
    pub(crate) fn property_type_of(&mut self, member: Option<&Member>) -> Type {
        let Some(Member {
            source: MemberSource::Property(p, k),
            ..
        }) = member
        else {
            return Type::Error;
        };
        let ty = self.unit.pous[*p].properties[*k].ty.clone();
        self.resolve_type(&ty, &[])
    }

    /// An ABSTRACT function block has no instances of its own.
    pub(crate) fn no_abstract_instance(&mut self, d: &VarDecl, ty: &Type) {
        let mut t = ty;
        while let Type::Array(a) = t {
            t = &a.elem;
        }
        if let Type::Fb(i) = t
            && self.prog.pous[*i].is_abstract
        {
            let name = self.prog.pous[*i].text.clone();
            self.diags.error(
                codes::ABSTRACT_INSTANCE,
                d.ty.span(),
                format!(
                    "`{name}` is ABSTRACT: declare an instance of a function block derived from it"
                ),
            );
        }
    }

    /// After every POU is laid out: interface members and their slots, overrides, slots of
    /// class methods, interface conformance and the classes' dispatch lists.
    pub(crate) fn finish_classes(&mut self) {
        self.resolve_interfaces();
        let classes: Vec<usize> = self.prog.classes.iter().map(|c| c.pou).collect();
        // Bases before derived blocks: slots flow down.
        let mut done = vec![false; self.prog.pous.len()];
        for c in &classes {
            self.class_slots(*c, &mut done);
        }
        for (k, c) in classes.iter().enumerate() {
            self.class_dispatch(k, *c);
        }
        self.check_plain_members();
    }

    fn resolve_interfaces(&mut self) {
        let unit = self.unit;
        for i in 0..self.prog.interfaces.len() {
            let ast = &unit.interfaces[self.prog.interfaces[i].ast];
            let mut extends = Vec::new();
            for e in &ast.extends {
                match self.interface_named(&e.name) {
                    Some(&j) => extends.push(j),
                    None => self.diags.error(
                        codes::UNKNOWN_INTERFACE,
                        e.span,
                        format!("unknown interface `{}`", e.text),
                    ),
                }
            }
            self.prog.interfaces[i].extends = extends;
        }
        for i in 0..self.prog.interfaces.len() {
            let cyclic = self.prog.interfaces[i]
                .extends
                .clone()
                .into_iter()
                .any(|j| self.prog.interface_extends(j, i));
            if cyclic {
                let (span, text) = (
                    self.prog.interfaces[i].span,
                    self.prog.interfaces[i].text.clone(),
                );
                self.diags.error(
                    codes::INTERFACE_CYCLE,
                    span,
                    format!("interface `{text}` extends itself"),
                );
                self.prog.interfaces[i].extends.clear();
            }
        }
        for i in 0..self.prog.interfaces.len() {
            let ast = &unit.interfaces[self.prog.interfaces[i].ast];
            let mut members = Vec::new();
            for m in &ast.methods {
                let rt = m.return_type.as_ref().map(|t| self.resolve_type(t, &[]));
                let params = self.signature_of(&m.var_blocks, None, rt.as_ref(), &m.name);
                members.push(self.interface_member(&m.name, MemberKind::Method, rt, params));
            }
            for p in &ast.properties {
                let t = self.resolve_type(&p.ty, &[]);
                if p.get.is_some() {
                    let params = self.signature_of(&[], None, Some(&t), &p.name);
                    members.push(self.interface_member(
                        &p.name,
                        MemberKind::Getter,
                        Some(t.clone()),
                        params,
                    ));
                }
                if p.set.is_some() {
                    let params = self.signature_of(&[], Some(&t), None, &p.name);
                    members.push(self.interface_member(&p.name, MemberKind::Setter, None, params));
                }
            }
            for (a, m) in members.iter().enumerate() {
                if members[..a]
                    .iter()
                    .any(|o| o.name == m.name && o.kind == m.kind)
                {
                    self.diags.error(
                        codes::DUPLICATE_VARIABLE,
                        m.span,
                        format!("`{}` is declared twice", m.text),
                    );
                }
            }
            self.prog.interfaces[i].members = members;
        }
    }

    fn interface_member(
        &mut self,
        name: &Ident,
        kind: MemberKind,
        return_type: Option<Type>,
        params: Vec<VarDef>,
    ) -> InterfaceMember {
        let slot = self.new_slot(name.span);
        InterfaceMember {
            name: name.name.clone(),
            text: name.text.clone(),
            kind,
            return_type,
            params,
            slot,
            span: name.span,
        }
    }

    fn new_slot(&mut self, span: Span) -> u16 {
        let slot = self.prog.slot_count;
        match slot.checked_add(1) {
            Some(next) => self.prog.slot_count = next,
            None => self.diags.error(
                codes::TOO_MANY_DYNAMIC_METHODS,
                span,
                "too many methods that can be called dynamically",
            ),
        }
        slot
    }

    /// The parameters (laid out as a method lays them out) of a method declaration, or of
    /// a property accessor (`setter`: the value's type; `result`: a getter's type).
    fn signature_of(
        &mut self,
        blocks: &[VarBlock],
        setter: Option<&Type>,
        result: Option<&Type>,
        name: &Ident,
    ) -> Vec<VarDef> {
        let var = |name: &Ident, ty: Type, kind: VarKind| VarDef {
            name: name.name.clone(),
            text: name.text.clone(),
            span: name.span,
            ty,
            offset: 0,
            kind,
            constant: false,
            init: None,
            location: None,
            retain: false,
        };
        let mut vars = Vec::new();
        if let Some(t) = result {
            vars.push(var(name, t.clone(), VarKind::Output));
        }
        if let Some(t) = setter {
            vars.push(var(name, t.clone(), VarKind::Input));
        }
        for b in blocks {
            if !matches!(b.kind, VarKind::Input | VarKind::Output | VarKind::InOut) {
                self.diags.error(
                    codes::INTERFACE_CONTENT,
                    b.span,
                    "an interface method declares VAR_INPUT, VAR_OUTPUT and VAR_IN_OUT only",
                );
                continue;
            }
            for d in &b.decls {
                let ty = self.resolve_type(&d.ty, &[]);
                for n in &d.names {
                    let mut v = var(n, ty.clone(), b.kind);
                    v.init = d.init.clone();
                    vars.push(v);
                }
            }
        }
        frame_layout(&self.prog, &mut vars, PouKind::Function, true, 0);
        let has_result = result.is_some();
        vars.into_iter()
            .enumerate()
            .filter(|(k, _)| !(has_result && *k == 0))
            .map(|(_, v)| v)
            .collect()
    }

    /// Slots of the methods of class `c` (and its bases first): a method overriding a base
    /// method takes its slot (same signature, base not FINAL), a new one gets its own.
    fn class_slots(&mut self, c: usize, done: &mut [bool]) {
        if done[c] {
            return;
        }
        done[c] = true;
        if let Some(b) = self.prog.pous[c].base {
            self.class_slots(b, done);
        }
        let own: Vec<(String, MemberKind, usize)> = self
            .prog
            .members
            .iter()
            .filter(|((o, _, k), _)| *o == c && *k != MemberKind::Action)
            .map(|((_, n, k), p)| (n.clone(), *k, *p))
            .collect();
        let mut own = own;
        own.sort_by_key(|m| m.2);
        for (name, kind, pou) in own {
            let inherited = self.prog.pous[c]
                .base
                .and_then(|b| self.prog.find_member(b, &name, kind));
            let m = self.prog.pous[pou].member.clone().expect("member");
            let slot = match inherited {
                Some(base_pou) => {
                    let bm = self.prog.pous[base_pou].member.clone().expect("member");
                    if bm.is_final {
                        self.diags.error(
                            codes::FINAL_OVERRIDE,
                            m_span(&self.prog.pous[pou]),
                            format!(
                                "`{}` is FINAL in `{}` and cannot be overridden",
                                m.text, self.prog.pous[bm.owner].text
                            ),
                        );
                    }
                    self.same_signature(pou, base_pou, "overrides");
                    match self.prog.slots.get(&base_pou) {
                        Some(&s) => s,
                        None => {
                            let s = self.new_slot(m_span(&self.prog.pous[pou]));
                            self.prog.slots.insert(base_pou, s);
                            s
                        }
                    }
                }
                None => self.new_slot(m_span(&self.prog.pous[pou])),
            };
            self.prog.slots.insert(pou, slot);
        }
    }

    /// Reports unless method POU `a` has the signature of `b` (return type, parameters).
    fn same_signature(&mut self, a: usize, b: usize, relation: &str) {
        let same = self.prog.pous[a].return_type == self.prog.pous[b].return_type
            && shape(self.prog.signature(a)) == shape(self.prog.signature(b));
        if !same {
            let msg = format!(
                "`{}` {relation} `{}` but has another signature (return type, or names, kinds and types of its parameters)",
                self.prog.pous[a].text, self.prog.pous[b].text
            );
            self.diags
                .error(codes::SIGNATURE_MISMATCH, m_span(&self.prog.pous[a]), msg);
        }
    }

    /// The dispatch list of class `k` (POU `c`), its interfaces, and the checks that it
    /// implements them and, unless ABSTRACT, every abstract method.
    fn class_dispatch(&mut self, k: usize, c: usize) {
        let is_abstract = self.prog.pous[c].is_abstract;
        let class_name = self.prog.pous[c].text.clone();
        let span = self.prog.pous[c].span;
        let mut dispatch: HashMap<u16, usize> = HashMap::new();
        // Class methods: the most derived implementation of every slot along the chain.
        let mut chain = Vec::new();
        let mut cur = Some(c);
        while let Some(x) = cur {
            if chain.contains(&x) {
                break;
            }
            chain.push(x);
            cur = self.prog.pous[x].base;
        }
        for &x in chain.iter().rev() {
            let members: Vec<usize> = self
                .prog
                .members
                .iter()
                .filter(|((o, _, kind), _)| *o == x && *kind != MemberKind::Action)
                .map(|(_, p)| *p)
                .collect();
            for p in members {
                if let Some(&s) = self.prog.slots.get(&p) {
                    dispatch.insert(s, p);
                }
            }
        }
        if !is_abstract {
            let mut missing: Vec<String> = dispatch
                .values()
                .filter(|&&p| {
                    self.prog.pous[p]
                        .member
                        .as_ref()
                        .is_some_and(|m| m.is_abstract)
                })
                .map(|&p| self.prog.pous[p].text.clone())
                .collect();
            missing.sort();
            if let Some(m) = missing.first() {
                self.diags.error(codes::MISSING_IMPLEMENTATION,
                    span,
                    format!("`{class_name}` must implement the ABSTRACT method `{m}` or be declared ABSTRACT"),
                );
            }
        }
        dispatch.retain(|_, p| {
            !self.prog.pous[*p]
                .member
                .as_ref()
                .is_some_and(|m| m.is_abstract)
        });
        // Interfaces: declared here, by a base, or extended by those.
        let mut interfaces = Vec::new();
        for &x in &chain {
            let ast = &self.unit.pous[self.prog.pous[x].ast];
            for name in &ast.implements {
                match self.interface_named(&name.name) {
                    Some(&i) => {
                        for j in self.prog.interface_closure(i) {
                            if !interfaces.contains(&j) {
                                interfaces.push(j);
                            }
                        }
                    }
                    None if x == c => self.diags.error(
                        codes::UNKNOWN_INTERFACE,
                        name.span,
                        format!("unknown interface `{}`", name.text),
                    ),
                    None => {}
                }
            }
        }
        for &i in &interfaces {
            for m in self.prog.interfaces[i].members.clone() {
                let found = self.prog.find_member(c, &m.name, m.kind).filter(|&p| {
                    !self.prog.pous[p]
                        .member
                        .as_ref()
                        .is_some_and(|mm| mm.is_abstract)
                });
                let what = match m.kind {
                    MemberKind::Getter => format!("the GET accessor of property `{}`", m.text),
                    MemberKind::Setter => format!("the SET accessor of property `{}`", m.text),
                    _ => format!("method `{}`", m.text),
                };
                let iface = self.prog.interfaces[i].text.clone();
                match found {
                    Some(p) => {
                        let same = self.prog.pous[p].return_type == m.return_type
                            && shape(self.prog.signature(p)) == shape(&m.params);
                        if !same {
                            let msg = format!(
                                "`{}` implements {what} of interface `{iface}` but has another signature (return type, or names, kinds and types of its parameters)",
                                self.prog.pous[p].text
                            );
                            self.diags.error(
                                codes::SIGNATURE_MISMATCH,
                                m_span(&self.prog.pous[p]),
                                msg,
                            );
                        }
                        dispatch.insert(m.slot, p);
                    }
                    None if is_abstract => {}
                    None => {
                        self.diags.error(
                            codes::MISSING_IMPLEMENTATION,
                            span,
                            format!(
                                "`{class_name}` does not implement {what} of interface `{iface}`"
                            ),
                        );
                    }
                }
            }
        }
        let mut list: Vec<(u16, usize)> = dispatch.into_iter().collect();
        list.sort();
        self.prog.classes[k].interfaces = interfaces;
        self.prog.classes[k].dispatch = list;
    }

    /// Every member: its name is not also a variable of its block, and ABSTRACT needs an
    /// ABSTRACT block.
    fn check_plain_members(&mut self) {
        for p in 0..self.prog.pous.len() {
            let Some(m) = self.prog.pous[p].member.clone() else {
                continue;
            };
            if self.prog.pous[m.owner].var(&m.name).is_some() && m.kind != MemberKind::Setter {
                let owner = self.prog.pous[m.owner].text.clone();
                self.diags.error(
                    codes::DUPLICATE_VARIABLE,
                    m_span(&self.prog.pous[p]),
                    format!("`{owner}` already has a variable `{}`", m.text),
                );
            }
            if m.is_abstract && !self.prog.pous[m.owner].is_abstract {
                let owner = self.prog.pous[m.owner].text.clone();
                self.diags.error(codes::ABSTRACT_METHOD_OWNER,
                    m_span(&self.prog.pous[p]),
                    format!("the ABSTRACT method `{}` needs an ABSTRACT function block (`FUNCTION_BLOCK ABSTRACT {owner}`)", m.text),
                );
            }
        }
    }
}

fn m_span(p: &PouDef) -> Span {
    p.span
}
