//! The one process most partition programs run (a driver's server, a test program's loop):
//! created and started in the partition's start, just below the partition's MCP (processes
//! must stay under it), so no partition with a lower MCP that runs in the background can
//! delay it, with a soft deadline.

use crate::Warden;
use a653rs::bindings::ApexPartitionP4;
use a653rs::prelude::*;
use core::fmt;
use core::str::FromStr;
use core::time::Duration;

/// When the process is released.
#[derive(Clone, Copy, Debug)]
pub enum Release {
    /// Once, at NORMAL mode: the process loops (and waits) by itself.
    Aperiodic,
    /// Every period of the partition (its `period` in the configuration).
    PartitionPeriod,
    /// Every this long.
    Every(Duration),
}

/// Why the process does not run.
#[derive(Debug)]
pub enum StartError<'a> {
    /// The name is not an ARINC 653 name (at most 32 bytes).
    Name(&'a str),
    /// CREATE_PROCESS refused.
    Create(&'a str, Error),
    /// START refused.
    Start(&'a str, Error),
}

impl fmt::Display for StartError<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Name(name) => write!(f, "{name:?} is not a process name"),
            Self::Create(name, e) => write!(f, "cannot create the {name} process: {e:?}"),
            Self::Start(name, e) => write!(f, "cannot start the {name} process: {e:?}"),
        }
    }
}

/// Creates the process `name` running `entry` on a stack of `stack_size` bytes, at the
/// priority just below the partition's MCP, and starts it.
pub fn start(
    ctx: &mut StartContext<Warden>,
    name: &'static str,
    entry: extern "C" fn(),
    stack_size: u32,
    release: Release,
) -> Result<(), StartError<'static>> {
    start_at(ctx, name, entry, stack_size, release, priority_below_mcp())
}

/// The priority [`start`] gives its process: just below the partition's MCP.
pub fn priority_below_mcp() -> u8 {
    crate::runtime::mcp().saturating_sub(1).max(1)
}

/// [`start`] at `priority` (below the partition's MCP), for a program whose other
/// processes must be able to preempt this one.
pub fn start_at<'a>(
    ctx: &mut StartContext<Warden>,
    name: &'a str,
    entry: extern "C" fn(),
    stack_size: u32,
    release: Release,
    priority: u8,
) -> Result<(), StartError<'a>> {
    let process_name = Name::from_str(name).map_err(|_| StartError::Name(name))?;
    let period = match release {
        Release::Aperiodic => SystemTime::Infinite,
        Release::PartitionPeriod => {
            let period = <Warden as ApexPartitionP4>::get_partition_status().period;
            SystemTime::Normal(Duration::from_nanos(period.max(1) as u64))
        }
        Release::Every(period) => SystemTime::Normal(period),
    };
    let attributes = ProcessAttribute {
        period,
        time_capacity: SystemTime::Infinite,
        entry_point: entry,
        stack_size,
        base_priority: i32::from(priority),
        deadline: Deadline::Soft,
        name: process_name,
    };
    let process = ctx
        .create_process(attributes)
        .map_err(|e| StartError::Create(name, e))?;
    process.start().map_err(|e| StartError::Start(name, e))
}
