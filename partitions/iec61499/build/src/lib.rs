//! Basic FB types from 4diac's XML to what the IEC 61499 runtime executes: the interface
//! and the ECC as the runtime's verified data, the algorithms and transition guards
//! compiled by the PLC's ST compiler into one verified bytecode program (see
//! `iec61499_runtime::vmcode`). Runs on the host (the engineering side, or a helper in the
//! Linux guest); the real-time partition accepts only the result. Errors name the `.fbt`
//! file, line and column, also for ST errors inside an algorithm or guard.
//!
//! A simple FB (one algorithm per input event) becomes an ECC of its own: from START, each
//! input event enters the state of its name, which runs the algorithm of that name, sends
//! the output event of the same index (as FORTE does; none if there are fewer outputs)
//! and returns to START.

use iec61499_runtime::basic::{Action, BasicFb, Ecc, State, Transition};
use iec61499_runtime::composite::{Component, CompositeType, End, Link};
use iec61499_runtime::fb::{AdapterSpec, EventDecl, Interface, VarDecl, VarSpec, adapter_port};
use iec61499_runtime::vmcode::{GUARD_BASE, INSTANCE, VmCode};
use iec61499_runtime::{FunctionBlock, type_named};
pub use iec61499_xml::{AdapterType, read_adp};
use iec61499_xml::{Body, Condition, Event, FbType, Pos, Var, read_fbt};
use std::fmt::Write as _;

/// A compiled basic FB type: what its instances are made from.
#[derive(Clone, Debug)]
pub struct BasicType {
    pub name: String,
    pub interface: Interface,
    pub ecc: Ecc,
    pub internals: Vec<VarSpec>,
    pub code: VmCode,
}

impl BasicType {
    /// The type as a package (`iec61499_runtime::package`): what a device is sent.
    pub fn package(&self) -> Vec<u8> {
        iec61499_runtime::package::encode(
            &self.name,
            &self.interface,
            &self.internals,
            &self.ecc,
            &self.code,
        )
    }

    /// A new instance.
    pub fn instantiate(&self) -> Box<dyn FunctionBlock> {
        match BasicFb::new(
            self.interface.clone(),
            self.ecc.clone(),
            self.internals.clone(),
            Box::new(self.code.clone()),
        ) {
            Ok(fb) => Box::new(fb),
            Err(e) => unreachable!("the ECC was verified when the type was compiled: {e}"),
        }
    }
}

/// ST text with the place its first character has in the `.fbt`.
type Text = (String, Pos);

/// What a body is made of, before the code is compiled.
struct Parts<'f> {
    internals: Vec<(VarSpec, &'f Var)>,
    algorithms: Vec<Text>,
    guards: Vec<Text>,
    ecc: Ecc,
}

fn spec(file: &str, v: &Var) -> Result<VarSpec, String> {
    let ty = type_named(&v.ty).ok_or_else(|| {
        format!(
            "{file}:{}:{}: variable {}: type {} is not supported",
            v.pos.line, v.pos.col, v.name, v.ty
        )
    })?;
    Ok(VarSpec {
        name: v.name.clone(),
        ty,
        array: v.array_size.map(|n| n as usize),
    })
}

fn specs<'f>(file: &str, vars: &'f [Var]) -> Result<Vec<(VarSpec, &'f Var)>, Vec<String>> {
    vars.iter()
        .map(|v| spec(file, v).map(|s| (s, v)).map_err(|e| vec![e]))
        .collect()
}

/// The runtime's interface of the type `fb` read from `file`.
pub fn interface_of_xml(file: &str, fb: &FbType) -> Result<Interface, Vec<String>> {
    interface_of(file, fb)
}

/// The runtime's interface of `fb`.
fn interface_of(file: &str, fb: &FbType) -> Result<Interface, Vec<String>> {
    let ifc = &fb.interface;
    let inputs: Vec<VarSpec> = specs(file, &ifc.inputs)?
        .into_iter()
        .map(|(s, _)| s)
        .collect();
    let outputs: Vec<VarSpec> = specs(file, &ifc.outputs)?
        .into_iter()
        .map(|(s, _)| s)
        .collect();
    let ei_with: Vec<Vec<&str>> = ifc
        .event_inputs
        .iter()
        .map(|e| e.with.iter().map(String::as_str).collect())
        .collect();
    let eo_with: Vec<Vec<&str>> = ifc
        .event_outputs
        .iter()
        .map(|e| e.with.iter().map(String::as_str).collect())
        .collect();
    let ei: Vec<EventDecl<'_>> = ifc
        .event_inputs
        .iter()
        .zip(&ei_with)
        .map(|(e, w)| (e.name.as_str(), w.as_slice()))
        .collect();
    let eo: Vec<EventDecl<'_>> = ifc
        .event_outputs
        .iter()
        .zip(&eo_with)
        .map(|(e, w)| (e.name.as_str(), w.as_slice()))
        .collect();
    let decl = |v: &Vec<VarSpec>| -> Vec<(String, VarSpec)> {
        v.iter().map(|s| (s.name.clone(), s.clone())).collect()
    };
    let (ins, outs) = (decl(&inputs), decl(&outputs));
    let ins: Vec<VarDecl<'_>> = ins
        .iter()
        .map(|(n, s)| (n.as_str(), s.ty, s.array))
        .collect();
    let outs: Vec<VarDecl<'_>> = outs
        .iter()
        .map(|(n, s)| (n.as_str(), s.ty, s.array))
        .collect();
    let mut interface = Interface::build(&ei, &eo, &ins, &outs)
        .map_err(|e| vec![format!("{file}: {}: {e}", fb.name)])?;
    interface.adapters = adapter_specs(fb);
    Ok(interface)
}

/// The plugs (`true`) and sockets (`false`) of `fb`.
fn adapters_of(fb: &FbType) -> impl Iterator<Item = (&iec61499_xml::Adapter, bool)> {
    let ifc = &fb.interface;
    ifc.plugs
        .iter()
        .map(|a| (a, true))
        .chain(ifc.sockets.iter().map(|a| (a, false)))
}

/// The plugs and sockets of `fb` as the runtime declares them.
fn adapter_specs(fb: &FbType) -> Vec<AdapterSpec> {
    adapters_of(fb)
        .map(|(a, plug)| AdapterSpec {
            name: a.name.clone(),
            ty: a.ty.clone(),
            plug,
        })
        .collect()
}

/// `fb` with the ports of its plugs and sockets added to its interface as events and
/// variables named `ADAPTER.PORT`: a plug's as its adapter type declares them, a
/// socket's mirrored (the adapter type's input events and variables are the socket's
/// outputs). Each adapter's type is one of `adapters`.
pub fn with_adapters(
    file: &str,
    fb: &FbType,
    adapters: &[AdapterType],
) -> Result<FbType, Vec<String>> {
    let mut out = fb.clone();
    for (a, plug) in adapters_of(fb) {
        let Some(ty) = adapters.iter().find(|t| t.name == a.ty) else {
            return Err(vec![format!(
                "{file}:{}:{}: adapter {}: adapter type {} is unknown (give its .adp file)",
                a.pos.line, a.pos.col, a.name, a.ty
            )]);
        };
        let named = |n: &str| format!("{}.{n}", a.name);
        let events = |list: &[Event]| -> Vec<Event> {
            list.iter()
                .map(|e| Event {
                    name: named(&e.name),
                    with: e.with.iter().map(|w| named(w)).collect(),
                    pos: a.pos,
                })
                .collect()
        };
        let vars = |list: &[Var]| -> Vec<Var> {
            list.iter()
                .map(|v| Var {
                    name: named(&v.name),
                    pos: a.pos,
                    ..v.clone()
                })
                .collect()
        };
        let t = &ty.interface;
        let (ins, outs) = if plug {
            ((&t.event_inputs, &t.inputs), (&t.event_outputs, &t.outputs))
        } else {
            ((&t.event_outputs, &t.outputs), (&t.event_inputs, &t.inputs))
        };
        let ifc = &mut out.interface;
        ifc.event_inputs.extend(events(ins.0));
        ifc.inputs.extend(vars(ins.1));
        ifc.event_outputs.extend(events(outs.0));
        ifc.outputs.extend(vars(outs.1));
    }
    Ok(out)
}

/// States, transitions, algorithms and guards of `fb`'s body.
fn parts_of<'f>(
    file: &str,
    fb: &'f FbType,
    interface: &Interface,
) -> Result<Parts<'f>, Vec<String>> {
    match &fb.body {
        Body::Basic(b) => {
            let state = |name: &str| b.states.iter().position(|s| s.name == name).unwrap_or(0);
            let algorithm = |name: &str| b.algorithms.iter().position(|a| a.name == name);
            let states = b
                .states
                .iter()
                .map(|s| {
                    let actions = s.actions.iter().map(|a| {
                        Ok(Action {
                            algorithm: a.algorithm.as_deref().and_then(algorithm),
                            output: a
                                .output
                                .as_deref()
                                .map(|o| port(file, a.pos, o, interface.event_output(o), "output"))
                                .transpose()?,
                        })
                    });
                    Ok(State {
                        name: s.name.clone(),
                        actions: actions.collect::<Result<_, Vec<String>>>()?,
                    })
                })
                .collect::<Result<_, Vec<String>>>()?;
            let mut guards = Vec::new();
            let transitions = b
                .transitions
                .iter()
                .map(|t| {
                    let (event, guard) = match &t.condition {
                        Condition::Always => (None, None),
                        Condition::When { event, guard } => (
                            event
                                .as_deref()
                                .map(|e| port(file, t.pos, e, interface.event_input(e), "input"))
                                .transpose()?,
                            guard.as_ref().map(|g| {
                                guards.push(g.clone());
                                guards.len() - 1
                            }),
                        ),
                    };
                    Ok(Transition {
                        source: state(&t.source),
                        destination: state(&t.destination),
                        event,
                        guard,
                    })
                })
                .collect::<Result<_, Vec<String>>>()?;
            Ok(Parts {
                internals: specs(file, &b.internals)?,
                algorithms: b
                    .algorithms
                    .iter()
                    .map(|a| (statements(&a.st), a.pos))
                    .collect(),
                guards,
                ecc: Ecc {
                    states,
                    transitions,
                },
            })
        }
        Body::Simple(s) => {
            let mut states = vec![State {
                name: "START".into(),
                actions: Vec::new(),
            }];
            let mut transitions = Vec::new();
            for (i, event) in interface.event_inputs.iter().enumerate() {
                let algorithm = s.algorithms.iter().position(|a| a.name == event.name);
                // As FORTE's simple FBs: the output event of the input event's index
                // follows the algorithm.
                states.push(State {
                    name: event.name.clone(),
                    actions: vec![Action {
                        algorithm,
                        output: (i < interface.event_outputs.len()).then_some(i),
                    }],
                });
                transitions.push(Transition {
                    source: 0,
                    destination: i + 1,
                    event: Some(i),
                    guard: None,
                });
                transitions.push(Transition {
                    source: i + 1,
                    destination: 0,
                    event: None,
                    guard: None,
                });
            }
            Ok(Parts {
                internals: specs(file, &s.internals)?,
                algorithms: s
                    .algorithms
                    .iter()
                    .map(|a| (statements(&a.st), a.pos))
                    .collect(),
                guards: Vec::new(),
                ecc: Ecc {
                    states,
                    transitions,
                },
            })
        }
        Body::Composite(_) | Body::Service => Err(vec![format!(
            "{file}: {} is not a basic or simple FB (composite and service FBs are built otherwise)",
            fb.name
        )]),
    }
}

/// The index `found` of event `name` that an action sends or a transition waits for, or
/// the error at `pos` that it is no event of that `direction` (an adapter's port the type
/// does not have, or a misspelt name the reader let through as an adapter's).
fn port(
    file: &str,
    pos: Pos,
    name: &str,
    found: Option<usize>,
    direction: &str,
) -> Result<usize, Vec<String>> {
    found.ok_or_else(|| {
        vec![format!(
            "{file}:{}:{}: `{name}` is no {direction} event",
            pos.line, pos.col
        )]
    })
}

/// The statements of an algorithm's text: 4diac IDE 3 wraps them in `ALGORITHM NAME` ...
/// `END_ALGORITHM`, older files do not. The wrapper's words become blanks, so every
/// statement keeps its line and column for the messages.
fn statements(st: &str) -> String {
    let lead = st.len() - st.trim_start().len();
    let rest = &st[lead..];
    let Some(after) = rest
        .get(..9)
        .filter(|w| w.eq_ignore_ascii_case("ALGORITHM"))
        .and_then(|_| rest.get(9..))
        .filter(|a| a.starts_with(char::is_whitespace))
    else {
        return st.to_string();
    };
    // `ALGORITHM` and the name after it.
    let name_start = after.len() - after.trim_start().len();
    let name_len = after[name_start..]
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(after.len() - name_start);
    let header = lead + 9 + name_start + name_len;
    let mut out: String = st[..header]
        .chars()
        .map(|c| if c == '\n' { c } else { ' ' })
        .collect();
    let body = &st[header..];
    match body.to_ascii_uppercase().rfind("END_ALGORITHM") {
        Some(end) => {
            out.push_str(&body[..end]);
            out.push_str(&" ".repeat(13));
            out.push_str(&body[end + 13..]);
        }
        None => out.push_str(body),
    }
    out
}

fn st_type(spec: &VarSpec) -> String {
    match spec.array {
        Some(n) => format!("ARRAY[0..{}] OF {}", n.saturating_sub(1), spec.ty.name()),
        None => spec.ty.name().to_string(),
    }
}

/// The ST program of the type, and for each algorithm and guard the program line its text
/// starts at with its place in the `.fbt`.
fn program_of(
    fb: &FbType,
    interface: &Interface,
    parts: &Parts<'_>,
) -> (String, Vec<(usize, Pos)>) {
    let declared = interface
        .inputs
        .iter()
        .zip(&fb.interface.inputs)
        .chain(interface.outputs.iter().zip(&fb.interface.outputs))
        .chain(parts.internals.iter().map(|(s, v)| (s, *v)));
    let declaration = |name: &str, spec: &VarSpec, var: &Var| {
        let init = var
            .initial
            .as_ref()
            .map_or(String::new(), |i| format!(" := {i}"));
        format!("  {name} : {}{init};\n", st_type(spec))
    };
    // A plug's or socket's variables are the members of a structure of its name, so the
    // algorithms write `ADAPTER.VAR` as 4diac's do.
    let mut program = String::new();
    let mut vars = String::new();
    for (a, _) in adapters_of(fb) {
        let members: String = declared
            .clone()
            .filter_map(|(spec, var)| {
                Some(declaration(adapter_port(&spec.name, &a.name)?, spec, var))
            })
            .collect();
        if !members.is_empty() {
            let _ = write!(
                program,
                "TYPE __ADAPTER_{0} : STRUCT\n{members}END_STRUCT;\nEND_TYPE\n",
                a.name
            );
            let _ = writeln!(vars, "  {0} : __ADAPTER_{0};", a.name);
        }
    }
    program.push_str("PROGRAM FB_TYPE\nVAR\n");
    for (spec, var) in declared {
        if !adapters_of(fb).any(|(a, _)| adapter_port(&spec.name, &a.name).is_some()) {
            program.push_str(&declaration(&spec.name, spec, var));
        }
    }
    program.push_str(&vars);
    program.push_str("  __SEL : LINT;\n  __GUARD : BOOL;\nEND_VAR\nCASE __SEL OF\n");
    let mut places = Vec::new();
    let labelled = parts
        .algorithms
        .iter()
        .enumerate()
        .map(|(i, t)| (i as i64, t, false))
        .chain(
            parts
                .guards
                .iter()
                .enumerate()
                .map(|(k, t)| (GUARD_BASE + k as i64, t, true)),
        );
    for (label, (text, pos), guard) in labelled {
        let _ = writeln!(program, "{label}:");
        let line = program.lines().count() + 1;
        if guard {
            // The guard's text starts after `__GUARD := (`.
            places.push((
                line,
                Pos {
                    line: pos.line,
                    col: pos.col.saturating_sub(12),
                },
            ));
            let _ = writeln!(program, "__GUARD := ({text});");
        } else {
            places.push((line, *pos));
            let _ = writeln!(program, "{text}");
        }
    }
    let _ = write!(
        program,
        "END_CASE\nEND_PROGRAM\nCONFIGURATION C\n  TASK T (INTERVAL := T#1s, PRIORITY := 1);\n  PROGRAM {INSTANCE} WITH T : FB_TYPE;\nEND_CONFIGURATION\n"
    );
    (program, places)
}

/// A compiled type of either kind.
#[derive(Clone, Debug)]
pub enum Compiled {
    Basic(BasicType),
    Composite(CompositeType),
}

impl Compiled {
    pub fn name(&self) -> &str {
        match self {
            Compiled::Basic(t) => &t.name,
            Compiled::Composite(t) => &t.name,
        }
    }

    /// The package a device is sent.
    pub fn package(&self) -> Vec<u8> {
        match self {
            Compiled::Basic(t) => t.package(),
            Compiled::Composite(t) => t.encode(),
        }
    }
}

/// Reads and compiles the basic, simple or composite FB type in the `.fbt` text of `file`;
/// its plugs and sockets are of `adapters`.
pub fn compile_any(
    file: &str,
    text: &str,
    adapters: &[AdapterType],
) -> Result<Compiled, Vec<String>> {
    let fb = read_fbt(file, text).map_err(|e| vec![e.to_string()])?;
    match &fb.body {
        Body::Composite(_) => composite_of(file, &fb, adapters).map(Compiled::Composite),
        _ => compile_type(file, &fb, adapters).map(Compiled::Basic),
    }
}

/// The composite type of `fb` (its network as the device flattens it; the component types
/// are checked when the device creates an instance, against the types it has); its own
/// plugs and sockets are of `adapters`, their ports ports of its interface.
pub fn composite_of(
    file: &str,
    fb: &FbType,
    adapters: &[AdapterType],
) -> Result<CompositeType, Vec<String>> {
    let fb = &with_adapters(file, fb, adapters)?;
    let Body::Composite(net) = &fb.body else {
        return Err(vec![format!("{file}: {} is not a composite FB", fb.name)]);
    };
    let ifc = &fb.interface;
    fn own<'i>(fb: &FbType, instance: &'i Option<String>) -> Option<&'i String> {
        instance
            .as_ref()
            .filter(|i| adapters_of(fb).any(|(a, _)| a.name == **i))
    }
    let names = |events: &[iec61499_xml::Event]| events.iter().map(|e| e.name.clone()).collect();
    let vars = |vars: &[Var]| vars.iter().map(|v| v.name.clone()).collect();
    // A port of an own plug or socket is a port of the interface.
    let end = |e: &iec61499_xml::Endpoint| match own(fb, &e.instance) {
        Some(a) => End {
            component: None,
            port: format!("{a}.{}", e.port),
        },
        None => End {
            component: e.instance.clone(),
            port: e.port.clone(),
        },
    };
    let links = |list: &[iec61499_xml::Connection], event: bool| {
        list.iter()
            .map(|c| Link {
                event,
                source: end(&c.source),
                destination: end(&c.destination),
                line: c.pos.line,
                col: c.pos.col,
            })
            .collect::<Vec<_>>()
    };
    for c in &net.adapter_connections {
        for e in [&c.source, &c.destination] {
            if let Some(a) = own(fb, &e.instance) {
                return Err(vec![format!(
                    "{file}:{}:{}: adapter connection to {a}: an adapter connection to the composite's own plug or socket is not supported (connect its ports)",
                    c.pos.line, c.pos.col
                )]);
            }
        }
    }
    let t = CompositeType {
        name: fb.name.clone(),
        file: file.into(),
        event_inputs: names(&ifc.event_inputs),
        event_outputs: names(&ifc.event_outputs),
        inputs: vars(&ifc.inputs),
        outputs: vars(&ifc.outputs),
        adapters: adapter_specs(fb),
        components: net
            .instances
            .iter()
            .map(|i| Component {
                name: i.name.clone(),
                ty: i.ty.clone(),
                parameters: i.parameters.clone(),
                line: i.pos.line,
                col: i.pos.col,
            })
            .collect(),
        // An adapter connection between components is made as the device makes one
        // between instances.
        links: links(&net.event_connections, true)
            .into_iter()
            .chain(links(&net.data_connections, false))
            .chain(links(&net.adapter_connections, false))
            .collect(),
    };
    // What the device checks when it takes the package, here with the file's name.
    CompositeType::decode(&t.encode()).map_err(|e| vec![format!("{file}: {e}")])
}

/// Reads and compiles the basic or simple FB type in the `.fbt` text of `file` (without
/// plugs or sockets).
pub fn compile(file: &str, text: &str) -> Result<BasicType, Vec<String>> {
    let fb = read_fbt(file, text).map_err(|e| vec![e.to_string()])?;
    compile_type(file, &fb, &[])
}

/// Compiles an FB type read from `file`; its plugs and sockets are of `adapters`.
pub fn compile_type(
    file: &str,
    fb: &FbType,
    adapters: &[AdapterType],
) -> Result<BasicType, Vec<String>> {
    let fb = &with_adapters(file, fb, adapters)?;
    let interface = interface_of(file, fb)?;
    let parts = parts_of(file, fb, &interface)?;
    let (program, places) = program_of(fb, &interface, &parts);
    let compiled = plc_compiler::compile(
        &[(format!("{}.st", fb.name), program)],
        &plc_compiler::Options::default(),
    );
    let image = match compiled {
        Ok((compiled, _)) => compiled.image,
        Err((diagnostics, sources)) => {
            let generated = &sources.files[0];
            return Err(diagnostics
                .iter()
                .map(|d| {
                    let (line, col) = generated.line_col(d.span.start as usize);
                    match places.iter().rev().find(|(start, _)| *start <= line) {
                        // Inside an algorithm or guard: its place in the .fbt.
                        Some(&(start, pos)) if line > start => format!(
                            "{file}:{}:{col}: {}",
                            pos.line as usize + line - start,
                            d.message
                        ),
                        Some(&(_, pos)) => format!(
                            "{file}:{}:{}: {}",
                            pos.line,
                            pos.col as usize + col - 1,
                            d.message
                        ),
                        None => format!(
                            "{file}: {} (in the variables of {}): {}",
                            line, fb.name, d.message
                        ),
                    }
                })
                .collect());
        }
    };
    let internals: Vec<VarSpec> = parts.internals.iter().map(|(s, _)| s.clone()).collect();
    let code = VmCode::new(
        image,
        interface.inputs.clone(),
        interface.outputs.clone(),
        internals.clone(),
        parts.algorithms.len(),
        parts.guards.len(),
    )
    .map_err(|e| vec![format!("{file}: {e}")])?;
    parts
        .ecc
        .verify(&interface, parts.algorithms.len(), parts.guards.len())
        .map_err(|e| vec![format!("{file}: {e}")])?;
    Ok(BasicType {
        name: fb.name.clone(),
        interface,
        ecc: parts.ecc,
        internals,
        code,
    })
}

#[cfg(test)]
mod tests;
