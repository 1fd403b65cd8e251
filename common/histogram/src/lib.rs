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

/// The lowest value of bucket `index`.
fn low(index: usize) -> u64 {
    if index < LINEAR as usize {
        return index as u64;
    }
    let above = index - LINEAR as usize;
    ((SUB + above % SUB) as u64) << ((above / SUB) as u32 + 1)
}

/// The bin of `bits` significant bits that holds `ns`: `[low, high)`.
fn coarse(ns: u64, bits: u32) -> (u64, u64) {
    let top = 63 - ns.leading_zeros().min(63);
    if top < bits {
        return (ns, ns + 1);
    }
    let shift = top + 1 - bits;
    let low = ns >> shift << shift;
    (low, low + (1 << shift))
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

    /// The non-empty bins of `bits` (1 to 6) significant bits, in increasing order, as
    /// `(low, high, count)` for the values in `[low, high)`: a bin is at most 2^(1 - bits)
    /// of its values wide (a quarter with 3 bits), values below 2^bits have one each; the
    /// bin of the largest values reaches to `u64::MAX` (see [`MAX_EXPONENT`]). A
    /// coarser view than the buckets, for a log line or a picture.
    pub fn bins(&self, bits: u32) -> impl Iterator<Item = (u64, u64, u64)> + '_ {
        let bits = bits.clamp(1, SUB_BITS + 1);
        let mut filled = self
            .counts
            .iter()
            .enumerate()
            .filter(|&(_, &c)| c > 0)
            .map(move |(i, &c)| {
                let (low, high) = coarse(low(i), bits);
                // The last bucket also holds every larger value.
                let high = if i == BUCKETS - 1 { u64::MAX } else { high };
                ((low, high), u64::from(c))
            })
            .peekable();
        core::iter::from_fn(move || {
            let ((low, high), mut count) = filled.next()?;
            // A bucket lies inside one bin: the bin's buckets follow each other.
            while let Some(&(_, more)) = filled.peek().filter(|(bin, _)| *bin == (low, high)) {
                count += more;
                filled.next();
            }
            Some((low, high, count))
        })
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
    fn bins_count_every_value_in_its_range() {
        let mut h = Histogram::new();
        let values = [
            0,
            3,
            7,
            8,
            9,
            11,
            12,
            63,
            64,
            100,
            127,
            20_000,
            23_000,
            24_576,
            1 << 45,
        ];
        for ns in values {
            h.record(ns);
        }
        let bins: Vec<(u64, u64, u64)> = h.bins(3).collect();
        assert_eq!(
            bins,
            [
                (0, 1, 1),
                (3, 4, 1),
                (7, 8, 1),
                (8, 10, 2),
                (10, 12, 1),
                (12, 14, 1),
                (56, 64, 1),
                (64, 80, 1),
                (96, 112, 1),
                (112, 128, 1),
                (16_384, 20_480, 1),
                (20_480, 24_576, 1),
                (24_576, 28_672, 1),
                (7 << 38, u64::MAX, 1),
            ]
        );
        for (low, high, _) in &bins {
            assert!(
                high - low <= (*low / 4).max(1) || *high == u64::MAX,
                "{low}..{high}"
            );
        }
        let mut many = Histogram::new();
        for ns in 0..100_000u64 {
            many.record(ns * 37);
        }
        let bins: Vec<_> = many.bins(3).collect();
        assert_eq!(bins.iter().map(|b| b.2).sum::<u64>(), 100_000);
        assert!(
            bins.windows(2).all(|w| w[0].1 <= w[1].0),
            "ordered, disjoint"
        );
        for ns in [0u64, 37, 40_000 * 37, 99_999 * 37] {
            let (low, high, _) = *bins.iter().find(|b| b.0 <= ns && ns < b.1).unwrap();
            assert!(low <= ns && ns < high);
        }
        assert_eq!(Histogram::new().bins(3).count(), 0);
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
