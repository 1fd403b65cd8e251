//! System-call dispatch: one handler per call (all of one signature, [`Handler`]), which
//! decodes its arguments (`abi::args`, the one definition of each call's registers), checks
//! abilities, rights and ranges, then calls the object operations in
//! [`state`](crate::state) and [`ipc`](crate::ipc) and says what happens next ([`Next`]).
//! The ABI (numbers, registers, errors) is documented once, in `abi::syscall`.

use crate::ipc::deadline;
use crate::kprintln;
use crate::rp::Amount;
use crate::state::{Kernel, Source};
use crate::table::{Slot, TaskIdx, ThreadIdx};
use crate::thread::{Fault, State};
use crate::timepart::{Schedule, Window};
use abi::args::{self, ArgRegs, RpCounts, results};
use abi::ipc::{
    IPC_BUFFER_SIZE, LABEL_EXCEPTION, LABEL_SYSCALL, MessageTag, VECTOR_INTERRUPT, VECTOR_SYSCALL,
};
use abi::syscall::{
    Abilities, Call, DEBUG_WRITE_MAX, Error, MAX_SCHEDULES, MAX_WINDOWS, PageRights, TASK_NAME_MAX,
    TIME_PARTITIONS, ThreadAttribute, ThreadId, USER_END, WindowSpec,
};

/// What the entry glue must do after a kernel operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Schedule and return to user mode.
    Continue,
    /// Return to user mode in this thread, which the scheduler would choose (the IPC fast
    /// path knows it without asking).
    SwitchTo(ThreadIdx),
    /// Stop the machine (system_halt, or a fault nobody can handle).
    Halt { success: bool },
}

/// What happens after a system call's handler returned `Ok`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Next {
    /// The call is complete: the caller gets `rax` = Ok (its results are already in its
    /// registers).
    Return,
    /// `rax` is not the dispatcher's to set: the caller blocked (the call sets it when it
    /// ends), is gone, or the IPC path already set it.
    Pending,
    /// Stop the machine.
    Halt { success: bool },
}

/// The clock a handler may read (ns since boot).
type Clock = fn() -> u64;
/// What a handler returns.
type Handled = Result<Next, Error>;

/// Defines `dispatch`, which runs the handler of each call, from one table. Every handler
/// has one signature: the kernel, the calling thread, its argument registers and the clock
/// (read only by calls that need it: it costs a division); an `Err` is the caller's `rax`.
/// Direct calls (not a table of function pointers) let the compiler inline them.
macro_rules! handlers {
    ($($call:ident => $handler:ident,)*) => {
        fn dispatch(call: Call, k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, clock: Clock) -> Handled {
            match call {
                $(Call::$call => $handler(k, t, r, clock),)*
            }
        }
    };
}

handlers! {
    DebugWrite => debug_write, Clock => clock, ThreadExit => thread_exit,
    SystemHalt => system_halt, Yield => yield_now, SleepUntil => sleep_until,
    TaskCreate => task_create, TaskKill => task_kill, TaskStop => task_stop,
    TaskAllowSend => task_allow_send,
    ThreadCreate => thread_create, ThreadStart => thread_start, ThreadSuspend => thread_suspend,
    ThreadResume => thread_resume, ThreadKill => thread_kill, ThreadSet => thread_set,
    ThreadSelf => thread_self, ThreadFpu => thread_fpu,
    ThreadInterrupt => thread_interrupt, Map => map, MapPhysical => map_physical,
    MapDevice => map_device, Unmap => unmap,
    Protect => protect, Send => send, Receive => receive, Call => ipc_call,
    ReplyWait => reply_wait, Reply => reply, NotifySignal => notify_signal,
    NotifyWait => notify_wait, RpCreate => rp_create, RpInfo => rp_info,
    SetHealthMonitor => set_health_monitor, ScheduleSet => schedule_set,
    ScheduleSwitch => schedule_switch, PartitionInfo => partition_info, IoGrant => io_grant,
    IrqGrant => irq_grant, IrqAttach => irq_attach, IrqWait => irq_wait, IrqAck => irq_ack,
    IrqDetach => irq_detach, PciConfig => pci_config, DmaMap => dma_map,
    DmaFault => dma_fault,
}

/// A `syscall` of thread `t` (its registers are in its context); `clock` gives the time in
/// ns since boot, read only by calls that need it (it costs a division).
pub fn on_syscall(k: &mut Kernel, t: ThreadIdx, clock: fn() -> u64) -> Outcome {
    let task = k.threads[t].task();
    if !k.tasks[task]
        .abilities()
        .contains(Abilities::NATIVE_SYSCALLS)
    {
        if k.threads[t].answered() {
            return Outcome::Continue;
        }
        let fault = Fault {
            label: LABEL_SYSCALL,
            vector: VECTOR_SYSCALL,
            error_code: 0,
            address: 0,
        };
        return crate::fault::deliver_or_report(k, t, fault);
    }
    let raw = k.threads[t].context().rax;
    let call = raw == Call::Call.code();
    if (call || raw == Call::ReplyWait.code())
        && let Some(outcome) = k.fast_ipc(t, call)
    {
        return outcome;
    }
    let result = match Call::from_code(raw) {
        None => Err(Error::InvalidCall),
        Some(call) => dispatch(call, k, t, &k.threads[t].arg_regs(), clock),
    };
    match result {
        Ok(Next::Return) => {
            k.threads[t].set_status(Error::Ok);
            Outcome::Continue
        }
        Ok(Next::Pending) => Outcome::Continue,
        Ok(Next::Halt { success }) => Outcome::Halt { success },
        Err(e) => {
            k.threads[t].set_status(e);
            Outcome::Continue
        }
    }
}

/// `rax` = Ok now, for calls that may block: the wake-up sets it again if the wait fails.
fn ok_unless_changed(k: &mut Kernel, t: ThreadIdx) {
    k.threads[t].set_status(Error::Ok);
}

fn rights(bits: u64) -> Result<PageRights, Error> {
    PageRights::from_bits(bits).ok_or(Error::InvalidArgument)
}

/// The calling thread's task.
fn task_of(k: &Kernel, t: ThreadIdx) -> TaskIdx {
    k.threads[t].task()
}

fn debug_write(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let task = task_of(k, t);
    k.require(task, Abilities::DEBUG_LOG)?;
    let a = args::DebugWrite::decode(r);
    if a.len > DEBUG_WRITE_MAX {
        return Err(Error::InvalidArgument);
    }
    let mut buf = [0u8; DEBUG_WRITE_MAX as usize];
    let text = &mut buf[..a.len as usize];
    if !k.tasks[task].space().copy_from_user(a.ptr, text) {
        return Err(Error::BadAddress);
    }
    let text = core::str::from_utf8(text).unwrap_or("<invalid UTF-8>");
    kprintln!("[{}] {}", k.tasks[task].name(), text.trim_end_matches('\n'));
    Ok(Next::Return)
}

fn clock(k: &mut Kernel, t: ThreadIdx, _: &ArgRegs, clock: Clock) -> Handled {
    let now = results::Clock {
        ns: clock(),
        tsc_hz: crate::time::tsc_hz(),
        boot_tsc: crate::time::boot_tsc(),
        wall_clock_at_boot: crate::time::wall_clock_at_boot(),
    };
    k.threads[t].set_results(|r| now.encode_into(r));
    Ok(Next::Return)
}

fn thread_exit(k: &mut Kernel, t: ThreadIdx, _: &ArgRegs, _: Clock) -> Handled {
    kprintln!(
        "kernel: thread of task {} exited",
        k.tasks[task_of(k, t)].name()
    );
    k.kill_thread(t);
    Ok(Next::Pending)
}

fn system_halt(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    k.require(task_of(k, t), Abilities::SYSTEM_HALT)?;
    let success = match args::SystemHalt::decode(r).outcome {
        0 => true,
        1 => false,
        _ => return Err(Error::InvalidArgument),
    };
    kprintln!(
        "kernel: halt requested by user space ({})",
        if success { "Success" } else { "Failure" }
    );
    Ok(Next::Halt { success })
}

fn yield_now(k: &mut Kernel, t: ThreadIdx, _: &ArgRegs, _: Clock) -> Handled {
    k.run.rotate(t.position());
    Ok(Next::Return)
}

fn sleep_until(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, clock: Clock) -> Handled {
    let time = args::SleepUntil::decode(r).time;
    ok_unless_changed(k, t);
    if time > clock() {
        k.block(t, State::Sleeping, time);
    }
    Ok(Next::Pending)
}

fn task_create(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let task = task_of(k, t);
    k.require(task, Abilities::CREATE_TASK)?;
    let a = args::TaskCreate::decode(r);
    let abilities = Abilities::from_bits(a.abilities).ok_or(Error::InvalidArgument)?;
    let mcp = u8::try_from(a.mcp).map_err(|_| Error::McpExceeded)?;
    let rp = k.resource_partition(task, a.rp)?;
    if rp != k.tasks[task].rp() {
        k.require(task, Abilities::PARTITION_CONTROL)?;
        if k.rps[rp].owner != task {
            return Err(Error::NotPermitted);
        }
    }
    if a.name_len > TASK_NAME_MAX {
        return Err(Error::InvalidArgument);
    }
    let mut name = [0u8; TASK_NAME_MAX as usize];
    let name = &mut name[..a.name_len as usize];
    if !k.tasks[task].space().copy_from_user(a.name_ptr, name) {
        return Err(Error::BadAddress);
    }
    let name = core::str::from_utf8(name).map_err(|_| Error::InvalidArgument)?;
    let child = k.create_task(task, abilities, mcp, rp, name)?;
    let task = k.task_id(child);
    k.threads[t].set_results(|r| results::TaskCreate { task }.encode_into(r));
    Ok(Next::Return)
}

/// The strict descendant (live or dying) that `task_kill` or `task_stop` names.
fn descendant_to_kill(k: &Kernel, t: ThreadIdx, r: &ArgRegs) -> Result<TaskIdx, Error> {
    let task = task_of(k, t);
    k.require(task, Abilities::CREATE_TASK)?;
    let target = k.task_to_kill(args::TaskKill::decode(r).task)?;
    if target == task || !k.is_within(target, task) {
        return Err(Error::NotPermitted);
    }
    Ok(target)
}

fn task_kill(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let target = descendant_to_kill(k, t, r)?;
    if k.destroy_task(target, crate::task::KILL_BUDGET) {
        return Ok(Next::Return);
    }
    // Not done: the caller executes the same `syscall` again (2 bytes back, its registers
    // unchanged), so a window boundary or a higher priority can come in between.
    k.threads[t].rewind(SYSCALL_LEN);
    Ok(Next::Pending)
}

fn task_stop(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let target = descendant_to_kill(k, t, r)?;
    k.stop_task(target);
    Ok(Next::Return)
}

/// Length of the `syscall` instruction (0f 05).
const SYSCALL_LEN: u64 = 2;

fn task_allow_send(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let task = task_of(k, t);
    k.require(task, Abilities::CREATE_TASK)?;
    let a = args::TaskAllowSend::decode(r);
    if a.notify_only > 1 {
        return Err(Error::InvalidArgument);
    }
    let from = k.controlled_task(task, a.from)?;
    let to = k.controlled_task(task, a.to)?;
    k.allow_send(from, to, a.notify_only == 1);
    Ok(Next::Return)
}

fn thread_create(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let task = task_of(k, t);
    k.require(task, Abilities::CREATE_THREAD)?;
    let a = args::ThreadCreate::decode(r);
    let target = k.controlled_task(task, a.task)?;
    let priority = u8::try_from(a.priority).map_err(|_| Error::McpExceeded)?;
    let tp = k.threads[t].time_partition();
    let new = k.create_thread(target, a.entry, a.stack, priority, tp, a.arg)?;
    let thread = k.thread_id(new);
    k.threads[t].set_results(|r| results::ThreadCreate { thread }.encode_into(r));
    Ok(Next::Return)
}

fn thread_start(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    k.require(task_of(k, t), Abilities::CREATE_THREAD)?;
    let target = k.controlled_thread(t, args::OnThread::decode(r).thread)?;
    if k.threads[target].state() != State::Inactive {
        return Err(Error::InvalidArgument);
    }
    k.set_state(target, State::Ready);
    Ok(Next::Return)
}

fn thread_suspend(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let target = k.controlled_thread(t, args::OnThread::decode(r).thread)?;
    k.set_suspended(target, true);
    Ok(Next::Return)
}

fn thread_resume(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let target = k.controlled_thread(t, args::OnThread::decode(r).thread)?;
    k.set_suspended(target, false);
    Ok(Next::Return)
}

fn thread_kill(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let target = k.controlled_thread(t, args::OnThread::decode(r).thread)?;
    k.kill_thread(target);
    Ok(if target == t {
        Next::Pending
    } else {
        Next::Return
    })
}

fn thread_set(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let a = args::ThreadSet::decode(r);
    let target = k.controlled_thread(t, a.thread)?;
    set_attribute(k, task_of(k, t), target, a.attribute, a.value)?;
    Ok(Next::Return)
}

fn thread_fpu(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let a = args::ThreadFpu::decode(r);
    let target = k.controlled_thread(t, a.thread)?;
    // The caller runs, so the target's image is the one saved when it was switched out.
    if target == t || a.write > 1 {
        return Err(Error::InvalidArgument);
    }
    let space = &k.tasks[task_of(k, t)].space();
    if a.write == 0 {
        let image = k.threads[target].fpu().0;
        return if space.copy_to_user(a.buffer, &image) {
            Ok(Next::Return)
        } else {
            Err(Error::BadAddress)
        };
    }
    let mut image = [0u8; 512];
    if !space.copy_from_user(a.buffer, &mut image) {
        return Err(Error::BadAddress);
    }
    k.threads[target].load_fpu(image);
    Ok(Next::Return)
}

fn thread_interrupt(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let target = k.controlled_thread(t, args::OnThread::decode(r).thread)?;
    let handler = k.thread(k.threads[target].exception_handler());
    if target == t || handler.is_err() {
        return Err(Error::InvalidArgument);
    }
    // One CPU: the caller runs, so a ready target is preempted in user mode.
    let interrupted = k.threads[target].state() == State::Ready;
    if interrupted {
        let fault = Fault {
            label: LABEL_EXCEPTION,
            vector: VECTOR_INTERRUPT,
            error_code: 0,
            address: 0,
        };
        k.raise_fault(target, fault);
    }
    k.threads[t].set_results(|r| results::ThreadInterrupt { interrupted }.encode_into(r));
    Ok(Next::Return)
}

fn thread_self(k: &mut Kernel, t: ThreadIdx, _: &ArgRegs, _: Clock) -> Handled {
    let me = results::ThreadSelf {
        thread: k.thread_id(t),
        task: k.task_id(task_of(k, t)),
    };
    k.threads[t].set_results(|r| me.encode_into(r));
    Ok(Next::Return)
}

/// `map` and `map_physical`, which differ only in where the frames come from.
fn map_from(
    k: &mut Kernel,
    t: ThreadIdx,
    r: &ArgRegs,
    need: Abilities,
    from: fn(u64) -> Source,
) -> Handled {
    let task = task_of(k, t);
    k.require(task, need)?;
    let a = args::Map::decode(r);
    let target = k.controlled_task(task, a.task)?;
    k.map(
        task,
        target,
        from(a.source),
        a.destination,
        a.pages,
        rights(a.rights)?,
    )?;
    Ok(Next::Return)
}

fn map(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    map_from(k, t, r, Abilities::MAP, Source::Virtual)
}

fn map_physical(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    map_from(k, t, r, Abilities::PHYSICAL_MEMORY, Source::Physical)
}

fn map_device(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    map_from(k, t, r, Abilities::PHYSICAL_MEMORY, Source::Device)
}

fn pci_config(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let task = task_of(k, t);
    k.require(task, Abilities::PHYSICAL_MEMORY)?;
    if task != TaskIdx::ROOT {
        return Err(Error::NotPermitted);
    }
    let a = args::PciConfig::decode(r);
    if a.address >> 24 != 0 || !a.address.is_multiple_of(4) || a.write > 1 || a.value >> 32 != 0 {
        return Err(Error::InvalidArgument);
    }
    let value = crate::arch::pci::config(a.address as u32, a.value as u32, a.write == 1);
    let result = results::PciConfig {
        value: u64::from(value),
    };
    k.threads[t].set_results(|r| result.encode_into(r));
    Ok(Next::Return)
}

/// The IOMMU, for the root task only.
fn root_dma(k: &mut Kernel, t: ThreadIdx) -> Result<&mut crate::state::Dma, Error> {
    let task = task_of(k, t);
    k.require(task, Abilities::PHYSICAL_MEMORY)?;
    if task != TaskIdx::ROOT {
        return Err(Error::NotPermitted);
    }
    k.dma.as_mut().ok_or(Error::NoSuchObject)
}

fn dma_map(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let a = args::DmaMap::decode(r);
    root_dma(k, t)?;
    if a.source >> 16 != 0 {
        return Err(Error::InvalidArgument);
    }
    if !k.is_user_memory(a.physical, a.pages) {
        return Err(Error::BadAddress);
    }
    let dma = root_dma(k, t)?;
    if !dma.covers(a.source as u16) {
        return Err(Error::NoSuchObject);
    }
    dma.tables.confine(a.source as u16, a.physical, a.pages)?;
    if !dma.unit.invalidate() {
        return Err(Error::OutOfResources);
    }
    let result = results::DmaMap {
        bus_address: a.physical,
    };
    k.threads[t].set_results(|r| result.encode_into(r));
    Ok(Next::Return)
}

fn dma_fault(k: &mut Kernel, t: ThreadIdx, _: &ArgRegs, _: Clock) -> Handled {
    let fault = root_dma(k, t)?.unit.take_fault().ok_or(Error::TimedOut)?;
    let result = results::DmaFault {
        source: u64::from(fault.source),
        address: fault.address,
        reason: u64::from(fault.reason),
        write: u64::from(fault.write),
    };
    k.threads[t].set_results(|r| result.encode_into(r));
    Ok(Next::Return)
}

fn unmap(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let task = task_of(k, t);
    k.require(task, Abilities::MAP)?;
    let a = args::Unmap::decode(r);
    let target = k.controlled_task(task, a.task)?;
    k.unmap(target, a.address, a.pages)?;
    Ok(Next::Return)
}

fn protect(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let task = task_of(k, t);
    k.require(task, Abilities::MAP)?;
    let a = args::Protect::decode(r);
    let target = k.controlled_task(task, a.task)?;
    k.protect(target, a.address, a.pages, rights(a.rights)?)?;
    Ok(Next::Return)
}

/// `send` and `call` (which also waits for the reply); the IPC path sets `rax`.
fn send_message(
    k: &mut Kernel,
    t: ThreadIdx,
    r: &ArgRegs,
    clock: Clock,
    and_wait: bool,
) -> Handled {
    let a = args::Ipc::decode(r);
    let dest = k.thread(a.peer)?;
    if !k.may_send(task_of(k, t), k.threads[dest].task()) {
        return Err(Error::NotPermitted);
    }
    if !MessageTag(a.tag).is_valid() {
        return Err(Error::InvalidArgument);
    }
    k.send(
        t,
        dest,
        and_wait,
        deadline(clock, a.timeout),
        a.timeout == 0,
    );
    Ok(Next::Pending)
}

fn send(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, clock: Clock) -> Handled {
    send_message(k, t, r, clock, false)
}

fn ipc_call(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, clock: Clock) -> Handled {
    send_message(k, t, r, clock, true)
}

fn receive(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, clock: Clock) -> Handled {
    let a = args::Ipc::decode(r);
    let from = match a.peer.named() {
        None => None,
        Some(id) => Some(k.thread(id)?),
    };
    k.receive(t, from, deadline(clock, a.timeout), a.timeout == 0);
    Ok(Next::Pending)
}

/// The reply half of `reply` and `reply_wait` (no caller to answer when the peer is 0).
fn answer_caller(k: &mut Kernel, t: ThreadIdx, a: &args::Ipc) -> Result<(), Error> {
    if !MessageTag(a.tag).is_valid() {
        return Err(Error::InvalidArgument);
    }
    if let Some(peer) = a.peer.named() {
        let caller = k.thread(peer).map_err(|_| Error::NotWaiting)?;
        k.reply(t, caller)?;
    }
    Ok(())
}

fn reply_wait(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, clock: Clock) -> Handled {
    let a = args::Ipc::decode(r);
    answer_caller(k, t, &a)?;
    k.receive(t, None, deadline(clock, a.timeout), a.timeout == 0);
    Ok(Next::Pending)
}

fn reply(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    answer_caller(k, t, &args::Ipc::decode(r))?;
    Ok(Next::Return)
}

fn notify_signal(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let a = args::NotifySignal::decode(r);
    let target = k.thread(a.thread)?;
    if !k.may_notify(task_of(k, t), k.threads[target].task()) {
        return Err(Error::NotPermitted);
    }
    k.signal(target, a.bits);
    Ok(Next::Return)
}

fn notify_wait(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, clock: Clock) -> Handled {
    let a = args::NotifyWait::decode(r);
    k.wait_notify(t, a.mask, deadline(clock, a.timeout), a.timeout == 0);
    Ok(Next::Pending)
}

fn rp_create(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let task = task_of(k, t);
    k.require(task, Abilities::PARTITION_CONTROL)?;
    let a = args::RpCreate::decode(r);
    let rp = k.rp_create(
        task,
        Amount {
            tasks: a.tasks,
            threads: a.threads,
            pages: a.pages,
        },
        a.cpus,
    )?;
    let rp = rp.position() as u64 + 1;
    k.threads[t].set_results(|r| results::RpCreate { rp }.encode_into(r));
    Ok(Next::Return)
}

fn rp_info(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let rp = k.resource_partition(task_of(k, t), args::RpInfo::decode(r).rp)?;
    let (used, quota) = (k.rps[rp].used, k.rps[rp].quota);
    let info = results::RpInfo {
        pages_used: used.pages,
        pages_quota: quota.pages,
        counts: RpCounts {
            threads_used: used.threads as u16,
            threads_quota: quota.threads as u16,
            tasks_used: used.tasks as u16,
            tasks_quota: quota.tasks as u16,
        },
        cpus: k.rps[rp].cpus.into(),
    };
    k.threads[t].set_results(|r| info.encode_into(r));
    Ok(Next::Return)
}

fn set_health_monitor(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let task = task_of(k, t);
    k.require(task, Abilities::PARTITION_CONTROL)?;
    let id = args::SetHealthMonitor::decode(r).thread;
    let monitor = k.thread(id)?;
    if task != TaskIdx::ROOT || k.threads[monitor].task() != TaskIdx::ROOT {
        return Err(Error::NotPermitted);
    }
    k.health_monitor = id;
    Ok(Next::Return)
}

fn schedule_set(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let task = task_of(k, t);
    k.require(task, Abilities::SCHEDULING)?;
    let a = args::ScheduleSet::decode(r);
    if a.slot >= MAX_SCHEDULES || a.count > MAX_WINDOWS {
        return Err(Error::InvalidArgument);
    }
    let mut windows = [Window::default(); MAX_WINDOWS as usize];
    for (i, w) in windows.iter_mut().take(a.count as usize).enumerate() {
        let mut raw = [0u8; WindowSpec::SIZE];
        let at = (a.windows)
            .checked_add((i * WindowSpec::SIZE) as u64)
            .ok_or(Error::BadAddress)?;
        if !k.tasks[task].space().copy_from_user(at, &mut raw) {
            return Err(Error::BadAddress);
        }
        let spec = WindowSpec::from_bytes(&raw);
        *w = Window {
            offset: spec.offset,
            duration: spec.duration,
            partition: u8::try_from(spec.partition).map_err(|_| Error::InvalidArgument)?,
            cpu: u8::try_from(spec.cpu).map_err(|_| Error::InvalidArgument)?,
        };
    }
    let schedule = Schedule::new(a.major_frame, &windows[..a.count as usize], k.online)
        .map_err(|_| Error::InvalidArgument)?;
    k.time
        .install(a.slot as usize, schedule)
        .map_err(|_| Error::NotPermitted)?;
    Ok(Next::Return)
}

fn schedule_switch(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, clock: Clock) -> Handled {
    let now = clock();
    k.require(task_of(k, t), Abilities::SCHEDULING)?;
    let slot = args::ScheduleSwitch::decode(r).slot;
    let at = (slot < MAX_SCHEDULES)
        .then(|| k.time.switch_to(slot as usize, now))
        .flatten()
        .ok_or(Error::InvalidArgument)?;
    for cpu in 0..k.online {
        k.update_window(cpu, now);
    }
    k.threads[t].set_results(|r| results::ScheduleSwitch { at }.encode_into(r));
    Ok(Next::Return)
}

fn partition_info(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, clock: Clock) -> Handled {
    let now = clock();
    let tp = u8::try_from(args::PartitionInfo::decode(r).partition)
        .ok()
        .filter(|&p| (p as u64) < TIME_PARTITIONS)
        .ok_or(Error::InvalidArgument)?;
    let (start, length) = k.time.next_window(tp, now).unwrap_or((u64::MAX, 0));
    let ns = |ticks| crate::time::ticks_to_ns(ticks, crate::time::tsc_hz());
    let (cpu, idle, frames) = (
        ns(k.cpu_ticks[tp as usize]),
        ns(k.core().idle_ticks),
        k.time.frames,
    );
    let info = results::PartitionInfo {
        active: k.core().active_partition.unwrap_or(0) as u64,
        window_start: start,
        window_length: length,
        cpu_ns: cpu,
        idle_ns: idle,
        frames,
    };
    k.threads[t].set_results(|r| info.encode_into(r));
    Ok(Next::Return)
}

fn io_grant(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let task = task_of(k, t);
    k.require(task, Abilities::IO_PORTS)?;
    let a = args::IoGrant::decode(r);
    let target = k.task(a.task)?;
    k.io_grant(task, target, a.first, a.count)?;
    Ok(Next::Return)
}

fn irq_grant(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    let task = task_of(k, t);
    k.require(task, Abilities::IRQ)?;
    let a = args::IrqGrant::decode(r);
    let target = k.task(a.task)?;
    k.irq_grant(task, target, a.line)?;
    Ok(Next::Return)
}

fn irq_attach(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    k.require(task_of(k, t), Abilities::IRQ)?;
    let a = args::IrqAttach::decode(r);
    ok_unless_changed(k, t);
    k.irq_attach(t, a.line, a.bit)?;
    Ok(Next::Pending)
}

fn irq_wait(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, clock: Clock) -> Handled {
    k.require(task_of(k, t), Abilities::IRQ)?;
    let a = args::IrqWait::decode(r);
    ok_unless_changed(k, t);
    k.irq_wait(t, a.line, deadline(clock, a.timeout), a.timeout == 0)?;
    Ok(Next::Pending)
}

fn irq_ack(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    k.require(task_of(k, t), Abilities::IRQ)?;
    ok_unless_changed(k, t);
    k.irq_ack(t, args::IrqLine::decode(r).line)?;
    Ok(Next::Pending)
}

fn irq_detach(k: &mut Kernel, t: ThreadIdx, r: &ArgRegs, _: Clock) -> Handled {
    k.require(task_of(k, t), Abilities::IRQ)?;
    ok_unless_changed(k, t);
    k.irq_detach(t, args::IrqLine::decode(r).line)?;
    Ok(Next::Pending)
}

fn set_attribute(
    k: &mut Kernel,
    caller_task: TaskIdx,
    target: ThreadIdx,
    attribute: u64,
    value: u64,
) -> Result<(), Error> {
    let handler = ThreadId(value);
    match ThreadAttribute::from_code(attribute).ok_or(Error::InvalidArgument)? {
        ThreadAttribute::Priority => {
            let priority = u8::try_from(value).map_err(|_| Error::McpExceeded)?;
            k.set_priority(target, priority)
        }
        ThreadAttribute::ExceptionHandler => {
            if let Some(handler) = handler.named() {
                let handler = k.thread(handler)?;
                if !k.is_within(k.threads[target].task(), k.threads[handler].task()) {
                    return Err(Error::NotPermitted);
                }
            }
            k.threads[target].set_exception_handler(handler);
            Ok(())
        }
        ThreadAttribute::IpcBuffer => {
            let space = k.tasks[k.threads[target].task()].space();
            if value != 0
                && (!value.is_multiple_of(8) || !space.accessible(value, IPC_BUFFER_SIZE, true))
            {
                return Err(Error::BadAddress);
            }
            k.threads[target].set_ipc_buffer(value);
            Ok(())
        }
        ThreadAttribute::FsBase | ThreadAttribute::GsBase => {
            if value >= USER_END {
                return Err(Error::InvalidArgument);
            }
            let fs = attribute == ThreadAttribute::FsBase as u64;
            k.threads[target].set_base(fs, value);
            for core in k.cores.iter_mut().filter(|c| c.current == Some(target)) {
                core.reload_bases = true;
            }
            Ok(())
        }
        ThreadAttribute::SyscallAnswer => {
            k.threads[target].set_syscall_answer(value);
            Ok(())
        }
        ThreadAttribute::TimePartition => {
            k.require(caller_task, Abilities::SCHEDULING)?;
            k.set_time_partition(
                target,
                u8::try_from(value).map_err(|_| Error::InvalidArgument)?,
            )
        }
        ThreadAttribute::Cpu => k.set_cpu(target, value),
        ThreadAttribute::FollowsCallers => {
            k.threads[target].follows_callers = match value {
                0 | 1 => value == 1,
                _ => return Err(Error::InvalidArgument),
            };
            Ok(())
        }
    }
}
