//! The simulator's conf lines (see the [module doc](super) and `docs/simulator.md`)
//! turned into a [`Simulation`] ready to run: the [`Sim`] with its world and robots,
//! what each robot provides, the clock and the publishing periods. Every line is
//! read through its declaration ([`LINES`]) and nowhere else, so every error
//! names `file:line`, the argument and its range, and no value is clamped.

use std::time::Duration;

use crate::{
    conf::{
        ComponentConf, ConfError, ConfLine,
        settings::{
            self, Form, MOTORS_TIMEOUT, NumberOr, Setting, choice, float, float_or, int, kinds,
            name, on_off, path, pixels,
        },
    },
    interfaces::{COLOR_HEIGHT, COLOR_WIDTH, Kind, interface_name},
    world::{LiveScore, Rule, World, closest_on_segment},
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
    /// The run's clock (`run.clock`), exported when the simulation does not run
    /// in real time (`speed` other than 1, `max`, `stepped`): simulated time.
    pub run_clock: Option<std::sync::Arc<crate::runtime::RunClock>>,
    /// Where the driver stores the score (`world.score`) as it changes, when the
    /// conf keeps one (`score`) and the simulation exports it.
    pub live_score: Option<std::sync::Arc<LiveScore>>,
}

/// The sensors a `period` line names (the words of [`Sensor`]).
const SENSORS: &[&str] = &[
    "encoders",
    "laser",
    "sonars",
    "bumpers",
    "camera",
    "pantiltencoders",
    "imu",
];

/// A sensor a `period` line names: an interface kind, or the camera (every image
/// interface of the robot).
#[derive(Clone, Copy, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
enum Sensor {
    Encoders,
    Laser,
    Sonars,
    Bumpers,
    Camera,
    Pantiltencoders,
    Imu,
}

/// A `score` line's rule.
#[derive(Clone, Copy, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
enum ScoreLine {
    None,
    Swept,
    Targets,
    Lap,
}

/// The devices a `provides` line of the device form names.
const DEVICES: &[Kind] = &[
    Kind::Encoders,
    Kind::Motors,
    Kind::Sonars,
    Kind::Bumpers,
    Kind::PtEncoders,
    Kind::PtMotors,
    Kind::Imu,
];

crate::declare_lines! {
    /// The simulator's lines, declared once (`jderobot help simulator`) and read
    /// into [`Lines`]; nothing else reads them.
    pub(crate) struct Lines {
        #[allow(dead_code)] // its file is read by `world`, which names what it is
        world: Option<std::path::PathBuf> = Setting::new(
            "world",
            "the world: walls, starts, balls (a world file)",
            &[path("FILE")],
        ),
        robot: Vec<RobotLine> = Setting::new(
            "robot",
            "a robot; its pose (mm, mm, deg) or the world's next start",
            &[
                name("NAME"),
                float("X", "mm", -1e7, 1e7).optional(),
                float("Y", "mm", -1e7, 1e7),
                float("THETA", "deg", -36_000.0, 36_000.0),
            ],
        )
        .repeats(),
        initial_position: Option<(f64, f64, f64)> = settings::INITIAL_POSITION.help("the first robot's pose"),
        provides: Vec<ProvidesLine> = settings::provides_forms(
            "what a robot provides (ROBOT: a `robot` line's name; default the first robot)",
            &[
                Form::new(
                    "device",
                    "the robot's device",
                    &[kinds("INTERFACE", DEVICES), name("ROBOT").optional()],
                ),
                Form::new(
                    "laser",
                    "its laser: N readings at RESOLUTION readings/deg (default: 180 at 1)",
                    &[
                        kinds("laser", &[Kind::Laser]),
                        int("N", "", 1, 720).optional(),
                        float("RESOLUTION", "readings/deg", 0.01, 100.0),
                        name("ROBOT").optional(),
                    ],
                ),
                Form::new(
                    "color",
                    "its pan-tilt camera at 320x240",
                    &[settings::COLOR, name("ROBOT").optional()],
                ),
                Form::new(
                    "varcolor",
                    "its pan-tilt camera at W x H (default 320x240)",
                    &[
                        settings::VARCOLOR,
                        pixels("W", 4096).optional(),
                        pixels("H", 4096),
                        name("ROBOT").optional(),
                    ],
                ),
            ],
        ),
        #[allow(dead_code)] // read by `conf.motors_timeout()`
        motors_timeout: u64 = MOTORS_TIMEOUT,
        speed: NumberOr = Setting::new(
            "speed",
            "simulated seconds per wall second (1 = real time), or max: as fast as it can",
            &[float_or("N", "", 0.001, 1e6, "max")],
        )
        .default("1"),
        stepped: Option<f64> = Setting::new(
            "stepped",
            "advance this much simulated time per new command on the first robot's motors",
            &[float("MS", "ms", 0.001, 60_000.0)],
        ),
        seed: u64 = Setting::new(
            "seed",
            "the noise's random seed",
            &[int("N", "", 0, i64::MAX)],
        )
        .default("1"),
        step: f64 = Setting::new(
            "step",
            "the physics step",
            &[float("MS", "ms", 0.001, 100.0)],
        )
        .default("10"),
        period: Vec<(Sensor, f64)> = Setting::new(
            "period",
            "how often a sensor publishes (simulated time)",
            &[
                choice("SENSOR", SENSORS),
                float("MS", "ms", 0.001, 60_000.0),
            ],
        )
        .repeats(),
        noise: Vec<NoiseLine> = Setting::forms(
            "noise",
            "sensor noise",
            &[
                Form::new(
                    "odometry",
                    "odometry's error: a fraction of each distance and of each turn",
                    &[
                        choice("odometry", &["odometry"]),
                        float("DISTANCE_FRACTION", "", 0.0, 1e6),
                        float("ANGLE_FRACTION", "", 0.0, 1e6),
                    ],
                ),
                Form::new(
                    "range",
                    "a range sensor's standard deviation",
                    &[
                        kinds("laser|sonars", &[Kind::Laser, Kind::Sonars]),
                        float("MM", "mm", 0.0, 1e6),
                    ],
                ),
            ],
        )
        .repeats(),
        accel: Option<(f64, f64)> = Setting::new(
            "accel",
            "the robot's accelerations",
            &[
                float("V", "mm/s²", 0.001, 1e6),
                float("W", "deg/s²", 0.001, 1e6),
            ],
        ),
        radius: Option<f64> = Setting::new(
            "radius",
            "the robot's radius",
            &[float("R", "mm", 0.001, 1e5)],
        ),
        laser_range: Option<f64> = Setting::new(
            "laser_range",
            "the laser's range",
            &[float("RANGE", "mm", 0.001, 1e6)],
        ),
        camera_height: Option<f64> = Setting::new(
            "camera_height",
            "the pan-tilt camera's height",
            &[float("H", "mm", 0.001, 1e5)],
        ),
        camera_fov: Option<f64> = Setting::new(
            "camera_fov",
            "the pan-tilt camera's horizontal field of view",
            &[float("FOV", "deg", 0.001, 169.999)],
        ),
        camera_tilt: Option<f64> = Setting::new(
            "camera_tilt",
            "the pan-tilt camera's tilt at the start (negative: down, at the floor ahead)",
            &[float("TILT", "deg", -46.0, 30.0)],
        ),
        score: ScoreLine = Setting::new(
            "score",
            "the exercise's score, kept from the first robot's true pose and exported as world.score: \
             floor swept, targets reached in order, laps of the closed painted line (docs/simulator.md)",
            &[choice("RULE", &["none", "swept", "targets", "lap"])],
        )
        .default("none"),
        publish_always: bool = Setting::new(
            "publish_always",
            "publish sensors even while nobody uses them",
            &[on_off("SWITCH")],
        )
        .default("off"),
    }
}
/// `robot NAME [X Y THETA]`.
type RobotLine = (String, Option<f64>, Option<f64>, Option<f64>);

/// A `provides` line in its form: the interface, its arguments, the robot.
#[derive(serde::Deserialize)]
enum ProvidesLine {
    #[serde(rename = "device")]
    Device(Kind, Option<String>),
    #[serde(rename = "laser")]
    Laser(Kind, Option<usize>, Option<f64>, Option<String>),
    #[serde(rename = "color")]
    Color(String, Option<String>),
    #[serde(rename = "varcolor")]
    Varcolor(String, Option<u32>, Option<u32>, Option<String>),
}

#[derive(serde::Deserialize)]
enum NoiseLine {
    #[serde(rename = "odometry")]
    Odometry(serde::de::IgnoredAny, f64, f64),
    #[serde(rename = "range")]
    Range(Kind, f64),
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
    score: Option<Rule>,
}

/// The world of the `world` line (an empty world without one).
fn world(conf: &ComponentConf) -> Result<World, ConfError> {
    match conf.line("world") {
        Some(l) => {
            // The declaration resolved the path; this says what a non-file is.
            let f = l.existing_file(0, "the world file")?;
            World::load(&f).map_err(|e| l.error(format!("world file: {e}")))
        }
        None => Ok(World::new()),
    }
}

/// The robots of the `robot` lines (one `robot1` without any), each named once.
fn robots(conf: &ComponentConf, l: &Lines) -> Result<Vec<(String, Option<Pose>)>, ConfError> {
    let mut robots: Vec<(String, Option<Pose>)> = Vec::new();
    for ((name, x, y, theta), line) in l.robot.iter().zip(conf.lines_with("robot")) {
        if robots.iter().any(|r| r.0 == *name) {
            return Err(line.error(format!("robot `{name}` is declared twice")));
        }
        let at = match (x, y, theta) {
            (Some(x), Some(y), Some(t)) => Some(Pose::new(*x, *y, *t)),
            _ => None,
        };
        robots.push((name.clone(), at));
    }
    let initial = l.initial_position.map(|(x, y, t)| Pose::new(x, y, t));
    if robots.is_empty() {
        robots.push(("robot1".into(), initial));
    } else if let Some(p) = initial {
        robots[0].1 = Some(p);
    }
    Ok(robots)
}

/// The robot model, noise and periods the lines set (each value as declared).
fn model(l: &Lines) -> (RobotModel, Noise, Periods) {
    let mut model = RobotModel::default();
    if let Some((v, w)) = l.accel {
        (model.accel_v, model.accel_w) = (v, w);
    }
    let set = |field: &mut f64, v: Option<f64>| {
        if let Some(v) = v {
            *field = v;
        }
    };
    set(&mut model.radius, l.radius);
    set(&mut model.laser_range, l.laser_range);
    set(&mut model.camera_height, l.camera_height);
    set(&mut model.camera_fov, l.camera_fov);
    if let Some(t) = l.camera_tilt {
        model.pantilt.latitude = t as f32;
    }
    let mut noise = Noise::default();
    for n in &l.noise {
        match n {
            NoiseLine::Odometry(_, d, a) => {
                (noise.odometry_distance, noise.odometry_angle) = (*d, *a)
            }
            NoiseLine::Range(Kind::Laser, mm) => noise.laser = *mm,
            NoiseLine::Range(_, mm) => noise.sonars = *mm,
        }
    }
    let mut periods = Periods::default();
    for (sensor, ms) in &l.period {
        let p = &mut periods;
        *match sensor {
            Sensor::Encoders => &mut p.encoders,
            Sensor::Laser => &mut p.laser,
            Sensor::Sonars => &mut p.sonars,
            Sensor::Bumpers => &mut p.bumpers,
            Sensor::Camera => &mut p.camera,
            Sensor::Imu => &mut p.imu,
            Sensor::Pantiltencoders => &mut p.pantiltencoders,
        } = ms / 1000.0;
    }
    (model, noise, periods)
}

/// Reads the lines (every one through its declaration) into [`Settings`] and the
/// `provides` lines.
fn settings(conf: &ComponentConf) -> Result<(Settings, Vec<ProvidesLine>), ConfError> {
    let l: Lines = conf.read()?;
    // `speed` and `stepped`: the later line counts.
    let at = |k: &str| conf.lines_with(k).last().map(|l| l.at.line);
    let clock = match (l.stepped, l.speed) {
        (Some(ms), _) if at("stepped") > at("speed") => Clock::Stepped(ms / 1000.0),
        (_, NumberOr::Word) => Clock::Max,
        (_, NumberOr::Number(n)) => Clock::Speed(n),
    };
    let (model, noise, periods) = model(&l);
    let s = Settings {
        world: world(conf)?,
        robots: robots(conf, &l)?,
        model,
        noise,
        seed: l.seed,
        clock,
        step: l.step / 1000.0,
        periods,
        publish_always: l.publish_always,
        score: match l.score {
            ScoreLine::None => None,
            ScoreLine::Swept => Some(Rule::Swept),
            ScoreLine::Targets => Some(Rule::Targets),
            ScoreLine::Lap => Some(Rule::Lap),
        },
    };
    Ok((s, l.provides))
}

/// Puts one `provides` line into the robots' [`Provides`] (and their laser
/// model); returns the interface's name.
fn provides(
    p: ProvidesLine,
    l: &ConfLine,
    names: &[String],
    sim: &mut Sim,
    provides: &mut [Provides],
) -> Result<String, ConfError> {
    let (kind, robot) = match &p {
        ProvidesLine::Device(k, r) | ProvidesLine::Laser(k, .., r) => (k.to_string(), r.clone()),
        ProvidesLine::Color(k, r) | ProvidesLine::Varcolor(k, .., r) => (k.clone(), r.clone()),
    };
    let robot = match robot {
        Some(w) => names.iter().position(|n| *n == w).ok_or_else(|| {
            l.error(format!(
                "`provides {kind}`: no robot called `{w}`; robots: {}",
                names.join(", ")
            ))
        })?,
        None => 0,
    };
    let name = interface_name(&kind, (robot > 0).then(|| names[robot].as_str()));
    let p_robot = &mut provides[robot];
    match p {
        ProvidesLine::Device(device, _) => {
            *match device {
                Kind::Encoders => &mut p_robot.encoders,
                Kind::Motors => &mut p_robot.motors,
                Kind::Sonars => &mut p_robot.sonars,
                Kind::Bumpers => &mut p_robot.bumpers,
                Kind::PtEncoders => &mut p_robot.pantiltencoders,
                Kind::Imu => &mut p_robot.imu,
                Kind::PtMotors => &mut p_robot.pantiltmotors,
                Kind::Image | Kind::Laser | Kind::ZoomEncoders | Kind::ZoomMotors => {
                    return Err(l.error(format!("`provides {device}`: the simulator has none")));
                }
            } = Some(name.clone());
        }
        ProvidesLine::Laser(_, n, r, _) => {
            if let (Some(n), Some(r)) = (n, r) {
                let m = &mut sim.robots[robot].model;
                (m.laser_count, m.laser_resolution) = (n, r);
            }
            p_robot.laser = Some(name.clone());
        }
        ProvidesLine::Color(..) => p_robot
            .cameras
            .push((name.clone(), COLOR_WIDTH, COLOR_HEIGHT)),
        ProvidesLine::Varcolor(_, w, h, _) => {
            let (w, h) = w.zip(h).unwrap_or((COLOR_WIDTH, COLOR_HEIGHT));
            p_robot.cameras.push((name.clone(), w, h));
        }
    }
    Ok(name)
}

impl Simulation {
    /// Parses the driver's conf lines (every error names file:line).
    pub fn parse(conf: &ComponentConf) -> Result<Simulation, ConfError> {
        let (s, lines) = settings(conf)?;
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
        for (p, l) in lines.into_iter().zip(conf.provides()) {
            let name = provides(p, l, &names, &mut sim, &mut provided)?;
            if taken.contains(&name) {
                return Err(l.error(format!("interface `{name}` is provided twice")));
            }
            taken.push(name);
        }
        if let Some(rule) = s.score
            && let Err(e) = sim.start_score(rule)
            && let Some(l) = conf.line("score")
        {
            let world = conf
                .line("world")
                .map_or("none".into(), |w| w.args().join(" "));
            return Err(l.error(format!(
                "`score {}`: {e} (world: {world}); or choose another score: swept, targets, lap, none",
                l.args().join(" ")
            )));
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
            run_clock: None,
            live_score: None,
        })
    }
}
