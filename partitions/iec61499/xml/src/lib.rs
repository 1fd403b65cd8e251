//! Function-block types from IEC 61499 XML as 4diac IDE writes them (`.fbt`, the
//! `LibraryElement` document type): the interface (events with their WITH associations,
//! input, output and internal variables), and the body of a basic FB (the execution control
//! chart: states, actions, transitions, and its algorithms in Structured Text), of a
//! simple FB (one algorithm per input event), of a composite FB (its network: instances,
//! parameters, event, data and adapter connections) or of a service-interface FB
//! (interface only); and adapter types (`.adp`, [`read_adp`]), whose ports a plug or
//! socket of an FB adds to its interface as `ADAPTER.PORT`. A host library; every error
//! names the file, line and column of the XML it comes from.
//!
//! The reader checks what the document alone can tell: names unique within their
//! namespace, WITH naming a variable of the same direction, ECC transitions between
//! declared states, transition conditions naming an input event, actions naming a declared
//! algorithm and output event, network connections between declared instances or the
//! type's own interface. What needs other types (the instance types of a network, the
//! algorithms' Structured Text) is checked where those are known: the algorithm compiler
//! and the loader of a network.
//!
//! # Transition conditions
//!
//! 4diac writes a condition as `1` (always), `EVENT` (when that input event arrived),
//! `EVENT[guard]` or `[guard]`, or a bare guard (a Boolean ST expression). [`Condition`]
//! keeps the event and the guard's text with its position for the compiler (a column inside
//! an attribute counts the attribute's characters after `&lt;` and the like are replaced).

use roxmltree::{Document, Node, ParsingOptions};
use std::fmt;

/// Where in a file something is (1-based).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pos {
    pub line: u32,
    pub col: u32,
}

/// An error in a type file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Error {
    pub file: String,
    pub pos: Pos,
    pub message: String,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}:{}:{}: {}",
            self.file, self.pos.line, self.pos.col, self.message
        )
    }
}

impl std::error::Error for Error {}

/// An event of the interface.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Event {
    pub name: String,
    /// The variables sampled with it (inputs) or sent with it (outputs).
    pub with: Vec<String>,
    pub pos: Pos,
}

/// A variable declaration.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Var {
    pub name: String,
    pub ty: String,
    /// Elements of an array variable (`ArraySize`), `None` for a scalar.
    pub array_size: Option<u32>,
    /// The `InitialValue` text (an ST literal).
    pub initial: Option<String>,
    pub pos: Pos,
}

/// An adapter of the interface: a plug (this FB offers the adapter type's interface) or
/// a socket (it takes one); its ports are named `ADAPTER.PORT` like an instance's.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Adapter {
    pub name: String,
    pub ty: String,
    pub pos: Pos,
}

/// An adapter type (`.adp`): the interface as its plug has it. The FB holding the plug
/// receives the input events with the input variables and sends the output events with
/// the output variables; the FB holding a socket has the mirror image (it sends the input
/// events and receives the output events), as in 4diac and FORTE.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AdapterType {
    pub name: String,
    pub interface: Interface,
    pub pos: Pos,
}

/// The interface of a type.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Interface {
    pub event_inputs: Vec<Event>,
    pub event_outputs: Vec<Event>,
    pub inputs: Vec<Var>,
    pub outputs: Vec<Var>,
    pub plugs: Vec<Adapter>,
    pub sockets: Vec<Adapter>,
}

/// An action of an ECC state: run an algorithm, then send an output event (either may be
/// absent).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Action {
    pub algorithm: Option<String>,
    pub output: Option<String>,
    pub pos: Pos,
}

/// An ECC state.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct State {
    pub name: String,
    pub actions: Vec<Action>,
    pub pos: Pos,
}

/// When an ECC transition may fire.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Condition {
    /// `1`: always (after the state's actions).
    Always,
    /// `EVENT`, `EVENT[guard]`, `[guard]` or a bare guard.
    When {
        event: Option<String>,
        /// The guard's ST text and where it starts in the file.
        guard: Option<(String, Pos)>,
    },
}

/// An ECC transition.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Transition {
    pub source: String,
    pub destination: String,
    pub condition: Condition,
    pub pos: Pos,
}

/// An algorithm in Structured Text.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Algorithm {
    pub name: String,
    pub st: String,
    /// Where the ST text starts in the file.
    pub pos: Pos,
}

/// A basic FB's body.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Basic {
    pub internals: Vec<Var>,
    /// The first state is the initial one.
    pub states: Vec<State>,
    pub transitions: Vec<Transition>,
    pub algorithms: Vec<Algorithm>,
}

/// An FB instance of a network.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Instance {
    pub name: String,
    pub ty: String,
    /// Parameters: input name and its literal.
    pub parameters: Vec<(String, String)>,
    pub pos: Pos,
}

/// An end of a connection: an instance's port (`FB.PORT`) or the type's own interface
/// (`PORT`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Endpoint {
    pub instance: Option<String>,
    pub port: String,
}

/// A connection of a network.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Connection {
    pub source: Endpoint,
    pub destination: Endpoint,
    pub pos: Pos,
}

/// A composite FB's network.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Network {
    pub instances: Vec<Instance>,
    pub event_connections: Vec<Connection>,
    pub data_connections: Vec<Connection>,
    /// From a plug (`FB.PLUG`) to a socket (`FB.SOCKET`).
    pub adapter_connections: Vec<Connection>,
}

/// A simple FB's body: one algorithm per input event, run when that event arrives.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Simple {
    pub internals: Vec<Var>,
    pub algorithms: Vec<Algorithm>,
}

/// What a type is made of.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Body {
    Basic(Basic),
    Simple(Simple),
    Composite(Network),
    /// A service-interface FB: its behaviour is the runtime's.
    Service,
}

/// A function-block type.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FbType {
    pub name: String,
    pub comment: Option<String>,
    pub interface: Interface,
    pub body: Body,
}

/// Reads a type from the text of an `.fbt` file named `file` (for messages).
pub fn read_fbt(file: &str, text: &str) -> Result<FbType, Error> {
    let doc = document(file, text)?;
    let r = Reader { file, doc: &doc };
    r.fb_type(doc.root_element())
}

/// Reads an adapter type from the text of an `.adp` file named `file` (for messages).
pub fn read_adp(file: &str, text: &str) -> Result<AdapterType, Error> {
    let doc = document(file, text)?;
    let r = Reader { file, doc: &doc };
    r.adapter_type(doc.root_element())
}

fn document<'i>(file: &str, text: &'i str) -> Result<Document<'i>, Error> {
    let options = ParsingOptions {
        allow_dtd: true,
        ..ParsingOptions::default()
    };
    Document::parse_with_options(text, options).map_err(|e| {
        let p = e.pos();
        Error {
            file: file.into(),
            pos: Pos {
                line: p.row,
                col: p.col,
            },
            message: format!("not well-formed XML: {e}"),
        }
    })
}

struct Reader<'a, 'i> {
    file: &'a str,
    doc: &'a Document<'i>,
}

impl Reader<'_, '_> {
    fn pos(&self, node: Node<'_, '_>) -> Pos {
        let p = self.doc.text_pos_at(node.range().start);
        Pos {
            line: p.row,
            col: p.col,
        }
    }

    fn error(&self, node: Node<'_, '_>, message: impl Into<String>) -> Error {
        Error {
            file: self.file.into(),
            pos: self.pos(node),
            message: message.into(),
        }
    }

    fn attr(&self, node: Node<'_, '_>, name: &str) -> Result<String, Error> {
        match node.attribute(name) {
            Some(v) if !v.trim().is_empty() => Ok(v.trim().into()),
            _ => Err(self.error(
                node,
                format!("<{}> needs the attribute {name}", node.tag_name().name()),
            )),
        }
    }

    fn children<'n, 'i>(
        node: Node<'n, 'i>,
        tag: &'static str,
    ) -> impl Iterator<Item = Node<'n, 'i>> {
        node.children()
            .filter(move |c| c.is_element() && c.tag_name().name() == tag)
    }

    fn child<'n, 'i>(node: Node<'n, 'i>, tag: &'static str) -> Option<Node<'n, 'i>> {
        Self::children(node, tag).next()
    }

    fn fb_type(&self, root: Node<'_, '_>) -> Result<FbType, Error> {
        if root.tag_name().name() != "FBType" {
            return Err(self.error(
                root,
                format!(
                    "expected an <FBType> document, found <{}>",
                    root.tag_name().name()
                ),
            ));
        }
        let name = self.attr(root, "Name")?;
        let interface = match Self::child(root, "InterfaceList") {
            Some(list) => self.interface(list)?,
            None => return Err(self.error(root, format!("FB type {name} has no <InterfaceList>"))),
        };
        let body = if let Some(basic) = Self::child(root, "BasicFB") {
            Body::Basic(self.basic(basic, &interface)?)
        } else if let Some(net) = Self::child(root, "FBNetwork") {
            Body::Composite(self.network(net, &interface)?)
        } else if let Some(simple) = Self::child(root, "SimpleFB") {
            Body::Simple(self.simple(simple, &interface)?)
        } else {
            Body::Service
        };
        Ok(FbType {
            name,
            comment: root.attribute("Comment").map(Into::into),
            interface,
            body,
        })
    }

    fn adapter_type(&self, root: Node<'_, '_>) -> Result<AdapterType, Error> {
        if root.tag_name().name() != "AdapterType" {
            return Err(self.error(
                root,
                format!(
                    "expected an <AdapterType> document, found <{}>",
                    root.tag_name().name()
                ),
            ));
        }
        let name = self.attr(root, "Name")?;
        let Some(list) = Self::child(root, "InterfaceList") else {
            return Err(self.error(root, format!("adapter type {name} has no <InterfaceList>")));
        };
        let interface = self.interface(list)?;
        if let Some(a) = interface.plugs.iter().chain(&interface.sockets).next() {
            return Err(Error {
                file: self.file.into(),
                pos: a.pos,
                message: format!(
                    "adapter type {name} declares adapter {}: an adapter's interface has only events and variables",
                    a.name
                ),
            });
        }
        Ok(AdapterType {
            name,
            interface,
            pos: self.pos(root),
        })
    }

    fn unique<'n>(
        &self,
        names: impl Iterator<Item = (&'n str, Node<'n, 'n>)>,
        what: &str,
    ) -> Result<(), Error> {
        let mut seen: Vec<&str> = Vec::new();
        for (name, node) in names {
            if seen.iter().any(|s| s.eq_ignore_ascii_case(name)) {
                return Err(self.error(node, format!("{what} `{name}` is declared twice")));
            }
            seen.push(name);
        }
        Ok(())
    }

    fn events(&self, list: Option<Node<'_, '_>>) -> Result<Vec<Event>, Error> {
        let Some(list) = list else {
            return Ok(Vec::new());
        };
        Self::children(list, "Event")
            .map(|e| {
                Ok(Event {
                    name: self.attr(e, "Name")?,
                    with: Self::children(e, "With")
                        .map(|w| self.attr(w, "Var"))
                        .collect::<Result<_, _>>()?,
                    pos: self.pos(e),
                })
            })
            .collect()
    }

    fn vars(&self, list: Option<Node<'_, '_>>) -> Result<Vec<Var>, Error> {
        let Some(list) = list else {
            return Ok(Vec::new());
        };
        Self::children(list, "VarDeclaration")
            .map(|v| {
                let array_size = match v.attribute("ArraySize").map(str::trim) {
                    None | Some("") => None,
                    Some(text) => {
                        Some(text.parse::<u32>().ok().filter(|n| *n > 0).ok_or_else(|| {
                            self.error(v, format!("ArraySize `{text}` is not a positive number"))
                        })?)
                    }
                };
                Ok(Var {
                    name: self.attr(v, "Name")?,
                    ty: self.attr(v, "Type")?,
                    array_size,
                    initial: v
                        .attribute("InitialValue")
                        .filter(|s| !s.is_empty())
                        .map(Into::into),
                    pos: self.pos(v),
                })
            })
            .collect()
    }

    fn adapters(&self, list: Option<Node<'_, '_>>) -> Result<Vec<Adapter>, Error> {
        let Some(list) = list else {
            return Ok(Vec::new());
        };
        Self::children(list, "AdapterDeclaration")
            .map(|a| {
                Ok(Adapter {
                    name: self.attr(a, "Name")?,
                    ty: self.attr(a, "Type")?,
                    pos: self.pos(a),
                })
            })
            .collect()
    }

    fn interface(&self, list: Node<'_, '_>) -> Result<Interface, Error> {
        let interface = Interface {
            event_inputs: self.events(Self::child(list, "EventInputs"))?,
            event_outputs: self.events(Self::child(list, "EventOutputs"))?,
            inputs: self.vars(Self::child(list, "InputVars"))?,
            outputs: self.vars(Self::child(list, "OutputVars"))?,
            plugs: self.adapters(Self::child(list, "Plugs"))?,
            sockets: self.adapters(Self::child(list, "Sockets"))?,
        };
        // One namespace for the whole interface, as instance ports are named `FB.NAME`.
        let names = list
            .descendants()
            .filter(|n| {
                n.is_element()
                    && matches!(
                        n.tag_name().name(),
                        "Event" | "VarDeclaration" | "AdapterDeclaration"
                    )
            })
            .filter_map(|n| n.attribute("Name").map(|a| (a, n)));
        self.unique(names, "interface element")?;
        for (events, vars, direction) in [
            (&interface.event_inputs, &interface.inputs, "input"),
            (&interface.event_outputs, &interface.outputs, "output"),
        ] {
            for event in events {
                for with in &event.with {
                    if !vars.iter().any(|v| v.name == *with) {
                        return Err(Error {
                            file: self.file.into(),
                            pos: event.pos,
                            message: format!(
                                "event {} is WITH `{with}`, which is no {direction} variable",
                                event.name
                            ),
                        });
                    }
                }
            }
        }
        Ok(interface)
    }

    fn basic(&self, node: Node<'_, '_>, interface: &Interface) -> Result<Basic, Error> {
        let internals = self.vars(Self::child(node, "InternalVars"))?;
        let mut basic = Basic {
            internals,
            ..Basic::default()
        };
        for alg in Self::children(node, "Algorithm") {
            basic.algorithms.push(self.algorithm(alg)?);
        }
        self.unique(
            Self::children(node, "Algorithm").filter_map(|a| a.attribute("Name").map(|n| (n, a))),
            "algorithm",
        )?;
        let Some(ecc) = Self::child(node, "ECC") else {
            return Err(self.error(node, "a basic FB needs an <ECC>"));
        };
        for s in Self::children(ecc, "ECState") {
            let mut actions = Vec::new();
            for a in Self::children(s, "ECAction") {
                let action = Action {
                    algorithm: a
                        .attribute("Algorithm")
                        .filter(|v| !v.is_empty())
                        .map(Into::into),
                    output: a
                        .attribute("Output")
                        .filter(|v| !v.is_empty())
                        .map(Into::into),
                    pos: self.pos(a),
                };
                if let Some(alg) = &action.algorithm
                    && !basic.algorithms.iter().any(|x| x.name == *alg)
                {
                    return Err(self.error(
                        a,
                        format!("action runs algorithm `{alg}`, which is not declared"),
                    ));
                }
                if let Some(out) = &action.output
                    && !interface.event_outputs.iter().any(|e| e.name == *out)
                    && !through_adapter(interface, out)
                {
                    return Err(
                        self.error(a, format!("action sends `{out}`, which is no output event"))
                    );
                }
                actions.push(action);
            }
            basic.states.push(State {
                name: self.attr(s, "Name")?,
                actions,
                pos: self.pos(s),
            });
        }
        if basic.states.is_empty() {
            return Err(self.error(ecc, "the ECC has no state"));
        }
        self.unique(
            Self::children(ecc, "ECState").filter_map(|s| s.attribute("Name").map(|n| (n, s))),
            "ECC state",
        )?;
        for t in Self::children(ecc, "ECTransition") {
            let transition = Transition {
                source: self.attr(t, "Source")?,
                destination: self.attr(t, "Destination")?,
                condition: self.condition(t, interface)?,
                pos: self.pos(t),
            };
            for end in [&transition.source, &transition.destination] {
                if !basic.states.iter().any(|s| s.name == *end) {
                    return Err(self.error(
                        t,
                        format!("transition names state `{end}`, which is not declared"),
                    ));
                }
            }
            basic.transitions.push(transition);
        }
        Ok(basic)
    }

    fn simple(&self, node: Node<'_, '_>, interface: &Interface) -> Result<Simple, Error> {
        let simple = Simple {
            internals: self.vars(Self::child(node, "InternalVars"))?,
            algorithms: Self::children(node, "Algorithm")
                .map(|a| self.algorithm(a))
                .collect::<Result<_, _>>()?,
        };
        self.unique(
            Self::children(node, "Algorithm").filter_map(|a| a.attribute("Name").map(|n| (n, a))),
            "algorithm",
        )?;
        for event in &interface.event_inputs {
            if !simple.algorithms.iter().any(|a| a.name == event.name) {
                return Err(Error {
                    file: self.file.into(),
                    pos: event.pos,
                    message: format!(
                        "simple FB: input event {} has no algorithm of its name",
                        event.name
                    ),
                });
            }
        }
        Ok(simple)
    }

    fn algorithm(&self, alg: Node<'_, '_>) -> Result<Algorithm, Error> {
        let name = self.attr(alg, "Name")?;
        let Some(st) = Self::child(alg, "ST") else {
            let other = alg.children().find(|c| c.is_element());
            let found = other.map_or("nothing".into(), |o| format!("<{}>", o.tag_name().name()));
            return Err(self.error(
                alg,
                format!(
                    "algorithm {name}: only Structured Text (<ST>) is supported, found {found}"
                ),
            ));
        };
        // 4diac writes the text as an attribute (older files) or as element text (CDATA).
        let (text, pos) = match st.attribute_node("Text") {
            Some(a) => (
                a.value().to_string(),
                self.doc.text_pos_at(a.range_value().start),
            ),
            None => {
                let text: String = st.children().filter_map(|c| c.text()).collect();
                let start = st
                    .first_child()
                    .map_or(st.range().start, |c| c.range().start);
                (text, self.doc.text_pos_at(start))
            }
        };
        Ok(Algorithm {
            name,
            st: text,
            pos: Pos {
                line: pos.row,
                col: pos.col,
            },
        })
    }

    fn condition(&self, t: Node<'_, '_>, interface: &Interface) -> Result<Condition, Error> {
        let attr = t.attribute_node("Condition");
        let text = attr.map_or("1", |a| a.value()).trim();
        let start = attr.map_or(t.range().start, |a| a.range_value().start);
        if text == "1" || text.eq_ignore_ascii_case("TRUE") {
            return Ok(Condition::Always);
        }
        let (event, guard) = match text.find('[') {
            Some(open) => {
                if !text.ends_with(']') {
                    return Err(self.error(
                        t,
                        format!("condition `{text}`: a guard in [ ] must close the condition"),
                    ));
                }
                let event = text[..open].trim();
                let guard_start = start + text_offset(attr.map(|a| a.value()), open + 1);
                let p = self.doc.text_pos_at(guard_start);
                let guard = text[open + 1..text.len() - 1].trim();
                if guard.is_empty() {
                    return Err(self.error(t, format!("condition `{text}` has an empty guard")));
                }
                (
                    (!event.is_empty()).then(|| event.to_string()),
                    Some((
                        guard.to_string(),
                        Pos {
                            line: p.row,
                            col: p.col,
                        },
                    )),
                )
            }
            None if interface.event_inputs.iter().any(|e| e.name == text)
                || through_adapter(interface, text) =>
            {
                (Some(text.to_string()), None)
            }
            None => {
                let p = self.doc.text_pos_at(start);
                (
                    None,
                    Some((
                        text.to_string(),
                        Pos {
                            line: p.row,
                            col: p.col,
                        },
                    )),
                )
            }
        };
        if let Some(e) = &event
            && !interface.event_inputs.iter().any(|x| x.name == *e)
            && !through_adapter(interface, e)
        {
            return Err(self.error(
                t,
                format!("condition `{text}` names `{e}`, which is no input event"),
            ));
        }
        Ok(Condition::When { event, guard })
    }

    fn endpoint(&self, node: Node<'_, '_>, attr: &str) -> Result<Endpoint, Error> {
        let text = self.attr(node, attr)?;
        Ok(match text.split_once('.') {
            Some((fb, port)) if !fb.is_empty() && !port.is_empty() => Endpoint {
                instance: Some(fb.into()),
                port: port.into(),
            },
            Some(_) => {
                return Err(self.error(node, format!("{attr} `{text}` is not FB.PORT or PORT")));
            }
            None => Endpoint {
                instance: None,
                port: text,
            },
        })
    }

    fn network(&self, net: Node<'_, '_>, interface: &Interface) -> Result<Network, Error> {
        let mut network = Network::default();
        for fb in Self::children(net, "FB") {
            let parameters = Self::children(fb, "Parameter")
                .map(|p| Ok((self.attr(p, "Name")?, self.attr(p, "Value")?)))
                .collect::<Result<_, Error>>()?;
            network.instances.push(Instance {
                name: self.attr(fb, "Name")?,
                ty: self.attr(fb, "Type")?,
                parameters,
                pos: self.pos(fb),
            });
        }
        self.unique(
            Self::children(net, "FB").filter_map(|f| f.attribute("Name").map(|n| (n, f))),
            "FB instance",
        )?;
        for (tag, out) in [
            ("EventConnections", &mut network.event_connections),
            ("DataConnections", &mut network.data_connections),
            ("AdapterConnections", &mut network.adapter_connections),
        ] {
            let Some(list) = Self::child(net, tag) else {
                continue;
            };
            for c in Self::children(list, "Connection") {
                let connection = Connection {
                    source: self.endpoint(c, "Source")?,
                    destination: self.endpoint(c, "Destination")?,
                    pos: self.pos(c),
                };
                for end in [&connection.source, &connection.destination] {
                    let known = match &end.instance {
                        // An adapter connection's ends are `FB.ADAPTER`; which are plugs
                        // and sockets is known with the instances' types.
                        Some(_) if tag == "AdapterConnections" => true,
                        Some(fb) => {
                            network.instances.iter().any(|i| i.name == *fb)
                                || interface
                                    .plugs
                                    .iter()
                                    .chain(&interface.sockets)
                                    .any(|a| a.name == *fb)
                        }
                        None => interface_has(interface, &end.port),
                    };
                    if !known {
                        let shown = end
                            .instance
                            .as_ref()
                            .map_or(end.port.clone(), |i| format!("{i}.{}", end.port));
                        return Err(self.error(c, format!("connection end `{shown}` is neither an instance's or adapter's port nor the type's interface")));
                    }
                }
                out.push(connection);
            }
        }
        Ok(network)
    }
}

/// Whether `name` is `ADAPTER.PORT` of a plug or socket of `interface` (the port itself is
/// checked against the adapter type where that is known: by the compiler).
fn through_adapter(interface: &Interface, name: &str) -> bool {
    name.split_once('.').is_some_and(|(adapter, port)| {
        !port.is_empty()
            && interface
                .plugs
                .iter()
                .chain(&interface.sockets)
                .any(|a| a.name == adapter)
    })
}

fn interface_has(interface: &Interface, port: &str) -> bool {
    interface
        .event_inputs
        .iter()
        .chain(&interface.event_outputs)
        .any(|e| e.name == port)
        || interface
            .inputs
            .iter()
            .chain(&interface.outputs)
            .any(|v| v.name == port)
}

/// The byte offset in the raw attribute value of the `n`th byte of its trimmed text
/// (positions point into the file, where leading blanks and entities count).
fn text_offset(raw: Option<&str>, n: usize) -> usize {
    let raw = raw.unwrap_or("");
    raw.len() - raw.trim_start().len() + n
}

#[cfg(test)]
mod tests;

/// Where 4diac IDE's type library is for the compatibility checks: the directory named by
/// `FORDIAC_TYPELIB`, else `target/4diac-ide/data/typelibrary` of the workspace (a copy of
/// eclipse-4diac/4diac-ide's `data/typelibrary`, never committed); `None` when neither exists.
pub fn fourdiac_library() -> Option<std::path::PathBuf> {
    let dir = std::env::var_os("FORDIAC_TYPELIB")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../../target/4diac-ide/data/typelibrary")
        });
    dir.is_dir().then_some(dir)
}

/// Every file named `name` below `dir`, depth first, in directory order sorted by path.
pub fn find_file(dir: &std::path::Path, name: &str) -> Option<std::path::PathBuf> {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .ok()?
        .flatten()
        .map(|e| e.path())
        .collect();
    entries.sort();
    for path in entries {
        if path.is_dir() {
            if let Some(found) = find_file(&path, name) {
                return Some(found);
            }
        } else if path.file_name().is_some_and(|n| n == name) {
            return Some(path);
        }
    }
    None
}
