//! The console device of the partition program: COM2, a 16550 UART at ports
//! 0x2f8..=0x2ff on interrupt line 3 (the partition's `io_ports` and `irqs`). Output is
//! written by polling the transmit holding register; input comes from a thread of its own,
//! the reader, which waits for line 3, drains the receive FIFO and sends the bytes to the
//! main thread as IPC messages ([`LABEL_INPUT`]). The main thread waits in `receive` for
//! its processes' exception messages, so input arriving there is one more message it
//! serves in turn, and the terminal state ([`guest::tty`]) has one owner.
//!
//! It never interprets the bytes: that is the line discipline's.

use user_rt::abi::ipc::MessageTag;
use user_rt::abi::syscall::{Error, TIMEOUT_INFINITE, ThreadId};
use user_rt::port::{inb, outb};
use user_rt::println;
use user_rt::sys::{self, Message};

const BASE: u16 = 0x2f8;
const DATA: u16 = BASE;
const IER: u16 = BASE + 1;
const FCR: u16 = BASE + 2;
const LCR: u16 = BASE + 3;
const MCR: u16 = BASE + 4;
const LSR: u16 = BASE + 5;
const SCRATCH: u16 = BASE + 7;
/// `LSR`: a received byte waits; the transmit holding register is empty.
const LSR_DATA_READY: u8 = 0x01;
const LSR_THR_EMPTY: u8 = 0x20;
const LINE: u64 = 3;
/// The notification bit the line fires as (the reader waits for nothing else).
const BIT: u64 = 0;
/// Most polls of `LSR` for one output byte before it is dropped (a stuck device must not
/// stop the guest).
const TRANSMIT_POLLS: u32 = 100_000;

/// The label of an input message: `words[0]` is the byte count (1..=16), `words[1..3]`
/// the bytes, little-endian.
pub const LABEL_INPUT: u32 = 0x636f_6e73; // "cons"
const BYTES_PER_MESSAGE: usize = 16;

const STACK_SIZE: usize = 8192;
#[repr(C, align(16))]
struct Stack([u8; STACK_SIZE]);
// Used only through its address, by the reader thread running on it.
static mut READER_STACK: Stack = Stack([0; STACK_SIZE]);

/// Sets the UART up: 8N1, FIFO on with a trigger level of one byte, the interrupt on
/// received data. `false` when there is no UART (its scratch register does not keep a
/// byte: absent ports read 0xff, which would look like endless input).
pub fn init() -> bool {
    outb(SCRATCH, 0x5a);
    if inb(SCRATCH) != 0x5a {
        return false;
    }
    outb(IER, 0);
    outb(LCR, 0x80); // divisor latch: 115200 baud
    outb(DATA, 1);
    outb(IER, 0);
    outb(LCR, 0x03);
    outb(FCR, 0x07);
    outb(MCR, 0x0b); // DTR, RTS, OUT2 (the PC's interrupt gate)
    outb(IER, 0x01);
    true
}

/// Writes one byte (dropped when the device does not take it).
pub fn put(byte: u8) {
    for _ in 0..TRANSMIT_POLLS {
        if inb(LSR) & LSR_THR_EMPTY != 0 {
            outb(DATA, byte);
            return;
        }
        core::hint::spin_loop();
    }
}

/// Starts the reader thread, which sends the input to `main`.
pub fn start_reader(main: ThreadId, priority: u8) -> Result<ThreadId, Error> {
    let stack = (&raw mut READER_STACK).cast::<u8>() as u64;
    // As if called: the SysV ABI expects rsp + 8 to be 16-byte aligned at entry.
    let top = stack + STACK_SIZE as u64 - 8;
    let thread = sys::thread_create(None, reader as *const () as u64, top, priority, main.0)?;
    sys::thread_start(thread)?;
    Ok(thread)
}

/// The bytes of an input message.
pub fn decode(m: &Message) -> ([u8; BYTES_PER_MESSAGE], usize) {
    let mut bytes = [0u8; BYTES_PER_MESSAGE];
    bytes[..8].copy_from_slice(&m.words[1].to_le_bytes());
    bytes[8..].copy_from_slice(&m.words[2].to_le_bytes());
    (bytes, (m.words[0] as usize).min(BYTES_PER_MESSAGE))
}

extern "C" fn reader(main: u64) -> ! {
    let main = ThreadId(main);
    if let Err(e) = sys::irq_attach(LINE, BIT) {
        println!("guest: console: cannot attach interrupt line {LINE}: {e:?}");
        sys::thread_exit();
    }
    loop {
        drain(main);
        let _ = sys::irq_ack(LINE);
        // A byte that came between the drain and the acknowledgement raised no new edge
        // (the line was masked and stays high): it is taken now.
        drain(main);
        let _ = sys::irq_wait(LINE, TIMEOUT_INFINITE);
    }
}

/// Sends every byte the FIFO holds to `main`. Each message waits until the main thread
/// takes it, so a flood of input is paced by the guest, not buffered.
fn drain(main: ThreadId) {
    while inb(LSR) & LSR_DATA_READY != 0 {
        let mut bytes = [0u8; BYTES_PER_MESSAGE];
        let mut n = 0;
        while n < BYTES_PER_MESSAGE && inb(LSR) & LSR_DATA_READY != 0 {
            bytes[n] = inb(DATA);
            n += 1;
        }
        let word = |i: usize| u64::from_le_bytes(bytes[i..i + 8].try_into().unwrap_or([0; 8]));
        let m = Message {
            tag: MessageTag::new(LABEL_INPUT, 0, 0),
            words: [n as u64, word(0), word(8)],
        };
        if sys::send(main, TIMEOUT_INFINITE, &m).is_err() {
            return;
        }
    }
}
