//! IEC 61131-3 Structured Text compiler (host): source -> verified plc-vm bytecode image.
//!
//! Pipeline: [`lexer`] -> [`parser`] ([`ast`]) -> [`sema`] (declarations, types, layout) ->
//! [`typed::check`] (bodies: every diagnostic, the type of every expression) ->
//! [`typed::emit`] ([`codegen`], through `plc_vm::image::ImageBuilder`) -> image.
//! The standard function blocks come from an ST [`PRELUDE`] compiled with every program.
//! [`run`] is the host runner behind `plcc run`.

pub mod ast;
mod classes;
pub mod codegen;
pub mod codes;
pub mod diagnostics;
pub mod lexer;
pub mod library;
pub mod monitor;
pub mod parser;
pub mod run;
pub mod sema;
pub mod typed;
pub mod types;

use diagnostics::{Diagnostic, Diagnostics, SourceMap};

/// ST source of the standard function blocks (TON, TOF, TP, CTU, CTD, CTUD, R_TRIG, F_TRIG, SR, RS).
pub const PRELUDE: &str = include_str!("prelude.st");

/// Name under which the prelude appears in the source map.
pub const PRELUDE_NAME: &str = "<prelude>";

/// Compiler options.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// Program to run when there is no CONFIGURATION and several PROGRAMs.
    pub program: Option<String>,
    /// Compile a library: every POU is checked and compiled, no PROGRAM is needed and none
    /// becomes a task (the image has no tasks unless a CONFIGURATION declares some).
    pub library: bool,
}

/// A task as the host runner schedules it.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskInfo {
    pub name: String,
    /// Cyclic interval in ns; 0 means "every base tick" (no CONFIGURATION, or no task given).
    pub interval_ns: i64,
    /// Data address of the global BOOL whose rising edge triggers an event (SINGLE) task.
    pub single_addr: Option<u32>,
    pub priority: u32,
    /// Index of the task record in the image (one record per program instance).
    pub image_tasks: Vec<usize>,
}

/// A located output's safe value from an `{attribute 'safe' := 'VALUE'}` pragma: what the
/// runtime writes when a task faults and the outputs go safe (the system configuration's
/// `plc.safe` may override it).
#[derive(Debug, Clone, PartialEq)]
pub struct SafeOutput {
    /// The variable's name in the variable map (`out`, `Main.valve`).
    pub name: String,
    pub address: u32,
    /// Bytes written (the `%Q` address's width).
    pub width: u8,
    /// The little-endian bits written.
    pub value: u64,
}

/// Result of a successful compilation.
#[derive(Debug, Clone)]
pub struct Compiled {
    pub image: Vec<u8>,
    /// Every printable variable (scalars and strings, including struct members, array
    /// elements and FB instance variables), with its full name.
    pub vars: Vec<monitor::MonitorVar>,
    pub tasks: Vec<TaskInfo>,
    pub has_configuration: bool,
    /// The safe values the program's pragmas give its located outputs.
    pub safe: Vec<SafeOutput>,
}

/// Compiles the given `(file name, source)` pairs. On failure returns the diagnostics together
/// with the source map needed to render them.
pub fn compile(
    files: &[(String, String)],
    opts: &Options,
) -> Result<(Compiled, SourceMap), (Vec<Diagnostic>, SourceMap)> {
    let mut sources = SourceMap::default();
    for (name, text) in files {
        sources.add(name.clone(), text.clone());
    }
    let prelude_id = sources.add(PRELUDE_NAME, PRELUDE);
    let mut raw: Vec<Diagnostic> = Vec::new();
    let mut unit = {
        let toks = lexer::lex(prelude_id, PRELUDE, &mut raw);
        parser::parse(toks, &mut raw)
    };
    let prelude_pous = unit.pous.len();
    for (i, (_, text)) in files.iter().enumerate() {
        let toks = lexer::lex(i as u32, text, &mut raw);
        let u = parser::parse(toks, &mut raw);
        unit.pous.extend(u.pous);
        unit.types.extend(u.types);
        unit.globals.extend(u.globals);
        unit.configs.extend(u.configs);
        unit.interfaces.extend(u.interfaces);
        unit.actions.extend(u.actions);
    }
    let mut diags = Diagnostics::default();
    for d in raw {
        diags.push(d);
    }
    let mut prog = sema::analyse(&unit, prelude_pous, opts, &mut diags);
    if prog.instances.is_empty() && diags.is_empty() && !opts.library {
        diags.error(
            codes::PROGRAM_SELECTION,
            diagnostics::Span::new(0, 0, 0),
            "no PROGRAM to run (declare a PROGRAM or a CONFIGURATION)",
        );
    }
    // Check every body (all diagnostics, the type of every expression), then emit.
    let checked = typed::check(&mut prog, &unit, &sources, &mut diags);
    let task_records: usize = prog.tasks.iter().map(|t| t.programs.len()).sum();
    if task_records > plc_vm::verify::MAX_TASKS {
        let span = unit
            .configs
            .first()
            .map(|c| c.name.span)
            .unwrap_or_default();
        diags.error(
            codes::TOO_MANY_PROGRAM_INSTANCES,
            span,
            format!(
                "too many program instances: the VM runs at most {}",
                plc_vm::verify::MAX_TASKS
            ),
        );
    }
    let emitted = if diags.is_empty() {
        match typed::emit(&mut prog, &unit, &sources, checked) {
            Ok(emitted) => Some(emitted),
            Err(internal) => {
                internal.list.into_iter().for_each(|d| diags.push(d));
                None
            }
        }
    } else {
        None
    };
    // The data of the declarations and, once emitted, the temporaries of the bodies.
    if prog.data_overflow {
        let span = prog
            .instances
            .first()
            .map(|i| prog.pous[i.pou].span)
            .unwrap_or_default();
        diags.error(
            codes::DATA_MEMORY_EXCEEDED,
            span,
            format!(
                "the program needs more than {} MiB of data memory",
                sema::MAX_DATA >> 20
            ),
        );
    }
    let Some(emitted) = emitted.filter(|_| diags.is_empty()) else {
        let mut list = diags.list;
        list.sort_by_key(|d| (d.span.file, d.span.start));
        return Err((list, sources));
    };
    let typed::Emitted {
        builder: mut b,
        init,
        pou_ids,
        file_ids,
    } = emitted;
    b.set_init(0, &init);
    b.reserve_data(prog.data_size.max(8));
    let tasks = add_tasks(&prog, &mut b, &pou_ids);
    let vars = monitor::variable_map(&prog);
    let safe = safe_outputs(&prog);
    add_variables(&prog, &mut b, &vars, &sources, &file_ids);
    let image = match b.build() {
        Ok(i) => i,
        Err(e) => {
            let d = Diagnostic::error(
                codes::INTERNAL_ERROR,
                diagnostics::Span::new(0, 0, 0),
                format!("internal error building the image: {e}"),
            );
            return Err((vec![d], sources));
        }
    };
    // The VM's verifier is the final judge; a rejection here is a compiler bug.
    if let Err(e) = verify_image(&image) {
        let d = Diagnostic::error(
            codes::INTERNAL_ERROR,
            diagnostics::Span::new(0, 0, 0),
            format!("internal error: generated image rejected by the verifier: {e}"),
        );
        return Err((vec![d], sources));
    }
    Ok((
        Compiled {
            image,
            vars,
            tasks,
            has_configuration: prog.has_configuration,
            safe,
        },
        sources,
    ))
}

/// Adds one task record per program instance to the image; returns the tasks as the host
/// runner schedules them.
fn add_tasks(
    prog: &sema::Program,
    b: &mut plc_vm::image::ImageBuilder,
    pou_ids: &[plc_vm::image::PouId],
) -> Vec<TaskInfo> {
    let mut tasks = Vec::new();
    let mut image_task = 0usize;
    for t in &prog.tasks {
        let mut info = TaskInfo {
            name: t.name.clone(),
            interval_ns: t.interval_ns,
            single_addr: t
                .single
                .as_ref()
                .and_then(|g| prog.global(g))
                .map(|g| g.offset),
            priority: t.priority,
            image_tasks: Vec::new(),
        };
        for (inst_name, pi) in &t.programs {
            let Some(inst) = prog.instances.iter().find(|i| &i.name == inst_name) else {
                continue;
            };
            let index = b.add_task(&plc_vm::image::TaskDef {
                name: format!("{}.{}", t.name, inst_name),
                kind: if t.single.is_some() {
                    plc_vm::image::TaskKind::Event
                } else {
                    plc_vm::image::TaskKind::Cyclic
                },
                priority: t.priority.min(255) as u8,
                pou: pou_ids[*pi],
                instance_base: inst.addr,
                interval_ns: t.interval_ns.max(0) as u64,
                watchdog_budget: 0,
            });
            if let Some(trigger) = info.single_addr {
                b.set_task_trigger(index, trigger);
            }
            info.image_tasks.push(image_task);
            image_task += 1;
        }
        tasks.push(info);
    }
    tasks
}

/// Adds the variable records, the located variables and the shared globals to the image.
fn add_variables(
    prog: &sema::Program,
    b: &mut plc_vm::image::ImageBuilder,
    vars: &[monitor::MonitorVar],
    sources: &SourceMap,
    file_ids: &[u16],
) {
    // Variable-record index of each global shared with another project.
    let mut shared_records = vec![None; prog.shared.len()];
    for v in vars {
        if let Some(vt) = v.kind.var_type() {
            if let Some(i) = prog.shared.iter().position(|s| s.text == v.name) {
                shared_records[i] = Some(b.var_count());
            }
            b.add_var(
                &v.name,
                vt,
                if v.constant {
                    plc_vm::image::VAR_FLAG_CONSTANT
                } else {
                    0
                } | if v.retain {
                    plc_vm::image::VAR_FLAG_RETAIN
                } else {
                    0
                },
                v.addr,
                v.size,
            );
        }
    }
    for located in located_vars(prog) {
        b.add_located(&located);
    }
    for (shared, record) in prog.shared.iter().zip(shared_records) {
        let (line, column) = sources
            .file(shared.span.file)
            .line_col(shared.span.start as usize);
        let location = plc_vm::image::SourceLocation {
            file: file_ids[shared.span.file as usize],
            line: line as u32,
            column: column as u32,
        };
        // Every shared global is an elementary variable with a record (checked by sema).
        if let Some(record) = record {
            b.add_shared(record, shared.direction, location);
        }
    }
}

/// The safe values of the located outputs with an `{attribute 'safe'}`: a global's once, a
/// PROGRAM variable's for each instance of the PROGRAM.
fn safe_outputs(prog: &sema::Program) -> Vec<SafeOutput> {
    let mut out = Vec::new();
    for s in &prog.safe {
        let mut add = |name: String, address: u32| {
            out.push(SafeOutput {
                name,
                address,
                width: s.width,
                value: s.value,
            })
        };
        match s.pou {
            None => {
                if let Some(g) = prog.global(&s.name) {
                    add(s.text.clone(), g.offset);
                }
            }
            Some(pi) => {
                let Some(v) = prog.pous[pi].var(&s.name) else {
                    continue;
                };
                for inst in prog.instances.iter().filter(|inst| inst.pou == pi) {
                    add(format!("{}.{}", inst.name, s.text), inst.addr + v.offset);
                }
            }
        }
    }
    out
}

/// The located variables in declaration order: globals, then each program instance's.
fn located_vars(prog: &sema::Program) -> Vec<plc_vm::located::Located> {
    let globals = prog.globals.iter().map(|g| (g, 0));
    let instances = prog
        .instances
        .iter()
        .flat_map(|i| prog.pous[i.pou].vars.iter().map(move |v| (v, i.addr)));
    globals
        .chain(instances)
        .filter_map(|(v, base)| {
            Some(plc_vm::located::Located {
                location: v.location?,
                address: base + v.offset,
            })
        })
        .collect()
}

/// Parses and verifies an image, returning the verifier's reason on failure.
pub fn verify_image(image: &[u8]) -> Result<(), String> {
    let parsed = plc_vm::image::Image::parse(image).map_err(|e| e.to_string())?;
    plc_vm::verify::verify(&parsed).map_err(|e| e.to_string())?;
    Ok(())
}

/// Compiles and renders any diagnostics as text (used by `plcc check` and tests).
pub fn check(files: &[(String, String)], opts: &Options) -> Result<(), String> {
    match compile(files, opts) {
        Ok(_) => Ok(()),
        Err((diags, sources)) => Err(diagnostics::render(&sources, &diags, false)),
    }
}
