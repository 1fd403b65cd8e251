//! `plcctl`'s program: parses the command line and runs it ([`plcctl::execute`]: over the
//! request and response devices, or with `--connect` authenticated over TCP), its lines on
//! stdout, an error on stderr with the exit status [`plcctl`] documents. Glue only.

use plcctl::{Command, USAGE, execute};
use std::io::Write;
use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let command = match Command::parse(&args) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("plcctl: {e}\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    let mut stdout = std::io::stdout();
    let mut out = |line: &str| {
        let _ = writeln!(stdout, "{line}");
        let _ = stdout.flush();
    };
    match execute(&command, &mut out) {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("plcctl: {}", f.message);
            ExitCode::from(f.status as u8)
        }
    }
}
