//! A network storm beside the PLC (scenario `net_storm`, the default system
//! `config/systems/plc-guest.toml` on virtual time): the host floods the NIC with 64-byte
//! UDP datagrams and TCP connection attempts to the guest's httpd while the PLC controls
//! the plant in its window and the NIC partition works in its own.

use scenarios::tank;
use scenarios::{boot_while, check, http_get};
use std::net::{TcpStream, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use xtask::qemu::Ending;

/// The storm's bounds: how long (real time) and how many of each.
const STORM: Duration = Duration::from_secs(20);
const DATAGRAMS: u64 = 2_000_000;
const CONNECTIONS: u64 = 5_000;
/// How much later than in the quiet seconds a release may be in the storm's.
const STORM_BOUND_NS: u64 = 50_000;
/// Frames a second from the wire that make a second stormy, or at most quiet.
const STORMY: u64 = 500;
const QUIET: u64 = 20;

/// What the host sent.
#[derive(Debug, Default)]
struct Storm {
    reached: bool,
    datagrams: u64,
    connections: u64,
    connected: u64,
}

/// Quiet real time before the storm and after it (the run ends then).
const QUIET_SPELL: Duration = Duration::from_secs(5);

/// Waits until the guest's httpd answers, lets the system run quietly for [`QUIET_SPELL`],
/// then storms for [`STORM`] (one thread sending datagrams to the forwarded UDP port, one
/// opening and dropping connections to the forwarded TCP port) and lets it run quietly
/// again for [`QUIET_SPELL`].
fn storm(udp: u16, tcp: u16, ended: &AtomicBool) -> Storm {
    let mut s = Storm::default();
    while !ended.load(Ordering::SeqCst) && !s.reached {
        s.reached = http_get(tcp, "/").is_some();
        if !s.reached {
            std::thread::sleep(Duration::from_millis(500));
        }
    }
    if !s.reached {
        return s;
    }
    std::thread::sleep(QUIET_SPELL);
    let start = Instant::now();
    let until = start + STORM;
    let going = || Instant::now() < until && !ended.load(Ordering::SeqCst);
    std::thread::scope(|scope| {
        // The flood is paced over the whole storm: sent as fast as the host can, the
        // datagrams may all be gone in the storm's first seconds, before the system has
        // run enough of them (on virtual time) to measure a stormy second.
        let flood = scope.spawn(|| {
            let socket = UdpSocket::bind(("127.0.0.1", 0)).expect("a UDP socket");
            let payload = [0x5au8; 64];
            let mut sent = 0;
            while sent < DATAGRAMS && going() {
                let due = DATAGRAMS * start.elapsed().as_millis() as u64 / STORM.as_millis() as u64;
                if sent >= due {
                    std::thread::sleep(Duration::from_millis(1));
                    continue;
                }
                for _ in 0..64 {
                    let _ = socket.send_to(&payload, ("127.0.0.1", udp));
                    sent += 1;
                }
            }
            sent
        });
        let (mut tried, mut connected) = (0, 0);
        while tried < CONNECTIONS && going() {
            tried += 1;
            if TcpStream::connect_timeout(&([127, 0, 0, 1], tcp).into(), Duration::from_secs(1))
                .is_ok()
            {
                connected += 1;
            }
        }
        s.connections = tried;
        s.connected = connected;
        s.datagrams = flood.join().unwrap_or(0);
    });
    if !ended.load(Ordering::SeqCst) {
        std::thread::sleep(QUIET_SPELL);
    }
    s
}

#[test]
fn net_storm() {
    let (o, s) = boot_while("net_storm", |ports, ended| storm(ports[0], ports[1], ended));
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        matches!(o.ending, Ending::Stopped),
        "expected the system to run until the host's storm and quiet spells were over",
    );
    check(&o, s.reached, "the guest's httpd never answered the host");
    let split = scenarios::plc_lateness_by_load(&o, STORMY, QUIET);
    let (quiet, stormy, peak) = (split.quiet, split.loud, split.peak);
    let (quiet_max, storm_max) = (
        quiet.iter().copied().max().unwrap_or(0),
        stormy.iter().copied().max().unwrap_or(0),
    );
    println!(
        "net_storm: the host sent {} datagrams and tried {} connections ({} connected) in {STORM:?}; the NIC took up to {peak} frames a second from the wire; PLC release lateness (virtual time): max {quiet_max} ns over {} quiet seconds, max {storm_max} ns over {} stormy seconds",
        s.datagrams,
        s.connections,
        s.connected,
        quiet.len(),
        stormy.len()
    );
    check(
        &o,
        stormy.len() >= 3 && quiet.len() >= 3,
        &format!(
            "{} stormy and {} quiet seconds of PLC period lines",
            stormy.len(),
            quiet.len()
        ),
    );
    check(
        &o,
        storm_max <= quiet_max + STORM_BOUND_NS,
        "a release in the storm later than 50 us beyond the quiet seconds' latest",
    );
    scenarios::plc_kept_every_cycle(&o);
    tank::settles_and_holds(&o);
}
