//! `cargo xtask oscat [FILE]`: the OSCAT BASIC library check. Compiles the library text as
//! one project and one POU at a time (each with the TYPEs and POUs it uses) and prints how
//! many POUs compile and, for each one that does not, why (`plc_compiler::library`).
//!
//! The library text is never part of this repository: it is read from FILE, else from the
//! environment variable `OSCAT_ST`, else from `target/oscat/oscat.st`. Without it the check
//! says how to get it and reports "skipped" (exit 0). `--write-status` puts the figures and
//! the failure list into the generated section of `partitions/softplc/compiler/STATUS.md`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use plc_compiler::library::{self, STATUS_BEGIN, STATUS_END};

/// The text the figures in STATUS.md are measured on.
pub const SOURCE: &str = "OSCAT BASIC 3.33 as published in github.com/PLC-lang/oscat (`oscat.st` of commit 2153dac, the RuSTy adaptation: REF_TO for POINTER TO, REF for ADR)";

/// How to get the library text.
const HOW_TO_GET: &str = "get it with: git clone https://github.com/PLC-lang/oscat && mkdir -p target/oscat && cp oscat/oscat.st target/oscat/ (or point OSCAT_ST or the FILE argument at it)";

/// The library text to check: `file`, else `$OSCAT_ST`, else `target/oscat/oscat.st`.
pub fn default_path(file: Option<&Path>) -> PathBuf {
    match (file, std::env::var_os("OSCAT_ST")) {
        (Some(f), _) => f.to_path_buf(),
        (None, Some(env)) if !env.is_empty() => PathBuf::from(env),
        _ => crate::target_dir().join("oscat").join("oscat.st"),
    }
}

/// Reads a source text: UTF-8, or else Latin-1 (CODESYS exports often are).
pub fn read_source(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    Ok(match String::from_utf8(bytes) {
        Ok(text) => text,
        Err(e) => e.into_bytes().iter().map(|&b| b as char).collect(),
    })
}

pub fn run(file: Option<&Path>, write_status: bool) -> Result<bool> {
    let path = default_path(file);
    if !path.is_file() {
        if file.is_some() {
            bail!("{} does not exist; {HOW_TO_GET}", path.display());
        }
        println!("oscat: no library text at {}", path.display());
        println!("oscat: {HOW_TO_GET}");
        println!("oscat: skipped");
        return Ok(true);
    }
    let text = read_source(&path)?;
    let name = path
        .file_name()
        .map_or_else(|| "oscat.st".into(), |n| n.to_string_lossy().to_string());
    let fingerprint = library::fingerprint(&text);
    println!(
        "oscat: {} ({} lines, fingerprint {fingerprint:016x})",
        path.display(),
        text.lines().count()
    );
    let report = library::check(&name, &text);
    if report.project_errors == 0 {
        println!("oscat: as one project: compiles");
    } else {
        println!(
            "oscat: as one project: {} error(s) in {} declaration(s); the first:",
            report.project_errors, report.project_failing_decls
        );
        for line in &report.project_first {
            println!("oscat:   {line}");
        }
    }
    for p in report.pous.iter().chain(&report.others) {
        if let Some(why) = &p.failure {
            println!(
                "oscat: FAIL {} {} (line {}): {why}",
                p.kind.keyword(),
                p.name,
                p.line
            );
        }
    }
    let others_ok = report.others.iter().filter(|o| o.failure.is_none()).count();
    println!(
        "oscat: TYPE/VAR_GLOBAL blocks: {others_ok} of {} compile",
        report.others.len()
    );
    println!(
        "oscat: one POU at a time: {} of {} POUs compile ({:.1} %)",
        report.compiled(),
        report.pous.len(),
        report.percent()
    );
    if write_status {
        let status = crate::workspace_root().join("partitions/softplc/compiler/STATUS.md");
        let old = std::fs::read_to_string(&status)
            .with_context(|| format!("cannot read {}", status.display()))?;
        let section = report.markdown(SOURCE, fingerprint);
        let new = replace_section(&old, &section).with_context(|| {
            format!(
                "{} has no generated section ({STATUS_BEGIN} ... {STATUS_END})",
                status.display()
            )
        })?;
        std::fs::write(&status, new)
            .with_context(|| format!("cannot write {}", status.display()))?;
        println!("oscat: wrote the figures into {}", status.display());
    }
    Ok(true)
}

/// `text` with the generated section replaced by `section` (`None` without markers).
fn replace_section(text: &str, section: &str) -> Option<String> {
    let begin = text.find(STATUS_BEGIN)?;
    let end = begin + text[begin..].find(STATUS_END)? + STATUS_END.len();
    let end = if text[end..].starts_with('\n') {
        end + 1
    } else {
        end
    };
    Some(format!("{}{section}{}", &text[..begin], &text[end..]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_only_the_generated_section() {
        let text = format!("# head\n{STATUS_BEGIN}\nold\n{STATUS_END}\ntail\n");
        let new = replace_section(&text, &format!("{STATUS_BEGIN}\nnew\n{STATUS_END}\n")).unwrap();
        assert_eq!(
            new,
            format!("# head\n{STATUS_BEGIN}\nnew\n{STATUS_END}\ntail\n")
        );
        assert!(replace_section("no markers", "x").is_none());
    }
}
