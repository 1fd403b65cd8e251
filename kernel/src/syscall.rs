//! System-call dispatch (the ABI is documented in `abi::syscall`).

use crate::arch::syscall::SyscallFrame;
use crate::task::CURRENT;
use crate::{kprintln, qemu};
use abi::syscall::{Abilities, Call, DEBUG_WRITE_MAX, Error};

pub fn dispatch(frame: &mut SyscallFrame) {
    let result = match Call::from_raw(frame.rax) {
        None => Err(Error::InvalidCall),
        Some(call) => handle(call, frame),
    };
    frame.rax = match result {
        Ok(()) => Error::Ok as u64,
        Err(e) => e as u64,
    };
}

fn require(ability: Abilities) -> Result<(), Error> {
    let current = CURRENT.lock();
    let task = current
        .as_ref()
        .expect("system call without a current task");
    if task.abilities.contains(ability) {
        Ok(())
    } else {
        Err(Error::AbilityDenied)
    }
}

fn handle(call: Call, frame: &mut SyscallFrame) -> Result<(), Error> {
    match call {
        Call::DebugWrite => {
            require(Abilities::DEBUG_LOG)?;
            let (ptr, len) = (frame.rdi, frame.rsi);
            if len > DEBUG_WRITE_MAX {
                return Err(Error::InvalidArgument);
            }
            let mut buf = [0u8; DEBUG_WRITE_MAX as usize];
            let text = &mut buf[..len as usize];
            let current = CURRENT.lock();
            let task = current.as_ref().expect("current task");
            if !task.space.copy_from_user(ptr, text) {
                return Err(Error::BadAddress);
            }
            let text = core::str::from_utf8(text).unwrap_or("<invalid UTF-8>");
            kprintln!("[{}] {}", task.name, text.trim_end_matches('\n'));
            Ok(())
        }
        Call::Clock => {
            frame.rdi = crate::time::since_boot_ns();
            Ok(())
        }
        Call::ThreadExit => {
            let name = CURRENT.lock().as_ref().map_or("?", |t| t.name);
            kprintln!("kernel: thread of task {name} exited; no runnable thread left, idling");
            crate::boot::idle()
        }
        Call::SystemHalt => {
            require(Abilities::SYSTEM_HALT)?;
            let code = match frame.rdi {
                0 => qemu::ExitCode::Success,
                1 => qemu::ExitCode::Failure,
                _ => return Err(Error::InvalidArgument),
            };
            kprintln!("kernel: halt requested by user space ({code:?})");
            qemu::exit(code)
        }
    }
}
