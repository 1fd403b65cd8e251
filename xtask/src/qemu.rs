//! Boots an ESP folder (or, for the native reference of the guest benchmark, a Linux
//! kernel directly: [`run_linux`]) under QEMU (TCG) and captures the serial log (COM1),
//! with COM2 (the guest's console) unconnected, fed from a script ([`Com2::Scripted`]:
//! scenarios) or on this terminal ([`Com2::Terminal`]: `cargo xtask run`).
//!
//! Exit convention (kernel `qemu::exit`): 0x10 written to isa-debug-exit at port 0xf4 makes
//! QEMU exit with 33 (success), 0x11 with 35 (failure). Anything else, or a timeout, is a
//! failure unless the caller expected the system to keep running.
//!
//! A power cut ([`run_cut`], scenario `store_power_cut`): QEMU is killed with SIGKILL a
//! chosen delay after a chosen COM1 line, without a shutdown, and the run ends as
//! [`Ending::Cut`] (killed by us, not a crash).

use crate::tools::Qemu;
use anyhow::{Context, Result};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, mpsc};
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
    pub com2: Com2,
    /// Stop QEMU as soon as the log has shown each of these texts ([`Ending::Done`]).
    pub done_when: Vec<String>,
    /// More QEMU arguments: devices such as the NIC ([`nic`]).
    pub extra_args: Vec<String>,
}

/// The NIC of `cargo xtask run`: a virtio-net function at PCI address 00:03.0 (its INTA
/// reaches IOAPIC input 23 on q35), modern transport only and with `iommu_platform=on`:
/// QEMU lets a virtio device DMA past the IOMMU unless it offers VIRTIO_F_ACCESS_PLATFORM
/// (which a transitional device cannot), so only then does [`iommu`] confine it. On
/// QEMU's user-mode network, each of `forwards`
/// (host port, guest port) a TCP forward that listens on 127.0.0.1 only, never on
/// another interface of the host.
pub fn nic(forwards: &[(u16, &str, u16)]) -> Vec<String> {
    let mut backend = String::from("user");
    for (host, address, port) in forwards {
        backend.push_str(&format!(",hostfwd=tcp:127.0.0.1:{host}-{address}:{port}"));
    }
    nic_on(&backend)
}

/// The NIC of [`nic`] on QEMU network backend `backend` (`-netdev`'s value without its id:
/// `user,hostfwd=...` or `dgram,local...,remote...` for a link between two machines); with
/// [`iommu`] before it.
pub fn nic_on(backend: &str) -> Vec<String> {
    vec![
        "-netdev".into(),
        format!("{backend},id=net0"),
        "-device".into(),
        "virtio-net-pci,netdev=net0,addr=03.0,disable-legacy=on,iommu_platform=on".into(),
    ]
}

/// The IOMMU of `cargo xtask run` (and of scenarios that give partitions DMA regions): QEMU's
/// VT-d, which the kernel programs so that a partition's devices reach only its DMA region
/// (`dma`). QEMU wants it before every PCI device on the command line.
pub fn iommu() -> Vec<String> {
    vec!["-device".into(), "intel-iommu".into()]
}

/// What `cargo xtask run` forwards to the NIC (host port on 127.0.0.1, address and port
/// behind the NIC): the soft-PLC's Modbus/TCP server and online service on TCP (its
/// `plc.net` address in config/systems/plc-guest.toml) and the guest's HTTP port,
/// documented in docs/commands.md.
pub const RUN_FORWARDS: &[(u16, &str, u16)] = &[
    (10502, "10.0.2.16", 502),
    (11202, "10.0.2.16", 1202),
    (10080, "10.0.2.15", 80),
];

/// Where COM2 goes.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum Com2 {
    /// Nowhere (a device user threads can drive: interrupt tests put it in loopback mode).
    #[default]
    Unconnected,
    /// Typed from a script: once the output shows `start` (the firmware and the loader
    /// write to COM2 too), each piece is sent when the output has been quiet for [`QUIET`]
    /// after it grew (a prompt came), as a person would type; the output is
    /// [`Outcome::console`]. Through a pair of FIFOs `work_dir/com2.{in,out}`.
    Scripted { start: String, input: Vec<String> },
    /// This terminal, raw, multiplexed with QEMU's monitor (Ctrl-A X quits, Ctrl-A C
    /// switches to the monitor); COM1 then goes to `work_dir/com1.log`, not echoed.
    Terminal,
}

/// How long the console output must stay unchanged before a scripted piece is typed.
pub const QUIET: Duration = Duration::from_millis(500);
/// Longest wait for output before a scripted piece is typed anyway.
const PROMPT_WAIT: Duration = Duration::from_secs(60);

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
    /// Every text of [`RunOptions::done_when`] appeared; QEMU was stopped.
    Done,
    /// The power cut of [`run_cut`]: we killed QEMU with SIGKILL (not a crash, not a
    /// timeout); [`Outcome::lines`] hold every COM1 line QEMU wrote before it died.
    Cut,
    /// The caller's flag of [`run_until`] was set; QEMU was stopped.
    Stopped,
}

/// When [`run_cut`] cuts the power: `delay` after the first COM1 line that contains
/// `after` (a point of the workload, such as its first line: TCG boot times vary with the
/// host's load, a delay from QEMU's start would not). The cut is SIGKILL: QEMU neither
/// shuts down nor writes anything more, so a disk image keeps exactly what QEMU had
/// written to it by then (with `cache=writeback`, what a guest's flush had made durable
/// and whatever else had left QEMU; the host's page cache survives a killed process), the
/// way a machine losing power keeps what reached its disk.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PowerCut {
    pub after: String,
    pub delay: Duration,
}

#[derive(Clone, Debug)]
pub struct Outcome {
    pub ending: Ending,
    /// Serial lines (COM1), without line terminators.
    pub lines: Vec<String>,
    /// What came out of COM2 ([`Com2::Scripted`]), as it came (`\r\n` line ends from the
    /// guest's terminal, escape sequences).
    pub console: String,
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
            "--- ending: {:?} after {:.1} s\n--- serial:\n{}\n--- console (COM2):\n{}\n--- qemu stderr:\n{}",
            self.ending,
            self.elapsed.as_secs_f64(),
            self.lines.join("\n"),
            self.console,
            self.stderr
        )
    }

    /// The console's output as lines, without the terminal's carriage returns.
    pub fn console_lines(&self) -> Vec<&str> {
        self.console
            .split('\n')
            .map(|l| l.trim_end_matches('\r'))
            .collect()
    }
}

/// What QEMU boots.
#[derive(Clone, Copy, Debug)]
pub enum Media<'a> {
    /// An ESP folder, as a FAT drive the firmware boots from.
    Esp(&'a Path),
    /// A Linux kernel and initramfs QEMU hands to the firmware (`-kernel`, `-initrd`,
    /// `-append`; OVMF boots it through its EFI stub): no drive.
    Linux(&'a LinuxBoot),
}

/// A Linux kernel to boot directly ([`run_linux`]).
#[derive(Clone, Debug)]
pub struct LinuxBoot {
    pub kernel: PathBuf,
    pub initrd: PathBuf,
    pub command_line: String,
}

/// The emulated machine of every run: the same for the Warden systems and a stock Linux
/// kernel ([`run_linux`]), so their cycle counts compare.
pub const MACHINE: &[&str] = &[
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
];

pub fn command(
    qemu: &Qemu,
    media: Media,
    vars: &Path,
    deterministic_time: bool,
    com2: &Com2,
    work_dir: &Path,
    held: Option<&HeldCpu>,
) -> Command {
    let mut cmd = match held.map(|h| h.cpu) {
        Some(cpu) => {
            let mut cmd = Command::new(TASKSET);
            cmd.arg("-c").arg(cpu.to_string()).arg(&qemu.binary);
            cmd
        }
        None => Command::new(&qemu.binary),
    };
    cmd.args(MACHINE);
    // At least the CPUs the booted system uses, or `WARDEN_SMP=N` if that is more (a
    // scenario's own `-smp` in `qemu_args` comes later and wins).
    let configured = match media {
        Media::Esp(esp) => configured_cpus(esp),
        Media::Linux(_) => None,
    };
    let smp_env = std::env::var("WARDEN_SMP").ok();
    if let Some(cpus) = smp(smp_env.as_deref(), configured) {
        cmd.arg("-smp").arg(cpus);
    }
    cmd.arg("-drive").arg(format!(
        "if=pflash,format=raw,readonly=on,file={}",
        qemu.ovmf_code.display()
    ));
    cmd.arg("-drive")
        .arg(format!("if=pflash,format=raw,file={}", vars.display()));
    match media {
        Media::Esp(esp) => {
            cmd.arg("-drive")
                .arg(format!("format=raw,file=fat:rw:{}", esp.display()));
        }
        Media::Linux(linux) => {
            cmd.arg("-kernel").arg(&linux.kernel);
            cmd.arg("-initrd").arg(&linux.initrd);
            cmd.arg("-append").arg(&linux.command_line);
        }
    }
    // COM1 (the kernel log), then COM2 (0x2f8, IRQ 3).
    match com2 {
        Com2::Unconnected => {
            cmd.args(["-serial", "stdio", "-serial", "null"]);
        }
        Com2::Scripted { .. } => {
            cmd.args(["-serial", "stdio", "-chardev"]);
            cmd.arg(format!(
                "pipe,id=com2,path={}",
                work_dir.join("com2").display()
            ));
            cmd.args(["-serial", "chardev:com2"]);
        }
        Com2::Terminal => {
            cmd.arg("-serial")
                .arg(format!("file:{}", work_dir.join("com1.log").display()));
            // Ctrl-C goes to the guest (signal=off); Ctrl-A X quits QEMU.
            cmd.args([
                "-chardev",
                "stdio,id=com2,mux=on,signal=off",
                "-serial",
                "chardev:com2",
                "-mon",
                "chardev=com2,mode=readline",
            ]);
        }
    }
    cmd.args(["-device", "isa-debug-exit,iobase=0xf4,iosize=0x04"]);
    if deterministic_time {
        // 2 ns of virtual time per instruction (a 500 MHz guest); no sleeping when idle,
        // so idle time passes at once instead of in host time.
        cmd.args(["-icount", "shift=1,sleep=off"]);
    }
    cmd
}

/// util-linux's `taskset`, which starts a program held to some of the host's CPUs.
const TASKSET: &str = "/usr/bin/taskset";

/// Runs held to each of this process's CPUs now (index: the CPU).
static HELD: Mutex<Vec<usize>> = Mutex::new(Vec::new());

/// The host CPU a run on deterministic time is held to while this lives: the one the
/// fewest runs of this process are held to now, so that the two scenarios run at a time
/// get different ones. On deterministic time QEMU runs the guest's CPUs in turns on one
/// thread, and every idle stretch of the guest is a hand-off between that thread and
/// QEMU's main loop (the main loop moves the virtual clock to the next timer); where
/// waking a thread on another host CPU is slow (a host that is itself a virtual machine),
/// those hand-offs set the pace: the default system's virtual time ran at 0.08 of real
/// time with QEMU's threads on two CPUs, 0.47 with them held to one.
pub struct HeldCpu {
    cpu: usize,
}

impl HeldCpu {
    /// The least-held CPU, if `taskset` is there.
    fn take() -> Option<HeldCpu> {
        let cpus = std::thread::available_parallelism().ok()?.get();
        if !Path::new(TASKSET).is_file() {
            return None;
        }
        let mut held = HELD.lock().unwrap_or_else(|e| e.into_inner());
        if held.len() < cpus {
            held.resize(cpus, 0);
        }
        let cpu = (0..cpus).min_by_key(|&c| held[c])?;
        held[cpu] += 1;
        Some(HeldCpu { cpu })
    }
}

impl Drop for HeldCpu {
    fn drop(&mut self) {
        let mut held = HELD.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(n) = held.get_mut(self.cpu) {
            *n = n.saturating_sub(1);
        }
    }
}

/// The `-smp` value of a run: the larger of `WARDEN_SMP` (`warden_smp`) and the CPUs the
/// booted system's configuration uses (`configured`, see [`configured_cpus`]); none when
/// neither asks for more than QEMU's one CPU. A `WARDEN_SMP` that is not a plain count
/// (such as `4,sockets=2`) is passed on as it is.
pub fn smp(warden_smp: Option<&str>, configured: Option<u8>) -> Option<String> {
    let configured = configured.map_or(1, u32::from);
    match warden_smp.map(str::trim) {
        Some(text) => match text.parse::<u32>() {
            Ok(n) => Some(n.max(configured).to_string()),
            Err(_) => Some(text.to_string()),
        },
        None => (configured > 1).then(|| configured.to_string()),
    }
}

/// How many CPUs the system in the ESP folder `esp` uses: `[system] cpus` of the `config`
/// entry of its `system.img`; `None` when it has none that decodes (no configuration, a
/// damaged image on purpose).
pub fn configured_cpus(esp: &Path) -> Option<u8> {
    let bytes = std::fs::read(esp.join("system.img")).ok()?;
    let image = abi::sysimg::SystemImage::parse(&bytes).ok()?;
    let entry = image.find("config")?;
    config::decode(entry.data).ok().map(|system| system.cpus())
}

fn stop(child: &mut Child) {
    // SIGTERM first: QEMU then restores the terminal it put in raw mode.
    let terminated = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .is_ok_and(|s| s.success());
    if terminated {
        let until = Instant::now() + Duration::from_secs(5);
        while Instant::now() < until {
            if child.try_wait().ok().flatten().is_some() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// COM2's output so far and when it last grew.
#[derive(Default)]
struct ConsoleOutput {
    bytes: Vec<u8>,
    changed: Option<Instant>,
}

/// Makes the FIFOs of a scripted COM2 (`base.in`, `base.out`).
fn make_fifos(base: &Path) -> Result<()> {
    for end in ["in", "out"] {
        let path = base.with_extension(end);
        let _ = std::fs::remove_file(&path);
        let ok = Command::new("mkfifo")
            .arg(&path)
            .status()
            .is_ok_and(|s| s.success());
        if !ok {
            anyhow::bail!("cannot create the FIFO {}", path.display());
        }
    }
    Ok(())
}

/// Reads COM2's output (`base.out`) until QEMU closes it.
fn read_console(base: PathBuf, output: Arc<Mutex<ConsoleOutput>>) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let Ok(mut fifo) = std::fs::File::open(base.with_extension("out")) else {
            return;
        };
        let mut buf = [0u8; 4096];
        while let Ok(n) = std::io::Read::read(&mut fifo, &mut buf) {
            if n == 0 {
                break;
            }
            let mut o = output.lock().unwrap_or_else(|e| e.into_inner());
            o.bytes.extend_from_slice(&buf[..n]);
            o.changed = Some(Instant::now());
        }
    })
}

/// Types `script` into COM2 (`base.in`) once the output shows `start`, each piece once the
/// output grew and went quiet.
fn type_console(
    base: PathBuf,
    start: String,
    script: Vec<String>,
    output: Arc<Mutex<ConsoleOutput>>,
) {
    std::thread::spawn(move || {
        let Ok(mut fifo) = std::fs::OpenOptions::new()
            .write(true)
            .open(base.with_extension("in"))
        else {
            return;
        };
        let mut seen = 0;
        let asked = Instant::now();
        while asked.elapsed() < PROMPT_WAIT {
            std::thread::sleep(Duration::from_millis(50));
            let o = output.lock().unwrap_or_else(|e| e.into_inner());
            if let Some(at) = String::from_utf8_lossy(&o.bytes).find(&start) {
                seen = at;
                break;
            }
        }
        for piece in script {
            let asked = Instant::now();
            loop {
                std::thread::sleep(Duration::from_millis(50));
                let o = output.lock().unwrap_or_else(|e| e.into_inner());
                let quiet = o.changed.is_some_and(|t| t.elapsed() >= QUIET);
                if (o.bytes.len() > seen && quiet) || asked.elapsed() >= PROMPT_WAIT {
                    seen = o.bytes.len();
                    break;
                }
            }
            if std::io::Write::write_all(&mut fifo, piece.as_bytes()).is_err() {
                return;
            }
        }
    });
}

/// Follows COM1's log file (`Com2::Terminal`), a line at a time, until `done`.
fn follow(path: PathBuf, tx: mpsc::Sender<String>, done: Arc<Mutex<bool>>) {
    std::thread::spawn(move || {
        let Ok(mut file) = std::fs::File::open(&path) else {
            return;
        };
        let mut pending = Vec::new();
        loop {
            let finished = *done.lock().unwrap_or_else(|e| e.into_inner());
            // Reads on from where the last read ended.
            if std::io::Read::read_to_end(&mut file, &mut pending).is_ok() {
                while let Some(end) = pending.iter().position(|&b| b == b'\n') {
                    let line: Vec<u8> = pending.drain(..=end).collect();
                    let text = String::from_utf8_lossy(&line)
                        .trim_end_matches(['\n', '\r'])
                        .to_string();
                    if tx.send(text).is_err() {
                        return;
                    }
                }
            }
            if finished {
                return;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    });
}

/// Runs `boot` (a QEMU run) while `host` works beside it on another thread (a benchmark's
/// host side, timing the system from here); `host` sees its flag set once QEMU has ended,
/// to stop waiting for an answer. Both results.
pub fn with_host<T: Send>(
    boot: impl FnOnce() -> Result<Outcome>,
    host: impl FnOnce(&AtomicBool) -> Result<T> + Send,
) -> (Result<Outcome>, Result<T>) {
    let ended = AtomicBool::new(false);
    std::thread::scope(|scope| {
        let host = scope.spawn(|| host(&ended));
        let outcome = boot();
        ended.store(true, Ordering::SeqCst);
        let measured = host
            .join()
            .unwrap_or_else(|_| Err(anyhow::anyhow!("the host side panicked")));
        (outcome, measured)
    })
}

/// How long a benchmark's host side waits for the system it measures to answer first.
pub const READY_WITHIN: Duration = Duration::from_secs(300);

/// Asks `probe` every half second until it answers (`Ok(Some)`), for a host side waiting
/// for `what` in the booting system to answer; fails when the probe does, when QEMU has
/// `ended`, or after [`READY_WITHIN`].
pub fn when_answering<T>(
    what: &str,
    ended: &AtomicBool,
    mut probe: impl FnMut() -> Result<Option<T>>,
) -> Result<T> {
    let start = Instant::now();
    loop {
        if let Some(answer) = probe()? {
            eprintln!(
                "xtask: {what} answered after {:.1} s",
                start.elapsed().as_secs_f64()
            );
            return Ok(answer);
        }
        anyhow::ensure!(
            !ended.load(Ordering::SeqCst),
            "QEMU ended before {what} answered"
        );
        anyhow::ensure!(
            start.elapsed() <= READY_WITHIN,
            "{what} did not answer within {READY_WITHIN:?}"
        );
        std::thread::sleep(Duration::from_millis(500));
    }
}

/// Boots `options.esp`.
pub fn run(qemu: &Qemu, options: &RunOptions) -> Result<Outcome> {
    launch(qemu, Media::Esp(&options.esp), options, None, None)
}

/// Boots `options.esp` as [`run`] does, and stops QEMU ([`Ending::Stopped`]) once `stop`
/// is set (within 200 ms) and every text of `options.done_when` has appeared, unless the
/// system ended first: for a run that lasts as long as something beside it (a client on
/// the host) and at least until the log says enough has happened.
pub fn run_until(qemu: &Qemu, options: &RunOptions, stop: &AtomicBool) -> Result<Outcome> {
    launch(qemu, Media::Esp(&options.esp), options, None, Some(stop))
}

/// Boots `options.esp` and cuts its power as `cut` says: the outcome ends with
/// [`Ending::Cut`], or as [`run`]'s would when the system ended first (its line never came,
/// it exited, the timeout). Not with [`Com2::Terminal`] (a killed QEMU leaves the terminal
/// raw).
pub fn run_cut(qemu: &Qemu, options: &RunOptions, cut: &PowerCut) -> Result<Outcome> {
    anyhow::ensure!(
        options.com2 != Com2::Terminal,
        "a power cut kills QEMU, which would leave this terminal raw: not with Com2::Terminal"
    );
    anyhow::ensure!(
        !cut.after.is_empty(),
        "a power cut needs a line to count from"
    );
    launch(qemu, Media::Esp(&options.esp), options, Some(cut), None)
}

/// Boots the Linux kernel `linux` on the same machine and firmware as [`run`], with COM1
/// (its console, if the command line says `console=ttyS0`) captured; `options.esp` and
/// `options.com2` are not used (COM2 is unconnected).
pub fn run_linux(qemu: &Qemu, linux: &LinuxBoot, options: &RunOptions) -> Result<Outcome> {
    let options = RunOptions {
        com2: Com2::Unconnected,
        done_when: Vec::new(),
        ..options.clone()
    };
    launch(qemu, Media::Linux(linux), &options, None, None)
}

fn launch(
    qemu: &Qemu,
    media: Media,
    options: &RunOptions,
    cut: Option<&PowerCut>,
    stop_when: Option<&AtomicBool>,
) -> Result<Outcome> {
    std::fs::create_dir_all(&options.work_dir)?;
    let vars = options.work_dir.join("OVMF_VARS.fd");
    std::fs::copy(&qemu.ovmf_vars, &vars)
        .with_context(|| format!("cannot copy {}", qemu.ovmf_vars.display()))?;
    let terminal = options.com2 == Com2::Terminal;
    let com2_base = options.work_dir.join("com2");
    let com1_log = options.work_dir.join("com1.log");
    if let Com2::Scripted { .. } = options.com2 {
        make_fifos(&com2_base)?;
    }
    if terminal {
        std::fs::write(&com1_log, "")?;
    }
    // Held until QEMU has ended (this function waits for it).
    let held = options.deterministic_time.then(HeldCpu::take).flatten();
    let mut cmd = command(
        qemu,
        media,
        &vars,
        options.deterministic_time,
        &options.com2,
        &options.work_dir,
        held.as_ref(),
    );
    cmd.args(&options.extra_args);
    // QEMU runs the CPUs in turns on one host thread on deterministic time and with a
    // scenario's `thread=single`; the kernel cannot tell that from a loaded host.
    if options.deterministic_time
        || options
            .extra_args
            .iter()
            .any(|a| a.contains("thread=single"))
    {
        let file = String::from_utf8_lossy(abi::boot::CPUS_IN_TURNS_FILE);
        cmd.arg("-fw_cfg").arg(format!("name={file},string=1"));
    }
    if terminal {
        cmd.stdin(Stdio::inherit()).stdout(Stdio::inherit());
    } else {
        cmd.stdin(Stdio::null()).stdout(Stdio::piped());
    }
    let mut child = cmd
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("cannot start {}", qemu.binary.display()))?;
    let started = Instant::now();

    let console = Arc::new(Mutex::new(ConsoleOutput::default()));
    let console_reader = match &options.com2 {
        Com2::Scripted { start, input } => {
            let reader = read_console(com2_base.clone(), console.clone());
            let script = (start.clone(), input.clone());
            type_console(com2_base.clone(), script.0, script.1, console.clone());
            Some(reader)
        }
        _ => None,
    };
    let (tx, rx) = mpsc::channel();
    let followed = Arc::new(Mutex::new(false));
    if terminal {
        follow(com1_log.clone(), tx, followed.clone());
    } else {
        let stdout = child.stdout.take().expect("piped stdout");
        spawn_line_reader(stdout, tx);
    }
    let stderr = child.stderr.take().expect("piped stderr");
    let stderr_reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = std::io::Read::read_to_string(&mut BufReader::new(stderr), &mut text);
        text
    });

    let mut lines = Vec::new();
    let mut awaited: Vec<&str> = options.done_when.iter().map(String::as_str).collect();
    let deadline = options.timeout.map(|t| started + t);
    // When the power cut is due (once its line came).
    let mut cut_at: Option<Instant> = None;
    let ending = loop {
        if cut_at.is_some_and(|at| Instant::now() >= at) {
            // SIGKILL (`Child::kill` on Unix): no shutdown.
            let _ = child.kill();
            let _ = child.wait();
            // The lines QEMU wrote before it died, still in the pipe: the reader ends at
            // its end of file (bounded, should something else hold the pipe open).
            let until = Instant::now() + Duration::from_secs(5);
            while let Ok(line) = rx.recv_timeout(until.saturating_duration_since(Instant::now())) {
                if options.echo {
                    println!("{line}");
                }
                lines.push(line);
            }
            break Ending::Cut;
        }
        if awaited.is_empty() && stop_when.is_some_and(|flag| flag.load(Ordering::SeqCst)) {
            stop(&mut child);
            break Ending::Stopped;
        }
        let wait = deadline
            .map(|d| d.saturating_duration_since(Instant::now()))
            .unwrap_or(Duration::from_secs(3600))
            .min(Duration::from_millis(200))
            .min(cut_at.map_or(Duration::MAX, |at| {
                at.saturating_duration_since(Instant::now())
            }));
        match rx.recv_timeout(wait) {
            Ok(line) => {
                if options.echo && !terminal {
                    println!("{line}");
                }
                if let Some(cut) = cut
                    && cut_at.is_none()
                    && line.contains(&cut.after)
                {
                    cut_at = Some(Instant::now() + cut.delay);
                }
                let fatal = FATAL_MARKERS.iter().any(|m| line.contains(m));
                let was_awaited = !awaited.is_empty();
                awaited.retain(|text| !line.contains(text));
                lines.push(line.clone());
                if fatal {
                    stop(&mut child);
                    break Ending::Aborted(line);
                }
                if was_awaited && awaited.is_empty() && stop_when.is_none() {
                    stop(&mut child);
                    break Ending::Done;
                }
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                if deadline.is_some_and(|d| Instant::now() >= d) {
                    stop(&mut child);
                    break Ending::TimedOut;
                }
                if terminal && let Some(status) = child.try_wait()? {
                    break status.code().map_or(Ending::Killed, Ending::Exited);
                }
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                let status = child.wait()?;
                break status.code().map_or(Ending::Killed, Ending::Exited);
            }
        }
    };
    if terminal {
        // The log's last lines.
        *followed.lock().unwrap_or_else(|e| e.into_inner()) = true;
        while let Ok(line) = rx.recv_timeout(Duration::from_secs(1)) {
            lines.push(line);
        }
    }
    let stderr = stderr_reader.join().unwrap_or_default();
    let console = match console_reader {
        Some(reader) => {
            // Opening the ends QEMU never opened (it failed to start) unblocks the threads.
            for end in ["in", "out"] {
                let _ = std::fs::OpenOptions::new()
                    .read(true)
                    .write(true)
                    .open(com2_base.with_extension(end));
            }
            let _ = reader.join();
            let o = console.lock().unwrap_or_else(|e| e.into_inner());
            String::from_utf8_lossy(&o.bytes).into_owned()
        }
        None => String::new(),
    };
    // Kept for reading after a passing run too (scenario logs hold measurements).
    let _ = std::fs::write(options.work_dir.join("serial.log"), lines.join("\n") + "\n");
    // How it ended and how long it took (real time), to find a suite's slow runs.
    let elapsed = started.elapsed();
    let _ = std::fs::write(
        options.work_dir.join("ending.txt"),
        format!("{ending:?} after {:.1} s\n", elapsed.as_secs_f64()),
    );
    if !console.is_empty() {
        let _ = std::fs::write(options.work_dir.join("console.log"), &console);
    }
    Ok(Outcome {
        ending,
        lines,
        console,
        stderr,
        elapsed,
    })
}

/// Sends COM1's lines (QEMU's stdout) to `tx`.
fn spawn_line_reader(stdout: std::process::ChildStdout, tx: mpsc::Sender<String>) {
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
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs held at once go to different CPUs while there are free ones, and a CPU is
    /// free again when its run ends.
    #[test]
    fn runs_held_at_once_get_the_least_held_cpus() {
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        let Some(first) = HeldCpu::take() else {
            return; // no taskset: runs are not held
        };
        let second = HeldCpu::take().unwrap();
        if cpus >= 2 {
            assert_ne!(first.cpu, second.cpu);
        }
        let freed = first.cpu;
        drop(first);
        let third = HeldCpu::take().unwrap();
        if cpus == 2 {
            assert_eq!(third.cpu, freed, "the CPU its run left");
        }
    }

    #[test]
    fn a_power_cut_kills_qemu_its_delay_after_its_line() {
        let dir = std::env::temp_dir().join(format!("warden-power-cut-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // A stand-in for QEMU that never ends by itself (a tick every 10 ms, for 30 s).
        // `install` writes it in its own process: no thread of this one holds it open for
        // writing when it is started (ETXTBSY).
        let script = dir.join("fake-qemu.sh");
        std::fs::write(
            &script,
            "#!/bin/sh\necho booting\necho workload starts\ni=0\nwhile [ $i -lt 3000 ]; do echo tick $i; i=$((i + 1)); sleep 0.01; done\n",
        )
        .unwrap();
        let fake = dir.join("fake-qemu");
        let installed = Command::new("install")
            .args(["-m", "755"])
            .arg(&script)
            .arg(&fake)
            .status()
            .unwrap();
        assert!(installed.success());
        let vars = dir.join("vars.fd");
        std::fs::write(&vars, b"").unwrap();
        let tools = Qemu {
            binary: fake,
            ovmf_code: vars.clone(),
            ovmf_vars: vars,
        };
        let options = RunOptions {
            esp: dir.clone(),
            timeout: Some(Duration::from_secs(20)),
            echo: false,
            work_dir: dir.join("state"),
            deterministic_time: false,
            com2: Com2::Unconnected,
            done_when: Vec::new(),
            extra_args: Vec::new(),
        };
        let cut = PowerCut {
            after: "workload starts".into(),
            delay: Duration::from_millis(300),
        };
        let o = run_cut(&tools, &options, &cut).unwrap();
        assert_eq!(o.ending, Ending::Cut, "{}", o.transcript());
        assert_eq!(o.lines[..2], ["booting", "workload starts"]);
        assert!(o.lines.iter().any(|l| l.starts_with("tick ")));
        assert!(o.elapsed < Duration::from_secs(15), "{:?}", o.elapsed);
        let terminal = RunOptions {
            com2: Com2::Terminal,
            ..options
        };
        assert!(run_cut(&tools, &terminal, &cut).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_system_boots_with_at_least_its_cpus() {
        assert_eq!(smp(None, None), None);
        assert_eq!(smp(None, Some(1)), None);
        assert_eq!(smp(None, Some(2)).as_deref(), Some("2"));
        assert_eq!(smp(Some("4"), Some(2)).as_deref(), Some("4"));
        assert_eq!(smp(Some("1"), Some(2)).as_deref(), Some("2"));
        assert_eq!(smp(Some(" 2 "), None).as_deref(), Some("2"));
        assert_eq!(
            smp(Some("4,sockets=2"), Some(2)).as_deref(),
            Some("4,sockets=2")
        );

        let dir = std::env::temp_dir().join(format!("warden-smp-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        assert_eq!(configured_cpus(&dir), None, "no system.img");
        let source = "[system]\nmemory = \"64MiB\"\ncpus = 3\n";
        let blob = config::compile("smp.toml", source, &|_| true).unwrap();
        let entries = [crate::esp::ImageEntry::Bytes {
            name: "config".into(),
            data: blob,
        }];
        let image = crate::esp::build_system_image(&entries).unwrap();
        std::fs::write(dir.join("system.img"), &image).unwrap();
        assert_eq!(configured_cpus(&dir), Some(3));
        std::fs::write(dir.join("system.img"), &image[..image.len() / 2]).unwrap();
        assert_eq!(configured_cpus(&dir), None, "a damaged image");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_nic_forwards_listen_on_the_loopback_address_only() {
        let args = nic(RUN_FORWARDS);
        assert_eq!(args[0], "-netdev");
        let forwards: Vec<&str> = args[1]
            .split(',')
            .filter(|a| a.starts_with("hostfwd="))
            .collect();
        assert_eq!(forwards.len(), RUN_FORWARDS.len());
        assert!(
            forwards
                .iter()
                .all(|f| f.starts_with("hostfwd=tcp:127.0.0.1:"))
        );
        assert!(args[1].contains("hostfwd=tcp:127.0.0.1:10502-10.0.2.16:502"));
        assert_eq!(
            args[3],
            "virtio-net-pci,netdev=net0,addr=03.0,disable-legacy=on,iommu_platform=on"
        );
    }
}
