//! The block-device partition program (`image = "blk"`): drives the virtio-blk function
//! the partition owns (`devices`, modern PCI transport, behind the IOMMU with `dma`;
//! `device.rs`) and serves each tenant its virtual disk, a fixed range of the disk's
//! sectors (`blk.tenants`, the data entry `blk_core::tenants`), over a pair of queuing
//! ports: one request a message in, one response a message out (`blk_core::link`: read,
//! write, flush, a CRC-32 over each). A request is decoded, its CRC checked and its
//! sectors checked against the tenant's range here, before the device sees it
//! (`blk_core::driver::serve`); a flush reaches the device (QEMU `cache=writeback`).
//!
//! One APEX process serves the tenants round-robin, one request at a time, at most
//! [`BUDGET`] requests a tenant and round; with nothing to do it waits for a tenant's
//! doorbell (syssw notifies it when a request arrives), at most [`POLL`].
//!
//! Log lines (on the serial log as `[<partition>] blk: ...`; an interface):
//! - `blk: virtio-blk <BB:DD.F> <n> sectors, flush <yes|no>, line <irq>, <k> tenant(s)`
//!   once up, then `blk: tenant <partition> sectors <first>+<n> from <port> to <port>`;
//! - `blk: not started: <reason>` when the tenant table (also against the disk's
//!   capacity), the device or the DMA region is unusable (also reported to the health
//!   monitor as APPLICATION_ERROR; the partition then idles);
//! - `blk: tenant <partition> refused: <reason>` for each request refused (malformed,
//!   damaged, outside its range), at most [`REFUSALS_LOGGED`] a tenant;
//! - every [`STATS_EVERY_MS`] of the partition's clock while requests were served, for each
//!   tenant `blk: t=<ms>ms tenant <partition> reads=<n> writes=<n> flushes=<n>
//!   refused=<n> failed=<n>` (failed: the device's error), counted since start.
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
use blk_core::driver::{Outcome, serve};
use blk_core::link::{MAX_REQUEST, MAX_RESPONSE, Operation, Status};
use blk_core::tenants::Table;
use blk_core::virtio_blk::{FEATURE_FLUSH, Refusal};
use core::time::Duration;
use device::Disk;
use driver_link as link;

/// Requests a tenant may have served per round.
const BUDGET: u32 = 4;
/// The longest wait when no tenant has a request (a tenant without a doorbell is found
/// then).
const POLL: Duration = Duration::from_micros(500);
/// The notification bit the device's interrupt line fires as (an index; the APEX
/// runtime's bits are 0 and 1).
const IRQ_BIT: u64 = 8;
/// The notification bit of the tenants' doorbells.
const DOORBELL_BIT: u64 = 1 << 9;
const STATS_EVERY_MS: u64 = 1000;
const REFUSALS_LOGGED: u64 = 8;
/// virtio's PCI vendor and its block device ids (transitional, modern).
const VIRTIO_VENDOR: u16 = 0x1af4;
const VIRTIO_BLK: [u16; 2] = [0x1001, 0x1042];

fn refuse(text: core::fmt::Arguments<'_>) {
    let line = alloc::format!("{text}");
    println!("blk: not started: {line}");
    let _ = <Warden as ApexErrorP4Ext>::raise_application_error(line.as_bytes());
}

fn table() -> Option<Table<'static>> {
    match blk_core::tenants::decode(apex::runtime::start_info().data()) {
        Ok(t) => Some(t),
        Err(e) => {
            refuse(format_args!("the tenant table (data entry): {e}"));
            None
        }
    }
}

#[derive(Default)]
struct Counts {
    reads: u64,
    writes: u64,
    flushes: u64,
    refused: u64,
    failed: u64,
}

struct Tenant {
    name: &'static str,
    disk: blk_core::disk::VirtualDisk,
    from: QueuingPortReceiver<Warden>,
    to: QueuingPortSender<Warden>,
    counts: Counts,
}

impl Tenant {
    fn count(&mut self, outcome: Outcome) {
        let c = &mut self.counts;
        match outcome {
            Outcome::Done(_, s) if s != Status::Ok => c.failed += 1,
            Outcome::Done(Operation::Read, _) => c.reads += 1,
            Outcome::Done(Operation::Write, _) => c.writes += 1,
            Outcome::Done(Operation::Flush, _) => c.flushes += 1,
            Outcome::Refused(why) => {
                c.refused += 1;
                if c.refused <= REFUSALS_LOGGED {
                    let reason = match why {
                        Refusal::Malformed(e) => alloc::format!("{e}"),
                        Refusal::OutOfRange(e) => alloc::format!("{e}"),
                        Refusal::ReadOnly => "the disk is read-only".into(),
                        Refusal::NoFlush => "the device has no flush".into(),
                    };
                    println!("blk: tenant {} refused: {reason}", self.name);
                }
            }
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
    let claim = match pci::claim(page, VIRTIO_VENDOR, &VIRTIO_BLK) {
        Ok(claim) => claim,
        Err(e) => {
            refuse(format_args!("virtio-blk: {e}"));
            return;
        }
    };
    let (record, line) = (claim.record, claim.line);
    if let Err(e) = sys::irq_attach(u64::from(line), IRQ_BIT) {
        refuse(format_args!("interrupt line {line}: {e:?}"));
        return;
    }
    let mut disk = match Disk::bring_up(&record, &claim.capabilities, claim.region, u64::from(line))
    {
        Ok(d) => d,
        Err(e) => {
            refuse(format_args!("virtio-blk {}: {e}", record.address));
            return;
        }
    };
    if let Err(e) = table.check(disk.capacity) {
        refuse(format_args!("the tenant table: {e}"));
        return;
    }
    let mut tenants = Vec::new();
    for t in table.tenants() {
        let link = match link::open(&t.from, &t.to) {
            Ok(link) => link,
            Err(e) => {
                refuse(format_args!("tenant {}: {e}", t.partition));
                return;
            }
        };
        if let Err(e) = link.ring_on_arrival(DOORBELL_BIT) {
            println!(
                "blk: tenant {}: no doorbell ({e:?}); its port is polled",
                t.partition
            );
        }
        let link::Link { from, to } = link;
        tenants.push(Tenant {
            name: t.partition,
            disk: t.disk,
            from,
            to,
            counts: Counts::default(),
        });
    }
    println!(
        "blk: virtio-blk {} {} sectors, flush {}, line {line}, {} tenant(s)",
        record.address,
        disk.capacity,
        if disk.features & FEATURE_FLUSH != 0 {
            "yes"
        } else {
            "no"
        },
        tenants.len()
    );
    for t in table.tenants() {
        println!(
            "blk: tenant {} sectors {}+{} from {} to {}",
            t.partition, t.disk.first_sector, t.disk.sectors, t.from.name, t.to.name
        );
    }
    let mut request = [0u8; MAX_REQUEST];
    let mut response = [0u8; MAX_RESPONSE];
    let start = sys::clock();
    let mut next_log = STATS_EVERY_MS;
    let mut served_since_log = false;
    loop {
        let mut served = false;
        for t in tenants.iter_mut() {
            for _ in 0..BUDGET {
                let Ok((msg, _)) = t
                    .from
                    .receive(&mut request, SystemTime::Normal(Duration::ZERO))
                else {
                    break;
                };
                let (n, outcome) = serve(msg, &t.disk, disk.features, &mut disk, &mut response);
                t.count(outcome);
                // A tenant whose port is full loses its own response (it times out).
                let _ =
                    t.to.send(&response[..n], SystemTime::Normal(Duration::ZERO));
                served = true;
            }
        }
        served_since_log |= served;
        let now_ms = sys::clock().saturating_sub(start) / 1_000_000;
        if now_ms >= next_log {
            if served_since_log {
                for t in &tenants {
                    let c = &t.counts;
                    println!(
                        "blk: t={now_ms}ms tenant {} reads={} writes={} flushes={} refused={} failed={}",
                        t.name, c.reads, c.writes, c.flushes, c.refused, c.failed
                    );
                }
                served_since_log = false;
            }
            next_log = now_ms - now_ms % STATS_EVERY_MS + STATS_EVERY_MS;
        }
        if !served {
            let _ = sys::notify_wait(DOORBELL_BIT, POLL.as_nanos() as u64);
        }
    }
}

struct BlkPartition;

impl Partition<Warden> for BlkPartition {
    fn cold_start(&self, ctx: &mut StartContext<Warden>) {
        let Some(table) = table() else { return };
        for t in table.tenants() {
            if (t.from.size as usize) < MAX_REQUEST || (t.to.size as usize) < MAX_RESPONSE {
                refuse(format_args!(
                    "tenant {}: ports of {}/{} bytes, a request needs {MAX_REQUEST} and a response {MAX_RESPONSE}",
                    t.partition, t.from.size, t.to.size
                ));
                return;
            }
            if let Err(e) = link::create(ctx, &t.from, &t.to) {
                refuse(format_args!(
                    "tenant {} (ports {}/{}): {e}",
                    t.partition, t.from.name, t.to.name
                ));
                return;
            }
        }
        if let Err(e) = main_process::start(ctx, "server", run, 32 * 1024, Release::Aperiodic) {
            refuse(format_args!("{e}"));
        }
    }

    fn warm_start(&self, ctx: &mut StartContext<Warden>) {
        self.cold_start(ctx)
    }
}

fn main() {
    BlkPartition.run()
}

apex::partition_entry!(main);
