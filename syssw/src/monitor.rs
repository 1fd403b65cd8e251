//! The health monitor: the kernel reports every fault of a partition thread that has no
//! exception handler here (`LABEL_FAULT_REPORT`); syssw classifies it as an ARINC 653
//! error, looks the action up in the partition's and the module's health tables, logs the
//! event and carries the action out.
//!
//! Event line (an interface): `health: t=<ms>.<us>ms partition=<name> error=<ERROR>
//! detail=<what> action=<action>`.

use config::binary::SystemView;
use config::model::{HealthAction, HealthError, HealthTable};
use user_rt::abi::ipc::{LABEL_FAULT_REPORT, MessageTag, REPLY_KILL};
use user_rt::abi::syscall::{TIMEOUT_INFINITE, TaskId};
use user_rt::ipc_buffer::IpcBufferRef;
use user_rt::println;
use user_rt::sys::{self, Message};

/// The ARINC 653 error a CPU exception of a partition thread is.
fn classify(vector: u64) -> HealthError {
    match vector {
        0 | 16 | 19 => HealthError::NumericError,
        6 => HealthError::IllegalRequest,
        2 | 18 => HealthError::HardwareFault,
        12 => HealthError::StackOverflow,
        _ => HealthError::MemoryViolation,
    }
}

/// Writes a name in capitals (ARINC 653 spells errors that way).
struct Upper(&'static str);

impl core::fmt::Display for Upper {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        for c in self.0.chars() {
            core::fmt::Write::write_char(f, c.to_ascii_uppercase())?;
        }
        Ok(())
    }
}

pub fn run(system: &SystemView, tasks: &[TaskId], ipc: IpcBufferRef) -> ! {
    loop {
        let Ok(m) = sys::receive(None, TIMEOUT_INFINITE) else {
            continue;
        };
        if m.message.tag.label() != LABEL_FAULT_REPORT {
            // Requests of partitions come with the port services; answer "not supported".
            let _ = sys::reply(m.sender, &Message::new(1, [0; 3]));
            continue;
        }
        let e = ipc.exception();
        let Some(index) = tasks.iter().position(|t| t.0 == e.task) else {
            println!(
                "health: fault report for unknown task {:#x}; thread killed",
                e.task
            );
            let _ = sys::reply(
                m.sender,
                &Message {
                    tag: MessageTag::new(REPLY_KILL, 0, 0),
                    words: [0; 3],
                },
            );
            continue;
        };
        let p = system.partition(index);
        let error = classify(e.vector);
        let action = HealthTable::resolve(Some(&p.health), &system.health(), error);
        let now = sys::clock();
        println!(
            "health: t={}.{:03}ms partition={} error={} detail=vector {} error code {:#x} at rip {:#x} address {:#x} action={}",
            now / 1_000_000,
            now / 1000 % 1000,
            p.name,
            Upper(error.name()),
            e.vector,
            e.error_code,
            e.registers.rip,
            e.fault_address,
            action.name()
        );
        match action {
            HealthAction::Shutdown => {
                let _ = sys::system_halt(false);
            }
            HealthAction::ShutdownSuccess => {
                let _ = sys::system_halt(true);
            }
            // Restarts need the partition's image reloaded: until the partition modes
            // exist, the partition is stopped like IDLE (logged above as requested).
            _ => {
                let _ = sys::task_kill(tasks[index]);
            }
        }
    }
}
