//! The PLC side of the online protocol (`plc-online`): answers one request against the
//! running program. The scan process calls it between cycles (at most
//! [`REQUESTS_PER_CYCLE`] requests per release), so a request always sees and changes a
//! consistent image and a flood of requests costs each cycle a bounded amount of work.

use crate::package::Package;
use crate::scan::{MAX_TASKS, PortIo, Runtime};
use plc_online::{
    Access, MAX_MESSAGE, Op, Request, Status, TaskStats, begin_response, decode_request, put_stats,
};
use plc_vm::image::{Image, VarType};
use plc_vm::vm::{Machine, VarError};

/// Requests served per release of the scan process.
pub const REQUESTS_PER_CYCLE: usize = 4;

fn status_of(e: VarError) -> Status {
    match e {
        VarError::UnknownName => Status::UnknownName,
        VarError::TypeMismatch => Status::TypeMismatch,
        VarError::Constant => Status::Constant,
        VarError::NotForceable => Status::Unsupported,
        VarError::TooManyForces => Status::TooManyForces,
    }
}

/// Answers the requests waiting on the package's online request port (at most
/// [`REQUESTS_PER_CYCLE`]) on its response port; returns how many.
pub fn serve_pending(
    package: &Package,
    io: &mut impl PortIo,
    machine: &mut Machine,
    image: &Image,
    rt: &Runtime,
) -> usize {
    let Some(online) = package.online() else {
        return 0;
    };
    let mut served = 0;
    let mut request = [0u8; MAX_MESSAGE];
    let mut response = [0u8; MAX_MESSAGE];
    while served < REQUESTS_PER_CYCLE {
        let Some((len, _)) = io.receive(online.request, &mut request) else {
            break;
        };
        let len = len.min(MAX_MESSAGE);
        let n = serve(
            &request[..len],
            online.access,
            machine,
            image,
            rt,
            &mut response,
        );
        io.send(online.response, &response[..n]);
        served += 1;
    }
    served
}

/// Answers `request` (raw bytes) for a client allowed `access`; returns the response length
/// in `out` (at least [`MAX_MESSAGE`] bytes).
pub fn serve(
    request: &[u8],
    access: Access,
    machine: &mut Machine,
    image: &Image,
    rt: &Runtime,
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
        Request::Read { name } => match machine.read_var(name) {
            Ok(value) => {
                let mut w = begin_response(Op::Read.code(), seq, Status::Ok, out);
                if w.value(&value).is_none() {
                    // A STRING longer than a message: say so rather than cut it.
                    return begin_response(op.code(), seq, Status::Unsupported, out).len();
                }
                w.len()
            }
            Err(e) => done(out, Err(e)),
        },
        Request::Write { name, value } => {
            let converted = convert(image, name, value);
            done(out, converted.and_then(|v| machine.write_var(name, v)))
        }
        Request::Force { name, value } => {
            let converted = convert(image, name, value);
            done(out, converted.and_then(|v| machine.force_var(name, v)))
        }
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
    }
}

/// The wire value in the variable's own kind: the protocol carries integers as 64 bits,
/// the VM wants signed values for signed types and unsigned ones for the others.
fn convert<'v>(
    image: &Image,
    name: &str,
    value: plc_vm::vm::Value<'v>,
) -> Result<plc_vm::vm::Value<'v>, VarError> {
    use plc_vm::vm::Value;
    let var = image.find_var(name).ok_or(VarError::UnknownName)?;
    let ty = VarType::from_code(var.ty).ok_or(VarError::TypeMismatch)?;
    let signed = matches!(
        ty,
        VarType::SInt | VarType::Int | VarType::DInt | VarType::LInt
    );
    Ok(match value {
        Value::UInt(v) if signed => Value::Int(v as i64),
        Value::Int(v) if !signed && ty != VarType::Time => Value::UInt(v as u64),
        other => other,
    })
}
