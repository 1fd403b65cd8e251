//! The management protocol on TCP, as 4diac IDE speaks it to FORTE's device manager on
//! port [`PORT`] (61499): each request is two ASN.1 STRINGs of the FBDK encoding (tag
//! `0x50`, the length as u16 big-endian, the bytes), the destination (empty: the device;
//! else a resource's name) and the request's XML; each response is one STRING, the
//! response's XML. Requests follow each other on a connection and are answered in order.
//! The requests are the message ports' requests: [`crate::serve::serve_parts`] reads,
//! checks and carries out both.
//!
//! [`next_request`] finds the next whole request in a connection's bytes, however TCP cut
//! them into segments; with the feature `net`, [`server`] serves the protocol on a
//! [`netstack`] stack.
//!
//! Bounds: a request is at most [`MAX_REQUEST`] bytes (both STRINGs with their headers), a
//! response at most [`MAX_RESPONSE`] bytes of XML (a longer one is the request's refusal
//! with OVERFLOW, as on the ports). A stream that is not this framing (a tag other than
//! `0x50`) or announces a longer request gets one refusal, `BAD_PARAMS` or `OVERFLOW`
//! with an empty ID, and its connection is closed (the rest of the stream cannot be read
//! as requests).

use alloc::vec::Vec;
use core::ops::Range;

/// FORTE's management port, which 4diac IDE deploys to.
pub const PORT: u16 = 61499;
/// The FBDK tag of a STRING.
pub const STRING_TAG: u8 = 0x50;
/// The most bytes of one request: both STRINGs with their headers.
pub const MAX_REQUEST: usize = 8192;
/// The most bytes of one response's XML (its STRING has 3 more).
pub const MAX_RESPONSE: usize = 16384;

/// What a stream's bytes hold next.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Next {
    /// An incomplete request: the stream's first this many bytes tell more (the headers
    /// seen so far say at least this many).
    Need(usize),
    /// A whole request of `len` bytes: where its destination and its XML are in them.
    Request {
        destination: Range<usize>,
        request: Range<usize>,
        len: usize,
    },
}

/// Why a stream cannot be read as requests.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// The byte at offset `at` of the request should be a STRING's tag.
    Tag { at: usize, found: u8 },
    /// The request is at least `len` bytes, more than the limit.
    TooLong { len: usize },
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Tag { at, found } => write!(
                f,
                "byte {at} of a request is {found:#04x}, not an ASN.1 STRING's tag (0x50)"
            ),
            Self::TooLong { len } => write!(
                f,
                "a request of at least {len} bytes (at most {MAX_REQUEST})"
            ),
        }
    }
}

/// The next request in `bytes` (the start of a connection's unread stream), requests at
/// most `max` bytes long. Never panics.
pub fn next_request(bytes: &[u8], max: usize) -> Result<Next, FrameError> {
    let string = |at: usize| -> Result<Option<Range<usize>>, FrameError> {
        match bytes.get(at) {
            None => return Ok(None),
            Some(&STRING_TAG) => {}
            Some(&found) => return Err(FrameError::Tag { at, found }),
        }
        let Some(len) = bytes.get(at + 1..at + 3) else {
            return Ok(None);
        };
        let start = at + 3;
        Ok(Some(
            start..start + usize::from(u16::from_be_bytes([len[0], len[1]])),
        ))
    };
    let Some(destination) = string(0)? else {
        return Ok(Next::Need(3));
    };
    let second = destination.end;
    if second + 3 > max {
        return Err(FrameError::TooLong { len: second + 3 });
    }
    let Some(request) = string(second)? else {
        return Ok(Next::Need(second + 3));
    };
    let len = request.end;
    if len > max {
        return Err(FrameError::TooLong { len });
    }
    if bytes.len() < len {
        return Ok(Next::Need(len));
    }
    Ok(Next::Request {
        destination,
        request,
        len,
    })
}

/// `text` as a STRING: the bytes of a response (or of one part of a request). Text beyond
/// 65535 bytes, which a STRING cannot carry, is cut (responses are at most
/// [`MAX_RESPONSE`]).
pub fn push_string(out: &mut Vec<u8>, text: &[u8]) {
    let text = &text[..text.len().min(usize::from(u16::MAX))];
    out.push(STRING_TAG);
    out.extend_from_slice(&(text.len() as u16).to_be_bytes());
    out.extend_from_slice(text);
}

/// The bytes of a request to `destination` (a client's side).
pub fn encode_request(destination: &str, request: &str) -> Vec<u8> {
    let mut out = Vec::with_capacity(6 + destination.len() + request.len());
    push_string(&mut out, destination.as_bytes());
    push_string(&mut out, request.as_bytes());
    out
}

/// The response in `bytes` (a client's side): its XML and the bytes it took, `None` while
/// incomplete, an error when it is no STRING.
pub fn read_response(bytes: &[u8]) -> Result<Option<(&[u8], usize)>, FrameError> {
    match bytes.first() {
        None => return Ok(None),
        Some(&STRING_TAG) => {}
        Some(&found) => return Err(FrameError::Tag { at: 0, found }),
    }
    let Some(len) = bytes.get(1..3) else {
        return Ok(None);
    };
    let end = 3 + usize::from(u16::from_be_bytes([len[0], len[1]]));
    Ok(bytes.get(3..end).map(|text| (text, end)))
}

#[cfg(any(feature = "net", test))]
pub mod server;

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::string::ToString;

    const CREATE: &str =
        "<Request ID=\"1\" Action=\"CREATE\"><FB Name=\"R\" Type=\"EMB_RES\"/></Request>";

    #[test]
    fn a_request_is_found_whole_however_the_stream_is_cut() {
        let mut stream = encode_request("", CREATE);
        let second = encode_request("R", "<Request ID=\"2\" Action=\"START\"/>");
        stream.extend_from_slice(&second);
        let first_len = 6 + CREATE.len();
        // Every prefix shorter than the first request asks for more, never for fewer bytes
        // than it has; the prefix of its exact length is the request.
        for cut in 0..first_len {
            match next_request(&stream[..cut], MAX_REQUEST) {
                Ok(Next::Need(n)) => assert!(n > cut && n <= first_len, "cut {cut}: need {n}"),
                other => panic!("cut {cut}: {other:?}"),
            }
        }
        let Ok(Next::Request {
            destination,
            request,
            len,
        }) = next_request(&stream, MAX_REQUEST)
        else {
            panic!("no request");
        };
        assert_eq!((destination, len), (3..3, first_len));
        assert_eq!(&stream[request], CREATE.as_bytes());
        // The next one starts where the first ended.
        let Ok(Next::Request {
            destination,
            request,
            ..
        }) = next_request(&stream[first_len..], MAX_REQUEST)
        else {
            panic!("no second request");
        };
        assert_eq!(&stream[first_len..][destination], b"R");
        assert!(stream[first_len..][request].ends_with(b"\"START\"/>"));
    }

    #[test]
    fn reading_only_what_is_needed_reassembles_any_segmentation() {
        // A reader that takes at most what `Need` asks for, in segments of every size.
        let mut stream = Vec::new();
        for (d, r) in [("", CREATE), ("R", "<Request ID=\"2\" Action=\"START\"/>")] {
            stream.extend_from_slice(&encode_request(d, r));
        }
        for segment in 1..=stream.len() {
            let mut got = Vec::new();
            let (mut at, mut buf): (usize, Vec<u8>) = (0, Vec::new());
            while at < stream.len() {
                match next_request(&buf, MAX_REQUEST).unwrap() {
                    Next::Need(n) => {
                        let take = (n - buf.len()).min(segment).min(stream.len() - at);
                        buf.extend_from_slice(&stream[at..at + take]);
                        at += take;
                    }
                    Next::Request { .. } => unreachable!("consumed below"),
                }
                if let Next::Request { request, len, .. } = next_request(&buf, MAX_REQUEST).unwrap()
                {
                    assert_eq!(len, buf.len(), "never read past a request");
                    got.push(buf[request].to_vec());
                    buf.clear();
                }
            }
            assert_eq!(got.len(), 2, "segment {segment}");
            assert_eq!(got[0], CREATE.as_bytes());
        }
    }

    #[test]
    fn a_wrong_tag_or_a_long_request_is_an_error() {
        assert_eq!(
            next_request(b"GET / HTTP/1.0", MAX_REQUEST),
            Err(FrameError::Tag { at: 0, found: b'G' })
        );
        // The second part's tag.
        assert_eq!(
            next_request(&[0x50, 0, 1, b'R', 0x51], MAX_REQUEST),
            Err(FrameError::Tag { at: 4, found: 0x51 })
        );
        // Announced lengths beyond the limit, before the bytes arrive.
        assert_eq!(
            next_request(&[0x50, 0xff, 0xff], MAX_REQUEST),
            Err(FrameError::TooLong { len: 65_541 })
        );
        let long = [0x50, 0, 0, 0x50, 0x20, 0x00];
        assert_eq!(
            next_request(&long, MAX_REQUEST),
            Err(FrameError::TooLong { len: 6 + 0x2000 })
        );
        assert_eq!(next_request(&long, 6 + 0x2000), Ok(Next::Need(6 + 0x2000)));
        assert!(
            FrameError::Tag { at: 0, found: 1 }
                .to_string()
                .contains("0x01")
        );
    }

    #[test]
    fn responses_are_one_string() {
        let mut out = Vec::new();
        push_string(&mut out, b"<Response ID=\"1\" />");
        assert_eq!(&out[..3], &[0x50, 0, 19]);
        assert_eq!(read_response(&out), Ok(Some((&out[3..], out.len()))));
        assert_eq!(read_response(&out[..5]), Ok(None));
        assert!(read_response(b"x").is_err());
        let mut big = Vec::new();
        push_string(&mut big, &alloc::vec![b'a'; 70_000]);
        assert_eq!(big.len(), 3 + 65_535);
    }

    proptest::proptest! {
        #[test]
        fn arbitrary_streams_never_panic(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..300), max in 0usize..400) {
            if let Ok(Next::Request { destination, request, len }) = next_request(&bytes, max) {
                proptest::prop_assert!(len <= bytes.len() && len <= max);
                proptest::prop_assert!(destination.end <= len && request.end == len);
            }
        }
    }
}
