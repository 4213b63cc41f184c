//! Test binary `robots`: the simulator and the schemas that drive it (introrob, teleoperator, followball, naooperator), scan geometry, the serial heads and serial robots on ptys.
//!
//! One binary per area so the suite links a few times, not once per file
//! (docs/benchmarks.md, CI); each module is one of the files beside it.

#[path = "../common/mod.rs"]
mod common;
/// The pan-tilt unit's emulator and the pty helpers every serial emulator uses.
#[cfg(any(
    feature = "evi",
    feature = "pantilt",
    feature = "roomba",
    feature = "rplidar"
))]
#[path = "../emulators/ptu.rs"]
mod ptu;

#[path = "../academy_worlds.rs"]
mod academy_worlds;
#[path = "../evi.rs"]
mod evi;
#[path = "../followball.rs"]
mod followball;
#[path = "../introrob.rs"]
mod introrob;
#[path = "../naooperator.rs"]
mod naooperator;
#[path = "../pantilt.rs"]
mod pantilt;
#[path = "../python.rs"]
mod python;
#[path = "../replay_introrob.rs"]
mod replay_introrob;
#[path = "../scan_geometry.rs"]
mod scan_geometry;
#[path = "../serial_robots.rs"]
mod serial_robots;
#[path = "../simulator.rs"]
mod simulator;
#[path = "../teleoperator.rs"]
mod teleoperator;
