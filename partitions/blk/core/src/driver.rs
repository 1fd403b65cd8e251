//! The driver's answer to one tenant request: [`serve`] plans it ([`crate::virtio_blk::plan`]:
//! decoded, CRC checked, mapped into the tenant's virtual disk), has the device carry it
//! out ([`Device`]: virtio-blk on the hardware, a disk in memory in the tests) and writes
//! the response, CRC and all. One request at a time, so a response is always the answer
//! to the request just taken.

use crate::SECTOR;
use crate::disk::VirtualDisk;
use crate::link::{self, MAX_SECTORS, Operation, Status};
use crate::virtio_blk::{Plan, Refusal};

/// What carries requests out on the disk (whole requests, disk sectors).
pub trait Device {
    /// Reads `out.len() / 512` sectors from `disk_sector`.
    fn read(&mut self, disk_sector: u64, out: &mut [u8]) -> Status;
    /// Writes `data` (whole sectors) at `disk_sector`.
    fn write(&mut self, disk_sector: u64, data: &[u8]) -> Status;
    /// Returns once every completed write is on stable storage.
    fn flush(&mut self) -> Status;
}

/// What became of a request (for the driver's counters and log).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    Done(Operation, Status),
    Refused(Refusal),
}

/// Serves the tenant request `msg` (the tenant's virtual disk `disk`, the device's
/// negotiated `features`); writes the response into `out` (at least
/// [`link::MAX_RESPONSE`] bytes) and returns its length and what happened. A response
/// that does not fit `out` is cut to a status-only one.
pub fn serve(
    msg: &[u8],
    disk: &VirtualDisk,
    features: u64,
    device: &mut impl Device,
    out: &mut [u8],
) -> (usize, Outcome) {
    let mut data = [0u8; MAX_SECTORS as usize * SECTOR];
    let (tag, status, len, outcome) = match crate::virtio_blk::plan(msg, disk, features) {
        Plan::Refuse { tag, status, why } => (tag, status, 0, Outcome::Refused(why)),
        Plan::Device {
            tag,
            operation,
            disk_sector,
            sectors,
            data: written,
        } => {
            let len = sectors as usize * SECTOR;
            let status = match operation {
                Operation::Read => device.read(disk_sector, &mut data[..len]),
                Operation::Write => device.write(disk_sector, written),
                Operation::Flush => device.flush(),
            };
            let len = if operation == Operation::Read && status == Status::Ok {
                len
            } else {
                0
            };
            (tag, status, len, Outcome::Done(operation, status))
        }
    };
    let n = link::encode_response(status, tag, &data[..len], out)
        .or_else(|_| link::encode_response(status, tag, &[], out))
        .unwrap_or(0);
    (n, outcome)
}
