//! A tenant of the NIC partition's switch (scenario `net_nic`), attached by its queuing
//! ports `tx` (frames out) and `rx` (frames in), size 1514. What it does depends on its
//! partition name:
//!
//! * `echo*`: the host 10.0.2.15 with MAC 52:54:00:12:34:56 (QEMU user networking's guest
//!   address, where the scenario's `hostfwd` sends): answers ARP requests for its address
//!   and echoes UDP datagrams to port 7 (RFC 862) back to their sender; logs
//!   `echo: t=<ms>ms arp=<n> udp=<n> other=<n>` each second something came (ARP requests
//!   answered, datagrams echoed, frames ignored), and `echo: the host is done` for a
//!   datagram saying `done` (the scenario's end);
//! * `flood*`: MAC 52:54:00:12:34:57, sends full-size frames of a local experimental
//!   EtherType (0x88b5, which the wire and the other tenants ignore), three to QEMU's
//!   gateway and one broadcast in turn, as fast as its port takes them, for ever; logs `flood: t=<ms>ms sent=<n> refused=<n>` each second (refused: its
//!   port was full);
//! * `scribble*`: a hostile tenant on a frame ring (its configuration's first shared
//!   segment, [`RING_SIZE`] bytes): pushes the flood's frames into its ring as fast as it
//!   takes them and, after every frame, writes four random bytes at a random offset of the
//!   segment (indices, lengths, frames, the NIC partition's half too); logs `scribble:
//!   t=<ms>ms pushed=<n> full=<n> scribbled=<n>` each second;
//! * `idle*`: sends nothing and takes whatever comes (the quiet case to compare with).
//!
//! A hand-made minimal responder, not a TCP/IP stack. A test program: it must never be
//! needed by anything but its scenario.
#![no_std]
#![no_main]

use apex::Warden;
use apex::a653rs::prelude::*;
use apex::main_process::{self, Release};
use apex::user_rt::println;
use core::str::FromStr;
use core::time::Duration;

const FRAME: usize = 1514;
const ECHO_MAC: [u8; 6] = [0x52, 0x54, 0, 0x12, 0x34, 0x56];
const ECHO_IP: [u8; 4] = [10, 0, 2, 15];
const FLOOD_MAC: [u8; 6] = [0x52, 0x54, 0, 0x12, 0x34, 0x57];
/// QEMU user networking's gateway (10.0.2.2).
const GATEWAY_MAC: [u8; 6] = [0x52, 0x55, 10, 0, 2, 2];
const ETHERTYPE_ARP: u16 = 0x0806;
const ETHERTYPE_IPV4: u16 = 0x0800;
const ETHERTYPE_EXPERIMENTAL: u16 = 0x88b5;
const UDP: u8 = 17;
const ECHO_PORT: u16 = 7;
/// The `scribble` tenant's frame ring: the first shared segment, of this size.
const RING_SIZE: usize = 64 * 1024;

fn name(text: &str) -> Name {
    Name::from_str(text).expect("names here are short")
}

fn now_ms() -> u64 {
    <Warden as ApexTimeP4Ext>::get_time()
        .unwrap_duration()
        .as_millis() as u64
}

fn be16(b: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([b[at], b[at + 1]])
}

/// The Internet checksum of `bytes` (RFC 1071).
fn checksum(bytes: &[u8]) -> u16 {
    let mut sum = 0u32;
    for pair in bytes.chunks(2) {
        sum += u32::from(u16::from_be_bytes([pair[0], *pair.get(1).unwrap_or(&0)]));
    }
    while sum > 0xffff {
        sum = (sum & 0xffff) + (sum >> 16);
    }
    !(sum as u16)
}

enum Answer {
    Arp(usize),
    /// The echo's length, and the payload's range in it.
    Udp(usize, core::ops::Range<usize>),
    None,
}

/// The answer to `frame` in `out`, if it is an ARP request for our address or a UDP
/// datagram to our port 7.
fn answer(frame: &[u8], out: &mut [u8; FRAME]) -> Answer {
    if frame.len() < 14 {
        return Answer::None;
    }
    let body = &frame[14..];
    match be16(frame, 12) {
        ETHERTYPE_ARP if body.len() >= 28 && be16(body, 6) == 1 && body[24..28] == ECHO_IP => {
            out[..6].copy_from_slice(&body[8..14]);
            out[6..12].copy_from_slice(&ECHO_MAC);
            out[12..14].copy_from_slice(&ETHERTYPE_ARP.to_be_bytes());
            let arp = &mut out[14..42];
            arp[..6].copy_from_slice(&body[..6]); // hardware and protocol types, sizes
            arp[6..8].copy_from_slice(&2u16.to_be_bytes()); // reply
            arp[8..14].copy_from_slice(&ECHO_MAC);
            arp[14..18].copy_from_slice(&ECHO_IP);
            arp[18..28].copy_from_slice(&body[8..18]); // the asker's MAC and address
            Answer::Arp(42)
        }
        ETHERTYPE_IPV4 if body.len() >= 28 => {
            let ihl = usize::from(body[0] & 0xf) * 4;
            let total = usize::from(be16(body, 2));
            let ok = body[0] >> 4 == 4
                && ihl >= 20
                && total >= ihl + 8
                && total <= body.len()
                && body[9] == UDP
                && body[16..20] == ECHO_IP
                && be16(body, ihl + 2) == ECHO_PORT;
            if !ok {
                return Answer::None;
            }
            let len = 14 + total;
            out[..len].copy_from_slice(&frame[..len]);
            out[..6].copy_from_slice(&frame[6..12]);
            out[6..12].copy_from_slice(&ECHO_MAC);
            let ip = &mut out[14..len];
            ip[8] = 64; // TTL
            ip[12..16].copy_from_slice(&body[16..20]);
            ip[16..20].copy_from_slice(&body[12..16]);
            ip[10..12].fill(0);
            let sum = checksum(&ip[..ihl]);
            ip[10..12].copy_from_slice(&sum.to_be_bytes());
            let udp = &mut ip[ihl..];
            udp[..2].copy_from_slice(&body[ihl + 2..ihl + 4]);
            udp[2..4].copy_from_slice(&body[ihl..ihl + 2]);
            udp[6..8].fill(0); // no UDP checksum (allowed over IPv4)
            Answer::Udp(len, 14 + ihl + 8..len)
        }
        _ => Answer::None,
    }
}

extern "C" fn echo() {
    let rx = QueuingPortReceiver::<Warden>::from_name(name("rx")).expect("rx");
    let tx = QueuingPortSender::<Warden>::from_name(name("tx")).expect("tx");
    let mut frame = [0u8; FRAME];
    let mut out = [0u8; FRAME];
    let (mut arp, mut udp, mut other) = (0u64, 0u64, 0u64);
    let mut logged = (0, 0, 0);
    let mut next_log = now_ms() + 1000;
    loop {
        let wait = SystemTime::Normal(Duration::from_millis(100));
        if let Ok((message, _)) = rx.receive(&mut frame, wait) {
            let len = message.len();
            let reply = match answer(&frame[..len], &mut out) {
                Answer::Arp(n) => {
                    arp += 1;
                    n
                }
                Answer::Udp(n, payload) => {
                    udp += 1;
                    if &out[payload] == b"done" {
                        println!("echo: the host is done");
                    }
                    n
                }
                Answer::None => {
                    other += 1;
                    0
                }
            };
            if reply > 0 {
                let _ = tx.send(&out[..reply], SystemTime::Normal(Duration::ZERO));
            }
        }
        let now = now_ms();
        if now >= next_log {
            if (arp, udp, other) != logged {
                println!("echo: t={now}ms arp={arp} udp={udp} other={other}");
                logged = (arp, udp, other);
            }
            next_log = now + 1000;
        }
    }
}

extern "C" fn flood() {
    let tx = QueuingPortSender::<Warden>::from_name(name("tx")).expect("tx");
    let mut frame = [0xa5u8; FRAME];
    frame[..6].copy_from_slice(&GATEWAY_MAC);
    frame[6..12].copy_from_slice(&FLOOD_MAC);
    frame[12..14].copy_from_slice(&ETHERTYPE_EXPERIMENTAL.to_be_bytes());
    let (mut sent, mut refused) = (0u64, 0u64);
    let mut next_log = now_ms() + 1000;
    loop {
        flood_frame(sent + refused, &mut frame);
        match tx.send(&frame, SystemTime::Normal(Duration::ZERO)) {
            Ok(()) => sent += 1,
            Err(_) => refused += 1,
        }
        let now = now_ms();
        if now >= next_log {
            println!("flood: t={now}ms sent={sent} refused={refused}");
            next_log = now + 1000;
        }
    }
}

/// The flood's frame to the gateway or, every fourth, to everyone.
fn flood_frame(n: u64, frame: &mut [u8; FRAME]) {
    frame[..6].copy_from_slice(if n % 4 == 3 { &[0xff; 6] } else { &GATEWAY_MAC });
}

extern "C" fn scribble() {
    let tx = QueuingPortSender::<Warden>::from_name(name("tx")).expect("tx");
    let segment = apex::user_rt::partition::SHARED_BASE as *mut u8;
    #[allow(unsafe_code)]
    // SAFETY: the first shared segment (RING_SIZE bytes), read-write at SHARED_BASE in this
    // partition and the NIC partition only; the tenant's one attach.
    let ring = unsafe { frame_ring::attach(segment, RING_SIZE, frame_ring::Side::Tenant) };
    let (mut to_nic, _) = ring.expect("the frame ring");
    let mut frame = [0xa5u8; FRAME];
    frame[6..12].copy_from_slice(&FLOOD_MAC);
    frame[12..14].copy_from_slice(&ETHERTYPE_EXPERIMENTAL.to_be_bytes());
    let (mut pushed, mut full, mut scribbled) = (0u64, 0u64, 0u64);
    let mut x: u64 = 0x2545_f491_4f6c_dd1d;
    let mut next_log = now_ms() + 1000;
    loop {
        flood_frame(pushed + full, &mut frame);
        match to_nic.push(&frame) {
            Ok(p) => {
                pushed += 1;
                if p.first {
                    let _ = tx.send(&[0], SystemTime::Normal(Duration::ZERO));
                }
            }
            Err(_) => full += 1,
        }
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let at = (x % (RING_SIZE as u64 - 4)) as usize;
        // SAFETY: `at + 4 <= RING_SIZE`: inside the segment mapped read-write above (what
        // the bytes break is the ring's business, which trusts none of them).
        #[allow(unsafe_code)]
        unsafe {
            core::ptr::write_unaligned(segment.wrapping_add(at) as *mut u32, (x >> 32) as u32)
        };
        scribbled += 1;
        let now = now_ms();
        if now >= next_log {
            println!("scribble: t={now}ms pushed={pushed} full={full} scribbled={scribbled}");
            next_log = now + 1000;
        }
    }
}

extern "C" fn idle() {
    let rx = QueuingPortReceiver::<Warden>::from_name(name("rx")).expect("rx");
    let mut frame = [0u8; FRAME];
    loop {
        let _ = rx.receive(&mut frame, SystemTime::Infinite);
    }
}

struct Tenant;

impl Partition<Warden> for Tenant {
    fn cold_start(&self, ctx: &mut StartContext<Warden>) {
        let fifo = QueuingDiscipline::Fifo;
        ctx.create_queuing_port_sender(name("tx"), FRAME as u32, 16, fifo)
            .expect("CREATE_QUEUING_PORT tx");
        ctx.create_queuing_port_receiver(name("rx"), FRAME as u32, 16, fifo)
            .expect("CREATE_QUEUING_PORT rx");
        let me = apex::runtime::start_info();
        let entry_point: extern "C" fn() = if me.name().starts_with("flood") {
            flood
        } else if me.name().starts_with("scribble") {
            scribble
        } else if me.name().starts_with("idle") {
            idle
        } else {
            echo
        };
        main_process::start(ctx, "tenant", entry_point, 16 * 1024, Release::Aperiodic)
            .unwrap_or_else(|e| panic!("{e}"));
    }

    fn warm_start(&self, ctx: &mut StartContext<Warden>) {
        self.cold_start(ctx)
    }
}

fn main() {
    Tenant.run()
}

apex::partition_entry!(main);
