//! The legacy 8259 PIC pair: remapped away from the exception vectors, then fully masked
//! (the IOAPIC delivers device interrupts). Spurious IRQ 7/15 may still arrive on
//! [`VECTOR_BASE`]+7 / +15; the IDT ignores them.

use super::cpu::outb;

/// Vectors 0x20..0x2f; never used for anything else.
pub const VECTOR_BASE: u8 = 0x20;

pub fn remap_and_mask() {
    const ICW1_INIT_ICW4: u8 = 0x11;
    // Master at 0x20/0x21, slave at 0xa0/0xa1.
    outb(0x20, ICW1_INIT_ICW4);
    outb(0xa0, ICW1_INIT_ICW4);
    outb(0x21, VECTOR_BASE);
    outb(0xa1, VECTOR_BASE + 8);
    outb(0x21, 4); // slave on IRQ2
    outb(0xa1, 2); // slave identity
    outb(0x21, 0x01); // 8086 mode
    outb(0xa1, 0x01);
    outb(0x21, 0xff);
    outb(0xa1, 0xff);
}
