//! Kernel micro-benchmarks, run as the root task by `cargo xtask bench`. Prints one
//! `bench NAME median=N min=N max=N unit=cycles samples=N` line per metric:
//!
//! * `null_syscall`: an unknown call number, the cheapest kernel entry and exit;
//! * `ipc_roundtrip`: `call` from the root to a server thread in a child task that answers
//!   from a `reply_wait` loop (register-only messages), measured in the root;
//!   `ipc_roundtrip_cross_cpu` the same with the server on CPU 1 (only on a machine with
//!   a second CPU);
//! * `exception_roundtrip`: a thread of the root task executes `ud2`; its handler (the
//!   root's main thread) advances rip by 2 and replies `REPLY_RESUME`; measured in the
//!   faulting thread from before the fault to after the resume;
//! * `window_switch` (cycles) and `window_jitter` (ns): a schedule of 1 ms frames with
//!   TP1 [0, 400 us) and TP2 [500, 900 us); a thread spins in TP1, another in TP2 records,
//!   for 10,000 window starts, how long after the scheduled start its first instruction ran
//!   (`user_rt::window`): the cost of the switch (timer deadline to the first user
//!   instruction of the next partition, including the timer's own delay under QEMU), and
//!   its spread in ns.
#![no_std]
#![no_main]

use core::sync::atomic::{AtomicU64, Ordering};
use root_task::spawn::{AddressRange, FramePool, Spawner, words_at};
use user_rt::abi::ipc::{EXCEPTION_MESSAGE_SIZE, LABEL_EXCEPTION, MessageTag, REPLY_RESUME};
use user_rt::abi::syscall::{Abilities, TIMEOUT_INFINITE, ThreadAttribute, ThreadId, WindowSpec};
use user_rt::ipc_buffer::IpcBufferRef;
use user_rt::println;
use user_rt::sys::{self, Message};

user_rt::entry!(main);

const SAMPLES: usize = 10_000;
const WARMUP: usize = 1000;
/// Where the spawner takes the root's addresses from.
const SPAWN_BASE: u64 = 0x0000_1000_0000_0000;
const SPAWN_END: u64 = 0x0000_2000_0000_0000;
/// Word index of `rip` in an `ExceptionMessage` (vector, error code, fault address, thread,
/// task, then rax..r15 = 16 registers, then rip).
const RIP_WORD: usize = 5 + 16;

fn rdtsc() -> u64 {
    #[allow(unsafe_code)]
    // SAFETY: RDTSC only reads the time-stamp counter (CR4.TSD is clear).
    unsafe {
        core::arch::x86_64::_rdtsc()
    }
}

fn report(name: &str, samples: &mut [u32]) {
    report_in(name, "cycles", samples);
}

fn report_in(name: &str, unit: &str, samples: &mut [u32]) {
    samples.sort_unstable();
    let median = samples[samples.len() / 2];
    println!(
        "bench {name} median={median} min={} max={} unit={unit} samples={}",
        samples[0],
        samples[samples.len() - 1],
        samples.len()
    );
}

/// Ends the run as failed with a reason (setup of a benchmark went wrong).
fn broken(what: &str, detail: impl core::fmt::Debug) -> ! {
    println!("bench setup failed: {what}: {detail:?}");
    let _ = sys::system_halt(false);
    sys::thread_exit()
}

fn main(_: u64, _: u64) {
    let mut samples = [0u32; SAMPLES];
    null_syscall(&mut samples);

    let mut spawner = Spawner::new(
        FramePool::from_root_info(),
        AddressRange::new(SPAWN_BASE, SPAWN_END),
    )
    .unwrap_or_else(|e| broken("spawner", e));
    let ipc = spawner
        .own_ipc_buffer()
        .unwrap_or_else(|e| broken("root IPC buffer", e));
    ipc_roundtrip(&mut spawner, &mut samples, None);
    ipc_roundtrip(&mut spawner, &mut samples, Some(1));
    exception_roundtrip(&mut spawner, ipc, &mut samples);
    windows(&mut spawner, &mut samples);
    let _ = sys::system_halt(true);
}

fn null_syscall(samples: &mut [u32; SAMPLES]) {
    // Warm up caches and the TLB.
    for _ in 0..WARMUP {
        sys::raw(0, 0, 0, 0, 0);
    }
    for s in samples.iter_mut() {
        let t0 = rdtsc();
        // Call number 0 does not exist: the cheapest complete kernel entry and exit.
        sys::raw(0, 0, 0, 0, 0);
        *s = (rdtsc() - t0) as u32;
    }
    report("null_syscall", samples);
}

/// Answers every call with its words, forever.
extern "C" fn echo_server(_: u64) -> ! {
    let mut next = sys::receive(None, TIMEOUT_INFINITE);
    loop {
        next = match next {
            Ok(m) => sys::reply_wait(
                Some(m.sender),
                TIMEOUT_INFINITE,
                &Message::new(0, m.message.words),
            ),
            Err(_) => sys::receive(None, TIMEOUT_INFINITE),
        };
    }
}

/// The round trip to a server on the root's CPU, or on `cpu` (skipped if it is not online).
fn ipc_roundtrip(spawner: &mut Spawner, samples: &mut [u32; SAMPLES], cpu: Option<u64>) {
    let task = spawner
        .create_task(Abilities::NATIVE_SYSCALLS, 255, 0, "bench-server")
        .unwrap_or_else(|e| broken("server task", e));
    // Above the root: it starts at once and waits in `receive` before the first call.
    let server = spawner
        .thread(Some(task), echo_server, 210, 0, 4)
        .unwrap_or_else(|e| broken("server thread", e));
    if let Some(cpu) = cpu
        && sys::thread_set(Some(server.id), ThreadAttribute::Cpu, cpu).is_err()
    {
        println!("bench: CPU {cpu} is not online: no ipc_roundtrip_cross_cpu");
        let _ = sys::task_kill(task);
        return;
    }
    sys::thread_start(server.id).unwrap_or_else(|e| broken("thread_start", e));
    let m = Message::new(1, [1, 2, 3]);
    for _ in 0..WARMUP {
        sys::ipc_call(server.id, TIMEOUT_INFINITE, &m).unwrap_or_else(|e| broken("call", e));
    }
    for s in samples.iter_mut() {
        let t0 = rdtsc();
        let r = sys::ipc_call(server.id, TIMEOUT_INFINITE, &m);
        *s = (rdtsc() - t0) as u32;
        if r.is_err() {
            broken("call", r);
        }
    }
    report(
        match cpu {
            None => "ipc_roundtrip",
            Some(_) => "ipc_roundtrip_cross_cpu",
        },
        samples,
    );
    let _ = sys::task_kill(task);
}

/// Faults `WARMUP + SAMPLES` times (ud2, which the handler skips), recording each round
/// trip in the words at `arg`; sets the word after the samples when done.
extern "C" fn faulter(arg: u64) -> ! {
    #[allow(unsafe_code)]
    // SAFETY: `arg` is the address of `WARMUP + SAMPLES + 1` words the root mapped for
    // good in its own task (this thread's task) with `shared_words`; only used atomically.
    let words = unsafe { words_at(arg, WARMUP + SAMPLES + 1) };
    for word in &words[..WARMUP + SAMPLES] {
        let t0 = rdtsc();
        #[allow(unsafe_code)]
        // SAFETY: `ud2` raises #UD; the handler resumes 2 bytes later, right after it,
        // with all registers unchanged.
        unsafe {
            core::arch::asm!("ud2", options(nostack))
        };
        word.store(rdtsc() - t0, Ordering::Relaxed);
    }
    words[WARMUP + SAMPLES].store(1, Ordering::Release);
    sys::thread_exit()
}

fn exception_roundtrip(spawner: &mut Spawner, ipc: IpcBufferRef, samples: &mut [u32; SAMPLES]) {
    let total = WARMUP + SAMPLES;
    let words: &'static [AtomicU64] = spawner
        .shared_words(None, total + 1)
        .unwrap_or_else(|e| broken("sample memory", e));
    let thread = spawner
        .thread(None, faulter, 100, words.as_ptr() as u64, 4)
        .unwrap_or_else(|e| broken("faulting thread", e));
    let (me, _) = sys::thread_self();
    sys::thread_set(Some(thread.id), ThreadAttribute::ExceptionHandler, me.0)
        .unwrap_or_else(|e| broken("thread_set ExceptionHandler", e));
    sys::thread_start(thread.id).unwrap_or_else(|e| broken("thread_start", e));

    let f: ThreadId = thread.id;
    let resume = Message {
        tag: MessageTag::new(REPLY_RESUME, EXCEPTION_MESSAGE_SIZE, 0),
        words: [0; 3],
    };
    let mut next = sys::receive(Some(f), TIMEOUT_INFINITE);
    for i in 0..total {
        match next {
            Ok(m) if m.message.tag.label() == LABEL_EXCEPTION => {}
            other => broken("exception message", other),
        }
        // The message is still in the buffer: skip the 2-byte ud2 and send it back.
        ipc.set_data_word(RIP_WORD, ipc.data_word(RIP_WORD) + 2);
        if i + 1 < total {
            next = sys::reply_wait(Some(f), TIMEOUT_INFINITE, &resume);
        } else {
            sys::reply(f, &resume).unwrap_or_else(|e| broken("reply", e));
        }
    }
    while words[total].load(Ordering::Acquire) == 0 {
        sys::sleep(1_000_000);
    }
    for (s, w) in samples.iter_mut().zip(&words[WARMUP..total]) {
        *s = w.load(Ordering::Relaxed) as u32;
    }
    report("exception_roundtrip", samples);
}

const WINDOW_FRAME: u64 = 1_000_000;
/// Header words before the window samples: done flag, outside, missed, pauses.
const WINDOW_HEADER: usize = 4;

extern "C" fn window_spinner(_: u64) -> ! {
    loop {
        core::hint::spin_loop();
    }
}

/// Records SAMPLES window starts of TP2 into the words at `arg` (after the header).
extern "C" fn window_meter(arg: u64) -> ! {
    #[allow(unsafe_code)]
    // SAFETY: the root mapped WINDOW_HEADER + SAMPLES words at `arg` in this thread's task
    // for good; only used atomically.
    let words = unsafe { words_at(arg, WINDOW_HEADER + SAMPLES) };
    let seen = test_support::window::measure_window_starts(
        2,
        WINDOW_FRAME,
        50_000,
        &words[WINDOW_HEADER..],
    );
    words[1].store(seen.outside, Ordering::Relaxed);
    words[2].store(seen.missed, Ordering::Relaxed);
    words[3].store(seen.pauses, Ordering::Relaxed);
    words[0].store(1, Ordering::Release);
    loop {
        core::hint::spin_loop();
    }
}

fn windows(spawner: &mut Spawner, samples: &mut [u32; SAMPLES]) {
    let task = spawner
        .create_task(Abilities::NATIVE_SYSCALLS, 100, 0, "bench-windows")
        .unwrap_or_else(|e| broken("window task", e));
    let words: &'static [AtomicU64] = spawner
        .shared_words(Some(task), WINDOW_HEADER + SAMPLES)
        .unwrap_or_else(|e| broken("window sample memory", e));
    let spin = spawner
        .thread(Some(task), window_spinner, 100, 0, 4)
        .unwrap_or_else(|e| broken("spinner", e));
    let meter = spawner
        .thread(Some(task), window_meter, 100, words.as_ptr() as u64, 4)
        .unwrap_or_else(|e| broken("meter", e));
    for (thread, tp) in [(spin.id, 1), (meter.id, 2)] {
        sys::thread_set(Some(thread), ThreadAttribute::TimePartition, tp)
            .unwrap_or_else(|e| broken("thread_set TimePartition", e));
    }
    let window = |offset, duration, partition| WindowSpec {
        offset,
        duration,
        partition,
        cpu: 0,
    };
    sys::schedule_set(
        0,
        WINDOW_FRAME,
        &[window(0, 400_000, 1), window(500_000, 400_000, 2)],
    )
    .unwrap_or_else(|e| broken("schedule_set", e));
    sys::schedule_switch(0).unwrap_or_else(|e| broken("schedule_switch", e));
    for thread in [spin.id, meter.id] {
        sys::thread_start(thread).unwrap_or_else(|e| broken("thread_start", e));
    }
    // Sleep through the measurement (the root is in TP0 at a higher priority: waking up
    // inside TP2's window would count as lateness).
    sys::sleep(SAMPLES as u64 * WINDOW_FRAME + 50_000_000);
    while words[0].load(Ordering::Acquire) == 0 {
        sys::sleep(100_000_000);
    }
    let base = sys::TscBase::get();
    for (s, w) in samples.iter_mut().zip(&words[WINDOW_HEADER..]) {
        *s = w.load(Ordering::Relaxed).min(u32::MAX as u64) as u32;
    }
    report("window_switch", samples);
    for s in samples.iter_mut() {
        *s = base.ns(*s as u64) as u32;
    }
    report_in("window_jitter", "ns", samples);
    println!(
        "windows: {} runs outside the window, {} windows lost, {} pauses inside windows",
        words[1].load(Ordering::Relaxed),
        words[2].load(Ordering::Relaxed),
        words[3].load(Ordering::Relaxed)
    );
    let _ = sys::task_kill(task);
}
