//! The management protocol on a pair of message ports (an ARINC 653 queuing port pair from
//! a client in the Linux guest; a TCP connection carries the same requests in 4diac's
//! framing, [`crate::tcp`], answered by the same [`serve_parts`]): one request a message,
//! `destination;request` as a boot-file line holds it (UTF-8, the destination empty for
//! the device), answered by one message, the response. A response
//! longer than the port's messages is replaced by the request's refusal with OVERFLOW.
//! What a client may do depends on its configured [`Access`]; a request beyond it is
//! refused with ACCESS_DENIED and changes nothing.

use crate::Device;
use crate::request::{Action, Object, Reason, Request, response};
use alloc::string::String;
use alloc::vec::Vec;

/// How a request reaches the device: directly, or, in a partition whose processes share the
/// device, under their lock, held only while the request is carried out (the request is
/// read, checked against the client's access and its response sized outside it).
pub trait DeviceAccess {
    /// [`Device::carry_out`].
    fn carry_out(&mut self, destination: &str, request: &Request, now: i64) -> String;
}

impl DeviceAccess for Device {
    fn carry_out(&mut self, destination: &str, request: &Request, now: i64) -> String {
        Device::carry_out(self, destination, request, now)
    }
}

/// What a management client may do (the names and codes of the PLC's online access levels).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Access {
    /// READ and QUERY; create and delete watches.
    Monitor = 0,
    /// And WRITE: parameters, forcing, event triggers.
    Force = 1,
    /// And everything else: resources, FBs, connections, START/STOP/KILL/RESET, types.
    Download = 2,
}

impl Access {
    /// The level of code `code` (0, 1, 2).
    pub fn from_code(code: u8) -> Option<Self> {
        [Access::Monitor, Access::Force, Access::Download]
            .into_iter()
            .find(|a| *a as u8 == code)
    }

    /// The level `request` needs.
    pub fn needed(request: &Request) -> Access {
        match (&request.action, &request.object) {
            (Action::Read | Action::Query, _) => Access::Monitor,
            (Action::Create | Action::Delete, Object::Watch { .. }) => Access::Monitor,
            (Action::Write, _) => Access::Force,
            _ => Access::Download,
        }
    }
}

/// Answers one request message from a client of level `access` at instant `now`; the
/// response fits in `max_response` bytes.
pub fn serve(
    device: &mut impl DeviceAccess,
    message: &[u8],
    access: Access,
    max_response: usize,
    now: i64,
) -> String {
    match message.iter().position(|&b| b == b';') {
        Some(at) => serve_parts(
            device,
            &message[..at],
            &message[at + 1..],
            access,
            max_response,
            now,
        ),
        None => refusal(Reason::BadParams),
    }
}

/// Answers one request, its `destination` (empty: the device) and its XML `request` apart
/// (as the TCP framing carries them, [`crate::tcp`]; [`serve`] splits a message into
/// them): the one place a client's request is read, checked against its `access` and
/// carried out. The response fits in `max_response` bytes.
pub fn serve_parts(
    device: &mut impl DeviceAccess,
    destination: &[u8],
    request: &[u8],
    access: Access,
    max_response: usize,
    now: i64,
) -> String {
    let (Ok(destination), Ok(text)) = (
        core::str::from_utf8(destination),
        core::str::from_utf8(request),
    ) else {
        return refusal(Reason::BadParams);
    };
    let (destination, text) = (destination.trim(), text.trim());
    let answer = match Request::parse(text) {
        Err((id, reason)) => response(&id, Some(reason), None),
        Ok(request) if Access::needed(&request) > access => {
            response(&request.id, Some(Reason::AccessDenied), None)
        }
        Ok(request) => {
            let answer = device.carry_out(destination, &request, now);
            if answer.len() > max_response {
                response(&request.id, Some(Reason::Overflow), None)
            } else {
                answer
            }
        }
    };
    if answer.len() > max_response {
        // Only an absurd ID can make a refusal too long.
        return refusal(Reason::Overflow);
    }
    answer
}

/// The refusal of a request whose ID could not be read (`<Response ID="" Reason=... />`,
/// 40 bytes at most).
pub fn refusal(reason: Reason) -> String {
    response("", Some(reason), None)
}

/// The request messages that send type `name`'s `package` in parts (each at most
/// `max_message` bytes, IDs from `first_id`): what a client sends to add or replace a type.
pub fn type_messages(name: &str, package: &[u8], max_message: usize, first_id: u32) -> Vec<String> {
    use base64::Engine as _;
    let name = crate::request::escape(name);
    let frame = |id: u32, offset: usize, data: &str| {
        alloc::format!(
            ";<Request ID=\"{id}\" Action=\"CREATE\"><FBType Name=\"{name}\" Offset=\"{offset}\" Size=\"{}\" Data=\"{data}\"/></Request>",
            package.len()
        )
    };
    // Base64 takes 4 characters per 3 bytes; the rest of a message is the frame.
    let overhead = frame(u32::MAX, package.len(), "").len();
    let per_part = (max_message.saturating_sub(overhead) / 4 * 3).max(3);
    let mut out = Vec::new();
    let mut offset = 0;
    let mut id = first_id;
    while offset < package.len() || out.is_empty() {
        let end = (offset + per_part).min(package.len());
        let data = base64::engine::general_purpose::STANDARD.encode(&package[offset..end]);
        out.push(frame(id, offset, &data));
        offset = end;
        id = id.wrapping_add(1);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use iec61499_runtime::Limits;

    fn ask(d: &mut Device, access: Access, message: &str) -> String {
        serve(d, message.as_bytes(), access, 4096, 0)
    }

    fn reason(answer: &str) -> &str {
        answer
            .split("Reason=\"")
            .nth(1)
            .and_then(|r| r.split('"').next())
            .unwrap_or("")
    }

    const CREATE_RES: &str =
        ";<Request ID=\"1\" Action=\"CREATE\"><FB Name=\"R\" Type=\"EMB_RES\"/></Request>";
    const CREATE_CTU: &str =
        "R;<Request ID=\"2\" Action=\"CREATE\"><FB Name=\"C\" Type=\"E_CTU\"/></Request>";

    #[test]
    fn access_levels() {
        let mut d = Device::new(Limits::default(), 4);
        assert_eq!(
            reason(&ask(&mut d, Access::Force, CREATE_RES)),
            "ACCESS_DENIED"
        );
        assert_eq!(reason(&ask(&mut d, Access::Download, CREATE_RES)), "");
        assert_eq!(reason(&ask(&mut d, Access::Download, CREATE_CTU)), "");
        let write = "R;<Request ID=\"3\" Action=\"WRITE\"><Connection Source=\"5\" Destination=\"C.PV\"/></Request>";
        assert_eq!(
            reason(&ask(&mut d, Access::Monitor, write)),
            "ACCESS_DENIED"
        );
        assert_eq!(reason(&ask(&mut d, Access::Force, write)), "");
        let watch = "R;<Request ID=\"4\" Action=\"CREATE\"><Watch Source=\"C.CV\" Destination=\"*\"/></Request>";
        assert_eq!(reason(&ask(&mut d, Access::Monitor, watch)), "");
        let read =
            "R;<Request ID=\"5\" Action=\"READ\"><Watch Source=\"*\" Destination=\"*\"/></Request>";
        let answer = ask(&mut d, Access::Monitor, read);
        assert!(answer.contains("<Port name=\"CV\">"), "{answer}");
        assert_eq!(
            reason(&ask(
                &mut d,
                Access::Monitor,
                "R;<Request ID=\"6\" Action=\"START\"/>"
            )),
            "ACCESS_DENIED"
        );
        let stop_all =
            ";<Request ID=\"7\" Action=\"DELETE\"><FB Name=\"R\" Type=\"EMB_RES\"/></Request>";
        assert_eq!(
            reason(&ask(&mut d, Access::Force, stop_all)),
            "ACCESS_DENIED"
        );
        assert_eq!(Access::from_code(2), Some(Access::Download));
        assert_eq!(Access::from_code(3), None);
    }

    #[test]
    fn malformed_messages_and_long_responses_are_refused() {
        let mut d = Device::new(Limits::default(), 4);
        assert_eq!(
            reason(&ask(&mut d, Access::Download, "no separator")),
            "BAD_PARAMS"
        );
        assert_eq!(
            reason(&serve(&mut d, &[0xff, b';'], Access::Download, 4096, 0)),
            "BAD_PARAMS"
        );
        assert_eq!(
            reason(&ask(&mut d, Access::Download, ";<Request")),
            "BAD_PARAMS"
        );
        ask(&mut d, Access::Download, CREATE_RES);
        let query = "R;<Request ID=\"9\" Action=\"QUERY\"><FB Name=\"*\" Type=\"*\"/></Request>";
        let short = serve(&mut d, query.as_bytes(), Access::Monitor, 40, 0);
        assert_eq!(reason(&short), "OVERFLOW");
        assert!(short.len() <= 40, "{short}");
    }

    proptest::proptest! {
        #[test]
        fn arbitrary_messages_never_panic(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..300)) {
            let mut d = Device::new(Limits::default(), 4);
            let answer = serve(&mut d, &bytes, Access::Download, 4096, 0);
            proptest::prop_assert!(answer.starts_with("<Response"));
        }
    }
}
