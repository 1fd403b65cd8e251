//! Initial values: the constant data image of every variable's declared initial value.

use super::*;

impl Gen<'_> {
    /// Writes the initial value of a variable of type `ty` at `addr` into the INIT image.
    pub fn write_init(
        &mut self,
        addr: u32,
        ty: &Type,
        init: Option<&Init>,
        scope_pou: Option<usize>,
    ) {
        let size = self.prog.size_align(ty).0;
        if self.prog.data_overflow || addr.saturating_add(size) > crate::sema::MAX_DATA {
            return;
        }
        self.ensure_init(addr + size);
        match ty {
            Type::Elem(_) | Type::Subrange(..) | Type::Enum(_) | Type::Exception => {
                let elem = ty.elem().unwrap_or(Elem::DInt);
                let value = match init {
                    Some(Init::Expr(e)) => {
                        let v = match scope_pou {
                            Some(p) => const_eval(
                                self.prog,
                                &PouConsts {
                                    prog: self.prog,
                                    vars: &self.prog.pous[p].vars,
                                },
                                e,
                            ),
                            None => const_eval(self.prog, &(), e),
                        };
                        match v {
                            Some(v) => v,
                            None => {
                                self.diags.error(
                                    codes::NOT_CONSTANT,
                                    e.span,
                                    "initial value must be a constant expression",
                                );
                                return;
                            }
                        }
                    }
                    Some(other) => {
                        self.diags.error(
                            codes::INITIAL_VALUE_SHAPE,
                            other.span(),
                            format!(
                                "a value of type {} cannot be initialised with an aggregate",
                                self.tname(ty)
                            ),
                        );
                        return;
                    }
                    None => match ty {
                        Type::Subrange(_, lo, _) => ConstVal::Int(*lo as i128),
                        Type::Enum(i) => ConstVal::Int(
                            self.prog.enums[*i].values.first().map_or(0, |v| v.1) as i128,
                        ),
                        _ => return,
                    },
                };
                let span = init.map(|i| i.span()).unwrap_or_default();
                let Some(cell) = self.const_cell(&value, ty, elem, span) else {
                    return;
                };
                let w = elem.size() as usize;
                let bytes = cell.to_le_bytes();
                self.write_bytes(addr, &bytes[..w]);
            }
            Type::WString(_) => self.write_wstring_init(addr, ty, init),
            Type::String(_) => self.write_string_init(addr, ty, init),
            Type::Array(_) => self.write_array_init(addr, ty, init, scope_pou),
            Type::Struct(_) => self.write_struct_init(addr, ty, init),
            Type::Fb(_) => self.write_fb_init(addr, ty, init),
            Type::Ref(_) | Type::Reference(_) | Type::Interface(_) | Type::Null => {
                // A reference starts as NULL (the zeroed cell); nothing else is a constant.
                match init {
                    None
                    | Some(Init::Expr(Expr {
                        kind: ExprKind::Null | ExprKind::Int(0),
                        ..
                    })) => {}
                    Some(other) => {
                        self.diags.error(codes::REFERENCE_INITIAL_VALUE,
                            other.span(),
                            "the initial value of a reference or interface variable must be NULL (assign REF()/ADR() in the program)",
                        );
                    }
                }
            }
            Type::Void | Type::Error => {}
        }
    }

    /// `write_init` of a WSTRING.
    fn write_wstring_init(&mut self, addr: u32, ty: &Type, init: Option<&Init>) {
        let Type::WString(n) = ty else { return };
        let text = match init {
            Some(Init::Expr(e)) => match const_eval(self.prog, &(), e) {
                Some(ConstVal::Str(s)) => s,
                _ => {
                    self.diags.error(
                        codes::STRING_INITIAL_VALUE,
                        e.span,
                        "WSTRING initial value must be a string literal",
                    );
                    String::new()
                }
            },
            Some(other) => {
                self.diags.error(
                    codes::STRING_INITIAL_VALUE,
                    other.span(),
                    "WSTRING initial value must be a string literal",
                );
                String::new()
            }
            None => String::new(),
        };
        let units: Vec<u16> = text.encode_utf16().collect();
        self.write_wide(addr, *n, &units);
    }

    /// `write_init` of a STRING.
    fn write_string_init(&mut self, addr: u32, ty: &Type, init: Option<&Init>) {
        let Type::String(n) = ty else { return };
        let text = match init {
            Some(Init::Expr(e)) => match const_eval(self.prog, &(), e) {
                Some(ConstVal::Str(s)) => s,
                _ => {
                    self.diags.error(
                        codes::STRING_INITIAL_VALUE,
                        e.span,
                        "STRING initial value must be a string literal",
                    );
                    String::new()
                }
            },
            Some(other) => {
                self.diags.error(
                    codes::STRING_INITIAL_VALUE,
                    other.span(),
                    "STRING initial value must be a string literal",
                );
                String::new()
            }
            None => String::new(),
        };
        let len = text.len().min(*n as usize);
        self.write_bytes(addr, &(*n as u16).to_le_bytes());
        self.write_bytes(addr + 2, &(len as u16).to_le_bytes());
        self.write_bytes(addr + 4, &text.as_bytes()[..len]);
    }

    /// `write_init` of an array.
    fn write_array_init(
        &mut self,
        addr: u32,
        ty: &Type,
        init: Option<&Init>,
        scope_pou: Option<usize>,
    ) {
        let Type::Array(a) = ty else { return };
        let stride = self.prog.stride(&a.elem);
        let count = a.len();
        let mut values: Vec<Option<&Init>> = Vec::new();
        match init {
            Some(Init::Array(items, span)) => {
                for it in items {
                    for _ in 0..it.repeat {
                        if values.len() as u64 >= count {
                            break;
                        }
                        values.push(it.value.as_ref());
                    }
                }
                let given: u64 = items.iter().map(|i| i.repeat).sum();
                if given > count {
                    self.diags.error(
                        codes::INITIAL_VALUE_SHAPE,
                        *span,
                        format!("too many initial values: the array has {count} elements"),
                    );
                }
            }
            Some(i @ Init::Expr(_)) if count == 1 => values.push(Some(i)),
            Some(other) => {
                self.diags.error(
                    codes::INITIAL_VALUE_SHAPE,
                    other.span(),
                    "array initial value must be written `[v1, v2, n(v)]`",
                );
            }
            None => {}
        }
        let elem = a.elem.clone();
        for i in 0..count {
            let v = values.get(i as usize).copied().flatten();
            // Default elements still need headers (strings) and FB defaults.
            self.write_init(addr + i as u32 * stride, &elem, v, scope_pou);
        }
    }

    /// `write_init` of a structure.
    fn write_struct_init(&mut self, addr: u32, ty: &Type, init: Option<&Init>) {
        let Type::Struct(si) = ty else { return };
        let members = self.prog.structs[*si].members.clone();
        let fields: Vec<(Ident, Init)> = match init {
            Some(Init::Struct(f, _)) => f.clone(),
            Some(other) => {
                self.diags.error(
                    codes::INITIAL_VALUE_SHAPE,
                    other.span(),
                    "structure initial value must be written `(member := value, ...)`",
                );
                Vec::new()
            }
            None => Vec::new(),
        };
        for (n, _) in &fields {
            if !members.iter().any(|m| m.name == n.name) {
                self.diags.error(
                    codes::INITIAL_VALUE_MEMBER,
                    n.span,
                    format!("`{}` is not a member of {}", n.text, self.tname(ty)),
                );
            }
        }
        for m in &members {
            let given = fields
                .iter()
                .find(|(n, _)| n.name == m.name)
                .map(|(_, i)| i.clone());
            let v = given.or_else(|| m.init.clone());
            self.write_init(addr + m.offset, &m.ty, v.as_ref(), None);
        }
    }

    /// `write_init` of a function block instance.
    fn write_fb_init(&mut self, addr: u32, ty: &Type, init: Option<&Init>) {
        let Type::Fb(pi) = ty else { return };
        if self.prog.pous[*pi].recursive {
            return;
        }
        let fields: Vec<(Ident, Init)> = match init {
            Some(Init::Struct(f, _)) => f.clone(),
            Some(other) => {
                self.diags.error(
                    codes::INITIAL_VALUE_SHAPE,
                    other.span(),
                    "function block initial values must be written `(input := value, ...)`",
                );
                Vec::new()
            }
            None => Vec::new(),
        };
        if let Some(class) = self.prog.pous[*pi].class {
            // The class id dynamic dispatch reads (see `classes`).
            self.write_bytes(addr, &(class as u32).to_le_bytes());
        }
        let vars = self.prog.pous[*pi].vars.clone();
        for (n, _) in &fields {
            if !vars.iter().any(|m| {
                m.name == n.name
                    && matches!(m.kind, VarKind::Input | VarKind::Output | VarKind::Local)
            }) {
                self.diags.error(
                    codes::INITIAL_VALUE_MEMBER,
                    n.span,
                    format!("`{}` is not a variable of {}", n.text, self.tname(ty)),
                );
            }
        }
        for v in &vars {
            if matches!(v.kind, VarKind::External | VarKind::Global | VarKind::InOut) {
                continue;
            }
            let given = fields
                .iter()
                .find(|(n, _)| n.name == v.name)
                .map(|(_, i)| i.clone());
            let iv = given.or_else(|| v.init.clone());
            self.write_init(addr + v.offset, &v.ty, iv.as_ref(), Some(*pi));
        }
    }

    /// Converts a constant to the cell of an elementary type, checking its range.
    pub fn const_cell(&mut self, v: &ConstVal, ty: &Type, elem: Elem, span: Span) -> Option<u64> {
        let bad = |s: &mut Self| {
            let msg = format!("constant does not fit type {}", s.tname(ty));
            s.diags.error(codes::VALUE_OUT_OF_RANGE, span, msg);
            None
        };
        match (v, elem) {
            (ConstVal::Bool(b), Elem::Bool) => Some(*b as u64),
            (ConstVal::Int(i), Elem::Bool) if *i == 0 || *i == 1 => Some(*i as u64),
            (ConstVal::Int(i), e) if e.is_integral() => {
                let (lo, hi) = match ty {
                    Type::Subrange(_, lo, hi) => (*lo as i128, *hi as i128),
                    Type::Enum(_) | Type::Exception => (i32::MIN as i128, i32::MAX as i128),
                    _ => e.int_range(),
                };
                if *i < lo || *i > hi {
                    return bad(self);
                }
                Some(*i as i64 as u64)
            }
            (ConstVal::Int(i), Elem::Real) => Some((*i as f32).to_bits() as u64),
            (ConstVal::Int(i), Elem::LReal) => Some((*i as f64).to_bits()),
            (ConstVal::Real(r), Elem::Real) => Some((*r as f32).to_bits() as u64),
            (ConstVal::Real(r), Elem::LReal) => Some(r.to_bits()),
            (ConstVal::Time(t), e) if e.is_duration() => Some(*t as i64 as u64),
            (ConstVal::Temporal(k, t), e) if implicit_ok(*k, e) => Some(*t as i64 as u64),
            (ConstVal::Int(i), e) if e.is_char() => {
                let (lo, hi) = e.int_range();
                if *i < lo || *i > hi {
                    return bad(self);
                }
                Some(*i as u64)
            }
            (ConstVal::Str(text), e) if e.is_char() => match crate::sema::single_char(text) {
                Some(c) if c <= e.int_range().1 => Some(c as u64),
                _ => bad(self),
            },
            _ => {
                let msg = format!("initial value has the wrong type for {}", self.tname(ty));
                self.diags.error(codes::INITIAL_VALUE_TYPE, span, msg);
                None
            }
        }
    }
}
