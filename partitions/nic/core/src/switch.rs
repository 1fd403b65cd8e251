//! The layer-2 switch between the uplink (the NIC) and the tenant partitions' virtual
//! interfaces, each with the MAC address the configuration gives it.
//!
//! # Forwarding
//!
//! - A frame is 14..=[`MAX_FRAME`] bytes (destination MAC, source MAC, EtherType, payload;
//!   no FCS). Shorter or longer frames are dropped ([`Drop::Malformed`]).
//! - A tenant may only send with its own MAC as the source: any other source, or a group
//!   address as the source, is dropped ([`Drop::Spoofed`]), so no tenant can pose as another
//!   or poison a peer's view of the network.
//! - Broadcast and multicast go to every port but the one they came from. A tenant may
//!   send at most [`GROUP_BURST`] of them at once and [`GROUP_RATE`] a second
//!   ([`Drop::Limited`] beyond): every other tenant must take them, so without a bound a
//!   tenant's broadcast storm would fill the other tenants' ports and cost them frames.
//! - Unicast to a tenant's MAC goes to that tenant only (tenant to tenant stays inside the
//!   machine); from a tenant, unicast to any other MAC goes to the uplink; from the uplink,
//!   unicast to no tenant's MAC is dropped ([`Drop::Unknown`]) rather than flooded, since
//!   the tenants' addresses are static and known.
//!
//! # Fairness
//!
//! The driver takes frames from the tenants' transmit rings in rounds ([`Rounds`]): each
//! tenant at most its per-round budget, so a tenant that floods its ring delays and loses
//! only its own frames. A full receive ring drops the frame for that destination only, and
//! the switch counts every drop per port.

/// Largest frame without FCS (1,500 bytes of payload).
pub const MAX_FRAME: usize = 1514;
/// Smallest frame the switch forwards: the Ethernet header.
pub const MIN_FRAME: usize = 14;
/// Most tenants.
pub const MAX_TENANTS: usize = 15;
/// Broadcast and multicast frames a tenant may send at once, and a second after that.
pub const GROUP_BURST: u32 = 32;
pub const GROUP_RATE: u32 = 100;

/// A MAC address.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Mac(pub [u8; 6]);

impl Mac {
    pub const BROADCAST: Mac = Mac([0xFF; 6]);

    /// `text` as six two-digit hex octets separated by colons (`52:54:00:12:34:56`).
    pub fn parse(text: &str) -> Option<Mac> {
        let mut mac = [0u8; 6];
        let mut parts = text.split(':');
        for octet in mac.iter_mut() {
            let part = parts.next()?;
            if part.len() != 2 || !part.bytes().all(|b| b.is_ascii_hexdigit()) {
                return None;
            }
            *octet = u8::from_str_radix(part, 16).ok()?;
        }
        parts.next().is_none().then_some(Mac(mac))
    }

    /// Broadcast or multicast (the group bit of the first octet).
    pub fn is_group(self) -> bool {
        self.0[0] & 1 != 0
    }
}

impl core::fmt::Display for Mac {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let m = self.0;
        write!(
            f,
            "{:02x}:{:02x}:{:02x}:{:02x}:{:02x}:{:02x}",
            m[0], m[1], m[2], m[3], m[4], m[5]
        )
    }
}

/// A port of the switch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Port {
    /// The physical NIC.
    Uplink,
    /// Tenant `n` (its index in the configuration).
    Tenant(usize),
}

impl Port {
    fn bit(self) -> u32 {
        match self {
            Port::Uplink => 1,
            Port::Tenant(n) => 2 << n,
        }
    }
}

/// A set of destination ports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Ports(u32);

impl Ports {
    pub fn contains(self, port: Port) -> bool {
        self.0 & port.bit() != 0
    }

    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The ports in the set: the uplink first, then the tenants in order.
    pub fn iter(self, tenants: usize) -> impl Iterator<Item = Port> {
        core::iter::once(Port::Uplink)
            .chain((0..tenants).map(Port::Tenant))
            .filter(move |p| self.contains(*p))
    }
}

/// Why a frame was not forwarded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Drop {
    /// Not 14..=1514 bytes.
    Malformed,
    /// A tenant's frame with a source MAC that is not its own.
    Spoofed,
    /// Unicast from the uplink to no tenant.
    Unknown,
    /// The port is not attached.
    NoSuchPort,
    /// A tenant's broadcast or multicast beyond its rate.
    Limited,
}

/// Per-port counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Frames taken from the port.
    pub received: u64,
    /// Frames delivered to the port.
    pub delivered: u64,
    pub malformed: u64,
    pub spoofed: u64,
    pub unknown: u64,
    /// Frames for the port dropped because its receive ring was full.
    pub overflow: u64,
    /// The tenant's broadcast and multicast frames beyond [`GROUP_RATE`].
    pub limited: u64,
}

/// The switch: the tenants' MACs and every port's counters.
#[derive(Clone, Debug)]
pub struct Switch {
    macs: [Mac; MAX_TENANTS],
    tenants: usize,
    counters: [Counters; MAX_TENANTS + 1],
    /// Each tenant's group frames left (a token bucket), and when it was last refilled.
    group_tokens: [u32; MAX_TENANTS],
    refilled_ns: u64,
    now_ns: u64,
}

/// A configuration error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConfigError {
    TooMany,
    /// A group (multicast) address cannot be an interface's MAC.
    GroupAddress(Mac),
    /// Two tenants with one MAC.
    Duplicate(Mac),
}

impl Switch {
    /// A switch for tenants with these MACs (in configuration order).
    pub fn new(macs: &[Mac]) -> Result<Self, ConfigError> {
        if macs.len() > MAX_TENANTS {
            return Err(ConfigError::TooMany);
        }
        for (i, mac) in macs.iter().enumerate() {
            if mac.is_group() {
                return Err(ConfigError::GroupAddress(*mac));
            }
            if macs[..i].contains(mac) {
                return Err(ConfigError::Duplicate(*mac));
            }
        }
        let mut table = [Mac([0; 6]); MAX_TENANTS];
        table[..macs.len()].copy_from_slice(macs);
        Ok(Switch {
            macs: table,
            tenants: macs.len(),
            counters: [Counters::default(); MAX_TENANTS + 1],
            group_tokens: [GROUP_BURST; MAX_TENANTS],
            refilled_ns: 0,
            now_ns: 0,
        })
    }

    /// The time (ns, any monotonic clock) for the tenants' group-frame rates; a clock that
    /// goes back is taken as standing still.
    pub fn set_time(&mut self, now_ns: u64) {
        self.now_ns = self.now_ns.max(now_ns);
        let per_token = 1_000_000_000 / u64::from(GROUP_RATE);
        let earned = (self.now_ns - self.refilled_ns) / per_token;
        if earned > 0 {
            let earned = earned.min(u64::from(GROUP_BURST)) as u32;
            for tokens in &mut self.group_tokens {
                *tokens = (*tokens + earned).min(GROUP_BURST);
            }
            self.refilled_ns = self.now_ns;
        }
    }

    pub fn tenants(&self) -> usize {
        self.tenants
    }

    fn slot(&self, port: Port) -> Option<usize> {
        match port {
            Port::Uplink => Some(0),
            Port::Tenant(n) if n < self.tenants => Some(n + 1),
            Port::Tenant(_) => None,
        }
    }

    /// The counters of `port` (zero for a port that is not attached).
    pub fn counters(&self, port: Port) -> Counters {
        self.slot(port)
            .map_or_else(Counters::default, |s| self.counters[s])
    }

    /// Where a frame that arrived on `from` goes (counted as received, and as the drop's
    /// reason when it goes nowhere).
    pub fn route(&mut self, from: Port, frame: &[u8]) -> Result<Ports, Drop> {
        let Some(slot) = self.slot(from) else {
            return Err(Drop::NoSuchPort);
        };
        let counters = &mut self.counters[slot];
        counters.received += 1;
        if !(MIN_FRAME..=MAX_FRAME).contains(&frame.len()) {
            counters.malformed += 1;
            return Err(Drop::Malformed);
        }
        let mac = |at: usize| {
            let mut m = [0u8; 6];
            m.copy_from_slice(&frame[at..at + 6]);
            Mac(m)
        };
        let (destination, source) = (mac(0), mac(6));
        if let Port::Tenant(n) = from
            && source != self.macs[n]
        {
            counters.spoofed += 1;
            return Err(Drop::Spoofed);
        }
        let all = (1u32 | ((1u32 << self.tenants) - 1) << 1) & !from.bit();
        if destination.is_group() {
            if let Port::Tenant(n) = from {
                if self.group_tokens[n] == 0 {
                    counters.limited += 1;
                    return Err(Drop::Limited);
                }
                self.group_tokens[n] -= 1;
            }
            return Ok(Ports(all));
        }
        if let Some(n) = self.macs[..self.tenants]
            .iter()
            .position(|m| *m == destination)
        {
            let to = Port::Tenant(n);
            // A frame to the sender's own MAC goes nowhere: a stack loops its own traffic
            // back itself.
            return if to == from {
                counters.unknown += 1;
                Err(Drop::Unknown)
            } else {
                Ok(Ports(to.bit()))
            };
        }
        match from {
            Port::Tenant(_) => Ok(Ports(Port::Uplink.bit())),
            Port::Uplink => {
                counters.unknown += 1;
                Err(Drop::Unknown)
            }
        }
    }

    /// Counts a frame delivered to `to` (`true`) or dropped because its ring was full.
    pub fn delivered(&mut self, to: Port, fitted: bool) {
        if let Some(slot) = self.slot(to) {
            if fitted {
                self.counters[slot].delivered += 1;
            } else {
                self.counters[slot].overflow += 1;
            }
        }
    }
}

/// Round-robin service of the tenants' transmit rings with a per-round budget each.
#[derive(Clone, Copy, Debug)]
pub struct Rounds {
    budget: u32,
    tenants: usize,
    next: usize,
    left: u32,
}

impl Rounds {
    /// `budget` frames per tenant and round (at least 1).
    pub fn new(tenants: usize, budget: u32) -> Self {
        Rounds {
            budget: budget.max(1),
            tenants,
            next: 0,
            left: budget.max(1),
        }
    }

    /// The tenant whose ring to take the next frame from, given which rings have frames
    /// (`pending(n)`), or `None` when all are empty. Call [`Rounds::took`] after taking one.
    pub fn pick(&mut self, pending: impl Fn(usize) -> bool) -> Option<usize> {
        for _ in 0..=self.tenants {
            if self.tenants == 0 {
                return None;
            }
            if self.left > 0 && pending(self.next) {
                return Some(self.next);
            }
            self.next = (self.next + 1) % self.tenants;
            self.left = self.budget;
        }
        None
    }

    /// One frame was taken from the tenant [`Rounds::pick`] named.
    pub fn took(&mut self) {
        self.left = self.left.saturating_sub(1);
    }
}

#[cfg(test)]
mod tests;
