//! The IPC message layout.
//!
//! A message is a [`MessageTag`] and three words in registers (`rdx`, `r10`, `r8`, `r9` on
//! both send and receive, see [`Call::Send`](crate::syscall::Call::Send)) plus, in the
//! sender's and receiver's [`IpcBuffer`] (one per thread, registered with
//! `thread_set(IpcBuffer)`), up to [`IPC_DATA_MAX`] bytes copied by the kernel and up to
//! [`IPC_MAX_ITEMS`] page-map items. The receiver sees the sender's tag with the length and
//! item count actually transferred.
//!
//! **Map items**: each names a page range of the sender ([`MapItem`]); the kernel maps the
//! ranges, one after the other, into the receiver's [`ReceiveWindow`] with at most the
//! sender's rights. A *grant* item also unmaps the range from the sender. If the receiver
//! has no window large enough, or a page there is already mapped, the send fails and the
//! receiver keeps waiting.
//!
//! **Exceptions** are messages the kernel sends on behalf of the faulting thread, as if it
//! had `call`ed its handler: label [`LABEL_EXCEPTION`] (a CPU exception),
//! [`LABEL_SYSCALL`] (a `syscall` of a task without `NATIVE_SYSCALLS`) or
//! [`LABEL_FAULT_REPORT`] (to the root task's health monitor, for a thread without a
//! handler); the data is an [`ExceptionMessage`]. The handler's reply decides: label
//! [`REPLY_RESUME`] resumes the thread, with the registers of the [`ExceptionMessage`] in
//! the reply data if it carries one (else unchanged); [`REPLY_KILL`] kills the thread.

/// Most data bytes one message carries.
pub const IPC_DATA_MAX: usize = 4096;
/// Most map items one message carries.
pub const IPC_MAX_ITEMS: usize = 4;

/// Labels the kernel uses for messages it sends (user labels must be below them).
pub const LABEL_EXCEPTION: u32 = 0xffff_0001;
pub const LABEL_SYSCALL: u32 = 0xffff_0002;
pub const LABEL_FAULT_REPORT: u32 = 0xffff_0003;
/// Labels from this value up are the kernel's own (the exception and fault messages above):
/// a message user space sends or replies with never carries one ([`MessageTag::is_valid`]),
/// so a receiver can trust that such a message comes from the kernel.
pub const KERNEL_LABELS: u32 = 0xffff_0000;
/// Reply labels for exception messages.
pub const REPLY_RESUME: u32 = 0;
pub const REPLY_KILL: u32 = 1;

/// Pseudo-vector of a forwarded `syscall` in an [`ExceptionMessage`].
pub const VECTOR_SYSCALL: u64 = 0x100;
/// Pseudo-vector of a thread stopped by `thread_interrupt` where it was running (its
/// registers are those of the next instruction it would have executed).
pub const VECTOR_INTERRUPT: u64 = 0x101;

/// Message descriptor: label (bits 0..32), data length in bytes (bits 32..45), map-item
/// count (bits 48..51).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct MessageTag(pub u64);

impl MessageTag {
    pub const fn new(label: u32, len: usize, items: usize) -> Self {
        Self(label as u64 | ((len as u64 & 0x1fff) << 32) | ((items as u64 & 0x7) << 48))
    }
    pub const fn label(self) -> u32 {
        self.0 as u32
    }
    pub const fn len(self) -> usize {
        ((self.0 >> 32) & 0x1fff) as usize
    }
    pub const fn is_empty(self) -> bool {
        self.len() == 0
    }
    pub const fn items(self) -> usize {
        ((self.0 >> 48) & 0x7) as usize
    }
    /// A tag user space may send ([`Self::is_valid`]) that carries no data bytes and no map
    /// items: the message is its label and three words, all in registers.
    pub const fn is_registers_only(self) -> bool {
        self.0 < KERNEL_LABELS as u64
    }
    /// The tag is one user space may send: no stray bits, length and item count within the
    /// limits, and not a label of the kernel's ([`KERNEL_LABELS`]).
    pub const fn is_valid(self) -> bool {
        self.0 & !0x0007_1fff_ffff_ffff == 0
            && self.len() <= IPC_DATA_MAX
            && self.items() <= IPC_MAX_ITEMS
            && self.label() < KERNEL_LABELS
    }
}

/// Map-item flag: move the pages (unmap them from the sender) instead of sharing them.
pub const MAP_ITEM_GRANT: u32 = 1 << 8;

/// A page range of the sender to map into the receiver.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MapItem {
    /// Page-aligned start in the sender's address space.
    pub source: u64,
    pub pages: u32,
    /// [`PageRights`](crate::syscall::PageRights) bits, plus [`MAP_ITEM_GRANT`].
    pub flags: u32,
}

impl MapItem {
    /// The item in its in-buffer layout (16 bytes, native-endian).
    pub fn from_bytes(b: &[u8; 16]) -> Self {
        let u32_at = |at: usize| u32::from_ne_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]);
        let mut source = [0; 8];
        source.copy_from_slice(&b[..8]);
        Self {
            source: u64::from_ne_bytes(source),
            pages: u32_at(8),
            flags: u32_at(12),
        }
    }
}

/// Where a receiver accepts mapped pages.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReceiveWindow {
    /// Page-aligned base (0 = no pages accepted).
    pub base: u64,
    pub pages: u64,
}

/// A thread's IPC buffer, in its own memory (8-byte aligned).
#[repr(C)]
#[derive(Clone, Copy)]
pub struct IpcBuffer {
    pub data: [u8; IPC_DATA_MAX],
    pub items: [MapItem; IPC_MAX_ITEMS],
    pub window: ReceiveWindow,
}

impl IpcBuffer {
    pub const fn new() -> Self {
        Self {
            data: [0; IPC_DATA_MAX],
            items: [MapItem {
                source: 0,
                pages: 0,
                flags: 0,
            }; IPC_MAX_ITEMS],
            window: ReceiveWindow { base: 0, pages: 0 },
        }
    }
}

impl Default for IpcBuffer {
    fn default() -> Self {
        Self::new()
    }
}

/// Byte offsets inside [`IpcBuffer`] (the kernel copies fields, not the whole struct).
pub const IPC_ITEMS_OFFSET: usize = IPC_DATA_MAX;
pub const IPC_WINDOW_OFFSET: usize =
    IPC_ITEMS_OFFSET + IPC_MAX_ITEMS * core::mem::size_of::<MapItem>();
pub const IPC_BUFFER_SIZE: usize = core::mem::size_of::<IpcBuffer>();

/// The user register context of a thread.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Registers {
    pub rax: u64,
    pub rbx: u64,
    pub rcx: u64,
    pub rdx: u64,
    pub rsi: u64,
    pub rdi: u64,
    pub rbp: u64,
    pub rsp: u64,
    pub r8: u64,
    pub r9: u64,
    pub r10: u64,
    pub r11: u64,
    pub r12: u64,
    pub r13: u64,
    pub r14: u64,
    pub r15: u64,
    pub rip: u64,
    /// Only the arithmetic flags, DF, TF and AC may be changed by a handler; IF stays set
    /// and IOPL stays 0.
    pub rflags: u64,
    pub fs_base: u64,
    pub gs_base: u64,
}

/// What an exception message carries (the data of the message).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ExceptionMessage {
    /// CPU exception vector (0..32), [`VECTOR_SYSCALL`] or [`VECTOR_INTERRUPT`].
    pub vector: u64,
    pub error_code: u64,
    /// CR2 for a page fault, else 0.
    pub fault_address: u64,
    /// The faulting thread and its task.
    pub thread: u64,
    pub task: u64,
    pub registers: Registers,
}

pub const EXCEPTION_MESSAGE_SIZE: usize = core::mem::size_of::<ExceptionMessage>();
/// The message as words, in the order of its fields (vector first, `gs_base` last).
pub const EXCEPTION_MESSAGE_WORDS: usize = EXCEPTION_MESSAGE_SIZE / 8;

/// RFLAGS bits a handler may change: CF, PF, AF, ZF, SF, TF, DF, OF, AC.
pub const USER_RFLAGS_MASK: u64 = 0x0004_0dd5;

impl ExceptionMessage {
    /// Serialises into native-endian bytes (the in-buffer layout).
    pub fn to_bytes(&self) -> [u8; EXCEPTION_MESSAGE_SIZE] {
        let mut out = [0u8; EXCEPTION_MESSAGE_SIZE];
        for (i, word) in self.words().iter().enumerate() {
            out[i * 8..i * 8 + 8].copy_from_slice(&word.to_ne_bytes());
        }
        out
    }

    pub fn from_bytes(bytes: &[u8]) -> Option<Self> {
        if bytes.len() < EXCEPTION_MESSAGE_SIZE {
            return None;
        }
        let mut w = [0u64; EXCEPTION_MESSAGE_WORDS];
        for (i, word) in w.iter_mut().enumerate() {
            *word = u64::from_ne_bytes(bytes[i * 8..i * 8 + 8].try_into().ok()?);
        }
        Some(Self::from_words(&w))
    }

    /// The message whose words ([`Self::words`]) are `w`.
    pub fn from_words(w: &[u64; EXCEPTION_MESSAGE_WORDS]) -> Self {
        let r = Registers {
            rax: w[5],
            rbx: w[6],
            rcx: w[7],
            rdx: w[8],
            rsi: w[9],
            rdi: w[10],
            rbp: w[11],
            rsp: w[12],
            r8: w[13],
            r9: w[14],
            r10: w[15],
            r11: w[16],
            r12: w[17],
            r13: w[18],
            r14: w[19],
            r15: w[20],
            rip: w[21],
            rflags: w[22],
            fs_base: w[23],
            gs_base: w[24],
        };
        Self {
            vector: w[0],
            error_code: w[1],
            fault_address: w[2],
            thread: w[3],
            task: w[4],
            registers: r,
        }
    }

    /// The message as words, its in-buffer layout.
    pub fn words(&self) -> [u64; EXCEPTION_MESSAGE_WORDS] {
        let r = &self.registers;
        [
            self.vector,
            self.error_code,
            self.fault_address,
            self.thread,
            self.task,
            r.rax,
            r.rbx,
            r.rcx,
            r.rdx,
            r.rsi,
            r.rdi,
            r.rbp,
            r.rsp,
            r.r8,
            r.r9,
            r.r10,
            r.r11,
            r.r12,
            r.r13,
            r.r14,
            r.r15,
            r.rip,
            r.rflags,
            r.fs_base,
            r.gs_base,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tag_round_trips_and_rejects_stray_bits() {
        let t = MessageTag::new(0x1234, 4096, 4);
        assert_eq!((t.label(), t.len(), t.items()), (0x1234, 4096, 4));
        assert!(t.is_valid());
        assert!(!MessageTag(t.0 | 1 << 63).is_valid());
        assert!(!MessageTag::new(1, 4097, 0).is_valid());
        assert!(!MessageTag::new(1, 0, 5).is_valid());
        // No user message can pass for the kernel's exception or fault messages.
        for label in [LABEL_EXCEPTION, LABEL_SYSCALL, LABEL_FAULT_REPORT, u32::MAX] {
            assert!(!MessageTag::new(label, 0, 0).is_valid(), "{label:#x}");
        }
        assert!(MessageTag::new(KERNEL_LABELS - 1, 0, 0).is_valid());
        assert!(MessageTag::new(KERNEL_LABELS - 1, 0, 0).is_registers_only());
        let mut item = [0u8; 16];
        item[..8].copy_from_slice(&0x1234_5000u64.to_ne_bytes());
        item[8..12].copy_from_slice(&3u32.to_ne_bytes());
        item[12..].copy_from_slice(&(MAP_ITEM_GRANT | 2).to_ne_bytes());
        assert_eq!(
            MapItem::from_bytes(&item),
            MapItem {
                source: 0x1234_5000,
                pages: 3,
                flags: MAP_ITEM_GRANT | 2
            }
        );
        assert!(!MessageTag::new(KERNEL_LABELS, 0, 0).is_registers_only());
        assert!(!MessageTag::new(7, 1, 0).is_registers_only());
        assert!(!MessageTag::new(7, 0, 1).is_registers_only());
    }

    #[test]
    fn exception_message_round_trips() {
        let mut m = ExceptionMessage {
            vector: 14,
            error_code: 6,
            fault_address: 0xdead_0000,
            thread: 0x10001,
            task: 0x10002,
            ..Default::default()
        };
        m.registers.rip = 0x40_1000;
        m.registers.gs_base = 7;
        m.registers.r15 = 99;
        assert_eq!(ExceptionMessage::from_bytes(&m.to_bytes()), Some(m));
        assert_eq!(ExceptionMessage::from_bytes(&[0; 8]), None);
    }

    #[test]
    fn buffer_offsets_match_the_struct() {
        assert_eq!(IPC_WINDOW_OFFSET + 16, IPC_BUFFER_SIZE);
        assert_eq!(EXCEPTION_MESSAGE_SIZE, 25 * 8);
    }
}
