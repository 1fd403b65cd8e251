//! The service protocol between partitions and syssw (an interface: syssw serves it, the
//! APEX runtime `partitions/apex` and test programs use it).
//!
//! A request is a synchronous IPC `call` to syssw's server thread
//! ([`StartInfo::server`](crate::partition::StartInfo)) with the request's label, three
//! words and, where a request says so, data bytes in the caller's IPC buffer. The caller
//! must `call` with [`TIMEOUT_INFINITE`](abi::syscall::TIMEOUT_INFINITE): a request that
//! waits (a queuing port) carries its own time-out in a word and syssw answers when it is
//! done or timed out. The reply's label is an ARINC 653 return code ([`code`]), its words
//! and data as each request says. syssw never trusts a request: the caller's partition is
//! known from its task, every index and length is checked, and a malformed request gets
//! `INVALID_PARAM`.
//!
//! | label | request words / data | reply words / data |
//! |---|---|---|
//! | [`PARTITION_STATUS`] | – | w0 = mode \| start condition << 8 \| index << 16, w1 = period ns, w2 = duration ns |
//! | [`SET_PARTITION_MODE`] | w0 = mode ([`mode`]) | – (no reply for IDLE/restarts: the caller's thread is gone) |
//! | [`CREATE_PORT`] | w0 = kind \| direction << 8, w1 = max message size, w2 = refresh ns (sampling) or depth (queuing); data = name | w0 = port id |
//! | [`PORT_ID`] | w0 = kind; data = name | w0 = port id |
//! | [`WRITE_SAMPLING`] | w0 = port id; data = message | – |
//! | [`READ_SAMPLING`] | w0 = port id | w0 = length, w1 = validity (1 valid); data = message |
//! | [`SAMPLING_STATUS`] | w0 = port id | w0 = max size \| direction << 32, w1 = refresh ns, w2 = last validity |
//! | [`SEND_QUEUING`] | w0 = port id, w1 = time-out ns; data = message | – |
//! | [`RECEIVE_QUEUING`] | w0 = port id, w1 = time-out ns | w0 = length; data = message |
//! | [`QUEUING_STATUS`] | w0 = port id | w0 = messages \| max messages << 32, w1 = max size \| direction << 32, w2 = waiting processes |
//! | [`CLEAR_QUEUING`] | w0 = port id | – |
//! | [`REPORT_ERROR`] | w0 = error ([`error`]); data = detail text | – (or no reply: the action stopped the caller) |
//! | [`APPLICATION_MESSAGE`] | data = text | – |
//!
//! Port ids are the ports' global indexes in the configuration; a port must be created
//! (in COLD_START or WARM_START mode, matching its configuration) before use. Time-outs: 0 =
//! do not wait, `u64::MAX` = forever, else nanoseconds.

use crate::ipc_buffer::IpcBufferRef;
use crate::sys::{self, Message};
use abi::ipc::{IPC_DATA_MAX, MessageTag};
use abi::syscall::{Error, TIMEOUT_INFINITE, ThreadId};
use core::sync::atomic::{AtomicU64, Ordering};

pub const PARTITION_STATUS: u32 = 1;
pub const SET_PARTITION_MODE: u32 = 2;
pub const CREATE_PORT: u32 = 10;
pub const PORT_ID: u32 = 11;
pub const WRITE_SAMPLING: u32 = 12;
pub const READ_SAMPLING: u32 = 13;
pub const SAMPLING_STATUS: u32 = 14;
pub const SEND_QUEUING: u32 = 15;
pub const RECEIVE_QUEUING: u32 = 16;
pub const QUEUING_STATUS: u32 = 17;
pub const CLEAR_QUEUING: u32 = 18;
pub const REPORT_ERROR: u32 = 20;
pub const APPLICATION_MESSAGE: u32 = 21;

/// Port kinds (`CREATE_PORT`/`PORT_ID` w0 low byte).
pub const KIND_SAMPLING: u64 = 0;
pub const KIND_QUEUING: u64 = 1;
/// Port directions (ARINC `PORT_DIRECTION_TYPE`: source, destination).
pub const DIRECTION_SOURCE: u64 = 0;
pub const DIRECTION_DESTINATION: u64 = 1;

/// ARINC 653 `RETURN_CODE_TYPE` values (reply labels).
pub mod code {
    pub const NO_ERROR: u32 = 0;
    pub const NO_ACTION: u32 = 1;
    pub const NOT_AVAILABLE: u32 = 2;
    pub const INVALID_PARAM: u32 = 3;
    pub const INVALID_CONFIG: u32 = 4;
    pub const INVALID_MODE: u32 = 5;
    pub const TIMED_OUT: u32 = 6;
}

/// ARINC 653 `OPERATING_MODE_TYPE` values.
pub mod mode {
    pub const IDLE: u64 = 0;
    pub const COLD_START: u64 = 1;
    pub const WARM_START: u64 = 2;
    pub const NORMAL: u64 = 3;
}

/// ARINC 653 `ERROR_CODE_TYPE` values (`REPORT_ERROR` w0).
pub mod error {
    pub const DEADLINE_MISSED: u64 = 0;
    pub const APPLICATION_ERROR: u64 = 1;
    pub const NUMERIC_ERROR: u64 = 2;
    pub const ILLEGAL_REQUEST: u64 = 3;
    pub const STACK_OVERFLOW: u64 = 4;
    pub const MEMORY_VIOLATION: u64 = 5;
    pub const HARDWARE_FAULT: u64 = 6;
    pub const POWER_FAIL: u64 = 7;
}

/// A reply: the return code and the three words (data stays in the IPC buffer).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Reply {
    pub code: u32,
    pub words: [u64; 3],
}

/// Sends one request and waits for its reply. `data` goes into the caller's IPC buffer
/// first (at most [`IPC_DATA_MAX`] bytes); reply data is read with
/// [`IpcBufferRef::read_data`]. A kernel error (syssw gone, no IPC buffer) comes back as
/// `Err`.
pub fn request(
    server: ThreadId,
    ipc: IpcBufferRef,
    label: u32,
    words: [u64; 3],
    data: &[u8],
) -> Result<Reply, Error> {
    if data.len() > IPC_DATA_MAX {
        return Err(Error::InvalidArgument);
    }
    ipc.write_data(0, data);
    let m = Message {
        tag: MessageTag::new(label, data.len(), 0),
        words,
    };
    let r = sys::ipc_call(server, TIMEOUT_INFINITE, &m)?;
    Ok(Reply {
        code: r.message.tag.label(),
        words: r.message.words,
    })
}

/// syssw's server thread, once a partition runtime has set it: the panic handler reports
/// a panic there as an APPLICATION_ERROR.
static SERVER: AtomicU64 = AtomicU64::new(0);

pub fn set_server(server: ThreadId) {
    SERVER.store(server.0, Ordering::Relaxed);
}

pub fn server() -> Option<ThreadId> {
    match SERVER.load(Ordering::Relaxed) {
        0 => None,
        t => Some(ThreadId(t)),
    }
}

/// Reports an error to the health monitor with registers only (no IPC buffer needed):
/// w0 = error, no detail text. Used on panic.
pub fn report_error_bare(error: u64) {
    if let Some(server) = server() {
        let _ = sys::ipc_call(
            server,
            TIMEOUT_INFINITE,
            &Message::new(REPORT_ERROR, [error, 0, 0]),
        );
    }
}
