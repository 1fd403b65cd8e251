//! `plcc`: check, build and run IEC 61131-3 Structured Text programs.
//!
//! Exit codes: 0 success, 1 compile errors (or I/O errors), 2 usage errors (and an unknown
//! code given to `explain`), 3 uncaught trap during `run`.

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use plc_compiler::run::{RunConfig, run};
use plc_compiler::{Options, codes, compile, diagnostics};

#[derive(Parser)]
#[command(
    name = "plcc",
    version,
    about = "IEC 61131-3 Structured Text compiler and host runner"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Report diagnostics only (exit 0 if clean, 1 on errors).
    Check {
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Program to use when there are several PROGRAMs and no CONFIGURATION.
        #[arg(long)]
        program: Option<String>,
        /// Check a library: every POU is compiled, no PROGRAM is needed.
        #[arg(long, conflicts_with = "program")]
        library: bool,
    },
    /// Compile to a bytecode image.
    Build {
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Output image file.
        #[arg(short = 'o', long = "output", required = true)]
        output: PathBuf,
        #[arg(long)]
        program: Option<String>,
        /// Build a library: every POU is compiled, no PROGRAM is needed.
        #[arg(long, conflicts_with = "program")]
        library: bool,
    },
    /// Compile and run on the host with a simulated clock.
    Run {
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Number of cycles (base ticks) to run.
        #[arg(long, default_value_t = 1)]
        cycles: u64,
        /// Cycle interval without a CONFIGURATION, e.g. T#10ms.
        #[arg(long, default_value = "T#10ms", value_parser = parse_interval)]
        interval: i64,
        /// Program to run when there are several PROGRAMs and no CONFIGURATION.
        #[arg(long)]
        program: Option<String>,
        /// Variables printed after each cycle (comma separated, repeatable).
        #[arg(long)]
        print: Vec<String>,
        /// NAME=VALUE applied once before the first cycle (repeatable).
        #[arg(long, value_parser = parse_set)]
        set: Vec<(String, String)>,
    },
    /// Explain a diagnostic code, e.g. `plcc explain E0042`.
    Explain {
        /// The code, as printed in `error[E0042]`.
        #[arg(required_unless_present = "markdown")]
        code: Option<String>,
        /// Print every code as Markdown (the text of docs/plc-diagnostics.md).
        #[arg(long, conflicts_with = "code")]
        markdown: bool,
    },
}

/// `plcc explain`: the explanation of one code, or the whole list as Markdown.
fn explain(code: Option<&str>, markdown: bool) -> ExitCode {
    if markdown {
        print!("{}", codes::markdown());
        return ExitCode::SUCCESS;
    }
    let code = code.unwrap_or_default();
    match codes::lookup(code) {
        Some(e) => {
            println!("{}: {}\n\n{}", e.code, e.title, e.explanation);
            ExitCode::SUCCESS
        }
        None => {
            eprintln!(
                "plcc: `{code}` is not a diagnostic code (they are E0001 to E{:04})",
                codes::TABLE.len()
            );
            ExitCode::from(2)
        }
    }
}

fn parse_interval(s: &str) -> Result<i64, String> {
    let text = if s.contains('#') {
        s.to_string()
    } else {
        format!("T#{s}")
    };
    let mut diags = Vec::new();
    let toks = plc_compiler::lexer::lex(0, &text, &mut diags);
    match toks.first().map(|t| &t.tok) {
        Some(plc_compiler::lexer::Tok::Time(ns))
            if diags.is_empty() && toks.len() == 2 && *ns > 0 =>
        {
            Ok(*ns as i64)
        }
        _ => Err(format!("`{s}` is not a positive duration such as T#10ms")),
    }
}

fn parse_set(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((n, v)) if !n.trim().is_empty() => Ok((n.trim().to_string(), v.to_string())),
        _ => Err(format!("`{s}` is not NAME=VALUE")),
    }
}

/// Splits `a,b[1,2],c` at the commas that are not inside brackets.
fn split_names(s: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut depth = 0i32;
    let mut cur = String::new();
    for ch in s.chars() {
        match ch {
            '[' => depth += 1,
            ']' => depth -= 1,
            ',' if depth == 0 => {
                out.push(std::mem::take(&mut cur));
                continue;
            }
            _ => {}
        }
        cur.push(ch);
    }
    out.push(cur);
    out.into_iter()
        .map(|n| n.trim().to_string())
        .filter(|n| !n.is_empty())
        .collect()
}

fn read_files(files: &[PathBuf]) -> Result<Vec<(String, String)>, String> {
    files
        .iter()
        .map(|p| {
            std::fs::read_to_string(p)
                .map(|t| (p.display().to_string(), t))
                .map_err(|e| format!("plcc: cannot read {}: {e}", p.display()))
        })
        .collect()
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let (files, program, library) = match &cli.command {
        Command::Check {
            files,
            program,
            library,
        }
        | Command::Build {
            files,
            program,
            library,
            ..
        } => (files, program, *library),
        Command::Run { files, program, .. } => (files, program, false),
        Command::Explain { code, markdown } => return explain(code.as_deref(), *markdown),
    };
    let sources = match read_files(files) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(1);
        }
    };
    let opts = Options {
        program: program.clone(),
        library,
    };
    let compiled = match compile(&sources, &opts) {
        Ok((c, _)) => c,
        Err((diags, map)) => {
            let color = std::io::stderr().is_terminal();
            eprint!("{}", diagnostics::render(&map, &diags, color));
            eprintln!("plcc: {} error(s)", diags.len());
            return ExitCode::from(1);
        }
    };
    match cli.command {
        Command::Check { .. } | Command::Explain { .. } => ExitCode::SUCCESS,
        Command::Build { output, .. } => match std::fs::write(&output, &compiled.image) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("plcc: cannot write {}: {e}", output.display());
                ExitCode::from(1)
            }
        },
        Command::Run {
            cycles,
            interval,
            print,
            set,
            ..
        } => {
            let print = print.iter().flat_map(|p| split_names(p)).collect();
            let out = run(
                &compiled,
                &RunConfig {
                    cycles,
                    interval_ns: interval,
                    print,
                    set,
                },
            );
            print!("{}", out.stdout);
            let _ = std::io::stdout().flush();
            eprint!("{}", out.stderr);
            ExitCode::from(out.exit_code as u8)
        }
    }
}
