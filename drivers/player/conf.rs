//! The driver's conf lines.

use std::time::Duration;

use crate::conf::{
    ComponentConf, ConfLine,
    settings::{MOTORS_TIMEOUT, Setting, choice, float, int, rest, word},
};
use crate::interfaces::interface_name;

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

/// The driver's lines, declared once (`jderobot help player`); `provides` lines take
/// several forms and are read below.
pub const LINES: &[Setting] = &[
    Setting::new(
        "hostname",
        "the Player server (`hostname H port P`)",
        &[
            word("HOST"),
            choice("port", &["port"]).optional(),
            int("PORT", "", 1, 65_535),
        ],
    ),
    Setting::new(
        "port",
        "the Player server's TCP port (`port P hostname H` too)",
        &[
            int("PORT", "", 1, 65_535),
            choice("hostname", &["hostname"]).optional(),
            word("HOST"),
        ],
    ),
    Setting::new(
        "initial_position",
        "the odometry offset of a robot (the one with no suffix unless ROBOT)",
        &[
            float("X", "mm", -1e9, 1e9),
            float("Y", "mm", -1e9, 1e9),
            float("THETA", "deg", -36_000.0, 36_000.0),
            word("ROBOT").optional(),
        ],
    )
    .repeats(),
    Setting::new(
        "provides",
        USAGE_PROVIDES,
        &[word("INTERFACE"), rest("ARGS").optional()],
    )
    .repeats(),
    MOTORS_TIMEOUT,
    Setting::new(
        "timeout",
        "how long the server may stay silent before the session counts as lost",
        &[int("MS", "ms", 50, 60_000)],
    )
    .default("2000"),
    Setting::new(
        "datamode",
        "push: the server sends data as it comes; pull: on request each cycle",
        &[choice("MODE", &["push", "pull"])],
    )
    .default("push"),
    Setting::new(
        "cycle",
        "the command cycle (4.3's PLAYER_COMMAND_CYCLE)",
        &[int("MS", "ms", 5, 10_000)],
    )
    .default("75"),
];

pub const USAGE_PROVIDES: &str = "provides encoders|motors|sonars|bumpers|pantiltencoders|pantiltmotors|\
colorA..D|varcolorA..D|blobs [index I] [device INTERF[:I]] [ROBOT], provides laser N R [index I] \
[device laser|ranger[:I]] [ROBOT]";

fn err(l: &ConfLine, m: impl Into<String>) -> anyhow::Error {
    l.error(m).into()
}

fn interf_code(name: &str) -> Option<u32> {
    Some(match name {
        "position2d" => interf::POSITION2D,
        "laser" => interf::LASER,
        "ranger" => interf::RANGER,
        "sonar" => interf::SONAR,
        "bumper" => interf::BUMPER,
        "ptz" => interf::PTZ,
        "camera" => interf::CAMERA,
        "blobfinder" => interf::BLOBFINDER,
        _ => return None,
    })
}

fn finite(l: &ConfLine, i: usize, what: &str) -> anyhow::Result<f64> {
    let v: f64 = l.arg(i, what)?;
    if !v.is_finite() {
        return Err(err(
            l,
            format!("`{}`: {what} must be a finite number", l.keyword()),
        ));
    }
    Ok(v)
}

fn robot_name(l: &ConfLine, w: &str) -> anyhow::Result<String> {
    if w.parse::<f64>().is_ok() || w.contains('.') || w.contains(':') {
        return Err(err(
            l,
            format!("`{w}` is not a robot name (a word without dots); usage: {USAGE_PROVIDES}"),
        ));
    }
    Ok(w.to_string())
}

impl PlayerConf {
    pub fn parse(conf: &ComponentConf) -> anyhow::Result<PlayerConf> {
        conf.check(LINES)?;
        let mut host = "localhost".to_string();
        let mut port: u16 = 6665;
        let mut offsets = Vec::new();
        let mut wants: Vec<Want> = Vec::new();
        let mut timeout = Duration::from_millis(2000);
        let mut mode = DataMode::Push;
        let mut cycle = Duration::from_millis(75);
        for l in &conf.lines {
            match l.keyword() {
                "hostname" | "port" => {
                    // `hostname H port P` (either part alone too).
                    let w = &l.words;
                    let mut i = 0;
                    while i < w.len() {
                        match (w[i].as_str(), w.get(i + 1)) {
                            ("hostname", Some(h)) => host = h.clone(),
                            ("port", Some(p)) => {
                                port = p.parse().ok().filter(|p| *p > 0).ok_or_else(|| {
                                    err(l, format!("`port {p}`: expected a TCP port 1..65535"))
                                })?
                            }
                            _ => {
                                return Err(err(
                                    l,
                                    format!(
                                        "`{}`: expected `hostname H port P` (e.g. `hostname localhost port 6665`)",
                                        w.join(" ")
                                    ),
                                ));
                            }
                        }
                        i += 2;
                    }
                }
                "initial_position" => {
                    l.expect_args(3, 4, "initial_position X_MM Y_MM THETA_DEG [ROBOT]")?;
                    let robot = match l.args().get(3) {
                        Some(r) => Some(robot_name(l, r)?),
                        None => None,
                    };
                    offsets.push((
                        robot,
                        Offset {
                            x: finite(l, 0, "X in mm")?,
                            y: finite(l, 1, "Y in mm")?,
                            theta_deg: finite(l, 2, "THETA in degrees")?,
                        },
                    ));
                }
                "motors_timeout" => {}
                "timeout" => {
                    l.expect_args(1, 1, "timeout MS")?;
                    timeout = l.millis(0, "milliseconds", 50..=60_000)?;
                }
                "cycle" => {
                    l.expect_args(1, 1, "cycle MS")?;
                    cycle = l.millis(0, "milliseconds", 5..=10_000)?;
                }
                "datamode" => {
                    l.expect_args(1, 1, "datamode push|pull")?;
                    mode = match l.args()[0].as_str() {
                        "push" => DataMode::Push,
                        "pull" => DataMode::Pull,
                        o => return Err(err(l, format!("`datamode {o}`: expected push or pull"))),
                    };
                }
                "provides" => {
                    let w = parse_provides(l)?;
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
                _ => {} // refused by the declaration
            }
        }
        Ok(PlayerConf {
            host,
            port,
            offsets,
            wants,
            motors_timeout: conf.motors_timeout()?,
            timeout,
            mode,
            cycle,
        })
    }
}

fn parse_provides(l: &ConfLine) -> anyhow::Result<Want> {
    l.expect_args(1, 12, USAGE_PROVIDES)?;
    let what = l.args()[0].as_str();
    let rest: Vec<&str> = l.args()[1..].iter().map(String::as_str).collect();
    let mut index = None;
    let mut device = None;
    let mut robot = None;
    let mut numbers: Vec<&str> = Vec::new();
    let mut i = 0;
    while i < rest.len() {
        match rest[i] {
            "index" => {
                let v = rest
                    .get(i + 1)
                    .and_then(|s| s.parse::<u32>().ok())
                    .ok_or_else(|| {
                        err(
                            l,
                            format!("`provides {what}`: `index` needs a device index (0, 1, ...)"),
                        )
                    })?;
                index = Some(v);
                i += 2;
            }
            "device" => {
                let d = rest.get(i + 1).copied().unwrap_or("");
                let (name, idx) = match d.split_once(':') {
                    Some((n, k)) => (n, Some(k)),
                    None => (d, None),
                };
                let code = interf_code(name).ok_or_else(|| {
                    err(
                        l,
                        format!(
                            "`device {d}`: expected a Player interface (position2d, laser, ranger, sonar, \
                             bumper, ptz, camera, blobfinder) with an optional :INDEX"
                        ),
                    )
                })?;
                let idx = match idx {
                    Some(k) => Some(k.parse::<u32>().map_err(|_| {
                        err(l, format!("`device {d}`: `{k}` is not a device index"))
                    })?),
                    None => None,
                };
                device = Some((code, idx));
                i += 2;
            }
            w if w.parse::<f64>().is_ok() => {
                numbers.push(w);
                i += 1;
            }
            w => {
                if robot.is_some() {
                    return Err(err(
                        l,
                        format!("`provides {what}`: unexpected `{w}`; usage: {USAGE_PROVIDES}"),
                    ));
                }
                robot = Some(robot_name(l, w)?);
                i += 1;
            }
        }
    }
    let kind = match what {
        "laser" => match numbers.as_slice() {
            [] => Provided::Laser(180, 1.0),
            [n, r] => {
                let n = n
                    .parse::<usize>()
                    .ok()
                    .filter(|n| (1..=720).contains(n))
                    .ok_or_else(|| {
                        err(
                            l,
                            format!("`provides laser`: `{n}` is not a number of readings 1..720"),
                        )
                    })?;
                let r = r.parse::<f64>().ok().filter(|r| *r > 0.0 && r.is_finite()).ok_or_else(|| {
                    err(l, format!("`provides laser`: `{r}` is not a positive resolution (readings/deg)"))
                })?;
                Provided::Laser(n, r)
            }
            _ => {
                return Err(err(
                    l,
                    format!(
                        "`provides laser` takes N R (e.g. `provides laser 180 1`); usage: {USAGE_PROVIDES}"
                    ),
                ));
            }
        },
        other => {
            if !numbers.is_empty() {
                return Err(err(
                    l,
                    format!(
                        "`provides {other}`: unexpected `{}`; usage: {USAGE_PROVIDES}",
                        numbers.join(" ")
                    ),
                ));
            }
            match other {
                "encoders" | "jde_robot" => Provided::Encoders,
                "motors" => Provided::Motors,
                "sonars" | "us" => Provided::Sonars,
                "bumpers" => Provided::Bumpers,
                "pantiltencoders" | "ptencoders" => Provided::PanTiltEncoders,
                "pantiltmotors" | "ptmotors" => Provided::PanTiltMotors,
                "colorA" | "colorB" | "colorC" | "colorD" => Provided::Camera(true),
                "varcolorA" | "varcolorB" | "varcolorC" | "varcolorD" => Provided::Camera(false),
                "blobs" => Provided::Blobs,
                _ => {
                    return Err(err(
                        l,
                        format!(
                            "the player driver does not provide `{other}`; usage: {USAGE_PROVIDES}"
                        ),
                    ));
                }
            }
        }
    };
    let base = match what {
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
