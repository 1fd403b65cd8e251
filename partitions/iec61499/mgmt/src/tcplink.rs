//! The TCP connections of CLIENT_m_n/SERVER_m_n with an IP ID (`crate::clientserver`) on
//! the partition's own TCP/IP stack ([`netstack`], the interface of `iec61499.net`), as
//! FORTE's `ip` layer has them: a client connects to its address; a server listens on its
//! port (of every address) and talks to one client at a time: a second client is accepted
//! and closed at once (FORTE's answer), and when its client goes the server listens again.
//! The bytes are a stream: the FBDK encodings of the messages one after the other, with
//! nothing between them (the receiving FB finds where each ends).
//!
//! As [`crate::udp`] for UDP, the FBs never touch the stack: [`TcpLinks`] is the table
//! between them and it. The partition's `ProcessIo` hands `tcp_open`/`tcp_state`/
//! `tcp_send`/`tcp_receive`/`tcp_close` to it, which only check and move bytes between
//! buffers; [`TcpLinks::pump`], in the partition's network pass (between event chains,
//! with the frames in and before the frames out), opens, connects, accepts, closes, and
//! moves the bytes between the buffers and the sockets. A device never waits for the
//! network.
//!
//! Bounds: [`MAX_LINKS`] clients and servers at once (refused at `open` with the reason),
//! [`BUFFER`] bytes waiting each way a link (a send that does not fit: `send buffer full`;
//! what the FB has not taken stays in the socket, whose window then stops the peer).

use crate::pubsub::NetAddr;
use crate::sifb::{TCP_BUFFER, TcpState};
use alloc::collections::VecDeque;
use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;
use netstack::{Error, Ipv4Address, SocketAddr, SocketId, Stack, linux};

/// Clients and servers at once.
pub const MAX_LINKS: usize = 8;
/// Bytes waiting to be sent, and received bytes waiting for the FB, a link.
pub const BUFFER: usize = TCP_BUFFER;
/// The listen backlog of a server: its client and one more, refused at once.
pub const BACKLOG: usize = 2;
/// Sockets of the stack the links use at most: a server's listener (its backlog on eth0
/// and lo), its client and one closing; a client's connection and one closing.
pub const SOCKETS: usize = (2 * BACKLOG + 2) * MAX_LINKS;

/// Counters the partition logs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TcpLinkStats {
    /// Connections made: clients connected, clients a server accepted.
    pub connected: u64,
    /// Clients a busy server accepted and closed at once.
    pub refused: u64,
    /// Connections ended by the peer or by an error.
    pub ended: u64,
    /// Bytes handed to the stack and taken from it.
    pub bytes_out: u64,
    pub bytes_in: u64,
}

struct Link {
    at: NetAddr,
    server: bool,
    state: TcpState,
    /// A server's listening socket.
    listener: Option<SocketId>,
    /// The connection (a client's, being made or made; a server's client).
    connection: Option<SocketId>,
    outbound: VecDeque<u8>,
    inbound: VecDeque<u8>,
}

/// The links of one partition (see the module).
#[derive(Default)]
pub struct TcpLinks {
    links: Vec<Option<Link>>,
    /// Sockets of closed links, closed at the next pump.
    closing: Vec<SocketId>,
    pub stats: TcpLinkStats,
}

impl TcpLinks {
    pub fn new() -> Self {
        Self::default()
    }

    /// `ProcessIo::tcp_open`: a client of `at`, or a server on `at`'s port; its number,
    /// or why not.
    pub fn open(&mut self, at: NetAddr, server: bool) -> Result<usize, String> {
        let free = self.links.iter().position(Option::is_none);
        if free.is_none() && self.links.len() >= MAX_LINKS {
            return Err(format!(
                "too many TCP clients and servers (at most {MAX_LINKS})"
            ));
        }
        if server {
            if self
                .links
                .iter()
                .flatten()
                .any(|l| l.server && l.at.port == at.port)
            {
                return Err(format!(
                    "a server of this device listens on port {} already",
                    at.port
                ));
            }
        } else if at.ip == [0; 4] || at.is_multicast() || at.ip == [255; 4] {
            return Err(format!("{at} is no server address"));
        }
        let link = Link {
            at,
            server,
            state: TcpState::Opening,
            listener: None,
            connection: None,
            outbound: VecDeque::new(),
            inbound: VecDeque::new(),
        };
        Ok(match free {
            Some(i) => {
                self.links[i] = Some(link);
                i
            }
            None => {
                self.links.push(Some(link));
                self.links.len() - 1
            }
        })
    }

    /// `ProcessIo::tcp_state`: what `link` is doing (`Down` for no such link).
    pub fn state(&self, link: usize) -> TcpState {
        match self.links.get(link) {
            Some(Some(l)) => l.state.clone(),
            _ => TcpState::Down("no such TCP link".into()),
        }
    }

    /// `ProcessIo::tcp_send`: queues `bytes` for the next pump, or why not.
    pub fn send(&mut self, link: usize, bytes: &[u8]) -> Result<(), String> {
        let Some(Some(l)) = self.links.get_mut(link) else {
            return Err("no such TCP link".into());
        };
        match &l.state {
            TcpState::Connected { .. } => {}
            TcpState::Listening => return Err("no client connected".into()),
            TcpState::Opening => return Err("not connected yet".into()),
            TcpState::Down(why) => return Err(why.clone()),
        }
        if l.outbound.len() + bytes.len() > BUFFER {
            return Err("send buffer full".into());
        }
        l.outbound.extend(bytes);
        Ok(())
    }

    /// `ProcessIo::tcp_receive`: received bytes of `link` into `buf`, how many.
    pub fn receive(&mut self, link: usize, buf: &mut [u8]) -> usize {
        let Some(Some(l)) = self.links.get_mut(link) else {
            return 0;
        };
        let n = l.inbound.len().min(buf.len());
        for (slot, byte) in buf.iter_mut().zip(l.inbound.drain(..n)) {
            *slot = byte;
        }
        n
    }

    /// `ProcessIo::tcp_close`: the link is gone; its sockets close at the next pump (what
    /// waited to be sent is dropped).
    pub fn close(&mut self, link: usize) {
        if let Some(slot) = self.links.get_mut(link)
            && let Some(l) = slot.take()
        {
            self.closing.extend(l.listener);
            self.closing.extend(l.connection);
        }
    }

    /// Links open now.
    pub fn open_count(&self) -> usize {
        self.links.iter().flatten().count()
    }

    /// Does on `stack` what the links need (see the module). The caller polls the stack
    /// before (frames in) and after (frames out).
    pub fn pump(&mut self, stack: &mut Stack) {
        for socket in self.closing.drain(..) {
            let _ = stack.close(socket);
        }
        for l in self.links.iter_mut().flatten() {
            if matches!(l.state, TcpState::Down(_)) {
                continue;
            }
            if l.server {
                listen_and_accept(l, stack, &mut self.stats);
            } else {
                connect(l, stack, &mut self.stats);
            }
            if l.connection.is_some() && matches!(l.state, TcpState::Connected { .. }) {
                move_bytes(l, stack, &mut self.stats);
            }
        }
    }
}

/// A non-blocking TCP socket.
fn stream(stack: &mut Stack) -> Result<SocketId, Error> {
    stack.socket(linux::AF_INET, linux::SOCK_STREAM | linux::SOCK_NONBLOCK, 0)
}

fn peer_of(stack: &mut Stack, socket: SocketId) -> NetAddr {
    let peer = stack
        .peer_addr(socket)
        .unwrap_or(SocketAddr::new(Ipv4Address::UNSPECIFIED, 0));
    NetAddr {
        ip: peer.ip.octets(),
        port: peer.port,
    }
}

fn listen_and_accept(l: &mut Link, stack: &mut Stack, stats: &mut TcpLinkStats) {
    let listener = match l.listener {
        Some(s) => s,
        None => {
            let opened = stream(stack).and_then(|s| {
                let listening = stack
                    .bind(s, SocketAddr::new(Ipv4Address::UNSPECIFIED, l.at.port))
                    .and_then(|()| stack.listen(s, BACKLOG as i32));
                match listening {
                    Ok(()) => Ok(s),
                    Err(e) => {
                        let _ = stack.close(s);
                        Err(e)
                    }
                }
            });
            match opened {
                Ok(s) => {
                    l.state = TcpState::Listening;
                    *l.listener.insert(s)
                }
                Err(e) => {
                    l.state = TcpState::Down(format!("cannot listen on port {}: {e:?}", l.at.port));
                    return;
                }
            }
        }
    };
    // Bounded: the backlog holds the client and one more, which learns at once that the
    // server is busy (a third at once finds the backlog full: refused by the stack).
    for _ in 0..4 {
        let Ok((socket, _)) = stack.accept(listener) else {
            break;
        };
        if l.connection.is_some() {
            // Busy: the client learns it at once, as FORTE's.
            let _ = stack.close(socket);
            stats.refused += 1;
            continue;
        }
        let _ = stack.set_nonblocking(socket, true);
        l.state = TcpState::Connected {
            peer: peer_of(stack, socket),
        };
        l.connection = Some(socket);
        stats.connected += 1;
    }
}

fn connect(l: &mut Link, stack: &mut Stack, stats: &mut TcpLinkStats) {
    let socket = match l.connection {
        Some(s) => s,
        None => {
            let [a, b, c, d] = l.at.ip;
            let to = SocketAddr::new(Ipv4Address::new(a, b, c, d), l.at.port);
            let started = stream(stack).and_then(|s| match stack.connect(s, to) {
                Ok(()) | Err(Error::InProgress | Error::WouldBlock) => Ok(s),
                Err(e) => {
                    let _ = stack.close(s);
                    Err(e)
                }
            });
            match started {
                Ok(s) => *l.connection.insert(s),
                Err(e) => {
                    l.state = TcpState::Down(format!("cannot connect to {}: {e:?}", l.at));
                    return;
                }
            }
        }
    };
    if l.state == TcpState::Opening {
        match stack.connect_result(socket) {
            Ok(()) => {
                l.state = TcpState::Connected { peer: l.at };
                stats.connected += 1;
            }
            Err(Error::WouldBlock) => {}
            Err(e) => {
                l.state = TcpState::Down(format!("cannot connect to {}: {e:?}", l.at));
                let _ = stack.close(socket);
                l.connection = None;
            }
        }
    }
}

/// Sends what waits (as much as the socket takes) and receives what fits the buffer; an
/// end of the connection ends a client's link and sends a server back to listening.
fn move_bytes(l: &mut Link, stack: &mut Stack, stats: &mut TcpLinkStats) {
    let Some(socket) = l.connection else { return };
    let mut ended = None;
    while !l.outbound.is_empty() {
        let (front, _) = l.outbound.as_slices();
        match stack.send(socket, front, None) {
            Ok(0) | Err(Error::WouldBlock) => break,
            Ok(n) => {
                l.outbound.drain(..n);
                stats.bytes_out += n as u64;
            }
            Err(e) => {
                ended = Some(format!("the connection failed: {e:?}"));
                break;
            }
        }
    }
    let mut buf = [0u8; 512];
    while ended.is_none() && l.inbound.len() < BUFFER {
        let room = (BUFFER - l.inbound.len()).min(buf.len());
        match stack.recv(socket, &mut buf[..room]) {
            Ok((0, _)) => ended = Some("the connection was closed by the peer".into()),
            Ok((n, _)) => {
                l.inbound.extend(&buf[..n]);
                stats.bytes_in += n as u64;
            }
            Err(Error::WouldBlock) => break,
            Err(e) => ended = Some(format!("the connection failed: {e:?}")),
        }
    }
    let Some(why) = ended else { return };
    stats.ended += 1;
    let _ = stack.close(socket);
    l.connection = None;
    l.outbound.clear();
    if l.server {
        // Its bytes are the client's that left: a new client starts afresh.
        l.inbound.clear();
        l.state = TcpState::Listening;
    } else {
        // What arrived before the end stays for the FB; the link is down after it.
        l.state = TcpState::Down(why);
    }
}

#[cfg(test)]
mod tests;
