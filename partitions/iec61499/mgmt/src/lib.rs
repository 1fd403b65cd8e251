//! IEC 61499 device management as 4diac IDE and FORTE speak it: the XML requests (CREATE,
//! DELETE, START, STOP, KILL, RESET, READ, WRITE, QUERY and the monitoring requests: watches,
//! forcing, event triggers), boot files (`.fboot`), the literals of WRITE, and a device that
//! carries requests out on its resources. no_std with `alloc`; nothing a client sends can
//! panic it: every request gets a response, a refusal with its reason.
//!
//! # Requests and responses
//!
//! A request is addressed to the device (empty destination) or to one of its resources
//! (the resource's name) and is one XML element, e.g.
//! `<Request ID="3" Action="CREATE"><FB Name="C" Type="E_CTU"/></Request>`. The response
//! echoes the ID: `<Response ID="3" />` when done, `<Response ID="3" Reason="NO_SUCH_OBJECT"
//! />` when refused ([`Reason`]); READ and QUERY answer with data inside the response.
//!
//! | action | object | what it does |
//! |---|---|---|
//! | CREATE | `FB Name Type` (device: a resource type, `EMB_RES`) | creates an FB instance or a resource |
//! | CREATE | `Connection Source Destination` | connects an event or data output to an input |
//! | CREATE | `Watch Source Destination` | watches a port (`FB.PORT`) |
//! | DELETE | `FB`, `Connection`, `Watch` | the reverse (an FB only while its resource is stopped) |
//! | WRITE | `Connection Source=literal Destination=FB.IN` | sets a parameter |
//! | WRITE | `... force="true"` / `force="false"` | forces a port to the literal / releases it |
//! | WRITE | `Connection Source="$e" Destination=FB.EI` | triggers an input event |
//! | READ | `Watch` | every watched port's value (below) |
//! | READ | `Connection Source=FB.PORT` | one port's value, as FORTE answers: `<Connection Source="FB.PORT" Destination="VALUE" />` |
//! | START, STOP, KILL, RESET | none (a resource) | starts (COLD), stops (STOP event), stops without it, resets |
//! | QUERY | `FB Name="*" Type="*"` | the resource's FB list |
//!
//! A READ of the watches answers
//! `<Watches><Resource name="R"><FB name="C"><Port name="CV"><Data value="3" forced="false"/></Port></FB></Resource></Watches>`.
//!
//! # Boot files
//!
//! One request a line, `destination;request`, as FORTE reads them ([`fboot`]).
//!
//! # Transports
//!
//! The same requests come over message ports (one a message, [`serve`]) and over TCP in
//! 4diac's framing (two ASN.1 STRINGs, [`tcp`]); [`serve::serve_parts`] answers both.
//! PUBLISH/SUBSCRIBE go over queuing ports or, with a UDP ID, over UDP ([`pubsub`]; the
//! partition's endpoints on its TCP/IP stack: `udp`, feature `net`).

#![no_std]

extern crate alloc;

pub mod clientserver;
pub mod device;
pub mod fboot;
pub mod flat;
pub mod literal;
pub mod package;
pub mod pubsub;
pub mod request;
#[cfg(test)]
mod segment;
pub mod serve;
pub mod sifb;
pub mod tcp;
#[cfg(any(feature = "net", test))]
pub mod tcplink;
pub mod types;
#[cfg(any(feature = "net", test))]
pub mod udp;

pub use device::Device;
pub use request::{Action, Object, Reason, Request};
