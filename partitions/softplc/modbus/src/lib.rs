//! Modbus/TCP server side on the PLC's process image: framing (MBAP), request decoding,
//! the address map onto the located-variable areas, and the responses. An interface; no_std,
//! no allocation, and nothing a client sends can panic it: every request gets a response or
//! an exception, and a byte stream that is not Modbus/TCP is a [`FrameError`] after which the
//! server closes the connection.
//!
//! # Framing
//!
//! An ADU is the MBAP header — `transaction u16, protocol u16 (0), length u16, unit u8`, big
//! endian, `length` counting the unit byte and the PDU — then the PDU, `function u8, data`.
//! `length` is 2..=254 (an ADU is at most [`MAX_ADU`] = 260 bytes). A protocol other than 0
//! or a length outside that range is a [`FrameError`]. Requests may arrive split over TCP
//! segments or several in one: [`split_frame`] says how many bytes the first one needs.
//!
//! # Functions and exceptions
//!
//! | function | request data | response data |
//! |---|---|---|
//! | 1 read coils | `start u16, quantity u16` (1..=2000) | `bytes u8`, the bits, LSB first |
//! | 2 read discrete inputs | as 1 | as 1 |
//! | 3 read holding registers | `start u16, quantity u16` (1..=125) | `bytes u8`, the registers |
//! | 4 read input registers | as 3 | as 3 |
//! | 5 write single coil | `address u16, value u16` (0xFF00 on, 0x0000 off) | the request echoed |
//! | 6 write single register | `address u16, value u16` | the request echoed |
//! | 15 write multiple coils | `start u16, quantity u16` (1..=1968), `bytes u8` (= ⌈quantity/8⌉), the bits | `start, quantity` |
//! | 16 write multiple registers | `start u16, quantity u16` (1..=123), `bytes u8` (= 2·quantity), the registers | `start, quantity` |
//!
//! An exception response is `function | 0x80, code u8` ([`Exception`]): 1 ILLEGAL FUNCTION for
//! any other function code; 2 ILLEGAL DATA ADDRESS for a range that leaves the mapped area,
//! crosses from the outputs into the markers, or writes an area the configuration keeps
//! read-only; 3 ILLEGAL DATA VALUE for a quantity out of range, a byte count that does not
//! match, a coil value other than 0xFF00/0x0000 or a PDU of the wrong length; 4 SERVER DEVICE
//! FAILURE for a write while the PLC program is stopped (nothing would take it into a scan;
//! reads are answered with the image as the last cycle left it); 0x0A GATEWAY PATH UNAVAILABLE
//! for a unit id other than the configured one and 0xFF (the "this device" id of Modbus/TCP).
//!
//! # Address map (as WAGO's and CODESYS's controllers count)
//!
//! Areas are the located-variable areas of `plc_vm::located` (little-endian byte arrays, a
//! word `%xWn` is bytes `2n..2n+1`, a bit `%xXb.i` is bit `i` of byte `b`). A register's
//! value is that word (sent big-endian as Modbus requires).
//!
//! | table | Modbus address `a` | located variable |
//! |---|---|---|
//! | discrete inputs (1x) | `a` | `%IX(a/8).(a%8)` |
//! | coils (0x) | `a` < 12288 | `%QX(a/8).(a%8)` |
//! | coils (0x) | 12288 ≤ `a` | `%MX(b/8).(b%8)`, `b = a − 12288` |
//! | input registers (3x) | `a` | `%IW a` |
//! | holding registers (4x) | `a` < 12288 | `%QW a` |
//! | holding registers (4x) | 12288 ≤ `a` | `%MW (a − 12288)` |
//!
//! 12288 (0x3000) is where WAGO's PFC controllers place `%MW0` and `%MX0.0`; a range must lie
//! in one area. Writes ([`Writable`]) are refused unless the configuration allows that area;
//! an accepted write changes the image the server was given — the runtime hands that image
//! to the scan between cycles, never during one.

#![no_std]

use plc_vm::located::Area;

/// Largest ADU: the 7-byte MBAP header and a 253-byte PDU.
pub const MAX_ADU: usize = 260;
/// Bytes of the MBAP header (including the unit id).
pub const MBAP_LEN: usize = 7;
/// First coil / holding register of the marker area (`%MX0.0`, `%MW0`).
pub const MARKER_BASE: u16 = 0x3000;
/// The unit id that addresses the device itself on Modbus/TCP.
pub const THIS_DEVICE: u8 = 0xFF;

codes::code_enum! {
    /// A Modbus exception code.
    pub enum Exception: u8 {
        /// The function code is not supported.
        IllegalFunction = 1 => "ILLEGAL_FUNCTION",
        /// The address range is not mapped or not writable.
        IllegalDataAddress = 2 => "ILLEGAL_DATA_ADDRESS",
        /// A quantity, byte count, coil value or PDU length is wrong.
        IllegalDataValue = 3 => "ILLEGAL_DATA_VALUE",
        /// The PLC cannot carry the request out (its program is stopped).
        ServerDeviceFailure = 4 => "SERVER_DEVICE_FAILURE",
        /// No device with that unit id is behind this server.
        GatewayPathUnavailable = 10 => "GATEWAY_PATH_UNAVAILABLE",
    }
}

/// Why a byte stream is not Modbus/TCP; the server closes the connection.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// The MBAP protocol identifier is not 0.
    Protocol(u16),
    /// The MBAP length is outside 2..=254.
    Length(u16),
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FrameError::Protocol(p) => write!(f, "MBAP protocol identifier {p}, expected 0"),
            FrameError::Length(l) => write!(f, "MBAP length {l}, expected 2..=254"),
        }
    }
}

/// The MBAP fields a response echoes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    pub transaction: u16,
    pub unit: u8,
}

/// The first request in a receive buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Frame<'a> {
    /// More bytes are needed: at least this many in all.
    Incomplete { need: usize },
    /// A whole ADU of `len` bytes.
    Complete {
        header: Header,
        pdu: &'a [u8],
        len: usize,
    },
}

fn be16(bytes: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([bytes[at], bytes[at + 1]])
}

/// Finds the first ADU in `buffer` (the bytes received so far on a connection).
pub fn split_frame(buffer: &[u8]) -> Result<Frame<'_>, FrameError> {
    if buffer.len() < MBAP_LEN {
        return Ok(Frame::Incomplete { need: MBAP_LEN });
    }
    let protocol = be16(buffer, 2);
    if protocol != 0 {
        return Err(FrameError::Protocol(protocol));
    }
    let length = be16(buffer, 4);
    if !(2..=254).contains(&length) {
        return Err(FrameError::Length(length));
    }
    let len = 6 + length as usize;
    if buffer.len() < len {
        return Ok(Frame::Incomplete { need: len });
    }
    Ok(Frame::Complete {
        header: Header {
            transaction: be16(buffer, 0),
            unit: buffer[6],
        },
        pdu: &buffer[MBAP_LEN..len],
        len,
    })
}

/// The object tables of the Modbus data model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Table {
    DiscreteInputs,
    Coils,
    InputRegisters,
    HoldingRegisters,
}

impl Table {
    fn is_bits(self) -> bool {
        matches!(self, Table::DiscreteInputs | Table::Coils)
    }
}

/// A decoded request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Request<'a> {
    /// Functions 1-4.
    Read {
        table: Table,
        start: u16,
        quantity: u16,
    },
    /// Function 5.
    WriteCoil { address: u16, on: bool },
    /// Function 6.
    WriteRegister { address: u16, value: u16 },
    /// Function 15: `bits` LSB first, ⌈quantity/8⌉ bytes.
    WriteCoils {
        start: u16,
        quantity: u16,
        bits: &'a [u8],
    },
    /// Function 16: `values` big-endian, 2·quantity bytes.
    WriteRegisters {
        start: u16,
        quantity: u16,
        values: &'a [u8],
    },
}

impl Request<'_> {
    /// The table, first address and quantity of the objects the request reads or writes.
    pub fn objects(&self) -> (Table, u16, u16) {
        match *self {
            Request::Read {
                table,
                start,
                quantity,
            } => (table, start, quantity),
            Request::WriteCoil { address, .. } => (Table::Coils, address, 1),
            Request::WriteRegister { address, .. } => (Table::HoldingRegisters, address, 1),
            Request::WriteCoils {
                start, quantity, ..
            } => (Table::Coils, start, quantity),
            Request::WriteRegisters {
                start, quantity, ..
            } => (Table::HoldingRegisters, start, quantity),
        }
    }
}

/// Decodes a request PDU (function code and data).
pub fn decode_request(pdu: &[u8]) -> Result<Request<'_>, Exception> {
    let Some((&function, data)) = pdu.split_first() else {
        return Err(Exception::IllegalFunction);
    };
    let fixed = |data: &[u8]| -> Result<(u16, u16), Exception> {
        if data.len() != 4 {
            return Err(Exception::IllegalDataValue);
        }
        Ok((be16(data, 0), be16(data, 2)))
    };
    let read = |table, max: u16| -> Result<Request<'_>, Exception> {
        let (start, quantity) = fixed(data)?;
        if !(1..=max).contains(&quantity) {
            return Err(Exception::IllegalDataValue);
        }
        Ok(Request::Read {
            table,
            start,
            quantity,
        })
    };
    match function {
        1 => read(Table::Coils, 2000),
        2 => read(Table::DiscreteInputs, 2000),
        3 => read(Table::HoldingRegisters, 125),
        4 => read(Table::InputRegisters, 125),
        5 => {
            let (address, value) = fixed(data)?;
            match value {
                0xFF00 => Ok(Request::WriteCoil { address, on: true }),
                0x0000 => Ok(Request::WriteCoil { address, on: false }),
                _ => Err(Exception::IllegalDataValue),
            }
        }
        6 => {
            let (address, value) = fixed(data)?;
            Ok(Request::WriteRegister { address, value })
        }
        15 | 16 => {
            if data.len() < 5 {
                return Err(Exception::IllegalDataValue);
            }
            let (start, quantity) = (be16(data, 0), be16(data, 2));
            let payload = &data[5..];
            let (max, bytes) = if function == 15 {
                (1968, quantity.div_ceil(8))
            } else {
                (123, quantity.wrapping_mul(2))
            };
            if !(1..=max).contains(&quantity)
                || usize::from(data[4]) != usize::from(bytes)
                || payload.len() != usize::from(bytes)
            {
                return Err(Exception::IllegalDataValue);
            }
            Ok(if function == 15 {
                Request::WriteCoils {
                    start,
                    quantity,
                    bits: payload,
                }
            } else {
                Request::WriteRegisters {
                    start,
                    quantity,
                    values: payload,
                }
            })
        }
        _ => Err(Exception::IllegalFunction),
    }
}

/// Where a range of a table lies: the area and the first bit or word in it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Placement {
    pub area: Area,
    /// The first bit (bit tables) or word (register tables) in the area.
    pub first: u32,
}

/// The area and offset of `quantity` objects of `table` from `start` (the address map of
/// the module doc), or `None` when the range leaves one area's side of the map. The area's
/// size is checked by the caller.
pub fn place(table: Table, start: u16, quantity: u16) -> Option<Placement> {
    let end = u32::from(start) + u32::from(quantity);
    let split = |low: Area| {
        if start >= MARKER_BASE {
            Some(Placement {
                area: Area::Memory,
                first: u32::from(start - MARKER_BASE),
            })
        } else if end <= u32::from(MARKER_BASE) {
            Some(Placement {
                area: low,
                first: u32::from(start),
            })
        } else {
            None
        }
    };
    match table {
        Table::DiscreteInputs | Table::InputRegisters => Some(Placement {
            area: Area::Input,
            first: u32::from(start),
        }),
        Table::Coils | Table::HoldingRegisters => split(Area::Output),
    }
}

/// Which areas a client may write (the configuration's `plc.modbus.writable`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Writable {
    /// Coils 0..12288 and holding registers 0..12288 (`%QX`, `%QW`).
    pub outputs: bool,
    /// Coils and holding registers from 12288 (`%MX`, `%MW`).
    pub markers: bool,
}

impl Writable {
    fn allows(self, area: Area) -> bool {
        match area {
            Area::Input => false,
            Area::Output => self.outputs,
            Area::Memory => self.markers,
        }
    }
}

/// The process image a request works on: the three areas' bytes.
pub trait ProcessImage {
    fn area(&self, area: Area) -> &[u8];
    fn area_mut(&mut self, area: Area) -> &mut [u8];
}

/// What the server knows besides the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Server {
    /// The configured unit id (0xFF is always accepted too).
    pub unit: u8,
    pub writable: Writable,
    /// Whether the PLC program runs (writes are refused while it is stopped).
    pub running: bool,
}

/// Serves one ADU: decodes `pdu`, carries it out on `image` and writes the response ADU
/// into `out`; returns its length.
pub fn respond(
    server: &Server,
    header: Header,
    pdu: &[u8],
    image: &mut impl ProcessImage,
    out: &mut [u8; MAX_ADU],
) -> usize {
    let function = pdu.first().copied().unwrap_or(0);
    let body = if header.unit != server.unit && header.unit != THIS_DEVICE {
        Err(Exception::GatewayPathUnavailable)
    } else {
        decode_request(pdu).and_then(|request| execute(server, request, image, &mut out[8..]))
    };
    let pdu_len = match body {
        Ok(len) => {
            out[7] = function;
            1 + len
        }
        Err(exception) => {
            out[7] = function | 0x80;
            out[8] = exception.code();
            2
        }
    };
    out[0..2].copy_from_slice(&header.transaction.to_be_bytes());
    out[2..4].copy_from_slice(&0u16.to_be_bytes());
    out[4..6].copy_from_slice(&(1 + pdu_len as u16).to_be_bytes());
    out[6] = header.unit;
    MBAP_LEN + pdu_len
}

/// The bytes of `area` that `count` bits or words from `first` cover, if it has them.
fn span(area: &[u8], bits: bool, first: u32, count: u16) -> Option<core::ops::Range<usize>> {
    let bytes = bytes_of(bits, first, count);
    (bytes.end <= area.len()).then_some(bytes)
}

/// The bytes that `count` bits or words from `first` cover.
fn bytes_of(bits: bool, first: u32, count: u16) -> core::ops::Range<usize> {
    let (from, to) = if bits {
        (first / 8, (first + u32::from(count)).div_ceil(8))
    } else {
        (first * 2, (first + u32::from(count)) * 2)
    };
    from as usize..to as usize
}

/// The area and bytes a write request (`pdu`) covers; `None` for a read or a request
/// that does not decode. A server that keeps the image's values in a second place too
/// (the soft-PLC: its program's variables) carries these bytes over after a write that
/// [`respond`] carried out (its response is no exception).
pub fn written(pdu: &[u8]) -> Option<(Area, core::ops::Range<usize>)> {
    let request = decode_request(pdu).ok()?;
    if matches!(request, Request::Read { .. }) {
        return None;
    }
    let (table, start, quantity) = request.objects();
    let place = place(table, start, quantity)?;
    Some((place.area, bytes_of(table.is_bits(), place.first, quantity)))
}

/// Carries out `request`, writing the response data (after the function code) into `out`.
fn execute(
    server: &Server,
    request: Request<'_>,
    image: &mut impl ProcessImage,
    out: &mut [u8],
) -> Result<usize, Exception> {
    let (table, start, quantity) = request.objects();
    let place = place(table, start, quantity).ok_or(Exception::IllegalDataAddress)?;
    let bits = table.is_bits();
    span(image.area(place.area), bits, place.first, quantity)
        .ok_or(Exception::IllegalDataAddress)?;
    if !matches!(request, Request::Read { .. }) {
        if !server.writable.allows(place.area) {
            return Err(Exception::IllegalDataAddress);
        }
        if !server.running {
            return Err(Exception::ServerDeviceFailure);
        }
    }
    let first = place.first as usize;
    match request {
        Request::Read { .. } => {
            let area = image.area(place.area);
            let n = usize::from(quantity);
            let bytes = if bits { n.div_ceil(8) } else { 2 * n };
            out[0] = bytes as u8;
            let data = &mut out[1..1 + bytes];
            data.fill(0);
            for i in 0..n {
                if bits {
                    let bit = first + i;
                    if area[bit / 8] >> (bit % 8) & 1 != 0 {
                        data[i / 8] |= 1 << (i % 8);
                    }
                } else {
                    let w = 2 * (first + i);
                    data[2 * i..2 * i + 2].copy_from_slice(&[area[w + 1], area[w]]);
                }
            }
            Ok(1 + bytes)
        }
        Request::WriteCoil { address, on } => {
            set_bit(image.area_mut(place.area), first, on);
            out[..2].copy_from_slice(&address.to_be_bytes());
            out[2..4].copy_from_slice(&(if on { 0xFF00u16 } else { 0 }).to_be_bytes());
            Ok(4)
        }
        Request::WriteRegister { address, value } => {
            let area = image.area_mut(place.area);
            area[2 * first..2 * first + 2].copy_from_slice(&value.to_le_bytes());
            out[..2].copy_from_slice(&address.to_be_bytes());
            out[2..4].copy_from_slice(&value.to_be_bytes());
            Ok(4)
        }
        Request::WriteCoils { bits: payload, .. } => {
            let area = image.area_mut(place.area);
            for i in 0..usize::from(quantity) {
                set_bit(area, first + i, payload[i / 8] >> (i % 8) & 1 != 0);
            }
            echo_range(out, start, quantity)
        }
        Request::WriteRegisters { values, .. } => {
            let area = image.area_mut(place.area);
            for (i, value) in values.chunks_exact(2).enumerate() {
                let w = 2 * (first + i);
                area[w..w + 2].copy_from_slice(&[value[1], value[0]]);
            }
            echo_range(out, start, quantity)
        }
    }
}

fn set_bit(area: &mut [u8], bit: usize, on: bool) {
    let mask = 1 << (bit % 8);
    if on {
        area[bit / 8] |= mask;
    } else {
        area[bit / 8] &= !mask;
    }
}

fn echo_range(out: &mut [u8], start: u16, quantity: u16) -> Result<usize, Exception> {
    out[..2].copy_from_slice(&start.to_be_bytes());
    out[2..4].copy_from_slice(&quantity.to_be_bytes());
    Ok(4)
}

#[cfg(test)]
mod tests;
