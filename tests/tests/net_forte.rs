//! The soft-PLC's publish/subscribe with 4diac FORTE, the IEC 61499 reference runtime, as
//! its peer (scenario `net_pubsub_forte`): FORTE on the host runs
//! tests/configs/forte/tank_controller.fboot, a proportional controller of FORTE's own
//! function blocks (SUBSCRIBE_3 → F_SUB, F_MUL, F_ADD, F_LIMIT, F_SEL → PUBLISH_2; FORTE's
//! generic blocks need a typed block such as LREAL2LREAL between them), the same law as
//! `tests/configs/plc/pubsub_ctl.st`. The field PLC publishes the level, its validity and
//! its cycle count in the FBDK encoding; FORTE publishes the valve command and the count
//! back. Without FORTE ([`xtask::forte`]) the test passes without booting, with a message.

use scenarios::tank;
use scenarios::{boot_beside, check};
use std::net::UdpSocket;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Where the field PLC publishes (its configuration: 10.0.2.2, the host, port 61500).
const FORTE_SUBSCRIBES: u16 = 61_500;
/// How long FORTE runs: the PLC boots, the loop settles, then FORTE stops.
const FORTE_RUNS: Duration = Duration::from_secs(40);

/// What the host side saw.
#[derive(Debug, Default)]
struct Peer {
    /// FORTE's output (it logs to stdout and stderr), or why it did not run.
    log: String,
    /// It ran [`FORTE_RUNS`] and was stopped.
    stopped: bool,
}

fn start_forte(forte: &Path, dir: &Path, publish_to: u16) -> Result<Child, String> {
    // FORTE's SUBSCRIBE binds the port on every address; a port in use would leave it deaf.
    UdpSocket::bind(("127.0.0.1", FORTE_SUBSCRIBES))
        .map_err(|e| format!("UDP port {FORTE_SUBSCRIBES} of 127.0.0.1 is in use: {e}"))?;
    let template = xtask::workspace_root().join("tests/configs/forte/tank_controller.fboot");
    let boot = std::fs::read_to_string(&template)
        .map_err(|e| format!("{}: {e}", template.display()))?
        .replace("{in_port}", &FORTE_SUBSCRIBES.to_string())
        .replace("{out_port}", &publish_to.to_string());
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let file = dir.join("tank_controller.fboot");
    std::fs::write(&file, boot).map_err(|e| format!("{}: {e}", file.display()))?;
    // Its management port (for the 4diac IDE) on a free TCP port of 127.0.0.1.
    let management = xtask::scenario::free_host_ports(1).map_err(|e| format!("{e:#}"))?[0];
    let log = std::fs::File::create(dir.join("forte.log")).map_err(|e| e.to_string())?;
    let err = log.try_clone().map_err(|e| e.to_string())?;
    Command::new(forte)
        .arg("-c")
        .arg(format!("127.0.0.1:{management}"))
        .arg("-f")
        .arg(&file)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(log)
        .stderr(err)
        .spawn()
        .map_err(|e| format!("cannot run {}: {e}", forte.display()))
}

fn peer(forte: &Path, publish_to: u16, ended: &AtomicBool) -> Peer {
    let dir = xtask::scenario::output_dir()
        .join("net_pubsub_forte")
        .join("forte");
    let mut child = match start_forte(forte, &dir, publish_to) {
        Ok(child) => child,
        Err(e) => {
            return Peer {
                log: e,
                stopped: false,
            };
        }
    };
    let started = Instant::now();
    while !ended.load(Ordering::SeqCst) && started.elapsed() < FORTE_RUNS {
        std::thread::sleep(Duration::from_millis(200));
    }
    let stopped = started.elapsed() >= FORTE_RUNS;
    let _ = child.kill();
    let _ = child.wait();
    Peer {
        log: std::fs::read_to_string(dir.join("forte.log")).unwrap_or_default(),
        stopped,
    }
}

#[test]
fn net_pubsub_forte() {
    let forte = match xtask::forte::binary() {
        Ok(Some(forte)) => forte,
        Ok(None) => {
            println!(
                "net_pubsub_forte: skipped, no 4diac FORTE; {}",
                xtask::forte::HOW_TO_GET
            );
            return;
        }
        Err(e) => panic!("4diac FORTE: {e:#}"),
    };
    let (o, p) = boot_beside("net_pubsub_forte", |ports, ended| {
        peer(&forte, ports[0], ended)
    });
    println!("net_pubsub_forte: FORTE said:\n{}", p.log);
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        p.log.contains("Bootfile correctly loaded"),
        "FORTE did not load the controller's boot file (its log above)",
    );
    check(
        &o,
        !p.log.contains("ERROR") && !p.log.contains("Datatype error"),
        "FORTE reported an error (its log above)",
    );
    check(
        &o,
        o.line("[field] plc: subscription valid").is_some(),
        "the PLC never received a good publication from FORTE",
    );
    // The loop closed through FORTE: the level reaches the band with the valve open.
    let status = tank::status(&o);
    check(
        &o,
        tank::reaches_band(&status),
        "the level never reached the band under FORTE's control",
    );
    let loops = xtask::pubsubbench::loop_round_trips(&o.lines, 0, u64::MAX);
    println!(
        "net_pubsub_forte: loop round trip (real time, PLC → FORTE → PLC, in the PLC's 10 ms cycles): {loops:?} ms"
    );
    check(
        &o,
        loops.iter().any(|&ms| ms > 0),
        "no count came back from FORTE",
    );
    // FORTE stopped: the subscription lapses and the valve closes.
    check(&o, p.stopped, "the run ended before FORTE was stopped");
    check(
        &o,
        o.line("[field] plc: subscription lapsed").is_some(),
        "the PLC's subscription did not lapse when FORTE stopped",
    );
}
