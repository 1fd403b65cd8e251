//! Kernel micro-benchmarks, run as the root task by `cargo xtask bench`. Prints one
//! `bench NAME median=N min=N max=N unit=cycles samples=N` line per metric.
#![no_std]
#![no_main]
#![forbid(unsafe_op_in_unsafe_fn)]
#![deny(unsafe_code)]

use user_rt::{println, sys};

user_rt::entry!(main);

const SAMPLES: usize = 10_000;

fn rdtsc() -> u64 {
    #[allow(unsafe_code)]
    // SAFETY: RDTSC only reads the time-stamp counter (CR4.TSD is clear).
    unsafe {
        core::arch::x86_64::_rdtsc()
    }
}

fn report(name: &str, samples: &mut [u32]) {
    samples.sort_unstable();
    let median = samples[samples.len() / 2];
    println!(
        "bench {name} median={median} min={} max={} unit=cycles samples={}",
        samples[0],
        samples[samples.len() - 1],
        samples.len()
    );
}

fn main(_: u64, _: u64) {
    // Warm up caches and the TLB.
    for _ in 0..1000 {
        sys::raw(0, 0, 0, 0, 0);
    }
    let mut samples = [0u32; SAMPLES];
    for s in samples.iter_mut() {
        let t0 = rdtsc();
        // Call number 0 does not exist: the cheapest complete kernel entry and exit.
        sys::raw(0, 0, 0, 0, 0);
        *s = (rdtsc() - t0) as u32;
    }
    report("null_syscall", &mut samples);
    let _ = sys::system_halt(true);
}
