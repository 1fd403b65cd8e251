//! The block-device partition's tenant table: which partitions have a virtual disk, which
//! sectors of the disk it is, and over which of the partition's queuing ports its requests
//! come and its responses go (`blk.tenants.<partition>`). `cargo xtask` writes it as the
//! partition's data entry ([`encode`]); the partition reads it at start ([`decode`]) and
//! checks it against the disk's capacity ([`Table::check`]).
//!
//! Format (little-endian): `BLK1`, a tenant count (1 byte, at most [`MAX_TENANTS`]),
//! then per tenant: the partition's name, the `from` port (the partition's queuing input
//! carrying the tenant's requests), the `to` port (its queuing output to the tenant), a
//! port being its name, its message size (4 bytes) and depth (4 bytes), then the first
//! sector (8 bytes) and the sectors (8 bytes) of the virtual disk; a name is a length
//! byte and that many UTF-8 bytes (the fields of `driver_table`).

use crate::disk::VirtualDisk;
pub use driver_table::PortSpec;
use driver_table::{FieldError, Reader};

const MAGIC: &[u8; 4] = b"BLK1";
/// Most tenants a block-device partition serves.
pub const MAX_TENANTS: usize = 8;

/// A tenant and its virtual disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tenant<'a> {
    pub partition: &'a str,
    pub from: PortSpec<'a>,
    pub to: PortSpec<'a>,
    pub disk: VirtualDisk,
}

/// The decoded table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Table<'a> {
    tenants: [Option<Tenant<'a>>; MAX_TENANTS],
    count: usize,
}

/// Why a data entry is not a tenant table, or a table does not fit the disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TableError {
    NoMagic,
    TooMany(usize),
    /// Ends inside tenant `n`.
    Truncated(usize),
    /// A name of tenant `n` is not UTF-8.
    BadName(usize),
    /// Bytes after the last tenant.
    Trailing,
    /// Tenant `n`'s virtual disk has no sectors.
    Empty(usize),
    /// Tenants `a` and `b` share sectors.
    Overlap(usize, usize),
    /// Tenant `n`'s virtual disk ends past the disk's `capacity` sectors.
    Outside {
        tenant: usize,
        capacity: u64,
    },
}

impl core::fmt::Display for TableError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NoMagic => write!(f, "not a tenant table (no BLK1 header)"),
            Self::TooMany(n) => write!(f, "{n} tenants, at most {MAX_TENANTS}"),
            Self::Truncated(n) => write!(f, "truncated in tenant {n}"),
            Self::BadName(n) => write!(f, "a name of tenant {n} is not UTF-8"),
            Self::Trailing => write!(f, "bytes after the last tenant"),
            Self::Empty(n) => write!(f, "tenant {n}'s virtual disk has no sectors"),
            Self::Overlap(a, b) => write!(f, "the virtual disks of tenants {a} and {b} overlap"),
            Self::Outside { tenant, capacity } => write!(
                f,
                "tenant {tenant}'s virtual disk ends past the disk's {capacity} sectors"
            ),
        }
    }
}

impl From<FieldError> for TableError {
    fn from(e: FieldError) -> Self {
        match e {
            FieldError::Truncated(n) => Self::Truncated(n),
            FieldError::BadName(n) => Self::BadName(n),
        }
    }
}

impl<'a> Table<'a> {
    pub fn tenants(&self) -> impl Iterator<Item = &Tenant<'a>> + Clone {
        self.tenants[..self.count].iter().flatten()
    }

    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Every virtual disk has sectors, lies inside a disk of `capacity` sectors, and
    /// shares none with another's.
    pub fn check(&self, capacity: u64) -> Result<(), TableError> {
        check_disks(self.tenants().map(|t| t.disk), capacity)
    }
}

/// The checks of [`Table::check`] on a list of virtual disks (the configuration tools
/// run them without a capacity: `u64::MAX`).
pub fn check_disks(
    disks: impl Iterator<Item = VirtualDisk> + Clone,
    capacity: u64,
) -> Result<(), TableError> {
    for (i, d) in disks.clone().enumerate() {
        if d.sectors == 0 {
            return Err(TableError::Empty(i));
        }
        if d.end().is_none_or(|end| end > capacity) {
            return Err(TableError::Outside {
                tenant: i,
                capacity,
            });
        }
        if let Some(j) = disks.clone().take(i).position(|o| o.overlaps(&d)) {
            return Err(TableError::Overlap(j, i));
        }
    }
    Ok(())
}

/// Appends the table of `tenants` to `out` (names longer than 255 bytes are cut; the
/// configuration's names are far shorter).
#[cfg(any(test, feature = "host"))]
pub fn encode(tenants: &[Tenant<'_>], out: &mut impl Extend<u8>) {
    out.extend(MAGIC.iter().copied());
    out.extend([tenants.len().min(255) as u8]);
    for t in tenants {
        driver_table::put_name(out, t.partition);
        driver_table::put_port(out, t.from);
        driver_table::put_port(out, t.to);
        out.extend(t.disk.first_sector.to_le_bytes());
        out.extend(t.disk.sectors.to_le_bytes());
    }
}

/// The table in `entry`, checked whole (not yet against the disk: [`Table::check`]).
pub fn decode(entry: &[u8]) -> Result<Table<'_>, TableError> {
    let rest = entry.strip_prefix(MAGIC).ok_or(TableError::NoMagic)?;
    let (&count, mut rest) = rest.split_first().ok_or(TableError::Truncated(0))?;
    let count = usize::from(count);
    if count > MAX_TENANTS {
        return Err(TableError::TooMany(count));
    }
    let mut table = Table {
        tenants: [None; MAX_TENANTS],
        count,
    };
    for (n, slot) in table.tenants[..count].iter_mut().enumerate() {
        let mut r = Reader { rest, tenant: n };
        let partition = r.name()?;
        let from = r.port()?;
        let to = r.port()?;
        let disk = VirtualDisk {
            first_sector: r.u64()?,
            sectors: r.u64()?,
        };
        *slot = Some(Tenant {
            partition,
            from,
            to,
            disk,
        });
        rest = r.rest;
    }
    if !rest.is_empty() {
        return Err(TableError::Trailing);
    }
    Ok(table)
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use proptest::prelude::*;
    use std::format;
    use std::vec::Vec;

    fn tenant(partition: &str, first_sector: u64, sectors: u64) -> Tenant<'_> {
        Tenant {
            partition,
            from: PortSpec {
                name: "plc-blk-req",
                size: 2072,
                depth: 4,
            },
            to: PortSpec {
                name: "plc-blk-resp",
                size: 2064,
                depth: 4,
            },
            disk: VirtualDisk {
                first_sector,
                sectors,
            },
        }
    }

    #[test]
    fn the_table_round_trips_and_checks_against_the_disk() {
        let tenants = [tenant("plc", 2048, 4096), tenant("linux", 8192, 65536)];
        let mut entry = Vec::new();
        encode(&tenants, &mut entry);
        let table = decode(&entry).unwrap();
        assert_eq!(table.tenants().copied().collect::<Vec<_>>(), tenants);
        assert_eq!(table.check(8192 + 65536), Ok(()));
        let e = table.check(8192 + 65535).unwrap_err();
        assert_eq!(
            e,
            TableError::Outside {
                tenant: 1,
                capacity: 73727
            }
        );
        assert!(format!("{e}").contains("ends past the disk's 73727 sectors"));
    }

    #[test]
    fn overlapping_or_empty_disks_are_refused() {
        let check = |t: &[Tenant<'_>]| check_disks(t.iter().map(|t| t.disk), u64::MAX);
        assert_eq!(
            check(&[tenant("a", 0, 10), tenant("b", 10, 10), tenant("c", 19, 2)]),
            Err(TableError::Overlap(1, 2))
        );
        assert_eq!(check(&[tenant("a", 0, 0)]), Err(TableError::Empty(0)));
        assert!(matches!(
            check(&[tenant("a", u64::MAX, 2)]),
            Err(TableError::Outside { tenant: 0, .. })
        ));
        assert_eq!(check(&[tenant("a", 0, 10), tenant("b", 10, 10)]), Ok(()));
    }

    #[test]
    fn damaged_tables_are_refused_with_the_reason() {
        let mut entry = Vec::new();
        encode(&[tenant("plc", 0, 8)], &mut entry);
        assert_eq!(decode(b"NIC1\x00"), Err(TableError::NoMagic));
        for cut in 5..entry.len() {
            assert_eq!(
                decode(&entry[..cut]),
                Err(TableError::Truncated(0)),
                "cut at {cut}"
            );
        }
        let mut long = entry.clone();
        long.push(0);
        assert_eq!(decode(&long), Err(TableError::Trailing));
        let mut many = entry.clone();
        many[4] = 9;
        assert_eq!(decode(&many), Err(TableError::TooMany(9)));
        let mut bad = entry;
        bad[6] = 0xff;
        assert_eq!(decode(&bad), Err(TableError::BadName(0)));
    }

    proptest! {
        #[test]
        fn random_entries_never_panic(
            entry in proptest::collection::vec(any::<u8>(), 0..300),
            capacity in any::<u64>(),
        ) {
            let mut e = b"BLK1".to_vec();
            e.extend(entry);
            if let Ok(t) = decode(&e) {
                let _ = t.check(capacity);
            }
        }
    }
}
