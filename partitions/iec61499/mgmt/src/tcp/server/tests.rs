//! The server and a client on one wire, the device between them.

use super::*;
use crate::Device;
use crate::tcp::{encode_request, read_response};
use alloc::string::String;
extern crate std;

const SERVER_IP: [u8; 4] = [10, 0, 2, 15];

struct Wire {
    server: Server,
    client: Stack,
    device: Device,
    now_ns: u64,
}

impl Wire {
    fn new(connections: usize, access: Access) -> Self {
        let client = Stack::new(
            Config {
                mac: [0x52, 0x54, 0, 0x12, 0x34, 0x99],
                address: Ipv4Address::new(10, 0, 2, 2),
                prefix: 24,
                gateway: None,
                limits: Limits::default(),
            },
            0,
        );
        let settings = Settings {
            mac: [0x52, 0x54, 0, 0x12, 0x34, 0x56],
            address: SERVER_IP,
            prefix: 24,
            gateway: None,
            port: crate::tcp::PORT,
            connections,
            access,
        };
        Wire {
            server: Server::new(&settings, 0).unwrap(),
            client,
            device: Device::new(iec61499_runtime::Limits::default(), 4),
            now_ns: 0,
        }
    }

    /// One millisecond: frames both ways, the device's timers, the server's run.
    fn step(&mut self) {
        self.now_ns += 1_000_000;
        self.client.poll((self.now_ns / 1000) as i64);
        while let Some(f) = self.client.device.take() {
            self.server.stack.device.deliver(&f);
        }
        self.device.advance(self.now_ns as i64);
        self.server.run(self.now_ns, &mut self.device);
        while let Some(f) = self.server.stack.device.take() {
            self.client.device.deliver(&f);
        }
        self.client.poll((self.now_ns / 1000) as i64);
    }

    fn connect(&mut self) -> SocketId {
        let s = self
            .client
            .socket(linux::AF_INET, linux::SOCK_STREAM | linux::SOCK_NONBLOCK, 0)
            .unwrap();
        let [a, b, c, d] = SERVER_IP;
        let _ = self.client.connect(
            s,
            SocketAddr::new(Ipv4Address::new(a, b, c, d), crate::tcp::PORT),
        );
        for _ in 0..50 {
            self.step();
            if self.client.readiness(s).unwrap().writable {
                break;
            }
        }
        s
    }

    /// Sends `bytes`, then collects what comes back within `steps` milliseconds: the
    /// bytes and whether the connection closed.
    fn exchange(&mut self, s: SocketId, bytes: &[u8], steps: usize) -> (Vec<u8>, bool) {
        if !bytes.is_empty() {
            let mut at = 0;
            while at < bytes.len() {
                at += self.client.send(s, &bytes[at..], None).unwrap_or(0);
                self.step();
            }
        }
        let mut got = Vec::new();
        for _ in 0..steps {
            self.step();
            let mut buf = [0u8; 2048];
            loop {
                match self.client.recv(s, &mut buf) {
                    Ok((0, _)) | Err(Error::ConnectionReset) => return (got, true),
                    Ok((n, _)) => got.extend_from_slice(&buf[..n]),
                    Err(_) => break,
                }
            }
        }
        (got, false)
    }

    /// The responses to `requests` (destination, XML) sent at once, in order.
    fn ask(&mut self, s: SocketId, requests: &[(&str, &str)]) -> Vec<String> {
        let mut bytes = Vec::new();
        for (d, r) in requests {
            bytes.extend_from_slice(&encode_request(d, r));
        }
        let (got, _) = self.exchange(s, &bytes, 20 + 5 * requests.len());
        responses(&got)
    }
}

/// The responses in a client's received bytes.
fn responses(mut bytes: &[u8]) -> Vec<String> {
    let mut out = Vec::new();
    while let Ok(Some((text, len))) = read_response(bytes) {
        out.push(String::from_utf8(text.to_vec()).unwrap());
        bytes = &bytes[len..];
    }
    assert!(bytes.is_empty(), "a partial response is left: {bytes:?}");
    out
}

const DEPLOY: [(&str, &str); 7] = [
    (
        "",
        "<Request ID=\"1\" Action=\"CREATE\"><FB Name=\"R\" Type=\"EMB_RES\"/></Request>",
    ),
    (
        "R",
        "<Request ID=\"2\" Action=\"CREATE\"><FB Name=\"CYCLE\" Type=\"E_CYCLE\"/></Request>",
    ),
    (
        "R",
        "<Request ID=\"3\" Action=\"CREATE\"><FB Name=\"C\" Type=\"E_CTU\"/></Request>",
    ),
    (
        "R",
        "<Request ID=\"4\" Action=\"WRITE\"><Connection Source=\"T#10ms\" Destination=\"CYCLE.DT\"/></Request>",
    ),
    (
        "R",
        "<Request ID=\"5\" Action=\"CREATE\"><Connection Source=\"CYCLE.EO\" Destination=\"C.CU\"/></Request>",
    ),
    (
        "R",
        "<Request ID=\"6\" Action=\"CREATE\"><Connection Source=\"START.COLD\" Destination=\"CYCLE.START\"/></Request>",
    ),
    ("R", "<Request ID=\"7\" Action=\"START\"/>"),
];

const READ_CV: (&str, &str) = (
    "R",
    "<Request ID=\"8\" Action=\"READ\"><Connection Source=\"C.CV\" Destination=\"\"/></Request>",
);

/// The value in a READ's response.
fn value(response: &str) -> u64 {
    response
        .split("Destination=\"")
        .nth(1)
        .and_then(|r| r.split('"').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no value in {response}"))
}

#[test]
fn a_client_deploys_and_reads_over_tcp() {
    let mut w = Wire::new(2, Access::Download);
    let s = w.connect();
    let answers = w.ask(s, &DEPLOY);
    assert_eq!(answers.len(), DEPLOY.len(), "{answers:?}");
    for (i, a) in answers.iter().enumerate() {
        assert_eq!(a, &std::format!("<Response ID=\"{}\" />", i + 1));
    }
    // The E_CYCLE counts while the connection idles.
    let first = value(&w.ask(s, &[READ_CV])[0]);
    let (_, closed) = w.exchange(s, &[], 100);
    assert!(!closed);
    let later = value(&w.ask(s, &[READ_CV])[0]);
    assert!(later >= first + 9, "{first} -> {later}");
    assert_eq!(w.server.stats.requests, 9);
    assert!(matches!(
        w.server.take_events().next(),
        Some(Event::Accepted(_))
    ));
}

#[test]
fn a_request_cut_into_segments_is_answered_once_whole() {
    let mut w = Wire::new(1, Access::Download);
    let s = w.connect();
    let bytes = encode_request(DEPLOY[0].0, DEPLOY[0].1);
    // Three segments, milliseconds apart: nothing is answered before the last byte.
    for part in [&bytes[..2], &bytes[2..20]] {
        let (got, closed) = w.exchange(s, part, 5);
        assert!(got.is_empty() && !closed);
    }
    let (got, _) = w.exchange(s, &bytes[20..], 10);
    assert_eq!(responses(&got), ["<Response ID=\"1\" />"]);
}

#[test]
fn a_malformed_request_is_refused_and_the_connection_goes_on() {
    let mut w = Wire::new(1, Access::Download);
    let s = w.connect();
    let answers = w.ask(
        s,
        &[
            ("", "<Request ID=\"1\" Action=\"CREATE\"><FB Name="),
            ("", "<Request ID=\"2\" Action=\"FLY\"/>"),
            DEPLOY[0],
        ],
    );
    assert_eq!(
        answers,
        [
            "<Response ID=\"\" Reason=\"BAD_PARAMS\" />",
            "<Response ID=\"2\" Reason=\"UNSUPPORTED_CMD\" />",
            "<Response ID=\"1\" />",
        ]
    );
    // A destination that is not UTF-8.
    let mut bad = Vec::new();
    crate::tcp::push_string(&mut bad, &[0xff]);
    crate::tcp::push_string(&mut bad, DEPLOY[0].1.as_bytes());
    let (got, closed) = w.exchange(s, &bad, 10);
    assert_eq!(
        responses(&got),
        ["<Response ID=\"\" Reason=\"BAD_PARAMS\" />"]
    );
    assert!(!closed);
}

#[test]
fn a_stream_that_is_not_requests_gets_a_refusal_and_is_closed() {
    let mut w = Wire::new(1, Access::Download);
    for (bytes, reason) in [
        (&b"GET / HTTP/1.0\r\n\r\n"[..], "BAD_PARAMS"),
        (&[0x50, 0, 0, 0x50, 0x7f, 0xff][..], "OVERFLOW"),
    ] {
        let s = w.connect();
        let (got, closed) = w.exchange(s, bytes, 20);
        assert_eq!(
            responses(&got),
            [std::format!("<Response ID=\"\" Reason=\"{reason}\" />")]
        );
        assert!(closed);
        let _ = w.client.close(s);
    }
    assert_eq!(w.server.stats.malformed, 2);
    assert_eq!(w.server.open(), 0);
    let events: Vec<_> = w.server.take_events().collect();
    assert!(matches!(
        events[..],
        [
            Event::Accepted(_),
            Event::Malformed(_, FrameError::Tag { at: 0, found: b'G' }),
            Event::Accepted(_),
            Event::Malformed(_, FrameError::TooLong { len: 32_773 }),
        ]
    ));
    // The device still answers.
    let s = w.connect();
    assert_eq!(w.ask(s, &[DEPLOY[0]]), ["<Response ID=\"1\" />"]);
}

#[test]
fn the_access_level_holds_for_every_client() {
    let mut w = Wire::new(1, Access::Monitor);
    let s = w.connect();
    let answers = w.ask(s, &[DEPLOY[0]]);
    assert_eq!(answers, ["<Response ID=\"1\" Reason=\"ACCESS_DENIED\" />"]);
    let query = (
        "",
        "<Request ID=\"2\" Action=\"QUERY\"><FB Name=\"*\" Type=\"*\"/></Request>",
    );
    let answer = &w.ask(s, &[query])[0];
    assert!(!answer.contains("ACCESS_DENIED"), "{answer}");
}

#[test]
fn a_stalled_request_blocks_nothing_and_times_out() {
    let mut w = Wire::new(2, Access::Download);
    let a = w.connect();
    let half = encode_request(DEPLOY[0].0, DEPLOY[0].1);
    let (got, _) = w.exchange(a, &half[..half.len() / 2], 5);
    assert!(got.is_empty());
    // Another client deploys and the resource runs meanwhile.
    let b = w.connect();
    assert_eq!(w.ask(b, &DEPLOY).len(), DEPLOY.len());
    let first = value(&w.ask(b, &[READ_CV])[0]);
    let _ = w.exchange(b, &[], 50);
    assert!(value(&w.ask(b, &[READ_CV])[0]) > first);
    // Without progress the stalled one is closed.
    w.now_ns += REQUEST_TIMEOUT_NS;
    let (got, closed) = w.exchange(a, &[], 10);
    assert!(got.is_empty() && closed);
    assert_eq!((w.server.stats.timed_out, w.server.open()), (1, 1));
    assert!(w.server.take_events().any(|e| matches!(
        e,
        Event::TimedOut { received, unsent: 0, .. } if received == half.len() / 2
    )));
}

#[test]
fn a_client_that_takes_no_response_is_closed() {
    // The client's receive buffer holds 512 bytes and it never reads.
    let mut w = Wire::new(1, Access::Download);
    w.client = Stack::new(
        Config {
            limits: netstack::Limits {
                tcp_buffer: 512,
                ..netstack::Limits::default()
            },
            ..*w.client.config()
        },
        0,
    );
    let s = w.connect();
    let name = "N".repeat(100);
    let mut bytes = encode_request(DEPLOY[0].0, DEPLOY[0].1);
    for i in 0..50 {
        let create = std::format!(
            "<Request ID=\"{i}\" Action=\"CREATE\"><FB Name=\"{name}{i}\" Type=\"E_SR\"/></Request>"
        );
        bytes.extend_from_slice(&encode_request("R", &create));
    }
    let query = "<Request ID=\"q\" Action=\"QUERY\"><FB Name=\"*\" Type=\"*\"/></Request>";
    bytes.extend_from_slice(&encode_request("R", query));
    for chunk in bytes.chunks(256) {
        let mut at = 0;
        while at < chunk.len() {
            at += w.client.send(s, &chunk[at..], None).unwrap_or(0);
            w.step();
        }
    }
    for _ in 0..200 {
        w.step();
    }
    assert_eq!((w.server.open(), w.server.stats.timed_out), (1, 0));
    w.now_ns += REQUEST_TIMEOUT_NS;
    for _ in 0..5 {
        w.step();
    }
    assert_eq!((w.server.open(), w.server.stats.timed_out), (0, 1));
    assert!(w.server.take_events().any(|e| matches!(
        e,
        Event::TimedOut { received: 0, unsent, .. } if unsent > 0
    )));
}

#[test]
fn connections_beyond_the_limit_are_closed_at_once() {
    let mut w = Wire::new(2, Access::Download);
    let a = w.connect();
    let b = w.connect();
    let c = w.connect();
    for _ in 0..10 {
        w.step();
    }
    assert_eq!(w.server.open(), 2);
    assert!(w.server.stats.refused >= 1);
    let mut buf = [0u8; 8];
    assert!(matches!(
        w.client.recv(c, &mut buf),
        Ok((0, _)) | Err(Error::ConnectionReset)
    ));
    assert_eq!(w.ask(a, &[DEPLOY[0]]), ["<Response ID=\"1\" />"]);
    assert_eq!(
        w.ask(b, &[DEPLOY[0]]),
        ["<Response ID=\"1\" Reason=\"INVALID_STATE\" />"]
    );
}

#[test]
fn a_long_response_is_refused_with_overflow() {
    let mut w = Wire::new(1, Access::Download);
    let s = w.connect();
    assert_eq!(w.ask(s, &DEPLOY[..1]).len(), 1);
    // A QUERY of many FBs: each name long, more than MAX_RESPONSE in all.
    let name = "N".repeat(200);
    let mut creates = Vec::new();
    for i in 0..100 {
        creates.push(std::format!(
            "<Request ID=\"{i}\" Action=\"CREATE\"><FB Name=\"{name}{i}\" Type=\"E_SR\"/></Request>"
        ));
    }
    for c in &creates {
        let answers = w.ask(s, &[("R", c)]);
        assert!(!answers[0].contains("Reason"), "{answers:?}");
    }
    let query = (
        "R",
        "<Request ID=\"q\" Action=\"QUERY\"><FB Name=\"*\" Type=\"*\"/></Request>",
    );
    assert_eq!(
        w.ask(s, &[query]),
        ["<Response ID=\"q\" Reason=\"OVERFLOW\" />"]
    );
}
