//! Access to a thread's IPC buffer ([`abi::ipc::IpcBuffer`]) by address.
//!
//! The kernel reads and writes the buffer during IPC calls, so no Rust reference to it may
//! live across a system call. [`IpcBufferRef`] therefore holds only the address and copies
//! fields in and out with volatile accesses, one call at a time, between system calls.
// Raw accesses to memory the kernel also writes: the one reason for `unsafe` here.
#![allow(unsafe_code)]

use abi::ipc::{
    EXCEPTION_MESSAGE_SIZE, ExceptionMessage, IPC_DATA_MAX, IPC_ITEMS_OFFSET, IPC_MAX_ITEMS,
    IPC_WINDOW_OFFSET, MapItem, ReceiveWindow,
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
        for (i, byte) in out.iter_mut().enumerate() {
            // SAFETY: offset + i < IPC_DATA_MAX, inside the mapped buffer (`new`).
            *byte = unsafe { core::ptr::read_volatile(self.at(offset + i)) };
        }
    }

    /// Copies `bytes` into the data area at `offset`. Panics if they do not fit.
    pub fn write_data(self, offset: usize, bytes: &[u8]) {
        assert!(
            offset + bytes.len() <= IPC_DATA_MAX,
            "outside the IPC data area"
        );
        for (i, byte) in bytes.iter().enumerate() {
            // SAFETY: offset + i < IPC_DATA_MAX, inside the mapped, writable buffer (`new`).
            unsafe { core::ptr::write_volatile(self.at(offset + i), *byte) };
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
        let mut bytes = [0u8; EXCEPTION_MESSAGE_SIZE];
        self.read_data(0, &mut bytes);
        ExceptionMessage::from_bytes(&bytes).expect("EXCEPTION_MESSAGE_SIZE bytes")
    }

    /// Writes `message` to the start of the data area (for a `REPLY_RESUME` with edited
    /// registers, tag length `EXCEPTION_MESSAGE_SIZE`).
    pub fn set_exception(self, message: &ExceptionMessage) {
        self.write_data(0, &message.to_bytes());
    }
}

// The item layout `set_item` writes: source, then pages (low half) and flags (high half).
const _: () = assert!(core::mem::size_of::<MapItem>() == 16);
const _: () = assert!(core::mem::offset_of!(MapItem, pages) == 8);
const _: () = assert!(core::mem::offset_of!(MapItem, flags) == 12);
