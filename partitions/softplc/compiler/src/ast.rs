//! Abstract syntax tree of a Structured Text compilation unit. Every node keeps its [`Span`]
//! so that later phases can point at the exact source position.

use crate::diagnostics::Span;

/// A name as written (`text`) and upper-cased for case-insensitive lookup (`name`).
#[derive(Debug, Clone, PartialEq)]
pub struct Ident {
    pub name: String,
    pub text: String,
    pub span: Span,
}

#[derive(Debug, Default)]
pub struct Unit {
    pub pous: Vec<Pou>,
    pub types: Vec<TypeDecl>,
    /// VAR_GLOBAL blocks at the top level or inside CONFIGURATION/RESOURCE.
    pub globals: Vec<VarBlock>,
    pub configs: Vec<Configuration>,
    pub interfaces: Vec<Interface>,
    /// Actions declared outside their POU (`ACTIONS P ... END_ACTIONS`, `ACTION P.a`).
    pub actions: Vec<(Ident, Action)>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PouKind {
    Program,
    Function,
    FunctionBlock,
}

#[derive(Debug)]
pub struct Pou {
    pub kind: PouKind,
    pub name: Ident,
    /// Return type of a FUNCTION.
    pub return_type: Option<TypeRef>,
    pub var_blocks: Vec<VarBlock>,
    pub body: Vec<Stmt>,
    pub span: Span,
    /// ABSTRACT / FINAL (and an access specifier, accepted and ignored on a POU).
    pub modifiers: Modifiers,
    /// `EXTENDS Base` of a FUNCTION_BLOCK.
    pub extends: Option<Ident>,
    /// `IMPLEMENTS I1, I2` of a FUNCTION_BLOCK.
    pub implements: Vec<Ident>,
    pub methods: Vec<Method>,
    pub properties: Vec<Property>,
    pub actions: Vec<Action>,
    /// Declared as a CLASS (IEC 61131-3 3rd edition): a function block without a body.
    pub is_class: bool,
}

/// Access specifier of a method or property.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Access {
    #[default]
    Public,
    Private,
    Protected,
    Internal,
}

impl Access {
    pub fn keyword(self) -> &'static str {
        match self {
            Access::Public => "PUBLIC",
            Access::Private => "PRIVATE",
            Access::Protected => "PROTECTED",
            Access::Internal => "INTERNAL",
        }
    }
}

/// Modifiers of a POU, method or property.
#[derive(Debug, Clone, Copy, Default)]
pub struct Modifiers {
    pub access: Access,
    pub is_abstract: bool,
    pub is_final: bool,
    pub is_override: bool,
}

/// A METHOD (also the accessors of a PROPERTY, and the declarations of an INTERFACE).
#[derive(Debug, Clone)]
pub struct Method {
    pub name: Ident,
    pub modifiers: Modifiers,
    pub return_type: Option<TypeRef>,
    pub var_blocks: Vec<VarBlock>,
    pub body: Vec<Stmt>,
    pub span: Span,
}

/// A PROPERTY with its GET and SET accessors.
#[derive(Debug, Clone)]
pub struct Property {
    pub name: Ident,
    pub modifiers: Modifiers,
    pub ty: TypeRef,
    pub get: Option<Accessor>,
    pub set: Option<Accessor>,
    pub span: Span,
}

#[derive(Debug, Clone)]
pub struct Accessor {
    pub var_blocks: Vec<VarBlock>,
    pub body: Vec<Stmt>,
    pub span: Span,
}

/// An ACTION: statements run on the variables of its POU.
#[derive(Debug, Clone)]
pub struct Action {
    pub name: Ident,
    pub body: Vec<Stmt>,
    pub span: Span,
}

/// An INTERFACE: method and property declarations.
#[derive(Debug, Clone)]
pub struct Interface {
    pub name: Ident,
    pub extends: Vec<Ident>,
    pub methods: Vec<Method>,
    pub properties: Vec<Property>,
    pub span: Span,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VarKind {
    Local,
    Input,
    Output,
    InOut,
    Global,
    External,
    Temp,
}

#[derive(Debug, Clone)]
pub struct VarBlock {
    pub kind: VarKind,
    pub constant: bool,
    pub retain: bool,
    pub decls: Vec<VarDecl>,
    pub span: Span,
}

#[derive(Debug, Clone)]
pub struct VarDecl {
    pub names: Vec<Ident>,
    /// `AT %IX0.1`: the address text after `%` and its span.
    pub at: Option<(String, Span)>,
    pub ty: TypeRef,
    pub init: Option<Init>,
    pub span: Span,
    /// `{attribute 'shared' := 'write' | 'read'}` before it: a global shared with another
    /// PLC project.
    pub shared: Option<SharedAttr>,
    /// `{attribute 'safe' := 'VALUE'}` before it: the value (as written) a located output
    /// takes when the outputs go safe, and the pragma's span.
    pub safe: Option<(String, Span)>,
}

/// A declaration's `{attribute 'shared'}` pragma.
#[derive(Debug, Clone, Copy)]
pub struct SharedAttr {
    pub direction: plc_vm::image::SharedDirection,
    /// The pragma.
    pub span: Span,
}

#[derive(Debug, Clone)]
pub struct TypeDecl {
    pub name: Ident,
    pub ty: TypeRef,
    pub init: Option<Init>,
}

#[derive(Debug, Clone)]
pub enum TypeRef {
    Named(Ident),
    /// `STRING` or `STRING[n]` / `STRING(n)`; WSTRING when the flag is set.
    String(Option<Box<Expr>>, Span, bool),
    Array {
        dims: Vec<(Expr, Expr)>,
        elem: Box<TypeRef>,
        span: Span,
    },
    Subrange {
        base: Ident,
        lo: Box<Expr>,
        hi: Box<Expr>,
        span: Span,
    },
    Enum {
        values: Vec<(Ident, Option<Expr>)>,
        span: Span,
    },
    Struct {
        members: Vec<VarDecl>,
        span: Span,
    },
    /// `REF_TO T`, `POINTER TO T` (CODESYS) or `REFERENCE TO T` (CODESYS, dereferenced
    /// implicitly).
    Ref {
        kind: RefKind,
        target: Box<TypeRef>,
        span: Span,
    },
}

/// How a reference type was written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefKind {
    /// IEC `REF_TO T`.
    RefTo,
    /// CODESYS `POINTER TO T` (the same checked reference as `REF_TO`).
    Pointer,
    /// CODESYS `REFERENCE TO T`: an alias, dereferenced wherever it is used, bound with `REF=`.
    Reference,
}

impl TypeRef {
    pub fn span(&self) -> Span {
        match self {
            TypeRef::Named(i) => i.span,
            TypeRef::String(_, s, _)
            | TypeRef::Array { span: s, .. }
            | TypeRef::Subrange { span: s, .. }
            | TypeRef::Enum { span: s, .. }
            | TypeRef::Struct { span: s, .. }
            | TypeRef::Ref { span: s, .. } => *s,
        }
    }
}

/// Initial value: a plain expression, an array initialiser `[1, 2, 3(0)]` or a structure
/// initialiser `(a := 1, b := 2)`.
#[derive(Debug, Clone)]
pub enum Init {
    Expr(Expr),
    Array(Vec<ArrayInitItem>, Span),
    Struct(Vec<(Ident, Init)>, Span),
}

impl Init {
    pub fn span(&self) -> Span {
        match self {
            Init::Expr(e) => e.span,
            Init::Array(_, s) | Init::Struct(_, s) => *s,
        }
    }
}

#[derive(Debug, Clone)]
pub struct ArrayInitItem {
    /// Repetition count of `n(value)`; 1 for a plain value.
    pub repeat: u64,
    pub value: Option<Init>,
}

#[derive(Debug)]
pub struct Configuration {
    pub name: Ident,
    pub resources: Vec<Resource>,
}

#[derive(Debug)]
pub struct Resource {
    pub name: Ident,
    pub tasks: Vec<TaskDecl>,
    pub programs: Vec<ProgramBinding>,
}

#[derive(Debug)]
pub struct TaskDecl {
    pub name: Ident,
    pub interval: Option<Expr>,
    pub single: Option<Expr>,
    pub priority: Option<Expr>,
}

#[derive(Debug)]
pub struct ProgramBinding {
    pub instance: Ident,
    pub task: Option<Ident>,
    pub program_type: Ident,
}

#[derive(Debug, Clone)]
pub struct Stmt {
    pub kind: StmtKind,
    pub span: Span,
}

#[derive(Debug, Clone)]
pub enum StmtKind {
    Assign {
        target: Expr,
        value: Expr,
    },
    /// `r REF= x`: binds a `REFERENCE TO` variable.
    RefAssign {
        target: Expr,
        value: Expr,
    },
    /// A call used as a statement: FB instance call or function call.
    Call(Expr),
    If {
        branches: Vec<(Expr, Vec<Stmt>)>,
        else_body: Option<Vec<Stmt>>,
    },
    Case {
        selector: Expr,
        arms: Vec<CaseArm>,
        else_body: Option<Vec<Stmt>>,
    },
    For {
        var: Ident,
        from: Expr,
        to: Expr,
        by: Option<Expr>,
        body: Vec<Stmt>,
    },
    While {
        cond: Expr,
        body: Vec<Stmt>,
    },
    Repeat {
        body: Vec<Stmt>,
        until: Expr,
    },
    Exit,
    Return,
    Try {
        body: Vec<Stmt>,
        catch_var: Option<Ident>,
        catch_body: Vec<Stmt>,
        finally_body: Vec<Stmt>,
    },
    Empty,
}

#[derive(Debug, Clone)]
pub struct CaseArm {
    pub labels: Vec<CaseLabel>,
    pub body: Vec<Stmt>,
}

#[derive(Debug, Clone)]
pub enum CaseLabel {
    Value(Expr),
    Range(Expr, Expr),
}

#[derive(Debug, Clone)]
pub struct Expr {
    pub kind: ExprKind,
    pub span: Span,
}

#[derive(Debug, Clone)]
pub enum ExprKind {
    Int(u128),
    Real(f64),
    Bool(bool),
    Str(String),
    /// `"..."`: a WSTRING literal.
    WStr(String),
    Time(i128),
    /// A date/time literal other than TIME (`LT#`, `D#`, `TOD#`, `DT#`, ...): its type and
    /// nanoseconds.
    Temporal(crate::types::Elem, i128),
    /// `TYPE#literal`, e.g. `INT#5`, `REAL#1`, `Color#Red`.
    Typed(Ident, Box<Expr>),
    Name(Ident),
    Member(Box<Expr>, Ident),
    Index(Box<Expr>, Vec<Expr>),
    /// Partial access of a bit string or integer: `x.3` and `x.%X3` (bit 3), `x.%B1`
    /// (byte 1), `x.%W0`, `x.%D1`, `x.%L0`; `width` in bits, `index` counted in units of it.
    Bits {
        base: Box<Expr>,
        width: u8,
        index: u32,
    },
    Call {
        callee: Box<Expr>,
        args: Vec<Arg>,
    },
    Unary(UnOp, Box<Expr>),
    Binary(BinOp, Box<Expr>, Box<Expr>),
    /// `e^`: the variable a reference refers to.
    Deref(Box<Expr>),
    /// `NULL`: the reference to nothing.
    Null,
    /// `THIS`: a reference to the function-block instance a body, method or action runs on.
    This,
    /// `SUPER`: `THIS` seen as an instance of the base function block (`SUPER^.m()`,
    /// `SUPER^()`).
    Super,
    /// Placeholder produced after a syntax error so parsing can continue.
    Error,
}

#[derive(Debug, Clone)]
pub struct Arg {
    /// `name := value` (input) or `name => var` (output) when named.
    pub name: Option<Ident>,
    pub output: bool,
    pub value: Expr,
    pub span: Span,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnOp {
    Neg,
    Not,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinOp {
    Or,
    Xor,
    And,
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
    Add,
    Sub,
    Mul,
    Div,
    Mod,
    Pow,
}

impl BinOp {
    pub fn symbol(self) -> &'static str {
        match self {
            BinOp::Or => "OR",
            BinOp::Xor => "XOR",
            BinOp::And => "AND",
            BinOp::Eq => "=",
            BinOp::Ne => "<>",
            BinOp::Lt => "<",
            BinOp::Le => "<=",
            BinOp::Gt => ">",
            BinOp::Ge => ">=",
            BinOp::Add => "+",
            BinOp::Sub => "-",
            BinOp::Mul => "*",
            BinOp::Div => "/",
            BinOp::Mod => "MOD",
            BinOp::Pow => "**",
        }
    }
}
