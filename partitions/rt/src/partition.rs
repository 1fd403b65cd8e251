//! How the system software starts a partition's first thread (an interface between syssw
//! and every partition program):
//!
//! The thread starts at the image's ELF entry with `rdi` = the address of a [`StartInfo`]
//! record at the top of its stack (read-only by convention) and `rsp` 16-byte aligned
//! below it, minus 8 (as if called). Everything else the partition needs from syssw comes
//! through this record.

/// `StartInfo::magic`.
pub const START_MAGIC: u64 = u64::from_le_bytes(*b"WRDNPART");

#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct StartInfo {
    pub magic: u64,
    /// Index of the partition in the configuration.
    pub index: u64,
    /// Its time partition (0 = background).
    pub time_partition: u64,
    /// Raw thread id of syssw's server thread (requests go there by IPC).
    pub server: u64,
    /// How it was started: 0 = normal start, 1 = cold restart, 2 = warm restart.
    pub start_condition: u64,
    /// Length of `name` in bytes (the partition's name, UTF-8).
    pub name_len: u64,
    pub name: [u8; 32],
}

impl StartInfo {
    /// The record syssw passed in `rdi`, if `address` holds one.
    ///
    /// # Safety
    /// `address` must be the value syssw passed in `rdi` (a readable record).
    pub unsafe fn from_start(address: u64) -> Option<&'static StartInfo> {
        // SAFETY: the caller guarantees the address came from syssw's start convention.
        let info = unsafe { &*(address as *const StartInfo) };
        (info.magic == START_MAGIC && info.name_len <= 32).then_some(info)
    }

    pub fn name(&self) -> &str {
        core::str::from_utf8(&self.name[..self.name_len as usize]).unwrap_or("?")
    }
}
