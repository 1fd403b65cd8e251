//! virtio-blk (virtio 1.x, 5.2) on the shared transport and queue (the `virtio` crate):
//! the features the driver takes, the request header the device reads first and the
//! status byte it writes last, and what the driver asks of the device for a tenant's
//! request ([`plan`]: its link message decoded and checked against its virtual disk).
//! A request is one descriptor chain: header (16 bytes, device reads), data (device
//! reads for a write, writes for a read; none for a flush), status (1 byte, device writes).

use crate::disk::VirtualDisk;
use crate::link::{self, LinkError, Operation, Status};

/// VIRTIO_BLK_F_RO: the disk is read-only (the driver then refuses writes).
pub const FEATURE_RO: u64 = 1 << 5;
/// VIRTIO_BLK_F_FLUSH: the device has a write-back cache and honours flush requests
/// (QEMU's `cache=writeback`). Without it a flush answers [`Status::Unsupported`].
pub const FEATURE_FLUSH: u64 = 1 << 9;
/// The device features the driver takes when offered.
pub const DRIVER_FEATURES: u64 = FEATURE_RO | FEATURE_FLUSH;

/// The request header's bytes.
pub const HEADER: usize = 16;
/// The device configuration's capacity (`u64`, sectors of 512 bytes) offset.
pub const CONFIG_CAPACITY: u32 = 0;

const TYPE_IN: u32 = 0;
const TYPE_OUT: u32 = 1;
const TYPE_FLUSH: u32 = 4;

/// The header of a request of `operation` at `disk_sector` (0 for a flush).
pub fn header(operation: Operation, disk_sector: u64) -> [u8; HEADER] {
    let kind = match operation {
        Operation::Read => TYPE_IN,
        Operation::Write => TYPE_OUT,
        Operation::Flush => TYPE_FLUSH,
    };
    let mut h = [0u8; HEADER];
    h[..4].copy_from_slice(&kind.to_le_bytes());
    h[8..].copy_from_slice(&disk_sector.to_le_bytes());
    h
}

/// The link status of the device's status byte (anything but OK and UNSUPP is an error).
pub fn status(byte: u8) -> Status {
    match byte {
        0 => Status::Ok,
        2 => Status::Unsupported,
        _ => Status::IoError,
    }
}

/// What the driver does with a tenant's message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plan<'a> {
    /// Send the device this request.
    Device {
        tag: u32,
        operation: Operation,
        disk_sector: u64,
        sectors: u32,
        /// A write's data.
        data: &'a [u8],
    },
    /// Answer at once with `status`: the device never sees it.
    Refuse {
        tag: u32,
        status: Status,
        why: Refusal,
    },
}

/// Why a request was refused (for the driver's counters and log).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    Malformed(LinkError),
    OutOfRange(crate::disk::OutOfRange),
    ReadOnly,
    NoFlush,
}

/// The plan for `msg` from a tenant whose virtual disk is `disk`, on a device with the
/// negotiated `features`. A malformed message is answered with the tag it seems to carry
/// (0 if too short to have one), so the tenant can match it.
pub fn plan<'a>(msg: &'a [u8], disk: &VirtualDisk, features: u64) -> Plan<'a> {
    let request = match link::decode_request(msg) {
        Ok(r) => r,
        Err(e) => {
            let tag = msg
                .get(4..8)
                .map_or(0, |t| u32::from_le_bytes([t[0], t[1], t[2], t[3]]));
            return Plan::Refuse {
                tag,
                status: Status::BadRequest,
                why: Refusal::Malformed(e),
            };
        }
    };
    let refuse = |status, why| Plan::Refuse {
        tag: request.tag,
        status,
        why,
    };
    let disk_sector = match request.operation {
        Operation::Flush => 0,
        _ => match disk.map(request.sector, request.sectors) {
            Ok(at) => at,
            Err(e) => return refuse(Status::OutOfRange, Refusal::OutOfRange(e)),
        },
    };
    match request.operation {
        Operation::Write if features & FEATURE_RO != 0 => {
            return refuse(Status::IoError, Refusal::ReadOnly);
        }
        Operation::Flush if features & FEATURE_FLUSH == 0 => {
            return refuse(Status::Unsupported, Refusal::NoFlush);
        }
        _ => {}
    }
    Plan::Device {
        tag: request.tag,
        operation: request.operation,
        disk_sector,
        sectors: request.sectors,
        data: request.data,
    }
}
