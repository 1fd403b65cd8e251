use super::*;
use std::collections::BTreeMap;
use std::string::ToString;

/// A configuration space with real BAR semantics: a BAR register keeps only the address
/// bits its size allows (writing all ones reads back the size mask), the type bits are
/// read-only, absent functions read all ones.
#[derive(Default)]
struct Fake {
    registers: BTreeMap<(Address, u8), u32>,
    /// (function, register) -> (size, type bits) of each BAR register (a 64-bit BAR's
    /// upper half has type bits 0 and the size's upper half).
    bars: BTreeMap<(Address, u8), (u64, u32)>,
    writes: std::vec::Vec<(Address, u8, u32)>,
}

impl Fake {
    fn function(&mut self, at: Address, vendor: u16, device: u16, pin: u8) {
        self.registers
            .insert((at, ID), u32::from(device) << 16 | u32::from(vendor));
        self.registers.insert((at, CLASS), 0x0200_0000);
        self.registers.insert((at, COMMAND), 0x0010_0000);
        self.registers
            .insert((at, INTERRUPT), u32::from(pin) << 8 | 11);
    }

    fn io_bar(&mut self, at: Address, i: u8, port: u16, size: u64) {
        let r = BAR0 + 4 * i;
        self.bars.insert((at, r), (size, 1));
        self.registers.insert((at, r), u32::from(port) | 1);
    }

    fn memory_bar(&mut self, at: Address, i: u8, base: u64, size: u64, wide: bool) {
        let r = BAR0 + 4 * i;
        let kind = if wide { 0b1100 } else { 0 };
        self.bars.insert((at, r), (size, kind));
        self.registers.insert((at, r), base as u32 | kind);
        if wide {
            self.bars.insert((at, r + 4), (size, u32::MAX));
            self.registers.insert((at, r + 4), (base >> 32) as u32);
        }
    }
}

impl ConfigSpace for Fake {
    fn read(&mut self, at: Address, register: u8) -> u32 {
        let absent = !self.registers.contains_key(&(at, ID));
        if absent {
            return !0;
        }
        self.registers.get(&(at, register)).copied().unwrap_or(0)
    }

    fn write(&mut self, at: Address, register: u8, value: u32) {
        self.writes.push((at, register, value));
        let value = match self.bars.get(&(at, register)) {
            // The upper half of a 64-bit BAR.
            Some(&(size, u32::MAX)) => value & (!(size - 1) >> 32) as u32,
            Some(&(size, kind)) => {
                let low = if kind & 1 == 1 { 3 } else { 0xf };
                value & !(size as u32 - 1) & !low | kind
            }
            // Unimplemented BARs are hard-wired to zero.
            // The status half is write-one-to-clear.
            None if register == COMMAND => {
                let old = self.registers.get(&(at, register)).copied().unwrap_or(0);
                old & 0xffff_0000 & !(value & 0xffff_0000) | value & 0xffff
            }
            None if (BAR0..BAR0 + 24).contains(&register) => 0,
            None => value,
        };
        self.registers.insert((at, register), value);
    }
}

fn addr(text: &str) -> Address {
    Address::parse(text).unwrap()
}

#[test]
fn addresses_parse_and_print_as_lspci_does() {
    let a = addr("00:03.0");
    assert_eq!((a.bus, a.device, a.function), (0, 3, 0));
    assert_eq!(addr("0000:1f:1f.7"), addr("1f:1f.7"));
    assert_eq!(addr("1F:1f.7").to_string(), "1f:1f.7");
    assert_eq!(Address::from_id(a.id()), a);
    assert_eq!(addr("01:02.3").config_address(0x3c), 0x8001_133c);
}

#[test]
fn malformed_addresses_are_refused_with_the_reason() {
    for bad in [
        "00:1g.0", "00:03", "0:03:0", "", "003.0", "00:03.", "100:03.0", ":03.0",
    ] {
        assert_eq!(Address::parse(bad), Err(AddressError::Form), "{bad}");
    }
    assert_eq!(Address::parse("00:20.0"), Err(AddressError::Device(0x20)));
    assert_eq!(Address::parse("00:03.8"), Err(AddressError::Function(8)));
    assert!(AddressError::Form.to_string().contains("00:03.0"));
}

#[test]
fn bars_are_decoded_and_sized_with_decoding_off_and_restored() {
    let mut cs = Fake::default();
    let at = addr("00:03.0");
    cs.function(at, 0x1af4, 0x1000, 1);
    cs.io_bar(at, 0, 0xc040, 32);
    cs.memory_bar(at, 1, 0xc000_1000, 0x1000, false);
    cs.memory_bar(at, 4, 0x8_0000_0000, 0x4000, true);
    let before = cs.registers.clone();
    let f = probe(&mut cs, at).unwrap();
    assert_eq!(
        (f.vendor, f.device, f.interrupt_pin, f.class),
        (0x1af4, 0x1000, 1, 0x02_0000)
    );
    assert_eq!(
        f.bars[0],
        Some(Bar::Io {
            port: 0xc040,
            size: 32
        })
    );
    assert_eq!(
        f.bars[1],
        Some(Bar::Memory {
            base: 0xc000_1000,
            size: 0x1000,
            prefetchable: false
        })
    );
    assert_eq!(f.bars[2], None);
    assert_eq!(
        f.bars[4],
        Some(Bar::Memory {
            base: 0x8_0000_0000,
            size: 0x4000,
            prefetchable: true
        })
    );
    // BAR5 is the upper half of BAR4, not a BAR of its own.
    assert_eq!(f.bars[5], None);
    cs.registers
        .retain(|k, v| *v != 0 || before.contains_key(k));
    assert_eq!(cs.registers, before, "every register as it was");
    // Decoding was off before the first all-ones write.
    let first_bar_write = cs.writes.iter().position(|w| w.1 >= BAR0).unwrap();
    let off = cs.writes[..first_bar_write]
        .iter()
        .rev()
        .find(|w| w.1 == COMMAND)
        .unwrap();
    assert_eq!(off.2 & (COMMAND_IO | COMMAND_MEMORY), 0);
    assert!(check_bars(&f).is_ok());
}

#[test]
fn absent_functions_and_bridges_are_refused() {
    let mut cs = Fake::default();
    assert_eq!(probe(&mut cs, addr("00:05.0")), Err(DeviceError::Absent));
    let bridge = addr("00:1e.0");
    cs.function(bridge, 0x8086, 0x244e, 0);
    cs.registers.insert((bridge, HEADER), 0x0001_0000);
    assert_eq!(
        probe(&mut cs, bridge),
        Err(DeviceError::NotEndpoint { header_type: 1 })
    );
    assert!(DeviceError::Absent.to_string().contains("no such device"));
}

#[test]
fn memory_bars_smaller_than_a_page_and_bars_over_config_ports_are_refused() {
    let mut cs = Fake::default();
    let at = addr("00:04.0");
    cs.function(at, 0x1234, 0x1111, 0);
    cs.memory_bar(at, 0, 0xc000_0010, 0x10, false);
    let f = probe(&mut cs, at).unwrap();
    assert_eq!(
        check_bars(&f),
        Err(DeviceError::PartialPage {
            bar: 0,
            base: 0xc000_0010,
            size: 0x10
        })
    );
    let mut f = f;
    f.bars[0] = Some(Bar::Io {
        port: 0xcf0,
        size: 16,
    });
    assert_eq!(check_bars(&f), Err(DeviceError::ConfigPorts { bar: 0 }));
    f.bars[0] = Some(Bar::Io {
        port: 0xcd0,
        size: 16,
    });
    assert!(check_bars(&f).is_ok());
}

#[test]
fn enabling_turns_on_decoding_and_intx_and_bus_mastering_only_when_asked() {
    let mut cs = Fake::default();
    let at = addr("00:03.0");
    cs.function(at, 0x1af4, 0x1000, 1);
    cs.registers.insert(
        (at, COMMAND),
        0xffff_0000 | COMMAND_BUS_MASTER | COMMAND_INTX_DISABLE,
    );
    cs.io_bar(at, 0, 0xc040, 32);
    let f = probe(&mut cs, at).unwrap();
    enable(&mut cs, &f, false);
    assert_eq!(
        cs.registers[&(at, COMMAND)],
        0xffff_0000 | COMMAND_IO,
        "I/O on, memory, bus master and INTx-disable off, status untouched"
    );
    enable(&mut cs, &f, true);
    assert_eq!(
        cs.registers[&(at, COMMAND)],
        0xffff_0000 | COMMAND_IO | COMMAND_BUS_MASTER,
        "a partition with a DMA region gets bus mastering"
    );
}

#[test]
fn intx_pins_of_bus_zero_reach_pirq_e_to_h_rotated_by_the_device() {
    // QEMU q35: device 3 INTA -> PIRQH (input 23), device 4 INTA -> PIRQE (input 20).
    assert_eq!(q35_interrupt_line(addr("00:03.0"), 1), Some(23));
    assert_eq!(q35_interrupt_line(addr("00:04.0"), 1), Some(20));
    assert_eq!(q35_interrupt_line(addr("00:04.0"), 2), Some(21));
    assert_eq!(q35_interrupt_line(addr("00:03.0"), 0), None);
    assert_eq!(q35_interrupt_line(addr("00:1f.0"), 1), None);
    assert_eq!(q35_interrupt_line(addr("01:00.0"), 1), None);
}

#[test]
fn records_round_trip_through_the_device_page() {
    let record = Record {
        address: addr("00:03.0"),
        vendor: 0x1af4,
        device: 0x1000,
        interrupt_line: Some(23),
        interrupt_pin: 1,
        class: 0x02_0000,
        bars: [
            Some(Bar::Io {
                port: 0xc040,
                size: 32,
            }),
            Some(Bar::Memory {
                base: 0x6800_0000_1000,
                size: 0x1000,
                prefetchable: false,
            }),
            None,
            None,
            None,
            None,
        ],
    };
    let mut page = [0u8; 4096];
    page[..8].copy_from_slice(&1u64.to_le_bytes());
    page[RECORDS_AT..RECORDS_AT + RECORD_SIZE].copy_from_slice(&record.encode());
    let got: std::vec::Vec<Record> = records(&page).collect();
    assert_eq!(got, [record]);
    // A damaged kind is no record; a huge count stops at the page's records.
    page[RECORDS_AT + 28] = 9;
    assert_eq!(records(&page).count(), 0);
    page[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    assert!(records(&page).count() <= MAX_PARTITION_DEVICES);
}

#[test]
fn the_capability_list_is_copied_and_walked_without_configuration_space() {
    let mut cs = Fake::default();
    let at = addr("00:03.0");
    cs.function(at, 0x1af4, 0x1041, 1);
    cs.registers.insert((at, CAPABILITIES_POINTER), 0x84);
    // 0x84: vendor (9) -> 0x70: vendor -> 0x40: MSI-X (0x11) -> end.
    cs.registers.insert((at, 0x84), 0x1009_7009);
    cs.registers.insert((at, 0x70), 0x1002_4009);
    cs.registers.insert((at, 0x40), 0x0000_0011);
    let caps = read_capabilities(&mut cs, at);
    // Through the device page, as the partition sees it (after one function's).
    let mut page = [0u8; 4096];
    let slot = CAPABILITIES_AT + CAPABILITIES_SIZE;
    page[slot..slot + CAPABILITIES_SIZE].copy_from_slice(&caps.encode());
    let seen = capabilities(&page, 1);
    assert_eq!(seen, caps);
    let list: std::vec::Vec<(u8, u8)> = seen.iter().map(|c| (c.id, c.offset)).collect();
    assert_eq!(list, [(9, 0x84), (9, 0x70), (0x11, 0x40)]);
    let first = seen.iter().next().unwrap();
    assert_eq!(
        first.bytes[2..4],
        [0x09, 0x10],
        "length and the virtio cfg_type byte"
    );
    assert_eq!(capabilities(&page, 0).iter().count(), 0);
    assert_eq!(capabilities(&page, 99).iter().count(), 0, "past the page");
    const {
        assert!(CAPABILITIES_AT >= RECORDS_AT + MAX_PARTITION_DEVICES * RECORD_SIZE);
        assert!(CAPABILITIES_AT + MAX_PARTITION_DEVICES * CAPABILITIES_SIZE <= 4096);
    }
    // Without the status bit there is no list.
    cs.registers.insert((at, COMMAND), 0);
    assert_eq!(read_capabilities(&mut cs, at).iter().count(), 0);
}

#[test]
fn a_damaged_capability_list_ends_the_walk_never_panics() {
    // A list pointing at itself, and pointers below 0x40 or past 0xfc.
    let mut looped = Capabilities {
        first: 0x40,
        ..Capabilities::default()
    };
    looped.area[1] = 0x40;
    assert_eq!(looped.iter().count(), DEVICE_AREA_SIZE / 4);
    for first in [0, 0x3f, 0xfd, 0xff] {
        let c = Capabilities {
            first,
            ..Capabilities::default()
        };
        assert_eq!(c.iter().count(), 0, "pointer {first:#x}");
    }
    for seed in 0..200u32 {
        let mut c = Capabilities {
            first: (seed * 37) as u8,
            ..Capabilities::default()
        };
        for (i, b) in c.area.iter_mut().enumerate() {
            *b = (seed.wrapping_mul(2_654_435_761).rotate_left(i as u32 % 31) >> 7) as u8;
        }
        assert!(c.iter().count() <= DEVICE_AREA_SIZE / 4);
    }
}

#[test]
fn the_dma_region_round_trips_through_the_device_page_and_translates_addresses() {
    let mut page = [0u8; 4096];
    assert_eq!(dma_region(&page), None, "no region: length 0");
    let region = DmaRegion {
        address: 0x6c00_0000_0000,
        length: 0x8_0000,
        bus_address: 0x0123_4000,
    };
    page[DMA_AT..DMA_AT + DMA_SIZE].copy_from_slice(&region.encode());
    assert_eq!(dma_region(&page), Some(region));
    assert_eq!(dma_region(&page[..DMA_AT + 8]), None, "a short page");
    const { assert!(DMA_AT >= RECORDS_AT + MAX_PARTITION_DEVICES * RECORD_SIZE) };
    assert_eq!(region.bus_address_of(0x6c00_0000_0010), Some(0x0123_4010));
    assert_eq!(
        region.bus_address_of(0x6c00_0008_0000),
        None,
        "one past the end"
    );
    assert_eq!(region.bus_address_of(0x6bff_ffff_ffff), None);
}

#[test]
fn transitional_virtio_devices_pass_the_iommu_by() {
    assert!(
        dma_bypasses_iommu(0x1af4, 0x1000),
        "transitional virtio-net"
    );
    assert!(!dma_bypasses_iommu(0x1af4, 0x1041), "modern virtio-net");
    assert!(!dma_bypasses_iommu(0x1234, 0x11e8), "edu");
}
