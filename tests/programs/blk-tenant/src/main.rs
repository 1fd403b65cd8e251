//! A tenant of a block-device partition (scenario `blk_tenants`), joined to it by its
//! queuing ports `req` (requests out) and `resp` (responses in). It checks its virtual
//! disk through the link, logging `check ok: <what>` or `check FAILED: <what>` for each:
//! a slot record written and read back through `slots` (scan, write, read), a flushed
//! sector of its partition name's pattern read back, a request beyond its range refused
//! (OutOfRange), a damaged request refused (BadRequest), 32 sectors written one request
//! each, flushed and read back (timed: `blk-tenant: <partition> 32 single-sector writes
//! <us> us, flush <us> us, 32 reads <us> us`); then `blk-tenant: <partition> done`. A test program: it must never be needed by anything
//! but its scenario.
#![no_std]
#![no_main]

use apex::Warden;
use apex::a653rs::prelude::*;
use apex::main_process::{self, Release};
use apex::user_rt::println;
use blk_core::SECTOR;
use blk_core::client::{Client, ClientError, Transport};
use blk_core::link::{self, MAX_REQUEST, MAX_RESPONSE, Operation, Status};
use core::str::FromStr;
use core::time::Duration;
use slots::BlockDevice;

/// The sectors of the virtual disk the scenario's configuration gives each tenant.
const SECTORS: u64 = 64;
const REGION: slots::Region = slots::Region {
    first: 0,
    sectors: 16,
    kind: 7,
};

fn now_us() -> u64 {
    <Warden as ApexTimeP4Ext>::get_time()
        .unwrap_duration()
        .as_micros() as u64
}

fn name(text: &str) -> Name {
    Name::from_str(text).expect("names here are short")
}

struct Ports {
    req: QueuingPortSender<Warden>,
    resp: QueuingPortReceiver<Warden>,
}

impl Transport for Ports {
    type Error = &'static str;
    fn exchange(&mut self, request: &[u8], response: &mut [u8]) -> Result<usize, &'static str> {
        self.req
            .send(request, SystemTime::Normal(Duration::from_secs(1)))
            .map_err(|_| "the request port stayed full")?;
        let (msg, _) = self
            .resp
            .receive(response, SystemTime::Normal(Duration::from_secs(5)))
            .map_err(|_| "no response within 5 s")?;
        Ok(msg.len())
    }
}

fn check(ok: bool, what: core::fmt::Arguments<'_>) {
    if ok {
        println!("check ok: {what}");
    } else {
        println!("check FAILED: {what}");
    }
}

extern "C" fn run() {
    let info = apex::runtime::start_info();
    let me = info.name();
    let mut disk = Client::new(Ports {
        req: QueuingPortSender::from_name(name("req")).expect("req"),
        resp: QueuingPortReceiver::from_name(name("resp")).expect("resp"),
    });

    // A slot record through the whole path.
    let payload = payload_of(me);
    let len = me.len() + 600;
    let wrote = slots::scan(&mut disk, &REGION)
        .and_then(|scan| slots::write(&mut disk, &REGION, &scan, &payload[..len]));
    let read_back = wrote.and_then(|_| {
        let scan = slots::scan(&mut disk, &REGION)?;
        let record = scan.newest().ok_or(slots::Error::Region)?;
        let mut back = [0u8; 1024];
        let n = slots::read(&mut disk, &REGION, &record, &mut back)?;
        Ok((
            record.sequence,
            n == Some(me.len() + 600) && back[..me.len() + 600] == payload[..me.len() + 600],
        ))
    });
    check(
        matches!(read_back, Ok((_, true))),
        format_args!("{me}: a slot record written and read back ({read_back:?})"),
    );

    // A flushed sector of its own pattern.
    let pattern = [me.as_bytes()[0]; SECTOR];
    let mut back = [0u8; SECTOR];
    let result = disk
        .write(20, &pattern)
        .and_then(|()| disk.flush())
        .and_then(|()| disk.read(20, &mut back));
    check(
        result.is_ok() && back == pattern,
        format_args!("{me}: sector 20 written, flushed and read back ({result:?})"),
    );

    // Beyond its range: refused by the driver.
    let beyond = disk.read(SECTORS, &mut back);
    check(
        beyond == Err(ClientError::Status(Status::OutOfRange)),
        format_args!("{me}: sector {SECTORS} is beyond its virtual disk ({beyond:?})"),
    );

    // A damaged request: refused, nothing written.
    let mut request = [0u8; MAX_REQUEST];
    let mut response = [0u8; MAX_RESPONSE];
    let n = link::encode_request(Operation::Write, 99, 21, 1, &[0xee; SECTOR], &mut request)
        .expect("a request");
    request[100] ^= 1;
    let status = disk_transport(&mut disk)
        .exchange(&request[..n], &mut response)
        .ok()
        .and_then(|len| link::decode_response(&response[..len]).ok())
        .map(|r| (r.tag, r.status));
    let untouched = disk.read(21, &mut back).is_ok() && back != [0xee; SECTOR];
    check(
        status == Some((99, Status::BadRequest)) && untouched,
        format_args!("{me}: a damaged request is refused and not written ({status:?})"),
    );
    // Timing: 32 sectors written one request each, a flush, read back (each request
    // waits for the block-device partition's window: this measures the schedule as much
    // as the device).
    let t0 = now_us();
    let wrote = (24..56).all(|s| disk.write(s, &pattern).is_ok());
    let t1 = now_us();
    let flushed = disk.flush().is_ok();
    let t2 = now_us();
    let read = (24..56).all(|s| disk.read(s, &mut back).is_ok() && back == pattern);
    let t3 = now_us();
    check(
        wrote && flushed && read,
        format_args!("{me}: 32 sectors written, flushed and read back"),
    );
    println!(
        "blk-tenant: {me} 32 single-sector writes {} us, flush {} us, 32 reads {} us",
        t1 - t0,
        t2 - t1,
        t3 - t2
    );
    println!("blk-tenant: {me} done");
    loop {
        let _ = <Warden as ApexTimeP1Ext>::timed_wait(Duration::from_secs(1));
    }
}

/// The payload of its slot record: its name, then a counting pattern.
fn payload_of(me: &str) -> [u8; 1024] {
    let mut p = [0u8; 1024];
    p[..me.len()].copy_from_slice(me.as_bytes());
    for (i, b) in p[me.len()..].iter_mut().enumerate() {
        *b = i as u8;
    }
    p
}

fn disk_transport(disk: &mut Client<Ports>) -> &mut Ports {
    disk.transport_mut()
}

struct Tenant;

impl Partition<Warden> for Tenant {
    fn cold_start(&self, ctx: &mut StartContext<Warden>) {
        let fifo = QueuingDiscipline::Fifo;
        ctx.create_queuing_port_sender(name("req"), MAX_REQUEST as u32, 2, fifo)
            .expect("CREATE_QUEUING_PORT req");
        ctx.create_queuing_port_receiver(name("resp"), MAX_RESPONSE as u32, 2, fifo)
            .expect("CREATE_QUEUING_PORT resp");
        main_process::start(ctx, "tenant", run, 32 * 1024, Release::Aperiodic)
            .unwrap_or_else(|e| panic!("{e}"));
    }

    fn warm_start(&self, ctx: &mut StartContext<Warden>) {
        self.cold_start(ctx)
    }
}

fn main() {
    Tenant.run()
}

apex::partition_entry!(main);
