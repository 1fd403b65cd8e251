//! Initial values: the constant data image of every variable's declared initial value, as
//! the initial-value checker ([`crate::sema::init`]) passed them.

use super::*;

impl Gen<'_> {
    /// Writes the initial value of a variable of type `ty` at `addr` into the INIT image (a
    /// constant evaluated in the scope of `scope_pou`'s constants, if any).
    pub fn write_init(
        &mut self,
        addr: u32,
        ty: &Type,
        init: Option<&Init>,
        scope_pou: Option<usize>,
    ) {
        if self.prog.beyond_data(addr, ty) {
            return;
        }
        self.ensure_init(addr + self.prog.size_align(ty).0);
        match ty {
            Type::Elem(_) | Type::Subrange(..) | Type::Enum(_) | Type::Exception => {
                let elem = ty.elem().unwrap_or(Elem::DInt);
                let value = match init {
                    Some(Init::Expr(e)) => {
                        let v = match scope_pou {
                            Some(p) => const_eval(self.prog, &self.pou_consts(p), e),
                            None => const_eval(self.prog, &(), e),
                        };
                        let Some(v) = v else {
                            return self.missing_record(
                                e.span,
                                "passed an initial value that is no constant",
                            );
                        };
                        v
                    }
                    Some(_) => return,
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
                _ => String::new(),
            },
            _ => String::new(),
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
                _ => String::new(),
            },
            _ => String::new(),
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
        let values = crate::sema::init::array_init_values(init, count);
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
            _ => Vec::new(),
        };
        for m in &members {
            let v = crate::sema::init::member_init(&fields, m);
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
            _ => Vec::new(),
        };
        if let Some(class) = self.prog.pous[*pi].class {
            // The class id dynamic dispatch reads (see `classes`).
            self.write_bytes(addr, &(class as u32).to_le_bytes());
        }
        let vars = self.prog.pous[*pi].vars.clone();
        for v in &vars {
            if matches!(v.kind, VarKind::External | VarKind::Global | VarKind::InOut) {
                continue;
            }
            let iv = crate::sema::init::member_init(&fields, v);
            self.write_init(addr + v.offset, &v.ty, iv.as_ref(), Some(*pi));
        }
    }

    /// The cell of the constant `v` as a value of type `ty`
    /// ([`crate::sema::init::constant_cell`]; the checker refused one that does not fit).
    pub(crate) fn const_cell(
        &mut self,
        v: &ConstVal,
        ty: &Type,
        elem: Elem,
        span: Span,
    ) -> Option<u64> {
        match crate::sema::init::constant_cell(self.prog, v, ty, elem) {
            Ok(cell) => Some(cell),
            Err(_) => {
                self.missing_record(span, "passed a constant that does not fit its type");
                None
            }
        }
    }
}
