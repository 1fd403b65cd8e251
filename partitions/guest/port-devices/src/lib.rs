//! A request/response pair of queuing-port devices (`/dev/arinc/<port>`, [guest.md]) as a
//! Linux program in the guest talks through them: one message a `write` to the request
//! device, one message a `read` from the response device, which is opened without waiting
//! (`O_NONBLOCK`) so that the tool decides how long to wait. The tools' protocol logic
//! works on [`Transport`], so their tests replace the devices with a model of the far end.
//!
//! [guest.md]: ../../../../docs/guest.md

use std::fs::{File, OpenOptions};
use std::io::{ErrorKind, Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::time::Duration;

/// Linux's `O_NONBLOCK`.
const O_NONBLOCK: i32 = 0o4000;

/// Where requests go and answers come from.
pub trait Transport {
    /// Sends one request message.
    fn send(&mut self, message: &[u8]) -> Result<(), String>;
    /// One answer message, if one is there now (never waits).
    fn try_receive(&mut self, buf: &mut [u8]) -> Result<Option<usize>, String>;
    /// Waits a little before the next [`Transport::try_receive`].
    fn pause(&mut self, time: Duration);
}

/// The two port devices.
pub struct Devices {
    request: File,
    response: File,
}

impl Devices {
    /// Opens `request` for writing and `response` for reading without waiting; the error
    /// names the device and why.
    pub fn open(request: &str, response: &str) -> Result<Devices, String> {
        let fail = |path: &str, e: std::io::Error| format!("cannot open {path}: {e}");
        let request_file = OpenOptions::new()
            .write(true)
            .open(request)
            .map_err(|e| fail(request, e))?;
        let response_file = OpenOptions::new()
            .read(true)
            .custom_flags(O_NONBLOCK)
            .open(response)
            .map_err(|e| fail(response, e))?;
        Ok(Devices {
            request: request_file,
            response: response_file,
        })
    }
}

impl Transport for Devices {
    fn send(&mut self, message: &[u8]) -> Result<(), String> {
        match self.request.write(message) {
            Ok(n) if n == message.len() => Ok(()),
            Ok(n) => Err(format!(
                "the request device took {n} of {} bytes",
                message.len()
            )),
            Err(e) => Err(format!("cannot send the request: {e}")),
        }
    }

    fn try_receive(&mut self, buf: &mut [u8]) -> Result<Option<usize>, String> {
        match self.response.read(buf) {
            Ok(n) => Ok(Some(n)),
            Err(e) if e.kind() == ErrorKind::WouldBlock => Ok(None),
            Err(e) => Err(format!("cannot read the response device: {e}")),
        }
    }

    fn pause(&mut self, time: Duration) {
        std::thread::sleep(time);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_device_is_named_in_the_error() {
        let e = Devices::open("/nonexistent/request", "/dev/null")
            .err()
            .unwrap();
        assert!(e.starts_with("cannot open /nonexistent/request: "), "{e}");
        let e = Devices::open("/dev/null", "/nonexistent/response")
            .err()
            .unwrap();
        assert!(e.starts_with("cannot open /nonexistent/response: "), "{e}");
    }

    #[test]
    fn a_message_goes_out_whole_and_an_empty_response_device_does_not_wait() {
        let mut d = Devices::open("/dev/null", "/dev/null").unwrap();
        d.send(b"hello").unwrap();
        // /dev/null reads as end of file: zero bytes, at once.
        assert_eq!(d.try_receive(&mut [0; 8]).unwrap(), Some(0));
    }
}
