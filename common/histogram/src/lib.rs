//! A fixed-size latency histogram: what the soft-PLC runtime keeps of every release's
//! lateness and of its own work per release, and the soak victim of every window start's
//! lateness, so that they can report min/median/max over any number of samples (a bench
//! wants 10,000 and more, the soak 10^6) in constant memory and constant time per sample,
//! whether a figure is 10 us on virtual time or 10 ms under a loaded emulator.
//!
//! Buckets are log-linear: values below 64 ns have a bucket each; above, every power of two
//! is split into 32 buckets, so a bucket is at most 1/32 of its values wide. Min and max
//! are exact; the median is the midpoint of the bucket that holds it (within 1/64 of the
//! true value), clamped to [min, max]. Values from 2^([`MAX_EXPONENT`] + 1) ns (about 37
//! minutes) share the last bucket.
#![cfg_attr(not(test), no_std)]

/// Significant bits a bucket keeps below a value's top bit.
const SUB_BITS: u32 = 5;
const SUB: usize = 1 << SUB_BITS;
/// Values below this have a bucket each.
const LINEAR: u64 = 2 * SUB as u64;
/// Highest top-bit position with buckets of its own.
pub const MAX_EXPONENT: u32 = 40;
/// Buckets per histogram.
pub const BUCKETS: usize = LINEAR as usize + (MAX_EXPONENT as usize - SUB_BITS as usize) * SUB;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Histogram {
    counts: [u32; BUCKETS],
    count: u64,
    min: u64,
    max: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        Self::new()
    }
}

/// The bucket of `ns`.
fn bucket(ns: u64) -> usize {
    if ns < LINEAR {
        return ns as usize;
    }
    let top = 63 - ns.leading_zeros();
    if top > MAX_EXPONENT {
        return BUCKETS - 1;
    }
    let shift = top - SUB_BITS;
    let mantissa = (ns >> shift) as usize & (SUB - 1);
    LINEAR as usize + (top - SUB_BITS - 1) as usize * SUB + mantissa
}

/// The middle of bucket `index`.
fn midpoint(index: usize) -> u64 {
    if index < LINEAR as usize {
        return index as u64;
    }
    let above = index - LINEAR as usize;
    let shift = (above / SUB) as u32 + 1;
    let low = ((SUB + above % SUB) as u64) << shift;
    low + (1u64 << shift) / 2
}

impl Histogram {
    pub const fn new() -> Self {
        Self {
            counts: [0; BUCKETS],
            count: 0,
            min: u64::MAX,
            max: 0,
        }
    }

    /// Empty again (in place).
    pub fn clear(&mut self) {
        self.counts.fill(0);
        self.count = 0;
        self.min = u64::MAX;
        self.max = 0;
    }

    pub fn record(&mut self, ns: u64) {
        let slot = &mut self.counts[bucket(ns)];
        *slot = slot.saturating_add(1);
        self.count += 1;
        self.min = self.min.min(ns);
        self.max = self.max.max(ns);
    }

    /// How many samples it holds.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// `(min, median, max)`, or `None` before the first sample.
    pub fn summary(&self) -> Option<(u64, u64, u64)> {
        if self.count == 0 {
            return None;
        }
        let rank = self.count.div_ceil(2);
        let mut seen = 0u64;
        let mut median = self.max;
        for (i, &c) in self.counts.iter().enumerate() {
            seen += u64::from(c);
            if seen >= rank {
                median = midpoint(i);
                break;
            }
        }
        Some((self.min, median.clamp(self.min, self.max), self.max))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_of_samples() {
        let mut h = Histogram::new();
        assert_eq!(h.summary(), None);
        for ns in [12_300, 11_100, 11_900, 40_000, 11_500] {
            h.record(ns);
        }
        // Sorted: 11.1, 11.5, 11.9, 12.3, 40 us: the median 11.9 us, in a bucket of 256 ns.
        let (min, median, max) = h.summary().unwrap();
        assert_eq!((min, max, h.count()), (11_100, 40_000, 5));
        assert!(median.abs_diff(11_900) <= 11_900 / 64, "{median}");
    }

    #[test]
    fn buckets_hold_their_values_within_one_sixty_fourth() {
        let mut previous = 0;
        for ns in (0..200_000u64).chain([1 << 20, 7_935_329, 1 << 39, u64::MAX / 3]) {
            let b = bucket(ns);
            assert!(
                b >= previous || ns >= 200_000,
                "buckets grow with the value"
            );
            previous = b;
            if ns < 1 << (MAX_EXPONENT + 1) {
                let mid = midpoint(b);
                assert!(mid.abs_diff(ns) <= ns / 32 + 1, "{ns}: bucket {b} at {mid}");
            } else {
                assert_eq!(b, BUCKETS - 1);
            }
        }
    }

    #[test]
    fn the_median_stays_within_min_and_max() {
        let mut h = Histogram::new();
        h.record(5);
        assert_eq!(h.summary(), Some((5, 5, 5)));
        let mut h = Histogram::new();
        for _ in 0..3 {
            h.record(7_935_329);
        }
        h.record(3);
        let (_, median, max) = h.summary().unwrap();
        assert!(median.abs_diff(7_935_329) <= 7_935_329 / 64 && max == 7_935_329);
        let mut h = Histogram::new();
        h.record(u64::MAX);
        assert_eq!(h.summary(), Some((u64::MAX, u64::MAX, u64::MAX)));
        h.clear();
        assert_eq!((h.summary(), h), (None, Histogram::new()));
    }
}
