//! Kernel-side test hooks, compiled only with the `test-hooks` feature (scenario images).
//! The system image entry `test/hook` names the hook to run once the kernel is ready:
//! - `exit-on-ready`: exit with success;
//! - `page-fault`: read an unmapped lower-half address (must be reported as #PF, failure);
//! - `timer N`: count N interrupts of the 1 kHz APIC timer, report the time, exit success;
//! - `exit-on-idle`: run user space normally; exit with success once no thread is left.

use crate::qemu::{ExitCode, exit};
use crate::{boot, kprintln};
use abi::sysimg::SystemImage;

/// An address in the (empty) lower half, distinctive in the CR2 report.
pub const UNMAPPED_ADDRESS: u64 = 0x0000_0dea_dbee_f000;

static EXIT_ON_IDLE: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);

/// Called when the kernel has nothing left to run.
pub fn on_idle() {
    if EXIT_ON_IDLE.load(core::sync::atomic::Ordering::Relaxed) {
        kprintln!("test: idle, exiting");
        exit(ExitCode::Success);
    }
}

#[allow(unsafe_code)] // the page-fault hook reads an unmapped address on purpose
pub fn run(image: &SystemImage, apic_timer_hz: u64) {
    let Some(entry) = image.find("test/hook") else {
        return;
    };
    let hook = core::str::from_utf8(entry.data).unwrap_or("").trim();
    if hook == "exit-on-idle" {
        EXIT_ON_IDLE.store(true, core::sync::atomic::Ordering::Relaxed);
        return;
    }
    kprintln!("test: running hook '{hook}'");
    let mut words = hook.split_whitespace();
    match (words.next(), words.next()) {
        (Some("exit-on-ready"), None) => exit(ExitCode::Success),
        (Some("page-fault"), None) => {
            // SAFETY: deliberately unsound: the read must fault; the #PF handler never returns.
            let value = unsafe { core::ptr::read_volatile(UNMAPPED_ADDRESS as *const u64) };
            panic!(
                "read of unmapped address {UNMAPPED_ADDRESS:#x} returned {value:#x} instead of faulting"
            );
        }
        (Some("timer"), Some(n)) => {
            let count: u64 = n
                .parse()
                .unwrap_or_else(|_| panic!("test hook: bad count '{n}'"));
            let ns = boot::count_timer_interrupts(apic_timer_hz, 1000, count);
            kprintln!("test: timer fired {count} times in {} us", ns / 1000);
            exit(ExitCode::Success)
        }
        _ => panic!("test hook: unknown hook '{hook}'"),
    }
}
