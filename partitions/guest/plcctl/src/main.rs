//! `plcctl`'s program: opens the request device for writing and the response device for
//! reading without waiting (`O_NONBLOCK`), then runs the command ([`plcctl`] says what
//! each one does and prints). Glue only.

use plcctl::{Action, Command, Failure, Link, Transport, USAGE};
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

    fn try_receive(
        &mut self,
        buf: &mut [u8; plc_online::MAX_MESSAGE],
    ) -> Result<Option<usize>, String> {
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

fn open(command: &Command) -> Result<Devices, Failure> {
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
    Ok(Devices { request, response })
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
