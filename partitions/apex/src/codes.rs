//! ARINC 653 return codes and names as the syssw protocol carries them (pure: no system
//! calls, host-tested).

use a653rs::bindings::{ApexName, ErrorReturnCode, ReturnCode};

/// A protocol reply label (an ARINC 653 `RETURN_CODE_TYPE`) as a result.
///
/// A label outside the ARINC range would be a protocol fault of syssw; it is reported as
/// `NOT_AVAILABLE` (the service could not be performed) rather than trusted or panicked on.
pub fn from_reply(code: ReturnCode) -> Result<(), ErrorReturnCode> {
    match code {
        0 => Ok(()),
        1 => Err(ErrorReturnCode::NoAction),
        2 => Err(ErrorReturnCode::NotAvailable),
        3 => Err(ErrorReturnCode::InvalidParam),
        4 => Err(ErrorReturnCode::InvalidConfig),
        5 => Err(ErrorReturnCode::InvalidMode),
        6 => Err(ErrorReturnCode::TimedOut),
        _ => Err(ErrorReturnCode::NotAvailable),
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
