//! Test binary `cameras`: the image drivers: FireWire, GigE, V4L2 devices, files, mplayer, ffmpeg, simulated3D.
//!
//! One binary per area so the suite links a few times, not once per file
//! (docs/benchmarks.md, CI); each module is one of the files beside it.

#[path = "../common/mod.rs"]
mod common;

#[path = "../cameras_dev.rs"]
mod cameras_dev;
#[path = "../cameras_dev_gige.rs"]
mod cameras_dev_gige;
#[path = "../cameras_dev_v4l2.rs"]
mod cameras_dev_v4l2;
#[path = "../cameras_streams.rs"]
mod cameras_streams;
#[path = "../cameras_streams_sim3d.rs"]
mod cameras_streams_sim3d;
