//! The whole system: the default system as `cargo xtask run` boots it, with commands
//! typed into its console and its httpd's page fetched from the host (`system_default`,
//! `config/systems/plc-guest.toml`); the soft-PLC
//! controls the plant while a hostile guest runs in the background (`system_hostile_guest`,
//! configuration `tests/configs/system_hostile_guest.toml`, the guest's init
//! `tests/configs/guest/hostile.sh`); and the guest gets the time the windows leave
//! (`system_leftover`, `tests/configs/system_leftover.toml`); the default system's web HMI
//! in a real browser (`net_hmi`).

use scenarios::browser::Browser;
use scenarios::tank::{self, BAND, DISTURBANCE_MS, SETTLED_MS};
use scenarios::{boot, boot_beside, boot_while, check, http_get, kernel_seconds};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use xtask::qemu::Ending;

/// When the level is back in the band after the plant's first disturbance.
const RECOVERED_MS: u64 = DISTURBANCE_MS.1 + 1_000;
/// The PLC's release lateness (cycle start minus window start) the guest must not push
/// beyond. Without a guest a cycle starts 27 us after its window (virtual time, scenario
/// `plc_tank`); in this run at most 63 us. A variant of the script (other moments of its
/// processes' forks and exits) had one window start 0.3 ms late: the kernel finishes a
/// call of the guest before it switches windows.
const JITTER_BOUND_US: u64 = 500;

/// The value of `name=` in a PLC statistics line: its `/`-separated numbers.
fn field(line: &str, name: &str) -> Vec<u64> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(name))
        .map(|v| v.split('/').filter_map(|x| x.parse().ok()).collect())
        .unwrap_or_default()
}

/// The `t=<ms>ms` of a PLC line.
fn plc_t_ms(line: &str) -> Option<u64> {
    line.split("plc: t=")
        .nth(1)?
        .split("ms")
        .next()?
        .parse()
        .ok()
}

#[test]
fn system_hostile_guest() {
    let o = boot("system_hostile_guest");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the stopwatch ends the run",
    );

    // The guest ran every attack, crashed, and came back with a shell that runs commands.
    for step in [
        "hostile: cpu hog started",
        "hostile: dd of a 200 MiB block ended with status ",
        "hostile: memory hog ended with status ",
        "hostile: 64 MiB into the file system, dd ended with status 1",
        "hostile: idle phase over",
        "hostile: pipe flood done",
        "hostile: port flood done",
        "threads: ",
        " created, then EAGAIN",
        "hostile: thread bomb done",
        "hostile: fork bomb running: ",
        "can't fork: Resource temporarily unavailable",
        "hostile: crash",
    ] {
        check(
            &o,
            o.line(step).is_some(),
            &format!("the guest did not log {step:?}"),
        );
    }
    // The port flood: requests went to the PLC (every call a request to syssw), the queue
    // was full for many, and answers came back, refusals included.
    let floods: Vec<Vec<u64>> = o
        .lines
        .iter()
        .filter_map(|l| l.split_once(" stdout: flood: ").map(|(_, f)| f))
        .map(|f| {
            f.split(|c: char| !c.is_ascii_digit())
                .filter_map(|n| n.parse().ok())
                .collect()
        })
        .collect();
    println!(
        "port floods (calls, sent, refused, answers, OK, FORBIDDEN, MALFORMED, other): {floods:?}"
    );
    check(
        &o,
        floods.len() >= 2
            && floods.iter().all(|f| f.len() == 8 && f[1] > 0 && f[2] > 0)
            && floods.iter().map(|f| f[3]).sum::<u64>() > 0,
        &format!("the port flooders sent, were refused (full queue) and got answers: {floods:?}"),
    );
    check(
        &o,
        floods
            .iter()
            .map(|f| f.get(5).unwrap_or(&0) + f.get(6).unwrap_or(&0))
            .sum::<u64>()
            > 0,
        &format!("the PLC refused the forbidden or malformed requests: {floods:?}"),
    );
    let crash = o
        .lines
        .iter()
        .position(|l| l.contains("[linux] guest: init killed by signal 11"));
    check(
        &o,
        crash.is_some(),
        "the guest's init did not die of SIGSEGV",
    );
    let reboot = crash.and_then(|at| {
        o.lines[at..]
            .iter()
            .position(|l| l.contains("hostile: boot: a fresh shell, pid 1, runs commands"))
    });
    check(
        &o,
        reboot.is_some(),
        "the restarted guest did not run its shell again",
    );

    // The plant: in the band from SETTLED_MS to the disturbance and from the end of it to
    // the end of the run (the guest's crash and restart included), with the PLC's setpoint
    // and a fresh valve command in every status line.
    let status = tank::status(&o);
    tank::settles(&o, &status);
    tank::holds(
        &o,
        &status,
        |t| (SETTLED_MS..DISTURBANCE_MS.0).contains(&t) || t >= RECOVERED_MS,
        0,
    );

    // The PLC's release lateness with an idle guest (the `period` lines whose second lies
    // in the 3 s after a boot of the guest) and under attack (whose second lies after the
    // idle phase; the guest's crash and restart included): reported, and bounded like
    // the statistics lines' below. A line at kernel time T covers the second before T.
    let (mut idle, mut hostile) = (Vec::new(), Vec::new());
    let mut phase: Option<(bool, f64)> = None; // (idle, since when)
    for line in &o.lines {
        let Some(at) = kernel_seconds(line) else {
            continue;
        };
        if line.contains("hostile: boot: a fresh shell") {
            phase = Some((true, at));
        } else if line.contains("hostile: idle phase over") {
            phase = Some((false, at));
        } else if let Some(("plc", period)) = xtask::plot::period_line(line)
            && let Some((is_idle, since)) = phase
            && at - 1.0 >= since
        {
            if is_idle { &mut idle } else { &mut hostile }.push(period.lateness_ns);
        }
    }
    let summary = |periods: &[(u64, u64, u64)]| {
        let mut medians: Vec<u64> = periods.iter().map(|p| p.1).collect();
        medians.sort_unstable();
        (
            periods.len(),
            medians.get(medians.len() / 2).copied().unwrap_or(0),
            periods.iter().map(|p| p.2).max().unwrap_or(0),
        )
    };
    let (idle_s, idle_median, idle_max) = summary(&idle);
    let (hostile_s, hostile_median, hostile_max) = summary(&hostile);
    println!(
        "PLC release lateness (virtual time): idle guest {idle_s} s, median of the seconds' medians {idle_median} ns, max {idle_max} ns; hostile guest {hostile_s} s, median {hostile_median} ns, max {hostile_max} ns"
    );
    check(
        &o,
        idle_s >= 2 && hostile_s >= 20,
        &format!("{idle_s} idle and {hostile_s} hostile seconds of PLC period lines"),
    );
    check(
        &o,
        idle_max.max(hostile_max) <= JITTER_BOUND_US * 1000,
        &format!("a release later than {JITTER_BOUND_US} us"),
    );

    // The PLC: one cycle per 10 ms frame, none late beyond the bound, no overrun or fault,
    // in every statistics line of the run.
    let stats: Vec<&String> = o
        .lines
        .iter()
        .filter(|l| l.contains("[plc] plc: t=") && l.contains(" task="))
        .collect();
    check(
        &o,
        stats.len() >= 30,
        &format!("{} PLC statistics lines", stats.len()),
    );
    for line in &stats {
        let t = plc_t_ms(line).unwrap_or(0);
        let cycles = field(line, "cycles=").first().copied().unwrap_or(0);
        check(
            &o,
            cycles + 2 >= t / 10 && cycles <= t / 10 + 2,
            &format!("{line}: a cycle was missed (one per 10 ms frame)"),
        );
        let jitter = field(line, "jitter_us=");
        check(
            &o,
            jitter.len() == 2 && jitter[1] <= JITTER_BOUND_US,
            &format!("{line}: release lateness above {JITTER_BOUND_US} us"),
        );
        check(
            &o,
            line.contains("overruns=0 faults=0"),
            &format!("{line}: overruns or faults"),
        );
    }
}

/// `cpu: at <s> s CPU time us TP0=<us> ... TP4=<us> idle=<us>` lines as (s, [TP0..TP4], idle).
fn accounting(lines: &[String]) -> Vec<(u64, [u64; 5], u64)> {
    lines
        .iter()
        .filter_map(|l| {
            let rest = &l[l.find("[cpu] cpu: at ")? + "[cpu] cpu: at ".len()..];
            let (s, rest) = rest.split_once(" s CPU time us ")?;
            let mut values = rest.split_whitespace().map(|w| {
                w.split_once('=')
                    .and_then(|(_, v)| v.parse::<u64>().ok())
                    .unwrap_or(u64::MAX)
            });
            let mut tp = [0; 5];
            for t in &mut tp {
                *t = values.next()?;
            }
            Some((s.parse().ok()?, tp, values.next()?))
        })
        .collect()
}

#[test]
fn system_leftover() {
    let o = boot("system_leftover");
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        o.succeeded(),
        "expected success exit (33): the stopwatch ends the run",
    );
    // Over 30 s: the CPU was never idle, and the guest (TP0) got all the time the windowed
    // partitions (TP1..TP3) did not use: the gaps (6 ms of each 10 ms frame) and most of
    // the windows.
    let cpu = accounting(&o.lines);
    let first = cpu.iter().find(|(s, _, _)| *s == 3);
    let last = cpu.iter().find(|(s, _, _)| *s == 33);
    check(
        &o,
        first.is_some() && last.is_some(),
        "no CPU time lines at 3 s and 33 s",
    );
    let (Some((_, tp0, idle0)), Some((_, tp1, idle1))) = (first, last) else {
        return;
    };
    let span_us = 30_000_000;
    let used: Vec<u64> = (0..5).map(|i| tp1[i] - tp0[i]).collect();
    let windowed: u64 = used[1..].iter().sum();
    let idle = idle1 - idle0;
    println!("CPU time over 30 s (us): TP0..TP4 {used:?}, idle {idle}");
    check(
        &o,
        idle <= span_us / 100,
        &format!("the CPU was idle {idle} us of 30 s"),
    );
    // Each of the six counters is printed truncated to whole microseconds, so their sum over
    // a span may exceed it by up to one microsecond per counter.
    let total = used[0] + windowed + idle;
    check(
        &o,
        total <= span_us + 6 && total >= span_us * 98 / 100,
        &format!("the CPU times {used:?} and idle {idle} do not add up to 30 s"),
    );
    check(
        &o,
        used[0] >= span_us * 90 / 100,
        &format!(
            "the guest got {} us of 30 s, not the gaps and the unused window time",
            used[0]
        ),
    );
    // The PLC got its whole window when its burst needed it: the longest cycle took most of
    // the 3 ms window, with one cycle per frame and no overrun.
    let stats = o
        .lines
        .iter()
        .rev()
        .find(|l| l.contains("[plc] plc: t=") && l.contains(" task="));
    check(&o, stats.is_some(), "no PLC statistics line");
    if let Some(line) = stats {
        let t = plc_t_ms(line).unwrap_or(0);
        let cycles = field(line, "cycles=").first().copied().unwrap_or(0);
        let exec = field(line, "exec_us=");
        check(
            &o,
            cycles + 2 >= t / 10 && cycles <= t / 10 + 2,
            &format!("{line}: a cycle was missed (one per 10 ms frame)"),
        );
        check(
            &o,
            exec.len() == 4 && exec[3] >= 2_000 && exec[3] < 3_000,
            &format!("{line}: the burst did not take most of the 3 ms window"),
        );
        check(
            &o,
            line.contains("overruns=0 faults=0"),
            &format!("{line}: overruns or faults"),
        );
    }
}

/// `plcctl --connect 127.0.0.1:PORT --key config/systems/plc-guest/keys/engineering.key
/// read NAME`'s line, once the PLC answers.
fn online_read(port: u16, name: &str) -> Option<String> {
    let key = xtask::workspace_root().join("config/systems/plc-guest/keys/engineering.key");
    let args: Vec<String> = [
        "--connect",
        &format!("127.0.0.1:{port}"),
        "--key",
        &key.display().to_string(),
        "read",
        name,
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let command = plcctl::Command::parse(&args).ok()?;
    let mut lines = Vec::new();
    plcctl::execute(&command, &mut |l| lines.push(l.to_string())).ok()?;
    lines.into_iter().next()
}

#[test]
fn system_default() {
    // The host side: the guest's page through the forwarded port, asked for until it
    // comes (the system boots meanwhile).
    let (o, (page, level, online)) = boot_beside("system_default", |ports, ended| {
        let (mut page, mut level, mut online) = (None, None, None);
        while !ended.load(std::sync::atomic::Ordering::SeqCst)
            && (page.is_none() || level.is_none() || online.is_none())
        {
            page = page.or_else(|| http_get(ports[0], "/"));
            level = level.or_else(|| scenarios::modbus_level(ports[1]));
            online = online.or_else(|| online_read(ports[2], "level"));
            std::thread::sleep(std::time::Duration::from_millis(500));
        }
        (page, level, online)
    });
    check(
        &o,
        online.as_deref().is_some_and(|l| l.starts_with("level = ")),
        &format!("plcctl over TCP with the engineering key: {online:?}"),
    );
    check(
        &o,
        level.is_some_and(|l| (0.0..2.0).contains(&l)),
        &format!("the level from the PLC's Modbus/TCP server: {level:?}"),
    );
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    let (status, body) = page.unwrap_or_default();
    check(
        &o,
        status.contains(" 200") && body.contains("<h1>Warden: tank HMI</h1>"),
        &format!("the guest's page from the host: {status:?} {body:?}"),
    );
    check(
        &o,
        matches!(o.ending, Ending::TimedOut),
        "expected the system to run until the timeout",
    );
    let console = o.console_lines();
    let banners = console
        .iter()
        .filter(|l| l.starts_with("Warden: a busybox shell in the Linux guest"))
        .count();
    check(
        &o,
        banners == 2,
        &format!("console: {banners} banners, expected one per boot of the guest (2)"),
    );
    check(
        &o,
        console.contains(&"the guest answers"),
        "console: the shell did not run `echo`",
    );
    // The banner's first suggestions work: the plant's level from its device, the PLC's
    // variables over its online service.
    let level = console
        .iter()
        .find_map(|l| l.strip_prefix("level "))
        .and_then(|v| v.trim().parse::<f64>().ok());
    check(
        &o,
        level.is_some_and(|l| (0.0..=2.0).contains(&l)),
        &format!("console: od of /dev/arinc/level gave {level:?}"),
    );
    let valve = console
        .iter()
        .find_map(|l| l.strip_prefix("valve = "))
        .and_then(|v| v.trim().parse::<f64>().ok());
    check(
        &o,
        valve.is_some_and(|v| (0.0..=1.0).contains(&v))
            && console
                .iter()
                .any(|l| *l == "alarm = FALSE" || *l == "alarm = TRUE"),
        &format!("console: plcctl read valve alarm gave {valve:?}"),
    );
    check(&o, o.console.contains("^C"), "console: the echoed ^C");
    check(
        &o,
        o.lines
            .iter()
            .any(|l| l.contains("(busybox) killed by signal 2 (SIGINT)")),
        "the Ctrl-C did not kill the foreground cat",
    );
    check(
        &o,
        o.line("[linux] guest: init exited with status ").is_some()
            && o.line("syssw: partition linux: COLD_START (HM_PARTITION_RESTART, restart 1)")
                .is_some(),
        "`exit` did not restart the guest",
    );
    // The PLC kept cycling (real time on a shared host: its timing is not asserted here).
    // After the host held the PLC's statistics back for seconds, the lines of the seconds
    // missed come one after the other, two of them within one cycle (the same count).
    let cycles: Vec<u64> = o
        .lines
        .iter()
        .filter(|l| l.contains("[plc] plc: t=") && l.contains(" task="))
        .filter_map(|l| field(l, "cycles=").first().copied())
        .collect();
    check(
        &o,
        cycles.len() >= 5
            && cycles.windows(2).all(|w| w[1] >= w[0])
            && cycles.first() < cycles.last(),
        &format!("the PLC's cycle counts {cycles:?}"),
    );
    // The loop closed: the level reached the setpoint band with the PLC's setpoint there.
    // That it holds the band is scenario `net_storm`'s check of this system, on virtual
    // time: here, on real time, a host that holds back CPU 0's thread for over 100 ms ages
    // the plant's level past its refresh, and the PLC closes the valve for that cycle (its
    // safe state); on a loaded host enough of them took the level out of the band.
    let status = tank::status(&o);
    let settled: Vec<_> = status
        .iter()
        .filter(|s| (SETTLED_MS..DISTURBANCE_MS.0).contains(&s.t_ms))
        .collect();
    check(
        &o,
        settled.len() >= 10,
        &format!(
            "{} plant status lines between {SETTLED_MS} ms and the disturbance",
            settled.len()
        ),
    );
    let outside = settled
        .iter()
        .filter(|s| (s.level - 1.0).abs() > BAND)
        .count();
    eprintln!(
        "system_default: {outside} of {} plant status lines between {SETTLED_MS} ms and the disturbance outside the band",
        settled.len()
    );
    check(
        &o,
        tank::reaches_band(&status) && status.iter().any(|s| s.setpoint == Some(1.0)),
        "the level did not reach the setpoint band under the PLC's control",
    );
}

// Scenario net_hmi: the tank's web HMI of the default system in a real browser (headless
// Chromium over its DevTools protocol, `scenarios::browser`). The test reads what the page
// shows every half second, types a setpoint into the page and clicks Set, and saves a
// screenshot as `target/scenarios/net_hmi/hmi.png`.

/// What the page showed at one moment.
#[derive(Clone, Debug, PartialEq)]
struct Shown {
    /// Seconds since the browser opened the page.
    at: f64,
    level: Option<f64>,
    setpoint: Option<f64>,
    alarm: String,
    /// The page's count of updates it got from the guest.
    updates: u64,
}

#[derive(Debug, Default)]
struct Session {
    error: Option<String>,
    shown: Vec<Shown>,
    /// What the page said after Set, and when it was typed.
    set_status: String,
    typed_at: Option<f64>,
}

const SETPOINT: f64 = 0.5;
/// How long the page is watched after the setpoint was typed.
const AFTER_SET: Duration = Duration::from_secs(25);

fn sample(browser: &mut Browser, opened: Instant) -> Result<Shown, String> {
    let v = browser.eval(
        "['level', 'setpoint', 'alarm', 'state'].map(id => document.getElementById(id)?.textContent ?? '')",
    )?;
    let text = |i: usize| v[i].as_str().unwrap_or("").to_string();
    let updates = text(3)
        .strip_prefix("updated ")
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or(0);
    Ok(Shown {
        at: opened.elapsed().as_secs_f64(),
        level: text(0).parse().ok(),
        setpoint: text(1).parse().ok(),
        alarm: text(2),
        updates,
    })
}

fn drive(port: u16, ended: &AtomicBool) -> Session {
    let mut session = Session::default();
    if let Err(e) = watch(port, ended, &mut session) {
        session.error = Some(e);
    }
    session
}

fn watch(port: u16, ended: &AtomicBool, session: &mut Session) -> Result<(), String> {
    // The guest's httpd first (the system boots meanwhile).
    while http_get(port, "/").is_none() {
        if ended.load(Ordering::SeqCst) {
            return Err("the guest's httpd never answered".into());
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    let mut browser = Browser::launch()?;
    browser.navigate(&format!("http://127.0.0.1:{port}/"))?;
    let opened = Instant::now();
    let mut typed: Option<Instant> = None;
    while !ended.load(Ordering::SeqCst) {
        let shown = sample(&mut browser, opened)?;
        // The downloaded program raises the alarm at the level the first one settles at:
        // then the page has shown the download's effect, and the user sets a lower level.
        if typed.is_none() && shown.alarm == "ALARM" {
            browser.type_into("sp-value", &SETPOINT.to_string())?;
            browser.click("sp-set")?;
            typed = Some(Instant::now());
            session.typed_at = Some(opened.elapsed().as_secs_f64());
        }
        session.shown.push(shown);
        if let Some(t) = typed {
            let status = browser.eval("document.getElementById('sp-status').textContent")?;
            session.set_status = status.as_str().unwrap_or("").to_string();
            if t.elapsed() > AFTER_SET {
                break;
            }
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    let png = browser.screenshot()?;
    let path = xtask::scenario::output_dir()
        .join("net_hmi")
        .join("hmi.png");
    std::fs::write(&path, png).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(())
}

#[test]
fn net_hmi() {
    let (o, s) = boot_while("net_hmi", |ports, ended| drive(ports[0], ended));
    check(&o, o.line("panic at ").is_none(), "a partition panicked");
    check(
        &o,
        s.error.is_none(),
        &format!("the browser: {:?}", s.error),
    );
    let summary = format!("the page showed {:#?}", s.shown);
    // The page updates every second, also while the guest built and downloaded the
    // program: no update missed for more than 3 s.
    // From the first update on (before it, the page is still loading).
    let shown: Vec<&Shown> = s.shown.iter().filter(|x| x.updates > 0).collect();
    let stalled = shown
        .windows(2)
        .filter(|w| w[0].updates == w[1].updates)
        .map(|w| w[1].at)
        .collect::<Vec<_>>();
    let longest = shown
        .iter()
        .fold(
            (0.0f64, None::<&Shown>),
            |(worst, since), now| match since {
                Some(s) if s.updates == now.updates => (worst.max(now.at - s.at), since),
                _ => (worst, Some(now)),
            },
        )
        .0;
    check(
        &o,
        shown.last().is_some_and(|l| l.updates >= 20) && longest <= 3.0,
        &format!("updates stalled for {longest:.1} s (at {stalled:?}); {summary}"),
    );
    check(
        &o,
        o.console.contains("\ndownload done"),
        "the guest's shell did not download the changed program",
    );
    check(
        &o,
        s.typed_at.is_some(),
        &format!("the page never showed the downloaded program's alarm; {summary}"),
    );
    // The page was live before the download took effect (its alarm off), so the updates
    // above went on through it.
    let before = shown
        .iter()
        .filter(|x| x.alarm == "off" && Some(x.at) < s.typed_at)
        .count();
    check(
        &o,
        before >= 5,
        &format!("{before} updates shown before the download took effect; {summary}"),
    );
    check(
        &o,
        s.set_status
            .starts_with(&format!("setpoint {SETPOINT} m: wrote tank.setpoint = ")),
        &format!("the page's answer to Set: {:?}", s.set_status),
    );
    // The PLC took it (its setpoint port, shown by the page) and the plant follows it.
    let after: Vec<&Shown> = s
        .shown
        .iter()
        .filter(|x| x.at > s.typed_at.unwrap_or(f64::MAX))
        .collect();
    check(
        &o,
        after.iter().any(|x| x.setpoint == Some(SETPOINT)),
        &format!("the page never showed setpoint {SETPOINT}; {summary}"),
    );
    let plant = format!("setpoint={SETPOINT:.3}");
    check(
        &o,
        o.lines
            .iter()
            .any(|l| l.contains("plant: t=") && l.contains(&plant)),
        &format!("no plant line with {plant}"),
    );
    let levels: Vec<f64> = after.iter().filter_map(|x| x.level).collect();
    check(
        &o,
        levels
            .first()
            .zip(levels.last())
            .is_some_and(|(a, b)| a - b > 0.1),
        &format!("the shown level did not fall towards {SETPOINT}: {levels:?}"),
    );
    check(
        &o,
        after.last().is_some_and(|x| x.alarm == "off"),
        &format!("the alarm did not clear; {summary}"),
    );
    println!(
        "net_hmi: {} samples over {:.0} s, {} updates, longest stall {longest:.1} s; set at {:.0} s: {}; level {:?} -> {:?}",
        shown.len(),
        shown.last().map_or(0.0, |x| x.at),
        shown.last().map_or(0, |x| x.updates),
        s.typed_at.unwrap_or(0.0),
        s.set_status,
        levels.first(),
        levels.last()
    );
}
