//! `humantime::format_duration` on `alloc` for the a653rs-linux example partitions built for
//! Warden (`cargo xtask a653rs-examples`): their programs name this crate `humantime`
//! (a dependency rename in the generated manifest), since humantime itself needs `std`.
//!
//! The text is humantime 2's: the non-zero parts of the duration, largest first, separated
//! by one space, each a number and its unit without a space — `year(s)` (365.25 days),
//! `month(s)` (30.44 days), `day(s)`, `h`, `m`, `s`, `ms`, `us`, `ns` — and `0s` for
//! zero, e.g. `1h 2m 3s 4ms`.
#![no_std]

use core::fmt;
use core::time::Duration;

/// A duration shown as humantime shows it (see the crate documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FormattedDuration(Duration);

/// `duration` as text: `format_duration(d).to_string()` or `{}`.
pub fn format_duration(duration: Duration) -> FormattedDuration {
    FormattedDuration(duration)
}

impl FormattedDuration {
    /// The duration shown.
    pub fn get_ref(&self) -> &Duration {
        &self.0
    }
}

const YEAR: u64 = 31_557_600; // 365.25 days
const MONTH: u64 = 2_630_016; // 30.44 days
const DAY: u64 = 86_400;

impl fmt::Display for FormattedDuration {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let secs = self.0.as_secs();
        let nanos = u64::from(self.0.subsec_nanos());
        if secs == 0 && nanos == 0 {
            return f.write_str("0s");
        }
        let (years, rest) = (secs / YEAR, secs % YEAR);
        let (months, rest) = (rest / MONTH, rest % MONTH);
        let (days, rest) = (rest / DAY, rest % DAY);
        // Calendar parts are words with a plural; the others are unit symbols.
        let words = [(years, "year"), (months, "month"), (days, "day")];
        let symbols = [
            (rest / 3600, "h"),
            (rest % 3600 / 60, "m"),
            (rest % 60, "s"),
            (nanos / 1_000_000, "ms"),
            (nanos / 1_000 % 1_000, "us"),
            (nanos % 1_000, "ns"),
        ];
        let mut first = true;
        let mut part = |f: &mut fmt::Formatter<'_>, n: u64, unit: &str, plural: &str| {
            if n == 0 {
                return Ok(());
            }
            let gap = if first { "" } else { " " };
            first = false;
            write!(f, "{gap}{n}{unit}{plural}")
        };
        for (n, unit) in words {
            part(f, n, unit, if n > 1 { "s" } else { "" })?;
        }
        for (n, unit) in symbols {
            part(f, n, unit, "")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::string::ToString;

    fn text(d: Duration) -> std::string::String {
        format_duration(d).to_string()
    }

    #[test]
    fn parts_largest_first_zero_parts_left_out() {
        assert_eq!(text(Duration::ZERO), "0s");
        assert_eq!(text(Duration::from_millis(1)), "1ms");
        assert_eq!(text(Duration::from_millis(1_005)), "1s 5ms");
        assert_eq!(text(Duration::from_millis(3_723_004)), "1h 2m 3s 4ms");
        assert_eq!(text(Duration::new(0, 1_002_003)), "1ms 2us 3ns");
        assert_eq!(text(Duration::from_secs(DAY)), "1day");
        assert_eq!(text(Duration::from_secs(2 * DAY + 60)), "2days 1m");
        assert_eq!(
            text(Duration::from_secs(YEAR + 2 * MONTH + 5)),
            "1year 2months 5s"
        );
    }
}
