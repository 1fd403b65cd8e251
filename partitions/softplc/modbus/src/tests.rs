//! The codec and server against the Modbus Application Protocol specification's own
//! examples, every function and exception, and hostile input.

extern crate std;

use super::*;
use proptest::prelude::*;
use std::vec;
use std::vec::Vec;

/// An image of 16 input, 16 output and 16 marker bytes.
struct Image {
    input: Vec<u8>,
    output: Vec<u8>,
    memory: Vec<u8>,
}

impl Image {
    fn new() -> Self {
        Image {
            input: (0..16).collect(),
            output: vec![0; 16],
            memory: vec![0; 16],
        }
    }
}

impl ProcessImage for Image {
    fn area(&self, area: Area) -> &[u8] {
        match area {
            Area::Input => &self.input,
            Area::Output => &self.output,
            Area::Memory => &self.memory,
        }
    }
    fn area_mut(&mut self, area: Area) -> &mut [u8] {
        match area {
            Area::Input => &mut self.input,
            Area::Output => &mut self.output,
            Area::Memory => &mut self.memory,
        }
    }
}

const SERVER: Server = Server {
    unit: 1,
    writable: Writable {
        outputs: true,
        markers: true,
    },
    running: true,
};

/// Sends `pdu` as one ADU to unit 1 and returns the response PDU.
fn call(server: &Server, image: &mut Image, pdu: &[u8]) -> Vec<u8> {
    call_unit(server, image, 1, pdu)
}

fn call_unit(server: &Server, image: &mut Image, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut adu = vec![0x12, 0x34, 0, 0];
    adu.extend_from_slice(&(pdu.len() as u16 + 1).to_be_bytes());
    adu.push(unit);
    adu.extend_from_slice(pdu);
    let Ok(Frame::Complete { header, pdu, len }) = split_frame(&adu) else {
        panic!("a whole ADU")
    };
    assert_eq!(len, adu.len());
    let mut out = [0u8; MAX_ADU];
    let n = respond(server, header, pdu, image, &mut out);
    assert_eq!(&out[..2], &[0x12, 0x34], "transaction echoed");
    assert_eq!(&out[2..4], &[0, 0]);
    assert_eq!(usize::from(u16::from_be_bytes([out[4], out[5]])), n - 6);
    assert_eq!(out[6], unit);
    out[7..n].to_vec()
}

fn exception(function: u8, code: Exception) -> Vec<u8> {
    vec![function | 0x80, code.code()]
}

#[test]
fn reads_each_table_from_its_area() {
    let mut image = Image::new();
    image.output[0] = 0b1010_0101;
    image.output[1] = 0b0000_0011;
    image.memory[2] = 0x34;
    image.memory[3] = 0x12;
    // Coils 0..10 = %QX0.0..%QX1.1, LSB first.
    assert_eq!(
        call(&SERVER, &mut image, &[1, 0, 0, 0, 10]),
        [1, 2, 0b1010_0101, 0b11]
    );
    // Discrete inputs 8..12 = %IX1.0..%IX1.3: input byte 1 is 0x01.
    assert_eq!(call(&SERVER, &mut image, &[2, 0, 8, 0, 4]), [2, 1, 0b0001]);
    // Input registers 1..3 = %IW1, %IW2: bytes 2,3 and 4,5 little-endian, sent big-endian.
    assert_eq!(
        call(&SERVER, &mut image, &[4, 0, 1, 0, 2]),
        [4, 4, 3, 2, 5, 4]
    );
    // Holding register 0x3001 = %MW1.
    assert_eq!(
        call(&SERVER, &mut image, &[3, 0x30, 1, 0, 1]),
        [3, 2, 0x12, 0x34]
    );
}

#[test]
fn writes_land_in_the_image() {
    let mut image = Image::new();
    assert_eq!(
        call(&SERVER, &mut image, &[5, 0, 9, 0xFF, 0]),
        [5, 0, 9, 0xFF, 0]
    );
    assert_eq!(image.output[1], 0b10, "%QX1.1");
    assert_eq!(call(&SERVER, &mut image, &[5, 0, 9, 0, 0]), [5, 0, 9, 0, 0]);
    assert_eq!(image.output[1], 0);
    assert_eq!(
        call(&SERVER, &mut image, &[6, 0, 2, 0xAB, 0xCD]),
        [6, 0, 2, 0xAB, 0xCD]
    );
    assert_eq!(&image.output[4..6], &[0xCD, 0xAB], "%QW2 little-endian");
    // Coils 0x3000..0x300A = %MX0.0..%MX1.1.
    let coils = [15, 0x30, 0, 0, 10, 2, 0xFF, 0b01];
    assert_eq!(call(&SERVER, &mut image, &coils), [15, 0x30, 0, 0, 10]);
    assert_eq!(&image.memory[..2], &[0xFF, 0b01]);
    let regs = [16, 0x30, 4, 0, 2, 4, 0, 1, 0x80, 0];
    assert_eq!(call(&SERVER, &mut image, &regs), [16, 0x30, 4, 0, 2]);
    assert_eq!(&image.memory[8..12], &[1, 0, 0, 0x80]);
    // Where each write landed, as `written` says.
    assert_eq!(written(&[5, 0, 9, 0xFF, 0]), Some((Area::Output, 1..2)));
    assert_eq!(written(&[6, 0, 2, 0xAB, 0xCD]), Some((Area::Output, 4..6)));
    assert_eq!(written(&coils), Some((Area::Memory, 0..2)));
    assert_eq!(written(&regs), Some((Area::Memory, 8..12)));
    assert_eq!(written(&[3, 0x30, 0, 0, 1]), None, "a read");
    assert_eq!(written(&[6, 0, 2]), None, "cut short");
}

#[test]
fn every_exception_is_provoked() {
    let mut image = Image::new();
    use Exception::*;
    // 1: unknown or unsupported function codes.
    for function in [0u8, 7, 8, 17, 23, 43, 0x7F, 0x81] {
        assert_eq!(
            call(&SERVER, &mut image, &[function, 0, 0, 0, 1]),
            exception(function, IllegalFunction)
        );
    }
    // 2: beyond the area, across the output/marker border, into the inputs.
    assert_eq!(
        call(&SERVER, &mut image, &[3, 0, 8, 0, 1]),
        exception(3, IllegalDataAddress)
    );
    assert_eq!(
        call(&SERVER, &mut image, &[1, 0, 120, 0, 9]),
        exception(1, IllegalDataAddress)
    );
    assert_eq!(
        call(&SERVER, &mut image, &[3, 0x2F, 0xFF, 0, 2]),
        exception(3, IllegalDataAddress)
    );
    assert_eq!(
        call(&SERVER, &mut image, &[4, 0xFF, 0xFF, 0, 1]),
        exception(4, IllegalDataAddress)
    );
    // 3: quantities, byte counts, coil values, PDU lengths.
    assert_eq!(
        call(&SERVER, &mut image, &[3, 0, 0, 0, 0]),
        exception(3, IllegalDataValue)
    );
    assert_eq!(
        call(&SERVER, &mut image, &[3, 0, 0, 0, 126]),
        exception(3, IllegalDataValue)
    );
    assert_eq!(
        call(&SERVER, &mut image, &[1, 0, 0, 0x07, 0xD1]),
        exception(1, IllegalDataValue)
    );
    assert_eq!(
        call(&SERVER, &mut image, &[5, 0, 0, 0x12, 0x34]),
        exception(5, IllegalDataValue)
    );
    assert_eq!(
        call(&SERVER, &mut image, &[6, 0, 0, 1]),
        exception(6, IllegalDataValue)
    );
    assert_eq!(
        call(&SERVER, &mut image, &[15, 0, 0, 0, 9, 1, 0xFF]),
        exception(15, IllegalDataValue)
    );
    assert_eq!(
        call(&SERVER, &mut image, &[16, 0, 0, 0, 1, 2, 0]),
        exception(16, IllegalDataValue)
    );
    assert_eq!(
        call(&SERVER, &mut image, &[16, 0, 0, 0, 124, 248]),
        exception(16, IllegalDataValue)
    );
    // 4: a write while the program is stopped; reads still answer.
    let stopped = Server {
        running: false,
        ..SERVER
    };
    assert_eq!(
        call(&stopped, &mut image, &[6, 0, 0, 0, 1]),
        exception(6, ServerDeviceFailure)
    );
    assert_eq!(call(&stopped, &mut image, &[4, 0, 0, 0, 1]), [4, 2, 1, 0]);
    // 0x0A: another unit; 0xFF is this device.
    assert_eq!(
        call_unit(&SERVER, &mut image, 7, &[4, 0, 0, 0, 1]),
        exception(4, GatewayPathUnavailable)
    );
    assert_eq!(
        call_unit(&SERVER, &mut image, 0xFF, &[4, 0, 0, 0, 1]),
        [4, 2, 1, 0]
    );
}

#[test]
fn read_only_areas_refuse_writes_and_keep_their_bytes() {
    let mut image = Image::new();
    let read_only = Server {
        writable: Writable {
            outputs: false,
            markers: true,
        },
        ..SERVER
    };
    assert_eq!(
        call(&read_only, &mut image, &[6, 0, 0, 0, 1]),
        exception(6, Exception::IllegalDataAddress)
    );
    assert_eq!(
        call(&read_only, &mut image, &[15, 0, 0, 0, 8, 1, 0xFF]),
        exception(15, Exception::IllegalDataAddress)
    );
    assert_eq!(image.output, vec![0; 16]);
    assert_eq!(
        call(&read_only, &mut image, &[6, 0x30, 0, 0, 1]),
        [6, 0x30, 0, 0, 1]
    );
}

#[test]
fn largest_reads_fit_one_adu() {
    let mut image = Image {
        input: vec![0xA5; 4096],
        output: vec![0; 4096],
        memory: vec![0; 4096],
    };
    let coils = call(&SERVER, &mut image, &[2, 0, 0, 0x07, 0xD0]);
    assert_eq!((coils.len(), coils[1]), (2 + 250, 250));
    let regs = call(&SERVER, &mut image, &[4, 0, 0, 0, 125]);
    assert_eq!((regs.len(), regs[1]), (2 + 250, 250));
}

#[test]
fn framing_waits_splits_and_refuses() {
    assert_eq!(split_frame(&[0, 1, 0]), Ok(Frame::Incomplete { need: 7 }));
    assert_eq!(
        split_frame(&[0, 1, 0, 0, 0, 6, 1, 3]),
        Ok(Frame::Incomplete { need: 12 })
    );
    let two = [0, 1, 0, 0, 0, 2, 1, 7, 0, 2, 0, 0, 0, 2, 1, 8];
    let Ok(Frame::Complete { header, pdu, len }) = split_frame(&two) else {
        panic!()
    };
    assert_eq!(
        (header.transaction, header.unit, pdu, len),
        (1, 1, &[7u8][..], 8)
    );
    assert!(matches!(
        split_frame(&two[len..]),
        Ok(Frame::Complete { len: 8, .. })
    ));
    assert_eq!(
        split_frame(&[0, 1, 0, 1, 0, 6, 1]),
        Err(FrameError::Protocol(1))
    );
    assert_eq!(
        split_frame(&[0, 1, 0, 0, 0, 1, 1]),
        Err(FrameError::Length(1))
    );
    assert_eq!(
        split_frame(&[0, 1, 0, 0, 0, 255, 1]),
        Err(FrameError::Length(255))
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(5_000))]

    /// Any bytes: framing never panics; every complete frame gets a well-formed response,
    /// a normal one for its own function code or an exception with a defined code.
    #[test]
    fn hostile_bytes_get_a_defined_answer(bytes in proptest::collection::vec(any::<u8>(), 0..300),
                                          unit in any::<u8>(), running in any::<bool>()) {
        let mut image = Image::new();
        let server = Server { running, ..SERVER };
        let mut rest = &bytes[..];
        while let Ok(Frame::Complete { header, pdu, len }) = split_frame(rest) {
            let mut out = [0u8; MAX_ADU];
            let n = respond(&server, Header { unit, ..header }, pdu, &mut image, &mut out);
            prop_assert!((9..=MAX_ADU).contains(&n));
            prop_assert_eq!(usize::from(u16::from_be_bytes([out[4], out[5]])), n - 6);
            let function = pdu.first().copied().unwrap_or(0);
            if out[7] & 0x80 != 0 {
                prop_assert_eq!(n, 9);
                prop_assert!(Exception::from_code(out[8]).is_some());
            } else {
                prop_assert_eq!(out[7], function);
            }
            rest = &rest[len..];
        }
    }

    /// Well-formed random requests: decoding and the server agree with a direct model of
    /// the address map on which exception (if any) a request gets.
    /// Frames with a valid header around a random PDU (function codes mostly the
    /// defined ones and their neighbours): answered, never a panic, writes only where
    /// the map allows.
    #[test]
    fn random_pdus_get_a_defined_answer(function in 0u8..20, data in proptest::collection::vec(any::<u8>(), 0..252)) {
        let mut image = Image::new();
        let mut pdu = vec![function];
        pdu.extend_from_slice(&data);
        let answer = call(&SERVER, &mut image, &pdu);
        prop_assert!(answer[0] == function || (answer[0] == function | 0x80 && answer.len() == 2));
        prop_assert_eq!(&image.input, &(0..16).collect::<Vec<u8>>(), "inputs are never written");
        // What changed lies in what `written` says the request covers.
        let before = Image::new();
        let changed = |area: Area| -> Vec<usize> {
            let (now, was) = match area {
                Area::Input => (&image.input, &before.input),
                Area::Output => (&image.output, &before.output),
                Area::Memory => (&image.memory, &before.memory),
            };
            (0..now.len()).filter(|&i| now[i] != was[i]).collect()
        };
        for area in [Area::Output, Area::Memory] {
            for byte in changed(area) {
                prop_assert!(
                    written(&pdu).is_some_and(|(a, bytes)| a == area && bytes.contains(&byte)),
                    "{:?} byte {} changed outside {:?}", area, byte, written(&pdu)
                );
            }
        }
    }

    #[test]
    fn random_reads_match_the_map(function in 1u8..=4, start in any::<u16>(), quantity in 0u16..2100) {
        let mut image = Image::new();
        let mut pdu = vec![function];
        pdu.extend_from_slice(&start.to_be_bytes());
        pdu.extend_from_slice(&quantity.to_be_bytes());
        let answer = call(&SERVER, &mut image, &pdu);
        let bits = function <= 2;
        let max = if bits { 2000 } else { 125 };
        let (s, e) = (u32::from(start), u32::from(start) + u32::from(quantity));
        let marker = u32::from(MARKER_BASE);
        let units = if bits { 128 } else { 8 };
        let expected = if quantity == 0 || quantity > max {
            Some(Exception::IllegalDataValue)
        } else if matches!(function, 2 | 4) {
            (e > units).then_some(Exception::IllegalDataAddress)
        } else if s >= marker {
            (e - marker > units).then_some(Exception::IllegalDataAddress)
        } else {
            (e > units).then_some(Exception::IllegalDataAddress)
        };
        match expected {
            Some(code) => prop_assert_eq!(answer, exception(function, code)),
            None => prop_assert_eq!(answer[0], function),
        }
    }
}
