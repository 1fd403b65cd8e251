//! The doorbell of the guest's ports: a thread of its own asks syssw to notify it when a
//! message arrives at one of the guest's queuing destination ports (PORT_DOORBELL of the
//! service protocol), waits for that notification, or for the NIC partition's when a frame
//! goes into `eth0`'s empty ring ([`RING_BIT`]), and tells the main thread with an IPC
//! message ([`LABEL_RUNG`], the bits that rang in its first word), as the COM2 reader does
//! with input. The main thread waits in
//! `receive` for its processes' exception messages, which a notification cannot end, so
//! the news must come as a message. It then looks at `eth0`'s frames and serves the calls
//! waiting for ports at once, where it would otherwise find them at its next poll.
//!
//! The doorbell is an optimisation: when it cannot be set up, the polls still find every
//! message, later.

use user_rt::abi::ipc::MessageTag;
use user_rt::abi::syscall::{Error, TIMEOUT_INFINITE, ThreadId};
use user_rt::println;
use user_rt::protocol::{self, Request, ReturnCode};
use user_rt::sys::{self, Message};

/// The label of the message to the main thread: messages arrived at a port.
pub const LABEL_RUNG: u32 = 0x6265_6c6c; // "bell"
/// The notification bit syssw rings.
pub const PORT_BIT: u64 = 1;
/// The notification bit the NIC partition rings when a frame goes into `eth0`'s empty
/// ring (the ring's `waiter`).
pub const RING_BIT: u64 = 2;
/// Most ports it watches.
pub const MAX_PORTS: usize = 16;

const STACK_SIZE: usize = 8192;
#[repr(C, align(16))]
struct Stack([u8; STACK_SIZE]);
// Used only through its address, by the doorbell thread running on it.
static mut STACK: Stack = Stack([0; STACK_SIZE]);

/// What the thread needs, written before it starts and only read by it afterwards.
struct Setup {
    main: ThreadId,
    server: ThreadId,
    ports: [u64; MAX_PORTS],
    count: usize,
}

static SETUP: spin::Once<Setup> = spin::Once::new();

/// Starts the doorbell thread for syssw's port ids `ports` (at most [`MAX_PORTS`]; the
/// rest are polled), telling `main`.
pub fn start(
    main: ThreadId,
    server: ThreadId,
    priority: u8,
    ports: &[u64],
) -> Result<ThreadId, Error> {
    let mut ids = [0; MAX_PORTS];
    let count = ports.len().min(MAX_PORTS);
    ids[..count].copy_from_slice(&ports[..count]);
    SETUP.call_once(|| Setup {
        main,
        server,
        ports: ids,
        count,
    });
    let stack = (&raw mut STACK).cast::<u8>() as u64;
    // As if called: the SysV ABI expects rsp + 8 to be 16-byte aligned at entry.
    let top = stack + STACK_SIZE as u64 - 8;
    let thread = sys::thread_create(None, doorbell as *const () as u64, top, priority, 0)?;
    sys::thread_start(thread)?;
    Ok(thread)
}

extern "C" fn doorbell(_: u64) -> ! {
    let Some(setup) = SETUP.get() else {
        sys::thread_exit();
    };
    for &port in &setup.ports[..setup.count] {
        let request = Request::PortDoorbell {
            port,
            bits: PORT_BIT,
        };
        let answer = user_rt::service::request_without_buffer(setup.server, &request)
            .map(|reply| protocol::reply_result(reply.label));
        if !matches!(answer, Ok(Ok(Ok(())))) {
            let why = match answer {
                Ok(Ok(Err(code))) => code.name(),
                _ => ReturnCode::NotAvailable.name(),
            };
            println!("guest: port {port}: no doorbell ({why}); it is polled");
        }
    }
    loop {
        let Ok(bits) = sys::notify_wait(PORT_BIT | RING_BIT, TIMEOUT_INFINITE) else {
            continue;
        };
        let rung = Message {
            tag: MessageTag::new(LABEL_RUNG, 0, 0),
            words: [bits, 0, 0],
        };
        if sys::send(setup.main, TIMEOUT_INFINITE, &rung).is_err() {
            sys::thread_exit();
        }
    }
}
