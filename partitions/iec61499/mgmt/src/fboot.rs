//! Boot files (`.fboot`): one management request a line, `destination;request`, the
//! destination empty for the device itself.

use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;

/// A line of a boot file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Line<'a> {
    /// 1-based.
    pub number: usize,
    pub destination: &'a str,
    pub request: &'a str,
}

/// The request lines of a boot file (blank lines are skipped); a line without `;` is an
/// error naming it.
pub fn lines(text: &str) -> Result<Vec<Line<'_>>, String> {
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim_end_matches('\r');
        if line.trim().is_empty() {
            continue;
        }
        let Some((destination, request)) = line.split_once(';') else {
            return Err(format!(
                "boot file line {}: no ';' between destination and request",
                i + 1
            ));
        };
        out.push(Line {
            number: i + 1,
            destination: destination.trim(),
            request: request.trim(),
        });
    }
    Ok(out)
}
