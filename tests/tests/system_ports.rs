//! A guest partition reaching its ARINC ports as Linux devices, `/dev/arinc/<port>`.
//!
//! `system_devices` (configuration `tests/configs/system_devices.toml`): the static C
//! program `linux-arinc check` (`tests/linux/arinc.c`, expected output
//! `tests/linux/arinc.out`) and busybox one-liners (`tests/configs/guest/devices.sh`)
//! write, read, poll and ask the validity of ports looped back to the guest, and of the
//! plant's level and the PLC's online ports.
//!
//! `system_plcctl` (configuration `tests/configs/system_plcctl.toml`): busybox reads the
//! plant's level from `/dev/arinc/level`, and `plcctl` lists, reads, forces, unforces,
//! watches, asks the statistics of the tank PLC over `/dev/arinc/plc-request` and
//! `/dev/arinc/plc-response`, downloads a file that is no program (refused) and the
//! changed controller (which then runs), then reads from and is refused a force and a
//! download by a monitor-only PLC over two other ports.

use scenarios::{boot, check};

/// The lines of `out` from the first that starts with `prefix` on, at most `n` of them.
fn from<'o>(out: &'o [String], prefix: &str, n: usize) -> &'o [String] {
    let start = out
        .iter()
        .position(|l| l.starts_with(prefix))
        .unwrap_or(out.len());
    &out[start..(start + n).min(out.len())]
}

/// The number after `name=` or `name = ` in `line`.
fn number(line: &str, name: &str) -> Option<f64> {
    let (_, rest) = line
        .split_once(&format!("{name} = "))
        .or_else(|| line.split_once(&format!("{name}=")))?;
    rest.split_whitespace().next()?.parse().ok()
}

/// What `linux-arinc check` prints in a guest of `system_devices`, line by line.
const ARINC_EXPECTED: &str = include_str!("../linux/arinc.out");

#[test]
fn system_devices() {
    let o = boot("system_devices");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the end of the guest's script ends the run",
    );
    for needle in [
        "unsupported system call",
        "cannot create it",
        "/etc/guest/ports line",
    ] {
        check(
            &o,
            o.line(needle).is_none(),
            &format!("unexpected {needle:?}"),
        );
    }
    let out = scenarios::guest_output(&o);
    // The C program: every check, in order, and its exit status.
    let expected: Vec<&str> = ARINC_EXPECTED.lines().collect();
    let got: Vec<&str> = out
        .iter()
        .map(String::as_str)
        .take_while(|l| !l.starts_with("arinc status "))
        .collect();
    let differences: Vec<String> = expected
        .iter()
        .zip(got.iter().chain(std::iter::repeat(&"(nothing)")))
        .filter(|(e, g)| e != g)
        .map(|(e, g)| format!("expected {e:?} got {g:?}"))
        .collect();
    check(
        &o,
        differences.is_empty() && got.len() == expected.len(),
        &format!(
            "linux-arinc check: {} lines, expected {}; {differences:#?}",
            got.len(),
            expected.len()
        ),
    );
    check(
        &o,
        out.iter().any(|l| l == "arinc status 0"),
        "linux-arinc check exited with status 0",
    );
    // The busybox one-liners.
    for line in [
        "devices: level plc-request plc-response queue-in queue-out sample-in sample-out ",
        "sampling: ping",
        "sampling again: ping",
        "queuing: onetwo",
        "waited for: late",
        "dd: /dev/arinc/sample-in: Message too long",
        "dd: error writing '/dev/arinc/queue-out': Message too long",
        "done",
    ] {
        check(
            &o,
            out.iter().any(|l| l == line),
            &format!("the shell did not print {line:?}"),
        );
    }
    let words = |prefix: &str| -> Vec<String> {
        out.iter()
            .find_map(|l| l.strip_prefix(prefix))
            .map(|rest| rest.split_whitespace().map(str::to_string).collect())
            .unwrap_or_default()
    };
    check(
        &o,
        words("queuing bytes: ") == ["1", "2", "255"],
        "od of a queuing message's bytes",
    );
    check(
        &o,
        words("plc answer: ") == ["2", "7", "0", "10"],
        "the PLC's answer to a READ written with printf (op, seq, OK, LREAL)",
    );
    let level = words("level: ").first().and_then(|v| v.parse::<f64>().ok());
    check(
        &o,
        level.is_some_and(|l| (0.0..=2.0).contains(&l)),
        &format!("od read the plant's level from /dev/arinc/level: {level:?}"),
    );
}

#[test]
fn system_plcctl() {
    let o = boot("system_plcctl");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the end of the guest's script ends the run",
    );
    for needle in [
        "unsupported system call",
        "cannot create it",
        "/etc/guest/ports line",
    ] {
        check(
            &o,
            o.line(needle).is_none(),
            &format!("unexpected {needle:?}"),
        );
    }
    check(
        &o,
        o.line("[linux] guest: init exited with status 0").is_some(),
        "the script ended with status 0",
    );
    let out = scenarios::guest_output(&o);
    let level = out
        .iter()
        .find_map(|l| l.strip_prefix("level "))
        .and_then(|v| v.trim().parse::<f64>().ok());
    check(
        &o,
        level.is_some_and(|l| (0.0..=2.0).contains(&l)),
        &format!("od read the plant's level from /dev/arinc/level: {level:?}"),
    );
    check(
        &o,
        out.iter()
            .any(|l| l == "dd: /dev/arinc/level: Message too long"),
        "a read smaller than the port's messages is EMSGSIZE",
    );
    check(
        &o,
        out.iter().any(|l| l == "answer 2 7 0 10"),
        "a READ written with printf, its answer (op, seq, OK, LREAL) read by a waiting dd",
    );
    for var in [
        "level LREAL",
        "valve LREAL",
        "alarm BOOL",
        "tank.alarm_count UDINT",
    ] {
        check(
            &o,
            out.iter().any(|l| l == var),
            &format!("plcctl list: {var}"),
        );
    }
    let read = from(&out, "level = ", 3);
    check(
        &o,
        read.len() == 3
            && number(&read[0], "level").is_some()
            && number(&read[1], "valve").is_some()
            && (read[2] == "alarm = FALSE" || read[2] == "alarm = TRUE"),
        &format!("plcctl read level valve alarm: {read:?}"),
    );
    check(
        &o,
        from(&out, "forced ", 3) == ["forced valve = 0.25", "valve = 0.25", "unforced valve"],
        "plcctl force, read, unforce",
    );
    let stats = from(&out, "task ", 1);
    check(
        &o,
        stats.len() == 1
            && stats[0].starts_with("task CYCLE.tank stopped=false cycles=")
            && stats[0].contains(" overruns=")
            && stats[0].ends_with(" faults=0"),
        &format!("plcctl stats: {stats:?}"),
    );
    let watch = from(&out, "t=0 ", 3);
    check(
        &o,
        watch.len() == 3
            && ["t=0 ", "t=100 ", "t=200 "]
                .iter()
                .zip(watch)
                .all(|(t, l)| l.starts_with(t) && number(l, "level").is_some()),
        &format!("plcctl watch: {watch:?}"),
    );
    for (first, second) in [
        (
            "plcctl: DOWNLOAD_COMMIT: REFUSED (the PLC's checks refused the program; its log says why)",
            "download status 1",
        ),
        (
            "plcctl: FORCE Count.n: FORBIDDEN (the client's access in the PLC's configuration does not allow it)",
            "force status 1",
        ),
        (
            "plcctl: DOWNLOAD_BEGIN: FORBIDDEN (the client's access in the PLC's configuration does not allow it)",
            "counter download status 1",
        ),
        (
            "plcctl: READ tank.revision: UNKNOWN_NAME (no variable of that name)",
            "revision status 1",
        ),
        (
            "plcctl: READ nothing: UNKNOWN_NAME (no variable of that name)",
            "read status 1",
        ),
    ] {
        check(
            &o,
            from(&out, first, 2) == [first, second],
            &format!("a refusal: {first}"),
        );
    }
    check(
        &o,
        o.line("[plc] plc: download refused: ").is_some(),
        "the PLC logs why it refused the download",
    );
    check(
        &o,
        out.iter().any(|l| l == "compiled in the guest"),
        "plcc did not compile the changed controller in the guest",
    );
    let downloaded = from(&out, "downloaded ", 2);
    check(
        &o,
        downloaded.len() == 2
            && downloaded[0].starts_with("downloaded /root/tank_v2.plcb: ")
            && downloaded[0].contains(" bytes, running from release ")
            && downloaded[1] == "tank.revision = 2",
        &format!("plcctl download of the changed controller: {downloaded:?}"),
    );
    let count = out.iter().find_map(|l| l.strip_prefix("Count.n = "));
    check(
        &o,
        count.is_some_and(|n| n.parse::<u64>().is_ok()),
        &format!("plcctl --request/--response read the counter PLC: {count:?}"),
    );
    check(
        &o,
        out.last().is_some_and(|l| l == "done"),
        "the script ran to its end",
    );
}
