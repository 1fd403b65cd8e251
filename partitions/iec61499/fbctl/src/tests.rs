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

#[test]
fn boot_type_and_send_against_a_device() {
    let mut l = link(Access::Download);
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
    assert_eq!(lines[1], "1: <Response ID=\"1\" />");
    let send = |l: &mut Link<Loopback>, dest: &str, request: &str| {
        let mut out = Vec::new();
        let r = l.run(
            &Action::Send {
                destination: dest.into(),
                request: request.into(),
            },
            b"",
            &mut |s| out.push(s.to_string()),
        );
        (r.map(drop), out.join("\n"))
    };
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
