//! Test binary `network`: serving and reaching robots over the network: 4.3's wire, Zenoh (Rust and Python), Foxglove, ROS 2, and hostile peers against them.
//!
//! One binary per area so the suite links a few times, not once per file
//! (docs/benchmarks.md, CI); each module is one of the files beside it.

#[path = "../common/mod.rs"]
mod common;

#[path = "../foxglove.rs"]
mod foxglove;
#[path = "../hostile_net.rs"]
mod hostile_net;
#[path = "../network_bad_input.rs"]
mod network_bad_input;
#[path = "../network_processes.rs"]
mod network_processes;
#[path = "../network_wire.rs"]
mod network_wire;
#[path = "../ros2.rs"]
mod ros2;
#[path = "../zenoh.rs"]
mod zenoh;
#[path = "../zenoh_python.rs"]
mod zenoh_python;
