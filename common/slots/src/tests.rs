//! The format against a power cut at every point of a write: a disk with a write-back cache
//! where, between two flushes, any subset of the pending sector writes may have landed, and
//! a landed sector may be torn at any of many byte offsets.

extern crate std;

use super::*;
use proptest::prelude::*;
use std::vec;
use std::vec::Vec;

#[derive(Clone, Debug)]
enum Op {
    Write(u64, std::boxed::Box<[u8; SECTOR]>),
    Flush,
}

/// A disk that records the operations of a write instead of applying them.
#[derive(Clone)]
struct Disk {
    sectors: Vec<[u8; SECTOR]>,
    log: Vec<Op>,
}

impl Disk {
    fn new(n: usize) -> Self {
        Disk {
            sectors: vec![[0u8; SECTOR]; n],
            log: Vec::new(),
        }
    }

    fn apply(&mut self) {
        for op in core::mem::take(&mut self.log) {
            if let Op::Write(s, data) = op {
                self.sectors[s as usize] = *data;
            }
        }
    }
}

impl BlockDevice for Disk {
    type Error = ();
    fn read(&mut self, sector: u64, buf: &mut [u8; SECTOR]) -> Result<(), ()> {
        *buf = *self.sectors.get(sector as usize).ok_or(())?;
        Ok(())
    }
    fn write(&mut self, sector: u64, data: &[u8; SECTOR]) -> Result<(), ()> {
        self.sectors.get(sector as usize).ok_or(())?;
        self.log
            .push(Op::Write(sector, std::boxed::Box::new(*data)));
        Ok(())
    }
    fn flush(&mut self) -> Result<(), ()> {
        self.log.push(Op::Flush);
        Ok(())
    }
}

const REGION: Region = Region {
    first: 2,
    sectors: 20,
    kind: 7,
};

/// Offsets at which a landed sector may be torn (new bytes before, old after).
const TEARS: [usize; 9] = [1, 4, 24, 27, 28, 64, 256, 300, 511];

/// Every disk state a power cut during `ops` (applied to `before`) can leave.
fn cut_states(before: &Disk, ops: &[Op]) -> Vec<Disk> {
    let epochs: Vec<Vec<(u64, [u8; SECTOR])>> = ops
        .split(|op| matches!(op, Op::Flush))
        .map(|epoch| {
            epoch
                .iter()
                .filter_map(|op| match op {
                    Op::Write(s, d) => Some((*s, **d)),
                    Op::Flush => None,
                })
                .collect()
        })
        .collect();
    let mut states = Vec::new();
    let mut base = before.clone();
    for epoch in &epochs {
        assert!(epoch.len() < 16, "keep the subsets enumerable");
        for subset in 0u32..1 << epoch.len() {
            let landed: Vec<&(u64, [u8; SECTOR])> = epoch
                .iter()
                .enumerate()
                .filter(|(i, _)| subset >> i & 1 == 1)
                .map(|(_, w)| w)
                .collect();
            let mut whole = base.clone();
            for (s, d) in &landed {
                whole.sectors[*s as usize] = *d;
            }
            states.push(whole);
            for (torn_index, (s, d)) in landed.iter().enumerate() {
                for tear in TEARS {
                    let mut torn = base.clone();
                    for (j, (s2, d2)) in landed.iter().enumerate() {
                        if j != torn_index {
                            torn.sectors[*s2 as usize] = *d2;
                        }
                    }
                    torn.sectors[*s as usize][..tear].copy_from_slice(&d[..tear]);
                    states.push(torn);
                }
            }
        }
        for (s, d) in epoch {
            base.sectors[*s as usize] = *d;
        }
    }
    states.push(base);
    states
}

fn newest_payload(disk: &mut Disk) -> Option<Vec<u8>> {
    let scan = scan(disk, &REGION).unwrap();
    let record = scan.newest()?;
    let mut out = vec![0u8; record.len];
    assert_eq!(
        read(disk, &REGION, &record, &mut out).unwrap(),
        Some(record.len)
    );
    Some(out)
}

/// Writes `payloads` one after another, cutting the power at every point of each write:
/// the disk then holds the previous payload or the new one, never anything else.
fn check_series(payloads: &[Vec<u8>]) -> usize {
    let mut disk = Disk::new(24);
    let mut previous: Option<Vec<u8>> = None;
    let mut checked = 0;
    for payload in payloads {
        let s = scan(&mut disk, &REGION).unwrap();
        let mut writing = disk.clone();
        write(&mut writing, &REGION, &s, payload).unwrap();
        for mut state in cut_states(&disk, &writing.log) {
            let got = newest_payload(&mut state);
            assert!(
                got == previous || got.as_deref() == Some(&payload[..]),
                "a cut left {got:?}, neither the old {previous:?} nor the new record"
            );
            checked += 1;
        }
        writing.apply();
        disk = writing;
        assert_eq!(newest_payload(&mut disk).as_deref(), Some(&payload[..]));
        previous = Some(payload.clone());
    }
    checked
}

#[test]
fn every_cut_of_a_series_of_writes_leaves_old_or_new() {
    let full = REGION.capacity();
    let payloads: Vec<Vec<u8>> = [0usize, 1, 511, 512, 513, full, 100, full - 1]
        .iter()
        .enumerate()
        .map(|(i, &n)| (0..n).map(|b| (b * 7 + i * 13) as u8).collect())
        .collect();
    let checked = check_series(&payloads);
    assert!(checked > 40_000, "{checked} cut states");
}

#[test]
fn corrupt_slots_are_named_and_skipped() {
    let mut disk = Disk::new(24);
    for payload in [&b"first"[..], b"second"] {
        let s = scan(&mut disk, &REGION).unwrap();
        write(&mut disk, &REGION, &s, payload).unwrap();
        disk.apply();
    }
    // "second" is in slot 1 (sector 12); break its payload.
    disk.sectors[13][0] ^= 0xFF;
    let s = scan(&mut disk, &REGION).unwrap();
    assert_eq!(
        s.slots[1],
        SlotState::Corrupt(Corruption::Payload { sequence: 2 })
    );
    assert_eq!(newest_payload(&mut disk).as_deref(), Some(&b"first"[..]));
    // The next write goes above every sequence seen and into the corrupt slot.
    let record = write(&mut disk, &REGION, &s, b"third").unwrap();
    disk.apply();
    assert_eq!((record.slot, record.sequence), (1, 3));
    // A header of another kind, a broken header CRC, an impossible length.
    let other = Region { kind: 8, ..REGION };
    assert_eq!(scan(&mut disk, &other).unwrap().newest(), None);
    disk.sectors[2][8] ^= 1;
    assert_eq!(
        scan(&mut disk, &REGION).unwrap().slots[0],
        SlotState::Corrupt(Corruption::Header)
    );
    let mut long = disk.clone();
    long.sectors[12][16..20].copy_from_slice(&10_000u32.to_le_bytes());
    let c = crc(&long.sectors[12][..24]);
    long.sectors[12][24..28].copy_from_slice(&c.to_le_bytes());
    assert_eq!(
        scan(&mut long, &REGION).unwrap().slots[1],
        SlotState::Corrupt(Corruption::Length { len: 10_000 })
    );
}

#[test]
fn sizes_and_regions_are_checked() {
    let mut disk = Disk::new(24);
    let s = scan(&mut disk, &REGION).unwrap();
    assert_eq!(s.slots, [SlotState::Empty; 2]);
    let big = vec![0u8; REGION.capacity() + 1];
    assert_eq!(
        write(&mut disk, &REGION, &s, &big),
        Err(Error::TooLarge {
            len: big.len(),
            capacity: REGION.capacity()
        })
    );
    let tiny = Region {
        sectors: 3,
        ..REGION
    };
    assert_eq!(scan(&mut disk, &tiny), Err(Error::Region));
    assert_eq!(write(&mut disk, &tiny, &s, b""), Err(Error::Region));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn random_series_survive_every_cut(sizes in proptest::collection::vec(0usize..=4608, 1..4), seed in any::<u8>()) {
        let payloads: Vec<Vec<u8>> = sizes
            .iter()
            .map(|&n| (0..n).map(|b| (b as u8).wrapping_mul(31).wrapping_add(seed)).collect())
            .collect();
        check_series(&payloads);
    }

    /// Random sectors as a disk: scan never panics and never calls garbage valid.
    #[test]
    fn random_disks_are_scanned_safely(bytes in proptest::collection::vec(any::<u8>(), SECTOR * 24)) {
        let mut disk = Disk::new(24);
        for (i, chunk) in bytes.chunks(SECTOR).enumerate() {
            disk.sectors[i].copy_from_slice(chunk);
        }
        let s = scan(&mut disk, &REGION).unwrap();
        prop_assert_eq!(s.newest(), None);
    }
}
