//! Two stacks joined by a wire on virtual time (the guest at 10.0.2.15, a peer at 10.0.2.2),
//! and one stack's loopback: Linux's socket semantics, retransmission over a lossy wire,
//! and hostile frames.

extern crate std;

use super::stack::linux::*;
use super::*;
use proptest::prelude::*;
use std::vec;
use std::vec::Vec;

const GUEST: Ipv4Address = Ipv4Address::new(10, 0, 2, 15);
const PEER: Ipv4Address = Ipv4Address::new(10, 0, 2, 2);
const LOCAL: Ipv4Address = Ipv4Address::new(127, 0, 0, 1);

fn stack(mac: u8, ip: Ipv4Address) -> Stack {
    Stack::new(
        Config {
            mac: [0x02, 0, 0, 0, 0, mac],
            address: ip,
            prefix: 24,
            gateway: Some(PEER),
            limits: Limits {
                backlog: 4,
                ..Limits::default()
            },
        },
        0,
    )
}

/// Two stacks and the wire between them; `drop_nth` loses that frame (1-based) once.
struct Net {
    a: Stack,
    b: Stack,
    now: i64,
    frames: usize,
    drop_nth: Option<usize>,
}

impl Net {
    fn new() -> Self {
        Net {
            a: stack(1, GUEST),
            b: stack(2, PEER),
            now: 0,
            frames: 0,
            drop_nth: None,
        }
    }

    /// Lets time pass in 1 ms steps, moving frames both ways.
    fn run(&mut self, ms: i64) {
        for _ in 0..ms {
            self.now += 1_000;
            for _ in 0..32 {
                self.a.poll(self.now);
                self.b.poll(self.now);
                let mut moved = false;
                while let Some(f) = self.a.device.take() {
                    self.frames += 1;
                    moved = true;
                    if self.drop_nth != Some(self.frames) {
                        self.b.device.deliver(&f);
                    }
                }
                while let Some(f) = self.b.device.take() {
                    self.frames += 1;
                    moved = true;
                    if self.drop_nth != Some(self.frames) {
                        self.a.device.deliver(&f);
                    }
                }
                if !moved {
                    break;
                }
            }
        }
    }
}

fn tcp(s: &mut Stack) -> SocketId {
    s.socket(AF_INET, SOCK_STREAM, 0).unwrap()
}

fn listener(s: &mut Stack, port: u16, backlog: i32) -> SocketId {
    let l = tcp(s);
    s.set_option(l, SOL_SOCKET, SO_REUSEADDR, 1).unwrap();
    s.bind(l, SocketAddr::new(Ipv4Address::UNSPECIFIED, port))
        .unwrap();
    s.listen(l, backlog).unwrap();
    l
}

/// Reads until `n` bytes arrived or end of file.
fn read_all(net: &mut Net, on_b: bool, id: SocketId, n: usize) -> Vec<u8> {
    let mut out = Vec::new();
    let mut buf = vec![0u8; 4096];
    for _ in 0..10_000 {
        let s = if on_b { &mut net.b } else { &mut net.a };
        match s.recv(id, &mut buf) {
            Ok((0, _)) => break,
            Ok((k, _)) => out.extend_from_slice(&buf[..k]),
            Err(Error::WouldBlock) => net.run(1),
            Err(e) => panic!("{e:?}"),
        }
        if out.len() >= n {
            break;
        }
    }
    out
}

#[test]
fn tcp_connect_accept_transfer_close() {
    let mut net = Net::new();
    let l = listener(&mut net.b, 80, 4);
    let c = tcp(&mut net.a);
    assert_eq!(net.a.accept(c).err(), Some(Error::Invalid));
    assert_eq!(
        net.a.connect(c, SocketAddr::new(PEER, 80)),
        Err(Error::WouldBlock)
    );
    assert_eq!(
        net.a.connect(c, SocketAddr::new(PEER, 80)),
        Err(Error::Already)
    );
    net.run(5);
    assert_eq!(net.a.connect_result(c), Ok(()));
    assert_eq!(
        net.a.connect(c, SocketAddr::new(PEER, 80)),
        Err(Error::IsConnected)
    );
    assert!(net.b.readiness(l).unwrap().readable);
    let (s, peer) = net.b.accept(l).unwrap();
    assert_eq!(peer.ip, GUEST);
    assert_eq!(net.a.local_addr(c).unwrap().ip, GUEST);
    assert_eq!(net.a.peer_addr(c).unwrap(), SocketAddr::new(PEER, 80));
    // 200 KiB each way, more than a buffer holds.
    let data: Vec<u8> = (0..200 * 1024).map(|i| (i * 7 % 251) as u8).collect();
    let mut sent = 0;
    let mut got = Vec::new();
    let mut buf = vec![0u8; 8192];
    while got.len() < data.len() {
        if sent < data.len() {
            match net.a.send(c, &data[sent..], None) {
                Ok(n) => sent += n,
                Err(Error::WouldBlock) => {}
                Err(e) => panic!("{e:?}"),
            }
        }
        net.run(1);
        while let Ok((n, _)) = net.b.recv(s, &mut buf) {
            if n == 0 {
                break;
            }
            got.extend_from_slice(&buf[..n]);
        }
    }
    assert_eq!(got, data);
    // Half-close: the peer reads end of file and can still answer.
    net.a.shutdown(c, SHUT_WR).unwrap();
    assert_eq!(net.a.send(c, b"x", None), Err(Error::BrokenPipe));
    net.run(5);
    assert_eq!(net.b.recv(s, &mut buf), Ok((0, None)));
    assert_eq!(net.b.send(s, b"bye", None), Ok(3));
    net.run(5);
    assert_eq!(read_all(&mut net, false, c, 3), b"bye");
    net.b.close(s).unwrap();
    net.run(5);
    assert_eq!(net.a.recv(c, &mut buf), Ok((0, None)));
    net.a.close(c).unwrap();
    net.run(300);
    assert_eq!(net.a.send(c, b"x", None), Err(Error::BadDescriptor));
}

/// `poll` says when a socket may have changed (frames came or went), and a poll with
/// nothing to do says it did nothing: the guest serves the calls waiting for sockets
/// again only after the former.
#[test]
fn a_poll_says_whether_a_socket_may_have_changed() {
    let mut net = Net::new();
    let l = listener(&mut net.b, 80, 4);
    let c = tcp(&mut net.a);
    net.now += 1_000;
    assert!(!net.b.poll(net.now), "a listener alone");
    assert_eq!(
        net.a.connect(c, SocketAddr::new(PEER, 80)),
        Err(Error::WouldBlock)
    );
    // The SYN went out in connect's own poll; it reaches the listener.
    let syn = net.a.device.take().expect("the SYN");
    net.b.device.deliver(&syn);
    assert!(net.b.poll(net.now), "a SYN came, a SYN-ACK went");
    assert!(!net.b.poll(net.now), "nothing new");
    net.run(5);
    let (s, _) = net.b.accept(l).unwrap();
    assert_eq!(net.a.send(c, b"ping", None), Ok(4));
    assert!(net.a.poll(net.now), "data went");
    let segment = net.a.device.take().expect("the data");
    net.b.device.deliver(&segment);
    assert!(net.b.poll(net.now), "data came");
    assert!(net.b.readiness(s).unwrap().readable);
    net.run(5);
    assert!(!net.a.poll(net.now) && !net.b.poll(net.now));
}

#[test]
fn a_poll_names_the_sockets_it_changed() {
    let mut net = Net::new();
    let l = listener(&mut net.b, 80, 4);
    let idle = listener(&mut net.b, 81, 4);
    let u = net.b.socket(AF_INET, SOCK_DGRAM, 0).unwrap();
    net.b
        .bind(u, SocketAddr::new(Ipv4Address::UNSPECIFIED, 5353))
        .unwrap();
    let c = tcp(&mut net.a);
    assert_eq!(
        net.a.connect(c, SocketAddr::new(PEER, 80)),
        Err(Error::WouldBlock)
    );
    net.run(5);
    assert_eq!(
        net.b.take_changed(),
        vec![l],
        "a connection came to the listener"
    );
    assert_eq!(net.b.take_changed(), vec![], "taken");
    let (s, _) = net.b.accept(l).unwrap();
    assert_eq!(net.a.send(c, b"ping", None), Ok(4));
    net.run(5);
    assert_eq!(
        net.b.take_changed(),
        vec![s],
        "data came to the accepted socket only"
    );
    let datagram = net.a.socket(AF_INET, SOCK_DGRAM, 0).unwrap();
    assert_eq!(
        net.a.send(datagram, b"", Some(SocketAddr::new(PEER, 5353))),
        Ok(0)
    );
    net.run(5);
    assert_eq!(
        net.b.take_changed(),
        vec![u],
        "an empty datagram is news too"
    );
    net.run(5);
    assert_eq!(net.b.take_changed(), vec![], "nothing new");
    assert_eq!(net.b.accept(idle).err(), Some(Error::WouldBlock));
    // A connect nobody answers fails when its time is up: a change too.
    let lost = tcp(&mut net.a);
    assert_eq!(
        net.a.connect(lost, SocketAddr::new(PEER, 80)),
        Err(Error::WouldBlock)
    );
    let _ = net.a.take_changed();
    net.a.poll(net.now + 74_000_000);
    assert_eq!(net.a.take_changed(), vec![]);
    assert!(net.a.poll(net.now + 76_000_000));
    assert_eq!(net.a.take_changed(), vec![lost]);
    assert_eq!(net.a.connect_result(lost), Err(Error::TimedOut));
}

#[test]
fn refused_and_nonblocking_connects() {
    let mut net = Net::new();
    let c = tcp(&mut net.a);
    net.a.set_nonblocking(c, true).unwrap();
    assert_eq!(
        net.a.connect(c, SocketAddr::new(PEER, 81)),
        Err(Error::InProgress)
    );
    assert!(!net.a.readiness(c).unwrap().writable);
    net.run(5);
    // Nobody listens: the peer answers RST.
    assert_eq!(net.a.connect_result(c), Err(Error::ConnectionRefused));
    assert_eq!(net.a.option(c, SOL_SOCKET, SO_ERROR), Ok(111));
    assert_eq!(net.a.option(c, SOL_SOCKET, SO_ERROR), Ok(0));
    let l = listener(&mut net.b, 81, 1);
    assert_eq!(
        net.a.connect(c, SocketAddr::new(PEER, 81)),
        Err(Error::InProgress)
    );
    net.run(5);
    assert!(net.a.readiness(c).unwrap().writable);
    assert!(net.b.accept(l).is_ok());
    let lost = tcp(&mut net.a);
    assert_eq!(
        net.a
            .connect(lost, SocketAddr::new(Ipv4Address::new(192, 168, 7, 7), 80)),
        Err(Error::WouldBlock)
    );
    net.run(76_000);
    assert_eq!(net.a.connect_result(lost), Err(Error::TimedOut));
}

#[test]
fn backlog_and_accept_order() {
    let mut net = Net::new();
    let l = listener(&mut net.b, 7000, 2);
    net.b.set_nonblocking(l, true).unwrap();
    assert_eq!(net.b.accept(l).err(), Some(Error::WouldBlock));
    let clients: Vec<SocketId> = (0..3).map(|_| tcp(&mut net.a)).collect();
    for &c in &clients {
        let _ = net.a.connect(c, SocketAddr::new(PEER, 7000));
    }
    net.run(10);
    let connected = clients
        .iter()
        .filter(|&&c| net.a.connect_result(c) == Ok(()))
        .count();
    assert_eq!(connected, 2, "a backlog of 2 takes 2 at once");
    net.b.accept(l).unwrap();
    net.b.accept(l).unwrap();
    assert_eq!(net.b.accept(l).err(), Some(Error::WouldBlock));
}

#[test]
fn udp_both_ways_and_errors() {
    let mut net = Net::new();
    let u = net.b.socket(AF_INET, SOCK_DGRAM, 0).unwrap();
    net.b
        .bind(u, SocketAddr::new(Ipv4Address::UNSPECIFIED, 5353))
        .unwrap();
    let c = net
        .a
        .socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0)
        .unwrap();
    assert_eq!(net.a.send(c, b"x", None), Err(Error::DestinationRequired));
    assert_eq!(
        net.a.send(c, b"hello", Some(SocketAddr::new(PEER, 5353))),
        Ok(5)
    );
    net.run(3);
    let mut buf = [0u8; 3];
    let (n, from) = net.b.recv(u, &mut buf).unwrap();
    assert_eq!(
        (n, &buf[..], from.unwrap().ip),
        (3, &b"hel"[..], GUEST),
        "cut to the buffer"
    );
    assert_eq!(net.b.recv(u, &mut buf), Err(Error::WouldBlock));
    net.b.send(u, b"back", from).unwrap();
    net.run(3);
    let mut big = [0u8; 64];
    assert_eq!(net.a.recv(c, &mut big).unwrap().0, 4);
    assert_eq!(
        net.a
            .send(c, &vec![0; 70_000], Some(SocketAddr::new(PEER, 5353))),
        Err(Error::MessageTooLong)
    );
    assert_eq!(net.a.listen(c, 1), Err(Error::OperationNotSupported));
    let u2 = net.b.socket(AF_INET, SOCK_DGRAM, 0).unwrap();
    assert_eq!(
        net.b
            .bind(u2, SocketAddr::new(Ipv4Address::UNSPECIFIED, 5353)),
        Err(Error::AddressInUse)
    );
}

#[test]
fn loopback_inside_one_stack() {
    let mut net = Net::new();
    let l = listener(&mut net.a, 8080, 2);
    let c = tcp(&mut net.a);
    assert_eq!(
        net.a.connect(c, SocketAddr::new(LOCAL, 8080)),
        Err(Error::WouldBlock)
    );
    net.run(3);
    assert_eq!(net.a.connect_result(c), Ok(()));
    let (s, peer) = net.a.accept(l).unwrap();
    assert_eq!(peer.ip, LOCAL);
    net.a.send(c, b"ping", None).unwrap();
    net.run(2);
    assert_eq!(read_all(&mut net, false, s, 4), b"ping");
    assert_eq!(net.frames, 0, "nothing left the machine");
}

/// A partition without `eth0`: the loopback works, every other address is unreachable,
/// and the stack never makes a frame.
#[test]
fn a_loopback_only_stack() {
    let mut s = Stack::new(Config::loopback_only(Limits::default()), 0);
    assert!(!s.config().has_eth());
    let l = listener(&mut s, 7, 1);
    let c = tcp(&mut s);
    assert_eq!(
        s.connect(c, SocketAddr::new(LOCAL, 7)),
        Err(Error::WouldBlock)
    );
    s.poll(1_000);
    assert_eq!(s.connect_result(c), Ok(()));
    assert!(s.accept(l).is_ok());
    let far = tcp(&mut s);
    assert_eq!(
        s.connect(far, SocketAddr::new(PEER, 80)),
        Err(Error::NetworkUnreachable)
    );
    let u = s.socket(AF_INET, SOCK_DGRAM, 0).unwrap();
    assert_eq!(
        s.send(u, b"x", Some(SocketAddr::new(PEER, 9))),
        Err(Error::NetworkUnreachable)
    );
    assert_eq!(
        s.bind(far, SocketAddr::new(Ipv4Address::UNSPECIFIED, 0)),
        Ok(())
    );
    s.poll(2_000);
    assert!(s.device.take().is_none(), "no frame without eth0");
}

/// A server that closes first leaves its side in TIME-WAIT for 10 s; with every socket
/// in use, those give their places to new connections instead of refusing them.
#[test]
fn time_wait_gives_way_to_new_connections() {
    let limits = Limits {
        sockets: 6,
        backlog: 1,
        ..Limits::default()
    };
    let mut s = Stack::new(Config::loopback_only(limits), 0);
    let l = tcp(&mut s);
    s.bind(l, SocketAddr::new(LOCAL, 80)).unwrap();
    s.listen(l, 1).unwrap();
    let mut now = 0;
    for round in 0..10 {
        let c = tcp(&mut s);
        let to = SocketAddr::new(LOCAL, 80);
        assert_eq!(s.connect(c, to), Err(Error::WouldBlock), "round {round}");
        now += 1_000;
        s.poll(now);
        let (a, _) = s.accept(l).unwrap();
        s.close(a).unwrap();
        now += 1_000;
        s.poll(now);
        let mut buf = [0u8; 4];
        assert_eq!(s.recv(c, &mut buf), Ok((0, None)), "round {round}");
        s.close(c).unwrap();
        now += 1_000;
        s.poll(now);
    }
}

#[test]
fn retransmission_over_a_lossy_wire() {
    for nth in 1..=6 {
        let mut net = Net::new();
        net.drop_nth = Some(nth);
        let l = listener(&mut net.b, 9, 1);
        let c = tcp(&mut net.a);
        let _ = net.a.connect(c, SocketAddr::new(PEER, 9));
        net.run(5_000);
        assert_eq!(net.a.connect_result(c), Ok(()), "frame {nth} lost");
        let (s, _) = net.b.accept(l).unwrap();
        net.a.send(c, b"after a loss", None).unwrap();
        net.run(5_000);
        assert_eq!(
            read_all(&mut net, true, s, 12),
            b"after a loss",
            "frame {nth} lost"
        );
    }
}

#[test]
fn refusals() {
    let mut s = stack(1, GUEST);
    assert_eq!(
        s.socket(AF_INET6, SOCK_STREAM, 0),
        Err(Error::AddressFamilyNotSupported)
    );
    assert_eq!(s.socket(AF_INET, 5, 0), Err(Error::SocketTypeNotSupported));
    assert_eq!(
        s.socket(AF_INET, SOCK_STREAM, IPPROTO_UDP),
        Err(Error::ProtocolNotSupported)
    );
    let a = tcp(&mut s);
    assert_eq!(
        s.bind(a, SocketAddr::new(Ipv4Address::new(10, 9, 9, 9), 1)),
        Err(Error::AddressNotAvailable)
    );
    s.bind(a, SocketAddr::new(GUEST, 22)).unwrap();
    assert_eq!(s.bind(a, SocketAddr::new(GUEST, 23)), Err(Error::Invalid));
    s.listen(a, 1).unwrap();
    let b = tcp(&mut s);
    s.set_option(b, SOL_SOCKET, SO_REUSEADDR, 1).unwrap();
    assert_eq!(
        s.bind(b, SocketAddr::new(Ipv4Address::UNSPECIFIED, 22)),
        Err(Error::AddressInUse),
        "a listener holds it"
    );
    assert_eq!(s.send(b, b"x", None), Err(Error::NotConnected));
    assert_eq!(s.shutdown(b, SHUT_RD), Err(Error::NotConnected));
    assert_eq!(s.set_option(b, 99, 1, 1), Err(Error::NoProtocolOption));
    assert_eq!(s.option(b, SOL_SOCKET, SO_TYPE), Ok(SOCK_STREAM));
    assert_eq!(
        s.option(SocketId(999), SOL_SOCKET, SO_TYPE),
        Err(Error::BadDescriptor)
    );
    let mut count = 2;
    while s.socket(AF_INET, SOCK_STREAM, 0).is_ok() {
        count += 1;
        assert!(count <= 64);
    }
    assert_eq!(s.socket(AF_INET, SOCK_STREAM, 0), Err(Error::NoBuffers));
}

/// TCP buffers the heap cannot hold make the call fail with `ENOBUFS`; the partition goes
/// on, the failed socket can try again, and nothing stays allocated for it.
#[test]
fn buffers_the_heap_cannot_hold_are_an_error() {
    let mut s = Stack::new(
        Config {
            limits: Limits {
                tcp_buffer: isize::MAX as usize,
                ..Limits::default()
            },
            ..Config::loopback_only(Limits::default())
        },
        0,
    );
    let l = tcp(&mut s);
    s.bind(l, SocketAddr::new(LOCAL, 80)).unwrap();
    assert_eq!(s.listen(l, 4), Err(Error::NoBuffers));
    assert_eq!(s.listen(l, 4), Err(Error::NoBuffers), "still fresh");
    let c = tcp(&mut s);
    assert_eq!(
        s.connect(c, SocketAddr::new(LOCAL, 80)),
        Err(Error::NoBuffers)
    );
    // Every failed attempt gave its sockets back: the limit still admits as many.
    let mut open = 2;
    while s.socket(AF_INET, SOCK_DGRAM, 0).is_ok() {
        open += 1;
    }
    assert_eq!(open, Limits::default().sockets);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3_000))]

    /// Any bytes as a frame from the wire, with a listener and a connection open: never a
    /// panic; the stack still serves the connection afterwards.
    #[test]
    fn hostile_frames(frames in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..1600), 1..8),
                      ethertype_ip in any::<bool>()) {
        let mut net = Net::new();
        let l = listener(&mut net.b, 80, 1);
        let c = tcp(&mut net.a);
        let _ = net.a.connect(c, SocketAddr::new(PEER, 80));
        net.run(5);
        for mut f in frames {
            if ethertype_ip && f.len() >= 14 {
                f[..6].copy_from_slice(&[0x02, 0, 0, 0, 0, 2]);
                f[12] = 0x08;
                f[13] = 0x00;
            }
            net.b.device.deliver(&f);
            net.run(1);
        }
        let (s, _) = net.b.accept(l).unwrap();
        net.a.send(c, b"still", None).unwrap();
        net.run(50);
        prop_assert_eq!(read_all(&mut net, true, s, 5), b"still");
    }
}
