//! The request link between a tenant and the block-device partition: one request a
//! message on the tenant's `from` port, one response a message on its `to` port, in the
//! order of the requests. Every message carries a CRC-32 over its header and data, so a
//! request damaged between the tenant and the driver is never written, and a response
//! damaged on the way back is never taken for data. An interface (docs/interfaces.md).
//!
//! Request, little-endian:
//!
//! | offset | field |
//! |---|---|
//! | 0 | operation `u8`: 1 read, 2 write, 3 flush |
//! | 1 | zero (3 bytes) |
//! | 4 | tag `u32` (the tenant's; copied into the response) |
//! | 8 | first sector `u64` (of the tenant's virtual disk) |
//! | 16 | sectors `u32` (1..=[`MAX_SECTORS`] for read and write, 0 for flush) |
//! | 20 | CRC-32 `u32` of bytes 0..20 and the data |
//! | 24 | data: `sectors * 512` bytes for a write, nothing otherwise |
//!
//! Response:
//!
//! | offset | field |
//! |---|---|
//! | 0 | status `u8` ([`Status`]) |
//! | 1 | zero (3 bytes) |
//! | 4 | tag `u32` |
//! | 8 | sectors `u32` of data that follow (a successful read's; 0 otherwise) |
//! | 12 | CRC-32 `u32` of bytes 0..12 and the data |
//! | 16 | data |
//!
//! A flush answers once every write the device completed before it is on stable storage.

use crate::SECTOR;
use abi::crc32::Crc32;

/// Most sectors one request reads or writes (a message of 24 + 2048 bytes).
pub const MAX_SECTORS: u32 = 4;
pub const REQUEST_HEADER: usize = 24;
pub const RESPONSE_HEADER: usize = 16;
/// The largest request and response: the ports' message size must be at least this.
pub const MAX_REQUEST: usize = REQUEST_HEADER + MAX_SECTORS as usize * SECTOR;
pub const MAX_RESPONSE: usize = RESPONSE_HEADER + MAX_SECTORS as usize * SECTOR;

/// What a request asks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Operation {
    Read,
    Write,
    Flush,
}

impl Operation {
    fn code(self) -> u8 {
        match self {
            Self::Read => 1,
            Self::Write => 2,
            Self::Flush => 3,
        }
    }
}

/// A request as the driver decoded it (`data` a write's, borrowed from the message).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Request<'a> {
    pub operation: Operation,
    pub tag: u32,
    pub sector: u64,
    pub sectors: u32,
    pub data: &'a [u8],
}

/// A response's status.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    Ok,
    /// The device failed the request.
    IoError,
    /// The device does not do it (a flush without VIRTIO_BLK_F_FLUSH).
    Unsupported,
    /// It reaches outside the tenant's virtual disk (checked by the driver).
    OutOfRange,
    /// The request was malformed or its CRC did not match: nothing was done.
    BadRequest,
}

impl Status {
    pub fn code(self) -> u8 {
        match self {
            Self::Ok => 0,
            Self::IoError => 1,
            Self::Unsupported => 2,
            Self::OutOfRange => 3,
            Self::BadRequest => 4,
        }
    }

    pub fn from_code(code: u8) -> Option<Status> {
        Some(match code {
            0 => Self::Ok,
            1 => Self::IoError,
            2 => Self::Unsupported,
            3 => Self::OutOfRange,
            4 => Self::BadRequest,
            _ => return None,
        })
    }
}

/// Why a message is not a request or a response.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkError {
    /// Shorter than its header.
    Short(usize),
    UnknownOperation(u8),
    UnknownStatus(u8),
    /// Nonzero reserved bytes.
    Reserved,
    /// A read or write of 0 or more than [`MAX_SECTORS`] sectors, or a flush of some.
    BadCount(u32),
    /// The message's length is not its header plus its data.
    Length {
        expected: usize,
        got: usize,
    },
    /// The CRC does not match: damaged on the way.
    Crc {
        expected: u32,
        got: u32,
    },
    /// The output buffer is too small, or the data is not whole sectors (encoding).
    Buffer,
}

impl core::fmt::Display for LinkError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Short(n) => write!(f, "{n} bytes, shorter than a header"),
            Self::UnknownOperation(op) => write!(f, "unknown operation {op}"),
            Self::UnknownStatus(s) => write!(f, "unknown status {s}"),
            Self::Reserved => write!(f, "reserved bytes are not zero"),
            Self::BadCount(n) => write!(
                f,
                "{n} sectors (1..={MAX_SECTORS} to read or write, 0 to flush)"
            ),
            Self::Length { expected, got } => {
                write!(f, "{got} bytes where header and data make {expected}")
            }
            Self::Crc { expected, got } => write!(
                f,
                "CRC-32 {got:#010x} where the message has {expected:#010x} (damaged)"
            ),
            Self::Buffer => write!(f, "no room for the message, or data not whole sectors"),
        }
    }
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    let mut w = [0; 4];
    w.copy_from_slice(&b[at..at + 4]);
    u32::from_le_bytes(w)
}

fn crc(header: &[u8], data: &[u8]) -> u32 {
    let mut c = Crc32::new();
    c.update(header);
    c.update(data);
    c.finish()
}

/// The data bytes a request of `sectors` carries, after checking the count.
fn request_data(operation: Operation, sectors: u32) -> Result<usize, LinkError> {
    let ok = match operation {
        Operation::Flush => sectors == 0,
        _ => (1..=MAX_SECTORS).contains(&sectors),
    };
    if !ok {
        return Err(LinkError::BadCount(sectors));
    }
    Ok(match operation {
        Operation::Write => sectors as usize * SECTOR,
        _ => 0,
    })
}

/// Writes a request into `out` (tenant side); its length. `data` is a write's (whole
/// sectors); for a read, `sectors` says how many; a flush has neither.
pub fn encode_request(
    operation: Operation,
    tag: u32,
    sector: u64,
    sectors: u32,
    data: &[u8],
    out: &mut [u8],
) -> Result<usize, LinkError> {
    let len = request_data(operation, sectors)?;
    if data.len() != len {
        return Err(LinkError::Buffer);
    }
    let out = out
        .get_mut(..REQUEST_HEADER + len)
        .ok_or(LinkError::Buffer)?;
    out[..4].copy_from_slice(&[operation.code(), 0, 0, 0]);
    out[4..8].copy_from_slice(&tag.to_le_bytes());
    out[8..16].copy_from_slice(&sector.to_le_bytes());
    out[16..20].copy_from_slice(&sectors.to_le_bytes());
    let c = crc(&out[..20], data);
    out[20..24].copy_from_slice(&c.to_le_bytes());
    out[24..].copy_from_slice(data);
    Ok(out.len())
}

/// The request in `msg` (driver side), checked whole: header, count, length, CRC.
pub fn decode_request(msg: &[u8]) -> Result<Request<'_>, LinkError> {
    if msg.len() < REQUEST_HEADER {
        return Err(LinkError::Short(msg.len()));
    }
    let operation = match msg[0] {
        1 => Operation::Read,
        2 => Operation::Write,
        3 => Operation::Flush,
        op => return Err(LinkError::UnknownOperation(op)),
    };
    if msg[1..4] != [0; 3] {
        return Err(LinkError::Reserved);
    }
    let sectors = u32_at(msg, 16);
    let expected = REQUEST_HEADER + request_data(operation, sectors)?;
    if msg.len() != expected {
        return Err(LinkError::Length {
            expected,
            got: msg.len(),
        });
    }
    let data = &msg[REQUEST_HEADER..];
    let (stored, computed) = (u32_at(msg, 20), crc(&msg[..20], data));
    if stored != computed {
        return Err(LinkError::Crc {
            expected: stored,
            got: computed,
        });
    }
    let mut sector = [0; 8];
    sector.copy_from_slice(&msg[8..16]);
    Ok(Request {
        operation,
        tag: u32_at(msg, 4),
        sector: u64::from_le_bytes(sector),
        sectors,
        data,
    })
}

/// A response as the tenant decoded it (`data` a read's).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Response<'a> {
    pub status: Status,
    pub tag: u32,
    pub data: &'a [u8],
}

/// Writes a response into `out` (driver side); its length. `data`: a successful read's
/// (whole sectors, at most [`MAX_SECTORS`]), else empty.
pub fn encode_response(
    status: Status,
    tag: u32,
    data: &[u8],
    out: &mut [u8],
) -> Result<usize, LinkError> {
    if !data.len().is_multiple_of(SECTOR) || data.len() > MAX_SECTORS as usize * SECTOR {
        return Err(LinkError::Buffer);
    }
    let out = out
        .get_mut(..RESPONSE_HEADER + data.len())
        .ok_or(LinkError::Buffer)?;
    out[..4].copy_from_slice(&[status.code(), 0, 0, 0]);
    out[4..8].copy_from_slice(&tag.to_le_bytes());
    out[8..12].copy_from_slice(&((data.len() / SECTOR) as u32).to_le_bytes());
    let c = crc(&out[..12], data);
    out[12..16].copy_from_slice(&c.to_le_bytes());
    out[16..].copy_from_slice(data);
    Ok(out.len())
}

/// The response in `msg` (tenant side), checked whole.
pub fn decode_response(msg: &[u8]) -> Result<Response<'_>, LinkError> {
    if msg.len() < RESPONSE_HEADER {
        return Err(LinkError::Short(msg.len()));
    }
    let status = Status::from_code(msg[0]).ok_or(LinkError::UnknownStatus(msg[0]))?;
    if msg[1..4] != [0; 3] {
        return Err(LinkError::Reserved);
    }
    let sectors = u32_at(msg, 8);
    if sectors > MAX_SECTORS {
        return Err(LinkError::BadCount(sectors));
    }
    let expected = RESPONSE_HEADER + sectors as usize * SECTOR;
    if msg.len() != expected {
        return Err(LinkError::Length {
            expected,
            got: msg.len(),
        });
    }
    let data = &msg[RESPONSE_HEADER..];
    let (stored, computed) = (u32_at(msg, 12), crc(&msg[..12], data));
    if stored != computed {
        return Err(LinkError::Crc {
            expected: stored,
            got: computed,
        });
    }
    Ok(Response {
        status,
        tag: u32_at(msg, 4),
        data,
    })
}

#[cfg(test)]
mod tests;
