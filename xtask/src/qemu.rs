//! Boots an ESP folder under QEMU (TCG) and captures the serial log (COM1).
//!
//! Exit convention (kernel `qemu::exit`): 0x10 written to isa-debug-exit at port 0xf4 makes
//! QEMU exit with 33 (success), 0x11 with 35 (failure). Anything else, or a timeout, is a
//! failure unless the caller expected the system to keep running.

use crate::tools::Qemu;
use anyhow::{Context, Result};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

pub const EXIT_SUCCESS: i32 = 33;
pub const EXIT_FAILURE: i32 = 35;

/// Lines after which the run cannot recover; QEMU is stopped at once.
const FATAL_MARKERS: &[&str] = &["loader: error:"];

#[derive(Clone, Debug)]
pub struct RunOptions {
    pub esp: PathBuf,
    /// Stop QEMU after this long.
    pub timeout: Option<Duration>,
    /// Print serial lines as they arrive.
    pub echo: bool,
    /// Where to put the per-run copy of the OVMF variable store.
    pub work_dir: PathBuf,
    /// Run on deterministic virtual time (`-icount`): the guest clock advances with the
    /// instructions executed, so host scheduling stalls cannot make a timer late. For
    /// scenarios that assert a timing property of the kernel rather than measure QEMU.
    pub deterministic_time: bool,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Ending {
    /// QEMU exited by itself with this code.
    Exited(i32),
    /// QEMU was killed by a signal or did not report a code.
    Killed,
    /// The timeout elapsed; QEMU was stopped.
    TimedOut,
    /// A fatal marker line appeared; QEMU was stopped.
    Aborted(String),
}

#[derive(Clone, Debug)]
pub struct Outcome {
    pub ending: Ending,
    /// Serial lines (COM1), without line terminators.
    pub lines: Vec<String>,
    pub stderr: String,
    pub elapsed: Duration,
}

impl Outcome {
    pub fn succeeded(&self) -> bool {
        self.ending == Ending::Exited(EXIT_SUCCESS)
    }

    /// The first line containing `needle`.
    pub fn line(&self, needle: &str) -> Option<&str> {
        self.lines
            .iter()
            .map(String::as_str)
            .find(|l| l.contains(needle))
    }

    /// The serial log followed by QEMU's stderr, for failure messages.
    pub fn transcript(&self) -> String {
        format!(
            "--- ending: {:?} after {:.1} s\n--- serial:\n{}\n--- qemu stderr:\n{}",
            self.ending,
            self.elapsed.as_secs_f64(),
            self.lines.join("\n"),
            self.stderr
        )
    }
}

pub fn command(qemu: &Qemu, esp: &Path, vars: &Path, deterministic_time: bool) -> Command {
    let mut cmd = Command::new(&qemu.binary);
    cmd.args([
        "-nodefaults",
        "-machine",
        "q35",
        "-m",
        "512M",
        "-cpu",
        // QEMU 7.2's TCG has no TSC-deadline mode: the kernel's timer uses one-shot counts.
        "qemu64",
        "-display",
        "none",
        "-no-reboot",
    ]);
    cmd.arg("-drive").arg(format!(
        "if=pflash,format=raw,readonly=on,file={}",
        qemu.ovmf_code.display()
    ));
    cmd.arg("-drive")
        .arg(format!("if=pflash,format=raw,file={}", vars.display()));
    cmd.arg("-drive")
        .arg(format!("format=raw,file=fat:rw:{}", esp.display()));
    cmd.args([
        "-serial",
        "stdio",
        // COM2 (0x2f8, IRQ 3) exists but goes nowhere: a device user threads can drive
        // (interrupt tests put it in loopback mode; the guest's console later).
        "-serial",
        "null",
        "-device",
        "isa-debug-exit,iobase=0xf4,iosize=0x04",
    ]);
    if deterministic_time {
        // 2 ns of virtual time per instruction (a 500 MHz guest); no sleeping when idle,
        // so idle time passes at once instead of in host time.
        cmd.args(["-icount", "shift=1,sleep=off"]);
    }
    cmd
}

fn stop(child: &mut Child) {
    let _ = child.kill();
    let _ = child.wait();
}

pub fn run(qemu: &Qemu, options: &RunOptions) -> Result<Outcome> {
    std::fs::create_dir_all(&options.work_dir)?;
    let vars = options.work_dir.join("OVMF_VARS.fd");
    std::fs::copy(&qemu.ovmf_vars, &vars)
        .with_context(|| format!("cannot copy {}", qemu.ovmf_vars.display()))?;
    let mut child = command(qemu, &options.esp, &vars, options.deterministic_time)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("cannot start {}", qemu.binary.display()))?;
    let started = Instant::now();

    let (tx, rx) = mpsc::channel();
    let stdout = child.stdout.take().expect("piped stdout");
    std::thread::spawn(move || {
        let mut reader = BufReader::new(stdout);
        let mut buf = Vec::new();
        // Firmware output may contain escape sequences and invalid UTF-8: read raw bytes.
        while reader
            .read_until(b'\n', &mut buf)
            .map(|n| n > 0)
            .unwrap_or(false)
        {
            let line = String::from_utf8_lossy(&buf)
                .trim_end_matches(['\n', '\r'])
                .to_string();
            if tx.send(line).is_err() {
                break;
            }
            buf.clear();
        }
    });
    let stderr = child.stderr.take().expect("piped stderr");
    let stderr_reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = std::io::Read::read_to_string(&mut BufReader::new(stderr), &mut text);
        text
    });

    let mut lines = Vec::new();
    let deadline = options.timeout.map(|t| started + t);
    let ending = loop {
        let wait = deadline
            .map(|d| d.saturating_duration_since(Instant::now()))
            .unwrap_or(Duration::from_secs(3600));
        match rx.recv_timeout(wait) {
            Ok(line) => {
                if options.echo {
                    println!("{line}");
                }
                let fatal = FATAL_MARKERS.iter().any(|m| line.contains(m));
                lines.push(line.clone());
                if fatal {
                    stop(&mut child);
                    break Ending::Aborted(line);
                }
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                if deadline.is_some_and(|d| Instant::now() >= d) {
                    stop(&mut child);
                    break Ending::TimedOut;
                }
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                let status = child.wait()?;
                break status.code().map_or(Ending::Killed, Ending::Exited);
            }
        }
    };
    let stderr = stderr_reader.join().unwrap_or_default();
    // Kept for reading after a passing run too (scenario logs hold measurements).
    let _ = std::fs::write(options.work_dir.join("serial.log"), lines.join("\n") + "\n");
    Ok(Outcome {
        ending,
        lines,
        stderr,
        elapsed: started.elapsed(),
    })
}
