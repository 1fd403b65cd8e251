//! The IPC glue of the service protocol between partitions and syssw. The protocol itself
//! (labels, word packing, codes, typed requests and replies, and its documentation) is the
//! crate `syssw/protocol`; this module only moves an encoded request through the caller's
//! IPC buffer to syssw's server thread and hands back the raw reply.

use crate::ipc_buffer::IpcBufferRef;
use crate::sys::{self, Message};
use abi::ipc::{IPC_DATA_MAX, MessageTag};
use abi::syscall::{Error, TIMEOUT_INFINITE, ThreadId};
use core::sync::atomic::{AtomicU64, Ordering};
use protocol::{ErrorCode, Request, Wire};

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
