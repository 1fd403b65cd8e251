//! Places: variables, members, array elements and partial accesses as addressable
//! locations. The place checker ([`crate::sema::place`]) checks them and records what each
//! name and member denotes; this walk emits the access the records describe. Where a place
//! lies ([`Place`]'s constructors here) is computed once for both.

use super::*;
use crate::typed::{Member, Variable};

impl Place {
    /// The place `base.m`, `member` being what `m` denotes (`None` for the block's own
    /// VAR_IN_OUT, which is the variable the name denotes).
    pub(crate) fn member(base: &Place, member: &Member) -> Option<Place> {
        let (offset, ty, writable) = match member {
            Member::Field { offset, ty } => (*offset, ty.clone(), base.writable),
            Member::Var {
                offset,
                ty,
                writable,
            } => (*offset, ty.clone(), base.writable && *writable),
            Member::OwnInOut => return None,
        };
        Some(Place {
            loc: offset_loc(base.loc, offset),
            ty,
            writable,
            window: None,
        })
    }

    /// What a reference to `target` refers to: an instance at the address it holds
    /// (checked for NULL when it is taken), anything else at the reference cell, checked
    /// when it is accessed.
    pub(crate) fn referred(target: Type) -> Place {
        let loc = match target {
            Type::Fb(_) => Loc::Ind(0),
            _ => Loc::Ref(0),
        };
        Place {
            loc,
            ty: target,
            writable: true,
            window: None,
        }
    }

    /// `THIS^` of an instance of `class`: the frame the body runs on.
    pub(crate) fn instance(class: usize) -> Place {
        Place {
            loc: Loc::Rel(0),
            ty: Type::Fb(class),
            writable: true,
            window: None,
        }
    }

    /// The place once its reference (if it is reached through one) was checked: a plain
    /// indirect place.
    pub(crate) fn finalized(self) -> Place {
        match self.loc {
            Loc::Ref(_) => Place {
                loc: Loc::Ind(0),
                ..self
            },
            _ => self,
        }
    }

    /// An element of type `elem` of the array at `base`, `static_offset` bytes in (the
    /// constant indices), `computed` when an index is computed (its address is then on the
    /// stack, or the reference to the array moves by it).
    pub(crate) fn element(base: &Place, elem: Type, static_offset: i64, computed: bool) -> Place {
        let offset = static_offset as u32;
        let (loc, writable) = match base.loc {
            _ if !computed => (offset_loc(base.loc, offset), base.writable),
            Loc::Ref(o) => (Loc::Ref(o.wrapping_add(offset)), true),
            Loc::Ind(o) => (Loc::Ind(o.wrapping_add(offset)), base.writable),
            Loc::Abs(_) | Loc::Rel(_) => (Loc::Ind(0), base.writable),
        };
        Place {
            loc,
            ty: elem,
            writable,
            window: None,
        }
    }

    /// The bits a partial access can reach: (the integer or bit-string type holding them,
    /// the first bit, how many); `None` when the place is neither.
    pub(crate) fn bits(&self) -> Option<(Elem, u32, u32)> {
        match (&self.ty, self.window) {
            (_, Some(w)) => Some((w.container, w.shift, w.width)),
            (Type::Elem(c), None) if c.is_integral() => Some((*c, 0, c.size() * 8)),
            _ => None,
        }
    }

    /// Partial access `index` of `width` bits of `base`, whose bits start at bit `shift` of
    /// a `container` ([`Place::bits`]).
    pub(crate) fn partial(
        base: &Place,
        container: Elem,
        shift: u32,
        width: u32,
        index: u32,
    ) -> Place {
        let ty = match width {
            1 => Type::BOOL,
            8 => Type::Elem(Elem::Byte),
            16 => Type::Elem(Elem::Word),
            32 => Type::Elem(Elem::DWord),
            _ => Type::Elem(Elem::LWord),
        };
        Place {
            loc: base.loc,
            ty,
            writable: base.writable,
            window: Some(Window {
                shift: shift + index * width,
                width,
                container,
            }),
        }
    }
}

/// The strides of the dimensions of `arr` (row-major, in bytes) and the offset of the
/// constant indices `consts` (one per dimension; `None` for a computed one, and an index
/// outside its bounds adds nothing: the checker reports it).
pub(crate) fn element_offsets(
    prog: &Program,
    arr: &ArrayType,
    consts: &[Option<i128>],
) -> (Vec<i64>, i64) {
    let elem_stride = prog.stride(&arr.elem) as i64;
    let mut strides = vec![elem_stride; arr.dims.len()];
    for d in (0..arr.dims.len().saturating_sub(1)).rev() {
        let (lo, hi) = arr.dims[d + 1];
        strides[d] = strides[d + 1] * (hi - lo + 1);
    }
    let mut static_offset = 0;
    for ((c, &(lo, hi)), stride) in consts.iter().zip(&arr.dims).zip(&strides) {
        if let Some(v) = *c
            && lo as i128 <= v
            && v <= hi as i128
        {
            static_offset += (v as i64 - lo) * stride;
        }
    }
    (strides, static_offset)
}

impl Gen<'_> {
    /// Emits the access to the place `e` as far as its address (for dynamic places the base
    /// address is pushed; a place reached through a reference is checked here, for the
    /// bytes of its type), as the place checker passed it ([`crate::sema::place::place`]).
    pub(crate) fn place(&mut self, e: &Expr) -> Option<Place> {
        let p = self.place_inner(e)?;
        Some(self.finalize_place(p))
    }

    /// [`Gen::place`] without the final check: a place reached through a reference stays a
    /// reference cell plus an offset (`Loc::Ref`) so that members and elements of it are
    /// checked for their own bytes only.
    fn place_inner(&mut self, e: &Expr) -> Option<Place> {
        let p = match &e.kind {
            ExprKind::Name(n) => self.name_place(n),
            ExprKind::Deref(inner) if matches!(inner.kind, ExprKind::This | ExprKind::Super) => {
                self.this_place(matches!(inner.kind, ExprKind::Super), e.span)
            }
            ExprKind::Deref(inner) => self.deref_place(inner, e.span),
            ExprKind::Member(base, m) => self.member_place(base, m),
            ExprKind::Index(base, idx) => self.index_place(base, idx),
            ExprKind::Bits { base, width, index } => {
                self.partial_place(base, *width, *index, e.span)
            }
            _ => {
                self.missing_record(e.span, "passed an expression that is no variable");
                None
            }
        }?;
        Some(self.auto_deref(p))
    }

    /// `base.m`: the member the checker recorded.
    fn member_place(&mut self, base: &Expr, m: &Ident) -> Option<Place> {
        let bp = self.place_inner(base)?;
        let Some(member) = self.members.of(self.cur, m).cloned() else {
            self.missing_record(m.span, "resolved no member for this name");
            self.drop_place(&bp);
            return None;
        };
        match Place::member(&bp, &member) {
            Some(p) => Some(p),
            None => {
                self.drop_place(&bp);
                self.name_place(m)
            }
        }
    }

    /// The value of each constant index of `idx` (`None` for a computed one).
    pub(crate) fn constant_indices(&self, idx: &[Expr]) -> Vec<Option<i128>> {
        idx.iter()
            .map(|i| match self.const_value(i) {
                Some(ConstVal::Int(v)) => Some(v),
                _ => None,
            })
            .collect()
    }

    /// `base[i, ...]`: an array element, its constant indices folded in.
    fn index_place(&mut self, base: &Expr, idx: &[Expr]) -> Option<Place> {
        let bp = self.place_inner(base)?;
        let Type::Array(arr) = bp.ty.clone() else {
            self.missing_record(base.span, "passed an index of a value that is no array");
            self.drop_place(&bp);
            return None;
        };
        let consts = self.constant_indices(idx);
        let (strides, static_offset) = element_offsets(self.prog, &arr, &consts);
        let computed = consts.iter().any(Option::is_none);
        let place = Place::element(&bp, arr.elem.clone(), static_offset, computed);
        if !computed {
            return Some(place);
        }
        if let Loc::Ref(_) = bp.loc {
            self.index_through_reference(&arr, idx, &consts, &strides);
            return Some(place);
        }
        // A static array (absolute or frame-relative): the first computed index goes
        // through ELEM_ABS/ELEM_REL, which gives the element's address (the constant
        // indices' offset included; the builder fuses it with the load or store);
        // further computed indices, and arrays whose address is on the stack, through
        // INDEX.
        let mut static_base = match bp.loc {
            Loc::Abs(a) => Some(Loc::Abs(a.wrapping_add(static_offset as u32))),
            Loc::Rel(o) => Some(Loc::Rel(o.wrapping_add(static_offset as u32))),
            Loc::Ind(_) | Loc::Ref(_) => None,
        };
        for (d, c) in consts.iter().enumerate() {
            if c.is_some() {
                continue;
            }
            let (lo, hi) = arr.dims[d];
            self.expr(&idx[d], Some(&Type::DINT));
            let stride = strides[d] as u32;
            match static_base.take() {
                Some(Loc::Abs(a)) => self.emit(|b| b.elem_abs(a, lo, hi, stride)),
                Some(Loc::Rel(o)) => self.emit(|b| b.elem_rel(o, lo, hi, stride)),
                _ => self.emit(|b| b.index(lo, hi, stride)),
            }
        }
        Some(place)
    }

    /// `base.N`, `base.%B1`, ...: the bits of an integer or bit-string variable (or of such
    /// a partial access).
    fn partial_place(&mut self, base: &Expr, width: u8, index: u32, span: Span) -> Option<Place> {
        let bp = self.place(base)?;
        let Some((container, shift, _)) = bp.bits() else {
            self.missing_record(span, "passed a partial access of a value without bits");
            self.drop_place(&bp);
            return None;
        };
        Some(Place::partial(&bp, container, shift, width as u32, index))
    }

    pub(crate) fn drop_place(&mut self, p: &Place) {
        if matches!(p.loc, Loc::Ind(_) | Loc::Ref(_)) {
            self.op(Opcode::Drop);
        }
    }

    /// The place of the variable named `n`, as the checker recorded it (a VAR_IN_OUT's
    /// address is loaded).
    fn name_place(&mut self, n: &Ident) -> Option<Place> {
        let Some(var) = self.variables.of(self.cur, n).cloned() else {
            self.missing_record(n.span, "resolved no variable for this name");
            return None;
        };
        let place = self.variable_place(&var);
        if let Variable::Frame { var: v, own } = &var
            && v.kind == VarKind::InOut
        {
            match self.own_frame(*own) {
                Some(f) => self.emit(|b| b.ld_abs(MemType::U32, f + v.offset)),
                None => self.emit(|b| b.ld_rel(MemType::U32, v.offset)),
            }
        }
        Some(place)
    }

    /// The static frame a variable of the POU walked lives in: a METHOD's own variables
    /// (`own`) are in its static frame; the instance's are frame-relative (`None`).
    fn own_frame(&self, own: bool) -> Option<u32> {
        if own { self.method_frame() } else { None }
    }

    /// The place of the variable `var` (a VAR_IN_OUT's at the address [`Gen::place`]
    /// loads).
    pub(crate) fn variable_place(&self, var: &Variable) -> Place {
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
                let loc = match (v.kind, self.own_frame(*own)) {
                    (VarKind::InOut, _) => Loc::Ind(0),
                    (_, Some(f)) => Loc::Abs(f + v.offset),
                    (_, None) => Loc::Rel(v.offset),
                };
                Place {
                    loc,
                    ty: v.ty.clone(),
                    writable: v.kind == VarKind::InOut || !v.constant,
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
