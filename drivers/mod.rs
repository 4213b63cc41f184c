//! Drivers: one module per device family. Each connects interfaces to a device and
//! is compiled in only under the cargo feature of its own name.

#[cfg(feature = "evi")]
pub mod evi;
#[cfg(feature = "pantilt")]
pub mod pantilt;
#[cfg(feature = "simulator")]
pub mod simulator;
