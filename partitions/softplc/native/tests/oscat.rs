//! The OSCAT BASIC library through the native tier: when its text is present (as for
//! `cargo xtask oscat`: `$OSCAT_ST`, else `target/oscat/oscat.st`; it is never part of this
//! repository), the library is compiled as one project (the declarations the compiler
//! refuses left out, as the OSCAT check lists them), every POU is translated, and the
//! generated Rust is compiled (under `target/plc-native-tests/oscat/`). Without the text the
//! test says how to get it and passes.

use plc_native::harness::{Dependency, Member, Root, Workspace, softplc_crate, target_dir};

#[test]
fn the_oscat_library_translates_and_compiles() {
    let path = std::env::var_os("OSCAT_ST")
        .filter(|p| !p.is_empty())
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| target_dir().join("oscat").join("oscat.st"));
    let Ok(bytes) = std::fs::read(&path) else {
        println!(
            "skipped: no OSCAT text at {} (git clone https://github.com/PLC-lang/oscat, then copy oscat.st there or point OSCAT_ST at it)",
            path.display()
        );
        return;
    };
    let text: String = match String::from_utf8(bytes) {
        Ok(t) => t,
        Err(e) => e.into_bytes().iter().map(|&b| b as char).collect(),
    };
    let decls = plc_compiler::library::split(&text);
    let mut keep = vec![true; decls.len()];
    let options = plc_compiler::Options {
        library: true,
        ..Default::default()
    };
    let image = loop {
        // Kept declarations, and where each starts in the joined text.
        let mut source = String::new();
        let mut starts = Vec::new();
        for (i, d) in decls.iter().enumerate().filter(|(i, _)| keep[*i]) {
            starts.push((source.len(), i));
            source.push_str(&text[d.start..d.end]);
            source.push('\n');
        }
        match plc_compiler::compile(&[("oscat.st".into(), source)], &options) {
            Ok((c, _)) => break c.image,
            Err((diags, _)) => {
                let mut dropped = 0;
                for d in diags.iter().filter(|d| d.span.file == 0) {
                    let at = d.span.start as usize;
                    if let Some(&(_, i)) = starts.iter().rev().find(|(s, _)| *s <= at)
                        && keep[i]
                    {
                        keep[i] = false;
                        dropped += 1;
                    }
                }
                assert!(dropped > 0, "the OSCAT library does not compile");
            }
        }
    };
    let kept = keep.iter().filter(|k| **k).count();
    let module = plc_native::translate_every_pou(&image)
        .unwrap_or_else(|e| panic!("the OSCAT library does not translate: {e}"));
    let workspace = Workspace {
        dir: target_dir().join("plc-native-tests/oscat"),
        opt_level: 0,
        members: vec![Member {
            name: "oscat".into(),
            root: Root::Lib(plc_native::bundle(&[("oscat".into(), module.clone())])),
            dependencies: vec![Dependency::Path(
                "plc-vm".into(),
                softplc_crate("vm"),
                Vec::new(),
            )],
            files: Vec::new(),
        }],
    };
    let built = workspace
        .build("oscat")
        .unwrap_or_else(|e| panic!("the translated OSCAT library does not compile: {e}"));
    println!(
        "OSCAT: {kept} of {} declarations compiled into a {} byte image, every POU translated ({} KiB of Rust), compiled in {:.1} s",
        decls.len(),
        image.len(),
        module.len() / 1024,
        built.seconds
    );
}
