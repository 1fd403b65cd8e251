//! `fbctl`'s program: reads the command's file, opens the request and response devices
//! ([`port_devices`]) or the TCP connection (`--tcp`), then runs the command ([`fbctl`] says what each one does and
//! prints). Glue only.

use fbctl::{Action, Command, Failure, Link, TcpTransport, Transport, USAGE, read_adapters};
use port_devices::Devices;
use std::io::Write;
use std::process::ExitCode;
use std::time::Duration;

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
    let adapters = read_adapters(&command.adapters)?;
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
            adapters: adapters.clone(),
        };
        let package = offline.run(&command.action, &file, &mut print)?;
        return std::fs::write(out, package.unwrap_or_default()).map_err(|e| Failure {
            message: format!("cannot write {out}: {e}"),
            status: 2,
        });
    }
    if let Some(address) = &command.tcp {
        let tcp = TcpTransport::connect(address, command.timeout)
            .map_err(|message| Failure { message, status: 3 })?;
        let mut link = Link {
            transport: tcp,
            timeout: command.timeout,
            adapters: adapters.clone(),
        };
        return link.run(&command.action, &file, &mut print).map(drop);
    }
    let devices = Devices::open(&command.request, &command.response)
        .map_err(|message| Failure { message, status: 3 })?;
    let mut link = Link {
        transport: devices,
        timeout: command.timeout,
        adapters,
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
