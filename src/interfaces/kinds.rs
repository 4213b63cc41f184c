//! The table of interface kinds: every value type, once, with its kind name.
//!
//! Code that handles "any interface" generically (zenoh's two formats, the MCAP
//! recorder, replay and `jderobot info`) takes its per-kind code from this table,
//! never from a match of its own:
//!
//! - [`by_kind!`](crate::interfaces::by_kind) calls a generic function with the
//!   value type of a kind name (`by_kind!(kind, publish(a, b), other)` calls
//!   `publish::<Laser>(a, b)` for `"laser"`);
//! - [`for_each_kind!`](crate::interfaces::for_each_kind) hands the whole table to a
//!   macro, which builds enums over every kind (mcapfmt's `Recorded`, `Snapshot`,
//!   `Source`) and their matches;
//! - each kind's encodings are trait impls next to the format that needs them
//!   (zenoh's `Wire`, mcapfmt's `Record`), so a kind missing one fails to compile.
//!
//! Adding a type: its value type in `values.rs`, one row here, and its encodings.

/// Calls `$m! { $args ; (Type, "kind"), ... }` with every interface kind: the value
/// type (in `crate::interfaces`) and its kind name ([`InterfaceValue::KIND`]).
///
/// [`InterfaceValue::KIND`]: crate::interfaces::InterfaceValue::KIND
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

/// Calls `$f::<T>(args)` with `T` the value type of interface kind `$kind` (a
/// `&str`), or evaluates `$other` for a name that is no kind. (Only components
/// behind cargo features use it, hence the `allow` for a build without them.)
#[allow(unused_macros)]
macro_rules! by_kind {
    ($kind:expr, $f:ident $args:tt, $other:expr) => {
        $crate::interfaces::for_each_kind!(
            $crate::interfaces::by_kind_match! { $kind, $f, $args, $other }
        )
    };
}
#[allow(unused_imports)]
pub(crate) use by_kind;

#[doc(hidden)]
#[allow(unused_macros)]
macro_rules! by_kind_match {
    ($kind:expr, $f:ident, $args:tt, $other:expr ; $(($t:ident, $k:literal)),*) => {
        match $kind {
            $($k => $f::<$crate::interfaces::$t> $args,)*
            _ => $other,
        }
    };
}
#[allow(unused_imports)]
pub(crate) use by_kind_match;

/// The kind names, in the table's order.
macro_rules! kind_names {
    (; $(($t:ident, $k:literal)),*) => {
        &[$($k),*]
    };
}

/// Every interface kind's name ([`InterfaceValue::KIND`]), in the table's order.
///
/// [`InterfaceValue::KIND`]: crate::interfaces::InterfaceValue::KIND
pub const KINDS: &[&str] = for_each_kind!(kind_names! {});

#[cfg(test)]
mod tests {
    use super::*;
    use crate::interfaces::InterfaceValue;

    fn kind_of<T: InterfaceValue>() -> &'static str {
        T::KIND
    }

    #[test]
    fn each_row_names_its_types_kind() {
        for &k in KINDS {
            assert_eq!(by_kind!(k, kind_of(), "none"), k);
        }
        assert_eq!(by_kind!("nothing", kind_of(), "none"), "none");
    }
}
