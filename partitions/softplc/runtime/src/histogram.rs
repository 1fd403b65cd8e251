//! A fixed-size latency histogram: what the runtime keeps of every release's lateness and
//! of its own work per cycle, so that it can report min/median/max over any number of
//! cycles (a bench wants 10,000 and more) in constant memory and constant time per sample.
//!
//! Samples fall into [`BUCKETS`] buckets of `width` ns; larger ones into an overflow count.
//! Min and max are exact; the median is the midpoint of the bucket that holds it (so it is
//! exact to `width / 2`), clamped to [min, max] — and the max when the median overflows.

/// Buckets per histogram.
pub const BUCKETS: usize = 256;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Histogram {
    width: u64,
    counts: [u32; BUCKETS],
    overflow: u64,
    count: u64,
    min: u64,
    max: u64,
}

impl Histogram {
    /// An empty histogram with buckets `width` ns wide (at least 1).
    pub const fn new(width: u64) -> Self {
        Self {
            width: if width == 0 { 1 } else { width },
            counts: [0; BUCKETS],
            overflow: 0,
            count: 0,
            min: u64::MAX,
            max: 0,
        }
    }

    pub fn record(&mut self, ns: u64) {
        match self.counts.get_mut((ns / self.width) as usize) {
            Some(c) => *c = c.saturating_add(1),
            None => self.overflow += 1,
        }
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
                median = (i as u64)
                    .saturating_mul(self.width)
                    .saturating_add(self.width / 2);
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
        let mut h = Histogram::new(1_000);
        assert_eq!(h.summary(), None);
        for ns in [12_300, 11_100, 11_900, 40_000, 11_500] {
            h.record(ns);
        }
        // Sorted: 11.1, 11.5, 11.9, 12.3, 40 us: the median 11.9 us lies in bucket 11.
        assert_eq!(h.summary(), Some((11_100, 11_500, 40_000)));
        assert_eq!(h.count(), 5);
    }

    #[test]
    fn the_median_stays_within_min_and_max_and_overflow_counts() {
        let mut h = Histogram::new(1_000);
        h.record(5);
        assert_eq!(h.summary(), Some((5, 5, 5)));
        let mut h = Histogram::new(10);
        for _ in 0..3 {
            h.record(1_000_000);
        }
        h.record(3);
        assert_eq!(h.summary(), Some((3, 1_000_000, 1_000_000)));
        let mut h = Histogram::new(0);
        h.record(u64::MAX);
        assert_eq!(h.summary(), Some((u64::MAX, u64::MAX, u64::MAX)));
    }
}
