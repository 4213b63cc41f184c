//! Compiles the gazebo peer (`tests/gazebo/peer.cc`, on Debian's gz-transport 11
//! and gz-msgs 8) into `target/gazebo-peer`: the one recipe, for the gazebo tests
//! and the gazebo benchmark (each mounts this file).

use std::{
    path::{Path, PathBuf},
    process::Command,
};

/// Compiles `root/tests/gazebo/peer.cc` into `root/target/gazebo-peer/NAME`
/// (through a temporary name, so that a running copy is never overwritten), or
/// says what is missing and how to install it.
pub fn build_peer(root: &Path, name: &str) -> Result<PathBuf, String> {
    let flags = Command::new("pkg-config")
        .args([
            "--cflags",
            "--libs",
            "ignition-transport11",
            "ignition-msgs8",
        ])
        .output();
    let flags = match flags {
        Ok(o) if o.status.success() => String::from_utf8_lossy(&o.stdout).into_owned(),
        _ => {
            return Err(
                "the gazebo peer needs pkg-config and gz-transport 11: apt-get install pkg-config \
                 g++ libignition-transport-dev libignition-msgs-dev ignition-transport-cli"
                    .into(),
            );
        }
    };
    let dir = root.join("target/gazebo-peer");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let (bin, tmp) = (
        dir.join(name),
        dir.join(format!("{name}.{}", std::process::id())),
    );
    let st = Command::new("g++")
        .args(["-O2", "-std=c++17"])
        .arg(root.join("tests/gazebo/peer.cc"))
        .args(flags.split_whitespace())
        .arg("-o")
        .arg(&tmp)
        .status();
    match st {
        Ok(s) if s.success() => {
            std::fs::rename(&tmp, &bin).map_err(|e| format!("{}: {e}", bin.display()))?;
            Ok(bin)
        }
        _ => Err("g++ could not build tests/gazebo/peer.cc (apt-get install g++)".into()),
    }
}
