//! `cargo xtask plot LOG [-o OUT] [--plc NAME]`: a picture (SVG) of a run from its serial
//! log (the COM1 file of `cargo xtask run`, `target/esp/run-state/com1.log`, or a
//! scenario's `target/scenarios/<name>/state/serial.log`).
//!
//! What it reads (both formats are interfaces of their partitions):
//! - the plant's status lines, `plant: t=<ms>ms level=... valve=... setpoint=...
//!   disturbance=on|off ...` (format and parser `plant::Status`), every 500 ms of
//!   simulated time;
//! - a soft-PLC partition's `period` lines, `[<plc>] plc: t=<ms>ms period releases=<n>
//!   lateness_ns=<min>/<median>/<max> histogram_ns=<low>-<high>:<count>,...` and their
//!   continuation lines `[<plc>] plc: t=<ms>ms period histogram_ns=...` (format in
//!   `partitions/softplc/runtime/src/main.rs`): once a second, the lateness of every
//!   release since the previous line (its first start minus its window start) as a
//!   histogram of bins a quarter of their values wide.
//!
//! What it draws: the tank's level and the setpoint (m) and the valve (0..1) over the
//! plant's simulated time, the disturbances shaded; the histogram of every release's
//! lateness over the whole log; and each second's median and maximum lateness over the
//! PLC's partition time. Lines of other kinds, and lines cut or mixed by the serial
//! console, are skipped. It never changes the log.

use anyhow::{Context, Result, bail};
use plant::Status;
use plotters::prelude::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One bin of a lateness histogram: the releases whose lateness was in `[low, high)` ns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Bin {
    pub low: u64,
    pub high: u64,
    pub count: u64,
}

/// A PLC's `period` line (with its continuation lines): the releases of one second.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Period {
    /// The PLC's partition time at the line, ms.
    pub t_ms: u64,
    pub releases: u64,
    /// Lateness of those releases: min, median, max (ns).
    pub lateness_ns: (u64, u64, u64),
    pub bins: Vec<Bin>,
}

/// What a serial log holds for the picture.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SerialLog {
    /// The plant's status lines, in log order.
    pub plant: Vec<Status>,
    /// Per PLC partition (by name), its `period` lines in log order.
    pub periods: BTreeMap<String, Vec<Period>>,
}

impl SerialLog {
    /// Reads a serial log's text.
    pub fn parse(text: &str) -> Self {
        let mut log = SerialLog::default();
        for line in text.lines() {
            if line.contains("plant: t=") {
                if let Some(status) = Status::parse(line) {
                    log.plant.push(status);
                }
                continue;
            }
            let Some((partition, t_ms, rest)) = plc_line(line) else {
                continue;
            };
            let Some(rest) = rest.strip_prefix("period ") else {
                continue;
            };
            let periods = log.periods.entry(partition.to_string()).or_default();
            if let Some(bins) = rest.strip_prefix("histogram_ns=") {
                // A continuation: more bins of the period line just before.
                if let (Some(last), Some(bins)) = (periods.last_mut(), parse_bins(bins))
                    && last.t_ms == t_ms
                {
                    last.bins.extend(bins);
                }
                continue;
            }
            if let Some(period) = parse_period(t_ms, rest) {
                periods.push(period);
            }
        }
        log
    }

    /// The periods of PLC partition `name`, or of the only (or first) one when `None`.
    pub fn plc(&self, name: Option<&str>) -> Option<(&str, &[Period])> {
        match name {
            Some(name) => self
                .periods
                .get_key_value(name)
                .map(|(n, p)| (n.as_str(), p.as_slice())),
            None => self
                .periods
                .iter()
                .next()
                .map(|(n, p)| (n.as_str(), p.as_slice())),
        }
    }
}

/// A PLC `period` line's partition and values (the first line of a period; its
/// continuation lines, only bins, are `None`).
pub fn period_line(line: &str) -> Option<(&str, Period)> {
    let (partition, t_ms, rest) = plc_line(line)?;
    Some((
        partition,
        parse_period(t_ms, rest.strip_prefix("period ")?)?,
    ))
}

/// A PLC line `[<partition>] plc: t=<ms>ms <rest>` as (partition, ms, rest).
fn plc_line(line: &str) -> Option<(&str, u64, &str)> {
    let (head, text) = line.split_once("] plc: t=")?;
    let partition = &head[head.rfind('[')? + 1..];
    let (ms, rest) = text.split_once("ms ")?;
    Some((partition, ms.parse().ok()?, rest))
}

/// `releases=<n> lateness_ns=<a>/<b>/<c> histogram_ns=<bins>`.
fn parse_period(t_ms: u64, rest: &str) -> Option<Period> {
    let mut releases = None;
    let mut lateness = None;
    let mut bins = None;
    for word in rest.split_whitespace() {
        if let Some(v) = word.strip_prefix("releases=") {
            releases = v.parse().ok();
        } else if let Some(v) = word.strip_prefix("lateness_ns=") {
            let v: Vec<u64> = v.split('/').filter_map(|x| x.parse().ok()).collect();
            if let [min, median, max] = v[..] {
                lateness = Some((min, median, max));
            }
        } else if let Some(v) = word.strip_prefix("histogram_ns=") {
            bins = parse_bins(v);
        }
    }
    Some(Period {
        t_ms,
        releases: releases?,
        lateness_ns: lateness?,
        bins: bins?,
    })
}

/// `<low>-<high>:<count>,...` (empty: no bins).
fn parse_bins(text: &str) -> Option<Vec<Bin>> {
    text.split(',')
        .filter(|b| !b.is_empty())
        .map(|b| {
            let (range, count) = b.split_once(':')?;
            let (low, high) = range.split_once('-')?;
            let bin = Bin {
                low: low.parse().ok()?,
                high: high.parse().ok()?,
                count: count.parse().ok()?,
            };
            (bin.low < bin.high).then_some(bin)
        })
        .collect()
}

/// The bins of all `periods` together, by range.
pub fn merged(periods: &[Period]) -> Vec<Bin> {
    let mut sum: BTreeMap<(u64, u64), u64> = BTreeMap::new();
    for bin in periods.iter().flat_map(|p| &p.bins) {
        *sum.entry((bin.low, bin.high)).or_default() += bin.count;
    }
    sum.into_iter()
        .map(|((low, high), count)| Bin { low, high, count })
        .collect()
}

/// The time spans (s) in which the plant's disturbance was on.
fn disturbances(plant: &[Status]) -> Vec<(f64, f64)> {
    let mut spans = Vec::new();
    let mut start = None;
    for s in plant {
        let t = s.t_ms as f64 / 1000.0;
        match (s.disturbance, start) {
            (true, None) => start = Some(t),
            (false, Some(from)) => {
                spans.push((from, t));
                start = None;
            }
            _ => {}
        }
    }
    if let (Some(from), Some(last)) = (start, plant.last()) {
        spans.push((from, last.t_ms as f64 / 1000.0));
    }
    spans
}

/// Draws `log` (the PLC partition `plc`, or the first) as an SVG at `out`, titled `title`.
pub fn draw(log: &SerialLog, plc: Option<&str>, out: &Path, title: &str) -> Result<()> {
    let root = SVGBackend::new(out, (1100, 820)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_error)?;
    let root = root.titled(title, ("sans-serif", 22)).map_err(plot_error)?;
    let (top, bottom) = root.split_vertically(440);
    let (left, right) = bottom.split_horizontally(550);
    draw_plant(&top, &log.plant)?;
    match log.plc(plc) {
        Some((name, periods)) if !periods.is_empty() => {
            draw_histogram(&left, name, periods)?;
            draw_lateness(&right, name, periods)?;
        }
        _ => {
            let text = "no PLC period lines in this log (plc: t=... period ...)";
            for area in [&left, &right] {
                area.draw(&Text::new(text, (20, 40), ("sans-serif", 16)))
                    .map_err(plot_error)?;
            }
        }
    }
    root.present().map_err(plot_error)?;
    Ok(())
}

fn plot_error(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!("drawing the picture failed: {e}")
}

type Area<'a> = DrawingArea<SVGBackend<'a>, plotters::coord::Shift>;

fn draw_plant(area: &Area, plant: &[Status]) -> Result<()> {
    let t_max = plant
        .iter()
        .map(|s| s.t_ms as f64 / 1000.0)
        .fold(1.0, f64::max);
    let mut chart = ChartBuilder::on(area)
        .caption(
            "plant: the tank's level and the setpoint (m), the valve (0..1); disturbances shaded",
            ("sans-serif", 16),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .right_y_label_area_size(55)
        .build_cartesian_2d(0.0..t_max, 0.0..2.0)
        .map_err(plot_error)?
        .set_secondary_coord(0.0..t_max, 0.0..1.0);
    chart
        .configure_mesh()
        .x_desc("simulated time (s)")
        .y_desc("level, setpoint (m)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .draw()
        .map_err(plot_error)?;
    chart
        .configure_secondary_axes()
        .y_desc("valve")
        .draw()
        .map_err(plot_error)?;
    let shade = RGBColor(255, 225, 215).filled();
    chart
        .draw_series(
            disturbances(plant)
                .into_iter()
                .map(|(a, b)| Rectangle::new([(a, 0.0), (b, 2.0)], shade)),
        )
        .map_err(plot_error)?;
    let blue = RGBColor(31, 100, 200);
    let grey = RGBColor(90, 90, 90);
    let green = RGBColor(40, 160, 60);
    chart
        .draw_series(LineSeries::new(
            plant
                .iter()
                .filter_map(|s| Some((s.t_ms as f64 / 1000.0, s.setpoint?))),
            grey.stroke_width(2),
        ))
        .map_err(plot_error)?
        .label("setpoint")
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], grey.stroke_width(2)));
    chart
        .draw_series(LineSeries::new(
            plant.iter().map(|s| (s.t_ms as f64 / 1000.0, s.level)),
            blue.stroke_width(2),
        ))
        .map_err(plot_error)?
        .label("level")
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], blue.stroke_width(2)));
    chart
        .draw_secondary_series(LineSeries::new(
            plant.iter().map(|s| (s.t_ms as f64 / 1000.0, s.valve)),
            green.stroke_width(1),
        ))
        .map_err(plot_error)?
        .label("valve (right axis)")
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], green.stroke_width(2)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(plot_error)?;
    Ok(())
}

/// Where the histogram's bars start on its log-scaled count axis (below one release).
const BAR_BASE: f64 = 0.5;

/// The lateness histogram over every release (us and counts, log scales).
fn draw_histogram(area: &Area, plc: &str, periods: &[Period]) -> Result<()> {
    let bins = merged(periods);
    let releases: u64 = bins.iter().map(|b| b.count).sum();
    let us = |ns: u64| (ns as f64 / 1000.0).max(0.1);
    let low = bins.first().map_or(1.0, |b| us(b.low));
    let high = bins.last().map_or(10.0, |b| us(b.high).min(1e7));
    let most = bins.iter().map(|b| b.count).max().unwrap_or(1) as f64;
    let min = periods.iter().map(|p| p.lateness_ns.0).min().unwrap_or(0);
    let max = periods.iter().map(|p| p.lateness_ns.2).max().unwrap_or(0);
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "{plc}: release lateness, {releases} releases (min {:.1} us, max {:.1} us)",
                min as f64 / 1000.0,
                max as f64 / 1000.0
            ),
            ("sans-serif", 15),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        // Counts on a log scale too: the rare late releases are what matters.
        .build_cartesian_2d(
            (low * 0.8..high * 1.25).log_scale(),
            (BAR_BASE..most * 2.0).log_scale(),
        )
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc("cycle start minus window start (us)")
        .y_desc("releases")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| format!("{y:.0}"))
        .draw()
        .map_err(plot_error)?;
    let bar = |b: &Bin| [(us(b.low), BAR_BASE), (us(b.high).min(1e7), b.count as f64)];
    let (fill, edge) = (RGBColor(31, 100, 200).filled(), WHITE.stroke_width(1));
    chart
        .draw_series(bins.iter().map(|b| Rectangle::new(bar(b), fill)))
        .map_err(plot_error)?;
    chart
        .draw_series(bins.iter().map(|b| Rectangle::new(bar(b), edge)))
        .map_err(plot_error)?;
    Ok(())
}

/// Each second's median and maximum lateness over the PLC's time (us, log scale).
fn draw_lateness(area: &Area, plc: &str, periods: &[Period]) -> Result<()> {
    let us = |ns: u64| (ns as f64 / 1000.0).max(0.1);
    let t_max = periods
        .iter()
        .map(|p| p.t_ms as f64 / 1000.0)
        .fold(1.0, f64::max);
    let low = periods
        .iter()
        .map(|p| us(p.lateness_ns.1))
        .fold(f64::MAX, f64::min)
        .min(1e7);
    let high = periods
        .iter()
        .map(|p| us(p.lateness_ns.2))
        .fold(1.0, f64::max);
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!("{plc}: each second's release lateness"),
            ("sans-serif", 15),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..t_max, (low * 0.8..high * 1.25).log_scale())
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc("PLC partition time (s)")
        .y_desc("lateness (us)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| format!("{y:.0}"))
        .draw()
        .map_err(plot_error)?;
    let red = RGBColor(200, 50, 40);
    let blue = RGBColor(31, 100, 200);
    for (label, color, pick) in [("max", red, 2usize), ("median", blue, 1usize)] {
        let value = move |p: &Period| match pick {
            2 => p.lateness_ns.2,
            _ => p.lateness_ns.1,
        };
        chart
            .draw_series(LineSeries::new(
                periods
                    .iter()
                    .map(|p| (p.t_ms as f64 / 1000.0, us(value(p)))),
                color.stroke_width(2),
            ))
            .map_err(plot_error)?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], color.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(plot_error)?;
    Ok(())
}

/// Where `cargo xtask plot LOG` writes without `-o`: LOG's name with `.svg`.
pub fn default_output(log: &Path) -> PathBuf {
    log.with_extension("svg")
}

/// `cargo xtask plot`: reads `log`, draws it to `out` (default [`default_output`]) and
/// prints what it drew. `Ok(false)` when the log has nothing to draw.
pub fn run(log: &Path, out: Option<&Path>, plc: Option<&str>) -> Result<bool> {
    let text = std::fs::read(log).with_context(|| format!("cannot read {}", log.display()))?;
    let parsed = SerialLog::parse(&String::from_utf8_lossy(&text));
    let out = out.map_or_else(|| default_output(log), Path::to_path_buf);
    if out.extension().is_none_or(|e| e != "svg") {
        bail!(
            "{}: the picture is an SVG file: name it *.svg",
            out.display()
        );
    }
    if let Some(name) = plc
        && !parsed.periods.contains_key(name)
    {
        bail!(
            "{}: no `period` lines of a PLC partition `{name}` (found: {})",
            log.display(),
            parsed
                .periods
                .keys()
                .cloned()
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if parsed.plant.is_empty() && parsed.periods.is_empty() {
        eprintln!(
            "xtask: {}: no plant status lines and no PLC period lines: nothing to draw",
            log.display()
        );
        return Ok(false);
    }
    draw(&parsed, plc, &out, &format!("Warden: {}", log.display()))?;
    let (name, periods) = parsed.plc(plc).unwrap_or(("-", &[]));
    let releases: u64 = periods.iter().map(|p| p.releases).sum();
    println!(
        "xtask: {}: {} plant status lines, {} periods ({releases} releases) of PLC `{name}`",
        out.display(),
        parsed.plant.len(),
        periods.len(),
    );
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = "\
[   1.000100] [plant] plant: t=500ms level=0.100 valve=1.000 setpoint=1.000 disturbance=off stale=0 bad=0 overflow=0
[   1.001000] [plc] plc: t=1009ms task=CYCLE.tank cycles=101 exec_us=46/6/44/595 jitter_us=18/177 overruns=0 faults=0
[   1.002000] [plc] plc: t=1009ms scan releases=101 lateness_ns=6482/11980/167512 overhead_ns=4411/11980/62774 forced=0
[   1.003000] [plc] plc: t=1009ms period releases=100 lateness_ns=6482/11980/167512 histogram_ns=6144-7168:10,10240-12288:80,163840-196608:10
[   1.500000] [plant] plant: t=1000ms level=0.300 valve=0.900 setpoint=1.000 disturbance=off stale=0 bad=0 overflow=0
[   1.600000] [linux] guest: process 1 stdout: plc: t=5ms period releases=1 lateness_ns=1/1/1 histogram_ns=1-2:1
[   2.003000] [plc] plc: t=2009ms period releases=100 lateness_ns=7000/11000/900000 histogram_ns=6144-7168:50
[   2.003100] [plc] plc: t=2009ms period histogram_ns=10240-12288:40,786432-917504:10
[   2.004000] [plc] plc: t=2009ms period releases=garbled
[   2.100000] [counter] plc: t=1000ms period releases=100 lateness_ns=1/2/3 histogram_ns=1-2:100
[   2.500000] [plant] plant: t=1500ms level=0.500 valve=0.800 setpoint=- disturbance=on stale=0 bad=0 overflow=0
[   3.000000] [plant] plant: t=2000ms level=0.6";

    #[test]
    fn parses_the_plant_and_the_plc_periods() {
        let log = SerialLog::parse(SAMPLE);
        assert_eq!(log.plant.len(), 3, "the cut last line is skipped");
        assert_eq!((log.plant[2].t_ms, log.plant[2].setpoint), (1500, None));
        assert!(log.plant[2].disturbance);
        let (name, periods) = log.plc(None).unwrap();
        assert_eq!(name, "counter", "the first by name without --plc");
        assert_eq!(periods.len(), 1);
        let (name, periods) = log.plc(Some("plc")).unwrap();
        assert_eq!(name, "plc");
        assert_eq!(
            periods.len(),
            2,
            "the guest's echo and the garbled line are skipped"
        );
        assert_eq!(
            periods[0],
            Period {
                t_ms: 1009,
                releases: 100,
                lateness_ns: (6482, 11980, 167512),
                bins: vec![
                    Bin {
                        low: 6144,
                        high: 7168,
                        count: 10
                    },
                    Bin {
                        low: 10240,
                        high: 12288,
                        count: 80
                    },
                    Bin {
                        low: 163840,
                        high: 196608,
                        count: 10
                    },
                ],
            }
        );
        assert_eq!(
            periods[1].bins.len(),
            3,
            "the continuation line's bins are added"
        );
        assert_eq!(
            merged(periods),
            [
                Bin {
                    low: 6144,
                    high: 7168,
                    count: 60
                },
                Bin {
                    low: 10240,
                    high: 12288,
                    count: 120
                },
                Bin {
                    low: 163840,
                    high: 196608,
                    count: 10
                },
                Bin {
                    low: 786432,
                    high: 917504,
                    count: 10
                },
            ]
        );
        assert_eq!(disturbances(&log.plant), [(1.5, 1.5)]);
        assert!(log.plc(Some("nothing")).is_none());
    }

    #[test]
    fn bad_bins_are_refused() {
        assert_eq!(parse_bins(""), Some(vec![]));
        assert_eq!(parse_bins("5-3:1"), None);
        assert_eq!(parse_bins("1-2"), None);
        assert_eq!(parse_bins("1-2:x"), None);
    }

    #[test]
    fn draws_an_svg_from_a_small_log() {
        let dir = std::env::temp_dir().join(format!("xtask-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let log = dir.join("com1.log");
        std::fs::write(&log, SAMPLE).unwrap();
        assert!(run(&log, None, Some("plc")).unwrap());
        let svg = std::fs::read_to_string(dir.join("com1.svg")).unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..80.min(svg.len())]);
        for text in [
            "level",
            "valve",
            "setpoint",
            "release lateness",
            "200 releases",
        ] {
            assert!(svg.contains(text), "the picture has no {text:?}");
        }
        assert!(svg.matches("<rect").count() >= 4, "the histogram's bars");
        // No PLC lines: the plant alone, with a note.
        std::fs::write(&log, &SAMPLE[..SAMPLE.find("[plc]").unwrap()]).unwrap();
        let out = dir.join("plant.svg");
        assert!(run(&log, Some(&out), None).unwrap());
        assert!(
            std::fs::read_to_string(&out)
                .unwrap()
                .contains("no PLC period lines")
        );
        // Nothing to draw, a wrong name, a wrong extension.
        std::fs::write(&log, "nothing\n").unwrap();
        assert!(!run(&log, None, None).unwrap());
        assert!(run(&log, None, Some("plc")).is_err());
        assert!(run(&log, Some(&dir.join("x.png")), None).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
