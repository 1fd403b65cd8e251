//! The partitions of scenario `pci_devices`; what one does depends on its name:
//!
//! * `nic*`: owns a virtio-net function (`devices`). Reads the records page syssw mapped at
//!   `DEVICES_BASE` and logs each record, then uses exactly what it was granted: the legacy
//!   I/O BAR's host-features and device-status registers, the modern common configuration
//!   (memory BAR 4, mapped uncached: selects feature word 0, reads it), and attaches the
//!   function's interrupt line; a line it was not granted is refused. Logs
//!   `nic: done` and, after 1 s (the other partitions are done by then), executes `ud2`,
//!   which the scenario maps to `shutdown_success`.
//! * `edu*`: owns QEMU's `edu` test function, which raises its INTx (level) when told to
//!   through its memory BAR and keeps it asserted until its status is acknowledged there.
//!   Shows the interrupt path: the line fires; it stays masked while the driver has not
//!   called `irq_ack` although the device still asserts it; after `irq_ack` the still
//!   asserted level fires again (level-triggered); once the device is served and the line
//!   acknowledged, nothing more comes. Logs `edu: done`.
//! * `dma-attack*`: [`dma::attack`] (scenario `attack_dma`).
//! * `dma*`: owns an `edu` function and a DMA region (`dma`): the positive control of
//!   [`dma::check_own_region`], then logs `dma: done` (scenario `dma_regions`).
//! * `cfg*`: reads CONFIG_ADDRESS (port 0xcf8), which no partition is ever granted: the #GP
//!   reaches the health monitor (`illegal_request`).
//! * anything else: logs `<name>: started` (a partition that must never start).
//!
//! A test program: it must never be needed by anything but its scenarios.
#![no_std]
#![no_main]

mod dma;

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
    } else if name.starts_with("edu") {
        edu();
    } else if name.starts_with("dma-attack") {
        dma::attack("dma-attack");
    } else if name.starts_with("dma") {
        if let Some(edu) = dma::Edu::find("dma") {
            println!(
                "dma: device {}, DMA region at {:#x}, {} KiB, bus address {:#x}",
                edu.record.address,
                edu.region.address,
                edu.region.length / 1024,
                edu.region.bus_address
            );
            dma::check_own_region("dma", &edu);
        }
        println!("dma: done");
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
                        let select = (base + COMMON_FEATURE_SELECT) as *mut u32;
                        let feature = (base + COMMON_DEVICE_FEATURE) as *const u32;
                        #[allow(unsafe_code)]
                        // SAFETY: syssw mapped this BAR (`size` bytes at `base`) uncached for
                        // this partition; a volatile write of an aligned register.
                        unsafe {
                            core::ptr::write_volatile(select, 0)
                        };
                        #[allow(unsafe_code)]
                        // SAFETY: as above, a volatile read of the next register.
                        let features = unsafe { core::ptr::read_volatile(feature) };
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
    sys::sleep_until(sys::clock() + 1_000_000_000);
    // SAFETY: `ud2` only raises #UD, which syssw's health monitor turns into the
    // scenario's end (illegal_request = shutdown_success).
    #[allow(unsafe_code)]
    unsafe {
        core::arch::asm!("ud2")
    };
}

/// `edu`'s registers in its memory BAR 0: identification, interrupt status, raise, ack.
const EDU_ID: u64 = 0x00;
const EDU_STATUS: u64 = 0x24;
const EDU_RAISE: u64 = 0x60;
const EDU_ACK: u64 = 0x64;
const MS: u64 = 1_000_000;

fn edu() {
    #[allow(unsafe_code)]
    // SAFETY: as in `nic`: syssw's records page, read-only for the task's life.
    let page = unsafe { core::slice::from_raw_parts(DEVICES_BASE as *const u8, 4096) };
    let Some(record) = pci::records(page).next() else {
        println!("edu: check FAILED: no device record");
        return;
    };
    let (Some(Bar::Memory { base, .. }), Some(line)) = (record.bars[0], record.interrupt_line)
    else {
        println!("edu: check FAILED: no memory BAR0 or no interrupt line");
        return;
    };
    let register = |offset: u64| (base + offset) as *mut u32;
    #[allow(unsafe_code)]
    // SAFETY: syssw mapped edu's BAR 0 (1 MiB) uncached at `base`; aligned 32-bit registers.
    let read = |offset: u64| unsafe { core::ptr::read_volatile(register(offset)) };
    #[allow(unsafe_code)]
    // SAFETY: as for `read`.
    let write =
        |offset: u64, value: u32| unsafe { core::ptr::write_volatile(register(offset), value) };
    let line = u64::from(line);
    println!(
        "edu: device {} id {:#010x}, interrupt line {line}",
        record.address,
        read(EDU_ID)
    );
    let report = |what: &str, ok: bool| {
        println!("edu: check {}: {what}", if ok { "ok" } else { "FAILED" });
    };
    let wait = |ms: u64| sys::irq_wait(line, ms * MS);
    report("irq_attach of its line", sys::irq_attach(line, 0).is_ok());
    report(
        "no interrupt before the device raises one",
        wait(20).is_err(),
    );
    write(EDU_RAISE, 1);
    report("the raised interrupt arrives", wait(100).is_ok());
    report(
        "the line stays masked until irq_ack though the device still asserts it",
        read(EDU_STATUS) == 1 && wait(50).is_err(),
    );
    report("irq_ack", sys::irq_ack(line).is_ok());
    report(
        "after irq_ack the still-asserted level fires again",
        wait(100).is_ok(),
    );
    write(EDU_ACK, 1);
    let _ = sys::irq_ack(line);
    report(
        "once the device is served and the line acknowledged, nothing more comes",
        read(EDU_STATUS) == 0 && wait(50).is_err(),
    );
    println!("edu: done");
}
