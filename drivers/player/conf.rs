//! The driver's conf lines.

use std::time::Duration;

use crate::conf::{
    ComponentConf, ConfLine,
    settings::{Form, MOTORS_TIMEOUT, Setting, choice, custom, float, int, kinds, name, word},
};
use crate::interfaces::{IMAGE_NAMES, Kind, interface_name};

use super::xdr::{Addr, interf};

/// What a `provides` line asks for.
#[derive(Clone, Debug, PartialEq)]
pub enum Provided {
    Encoders,
    Motors,
    /// N readings at R readings per degree.
    Laser(usize, f64),
    Sonars,
    Bumpers,
    PanTiltEncoders,
    PanTiltMotors,
    /// `colorA..D` (320x240) or `varcolorA..D` (the camera's size): is it fixed-size.
    Camera(bool),
    Blobs,
}

/// One `provides` line.
#[derive(Clone, Debug)]
pub struct Want {
    pub kind: Provided,
    /// The interface (or name-space) name, with the robot suffix.
    pub name: String,
    pub robot: Option<String>,
    /// `index I`.
    pub index: Option<u32>,
    /// `device INTERF[:I]`: the Player device named explicitly.
    pub device: Option<(u32, Option<u32>)>,
    pub line: ConfLine,
}

/// The odometry offset of `initial_position X Y THETA` (mm, mm, deg).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Offset {
    pub x: f64,
    pub y: f64,
    pub theta_deg: f64,
}

/// How data reaches the client.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DataMode {
    Push,
    Pull,
}

#[derive(Clone, Debug)]
pub struct PlayerConf {
    pub host: String,
    pub port: u16,
    /// Per robot (None = the robot with no suffix).
    pub offsets: Vec<(Option<String>, Offset)>,
    pub wants: Vec<Want>,
    pub motors_timeout: Duration,
    pub timeout: Duration,
    pub mode: DataMode,
    /// The command cycle (4.3's PLAYER_COMMAND_CYCLE, 75 ms).
    pub cycle: Duration,
}

impl PlayerConf {
    pub fn offset(&self, robot: &Option<String>) -> Offset {
        self.offsets
            .iter()
            .rev()
            .find(|(r, _)| r == robot)
            .map(|(_, o)| *o)
            .unwrap_or_default()
    }
}

/// The Player interfaces a `device` word may name (`laser`, `ranger:1`).
const DEVICES: &[&str] = &[
    "position2d",
    "laser",
    "ranger",
    "sonar",
    "bumper",
    "ptz",
    "camera",
    "blobfinder",
];
/// Their interface codes, in the same order.
const DEVICE_CODES: &[u32] = &[
    interf::POSITION2D,
    interf::LASER,
    interf::RANGER,
    interf::SONAR,
    interf::BUMPER,
    interf::PTZ,
    interf::CAMERA,
    interf::BLOBFINDER,
];

/// `[index I] [device INTERF[:I]] [ROBOT]`: what every `provides` form ends with.
macro_rules! provides_tail {
    ($($head:expr),* $(,)?) => {
        &[
            $($head,)*
            choice("index", &["index"]).optional(),
            int("I", "", 0, u32::MAX as i64),
            choice("device", &["device"]).optional(),
            custom("INTERF[:I]", "a Player interface with an optional :INDEX", check_device),
            name("ROBOT").optional(),
        ]
    };
}

crate::declare_lines! {
    /// The driver's lines, declared once (`jderobot help player`).
    pub(crate) struct Lines {
        hostname: Option<(String, Option<String>, Option<u16>)> = Setting::new(
            "hostname",
            "the Player server (`hostname H port P`)",
            &[
                word("HOST"),
                choice("port", &["port"]).optional(),
                int("PORT", "", 1, 65_535),
            ],
        ),
        port: Option<(u16, Option<String>, Option<String>)> = Setting::new(
            "port",
            "the Player server's TCP port (`port P hostname H` too)",
            &[
                int("PORT", "", 1, 65_535),
                choice("hostname", &["hostname"]).optional(),
                word("HOST"),
            ],
        ),
        initial_position: Vec<(f64, f64, f64, Option<String>)> = Setting::new(
            "initial_position",
            "the odometry offset of a robot (the one with no suffix unless ROBOT)",
            &[
                float("X", "mm", -1e9, 1e9),
                float("Y", "mm", -1e9, 1e9),
                float("THETA", "deg", -36_000.0, 36_000.0),
                name("ROBOT").optional(),
            ],
        )
        .repeats(),
        provides: Vec<Provides> = Setting::forms(
            "provides",
            "an interface and the Player device it comes from: `index I` (the device index, default 0), \
             `device INTERF[:I]` (a Player interface named explicitly), ROBOT (the interface's suffix)",
            &[
                Form::new(
                    "laser",
                    "N readings at R readings/deg (default 180 1), from laser:I or a ranger",
                    provides_tail![
                        choice("laser", &["laser"]),
                        int("N", "", 1, 720).optional(),
                        float("R", "readings/deg", 0.01, 100.0),
                    ],
                ),
                Form::new(
                    "device",
                    "from position2d (encoders, motors), sonar or ranger, bumper, ptz",
                    provides_tail![kinds(
                        "INTERFACE",
                        &[
                            Kind::Encoders,
                            Kind::Motors,
                            Kind::Sonars,
                            Kind::Bumpers,
                            Kind::PtEncoders,
                            Kind::PtMotors,
                        ],
                    )],
                ),
                Form::new(
                    "named",
                    "4.3's jde_robot (encoders), the blobs of a blobfinder",
                    provides_tail![choice("INTERFACE", &["jde_robot", "blobs"])],
                ),
                Form::new(
                    "named",
                    "an image from camera",
                    provides_tail![choice("IMAGE", &IMAGE_NAMES)],
                ),
            ],
        )
        .repeats(),
        #[allow(dead_code)] // read by `conf.motors_timeout()`
        motors_timeout: u64 = MOTORS_TIMEOUT,
        timeout: u64 = Setting::new(
            "timeout",
            "how long the server may stay silent before the session counts as lost",
            &[int("MS", "ms", 50, 60_000)],
        )
        .default("2000"),
        datamode: String = Setting::new(
            "datamode",
            "push: the server sends data as it comes; pull: on request each cycle",
            &[choice("MODE", &["push", "pull"])],
        )
        .default("push"),
        cycle: u64 = Setting::new(
            "cycle",
            "the command cycle (4.3's PLAYER_COMMAND_CYCLE)",
            &[int("MS", "ms", 5, 10_000)],
        )
        .default("75"),
    }
}
/// The words after a `provides` line's interface (and a laser's N R).
type Tail = (
    Option<String>,
    Option<u32>,
    Option<String>,
    Option<String>,
    Option<String>,
);

#[derive(serde::Deserialize)]
enum Provides {
    #[serde(rename = "laser")]
    Laser(
        String,
        Option<usize>,
        Option<f64>,
        Option<String>,
        Option<u32>,
        Option<String>,
        Option<String>,
        Option<String>,
    ),
    #[serde(rename = "device")]
    Device(
        Kind,
        Option<String>,
        Option<u32>,
        Option<String>,
        Option<String>,
        Option<String>,
    ),
    /// `jde_robot`, `blobs`, an image.
    #[serde(rename = "named")]
    Named(
        String,
        Option<String>,
        Option<u32>,
        Option<String>,
        Option<String>,
        Option<String>,
    ),
}

impl PlayerConf {
    pub fn parse(conf: &ComponentConf) -> anyhow::Result<PlayerConf> {
        let lines: Lines = conf.read()?;
        // `hostname H [port P]` and `port P [hostname H]`: the last of each counts.
        let mut host = "localhost".to_string();
        let mut port: u16 = 6665;
        let order = |k: &str| conf.lines_with(k).last().map(|l| l.at.line);
        let (h_at, p_at) = (order("hostname"), order("port"));
        let from_host = |port: &mut u16, host: &mut String| {
            if let Some((h, _, p)) = &lines.hostname {
                *host = h.clone();
                if let Some(p) = p {
                    *port = *p;
                }
            }
        };
        let from_port = |port: &mut u16, host: &mut String| {
            if let Some((p, _, h)) = &lines.port {
                *port = *p;
                if let Some(h) = h {
                    *host = h.clone();
                }
            }
        };
        if h_at <= p_at {
            from_host(&mut port, &mut host);
            from_port(&mut port, &mut host);
        } else {
            from_port(&mut port, &mut host);
            from_host(&mut port, &mut host);
        }
        let offsets = lines
            .initial_position
            .into_iter()
            .map(|(x, y, theta_deg, robot)| (robot, Offset { x, y, theta_deg }))
            .collect();
        let mut wants: Vec<Want> = Vec::new();
        for (p, l) in lines.provides.into_iter().zip(conf.provides()) {
            let w = want(p, l)?;
            if let Some(o) = wants.iter().find(|o| o.name == w.name) {
                return Err(err(
                    l,
                    format!(
                        "`{}` is already provided at line {}",
                        w.name, o.line.at.line
                    ),
                ));
            }
            wants.push(w);
        }
        Ok(PlayerConf {
            host,
            port,
            offsets,
            wants,
            motors_timeout: conf.motors_timeout()?,
            timeout: Duration::from_millis(lines.timeout),
            mode: if lines.datamode == "pull" {
                DataMode::Pull
            } else {
                DataMode::Push
            },
            cycle: Duration::from_millis(lines.cycle),
        })
    }
}

fn err(l: &ConfLine, m: impl Into<String>) -> anyhow::Error {
    l.error(m).into()
}

/// A `device INTERF[:I]` word: the Player interface's code and its index (the
/// declaration's check of the word, and its value).
fn device(d: &str) -> Result<(u32, Option<u32>), String> {
    let (name, idx) = match d.split_once(':') {
        Some((n, k)) => (n, Some(k)),
        None => (d, None),
    };
    let code = DEVICES
        .iter()
        .zip(DEVICE_CODES)
        .find(|(n, _)| **n == name)
        .map(|(_, c)| *c)
        .ok_or_else(|| {
            format!(
                "`device {d}`: expected a Player interface ({}) with an optional :INDEX",
                DEVICES.join(", ")
            )
        })?;
    let idx = match idx {
        Some(k) => Some(
            k.parse::<u32>()
                .map_err(|_| format!("`device {d}`: `{k}` is not a device index"))?,
        ),
        None => None,
    };
    Ok((code, idx))
}

fn check_device(d: &str) -> Result<(), String> {
    device(d).map(drop)
}

/// One `provides` line, as declared, into what the driver asks the server for.
fn want(p: Provides, l: &ConfLine) -> anyhow::Result<Want> {
    let (what, kind, tail): (String, Provided, Tail) = match p {
        Provides::Laser(w, n, r, a, b, c, d, e) => (
            w,
            Provided::Laser(n.unwrap_or(180), r.unwrap_or(1.0)),
            (a, b, c, d, e),
        ),
        Provides::Device(k, a, b, c, d, e) => {
            let kind = match k {
                Kind::Encoders => Provided::Encoders,
                Kind::Motors => Provided::Motors,
                Kind::Sonars => Provided::Sonars,
                Kind::Bumpers => Provided::Bumpers,
                Kind::PtEncoders => Provided::PanTiltEncoders,
                Kind::PtMotors => Provided::PanTiltMotors,
                other => {
                    return Err(err(
                        l,
                        format!("`provides {other}`: Player gives no {other}"),
                    ));
                }
            };
            (k.name().to_string(), kind, (a, b, c, d, e))
        }
        Provides::Named(w, a, b, c, d, e) => {
            let kind = match w.as_str() {
                "jde_robot" => Provided::Encoders,
                "blobs" => Provided::Blobs,
                image => Provided::Camera(image.starts_with("color")),
            };
            (w, kind, (a, b, c, d, e))
        }
    };
    let (_, index, _, device_word, robot) = tail;
    let device = match device_word {
        Some(d) => Some(device(&d).map_err(|e| err(l, e))?),
        None => None,
    };
    let base = match what.as_str() {
        "jde_robot" => "encoders",
        w => w,
    };
    let name = match kind {
        Provided::Blobs => match &robot {
            Some(r) => format!("blobs.{r}"),
            None => "blobs".into(),
        },
        _ => interface_name(base, robot.as_deref()),
    };
    if let (Some((code, Some(k))), Some(i)) = (device, index)
        && k != i
    {
        return Err(err(
            l,
            format!(
                "`provides {what}`: `device {}:{k}` and `index {i}` disagree; give one",
                super::xdr::interf_name(code)
            ),
        ));
    }
    Ok(Want {
        kind,
        name,
        robot,
        index,
        device,
        line: l.clone(),
    })
}

/// The Player device a want reads or drives, chosen among the server's devices.
/// Errors name the line and list what the server has.
pub fn choose(w: &Want, devices: &[Addr], server: &str) -> anyhow::Result<Addr> {
    let has = |a: Addr| devices.contains(&a);
    let list = || {
        if devices.is_empty() {
            "no devices".to_string()
        } else {
            devices
                .iter()
                .map(|a| a.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        }
    };
    let missing = |what: String| -> anyhow::Error {
        err(
            &w.line,
            format!(
                "the Player server at {server} has no {what} for `{}`; it has: {}. \
                 Fix the server's .cfg (provides [\"6665:{what}\" ...]) or this line's `index`/`device`",
                w.line.words.join(" "),
                list()
            ),
        )
    };
    let idx = w.index.unwrap_or(0);
    if let Some((code, k)) = w.device {
        let a = Addr::new(code, k.or(w.index).unwrap_or(0));
        return if has(a) {
            Ok(a)
        } else {
            Err(missing(a.to_string()))
        };
    }
    let one = |code: u32| {
        let a = Addr::new(code, idx);
        if has(a) {
            Ok(a)
        } else {
            Err(missing(a.to_string()))
        }
    };
    match w.kind {
        Provided::Encoders | Provided::Motors => one(interf::POSITION2D),
        Provided::Bumpers => one(interf::BUMPER),
        Provided::PanTiltEncoders | Provided::PanTiltMotors => one(interf::PTZ),
        Provided::Camera(_) => one(interf::CAMERA),
        Provided::Blobs => one(interf::BLOBFINDER),
        Provided::Sonars => {
            let s = Addr::new(interf::SONAR, idx);
            let r = Addr::new(interf::RANGER, idx);
            if has(s) {
                Ok(s)
            } else if has(r) {
                Ok(r)
            } else {
                Err(missing(format!("sonar:{idx} or ranger:{idx}")))
            }
        }
        Provided::Laser(..) => {
            let l = Addr::new(interf::LASER, idx);
            if has(l) {
                return Ok(l);
            }
            if w.index.is_some() {
                let r = Addr::new(interf::RANGER, idx);
                return if has(r) {
                    Ok(r)
                } else {
                    Err(missing(format!("laser:{idx} or ranger:{idx}")))
                };
            }
            // Stage 4 serves a Pioneer's sonar ring as ranger:0 and its laser as
            // ranger:1: with no index, the last ranger listed.
            devices
                .iter()
                .rev()
                .find(|a| a.interf == interf::RANGER)
                .copied()
                .ok_or_else(|| missing("laser:0 or a ranger".into()))
        }
    }
}
