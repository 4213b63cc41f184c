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

use std::{
    ops::Bound::{Excluded, Unbounded},
    sync::Arc,
    time::Duration,
};

use parking_lot::Mutex;

use crate::{
    conf::{ComponentConf, ConfError, ConfLine},
    interfaces::{Encoders, Image, Interface, Laser, Motors, PtEncoders, PtMotors},
    runtime::{Context, Runtime, Schema},
    world::{self, World},
};

/// Commands shared by the schema, its panel and the name space.
pub struct Commands {
    pub base: Arc<Mutex<Motors>>,
    pub pantilt: Arc<Mutex<[f32; 2]>>,
    pub max_v: f32,
    pub max_w: f32,
}

impl Commands {
    /// Sets the base command, clamped to the maxima.
    pub fn set_base(&self, v: f32, w: f32) {
        *self.base.lock() = Motors::limited(v, w, self.max_v, self.max_w);
    }
    /// Sets the pan-tilt command (the unit clamps it to its limits).
    pub fn set_pantilt(&self, longitude: f32, latitude: f32) {
        let fin = |x: f32| if x.is_finite() { x } else { 0.0 };
        *self.pantilt.lock() = [fin(longitude), fin(latitude)];
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

/// The schema.
pub struct Teleoperator {
    pub commands: Arc<Commands>,
    dev: Devices,
    children: Vec<String>,
    cycle: Duration,
    last_pantilt: Option<[f32; 2]>,
    #[cfg(feature = "gui")]
    panel: Option<Box<dyn crate::runtime::Panel>>,
}

impl Schema for Teleoperator {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        ctx.run_children(&self.children, None)?;
        self.last_pantilt = None;
        Ok(())
    }
    fn iteration(&mut self, _ctx: &Context) -> anyhow::Result<()> {
        let base = *self.commands.base.lock();
        self.dev.motors.publish(base).map_err(anyhow::Error::msg)?;
        let pt = *self.commands.pantilt.lock();
        if let Some(pantilt_motors) = &self.dev.pantilt_motors
            && self.last_pantilt != Some(pt)
        {
            pantilt_motors.point(pt[0], pt[1])?;
            self.last_pantilt = Some(pt);
        }
        Ok(())
    }
    fn on_stop(&mut self, _ctx: &Context) {
        let _ = self.dev.motors.publish(Motors::default());
    }
    #[cfg(feature = "gui")]
    fn panel(&mut self) -> Option<Box<dyn crate::runtime::Panel>> {
        self.panel.take()
    }
}

/// A `KEY A B` line of two finite numbers.
fn pair(l: &ConfLine, a: &str, b: &str) -> Result<[f32; 2], ConfError> {
    l.expect_args(2, 2, &format!("{} {a} {b}", l.keyword()))?;
    Ok([l.number(0, a, ..)?, l.number(1, b, ..)?])
}

/// A `KEY NUMBER` line with a positive number.
fn positive(l: &ConfLine, what: &str) -> Result<f32, ConfError> {
    l.expect_args(1, 1, &format!("{} <{what}>", l.keyword()))?;
    l.number(0, what, (Excluded(0.0), Unbounded))
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let mut base = [0.0f32, 0.0];
    let mut pantilt = [0.0f32, 0.0];
    let (mut max_v, mut max_w) = (500.0f32, 30.0f32);
    let mut cycle = Duration::from_millis(100);
    // None: no `world` line (the exported world.map); Some(None): `world none`.
    let mut world: Option<Option<Arc<World>>> = None;
    let mut names: Vec<(&str, Option<String>)> = [
        ("motors", "motors"),
        ("encoders", "encoders"),
        ("laser", "laser"),
        ("pantiltmotors", "pantiltmotors"),
        ("pantiltencoders", "pantiltencoders"),
        ("camera", "colorA"),
    ]
    .into_iter()
    .map(|(k, v)| (k, Some(v.to_string())))
    .collect();
    for l in &conf.lines {
        match l.keyword() {
            "base" => base = pair(l, "V(mm/s)", "W(deg/s)")?,
            "pantilt" => pantilt = pair(l, "LONGITUDE(deg)", "LATITUDE(deg)")?,
            "max_v" => max_v = positive(l, "speed in mm/s")?.min(1000.0),
            "max_w" => max_w = positive(l, "speed in deg/s")?.min(180.0),
            "cycle" => {
                let ms = positive(l, "period in ms")?;
                cycle = Duration::from_secs_f32(ms.clamp(1.0, 10_000.0) / 1000.0);
            }
            "world" => {
                l.expect_args(1, 1, "world FILE|none")?;
                world = Some(if l.args()[0] == "none" {
                    None
                } else {
                    let file = l.existing_file(0, "the world file")?;
                    let w = World::load(&file).map_err(|e| l.error(format!("world: {e}")))?;
                    Some(Arc::new(w))
                });
            }
            k if names.iter().any(|(n, _)| *n == k) => {
                l.expect_args(1, 1, &format!("{k} INTERFACE|none"))?;
                let v = &l.args()[0];
                if k == "motors" && v == "none" {
                    return Err(l.error("teleoperator needs a motors interface").into());
                }
                if let Some(e) = names.iter_mut().find(|(n, _)| *n == k) {
                    e.1 = (v != "none").then(|| v.clone());
                }
            }
            _ => {
                return Err(conf
                    .unknown(
                        l,
                        "base, pantilt, max_v, max_w, cycle, world, motors, encoders, laser, \
                         pantiltmotors, pantiltencoders or camera",
                    )
                    .into());
            }
        }
    }
    let world = world.unwrap_or_else(|| world::map(&rt.names));
    let name = |k: &str| {
        names
            .iter()
            .find(|(n, _)| *n == k)
            .and_then(|(_, v)| v.clone())
            .filter(|n| rt.interfaces.contains(n))
    };
    let Some(motors_name) = name("motors") else {
        anyhow::bail!(
            "{}: teleoperator needs a motors interface; load a driver that provides it (e.g. \
             the simulator with `provides motors`) before teleoperator",
            conf.file.display()
        );
    };
    let ifs = &rt.interfaces;
    let dev = Devices {
        motors: ifs.get(&motors_name)?,
        encoders: name("encoders").map(|n| ifs.get(&n)).transpose()?,
        laser: name("laser").map(|n| ifs.get(&n)).transpose()?,
        pantilt_motors: name("pantiltmotors").map(|n| ifs.get(&n)).transpose()?,
        pantilt_encoders: name("pantiltencoders").map(|n| ifs.get(&n)).transpose()?,
        camera: name("camera").map(|n| ifs.get(&n)).transpose()?,
    };
    let children: Vec<String> = [
        "motors",
        "encoders",
        "laser",
        "pantiltmotors",
        "pantiltencoders",
        "camera",
    ]
    .iter()
    .filter_map(|k| name(k))
    .collect();
    let c = conf.name.as_str();
    let shared = |n: &str, init| -> Arc<Mutex<[f32; 2]>> {
        if let Ok(a) = rt.names.import::<Mutex<[f32; 2]>>(c, n) {
            *a.lock() = init;
            return a;
        }
        let a = Arc::new(Mutex::new(init));
        let _ = rt.names.export_arc(c, n, a.clone());
        a
    };
    let base_cmd = match rt.names.import::<Mutex<Motors>>(c, "base") {
        Ok(a) => a,
        Err(_) => {
            let a = Arc::new(Mutex::new(Motors::default()));
            let _ = rt.names.export_arc(c, "base", a.clone());
            a
        }
    };
    let commands = Arc::new(Commands {
        base: base_cmd,
        pantilt: shared("pantilt", [0.0, 0.0]),
        max_v,
        max_w,
    });
    commands.set_base(base[0], base[1]);
    commands.set_pantilt(pantilt[0], pantilt[1]);
    #[cfg(feature = "gui")]
    let panel: Option<Box<dyn crate::runtime::Panel>> =
        Some(Box::new(panel::TeleoperatorPanel::new(
            commands.clone(),
            dev.clone(),
            world,
            world::balls(&rt.names),
        )));
    #[cfg(not(feature = "gui"))]
    let _ = world;
    Ok(Box::new(Teleoperator {
        commands,
        dev,
        children,
        cycle,
        last_pantilt: None,
        #[cfg(feature = "gui")]
        panel,
    }))
}

crate::register_schema!(
    "teleoperator",
    "drive the base and the pan-tilt; 3D view of the world, robot and laser; camera image",
    create
);
