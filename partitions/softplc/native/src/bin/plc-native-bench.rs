//! `plc-native-bench`: the native tier's leg of the soft-PLC benchmark suite. Compiles each
//! program of `plc-bench-suite` with the ST compiler, translates the image, builds the
//! translations with the suite's references into one program (`harness/bench.rs`, under
//! `target/plc-native-bench/`, optimised as the partition is: opt-level 3) and runs it;
//! its stdout is exactly the metric lines (`bench plc_native_<name>` and `..._ratio`),
//! what `cargo xtask bench` collects. The build's time goes to stderr.

use plc_bench_suite::PROGRAMS;
use plc_native::harness::{Dependency, Member, Root, Workspace, softplc_crate, target_dir};
use std::fmt::Write;

fn main() {
    let mut modules = Vec::new();
    let mut table = String::from(
        "/// The suite's programs by name.\npub static BY_NAME: &[(&str, &plc_vm::native::NativeProgram)] = &[",
    );
    for program in PROGRAMS {
        let compiled = plc_compiler::compile(
            &[(program.file.to_string(), program.source.to_string())],
            &plc_compiler::Options::default(),
        );
        let image = match compiled {
            Ok((c, _)) => c.image,
            Err((d, map)) => {
                eprintln!(
                    "plc-native-bench: {} does not compile:\n{}",
                    program.file,
                    plc_compiler::diagnostics::render(&map, &d, false)
                );
                std::process::exit(1);
            }
        };
        match plc_native::translate(&image) {
            Ok(module) => modules.push((program.name.to_string(), module)),
            Err(e) => {
                eprintln!("plc-native-bench: {}: {e}", program.file);
                std::process::exit(1);
            }
        }
        write!(table, "(\"{0}\", &{0}::PROGRAM), ", program.name).ok();
    }
    table.push_str("];\n");
    let vm = || Dependency::Path("plc-vm".into(), softplc_crate("vm"), vec!["alloc".into()]);
    let mut library = plc_native::bundle(&modules);
    library.push_str(&table);
    let workspace = Workspace {
        dir: target_dir().join("plc-native-bench"),
        opt_level: 3,
        members: vec![
            Member {
                name: "programs".into(),
                root: Root::Lib(library),
                dependencies: vec![vm()],
                files: Vec::new(),
            },
            Member {
                name: "bench".into(),
                root: Root::Bin(include_str!("../../harness/bench.rs").into()),
                dependencies: vec![
                    vm(),
                    Dependency::Path("plc-bench-suite".into(), softplc_crate("bench"), Vec::new()),
                    Dependency::Member("programs".into()),
                ],
                files: Vec::new(),
            },
        ],
    };
    let built = workspace.build("bench").unwrap_or_else(|e| {
        eprintln!("plc-native-bench: {e}");
        std::process::exit(1);
    });
    eprintln!(
        "plc-native-bench: {} programs translated and built in {:.1} s (opt-level 3)",
        PROGRAMS.len(),
        built.seconds
    );
    let status = std::process::Command::new(&built.binary)
        .status()
        .unwrap_or_else(|e| {
            eprintln!(
                "plc-native-bench: cannot run {}: {e}",
                built.binary.display()
            );
            std::process::exit(1);
        });
    std::process::exit(status.code().unwrap_or(1));
}
