//! The link's codec round trips, refuses every damaged message with the reason, and the
//! driver's plan keeps every tenant inside its virtual disk, whatever it sends.

extern crate std;

use super::*;
use crate::disk::VirtualDisk;
use crate::virtio_blk::{self, FEATURE_FLUSH, FEATURE_RO, Plan, Refusal};
use proptest::prelude::*;
use std::format;
use std::vec;
use std::vec::Vec;

const DISK: VirtualDisk = VirtualDisk {
    first_sector: 2048,
    sectors: 64,
};

fn request(operation: Operation, tag: u32, sector: u64, sectors: u32, data: &[u8]) -> Vec<u8> {
    let mut out = vec![0; MAX_REQUEST];
    let n = encode_request(operation, tag, sector, sectors, data, &mut out).unwrap();
    out.truncate(n);
    out
}

#[test]
fn requests_and_responses_round_trip() {
    let data: Vec<u8> = (0..2 * SECTOR).map(|i| i as u8).collect();
    let w = request(Operation::Write, 7, 3, 2, &data);
    assert_eq!(w.len(), REQUEST_HEADER + 1024);
    assert_eq!(
        decode_request(&w),
        Ok(Request {
            operation: Operation::Write,
            tag: 7,
            sector: 3,
            sectors: 2,
            data: &data
        })
    );
    let r = request(Operation::Read, 8, 63, 1, &[]);
    assert_eq!(r.len(), REQUEST_HEADER);
    assert_eq!(decode_request(&r).unwrap().sectors, 1);
    let f = request(Operation::Flush, 9, 0, 0, &[]);
    assert_eq!(decode_request(&f).unwrap().operation, Operation::Flush);

    let mut out = [0; MAX_RESPONSE];
    let n = encode_response(Status::Ok, 8, &data, &mut out).unwrap();
    assert_eq!(
        decode_response(&out[..n]),
        Ok(Response {
            status: Status::Ok,
            tag: 8,
            data: &data
        })
    );
    let n = encode_response(Status::OutOfRange, 9, &[], &mut out).unwrap();
    assert_eq!(
        decode_response(&out[..n]).unwrap().status,
        Status::OutOfRange
    );
}

#[test]
fn encoding_refuses_what_the_link_cannot_carry() {
    let mut out = [0; MAX_REQUEST];
    let e = |op, sectors, data: &[u8], out: &mut [u8]| {
        encode_request(op, 1, 0, sectors, data, out).unwrap_err()
    };
    assert_eq!(e(Operation::Read, 0, &[], &mut out), LinkError::BadCount(0));
    assert_eq!(e(Operation::Read, 5, &[], &mut out), LinkError::BadCount(5));
    assert_eq!(
        e(Operation::Flush, 1, &[], &mut out),
        LinkError::BadCount(1)
    );
    assert_eq!(
        e(Operation::Write, 1, &[0; 100], &mut out),
        LinkError::Buffer
    );
    assert_eq!(
        e(Operation::Write, 1, &[0; 512], &mut out[..100]),
        LinkError::Buffer
    );
    assert_eq!(
        encode_response(Status::Ok, 1, &[0; 100], &mut out),
        Err(LinkError::Buffer)
    );
}

#[test]
fn damaged_requests_are_refused_with_the_reason() {
    let w = request(Operation::Write, 7, 3, 1, &[0x5a; SECTOR]);
    assert_eq!(decode_request(&w[..10]), Err(LinkError::Short(10)));
    assert_eq!(
        decode_request(&w[..w.len() - 1]),
        Err(LinkError::Length {
            expected: REQUEST_HEADER + SECTOR,
            got: REQUEST_HEADER + SECTOR - 1
        })
    );
    let mut bad = w.clone();
    bad[REQUEST_HEADER + 100] ^= 1;
    let e = decode_request(&bad).unwrap_err();
    assert!(matches!(e, LinkError::Crc { .. }), "{e}");
    assert!(format!("{e}").contains("damaged"));
    let mut bad = w.clone();
    bad[0] = 9;
    assert_eq!(decode_request(&bad), Err(LinkError::UnknownOperation(9)));
    let mut bad = w.clone();
    bad[2] = 1;
    assert_eq!(decode_request(&bad), Err(LinkError::Reserved));
    let mut bad = w;
    bad[16] = 200;
    assert_eq!(decode_request(&bad), Err(LinkError::BadCount(200)));
}

#[test]
fn the_plan_maps_into_the_tenants_range_and_refuses_the_rest() {
    let all = FEATURE_FLUSH;
    let data = [1u8; SECTOR];
    let w = request(Operation::Write, 1, 63, 1, &data);
    assert_eq!(
        virtio_blk::plan(&w, &DISK, all),
        Plan::Device {
            tag: 1,
            operation: Operation::Write,
            disk_sector: 2048 + 63,
            sectors: 1,
            data: &data
        }
    );
    let past = request(Operation::Read, 2, 63, 2, &[]);
    assert!(matches!(
        virtio_blk::plan(&past, &DISK, all),
        Plan::Refuse {
            tag: 2,
            status: Status::OutOfRange,
            why: Refusal::OutOfRange(_)
        }
    ));
    let far = request(Operation::Read, 3, u64::MAX, 4, &[]);
    assert!(matches!(
        virtio_blk::plan(&far, &DISK, all),
        Plan::Refuse {
            status: Status::OutOfRange,
            ..
        }
    ));
    assert!(matches!(
        virtio_blk::plan(&w, &DISK, all | FEATURE_RO),
        Plan::Refuse {
            why: Refusal::ReadOnly,
            ..
        }
    ));
    let f = request(Operation::Flush, 4, 0, 0, &[]);
    assert!(matches!(
        virtio_blk::plan(&f, &DISK, all),
        Plan::Device {
            operation: Operation::Flush,
            ..
        }
    ));
    assert!(matches!(
        virtio_blk::plan(&f, &DISK, 0),
        Plan::Refuse {
            status: Status::Unsupported,
            why: Refusal::NoFlush,
            ..
        }
    ));
    let mut damaged = w.clone();
    damaged[30] ^= 0x80;
    assert!(matches!(
        virtio_blk::plan(&damaged, &DISK, all),
        Plan::Refuse {
            tag: 1,
            status: Status::BadRequest,
            why: Refusal::Malformed(LinkError::Crc { .. })
        }
    ));
    assert!(matches!(
        virtio_blk::plan(&[1, 2], &DISK, all),
        Plan::Refuse { tag: 0, .. }
    ));
}

#[test]
fn the_virtio_blk_header_and_status() {
    let h = virtio_blk::header(Operation::Write, 0x0102_0304_0506);
    assert_eq!(&h[..4], &1u32.to_le_bytes());
    assert_eq!(&h[4..8], &[0; 4]);
    assert_eq!(&h[8..], &0x0102_0304_0506u64.to_le_bytes());
    assert_eq!(
        &virtio_blk::header(Operation::Flush, 0)[..4],
        &4u32.to_le_bytes()
    );
    assert_eq!(
        &virtio_blk::header(Operation::Read, 9)[..4],
        &0u32.to_le_bytes()
    );
    assert_eq!(virtio_blk::status(0), Status::Ok);
    assert_eq!(virtio_blk::status(1), Status::IoError);
    assert_eq!(virtio_blk::status(2), Status::Unsupported);
    assert_eq!(
        virtio_blk::status(0xff),
        Status::IoError,
        "a hostile device"
    );
}

proptest! {
    /// Random bytes from a tenant never panic the driver, and whatever it plans for the
    /// device lies inside the tenant's range.
    #[test]
    fn hostile_requests_stay_inside_the_range(
        msg in proptest::collection::vec(any::<u8>(), 0..MAX_REQUEST + 8),
    ) {
        if let Plan::Device { disk_sector, sectors, operation, .. } =
            virtio_blk::plan(&msg, &DISK, FEATURE_FLUSH)
            && operation != Operation::Flush
        {
            prop_assert!(disk_sector >= DISK.first_sector);
            prop_assert!(disk_sector + u64::from(sectors) <= DISK.end().unwrap());
        }
        let _ = decode_response(&msg);
    }

    /// A well-formed request with a random address and count, its CRC right: the driver
    /// sends it to the device only when it is wholly inside the range.
    #[test]
    fn well_formed_requests_with_any_address(
        sector in any::<u64>(), sectors in 1..=MAX_SECTORS, write in any::<bool>(),
    ) {
        let data = vec![0u8; sectors as usize * SECTOR];
        let msg = if write {
            request(Operation::Write, 5, sector, sectors, &data)
        } else {
            request(Operation::Read, 5, sector, sectors, &[])
        };
        let inside = sector.checked_add(u64::from(sectors)).is_some_and(|e| e <= DISK.sectors);
        match virtio_blk::plan(&msg, &DISK, FEATURE_FLUSH) {
            Plan::Device { disk_sector, .. } => {
                prop_assert!(inside);
                prop_assert_eq!(disk_sector, DISK.first_sector + sector);
            }
            Plan::Refuse { status, .. } => {
                prop_assert!(!inside);
                prop_assert_eq!(status, Status::OutOfRange);
            }
        }
    }

    /// Every single-bit flip of a request or a response is caught.
    #[test]
    fn every_bit_flip_is_caught(bit in 0..(REQUEST_HEADER + SECTOR) * 8) {
        let w = request(Operation::Write, 5, 1, 1, &[0x33; SECTOR]);
        let mut bad = w.clone();
        bad[bit / 8] ^= 1 << (bit % 8);
        prop_assert!(decode_request(&bad).is_err());
        let mut out = [0; MAX_RESPONSE];
        let n = encode_response(Status::Ok, 5, &[0x44; SECTOR], &mut out).unwrap();
        let bit = bit % (n * 8);
        out[bit / 8] ^= 1 << (bit % 8);
        prop_assert!(decode_response(&out[..n]).is_err());
    }
}
