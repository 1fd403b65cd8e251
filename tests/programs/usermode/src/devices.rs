//! Interrupts and I/O ports at user level (mode `irq-ports`), with COM2 (ports 0x2f8..0x2ff,
//! IOAPIC line 3; QEMU's second serial port, connected to nothing) as the device: in
//! loopback mode every byte written to it is received at once and raises its receive
//! interrupt, so a program can trigger interrupts itself.
//!
//! Task `dev` gets COM2's ports and line 3. Its `driver` thread (TP2) attaches the line,
//! exchanges bytes interrupt-driven, shows the line stays masked until acknowledged, then
//! serves bytes a `trigger` thread of the same task sends from TP1's window: those
//! interrupts arrive while TP2 may not run, are latched, and reach the driver at TP2's next
//! window start. A `stray` thread touches ports it was not granted and faults (#GP) into
//! its exception handler, the root.

use crate::check::{expect, expect_eq, expect_err, expect_ok, fail, must};
use crate::child::{BASIC, Lab, MS, WAIT, worker};
use crate::exceptions::{next_exception, reply_plain};
use user_rt::abi::ipc::{LABEL_EXCEPTION, REPLY_KILL};
use user_rt::abi::syscall::{Abilities, Error, ThreadAttribute, WindowSpec};
use user_rt::port::{inb, outb};
use user_rt::{println, sys};

const COM2: u16 = 0x2f8;
const DATA: u16 = COM2;
const IER: u16 = COM2 + 1;
const FCR: u16 = COM2 + 2;
const LCR: u16 = COM2 + 3;
const MCR: u16 = COM2 + 4;
const LSR: u16 = COM2 + 5;
const SCRATCH: u16 = COM2 + 7;
const LINE: u64 = 3;
const BIT: u64 = 1;
const BYTES: u64 = 20;
/// Interrupts sent from TP1's window.
const LATCHED: usize = 5;

const MAJOR: u64 = 10 * MS;
const TP1: (u64, u64) = (0, 4 * MS);
const TP2: (u64, u64) = (5 * MS, 4 * MS);

// Driver block words.
const R_ATTACH: usize = 0;
const R_SCRATCH: usize = 1;
const R_RECEIVED: usize = 2;
const R_FIRST_ERROR: usize = 3; // code | byte << 8 | step << 16
const R_MASKED_WAIT: usize = 4;
const R_ACKED_WAIT: usize = 5;
const R_ARMED: usize = 6; // latched round the driver waits in (1-based)
const R_WOKE: usize = 8; // ..+LATCHED: when each latched interrupt reached the driver
const R_TRIGGERED: usize = 16; // ..+LATCHED: when the trigger sent each byte
const A_TRIGGER_BLOCK: usize = 0;
// Stray block words.
const R_STRAY_STEP: usize = 0;

fn uart_setup() {
    outb(IER, 0);
    outb(LCR, 0x03); // 8 data bits, no parity, 1 stop bit
    outb(FCR, 0); // no FIFO: one byte, one interrupt
    outb(MCR, 0x18); // loopback, OUT2 (the PC's interrupt gate)
    while inb(LSR) & 1 != 0 {
        inb(DATA);
    }
    outb(IER, 0x01); // interrupt on received data
}

worker!(
    fn driver(b, ipc) {
        b.set_code(R_ATTACH, &sys::irq_attach(LINE, BIT));
        outb(SCRATCH, 0xa5);
        b.set_result(R_SCRATCH, inb(SCRATCH) as u64);
        uart_setup();
        let error = |step: u64, byte: u64, e: Error| {
            if b.result(R_FIRST_ERROR) == 0 {
                b.set_result(R_FIRST_ERROR, e as u64 | byte << 8 | step << 16);
            }
        };
        for byte in 0..BYTES {
            outb(DATA, byte as u8);
            if let Err(e) = sys::irq_wait(LINE, WAIT) {
                error(1, byte, e);
            }
            let got = inb(DATA) as u64;
            if got != byte {
                error(2, byte, Error::InvalidArgument);
            }
            if let Err(e) = sys::irq_ack(LINE) {
                error(3, byte, e);
            }
            b.add_result(R_RECEIVED, 1);
        }
        // One interrupt, not acknowledged: the next byte's interrupt must not come ...
        outb(DATA, 0x40);
        let _ = sys::irq_wait(LINE, WAIT);
        inb(DATA);
        outb(DATA, 0x41);
        b.set_code(R_MASKED_WAIT, &sys::irq_wait(LINE, 20 * MS));
        // ... and an edge-triggered request that came while masked is gone for good (the
        // IOAPIC ignores edges on a masked input), so a driver looks at its device after
        // acknowledging: the byte is there. Then the line works again.
        let _ = sys::irq_ack(LINE);
        let pending = inb(LSR) & 1 != 0 && inb(DATA) == 0x41;
        outb(DATA, 0x42);
        let again = sys::irq_wait(LINE, WAIT);
        b.set_result(R_ACKED_WAIT, (pending && again.is_ok() && inb(DATA) == 0x42) as u64);
        let _ = sys::irq_ack(LINE);
        b.set_step(1);

        for round in 1..=LATCHED {
            b.set_result(R_ARMED, round as u64);
            if let Err(e) = sys::irq_wait(LINE, WAIT) {
                error(4, round as u64, e);
            }
            b.set_result(R_WOKE + round - 1, sys::clock());
            inb(DATA);
            let _ = sys::irq_ack(LINE);
        }
    }
);

worker!(
    /// Sends one byte per round the driver arms (from TP1's window).
    fn trigger(b, ipc) {
        // SAFETY: arg 0 is the driver's block, mapped in this task too.
        let driver = unsafe { crate::child::Block::from_arg(b.arg(A_TRIGGER_BLOCK)) };
        for round in 1..=LATCHED {
            while driver.result(R_ARMED) < round as u64 {
                core::hint::spin_loop();
            }
            driver.set_result(R_TRIGGERED + round - 1, sys::clock());
            outb(DATA, round as u8);
            // Let the round pass before the next (the driver wakes only in TP2's window).
            while driver.result(R_ARMED) == round as u64 && round < LATCHED {
                core::hint::spin_loop();
            }
        }
    }
);

worker!(
    /// Reads the port just past its grant, which must fault.
    fn stray(b, ipc) {
        b.set_result(R_STRAY_STEP, 1);
        inb(COM2 + 8);
        b.set_result(R_STRAY_STEP, 2);
    }
);

pub fn run() {
    let mut lab = Lab::new();
    let dev = lab.task("dev", BASIC | Abilities::IRQ, 150);
    expect_err(
        "io_grant of COM1 (the kernel's log) is NotPermitted",
        sys::io_grant(dev, 0x3f8, 8),
        Error::NotPermitted,
    );
    expect_err(
        "irq_grant of line 4 (COM1, the kernel's) is NotPermitted",
        sys::irq_grant(dev, 4),
        Error::NotPermitted,
    );
    expect_ok("io_grant of COM2's ports", sys::io_grant(dev, COM2, 8));
    expect_ok("irq_grant of COM2's line 3", sys::irq_grant(dev, LINE));

    // An access outside the grant is a #GP, delivered to the handler.
    let s = lab.worker(Some(dev), stray, 100, &[]);
    must(
        "thread_set ExceptionHandler",
        sys::thread_set(Some(s.id), ThreadAttribute::ExceptionHandler, lab.me.0),
    );
    s.start();
    let m = next_exception(
        &lab,
        s.id,
        "the stray thread's fault arrives",
        LABEL_EXCEPTION,
    );
    expect_eq(
        "a port outside the grant raises #GP (vector 13, error 0) to the exception handler",
        (m.vector, m.error_code, s.block.result(R_STRAY_STEP)),
        (13, 0, 1),
    );
    must("reply REPLY_KILL", reply_plain(s.id, REPLY_KILL));

    let window = |(offset, duration): (u64, u64), partition| WindowSpec {
        offset,
        duration,
        partition,
        cpu: 0,
    };
    must(
        "schedule_set",
        sys::schedule_set(0, MAJOR, &[window(TP1, 1), window(TP2, 2)]),
    );
    must("schedule_switch", sys::schedule_switch(0));
    let d = lab.worker(Some(dev), driver, 100, &[]);
    let t = lab.worker(Some(dev), trigger, 100, &[d.block.address()]);
    let in_tp = |id, tp| {
        must(
            "thread_set TimePartition",
            sys::thread_set(Some(id), ThreadAttribute::TimePartition, tp),
        );
    };
    in_tp(d.id, 2);
    in_tp(t.id, 1);
    d.start();
    let b = &d.block;
    if !crate::child::wait_until(WAIT, || b.step() >= 1) {
        fail(
            "the driver's interrupt-driven exchange",
            format_args!(
                ": not done within {} ms: attach {}, {} bytes received, first error {:#x}",
                WAIT / MS,
                b.result(R_ATTACH),
                b.result(R_RECEIVED),
                b.result(R_FIRST_ERROR)
            ),
        );
    }
    expect_eq("irq_attach of a granted line", b.result(R_ATTACH), 0);
    expect_eq(
        "a granted port works (COM2 scratch register reads back 0xa5)",
        b.result(R_SCRATCH),
        0xa5,
    );
    expect_eq(
        "no error in the interrupt-driven exchange",
        b.result(R_FIRST_ERROR),
        0,
    );
    expect_eq(
        "every byte arrived by its interrupt (COM2 loopback, line 3)",
        b.result(R_RECEIVED),
        BYTES,
    );
    expect_eq(
        "an unacknowledged line stays masked (the next interrupt does not arrive)",
        b.result(R_MASKED_WAIT),
        Error::TimedOut as u64,
    );
    expect_eq(
        "after irq_ack the device is served and its next interrupt arrives",
        b.result(R_ACKED_WAIT),
        1,
    );

    t.start();
    d.wait_done("the driver receives the latched interrupts");
    let frame0 = must("partition_info", sys::partition_info(1)).next_window_start % MAJOR;
    let phase = |at: u64| (at + MAJOR - frame0) % MAJOR;
    for round in 0..LATCHED {
        let sent = b.result(R_TRIGGERED + round);
        let woke = b.result(R_WOKE + round);
        let tp2_start = {
            let frame = sent - phase(sent);
            frame + TP2.0
        };
        println!(
            "latched interrupt {}: sent at frame phase {} us (TP1), reached the driver at phase {} us, {} us after TP2's window start",
            round + 1,
            phase(sent) / 1000,
            phase(woke) / 1000,
            woke.saturating_sub(tp2_start) / 1000
        );
        // Delivered in the TP2 window that follows the sending (how punctually that
        // window starts is the time-window scenario's business).
        if !(phase(sent) < TP1.1 && woke >= tp2_start && woke < tp2_start + TP2.1) {
            fail(
                "an interrupt sent in TP1's window reaches the TP2 driver in TP2's next window",
                format_args!(
                    ": round {}: sent {sent}, woke {woke}, TP2 start {tp2_start}",
                    round + 1
                ),
            );
        }
    }
    expect(
        "an interrupt sent in TP1's window reaches the TP2 driver in TP2's next window",
        true,
    );
    println!("all irq-ports checks passed");
    let _ = sys::system_halt(true);
}
