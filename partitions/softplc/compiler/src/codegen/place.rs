//! Places: variables, members, array elements and partial accesses as addressable locations.

use super::*;
use crate::typed::{Member, Variable};

impl Gen<'_> {
    /// Resolves an l-value; for dynamic places the base address is pushed (a place reached
    /// through a reference is checked here, for the bytes of its type).
    pub(crate) fn place(&mut self, e: &Expr) -> Option<Place> {
        let p = self.place_inner(e)?;
        Some(self.finalize_place(p))
    }

    /// [`Gen::place`] without the final check: a place reached through a reference stays a
    /// reference cell plus an offset (`Loc::Ref`) so that members and elements of it are
    /// checked for their own bytes only.
    pub(crate) fn place_inner(&mut self, e: &Expr) -> Option<Place> {
        let p = self.place_unaliased(e)?;
        Some(self.auto_deref(p))
    }

    pub(super) fn place_unaliased(&mut self, e: &Expr) -> Option<Place> {
        match &e.kind {
            ExprKind::Name(n) => self.name_place(n),
            ExprKind::Deref(inner) if matches!(inner.kind, ExprKind::This | ExprKind::Super) => {
                self.this_place(matches!(inner.kind, ExprKind::Super), e.span)
            }
            ExprKind::Deref(inner) => self.deref_place(inner, e.span),
            ExprKind::Member(base, m) => self.member_place(base, m),
            ExprKind::Index(base, idx) => self.index_place(e, base, idx),
            ExprKind::Bits { base, width, index } => self.partial_place(e, base, *width, *index),
            _ => {
                self.error(codes::EXPECTED_VARIABLE, e.span, "expected a variable");
                None
            }
        }
    }

    /// `base.m`: a member of a structure or an input or output of a function block instance.
    /// The checking pass resolves the member (reporting a wrong one) and records it
    /// ([`Member`]); emission reads the record.
    fn member_place(&mut self, base: &Expr, m: &Ident) -> Option<Place> {
        let bp = self.place_inner(base)?;
        let member = if self.check_only {
            let member = self.resolve_member(base, &bp.ty, m);
            if let Some(member) = &member {
                self.members.record(self.cur, m, member.clone());
            }
            member
        } else {
            let member = self.members.of(self.cur, m).cloned();
            if member.is_none() {
                self.missing_record(m.span, "resolved no member for this name");
            }
            member
        };
        match member {
            Some(Member::Field { offset, ty }) => Some(Place {
                loc: offset_loc(bp.loc, offset),
                ty,
                writable: bp.writable,
                window: None,
            }),
            Some(Member::Var {
                offset,
                ty,
                writable,
            }) => Some(Place {
                loc: offset_loc(bp.loc, offset),
                ty,
                writable: bp.writable && writable,
                window: None,
            }),
            Some(Member::OwnInOut) => {
                self.drop_place(&bp);
                self.name_place(m)
            }
            None => {
                self.drop_place(&bp);
                None
            }
        }
    }

    /// What `m` of `base.m` denotes, `base` being of type `base_ty` (reports a wrong member).
    fn resolve_member(&mut self, base: &Expr, base_ty: &Type, m: &Ident) -> Option<Member> {
        match base_ty {
            Type::Struct(si) => {
                let Some(mem) = self.prog.structs[*si]
                    .members
                    .iter()
                    .find(|x| x.name == m.name)
                    .cloned()
                else {
                    let msg = format!("{} has no member `{}`", self.tname(base_ty), m.text);
                    self.error(codes::NO_SUCH_MEMBER, m.span, msg);
                    return None;
                };
                Some(Member::Field {
                    offset: mem.offset,
                    ty: mem.ty,
                })
            }
            Type::Fb(pi) => {
                let pi = *pi;
                let v = self.prog.pous[pi].param(&m.name).cloned();
                // `THIS^.x` / `SUPER^.x`: the block's own variables, all of them.
                let own = matches!(&base.kind, ExprKind::Deref(i) if matches!(i.kind, ExprKind::This | ExprKind::Super));
                match v {
                    Some(v) if own && !matches!(v.kind, VarKind::External | VarKind::Global) => {
                        if v.kind == VarKind::InOut {
                            return Some(Member::OwnInOut);
                        }
                        Some(Member::Var {
                            offset: v.offset,
                            ty: v.ty,
                            writable: !v.constant,
                        })
                    }
                    // Outputs are read-only from outside; inputs may be set before a call.
                    Some(v) if matches!(v.kind, VarKind::Input | VarKind::Output) => {
                        Some(Member::Var {
                            offset: v.offset,
                            ty: v.ty,
                            writable: v.kind == VarKind::Input,
                        })
                    }
                    Some(_) => {
                        let msg = format!(
                            "`{}` is not an input or output of {}",
                            m.text, self.prog.pous[pi].text
                        );
                        self.error(codes::NO_SUCH_MEMBER, m.span, msg);
                        None
                    }
                    None => {
                        let msg = format!(
                            "{} has no input or output `{}`",
                            self.prog.pous[pi].text, m.text
                        );
                        self.error(codes::NO_SUCH_MEMBER, m.span, msg);
                        None
                    }
                }
            }
            Type::Error => None,
            other => {
                let msg = format!("{} has no members (`.{}`)", self.tname(other), m.text);
                self.error(codes::NO_SUCH_MEMBER, m.span, msg);
                None
            }
        }
    }

    /// `base[i, ...]`: an array element, its constant indices folded in.
    /// Reports an array index `index` of type `t` that is no integer (the checking pass
    /// asks).
    pub(super) fn check_index_type(&mut self, t: &Type, index: &Expr) {
        if self.check_only && !t.is_error() && !t.is_integral() {
            let msg = format!("array index must be an integer, found {}", self.tname(t));
            self.error(codes::INDEX_NOT_INTEGER, index.span, msg);
        }
    }

    fn index_place(&mut self, e: &Expr, base: &Expr, idx: &[Expr]) -> Option<Place> {
        let bp = self.place_inner(base)?;
        let Type::Array(arr) = bp.ty.clone() else {
            if !bp.ty.is_error() {
                let msg = format!("{} is not an array", self.tname(&bp.ty));
                self.error(codes::NOT_AN_ARRAY, base.span, msg);
            }
            self.drop_place(&bp);
            for i in idx {
                self.infer(i);
            }
            return None;
        };
        if self.check_only && idx.len() != arr.dims.len() {
            let msg = format!(
                "array has {} dimension(s) but {} index(es) given",
                arr.dims.len(),
                idx.len()
            );
            self.error(codes::NOT_AN_ARRAY, e.span, msg);
            self.drop_place(&bp);
            return None;
        }
        let elem_stride = self.prog.stride(&arr.elem) as i64;
        // Dimension strides, row-major.
        let mut strides = vec![elem_stride; arr.dims.len()];
        for d in (0..arr.dims.len().saturating_sub(1)).rev() {
            let (lo, hi) = arr.dims[d + 1];
            strides[d] = strides[d + 1] * (hi - lo + 1);
        }
        // Constant indices fold into the static offset.
        let consts: Vec<Option<i128>> = idx
            .iter()
            .map(|i| match self.const_value(i) {
                Some(ConstVal::Int(v)) => Some(v),
                _ => None,
            })
            .collect();
        let mut static_off: i64 = 0;
        let mut dynamic = false;
        for (d, c) in consts.iter().enumerate() {
            let (lo, hi) = arr.dims[d];
            match c {
                Some(v) => {
                    if self.check_only && (*v < lo as i128 || *v > hi as i128) {
                        let msg = format!("index {v} is outside the array bounds {lo}..{hi}");
                        self.error(codes::INDEX_OUT_OF_BOUNDS, idx[d].span, msg);
                    } else {
                        static_off += (*v as i64 - lo) * strides[d];
                    }
                }
                None => dynamic = true,
            }
        }
        if !dynamic {
            return Some(Place {
                loc: offset_loc(bp.loc, static_off as u32),
                ty: arr.elem.clone(),
                writable: bp.writable,
                window: None,
            });
        }
        if let Loc::Ref(o) = bp.loc {
            return self.index_through_reference(o, &arr, idx, &consts, &strides, static_off);
        }
        // A static array (absolute or frame-relative): the first computed index goes
        // through ELEM_ABS/ELEM_REL, which gives the element's address (the constant
        // indices' offset included; the builder fuses it with the load or store);
        // further computed indices, and arrays whose address is on the stack, through
        // INDEX.
        let mut static_base = match bp.loc {
            Loc::Abs(a) => Some(Loc::Abs(a.wrapping_add(static_off as u32))),
            Loc::Rel(o) => Some(Loc::Rel(o.wrapping_add(static_off as u32))),
            Loc::Ind(_) | Loc::Ref(_) => None,
        };
        let offset = match bp.loc {
            Loc::Ind(o) | Loc::Ref(o) => o.wrapping_add(static_off as u32),
            Loc::Abs(_) | Loc::Rel(_) => 0,
        };
        for (d, c) in consts.iter().enumerate() {
            if c.is_some() {
                continue;
            }
            let (lo, hi) = arr.dims[d];
            let t = self.expr(&idx[d], Some(&Type::DINT));
            self.check_index_type(&t, &idx[d]);
            let stride = strides[d] as u32;
            match static_base.take() {
                Some(Loc::Abs(a)) => self.emit(|b| b.elem_abs(a, lo, hi, stride)),
                Some(Loc::Rel(o)) => self.emit(|b| b.elem_rel(o, lo, hi, stride)),
                _ => self.emit(|b| b.index(lo, hi, stride)),
            }
        }
        Some(Place {
            loc: Loc::Ind(offset),
            ty: arr.elem.clone(),
            writable: bp.writable,
            window: None,
        })
    }

    /// `base.N`, `base.%B1`, ...: the bits of an integer or bit-string variable (or of such
    /// a partial access).
    pub(super) fn partial_place(
        &mut self,
        e: &Expr,
        base: &Expr,
        width: u8,
        index: u32,
    ) -> Option<Place> {
        let bp = self.place(base)?;
        let (container, outer_shift, bits) = match (&bp.ty, bp.window) {
            (_, Some(w)) => (w.container, w.shift, w.width),
            (Type::Elem(c), None) if c.is_integral() => (*c, 0, c.size() * 8),
            (ty, None) => {
                if !ty.is_error() {
                    let msg = format!(
                        "partial access `.{}` needs a bit string or integer variable, found {}",
                        index,
                        self.tname(ty)
                    );
                    self.error(codes::PARTIAL_ACCESS, e.span, msg);
                }
                self.drop_place(&bp);
                return None;
            }
        };
        let width = width as u32;
        if self.check_only && (index as u64 + 1) * width as u64 > bits as u64 {
            let unit = match width {
                1 => "bit",
                8 => "byte",
                16 => "word",
                32 => "double word",
                _ => "long word",
            };
            let msg = format!(
                "{unit} {index} is outside the variable ({} bits: {unit}s 0..{})",
                bits,
                (bits / width).saturating_sub(1)
            );
            self.error(codes::PARTIAL_ACCESS, e.span, msg);
            self.drop_place(&bp);
            return None;
        }
        let ty = match width {
            1 => Type::BOOL,
            8 => Type::Elem(Elem::Byte),
            16 => Type::Elem(Elem::Word),
            32 => Type::Elem(Elem::DWord),
            _ => Type::Elem(Elem::LWord),
        };
        Some(Place {
            loc: bp.loc,
            ty,
            writable: bp.writable,
            window: Some(Window {
                shift: outer_shift + index * width,
                width,
                container,
            }),
        })
    }

    pub(crate) fn drop_place(&mut self, p: &Place) {
        if matches!(p.loc, Loc::Ind(_) | Loc::Ref(_)) {
            self.op(Opcode::Drop);
        }
    }

    /// The place of a variable's name. The checking pass resolves the name (reporting an
    /// unknown one) and records the variable ([`Variable`]); emission reads the record.
    pub(super) fn name_place(&mut self, n: &Ident) -> Option<Place> {
        let var = if self.check_only {
            let var = self.resolve_variable(n)?;
            self.variables.record(self.cur, n, var.clone());
            var
        } else {
            match self.variables.of(self.cur, n) {
                Some(var) => var.clone(),
                None => {
                    self.missing_record(n.span, "resolved no variable for this name");
                    return None;
                }
            }
        };
        Some(self.variable_place(&var))
    }

    /// The variable `n` denotes in the current POU: its own, its owner's (for a METHOD or
    /// action) or a global (directly or through VAR_EXTERNAL).
    fn resolve_variable(&mut self, n: &Ident) -> Option<Variable> {
        let pou = &self.prog.pous[self.cur];
        let (v, own) = match pou.var(&n.name).cloned() {
            Some(v) => (Some(v), true),
            None => (
                self.var_owner(&n.name)
                    .and_then(|o| self.prog.pous[o].var(&n.name).cloned()),
                false,
            ),
        };
        let global = self.prog.globals.iter().position(|g| g.name == n.name);
        match (v, global) {
            (Some(v), _) if v.kind != VarKind::External => Some(Variable::Frame { var: v, own }),
            (Some(v), Some(index)) => {
                let g = &self.prog.globals[index];
                if g.ty != v.ty && !v.ty.is_error() && !g.ty.is_error() {
                    let msg = format!(
                        "VAR_EXTERNAL `{}` declared as {} but the global is {}",
                        v.text,
                        self.tname(&v.ty),
                        self.tname(&g.ty)
                    );
                    self.error(codes::VAR_EXTERNAL, v.span, msg);
                }
                let writable = !self.prog.globals[index].constant && !v.constant;
                Some(Variable::Global { index, writable })
            }
            (Some(v), None) => {
                let msg = format!("VAR_EXTERNAL `{}` has no matching VAR_GLOBAL", v.text);
                self.error(codes::VAR_EXTERNAL, n.span, msg);
                None
            }
            (None, Some(index)) => Some(Variable::Global {
                index,
                writable: !self.prog.globals[index].constant,
            }),
            (None, None) => {
                let msg = format!("unknown variable `{}`", n.text);
                self.error(codes::UNKNOWN_VARIABLE, n.span, msg);
                None
            }
        }
    }

    /// The place of a resolved variable (a VAR_IN_OUT's address is loaded).
    fn variable_place(&mut self, var: &Variable) -> Place {
        match var {
            Variable::Global { index, writable } => {
                let g = &self.prog.globals[*index];
                Place {
                    loc: Loc::Abs(g.offset),
                    ty: g.ty.clone(),
                    writable: *writable,
                    window: None,
                }
            }
            Variable::Frame { var: v, own } => {
                // A method's own variables are in its static frame; the instance's are
                // frame-relative.
                let frame = if *own { self.method_frame() } else { None };
                if v.kind == VarKind::InOut {
                    match frame {
                        Some(f) => self.emit(|b| b.ld_abs(MemType::U32, f + v.offset)),
                        None => self.emit(|b| b.ld_rel(MemType::U32, v.offset)),
                    }
                    return Place {
                        loc: Loc::Ind(0),
                        ty: v.ty.clone(),
                        writable: true,
                        window: None,
                    };
                }
                Place {
                    loc: match frame {
                        Some(f) => Loc::Abs(f + v.offset),
                        None => Loc::Rel(v.offset),
                    },
                    ty: v.ty.clone(),
                    writable: !v.constant,
                    window: None,
                }
            }
        }
    }

    /// Pushes the address of an aggregate place.
    pub(crate) fn addr_of(&mut self, p: &Place) {
        match p.loc {
            Loc::Abs(a) => self.emit(|b| b.push_u32(a)),
            Loc::Rel(o) => self.emit(|b| b.lea_rel(o)),
            Loc::Ind(0) => {}
            Loc::Ind(o) => self.emit(|b| {
                b.push_u32(o);
                b.op(Opcode::Add);
            }),
            Loc::Ref(_) => unreachable!("places are finalized"),
        }
    }

    /// Pushes the value of a place (elementary) or its address (aggregate).
    pub(crate) fn load(&mut self, p: &Place) {
        if let Some(w) = p.window {
            let mt = mem_type(w.container);
            match p.loc {
                Loc::Abs(a) => self.emit(|b| b.ld_abs(mt, a)),
                Loc::Rel(o) => self.emit(|b| b.ld_rel(mt, o)),
                Loc::Ind(o) => self.emit(|b| b.ld_ind(mt, o)),
                Loc::Ref(_) => unreachable!("places are finalized"),
            }
            self.emit(|b| {
                if w.shift != 0 {
                    b.push_i32(w.shift as i32);
                    b.op(Opcode::ShrU);
                }
                if w.width < 64 {
                    b.push_int(w.mask() as i64);
                    b.op(Opcode::And);
                }
            });
            return;
        }
        match scalar_mem(&p.ty) {
            Some(mt) => match p.loc {
                Loc::Abs(a) => self.emit(|b| b.ld_abs(mt, a)),
                Loc::Rel(o) => self.emit(|b| b.ld_rel(mt, o)),
                Loc::Ind(o) => self.emit(|b| b.ld_ind(mt, o)),
                Loc::Ref(_) => unreachable!("places are finalized"),
            },
            None => self.addr_of(p),
        }
    }
}
