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
//!                          #   default: the loaded simulator's world; `none`: no map
//! cell 50                  # gpp grid cell, mm (default 50)
//! cycle 100                # ms (default 100)
//! laser laser              # interface names (defaults shown); sonars, bumpers
//! encoders encoders        #   and camera (colorA) may be `none`
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
//! ([`Shared`], everything the panel shows).

pub mod gpp;
pub mod navigation;
#[cfg(feature = "gui")]
pub mod panel;
pub mod vff;

use std::{
    fmt,
    path::PathBuf,
    str::FromStr,
    sync::Arc,
    time::{Duration, Instant},
};

use parking_lot::Mutex;

use crate::{
    conf::{ComponentConf, ConfError},
    interfaces::{Bumpers, Encoders, Image, Interface, Laser, Motors, Sonars},
    runtime::{Context, Runtime, Schema},
    world::{self, World},
};

use gpp::{Follower, GridMap, PlanParams};
use navigation::{Drawing, Robot, YourState};
use vff::{Forces, VffParams};

/// What introrob does each iteration.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Behaviour {
    #[default]
    Teleop,
    Stop,
    Vff,
    Gpp,
    YourCode,
}

impl Behaviour {
    pub const ALL: [Behaviour; 5] = [
        Behaviour::Teleop,
        Behaviour::Stop,
        Behaviour::Vff,
        Behaviour::Gpp,
        Behaviour::YourCode,
    ];
    pub fn as_str(self) -> &'static str {
        match self {
            Behaviour::Teleop => "teleop",
            Behaviour::Stop => "stop",
            Behaviour::Vff => "vff",
            Behaviour::Gpp => "gpp",
            Behaviour::YourCode => "yourcode",
        }
    }
}

impl fmt::Display for Behaviour {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Behaviour {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s.to_ascii_lowercase().as_str() {
            "teleop" | "teleoperated" | "teleoperation" => Behaviour::Teleop,
            "stop" => Behaviour::Stop,
            "vff" => Behaviour::Vff,
            "gpp" => Behaviour::Gpp,
            "yourcode" | "your_code" => Behaviour::YourCode,
            _ => {
                return Err(format!(
                    "unknown behaviour `{s}`; expected teleop, stop, vff, gpp or yourcode"
                ));
            }
        })
    }
}

/// What the panel shows of the last iteration.
#[derive(Clone, Debug, Default)]
pub struct View {
    /// The planned path (gpp), world mm.
    pub path: Vec<[f32; 2]>,
    /// The point the follower steers to (gpp).
    pub carrot: Option<[f32; 2]>,
    /// The VFF forces (vff, gpp), robot frame.
    pub forces: Option<Forces>,
    /// What your code drew.
    pub drawings: Vec<Drawing>,
    /// One line: what the behaviour is doing.
    pub status: String,
    /// The last command written.
    pub command: Motors,
    /// The pose of the last iteration.
    pub pose: Encoders,
}

/// State shared by the schema, its panel and the name space.
pub struct Shared {
    pub behaviour: Arc<Mutex<Behaviour>>,
    pub target: Arc<Mutex<Option<[f32; 2]>>>,
    pub teleop: Arc<Mutex<Motors>>,
    pub view: Mutex<View>,
    /// The world (walls for the world view, map for gpp), if known.
    pub world: Option<Arc<World>>,
    pub max_v: f32,
    pub max_w: f32,
}

impl Shared {
    /// A fresh state (not exported).
    pub fn new(world: Option<Arc<World>>, max_v: f32, max_w: f32) -> Arc<Shared> {
        Arc::new(Shared {
            behaviour: Arc::new(Mutex::new(Behaviour::default())),
            target: Arc::new(Mutex::new(None)),
            teleop: Arc::new(Mutex::new(Motors::default())),
            view: Mutex::new(View::default()),
            world,
            max_v,
            max_w,
        })
    }
    pub fn set_behaviour(&self, b: Behaviour) {
        *self.behaviour.lock() = b;
    }
    pub fn set_target(&self, t: Option<[f32; 2]>) {
        *self.target.lock() = t;
    }
    /// Sets the teleoperation command (clamped to the maxima).
    pub fn set_teleop(&self, v: f32, w: f32) {
        *self.teleop.lock() = Motors::limited(v, w, self.max_v, self.max_w);
    }
}

/// What the brain gets each iteration.
pub struct Inputs<'a> {
    pub pose: Encoders,
    pub laser: &'a Laser,
    pub sonars: Option<&'a Sonars>,
    pub bumpers: Option<&'a Bumpers>,
    pub image: Option<&'a Image>,
    /// Seconds since introrob started.
    pub time: f64,
}

/// introrob's controller, free of interfaces and threads: tests drive it against
/// a stepped simulation, the schema against the live interfaces.
pub struct Brain {
    pub shared: Arc<Shared>,
    pub vff: VffParams,
    pub plan: PlanParams,
    /// gpp grid cell, mm.
    pub cell: f32,
    map: Option<Arc<GridMap>>,
    follower: Option<(Option<[f32; 2]>, Follower)>,
    your: YourState,
    robot: Robot,
    last: Behaviour,
}

impl Brain {
    pub fn new(shared: Arc<Shared>) -> Brain {
        let vff = VffParams {
            max_v: shared.max_v,
            max_w: shared.max_w,
            ..VffParams::default()
        };
        Brain {
            shared,
            vff,
            plan: PlanParams::default(),
            cell: 50.0,
            map: None,
            follower: None,
            your: YourState::default(),
            robot: Robot::default(),
            last: Behaviour::Teleop,
        }
    }

    /// The gpp map (built from the world on first use).
    pub fn map(&mut self) -> Option<Arc<GridMap>> {
        if self.map.is_none()
            && let Some(w) = &self.shared.world
        {
            self.map = Some(Arc::new(GridMap::from_world(w, self.cell)));
        }
        self.map.clone()
    }

    /// One iteration: the command to write to the motors.
    pub fn step(&mut self, input: &Inputs) -> Motors {
        let behaviour = *self.shared.behaviour.lock();
        let target = *self.shared.target.lock();
        if behaviour != self.last {
            self.follower = None;
            self.last = behaviour;
        }
        let mut view = View {
            pose: input.pose,
            ..View::default()
        };
        let m = match behaviour {
            Behaviour::Teleop => {
                view.status = "teleoperated".into();
                *self.shared.teleop.lock()
            }
            Behaviour::Stop => {
                view.status = "stopped".into();
                Motors::default()
            }
            Behaviour::Vff => match target {
                None => {
                    view.status = "vff: no target (click in the world view)".into();
                    Motors::default()
                }
                Some(t) => {
                    let out = vff::command(&input.pose, input.laser, t, &self.vff);
                    view.forces = Some(out.forces);
                    view.status = if out.arrived {
                        "vff: target reached".into()
                    } else {
                        format!("vff: going to ({:.0}, {:.0})", t[0], t[1])
                    };
                    out.motors
                }
            },
            Behaviour::Gpp => self.gpp(input, target, &mut view),
            Behaviour::YourCode => {
                let r = &mut self.robot;
                r.robot = input.pose.robot();
                r.laser.clear();
                r.laser.extend_from_slice(&input.laser.readings);
                r.laser_resolution = input.laser.resolution;
                r.sonars.clear();
                if let Some(s) = input.sonars {
                    r.sonars.extend_from_slice(&s.us);
                }
                r.bumpers.clear();
                if let Some(b) = input.bumpers {
                    r.bumpers.extend_from_slice(&b.bumpers);
                }
                r.image = input.image.cloned();
                r.target = target.unwrap_or([r.robot[0], r.robot[1]]);
                r.time = input.time;
                r.drawings.clear();
                navigation::your_code(r, &mut self.your);
                view.drawings = r.drawings.clone();
                view.status = "your code".into();
                let m = Motors { v: r.v, w: r.w };
                r.image = None;
                m
            }
        };
        let m = Motors::limited(m.v, m.w, self.shared.max_v, self.shared.max_w);
        self.robot.v = m.v;
        self.robot.w = m.w;
        view.command = m;
        *self.shared.view.lock() = view;
        m
    }

    fn gpp(&mut self, input: &Inputs, target: Option<[f32; 2]>, view: &mut View) -> Motors {
        let Some(goal) = target else {
            view.status = "gpp: no goal (click in the world view)".into();
            return Motors::default();
        };
        let here = [input.pose.x, input.pose.y];
        let replan = match &self.follower {
            Some((g, _)) => *g != Some(goal),
            None => true,
        };
        if replan {
            let Some(map) = self.map() else {
                view.status = "gpp: no world map (give introrob a `world FILE` line)".into();
                return Motors::default();
            };
            match gpp::plan(&map, here, goal, &self.plan) {
                Ok(path) => self.follower = Some((Some(goal), Follower::new(path, 500.0))),
                Err(e) => {
                    // Remember the failure for this goal so we do not plan every cycle.
                    self.follower = Some((Some(goal), Follower::new(Vec::new(), 500.0)));
                    view.status = format!("gpp: {e}");
                    return Motors::default();
                }
            }
        }
        let Some((_, f)) = &mut self.follower else {
            return Motors::default();
        };
        if f.path.is_empty() {
            view.status = "gpp: no path to the goal".into();
            return Motors::default();
        }
        let out = f.step(&input.pose, input.laser, &self.vff);
        view.path = f.path.clone();
        view.carrot = Some(out.carrot);
        view.forces = Some(out.forces);
        if out.lost {
            // Off the path (pushed away): plan again next iteration.
            self.follower = None;
        }
        view.status = if out.done {
            "gpp: goal reached".into()
        } else {
            format!(
                "gpp: following a {}-point path to ({:.0}, {:.0})",
                view.path.len(),
                goal[0],
                goal[1]
            )
        };
        out.motors
    }
}

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
    panel: Option<Box<dyn crate::gui::Panel>>,
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
        let wants_image = *self.brain.shared.behaviour.lock() == Behaviour::YourCode;
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
        let m = self.brain.step(&input);
        self.motors.publish(m).map_err(anyhow::Error::msg)?;
        Ok(())
    }
    fn on_stop(&mut self, _ctx: &Context) {
        let _ = self.motors.publish(Motors::default());
    }
    #[cfg(feature = "gui")]
    fn panel(&mut self) -> Option<Box<dyn crate::gui::Panel>> {
        self.panel.take()
    }
}

/// The interface names introrob uses.
struct Names {
    laser: String,
    encoders: String,
    motors: String,
    sonars: Option<String>,
    bumpers: Option<String>,
    camera: Option<String>,
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

/// Parsed conf.
struct Settings {
    behaviour: Behaviour,
    target: Option<[f32; 2]>,
    teleop: Motors,
    max_v: f32,
    max_w: f32,
    cycle: Duration,
    cell: f32,
    /// `world FILE` and where the line was; `world_none`: `world none`.
    world: Option<(PathBuf, crate::conf::Location)>,
    world_none: bool,
    names: Names,
}

fn positive(l: &crate::conf::ConfLine, what: &str) -> Result<f32, ConfError> {
    l.expect_args(1, 1, &format!("{} <{what}>", l.keyword()))?;
    let x: f32 = l.arg(0, what)?;
    if !(x.is_finite() && x > 0.0) {
        return Err(l.error(format!(
            "`{}` must be a positive {what}, got {x}",
            l.keyword()
        )));
    }
    Ok(x)
}

fn point(l: &crate::conf::ConfLine) -> Result<[f32; 2], ConfError> {
    l.expect_args(2, 2, &format!("{} X Y (mm)", l.keyword()))?;
    let (x, y): (f32, f32) = (l.arg(0, "X in mm")?, l.arg(1, "Y in mm")?);
    if !(x.is_finite() && y.is_finite()) {
        return Err(l.error(format!("`{}` needs finite numbers", l.keyword())));
    }
    Ok([x, y])
}

fn parse(conf: &ComponentConf) -> Result<Settings, ConfError> {
    let mut s = Settings {
        behaviour: Behaviour::Teleop,
        target: None,
        teleop: Motors::default(),
        max_v: 500.0,
        max_w: 30.0,
        cycle: Duration::from_millis(100),
        cell: 50.0,
        world: None,
        world_none: false,
        names: Names {
            laser: "laser".into(),
            encoders: "encoders".into(),
            motors: "motors".into(),
            sonars: Some("sonars".into()),
            bumpers: Some("bumpers".into()),
            camera: Some("colorA".into()),
        },
    };
    for l in &conf.lines {
        let one_name = |l: &crate::conf::ConfLine| -> Result<String, ConfError> {
            l.expect_args(1, 1, &format!("{} INTERFACE", l.keyword()))?;
            Ok(l.args()[0].clone())
        };
        let optional = |l: &crate::conf::ConfLine| -> Result<Option<String>, ConfError> {
            let n = one_name(l)?;
            Ok((n != "none").then_some(n))
        };
        match l.keyword() {
            "behaviour" | "behavior" => {
                l.expect_args(1, 1, "behaviour teleop|stop|vff|gpp|yourcode")?;
                s.behaviour = l.args()[0].parse().map_err(|e: String| l.error(e))?;
            }
            "target" => s.target = Some(point(l)?),
            "teleop" => {
                l.expect_args(2, 2, "teleop V W (mm/s, deg/s)")?;
                let (v, w): (f32, f32) = (l.arg(0, "v in mm/s")?, l.arg(1, "w in deg/s")?);
                if !(v.is_finite() && w.is_finite()) {
                    return Err(l.error("`teleop` needs finite numbers"));
                }
                s.teleop = Motors { v, w };
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
                let w = &l.args()[0];
                s.world_none = w == "none";
                s.world = (!s.world_none).then(|| (conf.resolve(w), l.at.clone()));
            }
            "laser" => s.names.laser = one_name(l)?,
            "encoders" => s.names.encoders = one_name(l)?,
            "motors" => s.names.motors = one_name(l)?,
            "sonars" => s.names.sonars = optional(l)?,
            "bumpers" => s.names.bumpers = optional(l)?,
            "camera" => s.names.camera = optional(l)?,
            _ => {
                return Err(conf.unknown(
                    l,
                    "behaviour, target, teleop, max_v, max_w, cycle, cell, world, laser, \
                     encoders, motors, sonars, bumpers or camera",
                ));
            }
        }
    }
    Ok(s)
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let s = parse(conf)?;
    let world = match &s.world {
        Some((file, at)) => {
            let w = World::load(file).map_err(|e| ConfError {
                at: at.clone(),
                message: format!("world: {e}"),
            })?;
            Some(Arc::new(w))
        }
        None if s.world_none => None,
        None => world::map(&rt.names),
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
    need(&s.names.laser, "laser")?;
    need(&s.names.encoders, "encoders")?;
    need(&s.names.motors, "motors")?;
    let opt = |n: &Option<String>| n.clone().filter(|n| rt.interfaces.contains(n));
    let (sonars_n, bumpers_n, camera_n) = (
        opt(&s.names.sonars),
        opt(&s.names.bumpers),
        opt(&s.names.camera),
    );
    let ifs = &rt.interfaces;
    let laser = ifs.get::<Laser>(&s.names.laser)?;
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
    let mut children = vec![
        s.names.laser.clone(),
        s.names.encoders.clone(),
        s.names.motors.clone(),
    ];
    children.extend([sonars_n, bumpers_n, camera_n].into_iter().flatten());

    let c = conf.name.as_str();
    let teleop = Motors::limited(s.teleop.v, s.teleop.w, s.max_v, s.max_w);
    let shared = match rt.names.import::<Shared>(c, "state") {
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
            let shared = Arc::new(Shared {
                behaviour: shared_value(rt, c, "behaviour", s.behaviour),
                target: shared_value(rt, c, "target", s.target),
                teleop: shared_value(rt, c, "teleop", teleop),
                view: Mutex::new(View::default()),
                world,
                max_v: s.max_v,
                max_w: s.max_w,
            });
            let _ = rt.names.export_arc(c, "state", shared.clone());
            shared
        }
    };
    let mut brain = Brain::new(shared.clone());
    brain.cell = s.cell;
    #[cfg(feature = "gui")]
    let panel: Option<Box<dyn crate::gui::Panel>> = Some(Box::new(panel::IntrorobPanel::new(
        shared.clone(),
        encoders.clone(),
        laser.clone(),
        sonars.clone(),
        camera.clone(),
        world::balls(&rt.names),
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
    create
);
