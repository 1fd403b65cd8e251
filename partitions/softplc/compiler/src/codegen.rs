//! Code generation: checks statement bodies (types, names, l-values) and emits plc-vm
//! bytecode through [`ImageBuilder`].
//!
//! Every POU gets one POU-table entry with `arg_cells = ret_cells = 0`: parameters are passed
//! through the callee's frame (FB instance or the function's static frame). Expression values
//! are 64-bit cells; aggregates (STRING, arrays, structs) are represented by their address.
//! Hidden temporaries (string results, FOR bounds, CASE selectors) get a static data slot
//! per use site, which is sound because IEC programs are not recursive (checked) and tasks
//! do not preempt each other on the host runner.
//!
//! Code shape, for the interpreter's speed (the builder fuses what follows): an element of a
//! static array is addressed by `ELEM_REL`/`ELEM_ABS` after its index (one instruction with
//! the bounds check, the constant indices folded in); MIN, MAX and LIMIT use `SEL_IF` on the
//! stack; FOR and WHILE loops are rotated (the test after the body, one jump per iteration),
//! a FOR loop with a constant bound compares with the constant; the last IF branch without
//! ELSE falls through.

use crate::codes::{self, Code};
use std::collections::HashMap;

use plc_vm::image::{ImageBuilder, Label, PouId};
use plc_vm::isa::{Builtin, MemType, Opcode, RoundMode, Trap};

use crate::ast::*;
use crate::diagnostics::{Diagnostics, SourceMap, Span};
use crate::sema::{ConstScope, ConstVal, Program, VarDef, const_eval};
use crate::types::*;

/// Where a value lives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Loc {
    /// Absolute data address.
    Abs(u32),
    /// Offset from the frame base.
    Rel(u32),
    /// Address on the operand stack plus an offset.
    Ind(u32),
    /// A reference cell on the operand stack; the place is at its address plus an offset and
    /// is checked against the reference's object (`REF_CHECK`) when the access is known
    /// ([`Gen::place`] turns it into `Ind(0)`).
    Ref(u32),
}

#[derive(Debug, Clone)]
pub(crate) struct Place {
    pub loc: Loc,
    pub ty: Type,
    pub writable: bool,
    /// A partial access (`x.3`, `x.%B1`): the bits of the variable at `loc` this place is.
    pub window: Option<Window>,
}

/// `width` bits starting at bit `shift` of an integer or bit-string variable of type
/// `container`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Window {
    pub shift: u32,
    pub width: u32,
    pub container: Elem,
}

impl Window {
    fn mask(self) -> u64 {
        if self.width >= 64 {
            u64::MAX
        } else {
            (1u64 << self.width) - 1
        }
    }
}

/// The memory type a value of `ty` is loaded and stored with: elementary types by their
/// width, references and interface values as 64-bit cells; `None` for aggregates.
pub(crate) fn scalar_mem(ty: &Type) -> Option<MemType> {
    match ty {
        Type::Ref(_) | Type::Reference(_) | Type::Interface(_) | Type::Null => Some(MemType::U64),
        t => t.elem().map(mem_type),
    }
}

pub(crate) fn mem_type(e: Elem) -> MemType {
    match e {
        Elem::Bool | Elem::USInt | Elem::Byte | Elem::Char => MemType::U8,
        Elem::SInt => MemType::I8,
        Elem::Int => MemType::I16,
        Elem::DInt => MemType::I32,
        Elem::LInt | Elem::Time | Elem::LTime | Elem::Date | Elem::LDate | Elem::Tod => {
            MemType::I64
        }
        Elem::LTod | Elem::Dt | Elem::LDt => MemType::I64,
        Elem::UInt | Elem::Word | Elem::WChar => MemType::U16,
        Elem::UDInt | Elem::DWord => MemType::U32,
        Elem::ULInt | Elem::LWord => MemType::U64,
        Elem::Real => MemType::F32,
        Elem::LReal => MemType::F64,
    }
}

struct LoopCtx {
    exit: Label,
    try_depth: usize,
}

pub(crate) struct Gen<'a> {
    pub prog: &'a mut Program,
    pub unit: &'a Unit,
    pub sources: &'a SourceMap,
    pub b: ImageBuilder,
    pub diags: &'a mut Diagnostics,
    pub pou_ids: Vec<PouId>,
    /// Initial data memory image.
    pub init: Vec<u8>,
    /// Image file index of each source file.
    pub file_ids: Vec<u16>,
    /// POU whose body is being compiled.
    pub cur: usize,
    loops: Vec<LoopCtx>,
    try_depth: usize,
    return_label: Option<Label>,
    /// When set, nothing is emitted and no diagnostics are reported (type inference).
    pub dry: bool,
    infer_cache: HashMap<usize, Type>,
    str_lits: HashMap<String, u32>,
    /// Call graph edges between user POUs (for the recursion check).
    pub calls: Vec<(usize, usize, Span)>,
    /// Static frame address of each FUNCTION and the pristine copy of each POU frame.
    pub frames: Vec<(Option<u32>, Option<u32>)>,
    /// What code generation learns about references (for the object table).
    pub(crate) refs: crate::refs::RefState,
}

/// Constants visible in the POU being compiled.
struct PouConsts<'p> {
    prog: &'p Program,
    vars: &'p [VarDef],
}

impl ConstScope for PouConsts<'_> {
    fn constant(&self, name: &str) -> Option<ConstVal> {
        let v = self.vars.iter().find(|v| v.name == name && v.constant)?;
        match &v.init {
            Some(Init::Expr(e)) => const_eval(self.prog, &(), e),
            _ => None,
        }
    }
}

impl<'a> Gen<'a> {
    pub fn new(
        prog: &'a mut Program,
        unit: &'a Unit,
        sources: &'a SourceMap,
        diags: &'a mut Diagnostics,
    ) -> Gen<'a> {
        let mut b = ImageBuilder::new();
        let file_ids = sources.files.iter().map(|f| b.add_file(&f.name)).collect();
        Gen {
            prog,
            unit,
            sources,
            b,
            diags,
            pou_ids: Vec::new(),
            init: Vec::new(),
            file_ids,
            cur: 0,
            loops: Vec::new(),
            try_depth: 0,
            return_label: None,
            dry: false,
            infer_cache: HashMap::new(),
            str_lits: HashMap::new(),
            calls: Vec::new(),
            frames: Vec::new(),
            refs: Default::default(),
        }
    }

    // ----- small helpers -------------------------------------------------------------

    pub fn error(&mut self, code: Code, span: Span, msg: impl Into<String>) {
        if !self.dry {
            self.diags.error(code, span, msg);
        }
    }

    pub fn emit(&mut self, f: impl FnOnce(&mut ImageBuilder)) {
        if !self.dry {
            f(&mut self.b);
        }
    }

    pub fn op(&mut self, op: Opcode) {
        self.emit(|b| b.op(op));
    }

    pub fn label(&mut self) -> Label {
        self.b.new_label()
    }

    pub fn bind(&mut self, l: Label) {
        self.emit(|b| b.bind(l));
    }

    pub fn tname(&self, t: &Type) -> String {
        self.prog.type_name(t)
    }

    /// Allocates zero-initialised static data; nothing in dry mode.
    pub fn alloc_static(&mut self, size: u32, align: u32) -> u32 {
        if self.dry {
            return 0;
        }
        let a = self.prog.alloc(size, align);
        self.ensure_init(self.prog.data_size);
        a
    }

    fn ensure_init(&mut self, len: u32) {
        if self.init.len() < len as usize {
            self.init.resize(len as usize, 0);
        }
    }

    pub fn temp_cell(&mut self) -> u32 {
        self.alloc_static(8, 8)
    }

    /// A static STRING[len] temporary with its header initialised.
    pub fn temp_string(&mut self, len: u32) -> u32 {
        if self.dry {
            return 0;
        }
        let a = self.alloc_static(4 + len, 2);
        self.write_bytes(a, &(len as u16).to_le_bytes());
        a
    }

    /// A static WSTRING[len] temporary with its header initialised.
    pub fn temp_wstring(&mut self, len: u32) -> u32 {
        if self.dry {
            return 0;
        }
        let a = self.alloc_static(4 + 2 * len, 2);
        self.write_bytes(a, &(len as u16).to_le_bytes());
        a
    }

    /// A temporary of a string type's kind (STRING or WSTRING) and length.
    pub fn temp_string_like(&mut self, ty: &Type) -> u32 {
        match ty {
            Type::WString(n) => self.temp_wstring(*n),
            Type::String(n) => self.temp_string(*n),
            _ => self.temp_string(DEFAULT_STRING_LEN),
        }
    }

    /// A WSTRING constant in static data (shared by equal literals).
    fn wstring_literal(&mut self, s: &str) -> u32 {
        if self.dry {
            return 0;
        }
        let key = format!("\u{0}W{s}");
        if let Some(&a) = self.str_lits.get(&key) {
            return a;
        }
        let units: Vec<u16> = s.encode_utf16().take(32000).collect();
        let len = units.len() as u32;
        let a = self.alloc_static(4 + 2 * len.max(1), 2);
        self.write_wide(a, len, &units);
        self.str_lits.insert(key, a);
        a
    }

    /// Writes a WSTRING of capacity `max` holding `units` into the INIT image.
    fn write_wide(&mut self, addr: u32, max: u32, units: &[u16]) {
        let len = units.len().min(max as usize);
        self.write_bytes(addr, &(max as u16).to_le_bytes());
        self.write_bytes(addr + 2, &(len as u16).to_le_bytes());
        let bytes: Vec<u8> = units[..len].iter().flat_map(|u| u.to_le_bytes()).collect();
        self.write_bytes(addr + 4, &bytes);
    }

    pub fn write_bytes(&mut self, addr: u32, bytes: &[u8]) {
        self.ensure_init(addr + bytes.len() as u32);
        self.init[addr as usize..addr as usize + bytes.len()].copy_from_slice(bytes);
    }

    fn string_literal(&mut self, s: &str) -> u32 {
        if self.dry {
            return 0;
        }
        if let Some(&a) = self.str_lits.get(s) {
            return a;
        }
        let bytes = s.as_bytes();
        let len = bytes.len().min(65000) as u32;
        let a = self.alloc_static(4 + len.max(1), 2);
        self.write_bytes(a, &(len as u16).to_le_bytes());
        self.write_bytes(a + 2, &(len as u16).to_le_bytes());
        self.write_bytes(a + 4, &bytes[..len as usize]);
        self.str_lits.insert(s.to_string(), a);
        a
    }

    pub fn push_int(&mut self, v: i64) {
        self.emit(|b| b.push_int(v));
    }

    fn set_location(&mut self, span: Span) {
        if self.dry {
            return;
        }
        let file = self.sources.file(span.file);
        let (line, col) = file.line_col(span.start as usize);
        let fid = self.file_ids[span.file as usize];
        self.b.source_location(fid, line as u32, col as u32);
    }

    fn consts(&self) -> PouConsts<'_> {
        PouConsts {
            prog: self.prog,
            vars: &self.prog.pous[self.cur].vars,
        }
    }

    pub fn const_value(&self, e: &Expr) -> Option<ConstVal> {
        const_eval(self.prog, &self.consts(), e)
    }

    // ----- initial values ------------------------------------------------------------

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
            Type::WString(n) => {
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
            Type::String(n) => {
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
            Type::Array(a) => {
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
            Type::Struct(si) => {
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
            Type::Fb(pi) => {
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

    // ----- POUs ----------------------------------------------------------------------

    /// Declares all POUs, lays out static data and emits every body.
    pub fn generate(&mut self) {
        for i in 0..self.prog.pous.len() {
            let p = &self.prog.pous[i];
            // Methods and actions run on their owner's instance.
            let vm_frame = match &p.member {
                Some(m) => self.prog.pous[m.owner].frame_size,
                None => p.frame_size,
            };
            let id = self.b.declare_pou(&p.text, 0, 0, vm_frame);
            self.pou_ids.push(id);
        }
        // Static storage: globals and program instances are already allocated by sema.
        self.ensure_init(self.prog.data_size);
        let globals = self.prog.globals.clone();
        for g in &globals {
            self.write_init(g.offset, &g.ty, g.init.as_ref(), None);
        }
        for inst in self.prog.instances.clone() {
            self.write_init(inst.addr, &Type::Fb(inst.pou), None, None);
        }
        // Function frames and pristine copies used to re-initialise locals on each call.
        let mut frames = Vec::new();
        for i in 0..self.prog.pous.len() {
            let p = &self.prog.pous[i];
            let size = p.frame_size;
            let needs_pristine = p.reinit_start < size || p.kind == PouKind::Function;
            let frame = if p.kind == PouKind::Function {
                Some(self.alloc_static(size.max(8), 8))
            } else {
                None
            };
            let pristine = if needs_pristine {
                Some(self.alloc_static(size, 8))
            } else {
                None
            };
            for addr in [frame, pristine].into_iter().flatten() {
                self.write_init(addr, &Type::Fb(i), None, None);
            }
            frames.push((frame, pristine));
        }
        self.frames = frames;
        for i in 0..self.prog.pous.len() {
            let pristine = self.frames[i]
                .1
                .filter(|_| self.prog.pous[i].reinit_start < self.prog.pous[i].frame_size);
            self.gen_pou(i, pristine);
        }
        self.check_recursion();
        self.build_objects();
        self.build_classes();
    }

    /// The static frames (of FUNCTIONs) with their POUs: `(POU, frame address)`.
    pub(crate) fn static_frames(&self) -> Vec<(usize, u32)> {
        self.frames
            .iter()
            .enumerate()
            .filter_map(|(i, f)| f.0.map(|a| (i, a)))
            .collect()
    }

    fn gen_pou(&mut self, i: usize, pristine: Option<u32>) {
        self.cur = i;
        self.loops.clear();
        self.try_depth = 0;
        let id = self.pou_ids[i];
        self.b.begin_pou(id);
        let source = crate::classes::pou_source(self.unit, &self.prog.pous[i]);
        self.set_location(source.name.span);
        if let Some(pr) = pristine {
            let start = self.prog.pous[i].reinit_start;
            let len = self.prog.pous[i].frame_size - start;
            match self.method_frame() {
                // A method's variables are in its static frame, not in the instance.
                Some(frame) => self.emit(|b| {
                    b.push_u32(frame + start);
                    b.push_u32(pr + start);
                    b.copy(len);
                }),
                None => self.emit(|b| {
                    b.lea_rel(start);
                    b.push_u32(pr + start);
                    b.copy(len);
                }),
            }
        }
        let ret = self.label();
        self.return_label = Some(ret);
        let body = source.body;
        self.scan_byte_views(body);
        self.scan_temporary_references(body);
        self.stmts(body);
        self.bind(ret);
        self.sync_byte_views_on_return();
        self.emit(|b| b.ret());
        self.b.end_pou(id);
    }

    fn check_recursion(&mut self) {
        let n = self.prog.pous.len();
        let mut adj = vec![Vec::new(); n];
        for &(a, b, span) in &self.calls {
            adj[a].push((b, span));
        }
        // Depth-first search for a cycle; report the call that closes it.
        let mut state = vec![0u8; n];
        fn dfs(
            v: usize,
            adj: &[Vec<(usize, Span)>],
            state: &mut [u8],
            found: &mut Option<(usize, Span)>,
        ) {
            state[v] = 1;
            for &(w, span) in &adj[v] {
                if found.is_some() {
                    return;
                }
                if state[w] == 1 {
                    *found = Some((w, span));
                    return;
                }
                if state[w] == 0 {
                    dfs(w, adj, state, found);
                }
            }
            state[v] = 2;
        }
        for v in 0..n {
            if state[v] == 0 {
                let mut found = None;
                dfs(v, &adj, &mut state, &mut found);
                if let Some((w, span)) = found {
                    let name = self.prog.pous[w].text.clone();
                    self.diags.error(
                        codes::RECURSION,
                        span,
                        format!("recursive call of `{name}` (IEC 61131-3 forbids recursion)"),
                    );
                    return;
                }
            }
        }
    }

    // ----- statements ----------------------------------------------------------------

    fn stmts(&mut self, list: &[Stmt]) {
        for s in list {
            self.stmt(s);
        }
    }

    fn stmt(&mut self, s: &Stmt) {
        self.set_location(s.span);
        match &s.kind {
            StmtKind::Empty => {}
            StmtKind::Assign { target, value } => self.assign(target, value),
            StmtKind::RefAssign { target, value } => self.ref_assign(target, value),
            StmtKind::Call(e) => {
                let t = self.expr(e, None);
                if !matches!(t, Type::Void | Type::Error) {
                    self.op(Opcode::Drop);
                }
            }
            StmtKind::If {
                branches,
                else_body,
            } => {
                let end = self.label();
                for (k, (cond, body)) in branches.iter().enumerate() {
                    let next = self.label();
                    self.condition(cond);
                    self.emit(|b| b.jz(next));
                    self.stmts(body);
                    // The last branch without ELSE falls through to the end.
                    if k + 1 < branches.len() || else_body.is_some() {
                        self.emit(|b| b.jmp(end));
                    }
                    self.bind(next);
                }
                if let Some(b) = else_body {
                    self.stmts(b);
                }
                self.bind(end);
            }
            StmtKind::Case {
                selector,
                arms,
                else_body,
            } => self.case(selector, arms, else_body.as_deref()),
            StmtKind::For {
                var,
                from,
                to,
                by,
                body,
            } => self.for_loop(var, from, to, by.as_ref(), body),
            StmtKind::While { cond, body } => {
                // Rotated: the condition is tested after the body (one jump per iteration).
                let top = self.label();
                let test = self.label();
                let exit = self.label();
                self.emit(|b| b.jmp(test));
                self.bind(top);
                self.loops.push(LoopCtx {
                    exit,
                    try_depth: self.try_depth,
                });
                self.stmts(body);
                self.loops.pop();
                self.bind(test);
                self.set_location(s.span);
                self.condition(cond);
                self.emit(|b| b.jnz(top));
                self.bind(exit);
            }
            StmtKind::Repeat { body, until } => {
                let top = self.label();
                let exit = self.label();
                self.bind(top);
                self.loops.push(LoopCtx {
                    exit,
                    try_depth: self.try_depth,
                });
                self.stmts(body);
                self.loops.pop();
                self.set_location(until.span);
                self.condition(until);
                self.emit(|b| b.jz(top));
                self.bind(exit);
            }
            StmtKind::Exit => match self.loops.last() {
                Some(l) => {
                    let exit = l.exit;
                    for _ in l.try_depth..self.try_depth {
                        self.emit(|b| b.try_end());
                    }
                    self.emit(|b| b.jmp(exit));
                }
                None => self.error(codes::EXIT_OUTSIDE_LOOP, s.span, "EXIT outside of a loop"),
            },
            StmtKind::Return => {
                for _ in 0..self.try_depth {
                    self.emit(|b| b.try_end());
                }
                if let Some(r) = self.return_label {
                    self.emit(|b| b.jmp(r));
                }
            }
            StmtKind::Try {
                body,
                catch_var,
                catch_body,
                finally_body,
            } => self.try_stmt(body, catch_var.as_ref(), catch_body, finally_body),
        }
    }

    fn try_stmt(
        &mut self,
        body: &[Stmt],
        catch_var: Option<&Ident>,
        catch_body: &[Stmt],
        finally_body: &[Stmt],
    ) {
        let has_catch = catch_var.is_some() || !catch_body.is_empty();
        let handler = self.label();
        let finally = self.label();
        let pending = self.temp_cell();
        self.emit(|b| b.try_begin(handler));
        self.try_depth += 1;
        self.stmts(body);
        self.try_depth -= 1;
        self.emit(|b| {
            b.try_end();
            b.push_i32(0);
            b.jmp(finally);
            b.bind(handler);
        });
        // The trap code is on the stack here.
        if has_catch {
            match catch_var {
                Some(v) => {
                    let e = Expr {
                        kind: ExprKind::Name(v.clone()),
                        span: v.span,
                    };
                    match self.place(&e) {
                        Some(p)
                            if matches!(p.ty, Type::Exception)
                                || p.ty.elem().is_some_and(|e| e.is_integral()) =>
                        {
                            self.store_top(&p)
                        }
                        Some(p) => {
                            let msg = format!(
                                "exception variable must be declared `: __EXCEPTION`, not {}",
                                self.tname(&p.ty)
                            );
                            self.error(codes::EXCEPTION_VARIABLE, v.span, msg);
                            self.op(Opcode::Drop);
                        }
                        None => self.op(Opcode::Drop),
                    }
                }
                None => self.op(Opcode::Drop),
            }
            self.stmts(catch_body);
            self.emit(|b| b.push_i32(0));
        }
        self.bind(finally);
        self.emit(|b| b.st_abs(MemType::I64, pending));
        self.stmts(finally_body);
        if !has_catch {
            // No handler: the trap continues to the next enclosing __TRY (or ends the cycle).
            self.emit(|b| {
                b.ld_abs(MemType::I64, pending);
                b.rethrow();
            });
        }
    }

    /// Stores the top of stack into a place whose address part (if any) is below it...
    /// only valid for static places (`Abs`/`Rel`).
    fn store_top(&mut self, p: &Place) {
        if p.window.is_some() {
            self.store_checked(p);
            return;
        }
        let Some(mt) = scalar_mem(&p.ty) else { return };
        match p.loc {
            Loc::Abs(a) => self.emit(|b| b.st_abs(mt, a)),
            Loc::Rel(o) => self.emit(|b| b.st_rel(mt, o)),
            Loc::Ind(_) | Loc::Ref(_) => {
                // The address was pushed before the value; not used for catch variables.
                self.op(Opcode::Drop);
                self.op(Opcode::Drop);
            }
        }
    }

    fn condition(&mut self, e: &Expr) {
        let t = self.expr(e, Some(&Type::BOOL));
        if !t.is_error() && t != Type::BOOL {
            let msg = format!("condition must be BOOL, found {}", self.tname(&t));
            self.error(codes::TYPE_MISMATCH, e.span, msg);
        }
    }

    fn case(&mut self, selector: &Expr, arms: &[CaseArm], else_body: Option<&[Stmt]>) {
        let st = self.expr(selector, None);
        let ok = matches!(st, Type::Enum(_) | Type::Exception | Type::Error)
            || st.elem().is_some_and(|e| e.is_integral());
        if !ok {
            let msg = format!(
                "CASE selector must be an integer or enumeration, found {}",
                self.tname(&st)
            );
            self.error(codes::CASE_SELECTOR, selector.span, msg);
        }
        let signed = st
            .elem()
            .is_none_or(|e| e.signed_storage() || !e.is_integral() || e.size() < 8);
        let end = self.label();
        let mut arm_labels = Vec::new();
        let mut seen: Vec<(i128, i128, Span)> = Vec::new();
        for arm in arms {
            let l = self.label();
            arm_labels.push(l);
            for lab in &arm.labels {
                let (lo_e, hi_e) = match lab {
                    CaseLabel::Value(v) => (v, v),
                    CaseLabel::Range(a, b) => (a, b),
                };
                let lo = self.case_label_value(lo_e, &st);
                let hi = self.case_label_value(hi_e, &st);
                let (Some(lo), Some(hi)) = (lo, hi) else {
                    continue;
                };
                if lo > hi {
                    self.error(
                        codes::CASE_LABEL,
                        lo_e.span.to(hi_e.span),
                        "empty CASE range (lower bound exceeds upper bound)",
                    );
                }
                if let Some(prev) = seen.iter().find(|(a, b, _)| lo <= *b && *a <= hi) {
                    let _ = prev;
                    self.error(
                        codes::CASE_LABEL,
                        lo_e.span,
                        "CASE label overlaps an earlier label",
                    );
                }
                seen.push((lo, hi, lo_e.span));
                if lo == hi {
                    self.emit(|b| {
                        b.dup();
                        b.push_int(lo as i64);
                        b.op(Opcode::Eq);
                        b.jnz(l);
                    });
                } else {
                    let (ge, le) = if signed {
                        (Opcode::GeS, Opcode::LeS)
                    } else {
                        (Opcode::GeU, Opcode::LeU)
                    };
                    self.emit(|b| {
                        b.dup();
                        b.push_int(lo as i64);
                        b.op(ge);
                        b.over();
                        b.push_int(hi as i64);
                        b.op(le);
                        b.op(Opcode::And);
                        b.jnz(l);
                    });
                }
            }
        }
        self.op(Opcode::Drop);
        if let Some(e) = else_body {
            self.stmts(e);
        }
        self.emit(|b| b.jmp(end));
        for (arm, l) in arms.iter().zip(arm_labels) {
            self.bind(l);
            self.op(Opcode::Drop);
            self.stmts(&arm.body);
            self.emit(|b| b.jmp(end));
        }
        self.bind(end);
    }

    fn case_label_value(&mut self, e: &Expr, sel: &Type) -> Option<i128> {
        // Enumeration labels may be bare value names of the selector's enumeration.
        if let (Type::Enum(ei), ExprKind::Name(n)) = (sel, &e.kind)
            && let Some((_, v)) = self.prog.enums[*ei]
                .values
                .iter()
                .find(|(vn, _)| *vn == n.name)
        {
            return Some(*v as i128);
        }
        if let (Type::Exception, ExprKind::Name(n)) = (sel, &e.kind)
            && let Some(t) = Trap::ALL.iter().find(|t| t.name() == n.name)
        {
            return Some(t.code() as i128);
        }
        match self.const_value(e) {
            Some(ConstVal::Int(v)) => Some(v),
            _ => {
                self.error(
                    codes::CASE_LABEL,
                    e.span,
                    "CASE label must be a constant integer or enumeration value",
                );
                None
            }
        }
    }

    fn for_loop(&mut self, var: &Ident, from: &Expr, to: &Expr, by: Option<&Expr>, body: &[Stmt]) {
        let ve = Expr {
            kind: ExprKind::Name(var.clone()),
            span: var.span,
        };
        let Some(vp) = self.place(&ve) else { return };
        let Some(elem) = vp
            .ty
            .elem()
            .filter(|e| e.is_integral() && !matches!(vp.ty, Type::Enum(_)))
        else {
            let msg = format!(
                "FOR control variable must be an integer, found {}",
                self.tname(&vp.ty)
            );
            self.error(codes::FOR_VARIABLE, var.span, msg);
            return;
        };
        if !matches!(vp.loc, Loc::Abs(_) | Loc::Rel(_)) || vp.window.is_some() {
            self.error(
                codes::FOR_VARIABLE,
                var.span,
                "FOR control variable must be a plain variable",
            );
            return;
        }
        let vty = vp.ty.clone();
        // i := from
        self.value_to(from, &vty);
        self.store_checked(&vp);
        let step_const = match by {
            None => Some(1i128),
            Some(e) => match self.const_value(e) {
                Some(ConstVal::Int(v)) => Some(v),
                _ => None,
            },
        };
        if step_const == Some(0) {
            self.error(
                codes::FOR_STEP_ZERO,
                by.map_or(var.span, |e| e.span),
                "FOR step must not be zero",
            );
        }
        // The end value is evaluated once into a hidden temporary; the loop tests compare
        // with the constant instead when `to` is one that fits the control variable's type.
        let end_const = match self.const_value(to) {
            Some(ConstVal::Int(v)) if type_holds(elem, v) && i32::try_from(v).is_ok() => {
                Some(v as i64)
            }
            _ => None,
        };
        let end_slot = self.temp_cell();
        self.value_to(to, &vty);
        self.emit(|b| b.st_abs(MemType::I64, end_slot));
        let step_slot = self.temp_cell();
        if step_const.is_none() {
            if let Some(e) = by {
                self.value_to(e, &vty);
            }
            self.emit(|b| b.st_abs(MemType::I64, step_slot));
        }
        let signed = elem.signed_storage() || elem.size() < 8;
        let (le, ge) = if signed {
            (Opcode::LeS, Opcode::GeS)
        } else {
            (Opcode::LeU, Opcode::GeU)
        };
        let top = self.label();
        let exit = self.label();
        let mt = mem_type(elem);
        let load_var = |g: &mut Self| match vp.loc {
            Loc::Abs(a) => g.emit(|b| b.ld_abs(mt, a)),
            Loc::Rel(o) => g.emit(|b| b.ld_rel(mt, o)),
            Loc::Ind(_) | Loc::Ref(_) => {}
        };
        let load_end = |g: &mut Self| match end_const {
            Some(v) => g.push_int(v),
            None => g.emit(|b| b.ld_abs(MemType::I64, end_slot)),
        };
        // The loop test `i <= end` (`>=` for a negative step; both, chosen by the step's sign,
        // for a computed step): jumps to `target` when it holds (`when`) or when it does not.
        let test = |g: &mut Self, when: bool, target: Label| match step_const {
            Some(s) => {
                load_var(g);
                load_end(g);
                g.op(if s > 0 { le } else { ge });
                g.emit(|b| if when { b.jnz(target) } else { b.jz(target) });
            }
            None => {
                let neg = g.label();
                let done = g.label();
                g.emit(|b| {
                    b.ld_abs(MemType::I64, step_slot);
                    b.push_i32(0);
                    b.op(Opcode::LtS);
                    b.jnz(neg);
                });
                load_var(g);
                load_end(g);
                g.op(le);
                g.emit(|b| {
                    if when {
                        b.jnz(target);
                    } else {
                        b.jz(target);
                    }
                    b.jmp(done);
                    b.bind(neg);
                });
                load_var(g);
                load_end(g);
                g.op(ge);
                g.emit(|b| {
                    if when {
                        b.jnz(target);
                    } else {
                        b.jz(target);
                    }
                    b.bind(done);
                });
            }
        };
        // Rotated: tested once before the first iteration, then after each increment (one
        // jump per iteration).
        test(self, false, exit);
        self.bind(top);
        self.loops.push(LoopCtx {
            exit,
            try_depth: self.try_depth,
        });
        self.stmts(body);
        self.loops.pop();
        load_var(self);
        match step_const {
            Some(s) => self.push_int(s as i64),
            None => self.emit(|b| b.ld_abs(MemType::I64, step_slot)),
        }
        self.op(Opcode::Add);
        self.wrap(elem);
        match vp.loc {
            Loc::Abs(a) => self.emit(|b| b.st_abs(mt, a)),
            Loc::Rel(o) => self.emit(|b| b.st_rel(mt, o)),
            Loc::Ind(_) | Loc::Ref(_) => {}
        }
        test(self, true, top);
        self.bind(exit);
    }

    fn assign(&mut self, target: &Expr, value: &Expr) {
        if self.property_write(target, value) {
            return;
        }
        let Some(p) = self.place(target) else {
            // Still check the value for errors.
            self.infer(value);
            return;
        };
        if !p.writable {
            self.error(
                codes::ASSIGN_TO_READ_ONLY,
                target.span,
                "cannot assign to a constant or an input of another POU",
            );
        }
        if p.ty.is_pointer_like() {
            self.check_escape(Some(target), value, "this variable");
        }
        self.store_expr(&p, value, target.span);
    }

    /// `r REF= x`: binds the `REFERENCE TO` variable `r` to `x` (or to NULL).
    fn ref_assign(&mut self, target: &Expr, value: &Expr) {
        let saved = std::mem::replace(&mut self.refs.keep_reference, true);
        let p = self.place(target);
        self.refs.keep_reference = saved;
        let Some(p) = p else {
            self.infer(value);
            return;
        };
        let Type::Reference(t) = p.ty.clone() else {
            if !p.ty.is_error() {
                let msg = format!(
                    "`REF=` binds a REFERENCE TO variable, not {}",
                    self.tname(&p.ty)
                );
                self.error(codes::REF_ASSIGN_TARGET, target.span, msg);
            }
            self.drop_place_value(&p);
            self.infer(value);
            return;
        };
        let cell = Place {
            ty: Type::Ref(t.clone()),
            ..p
        };
        match &value.kind {
            ExprKind::Null | ExprKind::Int(0) => self.push_int(0),
            _ => {
                let args = [Arg {
                    name: None,
                    output: false,
                    value: value.clone(),
                    span: value.span,
                }];
                let id = Ident {
                    name: "REF".into(),
                    text: "REF".into(),
                    span: value.span,
                };
                let as_ref = Expr {
                    kind: ExprKind::Call {
                        callee: Box::new(Expr {
                            kind: ExprKind::Name(id.clone()),
                            span: value.span,
                        }),
                        args: args.to_vec(),
                    },
                    span: value.span,
                };
                self.check_escape(Some(target), &as_ref, "this variable");
                let rt = self.ref_function(&id, &args, Some(&Type::Ref(t.clone())), value.span);
                self.coerce(&rt, &Type::Ref(t), value.span);
            }
        }
        self.store_checked(&cell);
    }

    fn drop_place_value(&mut self, p: &Place) {
        if matches!(p.loc, Loc::Ind(_) | Loc::Ref(_)) {
            self.op(Opcode::Drop);
        }
    }

    /// Evaluates `value` and stores it into `p` (whose address, for `Ind`, is already on the stack).
    pub(crate) fn store_expr(&mut self, p: &Place, value: &Expr, span: Span) {
        match &p.ty {
            Type::String(_) | Type::WString(_) => {
                self.addr_of(p);
                let t = self.expr(value, Some(&p.ty));
                let wide = p.ty.is_wstring();
                let text = t.is_string() || t.is_wstring();
                if (t.is_wstring() != wide || !text) && !t.is_error() {
                    let hint = match (wide, text) {
                        (true, true) => " (use STRING_TO_WSTRING)",
                        (false, true) => " (use WSTRING_TO_STRING)",
                        _ => "",
                    };
                    let msg = format!(
                        "cannot assign {} to {}{hint}",
                        self.tname(&t),
                        self.tname(&p.ty)
                    );
                    self.error(codes::ASSIGN_TYPE, value.span, msg);
                }
                self.emit(|b| {
                    b.call_builtin(if wide {
                        Builtin::WStrAssign
                    } else {
                        Builtin::StrAssign
                    })
                });
            }
            Type::Array(_) | Type::Struct(_) | Type::Fb(_) => {
                self.addr_of(p);
                let t = self.expr(value, Some(&p.ty));
                if t != p.ty && !t.is_error() {
                    let msg = format!("cannot assign {} to {}", self.tname(&t), self.tname(&p.ty));
                    self.error(codes::ASSIGN_TYPE, value.span, msg);
                }
                if matches!(p.ty, Type::Fb(_)) {
                    self.error(
                        codes::ASSIGN_FB_INSTANCE,
                        span,
                        "function block instances cannot be assigned",
                    );
                }
                let (size, _) = self.prog.size_align(&p.ty);
                self.emit(|b| b.copy(size));
            }
            Type::Error | Type::Void => {
                if matches!(p.loc, Loc::Ind(_)) {
                    self.op(Opcode::Drop);
                }
                self.infer(value);
            }
            _ => {
                self.value_to(value, &p.ty.clone());
                self.store_checked(p);
            }
        }
    }

    /// Stores the elementary value on top of the stack into `p`, checking subranges.
    pub(crate) fn store_checked(&mut self, p: &Place) {
        if let Some(w) = p.window {
            // Read, modify, write the variable: (old AND NOT m) OR (v << shift).
            let mt = mem_type(w.container);
            let keep = !(w.mask() << w.shift) as i64;
            self.emit(|b| {
                if w.width < 64 {
                    b.push_int(w.mask() as i64);
                    b.op(Opcode::And);
                }
                if w.shift != 0 {
                    b.push_i32(w.shift as i32);
                    b.op(Opcode::Shl);
                }
            });
            match p.loc {
                Loc::Abs(a) => self.emit(|b| {
                    b.ld_abs(mt, a);
                    b.push_int(keep);
                    b.op(Opcode::And);
                    b.op(Opcode::Or);
                    b.st_abs(mt, a);
                }),
                Loc::Rel(o) => self.emit(|b| {
                    b.ld_rel(mt, o);
                    b.push_int(keep);
                    b.op(Opcode::And);
                    b.op(Opcode::Or);
                    b.st_rel(mt, o);
                }),
                Loc::Ind(o) => self.emit(|b| {
                    b.over();
                    b.ld_ind(mt, o);
                    b.push_int(keep);
                    b.op(Opcode::And);
                    b.op(Opcode::Or);
                    b.st_ind(mt, o);
                }),
                Loc::Ref(_) => unreachable!("places are finalized"),
            }
            return;
        }
        if let Type::Subrange(e, lo, hi) = p.ty {
            if e.signed_storage() || e.size() < 8 {
                self.emit(|b| b.chk_range_s(lo, hi));
            } else {
                self.emit(|b| b.chk_range_u(lo as u64, hi as u64));
            }
        }
        let Some(mt) = scalar_mem(&p.ty) else { return };
        match p.loc {
            Loc::Abs(a) => self.emit(|b| b.st_abs(mt, a)),
            Loc::Rel(o) => self.emit(|b| b.st_rel(mt, o)),
            Loc::Ind(o) => self.emit(|b| b.st_ind(mt, o)),
            Loc::Ref(_) => unreachable!("places are finalized"),
        }
    }

    // ----- places --------------------------------------------------------------------

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

    fn place_unaliased(&mut self, e: &Expr) -> Option<Place> {
        match &e.kind {
            ExprKind::Name(n) => self.name_place(n),
            ExprKind::Deref(inner) if matches!(inner.kind, ExprKind::This | ExprKind::Super) => {
                self.this_place(matches!(inner.kind, ExprKind::Super), e.span)
            }
            ExprKind::Deref(inner) => self.deref_place(inner, e.span),
            ExprKind::Member(base, m) => {
                let bp = self.place_inner(base)?;
                match &bp.ty {
                    Type::Struct(si) => {
                        let Some(mem) = self.prog.structs[*si]
                            .members
                            .iter()
                            .find(|x| x.name == m.name)
                            .cloned()
                        else {
                            let msg = format!("{} has no member `{}`", self.tname(&bp.ty), m.text);
                            self.error(codes::NO_SUCH_MEMBER, m.span, msg);
                            self.drop_place(&bp);
                            return None;
                        };
                        Some(Place {
                            loc: offset_loc(bp.loc, mem.offset),
                            ty: mem.ty,
                            writable: bp.writable,
                            window: None,
                        })
                    }
                    Type::Fb(pi) => {
                        let pi = *pi;
                        let v = self.prog.pous[pi].param(&m.name).cloned();
                        // `THIS^.x` / `SUPER^.x`: the block's own variables, all of them.
                        let own = matches!(&base.kind, ExprKind::Deref(i) if matches!(i.kind, ExprKind::This | ExprKind::Super));
                        match v {
                            Some(v)
                                if own
                                    && !matches!(v.kind, VarKind::External | VarKind::Global) =>
                            {
                                if v.kind == VarKind::InOut {
                                    self.drop_place(&bp);
                                    return self.name_place(m);
                                }
                                Some(Place {
                                    loc: offset_loc(bp.loc, v.offset),
                                    ty: v.ty,
                                    writable: bp.writable && !v.constant,
                                    window: None,
                                })
                            }
                            Some(v) if matches!(v.kind, VarKind::Input | VarKind::Output) => {
                                // Outputs are read-only from outside; inputs may be set before a call.
                                let writable = bp.writable && v.kind == VarKind::Input;
                                Some(Place {
                                    loc: offset_loc(bp.loc, v.offset),
                                    ty: v.ty,
                                    writable,
                                    window: None,
                                })
                            }
                            Some(_) => {
                                let msg = format!(
                                    "`{}` is not an input or output of {}",
                                    m.text, self.prog.pous[pi].text
                                );
                                self.error(codes::NO_SUCH_MEMBER, m.span, msg);
                                self.drop_place(&bp);
                                None
                            }
                            None => {
                                let msg = format!(
                                    "{} has no input or output `{}`",
                                    self.prog.pous[pi].text, m.text
                                );
                                self.error(codes::NO_SUCH_MEMBER, m.span, msg);
                                self.drop_place(&bp);
                                None
                            }
                        }
                    }
                    Type::Error => {
                        self.drop_place(&bp);
                        None
                    }
                    other => {
                        let msg = format!("{} has no members (`.{}`)", self.tname(other), m.text);
                        self.error(codes::NO_SUCH_MEMBER, m.span, msg);
                        self.drop_place(&bp);
                        None
                    }
                }
            }
            ExprKind::Index(base, idx) => {
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
                if idx.len() != arr.dims.len() {
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
                            if *v < lo as i128 || *v > hi as i128 {
                                let msg =
                                    format!("index {v} is outside the array bounds {lo}..{hi}");
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
                    return self
                        .index_through_reference(o, &arr, idx, &consts, &strides, static_off);
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
                    if !t.is_error() && !t.elem().is_some_and(|e| e.is_integral())
                        || matches!(t, Type::Enum(_))
                    {
                        let msg =
                            format!("array index must be an integer, found {}", self.tname(&t));
                        self.error(codes::INDEX_NOT_INTEGER, idx[d].span, msg);
                    }
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
            ExprKind::Bits { base, width, index } => self.partial_place(e, base, *width, *index),
            _ => {
                self.error(codes::EXPECTED_VARIABLE, e.span, "expected a variable");
                None
            }
        }
    }

    /// `base.N`, `base.%B1`, ...: the bits of an integer or bit-string variable (or of such
    /// a partial access).
    fn partial_place(&mut self, e: &Expr, base: &Expr, width: u8, index: u32) -> Option<Place> {
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
        if (index as u64 + 1) * width as u64 > bits as u64 {
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

    fn name_place(&mut self, n: &Ident) -> Option<Place> {
        let pou = &self.prog.pous[self.cur];
        // A method's own variables are in its static frame; the instance's are frame-relative.
        let (v, frame) = match pou.var(&n.name).cloned() {
            Some(v) => (Some(v), self.method_frame()),
            None => (
                self.var_owner(&n.name)
                    .and_then(|o| self.prog.pous[o].var(&n.name).cloned()),
                None,
            ),
        };
        if let Some(v) = v {
            return match v.kind {
                VarKind::External => match self.prog.global(&n.name).cloned() {
                    Some(g) => {
                        if g.ty != v.ty && !v.ty.is_error() && !g.ty.is_error() {
                            let msg = format!(
                                "VAR_EXTERNAL `{}` declared as {} but the global is {}",
                                v.text,
                                self.tname(&v.ty),
                                self.tname(&g.ty)
                            );
                            self.error(codes::VAR_EXTERNAL, v.span, msg);
                        }
                        Some(Place {
                            loc: Loc::Abs(g.offset),
                            ty: g.ty.clone(),
                            writable: !g.constant && !v.constant,
                            window: None,
                        })
                    }
                    None => {
                        let msg = format!("VAR_EXTERNAL `{}` has no matching VAR_GLOBAL", v.text);
                        self.error(codes::VAR_EXTERNAL, n.span, msg);
                        None
                    }
                },
                VarKind::InOut => {
                    match frame {
                        Some(f) => self.emit(|b| b.ld_abs(MemType::U32, f + v.offset)),
                        None => self.emit(|b| b.ld_rel(MemType::U32, v.offset)),
                    }
                    Some(Place {
                        loc: Loc::Ind(0),
                        ty: v.ty,
                        writable: true,
                        window: None,
                    })
                }
                _ => Some(Place {
                    loc: match frame {
                        Some(f) => Loc::Abs(f + v.offset),
                        None => Loc::Rel(v.offset),
                    },
                    ty: v.ty,
                    writable: !v.constant,
                    window: None,
                }),
            };
        }
        if let Some(g) = self.prog.global(&n.name) {
            return Some(Place {
                loc: Loc::Abs(g.offset),
                ty: g.ty.clone(),
                writable: !g.constant,
                window: None,
            });
        }
        let msg = format!("unknown variable `{}`", n.text);
        self.error(codes::UNKNOWN_VARIABLE, n.span, msg);
        None
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

    // ----- expressions ---------------------------------------------------------------

    /// Type of an expression without emitting code or reporting errors (memoised).
    pub(crate) fn infer(&mut self, e: &Expr) -> Type {
        let key = e as *const Expr as usize;
        if let Some(t) = self.infer_cache.get(&key) {
            return t.clone();
        }
        let saved = self.dry;
        self.dry = true;
        let t = self.expr(e, None);
        self.dry = saved;
        self.infer_cache.insert(key, t.clone());
        t
    }

    /// Whether `e` is built only from untyped numeric literals (it adapts to its context).
    pub(crate) fn is_flexible(e: &Expr) -> bool {
        match &e.kind {
            ExprKind::Int(_) | ExprKind::Real(_) => true,
            // TRUNC and SIZEOF give any integer type (IEC: ANY_INT), whatever their argument.
            ExprKind::Call { callee, .. } if matches!(&callee.kind, ExprKind::Name(n) if n.name == "TRUNC" || n.name == "SIZEOF") => {
                true
            }
            // Numeric standard functions of literals are as untyped as the literals.
            ExprKind::Call { callee, args } => match &callee.kind {
                ExprKind::Name(n) => {
                    const GENERIC: &[&str] = &[
                        "ABS", "SQRT", "LN", "LOG", "EXP", "SIN", "COS", "TAN", "ASIN", "ACOS",
                        "ATAN", "EXPT", "MAX", "MIN", "LIMIT",
                    ];
                    GENERIC.contains(&n.name.as_str())
                        && !args.is_empty()
                        && args
                            .iter()
                            .all(|a| !a.output && Self::is_flexible(&a.value))
                }
                _ => false,
            },
            ExprKind::Unary(UnOp::Neg, x) => Self::is_flexible(x),
            ExprKind::Binary(op, a, b)
                if !matches!(
                    op,
                    BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge
                ) =>
            {
                Self::is_flexible(a) && Self::is_flexible(b)
            }
            _ => false,
        }
    }

    pub(crate) fn has_real_literal(e: &Expr) -> bool {
        match &e.kind {
            ExprKind::Real(_) => true,
            ExprKind::Call { callee, .. } if matches!(&callee.kind, ExprKind::Name(n) if n.name == "TRUNC" || n.name == "SIZEOF") => {
                false
            }
            ExprKind::Call { callee, args } => {
                matches!(&callee.kind, ExprKind::Name(n) if !["ABS", "MAX", "MIN", "LIMIT"].contains(&n.name.as_str()))
                    || args.iter().any(|a| Self::has_real_literal(&a.value))
            }
            ExprKind::Unary(_, x) => Self::has_real_literal(x),
            ExprKind::Binary(_, a, b) => Self::has_real_literal(a) || Self::has_real_literal(b),
            _ => false,
        }
    }

    /// Compiles `e` and converts the result to `to` (implicit conversions only).
    pub(crate) fn value_to(&mut self, e: &Expr, to: &Type) {
        if to.is_pointer_like() && matches!(e.kind, ExprKind::Int(0)) {
            // The literal 0 is NULL.
            self.push_int(0);
            return;
        }
        if let Type::Reference(target) = to {
            // A REFERENCE TO parameter is bound to the argument (as `REF=` does).
            let as_ref = Type::Ref(target.clone());
            if matches!(e.kind, ExprKind::Null) {
                self.push_int(0);
                return;
            }
            let r = crate::refs::reference_to(e);
            let t = self.expr(&r, Some(&as_ref));
            self.coerce(&t, &as_ref, e.span);
            return;
        }
        let t = self.expr(e, Some(to));
        self.coerce(&t, to, e.span);
    }

    /// Emits an implicit conversion from `from` to `to`, or reports a type mismatch.
    pub(crate) fn coerce(&mut self, from: &Type, to: &Type, span: Span) {
        if from.is_error() || to.is_error() || from == to {
            return;
        }
        if self.coerce_pointer(from, to, span) {
            return;
        }
        match (from, to) {
            (Type::String(_), Type::String(_)) | (Type::WString(_), Type::WString(_)) => return,
            (Type::Subrange(a, ..), _)
                if to.elem() == Some(*a) && !matches!(to, Type::Enum(_) | Type::Exception) =>
            {
                return;
            }
            _ => {}
        }
        let (Some(f), Some(t)) = (from.elem(), to.elem()) else {
            let msg = format!(
                "type mismatch: expected {}, found {}",
                self.tname(to),
                self.tname(from)
            );
            self.error(codes::TYPE_MISMATCH, span, msg);
            return;
        };
        let enumish = |x: &Type| matches!(x, Type::Enum(_) | Type::Exception);
        if enumish(from) || enumish(to) {
            let msg = format!(
                "type mismatch: expected {}, found {}",
                self.tname(to),
                self.tname(from)
            );
            self.error(codes::TYPE_MISMATCH, span, msg);
            return;
        }
        if !implicit_ok(f, t) {
            let msg = if f.is_numeric() && t.is_numeric() {
                format!(
                    "cannot convert {} to {} implicitly (use {}_TO_{})",
                    f, t, f, t
                )
            } else {
                format!(
                    "type mismatch: expected {}, found {}",
                    self.tname(to),
                    self.tname(from)
                )
            };
            self.error(codes::IMPLICIT_CONVERSION, span, msg);
            return;
        }
        self.convert(f, t);
    }

    /// Emits the conversion of an elementary value (explicit conversions use this too).
    pub(crate) fn convert(&mut self, f: Elem, t: Elem) {
        if f == t {
            return;
        }
        if f.is_temporal() || t.is_temporal() {
            self.convert_temporal(f, t);
            return;
        }
        // Characters convert like the unsigned integers of their size.
        let as_int = |e: Elem| match e {
            Elem::Char => Elem::USInt,
            Elem::WChar => Elem::UInt,
            e => e,
        };
        if f.is_char() || t.is_char() {
            self.convert(as_int(f), as_int(t));
            return;
        }
        match (f.is_real(), t.is_real()) {
            (false, false) => {
                if t == Elem::Bool {
                    self.emit(|b| {
                        b.push_i32(0);
                        b.op(Opcode::Ne);
                    });
                } else if t.size() < f.size() || t.signed_storage() != f.signed_storage() {
                    self.wrap(t);
                }
            }
            (false, true) => {
                let signed = !(f.is_unsigned_int() || f.is_bits() && f.size() == 8);
                let op = match (t, signed) {
                    (Elem::Real, true) => Opcode::IToF32S,
                    (Elem::Real, false) => Opcode::IToF32U,
                    (_, true) => Opcode::IToF64S,
                    (_, false) => Opcode::IToF64U,
                };
                self.op(op);
            }
            (true, true) => self.op(if f == Elem::Real {
                Opcode::F32ToF64
            } else {
                Opcode::F64ToF32
            }),
            (true, false) => {
                let op = if f == Elem::Real {
                    Opcode::F32ToInt
                } else {
                    Opcode::F64ToInt
                };
                if t == Elem::Bool {
                    let zero_op = if f == Elem::Real {
                        Opcode::NeF32
                    } else {
                        Opcode::NeF64
                    };
                    self.emit(|b| {
                        if f == Elem::Real {
                            b.push_f32(0.0)
                        } else {
                            b.push_f64(0.0)
                        }
                        b.op(zero_op);
                    });
                } else {
                    self.emit(|b| b.float_to_int(op, mem_type(t), RoundMode::NearestTiesAway));
                }
            }
        }
    }

    /// Conversions to, from and between the date/time types. All hold nanoseconds; as
    /// numbers (CODESYS's conventions) TIME and TOD count milliseconds, DATE and DT seconds,
    /// the long forms nanoseconds. A DATE result is the midnight of its day, a TOD result
    /// lies within its day.
    fn convert_temporal(&mut self, f: Elem, t: Elem) {
        fn unit(e: Elem) -> i64 {
            match e {
                Elem::Time | Elem::Tod => 1_000_000,
                Elem::Date | Elem::Dt => 1_000_000_000,
                _ => 1,
            }
        }
        if f.is_temporal() && !t.is_temporal() {
            let n = unit(f);
            if t == Elem::Bool {
                self.emit(|b| {
                    b.push_i32(0);
                    b.op(Opcode::Ne);
                });
            } else if t.is_real() {
                self.op(Opcode::IToF64S);
                if n != 1 {
                    self.emit(|b| {
                        b.push_f64(n as f64);
                        b.op(Opcode::DivF64);
                    });
                }
                if t == Elem::Real {
                    self.op(Opcode::F64ToF32);
                }
            } else {
                if n != 1 {
                    self.emit(|b| {
                        b.push_int(n);
                        b.op(Opcode::DivS);
                    });
                }
                let as_int = match t {
                    Elem::Char => Elem::USInt,
                    Elem::WChar => Elem::UInt,
                    e => e,
                };
                self.wrap(as_int);
            }
            return;
        }
        if !f.is_temporal() {
            let n = unit(t);
            if f.is_real() {
                if f == Elem::Real {
                    self.op(Opcode::F32ToF64);
                }
                self.emit(|b| {
                    b.push_f64(n as f64);
                    b.op(Opcode::MulF64);
                    b.float_to_int(Opcode::F64ToInt, MemType::I64, RoundMode::NearestTiesAway);
                });
            } else if n != 1 {
                self.emit(|b| {
                    b.push_int(n);
                    b.op(Opcode::Mul);
                });
            }
        }
        // Into the day: a DATE is a midnight, a TOD a time within its day.
        match t.temporal_family() {
            Some(Elem::Date) if f.temporal_family() != Some(Elem::Date) => {
                self.emit(|b| b.call_builtin(Builtin::DateOf))
            }
            Some(Elem::Tod) if f.temporal_family() != Some(Elem::Tod) => {
                self.emit(|b| b.call_builtin(Builtin::TodOf))
            }
            _ => {}
        }
    }

    /// Wraps the 64-bit cell on top of the stack to the width of `e`.
    pub(crate) fn wrap(&mut self, e: Elem) {
        let w = (e.size() * 8) as u8;
        if e == Elem::Bool {
            self.emit(|b| {
                b.push_i32(1);
                b.op(Opcode::And);
            });
        } else if w < 64 && !e.is_real() {
            let op = if e.is_signed_int() {
                Opcode::Sext
            } else {
                Opcode::Zext
            };
            self.emit(|b| b.op_width(op, w));
        }
    }

    /// Compiles an expression; `expected` guides the typing of untyped literals.
    pub(crate) fn expr(&mut self, e: &Expr, expected: Option<&Type>) -> Type {
        match &e.kind {
            ExprKind::Error => Type::Error,
            ExprKind::Int(v) => self.int_literal(*v as i128, expected, e.span),
            ExprKind::Real(r) => {
                if expected.and_then(|t| t.elem()) == Some(Elem::Real) {
                    let r = *r as f32;
                    self.emit(|b| b.push_f32(r));
                    Type::REAL
                } else {
                    let r = *r;
                    self.emit(|b| b.push_f64(r));
                    Type::LREAL
                }
            }
            ExprKind::Bool(v) => {
                self.push_int(*v as i64);
                Type::BOOL
            }
            ExprKind::Time(t) => {
                self.push_int(*t as i64);
                Type::TIME
            }
            ExprKind::Temporal(elem, t) => {
                self.push_int(*t as i64);
                Type::Elem(*elem)
            }
            // A one-character string literal where a CHAR or WCHAR is expected.
            ExprKind::Str(s)
                if expected
                    .and_then(|t| t.elem())
                    .is_some_and(|e| e.is_char() && !matches!(expected, Some(Type::Enum(_))))
                    && crate::sema::single_char(s).is_some() =>
            {
                let elem = expected.and_then(|t| t.elem()).unwrap_or(Elem::Char);
                let code = crate::sema::single_char(s).unwrap_or(0);
                if code > elem.int_range().1 {
                    let msg = format!("character '{s}' does not fit type {elem}");
                    self.error(codes::VALUE_OUT_OF_RANGE, e.span, msg);
                }
                self.push_int(code as i64);
                Type::Elem(elem)
            }
            ExprKind::WStr(s) => {
                let a = self.wstring_literal(s);
                self.emit(|b| b.push_u32(a));
                Type::WString(s.encode_utf16().count().max(1) as u32)
            }
            // A STRING literal where a WSTRING is expected is that WSTRING.
            ExprKind::Str(s) if matches!(expected, Some(Type::WString(_))) => {
                let a = self.wstring_literal(s);
                self.emit(|b| b.push_u32(a));
                Type::WString(s.encode_utf16().count().max(1) as u32)
            }
            ExprKind::Str(s) => {
                let a = self.string_literal(s);
                self.emit(|b| b.push_u32(a));
                Type::String(s.len().max(1) as u32)
            }
            ExprKind::Typed(ty, inner) => self.typed_literal(ty, inner, e.span),
            ExprKind::Name(n) => {
                // Variables shadow enumeration values.
                let is_var = self.is_visible_var(&n.name);
                if !is_var && let Some(t) = self.property_read(e) {
                    return t;
                }
                if !is_var {
                    if let Some(Type::Enum(ei)) = expected
                        && let Some((_, v)) = self.prog.enums[*ei]
                            .values
                            .iter()
                            .find(|(vn, _)| *vn == n.name)
                    {
                        let v = *v;
                        self.push_int(v);
                        return Type::Enum(*ei);
                    }
                    if let Some((ei, v)) = self.prog.enum_value(&n.name) {
                        self.push_int(v);
                        return Type::Enum(ei);
                    }
                    if let Some(t) = Trap::ALL.iter().find(|t| t.name() == n.name) {
                        self.push_int(t.code() as i64);
                        return Type::Exception;
                    }
                }
                self.sync_if_byte_viewed(e);
                match self.place(e) {
                    Some(p) => {
                        self.load(&p);
                        p.ty
                    }
                    None => Type::Error,
                }
            }
            ExprKind::Null => {
                self.push_int(0);
                Type::Null
            }
            ExprKind::This => self.this_expr(false, e.span),
            ExprKind::Super => self.this_expr(true, e.span),
            ExprKind::Member(..) if let Some(t) = self.property_read(e) => t,
            ExprKind::Member(..)
            | ExprKind::Index(..)
            | ExprKind::Deref(..)
            | ExprKind::Bits { .. } => match self.place(e) {
                Some(p) => {
                    self.load(&p);
                    p.ty
                }
                None => Type::Error,
            },
            ExprKind::Call { callee, args } => self.call(callee, args, expected, e.span),
            ExprKind::Unary(op, x) => self.unary(*op, x, expected, e.span),
            ExprKind::Binary(op, a, b) => self.binary(*op, a, b, expected, e.span),
        }
    }

    pub(crate) fn int_literal(&mut self, v: i128, expected: Option<&Type>, span: Span) -> Type {
        let exp_elem = expected.and_then(|t| match t {
            Type::Enum(_) | Type::Exception => None,
            t => t.elem(),
        });
        match exp_elem {
            // IEC boolean literals include 0 and 1.
            Some(Elem::Bool) if v == 0 || v == 1 => {
                self.push_int(v as i64);
                Type::BOOL
            }
            Some(e) if e.is_real() => {
                if e == Elem::Real {
                    self.emit(|b| b.push_f32(v as f32));
                } else {
                    self.emit(|b| b.push_f64(v as f64));
                }
                Type::Elem(e)
            }
            Some(e) if e.is_integral() => {
                let (lo, hi) = e.int_range();
                if v < lo || v > hi {
                    let msg = format!("constant {v} does not fit type {e}");
                    self.error(codes::VALUE_OUT_OF_RANGE, span, msg);
                    return Type::Error;
                }
                self.push_int(v as i64);
                Type::Elem(e)
            }
            _ => {
                if v > u64::MAX as i128 || v < i64::MIN as i128 {
                    self.error(codes::INTEGER_TOO_LARGE, span, "integer constant too large");
                    return Type::Error;
                }
                self.push_int(v as i64);
                if v >= i32::MIN as i128 && v <= i32::MAX as i128 {
                    Type::DINT
                } else if v <= i64::MAX as i128 {
                    Type::LINT
                } else {
                    Type::Elem(Elem::ULInt)
                }
            }
        }
    }

    fn typed_literal(&mut self, ty: &Ident, inner: &Expr, span: Span) -> Type {
        if let Some(elem) = Elem::from_name(&ty.name) {
            let t = Type::Elem(elem);
            let v = match const_eval(self.prog, &(), inner) {
                Some(v) => v,
                None => {
                    self.error(
                        codes::MALFORMED_LITERAL,
                        inner.span,
                        format!("invalid {} literal", elem),
                    );
                    return Type::Error;
                }
            };
            let v = match (v, elem) {
                (ConstVal::Bool(b), e) if e != Elem::Bool => ConstVal::Int(b as i128),
                (v, _) => v,
            };
            if self.dry {
                return t;
            }
            return match self.const_cell(&v, &t, elem, span) {
                Some(cell) => {
                    self.emit(|b| b.push_i64(cell as i64));
                    t
                }
                None => Type::Error,
            };
        }
        if ty.name == "STRING" {
            return self.expr(inner, None);
        }
        if let (Some((Type::Enum(ei), _)), ExprKind::Name(n)) =
            (self.prog.aliases.get(&ty.name).cloned(), &inner.kind)
        {
            if let Some((_, v)) = self.prog.enums[ei]
                .values
                .iter()
                .find(|(vn, _)| *vn == n.name)
            {
                let v = *v;
                self.push_int(v);
                return Type::Enum(ei);
            }
            let msg = format!("`{}` is not a value of {}", n.text, ty.text);
            self.error(codes::UNKNOWN_ENUMERATION_VALUE, n.span, msg);
            return Type::Error;
        }
        self.error(
            codes::UNKNOWN_TYPE,
            ty.span,
            format!("unknown type `{}` in typed literal", ty.text),
        );
        Type::Error
    }

    fn unary(&mut self, op: UnOp, x: &Expr, expected: Option<&Type>, span: Span) -> Type {
        // Negative literals are folded so that e.g. INT's -32768 is accepted.
        if op == UnOp::Neg {
            if let ExprKind::Int(v) = x.kind {
                return self.int_literal(-(v as i128), expected, span);
            }
            if let ExprKind::Real(_) = x.kind {
                let t = self.expr(x, expected);
                self.op(if t == Type::REAL {
                    Opcode::NegF32
                } else {
                    Opcode::NegF64
                });
                return t;
            }
        }
        let t = self.expr(x, expected);
        let Some(e) = t
            .elem()
            .filter(|_| !matches!(t, Type::Enum(_) | Type::Exception))
        else {
            if !t.is_error() {
                let msg = format!(
                    "operator {} cannot be applied to {}",
                    if op == UnOp::Neg { "-" } else { "NOT" },
                    self.tname(&t)
                );
                self.error(codes::OPERATOR_TYPES, span, msg);
            }
            return Type::Error;
        };
        match op {
            UnOp::Neg => match e {
                Elem::Real => self.op(Opcode::NegF32),
                Elem::LReal => self.op(Opcode::NegF64),
                e if e.is_signed_int() || e.is_duration() => {
                    self.op(Opcode::Neg);
                    self.wrap(e);
                }
                // `-step` of a BYTE (CODESYS): the negated value in a signed integer
                // twice as wide (which holds it).
                e if (e.is_unsigned_int() || e.is_bits()) && e.size() < 8 => {
                    let signed = signed_of_size(e.size() * 2);
                    self.op(Opcode::Neg);
                    return Type::Elem(signed);
                }
                _ => {
                    let msg = format!("operator - cannot be applied to {e}");
                    self.error(codes::OPERATOR_TYPES, span, msg);
                    return Type::Error;
                }
            },
            UnOp::Not => match e {
                Elem::Bool => self.op(Opcode::NotBool),
                e if e.is_integral() => {
                    self.op(Opcode::Not);
                    self.wrap(e);
                }
                _ => {
                    let msg = format!("operator NOT cannot be applied to {e}");
                    self.error(codes::OPERATOR_TYPES, span, msg);
                    return Type::Error;
                }
            },
        }
        Type::Elem(e)
    }

    /// Type both operands are brought to.
    fn operand_type(&mut self, a: &Expr, b: &Expr, expected: Option<&Type>) -> (Type, Type) {
        let fa = Self::is_flexible(a);
        let fb = Self::is_flexible(b);
        let ta = if fa { None } else { Some(self.infer(a)) };
        let tb = if fb { None } else { Some(self.infer(b)) };
        // Only a plain literal: arithmetic of literals keeps wrapping in the other operand's
        // type as it always did.
        let int_value = |e: &Expr| match &e.kind {
            ExprKind::Int(v) => Some(*v as i128),
            ExprKind::Unary(UnOp::Neg, x) => match x.kind {
                ExprKind::Int(v) => Some(-(v as i128)),
                _ => None,
            },
            _ => None,
        };
        let (va, vb) = (int_value(a), int_value(b));
        // An integer literal takes the other operand's type, or a wider one when it does not
        // fit it (`int_var * 60000` is a DINT product, as the literal is a DINT).
        let flex_type = |other: &Type, e: &Expr, value: Option<i128>| -> Type {
            if Self::has_real_literal(e) {
                return match other.elem() {
                    Some(x) if x.is_real() => other.clone(),
                    _ => Type::LREAL,
                };
            }
            match (other, value) {
                (Type::Elem(x), Some(v)) if x.is_integral() => {
                    let (lo, hi) = x.int_range();
                    if lo <= v && v <= hi {
                        return other.clone();
                    }
                    let literal = if i32::try_from(v).is_ok() {
                        Elem::DInt
                    } else {
                        Elem::LInt
                    };
                    match common_numeric(*x, literal) {
                        Some(c) if c.int_range().0 <= v && v <= c.int_range().1 => Type::Elem(c),
                        _ => other.clone(),
                    }
                }
                _ => other.clone(),
            }
        };
        match (ta, tb) {
            (Some(x), Some(y)) => (x, y),
            (Some(x), None) => {
                let y = flex_type(&x, b, vb);
                (x, y)
            }
            (None, Some(y)) => {
                let x = flex_type(&y, a, va);
                (x, y)
            }
            (None, None) => {
                let num = expected
                    .and_then(|t| t.elem())
                    .filter(|e| e.is_numeric() && !matches!(expected, Some(Type::Enum(_))));
                let any_real = Self::has_real_literal(a) || Self::has_real_literal(b);
                // Integer literals stay integers (5 / 2 = 2 even when assigned to a REAL);
                // real literals take a REAL context's precision.
                let t = match num {
                    Some(e) if e.is_real() == any_real => Type::Elem(e),
                    _ => {
                        if Self::has_real_literal(a) || Self::has_real_literal(b) {
                            Type::LREAL
                        } else {
                            Type::DINT
                        }
                    }
                };
                (t.clone(), t)
            }
        }
    }

    pub(crate) fn binary(
        &mut self,
        op: BinOp,
        a: &Expr,
        b: &Expr,
        expected: Option<&Type>,
        span: Span,
    ) -> Type {
        if self.is_pointer_operation(a, b) {
            return self.pointer_binary(op, a, b, expected, span);
        }
        let (ta, tb) = self.operand_type(a, b, expected);
        if ta.is_error() || tb.is_error() {
            self.expr(a, None);
            self.expr(b, None);
            return Type::Error;
        }
        let is_cmp = matches!(
            op,
            BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge
        );
        let mismatch = |g: &mut Self| {
            let msg = format!(
                "operator {} cannot be applied to {} and {}",
                op.symbol(),
                g.tname(&ta),
                g.tname(&tb)
            );
            g.error(codes::OPERATOR_TYPES, span, msg);
            Type::Error
        };
        // Strings: comparisons only (STRING with STRING, WSTRING with WSTRING).
        if ta.is_string() || tb.is_string() || ta.is_wstring() || tb.is_wstring() {
            let wide = ta.is_wstring() || tb.is_wstring();
            let same_kind =
                (ta.is_string() && tb.is_string()) || (ta.is_wstring() && tb.is_wstring());
            // A STRING literal compared with a WSTRING is a WSTRING literal.
            let literal = |e: &Expr| matches!(e.kind, ExprKind::Str(_));
            let adapts = wide && (literal(a) && tb.is_wstring() || literal(b) && ta.is_wstring());
            if !((same_kind || adapts) && is_cmp) {
                return mismatch(self);
            }
            let w = Type::WString(DEFAULT_STRING_LEN);
            self.expr(a, wide.then_some(&w));
            self.expr(b, wide.then_some(&w));
            self.emit(|bb| {
                bb.call_builtin(if wide {
                    Builtin::WStrCompare
                } else {
                    Builtin::StrCompare
                });
                bb.push_i32(0);
            });
            self.op(cmp_op(op, true));
            return Type::BOOL;
        }
        // Enumerations (and exceptions): equality/ordering within the same type.
        let enumish = |t: &Type| matches!(t, Type::Enum(_) | Type::Exception);
        if enumish(&ta) || enumish(&tb) {
            if ta != tb || !is_cmp {
                return mismatch(self);
            }
            self.expr(a, Some(&ta));
            self.expr(b, Some(&tb));
            self.op(cmp_op(op, true));
            return Type::BOOL;
        }
        let (Some(ea), Some(eb)) = (ta.elem(), tb.elem()) else {
            return mismatch(self);
        };
        if ea.is_temporal() || eb.is_temporal() {
            return self.temporal_binary(op, (a, &ta, ea), (b, &tb, eb), span);
        }
        // Characters: comparisons within CHAR/WCHAR.
        if ea.is_char() || eb.is_char() {
            if Self::is_flexible(a) || Self::is_flexible(b) {
                self.error(codes::CHARACTER_IS_NO_NUMBER,
                    span,
                    "a character is no number: compare it with a character (CHAR#'a') or convert it (CHAR_TO_BYTE)",
                );
                return Type::Error;
            }
            if !(is_cmp && ea.is_char() && eb.is_char()) {
                return mismatch(self);
            }
            self.expr(a, Some(&ta));
            self.expr(b, Some(&tb));
            self.op(cmp_op(op, true));
            return Type::BOOL;
        }
        // Booleans and bit strings: logic operators.
        if matches!(op, BinOp::And | BinOp::Or | BinOp::Xor) {
            let t = if ea == Elem::Bool && eb == Elem::Bool {
                Elem::Bool
            } else if ea.is_integral() && eb.is_integral() {
                match common_numeric(ea, eb) {
                    Some(t) => t,
                    None => return mismatch(self),
                }
            } else {
                return mismatch(self);
            };
            let tt = Type::Elem(t);
            self.value_to_any(a, &ta, &tt);
            self.value_to_any(b, &tb, &tt);
            self.op(match op {
                BinOp::And => Opcode::And,
                BinOp::Or => Opcode::Or,
                _ => Opcode::Xor,
            });
            return tt;
        }
        if ea == Elem::Bool || eb == Elem::Bool {
            if ea == eb && matches!(op, BinOp::Eq | BinOp::Ne) {
                self.expr(a, Some(&ta));
                self.expr(b, Some(&tb));
                self.op(cmp_op(op, true));
                return Type::BOOL;
            }
            return mismatch(self);
        }
        let Some(mut ct) = common_numeric(ea, eb) else {
            return mismatch(self);
        };
        if op == BinOp::Pow && !ct.is_real() {
            // Integer ** integer: computed in LREAL, rounded back.
            let rt = Type::Elem(ct);
            self.value_to_any(a, &ta, &Type::LREAL);
            self.value_to_any(b, &tb, &Type::LREAL);
            self.emit(|bb| {
                bb.call_builtin(Builtin::ExptF64);
                bb.float_to_int(Opcode::F64ToInt, mem_type(ct), RoundMode::NearestTiesAway);
            });
            return rt;
        }
        if op == BinOp::Pow {
            ct = if ct == Elem::Real {
                Elem::Real
            } else {
                Elem::LReal
            };
        }
        let tt = Type::Elem(ct);
        self.value_to_any(a, &ta, &tt);
        self.value_to_any(b, &tb, &tt);
        if is_cmp {
            let opc = if ct == Elem::Real {
                match op {
                    BinOp::Eq => Opcode::EqF32,
                    BinOp::Ne => Opcode::NeF32,
                    BinOp::Lt => Opcode::LtF32,
                    BinOp::Le => Opcode::LeF32,
                    BinOp::Gt => Opcode::GtF32,
                    _ => Opcode::GeF32,
                }
            } else if ct == Elem::LReal {
                match op {
                    BinOp::Eq => Opcode::EqF64,
                    BinOp::Ne => Opcode::NeF64,
                    BinOp::Lt => Opcode::LtF64,
                    BinOp::Le => Opcode::LeF64,
                    BinOp::Gt => Opcode::GtF64,
                    _ => Opcode::GeF64,
                }
            } else {
                // Only 64-bit unsigned values can exceed i64; narrower ones are zero-extended.
                cmp_op(op, ct.size() != 8 || ct.is_signed_int())
            };
            self.op(opc);
            return Type::BOOL;
        }
        match ct {
            Elem::Real => self.op(match op {
                BinOp::Add => Opcode::AddF32,
                BinOp::Sub => Opcode::SubF32,
                BinOp::Mul => Opcode::MulF32,
                BinOp::Div => Opcode::DivF32,
                BinOp::Pow => {
                    self.emit(|bb| bb.call_builtin(Builtin::ExptF32));
                    return tt;
                }
                _ => return mismatch(self),
            }),
            Elem::LReal => self.op(match op {
                BinOp::Add => Opcode::AddF64,
                BinOp::Sub => Opcode::SubF64,
                BinOp::Mul => Opcode::MulF64,
                BinOp::Div => Opcode::DivF64,
                BinOp::Pow => {
                    self.emit(|bb| bb.call_builtin(Builtin::ExptF64));
                    return tt;
                }
                _ => return mismatch(self),
            }),
            _ => {
                let signed = ct.is_signed_int();
                self.op(match op {
                    BinOp::Add => Opcode::Add,
                    BinOp::Sub => Opcode::Sub,
                    BinOp::Mul => Opcode::Mul,
                    BinOp::Div => {
                        if signed {
                            Opcode::DivS
                        } else {
                            Opcode::DivU
                        }
                    }
                    BinOp::Mod => {
                        if signed {
                            Opcode::ModS
                        } else {
                            Opcode::ModU
                        }
                    }
                    _ => return mismatch(self),
                });
                self.wrap(ct);
            }
        }
        tt
    }

    /// Date and time arithmetic (IEC 61131-3 table of time operations): TIME +/- TIME,
    /// TOD +/- TIME (wrapping within the day), DT +/- TIME, DATE - DATE, TOD - TOD, DT - DT
    /// (giving TIME), TIME * and / numbers, comparisons within one family. The long forms
    /// follow the same rules; an operation with a long operand gives the long result.
    fn temporal_binary(
        &mut self,
        op: BinOp,
        (a, ta, ea): (&Expr, &Type, Elem),
        (b, tb, eb): (&Expr, &Type, Elem),
        span: Span,
    ) -> Type {
        // A literal factor is a number, not a duration (`T#1s * 2`).
        let literal_type = |e: &Expr| {
            if Self::has_real_literal(e) {
                Type::LREAL
            } else {
                Type::LINT
            }
        };
        let (ta, ea) = if Self::is_flexible(a) && matches!(op, BinOp::Mul) {
            let t = literal_type(a);
            let e = t.elem().unwrap_or(Elem::LInt);
            (&t.clone(), e)
        } else {
            (ta, ea)
        };
        let (tb, eb) = if Self::is_flexible(b) && matches!(op, BinOp::Mul | BinOp::Div) {
            let t = literal_type(b);
            let e = t.elem().unwrap_or(Elem::LInt);
            (&t.clone(), e)
        } else {
            (tb, eb)
        };
        let fa = ea.temporal_family();
        let fb = eb.temporal_family();
        let long = ea.is_long_temporal() || eb.is_long_temporal();
        let pick = |short: Elem| -> Elem {
            match (short, long) {
                (Elem::Time, true) => Elem::LTime,
                (Elem::Tod, true) => Elem::LTod,
                (Elem::Dt, true) => Elem::LDt,
                (Elem::Date, true) => Elem::LDate,
                (e, _) => e,
            }
        };
        let is_cmp = matches!(
            op,
            BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge
        );
        let time = Some(Elem::Time);
        // (result, whether a TOD result wraps into its day)
        let result = match op {
            _ if is_cmp && fa == fb => Some((Elem::Bool, false)),
            BinOp::Add if fa == time && fb == time => Some((pick(Elem::Time), false)),
            BinOp::Add
                if fa == Some(Elem::Tod) && fb == time || fa == time && fb == Some(Elem::Tod) =>
            {
                Some((pick(Elem::Tod), true))
            }
            BinOp::Add
                if fa == Some(Elem::Dt) && fb == time || fa == time && fb == Some(Elem::Dt) =>
            {
                Some((pick(Elem::Dt), false))
            }
            BinOp::Sub if fa == fb && fa != Some(Elem::Dt) && fa != Some(Elem::Tod) => {
                // TIME - TIME, DATE - DATE
                Some((pick(Elem::Time), false))
            }
            BinOp::Sub if fa == fb => Some((pick(Elem::Time), false)),
            BinOp::Sub if fa == Some(Elem::Tod) && fb == time => Some((pick(Elem::Tod), true)),
            BinOp::Sub if fa == Some(Elem::Dt) && fb == time => Some((pick(Elem::Dt), false)),
            BinOp::Mul | BinOp::Div
                if fa == time && eb.is_numeric()
                    || op == BinOp::Mul && fb == time && ea.is_numeric() =>
            {
                Some((if fa == time { ea } else { eb }, false))
            }
            _ => None,
        };
        let Some((result, wraps)) = result else {
            let hint = match (op, fa, fb) {
                (BinOp::Add | BinOp::Sub, Some(Elem::Date), Some(Elem::Time)) => {
                    " (a DATE is a day: use DATE_TO_DT or CONCAT_DATE_TOD for a point in time)"
                }
                (BinOp::Add, Some(x), Some(y)) if x == y && x != Elem::Time => {
                    " (two points in time cannot be added; subtract them for a TIME)"
                }
                _ => "",
            };
            let msg = format!(
                "operator {} cannot be applied to {} and {}{hint}",
                op.symbol(),
                self.tname(ta),
                self.tname(tb)
            );
            self.error(codes::OPERATOR_TYPES, span, msg);
            return Type::Error;
        };
        if matches!(op, BinOp::Mul | BinOp::Div) {
            let (duration, number, number_type) = if fa == time { (a, b, tb) } else { (b, a, ta) };
            let duration_type = Type::Elem(result);
            if number_type.elem().is_some_and(|e| e.is_real()) {
                // TIME * REAL: computed in LREAL nanoseconds, rounded.
                self.value_to_any(duration, &duration_type, &duration_type);
                self.op(Opcode::IToF64S);
                self.value_to_any(number, number_type, &Type::LREAL);
                self.op(if op == BinOp::Mul {
                    Opcode::MulF64
                } else {
                    Opcode::DivF64
                });
                self.emit(|bb| {
                    bb.float_to_int(Opcode::F64ToInt, MemType::I64, RoundMode::NearestTiesAway)
                });
            } else {
                self.value_to_any(duration, &duration_type, &duration_type);
                self.value_to_any(number, number_type, &Type::LINT);
                self.op(if op == BinOp::Mul {
                    Opcode::Mul
                } else {
                    Opcode::DivS
                });
            }
            return Type::Elem(result);
        }
        // The operands keep their nanoseconds (TIME widens to LTIME implicitly).
        self.value_to_any(a, ta, ta);
        self.value_to_any(b, tb, tb);
        self.op(match op {
            BinOp::Add => Opcode::Add,
            BinOp::Sub => Opcode::Sub,
            _ => cmp_op(op, true),
        });
        if wraps {
            self.emit(|bb| bb.call_builtin(Builtin::TodOf));
        }
        Type::Elem(result)
    }

    /// Compiles `e` (whose type was inferred as `from`) and converts to `to` without the
    /// implicit-conversion restriction (used for operands already checked by the caller).
    pub(crate) fn value_to_any(&mut self, e: &Expr, from: &Type, to: &Type) {
        let t = self.expr(e, Some(if Self::is_flexible(e) { to } else { from }));
        if let (Some(f), Some(t2)) = (t.elem(), to.elem()) {
            self.convert(f, t2);
        }
    }
}

fn offset_loc(l: Loc, off: u32) -> Loc {
    // Wrapping: only programs that already failed the data-size check can get near u32::MAX.
    match l {
        Loc::Abs(a) => Loc::Abs(a.wrapping_add(off)),
        Loc::Rel(o) => Loc::Rel(o.wrapping_add(off)),
        Loc::Ind(o) => Loc::Ind(o.wrapping_add(off)),
        Loc::Ref(o) => Loc::Ref(o.wrapping_add(off)),
    }
}

/// Whether `v` lies in the range of integer type `e`.
fn type_holds(e: Elem, v: i128) -> bool {
    let bits = e.size() * 8;
    if e.signed_storage() {
        let half = 1i128 << (bits - 1);
        -half <= v && v < half
    } else {
        0 <= v && v < (1i128 << bits)
    }
}

fn cmp_op(op: BinOp, signed: bool) -> Opcode {
    match (op, signed) {
        (BinOp::Eq, _) => Opcode::Eq,
        (BinOp::Ne, _) => Opcode::Ne,
        (BinOp::Lt, true) => Opcode::LtS,
        (BinOp::Le, true) => Opcode::LeS,
        (BinOp::Gt, true) => Opcode::GtS,
        (BinOp::Ge, true) => Opcode::GeS,
        (BinOp::Lt, false) => Opcode::LtU,
        (BinOp::Le, false) => Opcode::LeU,
        (BinOp::Gt, false) => Opcode::GtU,
        _ => Opcode::GeU,
    }
}
