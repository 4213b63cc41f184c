//! jderobot: the JDE 4.3 robotics suite rebuilt in Rust.
//!
//! A robot control program is a set of concurrent periodic **schemas** that read
//! sensor [`interfaces`] and write actuator ones as if they were local variables.
//! **Drivers** connect interfaces to devices, **services** offer cross-cutting
//! facilities, and a `jde.conf` file ([`conf`]) says what a run loads. Every
//! component registers itself in the [`registry`] and is compiled in only under the
//! cargo feature of its own name.
//!
//! A user's own crate can link this library, add schemas with
//! [`register_schema!`] and call [`cli::main`]; see `examples/own_schema.rs`.

pub mod blobs;
pub mod cli;
pub mod colorspaces;
pub mod conf;
pub mod estop;
pub mod files;
pub mod fuzzy;
#[cfg(feature = "gui")]
pub mod gui;
pub mod imagesource;
pub mod interfaces;
pub mod loader;
#[cfg(feature = "_mcap")]
pub mod mcapfmt;
#[cfg(feature = "_media")]
pub mod media;
pub mod namespace;
pub mod netwire;
pub mod operator;
pub mod output;
pub mod progeo;
#[cfg(any(feature = "gazebo", feature = "_mcap"))]
pub mod protowire;
pub mod registry;
pub mod runtime;
pub mod secret;
#[cfg(feature = "_serialhead")]
pub mod serialhead;
pub mod shell;
pub mod sockets;
pub mod supervisor;
pub mod vision;
#[cfg(feature = "gui")]
pub mod widgets;
pub mod world;

#[path = "../drivers/mod.rs"]
pub mod drivers;
#[path = "../schemas/mod.rs"]
pub mod schemas;
#[path = "../services/mod.rs"]
pub mod services;

pub use conf::Kind;
pub use conf::{ComponentConf, Conf};
pub use interfaces::{Interface, Interfaces, Sample};
pub use registry::Entry;
pub use runtime::{Context, Runtime, Schema, State};

/// Re-exported so that `register_schema!` and friends work from a user's crate.
#[doc(hidden)]
pub use inventory;
