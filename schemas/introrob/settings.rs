//! introrob's conf lines (see the [module doc](super)) read with the conf
//! vocabulary of [`ConfLine`]: every error names `file:line`, the argument and
//! what would be right.

use std::{
    ops::Bound::{Excluded, Unbounded},
    sync::Arc,
    time::Duration,
};

use crate::{
    conf::{ComponentConf, ConfError, ConfLine},
    interfaces::Motors,
    world::World,
};

use super::brain::Behaviour;

/// The interface names introrob uses (`None`: the conf said `none`).
pub struct InterfaceNames {
    pub laser: String,
    pub encoders: String,
    pub motors: String,
    pub sonars: Option<String>,
    pub bumpers: Option<String>,
    pub camera: Option<String>,
}

/// Where introrob's map comes from.
pub enum MapSource {
    /// No `world` line: whatever a driver exported as `world.map`, if anything.
    Exported,
    /// `world none`: no map (gpp cannot plan; the world view shows no walls).
    Nothing,
    /// `world FILE`: that file.
    File(Arc<World>),
}

/// introrob's settings, from its conf lines.
pub struct Settings {
    pub behaviour: Behaviour,
    pub target: Option<[f32; 2]>,
    /// The initial teleoperation command (not yet clamped to the maxima).
    pub teleop: Motors,
    /// mm/s, at most 1000.
    pub max_v: f32,
    /// deg/s, at most 180.
    pub max_w: f32,
    pub cycle: Duration,
    /// gpp grid cell, mm (10..1000).
    pub cell: f32,
    pub map: MapSource,
    pub names: InterfaceNames,
}

/// Numbers above zero.
const POSITIVE: (std::ops::Bound<f32>, std::ops::Bound<f32>) = (Excluded(0.0), Unbounded);

const EXPECTED: &str = "behaviour, target, teleop, max_v, max_w, cycle, cell, world, laser, \
                        encoders, motors, sonars, bumpers or camera";

/// A `KEY NUMBER` line with a positive number.
fn positive(l: &ConfLine, what: &str) -> Result<f32, ConfError> {
    l.expect_args(1, 1, &format!("{} <{what}>", l.keyword()))?;
    l.number(0, what, POSITIVE)
}

/// A `KEY INTERFACE` line.
fn interface_name(l: &ConfLine) -> Result<String, ConfError> {
    l.expect_args(1, 1, &format!("{} INTERFACE", l.keyword()))?;
    Ok(l.word(0, "an interface name")?.to_string())
}

/// A `KEY INTERFACE|none` line.
fn optional_interface(l: &ConfLine) -> Result<Option<String>, ConfError> {
    let n = interface_name(l)?;
    Ok((n != "none").then_some(n))
}

impl Settings {
    /// Reads introrob's conf lines (every line optional).
    pub fn parse(conf: &ComponentConf) -> Result<Settings, ConfError> {
        let mut s = Settings {
            behaviour: Behaviour::Teleop,
            target: None,
            teleop: Motors::default(),
            max_v: 500.0,
            max_w: 30.0,
            cycle: Duration::from_millis(100),
            cell: 50.0,
            map: MapSource::Exported,
            names: InterfaceNames {
                laser: "laser".into(),
                encoders: "encoders".into(),
                motors: "motors".into(),
                sonars: Some("sonars".into()),
                bumpers: Some("bumpers".into()),
                camera: Some("colorA".into()),
            },
        };
        for l in &conf.lines {
            match l.keyword() {
                "behaviour" | "behavior" => {
                    l.expect_args(1, 1, "behaviour teleop|stop|vff|gpp|yourcode")?;
                    s.behaviour = l.args()[0].parse().map_err(|e: String| l.error(e))?;
                }
                "target" => {
                    l.expect_args(2, 2, "target X Y (mm)")?;
                    s.target = Some([l.number(0, "X in mm", ..)?, l.number(1, "Y in mm", ..)?]);
                }
                "teleop" => {
                    l.expect_args(2, 2, "teleop V W (mm/s, deg/s)")?;
                    s.teleop = Motors {
                        v: l.number(0, "v in mm/s", ..)?,
                        w: l.number(1, "w in deg/s", ..)?,
                    };
                }
                "max_v" => s.max_v = positive(l, "speed in mm/s")?.min(1000.0),
                "max_w" => s.max_w = positive(l, "speed in deg/s")?.min(180.0),
                "cycle" => {
                    let ms = positive(l, "period in ms")?;
                    s.cycle = Duration::from_secs_f32(ms.clamp(1.0, 10_000.0) / 1000.0);
                }
                "cell" => s.cell = positive(l, "cell size in mm")?.clamp(10.0, 1000.0),
                "world" => {
                    l.expect_args(1, 1, "world FILE|none")?;
                    s.map = if l.args()[0] == "none" {
                        MapSource::Nothing
                    } else {
                        let file = l.existing_file(0, "the world file")?;
                        let w = World::load(&file).map_err(|e| l.error(format!("world: {e}")))?;
                        MapSource::File(Arc::new(w))
                    };
                }
                "laser" => s.names.laser = interface_name(l)?,
                "encoders" => s.names.encoders = interface_name(l)?,
                "motors" => s.names.motors = interface_name(l)?,
                "sonars" => s.names.sonars = optional_interface(l)?,
                "bumpers" => s.names.bumpers = optional_interface(l)?,
                "camera" => s.names.camera = optional_interface(l)?,
                _ => return Err(conf.unknown(l, EXPECTED)),
            }
        }
        Ok(s)
    }
}
