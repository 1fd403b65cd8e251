//! What an IEC 61499 partition boots from: its data entry, written by `cargo xtask` from the
//! partition's `iec61499.*` keys. The basic FB types it needs beyond the standard library
//! (compiled on the host into type packages, `iec61499_runtime::package`) and the boot file
//! (`.fboot` text) the device carries out at start. An interface, integers little-endian;
//! decoding never panics and checks everything but the types themselves, which
//! [`crate::Device::add_type`] checks whole.
//!
//! ```text
//! 0  4 magic "W61D"          4 2 version (1)            6 2 type count
//! 8  4 CRC-32 of the bytes from offset 12 to the end
//! 12 4 boot file length      16 4 queue depth (events)  20 4 events per chain
//! 24 1 management ports: 0 none, 1 the ports follow
//!   [1 access (`serve::Access` code), then request and response port: name length u8,
//!    name (UTF-8), message size u32, depth u32]
//! .. 1 network interface and the management protocol on TCP (`crate::tcp`): 0 none, 1 it
//!   follows [6 MAC, 4 IPv4 address, 1 prefix length, 1 gateway (0 none, 1 the 4 bytes
//!   follow), TCP port u16, connections u8, access u8, then the frame ports rx (in) and
//!   tx (out) as the management ports, then the frame ring: 0 none, 1 its segment's
//!   address u64 and size u64 (not 0) follow (`frame_ring`; the ports then carry the
//!   wake-ups)]
//! .. sampling ports (for the process-image FBs, `crate::sifb`): count u16, per port: name
//!    length u8, name, direction u8 (1 in, 0 out), message size u32, refresh period u64 (ns)
//! .. queuing ports (for PUBLISH/SUBSCRIBE, `crate::pubsub`): count u16, per port: name
//!    length u8, name, direction u8 (1 in, 0 out), message size u32, depth u32
//! .. resources with a process of their own: count u8 (at most [`MAX_RESOURCES`]), per
//!    resource: name length u8, name, the process's priority u8 (not 0)
//! .. per type: length u32, the type package; then the boot file (UTF-8)
//! ```
//!
//! [`boot`] makes the device a package describes; `cargo xtask` runs it on the host too, so
//! a boot file the device would refuse stops the build.

use crate::Device;
use crate::serve::Access;
use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;
use iec61499_runtime::Limits;

const MAGIC: &[u8; 4] = b"W61D";
const VERSION: u16 = 4;
/// The most types one package may carry.
pub const MAX_TYPES: usize = 256;
/// The most sampling ports a package names (a partition has fewer).
pub const MAX_PORTS: usize = 128;
/// The most resources a device holds.
pub const MAX_RESOURCES: usize = 4;
/// The largest event queue and chain a package may ask for.
pub const MAX_QUEUE: usize = 4096;
pub const MAX_CHAIN_EVENTS: usize = 1_000_000;

/// A device package: borrowed views of its parts.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DevicePackage<'a> {
    /// Each type package, in the order the configuration names them.
    pub types: Vec<&'a [u8]>,
    /// The boot file.
    pub boot: &'a str,
    /// Each resource's event-queue depth and the events one chain may deliver.
    pub queue: usize,
    pub chain_events: usize,
    /// The queuing ports of the management protocol, if it has a client.
    pub mgmt: Option<MgmtPorts<'a>>,
    /// The network interface and the management protocol's TCP port, if it has one.
    pub net: Option<NetPorts<'a>>,
    /// The partition's sampling ports.
    pub ports: Vec<SamplingPort<'a>>,
    /// The partition's queuing ports other than the management ones.
    pub queues: Vec<DataQueue<'a>>,
    /// The resources that run in a process of their own, and its priority.
    pub processes: Vec<ResourceProcess<'a>>,
}

/// A resource that runs in a process of its own (`iec61499.resources`): its timers and the
/// chains they start run there, at the process's priority.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ResourceProcess<'a> {
    pub resource: &'a str,
    pub priority: u8,
}

/// A queuing port for PUBLISH/SUBSCRIBE as the partition creates it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DataQueue<'a> {
    pub port: QueuingPort<'a>,
    /// The partition receives on it.
    pub input: bool,
}

/// A sampling port as the partition creates it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SamplingPort<'a> {
    pub name: &'a str,
    pub input: bool,
    pub size: u32,
    pub refresh_ns: u64,
}

/// The management protocol's ports ([`crate::serve`]) and what their client may do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MgmtPorts<'a> {
    pub access: Access,
    pub request: QueuingPort<'a>,
    pub response: QueuingPort<'a>,
}

/// The partition's interface on the NIC partition's switch (its frames on two queuing
/// ports) and the management protocol's TCP server on it ([`crate::tcp`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NetPorts<'a> {
    pub mac: [u8; 6],
    pub address: [u8; 4],
    pub prefix: u8,
    pub gateway: Option<[u8; 4]>,
    /// The TCP port of the management protocol.
    pub port: u16,
    /// Connections at once (1..=`tcp::server::MAX_CONNECTIONS`).
    pub connections: u8,
    /// What every client on TCP may do.
    pub access: Access,
    /// The queuing input of received frames and output of frames to send (with a ring:
    /// of its wake-ups).
    pub rx: QueuingPort<'a>,
    pub tx: QueuingPort<'a>,
    /// The frame ring's segment (address, size) when the frames go through one.
    pub ring: Option<(u64, u64)>,
}

/// A queuing port as the partition creates it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QueuingPort<'a> {
    pub name: &'a str,
    pub size: u32,
    pub depth: u32,
}

/// Why a device package was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DevicePackageError {
    /// It does not start with the magic bytes (not a device package).
    Magic,
    /// A version this runtime does not read.
    Version(u16),
    /// The checksum does not match (damaged).
    Checksum,
    /// The bytes end inside the field at this offset.
    Truncated(usize),
    /// More types than [`MAX_TYPES`].
    TooManyTypes(usize),
    /// The boot file is not UTF-8.
    BootText,
    /// Bytes follow the boot file.
    Trailing(usize),
    /// A queue depth or chain length of 0 or above [`MAX_QUEUE`] / [`MAX_CHAIN_EVENTS`].
    Limit(&'static str, usize),
    /// The management-ports field at this offset is not valid.
    Mgmt(usize),
    /// The network field at this offset is not valid.
    Net(usize),
    /// The sampling- or queuing-ports field at this offset is not valid.
    Ports(usize),
    /// The resource-processes field at this offset is not valid (too many, an empty name,
    /// priority 0).
    Processes(usize),
}

impl core::fmt::Display for DevicePackageError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Magic => f.write_str("not an IEC 61499 device package (bad magic)"),
            Self::Version(v) => write!(
                f,
                "device package version {v} (this runtime reads {VERSION})"
            ),
            Self::Checksum => f.write_str("device package checksum mismatch (damaged)"),
            Self::Truncated(at) => write!(f, "device package ends inside the field at offset {at}"),
            Self::TooManyTypes(n) => {
                write!(f, "device package has {n} types (at most {MAX_TYPES})")
            }
            Self::BootText => f.write_str("the boot file is not UTF-8"),
            Self::Trailing(at) => write!(f, "bytes after the boot file at offset {at}"),
            Self::Limit(what, n) => write!(f, "{what} {n} is out of range"),
            Self::Mgmt(at) => write!(f, "invalid management ports at offset {at}"),
            Self::Net(at) => write!(f, "invalid network interface at offset {at}"),
            Self::Ports(at) => write!(f, "invalid sampling or queuing ports at offset {at}"),
            Self::Processes(at) => write!(f, "invalid resource processes at offset {at}"),
        }
    }
}

fn crc(bytes: &[u8]) -> u32 {
    let mut c = abi::crc32::Crc32::new();
    c.update(bytes);
    c.finish()
}

/// The bytes of `package`.
pub fn encode(package: &DevicePackage<'_>) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&(package.types.len() as u16).to_le_bytes());
    let mut body = Vec::new();
    body.extend_from_slice(&(package.boot.len() as u32).to_le_bytes());
    body.extend_from_slice(&(package.queue as u32).to_le_bytes());
    body.extend_from_slice(&(package.chain_events as u32).to_le_bytes());
    match &package.mgmt {
        None => body.push(0),
        Some(m) => {
            body.push(1);
            body.push(m.access as u8);
            for port in [m.request, m.response] {
                push_name(&mut body, port.name);
                body.extend_from_slice(&port.size.to_le_bytes());
                body.extend_from_slice(&port.depth.to_le_bytes());
            }
        }
    }
    match &package.net {
        None => body.push(0),
        Some(n) => {
            body.push(1);
            body.extend_from_slice(&n.mac);
            body.extend_from_slice(&n.address);
            body.push(n.prefix);
            match n.gateway {
                None => body.push(0),
                Some(g) => {
                    body.push(1);
                    body.extend_from_slice(&g);
                }
            }
            body.extend_from_slice(&n.port.to_le_bytes());
            body.push(n.connections);
            body.push(n.access as u8);
            for port in [n.rx, n.tx] {
                push_name(&mut body, port.name);
                body.extend_from_slice(&port.size.to_le_bytes());
                body.extend_from_slice(&port.depth.to_le_bytes());
            }
            match n.ring {
                None => body.push(0),
                Some((address, size)) => {
                    body.push(1);
                    body.extend_from_slice(&address.to_le_bytes());
                    body.extend_from_slice(&size.to_le_bytes());
                }
            }
        }
    }
    body.extend_from_slice(&(package.ports.len() as u16).to_le_bytes());
    for port in &package.ports {
        push_name(&mut body, port.name);
        body.push(u8::from(port.input));
        body.extend_from_slice(&port.size.to_le_bytes());
        body.extend_from_slice(&port.refresh_ns.to_le_bytes());
    }
    body.extend_from_slice(&(package.queues.len() as u16).to_le_bytes());
    for q in &package.queues {
        push_name(&mut body, q.port.name);
        body.push(u8::from(q.input));
        body.extend_from_slice(&q.port.size.to_le_bytes());
        body.extend_from_slice(&q.port.depth.to_le_bytes());
    }
    body.push(package.processes.len() as u8);
    for p in &package.processes {
        push_name(&mut body, p.resource);
        body.push(p.priority);
    }
    for t in &package.types {
        body.extend_from_slice(&(t.len() as u32).to_le_bytes());
        body.extend_from_slice(t);
    }
    body.extend_from_slice(package.boot.as_bytes());
    out.extend_from_slice(&crc(&body).to_le_bytes());
    out.extend_from_slice(&body);
    out
}

/// A name: length u8, then at most 255 bytes of it (port names are far shorter).
fn push_name(body: &mut Vec<u8>, name: &str) {
    let name = &name.as_bytes()[..name.len().min(255)];
    body.push(name.len() as u8);
    body.extend_from_slice(name);
}

fn name_at<'a>(bytes: &'a [u8], at: &mut usize) -> Result<&'a str, DevicePackageError> {
    let field = *at;
    let len = usize::from(take(bytes, at, 1)?[0]);
    core::str::from_utf8(take(bytes, at, len)?).map_err(|_| DevicePackageError::Ports(field))
}

fn take<'a>(bytes: &'a [u8], at: &mut usize, len: usize) -> Result<&'a [u8], DevicePackageError> {
    let end = at
        .checked_add(len)
        .filter(|&end| end <= bytes.len())
        .ok_or(DevicePackageError::Truncated(*at))?;
    let part = &bytes[*at..end];
    *at = end;
    Ok(part)
}

fn u32_at(bytes: &[u8], at: &mut usize) -> Result<usize, DevicePackageError> {
    let b = take(bytes, at, 4)?;
    Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
}

/// A list of ports: count u16 (at most [`MAX_PORTS`]), per port its name, its direction
/// (u8: 1 in, 0 out) and what `rest` reads after them.
fn port_list<'a, T>(
    bytes: &'a [u8],
    at: &mut usize,
    mut rest: impl FnMut(&'a [u8], &mut usize, &'a str, bool) -> Result<T, DevicePackageError>,
) -> Result<Vec<T>, DevicePackageError> {
    let field = *at;
    let count = take(bytes, at, 2)?;
    let count = usize::from(u16::from_le_bytes([count[0], count[1]]));
    if count > MAX_PORTS {
        return Err(DevicePackageError::Ports(field));
    }
    let mut ports = Vec::with_capacity(count);
    for _ in 0..count {
        let name = name_at(bytes, at)?;
        let field = *at;
        let input = match take(bytes, at, 1)?[0] {
            0 => false,
            1 => true,
            _ => return Err(DevicePackageError::Ports(field)),
        };
        ports.push(rest(bytes, at, name, input)?);
    }
    Ok(ports)
}

/// Reads a device package.
pub fn decode(bytes: &[u8]) -> Result<DevicePackage<'_>, DevicePackageError> {
    let mut at = 0;
    if take(bytes, &mut at, 4)? != MAGIC {
        return Err(DevicePackageError::Magic);
    }
    let header = take(bytes, &mut at, 4)?;
    let version = u16::from_le_bytes([header[0], header[1]]);
    if version != VERSION {
        return Err(DevicePackageError::Version(version));
    }
    let count = usize::from(u16::from_le_bytes([header[2], header[3]]));
    if count > MAX_TYPES {
        return Err(DevicePackageError::TooManyTypes(count));
    }
    let sum = u32_at(bytes, &mut at)? as u32;
    if crc(&bytes[at..]) != sum {
        return Err(DevicePackageError::Checksum);
    }
    let boot_len = u32_at(bytes, &mut at)?;
    let queue = u32_at(bytes, &mut at)?;
    if !(1..=MAX_QUEUE).contains(&queue) {
        return Err(DevicePackageError::Limit("queue depth", queue));
    }
    let chain_events = u32_at(bytes, &mut at)?;
    if !(1..=MAX_CHAIN_EVENTS).contains(&chain_events) {
        return Err(DevicePackageError::Limit("events per chain", chain_events));
    }
    let mgmt = match take(bytes, &mut at, 1)?[0] {
        0 => None,
        1 => {
            let field = at;
            let access = Access::from_code(take(bytes, &mut at, 1)?[0])
                .ok_or(DevicePackageError::Mgmt(field))?;
            let mut port = || -> Result<QueuingPort<'_>, DevicePackageError> {
                let name = name_at(bytes, &mut at)?;
                let size = u32_at(bytes, &mut at)? as u32;
                let depth = u32_at(bytes, &mut at)? as u32;
                Ok(QueuingPort { name, size, depth })
            };
            let request = port()?;
            let response = port()?;
            Some(MgmtPorts {
                access,
                request,
                response,
            })
        }
        _ => return Err(DevicePackageError::Mgmt(at - 1)),
    };
    let net = net_at(bytes, &mut at)?;
    let ports = port_list(bytes, &mut at, |bytes, at, name, input| {
        let size = u32_at(bytes, at)? as u32;
        let refresh = take(bytes, at, 8)?;
        let mut raw = [0u8; 8];
        raw.copy_from_slice(refresh);
        Ok(SamplingPort {
            name,
            input,
            size,
            refresh_ns: u64::from_le_bytes(raw),
        })
    })?;
    let queues = port_list(bytes, &mut at, |bytes, at, name, input| {
        let size = u32_at(bytes, at)? as u32;
        let depth = u32_at(bytes, at)? as u32;
        Ok(DataQueue {
            port: QueuingPort { name, size, depth },
            input,
        })
    })?;
    let field = at;
    let process_count = usize::from(take(bytes, &mut at, 1)?[0]);
    if process_count > MAX_RESOURCES {
        return Err(DevicePackageError::Processes(field));
    }
    let mut processes = Vec::with_capacity(process_count);
    for _ in 0..process_count {
        let field = at;
        let resource = name_at(bytes, &mut at)?;
        let priority = take(bytes, &mut at, 1)?[0];
        if resource.is_empty() || priority == 0 {
            return Err(DevicePackageError::Processes(field));
        }
        processes.push(ResourceProcess { resource, priority });
    }
    let mut types = Vec::with_capacity(count);
    for _ in 0..count {
        let len = u32_at(bytes, &mut at)?;
        types.push(take(bytes, &mut at, len)?);
    }
    let boot = core::str::from_utf8(take(bytes, &mut at, boot_len)?)
        .map_err(|_| DevicePackageError::BootText)?;
    if at != bytes.len() {
        return Err(DevicePackageError::Trailing(at));
    }
    Ok(DevicePackage {
        types,
        boot,
        queue,
        chain_events,
        mgmt,
        net,
        ports,
        queues,
        processes,
    })
}

/// The network field at `at`.
fn net_at<'a>(bytes: &'a [u8], at: &mut usize) -> Result<Option<NetPorts<'a>>, DevicePackageError> {
    let field = *at;
    let bad = DevicePackageError::Net(field);
    match take(bytes, at, 1)?[0] {
        0 => return Ok(None),
        1 => {}
        _ => return Err(bad),
    }
    let array = |at: &mut usize, len: usize| take(bytes, at, len);
    let mut mac = [0u8; 6];
    mac.copy_from_slice(array(at, 6)?);
    let mut address = [0u8; 4];
    address.copy_from_slice(array(at, 4)?);
    let prefix = array(at, 1)?[0];
    let gateway = match array(at, 1)?[0] {
        0 => None,
        1 => {
            let mut g = [0u8; 4];
            g.copy_from_slice(array(at, 4)?);
            Some(g)
        }
        _ => return Err(bad),
    };
    let port = array(at, 2)?;
    let port = u16::from_le_bytes([port[0], port[1]]);
    let connections = array(at, 1)?[0];
    let access = Access::from_code(array(at, 1)?[0]).ok_or(bad)?;
    if !(1..=32).contains(&prefix) || connections == 0 {
        return Err(bad);
    }
    let mut queuing = || -> Result<QueuingPort<'a>, DevicePackageError> {
        let name = name_at(bytes, at)?;
        let size = u32_at(bytes, at)? as u32;
        let depth = u32_at(bytes, at)? as u32;
        Ok(QueuingPort { name, size, depth })
    };
    let rx = queuing()?;
    let tx = queuing()?;
    let ring = match array(at, 1)?[0] {
        0 => None,
        1 => {
            let word = |at: &mut usize| -> Result<u64, DevicePackageError> {
                let b = array(at, 8)?;
                Ok(u64::from_le_bytes(core::array::from_fn(|i| b[i])))
            };
            let (address, size) = (word(at)?, word(at)?);
            if size == 0 {
                return Err(bad);
            }
            Some((address, size))
        }
        _ => return Err(bad),
    };
    Ok(Some(NetPorts {
        mac,
        address,
        prefix,
        gateway,
        port,
        connections,
        access,
        rx,
        tx,
        ring,
    }))
}

/// What [`boot`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Booted {
    pub types: usize,
    pub requests: usize,
}

/// The device a package describes, its process-image FBs on `io`, its types added and its
/// boot file carried out at instant `now`; or why not (the package, a type or a boot-file
/// line, named).
pub fn boot(
    bytes: &[u8],
    io: alloc::boxed::Box<dyn crate::sifb::ProcessIo>,
    now: i64,
) -> Result<(Device, Booted), String> {
    let package = decode(bytes).map_err(|e| format!("{e}"))?;
    let limits = Limits {
        queue: package.queue,
        chain_events: package.chain_events,
        ..Limits::default()
    };
    let mut device = Device::new(limits, MAX_RESOURCES);
    device.set_io(io);
    for (index, t) in package.types.iter().enumerate() {
        device
            .add_type(t)
            .map_err(|e| format!("type {} of the package: {e}", index + 1))?;
    }
    let requests = device.boot(package.boot, now)?;
    Ok((
        device,
        Booted {
            types: package.types.len(),
            requests,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sifb::NoPorts;
    use alloc::boxed::Box;
    use alloc::vec;

    fn package<'a>(
        types: &[&'a [u8]],
        boot: &'a str,
        queue: usize,
        chain: usize,
    ) -> DevicePackage<'a> {
        DevicePackage {
            types: types.to_vec(),
            boot,
            queue,
            chain_events: chain,
            mgmt: None,
            net: None,
            ports: Vec::new(),
            queues: Vec::new(),
            processes: Vec::new(),
        }
    }

    #[test]
    fn round_trip() {
        let port = |name, depth| QueuingPort {
            name,
            size: 4096,
            depth,
        };
        let original = DevicePackage {
            types: vec![&[1, 2, 3], &[], &[9; 300]],
            boot: "R;<Request ID=\"1\" Action=\"START\"/>\n",
            queue: 8,
            chain_events: 100,
            mgmt: Some(MgmtPorts {
                access: Access::Force,
                request: port("fb-req", 4),
                response: port("fb-resp", 2),
            }),
            net: Some(NetPorts {
                mac: [0x52, 0x54, 0, 0x12, 0x34, 0x58],
                address: [10, 0, 2, 17],
                prefix: 24,
                gateway: Some([10, 0, 2, 2]),
                port: 61499,
                connections: 4,
                access: Access::Download,
                rx: port("eth-rx", 32),
                tx: port("eth-tx", 32),
                ring: Some((0x6000_0000_0000, 65536)),
            }),
            ports: vec![
                SamplingPort {
                    name: "level",
                    input: true,
                    size: 8,
                    refresh_ns: 100_000_000,
                },
                SamplingPort {
                    name: "valve",
                    input: false,
                    size: 8,
                    refresh_ns: 0,
                },
            ],
            queues: vec![
                DataQueue {
                    port: port("counts", 8),
                    input: false,
                },
                DataQueue {
                    port: port("counts-in", 4),
                    input: true,
                },
            ],
            processes: vec![
                ResourceProcess {
                    resource: "CYCLE",
                    priority: 40,
                },
                ResourceProcess {
                    resource: "SLOW",
                    priority: 30,
                },
            ],
        };
        assert_eq!(decode(&encode(&original)).unwrap(), original);
        let mut bad = original.clone();
        bad.processes[1].priority = 0;
        assert!(matches!(
            decode(&encode(&bad)),
            Err(DevicePackageError::Processes(_))
        ));
        bad.processes = vec![original.processes[0]; MAX_RESOURCES + 1];
        assert!(matches!(
            decode(&encode(&bad)),
            Err(DevicePackageError::Processes(_))
        ));
        let without_gateway = DevicePackage {
            net: original.net.map(|n| NetPorts {
                gateway: None,
                ring: None,
                ..n
            }),
            ..original
        };
        assert_eq!(decode(&encode(&without_gateway)).unwrap(), without_gateway);
        let plain = package(&[], "", 1, 1);
        assert_eq!(decode(&encode(&plain)).unwrap(), plain);
    }

    #[test]
    fn damage_is_refused_never_panics() {
        let bytes = encode(&package(&[&[7; 20]], "boot", 1, 1));
        assert_eq!(
            decode(&encode(&package(&[], "", 0, 1))),
            Err(DevicePackageError::Limit("queue depth", 0))
        );
        assert_eq!(decode(b"W61"), Err(DevicePackageError::Truncated(0)));
        assert_eq!(decode(b"W61TXXXXXXXXXXXX"), Err(DevicePackageError::Magic));
        // Version 1 had no queuing ports for PUBLISH/SUBSCRIBE, version 2 no network.
        for old in [1, 2] {
            let mut v = bytes.clone();
            v[4] = old;
            assert_eq!(decode(&v), Err(DevicePackageError::Version(u16::from(old))));
        }
        for i in 12..bytes.len() {
            let mut flipped = bytes.clone();
            flipped[i] ^= 0x40;
            assert_eq!(
                decode(&flipped),
                Err(DevicePackageError::Checksum),
                "byte {i}"
            );
        }
        for len in 0..bytes.len() {
            assert!(decode(&bytes[..len]).is_err(), "truncated to {len}");
        }
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(decode(&longer).is_err());
    }

    #[test]
    fn boot_runs_the_file_and_names_a_refused_line() {
        let ok = "\n;<Request ID=\"1\" Action=\"CREATE\"><FB Name=\"R\" Type=\"EMB_RES\"/></Request>\nR;<Request ID=\"2\" Action=\"START\"/>\n";
        let (_, booted) = boot(&encode(&package(&[], ok, 16, 100)), Box::new(NoPorts), 0).unwrap();
        assert_eq!(
            booted,
            Booted {
                types: 0,
                requests: 2
            }
        );
        let bad = ";<Request ID=\"1\" Action=\"CREATE\"><FB Name=\"R\" Type=\"NOPE\"/></Request>\n";
        let e = boot(&encode(&package(&[], bad, 16, 100)), Box::new(NoPorts), 0)
            .err()
            .unwrap();
        assert!(
            e.contains("line 1") && e.contains("UNSUPPORTED_TYPE"),
            "{e}"
        );
        let e = boot(
            &encode(&package(&[&[1, 2, 3]], ok, 16, 100)),
            Box::new(NoPorts),
            0,
        )
        .err()
        .unwrap();
        assert!(e.starts_with("type 1 of the package"), "{e}");
    }

    proptest::proptest! {
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..200)) {
            let _ = decode(&bytes);
        }
    }
}
