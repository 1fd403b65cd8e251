//! The PLC side of the online protocol (`plc-online`): answers one request against the
//! running program. The control process calls it after the tasks of a release (at most
//! [`REQUESTS_PER_CYCLE`] requests per release), so a request always sees and changes a
//! consistent image and a flood of requests costs each cycle a bounded amount of work.
//! A DOWNLOAD_COMMIT that passes every check ends the batch: the caller swaps the new
//! program in before the next release ([`Loader::committed`]).

#[cfg(any(feature = "net", test))]
use crate::comm::{Exchange, Service, SlotState};
use crate::download::{Download, Refusal, Takeover, check_program, fit_configuration, take_over};
use crate::package::Package;
use crate::scan::{MAX_TASKS, PortIo, Runtime};
use plc_online::{
    Access, MAX_CHUNK, MAX_MESSAGE, Op, PROTOCOL_VERSION, Request, Status, TaskStats,
    begin_response, decode_request, put_stats, put_store_status,
};
use plc_vm::image::{Image, VarType};
use plc_vm::vm::{Machine, VarError};

/// Requests served per release of the control process.
pub const REQUESTS_PER_CYCLE: usize = 4;

fn status_of(e: VarError) -> Status {
    match e {
        VarError::UnknownName => Status::UnknownName,
        VarError::TypeMismatch => Status::TypeMismatch,
        VarError::Constant => Status::Constant,
        VarError::NotForceable => Status::Unsupported,
        VarError::TooManyForces => Status::TooManyForces,
        VarError::ReadOnly => Status::ReadOnly,
    }
}

/// The download side of a PLC: the buffer a new program is assembled in, the verifier's
/// scratch, the limits a program must meet, and the outcome of the last commit.
pub struct Loader<'b> {
    /// Where the chunks go (the image buffer the running program does not use).
    pub buffer: &'b mut [u8],
    /// Verifier scratch, two cells per code byte.
    pub scratch: &'b mut [u32],
    /// Data memory a program may use.
    pub max_data: usize,
    /// The partition's period.
    pub period_ns: u64,
    /// The release number of the running program's first release (its releases count on
    /// from there), to tell a client from which release a committed program runs.
    pub first_release: u64,
    download: Download,
    /// A verified download waiting to be swapped in: its length in `buffer` and what it
    /// takes over from the running program.
    pub committed: Option<(usize, Takeover)>,
    /// Why the last commit was refused (for the log), taken by the caller.
    pub refusal: Option<Refusal>,
}

impl<'b> Loader<'b> {
    pub fn new(
        buffer: &'b mut [u8],
        scratch: &'b mut [u32],
        max_data: usize,
        period_ns: u64,
        first_release: u64,
    ) -> Self {
        Self {
            buffer,
            scratch,
            max_data,
            period_ns,
            first_release,
            download: Download::new(),
            committed: None,
            refusal: None,
        }
    }

    /// DOWNLOAD_COMMIT: the assembled image checked as at start and taken over from the
    /// running program; on success [`Loader::committed`] holds it.
    fn commit(&mut self, package: &Package, machine: &Machine, rt: &Runtime) -> Result<(), Status> {
        let len = self.download.finish(self.buffer)?.len();
        let checked = check_program(
            &self.buffer[..len],
            self.scratch,
            self.max_data,
            self.period_ns,
        )
        .and_then(|(verified, schedule)| {
            fit_configuration(verified.image(), schedule, package)?;
            take_over(
                machine.image(),
                verified.image(),
                &rt.safe,
                machine.forced(),
                package.watch(),
            )
        });
        match checked {
            Ok(takeover) => {
                self.committed = Some((len, takeover));
                Ok(())
            }
            Err(refusal) => {
                self.refusal = Some(refusal);
                Err(Status::Refused)
            }
        }
    }
}

/// Answers the requests waiting on the package's online request port (at most
/// [`REQUESTS_PER_CYCLE`], fewer when a download is committed) on its response port;
/// returns how many.
pub fn serve_pending(
    package: &Package,
    io: &mut impl PortIo,
    machine: &mut Machine,
    image: &Image,
    rt: &mut Runtime,
    loader: &mut Loader,
) -> usize {
    let Some(online) = package.online() else {
        return 0;
    };
    let mut served = 0;
    let mut request = [0u8; MAX_MESSAGE];
    let mut response = [0u8; MAX_MESSAGE];
    while served < REQUESTS_PER_CYCLE && loader.committed.is_none() {
        let Some((len, _)) = io.receive(online.request, &mut request) else {
            break;
        };
        let len = len.min(MAX_MESSAGE);
        let n = serve(
            &request[..len],
            online.access,
            package,
            machine,
            image,
            rt,
            loader,
            &mut response,
        );
        io.send(online.response, &response[..n]);
        served += 1;
    }
    served
}

/// Answers the online requests waiting in the communication process's exchange (the online
/// protocol on TCP, [`crate::comm`]), each for the access of the client that sent it: at
/// most [`REQUESTS_PER_CYCLE`], none once a download is committed. Returns how many.
#[cfg(any(feature = "net", test))]
pub fn serve_exchange(
    exchange: &mut Exchange,
    package: &Package,
    machine: &mut Machine,
    image: &Image,
    rt: &mut Runtime,
    loader: &mut Loader,
) -> usize {
    let mut served = 0;
    for slot in exchange.slots.iter_mut() {
        if served >= REQUESTS_PER_CYCLE || loader.committed.is_some() {
            break;
        }
        let (SlotState::Request, Service::Online(access)) = (slot.state, slot.service) else {
            continue;
        };
        let mut response = [0u8; MAX_MESSAGE];
        let request = &slot.bytes[..slot.len.min(MAX_MESSAGE)];
        let n = serve(
            request,
            access,
            package,
            machine,
            image,
            rt,
            loader,
            &mut response,
        );
        slot.bytes[..n].copy_from_slice(&response[..n]);
        slot.len = n;
        slot.state = SlotState::Response;
        served += 1;
    }
    served
}

/// Answers `request` (raw bytes) for a client allowed `access`; returns the response length
/// in `out` (at least [`MAX_MESSAGE`] bytes).
// The request touches the whole running PLC; a bundle would only rename these.
#[allow(clippy::too_many_arguments)]
pub fn serve(
    request: &[u8],
    access: Access,
    package: &Package,
    machine: &mut Machine,
    image: &Image,
    rt: &mut Runtime,
    loader: &mut Loader,
    out: &mut [u8; MAX_MESSAGE],
) -> usize {
    let (seq, request) = match decode_request(request) {
        Ok(decoded) => decoded,
        Err((op, seq)) => return begin_response(op, seq, Status::Malformed, out).len(),
    };
    let op = request.op();
    if op.needs().code() > access.code() {
        return begin_response(op.code(), seq, Status::Forbidden, out).len();
    }
    let done = |out: &mut [u8; MAX_MESSAGE], result: Result<(), VarError>| match result {
        Ok(()) => begin_response(op.code(), seq, Status::Ok, out).len(),
        Err(e) => begin_response(op.code(), seq, status_of(e), out).len(),
    };
    match request {
        Request::List { from } => {
            let total = image.var_count();
            let mut w = begin_response(Op::List.code(), seq, Status::Ok, out);
            let _ = w.put(&(total.min(u16::MAX as usize) as u16).to_le_bytes());
            let count_at = w.len();
            let _ = w.put(&[0]);
            let mut count = 0u8;
            for v in (from as usize..total).filter_map(|i| image.var(i)) {
                let name = &v.name.as_bytes()[..v.name.len().min(u8::MAX as usize)];
                if w.room() < 2 + name.len() || count == u8::MAX {
                    break;
                }
                let _ = w.put(&[v.ty, name.len() as u8]);
                let _ = w.put(name);
                count += 1;
            }
            let len = w.len();
            out[count_at] = count;
            len
        }
        Request::Read { name } => {
            let Some(var) = machine.image().find_var(name) else {
                return done(out, Err(VarError::UnknownName));
            };
            let ty = VarType::from_code(var.ty).expect("verified");
            let mut w = begin_response(Op::Read.code(), seq, Status::Ok, out);
            if w.typed_value(ty, &machine.read_entry(&var)).is_none() {
                // A text longer than a message: say so rather than cut it.
                return begin_response(op.code(), seq, Status::Unsupported, out).len();
            }
            w.len()
        }
        // Any integer fits an integer variable and references are refused
        // ([`plc_vm::vm::Value::to_cell`]).
        Request::Write { name, value } => done(out, machine.write_var(name, value)),
        Request::Force { name, value } => done(out, machine.force_var(name, value)),
        Request::Unforce { name } => done(out, machine.unforce_var(name)),
        Request::Stats { task } => {
            let task = task as usize;
            let Some(t) = image.task(task).filter(|_| task < MAX_TASKS) else {
                return begin_response(op.code(), seq, Status::NoSuchTask, out).len();
            };
            let s = &rt.stats[task];
            let stats = TaskStats {
                name: t.name,
                stopped: rt.stopped[task].is_some(),
                figures: [
                    s.count,
                    s.last,
                    s.min,
                    s.mean(),
                    s.max,
                    s.last_jitter,
                    s.max_jitter,
                    s.overruns,
                    s.faults,
                ],
            };
            let mut w = begin_response(Op::Stats.code(), seq, Status::Ok, out);
            let _ = put_stats(&mut w, &stats);
            w.len()
        }
        Request::Stop { task } | Request::Start { task } => {
            let known = if op == Op::Stop {
                rt.stop_task(task as usize, machine)
            } else {
                rt.start_task(task as usize, machine)
            };
            let status = if known {
                Status::Ok
            } else {
                Status::NoSuchTask
            };
            begin_response(op.code(), seq, status, out).len()
        }
        Request::DownloadBegin { size, crc32 } => {
            match loader.download.begin(size, crc32, loader.buffer.len()) {
                Ok(()) => {
                    let mut w = begin_response(op.code(), seq, Status::Ok, out);
                    let _ = w.put(&(MAX_CHUNK as u16).to_le_bytes());
                    w.len()
                }
                Err(status) => begin_response(op.code(), seq, status, out).len(),
            }
        }
        Request::DownloadChunk { offset, bytes } => {
            let status = match loader.download.chunk(loader.buffer, offset, bytes) {
                Ok(()) => Status::Ok,
                Err(status) => status,
            };
            begin_response(op.code(), seq, status, out).len()
        }
        Request::Version => {
            let mut w = begin_response(op.code(), seq, Status::Ok, out);
            let _ = w.put(&PROTOCOL_VERSION.to_le_bytes());
            w.len()
        }
        Request::Store => {
            let mut w = begin_response(op.code(), seq, Status::Ok, out);
            let _ = put_store_status(&mut w, &crate::persist::STATUS.get());
            w.len()
        }
        Request::DownloadCommit => match loader.commit(package, machine, rt) {
            Ok(()) => {
                let mut w = begin_response(op.code(), seq, Status::Ok, out);
                let _ = w.put(&(loader.first_release + rt.releases).to_le_bytes());
                w.len()
            }
            Err(status) => begin_response(op.code(), seq, status, out).len(),
        },
    }
}
