//! The guest's ARINC 653 ports through syssw, the glue of [`guest::arinc`]: creates the
//! ports of the initramfs's port table at start (still in COLD_START, as ARINC wants) and
//! moves their messages with requests that never wait (time-out 0), so a Linux call that
//! must wait is the library's deferred reply, served again on the guest's next tick.
//! Nothing here decides what a Linux call means.

use alloc::vec::Vec;
use guest::arinc::{Direction, Kind, Port, Readiness, Received};
use guest::linux::Errno;
use user_rt::abi::syscall::ThreadId;
use user_rt::ipc_buffer::IpcBufferRef;
use user_rt::println;
use user_rt::protocol::{
    self, PortIdReply, PortKind, QueuingMessage, QueuingStatus, ReplyWords, Request, ReturnCode,
    SamplingMessage, Validity,
};

/// A created port: syssw's id, its kind and direction.
#[derive(Clone, Copy)]
struct Created {
    id: u64,
    kind: Kind,
    direction: Direction,
}

pub struct Ports {
    server: ThreadId,
    ipc: IpcBufferRef,
    /// By the table's index; `None` where syssw refused the port.
    created: Vec<Option<Created>>,
}

impl Ports {
    /// Creates every port of `table`; a refusal is logged as
    /// `guest: port <name>: cannot create it: <code>` and its device answers `ENXIO`.
    pub fn create(server: ThreadId, ipc: IpcBufferRef, table: &[Port]) -> Self {
        let mut ports = Ports {
            server,
            ipc,
            created: Vec::new(),
        };
        for port in table {
            let request = Request::CreatePort {
                kind: match port.kind {
                    Kind::Sampling => PortKind::Sampling,
                    Kind::Queuing => PortKind::Queuing,
                },
                direction: match port.direction {
                    Direction::In => protocol::Direction::In,
                    Direction::Out => protocol::Direction::Out,
                },
                // Its calls never wait (the configuration keeps its ports FIFO).
                discipline: protocol::Discipline::Fifo,
                max_message_size: u64::from(port.size),
                refresh_or_depth: port.refresh_or_depth,
                name: port.name.as_bytes(),
            };
            let created = match ports.call(&request) {
                Ok((Ok(()) | Err(ReturnCode::NoAction), words)) => {
                    PortIdReply::from_words(words).ok().map(|r| Created {
                        id: r.port,
                        kind: port.kind,
                        direction: port.direction,
                    })
                }
                Ok((Err(code), _)) => {
                    println!(
                        "guest: port {}: cannot create it: {}",
                        port.name,
                        code.name()
                    );
                    None
                }
                Err(()) => {
                    println!("guest: port {}: cannot create it: no answer", port.name);
                    None
                }
            };
            ports.created.push(created);
        }
        ports
    }

    /// One request: its return code and reply words (`Err` when syssw did not answer).
    fn call(&self, request: &Request) -> Result<(Result<(), ReturnCode>, [u64; 3]), ()> {
        let reply = user_rt::service::request(self.server, self.ipc, request).map_err(|_| ())?;
        let code = protocol::reply_result(reply.label).map_err(|_| ())?;
        Ok((code, reply.words))
    }

    fn port(&self, index: usize) -> Result<Created, Errno> {
        self.created
            .get(index)
            .copied()
            .flatten()
            .ok_or(Errno::ENXIO)
    }

    pub fn send(&mut self, index: usize, message: &[u8]) -> Result<(), Errno> {
        let p = self.port(index)?;
        let request = match p.kind {
            // Its messages fit one request (the configuration keeps them at 4096 bytes).
            Kind::Sampling => Request::WriteSampling {
                port: p.id,
                staged: 0,
                message,
            },
            Kind::Queuing => Request::SendQueuing {
                port: p.id,
                timeout: 0,
                priority: 0,
                staged: 0,
                message,
            },
        };
        match self.call(&request).map_err(|()| Errno::EIO)?.0 {
            Ok(()) => Ok(()),
            Err(ReturnCode::NotAvailable | ReturnCode::TimedOut) => Err(Errno::EAGAIN),
            Err(_) => Err(Errno::EIO),
        }
    }

    pub fn receive(&mut self, index: usize, buf: &mut [u8]) -> Result<Received, Errno> {
        let p = self.port(index)?;
        let (code, len, valid) = match p.kind {
            Kind::Sampling => {
                let (code, words) = self
                    .call(&Request::ReadSampling { port: p.id })
                    .map_err(|()| Errno::EIO)?;
                let m = SamplingMessage::from_words(words).map_err(|_| Errno::EIO)?;
                (code, m.len, m.validity == Validity::Valid)
            }
            Kind::Queuing => {
                let request = Request::ReceiveQueuing {
                    port: p.id,
                    timeout: 0,
                    priority: 0,
                };
                let (code, words) = self.call(&request).map_err(|()| Errno::EIO)?;
                let m = QueuingMessage::from_words(words).map_err(|_| Errno::EIO)?;
                (code, m.len, true)
            }
        };
        let len = len as usize;
        match code {
            // A message (with INVALID_CONFIG: a queue that overflowed before it).
            _ if len > 0 && len <= buf.len() => {
                self.ipc.read_data(0, &mut buf[..len]);
                Ok(Received { len, valid })
            }
            Ok(()) if len > buf.len() => Err(Errno::EMSGSIZE),
            Ok(())
            | Err(ReturnCode::NoAction | ReturnCode::NotAvailable | ReturnCode::TimedOut) => {
                Err(Errno::EAGAIN)
            }
            Err(_) => Err(Errno::EIO),
        }
    }

    pub fn readiness(&mut self, index: usize) -> Readiness {
        let mut now = Readiness {
            readable: false,
            writable: false,
            valid: false,
        };
        let Ok(p) = self.port(index) else {
            return now;
        };
        match (p.kind, p.direction) {
            (Kind::Sampling, Direction::Out) => now.writable = true,
            (Kind::Sampling, Direction::In) => {
                // Reading a sampling port takes nothing away.
                if let Ok((Ok(()), words)) = self.call(&Request::ReadSampling { port: p.id })
                    && let Ok(m) = SamplingMessage::from_words(words)
                {
                    now.readable = m.len > 0;
                    now.valid = m.len > 0 && m.validity == Validity::Valid;
                }
            }
            (Kind::Queuing, direction) => {
                if let Ok((Ok(()), words)) = self.call(&Request::QueuingStatus { port: p.id })
                    && let Ok(s) = QueuingStatus::from_words(words)
                {
                    match direction {
                        Direction::In => now.readable = s.nb_message > 0,
                        Direction::Out => now.writable = s.nb_message < s.max_nb_message,
                    }
                }
            }
        }
        now
    }
}

impl Ports {
    /// `/dev/vda`'s link over ports `request` (a queuing source) and `response` (a queuing
    /// destination) of the table (`None` when syssw refused either).
    /// syssw's ids of the created queuing destination ports, but for the port table's
    /// index `skip`.
    pub fn queuing_destinations(&self, skip: Option<usize>) -> Vec<u64> {
        self.created
            .iter()
            .enumerate()
            .filter(|&(i, _)| Some(i) != skip)
            .filter_map(|(_, c)| *c)
            .filter(|c| c.kind == Kind::Queuing && c.direction == Direction::In)
            .map(|c| c.id)
            .collect()
    }

    pub fn disk_link(&self, request: usize, response: usize) -> Option<DiskLink> {
        let (req, resp) = (self.port(request).ok()?, self.port(response).ok()?);
        let queuing = req.kind == Kind::Queuing && resp.kind == Kind::Queuing;
        let ways = req.direction == Direction::Out && resp.direction == Direction::In;
        (queuing && ways).then_some(DiskLink {
            server: self.server,
            ipc: self.ipc,
            request: req.id,
            response: resp.id,
        })
    }
}

/// How long a request may wait for room in its port (ns).
const DISK_SEND_TIMEOUT_NS: u64 = 1_000_000_000;
/// How long the guest waits for a response (ns): the block-device partition answers in
/// its next window; meanwhile the guest serves no other call.
const DISK_RESPONSE_TIMEOUT_NS: u64 = 2_000_000_000;
/// Most stale responses dropped before a request (more than a port holds).
const DISK_STALE_MAX: usize = 16;

/// The transport of `/dev/vda`'s client (`blk_core::client`): one request and its
/// response through syssw, waiting for each within a bound.
pub struct DiskLink {
    server: ThreadId,
    ipc: IpcBufferRef,
    request: u64,
    response: u64,
}

impl DiskLink {
    fn call(&self, request: &Request) -> Result<(Result<(), ReturnCode>, [u64; 3]), ()> {
        let reply = user_rt::service::request(self.server, self.ipc, request).map_err(|_| ())?;
        let code = protocol::reply_result(reply.label).map_err(|_| ())?;
        Ok((code, reply.words))
    }

    /// One message of the response port into `buf` within `timeout` ns: its length, or
    /// `None` when none came.
    fn receive(&self, timeout: u64, buf: &mut [u8]) -> Result<Option<usize>, &'static str> {
        let request = Request::ReceiveQueuing {
            port: self.response,
            timeout,
            priority: 0,
        };
        let (code, words) = self.call(&request).map_err(|()| "syssw did not answer")?;
        let len = QueuingMessage::from_words(words)
            .map_err(|_| "syssw's answer is malformed")?
            .len as usize;
        match code {
            // A message (with INVALID_CONFIG: a queue that overflowed before it).
            _ if len > 0 && len <= buf.len() => {
                self.ipc.read_data(0, &mut buf[..len]);
                Ok(Some(len))
            }
            Ok(()) if len > buf.len() => Err("a response longer than the link's"),
            Ok(())
            | Err(ReturnCode::NoAction | ReturnCode::NotAvailable | ReturnCode::TimedOut) => {
                Ok(None)
            }
            Err(_) => Err("the response port refused the receive"),
        }
    }
}

impl blk_core::client::Transport for DiskLink {
    type Error = &'static str;

    fn exchange(&mut self, request: &[u8], response: &mut [u8]) -> Result<usize, &'static str> {
        // Responses to requests given up on (a time-out) are stale: dropped first.
        for _ in 0..DISK_STALE_MAX {
            if self.receive(0, response)?.is_none() {
                break;
            }
        }
        let send = Request::SendQueuing {
            port: self.request,
            timeout: DISK_SEND_TIMEOUT_NS,
            priority: 0,
            staged: 0,
            message: request,
        };
        match self.call(&send).map_err(|()| "syssw did not answer")?.0 {
            Ok(()) => {}
            Err(ReturnCode::NotAvailable | ReturnCode::TimedOut) => {
                return Err("the request port stayed full for 1 s");
            }
            Err(_) => return Err("the request port refused the send"),
        }
        self.receive(DISK_RESPONSE_TIMEOUT_NS, response)?
            .ok_or("no response within 2 s")
    }
}
