//! Test binary `recording`: the MCAP recorder and replay, damaged files, the Python readers.
//!
//! One binary per area so the suite links a few times, not once per file
//! (docs/benchmarks.md, CI); each module is one of the files beside it.

#[path = "../common/mod.rs"]
mod common;

#[path = "../mcap_damage.rs"]
mod mcap_damage;
#[path = "../recorder.rs"]
mod recorder;
#[path = "../recorder_python.rs"]
mod recorder_python;
#[path = "../replay.rs"]
mod replay;
