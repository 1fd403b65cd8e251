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
