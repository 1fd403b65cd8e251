//! The frames between the stack and the partition's rings: a bounded queue each way that
//! smoltcp reads and writes as its device.

use alloc::collections::VecDeque;
use alloc::vec;
use alloc::vec::Vec;
use smoltcp::phy::{self, DeviceCapabilities, Medium};
use smoltcp::time::Instant;

/// Largest Ethernet frame without FCS.
pub const MTU: usize = 1514;

/// Frames received from the wire (`rx`) and frames to send (`tx`), each bounded: a frame
/// that arrives when `rx` is full is dropped and counted, as a NIC drops on a full ring.
#[derive(Debug, Default)]
pub struct Queues {
    rx: VecDeque<Vec<u8>>,
    tx: VecDeque<Vec<u8>>,
    capacity: usize,
    /// Frames dropped: `rx` was full, or the frame was longer than [`MTU`].
    pub dropped: u64,
    /// What went each way (`/proc/net/dev`).
    pub counters: Counters,
}

/// Frames and bytes an interface received and sent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    pub rx_frames: u64,
    pub rx_bytes: u64,
    pub tx_frames: u64,
    pub tx_bytes: u64,
}

impl Queues {
    /// Queues of `capacity` frames each way.
    pub fn new(capacity: usize) -> Self {
        Queues {
            capacity: capacity.max(1),
            ..Default::default()
        }
    }

    /// A frame from the wire.
    pub fn deliver(&mut self, frame: &[u8]) {
        if self.rx.len() >= self.capacity || frame.len() > MTU {
            self.dropped += 1;
            return;
        }
        self.counters.rx_frames += 1;
        self.counters.rx_bytes += frame.len() as u64;
        self.rx.push_back(frame.to_vec());
    }

    /// The next frame to put on the wire.
    pub fn take(&mut self) -> Option<Vec<u8>> {
        let frame = self.tx.pop_front()?;
        self.counters.tx_frames += 1;
        self.counters.tx_bytes += frame.len() as u64;
        Some(frame)
    }
}

pub struct RxToken(Vec<u8>);
pub struct TxToken<'a>(&'a mut Queues);

impl phy::RxToken for RxToken {
    fn consume<R, F: FnOnce(&[u8]) -> R>(self, f: F) -> R {
        f(&self.0)
    }
}

impl phy::TxToken for TxToken<'_> {
    fn consume<R, F: FnOnce(&mut [u8]) -> R>(self, len: usize, f: F) -> R {
        let mut frame = vec![0; len];
        let result = f(&mut frame);
        if self.0.tx.len() < self.0.capacity {
            self.0.tx.push_back(frame);
        } else {
            self.0.dropped += 1;
        }
        result
    }
}

impl phy::Device for Queues {
    type RxToken<'a> = RxToken;
    type TxToken<'a> = TxToken<'a>;

    fn receive(&mut self, _: Instant) -> Option<(RxToken, TxToken<'_>)> {
        let frame = self.rx.pop_front()?;
        Some((RxToken(frame), TxToken(self)))
    }

    fn transmit(&mut self, _: Instant) -> Option<TxToken<'_>> {
        (self.tx.len() < self.capacity).then_some(TxToken(self))
    }

    fn capabilities(&self) -> DeviceCapabilities {
        let mut caps = DeviceCapabilities::default();
        caps.medium = Medium::Ethernet;
        caps.max_transmission_unit = MTU;
        caps
    }
}
