//! A client of the PLC online protocol (scenario `plc_online`), as another partition would
//! be: queuing ports `cmd` (requests out) and `reply` (responses in), size 256. What it
//! asks depends on its partition name:
//!
//! * `client` (the tank PLC, access "download"): LIST, READ `valve`, FORCE `valve` := 0.25
//!   for 300 frames (the plant shows it), UNFORCE, STATS of task 0, a malformed request;
//!   STOP task 0 for 200 frames (the plant sees the safe valve) and START it (STATS each
//!   time); WRITE the RETAIN `tank.alarm_count` := 42; two bad downloads (a wrong CRC-32, a
//!   truncated image) and READ `tank.revision` (still unknown); then the download of its
//!   data entry (the image of tests/configs/plc/tank_v2.st, `data.plc_image`) and READ
//!   `tank.revision` and `tank.alarm_count` from the new program; then it ends the run (an
//!   application error the configuration maps to `shutdown_success`);
//! * `viewer` (a PLC with access "monitor"): READs (also of a TOD and a WSTRING, printed as
//!   their IEC literals), then a WRITE, a FORCE, a STOP and a DOWNLOAD_BEGIN, which must be
//!   refused;
//! * `bench` (`cargo xtask bench`, tests/configs/bench_plc.toml): times [`BENCH_READS`] READs
//!   of `Count.n` from sending the request to receiving the answer (TSC cycles) and prints
//!   `bench plc_online_read ...`, then lets the PLC run [`BENCH_FRAMES`] more frames before it
//!   ends the run.
//!
//! Each answer is printed as `<name>: <OP> -> <STATUS> ...`. A test program: it must never
//! be needed by anything but its scenario.
#![no_std]
#![no_main]

use apex::Warden;
use apex::a653rs::prelude::*;
use apex::main_process::{self, Release};
use apex::user_rt::println;
use apex::user_rt::sys::rdtsc;
use core::str::FromStr;
use core::time::Duration;
use plc_online::{
    MAX_CHUNK, MAX_MESSAGE, Request, Status, crc32, decode_response, encode_request, read_stats,
};
use plc_vm::vm::Value;

fn name(text: &str) -> Name {
    Name::from_str(text).expect("names here are short")
}

fn wait_frames(n: u32) {
    for _ in 0..n {
        <Warden as ApexTimeP4Ext>::periodic_wait().expect("PERIODIC_WAIT");
    }
}

struct Link {
    cmd: QueuingPortSender<Warden>,
    reply: QueuingPortReceiver<Warden>,
    me: &'static str,
    seq: u8,
}

impl Link {
    /// Sends raw bytes and waits (frame by frame, at most 100) for the answer.
    fn exchange(&mut self, request: &[u8], answer: &mut [u8; MAX_MESSAGE]) -> Option<usize> {
        let poll = || SystemTime::Normal(Duration::ZERO);
        if let Err(e) = self.cmd.send(request, poll()) {
            println!("{}: send failed: {e:?}", self.me);
            return None;
        }
        for _ in 0..100 {
            wait_frames(1);
            if let Ok((message, _)) = self.reply.receive(answer, poll()) {
                return Some(message.len());
            }
        }
        println!("{}: no answer", self.me);
        None
    }

    /// Sends `r` and prints the answer's head; returns its status and result bytes.
    fn ask(&mut self, r: Request) -> Option<(Status, [u8; MAX_MESSAGE], usize)> {
        let answer = self.ask_quietly(r)?;
        let (op, _, status, _) = decode_response(&answer.1[..answer.2])?;
        println!("{}: {} -> {}", self.me, op.name(), status.name());
        Some(answer)
    }

    /// [`Link::ask`] without printing.
    fn ask_quietly(&mut self, r: Request) -> Option<(Status, [u8; MAX_MESSAGE], usize)> {
        self.seq = self.seq.wrapping_add(1);
        let mut request = [0u8; MAX_MESSAGE];
        let n = encode_request(&r, self.seq, &mut request)?;
        let mut answer = [0u8; MAX_MESSAGE];
        let len = self.exchange(&request[..n], &mut answer)?;
        let (_, seq, status, _) = decode_response(&answer[..len])?;
        if seq != self.seq {
            println!("{}: answer to seq {seq}, expected {}", self.me, self.seq);
        }
        Some((status, answer, len))
    }
}

fn read(link: &mut Link, var: &str) {
    if let Some((Status::Ok, answer, len)) = link.ask(Request::Read { name: var }) {
        let (_, _, _, mut r) = decode_response(&answer[..len]).expect("decoded above");
        match r.value() {
            Some(v) => println!("{}: {var} = {v}", link.me),
            None => println!("{}: {var}: bad value", link.me),
        }
    }
}

/// STATS of task 0, printed as `<me>: stats <name> stopped=<bool> cycles=<n> ...`.
fn stats(link: &mut Link) {
    if let Some((Status::Ok, answer, len)) = link.ask(Request::Stats { task: 0 }) {
        let (_, _, _, mut r) = decode_response(&answer[..len]).expect("decoded above");
        if let Some(s) = read_stats(&mut r) {
            let [count, _, _, _, max, _, max_jitter, overruns, faults] = s.figures;
            println!(
                "{}: stats {} stopped={} cycles={count} max_us={} max_jitter_us={} overruns={overruns} faults={faults}",
                link.me,
                s.name,
                s.stopped,
                max / 1000,
                max_jitter / 1000
            );
        }
    }
}

/// Downloads `image` announcing `crc`: BEGIN, the chunks, COMMIT; prints
/// `client: download <what>: <STATUS>` with the status of the first step that was not OK
/// (or COMMIT's) and, after an OK commit, the release from which the program runs.
fn download(link: &mut Link, what: &str, image: &[u8], crc: u32) {
    let begin = Request::DownloadBegin {
        size: image.len() as u32,
        crc32: crc,
    };
    let mut status = link.ask_quietly(begin).map(|a| a.0);
    for (i, bytes) in image.chunks(MAX_CHUNK).enumerate() {
        if status != Some(Status::Ok) {
            break;
        }
        let offset = (i * MAX_CHUNK) as u32;
        status = link
            .ask_quietly(Request::DownloadChunk { offset, bytes })
            .map(|a| a.0);
    }
    let mut release = None;
    if status == Some(Status::Ok) {
        let answer = link.ask_quietly(Request::DownloadCommit);
        status = answer.map(|a| a.0);
        release = answer.and_then(|(_, a, len)| {
            let (_, _, _, mut r) = decode_response(&a[..len])?;
            r.u64()
        });
    }
    match (status, release) {
        (Some(Status::Ok), Some(r)) => {
            println!("client: download {what}: OK, runs from release {r}")
        }
        (Some(status), _) => println!("client: download {what}: {}", status.name()),
        (None, _) => println!("client: download {what}: no answer"),
    }
}

fn client(link: &mut Link) {
    if let Some((Status::Ok, answer, len)) = link.ask(Request::List { from: 0 }) {
        let (_, _, _, mut r) = decode_response(&answer[..len]).expect("decoded above");
        let (total, count) = (r.u16().unwrap_or(0), r.u8().unwrap_or(0));
        let first = r.u8().and_then(|_| r.short_str()).unwrap_or("?");
        println!("client: list total={total} count={count} first={first}");
    }
    read(link, "valve");
    let force = Request::Force {
        name: "valve",
        value: Value::LReal(0.25),
    };
    link.ask(force);
    wait_frames(300);
    read(link, "valve");
    link.ask(Request::Unforce { name: "valve" });
    wait_frames(100);
    read(link, "valve");
    stats(link);
    let mut answer = [0u8; MAX_MESSAGE];
    if let Some(len) = link.exchange(&[3, 77, 0xff, 0xff], &mut answer)
        && let Some((op, seq, status, _)) = decode_response(&answer[..len])
    {
        println!(
            "client: malformed {} seq {seq} -> {}",
            op.name(),
            status.name()
        );
    }
    // Stop and start the tank task: the plant sees the safe valve meanwhile.
    link.ask(Request::Stop { task: 0 });
    stats(link);
    wait_frames(200);
    link.ask(Request::Start { task: 0 });
    wait_frames(2);
    stats(link);
    // Online download: a RETAIN value to keep, two bad downloads, then the good one.
    link.ask(Request::Write {
        name: "tank.alarm_count",
        value: Value::UInt(42),
    });
    let image = apex::runtime::start_info().data();
    let crc = crc32(image);
    download(link, "bad-checksum", image, crc ^ 0x5a5a);
    let cut = &image[..image.len() / 2];
    download(link, "truncated", cut, crc32(cut));
    read(link, "tank.revision");
    download(link, "tank_v2", image, crc);
    wait_frames(5);
    read(link, "tank.revision");
    read(link, "tank.alarm_count");
    stats(link);
    wait_frames(50);
    println!("client: done");
    let _ = <Warden as ApexErrorP4Ext>::raise_application_error(b"done");
}

/// READs timed by the `bench` role.
const BENCH_READS: usize = 200;
/// Frames the `bench` role waits after its reads: with 1 ms frames, enough for the PLC's
/// 10,000 releases of `plc_release_jitter` to be in its last statistics line.
const BENCH_FRAMES: u32 = 12_000;

fn bench(link: &mut Link) {
    let mut samples = [0u64; BENCH_READS];
    let mut request = [0u8; MAX_MESSAGE];
    let mut answer = [0u8; MAX_MESSAGE];
    let mut taken = 0;
    for sample in samples.iter_mut() {
        link.seq = link.seq.wrapping_add(1);
        let read = Request::Read { name: "Count.n" };
        let Some(n) = encode_request(&read, link.seq, &mut request) else {
            break;
        };
        let start = rdtsc();
        let Some(len) = link.exchange(&request[..n], &mut answer) else {
            break;
        };
        *sample = rdtsc().saturating_sub(start);
        match decode_response(&answer[..len]) {
            Some((_, seq, Status::Ok, _)) if seq == link.seq => taken += 1,
            _ => {
                println!("bench: bad answer to READ seq {}", link.seq);
                break;
            }
        }
    }
    let samples = &mut samples[..taken];
    samples.sort_unstable();
    if let (Some(min), Some(max)) = (samples.first(), samples.last()) {
        println!(
            "bench plc_online_read median={} min={min} max={max} unit=cycles samples={taken}",
            samples[taken / 2]
        );
    }
    wait_frames(BENCH_FRAMES);
    println!("bench: done");
    let _ = <Warden as ApexErrorP4Ext>::raise_application_error(b"done");
}

fn viewer(link: &mut Link) {
    read(link, "Count.n");
    read(link, "Count.shift_start");
    read(link, "Count.label");
    link.ask(Request::Write {
        name: "Count.n",
        value: Value::UInt(0),
    });
    link.ask(Request::Force {
        name: "Count.n",
        value: Value::UInt(0),
    });
    read(link, "Count.n");
    link.ask(Request::Stop { task: 0 });
    link.ask(Request::DownloadBegin { size: 16, crc32: 0 });
    println!("viewer: done");
}

extern "C" fn run() {
    let me = apex::runtime::start_info();
    let me: &'static str = match me.name() {
        "viewer" => "viewer",
        "bench" => "bench",
        _ => "client",
    };
    let mut link = Link {
        cmd: QueuingPortSender::<Warden>::from_name(name("cmd")).expect("cmd"),
        reply: QueuingPortReceiver::<Warden>::from_name(name("reply")).expect("reply"),
        me,
        seq: 0,
    };
    // Let the PLC start its cycles.
    wait_frames(50);
    match me {
        "viewer" => viewer(&mut link),
        "bench" => bench(&mut link),
        _ => client(&mut link),
    }
    loop {
        wait_frames(100);
    }
}

struct Client;

impl Partition<Warden> for Client {
    fn cold_start(&self, ctx: &mut StartContext<Warden>) {
        ctx.create_queuing_port_sender(name("cmd"), MAX_MESSAGE as u32, 4, QueuingDiscipline::Fifo)
            .expect("CREATE_QUEUING_PORT cmd");
        ctx.create_queuing_port_receiver(
            name("reply"),
            MAX_MESSAGE as u32,
            4,
            QueuingDiscipline::Fifo,
        )
        .expect("CREATE_QUEUING_PORT reply");
        main_process::start(ctx, "run", run, 16 * 1024, Release::PartitionPeriod)
            .unwrap_or_else(|e| panic!("{e}"));
    }

    fn warm_start(&self, ctx: &mut StartContext<Warden>) {
        self.cold_start(ctx)
    }
}

fn main() {
    Client.run()
}

apex::partition_entry!(main);
