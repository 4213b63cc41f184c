//! introrob's conf lines (see the [module doc](super)), declared once in
//! [`LINES`]: every error names `file:line`, the argument and what would be right,
//! and `jderobot help introrob` prints them.

use std::{sync::Arc, time::Duration};

use crate::{
    conf::{
        ComponentConf, ConfError,
        settings::{self, CYCLE, Setting, choice, float, word},
    },
    interfaces::Motors,
    operator,
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

crate::declare_lines! {
    /// introrob's lines, declared once (`jderobot help introrob`).
    pub(crate) struct Lines {
        behaviour: String = Setting::new(
            "behaviour",
            "what drives the robot at start",
            &[choice("BEHAVIOUR", BEHAVIOURS)],
        )
        .default("teleop"),
        behavior: Option<String> = Setting::new(
            "behavior",
            "the same as behaviour",
            &[choice("BEHAVIOUR", BEHAVIOURS)],
        ),
        target: Option<[f32; 2]> = Setting::new(
            "target",
            "vff's and gpp's target, in world coordinates (none: click one in the panel)",
            &[float("X", "mm", -1e7, 1e7), float("Y", "mm", -1e7, 1e7)],
        ),
        teleop: (f32, f32) = operator::BASE
            .key("teleop")
            .help("the initial teleoperation command (limited to max_v and max_w)"),
        max_v: f32 = operator::MAX_V,
        max_w: f32 = operator::MAX_W,
        cycle: u64 = CYCLE.default("100"),
        cell: f32 = Setting::new(
            "cell",
            "gpp's grid cell",
            &[float("SIZE", "mm", 10.0, 1000.0)],
        )
        .default("50"),
        world: Option<String> = Setting::new(
            "world",
            "the map for gpp and the panel: a world file, or none (default: the exported world.map)",
            &[word("FILE|none")],
        ),
        laser: String = settings::uses(
            "laser",
            "the laser it avoids obstacles with (none: a robot without one; no laser obstacles)",
        ),
        encoders: String = settings::uses("encoders", "the robot's pose"),
        motors: String = settings::uses("motors", "the base it drives"),
        sonars: String = settings::uses("sonars", "sonars it shows (none: none)"),
        bumpers: String = settings::uses("bumpers", "bumpers it reacts to (none: none)"),
        camera: String = settings::uses("camera", "the image it shows (none: none)").default("colorA"),
    }
}
/// The behaviours' names (with 4.3's synonyms).
const BEHAVIOURS: &[&str] = &[
    "teleop",
    "teleoperated",
    "teleoperation",
    "stop",
    "vff",
    "gpp",
    "yourcode",
    "your_code",
];

impl Settings {
    /// Reads introrob's conf lines (every line optional).
    pub fn parse(conf: &ComponentConf) -> Result<Settings, ConfError> {
        let l: Lines = conf.read()?;
        let behaviour = l.behavior.as_deref().unwrap_or(&l.behaviour);
        let optional = |n: String| (n != "none").then_some(n);
        let map = match l.world.as_deref() {
            None => MapSource::Exported,
            Some("none") => MapSource::Nothing,
            Some(_) => {
                let line = conf.line("world").expect("a world line");
                let file = line.existing_file(0, "the world file")?;
                let w = World::load(&file).map_err(|e| line.error(format!("world: {e}")))?;
                MapSource::File(Arc::new(w))
            }
        };
        Ok(Settings {
            // The declared choices are exactly the names Behaviour reads.
            behaviour: behaviour.parse().unwrap_or(Behaviour::Teleop),
            target: l.target,
            teleop: Motors {
                v: l.teleop.0,
                w: l.teleop.1,
            },
            max_v: l.max_v,
            max_w: l.max_w,
            cycle: Duration::from_millis(l.cycle),
            cell: l.cell,
            map,
            names: InterfaceNames {
                laser: l.laser,
                encoders: l.encoders,
                motors: l.motors,
                sonars: optional(l.sonars),
                bumpers: optional(l.bumpers),
                camera: optional(l.camera),
            },
        })
    }
}
