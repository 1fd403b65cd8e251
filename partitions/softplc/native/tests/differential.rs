//! The native tier against the reference model: the VM's differential cases (random
//! verified images, `plc_vm::testgen`), the compiler's (random well-typed ST programs,
//! `compiler/tests/support/random_st.rs`) and every run case of the compiler corpus are
//! translated, compiled together into one program (`harness/check.rs`, built under
//! `target/plc-native-tests/`) and run: the complete state after every activation against
//! the model, and with varying budgets and expiring deadlines against the model and the VM
//! (see `harness/check.rs`).
//!
//! `PLC_RANDOM_CASES=N` sets how many cases of each random generator (default 200, so 446
//! cases with the corpus and the handcrafted ones; 500 or more for a longer search); `PLC_NATIVE_OPT_LEVEL` the optimisation level of the
//! generated program (default 0: the same Rust semantics, compiled fastest; the partition
//! builds at opt-level 3). The test prints how long translation, compilation and the run
//! took.

#[path = "../../compiler/tests/support/random_st.rs"]
mod random_st;

use plc_compiler::run::{CALL_FRAMES, STACK_CELLS, Scheduler, TRY_FRAMES, apply_sets};
use plc_compiler::{Options, compile};
use plc_native::harness::{
    Dependency, Member, Root, Workspace, softplc_crate, target_dir, write_file,
};
use plc_vm::image::Image;
use plc_vm::testgen;
use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame};
use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One case before translation (see `harness/check.rs`).
struct Case {
    name: String,
    image: Vec<u8>,
    limits: (usize, usize, usize),
    patches: Vec<(u32, Vec<u8>)>,
    steps: Vec<(usize, i64)>,
    reset_after_fault: bool,
}

fn env_number(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// The VM's random images, run as its differential test runs them.
fn vm_cases(count: u64) -> Vec<Case> {
    (0..count)
        .map(|seed| Case {
            name: format!("random image {seed}"),
            image: testgen::random_program(seed),
            limits: (testgen::STACK, testgen::CALLS, testgen::TRIES),
            patches: Vec::new(),
            // Task 0 every cycle, the event task every other cycle.
            steps: (0..5i64)
                .map(|c| (if c % 2 == 1 { 1 } else { 0 }, c * 7_000_000))
                .collect(),
            reset_after_fault: true,
        })
        .collect()
}

/// The compiler's random ST programs, run as its differential test runs them.
fn st_cases(count: u64) -> Vec<Case> {
    (0..count)
        .map(|seed| {
            let src = random_st::program(seed);
            let (c, _) = compile(&[("gen.st".into(), src)], &Options::default())
                .unwrap_or_else(|_| panic!("random ST program {seed} does not compile"));
            Case {
                name: format!("random ST program {seed}"),
                image: c.image,
                limits: (STACK_CELLS, CALL_FRAMES, TRY_FRAMES),
                patches: Vec::new(),
                steps: (0..4i64).map(|k| (0, k * 10_000_000)).collect(),
                reset_after_fault: false,
            }
        })
        .collect()
}

/// Control flow the compiler does not produce but a verified image may have: a loop with
/// two entries (irreducible), and a try handler that jumps back before its TRY_BEGIN (a
/// block reached from two regions).
fn handcrafted_cases() -> Vec<Case> {
    use plc_vm::image::{ImageBuilder, TaskDef, TaskKind};
    use plc_vm::isa::{MemType, Opcode};
    let program = |body: &dyn Fn(&mut ImageBuilder)| {
        let mut b = ImageBuilder::new();
        b.reserve_data(64);
        let main = b.declare_pou("Main", 0, 0, 0);
        b.add_task(&TaskDef {
            name: "T".into(),
            kind: TaskKind::Cyclic,
            priority: 0,
            pou: main,
            instance_base: 0,
            interval_ns: 0,
            watchdog_budget: 0,
        });
        b.begin_pou(main);
        body(&mut b);
        b.end_pou(main);
        b.build().expect("build")
    };
    // `at += step` on an I32 at `at`.
    let bump = |b: &mut ImageBuilder, at: u32, step: i32| {
        b.ld_abs(MemType::I32, at);
        b.add_imm(step);
        b.st_abs(MemType::I32, at);
    };
    let irreducible = program(&|b| {
        let (one, two, end) = (b.new_label(), b.new_label(), b.new_label());
        b.ld_abs(MemType::I32, 0);
        b.push_i32(1);
        b.op(Opcode::And);
        b.jz(two);
        b.bind(one);
        bump(b, 4, 1);
        bump(b, 0, 1);
        b.ld_abs(MemType::I32, 0);
        b.push_i32(7);
        b.op(Opcode::GeS);
        b.jnz(end);
        b.jmp(two);
        b.bind(two);
        bump(b, 8, 3);
        bump(b, 0, 2);
        b.ld_abs(MemType::I32, 0);
        b.push_i32(9);
        b.op(Opcode::GeS);
        b.jnz(end);
        b.jmp(one);
        b.bind(end);
        b.push_i32(0);
        b.st_abs(MemType::I32, 0);
        b.ret();
    });
    let retry = program(&|b| {
        let (again, handler, end) = (b.new_label(), b.new_label(), b.new_label());
        b.bind(again);
        b.try_begin(handler);
        bump(b, 16, 1);
        // 12 / (3 - tries): a division by zero at the third try.
        b.push_i32(12);
        b.push_i32(3);
        b.ld_abs(MemType::I32, 16);
        b.op(Opcode::Sub);
        b.op(Opcode::DivS);
        b.st_abs(MemType::I32, 20);
        b.try_end();
        b.jmp(end);
        b.bind(handler);
        b.st_abs(MemType::U8, 24);
        bump(b, 28, 1);
        b.ld_abs(MemType::I32, 28);
        b.push_i32(5);
        b.op(Opcode::LtS);
        b.jnz(again);
        b.bind(end);
        b.ret();
    });
    [
        ("an irreducible loop", irreducible),
        ("a handler that retries", retry),
    ]
    .into_iter()
    .map(|(name, image)| Case {
        name: format!("handcrafted: {name}"),
        image,
        limits: (testgen::STACK, testgen::CALLS, testgen::TRIES),
        patches: Vec::new(),
        steps: (0..4i64).map(|k| (0, k * 1_000_000)).collect(),
        reset_after_fault: true,
    })
    .collect()
}

fn corpus_dir() -> PathBuf {
    softplc_crate("compiler").join("tests/corpus")
}

/// Arguments of a corpus case (as `compiler/tests/corpus.rs` splits them).
fn corpus_args(st: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(st.with_extension("args")).unwrap_or_default();
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut quoted = false;
    for ch in text.chars() {
        if ch == '\'' {
            quoted = !quoted;
            cur.push(ch);
        } else if ch.is_whitespace() && !quoted {
            if !cur.is_empty() {
                out.push(std::mem::take(&mut cur));
            }
        } else {
            cur.push(ch);
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// Every run case of the compiler corpus: its `--set` values as patches and the task
/// activations `plcc run` makes (recorded on the VM; a diverging native run shows at the
/// comparison).
fn corpus_cases() -> Vec<Case> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(corpus_dir())
        .expect("corpus")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "st"))
        .filter(|p| !p.with_extension("errors").exists())
        .collect();
    files.sort();
    files
        .iter()
        .map(|st| {
            let name = st.file_stem().unwrap().to_string_lossy().to_string();
            let args = corpus_args(st);
            let (mut cycles, mut interval, mut program, mut sets) =
                (1u64, 10_000_000i64, None, Vec::new());
            for pair in args.chunks(2) {
                match (pair[0].as_str(), pair.get(1)) {
                    ("--cycles", Some(v)) => cycles = v.parse().unwrap(),
                    ("--interval", Some(v)) => {
                        let mut d = Vec::new();
                        let t = plc_compiler::lexer::lex(0, v, &mut d);
                        if let plc_compiler::lexer::Tok::Time(ns) = t[0].tok {
                            interval = ns as i64;
                        }
                    }
                    ("--program", Some(v)) => program = Some(v.clone()),
                    ("--set", Some(v)) => {
                        let (n, v) = v.split_once('=').unwrap();
                        sets.push((n.to_string(), v.to_string()));
                    }
                    _ => {}
                }
            }
            let src = std::fs::read_to_string(st).unwrap();
            let (c, _) = compile(
                &[(st.display().to_string(), src)],
                &Options {
                    program,
                    ..Options::default()
                },
            )
            .unwrap_or_else(|_| panic!("corpus {name} does not compile"));
            let image = Image::parse(&c.image).unwrap();
            let verified = plc_vm::verify::verify(&image).unwrap();
            let mut data = vec![0u8; image.data_size() as usize];
            let mut stack = vec![0u64; STACK_CELLS];
            let mut calls = vec![CallFrame::EMPTY; CALL_FRAMES];
            let mut tries = vec![TryFrame::EMPTY; TRY_FRAMES];
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
            let initial = vm.data().to_vec();
            apply_sets(&c, &sets, vm.data_mut()).unwrap();
            let patches: Vec<(u32, Vec<u8>)> = vm
                .data()
                .iter()
                .zip(&initial)
                .enumerate()
                .filter(|(_, (a, b))| a != b)
                .map(|(at, (a, _))| (at as u32, vec![*a]))
                .collect();
            let mut sched = Scheduler::new(&c, interval);
            let mut steps = Vec::new();
            'run: for k in 1..=cycles {
                let now = sched.now(k);
                for task in sched.due(&c, k, vm.data()) {
                    steps.push((task, now));
                    if vm.run_cycle(task, now).is_err() {
                        break 'run;
                    }
                }
            }
            Case {
                name: format!("corpus {name}"),
                image: c.image.clone(),
                limits: (STACK_CELLS, CALL_FRAMES, TRY_FRAMES),
                patches,
                steps,
                reset_after_fault: false,
            }
        })
        .collect()
}

/// How many library crates the translated cases are spread over (compiled in parallel).
const PARTS: usize = 4;

fn part_of(case: usize, count: usize) -> usize {
    case * PARTS / count.max(1)
}

/// The harness: `PARTS` libraries with the translated cases (`c<i>` modules, the images
/// beside them) and the checking program with the case table (`programs.rs`).
fn harness(cases: &[Case], dir: &Path, opt_level: u8) -> (Workspace, usize) {
    let images = dir.join("images");
    let vm = Dependency::Path(
        "plc-vm".into(),
        softplc_crate("vm"),
        vec!["alloc".into(), "model".into()],
    );
    let mut parts: Vec<Vec<(String, String)>> = vec![Vec::new(); PARTS];
    let mut rust = 0;
    for (i, case) in cases.iter().enumerate() {
        let file = images.join(format!("c{i}.plcb"));
        write_file(&file, &case.image).expect("write image");
        let source = plc_native::ImageSource::File(file.display().to_string());
        let module = plc_native::translate_with(&case.image, &source)
            .unwrap_or_else(|e| panic!("{}: translation failed: {e}", case.name));
        rust += module.len();
        parts[part_of(i, cases.len())].push((format!("c{i}"), module));
    }
    let mut table = String::from("pub static CASES: &[crate::Case] = &[\n");
    for (i, case) in cases.iter().enumerate() {
        let patches: Vec<String> = case
            .patches
            .iter()
            .map(|(at, bytes)| format!("({at}, &{bytes:?})"))
            .collect();
        let steps: Vec<String> = case
            .steps
            .iter()
            .map(|(task, now)| format!("({task}, {now})"))
            .collect();
        writeln!(
            table,
            "crate::Case {{ name: {:?}, program: &cases_{}::c{i}::PROGRAM, stack: {}, calls: {}, tries: {}, patches: &[{}], steps: &[{}], reset_after_fault: {} }},",
            case.name,
            part_of(i, cases.len()),
            case.limits.0,
            case.limits.1,
            case.limits.2,
            patches.join(", "),
            steps.join(", "),
            case.reset_after_fault
        )
        .ok();
    }
    table.push_str("];\n");
    let mut members: Vec<Member> = parts
        .into_iter()
        .enumerate()
        .map(|(k, modules)| Member {
            name: format!("cases_{k}"),
            root: Root::Lib(plc_native::bundle(&modules)),
            dependencies: vec![Dependency::Path(
                "plc-vm".into(),
                softplc_crate("vm"),
                vec!["alloc".into(), "model".into()],
            )],
            files: Vec::new(),
        })
        .collect();
    let mut dependencies = vec![vm];
    dependencies.extend((0..PARTS).map(|k| Dependency::Member(format!("cases_{k}"))));
    members.push(Member {
        name: "check".into(),
        root: Root::Bin(include_str!("../harness/check.rs").into()),
        dependencies,
        files: vec![("programs.rs".into(), table)],
    });
    (
        Workspace {
            dir: dir.to_path_buf(),
            opt_level,
            members,
        },
        rust,
    )
}

#[test]
fn native_matches_model() {
    let count = env_number("PLC_RANDOM_CASES", 200);
    let opt_level = env_number("PLC_NATIVE_OPT_LEVEL", 0) as u8;
    let started = Instant::now();
    let mut cases = vm_cases(count);
    cases.extend(st_cases(count));
    cases.extend(corpus_cases());
    cases.extend(handcrafted_cases());
    let generated = started.elapsed().as_secs_f64();
    let started = Instant::now();
    let dir = target_dir().join("plc-native-tests/differential");
    let (workspace, rust) = harness(&cases, &dir, opt_level);
    let translated = started.elapsed().as_secs_f64();
    let built = workspace.build("check").unwrap_or_else(|e| panic!("{e}"));
    let started = Instant::now();
    let out = std::process::Command::new(&built.binary)
        .output()
        .expect("run the harness");
    let ran = started.elapsed().as_secs_f64();
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!(
        "native differential: {} cases ({count} random images, {count} random ST programs, {} corpus programs and handcrafted control flow); generated in {generated:.1} s, translated in {translated:.1} s ({} KiB of Rust), compiled in {:.1} s (opt-level {opt_level}), ran in {ran:.1} s",
        cases.len(),
        cases.len() - 2 * count as usize - 2,
        rust / 1024,
        built.seconds
    );
    print!("{stdout}");
    eprint!("{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        out.status.success(),
        "the native tier disagrees (see above)"
    );
    assert!(stdout.contains(", 0 failed"));
}
