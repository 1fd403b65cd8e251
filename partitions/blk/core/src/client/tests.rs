//! The PLC's records through the whole path: `slots` on the client, the link, the
//! driver's [`serve`] and a disk in memory with a write-back cache that a power cut
//! empties; and a damaged or hostile path noticed, never taken for data.

extern crate std;

use super::*;
use crate::disk::VirtualDisk;
use crate::driver::{Device, Outcome, serve};
use crate::virtio_blk::{FEATURE_FLUSH, Refusal};
use std::collections::BTreeMap;
use std::vec;
use std::vec::Vec;

/// A disk with a write-back cache: writes land in `cache` until a flush.
#[derive(Default)]
struct CachedDisk {
    stable: BTreeMap<u64, Vec<u8>>,
    cache: BTreeMap<u64, Vec<u8>>,
    flushes: usize,
}

impl Device for CachedDisk {
    fn read(&mut self, at: u64, out: &mut [u8]) -> Status {
        for (i, s) in out.chunks_mut(SECTOR).enumerate() {
            let k = at + i as u64;
            let v = self.cache.get(&k).or(self.stable.get(&k));
            s.copy_from_slice(v.map_or(&[0u8; SECTOR][..], |v| v));
        }
        Status::Ok
    }
    fn write(&mut self, at: u64, data: &[u8]) -> Status {
        for (i, s) in data.chunks(SECTOR).enumerate() {
            self.cache.insert(at + i as u64, s.to_vec());
        }
        Status::Ok
    }
    fn flush(&mut self) -> Status {
        self.flushes += 1;
        self.stable.append(&mut self.cache);
        Status::Ok
    }
}

/// The driver partition in one call: the tenant's message served against the disk.
struct Loopback<'a> {
    disk: &'a mut CachedDisk,
    range: VirtualDisk,
    /// Flips this byte of the next response (a damaged path).
    damage: Option<usize>,
    outcomes: Vec<Outcome>,
}

impl Transport for Loopback<'_> {
    type Error = ();
    fn exchange(&mut self, request: &[u8], response: &mut [u8]) -> Result<usize, ()> {
        let (n, outcome) = serve(request, &self.range, FEATURE_FLUSH, self.disk, response);
        self.outcomes.push(outcome);
        if let Some(at) = self.damage.take() {
            response[at % n] ^= 0x10;
        }
        Ok(n)
    }
}

const PLC: VirtualDisk = VirtualDisk {
    first_sector: 64,
    sectors: 32,
};
const REGION: slots::Region = slots::Region {
    first: 0,
    sectors: 16,
    kind: 1,
};

#[test]
fn records_go_through_the_link_into_the_tenants_range_and_survive_a_power_cut() {
    let mut disk = CachedDisk::default();
    let payload: Vec<u8> = (0..1500u32).map(|i| (i * 7) as u8).collect();
    {
        let mut c = Client::new(Loopback {
            disk: &mut disk,
            range: PLC,
            damage: None,
            outcomes: Vec::new(),
        });
        let scan = slots::scan(&mut c, &REGION).unwrap();
        assert_eq!(scan.newest(), None);
        slots::write(&mut c, &REGION, &scan, &payload).unwrap();
    }
    assert_eq!(disk.flushes, 2, "payload, flush, header, flush");
    assert!(disk.cache.is_empty());
    assert!(
        disk.stable.keys().all(|s| (64..64 + 32).contains(s)),
        "only its range"
    );
    // A power cut: only what was flushed is there.
    disk.cache.clear();
    let mut c = Client::new(Loopback {
        disk: &mut disk,
        range: PLC,
        damage: None,
        outcomes: Vec::new(),
    });
    let scan = slots::scan(&mut c, &REGION).unwrap();
    let record = scan.newest().unwrap();
    let mut back = vec![0u8; record.len];
    assert_eq!(
        slots::read(&mut c, &REGION, &record, &mut back),
        Ok(Some(payload.len()))
    );
    assert_eq!(back, payload);
}

/// A run of sectors goes four to a request (the last request shorter), lands where single
/// writes would, and reads back the same way; a length that is no multiple of a sector
/// moves its whole sectors only.
#[test]
fn runs_of_sectors_go_four_to_a_request() {
    use slots::BlockDevice;
    let mut disk = CachedDisk::default();
    let data: Vec<u8> = (0..11 * SECTOR).map(|i| (i * 13 % 251) as u8).collect();
    let mut c = Client::new(Loopback {
        disk: &mut disk,
        range: PLC,
        damage: None,
        outcomes: Vec::new(),
    });
    c.write_sectors(5, &data).unwrap();
    assert_eq!(c.transport.outcomes.len(), 3, "4 + 4 + 3 sectors");
    let mut back = vec![0u8; 11 * SECTOR + 100];
    c.read_sectors(5, &mut back).unwrap();
    assert_eq!(c.transport.outcomes.len(), 6);
    assert_eq!(back[..11 * SECTOR], data[..]);
    assert!(
        back[11 * SECTOR..].iter().all(|&b| b == 0),
        "the partial sector untouched"
    );
    for sector in 0..11 {
        let mut one = [0u8; SECTOR];
        c.read(5 + sector, &mut one).unwrap();
        let at = sector as usize * SECTOR;
        assert_eq!(one[..], data[at..at + SECTOR]);
    }
    // A run reaching past the range: the driver refuses the request that does.
    let e = c.write_sectors(28, &data[..8 * SECTOR]).unwrap_err();
    assert_eq!(e, ClientError::Status(Status::OutOfRange));
}

#[test]
fn a_damaged_response_is_an_error_not_data() {
    let mut disk = CachedDisk::default();
    let mut c = Client::new(Loopback {
        disk: &mut disk,
        range: PLC,
        damage: None,
        outcomes: Vec::new(),
    });
    slots::BlockDevice::write(&mut c, 3, &[0x42; SECTOR]).unwrap();
    for at in [0, 5, 9, 13, 100, 400] {
        c.transport.damage = Some(at);
        let mut buf = [0u8; SECTOR];
        let e = slots::BlockDevice::read(&mut c, 3, &mut buf).unwrap_err();
        assert!(
            matches!(e, ClientError::Response(_) | ClientError::Tag { .. }),
            "{at}: {e}"
        );
    }
}

#[test]
fn a_tenant_beyond_its_range_is_refused_by_the_driver() {
    let mut disk = CachedDisk::default();
    let mut c = Client::new(Loopback {
        disk: &mut disk,
        range: PLC,
        damage: None,
        outcomes: Vec::new(),
    });
    let e = slots::BlockDevice::write(&mut c, 32, &[1; SECTOR]).unwrap_err();
    assert_eq!(e, ClientError::Status(Status::OutOfRange));
    assert!(matches!(
        c.transport.outcomes.last(),
        Some(Outcome::Refused(Refusal::OutOfRange(_)))
    ));
    assert!(
        disk.cache.is_empty() && disk.stable.is_empty(),
        "nothing written"
    );
}
