//! A tenant's side of the link: its virtual disk as a `slots::BlockDevice` (the PLC's
//! persistent store writes its records through it), one request and its response at a
//! time over a [`Transport`] (a pair of queuing ports in a partition); a run of sectors
//! goes [`MAX_SECTORS`] to a request. Every response is
//! checked (CRC, tag, status) before its data is used.

use crate::SECTOR;
use crate::link::{self, LinkError, MAX_REQUEST, MAX_RESPONSE, MAX_SECTORS, Operation, Status};

/// Carries one request to the driver and its response back.
pub trait Transport {
    type Error: core::fmt::Debug;
    /// Sends `request`, receives the response into `response`; its length.
    fn exchange(&mut self, request: &[u8], response: &mut [u8]) -> Result<usize, Self::Error>;
}

/// Why a request failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClientError<E> {
    Transport(E),
    /// The response is damaged or malformed.
    Response(LinkError),
    /// The response answers another request.
    Tag {
        sent: u32,
        got: u32,
    },
    /// The driver or the device refused or failed the request.
    Status(Status),
    /// A read answered with another amount of data.
    Data {
        expected: usize,
        got: usize,
    },
}

impl<E: core::fmt::Debug> core::fmt::Display for ClientError<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Transport(e) => write!(f, "transport: {e:?}"),
            Self::Response(e) => write!(f, "bad response: {e}"),
            Self::Tag { sent, got } => write!(f, "response to request {got}, sent {sent}"),
            Self::Status(s) => write!(f, "the driver answered {s:?}"),
            Self::Data { expected, got } => write!(f, "{got} bytes read, asked {expected}"),
        }
    }
}

/// A tenant's virtual disk over the link.
pub struct Client<T> {
    transport: T,
    tag: u32,
    request: [u8; MAX_REQUEST],
    response: [u8; MAX_RESPONSE],
}

impl<T: Transport> Client<T> {
    pub fn new(transport: T) -> Client<T> {
        Client {
            transport,
            tag: 0,
            request: [0; MAX_REQUEST],
            response: [0; MAX_RESPONSE],
        }
    }

    /// The transport (to send what the client would not, in tests).
    pub fn transport_mut(&mut self) -> &mut T {
        &mut self.transport
    }

    /// One request; the response's data (a read's) is copied into `out`.
    fn exchange(
        &mut self,
        operation: Operation,
        sector: u64,
        sectors: u32,
        data: &[u8],
        out: &mut [u8],
    ) -> Result<(), ClientError<T::Error>> {
        self.tag = self.tag.wrapping_add(1);
        let n = link::encode_request(
            operation,
            self.tag,
            sector,
            sectors,
            data,
            &mut self.request,
        )
        .map_err(ClientError::Response)?;
        let got = self
            .transport
            .exchange(&self.request[..n], &mut self.response)
            .map_err(ClientError::Transport)?;
        let response = self
            .response
            .get(..got)
            .ok_or(ClientError::Response(LinkError::Buffer))?;
        let r = link::decode_response(response).map_err(ClientError::Response)?;
        if r.tag != self.tag {
            return Err(ClientError::Tag {
                sent: self.tag,
                got: r.tag,
            });
        }
        if r.status != Status::Ok {
            return Err(ClientError::Status(r.status));
        }
        if r.data.len() != out.len() {
            return Err(ClientError::Data {
                expected: out.len(),
                got: r.data.len(),
            });
        }
        out.copy_from_slice(r.data);
        Ok(())
    }
}

impl<T: Transport> slots::BlockDevice for Client<T> {
    type Error = ClientError<T::Error>;

    fn read(&mut self, sector: u64, buf: &mut [u8; SECTOR]) -> Result<(), Self::Error> {
        self.exchange(Operation::Read, sector, 1, &[], buf)
    }

    fn write(&mut self, sector: u64, data: &[u8; SECTOR]) -> Result<(), Self::Error> {
        self.exchange(Operation::Write, sector, 1, data, &mut [])
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        self.exchange(Operation::Flush, 0, 0, &[], &mut [])
    }

    /// [`MAX_SECTORS`] sectors a request.
    fn read_sectors(&mut self, first: u64, buf: &mut [u8]) -> Result<(), Self::Error> {
        let whole = buf.len() / SECTOR * SECTOR;
        for (i, chunk) in buf[..whole].chunks_mut(REQUEST_BYTES).enumerate() {
            let sector = first + (i * MAX_SECTORS as usize) as u64;
            let sectors = (chunk.len() / SECTOR) as u32;
            self.exchange(Operation::Read, sector, sectors, &[], chunk)?;
        }
        Ok(())
    }

    /// [`MAX_SECTORS`] sectors a request, in order.
    fn write_sectors(&mut self, first: u64, data: &[u8]) -> Result<(), Self::Error> {
        let whole = data.len() / SECTOR * SECTOR;
        for (i, chunk) in data[..whole].chunks(REQUEST_BYTES).enumerate() {
            let sector = first + (i * MAX_SECTORS as usize) as u64;
            let sectors = (chunk.len() / SECTOR) as u32;
            self.exchange(Operation::Write, sector, sectors, chunk, &mut [])?;
        }
        Ok(())
    }
}

/// Bytes one read or write request moves at most.
const REQUEST_BYTES: usize = MAX_SECTORS as usize * SECTOR;

#[cfg(test)]
mod tests;
