//! System-call dispatch: argument decoding, ability and right checks, then the object
//! operations in [`state`](crate::state) and [`ipc`](crate::ipc). The ABI (numbers,
//! registers, errors) is documented once, in `abi::syscall`.

use crate::ipc::deadline;
use crate::kprintln;
use crate::rp::Amount;
use crate::state::{Kernel, Source};
use crate::thread::{Fault, State};
use crate::timepart::{Schedule, Window};
use abi::ipc::{IPC_BUFFER_SIZE, LABEL_SYSCALL, MessageTag, VECTOR_SYSCALL};
use abi::syscall::{
    Abilities, Call, DEBUG_WRITE_MAX, Error, MAX_SCHEDULES, MAX_WINDOWS, PageRights, TASK_NAME_MAX,
    TIME_PARTITIONS, ThreadAttribute, USER_END,
};

/// What the entry glue must do after a kernel operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Schedule and return to user mode.
    Continue,
    /// Stop the machine (system_halt, or a fault nobody can handle).
    Halt { success: bool },
}

/// The six argument registers of thread `t`.
fn args(k: &Kernel, t: usize) -> [u64; 6] {
    let c = &k.threads[t].context;
    [c.rdi, c.rsi, c.rdx, c.r10, c.r8, c.r9]
}

/// A `syscall` of thread `t` (its registers are in its context); `clock` gives the time in
/// ns since boot, read only by calls that need it (it costs a division).
pub fn on_syscall(k: &mut Kernel, t: usize, clock: fn() -> u64) -> Outcome {
    let task = k.threads[t].task;
    if !k.tasks[task].abilities.contains(Abilities::NATIVE_SYSCALLS) {
        let fault = Fault {
            label: LABEL_SYSCALL,
            vector: VECTOR_SYSCALL,
            error_code: 0,
            address: 0,
        };
        return crate::fault::deliver_or_report(k, t, fault);
    }
    let raw = k.threads[t].context.rax;
    let result = match Call::from_code(raw) {
        None => Err(Error::InvalidCall),
        Some(call) => handle(k, t, call, clock),
    };
    match result {
        Ok(Some(halt)) => halt,
        Ok(None) => Outcome::Continue,
        Err(e) => {
            k.threads[t].context.rax = e as u64;
            Outcome::Continue
        }
    }
}

/// Sets `rax` = Ok for calls that completed (blocking calls set it when they end).
fn done(k: &mut Kernel, t: usize) -> Result<Option<Outcome>, Error> {
    k.threads[t].context.rax = Error::Ok as u64;
    Ok(None)
}

fn rights(bits: u64) -> Result<PageRights, Error> {
    PageRights::from_bits(bits).ok_or(Error::InvalidArgument)
}

fn handle(
    k: &mut Kernel,
    t: usize,
    call: Call,
    clock: fn() -> u64,
) -> Result<Option<Outcome>, Error> {
    let task = k.threads[t].task;
    let a = args(k, t);
    match call {
        Call::DebugWrite => {
            k.require(task, Abilities::DEBUG_LOG)?;
            let (ptr, len) = (a[0], a[1]);
            if len > DEBUG_WRITE_MAX {
                return Err(Error::InvalidArgument);
            }
            let mut buf = [0u8; DEBUG_WRITE_MAX as usize];
            let text = &mut buf[..len as usize];
            if !k.tasks[task].space.copy_from_user(ptr, text) {
                return Err(Error::BadAddress);
            }
            let text = core::str::from_utf8(text).unwrap_or("<invalid UTF-8>");
            kprintln!("[{}] {}", k.tasks[task].name(), text.trim_end_matches('\n'));
            done(k, t)
        }
        Call::Clock => {
            let c = &mut k.threads[t].context;
            (c.rdi, c.rsi, c.rdx) = (clock(), crate::time::tsc_hz(), crate::time::boot_tsc());
            done(k, t)
        }
        Call::ThreadExit => {
            kprintln!("kernel: thread of task {} exited", k.tasks[task].name());
            k.kill_thread(t);
            Ok(None)
        }
        Call::SystemHalt => {
            k.require(task, Abilities::SYSTEM_HALT)?;
            let success = match a[0] {
                0 => true,
                1 => false,
                _ => return Err(Error::InvalidArgument),
            };
            kprintln!(
                "kernel: halt requested by user space ({})",
                if success { "Success" } else { "Failure" }
            );
            Ok(Some(Outcome::Halt { success }))
        }
        Call::Yield => {
            k.run.rotate(t);
            done(k, t)
        }
        Call::SleepUntil => {
            k.threads[t].context.rax = Error::Ok as u64;
            if a[0] > clock() {
                k.block(t, State::Sleeping, a[0]);
            }
            Ok(None)
        }

        Call::TaskCreate => {
            k.require(task, Abilities::CREATE_TASK)?;
            let abilities = Abilities::from_bits(a[0]).ok_or(Error::InvalidArgument)?;
            let mcp = u8::try_from(a[1]).map_err(|_| Error::McpExceeded)?;
            let rp = k.resource_partition(task, a[2])?;
            if rp != k.tasks[task].rp {
                k.require(task, Abilities::PARTITION_CONTROL)?;
                if k.rps[rp].owner != task {
                    return Err(Error::NotPermitted);
                }
            }
            if a[4] > TASK_NAME_MAX {
                return Err(Error::InvalidArgument);
            }
            let mut name = [0u8; TASK_NAME_MAX as usize];
            let name = &mut name[..a[4] as usize];
            if !k.tasks[task].space.copy_from_user(a[3], name) {
                return Err(Error::BadAddress);
            }
            let name = core::str::from_utf8(name).map_err(|_| Error::InvalidArgument)?;
            let child = k.create_task(task, abilities, mcp, rp, name)?;
            k.threads[t].context.rdi = k.task_id(child);
            done(k, t)
        }
        Call::TaskKill => {
            k.require(task, Abilities::CREATE_TASK)?;
            let target = k.task(a[0])?;
            if target == task || !k.is_within(target, task) {
                return Err(Error::NotPermitted);
            }
            k.destroy_task(target);
            done(k, t)
        }
        Call::TaskAllowSend => {
            k.require(task, Abilities::CREATE_TASK)?;
            let from = k.controlled_task(task, a[0])?;
            let to = k.controlled_task(task, a[1])?;
            k.tasks[from].send_to |= 1 << to;
            done(k, t)
        }

        Call::ThreadCreate => {
            k.require(task, Abilities::CREATE_THREAD)?;
            let target = k.controlled_task(task, a[0])?;
            let priority = u8::try_from(a[3]).map_err(|_| Error::McpExceeded)?;
            let tp = k.threads[t].time_partition;
            let new = k.create_thread(target, a[1], a[2], priority, tp, a[4])?;
            k.threads[t].context.rdi = k.thread_id(new);
            done(k, t)
        }
        Call::ThreadStart => {
            k.require(task, Abilities::CREATE_THREAD)?;
            let target = k.controlled_thread(t, a[0])?;
            if k.threads[target].state != State::Inactive {
                return Err(Error::InvalidArgument);
            }
            k.set_state(target, State::Ready);
            done(k, t)
        }
        Call::ThreadSuspend | Call::ThreadResume => {
            let target = k.controlled_thread(t, a[0])?;
            k.set_suspended(target, call == Call::ThreadSuspend);
            done(k, t)
        }
        Call::ThreadKill => {
            let target = k.controlled_thread(t, a[0])?;
            k.kill_thread(target);
            if target != t {
                done(k, t)?;
            }
            Ok(None)
        }
        Call::ThreadSet => {
            let target = k.controlled_thread(t, a[0])?;
            set_attribute(k, task, target, a[1], a[2])?;
            done(k, t)
        }
        Call::ThreadSelf => {
            k.threads[t].context.rdi = k.thread_id(t);
            k.threads[t].context.rsi = k.task_id(task);
            done(k, t)
        }

        Call::Map | Call::MapPhysical => {
            let source = if call == Call::Map {
                k.require(task, Abilities::MAP)?;
                Source::Virtual(a[1])
            } else {
                k.require(task, Abilities::PHYSICAL_MEMORY)?;
                Source::Physical(a[1])
            };
            let target = k.controlled_task(task, a[0])?;
            k.map(task, target, source, a[2], a[3], rights(a[4])?)?;
            done(k, t)
        }
        Call::Unmap => {
            k.require(task, Abilities::MAP)?;
            let target = k.controlled_task(task, a[0])?;
            k.unmap(target, a[1], a[2])?;
            done(k, t)
        }
        Call::Protect => {
            k.require(task, Abilities::MAP)?;
            let target = k.controlled_task(task, a[0])?;
            k.protect(target, a[1], a[2], rights(a[3])?)?;
            done(k, t)
        }

        Call::Send | Call::Call => {
            let dest = k.thread(a[0])?;
            if !k.may_send(task, k.threads[dest].task) {
                return Err(Error::NotPermitted);
            }
            if !MessageTag(a[2]).is_valid() {
                return Err(Error::InvalidArgument);
            }
            k.send(
                t,
                dest,
                call == Call::Call,
                deadline(clock, a[1]),
                a[1] == 0,
            );
            Ok(None)
        }
        Call::Receive => {
            let from = match a[0] {
                0 => None,
                id => Some(k.thread(id)?),
            };
            k.receive(t, from, deadline(clock, a[1]), a[1] == 0);
            Ok(None)
        }
        Call::ReplyWait | Call::Reply => {
            if !MessageTag(a[2]).is_valid() {
                return Err(Error::InvalidArgument);
            }
            if a[0] != 0 {
                let caller = k.thread(a[0]).map_err(|_| Error::NotWaiting)?;
                k.reply(t, caller)?;
            }
            if call == Call::ReplyWait {
                k.receive(t, None, deadline(clock, a[1]), a[1] == 0);
                Ok(None)
            } else {
                done(k, t)
            }
        }

        Call::NotifySignal => {
            let target = k.thread(a[0])?;
            if !k.may_send(task, k.threads[target].task) {
                return Err(Error::NotPermitted);
            }
            k.signal(target, a[1]);
            done(k, t)
        }
        Call::NotifyWait => {
            k.wait_notify(t, a[0], deadline(clock, a[1]), a[1] == 0);
            Ok(None)
        }

        Call::RpCreate => {
            k.require(task, Abilities::PARTITION_CONTROL)?;
            let rp = k.rp_create(
                task,
                Amount {
                    tasks: a[0],
                    threads: a[1],
                    pages: a[2],
                },
            )?;
            k.threads[t].context.rdi = rp as u64 + 1;
            done(k, t)
        }
        Call::RpInfo => {
            let rp = k.resource_partition(task, a[0])?;
            let r = k.rps[rp];
            let c = &mut k.threads[t].context;
            c.rdi = r.used.pages;
            c.rsi = r.quota.pages;
            c.rdx = (r.used.threads & 0xffff)
                | (r.quota.threads & 0xffff) << 16
                | (r.used.tasks & 0xffff) << 32
                | (r.quota.tasks & 0xffff) << 48;
            done(k, t)
        }
        Call::ScheduleSet | Call::ScheduleSwitch | Call::PartitionInfo => {
            time_call(k, t, call, a, clock())?;
            done(k, t)
        }
        Call::IoGrant => {
            k.require(task, Abilities::IO_PORTS)?;
            let target = k.task(a[0])?;
            k.io_grant(task, target, a[1], a[2])?;
            done(k, t)
        }
        Call::IrqGrant => {
            k.require(task, Abilities::IRQ)?;
            let target = k.task(a[0])?;
            k.irq_grant(task, target, a[1])?;
            done(k, t)
        }
        Call::IrqAttach | Call::IrqWait | Call::IrqAck | Call::IrqDetach => {
            k.require(task, Abilities::IRQ)?;
            k.threads[t].context.rax = Error::Ok as u64;
            match call {
                Call::IrqAttach => k.irq_attach(t, a[0], a[1])?,
                Call::IrqWait => k.irq_wait(t, a[0], deadline(clock, a[1]), a[1] == 0)?,
                Call::IrqAck => k.irq_ack(t, a[0])?,
                _ => k.irq_detach(t, a[0])?,
            }
            Ok(None)
        }
        Call::SetHealthMonitor => {
            k.require(task, Abilities::PARTITION_CONTROL)?;
            let monitor = k.thread(a[0])?;
            if task != 0 || k.threads[monitor].task != 0 {
                return Err(Error::NotPermitted);
            }
            k.health_monitor = a[0];
            done(k, t)
        }
    }
}

fn time_call(k: &mut Kernel, t: usize, call: Call, a: [u64; 6], now: u64) -> Result<(), Error> {
    let task = k.threads[t].task;
    match call {
        Call::ScheduleSet => {
            k.require(task, Abilities::SCHEDULING)?;
            let (slot, major, ptr, count) = (a[0], a[1], a[2], a[3]);
            if slot >= MAX_SCHEDULES || count > MAX_WINDOWS {
                return Err(Error::InvalidArgument);
            }
            let mut windows = [Window::default(); MAX_WINDOWS as usize];
            for (i, w) in windows.iter_mut().take(count as usize).enumerate() {
                let mut raw = [0u8; 24];
                let at = ptr.checked_add(i as u64 * 24).ok_or(Error::BadAddress)?;
                if !k.tasks[task].space.copy_from_user(at, &mut raw) {
                    return Err(Error::BadAddress);
                }
                let word = |n: usize| u64::from_ne_bytes(raw[n * 8..n * 8 + 8].try_into().unwrap());
                *w = Window {
                    offset: word(0),
                    duration: word(1),
                    partition: u8::try_from(word(2)).map_err(|_| Error::InvalidArgument)?,
                };
            }
            let schedule = Schedule::new(major, &windows[..count as usize])
                .map_err(|_| Error::InvalidArgument)?;
            k.time
                .install(slot as usize, schedule)
                .map_err(|_| Error::NotPermitted)
        }
        Call::ScheduleSwitch => {
            k.require(task, Abilities::SCHEDULING)?;
            if a[0] < MAX_SCHEDULES && k.time.switch_to(a[0] as usize, now) {
                k.update_window(now);
                Ok(())
            } else {
                Err(Error::InvalidArgument)
            }
        }
        _ => {
            let tp = u8::try_from(a[0])
                .ok()
                .filter(|&p| (p as u64) < TIME_PARTITIONS)
                .ok_or(Error::InvalidArgument)?;
            let (start, length) = k.time.next_window(tp, now).unwrap_or((u64::MAX, 0));
            let ns = |ticks| crate::time::ticks_to_ns(ticks, crate::time::tsc_hz());
            let (cpu, idle, frames) = (
                ns(k.cpu_ticks[tp as usize]),
                ns(k.idle_ticks),
                k.time.frames,
            );
            let active = k.active_partition.unwrap_or(0) as u64;
            let c = &mut k.threads[t].context;
            (c.rdi, c.rsi, c.rdx, c.r10, c.r8, c.r9) = (active, start, length, cpu, idle, frames);
            Ok(())
        }
    }
}

fn set_attribute(
    k: &mut Kernel,
    caller_task: usize,
    target: usize,
    attribute: u64,
    value: u64,
) -> Result<(), Error> {
    match ThreadAttribute::from_code(attribute).ok_or(Error::InvalidArgument)? {
        ThreadAttribute::Priority => {
            let priority = u8::try_from(value).map_err(|_| Error::McpExceeded)?;
            k.set_priority(target, priority)
        }
        ThreadAttribute::ExceptionHandler => {
            if value != 0 {
                let handler = k.thread(value)?;
                if !k.is_within(k.threads[target].task, k.threads[handler].task) {
                    return Err(Error::NotPermitted);
                }
            }
            k.threads[target].exception_handler = value;
            Ok(())
        }
        ThreadAttribute::IpcBuffer => {
            let space = k.tasks[k.threads[target].task].space;
            if value != 0
                && (!value.is_multiple_of(8) || !space.accessible(value, IPC_BUFFER_SIZE, true))
            {
                return Err(Error::BadAddress);
            }
            k.threads[target].ipc_buffer = value;
            Ok(())
        }
        ThreadAttribute::FsBase | ThreadAttribute::GsBase => {
            if value >= USER_END {
                return Err(Error::InvalidArgument);
            }
            if attribute == ThreadAttribute::FsBase as u64 {
                k.threads[target].fs_base = value;
            } else {
                k.threads[target].gs_base = value;
            }
            k.reload_bases |= k.current == Some(target);
            Ok(())
        }
        ThreadAttribute::TimePartition => {
            k.require(caller_task, Abilities::SCHEDULING)?;
            k.set_time_partition(
                target,
                u8::try_from(value).map_err(|_| Error::InvalidArgument)?,
            )
        }
    }
}
