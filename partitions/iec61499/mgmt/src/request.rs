//! Management requests, read from their XML, and the reasons of a refusal.

use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;

/// What a request does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    Create,
    Delete,
    Start,
    Stop,
    Kill,
    Reset,
    Read,
    Write,
    Query,
}

impl Action {
    fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "CREATE" => Action::Create,
            "DELETE" => Action::Delete,
            "START" => Action::Start,
            "STOP" => Action::Stop,
            "KILL" => Action::Kill,
            "RESET" => Action::Reset,
            "READ" => Action::Read,
            "WRITE" => Action::Write,
            "QUERY" => Action::Query,
            _ => return None,
        })
    }
}

/// What a request is about.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Object {
    None,
    Fb {
        name: String,
        ty: String,
    },
    /// `force`: `Some(true)` forces, `Some(false)` releases.
    Connection {
        source: String,
        destination: String,
        force: Option<bool>,
    },
    Watch {
        source: String,
        destination: String,
    },
    /// A part of a compiled FB type's package (ours: 4diac has no compiled types):
    /// `<FBType Name="T" Offset="0" Size="5234" Data="base64"/>`, the bytes `Offset..` of a
    /// package of `Size` bytes; the part that completes it adds the type
    /// ([`crate::Device::add_type`]).
    FbType {
        name: String,
        offset: usize,
        size: usize,
        data: Vec<u8>,
    },
}

/// A request.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Request {
    pub id: String,
    pub action: Action,
    pub object: Object,
}

/// Why a request was refused, with the names 4diac shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reason {
    /// The request is not well-formed.
    BadParams,
    NotReady,
    UnsupportedCmd,
    UnsupportedType,
    NoSuchObject,
    InvalidObject,
    InvalidOperation,
    InvalidState,
    Overflow,
    InvalidDst,
    /// The client's access level does not allow the request (ours; see
    /// [`crate::serve::Access`]).
    AccessDenied,
}

impl Reason {
    pub fn name(self) -> &'static str {
        match self {
            Reason::BadParams => "BAD_PARAMS",
            Reason::NotReady => "NOT_READY",
            Reason::UnsupportedCmd => "UNSUPPORTED_CMD",
            Reason::UnsupportedType => "UNSUPPORTED_TYPE",
            Reason::NoSuchObject => "NO_SUCH_OBJECT",
            Reason::InvalidObject => "INVALID_OBJECT",
            Reason::InvalidOperation => "INVALID_OPERATION",
            Reason::InvalidState => "INVALID_STATE",
            Reason::Overflow => "OVERFLOW",
            Reason::InvalidDst => "INVALID_DST",
            Reason::AccessDenied => "ACCESS_DENIED",
        }
    }
}

impl Request {
    /// Reads a request; what is not one is [`Reason::BadParams`] (with the ID if it could
    /// be read).
    pub fn parse(text: &str) -> Result<Request, (String, Reason)> {
        let doc =
            roxmltree::Document::parse(text).map_err(|_| (String::new(), Reason::BadParams))?;
        let root = doc.root_element();
        let id = root.attribute("ID").unwrap_or("").to_string();
        let bad = |_| (id.clone(), Reason::BadParams);
        if root.tag_name().name() != "Request" {
            return Err(bad(()));
        }
        let action = root
            .attribute("Action")
            .and_then(Action::from_name)
            .ok_or((id.clone(), Reason::UnsupportedCmd))?;
        let attr = |node: roxmltree::Node<'_, '_>, name: &str| {
            node.attribute(name).map(str::to_string).ok_or(())
        };
        let object = match root.children().find(|c| c.is_element()) {
            None => Object::None,
            Some(node) => match node.tag_name().name() {
                "FB" => Object::Fb {
                    name: attr(node, "Name").map_err(bad)?,
                    ty: node.attribute("Type").unwrap_or("*").to_string(),
                },
                "Connection" => Object::Connection {
                    source: attr(node, "Source").map_err(bad)?,
                    destination: attr(node, "Destination").map_err(bad)?,
                    force: match node.attribute("force") {
                        None => None,
                        Some("true") => Some(true),
                        Some("false") => Some(false),
                        Some(_) => return Err(bad(())),
                    },
                },
                "Watch" => Object::Watch {
                    source: attr(node, "Source").map_err(bad)?,
                    destination: attr(node, "Destination").map_err(bad)?,
                },
                "FBType" => {
                    let number = |name: &str| {
                        node.attribute(name)
                            .and_then(|v| v.parse::<usize>().ok())
                            .ok_or(())
                    };
                    let data = node.attribute("Data").ok_or(()).and_then(|d| {
                        use base64::Engine as _;
                        base64::engine::general_purpose::STANDARD
                            .decode(d)
                            .map_err(|_| ())
                    });
                    Object::FbType {
                        name: attr(node, "Name").map_err(bad)?,
                        offset: number("Offset").map_err(bad)?,
                        size: number("Size").map_err(bad)?,
                        data: data.map_err(bad)?,
                    }
                }
                _ => return Err((id, Reason::UnsupportedCmd)),
            },
        };
        Ok(Request { id, action, object })
    }
}

/// The response to request `id`: done (`reason` `None`), with `body` inside if given.
pub fn response(id: &str, reason: Option<Reason>, body: Option<&str>) -> String {
    let id = escape(id);
    let reason = reason.map_or(String::new(), |r| format!(" Reason=\"{}\"", r.name()));
    match body {
        None => format!("<Response ID=\"{id}\"{reason} />"),
        Some(body) => format!("<Response ID=\"{id}\"{reason}>\n  {body}\n</Response>"),
    }
}

/// `text` for an XML attribute value.
pub fn escape(text: &str) -> String {
    let mut out = String::new();
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out
}
