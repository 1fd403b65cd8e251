//! The TOML document as serde reads it: the shape only (which keys exist, which types they
//! have), every value with its source span. Units, ranges, names and cross references are
//! checked afterwards by [`crate::validate`], which can then report all problems at once.

use serde::Deserialize;
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use std::collections::BTreeMap;
use std::fmt;
use std::string::{String, ToString};
use std::vec::Vec;
use toml::Spanned;

/// A table keyed by names, with the span of each key.
pub type Named<T> = BTreeMap<Spanned<String>, Spanned<T>>;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Document {
    pub system: Spanned<SystemSection>,
    /// The single-schedule form.
    pub schedule: Option<Spanned<Schedule>>,
    #[serde(default)]
    pub schedules: Vec<Spanned<Schedule>>,
    #[serde(default)]
    pub partitions: Named<Partition>,
    #[serde(default)]
    pub shared_memory: Vec<Spanned<Segment>>,
    #[serde(default)]
    pub channels: Vec<Spanned<Channel>>,
    #[serde(default)]
    pub health: Named<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SystemSection {
    pub name: Option<Spanned<String>>,
    pub memory: Spanned<Scalar>,
    /// How many CPUs the system uses.
    pub cpus: Option<Spanned<i64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Schedule {
    pub name: Option<Spanned<String>>,
    pub major_frame: Option<Spanned<Scalar>>,
    #[serde(default)]
    pub windows: Vec<Spanned<Window>>,
    /// Partition name -> ARINC schedule change action.
    #[serde(default)]
    pub change_actions: Named<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Window {
    pub partition: Spanned<String>,
    pub offset: Spanned<Scalar>,
    pub duration: Spanned<Scalar>,
    /// The CPU whose schedule the window is in (default: its partition's).
    pub cpu: Option<Spanned<i64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Partition {
    pub image: Spanned<String>,
    pub memory: Spanned<Scalar>,
    pub kernel_memory: Spanned<Scalar>,
    pub stack: Option<Spanned<Scalar>>,
    pub kernel_threads: Option<Spanned<i64>>,
    pub kernel_tasks: Option<Spanned<i64>>,
    pub max_priority: Spanned<i64>,
    pub priority: Option<Spanned<i64>>,
    #[serde(default)]
    pub abilities: Vec<Spanned<String>>,
    pub native_syscalls: Option<Spanned<bool>>,
    pub time: Option<Spanned<Scalar>>,
    pub preempts_windows: Option<Spanned<bool>>,
    pub schedule_control: Option<Spanned<bool>>,
    /// The CPUs it runs on (one, for now).
    pub cpus: Option<Spanned<Vec<Spanned<i64>>>>,
    #[serde(default)]
    pub io_ports: Vec<Spanned<Scalar>>,
    #[serde(default)]
    pub irqs: Vec<Spanned<i64>>,
    #[serde(default)]
    pub devices: Vec<Spanned<String>>,
    pub dma: Option<Spanned<Scalar>>,
    pub dma_unconfined: Option<Spanned<bool>>,
    #[serde(default)]
    pub shared: Named<String>,
    #[serde(default)]
    pub ports: Named<Port>,
    #[serde(default)]
    pub health: Named<String>,
    pub plc: Option<Spanned<Plc>>,
    pub data: Option<Spanned<Data>>,
    pub guest: Option<Spanned<Guest>>,
    pub iec61499: Option<Spanned<Iec61499>>,
    pub nic: Option<Spanned<Nic>>,
    pub blk: Option<Spanned<Blk>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Blk {
    #[serde(default)]
    pub tenants: Named<BlkTenant>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlkTenant {
    pub from: Spanned<String>,
    pub to: Spanned<String>,
    pub first_sector: Spanned<u64>,
    pub sectors: Spanned<u64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Nic {
    #[serde(default)]
    pub tenants: Named<NicTenant>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NicTenant {
    pub mac: Spanned<String>,
    pub from: Spanned<String>,
    pub to: Spanned<String>,
    pub ring: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Iec61499 {
    pub boot: Spanned<String>,
    #[serde(default)]
    pub types: Vec<Spanned<String>>,
    pub mgmt: Option<Spanned<OnlinePorts>>,
    pub net: Option<Spanned<Iec61499Net>>,
    /// Resource name to the priority of its own process.
    #[serde(default)]
    pub resources: Named<i64>,
}

/// `iec61499.net`: the IEC 61499 partition's own interface (as `guest.net`) and the
/// management protocol on TCP.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Iec61499Net {
    pub mac: Spanned<String>,
    pub address: Spanned<String>,
    pub gateway: Option<Spanned<String>>,
    pub rx: Spanned<String>,
    pub tx: Spanned<String>,
    pub port: Option<Spanned<i64>>,
    pub connections: Option<Spanned<i64>>,
    pub access: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Guest {
    pub init: Vec<Spanned<String>>,
    pub env: Option<Vec<Spanned<String>>>,
    #[serde(default)]
    pub files: Named<String>,
    pub console: Option<Spanned<String>>,
    #[serde(default)]
    pub programs: Vec<Spanned<String>>,
    pub net: Option<Spanned<GuestNet>>,
    pub disk: Option<Spanned<GuestDisk>>,
}

/// `guest.disk`: the guest's block device `/dev/vda`, a virtual disk of a block-device
/// partition.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GuestDisk {
    pub request: Spanned<String>,
    pub response: Spanned<String>,
}

/// `guest.net`: the guest's `eth0`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GuestNet {
    pub mac: Spanned<String>,
    pub address: Spanned<String>,
    pub gateway: Option<Spanned<String>>,
    pub rx: Spanned<String>,
    pub tx: Spanned<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Data {
    pub plc_image: Vec<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plc {
    pub program: Vec<Spanned<String>>,
    #[serde(default)]
    pub inputs: Named<PlcInput>,
    #[serde(default)]
    pub outputs: Named<PlcOutput>,
    #[serde(default)]
    pub watch: Vec<Spanned<String>>,
    pub online: Option<Spanned<OnlinePorts>>,
    #[serde(default)]
    pub safe: Named<PlcValue>,
    #[serde(default)]
    pub deadline: Named<Scalar>,
    pub shared: Option<Spanned<String>>,
    pub native: Option<Spanned<bool>>,
    pub net: Option<Spanned<PlcNet>>,
    pub modbus: Option<Spanned<PlcModbus>>,
    pub online_tcp: Option<Spanned<PlcOnlineTcp>>,
    pub publish: Option<Spanned<PlcPublish>>,
    pub subscribe: Option<Spanned<PlcSubscribe>>,
    pub store: Option<Spanned<PlcStore>>,
}

/// `plc.publish`: variables sent over UDP after every release.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlcPublish {
    pub to: Spanned<String>,
    pub vars: Vec<Spanned<String>>,
}

/// `plc.subscribe`: variables received over UDP, with a validity.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlcSubscribe {
    pub port: Spanned<i64>,
    pub group: Option<Spanned<String>>,
    pub vars: Vec<Spanned<String>>,
    pub valid: Option<Spanned<String>>,
    pub timeout: Option<Spanned<Scalar>>,
}

/// `plc.online_tcp`: the online protocol on a TCP port, each client with its key.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlcOnlineTcp {
    pub port: Option<Spanned<i64>>,
    #[serde(default)]
    pub clients: Named<OnlineClient>,
}

/// One client of `plc.online_tcp`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OnlineClient {
    pub key: Spanned<String>,
    pub access: Spanned<String>,
}

/// `plc.store`: the PLC's persistent store on its virtual disk of a block-device partition.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlcStore {
    pub request: Spanned<String>,
    pub response: Spanned<String>,
    pub retain_every: Option<Spanned<Scalar>>,
}

/// `plc.net`: the PLC's own interface (as `guest.net`) and its communication limits.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlcNet {
    pub mac: Spanned<String>,
    pub address: Spanned<String>,
    pub gateway: Option<Spanned<String>>,
    pub rx: Spanned<String>,
    pub tx: Spanned<String>,
    pub connections: Option<Spanned<i64>>,
    pub buffer: Option<Spanned<i64>>,
    pub requests_per_second: Option<Spanned<i64>>,
}

/// `plc.modbus`: the Modbus/TCP server on the process image.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlcModbus {
    pub port: Option<Spanned<i64>>,
    pub unit: Option<Spanned<i64>>,
    #[serde(default)]
    pub writable: Vec<Spanned<String>>,
}

/// A value written in the description (`plc.safe`).
#[derive(Debug, Deserialize, Clone, Copy)]
#[serde(untagged)]
pub enum PlcValue {
    Bool(bool),
    Int(i64),
    Float(f64),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OnlinePorts {
    pub request: Spanned<String>,
    pub response: Spanned<String>,
    pub access: Spanned<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlcInput {
    pub at: Spanned<String>,
    pub valid: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlcOutput {
    pub at: Spanned<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Port {
    pub kind: Spanned<String>,
    pub direction: Spanned<String>,
    pub size: Spanned<Scalar>,
    pub depth: Option<Spanned<i64>>,
    pub refresh: Option<Spanned<Scalar>>,
    pub discipline: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Segment {
    pub name: Spanned<String>,
    pub size: Spanned<Scalar>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Channel {
    pub name: Option<Spanned<String>>,
    pub kind: Spanned<String>,
    pub from: Spanned<String>,
    pub to: Spanned<Targets>,
}

/// A value that may be written as an integer or as a string (sizes, durations, I/O ports,
/// `time`); what it means is decided by the validator.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Scalar {
    Int(i64),
    Str(String),
}

impl<'de> Deserialize<'de> for Scalar {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct ScalarVisitor;
        impl Visitor<'_> for ScalarVisitor {
            type Value = Scalar;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an integer or a string")
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Scalar, E> {
                Ok(Scalar::Int(v))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Scalar, E> {
                i64::try_from(v)
                    .map(Scalar::Int)
                    .map_err(|_| E::custom("integer too large"))
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<Scalar, E> {
                Ok(Scalar::Str(v.to_string()))
            }
        }
        deserializer.deserialize_any(ScalarVisitor)
    }
}

/// `to = "plc.level"` or `to = ["plc.level", "hmi.level"]`.
#[derive(Debug)]
pub enum Targets {
    One(String),
    Many(Vec<Spanned<String>>),
}

impl<'de> Deserialize<'de> for Targets {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct TargetsVisitor;
        impl<'de> Visitor<'de> for TargetsVisitor {
            type Value = Targets;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a port \"partition.port\" or a list of them")
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<Targets, E> {
                Ok(Targets::One(v.to_string()))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Targets, A::Error> {
                let mut items = Vec::new();
                while let Some(item) = seq.next_element::<Spanned<String>>()? {
                    items.push(item);
                }
                Ok(Targets::Many(items))
            }
        }
        deserializer.deserialize_any(TargetsVisitor)
    }
}
