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
