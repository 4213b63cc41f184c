//! naobody: a NAO humanoid (or the NAOqi simulator) through NAOqi, as JDE 4.3.1's
//! `naobody` driver drove it: the walk, the head, the camera, and (beyond 4.3)
//! odometry, the sonars and the foot bumpers. It speaks libqi's messaging
//! protocol itself ([`qi`]: plain TCP, NAOqi 2.1 and 2.5; NAOqi 2.9's TLS with
//! credentials is not supported), so it needs no NAOqi SDK.
//!
//! # Conf
//! ```text
//! driver naobody
//! host nao.local            # NAOqi's host (default 127.0.0.1) ...
//! port 9559                 # ... and port (default 9559), or instead:
//! url tcp://nao.local:9559
//! provides motors           # the walk (ALMotion.move)
//! provides ptmotors         # the head (ALMotion.setAngles HeadYaw/HeadPitch)
//! provides ptencoders       # the head's angles (ALMotion.getAngles)
//! provides encoders         # odometry (ALMotion.getRobotPosition)
//! provides sonars           # left and right ultrasound (ALMemory)
//! provides bumpers          # the four foot bumpers (ALMemory)
//! provides varcolorA 0 320 240   # CAMERA W H: 0 top, 1 bottom; 160x120, 320x240,
//!                                #   640x480 or 1280x960 (kQQVGA..k4VGA)
//! provides colorB 1         # CAMERA: 320x240
//! fps 15                    # camera frames per second (NAOqi serves at most 30)
//! colorspace bgr            # bgr, rgb or yuv422: what the robot sends (yuv422 is 2/3 the bytes)
//! poll 100                  # ms between reads of the head, odometry, sonars, bumpers
//! max_v 100                 # mm/s: the fastest walk asked for
//! max_w 40                  # deg/s: the fastest turn asked for
//! motors_timeout 500        # ms: an older motors command stops the walk
//! reply_timeout 2000        # ms: a call without answer counts as a lost session
//! end_driver
//! ```
//!
//! # Interfaces
//! | interface | fields, units, NAOqi |
//! |---|---|
//! | `motors` | `v` mm/s forward, `w` deg/s counter-clockwise, limited to ±`max_v`, ±`max_w` and sent as `ALMotion.move(v/1000 m/s, 0, w·π/180 rad/s)` when they change (`moveToward` with v/max_v, w/max_w when the robot has no `move`); zero, a command older than `motors_timeout`, and stopping the driver send `stopMove()`; `wakeUp()` (logged) before the first step of a session when `robotIsWakeUp()` says it sleeps |
//! | `pantiltmotors` | `longitude` = HeadYaw (deg, positive to the left), `latitude` = −HeadPitch (deg, positive up), limited to the limits `ALMotion.getLimits` gives (published in the value); `longitude_speed`, `latitude_speed` deg/s as `setAngles`' fraction of the joint's maximum speed (0.01..1); speed 0 sends nothing (the head holds its target) |
//! | `pantiltencoders` | `pan_angle` = HeadYaw, `tilt_angle` = −HeadPitch, deg (`getAngles(..., true)`: the sensors) |
//! | `encoders` | `ALMotion.getRobotPosition(true)`: x, y mm, θ rad in the robot's odometry frame |
//! | `sonars` | `us[0]` left, `us[1]` right, mm (`Device/SubDeviceList/US/{Left,Right}/Sensor/Value`, metres); `ALSonar.subscribe` first where it exists |
//! | `bumpers` | 1 = pressed: left foot left, left foot right, right foot left, right foot right (`Device/SubDeviceList/{L,R}Foot/Bumper/{Left,Right}/Sensor/Value`) |
//! | `colorA..D`, `varcolorA..D` | BGR; `ALVideoDevice.subscribeCamera(name, CAMERA, resolution, colorspace, fps)` while the interface is used, `getImageRemote` paced at `fps` (a repeated frame, same timestamp, is not republished), `unsubscribe` when unused or stopped; kBGRColorSpace (13) copied, kRGBColorSpace (11) swapped, kYUV422ColorSpace (9, `0xY'Y'VVYYUU`: bytes U Y V Y', BT.601) converted |
//!
//! # Behaviour
//! - The body (walk, head, odometry, sonars, bumpers) is one [`Device`] and each
//!   camera another, each on its own qi connection under a [`Supervisor`]: NAOqi
//!   absent at start is one line naming the URL and what to start, the
//!   interfaces are stale with that reason, and it is tried again (0.5 s doubling
//!   to 5 s). A service or method the robot lacks is an error naming it and the
//!   robot's NAOqi version. A lost session (a vanished NAOqi, a call unanswered
//!   within `reply_timeout`, garbage on the socket) marks the interfaces stale;
//!   on reconnection the walk is stopped (`stopMove`) until a new command, and
//!   cameras are subscribed again.
//! - The walk's emergency stop: `stopMove`, registered with [`crate::estop`]
//!   while a session lasts (SIGINT, SIGTERM, SIGHUP, Ctrl+Z, an abort and a
//!   panic run it first), sent through a second handle on the session's socket
//!   ([`qi::Detached`]); after [`crate::estop::halted`] the driver sends no walk
//!   or head command, only `stopMove`; after a suspension the robot walks again
//!   on the next `motors` command.
//! - The body thread wakes on every motors or head command (no polling delay) and
//!   reads the sensors every `poll` ms.
//!
//! System packages: none.

pub mod qi;

use std::{
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, Instant},
};

use crate::{
    conf::{
        ComponentConf, ConfLine,
        settings::{self, Form, MOTORS_TIMEOUT, Setting, choice, float, int, kinds, pixels, word},
    },
    estop,
    interfaces::{
        AnyInterface, Bumpers, COLOR_HEIGHT, COLOR_WIDTH, Encoders, Image, Interface, Kind, Motors,
        PtEncoders, PtMotors, Sonars, Source, Watch, limit,
    },
    runtime::{Backoff, Device, Driver, Runtime, Supervision, Supervisor},
    supervisor::Absent,
    vision::pixfmt::{self, Yuv422Order, YuvMatrix},
};
use qi::{QiError, Service, Session, Value};

const USAGE: &str = "provides motors|encoders|pantiltencoders|pantiltmotors|sonars|bumpers, \
provides colorA..D [CAMERA], provides varcolorA..D CAMERA W H (CAMERA 0 top, 1 bottom; \
W H 160 120, 320 240, 640 480 or 1280 960)";

crate::declare_lines! {
    /// The lines `naobody` takes (`jderobot help naobody` prints them).
    struct Lines {
        provides: Vec<ProvidesLine> = settings::provides_forms(
            USAGE,
            &[
                Form::new(
                    "device",
                    "the walk, the odometry, the head, the sonars or the foot bumpers",
                    &[kinds(
                        "INTERFACE",
                        &[
                            Kind::Motors,
                            Kind::Encoders,
                            Kind::PtEncoders,
                            Kind::PtMotors,
                            Kind::Sonars,
                            Kind::Bumpers,
                        ],
                    )],
                ),
                Form::new(
                    "color",
                    "a camera at 320x240 (CAMERA 0 top, the default, or 1 bottom)",
                    &[settings::COLOR, int("CAMERA", "", 0, 1).optional()],
                ),
                Form::new(
                    "varcolor",
                    "a camera at W x H: 160 120, 320 240, 640 480 or 1280 960",
                    &[
                        settings::VARCOLOR,
                        int("CAMERA", "", 0, 1),
                        pixels("W", 1280),
                        pixels("H", 960),
                    ],
                ),
            ],
        )
        .required(),
        url: Option<String> = Setting::new(
            "url",
            "NAOqi's endpoint, instead of host and port",
            &[word("tcp://HOST:PORT")],
        ),
        host: String = Setting::new(
            "host",
            "the robot (or simulator) NAOqi runs on",
            &[word("HOST")],
        )
        .default("127.0.0.1"),
        port: u16 = Setting::new("port", "NAOqi's port", &[int("PORT", "", 1, 65_535)]).default("9559"),
        fps: u32 = Setting::new(
            "fps",
            "camera frames per second (NAOqi's cameras give at most 30; above that it polls faster, for peers that serve every call)",
            &[int("N", "frames/s", 1, 10_000)],
        )
        .default("15"),
        colorspace: String = Setting::new(
            "colorspace",
            "what the robot sends the camera's frames in (yuv422 is 2/3 of the bytes)",
            &[choice("SPACE", &["bgr", "rgb", "yuv422"])],
        )
        .default("bgr"),
        poll: u64 = Setting::new(
            "poll",
            "the time between reads of the head, odometry, sonars and bumpers",
            &[int("MS", "ms", 10, 10_000)],
        )
        .default("100"),
        max_v: f32 = Setting::new(
            "max_v",
            "the fastest walk sent to the robot",
            &[float("V", "mm/s", 1.0, 1000.0)],
        )
        .default("100"),
        max_w: f32 = Setting::new(
            "max_w",
            "the fastest turn sent to the robot",
            &[float("W", "deg/s", 1.0, 360.0)],
        )
        .default("40"),
        motors_timeout: u64 = MOTORS_TIMEOUT,
        reply_timeout: u64 = Setting::new(
            "reply_timeout",
            "how long a call may go unanswered before the session counts as lost",
            &[int("MS", "ms", 10, 60_000)],
        )
        .default("2000"),
    }
}
/// A `provides` line in its declared form.
#[derive(serde::Deserialize)]
enum ProvidesLine {
    #[serde(rename = "device")]
    Device(Kind),
    /// colorA..D [CAMERA].
    #[serde(rename = "color")]
    Color(String, Option<i64>),
    /// varcolorA..D CAMERA W H.
    #[serde(rename = "varcolor")]
    Varcolor(String, i64, u32, u32),
}

/// NAOqi's resolutions (`kQQVGA`..`k4VGA`) by size.
pub const RESOLUTIONS: &[(u32, u32, i64)] =
    &[(160, 120, 0), (320, 240, 1), (640, 480, 2), (1280, 960, 3)];
/// NAOqi's colour spaces the driver decodes.
pub const K_YUV422: i64 = 9;
pub const K_RGB: i64 = 11;
pub const K_BGR: i64 = 13;

/// One camera line.
#[derive(Clone, Debug, PartialEq)]
pub struct CamConf {
    pub iface: String,
    /// 0 top, 1 bottom.
    pub camera: i64,
    pub width: u32,
    pub height: u32,
    /// NAOqi's resolution id.
    pub resolution: i64,
    /// Where its provides line is (for the absent-at-start line).
    pub at: String,
}

/// The driver's settings.
#[derive(Clone, Debug)]
pub struct NaoConf {
    pub host: String,
    pub port: u16,
    pub motors: bool,
    pub encoders: bool,
    pub ptencoders: bool,
    pub ptmotors: bool,
    pub sonars: bool,
    pub bumpers: bool,
    pub cameras: Vec<CamConf>,
    pub fps: u32,
    /// NAOqi's colour space id.
    pub colorspace: i64,
    pub poll: Duration,
    pub max_v: f32,
    pub max_w: f32,
    pub motors_timeout: Duration,
    pub reply_timeout: Duration,
    /// Where the driver's section is, for messages.
    pub at: String,
}

impl NaoConf {
    /// `tcp://HOST:PORT`.
    pub fn url(&self) -> String {
        if self.host.contains(':') {
            format!("tcp://[{}]:{}", self.host, self.port)
        } else {
            format!("tcp://{}:{}", self.host, self.port)
        }
    }

    /// Whether the body device (ALMotion, ALMemory) has anything to do.
    fn has_body(&self) -> bool {
        self.motors
            || self.encoders
            || self.ptencoders
            || self.ptmotors
            || self.sonars
            || self.bumpers
    }

    /// Parses the driver's lines (errors name file:line).
    pub fn parse(conf: &ComponentConf) -> anyhow::Result<NaoConf> {
        let lines: Lines = conf.read()?;
        let (mut host, mut port) = (lines.host, lines.port);
        if let Some(url) = &lines.url {
            let l = conf.line("url").expect("a url line");
            let (h, p) = qi::parse_url(url).map_err(|e| l.error(format!("`url`: {e}")))?;
            for k in ["host", "port"] {
                if let Some(other) = conf.line(k) {
                    return Err(other
                        .error(format!("`{k}` and `url` both say where NAOqi is; keep one"))
                        .into());
                }
            }
            (host, port) = (h, p);
        }
        let mut c = NaoConf {
            host,
            port,
            motors: false,
            encoders: false,
            ptencoders: false,
            ptmotors: false,
            sonars: false,
            bumpers: false,
            cameras: Vec::new(),
            fps: lines.fps,
            colorspace: match lines.colorspace.as_str() {
                "rgb" => K_RGB,
                "yuv422" => K_YUV422,
                _ => K_BGR,
            },
            poll: Duration::from_millis(lines.poll),
            max_v: lines.max_v,
            max_w: lines.max_w,
            motors_timeout: Duration::from_millis(lines.motors_timeout),
            reply_timeout: Duration::from_millis(lines.reply_timeout),
            at: conf.file.display().to_string(),
        };
        for (l, p) in conf.lines_with("provides").zip(lines.provides) {
            c.provides(p, l)?;
        }
        Ok(c)
    }

    /// Puts one `provides` line (read as `p`) into the settings.
    fn provides(&mut self, p: ProvidesLine, l: &ConfLine) -> anyhow::Result<()> {
        let (iface, camera, size) = match p {
            ProvidesLine::Device(kind) => {
                let flag = match kind {
                    Kind::Motors => &mut self.motors,
                    Kind::Encoders => &mut self.encoders,
                    Kind::PtEncoders => &mut self.ptencoders,
                    Kind::PtMotors => &mut self.ptmotors,
                    Kind::Sonars => &mut self.sonars,
                    Kind::Bumpers => &mut self.bumpers,
                    other => {
                        return Err(l
                            .error(format!(
                                "`provides {other}`: a NAO has none; usage: {USAGE}"
                            ))
                            .into());
                    }
                };
                if *flag {
                    return Err(l.error(format!("`{kind}` is provided twice")).into());
                }
                *flag = true;
                return Ok(());
            }
            ProvidesLine::Color(name, camera) => (name, camera, (COLOR_WIDTH, COLOR_HEIGHT)),
            ProvidesLine::Varcolor(name, camera, w, h) => (name, Some(camera), (w, h)),
        };
        if self.cameras.iter().any(|c| c.iface == iface) {
            return Err(l.error(format!("`{iface}` is provided twice")).into());
        }
        let (width, height) = size;
        let Some(&(_, _, resolution)) = RESOLUTIONS
            .iter()
            .find(|(w, h, _)| (*w, *h) == (width, height))
        else {
            return Err(l
                .error(format!(
                    "{width}x{height} is not a NAO camera resolution; it gives 160x120, 320x240, 640x480 and 1280x960"
                ))
                .into());
        };
        self.cameras.push(CamConf {
            iface,
            camera: camera.unwrap_or(0),
            width,
            height,
            resolution,
            at: l.at.to_string(),
        });
        Ok(())
    }
}

/// The reason NAOqi could not be reached at `url`, and what to do.
fn unreachable(url: &str, e: &QiError) -> String {
    match e {
        QiError::Io(_) | QiError::Timeout(_) => format!(
            "{url}: no NAOqi answers ({e}); start NAOqi on the robot (or `naoqi-bin` for the \
             simulator), or fix the driver's `host`/`port`/`url` line"
        ),
        _ => format!("{url}: {e}"),
    }
}

/// Connects to NAOqi, or says why not.
fn connect(c: &NaoConf) -> Result<Session, String> {
    let url = c.url();
    let t = c.reply_timeout.min(Duration::from_secs(5));
    Session::connect(&c.host, c.port, t)
        .map_err(|e| unreachable(&url, &e))
        .map(|mut s| {
            s.set_timeout(c.reply_timeout);
            s
        })
}

/// The robot's NAOqi version: `ALSystem.systemVersion()`, else the `version()`
/// of one of `services` (every NAOqi 2 module has one).
fn version(qi: &mut Session, services: &[&Service]) -> String {
    if let Ok(Some(sys)) = qi.service("ALSystem")
        && let Ok(v) = qi.call(&sys, "systemVersion", &[])
        && let Some(t) = v.text()
    {
        return t;
    }
    for s in services {
        if s.method("version", 0).is_some()
            && let Ok(v) = qi.call(s, "version", &[])
            && let Some(t) = v.text()
        {
            return t;
        }
    }
    "unknown (no ALSystem.systemVersion, no version())".into()
}

/// A service the robot must have, or the error naming it and the NAOqi version.
fn need_service(qi: &mut Session, url: &str, name: &str, why: &str) -> Result<Service, String> {
    match qi.service(name) {
        Ok(Some(s)) => Ok(s),
        Ok(None) => Err(format!(
            "{url}: NAOqi {} has no {name} service, which {why} needs",
            version(qi, &[])
        )),
        Err(e) => Err(format!("{url}: looking up {name}: {e}")),
    }
}

/// Checks that `svc` has each (method, arity); else the error naming the first
/// missing one and the NAOqi version.
fn need_methods(
    qi: &mut Session,
    url: &str,
    svc: &Service,
    methods: &[(&str, usize)],
) -> Result<(), String> {
    for (m, n) in methods {
        if svc.method(m, *n).is_none() {
            let have = if svc.has(m) {
                " with that many arguments"
            } else {
                ""
            };
            return Err(format!(
                "{url}: {}.{m} ({n} argument(s)) is missing{have} on this robot (NAOqi {}); \
                 naobody needs NAOqi 2.1 or later",
                svc.name,
                version(qi, &[svc])
            ));
        }
    }
    Ok(())
}

// -------------------------------------------------------------------- body

const HEAD: [&str; 2] = ["HeadYaw", "HeadPitch"];
const US_KEYS: [&str; 2] = [
    "Device/SubDeviceList/US/Left/Sensor/Value",
    "Device/SubDeviceList/US/Right/Sensor/Value",
];
const BUMPER_KEYS: [&str; 4] = [
    "Device/SubDeviceList/LFoot/Bumper/Left/Sensor/Value",
    "Device/SubDeviceList/LFoot/Bumper/Right/Sensor/Value",
    "Device/SubDeviceList/RFoot/Bumper/Left/Sensor/Value",
    "Device/SubDeviceList/RFoot/Bumper/Right/Sensor/Value",
];

/// A joint's limits as `getLimits` gives them: rad, rad, rad/s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Joint {
    pub min: f32,
    pub max: f32,
    pub speed: f32,
}

/// The range a head joint's limits must be in: angles within ±2π rad, the
/// speed in (0, 100] rad/s (a NAO's head: ±2.09 rad, 8.27 rad/s).
const JOINT_RANGE: &str = "min <= max within ±2π rad, maxVelocity in (0, 100] rad/s";

/// Reads `getLimits(name)`'s `[[min, max, maxVelocity, maxTorque]]`, in range.
fn joint(v: &Value) -> Option<Joint> {
    let row = v.items()?.first()?.items()?;
    let f = |i: usize| number(row.get(i)?).map(|x| x as f32);
    let j = Joint {
        min: f(0)?,
        max: f(1)?,
        speed: f(2)?,
    };
    let tau = std::f32::consts::TAU;
    (j.min <= j.max && j.min >= -tau && j.max <= tau && j.speed > 0.0 && j.speed <= 100.0)
        .then_some(j)
}

/// How the walk is commanded.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Walk {
    /// `move(x m/s, y m/s, θ rad/s)`.
    Move,
    /// `moveToward(x, y, θ)` normalised to [-1, 1].
    MoveToward,
}

/// The walk command for (v mm/s, w deg/s), limited: the arguments of `move` (m/s,
/// rad/s) or of `moveToward` (fractions of max_v, max_w).
pub fn walk_args(v: f32, w: f32, max_v: f32, max_w: f32, normalised: bool) -> (f32, f32) {
    let m = Motors::limited(v, w, max_v, max_w);
    if normalised {
        (m.v / max_v, m.w / max_w)
    } else {
        (m.v / 1000.0, m.w.to_radians())
    }
}

/// HeadYaw/HeadPitch targets (rad) and speed fractions for a pan-tilt command.
pub fn head_targets(m: &PtMotors, yaw: Joint, pitch: Joint) -> [(f32, f32); 2] {
    let frac = |speed: f32, j: Joint| limit(speed.to_radians() / j.speed, 0.0, 1.0);
    let lon = limit(m.longitude.to_radians(), yaw.min, yaw.max);
    let lat = limit(-m.latitude.to_radians(), pitch.min, pitch.max);
    [
        (lon, frac(m.longitude_speed, yaw)),
        (lat, frac(m.latitude_speed, pitch)),
    ]
}

struct Body {
    conf: Arc<NaoConf>,
    motors: Option<Arc<Interface<Motors>>>,
    encoders: Option<Arc<Interface<Encoders>>>,
    pte: Option<Arc<Interface<PtEncoders>>>,
    ptm: Option<Arc<Interface<PtMotors>>>,
    sonars: Option<Arc<Interface<Sonars>>>,
    bumpers: Option<Arc<Interface<Bumpers>>>,
    source: Source,
    /// Wakes the thread on a motors or head command (made on the thread itself).
    watch: Option<Arc<Watch>>,
    /// The limits read from the robot, kept across sessions.
    limits: Option<(Joint, Joint)>,
    /// The last odometry reading (m, m) and when it came, for [`odometry_plausible`].
    last_odometry: Option<(f64, f64, Instant)>,
}

/// The farthest a NAO's odometry may be from its origin, m: 10 km (a NAO walks
/// 0.1 m/s at most, so 28 hours of walking); beyond it the reading is not a
/// NAO's (an attacker's stand-in sent 200 km).
pub const MAX_ODOMETRY_M: f64 = 10_000.0;
/// The fastest a reading may move from the one before, m/s (ten times a NAO's
/// top walk), plus [`ODOMETRY_SLACK_M`]: a jump beyond is refused.
pub const MAX_ODOMETRY_SPEED: f64 = 1.0;
pub const ODOMETRY_SLACK_M: f64 = 0.5;
/// How far past a head joint's limits a reading may be (sensor noise), rad.
pub const JOINT_SLACK_RAD: f32 = 0.05;
/// A NAO's head joints (HeadYaw, HeadPitch), rad, when the robot has not told
/// its own (`getLimits`): Aldebaran's documented ranges.
pub const NAO_HEAD: (Joint, Joint) = (
    Joint {
        min: -2.0857,
        max: 2.0857,
        speed: 8.27,
    },
    Joint {
        min: -0.6720,
        max: 0.5149,
        speed: 7.19,
    },
);

/// Whether odometry reading (x, y) m, taken at `now`, is a NAO's after `prev`:
/// within [`MAX_ODOMETRY_M`] of the origin and no farther from the previous
/// reading than [`MAX_ODOMETRY_SPEED`] for the time between, plus
/// [`ODOMETRY_SLACK_M`]. The reason when it is not.
pub fn odometry_plausible(
    prev: Option<(f64, f64, Instant)>,
    x: f64,
    y: f64,
    now: Instant,
) -> Result<(), String> {
    let far = x.hypot(y);
    if far > MAX_ODOMETRY_M {
        return Err(format!(
            "odometry {:.0} km from its origin is no NAO's (at most {} km)",
            far / 1000.0,
            MAX_ODOMETRY_M / 1000.0
        ));
    }
    if let Some((px, py, at)) = prev {
        let dt = now.saturating_duration_since(at).as_secs_f64();
        let jump = (x - px).hypot(y - py);
        let most = MAX_ODOMETRY_SPEED * dt + ODOMETRY_SLACK_M;
        if jump > most {
            return Err(format!(
                "odometry jumped {jump:.1} m in {dt:.2} s (a NAO walks at most {most:.1} m in that time)"
            ));
        }
    }
    Ok(())
}

/// Whether head angles (HeadYaw, HeadPitch) rad are within the joints' limits
/// (the robot's, else a NAO's: [`NAO_HEAD`]) and [`JOINT_SLACK_RAD`]. The reason
/// when they are not.
pub fn head_plausible(a: [f32; 2], limits: Option<(Joint, Joint)>) -> Result<(), String> {
    let (yaw, pitch) = limits.unwrap_or(NAO_HEAD);
    for ((angle, j), name) in a.into_iter().zip([yaw, pitch]).zip(HEAD) {
        if angle < j.min - JOINT_SLACK_RAD || angle > j.max + JOINT_SLACK_RAD {
            return Err(format!(
                "{name} {angle:.2} rad is outside the joint's limits [{:.2}, {:.2}] rad",
                j.min, j.max
            ));
        }
    }
    Ok(())
}

/// ALMotion with the methods the conf's interfaces call (None when none needs
/// it), and the walk command it has.
fn motion_service(
    qi: &mut Session,
    c: &NaoConf,
    url: &str,
) -> Result<(Option<Service>, Walk), String> {
    if !(c.motors || c.encoders || c.ptencoders || c.ptmotors) {
        return Ok((None, Walk::Move));
    }
    let m = need_service(qi, url, "ALMotion", "the walk, the head and odometry")?;
    let mut walk = Walk::Move;
    let mut want: Vec<(&str, usize)> = Vec::new();
    if c.motors {
        if m.method("move", 3).is_none() && m.method("moveToward", 3).is_some() {
            walk = Walk::MoveToward;
            want.push(("moveToward", 3));
        } else {
            want.push(("move", 3));
        }
        want.push(("stopMove", 0));
    }
    if c.ptmotors {
        want.extend([("setAngles", 3), ("getLimits", 1)]);
    }
    if c.ptencoders {
        want.push(("getAngles", 2));
    }
    if c.encoders {
        want.push(("getRobotPosition", 1));
    }
    need_methods(qi, url, &m, &want)?;
    Ok((Some(m), walk))
}

/// ALMemory for the sonars and bumpers, and ALSonar subscribed when the robot
/// has it (a real NAO updates the sonar values only while it is subscribed).
fn memory_services(
    qi: &mut Session,
    c: &NaoConf,
    url: &str,
) -> Result<(Option<Service>, Option<Service>), String> {
    if !(c.sonars || c.bumpers) {
        return Ok((None, None));
    }
    let mem = need_service(qi, url, "ALMemory", "the sonars and bumpers")?;
    need_methods(qi, url, &mem, &[("getListData", 1)])?;
    let sonar = if c.sonars {
        qi.service("ALSonar")
            .ok()
            .flatten()
            .filter(|s| s.method("subscribe", 1).is_some())
    } else {
        None
    };
    if let Some(s) = &sonar {
        qi.call(s, "subscribe", &[Value::str("jderobot")])
            .map_err(|e| format!("{url}: {e}"))?;
    }
    Ok((Some(mem), sonar))
}

/// Registers the walk's stop (`ALMotion.stopMove`, a [`qi::Detached`] call on
/// the session's socket) with [`estop`]; the flag it returns is set each time
/// the stop runs.
fn register_stop(
    qi: &Session,
    motion: &Service,
    url: &str,
) -> Result<(estop::Registration, Arc<AtomicBool>), String> {
    let stop = qi
        .detached(motion, "stopMove", &[])
        .map_err(|e| format!("{url}: the emergency stop: {e}"))?;
    let ran = Arc::new(AtomicBool::new(false));
    let flag = ran.clone();
    let registration = estop::register(format!("naobody {url}"), move || {
        let _ = stop.send();
        flag.store(true, Ordering::Release);
    });
    Ok((registration, ran))
}

struct BodySession {
    qi: Session,
    motion: Option<Service>,
    memory: Option<Service>,
    sonar: Option<Service>,
    walk: Walk,
    awake: bool,
    /// The walk last sent (move's or moveToward's x, θ).
    sent: Option<(f32, f32)>,
    head_clock: Option<u64>,
    head_sent: [Option<(f32, f32)>; 2],
    next_poll: Instant,
    /// The walk's emergency stop, registered with [`estop`] while the session
    /// lasts, and whether it ran since the walk was last sent.
    estop: Option<(estop::Registration, Arc<AtomicBool>)>,
    /// The `motors` clock when the emergency stop last ran (a suspension): the
    /// robot stands until a newer command.
    stood_at: Option<u64>,
}

impl Body {
    fn open_session(&mut self) -> Result<BodySession, String> {
        let c = self.conf.clone();
        let url = c.url();
        if self.watch.is_none() {
            let w = Watch::for_current_thread();
            if let Some(m) = &self.motors {
                m.watch(w.clone());
            }
            if let Some(m) = &self.ptm {
                m.watch(w.clone());
            }
            self.watch = Some(w);
        }
        let mut qi = connect(&c)?;
        let (motion, walk) = motion_service(&mut qi, &c, &url)?;
        let (memory, sonar) = memory_services(&mut qi, &c, &url)?;
        // The robot is back: a command now reaches it.
        if let Some(m) = &self.motors {
            m.clear_stale();
        }
        let mut s = BodySession {
            qi,
            motion,
            memory,
            sonar,
            walk,
            awake: false,
            sent: None,
            head_clock: None,
            head_sent: [None, None],
            next_poll: Instant::now(),
            estop: None,
            stood_at: None,
        };
        if let Some(m) = s.motion.clone() {
            if c.motors {
                // Whatever walk the last session left running stops until a new
                // command comes.
                s.qi.call(&m, "stopMove", &[])
                    .map_err(|e| format!("{url}: {e}"))?;
                s.sent = Some((0.0, 0.0));
                s.estop = Some(register_stop(&s.qi, &m, &url)?);
            }
            if c.ptmotors {
                self.read_head_limits(&mut s, &m, &url)?;
            }
        }
        Ok(s)
    }

    /// Reads the head's joint limits from the robot, keeps them, and publishes
    /// them in a copy of the latest head command.
    fn read_head_limits(
        &mut self,
        s: &mut BodySession,
        m: &Service,
        url: &str,
    ) -> Result<(), String> {
        let mut get = |name: &str| -> Result<Joint, String> {
            let v =
                s.qi.call(m, "getLimits", &[Value::str(name)])
                    .map_err(|e| format!("{url}: {e}"))?;
            joint(&v).ok_or_else(|| {
                format!(
                    "{url}: ALMotion.getLimits(\"{name}\") gave {}, not [[min, max, maxVelocity, maxTorque]] \
                     with {JOINT_RANGE}: refused",
                    short(&v)
                )
            })
        };
        let (yaw, pitch) = (get(HEAD[0])?, get(HEAD[1])?);
        self.limits = Some((yaw, pitch));
        if let Some(p) = &self.ptm {
            // A copy of the latest command with the robot's limits.
            let mut v = p.read().value;
            v.min_longitude = yaw.min.to_degrees();
            v.max_longitude = yaw.max.to_degrees();
            v.min_latitude = -pitch.max.to_degrees();
            v.max_latitude = -pitch.min.to_degrees();
            v.max_longitude_speed = yaw.speed.to_degrees();
            v.max_latitude_speed = pitch.speed.to_degrees();
            v.longitude_speed = limit(v.longitude_speed, 0.0, v.max_longitude_speed);
            v.latitude_speed = limit(v.latitude_speed, 0.0, v.max_latitude_speed);
            let _ = p.publish(v);
            s.head_clock = Some(p.clock());
        }
        Ok(())
    }

    /// Wakes the robot up (stiffness on, standing) before it walks or moves its head.
    fn wake(&self, s: &mut BodySession, m: &Service) -> Result<(), QiError> {
        if s.awake {
            return Ok(());
        }
        let asleep = match m.method("robotIsWakeUp", 0) {
            Some(_) => s.qi.call(m, "robotIsWakeUp", &[])?.as_f64() != Some(1.0),
            None => true,
        };
        if asleep && m.method("wakeUp", 0).is_some() {
            crate::output::println(format!(
                "naobody: waking the robot up (ALMotion.wakeUp) at {} before it moves",
                self.conf.url()
            ));
            s.qi.call(m, "wakeUp", &[])?;
        }
        s.awake = true;
        Ok(())
    }

    fn serve(&mut self, s: &mut BodySession) -> Result<(), QiError> {
        let c = self.conf.clone();
        if let (Some((_, ran)), Some(mi)) = (&s.estop, &self.motors)
            && ran.swap(false, Ordering::AcqRel)
        {
            // The emergency stop stopped the walk (a suspension): it walks again
            // on the controller's next command, not on the one it had (which
            // could go out before the process is suspended).
            s.sent = Some((0.0, 0.0));
            s.stood_at = Some(mi.clock());
        }
        if let (Some(mi), Some(m)) = (&self.motors, s.motion.clone()) {
            let cmd = mi.command(c.motors_timeout);
            // Once the process is ending (estop::halt), nothing but stopMove.
            let want = if estop::halted() || s.stood_at == Some(mi.clock()) {
                (0.0, 0.0)
            } else {
                walk_args(cmd.v, cmd.w, c.max_v, c.max_w, s.walk == Walk::MoveToward)
            };
            if s.sent != Some(want) {
                if want == (0.0, 0.0) {
                    s.qi.call(&m, "stopMove", &[])?;
                } else {
                    self.wake(s, &m)?;
                    let name = if s.walk == Walk::Move {
                        "move"
                    } else {
                        "moveToward"
                    };
                    s.qi.call(
                        &m,
                        name,
                        &[
                            Value::Float(want.0),
                            Value::Float(0.0),
                            Value::Float(want.1),
                        ],
                    )?;
                }
                s.sent = Some(want);
            }
        }
        // Once the process is ending, the head is not moved either.
        if !estop::halted()
            && let (Some(p), Some(m), Some((yaw, pitch))) =
                (&self.ptm, s.motion.clone(), self.limits)
        {
            let clock = p.clock();
            if s.head_clock != Some(clock) {
                s.head_clock = Some(clock);
                let targets = head_targets(&p.read().value, yaw, pitch);
                for (i, t) in targets.iter().enumerate() {
                    if t.1 > 0.0 && s.head_sent[i] != Some(*t) {
                        self.wake(s, &m)?;
                        s.qi.call(
                            &m,
                            "setAngles",
                            &[
                                Value::str(HEAD[i]),
                                Value::Float(t.0),
                                Value::Float(t.1.max(0.01)),
                            ],
                        )?;
                        s.head_sent[i] = Some(*t);
                    }
                }
            }
        }
        let now = Instant::now();
        if now >= s.next_poll {
            s.next_poll += c.poll;
            if s.next_poll < now {
                s.next_poll = now + c.poll;
            }
            self.poll(s)?;
        }
        let wait = s
            .next_poll
            .saturating_duration_since(Instant::now())
            .min(Duration::from_millis(100));
        if let Some(w) = &self.watch {
            w.wait(wait);
        }
        Ok(())
    }

    /// Reads the head, odometry, sonars and bumpers.
    fn poll(&mut self, s: &mut BodySession) -> Result<(), QiError> {
        if let (Some(e), Some(m)) = (&self.pte, s.motion.clone()) {
            let names = Value::List(HEAD.iter().map(|n| Value::str(n)).collect());
            let v = s.qi.call(&m, "getAngles", &[names, Value::Bool(true)])?;
            match numbers(&v, 2) {
                Some(a) => match head_plausible([a[0] as f32, a[1] as f32], self.limits) {
                    Ok(()) => {
                        e.accept(
                            &self.source,
                            PtEncoders {
                                pan_angle: (a[0] as f32).to_degrees(),
                                tilt_angle: -(a[1] as f32).to_degrees(),
                            },
                        );
                    }
                    Err(why) => e.set_stale(format!("ALMotion.getAngles: {why}")),
                },
                None => e.set_stale(format!(
                    "ALMotion.getAngles gave {}, not 2 angles",
                    short(&v)
                )),
            }
        }
        if let (Some(e), Some(m)) = (&self.encoders, s.motion.clone()) {
            let v = s.qi.call(&m, "getRobotPosition", &[Value::Bool(true)])?;
            match numbers(&v, 3) {
                Some(p) => {
                    let now = Instant::now();
                    let plausible = odometry_plausible(self.last_odometry, p[0], p[1], now);
                    // The next reading is judged against this one, so a reset of
                    // the odometry is believed from its second reading on.
                    self.last_odometry = Some((p[0], p[1], now));
                    match plausible {
                        Ok(()) => {
                            e.accept(
                                &self.source,
                                Encoders::from_pose(
                                    (p[0] * 1000.0) as f32,
                                    (p[1] * 1000.0) as f32,
                                    p[2] as f32,
                                ),
                            );
                        }
                        Err(why) => e.set_stale(format!("ALMotion.getRobotPosition: {why}")),
                    }
                }
                None => e.set_stale(format!(
                    "ALMotion.getRobotPosition gave {}, not [x, y, theta]",
                    short(&v)
                )),
            }
        }
        if let Some(mem) = s.memory.clone() {
            let mut keys: Vec<&str> = Vec::new();
            if self.sonars.is_some() {
                keys.extend(US_KEYS);
            }
            if self.bumpers.is_some() {
                keys.extend(BUMPER_KEYS);
            }
            let list = Value::List(keys.iter().map(|k| Value::str(k)).collect());
            let v = s.qi.call(&mem, "getListData", &[list])?;
            let got = numbers_or_bools(&v, keys.len());
            let mut at = 0;
            if let Some(i) = &self.sonars {
                let sonar = got.as_ref().map(|n| {
                    (
                        n[..2].to_vec(),
                        n[..2].iter().all(|m| (0.0..=MAX_SONAR_M).contains(m)),
                    )
                });
                match sonar {
                    Some((n, false)) => {
                        self.source.refused(format_args!(
                            "ALMemory's sonars say {n:?} m; a sonar reads 0..{MAX_SONAR_M} m: refused"
                        ));
                    }
                    Some((n, true)) => {
                        i.accept(
                            &self.source,
                            Sonars {
                                us: n.iter().map(|m| (*m * 1000.0) as f32).collect(),
                            },
                        );
                    }
                    None => i.set_stale(format!(
                        "ALMemory.getListData gave {} for the sonar keys {}",
                        short(&v),
                        US_KEYS.join(", ")
                    )),
                }
                at = 2;
            }
            if let Some(i) = &self.bumpers {
                match &got {
                    Some(n) => {
                        i.accept(
                            &self.source,
                            Bumpers {
                                bumpers: n[at..at + 4].iter().map(|b| (*b > 0.5) as u8).collect(),
                            },
                        );
                    }
                    None => i.set_stale(format!(
                        "ALMemory.getListData gave {} for the bumper keys",
                        short(&v)
                    )),
                }
            }
        }
        Ok(())
    }
}

/// The farthest a sonar reading may be, m (a NAO's reads 0.25..2.55 m, 5 m for nothing).
const MAX_SONAR_M: f64 = 10.0;

/// A finite number (an int or a float; a boolean is not a number here).
fn number(v: &Value) -> Option<f64> {
    match v {
        Value::Int(_) | Value::UInt(_) | Value::Float(_) | Value::Double(_) => {
            v.as_f64().filter(|f| f.is_finite())
        }
        _ => None,
    }
}

/// `n` finite numbers from a list (booleans are not taken as a pose).
fn numbers(v: &Value, n: usize) -> Option<Vec<f64>> {
    let items = v.items()?;
    if items.len() != n {
        return None;
    }
    items.iter().map(number).collect()
}

/// `n` finite numbers or booleans (as 0 and 1) from a list: ALMemory's values.
fn numbers_or_bools(v: &Value, n: usize) -> Option<Vec<f64>> {
    let items = v.items()?;
    if items.len() != n {
        return None;
    }
    items
        .iter()
        .map(|x| match x {
            Value::Bool(b) => Some(*b as u8 as f64),
            _ => number(x),
        })
        .collect()
}

/// A value as a short text for a message: formatting stops at [`qi::SHOW`]
/// characters, so a huge bad reply costs no more than a small one.
fn short(v: &Value) -> String {
    qi::show(v)
}

impl Device for Body {
    type Session = BodySession;
    fn open(&mut self) -> Result<BodySession, String> {
        self.open_session()
    }
    fn step(&mut self, s: &mut BodySession) -> Result<(), String> {
        let url = self.conf.url();
        self.serve(s).map_err(|e| format!("{url}: {e}"))
    }
    fn on_loss(&mut self) {
        if let Some(m) = &self.motors {
            let _ = m.publish(Motors::default());
        }
    }
    /// The driver stops: the walk stops, the sonars are let go.
    fn close(&mut self, mut s: BodySession) {
        if let (true, Some(m)) = (self.motors.is_some(), s.motion.clone()) {
            let _ = s.qi.call(&m, "stopMove", &[]);
        }
        if let Some(so) = s.sonar.clone() {
            let _ = s.qi.call(&so, "unsubscribe", &[Value::str("jderobot")]);
        }
    }
}

impl Drop for Body {
    fn drop(&mut self) {
        if let Some(w) = &self.watch {
            if let Some(m) = &self.motors {
                m.unwatch(w.as_ref());
            }
            if let Some(m) = &self.ptm {
                m.unwatch(w.as_ref());
            }
        }
    }
}

// ------------------------------------------------------------------ camera

struct Camera {
    conf: Arc<NaoConf>,
    cam: CamConf,
    iface: Arc<Interface<Image>>,
    source: Source,
    /// The subscriber name of the last session, let go of when a new one starts.
    handle: Option<String>,
}

struct CamSession {
    qi: Session,
    video: Service,
    handle: String,
    next: Instant,
    last_stamp: Option<(i64, i64)>,
}

/// One frame of `getImageRemote`: [width, height, layers, colorspace, seconds,
/// microseconds, data, camera, left, top, right, bottom angles].
#[derive(Debug, PartialEq)]
pub struct Frame<'a> {
    pub width: u32,
    pub height: u32,
    pub layers: u32,
    pub colorspace: i64,
    pub stamp: (i64, i64),
    pub data: &'a [u8],
}

/// Reads a `getImageRemote` reply, checking its sizes.
pub fn frame(v: &Value) -> Result<Frame<'_>, String> {
    let f = v
        .items()
        .filter(|f| f.len() >= 7)
        .ok_or_else(|| format!("getImageRemote gave {}, not an image", short(v)))?;
    let int = |i: usize, what: &str| {
        f[i].as_i64()
            .ok_or_else(|| format!("getImageRemote: {what} is {}", short(&f[i])))
    };
    let (w, h, layers) = (
        int(0, "the width")?,
        int(1, "the height")?,
        int(2, "the layers")?,
    );
    if !(1..=8192).contains(&w) || !(1..=8192).contains(&h) || !(1..=4).contains(&layers) {
        return Err(format!("getImageRemote: an image of {w}x{h}x{layers}"));
    }
    let data = f[6]
        .bytes()
        .ok_or_else(|| format!("getImageRemote: the pixels are {}", short(&f[6])))?;
    let need = (w * h * layers) as usize;
    if data.len() != need {
        return Err(format!(
            "getImageRemote: {} bytes of pixels for {w}x{h}x{layers} ({need})",
            data.len()
        ));
    }
    Ok(Frame {
        width: w as u32,
        height: h as u32,
        layers: layers as u32,
        colorspace: int(3, "the colour space")?,
        stamp: (int(4, "the seconds")?, int(5, "the microseconds")?),
        data,
    })
}

/// Converts a frame to BGR into `out`.
pub fn to_bgr(f: &Frame, out: &mut Vec<u8>) -> Result<(), String> {
    let (w, h) = (f.width, f.height);
    let r = match (f.colorspace, f.layers) {
        (K_BGR, 3) => pixfmt::bgr_to_bgr(f.data, w, h, out),
        (K_RGB, 3) => pixfmt::rgb_to_bgr(f.data, w, h, out),
        (K_YUV422, 2) => {
            pixfmt::yuv422_to_bgr(f.data, w, h, Yuv422Order::Uyvy, YuvMatrix::Bt601, out)
        }
        (cs, l) => {
            return Err(format!(
                "the robot sent colour space {cs} with {l} layer(s); naobody decodes 13 (BGR), 11 (RGB) and 9 (YUV422)"
            ));
        }
    };
    r.map_err(|e| e.to_string())
}

impl Camera {
    fn open_session(&mut self) -> Result<CamSession, String> {
        let c = self.conf.clone();
        let url = c.url();
        let mut qi = connect(&c)?;
        let video = need_service(&mut qi, &url, "ALVideoDevice", "the camera")?;
        need_methods(
            &mut qi,
            &url,
            &video,
            &[
                ("subscribeCamera", 5),
                ("getImageRemote", 1),
                ("unsubscribe", 1),
            ],
        )?;
        if let Some(old) = self.handle.take() {
            let _ = qi.call(&video, "unsubscribe", &[Value::Str(old.into_bytes())]);
        }
        let name = format!("jderobot_{}", self.cam.iface);
        let v = qi
            .call(
                &video,
                "subscribeCamera",
                &[
                    Value::str(&name),
                    Value::Int(self.cam.camera),
                    Value::Int(self.cam.resolution),
                    Value::Int(c.colorspace),
                    Value::Int(c.fps.min(30) as i64),
                ],
            )
            .map_err(|e| format!("{url}: {e}"))?;
        let handle = v.text().filter(|h| !h.is_empty()).ok_or_else(|| {
            format!(
                "{url}: ALVideoDevice.subscribeCamera gave {}, not a name",
                short(&v)
            )
        })?;
        self.handle = Some(handle.clone());
        Ok(CamSession {
            qi,
            video,
            handle,
            next: Instant::now(),
            last_stamp: None,
        })
    }

    fn serve(&mut self, s: &mut CamSession) -> Result<(), String> {
        let url = self.conf.url();
        let wait = s.next.saturating_duration_since(Instant::now());
        if !wait.is_zero() {
            std::thread::sleep(wait.min(Duration::from_millis(100)));
            return Ok(());
        }
        let period = Duration::from_secs_f64(1.0 / self.conf.fps as f64);
        s.next += period;
        if s.next < Instant::now() {
            s.next = Instant::now() + period;
        }
        let v =
            s.qi.call(
                &s.video,
                "getImageRemote",
                &[Value::Str(s.handle.clone().into_bytes())],
            )
            .map_err(|e| format!("{url}: {e}"))?;
        if matches!(v, Value::Void | Value::Nothing) {
            // No image yet (the camera is starting).
            return Ok(());
        }
        let f = frame(&v).map_err(|e| format!("{url}: {e}"))?;
        if (f.width, f.height) != (self.cam.width, self.cam.height) {
            return Err(format!(
                "{url}: asked for {}x{} frames, the robot sends {}x{}",
                self.cam.width, self.cam.height, f.width, f.height
            ));
        }
        if s.last_stamp == Some(f.stamp) {
            return Ok(());
        }
        s.last_stamp = Some(f.stamp);
        let mut bad = None;
        self.iface.accept_with(&self.source, |img| {
            img.width = f.width;
            img.height = f.height;
            if let Err(e) = to_bgr(&f, &mut img.data) {
                bad = Some(e);
                img.data.clear();
            }
        });
        match bad {
            Some(e) => Err(format!("{url}: {e}")),
            None => Ok(()),
        }
    }
}

impl Device for Camera {
    type Session = CamSession;
    fn open(&mut self) -> Result<CamSession, String> {
        self.open_session()
    }
    fn step(&mut self, s: &mut CamSession) -> Result<(), String> {
        self.serve(s)
    }
    fn close(&mut self, mut s: CamSession) {
        let _ = s.qi.call(
            &s.video,
            "unsubscribe",
            &[Value::Str(s.handle.clone().into_bytes())],
        );
        self.handle = None;
    }
}

// ------------------------------------------------------------------ driver

/// The retries: 0.5 s doubling to 5 s.
const BACKOFF: Backoff = Backoff {
    first: Duration::from_millis(500),
    max: Duration::from_secs(5),
};

/// Provides the interfaces and starts the body and camera devices.
pub fn start(conf: NaoConf, rt: &Runtime, provider: &str) -> anyhow::Result<Vec<Supervisor>> {
    let ifs = &rt.interfaces;
    let motors = conf
        .motors
        .then(|| ifs.provide::<Motors>("motors", provider))
        .transpose()?;
    let encoders = conf
        .encoders
        .then(|| ifs.provide::<Encoders>("encoders", provider))
        .transpose()?;
    let pte = conf
        .ptencoders
        .then(|| ifs.provide::<PtEncoders>("pantiltencoders", provider))
        .transpose()?;
    // The head starts at half its speed, so a position alone moves it.
    let initial = PtMotors {
        longitude_speed: 100.0,
        latitude_speed: 100.0,
        ..PtMotors::default()
    };
    let ptm = conf
        .ptmotors
        .then(|| ifs.provide_value::<PtMotors>("pantiltmotors", provider, initial))
        .transpose()?;
    let sonars = conf
        .sonars
        .then(|| ifs.provide::<Sonars>("sonars", provider))
        .transpose()?;
    let bumpers = conf
        .bumpers
        .then(|| ifs.provide::<Bumpers>("bumpers", provider))
        .transpose()?;
    let cams: Vec<Arc<Interface<Image>>> = conf
        .cameras
        .iter()
        .map(|c| ifs.provide_value(&c.iface, provider, Image::new(c.width, c.height)))
        .collect::<Result<_, _>>()?;
    let conf = Arc::new(conf);
    let url = conf.url();
    // One quick look at start: an absent NAOqi is said once, for every device.
    let absent = match qi::Conn::connect(&conf.host, conf.port, Duration::from_millis(1500)) {
        Ok(_) => None,
        Err(e) => Some(unreachable(&url, &e)),
    };
    let mut sups = Vec::new();
    if conf.has_body() {
        let mut interfaces: Vec<Arc<dyn AnyInterface>> = Vec::new();
        macro_rules! add {
            ($($i:ident),*) => { $( if let Some(i) = &$i { interfaces.push(i.clone()); } )* };
        }
        add!(motors, encoders, pte, ptm, sonars, bumpers);
        let mut how = Supervision {
            name: format!("{provider} body"),
            interfaces,
            on_demand: false,
            backoff: BACKOFF,
            absent: None,
        };
        if let Some(why) = &absent {
            let line = format!(
                "{}: driver {provider}: {why}; its interfaces stay stale until NAOqi answers (tried again every few seconds)",
                conf.at
            );
            how = how.absent_at_load(why.clone(), Some(line));
        }
        sups.push(Supervisor::start(
            how,
            Body {
                conf: conf.clone(),
                motors,
                encoders,
                pte,
                ptm,
                sonars,
                bumpers,
                source: Source::new(format!("{provider}: {url}")),
                watch: None,
                limits: None,
                last_odometry: None,
            },
        )?);
    }
    for (c, iface) in conf.cameras.iter().zip(cams) {
        let how = Supervision::camera(
            format!("{provider} {}", c.iface),
            iface.clone(),
            absent
                .as_ref()
                .filter(|_| !conf.has_body())
                .map(|why| Absent::new(&c.at, provider, why.clone(), "NAOqi answers")),
        );
        // With a body, its line said NAOqi is absent: the camera is only marked.
        let how = match (&absent, how.absent.is_some()) {
            (Some(why), false) => how.absent_at_load(why.clone(), None),
            _ => how,
        };
        sups.push(Supervisor::start(
            how,
            Camera {
                conf: conf.clone(),
                cam: c.clone(),
                iface,
                source: Source::new(format!("{provider}: {url} {}", c.iface)),
                handle: None,
            },
        )?);
    }
    Ok(sups)
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let c = NaoConf::parse(conf)?;
    Ok(Box::new(start(c, rt, &conf.name)?))
}

crate::register_driver!(
    Driver,
    "naobody",
    "a NAO robot through NAOqi (qi messaging over TCP): walk, head, camera, odometry, sonars, bumpers",
    create,
    lines = Lines
);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conf::Kind;

    fn parse(text: &str) -> anyhow::Result<NaoConf> {
        NaoConf::parse(&ComponentConf::from_text(Kind::Driver, "naobody", text).unwrap())
    }

    #[test]
    fn the_manuals_lines_parse() {
        let c = parse(
            "provides ptencoders\nprovides ptmotors\nprovides motors\nprovides varcolorA 0 320 240\nfps 10\n",
        )
        .unwrap();
        assert!(c.ptencoders && c.ptmotors && c.motors && !c.encoders);
        assert_eq!(c.cameras[0].resolution, 1);
        assert_eq!((c.url(), c.fps), ("tcp://127.0.0.1:9559".into(), 10));
        let c = parse("url tcp://nao.local:9600\nprovides colorB 1\n").unwrap();
        assert_eq!((c.host.as_str(), c.port), ("nao.local", 9600));
        assert_eq!((c.cameras[0].camera, c.cameras[0].width), (1, 320));
    }

    #[test]
    fn bad_lines_say_what_is_right() {
        for (text, expect) in [
            (
                "provides varcolorA 0 300 200\n",
                "160x120, 320x240, 640x480",
            ),
            (
                "provides varcolorA 2 320 240\n",
                "CAMERA (argument 2) is `2`, expected a whole number between 0 and 1",
            ),
            ("provides varcolorA 0\n", "CAMERA W H"),
            ("provides motors\nprovides motors\n", "provided twice"),
            ("provides laser\n", "usage"),
            ("url tcps://nao:9503\nprovides motors\n", "TLS"),
            (
                "url tcp://nao:9559\nhost nao\nprovides motors\n",
                "keep one",
            ),
            ("provides motors\nfps 0\n", "fps"),
            ("host x\n", "provides"),
        ] {
            let e = parse(text).err().map(|e| e.to_string()).unwrap_or_default();
            assert!(e.contains(expect), "{text}: {e}");
        }
    }

    #[test]
    fn odometry_and_head_readings_a_nao_cannot_give_are_refused() {
        let t0 = Instant::now();
        let t1 = t0 + Duration::from_millis(100);
        assert!(odometry_plausible(None, 1.0, 2.0, t0).is_ok());
        assert!(odometry_plausible(Some((1.0, 2.0, t0)), 1.05, 2.0, t1).is_ok());
        // 200 km: no NAO's, whatever came before.
        let e = odometry_plausible(None, 200_000.0, 0.0, t0).unwrap_err();
        assert!(e.contains("200 km"), "{e}");
        // A 3 m jump in 0.1 s.
        let e = odometry_plausible(Some((0.0, 0.0, t0)), 3.0, 0.0, t1).unwrap_err();
        assert!(e.contains("jumped 3.0 m"), "{e}");
        // The head: a NAO's limits without the robot's, the robot's when it told them.
        assert!(head_plausible([2.0, -0.5], None).is_ok());
        let e = head_plausible([6.0, 0.0], None).unwrap_err();
        assert!(e.contains("HeadYaw 6.00 rad"), "{e}");
        let tight = Joint {
            min: -0.2,
            max: 0.2,
            speed: 1.0,
        };
        assert!(head_plausible([0.0, 0.5], Some((tight, tight))).is_err());
    }

    #[test]
    fn walk_and_head_are_converted_and_limited() {
        assert_eq!(walk_args(50.0, 0.0, 100.0, 40.0, false), (0.05, 0.0));
        let (x, th) = walk_args(500.0, -90.0, 100.0, 40.0, false);
        assert_eq!(x, 0.1);
        assert!((th + 40f32.to_radians()).abs() < 1e-6);
        assert_eq!(walk_args(50.0, 20.0, 100.0, 40.0, true), (0.5, 0.5));
        assert_eq!(walk_args(f32::NAN, 0.0, 100.0, 40.0, false), (0.0, 0.0));
        let yaw = Joint {
            min: -2.0,
            max: 2.0,
            speed: 8.0,
        };
        let pitch = Joint {
            min: -0.6,
            max: 0.5,
            speed: 7.0,
        };
        let m = PtMotors {
            longitude: 200.0,
            latitude: 10.0,
            longitude_speed: 10_000.0,
            latitude_speed: 7f32.to_degrees() / 2.0,
            ..PtMotors::default()
        };
        let [(y, fy), (p, fp)] = head_targets(&m, yaw, pitch);
        assert_eq!((y, fy), (2.0, 1.0));
        assert!((p + 10f32.to_radians()).abs() < 1e-6 && (fp - 0.5).abs() < 1e-6);
    }

    #[test]
    fn absurd_replies_are_refused_and_shown_short() {
        // Booleans are not a pose; ALMemory's booleans are bumpers.
        let b = Value::List(vec![
            Value::Bool(true),
            Value::Bool(false),
            Value::Bool(true),
        ]);
        assert_eq!(numbers(&b, 3), None);
        assert_eq!(numbers_or_bools(&b, 3), Some(vec![1.0, 0.0, 1.0]));
        // getLimits of ±1e30 rad is refused; a NAO's are taken.
        let limits = |lo: f64, hi: f64, v: f64| {
            Value::List(vec![Value::List(vec![
                Value::Double(lo),
                Value::Double(hi),
                Value::Double(v),
                Value::Double(1.5),
            ])])
        };
        assert!(joint(&limits(-1e30, 1e30, 8.0)).is_none());
        assert!(joint(&limits(-2.0857, 2.0857, 1e9)).is_none());
        assert!(joint(&limits(-2.0857, 2.0857, 8.26797)).is_some());
        // A 30 MB value is shown by its first characters, at once.
        let huge = Value::Raw(vec![7; 30 << 20]);
        let t = std::time::Instant::now();
        let s = short(&huge);
        assert!(s.chars().count() <= qi::SHOW + 1 && s.ends_with('…'), "{s}");
        assert!(t.elapsed() < Duration::from_secs(1));
    }

    #[test]
    fn frames_are_checked_and_decoded() {
        let reply = |w: i64, h: i64, l: i64, cs: i64, data: Vec<u8>| {
            Value::List(vec![
                Value::Int(w),
                Value::Int(h),
                Value::Int(l),
                Value::Int(cs),
                Value::Int(1),
                Value::Int(2),
                Value::Raw(data),
                Value::Int(0),
            ])
        };
        let v = reply(2, 1, 3, K_RGB, vec![1, 2, 3, 4, 5, 6]);
        let f = frame(&v).unwrap();
        let mut out = Vec::new();
        to_bgr(&f, &mut out).unwrap();
        assert_eq!(out, vec![3, 2, 1, 6, 5, 4]);
        // YUV422 U Y V Y': grey (128 chroma) stays grey.
        let v = reply(2, 1, 2, K_YUV422, vec![128, 100, 128, 200]);
        to_bgr(&frame(&v).unwrap(), &mut out).unwrap();
        assert_eq!(out[0], out[2]);
        assert!(out[0] < out[3], "{out:?}");
        assert!(frame(&reply(2, 1, 3, K_BGR, vec![0; 5])).is_err());
        assert!(frame(&reply(100_000, 1, 3, K_BGR, vec![])).is_err());
        assert!(frame(&Value::Int(1)).is_err());
        let v = reply(2, 1, 1, 0, vec![0; 2]);
        assert!(
            to_bgr(&frame(&v).unwrap(), &mut out)
                .unwrap_err()
                .contains("colour space 0")
        );
    }
}
