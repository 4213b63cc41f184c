//! Driver `networkclient`: a robot's interfaces served by `networkserver` on another
//! machine (ours or JDE 4.3's), provided here as if they were local. It speaks
//! 4.3's wire protocol ([`crate::netwire`]): one TCP connection per device, the
//! 20-byte client name, `1019`/`1020` images, subscription pushes every 33 ms,
//! `22`/`23` motors, pan-tilt and zoom messages, goodbye. See `docs/network.md`.
//!
//! # Conf
//! ```text
//! driver networkclient
//! provides colorA robot.local 3001 0        # NAME HOST PORT NETID: a 320x240 image
//! provides varcolorA robot.local 3001 1 640 480   # NETID W H: frames must be W x H
//! provides varcolorB robot.local 3001 2     # NETID alone: any size
//! provides laser robot.local 3001           # laser, sonars, encoders, motors,
//! provides encoders robot.local 3001        #   pantiltencoders, pantiltmotors,
//! provides motors robot.local 3001          #   zoomencoders, zoommotors, imu (jderobot)
//! initial_position 1000 1000 90             # X Y mm, THETA deg: where the remote odometry's
//!                                           #   origin is in this side's world (default 0 0 0)
//! token s3cret                              # the server's token, if it has one
//! motors_timeout 500                        # ms: an older motors command is sent as zero
//! depth 2                                   # image requests kept in flight (pipelining)
//! end_driver
//! ```
//!
//! # Interfaces (the server's units)
//! | interface | what |
//! |---|---|
//! | `colorA..D` | 320x240 BGR; `varcolorA..D` any size (or exactly `W H` when given) |
//! | `laser` | readings in mm, as many as the server sends; resolution 1 reading/deg when 180 |
//! | `encoders` | x, y mm, θ rad (0, 2π] (sent in degrees), after `initial_position` |
//! | `sonars` | mm, one per sonar |
//! | `motors` | v mm/s, w deg/s: sent as `22 v 0.0` / `23 w 0.0` every 100 ms and on change |
//! | `pantiltencoders`, `zoomencoders` | deg; zoom position |
//! | `pantiltmotors`, `zoommotors` | commands sent on change; limits asked (`1004`, `1022`) on connect |
//!
//! Each device's connection is a [`Supervisor`]'s: sensors and images connect
//! and are subscribed/requested only while someone uses the interface (then
//! unsubscribed, the connection kept); commands connect at once. When a server
//! goes away the driver reconnects with backoff (0.1 s doubling to 5 s), marks each interface stale with the reason meanwhile (`ps`,
//! `echo` and mastergui show it), publishes zero on `motors`, and subscribes again
//! when the server is back. An image of an unexpected size is an error naming both
//! sizes (logged once; the interface is stale) and the connection goes on.
//! Image requests are pipelined (`depth`, default 2), so frame rate is not bound by
//! one round trip per frame.
//!
//! 4.3 differences: 4.3 exited when a `colorA` frame was not 320x240; it had no
//! reconnection (a server restart left stale values forever) and no `varcolor`
//! without a fixed size.
//!
//! System packages: none.

use std::{
    io::{self, Write},
    net::{SocketAddr, TcpStream, ToSocketAddrs},
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, Instant},
};

use crate::{
    conf::{
        ComponentConf, ConfLine,
        settings::{self, MOTORS_TIMEOUT, Setting, int, interface, word},
    },
    interfaces::{
        AnyInterface, COLOR_HEIGHT, COLOR_WIDTH, Encoders, Image, Imu, Interface, Interfaces,
        Laser, Motors, PtEncoders, PtMotors, Sonars, Source, ZoomEncoders, ZoomMotors, canonical,
        family,
    },
    netwire::{self, Feed, LineEvent, LineReader, Message, Request},
    runtime::{self, Backoff, Driver, Runtime, Supervision, Supervisor},
};

/// One `provides` line.
#[derive(Clone, Debug, PartialEq)]
pub struct Remote {
    /// Local interface name.
    pub name: String,
    pub host: String,
    pub port: u16,
    /// Images: network id and the required size (None = any).
    pub netid: Option<u32>,
    pub size: Option<(u32, u32)>,
}

/// The driver's settings.
#[derive(Clone, Debug)]
pub struct ClientConf {
    pub remotes: Vec<Remote>,
    /// x, y mm, θ deg.
    pub initial: (f32, f32, f32),
    pub token: Option<String>,
    pub motors_timeout: Duration,
    pub depth: u32,
}

const USAGE: &str = "provides colorA..D HOST PORT NETID, provides varcolorA..D HOST PORT NETID [W H], \
provides laser|sonars|encoders|motors|pantiltencoders|pantiltmotors|zoomencoders|zoommotors HOST PORT";

/// The driver's lines, declared once (`jderobot help networkclient`).
const LINES: &[Setting] = &[
    Setting::new(
        "provides",
        USAGE,
        &[
            interface("NAME"),
            word("HOST"),
            int("PORT", "", 1, 65_535),
            int("NETID", "", 0, u32::MAX as i64).optional(),
            int("W", "px", 1, 8192),
            int("H", "px", 1, 8192),
        ],
    )
    .repeats()
    .required(),
    settings::INITIAL_POSITION.help("the odometry offset added to the remote encoders"),
    Setting::new(
        "token",
        "the server's secret (its `token` line)",
        &[word("SECRET")],
    ),
    MOTORS_TIMEOUT,
    Setting::new(
        "depth",
        "image requests in flight per image",
        &[int("N", "", 1, 16)],
    )
    .default("2"),
];

fn err(l: &ConfLine, m: impl Into<String>) -> anyhow::Error {
    l.error(m).into()
}

impl ClientConf {
    pub fn parse(conf: &ComponentConf) -> anyhow::Result<ClientConf> {
        conf.check(LINES)?;
        let mut c = ClientConf {
            remotes: Vec::new(),
            initial: (0.0, 0.0, 0.0),
            token: None,
            motors_timeout: conf.motors_timeout()?,
            depth: 2,
        };
        for l in &conf.lines {
            match l.keyword() {
                "provides" => {
                    let a = l.args();
                    if a.len() < 3 {
                        return Err(err(
                            l,
                            format!("`provides` needs NAME HOST PORT; usage: {USAGE}"),
                        ));
                    }
                    let name = canonical(&a[0]);
                    let fam = family(&name).ok_or_else(|| {
                        err(
                            l,
                            format!("`provides {}`: not an interface; usage: {USAGE}", a[0]),
                        )
                    })?;
                    if fam == "bumpers" {
                        return Err(err(
                            l,
                            "4.3's wire has no bumpers message; bumpers cannot be provided",
                        ));
                    }
                    let port: u16 = l.arg(2, "a TCP port 1..65535")?;
                    let mut r = Remote {
                        name: name.clone(),
                        host: a[1].clone(),
                        port,
                        netid: None,
                        size: None,
                    };
                    if fam == "image" {
                        let var = name.starts_with("varcolor");
                        match (a.len(), var) {
                            (4, _) => {}
                            (6, true) => {
                                let dim = |i: usize| -> anyhow::Result<u32> {
                                    let v: u32 = l.arg(i, "a size in pixels 1..8192")?;
                                    if !(1..=8192).contains(&v) {
                                        return Err(err(
                                            l,
                                            format!(
                                                "`provides {name}`: size {v} is out of 1..8192"
                                            ),
                                        ));
                                    }
                                    Ok(v)
                                };
                                r.size = Some((dim(4)?, dim(5)?));
                            }
                            _ => {
                                return Err(err(
                                    l,
                                    format!(
                                        "`provides {name}` takes HOST PORT NETID{}; usage: {USAGE}",
                                        if var { " [W H]" } else { "" }
                                    ),
                                ));
                            }
                        }
                        r.netid = Some(l.arg(3, "a network id (0, 1, 2 ...)")?);
                        if !var {
                            r.size = Some((COLOR_WIDTH, COLOR_HEIGHT));
                        }
                    } else if a.len() != 3 {
                        return Err(err(
                            l,
                            format!("`provides {name}` takes HOST PORT only; usage: {USAGE}"),
                        ));
                    }
                    if c.remotes.iter().any(|x| x.name == name) {
                        return Err(err(l, format!("interface `{name}` is provided twice")));
                    }
                    c.remotes.push(r);
                }
                "initial_position" => {
                    l.expect_args(3, 3, "initial_position X_MM Y_MM THETA_DEG")?;
                    let f = |i: usize, what: &str| -> anyhow::Result<f32> {
                        let v: f32 = l.arg(i, what)?;
                        if !v.is_finite() {
                            return Err(err(
                                l,
                                format!("`initial_position`: {what} must be finite"),
                            ));
                        }
                        Ok(v)
                    };
                    c.initial = (
                        f(0, "X in mm")?,
                        f(1, "Y in mm")?,
                        f(2, "THETA in degrees")?,
                    );
                }
                "token" => {
                    l.expect_args(1, 1, "token SECRET")?;
                    netwire::check_token(&l.args()[0])
                        .map_err(|e| err(l, format!("`token`: {e}")))?;
                    c.token = Some(l.args()[0].clone());
                }
                "depth" => {
                    l.expect_args(1, 1, "depth N")?;
                    let d: u32 = l.arg(0, "a number of requests 1..16")?;
                    if !(1..=16).contains(&d) {
                        return Err(err(l, format!("`depth`: {d} is out of 1..16")));
                    }
                    c.depth = d;
                }
                _ => {} // motors_timeout above; the rest refused by the declaration
            }
        }
        Ok(c)
    }
}

/// A device and its local interface.
#[derive(Clone)]
enum Dev {
    Image(Arc<Interface<Image>>, u32, Option<(u32, u32)>),
    Laser(Arc<Interface<Laser>>),
    Encoders(Arc<Interface<Encoders>>, (f32, f32, f32)),
    Sonars(Arc<Interface<Sonars>>),
    PtEncoders(Arc<Interface<PtEncoders>>),
    ZoomEncoders(Arc<Interface<ZoomEncoders>>),
    Imu(Arc<Interface<Imu>>),
    Motors(Arc<Interface<Motors>>, Duration),
    PtMotors(Arc<Interface<PtMotors>>),
    ZoomMotors(Arc<Interface<ZoomMotors>>),
}

impl Dev {
    /// The local interface.
    fn interface(&self) -> Arc<dyn AnyInterface> {
        match self {
            Dev::Image(i, ..) => i.clone(),
            Dev::Laser(i) => i.clone(),
            Dev::Encoders(i, _) => i.clone(),
            Dev::Sonars(i) => i.clone(),
            Dev::PtEncoders(i) => i.clone(),
            Dev::ZoomEncoders(i) => i.clone(),
            Dev::Imu(i) => i.clone(),
            Dev::Motors(i, _) => i.clone(),
            Dev::PtMotors(i) => i.clone(),
            Dev::ZoomMotors(i) => i.clone(),
        }
    }

    /// The pushed feed of a sensor.
    fn feed(&self) -> Option<Feed> {
        Some(match self {
            Dev::Laser(_) => Feed::Laser,
            Dev::Encoders(..) => Feed::Encoders,
            Dev::Sonars(_) => Feed::Sonars,
            Dev::PtEncoders(_) => Feed::PtEncoders,
            Dev::ZoomEncoders(_) => Feed::ZoomEncoders,
            Dev::Imu(_) => Feed::Imu,
            _ => return None,
        })
    }
}

/// The running driver: one supervised connection per device.
pub struct NetClient {
    /// Seen by a connection in the middle of a frame, so a stop never waits for one.
    stop: Arc<AtomicBool>,
    links: Vec<Supervisor>,
}

impl NetClient {
    /// Provides the interfaces of `cc` on `ifaces` and starts one supervised
    /// connection each: sensors and images connect while somebody uses them,
    /// commands always.
    pub fn start(cc: ClientConf, ifaces: &Interfaces, provider: &str) -> anyhow::Result<NetClient> {
        let name = netwire::client_name(cc.token.as_deref()).map_err(anyhow::Error::msg)?;
        let stop = Arc::new(AtomicBool::new(false));
        let mut devs = Vec::new();
        for r in &cc.remotes {
            let dev = match family(&r.name).unwrap_or("") {
                "image" => {
                    let (w, h) = r.size.unwrap_or((COLOR_WIDTH, COLOR_HEIGHT));
                    Dev::Image(
                        ifaces.provide_value(&r.name, provider, Image::new(w, h))?,
                        r.netid.unwrap_or(0),
                        r.size,
                    )
                }
                "laser" => Dev::Laser(ifaces.provide(&r.name, provider)?),
                "encoders" => {
                    let (x, y, t) = cc.initial;
                    Dev::Encoders(
                        ifaces.provide_value(
                            &r.name,
                            provider,
                            Encoders::from_pose(x, y, t.to_radians()),
                        )?,
                        cc.initial,
                    )
                }
                "sonars" => Dev::Sonars(ifaces.provide(&r.name, provider)?),
                "pantiltencoders" => Dev::PtEncoders(ifaces.provide(&r.name, provider)?),
                "zoomencoders" => Dev::ZoomEncoders(ifaces.provide(&r.name, provider)?),
                "imu" => Dev::Imu(ifaces.provide(&r.name, provider)?),
                "motors" => Dev::Motors(ifaces.provide(&r.name, provider)?, cc.motors_timeout),
                "pantiltmotors" => Dev::PtMotors(ifaces.provide(&r.name, provider)?),
                "zoommotors" => Dev::ZoomMotors(ifaces.provide(&r.name, provider)?),
                other => anyhow::bail!("networkclient: cannot provide a {other} interface"),
            };
            devs.push((r.clone(), dev));
        }
        let mut links = Vec::new();
        for (r, dev) in devs {
            let how = Supervision {
                name: format!("networkclient {}@{}:{}", r.name, r.host, r.port),
                interfaces: vec![dev.interface()],
                on_demand: !dev.interface().is_actuator(),
                backoff: Backoff {
                    first: Duration::from_millis(100),
                    max: Duration::from_secs(5),
                },
                absent: None,
            };
            let link = Link {
                from: Source::new(format!(
                    "networkclient: {}:{} (for `{}`)",
                    r.host, r.port, r.name
                )),
                remote: r,
                dev,
                stop: stop.clone(),
                name,
                depth: cc.depth,
            };
            links.push(Supervisor::start(how, link)?);
        }
        Ok(NetClient { stop, links })
    }

    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::Release);
        self.links.terminate();
    }
}

impl Driver for NetClient {
    fn terminate(&mut self) {
        self.stop();
    }
}

impl Drop for NetClient {
    fn drop(&mut self) {
        self.stop();
    }
}

/// How often a command connection checks for a new command.
const TICK: Duration = Duration::from_millis(10);
/// How long a sensor or image connection waits for a line before looking again.
const SENSOR_TICK: Duration = Duration::from_millis(50);
/// The longest line the client accepts (a laser push of 4096 readings fits).
const MAX_LINE: usize = 64 * 1024;
/// The largest frame accepted, in bytes (a bigger announced size ends the connection).
const MAX_FRAME: usize = 256 << 20;

/// One device's connection, as its [`Supervisor`] opens and serves it.
struct Link {
    remote: Remote,
    dev: Dev,
    stop: Arc<AtomicBool>,
    name: [u8; netwire::NAME_LEN],
    depth: u32,
    /// The server's values, refused (an encoders pose out of range, ...) with one
    /// log line per change of state.
    from: Source,
}

/// An open connection and what its side of the protocol keeps between steps.
struct Session {
    stream: TcpStream,
    lines: LineReader,
    state: State,
}

enum State {
    /// A pushed sensor: whether it is subscribed.
    Sensor { subscribed: bool },
    /// Image requests in flight, the frame buffer, the wrong size last reported.
    Image {
        inflight: u32,
        buf: Vec<u8>,
        reported: Option<(u32, u32)>,
    },
    /// When the last command was sent, and the command's clock then.
    Motors { last_sent: Instant, last_clock: u64 },
    /// Pan-tilt or zoom commands: the clock of the last one sent.
    Command { last_clock: u64 },
}

impl runtime::Device for Link {
    type Session = Session;

    fn open(&mut self) -> Result<Session, String> {
        let stream = self.connect().map_err(|e| {
            format!(
                "networkclient: cannot connect to {} for {} ({e})",
                self.where_(),
                self.remote.name
            )
        })?;
        let command = self.dev.interface().is_actuator();
        let _ = stream.set_read_timeout(Some(if command { TICK } else { SENSOR_TICK }));
        let state = match &self.dev {
            Dev::Image(..) => State::Image {
                inflight: 0,
                buf: Vec::new(),
                reported: None,
            },
            Dev::Motors(..) => State::Motors {
                last_sent: Instant::now() - Duration::from_secs(1),
                last_clock: u64::MAX,
            },
            Dev::PtMotors(_) | Dev::ZoomMotors(_) => {
                let query = if matches!(self.dev, Dev::PtMotors(_)) {
                    Request::PtLimitsQuery
                } else {
                    Request::ZoomLimitsQuery
                };
                self.send(&stream, &[query]).map_err(|e| self.lost(e))?;
                State::Command {
                    last_clock: u64::MAX,
                }
            }
            _ => State::Sensor { subscribed: false },
        };
        Ok(Session {
            stream,
            lines: LineReader::new(MAX_LINE),
            state,
        })
    }

    fn step(&mut self, s: &mut Session) -> Result<(), String> {
        let Session {
            stream,
            lines,
            state,
        } = s;
        let r = match (&self.dev, state) {
            (
                Dev::Image(i, netid, size),
                State::Image {
                    inflight,
                    buf,
                    reported,
                },
            ) => self.image_step(stream, lines, i, *netid, *size, inflight, buf, reported),
            (
                Dev::Motors(m, timeout),
                State::Motors {
                    last_sent,
                    last_clock,
                },
            ) => self.motors_step(stream, lines, m, *timeout, last_sent, last_clock),
            (Dev::PtMotors(p), State::Command { last_clock }) => {
                self.ptmotors_step(stream, lines, p, last_clock)
            }
            (Dev::ZoomMotors(z), State::Command { last_clock }) => {
                self.zoommotors_step(stream, lines, z, last_clock)
            }
            (_, State::Sensor { subscribed }) => self.sensor_step(stream, lines, subscribed),
            _ => Err("internal: a session of another kind".into()),
        };
        r.map_err(|e| self.lost(e))
    }

    /// Nobody uses the sensor any more: unsubscribe, and keep the connection.
    fn idle(&mut self, s: &mut Session) -> bool {
        if let (Some(d), State::Sensor { subscribed }) = (self.dev.feed(), &mut s.state)
            && *subscribed
        {
            *subscribed = false;
            return self.send(&s.stream, &[Request::Unsubscribe(d)]).is_ok();
        }
        true
    }

    /// The connection is gone: a motors command counts as zero here too.
    fn on_loss(&mut self) {
        if let Dev::Motors(m, _) = &self.dev {
            let _ = m.publish(Motors::default());
        }
    }

    /// The driver stops: stop what moves on the server, and say goodbye.
    fn close(&mut self, s: Session) {
        let farewell: Vec<Request> = match &self.dev {
            Dev::Image(..) => vec![Request::GoodbyeImages],
            Dev::Motors(..) => vec![
                Request::DriveSpeed { v: 0.0, ac: 0.0 },
                Request::SteerSpeed { w: 0.0, ac: 0.0 },
                Request::Goodbye,
            ],
            Dev::PtMotors(p) => vec![pt_command(&p.read().value), Request::Goodbye],
            Dev::ZoomMotors(_) => vec![Request::Goodbye],
            sensor => match sensor.feed() {
                Some(d) => vec![Request::Unsubscribe(d), Request::Goodbye],
                None => vec![Request::Goodbye],
            },
        };
        let _ = self.send(&s.stream, &farewell);
    }
}

/// A pan-tilt command as 4.3's `1006` line.
fn pt_command(c: &PtMotors) -> Request {
    Request::PtPosition {
        pan: c.longitude,
        tilt: c.latitude,
        pan_speed: c.longitude_speed,
        tilt_speed: c.latitude_speed,
    }
}

impl Link {
    fn where_(&self) -> String {
        format!("{}:{}", self.remote.host, self.remote.port)
    }

    /// The reason a session was lost, for the stale mark and the log.
    fn lost(&self, why: String) -> String {
        format!(
            "networkclient: {} for {}: {why}; reconnecting",
            self.where_(),
            self.remote.name
        )
    }

    fn connect(&self) -> io::Result<TcpStream> {
        let addrs: Vec<SocketAddr> = (self.remote.host.as_str(), self.remote.port)
            .to_socket_addrs()?
            .collect();
        let mut last = io::Error::new(io::ErrorKind::NotFound, "no address for the host");
        for a in addrs {
            match TcpStream::connect_timeout(&a, Duration::from_secs(2)) {
                Ok(s) => {
                    s.set_nodelay(true)?;
                    s.set_write_timeout(Some(Duration::from_secs(5)))?;
                    (&s).write_all(&self.name)?;
                    return Ok(s);
                }
                Err(e) => last = e,
            }
        }
        Err(last)
    }

    fn send(&self, mut s: &TcpStream, reqs: &[Request]) -> Result<(), String> {
        let mut out = Vec::new();
        for r in reqs {
            r.write_to(&mut out);
        }
        s.write_all(&out).map_err(|e| format!("cannot send: {e}"))
    }

    /// Reads a line if one arrives within the read timeout (the step's tick);
    /// an error when the connection ends.
    fn next_line<'a>(
        &self,
        lr: &'a mut LineReader,
        mut s: &TcpStream,
    ) -> Result<Option<&'a [u8]>, String> {
        match lr.read_line(&mut s) {
            Ok(LineEvent::Line(l)) => Ok(Some(l)),
            Ok(LineEvent::Closed) => Err("the server closed the connection".into()),
            Err(e) if netwire::is_timeout(&e) => Ok(None),
            Err(e) => Err(format!("connection error: {e}")),
        }
    }

    /// (Un)subscribes as the interface is used, and publishes what arrives.
    fn sensor_step(
        &self,
        s: &TcpStream,
        lr: &mut LineReader,
        subscribed: &mut bool,
    ) -> Result<(), String> {
        let dev = self.dev.feed().expect("a sensor");
        if !*subscribed {
            self.send(s, &[Request::Subscribe(dev)])?;
            *subscribed = true;
        }
        if let Some(line) = self.next_line(lr, s)? {
            let m = Message::parse(line).map_err(|e| format!("the server sent a bad line: {e}"))?;
            self.publish(m);
        }
        Ok(())
    }

    fn publish(&self, m: Message) {
        match (&self.dev, m) {
            (Dev::Laser(i), Message::Laser { readings, .. }) => {
                i.accept_with(&self.from, |l| {
                    l.readings.clear();
                    l.readings.extend_from_slice(&readings);
                    // 4.3's wire carries only the readings, of 4.3's laser: 180°
                    // from −90° (docs/network.md).
                    l.resolution = (readings.len() as f32 / 180.0).max(f32::MIN_POSITIVE);
                    l.start = crate::interfaces::JDE43_LASER_START;
                });
            }
            (
                Dev::Encoders(i, (x0, y0, t0)),
                Message::Encoders {
                    x, y, theta_deg, ..
                },
            ) => {
                let (s, c) = t0.to_radians().sin_cos();
                let gx = x0 + c * x - s * y;
                let gy = y0 + s * x + c * y;
                i.accept(
                    &self.from,
                    Encoders::from_pose(gx, gy, (theta_deg + t0).to_radians()),
                );
            }
            (Dev::Sonars(i), Message::Sonars { us, .. }) => {
                let n = us.iter().map(|(k, _)| k + 1).max().unwrap_or(0);
                i.accept_with(&self.from, |v| {
                    v.us.clear();
                    v.us.resize(n, 0.0);
                    for (k, u) in &us {
                        v.us[*k] = *u;
                    }
                });
            }
            (Dev::PtEncoders(i), Message::PtEncoders { pan, tilt, .. }) => {
                i.accept(
                    &self.from,
                    PtEncoders {
                        pan_angle: pan,
                        tilt_angle: tilt,
                    },
                );
            }
            (Dev::ZoomEncoders(i), Message::ZoomEncoders { zoom, .. }) => {
                i.accept(
                    &self.from,
                    ZoomEncoders {
                        zoom_position: zoom,
                    },
                );
            }
            (Dev::Imu(i), Message::Imu { fields, .. }) => {
                i.accept(&self.from, Imu::from_fields(fields));
            }
            (_, Message::Error(t)) => {
                tracing::warn!(
                    "networkclient: {} for {} says: {t}",
                    self.where_(),
                    self.remote.name
                );
            }
            (_, m) => tracing::debug!("networkclient: unexpected {m:?}"),
        }
    }

    /// Keeps `depth` image requests in flight and publishes the next frame.
    #[allow(clippy::too_many_arguments)]
    fn image_step(
        &self,
        s: &TcpStream,
        lr: &mut LineReader,
        iface: &Interface<Image>,
        netid: u32,
        size: Option<(u32, u32)>,
        inflight: &mut u32,
        buf: &mut Vec<u8>,
        reported: &mut Option<(u32, u32)>,
    ) -> Result<(), String> {
        if *inflight < self.depth {
            let n = self.depth - *inflight;
            self.send(s, &vec![Request::ImageQuery(netid); n as usize])?;
            *inflight += n;
        }
        let Some(line) = self.next_line(lr, s)? else {
            return Ok(());
        };
        let m = Message::parse(line).map_err(|e| format!("the server sent a bad line: {e}"))?;
        let (width, height) = match m {
            Message::Image {
                netid: id,
                width,
                height,
                depth,
                ..
            } => {
                if id != netid || depth != 3 {
                    return Err(format!(
                        "the server sent image {id} with depth {depth}; asked for image {netid}, depth 3"
                    ));
                }
                (width, height)
            }
            other => {
                self.publish(other);
                return Ok(());
            }
        };
        *inflight = inflight.saturating_sub(1);
        let bytes = width as usize * height as usize * 3;
        if bytes > MAX_FRAME {
            return Err(format!(
                "the server announced a {width}x{height} frame ({bytes} bytes), over the {MAX_FRAME}-byte limit"
            ));
        }
        buf.resize(bytes, 0);
        let stop = &self.stop;
        let mut stalled_since: Option<Instant> = None;
        lr.read_exact(&mut &*s, buf, || {
            let t0 = *stalled_since.get_or_insert_with(Instant::now);
            !stop.load(Ordering::Acquire) && t0.elapsed() < Duration::from_secs(10)
        })
        .map_err(|e| format!("while reading a {width}x{height} frame: {e}"))?;
        if let Some((w, h)) = size
            && (w, h) != (width, height)
        {
            let why = format!(
                "networkclient: {} sends {width}x{height} images for {}, which is {w}x{h} here; frames dropped{}",
                self.where_(),
                self.remote.name,
                if self.remote.name.starts_with("color") {
                    " (use a varcolor interface for other sizes)"
                } else {
                    ""
                }
            );
            if *reported != Some((width, height)) {
                tracing::error!("{why}");
                *reported = Some((width, height));
            }
            iface.set_stale(why);
            return Ok(());
        }
        iface.accept_with(&self.from, |img| {
            img.width = width;
            img.height = height;
            std::mem::swap(&mut img.data, buf);
        });
        Ok(())
    }

    /// Sends the command when it changes, and every 100 ms (a stale one as zero).
    fn motors_step(
        &self,
        s: &TcpStream,
        lr: &mut LineReader,
        m: &Interface<Motors>,
        timeout: Duration,
        last_sent: &mut Instant,
        last_clock: &mut u64,
    ) -> Result<(), String> {
        let clock = m.clock();
        if clock != *last_clock || last_sent.elapsed() >= Duration::from_millis(100) {
            let c = m.command(timeout);
            self.send(
                s,
                &[
                    Request::DriveSpeed { v: c.v, ac: 0.0 },
                    Request::SteerSpeed { w: c.w, ac: 0.0 },
                ],
            )?;
            *last_clock = clock;
            *last_sent = Instant::now();
        }
        // The read doubles as the tick's sleep and notices a closed server.
        if let Some(line) = self.next_line(lr, s)?
            && let Ok(msg) = Message::parse(line)
        {
            self.publish(msg);
        }
        Ok(())
    }

    /// Sends the pan-tilt command when it changes; takes the limits the server
    /// answers.
    fn ptmotors_step(
        &self,
        s: &TcpStream,
        lr: &mut LineReader,
        p: &Interface<PtMotors>,
        last_clock: &mut u64,
    ) -> Result<(), String> {
        let clock = p.clock();
        if clock != *last_clock {
            if clock > 0 {
                self.send(s, &[pt_command(&p.read().value)])?;
            }
            *last_clock = clock;
        }
        if let Some(line) = self.next_line(lr, s)? {
            match Message::parse(line) {
                Ok(Message::PtLimits(v)) => {
                    let mut c = p.read().value;
                    c.max_longitude = v[0];
                    c.max_latitude = v[1];
                    c.min_longitude = v[2];
                    c.min_latitude = v[3];
                    c.max_longitude_speed = v[4];
                    c.max_latitude_speed = v[5];
                    if let Ok(k) = p.publish(c) {
                        *last_clock = k;
                    }
                }
                Ok(m) => self.publish(m),
                Err(e) => return Err(format!("the server sent a bad line: {e}")),
            }
        }
        Ok(())
    }

    /// Sends the zoom command when it changes; takes the limits the server answers.
    fn zoommotors_step(
        &self,
        s: &TcpStream,
        lr: &mut LineReader,
        z: &Interface<ZoomMotors>,
        last_clock: &mut u64,
    ) -> Result<(), String> {
        let clock = z.clock();
        if clock != *last_clock {
            if clock > 0 {
                let c = z.read().value;
                self.send(
                    s,
                    &[Request::ZoomPosition {
                        zoom: c.zoom,
                        speed: c.zoom_speed,
                    }],
                )?;
            }
            *last_clock = clock;
        }
        if let Some(line) = self.next_line(lr, s)? {
            match Message::parse(line) {
                Ok(Message::ZoomLimits(v)) => {
                    let mut c = z.read().value;
                    c.max_zoom = v[0];
                    c.min_zoom = v[1];
                    c.max_zoom_speed = v[2];
                    if let Ok(k) = z.publish(c) {
                        *last_clock = k;
                    }
                }
                Ok(m) => self.publish(m),
                Err(e) => return Err(format!("the server sent a bad line: {e}")),
            }
        }
        Ok(())
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let cc = ClientConf::parse(conf)?;
    Ok(Box::new(NetClient::start(cc, &rt.interfaces, &conf.name)?))
}

crate::register_driver!(
    Driver,
    "networkclient",
    "a robot's interfaces served by networkserver (4.3 wire) on another machine",
    create,
    lines = LINES
);
