//! Interrupts and I/O ports at user level (the user-mode test program in mode
//! `irq-ports`). A separate test binary from the time-window scenario, so the two never
//! share the host's CPUs (their timing checks would disturb each other).

use scenarios::passes;

#[test]
fn irq_ports() {
    passes(
        "irq_ports",
        "irq-ports",
        &[
            "io_grant of COM1 (the kernel's log) is NotPermitted",
            "irq_grant of line 4 (COM1, the kernel's) is NotPermitted",
            "io_grant of COM2's ports",
            "irq_grant of COM2's line 3",
            "a port outside the grant raises #GP (vector 13, error 0) to the exception handler",
            "irq_attach of a granted line",
            "a granted port works (COM2 scratch register reads back 0xa5)",
            "no error in the interrupt-driven exchange",
            "every byte arrived by its interrupt (COM2 loopback, line 3)",
            "an unacknowledged line stays masked (the next interrupt does not arrive)",
            "after irq_ack the device is served and its next interrupt arrives",
            "an interrupt sent in TP1's window reaches the TP2 driver in TP2's next window",
        ],
    );
}
