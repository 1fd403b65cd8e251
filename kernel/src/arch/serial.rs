//! 16550 UART on COM1 (0x3f8), the kernel log. 115200 baud, 8N1, FIFO on, polled (no
//! interrupts).

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

    /// True when the transmit FIFO is empty ("transmit holding register empty"): it takes
    /// 16 bytes without waiting.
    pub fn ready(&self) -> bool {
        inb(self.base + 5) & 0x20 != 0
    }

    /// Hands the UART one byte (the caller knows it has room).
    pub fn send(&self, byte: u8) {
        outb(self.base, byte);
    }

    /// Waits until the UART has room, then sends `byte`.
    pub fn write_byte(&self, byte: u8) {
        // Bounded wait: a missing UART must not hang us.
        for _ in 0..100_000 {
            if self.ready() {
                break;
            }
            core::hint::spin_loop();
        }
        self.send(byte);
    }
}
