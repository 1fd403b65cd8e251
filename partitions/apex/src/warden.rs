//! [`Warden`]: the a653rs APEX traits implemented on the Warden kernel and syssw.

use crate::codes::{self, id_word, name_bytes};
use crate::intra::{Caller, Intra, Step};
use crate::runtime::{
    self, Critical, OBJECT_BIT, WAKE_BIT, apply_intra, own_index, own_slot, request, request_code,
    request_words,
};
use crate::table::{self, ERROR_HANDLER_SLOT, MAX_PROCESSES, Wait};
use crate::time::{self, finite, protocol_timeout};
use a653rs::bindings::*;
use protocol::{
    Discipline, MAX_MESSAGE_SIZE, PART_MAX, PortIdReply, PortKind, QueuingMessage, ReplyWords,
    Request, SamplingMessage,
};
use user_rt::abi::syscall::{ThreadAttribute, ThreadId};
use user_rt::sys;

/// The APEX implementation partition programs name as a653rs's hypervisor type
/// (`impl Partition<Warden> for MyPartition`, `Process<Warden>`, ...).
#[derive(Debug, Clone, Copy, Default)]
pub struct Warden;

type Result<T> = core::result::Result<T, ErrorReturnCode>;

impl ApexLimits for Warden {
    const SYSTEM_LIMIT_NUMBER_OF_PROCESSES: ApexUnsigned = MAX_PROCESSES as ApexUnsigned;
    const SYSTEM_LIMIT_MESSAGE_SIZE: MessageSize = MAX_MESSAGE_SIZE as MessageSize;
    const SYSTEM_LIMIT_NUMBER_OF_MESSAGES: MessageRange = 256;
}

// ---------------------------------------------------------------- partition (3.2.2)

impl ApexPartitionP4 for Warden {
    fn get_partition_status() -> ApexPartitionStatus {
        // ARINC: never fails. Should syssw not answer, the runtime's own view is reported.
        let (mode, start_condition, identifier, period, duration) =
            match runtime::partition_status() {
                Ok(status) => (
                    u32::from(status.mode.code()),
                    u32::from(status.start_condition.code()),
                    status.index as i64,
                    status.period_ns as i64,
                    status.duration_ns as i64,
                ),
                Err(_) => {
                    let normal = Critical::enter().table().normal;
                    let mode = if normal { 3 } else { 1 };
                    (mode, 0, runtime::partition_index() as i64, 0, 0)
                }
            };
        ApexPartitionStatus {
            period,
            duration,
            identifier,
            lock_level: Critical::enter().parts().1.lock_level(),
            operating_mode: OperatingMode::try_from(mode).unwrap_or(OperatingMode::Idle),
            start_condition: StartCondition::try_from(start_condition)
                .unwrap_or(StartCondition::NormalStart),
            num_assigned_cores: 1,
        }
    }

    fn set_partition_mode(operating_mode: OperatingMode) -> Result<()> {
        // IDLE and restarts get no reply when syssw carries them out: this thread is gone.
        let mode = codes::mode(operating_mode).ok_or(ErrorReturnCode::InvalidParam)?;
        request_code(&Request::SetPartitionMode { mode })?;
        if operating_mode != OperatingMode::Normal {
            return Ok(());
        }
        let main = own_index() == Some(runtime::MAIN);
        let mut critical = Critical::enter();
        runtime::begin_normal(critical.table());
        if main {
            // ARINC: initialisation ends with the switch to NORMAL.
            critical.exit()
        }
        Ok(())
    }
}

// ---------------------------------------------------------------- processes (3.3.2)

impl ApexProcessP4 for Warden {
    fn create_process(attributes: &ApexProcessAttribute) -> Result<ProcessId> {
        let mut critical = Critical::enter();
        let table = critical.table();
        match time::a653rs_linux_period(
            attributes.period,
            table.partition_period,
            runtime::zero_period_is_partition_period(),
        ) {
            Some(period) => table.create(&ApexProcessAttribute {
                period,
                ..attributes.clone()
            }),
            None => table.create(attributes),
        }
    }

    fn start(process_id: ProcessId) -> Result<()> {
        Self::delayed_start(process_id, 0)
    }
}

impl ApexProcessP1 for Warden {
    fn set_priority(process_id: ProcessId, priority: Priority) -> Result<()> {
        let caller = own_slot();
        let mut critical = Critical::enter();
        let (table, intra) = critical.parts();
        let slot = table.slot(process_id)?;
        let current = table.current_priority(Some(slot));
        let thread = table.set_priority(slot, priority)?;
        if intra.set_retained_priority(slot, priority as u8) {
            // A mutex owner keeps the mutex's priority; the new one is what it gets back.
            table.set_current_priority(slot, current);
            return Ok(());
        }
        // The caller's own new priority takes effect when it leaves the critical section
        // (lowering it inside would let others preempt the lock holder).
        if let Some(thread) = thread
            && Some(slot) != caller
        {
            runtime::note_own_priority(slot, priority as u8);
            let _ = sys::thread_set(
                Some(ThreadId(thread)),
                ThreadAttribute::Priority,
                priority as u64,
            );
        }
        Ok(())
    }

    fn suspend_self(time_out: ApexSystemTime) -> Result<()> {
        let slot = own_slot().ok_or(ErrorReturnCode::InvalidMode)?;
        {
            let mut critical = Critical::enter();
            let (table, intra) = critical.parts();
            if intra.owns_a_mutex(slot) {
                return Err(ErrorReturnCode::InvalidMode);
            }
            if !table.suspend_self(slot, time_out)? {
                return Ok(());
            }
        }
        let woken = sys::notify_wait(WAKE_BIT, protocol_timeout(time_out)).is_ok();
        let (result, stale_wake) = Critical::enter().table().suspend_self_end(slot, woken);
        if stale_wake {
            let _ = sys::notify_wait(WAKE_BIT, 0);
        }
        result
    }

    fn suspend(process_id: ProcessId) -> Result<()> {
        let caller = own_slot();
        let mut critical = Critical::enter();
        let (table, intra) = critical.parts();
        let slot = table.slot(process_id)?;
        // The owner of a mutex (or of the preemption lock) may not be suspended; asking it
        // of itself or of the error handler stays INVALID_PARAM (`Table::suspend`).
        if Some(slot) != caller && slot != ERROR_HANDLER_SLOT && intra.owns_a_mutex(slot) {
            return Err(ErrorReturnCode::InvalidMode);
        }
        let thread = table.suspend(slot, caller)?;
        // Not inside the heap, which the others would wait for.
        crate::heap::leave(thread);
        let _ = sys::thread_suspend(ThreadId(thread));
        Ok(())
    }

    fn resume(process_id: ProcessId) -> Result<()> {
        let mut critical = Critical::enter();
        let table = critical.table();
        let slot = table.slot(process_id)?;
        let resume = table.resume(slot)?;
        if resume.kernel_resume {
            let _ = sys::thread_resume(ThreadId(resume.thread));
        }
        if resume.notify {
            let _ = sys::notify_signal(ThreadId(resume.thread), WAKE_BIT);
        }
        Ok(())
    }

    fn stop_self() {
        runtime::stop_self()
    }

    fn stop(process_id: ProcessId) -> Result<()> {
        let caller = own_slot();
        let mut critical = Critical::enter();
        let slot = critical.table().slot(process_id)?;
        if Some(slot) == caller {
            drop(critical);
            runtime::stop_self()
        }
        let (table, intra) = critical.parts();
        if let Some(thread) = table.stop(slot)? {
            // Not inside the heap, which would stay taken.
            crate::heap::leave(thread);
            let _ = sys::thread_kill(ThreadId(thread));
        }
        intra.forget(slot);
        apply_intra(table, intra, caller);
        runtime::forget_thread(slot);
        Ok(())
    }

    fn delayed_start(process_id: ProcessId, delay_time: ApexSystemTime) -> Result<()> {
        let mut critical = Critical::enter();
        let table = critical.table();
        let slot = table.check_start(process_id, delay_time)?;
        let delay = finite(delay_time).unwrap_or(0);
        if !table.normal {
            return runtime::prepare(table, slot, delay);
        }
        let now = sys::clock();
        let periodic = table.get(slot).is_some_and(|p| p.periodic().is_some());
        let point = if periodic {
            runtime::release_point(now, table.partition_period)
        } else {
            now
        };
        let release = time::first_release(periodic, now, point, delay);
        runtime::ensure_watchdog(table)?;
        runtime::launch(table, slot, release)
    }

    /// The owner runs above every process of the partition while the level is above 0
    /// (`Intra::lock_preemption`); its priority is set when it leaves the critical section.
    fn lock_preemption() -> Result<LockLevel> {
        with_intra(|intra, c| intra.lock_preemption(c.caller, c.normal, c.mcp))
    }

    /// At level 0 the caller drops to its retained priority on leaving the critical section,
    /// and a higher-priority process that became ready meanwhile runs at once.
    fn unlock_preemption() -> Result<LockLevel> {
        with_intra(|intra, c| intra.unlock_preemption(c.caller, c.normal))
    }

    /// INVALID_MODE for the initialisation thread and the watchdog (they are no processes).
    fn get_my_id() -> Result<ProcessId> {
        own_slot()
            .map(table::id_of)
            .ok_or(ErrorReturnCode::InvalidMode)
    }

    fn get_process_id(process_name: ProcessName) -> Result<ProcessId> {
        Critical::enter().table().find(name_bytes(&process_name))
    }

    fn get_process_status(process_id: ProcessId) -> Result<ApexProcessStatus> {
        let caller = own_slot();
        let mut critical = Critical::enter();
        let table = critical.table();
        let slot = table.slot(process_id)?;
        table.status(slot, caller)
    }

    /// One core: only "no preference" and core 0 are valid, during initialisation.
    fn initialize_process_core_affinity(
        process_id: ProcessId,
        processor_core_id: ProcessorCoreId,
    ) -> Result<()> {
        let mut critical = Critical::enter();
        let table = critical.table();
        table.slot(process_id)?;
        if table.normal {
            return Err(ErrorReturnCode::InvalidMode);
        }
        if processor_core_id != CORE_AFFINITY_NO_PREFERENCE && processor_core_id != 0 {
            return Err(ErrorReturnCode::InvalidConfig);
        }
        Ok(())
    }

    fn get_my_processor_core_id() -> ProcessorCoreId {
        0
    }

    fn get_my_index() -> Result<ProcessIndex> {
        own_slot()
            .map(|slot| slot as ProcessIndex)
            .ok_or(ErrorReturnCode::InvalidMode)
    }
}

// ---------------------------------------------------------------- time (3.4.2)

impl ApexTimeP4 for Warden {
    fn periodic_wait() -> Result<()> {
        let slot = own_slot().ok_or(ErrorReturnCode::InvalidMode)?;
        let release = {
            let mut critical = Critical::enter();
            let (table, intra) = critical.parts();
            if intra.owns_a_mutex(slot) {
                return Err(ErrorReturnCode::InvalidMode);
            }
            let release = table.periodic_wait(slot)?;
            runtime::poke_watchdog(table);
            release
        };
        sys::sleep_until(release);
        Critical::enter().table().released(slot);
        Ok(())
    }

    fn get_time() -> ApexSystemTime {
        i64::try_from(sys::clock()).unwrap_or(i64::MAX)
    }
}

impl ApexTimeP1 for Warden {
    fn timed_wait(delay_time: ApexSystemTime) -> Result<()> {
        let slot = own_slot();
        if may_not_wait(slot) {
            return Err(ErrorReturnCode::InvalidMode);
        }
        let delay = finite(delay_time).ok_or(ErrorReturnCode::InvalidParam)?;
        if delay == 0 {
            // ARINC: a zero delay moves the caller behind its equal-priority peers.
            sys::yield_now();
            return Ok(());
        }
        let until = sys::clock().saturating_add(delay);
        with_wait(slot, Wait::Delay, || sys::sleep_until(until));
        Ok(())
    }

    fn replenish(budget_time: ApexSystemTime) -> Result<()> {
        let slot = own_slot().ok_or(ErrorReturnCode::NoAction)?;
        let mut critical = Critical::enter();
        let table = critical.table();
        table.replenish(slot, budget_time, sys::clock())?;
        runtime::poke_watchdog(table);
        Ok(())
    }
}

/// ARINC's "the current process is the error handler, or preemption is locked, or it owns
/// a mutex": a caller that may not wait (INVALID_MODE). Takes the runtime lock.
fn may_not_wait(slot: Option<usize>) -> bool {
    slot == Some(ERROR_HANDLER_SLOT)
        || slot.is_some_and(|slot| Critical::enter().parts().1.owns_a_mutex(slot))
}

/// Runs `wait` with the calling process marked as waiting (ARINC state WAITING).
fn with_wait<R>(slot: Option<usize>, wait: Wait, f: impl FnOnce() -> R) -> R {
    if let Some(slot) = slot {
        Critical::enter().table().set_wait(slot, wait);
    }
    let result = f();
    if let Some(slot) = slot {
        Critical::enter().table().set_wait(slot, Wait::None);
    }
    result
}

// ---------------------------------------------------------------- ports (3.6.2)

/// A message a port can carry (longer ones exceed every port: INVALID_CONFIG).
fn check_message(message: &[ApexByte]) -> Result<()> {
    if message.len() > MAX_MESSAGE_SIZE as usize {
        return Err(ErrorReturnCode::InvalidConfig);
    }
    Ok(())
}

impl ApexSamplingPortP4 for Warden {
    fn create_sampling_port(
        sampling_port_name: SamplingPortName,
        max_message_size: MessageSize,
        port_direction: PortDirection,
        refresh_period: ApexSystemTime,
    ) -> Result<SamplingPortId> {
        // A source has no refresh period (a653rs passes a dummy one): the protocol's 0.
        let refresh = match port_direction {
            PortDirection::Source => 0,
            PortDirection::Destination => {
                finite(refresh_period).ok_or(ErrorReturnCode::InvalidConfig)?
            }
        };
        let reply: PortIdReply = request_words(&Request::CreatePort {
            kind: PortKind::Sampling,
            direction: codes::direction(port_direction),
            discipline: Discipline::Fifo,
            max_message_size: u64::from(max_message_size),
            refresh_or_depth: refresh,
            name: name_bytes(&sampling_port_name),
        })?;
        Ok(reply.port as SamplingPortId)
    }

    fn write_sampling_message(
        sampling_port_id: SamplingPortId,
        message: &[ApexByte],
    ) -> Result<()> {
        check_message(message)?;
        let port = id_word(sampling_port_id)?;
        let reply = runtime::long_transfer(message.len() > PART_MAX, || {
            runtime::request_message(message, |staged, message| Request::WriteSampling {
                port,
                staged,
                message,
            })
        })?;
        codes::from_reply(reply.label)?;
        Ok(())
    }

    /// # Safety
    /// None beyond a653rs's contract: at most `message.len()` bytes are written; a longer
    /// message is refused with INVALID_PARAM.
    #[allow(unsafe_code)] // a653rs declares the method unsafe; its body needs no unsafe
    unsafe fn read_sampling_message(
        sampling_port_id: SamplingPortId,
        message: &mut [ApexByte],
    ) -> Result<(Validity, MessageSize)> {
        let port = id_word(sampling_port_id)?;
        runtime::long_transfer(message.len() > PART_MAX, || {
            let (reply, _) = request(&Request::ReadSampling { port })?;
            codes::from_reply(reply.label)?;
            let sample = SamplingMessage::from_words(reply.words)
                .map_err(|_| ErrorReturnCode::NotAvailable)?;
            let length = sample.len as usize;
            runtime::receive_message(length, message)?;
            Ok((codes::validity(sample.validity), length as MessageSize))
        })
    }
}

impl ApexSamplingPortP1 for Warden {
    fn get_sampling_port_id(sampling_port_name: SamplingPortName) -> Result<SamplingPortId> {
        let reply: PortIdReply = request_words(&Request::PortId {
            kind: PortKind::Sampling,
            name: name_bytes(&sampling_port_name),
        })?;
        Ok(reply.port as SamplingPortId)
    }

    fn get_sampling_port_status(
        sampling_port_id: SamplingPortId,
    ) -> Result<ApexSamplingPortStatus> {
        let status: protocol::SamplingStatus = request_words(&Request::SamplingStatus {
            port: id_word(sampling_port_id)?,
        })?;
        Ok(ApexSamplingPortStatus {
            refresh_period: i64::try_from(status.refresh_period).unwrap_or(INFINITE_TIME_VALUE),
            max_message_size: status.max_message_size,
            port_direction: codes::port_direction(status.direction),
            last_msg_validity: codes::validity(status.last_msg_validity),
        })
    }
}

/// Queuing-port calls that may block: not from the error handler or while preemption is
/// locked (ARINC), and the caller shows as WAITING meanwhile.
fn blocking_port_call<R>(time_out: ApexSystemTime, f: impl FnOnce() -> R) -> Result<R> {
    let slot = own_slot();
    if time_out == 0 {
        return Ok(f());
    }
    if may_not_wait(slot) {
        return Err(ErrorReturnCode::InvalidMode);
    }
    Ok(with_wait(slot, Wait::Port, f))
}

/// The caller's current priority, its place among the processes waiting on a PRIORITY
/// queuing port (syssw keeps those queues).
fn own_priority() -> u8 {
    Critical::enter().table().current_priority(own_slot())
}

impl ApexQueuingPortP4 for Warden {
    /// The discipline must be the port's configured one (INVALID_CONFIG otherwise); syssw
    /// serves the port's waiting processes by it.
    fn create_queuing_port(
        queuing_port_name: QueuingPortName,
        max_message_size: MessageSize,
        max_nb_message: MessageRange,
        port_direction: PortDirection,
        queuing_discipline: QueuingDiscipline,
    ) -> Result<QueuingPortId> {
        let reply: PortIdReply = request_words(&Request::CreatePort {
            kind: PortKind::Queuing,
            direction: codes::direction(port_direction),
            discipline: codes::discipline(queuing_discipline),
            max_message_size: u64::from(max_message_size),
            refresh_or_depth: u64::from(max_nb_message),
            name: name_bytes(&queuing_port_name),
        })?;
        Ok(reply.port as QueuingPortId)
    }

    fn send_queuing_message(
        queuing_port_id: QueuingPortId,
        message: &[ApexByte],
        time_out: ApexSystemTime,
    ) -> Result<()> {
        check_message(message)?;
        let id = id_word(queuing_port_id)?;
        let priority = own_priority();
        let reply = blocking_port_call(time_out, || {
            runtime::long_transfer(message.len() > PART_MAX, || {
                runtime::request_message(message, |staged, message| Request::SendQueuing {
                    port: id,
                    timeout: protocol_timeout(time_out),
                    priority,
                    staged,
                    message,
                })
            })
        })??;
        codes::from_reply(reply.label)?;
        Ok(())
    }

    /// # Safety
    /// None beyond a653rs's contract: at most `message.len()` bytes are written. A message
    /// longer than the buffer is refused with INVALID_PARAM (it has left the queue then).
    /// syssw does not report sender-side overflow, so `QueueOverflow` is always `false`.
    #[allow(unsafe_code)] // a653rs declares the method unsafe; its body needs no unsafe
    unsafe fn receive_queuing_message(
        queuing_port_id: QueuingPortId,
        time_out: ApexSystemTime,
        message: &mut [ApexByte],
    ) -> Result<(MessageSize, QueueOverflow)> {
        let id = id_word(queuing_port_id)?;
        let priority = own_priority();
        let length = blocking_port_call(time_out, || {
            runtime::long_transfer(message.len() > PART_MAX, || {
                let (reply, _) = request(&Request::ReceiveQueuing {
                    port: id,
                    timeout: protocol_timeout(time_out),
                    priority,
                })?;
                codes::from_reply(reply.label)?;
                let received = QueuingMessage::from_words(reply.words)
                    .map_err(|_| ErrorReturnCode::NotAvailable)?;
                let length = received.len as usize;
                runtime::receive_message(length, message)?;
                Ok(length)
            })
        })??;
        Ok((length as MessageSize, false))
    }

    fn get_queuing_port_status(queuing_port_id: QueuingPortId) -> Result<QueuingPortStatus> {
        let status: protocol::QueuingStatus = request_words(&Request::QueuingStatus {
            port: id_word(queuing_port_id)?,
        })?;
        Ok(QueuingPortStatus {
            nb_message: status.nb_message,
            max_nb_message: status.max_nb_message,
            max_message_size: status.max_message_size,
            port_direction: codes::port_direction(status.direction),
            waiting_processes: i32::try_from(status.waiting_processes).unwrap_or(i32::MAX),
        })
    }

    fn clear_queuing_port(queuing_port_id: QueuingPortId) -> Result<()> {
        request_code(&Request::ClearQueuing {
            port: id_word(queuing_port_id)?,
        })?;
        Ok(())
    }
}

impl ApexQueuingPortP1 for Warden {
    fn get_queuing_port_id(queuing_port_name: QueuingPortName) -> Result<QueuingPortId> {
        let reply: PortIdReply = request_words(&Request::PortId {
            kind: PortKind::Queuing,
            name: name_bytes(&queuing_port_name),
        })?;
        Ok(reply.port as QueuingPortId)
    }
}

// ---------------------------------------------------------------- module schedules (Part 2, 3.4)

/// Schedule ids are the schedules' indexes in the configuration; syssw keeps the status
/// and lets only a partition with `schedule_control` switch (INVALID_CONFIG otherwise). The
/// switch takes effect at the end of the running major frame.
impl ApexScheduleP2 for Warden {
    fn set_module_schedule(schedule_id: ScheduleId) -> Result<()> {
        let schedule = u64::try_from(schedule_id).map_err(|_| ErrorReturnCode::InvalidParam)?;
        request_code(&Request::SetModuleSchedule { schedule })?;
        Ok(())
    }

    fn get_module_schedule_status() -> Result<ApexScheduleStatus> {
        let status: protocol::ScheduleStatus = request_words(&Request::ModuleScheduleStatus)?;
        let id = |index: u64| ScheduleId::try_from(index).unwrap_or(ScheduleId::MAX);
        Ok(ApexScheduleStatus {
            time_of_last_schedule_switch: i64::try_from(status.last_switch).unwrap_or(i64::MAX),
            current_schedule: id(status.current),
            next_schedule: id(status.next),
        })
    }

    fn get_module_schedule_id(schedule_name: ScheduleName) -> Result<ScheduleId> {
        let reply: protocol::ScheduleIdReply = request_words(&Request::ModuleScheduleId {
            name: name_bytes(&schedule_name),
        })?;
        ScheduleId::try_from(reply.schedule).map_err(|_| ErrorReturnCode::InvalidConfig)
    }
}

// ---------------------------------------------------------------- health monitoring (3.8.2)

impl ApexErrorP4 for Warden {
    fn report_application_message(message: &[ApexByte]) -> Result<()> {
        if message.len() > MAX_ERROR_MESSAGE_SIZE {
            return Err(ErrorReturnCode::InvalidParam);
        }
        request_code(&Request::ApplicationMessage { text: message })?;
        Ok(())
    }

    fn raise_application_error(error_code: ErrorCode, message: &[ApexByte]) -> Result<()> {
        if error_code != ErrorCode::ApplicationError || message.len() > MAX_ERROR_MESSAGE_SIZE {
            return Err(ErrorReturnCode::InvalidParam);
        }
        runtime::raise(error_code, own_slot(), message)
    }
}

/// The address GET_ERROR_STATUS names for an error outside any process entry point.
extern "C" fn no_process() {}

impl ApexErrorP1 for Warden {
    fn create_error_handler(entry_point: SystemAddress, stack_size: StackSize) -> Result<()> {
        Critical::enter()
            .table()
            .create_error_handler(entry_point, stack_size)
    }

    fn get_error_status() -> Result<ErrorStatus> {
        let caller = own_slot();
        let mut critical = Critical::enter();
        let table = critical.table();
        let error = table.pop_error(caller)?;
        let failed_address = table::slot_of(error.process)
            .and_then(|slot| table.get(slot))
            .map_or(no_process as SystemAddress, |p| p.attributes.entry_point);
        Ok(ErrorStatus {
            failed_address,
            failed_process_id: error.process,
            error_code: error.code,
            length: error.length as ErrorMessageSize,
            message: error.message,
        })
    }

    /// Only PROCESSES_SCHEDULED on core 0 (or no preference): the error handler is a
    /// thread at the top priority of the partition, other processes are not paused.
    fn configure_error_handler(
        concurrency_control: ErrorHandlerConcurrencyControl,
        processor_core_id: ProcessorCoreId,
    ) -> Result<()> {
        let mut critical = Critical::enter();
        let table = critical.table();
        if !table.has_error_handler() {
            return Err(ErrorReturnCode::InvalidConfig);
        }
        if table.normal {
            return Err(ErrorReturnCode::InvalidMode);
        }
        if concurrency_control != ErrorHandlerConcurrencyControl::ProcessesScheduled
            || (processor_core_id != CORE_AFFINITY_NO_PREFERENCE && processor_core_id != 0)
        {
            return Err(ErrorReturnCode::InvalidConfig);
        }
        Ok(())
    }
}

// ---------------------------------------------------------------- intra-partition (3.7.2)

/// What the intra-partition services need to know of the caller and the partition.
struct Context {
    caller: Caller,
    normal: bool,
    mcp: u8,
}

/// A service on the intra-partition objects that does not wait.
fn with_intra<R>(f: impl FnOnce(&mut Intra, Context) -> R) -> R {
    let slot = own_slot();
    let mut critical = Critical::enter();
    let (table, intra) = critical.parts();
    let context = Context {
        caller: Caller {
            slot,
            priority: table.current_priority(slot),
        },
        normal: table.normal,
        mcp: table.mcp,
    };
    let result = f(intra, context);
    apply_intra(table, intra, slot);
    result
}

/// A service that may wait: `start` runs under the runtime lock; if it queued the caller,
/// the caller's thread waits (outside the lock) for OBJECT_BIT until `time_out` has passed,
/// then collects the outcome the waker decided, or TIMED_OUT. `woken` turns a waker's
/// outcome (a message length) into the result, copying the mailbox into `out`.
fn blocking<T>(
    time_out: ApexSystemTime,
    out: &mut [u8],
    start: impl FnOnce(&mut Intra, Caller, &mut [u8]) -> Result<Step<T>>,
    woken: impl FnOnce(&Intra, usize, usize, &mut [u8]) -> T,
) -> Result<T> {
    let slot = own_slot();
    let deadline = finite(time_out).map(|t| sys::clock().saturating_add(t));
    {
        let mut critical = Critical::enter();
        let (table, intra) = critical.parts();
        let caller = Caller {
            slot,
            priority: table.current_priority(slot),
        };
        let step = start(intra, caller, out);
        apply_intra(table, intra, slot);
        match (step?, slot) {
            (Step::Done(value), _) => return Ok(value),
            (Step::Wait, Some(slot)) => table.set_wait(slot, Wait::Object),
            (Step::Wait, None) => unreachable!("only processes are queued"),
        }
    }
    let slot = slot.expect("a queued process");
    loop {
        let timeout = deadline.map_or(time::PROTOCOL_FOREVER, |d| d.saturating_sub(sys::clock()));
        let notified = timeout != 0 && sys::notify_wait(OBJECT_BIT, timeout).is_ok();
        let mut critical = Critical::enter();
        let (table, intra) = critical.parts();
        let expired = deadline.is_some_and(|d| sys::clock() >= d);
        if let Some(outcome) = intra.end_wait(slot, expired) {
            table.set_wait(slot, Wait::None);
            let result = outcome.map(|length| woken(intra, slot, length, out));
            drop(critical);
            if !notified && result.is_ok() {
                // The wake raced with the time-out: its notification is still pending.
                let _ = sys::notify_wait(OBJECT_BIT, 0);
            }
            return result;
        }
    }
}

/// A service that may wait and whose wait ends with nothing to hand over (SEND_BUFFER,
/// WAIT_SEMAPHORE, WAIT_EVENT, ACQUIRE_MUTEX).
fn blocking_unit(
    time_out: ApexSystemTime,
    start: impl FnOnce(&mut Intra, Caller) -> Result<Step<()>>,
) -> Result<()> {
    blocking(
        time_out,
        &mut [],
        |intra, caller, _| start(intra, caller),
        |_, _, _, _| (),
    )
}

/// A read that may wait (RECEIVE_BUFFER, READ_BLACKBOARD): the message lands in `out`,
/// read at once or handed over through the waiter's mailbox.
fn blocking_read(
    time_out: ApexSystemTime,
    out: &mut [u8],
    start: impl FnOnce(&mut Intra, Caller, &mut [u8]) -> Result<Step<usize>>,
) -> Result<MessageSize> {
    let take_mail = |intra: &Intra, slot, length: usize, out: &mut [u8]| {
        out[..length].copy_from_slice(intra.mail(slot));
        length
    };
    blocking(time_out, out, start, take_mail).map(|length| length as MessageSize)
}

impl ApexBufferP1 for Warden {
    fn create_buffer(
        buffer_name: BufferName,
        max_message_size: MessageSize,
        max_nb_message: MessageRange,
        queuing_discipline: QueuingDiscipline,
    ) -> Result<BufferId> {
        with_intra(|intra, c| {
            intra.create_buffer(
                c.normal,
                buffer_name,
                max_message_size,
                max_nb_message,
                queuing_discipline,
            )
        })
    }

    fn send_buffer(
        buffer_id: BufferId,
        message: &[ApexByte],
        time_out: ApexSystemTime,
    ) -> Result<()> {
        blocking_unit(time_out, |intra, caller| {
            intra.send_buffer(caller, buffer_id, message, time_out)
        })
    }

    /// # Safety
    /// None beyond a653rs's contract: at most `message.len()` bytes are written; a buffer
    /// shorter than the buffer's MAX_MESSAGE_SIZE is refused with INVALID_PARAM.
    #[allow(unsafe_code)] // a653rs declares the method unsafe; its body needs no unsafe
    unsafe fn receive_buffer(
        buffer_id: BufferId,
        time_out: ApexSystemTime,
        message: &mut [ApexByte],
    ) -> Result<MessageSize> {
        blocking_read(time_out, message, |intra, caller, out| {
            intra.receive_buffer(caller, buffer_id, time_out, out)
        })
    }

    fn get_buffer_id(buffer_name: BufferName) -> Result<BufferId> {
        with_intra(|intra, _| intra.get_buffer_id(&buffer_name))
    }

    fn get_buffer_status(buffer_id: BufferId) -> Result<BufferStatus> {
        with_intra(|intra, _| intra.get_buffer_status(buffer_id))
    }
}

impl ApexBlackboardP1 for Warden {
    fn create_blackboard(
        blackboard_name: BlackboardName,
        max_message_size: MessageSize,
    ) -> Result<BlackboardId> {
        with_intra(|intra, c| intra.create_blackboard(c.normal, blackboard_name, max_message_size))
    }

    fn display_blackboard(blackboard_id: BlackboardId, message: &[ApexByte]) -> Result<()> {
        with_intra(|intra, _| intra.display_blackboard(blackboard_id, message))
    }

    /// # Safety
    /// None beyond a653rs's contract: at most `message.len()` bytes are written; a buffer
    /// shorter than the blackboard's MAX_MESSAGE_SIZE is refused with INVALID_PARAM.
    #[allow(unsafe_code)] // a653rs declares the method unsafe; its body needs no unsafe
    unsafe fn read_blackboard(
        blackboard_id: BlackboardId,
        time_out: ApexSystemTime,
        message: &mut [ApexByte],
    ) -> Result<MessageSize> {
        blocking_read(time_out, message, |intra, caller, out| {
            intra.read_blackboard(caller, blackboard_id, time_out, out)
        })
    }

    fn clear_blackboard(blackboard_id: BlackboardId) -> Result<()> {
        with_intra(|intra, _| intra.clear_blackboard(blackboard_id))
    }

    fn get_blackboard_id(blackboard_name: BlackboardName) -> Result<BlackboardId> {
        with_intra(|intra, _| intra.get_blackboard_id(&blackboard_name))
    }

    fn get_blackboard_status(blackboard_id: BlackboardId) -> Result<BlackboardStatus> {
        with_intra(|intra, _| intra.get_blackboard_status(blackboard_id))
    }
}

impl ApexSemaphoreP1 for Warden {
    fn create_semaphore(
        semaphore_name: SemaphoreName,
        current_value: SemaphoreValue,
        maximum_value: SemaphoreValue,
        queuing_discipline: QueuingDiscipline,
    ) -> Result<SemaphoreId> {
        with_intra(|intra, c| {
            intra.create_semaphore(
                c.normal,
                semaphore_name,
                current_value,
                maximum_value,
                queuing_discipline,
            )
        })
    }

    fn wait_semaphore(semaphore_id: SemaphoreId, time_out: ApexSystemTime) -> Result<()> {
        blocking_unit(time_out, |intra, caller| {
            intra.wait_semaphore(caller, semaphore_id, time_out)
        })
    }

    fn signal_semaphore(semaphore_id: SemaphoreId) -> Result<()> {
        with_intra(|intra, _| intra.signal_semaphore(semaphore_id))
    }

    fn get_semaphore_id(semaphore_name: SemaphoreName) -> Result<SemaphoreId> {
        with_intra(|intra, _| intra.get_semaphore_id(&semaphore_name))
    }

    fn get_semaphore_status(semaphore_id: SemaphoreId) -> Result<SemaphoreStatus> {
        with_intra(|intra, _| intra.get_semaphore_status(semaphore_id))
    }
}

impl ApexEventP1 for Warden {
    fn create_event(event_name: EventName) -> Result<EventId> {
        with_intra(|intra, c| intra.create_event(c.normal, event_name))
    }

    fn set_event(event_id: EventId) -> Result<()> {
        with_intra(|intra, _| intra.set_event(event_id))
    }

    fn reset_event(event_id: EventId) -> Result<()> {
        with_intra(|intra, _| intra.reset_event(event_id))
    }

    fn wait_event(event_id: EventId, time_out: ApexSystemTime) -> Result<()> {
        blocking_unit(time_out, |intra, caller| {
            intra.wait_event(caller, event_id, time_out)
        })
    }

    fn get_event_id(event_name: EventName) -> Result<EventId> {
        with_intra(|intra, _| intra.get_event_id(&event_name))
    }

    fn get_event_status(event_id: EventId) -> Result<EventStatus> {
        with_intra(|intra, _| intra.get_event_status(event_id))
    }
}

impl ApexMutexP1 for Warden {
    fn create_mutex(
        mutex_name: MutexName,
        mutex_priority: Priority,
        queuing_discipline: QueuingDiscipline,
    ) -> Result<MutexId> {
        with_intra(|intra, c| {
            intra.create_mutex(
                c.normal,
                c.mcp,
                mutex_name,
                mutex_priority,
                queuing_discipline,
            )
        })
    }

    fn acquire_mutex(mutex_id: MutexId, time_out: ApexSystemTime) -> Result<()> {
        blocking_unit(time_out, |intra, caller| {
            intra.acquire_mutex(caller, mutex_id, time_out)
        })
    }

    fn release_mutex(mutex_id: MutexId) -> Result<()> {
        with_intra(|intra, c| intra.release_mutex(c.caller, mutex_id))
    }

    fn reset_mutex(mutex_id: MutexId, process_id: ProcessId) -> Result<()> {
        let caller = own_slot();
        let mut critical = Critical::enter();
        let (table, intra) = critical.parts();
        let slot = table.slot(process_id)?;
        let result = intra.reset_mutex(mutex_id, slot);
        apply_intra(table, intra, caller);
        result
    }

    fn get_mutex_id(mutex_name: MutexName) -> Result<MutexId> {
        with_intra(|intra, _| intra.get_mutex_id(&mutex_name))
    }

    fn get_mutex_status(mutex_id: MutexId) -> Result<MutexStatus> {
        with_intra(|intra, _| intra.get_mutex_status(mutex_id))
    }

    fn get_process_mutex_state(process_id: ProcessId) -> Result<MutexId> {
        let mut critical = Critical::enter();
        let (table, intra) = critical.parts();
        let slot = table.slot(process_id)?;
        Ok(intra.process_mutex_state(slot))
    }
}
