//! Host tests of the IOAPIC's interrupt signalling (`kernel/src/arch/ioapic.rs`).

use super::{InterruptOverride, Signal, signal_of};

#[test]
fn signal_follows_overrides_and_bus_defaults() {
    let overrides = [
        InterruptOverride {
            isa_irq: 0,
            gsi: 2,
            flags: 0,
        },
        InterruptOverride {
            isa_irq: 9,
            gsi: 9,
            flags: 0b1101,
        },
    ];
    let edge_high = Signal {
        active_low: false,
        level_triggered: false,
    };
    assert_eq!(signal_of(3, &overrides), edge_high);
    assert_eq!(signal_of(2, &overrides), edge_high);
    assert_eq!(
        signal_of(9, &overrides),
        Signal {
            active_low: false,
            level_triggered: true
        }
    );
    assert_eq!(
        signal_of(18, &[]),
        Signal {
            active_low: true,
            level_triggered: true
        }
    );
}
