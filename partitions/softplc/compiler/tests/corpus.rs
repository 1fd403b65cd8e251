//! Corpus tests: every `tests/corpus/NAME.st` either runs through the `plcc` binary (the
//! exact `plcc run` code path) with the arguments in `NAME.args` and must print
//! `NAME.expected` (exit code 3 when the last line reports a trap, else 0, unless `NAME.exit`
//! says otherwise), or, when `NAME.errors` exists, must fail to compile with diagnostics at
//! exactly the listed `line:column` positions (one per line, optionally followed by text
//! that the message must contain).
//!
//! Every run case is also executed on the VM's reference model side by side with the VM,
//! comparing data memory and stack after every task activation.

use std::path::{Path, PathBuf};
use std::process::Command;

use plc_compiler::run::{CALL_FRAMES, STACK_CELLS, Scheduler, TRY_FRAMES, apply_sets};
use plc_compiler::{Options, compile};
use plc_vm::image::Image;
use plc_vm::model::{Model, ModelCycle};
use plc_vm::vm::{CallFrame, Machine, Memory, TryFrame};

fn corpus_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus")
}

fn cases() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(corpus_dir())
        .expect("corpus dir")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "st"))
        .collect();
    v.sort();
    v
}

/// Splits an args file into words; single quotes group (and are kept, since STRING values
/// in `--set` are written with quotes).
fn split_args(text: &str) -> Vec<String> {
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

fn args_of(st: &Path) -> Vec<String> {
    std::fs::read_to_string(st.with_extension("args"))
        .map(|t| split_args(&t))
        .unwrap_or_default()
}

fn run_case(st: &Path) -> Result<usize, String> {
    let name = st.file_stem().unwrap().to_string_lossy().to_string();
    let errors = st.with_extension("errors");
    if errors.exists() {
        return error_case(st, &errors).map(|()| 0);
    }
    let expected = std::fs::read_to_string(st.with_extension("expected"))
        .map_err(|e| format!("{name}: no .expected: {e}"))?;
    let args = args_of(st);
    let out = Command::new(env!("CARGO_BIN_EXE_plcc"))
        .arg("run")
        .arg(st)
        .args(&args)
        .output()
        .map_err(|e| format!("{name}: cannot run plcc: {e}"))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let want_exit = match std::fs::read_to_string(st.with_extension("exit")) {
        Ok(t) => t.trim().parse::<i32>().unwrap(),
        Err(_)
            if expected
                .lines()
                .last()
                .is_some_and(|l| l.contains(": trap ")) =>
        {
            3
        }
        Err(_) => 0,
    };
    if stdout != expected {
        return Err(format!(
            "{name}: stdout differs\n--- expected\n{expected}--- actual\n{stdout}--- stderr\n{stderr}"
        ));
    }
    if out.status.code() != Some(want_exit) {
        return Err(format!(
            "{name}: exit code {:?}, expected {want_exit}\nstderr: {stderr}",
            out.status.code()
        ));
    }
    if want_exit == 3 && !stderr.contains(".st:") {
        return Err(format!(
            "{name}: trap without a source location on stderr: {stderr}"
        ));
    }
    differential(st, &args)
}

fn error_case(st: &Path, errors: &Path) -> Result<(), String> {
    let name = st.file_stem().unwrap().to_string_lossy().to_string();
    let src = std::fs::read_to_string(st).unwrap();
    let file = st.display().to_string();
    let opts = Options::default();
    let diags = match compile(&[(file.clone(), src)], &opts) {
        Ok(_) => return Err(format!("{name}: compiled but errors were expected")),
        Err((d, map)) => d
            .into_iter()
            .map(|d| (map.location(d.span), d.message))
            .collect::<Vec<_>>(),
    };
    let want: Vec<(String, String)> = std::fs::read_to_string(errors)
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let (pos, text) = l.split_once(' ').unwrap_or((l, ""));
            (pos.trim().to_string(), text.trim().to_string())
        })
        .collect();
    let got: Vec<String> = diags
        .iter()
        .map(|(loc, _)| {
            loc.rsplitn(3, ':')
                .collect::<Vec<_>>()
                .into_iter()
                .take(2)
                .rev()
                .collect::<Vec<_>>()
                .join(":")
        })
        .collect();
    let want_pos: Vec<String> = want.iter().map(|w| w.0.clone()).collect();
    if got != want_pos {
        return Err(format!(
            "{name}: diagnostics at {got:?}, expected {want_pos:?}\n{diags:#?}"
        ));
    }
    for ((_, msg), (_, text)) in diags.iter().zip(&want) {
        if !msg.contains(text.as_str()) {
            return Err(format!("{name}: message `{msg}` does not contain `{text}`"));
        }
    }
    // The same through the binary: exit code 1 and `file:line:col` on stderr.
    let out = Command::new(env!("CARGO_BIN_EXE_plcc"))
        .arg("check")
        .arg(st)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    if out.status.code() != Some(1) {
        return Err(format!("{name}: plcc check exit {:?}", out.status.code()));
    }
    for w in &want_pos {
        if !stderr.contains(&format!("{file}:{w}")) {
            return Err(format!("{name}: stderr lacks {file}:{w}\n{stderr}"));
        }
    }
    Ok(())
}

/// Runs the case on the VM and on the reference model with the same schedule and compares
/// complete data memory, stack and outcome after every task activation.
fn differential(st: &Path, args: &[String]) -> Result<usize, String> {
    let name = st.file_stem().unwrap().to_string_lossy().to_string();
    let mut cycles = 1u64;
    let mut interval = 10_000_000i64;
    let mut program = None;
    let mut sets = Vec::new();
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--cycles" => cycles = args[i + 1].parse().unwrap(),
            "--interval" => {
                let mut d = Vec::new();
                let t = plc_compiler::lexer::lex(0, &args[i + 1], &mut d);
                if let plc_compiler::lexer::Tok::Time(ns) = t[0].tok {
                    interval = ns as i64;
                }
            }
            "--program" => program = Some(args[i + 1].clone()),
            "--set" => {
                let (n, v) = args[i + 1].split_once('=').unwrap();
                sets.push((n.to_string(), v.to_string()));
            }
            _ => {}
        }
        i += 2;
    }
    let src = std::fs::read_to_string(st).unwrap();
    let (c, _) = compile(
        &[(st.display().to_string(), src)],
        &Options {
            program,
            ..Options::default()
        },
    )
    .map_err(|_| format!("{name}: compile failed"))?;
    let image = Image::parse(&c.image).unwrap();
    let verified = plc_vm::verify::verify(&image).unwrap();
    let mut model = Model::new(&verified, STACK_CELLS, CALL_FRAMES, TRY_FRAMES);
    let mut data = vec![0u8; image.data_size() as usize];
    let mut stack = vec![0u64; STACK_CELLS];
    let mut calls = vec![CallFrame::EMPTY; CALL_FRAMES];
    let mut tries = vec![TryFrame::EMPTY; TRY_FRAMES];
    let memory = Memory {
        data: &mut data,
        stack: &mut stack,
        calls: &mut calls,
        tries: &mut tries,
    };
    let mut vm = Machine::new(verified, memory).unwrap();
    apply_sets(&c, &sets, vm.data_mut()).map_err(|e| format!("{name}: {e}"))?;
    apply_sets(&c, &sets, model.data_mut()).map_err(|e| format!("{name}: {e}"))?;
    let mut sched = Scheduler::new(&c, interval);
    let mut compared = 0;
    for k in 1..=cycles {
        let now = sched.now(k);
        for task in sched.due(&c, k, vm.data()) {
            let a = vm.run_cycle(task, now);
            let b = model.run_cycle(task, now, None);
            let same = match (&a, &b) {
                (
                    Ok(s),
                    ModelCycle::Completed {
                        instructions,
                        caught,
                    },
                ) => s.instructions == *instructions && s.caught_traps == *caught,
                (Err(f), ModelCycle::Faulted { trap, pc }) => {
                    f.trap == *trap && f.code_offset == *pc
                }
                _ => false,
            };
            if !same {
                return Err(format!(
                    "{name}: cycle {k} task {task}: VM {a:?} vs model {b:?}"
                ));
            }
            if vm.data() != model.data() {
                let at = vm
                    .data()
                    .iter()
                    .zip(model.data())
                    .position(|(x, y)| x != y)
                    .unwrap_or(0);
                return Err(format!("{name}: cycle {k}: data memory differs at {at}"));
            }
            if vm.stack() != model.stack() {
                return Err(format!(
                    "{name}: cycle {k}: stacks differ {:?} vs {:?}",
                    vm.stack(),
                    model.stack()
                ));
            }
            compared += 1;
            if a.is_err() {
                return Ok(compared);
            }
        }
    }
    Ok(compared)
}

#[test]
fn corpus() {
    let cases = cases();
    assert!(cases.len() >= 10, "corpus missing");
    let failures: Vec<String> = cases.iter().filter_map(|c| run_case(c).err()).collect();
    assert!(
        failures.is_empty(),
        "{} of {} corpus cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n\n")
    );
}
