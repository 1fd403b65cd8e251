//! For host tests of the drivers: a DMA region in plain memory ([`Ram`]) and the device's
//! side of one queue ([`DeviceModel`]): it reads the avail ring and the descriptor chains,
//! and writes the used ring as the specification says, or as told when a test plays a
//! hostile device.

extern crate std;

use crate::Memory;
use crate::queue::{DESC_NEXT, Queue};
use std::vec::Vec;

/// A DMA region in plain memory.
pub struct Ram(pub Vec<u8>);

impl Memory for Ram {
    fn load16(&self, at: usize) -> u16 {
        u16::from_le_bytes([self.0[at], self.0[at + 1]])
    }
    fn load32(&self, at: usize) -> u32 {
        let mut w = [0; 4];
        w.copy_from_slice(&self.0[at..at + 4]);
        u32::from_le_bytes(w)
    }
    fn store16(&mut self, at: usize, value: u16) {
        self.0[at..at + 2].copy_from_slice(&value.to_le_bytes());
    }
    fn store32(&mut self, at: usize, value: u32) {
        self.0[at..at + 4].copy_from_slice(&value.to_le_bytes());
    }
    fn store64(&mut self, at: usize, value: u64) {
        self.0[at..at + 8].copy_from_slice(&value.to_le_bytes());
    }
    fn write(&mut self, at: usize, bytes: &[u8]) {
        self.0[at..at + bytes.len()].copy_from_slice(bytes);
    }
    fn read(&self, at: usize, out: &mut [u8]) {
        out.copy_from_slice(&self.0[at..at + out.len()]);
    }
    fn fence(&self) {}
}

/// One descriptor as the device sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Descriptor {
    pub id: u16,
    pub addr: u64,
    pub len: u32,
    pub flags: u16,
}

/// The device's side of one queue.
pub struct DeviceModel {
    desc: usize,
    avail: usize,
    used: usize,
    size: u16,
    seen: u16,
    used_idx: u16,
}

impl DeviceModel {
    pub fn of(q: &Queue) -> DeviceModel {
        let (desc, avail, used) = q.rings();
        DeviceModel {
            desc,
            avail,
            used,
            size: q.size(),
            seen: 0,
            used_idx: 0,
        }
    }

    /// The next available request's head descriptor.
    pub fn next(&mut self, mem: &Ram) -> Option<Descriptor> {
        if mem.load16(self.avail + 2) == self.seen {
            return None;
        }
        let id = mem.load16(self.avail + 4 + 2 * usize::from(self.seen % self.size));
        self.seen = self.seen.wrapping_add(1);
        Some(self.descriptor(mem, id))
    }

    /// The next available request's descriptors, following the chain (at most the
    /// queue's size of them).
    pub fn next_chain(&mut self, mem: &Ram) -> Option<Vec<Descriptor>> {
        let mut d = self.next(mem)?;
        let mut chain = std::vec![d];
        while d.flags & DESC_NEXT != 0 && chain.len() < usize::from(self.size) {
            let next = mem.load16(self.desc + 16 * usize::from(d.id) + 14);
            d = self.descriptor(mem, next);
            chain.push(d);
        }
        Some(chain)
    }

    fn descriptor(&self, mem: &Ram, id: u16) -> Descriptor {
        let d = self.desc + 16 * usize::from(id);
        Descriptor {
            id,
            addr: u64::from(mem.load32(d)) | u64::from(mem.load32(d + 4)) << 32,
            len: mem.load32(d + 8),
            flags: mem.load16(d + 12),
        }
    }

    /// Whether the driver wants an interrupt for a used buffer (no
    /// [`crate::queue::AVAIL_NO_INTERRUPT`]).
    pub fn wants_interrupts(&self, mem: &Ram) -> bool {
        mem.load16(self.avail) & crate::queue::AVAIL_NO_INTERRUPT == 0
    }

    /// Puts `id` (with `len` bytes written) in the used ring.
    pub fn complete(&mut self, mem: &mut Ram, id: u32, len: u32) {
        let slot = usize::from(self.used_idx % self.size);
        mem.store32(self.used + 4 + 8 * slot, id);
        mem.store32(self.used + 8 + 8 * slot, len);
        self.used_idx = self.used_idx.wrapping_add(1);
        mem.store16(self.used + 2, self.used_idx);
    }
}
