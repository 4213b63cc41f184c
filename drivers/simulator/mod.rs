//! simulator: Pioneer-like robots in a 2D world (2.5D for the camera), so every
//! robot and vision schema runs with no hardware.
//!
//! The core is a plain struct, [`Sim`] (a [`World`] plus robots and balls), that
//! [`Sim::step`] advances deterministically; the driver runs it on a thread in real
//! time (or `speed N` times faster, or lock-stepped with the controller) and
//! publishes the interfaces below. See `docs/simulator.md` and
//! `examples/simulator.conf`.
//!
//! # Interfaces (the seed's names, layouts and units)
//! | interface | what |
//! |---|---|
//! | `encoders` | odometry: x, y mm, θ rad in (0, 2π], cos θ, sin θ; starts at the robot's pose |
//! | `motors` | v mm/s (\|v\| ≤ 1000), w deg/s counter-clockwise (\|w\| ≤ 180); a command older than `motors_timeout` counts as zero |
//! | `laser` | N readings (180 by default) at R per degree (1), mm, max 8000; reading i at −90 + i/R deg; the laser is at (19, 0) mm on the robot |
//! | `sonars` | the 16-sonar Pioneer ring (positions of R430 libs/pioneer), mm, max 5000 |
//! | `bumpers` | 10 bytes: 5 front (left to right), 5 rear (right to left); 1 = touching |
//! | `colorA..D` | 320x240 BGR image from the camera on the pan-tilt unit |
//! | `varcolorA..D` | the same camera at any size (`provides varcolorA W H`) |
//! | `pantiltencoders` | pan_angle, tilt_angle deg (pan counter-clockwise, tilt up) |
//! | `pantiltmotors` | longitude, latitude deg; longitude_speed, latitude_speed deg/s (0 = the unit's maximum); limits of the Directed Perception PTU: pan ±159.13, tilt −46..+30, 205.89 deg/s |
//!
//! The camera sits on the pan-tilt unit at the Pioneer camera position (190, 0) mm,
//! 500 mm above the floor, 65° horizontal field of view; it uses progeo's pinhole
//! model (`position`, `foa`, `fx = fy`, `u0 = rows/2`, `v0 = columns/2`).
//!
//! # Conf
//! ```text
//! driver simulator
//! world assets/worlds/simple.world   # world file (relative to this conf file); none = an empty plane
//! robot robot1 1000 1000 90          # NAME X_MM Y_MM THETA_DEG, repeatable; the first robot's
//!                                    # interfaces have plain names, the others' get a .NAME suffix
//! initial_position 1000 1000 90      # the seed's player line: the first robot's pose
//! provides encoders                  # encoders, motors, sonars, bumpers, pantiltencoders,
//! provides motors                    #   pantiltmotors, colorA..D [ROBOT]
//! provides laser 180 1               # laser [N RESOLUTION] [ROBOT]
//! provides varcolorA 640 480         # varcolorA..D [W H] [ROBOT]
//! provides laser robot2              # robot2's laser: interface laser.robot2
//! motors_timeout 500                 # ms; a stale motors command counts as zero
//! speed 1                            # real time (default); N = N times faster; max = as fast as possible
//! stepped 100                        # instead of speed: advance 100 ms per new motors command
//! seed 1                             # noise seed
//! step 10                            # physics step, ms
//! period laser 100                   # publishing period (ms) of encoders, laser, sonars,
//!                                    #   bumpers, camera, pantiltencoders
//! noise odometry 0.02 0.01           # odometry: σ of distance and turn, as fractions
//! noise laser 10                     # σ, mm (also: noise sonars MM); no noise by default
//! accel 300 100                      # mm/s², deg/s² (a Pioneer's defaults)
//! radius 250                         # robot radius, mm
//! laser_range 8000                   # mm
//! camera_height 500                  # mm; camera_fov 65 (deg)
//! publish_always off                 # on: compute laser, sonars and camera even when unused
//! end_driver
//! ```
//! The laser, sonars and cameras are computed only while someone uses them
//! (resume/suspend), unless `publish_always on`.
//!
//! # Name space
//! `simulator.world`: the static [`World`] (walls, boxes, where balls start), for
//! schemas that draw or plan over the map ([`loaded_world`]); `simulator.balls`:
//! the balls as they roll ([`LiveBalls`], refreshed at the encoders' period;
//! [`live_balls`]).
//!
//! # World file
//! Line based, `#` comments, lengths in mm, angles in degrees; errors name
//! `file:line`. Colours are names (`red`, `green`, `blue`, `yellow`, `orange`,
//! `white`, `grey`, ... see [`world::COLOR_NAMES`]) or `R,G,B`.
//! ```text
//! wall_height 1000             # height of the walls that follow (default 1000)
//! wall_color beige             # colour of the walls that follow
//! floor_color 150,150,140      # floor_tile 1000: checker tiles (0 = plain floor)
//! sky_color sky
//! room X1 Y1 X2 Y2             # four walls around a rectangle
//! wall X1 Y1 X2 Y2             # one thin wall
//! floorplan plan.png 50 [X0 Y0]  # occupancy bitmap, 50 mm per pixel, bottom-left corner at
//!                              #   (X0, Y0); pixels darker than 50 % grey are walls
//! box X Y SIZE_X SIZE_Y HEIGHT COLOR [THETA]   # a static box centred at (X, Y)
//! ball X Y RADIUS COLOR [FRICTION]             # a ball; rolling deceleration mm/s² (300)
//! start X Y THETA              # a start pose for robots the conf does not place
//! ```

pub mod camera;
pub mod physics;
pub mod sensors;
pub mod world;

use std::{
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    thread::JoinHandle,
    time::{Duration, Instant},
};

use anyhow::Context as _;
use arc_swap::ArcSwap;

use crate::{
    conf::{ComponentConf, ConfLine},
    interfaces::{
        Bumpers, Encoders, Image, Interface, Interfaces, Laser, Motors, PtEncoders, PtMotors,
        Sonars, interface_name,
    },
    runtime::{Driver, Runtime},
};

pub use camera::Renderer;
pub use physics::{Ball, Noise, Pose, Rng, Robot, RobotModel, Sim};
pub use world::{BallSpec, BoxObj, World, WorldError};

/// How simulated time advances.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Clock {
    /// `speed` simulated seconds per wall second (1 = real time).
    Speed(f64),
    /// As fast as possible.
    Max,
    /// Advance this many simulated seconds per new command on the first robot's motors.
    Stepped(f64),
}

/// Publishing periods, simulated seconds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Periods {
    pub encoders: f64,
    pub laser: f64,
    pub sonars: f64,
    pub bumpers: f64,
    pub camera: f64,
    pub pantiltencoders: f64,
}

impl Default for Periods {
    fn default() -> Self {
        Periods {
            encoders: 0.05,
            laser: 0.1,
            sonars: 0.1,
            bumpers: 0.05,
            camera: 0.1,
            pantiltencoders: 0.05,
        }
    }
}

/// What a robot provides: interface names (already suffixed) and camera sizes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Provides {
    pub encoders: Option<String>,
    pub motors: Option<String>,
    pub laser: Option<String>,
    pub sonars: Option<String>,
    pub bumpers: Option<String>,
    pub pantiltencoders: Option<String>,
    pub pantiltmotors: Option<String>,
    /// (interface name, columns, rows).
    pub cameras: Vec<(String, u32, u32)>,
}

/// The driver's settings, parsed from its conf lines.
#[derive(Clone, Debug)]
pub struct SimConf {
    pub sim: Sim,
    pub provides: Vec<Provides>,
    pub clock: Clock,
    pub step: f64,
    pub periods: Periods,
    pub motors_timeout: Duration,
    pub publish_always: bool,
}

const EXPECTED: &str = "world, robot, initial_position, provides, motors_timeout, speed, stepped, seed, \
step, period, noise, accel, radius, laser_range, camera_height, camera_fov or publish_always";

const USAGE_PROVIDES: &str = "provides encoders|motors|sonars|bumpers|pantiltencoders|pantiltmotors|colorA..D [ROBOT], \
provides laser [N RESOLUTION] [ROBOT], provides varcolorA..D [W H] [ROBOT]";

fn err(l: &ConfLine, m: impl Into<String>) -> anyhow::Error {
    l.error(m).into()
}

fn positive(l: &ConfLine, i: usize, what: &str) -> anyhow::Result<f64> {
    let v: f64 = l.arg(i, what)?;
    if !(v > 0.0 && v.is_finite()) {
        return Err(err(
            l,
            format!(
                "`{}`: {what} must be a positive number, got {v}",
                l.keyword()
            ),
        ));
    }
    Ok(v)
}

fn finite(l: &ConfLine, i: usize, what: &str) -> anyhow::Result<f64> {
    let v: f64 = l.arg(i, what)?;
    if !v.is_finite() {
        return Err(err(
            l,
            format!(
                "`{}`: argument {} must be {what}, got {v}",
                l.keyword(),
                i + 1
            ),
        ));
    }
    Ok(v)
}

fn non_negative(l: &ConfLine, i: usize, what: &str) -> anyhow::Result<f64> {
    let v: f64 = l.arg(i, what)?;
    if !(v >= 0.0 && v.is_finite()) {
        return Err(err(
            l,
            format!("`{}`: {what} must be >= 0, got {v}", l.keyword()),
        ));
    }
    Ok(v)
}

impl SimConf {
    /// Parses the driver's conf lines (every error names file:line).
    pub fn parse(conf: &ComponentConf) -> anyhow::Result<SimConf> {
        let mut model = RobotModel::default();
        let mut noise = Noise::default();
        let mut seed = 1u64;
        let mut clock = Clock::Speed(1.0);
        let mut step = 0.01;
        let mut periods = Periods::default();
        let mut publish_always = false;
        let mut world = World::new();
        let mut robots: Vec<(String, Option<Pose>)> = Vec::new();
        let mut initial: Option<Pose> = None;
        for l in &conf.lines {
            match l.keyword() {
                "world" => {
                    l.expect_args(1, 1, "world FILE")?;
                    let path = conf.resolve(&l.args()[0]);
                    world = World::load(&path).map_err(|e| err(l, format!("world file: {e}")))?;
                }
                "robot" => {
                    if l.args().len() != 1 && l.args().len() != 4 {
                        l.expect_args(4, 4, "robot NAME X_MM Y_MM THETA_DEG")?;
                    }
                    let name = l.args()[0].clone();
                    if name.parse::<f64>().is_ok() || name.contains('.') {
                        return Err(err(
                            l,
                            format!(
                                "`robot`: `{name}` is not a valid robot name (a word without dots)"
                            ),
                        ));
                    }
                    if robots.iter().any(|r| r.0 == name) {
                        return Err(err(l, format!("robot `{name}` is declared twice")));
                    }
                    let pose = if l.args().len() == 4 {
                        Some(Pose::new(
                            finite(l, 1, "X in mm")?,
                            finite(l, 2, "Y in mm")?,
                            finite(l, 3, "THETA in degrees")?,
                        ))
                    } else {
                        None
                    };
                    robots.push((name, pose));
                }
                "initial_position" => {
                    l.expect_args(3, 3, "initial_position X_MM Y_MM THETA_DEG")?;
                    initial = Some(Pose::new(
                        finite(l, 0, "X in mm")?,
                        finite(l, 1, "Y in mm")?,
                        finite(l, 2, "THETA in degrees")?,
                    ));
                }
                "provides" | "motors_timeout" => {}
                "speed" => {
                    l.expect_args(1, 1, "speed N|max")?;
                    clock = if l.args()[0] == "max" {
                        Clock::Max
                    } else {
                        Clock::Speed(positive(l, 0, "a speed factor")?)
                    };
                }
                "stepped" => {
                    l.expect_args(1, 1, "stepped MS")?;
                    clock = Clock::Stepped(positive(l, 0, "milliseconds per command")? / 1000.0);
                }
                "seed" => {
                    l.expect_args(1, 1, "seed N")?;
                    seed = l.arg(0, "an integer seed")?;
                }
                "step" => {
                    l.expect_args(1, 1, "step MS")?;
                    step = positive(l, 0, "the physics step in ms")?.min(100.0) / 1000.0;
                }
                "period" => {
                    l.expect_args(
                        2,
                        2,
                        "period encoders|laser|sonars|bumpers|camera|pantiltencoders MS",
                    )?;
                    let v = positive(l, 1, "a period in ms")? / 1000.0;
                    match l.args()[0].as_str() {
                        "encoders" => periods.encoders = v,
                        "laser" => periods.laser = v,
                        "sonars" => periods.sonars = v,
                        "bumpers" => periods.bumpers = v,
                        "camera" => periods.camera = v,
                        "pantiltencoders" => periods.pantiltencoders = v,
                        other => {
                            return Err(err(
                                l,
                                format!(
                                    "`period`: `{other}` is not a sensor; expected encoders, laser, sonars, bumpers, camera or pantiltencoders"
                                ),
                            ));
                        }
                    }
                }
                "noise" => match l.args().first().map(String::as_str) {
                    Some("odometry") => {
                        l.expect_args(3, 3, "noise odometry DISTANCE_FRACTION ANGLE_FRACTION")?;
                        noise.odometry_distance = non_negative(l, 1, "a fraction of the distance")?;
                        noise.odometry_angle = non_negative(l, 2, "a fraction of the angle")?;
                    }
                    Some("laser") => {
                        l.expect_args(2, 2, "noise laser MM")?;
                        noise.laser = non_negative(l, 1, "a standard deviation in mm")?;
                    }
                    Some("sonars") => {
                        l.expect_args(2, 2, "noise sonars MM")?;
                        noise.sonars = non_negative(l, 1, "a standard deviation in mm")?;
                    }
                    _ => {
                        return Err(err(
                            l,
                            "`noise` expects `odometry D A`, `laser MM` or `sonars MM`",
                        ));
                    }
                },
                "accel" => {
                    l.expect_args(2, 2, "accel MM_S2 DEG_S2")?;
                    model.accel_v = positive(l, 0, "a linear acceleration in mm/s²")?;
                    model.accel_w = positive(l, 1, "an angular acceleration in deg/s²")?;
                }
                "radius" => {
                    l.expect_args(1, 1, "radius MM")?;
                    model.radius = positive(l, 0, "a radius in mm")?;
                }
                "laser_range" => {
                    l.expect_args(1, 1, "laser_range MM")?;
                    model.laser_range = positive(l, 0, "a range in mm")?;
                }
                "camera_height" => {
                    l.expect_args(1, 1, "camera_height MM")?;
                    model.camera_height = positive(l, 0, "a height in mm")?;
                }
                "camera_fov" => {
                    l.expect_args(1, 1, "camera_fov DEG")?;
                    let f = positive(l, 0, "a field of view in degrees")?;
                    if f >= 170.0 {
                        return Err(err(
                            l,
                            format!("`camera_fov` must be below 170 degrees, got {f}"),
                        ));
                    }
                    model.camera_fov = f;
                }
                "publish_always" => {
                    l.expect_args(1, 1, "publish_always on|off")?;
                    publish_always = match l.args()[0].as_str() {
                        "on" | "yes" | "true" | "1" => true,
                        "off" | "no" | "false" | "0" => false,
                        o => {
                            return Err(err(
                                l,
                                format!("`publish_always`: `{o}`, expected on or off"),
                            ));
                        }
                    };
                }
                _ => return Err(conf.unknown(l, EXPECTED).into()),
            }
        }
        let motors_timeout = conf.motors_timeout()?;
        if robots.is_empty() {
            robots.push(("robot1".into(), initial));
        } else if let Some(p) = initial {
            robots[0].1 = Some(p);
        }
        let mut sim = Sim::new(world, seed);
        sim.noise = noise;
        let mut starts = sim.world.starts.clone().into_iter();
        for (name, pose) in &robots {
            let p = pose.unwrap_or_else(|| {
                starts
                    .next()
                    .map(|s| Pose::new(s.x, s.y, s.theta))
                    .unwrap_or_default()
            });
            sim.add_robot(name, model.clone(), p.x, p.y, p.theta.to_degrees());
        }
        let names: Vec<String> = robots.iter().map(|r| r.0.clone()).collect();
        let mut provides = vec![Provides::default(); names.len()];
        let mut taken: Vec<String> = Vec::new();
        for l in conf.provides() {
            let mut args: Vec<&str> = l.args().iter().map(String::as_str).collect();
            let Some(&kind) = args.first() else {
                return Err(err(
                    l,
                    format!("`provides` needs an interface; usage: {USAGE_PROVIDES}"),
                ));
            };
            args.remove(0);
            // A trailing word that is not a number names the robot.
            let robot = match args.last() {
                Some(w) if w.parse::<f64>().is_err() => {
                    let k = names.iter().position(|n| n == w).ok_or_else(|| {
                        err(
                            l,
                            format!(
                                "`provides {kind}`: no robot called `{w}`; robots: {}",
                                names.join(", ")
                            ),
                        )
                    })?;
                    args.pop();
                    k
                }
                _ => 0,
            };
            let suffix = (robot > 0).then(|| names[robot].as_str());
            let canon = crate::interfaces::canonical(kind);
            let name = interface_name(&canon, suffix);
            if taken.contains(&name) {
                return Err(err(l, format!("interface `{name}` is provided twice")));
            }
            let p = &mut provides[robot];
            let no_args = |args: &[&str]| -> anyhow::Result<()> {
                if args.is_empty() {
                    Ok(())
                } else {
                    Err(err(
                        l,
                        format!(
                            "`provides {kind}` takes no arguments besides a robot name; usage: {USAGE_PROVIDES}"
                        ),
                    ))
                }
            };
            match canon.as_str() {
                "encoders" | "motors" | "sonars" | "bumpers" | "pantiltencoders"
                | "pantiltmotors" => {
                    no_args(&args)?;
                    let slot = match canon.as_str() {
                        "encoders" => &mut p.encoders,
                        "motors" => &mut p.motors,
                        "sonars" => &mut p.sonars,
                        "bumpers" => &mut p.bumpers,
                        "pantiltencoders" => &mut p.pantiltencoders,
                        _ => &mut p.pantiltmotors,
                    };
                    *slot = Some(name.clone());
                }
                "laser" => {
                    let m = &mut sim.robots[robot].model;
                    match args.len() {
                        0 => {}
                        2 => {
                            let n: usize = args[0]
                                .parse()
                                .ok()
                                .filter(|n| (1..=720).contains(n))
                                .ok_or_else(|| {
                                err(
                                    l,
                                    format!(
                                        "`provides laser`: `{}` is not a number of readings 1..720",
                                        args[0]
                                    ),
                                )
                            })?;
                            let res: f64 = args[1].parse().ok().filter(|r: &f64| *r > 0.0 && r.is_finite()).ok_or_else(|| {
                                err(l, format!("`provides laser`: `{}` is not a positive resolution (readings/deg)", args[1]))
                            })?;
                            m.laser_count = n;
                            m.laser_resolution = res;
                        }
                        _ => {
                            return Err(err(
                                l,
                                format!(
                                    "`provides laser` takes [N RESOLUTION] [ROBOT]; usage: {USAGE_PROVIDES}"
                                ),
                            ));
                        }
                    }
                    p.laser = Some(name.clone());
                }
                "colorA" | "colorB" | "colorC" | "colorD" => {
                    no_args(&args)?;
                    p.cameras.push((
                        name.clone(),
                        crate::interfaces::COLOR_WIDTH,
                        crate::interfaces::COLOR_HEIGHT,
                    ));
                }
                "varcolorA" | "varcolorB" | "varcolorC" | "varcolorD" => {
                    let (w, h) = match args.len() {
                        0 => (320, 240),
                        2 => {
                            let dim =
                                |s: &str| s.parse::<u32>().ok().filter(|v| (1..=4096).contains(v));
                            match (dim(args[0]), dim(args[1])) {
                                (Some(w), Some(h)) => (w, h),
                                _ => {
                                    return Err(err(
                                        l,
                                        format!(
                                            "`provides {kind}`: `{} {}` is not a size W H in 1..4096 pixels",
                                            args[0], args[1]
                                        ),
                                    ));
                                }
                            }
                        }
                        _ => {
                            return Err(err(
                                l,
                                format!(
                                    "`provides {kind}` takes [W H] [ROBOT]; usage: {USAGE_PROVIDES}"
                                ),
                            ));
                        }
                    };
                    p.cameras.push((name.clone(), w, h));
                }
                _ => {
                    return Err(err(
                        l,
                        format!("the simulator does not provide `{kind}`; usage: {USAGE_PROVIDES}"),
                    ));
                }
            }
            taken.push(name);
        }
        for (k, r) in sim.robots.iter().enumerate() {
            if sim.world.segments.iter().any(|s| {
                let q = world::closest_on_segment([r.pose.x, r.pose.y], s);
                (q[0] - r.pose.x).hypot(q[1] - r.pose.y) < r.model.radius
            }) {
                tracing::warn!(
                    "simulator: robot `{}` starts touching a wall (at {:.0}, {:.0})",
                    names[k],
                    r.pose.x,
                    r.pose.y
                );
            }
        }
        Ok(SimConf {
            sim,
            provides,
            clock,
            step,
            periods,
            motors_timeout,
            publish_always,
        })
    }
}

/// One robot's interfaces.
struct RobotIfaces {
    encoders: Option<Arc<Interface<Encoders>>>,
    motors: Option<Arc<Interface<Motors>>>,
    laser: Option<Arc<Interface<Laser>>>,
    sonars: Option<Arc<Interface<Sonars>>>,
    bumpers: Option<Arc<Interface<Bumpers>>>,
    pte: Option<Arc<Interface<PtEncoders>>>,
    ptm: Option<Arc<Interface<PtMotors>>>,
    cameras: Vec<(Arc<Interface<Image>>, u32, u32, Renderer)>,
}

/// What the simulator thread publishes to: each robot's interfaces and the balls.
struct Outputs {
    robots: Vec<RobotIfaces>,
    balls: Arc<LiveBalls>,
}

/// The running driver: a thread that steps the simulation and publishes.
pub struct SimDriver {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    motors: Vec<Arc<Interface<Motors>>>,
}

impl SimDriver {
    /// Provides the interfaces of `sc` on `ifaces` and starts the thread, which also
    /// keeps `balls` up to date.
    pub fn start(
        sc: SimConf,
        ifaces: &Interfaces,
        provider: &str,
        balls: Arc<LiveBalls>,
    ) -> anyhow::Result<SimDriver> {
        let mut robots = Vec::new();
        for (k, p) in sc.provides.iter().enumerate() {
            let pt_limits = sc.sim.robots[k].model.pantilt;
            let ri = RobotIfaces {
                encoders: p
                    .encoders
                    .as_ref()
                    .map(|n| ifaces.provide_value(n, provider, sc.sim.encoders(k)))
                    .transpose()?,
                motors: p
                    .motors
                    .as_ref()
                    .map(|n| ifaces.provide(n, provider))
                    .transpose()?,
                laser: p
                    .laser
                    .as_ref()
                    .map(|n| ifaces.provide(n, provider))
                    .transpose()?,
                sonars: p
                    .sonars
                    .as_ref()
                    .map(|n| ifaces.provide(n, provider))
                    .transpose()?,
                bumpers: p
                    .bumpers
                    .as_ref()
                    .map(|n| ifaces.provide(n, provider))
                    .transpose()?,
                pte: p
                    .pantiltencoders
                    .as_ref()
                    .map(|n| ifaces.provide(n, provider))
                    .transpose()?,
                ptm: p
                    .pantiltmotors
                    .as_ref()
                    .map(|n| ifaces.provide_value(n, provider, pt_limits))
                    .transpose()?,
                cameras: p
                    .cameras
                    .iter()
                    .map(|(n, w, h)| {
                        ifaces
                            .provide_value(n, provider, Image::new(*w, *h))
                            .map(|i| (i, *w, *h, Renderer::new()))
                    })
                    .collect::<Result<_, _>>()?,
            };
            robots.push(ri);
        }
        let motors = robots.iter().filter_map(|r| r.motors.clone()).collect();
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = stop.clone();
        let thread = std::thread::Builder::new()
            .name("simulator".into())
            .spawn(move || run(sc, Outputs { robots, balls }, &stop2))
            .context("cannot start the simulator thread")?;
        Ok(SimDriver {
            stop,
            thread: Some(thread),
            motors,
        })
    }
}

impl Driver for SimDriver {
    fn terminate(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        for m in &self.motors {
            let _ = m.publish(Motors::default());
        }
    }
}

impl Drop for SimDriver {
    fn drop(&mut self) {
        self.terminate();
    }
}

/// Next publishing times (simulated seconds).
#[derive(Default)]
struct Due {
    encoders: f64,
    laser: f64,
    sonars: f64,
    bumpers: f64,
    camera: f64,
    pte: f64,
}

fn due(next: &mut f64, now: f64, period: f64) -> bool {
    if now + 1e-9 >= *next {
        *next = (*next + period).max(now + period * 0.5);
        true
    } else {
        false
    }
}

fn used<T: crate::interfaces::InterfaceValue>(i: &Interface<T>, always: bool) -> bool {
    always || i.users() > 0
}

/// Publishes what is due after a step.
fn publish(sc: &mut SimConf, out: &mut Outputs, next: &mut Due) {
    let t = sc.sim.time;
    let p = sc.periods;
    let always = sc.publish_always;
    let (enc, las, son, bum, cam, pte) = (
        due(&mut next.encoders, t, p.encoders),
        due(&mut next.laser, t, p.laser),
        due(&mut next.sonars, t, p.sonars),
        due(&mut next.bumpers, t, p.bumpers),
        due(&mut next.camera, t, p.camera),
        due(&mut next.pte, t, p.pantiltencoders),
    );
    let sim = &mut sc.sim;
    if enc && !sim.balls.is_empty() {
        out.balls.store(Arc::new(sim.balls.clone()));
    }
    for (k, r) in out.robots.iter_mut().enumerate() {
        if enc && let Some(i) = &r.encoders {
            let _ = i.publish(sim.encoders(k));
        }
        if pte && let Some(i) = &r.pte {
            let _ = i.publish(sim.pantilt_encoders(k));
        }
        if bum && let Some(i) = &r.bumpers {
            let _ = i.write(|b| sim.bumpers(k, b));
        }
        if las
            && let Some(i) = &r.laser
            && used(i, always)
        {
            let _ = i.write(|l| sim.laser(k, l));
        }
        if son
            && let Some(i) = &r.sonars
            && used(i, always)
        {
            let _ = i.write(|s| sim.sonars(k, s));
        }
        if cam {
            for (i, w, h, rend) in &mut r.cameras {
                if used(i, always) {
                    let c = sim.camera(k, *w, *h);
                    let _ = i.write(|img| rend.render(sim, k, &c, img));
                }
            }
        }
    }
}

/// Reads the commands into the simulation.
fn commands(sc: &mut SimConf, robots: &[RobotIfaces], stepped: bool) {
    for (k, r) in robots.iter().enumerate() {
        if let Some(m) = &r.motors {
            let cmd = if stepped {
                m.read().value
            } else {
                m.command(sc.motors_timeout)
            };
            sc.sim.set_motors(k, cmd);
        }
        if let Some(p) = &r.ptm {
            let lim = sc.sim.robots[k].model.pantilt;
            let c = p.read().value;
            sc.sim.set_pantilt(
                k,
                PtMotors {
                    longitude: c.longitude,
                    latitude: c.latitude,
                    longitude_speed: c.longitude_speed,
                    latitude_speed: c.latitude_speed,
                    ..lim
                },
            );
        }
    }
}

/// The driver thread.
fn run(mut sc: SimConf, mut out: Outputs, stop: &AtomicBool) {
    let dt = sc.step;
    let mut next = Due::default();
    commands(&mut sc, &out.robots, false);
    publish(&mut sc, &mut out, &mut next);
    match sc.clock {
        Clock::Stepped(per) => {
            let steps = ((per / dt).round() as u64).max(1);
            let trigger = out.robots.iter().find_map(|r| r.motors.clone());
            // The interface was created with clock 0: any later value is a command.
            let mut seen = 0;
            while !stop.load(Ordering::Acquire) {
                let Some(m) = &trigger else {
                    std::thread::sleep(Duration::from_millis(20));
                    continue;
                };
                let c = m.clock();
                if c == seen {
                    std::thread::sleep(Duration::from_micros(500));
                    continue;
                }
                seen = c;
                commands(&mut sc, &out.robots, true);
                for _ in 0..steps {
                    sc.sim.step(dt);
                    publish(&mut sc, &mut out, &mut next);
                }
            }
        }
        Clock::Speed(_) | Clock::Max => {
            let speed = match sc.clock {
                Clock::Speed(s) => Some(s),
                _ => None,
            };
            let t0 = Instant::now();
            let mut done: u64 = 0; // steps counted against the wall clock
            // At most half a simulated second of catching up after a stall.
            let cap = ((0.5 / dt) as u64).max(1);
            while !stop.load(Ordering::Acquire) {
                let target = match speed {
                    Some(s) => (t0.elapsed().as_secs_f64() * s / dt) as u64,
                    None => done + 64,
                };
                if target <= done {
                    let s = speed.unwrap_or(1.0);
                    let wait =
                        ((done + 1) as f64 * dt / s - t0.elapsed().as_secs_f64()).clamp(0.0, 0.005);
                    std::thread::sleep(Duration::from_secs_f64(wait));
                    continue;
                }
                if target - done > cap {
                    done = target - cap;
                }
                while done < target && !stop.load(Ordering::Acquire) {
                    commands(&mut sc, &out.robots, false);
                    sc.sim.step(dt);
                    publish(&mut sc, &mut out, &mut next);
                    done += 1;
                }
            }
        }
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let sc = SimConf::parse(conf)?;
    rt.names
        .export(&conf.name, WORLD_EXPORT, sc.sim.world.clone())?;
    let balls = rt.names.export(
        &conf.name,
        BALLS_EXPORT,
        LiveBalls::from_pointee(sc.sim.balls.clone()),
    )?;
    Ok(Box::new(SimDriver::start(
        sc,
        &rt.interfaces,
        &conf.name,
        balls,
    )?))
}

/// The name under which the driver exports its (static) [`World`].
pub const WORLD_EXPORT: &str = "world";
/// The name under which the driver exports its [`LiveBalls`].
pub const BALLS_EXPORT: &str = "balls";

/// The balls as they are now, refreshed at the encoders' period; readers never wait.
pub type LiveBalls = ArcSwap<Vec<Ball>>;

/// The world of a loaded simulator driver, for schemas that draw or plan over the
/// map (introrob, teleoperator); None if no simulator is loaded.
pub fn loaded_world(rt: &Runtime) -> Option<Arc<World>> {
    rt.names.import::<World>("simulator", WORLD_EXPORT).ok()
}

/// The live balls of a loaded simulator, to import once and `load()` whenever they
/// are drawn; None if no simulator is loaded.
pub fn live_balls(rt: &Runtime) -> Option<Arc<LiveBalls>> {
    rt.names.import::<LiveBalls>("simulator", BALLS_EXPORT).ok()
}

crate::register_driver!(
    Driver,
    "simulator",
    "simulated Pioneer robots in a 2D world: encoders, motors, laser, sonars, bumpers, camera, pan-tilt",
    create
);
