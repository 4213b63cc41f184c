//! Drivers: one module per device family. Each connects interfaces to a device and
//! is compiled in only under the cargo feature of its own name.

#[cfg(feature = "evi")]
pub mod evi;
#[cfg(feature = "firewire")]
pub mod firewire;
#[cfg(feature = "gazebo")]
pub mod gazebo;
#[cfg(feature = "gige")]
pub mod gige;
#[cfg(feature = "imagefile")]
pub mod imagefile;
#[cfg(feature = "mplayer")]
pub mod mplayer;
#[cfg(feature = "naobody")]
pub mod naobody;
#[cfg(feature = "networkclient")]
pub mod networkclient;
#[cfg(feature = "opencv")]
pub mod opencv;
#[cfg(feature = "pantilt")]
pub mod pantilt;
#[cfg(feature = "player")]
pub mod player;
#[cfg(feature = "replay")]
pub mod replay;
#[cfg(feature = "ros2")]
pub mod ros2;
#[cfg(feature = "simulated3D")]
#[path = "simulated3D/mod.rs"]
pub mod simulated3d;
#[cfg(feature = "simulator")]
pub mod simulator;
#[cfg(feature = "video4linux2")]
pub mod video4linux2;
