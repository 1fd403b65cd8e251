//! Host tests of `kernel/src/time.rs` (a child module of it: `super` is that module).

use super::ticks_to_ns;

#[test]
fn converts_ticks_without_overflow() {
    assert_eq!(ticks_to_ns(0, 0), 0);
    assert_eq!(ticks_to_ns(3_000_000_000, 3_000_000_000), 1_000_000_000);
    // A year of ticks at 5 GHz does not overflow.
    assert_eq!(
        ticks_to_ns(5_000_000_000 * 31_536_000, 5_000_000_000),
        31_536_000 * 1_000_000_000
    );
}
