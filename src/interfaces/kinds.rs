//! The table of interface kinds: every value type, once, with its kind name, and
//! [`Kind`], the enum of them.
//!
//! A kind is a [`Kind`], never a string: `provides` lines, recordings and the
//! wires parse a name into one at their edge ([`Kind::parse`]), and every
//! transport matches it exhaustively, so a new row here is a compile error
//! wherever it is not handled yet. Code that handles "any interface" generically
//! takes its per-kind code from this table:
//!
//! - [`with_kind!`](crate::interfaces::with_kind) calls a generic function with the
//!   value type of a [`Kind`] (`with_kind!(kind, publish(a, b))` calls
//!   `publish::<Laser>(a, b)` for [`Kind::Laser`]);
//! - [`for_each_kind!`](crate::interfaces::for_each_kind) hands the whole table to a
//!   macro, which builds enums over every kind (mcapfmt's `Recorded`, `Snapshot`,
//!   `Source`) and their matches;
//! - each kind's encodings are trait impls next to the format that needs them
//!   (zenoh's `Wire`, mcapfmt's `Ros2`, the 4.3 wire's `Net43`), so a kind missing
//!   one fails to compile.
//!
//! Adding a type: its value type in `values.rs`, one row here, and its encodings.
//! `tests/layers.rs` fails on a kind name matched as a string outside this module.

use std::fmt;

/// Calls `$m! { $args ; (Type, "kind"), ... }` with every interface kind: the value
/// type (in `crate::interfaces`, also the [`Kind`] variant's name) and its kind name.
macro_rules! for_each_kind {
    ($($m:ident)::+ ! { $($args:tt)* }) => {
        $($m)::+! { $($args)* ;
            (Image, "image"),
            (Laser, "laser"),
            (Sonars, "sonars"),
            (Encoders, "encoders"),
            (Motors, "motors"),
            (PtEncoders, "pantiltencoders"),
            (PtMotors, "pantiltmotors"),
            (ZoomEncoders, "zoomencoders"),
            (ZoomMotors, "zoommotors"),
            (Bumpers, "bumpers"),
            (Imu, "imu")
        }
    };
}
pub(crate) use for_each_kind;

/// Calls `$f::<T>(args)` with `T` the value type of `$kind` (a [`Kind`]): an
/// exhaustive match built from the table. (Only components behind cargo features
/// use it, hence the `allow` for a build without them.)
#[allow(unused_macros)]
macro_rules! with_kind {
    ($kind:expr, $f:ident $args:tt) => {
        $crate::interfaces::for_each_kind!(
            $crate::interfaces::with_kind_match! { $kind, $f, $args }
        )
    };
}
#[allow(unused_imports)]
pub(crate) use with_kind;

#[doc(hidden)]
#[allow(unused_macros)]
macro_rules! with_kind_match {
    ($kind:expr, $f:ident, $args:tt ; $(($t:ident, $k:literal)),*) => {
        match $kind {
            $($crate::interfaces::Kind::$t => $f::<$crate::interfaces::$t> $args,)*
        }
    };
}
#[allow(unused_imports)]
pub(crate) use with_kind_match;

macro_rules! kind_enum {
    (; $(($t:ident, $k:literal)),*) => {
        /// An interface kind: the family of a value type (`laser`, `motors`,
        /// `image`...), one variant per row of the kinds table.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum Kind {
            $(#[doc = concat!("`", $k, "`")] $t,)*
        }

        impl Kind {
            /// Every kind, in the table's order.
            pub const ALL: &[Kind] = &[$(Kind::$t),*];
            /// Every kind's name, in the table's order (for help texts and
            /// `choice` arguments).
            pub const NAMES: &[&str] = &[$($k),*];
            /// Its name, as `provides` lines, recordings and the wires spell it.
            pub const fn name(self) -> &'static str {
                match self { $(Kind::$t => $k,)* }
            }
            /// The kind named `name` (a kind name, not an interface name: see
            /// [`family`](crate::interfaces::family) for `colorA` or `laser.robot2`).
            pub fn parse(name: &str) -> Option<Kind> {
                match name { $($k => Some(Kind::$t),)* _ => None }
            }
        }
    };
}
for_each_kind!(kind_enum! {});

impl Kind {
    /// Its position in the table ([`Kind::ALL`]), for arrays of one slot per kind.
    pub const fn index(self) -> usize {
        self as usize
    }
    /// The kind named `name`, or an error listing the kinds there are.
    pub fn parse_or_list(name: &str) -> Result<Kind, String> {
        Kind::parse(name).ok_or_else(|| {
            format!(
                "`{name}` is not an interface kind jderobot knows ({})",
                Kind::NAMES.join(", ")
            )
        })
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl serde::Serialize for Kind {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> serde::Deserialize<'de> for Kind {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = <std::borrow::Cow<'de, str>>::deserialize(d)?;
        Kind::parse_or_list(&name).map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::interfaces::InterfaceValue;

    fn kind_of<T: InterfaceValue>() -> Kind {
        T::KIND
    }

    #[test]
    fn each_row_names_its_types_kind() {
        for (i, &k) in Kind::ALL.iter().enumerate() {
            assert_eq!(with_kind!(k, kind_of()), k);
            assert_eq!(Kind::parse(k.name()), Some(k));
            assert_eq!(k.index(), i);
            assert_eq!(Kind::NAMES[i], k.to_string());
        }
        assert_eq!(Kind::parse("nothing"), None);
        assert!(
            Kind::parse_or_list("lazer")
                .unwrap_err()
                .contains("laser, sonars")
        );
    }
}
