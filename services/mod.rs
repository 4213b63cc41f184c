//! Services: cross-cutting facilities (network serving, the GUI host). Each is
//! compiled in only under the cargo feature of its own name.

#[cfg(feature = "gui")]
pub mod gui;

#[cfg(feature = "foxglove")]
pub mod foxglove;
#[cfg(feature = "networkserver")]
pub mod networkserver;
#[cfg(feature = "recorder")]
pub mod recorder;
#[cfg(feature = "ros2")]
pub mod ros2;
#[cfg(feature = "zenoh")]
pub mod zenoh;
