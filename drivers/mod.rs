//! Drivers: one module per device family. Each connects interfaces to a device and
//! is compiled in only under the cargo feature of its own name.

#[cfg(feature = "firewire")]
pub mod firewire;
#[cfg(feature = "gige")]
pub mod gige;
#[cfg(feature = "simulator")]
pub mod simulator;
#[cfg(feature = "video4linux2")]
pub mod video4linux2;
