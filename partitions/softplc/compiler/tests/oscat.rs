//! The OSCAT BASIC library check (`cargo xtask oscat`), run when the library text is present
//! (`$OSCAT_ST`, else `target/oscat/oscat.st`; it is never part of the repository).
//!
//! It must not hit a compiler bug (an internal error), and on the text STATUS.md was
//! measured on (same fingerprint) at least as many POUs must compile as STATUS.md says.

use std::path::{Path, PathBuf};

use plc_compiler::library;

fn library_text() -> Option<(PathBuf, String)> {
    let path = match std::env::var_os("OSCAT_ST") {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => std::env::var_os("CARGO_TARGET_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../target"))
            .join("oscat/oscat.st"),
    };
    let bytes = std::fs::read(&path).ok()?;
    let text = match String::from_utf8(bytes) {
        Ok(t) => t,
        Err(e) => e.into_bytes().iter().map(|&b| b as char).collect(),
    };
    Some((path, text))
}

/// (fingerprint, POUs that compile) recorded in STATUS.md's generated section.
fn recorded() -> Option<(u64, usize)> {
    let status =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("STATUS.md")).ok()?;
    let after = |key: &str| -> Option<&str> {
        let at = status.find(key)? + key.len();
        Some(&status[at..])
    };
    let fp = after("fingerprint `")?;
    let fp = u64::from_str_radix(&fp[..fp.find('`')?], 16).ok()?;
    let n = after("**One POU at a time: ")?;
    let n = n[..n.find(' ')?].parse().ok()?;
    Some((fp, n))
}

#[test]
fn oscat_library_check() {
    let Some((path, text)) = library_text() else {
        println!(
            "oscat: no library text (set OSCAT_ST or put it at target/oscat/oscat.st): skipped"
        );
        return;
    };
    let report = library::check("oscat.st", &text);
    println!(
        "oscat: {}: {} of {} POUs compile ({:.1} %)",
        path.display(),
        report.compiled(),
        report.pous.len(),
        report.percent()
    );
    let internal: Vec<String> = report
        .pous
        .iter()
        .chain(&report.others)
        .filter_map(|p| {
            let why = p.failure.as_deref()?;
            why.contains("internal error")
                .then(|| format!("{}: {why}", p.name))
        })
        .collect();
    assert!(internal.is_empty(), "compiler bugs: {internal:#?}");
    if let Some((fingerprint, compiled)) = recorded()
        && fingerprint == library::fingerprint(&text)
    {
        assert!(
            report.compiled() >= compiled,
            "{} POUs compile, STATUS.md records {compiled}: a regression (or update STATUS.md with `cargo xtask oscat --write-status`)",
            report.compiled()
        );
    }
}

/// OSCAT's pointer-based functions (byte pointers over STRINGs and buffers, `ADR` with
/// `SIZEOF`, REAL bits through a DWORD pointer) compiled from the library text with a test
/// program: the results CODESYS gives, the same on the VM and on the reference model.
#[test]
fn oscat_pointer_functions_run() {
    let Some((_, text)) = library_text() else {
        println!("oscat: no library text: skipped");
        return;
    };
    let test = "
PROGRAM TestMain
VAR
  s1, s2, s3, s4, s5, s6 : STRING[80];
  b : BYTE;
  d : DWORD;
  n, pos, found : INT;
  list : STRING[250] := ',,a,,bc,';
  buf : ARRAY[0..15] OF BYTE;
  arr : ARRAY[0..4] OF REAL := [5.0, 1.0, 4.0, 2.0, 3.0];
  ok : BOOL;
  r : REAL;
  dw : DWORD;
END_VAR
s1 := BYTE_TO_STRB(16#A5);
s2 := CAPITALIZE('hello big world');
s3 := UPPERCASE('MiXeD case');
s4 := LOWERCASE('MiXeD CASE');
s5 := MIRROR('abcdef');
b := BIN_TO_BYTE('1010');
d := HEX_TO_DWORD('1F');
n := DEC_TO_INT('-123');
ok := LIST_CLEAN(44, list);
pos := _STRING_TO_BUFFER('HELLO', 2, ADR(buf), SIZEOF(buf));
found := BUFFER_SEARCH(ADR(buf), SIZEOF(buf), 'LL', 0, FALSE);
s6 := BUFFER_TO_STRING(ADR(buf), SIZEOF(buf), 2, 6);
ok := _ARRAY_SORT(ADR(arr), SIZEOF(arr));
r := ARRAY_AVG(ADR(arr), SIZEOF(arr));
dw := REAL_TO_DW(1.0);
END_PROGRAM
";
    // The library's TYPEs and globals, and the POUs the test uses (transitively).
    let decls = library::split(&text);
    let mut wanted: Vec<String> = [
        "BYTE_TO_STRB",
        "CAPITALIZE",
        "UPPERCASE",
        "LOWERCASE",
        "MIRROR",
        "BIN_TO_BYTE",
        "HEX_TO_DWORD",
        "DEC_TO_INT",
        "LIST_CLEAN",
        "_STRING_TO_BUFFER",
        "BUFFER_SEARCH",
        "BUFFER_TO_STRING",
        "_ARRAY_SORT",
        "ARRAY_AVG",
        "REAL_TO_DW",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let mut taken = vec![false; decls.len()];
    while let Some(name) = wanted.pop() {
        for (k, d) in decls.iter().enumerate() {
            if !taken[k] && d.kind.is_pou() && d.declares.contains(&name) {
                taken[k] = true;
                wanted.extend(d.uses.iter().cloned());
            }
        }
    }
    let mut source = String::new();
    for (k, d) in decls.iter().enumerate() {
        if taken[k] || !d.kind.is_pou() {
            source.push_str(&text[d.start..d.end]);
            source.push('\n');
        }
    }
    source.push_str(test);
    let opts = plc_compiler::Options {
        program: Some("TestMain".into()),
        ..Default::default()
    };
    let (compiled, _) = match plc_compiler::compile(&[("oscat.st".into(), source)], &opts) {
        Ok(c) => c,
        Err((d, map)) => panic!("{}", plc_compiler::diagnostics::render(&map, &d, false)),
    };
    use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame};
    let image = plc_vm::image::Image::parse(&compiled.image).unwrap();
    let verified = plc_vm::verify::verify(&image).unwrap();
    let mut model = plc_vm::model::Model::new(&verified, 256, 32, 16);
    let mut data = vec![0u8; image.data_size() as usize];
    let (mut stack, mut calls, mut tries) = (
        vec![0u64; 256],
        vec![CallFrame::EMPTY; 32],
        vec![TryFrame::EMPTY; 16],
    );
    let mut vm = Machine::new(
        verified,
        Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        },
    )
    .unwrap();
    let result = vm.run_cycle(0, 0);
    let expected = model.run_cycle(0, 0, None);
    assert!(result.is_ok(), "{result:?}");
    assert!(
        matches!(expected, plc_vm::model::ModelCycle::Completed { .. }),
        "{expected:?}"
    );
    assert_eq!(vm.data(), model.data(), "VM and model disagree");
    let value = |name: &str| {
        vm.read_var(&format!("TestMain.{name}"))
            .unwrap()
            .to_string()
    };
    let got: Vec<String> = [
        "s1", "s2", "s3", "s4", "s5", "b", "d", "n", "list", "pos", "found", "s6", "arr[0]",
        "arr[4]", "r", "dw",
    ]
    .iter()
    .map(|v| format!("{v}={}", value(v)))
    .collect();
    assert_eq!(
        got.join(" "),
        "s1='10100101' s2='Hello Big World' s3='MIXED CASE' s4='mixed case' s5='fedcba' \
         b=10 d=31 n=-123 list=',a,bc' pos=7 found=4 s6='HELLO' arr[0]=1.0 arr[4]=5.0 r=3.0 \
         dw=1065353216"
    );
}
