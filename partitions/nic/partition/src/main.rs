//! The NIC partition program (`image = "nic"`): drives the virtio-net function the
//! partition owns (`devices`, modern PCI transport, `device.rs`) and is the Ethernet switch
//! (`nic_core::switch`) between the wire and its tenants, each attached by a pair of
//! queuing ports (`nic.tenants`, the data entry `nic_core::tenants`): one frame a message,
//! destination MAC first, no FCS, 14..=1514 bytes; or, for a tenant whose entry names a
//! frame ring, the same frames through the ring in the segment it shares with the tenant
//! (`frame_ring`), the ports carrying only the wake-ups: a one-byte message when a frame
//! goes into an empty ring, unless the other side named a thread to notify instead (the
//! ring's `waiter`; both sides name theirs, the switch's process for its tenants' rings).
//!
//! One APEX process, the switch, does everything in a loop: frames the device received go
//! where the switch routes them (to one tenant, to all for broadcast and multicast; unknown
//! unicast from the wire is dropped; a tenant's broadcasts and multicasts are bounded,
//! `nic_core::switch::GROUP_RATE`); then frames from the tenants' ports (or rings),
//! round-robin, at most [`BUDGET`] a tenant and round, and only while the transmit queue has room, so a
//! tenant that floods its port only fills its own port and loses its own frames (its
//! sends fail when the port is full) while every other tenant keeps its turn. A tenant's
//! frame with another source MAC is dropped. Then it waits for the device's interrupt (for
//! received frames; for sent ones only while the transmit queue is full), a tenant's
//! doorbell (syssw notifies it when a tenant's frames or wake-ups arrive) or a tenant's
//! notification that a frame went into its empty ring, at most [`POLL`] while a tenant
//! has no doorbell (its port is polled), else at most [`IDLE_POLL`].
//!
//! Log lines (on the serial log as `[<partition>] nic: ...`; an interface):
//! - `nic: virtio-net <BB:DD.F> MAC <mac>, <n> descriptors a queue, line <irq>, <k> tenant(s)`
//!   once up, then `nic: tenant <partition> MAC <mac> from <port> to <port>` for each
//!   (followed by `, frames in a ring of <n> slots each way at <address>` for a ring);
//! - `nic: not started: <reason>` when the tenant table, the device or the DMA region is
//!   unusable (also reported to the health monitor as APPLICATION_ERROR; the partition then
//!   idles);
//! - every [`STATS_EVERY_MS`] of the partition's clock, `nic: t=<ms>ms uplink in=<n>
//!   out=<n> overflow=<n> unknown=<n> malformed=<n> bogus=<n>` (frames from the wire,
//!   frames sent to it, frames for it dropped because its transmit queue was full, unicast
//!   from the wire for no tenant, runts from the device, used entries the device should
//!   not have written) and for each tenant `nic: t=<ms>ms tenant <partition> in=<n> out=<n>
//!   overflow=<n> spoofed=<n> malformed=<n> limited=<n> notified=<n> kicked=<n>` (frames
//!   taken from its port or ring, frames delivered to it, frames for it dropped because
//!   its port or ring was full, frames refused for a source MAC not its own, frames of a
//!   bad length and ring slots with a bogus length or index, broadcasts and multicasts
//!   beyond its rate, and the wake-ups of its ring: notifications of the thread it named,
//!   messages on its port).
//!   Counters count since start.
#![no_std]
#![no_main]

extern crate alloc;

mod device;

use alloc::vec::Vec;
use apex::Warden;
use apex::a653rs::prelude::*;
use apex::main_process::{self, Release};
use apex::user_rt::println;
use apex::user_rt::protocol::layout::DEVICES_BASE;
use apex::user_rt::sys;
use core::time::Duration;
use device::Net;
use driver_link as link;
use nic_core::switch::{MAX_FRAME, Port, Rounds, Switch};
use nic_core::tenants::Table;
use nic_core::virtio::{self, Memory, RECEIVE_QUEUE, TRANSMIT_QUEUE, Used};

/// Frames a tenant may have taken from its port per round of the switch.
const BUDGET: u32 = 8;
/// Longest wait for the device's interrupt or a tenant's doorbell before the tenants'
/// ports are looked at again, while a tenant has no doorbell (it is found then).
const POLL: Duration = Duration::from_micros(500);
/// Longest wait when every tenant has its doorbell: nothing arrives unannounced, the
/// look only in case a wake-up was lost (an idle switch then wakes a hundred times a
/// second, not two thousand, and takes no CPU from the partitions that run).
const IDLE_POLL: Duration = Duration::from_millis(10);
/// The notification bit the device's interrupt line fires as (an index).
const IRQ_BIT: u64 = 8;
/// The notification bit of tenant 0's doorbell (syssw rings it when the tenant's frames or
/// wake-ups arrive at its `from` port); tenant `n` has the bit `n` above it.
const DOORBELL_BIT: u64 = 9;
/// The notification bit a tenant sends when a frame goes into its empty ring, for tenant
/// 0; tenant `n` has the bit `n` above it.
const RING_BIT: u64 = DOORBELL_BIT + nic_core::switch::MAX_TENANTS as u64;
const _: () = assert!(RING_BIT + nic_core::switch::MAX_TENANTS as u64 <= 64);
/// How often the counters are logged.
const STATS_EVERY_MS: u64 = 1000;
/// The message buffer: the largest port message (config: 4096 bytes).
const MESSAGE: usize = 4096;
/// virtio's PCI vendor and its network device ids (transitional, modern).
const VIRTIO_VENDOR: u16 = 0x1af4;
const VIRTIO_NET: [u16; 2] = [0x1000, 0x1041];

/// Logs why the partition cannot work and reports it to the health monitor.
fn refuse(text: core::fmt::Arguments<'_>) {
    let line = alloc::format!("{text}");
    println!("nic: not started: {line}");
    let _ = <Warden as ApexErrorP4Ext>::raise_application_error(line.as_bytes());
}

fn table() -> Option<Table<'static>> {
    match nic_core::tenants::decode(apex::runtime::start_info().data()) {
        Ok(t) => Some(t),
        Err(e) => {
            refuse(format_args!("the tenant table (data entry): {e}"));
            None
        }
    }
}

/// A tenant's two ports, and its frame ring if it has one.
struct Link {
    name: &'static str,
    from: QueuingPortReceiver<Warden>,
    to: QueuingPortSender<Warden>,
    ring: Option<(frame_ring::Producer, frame_ring::Consumer)>,
    /// Ring slots with no frame in them (a bogus index or length the tenant wrote).
    bad: u64,
    /// The tenant woken for its ring: by a notification, by a message on its port.
    notified: u64,
    kicked: u64,
}

impl Link {
    /// The tenant's wake-ups, drained before its ring is read (one that comes after is
    /// left for the next pass, so its doorbell is not lost).
    fn drain_wakeups(&mut self, buf: &mut [u8; MESSAGE]) {
        for _ in 0..MESSAGE {
            if self
                .from
                .receive(buf, SystemTime::Normal(Duration::ZERO))
                .is_err()
            {
                break;
            }
        }
    }

    /// Sends `frame` to the tenant; `false` when its port or ring is full.
    fn deliver(&mut self, frame: &[u8]) -> bool {
        let poll = SystemTime::Normal(Duration::ZERO);
        let Some((to, _)) = self.ring.as_mut() else {
            return self.to.send(frame, poll).is_ok();
        };
        match to.push(frame) {
            Ok(pushed) => {
                if pushed.first && link::notify_waiter(to.waiter()) {
                    self.notified += 1;
                } else if pushed.first {
                    // A full port means wake-ups are already waiting there.
                    self.kicked += 1;
                    let _ = self.to.send(&[0], poll);
                }
                true
            }
            Err(_) => false,
        }
    }

    /// The tenant's next frame into `frame` (its length), if any.
    fn take(&mut self, frame: &mut [u8; MESSAGE]) -> Option<usize> {
        let Some((_, from)) = self.ring.as_mut() else {
            let poll = SystemTime::Normal(Duration::ZERO);
            return match self.from.receive(frame, poll) {
                Ok((message, _)) if !message.is_empty() => Some(message.len()),
                _ => None,
            };
        };
        let mut buf = [0u8; frame_ring::MTU];
        // Bogus slots are skipped, at most a ring's worth (the tenant may write more).
        for _ in 0..=from.slots() {
            match from.pop(&mut buf)? {
                Ok(len) => {
                    frame[..len].copy_from_slice(&buf[..len]);
                    return Some(len);
                }
                Err(_) => self.bad += 1,
            }
        }
        None
    }
}

struct Counts {
    /// Used entries the device should not have written (either queue).
    bogus: u64,
    /// Frames shorter than the virtio-net header from the device.
    runts: u64,
}

/// Everything the switch process owns.
struct Nic {
    net: Net,
    switch: Switch,
    links: Vec<Link>,
    counts: Counts,
    /// The transmit queue got frames since it was last rung.
    tx_pending: bool,
    /// Whether the transmit queue asks the device for interrupts.
    tx_interrupts: bool,
}

impl Nic {
    /// Sends `frame`, which came from `from`, wherever the switch routes it.
    fn forward(&mut self, from: Port, frame: &[u8]) {
        let Ok(to) = self.switch.route(from, frame) else {
            return;
        };
        for port in to.iter(self.links.len()) {
            let fitted = match port {
                Port::Uplink => self.transmit(frame),
                Port::Tenant(n) => self.links[n].deliver(frame),
            };
            self.switch.delivered(port, fitted);
        }
    }

    /// Puts `frame` on the transmit queue; `false` when it is full.
    fn transmit(&mut self, frame: &[u8]) -> bool {
        let Some(id) = self.net.tx.free() else {
            return false;
        };
        let at = self.net.tx.buffer(id);
        self.net.mem.write(at, &[0; virtio::NET_HEADER]);
        self.net.mem.write(at + virtio::NET_HEADER, frame);
        let len = (virtio::NET_HEADER + frame.len()) as u32;
        let given = self.net.tx.give(&mut self.net.mem, id, len, false);
        self.tx_pending |= given;
        given
    }

    /// Frames the device received, to where they go; the buffers back to the device.
    fn serve_wire(&mut self, frame: &mut [u8; MESSAGE]) {
        let mut refilled = false;
        for _ in 0..self.net.rx.size() {
            let Some(used) = self.net.rx.take(&self.net.mem) else {
                break;
            };
            let (id, len) = match used {
                Used::Buffer { id, len } => (id, len),
                Used::Bogus { .. } => {
                    self.counts.bogus += 1;
                    continue;
                }
            };
            match virtio::received_frame(len) {
                Some(range) => {
                    let n = range.len().min(MESSAGE);
                    let at = self.net.rx.buffer(id) + range.start;
                    self.net.mem.read(at, &mut frame[..n]);
                    self.forward(Port::Uplink, &frame[..n]);
                }
                None => self.counts.runts += 1,
            }
            let size = virtio::BUFFER_SIZE as u32;
            refilled |= self.net.rx.give(&mut self.net.mem, id, size, true);
        }
        if refilled {
            self.net.kick(RECEIVE_QUEUE);
        }
    }

    /// Descriptors the device has sent, free again.
    fn reclaim(&mut self) {
        for _ in 0..self.net.tx.size() {
            match self.net.tx.take(&self.net.mem) {
                None => break,
                Some(Used::Bogus { .. }) => self.counts.bogus += 1,
                Some(Used::Buffer { .. }) => {}
            }
        }
    }

    /// The device interrupts for the frames it sent only while the transmit queue is full
    /// (tenants' frames wait for room); otherwise their buffers are taken back on the next
    /// pass, so a frame sent costs no interrupt, and no pass, of its own. `true` when
    /// buffers came back as the interrupt was asked for (the device used them before):
    /// another pass is due at once.
    fn ask_transmit_interrupts(&mut self) -> bool {
        let full = self.net.tx.free().is_none();
        if full == self.tx_interrupts {
            return false;
        }
        self.tx_interrupts = full;
        self.net.tx.set_interrupts(&mut self.net.mem, full);
        if !full {
            return false;
        }
        self.reclaim();
        self.net.tx.free().is_some()
    }

    /// Frames from the tenants' ports or rings, round-robin within their budgets, while
    /// the transmit queue has room (what stays in a port or ring waits there, or the
    /// tenant's next send fails: only that tenant loses frames).
    fn serve_tenants(&mut self, rounds: &mut Rounds, frame: &mut [u8; MESSAGE]) {
        let mut pending = [true; nic_core::switch::MAX_TENANTS];
        let most = usize::from(self.net.tx.size()) + self.links.len();
        for _ in 0..most {
            if self.net.tx.free().is_none() {
                break;
            }
            let Some(n) = rounds.pick(|n| pending[n]) else {
                break;
            };
            match self.links[n].take(frame) {
                Some(len) => {
                    rounds.took();
                    self.forward(Port::Tenant(n), &frame[..len]);
                }
                None => pending[n] = false,
            }
        }
    }

    fn log(&self, now_ms: u64) {
        let up = self.switch.counters(Port::Uplink);
        println!(
            "nic: t={now_ms}ms uplink in={} out={} overflow={} unknown={} malformed={} bogus={}",
            up.received,
            up.delivered,
            up.overflow,
            up.unknown,
            up.malformed + self.counts.runts,
            self.counts.bogus
        );
        for (n, link) in self.links.iter().enumerate() {
            let c = self.switch.counters(Port::Tenant(n));
            println!(
                "nic: t={now_ms}ms tenant {} in={} out={} overflow={} spoofed={} malformed={} limited={} notified={} kicked={}",
                link.name,
                c.received,
                c.delivered,
                c.overflow,
                c.spoofed,
                c.malformed + link.bad,
                c.limited,
                link.notified,
                link.kicked
            );
        }
    }
}

extern "C" fn run() {
    let Some(table) = table() else { return };
    let page_len = 4096;
    // SAFETY: syssw maps the records page read-only at DEVICES_BASE before a partition
    // with devices starts, for the life of its task.
    #[allow(unsafe_code)]
    let page = unsafe { core::slice::from_raw_parts(DEVICES_BASE as *const u8, page_len) };
    let claim = match pci::claim(page, VIRTIO_VENDOR, &VIRTIO_NET) {
        Ok(claim) => claim,
        Err(e) => {
            refuse(format_args!("virtio-net: {e}"));
            return;
        }
    };
    let (record, line) = (claim.record, claim.line);
    let net = match Net::bring_up(&record, &claim.capabilities, claim.region) {
        Ok(net) => net,
        Err(e) => {
            refuse(format_args!("virtio-net {}: {e}", record.address));
            return;
        }
    };
    let macs: Vec<_> = table.tenants().map(|t| t.mac).collect();
    let switch = match Switch::new(&macs) {
        Ok(s) => s,
        Err(e) => {
            refuse(format_args!("the tenant table: {e:?}"));
            return;
        }
    };
    let mut links = Vec::new();
    // The longest wait of the switch: set once, by whether every tenant has its doorbell.
    let mut poll = IDLE_POLL;
    for (n, t) in table.tenants().enumerate() {
        let link = match link::open(&t.from, &t.to) {
            Ok(link) => link,
            Err(e) => {
                refuse(format_args!("tenant {}: {e}", t.partition));
                return;
            }
        };
        if let Err(e) = link.ring_on_arrival(1 << (DOORBELL_BIT + n as u64)) {
            println!(
                "nic: tenant {}: no doorbell ({e:?}); its port is polled",
                t.partition
            );
            poll = POLL;
        }
        let ring = match t.ring {
            None => None,
            Some(r) => {
                let (at, size) = (r.address as *mut u8, r.size as usize);
                #[allow(unsafe_code)]
                // SAFETY: a segment of this partition and the tenant only (the configuration
                // tools' check), mapped read-write for its life; the NIC side's one attach.
                let ring = unsafe { frame_ring::attach(at, size, frame_ring::Side::Driver) };
                match ring {
                    Ok(mut ring) => {
                        let me = sys::thread_self().0.0;
                        ring.1.wake_me(me, 1 << (RING_BIT + n as u64));
                        Some(ring)
                    }
                    Err(e) => {
                        refuse(format_args!("tenant {}: {e}", t.partition));
                        return;
                    }
                }
            }
        };
        let link::Link { from, to } = link;
        links.push(Link {
            name: t.partition,
            from,
            to,
            ring,
            bad: 0,
            notified: 0,
            kicked: 0,
        });
    }
    if let Err(e) = sys::irq_attach(u64::from(line), IRQ_BIT) {
        refuse(format_args!("interrupt line {line}: {e:?}"));
        return;
    }
    println!(
        "nic: virtio-net {} MAC {}, {} descriptors a queue, line {line}, {} tenant(s)",
        record.address,
        net.mac,
        net.rx.size(),
        links.len()
    );
    for (t, link) in table.tenants().zip(&links) {
        let slots = link.ring.as_ref().map_or(0, |(to, _)| to.slots());
        let ring = match t.ring {
            Some(r) => alloc::format!(
                ", frames in a ring of {slots} slots each way at {:#x}",
                r.address
            ),
            None => alloc::string::String::new(),
        };
        println!(
            "nic: tenant {} MAC {} from {} to {}{ring}",
            t.partition, t.mac, t.from.name, t.to.name
        );
    }
    let mut rounds = Rounds::new(links.len(), BUDGET);
    let mut nic = Nic {
        net,
        switch,
        links,
        counts: Counts { bogus: 0, runts: 0 },
        tx_pending: false,
        tx_interrupts: false,
    };
    nic.net.tx.set_interrupts(&mut nic.net.mem, false);
    let mut frame = [0u8; MESSAGE];
    let start = sys::clock();
    let mut next_log = STATS_EVERY_MS;
    loop {
        nic.switch.set_time(sys::clock());
        nic.serve_wire(&mut frame);
        nic.reclaim();
        nic.serve_tenants(&mut rounds, &mut frame);
        if core::mem::take(&mut nic.tx_pending) {
            nic.net.kick(TRANSMIT_QUEUE);
        }
        if nic.ask_transmit_interrupts() {
            continue;
        }
        let now_ms = (sys::clock() - start) / 1_000_000;
        if now_ms >= next_log {
            nic.log(now_ms);
            next_log = now_ms - now_ms % STATS_EVERY_MS + STATS_EVERY_MS;
        }
        let tenants = (1u64 << nic.links.len()) - 1;
        let (doorbells, rings) = (tenants << DOORBELL_BIT, tenants << RING_BIT);
        let wait = sys::notify_wait(1 << IRQ_BIT | doorbells | rings, poll.as_nanos() as u64);
        let bits = wait.unwrap_or(0);
        if bits & 1 << IRQ_BIT != 0 {
            nic.net.interrupt_status();
            let _ = sys::irq_ack(u64::from(line));
        }
        for (n, link) in nic.links.iter_mut().enumerate() {
            if link.ring.is_some() && bits & 1 << (DOORBELL_BIT + n as u64) != 0 {
                link.drain_wakeups(&mut frame);
            }
        }
    }
}

struct NicPartition;

impl Partition<Warden> for NicPartition {
    fn cold_start(&self, ctx: &mut StartContext<Warden>) {
        let Some(table) = table() else { return };
        for t in table.tenants() {
            if let Err(e) = link::create(ctx, &t.from, &t.to) {
                refuse(format_args!(
                    "tenant {} (ports {}/{}): {e}",
                    t.partition, t.from.name, t.to.name
                ));
                return;
            }
        }
        const { assert!(MAX_FRAME <= MESSAGE) };
        if let Err(e) = main_process::start(ctx, "switch", run, 32 * 1024, Release::Aperiodic) {
            refuse(format_args!("{e}"));
        }
    }

    fn warm_start(&self, ctx: &mut StartContext<Warden>) {
        self.cold_start(ctx)
    }
}

fn main() {
    NicPartition.run()
}

apex::partition_entry!(main);
