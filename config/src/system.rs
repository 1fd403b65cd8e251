//! The validated system (host side): what [`crate::load`] returns and
//! [`crate::binary::encode`] writes. Every value is already checked and in its final unit
//! (bytes, nanoseconds, indices); nothing here can be inconsistent.

use crate::binary::SystemView;
use crate::model::*;
use abi::syscall::Abilities;
use std::format;
use std::string::{String, ToString};
use std::vec::Vec;

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct System {
    pub name: String,
    /// RAM budget (bytes).
    pub memory: u64,
    /// CPUs the system uses (`cpus`, 1..=[`MAX_CPUS`]): CPUs 0..cpus.
    pub cpus: u8,
    /// The first is the initial schedule.
    pub schedules: Vec<Schedule>,
    /// In the order of the description.
    pub partitions: Vec<Partition>,
    pub segments: Vec<Segment>,
    pub channels: Vec<Channel>,
    /// The module health table.
    pub health: HealthTable,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Schedule {
    pub name: String,
    /// ns.
    pub major_frame: u64,
    /// Sorted by offset, inside the frame; those of one CPU disjoint.
    pub windows: Vec<Window>,
    /// What a switch to this schedule does to each partition (`change_actions`).
    pub change_actions: ChangeActions,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Segment {
    pub name: String,
    pub size: u64,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Partition {
    pub name: String,
    pub image: String,
    pub memory: u64,
    pub kernel_memory: u64,
    pub stack: u64,
    pub kernel_threads: u32,
    pub kernel_tasks: u32,
    pub abilities: Abilities,
    pub mcp: u8,
    pub priority: u8,
    /// 0 = background.
    pub time_partition: u8,
    /// The first of `cpus`: where its first thread starts.
    pub cpu: u8,
    /// The CPUs its threads run on (`cpus = [n, ...]`; bit n: CPU n), each in that CPU's
    /// windows of its time partition, or in that CPU's background.
    pub cpus: u8,
    /// May switch the module schedule (ARINC SET_MODULE_SCHEDULE).
    pub schedule_control: bool,
    pub io_ports: Vec<IoRange>,
    pub irqs: IrqMask,
    /// PCI functions it owns (`devices`), in the order given.
    pub devices: Vec<pci::Address>,
    /// Bytes of its DMA region (`dma`; 0: none), part of `memory`.
    pub dma: u64,
    /// Its devices may DMA without an IOMMU (`dma_unconfined`).
    pub dma_unconfined: bool,
    pub shared: Vec<Attachment>,
    pub ports: Vec<Port>,
    pub health: HealthTable,
    /// Its PLC program and process-image mapping (`plc.*`), if it runs the soft-PLC.
    pub plc: Option<Plc>,
    /// What `cargo xtask` puts into a partition's data entry other than a PLC package
    /// (`data.*`).
    pub data: Option<DataEntry>,
    /// Its first Linux process (`guest.*`), if it runs the paravirtualized guest.
    pub guest: Option<Guest>,
    /// Its boot file and FB types (`iec61499.*`), if it runs the IEC 61499 runtime.
    pub iec61499: Option<Iec61499>,
    /// The tenants of its switch (`nic.tenants`), if it is the NIC partition.
    pub nic: Option<Nic>,
    /// Its tenants' virtual disks (`blk.tenants`), if it is a block-device partition.
    pub blk: Option<Blk>,
}

/// A block-device partition's tenants, in the order of the description.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Blk {
    pub tenants: Vec<BlkTenant>,
}

/// A tenant's virtual disk: `sectors` sectors of 512 bytes of the disk from
/// `first_sector`, no two tenants' overlapping.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BlkTenant {
    /// Index into [`System::partitions`].
    pub partition: usize,
    /// The block-device partition's queuing input carrying the tenant's requests, and
    /// its queuing output to the tenant (indices into its ports).
    pub from: usize,
    pub to: usize,
    pub first_sector: u64,
    pub sectors: u64,
}

/// The NIC partition's tenants, in the order of the description.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Nic {
    pub tenants: Vec<NicTenant>,
}

/// A tenant attached to the NIC partition's switch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NicTenant {
    /// Index into [`System::partitions`].
    pub partition: usize,
    /// A unicast MAC address, unique among the tenants.
    pub mac: [u8; 6],
    /// The NIC partition's queuing input carrying the tenant's frames, and its queuing
    /// output to the tenant (indices into its ports).
    pub from: usize,
    pub to: usize,
    /// The shared-memory segment the frames go through instead of the ports, which then
    /// carry only the wake-ups (`frame_ring`).
    pub ring: Option<FrameRing>,
}

/// A frame ring's segment (`nic.tenants.<p>.ring`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameRing {
    /// Index into [`System::segments`].
    pub segment: usize,
    /// Where syssw maps it, the same in every partition.
    pub address: u64,
    pub size: u64,
}

/// An IEC 61499 partition's boot file and the basic FB types (`.fbt`) it needs beyond the
/// standard library; `cargo xtask` compiles the types and writes both into its data entry.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Iec61499 {
    pub boot: SourceFile,
    pub types: Vec<SourceFile>,
    /// The management protocol's ports and the client's access (`iec61499.mgmt`).
    pub mgmt: Option<OnlinePorts>,
    /// Its interface and the management protocol on TCP (`iec61499.net`).
    pub net: Option<Iec61499Net>,
    /// The resources with a process of their own (`iec61499.resources`), by name.
    pub resources: Vec<ResourceProcess>,
}

/// A resource of an IEC 61499 device that runs in its own process (`iec61499.resources`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ResourceProcess {
    /// The resource's name, as the boot file or a management client creates it.
    pub name: String,
    /// The process's priority (below the partition's `max_priority`).
    pub priority: u8,
}

impl ResourceProcess {
    /// Resources of a device with a process of their own, at most (the device's resources).
    pub const MAX: usize = 4;
    /// The longest resource name (the process is named after it, in 32 bytes).
    pub const MAX_NAME: usize = 24;
}

/// An IEC 61499 partition's interface on the NIC partition's switch (`iec61499.net`): the
/// link as a guest's `eth0`, and the management protocol's TCP server on it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Iec61499Net {
    pub link: GuestNet,
    /// The TCP port of the management protocol.
    pub port: u16,
    /// TCP connections open at once.
    pub connections: u8,
    /// What every client on the port may do (4diac's protocol carries no identity).
    pub access: plc_online::Access,
}

impl Iec61499Net {
    /// 4diac FORTE's management port, which 4diac IDE deploys to.
    pub const DEFAULT_PORT: u16 = 61499;
    pub const DEFAULT_CONNECTIONS: u8 = 4;
    pub const MAX_CONNECTIONS: u8 = 8;
}

/// What a guest partition starts: `argv` and the environment of its first process, and the
/// files it adds to its initramfs (all written into the initramfs by `cargo xtask`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Guest {
    pub init: Vec<String>,
    pub env: Vec<String>,
    /// (absolute path in the initramfs, host file), sorted by path.
    pub files: Vec<(String, SourceFile)>,
    /// The processes' console is a terminal on COM2 (`guest.console = "com2"`); otherwise
    /// their output goes to the log.
    pub console_com2: bool,
    /// Linux programs `cargo xtask` builds (one of [`GUEST_PROGRAMS`]) and adds as
    /// `/bin/<name>`, in the order given.
    pub programs: Vec<String>,
    /// `eth0` (`guest.net`); without it the guest has only the loopback.
    pub net: Option<GuestNet>,
    /// `/dev/vda` (`guest.disk`); without it the guest has no block device.
    pub disk: Option<GuestDisk>,
}

/// A guest's block device `/dev/vda` (`guest.disk`): the queuing ports of its link to a
/// block-device partition, whose `blk.tenants.<guest>` is the virtual disk (checked to
/// exist and to be joined to these ports by channels).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GuestDisk {
    /// Queuing output carrying the requests (size >= `blk_core::link::MAX_REQUEST`).
    pub request: String,
    /// Queuing input carrying the responses (size >= `blk_core::link::MAX_RESPONSE`).
    pub response: String,
    /// The virtual disk's size in sectors of 512 bytes (its `blk.tenants.<guest>.sectors`).
    pub sectors: u64,
}

impl GuestDisk {
    /// The file the guest reads it from (`/etc/guest/disk`, `guest::disk::DISK_PATH`):
    /// `key=value` lines.
    pub fn file(&self) -> String {
        format!(
            "request={}\nresponse={}\nsectors={}\n",
            self.request, self.response, self.sectors
        )
    }
}

/// A guest's `eth0`: its MAC and IPv4 address, the default route, and the queuing ports
/// its Ethernet frames go through (one frame a message, to and from the NIC partition).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GuestNet {
    pub mac: [u8; 6],
    pub address: [u8; 4],
    pub prefix: u8,
    pub gateway: Option<[u8; 4]>,
    /// The guest's queuing input port of received frames, and output port of frames to send.
    pub rx: String,
    pub tx: String,
    /// Where the frames go instead when the NIC partition's tenant entry names a frame ring
    /// (`nic.tenants.<p>.ring`): the segment's address and size; the ports then carry only
    /// the wake-ups (`frame_ring`).
    pub ring: Option<FrameRing>,
}

/// A PLC's interface on the NIC partition's switch (`plc.net`): the link as a guest's
/// `eth0`, and what its communication process allows.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlcNet {
    pub link: GuestNet,
    /// TCP connections open at once (all services together).
    pub connections: u8,
    /// Bytes of each connection's receive and of its send buffer.
    pub buffer: u32,
    /// Requests served per second per connection (more wait in its buffer).
    pub requests_per_second: u32,
}

impl PlcNet {
    pub const DEFAULT_CONNECTIONS: u8 = 8;
    pub const MAX_CONNECTIONS: u8 = 32;
    pub const DEFAULT_BUFFER: u32 = 2048;
    pub const DEFAULT_REQUESTS_PER_SECOND: u32 = 200;
}

/// The PLC's Modbus/TCP server (`plc.modbus`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PlcModbus {
    pub port: u16,
    pub unit: u8,
    /// Coils/holding registers of `%QX`/`%QW` writable from the network.
    pub write_outputs: bool,
    /// Coils/holding registers of `%MX`/`%MW` writable from the network.
    pub write_markers: bool,
}

/// The online protocol on TCP (`plc.online_tcp`; needs `plc.net`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlcOnlineTcp {
    pub port: u16,
    /// At least one, at most [`PlcOnlineTcp::MAX_CLIENTS`], names unique.
    pub clients: Vec<OnlineClient>,
}

impl PlcOnlineTcp {
    pub const DEFAULT_PORT: u16 = 1202;
    pub const MAX_CLIENTS: usize = 8;
}

/// A client of the online protocol on TCP: its name, its pre-shared key (read from the
/// key file) and what it may do.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OnlineClient {
    /// 1..=32 printable ASCII characters, no spaces (it appears in log lines).
    pub name: String,
    pub key: Vec<u8>,
    pub access: plc_online::Access,
}

/// PLC-to-PLC publication (`plc.publish`; needs `plc.net`): the variables' values in the
/// FBDK encoding, one UDP datagram to `to` after every release.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlcPublish {
    pub to: ([u8; 4], u16),
    /// Names of the program's variables (checked when it is compiled), 1..=16.
    pub vars: Vec<String>,
}

/// PLC-to-PLC subscription (`plc.subscribe`; needs `plc.net`): datagrams on `port` written
/// into the variables between releases; valid while the last good one is younger than
/// `timeout_ns`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlcSubscribe {
    pub port: u16,
    /// An IPv4 multicast group joined to receive its datagrams too.
    pub group: Option<[u8; 4]>,
    pub vars: Vec<String>,
    /// A BOOL variable the runtime keeps TRUE while the subscription is valid.
    pub valid: Option<String>,
    pub timeout_ns: u64,
}

impl PlcSubscribe {
    pub const DEFAULT_TIMEOUT_NS: u64 = 100_000_000;
    pub const MAX_VARS: usize = 16;
}

/// The largest Ethernet frame without its FCS: the size `guest.net`'s ports need.
pub const ETHERNET_FRAME_MAX: u32 = 1514;

impl GuestNet {
    /// The file the guest reads it from (`/etc/guest/net`, `guest::net::NET_PATH`):
    /// `key=value` lines.
    pub fn file(&self) -> String {
        let m = self.mac;
        let a = self.address;
        let mut text = format!(
            "mac={:02x}:{:02x}:{:02x}:{:02x}:{:02x}:{:02x}\naddress={}.{}.{}.{}/{}\n",
            m[0], m[1], m[2], m[3], m[4], m[5], a[0], a[1], a[2], a[3], self.prefix
        );
        if let Some(g) = self.gateway {
            text += &format!("gateway={}.{}.{}.{}\n", g[0], g[1], g[2], g[3]);
        }
        text += &format!("rx={}\ntx={}\n", self.rx, self.tx);
        if let Some(ring) = self.ring {
            text += &format!("ring={:#x},{}\n", ring.address, ring.size);
        }
        text
    }
}

/// COM2's ports and interrupt line, which `guest.console = "com2"` needs.
pub const COM2_PORTS: crate::model::IoRange = crate::model::IoRange {
    first: 0x2f8,
    last: 0x2ff,
};
pub const COM2_IRQ: u8 = 3;

/// The Linux programs `guest.programs` may name: static executables `cargo xtask` builds
/// (`xtask/src/linux.rs`) from `tests/linux` with `gcc -static`, and the Rust tools for
/// `x86_64-unknown-linux-musl`: `plcctl`, the PLC online tool (`partitions/guest/plcctl`),
/// `plcc`, the ST compiler, and `fbctl`, the IEC 61499 management tool
/// (`partitions/iec61499/fbctl`).
pub const GUEST_PROGRAMS: &[&str] = &[
    "linux-tests",
    "linux-bench",
    "linux-probe",
    "linux-arinc",
    "linux-netserve",
    "plcctl",
    "plcc",
    "fbctl",
    "linux-rust-std",
];

/// Paths of the initramfs `guest.files` may not replace: what the guest needs to run
/// (busybox, its applet links, the guest's command line, `/init`).
pub const GUEST_RESERVED_PATHS: &[&str] = &[
    "/bin/busybox",
    "/bin/sh",
    "/bin/echo",
    "/bin/cat",
    "/bin/ls",
    "/bin/wc",
    "/bin/true",
    "/etc/guest/init",
    "/etc/guest/env",
    "/etc/guest/console",
    "/etc/guest/net",
    "/etc/guest/disk",
    "/init",
];

/// The longest message of a guest partition's port (`guest::arinc::MAX_MESSAGE`: what its
/// port devices move in one `read` or `write`).
pub const GUEST_MAX_MESSAGE: u64 = 4096;

/// The smallest `stack` of a guest partition: the guest keeps its process table there.
pub const GUEST_MIN_STACK: u64 = 1 << 20;

/// The environment of a guest's first process without `guest.env`.
pub const GUEST_DEFAULT_ENV: &[&str] =
    &["PATH=/bin:/usr/bin:/sbin:/usr/sbin", "HOME=/", "TERM=dumb"];
/// Most strings `guest.init` and `guest.env` may have together, and most bytes (the
/// guest's room for them on the process's initial stack, with its auxiliary vector).
pub const GUEST_MAX_STRINGS: usize = 64;
pub const GUEST_MAX_BYTES: usize = 8192;

/// The contents of a (non-PLC) partition's data entry `data/<partition>`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DataEntry {
    /// ST sources compiled, in this order, into one verified bytecode image (what
    /// `plcc build` writes), e.g. the program an online-download client sends.
    PlcImage(Vec<SourceFile>),
}

/// A soft-PLC partition's program and how its ports meet its process image.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Plc {
    /// ST source files in the given order.
    pub program: Vec<SourceFile>,
    /// Input ports: their message lands in `%I`.
    pub inputs: Vec<PlcLink>,
    /// Output ports: their message is taken from `%Q`.
    pub outputs: Vec<PlcLink>,
    /// Variables the runtime logs with its statistics (checked against the program when
    /// it is compiled).
    pub watch: Vec<String>,
    /// The online ports (indices into the partition's `ports`) and what their client may do.
    pub online: Option<OnlinePorts>,
    /// Safe values of `%Q` variables by name (checked against the program when it is
    /// compiled); the others go to zero/FALSE.
    pub safe: Vec<(String, PlcValue)>,
    /// The PLC's own network interface and its communication limits (`plc.net`).
    pub net: Option<PlcNet>,
    /// The Modbus/TCP server on the process image (`plc.modbus`; needs `plc.net`).
    pub modbus: Option<PlcModbus>,
    /// The online protocol on TCP, authenticated (`plc.online_tcp`; needs `plc.net`).
    pub online_tcp: Option<PlcOnlineTcp>,
    /// PLC-to-PLC publication and subscription over UDP (`plc.publish`, `plc.subscribe`).
    pub publish: Option<PlcPublish>,
    pub subscribe: Option<PlcSubscribe>,
    /// Task deadlines by IEC TASK name (ns from the task's release; checked against the
    /// program when it is compiled); the other tasks have none.
    pub deadlines: Vec<(String, u64)>,
    /// The shared-memory segment (index into [`System::segments`]) through which its
    /// shared globals meet another PLC project's (`plc.shared`).
    pub shared: Option<usize>,
    /// Run the program on the native execution tier (`plc.native`): the build translates it
    /// and compiles it into the partition's binary.
    pub native: bool,
    /// The persistent store (`plc.store`): boot project and RETAIN snapshots on the
    /// partition's virtual disk of a block-device partition.
    pub store: Option<PlcStore>,
}

/// `plc.store`: the ports to the block-device partition (indices into the partition's
/// `ports`) and how often RETAIN is saved. The virtual disk is the partition's entry in a
/// block-device partition's `blk.tenants` (checked to exist).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PlcStore {
    /// Queuing output carrying the requests (size >= `blk_core::link::MAX_REQUEST`).
    pub request: usize,
    /// Queuing input carrying the responses (size >= `blk_core::link::MAX_RESPONSE`).
    pub response: usize,
    /// RETAIN is saved this often (ns; besides at every STOP and download).
    pub retain_every_ns: u64,
}

impl PlcStore {
    /// `retain_every` when absent.
    pub const DEFAULT_RETAIN_EVERY_NS: u64 = 1_000_000_000;
    /// The least `retain_every`: a save takes several windows of the block-device partition.
    pub const MIN_RETAIN_EVERY_NS: u64 = 100_000_000;
    /// The longest `retain_every`: an hour.
    pub const MAX_RETAIN_EVERY_NS: u64 = 3_600_000_000_000;
}

/// A value written in the description.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlcValue {
    Bool(bool),
    Int(i64),
    /// A float, as its `f64` bit pattern (so systems compare exactly).
    Float(u64),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OnlinePorts {
    pub request: usize,
    pub response: usize,
    pub access: plc_online::Access,
}

/// A PLC source file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SourceFile {
    /// As written in the description (what diagnostics and trap locations show).
    pub name: String,
    /// Resolved against the description's directory (where it is read from).
    pub path: String,
}

/// One port of a PLC partition in its process image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PlcLink {
    /// Index into the partition's `ports`.
    pub port: usize,
    /// First byte in the area (`%I` for inputs, `%Q` for outputs).
    pub at: u32,
    /// Inputs: the `%IX` bit set while the message is fresh, as (byte, bit).
    pub valid: Option<(u32, u8)>,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Port {
    pub name: String,
    pub kind: PortKind,
    pub direction: Direction,
    pub size: u32,
    /// Queuing: messages; sampling: 0.
    pub depth: u32,
    /// Sampling input: ns, 0 = none.
    pub refresh: u64,
    /// Queuing: the order waiting processes are served in; sampling: FIFO.
    pub discipline: Discipline,
    /// Index into [`System::channels`].
    pub channel: usize,
}

/// A port named by partition index and index within the partition.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PortRef {
    pub partition: usize,
    pub port: usize,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Channel {
    pub name: String,
    pub kind: PortKind,
    pub source: PortRef,
    pub destinations: Vec<PortRef>,
}

impl System {
    /// Index of `port` in the flat port table of the binary form.
    pub fn global_port(&self, port: PortRef) -> usize {
        self.partitions[..port.partition]
            .iter()
            .map(|p| p.ports.len())
            .sum::<usize>()
            + port.port
    }

    pub fn window_count(&self) -> usize {
        self.schedules.iter().map(|s| s.windows.len()).sum()
    }

    /// The owned copy of a decoded blob (for tests and tools).
    pub fn from_view(view: &SystemView<'_>) -> System {
        let port_ref = |global: usize| {
            let port = view.port(global);
            PortRef {
                partition: port.partition,
                port: global - view.partition(port.partition).port_indices().start,
            }
        };
        System {
            name: view.name().to_string(),
            memory: view.memory(),
            cpus: view.cpus(),
            schedules: view
                .schedules()
                .map(|s| Schedule {
                    name: s.name.to_string(),
                    major_frame: s.major_frame,
                    windows: s.windows().collect(),
                    change_actions: s.change_actions,
                })
                .collect(),
            partitions: view
                .partitions()
                .map(|p| Partition {
                    name: p.name.to_string(),
                    image: p.image.to_string(),
                    memory: p.memory,
                    kernel_memory: p.kernel_memory,
                    stack: p.stack,
                    kernel_threads: p.kernel_threads,
                    kernel_tasks: p.kernel_tasks,
                    abilities: p.abilities,
                    mcp: p.mcp,
                    priority: p.priority,
                    time_partition: p.time_partition,
                    cpu: p.cpu,
                    cpus: p.cpus,
                    schedule_control: p.schedule_control,
                    io_ports: p.io_ports().collect(),
                    irqs: p.irqs,
                    devices: p.devices().collect(),
                    dma: p.dma,
                    dma_unconfined: p.dma_unconfined,
                    shared: p.shared().collect(),
                    ports: p
                        .ports()
                        .map(|t| Port {
                            name: t.name.to_string(),
                            kind: t.kind,
                            direction: t.direction,
                            size: t.size,
                            depth: t.depth,
                            refresh: t.refresh,
                            discipline: t.discipline,
                            channel: t.channel,
                        })
                        .collect(),
                    health: p.health,
                    // The binary form carries none of these: they travel in the
                    // partition's data entry (the PLC package, the compiled image, the
                    // guest's initramfs, the IEC 61499 device package) instead.
                    plc: None,
                    data: None,
                    guest: None,
                    iec61499: None,
                    nic: None,
                    blk: None,
                })
                .collect(),
            segments: view
                .segments()
                .map(|g| Segment {
                    name: g.name.to_string(),
                    size: g.size,
                })
                .collect(),
            channels: view
                .channels()
                .map(|c| Channel {
                    name: c.name.to_string(),
                    kind: c.kind,
                    source: port_ref(c.source),
                    destinations: c.destinations().map(port_ref).collect(),
                })
                .collect(),
            health: view.health(),
        }
    }
}
