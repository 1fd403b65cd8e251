//! `fbctl` against a real device in the same process: the transport hands each request to
//! `iec61499_mgmt::serve` and queues its response.

use super::*;
use iec61499_mgmt::Device;
use iec61499_mgmt::serve::{Access, serve};
use iec61499_runtime::Limits;
use std::collections::VecDeque;

struct Loopback {
    device: Device,
    access: Access,
    responses: VecDeque<Vec<u8>>,
}

impl Transport for Loopback {
    fn send(&mut self, message: &[u8]) -> Result<(), String> {
        let answer = serve(&mut self.device, message, self.access, MAX_MESSAGE, 0);
        self.responses.push_back(answer.into_bytes());
        Ok(())
    }
    fn try_receive(&mut self, buf: &mut [u8]) -> Result<Option<usize>, String> {
        Ok(self.responses.pop_front().map(|r| {
            buf[..r.len()].copy_from_slice(&r);
            r.len()
        }))
    }
    fn pause(&mut self, _: Duration) {}
}

fn link(access: Access) -> Link<Loopback> {
    Link {
        transport: Loopback {
            device: Device::new(Limits::default(), 4),
            access,
            responses: VecDeque::new(),
        },
        timeout: Duration::from_millis(50),
        adapters: Vec::new(),
    }
}

fn args(text: &str) -> Vec<String> {
    text.split(' ').map(str::to_string).collect()
}

const COUNTDOWN: &str = include_str!("../../../../tests/configs/iec61499/COUNTDOWN.fbt");

#[test]
fn commands_parse() {
    let c = Command::parse(&args("--timeout 500 boot app.fboot")).unwrap();
    assert_eq!(
        (c.timeout, c.action),
        (Duration::from_millis(500), Action::Boot("app.fboot".into()))
    );
    assert_eq!(c.request, DEFAULT_REQUEST);
    let c = Command::parse(&args("--request /dev/arinc/q send R x")).unwrap();
    assert_eq!(c.request, "/dev/arinc/q");
    assert!(Command::parse(&args("frob")).is_err());
    assert!(Command::parse(&[]).is_err());
    assert!(Command::parse(&args("--timeout soon boot x")).is_err());
}

/// Deploys type COUNTDOWN and a boot file creating resource R with a COUNTDOWN `D`, as the
/// 4diac IDE does, checking what each step prints.
fn deploy<T: Transport>(l: &mut Link<T>) {
    let mut lines = Vec::new();
    l.run(
        &Action::Type("COUNTDOWN.fbt".into()),
        COUNTDOWN.as_bytes(),
        &mut |s| lines.push(s.to_string()),
    )
    .unwrap();
    assert!(
        lines[0].starts_with("type COUNTDOWN: ") && lines[0].ends_with(" part(s), added"),
        "{lines:?}"
    );
    let boot = ";<Request ID=\"1\" Action=\"CREATE\"><FB Name=\"R\" Type=\"EMB_RES\"/></Request>\nR;<Request ID=\"2\" Action=\"CREATE\"><FB Name=\"D\" Type=\"COUNTDOWN\"/></Request>\nR;<Request ID=\"3\" Action=\"START\"/>\n";
    l.run(
        &Action::Boot("app.fboot".into()),
        boot.as_bytes(),
        &mut |s| lines.push(s.to_string()),
    )
    .unwrap();
    assert_eq!(
        lines[1..],
        [
            "1: <Response ID=\"1\" />",
            "2: <Response ID=\"2\" />",
            "3: <Response ID=\"3\" />"
        ]
    );
}

/// Sends `request` to `destination`: how the run ended and what it printed.
fn send<T: Transport>(
    l: &mut Link<T>,
    destination: &str,
    request: &str,
) -> (Result<(), Failure>, String) {
    let mut out = Vec::new();
    let r = l.run(
        &Action::Send {
            destination: destination.into(),
            request: request.into(),
        },
        b"",
        &mut |s| out.push(s.to_string()),
    );
    (r.map(drop), out.join("\n"))
}

#[test]
fn boot_type_and_send_against_a_device() {
    let mut l = link(Access::Download);
    deploy(&mut l);
    let (r, _) = send(
        &mut l,
        "R",
        "<Request ID=\"4\" Action=\"WRITE\"><Connection Source=\"$e\" Destination=\"D.REQ\"/></Request>",
    );
    assert_eq!(r, Ok(()));
    let (_, out) = send(
        &mut l,
        "R",
        "<Request ID=\"5\" Action=\"READ\"><Connection Source=\"D.Q\" Destination=\"\"/></Request>",
    );
    assert!(out.contains("100"), "{out}");
    let (r, out) = send(
        &mut l,
        "R",
        "<Request ID=\"6\" Action=\"CREATE\"><FB Name=\"D\" Type=\"E_CTU\"/></Request>",
    );
    assert_eq!(r.unwrap_err().status, 1);
    assert!(out.contains("INVALID_STATE"), "{out}");
    // A boot file stops at its first refused line, naming it.
    let e = l
        .run(
            &Action::Boot("x.fboot".into()),
            b"R;<Request ID=\"7\" Action=\"FROB\"/>\n",
            &mut |_| {},
        )
        .unwrap_err();
    assert_eq!(
        e,
        Failure::refused("x.fboot:1: refused: UNSUPPORTED_CMD".into())
    );
    // A compiled package is sent as it is; a damaged one is refused by the device, which
    // keeps the type it has.
    let package = l
        .run(
            &Action::Compile {
                fbt: "COUNTDOWN.fbt".into(),
                out: "p".into(),
            },
            COUNTDOWN.as_bytes(),
            &mut |_| {},
        )
        .unwrap()
        .unwrap();
    assert_eq!(package_name(&package).as_deref(), Some("COUNTDOWN"));
    let mut damaged = package.clone();
    let at = damaged.len() - 10;
    damaged[at] ^= 1;
    let e = l
        .run(&Action::Type("p".into()), &damaged, &mut |_| {})
        .unwrap_err();
    assert_eq!(e.status, 1, "{e:?}");
    let log = l.transport.device.take_log();
    assert!(
        log.iter()
            .any(|line| line.starts_with("type COUNTDOWN refused: ")),
        "{log:?}"
    );
    l.run(&Action::Type("p".into()), &package, &mut |_| {})
        .unwrap();
    assert!(
        l.run(&Action::Type("p".into()), b"junk", &mut |_| {})
            .is_err()
    );
    // A type that does not compile never leaves the client.
    let e = l
        .run(
            &Action::Type("C.fbt".into()),
            COUNTDOWN.replace("300 / LEFT", "300 / ").as_bytes(),
            &mut |_| {},
        )
        .unwrap_err();
    assert!(e.status == 2 && e.message.starts_with("C.fbt:"), "{e:?}");
}

#[test]
fn a_monitor_client_cannot_deploy_and_a_silent_device_times_out() {
    let mut l = link(Access::Monitor);
    let e = l
        .run(
            &Action::Type("COUNTDOWN.fbt".into()),
            COUNTDOWN.as_bytes(),
            &mut |_| {},
        )
        .unwrap_err();
    assert!(e.message.contains("ACCESS_DENIED"), "{e:?}");
    struct Silent;
    impl Transport for Silent {
        fn send(&mut self, _: &[u8]) -> Result<(), String> {
            Ok(())
        }
        fn try_receive(&mut self, _: &mut [u8]) -> Result<Option<usize>, String> {
            Ok(None)
        }
        fn pause(&mut self, time: Duration) {
            std::thread::sleep(time);
        }
    }
    let mut l = Link {
        transport: Silent,
        timeout: Duration::from_millis(10),
        adapters: Vec::new(),
    };
    assert_eq!(
        l.ask("", "<Request ID=\"1\" Action=\"QUERY\"/>")
            .unwrap_err()
            .status,
        3
    );
}

#[test]
fn a_composite_type_package_names_its_type() {
    let t = iec61499_runtime::composite::CompositeType {
        name: "TICKER".into(),
        file: "TICKER.fbt".into(),
        ..Default::default()
    };
    assert_eq!(package_name(&t.encode()).as_deref(), Some("TICKER"));
    assert_eq!(package_name(b"W61N\x01"), None);
    assert_eq!(package_name(b"XXXX"), None);
}

/// A device served on a TCP port of 127.0.0.1 as the partition serves its port 61499
/// (`iec61499_mgmt::tcp`'s framing, `serve_parts`), to one connection, until it closes;
/// the thread returns how many requests it answered.
fn tcp_device() -> (String, std::thread::JoinHandle<usize>) {
    use iec61499_mgmt::serve::serve_parts;
    use iec61499_mgmt::tcp::{MAX_REQUEST, MAX_RESPONSE, Next, next_request, push_string};
    use std::io::{Read, Write};
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let address = listener.local_addr().unwrap().to_string();
    let server = std::thread::spawn(move || {
        let mut device = Device::new(Limits::default(), 4);
        let mut answered = 0;
        let (mut stream, _) = listener.accept().unwrap();
        let mut received = Vec::new();
        let mut chunk = [0u8; 4096];
        loop {
            while let Ok(Next::Request {
                destination,
                request,
                len,
            }) = next_request(&received, MAX_REQUEST)
            {
                let answer = serve_parts(
                    &mut device,
                    &received[destination],
                    &received[request],
                    Access::Download,
                    MAX_RESPONSE,
                    0,
                );
                let mut frame = Vec::new();
                push_string(&mut frame, answer.as_bytes());
                stream.write_all(&frame).unwrap();
                received.drain(..len);
                answered += 1;
            }
            match stream.read(&mut chunk) {
                Ok(0) | Err(_) => return answered,
                Ok(n) => received.extend_from_slice(&chunk[..n]),
            }
        }
    });
    (address, server)
}

#[test]
fn over_tcp_fbctl_deploys_types_and_reads_as_4diac_ide_does() {
    let (address, server) = tcp_device();
    let c = Command::parse(&args(&format!("--tcp {address} send R x"))).unwrap();
    assert_eq!(c.tcp.as_deref(), Some(address.as_str()));
    let timeout = Duration::from_secs(5);
    let mut l = Link {
        transport: TcpTransport::connect(&address, timeout).unwrap(),
        timeout,
        adapters: Vec::new(),
    };
    deploy(&mut l);
    let (r, out) = send(
        &mut l,
        "R",
        "<Request ID=\"4\" Action=\"READ\"><Connection Source=\"D.Q\" Destination=\"\"/></Request>",
    );
    assert_eq!(r, Ok(()));
    assert!(out.contains("Response ID=\"4\""), "{out}");
    drop(l);
    // The type's parts, the boot file's 3 lines and the read.
    assert!(server.join().unwrap() >= 5);
}

#[test]
fn over_tcp_a_refused_connection_and_a_stream_of_other_bytes_are_errors() {
    // Nobody listens on a port just closed.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let e = TcpTransport::connect(&format!("127.0.0.1:{port}"), Duration::from_secs(1));
    assert!(e.is_err_and(|e| e.starts_with("cannot connect to 127.0.0.1:")));
    // A peer that answers with something else than STRINGs.
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let address = listener.local_addr().unwrap().to_string();
    let peer = std::thread::spawn(move || {
        use std::io::Write;
        let (mut s, _) = listener.accept().unwrap();
        s.write_all(b"HTTP/1.0 400 Bad Request\r\n\r\n").unwrap();
        std::thread::sleep(Duration::from_millis(300));
    });
    let mut l = Link {
        transport: TcpTransport::connect(&address, Duration::from_secs(1)).unwrap(),
        timeout: Duration::from_secs(2),
        adapters: Vec::new(),
    };
    let e = l.ask(
        "",
        "<Request ID=\"1\" Action=\"QUERY\"><FB Name=\"*\" Type=\"*\"/></Request>",
    );
    let e = e.unwrap_err();
    assert_eq!(e.status, 3);
    assert!(
        e.message
            .starts_with("not a response of the management protocol"),
        "{e:?}"
    );
    peer.join().unwrap();
    // --tcp with the ports' flags is a usage error.
    assert!(Command::parse(&args("--tcp 10.0.2.15:61499 --request /dev/x send R x")).is_err());
}
