//! The PLC package: what `cargo xtask` puts into `system.img` as the PLC partition's data
//! entry (`data/<partition>`) and the runtime reads at start: the compiled program and how
//! the partition's ports connect to its process image. An interface (the build host writes
//! it, the partition checks it); all integers little-endian.
//!
//! ```text
//! offset size
//! 0      4    magic "WPKG"
//! 4      2    version (= 2; version 1 had no shared-globals block and no task deadlines)
//! 6      2    port count N (at most MAX_PORTS)
//! 8      4    program offset (from the package start)
//! 12     4    program length
//! 16     4    watch list offset
//! 20     4    watch list length
//! 24     1    online request port (index of a queuing input; NO_ONLINE: none)
//! 25     1    online response port (index of a queuing output)
//! 26     1    online access (plc_online::Access code)
//! 27     1    flags: bit 0 (FLAG_NATIVE) run the program on the native execution tier
//!             (`plc.native`), when this partition's binary holds its translation; bit 1
//!             (FLAG_STORE) the package ends with the store block; the other bits 0
//! 28     4    network block offset (0: the PLC has no network interface); the block
//!             runs to the end of the package or to the store block
//! 32     4    safe-value list offset
//! 36     4    safe-value list length
//! 40     4    shared-globals block offset
//! 44     4    shared-globals block length (0: the program shares no globals)
//! 48     4    task deadline list offset
//! 52     4    task deadline list length
//! 56     64*N port records:
//!   0    32   name (UTF-8, zero padded)
//!   32   1    kind (protocol::PortKind code: 1 sampling, 2 queuing)
//!   33   1    direction (protocol::Direction code: 1 in, 2 out)
//!   34   2    reserved (0)
//!   36   4    message size in bytes (max. for queuing ports)
//!   40   8    refresh period in ns (sampling in; 0 otherwise)
//!   48   4    queue depth (queuing; 0 otherwise)
//!   52   4    first byte in the process image: %I for an input, %Q for an output
//!   56   4    validity bit's byte in %I (inputs; NO_VALID_BIT: none)
//!   60   1    validity bit (0..=7)
//!   61   3    reserved (0)
//! ...         the program: a plc-vm bytecode image (re-verified by the runtime)
//! ...         the watch list: variable names (of the image's variable map), UTF-8,
//!             separated by `\n`, whose values the runtime logs with its statistics
//! ...         the safe values: 16-byte records `address u32` (a `%Q` variable's data
//!             address), `width u8` (1, 2, 4 or 8 bytes), reserved (3 bytes, 0), `value u64`
//!             (little-endian, the variable's bytes), used instead of zero/FALSE when a fault
//!             sets the outputs safe (at most `scan::MAX_SAFE_VALUES` records)
//! ...         the shared-globals block: where this project's shared globals lie in the
//!             shared-memory segment it shares with another project (the segment layout
//!             and its protocol are [`crate::shared`]'s):
//!   0    8    segment address in the partition's address space (page-aligned)
//!   8    4    segment size in bytes
//!   12   4    own area offset in the segment (NO_AREA: this project writes nothing)
//!   16   4    own area length (header included)
//!   20   4    other project's area offset (NO_AREA: this project reads nothing)
//!   24   4    other project's area length
//!   28   2    written variable count W
//!   30   2    read variable count R
//!   32   4    data address of the BOOL validity flag of the read variables (NO_FLAG:
//!             none), set before each cycle ([`crate::shared::copy_in`])
//!   36   12*(W+R) records, the written ones first: data address u32 (the variable in
//!             data memory), offset u32 (from its area's start, past the area header),
//!             size u32 (1, 2, 4 or 8 bytes)
//! ...         the task deadlines: 40-byte records `task name` (32 bytes, UTF-8, zero
//!             padded: an IEC TASK of the program, or `TASK.instance`), `deadline u64` (ns
//!             from the task's release, at least 1); tasks without one have no deadline
//! ...         the network block (`plc.net`, `plc.modbus`), [`NET_BLOCK`] bytes:
//!   0    6    MAC address
//!   6    4    IPv4 address
//!   10   1    prefix length (1..=30)
//!   11   1    flags: bit 0 a gateway, bit 1 a Modbus/TCP server, bit 2 Modbus may write
//!             the outputs (%QX, %QW), bit 3 the markers (%MX, %MW), bit 4 the online
//!             protocol on TCP (`plc.online_tcp`), bit 5 publish/subscribe
//!             (`plc.publish`, `plc.subscribe`), bit 6 a frame ring
//!             (`nic.tenants.<plc>.ring`)
//!   12   4    gateway (0 without)
//!   16   1    frames-in port (index of a queuing input of at least 1514 bytes)
//!   17   1    frames-out port (index of a queuing output of at least 1514 bytes)
//!   18   1    TCP connections at once (1..=32)
//!   19   1    Modbus unit id
//!   20   4    bytes of each connection's receive and of its send buffer (512..=65536)
//!   24   4    requests served per second and connection (at least 1)
//!   28   2    Modbus TCP port (0 without the server)
//!   30   2    online TCP port (0 without it)
//!   32   16   with a frame ring, its part: the segment's address u64 and size u64 (not 0);
//!             the frames then go through it (`frame_ring`) and the ports carry the
//!             wake-ups
//!   ...  ...  with publish/subscribe, its part ([`PUBSUB_HEAD`] bytes and the names):
//!   +0   4    publication's destination IPv4 address (0.0.0.0: no publication)
//!   +4   2    its UDP port
//!   +6   2    subscription's UDP port (0: no subscription)
//!   +8   8    subscription timeout in ns (at least 1 with a subscription)
//!   +16  2    bytes P of the published names
//!   +18  2    bytes S of the subscribed names
//!   +20  1    bytes V of the validity variable's name (0: none)
//!   +21  3    reserved (0)
//!   +24  4    the IPv4 multicast group the subscription joins (0.0.0.0: none)
//!   +28  P    published variable names, UTF-8, separated by `\n` (1..=16 names)
//!   ...  S    subscribed variable names, the same
//!   ...  V    the validity variable's name (a BOOL of the program)
//!   ...  ...  with the online protocol on TCP: 1..=[`MAX_CLIENTS`] client records of
//!             [`CLIENT_RECORD`] bytes: `name_len u8` (1..=32), `access u8`
//!             (plc_online::Access code), `key_len u8` (16..=64), reserved (0), `name`
//!             (32 bytes, zero padded), `key` (64 bytes, zero padded)
//! ...         the store block (`plc.store`), the package's last [`STORE_BLOCK`] bytes:
//!   0    1    request port (index of a queuing output of at least
//!             `blk_core::link::MAX_REQUEST` bytes)
//!   1    1    response port (index of a queuing input of at least
//!             `blk_core::link::MAX_RESPONSE` bytes)
//!   2    6    reserved (0)
//!   8    8    sectors of the partition's virtual disk (at least 1)
//!   16   8    RETAIN saved every that many ns (at least 1)
//! ```
//!
//! The online ports carry the online protocol (`plc-online`) instead of process-image
//! bytes (their first-byte fields are 0). An input port's message lands in `%I` from its
//! first byte, an output port's message is
//! that many bytes of `%Q` from its first byte. The validity bit of an input is set before
//! each scan cycle when the port gave a fresh message: a sampling message younger than its
//! refresh period, or a queuing message received for this cycle. The message bytes
//! themselves stay as last received, so a program must look at the bit (a stale level is
//! never silently fresh).

use plc_online::Access;
use plc_online::session;
pub use plc_online::session::ClientKey;
use plc_vm::located::MAX_AREA;
use protocol::{Direction, PortKind};

/// Package magic.
pub const MAGIC: [u8; 4] = *b"WPKG";
/// Format version.
pub const VERSION: u16 = 2;
/// Header bytes before the port records.
pub const HEADER_LEN: usize = 56;
/// Bytes of one task-deadline record.
pub const DEADLINE_RECORD: usize = NAME_LEN + 8;
/// Bytes of the shared-globals block before its records.
pub const SHARED_HEADER: usize = 36;
/// Validity-flag address of a project without one.
pub const NO_FLAG: u32 = u32::MAX;
/// Bytes of one shared-variable record.
pub const SHARED_VAR_RECORD: usize = 12;
/// Area offset of a side that has no area (nothing written, or nothing read).
pub const NO_AREA: u32 = u32::MAX;
/// Bytes of one safe-value record.
pub const SAFE_RECORD: usize = 16;
/// Flags bit: the configuration asks for the native execution tier (`plc.native`).
pub const FLAG_NATIVE: u8 = 1;
/// Flags bit: the package ends with the store block (`plc.store`).
pub const FLAG_STORE: u8 = 2;
/// Bytes of the store block.
pub const STORE_BLOCK: usize = 24;
/// The least request and response port sizes of the store (`blk_core::link`'s largest
/// request and response, which this crate does not depend on).
pub const STORE_REQUEST_MIN: u32 = 2072;
pub const STORE_RESPONSE_MIN: u32 = 2064;

/// Online port fields without online access.
pub const NO_ONLINE: u8 = u8::MAX;
/// Bytes of one port record.
pub const PORT_RECORD: usize = 64;
/// Longest port name.
pub const NAME_LEN: usize = 32;
/// Most ports a package maps.
pub const MAX_PORTS: usize = 32;
/// `valid_byte` of an input without a validity bit (and of every output).
pub const NO_VALID_BIT: u32 = u32::MAX;

/// One port and where it meets the process image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PortMap<'a> {
    pub name: &'a str,
    pub kind: PortKind,
    pub direction: Direction,
    /// Message size in bytes (the maximum for a queuing port).
    pub size: u32,
    /// Refresh period of a sampling input (ns), else 0.
    pub refresh_ns: u64,
    /// Queue depth of a queuing port, else 0.
    pub depth: u32,
    /// First byte in `%I` (inputs) or `%Q` (outputs).
    pub area_offset: u32,
    /// The input's validity bit in `%I` as (byte, bit), if any.
    pub valid: Option<(u32, u8)>,
}

/// Why a package was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PackageError {
    TooShort,
    BadMagic,
    UnsupportedVersion(u16),
    TooManyPorts(u16),
    /// The program range lies outside the package.
    ProgramOutOfBounds,
    /// The watch list lies outside the package or is not UTF-8.
    BadWatchList,
    /// The online ports are not a queuing input and a queuing output, or the access code
    /// is unknown.
    BadOnline,
    /// A flags bit this runtime does not know.
    BadFlags(u8),
    /// The safe-value list lies outside the package, is ragged, holds more than
    /// [`crate::scan::MAX_SAFE_VALUES`] records, or has a record with a
    /// width other than 1, 2, 4, 8 or a value wider than it.
    BadSafeValues,
    /// Port record `n` is malformed (name, codes, a range beyond the area, a validity bit
    /// on an output or above 7).
    BadPort(usize),
    /// The shared-globals block lies outside the package, is ragged, or its segment, areas
    /// or variable records are inconsistent (see [`SharedLayout`]).
    BadShared,
    /// The task-deadline list lies outside the package, is ragged, or has a record with a
    /// malformed name or a zero deadline.
    BadDeadlines,
    /// The network block is cut short, names ports that are not a queuing input and output
    /// of a frame's size, or has a field out of range.
    BadNet,
    /// The store block is cut short, names ports that are not a queuing output and input
    /// of a block request's and response's size, or has a zero field.
    BadStore,
}

impl core::fmt::Display for PackageError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::TooShort => write!(f, "shorter than its header and port records"),
            Self::BadMagic => write!(f, "bad magic (expected \"WPKG\")"),
            Self::UnsupportedVersion(v) => {
                write!(f, "unsupported version {v} (expected {VERSION})")
            }
            Self::TooManyPorts(n) => write!(f, "{n} ports (at most {MAX_PORTS})"),
            Self::ProgramOutOfBounds => write!(f, "the program lies outside the package"),
            Self::BadWatchList => {
                write!(f, "the watch list lies outside the package or is not UTF-8")
            }
            Self::BadOnline => write!(f, "the online ports are not a queuing input and output"),
            Self::BadSafeValues => write!(f, "the safe-value list is malformed"),
            Self::BadPort(n) => write!(f, "port record {n} is malformed"),
            Self::BadShared => write!(f, "the shared-globals block is malformed"),
            Self::BadDeadlines => write!(f, "the task-deadline list is malformed"),
            Self::BadNet => write!(f, "the network block is malformed"),
            Self::BadStore => write!(f, "the store block is malformed"),
            Self::BadFlags(flags) => write!(f, "unknown flags 0x{flags:02x}"),
        }
    }
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(core::array::from_fn(|i| b[at + i]))
}

/// A checked package (borrowing its bytes).
#[derive(Clone, Copy, Debug)]
pub struct Package<'a> {
    bytes: &'a [u8],
    ports: usize,
    program: &'a [u8],
    watch: &'a str,
    online: Option<Online>,
    safe: &'a [u8],
    shared: Option<SharedLayout<'a>>,
    deadlines: &'a [u8],
    net: Option<Net<'a>>,
    store: Option<Store>,
}

/// The PLC's persistent store on its virtual disk (the store block, `plc.store`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Store {
    /// Package port indices: the requests out, the responses in.
    pub request: usize,
    pub response: usize,
    pub sectors: u64,
    pub retain_every_ns: u64,
}

impl Store {
    fn parse(b: &[u8]) -> Option<Store> {
        if b.len() != STORE_BLOCK || b[2..8].iter().any(|&x| x != 0) {
            return None;
        }
        let store = Store {
            request: b[0] as usize,
            response: b[1] as usize,
            sectors: u64_at(b, 8),
            retain_every_ns: u64_at(b, 16),
        };
        (store.sectors > 0 && store.retain_every_ns > 0).then_some(store)
    }

    /// The block (for the image builder).
    #[cfg(any(feature = "alloc", test))]
    pub fn encode(&self) -> [u8; STORE_BLOCK] {
        let mut b = [0u8; STORE_BLOCK];
        b[0] = self.request as u8;
        b[1] = self.response as u8;
        b[8..16].copy_from_slice(&self.sectors.to_le_bytes());
        b[16..24].copy_from_slice(&self.retain_every_ns.to_le_bytes());
        b
    }
}

/// Bytes of the network block before its client records.
pub const NET_BLOCK: usize = 32;
/// Bytes of a client record of the online protocol on TCP.
pub const CLIENT_RECORD: usize = 4 + 32 + plc_online::session::MAX_KEY;
/// Most clients of the online protocol on TCP.
pub const MAX_CLIENTS: usize = 8;
/// Bytes of the publish/subscribe part's head.
pub const PUBSUB_HEAD: usize = 28;
/// Most variables a publication or subscription carries.
pub const MAX_PUBSUB_VARS: usize = 16;

/// PLC-to-PLC publication and subscription over UDP (the network block's part).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PubSub<'a> {
    /// Destination address and port, and the published names.
    pub publish: Option<([u8; 4], u16, &'a str)>,
    pub subscribe: Option<Subscription<'a>>,
}

/// A subscription's settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Subscription<'a> {
    pub port: u16,
    /// An IPv4 multicast group joined to receive its datagrams too.
    pub group: Option<[u8; 4]>,
    pub timeout_ns: u64,
    /// The subscribed names, separated by `\n`.
    pub names: &'a str,
    /// The BOOL variable kept TRUE while the subscription is valid.
    pub valid: Option<&'a str>,
}

/// The `\n`-separated names of `text` if there are 1..=[`MAX_PUBSUB_VARS`], none empty.
fn names_ok(text: &str) -> bool {
    let count = text.split('\n').count();
    (1..=MAX_PUBSUB_VARS).contains(&count) && text.split('\n').all(|n| !n.is_empty())
}

impl<'a> PubSub<'a> {
    /// The part at the start of `b`, and its length.
    fn parse(b: &'a [u8]) -> Option<(PubSub<'a>, usize)> {
        let head = b.get(..PUBSUB_HEAD)?;
        if head[21..24] != [0, 0, 0] {
            return None;
        }
        let (p, sl, v) = (
            usize::from(u16_at(head, 16)),
            usize::from(u16_at(head, 18)),
            usize::from(head[20]),
        );
        let len = PUBSUB_HEAD + p + sl + v;
        let text = core::str::from_utf8(b.get(PUBSUB_HEAD..len)?).ok()?;
        let (published, rest) = text.split_at_checked(p)?;
        let (subscribed, valid) = rest.split_at_checked(sl)?;
        let ip = [head[0], head[1], head[2], head[3]];
        let publish = if ip == [0; 4] {
            (p == 0 && u16_at(head, 4) == 0).then_some(None)?
        } else {
            let port = u16_at(head, 4);
            (port != 0 && names_ok(published)).then_some(Some((ip, port, published)))?
        };
        let port = u16_at(head, 6);
        let group = [head[24], head[25], head[26], head[27]];
        let subscribe = if port == 0 {
            (sl == 0 && v == 0 && u64_at(head, 8) == 0 && group == [0; 4]).then_some(None)?
        } else {
            let timeout_ns = u64_at(head, 8);
            let group_ok = group == [0; 4] || (224..=239).contains(&group[0]);
            let ok = timeout_ns > 0 && names_ok(subscribed) && group_ok;
            ok.then_some(Some(Subscription {
                port,
                group: (group != [0; 4]).then_some(group),
                timeout_ns,
                names: subscribed,
                valid: (v > 0).then_some(valid),
            }))?
        };
        (publish.is_some() || subscribe.is_some()).then_some((PubSub { publish, subscribe }, len))
    }

    /// The part (for the image builder).
    #[cfg(any(feature = "alloc", test))]
    pub fn encode(&self) -> alloc::vec::Vec<u8> {
        let mut b = alloc::vec![0u8; PUBSUB_HEAD];
        let mut text = alloc::vec::Vec::new();
        if let Some((ip, port, names)) = self.publish {
            b[..4].copy_from_slice(&ip);
            b[4..6].copy_from_slice(&port.to_le_bytes());
            b[16..18].copy_from_slice(&(names.len() as u16).to_le_bytes());
            text.extend_from_slice(names.as_bytes());
        }
        if let Some(s) = self.subscribe {
            b[6..8].copy_from_slice(&s.port.to_le_bytes());
            if let Some(g) = s.group {
                b[24..28].copy_from_slice(&g);
            }
            b[8..16].copy_from_slice(&s.timeout_ns.to_le_bytes());
            b[18..20].copy_from_slice(&(s.names.len() as u16).to_le_bytes());
            text.extend_from_slice(s.names.as_bytes());
            if let Some(v) = s.valid {
                b[20] = v.len() as u8;
                text.extend_from_slice(v.as_bytes());
            }
        }
        b.extend_from_slice(&text);
        b
    }
}
/// Largest Ethernet frame without FCS: the least size of the frame ports.
pub const FRAME_MAX: u32 = 1514;
/// Most TCP connections a PLC keeps.
pub const MAX_CONNECTIONS: u8 = 32;

/// The PLC's network interface and services (the network block).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Net<'a> {
    pub mac: [u8; 6],
    pub address: [u8; 4],
    pub prefix: u8,
    pub gateway: Option<[u8; 4]>,
    /// Package port indices: the frames in and out.
    pub rx: usize,
    pub tx: usize,
    pub connections: u8,
    pub buffer: u32,
    pub requests_per_second: u32,
    pub modbus: Option<Modbus>,
    pub online: Option<OnlineTcp<'a>>,
    pub pubsub: Option<PubSub<'a>>,
    /// The frame ring's segment (address, size) when the frames go through one.
    pub ring: Option<(u64, u64)>,
}

/// The online protocol on TCP: its port and its clients' keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OnlineTcp<'a> {
    pub port: u16,
    /// The client records (checked).
    records: &'a [u8],
}

impl<'a> OnlineTcp<'a> {
    /// The clients, in configuration order.
    pub fn clients(&self) -> impl Iterator<Item = ClientKey<'a>> + 'a {
        self.records.chunks_exact(CLIENT_RECORD).map(|r| ClientKey {
            name: &r[4..4 + usize::from(r[0])],
            secret: &r[36..36 + usize::from(r[2])],
            access: Access::from_code(r[1]).unwrap_or(Access::Monitor),
        })
    }

    /// The client records of `clients` (for the image builder; each name and key within
    /// its limits).
    #[cfg(any(feature = "alloc", test))]
    pub fn records(clients: &[ClientKey<'_>]) -> alloc::vec::Vec<u8> {
        let mut out = alloc::vec::Vec::new();
        for c in clients {
            let mut r = [0u8; CLIENT_RECORD];
            r[0] = c.name.len() as u8;
            r[1] = c.access.code();
            r[2] = c.secret.len() as u8;
            r[4..4 + c.name.len()].copy_from_slice(c.name);
            r[36..36 + c.secret.len()].copy_from_slice(c.secret);
            out.extend_from_slice(&r);
        }
        out
    }

    /// The online protocol on `port` for the client records `records`
    /// ([`OnlineTcp::records`]), if they are well formed.
    pub fn new(port: u16, records: &'a [u8]) -> Option<Self> {
        let count = records.len() / CLIENT_RECORD;
        let well_formed = |r: &[u8]| {
            let (name_len, key_len) = (usize::from(r[0]), usize::from(r[2]));
            (1..=session::MAX_NAME).contains(&name_len)
                && (session::MIN_KEY..=session::MAX_KEY).contains(&key_len)
                && Access::from_code(r[1]).is_some()
                && r[3] == 0
                && r[4 + name_len..36].iter().all(|&b| b == 0)
                && r[36 + key_len..].iter().all(|&b| b == 0)
        };
        let ok = port != 0
            && records.len().is_multiple_of(CLIENT_RECORD)
            && (1..=MAX_CLIENTS).contains(&count)
            && records.chunks_exact(CLIENT_RECORD).all(well_formed);
        ok.then_some(OnlineTcp { port, records })
    }
}

/// The Modbus/TCP server's settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Modbus {
    pub port: u16,
    pub unit: u8,
    pub write_outputs: bool,
    pub write_markers: bool,
}

const NET_GATEWAY: u8 = 1;
const NET_MODBUS: u8 = 2;
const NET_WRITE_OUTPUTS: u8 = 4;
const NET_WRITE_MARKERS: u8 = 8;
const NET_ONLINE: u8 = 16;
const NET_PUBSUB: u8 = 32;
const NET_RING: u8 = 64;
/// Bytes of the frame ring's part.
const RING_PART: usize = 16;

impl<'a> Net<'a> {
    /// The block's fields (its ports are checked by [`Package::parse`]).
    fn parse(b: &'a [u8]) -> Option<Net<'a>> {
        if b.len() < NET_BLOCK || b[11] & !0x7F != 0 {
            return None;
        }
        let flags = b[11];
        let (ring, part_at) = if flags & NET_RING != 0 {
            let part = b.get(NET_BLOCK..NET_BLOCK + RING_PART)?;
            let ring = (u64_at(part, 0), u64_at(part, 8));
            (ring.1 != 0).then_some(())?;
            (Some(ring), NET_BLOCK + RING_PART)
        } else {
            (None, NET_BLOCK)
        };
        let (pubsub, records_at) = if flags & NET_PUBSUB != 0 {
            let (pubsub, len) = PubSub::parse(&b[part_at..])?;
            (Some(pubsub), part_at + len)
        } else {
            (None, part_at)
        };
        let online = if flags & NET_ONLINE != 0 {
            Some(OnlineTcp::new(u16_at(b, 30), &b[records_at..])?)
        } else if b.len() != records_at || u16_at(b, 30) != 0 {
            return None;
        } else {
            None
        };
        let modbus = if flags & NET_MODBUS != 0 {
            let port = u16_at(b, 28);
            if port == 0 {
                return None;
            }
            Some(Modbus {
                port,
                unit: b[19],
                write_outputs: flags & NET_WRITE_OUTPUTS != 0,
                write_markers: flags & NET_WRITE_MARKERS != 0,
            })
        } else {
            None
        };
        let net = Net {
            mac: core::array::from_fn(|i| b[i]),
            address: [b[6], b[7], b[8], b[9]],
            prefix: b[10],
            gateway: (flags & NET_GATEWAY != 0).then(|| [b[12], b[13], b[14], b[15]]),
            rx: b[16] as usize,
            tx: b[17] as usize,
            connections: b[18],
            buffer: u32_at(b, 20),
            requests_per_second: u32_at(b, 24),
            modbus,
            online,
            pubsub,
            ring,
        };
        let fits = (1..=30).contains(&net.prefix)
            && net.mac[0] & 1 == 0
            && (1..=MAX_CONNECTIONS).contains(&net.connections)
            && (512..=65_536).contains(&net.buffer)
            && net.requests_per_second > 0;
        fits.then_some(net)
    }

    /// The block (for the image builder).
    #[cfg(any(feature = "alloc", test))]
    pub fn encode(&self) -> alloc::vec::Vec<u8> {
        let mut b = alloc::vec![0u8; NET_BLOCK];
        b[..6].copy_from_slice(&self.mac);
        b[6..10].copy_from_slice(&self.address);
        b[10] = self.prefix;
        let mut flags = 0;
        if let Some(g) = self.gateway {
            flags |= NET_GATEWAY;
            b[12..16].copy_from_slice(&g);
        }
        if let Some(m) = self.modbus {
            flags |= NET_MODBUS;
            if m.write_outputs {
                flags |= NET_WRITE_OUTPUTS;
            }
            if m.write_markers {
                flags |= NET_WRITE_MARKERS;
            }
            b[19] = m.unit;
            b[28..30].copy_from_slice(&m.port.to_le_bytes());
        }
        if let Some((address, size)) = self.ring {
            flags |= NET_RING;
            b.extend_from_slice(&address.to_le_bytes());
            b.extend_from_slice(&size.to_le_bytes());
        }
        if let Some(p) = self.pubsub {
            flags |= NET_PUBSUB;
            b.extend_from_slice(&p.encode());
        }
        if let Some(o) = self.online {
            flags |= NET_ONLINE;
            b[30..32].copy_from_slice(&o.port.to_le_bytes());
            b.extend_from_slice(o.records);
        }
        b[11] = flags;
        b[16] = self.rx as u8;
        b[17] = self.tx as u8;
        b[18] = self.connections;
        b[20..24].copy_from_slice(&self.buffer.to_le_bytes());
        b[24..28].copy_from_slice(&self.requests_per_second.to_le_bytes());
        b
    }
}

/// A configured task deadline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TaskDeadline<'a> {
    /// The IEC TASK's name (or `TASK.instance`).
    pub task: &'a str,
    /// Time from the task's release by which its cycle must be done (ns).
    pub deadline_ns: u64,
}

/// Where a project's shared globals lie in its shared-memory segment (checked by
/// [`Package::parse`]: both areas inside the segment, 8-byte aligned and disjoint, every
/// variable inside its area past the header, 1, 2, 4 or 8 bytes, naturally aligned, and the
/// written ones disjoint; that the data addresses and the validity flag are the program's,
/// and the segment where syssw maps segments, is [`crate::shared::check`]'s job, with the
/// verified program).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SharedLayout<'a> {
    /// The segment's address in the partition's address space.
    pub segment_address: u64,
    /// Its size in bytes.
    pub segment_size: u32,
    /// This project's area (offset, length), if it writes anything.
    pub own: Option<(u32, u32)>,
    /// The other project's area (offset, length), if this one reads anything.
    pub other: Option<(u32, u32)>,
    /// Data address of the BOOL set before each cycle to whether the read variables are a
    /// fresh copy, if the program has one.
    pub valid_flag: Option<u32>,
    written: &'a [u8],
    read: &'a [u8],
}

/// One shared variable: its bytes in data memory and in its area of the segment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SharedVar {
    /// Data address.
    pub address: u32,
    /// Offset from the start of its area.
    pub offset: u32,
    /// Bytes (1, 2, 4 or 8).
    pub size: u32,
}

/// The variable records of one side of a [`SharedLayout`].
pub type SharedVars<'a> = core::iter::Map<core::slice::ChunksExact<'a, u8>, fn(&[u8]) -> SharedVar>;

impl<'a> SharedLayout<'a> {
    /// The variables this project writes into its own area.
    pub fn written(&self) -> SharedVars<'a> {
        self.written.chunks_exact(SHARED_VAR_RECORD).map(shared_var)
    }

    /// The variables this project reads from the other project's area.
    pub fn read(&self) -> SharedVars<'a> {
        self.read.chunks_exact(SHARED_VAR_RECORD).map(shared_var)
    }

    /// Checks a block (see [`SharedLayout`]).
    fn parse(block: &'a [u8]) -> Option<SharedLayout<'a>> {
        let header = block.get(..SHARED_HEADER)?;
        let segment_address = u64_at(header, 0);
        let segment_size = u32_at(header, 8);
        let area = |at: usize| match u32_at(header, at) {
            NO_AREA => Some(None),
            offset => {
                let len = u32_at(header, at + 4);
                let fits = offset.is_multiple_of(8)
                    && len >= crate::shared::AREA_HEADER as u32
                    && offset
                        .checked_add(len)
                        .is_some_and(|end| end <= segment_size);
                fits.then_some(Some((offset, len)))
            }
        };
        let (own, other) = (area(12)?, area(20)?);
        let (w, r) = (u16_at(header, 28) as usize, u16_at(header, 30) as usize);
        let records = &block[SHARED_HEADER..];
        if !segment_address.is_multiple_of(4096)
            || segment_address == 0
            || w + r > 2 * plc_vm::image::MAX_SHARED_VARS
            || records.len() != (w + r) * SHARED_VAR_RECORD
            || (w > 0 && own.is_none())
            || (r > 0 && other.is_none())
        {
            return None;
        }
        if let (Some((a, al)), Some((b, bl))) = (own, other)
            && a < b + bl
            && b < a + al
        {
            return None;
        }
        let (written, read) = records.split_at(w * SHARED_VAR_RECORD);
        let inside = |v: SharedVar, area: Option<(u32, u32)>| {
            let (_, len) = area.unwrap_or((0, 0));
            matches!(v.size, 1 | 2 | 4 | 8)
                && v.offset.is_multiple_of(v.size)
                && v.offset >= crate::shared::AREA_HEADER as u32
                && v.offset + v.size <= len
                && v.address.checked_add(v.size).is_some()
        };
        let layout = SharedLayout {
            segment_address,
            segment_size,
            own,
            other,
            valid_flag: Some(u32_at(header, 32)).filter(|&a| a != NO_FLAG),
            written,
            read,
        };
        let mut ok =
            layout.written().all(|v| inside(v, own)) && layout.read().all(|v| inside(v, other));
        for (i, v) in layout.written().enumerate() {
            ok &= layout
                .written()
                .take(i)
                .all(|o| o.offset + o.size <= v.offset || v.offset + v.size <= o.offset);
        }
        ok.then_some(layout)
    }
}

fn shared_var(r: &[u8]) -> SharedVar {
    SharedVar {
        address: u32_at(r, 0),
        offset: u32_at(r, 4),
        size: u32_at(r, 8),
    }
}

/// A `%Q` variable's value when the outputs go safe.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SafeValue {
    /// Data address of the variable.
    pub address: u32,
    /// Its width in bytes.
    pub width: u8,
    /// Its bytes, little-endian.
    pub value: u64,
}

/// The online ports (package port indices) and what their client may do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Online {
    pub request: usize,
    pub response: usize,
    pub access: plc_online::Access,
}

impl<'a> Package<'a> {
    /// Checks the structure and every port record; the program is only located (the
    /// runtime verifies it).
    pub fn parse(bytes: &'a [u8]) -> Result<Self, PackageError> {
        if bytes.len() < HEADER_LEN {
            return Err(PackageError::TooShort);
        }
        if bytes[..4] != MAGIC {
            return Err(PackageError::BadMagic);
        }
        let version = u16_at(bytes, 4);
        if version != VERSION {
            return Err(PackageError::UnsupportedVersion(version));
        }
        if bytes[27] & !(FLAG_NATIVE | FLAG_STORE) != 0 {
            return Err(PackageError::BadFlags(bytes[27]));
        }
        let count = u16_at(bytes, 6);
        if count as usize > MAX_PORTS {
            return Err(PackageError::TooManyPorts(count));
        }
        if bytes.len() < HEADER_LEN + count as usize * PORT_RECORD {
            return Err(PackageError::TooShort);
        }
        let range = |at: usize| {
            let (offset, len) = (u32_at(bytes, at) as usize, u32_at(bytes, at + 4) as usize);
            offset
                .checked_add(len)
                .and_then(|end| bytes.get(offset..end))
        };
        let program = range(8).ok_or(PackageError::ProgramOutOfBounds)?;
        let watch = range(16)
            .and_then(|w| core::str::from_utf8(w).ok())
            .ok_or(PackageError::BadWatchList)?;
        let safe = range(32)
            .filter(|s| {
                s.len() % SAFE_RECORD == 0 && s.len() / SAFE_RECORD <= crate::scan::MAX_SAFE_VALUES
            })
            .ok_or(PackageError::BadSafeValues)?;
        for r in safe.chunks_exact(SAFE_RECORD) {
            let width = r[4];
            let value = u64_at(r, 8);
            let fits = width == 8 || (matches!(width, 1 | 2 | 4) && value >> (8 * width) == 0);
            if !fits || r[5..8] != [0; 3] {
                return Err(PackageError::BadSafeValues);
            }
        }
        let shared = match range(40).ok_or(PackageError::BadShared)? {
            [] => None,
            block => Some(SharedLayout::parse(block).ok_or(PackageError::BadShared)?),
        };
        let deadlines = range(48)
            .filter(|d| d.len() % DEADLINE_RECORD == 0)
            .ok_or(PackageError::BadDeadlines)?;
        for r in deadlines.chunks_exact(DEADLINE_RECORD) {
            if name_field(&r[..NAME_LEN]).is_none() || u64_at(r, NAME_LEN) == 0 {
                return Err(PackageError::BadDeadlines);
            }
        }
        let mut package = Package {
            bytes,
            ports: count as usize,
            program,
            watch,
            online: None,
            safe,
            shared,
            deadlines,
            net: None,
            store: None,
        };
        for i in 0..package.ports {
            package.decode_port(i).ok_or(PackageError::BadPort(i))?;
        }
        let queuing = |package: &Package, i: usize, direction, size: u32| {
            package.port(i).is_some_and(|p| {
                p.kind == PortKind::Queuing && p.direction == direction && p.size >= size
            })
        };
        let mut end = bytes.len();
        if bytes[27] & FLAG_STORE != 0 {
            end = end.checked_sub(STORE_BLOCK).ok_or(PackageError::BadStore)?;
            let store = Store::parse(&bytes[end..]).ok_or(PackageError::BadStore)?;
            if !queuing(&package, store.request, Direction::Out, STORE_REQUEST_MIN)
                || !queuing(&package, store.response, Direction::In, STORE_RESPONSE_MIN)
            {
                return Err(PackageError::BadStore);
            }
            package.store = Some(store);
        }
        let net_at = u32_at(bytes, 28) as usize;
        if net_at != 0 {
            let net = bytes
                .get(net_at..end)
                .and_then(Net::parse)
                .ok_or(PackageError::BadNet)?;
            let frame_port = |i: usize, direction| {
                package.port(i).is_some_and(|p| {
                    p.kind == PortKind::Queuing && p.direction == direction && p.size >= FRAME_MAX
                })
            };
            if !frame_port(net.rx, Direction::In) || !frame_port(net.tx, Direction::Out) {
                return Err(PackageError::BadNet);
            }
            package.net = Some(net);
        }
        if bytes[24] != NO_ONLINE {
            let port = |i: u8, direction| {
                package
                    .port(i as usize)
                    .filter(|p| p.kind == PortKind::Queuing && p.direction == direction)
                    .map(|_| i as usize)
            };
            let online = Online {
                request: port(bytes[24], Direction::In).ok_or(PackageError::BadOnline)?,
                response: port(bytes[25], Direction::Out).ok_or(PackageError::BadOnline)?,
                access: plc_online::Access::from_code(bytes[26]).ok_or(PackageError::BadOnline)?,
            };
            package.online = Some(online);
        }
        Ok(package)
    }

    /// The bytecode image.
    pub fn program(&self) -> &'a [u8] {
        self.program
    }

    /// Whether the configuration asks for the native execution tier (`plc.native`).
    pub fn native(&self) -> bool {
        self.bytes[27] & FLAG_NATIVE != 0
    }

    /// Where the shared globals lie in the shared segment, if the program shares any.
    pub fn shared(&self) -> Option<SharedLayout<'a>> {
        self.shared
    }

    /// The online ports, if the configuration gives the PLC any.
    pub fn online(&self) -> Option<Online> {
        self.online
    }

    /// The PLC's network interface and services, if the configuration gives it any.
    pub fn net(&self) -> Option<Net<'a>> {
        self.net
    }

    /// The PLC's persistent store, if the configuration gives it one.
    pub fn store(&self) -> Option<Store> {
        self.store
    }

    /// Whether port `i` moves process-image bytes (all but the online and frame ports).
    pub fn is_image_port(&self, i: usize) -> bool {
        self.online
            .is_none_or(|o| i != o.request && i != o.response)
            && self.net.is_none_or(|n| i != n.rx && i != n.tx)
            && self.store.is_none_or(|s| i != s.request && i != s.response)
    }

    /// The configured task deadlines (tasks without one have none).
    pub fn deadlines(&self) -> impl Iterator<Item = TaskDeadline<'a>> + 'a {
        self.deadlines
            .chunks_exact(DEADLINE_RECORD)
            .filter_map(|r| {
                Some(TaskDeadline {
                    task: name_field(&r[..NAME_LEN])?,
                    deadline_ns: u64_at(r, NAME_LEN),
                })
            })
    }

    /// The configured safe values (all others are zero/FALSE).
    pub fn safe_values(&self) -> impl Iterator<Item = SafeValue> + 'a {
        self.safe.chunks_exact(SAFE_RECORD).map(|r| SafeValue {
            address: u32_at(r, 0),
            width: r[4],
            value: u64_at(r, 8),
        })
    }

    /// The names of the variables to log.
    pub fn watch(&self) -> impl Iterator<Item = &'a str> {
        self.watch.split('\n').filter(|n| !n.is_empty())
    }

    pub fn port_count(&self) -> usize {
        self.ports
    }

    /// Port record `i` (every record was checked by [`Package::parse`]).
    pub fn port(&self, i: usize) -> Option<PortMap<'a>> {
        (i < self.ports).then(|| self.decode_port(i)).flatten()
    }

    pub fn ports(&self) -> impl Iterator<Item = PortMap<'a>> + '_ {
        (0..self.ports).filter_map(|i| self.port(i))
    }

    fn decode_port(&self, i: usize) -> Option<PortMap<'a>> {
        let at = HEADER_LEN + i * PORT_RECORD;
        let r = self.bytes.get(at..at + PORT_RECORD)?;
        let name = name_field(&r[..NAME_LEN])?;
        let kind = PortKind::from_code(r[32])?;
        let direction = Direction::from_code(r[33])?;
        let size = u32_at(r, 36);
        let area_offset = u32_at(r, 52);
        let valid = match (u32_at(r, 56), r[60]) {
            (NO_VALID_BIT, 0) => None,
            (byte, bit) if bit <= 7 && byte < MAX_AREA && direction == Direction::In => {
                Some((byte, bit))
            }
            _ => return None,
        };
        if size == 0 || area_offset.checked_add(size)? > MAX_AREA {
            return None;
        }
        Some(PortMap {
            name,
            kind,
            direction,
            size,
            refresh_ns: u64_at(r, 40),
            depth: u32_at(r, 48),
            area_offset,
            valid,
        })
    }
}

/// A zero-padded name field: non-empty UTF-8, nothing after the padding starts.
fn name_field(field: &[u8]) -> Option<&str> {
    let len = field.iter().position(|&b| b == 0).unwrap_or(field.len());
    let name = core::str::from_utf8(&field[..len]).ok()?;
    (!name.is_empty() && field[len..].iter().all(|&b| b == 0)).then_some(name)
}

/// `name` as a zero-padded [`NAME_LEN`]-byte field (cut to fit).
#[cfg(any(feature = "alloc", test))]
fn put_name(out: &mut alloc::vec::Vec<u8>, name: &str) {
    let mut field = [0u8; NAME_LEN];
    let name = &name.as_bytes()[..name.len().min(NAME_LEN)];
    field[..name.len()].copy_from_slice(name);
    out.extend_from_slice(&field);
}

/// Writes a package (for the image builder). Names longer than [`NAME_LEN`] are cut.
#[cfg(any(feature = "alloc", test))]
pub fn encode(
    ports: &[PortMap],
    program: &[u8],
    watch: &[&str],
    online: Option<Online>,
    safe: &[SafeValue],
    shared: Option<&SharedPlan>,
    deadlines: &[TaskDeadline],
) -> alloc::vec::Vec<u8> {
    let mut out = alloc::vec::Vec::new();
    let program_at = HEADER_LEN + ports.len() * PORT_RECORD;
    let watch = watch.join("\n");
    let shared = shared.map(SharedPlan::encode).unwrap_or_default();
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&(ports.len() as u16).to_le_bytes());
    out.extend_from_slice(&(program_at as u32).to_le_bytes());
    out.extend_from_slice(&(program.len() as u32).to_le_bytes());
    out.extend_from_slice(&((program_at + program.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(watch.len() as u32).to_le_bytes());
    match online {
        Some(o) => out.extend_from_slice(&[o.request as u8, o.response as u8, o.access.code()]),
        None => out.extend_from_slice(&[NO_ONLINE, NO_ONLINE, 0]),
    }
    out.extend_from_slice(&[0; 5]);
    let safe_at = program_at + program.len() + watch.len();
    out.extend_from_slice(&(safe_at as u32).to_le_bytes());
    out.extend_from_slice(&((safe.len() * SAFE_RECORD) as u32).to_le_bytes());
    let shared_at = safe_at + safe.len() * SAFE_RECORD;
    out.extend_from_slice(&(shared_at as u32).to_le_bytes());
    out.extend_from_slice(&(shared.len() as u32).to_le_bytes());
    let deadlines_at = shared_at + shared.len();
    out.extend_from_slice(&(deadlines_at as u32).to_le_bytes());
    out.extend_from_slice(&((deadlines.len() * DEADLINE_RECORD) as u32).to_le_bytes());
    for p in ports {
        let mut r = [0u8; PORT_RECORD];
        let name = &p.name.as_bytes()[..p.name.len().min(NAME_LEN)];
        r[..name.len()].copy_from_slice(name);
        r[32] = p.kind.code();
        r[33] = p.direction.code();
        r[36..40].copy_from_slice(&p.size.to_le_bytes());
        r[40..48].copy_from_slice(&p.refresh_ns.to_le_bytes());
        r[48..52].copy_from_slice(&p.depth.to_le_bytes());
        r[52..56].copy_from_slice(&p.area_offset.to_le_bytes());
        let (byte, bit) = p.valid.unwrap_or((NO_VALID_BIT, 0));
        r[56..60].copy_from_slice(&byte.to_le_bytes());
        r[60] = bit;
        out.extend_from_slice(&r);
    }
    out.extend_from_slice(program);
    out.extend_from_slice(watch.as_bytes());
    for s in safe {
        out.extend_from_slice(&s.address.to_le_bytes());
        out.extend_from_slice(&[s.width, 0, 0, 0]);
        out.extend_from_slice(&s.value.to_le_bytes());
    }
    out.extend_from_slice(&shared);
    for d in deadlines {
        put_name(&mut out, d.task);
        out.extend_from_slice(&d.deadline_ns.to_le_bytes());
    }
    out
}

/// Appends the network block to an [`encode`]d package (`plc.net`).
#[cfg(any(feature = "alloc", test))]
pub fn attach_net(package: &mut alloc::vec::Vec<u8>, net: &Net<'_>) {
    let at = package.len() as u32;
    package[28..32].copy_from_slice(&at.to_le_bytes());
    package.extend_from_slice(&net.encode());
}

/// Appends the store block to an [`encode`]d package (`plc.store`), after any network
/// block.
#[cfg(any(feature = "alloc", test))]
pub fn attach_store(package: &mut alloc::vec::Vec<u8>, store: &Store) {
    if let Some(flags) = package.get_mut(27) {
        *flags |= FLAG_STORE;
    }
    package.extend_from_slice(&store.encode());
}

/// Marks an [`encode`]d package as asking for the native execution tier (`plc.native`).
#[cfg(any(feature = "alloc", test))]
pub fn request_native(package: &mut [u8]) {
    if let Some(flags) = package.get_mut(27) {
        *flags |= FLAG_NATIVE;
    }
}

/// A project's shared-globals block as the image builder plans it (see the format above).
#[cfg(any(feature = "alloc", test))]
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SharedPlan {
    pub segment_address: u64,
    pub segment_size: u32,
    /// (offset, length) of this project's area.
    pub own: Option<(u32, u32)>,
    /// (offset, length) of the other project's area.
    pub other: Option<(u32, u32)>,
    /// Data address of the validity flag.
    pub valid_flag: Option<u32>,
    pub written: alloc::vec::Vec<SharedVar>,
    pub read: alloc::vec::Vec<SharedVar>,
}

#[cfg(any(feature = "alloc", test))]
impl SharedPlan {
    pub(crate) fn encode(&self) -> alloc::vec::Vec<u8> {
        let mut out = alloc::vec::Vec::new();
        out.extend_from_slice(&self.segment_address.to_le_bytes());
        out.extend_from_slice(&self.segment_size.to_le_bytes());
        for area in [self.own, self.other] {
            let (offset, len) = area.unwrap_or((NO_AREA, 0));
            out.extend_from_slice(&offset.to_le_bytes());
            out.extend_from_slice(&len.to_le_bytes());
        }
        out.extend_from_slice(&(self.written.len() as u16).to_le_bytes());
        out.extend_from_slice(&(self.read.len() as u16).to_le_bytes());
        out.extend_from_slice(&self.valid_flag.unwrap_or(NO_FLAG).to_le_bytes());
        for v in self.written.iter().chain(&self.read) {
            out.extend_from_slice(&v.address.to_le_bytes());
            out.extend_from_slice(&v.offset.to_le_bytes());
            out.extend_from_slice(&v.size.to_le_bytes());
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn level() -> PortMap<'static> {
        PortMap {
            name: "level",
            kind: PortKind::Sampling,
            direction: Direction::In,
            size: 8,
            refresh_ns: 100_000_000,
            depth: 0,
            area_offset: 0,
            valid: Some((16, 0)),
        }
    }

    fn valve() -> PortMap<'static> {
        PortMap {
            name: "valve",
            kind: PortKind::Sampling,
            direction: Direction::Out,
            size: 8,
            refresh_ns: 0,
            depth: 0,
            area_offset: 8,
            valid: None,
        }
    }

    #[test]
    fn round_trip() {
        let deadline = TaskDeadline {
            task: "fast",
            deadline_ns: 5_000_000,
        };
        let safe = SafeValue {
            address: 16,
            width: 8,
            value: 0.5f64.to_bits(),
        };
        let bytes = encode(
            &[level(), valve()],
            b"PLCB...",
            &["tank.alarm", "x"],
            None,
            &[safe],
            Some(&shared_plan()),
            &[deadline],
        );
        let p = Package::parse(&bytes).unwrap();
        assert_eq!(
            p.ports().collect::<alloc::vec::Vec<_>>(),
            [level(), valve()]
        );
        assert_eq!(p.program(), b"PLCB...");
        assert_eq!(
            p.watch().collect::<alloc::vec::Vec<_>>(),
            ["tank.alarm", "x"]
        );
        assert_eq!(p.safe_values().collect::<alloc::vec::Vec<_>>(), [safe]);
        assert_eq!(p.deadlines().collect::<alloc::vec::Vec<_>>(), [deadline]);
        let shared = p.shared().unwrap();
        let plan = shared_plan();
        assert_eq!(
            (
                shared.segment_address,
                shared.segment_size,
                shared.own,
                shared.other
            ),
            (
                plan.segment_address,
                plan.segment_size,
                plan.own,
                plan.other
            )
        );
        assert_eq!(
            shared.written().collect::<alloc::vec::Vec<_>>(),
            plan.written
        );
        assert_eq!(shared.read().collect::<alloc::vec::Vec<_>>(), plan.read);
        let plain = encode(&[level()], b"P", &[], None, &[], None, &[]);
        assert_eq!(Package::parse(&plain).unwrap().shared(), None);
    }

    #[test]
    fn the_native_flag() {
        let mut bytes = encode(&[level()], b"P", &[], None, &[], None, &[]);
        assert!(
            !Package::parse(&bytes).unwrap().native(),
            "the interpreter by default"
        );
        request_native(&mut bytes);
        let p = Package::parse(&bytes).unwrap();
        assert!(p.native());
        assert_eq!(p.program(), b"P");
        bytes[27] |= 0x80;
        assert_eq!(
            Package::parse(&bytes).unwrap_err(),
            PackageError::BadFlags(0x81)
        );
    }

    /// Writes a DINT at offset 8 of its area at 64, reads a BOOL at offset 8 and a LREAL at
    /// 16 of the other's area at 0.
    fn shared_plan() -> SharedPlan {
        SharedPlan {
            segment_address: 0x6000_0000_0000,
            segment_size: 4096,
            own: Some((64, 16)),
            other: Some((0, 24)),
            valid_flag: Some(120),
            written: alloc::vec![SharedVar {
                address: 100,
                offset: 8,
                size: 4
            }],
            read: alloc::vec![
                SharedVar {
                    address: 104,
                    offset: 8,
                    size: 1
                },
                SharedVar {
                    address: 112,
                    offset: 16,
                    size: 8
                }
            ],
        }
    }

    #[test]
    fn hostile_shared_blocks_are_refused() {
        let good = encode(&[level()], b"P", &[], None, &[], Some(&shared_plan()), &[]);
        assert!(Package::parse(&good).is_ok());
        let block = u32::from_le_bytes(good[40..44].try_into().unwrap()) as usize;
        let u32_field = |bytes: &mut alloc::vec::Vec<u8>, at: usize, v: u32| {
            bytes[block + at..block + at + 4].copy_from_slice(&v.to_le_bytes())
        };
        let refused = |bytes: &[u8], what: &str| {
            assert_eq!(
                Package::parse(bytes).unwrap_err(),
                PackageError::BadShared,
                "{what}"
            )
        };
        for (at, value, what) in [
            (0, 0x123, "segment not page-aligned"),
            (8, 32, "own area beyond the segment"),
            (12, 4, "own area not 8-aligned"),
            (16, 4, "own area shorter than its header"),
            (12, 8, "areas overlap"),
            (20, u32::MAX - 3, "other area offset overflows"),
            (24, 12, "a read variable beyond its area"),
            (36 + 4, 4, "a written variable inside the area header"),
            (36 + 4, 10, "a written variable not naturally aligned"),
            (36 + 8, 3, "a variable size of 3"),
            (36 + 12 + 8, 0, "a variable size of 0"),
        ] {
            let mut bad = good.clone();
            u32_field(&mut bad, at, value);
            refused(&bad, what);
        }
        // Counts beyond the records, a block beyond the package, records without an area.
        let mut bad = good.clone();
        bad[block + 28] = 9;
        refused(&bad, "more records than the block holds");
        let mut bad = good.clone();
        bad[44] = 0xff;
        refused(&bad, "block beyond the package");
        let mut bad = good.clone();
        u32_field(&mut bad, 12, NO_AREA);
        refused(&bad, "written records without an own area");
        // Two written variables on the same bytes.
        let mut plan = shared_plan();
        plan.written.push(plan.written[0]);
        refused(
            &encode(&[level()], b"P", &[], None, &[], Some(&plan), &[]),
            "written overlap",
        );
        // Every truncation and single-byte change of the block parses or is refused.
        for n in block..good.len() {
            let _ = Package::parse(&good[..n]);
            for v in [0u8, 1, 0x7f, 0xff] {
                let mut bad = good.clone();
                bad[n] = v;
                let _ = Package::parse(&bad);
            }
        }
    }

    #[test]
    fn hostile_packages_are_refused_never_panic() {
        let good = encode(
            &[level(), valve()],
            b"PLCB",
            &["a"],
            None,
            &[SafeValue {
                address: 0,
                width: 1,
                value: 1,
            }],
            None,
            &[TaskDeadline {
                task: "t",
                deadline_ns: 1,
            }],
        );
        assert_eq!(
            Package::parse(&good[..10]).unwrap_err(),
            PackageError::TooShort
        );
        assert_eq!(
            Package::parse(&good[..80]).unwrap_err(),
            PackageError::TooShort
        );
        let mut bad = good.clone();
        bad[0] = b'X';
        assert_eq!(Package::parse(&bad).unwrap_err(), PackageError::BadMagic);
        let mut bad = good.clone();
        bad[4] = 9;
        assert_eq!(
            Package::parse(&bad).unwrap_err(),
            PackageError::UnsupportedVersion(9)
        );
        let mut bad = good.clone();
        bad[6] = 200;
        assert_eq!(
            Package::parse(&bad).unwrap_err(),
            PackageError::TooManyPorts(200)
        );
        let mut bad = good.clone();
        bad[12] = 0xff;
        assert_eq!(
            Package::parse(&bad).unwrap_err(),
            PackageError::ProgramOutOfBounds
        );
        let mut bad = good.clone();
        bad[20] = 0xff;
        assert_eq!(
            Package::parse(&bad).unwrap_err(),
            PackageError::BadWatchList
        );
        let mut bad = good.clone();
        let watch_at = u32::from_le_bytes(bad[16..20].try_into().unwrap()) as usize;
        bad[watch_at] = 0xff;
        assert_eq!(
            Package::parse(&bad).unwrap_err(),
            PackageError::BadWatchList
        );
        // Safe values: a width of 3, a value wider than its byte, reserved bytes, ragged.
        let safe_at = u32::from_le_bytes(good[32..36].try_into().unwrap()) as usize;
        for (at, v) in [(4, 3u8), (9, 1), (5, 1)] {
            let mut bad = good.clone();
            bad[safe_at + at] = v;
            assert_eq!(
                Package::parse(&bad).unwrap_err(),
                PackageError::BadSafeValues,
                "safe record byte {at} = {v}"
            );
        }
        let mut bad = good.clone();
        bad[36] = 15;
        assert_eq!(
            Package::parse(&bad).unwrap_err(),
            PackageError::BadSafeValues
        );
        // Deadlines: ragged, an empty name, a gap in the name, a zero deadline.
        let mut bad = good.clone();
        bad[52] = 39;
        assert_eq!(
            Package::parse(&bad).unwrap_err(),
            PackageError::BadDeadlines
        );
        let deadline_at = u32::from_le_bytes(good[48..52].try_into().unwrap()) as usize;
        for (at, v) in [(0, 0u8), (2, b'x'), (NAME_LEN, 0)] {
            let mut bad = good.clone();
            bad[deadline_at + at] = v;
            assert_eq!(
                Package::parse(&bad).unwrap_err(),
                PackageError::BadDeadlines,
                "deadline record byte {at} = {v}"
            );
        }
        // Record fields: kind, direction, size 0, beyond the area, a bit above 7, a
        // validity bit on an output, a name with a gap.
        let record = HEADER_LEN + PORT_RECORD;
        for (at, value) in [
            (32, 9),
            (33, 0),
            (36, 0),
            (55, 0xff),
            (60, 8),
            (56, 0),
            (3, 0),
        ] {
            let mut bad = good.clone();
            bad[record + at] = value;
            assert_eq!(
                Package::parse(&bad).unwrap_err(),
                PackageError::BadPort(1),
                "byte {at} = {value}"
            );
        }
        // Every truncation and every single-byte change parses or is refused.
        for n in 0..good.len() {
            let _ = Package::parse(&good[..n]);
            for v in [0u8, 1, 0x7f, 0xff] {
                let mut bad = good.clone();
                bad[n] = v;
                let _ = Package::parse(&bad);
            }
        }
    }

    fn frame_port(name: &'static str, direction: Direction) -> PortMap<'static> {
        PortMap {
            name,
            kind: PortKind::Queuing,
            direction,
            size: FRAME_MAX,
            refresh_ns: 0,
            depth: 32,
            area_offset: 0,
            valid: None,
        }
    }

    fn network() -> Net<'static> {
        Net {
            mac: [0x52, 0x54, 0, 0x12, 0x34, 0x56],
            address: [10, 0, 2, 16],
            prefix: 24,
            gateway: Some([10, 0, 2, 2]),
            rx: 1,
            tx: 2,
            connections: 8,
            buffer: 2048,
            requests_per_second: 200,
            modbus: Some(Modbus {
                port: 502,
                unit: 1,
                write_outputs: false,
                write_markers: true,
            }),
            online: None,
            pubsub: None,
            ring: None,
        }
    }

    #[test]
    fn the_store_block_round_trips_after_a_network_block_and_hostile_ones_are_refused() {
        let store_port = |name, direction, size| PortMap {
            size,
            ..frame_port(name, direction)
        };
        let ports = [
            level(),
            frame_port("eth-rx", Direction::In),
            frame_port("eth-tx", Direction::Out),
            store_port("disk-req", Direction::Out, STORE_REQUEST_MIN),
            store_port("disk-resp", Direction::In, STORE_RESPONSE_MIN),
        ];
        let store = Store {
            request: 3,
            response: 4,
            sectors: 2048,
            retain_every_ns: 1_000_000_000,
        };
        let plain = encode(&ports, b"P", &[], None, &[], None, &[]);
        assert_eq!(Package::parse(&plain).unwrap().store(), None);
        let mut good = plain.clone();
        attach_net(&mut good, &network());
        attach_store(&mut good, &store);
        let package = Package::parse(&good).unwrap();
        assert_eq!(package.store(), Some(store));
        assert_eq!(package.net(), Some(network()));
        assert!(!package.is_image_port(3) && !package.is_image_port(4));
        let mut alone = plain.clone();
        attach_store(&mut alone, &store);
        assert_eq!(Package::parse(&alone).unwrap().store(), Some(store));
        let block = good.len() - STORE_BLOCK;
        // Ports swapped (wrong directions), a frame port (too small a response port is
        // not: it is big enough), a reserved byte, no sectors, no interval, a cut block.
        for (at, value) in [(0, 4), (1, 3), (0, 0), (2, 1), (8, 0), (16, 0)] {
            let mut bad = good.clone();
            if at == 8 || at == 16 {
                bad[block + at..block + at + 8].fill(value);
            } else {
                bad[block + at] = value;
            }
            assert_eq!(
                Package::parse(&bad).unwrap_err(),
                PackageError::BadStore,
                "byte {at} = {value}"
            );
        }
        assert!(Package::parse(&good[..good.len() - 1]).is_err());
    }

    #[test]
    fn the_online_clients_round_trip_and_hostile_records_are_refused() {
        let ports = [
            level(),
            frame_port("eth-rx", Direction::In),
            frame_port("eth-tx", Direction::Out),
        ];
        let clients = [
            ClientKey {
                name: b"engineering",
                secret: &[7; 32],
                access: Access::Download,
            },
            ClientKey {
                name: b"hmi",
                secret: &[9; 16],
                access: Access::Monitor,
            },
        ];
        let records = OnlineTcp::records(&clients);
        let net = Net {
            online: OnlineTcp::new(1202, &records),
            ..network()
        };
        assert!(net.online.is_some());
        let mut good = encode(&ports, b"P", &[], None, &[], None, &[]);
        let block = good.len();
        attach_net(&mut good, &net);
        let package = Package::parse(&good).unwrap();
        let online = package.net().unwrap().online.unwrap();
        assert_eq!(online.port, 1202);
        let got: Vec<_> = online
            .clients()
            .map(|c| (c.name, c.secret, c.access))
            .collect();
        assert_eq!(
            got,
            [
                (&b"engineering"[..], &[7u8; 32][..], Access::Download),
                (&b"hmi"[..], &[9u8; 16][..], Access::Monitor)
            ]
        );
        // Port 0, a name of 0 or 33 bytes, a key of 15 or 65 bytes, an unknown access, a
        // reserved byte, bytes past a name or a key, a cut record, no records.
        let first = block + NET_BLOCK;
        for (at, value) in [
            (block + 30, 0),
            (first, 0),
            (first, 33),
            (first + 2, 15),
            (first + 2, 65),
            (first + 1, 9),
            (first + 3, 1),
            (first + 4 + 11, b'x'),
            (first + 36 + 32, 1),
        ] {
            let mut bad = good.clone();
            bad[at] = value;
            if at == block + 30 {
                bad[at + 1] = 0;
            }
            assert_eq!(
                Package::parse(&bad).unwrap_err(),
                PackageError::BadNet,
                "byte {at} = {value}"
            );
        }
        assert!(Package::parse(&good[..good.len() - 1]).is_err());
        let mut none = good[..first].to_vec();
        assert!(Package::parse(&none).is_err());
        none[block + 11] &= !NET_ONLINE;
        assert!(Package::parse(&none).is_err(), "a port without the flag");
        none[block + 30..block + 32].fill(0);
        assert!(Package::parse(&none).is_ok());
    }

    #[test]
    fn the_pubsub_part_round_trips_beside_the_clients_and_hostile_ones_are_refused() {
        let ports = [
            level(),
            frame_port("eth-rx", Direction::In),
            frame_port("eth-tx", Direction::Out),
        ];
        let pubsub = PubSub {
            publish: Some(([10, 0, 2, 16], 61499, "level\nlevel_ok")),
            subscribe: Some(Subscription {
                port: 61500,
                group: Some([239, 0, 0, 1]),
                timeout_ns: 100_000_000,
                names: "valve",
                valid: Some("valve_ok"),
            }),
        };
        let clients = [ClientKey {
            name: b"eng",
            secret: &[1; 16],
            access: Access::Force,
        }];
        let records = OnlineTcp::records(&clients);
        let net = Net {
            pubsub: Some(pubsub),
            online: OnlineTcp::new(1202, &records),
            ..network()
        };
        let mut good = encode(&ports, b"P", &[], None, &[], None, &[]);
        let block = good.len();
        attach_net(&mut good, &net);
        let parsed = Package::parse(&good).unwrap().net().unwrap();
        assert_eq!(parsed.pubsub, Some(pubsub));
        assert_eq!(parsed.online.unwrap().clients().count(), 1);
        assert_eq!(parsed.ring, None);
        // With a frame ring too (its part first), and a ring of size 0 refused.
        let ring = Some((0x6000_0000_0000, 65536));
        let mut with_ring = encode(&ports, b"P", &[], None, &[], None, &[]);
        attach_net(&mut with_ring, &Net { ring, ..net });
        let parsed = Package::parse(&with_ring).unwrap().net().unwrap();
        assert_eq!((parsed.ring, parsed.pubsub), (ring, Some(pubsub)));
        assert_eq!(parsed.online.unwrap().clients().count(), 1);
        let mut empty = encode(&ports, b"P", &[], None, &[], None, &[]);
        attach_net(
            &mut empty,
            &Net {
                ring: Some((0x6000_0000_0000, 0)),
                ..net
            },
        );
        assert!(Package::parse(&empty).is_err());
        // Alone, each half.
        for half in [
            PubSub {
                subscribe: None,
                ..pubsub
            },
            PubSub {
                publish: None,
                ..pubsub
            },
        ] {
            let mut one = encode(&ports, b"P", &[], None, &[], None, &[]);
            attach_net(
                &mut one,
                &Net {
                    pubsub: Some(half),
                    ..network()
                },
            );
            assert_eq!(
                Package::parse(&one).unwrap().net().unwrap().pubsub,
                Some(half)
            );
        }
        // A publication without a port, a subscription timeout of 0, a reserved byte,
        // names longer than the part, an empty name, text that is not UTF-8, a group that
        // is no multicast address.
        let part = block + NET_BLOCK;
        for (at, value) in [
            (part + 4, 0u8),
            (part + 8, 0),
            (part + 21, 1),
            (part + 16, 200),
            (part + PUBSUB_HEAD, b'\n'),
            (part + PUBSUB_HEAD + 1, 0xff),
            (part + 24, 10),
        ] {
            let mut bad = good.clone();
            bad[at] = value;
            if at == part + 4 {
                bad[at + 1] = 0;
            }
            if at == part + 8 {
                bad[at + 1..at + 8].fill(0);
            }
            assert_eq!(
                Package::parse(&bad).unwrap_err(),
                PackageError::BadNet,
                "byte {at} = {value}"
            );
        }
    }

    #[test]
    fn the_network_block_round_trips_and_hostile_ones_are_refused() {
        let ports = [
            level(),
            frame_port("eth-rx", Direction::In),
            frame_port("eth-tx", Direction::Out),
        ];
        let plain = encode(&ports, b"P", &[], None, &[], None, &[]);
        assert_eq!(Package::parse(&plain).unwrap().net(), None);
        let mut good = plain.clone();
        attach_net(&mut good, &network());
        let package = Package::parse(&good).unwrap();
        assert_eq!(package.net(), Some(network()));
        assert!(package.is_image_port(0));
        assert!(!package.is_image_port(1) && !package.is_image_port(2));
        let block = plain.len();
        // A frame port of the wrong direction, a multicast MAC, a prefix of 0, no
        // connections, a tiny buffer, no rate, an unknown flag, a Modbus port 0, a cut block.
        for (at, value) in [
            (16, 2),
            (16, 9),
            (0, 1),
            (10, 0),
            (18, 0),
            (18, 33),
            (21, 0),
            (24, 0),
            (11, 0x23),
            (30, 1),
            (28, 0),
        ] {
            let mut bad = good.clone();
            bad[block + at] = value;
            if at == 28 {
                bad[block + 29] = 0;
            }
            if at == 24 {
                bad[block + 25..block + 28].fill(0);
            }
            if at == 21 {
                bad[block + 20] = 0;
            }
            assert_eq!(
                Package::parse(&bad).unwrap_err(),
                PackageError::BadNet,
                "byte {at} = {value}"
            );
        }
        assert_eq!(
            Package::parse(&good[..good.len() - 1]).unwrap_err(),
            PackageError::BadNet
        );
        for n in block..good.len() {
            for v in [0u8, 1, 0x7f, 0xff] {
                let mut bad = good.clone();
                bad[n] = v;
                let _ = Package::parse(&bad);
            }
        }
    }
}
