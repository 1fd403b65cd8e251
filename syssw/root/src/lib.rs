//! What only the root task (syssw, and the test programs that run as the root task) needs
//! on top of the user-mode runtime: its start information ([`root_info`]), the system image
//! the kernel maps for it ([`system_image`]) and the mechanism to run images in child tasks
//! ([`spawn`]). Mechanism only: which partitions, abilities and memory are used is syssw's
//! policy. Partitions never link this crate (they lack the abilities it needs).
#![no_std]

pub mod spawn;

/// The system image the kernel mapped for the root task (`rdi`/`rsi` at entry, see
/// `abi::syscall`), as a byte slice.
#[allow(unsafe_code)] // memory the kernel mapped, not a Rust object
pub fn system_image(base: u64, len: u64) -> &'static [u8] {
    assert_eq!(
        base,
        abi::syscall::ROOT_SYSTEM_IMAGE_BASE,
        "not started as the root task"
    );
    // SAFETY: the kernel maps `len` bytes at ROOT_SYSTEM_IMAGE_BASE read-only for the whole
    // life of the root task, and nothing writes them.
    unsafe { core::slice::from_raw_parts(base as *const u8, len as usize) }
}

/// The root task's start information (mapped read-only by the kernel at
/// `abi::syscall::ROOT_INFO_BASE`). Only valid in the root task.
#[allow(unsafe_code)] // memory the kernel mapped, not a Rust object
pub fn root_info() -> &'static abi::root::RootInfo {
    // SAFETY: the kernel maps a RootInfo page read-only at ROOT_INFO_BASE for the life of
    // the root task (checked by the magic below before use).
    let info = unsafe { &*(abi::syscall::ROOT_INFO_BASE as *const abi::root::RootInfo) };
    assert_eq!(info.magic, abi::root::ROOT_INFO_MAGIC, "not the root task");
    info
}
