//! Our standard event FBs have the interfaces of 4diac's: every type of `stdlib::TYPES`
//! against the `.fbt` of the same name in 4diac IDE's type library (the directory named by
//! `FORDIAC_TYPELIB`, default `target/4diac-ide/data/typelibrary`; skipped without it):
//! the same event inputs and outputs with the same WITH variables, the same data inputs and
//! outputs with the same types. One difference is ours on purpose: 4diac's E_N_TABLE
//! declares DT as a TIME yet connects it to E_TABLE's `ARRAY [0..3] OF TIME`; we follow the
//! standard (Annex A: an array of four TIMEs), as E_TABLE does in both.

use iec61499_runtime::stdlib;

#[test]
fn standard_interfaces_match_fourdiac() {
    let Some(dir) = iec61499_xml::fourdiac_library() else {
        eprintln!("skipped: no 4diac type library (set FORDIAC_TYPELIB)");
        return;
    };
    let mut compared = 0;
    let mut differences = Vec::new();
    for ty in stdlib::TYPES {
        let Some(file) = iec61499_xml::find_file(&dir, &format!("{ty}.fbt")) else {
            differences.push(format!("{ty}: no {ty}.fbt in the library"));
            continue;
        };
        let text = std::fs::read_to_string(&file).unwrap();
        let theirs = iec61499_xml::read_fbt(&file.display().to_string(), &text)
            .unwrap()
            .interface;
        let ours = stdlib::create(ty).unwrap();
        let ours = ours.interface();
        let events = |list: &[iec61499_runtime::EventSpec],
                      vars: &[iec61499_runtime::VarSpec]|
         -> Vec<String> {
            list.iter()
                .map(|e| {
                    let mut with: Vec<&str> =
                        e.with.iter().map(|w| vars[*w].name.as_str()).collect();
                    with.sort();
                    format!("{}({})", e.name, with.join(","))
                })
                .collect()
        };
        let their_events = |list: &[iec61499_xml::Event]| -> Vec<String> {
            list.iter()
                .map(|e| {
                    let mut with: Vec<&str> = e.with.iter().map(String::as_str).collect();
                    with.sort();
                    format!("{}({})", e.name, with.join(","))
                })
                .collect()
        };
        let vars = |list: &[iec61499_runtime::VarSpec]| -> Vec<String> {
            list.iter()
                .map(|v| {
                    format!(
                        "{}:{:?}{}",
                        v.name,
                        v.ty,
                        v.array.map_or(String::new(), |n| format!("[{n}]"))
                    )
                })
                .collect()
        };
        let their_vars = |list: &[iec61499_xml::Var]| -> Vec<String> {
            list.iter()
                .map(|v| {
                    let ty = iec61499_runtime::type_named(&v.ty)
                        .map_or(v.ty.clone(), |t| format!("{t:?}"));
                    format!(
                        "{}:{ty}{}",
                        v.name,
                        v.array_size.map_or(String::new(), |n| format!("[{n}]"))
                    )
                })
                .collect()
        };
        let pairs = [
            (
                "event inputs",
                events(&ours.event_inputs, &ours.inputs),
                their_events(&theirs.event_inputs),
            ),
            (
                "event outputs",
                events(&ours.event_outputs, &ours.outputs),
                their_events(&theirs.event_outputs),
            ),
            ("inputs", vars(&ours.inputs), their_vars(&theirs.inputs)),
            ("outputs", vars(&ours.outputs), their_vars(&theirs.outputs)),
        ];
        for (what, a, b) in pairs {
            let deliberate = ty == "E_N_TABLE" && what == "inputs";
            if a != b && !deliberate {
                differences.push(format!("{ty} {what}: ours {a:?}, 4diac {b:?}"));
            }
        }
        compared += 1;
    }
    eprintln!(
        "compared {compared} of {} standard FB interfaces with 4diac's",
        stdlib::TYPES.len()
    );
    for d in &differences {
        eprintln!("  {d}");
    }
    assert!(differences.is_empty(), "{} differences", differences.len());
}
