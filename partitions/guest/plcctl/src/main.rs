//! `plcctl`'s program: opens the request and response devices ([`port_devices`]), then
//! runs the command ([`plcctl`] says what each one does and prints). Glue only.

use plcctl::{Action, Command, Failure, Link, USAGE};
use port_devices::Devices;
use std::io::Write;
use std::process::ExitCode;

fn open(command: &Command) -> Result<Devices, Failure> {
    Devices::open(&command.request, &command.response)
        .map_err(|message| Failure { message, status: 3 })
}

fn run(command: &Command) -> Result<(), Failure> {
    let image = match &command.action {
        Action::Download(file) => Some(std::fs::read(file).map_err(|e| Failure {
            message: format!("cannot read {file}: {e}"),
            status: 2,
        })?),
        _ => None,
    };
    let mut link = Link::new(open(command)?, command.timeout);
    let mut stdout = std::io::stdout();
    let mut out = |line: &str| {
        let _ = writeln!(stdout, "{line}");
        let _ = stdout.flush();
    };
    match (&command.action, image) {
        (Action::Download(file), Some(image)) => link.download(file, &image, &mut out),
        (action, _) => link.run(action, &mut out),
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let command = match Command::parse(&args) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("plcctl: {e}\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    match run(&command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("plcctl: {}", f.message);
            ExitCode::from(f.status as u8)
        }
    }
}
