//! A small bit-set newtype generator, so the wire carries a plain integer and no
//! `bitflags` dependency is needed. Unknown bits (from a newer peer) are kept, not dropped.
//!
//! The types serialise as serde newtype structs: postcard writes just the inner integer
//! (a varint), and the layout generator still sees the type's name.

/// Defines a `#[serde(transparent)]` bit-set newtype with named flag constants.
macro_rules! flag_set {
    (
        $(#[$meta:meta])*
        pub struct $name:ident($repr:ty) {
            $( $(#[$flag_meta:meta])* const $flag:ident = $bit:expr => $help:expr; )*
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize)]
        pub struct $name($repr);

        impl $name {
            $( $(#[$flag_meta])* pub const $flag: Self = Self(1 << $bit); )*

            /// Every named flag with its name, in bit order.
            pub const NAMED: &'static [(&'static str, Self)] =
                &[$( (stringify!($flag), Self::$flag) ),*];

            /// Every named flag with its name and its one-line help for users (what it
            /// means and what to do), in bit order: the one table host and device share.
            pub const TABLE: &'static [$crate::flags::FlagInfo<Self>] = &[$(
                $crate::flags::FlagInfo { name: stringify!($flag), flag: Self::$flag, help: $help }
            ),*];

            /// The help of the flag called `name`; `None` for a name this version lacks.
            pub fn help_of(name: &str) -> Option<&'static str> {
                Self::TABLE.iter().find(|i| i.name == name).map(|i| i.help)
            }

            /// The named flags set in `self`, with their help, in bit order.
            pub fn explained(self) -> impl Iterator<Item = &'static $crate::flags::FlagInfo<Self>> {
                Self::TABLE.iter().filter(move |i| self.contains(i.flag))
            }

            /// The bits set in `self` that this version has no name (and no help) for.
            pub const fn unknown(self) -> Self {
                self.difference(Self::all())
            }

            /// No flag set.
            pub const fn empty() -> Self {
                Self(0)
            }

            /// Every named flag set.
            pub const fn all() -> Self {
                let mut bits = 0;
                let mut i = 0;
                while i < Self::NAMED.len() {
                    bits |= Self::NAMED[i].1.0;
                    i += 1;
                }
                Self(bits)
            }

            /// Wraps raw bits, keeping bits this version has no name for.
            pub const fn from_bits_retain(bits: $repr) -> Self {
                Self(bits)
            }

            /// The raw bits as sent on the wire.
            pub const fn bits(self) -> $repr {
                self.0
            }

            /// True when no bit is set.
            pub const fn is_empty(self) -> bool {
                self.0 == 0
            }

            /// True when every bit of `other` is set in `self`.
            pub const fn contains(self, other: Self) -> bool {
                self.0 & other.0 == other.0
            }

            /// True when `self` and `other` share a bit.
            pub const fn intersects(self, other: Self) -> bool {
                self.0 & other.0 != 0
            }

            /// Bits set in either.
            pub const fn union(self, other: Self) -> Self {
                Self(self.0 | other.0)
            }

            /// Bits of `self` that are not in `other`.
            pub const fn difference(self, other: Self) -> Self {
                Self(self.0 & !other.0)
            }

            /// Sets the bits of `other`.
            pub fn insert(&mut self, other: Self) {
                self.0 |= other.0;
            }

            /// Clears the bits of `other`.
            pub fn remove(&mut self, other: Self) {
                self.0 &= !other.0;
            }

            /// Sets or clears the bits of `other`.
            pub fn set(&mut self, other: Self, on: bool) {
                if on { self.insert(other) } else { self.remove(other) }
            }

            /// Names of the named flags that are set, in bit order.
            pub fn names(self) -> impl Iterator<Item = &'static str> {
                Self::NAMED
                    .iter()
                    .filter(move |(_, flag)| self.contains(*flag))
                    .map(|(name, _)| *name)
            }
        }

        impl core::ops::BitOr for $name {
            type Output = Self;
            fn bitor(self, rhs: Self) -> Self {
                self.union(rhs)
            }
        }

        impl core::ops::BitOrAssign for $name {
            fn bitor_assign(&mut self, rhs: Self) {
                self.insert(rhs);
            }
        }

        impl core::ops::BitAnd for $name {
            type Output = Self;
            fn bitand(self, rhs: Self) -> Self {
                Self(self.0 & rhs.0)
            }
        }

        /// `NAME | NAME | 0x..` (unknown bits in hex), or `none`.
        impl core::fmt::Display for $name {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                let mut sep = "";
                for name in self.names() {
                    write!(f, "{sep}{name}")?;
                    sep = " | ";
                }
                let unknown = self.difference(Self::all()).0;
                if unknown != 0 {
                    write!(f, "{sep}{unknown:#x}")?;
                } else if self.is_empty() {
                    write!(f, "none")?;
                }
                Ok(())
            }
        }

        impl core::fmt::Debug for $name {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                write!(f, "{}({})", stringify!($name), self)
            }
        }
    };
}

pub(crate) use flag_set;

/// One row of a flag set's table: the flag, its name and its help for users.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FlagInfo<F: 'static> {
    /// The flag's name as shown to users and in JSON (never renamed).
    pub name: &'static str,
    /// The flag.
    pub flag: F,
    /// What the flag means and what to do, one line.
    pub help: &'static str,
}
