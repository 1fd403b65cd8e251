//! ARINC 653 return codes, as syssw answers the partitions' port and mode requests.
//!
//! The numbering is ARINC 653 Part 1's `RETURN_CODE_TYPE` (a653rs uses the same values), so
//! the code can travel as a plain integer in an IPC reply word.

/// The outcome of an ARINC 653 service request.
#[repr(u8)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ReturnCode {
    /// The request was performed.
    NoError = 0,
    /// Nothing to do: the request changed nothing (e.g. reading a sampling port that was
    /// never written, or setting the mode the partition is already in).
    NoAction = 1,
    /// The resource is not available now and the caller asked not to wait.
    NotAvailable = 2,
    /// A parameter is wrong (unknown port, port of another partition, empty message, ...).
    InvalidParam = 3,
    /// The request is outside what the configuration provides (message longer than the
    /// port's size, more waiting processes than a port holds).
    InvalidConfig = 4,
    /// The request does not fit the object's mode (sending on a destination port,
    /// a warm start from cold start, ...).
    InvalidMode = 5,
    /// The caller waited and its time-out expired.
    TimedOut = 6,
}

impl ReturnCode {
    pub const ALL: [ReturnCode; 7] = [
        Self::NoError,
        Self::NoAction,
        Self::NotAvailable,
        Self::InvalidParam,
        Self::InvalidConfig,
        Self::InvalidMode,
        Self::TimedOut,
    ];

    /// The numeric ARINC 653 value.
    pub const fn code(self) -> u64 {
        self as u64
    }

    /// The return code with numeric value `code`.
    pub fn from_code(code: u64) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.code() == code)
    }

    /// The ARINC 653 name (`NO_ERROR`, `TIMED_OUT`, ...).
    pub const fn name(self) -> &'static str {
        match self {
            Self::NoError => "NO_ERROR",
            Self::NoAction => "NO_ACTION",
            Self::NotAvailable => "NOT_AVAILABLE",
            Self::InvalidParam => "INVALID_PARAM",
            Self::InvalidConfig => "INVALID_CONFIG",
            Self::InvalidMode => "INVALID_MODE",
            Self::TimedOut => "TIMED_OUT",
        }
    }
}

impl core::fmt::Display for ReturnCode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arinc_numbering() {
        let expected = [
            (ReturnCode::NoError, 0, "NO_ERROR"),
            (ReturnCode::NoAction, 1, "NO_ACTION"),
            (ReturnCode::NotAvailable, 2, "NOT_AVAILABLE"),
            (ReturnCode::InvalidParam, 3, "INVALID_PARAM"),
            (ReturnCode::InvalidConfig, 4, "INVALID_CONFIG"),
            (ReturnCode::InvalidMode, 5, "INVALID_MODE"),
            (ReturnCode::TimedOut, 6, "TIMED_OUT"),
        ];
        for (code, value, name) in expected {
            assert_eq!(code.code(), value);
            assert_eq!(ReturnCode::from_code(value), Some(code));
            assert_eq!(code.name(), name);
            assert_eq!(std::format!("{code}"), name);
        }
        assert_eq!(ReturnCode::from_code(7), None);
        assert_eq!(ReturnCode::from_code(u64::MAX), None);
    }
}
