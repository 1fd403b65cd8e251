//! The compliance reference applications of eclipse-4diac/4diac-examples (`compliance_tests/`
//! under the directory named by `FORDIAC_EXAMPLES`, default `target/4diac-examples`; never
//! committed; skipped without it): every type of its type library compiled, and every
//! example of `ReferenceExamples.sys` (a subapplication whose comment says what to
//! trigger and what to expect) deployed on a device of ours, its trigger fired, and the
//! expectations its comment states in a form we can read (`FB.EO`, `2x FB.EO`,
//! `FB.PORT := VALUE`, `PORT := VALUE`) checked. Prints the counts and every example that
//! was not deployed, not run or differs, with the reason.

use iec61499_build::{compile_any, read_adp};
use iec61499_mgmt::Device;
use iec61499_runtime::Limits;
use std::path::{Path, PathBuf};

fn dir() -> Option<PathBuf> {
    let dir = std::env::var_os("FORDIAC_EXAMPLES")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../target/4diac-examples")
        })
        .join("compliance_tests");
    dir.is_dir().then_some(dir)
}

/// An FB of an example: name, type, parameters (input, literal).
type Fb = (String, String, Vec<(String, String)>);

/// Carries out a request on a device: `(device, destination, action, object)`.
type Send<'a> = dyn FnMut(&mut Device, &str, &str, String) -> Result<(), String> + 'a;

/// An example: a subapplication's FBs, parameters and connections, and its comment.
struct Example {
    name: String,
    comment: String,
    fbs: Vec<Fb>,
    connections: Vec<(String, String)>,
    /// Why it cannot be deployed as it stands (nested subapplications, an interface).
    unsupported: Option<String>,
}

fn examples(sys: &str) -> Vec<Example> {
    let doc = roxmltree::Document::parse(sys).expect("ReferenceExamples.sys is XML");
    let mut out = Vec::new();
    for app in doc.descendants().filter(|n| n.has_tag_name("Application")) {
        let app_name = app.attribute("Name").unwrap_or("?");
        let Some(net) = app.children().find(|n| n.has_tag_name("SubAppNetwork")) else {
            continue;
        };
        for sub in net.children().filter(|n| n.has_tag_name("SubApp")) {
            let Some(inner) = sub.children().find(|n| n.has_tag_name("SubAppNetwork")) else {
                continue;
            };
            let interface = sub
                .children()
                .find(|n| n.has_tag_name("SubAppInterfaceList"))
                .is_some_and(|i| i.children().any(|c| c.is_element()));
            let nested = inner.children().any(|n| n.has_tag_name("SubApp"));
            let unsupported = match (nested, interface) {
                (true, _) => Some("nested subapplications".to_string()),
                (_, true) => Some("a subapplication interface".to_string()),
                _ => None,
            };
            let fbs = inner
                .children()
                .filter(|n| n.has_tag_name("FB"))
                .map(|fb| {
                    let params = fb
                        .children()
                        .filter(|p| p.has_tag_name("Parameter"))
                        .map(|p| {
                            (
                                p.attribute("Name").unwrap_or("").to_string(),
                                p.attribute("Value").unwrap_or("").to_string(),
                            )
                        })
                        .collect();
                    (
                        fb.attribute("Name").unwrap_or("").to_string(),
                        fb.attribute("Type").unwrap_or("").to_string(),
                        params,
                    )
                })
                .collect();
            let connections = inner
                .descendants()
                .filter(|n| n.has_tag_name("Connection"))
                .map(|c| {
                    (
                        c.attribute("Source").unwrap_or("").to_string(),
                        c.attribute("Destination").unwrap_or("").to_string(),
                    )
                })
                .collect();
            out.push(Example {
                name: format!("{app_name}/{}", sub.attribute("Name").unwrap_or("?")),
                comment: sub.attribute("Comment").unwrap_or("").to_string(),
                fbs,
                connections,
                unsupported,
            });
        }
    }
    out
}

/// What a comment expects, as far as we read it.
#[derive(Debug, Default)]
struct Expected {
    /// `(FB.EO, count if stated)`.
    events: Vec<(String, Option<u64>)>,
    /// `(FB.PORT or PORT, value)`.
    data: Vec<(String, String)>,
}

/// The text after `word` (case-insensitive) in `comment`, up to the next `- ` line start.
fn clause(comment: &str, word: &str) -> Option<String> {
    let lower = comment.to_ascii_lowercase();
    let at = lower.find(word)? + word.len();
    let rest = &comment[at..];
    let end = rest.find("\n-").unwrap_or(rest.len());
    Some(rest[..end].replace('\n', " "))
}

fn expected(comment: &str) -> Expected {
    let mut e = Expected::default();
    let Some(text) = clause(comment, "expect") else {
        return e;
    };
    let text = text.replace(":=", " := ").replace([',', '(', ')'], " ");
    let words: Vec<&str> = text.split_whitespace().collect();
    let mut i = 0;
    while i < words.len() {
        let w = words[i];
        if words.get(i + 1) == Some(&":=") {
            if let Some(v) = words.get(i + 2) {
                e.data.push((w.to_string(), v.to_string()));
            }
            i += 3;
            continue;
        }
        let (count, name) = match w.split_once(['x', 'X']) {
            Some((n, rest)) if n.parse::<u64>().is_ok() && !rest.is_empty() => {
                (n.parse().ok(), rest)
            }
            Some((n, "")) if n.parse::<u64>().is_ok() => {
                i += 1;
                (n.parse().ok(), words.get(i).copied().unwrap_or(""))
            }
            _ => (None, w),
        };
        if name.contains('.') && words.get(i + 1) != Some(&":=") {
            e.events.push((name.to_string(), count));
        }
        i += 1;
    }
    e
}

/// `ours` (a READ's literal) is `expected` (a comment's value): the same number, Boolean or
/// text once type prefixes are dropped (a bare hex word like `AFFE` included).
fn same_value(ours: &str, expected: &str) -> bool {
    let strip = |s: &str| {
        s.rsplit('#')
            .next()
            .unwrap_or(s)
            .trim()
            .to_ascii_uppercase()
    };
    let (a, b) = (strip(ours), strip(expected));
    if a == b {
        return true;
    }
    let number = |s: &str| s.parse::<f64>().ok();
    let truth = |s: &str| match s {
        "TRUE" => Some(1.0),
        "FALSE" => Some(0.0),
        _ => None,
    };
    let hex = |s: &str| i64::from_str_radix(s, 16).ok().map(|v| v as f64);
    let x = number(&a).or_else(|| truth(&a));
    let y = number(&b).or_else(|| truth(&b));
    match (x, y) {
        (Some(x), Some(y)) => (x - y).abs() < 1e-6,
        (Some(x), None) => hex(&b) == Some(x),
        _ => false,
    }
}

/// The FB of `ex` a comment means by `name`: its name (the comments write Fb2a as FB2a
/// now and then), else the one FB of that type.
fn resolve_fb(ex: &Example, name: &str) -> Option<String> {
    if let Some((n, _, _)) = ex.fbs.iter().find(|(n, _, _)| n.eq_ignore_ascii_case(name)) {
        return Some(n.clone());
    }
    let of_type: Vec<&String> = ex
        .fbs
        .iter()
        .filter(|(_, t, _)| t == name)
        .map(|(n, _, _)| n)
        .collect();
    (of_type.len() == 1).then(|| of_type[0].clone())
}

fn request(action: &str, object: &str) -> String {
    format!("<Request ID=\"1\" Action=\"{action}\">{object}</Request>")
}

fn refused(answer: &str) -> Option<String> {
    answer
        .split("Reason=\"")
        .nth(1)
        .map(|r| r.split('"').next().unwrap_or("").to_string())
}

fn read(d: &mut Device, path: &str) -> Option<String> {
    let answer = d.execute(
        "R",
        &request(
            "READ",
            &format!("<Connection Source=\"{path}\" Destination=\"\"/>"),
        ),
        0,
    );
    refused(&answer).is_none().then(|| {
        answer
            .split("Destination=\"")
            .nth(1)
            .and_then(|s| s.split('"').next())
            .unwrap_or("")
            .replace("&apos;", "'")
    })
}

/// Deploys and runs `ex` on a new device with the `types` packages; `Err` says why it was
/// not deployed or what differs, `Ok(checked)` how many expectations were checked.
fn run(ex: &Example, types: &[Vec<u8>]) -> Result<usize, String> {
    if let Some(why) = &ex.unsupported {
        return Err(format!("not deployed: {why}"));
    }
    let mut d = Device::new(Limits::default(), 2);
    for t in types {
        let _ = d.add_type(t);
    }
    let mut send = |d: &mut Device, dst: &str, action: &str, object: String| {
        let answer = d.execute(dst, &request(action, &object), 0);
        match refused(&answer) {
            Some(r) => Err(format!("{action} {object}: {r}")),
            None => Ok(()),
        }
    };
    let deploy = |d: &mut Device, send: &mut Send<'_>| {
        send(d, "", "CREATE", "<FB Name=\"R\" Type=\"EMB_RES\"/>".into())?;
        for (name, ty, _) in &ex.fbs {
            send(
                d,
                "R",
                "CREATE",
                format!("<FB Name=\"{name}\" Type=\"{ty}\"/>"),
            )?;
        }
        for (name, _, params) in &ex.fbs {
            for (input, value) in params {
                let c = format!("<Connection Source=\"{value}\" Destination=\"{name}.{input}\"/>");
                send(d, "R", "WRITE", c)?;
            }
        }
        for (s, t) in &ex.connections {
            let c = format!("<Connection Source=\"{s}\" Destination=\"{t}\"/>");
            send(d, "R", "CREATE", c)?;
        }
        Ok::<(), String>(())
    };
    deploy(&mut d, &mut send).map_err(|e| format!("not deployed: {e}"))?;
    // The trigger: `FB.EI`, or an input event name one FB has.
    let word = clause(&ex.comment, "trigger")
        .and_then(|t| {
            t.split_whitespace()
                .find(|w| {
                    let count = w
                        .strip_suffix(['x', 'X'])
                        .is_some_and(|n| n.parse::<u64>().is_ok());
                    !count
                })
                .map(|w| w.trim_matches(|c: char| c == ',' || c == '.').to_string())
        })
        .ok_or("not run: the comment names no trigger")?;
    let trigger = match word.split_once('.') {
        Some((fb, ev)) => format!(
            "{}.{ev}",
            resolve_fb(ex, fb).ok_or(format!("not run: trigger {word}: no such FB"))?
        ),
        None => {
            let mut having = Vec::new();
            for (name, _, _) in &ex.fbs {
                let c =
                    format!("<Connection Source=\"START.WARM\" Destination=\"{name}.{word}\"/>");
                if send(&mut d, "R", "CREATE", c.clone()).is_ok() {
                    let _ = send(&mut d, "R", "DELETE", c);
                    having.push(format!("{name}.{word}"));
                }
            }
            match having.as_slice() {
                [one] => one.clone(),
                [] => return Err(format!("not run: trigger `{word}`: no FB has it")),
                _ => return Err(format!("not run: trigger `{word}`: several FBs have it")),
            }
        }
    };
    let mut want = expected(&ex.comment);
    // Comments name an FB by its type now and then (E_PERMIT for E_PERMIT_1), and write
    // `FB.OUT` in a list of events: a data port there is no event.
    let paths = want.events.iter_mut().map(|(p, _)| p);
    for path in paths.chain(want.data.iter_mut().map(|(p, _)| p)) {
        if let Some((fb, port)) = path.split_once('.')
            && let Some(name) = resolve_fb(ex, fb)
        {
            *path = format!("{name}.{port}");
        }
    }
    want.events.retain(|(path, _)| read(&mut d, path).is_none());
    // A counter for each expected output event.
    for (k, (event, _)) in want.events.iter().enumerate() {
        let counter = format!("OBS{k}");
        send(
            &mut d,
            "R",
            "CREATE",
            format!("<FB Name=\"{counter}\" Type=\"E_CTU\"/>"),
        )
        .and_then(|()| {
            let c = format!("<Connection Source=\"{event}\" Destination=\"{counter}.CU\"/>");
            send(&mut d, "R", "CREATE", c)
        })
        .map_err(|e| format!("not checked: expected event {event}: {e}"))?;
    }
    send(&mut d, "R", "START", String::new()).map_err(|e| format!("not run: {e}"))?;
    let t = format!("<Connection Source=\"$e\" Destination=\"{trigger}\"/>");
    send(&mut d, "R", "WRITE", t).map_err(|e| format!("not run: {e}"))?;
    while let Some(at) = d.next_deadline().filter(|at| *at <= 5_000_000_000) {
        d.advance(at);
    }
    if let Some(fault) = d.take_log().iter().find(|l| l.contains("stopped")) {
        return Err(format!("ran into a fault: {fault}"));
    }
    let mut differs = Vec::new();
    for (k, (event, count)) in want.events.iter().enumerate() {
        let got: u64 = read(&mut d, &format!("OBS{k}.CV"))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0);
        let ok = match count {
            Some(n) => got == *n,
            None => got >= 1,
        };
        if !ok {
            differs.push(format!("{event} came {got} times"));
        }
    }
    for (port, value) in &want.data {
        // `FB.PORT`, or a port of one of the FBs (the last that has it: the chain's end).
        let paths: Vec<String> = if port.contains('.') {
            vec![port.clone()]
        } else {
            ex.fbs
                .iter()
                .rev()
                .map(|(n, _, _)| format!("{n}.{port}"))
                .collect()
        };
        match paths.iter().find_map(|p| read(&mut d, p)) {
            Some(v) if same_value(&v, value) => {}
            Some(v) => differs.push(format!("{port} is {v}, expected {value}")),
            None => differs.push(format!("{port}: no such port")),
        }
    }
    if differs.is_empty() {
        Ok(want.events.len() + want.data.len())
    } else {
        Err(format!("differs: {}", differs.join("; ")))
    }
}

#[test]
fn fourdiac_compliance_examples() {
    let Some(dir) = dir() else {
        eprintln!(
            "skipped: no 4diac compliance examples (put eclipse-4diac/4diac-examples' compliance_tests under target/4diac-examples or set FORDIAC_EXAMPLES)"
        );
        return;
    };
    // The type library.
    let mut files: Vec<PathBuf> = Vec::new();
    let mut stack = vec![dir.join("Type Library")];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                files.push(p);
            }
        }
    }
    files.sort();
    let (mut types, mut refused_types) = (Vec::new(), Vec::new());
    let named = |file: &PathBuf| file.file_name().unwrap().to_string_lossy().to_string();
    let with_extension = |ext: &'static str| {
        files
            .iter()
            .filter(move |p| p.extension().is_some_and(|e| e == ext))
    };
    let adapters: Vec<_> = with_extension("adp")
        .map(|file| read_adp(&named(file), &std::fs::read_to_string(file).unwrap()))
        .collect::<Result<_, _>>()
        .expect("the adapter types read");
    for file in with_extension("fbt") {
        let name = named(file);
        match compile_any(&name, &std::fs::read_to_string(file).unwrap(), &adapters) {
            Ok(t) => types.push(t.package()),
            Err(e) => refused_types.push(format!("{name}: {}", e.join("; "))),
        }
    }
    let others = files.len() - with_extension("fbt").count() - adapters.len();
    eprintln!(
        "4diac compliance type library: {} .fbt, {} compiled, {} refused, with {} adapter types (.adp); {others} other files (.dtp) not read",
        types.len() + refused_types.len(),
        types.len(),
        refused_types.len(),
        adapters.len()
    );
    for r in &refused_types {
        eprintln!("  refused {r}");
    }
    // The examples.
    let sys = std::fs::read_to_string(dir.join("ReferenceExamples.sys")).unwrap();
    let all = examples(&sys);
    let (mut passed, mut checked, mut problems) = (0, 0, Vec::new());
    for ex in &all {
        match run(ex, &types) {
            Ok(0) => problems.push(format!("{}: ran, no expectation we can read", ex.name)),
            Ok(n) => {
                passed += 1;
                checked += n;
            }
            Err(why) => problems.push(format!("{}: {why}", ex.name)),
        }
    }
    eprintln!(
        "4diac compliance examples: {} examples, {passed} pass ({checked} expectations checked)",
        all.len()
    );
    for p in &problems {
        eprintln!("  {p}");
    }
    assert!(!all.is_empty(), "ReferenceExamples.sys has no examples");
}
