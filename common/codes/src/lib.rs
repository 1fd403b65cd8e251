//! One way to write a code table: an enum whose variants travel as numbers (in a binary
//! format, an IPC word, a bytecode byte) and are shown by name (in a log line, a
//! configuration file, a disassembly). [`code_enum!`] defines the enum, its numbers and its
//! names once and derives both directions from that single list, so no hand-written
//! `match` on numbers can drift from the enum.
//!
//! It must stay a dependency-free `no_std` macro crate: the kernel ABI, the system
//! software, the partitions and the host tools all use it.
#![no_std]

/// Defines a `#[repr($repr)]` enum from one table of `Variant = number => "name"` rows and
/// gives it:
///
/// * `ALL` (every variant, in table order) and `COUNT`;
/// * `code(self) -> $repr` and `from_code($repr) -> Option<Self>`;
/// * `from_u64(u64) -> Option<Self>` for codes that arrive in a wider word (an out-of-range
///   value is `None`, never truncated into a valid code);
/// * `name(self) -> &'static str`, `from_name(&str) -> Option<Self>` and `Display` (the name).
///
/// Every generated decoder is total: any number or string decodes to `Some` or `None`.
///
/// ```
/// codes::code_enum! {
///     /// How a port moves messages.
///     pub enum Kind: u8 {
///         /// Latest value wins.
///         Sampling = 1 => "sampling",
///         /// First in, first out.
///         Queuing = 2 => "queuing",
///     }
/// }
/// assert_eq!(Kind::from_code(2), Some(Kind::Queuing));
/// assert_eq!(Kind::from_u64(0x102), None);
/// assert_eq!(Kind::from_name("sampling").map(Kind::code), Some(1));
/// ```
#[macro_export]
macro_rules! code_enum {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident : $repr:ty {
            $( $(#[$vmeta:meta])* $variant:ident = $code:literal => $text:literal ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        #[repr($repr)]
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        $vis enum $name {
            $( $(#[$vmeta])* $variant = $code, )+
        }

        #[allow(dead_code)]
        impl $name {
            /// Every variant, in table order.
            pub const ALL: [$name; [$($name::$variant),+].len()] = [$($name::$variant),+];
            /// Number of variants.
            pub const COUNT: usize = Self::ALL.len();

            /// The variant's number.
            #[inline]
            pub const fn code(self) -> $repr {
                self as $repr
            }

            /// The variant with number `code`, if any.
            #[inline]
            pub const fn from_code(code: $repr) -> Option<Self> {
                match code {
                    $( $code => Some($name::$variant), )+
                    _ => None,
                }
            }

            /// The variant whose number is `value` (a code carried in a wider word); a value
            /// outside the code type's range is `None`.
            #[inline]
            pub const fn from_u64(value: u64) -> Option<Self> {
                $( if value == $code as u64 { return Some($name::$variant); } )+
                None
            }

            /// The variant's name.
            pub const fn name(self) -> &'static str {
                match self {
                    $( $name::$variant => $text, )+
                }
            }

            /// The variant called `name`, if any (exact match).
            pub fn from_name(name: &str) -> Option<Self> {
                match name {
                    $( $text => Some($name::$variant), )+
                    _ => None,
                }
            }
        }

        impl ::core::fmt::Display for $name {
            fn fmt(&self, f: &mut ::core::fmt::Formatter<'_>) -> ::core::fmt::Result {
                f.write_str(self.name())
            }
        }
    };
}

#[cfg(test)]
mod tests {
    code_enum! {
        /// A test table with gaps and a wide repr.
        pub enum Sample: u32 {
            /// The first.
            One = 1 => "one",
            Ten = 10 => "ten",
            Big = 0xffff_ffff => "big",
        }
    }

    #[test]
    fn both_directions_agree() {
        assert_eq!(Sample::COUNT, 3);
        for v in Sample::ALL {
            assert_eq!(Sample::from_code(v.code()), Some(v));
            assert_eq!(Sample::from_u64(u64::from(v.code())), Some(v));
            assert_eq!(Sample::from_name(v.name()), Some(v));
        }
        assert_eq!(Sample::Ten.code(), 10);
        assert_eq!(Sample::Big.name(), "big");
    }

    #[test]
    fn unknown_values_are_none() {
        for c in [0u32, 2, 9, 11, 0xffff_fffe] {
            assert_eq!(Sample::from_code(c), None);
        }
        // A wide word whose low 32 bits are a valid code is still not one.
        assert_eq!(Sample::from_u64(0x1_0000_0001), None);
        assert_eq!(Sample::from_u64(u64::MAX), None);
        assert_eq!(Sample::from_name("One"), None);
        assert_eq!(Sample::from_name(""), None);
    }
}
