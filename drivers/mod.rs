//! Drivers: one module per device family. Each connects interfaces to a device and
//! is compiled in only under the cargo feature of its own name.

#[cfg(feature = "imagefile")]
pub mod imagefile;
#[cfg(feature = "mplayer")]
pub mod mplayer;
#[cfg(feature = "opencv")]
pub mod opencv;
#[cfg(feature = "replay")]
pub mod replay;
#[cfg(feature = "simulated3D")]
#[path = "simulated3D/mod.rs"]
pub mod simulated3d;
#[cfg(feature = "simulator")]
pub mod simulator;
