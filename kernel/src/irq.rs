//! Interrupts at user level: a line granted down the task tree, attached to one thread,
//! delivered as one of its notification bits, masked from the moment it fires until the
//! thread acknowledges it.
//!
//! The state here is pure: [`Irqs::unmasked`] says which lines user space wants open; the
//! entry glue (`arch::entry`) masks a line in the IOAPIC as it fires and brings the
//! controller in line with `unmasked` before returning to user mode. An interrupt whose
//! thread's time partition is not eligible just makes the thread ready; the scheduler runs
//! it when its window comes, which is the "latched" delivery ARINC 653 asks for.

use crate::state::Kernel;
use crate::table::{TaskIdx, ThreadIdx};
use abi::syscall::{Error, IRQ_LINES, KERNEL_IRQS};

pub const LINES: usize = IRQ_LINES as usize;

/// The thread a line is attached to and the notification bit it sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Binding {
    pub thread: Option<ThreadIdx>,
    pub bit: u8,
}

pub struct Irqs {
    pub lines: [Binding; LINES],
    /// Bit n: line n is attached and acknowledged, so the IOAPIC should deliver it.
    pub unmasked: u32,
    /// Bit n: line n is open in the IOAPIC (kept by the entry glue).
    pub applied: u32,
    /// Interrupts received per line (for the log and tests).
    pub count: [u32; LINES],
}

impl Irqs {
    pub const fn new() -> Self {
        Self {
            lines: [Binding {
                thread: None,
                bit: 0,
            }; LINES],
            unmasked: 0,
            applied: 0,
            count: [0; LINES],
        }
    }
}

impl Default for Irqs {
    fn default() -> Self {
        Self::new()
    }
}

/// All lines but the kernel's: what the root task holds.
pub fn root_lines() -> u32 {
    let all = (1u32 << LINES) - 1;
    KERNEL_IRQS.iter().fold(all, |m, &l| m & !(1 << l))
}

fn line_index(line: u64) -> Result<usize, Error> {
    if line < IRQ_LINES {
        Ok(line as usize)
    } else {
        Err(Error::InvalidArgument)
    }
}

impl Kernel {
    pub fn holds_irq(&self, task: TaskIdx, line: usize) -> bool {
        self.tasks[task].irq_lines() & (1 << line) != 0
    }

    /// `irq_grant` by `caller` to the descendant `target`.
    pub fn irq_grant(&mut self, caller: TaskIdx, target: TaskIdx, line: u64) -> Result<(), Error> {
        let line = line_index(line)?;
        if target == caller || !self.is_within(target, caller) || !self.holds_irq(caller, line) {
            return Err(Error::NotPermitted);
        }
        self.tasks[target].grant_irq_line(line);
        Ok(())
    }

    /// The line, if thread `t` has it attached.
    fn attached(&self, t: ThreadIdx, line: u64) -> Result<usize, Error> {
        let line = line_index(line)?;
        if self.irqs.lines[line].thread == Some(t) {
            Ok(line)
        } else {
            Err(Error::NotPermitted)
        }
    }

    pub fn irq_attach(&mut self, t: ThreadIdx, line: u64, bit: u64) -> Result<(), Error> {
        let index = line_index(line)?;
        if bit >= 64 {
            return Err(Error::InvalidArgument);
        }
        let owner = self.irqs.lines[index].thread;
        if !self.holds_irq(self.threads[t].task(), index) || owner.is_some_and(|o| o != t) {
            return Err(Error::NotPermitted);
        }
        self.irqs.lines[index] = Binding {
            thread: Some(t),
            bit: bit as u8,
        };
        self.irqs.unmasked |= 1 << index;
        Ok(())
    }

    /// `irq_wait`: a notification wait on the line's bit.
    pub fn irq_wait(
        &mut self,
        t: ThreadIdx,
        line: u64,
        deadline: u64,
        poll: bool,
    ) -> Result<(), Error> {
        let line = self.attached(t, line)?;
        let mask = 1u64 << self.irqs.lines[line].bit;
        self.wait_notify(t, mask, deadline, poll);
        // The wait reports the bits in rdi; irq_wait has no result besides the status.
        Ok(())
    }

    pub fn irq_ack(&mut self, t: ThreadIdx, line: u64) -> Result<(), Error> {
        let line = self.attached(t, line)?;
        self.irqs.unmasked |= 1 << line;
        Ok(())
    }

    pub fn irq_detach(&mut self, t: ThreadIdx, line: u64) -> Result<(), Error> {
        let line = self.attached(t, line)?;
        self.release_line(line);
        Ok(())
    }

    fn release_line(&mut self, line: usize) {
        self.irqs.lines[line].thread = None;
        self.irqs.unmasked &= !(1 << line);
    }

    /// Detaches every line of a dying thread (bounded by the number of lines).
    pub fn release_irqs_of(&mut self, t: ThreadIdx) {
        for line in 0..LINES {
            if self.irqs.lines[line].thread == Some(t) {
                self.release_line(line);
            }
        }
    }

    /// Line `line` fired (the glue has masked it): it stays masked until acknowledged, and
    /// its thread gets the notification.
    pub fn irq_fired(&mut self, line: usize) {
        self.irqs.count[line] = self.irqs.count[line].wrapping_add(1);
        self.irqs.unmasked &= !(1 << line);
        self.irqs.applied &= !(1 << line);
        let Binding { thread, bit } = self.irqs.lines[line];
        if let Some(thread) = thread {
            self.signal(thread, 1 << bit);
        }
    }
}
