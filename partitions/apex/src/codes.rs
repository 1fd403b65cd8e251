//! Conversions between a653rs's APEX types and the service protocol's (`syssw/protocol`),
//! and ARINC names (pure: no system calls, host-tested). The codes themselves are defined
//! once, in the protocol crate; a653rs numbers them as ARINC does, and so does the protocol.

use a653rs::bindings::{
    ApexName, ErrorCode as ApexErrorCode, ErrorReturnCode, OperatingMode as ApexMode,
    PortDirection, QueuingDiscipline, Validity as ApexValidity,
};
use protocol::{Direction, Discipline, ErrorCode, OperatingMode, Validity, reply_result};

/// A protocol reply label (an ARINC 653 `RETURN_CODE_TYPE`) as a result.
///
/// A label outside the ARINC range would be a protocol fault of syssw; it is reported as
/// `NOT_AVAILABLE` (the service could not be performed) rather than trusted or panicked on.
pub fn from_reply(label: u32) -> Result<(), ErrorReturnCode> {
    match reply_result(label) {
        Ok(Ok(())) => Ok(()),
        // In range (the protocol decoded it), so a653rs's decoder cannot panic on it.
        Ok(Err(code)) => ErrorReturnCode::from(code.code()),
        Err(_) => Err(ErrorReturnCode::NotAvailable),
    }
}

/// A port direction as the protocol carries it (ARINC SOURCE = the partition's `out`).
pub fn direction(direction: PortDirection) -> Direction {
    match direction {
        PortDirection::Source => Direction::Out,
        PortDirection::Destination => Direction::In,
    }
}

/// A queuing discipline as the protocol carries it.
pub fn discipline(discipline: QueuingDiscipline) -> Discipline {
    match discipline {
        QueuingDiscipline::Fifo => Discipline::Fifo,
        QueuingDiscipline::Priority => Discipline::Priority,
    }
}

/// The APEX direction of a protocol direction.
pub fn port_direction(direction: Direction) -> PortDirection {
    match direction {
        Direction::Out => PortDirection::Source,
        Direction::In => PortDirection::Destination,
    }
}

/// The APEX validity of a protocol validity.
pub fn validity(validity: Validity) -> ApexValidity {
    match validity {
        Validity::Valid => ApexValidity::Valid,
        Validity::Invalid => ApexValidity::Invalid,
    }
}

/// The protocol's operating mode for an APEX one (both ARINC-numbered).
pub fn mode(mode: ApexMode) -> Option<OperatingMode> {
    OperatingMode::from_u64(mode as u64)
}

/// The protocol's error code for an APEX one (both ARINC-numbered).
pub fn error_code(code: ApexErrorCode) -> Option<ErrorCode> {
    ErrorCode::from_u64(code as u64)
}

/// The APEX error code of a protocol one (both ARINC-numbered).
pub fn apex_error_code(code: ErrorCode) -> ApexErrorCode {
    match code {
        ErrorCode::DeadlineMissed => ApexErrorCode::DeadlineMissed,
        ErrorCode::ApplicationError => ApexErrorCode::ApplicationError,
        ErrorCode::NumericError => ApexErrorCode::NumericError,
        ErrorCode::IllegalRequest => ApexErrorCode::IllegalRequest,
        ErrorCode::StackOverflow => ApexErrorCode::StackOverflow,
        ErrorCode::MemoryViolation => ApexErrorCode::MemoryViolation,
        ErrorCode::HardwareFault => ApexErrorCode::HardwareFault,
        ErrorCode::PowerFail => ApexErrorCode::PowerFail,
    }
}

/// The bytes of an ARINC name: up to the first NUL, at most 32.
pub fn name_bytes(name: &ApexName) -> &[u8] {
    let end = name.iter().position(|&b| b == 0).unwrap_or(name.len());
    &name[..end]
}

/// An ARINC name from text (cut to 32 bytes).
pub fn apex_name(text: &str) -> ApexName {
    let mut name = [0u8; 32];
    let n = text.len().min(name.len());
    name[..n].copy_from_slice(&text.as_bytes()[..n]);
    name
}

/// A port or message id from the caller as a protocol word: ids are non-negative.
pub fn id_word(id: i64) -> Result<u64, ErrorReturnCode> {
    u64::try_from(id).map_err(|_| ErrorReturnCode::InvalidParam)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reply_codes_map_to_arinc_results() {
        assert_eq!(from_reply(0), Ok(()));
        assert_eq!(from_reply(1), Err(ErrorReturnCode::NoAction));
        assert_eq!(from_reply(4), Err(ErrorReturnCode::InvalidConfig));
        assert_eq!(from_reply(6), Err(ErrorReturnCode::TimedOut));
        assert_eq!(from_reply(7), Err(ErrorReturnCode::NotAvailable));
        assert_eq!(from_reply(u32::MAX), Err(ErrorReturnCode::NotAvailable));
    }

    #[test]
    fn apex_and_protocol_codes_agree() {
        for d in [PortDirection::Source, PortDirection::Destination] {
            assert_eq!(port_direction(direction(d)), d);
        }
        assert_eq!(direction(PortDirection::Source), Direction::Out);
        for d in [QueuingDiscipline::Fifo, QueuingDiscipline::Priority] {
            // The protocol numbers them as ARINC (and a653rs) do.
            assert_eq!(u32::from(discipline(d).code()), d as u32);
        }
        assert_eq!(validity(Validity::Valid), ApexValidity::Valid);
        assert_eq!(validity(Validity::Invalid), ApexValidity::Invalid);
        assert_eq!(mode(ApexMode::WarmStart), Some(OperatingMode::WarmStart));
        assert_eq!(mode(ApexMode::Idle), Some(OperatingMode::Idle));
        assert_eq!(
            error_code(ApexErrorCode::MemoryViolation),
            Some(ErrorCode::MemoryViolation)
        );
        assert_eq!(
            error_code(ApexErrorCode::PowerFail),
            Some(ErrorCode::PowerFail)
        );
        for code in ErrorCode::ALL {
            assert_eq!(error_code(apex_error_code(code)), Some(code));
        }
    }

    #[test]
    fn names_stop_at_the_first_nul() {
        let name = apex_name("sensor");
        assert_eq!(name_bytes(&name), b"sensor");
        assert_eq!(name_bytes(&[b'x'; 32]).len(), 32);
        assert_eq!(name_bytes(&apex_name("")), b"");
        assert_eq!(name_bytes(&apex_name(&"a".repeat(40))).len(), 32);
    }

    #[test]
    fn negative_ids_are_invalid() {
        assert_eq!(id_word(3), Ok(3));
        assert_eq!(id_word(-1), Err(ErrorReturnCode::InvalidParam));
    }
}
