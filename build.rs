//! Lists every component feature in Cargo.toml, so the binary can name the cargo
//! feature that would add a component it was not built with. Cargo.toml is the one
//! place where components are declared; every `[features]` key that is not a group
//! (`default`, `full`) is a component of the same name.

use std::{env, fs, path::Path};

fn main() {
    println!("cargo:rerun-if-changed=Cargo.toml");
    if !system_libraries_present() {
        return;
    }
    let manifest = fs::read_to_string("Cargo.toml").expect("read Cargo.toml");
    let mut in_features = false;
    let mut names = Vec::new();
    for line in manifest.lines() {
        let line = line.trim();
        if line.starts_with('[') {
            in_features = line == "[features]";
            continue;
        }
        if !in_features || line.starts_with('#') || line.is_empty() {
            continue;
        }
        if let Some((key, _)) = line.split_once('=') {
            let key = key.trim();
            if key != "default" && key != "full" && !key.starts_with('_') {
                names.push(key.to_string());
            }
        }
    }
    names.sort();
    let out = Path::new(&env::var("OUT_DIR").unwrap()).join("features.rs");
    let list: Vec<String> = names.iter().map(|n| format!("{n:?}")).collect();
    fs::write(
        out,
        format!(
            "/// Every component feature declared in Cargo.toml.\npub const ALL_COMPONENT_FEATURES: &[&str] = &[{}];\n",
            list.join(", ")
        ),
    )
    .unwrap();
}

/// The system libraries of the enabled device features (pkg-config probes): when
/// one is missing the build stops with ONE message naming the Debian package,
/// instead of a linker or bindgen dump. Returns false when a library is missing.
fn system_libraries_present() -> bool {
    println!("cargo:rerun-if-env-changed=PKG_CONFIG_PATH");
    println!("cargo:rerun-if-env-changed=LIBCLANG_PATH");
    let feature = |f: &str| env::var_os(format!("CARGO_FEATURE_{f}")).is_some();
    let pkg = |name: &str| {
        std::process::Command::new("pkg-config")
            .args(["--exists", name])
            .status()
            .map(|s| s.success())
            .unwrap_or(false)
    };
    let mut missing = Vec::new();
    if (feature("FIREWIRE") || feature("GIGE"))
        && std::process::Command::new("pkg-config")
            .arg("--version")
            .output()
            .is_err()
    {
        missing.push("pkg-config is not installed: apt-get install pkg-config".to_string());
    } else {
        if feature("FIREWIRE") && !pkg("libdc1394-2") {
            missing.push(
                "feature `firewire` needs libdc1394 2.x (pkg-config libdc1394-2): apt-get install libdc1394-dev"
                    .to_string(),
            );
        }
        if feature("GIGE") && !pkg("aravis-0.8") {
            missing.push(
                "feature `gige` needs Aravis 0.8 (pkg-config aravis-0.8): apt-get install libaravis-dev libusb-1.0-0-dev"
                    .to_string(),
            );
        }
    }
    if feature("VIDEO4LINUX2") && !libclang_present() {
        missing.push(
            "feature `video4linux2` needs libclang to generate the V4L2 bindings: apt-get install clang libclang-dev"
                .to_string(),
        );
    }
    for m in &missing {
        println!("cargo::error={m}");
    }
    missing.is_empty()
}

/// Whether a libclang shared library can be found (where clang-sys looks).
fn libclang_present() -> bool {
    let mut dirs: Vec<std::path::PathBuf> = Vec::new();
    if let Some(p) = env::var_os("LIBCLANG_PATH") {
        dirs.push(p.into());
    }
    for base in [
        "/usr/lib",
        "/usr/lib64",
        "/usr/local/lib",
        "/usr/lib/x86_64-linux-gnu",
        "/usr/lib/aarch64-linux-gnu",
    ] {
        dirs.push(base.into());
    }
    if let Ok(rd) = fs::read_dir("/usr/lib") {
        for e in rd.flatten() {
            if e.file_name().to_string_lossy().starts_with("llvm") {
                dirs.push(e.path().join("lib"));
            }
        }
    }
    dirs.iter().any(|d| {
        fs::read_dir(d)
            .map(|rd| {
                rd.flatten().any(|e| {
                    let n = e.file_name();
                    let n = n.to_string_lossy();
                    n.starts_with("libclang") && n.contains(".so")
                })
            })
            .unwrap_or(false)
    })
}
