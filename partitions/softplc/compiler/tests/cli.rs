//! `plcc` command-line behaviour: exit codes, `build` output, diagnostics format.

use std::process::Command;

fn plcc() -> Command {
    Command::new(env!("CARGO_BIN_EXE_plcc"))
}

fn write(name: &str, text: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("plcc-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

const OK: &str = "PROGRAM Main VAR x : INT; END_VAR x := x + 2; END_PROGRAM";

#[test]
fn check_exit_codes() {
    let good = write("good.st", OK);
    assert_eq!(
        plcc().arg("check").arg(&good).status().unwrap().code(),
        Some(0)
    );
    let bad = write(
        "bad.st",
        "PROGRAM Main\nVAR x : INT; END_VAR\nx := y;\nx := ;\nEND_PROGRAM\n",
    );
    let out = plcc().arg("check").arg(&bad).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    // Several errors, each with file:line:column, the source line and a marker.
    assert!(
        err.contains("bad.st:3:6: error[E0049]: unknown variable `y`"),
        "{err}"
    );
    assert!(
        err.contains("bad.st:4:6: error[E0009]: expected an expression"),
        "{err}"
    );
    assert!(err.contains("x := y;"), "{err}");
}

#[test]
fn a_malformed_set_value_says_what_was_expected() {
    let src = write(
        "typed.st",
        "PROGRAM Main VAR t : TOD; n : USINT; p : REF_TO USINT; END_VAR p := REF(n); END_PROGRAM",
    );
    for (set, want) in [
        (
            "Main.t=TOD#25:00",
            "--set Main.t: `TOD#25:00` is not a TOD literal (expected a time of day such as TOD#12:30:00",
        ),
        (
            "Main.n=300",
            "--set Main.n: `300` is out of the range of USINT (0 to 255)",
        ),
        (
            "Main.p=NULL",
            "--set Main.p: `NULL` is not writable: a reference is read-only",
        ),
    ] {
        let out = plcc()
            .arg("run")
            .arg(&src)
            .args(["--set", set])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{set}: {err}");
        assert!(err.starts_with(want), "{set}: {err}");
    }
}

#[test]
fn usage_errors_exit_2() {
    assert_eq!(plcc().arg("run").status().unwrap().code(), Some(2));
    assert_eq!(plcc().arg("frobnicate").status().unwrap().code(), Some(2));
    let good = write("good2.st", OK);
    assert_eq!(
        plcc()
            .args(["run", "--cycles", "x"])
            .arg(&good)
            .status()
            .unwrap()
            .code(),
        Some(2)
    );
    assert_eq!(
        plcc()
            .arg("run")
            .arg(&good)
            .args(["--print", "Main.nope"])
            .status()
            .unwrap()
            .code(),
        Some(2)
    );
    assert_eq!(
        plcc()
            .arg("run")
            .arg(&good)
            .args(["--interval", "fast"])
            .status()
            .unwrap()
            .code(),
        Some(2)
    );
}

#[test]
fn build_writes_a_verifiable_image() {
    let good = write("good3.st", OK);
    let out = good.with_extension("img");
    assert_eq!(
        plcc()
            .arg("build")
            .arg(&good)
            .arg("-o")
            .arg(&out)
            .status()
            .unwrap()
            .code(),
        Some(0)
    );
    let bytes = std::fs::read(&out).unwrap();
    plc_compiler::verify_image(&bytes).unwrap();
    let image = plc_vm::image::Image::parse(&bytes).unwrap();
    assert!(image.find_var("Main.x").is_some());
}

#[test]
fn run_prints_cycles() {
    let good = write("good4.st", OK);
    let out = plcc()
        .arg("run")
        .arg(&good)
        .args(["--cycles", "3", "--print", "Main.x"])
        .output()
        .unwrap();
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        "cycle 1: Main.x=2\ncycle 2: Main.x=4\ncycle 3: Main.x=6\n"
    );
    assert_eq!(out.status.code(), Some(0));
}

#[test]
fn multiple_files() {
    let a = write(
        "lib.st",
        "FUNCTION Twice : INT VAR_INPUT v : INT; END_VAR Twice := v * 2; END_FUNCTION",
    );
    let b = write(
        "main.st",
        "PROGRAM Main VAR x : INT := 1; END_VAR x := Twice(x); END_PROGRAM",
    );
    let out = plcc()
        .arg("run")
        .arg(&a)
        .arg(&b)
        .args(["--cycles", "2", "--print", "Main.x"])
        .output()
        .unwrap();
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        "cycle 1: Main.x=2\ncycle 2: Main.x=4\n"
    );
}

#[test]
fn explain_prints_the_paragraph_of_a_code() {
    let out = plcc().args(["explain", "E0049"]).output().unwrap();
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.starts_with("E0049: unknown variable\n\n"), "{text}");
    let out = plcc().args(["explain", "E9999"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a diagnostic code"));
}

/// docs/plc-diagnostics.md is the table of `codes.rs` (regenerate it with
/// `plcc explain --markdown > docs/plc-diagnostics.md`).
#[test]
fn the_diagnostics_document_matches_the_table() {
    let doc =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../docs/plc-diagnostics.md");
    let doc = std::fs::read_to_string(doc).unwrap();
    assert!(
        doc == plc_compiler::codes::markdown(),
        "docs/plc-diagnostics.md differs from the code table: regenerate it with `plcc explain --markdown`"
    );
}

/// Every code of the table is reported somewhere in the compiler (no dead entries).
#[test]
fn every_code_is_used() {
    let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut text = String::new();
    let mut dirs = vec![src];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") && !p.ends_with("codes.rs") {
                text.push_str(&std::fs::read_to_string(&p).unwrap());
            }
        }
    }
    let table = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/codes.rs"),
    )
    .unwrap();
    for line in table.lines() {
        if let Some(rest) = line.strip_prefix("pub const ") {
            let name = rest.split(':').next().unwrap();
            assert!(
                text.contains(&format!("codes::{name},")),
                "{name} is never reported"
            );
        }
    }
}
