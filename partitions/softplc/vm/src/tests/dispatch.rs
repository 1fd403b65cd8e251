//! The interpreter's dispatch covers the instruction set: every opcode of the `opcodes!`
//! table is named in a pattern of its own arm of `Machine::interpret`'s `match byte`, so no
//! assigned opcode can fall into the catch-all arm (which traps, and which the verifier
//! makes unreachable for assigned bytes only). The match is on raw bytes for speed, so the
//! compiler cannot check it for exhaustiveness; this test reads the interpreter's source.

use crate::isa::Opcode;
use alloc::collections::BTreeMap;
use alloc::string::String;
use alloc::vec::Vec;

/// The opcode names in the arm patterns of the interpreter's dispatch, with how often each
/// is named.
fn dispatched_names() -> BTreeMap<String, usize> {
    let source = include_str!("../vm.rs");
    let body = source
        .split_once("fn interpret(")
        .expect("vm.rs has the interpreter")
        .1;
    let dispatch = body
        .split_once("match byte {")
        .expect("the interpreter matches on the opcode byte")
        .1;
    let dispatch = dispatch
        .split_once("// Unassigned bytes: the verifier accepts none.")
        .expect("the dispatch ends with the catch-all arm")
        .0;
    let mut names = BTreeMap::new();
    // Brace depth inside the match: arm patterns stand at depth 0 (a nested `match op`
    // inside an arm's body is deeper).
    let mut depth = 0i32;
    for line in dispatch.lines() {
        let code = line.split("//").next().unwrap_or("");
        let at_arm_level = depth == 0;
        depth += code.matches('{').count() as i32 - code.matches('}').count() as i32;
        // A pattern line starts with `op::` (or `| op::` when rustfmt breaks a long
        // alternation).
        let line = line.trim_start().trim_start_matches("| ");
        if !at_arm_level || !line.starts_with("op::") {
            continue;
        }
        let pattern = line.split("=>").next().unwrap_or(line);
        for alternative in pattern.split('|') {
            let name = alternative.trim().trim_start_matches("op::").trim();
            if !name.is_empty() {
                *names.entry(String::from(name)).or_insert(0) += 1;
            }
        }
    }
    names
}

#[test]
fn every_opcode_has_its_own_arm() {
    let names = dispatched_names();
    let missing: Vec<&str> = Opcode::ALL
        .iter()
        .map(|op| variant_name(*op))
        .filter(|name| !names.contains_key(*name))
        .collect();
    assert!(
        missing.is_empty(),
        "opcodes that fall into the interpreter's catch-all trap: {missing:?}"
    );
    let twice: Vec<&String> = names
        .iter()
        .filter(|(_, n)| **n > 1)
        .map(|(k, _)| k)
        .collect();
    assert!(twice.is_empty(), "opcodes named in two arms: {twice:?}");
    let unknown: Vec<&String> = names
        .keys()
        .filter(|name| {
            !Opcode::ALL
                .iter()
                .any(|op| variant_name(*op) == name.as_str())
        })
        .collect();
    assert!(
        unknown.is_empty(),
        "arms for names that are not opcodes: {unknown:?}"
    );
    assert_eq!(names.len(), Opcode::ALL.len());
}

/// The opcode's variant name (`LdAbs`), as the dispatch's `op::` constants spell it.
fn variant_name(op: Opcode) -> &'static str {
    let debug = alloc::format!("{op:?}");
    // Leaked once per opcode in a test: the names live as long as the test binary.
    alloc::boxed::Box::leak(debug.into_boxed_str())
}
