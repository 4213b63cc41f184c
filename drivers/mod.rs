//! Drivers: one module per device family. Each connects interfaces to a device and
//! is compiled in only under the cargo feature of its own name.

#[cfg(feature = "simulator")]
pub mod simulator;

#[cfg(feature = "networkclient")]
pub mod networkclient;
