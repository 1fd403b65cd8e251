//! The NIC partition's tenant table: which partitions are attached to the switch, with
//! which MAC, over which of the NIC partition's queuing ports (`nic.tenants.<partition>`,
//! validated by the configuration tools). `cargo xtask` writes it as the partition's data
//! entry ([`encode`]); the partition reads it at start ([`decode`]).
//!
//! Format (little-endian): `NIC2`, a tenant count (1 byte, at most
//! [`crate::switch::MAX_TENANTS`]), then per tenant: its MAC (6 bytes), the partition's
//! name, the `from` port (the NIC's queuing input carrying the tenant's frames) and the
//! `to` port (the NIC's queuing output to the tenant), a port being its name, its message
//! size (4 bytes) and depth (4 bytes); a name is a length byte and that many UTF-8 bytes
//! (the fields of `driver_table`); then its frame ring's segment, address and size (8
//! bytes each, both 0 without one: `nic.tenants.<p>.ring`; the ports then carry only the
//! wake-ups of `frame_ring`).

use crate::switch::{MAX_TENANTS, Mac};
pub use driver_table::PortSpec;
use driver_table::{FieldError, Reader};

const MAGIC: &[u8; 4] = b"NIC2";

/// An attached tenant.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tenant<'a> {
    pub partition: &'a str,
    pub mac: Mac,
    pub from: PortSpec<'a>,
    pub to: PortSpec<'a>,
    /// The frame ring's segment in the partitions' address spaces, if any.
    pub ring: Option<RingSpec>,
}

/// Where a tenant's frame ring is: the same address in both partitions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RingSpec {
    pub address: u64,
    pub size: u64,
}

/// The decoded table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Table<'a> {
    tenants: [Option<Tenant<'a>>; MAX_TENANTS],
    count: usize,
}

impl<'a> Table<'a> {
    pub fn tenants(&self) -> impl Iterator<Item = &Tenant<'a>> {
        self.tenants[..self.count].iter().flatten()
    }

    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
}

/// Why a data entry is not a tenant table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecodeError {
    NoMagic,
    TooMany(usize),
    /// Ends inside tenant `n`.
    Truncated(usize),
    /// A name of tenant `n` is not UTF-8.
    BadName(usize),
    /// Bytes after the last tenant.
    Trailing,
}

impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NoMagic => write!(f, "not a tenant table (no NIC1 header)"),
            Self::TooMany(n) => write!(f, "{n} tenants, at most {MAX_TENANTS}"),
            Self::Truncated(n) => write!(f, "truncated in tenant {n}"),
            Self::BadName(n) => write!(f, "a name of tenant {n} is not UTF-8"),
            Self::Trailing => write!(f, "bytes after the last tenant"),
        }
    }
}

/// Appends the table of `tenants` to `out` (names longer than 255 bytes are cut; the
/// configuration's names are far shorter).
pub fn encode(tenants: &[Tenant<'_>], out: &mut impl Extend<u8>) {
    out.extend(MAGIC.iter().copied());
    out.extend([tenants.len().min(MAX_TENANTS) as u8]);
    for t in tenants.iter().take(MAX_TENANTS) {
        out.extend(t.mac.0);
        driver_table::put_name(out, t.partition);
        driver_table::put_port(out, t.from);
        driver_table::put_port(out, t.to);
        let ring = t.ring.map_or([0, 0], |r| [r.address, r.size]);
        out.extend(ring.iter().flat_map(|v| v.to_le_bytes()));
    }
}

impl From<FieldError> for DecodeError {
    fn from(e: FieldError) -> Self {
        match e {
            FieldError::Truncated(n) => Self::Truncated(n),
            FieldError::BadName(n) => Self::BadName(n),
        }
    }
}

/// The table in `bytes`.
pub fn decode(bytes: &[u8]) -> Result<Table<'_>, DecodeError> {
    let rest = bytes.strip_prefix(MAGIC).ok_or(DecodeError::NoMagic)?;
    let (&count, mut rest) = rest.split_first().ok_or(DecodeError::NoMagic)?;
    let count = usize::from(count);
    if count > MAX_TENANTS {
        return Err(DecodeError::TooMany(count));
    }
    let mut table = Table {
        tenants: [None; MAX_TENANTS],
        count,
    };
    for (n, slot) in table.tenants.iter_mut().take(count).enumerate() {
        let mut r = Reader { rest, tenant: n };
        let mut mac = [0u8; 6];
        mac.copy_from_slice(r.take(6)?);
        let partition = r.name()?;
        let from = r.port()?;
        let to = r.port()?;
        let (address, size) = (r.u64()?, r.u64()?);
        *slot = Some(Tenant {
            partition,
            mac: Mac(mac),
            from,
            to,
            ring: (size != 0).then_some(RingSpec { address, size }),
        });
        rest = r.rest;
    }
    if !rest.is_empty() {
        return Err(DecodeError::Trailing);
    }
    Ok(table)
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use proptest::prelude::*;
    use std::vec::Vec;

    fn sample() -> Vec<u8> {
        let port = |name, depth| PortSpec {
            name,
            size: 1514,
            depth,
        };
        let mut out = Vec::new();
        encode(
            &[
                Tenant {
                    partition: "linux",
                    mac: Mac([0x52, 0x54, 0, 0x12, 0x34, 0x56]),
                    from: port("linux-tx", 32),
                    to: port("linux-rx", 32),
                    ring: Some(RingSpec {
                        address: 0x6000_0000_0000,
                        size: 65536,
                    }),
                },
                Tenant {
                    partition: "plc",
                    mac: Mac([2, 0, 0, 0, 0, 1]),
                    from: port("plc-tx", 8),
                    to: port("plc-rx", 16),
                    ring: None,
                },
            ],
            &mut out,
        );
        out
    }

    #[test]
    fn the_table_round_trips() {
        let bytes = sample();
        let table = decode(&bytes).unwrap();
        assert_eq!(table.len(), 2);
        let names: Vec<(&str, &str, &str, u32)> = table
            .tenants()
            .map(|t| (t.partition, t.from.name, t.to.name, t.to.depth))
            .collect();
        assert_eq!(
            names,
            [
                ("linux", "linux-tx", "linux-rx", 32),
                ("plc", "plc-tx", "plc-rx", 16)
            ]
        );
        assert_eq!(table.tenants().nth(1).unwrap().mac, Mac([2, 0, 0, 0, 0, 1]));
        let rings: Vec<_> = table.tenants().map(|t| t.ring.map(|r| r.size)).collect();
        assert_eq!(rings, [Some(65536), None]);
    }

    #[test]
    fn damaged_tables_are_refused_with_the_reason() {
        let bytes = sample();
        assert_eq!(decode(b"NIC1\x00"), Err(DecodeError::NoMagic));
        assert_eq!(decode(b"NIC2\x10"), Err(DecodeError::TooMany(16)));
        assert_eq!(decode(&bytes[..20]), Err(DecodeError::Truncated(0)));
        assert_eq!(
            decode(&bytes[..bytes.len() - 1]),
            Err(DecodeError::Truncated(1))
        );
        let mut long = bytes.clone();
        long.push(0);
        assert_eq!(decode(&long), Err(DecodeError::Trailing));
        let mut bad = bytes.clone();
        bad[12] = 0xff;
        assert_eq!(decode(&bad), Err(DecodeError::BadName(0)));
    }

    proptest! {
        #[test]
        fn random_entries_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
            let mut with_magic = MAGIC.to_vec();
            with_magic.extend_from_slice(&bytes);
            let _ = decode(&bytes);
            let _ = decode(&with_magic);
        }
    }
}
