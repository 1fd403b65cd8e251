//! A partition program for system-software scenarios (and the default demo system). syssw
//! starts it with the start record (`user_rt::partition`); what it does depends on the
//! partition's name:
//!
//! * `ports-*`: uses its granted COM2 ports (scratch register), then touches port 0x80,
//!   which it was not granted: #GP, for the health monitor;
//! * `windows-*`: checks for 50 of its windows that it runs only inside them (it learns
//!   its window from `partition_info`), reports, then executes `ud2`: an illegal request
//!   for the health monitor;
//! * `hog*`: spins without ever blocking (a CPU hog at its priority) and prints its CPU time
//!   once a second;
//! * `cpu*`: prints the CPU time of time partitions 0..=4 (0 is the background) and the
//!   time its CPU was idle once a second: `<name>: at <s> s CPU time us TP0=<us> TP1=<us>
//!   TP2=<us> TP3=<us> TP4=<us> idle=<us>`;
//! * anything else: prints a heartbeat with its CPU time once a second.
#![no_std]
#![no_main]

use user_rt::partition::StartInfo;
use user_rt::port::{inb, outb};
use user_rt::println;
use user_rt::sys::{self, TscBase, rdtsc};

user_rt::entry!(main);

fn main(start: u64, _: u64) {
    #[allow(unsafe_code)]
    // SAFETY: syssw starts every partition with the start record's address in rdi.
    let Some(info) = (unsafe { StartInfo::from_start(start) }) else {
        println!("no start record from syssw");
        return;
    };
    let name = info.name();
    let tp = info.time_partition;
    println!("{name}: started as partition {} in TP{tp}", info.index);
    if name.starts_with("ports-") {
        outb(0x2ff, 0x5a);
        println!("{name}: granted port 0x2ff reads back {:#x}", inb(0x2ff));
        println!("{name}: touching port 0x80, which is not granted");
        inb(0x80);
        println!("{name}: port 0x80 did not fault");
    } else if name.starts_with("windows-") {
        windows(name, tp);
        #[allow(unsafe_code)]
        // SAFETY: ud2 only raises #UD.
        unsafe {
            core::arch::asm!("ud2")
        };
    } else if name.starts_with("hog") {
        hog(name, tp);
    } else if name.starts_with("cpu") {
        accounting(name);
    } else {
        heartbeat(name, tp);
    }
}

/// Never blocks: reads the clock in a loop and reports once a second.
fn hog(name: &str, tp: u64) -> ! {
    let mut next = sys::clock() / 1_000_000_000 + 1;
    loop {
        let now = sys::clock();
        if now >= next * 1_000_000_000 {
            let cpu = sys::partition_info(tp).map_or(0, |i| i.cpu_ns);
            println!(
                "{name}: spinning at {next} s, TP{tp} CPU time {} ms",
                cpu / 1_000_000
            );
            next += 1;
        }
        core::hint::spin_loop();
    }
}

/// Spins for 50 of its windows and checks it never ran clearly outside them (more than
/// 1 ms after a window's end, which is beyond the timer's lateness under QEMU).
fn windows(name: &str, tp: u64) {
    let base = TscBase::get();
    let info = sys::partition_info(tp).unwrap_or_else(|e| panic!("partition_info: {e:?}"));
    let (mut start, length) = (info.next_window_start, info.window_length);
    let mut previous_end = start;
    let mut outside = 0;
    let mut first_outside = (0, 0, 0, 0);
    let mut windows = 0;
    while windows < 50 {
        let now = base.ns(rdtsc() - base.at_boot);
        if now >= start + length {
            let next = sys::partition_info(tp).map_or(start, |i| i.next_window_start);
            if next != start {
                windows += 1;
                previous_end = start + length;
                start = next;
            }
        } else if now < start && now > previous_end + 1_000_000 {
            if outside == 0 {
                first_outside = (now, previous_end, start, windows);
            }
            outside += 1;
        }
    }
    println!("{name}: ran in {windows} of its windows, {outside} samples outside them");
    if outside > 0 {
        let (now, end, next, window) = first_outside;
        println!(
            "{name}: first sample outside at {now} ns: {} us after window {window} ended at {end} ns, next starts at {next} ns",
            (now - end) / 1000
        );
    }
}

/// Once a second: the CPU time of time partitions 0..=4 and the idle time, in us.
fn accounting(name: &str) -> ! {
    let us = |tp: u64| sys::partition_info(tp).map_or(0, |i| i.cpu_ns / 1000);
    loop {
        let t = sys::clock();
        sys::sleep_until((t / 1_000_000_000 + 1) * 1_000_000_000);
        let idle = sys::partition_info(0).map_or(0, |i| i.idle_ns / 1000);
        println!(
            "{name}: at {} s CPU time us TP0={} TP1={} TP2={} TP3={} TP4={} idle={idle}",
            sys::clock() / 1_000_000_000,
            us(0),
            us(1),
            us(2),
            us(3),
            us(4)
        );
    }
}

fn heartbeat(name: &str, tp: u64) {
    loop {
        let t = sys::clock();
        sys::sleep_until((t / 1_000_000_000 + 1) * 1_000_000_000);
        let info = sys::partition_info(tp).unwrap_or_else(|e| panic!("partition_info: {e:?}"));
        println!(
            "{name}: alive at {} s, TP{tp} CPU time {} ms",
            sys::clock() / 1_000_000_000,
            info.cpu_ns / 1_000_000
        );
    }
}
