//! gazebo (and `gazebo08`, the same driver under 4.3's second name): a robot and
//! its cameras in today's Gazebo (gz-sim: Fortress, Garden, Harmonic, Ionic)
//! through gz-transport. See `docs/gazebo.md` and `examples/gazebo.conf`.
//!
//! # Transport: a pure-Rust gz-transport node
//! gz-transport is UDP multicast discovery (a `Discovery` protobuf), ZeroMQ
//! PUB/SUB over TCP and protobuf payloads tagged with their type name. We speak
//! that wire ourselves ([`node`], [`zmtp`], [`pb`]) instead of binding the C++
//! libraries: the wire (discovery version 10) is the same from gz-transport 8 to
//! 13, so one build talks to Fortress (`ignition.msgs.*`, Debian 12's
//! libignition-transport11) and to Garden, Harmonic and Ionic (`gz.msgs.*`),
//! where bindings tie a build to one release's libraries (and the `gz` crates need
//! the C++ headers and a C++ build); the feature needs no system package and adds
//! one small crate (socket2) to the build. Measured here against the real
//! libignition-transport11: a Twist we publish reaches `ign-transport-topic -e`
//! and a C++ DiffDrive-like peer; its odometry, LaserScan and 640x480 Images reach
//! our interfaces (`tests/gazebo.rs`, `scripts/gazebo_bench.sh`).
//! Not spoken: unicast relays (`IGN_RELAY`), topic statistics
//! (`IGN_TRANSPORT_TOPIC_STATISTICS=1`: another wire version) and ZeroMQ
//! authentication (`IGN_TRANSPORT_USERNAME`); services are not needed.
//!
//! # Conf (4.3's lines; the second word is the model or sensor)
//! ```text
//! driver gazebo
//! provides laser lidar           # a LaserScan topic `/lidar`, or one with a `lidar` part
//!                                #   (.../sensor/lidar/scan); `provides laser lidar 180 1`: N R
//! provides motors robot1         # /model/robot1/cmd_vel (Twist), DiffDrive's
//! provides encoders robot1       # /model/robot1/odometry (Odometry), DiffDrive's
//! provides colorA camera         # an Image topic `/camera` (or with a `camera` part), 320x240
//! provides varcolorA /world/w/model/r/link/l/sensor/cam/image   # a topic: used as written
//! provides pantiltmotors robot1  # /model/robot1/joint/JOINT/0/cmd_pos (Double): pan and tilt
//! provides pantiltencoders robot1  # /world/WORLD/model/robot1/joint_state (Model)
//! provides imu imu               # an IMU topic `/imu`, or one with an `imu` part (the Imu system's)
//! joints pan_joint tilt_joint    # the pan-tilt's joints (defaults shown)
//! partition vm:root              # gz-transport's partition (default: IGN_PARTITION, else
//!                                #   GZ_PARTITION, else HOSTNAME:USERNAME as gz-transport's)
//! ip 127.0.0.1                   # the address for discovery and data (default: IGN_IP,
//!                                #   else GZ_IP, else the route's to 239.255.0.7)
//! messages auto                  # auto|ignition|gz: the type names we publish (auto: Gazebo's)
//! motors_timeout 500             # ms: an older motors command counts as zero
//! cycle 100                      # ms: how often cmd_vel is sent
//! wait 5000                      # ms: then a missing model or sensor lists the topics there are
//! end_driver
//! ```
//!
//! # Interfaces (4.3's units)
//! | interface | topic, type | conversion |
//! |---|---|---|
//! | `encoders` | `/model/NAME/odometry`, Odometry | x, y m → mm; θ = yaw, (0, 2π] |
//! | `motors` | `/model/NAME/cmd_vel`, Twist | v mm/s → linear.x m/s, w deg/s → angular.z rad/s, limited ±1000 mm/s, ±180 deg/s; sent every `cycle`; zero when older than `motors_timeout`, when Gazebo is lost and when the driver stops |
//! | `laser` | LaserScan | N (180) readings at R (1) per degree: reading i at −N/(2R) + i/R deg, the nearest ray; no hit or outside the scan: range_max; mm |
//! | `colorA..D` | Image | RGB, BGR, RGBA, BGRA or L 8-bit → BGR, scaled (nearest) to 320x240 |
//! | `varcolorA..D` | Image | the same at the camera's size |
//! | `pantiltencoders` | JointStatePublisher's Model | the joints' axis1 positions rad → deg |
//! | `pantiltmotors` | JointPositionController's cmd_pos, Double, per joint | longitude, latitude deg (within the interface's limits) → rad, every `cycle` (speeds are the controller's) |
//! | `imu` | the Imu system's IMU | SI as Gazebo sends them: orientation quaternion qx qy qz qw, angular velocity wx wy wz rad/s, linear acceleration (specific force: +9.8 up at rest) ax ay az m/s² |
//!
//! Gazebo's simulation time (each message's header stamp) is each value's `time`
//! (seconds since the epoch = seconds of simulation).
//!
//! # Behaviour
//! The driver is a [`Supervisor`]'s device. At start it listens for up to 1.2 s
//! (discovery takes 0.5–1 s); what is missing is said in one line naming the
//! topics awaited, the interfaces stay stale, and each binds when its topic
//! appears. When Gazebo goes away (its processes say BYE, fall silent for 3 s, or
//! their connections close) the interfaces turn stale with the reason, the motors
//! interface and cmd_vel go to zero, and it all resumes when Gazebo is back. A
//! model or sensor still missing after `wait` is said with the list of topics
//! that do exist; a topic published under a type we do not read is an error
//! naming both types. Type names must match exactly for gz-transport to deliver,
//! so what we publish uses the namespace Gazebo's own topics show (`messages`).
//!
//! # The stop
//! A zero Twist on each motors topic when the driver stops, when Gazebo is lost
//! (to the subscribers still connected), and whenever the process ends or is
//! suspended: registered with [`crate::estop`] (SIGINT, SIGTERM, SIGHUP, Ctrl+Z,
//! an abort and a panic run it first), it is written to each cmd_vel
//! subscriber's connection through a second handle (the list is swapped in
//! whole when subscribers change: no lock). The connections are non-blocking and
//! the stop is one write: were a subscriber's connection full (a subscriber far
//! behind), the stop is cut short and may split a message, and ZeroMQ drops that
//! connection. After [`crate::estop::halted`] the driver sends only zero. What
//! nothing can catch (`kill -9`, power loss) sends nothing: see docs/gazebo.md.

pub mod node;
pub mod pb;
pub mod zmtp;

use std::{
    io::Write,
    sync::Arc,
    time::{Duration, Instant, SystemTime},
};

use arc_swap::ArcSwap;

use crate::{
    conf::{
        ComponentConf, ConfError, ConfLine,
        settings::{
            COLOR, CYCLE, Form, MOTORS_TIMEOUT, Setting, VARCOLOR, choice, float, int, kinds, word,
        },
    },
    estop,
    interfaces::{
        AnyInterface, COLOR_HEIGHT, COLOR_WIDTH, Encoders, Image, Imu, Interface, Interfaces,
        Kind as IfaceKind, Laser, LaserMap, Motors, PtEncoders, PtMotors, Source, limit,
    },
    runtime::{self, Backoff, Driver, Runtime, Supervision, Supervisor},
};

use node::{Node, both};

/// 4.3's Pioneer limits.
pub const MAX_V: f32 = 1000.0;
pub const MAX_W: f32 = 180.0;

const USAGE: &str = "provides encoders|motors|pantiltencoders|pantiltmotors MODEL, provides laser SENSOR [N R], provides imu SENSOR, \
provides colorA..D|varcolorA..D SENSOR, or any of them with a /topic instead of the name";

crate::declare_lines! {
    /// The driver's lines (`jderobot help gazebo`).
    struct Lines {
        provides: Vec<ProvidesLine> = Setting::forms(
            "provides",
            USAGE,
            &[
                Form::new(
                    "device",
                    "a model's odometry, cmd_vel or pan-tilt joints, or an IMU sensor",
                    &[
                        kinds(
                            "INTERFACE",
                            &[
                                IfaceKind::Encoders,
                                IfaceKind::Motors,
                                IfaceKind::PtEncoders,
                                IfaceKind::PtMotors,
                                IfaceKind::Imu,
                            ],
                        ),
                        word("MODEL|SENSOR|/TOPIC"),
                    ],
                ),
                Form::new(
                    "laser",
                    "a lidar sensor's scan: N readings at R per degree (default 180 at 1)",
                    &[
                        kinds("laser", &[IfaceKind::Laser]),
                        word("SENSOR|/TOPIC"),
                        int("N", "", 1, 3600).optional(),
                        float("R", "readings/deg", 0.01, 100.0),
                    ],
                ),
                Form::new("color", "a camera sensor at 320x240", &[COLOR, word("SENSOR|/TOPIC")]),
                Form::new(
                    "varcolor",
                    "a camera sensor at its own size",
                    &[VARCOLOR, word("SENSOR|/TOPIC")],
                ),
            ],
        )
        .repeats()
        .required(),
        partition: Option<String> = Setting::new(
            "partition",
            "gz-transport's partition (default: IGN_PARTITION, else GZ_PARTITION, else HOSTNAME:USERNAME)",
            &[word("NAME")],
        ),
        ip: Option<String> = Setting::new(
            "ip",
            "the IPv4 address for discovery and data (default: IGN_IP, else GZ_IP, else the route's)",
            &[word("IPV4")],
        ),
        messages: String = Setting::new(
            "messages",
            "the type names published: ignition.msgs.* (Fortress), gz.msgs.* (Garden and later), or auto: those Gazebo's topics show",
            &[choice("NAMESPACE", &["auto", "ignition", "gz"])],
        )
        .default("auto"),
        motors_timeout: u64 = MOTORS_TIMEOUT,
        cycle: u64 = CYCLE.help("how often cmd_vel is sent").default("100"),
        joints: Vec<String> = Setting::new(
            "joints",
            "the pan-tilt head's joints (JointPositionController's, JointStatePublisher's)",
            &[word("PAN"), word("TILT")],
        )
        .default("pan_joint tilt_joint"),
        wait: u64 = Setting::new(
            "wait",
            "how long a model or sensor may be missing before the topics that exist are listed",
            &[int("MS", "ms", 100, 600_000)],
        )
        .default("5000"),
    }
}
/// What a `provides` line gives.
#[derive(Clone, Debug, PartialEq)]
pub enum Kind {
    Encoders,
    Motors,
    /// N readings at R per degree.
    Laser(usize, f64),
    /// Fixed at 320x240 (colorA..D)?
    Camera(bool),
    PtEncoders,
    PtMotors,
    Imu,
}

impl Kind {
    /// The gz-msgs message it reads or writes.
    fn msg(&self) -> &'static str {
        match self {
            Kind::Encoders => "Odometry",
            Kind::Motors => "Twist",
            Kind::Laser(..) => "LaserScan",
            Kind::Camera(_) => "Image",
            Kind::PtEncoders => "Model",
            Kind::PtMotors => "Double",
            Kind::Imu => "IMU",
        }
    }
}

/// One `provides` line.
#[derive(Clone, Debug)]
pub struct Want {
    pub iface: String,
    pub kind: Kind,
    /// A topic (`/…`, used as written) or a model/sensor name.
    pub target: String,
    pub at: String,
}

impl Want {
    /// The topic, when the line fixes it (a `/topic`, or DiffDrive's model topics).
    pub fn fixed_topic(&self) -> Option<String> {
        if self.target.starts_with('/') {
            return Some(self.target.clone());
        }
        match self.kind {
            Kind::Encoders => Some(format!("/model/{}/odometry", self.target)),
            Kind::Motors => Some(format!("/model/{}/cmd_vel", self.target)),
            _ => None,
        }
    }
}

/// The driver's settings.
#[derive(Clone, Debug)]
pub struct GzConf {
    pub wants: Vec<Want>,
    pub partition: String,
    pub ip: String,
    /// None: auto.
    pub namespace: Option<String>,
    pub motors_timeout: Duration,
    pub cycle: Duration,
    pub wait: Duration,
    /// The pan and tilt joints.
    pub joints: (String, String),
}

/// A `provides` line in its declared form: the interface, what it names (a
/// model, a sensor or a `/topic`) and, for a laser, N and R.
#[derive(serde::Deserialize)]
enum ProvidesLine {
    #[serde(rename = "device")]
    Device(IfaceKind, String),
    #[serde(rename = "laser")]
    Laser(IfaceKind, String, Option<usize>, Option<f64>),
    #[serde(rename = "color")]
    Color(String, String),
    #[serde(rename = "varcolor")]
    Varcolor(String, String),
}

/// What line `l` (read as `p`) wants.
fn want(p: ProvidesLine, l: &ConfLine) -> Result<Want, ConfError> {
    let (iface, kind, target) = match p {
        ProvidesLine::Device(k, target) => {
            let kind = match k {
                IfaceKind::Encoders => Kind::Encoders,
                IfaceKind::Motors => Kind::Motors,
                IfaceKind::PtEncoders => Kind::PtEncoders,
                IfaceKind::PtMotors => Kind::PtMotors,
                IfaceKind::Imu => Kind::Imu,
                other => {
                    return Err(l.error(format!(
                        "`provides {other}`: the gazebo driver gives encoders, motors, laser, imu, \
                         colorA..D, varcolorA..D, pantiltencoders and pantiltmotors (gz-sim has no \
                         sonars or bumpers); usage: {USAGE}"
                    )));
                }
            };
            (k.name().to_string(), kind, target)
        }
        ProvidesLine::Laser(k, target, n, r) => {
            let kind = Kind::Laser(n.unwrap_or(180), r.unwrap_or(1.0));
            (k.name().to_string(), kind, target)
        }
        ProvidesLine::Color(name, target) => (name, Kind::Camera(true), target),
        ProvidesLine::Varcolor(name, target) => (name, Kind::Camera(false), target),
    };
    if matches!(kind, Kind::PtMotors) && target.starts_with('/') {
        return Err(l.error(format!(
            "`provides pantiltmotors` takes the model's name (its joints' cmd_pos topics follow \
             from it and `joints`), not a topic; usage: {USAGE}"
        )));
    }
    Ok(Want {
        iface,
        kind,
        target,
        at: l.at.to_string(),
    })
}

/// A set, non-empty environment variable.
fn env(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.is_empty())
}

impl GzConf {
    pub fn parse(conf: &ComponentConf) -> anyhow::Result<GzConf> {
        let lines: Lines = conf.read()?;
        let mut wants: Vec<Want> = Vec::new();
        for (l, p) in conf.lines_with("provides").zip(lines.provides) {
            let w = want(p, l)?;
            if wants.iter().any(|x| x.iface == w.iface) {
                return Err(l
                    .error(format!("interface `{}` is provided twice", w.iface))
                    .into());
            }
            wants.push(w);
        }
        let partition = lines
            .partition
            .or_else(|| env("IGN_PARTITION"))
            .or_else(|| env("GZ_PARTITION"))
            .unwrap_or_else(node::default_partition);
        if let Some(ip) = &lines.ip
            && ip.parse::<std::net::Ipv4Addr>().is_err()
        {
            let l = conf.line("ip").expect("the line was read");
            return Err(l
                .error(format!(
                    "`ip {ip}`: expected an IPv4 address of this host, such as 127.0.0.1"
                ))
                .into());
        }
        Ok(GzConf {
            wants,
            partition,
            ip: node::choose_ip(lines.ip.as_deref()),
            namespace: (lines.messages != "auto").then_some(lines.messages),
            motors_timeout: Duration::from_millis(lines.motors_timeout),
            cycle: Duration::from_millis(lines.cycle),
            wait: Duration::from_millis(lines.wait),
            joints: (
                lines.joints.first().cloned().unwrap_or_default(),
                lines.joints.get(1).cloned().unwrap_or_default(),
            ),
        })
    }
}

/// Where a line's data goes.
enum Sink {
    Encoders(Arc<Interface<Encoders>>),
    Laser(Arc<Interface<Laser>>, LaserMap),
    Camera(Arc<Interface<Image>>, bool),
    Motors(Arc<Interface<Motors>>),
    /// The pan and tilt joints' names.
    PtEncoders(Arc<Interface<PtEncoders>>, String, String),
    /// The tilt joint's cmd_pos topic (the pan's is the line's topic).
    PtMotors(Arc<Interface<PtMotors>>, String),
    Imu(Arc<Interface<Imu>>),
}

impl Sink {
    /// Whether we publish it (a subscriber serves it).
    fn output(&self) -> bool {
        matches!(self, Sink::Motors(_) | Sink::PtMotors(..))
    }
}

/// One line at run time.
struct Line {
    want: Want,
    sink: Sink,
    /// The topic, once known.
    topic: Option<String>,
    /// Whether the topic was found by searching (not fixed by the line): it is
    /// searched again when its publisher leaves or fails.
    searched: bool,
    /// Topics found that failed (left, silent, bad), tried last; and the
    /// subscription's failures counted so far.
    failed: Vec<String>,
    failures: u64,
    /// Its subscription in the node (inputs).
    sub: Option<usize>,
    source: Source,
}

/// The device: the node and the lines.
struct Gz {
    node: Node,
    lines: Vec<Line>,
    gc: GzConf,
    started: Instant,
    next_cmd: Instant,
    twist: Vec<u8>,
    /// The namespace of the type names we publish.
    ns: String,
    /// The node's [`changes`](Node::changes) at the last [`resolve`](Self::resolve).
    resolved: Option<u64>,
    name: String,
    /// The stop's targets (read by [`estop`] without a lock) and what they were
    /// made from: the subscribers' changes and the Twist's type name.
    stops: Stops,
    stops_of: Option<(u64, String)>,
}

/// Each cmd_vel subscriber's connection (a second handle) and the zero Twists
/// it is to get, framed.
type Stops = Arc<ArcSwap<Vec<(std::net::TcpStream, Vec<u8>)>>>;

/// The topic a line that names a model or sensor reads: of the right type, named
/// `/NAME` (first) or with a part `NAME` (a joint state: `.../model/NAME/joint_state`),
/// not one of `avoid`.
fn search(want: &Want, known: &[(String, Vec<String>)], avoid: &[String]) -> Option<String> {
    let accept = both(want.kind.msg());
    let name = &want.target;
    let joint_state = format!("/model/{name}/joint_state");
    let pt = matches!(want.kind, Kind::PtEncoders);
    let fits = |(t, tys): &&(String, Vec<String>)| {
        !avoid.contains(t)
            && tys.iter().any(|ty| accept.contains(ty))
            && if pt {
                t.ends_with(&joint_state)
            } else {
                t.split('/').any(|part| part == name)
            }
    };
    let exact = format!("/{name}");
    known
        .iter()
        .filter(fits)
        .find(|(t, _)| *t == exact)
        .or_else(|| known.iter().find(fits))
        .map(|(t, _)| t.clone())
}

/// The farthest range a scan may say, m (1 km: beyond any lidar).
pub const MAX_RANGE_M: f64 = 1000.0;
/// The most rays a scan may have.
pub const MAX_RAYS: usize = 1 << 20;

/// Checks a LaserScan before it reaches the interface: rays there are, a finite
/// geometry, range_max and every finite range within 0..[`MAX_RANGE_M`] (no
/// return is inf or NaN, as Gazebo sends it).
pub fn check_scan(s: &pb::Scan) -> Result<(), String> {
    let n = s.n();
    if n == 0 {
        return Err("an empty scan (no ranges)".into());
    }
    if n > MAX_RAYS {
        return Err(format!("a scan of {n} rays (at most {MAX_RAYS})"));
    }
    let tau = std::f64::consts::TAU;
    if !s.angle_min.is_finite() || s.angle_min.abs() > 2.0 * tau {
        return Err(format!("angle_min {} rad", s.angle_min));
    }
    if !s.angle_step.is_finite() || s.angle_step == 0.0 || s.angle_step.abs() > tau {
        return Err(format!("angle_step {} rad", s.angle_step));
    }
    if !(s.range_max.is_finite() && s.range_max > 0.0 && s.range_max <= MAX_RANGE_M) {
        return Err(format!(
            "range_max {} m (a lidar's is in (0, {MAX_RANGE_M}] m)",
            s.range_max
        ));
    }
    if let Some(k) = (0..n).find(|&k| {
        let r = s.range(k);
        r.is_finite() && !(0.0..=MAX_RANGE_M).contains(&r)
    }) {
        return Err(format!(
            "range {k} is {} m (ranges are in [0, {MAX_RANGE_M}] m, or inf for no return)",
            s.range(k)
        ));
    }
    Ok(())
}

/// Fills `out` (mm, 4.3's N readings at R per degree) from a LaserScan.
pub fn laser(map: &mut LaserMap, s: &pb::Scan, out: &mut Laser) {
    map.fill(
        s.angle_min,
        s.angle_step,
        s.n(),
        s.range_max,
        |k| s.range(k),
        out,
    );
}

/// Checks an Image message's layout: (width, height, bytes per pixel, row step).
pub fn image_layout(f: &pb::Frame) -> Result<(usize, usize, usize, usize), String> {
    let bpp = match f.format {
        pb::pixel::L_INT8 => 1,
        pb::pixel::RGB_INT8 | pb::pixel::BGR_INT8 => 3,
        pb::pixel::RGBA_INT8 | pb::pixel::BGRA_INT8 => 4,
        other => {
            return Err(format!(
                "pixel format {other} is not read (8-bit L, RGB, BGR, RGBA, BGRA are)"
            ));
        }
    };
    let (w, h) = (f.width as usize, f.height as usize);
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("image size {w}x{h}"));
    }
    let step = if f.step == 0 {
        w * bpp
    } else {
        f.step as usize
    };
    if step < w * bpp || f.data.len() < step * (h - 1) + w * bpp {
        return Err(format!(
            "{w}x{h} image with step {step} has {} bytes of data",
            f.data.len()
        ));
    }
    Ok((w, h, bpp, step))
}

/// An Image message into a BGR image (`fixed`: scaled to 320x240); a bad
/// layout is an error and leaves `out` as it was.
pub fn fill_image(f: &pb::Frame, fixed: bool, out: &mut Image) -> Result<(), String> {
    let (w, h, bpp, step) = image_layout(f)?;
    let (ow, oh) = if fixed {
        (COLOR_WIDTH as usize, COLOR_HEIGHT as usize)
    } else {
        (w, h)
    };
    out.width = ow as u32;
    out.height = oh as u32;
    out.data.resize(ow * oh * 3, 0);
    let swap = matches!(f.format, pb::pixel::RGB_INT8 | pb::pixel::RGBA_INT8);
    for y in 0..oh {
        let sy = if oh == h { y } else { y * h / oh };
        let row = &f.data[sy * step..sy * step + w * bpp];
        let dst = &mut out.data[y * ow * 3..(y + 1) * ow * 3];
        if ow == w && bpp == 3 {
            if swap {
                for (d, s) in dst.chunks_exact_mut(3).zip(row.chunks_exact(3)) {
                    d[0] = s[2];
                    d[1] = s[1];
                    d[2] = s[0];
                }
            } else {
                dst.copy_from_slice(row);
            }
            continue;
        }
        for x in 0..ow {
            let sx = if ow == w { x } else { x * w / ow };
            let s = &row[sx * bpp..sx * bpp + bpp];
            let d = &mut dst[x * 3..x * 3 + 3];
            if bpp == 1 {
                d.fill(s[0]);
            } else if swap {
                d.copy_from_slice(&[s[2], s[1], s[0]]);
            } else {
                d.copy_from_slice(&s[..3]);
            }
        }
    }
    Ok(())
}

fn sim_time(t: Option<f64>) -> SystemTime {
    match t {
        Some(t) if (0.0..1e12).contains(&t) => SystemTime::UNIX_EPOCH + Duration::from_secs_f64(t),
        _ => SystemTime::now(),
    }
}

/// Feeds one message of subscription `sub` to its line.
/// Feeds one message of subscription `sub` to its line. Its type-name frame
/// must be the line's message (Odometry bytes on the lidar topic are refused),
/// and a value out of range is refused with a line, never reaching the interface.
fn feed(lines: &mut [Line], sub: usize, data: &[u8], ty: &str) {
    let Some(l) = lines.iter_mut().find(|l| l.sub == Some(sub)) else {
        return;
    };
    let src = &l.source;
    let msg = l.want.kind.msg();
    if ty
        .strip_prefix("ignition.msgs.")
        .or_else(|| ty.strip_prefix("gz.msgs."))
        != Some(msg)
    {
        let ty: String = ty.chars().take(80).collect();
        src.refused(format_args!(
            "a message of type `{ty}` on a topic of {msg}: refused"
        ));
        return;
    }
    let r = match &mut l.sink {
        Sink::Encoders(i) => pb::decode_odometry(data).map(|o| {
            if !(o.x.abs() <= 1e6 && o.y.abs() <= 1e6 && o.yaw.is_finite()) {
                src.refused(format_args!(
                    "odometry at ({}, {}) m, yaw {} rad: beyond 1000 km or not finite",
                    o.x, o.y, o.yaw
                ));
                return;
            }
            let e = Encoders::from_pose((o.x * 1000.0) as f32, (o.y * 1000.0) as f32, o.yaw as f32);
            src.note(i.write_recorded(i.clock() + 1, sim_time(o.time), |v| *v = e));
        }),
        Sink::Laser(i, m) => pb::decode_scan(data).map(|s| {
            if let Err(e) = check_scan(&s) {
                src.refused(format_args!("scan refused: {e}"));
                return;
            }
            src.note(i.write_recorded(i.clock() + 1, sim_time(s.time), |l| laser(m, &s, l)));
        }),
        Sink::Camera(i, fixed) => pb::decode_image(data).map(|f| {
            // Checked first: a refused frame never touches the interface.
            if let Err(e) = image_layout(&f) {
                src.refused(format_args!("camera frame refused: {e}"));
                return;
            }
            let r = i.write_recorded(i.clock() + 1, sim_time(f.time), |img| {
                let _ = fill_image(&f, *fixed, img);
            });
            src.note(r);
        }),
        Sink::PtEncoders(i, pan, tilt) => pb::decode_joints(data).map(|(time, joints)| {
            let at = |name: &str| {
                joints
                    .iter()
                    .find(|(n, _)| n == name)
                    .map(|(_, p)| p.to_degrees() as f32)
            };
            if let (Some(p), Some(t)) = (at(pan), at(tilt)) {
                let v = PtEncoders {
                    pan_angle: p,
                    tilt_angle: t,
                };
                src.note(i.write_recorded(i.clock() + 1, sim_time(time), |x| *x = v));
            } else {
                src.refused(format_args!(
                    "the joint state has no joints `{pan}` and `{tilt}` (set `joints PAN TILT`)"
                ));
            }
        }),
        Sink::Imu(i) => pb::decode_imu(data).map(|m| {
            let f = |x: f64| x as f32;
            let v = Imu::from_fields([
                f(m.q[0]),
                f(m.q[1]),
                f(m.q[2]),
                f(m.q[3]),
                f(m.w[0]),
                f(m.w[1]),
                f(m.w[2]),
                f(m.a[0]),
                f(m.a[1]),
                f(m.a[2]),
            ]);
            src.note(i.write_recorded(i.clock() + 1, sim_time(m.time), |x| *x = v));
        }),
        Sink::Motors(_) | Sink::PtMotors(..) => Ok(()),
    };
    if let Err(e) = r {
        src.refused(format_args!("a malformed {ty} message: {e}"));
    }
}

impl Gz {
    /// The type name we publish `msg` under (`ignition.msgs.Twist`).
    fn msg_type(&self, msg: &str) -> String {
        format!("{}.msgs.{msg}", self.ns)
    }

    /// Subscribes the lines whose topic is known or can now be found.
    fn resolve(&mut self) {
        // Nothing to look at again while the node's knowledge has not moved.
        let changes = self.node.changes;
        if self.resolved == Some(changes) {
            return;
        }
        self.resolved = Some(changes);
        let known = self.node.known();
        for l in &mut self.lines {
            if l.topic.is_none() {
                l.topic = l.want.fixed_topic();
                if l.topic.is_none() {
                    l.topic = search(&l.want, &known, &[]);
                    l.searched = l.topic.is_some();
                }
            } else if let (true, Some(s), Some(t)) = (l.searched, l.sub, l.topic.clone()) {
                // Searched again when the chosen topic's publisher left or failed (a
                // decoy advertised before Gazebo), preferring topics not failed yet.
                let w = &self.node.wants[s];
                if w.bound.is_none() {
                    let gone = !known.iter().any(|(k, _)| *k == t);
                    if w.failures > l.failures || gone {
                        l.failures = w.failures;
                        if l.failed.len() >= 16 {
                            l.failed.remove(0);
                        }
                        if !l.failed.contains(&t) {
                            l.failed.push(t.clone());
                        }
                        if let Some(n) = search(&l.want, &known, &l.failed)
                            .or_else(|| search(&l.want, &known, &[]))
                            && n != t
                        {
                            tracing::info!(
                                "{}: {t} left or failed; {} now reads {n}",
                                self.name,
                                l.want.iface
                            );
                            self.node.retopic(s, &n);
                            l.failures = self.node.wants[s].failures;
                            l.topic = Some(n);
                        }
                    }
                } else if w.got_data {
                    l.failed.clear();
                }
            }
            if let (Some(t), None, false) = (&l.topic, l.sub, l.sink.output()) {
                l.sub = Some(self.node.want(t, both(l.want.kind.msg())));
            }
        }
        // The namespace of what we publish: Gazebo's, as its topics show.
        if self.gc.namespace.is_none() {
            let seen = self
                .node
                .wants
                .iter()
                .filter_map(|w| w.bound.as_ref().map(|b| b.msg_type.clone()))
                .chain(known.iter().flat_map(|(_, t)| t.clone()))
                .find(|t| t.starts_with("gz.msgs.") || t.starts_with("ignition.msgs."));
            if let Some(t) = seen {
                let ns = if t.starts_with("gz.") {
                    "gz"
                } else {
                    "ignition"
                };
                if ns != self.ns {
                    self.ns = ns.into();
                    tracing::info!(
                        "{}: Gazebo uses {ns}.msgs.* type names; publishing them",
                        self.name
                    );
                }
            }
        }
        let (twist, double) = (self.msg_type("Twist"), self.msg_type("Double"));
        for l in &self.lines {
            match (&l.sink, &l.topic) {
                (Sink::Motors(_), Some(t)) => self.node.advertise(t, &twist),
                (Sink::PtMotors(_, tilt), Some(pan)) => {
                    self.node.advertise(pan, &double);
                    self.node.advertise(tilt, &double);
                }
                _ => {}
            }
        }
    }

    /// Whether line `l` is served (its publisher bound, or for motors, a subscriber there).
    fn served(&self, l: &Line) -> bool {
        match (&l.sink, &l.topic, l.sub) {
            (Sink::Motors(_), Some(t), _) => self.node.has_subscriber(&self.node.qualify(t)),
            (Sink::PtMotors(_, tilt), Some(pan), _) => {
                self.node.has_subscriber(&self.node.qualify(pan))
                    && self.node.has_subscriber(&self.node.qualify(tilt))
            }
            (_, _, Some(s)) => self.node.wants[s].bound.is_some(),
            _ => false,
        }
    }

    /// What is still missing, in words.
    fn missing(&self) -> Vec<String> {
        let mut out = Vec::new();
        for l in &self.lines {
            if self.served(l) {
                continue;
            }
            let msg = l.want.kind.msg();
            let what = match (&l.topic, &l.sink) {
                (Some(t), Sink::Motors(_)) => format!("{t} (a {msg} subscriber: DiffDrive)"),
                (Some(t), Sink::PtMotors(_, tilt)) => {
                    format!("{t} and {tilt} (Double subscribers: JointPositionController)")
                }
                (None, Sink::PtEncoders(..)) => format!(
                    "a Model topic /world/WORLD/model/{}/joint_state (JointStatePublisher)",
                    l.want.target
                ),
                (Some(t), _) => format!("{t} ({msg})"),
                (None, _) => format!(
                    "{} {msg} topic named /{n} or with a part `{n}`",
                    if msg.starts_with(['A', 'E', 'I', 'O', 'U']) {
                        "an"
                    } else {
                        "a"
                    },
                    n = l.want.target
                ),
            };
            if let Some(s) = l.sub
                && let Some(bad) = &self.node.wants[s].mismatch
            {
                out.push(format!(
                    "{} is published as {bad}, but {} reads {} (wrong message type)",
                    l.topic.as_deref().unwrap_or("?"),
                    l.want.iface,
                    both(msg).join(" or ")
                ));
                continue;
            }
            if !out.contains(&what) {
                out.push(what);
            }
        }
        out
    }

    /// Why the driver is not up, for the log and the stale interfaces.
    fn reason(&self) -> String {
        let missing = self.missing().join(", ");
        let known = self.node.known();
        if known.is_empty() {
            format!(
                "{}: no Gazebo in partition `{}` on {}: waiting for {missing}",
                self.name, self.gc.partition, self.node.ip
            )
        } else if self.started.elapsed() >= self.gc.wait {
            let list: Vec<String> = known
                .iter()
                .map(|(t, ty)| format!("{t} ({})", ty.join("|")))
                .collect();
            format!(
                "{}: after {:.0} s still no {missing} (an unknown model or sensor?); the topics \
                 that exist in partition `{}`: {}",
                self.name,
                self.gc.wait.as_secs_f64(),
                self.gc.partition,
                list.join(", ")
            )
        } else {
            format!("{}: waiting for {missing}", self.name)
        }
    }

    fn all_served(&self) -> bool {
        self.lines.iter().all(|l| self.served(l))
    }

    fn pump(&mut self, wait: Duration) {
        let lines = &mut self.lines;
        self.node.pump(wait, &mut |s, d, ty| feed(lines, s, d, ty));
    }

    /// Sends each motors command (zero if `zero`), and the pan-tilt's position
    /// (not when `zero`: the head stays where it is).
    fn commands(&mut self, zero: bool) {
        let ty = self.msg_type("Twist");
        let double = self.msg_type("Double");
        for k in 0..self.lines.len() {
            if let (Sink::PtMotors(m, tilt), Some(pan), false) =
                (&self.lines[k].sink, &self.lines[k].topic, zero)
            {
                let c = m.snapshot();
                let p = limit(c.longitude, c.min_longitude, c.max_longitude);
                let t = limit(c.latitude, c.min_latitude, c.max_latitude);
                for (topic, deg) in [(pan.clone(), p), (tilt.clone(), t)] {
                    pb::encode_double((deg as f64).to_radians(), &mut self.twist);
                    let fq = self.node.qualify(&topic);
                    self.node.publish(&fq, &double, &self.twist);
                }
                continue;
            }
            let (Sink::Motors(m), Some(t)) = (&self.lines[k].sink, &self.lines[k].topic) else {
                continue;
            };
            // Once the process is ending (estop::halt), nothing but zero.
            let c = if zero || estop::halted() {
                Motors::default()
            } else {
                let c = m.command(self.gc.motors_timeout);
                Motors::limited(c.v, c.w, MAX_V, MAX_W)
            };
            pb::encode_twist(
                c.v as f64 / 1000.0,
                (c.w as f64).to_radians(),
                &mut self.twist,
            );
            let fq = self.node.qualify(t);
            self.node.publish(&fq, &ty, &self.twist);
        }
    }

    /// Makes the stop's targets again when the subscribers or the type changed:
    /// a zero Twist on each motors line's topic, to each subscriber of it.
    fn refresh_stops(&mut self) {
        let key = (self.node.subscriber_changes(), self.msg_type("Twist"));
        if self.stops_of.as_ref() == Some(&key) {
            return;
        }
        let mut zero = Vec::new();
        pb::encode_twist(0.0, 0.0, &mut zero);
        let msgs: Vec<(String, String, Vec<u8>)> = self
            .lines
            .iter()
            .filter(|l| matches!(l.sink, Sink::Motors(_)))
            .filter_map(|l| l.topic.as_ref())
            .map(|t| (self.node.qualify(t), key.1.clone(), zero.clone()))
            .collect();
        self.stops.store(Arc::new(self.node.stop_targets(&msgs)));
        self.stops_of = Some(key);
    }

    /// Listens up to `max` until every line is served.
    fn settle(&mut self, max: Duration) -> bool {
        let end = Instant::now() + max;
        loop {
            self.resolve();
            if self.all_served() {
                return true;
            }
            let left = end.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            self.pump(left.min(Duration::from_millis(50)));
        }
    }
}

impl runtime::Device for Gz {
    type Session = ();

    fn open(&mut self) -> Result<(), String> {
        if !self.settle(Duration::from_millis(1000)) {
            return Err(self.reason());
        }
        self.next_cmd = Instant::now();
        // Back: a command reaches DiffDrive again (the driver never publishes
        // motors, so nothing else would clear its stale mark).
        for l in &self.lines {
            if let Sink::Motors(m) = &l.sink {
                m.clear_stale();
            }
        }
        Ok(())
    }

    fn step(&mut self, _: &mut ()) -> Result<(), String> {
        let now = Instant::now();
        if now >= self.next_cmd {
            self.commands(false);
            self.next_cmd += self.gc.cycle;
            if self.next_cmd < now {
                self.next_cmd = now + self.gc.cycle;
            }
        }
        let wait = self
            .next_cmd
            .saturating_duration_since(Instant::now())
            .min(Duration::from_millis(50));
        self.pump(wait);
        self.resolve();
        self.refresh_stops();
        if !self.all_served() {
            let why = format!(
                "{}: lost Gazebo (no {}: {}); motors zero, waiting for it to come back",
                self.name,
                self.missing().join(", "),
                if self.node.last_loss.is_empty() {
                    "a subscriber left"
                } else {
                    &self.node.last_loss
                }
            );
            return Err(why);
        }
        Ok(())
    }

    fn on_loss(&mut self) {
        self.commands(true);
        for l in &self.lines {
            if let Sink::Motors(m) = &l.sink {
                let _ = m.publish(Motors::default());
            }
        }
    }

    /// The driver stops: zero to DiffDrive, a moment for it to leave, goodbye.
    fn close(&mut self, _: ()) {
        self.commands(true);
        let end = Instant::now() + Duration::from_millis(200);
        while Instant::now() < end {
            self.pump(Duration::from_millis(20));
        }
        self.node.bye();
    }
}

/// The running driver.
pub struct GazeboDriver {
    sup: Supervisor,
    motors: Vec<Arc<Interface<Motors>>>,
    _estop: Option<estop::Registration>,
}

impl Driver for GazeboDriver {
    fn terminate(&mut self) {
        self.sup.stop();
        for m in &self.motors {
            let _ = m.publish(Motors::default());
        }
    }
}

impl Drop for GazeboDriver {
    fn drop(&mut self) {
        self.terminate();
    }
}

/// Provides the interface a `provides` line asks for, and the sink its
/// messages go to (sensors are added to `all`, motors to `motors`).
fn provide(
    w: &Want,
    gc: &GzConf,
    ifaces: &Interfaces,
    provider: &str,
    all: &mut Vec<Arc<dyn AnyInterface>>,
    motors: &mut Vec<Arc<Interface<Motors>>>,
) -> anyhow::Result<Sink> {
    Ok(match &w.kind {
        Kind::Encoders => {
            let i = ifaces.provide::<Encoders>(&w.iface, provider)?;
            all.push(i.clone());
            Sink::Encoders(i)
        }
        Kind::Motors => {
            let i = ifaces.provide::<Motors>(&w.iface, provider)?;
            motors.push(i.clone());
            Sink::Motors(i)
        }
        Kind::Laser(n, r) => {
            let i = ifaces.provide::<Laser>(&w.iface, provider)?;
            all.push(i.clone());
            Sink::Laser(i, LaserMap::new(*n, *r))
        }
        Kind::PtEncoders => {
            let i = ifaces.provide::<PtEncoders>(&w.iface, provider)?;
            all.push(i.clone());
            Sink::PtEncoders(i, gc.joints.0.clone(), gc.joints.1.clone())
        }
        Kind::PtMotors => {
            let i = ifaces.provide::<PtMotors>(&w.iface, provider)?;
            all.push(i.clone());
            let tilt = format!("/model/{}/joint/{}/0/cmd_pos", w.target, gc.joints.1);
            Sink::PtMotors(i, tilt)
        }
        Kind::Imu => {
            let i = ifaces.provide::<Imu>(&w.iface, provider)?;
            all.push(i.clone());
            Sink::Imu(i)
        }
        Kind::Camera(fixed) => {
            let init = if *fixed {
                Image::new(COLOR_WIDTH, COLOR_HEIGHT)
            } else {
                Image::default()
            };
            let i = ifaces.provide_value(&w.iface, provider, init)?;
            all.push(i.clone());
            Sink::Camera(i, *fixed)
        }
    })
}

impl GazeboDriver {
    /// Provides the interfaces, joins gz-transport and starts the thread.
    pub fn start(gc: GzConf, ifaces: &Interfaces, provider: &str) -> anyhow::Result<GazeboDriver> {
        let node = Node::new(&gc.ip, &gc.partition).map_err(|e| {
            anyhow::anyhow!(
                "{provider}: cannot join gz-transport's discovery (UDP {}:{}) on {}: {e}; set \
                 `ip` (or IGN_IP) to an address of this host",
                node::GROUP,
                node::MSG_PORT,
                gc.ip
            )
        })?;
        let mut lines = Vec::new();
        let mut all: Vec<Arc<dyn AnyInterface>> = Vec::new();
        let mut motors = Vec::new();
        for w in &gc.wants {
            let sink = provide(w, &gc, ifaces, provider, &mut all, &mut motors)?;
            let topic = matches!(w.kind, Kind::PtMotors)
                .then(|| format!("/model/{}/joint/{}/0/cmd_pos", w.target, gc.joints.0));
            lines.push(Line {
                want: w.clone(),
                sink,
                topic,
                searched: false,
                failed: Vec::new(),
                failures: 0,
                sub: None,
                source: Source::new(format!("{provider}: {} {}", w.iface, w.target)),
            });
        }
        for m in &motors {
            all.push(m.clone());
        }
        let ns = gc.namespace.clone().unwrap_or_else(|| "ignition".into());
        let mut gz = Gz {
            node,
            lines,
            gc,
            started: Instant::now(),
            next_cmd: Instant::now(),
            twist: Vec::new(),
            ns,
            resolved: None,
            name: provider.to_string(),
            stops: Stops::default(),
            stops_of: None,
        };
        let _estop = (!motors.is_empty()).then(|| {
            let stops = gz.stops.clone();
            estop::register(provider.to_string(), move || {
                for (s, bytes) in stops.load().iter() {
                    let _ = (&*s).write_all(bytes);
                }
            })
        });
        let mut how = Supervision {
            name: provider.into(),
            interfaces: all,
            on_demand: false,
            backoff: Backoff::fixed(Duration::from_millis(100)),
            absent: None,
        };
        if gz.settle(Duration::from_millis(1200)) {
            tracing::info!(
                "{provider}: bound to Gazebo in partition `{}` on {}",
                gz.gc.partition,
                gz.node.ip
            );
        } else {
            let why = gz.reason();
            let at = gz
                .gc
                .wants
                .first()
                .map(|w| w.at.as_str())
                .unwrap_or_default();
            let line = format!("{at}: {why}; the interfaces stay stale until they appear");
            how = how.absent_at_load(why, Some(line));
        }
        Ok(GazeboDriver {
            sup: Supervisor::start(how, gz)?,
            motors,
            _estop,
        })
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    if conf.name == "gazebo08" {
        tracing::info!("gazebo08: the same driver as gazebo (gz-transport)");
    }
    let gc = GzConf::parse(conf)?;
    Ok(Box::new(GazeboDriver::start(
        gc,
        &rt.interfaces,
        &conf.name,
    )?))
}

crate::register_driver!(
    Driver,
    "gazebo",
    "a robot and cameras in Gazebo (gz-sim) through gz-transport: encoders, motors, laser, imu, pan-tilt, colorA..D, varcolorA..D",
    create,
    lines = Lines
);

crate::register_driver!(
    Driver,
    "gazebo08",
    "the gazebo driver under 4.3's second name (gz-transport)",
    create,
    "gazebo08",
    lines = Lines
);

#[cfg(test)]
mod tests {
    use super::*;

    fn scan_bytes(ranges: &[f64]) -> Vec<u8> {
        ranges.iter().flat_map(|r| r.to_le_bytes()).collect()
    }

    #[test]
    fn a_scan_is_resampled_to_180_readings_in_mm() {
        // 360 rays over -pi..pi; ray k at -pi + k*step.
        let ranges: Vec<f64> = (0..360)
            .map(|k| {
                if k == 180 {
                    f64::INFINITY
                } else {
                    1.0 + k as f64 / 1000.0
                }
            })
            .collect();
        let b = scan_bytes(&ranges);
        let s = pb::Scan {
            angle_min: -std::f64::consts::PI,
            angle_step: std::f64::consts::TAU / 360.0,
            range_max: 10.0,
            count: 360,
            ranges: &b,
            time: None,
        };
        let mut l = Laser::default();
        laser(&mut LaserMap::new(180, 1.0), &s, &mut l);
        assert_eq!(l.readings.len(), 180);
        // reading 0 at -90 deg: ray 90.
        assert_eq!(l.readings[0], 1090);
        // reading 90 (ahead): ray 180, no hit: range_max.
        assert_eq!(l.readings[90], 10_000);
    }

    #[test]
    fn absurd_scans_are_refused() {
        let ok = scan_bytes(&[1.0, f64::INFINITY, 2.0]);
        let s = |range_max: f64, ranges: &[u8]| {
            check_scan(&pb::Scan {
                angle_min: -1.0,
                angle_step: 0.01,
                range_max,
                count: ranges.len() / 8,
                ranges,
                time: None,
            })
        };
        assert!(s(10.0, &ok).is_ok());
        assert!(s(1e300, &ok).unwrap_err().contains("range_max"));
        assert!(s(10.0, &[]).unwrap_err().contains("empty"));
        let huge = scan_bytes(&[1.0, 1e300]);
        assert!(s(10.0, &huge).unwrap_err().contains("range 1"));
    }

    #[test]
    fn an_rgb_frame_becomes_bgr_and_scales_to_colora() {
        let data: Vec<u8> = (0..640 * 480).flat_map(|_| [10u8, 20, 30]).collect();
        let f = pb::Frame {
            width: 640,
            height: 480,
            step: 1920,
            format: pb::pixel::RGB_INT8,
            data: &data,
            time: None,
        };
        let mut img = Image::default();
        fill_image(&f, true, &mut img).unwrap();
        assert_eq!((img.width, img.height), (320, 240));
        assert_eq!(img.pixel(5, 5), [30, 20, 10]);
        fill_image(&f, false, &mut img).unwrap();
        assert_eq!((img.width, img.height), (640, 480));
        let short = pb::Frame {
            data: &data[..100],
            ..f
        };
        assert!(fill_image(&short, false, &mut img).is_err());
    }
}
