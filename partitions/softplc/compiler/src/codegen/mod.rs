//! Code generation: the body walk that emits plc-vm bytecode through [`ImageBuilder`], for
//! a program the checking pass ([`crate::typed::check`], the checkers in [`crate::sema`])
//! passed. It checks nothing: it reads the checker's records ([`crate::typed::Checked`]) and
//! picks the instructions. `Gen` is the context both passes walk (the program, the POU
//! walked, the records); the checker uses it with `check_only` set and never emits nor
//! allocates with it.
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

mod calls;
pub(crate) use calls::{Bound, instance_callee};
mod classes;
pub(crate) use classes::Dynamic;
mod convert;
mod expr;
mod init;
mod ops;
mod place;
pub(crate) use place::element_offsets;
mod refs;
pub(crate) use refs::PointerOperation;
mod stdfuncs;
pub(crate) use stdfuncs::{MAX_TEMP_STRING, StdArgs, StdFamily, TimeFunction, split_arguments};
mod stmt;
mod strings;

use crate::codes::{self, Code};
use std::collections::HashMap;

use plc_vm::image::{ImageBuilder, Label, PouId};
use plc_vm::isa::{Builtin, MemType, Opcode, RoundMode};

use crate::ast::*;
use crate::diagnostics::{Diagnostics, SourceMap, Span};
use crate::sema::{ConstScope, ConstVal, Program, VarDef, const_eval};
use crate::typed::{
    Bare, BareNames, Bindings, Callees, CaseLabels, Coercions, ConversionArguments, ExprTypes,
    GenericTypes, Members, Operations, Properties, Roots, SetterArguments, StdArguments, Variables,
};
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

/// The context of a walk of the bodies: the program, the POU walked, what the checking pass
/// records and the code generator reads, and the code generator's image. The checking pass
/// (`sema`) walks with it too, `check_only` set: it reports and records, and never touches
/// the image.
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
    /// Set for the checking pass, which walks with this context (every diagnostic reported,
    /// every decision recorded) and allocates and emits nothing; [`Gen::infer`] then asks the
    /// checker.
    pub check_only: bool,
    /// The type of each expression inferred so far; the emission pass starts with the
    /// checking pass's (see [`crate::typed`]).
    pub(crate) types: ExprTypes,
    /// The value of each CASE label: resolved by the checking pass, read by emission.
    pub(crate) case_labels: CaseLabels,
    /// What the callee of each call resolved to: recorded by the checking pass, read by
    /// emission.
    pub(crate) callees: Callees,
    /// The variable each name denotes: recorded by the checking pass, read by emission.
    pub(crate) variables: Variables,
    /// The member each `base.m` denotes: recorded by the checking pass, read by emission.
    pub(crate) members: Members,
    /// What each bare name in an expression denotes: decided by the checking pass, read by
    /// emission.
    pub(crate) bare_names: BareNames,
    /// How the arguments of each call are bound: recorded by the checking pass, read by
    /// emission.
    pub(crate) bindings: Bindings,
    /// The order of each standard-function call's arguments: recorded by the checking pass,
    /// read by emission.
    pub(crate) std_arguments: StdArguments,
    /// The type each generic standard function is called at: decided by the checking
    /// pass, read by emission.
    pub(crate) generic_types: GenericTypes,
    /// What each implicit conversion takes: decided by the checking pass, read by emission.
    pub(crate) coercions: Coercions,
    /// How each conversion's argument reaches its source type: decided by the checking
    /// pass, read by emission.
    pub(crate) conversion_arguments: ConversionArguments,
    /// What each operator does: decided by the checking pass, read by emission.
    pub(crate) operations: Operations,
    /// Which property each member read and assignment target reaches, if any: resolved by
    /// the checking pass, read by emission.
    pub(crate) properties: Properties,
    /// The argument list of each property write: made by the checking pass, kept for
    /// emission.
    pub(crate) setter_arguments: SetterArguments,
    /// The variable each `REF()`/`ADR()` and VAR_IN_OUT argument is part of: found by the
    /// checking pass, read by emission (for the object table).
    pub(crate) roots: Roots,
    str_lits: HashMap<String, u32>,
    /// Call graph edges between user POUs, recorded for the recursion rule
    /// ([`crate::sema::body`]).
    pub calls: Vec<crate::sema::body::CallEdge>,
    /// Static frame address of each FUNCTION and the pristine copy of each POU frame.
    pub frames: Vec<(Option<u32>, Option<u32>)>,
    /// What code generation learns about references (for the object table).
    pub(crate) refs: crate::codegen::refs::RefState,
}

/// Constants visible in the POU being compiled.
pub(crate) struct PouConsts<'p> {
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
            check_only: false,
            types: ExprTypes::default(),
            case_labels: CaseLabels::default(),
            callees: Callees::default(),
            variables: Variables::default(),
            members: Members::default(),
            bare_names: BareNames::default(),
            bindings: Bindings::default(),
            std_arguments: StdArguments::default(),
            generic_types: GenericTypes::default(),
            coercions: Coercions::default(),
            conversion_arguments: ConversionArguments::default(),
            operations: Operations::default(),
            properties: Properties::default(),
            setter_arguments: SetterArguments::default(),
            roots: Roots::default(),
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

    /// Reports that emission found no record the checking pass should have left at `span`;
    /// `what` completes "the checker …" (e.g. "recorded no type for this expression").
    pub(crate) fn missing_record(&mut self, span: Span, what: &str) {
        self.diags.error(
            codes::INTERNAL_ERROR,
            span,
            format!("internal error: the checker {what}"),
        );
    }

    /// Whether nothing is emitted or allocated (inference, or the checking pass).
    fn silent(&self) -> bool {
        self.dry || self.check_only
    }

    pub fn emit(&mut self, f: impl FnOnce(&mut ImageBuilder)) {
        if !self.silent() {
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
        if self.silent() {
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
        if self.silent() {
            return 0;
        }
        let a = self.alloc_static(4 + len, 2);
        self.write_bytes(a, &(len as u16).to_le_bytes());
        a
    }

    /// A static WSTRING[len] temporary with its header initialised.
    pub fn temp_wstring(&mut self, len: u32) -> u32 {
        if self.silent() {
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
        if self.silent() {
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
        if self.silent() {
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
        if self.silent() {
            return;
        }
        let file = self.sources.file(span.file);
        let (line, col) = file.line_col(span.start as usize);
        let fid = self.file_ids[span.file as usize];
        self.b.source_location(fid, line as u32, col as u32);
    }

    fn consts(&self) -> PouConsts<'_> {
        self.pou_consts(self.cur)
    }

    /// The constants visible in POU `p` (its own and the global ones).
    pub(crate) fn pou_consts(&self, p: usize) -> PouConsts<'_> {
        PouConsts {
            prog: self.prog,
            vars: &self.prog.pous[p].vars,
        }
    }

    pub fn const_value(&self, e: &Expr) -> Option<ConstVal> {
        const_eval(self.prog, &self.consts(), e)
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
        self.stmts(body);
        self.bind(ret);
        self.sync_byte_views_on_return();
        self.emit(|b| b.ret());
        self.b.end_pou(id);
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
