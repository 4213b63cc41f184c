//! teleoperator: drive a robot's base (v/w) and its pan-tilt unit, and watch it in
//! a 3D canvas (world walls, robot, laser points) from an orbitable virtual camera,
//! with its camera image.
//!
//! Headless it holds the commanded values (from the conf or the name space) and
//! writes them every iteration: the base command to `motors` (so it never goes
//! stale) and the pan-tilt command to `pantiltmotors` when it changes.
//!
//! Conf (every line optional):
//! ```text
//! schema teleoperator
//! base 0 0                 # V W: initial base command, mm/s and deg/s
//! pantilt 0 0              # LONGITUDE LATITUDE: initial pan-tilt command, deg
//! max_v 500                # joystick maxima, mm/s and deg/s (4.3's 500 and 30)
//! max_w 30
//! world ../assets/worlds/simple.world   # walls for the 3D canvas; default: the
//!                          #   exported `world.map` (the simulator's); `none`: none
//! cycle 100                # ms
//! motors motors            # interface names (defaults shown); all but motors may
//! encoders encoders        #   be `none`, and are skipped when nothing provides them
//! laser laser
//! pantiltmotors pantiltmotors
//! pantiltencoders pantiltencoders
//! camera colorA
//! end_schema
//! ```
//! It draws the map from `world.map` and the balls from `world.balls`
//! ([`crate::world`]) when a driver exports them; without them the canvas shows the
//! robot and its laser only.
//!
//! Files: this one reads the conf and runs the schema; `panel` is its GUI panel.
//!
//! Name space, component `teleoperator`: `base` ([`parking_lot::Mutex`]`<`[`Motors`]`>`)
//! and `pantilt` (`Mutex<[f32; 2]>`, longitude and latitude in degrees).

#[cfg(feature = "gui")]
pub mod panel;

use std::sync::Arc;

use crate::{
    conf::{
        ComponentConf,
        settings::{self, CYCLE},
    },
    interfaces::{Encoders, Image, Interface, Laser, Motors, PtEncoders, PtMotors},
    operator::{self, CommandLines, Operator},
    runtime::{Runtime, Schema},
    world,
};

crate::declare_lines! {
    /// teleoperator's lines, declared once (`jderobot help teleoperator`).
    struct Lines {
        base: (f32, f32) = operator::BASE,
        pantilt: (f32, f32) = operator::HEAD,
        max_v: f32 = operator::MAX_V,
        max_w: f32 = operator::MAX_W,
        world: Option<String> = settings::WORLD,
        cycle: u64 = CYCLE.default("100"),
        motors: String = settings::uses("motors", "the base it drives"),
        encoders: String = settings::uses("encoders", "the robot's pose in the 3D canvas (none: none)"),
        laser: String = settings::uses("laser", "the laser in the 3D canvas (none: none)"),
        pantiltmotors: String = settings::uses("pantiltmotors", "the pan-tilt unit it points (none: none)"),
        pantiltencoders: String = settings::uses(
            "pantiltencoders",
            "the pan-tilt angles it shows (none: none)",
        ),
        camera: String = settings::uses("camera", "the image it shows (none: none)").default("colorA"),
    }
}
/// The interfaces the teleoperator uses (all but motors optional).
#[derive(Clone)]
pub struct Devices {
    pub motors: Arc<Interface<Motors>>,
    pub encoders: Option<Arc<Interface<Encoders>>>,
    pub laser: Option<Arc<Interface<Laser>>>,
    pub pantilt_motors: Option<Arc<Interface<PtMotors>>>,
    pub pantilt_encoders: Option<Arc<Interface<PtEncoders>>>,
    pub camera: Option<Arc<Interface<Image>>>,
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let lines: Lines = conf.read()?;
    let world = settings::world(conf, lines.world.as_deref(), &rt.names)?;
    let names = operator::interface_names(
        conf,
        rt,
        &lines.motors,
        &[
            &lines.encoders,
            &lines.laser,
            &lines.pantiltmotors,
            &lines.pantiltencoders,
            &lines.camera,
        ],
        "e.g. the simulator with `provides motors`",
    )?;
    let ifs = &rt.interfaces;
    let get = |i: usize| names[i].as_deref();
    let dev = Devices {
        motors: ifs.get(get(0).unwrap_or_default())?,
        encoders: get(1).map(|n| ifs.get(n)).transpose()?,
        laser: get(2).map(|n| ifs.get(n)).transpose()?,
        pantilt_motors: get(3).map(|n| ifs.get(n)).transpose()?,
        pantilt_encoders: get(4).map(|n| ifs.get(n)).transpose()?,
        camera: get(5).map(|n| ifs.get(n)).transpose()?,
    };
    let commands = CommandLines {
        keys: ("base", "pantilt"),
        max: (lines.max_v, lines.max_w),
        base: lines.base,
        head: lines.pantilt,
        cycle: lines.cycle,
    };
    let children = names.into_iter().flatten().collect();
    #[cfg_attr(not(feature = "gui"), allow(unused_mut))]
    let mut schema = Operator::from_lines(
        rt,
        conf,
        commands,
        dev.motors.clone(),
        dev.pantilt_motors.clone(),
        children,
    );
    #[cfg(feature = "gui")]
    {
        schema.panel = Some(Box::new(panel::TeleoperatorPanel::new(
            schema.commands.clone(),
            dev,
            world,
            world::balls(&rt.names),
        )));
    }
    #[cfg(not(feature = "gui"))]
    let _ = world;
    Ok(Box::new(schema))
}

crate::register_schema!(
    "teleoperator",
    "drive the base and the pan-tilt; 3D view of the world, robot and laser; camera image",
    create,
    lines = Lines
);
