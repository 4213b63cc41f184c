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
#[path = "../declarations.rs"]
mod declarations;
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

/// Every `tests/*.rs` is a module of one of these binaries: with `autotests = false`
/// a file that no suite mounts never compiles, and its tests never run.
#[test]
fn every_test_file_is_mounted_by_a_suite() {
    let tests = common::root().join("tests");
    let suites: String = std::fs::read_dir(tests.join("suites"))
        .unwrap()
        .map(|e| std::fs::read_to_string(e.unwrap().path()).unwrap())
        .collect();
    let mut missing = Vec::new();
    for e in std::fs::read_dir(&tests).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        if name.ends_with(".rs") && !suites.contains(&format!("\"../{name}\"")) {
            missing.push(name);
        }
    }
    assert!(
        missing.is_empty(),
        "tests/{missing:?}: add `#[path = \"../FILE\"] mod NAME;` to one of tests/suites/*.rs"
    );
}
