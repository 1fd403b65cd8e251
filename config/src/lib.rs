//! System descriptions of Warden: the TOML format, its validation, and the binary form syssw
//! reads at boot.
//!
//! Two halves:
//! - always (`no_std`, no allocation): the binary configuration decoder [`binary::decode`]
//!   with its zero-copy views, and the shared vocabulary in [`model`] and [`units`]. This is
//!   what syssw links (`default-features = false`).
//! - feature `host` (default): [`load`] parses and validates a TOML description into a
//!   [`System`], reporting every problem as a [`Diagnostic`] (`file:line:col: key.path:
//!   reason`); [`binary::encode`] turns a `System` into the blob; [`generate`] makes random
//!   valid descriptions from a seed (the boot property's tests).
//!
//! This crate must never let an inconsistent configuration through: whatever [`load`]
//! accepts encodes to a blob [`binary::decode`] accepts, and the decoder re-checks every rule
//! that matters for isolation (indices, limits, reserved resources, budgets) so that a
//! damaged blob is rejected rather than acted on. The decoder must never panic on any input,
//! allocate, or trust a count or index it has not checked.
//!
//! # The TOML format
//!
//! Sizes are bytes: an integer or `"64KiB"`, `"8MiB"`, `"1GiB"` (binary units only; memory
//! sizes must be whole 4 KiB pages). Durations always carry a unit: `"500ns"`, `"250us"`,
//! `"2ms"`, `"1s"`. Names are ASCII letters, digits, `_`, `-`, starting with a letter, at most
//! 31 bytes (partition names at most 15: they name the partition's task). Unknown keys are
//! errors everywhere.
//!
//! ```toml
//! [system]
//! name = "demo"                   # optional, default "system"
//! memory = "512MiB"               # RAM budget (see "Budgets")
//! cpus = 2                        # optional, default 1 (at most 8), see "CPUs"
//!
//! [[schedules]]                   # up to 4; the first is the initial schedule
//! name = "normal"                 # optional for the first (default "default")
//! major_frame = "10ms"            # optional: default = end of the last window
//! change_actions = { io = "cold_start" }  # optional: per partition, see "Time"
//! [[schedules.windows]]           # up to 32 per schedule; in the frame, disjoint per CPU
//! partition = "plc"               # a partition that is not background
//! offset = "0ms"
//! duration = "2ms"                # windows and major frames last at least 10us
//! cpu = 0                         # one of its partition's CPUs; optional with one
//! # A single schedule may also be written as [schedule] + [[schedule.windows]].
//!
//! [[shared_memory]]               # up to 32 segments
//! name = "frame"
//! size = "64KiB"                  # whole pages
//!
//! [partitions.plc]                # up to 15 partitions, kept in file order
//! image = "softplc"               # user program; system.img entry "partition/softplc"
//! memory = "8MiB"                 # whole pages, includes the stack
//! kernel_memory = "256KiB"        # resource-partition page quota, whole pages
//! stack = "64KiB"                 # optional, default 64KiB
//! kernel_threads = 16             # optional quota, default 16
//! kernel_tasks = 1                # optional quota, default 1
//! max_priority = 150              # MCP, 1..=199 (syssw runs at 200)
//! priority = 100                  # optional, first thread's priority, default = max_priority
//! abilities = ["debug_log"]       # optional, see "Abilities"
//! native_syscalls = true          # optional, default true; a paravirtualized guest says false
//! time = 1                        # optional: "background" (TP0) or a time partition 1..=15
//! cpus = [0]                      # optional, default [0]: its CPUs, see "CPUs"
//! preempts_windows = false         # optional, background only: see "Time"
//! schedule_control = false        # optional: may switch the module schedule, see "Time"
//! io_ports = ["0x2f8-0x2ff", "0x60", 0x61]   # inclusive ranges, hex or decimal
//! irqs = [3]                      # ISA lines 0..=23 except 0, 2, 4; needs ability "irq"
//! devices = ["00:03.0"]          # PCI functions it owns (bus:device.function); needs "irq"
//! dma = "512KiB"                  # optional: the memory its devices may DMA to, see "PCI devices"
//! dma_unconfined = false          # optional: may DMA without an IOMMU (a warning)
//! shared = { frame = "rw" }       # segment = "r" | "rw" | "rx"; partitions sharing one may notify each other's threads
//! ports.level = { kind = "sampling", direction = "in", size = 8, refresh = "20ms" }
//! ports.cmd = { kind = "queuing", direction = "out", size = 64, depth = 8, discipline = "priority" }
//! health.deadline_missed = "warm_restart"
//! plc.program = ["../plc/tank.st"]   # soft-PLC partitions only: see "PLC"
//! plc.inputs.level = { at = "%IB0", valid = "%IX8.0" }
//! plc.outputs.valve = { at = "%QB0" }
//! plc.watch = ["level", "tank.pid.integral"]
//! plc.online = { request = "cmd", response = "reply", access = "monitor" }
//! plc.safe = { valve = 0.0, "tank.heater" = false }
//! plc.deadline = { control = "5ms" }  # per IEC TASK; default: none
//! plc.shared = "frame"            # the segment its shared globals go through
//! plc.native = true               # optional, default false: the native execution tier
//! plc.net = { mac = "52:54:00:12:34:57", address = "10.0.2.16/24", gateway = "10.0.2.2", rx = "eth-rx", tx = "eth-tx", connections = 8, buffer = 2048, requests_per_second = 200 }
//! plc.modbus = { port = 502, unit = 1, writable = ["markers"] }  # needs plc.net
//! plc.online_tcp = { port = 1202, clients.eng = { key = "keys/eng.key", access = "download" } }  # needs plc.net
//! plc.publish = { to = "10.0.0.2:61499", vars = ["level", "level_ok"] }  # needs plc.net
//! plc.subscribe = { port = 61499, group = "239.0.0.1", vars = ["valve"], valid = "valve_ok", timeout = "100ms" }  # needs plc.net
//! plc.store = { request = "disk-req", response = "disk-resp", retain_every = "1s" }  # needs a virtual disk
//! data.plc_image = ["../plc/tank.st"]  # other partitions only: see "Data entries"
//! iec61499.boot = "app.fboot"      # IEC 61499 partitions only: see "IEC 61499"
//! iec61499.types = ["PID.fbt"]     # optional
//! iec61499.mgmt = { request = "fb-req", response = "fb-resp", access = "download" }  # optional
//! iec61499.net = { mac = "52:54:00:12:34:58", address = "10.0.2.17/24", gateway = "10.0.2.2", rx = "eth-rx", tx = "eth-tx", port = 61499, connections = 4, access = "monitor" }  # optional
//! iec61499.resources = { CYCLE = 90 }  # optional: resources with a process of their own
//! guest.init = ["/bin/busybox", "echo", "hello"]   # guest partitions only: see "Guest"
//! guest.env = ["PATH=/bin", "HOME=/"]              # optional
//! guest.files = { "/etc/motd" = "motd.txt" }      # optional: host files to add
//! guest.console = "com2"                           # optional: a terminal on COM2
//! guest.programs = ["linux-tests"]                # optional: Linux programs cargo xtask builds
//! guest.net = { mac = "52:54:00:12:34:56", address = "10.0.2.15/24", gateway = "10.0.2.2", rx = "eth0-rx", tx = "eth0-tx" }  # optional: eth0
//! guest.disk = { request = "vda-req", response = "vda-resp" }  # optional: /dev/vda, needs a virtual disk
//! nic.tenants.linux = { mac = "52:54:00:12:34:56", from = "linux-tx", to = "linux-rx", ring = "frames" }  # NIC partitions only: see "NIC"; `ring` optional
//! blk.tenants.plc = { from = "plc-req", to = "plc-resp", first_sector = 2048, sectors = 2048 }  # block-device partitions only: see "Block device"
//!
//! [[channels]]
//! name = "level"                  # optional, default = the `from` text
//! kind = "sampling"               # 1 source, >= 1 destinations
//! from = "plant.level"            # an output port ("partition.port")
//! to = ["plc.level"]              # input ports (a single string is fine too)
//!
//! [health]                        # module table: the default for every partition
//! memory_violation = "idle"
//! ```
//!
//! **Time.** A partition without `time` gets the lowest free time partition if some window
//! names it, and is an error otherwise ("has no window and is not background"). `time = N`
//! fixes the number; partitions may share a number (their windows then serve all of them),
//! and a fixed number must have a window in some schedule. `time = "background"` puts it in
//! TP0, which runs whenever no window's partition is ready; it cannot have windows.
//! Inside a window, the background's threads compete by priority with the window's
//! partition, so a background partition's `max_priority` must be below the `priority` of
//! every windowed partition (the floor the windowed partition's own threads keep to; a thread
//! it runs below its floor may lose its window to the background). A background partition
//! that is meant to preempt windows says `preempts_windows = true`; the tools then print a
//! warning instead of refusing the file. A partition with `schedule_control = true` may
//! switch the module to another of the `[[schedules]]` (ARINC SET_MODULE_SCHEDULE; the
//! switch takes effect at the end of the running major frame); every partition may ask
//! which schedule runs. A schedule's `change_actions` (ARINC 653 Part 2 schedule change
//! actions) maps partition names to what happens to each when a switch to that schedule
//! takes effect: `ignore` (the default for every partition not named), `idle` (ARINC STOP:
//! the partition is stopped for good, as by SET_PARTITION_MODE(IDLE)), `cold_start` or
//! `warm_start` (it restarts in that mode with start condition PARTITION_RESTART; a warm
//! start of a partition still in COLD_START is a cold one). They are not applied at boot,
//! to an IDLE partition, or to a partition being restarted at the time.
//!
//! **CPUs.** `[system] cpus` says how many CPUs the system uses (1..=8, default 1), CPUs
//! 0 (the boot CPU) to `cpus` − 1; `cargo xtask` boots it with at least that many. Every
//! CPU has its own schedule of windows within each major frame (the frames of all CPUs
//! start together; a schedule switch takes effect on every CPU at once). A partition is
//! bound to CPUs `cpus = [n, ...]` (default `[0]`; each below the system's `cpus`, none
//! twice): its threads run only there, each in the windows of its time partition on its
//! own CPU, or, for a background partition, in the time that CPU's windows leave. The
//! kernel holds the set (the partition's resource partition's CPU mask): the partition
//! moves its threads among its CPUs itself (`thread_set` `cpu`), never beyond. A window
//! is in the schedule of one CPU: `cpu = n`, which must be one of its partition's CPUs,
//! and may be left out when the partition has one CPU. A windowed partition on several
//! CPUs needs a window of its time partition on each (its threads there would never run
//! otherwise); its windows on different CPUs may overlap (it then runs on both at once).
//! Windows of one CPU must not overlap; windows of different CPUs may, and usually do
//! (the point of running partitions side by side). A fixed `time = N` needs a window on
//! each of the partition's CPUs, and a background partition must stay below the floor of
//! the windowed partitions of its own CPUs only. syssw starts every partition's first
//! thread on the first of its CPUs (the threads it creates start there too); a machine
//! with fewer CPUs online than a partition's stops the boot with `syssw: configuration
//! rejected: partition NAME: CPU n is not online ...`.
//!
//! **Abilities.** Every partition has `native_syscalls` unless `native_syscalls = false`;
//! `abilities` adds any of `create_task`, `create_thread`, `map`, `irq`, `io_ports`,
//! `debug_log`. `system_halt`, `physical_memory`, `scheduling` and `partition_control` are
//! syssw's alone and rejected. A partition with `irqs` needs `irq` (to attach them). Turning
//! `native_syscalls` off makes every `syscall` of the partition an exception message to its
//! handler; a guest kernel keeps it and creates its processes' tasks without it.
//!
//! **Ports and channels.** Ports have `kind` (`sampling` | `queuing`), `direction` (`in` |
//! `out`), `size` (largest message, 1..=65536 bytes; beyond 4096, one IPC message, it
//! travels in parts, see the service protocol's "long messages"), `depth` (queuing only,
//! 1..=256) and
//! `refresh` (sampling inputs only: how long a message stays valid), and queuing ports
//! `discipline` (`fifo`, the default, | `priority`: the order in which processes waiting on
//! the port are served, ARINC's QUEUING_DISCIPLINE; an APEX partition must create the port
//! with the same one; a guest partition's ports stay FIFO, since its calls never wait).
//! A sampling channel goes
//! from one output port to one or more input ports; a queuing channel connects exactly one
//! output to one input. Both ends must have the channel's kind, and each destination's size
//! must be at least the source's (the receiver can hold every message). Every port belongs to
//! exactly one channel.
//!
//! **Health monitoring.** Errors: `deadline_missed`, `application_error`, `numeric_error`,
//! `illegal_request`, `stack_overflow`, `memory_violation`, `hardware_fault`, `power_fail`.
//! Actions: `ignore`, `idle` (stop the partition), `cold_restart`, `warm_restart`,
//! `shutdown` (stop the module with the failure outcome), `shutdown_success` (stop it with
//! the success outcome: the expected end of a test scenario). A partition's table overrides
//! the module's `[health]`; see [`model::HealthTable::resolve`] for the defaults.
//!
//! **PLC.** A partition running the soft-PLC (`image = "softplc"`) names its Structured
//! Text sources in `plc.program` (paths relative to the description's directory, compiled
//! in that order into one program; a missing file is an error here, a compile error stops
//! `cargo xtask` exactly as `plcc check` prints it). Every port of the partition is mapped
//! into its process image: `plc.inputs.<port> = { at = "%IB<n>", valid = "%IX<b>.<i>" }`
//! puts the port's message at input byte `n` (`%IW`/`%ID`/`%IL` addresses count in their
//! own units, as in CODESYS: `%ID1` is byte 4) and, for a sampling input, sets bit `valid`
//! before each cycle while the message is fresh (required for sampling inputs, so a stale
//! value is never taken for a fresh one; queuing inputs may have one too);
//! `plc.outputs.<port> = { at = "%QB<n>" }` sends the port's size of bytes of `%Q` from
//! byte `n` after each cycle. Mapped ranges of one area must not overlap, a validity bit
//! must not lie inside a mapped message, and everything must fit in the 4096-byte areas.
//! `plc.online` names a queuing input and a queuing output (both `size = 256`) that carry
//! the PLC online protocol (crate `plc-online`: list, read, write, force, unforce, task
//! statistics, stop/start a task, online download) instead of process-image bytes, and
//! what their client may do: `"monitor"` (list, read, statistics), `"force"` (also write,
//! force, unforce, stop and start a task) or `"download"` (also replace the program by
//! online download); a request beyond it is answered FORBIDDEN. `plc.safe` gives located `%Q` variables (by name) the value
//! they take when a task faults and the outputs go safe (a number or a boolean fitting the
//! variable's type; checked when the program is compiled); without one they take the value
//! the program's `{attribute 'safe' := 'VALUE'}` pragma gives them, else zero/FALSE. `plc.deadline` gives IEC tasks a time deadline (CODESYS's task watchdog
//! time), counted from the task's release (its window start), between 100 us and one hour;
//! a task still running then is stopped with the trap DEADLINE (outputs safe, reported as
//! DEADLINE_MISSED, like the instruction-budget WATCHDOG that watches every task). Keys are
//! TASK names (all programs the TASK runs) or `TASK.instance`, case-insensitive, checked
//! against the compiled program. `plc.watch` names variables (globals by name, program variables as `instance.var`) the
//! runtime logs once a second; names are checked against the compiled program. Cyclic tasks
//! must have an INTERVAL that is a multiple of the major frame of every schedule that gives
//! the partition windows (checked when the program is compiled). `plc.shared` names the
//! shared-memory segment through which the program's shared globals (`{attribute 'shared'
//! := 'write' | 'read'}` in VAR_GLOBAL) meet those of one other PLC partition: the
//! partition must map it `"rw"`, and at most two PLC partitions name one segment. When the
//! programs are compiled the segment is laid out (each writer's area; format and protocol
//! in the runtime's `softplc::shared`) and paired: a variable written by both, a read
//! variable the other does not write or writes with another type, or areas beyond the
//! segment are build errors naming the declarations as `file:line:col`. `plc.native = true`
//! runs the program on the native execution tier instead of the interpreter: when the
//! system is built, the verified bytecode is translated to Rust (crate `plc-native`) and
//! compiled into the PLC partition's binary, which runs it natively when its package holds
//! exactly that image (a translation error stops the build); the semantics, traps, watchdogs
//! and monitoring are the interpreter's. A program downloaded online runs on the
//! interpreter until the next build. `plc.net` gives the PLC its own network interface, a
//! tenant of the NIC partition (`nic.tenants.<plc>` with the same MAC): `mac`, `address`,
//! `gateway`, `rx` and `tx` as `guest.net` has them (two queuing ports of at least 1514
//! bytes, joined to the NIC's by channels), and the limits of its communication process:
//! `connections` TCP connections at once (1..=32, default 8; one more is closed at once),
//! `buffer` bytes of each connection's receive and send buffer (512..=65536, default
//! 2048), `requests_per_second` requests taken from each connection (1..=100000, default
//! 200; more wait in the connection's buffer). `plc.modbus` (needs `plc.net`) serves
//! Modbus/TCP on the process image: `port` (default 502), `unit` (the unit id it answers
//! besides 0xFF; default 1), and `writable`, the areas a client may write: `"outputs"`
//! (coils and holding registers of `%QX`/`%QW`) and `"markers"` (`%MX`/`%MW`); default
//! none. The map and what the PLC does with requests: docs/plc.md. `plc.online_tcp`
//! (needs `plc.net`) serves the online protocol on TCP (`port`, default 1202, not the
//! Modbus port) to the clients of `clients.<name>` (1..=8; a name is 1..=32 printable ASCII
//! characters without spaces), each authenticating with the pre-shared key in its `key`
//! file (relative to this description's directory; the key as hex text, 32..=128 digits,
//! read when the system is built) and allowed what its `access` says (`"monitor"`,
//! `"force"` or `"download"`, as `plc.online.access`). `plc.publish` (needs `plc.net`)
//! sends the values of `vars` (1..=16 variables of the program, no name twice, of types the
//! FBDK encoding carries) after every release in which a task runs, as one UDP datagram
//! to `to` (`"<IPv4>:<port>"`, unicast or a multicast group); `plc.subscribe` (needs
//! `plc.net`) takes datagrams on UDP `port` (not a TCP service's port here), also those
//! to the multicast `group` it joins if one is given, into `vars` between releases, valid while the
//! last good one is younger than `timeout` (1 ms to 3600 s, default 100 ms), with `valid`
//! an optional BOOL variable the runtime keeps TRUE while it is; on a lapse the variables
//! go to zero. The encoding and the runtime's part: docs/plc.md. `plc.store` keeps the
//! boot project (the last committed online download) and RETAIN snapshots on the
//! partition's virtual disk, which a block-device partition gives it
//! (`blk.tenants.<plc>`, required): `request` is its queuing output of at least 2072
//! bytes to the tenant's `from` port, `response` its queuing input of at least 2064 bytes
//! from the tenant's `to` port (joined by channels), `retain_every` how often RETAIN is
//! saved besides at every STOP and download (100 ms to 1 h, default 1 s). The disk
//! layout and what start loads: docs/plc.md.
//!
//! **Data entries.** `cargo xtask` can give a partition a read-only data entry
//! (`data/<partition>` in `system.img`, which syssw maps at `DATA_BASE`; see
//! `user/rt/src/partition.rs`): a PLC partition's is its package (from `plc.*`), and any
//! other partition may name ST sources in `data.plc_image` (paths as for `plc.program`,
//! compiled in that order into one program, a compile error stops the build), whose
//! verified bytecode image — what `plcc build` writes as `.plcb` — becomes its data
//! entry: for example the program an online-download client sends to a PLC. A partition
//! cannot have both, and `data` has no other keys.
//!
//! **IEC 61499.** A partition running the IEC 61499 runtime (`image = "iec61499"`,
//! `partitions/iec61499/partition`) names its boot file, `iec61499.boot` (a 4diac `.fboot`
//! file: one management request a line, carried out at every start), and the basic,
//! simple and composite FB types (`.fbt`) it uses beyond the standard library, with the
//! adapter types (`.adp`) their plugs and sockets are of, `iec61499.types` (paths as for
//! `plc.program`). `cargo xtask` compiles each FB type
//! (algorithms and guards by the ST compiler; an error names the `.fbt` file, line and
//! column; a composite's network is checked when the boot file creates an instance, a
//! refusal naming its place in the `.fbt`) and writes the types and the
//! boot file as the partition's data entry (`iec61499_mgmt::package`); such a partition
//! has no `plc`, `guest` or `data` keys. `iec61499.mgmt` names a queuing input and a
//! queuing output of the partition (both `size = 4096`) that carry 4diac's management
//! requests, one a message (`iec61499_mgmt::serve`), and what their client may do:
//! `"monitor"` (READ, QUERY, watches), `"force"` (also WRITE: parameters, forcing, event
//! triggers) or `"download"` (also resources, FBs, connections, START/STOP/KILL/RESET and
//! FB types); a request beyond it is answered ACCESS_DENIED. `iec61499.net` gives the
//! partition its own network interface, a tenant of the NIC partition (`nic.tenants.<fb>`
//! with the same MAC; `mac`, `address`, `gateway`, `rx` and `tx` as `guest.net` has them),
//! on which it serves the same management requests on TCP `port` (default 61499) to
//! `connections` clients at once (1..=8, default 4; one more is closed at once), each
//! allowed what `access` says (as `iec61499.mgmt.access`; default `"monitor"`); the
//! protocol on TCP and why one access for every client: docs/iec61499.md. The partition's
//! other queuing ports are its PUBLISH_n/SUBSCRIBE_n's: one whose `ID` names an output
//! port sends on it, one whose `ID` names an input port receives from it
//! (`iec61499_mgmt::pubsub`); with `iec61499.net`, an `ID` that is a UDP address
//! (`a.b.c.d:port`, `fbdk[].ip[a.b.c.d:port]`) publishes or subscribes over UDP on the
//! partition's interface instead (`iec61499_mgmt::udp`). `iec61499.resources` gives up to
//! 4 resources (by name, IEC identifiers of at most 24 bytes, whether the boot file or a
//! management client creates them) an APEX process of their own at the given priority
//! (2 to `max_priority` − 1): it fires their timers and runs the chains those start, and
//! preempts the device process, which serves the network and the management requests and
//! runs the other resources just below the lowest of those priorities (how they share
//! the device: the module doc of `partitions/iec61499/partition/src/main.rs`).
//!
//! **Guest.** A partition running the paravirtualized guest (`image = "guest"`,
//! `partitions/guest`) says what its first Linux process runs: `guest.init` is its `argv`,
//! whose first string is the absolute path of a static executable in the initramfs (such
//! as `/bin/busybox`); `guest.env` its environment (`NAME=value` strings; default
//! `PATH=/bin:/usr/bin:/sbin:/usr/sbin`, `HOME=/`, `TERM=dumb`); together at most 64
//! strings and 8192 bytes, no NUL bytes. `guest.files` adds files to the initramfs: each key is the absolute path in the
//! initramfs (missing directories are created), each value a file on the host, relative to
//! the description's directory (its permission bits are kept, owner root; a `.st` file at a
//! path ending in `.plcb` is compiled into its PLC bytecode image, for `plcctl download`); they may replace
//! `/etc/passwd` and `/etc/group`, not what the guest needs to run (`/bin/busybox`, the
//! applet links, `/etc/guest/init`, `/etc/guest/env`, `/init`). `guest.programs` names
//! static Linux programs `cargo xtask` builds from `tests/linux` with `gcc -static`
//! ([`system::GUEST_PROGRAMS`]: `linux-tests`, the system-call checks, `linux-bench`, the
//! guest benchmark, `linux-probe`, the faults and forbidden accesses of the memory and
//! isolation scenarios, `linux-arinc`, the checks of the ARINC port devices and the
//! hostile guest's port flood, and `linux-netserve`, the guest side of the network
//! benchmark), or the Rust programs `plcctl` (the PLC online tool), `plcc` (the
//! Structured Text compiler), `fbctl` (the IEC 61499 management tool) and `linux-rust-std`
//! (the Rust std checks of scenario `guest_rust_std`), built for
//! `x86_64-unknown-linux-musl`, and adds as `/bin/<name>` (not also a `guest.files` path,
//! each once). The partition's `ports.*` reach the guest as the devices
//! `/dev/arinc/<name>` (the initramfs's `/etc/guest/ports`, see `guest::arinc`). `cargo xtask` builds the
//! partition's initramfs (a cpio "newc" archive: Debian's `busybox-static` as
//! `/bin/busybox` with the applet links `sh`, `echo`, `cat`, `ls`, `wc`, `true`,
//! `/etc/passwd`, `/etc/group`, an `/init` script, these keys in `/etc/guest/init` and
//! `/etc/guest/env`, and the files) as its data entry. The guest runs its processes as
//! child tasks backed by its memory pool (the part of `memory` its image, initramfs and
//! stack leave free, see `protocol::layout::POOL_BASE`), so it needs the abilities
//! `create_task`, `create_thread` and `map`, and its `kernel_tasks`, `kernel_threads` and
//! `kernel_memory` pay for its processes' tasks, threads and page tables (one task and one
//! thread a process, at most 16 processes: `kernel_tasks = 17` with its own; fewer tasks
//! limit its processes, `fork` then fails with EAGAIN); its process table lives on its
//! stack, so it needs a `stack` of at least 1 MiB (a smaller one is an error). A partition
//! has either `plc` or `guest` keys, not both. `guest.console = "com2"` makes the
//! processes' console a terminal on COM2 (`/etc/guest/console` in the initramfs; the line
//! discipline is `partitions/guest/src/tty.rs`): the partition then needs
//! `io_ports = ["0x2f8-0x2ff"]`, `irqs = [3]`, the ability `irq` and one more kernel
//! thread (the console's reader); `cargo xtask run` connects COM2 to the terminal and
//! scenarios feed it from `console_input`. Without it, the processes' output lines go to
//! the log and reading the console gives end of file. A guest always has the loopback
//! `lo` (127.0.0.1/8); `guest.net` gives it `eth0` too: `mac` (unicast, six hex octets),
//! `address` (IPv4 with a prefix length of 1 to 30), `gateway` (optional: the default
//! route, an address of that subnet other than the guest's), and two of the partition's
//! queuing ports of at least 1514 bytes, `rx` (`in`: the frames it receives) and `tx`
//! (`out`: the frames it sends), one Ethernet frame (destination MAC first, no FCS) a
//! message; `[[channels]]` join them to the NIC partition's ports for this tenant
//! (`/etc/guest/net` in the initramfs; the stack is `partitions/guest/src/net.rs`).
//! `guest.disk` gives it the block device `/dev/vda`, its virtual disk of a block-device
//! partition (`blk.tenants.<guest>`, required): `request` is its queuing output of at least
//! 2072 bytes to the tenant's `from` port, `response` its queuing input of at least 2064
//! bytes from the tenant's `to` port (joined by channels), as `plc.store`'s
//! (`/etc/guest/disk` in the initramfs, with the tenant's `sectors`; what the device does:
//! docs/guest.md).
//!
//! **PCI devices.** `devices` names the PCI functions a partition owns by bus address
//! (`BB:DD.F` in hex, as `lspci` prints it; an optional `0000:` in front), at most 8 a
//! partition and none named twice in the system; the partition needs the `irq` ability.
//! At boot syssw reads each function's configuration header through the kernel (no
//! partition ever reaches configuration space: the kernel keeps ports 0xcf8-0xcff and never
//! maps ECAM), turns its decoding on (bus mastering only with `dma`, below)
//! and grants exactly its BARs: I/O BARs as I/O-port grants, memory BARs (whole pages)
//! mapped uncached at `protocol::layout::DEVICES_BASE` and after, and its INTx interrupt
//! line (q35: IOAPIC inputs 20..23, level-triggered, masked from when it fires until the
//! driver's `irq_ack`). The page at `DEVICES_BASE` tells the partition what it got (the
//! records of `pci::Record`). A function that is absent at boot, a bridge, or one whose
//! BARs or interrupt line cannot be granted alone stops only its partition: syssw logs
//! `syssw: partition NAME not started: PCI device BB:DD.F: WHY` and starts the others.
//!
//! **DMA.** `dma` (a size, whole pages, part of the partition's `memory` like its stack;
//! only with `devices`) gives the partition a physically contiguous DMA region, the only
//! memory its devices may reach: syssw allocates it at boot (zeroed, and again at every
//! cold restart), maps it read-write into the partition and turns bus mastering on for the
//! partition's devices; without `dma` bus mastering stays off. The partition learns the
//! region's address, length and *bus address* (what a device must be given for its first
//! byte) from its device page (`pci::dma_region`; docs/interfaces.md). When the machine
//! has an IOMMU (VT-d, found through the ACPI DMAR table; QEMU's `-device intel-iommu`)
//! the kernel confines each device of the partition to the region (bus address = physical
//! address; any other DMA of the device is blocked and reported to the health monitor as
//! the partition's `memory_violation`); when it has none, or its DMAR does not list the
//! device, syssw does not start the partition (`syssw: partition NAME not started: ...
//! no IOMMU confines its DMA`, the others run) unless it says `dma_unconfined = true`
//! (the tools print a warning; syssw logs one and starts it with DMA unconfined).
//!
//! **NIC.** The NIC partition (`image = "nic"`, `partitions/nic/partition`) drives the
//! virtio-net function it owns (`devices`, with a `dma` region, which it needs) and
//! switches Ethernet frames between the wire and its tenants. `nic.tenants.<partition>` attaches another partition with a MAC
//! address (six hex octets separated by colons; unicast, not all zero, unique among the
//! tenants) over two queuing ports of the NIC partition: `from`, an `in` port carrying the
//! tenant's frames, and `to`, an `out` port to the tenant, each of `size` at least 1514
//! (one Ethernet frame without FCS a message), each used by one tenant, and each joined by
//! its channel to a port of that tenant (the validator names the partition a channel
//! reaches instead). A tenant may name a frame ring, `ring = "<segment>"`: a
//! `[[shared_memory]]` segment of at least 16 KiB (`frame_ring::MIN_SEGMENT`) that the NIC
//! partition and the tenant both map `"rw"` and no other partition maps; its frames then
//! go through the segment (a ring each way, `common/frame-ring`) and the ports carry only
//! wake-ups (the ports' rules stay). A guest, a soft-PLC or an IEC 61499 device learns
//! where its ring is with its interface (`guest.net`, `plc.net`, `iec61499.net`); another
//! partition program finds it at the segment's address. At most 15 tenants; the NIC partition has no `plc`, `guest`,
//! `iec61499` or `data` keys (`cargo xtask` writes the tenant table as its data entry,
//! `nic_core::tenants`). The frame link and the switch's rules: docs/interfaces.md.
//!
//! **Block device.** A block-device partition (`image = "blk"`, `partitions/blk/partition`)
//! drives the virtio-blk function it owns (`devices`, with a `dma` region of at least
//! 12 KiB, which it needs) and gives each tenant a virtual disk: `blk.tenants.<partition>`
//! names another partition, its `sectors` sectors of 512 bytes from `first_sector` of the
//! disk (at least one; no two tenants' ranges overlap; whether the range fits the disk the
//! partition checks against the device's capacity at start, and refuses to serve
//! otherwise), and two queuing ports of the block-device partition: `from`, an `in` port
//! of `size` at least 2072 carrying the tenant's requests, and `to`, an `out` port of
//! `size` at least 2064 to the tenant, each used by one tenant and joined by its channel
//! to a port of that tenant, as the NIC's. At most 8 tenants; the
//! partition has no `plc`, `guest`, `iec61499`, `nic` or `data` keys (`cargo xtask` writes
//! the tenant table as its data entry, `blk_core::tenants`). The request link:
//! docs/interfaces.md.
//!
//! **Reserved resources.** I/O ports the kernel keeps (PICs 0x20-0x21 and 0xa0-0xa1, PIT
//! 0x40-0x43, COM1 0x3f8-0x3ff, isa-debug-exit 0xf4-0xf7, PCI configuration 0xcf8-0xcff) and IRQs 0 (PIT), 2 (cascade) and 4 (COM1)
//! are refused; no two partitions may share an I/O port or an IRQ.
//!
//! **Budgets.** Partition memory plus shared segments must fit in `memory` minus the kernel's
//! page-table pool (1/8 of `memory`, 16..128 MiB, [`model::kernel_pool`]) minus a 32 MiB
//! reserve for the kernel image, firmware, system image and syssw; the `kernel_memory`
//! quotas together must fit in the pool minus 1 MiB syssw keeps; thread and task quotas must
//! fit in the kernel's tables (256 threads, 64 tasks) after syssw's share (16, 1). What a
//! partition needs to start depends on its image, so `cargo xtask` checks it when it builds
//! the images (`check-config` and every image build, with `syssw_core::budget`, as syssw
//! does at boot): image + data entry + stack within `memory`, and the page tables of what
//! syssw maps for it (plus 2 pages of I/O bitmap with `io_ports`) within `kernel_memory`.
//!
//! **Images.** `load` takes a predicate that says which image names exist; `cargo xtask
//! check-config` passes the user programs the workspace builds.
#![no_std]

#[cfg(feature = "host")]
extern crate std;

pub mod binary;
pub mod model;
pub mod units;

#[cfg(feature = "host")]
pub mod diagnostic;
#[cfg(feature = "host")]
pub mod generate;
#[cfg(feature = "host")]
mod schema;
#[cfg(feature = "host")]
pub mod system;
#[cfg(feature = "host")]
mod validate;

pub use binary::{DecodeError, SystemView, decode};
#[cfg(feature = "host")]
pub use diagnostic::{Diagnostic, text};
#[cfg(feature = "host")]
pub use system::System;
#[cfg(feature = "host")]
pub use validate::{load, load_with_warnings};

/// Parses, validates and encodes a description in one step (what the image builder needs).
#[cfg(feature = "host")]
pub fn compile(
    file: &str,
    source: &str,
    known_images: &dyn Fn(&str) -> bool,
) -> Result<std::vec::Vec<u8>, std::vec::Vec<Diagnostic>> {
    load(file, source, known_images).map(|system| binary::encode(&system))
}
