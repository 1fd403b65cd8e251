//! Compatibility with 4diac IDE's own type library: every `.fbt` under the directory named
//! by `FORDIAC_TYPELIB` (default: `target/4diac-ide/data/typelibrary` of the workspace, a
//! checkout of eclipse-4diac/4diac-ide's `data/typelibrary`, never committed) is read; a
//! file may be refused only for a construct this reader says it does not support yet. The
//! test passes without the library (nothing to read) and says so.

use std::path::{Path, PathBuf};

fn fbt_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            fbt_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "fbt") {
            out.push(path);
        }
    }
}

#[test]
fn fourdiac_type_library_reads() {
    let Some(dir) = iec61499_xml::fourdiac_library() else {
        eprintln!("skipped: no 4diac type library (set FORDIAC_TYPELIB)");
        return;
    };
    let mut files = Vec::new();
    fbt_files(&dir, &mut files);
    files.sort();
    if files.is_empty() {
        eprintln!(
            "skipped: no .fbt files under {} (set FORDIAC_TYPELIB)",
            dir.display()
        );
        return;
    }
    let (mut read, mut unsupported, mut failed) = (0, Vec::new(), Vec::new());
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        match iec61499_xml::read_fbt(&file.display().to_string(), &text) {
            Ok(_) => read += 1,
            Err(e)
                if e.message.contains("not supported")
                    || e.message.contains("only Structured Text") =>
            {
                unsupported.push(e.to_string())
            }
            Err(e) => failed.push(e.to_string()),
        }
    }
    eprintln!(
        "4diac type library: {} files, {read} read, {} unsupported constructs, {} refused",
        files.len(),
        unsupported.len(),
        failed.len()
    );
    for line in unsupported.iter().chain(&failed) {
        eprintln!("  {line}");
    }
    assert!(failed.is_empty(), "{} files refused", failed.len());
}
