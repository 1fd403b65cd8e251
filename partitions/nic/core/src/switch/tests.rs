//! Forwarding rules, isolation between tenants, fairness, and hostile frames.

extern crate std;

use super::*;
use proptest::prelude::*;
use std::vec;
use std::vec::Vec;

const PLC: Mac = Mac([0x02, 0, 0, 0, 0, 1]);
const GUEST: Mac = Mac([0x02, 0, 0, 0, 0, 2]);
const HOST: Mac = Mac([0x52, 0x55, 10, 0, 2, 2]);

fn frame(to: Mac, from: Mac, len: usize) -> Vec<u8> {
    let mut f = vec![0u8; len.max(MIN_FRAME)];
    f[..6].copy_from_slice(&to.0);
    f[6..12].copy_from_slice(&from.0);
    f[12..14].copy_from_slice(&0x0800u16.to_be_bytes());
    f.truncate(len);
    f
}

fn switch() -> Switch {
    Switch::new(&[PLC, GUEST]).unwrap()
}

fn ports(s: Ports) -> Vec<Port> {
    s.iter(2).collect()
}

#[test]
fn macs_parse_as_colon_separated_hex() {
    assert_eq!(
        Mac::parse("52:54:00:12:34:5f"),
        Some(Mac([0x52, 0x54, 0, 0x12, 0x34, 0x5f]))
    );
    assert_eq!(
        std::format!("{}", Mac::parse("52:54:00:AB:34:56").unwrap()),
        "52:54:00:ab:34:56"
    );
    for bad in [
        "",
        "52:54:00:12:34",
        "52:54:00:12:34:56:78",
        "52-54-00-12-34-56",
        "5:54:00:12:34:567",
        "+5:54:00:12:34:56",
        "zz:54:00:12:34:56",
    ] {
        assert_eq!(Mac::parse(bad), None, "{bad}");
    }
}

#[test]
fn forwarding_rules() {
    let mut s = switch();
    let (plc, guest) = (Port::Tenant(0), Port::Tenant(1));
    // Tenant to tenant stays inside; tenant to elsewhere goes out.
    assert_eq!(
        s.route(plc, &frame(GUEST, PLC, 60)).map(ports),
        Ok(vec![guest])
    );
    assert_eq!(
        s.route(guest, &frame(HOST, GUEST, 60)).map(ports),
        Ok(vec![Port::Uplink])
    );
    // From the wire, to a tenant; to nobody: dropped, not flooded.
    assert_eq!(
        s.route(Port::Uplink, &frame(GUEST, HOST, 60)).map(ports),
        Ok(vec![guest])
    );
    assert_eq!(
        s.route(Port::Uplink, &frame(Mac([2, 9, 9, 9, 9, 9]), HOST, 60)),
        Err(Drop::Unknown)
    );
    // Broadcast and multicast: everyone but the sender.
    assert_eq!(
        s.route(plc, &frame(Mac::BROADCAST, PLC, 42)).map(ports),
        Ok(vec![Port::Uplink, guest])
    );
    let multicast = Mac([0x01, 0x00, 0x5E, 0, 0, 1]);
    assert_eq!(
        s.route(Port::Uplink, &frame(multicast, HOST, 42))
            .map(ports),
        Ok(vec![plc, guest])
    );
    // To oneself: nowhere.
    assert_eq!(s.route(plc, &frame(PLC, PLC, 60)), Err(Drop::Unknown));
    assert_eq!(s.counters(Port::Uplink).received, 3);
    assert_eq!(s.counters(Port::Uplink).unknown, 1);
}

#[test]
fn tenants_cannot_spoof_or_send_garbage() {
    let mut s = switch();
    let guest = Port::Tenant(1);
    assert_eq!(
        s.route(guest, &frame(HOST, PLC, 60)),
        Err(Drop::Spoofed),
        "posing as the PLC"
    );
    assert_eq!(
        s.route(guest, &frame(HOST, Mac::BROADCAST, 60)),
        Err(Drop::Spoofed)
    );
    assert_eq!(
        s.route(guest, &frame(HOST, GUEST, 13)),
        Err(Drop::Malformed)
    );
    assert_eq!(
        s.route(guest, &frame(HOST, GUEST, 1515)),
        Err(Drop::Malformed)
    );
    assert_eq!(s.route(guest, &[]), Err(Drop::Malformed));
    assert_eq!(
        s.route(Port::Tenant(5), &frame(HOST, GUEST, 60)),
        Err(Drop::NoSuchPort)
    );
    let c = s.counters(guest);
    assert_eq!((c.received, c.spoofed, c.malformed), (5, 2, 3));
    assert_eq!(s.counters(Port::Tenant(0)), Counters::default());
    s.delivered(Port::Tenant(0), false);
    s.delivered(Port::Tenant(0), true);
    let c = s.counters(Port::Tenant(0));
    assert_eq!((c.delivered, c.overflow), (1, 1));
}

#[test]
fn a_tenants_broadcast_storm_is_bounded_and_costs_only_it() {
    let mut s = switch();
    let (plc, guest) = (Port::Tenant(0), Port::Tenant(1));
    s.set_time(5_000_000_000);
    let storm = frame(Mac::BROADCAST, GUEST, 60);
    let passed = (0..1000).filter(|_| s.route(guest, &storm).is_ok()).count();
    assert_eq!(
        passed, GROUP_BURST as usize,
        "the burst, then nothing at one instant"
    );
    assert_eq!(s.route(guest, &storm), Err(Drop::Limited));
    assert_eq!(s.counters(guest).limited, 1000 - u64::from(GROUP_BURST) + 1);
    // The other tenant's broadcasts and everyone's unicast are untouched.
    assert!(s.route(plc, &frame(Mac::BROADCAST, PLC, 60)).is_ok());
    assert!(s.route(guest, &frame(HOST, GUEST, 60)).is_ok());
    // Tokens come back at GROUP_RATE: 100 ms later, a tenth of a second's worth.
    s.set_time(5_100_000_000);
    let passed = (0..100).filter(|_| s.route(guest, &storm).is_ok()).count();
    assert_eq!(passed, (GROUP_RATE / 10) as usize);
    // A clock going back refills nothing; a long pause refills only the burst.
    s.set_time(1);
    assert_eq!(s.route(guest, &storm), Err(Drop::Limited));
    s.set_time(u64::MAX);
    let passed = (0..1000).filter(|_| s.route(guest, &storm).is_ok()).count();
    assert_eq!(passed, GROUP_BURST as usize);
    // The wire's broadcasts are not a tenant's.
    assert!((0..1000).all(|_| {
        s.route(Port::Uplink, &frame(Mac::BROADCAST, HOST, 60))
            .is_ok()
    }));
}

#[test]
fn configuration_is_checked() {
    assert_eq!(
        Switch::new(&[PLC, PLC]).err(),
        Some(ConfigError::Duplicate(PLC))
    );
    assert_eq!(
        Switch::new(&[Mac::BROADCAST]).err(),
        Some(ConfigError::GroupAddress(Mac::BROADCAST))
    );
    let many: Vec<Mac> = (0..16).map(|i| Mac([2, 0, 0, 0, 0, i])).collect();
    assert_eq!(Switch::new(&many).err(), Some(ConfigError::TooMany));
    assert!(Switch::new(&many[..15]).is_ok());
}

#[test]
fn a_flooding_tenant_gets_only_its_share() {
    // Tenant 0 always has frames; tenant 1 has 10. With a budget of 4 per round, tenant 1's
    // frames all go within its rounds: the flood never starves it.
    let mut rounds = Rounds::new(2, 4);
    let mut quiet_left = 10;
    let mut order = Vec::new();
    for _ in 0..40 {
        let Some(t) = rounds.pick(|n| n == 0 || quiet_left > 0) else {
            break;
        };
        rounds.took();
        if t == 1 {
            quiet_left -= 1;
        }
        order.push(t);
    }
    assert_eq!(quiet_left, 0);
    let flood_before_done = order.iter().position(|&t| t == 1).unwrap();
    assert!(flood_before_done <= 4);
    // Never more than 4 in a row from one tenant while the other waits.
    let last_quiet = order.iter().rposition(|&t| t == 1).unwrap();
    for window in order[..last_quiet].windows(5) {
        assert!(window.contains(&1), "{order:?}");
    }
    assert_eq!(Rounds::new(2, 4).pick(|_| false), None);
    assert_eq!(Rounds::new(0, 4).pick(|_| true), None);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(5_000))]

    /// Any bytes from any port: a set of ports or a drop reason, never a panic; a tenant's
    /// frame never goes back to it; only frames with its own source MAC leave a tenant.
    #[test]
    fn hostile_frames(bytes in proptest::collection::vec(any::<u8>(), 0..1600), from in 0usize..4) {
        let mut s = switch();
        let port = if from == 3 { Port::Uplink } else { Port::Tenant(from) };
        if let Ok(to) = s.route(port, &bytes) {
            prop_assert!(!to.is_empty());
            prop_assert!(!to.contains(port));
            if let Port::Tenant(n) = port {
                prop_assert_eq!(&bytes[6..12], &[PLC, GUEST][n].0[..]);
            }
        }
    }
}
