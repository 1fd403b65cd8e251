//! Host tests of `kernel/src/log.rs` (a child module of it: `super` is that module).

use super::{LOG_BUFFER, Ring};
use std::cell::Cell;

#[test]
fn timestamp_splits_seconds_and_micros() {
    assert_eq!(super::timestamp_parts(0), (0, 0));
    assert_eq!(super::timestamp_parts(1_234_567_891), (1, 234_567));
    assert_eq!(super::timestamp_parts(999), (0, 0));
}

#[test]
fn a_slow_uart_never_stalls_the_writer_and_full_lines_are_counted() {
    let mut ring = Ring::new();
    let out = std::cell::RefCell::new(Vec::new());
    // A UART that has room for one FIFO load per kernel exit.
    let room = Cell::new(true);
    let ready = || room.replace(false);
    let line = [b'L'; 600];
    let mut pushed = 0;
    for _ in 0..200 {
        if ring.push(&line) {
            pushed += 1;
        }
        room.set(true);
        ring.drain(ready, |b| out.borrow_mut().push(b));
    }
    // Each push took 16 bytes out at most: the ring filled up and the rest was counted.
    assert_eq!(out.borrow().len(), 200 * 16);
    assert!((LOG_BUFFER / 600..200).contains(&pushed), "{pushed}");
    assert_eq!(ring.dropped, 200 - pushed as u64);
    // Later exits empty it, oldest bytes first, lines whole.
    while !ring.is_empty() {
        room.set(true);
        ring.drain(ready, |b| out.borrow_mut().push(b));
    }
    assert_eq!(out.borrow().len(), pushed * 600);
    assert!(out.borrow().iter().all(|&b| b == b'L'));
    // Lines that wrap around the end of the ring come out whole and in order.
    out.borrow_mut().clear();
    let mut expected = Vec::new();
    for i in 0..3000 {
        let line = format!("line {i} {}\n", "x".repeat(i % 700));
        if ring.push(line.as_bytes()) {
            expected.extend_from_slice(line.as_bytes());
        }
        room.set(true);
        ring.drain(ready, |b| out.borrow_mut().push(b));
    }
    ring.drain(|| true, |b| out.borrow_mut().push(b));
    assert!(*out.borrow() == expected);
    // A UART that is always ready (QEMU's) takes a line at once.
    assert!(ring.push(b"hello\n"));
    ring.drain(|| true, |b| out.borrow_mut().push(b));
    assert!(ring.is_empty() && out.borrow().ends_with(b"hello\n"));
}
