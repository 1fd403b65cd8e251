//! The checked form of a program: what code generation consumes.
//!
//! Compilation checks first and emits second. [`sema`](crate::sema) checks the declarations
//! and lays out the data ([`Program`]); [`check`] then checks every body — names, types,
//! l-values, calls, references — reporting every diagnostic and recording what it learns
//! ([`Checked`]): the type of each expression it infers ([`ExprTypes`]), the value of each
//! CASE label ([`CaseLabels`]) and the calls between user POUs, on which
//! [`sema::body`](crate::sema::body) judges the recursion rule. Only a
//! program without diagnostics reaches [`emit`], which starts from those records and reports
//! nothing itself: a diagnostic raised while emitting is a compiler bug (an internal error).
//!
//! The separation is not complete: the body walk itself is still the code generator's
//! ([`crate::codegen::Gen`]), run once with emission and allocation switched off to check and
//! once more to emit. The second walk takes every type it asks for from the table (it never
//! infers: a missing record is an internal error) but re-resolves names, calls and
//! conversions while it emits and passes the same check branches again (none can fail on a
//! checked program). The exceptions so far: the recursion rule lives in `sema::body`; the
//! CASE rules (selector type, label values, empty and overlapping ranges) run in the checking
//! pass only, emission reading the label values from the table; the BOOL condition of IF,
//! WHILE and REPEAT, EXIT outside a loop, a zero FOR step and the assignment rules (read-only
//! target, assignable types, FB instances, the `REF=` target) are checked by the checking
//! pass only (for emission an EXIT outside a loop is an internal error).

use std::collections::HashMap;

use crate::ast::{Expr, Unit};
use crate::codegen::Gen;
use crate::codes;
use crate::diagnostics::{Diagnostics, SourceMap, Span};
use crate::sema::Program;
use crate::sema::body::{self, CallEdge};
use crate::types::Type;

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

/// The value of each CASE label expression (a constant, an enumeration value of the
/// selector's type or an exception name), as the checker resolved it.
pub type CaseLabels = ExprTable<i128>;

/// What checking the bodies records for emission.
#[derive(Debug, Default, Clone)]
pub struct Checked {
    /// The type of every expression the checker inferred.
    pub types: ExprTypes,
    /// The value of every CASE label.
    pub case_labels: CaseLabels,
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
    checker.generate();
    let checked = Checked {
        types: std::mem::take(&mut checker.types),
        calls: std::mem::take(&mut checker.calls),
        case_labels: std::mem::take(&mut checker.case_labels),
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
