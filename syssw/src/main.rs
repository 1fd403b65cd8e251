//! syssw: the system software, the root task (ring 3).
//!
//! It distributes every resource of the machine to the partitions exactly as the static
//! configuration (the `config` entry of system.img, `config::binary`) says: for each
//! partition a resource partition (kernel-memory quota), a task (abilities, MCP), its image
//! loaded into zeroed memory with the segments' rights, a stack with the start record
//! (`user_rt::partition`), I/O-port and interrupt grants, shared-memory segments and the
//! first thread in its time partition on its CPU; then it installs the schedules (the
//! windows of every CPU), starts the partitions and serves them ([`server`]: ports, modes,
//! health monitor, restarts). Two threads: the server thread answers every request and
//! fault report at once, the restart worker ([`restart`]) rebuilds restarted partitions in
//! their own windows. It must never
//! allocate after start-up and never trusts a partition: everything it gets from one is
//! checked.
//!
//! Log lines (an interface): `syssw: partition NAME: TP<n>|background, MCP m, priority p,
//! memory used/total KiB, kernel memory k KiB, ports ..., irqs ...` per partition (in a
//! system of several CPUs `TP<n> on CPU c, MCP ...`), then
//! `syssw: N partitions started, schedule NAME (major frame F us, W windows)`; fatal
//! configuration problems as `syssw: configuration rejected: REASON` followed by a failure
//! halt.
#![no_std]
#![no_main]

mod devices;
mod partitions;
mod restart;
mod server;

use root_task::spawn::{AddressRange, FramePool, Spawner};
use user_rt::abi::syscall::ThreadAttribute;
use user_rt::abi::sysimg::SystemImage;
use user_rt::println;
use user_rt::sys;

user_rt::entry!(main);

/// syssw's own addresses for scratch mappings.
const SPAWN_BASE: u64 = 0x0000_1000_0000_0000;
const SPAWN_END: u64 = 0x0000_2000_0000_0000;

fn reject(what: core::fmt::Arguments) -> ! {
    println!("syssw: configuration rejected: {what}");
    let _ = sys::system_halt(false);
    sys::thread_exit()
}

fn main(image_base: u64, image_len: u64) {
    let bytes = root_task::system_image(image_base, image_len);
    let image = SystemImage::parse(bytes)
        .unwrap_or_else(|e| reject(format_args!("system image damaged: {e}")));
    println!(
        "syssw: root task started; system image {} bytes, {} entries",
        image.size(),
        image.len()
    );
    let Some(config) = image.find("config") else {
        println!("syssw: no configuration in the system image; nothing to start");
        return;
    };
    let system = config::decode(config.data)
        .unwrap_or_else(|e| reject(format_args!("binary configuration damaged: {e}")));
    let mut spawner = Spawner::new(
        FramePool::from_root_info(),
        AddressRange::new(SPAWN_BASE, SPAWN_END),
    )
    .unwrap_or_else(|e| reject(format_args!("no address space for syssw: {e:?}")));
    let ipc = spawner
        .own_ipc_buffer()
        .unwrap_or_else(|e| reject(format_args!("no IPC buffer for syssw: {e:?}")));
    let (me, _) = sys::thread_self();

    // Every port buffer, sized once from the configuration: nothing is allocated later.
    let arena = spawner
        .own_memory(syssw_core::ports::arena_size(&system))
        .unwrap_or_else(|e| reject(format_args!("no memory for port buffers: {e:?}")));
    let ports = syssw_core::ports::Ports::new(&system, arena)
        .unwrap_or_else(|e| reject(format_args!("ports: {e}")));
    // And the staging buffers of messages longer than one IPC message.
    let arena = spawner
        .own_memory(syssw_core::staging::arena_size(&system))
        .unwrap_or_else(|e| reject(format_args!("no memory for staging buffers: {e:?}")));
    let staging = syssw_core::staging::Staging::new(&system, arena)
        .unwrap_or_else(|e| reject(format_args!("staging: {e}")));
    let scratch = spawner
        .own_memory(
            (0..config::model::MAX_PARTITIONS)
                .map(|p| staging.size(p))
                .max()
                .unwrap_or(0),
        )
        .unwrap_or_else(|e| reject(format_args!("no memory for staging buffers: {e:?}")));
    let mut loader = partitions::Loader::new(spawner, system, me)
        .unwrap_or_else(|e| reject(format_args!("shared memory: {e}")));
    let mut placed = [const { None }; config::model::MAX_PARTITIONS];
    let mut stopped = 0;
    for p in system.partitions() {
        let entry = image.entries().find(|e| p.is_image_entry(e.name));
        let data = image.entries().find(|e| p.is_data_entry(e.name));
        let placement = entry
            .ok_or(partitions::LoadError::NoImage)
            .and_then(|e| loader.place(&p, e.data, data.map_or(&[][..], |d| d.data)));
        let placement = match placement {
            Ok(placement) => placement,
            Err(partitions::LoadError::Devices(problem)) => {
                placed[p.index] = Some(not_started(p.name, &problem));
                stopped += 1;
                continue;
            }
            Err(e) => reject(format_args!("partition {}: {e}", p.name)),
        };
        if let Some(devices) = &placement.devices {
            devices::log(p.name, devices);
        }
        let used = placement.used;
        let stack_guard = placement.stack_guard.clone();
        let mode = syssw_core::mode::PartitionMode::boot();
        let instance = loader.instantiate(
            p.index,
            partitions::Start::Boot,
            mode.start_condition() as u64,
        );
        let instance = match instance {
            Ok(instance) => instance,
            // A device's grant the kernel refused (a BAR over its ports or memory, a quota
            // too small for the BARs' page tables): again only this partition stays stopped.
            Err(partitions::LoadError::Devices(problem)) => {
                placed[p.index] = Some(not_started(p.name, &problem));
                stopped += 1;
                continue;
            }
            Err(e) => reject(format_args!("partition {}: {e}", p.name)),
        };
        placed[p.index] = Some(server::Partition {
            stack_guard,
            instance: Some(instance),
            mode,
        });
        log_partition(&p, used, system.cpus());
    }
    // From here on the worker owns the loader (frame allocator, placements).
    let worker = restart::create_worker(loader, me)
        .unwrap_or_else(|e| reject(format_args!("no restart worker: {e:?}")));
    let server = server::Server {
        system,
        partitions: placed,
        ports,
        staging,
        scratch,
        created: [false; config::model::MAX_PORTS],
        health: syssw_core::health::HealthMonitor::new(),
        ipc,
        worker: worker.id,
        restarts: syssw_core::restart::Restarts::new(),
        worker_place: None,
        schedule: syssw_core::schedule::ModuleSchedule::new(system.schedule_count()),
        dma: system.partitions().any(|p| p.dma > 0),
        since_dma_poll: 0,
        deferred: syssw_core::deferred::Deferred::new(),
        windows: [(0, 0); config::model::MAX_PARTITIONS],
    };
    for s in system.schedules() {
        let mut windows = [user_rt::abi::syscall::WindowSpec::default(); 32];
        let n = s.window_count();
        for (w, window) in windows.iter_mut().zip(s.windows()) {
            *w = window.spec();
        }
        sys::schedule_set(s.index as u64, s.major_frame, &windows[..n])
            .unwrap_or_else(|e| reject(format_args!("schedule {}: {e:?}", s.name)));
    }
    if system.schedule_count() > 0 {
        sys::schedule_switch(0).unwrap_or_else(|e| reject(format_args!("schedule_switch: {e:?}")));
    }
    // The server thread stays in TP0 above every other thread: it only runs to serve
    // requests and faults. It follows its callers from CPU to CPU, so that serving a
    // partition takes that partition's CPU's time, never another CPU's.
    sys::set_health_monitor(me).unwrap_or_else(|e| reject(format_args!("health monitor: {e:?}")));
    let _ = sys::thread_set(None, ThreadAttribute::TimePartition, 0);
    sys::thread_set(
        None,
        ThreadAttribute::Priority,
        restart::SERVER_PRIORITY as u64,
    )
    .unwrap_or_else(|e| reject(format_args!("server priority: {e:?}")));
    sys::thread_set(None, ThreadAttribute::FollowsCallers, 1)
        .unwrap_or_else(|e| reject(format_args!("server follows its callers: {e:?}")));
    // The worker first asks for a job: it runs when this thread first waits for requests.
    sys::thread_start(worker.id)
        .unwrap_or_else(|e| reject(format_args!("thread_start of the restart worker: {e:?}")));
    for p in server.partitions.iter().flatten() {
        if let Some(instance) = &p.instance {
            sys::thread_start(instance.thread)
                .unwrap_or_else(|e| reject(format_args!("thread_start: {e:?}")));
        }
    }
    let first = (system.schedule_count() > 0).then(|| system.schedule(0));
    println!(
        "syssw: {} partitions started, schedule {} (major frame {} us, {} windows)",
        system.partition_count() - stopped,
        first.map_or("none", |s| s.name),
        first.map_or(0, |s| s.major_frame / 1000),
        first.map_or(0, |s| s.window_count())
    );
    server.run()
}

/// A partition whose PCI devices cannot be granted: logged and left IDLE (never started);
/// the others start.
fn not_started(name: &str, problem: &devices::DeviceProblem) -> server::Partition {
    println!("syssw: partition {name} not started: {problem}");
    server::Partition {
        stack_guard: 0..0,
        instance: None,
        mode: syssw_core::mode::PartitionMode::never_started(),
    }
}

/// The partition's start line; `cpus`: the CPUs of the system (with more than one, the
/// line names the partition's).
fn log_partition(p: &config::binary::PartitionView, used: u64, cpus: u8) {
    let mut irqs = [0u8; 24];
    let mut n = 0;
    for line in p.irqs.lines() {
        irqs[n] = line;
        n += 1;
    }
    println!(
        "syssw: partition {}: {}{}, MCP {}, priority {}, memory {}/{} KiB, kernel memory {} KiB, {} I/O range(s), irqs {:?}",
        p.name,
        TimePartition(p.time_partition),
        OnCpu((cpus > 1).then_some(p.cpus)),
        p.mcp,
        p.priority,
        used / 1024,
        p.memory / 1024,
        p.kernel_memory / 1024,
        p.io_ports().count(),
        &irqs[..n]
    );
}

/// ` on CPU 1`, ` on CPUs 1,2` for a CPU mask (nothing on a one-CPU system).
struct OnCpu(Option<u8>);

impl core::fmt::Display for OnCpu {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let Some(mask) = self.0 else {
            return Ok(());
        };
        let plural = if mask.is_power_of_two() { "" } else { "s" };
        write!(f, " on CPU{plural} ")?;
        let mut cpus = (0..8).filter(|c| mask & 1 << c != 0);
        if let Some(first) = cpus.next() {
            write!(f, "{first}")?;
        }
        cpus.try_for_each(|c| write!(f, ",{c}"))
    }
}

/// `background` for TP0, else `TP<n>`.
struct TimePartition(u8);

impl core::fmt::Display for TimePartition {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self.0 {
            0 => write!(f, "background"),
            tp => write!(f, "TP{tp}"),
        }
    }
}
