//! Test binary `peers`: drivers against their real peers or emulators: Player, Gazebo (gz-transport), NAOqi (libqi).
//!
//! One binary per area so the suite links a few times, not once per file
//! (docs/benchmarks.md, CI); each module is one of the files beside it.

#[path = "../common/mod.rs"]
mod common;

#[path = "../gazebo.rs"]
mod gazebo;
#[path = "../naobody.rs"]
mod naobody;
#[path = "../player.rs"]
mod player;
