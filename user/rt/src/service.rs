//! The IPC glue of the service protocol between partitions and syssw. The protocol itself
//! (labels, word packing, codes, typed requests and replies, and its documentation) is the
//! crate `syssw/protocol`; this module only moves an encoded request through the caller's
//! IPC buffer to syssw's server thread and hands back the raw reply.

use crate::ipc_buffer::IpcBufferRef;
use crate::sys::{self, Message};
use abi::ipc::{IPC_DATA_MAX, MessageTag};
use abi::syscall::{Error, TIMEOUT_INFINITE, ThreadId};
use core::sync::atomic::{AtomicU64, Ordering};
use protocol::{ErrorCode, FetchReply, PART_MAX, ReplyWords, Request, ReturnCode, Wire};

/// A reply as it arrived: the label (an ARINC return code, see
/// [`protocol::reply_result`]) and the three words (decoded with the request's
/// [`protocol::ReplyWords`] type); reply data stays in the IPC buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Reply {
    pub label: u32,
    pub words: [u64; 3],
}

/// Sends one request and waits for its reply. The request's data goes into the caller's IPC
/// buffer first (at most [`IPC_DATA_MAX`] bytes); reply data is read with
/// [`IpcBufferRef::read_data`]. A kernel error (syssw gone, no IPC buffer) comes back as
/// `Err`.
pub fn request(server: ThreadId, ipc: IpcBufferRef, request: &Request) -> Result<Reply, Error> {
    let wire = request.encode();
    if wire.data.len() > IPC_DATA_MAX {
        return Err(Error::InvalidArgument);
    }
    ipc.write_data(0, wire.data);
    let r = sys::ipc_call(server, TIMEOUT_INFINITE, &message(&wire))?;
    Ok(Reply {
        label: r.message.tag.label(),
        words: r.message.words,
    })
}

/// [`request`] for a thread without an IPC buffer: a request without data bytes (its
/// reply's data, if any, is lost). A request with data is `InvalidArgument`.
pub fn request_without_buffer(server: ThreadId, request: &Request) -> Result<Reply, Error> {
    let wire = request.encode();
    if !wire.data.is_empty() {
        return Err(Error::InvalidArgument);
    }
    let r = sys::ipc_call(server, TIMEOUT_INFINITE, &message(&wire))?;
    Ok(Reply {
        label: r.message.tag.label(),
        words: r.message.words,
    })
}

/// Sends a port request that carries a message of any length (the protocol's "long
/// messages"): every part but the last is staged first (STAGE_MESSAGE), then the request
/// `build(staged, last part)` makes is sent. A refused part ends the transfer with its reply.
pub fn request_with_message<'m>(
    server: ThreadId,
    ipc: IpcBufferRef,
    message: &'m [u8],
    build: impl FnOnce(u64, &'m [u8]) -> Request<'m>,
) -> Result<Reply, Error> {
    let last = message.len().saturating_sub(1) / PART_MAX * PART_MAX;
    for offset in (0..last).step_by(PART_MAX) {
        let part = &message[offset..offset + PART_MAX];
        let stage = Request::StageMessage {
            offset: offset as u64,
            part,
        };
        let reply = request(server, ipc, &stage)?;
        if reply.label != ReturnCode::NoError.code() {
            return Ok(reply);
        }
    }
    request(server, ipc, &build(last as u64, &message[last..]))
}

/// Why [`receive_message`] has no message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReceiveError {
    /// Longer than the caller's buffer (the rest was dropped in syssw).
    TooLong,
    /// syssw refused a fetch, or its answer does not fit the message: the service failed.
    Failed,
}

/// The message of `len` bytes a READ_SAMPLING or RECEIVE_QUEUING reply announced, into
/// `out`: its first part from the IPC buffer, the rest fetched (FETCH_MESSAGE).
pub fn receive_message(
    server: ThreadId,
    ipc: IpcBufferRef,
    len: usize,
    out: &mut [u8],
) -> Result<(), ReceiveError> {
    if len > out.len() {
        drop_message(server, ipc, len);
        return Err(ReceiveError::TooLong);
    }
    let first = len.min(PART_MAX);
    ipc.read_data(0, &mut out[..first]);
    for offset in (PART_MAX..len).step_by(PART_MAX) {
        let n = (len - offset).min(PART_MAX);
        let fetch = Request::FetchMessage {
            offset: offset as u64,
        };
        let reply = request(server, ipc, &fetch).map_err(|_| ReceiveError::Failed)?;
        let left = FetchReply::from_words(reply.words).map_err(|_| ReceiveError::Failed)?;
        if reply.label != ReturnCode::NoError.code() || left.left != (len - offset - n) as u64 {
            return Err(ReceiveError::Failed);
        }
        ipc.read_data(0, &mut out[offset..offset + n]);
    }
    Ok(())
}

/// Drops the rest of an announced message of `len` bytes that the caller does not read
/// (syssw holds it until fetched).
pub fn drop_message(server: ThreadId, ipc: IpcBufferRef, len: usize) {
    if len > PART_MAX {
        let _ = request(server, ipc, &Request::FetchMessage { offset: len as u64 });
    }
}

/// The IPC message of a request (its data already in the IPC buffer).
fn message(wire: &Wire) -> Message {
    Message {
        tag: MessageTag::new(wire.label, wire.data.len(), 0),
        words: wire.words,
    }
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

/// Reports an error to the health monitor with registers only (no IPC buffer needed: no
/// detail text). Used on panic.
pub fn report_error_bare(error: ErrorCode) {
    if let Some(server) = server() {
        let wire = Request::ReportError { error, detail: &[] }.encode();
        let _ = sys::ipc_call(server, TIMEOUT_INFINITE, &message(&wire));
    }
}
