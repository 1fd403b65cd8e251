//! The checked form of a program: what code generation consumes.
//!
//! Compilation checks first and emits second. [`sema`](crate::sema) checks the declarations
//! and lays out the data ([`Program`]); [`check`] then checks the declared initial values
//! (`sema::init`) and every body — statements, names, types, l-values,
//! calls, references — reporting every diagnostic and recording what it learns
//! ([`Checked`]): the type of each expression it infers ([`ExprTypes`]), what the callee of
//! each call is ([`Callees`]), the variable each name denotes ([`Variables`]), the member
//! each `base.m` denotes ([`Members`]), what each bare name denotes ([`BareNames`]: a
//! variable, a property, an enumeration value, an exception; also the value of each
//! `Enum#value`), which argument of each call binds which parameter ([`Bindings`]), the
//! order of each standard-function call's arguments ([`StdArguments`]) and the type each
//! generic standard function is called at ([`GenericTypes`]), how each conversion's
//! argument reaches its source type ([`ConversionArguments`]), what each implicit
//! conversion takes ([`Coercions`]), the property (receiver and accessors) each member read
//! and assignment target reaches, if any ([`Properties`]), the argument list of each
//! property write ([`SetterArguments`]), the variable each `REF()`/`ADR()` and VAR_IN_OUT
//! argument is part of ([`Roots`], for the object table), what each operator does by the
//! rules of [`sema::ops`](crate::sema::ops) ([`Operations`]), the value of each CASE label
//! ([`CaseLabels`]) and the calls between user POUs, on which
//! [`sema::body`](crate::sema::body) judges the recursion rule. Only a program without
//! diagnostics reaches [`emit`], which starts from those records and reports nothing
//! itself: a diagnostic raised while emitting is a compiler bug (an internal error).
//!
//! The checking pass is a walk of its own, in `sema`, one checker a construct: statements
//! (`sema::stmt`), expressions (literals, names, operators, implicit
//! conversions: `sema::expr`), places
//! (`sema::place`), calls (`sema::call`),
//! methods and properties (`sema::class`), references
//! (`sema::refs`), standard functions
//! (`sema::stdcall`) and initial values. The code generator
//! ([`crate::codegen`]) checks nothing and decides nothing a rule decides: it takes every
//! type it asks for from the records (a missing one is an internal error), every callee,
//! variable, member, bare name, binding, argument order, generic type, conversion,
//! property and operation, and only picks the instructions. What both passes need to
//! know the same way — where a place lies (`codegen::Place`), which standard
//! functions there are and their inputs, a constant's cell — is written once and used by
//! both. Both walk one context (`codegen::Gen`: the program, the POU walked, the
//! records), the checker with `check_only` set, which it never emits nor allocates with.
//! An expression the checker walks a second time only to infer its type (diagnostics off,
//! `Gen::dry`) records only what no real walk has, as the type its context expects may
//! differ.

use std::collections::HashMap;

use std::rc::Rc;

use crate::ast::{Arg, Expr, Ident, Unit};
use crate::codegen::Gen;
use crate::codes;
use crate::diagnostics::{Diagnostics, SourceMap, Span};
use crate::sema::body::{self, CallEdge};
use crate::sema::ops::Operation;
use crate::sema::stdfuncs::ConversionArgument;
use crate::sema::{InterfaceMember, Program, VarDef};
use crate::types::{Implicit, Type};

/// A value per expression of the bodies, keyed by the expression (its address in the syntax
/// tree, which lives as long as the compilation, and its span).
#[derive(Debug, Clone)]
pub struct ExprTable<T> {
    map: HashMap<(usize, Span), T>,
}

impl<T> Default for ExprTable<T> {
    fn default() -> Self {
        ExprTable {
            map: HashMap::new(),
        }
    }
}

impl<T> ExprTable<T> {
    fn key(e: &Expr) -> (usize, Span) {
        (e as *const Expr as usize, e.span)
    }

    /// The value recorded for `e`, if any.
    pub fn of(&self, e: &Expr) -> Option<&T> {
        self.map.get(&Self::key(e))
    }

    pub(crate) fn record(&mut self, e: &Expr, v: T) {
        self.map.insert(Self::key(e), v);
    }

    /// How many expressions have a record.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

/// The type of each expression the checker inferred.
pub type ExprTypes = ExprTable<Type>;

/// What each operation does ([`crate::sema::ops`]), keyed by its first operand (an
/// operator's, or a standard function's such as ADD: an expression is the first operand of
/// at most one).
pub type Operations = ExprTable<Operation>;

/// A variable whose address a program takes: what the object table must list.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Root {
    /// A global variable (upper-case name).
    Global(String),
    /// A variable of a POU (in every instance or frame of it).
    Var(usize, String),
    /// A `VAR_IN_OUT` parameter of a POU: the caller's variable.
    InOut(usize, String),
}

/// The variable each `REF()`/`ADR()` argument and each VAR_IN_OUT argument is part of
/// (none where it is reached through a reference, whose object already bounds it).
pub type Roots = ExprTable<Root>;

/// The argument list a property write passes to its SET accessor, keyed by the value
/// written: made once, by the checker, so that emission walks the very expressions whose
/// records the checker left (the records are keyed by the expressions' addresses).
pub type SetterArguments = ExprTable<Rc<[Arg; 1]>>;

/// The value of each CASE label expression (a constant, an enumeration value of the
/// selector's type or an exception name), as the checker resolved it.
pub type CaseLabels = ExprTable<i128>;

/// What the callee of a call resolved to: which kind of call it is and, for functions, which
/// POU or standard function it calls. Keyed by the callee expression.
#[derive(Debug, Clone)]
pub enum Callee {
    /// `REF`, `ADR` or `__ISVALIDREF` (no user POU of that name).
    RefFunction(Ident),
    /// A METHOD or action.
    Method(Method),
    /// A user FUNCTION (its POU index).
    Function(usize),
    /// A standard function, by its name without namespace.
    Standard(Ident),
    /// The body of a function block instance: the callee expression itself, or the
    /// namespace-qualified name it stands for.
    Instance(Option<Ident>),
}

/// The METHOD or action a call calls.
#[derive(Debug, Clone)]
pub enum Method {
    /// One of the class whose body is walked (`m(...)`): its POU.
    Own(usize),
    /// One of an instance (`base.m(...)`): its POU, as the instance's static type finds it
    /// (the call may still be dispatched to an override).
    OfInstance(usize),
    /// One of interface `.0`, as that interface (or one it extends) declares it.
    OfInterface(usize, Box<InterfaceMember>),
}

/// The callee of each call.
pub type Callees = ExprTable<Callee>;

/// The variable a name denotes, as the checker resolved it.
#[derive(Debug, Clone)]
pub enum Variable {
    /// A variable of the frame the POU runs on: declared by the POU itself (`own`; a
    /// METHOD's own variables are in its static frame) or by the block that owns the METHOD
    /// or action.
    Frame { var: VarDef, own: bool },
    /// Global `index` of the program, named directly or through a VAR_EXTERNAL (not
    /// writable when either declaration is CONSTANT).
    Global { index: usize, writable: bool },
}

/// What the checker resolved for each name of a kind in the bodies, keyed by the POU whose
/// body it is in, the name's span and the name (a name copied into an expression the walk
/// builds, such as the argument of an implicit `REF`, is the same name).
#[derive(Debug, Clone)]
pub struct NameTable<T> {
    map: HashMap<(usize, Span, String), T>,
}

impl<T> Default for NameTable<T> {
    fn default() -> Self {
        NameTable {
            map: HashMap::new(),
        }
    }
}

impl<T> NameTable<T> {
    /// What `name` resolved to in the body of POU `pou`, if recorded.
    pub fn of(&self, pou: usize, name: &Ident) -> Option<&T> {
        self.map.get(&(pou, name.span, name.name.clone()))
    }

    pub(crate) fn record(&mut self, pou: usize, name: &Ident, v: T) {
        self.map.insert((pou, name.span, name.name.clone()), v);
    }

    /// How many names have a record.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

/// The variable each name denotes.
pub type Variables = NameTable<Variable>;

/// What the member name of `base.m` denotes, as the checker resolved it.
#[derive(Debug, Clone)]
pub enum Member {
    /// A member of a structure, `offset` bytes into it.
    Field { offset: u32, ty: Type },
    /// A variable of a function block instance, `offset` bytes into it; `writable` when it
    /// may be written through this access (a writable instance given).
    Var {
        offset: u32,
        ty: Type,
        writable: bool,
    },
    /// A VAR_IN_OUT of the block itself (`THIS^.x`): the variable the name denotes.
    OwnInOut,
}

/// The member each member name (`m` of `base.m`) denotes.
pub type Members = NameTable<Member>;

/// What a bare name in an expression (one that is not called) denotes, as the checker
/// decided: variables shadow properties, properties shadow enumeration values (of the
/// expected enumeration first) and exception names.
#[derive(Debug, Clone, PartialEq)]
pub enum Bare {
    /// A variable (which one is in [`Variables`]), or nothing (reported as unknown).
    Variable,
    /// A property of `class`, the class whose body it is in, read through its GET
    /// accessor `getter` (`None`: the property is write-only, reported).
    Property { class: usize, getter: Option<usize> },
    /// Value `value` of enumeration `ty`.
    EnumValue { ty: usize, value: i64 },
    /// An exception name (a trap): its code.
    Exception(i64),
}

/// What each bare name denotes.
pub type BareNames = NameTable<Bare>;

/// One argument of a call bound to a parameter of the callee.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Binding {
    /// The parameter: its index among the variables the callee declares (in frame order).
    pub param: usize,
    /// The argument: its index in the call's argument list.
    pub arg: usize,
    /// An output (`param => target`).
    pub output: bool,
}

/// How the arguments of each call with arguments are bound, as the checker bound them (in
/// the order given, wrong arguments left out), keyed by the POU whose body it is in and the
/// span of the call's first argument.
#[derive(Debug, Default, Clone)]
pub struct Bindings {
    map: HashMap<(usize, Span), Vec<Binding>>,
}

impl Bindings {
    /// The binding of the call whose first argument is at `first` in the body of POU `pou`.
    pub fn of(&self, pou: usize, first: Span) -> Option<&[Binding]> {
        self.map.get(&(pou, first)).map(Vec::as_slice)
    }

    pub(crate) fn record(&mut self, pou: usize, first: Span, binding: Vec<Binding>) {
        self.map.insert((pou, first), binding);
    }

    /// How many calls have a record.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

/// The arguments of each standard-function call in the order of the function's inputs (the
/// index of each in the call's argument list), keyed by the called name.
pub type StdArguments = NameTable<Vec<usize>>;

/// The type each call of a generic standard function without a typed form is called at,
/// keyed by the called name: a selection function's (SEL, MAX, MIN, LIMIT, MUX) the common
/// type of its arguments; by the rules of [`crate::sema::stdfuncs`], a REAL function's
/// (SQRT, ..., EXPT, ATAN2, TRUNC) REAL or LREAL, the type ABS, SHL, SHR, ROL and ROR
/// compute in, the kind of string a string function (LEN, ..., CONCAT) works on and the
/// type a generic conversion (`TO_INT`) converts from.
pub type GenericTypes = NameTable<Type>;

/// What each value converted implicitly where another type is wanted takes (an argument, an
/// assigned value, an output bound to a variable), keyed by the value.
pub type Coercions = ExprTable<Implicit>;

/// How the argument of each conversion between elementary types (`INT_TO_REAL`, and
/// `TO_REAL` of an INT) reaches the source type, keyed by the called name.
pub type ConversionArguments = NameTable<ConversionArgument>;

/// What a method or property is called on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Receiver {
    /// A function-block instance of static type `class`; `exact` when it cannot be an
    /// instance of a derived block; `superclass` for `SUPER^`.
    Instance {
        class: usize,
        exact: bool,
        superclass: bool,
    },
    /// An interface value.
    Interface(usize),
}

/// A GET or SET accessor of a property.
#[derive(Debug, Clone)]
pub enum Accessor {
    /// Of a block: its POU (the call may still be dispatched to an override).
    Pou(usize),
    /// Of an interface, as it (or one it extends) declares it.
    Interface(Box<InterfaceMember>),
}

/// A property an access (`base.p`, or `p` in a block's own body) reaches.
#[derive(Debug, Clone)]
pub struct PropertyAccess {
    pub recv: Receiver,
    /// The GET accessor (`None`: write-only).
    pub getter: Option<Accessor>,
    /// The SET accessor (`None`: read-only).
    pub setter: Option<Accessor>,
}

/// For each name read as `base.m` or written as `m` or `base.m`, the property it reaches or
/// `None` when it is no property.
pub type Properties = NameTable<Option<PropertyAccess>>;

/// What checking the bodies records for emission.
#[derive(Debug, Default, Clone)]
pub struct Checked {
    /// The type of every expression the checker inferred.
    pub types: ExprTypes,
    /// What the callee of every call resolved to.
    pub callees: Callees,
    /// The variable every name denotes.
    pub variables: Variables,
    /// The member every member name denotes.
    pub members: Members,
    /// What every bare name in an expression denotes.
    pub bare_names: BareNames,
    /// How the arguments of every call are bound to the callee's parameters.
    pub bindings: Bindings,
    /// The order of every standard-function call's arguments.
    pub std_arguments: StdArguments,
    /// The type every generic standard function is called at.
    pub generic_types: GenericTypes,
    /// What every implicit conversion takes.
    pub coercions: Coercions,
    /// How the argument of every conversion between elementary types reaches its source.
    pub conversion_arguments: ConversionArguments,
    /// What every operator does.
    pub operations: Operations,
    /// Whether each member read and each assignment target is a property, and which.
    pub properties: Properties,
    /// The value of every CASE label.
    pub case_labels: CaseLabels,
    /// The argument list of every property write.
    pub setter_arguments: SetterArguments,
    /// The variable every `REF()`/`ADR()` and VAR_IN_OUT argument is part of.
    pub roots: Roots,
    /// The calls between user POUs (the call graph the recursion rule is judged on).
    pub calls: Vec<CallEdge>,
}

/// Checks every body of `prog`: reports the diagnostics into `diags` and returns what it
/// recorded. Allocates nothing: `prog` is left as `sema` laid it out.
pub fn check(
    prog: &mut Program,
    unit: &Unit,
    sources: &SourceMap,
    diags: &mut Diagnostics,
) -> Checked {
    let mut checker = Gen::new(prog, unit, sources, diags);
    checker.check_only = true;
    crate::sema::init::check_initial_values(&mut checker);
    for pou in 0..checker.prog.pous.len() {
        crate::sema::stmt::check_pou(&mut checker, pou);
    }
    let checked = Checked {
        types: std::mem::take(&mut checker.types),
        calls: std::mem::take(&mut checker.calls),
        case_labels: std::mem::take(&mut checker.case_labels),
        callees: std::mem::take(&mut checker.callees),
        variables: std::mem::take(&mut checker.variables),
        members: std::mem::take(&mut checker.members),
        bare_names: std::mem::take(&mut checker.bare_names),
        bindings: std::mem::take(&mut checker.bindings),
        std_arguments: std::mem::take(&mut checker.std_arguments),
        generic_types: std::mem::take(&mut checker.generic_types),
        coercions: std::mem::take(&mut checker.coercions),
        conversion_arguments: std::mem::take(&mut checker.conversion_arguments),
        operations: std::mem::take(&mut checker.operations),
        properties: std::mem::take(&mut checker.properties),
        setter_arguments: std::mem::take(&mut checker.setter_arguments),
        roots: std::mem::take(&mut checker.roots),
    };
    drop(checker);
    body::check_recursion(prog, &checked.calls, diags);
    checked
}

/// What the emission pass produces: the image builder with every POU, the initial data and
/// the ids the image gives the POUs and the source files.
pub struct Emitted {
    pub builder: plc_vm::image::ImageBuilder,
    pub init: Vec<u8>,
    pub pou_ids: Vec<plc_vm::image::PouId>,
    pub file_ids: Vec<u16>,
}

/// Emits the bytecode of a checked program (one that [`check`] found no error in), starting
/// from its expression types. A diagnostic here means the checker missed an error: it is
/// returned as an internal error.
pub fn emit(
    prog: &mut Program,
    unit: &Unit,
    sources: &SourceMap,
    checked: Checked,
) -> Result<Emitted, Diagnostics> {
    let mut missed = Diagnostics::default();
    let mut generator = Gen::new(prog, unit, sources, &mut missed);
    generator.types = checked.types;
    generator.case_labels = checked.case_labels;
    generator.callees = checked.callees;
    generator.variables = checked.variables;
    generator.members = checked.members;
    generator.bare_names = checked.bare_names;
    generator.bindings = checked.bindings;
    generator.std_arguments = checked.std_arguments;
    generator.generic_types = checked.generic_types;
    generator.coercions = checked.coercions;
    generator.conversion_arguments = checked.conversion_arguments;
    generator.operations = checked.operations;
    generator.properties = checked.properties;
    generator.setter_arguments = checked.setter_arguments;
    generator.roots = checked.roots;
    generator.generate();
    let emitted = Emitted {
        builder: std::mem::take(&mut generator.b),
        init: std::mem::take(&mut generator.init),
        pou_ids: generator.pou_ids.clone(),
        file_ids: generator.file_ids.clone(),
    };
    drop(generator);
    if missed.is_empty() {
        return Ok(emitted);
    }
    let mut internal = Diagnostics::default();
    for d in missed.list {
        if d.code == codes::INTERNAL_ERROR {
            internal.push(d);
            continue;
        }
        internal.error(
            codes::INTERNAL_ERROR,
            d.span,
            format!(
                "internal error: code generation found an error the checker missed: {}",
                d.message
            ),
        );
    }
    Err(internal)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Options, lexer, parser, sema};

    const PROGRAM: &str = "
TYPE Color : (Red, Green); END_TYPE
FUNCTION Twice : INT VAR_INPUT x : INT; END_VAR Twice := x * 2; END_FUNCTION
FUNCTION_BLOCK Count VAR_INPUT step : INT; END_VAR VAR_OUTPUT n : INT; END_VAR
METHOD Reset n := 0; END_METHOD
PROPERTY Total : INT GET Total := n; END_GET END_PROPERTY
n := n + step;
END_FUNCTION_BLOCK
PROGRAM Main
VAR c : Count; r : INT; p : REF_TO INT; k : Color; END_VAR
r := Twice(ABS(-3));
r := MAX(r, 1);
c(step := r);
r := c.n;
r := c.Total;
c.Reset();
p := REF(r);
k := Color#Green;
END_PROGRAM
";

    /// Checks [`PROGRAM`], lets `forget` drop part of the record, then emits.
    fn check_then_emit(forget: impl FnOnce(&mut Checked)) -> Result<Emitted, Diagnostics> {
        check_then_emit_source(PROGRAM, forget)
    }

    /// Checks `source`, lets `forget` drop part of the record, then emits.
    fn check_then_emit_source(
        source: &str,
        forget: impl FnOnce(&mut Checked),
    ) -> Result<Emitted, Diagnostics> {
        let mut sources = SourceMap::default();
        sources.add("main.st", source);
        let mut raw = Vec::new();
        let unit = parser::parse(lexer::lex(0, source, &mut raw), &mut raw);
        assert!(raw.is_empty(), "{raw:?}");
        let mut diags = Diagnostics::default();
        let mut prog = sema::analyse(&unit, 0, &Options::default(), &mut diags);
        let mut checked = check(&mut prog, &unit, &sources, &mut diags);
        assert!(diags.is_empty(), "{:?}", diags.list);
        forget(&mut checked);
        emit(&mut prog, &unit, &sources, checked)
    }

    fn internal_errors(result: Result<Emitted, Diagnostics>) -> Vec<String> {
        match result {
            Ok(_) => Vec::new(),
            Err(d) => d.list.into_iter().map(|d| d.message).collect(),
        }
    }

    #[test]
    fn emission_resolves_no_callee_itself() {
        assert!(check_then_emit(|_| {}).is_ok());
        let errors = internal_errors(check_then_emit(|c| c.callees = Callees::default()));
        // Twice(...), MAX(...), c(...), c.Reset() and REF(...): each is taken from the
        // checker's record (ABS(...) too, but it is an argument of Twice, not walked once
        // Twice has no callee).
        assert_eq!(errors.len(), 5, "{errors:?}");
        assert!(errors.iter().all(|e| e.contains("resolved no callee")));
    }

    #[test]
    fn emission_resolves_no_member_itself() {
        let errors = internal_errors(check_then_emit(|c| c.members = Members::default()));
        // `c.n`.
        assert!(errors[0].contains("resolved no member"), "{errors:?}");
    }

    #[test]
    fn emission_decides_no_bare_name_itself() {
        let errors = internal_errors(check_then_emit(|c| c.bare_names = BareNames::default()));
        // `x`, `n` and `step` in the bodies, `r` in Main, `Green` of `Color#Green`: none is
        // looked up again.
        assert!(
            errors.iter().any(|e| e.contains("no enumeration value")),
            "{errors:?}"
        );
        assert!(
            errors.iter().all(|e| e.contains("resolved no meaning")
                || e.contains("recorded no type")
                || e.contains("no enumeration value")),
            "{errors:?}"
        );
    }

    #[test]
    fn emission_binds_no_argument_itself() {
        let errors = internal_errors(check_then_emit(|c| c.bindings = Bindings::default()));
        // Twice(ABS(-3)) and c(step := r); ABS is a standard function, bound where it is
        // emitted.
        assert_eq!(errors.len(), 2, "{errors:?}");
        assert!(errors.iter().all(|e| e.contains("bound no arguments")));
    }

    #[test]
    fn emission_places_no_standard_argument_itself() {
        let errors = internal_errors(check_then_emit(|c| {
            c.std_arguments = StdArguments::default()
        }));
        // ABS(-3) and MAX(r, 1).
        assert_eq!(errors.len(), 2, "{errors:?}");
        assert!(errors.iter().all(|e| e.contains("placed no arguments")));
    }

    #[test]
    fn emission_decides_no_generic_type_itself() {
        let errors = internal_errors(check_then_emit(|c| {
            c.generic_types = GenericTypes::default()
        }));
        // MAX(r, 1) and ABS(-3).
        assert_eq!(errors.len(), 2, "{errors:?}");
        assert!(errors.iter().all(|e| e.contains("decided no type")));
        // The REAL functions' types are recorded too (a typed form needs none), ABS's,
        // SHL's, a string function's kind and the type a generic conversion converts from.
        let standard_functions = "PROGRAM Main VAR i : INT; d : DINT; r : REAL; l : LREAL; END_VAR
r := SQRT(i); l := EXPT(d, 2); d := TRUNC(l); r := SIN_REAL(r); l := TO_LREAL(i);
i := ABS(i); d := SHL(d, 2); i := LEN('abc'); END_PROGRAM";
        assert!(check_then_emit_source(standard_functions, |_| {}).is_ok());
        let errors = internal_errors(check_then_emit_source(standard_functions, |c| {
            c.generic_types = GenericTypes::default()
        }));
        assert_eq!(errors.len(), 7, "{errors:?}");
        assert!(errors.iter().all(|e| e.contains("decided no type")));
    }

    #[test]
    fn emission_decides_no_implicit_conversion_itself() {
        let widening = "PROGRAM Main VAR i : INT; d : DINT; r : REAL; l : LREAL; p : REF_TO INT;
u : ULINT; END_VAR d := i; l := r; r := i; p := REF(i); u := p; END_PROGRAM";
        assert!(check_then_emit_source(widening, |_| {}).is_ok());
        let errors = internal_errors(check_then_emit_source(widening, |c| {
            c.coercions = Coercions::default()
        }));
        // `i`, `r`, `i` and `p` (an address widened); `REF(i)` is a REF_TO INT already.
        assert_eq!(errors.len(), 4, "{errors:?}");
        assert!(
            errors
                .iter()
                .all(|e| e.contains("decided no implicit conversion"))
        );
    }

    #[test]
    fn emission_decides_no_conversion_itself() {
        let conversions = "PROGRAM Main VAR i : INT; d : DINT; r : REAL; l : LREAL; END_VAR
r := INT_TO_REAL(i); i := DINT_TO_INT(l); l := TO_LREAL(d); d := TIME_TO_DINT(T#1s);
END_PROGRAM";
        assert!(check_then_emit_source(conversions, |_| {}).is_ok());
        let errors = internal_errors(check_then_emit_source(conversions, |c| {
            c.conversion_arguments = ConversionArguments::default()
        }));
        assert_eq!(errors.len(), 4, "{errors:?}");
        assert!(errors.iter().all(|e| e.contains("decided no conversion")));
    }

    #[test]
    fn emission_decides_no_operation_itself() {
        let errors = internal_errors(check_then_emit(|c| c.operations = Operations::default()));
        // `x * 2` and `n + step`.
        assert_eq!(errors.len(), 2, "{errors:?}");
        assert!(errors.iter().all(|e| e.contains("decided no operation")));
    }

    #[test]
    fn emission_resolves_no_property_itself() {
        let errors = internal_errors(check_then_emit(|c| c.properties = Properties::default()));
        // Every member read (`c.n`, `c.Total`) and every assignment target is asked about;
        // `c.Total`, no longer a property, is then no member either.
        assert!(errors.len() >= 2, "{errors:?}");
        assert!(
            errors
                .iter()
                .all(|e| e.contains("whether this is a property")
                    || e.contains("resolved no member")),
            "{errors:?}"
        );
    }

    #[test]
    fn emission_resolves_no_variable_itself() {
        let errors = internal_errors(check_then_emit(|c| c.variables = Variables::default()));
        // Each name fails first; the expressions built on it then have no type either.
        assert!(errors[0].contains("resolved no variable"), "{errors:?}");
        assert!(
            errors
                .iter()
                .all(|e| e.contains("resolved no variable") || e.contains("recorded no type")),
            "{errors:?}"
        );
    }
}
