//! introrob: the Pioneer teaching schema (4.3's first robotic example).
//!
//! Each iteration (100 ms) it copies the encoders, laser, sonars and camera, runs
//! the chosen behaviour and writes v/w to the motors:
//!
//! | behaviour | what the robot does |
//! |---|---|
//! | `teleop` | drives at the joystick's v/w (panel, or `teleop V W` / the name space) |
//! | `stop` | stands still |
//! | `vff` | Virtual Force Field navigation to the target ([`vff`]) |
//! | `gpp` | Gradient Path Planning over the world map to the target, then follows the path ([`gpp`]) |
//! | `yourcode` | calls [`navigation::your_code`]: the student hook (4.3's `navegacion.c`) |
//!
//! Like 4.3 it runs the interfaces it uses (laser, encoders, motors, and the
//! sonars, bumpers and camera when the robot has them) as its children.
//!
//! Conf (every line optional):
//! ```text
//! schema introrob
//! behaviour vff            # teleop (default) | stop | vff | gpp | yourcode
//! target 5000 2200         # X Y mm: the navigation target (none: vff/gpp wait for one)
//! max_v 400                # mm/s (default 500, 4.3's joystick maximum)
//! max_w 40                 # deg/s (default 30)
//! teleop 0 0               # V W: the initial teleoperation command
//! world ../assets/worlds/simple.world   # the map for gpp and the world view;
//!                          #   default: the exported `world.map` (the simulator
//!                          #   exports its world); `none`: no map
//! cell 50                  # gpp grid cell, mm (default 50)
//! cycle 100                # ms (default 100)
//! laser laser              # interface names (defaults shown); laser, sonars,
//! encoders encoders        #   bumpers and camera (colorA) may be `none` (`laser
//!                          #   none`: a robot without one, e.g. a NAO; the
//!                          #   behaviours then see no laser obstacles)
//! motors motors
//! sonars sonars
//! bumpers bumpers
//! camera colorA
//! end_schema
//! ```
//!
//! Name space (for the shell, the GUI and other schemas), component `introrob`:
//! `behaviour` ([`parking_lot::Mutex`]`<`[`Behaviour`]`>`), `target`
//! (`Mutex<Option<[f32; 2]>>`, mm), `teleop` (`Mutex<`[`Motors`]`>`), and `state`
//! ([`Dashboard`], everything the panel shows). It reads the map from
//! `world.map` and the balls from `world.balls` ([`crate::world`]) when a driver
//! exports them (the world view draws the map's floor paint and targets, and says
//! the exercise's score from `world.score` when one is kept); without a map the world view shows the odometry pose and the laser
//! (the sonars in their own view), and gpp says it needs a map.
//!
//! Files: this one wires the schema (factory, [`Schema`] impl); [`settings`] reads
//! the conf; [`brain`] holds the behaviours and the [`Dashboard`]; [`vff`] and
//! [`gpp`] are the navigation algorithms; [`navigation`] is the student hook;
//! `panel` is the GUI panel.

pub mod brain;
pub mod gpp;
pub mod navigation;
#[cfg(feature = "gui")]
pub mod panel;
pub mod settings;
pub mod vff;

use std::{
    sync::Arc,
    time::{Duration, Instant},
};

use parking_lot::Mutex;

use crate::{
    conf::ComponentConf,
    interfaces::{Bumpers, Encoders, Image, Interface, Laser, Motors, Sonars},
    runtime::{Context, Runtime, Schema},
    world,
};

pub use brain::{Behaviour, Brain, Dashboard, Inputs, View};
use settings::{MapSource, Settings};

/// The schema: the brain over the live interfaces.
pub struct Introrob {
    pub brain: Brain,
    cycle: Duration,
    laser: Arc<Interface<Laser>>,
    encoders: Arc<Interface<Encoders>>,
    motors: Arc<Interface<Motors>>,
    sonars: Option<Arc<Interface<Sonars>>>,
    camera: Option<Arc<Interface<Image>>>,
    bumpers: Option<Arc<Interface<Bumpers>>>,
    children: Vec<String>,
    started: Instant,
    #[cfg(feature = "gui")]
    panel: Option<Box<dyn crate::runtime::Panel>>,
}

impl Schema for Introrob {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        ctx.run_children(&self.children, None)?;
        self.started = Instant::now();
        Ok(())
    }
    fn iteration(&mut self, _ctx: &Context) -> anyhow::Result<()> {
        let laser = self.laser.snapshot();
        let sonars = self.sonars.as_ref().map(|s| s.snapshot());
        let bumpers = self.bumpers.as_ref().map(|b| b.snapshot());
        let wants_image = *self.brain.dashboard.behaviour.lock() == Behaviour::YourCode;
        let image = self
            .camera
            .as_ref()
            .filter(|_| wants_image)
            .map(|c| c.snapshot());
        let input = Inputs {
            pose: self.encoders.read().value,
            laser: &laser.value,
            sonars: sonars.as_ref().map(|s| &s.value),
            bumpers: bumpers.as_ref().map(|s| &s.value),
            image: image.as_ref().map(|s| &s.value),
            time: self.started.elapsed().as_secs_f64(),
        };
        // The brain's command, every cycle (a rejected one is the error).
        Ok(self.motors.publish(self.brain.step(&input)).map(drop)?)
    }
    fn on_stop(&mut self, _ctx: &Context) {
        let _ = self.motors.publish(Motors::default());
    }
    #[cfg(feature = "gui")]
    fn panel(&mut self) -> Option<Box<dyn crate::runtime::Panel>> {
        self.panel.take()
    }
}

/// Exports `value` as `component.name`, or, after a re-init, reuses (and resets)
/// the handle exported before so importers keep seeing the live value.
fn shared_value<T: Send + 'static>(
    rt: &Runtime,
    component: &str,
    name: &str,
    value: T,
) -> Arc<Mutex<T>> {
    if let Ok(a) = rt.names.import::<Mutex<T>>(component, name) {
        *a.lock() = value;
        return a;
    }
    let a = Arc::new(Mutex::new(value));
    let _ = rt.names.export_arc(component, name, a.clone());
    a
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let s = Settings::parse(conf)?;
    let world = match s.map {
        MapSource::File(w) => Some(w),
        MapSource::Nothing => None,
        MapSource::Exported => world::map(&rt.names),
    };
    let need = |name: &str, what: &str| -> anyhow::Result<()> {
        if rt.interfaces.contains(name) {
            Ok(())
        } else {
            Err(anyhow::anyhow!(
                "{}: introrob needs the {what} interface `{name}`, which nothing provides; load a \
                 driver that provides it (e.g. the simulator with `provides {what}`) before introrob",
                conf.file.display()
            ))
        }
    };
    // `laser none` (a NAO has none): an empty laser of its own, which no driver
    // writes; the behaviours see no laser obstacles.
    let no_laser = s.names.laser == "none";
    if !no_laser {
        need(&s.names.laser, "laser")?;
    }
    need(&s.names.encoders, "encoders")?;
    need(&s.names.motors, "motors")?;
    let opt = |n: &Option<String>| n.clone().filter(|n| rt.interfaces.contains(n));
    let (sonars_n, bumpers_n, camera_n) = (
        opt(&s.names.sonars),
        opt(&s.names.bumpers),
        opt(&s.names.camera),
    );
    let ifs = &rt.interfaces;
    let laser = if no_laser {
        Arc::new(Interface::new("none", &conf.name))
    } else {
        ifs.get::<Laser>(&s.names.laser)?
    };
    let encoders = ifs.get::<Encoders>(&s.names.encoders)?;
    let motors = ifs.get::<Motors>(&s.names.motors)?;
    let sonars = sonars_n
        .as_ref()
        .map(|n| ifs.get::<Sonars>(n))
        .transpose()?;
    let bumpers = bumpers_n
        .as_ref()
        .map(|n| ifs.get::<Bumpers>(n))
        .transpose()?;
    let camera = camera_n.as_ref().map(|n| ifs.get::<Image>(n)).transpose()?;
    let mut children = vec![s.names.encoders.clone(), s.names.motors.clone()];
    let laser_n = (!no_laser).then(|| s.names.laser.clone());
    children.extend(
        [laser_n, sonars_n, bumpers_n, camera_n]
            .into_iter()
            .flatten(),
    );

    let c = conf.name.as_str();
    let teleop = Motors::limited(s.teleop.v, s.teleop.w, s.max_v, s.max_w);
    let dashboard = match rt.names.import::<Dashboard>(c, "state") {
        // A re-init (the shell's `init`): the panel and importers keep the state
        // exported at load; the conf's behaviour, target and teleop apply now (the
        // world and the maxima stay those of the first load).
        Ok(old) => {
            old.set_behaviour(s.behaviour);
            old.set_target(s.target);
            *old.teleop.lock() = teleop;
            old
        }
        Err(_) => {
            let dashboard = Arc::new(Dashboard {
                behaviour: shared_value(rt, c, "behaviour", s.behaviour),
                target: shared_value(rt, c, "target", s.target),
                teleop: shared_value(rt, c, "teleop", teleop),
                view: Mutex::new(View::default()),
                world,
                max_v: s.max_v,
                max_w: s.max_w,
            });
            let _ = rt.names.export_arc(c, "state", dashboard.clone());
            dashboard
        }
    };
    let mut brain = Brain::new(dashboard.clone());
    brain.cell = s.cell;
    #[cfg(feature = "gui")]
    let panel: Option<Box<dyn crate::runtime::Panel>> = Some(Box::new(panel::IntrorobPanel::new(
        dashboard.clone(),
        encoders.clone(),
        laser.clone(),
        sonars.clone(),
        camera.clone(),
        world::balls(&rt.names),
        world::score(&rt.names),
    )));
    Ok(Box::new(Introrob {
        brain,
        cycle: s.cycle,
        laser,
        encoders,
        motors,
        sonars,
        camera,
        bumpers,
        children,
        started: Instant::now(),
        #[cfg(feature = "gui")]
        panel,
    }))
}

crate::register_schema!(
    "introrob",
    "Pioneer teaching schema: teleoperation, VFF, gradient path planning and your own code",
    create,
    lines = settings::Lines
);
