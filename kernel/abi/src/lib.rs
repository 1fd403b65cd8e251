//! The kernel's ABI: the only kernel types user space and the loader see.
//!
//! What lives here is a contract between separately built programs (loader, kernel, system
//! software, partitions, host tools) and must stay stable: the boot-information block the
//! loader hands the kernel ([`boot`], with the machine it found in [`machine`]), the
//! system-image archive format ([`sysimg`]) and the checksum they use ([`crc32`]), the
//! system-call interface ([`syscall`], with the register of each argument in [`args`]), the
//! IPC and exception message layout ([`ipc`]), the loadable-segment rules of ELF images
//! ([`elf`]), the field tables of binary records ([`layout`]) and the root task's start
//! information ([`root`]). It must never contain kernel policy or anything that needs an
//! allocator (the `std` feature adds host-side writers only).
#![no_std]

#[cfg(feature = "std")]
extern crate std;

pub mod args;
pub mod boot;
pub mod crc32;
pub mod elf;
pub mod ipc;
pub mod layout;
pub mod machine;
pub mod root;
pub mod syscall;
pub mod sysimg;
