//! 16550 UART on COM1 (0x3f8), the kernel log. 115200 baud, 8N1, polled (no interrupts).

use super::cpu::{inb, outb};

pub const COM1: u16 = 0x3f8;

pub struct Uart {
    base: u16,
}

impl Uart {
    pub const fn new(base: u16) -> Self {
        Self { base }
    }

    pub fn init(&self) {
        let b = self.base;
        outb(b + 1, 0x00); // no UART interrupts
        outb(b + 3, 0x80); // DLAB on: set the divisor
        outb(b, 0x01); // divisor 1 = 115200 baud
        outb(b + 1, 0x00);
        outb(b + 3, 0x03); // 8N1, DLAB off
        outb(b + 2, 0xc7); // FIFO on, cleared, 14-byte threshold
        outb(b + 4, 0x03); // DTR + RTS
    }

    pub fn write_byte(&self, byte: u8) {
        // Bounded wait for "transmit holding register empty": a missing UART must not hang us.
        for _ in 0..100_000 {
            if inb(self.base + 5) & 0x20 != 0 {
                break;
            }
            core::hint::spin_loop();
        }
        outb(self.base, byte);
    }
}
