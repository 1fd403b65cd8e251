//! The partition's side of its persistent store (`plc.store`; what is stored and how:
//! `softplc::persist`, `softplc::store`): the link to the block-device partition over the
//! store's two queuing ports, the load at a cold start (by the control process before the
//! first program runs), the copies the control process makes between releases
//! ([`after_release`], [`committed`]: the only cost on its path) and the store process
//! ([`store_process`]), below it, which writes them to the disk and waits for the
//! block-device partition meanwhile.

use crate::{name, report};
use apex::Warden;
use apex::a653rs::prelude::*;
use apex::user_rt::print::LineBuffer;
use apex::user_rt::println;
use blk_core::client::{Client, Transport};
use core::fmt::Write;
use core::sync::atomic::{AtomicU8, Ordering};
use core::time::Duration;
use plc_vm::image::Image;
use softplc::package::Package;
use softplc::persist::{self, Found, Layout, Store};
use softplc::store::{self, RetainSchedule};

/// The largest encoded boot project (a program of the largest download and a watch list).
const BOOT_MAX: usize = crate::MAX_IMAGE + 4 * 1024;
/// The largest encoded RETAIN snapshot: 64 KiB of values with their names and headers.
const RETAIN_MAX: usize = 68 * 1024;

/// The store's ports as the client's transport.
pub struct Ports {
    request: QueuingPortSender<Warden>,
    response: QueuingPortReceiver<Warden>,
}

impl Transport for Ports {
    type Error = &'static str;
    fn exchange(&mut self, request: &[u8], response: &mut [u8]) -> Result<usize, &'static str> {
        // Responses to requests given up on (a timeout) are stale: dropped first.
        while self
            .response
            .receive(response, SystemTime::Normal(Duration::ZERO))
            .is_ok()
        {}
        self.request
            .send(request, SystemTime::Normal(Duration::from_secs(1)))
            .map_err(|_| "the request port stayed full for 1 s")?;
        let (message, _) = self
            .response
            .receive(response, SystemTime::Normal(Duration::from_secs(5)))
            .map_err(|_| "no response within 5 s")?;
        Ok(message.len())
    }
}

/// The disk and what start found on it (the store process's after the load).
static DISK: spin::Mutex<Option<(Client<Ports>, Store)>> = spin::Mutex::new(None);

/// The reading at the start ([`load`]): asked by the control process, done by the store
/// process.
static LOAD: AtomicU8 = AtomicU8::new(LOAD_NONE);
const LOAD_NONE: u8 = 0;
const LOAD_COLD: u8 = 1;
const LOAD_WARM: u8 = 2;
const LOAD_DONE: u8 = 3;
/// The boot project's record the reading found (its payload in the outbox).
static LOADED: spin::Mutex<Option<slots::Record>> = spin::Mutex::new(None);

/// What the control process copied for the store process.
struct Outbox {
    /// An encoded boot project waiting (its length).
    boot: Option<usize>,
    /// An encoded RETAIN snapshot waiting (its length and release).
    retain: Option<(usize, u64)>,
    /// How long the control process took to copy the waiting snapshot (ns).
    copy_ns: u64,
    boot_bytes: [u8; BOOT_MAX],
    retain_bytes: [u8; RETAIN_MAX],
}

static OUTBOX: spin::Mutex<Outbox> = spin::Mutex::new(Outbox {
    boot: None,
    retain: None,
    copy_ns: 0,
    boot_bytes: [0; BOOT_MAX],
    retain_bytes: [0; RETAIN_MAX],
});

/// The outbox for the control process at a program's start, when nothing is pending: the
/// store process holds it at most for a look. The control process sleeps while it does
/// (spinning, above the store process, it would never let it finish).
fn outbox_waiting() -> spin::MutexGuard<'static, Outbox> {
    loop {
        if let Some(outbox) = OUTBOX.try_lock() {
            return outbox;
        }
        apex::user_rt::sys::sleep_until(crate::now_ns() + 20_000);
    }
}

/// The control process's side: when RETAIN is due, the running program's CRC and the
/// snapshot start loaded to restore into the first program.
struct Control {
    schedule: RetainSchedule,
    program_crc: u32,
    /// The loaded snapshot's length in `OUTBOX.retain_bytes` until it is restored.
    restore: Option<usize>,
    /// The running program came by a download at this release and is not saved yet.
    boot_due: Option<u64>,
}

static CONTROL: spin::Mutex<Option<Control>> = spin::Mutex::new(None);

/// After a partition restart: the previous life's processes may have died holding the
/// locks; its ports are created again.
pub fn release_locks() {
    for lock in [&DISK as &dyn Forced, &OUTBOX, &CONTROL, &LOADED] {
        lock.open();
    }
    LOAD.store(LOAD_NONE, Ordering::Release);
    *LOADED.lock() = None;
    *DISK.lock() = None;
    let mut outbox = OUTBOX.lock();
    outbox.boot = None;
    outbox.retain = None;
    *CONTROL.lock() = None;
}

trait Forced {
    fn open(&self);
}

impl<T> Forced for spin::Mutex<T> {
    #[allow(unsafe_code)] // forcing a spin lock open
    fn open(&self) {
        if self.is_locked() {
            // SAFETY: called on the initialisation thread of a (re)started partition
            // before any process exists: no guard of the lock is alive.
            unsafe { self.force_unlock() };
        }
    }
}

/// A partition start, by the control process before the first program runs: reads the
/// store (reporting skipped slots); the boot project, if one is valid and `accept` takes
/// it, is copied into `image` (its length returned); at a `cold` start a valid RETAIN
/// snapshot is kept for [`start`] (a warm start keeps RAM's RETAIN values). Logs what was
/// loaded.
pub fn load(
    package: &Package,
    cold: bool,
    image: &mut [u8],
    accept: impl FnOnce(&[u8]) -> Result<(), softplc::download::Refusal>,
) -> Option<usize> {
    package.store()?;
    // The store process reads (on its own stack: the control process's holds the online
    // buffers); the checks run here.
    LOAD.store(if cold { LOAD_COLD } else { LOAD_WARM }, Ordering::Release);
    while LOAD.load(Ordering::Acquire) != LOAD_DONE {
        apex::user_rt::sys::sleep_until(crate::now_ns() + 1_000_000);
    }
    let record = LOADED.lock().take()?;
    let outbox = outbox_waiting();
    let mut boot_len = None;
    let payload = &outbox.boot_bytes[..record.len];
    let refused = |why: core::fmt::Arguments<'_>| {
        report(
            text!(
                "store: boot project #{} refused: {why}; the configured program runs",
                record.sequence
            )
            .as_str(),
        )
    };
    match store::decode_boot(payload) {
        Err(e) => refused(format_args!("{e}")),
        Ok(b) if b.program.len() > image.len() => refused(format_args!(
            "{} bytes, the most is {}",
            b.program.len(),
            image.len()
        )),
        Ok(b) => match accept(b.program) {
            Err(e) => refused(format_args!("{e}")),
            Ok(()) => {
                image[..b.program.len()].copy_from_slice(b.program);
                boot_len = Some(b.program.len());
                if cold {
                    persist::STATUS.boot_loaded(record.sequence);
                }
                println!(
                    "plc: store: boot project #{} loaded: {} bytes, downloaded at release {}",
                    record.sequence,
                    b.program.len(),
                    b.release
                );
                // The configuration's watch list wins (it names variables of the program:
                // `accept` checked); say so when the one saved with it differs.
                let saved = b.watch.lines();
                if !saved.clone().eq(package.watch()) {
                    let mut line = text!(
                        "plc: store: boot project #{} was saved watching",
                        record.sequence
                    );
                    for name in saved {
                        let _ = write!(line, " {name}");
                    }
                    let _ = write!(line, "; the configured watch list is used");
                    println!("{}", line.as_str());
                }
            }
        },
    }
    boot_len
}

/// The reading part of [`load`]: the boot project's record (its payload in the outbox), if
/// one is valid; the RETAIN snapshot kept for [`start`].
#[inline(never)]
fn read(package: &Package, period_ns: u64, cold: bool) -> Option<slots::Record> {
    let config = package.store()?;
    let port = |i: usize| package.port(i).and_then(|p| name(p.name));
    let ports = (|| {
        Some(Ports {
            request: QueuingPortSender::from_name(port(config.request)?).ok()?,
            response: QueuingPortReceiver::from_name(port(config.response)?).ok()?,
        })
    })();
    let Some(ports) = ports else {
        report("store: its ports cannot be opened");
        return None;
    };
    let Some(layout) = Layout::of(config.sectors) else {
        report("store: the virtual disk has fewer than 8 sectors; nothing is stored");
        return None;
    };
    let mut disk = Client::new(ports);
    let mut outbox = OUTBOX.lock();
    let outbox = &mut *outbox;
    let every = persist::retain_every_releases(config.retain_every_ns, period_ns);
    let mut control = Control {
        schedule: RetainSchedule::new(every),
        program_crc: 0,
        restore: None,
        boot_due: None,
    };
    let mut boot_record = None;
    match persist::load(
        &mut disk,
        layout,
        &mut outbox.boot_bytes,
        &mut outbox.retain_bytes,
    ) {
        Err(e) => {
            report(text!("store: cannot be read: {e}; nothing is loaded").as_str());
            *CONTROL.lock() = Some(control);
            return None;
        }
        Ok((found_store, boot, retain)) => {
            skipped("boot project", &boot, cold);
            skipped("RETAIN", &retain, cold);
            if cold {
                persist::STATUS.cold_start();
            }
            if !cold {
                // A warm restart runs the boot project too, with RAM's RETAIN values.
                *DISK.lock() = Some((disk, found_store));
                *CONTROL.lock() = Some(control);
                return boot.loaded;
            }
            match boot.loaded {
                None => println!("plc: store: no boot project; the configured program runs"),
                Some(record) => boot_record = Some(record),
            }
            match retain.loaded {
                None => println!("plc: store: no RETAIN snapshot; initial values"),
                Some(record) => match store::decode_retain(&outbox.retain_bytes[..record.len]) {
                    Ok(snapshot) => {
                        println!(
                            "plc: store: RETAIN snapshot #{} loaded: {} variable(s) of release {}",
                            record.sequence, snapshot.count, snapshot.release
                        );
                        control.restore = Some(record.len);
                        persist::STATUS.retain_loaded(record.sequence);
                    }
                    Err(e) => report(
                        text!(
                            "store: RETAIN snapshot #{} refused: {e}; initial values",
                            record.sequence
                        )
                        .as_str(),
                    ),
                },
            }
            *DISK.lock() = Some((disk, found_store));
        }
    }
    *CONTROL.lock() = Some(control);
    boot_record
}

/// Logs the slots of `region` that start skipped, and at a `cold` start reports them (a
/// warm restart the report caused must not report them again).
fn skipped(region: &str, found: &Found, cold: bool) {
    for (slot, corruption) in found.skipped.iter().flatten() {
        let text = text!("store: {region} slot {slot} skipped: {corruption}");
        if cold {
            report(text.as_str());
        } else {
            println!("plc: {}", text.as_str());
        }
    }
}

/// A program starts (`program` its bytes, `image` parsed, `data` its memory, initialised
/// or handed over; `downloaded_at`: the release a committed download swapped it in): the
/// snapshot loaded at a cold start goes into the first one; a downloaded one becomes the
/// boot project and RETAIN is saved at the next release.
pub fn start(program: &[u8], image: &Image, data: &mut [u8], downloaded_at: Option<u64>) {
    let mut control = CONTROL.lock();
    let Some(control) = control.as_mut() else {
        return;
    };
    control.program_crc = plc_online::crc32(program);
    if downloaded_at.is_some() {
        control.boot_due = downloaded_at;
        control.schedule.force();
    }
    if let Some(len) = control.restore.take() {
        let outbox = outbox_waiting();
        if let Ok(snapshot) = store::decode_retain(&outbox.retain_bytes[..len]) {
            let n = store::restore_retain(&snapshot, image, control.program_crc, data);
            println!("plc: store: {n} RETAIN variable(s) restored");
        }
    }
}

/// After a release's online requests (the control process, between releases; it never
/// waits for the store process): at `release`, a downloaded program not saved yet is
/// copied for the store process as the boot project, and RETAIN when due, or at once
/// when a task `stopped` at this release.
pub fn after_release(
    package: &Package,
    program: &[u8],
    image: &Image,
    data: &[u8],
    release: u64,
    stopped: bool,
) {
    let mut control = CONTROL.lock();
    let Some(control) = control.as_mut() else {
        return;
    };
    if stopped {
        control.schedule.force();
    }
    if control.boot_due.is_none() && !control.schedule.due(release) {
        return;
    }
    // The store process is writing: the next release tries again.
    let Some(mut outbox) = OUTBOX.try_lock() else {
        return;
    };
    let outbox = &mut *outbox;
    if let Some(at) = control.boot_due.take() {
        let mut watch = alloc::string::String::new();
        for name in package.watch() {
            watch.push_str(name);
            watch.push('\n');
        }
        match store::encode_boot(at, program, &watch, &mut outbox.boot_bytes) {
            Ok(n) => outbox.boot = Some(n),
            Err(e) => report(text!("store: boot project not saved: {e}").as_str()),
        }
    }
    if !control.schedule.due(release) {
        return;
    }
    let copy_start = crate::now_ns();
    match store::encode_retain(
        image,
        control.program_crc,
        data,
        release,
        &mut outbox.retain_bytes,
    ) {
        Ok(n) => {
            outbox.retain = Some((n, release));
            outbox.copy_ns = crate::now_ns() - copy_start;
        }
        Err(e) => report(text!("store: RETAIN not saved: {e}").as_str()),
    }
    control.schedule.saved(release);
}

/// The store process: writes what the control process copied, once per period.
pub extern "C" fn store_process() {
    // The control process asks for the reading at its start.
    let cold = loop {
        match LOAD.load(Ordering::Acquire) {
            LOAD_COLD => break true,
            LOAD_WARM => break false,
            _ => apex::user_rt::sys::sleep_until(crate::now_ns() + 1_000_000),
        }
    };
    if let Ok(package) = Package::parse(apex::runtime::start_info().data()) {
        *LOADED.lock() = read(&package, crate::period().as_nanos() as u64, cold);
    }
    LOAD.store(LOAD_DONE, Ordering::Release);
    loop {
        write_pending();
        if <Warden as ApexTimeP4Ext>::periodic_wait().is_err() {
            println!("plc: store: PERIODIC_WAIT failed; stopping");
            return;
        }
    }
}

fn write_pending() {
    let mut disk = DISK.lock();
    let Some((client, found)) = disk.as_mut() else {
        return;
    };
    // Held while it writes: the control process never waits for it (it tries).
    let mut outbox = OUTBOX.lock();
    let outbox = &mut *outbox;
    if let Some(n) = outbox.boot.take() {
        match found.write_boot(client, &outbox.boot_bytes[..n]) {
            Ok(r) => {
                persist::STATUS.boot_saved(r.sequence);
                println!("plc: store: boot project #{} saved ({n} bytes)", r.sequence)
            }
            Err(e) => report(text!("store: boot project not saved: {e}").as_str()),
        }
    }
    if let Some((n, release)) = outbox.retain.take() {
        // The store process's time for the save: its sector writes and both flushes.
        let write_start = crate::now_ns();
        match found.write_retain(client, &outbox.retain_bytes[..n]) {
            Ok(r) => {
                let written_ns = crate::now_ns() - write_start;
                persist::STATUS.retain_saved(r.sequence);
                println!(
                    "plc: store: RETAIN snapshot #{} saved (release {release}, {n} bytes, copied in {} us, written in {} us)",
                    r.sequence,
                    outbox.copy_ns / 1_000,
                    written_ns / 1_000
                )
            }
            Err(e) => report(text!("store: RETAIN not saved: {e}").as_str()),
        }
    }
}
