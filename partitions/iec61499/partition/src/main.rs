//! The IEC 61499 partition program: a device of function-block resources
//! (`iec61499_mgmt::Device`) booted from the partition's data entry, the device package
//! `cargo xtask` wrote from `iec61499.*` (`iec61499_mgmt::package`).
//!
//! One APEX process, the device process, owns the device: it boots the package at its
//! first run, then waits until the earliest timer of a running resource (E_CYCLE,
//! E_DELAY, ...), fires every timer due, and waits again. Timers are absolute instants
//! (`Device::advance`), so a late wake-up delays one firing but never shifts the ones
//! after it. The partition's sampling ports (created at start) are the process image of
//! the device's `PORT_IN_*`/`PORT_OUT_*` FBs (`iec61499_mgmt::sifb`); its queuing ports
//! other than the management pair (created at start) those of its PUBLISH_n/SUBSCRIBE_n
//! (`iec61499_mgmt::pubsub`): while a running resource has a subscriber, the process wakes
//! at least every `pubsub::POLL_NS` and lets it take what arrived. With management ports (`iec61499.mgmt`, created at start), the wait is a
//! RECEIVE_QUEUING_MESSAGE on the request port: a request is answered on the response port
//! (`iec61499_mgmt::serve`, with the configured access) between event chains, never inside
//! one.
//!
//! Log lines (on the serial log as `[<partition>] iec61499: ...`; an interface):
//! - `iec61499: booted: <t> type(s), <n> boot request(s)` when the package booted, then
//!   `iec61499: management on <request>/<response>, access <level>` with management ports;
//! - `iec61499: refusing the boot package: <reason>` when it did not (reported to the
//!   health monitor as APPLICATION_ERROR; the process stops, the partition idles);
//! - every line the device logs (`iec61499_mgmt::Device::take_log`): the test FBs'
//!   results and `resource <name> stopped: <fault>` when a fault (an event-queue overflow,
//!   a chain too long, an algorithm's trap) stops a resource, which is also reported to
//!   the health monitor as APPLICATION_ERROR with that text (the other resources go on);
//! - `iec61499: t=<ms>ms timers=<n> lateness_ns=<min>/<mean>/<max>` at every whole
//!   [`STATS_EVERY_MS`] of the partition's clock (`t`) while timers fire: how many wake-ups
//!   for timers there were since the line before and how late after its instant each ran
//!   (an instant outside the partition's windows waits for the next one; inside them, on
//!   virtual time, the lateness is the runtime's own cost), then
//!   `iec61499: t=<ms>ms watch <RESOURCE>.<FB>.<PORT>=<value> ...` for the watched ports
//!   (values as IEC literals; as many lines as they need).
#![no_std]
#![no_main]

extern crate alloc;

use alloc::boxed::Box;
use alloc::string::String;
use alloc::vec::Vec;
use apex::Warden;
use apex::a653rs::prelude::*;
use apex::main_process::{self, Release};
use apex::user_rt::println;
use core::str::FromStr;
use core::time::Duration;
use iec61499_mgmt::Device;
use iec61499_mgmt::package::{DataQueue, MgmtPorts, QueuingPort, SamplingPort};
use iec61499_mgmt::serve::{Access, serve};
use iec61499_mgmt::sifb::ProcessIo;

/// How often the statistics line is printed.
const STATS_EVERY_MS: i64 = 1000;
/// How long the device process sleeps when no resource has a timer.
const IDLE: Duration = Duration::from_millis(100);
/// The heap: the device's resources, FB instances, types and event queues.
const HEAP: usize = 1024 * 1024;

fn now_ns() -> i64 {
    <Warden as ApexTimeP4Ext>::get_time()
        .unwrap_duration()
        .as_nanos() as i64
}

/// Prints `text` and reports it to the health monitor as an application error.
fn report(text: &str) {
    println!("iec61499: {text}");
    let _ = <Warden as ApexErrorP4Ext>::raise_application_error(text.as_bytes());
}

/// Prints the lines the device logged; a fault among them goes to the health monitor.
fn drain(device: &mut Device, faults_seen: &mut u32) {
    let faults = device.report().faults;
    for line in device.take_log() {
        println!("iec61499: {line}");
        if faults != *faults_seen && line.starts_with("resource ") {
            let _ = <Warden as ApexErrorP4Ext>::raise_application_error(line.as_bytes());
        }
    }
    *faults_seen = faults;
}

/// The watched ports' values (watches come from the boot file or a management client),
/// as many to a line as fit the partition's log lines.
fn print_watches(device: &Device, at_ns: i64) {
    let mut line = String::new();
    for (name, value) in device.watched() {
        if line.len() + name.len() + value.len() > 160 {
            println!("iec61499: t={}ms watch{line}", at_ns / 1_000_000);
            line.clear();
        }
        line.push_str(&alloc::format!(" {name}={value}"));
    }
    if !line.is_empty() {
        println!("iec61499: t={}ms watch{line}", at_ns / 1_000_000);
    }
}

/// Lateness of the timer wake-ups since the last statistics line.
#[derive(Default)]
struct Lateness {
    count: u64,
    sum: i64,
    min: i64,
    max: i64,
}

impl Lateness {
    fn add(&mut self, ns: i64) {
        if self.count == 0 || ns < self.min {
            self.min = ns;
        }
        self.max = self.max.max(ns);
        self.sum += ns;
        self.count += 1;
    }
}

/// The management ports, opened by the device process (created at start).
struct Mgmt {
    request: QueuingPortReceiver<Warden>,
    response: QueuingPortSender<Warden>,
    access: Access,
    size: usize,
}

impl Mgmt {
    fn open(ports: &MgmtPorts<'_>) -> Option<Self> {
        Some(Mgmt {
            request: QueuingPortReceiver::from_name(Name::from_str(ports.request.name).ok()?)
                .ok()?,
            response: QueuingPortSender::from_name(Name::from_str(ports.response.name).ok()?)
                .ok()?,
            access: ports.access,
            size: ports.response.size as usize,
        })
    }
}

/// The partition's sampling ports (created at start) for the process-image FBs.
struct ApexIo {
    ports: Vec<(String, usize, Sampling)>,
    /// PUBLISH/SUBSCRIBE's queuing ports.
    queues: Vec<(String, usize, Queuing)>,
}

enum Queuing {
    In(QueuingPortReceiver<Warden>),
    Out(QueuingPortSender<Warden>),
}

enum Sampling {
    In(SamplingPortDestination<Warden>),
    Out(SamplingPortSource<Warden>),
}

impl ApexIo {
    fn open(ports: &[SamplingPort<'_>], queues: &[DataQueue<'_>]) -> Self {
        let queues = queues
            .iter()
            .filter_map(|q| {
                let name = Name::from_str(q.port.name).ok()?;
                let port = if q.input {
                    Queuing::In(QueuingPortReceiver::from_name(name).ok()?)
                } else {
                    Queuing::Out(QueuingPortSender::from_name(name).ok()?)
                };
                Some((q.port.name.into(), q.port.size as usize, port))
            })
            .collect();
        let ports = ports
            .iter()
            .filter_map(|p| {
                let name = Name::from_str(p.name).ok()?;
                let port = if p.input {
                    Sampling::In(SamplingPortDestination::from_name(name).ok()?)
                } else {
                    Sampling::Out(SamplingPortSource::from_name(name).ok()?)
                };
                Some((p.name.into(), p.size as usize, port))
            })
            .collect();
        ApexIo { ports, queues }
    }

    fn find(&self, port: &str) -> Option<&(String, usize, Sampling)> {
        self.ports.iter().find(|(name, _, _)| name == port)
    }
}

impl ProcessIo for ApexIo {
    fn size(&self, port: &str, input: bool) -> Option<usize> {
        match self.find(port)? {
            (_, size, Sampling::In(_)) if input => Some(*size),
            (_, size, Sampling::Out(_)) if !input => Some(*size),
            _ => None,
        }
    }

    fn read(&mut self, port: &str, buf: &mut [u8]) -> Option<bool> {
        match self.find(port)? {
            (_, _, Sampling::In(p)) => p
                .receive(buf)
                .ok()
                .filter(|(_, message)| !message.is_empty())
                .map(|(validity, _)| validity == Validity::Valid),
            _ => None,
        }
    }

    fn write(&mut self, port: &str, message: &[u8]) -> bool {
        match self.find(port) {
            Some((_, _, Sampling::Out(p))) => p.send(message).is_ok(),
            _ => false,
        }
    }

    fn queue_size(&self, port: &str, input: bool) -> Option<usize> {
        match self.queues.iter().find(|(name, _, _)| name == port)? {
            (_, size, Queuing::In(_)) if input => Some(*size),
            (_, size, Queuing::Out(_)) if !input => Some(*size),
            _ => None,
        }
    }

    fn receive(&mut self, port: &str, buf: &mut [u8]) -> Option<usize> {
        match self.queues.iter().find(|(name, _, _)| name == port)? {
            (_, _, Queuing::In(p)) => p
                .receive(buf, SystemTime::Normal(Duration::ZERO))
                .ok()
                .map(|(message, _)| message.len()),
            _ => None,
        }
    }

    fn send(&mut self, port: &str, message: &[u8]) -> bool {
        match self.queues.iter().find(|(name, _, _)| name == port) {
            Some((_, _, Queuing::Out(p))) => {
                p.send(message, SystemTime::Normal(Duration::ZERO)).is_ok()
            }
            _ => false,
        }
    }
}

/// Waits `timeout` for a request and answers it; false when the wait failed.
fn wait(device: &mut Device, mgmt: Option<&Mgmt>, timeout: Duration, buf: &mut [u8]) -> bool {
    let Some(m) = mgmt else {
        return <Warden as ApexTimeP1Ext>::timed_wait(timeout).is_ok();
    };
    match m.request.receive(buf, SystemTime::Normal(timeout)) {
        Ok((message, _)) => {
            let answer = serve(device, message, m.access, m.size, now_ns());
            if m.response
                .send(answer.as_bytes(), SystemTime::Normal(Duration::ZERO))
                .is_err()
            {
                println!("iec61499: management response dropped: the response port is full");
            }
            true
        }
        Err(Error::TimedOut) => true,
        // A message the port could not hand over whole: sleep as without a client rather
        // than spin on it.
        Err(Error::InvalidConfig | Error::NotAvailable) => {
            <Warden as ApexTimeP1Ext>::timed_wait(timeout).is_ok()
        }
        Err(e) => {
            report(&alloc::format!("RECEIVE_QUEUING_MESSAGE failed: {e:?}"));
            false
        }
    }
}

extern "C" fn device_process() {
    let info = apex::runtime::start_info();
    let package = match iec61499_mgmt::package::decode(info.data()) {
        Ok(package) => package,
        Err(reason) => {
            report(&alloc::format!("refusing the boot package: {reason}"));
            return;
        }
    };
    let io = Box::new(ApexIo::open(&package.ports, &package.queues));
    let (mut device, booted) = match iec61499_mgmt::package::boot(info.data(), io, now_ns()) {
        Ok(booted) => booted,
        Err(reason) => {
            report(&alloc::format!("refusing the boot package: {reason}"));
            return;
        }
    };
    println!(
        "iec61499: booted: {} type(s), {} boot request(s)",
        booted.types, booted.requests
    );
    let mgmt = package.mgmt.as_ref().and_then(Mgmt::open);
    match (&package.mgmt, &mgmt) {
        (Some(p), Some(m)) => println!(
            "iec61499: management on {}/{}, access {:?}",
            p.request.name, p.response.name, m.access
        ),
        (Some(p), None) => report(&alloc::format!(
            "cannot open the management ports {}/{}",
            p.request.name,
            p.response.name
        )),
        (None, _) => {}
    }
    let mut buf = alloc::vec![0u8; package.mgmt.map_or(0, |p| p.request.size as usize)];
    let mut faults_seen = 0;
    drain(&mut device, &mut faults_seen);
    let mut lateness = Lateness::default();
    // On the whole seconds of the partition's clock, so a log names them predictably.
    let every = STATS_EVERY_MS * 1_000_000;
    let mut next_stats = (now_ns() / every + 1) * every;
    loop {
        let now = now_ns();
        if let Some(due) = device.next_deadline().filter(|&due| due <= now) {
            lateness.add(now - due);
            device.advance(now);
            drain(&mut device, &mut faults_seen);
        }
        if now >= next_stats && lateness.count > 0 {
            println!(
                "iec61499: t={}ms timers={} lateness_ns={}/{}/{}",
                next_stats / 1_000_000,
                lateness.count,
                lateness.min,
                lateness.sum / lateness.count as i64,
                lateness.max
            );
            lateness = Lateness::default();
            print_watches(&device, next_stats);
            next_stats = (now / every + 1) * every;
        }
        if device.polls() {
            device.poll(now_ns());
            drain(&mut device, &mut faults_seen);
        }
        let now = now_ns();
        // A subscriber's messages wait at most one poll period.
        let idle = if device.polls() {
            Duration::from_nanos(iec61499_mgmt::pubsub::POLL_NS as u64)
        } else {
            IDLE
        };
        let sleep = match device.next_deadline() {
            Some(due) if due <= now => continue,
            Some(due) => Duration::from_nanos((due - now) as u64).min(idle),
            None => idle,
        };
        if !wait(&mut device, mgmt.as_ref(), sleep, &mut buf) {
            return;
        }
        drain(&mut device, &mut faults_seen);
    }
}

struct Iec61499Partition;

impl Iec61499Partition {
    fn start(&self, ctx: &mut StartContext<Warden>) {
        let Ok(package) = iec61499_mgmt::package::decode(apex::runtime::start_info().data()) else {
            // The device process reports it.
            return self.spawn(ctx);
        };
        for p in &package.ports {
            let created = Name::from_str(p.name)
                .map_err(|_| Error::InvalidParam)
                .and_then(|n| {
                    if p.input {
                        let refresh = Duration::from_nanos(p.refresh_ns);
                        ctx.create_sampling_port_destination(n, p.size, refresh)
                            .map(drop)
                    } else {
                        ctx.create_sampling_port_source(n, p.size).map(drop)
                    }
                });
            if let Err(e) = created {
                report(&alloc::format!(
                    "creating sampling port {} failed: {e:?}",
                    p.name
                ));
            }
        }
        for q in &package.queues {
            let created = Name::from_str(q.port.name)
                .map_err(|_| Error::InvalidParam)
                .and_then(|n| {
                    if q.input {
                        ctx.create_queuing_port_receiver(
                            n,
                            q.port.size,
                            q.port.depth,
                            QueuingDiscipline::Fifo,
                        )
                        .map(drop)
                    } else {
                        ctx.create_queuing_port_sender(
                            n,
                            q.port.size,
                            q.port.depth,
                            QueuingDiscipline::Fifo,
                        )
                        .map(drop)
                    }
                });
            if let Err(e) = created {
                report(&alloc::format!(
                    "creating queuing port {} failed: {e:?}",
                    q.port.name
                ));
            }
        }
        if let Some(m) = package.mgmt {
            let port =
                |p: &QueuingPort<'_>| Name::from_str(p.name).map_err(|_| Error::InvalidParam);
            let created = port(&m.request)
                .and_then(|n| {
                    ctx.create_queuing_port_receiver(
                        n,
                        m.request.size,
                        m.request.depth,
                        QueuingDiscipline::Fifo,
                    )
                    .map(drop)
                })
                .and_then(|()| port(&m.response))
                .and_then(|n| {
                    ctx.create_queuing_port_sender(
                        n,
                        m.response.size,
                        m.response.depth,
                        QueuingDiscipline::Fifo,
                    )
                    .map(drop)
                });
            if let Err(e) = created {
                report(&alloc::format!(
                    "creating the management ports failed: {e:?}"
                ));
            }
        }
        self.spawn(ctx);
    }

    /// Creates and starts the device process.
    fn spawn(&self, ctx: &mut StartContext<Warden>) {
        let stack = apex::table::MIN_STACK as u32;
        if let Err(e) =
            main_process::start(ctx, "device", device_process, stack, Release::Aperiodic)
        {
            report(&alloc::format!("{e}"));
        }
    }
}

impl Partition<Warden> for Iec61499Partition {
    fn cold_start(&self, ctx: &mut StartContext<Warden>) {
        self.start(ctx)
    }

    fn warm_start(&self, ctx: &mut StartContext<Warden>) {
        self.start(ctx)
    }
}

fn main() {
    Iec61499Partition.run()
}

apex::partition_entry!(main, heap = HEAP);
