//! Scenario net_hmi: the tank's web HMI of the default system in a real browser (headless
//! Chromium over its DevTools protocol, `scenarios::browser`). The test reads what the page
//! shows every half second, types a setpoint into the page and clicks Set, and saves a
//! screenshot as `target/scenarios/net_hmi/hmi.png`.

use scenarios::browser::Browser;
use scenarios::{boot_beside, check, http_get};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

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
    let (o, s) = boot_beside("net_hmi", |ports, ended| drive(ports[0], ended));
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
