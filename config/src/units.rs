//! Human units of the TOML description.
//!
//! Sizes: a whole number of bytes, either a TOML integer (`4096`) or a string with an optional
//! binary unit: `"4096"`, `"4096B"`, `"64KiB"`, `"8MiB"`, `"1GiB"`, `"1TiB"` (a space between
//! number and unit is allowed). Decimal units (`KB`, `MB`, ...) are rejected because they are
//! ambiguous; fractions (`"1.5MiB"`) are rejected too (write `"1536KiB"`).
//!
//! Durations: a string with a unit, always: `"500ns"`, `"250us"` (or `"250µs"`), `"2ms"`,
//! `"1s"`; the value is kept in nanoseconds. A bare number is rejected (its unit would be a
//! guess).

/// Why a size or duration was rejected.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum UnitError {
    /// No digits before the unit (`"KiB"`, `""`).
    NoNumber,
    /// `"1.5ms"`.
    Fraction,
    /// A negative TOML integer.
    Negative,
    /// More than `u64::MAX` bytes or nanoseconds.
    Overflow,
    /// A duration without a unit.
    MissingUnit,
    /// `KB`, `MB`, ... (suggests the binary unit).
    DecimalUnit {
        found: &'static str,
        use_instead: &'static str,
    },
    /// Something else after the number; `what` is "size" or "duration".
    UnknownUnit { what: &'static str },
}

impl core::fmt::Display for UnitError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NoNumber => write!(
                f,
                "expected a number followed by a unit, e.g. \"64KiB\" or \"2ms\""
            ),
            Self::Fraction => write!(
                f,
                "fractions are not allowed; use a smaller unit (e.g. \"1536KiB\", \"1500us\")"
            ),
            Self::Negative => write!(f, "must not be negative"),
            Self::Overflow => write!(f, "is too large"),
            Self::MissingUnit => {
                write!(f, "a duration needs a unit: ns, us, ms or s (e.g. \"2ms\")")
            }
            Self::DecimalUnit { found, use_instead } => write!(
                f,
                "unit `{found}` is decimal and ambiguous; sizes use binary units: write `{use_instead}` (B, KiB, MiB, GiB, TiB)"
            ),
            Self::UnknownUnit { what: "size" } => {
                write!(
                    f,
                    "unknown size unit; use B, KiB, MiB, GiB or TiB (e.g. \"64KiB\")"
                )
            }
            Self::UnknownUnit { .. } => {
                write!(
                    f,
                    "unknown duration unit; use ns, us, ms or s (e.g. \"250us\")"
                )
            }
        }
    }
}

/// Splits `"64 KiB"` into (64, "KiB").
fn split(text: &str) -> Result<(u64, &str), UnitError> {
    let text = text.trim();
    let digits = text.bytes().take_while(u8::is_ascii_digit).count();
    if digits == 0 {
        return Err(UnitError::NoNumber);
    }
    let (number, rest) = text.split_at(digits);
    if rest.starts_with(['.', ',']) {
        return Err(UnitError::Fraction);
    }
    let mut value: u64 = 0;
    for b in number.bytes() {
        value = value
            .checked_mul(10)
            .and_then(|v| v.checked_add(u64::from(b - b'0')))
            .ok_or(UnitError::Overflow)?;
    }
    Ok((value, rest.trim_start()))
}

/// Parses a size string (see the module documentation) into bytes.
pub fn parse_size(text: &str) -> Result<u64, UnitError> {
    let (value, unit) = split(text)?;
    let factor: u64 = match unit {
        "" | "B" => 1,
        "KiB" => 1 << 10,
        "MiB" => 1 << 20,
        "GiB" => 1 << 30,
        "TiB" => 1 << 40,
        _ => {
            let decimal = [
                (["K", "k", "KB", "kB", "kb"], "KiB"),
                (["M", "m", "MB", "mB", "mb"], "MiB"),
                (["G", "g", "GB", "gB", "gb"], "GiB"),
                (["T", "t", "TB", "tB", "tb"], "TiB"),
            ];
            for (spellings, binary) in decimal {
                if let Some(found) = spellings.into_iter().find(|s| *s == unit) {
                    return Err(UnitError::DecimalUnit {
                        found,
                        use_instead: binary,
                    });
                }
            }
            return Err(UnitError::UnknownUnit { what: "size" });
        }
    };
    value.checked_mul(factor).ok_or(UnitError::Overflow)
}

/// A size given as a TOML integer.
pub fn size_from_integer(value: i64) -> Result<u64, UnitError> {
    u64::try_from(value).map_err(|_| UnitError::Negative)
}

/// Parses a duration string (see the module documentation) into nanoseconds.
pub fn parse_duration(text: &str) -> Result<u64, UnitError> {
    let (value, unit) = split(text)?;
    let factor: u64 = match unit {
        "ns" => 1,
        "us" | "µs" => 1_000,
        "ms" => 1_000_000,
        "s" => 1_000_000_000,
        "" => return Err(UnitError::MissingUnit),
        _ => return Err(UnitError::UnknownUnit { what: "duration" }),
    };
    value.checked_mul(factor).ok_or(UnitError::Overflow)
}

/// Writes `bytes` in the largest binary unit that divides it (`8MiB`, `4100B`).
pub struct Size(pub u64);

impl core::fmt::Display for Size {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let units = [(40, "TiB"), (30, "GiB"), (20, "MiB"), (10, "KiB")];
        for (shift, unit) in units {
            if self.0 != 0 && self.0.is_multiple_of(1u64 << shift) {
                return write!(f, "{}{unit}", self.0 >> shift);
            }
        }
        write!(f, "{}B", self.0)
    }
}

/// Writes nanoseconds in the largest unit that divides them (`2ms`, `1500us`).
pub struct Duration(pub u64);

impl core::fmt::Display for Duration {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let units = [(1_000_000_000, "s"), (1_000_000, "ms"), (1_000, "us")];
        for (factor, unit) in units {
            if self.0 != 0 && self.0.is_multiple_of(factor) {
                return write!(f, "{}{unit}", self.0 / factor);
            }
        }
        write!(f, "{}ns", self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes() {
        assert_eq!(parse_size("4096"), Ok(4096));
        assert_eq!(parse_size("4096B"), Ok(4096));
        assert_eq!(parse_size("64KiB"), Ok(64 << 10));
        assert_eq!(parse_size("64 KiB"), Ok(64 << 10));
        assert_eq!(parse_size("8MiB"), Ok(8 << 20));
        assert_eq!(parse_size("1GiB"), Ok(1 << 30));
        assert_eq!(parse_size("2TiB"), Ok(2 << 40));
        assert_eq!(parse_size("KiB"), Err(UnitError::NoNumber));
        assert_eq!(parse_size("1.5MiB"), Err(UnitError::Fraction));
        assert_eq!(
            parse_size("64KB"),
            Err(UnitError::DecimalUnit {
                found: "KB",
                use_instead: "KiB"
            })
        );
        assert_eq!(
            parse_size("64 mb"),
            Err(UnitError::DecimalUnit {
                found: "mb",
                use_instead: "MiB"
            })
        );
        assert_eq!(
            parse_size("64 bytes"),
            Err(UnitError::UnknownUnit { what: "size" })
        );
        assert_eq!(parse_size("99999999999TiB"), Err(UnitError::Overflow));
        assert_eq!(
            parse_size("999999999999999999999999"),
            Err(UnitError::Overflow)
        );
        assert_eq!(size_from_integer(-1), Err(UnitError::Negative));
    }

    #[test]
    fn durations() {
        assert_eq!(parse_duration("500ns"), Ok(500));
        assert_eq!(parse_duration("250us"), Ok(250_000));
        assert_eq!(parse_duration("250µs"), Ok(250_000));
        assert_eq!(parse_duration("2ms"), Ok(2_000_000));
        assert_eq!(parse_duration("2 ms"), Ok(2_000_000));
        assert_eq!(parse_duration("1s"), Ok(1_000_000_000));
        assert_eq!(parse_duration("0ms"), Ok(0));
        assert_eq!(parse_duration("10"), Err(UnitError::MissingUnit));
        assert_eq!(parse_duration("1.5ms"), Err(UnitError::Fraction));
        assert_eq!(
            parse_duration("2 min"),
            Err(UnitError::UnknownUnit { what: "duration" })
        );
        assert_eq!(parse_duration("ms"), Err(UnitError::NoNumber));
    }
}
