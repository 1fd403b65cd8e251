//! The IEC 61499 partition program: a device of function-block resources
//! (`iec61499_mgmt::Device`) booted from the partition's data entry, the device package
//! `cargo xtask` wrote from `iec61499.*` (`iec61499_mgmt::package`).
//!
//! The device process boots the package at its first run, then waits until the earliest
//! timer of a running resource (E_CYCLE, E_DELAY, ...), fires every timer due, and waits
//! again. Timers are absolute instants (`Device::advance_of`), so a late wake-up delays
//! one firing but never shifts the ones after it. A resource named in
//! `iec61499.resources` has a process of its own (`r:<resource>`, at the configured
//! priority; the device process runs just below the lowest of them) that fires that
//! resource's timers and runs the chains they start, sleeping until its resource's
//! earliest timer or until the device process wakes it (an APEX event set when a request
//! or a subscription gave that resource an earlier timer). The processes share the device
//! under one ARINC 653 mutex, the device mutex (its priority ceiling the highest resource
//! process's), taken for a request's execution, a timer's chains, a poll and the pumps of
//! the network tables, never while the network stack works or a request is read or
//! answered: so a resource process preempts the device process anywhere else and waits
//! at most for one request's execution or one chain of another resource. Events from
//! outside (requests, subscriptions) run their chains in the device process, whichever
//! resource they are for. Without `iec61499.resources` the device process is the only
//! one and takes no mutex.
//!
//! The partition's sampling ports (created at start) are the process image of the device's
//! `PORT_IN_*`/`PORT_OUT_*` FBs (`iec61499_mgmt::sifb`); its queuing ports other than the
//! management pair (created at start) those of its PUBLISH_n/SUBSCRIBE_n
//! (`iec61499_mgmt::pubsub`): while a running resource has a subscriber, the process wakes
//! at least every `pubsub::POLL_NS` and lets it take what arrived. With management ports
//! (`iec61499.mgmt`, created at start), the wait is a RECEIVE_QUEUING_MESSAGE on the
//! request port: a request is answered on the response port (`iec61499_mgmt::serve`, with
//! the configured access) between event chains, never inside one. With a network interface
//! (`iec61499.net`), the same process drives its TCP/IP stack and the management protocol's
//! TCP server (`iec61499_mgmt::tcp::server`): at every pass of its loop, and at least every
//! [`NET_POLL`] then (sooner: the frame port's and the management request port's doorbell,
//! which syssw rings when messages arrive there, end its wait), it takes the frames the NIC
//! partition delivered (at most `FRAMES_PER_RUN`), lets the server answer at most one whole
//! request of each connection on the device (between event chains, as above; an incomplete
//! request just waits in its connection's buffer), pumps the TCP links of CLIENT/SERVER
//! with an IP ID (`iec61499_mgmt::tcplink`: connections made and accepted, their bytes
//! moved between the links' buffers and the sockets) and the UDP endpoints of
//! PUBLISH/SUBSCRIBE with a UDP ID (`iec61499_mgmt::udp`: the datagrams the FBs queued go
//! out, those received go to their subscribers' queues, which the device's poll right after
//! the pass takes), and sends the frames out. The links and endpoints exist before the boot
//! (a boot file's FBs open theirs at START); the FBs reach them through the partition's
//! `ProcessIo` (`tcp_open`/.../`tcp_close`, `udp_open`/.../`udp_close`), never the stack
//! itself. Without `iec61499.net` an IP ID's INIT answers `no network interface`.
//!
//! Log lines (on the serial log as `[<partition>] iec61499: ...`; an interface):
//! - `iec61499: resource <name> runs in process r:<name> at priority <p>, the device
//!   process at <q>` at start for each resource with a process of its own;
//! - `iec61499: booted: <t> type(s), <n> boot request(s)` when the package booted, then
//!   `iec61499: management on <request>/<response>, access <level>` with management ports
//!   and `iec61499: net <address>/<prefix> mac <mac>: management on tcp port <port>,
//!   connections <n>, access <level>` with a network interface;
//! - with a network interface, per TCP client (at most [`EVENT_LINES`] a second; the
//!   statistics line counts them all): `iec61499: tcp: connection from <ip>:<port>`,
//!   `iec61499: tcp: refused <ip>:<port>: all connections in use`, `iec61499: tcp: closed
//!   <ip>:<port>: <why>` (a stream that is not requests, answered with a refusal first,
//!   or no progress for 10 s with an incomplete request or an unsent response), and once a
//!   second when they changed `iec61499: t=<ms>ms net open=<n> accepted=<n> refused=<n>
//!   requests=<n> malformed=<n> timed_out=<n> frames_in=<n> frames_out=<n>`;
//! - with a network interface, once a second when they changed, `iec61499: t=<ms>ms udp
//!   endpoints=<n> sent=<n> received=<n> dropped=<n> send_failed=<n> errors=<n>` (the UDP
//!   endpoints open and their datagrams: `dropped` found their subscriber's queue full),
//!   and `iec61499: udp: <why>` for a failure of the stack (a socket, a bind, a group
//!   join, a send; within the [`EVENT_LINES`] a second);
//! - with a network interface, once a second when they changed, `iec61499: t=<ms>ms tcp
//!   links=<n> connected=<n> refused=<n> ended=<n> bytes_out=<n> bytes_in=<n>` (the TCP
//!   links of CLIENT/SERVER open, the connections they made or accepted, those a busy
//!   server refused, those that ended, and the bytes of their streams);
//! - `iec61499: refusing the boot package: <reason>` when it did not (reported to the
//!   health monitor as APPLICATION_ERROR; the process stops, the partition idles);
//! - every line the device logs (`iec61499_mgmt::Device::take_log`): the test FBs'
//!   results and `resource <name> stopped: <fault>` when a fault (an event-queue overflow,
//!   a chain too long, an algorithm's trap) stops a resource, which is also reported to
//!   the health monitor as APPLICATION_ERROR with that text (the other resources go on);
//! - `iec61499: t=<ms>ms timers=<n> lateness_ns=<min>/<mean>/<max>` at every whole
//!   [`STATS_EVERY_MS`] of the partition's clock (`t`) while timers fire: how many wake-ups
//!   for timers there were since the line before (of every process) and how late after
//!   its instant each ran
//!   (an instant outside the partition's windows waits for the next one; inside them, on
//!   virtual time, the lateness is the runtime's own cost), then
//!   `iec61499: t=<ms>ms watch <RESOURCE>.<FB>.<PORT>=<value> ...` for the watched ports
//!   (values as IEC literals; as many lines as they need).
#![no_std]
#![no_main]

extern crate alloc;

use alloc::boxed::Box;
use alloc::rc::Rc;
use alloc::string::String;
use alloc::vec::Vec;
use apex::Warden;
use apex::a653rs::bindings::{
    ApexEventP1, ApexMutexP1, ApexProcessP1, EventId, INFINITE_TIME_VALUE,
};
use apex::a653rs::prelude::*;
use apex::main_process::{self, Release};
use apex::user_rt::println;
use core::cell::{RefCell, UnsafeCell};
use core::str::FromStr;
use core::sync::atomic::{AtomicI64, Ordering};
use core::time::Duration;
use driver_link::tenant::TenantLink;
use iec61499_mgmt::Device;
use iec61499_mgmt::package::{
    DataQueue, MAX_RESOURCES, MgmtPorts, NetPorts, QueuingPort, ResourceProcess, SamplingPort,
};
use iec61499_mgmt::pubsub::NetAddr;
use iec61499_mgmt::serve::{Access, DeviceAccess, refusal, serve};
use iec61499_mgmt::sifb::{NO_NETWORK, ProcessIo, TcpState};
use iec61499_mgmt::tcp::server::{self, Event, Server, Settings, Stats};
use iec61499_mgmt::tcplink::{TcpLinkStats, TcpLinks};
use iec61499_mgmt::udp::{Endpoints, UdpStats};
use iec61499_mgmt::{Reason, Request};

/// The name prefix of a resource's process and of the event that wakes it.
const RESOURCE_PROCESS_PREFIX: &str = "r:";
/// How often the statistics line is printed.
const STATS_EVERY_MS: i64 = 1000;
/// How long the device process sleeps when no resource has a timer.
const IDLE: Duration = Duration::from_millis(100);
/// The heap: the device's resources, FB instances, types and event queues; the TCP/IP
/// stack's sockets and the TCP connections' buffers.
const HEAP: usize = 2 * 1024 * 1024;
/// How often the device process looks at its network interface at least (with one).
const NET_POLL: Duration = Duration::from_millis(2);
/// The notification bit of the doorbells of the frame port and the management request
/// port (syssw rings it when messages arrive there; the APEX runtime's bits are 0 and 1).
const DOORBELL_BIT: u64 = 1 << 9;
/// Lines about TCP clients per second at most (a flood of clients must not keep the
/// partition writing to the log); the statistics line counts them all.
const EVENT_LINES: u32 = 10;

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
fn drain(shared: &mut Shared) {
    let faults = shared.device.report().faults;
    for line in shared.device.take_log() {
        println!("iec61499: {line}");
        if faults != shared.faults_seen && line.starts_with("resource ") {
            let _ = <Warden as ApexErrorP4Ext>::raise_application_error(line.as_bytes());
        }
    }
    shared.faults_seen = faults;
}

/// What the partition's processes share: the device and its bookkeeping.
struct Shared {
    device: Device,
    faults_seen: u32,
    /// The timer wake-ups since the last statistics line (every process's).
    lateness: Lateness,
    /// The resources with a process of their own, in the package's order.
    own: Vec<String>,
    /// The event that wakes each one's process.
    events: Vec<EventId>,
    /// The instant each one's process sleeps until (`i64::MAX`: until woken).
    sleeps_until: Vec<i64>,
}

impl Shared {
    /// Whether `resource`'s timers are the device process's (it has no process of its own).
    fn device_runs(own: &[String], resource: &str) -> bool {
        !own.iter().any(|o| o == resource)
    }

    /// Fires the due timers of the resources `serves` accepts, counting the wake-up's
    /// lateness; their earliest timer after.
    fn fire(&mut self, now: i64, serves: impl Fn(&str) -> bool) -> Option<i64> {
        if let Some(due) = self.device.next_deadline_of(&serves).filter(|&d| d <= now) {
            self.lateness.add(now - due);
            self.device.advance_of(now, &serves);
            drain(self);
        }
        self.device.next_deadline_of(serves)
    }
}

/// The shared state. With resource processes, every access holds the device mutex (an
/// ARINC 653 mutex whose priority ceiling is the highest resource process's), so one
/// process at a time carries out a request, an event chain or a network pump, and a
/// resource process preempts the device process anywhere else (in its network stack,
/// between requests). Without them only the device process uses it, unlocked.
struct DeviceCell {
    shared: UnsafeCell<Option<Shared>>,
    /// The device mutex, or -1 (no resource processes).
    mutex: AtomicI64,
}

#[allow(unsafe_code)]
// SAFETY: `shared` is reached only inside `DeviceCell::lock` (never nested: nothing called
// there reaches `DEVICE`), which holds the device mutex whenever resource processes exist;
// without them only the device process calls it; `reset` runs in the partition's start,
// when no process runs. The `Rc`s and `RefCell`s the device shares with `Net` (the network
// tables) are touched only inside `with` too.
unsafe impl Sync for DeviceCell {}

static DEVICE: DeviceCell = DeviceCell {
    shared: UnsafeCell::new(None),
    mutex: AtomicI64::new(-1),
};

impl DeviceCell {
    /// At the partition's start, before any process runs: no device yet, and `mutex` (-1:
    /// none). A device of the run before is forgotten, not dropped: a restart may have
    /// made a new heap under it.
    fn reset(&self, mutex: i64) {
        self.mutex.store(mutex, Ordering::Release);
        #[allow(unsafe_code)]
        // SAFETY: the partition's start runs alone (no process has started yet).
        let old = unsafe { (*self.shared.get()).take() };
        core::mem::forget(old);
    }

    /// Runs `f` on the cell's content, holding the device mutex if there is one; `None`
    /// if it could not be taken (reported).
    fn lock<R>(&self, f: impl FnOnce(&mut Option<Shared>) -> R) -> Option<R> {
        let mutex = self.mutex.load(Ordering::Acquire);
        if mutex >= 0
            && let Err(e) = <Warden as ApexMutexP1>::acquire_mutex(mutex, INFINITE_TIME_VALUE)
        {
            report(&alloc::format!("ACQUIRE_MUTEX of the device failed: {e:?}"));
            return None;
        }
        #[allow(unsafe_code)]
        // SAFETY: see `impl Sync for DeviceCell`: the mutex is held, or no other process
        // uses the cell.
        let result = f(unsafe { &mut *self.shared.get() });
        if mutex >= 0 {
            let _ = <Warden as ApexMutexP1>::release_mutex(mutex);
        }
        Some(result)
    }

    /// Gives the cell the booted device; false if the mutex could not be taken.
    fn install(&self, shared: Shared) -> bool {
        self.lock(|cell| *cell = Some(shared)).is_some()
    }

    /// Runs `f` on the shared state (see [`DeviceCell::lock`]); `None` before the device
    /// process has booted the device.
    fn with<R>(&self, f: impl FnOnce(&mut Shared) -> R) -> Option<R> {
        self.lock(|cell| cell.as_mut().map(f)).flatten()
    }

    /// The device process's [`DeviceCell::with`]: after `f` (a request, a poll: either may
    /// start a timer), wakes each resource process whose resource now has a timer before
    /// the instant it sleeps until.
    fn with_wake<R>(&self, f: impl FnOnce(&mut Shared) -> R) -> Option<R> {
        let mut wake: [Option<EventId>; MAX_RESOURCES] = [None; MAX_RESOURCES];
        let result = self.with(|s| {
            let result = f(s);
            for (i, name) in s.own.iter().enumerate() {
                let due = s.device.next_deadline_of(|r| r == name).unwrap_or(i64::MAX);
                if due < s.sleeps_until[i] {
                    s.sleeps_until[i] = due;
                    wake[i] = Some(s.events[i]);
                }
            }
            result
        });
        for event in wake.into_iter().flatten() {
            let _ = <Warden as ApexEventP1>::set_event(event);
        }
        result
    }
}

/// A management request carried out on the shared device (`DeviceCell::with_wake`).
struct Locked;

impl DeviceAccess for Locked {
    fn carry_out(&mut self, destination: &str, request: &Request, now: i64) -> String {
        DEVICE
            .with_wake(|s| {
                let answer = s.device.carry_out(destination, request, now);
                drain(s);
                answer
            })
            .unwrap_or_else(|| refusal(Reason::InvalidState))
    }
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
    /// PUBLISH/SUBSCRIBE's UDP endpoints and CLIENT/SERVER's TCP links, with a network
    /// interface: [`Net`] pumps them on its stack.
    net: Option<NetTables>,
}

/// The tables between the FBs and the stack, shared by [`ApexIo`] and [`Net`].
struct NetTables {
    udp: Rc<RefCell<Endpoints>>,
    tcp: Rc<RefCell<TcpLinks>>,
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
    fn open(ports: &[SamplingPort<'_>], queues: &[DataQueue<'_>], net: Option<NetTables>) -> Self {
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
        ApexIo { ports, queues, net }
    }

    /// The UDP endpoints, or why not (never borrowed twice: [`Net::pass`] pumps them
    /// between event chains).
    fn endpoints(&self) -> Result<core::cell::RefMut<'_, Endpoints>, String> {
        let net = self.net.as_ref().ok_or(NO_NETWORK)?;
        net.udp
            .try_borrow_mut()
            .map_err(|_| String::from("the network interface is busy"))
    }

    /// The TCP links, or why not (as [`ApexIo::endpoints`]).
    fn links(&self) -> Result<core::cell::RefMut<'_, TcpLinks>, String> {
        let net = self.net.as_ref().ok_or(NO_NETWORK)?;
        net.tcp
            .try_borrow_mut()
            .map_err(|_| String::from("the network interface is busy"))
    }

    fn find(&self, port: &str) -> Option<&(String, usize, Sampling)> {
        self.ports.iter().find(|(name, _, _)| name == port)
    }
}

impl ProcessIo for ApexIo {
    fn clock(&self) -> Option<i64> {
        Some(now_ns())
    }
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

    fn udp_open(&mut self, at: NetAddr, subscribe: bool) -> Result<usize, String> {
        self.endpoints()?.open(at, subscribe)
    }

    fn udp_send(&mut self, endpoint: usize, datagram: &[u8]) -> Result<(), String> {
        self.endpoints()?.send(endpoint, datagram)
    }

    fn udp_receive(&mut self, endpoint: usize, buf: &mut [u8]) -> Option<usize> {
        self.endpoints().ok()?.receive(endpoint, buf)
    }

    fn udp_close(&mut self, endpoint: usize) {
        if let Ok(mut e) = self.endpoints() {
            e.close(endpoint);
        }
    }

    fn tcp_open(&mut self, at: NetAddr, server: bool) -> Result<usize, String> {
        self.links()?.open(at, server)
    }

    fn tcp_state(&self, link: usize) -> TcpState {
        match self.links() {
            Ok(links) => links.state(link),
            Err(why) => TcpState::Down(why),
        }
    }

    fn tcp_send(&mut self, link: usize, bytes: &[u8]) -> Result<(), String> {
        self.links()?.send(link, bytes)
    }

    fn tcp_receive(&mut self, link: usize, buf: &mut [u8]) -> usize {
        self.links().map_or(0, |mut links| links.receive(link, buf))
    }

    fn tcp_close(&mut self, link: usize) {
        if let Ok(mut links) = self.links() {
            links.close(link);
        }
    }
}

/// The network interface, the management protocol's TCP server (`iec61499.net`),
/// PUBLISH/SUBSCRIBE's UDP endpoints and CLIENT/SERVER's TCP links on its stack.
struct Net {
    server: Server,
    udp: Rc<RefCell<Endpoints>>,
    logged_udp: UdpStats,
    tcp: Rc<RefCell<TcpLinks>>,
    logged_tcp: TcpLinkStats,
    /// The frame port's doorbell is set: the device process waits for it.
    doorbell: bool,
    link: TenantLink,
    logged: Stats,
    event_lines: u32,
    next_stats: i64,
}

impl Net {
    /// Opens the frame ports (created at start), listens, and has no UDP endpoints yet;
    /// why not, else.
    fn open(n: &NetPorts<'_>, now: i64) -> Result<Self, String> {
        #[allow(unsafe_code)]
        // SAFETY: the ring's segment is this partition's and its NIC partition's only (the
        // configuration tools' check), mapped read-write for its life; this device alone
        // attaches it, once.
        let link = unsafe { TenantLink::open(n.rx.name, n.tx.name, n.ring) };
        let mut link =
            link.map_err(|e| alloc::format!("the frame link {}/{}: {e}", n.rx.name, n.tx.name))?;
        let settings = Settings {
            mac: n.mac,
            address: n.address,
            prefix: n.prefix,
            gateway: n.gateway,
            port: n.port,
            connections: usize::from(n.connections),
            access: n.access,
        };
        let server = Server::new(&settings, now.max(0) as u64)
            .map_err(|e| alloc::format!("cannot listen on tcp port {}: {e:?}", n.port))?;
        let doorbell = link.ring_on_arrival(DOORBELL_BIT);
        if let Err(e) = doorbell {
            println!(
                "iec61499: net: no doorbell on {} ({e:?}); it is polled",
                n.rx.name
            );
        }
        Ok(Net {
            server,
            udp: Rc::new(RefCell::new(Endpoints::new())),
            logged_udp: UdpStats::default(),
            tcp: Rc::new(RefCell::new(TcpLinks::new())),
            logged_tcp: TcpLinkStats::default(),
            doorbell: doorbell.is_ok(),
            link,
            logged: Stats::default(),
            event_lines: EVENT_LINES,
            next_stats: now,
        })
    }

    /// The frames in, the server's run (requests answered on `device`), the UDP endpoints'
    /// pump (datagrams sent and received) and the TCP links' (connections made, bytes
    /// moved), the frames out, the log lines. The device is taken only to carry out each
    /// request and for the pumps (the tables are the FBs' too), never while the stack
    /// works.
    fn pass(&mut self, now: i64) {
        let stack = &mut self.server.stack;
        self.link
            .receive(server::FRAMES_PER_RUN, |frame| stack.device.deliver(frame));
        self.server.run(now.max(0) as u64, &mut Locked);
        // One hold of the device for the pumps and what the log needs of the tables.
        let mut udp_errors: [Option<String>; iec61499_mgmt::udp::MAX_ERRORS] = Default::default();
        let (udp, tcp, stack) = (&self.udp, &self.tcp, &mut self.server.stack);
        let tables = DEVICE.with(|_| {
            if let (Ok(mut udp), Ok(mut tcp)) = (udp.try_borrow_mut(), tcp.try_borrow_mut()) {
                udp.pump(stack);
                tcp.pump(stack);
                for (slot, error) in udp_errors.iter_mut().zip(udp.take_errors()) {
                    *slot = Some(error);
                }
            }
            let udp = udp.try_borrow().ok().map(|u| (u.open_count(), u.stats));
            let tcp = tcp.try_borrow().ok().map(|t| (t.open_count(), t.stats));
            (udp, tcp)
        });
        if tables.is_some() {
            self.server.stack.poll(now.max(0) / 1000);
        }
        let stack = &mut self.server.stack;
        self.link
            .send(server::FRAMES_PER_RUN, || stack.device.take());
        let (udp_now, tcp_now) = tables.unwrap_or((None, None));
        self.log(now, udp_errors, udp_now, tcp_now);
    }

    /// The log lines of a pass: the server's events, the stack's UDP errors, and once a
    /// second the statistics (of the tables as the pass found them).
    fn log(
        &mut self,
        now: i64,
        udp_errors: [Option<String>; iec61499_mgmt::udp::MAX_ERRORS],
        udp_now: Option<(usize, UdpStats)>,
        tcp_now: Option<(usize, TcpLinkStats)>,
    ) {
        let mut events = [None; server::MAX_EVENTS];
        for (slot, event) in events.iter_mut().zip(self.server.take_events()) {
            *slot = Some(event);
        }
        for error in udp_errors.into_iter().flatten() {
            if self.event_lines > 0 {
                self.event_lines -= 1;
                println!("iec61499: udp: {error}");
            }
        }
        for event in events.into_iter().flatten() {
            if self.event_lines == 0 {
                continue;
            }
            self.event_lines -= 1;
            match event {
                Event::Accepted(p) => {
                    println!("iec61499: tcp: connection from {}:{}", p.ip, p.port)
                }
                Event::Refused(p) => println!(
                    "iec61499: tcp: refused {}:{}: all connections in use",
                    p.ip, p.port
                ),
                Event::Malformed(p, why) => println!(
                    "iec61499: tcp: closed {}:{}: {why} (answered with a refusal)",
                    p.ip, p.port
                ),
                Event::TimedOut {
                    peer: p,
                    received,
                    unsent,
                } => println!(
                    "iec61499: tcp: closed {}:{}: no progress for {} s ({received} bytes of a request received, {unsent} bytes of a response unsent)",
                    p.ip,
                    p.port,
                    server::REQUEST_TIMEOUT_NS / 1_000_000_000
                ),
            }
        }
        if now >= self.next_stats {
            let every = STATS_EVERY_MS * 1_000_000;
            self.next_stats = (now / every + 1) * every;
            self.event_lines = EVENT_LINES;
            let s = self.server.stats;
            if s != self.logged {
                self.logged = s;
                println!(
                    "iec61499: t={}ms net open={} accepted={} refused={} requests={} malformed={} timed_out={} frames_in={} frames_out={}",
                    now / 1_000_000,
                    self.server.open(),
                    s.accepted,
                    s.refused,
                    s.requests,
                    s.malformed,
                    s.timed_out,
                    self.link.frames_in,
                    self.link.frames_out
                );
            }
            if let Some((links, t)) = tcp_now
                && t != self.logged_tcp
            {
                self.logged_tcp = t;
                println!(
                    "iec61499: t={}ms tcp links={} connected={} refused={} ended={} bytes_out={} bytes_in={}",
                    now / 1_000_000,
                    links,
                    t.connected,
                    t.refused,
                    t.ended,
                    t.bytes_out,
                    t.bytes_in
                );
            }
            let Some((open, u)) = udp_now else {
                return;
            };
            if u != self.logged_udp {
                self.logged_udp = u;
                println!(
                    "iec61499: t={}ms udp endpoints={open} sent={} received={} dropped={} send_failed={} errors={}",
                    now / 1_000_000,
                    u.sent,
                    u.received,
                    u.dropped,
                    u.send_failed,
                    u.errors
                );
            }
        }
    }

    /// How long the device process may wait before the next pass.
    fn wait_at_most(&mut self, now: i64) -> Duration {
        let poll_at = self
            .server
            .poll_at_ns()
            .map(|at| (at as i64).saturating_sub(now).max(0) as u64);
        match poll_at {
            Some(ns) => Duration::from_nanos(ns).min(NET_POLL),
            None => NET_POLL,
        }
    }
}

/// Waits `timeout` for a request and answers it; false when the wait failed.
fn wait(mgmt: Option<&Mgmt>, timeout: Duration, buf: &mut [u8]) -> bool {
    let Some(m) = mgmt else {
        return <Warden as ApexTimeP1Ext>::timed_wait(timeout).is_ok();
    };
    match m.request.receive(buf, SystemTime::Normal(timeout)) {
        Ok((message, _)) => {
            let answer = serve(&mut Locked, message, m.access, m.size, now_ns());
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
    // The network before the boot: a boot file's PUBLISH/SUBSCRIBE open their UDP
    // endpoints at START (without an interface that opened, they say so).
    let opened = package.net.as_ref().map(|n| (n, Net::open(n, now_ns())));
    let links = match &opened {
        Some((_, Ok(net))) => Some(NetTables {
            udp: net.udp.clone(),
            tcp: net.tcp.clone(),
        }),
        _ => None,
    };
    let io = Box::new(ApexIo::open(&package.ports, &package.queues, links));
    let (device, booted) = match iec61499_mgmt::package::boot(info.data(), io, now_ns()) {
        Ok(booted) => booted,
        Err(reason) => {
            report(&alloc::format!("refusing the boot package: {reason}"));
            return;
        }
    };
    // The resources whose process and event exist (the start reported any that could
    // not be made): the device process runs the others' timers.
    let (own, events): (Vec<String>, Vec<EventId>) = package
        .processes
        .iter()
        .filter_map(|p| {
            let name = Name::from_str(&process_name(p.resource)).ok()?;
            <Warden as ApexProcessP1>::get_process_id(name.clone().into()).ok()?;
            let event = <Warden as ApexEventP1>::get_event_id(name.into()).ok()?;
            Some((String::from(p.resource), event))
        })
        .unzip();
    // From here on every process reaches the device through `DEVICE.with`.
    let installed = DEVICE.install(Shared {
        device,
        faults_seen: 0,
        lateness: Lateness::default(),
        sleeps_until: alloc::vec![i64::MAX; own.len()],
        own,
        events,
    });
    if !installed {
        return;
    }
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
    let mut net = opened.and_then(|(n, opened)| match opened {
        Ok(net) => {
            let (a, m) = (n.address, n.mac);
            println!(
                "iec61499: net {}.{}.{}.{}/{} mac {:02x}:{:02x}:{:02x}:{:02x}:{:02x}:{:02x}: management on tcp port {}, connections {}, access {:?}",
                a[0],
                a[1],
                a[2],
                a[3],
                n.prefix,
                m[0],
                m[1],
                m[2],
                m[3],
                m[4],
                m[5],
                n.port,
                n.connections,
                n.access
            );
            Some(net)
        }
        Err(why) => {
            report(&why);
            None
        }
    });
    let doorbell = net.as_ref().is_some_and(|n| n.doorbell);
    if doorbell
        && let Some(m) = &mgmt
        && let Err(e) = apex::runtime::port_doorbell(m.request.id(), DOORBELL_BIT)
    {
        // Its requests then wait for the next pass (at most NET_POLL).
        println!("iec61499: no doorbell on the management request port ({e:?})");
    }
    let mut buf = alloc::vec![0u8; package.mgmt.map_or(0, |p| p.request.size as usize)];
    // Wakes every resource process whose resource the boot file started a timer in.
    DEVICE.with_wake(drain);
    // On the whole seconds of the partition's clock, so a log names them predictably.
    let every = STATS_EVERY_MS * 1_000_000;
    let mut next_stats = (now_ns() / every + 1) * every;
    loop {
        let now = now_ns();
        // At the first pass after each whole second that follows a timer's wake-up.
        let printed = DEVICE.with(|s| {
            let own = core::mem::take(&mut s.own);
            s.fire(now, |r| Shared::device_runs(&own, r));
            s.own = own;
            let print = now >= next_stats && s.lateness.count > 0;
            if print {
                let l = &s.lateness;
                println!(
                    "iec61499: t={}ms timers={} lateness_ns={}/{}/{}",
                    next_stats / 1_000_000,
                    l.count,
                    l.min,
                    l.sum / l.count as i64,
                    l.max
                );
                s.lateness = Lateness::default();
                print_watches(&s.device, next_stats);
            }
            print
        });
        if printed == Some(true) {
            next_stats = (now / every + 1) * every;
        }
        // The network pass first: what the timers published goes out, the datagrams that
        // arrived are the subscribers' in the poll right after.
        if let Some(net) = net.as_mut() {
            net.pass(now_ns());
        }
        let now = now_ns();
        let (polls, due) = DEVICE
            .with_wake(|s| {
                let polls = s.device.polls();
                if polls {
                    s.device.poll(now);
                    drain(s);
                }
                let own = &s.own;
                let due = s.device.next_deadline_of(|r| Shared::device_runs(own, r));
                (polls, due)
            })
            .unwrap_or((false, None));
        let now = now_ns();
        // A subscriber's messages wait at most one poll period.
        let idle = if polls {
            Duration::from_nanos(iec61499_mgmt::pubsub::POLL_NS as u64)
        } else {
            IDLE
        };
        let idle = match net.as_mut() {
            Some(net) => idle.min(net.wait_at_most(now)),
            None => idle,
        };
        let sleep = match due {
            Some(due) if due <= now => continue,
            Some(due) => Duration::from_nanos((due - now) as u64).min(idle),
            None => idle,
        };
        // With the frame port's doorbell, a notification ends the wait: frames, or a
        // management request (its port rings too), then served without waiting.
        let waited = if doorbell {
            let _ = apex::user_rt::sys::notify_wait(DOORBELL_BIT, sleep.as_nanos() as u64);
            mgmt.is_none() || wait(mgmt.as_ref(), Duration::ZERO, &mut buf)
        } else {
            wait(mgmt.as_ref(), sleep, &mut buf)
        };
        if !waited {
            return;
        }
    }
}

/// The name of `resource`'s process and of the event that wakes it.
fn process_name(resource: &str) -> String {
    alloc::format!("{RESOURCE_PROCESS_PREFIX}{resource}")
}

/// The process of a resource configured with one (`iec61499.resources`): it fires that
/// resource's timers (E_CYCLE, E_DELAY, ...) and runs the chains they start, at its own
/// priority, above the device process; it sleeps until the resource's earliest timer or
/// until the device process wakes it (a request or a subscription started an earlier one,
/// or the device booted). The resource need not exist: the process then sleeps until it
/// does.
extern "C" fn resource_process() {
    let name = match Process::<Warden>::get_self() {
        Ok(me) => {
            let attributes = me.status().attributes;
            let name = attributes.name;
            let text = name.to_str().unwrap_or("");
            String::from(text.strip_prefix(RESOURCE_PROCESS_PREFIX).unwrap_or(text))
        }
        Err(e) => {
            report(&alloc::format!(
                "a resource process does not know itself: {e:?}"
            ));
            return;
        }
    };
    let Ok(event) = Name::from_str(&process_name(&name))
        .map_err(|_| Error::InvalidParam)
        .and_then(apex::a653rs::prelude::Event::<Warden>::from_name)
    else {
        report(&alloc::format!(
            "the event of resource {name}'s process is missing"
        ));
        return;
    };
    loop {
        // Reset before looking at the device: a wake-up after this is never lost.
        event.reset();
        let now = now_ns();
        let due = DEVICE
            .with(|s| {
                let due = s.fire(now, |r| r == name);
                if let Some(i) = s.own.iter().position(|o| *o == name) {
                    s.sleeps_until[i] = due.unwrap_or(i64::MAX);
                }
                due
            })
            .flatten();
        let timeout = match due {
            Some(due) => {
                let now = now_ns();
                if due <= now {
                    continue;
                }
                SystemTime::Normal(Duration::from_nanos((due - now) as u64))
            }
            None => SystemTime::Infinite,
        };
        if let Err(e) = event.wait(timeout)
            && e != Error::TimedOut
        {
            report(&alloc::format!(
                "WAIT_EVENT of resource {name}'s process failed: {e:?}"
            ));
            return;
        }
    }
}

struct Iec61499Partition;

impl Iec61499Partition {
    fn start(&self, ctx: &mut StartContext<Warden>) {
        DEVICE.reset(-1);
        let Ok(package) = iec61499_mgmt::package::decode(apex::runtime::start_info().data()) else {
            // The device process reports it.
            return self.spawn(ctx, &[]);
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
        if let Some(n) = package.net {
            let created = Name::from_str(n.rx.name)
                .map_err(|_| Error::InvalidParam)
                .and_then(|name| {
                    ctx.create_queuing_port_receiver(
                        name,
                        n.rx.size,
                        n.rx.depth,
                        QueuingDiscipline::Fifo,
                    )
                    .map(drop)
                })
                .and_then(|()| Name::from_str(n.tx.name).map_err(|_| Error::InvalidParam))
                .and_then(|name| {
                    ctx.create_queuing_port_sender(
                        name,
                        n.tx.size,
                        n.tx.depth,
                        QueuingDiscipline::Fifo,
                    )
                    .map(drop)
                });
            if let Err(e) = created {
                report(&alloc::format!("creating the frame ports failed: {e:?}"));
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
        self.spawn(ctx, &package.processes);
    }

    /// Creates and starts the device process and the resource processes, with the device
    /// mutex and their events when there are resource processes.
    fn spawn(&self, ctx: &mut StartContext<Warden>, processes: &[ResourceProcess<'_>]) {
        let stack = apex::table::MIN_STACK as u32;
        let lowest = processes.iter().map(|p| p.priority).min();
        let highest = processes.iter().map(|p| p.priority).max();
        let device_priority = match lowest {
            Some(lowest) => lowest.saturating_sub(1).max(1),
            None => main_process::priority_below_mcp(),
        };
        if let Some(ceiling) = highest {
            let mutex = Name::from_str("device")
                .map_err(|_| Error::InvalidParam)
                .and_then(|name| {
                    ctx.create_mutex(name, Priority::from(ceiling), QueuingDiscipline::Priority)
                });
            match mutex {
                Ok(mutex) => DEVICE.reset(mutex.id()),
                Err(e) => {
                    report(&alloc::format!("cannot create the device mutex: {e:?}"));
                    return;
                }
            }
        }
        for p in processes {
            let name = process_name(p.resource);
            let event = Name::from_str(&name)
                .map_err(|_| Error::InvalidParam)
                .and_then(|n| ctx.create_event(n));
            if let Err(e) = event {
                report(&alloc::format!(
                    "cannot create the event of resource {}'s process: {e:?}",
                    p.resource
                ));
                continue;
            }
            let started = main_process::start_at(
                ctx,
                &name,
                resource_process,
                stack,
                Release::Aperiodic,
                p.priority,
            );
            match started {
                Ok(()) => println!(
                    "iec61499: resource {} runs in process {name} at priority {}, the device process at {device_priority}",
                    p.resource, p.priority
                ),
                Err(e) => report(&alloc::format!("resource {}: {e}", p.resource)),
            }
        }
        if let Err(e) = main_process::start_at(
            ctx,
            "device",
            device_process,
            stack,
            Release::Aperiodic,
            device_priority,
        ) {
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
