//! `bench queuing_port_roundtrip`: one process sends a 64-byte message on a queuing port
//! whose channel leads back into the same partition and receives it, [`SAMPLES`] times;
//! each sample is the cycles for that pair of APEX calls (two requests served by syssw).
//! Prints the `cargo xtask bench` line, then ends the run (an APPLICATION_ERROR the bench
//! system maps to `shutdown_success`).

extern crate alloc;

use crate::{name, process, raise};
use alloc::vec::Vec;
use apex::Warden;
use apex::a653rs::prelude::*;
use apex::user_rt::println;
use apex::user_rt::sys::rdtsc;
use core::time::Duration;

/// Samples (kept on the runtime's bounded heap: 8 bytes each).
const SAMPLES: usize = 4_000;

pub fn create(ctx: &mut StartContext<Warden>) {
    ctx.create_queuing_port_sender(name("out"), 64, 4, QueuingDiscipline::Fifo)
        .expect("CREATE_QUEUING_PORT out");
    ctx.create_queuing_port_receiver(name("in"), 64, 4, QueuingDiscipline::Fifo)
        .expect("CREATE_QUEUING_PORT in");
    process(ctx, "roundtrip", roundtrip, None, None);
}

extern "C" fn roundtrip() {
    let out = QueuingPortSender::<Warden>::from_name(name("out")).expect("out");
    let inp = QueuingPortReceiver::<Warden>::from_name(name("in")).expect("in");
    let message = [0x5au8; 64];
    let mut buf = [0u8; 64];
    let poll = || SystemTime::Normal(Duration::ZERO);
    let mut samples = Vec::with_capacity(SAMPLES);
    for _ in 0..SAMPLES {
        let t0 = rdtsc();
        out.send(&message, poll()).expect("SEND_QUEUING_MESSAGE");
        let (got, _) = inp
            .receive(&mut buf, poll())
            .expect("RECEIVE_QUEUING_MESSAGE");
        let t1 = rdtsc();
        assert_eq!(got, &message[..], "the message comes back unchanged");
        samples.push(t1 - t0);
    }
    samples.sort_unstable();
    println!(
        "bench queuing_port_roundtrip median={} min={} max={} unit=cycles samples={SAMPLES}",
        samples[SAMPLES / 2],
        samples[0],
        samples[SAMPLES - 1]
    );
    raise(b"bench done");
}
