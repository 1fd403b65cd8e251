//! The checked form of a program: what code generation consumes.
//!
//! Compilation checks first and emits second. [`sema`](crate::sema) checks the declarations
//! and lays out the data ([`Program`]); [`check`] then checks every body — names, types,
//! l-values, calls, references, the recursion rule — reporting every diagnostic and recording
//! the type of each expression it infers ([`ExprTypes`]). Only a program without diagnostics
//! reaches [`emit`], which starts from those types and reports nothing itself: a diagnostic
//! raised while emitting is a compiler bug (an internal error).
//!
//! Today both passes run the same body walker ([`crate::codegen::Gen`]), the checking one with
//! emission and allocation switched off.

use std::collections::HashMap;

use crate::ast::{Expr, Unit};
use crate::codegen::Gen;
use crate::codes;
use crate::diagnostics::{Diagnostics, SourceMap, Span};
use crate::sema::Program;
use crate::types::Type;

/// The type of each expression of the bodies, keyed by the expression (its address in the
/// syntax tree, which lives as long as the compilation, and its span).
#[derive(Debug, Default, Clone)]
pub struct ExprTypes {
    map: HashMap<(usize, Span), Type>,
}

impl ExprTypes {
    fn key(e: &Expr) -> (usize, Span) {
        (e as *const Expr as usize, e.span)
    }

    /// The type recorded for `e`, if it was inferred.
    pub fn of(&self, e: &Expr) -> Option<&Type> {
        self.map.get(&Self::key(e))
    }

    pub(crate) fn record(&mut self, e: &Expr, t: Type) {
        self.map.insert(Self::key(e), t);
    }

    /// How many expressions have a recorded type.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

/// Checks every body of `prog`: reports the diagnostics into `diags` and returns the types of
/// the expressions. Allocates nothing: `prog` is left as `sema` laid it out.
pub fn check(
    prog: &mut Program,
    unit: &Unit,
    sources: &SourceMap,
    diags: &mut Diagnostics,
) -> ExprTypes {
    let mut checker = Gen::new(prog, unit, sources, diags);
    checker.check_only = true;
    checker.generate();
    std::mem::take(&mut checker.types)
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
    types: ExprTypes,
) -> Result<Emitted, Diagnostics> {
    let mut missed = Diagnostics::default();
    let mut generator = Gen::new(prog, unit, sources, &mut missed);
    generator.types = types;
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
