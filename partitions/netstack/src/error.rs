//! Why a socket call failed, each with its Linux errno.

/// A socket call's failure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error {
    /// Cannot finish now (EAGAIN for a non-blocking descriptor; otherwise the caller waits).
    WouldBlock,
    /// A non-blocking connect was started.
    InProgress,
    /// A connect is already under way.
    Already,
    IsConnected,
    NotConnected,
    ConnectionRefused,
    ConnectionReset,
    TimedOut,
    AddressInUse,
    AddressNotAvailable,
    AddressFamilyNotSupported,
    ProtocolNotSupported,
    SocketTypeNotSupported,
    OperationNotSupported,
    Invalid,
    /// No socket left ([`crate::Limits::sockets`]).
    NoBuffers,
    /// Writing to a connection that was shut down for writing or closed by the peer.
    BrokenPipe,
    DestinationRequired,
    MessageTooLong,
    NoProtocolOption,
    NetworkUnreachable,
    /// No such socket.
    BadDescriptor,
}

impl Error {
    /// The Linux errno.
    pub const fn errno(self) -> i32 {
        match self {
            Error::WouldBlock => 11,
            Error::InProgress => 115,
            Error::Already => 114,
            Error::IsConnected => 106,
            Error::NotConnected => 107,
            Error::ConnectionRefused => 111,
            Error::ConnectionReset => 104,
            Error::TimedOut => 110,
            Error::AddressInUse => 98,
            Error::AddressNotAvailable => 99,
            Error::AddressFamilyNotSupported => 97,
            Error::ProtocolNotSupported => 93,
            Error::SocketTypeNotSupported => 94,
            Error::OperationNotSupported => 95,
            Error::Invalid => 22,
            Error::NoBuffers => 105,
            Error::BrokenPipe => 32,
            Error::DestinationRequired => 89,
            Error::MessageTooLong => 90,
            Error::NoProtocolOption => 92,
            Error::NetworkUnreachable => 101,
            Error::BadDescriptor => 9,
        }
    }
}
