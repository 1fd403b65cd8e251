//! `std::thread::sleep` as the APEX service TIMED_WAIT of the calling process.

use apex::Warden;
use apex::a653rs::bindings::ApexTimeP1;
use core::time::Duration;

/// Waits `duration` (TIMED_WAIT; a zero duration yields to equal-priority processes).
/// std's sleep cannot fail: where TIMED_WAIT refuses (the initialisation thread, the error
/// handler, a preemption-lock owner: INVALID_MODE) it returns at once, as a sleep the
/// runtime cannot grant, and a duration beyond the APEX time range waits the longest
/// finite time.
pub fn sleep(duration: Duration) {
    let nanos = i64::try_from(duration.as_nanos()).unwrap_or(i64::MAX);
    let _ = Warden::timed_wait(nanos);
}
