//! The PLC on the network (`tests/scenarios/net_modbus.toml`): the soft-PLC's own
//! interface on the NIC partition's switch and its Modbus/TCP server, reached from the host
//! through QEMU's `hostfwd`. The client is pymodbus (tests/scripts/modbus_client.py) in the
//! venv `target/pymodbus-venv` (`.ci/run` makes it); without it that part is skipped with
//! a message, and only our own raw frames below are sent.

use scenarios::{boot_beside, check};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// The venv's python with pymodbus, if there is one.
fn pymodbus_python() -> Option<PathBuf> {
    let python = xtask::target_dir()
        .join("pymodbus-venv")
        .join("bin")
        .join("python");
    python.is_file().then_some(python)
}

/// One request ADU to `port` on a new connection: the response's bytes (empty when the
/// PLC closed the connection).
fn exchange(port: u16, adu: &[u8]) -> std::io::Result<Vec<u8>> {
    let mut s = TcpStream::connect(("127.0.0.1", port))?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    s.write_all(adu)?;
    let mut out = vec![0u8; 260];
    let n = s.read(&mut out)?;
    out.truncate(n);
    Ok(out)
}

/// Reads the level (input registers 0..4, `%IL0`) with our own frame.
fn raw_level(port: u16) -> Option<f64> {
    let r = exchange(port, &[0, 1, 0, 0, 0, 6, 1, 4, 0, 0, 0, 4]).ok()?;
    if r.len() != 9 + 8 || r[7] != 4 || r[8] != 8 {
        return None;
    }
    let mut bytes = [0u8; 8];
    for i in 0..4 {
        // Each register big-endian on the wire, the image's words little-endian.
        bytes[2 * i] = r[9 + 2 * i + 1];
        bytes[2 * i + 1] = r[9 + 2 * i];
    }
    Some(f64::from_le_bytes(bytes))
}

#[derive(Debug, Default)]
struct Client {
    level: Option<f64>,
    /// pymodbus's output and whether it passed; `None` when skipped.
    pymodbus: Option<(String, bool)>,
    /// The connection after a malformed frame was closed without an answer.
    malformed_closed: bool,
}

fn client(port: u16, ended: &AtomicBool) -> Client {
    let mut c = Client::default();
    while !ended.load(Ordering::SeqCst) && c.level.is_none() {
        c.level = raw_level(port);
        if c.level.is_none() {
            std::thread::sleep(Duration::from_millis(500));
        }
    }
    if c.level.is_none() {
        return c;
    }
    match pymodbus_python() {
        Some(python) => {
            let script = xtask::workspace_root().join("tests/scripts/modbus_client.py");
            match std::process::Command::new(python)
                .arg(script)
                .arg(port.to_string())
                .output()
            {
                Ok(out) => {
                    let text = String::from_utf8_lossy(&out.stdout).to_string()
                        + &String::from_utf8_lossy(&out.stderr);
                    c.pymodbus = Some((text, out.status.success()));
                }
                Err(e) => c.pymodbus = Some((format!("cannot run pymodbus: {e}"), false)),
            }
        }
        None => println!(
            "net_modbus: pymodbus skipped: no venv at {} (.ci/run makes it: python3 -m venv target/pymodbus-venv && target/pymodbus-venv/bin/pip install 'pymodbus>=3,<4')",
            xtask::target_dir().join("pymodbus-venv").display()
        ),
    }
    // A protocol id other than 0: not Modbus/TCP, the connection closes (and the PLC's
    // counter of such connections, which ends the run, goes to 1).
    c.malformed_closed = exchange(port, &[0, 2, 0, 1, 0, 6, 1, 3, 0, 0, 0, 1])
        .map(|r| r.is_empty())
        .unwrap_or(true);
    c
}

#[test]
fn net_modbus() {
    let (o, c) = boot_beside("net_modbus", |ports, ended| client(ports[0], ended));
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.line("plc: net 10.0.2.15/24 mac 52:54:00:12:34:56 connections=4")
            .is_some()
            && o.line("plc: modbus on port 502 unit 1 writable=markers")
                .is_some(),
        "the PLC did not report its interface and Modbus server",
    );
    check(
        &o,
        c.level.is_some_and(|l| (0.0..2.0).contains(&l)),
        &format!("the level read over Modbus/TCP: {:?}", c.level),
    );
    if let Some((text, passed)) = &c.pymodbus {
        println!("net_modbus: pymodbus said:\n{text}");
        check(&o, *passed, "pymodbus's checks failed (its lines above)");
    }
    check(
        &o,
        c.malformed_closed,
        "a malformed frame was answered, not closed",
    );
    check(
        &o,
        o.line(" malformed=1 ").is_some(),
        "the PLC did not count the malformed connection",
    );
}
