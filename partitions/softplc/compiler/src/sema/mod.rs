//! Semantic analysis of declarations: resolves TYPE declarations, lays out the variables of
//! every POU (frames) and of the globals, evaluates constant expressions (array bounds,
//! subrange limits, string lengths, CASE labels, task properties) and checks the
//! CONFIGURATION. The checking pass of the bodies ([`crate::typed::check`]) is here too, one
//! checker a construct: the initial values (`init`), statements (`stmt`), expressions
//! (`expr`: literals, names, operators, implicit conversions), places (`place`), calls
//! (`call`), methods and properties (`class`), references (`refs`) and standard
//! functions (`stdcall`), by the rules of [`ops`] and [`stdfuncs`]; [`body`] judges what
//! they record (the call graph: the recursion rule).
//!
//! Memory model: every variable has a static home. Globals and program instances live at
//! fixed addresses; an FB instance is a region inside its owner; a FUNCTION has one static
//! frame (IEC forbids recursion, which is checked). A POU body addresses its own variables
//! relative to the frame base register.

pub mod body;
pub(crate) mod call;
pub(crate) mod class;
mod config;
pub(crate) mod expr;
pub(crate) mod init;
pub mod ops;
pub(crate) mod place;
pub(crate) mod refs;
pub(crate) mod stdcall;
pub mod stdfuncs;
pub(crate) mod stmt;

use crate::codes;
use std::collections::HashMap;
use std::rc::Rc;

use crate::ast::*;
use crate::diagnostics::{Diagnostics, Span};
use crate::types::*;
use plc_vm::located::Location;

#[derive(Debug, Clone)]
pub struct StructDef {
    pub name: String,
    pub members: Vec<VarDef>,
    pub size: u32,
    pub align: u32,
}

#[derive(Debug, Clone)]
pub struct EnumDef {
    pub name: String,
    /// (UPPER-CASED name, value).
    pub values: Vec<(String, i64)>,
    /// Value names as written, for printing.
    pub display: Vec<String>,
}

/// A declared variable (or struct member) with its resolved type and offset within its frame
/// (or absolute address for globals).
#[derive(Debug, Clone)]
pub struct VarDef {
    pub name: String,
    pub text: String,
    pub span: Span,
    pub ty: Type,
    pub offset: u32,
    pub kind: VarKind,
    pub constant: bool,
    pub init: Option<Init>,
    /// Its direct address (`AT %IX0.1`), for PROGRAM variables and globals.
    pub location: Option<Location>,
    /// Declared in a RETAIN block: kept across a warm restart.
    pub retain: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum LayoutState {
    NotStarted,
    InProgress,
    Done,
}

#[derive(Debug)]
pub struct PouDef {
    pub kind: PouKind,
    pub name: String,
    pub text: String,
    pub span: Span,
    /// Index of the declaration in the unit's POU list.
    pub ast: usize,
    /// Variables in frame order: inputs and in-outs first (callers write those), then the rest.
    pub vars: Vec<VarDef>,
    pub return_type: Option<Type>,
    pub frame_size: u32,
    /// Offset where the part of the frame that is re-initialised on every call starts
    /// (functions: everything after the parameters; FBs/programs: the VAR_TEMP region).
    pub reinit_start: u32,
    /// Whether this POU comes from the built-in prelude.
    pub builtin: bool,
    pub(crate) state: LayoutState,
    /// It contains an instance of itself, directly or through other function blocks (E0020
    /// reported): nothing walks into its instances, which would never end.
    pub(crate) recursive: bool,
    /// A method, property accessor or action: what it belongs to.
    pub member: Option<Member>,
    /// A function block's base (`EXTENDS`).
    pub base: Option<usize>,
    /// Index in [`Program::classes`] when instances carry a class id (see `classes`).
    pub class: Option<usize>,
    /// ABSTRACT / FINAL function block.
    pub is_abstract: bool,
    pub is_final: bool,
}

/// What kind of member of a function block (or program) a POU is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MemberKind {
    Method,
    /// The GET accessor of a property.
    Getter,
    /// The SET accessor of a property.
    Setter,
    Action,
}

/// Where a member's declaration is in the unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MemberSource {
    /// `unit.pous[pou].methods[index]`.
    Method(usize, usize),
    /// `unit.pous[pou].properties[index]` (its GET or SET part).
    Property(usize, usize),
    /// `unit.pous[pou].actions[index]`.
    Action(usize, usize),
    /// `unit.actions[index]`.
    UnitAction(usize),
}

/// A method, property accessor or action: a POU of its own that runs on an instance of its
/// owner (the frame base register points at the instance). Methods and accessors have a
/// static frame of their own for their parameters and variables, as functions do.
#[derive(Debug, Clone)]
pub struct Member {
    pub owner: usize,
    pub kind: MemberKind,
    /// The method's, property's or action's name (upper case) and as written.
    pub name: String,
    pub text: String,
    pub access: Access,
    pub is_abstract: bool,
    pub is_final: bool,
    pub source: MemberSource,
}

/// A function block whose instances carry their class id in their first four bytes (it
/// implements interfaces, extends another block or is extended): what `CALL_VIRT` needs.
#[derive(Debug, Clone)]
pub struct ClassDef {
    pub pou: usize,
    /// Every interface it implements, directly, through its base or through interfaces
    /// extending others.
    pub interfaces: Vec<usize>,
    /// `(slot, method POU)`: what `CALL_VIRT slot` runs on its instances.
    pub dispatch: Vec<(u16, usize)>,
}

/// A method or property accessor an INTERFACE declares.
#[derive(Debug, Clone)]
pub struct InterfaceMember {
    pub name: String,
    pub text: String,
    pub kind: MemberKind,
    pub return_type: Option<Type>,
    /// Parameters and outputs in frame order (as a method implementing it lays them out).
    pub params: Vec<VarDef>,
    pub slot: u16,
    pub span: Span,
}

impl PouDef {
    pub fn var(&self, name: &str) -> Option<&VarDef> {
        self.vars.iter().find(|v| v.name == name)
    }

    /// A parameter by name as a caller writes it: the standard counters (CTU, CTD, CTUD)
    /// also take CODESYS's names RESET for R and LOAD for LD.
    pub fn param(&self, name: &str) -> Option<&VarDef> {
        self.var(name).or_else(|| {
            let alias = match (self.builtin, name) {
                (true, "RESET") => "R",
                (true, "LOAD") => "LD",
                _ => return None,
            };
            self.var(alias)
        })
    }

    /// Positional parameters (inputs, then in-outs, then outputs in declaration order is what
    /// IEC prescribes for non-formal calls; we use declaration order of inputs and in-outs).
    pub fn params(&self) -> impl Iterator<Item = &VarDef> {
        self.vars
            .iter()
            .filter(|v| matches!(v.kind, VarKind::Input | VarKind::InOut))
    }
}

/// A task after checking the configuration.
#[derive(Debug, Clone)]
pub struct TaskDef {
    pub name: String,
    /// Cyclic interval in ns (0 for a pure event task).
    pub interval_ns: i64,
    /// Global BOOL variable whose rising edge triggers the task (SINGLE).
    pub single: Option<String>,
    pub priority: u32,
    /// Program instances (instance name, POU index) in declaration order.
    pub programs: Vec<(String, usize)>,
}

/// A program instance with its static address.
#[derive(Debug, Clone)]
pub struct ProgramInstance {
    /// Name used to print its variables (`Main` or the configured instance name).
    pub name: String,
    pub pou: usize,
    pub addr: u32,
}

/// Constant value of a constant expression.
#[derive(Debug, Clone, PartialEq)]
pub enum ConstVal {
    Int(i128),
    Real(f64),
    Bool(bool),
    Time(i128),
    /// A date/time value other than TIME: its type and nanoseconds.
    Temporal(Elem, i128),
    Str(String),
}

/// The analysed compilation: all declarations resolved and laid out.
#[derive(Debug, Default)]
pub struct Program {
    pub structs: Vec<StructDef>,
    pub enums: Vec<EnumDef>,
    pub aliases: HashMap<String, (Type, Option<Init>)>,
    pub pous: Vec<PouDef>,
    pub pou_by_name: HashMap<String, usize>,
    /// Globals with absolute addresses in `offset`.
    pub globals: Vec<VarDef>,
    pub instances: Vec<ProgramInstance>,
    pub tasks: Vec<TaskDef>,
    pub has_configuration: bool,
    /// Bytes of data memory allocated so far (globals, instances, function frames, ...).
    pub data_size: u32,
    /// Set when an allocation would exceed [`MAX_DATA`] (reported as an error).
    pub data_overflow: bool,
    /// The globals shared with another PLC project (`{attribute 'shared'}`), in declaration
    /// order.
    pub shared: Vec<SharedGlobal>,
    /// The safe values of located outputs given by `{attribute 'safe' := 'VALUE'}`.
    pub safe: Vec<SafeDefault>,
    /// INTERFACE declarations.
    pub interfaces: Vec<InterfaceDef>,
    /// Function blocks whose instances carry a class id (see [`ClassDef`]).
    pub classes: Vec<ClassDef>,
    /// The dispatch slot of each method (and accessor) POU that can be called dynamically.
    pub slots: HashMap<usize, u16>,
    /// Number of slots handed out.
    pub slot_count: u16,
    /// Interfaces by upper-case name.
    pub interface_by_name: HashMap<String, usize>,
    /// Methods, accessors and actions by owner, name and kind.
    pub members: HashMap<(usize, String, MemberKind), usize>,
}

/// An INTERFACE.
#[derive(Debug, Clone)]
pub struct InterfaceDef {
    pub name: String,
    pub text: String,
    pub span: Span,
    /// Index in `unit.interfaces`.
    pub ast: usize,
    /// The interfaces it extends (directly).
    pub extends: Vec<usize>,
    /// Its own methods and accessors (not those of the interfaces it extends).
    pub members: Vec<InterfaceMember>,
}

/// A located output's safe value from its `{attribute 'safe'}` pragma.
#[derive(Debug, Clone)]
pub struct SafeDefault {
    /// The PROGRAM declaring it (its VAR), `None` for a global.
    pub pou: Option<usize>,
    /// Its name (upper-cased) and as written.
    pub name: String,
    pub text: String,
    /// Bytes of its address (`%QX` and `%QB` 1, `%QW` 2, ...).
    pub width: u8,
    /// The value's bits (the variable's little-endian cell).
    pub value: u64,
}

/// A global variable shared with another PLC project.
#[derive(Debug, Clone)]
pub struct SharedGlobal {
    /// Its name as declared (the variable-map name).
    pub text: String,
    pub direction: plc_vm::image::SharedDirection,
    /// Its name in the declaration.
    pub span: Span,
}

/// Bytes at the start of an instance of a class that hold its class id (a `u32`, padded).
pub const CLASS_HEADER: u32 = 8;

/// Bytes at the start of data memory that hold no variable, so that the address 0 of a
/// reference to a function-block instance or an interface value means NULL.
pub const NULL_GUARD: u32 = 8;

/// Upper limit of data memory for one program (the PLC partition is small).
pub const MAX_DATA: u32 = 16 << 20;

/// Finds the declared name (among `declared`) that `name` refers to, for names of POUs,
/// types and interfaces that may be qualified by a NAMESPACE: the name as written; for a
/// qualified name `A.B.X` that is not declared, `B.X`, then `X` (a CODESYS library
/// qualifier such as `Standard.TON` names the block this compiler provides); for a plain
/// name, the one `N.X` of that name declared in a NAMESPACE. `Err` lists the candidates when
/// a plain name is declared in several namespaces.
pub fn qualified<'a>(
    name: &str,
    declared: impl Iterator<Item = &'a String> + Clone,
) -> Result<Option<String>, Vec<String>> {
    if declared.clone().any(|d| d == name) {
        return Ok(Some(name.to_string()));
    }
    if let Some((_, rest)) = name.split_once('.') {
        return qualified(rest, declared);
    }
    let suffix = format!(".{name}");
    let mut found: Vec<String> = declared.filter(|d| d.ends_with(&suffix)).cloned().collect();
    // Sorted: the declarations come from hash maps, a diagnostic must not depend on their order.
    found.sort();
    match found.len() {
        0 => Ok(None),
        1 => Ok(found.into_iter().next()),
        _ => Err(found),
    }
}

/// The diagnostic for a plain `name` that [`qualified`] found in several namespaces.
pub(crate) fn ambiguous(name: &str, candidates: &[String]) -> String {
    format!(
        "`{name}` is ambiguous: it is declared in several namespaces ({}); qualify it",
        candidates.join(", ")
    )
}

/// Gives `vars` their frame offsets from `first_offset` on and returns the frame size and
/// where the part re-initialised on every call starts. Frame order: parameters first, then
/// outputs and locals, temporaries last. A method's result and outputs come before its
/// locals, so that methods of the same signature (overrides, implementations of one
/// interface method) agree on where the caller finds them.
pub(crate) fn frame_layout(
    prog: &Program,
    vars: &mut [VarDef],
    kind: PouKind,
    is_method: bool,
    first_offset: u32,
) -> (u32, u32) {
    let group = |v: &VarDef| match v.kind {
        VarKind::Input | VarKind::InOut => 0,
        VarKind::Temp => 3,
        VarKind::Output if is_method => 1,
        _ => 2,
    };
    let mut off = first_offset;
    let mut reinit_start = None;
    for g in 0..4 {
        for v in vars.iter_mut().filter(|v| group(v) == g) {
            if v.kind == VarKind::External || v.kind == VarKind::Global {
                continue;
            }
            let (sz, al) = if v.kind == VarKind::InOut {
                (4, 4)
            } else {
                prog.size_align(&v.ty)
            };
            off = align_up(off, al);
            let first_reinit = match kind {
                PouKind::Function => g >= 1,
                _ => g == 3,
            };
            if first_reinit && reinit_start.is_none() {
                reinit_start = Some(off);
            }
            v.offset = off;
            off = off.saturating_add(sz);
        }
        if g == 0 && kind == PouKind::Function {
            off = align_up(off, 8);
            reinit_start = Some(off);
        }
    }
    let frame_size = align_up(off, 8);
    (frame_size, reinit_start.unwrap_or(frame_size))
}

pub fn align_up(v: u32, a: u32) -> u32 {
    let a = a.max(1);
    v.div_ceil(a) * a
}

impl Program {
    /// Whether a variable of type `ty` at `addr` lies (partly) past the end of data memory,
    /// or data memory overflowed (the data-size check reports it; its initial values are
    /// neither checked nor written).
    pub fn beyond_data(&self, addr: u32, ty: &Type) -> bool {
        self.data_overflow || addr.saturating_add(self.size_align(ty).0) > MAX_DATA
    }

    pub fn size_align(&self, ty: &Type) -> (u32, u32) {
        match ty {
            Type::Elem(e) | Type::Subrange(e, ..) => (e.size(), e.size()),
            Type::Enum(_) | Type::Exception => (4, 4),
            // Header, text and the terminator byte CODESYS code writes through pointers.
            Type::String(n) => (5 + n, 2),
            Type::WString(n) => (4 + 2 * n, 2),
            Type::Ref(_) | Type::Reference(_) | Type::Interface(_) => (8, 8),
            Type::Null => (0, 1),
            Type::Array(a) => {
                let (s, al) = self.size_align(&a.elem);
                let stride = align_up(s, al);
                let total = (stride as u64)
                    .saturating_mul(a.len())
                    .min(u32::MAX as u64 / 2) as u32;
                (total, al)
            }
            Type::Struct(i) => (self.structs[*i].size, self.structs[*i].align),
            Type::Fb(i) => (self.pous[*i].frame_size, 8),
            Type::Void | Type::Error => (0, 1),
        }
    }

    pub fn stride(&self, ty: &Type) -> u32 {
        let (s, a) = self.size_align(ty);
        align_up(s, a)
    }

    pub fn type_name(&self, ty: &Type) -> String {
        match ty {
            Type::Elem(e) => e.name().to_string(),
            Type::String(n) => format!("STRING[{n}]"),
            Type::WString(n) => format!("WSTRING[{n}]"),
            Type::Array(a) => {
                let dims: Vec<String> = a.dims.iter().map(|(l, h)| format!("{l}..{h}")).collect();
                format!("ARRAY[{}] OF {}", dims.join(","), self.type_name(&a.elem))
            }
            Type::Struct(i) => self.structs[*i].name.clone(),
            Type::Enum(i) => self.enums[*i].name.clone(),
            Type::Subrange(e, lo, hi) => format!("{}({lo}..{hi})", e.name()),
            Type::Fb(i) => self.pous[*i].text.clone(),
            Type::Exception => "__EXCEPTION".into(),
            Type::Ref(t) => format!("REF_TO {}", self.type_name(t)),
            Type::Reference(t) => format!("REFERENCE TO {}", self.type_name(t)),
            Type::Interface(i) => self.interface_name(*i),
            Type::Null => "NULL".into(),
            Type::Void => "no value".into(),
            Type::Error => "?".into(),
        }
    }

    /// The name of interface `i` as written.
    pub fn interface_name(&self, i: usize) -> String {
        self.interfaces
            .get(i)
            .map_or_else(|| "?".into(), |d| d.text.clone())
    }

    pub fn global(&self, name: &str) -> Option<&VarDef> {
        self.globals.iter().find(|g| g.name == name)
    }

    /// Finds an enumeration value by bare name: (enum index, value).
    pub fn enum_value(&self, name: &str) -> Option<(usize, i64)> {
        self.enums.iter().enumerate().find_map(|(i, e)| {
            e.values
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, v)| (i, *v))
        })
    }

    /// Reserves `size` bytes of data memory aligned to `align`; returns the address.
    pub fn alloc(&mut self, size: u32, align: u32) -> u32 {
        let addr = align_up(self.data_size, align.max(1));
        let end = addr.saturating_add(size);
        if end > MAX_DATA {
            self.data_overflow = true;
            return 0;
        }
        self.data_size = end;
        addr
    }
}

/// Analyses all declarations of `unit`; `prelude_pous` counts the leading POUs of the unit
/// that come from the prelude.
pub fn analyse(
    unit: &Unit,
    prelude_pous: usize,
    opts: &crate::Options,
    diags: &mut Diagnostics,
) -> Program {
    let mut s = Sema {
        unit,
        // Data address 0 is never a variable: a zero reference or interface value is NULL.
        prog: Program {
            data_size: NULL_GUARD,
            ..Program::default()
        },
        diags,
        type_state: HashMap::new(),
        structs_in_progress: HashMap::new(),
    };
    s.declare_types();
    s.declare_pous(prelude_pous);
    s.declare_members();
    s.declare_interfaces();
    // Globals first: their CONSTANTs may size arrays in POUs (FB types they use are laid
    // out on demand).
    s.declare_globals();
    for i in 0..s.prog.pous.len() {
        s.layout_pou(i);
    }
    s.finish_classes();
    s.configure(opts.program.as_deref(), opts.library);
    s.prog
}

pub(crate) struct Sema<'a> {
    pub(crate) unit: &'a Unit,
    pub(crate) prog: Program,
    pub(crate) diags: &'a mut Diagnostics,
    /// Resolution state of named TYPE declarations (cycle detection).
    type_state: HashMap<String, LayoutState>,
    /// Structures being laid out (a reference to one may appear in its own members).
    structs_in_progress: HashMap<String, usize>,
}

/// Scope used to look up names inside constant expressions.
pub trait ConstScope {
    fn constant(&self, name: &str) -> Option<ConstVal>;
}

impl ConstScope for () {
    fn constant(&self, _: &str) -> Option<ConstVal> {
        None
    }
}

/// Evaluates a constant expression; `None` (without a diagnostic) when it is not constant.
pub fn const_eval(prog: &Program, scope: &dyn ConstScope, e: &Expr) -> Option<ConstVal> {
    // Constants defined in terms of each other (`c := d; d := c`) would recurse forever:
    // past this nesting the value is not a constant (their use then gets its own error).
    const MAX_NESTING: u32 = 512;
    thread_local! {
        static NESTING: std::cell::Cell<u32> = const { std::cell::Cell::new(0) };
    }
    let depth = NESTING.with(|n| {
        n.set(n.get() + 1);
        n.get()
    });
    let value = if depth > MAX_NESTING {
        None
    } else {
        const_eval_nested(prog, scope, e)
    };
    NESTING.with(|n| n.set(n.get() - 1));
    value
}

fn const_eval_nested(prog: &Program, scope: &dyn ConstScope, e: &Expr) -> Option<ConstVal> {
    use ConstVal::*;
    Some(match &e.kind {
        ExprKind::Int(v) => Int(*v as i128),
        ExprKind::Real(v) => Real(*v),
        ExprKind::Bool(b) => Bool(*b),
        ExprKind::Time(t) => Time(*t),
        ExprKind::Temporal(e, t) => Temporal(*e, *t),
        ExprKind::Str(s) | ExprKind::WStr(s) => Str(s.clone()),
        ExprKind::Typed(ty, inner) => {
            if let Some(elem) = Elem::from_name(&ty.name) {
                let v = const_eval(prog, scope, inner)?;
                match (v, elem) {
                    (Int(i), e) if e.is_real() => Real(i as f64),
                    (Int(i), Elem::Bool) => Bool(i != 0),
                    // `CHAR#'a'`: the character's code.
                    (Str(s), e) if e.is_char() => Int(single_char(&s)?),
                    (v, _) => v,
                }
            } else if let ExprKind::Name(n) = &inner.kind {
                let ei = prog.enums.iter().position(|en| en.name == ty.name)?;
                Int(prog.enums[ei]
                    .values
                    .iter()
                    .find(|(vn, _)| *vn == n.name)?
                    .1 as i128)
            } else {
                return None;
            }
        }
        ExprKind::Name(n) => {
            if let Some(v) = scope.constant(&n.name) {
                return Some(v);
            }
            if let Some(g) = prog.global(&n.name) {
                if g.constant
                    && let Some(Init::Expr(ie)) = &g.init
                {
                    return const_eval(prog, &(), ie);
                }
                return None;
            }
            Int(prog.enum_value(&n.name)?.1 as i128)
        }
        ExprKind::Unary(UnOp::Neg, x) => match const_eval(prog, scope, x)? {
            Int(i) => Int(-i),
            Real(r) => Real(-r),
            Time(t) => Time(-t),
            Temporal(Elem::LTime, t) => Temporal(Elem::LTime, -t),
            _ => return None,
        },
        ExprKind::Unary(UnOp::Not, x) => match const_eval(prog, scope, x)? {
            Bool(b) => Bool(!b),
            Int(i) => Int(!i),
            _ => return None,
        },
        ExprKind::Binary(op, a, b) => {
            let a = const_eval(prog, scope, a)?;
            let b = const_eval(prog, scope, b)?;
            match (a, b) {
                (Int(x), Int(y)) => match op {
                    BinOp::Add => Int(x.checked_add(y)?),
                    BinOp::Sub => Int(x.checked_sub(y)?),
                    BinOp::Mul => Int(x.checked_mul(y)?),
                    BinOp::Div if y != 0 => Int(x.checked_div(y)?),
                    BinOp::Mod if y != 0 => Int(x.checked_rem(y)?),
                    BinOp::And => Int(x & y),
                    BinOp::Or => Int(x | y),
                    BinOp::Xor => Int(x ^ y),
                    BinOp::Eq => Bool(x == y),
                    BinOp::Ne => Bool(x != y),
                    BinOp::Lt => Bool(x < y),
                    BinOp::Le => Bool(x <= y),
                    BinOp::Gt => Bool(x > y),
                    BinOp::Ge => Bool(x >= y),
                    _ => return None,
                },
                (Real(x), Real(y)) => match op {
                    BinOp::Add => Real(x + y),
                    BinOp::Sub => Real(x - y),
                    BinOp::Mul => Real(x * y),
                    BinOp::Div => Real(x / y),
                    _ => return None,
                },
                (Time(x), Time(y)) => match op {
                    BinOp::Add => Time(x.checked_add(y)?),
                    BinOp::Sub => Time(x.checked_sub(y)?),
                    _ => return None,
                },
                (Temporal(Elem::LTime, x), Temporal(Elem::LTime, y)) => match op {
                    BinOp::Add => Temporal(Elem::LTime, x.checked_add(y)?),
                    BinOp::Sub => Temporal(Elem::LTime, x.checked_sub(y)?),
                    _ => return None,
                },
                (Bool(x), Bool(y)) => match op {
                    BinOp::And => Bool(x & y),
                    BinOp::Or => Bool(x | y),
                    BinOp::Xor => Bool(x ^ y),
                    _ => return None,
                },
                _ => return None,
            }
        }
        _ => return None,
    })
}

/// The code of a one-character string (`CHAR#'a'`, `WCHAR#"ä"`).
pub fn single_char(s: &str) -> Option<i128> {
    let mut chars = s.chars();
    let c = chars.next()?;
    chars.next().is_none().then_some(c as i128)
}

/// Local constants of a POU being declared (for bounds like `ARRAY[1..N]` with a VAR CONSTANT N).
struct LocalConsts<'a> {
    prog: &'a Program,
    vars: &'a [VarDef],
}

impl ConstScope for LocalConsts<'_> {
    fn constant(&self, name: &str) -> Option<ConstVal> {
        let v = self.vars.iter().find(|v| v.name == name && v.constant)?;
        match &v.init {
            Some(Init::Expr(e)) => const_eval(self.prog, &(), e),
            _ => None,
        }
    }
}

impl Sema<'_> {
    /// The initial value written in a variable declaration, or else the default of its
    /// named TYPE (`TYPE Color : (Red, Green) := Green; END_TYPE`).
    fn init_of(&self, ty: &TypeRef, init: &Option<Init>) -> Option<Init> {
        if init.is_some() {
            return init.clone();
        }
        // Along a chain of named types, at most one step per type: a cycle (E0020,
        // reported by the type's layout) ends the walk.
        let mut ty = ty;
        for _ in 0..=self.unit.types.len() {
            let TypeRef::Named(id) = ty else {
                return None;
            };
            let decl = self.unit.types.iter().find(|d| d.name.name == id.name)?;
            if decl.init.is_some() {
                return decl.init.clone();
            }
            ty = &decl.ty;
        }
        None
    }

    fn declare_types(&mut self) {
        for d in &self.unit.types {
            if self.type_state.contains_key(&d.name.name) || Elem::from_name(&d.name.name).is_some()
            {
                self.diags.error(
                    codes::DUPLICATE_DEFINITION,
                    d.name.span,
                    format!("type `{}` is already defined", d.name.text),
                );
                continue;
            }
            self.type_state
                .insert(d.name.name.clone(), LayoutState::NotStarted);
        }
        for i in 0..self.unit.types.len() {
            let name = self.unit.types[i].name.name.clone();
            self.resolve_named_type(&name, self.unit.types[i].name.span);
        }
    }

    fn declare_pous(&mut self, prelude_pous: usize) {
        for (i, p) in self.unit.pous.iter().enumerate() {
            if self.prog.pou_by_name.contains_key(&p.name.name)
                || self.type_state.contains_key(&p.name.name)
            {
                self.diags.error(
                    codes::DUPLICATE_DEFINITION,
                    p.name.span,
                    format!("`{}` is already defined", p.name.text),
                );
                continue;
            }
            self.prog
                .pou_by_name
                .insert(p.name.name.clone(), self.prog.pous.len());
            self.prog.pous.push(PouDef {
                kind: p.kind,
                name: p.name.name.clone(),
                text: p.name.text.clone(),
                span: p.name.span,
                ast: i,
                vars: Vec::new(),
                return_type: None,
                frame_size: 0,
                reinit_start: 0,
                builtin: i < prelude_pous,
                state: LayoutState::NotStarted,
                recursive: false,
                member: None,
                base: None,
                class: None,
                is_abstract: p.modifiers.is_abstract,
                is_final: p.modifiers.is_final,
            });
        }
    }

    /// Resolves a TYPE declaration by name (on demand, so declarations may come in any order).
    fn resolve_named_type(&mut self, name: &str, use_span: Span) -> Option<Type> {
        if let Some((t, _)) = self.prog.aliases.get(name) {
            return Some(t.clone());
        }
        match self.type_state.get(name) {
            None => return None,
            Some(LayoutState::InProgress) => {
                let text = self
                    .unit
                    .types
                    .iter()
                    .find(|d| d.name.name == name)
                    .map_or(name, |d| d.name.text.as_str());
                self.diags.error(
                    codes::RECURSIVE_TYPE,
                    use_span,
                    format!("type `{text}` is defined in terms of itself"),
                );
                return Some(Type::Error);
            }
            Some(LayoutState::Done) => return Some(Type::Error),
            Some(LayoutState::NotStarted) => {}
        }
        self.type_state
            .insert(name.to_string(), LayoutState::InProgress);
        let decl = self.unit.types.iter().find(|d| d.name.name == name)?;
        let ty = match &decl.ty {
            TypeRef::Enum { values, .. } => {
                let mut vals: Vec<(String, i64)> = Vec::new();
                let display: Vec<String> = values.iter().map(|(id, _)| id.text.clone()).collect();
                let mut next = 0i64;
                for (id, v) in values {
                    let value = match v {
                        Some(e) => match const_eval(&self.prog, &(), e) {
                            Some(ConstVal::Int(i)) => i as i64,
                            _ => {
                                self.diags.error(
                                    codes::NOT_CONSTANT,
                                    e.span,
                                    "enumeration value must be a constant integer",
                                );
                                next
                            }
                        },
                        None => next,
                    };
                    if vals.iter().any(|(n, _)| *n == id.name) {
                        self.diags.error(
                            codes::DUPLICATE_MEMBER,
                            id.span,
                            format!("duplicate enumeration value `{}`", id.text),
                        );
                    }
                    vals.push((id.name.clone(), value));
                    next = value.wrapping_add(1);
                }
                self.prog.enums.push(EnumDef {
                    name: decl.name.text.clone(),
                    values: vals,
                    display,
                });
                Type::Enum(self.prog.enums.len() - 1)
            }
            TypeRef::Struct { members, .. } => {
                let idx = self.prog.structs.len();
                self.prog.structs.push(StructDef {
                    name: decl.name.text.clone(),
                    members: Vec::new(),
                    size: 0,
                    align: 1,
                });
                self.structs_in_progress.insert(name.to_string(), idx);
                let mut defs = Vec::new();
                let mut off = 0u32;
                let mut align = 1;
                for m in members {
                    self.no_shared_attribute(m, "structure members");
                    self.safe_default(m, &Type::Error, None, None);
                    let mty = self.resolve_type(&m.ty, &[]);
                    if matches!(mty, Type::Fb(_)) {
                        self.diags.error(
                            codes::FB_INSTANCE_NOT_ALLOWED,
                            m.ty.span(),
                            "function block instances cannot be structure members",
                        );
                    }
                    let (sz, al) = self.prog.size_align(&mty);
                    for n in &m.names {
                        if defs.iter().any(|d: &VarDef| d.name == n.name) {
                            self.diags.error(
                                codes::DUPLICATE_MEMBER,
                                n.span,
                                format!("duplicate member `{}`", n.text),
                            );
                        }
                        off = align_up(off, al);
                        defs.push(VarDef {
                            name: n.name.clone(),
                            text: n.text.clone(),
                            span: n.span,
                            ty: mty.clone(),
                            offset: off,
                            kind: VarKind::Local,
                            constant: false,
                            init: self.init_of(&m.ty, &m.init),
                            location: self.location(m, &mty, false),
                            retain: false,
                        });
                        off = off.saturating_add(sz);
                        align = align.max(al);
                    }
                }
                self.structs_in_progress.remove(name);
                let s = &mut self.prog.structs[idx];
                s.members = defs;
                s.size = align_up(off, align);
                s.align = align;
                Type::Struct(idx)
            }
            other => self.resolve_type(other, &[]),
        };
        self.type_state.insert(name.to_string(), LayoutState::Done);
        self.prog
            .aliases
            .insert(name.to_string(), (ty.clone(), decl.init.clone()));
        Some(ty)
    }

    fn const_int(&mut self, e: &Expr, locals: &[VarDef], what: &str) -> Option<i64> {
        let scope = LocalConsts {
            prog: &self.prog,
            vars: locals,
        };
        match const_eval(&self.prog, &scope, e) {
            Some(ConstVal::Int(v)) if v >= i64::MIN as i128 && v <= i64::MAX as i128 => {
                Some(v as i64)
            }
            _ => {
                self.diags.error(
                    codes::NOT_CONSTANT,
                    e.span,
                    format!("{what} must be a constant integer expression"),
                );
                None
            }
        }
    }

    /// The type a name stands for: elementary, declared, an interface or a function block.
    fn resolve_type_name(&mut self, id: &Ident, locals: &[VarDef]) -> Type {
        if let Some(e) = Elem::from_name(&id.name) {
            return Type::Elem(e);
        }
        match id.name.as_str() {
            "STRING" => return Type::String(DEFAULT_STRING_LEN),
            "__EXCEPTION" => return Type::Exception,
            "WSTRING" => return Type::WString(DEFAULT_STRING_LEN),
            _ => {}
        }
        if let Some(t) = self.resolve_named_type(&id.name, id.span) {
            return t;
        }
        if let Some(&i) = self.prog.interface_by_name.get(&id.name) {
            return Type::Interface(i);
        }
        if let Some(&i) = self.prog.pou_by_name.get(&id.name) {
            if self.prog.pous[i].kind == PouKind::FunctionBlock {
                self.layout_pou(i);
                return Type::Fb(i);
            }
            self.diags.error(
                codes::UNKNOWN_TYPE,
                id.span,
                format!("`{}` is not a data type or function block", id.text),
            );
            return Type::Error;
        }
        let declared: Vec<String> = self
            .type_state
            .keys()
            .chain(self.prog.interface_by_name.keys())
            .chain(self.prog.pou_by_name.keys())
            .cloned()
            .collect();
        match qualified(&id.name, declared.iter()) {
            Ok(Some(full)) if full != id.name => {
                let id = Ident {
                    name: full,
                    ..id.clone()
                };
                return self.resolve_type(&TypeRef::Named(id), locals);
            }
            Err(candidates) => {
                self.diags.error(
                    codes::AMBIGUOUS_NAME,
                    id.span,
                    ambiguous(&id.text, &candidates),
                );
                return Type::Error;
            }
            _ => {}
        }
        self.diags.error(
            codes::UNKNOWN_TYPE,
            id.span,
            format!("unknown type `{}`", id.text),
        );
        Type::Error
    }

    /// `BASE(lo..hi)`: an integer subrange, its bounds checked against the base type.
    fn resolve_subrange(
        &mut self,
        t: &TypeRef,
        base: &Ident,
        lo: &Expr,
        hi: &Expr,
        locals: &[VarDef],
    ) -> Type {
        let Some(e) = Elem::from_name(&base.name).filter(|e| e.is_integral()) else {
            self.diags.error(
                codes::INVALID_SUBRANGE,
                base.span,
                "subrange base type must be an integer type",
            );
            return Type::Error;
        };
        let l = self.const_int(lo, locals, "subrange bound");
        let h = self.const_int(hi, locals, "subrange bound");
        match (l, h) {
            (Some(l), Some(h)) if l <= h => {
                let (min, max) = e.int_range();
                if (l as i128) < min || (h as i128) > max {
                    self.diags.error(
                        codes::INVALID_SUBRANGE,
                        t.span(),
                        format!("subrange exceeds the range of {}", e.name()),
                    );
                }
                Type::Subrange(e, l, h)
            }
            (Some(_), Some(_)) => {
                self.diags.error(
                    codes::INVALID_SUBRANGE,
                    t.span(),
                    "subrange lower bound exceeds upper bound",
                );
                Type::Error
            }
            _ => Type::Error,
        }
    }

    /// Resolves a type reference; `locals` supplies constants of the enclosing POU.
    pub(crate) fn resolve_type(&mut self, t: &TypeRef, locals: &[VarDef]) -> Type {
        match t {
            TypeRef::Named(id) => self.resolve_type_name(id, locals),
            TypeRef::String(len, _, wide) => match len {
                None if *wide => Type::WString(DEFAULT_STRING_LEN),
                None => Type::String(DEFAULT_STRING_LEN),
                Some(e) => match self.const_int(e, locals, "string length") {
                    Some(n) if *wide && (1..=32000).contains(&n) => Type::WString(n as u32),
                    Some(_) if *wide => {
                        self.diags.error(
                            codes::STRING_LENGTH,
                            e.span,
                            "WSTRING length must be between 1 and 32000",
                        );
                        Type::Error
                    }
                    Some(n) if (1..=65000).contains(&n) => Type::String(n as u32),
                    Some(_) => {
                        self.diags.error(
                            codes::STRING_LENGTH,
                            e.span,
                            "string length must be between 1 and 65000",
                        );
                        Type::Error
                    }
                    None => Type::Error,
                },
            },
            TypeRef::Array { dims, elem, .. } => {
                let elem_ty = self.resolve_type(elem, locals);
                let mut out = Vec::new();
                for (lo, hi) in dims {
                    let l = self.const_int(lo, locals, "array bound");
                    let h = self.const_int(hi, locals, "array bound");
                    match (l, h) {
                        (Some(l), Some(h))
                            if h >= l && h.checked_sub(l).is_some_and(|d| d < (1 << 24)) =>
                        {
                            out.push((l, h))
                        }
                        (Some(_), Some(_)) => {
                            self.diags.error(codes::ARRAY_BOUNDS, lo.span.to(hi.span), "array upper bound must be >= lower bound (and the array not absurdly large)");
                            return Type::Error;
                        }
                        _ => return Type::Error,
                    }
                }
                let arr = ArrayType {
                    dims: out,
                    elem: elem_ty,
                };
                let (sz, al) = self.prog.size_align(&arr.elem);
                if (align_up(sz, al) as u64).saturating_mul(arr.len()) > MAX_DATA as u64 {
                    self.diags
                        .error(codes::ARRAY_BOUNDS, t.span(), "array too large");
                    return Type::Error;
                }
                Type::Array(Rc::new(arr))
            }
            TypeRef::Subrange { base, lo, hi, .. } => {
                self.resolve_subrange(t, base, lo, hi, locals)
            }
            TypeRef::Ref { kind, target, span } => {
                let t = self.resolve_ref_target(target, locals);
                if matches!(t, Type::Reference(_))
                    || (*kind == RefKind::Reference && matches!(t, Type::Ref(_)))
                {
                    self.diags.error(
                        codes::REFERENCE_TO_REFERENCE,
                        *span,
                        "a REFERENCE TO cannot refer to a reference",
                    );
                    return Type::Error;
                }
                if t.is_error() {
                    return Type::Error;
                }
                match kind {
                    RefKind::Reference => Type::Reference(Box::new(t)),
                    _ => Type::Ref(Box::new(t)),
                }
            }
            TypeRef::Enum { span, .. } | TypeRef::Struct { span, .. } => {
                self.diags.error(
                    codes::ANONYMOUS_TYPE,
                    *span,
                    "anonymous enumerations and structures must be declared in a TYPE block",
                );
                Type::Error
            }
        }
    }

    /// The target type of a reference: like [`Sema::resolve_type`], but a function block or
    /// a structure still being laid out may be referred to (a reference has a fixed size),
    /// which lets a structure or block hold a reference to its own type.
    fn resolve_ref_target(&mut self, t: &TypeRef, locals: &[VarDef]) -> Type {
        if let TypeRef::Named(id) = t {
            if let Some(&i) = self.structs_in_progress.get(&id.name) {
                return Type::Struct(i);
            }
            if let Some(&i) = self.prog.pou_by_name.get(&id.name)
                && self.prog.pous[i].kind == PouKind::FunctionBlock
            {
                return Type::Fb(i);
            }
        }
        self.resolve_type(t, locals)
    }

    /// Declares the variables of one declaration `d` of a VAR block of POU `i` (`inherited`:
    /// the base function block's variables; `constants`: the POU's CONSTANTs).
    fn declare_pou_var(
        &mut self,
        i: usize,
        block: &VarBlock,
        d: &VarDecl,
        constants: &[VarDef],
        inherited: &[VarDef],
        vars: &mut Vec<VarDef>,
    ) {
        let kind = self.prog.pous[i].kind;
        let what = if self.prog.pous[i].member.is_some() {
            "a METHOD"
        } else {
            "a FUNCTION"
        };
        self.no_shared_attribute(d, "variables of a POU (only top-level and CONFIGURATION/RESOURCE VAR_GLOBAL variables are shared)");
        let ty = self.resolve_type(&d.ty, constants);
        if kind == PouKind::Function && matches!(ty, Type::Fb(_)) {
            self.diags.error(
                codes::FB_INSTANCE_NOT_ALLOWED,
                d.ty.span(),
                format!("function block instances are not allowed inside {what}"),
            );
        }
        self.no_abstract_instance(d, &ty);
        if block.kind == VarKind::InOut && d.init.is_some() {
            self.diags.error(
                codes::INOUT_INITIAL_VALUE,
                d.span,
                "VAR_IN_OUT variables cannot have initial values",
            );
        }
        if block.constant && d.init.is_none() {
            self.diags.error(
                codes::CONSTANT_WITHOUT_VALUE,
                d.span,
                "a CONSTANT needs an initial value",
            );
        }
        self.no_retained_reference(block, d, &ty);
        let may_locate = kind == PouKind::Program && block.kind == VarKind::Local;
        let location = self.location(d, &ty, may_locate);
        self.safe_default(d, &ty, location, Some(i));
        for n in &d.names {
            if vars.iter().any(|v| v.name == n.name) {
                self.diags.error(
                    codes::DUPLICATE_VARIABLE,
                    n.span,
                    format!("`{}` is declared twice", n.text),
                );
                continue;
            }
            if inherited.iter().any(|v| v.name == n.name) {
                let msg = format!(
                    "`{}` is already a variable of the base function block",
                    n.text
                );
                self.diags.error(codes::DUPLICATE_VARIABLE, n.span, msg);
                continue;
            }
            vars.push(VarDef {
                name: n.name.clone(),
                text: n.text.clone(),
                span: n.span,
                ty: ty.clone(),
                offset: 0,
                kind: block.kind,
                constant: block.constant,
                init: self.init_of(&d.ty, &d.init),
                location,
                retain: block.retain,
            });
        }
    }

    /// Lays out the frame of POU `i` (recursively for the FB types it contains).
    pub(crate) fn layout_pou(&mut self, i: usize) {
        match self.prog.pous[i].state {
            LayoutState::Done => return,
            LayoutState::InProgress => {
                self.prog.pous[i].recursive = true;
                let span = self.prog.pous[i].span;
                let name = self.prog.pous[i].text.clone();
                let what = if self.prog.pous[i].base.is_some() {
                    format!(
                        "function block `{name}` extends itself or contains an instance of itself"
                    )
                } else {
                    format!("function block `{name}` contains an instance of itself")
                };
                self.diags.error(codes::RECURSIVE_TYPE, span, what);
                return;
            }
            LayoutState::NotStarted => {}
        }
        self.prog.pous[i].state = LayoutState::InProgress;
        let source = crate::classes::pou_source(self.unit, &self.prog.pous[i]);
        let kind = self.prog.pous[i].kind;
        let member_kind = self.prog.pous[i].member.as_ref().map(|m| m.kind);
        if member_kind == Some(MemberKind::Action) {
            // An action runs on its owner's variables and has none of its own.
            let p = &mut self.prog.pous[i];
            p.state = LayoutState::Done;
            return;
        }
        let is_method = member_kind.is_some();
        // Inherited variables keep their place; own ones follow the base's frame. Instances
        // of a class start with its class id.
        let mut inherited: Vec<VarDef> = Vec::new();
        let mut first_offset = 0u32;
        if let Some(b) = self.prog.pous[i].base {
            self.layout_pou(b);
            inherited = self.prog.pous[b].vars.clone();
            first_offset = align_up(self.prog.pous[b].frame_size, 8);
        } else if self.prog.pous[i].class.is_some() {
            first_offset = CLASS_HEADER;
        }
        let mut vars: Vec<VarDef> = Vec::new();
        if let Some(rt) = source.return_type {
            let t = self.resolve_type(rt, &[]);
            if matches!(t, Type::Fb(_)) {
                self.diags.error(
                    codes::FB_INSTANCE_NOT_ALLOWED,
                    rt.span(),
                    "a function cannot return a function block instance",
                );
            }
            self.prog.pous[i].return_type = Some(t.clone());
            // The result variable carries the function's (method's, property's) name, without
            // its namespace.
            let last = |n: &str| n.rsplit('.').next().unwrap_or(n).to_string();
            vars.push(VarDef {
                name: last(&source.name.name),
                text: last(&source.name.text),
                span: source.name.span,
                ty: t,
                offset: 0,
                kind: VarKind::Output,
                constant: false,
                init: None,
                location: None,
                retain: false,
            });
        }
        if member_kind == Some(MemberKind::Setter) {
            // The value being assigned, under the property's name.
            let pou = &self.prog.pous[i];
            let member = pou.member.clone();
            let t = self.property_type_of(member.as_ref());
            vars.push(VarDef {
                name: source.name.name.clone(),
                text: source.name.text.clone(),
                span: source.name.span,
                ty: t,
                offset: 0,
                kind: VarKind::Input,
                constant: false,
                init: None,
                location: None,
                retain: false,
            });
        }
        // The POU's CONSTANTs may size arrays declared before them.
        let constants: Vec<VarDef> = source
            .var_blocks
            .iter()
            .filter(|b| b.constant)
            .flat_map(|b| &b.decls)
            .flat_map(|d| {
                d.names.iter().map(|n| VarDef {
                    name: n.name.clone(),
                    text: n.text.clone(),
                    span: n.span,
                    ty: Type::Error,
                    offset: 0,
                    kind: VarKind::Local,
                    constant: true,
                    init: d.init.clone(),
                    location: None,
                    retain: false,
                })
            })
            .collect();
        for block in source.var_blocks {
            let allowed = match kind {
                PouKind::Program => !matches!(block.kind, VarKind::InOut),
                PouKind::FunctionBlock => !matches!(block.kind, VarKind::Global),
                PouKind::Function => {
                    !matches!(
                        block.kind,
                        VarKind::Global | VarKind::External | VarKind::Output
                    ) || block.kind == VarKind::Output
                }
            };
            if !allowed || (kind != PouKind::Program && block.kind == VarKind::Global) {
                self.diags.error(
                    codes::VAR_BLOCK_NOT_ALLOWED,
                    block.span,
                    "this kind of VAR block is not allowed in this POU",
                );
            }
            for d in &block.decls {
                self.declare_pou_var(i, block, d, &constants, &inherited, &mut vars);
            }
        }
        let (frame_size, reinit_start) =
            frame_layout(&self.prog, &mut vars, kind, is_method, first_offset);
        inherited.extend(vars);
        let p = &mut self.prog.pous[i];
        p.vars = inherited;
        p.frame_size = frame_size;
        p.reinit_start = reinit_start;
        p.state = LayoutState::Done;
    }

    fn declare_globals(&mut self) {
        for block in &self.unit.globals {
            for d in &block.decls {
                let ty = self.resolve_type(&d.ty, &[]);
                if block.constant && d.init.is_none() {
                    self.diags.error(
                        codes::CONSTANT_WITHOUT_VALUE,
                        d.span,
                        "a CONSTANT needs an initial value",
                    );
                }
                self.no_retained_reference(block, d, &ty);
                let location = self.location(d, &ty, true);
                self.safe_default(d, &ty, location, None);
                let shared = self.shared_global(d, block, &ty);
                for n in &d.names {
                    if self.prog.global(&n.name).is_some() {
                        self.diags.error(
                            codes::DUPLICATE_VARIABLE,
                            n.span,
                            format!("global `{}` is declared twice", n.text),
                        );
                        continue;
                    }
                    if let Some(direction) = shared {
                        self.prog.shared.push(SharedGlobal {
                            text: n.text.clone(),
                            direction,
                            span: n.span,
                        });
                    }
                    let (sz, al) = self.prog.size_align(&ty);
                    let addr = self.prog.alloc(sz, al);
                    self.prog.globals.push(VarDef {
                        name: n.name.clone(),
                        text: n.text.clone(),
                        span: n.span,
                        ty: ty.clone(),
                        offset: addr,
                        kind: VarKind::Global,
                        constant: block.constant,
                        init: self.init_of(&d.ty, &d.init),
                        location,
                        retain: block.retain,
                    });
                }
            }
        }
    }

    /// A RETAIN variable cannot hold references: a reference names a variable of this build
    /// of the program, which a warm restart after a download would not have.
    fn no_retained_reference(&mut self, block: &VarBlock, d: &VarDecl, ty: &Type) {
        if block.retain && self.holds_references(ty, 0) {
            self.diags.error(codes::RETAIN_REFERENCE,
                d.ty.span(),
                "a RETAIN variable cannot hold references or interface values (they name variables of this build of the program, which a restart after a download may not have)",
            );
        }
    }

    fn holds_references(&self, ty: &Type, depth: u32) -> bool {
        match ty {
            Type::Ref(_) | Type::Reference(_) | Type::Interface(_) => true,
            Type::Array(a) => self.holds_references(&a.elem, depth),
            Type::Struct(i) => self.prog.structs[*i]
                .members
                .iter()
                .any(|m| self.holds_references(&m.ty, depth)),
            Type::Fb(i) if depth < 32 => self.prog.pous[*i]
                .vars
                .iter()
                .any(|v| v.kind != VarKind::InOut && self.holds_references(&v.ty, depth + 1)),
            _ => false,
        }
    }
}
