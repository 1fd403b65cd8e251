//! The partitions of scenario `pci_devices`; what one does depends on its name:
//!
//! * `nic*`: owns a virtio-net function (`devices`). Reads the records page syssw mapped at
//!   `DEVICES_BASE` and logs each record, then uses exactly what it was granted: the legacy
//!   I/O BAR's host-features and device-status registers, the modern common configuration
//!   (memory BAR 4, mapped uncached: selects feature word 0, reads it), and attaches the
//!   function's interrupt line; a line it was not granted is refused. Logs
//!   `nic: done` and, after 200 ms (the `cfg` partition had its window), executes `ud2`,
//!   which the scenario maps to `shutdown_success`.
//! * `cfg*`: reads CONFIG_ADDRESS (port 0xcf8), which no partition is ever granted: the #GP
//!   reaches the health monitor (`illegal_request`).
//! * anything else: logs `<name>: started` (a partition that must never start).
//!
//! A test program: it must never be needed by anything but its scenarios.
#![no_std]
#![no_main]

use pci::Bar;
use user_rt::partition::StartInfo;
use user_rt::println;
use user_rt::protocol::layout::DEVICES_BASE;
use user_rt::sys;

user_rt::entry!(main);

/// Legacy virtio PCI registers (I/O BAR 0): host features, device status.
const LEGACY_HOST_FEATURES: u16 = 0;
const LEGACY_DEVICE_STATUS: u16 = 18;
/// virtio-net's feature "the device has a MAC address".
const VIRTIO_NET_F_MAC: u32 = 1 << 5;
/// The common configuration's `device_feature_select` and `device_feature`, in QEMU's
/// modern BAR (4) from offset 0.
const COMMON_FEATURE_SELECT: u64 = 0;
const COMMON_DEVICE_FEATURE: u64 = 4;

fn inl(port: u16) -> u32 {
    let value: u32;
    // SAFETY: `in` touches no memory of this program; the TSS I/O bitmap decides whether
    // the access happens or faults.
    #[allow(unsafe_code)]
    unsafe {
        core::arch::asm!("in eax, dx", out("eax") value, in("dx") port, options(nomem, nostack, preserves_flags))
    };
    value
}

fn main(start: u64, _: u64) {
    #[allow(unsafe_code)]
    // SAFETY: syssw starts every partition with the start record's address in rdi.
    let Some(info) = (unsafe { StartInfo::from_start(start) }) else {
        return;
    };
    let name = info.name();
    if name.starts_with("nic") {
        nic();
    } else if name.starts_with("cfg") {
        println!("cfg: reading port 0xcf8 (PCI CONFIG_ADDRESS)");
        let value = inl(0xcf8);
        println!("cfg: port 0xcf8 read {value:#x}: configuration space reached");
    } else {
        println!("{name}: started");
    }
    sys::sleep_until(u64::MAX);
}

fn nic() {
    #[allow(unsafe_code)]
    // SAFETY: syssw maps the records page read-only at DEVICES_BASE before a partition
    // with devices starts, for the life of its task.
    let page = unsafe { core::slice::from_raw_parts(DEVICES_BASE as *const u8, 4096) };
    let mut lines = 0u32;
    for record in pci::records(page) {
        println!(
            "nic: device {} [{:04x}:{:04x}] class {:06x} pin {} line {:?}",
            record.address,
            record.vendor,
            record.device,
            record.class,
            record.interrupt_pin,
            record.interrupt_line
        );
        for (i, bar) in record.bars.iter().enumerate() {
            match *bar {
                Some(Bar::Io { port, size }) => {
                    println!("nic: BAR{i} I/O {port:#x}+{size}");
                    if i == 0 {
                        let features = inl(port + LEGACY_HOST_FEATURES);
                        let status = user_rt::port::inb(port + LEGACY_DEVICE_STATUS);
                        println!(
                            "nic: legacy host features {features:#010x} (MAC {}), device status {status:#x}",
                            if features & VIRTIO_NET_F_MAC != 0 {
                                "yes"
                            } else {
                                "no"
                            }
                        );
                    }
                }
                Some(Bar::Memory { base, size, .. }) => {
                    println!("nic: BAR{i} memory at {base:#x}+{size:#x}");
                    if i == 4 {
                        #[allow(unsafe_code)]
                        // SAFETY: syssw mapped this BAR (`size` bytes at `base`) uncached for
                        // this partition; volatile accesses of two aligned registers.
                        let features = unsafe {
                            core::ptr::write_volatile(
                                (base + COMMON_FEATURE_SELECT) as *mut u32,
                                0,
                            );
                            core::ptr::read_volatile((base + COMMON_DEVICE_FEATURE) as *const u32)
                        };
                        println!(
                            "nic: modern device features 0..31 {features:#010x} (MAC {}; selected and read through memory BAR4)",
                            if features & VIRTIO_NET_F_MAC != 0 {
                                "yes"
                            } else {
                                "no"
                            }
                        );
                    }
                }
                None => {}
            }
        }
        if let Some(line) = record.interrupt_line {
            lines |= 1 << line;
            let attached = sys::irq_attach(u64::from(line), 1);
            println!("nic: irq_attach of its line {line}: {attached:?}");
        }
    }
    let other = (16..24).find(|l| lines & (1 << l) == 0).unwrap_or(16);
    let refused = sys::irq_attach(other, 2);
    println!("nic: irq_attach of line {other}, not granted: {refused:?}");
    println!("nic: done");
    sys::sleep_until(sys::clock() + 200_000_000);
    // SAFETY: `ud2` only raises #UD, which syssw's health monitor turns into the
    // scenario's end (illegal_request = shutdown_success).
    #[allow(unsafe_code)]
    unsafe {
        core::arch::asm!("ud2")
    };
}
