//! PCI configuration space through mechanism #1 (CONFIG_ADDRESS 0xcf8, CONFIG_DATA 0xcfc),
//! ports only the kernel holds: one dword a call, for syssw's `pci_config`.

#[cfg(not(test))]
use super::cpu::{inl, outl};

#[cfg(not(test))]
const CONFIG_ADDRESS: u16 = 0xcf8;
#[cfg(not(test))]
const CONFIG_DATA: u16 = 0xcfc;

/// Reads (or, with `write`, writes `value` to) the dword at `address` (bus << 16 |
/// device << 11 | function << 8 | register, checked by the caller); returns what was read.
#[cfg(not(test))]
pub fn config(address: u32, value: u32, write: bool) -> u32 {
    // The kernel runs with interrupts off: nothing comes between the two accesses.
    outl(CONFIG_ADDRESS, 1 << 31 | address);
    if write {
        outl(CONFIG_DATA, value);
        0
    } else {
        inl(CONFIG_DATA)
    }
}

/// Host tests have no PCI bus: every function is absent (reads all ones).
#[cfg(test)]
pub fn config(_: u32, _: u32, _: bool) -> u32 {
    !0
}
