//! `fbctl`'s program: opens the request device for writing and the response device for
//! reading without waiting (`O_NONBLOCK`), reads the command's file, then runs the command
//! ([`fbctl`] says what each one does and prints). Glue only.

use fbctl::{Action, Command, Failure, Link, Transport, USAGE};
use std::fs::{File, OpenOptions};
use std::io::{ErrorKind, Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::process::ExitCode;
use std::time::Duration;

/// Linux's `O_NONBLOCK`.
const O_NONBLOCK: i32 = 0o4000;

struct Devices {
    request: File,
    response: File,
}

impl Transport for Devices {
    fn send(&mut self, message: &[u8]) -> Result<(), String> {
        match self.request.write(message) {
            Ok(n) if n == message.len() => Ok(()),
            Ok(n) => Err(format!(
                "the request device took {n} of {} bytes",
                message.len()
            )),
            Err(e) => Err(format!("cannot send the request: {e}")),
        }
    }

    fn try_receive(&mut self, buf: &mut [u8]) -> Result<Option<usize>, String> {
        match self.response.read(buf) {
            Ok(n) => Ok(Some(n)),
            Err(e) if e.kind() == ErrorKind::WouldBlock => Ok(None),
            Err(e) => Err(format!("cannot read the response device: {e}")),
        }
    }

    fn pause(&mut self, time: Duration) {
        std::thread::sleep(time);
    }
}

fn run(command: &Command) -> Result<(), Failure> {
    let file = match &command.action {
        Action::Boot(file) | Action::Type(file) | Action::Compile { fbt: file, .. } => {
            std::fs::read(file).map_err(|e| Failure {
                message: format!("cannot read {file}: {e}"),
                status: 2,
            })?
        }
        Action::Send { .. } => Vec::new(),
    };
    let mut stdout = std::io::stdout();
    let mut print = |line: &str| {
        let _ = writeln!(stdout, "{line}");
        let _ = stdout.flush();
    };
    if let Action::Compile { out, .. } = &command.action {
        // No port devices: compiling is local.
        let mut offline = Link {
            transport: Offline,
            timeout: command.timeout,
        };
        let package = offline.run(&command.action, &file, &mut print)?;
        return std::fs::write(out, package.unwrap_or_default()).map_err(|e| Failure {
            message: format!("cannot write {out}: {e}"),
            status: 2,
        });
    }
    let fail = |path: &str, e: std::io::Error| Failure {
        message: format!("cannot open {path}: {e}"),
        status: 3,
    };
    let request = OpenOptions::new()
        .write(true)
        .open(&command.request)
        .map_err(|e| fail(&command.request, e))?;
    let response = OpenOptions::new()
        .read(true)
        .custom_flags(O_NONBLOCK)
        .open(&command.response)
        .map_err(|e| fail(&command.response, e))?;
    let mut link = Link {
        transport: Devices { request, response },
        timeout: command.timeout,
    };
    link.run(&command.action, &file, &mut print).map(drop)
}

/// The transport of a command that talks to no device.
struct Offline;

impl Transport for Offline {
    fn send(&mut self, _: &[u8]) -> Result<(), String> {
        Err("no device for this command".into())
    }
    fn try_receive(&mut self, _: &mut [u8]) -> Result<Option<usize>, String> {
        Ok(None)
    }
    fn pause(&mut self, _: Duration) {}
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let command = match Command::parse(&args) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("fbctl: {e}\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    match run(&command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("fbctl: {}", f.message);
            ExitCode::from(f.status)
        }
    }
}
