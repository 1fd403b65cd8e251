//! A tenant's virtual disk: `sectors` sectors of the disk from `first_sector`. The
//! tenant addresses sectors `0..sectors`; the driver maps them to the disk here, and a
//! request that reaches outside the range is refused before the device sees it.

/// A tenant's range of the disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VirtualDisk {
    pub first_sector: u64,
    pub sectors: u64,
}

/// Why a request does not fit its virtual disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutOfRange {
    pub sector: u64,
    pub count: u32,
    pub sectors: u64,
}

impl core::fmt::Display for OutOfRange {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "sectors {}+{} are outside the virtual disk of {} sectors",
            self.sector, self.count, self.sectors
        )
    }
}

impl VirtualDisk {
    /// The disk sector of the tenant's `sector`, when `count` sectors from it are all the
    /// tenant's.
    pub fn map(&self, sector: u64, count: u32) -> Result<u64, OutOfRange> {
        let refused = OutOfRange {
            sector,
            count,
            sectors: self.sectors,
        };
        match sector.checked_add(u64::from(count)) {
            Some(end) if end <= self.sectors => {
                self.first_sector.checked_add(sector).ok_or(refused)
            }
            _ => Err(refused),
        }
    }

    /// The disk sector after the range (`None` if it overflows).
    pub fn end(&self) -> Option<u64> {
        self.first_sector.checked_add(self.sectors)
    }

    /// Whether the two ranges share a sector.
    pub fn overlaps(&self, other: &VirtualDisk) -> bool {
        let (Some(a), Some(b)) = (self.end(), other.end()) else {
            return true;
        };
        self.first_sector < b && other.first_sector < a
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use proptest::prelude::*;
    use std::format;

    #[test]
    fn requests_map_inside_the_range_only() {
        let d = VirtualDisk {
            first_sector: 100,
            sectors: 10,
        };
        assert_eq!(d.map(0, 1), Ok(100));
        assert_eq!(d.map(6, 4), Ok(106));
        assert_eq!(
            d.map(9, 0),
            Ok(109),
            "a flush-like empty request at the end"
        );
        assert!(d.map(7, 4).is_err(), "one sector past the end");
        assert!(d.map(10, 1).is_err());
        assert!(d.map(u64::MAX, 2).is_err(), "wraps");
        let e = d.map(u64::MAX - 1, 1).unwrap_err();
        assert!(format!("{e}").contains("outside the virtual disk of 10 sectors"));
    }

    #[test]
    fn overlap_is_a_shared_sector() {
        let d = |first_sector, sectors| VirtualDisk {
            first_sector,
            sectors,
        };
        assert!(!d(0, 10).overlaps(&d(10, 10)));
        assert!(d(0, 11).overlaps(&d(10, 10)));
        assert!(d(15, 1).overlaps(&d(10, 10)));
        assert!(
            d(u64::MAX, 2).overlaps(&d(0, 1)),
            "a range that wraps is refused"
        );
    }

    proptest! {
        /// Whatever a tenant asks, a mapped request lies wholly inside its range.
        #[test]
        fn mapped_requests_stay_inside(
            first in any::<u64>(), sectors in any::<u64>(),
            sector in any::<u64>(), count in any::<u32>(),
        ) {
            let d = VirtualDisk { first_sector: first, sectors };
            if let Ok(at) = d.map(sector, count) {
                prop_assert!(at >= first);
                prop_assert!(at - first + u64::from(count) <= sectors);
            }
        }
    }
}
