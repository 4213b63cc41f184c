//! Lists every component feature in Cargo.toml, so the binary can name the cargo
//! feature that would add a component it was not built with. Cargo.toml is the one
//! place where components are declared; every `[features]` key that is not a group
//! (`default`, `full`) is a component of the same name.

use std::{env, fs, path::Path};

fn main() {
    println!("cargo:rerun-if-changed=Cargo.toml");
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
