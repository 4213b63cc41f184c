//! Test binary `core`: the core: conf, settings, the shell, the runtime, interfaces, the layers, the libraries, bad input and fuzzing.
//!
//! One binary per area so the suite links a few times, not once per file
//! (docs/benchmarks.md, CI); each module is one of the files beside it.

#[path = "../common/mod.rs"]
mod common;

#[path = "../bad_input.rs"]
mod bad_input;
#[path = "../cli.rs"]
mod cli;
#[path = "../conf.rs"]
mod conf;
#[path = "../fuzz.rs"]
mod fuzz;
#[path = "../interfaces.rs"]
mod interfaces;
#[path = "../layers.rs"]
mod layers;
#[path = "../libs_colorspaces.rs"]
mod libs_colorspaces;
#[path = "../libs_fuzzy.rs"]
mod libs_fuzzy;
#[path = "../libs_progeo.rs"]
mod libs_progeo;
#[path = "../libs_vision.rs"]
mod libs_vision;
#[path = "../runtime.rs"]
mod runtime;
#[path = "../settings.rs"]
mod settings;
#[path = "../shell_pty.rs"]
mod shell_pty;
