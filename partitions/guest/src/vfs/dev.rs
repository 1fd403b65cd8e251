//! The device files of `/dev`: what each one is and its device number. Reading and writing
//! them is the system calls' ([`crate::syscall`]): the console and `tty` are the guest's
//! console, `null` reads end of file and swallows writes, `zero` reads zeros, `urandom` and
//! `random` read the host's random bytes, and `arinc/<name>` are the partition's ARINC 653
//! ports ([`crate::arinc`]), and `vda` the block device on the partition's virtual disk
//! ([`crate::disk`]), there only with `guest.disk`. A device never holds data in the file
//! system.

/// A device file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Device {
    Console,
    Tty,
    Null,
    Zero,
    Urandom,
    Random,
    /// Port `n` of the port table ([`crate::vfs::Fs::ports`]).
    Port(u16),
    /// The block device `/dev/vda` ([`crate::disk`]).
    Disk,
}

impl Device {
    /// Every device, with its name in `/dev`.
    pub const ALL: [(&'static str, Device); 6] = [
        ("console", Device::Console),
        ("tty", Device::Tty),
        ("null", Device::Null),
        ("zero", Device::Zero),
        ("urandom", Device::Urandom),
        ("random", Device::Random),
    ];

    /// Its device number (`st_rdev`), as Linux numbers it (major << 8 | minor).
    pub const fn rdev(self) -> u64 {
        let (major, minor) = match self {
            Device::Console => (5, 1),
            Device::Tty => (5, 0),
            Device::Null => (1, 3),
            Device::Zero => (1, 5),
            Device::Urandom => (1, 9),
            Device::Random => (1, 8),
            Device::Port(n) => (crate::arinc::MAJOR, n as u64),
            Device::Disk => (crate::disk::MAJOR, crate::disk::MINOR),
        };
        major << 8 | minor
    }

    /// Whether opening it opens the console (a terminal).
    pub const fn is_console(self) -> bool {
        matches!(self, Device::Console | Device::Tty)
    }
}
