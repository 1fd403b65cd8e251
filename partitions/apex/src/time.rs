//! Time arithmetic of the APEX services (pure: no system calls, host-tested).
//!
//! Times are nanoseconds since boot (`clock()`), as `u64`. APEX durations are
//! `ApexSystemTime` (`i64` ns) where every negative value means INFINITE (ARINC 653 P1
//! 3.4.1; a653rs maps all negatives to `SystemTime::Infinite`).

use a653rs::bindings::{ApexSystemTime, ErrorReturnCode};

/// The syssw protocol's "wait forever" time-out.
pub const PROTOCOL_FOREVER: u64 = u64::MAX;

/// An APEX duration if it is finite.
pub fn finite(time: ApexSystemTime) -> Option<u64> {
    u64::try_from(time).ok()
}

/// An APEX time-out as a protocol word: INFINITE → `u64::MAX`, 0 → 0 (do not wait), else ns.
pub fn protocol_timeout(time_out: ApexSystemTime) -> u64 {
    finite(time_out).unwrap_or(PROTOCOL_FOREVER)
}

/// The first release point at or after `now`: the partition's windows start at
/// `window_start + k * period` (the current or next window start as `partition_info`
/// reports it; `u64::MAX` = the time partition has no window). Without a window or a
/// period (the background partition) the release point is `now`.
pub fn next_release_point(now: u64, window_start: u64, period: u64) -> u64 {
    if window_start == u64::MAX {
        return now;
    }
    if window_start >= now {
        return window_start;
    }
    if period == 0 {
        return now;
    }
    let periods = (now - window_start).div_ceil(period);
    window_start.saturating_add(periods.saturating_mul(period))
}

/// The deadline of a job released at `release` with `capacity` (none if INFINITE).
pub fn deadline(release: u64, capacity: ApexSystemTime) -> Option<u64> {
    finite(capacity).map(|c| release.saturating_add(c))
}

/// CREATE_PROCESS checks of a process's period and time capacity (ARINC 653 P1 3.3.2.3):
/// a period is INFINITE (aperiodic) or positive; a time capacity is INFINITE or positive and
/// at most the period; a period must be a multiple of the partition's period, which is
/// a configuration matter (INVALID_CONFIG), the others are INVALID_PARAM.
pub fn check_process_timing(
    period: ApexSystemTime,
    capacity: ApexSystemTime,
    partition_period: u64,
) -> Result<(), ErrorReturnCode> {
    if period == 0 || capacity == 0 {
        return Err(ErrorReturnCode::InvalidParam);
    }
    if let (Some(period), Some(capacity)) = (finite(period), finite(capacity))
        && capacity > period
    {
        return Err(ErrorReturnCode::InvalidParam);
    }
    if let Some(period) = finite(period)
        && partition_period != 0
        && !period.is_multiple_of(partition_period)
    {
        return Err(ErrorReturnCode::InvalidConfig);
    }
    Ok(())
}

/// The period a process gets instead of `period` when the program asked for a653rs-linux's
/// reading ([`crate::runtime::read_zero_period_as_partition_period`]): there a period of
/// 0 means "released once per partition period", the partition's own period; ARINC 653
/// (and this runtime otherwise) refuses a zero period with INVALID_PARAM. `None`: keep
/// `period`.
pub fn a653rs_linux_period(
    period: ApexSystemTime,
    partition_period: u64,
    linux_reading: bool,
) -> Option<ApexSystemTime> {
    if period != 0 || !linux_reading || partition_period == 0 {
        return None;
    }
    ApexSystemTime::try_from(partition_period).ok()
}

/// When a process started with `delay` is first released: a periodic one at the next
/// release point of the partition plus the delay, an aperiodic one `delay` after `now`.
pub fn first_release(periodic: bool, now: u64, release_point: u64, delay: u64) -> u64 {
    let base = if periodic { release_point } else { now };
    base.saturating_add(delay)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_zero_period_reads_as_the_partition_period_only_when_asked() {
        assert_eq!(
            a653rs_linux_period(0, 1_000_000_000, true),
            Some(1_000_000_000)
        );
        assert_eq!(a653rs_linux_period(0, 1_000_000_000, false), None);
        assert_eq!(a653rs_linux_period(5, 1_000_000_000, true), None);
        // Without a partition period (no window) the standard's answer stays.
        assert_eq!(a653rs_linux_period(0, 0, true), None);
    }

    #[test]
    fn time_outs_encode_infinite_as_max() {
        assert_eq!(protocol_timeout(-1), u64::MAX);
        assert_eq!(protocol_timeout(i64::MIN), u64::MAX);
        assert_eq!(protocol_timeout(0), 0);
        assert_eq!(protocol_timeout(1_500), 1_500);
        assert_eq!(protocol_timeout(i64::MAX), i64::MAX as u64);
    }

    #[test]
    fn release_points_follow_the_windows() {
        // Next window still ahead: it is the release point.
        assert_eq!(next_release_point(100, 150, 50), 150);
        assert_eq!(next_release_point(150, 150, 50), 150);
        // Inside the current window: the next one.
        assert_eq!(next_release_point(160, 150, 50), 200);
        assert_eq!(next_release_point(200, 150, 50), 200);
        assert_eq!(next_release_point(1_000_001, 0, 1_000_000), 2_000_000);
        // No window or no period: now.
        assert_eq!(next_release_point(77, u64::MAX, 50), 77);
        assert_eq!(next_release_point(77, 10, 0), 77);
        // No overflow near the end of time.
        assert_eq!(
            next_release_point(u64::MAX - 1, 0, u64::MAX / 2 + 1),
            u64::MAX
        );
    }

    #[test]
    fn deadlines_are_release_plus_capacity() {
        assert_eq!(deadline(1_000, 250), Some(1_250));
        assert_eq!(deadline(1_000, -1), None);
        assert_eq!(deadline(u64::MAX - 1, 5), Some(u64::MAX));
    }

    #[test]
    fn process_timing_checks() {
        let ms: i64 = 1_000_000;
        let partition = 10 * ms as u64;
        assert_eq!(check_process_timing(-1, -1, partition), Ok(()));
        assert_eq!(check_process_timing(20 * ms, 5 * ms, partition), Ok(()));
        assert_eq!(check_process_timing(20 * ms, -1, 0), Ok(()));
        assert_eq!(
            check_process_timing(0, -1, 0),
            Err(ErrorReturnCode::InvalidParam)
        );
        assert_eq!(
            check_process_timing(-1, 0, 0),
            Err(ErrorReturnCode::InvalidParam)
        );
        assert_eq!(
            check_process_timing(10 * ms, 11 * ms, 0),
            Err(ErrorReturnCode::InvalidParam)
        );
        assert_eq!(
            check_process_timing(15 * ms, -1, partition),
            Err(ErrorReturnCode::InvalidConfig)
        );
    }

    #[test]
    fn first_releases() {
        assert_eq!(first_release(true, 100, 150, 0), 150);
        assert_eq!(first_release(true, 100, 150, 7), 157);
        assert_eq!(first_release(false, 100, 150, 7), 107);
    }
}
