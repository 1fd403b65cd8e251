//! The service protocol between partitions and syssw: the one definition of its labels,
//! word packing, codes and typed requests and replies. syssw decodes requests and encodes
//! replies with it; the APEX runtime (`partitions/apex`) and the user runtime (`user/rt`)
//! encode requests and decode replies with it. It is an interface: change it only with
//! both sides, and keep this table current.
//!
//! A request is a synchronous IPC `call` to syssw's server thread (named in the partition's
//! start record) with the request's label, three words and, where a request says so, data
//! bytes in the caller's IPC buffer. The caller must `call` with an infinite time-out: a
//! request that waits (a queuing port) carries its own time-out in a word and syssw answers
//! when it is done or timed out. The reply's label is an ARINC 653 return code
//! ([`ReturnCode`]); its words and data are as each request says. syssw never trusts a
//! request: the caller's partition is the sender task the kernel reports, never a word of
//! the message; every index and length is checked.
//!
//! | label ([`Label`]) | request words / data | reply words / data |
//! |---|---|---|
//! | `PARTITION_STATUS` = 1 | – | w0 = mode \| start condition << 8 \| index << 16, w1 = period ns, w2 = duration ns ([`PartitionStatus`]) |
//! | `SET_PARTITION_MODE` = 2 | w0 = mode ([`OperatingMode`]) | – (no reply for IDLE/restarts: the caller's thread is gone) |
//! | `CREATE_PORT` = 10 | w0 = kind \| direction << 8 \| queuing discipline << 16 (FIFO for sampling), w1 = max message size, w2 = refresh ns (sampling) or depth (queuing); data = name | w0 = port id ([`PortIdReply`]) |
//! | `PORT_ID` = 11 | w0 = kind; data = name | w0 = port id ([`PortIdReply`]) |
//! | `WRITE_SAMPLING` = 12 | w0 = port id, w1 = staged bytes (0 = none); data = message (its end, after the staged bytes) | – |
//! | `READ_SAMPLING` = 13 | w0 = port id | w0 = length, w1 = validity; data = message (its first [`PART_MAX`] bytes) ([`SamplingMessage`]) |
//! | `SAMPLING_STATUS` = 14 | w0 = port id | w0 = max size \| direction << 32, w1 = refresh ns, w2 = last validity ([`SamplingStatus`]) |
//! | `SEND_QUEUING` = 15 | w0 = port id, w1 = time-out ns, w2 = the caller's priority (0..=255) \| staged bytes << 8; data = message (its end, after the staged bytes) | – |
//! | `RECEIVE_QUEUING` = 16 | w0 = port id, w1 = time-out ns, w2 = the caller's priority (0..=255) | w0 = length; data = message (its first [`PART_MAX`] bytes) ([`QueuingMessage`]) |
//! | `QUEUING_STATUS` = 17 | w0 = port id | w0 = messages \| max messages << 32, w1 = max size \| direction << 32, w2 = waiting processes ([`QueuingStatus`]) |
//! | `CLEAR_QUEUING` = 18 | w0 = port id | – |
//! | `PORT_DOORBELL` = 19 | w0 = port id (a queuing destination port), w1 = notification bits (0 = none) | – (from then on the calling thread is sent `notify_signal` with the bits whenever a message enters the port's FIFO and was not handed to a waiting receiver; once for several messages; a message already waiting rings at once; ends when the partition stops or restarts) |
//! | `REPORT_ERROR` = 20 | w0 = error ([`ErrorCode`]); data = detail text | – (or no reply: the action stopped the caller) |
//! | `APPLICATION_MESSAGE` = 21 | data = text | – |
//! | `SET_MODULE_SCHEDULE` = 30 | w0 = schedule id | – |
//! | `MODULE_SCHEDULE_STATUS` = 31 | – | w0 = time of the last switch (ns since boot, 0 = none), w1 = current schedule id, w2 = next schedule id ([`ScheduleStatus`]) |
//! | `MODULE_SCHEDULE_ID` = 32 | data = name | w0 = schedule id ([`ScheduleIdReply`]) |
//! | `STAGE_MESSAGE` = 40 | w0 = offset; data = the next part of a long message | – |
//! | `FETCH_MESSAGE` = 41 | w0 = offset | w0 = bytes after this part ([`FetchReply`]); data = the part of the received message from offset |
//!
//! **Long messages.** A request or reply carries at most [`PART_MAX`] data bytes (one IPC
//! message); a port message may be up to [`MAX_MESSAGE_SIZE`]. A longer one travels in
//! parts through the caller's *staging buffer* in syssw:
//! - Sending: STAGE_MESSAGE its first parts in order (offset 0 starts a new message and
//!   drops whatever the caller had staged; every other offset must be the number of bytes
//!   staged so far), then WRITE_SAMPLING or SEND_QUEUING with the number of staged bytes
//!   and the last part as data. syssw sends the staged bytes followed by the data, and the
//!   buffer is free again. A staged count that is not what the caller staged is
//!   INVALID_PARAM; more bytes than the partition's longest port message, INVALID_CONFIG.
//! - Receiving: READ_SAMPLING and RECEIVE_QUEUING answer with the whole length and the
//!   first [`PART_MAX`] bytes; the rest waits in the caller's staging buffer, read with
//!   FETCH_MESSAGE at offsets `PART_MAX`, `2 * PART_MAX`, ... A fetch at the message's
//!   length (or one that reaches it) frees the buffer; a caller that does not want the rest
//!   fetches at the length. FETCH_MESSAGE without a message waiting is INVALID_PARAM.
//! - Each partition that has a port longer than [`PART_MAX`] has staging buffers of its
//!   longest port's size in syssw: [`STAGING_RUNNERS`] for threads in the middle of a
//!   transfer, and `MAX_WAITERS` more for each such queuing input port (receivers parked
//!   on it get theirs when their message comes). A transfer that finds none free is
//!   INVALID_CONFIG, and the port is left as it was. A partition's buffers are emptied
//!   when it restarts.
//!
//! Codes travel as their numbers ([`PortKind`], [`Direction`], [`Validity`], ...; each table
//! is written once below). Port ids are the ports' global indexes in the configuration; a
//! port must be created (in COLD_START or WARM_START mode, matching its configuration)
//! before use. Schedule ids are the schedules' indexes in the configuration. Time-outs: 0 = do not wait, `u64::MAX` = forever, else nanoseconds. Words a
//! request does not use are ignored. The caller's priority orders it among the processes
//! waiting on a PRIORITY port; syssw takes it as given, since only processes of the caller's
//! own partition wait on the same port.
//!
//! Decoding is total: any label, words and data decode to a typed value or to a
//! [`DecodeError`], which names the return code syssw answers it with. This crate must stay
//! `no_std`, allocation-free and free of system calls: the IPC itself is the callers' glue.
#![no_std]

pub mod layout;

/// Most data bytes one request or reply carries: one IPC message.
pub const PART_MAX: usize = abi::ipc::IPC_DATA_MAX;
/// Longest port message (the configuration's `size` limit); longer than [`PART_MAX`], it
/// travels in parts (see the module documentation).
pub const MAX_MESSAGE_SIZE: u32 = 64 * 1024;
/// Staging buffers of a partition with long ports, besides those for its parked receivers:
/// threads that are in the middle of staging or fetching a message at the same time. The
/// APEX runtime moves a long message with its priority at the partition's MCP, so only
/// a thread running at the MCP (the error handler) can interrupt another's transfer.
pub const STAGING_RUNNERS: usize = 4;

codes::code_enum! {
    /// A request's IPC label.
    pub enum Label: u32 {
        PartitionStatus = 1 => "PARTITION_STATUS",
        SetPartitionMode = 2 => "SET_PARTITION_MODE",
        CreatePort = 10 => "CREATE_PORT",
        PortId = 11 => "PORT_ID",
        WriteSampling = 12 => "WRITE_SAMPLING",
        ReadSampling = 13 => "READ_SAMPLING",
        SamplingStatus = 14 => "SAMPLING_STATUS",
        SendQueuing = 15 => "SEND_QUEUING",
        ReceiveQueuing = 16 => "RECEIVE_QUEUING",
        QueuingStatus = 17 => "QUEUING_STATUS",
        ClearQueuing = 18 => "CLEAR_QUEUING",
        PortDoorbell = 19 => "PORT_DOORBELL",
        ReportError = 20 => "REPORT_ERROR",
        ApplicationMessage = 21 => "APPLICATION_MESSAGE",
        SetModuleSchedule = 30 => "SET_MODULE_SCHEDULE",
        ModuleScheduleStatus = 31 => "MODULE_SCHEDULE_STATUS",
        ModuleScheduleId = 32 => "MODULE_SCHEDULE_ID",
        StageMessage = 40 => "STAGE_MESSAGE",
        FetchMessage = 41 => "FETCH_MESSAGE",
    }
}

codes::code_enum! {
    /// ARINC 653 `RETURN_CODE_TYPE` (the numbering of ARINC 653 Part 1, which a653rs uses
    /// too): the label of every reply.
    pub enum ReturnCode: u32 {
        /// The request was performed.
        NoError = 0 => "NO_ERROR",
        /// Nothing to do: the request changed nothing (e.g. reading a sampling port that
        /// was never written, or setting the mode the partition is already in).
        NoAction = 1 => "NO_ACTION",
        /// The resource is not available now and the caller asked not to wait.
        NotAvailable = 2 => "NOT_AVAILABLE",
        /// A parameter is wrong (unknown port, port of another partition, empty message, ...).
        InvalidParam = 3 => "INVALID_PARAM",
        /// The request is outside what the configuration provides (message longer than the
        /// port's size, more waiting processes than a port holds).
        InvalidConfig = 4 => "INVALID_CONFIG",
        /// The request does not fit the object's mode (sending on a destination port, a warm
        /// start from cold start, ...).
        InvalidMode = 5 => "INVALID_MODE",
        /// The caller waited and its time-out expired.
        TimedOut = 6 => "TIMED_OUT",
    }
}

codes::code_enum! {
    /// ARINC 653 `OPERATING_MODE_TYPE`.
    pub enum OperatingMode: u8 {
        Idle = 0 => "IDLE",
        ColdStart = 1 => "COLD_START",
        WarmStart = 2 => "WARM_START",
        Normal = 3 => "NORMAL",
    }
}

codes::code_enum! {
    /// ARINC 653 `START_CONDITION_TYPE`: why the partition is (re)starting.
    pub enum StartCondition: u8 {
        /// The module started (boot).
        NormalStart = 0 => "NORMAL_START",
        /// The partition asked for its restart (SET_PARTITION_MODE).
        PartitionRestart = 1 => "PARTITION_RESTART",
        /// The health monitor restarted the module.
        HmModuleRestart = 2 => "HM_MODULE_RESTART",
        /// The health monitor restarted the partition.
        HmPartitionRestart = 3 => "HM_PARTITION_RESTART",
    }
}

codes::code_enum! {
    /// ARINC 653 `ERROR_CODE_TYPE`: the errors the health monitor handles, as REPORT_ERROR
    /// carries them, as the configuration's health tables name them and as the health
    /// monitor's log line prints them.
    pub enum ErrorCode: u8 {
        DeadlineMissed = 0 => "deadline_missed",
        ApplicationError = 1 => "application_error",
        NumericError = 2 => "numeric_error",
        IllegalRequest = 3 => "illegal_request",
        StackOverflow = 4 => "stack_overflow",
        MemoryViolation = 5 => "memory_violation",
        HardwareFault = 6 => "hardware_fault",
        PowerFail = 7 => "power_fail",
    }
}

codes::code_enum! {
    /// ARINC 653 port kinds (also the configuration's `kind`).
    pub enum PortKind: u8 {
        /// The latest message overwrites the previous one; readers see the newest.
        Sampling = 1 => "sampling",
        /// A FIFO of at most `depth` messages.
        Queuing = 2 => "queuing",
    }
}

codes::code_enum! {
    /// Direction of a port, seen from its partition (also the configuration's `direction`).
    pub enum Direction: u8 {
        /// The partition receives (ARINC 653 DESTINATION port).
        In = 1 => "in",
        /// The partition sends (ARINC 653 SOURCE port).
        Out = 2 => "out",
    }
}

codes::code_enum! {
    /// ARINC 653 `QUEUING_DISCIPLINE_TYPE` of a queuing port: the order in which the
    /// processes waiting on it (senders on a full port, receivers on an empty one) are
    /// served (also the configuration's `discipline`).
    pub enum Discipline: u8 {
        /// In the order they began to wait.
        Fifo = 0 => "fifo",
        /// Highest process priority first, in the order they began to wait among equals.
        Priority = 1 => "priority",
    }
}

codes::code_enum! {
    /// ARINC 653 `VALIDITY_TYPE` of a sampling message: whether it is younger than the
    /// destination port's refresh period.
    pub enum Validity: u8 {
        Invalid = 0 => "INVALID",
        Valid = 1 => "VALID",
    }
}

/// Why a request or reply could not be decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecodeError {
    /// The label names no request.
    UnknownLabel(u32),
    /// The label of a reply is no ARINC return code.
    UnknownReturnCode(u32),
    /// SET_PARTITION_MODE with a mode code ARINC does not define.
    UnknownMode(u64),
    /// REPORT_ERROR with an error code ARINC does not define.
    UnknownError(u64),
    /// A port kind or direction that no port can have.
    UnknownPortKind(u64),
    UnknownDirection(u64),
    /// A queuing discipline ARINC does not define.
    UnknownDiscipline(u64),
    /// A process priority above 255.
    BadPriority(u64),
    /// A reply word holds a value its field cannot (a mode, condition or validity code).
    BadReplyWord(u64),
}

impl DecodeError {
    /// The return code syssw answers an undecodable request with: a port request with a
    /// kind or direction no configured port can have asks for what the configuration does
    /// not provide (INVALID_CONFIG); anything else is a wrong parameter (INVALID_PARAM).
    pub const fn return_code(self) -> ReturnCode {
        match self {
            Self::UnknownPortKind(_) | Self::UnknownDirection(_) | Self::UnknownDiscipline(_) => {
                ReturnCode::InvalidConfig
            }
            _ => ReturnCode::InvalidParam,
        }
    }
}

/// A port id as requests carry it (the port's global index in the configuration).
pub type PortId = u64;

/// A request, borrowing its data bytes (names, messages, texts) from the IPC buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Request<'a> {
    PartitionStatus,
    SetPartitionMode {
        mode: OperatingMode,
    },
    CreatePort {
        kind: PortKind,
        direction: Direction,
        /// Queuing: the configured discipline it must match; sampling: FIFO.
        discipline: Discipline,
        max_message_size: u64,
        /// Refresh period in ns (sampling; a source's is ignored) or depth (queuing).
        refresh_or_depth: u64,
        name: &'a [u8],
    },
    PortId {
        kind: PortKind,
        name: &'a [u8],
    },
    WriteSampling {
        port: PortId,
        /// Bytes of the message staged before (STAGE_MESSAGE); `message` follows them.
        staged: u64,
        message: &'a [u8],
    },
    ReadSampling {
        port: PortId,
    },
    SamplingStatus {
        port: PortId,
    },
    SendQueuing {
        port: PortId,
        timeout: u64,
        /// The caller's current priority (its place among PRIORITY waiters).
        priority: u8,
        /// Bytes of the message staged before (STAGE_MESSAGE); `message` follows them.
        staged: u64,
        message: &'a [u8],
    },
    ReceiveQueuing {
        port: PortId,
        timeout: u64,
        priority: u8,
    },
    QueuingStatus {
        port: PortId,
    },
    ClearQueuing {
        port: PortId,
    },
    /// Notify the calling thread with `bits` (0: no more) when messages arrive at `port`.
    PortDoorbell {
        port: PortId,
        bits: u64,
    },
    ReportError {
        error: ErrorCode,
        detail: &'a [u8],
    },
    ApplicationMessage {
        text: &'a [u8],
    },
    SetModuleSchedule {
        schedule: u64,
    },
    ModuleScheduleStatus,
    ModuleScheduleId {
        name: &'a [u8],
    },
    StageMessage {
        offset: u64,
        part: &'a [u8],
    },
    FetchMessage {
        offset: u64,
    },
}

/// A request or reply as it travels: label, three words and the data bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Wire<'a> {
    pub label: u32,
    pub words: [u64; 3],
    pub data: &'a [u8],
}

impl<'a> Request<'a> {
    /// The request's label.
    pub const fn label(&self) -> Label {
        match self {
            Self::PartitionStatus => Label::PartitionStatus,
            Self::SetPartitionMode { .. } => Label::SetPartitionMode,
            Self::CreatePort { .. } => Label::CreatePort,
            Self::PortId { .. } => Label::PortId,
            Self::WriteSampling { .. } => Label::WriteSampling,
            Self::ReadSampling { .. } => Label::ReadSampling,
            Self::SamplingStatus { .. } => Label::SamplingStatus,
            Self::SendQueuing { .. } => Label::SendQueuing,
            Self::ReceiveQueuing { .. } => Label::ReceiveQueuing,
            Self::QueuingStatus { .. } => Label::QueuingStatus,
            Self::ClearQueuing { .. } => Label::ClearQueuing,
            Self::PortDoorbell { .. } => Label::PortDoorbell,
            Self::ReportError { .. } => Label::ReportError,
            Self::ApplicationMessage { .. } => Label::ApplicationMessage,
            Self::SetModuleSchedule { .. } => Label::SetModuleSchedule,
            Self::ModuleScheduleStatus => Label::ModuleScheduleStatus,
            Self::ModuleScheduleId { .. } => Label::ModuleScheduleId,
            Self::StageMessage { .. } => Label::StageMessage,
            Self::FetchMessage { .. } => Label::FetchMessage,
        }
    }

    /// The port a port request names (`None` for the others).
    pub const fn port(&self) -> Option<PortId> {
        match *self {
            Self::WriteSampling { port, .. }
            | Self::ReadSampling { port }
            | Self::SamplingStatus { port }
            | Self::SendQueuing { port, .. }
            | Self::ReceiveQueuing { port, .. }
            | Self::QueuingStatus { port }
            | Self::ClearQueuing { port }
            | Self::PortDoorbell { port, .. } => Some(port),
            _ => None,
        }
    }

    /// The request as label, words and data.
    pub fn encode(&self) -> Wire<'a> {
        let (words, data): ([u64; 3], &'a [u8]) = match *self {
            Self::PartitionStatus => ([0; 3], &[]),
            Self::SetPartitionMode { mode } => ([u64::from(mode.code()), 0, 0], &[]),
            Self::CreatePort {
                kind,
                direction,
                discipline,
                max_message_size,
                refresh_or_depth,
                name,
            } => (
                [
                    u64::from(kind.code())
                        | u64::from(direction.code()) << 8
                        | u64::from(discipline.code()) << 16,
                    max_message_size,
                    refresh_or_depth,
                ],
                name,
            ),
            Self::PortId { kind, name } => ([u64::from(kind.code()), 0, 0], name),
            Self::WriteSampling {
                port,
                staged,
                message,
            } => ([port, staged, 0], message),
            Self::ReadSampling { port }
            | Self::SamplingStatus { port }
            | Self::QueuingStatus { port }
            | Self::ClearQueuing { port } => ([port, 0, 0], &[]),
            Self::SendQueuing {
                port,
                timeout,
                priority,
                staged,
                message,
            } => ([port, timeout, u64::from(priority) | staged << 8], message),
            Self::ReceiveQueuing {
                port,
                timeout,
                priority,
            } => ([port, timeout, u64::from(priority)], &[]),
            Self::PortDoorbell { port, bits } => ([port, bits, 0], &[]),
            Self::ReportError { error, detail } => ([u64::from(error.code()), 0, 0], detail),
            Self::ApplicationMessage { text } => ([0; 3], text),
            Self::SetModuleSchedule { schedule } => ([schedule, 0, 0], &[]),
            Self::ModuleScheduleStatus => ([0; 3], &[]),
            Self::ModuleScheduleId { name } => ([0; 3], name),
            Self::StageMessage { offset, part } => ([offset, 0, 0], part),
            Self::FetchMessage { offset } => ([offset, 0, 0], &[]),
        };
        Wire {
            label: self.label().code(),
            words,
            data,
        }
    }

    /// The request a label, its words and data carry.
    pub fn decode(wire: Wire<'a>) -> Result<Self, DecodeError> {
        let [w0, w1, w2] = wire.words;
        let label = Label::from_code(wire.label).ok_or(DecodeError::UnknownLabel(wire.label))?;
        let kind = |word: u64| PortKind::from_u64(word).ok_or(DecodeError::UnknownPortKind(word));
        let priority = |word: u64| u8::try_from(word).map_err(|_| DecodeError::BadPriority(word));
        Ok(match label {
            Label::PartitionStatus => Self::PartitionStatus,
            Label::SetPartitionMode => Self::SetPartitionMode {
                mode: OperatingMode::from_u64(w0).ok_or(DecodeError::UnknownMode(w0))?,
            },
            Label::CreatePort => Self::CreatePort {
                kind: kind(w0 & 0xff)?,
                direction: Direction::from_u64(w0 >> 8 & 0xff)
                    .ok_or(DecodeError::UnknownDirection(w0 >> 8 & 0xff))?,
                discipline: Discipline::from_u64(w0 >> 16 & 0xff)
                    .ok_or(DecodeError::UnknownDiscipline(w0 >> 16 & 0xff))?,
                max_message_size: w1,
                refresh_or_depth: w2,
                name: wire.data,
            },
            Label::PortId => Self::PortId {
                kind: kind(w0)?,
                name: wire.data,
            },
            Label::WriteSampling => Self::WriteSampling {
                port: w0,
                staged: w1,
                message: wire.data,
            },
            Label::ReadSampling => Self::ReadSampling { port: w0 },
            Label::SamplingStatus => Self::SamplingStatus { port: w0 },
            Label::SendQueuing => Self::SendQueuing {
                port: w0,
                timeout: w1,
                priority: (w2 & 0xff) as u8,
                staged: w2 >> 8,
                message: wire.data,
            },
            Label::ReceiveQueuing => Self::ReceiveQueuing {
                port: w0,
                timeout: w1,
                priority: priority(w2)?,
            },
            Label::QueuingStatus => Self::QueuingStatus { port: w0 },
            Label::ClearQueuing => Self::ClearQueuing { port: w0 },
            Label::PortDoorbell => Self::PortDoorbell { port: w0, bits: w1 },
            Label::ReportError => Self::ReportError {
                error: ErrorCode::from_u64(w0).ok_or(DecodeError::UnknownError(w0))?,
                detail: wire.data,
            },
            Label::ApplicationMessage => Self::ApplicationMessage { text: wire.data },
            Label::SetModuleSchedule => Self::SetModuleSchedule { schedule: w0 },
            Label::ModuleScheduleStatus => Self::ModuleScheduleStatus,
            Label::ModuleScheduleId => Self::ModuleScheduleId { name: wire.data },
            Label::StageMessage => Self::StageMessage {
                offset: w0,
                part: wire.data,
            },
            Label::FetchMessage => Self::FetchMessage { offset: w0 },
        })
    }
}

/// A reply's label as a result: `Ok` for NO_ERROR, else the ARINC code; a label outside
/// the ARINC range is a decode error (a protocol fault of the server).
pub fn reply_result(label: u32) -> Result<Result<(), ReturnCode>, DecodeError> {
    match ReturnCode::from_code(label) {
        Some(ReturnCode::NoError) => Ok(Ok(())),
        Some(code) => Ok(Err(code)),
        None => Err(DecodeError::UnknownReturnCode(label)),
    }
}

/// The reply words of the requests that answer with words; each has one encoder and one
/// decoder. Replies without words (and their data, which stays in the IPC buffer) need none.
pub trait ReplyWords: Sized {
    fn to_words(&self) -> [u64; 3];
    fn from_words(words: [u64; 3]) -> Result<Self, DecodeError>;
}

fn byte_code<T>(word: u64, decode: impl FnOnce(u64) -> Option<T>) -> Result<T, DecodeError> {
    decode(word).ok_or(DecodeError::BadReplyWord(word))
}

/// Reply to PARTITION_STATUS.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PartitionStatus {
    pub mode: OperatingMode,
    pub start_condition: StartCondition,
    /// The partition's index in the configuration.
    pub index: u64,
    pub period_ns: u64,
    pub duration_ns: u64,
}

impl ReplyWords for PartitionStatus {
    fn to_words(&self) -> [u64; 3] {
        [
            u64::from(self.mode.code())
                | u64::from(self.start_condition.code()) << 8
                | self.index << 16,
            self.period_ns,
            self.duration_ns,
        ]
    }

    fn from_words([w0, period_ns, duration_ns]: [u64; 3]) -> Result<Self, DecodeError> {
        Ok(Self {
            mode: byte_code(w0 & 0xff, OperatingMode::from_u64)?,
            start_condition: byte_code(w0 >> 8 & 0xff, StartCondition::from_u64)?,
            index: w0 >> 16,
            period_ns,
            duration_ns,
        })
    }
}

/// Reply to CREATE_PORT and PORT_ID.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PortIdReply {
    pub port: PortId,
}

impl ReplyWords for PortIdReply {
    fn to_words(&self) -> [u64; 3] {
        [self.port, 0, 0]
    }

    fn from_words([port, _, _]: [u64; 3]) -> Result<Self, DecodeError> {
        Ok(Self { port })
    }
}

/// Reply to MODULE_SCHEDULE_ID.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ScheduleIdReply {
    pub schedule: u64,
}

impl ReplyWords for ScheduleIdReply {
    fn to_words(&self) -> [u64; 3] {
        [self.schedule, 0, 0]
    }

    fn from_words([schedule, _, _]: [u64; 3]) -> Result<Self, DecodeError> {
        Ok(Self { schedule })
    }
}

/// Reply to MODULE_SCHEDULE_STATUS (ARINC 653 Part 2 `SCHEDULE_STATUS_TYPE`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ScheduleStatus {
    /// When the running schedule took over from another (ns since boot); 0 if it is the
    /// initial one.
    pub last_switch: u64,
    pub current: u64,
    /// The schedule from the next major-frame boundary (the current one if no switch is
    /// pending).
    pub next: u64,
}

impl ReplyWords for ScheduleStatus {
    fn to_words(&self) -> [u64; 3] {
        [self.last_switch, self.current, self.next]
    }

    fn from_words([last_switch, current, next]: [u64; 3]) -> Result<Self, DecodeError> {
        Ok(Self {
            last_switch,
            current,
            next,
        })
    }
}

/// Reply to READ_SAMPLING (the message is the reply's data).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SamplingMessage {
    pub len: u64,
    pub validity: Validity,
}

impl ReplyWords for SamplingMessage {
    fn to_words(&self) -> [u64; 3] {
        [self.len, u64::from(self.validity.code()), 0]
    }

    fn from_words([len, validity, _]: [u64; 3]) -> Result<Self, DecodeError> {
        Ok(Self {
            len,
            validity: byte_code(validity, Validity::from_u64)?,
        })
    }
}

/// Reply to SAMPLING_STATUS (ARINC 653 `SAMPLING_PORT_STATUS_TYPE`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SamplingStatus {
    pub max_message_size: u32,
    pub direction: Direction,
    /// Refresh period in ns (0 = none, and always 0 for a source port).
    pub refresh_period: u64,
    /// Validity of the last message this port read (`Invalid` for a source port or before
    /// the first read).
    pub last_msg_validity: Validity,
}

impl ReplyWords for SamplingStatus {
    fn to_words(&self) -> [u64; 3] {
        [
            u64::from(self.max_message_size) | u64::from(self.direction.code()) << 32,
            self.refresh_period,
            u64::from(self.last_msg_validity.code()),
        ]
    }

    fn from_words(
        [size_direction, refresh_period, validity]: [u64; 3],
    ) -> Result<Self, DecodeError> {
        Ok(Self {
            max_message_size: size_direction as u32,
            direction: byte_code(size_direction >> 32, Direction::from_u64)?,
            refresh_period,
            last_msg_validity: byte_code(validity, Validity::from_u64)?,
        })
    }
}

/// Reply to RECEIVE_QUEUING (the message is the reply's data; length 0 on a time-out).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QueuingMessage {
    pub len: u64,
}

impl ReplyWords for QueuingMessage {
    fn to_words(&self) -> [u64; 3] {
        [self.len, 0, 0]
    }

    fn from_words([len, _, _]: [u64; 3]) -> Result<Self, DecodeError> {
        Ok(Self { len })
    }
}

/// Reply to FETCH_MESSAGE (the part is the reply's data).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FetchReply {
    /// Bytes of the message after this part (0: the staging buffer is free again).
    pub left: u64,
}

impl ReplyWords for FetchReply {
    fn to_words(&self) -> [u64; 3] {
        [self.left, 0, 0]
    }

    fn from_words([left, _, _]: [u64; 3]) -> Result<Self, DecodeError> {
        Ok(Self { left })
    }
}

/// Reply to QUEUING_STATUS (ARINC 653 `QUEUING_PORT_STATUS_TYPE`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QueuingStatus {
    /// Messages in the port.
    pub nb_message: u32,
    /// The port's configured depth.
    pub max_nb_message: u32,
    pub max_message_size: u32,
    pub direction: Direction,
    /// Processes waiting on the port.
    pub waiting_processes: u32,
}

impl ReplyWords for QueuingStatus {
    fn to_words(&self) -> [u64; 3] {
        [
            u64::from(self.nb_message) | u64::from(self.max_nb_message) << 32,
            u64::from(self.max_message_size) | u64::from(self.direction.code()) << 32,
            u64::from(self.waiting_processes),
        ]
    }

    fn from_words([messages, size_direction, waiting]: [u64; 3]) -> Result<Self, DecodeError> {
        Ok(Self {
            nb_message: messages as u32,
            max_nb_message: (messages >> 32) as u32,
            max_message_size: size_direction as u32,
            direction: byte_code(size_direction >> 32, Direction::from_u64)?,
            waiting_processes: u32::try_from(waiting)
                .map_err(|_| DecodeError::BadReplyWord(waiting))?,
        })
    }
}

#[cfg(test)]
mod tests;
