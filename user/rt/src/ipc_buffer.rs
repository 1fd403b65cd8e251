//! Access to a thread's IPC buffer ([`abi::ipc::IpcBuffer`]) by address.
//!
//! The kernel reads and writes the buffer during IPC calls, so no Rust reference to it may
//! live across a system call. [`IpcBufferRef`] therefore holds only the address and copies
//! fields in and out with volatile accesses, one call at a time, between system calls.
// Raw accesses to memory the kernel also writes: the one reason for `unsafe` here.
#![allow(unsafe_code)]

use abi::ipc::{
    ExceptionMessage, IPC_DATA_MAX, IPC_ITEMS_OFFSET, IPC_MAX_ITEMS, IPC_WINDOW_OFFSET, MapItem,
    ReceiveWindow,
};

/// The IPC buffer of the calling thread (or of another thread of the same task), by address.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IpcBufferRef {
    base: usize,
}

impl IpcBufferRef {
    /// # Safety
    /// `address` must be the start of `abi::ipc::IPC_BUFFER_SIZE` bytes (8-byte aligned)
    /// mapped readable and writable in the calling task for as long as this value or a
    /// copy of it is used, and that memory must not be accessed through Rust references.
    pub const unsafe fn new(address: u64) -> Self {
        Self {
            base: address as usize,
        }
    }

    /// The user address, as registered with `thread_set(IpcBuffer)`.
    pub fn address(self) -> u64 {
        self.base as u64
    }

    fn at(self, offset: usize) -> *mut u8 {
        (self.base + offset) as *mut u8
    }

    fn read_u64(self, offset: usize) -> u64 {
        debug_assert!(offset.is_multiple_of(8));
        // SAFETY: `new`'s contract: the whole buffer is mapped readable; offset is within it
        // (callers below only pass field offsets) and 8-aligned as the base is.
        unsafe { core::ptr::read_volatile(self.at(offset) as *const u64) }
    }

    fn write_u64(self, offset: usize, value: u64) {
        debug_assert!(offset.is_multiple_of(8));
        // SAFETY: as in `read_u64`, and the buffer is mapped writable.
        unsafe { core::ptr::write_volatile(self.at(offset) as *mut u64, value) }
    }

    /// Copies `out.len()` data bytes starting at `offset` out of the buffer.
    /// Panics if the range leaves the data area.
    pub fn read_data(self, offset: usize, out: &mut [u8]) {
        assert!(
            offset + out.len() <= IPC_DATA_MAX,
            "outside the IPC data area"
        );
        // Whole words from the first 8-aligned offset on (a message starts at 0): a
        // byte-wise volatile copy took ~1,500 instructions for an exception message.
        let (head, words, tail) = split_at_words(offset, out.len());
        for i in (0..head).chain(head + words * 8..head + words * 8 + tail) {
            // SAFETY: offset + i < IPC_DATA_MAX, inside the mapped buffer (`new`).
            out[i] = unsafe { core::ptr::read_volatile(self.at(offset + i)) };
        }
        for w in 0..words {
            let at = head + w * 8;
            out[at..at + 8].copy_from_slice(&self.read_u64(offset + at).to_ne_bytes());
        }
    }

    /// Copies `bytes` into the data area at `offset`. Panics if they do not fit.
    pub fn write_data(self, offset: usize, bytes: &[u8]) {
        assert!(
            offset + bytes.len() <= IPC_DATA_MAX,
            "outside the IPC data area"
        );
        let (head, words, tail) = split_at_words(offset, bytes.len());
        for i in (0..head).chain(head + words * 8..head + words * 8 + tail) {
            // SAFETY: offset + i < IPC_DATA_MAX, inside the mapped, writable buffer (`new`).
            unsafe { core::ptr::write_volatile(self.at(offset + i), bytes[i]) };
        }
        for w in 0..words {
            let at = head + w * 8;
            let word = u64::from_ne_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
            self.write_u64(offset + at, word);
        }
    }

    /// Word `index` (8 bytes, native endian) of the data area.
    pub fn data_word(self, index: usize) -> u64 {
        assert!(index < IPC_DATA_MAX / 8);
        self.read_u64(index * 8)
    }

    pub fn set_data_word(self, index: usize, value: u64) {
        assert!(index < IPC_DATA_MAX / 8);
        self.write_u64(index * 8, value);
    }

    /// Map item `index` the next send will use (if the tag counts it).
    pub fn set_item(self, index: usize, item: MapItem) {
        assert!(index < IPC_MAX_ITEMS);
        let offset = IPC_ITEMS_OFFSET + index * core::mem::size_of::<MapItem>();
        self.write_u64(offset, item.source);
        self.write_u64(offset + 8, item.pages as u64 | (item.flags as u64) << 32);
    }

    pub fn item(self, index: usize) -> MapItem {
        assert!(index < IPC_MAX_ITEMS);
        let offset = IPC_ITEMS_OFFSET + index * core::mem::size_of::<MapItem>();
        let packed = self.read_u64(offset + 8);
        MapItem {
            source: self.read_u64(offset),
            pages: packed as u32,
            flags: (packed >> 32) as u32,
        }
    }

    /// Where received map items go.
    pub fn set_window(self, window: ReceiveWindow) {
        self.write_u64(IPC_WINDOW_OFFSET, window.base);
        self.write_u64(IPC_WINDOW_OFFSET + 8, window.pages);
    }

    pub fn window(self) -> ReceiveWindow {
        ReceiveWindow {
            base: self.read_u64(IPC_WINDOW_OFFSET),
            pages: self.read_u64(IPC_WINDOW_OFFSET + 8),
        }
    }

    /// The [`ExceptionMessage`] at the start of the data area (of a received exception,
    /// syscall or fault-report message).
    pub fn exception(self) -> ExceptionMessage {
        ExceptionMessage::from_words(&core::array::from_fn(|i| self.read_u64(i * 8)))
    }

    /// Writes `message` to the start of the data area (for a `REPLY_RESUME` with edited
    /// registers, tag length `EXCEPTION_MESSAGE_SIZE`).
    pub fn set_exception(self, message: &ExceptionMessage) {
        for (i, word) in message.words().into_iter().enumerate() {
            self.write_u64(i * 8, word);
        }
    }
}

/// A copy of `len` bytes at buffer offset `offset` as `(head, words, tail)`: `head` bytes up
/// to the first 8-aligned offset, then `words` whole words, then `tail` bytes.
fn split_at_words(offset: usize, len: usize) -> (usize, usize, usize) {
    let head = ((8 - offset % 8) % 8).min(len);
    let rest = len - head;
    (head, rest / 8, rest % 8)
}

// The item layout `set_item` writes: source, then pages (low half) and flags (high half).
const _: () = assert!(core::mem::size_of::<MapItem>() == 16);
const _: () = assert!(core::mem::offset_of!(MapItem, pages) == 8);
const _: () = assert!(core::mem::offset_of!(MapItem, flags) == 12);

#[cfg(test)]
mod tests {
    use super::*;
    use abi::ipc::IPC_BUFFER_SIZE;

    #[test]
    fn copies_split_into_bytes_and_words() {
        assert_eq!(split_at_words(0, 200), (0, 25, 0));
        assert_eq!(split_at_words(0, 13), (0, 1, 5));
        assert_eq!(split_at_words(3, 2), (2, 0, 0));
        assert_eq!(split_at_words(3, 20), (5, 1, 7));
        assert_eq!(split_at_words(8, 7), (0, 0, 7));
        assert_eq!(split_at_words(4095, 1), (1, 0, 0));
    }

    /// Every offset and length round-trips, and a write touches exactly its bytes.
    #[test]
    fn data_round_trips_at_any_offset_and_length() {
        let mut memory = [0u64; IPC_BUFFER_SIZE / 8];
        // SAFETY: `memory` is IPC_BUFFER_SIZE bytes, 8-aligned, outlives `ipc` and is not
        // touched through a reference while `ipc` is used.
        let ipc = unsafe { IpcBufferRef::new(memory.as_mut_ptr() as u64) };
        for offset in 0..24 {
            for len in 0..40 {
                ipc.write_data(0, &[0xEE; 64]);
                let mut bytes = [0u8; 40];
                for (i, b) in bytes.iter_mut().enumerate() {
                    *b = i as u8 + 1;
                }
                let bytes = &bytes[..len];
                ipc.write_data(offset, bytes);
                let mut back = [0u8; 40];
                ipc.read_data(offset, &mut back[..len]);
                assert_eq!(&back[..len], bytes, "offset {offset} len {len}");
                let mut around = [0u8; 64];
                ipc.read_data(0, &mut around);
                assert!(around[..offset].iter().all(|&b| b == 0xEE));
                assert!(around[offset + len..].iter().all(|&b| b == 0xEE));
            }
        }
        let m = ExceptionMessage {
            vector: 14,
            fault_address: 0xdead_beef,
            ..Default::default()
        };
        ipc.set_exception(&m);
        assert_eq!(ipc.exception(), m);
    }
}
