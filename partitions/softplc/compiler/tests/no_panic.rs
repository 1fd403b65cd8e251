//! Property tests: the compiler never panics, whatever the input — random text, random
//! token soups of ST words, and corpus programs with random edits. Whenever a program
//! compiles, the image must pass the VM's verifier (checked inside `compile`), and a
//! program that does not compile is told why by a diagnostic of its own, never by an
//! internal error.

use std::path::Path;

use plc_compiler::{Options, compile};
use proptest::prelude::*;

fn check(src: &str) {
    // A compile that never finishes would otherwise hang the test silently.
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let d2 = done.clone();
    let s2 = src.to_string();
    std::thread::spawn(move || {
        std::thread::sleep(std::time::Duration::from_secs(10));
        if !d2.load(std::sync::atomic::Ordering::SeqCst) {
            let _ = std::fs::write(std::env::temp_dir().join("plcc-hang.st"), &s2);
            std::process::exit(9);
        }
    });
    let _ = compile(
        &[("fuzz.st".to_string(), src.to_string())],
        &Options {
            program: Some("Main".into()),
            ..Options::default()
        },
    );
    done.store(true, std::sync::atomic::Ordering::SeqCst);
    if let Err((diags, _)) = compile(
        &[("fuzz.st".to_string(), src.to_string())],
        &Options {
            library: true,
            ..Options::default()
        },
    ) && let Some(d) = diags.iter().find(|d| d.message.contains("internal error"))
    {
        panic!("{}\n{src}", d.message);
    }
    let _ = compile(
        &[("fuzz.st".to_string(), src.to_string())],
        &Options {
            program: Some("Main".into()),
            ..Options::default()
        },
    );
}

const WORDS: &[&str] = &[
    "PROGRAM",
    "Main",
    "END_PROGRAM",
    "FUNCTION",
    "F",
    ":",
    "INT",
    "END_FUNCTION",
    "FUNCTION_BLOCK",
    "FB",
    "END_FUNCTION_BLOCK",
    "VAR",
    "VAR_INPUT",
    "VAR_OUTPUT",
    "VAR_IN_OUT",
    "VAR_TEMP",
    "VAR_GLOBAL",
    "VAR_EXTERNAL",
    "END_VAR",
    "CONSTANT",
    "x",
    "y",
    "a",
    ":=",
    "=>",
    ";",
    ",",
    "(",
    ")",
    "[",
    "]",
    "..",
    ".",
    "+",
    "-",
    "*",
    "/",
    "**",
    "MOD",
    "AND",
    "OR",
    "XOR",
    "NOT",
    "=",
    "<>",
    "<",
    ">=",
    "IF",
    "THEN",
    "ELSIF",
    "ELSE",
    "END_IF",
    "CASE",
    "OF",
    "END_CASE",
    "FOR",
    "TO",
    "BY",
    "DO",
    "END_FOR",
    "WHILE",
    "END_WHILE",
    "REPEAT",
    "UNTIL",
    "END_REPEAT",
    "EXIT",
    "RETURN",
    "1",
    "0",
    "-1",
    "32767",
    "1.5",
    "T#1s",
    "'s'",
    "TRUE",
    "FALSE",
    "INT#5",
    "16#FF",
    "ARRAY",
    "STRUCT",
    "END_STRUCT",
    "TYPE",
    "END_TYPE",
    "STRING",
    "STRING[3]",
    "REAL",
    "BOOL",
    "TIME",
    "DINT",
    "TON",
    "__TRY",
    "__CATCH",
    "__FINALLY",
    "__ENDTRY",
    "__EXCEPTION",
    "e",
    "CONFIGURATION",
    "END_CONFIGURATION",
    "RESOURCE",
    "END_RESOURCE",
    "TASK",
    "WITH",
    "INTERVAL",
    "PRIORITY",
    "SINGLE",
    "LEN",
    "CONCAT",
    "MAX",
    "SEL",
    "MUX",
    "LIMIT",
    "SQRT",
    "INT_TO_REAL",
    "TRUNC",
    "TO_INT",
    "ATAN2",
    "SPLIT_DATE",
    "CONCAT_DT",
    "DAY_OF_WEEK",
    "ADD_TOD_TIME",
    "D#2024-02-29",
    "TOD#12:00",
    "DT#2024-02-29-12:00:00",
    "LT#1ns",
    "DATE",
    "TOD",
    "DT",
    "LTIME",
    "CHAR",
    "x.3",
    "x.%B1",
    "YEAR",
    "IN",
    "x[1]",
    "fb.Q",
    "(*c*)",
    "\n",
];

/// Every standard function called with an erroneous argument, a wrong type and a wrong
/// count: each is a diagnostic of the program, none an internal error.
#[test]
fn standard_functions_report_bad_arguments() {
    const NAMES: &[&str] = &[
        "ABS",
        "SQRT",
        "LN",
        "EXP",
        "ATAN2",
        "EXPT",
        "TRUNC",
        "TRUNC_INT",
        "REAL_TRUNC_DINT",
        "MOVE",
        "SEL",
        "MAX",
        "MIN",
        "LIMIT",
        "MUX",
        "SHL",
        "ROR",
        "LEN",
        "LEFT",
        "MID",
        "INSERT",
        "REPLACE",
        "FIND",
        "CONCAT",
        "INT_TO_REAL",
        "STRING_TO_DATE",
        "TO_INT",
        "TO_STRING",
        "ADD_TIME",
        "SUB_DT_DT",
        "MUL_TIME",
        "CONCAT_DATE",
        "CONCAT_TOD",
        "CONCAT_DT",
        "CONCAT_DATE_TOD",
        "SPLIT_DATE",
        "SPLIT_TOD",
        "SPLIT_DT",
        "DAY_OF_WEEK",
        "TIME",
        "DATE_TO_STRING",
        "CHAR_TO_STRING",
    ];
    const ARGS: &[&str] = &[
        "(nothing)",
        "(nothing, 1)",
        "(1, nothing, 2)",
        "(s)",
        "(r, s)",
        "(IN := nothing)",
        "(d, YEAR => nothing)",
        "()",
        "(1, 2, 3, 4, 5, 6, 7, 8)",
    ];
    for name in NAMES {
        for args in ARGS {
            let src = format!(
                "PROGRAM Main\nVAR i : INT; r : REAL; s : STRING; d : DATE; END_VAR\ni := {name}{args};\n{name}{args};\nEND_PROGRAM\n"
            );
            match compile(&[("t.st".into(), src.clone())], &Options::default()) {
                Ok(_) => assert!(!args.contains("nothing"), "accepted:\n{src}"),
                Err((diags, _)) => {
                    assert!(
                        !diags.iter().any(|d| d.message.contains("internal error")),
                        "{src}\n{diags:?}"
                    );
                    // A lone unknown argument is always the error reported.
                    if *args == "(nothing)" {
                        assert!(
                            diags.iter().any(|d| d.message.contains("`nothing`")),
                            "{src}\n{diags:?}"
                        );
                    }
                }
            }
        }
    }
}

fn corpus_sources() -> Vec<String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "st"))
        .collect();
    v.sort();
    v.into_iter()
        .map(|p| std::fs::read_to_string(p).unwrap())
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, .. ProptestConfig::default() })]

    #[test]
    fn arbitrary_text(s in "\\PC{0,300}") {
        check(&s);
    }

    #[test]
    fn token_soup(words in prop::collection::vec(prop::sample::select(WORDS), 0..120)) {
        check(&words.join(" "));
    }

    #[test]
    fn program_shaped_soup(words in prop::collection::vec(prop::sample::select(WORDS), 0..60)) {
        let src = format!(
            "PROGRAM Main\nVAR x : INT; y : REAL; a : ARRAY[1..3] OF INT; s : STRING; fb : TON; e : __EXCEPTION; END_VAR\n{}\nEND_PROGRAM",
            words.join(" ")
        );
        check(&src);
    }

    #[test]
    fn edited_corpus(idx in 0usize..64, edits in prop::collection::vec((0usize..4000, 0u8..3, prop::sample::select(WORDS)), 1..6)) {
        let sources = corpus_sources();
        let mut src = sources[idx % sources.len()].clone();
        for (pos, kind, word) in edits {
            let mut at = pos % (src.len() + 1);
            while !src.is_char_boundary(at) {
                at -= 1;
            }
            match kind {
                0 => src.insert_str(at, word),
                1 => {
                    let mut end = (at + word.len()).min(src.len());
                    while !src.is_char_boundary(end) {
                        end -= 1;
                    }
                    src.replace_range(at..end, "");
                }
                _ => src.insert_str(at, &format!(" {word} ")),
            }
        }
        check(&src);
    }
}

#[test]
fn deep_nesting_is_an_error_not_a_crash() {
    let deep = format!(
        "PROGRAM Main VAR x : INT; END_VAR x := {}1{}; END_PROGRAM",
        "(".repeat(5000),
        ")".repeat(5000)
    );
    assert!(compile(&[("d.st".into(), deep)], &Options::default()).is_err());
    let neg = format!(
        "PROGRAM Main VAR x : INT; END_VAR x := {}1; END_PROGRAM",
        "-".repeat(5000)
    );
    assert!(compile(&[("d.st".into(), neg)], &Options::default()).is_err());
    let ifs = format!(
        "PROGRAM Main VAR x : INT; END_VAR {} x := 1; {} END_PROGRAM",
        "IF TRUE THEN ".repeat(3000),
        "END_IF; ".repeat(3000)
    );
    assert!(compile(&[("d.st".into(), ifs)], &Options::default()).is_err());
}

/// Definitions in terms of themselves are refused with an error (E0020 or a constant's),
/// never followed forever: a named type that is itself, a function block holding an
/// instance of itself, global and local constants defined through each other.
#[test]
fn self_referencing_definitions_are_errors_not_crashes() {
    for src in [
        "TYPE T : T; END_TYPE PROGRAM Main VAR x : T; END_VAR END_PROGRAM",
        "TYPE T : U; END_TYPE TYPE U : T; END_TYPE PROGRAM Main VAR x : T; END_VAR END_PROGRAM",
        "FUNCTION_BLOCK A VAR x : A; END_VAR END_FUNCTION_BLOCK PROGRAM Main VAR x : A; END_VAR END_PROGRAM",
        "FUNCTION_BLOCK A VAR b : B; END_VAR END_FUNCTION_BLOCK FUNCTION_BLOCK B VAR a : A; END_VAR END_FUNCTION_BLOCK PROGRAM Main VAR x : A; END_VAR END_PROGRAM",
        "VAR_GLOBAL CONSTANT c : INT := d; d : INT := c; END_VAR PROGRAM Main VAR x : ARRAY[1..c] OF INT; END_VAR END_PROGRAM",
        "PROGRAM Main VAR CONSTANT a : INT := b + 1; b : INT := a; END_VAR VAR x : ARRAY[1..a] OF INT; END_VAR END_PROGRAM",
    ] {
        assert!(
            compile(&[("r.st".into(), src.into())], &Options::default()).is_err(),
            "{src}"
        );
        check(src);
    }
}
