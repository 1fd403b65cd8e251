//! The fields a driver partition's tenant table (its data entry, written by `cargo xtask`
//! from the configuration) is made of, written ([`put_name`], [`put_port`]) and read
//! ([`Reader`]) in one place; each driver's table (`nic_core::tenants`,
//! `blk_core::tenants`) arranges them. Little-endian integers; a name is a length byte and
//! that many UTF-8 bytes (longer names are cut at 255 bytes, which no port or partition
//! name reaches); a port is its name, its message size (4 bytes) and its depth (4 bytes).
//! no_std, no allocation; nothing in the bytes can make the reader panic.
#![no_std]

/// One of the driver partition's queuing ports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PortSpec<'a> {
    pub name: &'a str,
    pub size: u32,
    pub depth: u32,
}

/// Why a field of tenant `n` could not be read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldError {
    /// The bytes end inside tenant `n`.
    Truncated(usize),
    /// A name of tenant `n` is not UTF-8.
    BadName(usize),
}

/// Appends `name` as a length byte and its bytes.
pub fn put_name(out: &mut impl Extend<u8>, name: &str) {
    let bytes = &name.as_bytes()[..name.len().min(255)];
    out.extend([bytes.len() as u8]);
    out.extend(bytes.iter().copied());
}

/// Appends `port`: its name, size and depth.
pub fn put_port(out: &mut impl Extend<u8>, port: PortSpec<'_>) {
    put_name(out, port.name);
    out.extend(port.size.to_le_bytes());
    out.extend(port.depth.to_le_bytes());
}

/// Reads the fields of tenant `tenant` from the front of `rest`.
pub struct Reader<'a> {
    pub rest: &'a [u8],
    pub tenant: usize,
}

impl<'a> Reader<'a> {
    pub fn take(&mut self, n: usize) -> Result<&'a [u8], FieldError> {
        if self.rest.len() < n {
            return Err(FieldError::Truncated(self.tenant));
        }
        let (head, rest) = self.rest.split_at(n);
        self.rest = rest;
        Ok(head)
    }

    pub fn name(&mut self) -> Result<&'a str, FieldError> {
        let len = usize::from(self.take(1)?[0]);
        core::str::from_utf8(self.take(len)?).map_err(|_| FieldError::BadName(self.tenant))
    }

    pub fn u32(&mut self) -> Result<u32, FieldError> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    pub fn u64(&mut self) -> Result<u64, FieldError> {
        let b = self.take(8)?;
        let mut raw = [0u8; 8];
        raw.copy_from_slice(b);
        Ok(u64::from_le_bytes(raw))
    }

    pub fn port(&mut self) -> Result<PortSpec<'a>, FieldError> {
        Ok(PortSpec {
            name: self.name()?,
            size: self.u32()?,
            depth: self.u32()?,
        })
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use std::vec::Vec;

    #[test]
    fn fields_round_trip_and_every_cut_is_truncated() {
        let port = PortSpec {
            name: "plc-blk-req",
            size: 2072,
            depth: 4,
        };
        let mut bytes = Vec::new();
        put_name(&mut bytes, "plc");
        put_port(&mut bytes, port);
        bytes.extend(0x0102_0304_0506_0708u64.to_le_bytes());
        let mut r = Reader {
            rest: &bytes,
            tenant: 3,
        };
        assert_eq!(r.name(), Ok("plc"));
        assert_eq!(r.port(), Ok(port));
        assert_eq!(r.u64(), Ok(0x0102_0304_0506_0708));
        assert!(r.rest.is_empty());
        for cut in 0..bytes.len() {
            let mut r = Reader {
                rest: &bytes[..cut],
                tenant: 3,
            };
            let read = r.name().and_then(|_| r.port()).and_then(|_| r.u64());
            assert_eq!(read, Err(FieldError::Truncated(3)), "cut at {cut}");
        }
        let mut r = Reader {
            rest: &[2, 0xff, 0xfe],
            tenant: 1,
        };
        assert_eq!(r.name(), Err(FieldError::BadName(1)));
    }
}
