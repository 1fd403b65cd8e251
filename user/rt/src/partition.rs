//! How the system software starts a partition's first thread (an interface between syssw
//! and every partition program):
//!
//! The thread starts at the image's ELF entry with `rdi` = the address of a [`StartInfo`]
//! record at the top of its stack (read-only by convention) and `rsp` 16-byte aligned
//! below it, minus 8 (as if called). Everything else the partition needs from syssw comes
//! through this record.

/// The partition's address space: see [`protocol::layout`].
pub use protocol::layout::{DATA_BASE, POOL_BASE, POOL_EXEC_BASE, SHARED_BASE};

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
    /// Why it (re)started: ARINC 653 `START_CONDITION_TYPE` (0 = NORMAL_START,
    /// 1 = PARTITION_RESTART, 2 = HM_MODULE_RESTART, 3 = HM_PARTITION_RESTART); cold or warm
    /// is its operating mode (`PARTITION_STATUS` of the service protocol).
    pub start_condition: u64,
    /// The task's maximum controlled priority (no thread of it may be above).
    pub mcp: u64,
    /// The first thread's priority.
    pub priority: u64,
    /// Length of `name` in bytes (the partition's name, UTF-8).
    pub name_len: u64,
    pub name: [u8; 32],
    /// Bytes of its data entry mapped at [`DATA_BASE`] (0: none).
    pub data_len: u64,
    /// Bytes of its memory pool mapped read-write at [`POOL_BASE`] and read-execute at
    /// [`POOL_EXEC_BASE`] (0: none; only a partition with the `map` ability has one).
    pub pool_len: u64,
}

impl StartInfo {
    /// A record for partition `name` (cut to 32 bytes).
    // One argument per field of the record.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        index: u64,
        time_partition: u64,
        server: u64,
        start_condition: u64,
        mcp: u8,
        priority: u8,
        name: &str,
        data_len: u64,
        pool_len: u64,
    ) -> Self {
        let n = name.len().min(32);
        let mut bytes = [0u8; 32];
        bytes[..n].copy_from_slice(&name.as_bytes()[..n]);
        Self {
            magic: START_MAGIC,
            index,
            time_partition,
            server,
            start_condition,
            mcp: mcp as u64,
            priority: priority as u64,
            name_len: n as u64,
            name: bytes,
            data_len,
            pool_len,
        }
    }

    /// The record as it lies in memory (`repr(C)`: eight u64, the name, two u64; no
    /// padding).
    pub fn to_bytes(&self) -> [u8; core::mem::size_of::<StartInfo>()] {
        let mut out = [0u8; core::mem::size_of::<StartInfo>()];
        let words = [
            self.magic,
            self.index,
            self.time_partition,
            self.server,
            self.start_condition,
            self.mcp,
            self.priority,
            self.name_len,
        ];
        for (chunk, word) in out.chunks_exact_mut(8).zip(words) {
            chunk.copy_from_slice(&word.to_le_bytes());
        }
        out[64..96].copy_from_slice(&self.name);
        out[96..104].copy_from_slice(&self.data_len.to_le_bytes());
        out[104..].copy_from_slice(&self.pool_len.to_le_bytes());
        out
    }

    /// The record syssw passed in `rdi`, if `address` holds one.
    ///
    /// # Safety
    /// `address` must be the value syssw passed in `rdi` (a readable record).
    #[allow(unsafe_code)] // the record is raw memory syssw prepared on the stack
    pub unsafe fn from_start(address: u64) -> Option<&'static StartInfo> {
        // SAFETY: the caller guarantees the address came from syssw's start convention.
        let info = unsafe { &*(address as *const StartInfo) };
        (info.magic == START_MAGIC && info.name_len <= 32).then_some(info)
    }

    /// The partition's data entry (empty without one).
    #[allow(unsafe_code)] // memory syssw mapped for this partition
    pub fn data(&self) -> &'static [u8] {
        if self.data_len == 0 {
            return &[];
        }
        // SAFETY: a record from `from_start` is syssw's, which maps `data_len` bytes at
        // DATA_BASE read-only before the partition starts and never unmaps or changes them
        // while the partition's task lives.
        unsafe { core::slice::from_raw_parts(DATA_BASE as *const u8, self.data_len as usize) }
    }

    pub fn name(&self) -> &str {
        core::str::from_utf8(&self.name[..self.name_len as usize]).unwrap_or("?")
    }
}
