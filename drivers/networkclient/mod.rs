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
//! token 7f3a9c2e5b8d4f16a0c3e9b2d7f14a68     # the server's token, if it has one (16 to 128 characters)
//! motors_timeout 500                        # ms: an older motors command is sent as zero
//! depth 2                                   # image requests kept in flight (pipelining)
//! end_driver
//! ```
//!
//! # Interfaces (the server's units)
//! | interface | what |
//! |---|---|
//! | `colorA..D` | 320x240 BGR; `varcolorA..D` any size (or exactly `W H` when given) |
//! | `laser` | readings in mm, as many as the server sends, read as 4.3's laser: over 180° from −90° (1 reading/deg when 180), 0..8000 mm |
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
//! one round trip per frame, and a frame's pixels are read once they are all there
//! (one wake-up a frame: `WAKE_ONCE_FROM`).
//!
//! 4.3 differences: 4.3 exited when a `colorA` frame was not 320x240; it had no
//! reconnection (a server restart left stale values forever) and no `varcolor`
//! without a fixed size.
//!
//! The stop: a connection of `motors` writes zero (`22`, `23`) when the driver
//! stops and whenever the process ends or is suspended: registered with
//! [`crate::estop`] (SIGINT, SIGTERM, SIGHUP, Ctrl+Z, an abort and a panic run
//! it first), through a second handle on the connection; after
//! [`crate::estop::halted`] it sends only zero. A connection that closed carries
//! nothing; jderobot's networkserver sets the motors to zero when the client
//! that drove them leaves, which covers `kill -9` too (the kernel closes the
//! socket), but not a power loss of the client's machine.
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
        ComponentConf,
        settings::{self, Form, MOTORS_TIMEOUT, Setting, choice, int, word},
    },
    estop,
    interfaces::{
        AnyInterface, COLOR_HEIGHT, COLOR_WIDTH, Image, Interface, Interfaces, Source, canonical,
        family, with_kind,
    },
    netwire::{self, Feed, LineEvent, LineReader, Message, Net43, OnWire, Request, WireError},
    runtime::{self, Backoff, Driver, Runtime, Supervision, Supervisor},
    sockets,
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

const HOST: settings::Arg = word("HOST");
const PORT: settings::Arg = int("PORT", "", 1, 65_535);
const NETID: settings::Arg = int("NETID", "", 0, u32::MAX as i64);

crate::declare_lines! {
    /// The driver's lines, declared once (`jderobot help networkclient`).
    struct Lines {
        provides: Vec<Provides> = settings::provides_forms(
            "a remote interface: the server's HOST and PORT (and an image's network id)",
            &[
                Form::new(
                    "color",
                    "a 320x240 image, the server's image NETID",
                    &[settings::COLOR, HOST, PORT, NETID],
                ),
                Form::new(
                    "varcolor",
                    "an image of any size (exactly W x H when given), the server's image NETID",
                    &[
                        settings::VARCOLOR,
                        HOST,
                        PORT,
                        NETID,
                        int("W", "px", 1, 8192).optional(),
                        int("H", "px", 1, 8192),
                    ],
                ),
                Form::new(
                    "device",
                    "a device (4.3's wire has no bumpers message)",
                    &[
                        choice(
                            "INTERFACE",
                            &[
                                "laser",
                                "sonars",
                                "encoders",
                                "motors",
                                "pantiltencoders",
                                "pantiltmotors",
                                "zoomencoders",
                                "zoommotors",
                                "imu",
                                "us",
                                "ptencoders",
                                "ptmotors",
                                "zencoders",
                                "zmotors",
                            ],
                        ),
                        HOST,
                        PORT,
                    ],
                ),
            ],
        )
        .required(),
        initial_position: Option<(f32, f32, f32)> = settings::INITIAL_POSITION.help("the odometry offset added to the remote encoders"),
        token: Option<String> = settings::TOKEN.help("the server's secret (its `token` line)"),
        #[allow(dead_code)] // read by `conf.motors_timeout()`
        motors_timeout: u64 = MOTORS_TIMEOUT,
        depth: u32 = Setting::new(
            "depth",
            "image requests in flight per image",
            &[int("N", "", 1, 16)],
        )
        .default("2"),
    }
}
#[derive(serde::Deserialize)]
enum Provides {
    #[serde(rename = "color")]
    Color(String, String, u16, u32),
    #[serde(rename = "varcolor")]
    Varcolor(String, String, u16, u32, Option<u32>, Option<u32>),
    #[serde(rename = "device")]
    Device(String, String, u16),
}

impl ClientConf {
    pub fn parse(conf: &ComponentConf) -> anyhow::Result<ClientConf> {
        let lines: Lines = conf.read()?;
        let mut c = ClientConf {
            remotes: Vec::new(),
            initial: lines.initial_position.unwrap_or_default(),
            token: lines.token,
            motors_timeout: conf.motors_timeout()?,
            depth: lines.depth,
        };
        for (p, l) in lines.provides.into_iter().zip(conf.provides()) {
            let (name, host, port, netid, size) = match p {
                Provides::Color(n, h, p, id) => {
                    (n, h, p, Some(id), Some((COLOR_WIDTH, COLOR_HEIGHT)))
                }
                Provides::Varcolor(n, h, p, id, Some(w), Some(hh)) => {
                    (n, h, p, Some(id), Some((w, hh)))
                }
                Provides::Varcolor(n, h, p, id, ..) => (n, h, p, Some(id), None),
                Provides::Device(n, h, p) => (canonical(&n), h, p, None, None),
            };
            if c.remotes.iter().any(|x| x.name == name) {
                return Err(l
                    .error(format!("interface `{name}` is provided twice"))
                    .into());
            }
            c.remotes.push(Remote {
                name,
                host,
                port,
                netid,
                size,
            });
        }
        Ok(c)
    }
}

/// A device and its local interface.
#[derive(Clone)]
enum Dev {
    /// Frames on request: the image, its network id and required size.
    Image(Arc<Interface<Image>>, u32, Option<(u32, u32)>),
    /// A pushed or commanded kind.
    Wired(Arc<dyn Wired>),
}

impl Dev {
    /// The local interface.
    fn interface(&self) -> Arc<dyn AnyInterface> {
        match self {
            Dev::Image(i, ..) => i.clone(),
            Dev::Wired(w) => w.interface(),
        }
    }

    /// The pushed feed of a sensor.
    fn feed(&self) -> Option<Feed> {
        match self {
            Dev::Wired(w) => Feed::of(w.interface().kind()),
            Dev::Image(..) => None,
        }
    }
}

/// A remote device of a pushed or commanded kind, whatever the kind: its local
/// interface and its kind's [`Net43`] code.
trait Wired: Send + Sync {
    fn interface(&self) -> Arc<dyn AnyInterface>;
    fn on_wire(&self) -> OnWire;
    /// Pushed: publishes a push's fields (`f[0]` the clock).
    fn take_push(&self, code: u32, f: &[&str], from: &Source) -> Result<(), WireError>;
    /// Commanded: the requests that send the command (a renewed one older than
    /// `timeout` as zero).
    fn requests(&self, timeout: Duration) -> Vec<Request>;
    /// Commanded: what to send when the driver stops, before the goodbye.
    fn farewell(&self) -> Vec<Request>;
    /// Commanded: publishes the limits the server answered; the new clock.
    fn take_limits(&self, code: u32, f: &[&str]) -> Result<Option<u64>, WireError>;
    /// Publishes the zero value (a renewed command whose connection is gone).
    fn zero(&self);
    /// A renewed command's (motors') zero on the wire: the emergency stop.
    fn stop(&self) -> Option<Vec<Request>>;
}

/// A local interface of kind `T` fed or sent by a connection.
struct Remote43<T> {
    iface: Arc<Interface<T>>,
    origin: netwire::Origin,
}

impl<T: Net43> Wired for Remote43<T> {
    fn interface(&self) -> Arc<dyn AnyInterface> {
        self.iface.clone()
    }
    fn on_wire(&self) -> OnWire {
        T::ON_WIRE
    }
    fn take_push(&self, code: u32, f: &[&str], from: &Source) -> Result<(), WireError> {
        self.iface.accept(from, T::read_push(code, f, self.origin)?);
        Ok(())
    }
    fn requests(&self, timeout: Duration) -> Vec<Request> {
        match T::ON_WIRE {
            OnWire::Commanded {
                keep_alive: true, ..
            } => self
                .iface
                .fresh(timeout)
                .map(|s| s.value.clone())
                .unwrap_or_default()
                .requests(),
            _ => self.iface.read().value.requests(),
        }
    }
    fn farewell(&self) -> Vec<Request> {
        self.iface.read().value.farewell()
    }
    fn take_limits(&self, code: u32, f: &[&str]) -> Result<Option<u64>, WireError> {
        let mut v = self.iface.read().value.clone();
        v.read_limits(code, f)?;
        Ok(self.iface.publish(v).ok())
    }
    fn zero(&self) {
        if let OnWire::Commanded {
            keep_alive: true, ..
        } = T::ON_WIRE
        {
            let _ = self.iface.publish(T::default());
        }
    }
    fn stop(&self) -> Option<Vec<Request>> {
        matches!(
            T::ON_WIRE,
            OnWire::Commanded {
                keep_alive: true,
                ..
            }
        )
        .then(|| T::default().requests())
    }
}

/// Provides interface `r.name` of kind `T` on `ifaces`, at the client's origin.
fn wired<T: Net43>(
    ifaces: &Interfaces,
    r: &Remote,
    provider: &str,
    origin: netwire::Origin,
) -> anyhow::Result<Dev> {
    let iface = ifaces.provide_value(&r.name, provider, T::initial(origin))?;
    Ok(Dev::Wired(Arc::new(Remote43 { iface, origin })))
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
        let hello = netwire::hello(cc.token.as_deref()).map_err(anyhow::Error::msg)?;
        let stop = Arc::new(AtomicBool::new(false));
        let mut devs = Vec::new();
        for r in &cc.remotes {
            let Some(kind) = family(&r.name) else {
                anyhow::bail!(
                    "networkclient: `{}`: no interface kind has that name",
                    r.name
                )
            };
            let dev = match netwire::on_wire(kind) {
                OnWire::Absent => {
                    anyhow::bail!("networkclient: cannot provide a {kind} interface")
                }
                OnWire::Frames => {
                    let (w, h) = r.size.unwrap_or((COLOR_WIDTH, COLOR_HEIGHT));
                    Dev::Image(
                        ifaces.provide_value(&r.name, provider, Image::new(w, h))?,
                        r.netid.unwrap_or(0),
                        r.size,
                    )
                }
                _ => with_kind!(kind, wired(ifaces, r, provider, cc.initial))?,
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
                hello: hello.clone(),
                depth: cc.depth,
                timeout: cc.motors_timeout,
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
/// How long a frame's bytes may stop coming before the connection is given up.
const FRAME_STALL: Duration = Duration::from_secs(10);
/// Bytes/s: a frame must come at least this fast (32 kbit/s; a 640x480 frame
/// within 225 s, any frame within FRAME_STALL), so a server that sends a byte
/// now and then cannot hold the connection forever, and a slow link that keeps
/// delivering still gets its frames.
const SLOWEST_LINK: f64 = 4096.0;
/// Frames from this size on are read with the socket's low-water mark at the
/// bytes still to come (`SO_RCVLOWAT`), so the kernel wakes this thread once a
/// frame, when its pixels are all there, instead of for each 64-KB segment that
/// loopback or the network delivers (about 6 a 640x480 frame). Measured on the
/// frames bench, five pairs: 3.2 time slices a frame instead of 6.0, all threads'
/// CPU 234-251 µs a frame instead of 269-307, and the link's rate 92-102 % of a
/// raw TCP copy instead of 82-107 %. The two `setsockopt` calls and the `poll`
/// a frame cost less than the wake-ups they save only for large frames.
const WAKE_ONCE_FROM: usize = 64 * 1024;

/// One device's connection, as its [`Supervisor`] opens and serves it.
struct Link {
    remote: Remote,
    dev: Dev,
    stop: Arc<AtomicBool>,
    /// The 20-byte name and the token line, if any ([`netwire::hello`]).
    hello: Vec<u8>,
    depth: u32,
    /// A renewed command (motors) older than this is sent as zero.
    timeout: Duration,
    /// The server's values, refused (an encoders pose out of range, ...) with one
    /// log line per change of state.
    from: Source,
}

/// An open connection and what its side of the protocol keeps between steps.
struct Session {
    stream: TcpStream,
    lines: LineReader,
    state: State,
    /// A renewed command's stop, registered with [`estop`] while connected.
    _estop: Option<estop::Registration>,
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
    /// A command: when it was last sent, and its clock then.
    Command { last_sent: Instant, last_clock: u64 },
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
            Dev::Wired(w) => match w.on_wire() {
                OnWire::Commanded { limits, .. } => {
                    if let Some(l) = limits {
                        self.send(&stream, &[Request::LimitsQuery(l.query)])
                            .map_err(|e| self.lost(e))?;
                    }
                    State::Command {
                        last_sent: Instant::now() - Duration::from_secs(1),
                        last_clock: u64::MAX,
                    }
                }
                _ => State::Sensor { subscribed: false },
            },
        };
        Ok(Session {
            _estop: self.register_stop(&stream),
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
            ..
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
                Dev::Wired(w),
                State::Command {
                    last_sent,
                    last_clock,
                },
            ) => self.command_step(stream, lines, &**w, last_sent, last_clock),
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

    /// The connection is gone: a renewed command (motors) counts as zero here too.
    fn on_loss(&mut self) {
        if let Dev::Wired(w) = &self.dev {
            w.zero();
        }
    }

    /// The driver stops: stop what moves on the server, and say goodbye.
    fn close(&mut self, s: Session) {
        let mut farewell = match (&self.dev, self.dev.feed()) {
            (Dev::Image(..), _) => vec![Request::GoodbyeImages],
            (_, Some(d)) => vec![Request::Unsubscribe(d)],
            (Dev::Wired(w), None) => w.farewell(),
        };
        if !matches!(self.dev, Dev::Image(..)) {
            farewell.push(Request::Goodbye);
        }
        let _ = self.send(&s.stream, &farewell);
    }
}

impl Link {
    /// Registers a renewed command's stop (motors: `22 0.0 0.0`, `23 0.0 0.0`)
    /// with [`estop`], written through a second handle on the connection (each
    /// request a line of its own, in one write).
    fn register_stop(&self, stream: &TcpStream) -> Option<estop::Registration> {
        let Dev::Wired(w) = &self.dev else {
            return None;
        };
        let mut out = Vec::new();
        for r in w.stop()? {
            r.write_to(&mut out);
        }
        match stream.try_clone() {
            Ok(s) => Some(estop::register(
                format!("networkclient {} {}", self.remote.name, self.where_()),
                move || {
                    let _ = (&s).write_all(&out);
                },
            )),
            Err(e) => {
                tracing::warn!(
                    "networkclient: no second handle on the connection to {} ({e}): a signal or a panic will not stop {} first",
                    self.where_(),
                    self.remote.name
                );
                None
            }
        }
    }

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
                    (&s).write_all(&self.hello)?;
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
            let m = Message::parse(line).map_err(bad_line)?;
            self.publish(m).map_err(bad_line)?;
        }
        Ok(())
    }

    /// Publishes a push of this device's feed; logs the server's errors.
    fn publish(&self, m: Message) -> Result<(), WireError> {
        match (&self.dev, m) {
            (Dev::Wired(w), Message::Push { feed, fields }) if Some(feed) == self.dev.feed() => {
                w.take_push(feed.codes().2, &fields, &self.from)?;
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
        Ok(())
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
        let m = Message::parse(line).map_err(bad_line)?;
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
            other => return self.publish(other).map_err(bad_line),
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
        let rest = bytes - lr.pending().min(bytes);
        if rest >= WAKE_ONCE_FROM {
            wait_for_bytes(s, rest, SENSOR_TICK);
        }
        // One deadline for the whole frame, from the slowest link served, and
        // FRAME_STALL without a byte (`stall`: the bytes in, and since when).
        let t0 = Instant::now();
        let within = FRAME_STALL.max(Duration::from_secs_f64(bytes as f64 / SLOWEST_LINK));
        let mut stall = (0, t0);
        lr.read_exact(&mut &*s, buf, |done| {
            let now = Instant::now();
            if done != stall.0 {
                stall = (done, now);
            }
            !stop.load(Ordering::Acquire) && now - stall.1 < FRAME_STALL && now - t0 < within
        })
        .map_err(|e| {
            let what = format!("a {width}x{height} frame ({bytes} bytes)");
            if !netwire::is_timeout(&e) || stop.load(Ordering::Acquire) {
                format!("while reading {what}: {e}")
            } else if stall.1.elapsed() >= FRAME_STALL {
                format!(
                    "no byte for {} s after {} bytes of {what}",
                    FRAME_STALL.as_secs(),
                    stall.0
                )
            } else {
                format!(
                    "{what} took over {:.0} s ({} bytes in): slower than {} KB/s",
                    within.as_secs_f64(),
                    stall.0,
                    SLOWEST_LINK / 1024.0
                )
            }
        })?;
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

    /// Sends the command when it changes (a renewed one also every 100 ms, a
    /// stale one as zero); takes the limits the server answers.
    fn command_step(
        &self,
        s: &TcpStream,
        lr: &mut LineReader,
        w: &dyn Wired,
        last_sent: &mut Instant,
        last_clock: &mut u64,
    ) -> Result<(), String> {
        let renewed = matches!(
            w.on_wire(),
            OnWire::Commanded {
                keep_alive: true,
                ..
            }
        );
        let clock = w.interface().clock();
        let due = renewed && last_sent.elapsed() >= Duration::from_millis(100);
        if clock != *last_clock || due {
            if clock > 0 || renewed {
                // Once the process is ending (estop::halt), nothing but zero.
                let reqs = match w.stop().filter(|_| estop::halted()) {
                    Some(zero) => zero,
                    None => w.requests(self.timeout),
                };
                self.send(s, &reqs)?;
            }
            *last_clock = clock;
            *last_sent = Instant::now();
        }
        // The read doubles as the tick's sleep and notices a closed server.
        if let Some(line) = self.next_line(lr, s)? {
            match Message::parse(line).map_err(bad_line)? {
                Message::Limits { code, fields } => {
                    if let Some(k) = w.take_limits(code, &fields).map_err(bad_line)? {
                        *last_clock = k;
                    }
                }
                m => self.publish(m).map_err(bad_line)?,
            }
        }
        Ok(())
    }
}

/// Waits (at most `timeout`) until `bytes` have arrived on the socket, woken once:
/// the receive low-water mark is set to `bytes` for a `poll`, then back to 1.
/// Not for the read itself: the kernel wakes a blocked reader when the bytes not
/// yet copied reach the mark, so a read that copied part of a frame would then
/// wait for a whole mark more (until the next frame or its timeout). Linux caps
/// the mark at half the largest receive buffer and grows the buffer to hold it;
/// on a timeout, an error, or the peer closing, `poll` returns and the read that
/// follows says what happened.
fn wait_for_bytes(s: &TcpStream, bytes: usize, timeout: Duration) {
    let mark = |v: usize| {
        let v = v.min(i32::MAX as usize) as libc::c_int;
        sockets::set_int_option(s, libc::SOL_SOCKET, libc::SO_RCVLOWAT, v).is_ok()
    };
    if mark(bytes) {
        sockets::wait_readable(s, timeout);
        mark(1);
    }
}

/// The error of a line from the server that is not what the wire allows.
fn bad_line(e: WireError) -> String {
    format!("the server sent a bad line: {e}")
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
    lines = Lines
);
