//! syssw's service loop: one thread answers the partitions' requests (the service protocol,
//! `syssw/protocol`: partition status and modes, sampling and queuing ports, error reports,
//! application messages) and the kernel's fault reports, and carries out the
//! health monitor's decisions (stop, cold/warm restart, module shutdown).
//!
//! It runs in time partition 0 above every other thread (`crate::restart::SERVER_PRIORITY`)
//! and follows its callers from CPU to CPU (`ThreadAttribute::FollowsCallers`), so a
//! request is served at once, inside the caller's window on the caller's CPU, and it never
//! does anything slow. A windowed partition's fault report or REPORT_ERROR that comes too
//! near the end of its window is handled at the start of its next window instead
//! (`syssw_core::deferred`; an action that stops the partition stops its task at once), so
//! that the handling never runs into the next partition's window.
//! Restarts: a restart's quick part (forget the old task, reset its ports) is done here at
//! once, the rest (kill the old task, print the health line, reload, zero and map the
//! memory, create the task and its first thread) by the restart worker (`crate::restart`)
//! in the restarted partition's own windows (on its CPU: the worker moves there), while
//! this thread goes on serving (who kills and prints when the worker cannot start at once:
//! `syssw_core::restart`).
//! The worker asks for jobs with a `call` answered when one is queued
//! (`syssw_core::restart`) and reports the new instance with its next call; this thread
//! then records it and starts its first thread. Requests that wait (queuing ports)
//! are parked in `syssw_core::ports` and answered later with a deferred `reply`, like the
//! worker's; the receive time-out is the earliest waiter's deadline, so time-outs are
//! answered on time.
//!
//! DMA faults: when a partition has a DMA region, this thread also takes the DMA requests
//! the IOMMU blocked (`dma_fault`) at least every [`DMA_POLL_NS`] and every
//! [`DMA_POLL_MESSAGES`] messages, and reports each as a `memory_violation` of the
//! partition owning the device.
//!
//! Log lines (an interface, besides the health monitor's `health: ...` line of
//! `syssw_core::health`): `syssw: partition NAME: MODE (START_CONDITION, restart N)` on
//! every mode change, `schedule: t=<ms>.<us>ms partition=NAME change action ACTION of
//! schedule NAME (switch at t=<ms>.<us>ms)` before a module schedule switch's change action
//! is carried out (the mode-change line follows), and `message: t=<ms>.<us>ms partition=NAME text="..."` for
//! REPORT_APPLICATION_MESSAGE.

use crate::partitions::Instance;
use config::binary::SystemView;
use config::model::HealthAction;
use config::model::{ChangeAction, Direction, ErrorCode, MAX_PARTITIONS, MAX_PORTS, PortKind};
use syssw_core::deferred::{self, Answer, Deferred};
use syssw_core::health::{
    Detail, DmaFault, ErrorEvent, Fault, HealthMonitor, Record, Text, classify, decide,
    write_log_line,
};
use syssw_core::mode::{ModeChange, OperatingMode, PartitionMode, StartCondition};
use syssw_core::ports::{Completion, NEVER, Outcome, Ports, Waiter};
use syssw_core::restart::{Job, Kind, Report, Restarts, in_own_windows, worker_place};
use syssw_core::schedule::ModuleSchedule;
use syssw_core::staging::Staging;
use user_rt::abi::ipc::{LABEL_FAULT_REPORT, MessageTag, REPLY_KILL};
use user_rt::abi::syscall::{TIMEOUT_INFINITE, TaskId, ThreadAttribute, ThreadId};
use user_rt::ipc_buffer::IpcBufferRef;
use user_rt::println;
use user_rt::protocol::{
    FetchReply, PART_MAX, PartitionStatus, PortIdReply, QueuingMessage, ReplyWords, Request,
    ReturnCode, SamplingMessage, ScheduleIdReply, Wire,
};
use user_rt::sys::{self, Message, Received};

/// One configured partition at run time.
pub struct Partition {
    /// The unmapped page below its stack: a fault there is a stack overflow.
    pub stack_guard: core::ops::Range<u64>,
    /// `None` while it is IDLE or being restarted.
    pub instance: Option<Instance>,
    pub mode: PartitionMode,
}

pub struct Server<'a> {
    pub system: SystemView<'a>,
    pub partitions: [Option<Partition>; MAX_PARTITIONS],
    pub ports: Ports<'a>,
    /// The staging buffers of messages longer than one request, and a message's worth of
    /// room in which such a message is put together or received.
    pub staging: Staging<'a>,
    pub scratch: &'a mut [u8],
    /// Ports their partition has created since it last (re)started.
    pub created: [bool; MAX_PORTS],
    pub health: HealthMonitor,
    pub ipc: IpcBufferRef,
    /// The restart worker (`crate::restart`) and the restarts queued for it.
    pub worker: ThreadId,
    pub restarts: Restarts,
    /// The worker's CPU, time partition and priority since the last job (`None`: as
    /// created).
    pub worker_place: Option<(u8, u8, u8)>,
    /// Which schedule runs and comes next, as SET/GET_MODULE_SCHEDULE_* see it.
    pub schedule: ModuleSchedule,
    /// Whether some partition's devices may DMA (then blocked DMA is polled for), and
    /// the messages since the last poll.
    pub dma: bool,
    pub since_dma_poll: u32,
    /// Error reports waiting for their partition's next window.
    pub deferred: Deferred,
    /// Each partition's window the kernel last named (start, length; see `window_of`).
    pub windows: [(u64, u64); MAX_PARTITIONS],
}

/// How often the IOMMU's blocked DMA requests are taken at least: every so many ns, and
/// every so many messages when requests keep the receive from timing out.
pub const DMA_POLL_NS: u64 = 10_000_000;
pub const DMA_POLL_MESSAGES: u32 = 64;
/// Blocked requests taken per poll (the IOMMU keeps a few records; a flood of faults
/// overflows them, which loses records, never the partition's error).
const DMA_FAULTS_PER_POLL: usize = 8;

/// A request's data (name, message or its last part, text), copied out of the IPC buffer
/// before anything else uses it; a read or receive copies its message (or its first part)
/// here on the way back.
type Buffer = [u8; PART_MAX];

/// Replies `code` with `words` and `data` (through syssw's IPC buffer) to `to`. A caller
/// that is gone (killed while waiting) is no error.
fn answer(ipc: IpcBufferRef, to: ThreadId, code: ReturnCode, words: [u64; 3], data: &[u8]) {
    ipc.write_data(0, data);
    let m = Message {
        tag: MessageTag::new(code.code(), data.len(), 0),
        words,
    };
    let _ = sys::reply(to, &m);
}

/// Answers a parked queuing request that finished (sent, received or timed out). A
/// received message longer than one reply goes into the receiver's staging buffer, and the
/// reply carries its first part.
fn complete(ipc: IpcBufferRef, staging: &mut Staging<'_>, c: Completion<'_>) {
    let words = QueuingMessage {
        len: c.message.len() as u64,
    }
    .to_words();
    let first = c.message.len().min(PART_MAX);
    if !staging.deliver(c.token, c.message) {
        staging.release_token(c.token);
    }
    answer(ipc, ThreadId(c.token), c.code, words, &c.message[..first]);
}

/// The message of a WRITE_SAMPLING or SEND_QUEUING by `token` of partition `index` whose
/// data is `tail`: the data alone, or after the `staged` bytes it staged before, put
/// together in `scratch` (the staging buffer is free again either way).
fn whole_message<'m>(
    (staging, scratch): (&mut Staging<'_>, &'m mut [u8]),
    index: usize,
    token: u64,
    staged: u64,
    tail: &'m [u8],
) -> Result<&'m [u8], ReturnCode> {
    if staged == 0 {
        return Ok(tail);
    }
    let whole = staging.assemble(index, token, staged, tail).map(|whole| {
        scratch[..whole.len()].copy_from_slice(whole);
        whole.len()
    });
    staging.release(index, token);
    Ok(&scratch[..whole?])
}

/// A health record as the core's formatter writes it.
pub struct LogLine<'s, 'a>(pub &'s SystemView<'a>, pub &'s Record);

impl core::fmt::Display for LogLine<'_, '_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write_log_line(f, self.0, self.1)
    }
}

impl<'a> Server<'a> {
    pub fn run(mut self) -> ! {
        let mut buffer: Buffer = [0; PART_MAX];
        loop {
            // A module schedule switch that has taken effect: its change actions first.
            let switch_in = self.schedule_changes();
            // Error reports whose partition's window has come.
            let deferred_in = self.deferred_reports();
            // Without a waiter that can time out nothing expires (and the clock is not read:
            // one system call less on the path of every fault report and request).
            let timeout = match self.ports.next_deadline() {
                None => TIMEOUT_INFINITE,
                Some(_) => {
                    let now = sys::clock();
                    let ipc = self.ipc;
                    let staging = &mut self.staging;
                    match self.ports.expire(now, |c| complete(ipc, staging, c)) {
                        Some(deadline) if deadline != NEVER => deadline.saturating_sub(now).max(1),
                        _ => TIMEOUT_INFINITE,
                    }
                }
            };
            // Wake at the pending switch to carry out its change actions on time.
            let timeout = switch_in.map_or(timeout, |t| t.min(timeout));
            let timeout = deferred_in.map_or(timeout, |t| t.min(timeout));
            let timeout = if self.dma {
                timeout.min(DMA_POLL_NS)
            } else {
                timeout
            };
            let received = sys::receive(None, timeout);
            if self.dma {
                self.since_dma_poll += 1;
                if received.is_err() || self.since_dma_poll >= DMA_POLL_MESSAGES {
                    self.since_dma_poll = 0;
                    self.dma_faults();
                }
            }
            if let Ok(m) = received {
                if m.sender == self.worker {
                    self.worker_call(m);
                } else if m.message.tag.label() == LABEL_FAULT_REPORT {
                    self.fault(m);
                } else {
                    self.request(m, &mut buffer);
                }
                // Doorbells the message rang (a send, a receive or a restart that admitted
                // a parked sender, a doorbell set on a port that holds messages). A thread
                // that is gone is no error.
                self.ports.take_rung(|bell| {
                    let _ = sys::notify_signal(ThreadId(bell.token), bell.bits);
                });
            }
        }
    }

    fn partition_of(&self, task: TaskId) -> Option<usize> {
        self.partitions.iter().position(|p| {
            p.as_ref()
                .and_then(|p| p.instance.as_ref())
                .is_some_and(|i| i.task == task)
        })
    }

    fn running(&mut self, index: usize) -> &mut Partition {
        self.partitions[index]
            .as_mut()
            .expect("every configured partition is placed at start-up")
    }

    fn request(&mut self, m: Received, buffer: &mut Buffer) {
        let ipc = self.ipc;
        let Some(index) = self.partition_of(m.sender_task) else {
            answer(ipc, m.sender, ReturnCode::InvalidParam, [0; 3], &[]);
            return;
        };
        let tag = m.message.tag;
        if tag.len() > buffer.len() {
            // More than one request carries (the kernel never delivers that).
            answer(ipc, m.sender, ReturnCode::InvalidConfig, [0; 3], &[]);
            return;
        }
        let len = tag.len();
        ipc.read_data(0, &mut buffer[..len]);
        let now = sys::clock();
        let reply = |code: ReturnCode, words: [u64; 3]| answer(ipc, m.sender, code, words, &[]);
        let wire = Wire {
            label: tag.label(),
            words: m.message.words,
            data: &buffer[..len],
        };
        let request = match Request::decode(wire) {
            Ok(request) => request,
            Err(error) => return reply(error.return_code(), [0; 3]),
        };
        if let Some(port) = request.port()
            && !self.port_ready(index, port)
        {
            return reply(ReturnCode::InvalidParam, [0; 3]);
        }
        match request {
            Request::PartitionStatus => {
                let (period_ns, duration_ns) = self.period_and_duration(index);
                let mode = self.running(index).mode;
                let status = PartitionStatus {
                    mode: mode.mode(),
                    start_condition: mode.start_condition(),
                    index: index as u64,
                    period_ns,
                    duration_ns,
                };
                reply(ReturnCode::NoError, status.to_words());
            }
            Request::SetPartitionMode { mode } => match self.running(index).mode.request(mode) {
                Err(code) => reply(code, [0; 3]),
                Ok(ModeChange::Run) => {
                    self.log_mode(index);
                    reply(ReturnCode::NoError, [0; 3]);
                }
                Ok(change) => self.carry_out(index, change),
            },
            Request::CreatePort {
                kind,
                direction,
                discipline,
                max_message_size,
                refresh_or_depth,
                name,
            } => {
                let (code, port) = self.create_port(index, name, kind, |port| {
                    port.direction == direction
                        && port.size as u64 == max_message_size
                        && match port.kind {
                            // ARINC: only a destination has a refresh period (a source's
                            // is ignored).
                            PortKind::Sampling => {
                                port.direction == Direction::Out || port.refresh == refresh_or_depth
                            }
                            PortKind::Queuing => {
                                port.depth as u64 == refresh_or_depth
                                    && port.discipline == discipline
                            }
                        }
                });
                reply(code, PortIdReply { port }.to_words());
            }
            Request::PortId { kind, name } => {
                let (code, port) = self.port_id(index, name, kind);
                reply(code, PortIdReply { port }.to_words());
            }
            Request::WriteSampling {
                port,
                staged,
                message,
            } => {
                let token = m.sender.0;
                let whole = (&mut self.staging, &mut *self.scratch);
                let code = match whole_message(whole, index, token, staged, message) {
                    Ok(message) => self
                        .ports
                        .write_sampling(index, port as usize, message, now),
                    Err(code) => code,
                };
                reply(code, [0; 3]);
            }
            Request::ReadSampling { port } => {
                let token = m.sender.0;
                let s = if self.long_port(port) {
                    if let Err(code) = self.staging.reserve(index, token) {
                        return reply(code, [0; 3]);
                    }
                    let s = self
                        .ports
                        .read_sampling(index, port as usize, now, self.scratch);
                    let first = s.len.min(PART_MAX);
                    buffer[..first].copy_from_slice(&self.scratch[..first]);
                    self.staging.deliver(token, &self.scratch[..s.len]);
                    s
                } else {
                    self.ports.read_sampling(index, port as usize, now, buffer)
                };
                let words = SamplingMessage {
                    len: s.len as u64,
                    validity: s.validity,
                }
                .to_words();
                answer(ipc, m.sender, s.code, words, &buffer[..s.len.min(PART_MAX)]);
            }
            Request::SamplingStatus { port } => {
                match self.ports.sampling_status(index, port as usize) {
                    Ok(status) => reply(ReturnCode::NoError, status.to_words()),
                    Err(code) => reply(code, [0; 3]),
                }
            }
            Request::SendQueuing {
                port,
                timeout,
                priority,
                staged,
                message,
            } => {
                let token = m.sender.0;
                let whole = (&mut self.staging, &mut *self.scratch);
                let outcome = match whole_message(whole, index, token, staged, message) {
                    Ok(message) => {
                        let staging = &mut self.staging;
                        self.ports.send_queuing(
                            index,
                            port as usize,
                            message,
                            now,
                            timeout,
                            Waiter { token, priority },
                            |c| complete(ipc, staging, c),
                        )
                    }
                    Err(code) => Outcome::Done { code, len: 0 },
                };
                if let Outcome::Done { code, .. } = outcome {
                    reply(code, [0; 3]);
                }
            }
            Request::ReceiveQueuing {
                port,
                timeout,
                priority,
            } => {
                let token = m.sender.0;
                let waiter = Waiter { token, priority };
                let long = self.long_port(port);
                let staging = &mut self.staging;
                let outcome = if long {
                    // Its buffer is claimed first: a message never leaves the port without
                    // a place to go, now or when it completes a parked receive.
                    match staging.reserve(index, token) {
                        Ok(()) => {
                            let outcome = self.ports.receive_queuing(
                                index,
                                port as usize,
                                now,
                                timeout,
                                waiter,
                                self.scratch,
                                |c| complete(ipc, staging, c),
                            );
                            if let Outcome::Done { len, .. } = outcome {
                                let first = len.min(PART_MAX);
                                buffer[..first].copy_from_slice(&self.scratch[..first]);
                                staging.deliver(token, &self.scratch[..len]);
                            }
                            outcome
                        }
                        Err(code) => Outcome::Done { code, len: 0 },
                    }
                } else {
                    self.ports.receive_queuing(
                        index,
                        port as usize,
                        now,
                        timeout,
                        waiter,
                        buffer,
                        |c| complete(ipc, staging, c),
                    )
                };
                if let Outcome::Done { code, len } = outcome {
                    let words = QueuingMessage { len: len as u64 }.to_words();
                    answer(ipc, m.sender, code, words, &buffer[..len.min(PART_MAX)]);
                }
            }
            Request::QueuingStatus { port } => {
                match self.ports.queuing_status(index, port as usize) {
                    Ok(status) => reply(ReturnCode::NoError, status.to_words()),
                    Err(code) => reply(code, [0; 3]),
                }
            }
            Request::ClearQueuing { port } => {
                let staging = &mut self.staging;
                let code = self
                    .ports
                    .clear_queuing(index, port as usize, now, |c| complete(ipc, staging, c));
                reply(code, [0; 3]);
            }
            Request::PortDoorbell { port, bits } => {
                reply(
                    self.ports
                        .set_doorbell(index, port as usize, m.sender.0, bits),
                    [0; 3],
                );
            }
            Request::ReportError { error, detail } => {
                let detail = match detail {
                    [] => Detail::None,
                    text => Detail::Text(Text::new(text)),
                };
                let report = deferred::Report {
                    partition: index,
                    task: m.sender_task.0,
                    thread: m.sender.0,
                    answer: Answer::NoError,
                    error,
                    detail,
                    time: now,
                };
                if self.defer(report) {
                    return;
                }
                // The reply goes out first when the caller lives on (ignore).
                if self.error(index, error, detail, now) {
                    reply(ReturnCode::NoError, [0; 3]);
                }
            }
            Request::ApplicationMessage { text } => {
                println!(
                    "message: t={}.{:03}ms partition={} text={}",
                    now / 1_000_000,
                    now / 1000 % 1000,
                    self.system.partition(index).name,
                    Detail::Text(Text::new(text))
                );
                reply(ReturnCode::NoError, [0; 3]);
            }
            Request::SetModuleSchedule { schedule } => {
                let code = self.set_module_schedule(index, schedule, now);
                reply(code, [0; 3]);
            }
            Request::ModuleScheduleStatus => {
                reply(ReturnCode::NoError, self.schedule.status(now).to_words());
            }
            Request::StageMessage { offset, part } => {
                reply(self.staging.stage(index, m.sender.0, offset, part), [0; 3]);
            }
            Request::FetchMessage { offset } => {
                match self.staging.fetch(index, m.sender.0, offset, buffer) {
                    Ok((n, left)) => {
                        let words = FetchReply { left }.to_words();
                        answer(ipc, m.sender, ReturnCode::NoError, words, &buffer[..n]);
                    }
                    Err(code) => reply(code, [0; 3]),
                }
            }
            Request::ModuleScheduleId { name } => {
                let found = self.system.schedules().find(|s| s.name.as_bytes() == name);
                match found {
                    Some(s) => reply(
                        ReturnCode::NoError,
                        ScheduleIdReply {
                            schedule: s.index as u64,
                        }
                        .to_words(),
                    ),
                    None => reply(ReturnCode::InvalidConfig, [0; 3]),
                }
            }
        }
    }

    /// ARINC SET_MODULE_SCHEDULE by partition `index`: the kernel switches at the end of the
    /// running major frame and says when.
    fn set_module_schedule(&mut self, index: usize, schedule: u64, now: u64) -> ReturnCode {
        let partition = self.system.partition(index);
        if let Err(code) = self.schedule.check(partition.schedule_control, schedule) {
            return code;
        }
        match sys::schedule_switch(schedule) {
            Ok(at) => {
                self.schedule.requested(schedule, at, now);
                println!(
                    "schedule: t={}.{:03}ms partition={} asks for schedule {} from t={}.{:03}ms",
                    now / 1_000_000,
                    now / 1000 % 1000,
                    partition.name,
                    self.system.schedule(schedule as usize).name,
                    at / 1_000_000,
                    at / 1000 % 1000,
                );
                ReturnCode::NoError
            }
            // Every configured schedule is installed: the kernel has no reason to refuse.
            Err(_) => ReturnCode::InvalidParam,
        }
    }

    /// Carries out the change actions of the module schedule a switch made current, if one
    /// has taken effect; else, while a switch is pending, how long until it does (a
    /// receive time-out, >= 1). Reads the clock only while a switch is pending.
    fn schedule_changes(&mut self) -> Option<u64> {
        self.schedule.pending_at()?;
        let now = sys::clock();
        let Some(id) = self.schedule.take_switch(now) else {
            return self
                .schedule
                .pending_at()
                .map(|at| at.saturating_sub(now).max(1));
        };
        let schedule = self.system.schedule(id as usize);
        let at = self.schedule.status(now).last_switch;
        for index in 0..self.system.partition_count() {
            let action = schedule.change_actions.get(index);
            // A partition being restarted (no task, not IDLE) is already starting again.
            let restarting = self.partitions[index]
                .as_ref()
                .is_none_or(|p| p.instance.is_none() && p.mode.mode() != OperatingMode::Idle);
            if action == ChangeAction::Ignore || restarting {
                continue;
            }
            let change = self.running(index).mode.apply_schedule_change(action);
            if change == ModeChange::None {
                continue;
            }
            println!(
                "schedule: t={}.{:03}ms partition={} change action {} of schedule {} (switch at t={}.{:03}ms)",
                now / 1_000_000,
                now / 1000 % 1000,
                self.system.partition(index).name,
                action.name(),
                schedule.name,
                at / 1_000_000,
                at / 1000 % 1000,
            );
            self.carry_out(index, change);
        }
        self.schedule
            .pending_at()
            .map(|at| at.saturating_sub(now).max(1))
    }

    /// A port request's port id names a port this partition has created.
    /// Whether port `id` (a valid index) takes messages longer than one part.
    fn long_port(&self, id: u64) -> bool {
        self.system.port(id as usize).size as usize > PART_MAX
    }

    fn port_ready(&self, index: usize, id: u64) -> bool {
        (id as usize) < self.system.port_count()
            && self.created[id as usize]
            && self.system.port(id as usize).partition == index
    }

    /// ARINC CREATE_SAMPLING_PORT / CREATE_QUEUING_PORT: the port must be configured for
    /// this partition exactly as asked, and the partition still initialising.
    fn create_port(
        &mut self,
        index: usize,
        name: &[u8],
        kind: PortKind,
        matches: impl FnOnce(&config::binary::PortView<'a>) -> bool,
    ) -> (ReturnCode, u64) {
        let Some(port) = self.find_port(index, name, kind) else {
            return (ReturnCode::InvalidConfig, 0);
        };
        if !matches(&port) {
            return (ReturnCode::InvalidConfig, 0);
        }
        let mode = self.running(index).mode.mode();
        if !matches!(mode, OperatingMode::ColdStart | OperatingMode::WarmStart) {
            return (ReturnCode::InvalidMode, 0);
        }
        if self.created[port.index] {
            return (ReturnCode::NoAction, port.index as u64);
        }
        self.created[port.index] = true;
        (ReturnCode::NoError, port.index as u64)
    }

    /// ARINC GET_*_PORT_ID: a created port of this partition by name.
    fn port_id(&self, index: usize, name: &[u8], kind: PortKind) -> (ReturnCode, u64) {
        match self.find_port(index, name, kind) {
            Some(p) if self.created[p.index] => (ReturnCode::NoError, p.index as u64),
            _ => (ReturnCode::InvalidConfig, 0),
        }
    }

    fn find_port(
        &self,
        index: usize,
        name: &[u8],
        kind: PortKind,
    ) -> Option<config::binary::PortView<'a>> {
        let name = core::str::from_utf8(name).ok()?;
        self.system
            .ports()
            .find(|p| p.partition == index && p.kind == kind && p.name == name)
    }

    /// ARINC PERIOD and DURATION of a partition: the first schedule's major frame and the
    /// sum of its windows there, those of its CPU (0 and 0 for a background partition).
    fn period_and_duration(&self, index: usize) -> (u64, u64) {
        let p = self.system.partition(index);
        let tp = p.time_partition;
        if tp == 0 || self.system.schedule_count() == 0 {
            return (0, 0);
        }
        let s = self.system.schedule(0);
        let duration = s
            .windows_of(p.cpu)
            .filter(|w| w.time_partition == tp)
            .map(|w| w.duration)
            .sum();
        (s.major_frame, duration)
    }

    /// A kernel fault report for a thread without its own handler.
    fn fault(&mut self, m: Received) {
        let e = self.ipc.exception();
        let Some(index) = self.partition_of(TaskId(e.task)) else {
            if self.restarts.dying(e.task) {
                // A thread of a partition being restarted, before the worker killed it.
                kill_faulted(m.sender);
                return;
            }
            println!(
                "health: fault report for unknown task {:#x}; thread killed",
                e.task
            );
            kill_faulted(m.sender);
            return;
        };
        let fault = Fault::from_message(&e);
        let guard = self.running(index).stack_guard.clone();
        let error = classify(&fault, guard);
        let now = sys::clock();
        let report = deferred::Report {
            partition: index,
            task: e.task,
            thread: m.sender.0,
            answer: Answer::Kill,
            error,
            detail: Detail::Fault(fault),
            time: now,
        };
        if self.defer(report) {
            return;
        }
        if self.error(index, error, Detail::Fault(fault), now) {
            // "ignore": the partition goes on, but the faulting thread cannot.
            kill_faulted(m.sender);
        }
    }

    /// Reports the DMA requests the IOMMU blocked, each as a memory violation of the
    /// partition that owns the device (a device nobody owns: logged only).
    fn dma_faults(&mut self) {
        for _ in 0..DMA_FAULTS_PER_POLL {
            let Ok(f) = sys::dma_fault() else {
                return;
            };
            let fault = DmaFault {
                source: f.source,
                address: f.address,
                write: f.write,
                reason: f.reason,
            };
            let device = pci::Address::from_id(f.source);
            let owner = self
                .system
                .partitions()
                .find(|p| p.devices().any(|d| d == device))
                .map(|p| p.index);
            match owner {
                Some(index) if self.partitions[index].is_some() => {
                    let now = sys::clock();
                    self.error(index, ErrorCode::MemoryViolation, Detail::Dma(fault), now);
                }
                _ => println!(
                    "health: blocked DMA of a device no running partition owns: {}",
                    Detail::Dma(fault)
                ),
            }
        }
    }

    /// Leaves `report` for its partition's next window if too little of the current one is
    /// left to handle it (or reports before it wait): true if it did. An action that stops
    /// the partition stops its task now, so nothing of it runs before the report is handled
    /// (first thing in its next window, above every thread of it). Handled at once: a
    /// background partition's reports, a module shutdown, a restart the worker can start at
    /// once (the server only forgets the task and queues the job), a report the full queue
    /// refuses.
    fn defer(&mut self, report: deferred::Report) -> bool {
        let index = report.partition;
        let p = self.system.partition(index);
        let tp = p.time_partition;
        let action = decide(&self.system, Some(index), report.error);
        // A restart the worker takes at once costs the server less than a stop: its slow
        // part, the health line included, runs in the partition's windows anyway.
        let quick_restart = matches!(
            action,
            HealthAction::ColdRestart | HealthAction::WarmRestart
        ) && self.restarts.worker_idle();
        if tp == 0
            || quick_restart
            || matches!(
                action,
                HealthAction::Shutdown | HealthAction::ShutdownSuccess
            )
        {
            return false;
        }
        let Some((start, length)) = self.window_of(index, tp, report.time) else {
            return false;
        };
        if !self.deferred.waiting(index) && deferred::fits(start, length, report.time) {
            return false;
        }
        let window = self.window_after((tp, p.cpu), start, length, report.time);
        if self.deferred.push(report, window).is_err() {
            return false;
        }
        if action != HealthAction::Ignore {
            let _ = sys::task_stop(TaskId(report.task));
        }
        true
    }

    /// Partition `index`'s window (time partition `tp`) running at `now`, or its next one:
    /// start and length. The kernel's answer (`partition_info`) is kept while its window
    /// runs, so a report at the end of a window the server has already asked about (at its
    /// start, for a waiting report) costs no system call.
    fn window_of(&mut self, index: usize, tp: u8, now: u64) -> Option<(u64, u64)> {
        let (start, length) = self.windows[index];
        if start <= now && now < start.saturating_add(length) {
            return Some((start, length));
        }
        let info = sys::partition_info(tp as u64).ok()?;
        let window = (info.next_window_start, info.window_length);
        self.windows[index] = window;
        Some(window)
    }

    /// The start of the next window of time partition `tp` on CPU `cpu` (`place`) when its
    /// window (from the kernel's `partition_info`) is `start..start + length` at `now`:
    /// that one if it has not begun, else the one after it in the running schedule.
    fn window_after(&mut self, place: (u8, u8), start: u64, length: u64, now: u64) -> u64 {
        if start > now {
            return start;
        }
        let s = self
            .system
            .schedule(self.schedule.status(now).current as usize);
        let mut windows = [config::model::Window::default(); config::model::MAX_WINDOWS];
        let n = s.window_count();
        for (w, window) in windows.iter_mut().zip(s.windows()) {
            *w = window;
        }
        deferred::next_window_after(&windows[..n], s.major_frame, place, start, length)
    }

    /// Handles the waiting error reports whose partition's window has come and has room for
    /// them, oldest first; the others wait on. Returns how long until the next one is due
    /// (a receive time-out, >= 1), or `None` if none waits.
    fn deferred_reports(&mut self) -> Option<u64> {
        self.deferred.next_wake()?;
        let mut now = sys::clock();
        for index in 0..self.system.partition_count() {
            if !self.deferred.due(index, now) {
                continue;
            }
            let p = self.system.partition(index);
            let tp = p.time_partition;
            let Some((start, length)) = self.window_of(index, tp, now) else {
                continue;
            };
            // The work runs in the partition's window on its CPU, where this thread moves
            // (it stays there until a caller elsewhere takes it along).
            if deferred::fits(start, length, now) {
                let _ = sys::thread_set(None, ThreadAttribute::Cpu, p.cpu as u64);
            }
            while deferred::fits(start, length, now) {
                let Some(report) = self.deferred.take(index) else {
                    break;
                };
                self.handle_deferred(report);
                now = sys::clock();
            }
            if self.deferred.waiting(index) {
                let window = self.window_after((tp, p.cpu), start, length, now);
                self.deferred.wait_until(index, window);
            }
        }
        let next = self.deferred.next_wake()?;
        Some(next.saturating_sub(now).max(1))
    }

    /// A report that waited for its partition's window: handled as if it came now, timed
    /// when it came. An instance that is gone meanwhile (restarted) took its thread along.
    fn handle_deferred(&mut self, r: deferred::Report) {
        let thread = ThreadId(r.thread);
        if self.partition_of(TaskId(r.task)) != Some(r.partition) {
            kill_faulted(thread);
            return;
        }
        if self.error(r.partition, r.error, r.detail, r.time) {
            match r.answer {
                Answer::Kill => kill_faulted(thread),
                Answer::NoError => answer(self.ipc, thread, ReturnCode::NoError, [0; 3], &[]),
            }
        }
    }

    /// Records and logs an error of partition `index` reported at `now` and carries out the
    /// configured action. True if the partition is still running as before (the caller may
    /// answer).
    fn error(&mut self, index: usize, error: ErrorCode, detail: Detail, now: u64) -> bool {
        let event = ErrorEvent {
            partition: Some(index),
            error,
            detail,
        };
        let record = self.health.report(&self.system, now, event);
        let change = self.running(index).mode.apply_health(record.action);
        match change {
            ModeChange::None => {
                println!("{}", LogLine(&self.system, &record));
                true
            }
            ModeChange::Restart { warm } => {
                self.restart(index, warm, Some(record));
                false
            }
            _ => {
                println!("{}", LogLine(&self.system, &record));
                self.carry_out(index, change);
                false
            }
        }
    }

    /// Does what a mode change demands. Nothing here waits for long: a restart's slow part
    /// is queued for the worker.
    fn carry_out(&mut self, index: usize, change: ModeChange) {
        match change {
            ModeChange::None | ModeChange::Run => {}
            ModeChange::Halt { success } => {
                let _ = sys::system_halt(success);
            }
            ModeChange::Stop => {
                self.stop(index);
                self.log_mode(index);
            }
            ModeChange::Restart { warm } => self.restart(index, warm, None),
        }
    }

    /// Restarts partition `index`. The worker kills the old task and logs `health` (the
    /// error that caused the restart, if any) in the partition's window when it can start
    /// at once; otherwise (busy with another partition, or a background partition) this
    /// thread stops the old task now (`task_stop`: bounded, so that nothing of the
    /// partition runs on while it waits) and logs, and the worker destroys the task when the
    /// job starts, in the partition's own time. This thread, above every partition in every
    /// window, never destroys a task itself: a large one would take the time of whichever
    /// partition's window is running.
    fn restart(&mut self, index: usize, warm: bool, health: Option<Record>) {
        let old = self.forget(index);
        let at_once = in_own_windows(&self.system.partition(index)) && self.restarts.worker_idle();
        if let (Some(task), false) = (old, at_once) {
            let _ = sys::task_stop(task);
        }
        let kill = old.map(|task| task.0);
        if let Some(record) = health
            && !(at_once && crate::restart::hand_over_record(index, record))
        {
            println!("{}", LogLine(&self.system, &record));
        }
        let mode = self.running(index).mode;
        let job = Job {
            partition: index,
            kind: if warm { Kind::Warm } else { Kind::Cold },
            condition: mode.start_condition(),
            restarts: mode.restarts(),
            kill,
        };
        // Its old task is gone for the server, so nothing of it can ask for a second
        // restart before the worker reports this one.
        let queued = self.restarts.push(job);
        debug_assert!(queued, "a partition without a task restarts once");
        self.dispatch();
    }

    /// Stops the partition's task (no thread of it runs again; `task_stop`, bounded) and
    /// resets its ports. The task keeps its kernel memory and its slot, from the
    /// partition's own quota, until the module restarts: IDLE is for good.
    fn stop(&mut self, index: usize) {
        if let Some(task) = self.forget(index) {
            let _ = sys::task_stop(task);
        }
    }

    /// Forgets the partition's task (its requests and faults are no longer its partition's)
    /// and resets its ports; returns the task, still alive.
    fn forget(&mut self, index: usize) -> Option<TaskId> {
        let instance = self.running(index).instance.take();
        for p in self.system.ports().filter(|p| p.partition == index) {
            self.created[p.index] = false;
        }
        let ipc = self.ipc;
        let staging = &mut self.staging;
        self.ports
            .reset_partition(index, |c| complete(ipc, staging, c));
        self.staging.reset_partition(index);
        instance.map(|i| i.task)
    }

    /// Hands the next queued restart to the worker if it waits for one, where
    /// `syssw_core::restart::worker_place` puts it: on the restarted partition's CPU and in
    /// its time partition, so that partition's windows pay for the reload, at syssw's
    /// priority there (above every thread of the partition it may have to kill, below this
    /// thread), or for a background partition at its priority (it competes for the
    /// background as the partition itself would).
    fn dispatch(&mut self) {
        let Some(job) = self.restarts.dispatch() else {
            return;
        };
        let p = self.system.partition(job.partition);
        // A partition restarting again and again finds the worker where it was (two
        // system calls less on the path a fault report takes).
        let place = worker_place(&p);
        let (cpu, time_partition, priority) = place;
        if self.worker_place != Some(place) {
            // The worker waits for this reply, so no CPU runs it and it may move.
            let worker = Some(self.worker);
            let moved = sys::thread_set(worker, ThreadAttribute::Cpu, cpu as u64)
                .and_then(|()| {
                    let tp = time_partition as u64;
                    sys::thread_set(worker, ThreadAttribute::TimePartition, tp)
                })
                .and_then(|()| sys::thread_set(worker, ThreadAttribute::Priority, priority as u64));
            if let Err(e) = moved {
                self.worker_failed(format_args!("cannot move it to {}: {e:?}", p.name));
            }
            self.worker_place = Some(place);
        }
        let m = Message {
            tag: MessageTag::new(0, 0, 0),
            words: job.to_words(),
        };
        if let Err(e) = sys::reply(self.worker, &m) {
            self.worker_failed(format_args!("cannot hand it a job: {e:?}"));
        }
    }

    /// The worker's call: it reports the restart it finished (if any) and asks for the
    /// next. A restarted partition's instance is recorded before its first thread starts,
    /// so its first request finds it.
    fn worker_call(&mut self, m: Received) {
        let tag = m.message.tag;
        if tag.label() == LABEL_FAULT_REPORT {
            let e = self.ipc.exception();
            self.worker_failed(format_args!(
                "faulted (vector {}, rip {:#x})",
                e.vector, e.registers.rip
            ));
        }
        let Some(report) = Report::decode(tag.label(), m.message.words) else {
            self.worker_failed(format_args!("unknown report label {}", tag.label()));
        };
        let index = match self.restarts.report(report) {
            Ok(finished) => finished,
            Err(e) => self.worker_failed(format_args!("report refused: {e:?}")),
        };
        match report {
            Report::Ready => {}
            Report::Done { task, thread, .. } => {
                let instance = Instance {
                    task: TaskId(task),
                    thread: ThreadId(thread),
                };
                let index = index.expect("a finished job");
                self.running(index).instance = Some(instance);
                if let Err(e) = sys::thread_start(ThreadId(thread)) {
                    println!(
                        "syssw: partition {}: restart failed: thread_start failed: {e:?}; it stays IDLE",
                        self.system.partition(index).name
                    );
                    self.idle(index);
                }
            }
            Report::Failed { partition } => self.idle(partition),
        }
        self.dispatch();
    }

    /// A restart failed: the partition stays IDLE (without a task).
    fn idle(&mut self, index: usize) {
        self.stop(index);
        self.running(index)
            .mode
            .apply_health(config::model::HealthAction::Idle);
        self.log_mode(index);
    }

    /// The worker broke syssw's own protocol: no partition could be restarted any more.
    fn worker_failed(&self, what: core::fmt::Arguments) -> ! {
        println!("syssw: restart worker: {what}");
        let _ = sys::system_halt(false);
        sys::thread_exit()
    }

    fn log_mode(&mut self, index: usize) {
        let mode = self.running(index).mode;
        log_mode_change(
            self.system.partition(index).name,
            mode.mode(),
            mode.start_condition(),
            mode.restarts(),
        );
    }
}

/// The mode-change log line (see the module documentation).
pub fn log_mode_change(name: &str, mode: OperatingMode, condition: StartCondition, restarts: u32) {
    println!(
        "syssw: partition {name}: {} ({}, restart {restarts})",
        mode.name(),
        condition.name(),
    );
}

fn kill_faulted(thread: ThreadId) {
    let _ = sys::reply(
        thread,
        &Message {
            tag: MessageTag::new(REPLY_KILL, 0, 0),
            words: [0; 3],
        },
    );
}
