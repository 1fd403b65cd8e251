//! From TOML text to a validated [`System`]: syntax, shape (serde, `deny_unknown_fields`),
//! then every rule of the format (see the crate documentation), reporting all problems found
//! with file, line:column, key path and reason.
//!
//! Syntax errors are all reported; a shape error (unknown key, wrong type, missing key) stops
//! at the first, because serde does; the semantic rules after it report everything they find.
//! Positions point at the offending value, or at the key or table header when the entry
//! itself is the problem.

use crate::diagnostic::{Diagnostic, KeyPath, Reporter, key_path_at};
use crate::model::*;
use crate::schema::{self, Named, Scalar, Targets};
use crate::system::*;
use crate::units::{self, Duration, Size};
use abi::syscall::Abilities;
use std::string::{String, ToString};
use std::vec::Vec;
use std::{format, vec};
use toml::Spanned;

mod drivers;

/// Parses and validates the description `source`. `file` only names the file in messages.
/// `known_images` says whether a partition image (user program) of that name exists; the
/// `cargo xtask check-config` command passes the programs the workspace builds.
pub fn load(
    file: &str,
    source: &str,
    known_images: &dyn Fn(&str) -> bool,
) -> Result<System, Vec<Diagnostic>> {
    load_with_warnings(file, source, known_images).map(|(system, _)| system)
}

/// [`load`], also returning the warnings of a valid description: things it says are
/// intended but that weaken a guarantee (e.g. `preempts_windows`), for the tools to print.
pub fn load_with_warnings(
    file: &str,
    source: &str,
    known_images: &dyn Fn(&str) -> bool,
) -> Result<(System, Vec<Diagnostic>), Vec<Diagnostic>> {
    let (tree, syntax) = toml::de::DeTable::parse_recoverable(source);
    let mut reporter = Reporter::new(file, source);
    if !syntax.is_empty() {
        for e in syntax {
            let at = e.span().map_or(0, |s| s.start);
            let path = KeyPath::from_rendered(key_path_at(tree.get_ref(), at));
            reporter.error(at, &path, format!("TOML syntax: {}", e.message()));
        }
        return Err(reporter.finish());
    }
    let document: schema::Document = match toml::from_str(source) {
        Ok(d) => d,
        Err(e) => {
            let at = e.span().map_or(0, |s| s.start);
            let path = KeyPath::from_rendered(key_path_at(tree.get_ref(), at));
            reporter.error(at, &path, e.message());
            return Err(reporter.finish());
        }
    };
    let mut v = Validator {
        r: reporter,
        known_images,
        cpus: 1,
        cpus_given: false,
        unbound: Vec::new(),
    };
    let system = v.system(&document);
    if v.r.diagnostics.is_empty() {
        let mut warnings = core::mem::take(&mut v.r.warnings);
        warnings.sort_by_key(|d| (d.line, d.column));
        Ok((system, warnings))
    } else {
        Err(v.r.finish())
    }
}

struct Validator<'s, 'k> {
    r: Reporter<'s>,
    known_images: &'k dyn Fn(&str) -> bool,
    /// The CPUs the system uses (`[system] cpus`; [`MAX_CPUS`] when it has an error, so
    /// that no CPU number is refused twice), and whether the file gives it.
    cpus: u8,
    cpus_given: bool,
    /// Partitions whose `cpus` has an error (their windows' CPUs are then not checked).
    unbound: Vec<usize>,
}

/// A valid window of a schedule while the schedule is checked.
#[derive(Clone, Copy)]
struct Slot {
    offset: u64,
    duration: u64,
    /// Index of the partition it names.
    partition: usize,
    /// Index of the window in the schedule's source.
    source: usize,
    cpu: u8,
}

impl Slot {
    fn end(self) -> u64 {
        self.offset + self.duration
    }
}

/// Where a port was declared, for channel checks.
struct PortDecl {
    partition: usize,
    port: usize,
    key_at: usize,
    path: KeyPath,
    /// Channel that uses it, with the offset of that use.
    used_by: Option<(usize, usize)>,
    /// False if the declaration itself has errors (channels then skip it silently).
    valid: bool,
}

/// How a partition asked for CPU time.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Time {
    Background,
    Explicit(u8, usize),
    Auto,
    /// `time` has an error (already reported).
    Invalid,
}

fn start<T>(s: &Spanned<T>) -> usize {
    s.span().start
}

/// One entry of a list or table of the description: its place in the list, its key path
/// and where it starts in the source.
struct Entry<I> {
    index: usize,
    path: KeyPath,
    at: usize,
    item: I,
}

/// The entries of the array `items` at `base` (key paths `base[i]`).
fn array_entries<'d, T>(items: &'d [Spanned<T>], base: &KeyPath) -> Vec<Entry<&'d Spanned<T>>> {
    items
        .iter()
        .enumerate()
        .map(|(index, item)| Entry {
            index,
            path: base.index(index),
            at: start(item),
            item,
        })
        .collect()
}

fn list<T: Copy>(items: &[T], name: impl Fn(T) -> &'static str) -> String {
    items
        .iter()
        .map(|&i| name(i))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Named entries in the order of the source (BTreeMaps sort by name).
fn in_source_order<T>(map: &Named<T>) -> Vec<(&Spanned<String>, &Spanned<T>)> {
    let mut entries: Vec<_> = map.iter().collect();
    entries.sort_by_key(|(k, _)| k.span().start);
    entries
}

/// A scalar as the description wrote it (strings quoted), for messages.
fn shown(value: &Scalar) -> String {
    match value {
        Scalar::Int(i) => i.to_string(),
        Scalar::Str(s) => format!("{s:?}"),
    }
}

/// The link fields of a `plc.net` or `iec61499.net` (those of `guest.net`, which checks
/// them) as a `schema::GuestNet`.
macro_rules! link_fields {
    ($net:expr) => {
        schema::GuestNet {
            mac: $net.mac.clone(),
            address: $net.address.clone(),
            gateway: $net.gateway.clone(),
            rx: $net.rx.clone(),
            tx: $net.tx.clone(),
        }
    };
}

impl Validator<'_, '_> {
    fn error(&mut self, at: usize, path: &KeyPath, message: impl core::fmt::Display) {
        self.r.error(at, path, message);
    }

    /// `entries`, of which at most `max` are allowed: the first one past `max` is reported
    /// as "too many {what} (at most {max}{why})". All are returned, so every entry is still
    /// checked and one run reports every other error too.
    fn at_most<I>(
        &mut self,
        entries: Vec<Entry<I>>,
        max: usize,
        what: &str,
        why: &str,
    ) -> Vec<Entry<I>> {
        if let Some(first_too_many) = entries.get(max) {
            let (at, path) = (first_too_many.at, first_too_many.path.clone());
            self.error(at, &path, format!("too many {what} (at most {max}{why})"));
        }
        entries
    }

    fn size(&mut self, value: &Spanned<Scalar>, path: &KeyPath) -> Option<u64> {
        let parsed = match value.get_ref() {
            Scalar::Int(i) => units::size_from_integer(*i),
            Scalar::Str(s) => units::parse_size(s),
        };
        match parsed {
            Ok(bytes) => Some(bytes),
            Err(e) => {
                let shown = shown(value.get_ref());
                self.error(start(value), path, format!("invalid size {shown}: {e}"));
                None
            }
        }
    }

    /// A size that must be a non-zero multiple of 4 KiB.
    fn page_size(&mut self, value: &Spanned<Scalar>, path: &KeyPath) -> Option<u64> {
        let bytes = self.size(value, path)?;
        if bytes == 0 {
            self.error(start(value), path, "must not be zero");
            return None;
        }
        if !bytes.is_multiple_of(PAGE_SIZE) {
            let up = bytes.div_ceil(PAGE_SIZE).saturating_mul(PAGE_SIZE);
            self.error(
                start(value),
                path,
                format!(
                    "{} is not a multiple of 4 KiB (4096 bytes); memory is given in whole pages, e.g. {}",
                    Size(bytes),
                    Size(up)
                ),
            );
            return None;
        }
        Some(bytes)
    }

    fn duration(&mut self, value: &Spanned<Scalar>, path: &KeyPath) -> Option<u64> {
        let parsed = match value.get_ref() {
            Scalar::Int(_) => Err(units::UnitError::MissingUnit),
            Scalar::Str(s) => units::parse_duration(s),
        };
        match parsed {
            Ok(ns) => Some(ns),
            Err(e) => {
                let shown = shown(value.get_ref());
                self.error(start(value), path, format!("invalid duration {shown}: {e}"));
                None
            }
        }
    }

    fn name(&mut self, name: &Spanned<String>, path: &KeyPath, max: usize, what: &str) -> bool {
        match check_name(name.get_ref(), max) {
            Ok(()) => true,
            Err(e) => {
                self.error(
                    start(name),
                    path,
                    format!("{what} name {:?} {e}", name.get_ref()),
                );
                false
            }
        }
    }

    fn health(&mut self, table: &Named<String>, path: &KeyPath) -> HealthTable {
        let mut out = HealthTable::default();
        for (error, action) in in_source_order(table) {
            let here = path.key(error.get_ref());
            let e = ErrorCode::from_name(error.get_ref());
            if e.is_none() {
                self.error(
                    start(error),
                    &here,
                    format!(
                        "unknown health error `{}`; known errors: {}",
                        error.get_ref(),
                        list(&ErrorCode::ALL, ErrorCode::name)
                    ),
                );
            }
            let a = HealthAction::from_name(action.get_ref());
            if a.is_none() {
                self.error(
                    start(action),
                    &here,
                    format!(
                        "unknown health action `{}`; known actions: {}",
                        action.get_ref(),
                        list(&HealthAction::ALL, HealthAction::name)
                    ),
                );
            }
            if let (Some(e), Some(a)) = (e, a) {
                out.set(e, a);
            }
        }
        out
    }

    fn system(&mut self, doc: &schema::Document) -> System {
        let root = KeyPath::root();
        let section = doc.system.get_ref();
        let sys_path = root.key("system");
        let memory_path = sys_path.key("memory");
        let memory = self.page_size(&section.memory, &memory_path);
        let name = match &section.name {
            Some(n) => {
                self.name(n, &sys_path.key("name"), NAME_MAX, "system");
                n.get_ref().clone()
            }
            None => "system".to_string(),
        };

        self.cpus = self.system_cpus(section, &sys_path.key("cpus"));
        let segments = self.segments(doc);
        let (mut partitions, times, mut ports) = self.partitions(doc, &segments);
        let schedules = self.schedules(doc, &mut partitions, &times);
        self.background_priorities(doc, &partitions);
        let channels = self.channels(doc, &mut partitions, &mut ports);
        self.nic(doc, &mut partitions, &channels, &segments);
        self.blk(doc, &mut partitions, &channels);
        self.plc_stores(doc, &partitions);
        self.guest_disks(doc, &mut partitions, &channels);
        let health = self.health(&doc.health, &root.key("health"));

        if let Some(memory) = memory {
            self.budgets(
                memory,
                start(&section.memory),
                &memory_path,
                &partitions,
                &segments,
            );
        }
        System {
            name,
            memory: memory.unwrap_or(0),
            cpus: self.cpus,
            schedules,
            partitions,
            segments: segments.into_iter().map(|(s, _)| s).collect(),
            channels,
            health,
        }
    }

    /// `[system] cpus`: 1..=[`MAX_CPUS`], default 1.
    fn system_cpus(&mut self, section: &schema::SystemSection, path: &KeyPath) -> u8 {
        let Some(cpus) = &section.cpus else {
            return 1;
        };
        self.cpus_given = true;
        let n = *cpus.get_ref();
        if (1..=MAX_CPUS as i64).contains(&n) {
            return n as u8;
        }
        self.error(
            start(cpus),
            path,
            format!("cpus = {n} is not in 1..={MAX_CPUS} (the most CPUs the kernel runs)"),
        );
        MAX_CPUS as u8
    }

    /// How many CPUs the system uses, for a message about a CPU beyond them.
    fn cpus_used(&self) -> String {
        match (self.cpus, self.cpus_given) {
            (1, false) => "the system uses 1 CPU, CPU 0 (`cpus` in [system], default 1)".into(),
            (1, true) => "the system uses 1 CPU, CPU 0 (`[system] cpus = 1`)".into(),
            (n, _) => format!(
                "the system uses {n} CPUs, 0 to {} (`[system] cpus = {n}`)",
                n - 1
            ),
        }
    }

    /// A partition's `cpus`: CPUs the system uses, none twice (default `[0]`), as a mask
    /// (bit n: CPU n). `[0]` when it has an error (the partition is then marked in
    /// `unbound`).
    fn partition_cpus(
        &mut self,
        raw: &schema::Partition,
        path: &KeyPath,
        (index, name): (usize, &str),
    ) -> u8 {
        let Some(list) = &raw.cpus else {
            return 1;
        };
        let here = path.key("cpus");
        if list.get_ref().is_empty() {
            self.error(
                start(list),
                &here,
                format!("partition `{name}` names no CPU: give at least one, e.g. `cpus = [0]`"),
            );
            self.unbound.push(index);
            return 1;
        }
        let mut mask = 0u8;
        for (i, entry) in list.get_ref().iter().enumerate() {
            let n = *entry.get_ref();
            let why = if n < 0 {
                format!("partition `{name}`: {n} is not a CPU number (CPU 0 is the boot CPU)")
            } else if n >= i64::from(self.cpus) {
                format!(
                    "partition `{name}` runs on CPU {n}, but {}",
                    self.cpus_used()
                )
            } else if mask & 1 << n != 0 {
                format!("partition `{name}` lists CPU {n} twice")
            } else {
                mask |= 1 << n;
                continue;
            };
            self.error(start(entry), &here.index(i), why);
            if !self.unbound.contains(&index) {
                self.unbound.push(index);
            }
        }
        if self.unbound.contains(&index) {
            1
        } else {
            mask
        }
    }

    fn segments(&mut self, doc: &schema::Document) -> Vec<(Segment, usize)> {
        let mut out: Vec<(Segment, usize)> = Vec::new();
        let base = KeyPath::root().key("shared_memory");
        let entries = array_entries(&doc.shared_memory, &base);
        for Entry {
            path, item: seg, ..
        } in self.at_most(entries, MAX_SEGMENTS, "shared memory segments", "")
        {
            let raw = seg.get_ref();
            let name_path = path.key("name");
            self.name(&raw.name, &name_path, NAME_MAX, "segment");
            if let Some((_, at)) = out.iter().find(|(s, _)| s.name == *raw.name.get_ref()) {
                let line = self.r.line_of(*at);
                self.error(
                    start(&raw.name),
                    &name_path,
                    format!(
                        "shared memory segment `{}` is already defined at line {line}",
                        raw.name.get_ref()
                    ),
                );
            }
            let size = self.page_size(&raw.size, &path.key("size")).unwrap_or(0);
            out.push((
                Segment {
                    name: raw.name.get_ref().clone(),
                    size,
                },
                start(&raw.name),
            ));
        }
        out
    }

    fn partitions(
        &mut self,
        doc: &schema::Document,
        segments: &[(Segment, usize)],
    ) -> (Vec<Partition>, Vec<Time>, Vec<PortDecl>) {
        let mut partitions = Vec::new();
        let mut times = Vec::new();
        let mut ports = Vec::new();
        // (range, partition index, offset) of every I/O range and IRQ so far.
        let mut io_seen: Vec<(IoRange, usize, usize)> = Vec::new();
        let mut irq_seen: Vec<(u8, usize, usize)> = Vec::new();
        let mut devices_seen: Vec<(pci::Address, usize, usize)> = Vec::new();
        let mut attachment_total = 0;
        let base = KeyPath::root().key("partitions");
        let entries = in_source_order(&doc.partitions)
            .into_iter()
            .enumerate()
            .map(|(index, (key, value))| Entry {
                index,
                path: base.key(key.get_ref()),
                at: start(key),
                item: (key, value),
            })
            .collect();
        let entries = self.at_most(
            entries,
            MAX_PARTITIONS,
            "partitions",
            ": the kernel has 16 resource partitions and syssw keeps one",
        );
        for Entry {
            index,
            path,
            item: (key, value),
            ..
        } in entries
        {
            let raw = value.get_ref();
            let name = key.get_ref().clone();
            self.name(key, &path, PARTITION_NAME_MAX, "partition");

            let image_path = path.key("image");
            let image = raw.image.get_ref().clone();
            if self.name(&raw.image, &image_path, NAME_MAX, "image") && !(self.known_images)(&image)
            {
                self.error(
                    start(&raw.image),
                    &image_path,
                    format!("unknown image `{image}`: no user program of that name is built"),
                );
            }
            let (memory, kernel_memory, stack) = self.partition_memory(raw, &path);
            let kernel_threads = self.quota(
                raw.kernel_threads.as_ref(),
                &path.key("kernel_threads"),
                DEFAULT_KERNEL_THREADS,
                KERNEL_THREADS - SYSSW_THREADS,
                "threads",
            );
            let kernel_tasks = self.quota(
                raw.kernel_tasks.as_ref(),
                &path.key("kernel_tasks"),
                DEFAULT_KERNEL_TASKS,
                KERNEL_TASKS - SYSSW_TASKS,
                "tasks",
            );

            let (mcp, priority) = self.priorities(raw, &path);

            let abilities = self.abilities(raw, &path);
            let time = self.time(raw, &path);
            let cpus = self.partition_cpus(raw, &path, (index, &name));

            let io_ports = self.io_ports(doc, raw, &path, index, &mut io_seen);

            let irqs = self.irqs(doc, raw, &path, index, &mut irq_seen, abilities);
            let devices = self.devices(doc, raw, &path, index, &mut devices_seen, abilities);
            let (dma, dma_unconfined) = self.dma(raw, &path, memory, stack, &devices);

            let shared = self.attachments(raw, &path, segments, &mut attachment_total);

            let own_ports = self.partition_ports(raw, &path, index, &mut ports);

            let health = self.health(&raw.health, &path.key("health"));
            let plc = raw.plc.as_ref().and_then(|plc| {
                let plc_path = path.key("plc");
                let shared_segment =
                    self.plc_shared(plc, &plc_path, &shared, segments, &partitions);
                self.plc(plc, &plc_path, &own_ports).map(|p| Plc {
                    shared: shared_segment,
                    ..p
                })
            });
            let data = raw
                .data
                .as_ref()
                .and_then(|d| self.data_entry(d, &path.key("data"), raw.plc.is_some()));
            let guest = raw.guest.as_ref().and_then(|guest| {
                let stack = (stack, &path.key("stack"));
                let device = (io_ports.as_slice(), irqs);
                self.guest(raw, guest, &path.key("guest"), abilities, stack, device)
                    .map(|g| Guest {
                        net: guest.get_ref().net.as_ref().and_then(|net| {
                            self.guest_net(net, &path.key("guest").key("net"), &own_ports)
                        }),
                        disk: guest.get_ref().disk.as_ref().and_then(|disk| {
                            self.guest_disk(disk, &path.key("guest").key("disk"), &own_ports)
                        }),
                        ..g
                    })
            });
            if raw.guest.is_some() {
                for (port_key, port) in in_source_order(&raw.ports) {
                    // (An invalid size is the port check's to report.)
                    let size = match port.get_ref().size.get_ref() {
                        Scalar::Int(i) => units::size_from_integer(*i),
                        Scalar::Str(s) => units::parse_size(s),
                    };
                    if size.is_ok_and(|s| s > GUEST_MAX_MESSAGE) {
                        self.error(
                            start(&port.get_ref().size),
                            &path.key("ports").key(port_key.get_ref()).key("size"),
                            format!(
                                "a guest's port devices move at most {GUEST_MAX_MESSAGE} bytes a message (one `read` or `write`); longer messages are for APEX partitions"
                            ),
                        );
                    }
                    let discipline = port.get_ref().discipline.as_ref();
                    if let Some(d) = discipline.filter(|d| d.get_ref() == "priority") {
                        self.error(
                            start(d),
                            &path.key("ports").key(port_key.get_ref()).key("discipline"),
                            "a guest never waits on a port (its calls do not block): a PRIORITY discipline is for APEX partitions",
                        );
                    }
                }
            }
            if let (Some(_), Some(data)) = (&raw.guest, &raw.data) {
                self.error(
                    start(data),
                    &path.key("data"),
                    "a guest partition's data entry is its initramfs (from `guest.*`): `data` is for other partitions",
                );
            }
            let iec61499 = raw
                .iec61499
                .as_ref()
                .and_then(|fb| self.iec61499(raw, fb, &path.key("iec61499"), &own_ports));
            times.push(time);
            partitions.push(Partition {
                name,
                image,
                memory: memory.unwrap_or(0),
                kernel_memory,
                stack,
                kernel_threads,
                kernel_tasks,
                abilities,
                mcp,
                priority,
                time_partition: 0,
                cpu: cpus.trailing_zeros() as u8,
                cpus,
                schedule_control: raw.schedule_control.as_ref().is_some_and(|b| *b.get_ref()),
                io_ports,
                irqs,
                devices,
                dma,
                dma_unconfined,
                shared,
                ports: own_ports,
                health,
                plc,
                data,
                guest,
                iec61499,
                nic: None,
                blk: None,
            });
        }
        (partitions, times, ports)
    }

    /// A guest partition's first process (see the crate documentation).
    fn guest(
        &mut self,
        raw: &schema::Partition,
        guest: &Spanned<schema::Guest>,
        path: &KeyPath,
        abilities: Abilities,
        (stack, stack_path): (u64, &KeyPath),
        (io_ports, irqs): (&[IoRange], IrqMask),
    ) -> Option<Guest> {
        let before = self.r.diagnostics.len();
        let g = guest.get_ref();
        if stack != 0 && stack < GUEST_MIN_STACK {
            let (at, at_path) = match &raw.stack {
                Some(s) => (start(s), stack_path.clone()),
                None => (start(guest), path.clone()),
            };
            self.error(
                at,
                &at_path,
                format!(
                    "a guest partition needs a `stack` of at least {} (its process table lives there), not {}",
                    Size(GUEST_MIN_STACK),
                    Size(stack)
                ),
            );
        }
        let init_path = path.key("init");
        if raw.plc.is_some() {
            self.error(
                start(guest),
                path,
                "a partition runs either the soft-PLC (`plc`) or the guest (`guest`), not both",
            );
        }
        let needed = Abilities::CREATE_TASK | Abilities::CREATE_THREAD | Abilities::MAP;
        if !abilities.contains(needed) {
            self.error(
                start(guest),
                path,
                "a guest partition needs the abilities `create_task`, `create_thread` and `map` (its processes are child tasks backed by its memory pool)",
            );
        }
        match g.init.first() {
            None => self.error(
                start(guest),
                &init_path,
                "`init` needs at least the program to run, e.g. [\"/bin/busybox\", \"echo\", \"hello\"]",
            ),
            Some(program) if !program.get_ref().starts_with('/') => self.error(
                start(program),
                &init_path.index(0),
                format!(
                    "`{}` is not an absolute path in the initramfs (such as `/bin/busybox`)",
                    program.get_ref()
                ),
            ),
            Some(_) => {}
        }
        let env: Vec<Spanned<String>> = g.env.clone().unwrap_or_default();
        let mut bytes = 0;
        for (key, list) in [("init", &g.init), ("env", &env)] {
            for (i, s) in list.iter().enumerate() {
                bytes += s.get_ref().len() + 1;
                if s.get_ref().contains('\0') {
                    self.error(start(s), &path.key(key).index(i), "contains a NUL byte");
                }
                if key == "env" && !s.get_ref().contains('=') {
                    self.error(
                        start(s),
                        &path.key(key).index(i),
                        format!("`{}` is not NAME=value", s.get_ref()),
                    );
                }
            }
        }
        let strings = g.init.len() + env.len();
        if strings > GUEST_MAX_STRINGS || bytes > GUEST_MAX_BYTES {
            self.error(
                start(guest),
                path,
                format!(
                    "`init` and `env` have {strings} strings of {bytes} bytes; at most {GUEST_MAX_STRINGS} strings and {GUEST_MAX_BYTES} bytes"
                ),
            );
        }
        let base = std::path::Path::new(self.r.file())
            .parent()
            .unwrap_or(std::path::Path::new(""))
            .to_path_buf();
        let mut files = Vec::new();
        for (target, source) in &g.files {
            let at = path.key("files").key(target.get_ref());
            let t = target.get_ref();
            let normal = t.starts_with('/')
                && !t.ends_with('/')
                && t[1..]
                    .split('/')
                    .all(|part| !part.is_empty() && part != "." && part != "..")
                && !t.contains('\0');
            if !normal {
                self.error(
                    start(target),
                    &at,
                    format!(
                        "`{t}` is not a normalised absolute path of a file (such as `/etc/motd`)"
                    ),
                );
            } else if GUEST_RESERVED_PATHS.contains(&t.as_str()) {
                self.error(
                    start(target),
                    &at,
                    format!(
                        "`{t}` is written by the image builder and cannot be replaced (reserved: {})",
                        GUEST_RESERVED_PATHS.join(", ")
                    ),
                );
            }
            let resolved = base.join(source.get_ref());
            if !resolved.is_file() {
                self.error(
                    start(source),
                    &at,
                    format!(
                        "no such file `{}` (paths are relative to this description's directory: {})",
                        source.get_ref(),
                        resolved.display()
                    ),
                );
            }
            files.push((
                t.clone(),
                SourceFile {
                    name: source.get_ref().clone(),
                    path: resolved.to_string_lossy().into_owned(),
                },
            ));
        }
        let console_com2 = g.console.as_ref().is_some_and(|console| {
            let at = path.key("console");
            if console.get_ref() != "com2" {
                self.error(
                    start(console),
                    &at,
                    format!(
                        "`{}` is no console device (the only one is \"com2\")",
                        console.get_ref()
                    ),
                );
                return false;
            }
            let has_ports = io_ports
                .iter()
                .any(|r| r.first <= COM2_PORTS.first && COM2_PORTS.last <= r.last);
            if !has_ports || !irqs.contains(COM2_IRQ) {
                self.error(
                    start(console),
                    &at,
                    "a console on COM2 needs its ports and interrupt: io_ports = [\"0x2f8-0x2ff\"] and irqs = [3] (with the ability `irq`)",
                );
            }
            true
        });
        let mut programs: Vec<String> = Vec::new();
        for (i, program) in g.programs.iter().enumerate() {
            let name = program.get_ref();
            let at = path.key("programs").index(i);
            if !GUEST_PROGRAMS.contains(&name.as_str()) {
                self.error(
                    start(program),
                    &at,
                    format!(
                        "`{name}` is no program cargo xtask builds (known: {})",
                        GUEST_PROGRAMS.join(", ")
                    ),
                );
            } else if programs.contains(name) {
                self.error(start(program), &at, format!("`{name}` is listed twice"));
            } else if files.iter().any(|(t, _)| *t == format!("/bin/{name}")) {
                self.error(
                    start(program),
                    &at,
                    format!("`/bin/{name}` is also a `guest.files` path"),
                );
            }
            programs.push(name.clone());
        }
        (self.r.diagnostics.len() == before).then(|| Guest {
            console_com2,
            programs,
            net: None,
            disk: None,
            files,
            init: g.init.iter().map(|s| s.get_ref().clone()).collect(),
            env: match &g.env {
                Some(env) => env.iter().map(|s| s.get_ref().clone()).collect(),
                None => GUEST_DEFAULT_ENV.iter().map(|s| s.to_string()).collect(),
            },
        })
    }

    /// `guest.net`: a unicast MAC, an address with its prefix, a gateway inside that
    /// subnet, and two queuing ports of the partition (a frame a message: 1514 bytes).
    fn guest_net(
        &mut self,
        net: &Spanned<schema::GuestNet>,
        path: &KeyPath,
        ports: &[Port],
    ) -> Option<GuestNet> {
        let before = self.r.diagnostics.len();
        let n = net.get_ref();
        let mac = nic_core::switch::Mac::parse(n.mac.get_ref())
            .map(|m| m.0)
            .filter(|m| m[0] & 1 == 0);
        if mac.is_none() {
            self.error(
                start(&n.mac),
                &path.key("mac"),
                format!(
                    "`{}` is no unicast MAC address (six hex octets, e.g. \"52:54:00:12:34:56\", the first even)",
                    n.mac.get_ref()
                ),
            );
        }
        let address = n
            .address
            .get_ref()
            .split_once('/')
            .and_then(|(ip, prefix)| {
                Some((
                    parse_ipv4(ip)?,
                    prefix.parse::<u8>().ok().filter(|p| (1..=30).contains(p))?,
                ))
            });
        if address.is_none() {
            self.error(
                start(&n.address),
                &path.key("address"),
                format!(
                    "`{}` is no IPv4 address with a prefix length of 1 to 30 (e.g. \"10.0.2.15/24\")",
                    n.address.get_ref()
                ),
            );
        }
        let gateway = n.gateway.as_ref().and_then(|g| {
            let ip = parse_ipv4(g.get_ref());
            let inside = match (ip, address) {
                (Some(ip), Some((own, prefix))) => {
                    let mask = u32::MAX << (32 - u32::from(prefix));
                    u32::from_be_bytes(ip) & mask == u32::from_be_bytes(own) & mask
                        && ip != own
                }
                _ => false,
            };
            if !inside {
                self.error(
                    start(g),
                    &path.key("gateway"),
                    format!(
                        "`{}` is no IPv4 address of the guest's subnet other than its own (`address`)",
                        g.get_ref()
                    ),
                );
            }
            ip
        });
        for (key, name, direction) in [("rx", &n.rx, Direction::In), ("tx", &n.tx, Direction::Out)]
        {
            let port = ports.iter().find(|p| p.name == *name.get_ref());
            let fits = port.is_some_and(|p| {
                p.kind == PortKind::Queuing
                    && p.direction == direction
                    && p.size >= ETHERNET_FRAME_MAX
            });
            if !fits {
                let way = if direction == Direction::In {
                    "in"
                } else {
                    "out"
                };
                self.error(
                    start(name),
                    &path.key(key),
                    format!(
                        "`{}` is no queuing `{way}` port of this partition with `size` of at least {ETHERNET_FRAME_MAX} (one Ethernet frame a message)",
                        name.get_ref()
                    ),
                );
            }
        }
        if n.rx.get_ref() == n.tx.get_ref() {
            self.error(
                start(&n.tx),
                &path.key("tx"),
                "`rx` and `tx` must be two ports",
            );
        }
        let (address, prefix) = address?;
        (self.r.diagnostics.len() == before).then(|| GuestNet {
            mac: mac.unwrap_or_default(),
            address,
            prefix,
            gateway,
            rx: n.rx.get_ref().clone(),
            tx: n.tx.get_ref().clone(),
            ring: None,
        })
    }

    /// ST source files, resolved against the description's directory (each must exist).
    fn source_files(&mut self, files: &[Spanned<String>], at: &KeyPath) -> Vec<SourceFile> {
        let base = std::path::Path::new(self.r.file())
            .parent()
            .unwrap_or(std::path::Path::new(""))
            .to_path_buf();
        let mut program = Vec::new();
        for file in files {
            let resolved = base.join(file.get_ref());
            if !resolved.is_file() {
                self.error(
                    start(file),
                    at,
                    format!(
                        "no such file `{}` (program paths are relative to this description's directory: {})",
                        file.get_ref(),
                        resolved.display()
                    ),
                );
            }
            program.push(SourceFile {
                name: file.get_ref().clone(),
                path: resolved.to_string_lossy().into_owned(),
            });
        }
        program
    }

    /// An IEC 61499 partition's boot file and types (see the crate documentation).
    fn iec61499(
        &mut self,
        raw: &schema::Partition,
        fb: &Spanned<schema::Iec61499>,
        path: &KeyPath,
        ports: &[Port],
    ) -> Option<Iec61499> {
        let before = self.r.diagnostics.len();
        let others = [
            (raw.plc.is_some(), "the soft-PLC (`plc`)"),
            (raw.guest.is_some(), "the guest (`guest`)"),
            (raw.data.is_some(), "a `data` entry"),
        ];
        for (_, what) in others.iter().filter(|(has, _)| *has) {
            self.error(
                start(fb),
                path,
                format!(
                    "a partition runs the IEC 61499 runtime (`iec61499`) or {what}, not both: its data entry is its device package"
                ),
            );
        }
        let f = fb.get_ref();
        let boot_path = path.key("boot");
        let boot = self.source_files(core::slice::from_ref(&f.boot), &boot_path);
        let types = self.source_files(&f.types, &path.key("types"));
        let mgmt = f
            .mgmt
            .as_ref()
            .and_then(|m| self.online_ports(m, &path.key("mgmt"), ports, MGMT_MESSAGE_SIZE));
        let net = f
            .net
            .as_ref()
            .and_then(|n| self.iec61499_net(n, &path.key("net"), ports));
        if let (Some(m), Some(n), Some(raw)) = (&mgmt, &net, &f.net) {
            let frame_ports = [n.link.rx.as_str(), n.link.tx.as_str()];
            if [m.request, m.response]
                .iter()
                .any(|&i| frame_ports.contains(&ports[i].name.as_str()))
            {
                self.error(
                    start(raw),
                    &path.key("net"),
                    "`rx` and `tx` carry frames: they cannot be the management ports of `iec61499.mgmt`",
                );
            }
        }
        let resources = self.resource_processes(
            &f.resources,
            &path.key("resources"),
            *raw.max_priority.get_ref(),
        );
        if self.r.diagnostics.len() != before {
            return None;
        }
        Some(Iec61499 {
            boot: boot.into_iter().next()?,
            types,
            mgmt,
            net,
            resources,
        })
    }

    /// `iec61499.resources`: resource names (IEC identifiers) and their processes'
    /// priorities, each in 2..MCP: the device's own process runs just below the lowest.
    fn resource_processes(
        &mut self,
        raw: &schema::Named<i64>,
        path: &KeyPath,
        mcp: i64,
    ) -> Vec<ResourceProcess> {
        let mut resources = Vec::new();
        if raw.len() > ResourceProcess::MAX {
            if let Some((name, _)) = raw.iter().nth(ResourceProcess::MAX) {
                self.error(
                    start(name),
                    path,
                    format!(
                        "{} resources with their own process: a device has at most {} resources",
                        raw.len(),
                        ResourceProcess::MAX
                    ),
                );
            }
            return resources;
        }
        for (name, priority) in raw {
            let key = path.key(name.get_ref());
            let text = name.get_ref();
            let identifier = text
                .chars()
                .next()
                .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
                && text.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
            if !identifier || text.len() > ResourceProcess::MAX_NAME {
                self.error(
                    start(name),
                    &key,
                    format!(
                        "{text:?} is not a resource name: an IEC identifier (letters, digits, `_`, not starting with a digit) of at most {} bytes",
                        ResourceProcess::MAX_NAME
                    ),
                );
                continue;
            }
            let p = *priority.get_ref();
            if !(2..mcp).contains(&p) {
                self.error(
                    start(priority),
                    &key,
                    format!(
                        "priority {p} is not in 2..={}: a resource's process runs below the partition's max_priority ({mcp}) and above the device's own process (at least 1)",
                        mcp - 1
                    ),
                );
                continue;
            }
            resources.push(ResourceProcess {
                name: text.clone(),
                priority: p as u8,
            });
        }
        resources
    }

    /// `iec61499.net`: the link as `guest.net` checks it, the TCP port, the connections
    /// and the access of every client.
    fn iec61499_net(
        &mut self,
        net: &Spanned<schema::Iec61499Net>,
        path: &KeyPath,
        ports: &[Port],
    ) -> Option<Iec61499Net> {
        let n = net.get_ref();
        let link = self.guest_net(&Spanned::new(net.span(), link_fields!(n)), path, ports);
        let port = self.int_in(
            n.port.as_ref(),
            path,
            "port",
            1..=65_535,
            i64::from(Iec61499Net::DEFAULT_PORT),
        );
        let connections = self.int_in(
            n.connections.as_ref(),
            path,
            "connections",
            1..=i64::from(Iec61499Net::MAX_CONNECTIONS),
            i64::from(Iec61499Net::DEFAULT_CONNECTIONS),
        );
        let access = match &n.access {
            None => Some(plc_online::Access::Monitor),
            Some(a) => {
                let access = plc_online::Access::from_name(a.get_ref());
                if access.is_none() {
                    self.error(
                        start(a),
                        &path.key("access"),
                        format!(
                            "unknown access {:?}: expected \"monitor\", \"force\" or \"download\" (what each allows: the \"IEC 61499\" section of the format)",
                            a.get_ref()
                        ),
                    );
                }
                access
            }
        };
        Some(Iec61499Net {
            link: link?,
            port: port? as u16,
            connections: connections? as u8,
            access: access?,
        })
    }

    /// `data`: what `cargo xtask` puts into the partition's data entry (see the crate
    /// documentation); a PLC partition's data entry is its package, so it has none.
    fn data_entry(
        &mut self,
        raw: &Spanned<schema::Data>,
        path: &KeyPath,
        is_plc: bool,
    ) -> Option<DataEntry> {
        let before = self.r.diagnostics.len();
        let files_path = path.key("plc_image");
        if is_plc {
            self.error(
                start(raw),
                path,
                "a PLC partition's data entry is its PLC package (from `plc.*`): `data` is for other partitions",
            );
        }
        let files = &raw.get_ref().plc_image;
        if files.is_empty() {
            self.error(
                start(raw),
                &files_path,
                "`plc_image` needs at least one ST source file",
            );
        }
        let files = self.source_files(files, &files_path);
        (self.r.diagnostics.len() == before).then_some(DataEntry::PlcImage(files))
    }

    /// A soft-PLC partition's program files and port mapping (see the crate documentation).
    fn plc(&mut self, plc: &Spanned<schema::Plc>, path: &KeyPath, ports: &[Port]) -> Option<Plc> {
        use plc_vm::located::{Area, Location, MAX_AREA, Width};
        let raw = plc.get_ref();
        let before = self.r.diagnostics.len();
        let program_path = path.key("program");
        if raw.program.is_empty() {
            self.error(
                start(plc),
                &program_path,
                "a PLC partition needs at least one ST source file in `program`",
            );
        }
        let program = self.source_files(&raw.program, &program_path);
        // Parses an address of `area`; a bit when `bit`, else a byte/word/... start.
        let address =
            |v: &mut Self, text: &Spanned<String>, at_path: &KeyPath, area: Area, bit: bool| {
                let parsed = text
                    .get_ref()
                    .strip_prefix('%')
                    .ok_or_else(|| "a direct address starts with `%`".to_string())
                    .and_then(|t| Location::parse(t).map_err(|e| e.to_string()));
                match parsed {
                    Ok(l) if l.area == area && (l.width == Width::Bit) == bit => Some(l),
                    Ok(_) => {
                        let want = match (area, bit) {
                            (Area::Input, true) => "an input bit such as `%IX8.0`",
                            (Area::Input, false) => {
                                "an input byte address such as `%IB0` (or %IW/%ID/%IL)"
                            }
                            (_, _) => "an output byte address such as `%QB0` (or %QW/%QD/%QL)",
                        };
                        v.error(
                            start(text),
                            at_path,
                            format!("`{}` is not {want}", text.get_ref()),
                        );
                        None
                    }
                    Err(e) => {
                        v.error(
                            start(text),
                            at_path,
                            format!("invalid direct address `{}`: {e}", text.get_ref()),
                        );
                        None
                    }
                }
            };
        // (first byte, end, key offset) of every mapped range per area, for overlaps.
        let mut used: [Vec<(u32, u32, usize)>; 2] = [Vec::new(), Vec::new()];
        let mut inputs = Vec::new();
        let mut outputs = Vec::new();
        let mut mapped = vec![false; ports.len()];
        let online = raw.online.as_ref().and_then(|o| {
            let size = plc_online::MAX_MESSAGE as u32;
            let online = self.online_ports(o, &path.key("online"), ports, size)?;
            mapped[online.request] = true;
            mapped[online.response] = true;
            Some(online)
        });
        let net = raw.net.as_ref().and_then(|n| {
            let net = self.plc_net(n, &path.key("net"), ports)?;
            for name in [&net.link.rx, &net.link.tx] {
                if let Some(i) = ports.iter().position(|p| &p.name == name) {
                    mapped[i] = true;
                }
            }
            Some(net)
        });
        let store = raw.store.as_ref().and_then(|st| {
            let names = [&st.get_ref().request, &st.get_ref().response];
            for name in names {
                if let Some(i) = ports.iter().position(|p| &p.name == name.get_ref()) {
                    mapped[i] = true;
                }
            }
            self.plc_store(st, &path.key("store"), ports)
        });
        let modbus = raw.modbus.as_ref().and_then(|m| {
            if raw.net.is_none() {
                self.error(
                    start(m),
                    &path.key("modbus"),
                    "a Modbus/TCP server needs the PLC's network interface (`plc.net`)",
                );
            }
            self.plc_modbus(m, &path.key("modbus"))
        });
        let online_tcp = raw.online_tcp.as_ref().and_then(|o| {
            if raw.net.is_none() {
                self.error(
                    start(o),
                    &path.key("online_tcp"),
                    "the online protocol on TCP needs the PLC's network interface (`plc.net`)",
                );
            }
            let online = self.plc_online_tcp(o, &path.key("online_tcp"))?;
            if let Some(m) = &modbus
                && m.port == online.port
            {
                self.error(
                    start(o),
                    &path.key("online_tcp").key("port"),
                    format!(
                        "port {} is the Modbus/TCP server's (`plc.modbus.port`)",
                        m.port
                    ),
                );
                return None;
            }
            Some(online)
        });
        let publish = raw.publish.as_ref().and_then(|p| {
            self.needs_net(raw, start(p), &path.key("publish"));
            self.plc_publish(p, &path.key("publish"))
        });
        let subscribe = raw.subscribe.as_ref().and_then(|s| {
            self.needs_net(raw, start(s), &path.key("subscribe"));
            let sub = self.plc_subscribe(s, &path.key("subscribe"))?;
            let taken = [
                modbus.as_ref().map(|m| m.port),
                online_tcp.as_ref().map(|o| o.port),
            ];
            if taken.contains(&Some(sub.port)) {
                self.error(
                    start(s),
                    &path.key("subscribe").key("port"),
                    format!("UDP port {} is also a TCP service's port here; give the subscription its own", sub.port),
                );
            }
            Some(sub)
        });
        // (byte, source offset, port) of every validity bit.
        let mut valid_bits: Vec<(u32, usize, usize)> = Vec::new();
        let links = raw
            .inputs
            .iter()
            .map(|(k, v)| (k, Some(v.get_ref()), None, Direction::In))
            .chain(
                raw.outputs
                    .iter()
                    .map(|(k, v)| (k, None, Some(v.get_ref()), Direction::Out)),
            );
        for (key, input, output, direction) in links {
            let table = if direction == Direction::In {
                "inputs"
            } else {
                "outputs"
            };
            let link_path = path.key(table).key(key.get_ref());
            let Some(port) = ports.iter().position(|p| &p.name == key.get_ref()) else {
                self.error(
                    start(key),
                    &link_path,
                    format!("no port `{}` in this partition's `ports`", key.get_ref()),
                );
                continue;
            };
            let p = &ports[port];
            if p.direction != direction {
                self.error(
                    start(key),
                    &link_path,
                    format!(
                        "port `{}` is an `{}` port: map it under `plc.{}`",
                        p.name,
                        p.direction.name(),
                        if p.direction == Direction::In {
                            "inputs"
                        } else {
                            "outputs"
                        }
                    ),
                );
                continue;
            }
            mapped[port] = true;
            let (at, area) = match (input, output) {
                (Some(i), _) => (&i.at, Area::Input),
                (_, Some(o)) => (&o.at, Area::Output),
                _ => continue,
            };
            let at_path = link_path.key("at");
            let Some(location) = address(self, at, &at_path, area, false) else {
                continue;
            };
            let end = location.byte + p.size;
            if end > MAX_AREA {
                self.error(
                    start(at),
                    &at_path,
                    format!(
                        "the {}-byte message from {} reaches beyond the {MAX_AREA}-byte area",
                        p.size,
                        at.get_ref()
                    ),
                );
                continue;
            }
            let ranges = &mut used[(area == Area::Output) as usize];
            if let Some(&(_, _, other)) = ranges
                .iter()
                .find(|(lo, hi, _)| location.byte < *hi && *lo < end)
            {
                let (line, _) = self.r.line_col(other);
                self.error(
                    start(at),
                    &at_path,
                    format!(
                        "bytes {}..{end} overlap the mapping at line {line}",
                        location.byte
                    ),
                );
            }
            ranges.push((location.byte, end, start(at)));
            let mut valid = None;
            if let Some(i) = input {
                match (&i.valid, p.kind) {
                    (Some(bit), _) => {
                        valid = address(self, bit, &link_path.key("valid"), Area::Input, true).map(|l| (l.byte, l.bit));
                        if let Some((byte, _)) = valid {
                            valid_bits.push((byte, start(bit), port));
                        }
                    }
                    (None, PortKind::Sampling) => self.error(
                        start(key),
                        &link_path,
                        "a sampling input needs `valid`: the %IX bit the runtime sets while the message is fresh (so a stale value is never taken for a fresh one)",
                    ),
                    (None, PortKind::Queuing) => {}
                }
            }
            let link = PlcLink {
                port,
                at: location.byte,
                valid,
            };
            if direction == Direction::In {
                inputs.push(link)
            } else {
                outputs.push(link)
            }
        }
        // Validity bits must not fall into a message's bytes.
        for &(byte, at, port) in &valid_bits {
            if used[0].iter().any(|(lo, hi, _)| (*lo..*hi).contains(&byte)) {
                let message = format!(
                    "the validity bit of `{}` lies inside a mapped message (byte {byte})",
                    ports[port].name
                );
                self.error(
                    at,
                    &path.key("inputs").key(&ports[port].name).key("valid"),
                    message,
                );
            }
        }
        for (port, _) in mapped.iter().enumerate().filter(|(_, m)| !**m) {
            self.error(
                start(plc),
                path,
                format!("port `{}` is not in the process image: map it under `plc.inputs` or `plc.outputs`", ports[port].name),
            );
        }
        let watch = raw.watch.iter().map(|w| w.get_ref().clone()).collect();
        let safe = raw
            .safe
            .iter()
            .map(|(name, value)| {
                let value = match *value.get_ref() {
                    schema::PlcValue::Bool(b) => PlcValue::Bool(b),
                    schema::PlcValue::Int(i) => PlcValue::Int(i),
                    schema::PlcValue::Float(f) => PlcValue::Float(f.to_bits()),
                };
                (name.get_ref().clone(), value)
            })
            .collect();
        let mut deadlines = Vec::new();
        for (task, value) in &raw.deadline {
            let here = path.key("deadline").key(task.get_ref());
            let Some(ns) = self.duration(value, &here) else {
                continue;
            };
            if !(MIN_TASK_DEADLINE..=MAX_MAJOR_FRAME).contains(&ns) {
                self.error(
                    start(value),
                    &here,
                    format!(
                        "a task deadline must lie between {} and {} (it is {})",
                        Duration(MIN_TASK_DEADLINE),
                        Duration(MAX_MAJOR_FRAME),
                        Duration(ns)
                    ),
                );
                continue;
            }
            deadlines.push((task.get_ref().clone(), ns));
        }
        (self.r.diagnostics.len() == before).then_some(Plc {
            program,
            inputs,
            outputs,
            watch,
            online,
            safe,
            deadlines,
            shared: None,
            native: raw.native.as_ref().is_some_and(|n| *n.get_ref()),
            net,
            modbus,
            online_tcp,
            publish,
            subscribe,
            store,
        })
    }

    /// Reports `what` (a PLC network service at `at`) when the PLC has no `plc.net`.
    fn needs_net(&mut self, raw: &schema::Plc, at: usize, path: &KeyPath) {
        if raw.net.is_none() {
            self.error(
                at,
                path,
                "publish/subscribe needs the PLC's network interface (`plc.net`)",
            );
        }
    }

    /// The variable names of a publication or subscription: 1..=16, no name twice.
    fn pubsub_vars(
        &mut self,
        vars: &[Spanned<String>],
        at: usize,
        path: &KeyPath,
    ) -> Option<Vec<String>> {
        let names: Vec<String> = vars.iter().map(|v| v.get_ref().clone()).collect();
        if names.is_empty() || names.len() > PlcSubscribe::MAX_VARS {
            self.error(
                at,
                &path.key("vars"),
                format!(
                    "{} variables: 1..={} (what fits one datagram)",
                    names.len(),
                    PlcSubscribe::MAX_VARS
                ),
            );
            return None;
        }
        for (i, v) in vars.iter().enumerate() {
            if names[..i].contains(v.get_ref()) {
                self.error(
                    start(v),
                    &path.key("vars"),
                    format!("`{}` is named twice", v.get_ref()),
                );
                return None;
            }
        }
        Some(names)
    }

    /// `plc.publish`: `to` an IPv4 address and UDP port, and the variables.
    fn plc_publish(
        &mut self,
        publish: &Spanned<schema::PlcPublish>,
        path: &KeyPath,
    ) -> Option<PlcPublish> {
        let p = publish.get_ref();
        let to = p.to.get_ref().rsplit_once(':').and_then(|(ip, port)| {
            Some((
                parse_ipv4(ip)?,
                port.parse::<u16>().ok().filter(|&p| p != 0)?,
            ))
        });
        if to.is_none() {
            self.error(
                start(&p.to),
                &path.key("to"),
                format!(
                    "`{}` is no IPv4 address and UDP port (e.g. \"10.0.2.16:61499\")",
                    p.to.get_ref()
                ),
            );
        }
        let vars = self.pubsub_vars(&p.vars, start(publish), path);
        Some(PlcPublish {
            to: to?,
            vars: vars?,
        })
    }

    /// `plc.subscribe`: a UDP port, the variables, the validity variable and timeout.
    fn plc_subscribe(
        &mut self,
        subscribe: &Spanned<schema::PlcSubscribe>,
        path: &KeyPath,
    ) -> Option<PlcSubscribe> {
        let s = subscribe.get_ref();
        let port = self.int_in(Some(&s.port), path, "port", 1..=65_535, 0);
        let vars = self.pubsub_vars(&s.vars, start(subscribe), path);
        let timeout = match &s.timeout {
            None => Some(PlcSubscribe::DEFAULT_TIMEOUT_NS),
            Some(v) => {
                let here = path.key("timeout");
                self.duration(v, &here).and_then(|ns| {
                    if (1_000_000..=3_600_000_000_000).contains(&ns) {
                        Some(ns)
                    } else {
                        self.error(
                            start(v),
                            &here,
                            format!(
                                "a subscription times out after 1 ms to 3600 s, not {}",
                                Duration(ns)
                            ),
                        );
                        None
                    }
                })
            }
        };
        let group = match &s.group {
            None => Some(None),
            Some(g) => match parse_ipv4(g.get_ref()).filter(|ip| (224..=239).contains(&ip[0])) {
                Some(ip) => Some(Some(ip)),
                None => {
                    self.error(
                        start(g),
                        &path.key("group"),
                        format!(
                            "`{}` is no IPv4 multicast group (224.0.0.0 to 239.255.255.255, e.g. \"239.0.0.1\")",
                            g.get_ref()
                        ),
                    );
                    None
                }
            },
        };
        Some(PlcSubscribe {
            port: port? as u16,
            group: group?,
            vars: vars?,
            valid: s.valid.as_ref().map(|v| v.get_ref().clone()),
            timeout_ns: timeout?,
        })
    }

    /// `plc.online_tcp`: a TCP port and the clients, each with its key file (hex, read
    /// now) and its access.
    fn plc_online_tcp(
        &mut self,
        online: &Spanned<schema::PlcOnlineTcp>,
        path: &KeyPath,
    ) -> Option<PlcOnlineTcp> {
        let o = online.get_ref();
        let port = self.int_in(
            o.port.as_ref(),
            path,
            "port",
            1..=65_535,
            i64::from(PlcOnlineTcp::DEFAULT_PORT),
        );
        if o.clients.is_empty() || o.clients.len() > PlcOnlineTcp::MAX_CLIENTS {
            self.error(
                start(online),
                &path.key("clients"),
                format!(
                    "{} clients: a PLC serves 1..={} (each `clients.<name> = {{ key = \"FILE\", access = \"monitor\" }}`)",
                    o.clients.len(),
                    PlcOnlineTcp::MAX_CLIENTS
                ),
            );
            return None;
        }
        let base = std::path::Path::new(self.r.file())
            .parent()
            .unwrap_or(std::path::Path::new(""))
            .to_path_buf();
        let mut clients = Vec::new();
        for (name, client) in &o.clients {
            let at = path.key("clients").key(name.get_ref());
            let c = client.get_ref();
            let n = name.get_ref();
            if n.is_empty() || n.len() > 32 || !n.bytes().all(|b| b.is_ascii_graphic()) {
                self.error(
                    start(name),
                    &at,
                    format!(
                        "client name {n:?}: 1..=32 printable ASCII characters without spaces (it is sent in the handshake and logged)"
                    ),
                );
                continue;
            }
            let access = plc_online::Access::from_name(c.access.get_ref());
            if access.is_none() {
                self.error(
                    start(&c.access),
                    &at.key("access"),
                    format!(
                        "unknown access {:?}: expected \"monitor\", \"force\" or \"download\"",
                        c.access.get_ref()
                    ),
                );
            }
            let file = base.join(c.key.get_ref());
            let key = match std::fs::read_to_string(&file) {
                Ok(text) => parse_key(&text),
                Err(e) => Err(format!("cannot be read ({e})")),
            };
            let key = match key {
                Ok(key) => Some(key),
                Err(why) => {
                    self.error(
                        start(&c.key),
                        &at.key("key"),
                        format!(
                            "key file `{}` ({}) {why}; a key file holds 16..=64 bytes as hex text, e.g. from `head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \\n'`",
                            c.key.get_ref(),
                            file.display()
                        ),
                    );
                    None
                }
            };
            if let (Some(key), Some(access)) = (key, access) {
                clients.push(OnlineClient {
                    name: n.clone(),
                    key,
                    access,
                });
            }
        }
        (clients.len() == o.clients.len()).then_some(PlcOnlineTcp {
            port: port? as u16,
            clients,
        })
    }

    /// `plc.store`: the request and response ports to the block-device partition and the
    /// RETAIN interval.
    fn plc_store(
        &mut self,
        store: &Spanned<schema::PlcStore>,
        path: &KeyPath,
        ports: &[Port],
    ) -> Option<PlcStore> {
        let st = store.get_ref();
        let (request, response) = self.blk_link_ports(&st.request, &st.response, path, ports);
        let every = match &st.retain_every {
            None => Some(PlcStore::DEFAULT_RETAIN_EVERY_NS),
            Some(v) => {
                let here = path.key("retain_every");
                self.duration(v, &here).and_then(|ns| {
                    let range = PlcStore::MIN_RETAIN_EVERY_NS..=PlcStore::MAX_RETAIN_EVERY_NS;
                    if range.contains(&ns) {
                        Some(ns)
                    } else {
                        self.error(
                            start(v),
                            &here,
                            format!(
                                "RETAIN is saved every {} to {} (a save takes several windows of the block-device partition), not every {}",
                                Duration(*range.start()),
                                Duration(*range.end()),
                                Duration(ns)
                            ),
                        );
                        None
                    }
                })
            }
        };
        Some(PlcStore {
            request: request?,
            response: response?,
            retain_every_ns: every?,
        })
    }

    /// The two queuing ports of a tenant's link to a block-device partition (`plc.store`,
    /// `guest.disk`): `request` an output of at least `blk_core::link::MAX_REQUEST`
    /// bytes, `response` an input of at least `MAX_RESPONSE`; their indices.
    fn blk_link_ports(
        &mut self,
        request: &Spanned<String>,
        response: &Spanned<String>,
        path: &KeyPath,
        ports: &[Port],
    ) -> (Option<usize>, Option<usize>) {
        let mut port = |key: &str, name: &Spanned<String>, direction: Direction, size: usize| {
            let found = ports.iter().position(|p| {
                &p.name == name.get_ref()
                    && p.kind == PortKind::Queuing
                    && p.direction == direction
                    && p.size >= size as u32
            });
            if found.is_none() {
                self.error(
                    start(name),
                    &path.key(key),
                    format!(
                        "`{}` must be a queuing `{}` port of this partition with size >= {size} (the largest {} of the block-device link)",
                        name.get_ref(),
                        direction.name(),
                        if direction == Direction::Out { "request" } else { "response" }
                    ),
                );
            }
            found
        };
        let request = port(
            "request",
            request,
            Direction::Out,
            blk_core::link::MAX_REQUEST,
        );
        let response = port(
            "response",
            response,
            Direction::In,
            blk_core::link::MAX_RESPONSE,
        );
        (request, response)
    }

    /// `guest.disk`: the request and response ports of `/dev/vda`'s link (the virtual
    /// disk itself is checked by [`Validator::guest_disks`]).
    fn guest_disk(
        &mut self,
        disk: &Spanned<schema::GuestDisk>,
        path: &KeyPath,
        ports: &[Port],
    ) -> Option<GuestDisk> {
        let d = disk.get_ref();
        let (request, response) = self.blk_link_ports(&d.request, &d.response, path, ports);
        request?;
        response?;
        Some(GuestDisk {
            request: d.request.get_ref().clone(),
            response: d.response.get_ref().clone(),
            // Its tenant's, once the tenants are known (`guest_disks`).
            sectors: 0,
        })
    }

    /// A guest with `guest.disk` must have a virtual disk: be a tenant of a block-device
    /// partition (`blk.tenants`) whose `from` port is fed by the guest's `request` port
    /// and whose `to` port feeds its `response` port. Gives `guest.disk` the tenant's size.
    fn guest_disks(
        &mut self,
        doc: &schema::Document,
        partitions: &mut [Partition],
        channels: &[Channel],
    ) {
        let base = KeyPath::root().key("partitions");
        for (key, raw) in in_source_order(&doc.partitions) {
            let Some(disk) = raw
                .get_ref()
                .guest
                .as_ref()
                .and_then(|g| g.get_ref().disk.as_ref())
            else {
                continue;
            };
            let Some(me) = partitions.iter().position(|p| &p.name == key.get_ref()) else {
                continue;
            };
            let at = base.key(key.get_ref()).key("guest").key("disk");
            let Some((driver, tenant)) = partitions.iter().enumerate().find_map(|(i, p)| {
                let t = p.blk.as_ref()?.tenants.iter().find(|t| t.partition == me)?;
                Some((i, *t))
            }) else {
                self.error(
                    start(disk),
                    &at,
                    format!(
                        "partition `{}` has no virtual disk: give it one in a block-device partition's `blk.tenants.{}`",
                        key.get_ref(),
                        key.get_ref()
                    ),
                );
                continue;
            };
            // (Ports the port check refused have no index here: reported already.)
            let own = &partitions[me].ports;
            let d = disk.get_ref();
            let drv = &partitions[driver];
            for (port_key, name, theirs, to_driver) in [
                ("request", &d.request, tenant.from, true),
                ("response", &d.response, tenant.to, false),
            ] {
                let direction = if to_driver {
                    Direction::Out
                } else {
                    Direction::In
                };
                let Some(mine) = own
                    .iter()
                    .position(|p| &p.name == name.get_ref() && p.direction == direction)
                else {
                    continue;
                };
                let Some(channel) = channels.get(drv.ports[theirs].channel) else {
                    continue;
                };
                let joined = if to_driver {
                    channel.source
                        == PortRef {
                            partition: me,
                            port: mine,
                        }
                } else {
                    channel.destinations.contains(&PortRef {
                        partition: me,
                        port: mine,
                    })
                };
                if !joined {
                    let (way, what) = if to_driver {
                        ("feed", "from")
                    } else {
                        ("be fed by", "to")
                    };
                    self.error(
                        start(name),
                        &at.key(port_key),
                        format!(
                            "`{}` must {way} port `{}.{}`, the `{what}` port of this guest's virtual disk (`blk.tenants.{}`), through a channel",
                            name.get_ref(),
                            drv.name,
                            drv.ports[theirs].name,
                            key.get_ref()
                        ),
                    );
                }
            }
            if let Some(d) = partitions[me].guest.as_mut().and_then(|g| g.disk.as_mut()) {
                d.sectors = tenant.sectors;
            }
        }
    }

    /// A PLC with `plc.store` must have a virtual disk: be a tenant of a block-device
    /// partition (`blk.tenants`).
    fn plc_stores(&mut self, doc: &schema::Document, partitions: &[Partition]) {
        let base = KeyPath::root().key("partitions");
        for (key, raw) in in_source_order(&doc.partitions) {
            let Some(store) = raw
                .get_ref()
                .plc
                .as_ref()
                .and_then(|p| p.get_ref().store.as_ref())
            else {
                continue;
            };
            let Some(me) = partitions.iter().position(|p| &p.name == key.get_ref()) else {
                continue;
            };
            let tenant = partitions
                .iter()
                .filter_map(|p| p.blk.as_ref())
                .any(|b| b.tenants.iter().any(|t| t.partition == me));
            if !tenant {
                self.error(
                    start(store),
                    &base.key(key.get_ref()).key("plc").key("store"),
                    format!(
                        "partition `{}` has no virtual disk: give it one in a block-device partition's `blk.tenants.{}`",
                        key.get_ref(),
                        key.get_ref()
                    ),
                );
            }
        }
    }

    /// An optional integer of `range` at `key` of `path` (`default` when absent).
    fn int_in(
        &mut self,
        value: Option<&Spanned<i64>>,
        path: &KeyPath,
        key: &str,
        range: core::ops::RangeInclusive<i64>,
        default: i64,
    ) -> Option<i64> {
        let Some(v) = value else {
            return Some(default);
        };
        if range.contains(v.get_ref()) {
            return Some(*v.get_ref());
        }
        self.error(
            start(v),
            &path.key(key),
            format!(
                "{} is outside {}..={}",
                v.get_ref(),
                range.start(),
                range.end()
            ),
        );
        None
    }

    /// `plc.net`: the link as `guest.net` checks it, and the communication limits.
    fn plc_net(
        &mut self,
        net: &Spanned<schema::PlcNet>,
        path: &KeyPath,
        ports: &[Port],
    ) -> Option<PlcNet> {
        let n = net.get_ref();
        let link = self.guest_net(&Spanned::new(net.span(), link_fields!(n)), path, ports);
        let connections = self.int_in(
            n.connections.as_ref(),
            path,
            "connections",
            1..=i64::from(PlcNet::MAX_CONNECTIONS),
            i64::from(PlcNet::DEFAULT_CONNECTIONS),
        );
        let buffer = self.int_in(
            n.buffer.as_ref(),
            path,
            "buffer",
            512..=65_536,
            i64::from(PlcNet::DEFAULT_BUFFER),
        );
        let rate = self.int_in(
            n.requests_per_second.as_ref(),
            path,
            "requests_per_second",
            1..=100_000,
            i64::from(PlcNet::DEFAULT_REQUESTS_PER_SECOND),
        );
        Some(PlcNet {
            link: link?,
            connections: connections? as u8,
            buffer: buffer? as u32,
            requests_per_second: rate? as u32,
        })
    }

    /// `plc.modbus`: a TCP port, a unit id and the writable areas.
    fn plc_modbus(
        &mut self,
        modbus: &Spanned<schema::PlcModbus>,
        path: &KeyPath,
    ) -> Option<PlcModbus> {
        let m = modbus.get_ref();
        let port = self.int_in(m.port.as_ref(), path, "port", 1..=65_535, 502);
        let unit = self.int_in(m.unit.as_ref(), path, "unit", 0..=255, 1);
        let (mut write_outputs, mut write_markers) = (false, false);
        let mut ok = true;
        for w in &m.writable {
            match w.get_ref().as_str() {
                "outputs" => write_outputs = true,
                "markers" => write_markers = true,
                other => {
                    ok = false;
                    self.error(
                        start(w),
                        &path.key("writable"),
                        format!(
                            "`{other}` is no writable area: \"outputs\" (%QX, %QW) or \"markers\" (%MX, %MW)"
                        ),
                    );
                }
            }
        }
        Some(PlcModbus {
            port: port? as u16,
            unit: unit? as u8,
            write_outputs,
            write_markers,
        })
        .filter(|_| ok)
    }

    /// `plc.shared`: a segment the partition maps read-write, named by at most two PLC
    /// partitions (the two projects whose shared globals meet there).
    fn plc_shared(
        &mut self,
        plc: &Spanned<schema::Plc>,
        path: &KeyPath,
        attachments: &[Attachment],
        segments: &[(Segment, usize)],
        earlier: &[Partition],
    ) -> Option<usize> {
        let name = plc.get_ref().shared.as_ref()?;
        let here = path.key("shared");
        let index = self.segment_named(name, &here, segments)?;
        let writable = attachments
            .iter()
            .any(|a| a.segment == index && a.rights == Rights::ReadWrite);
        if !writable {
            self.error(
                start(name),
                &here,
                format!(
                    "the partition must map segment `{0}` read-write to share globals through it: add `shared = {{ {0} = \"rw\" }}`",
                    name.get_ref()
                ),
            );
            return None;
        }
        let others: Vec<&str> = earlier
            .iter()
            .filter(|p| p.plc.as_ref().is_some_and(|plc| plc.shared == Some(index)))
            .map(|p| p.name.as_str())
            .collect();
        if others.len() >= 2 {
            self.error(
                start(name),
                &here,
                format!(
                    "segment `{}` already links the shared globals of {} and {}: two PLC projects share one segment",
                    name.get_ref(),
                    others[0],
                    others[1]
                ),
            );
            return None;
        }
        Some(index)
    }

    /// `plc.online` and `iec61499.mgmt`: a queuing input for requests and a queuing output
    /// for responses, both of the protocol's message `size`, and the access level.
    fn online_ports(
        &mut self,
        raw: &Spanned<schema::OnlinePorts>,
        path: &KeyPath,
        ports: &[Port],
        size: u32,
    ) -> Option<OnlinePorts> {
        let raw = raw.get_ref();
        let port = |v: &mut Self, key: &str, name: &Spanned<String>, direction: Direction| {
            let found = ports.iter().position(|p| &p.name == name.get_ref());
            let ok = found.is_some_and(|i| {
                let p = &ports[i];
                p.kind == PortKind::Queuing && p.direction == direction && p.size == size
            });
            if !ok {
                v.error(
                    start(name),
                    &path.key(key),
                    format!(
                        "`{}` must be a queuing `{}` port of this partition with size = {size} (one message of the protocol)",
                        name.get_ref(),
                        direction.name()
                    ),
                );
            }
            found.filter(|_| ok)
        };
        let request = port(self, "request", &raw.request, Direction::In);
        let response = port(self, "response", &raw.response, Direction::Out);
        let access = plc_online::Access::from_name(raw.access.get_ref());
        if access.is_none() {
            self.error(
                start(&raw.access),
                &path.key("access"),
                format!(
                    "unknown access {:?}: expected \"monitor\", \"force\" or \"download\" (what each allows: the \"PLC\" and \"IEC 61499\" sections of the format)",
                    raw.access.get_ref()
                ),
            );
        }
        Some(OnlinePorts {
            request: request?,
            response: response?,
            access: access?,
        })
    }

    /// A partition's memory, kernel memory and stack (0 where invalid, after the error).
    fn partition_memory(
        &mut self,
        raw: &schema::Partition,
        path: &KeyPath,
    ) -> (Option<u64>, u64, u64) {
        let memory = self.page_size(&raw.memory, &path.key("memory"));
        let kernel_memory = self
            .page_size(&raw.kernel_memory, &path.key("kernel_memory"))
            .unwrap_or(0);
        let stack_path = path.key("stack");
        let stack = match &raw.stack {
            Some(s) => self.page_size(s, &stack_path),
            None => Some(DEFAULT_STACK),
        };
        if let (Some(stack), Some(memory)) = (stack, memory)
            && stack > memory
        {
            let (at, at_path) = match &raw.stack {
                Some(s) => (start(s), stack_path),
                None => (start(&raw.memory), path.key("memory")),
            };
            self.error(
                at,
                &at_path,
                format!(
                    "the stack of {} does not fit in the partition's memory of {}",
                    Size(stack),
                    Size(memory)
                ),
            );
        }
        let stack = stack.unwrap_or(0);
        (memory, kernel_memory, stack)
    }

    /// A partition's MCP and first thread's priority.
    fn priorities(&mut self, raw: &schema::Partition, path: &KeyPath) -> (u8, u8) {
        let mcp_value = *raw.max_priority.get_ref();
        let mcp = if (i64::from(MCP_MIN)..=i64::from(MCP_MAX)).contains(&mcp_value) {
            mcp_value as u8
        } else {
            self.error(
                start(&raw.max_priority),
                &path.key("max_priority"),
                format!(
                    "max_priority (MCP) {mcp_value} is not in {MCP_MIN}..={MCP_MAX}: partition threads must stay below syssw's priority {SYSSW_PRIORITY}"
                ),
            );
            MCP_MAX
        };
        let priority = match &raw.priority {
            Some(p) => {
                let value = *p.get_ref();
                if (0..=i64::from(mcp)).contains(&value) {
                    value as u8
                } else {
                    self.error(
                        start(p),
                        &path.key("priority"),
                        format!(
                            "priority {value} is not in 0..={mcp} (it may not exceed max_priority)"
                        ),
                    );
                    mcp
                }
            }
            None => mcp,
        };
        (mcp, priority)
    }

    /// A partition's I/O port ranges: not the kernel's, not another partition's (`io_seen`:
    /// every range so far with its partition and position).
    fn io_ports(
        &mut self,
        doc: &schema::Document,
        raw: &schema::Partition,
        path: &KeyPath,
        index: usize,
        io_seen: &mut Vec<(IoRange, usize, usize)>,
    ) -> Vec<IoRange> {
        let mut io_ports = Vec::new();
        for (i, entry) in raw.io_ports.iter().enumerate() {
            let here = path.key("io_ports").index(i);
            let Some(range) = self.io_range(entry, &here) else {
                continue;
            };
            if let Some(kernel) = range.kernel_conflict() {
                self.error(
                    start(entry),
                    &here,
                    format!(
                        "I/O ports {range} include {kernel}, which the kernel keeps for {}",
                        kernel_port_use(kernel)
                    ),
                );
                continue;
            }
            if let Some(&(other, owner, at)) = io_seen.iter().find(|(r, _, _)| r.overlaps(range)) {
                let line = self.r.line_of(at);
                let whose = holder(doc, owner, index);
                self.error(
                    start(entry),
                    &here,
                    format!("I/O ports {range} overlap {other}, {whose} at line {line}"),
                );
                continue;
            }
            if io_seen.len() == MAX_IO_RANGES {
                self.error(
                    start(entry),
                    &here,
                    format!("too many I/O port ranges (at most {MAX_IO_RANGES} in a system)"),
                );
                continue;
            }
            io_seen.push((range, index, start(entry)));
            io_ports.push(range);
        }
        io_ports
    }

    /// A partition's interrupt lines: ISA lines the kernel does not keep, not another
    /// partition's (`irq_seen`), and only with the `irq` ability.
    fn irqs(
        &mut self,
        doc: &schema::Document,
        raw: &schema::Partition,
        path: &KeyPath,
        index: usize,
        irq_seen: &mut Vec<(u8, usize, usize)>,
        abilities: Abilities,
    ) -> IrqMask {
        let mut irqs = IrqMask::default();
        for (i, entry) in raw.irqs.iter().enumerate() {
            let here = path.key("irqs").index(i);
            let line_no = *entry.get_ref();
            if !(0..i64::from(IRQ_LINES)).contains(&line_no) {
                self.error(
                    start(entry),
                    &here,
                    format!(
                        "IRQ {line_no} is not an ISA interrupt line (0..={})",
                        IRQ_LINES - 1
                    ),
                );
                continue;
            }
            let line_no = line_no as u8;
            if !irq_allowed(line_no) {
                self.error(
                    start(entry),
                    &here,
                    format!(
                        "IRQ {line_no} is reserved for {}",
                        reserved_irq_use(line_no)
                    ),
                );
                continue;
            }
            if let Some(&(_, owner, at)) = irq_seen.iter().find(|(l, _, _)| *l == line_no) {
                let line = self.r.line_of(at);
                let whose = holder(doc, owner, index);
                self.error(
                    start(entry),
                    &here,
                    format!("IRQ {line_no} is {whose} at line {line}"),
                );
                continue;
            }
            irq_seen.push((line_no, index, start(entry)));
            irqs.0 |= 1 << line_no;
        }

        if irqs.0 != 0 && !abilities.contains(Abilities::IRQ) {
            let first = &raw.irqs[0];
            self.error(
                start(first),
                &path.key("irqs"),
                "IRQ lines are listed but the partition lacks the `irq` ability it needs to attach them (add \"irq\" to `abilities`)",
            );
        }
        irqs
    }

    /// A partition's PCI functions (`devices`): well-formed bus addresses, none named twice
    /// in the system, at most [`pci::MAX_PARTITION_DEVICES`], and the `irq` ability to
    /// attach their interrupts. Whether each exists is known only at boot (syssw).
    fn devices(
        &mut self,
        doc: &schema::Document,
        raw: &schema::Partition,
        path: &KeyPath,
        index: usize,
        seen: &mut Vec<(pci::Address, usize, usize)>,
        abilities: Abilities,
    ) -> Vec<pci::Address> {
        let mut devices = Vec::new();
        for (i, entry) in raw.devices.iter().enumerate() {
            let here = path.key("devices").index(i);
            let text = entry.get_ref();
            let address = match pci::Address::parse(text) {
                Ok(a) => a,
                Err(e) => {
                    self.error(
                        start(entry),
                        &here,
                        format!("`{text}` is not a PCI bus address: {e}"),
                    );
                    continue;
                }
            };
            if let Some(&(_, owner, at)) = seen.iter().find(|(d, _, _)| *d == address) {
                let line = self.r.line_of(at);
                let whose = holder(doc, owner, index);
                self.error(
                    start(entry),
                    &here,
                    format!("PCI device {address} is named twice: it is {whose} at line {line}"),
                );
                continue;
            }
            if devices.len() == pci::MAX_PARTITION_DEVICES {
                self.error(
                    start(entry),
                    &here,
                    format!(
                        "too many PCI devices (at most {} a partition)",
                        pci::MAX_PARTITION_DEVICES
                    ),
                );
                continue;
            }
            seen.push((address, index, start(entry)));
            devices.push(address);
        }
        if !devices.is_empty() && !abilities.contains(Abilities::IRQ) {
            self.error(
                start(&raw.devices[0]),
                &path.key("devices"),
                "PCI devices are listed but the partition lacks the `irq` ability it needs to attach their interrupts (add \"irq\" to `abilities`)",
            );
        }
        devices
    }

    /// A partition's DMA region (`dma`, bytes; 0: none) and `dma_unconfined`: whole pages,
    /// only for a partition that owns PCI devices, within its memory beside the stack;
    /// `dma_unconfined` only with a region, and a warning (its devices' DMA is then
    /// confined by nothing when the machine has no IOMMU).
    fn dma(
        &mut self,
        raw: &schema::Partition,
        path: &KeyPath,
        memory: Option<u64>,
        stack: u64,
        devices: &[pci::Address],
    ) -> (u64, bool) {
        let dma_path = path.key("dma");
        let dma = match &raw.dma {
            None => 0,
            Some(value) => {
                let bytes = self.page_size(value, &dma_path).unwrap_or(0);
                if raw.devices.is_empty() {
                    self.error(
                        start(value),
                        &dma_path,
                        "a DMA region is for the partition's PCI devices, but it owns none (add `devices` or remove `dma`)",
                    );
                }
                if let Some(memory) = memory
                    && bytes > 0
                    && bytes.saturating_add(stack) > memory
                {
                    self.error(
                        start(value),
                        &dma_path,
                        format!(
                            "the DMA region of {} and the stack of {} do not fit in the partition's memory of {} (the region is part of `memory`)",
                            Size(bytes),
                            Size(stack),
                            Size(memory)
                        ),
                    );
                }
                bytes
            }
        };
        let unconfined_path = path.key("dma_unconfined");
        let unconfined = match &raw.dma_unconfined {
            Some(flag) if *flag.get_ref() => {
                if raw.dma.is_none() {
                    self.error(
                        start(flag),
                        &unconfined_path,
                        "dma_unconfined = true without a DMA region: give the partition `dma` (the size of the memory its devices may reach)",
                    );
                } else if !devices.is_empty() {
                    self.r.warning(
                        start(flag),
                        &unconfined_path,
                        "dma_unconfined = true: on a machine without an IOMMU the partition's devices start with bus mastering on and nothing confines their DMA to its DMA region",
                    );
                }
                true
            }
            _ => false,
        };
        (dma, unconfined)
    }

    /// The index of the segment `name` names, or an error at `path`.
    pub(super) fn segment_named(
        &mut self,
        name: &Spanned<String>,
        path: &KeyPath,
        segments: &[(Segment, usize)],
    ) -> Option<usize> {
        let found = segments.iter().position(|(s, _)| s.name == *name.get_ref());
        if found.is_none() {
            self.error(
                start(name),
                path,
                format!(
                    "unknown shared memory segment `{}` (define it in [[shared_memory]])",
                    name.get_ref()
                ),
            );
        }
        found
    }

    /// A partition's shared-memory attachments (`attachment_total` counts the system's).
    fn attachments(
        &mut self,
        raw: &schema::Partition,
        path: &KeyPath,
        segments: &[(Segment, usize)],
        attachment_total: &mut usize,
    ) -> Vec<Attachment> {
        let mut shared = Vec::new();
        for (segment, rights) in in_source_order(&raw.shared) {
            let here = path.key("shared").key(segment.get_ref());
            let found = self.segment_named(segment, &here, segments);
            let r = Rights::from_name(rights.get_ref());
            if r.is_none() {
                let why = if matches!(rights.get_ref().as_str(), "rwx" | "wx" | "xw") {
                    " (writable and executable at once is never allowed)"
                } else {
                    ""
                };
                self.error(
                    start(rights),
                    &here,
                    format!(
                        "rights {:?} are not \"r\", \"rw\" or \"rx\"{why}",
                        rights.get_ref()
                    ),
                );
            }
            if let (Some(index), Some(rights)) = (found, r) {
                *attachment_total += 1;
                if *attachment_total > MAX_ATTACHMENTS {
                    self.error(
                        start(segment),
                        &here,
                        format!(
                            "too many shared memory attachments (at most {MAX_ATTACHMENTS} in a system)"
                        ),
                    );
                }
                shared.push(Attachment {
                    segment: index,
                    rights,
                });
            }
        }
        shared
    }

    /// A partition's ports; each is also recorded in `ports` (every port of the system) for
    /// the channel checks.
    fn partition_ports(
        &mut self,
        raw: &schema::Partition,
        path: &KeyPath,
        index: usize,
        ports: &mut Vec<PortDecl>,
    ) -> Vec<Port> {
        let mut own_ports = Vec::new();
        for (port_key, port) in in_source_order(&raw.ports) {
            let here = path.key("ports").key(port_key.get_ref());
            self.name(port_key, &here, NAME_MAX, "port");
            if ports.len() == MAX_PORTS {
                self.error(
                    start(port_key),
                    &here,
                    format!("too many ports (at most {MAX_PORTS} in a system)"),
                );
            }
            let (p, valid) = self.port(port, port_key, &here);
            ports.push(PortDecl {
                partition: index,
                port: own_ports.len(),
                key_at: start(port_key),
                path: here,
                used_by: None,
                valid,
            });
            own_ports.push(p);
        }
        own_ports
    }

    fn quota(
        &mut self,
        value: Option<&Spanned<i64>>,
        path: &KeyPath,
        default: u32,
        max: u32,
        what: &str,
    ) -> u32 {
        let Some(value) = value else {
            return default;
        };
        let n = *value.get_ref();
        if (1..=i64::from(max)).contains(&n) {
            n as u32
        } else {
            self.error(
                start(value),
                path,
                format!("kernel {what} quota {n} is not in 1..={max}"),
            );
            default
        }
    }

    fn abilities(&mut self, raw: &schema::Partition, path: &KeyPath) -> Abilities {
        let mut abilities = Abilities::empty();
        let native = raw.native_syscalls.as_ref().is_none_or(|n| *n.get_ref());
        if native {
            abilities |= Abilities::NATIVE_SYSCALLS;
        }
        for (i, name) in raw.abilities.iter().enumerate() {
            let here = path.key("abilities").index(i);
            let Some(ability) = ability_by_name(name.get_ref()) else {
                self.error(
                    start(name),
                    &here,
                    format!(
                        "unknown ability `{}`; partitions may have: {}",
                        name.get_ref(),
                        ABILITY_NAMES
                            .iter()
                            .filter(|(_, a)| PARTITION_ABILITIES.contains(*a))
                            .map(|(n, _)| *n)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                );
                continue;
            };
            if !PARTITION_ABILITIES.contains(ability) {
                self.error(
                    start(name),
                    &here,
                    format!(
                        "ability `{}` is reserved for the system software (with it a partition could break the others' isolation)",
                        name.get_ref()
                    ),
                );
                continue;
            }
            if ability == Abilities::NATIVE_SYSCALLS && !native {
                self.error(
                    start(name),
                    &here,
                    "`native_syscalls` is listed but `native_syscalls = false` is set",
                );
                continue;
            }
            abilities |= ability;
        }
        abilities
    }

    fn time(&mut self, raw: &schema::Partition, path: &KeyPath) -> Time {
        let Some(time) = &raw.time else {
            return Time::Auto;
        };
        let here = path.key("time");
        match time.get_ref() {
            Scalar::Str(s) if s == "background" => Time::Background,
            Scalar::Int(n) if (1..i64::from(TIME_PARTITIONS)).contains(n) => {
                Time::Explicit(*n as u8, start(time))
            }
            Scalar::Int(0) => {
                self.error(
                    start(time),
                    &here,
                    "time partition 0 is the background: write `time = \"background\"`",
                );
                Time::Invalid
            }
            other => {
                let shown = match other {
                    Scalar::Int(n) => n.to_string(),
                    Scalar::Str(s) => format!("{s:?}"),
                };
                self.error(
                    start(time),
                    &here,
                    format!(
                        "time = {shown} is neither \"background\" nor a time partition number 1..={}",
                        TIME_PARTITIONS - 1
                    ),
                );
                Time::Invalid
            }
        }
    }

    fn io_range(&mut self, entry: &Spanned<Scalar>, path: &KeyPath) -> Option<IoRange> {
        fn port(text: &str) -> Option<u16> {
            let text = text.trim();
            match text.strip_prefix("0x").or_else(|| text.strip_prefix("0X")) {
                Some(hex) => u16::from_str_radix(hex, 16).ok(),
                None => text.parse().ok(),
            }
        }
        let range = match entry.get_ref() {
            Scalar::Int(n) => u16::try_from(*n)
                .ok()
                .map(|p| IoRange { first: p, last: p }),
            Scalar::Str(s) => match s.split_once('-') {
                Some((a, b)) => port(a)
                    .zip(port(b))
                    .map(|(first, last)| IoRange { first, last }),
                None => port(s).map(|p| IoRange { first: p, last: p }),
            },
        };
        let shown = match entry.get_ref() {
            Scalar::Int(n) => n.to_string(),
            Scalar::Str(s) => format!("{s:?}"),
        };
        match range {
            None => {
                self.error(
                    start(entry),
                    path,
                    format!(
                        "invalid I/O port range {shown}: expected a port 0..=0xffff or a range like \"0x2f8-0x2ff\""
                    ),
                );
                None
            }
            Some(r) if r.first > r.last => {
                self.error(
                    start(entry),
                    path,
                    format!("invalid I/O port range {shown}: the first port is above the last"),
                );
                None
            }
            r => r,
        }
    }

    /// The `kind` of a port or channel (`what`): "sampling" or "queuing".
    fn port_kind(
        &mut self,
        kind: &Spanned<String>,
        path: &KeyPath,
        what: &str,
    ) -> Option<PortKind> {
        let parsed = PortKind::from_name(kind.get_ref());
        if parsed.is_none() {
            self.error(
                start(kind),
                &path.key("kind"),
                format!(
                    "unknown {what} kind {:?}: expected \"sampling\" or \"queuing\"",
                    kind.get_ref()
                ),
            );
        }
        parsed
    }

    fn port(
        &mut self,
        port: &Spanned<schema::Port>,
        key: &Spanned<String>,
        path: &KeyPath,
    ) -> (Port, bool) {
        let raw = port.get_ref();
        let kind = self.port_kind(&raw.kind, path, "port");
        let direction = Direction::from_name(raw.direction.get_ref());
        if direction.is_none() {
            self.error(
                start(&raw.direction),
                &path.key("direction"),
                format!(
                    "unknown port direction {:?}: expected \"in\" or \"out\"",
                    raw.direction.get_ref()
                ),
            );
        }
        let size_path = path.key("size");
        let size = self.size(&raw.size, &size_path).and_then(|s| {
            if (1..=u64::from(MAX_MESSAGE_SIZE)).contains(&s) {
                Some(s as u32)
            } else {
                self.error(
                    start(&raw.size),
                    &size_path,
                    format!(
                        "message size {} is not in 1..={MAX_MESSAGE_SIZE} bytes (64 KiB)",
                        s
                    ),
                );
                None
            }
        });
        let depth = match (kind, &raw.depth) {
            (None, _) => None,
            (Some(PortKind::Queuing), Some(d)) => {
                let n = *d.get_ref();
                if (1..=i64::from(MAX_QUEUE_DEPTH)).contains(&n) {
                    Some(n as u32)
                } else {
                    self.error(
                        start(d),
                        &path.key("depth"),
                        format!("queue depth {n} is not in 1..={MAX_QUEUE_DEPTH}"),
                    );
                    None
                }
            }
            (Some(PortKind::Queuing), None) => {
                self.error(
                    start(port),
                    path,
                    "a queuing port needs a `depth` (messages it holds)",
                );
                None
            }
            (_, Some(d)) => {
                self.error(
                    start(d),
                    &path.key("depth"),
                    "`depth` is only for queuing ports",
                );
                None
            }
            (_, None) => Some(0),
        };
        let refresh = match &raw.refresh {
            None => Some(0),
            Some(r) => {
                let here = path.key("refresh");
                if (kind, direction) != (Some(PortKind::Sampling), Some(Direction::In)) {
                    if kind.is_some() && direction.is_some() {
                        self.error(
                            start(r),
                            &here,
                            "`refresh` is only for sampling input ports (kind = \"sampling\", direction = \"in\")",
                        );
                    }
                    None
                } else {
                    match self.duration(r, &here) {
                        Some(0) => {
                            self.error(start(r), &here, "a refresh period must be longer than 0");
                            None
                        }
                        other => other,
                    }
                }
            }
        };
        let discipline = match (&raw.discipline, kind) {
            (None, _) => Some(Discipline::Fifo),
            (Some(d), Some(PortKind::Queuing)) => {
                let parsed = Discipline::from_name(d.get_ref());
                if parsed.is_none() {
                    self.error(
                        start(d),
                        &path.key("discipline"),
                        format!(
                            "unknown queuing discipline {:?}: expected \"fifo\" or \"priority\"",
                            d.get_ref()
                        ),
                    );
                }
                parsed
            }
            (Some(_), None) => None,
            (Some(d), Some(PortKind::Sampling)) => {
                self.error(
                    start(d),
                    &path.key("discipline"),
                    "`discipline` is only for queuing ports",
                );
                None
            }
        };
        let valid = kind.is_some()
            && direction.is_some()
            && size.is_some()
            && depth.is_some()
            && refresh.is_some()
            && discipline.is_some();
        let port = Port {
            name: key.get_ref().clone(),
            kind: kind.unwrap_or(PortKind::Sampling),
            direction: direction.unwrap_or(Direction::In),
            size: size.unwrap_or(0),
            depth: depth.unwrap_or(0),
            refresh: refresh.unwrap_or(0),
            discipline: discipline.unwrap_or(Discipline::Fifo),
            channel: usize::MAX,
        };
        (port, valid)
    }

    fn schedules(
        &mut self,
        doc: &schema::Document,
        partitions: &mut [Partition],
        times: &[Time],
    ) -> Vec<Schedule> {
        let entries = self.schedule_entries(doc);
        let mut schedules = Vec::new();
        let mut window_owners: Vec<Vec<usize>> = Vec::new();
        let mut names: Vec<(String, usize)> = Vec::new();
        // Partitions some window names (even a window with other errors), with the CPUs of
        // their windows.
        let mut named = vec![None; partitions.len()];
        let entries = self.at_most(
            entries,
            MAX_SCHEDULES,
            "schedules",
            ", the kernel's schedule slots",
        );
        for Entry {
            index: i,
            path,
            item: schedule,
            ..
        } in &entries
        {
            let (i, schedule) = (*i, *schedule);
            let raw = schedule.get_ref();
            let name = self.schedule_name(i, path, schedule, &mut names);
            let mut windows = self.schedule_windows(path, raw, partitions, times, &mut named);
            let major_frame = self.major_frame(path, schedule, &windows);
            if let Some(frame) = major_frame {
                self.keep_windows_in_frame(path, raw, frame, &mut windows);
            }
            windows.sort_by_key(|w| (w.offset, w.source));
            self.window_overlaps(path, raw, &windows);
            window_owners.push(windows.iter().map(|w| w.partition).collect());
            let change_actions = self.change_actions(path, raw, partitions);
            schedules.push(Schedule {
                name,
                major_frame: major_frame.unwrap_or(0),
                windows: windows
                    .iter()
                    .map(|w| Window {
                        offset: w.offset,
                        duration: w.duration,
                        time_partition: 0,
                        cpu: w.cpu,
                    })
                    .collect(),
                change_actions,
            });
        }

        self.assign_time_partitions(doc, partitions, times, &named);
        for (schedule, owners) in schedules.iter_mut().zip(&window_owners) {
            for (window, &owner) in schedule.windows.iter_mut().zip(owners) {
                window.time_partition = partitions[owner].time_partition;
            }
        }
        schedules
    }

    /// A schedule's `change_actions`: partition name -> ARINC schedule change action.
    fn change_actions(
        &mut self,
        path: &KeyPath,
        raw: &schema::Schedule,
        partitions: &[Partition],
    ) -> ChangeActions {
        let mut out = ChangeActions::default();
        let base = path.key("change_actions");
        for (partition, action) in in_source_order(&raw.change_actions) {
            let here = base.key(partition.get_ref());
            let index = partitions
                .iter()
                .position(|p| p.name == *partition.get_ref());
            if index.is_none() {
                self.error(
                    start(partition),
                    &here,
                    format!(
                        "unknown partition `{}`; a change action names a partition of [partitions]",
                        partition.get_ref()
                    ),
                );
            }
            let a = ChangeAction::from_name(action.get_ref());
            if a.is_none() {
                self.error(
                    start(action),
                    &here,
                    format!(
                        "unknown schedule change action `{}`; known actions: {}",
                        action.get_ref(),
                        list(&ChangeAction::ALL, ChangeAction::name)
                    ),
                );
            }
            if let (Some(i), Some(a)) = (index, a) {
                out.set(i, a);
            }
        }
        out
    }

    /// The schedules of the file in order: the single `[schedule]` or the `[[schedules]]`
    /// list (both at once is an error).
    fn schedule_entries<'d>(
        &mut self,
        doc: &'d schema::Document,
    ) -> Vec<Entry<&'d Spanned<schema::Schedule>>> {
        let root = KeyPath::root();
        let mut entries = Vec::new();
        if let Some(single) = &doc.schedule {
            if !doc.schedules.is_empty() {
                self.error(
                    start(single),
                    &root.key("schedule"),
                    "give either one [schedule] or a list of [[schedules]], not both",
                );
            }
            entries.push(Entry {
                index: 0,
                path: root.key("schedule"),
                at: start(single),
                item: single,
            });
        }
        for entry in array_entries(&doc.schedules, &root.key("schedules")) {
            let index = entries.len();
            entries.push(Entry { index, ..entry });
        }
        entries
    }

    /// A schedule's name: unique; only the first may leave it out ("default").
    /// `names` holds the names so far with their positions.
    fn schedule_name(
        &mut self,
        i: usize,
        path: &KeyPath,
        schedule: &Spanned<schema::Schedule>,
        names: &mut Vec<(String, usize)>,
    ) -> String {
        let raw = schedule.get_ref();
        match &raw.name {
            Some(n) => {
                let name_path = path.key("name");
                self.name(n, &name_path, NAME_MAX, "schedule");
                if let Some((_, at)) = names.iter().find(|(m, _)| m == n.get_ref()) {
                    let line = self.r.line_of(*at);
                    self.error(
                        start(n),
                        &name_path,
                        format!(
                            "schedule `{}` is already defined at line {line}",
                            n.get_ref()
                        ),
                    );
                }
                names.push((n.get_ref().clone(), start(n)));
                n.get_ref().clone()
            }
            None if i == 0 => "default".to_string(),
            None => {
                self.error(
                    start(schedule),
                    path,
                    "every schedule but the first needs a `name` (the first defaults to \"default\")",
                );
                String::new()
            }
        }
    }

    /// A schedule's valid windows; marks in `named` every partition a window names (even a
    /// window with other errors) with the CPUs of its valid windows.
    fn schedule_windows(
        &mut self,
        path: &KeyPath,
        raw: &schema::Schedule,
        partitions: &[Partition],
        times: &[Time],
        named: &mut [Option<u8>],
    ) -> Vec<Slot> {
        let mut windows: Vec<Slot> = Vec::new();
        let entries = array_entries(&raw.windows, &path.key("windows"));
        for Entry {
            index: j,
            path: wpath,
            item: window,
            ..
        } in self.at_most(entries, MAX_WINDOWS, "windows", " per schedule")
        {
            let w = window.get_ref();
            let part_path = wpath.key("partition");
            let partition = partitions
                .iter()
                .position(|p| p.name == *w.partition.get_ref());
            match partition {
                None => self.error(
                    start(&w.partition),
                    &part_path,
                    format!("unknown partition `{}`", w.partition.get_ref()),
                ),
                Some(p) if times[p] == Time::Background => self.error(
                    start(&w.partition),
                    &part_path,
                    format!(
                        "partition `{}` runs in the background (time = \"background\") and cannot have windows",
                        w.partition.get_ref()
                    ),
                ),
                Some(p) => named[p] = Some(named[p].unwrap_or(0)),
            }
            // (A background partition's window is refused above.)
            let windowed = partition.filter(|&p| times[p] != Time::Background);
            let cpu = self.window_cpu(w, &wpath, windowed.map(|p| (p, &partitions[p])));
            // (A refused window counts as on all its partition's CPUs: one error is enough.)
            if let Some(p) = windowed {
                let on = cpu.map_or(partitions[p].cpus, |c| 1 << c);
                named[p] = named[p].map(|cpus| cpus | on);
            }
            let offset = self.duration(&w.offset, &wpath.key("offset"));
            let duration = self.duration(&w.duration, &wpath.key("duration"));
            if let Some(short) = duration.filter(|&d| d < MIN_WINDOW) {
                self.error(
                    start(&w.duration),
                    &wpath.key("duration"),
                    format!(
                        "a window of {} is shorter than the kernel's shortest window of {} (every window boundary is a timer interrupt)",
                        Duration(short),
                        Duration(MIN_WINDOW)
                    ),
                );
                continue;
            }
            if let (Some(p), Some(offset), Some(duration), Some(cpu)) =
                (partition, offset, duration, cpu)
            {
                if offset.checked_add(duration).is_none() {
                    self.error(
                        start(&w.duration),
                        &wpath.key("duration"),
                        "window end overflows",
                    );
                    continue;
                }
                if !matches!(times[p], Time::Background | Time::Invalid) {
                    windows.push(Slot {
                        offset,
                        duration,
                        partition: p,
                        source: j,
                        cpu,
                    });
                }
            }
        }
        windows
    }

    /// A window's CPU: its `cpu`, else the CPU of its partition (`partition`, index and
    /// model, when the window names a known one). It must be a CPU the system uses and the
    /// partition's; `None` (reported) otherwise.
    fn window_cpu(
        &mut self,
        w: &schema::Window,
        wpath: &KeyPath,
        partition: Option<(usize, &Partition)>,
    ) -> Option<u8> {
        let bound = partition.filter(|(p, _)| !self.unbound.contains(p));
        let Some(cpu) = &w.cpu else {
            // The partition's (0 for a partition without a valid `cpus`: not checked).
            let Some((_, p)) = bound.filter(|(_, p)| !p.cpus.is_power_of_two()) else {
                return Some(bound.map_or(0, |(_, p)| p.cpu));
            };
            self.error(
                start(&w.partition),
                &wpath.key("partition"),
                format!(
                    "partition `{}` runs on CPUs {}: say in which CPU's schedule this window is, e.g. `cpu = {}`",
                    p.name,
                    cpu_list(p.cpus),
                    p.cpu
                ),
            );
            return None;
        };
        let here = wpath.key("cpu");
        let n = *cpu.get_ref();
        if !(0..i64::from(self.cpus)).contains(&n) {
            let why = if n < 0 {
                format!("cpu = {n} is not a CPU number (CPU 0 is the boot CPU)")
            } else {
                format!("the window is on CPU {n}, but {}", self.cpus_used())
            };
            self.error(start(cpu), &here, why);
            return None;
        }
        if let Some((_, p)) = bound
            && p.cpus & 1 << n == 0
        {
            let (s, list) = if p.cpus.is_power_of_two() {
                ("", "its CPU")
            } else {
                ("s", "one of its CPUs")
            };
            self.error(
                start(cpu),
                &here,
                format!(
                    "partition `{}` runs on CPU{s} {}; this window is on CPU {n} (a partition's windows are in the schedule of {list})",
                    p.name, cpu_list(p.cpus)
                ),
            );
            return None;
        }
        Some(n as u8)
    }

    /// The major frame: as given, else the end of the last window.
    fn major_frame(
        &mut self,
        path: &KeyPath,
        schedule: &Spanned<schema::Schedule>,
        windows: &[Slot],
    ) -> Option<u64> {
        let raw = schedule.get_ref();
        match &raw.major_frame {
            Some(f) => {
                let fpath = path.key("major_frame");
                match self.duration(f, &fpath) {
                    Some(frame) if frame < MIN_WINDOW => {
                        let msg = format!(
                            "the major frame of {} is shorter than the kernel's shortest of {}",
                            Duration(frame),
                            Duration(MIN_WINDOW)
                        );
                        self.error(start(f), &fpath, msg);
                        None
                    }
                    Some(frame) if frame > MAX_MAJOR_FRAME => {
                        let msg = format!(
                            "the major frame of {} is longer than the kernel's limit of {}",
                            Duration(frame),
                            Duration(MAX_MAJOR_FRAME)
                        );
                        self.error(start(f), &fpath, msg);
                        None
                    }
                    other => other,
                }
            }
            None => {
                let end = windows.iter().map(|w| w.end()).max();
                if end.is_none() && raw.windows.is_empty() {
                    self.error(
                        start(schedule),
                        path,
                        "a schedule without windows needs a `major_frame`",
                    );
                }
                if let Some(end) = end.filter(|&end| end > MAX_MAJOR_FRAME) {
                    let msg = format!(
                        "the windows end at {}, beyond the kernel's longest major frame of {}",
                        Duration(end),
                        Duration(MAX_MAJOR_FRAME)
                    );
                    self.error(start(schedule), path, msg);
                    return None;
                }
                end
            }
        }
    }

    /// Drops (with an error) the windows that do not lie inside the major frame.
    fn keep_windows_in_frame(
        &mut self,
        path: &KeyPath,
        raw: &schema::Schedule,
        frame: u64,
        windows: &mut Vec<Slot>,
    ) {
        windows.retain(|&slot| {
            let (offset, duration, j) = (slot.offset, slot.duration, slot.source);
            let w = raw.windows[j].get_ref();
            let wpath = path.key("windows").index(j);
            if offset >= frame {
                self.error(
                    start(&w.offset),
                    &wpath.key("offset"),
                    format!(
                        "the window starts at {}, not inside the major frame of {}",
                        Duration(offset),
                        Duration(frame)
                    ),
                );
                false
            } else if offset + duration > frame {
                self.error(
                    start(&w.duration),
                    &wpath.key("duration"),
                    format!(
                        "the window ends at {}, after the major frame of {}",
                        Duration(offset + duration),
                        Duration(frame)
                    ),
                );
                false
            } else {
                true
            }
        });
    }

    /// Reports windows (sorted by offset) that overlap an earlier one of the same CPU
    /// (every CPU has its own schedule: windows of different CPUs may overlap).
    fn window_overlaps(&mut self, path: &KeyPath, raw: &schema::Schedule, windows: &[Slot]) {
        // Per CPU, the window reaching furthest so far: (offset, end, source index).
        let mut latest: [Option<(u64, u64, usize)>; MAX_CPUS] = [None; MAX_CPUS];
        for &Slot {
            offset,
            duration,
            source: j,
            cpu,
            ..
        } in windows
        {
            let latest = &mut latest[usize::from(cpu)];
            if let Some((lo, le, lj)) = *latest
                && offset < le
            {
                let w = raw.windows[j].get_ref();
                let both = if self.cpus > 1 {
                    format!(
                        ", both on CPU {cpu} (the windows of one CPU must not overlap; those of different CPUs may)"
                    )
                } else {
                    String::new()
                };
                self.error(
                    start(&w.offset),
                    &path.key("windows").index(j).key("offset"),
                    format!(
                        "the window {}..{} overlaps window {lj} ({}..{}){both}",
                        Duration(offset),
                        Duration(offset + duration),
                        Duration(lo),
                        Duration(le)
                    ),
                );
            }
            if latest.is_none_or(|(_, le, _)| offset + duration > le) {
                *latest = Some((offset, offset + duration, j));
            }
        }
    }

    /// A background partition competes by priority with the partition whose window is
    /// open on its CPU, so it must stay below the `priority` (the floor) of every windowed
    /// partition of its CPU or it can take that partition's window away; `preempts_windows
    /// = true` on the background partition says this is intended (then it is a warning).
    /// `preempts_windows` on a windowed partition is an error: it means nothing there.
    fn background_priorities(&mut self, doc: &schema::Document, partitions: &[Partition]) {
        let base = KeyPath::root().key("partitions");
        let raw = in_source_order(&doc.partitions);
        for (p, (_, value)) in partitions.iter().zip(&raw) {
            let floor = partitions
                .iter()
                .filter(|w| w.time_partition != 0 && w.cpus & p.cpus != 0)
                .min_by_key(|w| w.priority);
            let raw = value.get_ref();
            let path = base.key(&p.name);
            let intended = raw.preempts_windows.as_ref();
            if p.time_partition != 0 {
                if let Some(flag) = intended {
                    self.error(
                        start(flag),
                        &path.key("preempts_windows"),
                        format!(
                            "partition `{}` has windows; preempts_windows only applies to a background partition (time = \"background\")",
                            p.name
                        ),
                    );
                }
                continue;
            }
            let Some(windowed) = floor.filter(|w| p.mcp >= w.priority) else {
                continue;
            };
            let why = format!(
                "background partition `{}` has max_priority {} >= priority {} of windowed partition `{}`: its threads can take that partition's window away",
                p.name, p.mcp, windowed.priority, windowed.name
            );
            match intended {
                Some(flag) if *flag.get_ref() => self.r.warning(
                    start(flag),
                    &path.key("preempts_windows"),
                    format!("{why} (allowed by preempts_windows = true)"),
                ),
                _ => self.error(
                    start(&raw.max_priority),
                    &path.key("max_priority"),
                    format!(
                        "{why}; give it a max_priority below {} or say `preempts_windows = true` if that is intended",
                        windowed.priority
                    ),
                ),
            }
        }
    }

    /// Time partitions: explicit numbers first, then the lowest free ones in source order;
    /// every explicit one must have a window.
    fn assign_time_partitions(
        &mut self,
        doc: &schema::Document,
        partitions: &mut [Partition],
        times: &[Time],
        named: &[Option<u8>],
    ) {
        // Time partitions: explicit numbers first, then the lowest free ones in source order.
        let has_window = |p: usize| named[p].is_some();
        let mut used = [false; TIME_PARTITIONS as usize];
        for t in times {
            if let Time::Explicit(n, _) = t {
                used[*n as usize] = true;
            }
        }
        let base = KeyPath::root().key("partitions");
        for (p, time) in times.iter().enumerate() {
            let name = partitions[p].name.clone();
            let tp = match *time {
                Time::Background | Time::Invalid => 0,
                Time::Explicit(n, _) => n,
                Time::Auto if has_window(p) => {
                    match (1..TIME_PARTITIONS).find(|&n| !used[n as usize]) {
                        Some(n) => {
                            used[n as usize] = true;
                            n
                        }
                        None => {
                            let at = partition_key_at(doc, &name);
                            self.error(
                            at,
                            &base.key(&name),
                            format!(
                                "no time partition left for partition `{name}` (there are {}); let partitions share one with `time = N`",
                                TIME_PARTITIONS - 1
                            ),
                        );
                            0
                        }
                    }
                }
                Time::Auto => {
                    let at = partition_key_at(doc, &name);
                    self.error(
                        at,
                        &base.key(&name),
                        format!(
                            "partition `{name}` has no window and is not background (add a window or `time = \"background\"`)"
                        ),
                    );
                    0
                }
            };
            partitions[p].time_partition = tp;
        }
        // A partition runs in the windows of its time partition on each of its CPUs.
        for (p, time) in times.iter().enumerate() {
            let (n, at) = match *time {
                Time::Explicit(n, at) => (n, Some(at)),
                Time::Auto if named[p].is_some() => (partitions[p].time_partition, None),
                _ => continue,
            };
            let name = partitions[p].name.clone();
            let windows_on = |c: u8| {
                (0..partitions.len()).any(|q| {
                    partitions[q].time_partition == n && named[q].is_some_and(|on| on & 1 << c != 0)
                })
            };
            let windowed = |q: usize| named[q].is_some() && partitions[q].time_partition == n;
            if let Some(at) = at.filter(|_| !(0..partitions.len()).any(windowed)) {
                self.error(
                    at,
                    &base.key(&name).key("time"),
                    format!(
                        "time partition {n} of partition `{name}` has no window in any schedule"
                    ),
                );
                continue;
            }
            let cpus = partitions[p].cpus;
            // (A window of a one-CPU partition's own time partition is on its CPU or refused.)
            if n == 0 || self.unbound.contains(&p) || at.is_none() && cpus.is_power_of_two() {
                continue;
            }
            let Some(cpu) = (0..8).find(|&c| cpus & 1 << c != 0 && !windows_on(c)) else {
                continue;
            };
            let (key, at) = match at {
                Some(at) => ("time", at),
                None => ("cpus", partition_key_at(doc, &name)),
            };
            let why = if cpus.is_power_of_two() {
                format!(
                    "time partition {n} of partition `{name}` has no window on CPU {cpu}, the CPU it runs on (its windows are those of its CPU's schedule)"
                )
            } else {
                format!(
                    "partition `{name}` runs on CPUs {}, but time partition {n} has no window on CPU {cpu}: its threads there would never run (add a window with `cpu = {cpu}`)",
                    cpu_list(cpus)
                )
            };
            self.error(at, &base.key(&name).key(key), why);
        }
    }

    fn channels(
        &mut self,
        doc: &schema::Document,
        partitions: &mut [Partition],
        ports: &mut [PortDecl],
    ) -> Vec<Channel> {
        let mut channels: Vec<Channel> = Vec::new();
        let mut names: Vec<(String, usize)> = Vec::new();
        let entries = array_entries(&doc.channels, &KeyPath::root().key("channels"));
        for Entry {
            index: c,
            path,
            item: channel,
            ..
        } in self.at_most(entries, MAX_CHANNELS, "channels", "")
        {
            let raw = channel.get_ref();
            let kind = self.port_kind(&raw.kind, &path, "channel");
            let (name, name_at, name_path) = match &raw.name {
                Some(n) => {
                    self.name(n, &path.key("name"), NAME_MAX, "channel");
                    (n.get_ref().clone(), start(n), path.key("name"))
                }
                None if raw.from.get_ref().len() <= NAME_MAX => (
                    raw.from.get_ref().clone(),
                    start(&raw.from),
                    path.key("from"),
                ),
                None => (format!("channel{c}"), start(&raw.from), path.key("from")),
            };
            if let Some((_, at)) = names.iter().find(|(n, _)| *n == name) {
                let line = self.r.line_of(*at);
                self.error(
                    name_at,
                    &name_path,
                    format!("channel name `{name}` is already used at line {line}"),
                );
            }
            names.push((name.clone(), name_at));

            let from_path = path.key("from");
            let source = self.endpoint(
                &raw.from,
                &from_path,
                c,
                kind,
                Direction::Out,
                None,
                partitions,
                ports,
            );
            let source_size = source.map(|s| partitions[s.partition].ports[s.port].size);
            let to_path = path.key("to");
            let one;
            let targets: Vec<(&Spanned<String>, KeyPath)> = match raw.to.get_ref() {
                Targets::One(text) => {
                    one = Spanned::new(raw.to.span(), text.clone());
                    vec![(&one, to_path.clone())]
                }
                Targets::Many(items) => items
                    .iter()
                    .enumerate()
                    .map(|(i, t)| (t, to_path.index(i)))
                    .collect(),
            };
            let mut destinations = Vec::new();
            if targets.is_empty() {
                self.error(
                    start(&raw.to),
                    &to_path,
                    "a channel needs at least one destination",
                );
            }
            if kind == Some(PortKind::Queuing) && targets.len() > 1 {
                self.error(
                    start(targets[1].0),
                    &targets[1].1,
                    "a queuing channel connects exactly one destination (1:1)",
                );
            }
            for (target, target_path) in &targets {
                if let Some(d) = self.endpoint(
                    target,
                    target_path,
                    c,
                    kind,
                    Direction::In,
                    source_size,
                    partitions,
                    ports,
                ) {
                    destinations.push(d);
                }
            }
            let (Some(kind), Some(source)) = (kind, source) else {
                continue;
            };
            if destinations.len() != targets.len() || targets.is_empty() {
                continue;
            }
            let index = channels.len();
            partitions[source.partition].ports[source.port].channel = index;
            for d in &destinations {
                partitions[d.partition].ports[d.port].channel = index;
            }
            channels.push(Channel {
                name,
                kind,
                source,
                destinations,
            });
        }
        for decl in ports.iter() {
            if decl.used_by.is_none() {
                let p = &partitions[decl.partition];
                self.error(
                    decl.key_at,
                    &decl.path,
                    format!(
                        "port `{}.{}` is connected by no channel",
                        p.name, p.ports[decl.port].name
                    ),
                );
            }
        }
        channels
    }

    /// Resolves one end of channel `channel` and checks it against the channel.
    #[allow(clippy::too_many_arguments)]
    fn endpoint(
        &mut self,
        text: &Spanned<String>,
        path: &KeyPath,
        channel: usize,
        kind: Option<PortKind>,
        direction: Direction,
        source_size: Option<u32>,
        partitions: &[Partition],
        ports: &mut [PortDecl],
    ) -> Option<PortRef> {
        let at = start(text);
        let full = text.get_ref();
        let Some((partition_name, port_name)) = full.split_once('.') else {
            self.error(
                at,
                path,
                format!("{full:?} is not a port reference \"partition.port\""),
            );
            return None;
        };
        let Some(p) = partitions.iter().position(|p| p.name == partition_name) else {
            self.error(at, path, format!("unknown partition `{partition_name}`"));
            return None;
        };
        let Some(decl) = ports
            .iter_mut()
            .find(|d| d.partition == p && partitions[p].ports[d.port].name == port_name)
        else {
            self.error(
                at,
                path,
                format!("partition `{partition_name}` has no port `{port_name}`"),
            );
            return None;
        };
        if !decl.valid {
            // Its own errors are reported already.
            decl.used_by.get_or_insert((channel, at));
            return None;
        }
        let port = &partitions[p].ports[decl.port];
        let port_ref = PortRef {
            partition: p,
            port: decl.port,
        };
        let mut ok = true;
        if port.direction != direction {
            let role = if direction == Direction::Out {
                "`from`"
            } else {
                "`to`"
            };
            self.error(
                at,
                path,
                format!(
                    "`{full}` is an {} port but a channel's {role} must be direction = \"{}\"",
                    if port.direction == Direction::In {
                        "input"
                    } else {
                        "output"
                    },
                    direction.name()
                ),
            );
            ok = false;
        }
        if let Some(kind) = kind
            && port.kind != kind
        {
            self.error(
                at,
                path,
                format!(
                    "`{full}` is a {} port but the channel is {}",
                    port.kind.name(),
                    kind.name()
                ),
            );
            ok = false;
        }
        if let Some(source_size) = source_size
            && port.size < source_size
        {
            self.error(
                at,
                path,
                format!(
                    "`{full}` takes messages of at most {} bytes, less than the {source_size} bytes the source may send (a destination's size must be at least the source's)",
                    port.size
                ),
            );
            ok = false;
        }
        match decl.used_by {
            Some((other, other_at)) => {
                let line = self.r.line_of(other_at);
                let which = if other == channel {
                    "listed already in this channel".to_string()
                } else {
                    format!("already connected by channels[{other}]")
                };
                self.error(
                    at,
                    path,
                    format!("port `{full}` is {which} at line {line}; every port belongs to exactly one channel"),
                );
                ok = false;
            }
            None => decl.used_by = Some((channel, at)),
        }
        ok.then_some(port_ref)
    }

    fn budgets(
        &mut self,
        memory: u64,
        at: usize,
        path: &KeyPath,
        partitions: &[Partition],
        segments: &[(Segment, usize)],
    ) {
        let total = |sizes: &mut dyn Iterator<Item = u64>| sizes.fold(0u64, u64::saturating_add);
        let partition_memory = total(&mut partitions.iter().map(|p| p.memory));
        let segment_memory = total(&mut segments.iter().map(|(s, _)| s.size));
        let user = partition_memory.saturating_add(segment_memory);
        if user > user_memory_limit(memory) {
            self.error(
                at,
                path,
                format!(
                    "partitions ({}) and shared memory ({}) need {}, but of {} only {} are left for them (minus the kernel pool of {} and a reserve of {} for the kernel, firmware, system image and syssw)",
                    Size(partition_memory),
                    Size(segment_memory),
                    Size(user),
                    Size(memory),
                    Size(user_memory_limit(memory)),
                    Size(kernel_pool(memory)),
                    Size(SYSTEM_RESERVE)
                ),
            );
        }
        let kernel = total(&mut partitions.iter().map(|p| p.kernel_memory));
        if kernel > kernel_memory_limit(memory) {
            self.error(
                at,
                path,
                format!(
                    "the partitions' kernel_memory quotas need {}, but the kernel pool of {} (1/8 of memory, 16MiB..128MiB) leaves only {} after syssw's {}",
                    Size(kernel),
                    Size(kernel_pool(memory)),
                    Size(kernel_memory_limit(memory)),
                    Size(SYSSW_KERNEL_RESERVE)
                ),
            );
        }
        let threads: u32 = partitions.iter().map(|p| p.kernel_threads).sum();
        if threads > KERNEL_THREADS - SYSSW_THREADS {
            self.error(
                at,
                path,
                format!(
                    "the partitions' kernel_threads quotas add up to {threads}, more than the {} the kernel's thread table leaves after syssw",
                    KERNEL_THREADS - SYSSW_THREADS
                ),
            );
        }
        let tasks: u32 = partitions.iter().map(|p| p.kernel_tasks).sum();
        if tasks > KERNEL_TASKS - SYSSW_TASKS {
            self.error(
                at,
                path,
                format!(
                    "the partitions' kernel_tasks quotas add up to {tasks}, more than the {} the kernel's task table leaves after syssw",
                    KERNEL_TASKS - SYSSW_TASKS
                ),
            );
        }
    }
}

/// Name of the `index`-th partition in source order.
/// Who holds a resource partition `index` lists again: itself, or another partition.
fn holder(doc: &schema::Document, owner: usize, index: usize) -> String {
    if owner == index {
        "listed already".to_string()
    } else {
        format!("given to partition `{}`", partitions_name(doc, owner))
    }
}

fn partitions_name(doc: &schema::Document, index: usize) -> String {
    in_source_order(&doc.partitions)
        .get(index)
        .map(|(k, _)| k.get_ref().clone())
        .unwrap_or_default()
}

fn partition_key_at(doc: &schema::Document, name: &str) -> usize {
    doc.partitions
        .keys()
        .find(|k| k.get_ref() == name)
        .map_or(0, |k| k.span().start)
}

/// `a.b.c.d`.
fn parse_ipv4(text: &str) -> Option<[u8; 4]> {
    let mut octets = [0u8; 4];
    let mut parts = text.split('.');
    for o in &mut octets {
        let part = parts.next()?;
        if part.is_empty() || part.len() > 3 || !part.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        *o = part.parse().ok()?;
    }
    parts.next().is_none().then_some(octets)
}

/// A key file's key ([`plc_online::session::parse_key_file`]).
fn parse_key(text: &str) -> Result<Vec<u8>, String> {
    let mut key = [0u8; plc_online::session::MAX_KEY];
    plc_online::session::parse_key_file(text, &mut key)
        .map(|len| key[..len].to_vec())
        .map_err(|e| e.to_string())
}

/// CPUs of a mask as a config writes them: `1`, `1 and 2`, `0, 1 and 3`.
fn cpu_list(mask: u8) -> String {
    let cpus: Vec<String> = (0..8)
        .filter(|c| mask & 1 << c != 0)
        .map(|c| c.to_string())
        .collect();
    match cpus.split_last() {
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
        None => String::new(),
    }
}
