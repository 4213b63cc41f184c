//! The simulator's conf lines (see the [module doc](super) and `docs/simulator.md`)
//! turned into a [`Simulation`] ready to run: the [`Sim`] with its world and robots,
//! what each robot provides, the clock and the publishing periods. Every argument
//! is read with the conf vocabulary of [`ConfLine`], so every error names
//! `file:line`, the argument and what would be right.

use std::{
    ops::Bound::{Excluded, Unbounded},
    time::Duration,
};

use crate::{
    conf::{
        ComponentConf, ConfError, ConfLine,
        settings::{self, MOTORS_TIMEOUT, Setting, choice, float, int, on_off, path, word},
    },
    interfaces::{COLOR_HEIGHT, COLOR_WIDTH, interface_name},
    world::{World, closest_on_segment},
};

use super::physics::{Noise, Pose, RobotModel, Sim};

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
    pub imu: f64,
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
            imu: 0.02,
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
    pub imu: Option<String>,
    /// (interface name, columns, rows).
    pub cameras: Vec<(String, u32, u32)>,
}

/// A live simulation and how the driver runs it: the [`Sim`] (world, robots,
/// balls), what each robot provides, the clock, the physics step and the
/// publishing periods. [`Simulation::parse`] builds it from the driver's conf lines;
/// [`SimDriver::start`](super::SimDriver::start) runs it.
#[derive(Clone, Debug)]
pub struct Simulation {
    pub sim: Sim,
    /// One entry per robot, in `sim.robots` order.
    pub provides: Vec<Provides>,
    pub clock: Clock,
    /// Physics step, simulated seconds.
    pub step: f64,
    pub periods: Periods,
    pub motors_timeout: Duration,
    pub publish_always: bool,
}

/// The simulator's lines, declared once (`jderobot help simulator`). Their values
/// are read below, in file order (robots, then what each provides).
pub const LINES: &[Setting] = &[
    Setting::new(
        "world",
        "the world: walls, starts, balls (a world file)",
        &[path("FILE")],
    ),
    Setting::new(
        "robot",
        "a robot; its pose (mm, mm, deg) or the world's next start",
        &[
            word("NAME"),
            float("X", "mm", -1e7, 1e7).optional(),
            float("Y", "mm", -1e7, 1e7),
            float("THETA", "deg", -36_000.0, 36_000.0),
        ],
    )
    .repeats(),
    settings::INITIAL_POSITION.help("the first robot's pose"),
    settings::provides(USAGE_PROVIDES),
    MOTORS_TIMEOUT,
    Setting::new(
        "speed",
        "simulated seconds per wall second (1 = real time), or max",
        &[word("N|max")],
    ),
    Setting::new(
        "stepped",
        "advance this much simulated time per new command on the first robot's motors",
        &[float("MS", "ms", 0.001, 60_000.0)],
    ),
    Setting::new(
        "seed",
        "the noise's random seed",
        &[int("N", "", 0, i64::MAX)],
    ),
    Setting::new(
        "step",
        "the physics step",
        &[float("MS", "ms", 0.001, 100.0)],
    ),
    Setting::new(
        "period",
        "how often a sensor publishes (simulated time)",
        &[
            choice(
                "SENSOR",
                &[
                    "encoders",
                    "laser",
                    "sonars",
                    "bumpers",
                    "camera",
                    "pantiltencoders",
                    "imu",
                ],
            ),
            float("MS", "ms", 0.001, 60_000.0),
        ],
    )
    .repeats(),
    Setting::new(
        "noise",
        "sensor noise: odometry DISTANCE_FRACTION ANGLE_FRACTION, laser MM or sonars MM",
        &[
            choice("SENSOR", &["odometry", "laser", "sonars"]),
            float("A", "", 0.0, 1e6),
            float("B", "", 0.0, 1e6).optional(),
        ],
    )
    .repeats(),
    Setting::new(
        "accel",
        "the robot's accelerations",
        &[
            float("V", "mm/s²", 0.001, 1e6),
            float("W", "deg/s²", 0.001, 1e6),
        ],
    ),
    Setting::new(
        "radius",
        "the robot's radius",
        &[float("R", "mm", 0.001, 1e5)],
    ),
    Setting::new(
        "laser_range",
        "the laser's range",
        &[float("RANGE", "mm", 0.001, 1e6)],
    ),
    Setting::new(
        "camera_height",
        "the pan-tilt camera's height",
        &[float("H", "mm", 0.001, 1e5)],
    ),
    Setting::new(
        "camera_fov",
        "the pan-tilt camera's horizontal field of view",
        &[float("FOV", "deg", 0.001, 169.999)],
    ),
    Setting::new(
        "publish_always",
        "publish sensors even while nobody uses them",
        &[on_off("SWITCH")],
    ),
];

const USAGE_PROVIDES: &str = "provides encoders|motors|sonars|bumpers|pantiltencoders|pantiltmotors|imu|colorA..D [ROBOT], \
provides laser [N RESOLUTION] [ROBOT], provides varcolorA..D [W H] [ROBOT]";

/// Numbers above zero.
const POSITIVE: (std::ops::Bound<f64>, std::ops::Bound<f64>) = (Excluded(0.0), Unbounded);

/// A robot's pose from arguments `i..i+3`: X Y mm, THETA degrees.
fn pose(l: &ConfLine, i: usize) -> Result<Pose, ConfError> {
    Ok(Pose::new(
        l.number(i, "X in mm", ..)?,
        l.number(i + 1, "Y in mm", ..)?,
        l.number(i + 2, "THETA in degrees", ..)?,
    ))
}

/// The lines that are not `provides`: the world, the robots, the clock, the model.
struct Settings {
    world: World,
    robots: Vec<(String, Option<Pose>)>,
    model: RobotModel,
    noise: Noise,
    seed: u64,
    clock: Clock,
    step: f64,
    periods: Periods,
    publish_always: bool,
}

fn settings(conf: &ComponentConf) -> Result<Settings, ConfError> {
    conf.check(LINES)?;
    let mut s = Settings {
        world: World::new(),
        robots: Vec::new(),
        model: RobotModel::default(),
        noise: Noise::default(),
        seed: 1,
        clock: Clock::Speed(1.0),
        step: 0.01,
        periods: Periods::default(),
        publish_always: false,
    };
    let mut initial: Option<Pose> = None;
    for l in &conf.lines {
        match l.keyword() {
            "world" => {
                l.expect_args(1, 1, "world FILE")?;
                let path = l.existing_file(0, "the world file")?;
                s.world = World::load(&path).map_err(|e| l.error(format!("world file: {e}")))?;
            }
            "robot" => {
                if l.args().len() != 1 {
                    l.expect_args(4, 4, "robot NAME X_MM Y_MM THETA_DEG")?;
                }
                let name = l.word(0, "a robot name")?.to_string();
                if name.parse::<f64>().is_ok() || name.contains('.') {
                    return Err(l.error(format!(
                        "`robot`: `{name}` is not a valid robot name (a word without dots)"
                    )));
                }
                if s.robots.iter().any(|r| r.0 == name) {
                    return Err(l.error(format!("robot `{name}` is declared twice")));
                }
                let at = if l.args().len() == 4 {
                    Some(pose(l, 1)?)
                } else {
                    None
                };
                s.robots.push((name, at));
            }
            "initial_position" => {
                l.expect_args(3, 3, "initial_position X_MM Y_MM THETA_DEG")?;
                initial = Some(pose(l, 0)?);
            }
            "provides" | "motors_timeout" => {}
            "speed" => {
                l.expect_args(1, 1, "speed N|max")?;
                s.clock = if l.args()[0] == "max" {
                    Clock::Max
                } else {
                    Clock::Speed(l.number(0, "a speed factor (or max)", POSITIVE)?)
                };
            }
            "stepped" => {
                l.expect_args(1, 1, "stepped MS")?;
                s.clock =
                    Clock::Stepped(l.number(0, "milliseconds per command", POSITIVE)? / 1000.0);
            }
            "seed" => {
                l.expect_args(1, 1, "seed N")?;
                s.seed = l.number(0, "an integer seed", ..)?;
            }
            "step" => {
                l.expect_args(1, 1, "step MS")?;
                s.step = l.number(0, "the physics step in ms", 0.001..=100.0)? / 1000.0;
            }
            "period" => {
                l.expect_args(
                    2,
                    2,
                    "period encoders|laser|sonars|bumpers|camera|pantiltencoders|imu MS",
                )?;
                let sensor = l.choice(
                    0,
                    "the sensor",
                    &[
                        "encoders",
                        "laser",
                        "sonars",
                        "bumpers",
                        "camera",
                        "pantiltencoders",
                        "imu",
                    ],
                )?;
                let v = l.number(1, "a period in ms", POSITIVE)? / 1000.0;
                let p = &mut s.periods;
                *match sensor {
                    "encoders" => &mut p.encoders,
                    "laser" => &mut p.laser,
                    "sonars" => &mut p.sonars,
                    "bumpers" => &mut p.bumpers,
                    "camera" => &mut p.camera,
                    "imu" => &mut p.imu,
                    _ => &mut p.pantiltencoders,
                } = v;
            }
            "noise" => match l.choice(0, "the noisy sensor", &["odometry", "laser", "sonars"])? {
                "odometry" => {
                    l.expect_args(3, 3, "noise odometry DISTANCE_FRACTION ANGLE_FRACTION")?;
                    s.noise.odometry_distance = l.number(1, "a fraction of the distance", 0.0..)?;
                    s.noise.odometry_angle = l.number(2, "a fraction of the angle", 0.0..)?;
                }
                "laser" => {
                    l.expect_args(2, 2, "noise laser MM")?;
                    s.noise.laser = l.number(1, "a standard deviation in mm", 0.0..)?;
                }
                _ => {
                    l.expect_args(2, 2, "noise sonars MM")?;
                    s.noise.sonars = l.number(1, "a standard deviation in mm", 0.0..)?;
                }
            },
            "accel" => {
                l.expect_args(2, 2, "accel MM_S2 DEG_S2")?;
                s.model.accel_v = l.number(0, "a linear acceleration in mm/s²", POSITIVE)?;
                s.model.accel_w = l.number(1, "an angular acceleration in deg/s²", POSITIVE)?;
            }
            "radius" => {
                l.expect_args(1, 1, "radius MM")?;
                s.model.radius = l.number(0, "a radius in mm", POSITIVE)?;
            }
            "laser_range" => {
                l.expect_args(1, 1, "laser_range MM")?;
                s.model.laser_range = l.number(0, "a range in mm", POSITIVE)?;
            }
            "camera_height" => {
                l.expect_args(1, 1, "camera_height MM")?;
                s.model.camera_height = l.number(0, "a height in mm", POSITIVE)?;
            }
            "camera_fov" => {
                l.expect_args(1, 1, "camera_fov DEG")?;
                s.model.camera_fov = l.number(
                    0,
                    "a field of view in degrees",
                    (Excluded(0.0), Excluded(170.0)),
                )?;
            }
            "publish_always" => {
                l.expect_args(1, 1, "publish_always on|off")?;
                s.publish_always = l.on_off(0, "publish_always")?;
            }
            _ => {} // refused by the declaration
        }
    }
    if s.robots.is_empty() {
        s.robots.push(("robot1".into(), initial));
    } else if let Some(p) = initial {
        s.robots[0].1 = Some(p);
    }
    Ok(s)
}

/// Reads one `provides` line into the robots' [`Provides`] (and their laser
/// model); returns the interface's name.
fn provides(
    l: &ConfLine,
    names: &[String],
    sim: &mut Sim,
    provides: &mut [Provides],
) -> Result<String, ConfError> {
    if l.args().is_empty() {
        return Err(l.error(format!(
            "`provides` needs an interface; usage: {USAGE_PROVIDES}"
        )));
    }
    let kind = l.interface(0)?;
    // Arguments after the interface; a trailing word that is not a number names
    // the robot.
    let mut extra = l.args().len() - 1;
    let robot = match l.args().last().filter(|_| extra > 0) {
        Some(w) if w.parse::<f64>().is_err() => {
            let k = names.iter().position(|n| n == w).ok_or_else(|| {
                l.error(format!(
                    "`provides {kind}`: no robot called `{w}`; robots: {}",
                    names.join(", ")
                ))
            })?;
            extra -= 1;
            k
        }
        _ => 0,
    };
    let name = interface_name(&kind, (robot > 0).then(|| names[robot].as_str()));
    let p = &mut provides[robot];
    let takes = |usage: &str| {
        l.error(format!(
            "`provides {kind}` takes {usage}; usage: {USAGE_PROVIDES}"
        ))
    };
    match kind.as_str() {
        "encoders" | "motors" | "sonars" | "bumpers" | "pantiltencoders" | "pantiltmotors"
        | "imu" => {
            if extra != 0 {
                return Err(takes("no arguments besides a robot name"));
            }
            *match kind.as_str() {
                "encoders" => &mut p.encoders,
                "motors" => &mut p.motors,
                "sonars" => &mut p.sonars,
                "bumpers" => &mut p.bumpers,
                "pantiltencoders" => &mut p.pantiltencoders,
                "imu" => &mut p.imu,
                _ => &mut p.pantiltmotors,
            } = Some(name.clone());
        }
        "laser" => {
            match extra {
                0 => {}
                2 => {
                    let m = &mut sim.robots[robot].model;
                    m.laser_count = l.number(1, "a number of readings", 1..=720)?;
                    m.laser_resolution = l.number(2, "a resolution (readings/deg)", POSITIVE)?;
                }
                _ => return Err(takes("[N RESOLUTION] [ROBOT]")),
            }
            p.laser = Some(name.clone());
        }
        "colorA" | "colorB" | "colorC" | "colorD" => {
            if extra != 0 {
                return Err(takes("no arguments besides a robot name"));
            }
            p.cameras.push((name.clone(), COLOR_WIDTH, COLOR_HEIGHT));
        }
        "varcolorA" | "varcolorB" | "varcolorC" | "varcolorD" => {
            let (w, h) = match extra {
                0 => (COLOR_WIDTH, COLOR_HEIGHT),
                2 => (
                    l.number(1, "W in pixels", 1..=4096)?,
                    l.number(2, "H in pixels", 1..=4096)?,
                ),
                _ => return Err(takes("[W H] [ROBOT]")),
            };
            p.cameras.push((name.clone(), w, h));
        }
        _ => {
            return Err(l.error(format!(
                "the simulator does not provide `{kind}`; usage: {USAGE_PROVIDES}"
            )));
        }
    }
    Ok(name)
}

impl Simulation {
    /// Parses the driver's conf lines (every error names file:line).
    pub fn parse(conf: &ComponentConf) -> Result<Simulation, ConfError> {
        let s = settings(conf)?;
        let motors_timeout = conf.motors_timeout()?;
        let mut sim = Sim::new(s.world, s.seed);
        sim.noise = s.noise;
        let mut starts = sim.world.starts.clone().into_iter();
        for (name, at) in &s.robots {
            let p = at.unwrap_or_else(|| {
                starts
                    .next()
                    .map(|s| Pose::new(s.x, s.y, s.theta))
                    .unwrap_or_default()
            });
            sim.add_robot(name, s.model.clone(), p.x, p.y, p.theta.to_degrees());
        }
        let names: Vec<String> = s.robots.iter().map(|r| r.0.clone()).collect();
        let mut provided = vec![Provides::default(); names.len()];
        let mut taken: Vec<String> = Vec::new();
        for l in conf.provides() {
            let name = provides(l, &names, &mut sim, &mut provided)?;
            if taken.contains(&name) {
                return Err(l.error(format!("interface `{name}` is provided twice")));
            }
            taken.push(name);
        }
        for (k, r) in sim.robots.iter().enumerate() {
            if sim.world.segments.iter().any(|s| {
                let q = closest_on_segment([r.pose.x, r.pose.y], s);
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
        Ok(Simulation {
            sim,
            provides: provided,
            clock: s.clock,
            step: s.step,
            periods: s.periods,
            motors_timeout,
            publish_always: s.publish_always,
        })
    }
}
