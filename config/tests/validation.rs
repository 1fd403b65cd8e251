//! One test per validation rule: each checks the message, the key path and that line:column
//! points at the offending key or value.

mod common;
use common::*;
use config::model::{ChangeAction, ErrorCode, HealthAction, PortKind};

#[test]
fn base_is_valid() {
    let s = load_ok(BASE);
    assert_eq!(s.name, "system");
    assert_eq!(s.partitions[0].name, "a");
    assert_eq!(s.partitions[0].time_partition, 1);
    assert_eq!(s.partitions[1].time_partition, 0);
    assert_eq!(s.schedules[0].windows[0].time_partition, 1);
    assert_eq!(s.partitions[0].stack, 64 * 1024);
    assert_eq!(s.partitions[0].priority, 100);
    assert!(
        s.partitions[0]
            .abilities
            .contains(abi::syscall::Abilities::NATIVE_SYSCALLS)
    );
    assert_eq!(s.channels[0].name, "a.out");
}

// ---- syntax and shape -------------------------------------------------------------------

#[test]
fn syntax_errors_are_all_reported_with_positions() {
    let src = doc(&[
        (
            "max_priority = 100\nports.out",
            "max_priority = = 100\nports.out",
        ),
        ("# tail", "[broken\n"),
    ]);
    let diags = load(&src).unwrap_err();
    assert!(diags.len() >= 2, "{diags:?}");
    assert!(diags.iter().all(|d| d.message.starts_with("TOML syntax")));
    let (line, _) = position(&src, "= = 100", 0);
    assert!(diags.iter().any(|d| d.line == line));
    let (line, _) = position(&src, "[broken", 0);
    assert!(diags.iter().any(|d| d.line == line));
}

#[test]
fn unknown_key() {
    let src = doc(&[("# a", "colour = \"red\"")]);
    expect_one(
        &src,
        "colour",
        0,
        "partitions.a.colour",
        "unknown field `colour`",
    );
}

#[test]
fn unknown_key_in_window() {
    let src = doc(&[("duration = \"2ms\"", "duration = \"2ms\"\nlength = \"1ms\"")]);
    expect_one(
        &src,
        "length",
        0,
        "schedules[0].windows[0].length",
        "unknown field `length`",
    );
}

#[test]
fn wrong_type() {
    let src = doc(&[(
        "max_priority = 100\nports.out",
        "max_priority = \"high\"\nports.out",
    )]);
    expect_one(
        &src,
        "\"high\"",
        0,
        "partitions.a.max_priority",
        "invalid type: string \"high\"",
    );
}

#[test]
fn missing_key() {
    let src = doc(&[("image = \"app\"\nmemory = \"1MiB\"", "memory = \"1MiB\"")]);
    expect_one(
        &src,
        "[partitions.a]",
        0,
        "partitions.a",
        "missing field `image`",
    );
}

// ---- units ------------------------------------------------------------------------------

#[test]
fn decimal_size_unit() {
    let src = doc(&[("memory = \"512MiB\"", "memory = \"512MB\"")]);
    expect_one(
        &src,
        "\"512MB\"",
        0,
        "system.memory",
        "unit `MB` is decimal and ambiguous",
    );
}

#[test]
fn unknown_size_unit() {
    let src = doc(&[("kernel_memory = \"64KiB\"", "kernel_memory = \"64 pages\"")]);
    expect_one(
        &src,
        "\"64 pages\"",
        0,
        "partitions.a.kernel_memory",
        "unknown size unit",
    );
}

#[test]
fn negative_size() {
    let src = doc(&[("size = 8 }\n# a", "size = -8 }\n# a")]);
    expect_one(
        &src,
        "-8",
        0,
        "partitions.a.ports.out.size",
        "must not be negative",
    );
}

#[test]
fn duration_without_unit() {
    let src = doc(&[("major_frame = \"10ms\"", "major_frame = 10")]);
    expect_one(
        &src,
        "10\n",
        0,
        "schedules[0].major_frame",
        "a duration needs a unit",
    );
}

#[test]
fn unknown_duration_unit() {
    let src = doc(&[("offset = \"0ms\"", "offset = \"0min\"")]);
    expect_one(
        &src,
        "\"0min\"",
        0,
        "schedules[0].windows[0].offset",
        "unknown duration unit",
    );
}

#[test]
fn fractional_duration() {
    let src = doc(&[("duration = \"2ms\"", "duration = \"1.5ms\"")]);
    expect_one(
        &src,
        "\"1.5ms\"",
        0,
        "schedules[0].windows[0].duration",
        "fractions are not allowed",
    );
}

#[test]
fn memory_not_whole_pages() {
    let src = doc(&[("memory = \"1MiB\"", "memory = 5000")]);
    expect_one(
        &src,
        "5000",
        0,
        "partitions.a.memory",
        "not a multiple of 4 KiB",
    );
}

#[test]
fn zero_kernel_memory() {
    let src = doc(&[("kernel_memory = \"64KiB\"", "kernel_memory = 0")]);
    expect_one(
        &src,
        "kernel_memory = ^0",
        0,
        "partitions.a.kernel_memory",
        "must not be zero",
    );
    // The position is the value, not the key.
    let diags = load(&src).unwrap_err();
    assert_eq!(diags[0].column, "kernel_memory = ".len() + 1);
}

#[test]
fn stack_larger_than_memory() {
    let src = doc(&[("# a", "stack = \"2MiB\"")]);
    expect_one(
        &src,
        "\"2MiB\"",
        0,
        "partitions.a.stack",
        "does not fit in the partition's memory",
    );
}

// ---- priorities, abilities, time ----------------------------------------------------------

#[test]
fn mcp_at_or_above_syssw() {
    let src = doc(&[(
        "max_priority = 100\nports.out",
        "max_priority = 200\nports.out",
    )]);
    expect_one(
        &src,
        "200",
        0,
        "partitions.a.max_priority",
        "is not in 1..=199",
    );
}

#[test]
fn mcp_zero() {
    let src = doc(&[(
        "max_priority = 100\nports.out",
        "max_priority = 0\nports.out",
    )]);
    expect_one(
        &src,
        "0\nports.out",
        0,
        "partitions.a.max_priority",
        "is not in 1..=199",
    );
}

#[test]
fn priority_above_mcp() {
    let src = doc(&[("# a", "priority = 101")]);
    expect_one(
        &src,
        "101",
        0,
        "partitions.a.priority",
        "may not exceed max_priority",
    );
}

#[test]
fn unknown_ability() {
    let src = doc(&[("# a", "abilities = [\"debug_log\", \"fly\"]")]);
    expect_one(
        &src,
        "\"fly\"",
        0,
        "partitions.a.abilities[1]",
        "unknown ability `fly`",
    );
}

#[test]
fn syssw_only_abilities() {
    for ability in [
        "system_halt",
        "physical_memory",
        "scheduling",
        "partition_control",
    ] {
        let src = doc(&[("# a", &format!("abilities = [\"{ability}\"]"))]);
        expect_one(
            &src,
            &format!("\"{ability}\""),
            0,
            "partitions.a.abilities[0]",
            "reserved for the system software",
        );
    }
}

#[test]
fn native_syscalls_default_and_off() {
    let src = doc(&[(
        "# b",
        "native_syscalls = false\nabilities = [\"create_task\", \"map\"]",
    )]);
    let s = load_ok(&src);
    use abi::syscall::Abilities;
    assert_eq!(
        s.partitions[1].abilities,
        Abilities::CREATE_TASK | Abilities::MAP
    );
    let src = doc(&[(
        "# b",
        "native_syscalls = false\nabilities = [\"native_syscalls\"]",
    )]);
    expect_one(
        &src,
        "\"native_syscalls\"",
        0,
        "partitions.b.abilities[0]",
        "`native_syscalls = false` is set",
    );
}

#[test]
fn bad_time_value() {
    let src = doc(&[("time = \"background\"", "time = \"sometimes\"")]);
    expect_one(
        &src,
        "\"sometimes\"",
        0,
        "partitions.b.time",
        "neither \"background\" nor a time partition number 1..=15",
    );
    let src = doc(&[("time = \"background\"", "time = 16")]);
    expect_one(&src, "16", 0, "partitions.b.time", "1..=15");
}

#[test]
fn time_zero_means_background() {
    let src = doc(&[("time = \"background\"", "time = 0")]);
    expect_one(
        &src,
        "time = ^0",
        0,
        "partitions.b.time",
        "write `time = \"background\"`",
    );
}

#[test]
fn no_window_and_not_background() {
    let src = doc(&[("time = \"background\"\n", "")]);
    expect_one(
        &src,
        "b]",
        0,
        "partitions.b",
        "partition `b` has no window and is not background",
    );
}

#[test]
fn background_above_a_windowed_partition() {
    // b (background) at MCP 100 would outrank a (windowed, priority 100) in a's window.
    let src = doc(&[("max_priority = 50", "max_priority = 100")]);
    expect_one(
        &src,
        "max_priority = ^100\ntime",
        0,
        "partitions.b.max_priority",
        "background partition `b` has max_priority 100 >= priority 100 of windowed partition `a`",
    );
    // The floor is the windowed partition's `priority`, not its MCP.
    let src = doc(&[("# a", "priority = 40")]);
    expect_one(
        &src,
        "max_priority = ^50",
        0,
        "partitions.b.max_priority",
        "max_priority 50 >= priority 40 of windowed partition `a`",
    );
    load_ok(&doc(&[("# a", "priority = 51")]));
}

#[test]
fn background_preempting_windows_on_purpose_is_a_warning() {
    let src = doc(&[
        ("max_priority = 50", "max_priority = 100"),
        ("# b", "preempts_windows = true"),
    ]);
    let (_, warnings) = config::load_with_warnings("test.toml", &src, &any_image).unwrap();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    let (line, column) = position(&src, "preempts_windows = ^true", 0);
    assert_eq!((warnings[0].line, warnings[0].column), (line, column));
    assert_eq!(warnings[0].key_path, "partitions.b.preempts_windows");
    assert!(
        warnings[0]
            .message
            .contains("allowed by preempts_windows = true")
    );
    // Saying false changes nothing.
    let src = doc(&[
        ("max_priority = 50", "max_priority = 100"),
        ("# b", "preempts_windows = false"),
    ]);
    expect_one(
        &src,
        "max_priority = ^100\ntime",
        0,
        "partitions.b.max_priority",
        "or say `preempts_windows = true`",
    );
    // A background partition below every floor has no warning.
    let (_, warnings) = config::load_with_warnings(
        "test.toml",
        &doc(&[("# b", "preempts_windows = true")]),
        &any_image,
    )
    .unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
}

#[test]
fn preempts_windows_on_a_windowed_partition() {
    let src = doc(&[("# a", "preempts_windows = true")]);
    expect_one(
        &src,
        "preempts_windows = ^true",
        0,
        "partitions.a.preempts_windows",
        "partition `a` has windows; preempts_windows only applies to a background partition",
    );
}

#[test]
fn explicit_time_partition_without_window() {
    let src = doc(&[("time = \"background\"", "time = 5")]);
    expect_one(
        &src,
        "5\n",
        0,
        "partitions.b.time",
        "time partition 5 of partition `b` has no window in any schedule",
    );
}

#[test]
fn time_partitions_auto_explicit_and_shared() {
    // a (auto) gets the lowest number that no partition fixed: 2, because c fixed 1.
    // b shares c's time partition and runs in c's window.
    let src = doc(&[
        ("time = \"background\"", "time = 1"),
        (
            "# tail",
            "[partitions.c]\nimage = \"app\"\nmemory = \"1MiB\"\nkernel_memory = \"64KiB\"\nmax_priority = 10\ntime = 1\n\n[[schedules.windows]]\npartition = \"c\"\noffset = \"5ms\"\nduration = \"1ms\"\n",
        ),
    ]);
    // The window above is appended to the last [[schedules]] entry: the only one.
    let s = load_ok(&src);
    let tp: Vec<u8> = s.partitions.iter().map(|p| p.time_partition).collect();
    assert_eq!(tp, [2, 1, 1]);
    let windows: Vec<(u64, u8)> = s.schedules[0]
        .windows
        .iter()
        .map(|w| (w.offset, w.time_partition))
        .collect();
    assert_eq!(windows, [(0, 2), (5_000_000, 1)]);
}

// ---- schedules and windows ----------------------------------------------------------------

#[test]
fn window_for_unknown_partition() {
    let src = doc(&[("partition = \"a\"", "partition = \"nope\"")]);
    expect_some(
        &src,
        "\"nope\"",
        0,
        "schedules[0].windows[0].partition",
        "unknown partition `nope`",
    );
}

#[test]
fn change_actions_per_partition() {
    let s = load_ok(&doc(&[(
        "major_frame = \"10ms\"",
        "major_frame = \"10ms\"\nchange_actions = { b = \"cold_start\", a = \"warm_start\" }",
    )]));
    let actions = s.schedules[0].change_actions;
    assert_eq!(actions.get(0), ChangeAction::WarmStart);
    assert_eq!(actions.get(1), ChangeAction::ColdStart);
    let s = load_ok(BASE);
    assert_eq!(s.schedules[0].change_actions.get(0), ChangeAction::Ignore);
}

#[test]
fn change_action_for_unknown_partition() {
    let src = doc(&[(
        "major_frame = \"10ms\"",
        "major_frame = \"10ms\"\nchange_actions = { nope = \"idle\" }",
    )]);
    expect_one(
        &src,
        "nope",
        0,
        "schedules[0].change_actions.nope",
        "unknown partition `nope`",
    );
}

#[test]
fn unknown_change_action() {
    let src = doc(&[(
        "major_frame = \"10ms\"",
        "major_frame = \"10ms\"\nchange_actions = { a = \"stop\" }",
    )]);
    expect_one(
        &src,
        "\"stop\"",
        0,
        "schedules[0].change_actions.a",
        "unknown schedule change action `stop`; known actions: ignore, idle, cold_start, warm_start",
    );
}

#[test]
fn window_for_background_partition() {
    let src = doc(&[("partition = \"a\"", "partition = \"b\"")]);
    expect_some(
        &src,
        "\"b\"\noffset",
        0,
        "schedules[0].windows[0].partition",
        "runs in the background",
    );
}

fn with_windows(windows: &[(&str, &str)]) -> String {
    let mut text = String::new();
    for (offset, duration) in windows {
        text.push_str(&format!(
            "\n[[schedules.windows]]\npartition = \"a\"\noffset = \"{offset}\"\nduration = \"{duration}\"\n"
        ));
    }
    doc(&[(
        "[[schedules.windows]]\npartition = \"a\"\noffset = \"0ms\"\nduration = \"2ms\"\n",
        &text,
    )])
}

#[test]
fn window_ends_after_frame() {
    let src = with_windows(&[("0ms", "2ms"), ("8ms", "3ms")]);
    expect_one(
        &src,
        "\"3ms\"",
        0,
        "schedules[0].windows[1].duration",
        "the window ends at 11ms, after the major frame of 10ms",
    );
}

#[test]
fn window_starts_after_frame() {
    let src = with_windows(&[("10ms", "1ms")]);
    expect_one(
        &src,
        "\"10ms\"\n",
        1,
        "schedules[0].windows[0].offset",
        "not inside the major frame of 10ms",
    );
}

#[test]
fn overlapping_windows() {
    let src = with_windows(&[("4ms", "2ms"), ("0ms", "2ms"), ("5ms", "1ms")]);
    expect_one(
        &src,
        "\"5ms\"",
        0,
        "schedules[0].windows[2].offset",
        "the window 5ms..6ms overlaps window 0 (4ms..6ms)",
    );
}

#[test]
fn windows_are_sorted_by_offset() {
    let src = with_windows(&[("4ms", "2ms"), ("0ms", "2ms"), ("2ms", "2ms")]);
    let s = load_ok(&src);
    let offsets: Vec<u64> = s.schedules[0].windows.iter().map(|w| w.offset).collect();
    assert_eq!(offsets, [0, 2_000_000, 4_000_000]);
}

#[test]
fn zero_length_window() {
    let src = with_windows(&[("0ms", "0ms")]);
    expect_one(
        &src,
        "\"0ms\"\n",
        1,
        "schedules[0].windows[0].duration",
        "a window of 0ns is shorter than the kernel's shortest window of 10us",
    );
}

#[test]
fn windows_and_frames_shorter_than_the_kernel_allows() {
    // A 16 ns frame made the kernel spend all its time in window-boundary interrupts.
    let src = with_windows(&[("0ms", "9999ns")]);
    expect_one(
        &src,
        "\"9999ns\"",
        0,
        "schedules[0].windows[0].duration",
        "shorter than the kernel's shortest window of 10us",
    );
    load_ok(&with_windows(&[("0ms", "10us")]));
    let src = doc(&[("major_frame = \"10ms\"", "major_frame = \"16ns\"")]);
    expect_some(
        &src,
        "\"16ns\"",
        0,
        "schedules[0].major_frame",
        "the major frame of 16ns is shorter than the kernel's shortest of 10us",
    );
}

#[test]
fn too_many_windows() {
    let windows: Vec<(String, String)> = (0..33)
        .map(|i| (format!("{}us", i * 100), "100us".to_string()))
        .collect();
    let refs: Vec<(&str, &str)> = windows
        .iter()
        .map(|(a, b)| (a.as_str(), b.as_str()))
        .collect();
    let src = with_windows(&refs);
    expect_one(
        &src,
        "[[schedules.windows]]",
        32,
        "schedules[0].windows[32]",
        "too many windows (at most 32 per schedule)",
    );
}

#[test]
fn too_many_schedules() {
    let mut tail = String::new();
    for i in 1..5 {
        tail.push_str(&format!(
            "[[schedules]]\nname = \"s{i}\"\nmajor_frame = \"1ms\"\n\n"
        ));
    }
    let src = doc(&[("# tail", &tail)]);
    expect_one(
        &src,
        "[[schedules]]",
        4,
        "schedules[4]",
        "too many schedules (at most 4",
    );
}

#[test]
fn duplicate_schedule_name() {
    let src = doc(&[(
        "# tail",
        "[[schedules]]\nname = \"main\"\nmajor_frame = \"1ms\"\n",
    )]);
    expect_one(
        &src,
        "\"main\"",
        1,
        "schedules[1].name",
        "schedule `main` is already defined at line 5",
    );
}

#[test]
fn later_schedule_needs_a_name() {
    let src = doc(&[("# tail", "[[schedules]]\nmajor_frame = \"1ms\"\n")]);
    expect_one(&src, "[[schedules]]", 1, "schedules[1]", "needs a `name`");
}

#[test]
fn schedule_without_windows_needs_frame() {
    let src = doc(&[("# tail", "[[schedules]]\nname = \"idle\"\n")]);
    expect_one(
        &src,
        "[[schedules]]",
        1,
        "schedules[1]",
        "a schedule without windows needs a `major_frame`",
    );
}

#[test]
fn single_schedule_form() {
    let src = BASE
        .replace("[[schedules]]\nname = \"main\"\n", "[schedule]\n")
        .replace("[[schedules.windows]]", "[[schedule.windows]]");
    let s = load_ok(&src);
    assert_eq!(s.schedules.len(), 1);
    assert_eq!(s.schedules[0].name, "default");
    assert_eq!(s.schedules[0].major_frame, 10_000_000);
    // Without major_frame, the frame ends with the last window.
    let s = load_ok(&src.replace("major_frame = \"10ms\"\n", ""));
    assert_eq!(s.schedules[0].major_frame, 2_000_000);
}

#[test]
fn both_schedule_forms() {
    let src = doc(&[("# tail", "[schedule]\nmajor_frame = \"1ms\"\n")]);
    expect_one(
        &src,
        "[schedule]",
        0,
        "schedule",
        "either one [schedule] or a list of [[schedules]]",
    );
}

// ---- I/O ports and IRQs --------------------------------------------------------------------

#[test]
fn kernel_io_ports() {
    let src = doc(&[("# a", "io_ports = [\"0x3f8-0x3ff\"]")]);
    expect_one(
        &src,
        "\"0x3f8-0x3ff\"",
        0,
        "partitions.a.io_ports[0]",
        "the kernel keeps for COM1, the kernel log",
    );
    let src = doc(&[("# a", "io_ports = [0xf4]")]);
    expect_one(
        &src,
        "0xf4",
        0,
        "partitions.a.io_ports[0]",
        "isa-debug-exit",
    );
    // The exit device decodes four ports; the last one ends the run as well.
    let src = doc(&[("# a", "io_ports = [0xf7]")]);
    expect_one(
        &src,
        "0xf7",
        0,
        "partitions.a.io_ports[0]",
        "isa-debug-exit",
    );
    let src = doc(&[("# a", "io_ports = [\"0x40-0x50\"]")]);
    expect_one(
        &src,
        "\"0x40-0x50\"",
        0,
        "partitions.a.io_ports[0]",
        "the PIT",
    );
}

#[test]
fn malformed_io_ports() {
    let src = doc(&[("# a", "io_ports = [\"0x2f8-\"]")]);
    expect_one(
        &src,
        "\"0x2f8-\"",
        0,
        "partitions.a.io_ports[0]",
        "invalid I/O port range",
    );
    let src = doc(&[("# a", "io_ports = [\"0x2ff-0x2f8\"]")]);
    expect_one(
        &src,
        "\"0x2ff-0x2f8\"",
        0,
        "partitions.a.io_ports[0]",
        "the first port is above the last",
    );
    let src = doc(&[("# a", "io_ports = [70000]")]);
    expect_one(&src, "70000", 0, "partitions.a.io_ports[0]", "0..=0xffff");
}

#[test]
fn io_ports_shared_between_partitions() {
    let src = doc(&[
        ("# a", "io_ports = [\"0x2f8-0x2ff\"]"),
        ("# b", "io_ports = [\"0x2fc\"]"),
    ]);
    expect_one(
        &src,
        "\"0x2fc\"",
        0,
        "partitions.b.io_ports[0]",
        "overlap 0x2f8-0x2ff, given to partition `a` at line 19",
    );
}

#[test]
fn io_ports_listed_twice() {
    let src = doc(&[("# a", "io_ports = [\"0x60-0x64\", 0x64]")]);
    expect_one(
        &src,
        "0x64]",
        0,
        "partitions.a.io_ports[1]",
        "listed already",
    );
}

#[test]
fn reserved_irqs() {
    for (line, why) in [(0, "PIT"), (2, "cascade"), (4, "COM1")] {
        let src = doc(&[("# a", &format!("abilities = [\"irq\"]\nirqs = [{line}]"))]);
        expect_one(&src, &format!("[^{line}]"), 0, "partitions.a.irqs[0]", why);
    }
    let src = doc(&[("# a", "abilities = [\"irq\"]\nirqs = [3, 24]")]);
    expect_one(
        &src,
        "24",
        0,
        "partitions.a.irqs[1]",
        "not an ISA interrupt line",
    );
}

#[test]
fn irqs_need_the_irq_ability() {
    let src = doc(&[("# a", "irqs = [3]")]);
    expect_one(
        &src,
        "irqs = [^3]",
        0,
        "partitions.a.irqs",
        "lacks the `irq` ability",
    );
}

#[test]
fn irq_shared_between_partitions() {
    let src = doc(&[
        ("# a", "abilities = [\"irq\"]\nirqs = [3]"),
        ("# b", "abilities = [\"irq\"]\nirqs = [5, 3]"),
    ]);
    expect_one(
        &src,
        "3]",
        1,
        "partitions.b.irqs[1]",
        "IRQ 3 is given to partition `a`",
    );
}

// ---- PCI devices -------------------------------------------------------------------------

#[test]
fn pci_devices_are_kept_in_order() {
    let src = doc(&[(
        "# a",
        "abilities = [\"irq\"]\ndevices = [\"00:03.0\", \"0000:00:1f.7\"]",
    )]);
    let s = load_ok(&src);
    let shown: Vec<String> = s.partitions[0]
        .devices
        .iter()
        .map(|d| d.to_string())
        .collect();
    assert_eq!(shown, ["00:03.0", "00:1f.7"]);
    assert!(s.partitions[1].devices.is_empty());
}

#[test]
fn malformed_pci_address() {
    let src = doc(&[("# a", "abilities = [\"irq\"]\ndevices = [\"00:1g.0\"]")]);
    expect_one(
        &src,
        "\"00:1g.0\"",
        0,
        "partitions.a.devices[0]",
        "`00:1g.0` is not a PCI bus address: expected BUS:DEVICE.FUNCTION",
    );
    let src = doc(&[("# a", "abilities = [\"irq\"]\ndevices = [\"00:03.9\"]")]);
    expect_one(
        &src,
        "\"00:03.9\"",
        0,
        "partitions.a.devices[0]",
        "function 9 is beyond the 8 functions",
    );
}

#[test]
fn pci_device_named_twice() {
    let src = doc(&[
        ("# a", "abilities = [\"irq\"]\ndevices = [\"00:03.0\"]"),
        (
            "# b",
            "abilities = [\"irq\"]\ndevices = [\"00:04.0\", \"0000:00:03.0\"]",
        ),
    ]);
    expect_one(
        &src,
        "\"0000:00:03.0\"",
        0,
        "partitions.b.devices[1]",
        "PCI device 00:03.0 is named twice: it is given to partition `a` at line 20",
    );
    let src = doc(&[(
        "# a",
        "abilities = [\"irq\"]\ndevices = [\"00:03.0\", \"00:03.0\"]",
    )]);
    expect_one(
        &src,
        "\"00:03.0\"",
        1,
        "partitions.a.devices[1]",
        "listed already",
    );
}

#[test]
fn pci_devices_need_the_irq_ability() {
    let src = doc(&[("# a", "devices = [\"00:03.0\"]")]);
    expect_one(
        &src,
        "\"00:03.0\"",
        0,
        "partitions.a.devices",
        "lacks the `irq` ability",
    );
}

#[test]
fn a_dma_region_is_kept_with_its_flag() {
    let src = doc(&[(
        "# a",
        "abilities = [\"irq\"]\ndevices = [\"00:03.0\"]\ndma = \"512KiB\"",
    )]);
    let s = load_ok(&src);
    assert_eq!(s.partitions[0].dma, 512 * 1024);
    assert!(!s.partitions[0].dma_unconfined);
    assert_eq!(s.partitions[1].dma, 0);
}

#[test]
fn dma_needs_devices_whole_pages_and_room_in_memory() {
    let src = doc(&[("# a", "dma = \"64KiB\"")]);
    expect_one(
        &src,
        "dma = ^\"64KiB\"",
        0,
        "partitions.a.dma",
        "it owns none (add `devices` or remove `dma`)",
    );
    let devices = "abilities = [\"irq\"]\ndevices = [\"00:03.0\"]\n";
    let src = doc(&[("# a", &format!("{devices}dma = 5000"))]);
    expect_one(
        &src,
        "dma = ^5000",
        0,
        "partitions.a.dma",
        "is not a multiple of 4 KiB",
    );
    let src = doc(&[("# a", &format!("{devices}dma = 0"))]);
    expect_one(&src, "dma = ^0", 0, "partitions.a.dma", "must not be zero");
    let src = doc(&[("# a", &format!("{devices}dma = \"1MiB\""))]);
    expect_one(
        &src,
        "dma = ^\"1MiB\"",
        0,
        "partitions.a.dma",
        "the DMA region of 1MiB and the stack of 64KiB do not fit in the partition's memory of 1MiB",
    );
}

#[test]
fn dma_unconfined_needs_a_region_and_is_a_warning() {
    let src = doc(&[("# a", "dma_unconfined = true")]);
    expect_one(
        &src,
        "dma_unconfined = ^true",
        0,
        "partitions.a.dma_unconfined",
        "without a DMA region",
    );
    let region = "abilities = [\"irq\"]\ndevices = [\"00:03.0\"]\ndma = \"64KiB\"\n";
    let src = doc(&[("# a", &format!("{region}dma_unconfined = true"))]);
    let (s, warnings) = config::load_with_warnings("test.toml", &src, &any_image).unwrap();
    assert!(s.partitions[0].dma_unconfined);
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    let (line, column) = position(&src, "dma_unconfined = ^true", 0);
    assert_eq!((warnings[0].line, warnings[0].column), (line, column));
    assert_eq!(warnings[0].key_path, "partitions.a.dma_unconfined");
    assert!(warnings[0].message.contains("nothing confines their DMA"));
    let src = doc(&[("# a", &format!("{region}dma_unconfined = false"))]);
    let (s, warnings) = config::load_with_warnings("test.toml", &src, &any_image).unwrap();
    assert!(!s.partitions[0].dma_unconfined && warnings.is_empty());
}

#[test]
fn pci_configuration_ports_are_never_granted() {
    for ports in [
        "\"0xcf8-0xcff\"",
        "0xcfc",
        "\"0xc00-0xcf8\"",
        "\"0xcff-0xd00\"",
    ] {
        let src = doc(&[("# a", &format!("io_ports = [{ports}]"))]);
        expect_one(
            &src,
            ports,
            0,
            "partitions.a.io_ports[0]",
            "include 0xcf8-0xcff, which the kernel keeps for PCI configuration space",
        );
    }
}

// ---- shared memory -----------------------------------------------------------------------

const SEGMENT: &str = "[[shared_memory]]\nname = \"frame\"\nsize = \"64KiB\"\n";

#[test]
fn shared_memory_attached() {
    let src = doc(&[
        ("# a", "shared = { frame = \"rw\" }"),
        ("# b", "shared.frame = \"r\""),
        ("# tail", SEGMENT),
    ]);
    let s = load_ok(&src);
    assert_eq!(s.segments[0].size, 64 * 1024);
    assert_eq!(s.partitions[0].shared[0].segment, 0);
    assert_eq!(
        s.partitions[1].shared[0].rights,
        config::model::Rights::Read
    );
}

#[test]
fn unknown_segment() {
    let src = doc(&[("# a", "shared = { film = \"rw\" }"), ("# tail", SEGMENT)]);
    expect_one(
        &src,
        "film",
        0,
        "partitions.a.shared.film",
        "unknown shared memory segment `film`",
    );
}

#[test]
fn writable_and_executable_segment() {
    let src = doc(&[("# a", "shared = { frame = \"rwx\" }"), ("# tail", SEGMENT)]);
    expect_one(
        &src,
        "\"rwx\"",
        0,
        "partitions.a.shared.frame",
        "writable and executable at once is never allowed",
    );
}

#[test]
fn segment_size_whole_pages() {
    let src = doc(&[("# tail", &SEGMENT.replace("64KiB", "100"))]);
    expect_one(
        &src,
        "\"100\"",
        0,
        "shared_memory[0].size",
        "not a multiple of 4 KiB",
    );
}

#[test]
fn duplicate_segment() {
    let src = doc(&[("# tail", &format!("{SEGMENT}\n{SEGMENT}"))]);
    expect_one(
        &src,
        "\"frame\"",
        1,
        "shared_memory[1].name",
        "shared memory segment `frame` is already defined at line",
    );
}

// ---- ports -------------------------------------------------------------------------------

#[test]
fn unknown_port_kind_and_direction() {
    let src = doc(&[(
        "ports.out = { kind = \"sampling\", direction = \"out\"",
        "ports.out = { kind = \"mailbox\", direction = \"sideways\"",
    )]);
    expect_some(
        &src,
        "\"mailbox\"",
        0,
        "partitions.a.ports.out.kind",
        "unknown port kind \"mailbox\"",
    );
    expect_some(
        &src,
        "\"sideways\"",
        0,
        "partitions.a.ports.out.direction",
        "unknown port direction",
    );
}

#[test]
fn port_message_too_large() {
    let src = doc(&[(
        "direction = \"out\", size = 8 }",
        "direction = \"out\", size = 65537 }",
    )]);
    expect_some(
        &src,
        "65537",
        0,
        "partitions.a.ports.out.size",
        "message size 65537 is not in 1..=65536",
    );
}

#[test]
fn queuing_port_without_depth() {
    let src = doc(&[(
        "# a",
        "ports.q = { kind = \"queuing\", direction = \"out\", size = 8 }",
    )]);
    expect_some(
        &src,
        "{ kind = \"queuing\"",
        0,
        "partitions.a.ports.q",
        "a queuing port needs a `depth`",
    );
}

#[test]
fn depth_on_sampling_port() {
    let src = doc(&[(
        "direction = \"out\", size = 8 }",
        "direction = \"out\", size = 8, depth = 4 }",
    )]);
    expect_one(
        &src,
        "4 }",
        0,
        "partitions.a.ports.out.depth",
        "`depth` is only for queuing ports",
    );
}

#[test]
fn queue_depth_range() {
    let src = doc(&[(
        "# a",
        "ports.q = { kind = \"queuing\", direction = \"out\", size = 8, depth = 1000 }",
    )]);
    expect_some(
        &src,
        "1000",
        0,
        "partitions.a.ports.q.depth",
        "queue depth 1000 is not in 1..=256",
    );
}

#[test]
fn queuing_discipline_names_and_kind() {
    let src = doc(&[(
        "# a",
        "ports.q = { kind = \"queuing\", direction = \"out\", size = 8, depth = 2, discipline = \"lifo\" }",
    )]);
    expect_some(
        &src,
        "\"lifo\"",
        0,
        "partitions.a.ports.q.discipline",
        "unknown queuing discipline \"lifo\": expected \"fifo\" or \"priority\"",
    );
    let src = doc(&[(
        "direction = \"out\", size = 8 }",
        "direction = \"out\", size = 8, discipline = \"priority\" }",
    )]);
    expect_one(
        &src,
        "\"priority\" }",
        0,
        "partitions.a.ports.out.discipline",
        "`discipline` is only for queuing ports",
    );
}

#[test]
fn refresh_on_output_port() {
    let src = doc(&[(
        "direction = \"out\", size = 8 }",
        "direction = \"out\", size = 8, refresh = \"10ms\" }",
    )]);
    expect_one(
        &src,
        "\"10ms\" }",
        0,
        "partitions.a.ports.out.refresh",
        "only for sampling input ports",
    );
}

// ---- channels ----------------------------------------------------------------------------

#[test]
fn channel_unknown_partition_and_port() {
    let src = doc(&[("from = \"a.out\"", "from = \"x.out\"")]);
    expect_some(
        &src,
        "\"x.out\"",
        0,
        "channels[0].from",
        "unknown partition `x`",
    );
    let src = doc(&[("to = [\"b.in\"]", "to = [\"b.inn\"]")]);
    expect_some(
        &src,
        "\"b.inn\"",
        0,
        "channels[0].to[0]",
        "partition `b` has no port `inn`",
    );
    let src = doc(&[("to = [\"b.in\"]", "to = \"b\"")]);
    expect_some(
        &src,
        "\"b\"\n",
        0,
        "channels[0].to",
        "is not a port reference \"partition.port\"",
    );
}

#[test]
fn channel_direction_mismatch() {
    let src = doc(&[
        ("from = \"a.out\"", "from = \"b.in\""),
        ("to = [\"b.in\"]", "to = [\"a.out\"]"),
    ]);
    expect_some(
        &src,
        "\"b.in\"",
        0,
        "channels[0].from",
        "`b.in` is an input port but a channel's `from` must be direction = \"out\"",
    );
    expect_some(
        &src,
        "\"a.out\"",
        0,
        "channels[0].to[0]",
        "`a.out` is an output port but a channel's `to` must be direction = \"in\"",
    );
}

#[test]
fn channel_kind_mismatch() {
    let src = doc(&[("kind = \"sampling\"\nfrom", "kind = \"queuing\"\nfrom")]);
    expect_some(
        &src,
        "\"a.out\"",
        0,
        "channels[0].from",
        "`a.out` is a sampling port but the channel is queuing",
    );
}

#[test]
fn channel_receiver_too_small() {
    let src = doc(&[(
        "direction = \"in\", size = 8 }",
        "direction = \"in\", size = 4 }",
    )]);
    expect_one(
        &src,
        "\"b.in\"",
        0,
        "channels[0].to[0]",
        "takes messages of at most 4 bytes, less than the 8 bytes",
    );
}

#[test]
fn port_connected_twice() {
    let src = doc(&[(
        "# tail",
        "[[channels]]\nkind = \"sampling\"\nfrom = \"a.out\"\nto = \"b.in\"\nname = \"second\"\n",
    )]);
    expect_some(
        &src,
        "\"a.out\"",
        1,
        "channels[1].from",
        "already connected by channels[0]",
    );
    expect_some(
        &src,
        "\"b.in\"",
        1,
        "channels[1].to",
        "already connected by channels[0]",
    );
}

#[test]
fn destination_listed_twice() {
    let src = doc(&[("to = [\"b.in\"]", "to = [\"b.in\", \"b.in\"]")]);
    expect_one(
        &src,
        "\"b.in\"",
        1,
        "channels[0].to[1]",
        "listed already in this channel",
    );
}

#[test]
fn unconnected_port() {
    let src = doc(&[(
        "# b",
        "ports.spare = { kind = \"sampling\", direction = \"in\", size = 8 }",
    )]);
    expect_one(
        &src,
        "ports.^spare",
        0,
        "partitions.b.ports.spare",
        "port `b.spare` is connected by no channel",
    );
}

#[test]
fn queuing_channel_is_one_to_one() {
    let src = doc(&[
        (
            "# a",
            "ports.q = { kind = \"queuing\", direction = \"out\", size = 8, depth = 4 }",
        ),
        (
            "# b",
            "ports.q1 = { kind = \"queuing\", direction = \"in\", size = 8, depth = 4 }\nports.q2 = { kind = \"queuing\", direction = \"in\", size = 8, depth = 4 }",
        ),
        (
            "# tail",
            "[[channels]]\nkind = \"queuing\"\nfrom = \"a.q\"\nto = [\"b.q1\", \"b.q2\"]\n",
        ),
    ]);
    expect_some(
        &src,
        "\"b.q2\"",
        0,
        "channels[1].to[1]",
        "a queuing channel connects exactly one destination",
    );
    // 1:1 is fine, and the ports learn their channel.
    let ok = src
        .replace("to = [\"b.q1\", \"b.q2\"]", "to = \"b.q1\"")
        .replace(
            "[[channels]]\nkind = \"queuing\"",
            "[[channels]]\nkind = \"queuing\"\nname = \"q\"",
        );
    let ok = ok.replace(
        "ports.q2 = { kind = \"queuing\", direction = \"in\", size = 8, depth = 4 }",
        "",
    );
    let s = load_ok(&ok);
    assert_eq!(s.channels[1].kind, PortKind::Queuing);
    assert_eq!(s.partitions[0].ports[1].channel, 1);
    assert_eq!(s.partitions[0].ports[1].depth, 4);
}

#[test]
fn duplicate_channel_name() {
    let src = doc(&[
        ("from = \"a.out\"", "name = \"link\"\nfrom = \"a.out\""),
        (
            "# a",
            "ports.o2 = { kind = \"sampling\", direction = \"out\", size = 8 }",
        ),
        (
            "# b",
            "ports.i2 = { kind = \"sampling\", direction = \"in\", size = 8 }",
        ),
        (
            "# tail",
            "[[channels]]\nname = \"link\"\nkind = \"sampling\"\nfrom = \"a.o2\"\nto = \"b.i2\"\n",
        ),
    ]);
    expect_one(
        &src,
        "\"link\"",
        1,
        "channels[1].name",
        "channel name `link` is already used at line",
    );
}

// ---- health ------------------------------------------------------------------------------

#[test]
fn health_tables() {
    let src = doc(&[
        ("# a", "health.deadline_missed = \"warm_restart\""),
        (
            "# tail",
            "[health]\napplication_error = \"shutdown_success\"\n",
        ),
    ]);
    let s = load_ok(&src);
    assert_eq!(
        s.partitions[0].health.get(ErrorCode::DeadlineMissed),
        Some(HealthAction::WarmRestart)
    );
    assert_eq!(
        s.health.get(ErrorCode::ApplicationError),
        Some(HealthAction::ShutdownSuccess)
    );
}

#[test]
fn unknown_health_error() {
    let src = doc(&[("# a", "health.deadline_mised = \"idle\"")]);
    expect_one(
        &src,
        "deadline_mised",
        0,
        "partitions.a.health.deadline_mised",
        "unknown health error `deadline_mised`; known errors: deadline_missed,",
    );
}

#[test]
fn unknown_health_action() {
    let src = doc(&[("# tail", "[health]\npower_fail = \"panic\"\n")]);
    expect_one(
        &src,
        "\"panic\"",
        0,
        "health.power_fail",
        "unknown health action `panic`; known actions: ignore, idle, cold_restart, warm_restart, shutdown, shutdown_success",
    );
}

// ---- names, images, budgets, limits --------------------------------------------------------

#[test]
fn partition_name_rules() {
    let src = doc(&[("[partitions.b]", "[partitions.b_partition_long_name]")])
        .replace("\"b.in\"", "\"b_partition_long_name.in\"");
    expect_one(
        &src,
        "b_partition_long_name]",
        0,
        "partitions.b_partition_long_name",
        "is longer than 15 bytes",
    );
    let src = doc(&[("[partitions.b]", "[partitions.\"b b\"]")]).replace("\"b.in\"", "\"b b.in\"");
    expect_one(&src, "\"b b\"]", 0, "partitions.\"b b\"", "contains ' '");
}

#[test]
fn unknown_image() {
    let src = doc(&[(
        "image = \"app\"\nmemory = \"1MiB\"\nkernel_memory = \"64KiB\"\nmax_priority = 50\ntime",
        "image = \"ghost\"\nmemory = \"1MiB\"\nkernel_memory = \"64KiB\"\nmax_priority = 50\ntime",
    )]);
    let diags = config::load("test.toml", &src, &|name| name == "app").unwrap_err();
    assert_eq!(diags.len(), 1);
    let (line, column) = position(&src, "\"ghost\"", 0);
    assert_eq!((diags[0].line, diags[0].column), (line, column));
    assert_eq!(diags[0].key_path, "partitions.b.image");
    assert!(diags[0].message.contains("unknown image `ghost`"));
}

#[test]
fn user_memory_budget() {
    let src = doc(&[("memory = \"1MiB\"", "memory = \"500MiB\"")]);
    expect_one(
        &src,
        "\"512MiB\"",
        0,
        "system.memory",
        "only 416MiB are left for them (minus the kernel pool of 64MiB and a reserve of 32MiB",
    );
}

#[test]
fn kernel_memory_budget() {
    let src = doc(&[("kernel_memory = \"64KiB\"", "kernel_memory = \"64MiB\"")]);
    expect_one(
        &src,
        "\"512MiB\"",
        0,
        "system.memory",
        "kernel_memory quotas need 65600KiB, but the kernel pool of 64MiB",
    );
}

#[test]
fn thread_quota_budget() {
    let src = doc(&[
        ("# a", "kernel_threads = 200"),
        ("# b", "kernel_threads = 100"),
    ]);
    expect_one(
        &src,
        "\"512MiB\"",
        0,
        "system.memory",
        "kernel_threads quotas add up to 300, more than the 240",
    );
    let src = doc(&[("# a", "kernel_tasks = 0")]);
    expect_one(
        &src,
        "kernel_tasks = ^0",
        0,
        "partitions.a.kernel_tasks",
        "kernel tasks quota 0 is not in 1..=63",
    );
}

#[test]
fn too_many_partitions() {
    let mut tail = String::new();
    for i in 0..14 {
        tail.push_str(&format!(
            "[partitions.p{i}]\nimage = \"app\"\nmemory = \"4KiB\"\nstack = \"4KiB\"\nkernel_memory = \"4KiB\"\nkernel_threads = 1\nmax_priority = 1\ntime = \"background\"\n\n"
        ));
    }
    let src = doc(&[("# tail", &tail)]);
    expect_one(
        &src,
        "p13]",
        0,
        "partitions.p13",
        "too many partitions (at most 15",
    );
}

// ---- reporting ----------------------------------------------------------------------------

#[test]
fn all_problems_are_reported_in_source_order() {
    let src = doc(&[
        ("memory = \"512MiB\"", "memory = \"512MB\""),
        (
            "max_priority = 100\nports.out",
            "max_priority = 250\nports.out",
        ),
        ("# b", "abilities = [\"irq\"]\nirqs = [4]"),
        ("to = [\"b.in\"]", "to = [\"b.nope\"]"),
    ]);
    let diags = load(&src).unwrap_err();
    let paths: Vec<&str> = diags.iter().map(|d| d.key_path.as_str()).collect();
    assert_eq!(
        paths,
        [
            "system.memory",
            "partitions.a.max_priority",
            "partitions.b.ports.in",
            "partitions.b.irqs[0]",
            "channels[0].to[0]",
        ]
    );
    let text = diags[1].to_string();
    let (line, column) = position(&src, "250", 0);
    assert_eq!(
        text,
        format!(
            "test.toml:{line}:{column}: partitions.a.max_priority: max_priority (MCP) 250 is not in 1..=199: partition threads must stay below syssw's priority 200"
        )
    );
}

#[test]
fn too_many_segments() {
    let tail: String = (0..33)
        .map(|i| format!("[[shared_memory]]\nname = \"s{i}\"\nsize = \"4KiB\"\n\n"))
        .collect();
    let src = doc(&[("# tail", &tail)]);
    expect_one(
        &src,
        "[[shared_memory]]",
        32,
        "shared_memory[32]",
        "too many shared memory segments (at most 32)",
    );
}

#[test]
fn too_many_io_ranges() {
    let ports: Vec<String> = (0..65).map(|i| format!("{}", 0x1000 + i)).collect();
    let src = doc(&[("# a", &format!("io_ports = [{}]", ports.join(", ")))]);
    expect_one(
        &src,
        &format!("{}", 0x1000 + 64),
        0,
        "partitions.a.io_ports[64]",
        "too many I/O port ranges (at most 64 in a system)",
    );
}

#[test]
fn channel_without_destination() {
    let src = doc(&[("to = [\"b.in\"]", "to = []")]);
    expect_some(
        &src,
        "to = ^[]",
        0,
        "channels[0].to",
        "a channel needs at least one destination",
    );
}

#[test]
fn other_name_rules() {
    let src = doc(&[(
        "memory = \"512MiB\"",
        "memory = \"512MiB\"\nname = \"9lives\"",
    )]);
    expect_one(
        &src,
        "\"9lives\"",
        0,
        "system.name",
        "system name \"9lives\" starts with '9'",
    );
    let src = doc(&[("image = \"app\"", "image = \"my/app\"")]);
    expect_one(
        &src,
        "\"my/app\"",
        0,
        "partitions.a.image",
        "image name \"my/app\" contains '/'",
    );
}

#[test]
fn huge_values_are_errors_not_overflows() {
    let src = doc(&[
        ("memory = \"1MiB\"", "memory = \"18446744073709551615\""),
        ("memory = \"1MiB\"", "memory = \"16383TiB\""),
        ("kernel_memory = \"64KiB\"", "kernel_memory = \"16383TiB\""),
        (
            "duration = \"2ms\"",
            "duration = \"18446744073709551615ns\"",
        ),
    ]);
    let diags = load(&src).unwrap_err();
    assert!(
        diags
            .iter()
            .any(|d| d.key_path == "partitions.a.memory" && d.message.contains("4 KiB"))
    );
    assert!(diags.iter().any(|d| d.key_path == "system.memory"));
}

mod fuzz {
    use super::common::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(500))]

        /// Whatever text is spliced into a valid description, `load` reports or accepts; it
        /// never panics, and what it accepts encodes to a blob the decoder accepts.
        #[test]
        fn load_never_panics(at in 0..BASE.len(), text in "[ -~\n]{0,12}") {
            let mut at = at;
            while !BASE.is_char_boundary(at) {
                at -= 1;
            }
            let src = format!("{}{}{}", &BASE[..at], text, &BASE[at..]);
            if let Ok(system) = load(&src) {
                let blob = config::binary::encode(&system);
                prop_assert!(config::decode(&blob).is_ok());
            }
        }

        #[test]
        fn values_never_panic(value in "[0-9a-zA-Z\" .-]{0,24}") {
            for key in ["memory = \"1MiB\"", "duration = \"2ms\"", "max_priority = 100\nports.out"] {
                let replacement = format!("{} = {value}\n{}", key.split(" =").next().unwrap(),
                    key.split_once('\n').map_or("", |(_, rest)| rest));
                let src = doc(&[(key, &replacement)]);
                if let Ok(system) = load(&src) {
                    prop_assert!(config::decode(&config::binary::encode(&system)).is_ok());
                }
            }
        }
    }
}

#[test]
fn major_frame_beyond_the_kernels_limit() {
    let src = doc(&[("major_frame = \"10ms\"", "major_frame = \"7200s\"")]);
    expect_one(
        &src,
        "\"7200s\"",
        0,
        "schedules[0].major_frame",
        "the major frame of 7200s is longer than the kernel's limit of 3600s",
    );
}

#[test]
fn empty_description() {
    // The one key every description needs is reported at the start of the file.
    let diags = load("").unwrap_err();
    assert_eq!(diags.len(), 1, "{diags:?}");
    assert_eq!((diags[0].line, diags[0].column), (1, 1));
    assert!(
        diags[0].message.contains("missing field `system`"),
        "{diags:?}"
    );
}

#[test]
fn binary_garbage_is_a_syntax_error() {
    // Not UTF-8 text at all is the caller's to refuse (check-config reads a String); NULs,
    // control bytes and random symbols in text are TOML syntax errors with positions.
    let mut x: u64 = 0x5eed;
    let garbage: String = (0..4096)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            char::from((x % 128) as u8)
        })
        .collect();
    let diags = load(&garbage).unwrap_err();
    assert!(!diags.is_empty());
    assert!(
        diags
            .iter()
            .all(|d| d.message.starts_with("TOML syntax") && d.line >= 1)
    );
}

#[test]
fn very_large_descriptions_are_refused_by_the_limits_not_by_exhaustion() {
    // 2,000 partitions (a 200 KB file): refused as too many, naming the first one beyond
    // the limit (and no rule loops over them in a way a user would wait for).
    let mut src = BASE.to_string();
    for i in 0..2_000 {
        src.push_str(&format!(
            "\n[partitions.p{i}]\nimage = \"app\"\nmemory = \"1MiB\"\nkernel_memory = \"64KiB\"\nmax_priority = 10\ntime = \"background\"\n"
        ));
    }
    let diags = load(&src).unwrap_err();
    assert!(
        diags
            .iter()
            .any(|d| d.key_path == "partitions.p13" && d.message.contains("too many partitions")),
        "{:?}",
        &diags[..diags.len().min(5)]
    );
}

// ---- hostile input: what a mistaken or malicious file gives check-config -----------------

#[test]
fn bytes_that_are_not_utf8_are_reported_where_they_start() {
    let mut bytes = b"[system]\nmemory = \"512MiB\"\nname = \"caf".to_vec();
    bytes.extend_from_slice(&[0xe9, b'"', b'\n']); // Latin-1 e-acute, not UTF-8
    let d = config::text("test.toml", &bytes).unwrap_err();
    assert_eq!(
        (d.file.as_str(), d.line, d.column),
        ("test.toml", 3, 12),
        "{d}"
    );
    assert!(d.key_path.is_empty());
    assert!(
        d.message
            .contains("not UTF-8 text (byte 0xe9 at offset 38)"),
        "{d}"
    );
    // A whole binary file: the first byte already.
    let d = config::text("test.toml", &[0x7f, 0x45, 0x4c, 0x46, 0x02, 0xff, 0x00]).unwrap_err();
    assert_eq!((d.line, d.column), (1, 6), "{d}");
    assert_eq!(config::text("test.toml", b"[system]\n"), Ok("[system]\n"));
}

#[test]
fn a_nul_byte_in_a_string_is_a_syntax_error_at_the_byte() {
    let src = doc(&[(
        "memory = \"512MiB\"",
        "memory = \"512MiB\"\nname = \"a\u{0}b\"",
    )]);
    expect_one(
        &src,
        "name = \"a^\u{0}",
        0,
        "system.name",
        "TOML syntax: invalid basic string",
    );
}

#[test]
fn control_characters_as_a_key_are_a_syntax_error_at_the_key() {
    let src = doc(&[("# tail", "\u{1}\u{2} = 3")]);
    let diags = load(&src).unwrap_err();
    let (line, column) = position(&src, "\u{1}\u{2} = 3", 0);
    assert!(
        diags.iter().any(|d| (d.line, d.column) == (line, column)
            && d.message.contains("TOML syntax: invalid unquoted key")),
        "{diags:?}"
    );
}

#[test]
fn deeply_nested_values_are_refused_not_a_stack_overflow() {
    for value in [
        format!("{}{}", "[".repeat(100_000), "]".repeat(100_000)),
        format!("{}1{}", "{ a = ".repeat(50_000), " }".repeat(50_000)),
    ] {
        // (`# tail` lies in the last `[[channels]]` table.)
        let src = doc(&[("# tail", &format!("deep = {value}"))]);
        let diags = load(&src).unwrap_err();
        let (line, _) = position(&src, "deep = ", 0);
        assert!(
            diags.iter().any(|d| d.line == line
                && d.key_path.starts_with("channels[0].deep")
                && d.message.contains("max recursion depth")),
            "{:?}",
            &diags[..diags.len().min(3)]
        );
    }
}

#[test]
fn a_megabyte_name_is_refused_by_the_name_rule_at_its_key() {
    let name = "p".repeat(1 << 20);
    let src = doc(&[(
        "# tail",
        &format!(
            "[partitions.{name}]\nimage = \"app\"\nmemory = \"1MiB\"\nkernel_memory = \"64KiB\"\nmax_priority = 10\ntime = \"background\""
        ),
    )]);
    expect_one(
        &src,
        &format!("[partitions.^{name}]"),
        0,
        &format!("partitions.{name}"),
        "is longer than 15 bytes",
    );
}

#[test]
fn an_eight_megabyte_file_is_checked_in_seconds() {
    // An 8 MB comment: valid, and checked in seconds (about 3 s in a debug build).
    let src = format!("{BASE}# {}\n", "x".repeat(8 << 20));
    let started = std::time::Instant::now();
    load_ok(&src);
    assert!(started.elapsed().as_secs() < 60, "{:?}", started.elapsed());
}

// ---- CPUs -------------------------------------------------------------------------------

/// `BASE` on two CPUs (`[system] cpus = 2`), with `edits` applied after.
fn two_cpus(edits: &[(&str, &str)]) -> String {
    let mut all = vec![("memory = \"512MiB\"", "memory = \"512MiB\"\ncpus = 2")];
    all.extend_from_slice(edits);
    doc(&all)
}

/// Partition `c` (windowed, `max_priority = 100`) on CPU `cpu` with a window at 1ms..3ms
/// in the only schedule, for `# tail`.
fn partition_c(cpu: u8) -> String {
    format!(
        "[partitions.c]\nimage = \"app\"\nmemory = \"1MiB\"\nkernel_memory = \"64KiB\"\nmax_priority = 100\ncpus = [{cpu}]\n\n[[schedules.windows]]\npartition = \"c\"\noffset = \"1ms\"\nduration = \"2ms\"\n"
    )
}

#[test]
fn one_cpu_and_cpu_zero_by_default() {
    let s = load_ok(BASE);
    assert_eq!(s.cpus, 1);
    assert!(s.partitions.iter().all(|p| p.cpu == 0));
    let window = s.schedules[0].windows[0];
    assert_eq!((window.cpu, window.spec().cpu), (0, 0));
}

#[test]
fn system_cpus_within_the_kernels_limit() {
    assert_eq!(load_ok(&two_cpus(&[])).cpus, 2);
    let eight = doc(&[("memory = \"512MiB\"", "memory = \"512MiB\"\ncpus = 8")]);
    assert_eq!(load_ok(&eight).cpus, 8);
    for n in ["0", "9", "-1"] {
        let src = doc(&[(
            "memory = \"512MiB\"",
            &format!("memory = \"512MiB\"\ncpus = {n}"),
        )]);
        expect_one(
            &src,
            &format!("cpus = ^{n}"),
            0,
            "system.cpus",
            &format!("cpus = {n} is not in 1..=8 (the most CPUs the kernel runs)"),
        );
    }
}

#[test]
fn partitions_and_their_windows_carry_their_cpu() {
    // `a` on CPU 1: its window (without `cpu`) is in CPU 1's schedule.
    let s = load_ok(&two_cpus(&[("# a", "cpus = [1]")]));
    assert_eq!(s.cpus, 2);
    assert_eq!((s.partitions[0].cpu, s.partitions[1].cpu), (1, 0));
    let window = s.schedules[0].windows[0];
    assert_eq!((window.cpu, window.spec().cpu), (1, 1));
    // Saying so changes nothing.
    let explicit = two_cpus(&[
        ("# a", "cpus = [1]"),
        ("duration = \"2ms\"", "duration = \"2ms\"\ncpu = 1"),
    ]);
    assert_eq!(load_ok(&explicit), s);
}

/// `a` on CPUs 0 and 1 with its window at 0..2ms on CPU 0 and another at 4..6ms on CPU 1.
fn a_on_two_cpus() -> String {
    two_cpus(&[
        ("# a", "cpus = [0, 1]"),
        (
            "duration = \"2ms\"",
            "duration = \"2ms\"\ncpu = 0\n\n[[schedules.windows]]\npartition = \"a\"\noffset = \"4ms\"\nduration = \"2ms\"\ncpu = 1",
        ),
    ])
}

#[test]
fn a_partition_runs_on_several_cpus_in_each_ones_windows() {
    let s = load_ok(&a_on_two_cpus());
    let a = &s.partitions[0];
    assert_eq!(
        (a.cpus, a.cpu),
        (0b11, 0),
        "both CPUs; its first thread on CPU 0"
    );
    let on: Vec<_> = s.schedules[0]
        .windows
        .iter()
        .map(|w| (w.offset, w.cpu))
        .collect();
    assert_eq!(on, [(0, 0), (4_000_000, 1)]);
    // Overlapping windows of the partition on its two CPUs: it runs on both at once.
    let overlapping = a_on_two_cpus().replace("offset = \"4ms\"", "offset = \"1ms\"");
    assert_eq!(
        load_ok(&overlapping).schedules[0].windows[1].offset,
        1_000_000
    );
    // Windows on one CPU still must not overlap.
    let same_cpu = a_on_two_cpus()
        .replace("cpu = 1", "cpu = 0")
        .replace("offset = \"4ms\"", "offset = \"1ms\"");
    let errors = load(&same_cpu).expect_err("windows of one CPU overlap");
    assert!(
        errors.iter().any(|d| d.message.contains("overlap")),
        "{errors:?}"
    );
}

#[test]
fn a_several_cpu_partitions_windows_name_their_cpu_and_cover_each_cpu() {
    let src = two_cpus(&[("# a", "cpus = [0, 1]")]);
    expect_one(
        &src,
        "partition = ^\"a\"",
        0,
        "schedules[0].windows[0].partition",
        "partition `a` runs on CPUs 0 and 1: say in which CPU's schedule this window is, e.g. `cpu = 0`",
    );
    let src = two_cpus(&[
        ("# a", "cpus = [0, 1]"),
        ("duration = \"2ms\"", "duration = \"2ms\"\ncpu = 1"),
    ]);
    expect_one(
        &src,
        "[partitions.^a]",
        0,
        "partitions.a.cpus",
        "partition `a` runs on CPUs 0 and 1, but time partition 1 has no window on CPU 0: its threads there would never run (add a window with `cpu = 0`)",
    );
    let src = doc(&[
        ("memory = \"512MiB\"", "memory = \"512MiB\"\ncpus = 3"),
        ("# a", "cpus = [0, 2]"),
        ("duration = \"2ms\"", "duration = \"2ms\"\ncpu = 1"),
    ]);
    expect_one(
        &src,
        "cpu = ^1",
        0,
        "schedules[0].windows[0].cpu",
        "partition `a` runs on CPUs 0 and 2; this window is on CPU 1 (a partition's windows are in the schedule of one of its CPUs)",
    );
}

#[test]
fn a_partitions_cpu_list_is_not_empty_and_names_each_cpu_once() {
    let src = two_cpus(&[("# a", "cpus = [1, 1]")]);
    expect_one(
        &src,
        "cpus = [1, ^1]",
        0,
        "partitions.a.cpus[1]",
        "partition `a` lists CPU 1 twice",
    );
    let src = two_cpus(&[("# a", "cpus = []")]);
    expect_one(
        &src,
        "cpus = ^[]",
        0,
        "partitions.a.cpus",
        "partition `a` names no CPU: give at least one, e.g. `cpus = [0]`",
    );
}

#[test]
fn a_partition_on_a_cpu_the_system_does_not_use() {
    let src = doc(&[("# a", "cpus = [1]")]);
    expect_one(
        &src,
        "cpus = [^1]",
        0,
        "partitions.a.cpus[0]",
        "partition `a` runs on CPU 1, but the system uses 1 CPU, CPU 0 (`cpus` in [system], default 1)",
    );
    let src = two_cpus(&[("# b", "cpus = [2]")]);
    expect_one(
        &src,
        "cpus = [^2]",
        0,
        "partitions.b.cpus[0]",
        "partition `b` runs on CPU 2, but the system uses 2 CPUs, 0 to 1 (`[system] cpus = 2`)",
    );
    let src = two_cpus(&[("# b", "cpus = [-1]")]);
    expect_one(
        &src,
        "cpus = [^-1]",
        0,
        "partitions.b.cpus[0]",
        "partition `b`: -1 is not a CPU number (CPU 0 is the boot CPU)",
    );
}

#[test]
fn a_window_on_another_cpu_than_its_partition() {
    let src = two_cpus(&[
        ("# a", "cpus = [1]"),
        ("duration = \"2ms\"", "duration = \"2ms\"\ncpu = 0"),
    ]);
    expect_one(
        &src,
        "cpu = ^0",
        0,
        "schedules[0].windows[0].cpu",
        "partition `a` runs on CPU 1; this window is on CPU 0 (a partition's windows are in the schedule of its CPU)",
    );
}

#[test]
fn a_window_on_a_cpu_the_system_does_not_use() {
    let src = doc(&[("duration = \"2ms\"", "duration = \"2ms\"\ncpu = 1")]);
    expect_one(
        &src,
        "cpu = ^1",
        0,
        "schedules[0].windows[0].cpu",
        "the window is on CPU 1, but the system uses 1 CPU, CPU 0 (`cpus` in [system], default 1)",
    );
    let src = two_cpus(&[("duration = \"2ms\"", "duration = \"2ms\"\ncpu = 2")]);
    expect_one(
        &src,
        "cpu = ^2",
        0,
        "schedules[0].windows[0].cpu",
        "the window is on CPU 2, but the system uses 2 CPUs, 0 to 1 (`[system] cpus = 2`)",
    );
}

#[test]
fn windows_of_different_cpus_may_overlap() {
    // a (CPU 0) 0ms..2ms and c (CPU 1) 1ms..3ms.
    let s = load_ok(&two_cpus(&[("# tail", &partition_c(1))]));
    let windows: Vec<(u64, u8, u8)> = s.schedules[0]
        .windows
        .iter()
        .map(|w| (w.offset, w.cpu, w.time_partition))
        .collect();
    assert_eq!(windows, [(0, 0, 1), (1_000_000, 1, 2)]);
    // Both on CPU 0: they overlap.
    let src = two_cpus(&[("# tail", &partition_c(0))]);
    expect_one(
        &src,
        "\"1ms\"",
        0,
        "schedules[0].windows[1].offset",
        "the window 1ms..3ms overlaps window 0 (0ns..2ms), both on CPU 0 (the windows of one CPU must not overlap; those of different CPUs may)",
    );
}

#[test]
fn a_fixed_time_partition_needs_a_window_on_its_cpu() {
    // c shares a's time partition 1, whose only window is on CPU 0.
    let c = |cpu| {
        format!(
            "[partitions.c]\nimage = \"app\"\nmemory = \"1MiB\"\nkernel_memory = \"64KiB\"\nmax_priority = 100\ntime = 1\ncpus = [{cpu}]\n"
        )
    };
    load_ok(&two_cpus(&[("# a", "time = 1"), ("# tail", &c(0))]));
    let src = two_cpus(&[("# a", "time = 1"), ("# tail", &c(1))]);
    expect_one(
        &src,
        "time = ^1",
        1,
        "partitions.c.time",
        "time partition 1 of partition `c` has no window on CPU 1, the CPU it runs on",
    );
}

#[test]
fn a_background_partition_competes_only_on_its_cpu() {
    // b (background, MCP 100) would outrank a (priority 100) in a's window on CPU 0; on
    // CPU 1 there is no window to take.
    let above = ("max_priority = 50", "max_priority = 100");
    load_ok(&two_cpus(&[above, ("# b", "cpus = [1]")]));
    let src = two_cpus(&[above, ("# b", "cpus = [0]")]);
    expect_one(
        &src,
        "max_priority = ^100\ntime",
        0,
        "partitions.b.max_priority",
        "background partition `b` has max_priority 100 >= priority 100 of windowed partition `a`",
    );
}
