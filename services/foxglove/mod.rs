//! Service `foxglove`: a Foxglove WebSocket server (ws-protocol v1) on the official
//! Foxglove SDK (the `foxglove` crate), so the Foxglove app or Lichtblick shows a
//! running robot live (laser in 3D, the camera, the path, plots) and its Teleop
//! panel drives it. See `docs/foxglove.md`.
//!
//! # Conf
//! ```text
//! service foxglove
//! bind 127.0.0.1        # the address it listens on (default loopback; beyond it
//!                       #   only with `token` or `insecure`, e.g. 0.0.0.0)
//! port 8765             # the TCP port (default 8765; 0 = any free port)
//! sdk_port 8766         # off by default: a second port, the same server
//! serves all            # every interface (the default when no `serves` line), or
//! serves laser          #   one by one
//! images raw            # raw (RawImage bgr8, default) | jpeg [QUALITY 1..100, default 80]
//! world on              # the world map (name-space `world.map`, `world.balls`) as a SceneUpdate
//! max_queue 16          # message frames waiting per client; a slow client loses the oldest
//! max_message 65536     # bytes: a longer client message closes its connection (1009)
//! max_clients 64        # connections at once; when full the longest idle one is closed
//! token SECRET          # off by default: clients connect to ws://HOST:8765/?token=SECRET
//! tls cert.pem key.pem  # off by default: wss:// on both ports (PEM certificate chain, key)
//! insecure              # off by default: beyond loopback without TLS and a token, on purpose
//! end_service
//! ```
//!
//! # Interfaces
//! Provides none; serves the local ones ([`channels`] says each kind's channel and
//! schema, in m, rad and Foxglove's frames `odom`, `base_link`, `camera`). A
//! channel's interface is resumed while a client subscribes to it and suspended
//! when the last one leaves (so a simulator renders a camera only while it is
//! watched). Clients may publish (capability `clientPublish`, encoding `json`): a
//! Twist (`geometry_msgs/msg/Twist` shape, linear m/s, angular rad/s; the Teleop
//! panel's message) on `/cmd_vel` or on the motors' name drives `motors` (mm/s,
//! deg/s; a value beyond the `motors` interface's range is refused and told); a
//! jderobot value on a served actuator's name writes it. When a client that drove
//! the motors leaves (or unadvertises), the motors are set to zero. Services `run`,
//! `stop`, `show`, `hide` (`{"name": "introrob"}`) do what the shell's commands do;
//! parameters are the interfaces as `echo` prints them, and setting `motors.v` (or
//! `motors` = `"v=100 w=5"`) does what `set` does.
//!
//! # Subprotocols, the front door and its limits
//! The SDK's server accepts `foxglove.sdk.v1`/`v1.1` only; `@foxglove/ws-protocol`
//! 0.8.0 and Lichtblick offer `foxglove.websocket.v1` only. Both ports (`port`, and
//! `sdk_port` when set) are a front door ([`relay`]): it caps the connections,
//! reads the upgrade request and checks the token, then hands the socket to the
//! SDK's server (the vendored SDK's `serve_stream`) wrapped in its limits: the
//! subprotocol renamed in the handshake for legacy clients, the client's frame
//! headers checked before the SDK reads them, the SDK's frames written straight
//! to the client. A client that stops reading loses its own oldest message
//! frames in the SDK's backlog (`max_queue`), and is closed after taking nothing
//! for 15 s. Images are paced to the clients: a new frame is encoded only while
//! fewer than 4 are on their way to them (the door counts what their sockets
//! take; at least one every 100 ms), so a camera faster than the fastest client
//! costs no encoding of frames the backlog would drop; client messages over
//! `max_message`, unfinished for 10 s, or over 100 pings a second close the
//! connection (1009, 1008). Garbage JSON gets an error status from the SDK; a
//! request that is not a WebSocket upgrade gets `400`, a missing or wrong token
//! `401`. At most `max_clients` connections at once (both ports): a new one
//! closes the longest idle; running out of descriptors does the same, and the
//! door keeps accepting.
//!
//! Beyond loopback the service refuses to start without both `tls CERT.pem
//! KEY.pem` and `token SECRET` (or an `insecure` line saying so on purpose): the
//! token travels in the URL, so it must not cross the network in the clear. With
//! `tls`, both ports speak `wss://` only ([`tls`]: rustls in front of the door).
//!
//! System packages: none (tokio and the SDK are compiled in).

pub mod channels;
pub mod control;
pub mod relay;
pub mod tls;

use std::{
    collections::HashMap,
    net::{IpAddr, Ipv4Addr, SocketAddr},
    path::PathBuf,
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, Instant, SystemTime},
};

use ::foxglove::{
    ChannelBuilder, Context, WebSocketServer, WebSocketServerHandle,
    schemas::{FrameTransform, SceneUpdate},
    websocket::Capability,
};
use anyhow::Context as _;
use parking_lot::Mutex;

use crate::{
    conf::{
        ComponentConf, ConfError,
        settings::{self, Setting, choice, int, on_off, path, word},
    },
    interfaces::{self, AnyInterface, Watch},
    mcapfmt::{Snapshot, Source},
    runtime::{Driver, Runtime},
    supervisor::Worker,
    world::{self, LiveBalls, World},
};
use channels::{Out, Served};
use control::{Counters, Listener, Params, Wanted};
use relay::{Limits, RelayStats};

/// The service's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    pub bind: IpAddr,
    pub port: u16,
    /// A second port to the same server (the same front door), if any.
    pub sdk_port: Option<u16>,
    /// Interface names; empty: all.
    pub serves: Vec<String>,
    pub jpeg: Option<u8>,
    pub world: bool,
    pub limits: Limits,
    /// Beyond loopback without TLS and a token, said on purpose (`insecure`).
    pub insecure: bool,
    /// `wss://` on both ports: the certificate chain and the private key (PEM).
    pub tls: Option<(PathBuf, PathBuf)>,
}

crate::declare_lines! {
    struct Lines {
        bind: String = settings::BIND,
        port: u16 = Setting::new(
            "port",
            "the TCP port (0: any free port)",
            &[int("PORT", "", 0, 65_535)],
        )
        .default("8765"),
        sdk_port: Option<u16> = Setting::new(
            "sdk_port",
            "a second port to the same server, at the same `bind`, through the same front door \
             (the same limits and token; 0: any free port)",
            &[int("PORT", "", 0, 65_535)],
        ),
        serves: Vec<String> = Setting::new(
            "serves",
            "an interface to serve as a channel; `serves all` (the default when none): every one",
            &[word("NAME")],
        )
        .repeats(),
        images: (String, Option<u8>) = Setting::new(
            "images",
            "images as raw BGR (foxglove.RawImage), or JPEG of QUALITY (foxglove.CompressedImage, default 80)",
            &[choice("ENCODING", &["raw", "jpeg"]), int("QUALITY", "", 1, 100).optional()],
        )
        .default("raw"),
        world: bool = Setting::new(
            "world",
            "the world map (walls, boxes, balls) as a foxglove.SceneUpdate on `world`",
            &[on_off("WORLD")],
        )
        .default("on"),
        max_queue: usize = Setting::new(
            "max_queue",
            "message frames waiting per client; a client that does not read loses the oldest",
            &[int("N", "", 1, 4096)],
        )
        .default("16"),
        max_message: usize = Setting::new(
            "max_message",
            "the longest message a client may send; a longer one closes its connection",
            &[int("BYTES", "bytes", 1024, 16 << 20)],
        )
        .default("65536"),
        max_clients: usize = Setting::new(
            "max_clients",
            "connections at once over both ports; when full, the one idle longest is closed to admit a new one",
            &[int("N", "", 1, 4096)],
        )
        .default("64"),
        token: Option<String> = settings::TOKEN.help(
            "a secret clients must present (ws://HOST:PORT/?token=SECRET, or `Authorization: Bearer SECRET`)",
        ),
        #[allow(dead_code)] // read through `existing_file`, which checks them
        tls: Option<(String, String)> = Setting::new(
            "tls",
            "serve wss:// (TLS) on both ports with this certificate chain and its private key (PEM files)",
            &[path("CERT.pem"), path("KEY.pem")],
        ),
        /// `settings::guard_listen` reads the `insecure` line from the conf itself.
        #[serde(rename = "insecure", default)]
        _insecure: bool = settings::INSECURE,
    }
}
/// Reads the conf (every error names file:line and the fix).
pub fn parse(conf: &ComponentConf) -> Result<Settings, ConfError> {
    let lines: Lines = conf.read()?;
    let bind = match lines.bind.parse::<IpAddr>() {
        Ok(a) => a,
        Err(_) => {
            let l = conf
                .line("bind")
                .expect("a non-default bind comes from a line");
            return Err(l.error(format!(
                "`bind`: `{}` is not an IP address; expected one such as 127.0.0.1 or 0.0.0.0",
                crate::conf::settings::echo(&lines.bind)
            )));
        }
    };
    let jpeg = match lines.images {
        (e, Some(q)) if e == "jpeg" => Some(q),
        (e, None) if e == "jpeg" => Some(80),
        (_, None) => None,
        (_, Some(_)) => {
            let l = conf.line("images").expect("a quality comes from a line");
            return Err(l.error(
                "`images raw` takes no quality; usage: images raw | images jpeg [QUALITY]",
            ));
        }
    };
    if let Some(p) = lines.sdk_port
        && p != 0
        && p == lines.port
    {
        let l = conf.line("sdk_port").expect("sdk_port comes from a line");
        return Err(l.error(format!(
            "`sdk_port {p}` is the relay's `port` too; give the SDK's server another port (or 0)"
        )));
    }
    let mut serves = Vec::new();
    for name in lines.serves {
        if name == "all" {
            serves.clear();
            serves.push("all".to_string());
        } else if !serves.iter().any(|s| s == "all") {
            serves.push(interfaces::canonical(&name));
        }
    }
    if serves.iter().any(|s| s == "all") {
        serves.clear();
    }
    let tls = match conf.line("tls") {
        Some(l) => {
            let cert = l.existing_file(0, "the certificate chain")?;
            let key = l.existing_file(1, "the private key")?;
            tls::server_config(&cert, &key).map_err(|e| l.error(format!("`tls`: {e}")))?;
            Some((cert, key))
        }
        None => None,
    };
    let add_one = match (&lines.token, &tls) {
        (Some(_), None) => {
            "add `tls CERT.pem KEY.pem` too, so the token does not cross the network in the \
             clear (clients then connect to wss://HOST:PORT/?token=SECRET)"
        }
        (None, Some(_)) => {
            "add `token SECRET` too (clients connect to wss://HOST:PORT/?token=SECRET)"
        }
        _ => {
            "add `tls CERT.pem KEY.pem` and `token SECRET` (clients connect to \
             wss://HOST:PORT/?token=SECRET)"
        }
    };
    let exposure = settings::guard_listen(
        conf,
        "bind",
        &bind.to_string(),
        lines.token.is_some() && tls.is_some(),
        add_one,
    )?;
    Ok(Settings {
        bind,
        port: lines.port,
        sdk_port: lines.sdk_port,
        serves,
        jpeg,
        world: lines.world,
        limits: Limits {
            max_queue: lines.max_queue,
            max_message: lines.max_message,
            max_clients: lines.max_clients,
            token: lines.token,
        },
        insecure: exposure == settings::Exposure::Insecure,
        tls,
    })
}

/// What `ps` shows of a running server (exported as `<name>.status`).
pub struct Status {
    /// `ws` or `wss` (`tls`).
    pub scheme: &'static str,
    pub addr: SocketAddr,
    /// The second port (`sdk_port`), if it was asked for.
    pub direct: Option<SocketAddr>,
    pub relay: Arc<RelayStats>,
    pub counters: Arc<Counters>,
}

impl Status {
    /// One line: `ws://127.0.0.1:8765: 2 client(s), 1234 message(s) sent, 0 evicted, ...`.
    pub fn line(&self) -> String {
        let r = &self.relay;
        let direct = self
            .direct
            .map(|d| format!("; also {}://{d} (sdk_port)", self.scheme))
            .unwrap_or_default();
        format!(
            "{}://{}: {} client(s), {} message(s) sent, {} evicted (max_clients), {} command(s), {} refused{direct}",
            self.scheme,
            self.addr,
            r.clients.load(Ordering::Relaxed),
            r.sent.load(Ordering::Relaxed),
            r.evicted.load(Ordering::Relaxed),
            self.counters.commands.load(Ordering::Relaxed),
            self.counters.refused.load(Ordering::Relaxed) + r.refused.load(Ordering::Relaxed),
        )
    }
}

/// The name under which the service exports its [`Status`].
pub const STATUS_EXPORT: &str = "status";

// Its `ps` line: `foxglove: ws://...: N client(s), ...`.
crate::register_ps_line!("foxglove", |rt| {
    rt.names
        .import::<Status>("foxglove", STATUS_EXPORT)
        .ok()
        .map(|s| s.line())
});
/// The name under which the service exports the [`SocketAddr`] users connect to.
pub const ADDRESS_EXPORT: &str = "address";
/// The name under which the service exports the SDK server's own [`SocketAddr`]
/// (only with `sdk_port`).
pub const SDK_ADDRESS_EXPORT: &str = "sdk_address";

/// Threads of the server's tokio runtime (the SDK's writers and the front door).
const IO_THREADS: usize = 2;

/// Raises the soft limit of open files to the hard one, so idle clients meet the
/// connection cap (`max_clients`) long before the process runs out of descriptors.
fn raise_fd_limit() {
    let mut l = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit/setrlimit on a struct we own.
    unsafe {
        if libc::getrlimit(libc::RLIMIT_NOFILE, &mut l) == 0 && l.rlim_cur < l.rlim_max {
            l.rlim_cur = l.rlim_max;
            let _ = libc::setrlimit(libc::RLIMIT_NOFILE, &l);
        }
    }
}

/// The world map's channel and sources.
struct WorldOut {
    channel: ::foxglove::Channel<SceneUpdate>,
    map: Option<Arc<World>>,
    balls: Option<Arc<LiveBalls>>,
}

/// A running server.
pub struct Foxglove {
    /// The SDK's context of the channels (the server and channels hold it weakly).
    _ctx: Arc<Context>,
    runtime: Option<tokio::runtime::Runtime>,
    /// The SDK's server, which the door hands its checked sockets to.
    server: Arc<Mutex<Option<WebSocketServerHandle>>>,
    /// The publishing thread, which sleeps on `watch`.
    worker: Worker,
    watch: Arc<Watch>,
    wanted: Arc<Vec<Wanted>>,
    addr: SocketAddr,
    direct: Option<SocketAddr>,
}

impl Foxglove {
    /// The address users connect to.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Where the SDK's server listens itself (with `sdk_port`).
    pub fn sdk_addr(&self) -> Option<SocketAddr> {
        self.direct
    }

    fn stop(&mut self) {
        let watch = &self.watch;
        self.worker.stop_waking(|| watch.wake());
        let server = self.server.lock().take();
        if let Some(s) = server {
            let h = s.stop();
            if let Some(rt) = &self.runtime {
                let _ = rt.block_on(async {
                    tokio::time::timeout(Duration::from_secs(2), h.wait()).await
                });
            }
        }
        if let Some(rt) = self.runtime.take() {
            rt.shutdown_timeout(Duration::from_secs(1));
        }
        // Interfaces still resumed for subscribers are released.
        for w in self.wanted.iter() {
            if w.subs.swap(0, Ordering::AcqRel) > 0
                && let Some(i) = &w.iface
                && !i.is_actuator()
            {
                i.suspend();
            }
        }
    }
}

impl Driver for Foxglove {
    fn terminate(&mut self) {
        self.stop();
    }
}

impl Drop for Foxglove {
    fn drop(&mut self) {
        self.stop();
    }
}

/// The local interfaces to serve.
fn served_interfaces(s: &Settings, rt: &Runtime) -> anyhow::Result<Vec<Arc<dyn AnyInterface>>> {
    if s.serves.is_empty() {
        return Ok(rt.interfaces.all());
    }
    s.serves
        .iter()
        .map(|name| {
            rt.interfaces.get_any(name).map_err(|_| {
                anyhow::anyhow!(
                    "foxglove: `serves {name}`: no such interface here (have: {}); load the \
                     driver that provides it before foxglove",
                    rt.interfaces.names().join(", ")
                )
            })
        })
        .collect()
}

/// The channels of the served interfaces and of the world map: what the
/// publishing thread sends and what the listener gates.
struct Plan {
    served: Vec<Served>,
    world: Option<WorldOut>,
    wanted: Vec<Wanted>,
    /// Channel id → the entries of `wanted` it gates.
    by_channel: HashMap<::foxglove::ChannelId, Vec<usize>>,
    actuators: HashMap<String, Arc<dyn AnyInterface>>,
}

/// Step 1 of [`start`]: a channel (and `/tf`) per served interface, and the world's.
fn plan(s: &Settings, rt: &Runtime, ctx: &Arc<Context>) -> anyhow::Result<Plan> {
    let tf = Arc::new(
        ChannelBuilder::new(channels::TF)
            .context(ctx)
            .build::<FrameTransform>(),
    );
    let mut p = Plan {
        served: Vec::new(),
        world: None,
        wanted: Vec::new(),
        by_channel: HashMap::new(),
        actuators: HashMap::new(),
    };
    for i in served_interfaces(s, rt)? {
        let Some(source) = Source::find(&rt.interfaces, i.name()) else {
            continue;
        };
        if i.is_actuator() {
            p.actuators.insert(i.name().to_string(), i.clone());
        }
        let out = Out::new(
            ctx,
            i.name(),
            i.kind(),
            channels::Opts { jpeg: s.jpeg },
            &tf,
        )?;
        for id in out.channel_ids() {
            p.by_channel.entry(id).or_default().push(p.served.len());
        }
        p.wanted.push(Wanted::new(Some(i.clone())));
        p.served.push(Served {
            name: i.name().to_string(),
            source,
            out,
        });
    }
    if s.world {
        let map = world::map(&rt.names);
        let balls = world::balls(&rt.names);
        if map.is_some() || balls.is_some() {
            let channel = ChannelBuilder::new(channels::WORLD)
                .context(ctx)
                .build::<SceneUpdate>();
            p.by_channel
                .entry(channel.id())
                .or_default()
                .push(p.wanted.len());
            p.wanted.push(Wanted::new(None));
            p.world = Some(WorldOut {
                channel,
                map,
                balls,
            });
        }
    }
    Ok(p)
}

/// Step 3 of [`start`]: the door on `port` (and `sdk_port`): their addresses.
fn listen(
    s: &Settings,
    runtime: &tokio::runtime::Runtime,
    door: &Arc<relay::Door>,
) -> anyhow::Result<Vec<SocketAddr>> {
    let acceptor = match &s.tls {
        Some((cert, key)) => Some(tokio_rustls::TlsAcceptor::from(
            tls::server_config(cert, key).map_err(|e| anyhow::anyhow!("foxglove: `tls`: {e}"))?,
        )),
        None => None,
    };
    let mut addrs = Vec::new();
    for port in std::iter::once(s.port).chain(s.sdk_port) {
        let std_listener = std::net::TcpListener::bind((s.bind, port)).with_context(|| {
            format!(
                "foxglove: cannot listen on {}:{port} (is another program using the port? `port 0` takes any free one)",
                s.bind
            )
        })?;
        std_listener.set_nonblocking(true)?;
        addrs.push(std_listener.local_addr()?);
        let _g = runtime.enter();
        let listener = tokio::net::TcpListener::from_std(std_listener)?;
        let Some(acceptor) = &acceptor else {
            runtime.spawn(relay::accept_loop(listener, door.clone()));
            continue;
        };
        // TLS on the public port, the door behind it on a loopback port of its own.
        let plain = std::net::TcpListener::bind((Ipv4Addr::LOCALHOST, 0))
            .context("foxglove: cannot listen on a loopback port for the door behind TLS")?;
        plain.set_nonblocking(true)?;
        let door_addr = plain.local_addr()?;
        let plain = tokio::net::TcpListener::from_std(plain)?;
        runtime.spawn(relay::accept_loop(plain, door.clone()));
        runtime.spawn(tls::accept_loop(
            listener,
            acceptor.clone(),
            door_addr,
            door.clone(),
            s.limits.max_clients,
        ));
    }
    Ok(addrs)
}

/// Starts the server with settings `s` on the interfaces of `rt`.
pub fn start(s: &Settings, rt: &Runtime) -> anyhow::Result<Foxglove> {
    let ctx = Context::new();
    let Plan {
        served,
        world,
        wanted,
        by_channel,
        actuators,
    } = plan(s, rt, &ctx)?;
    let wanted = Arc::new(wanted);
    let counters = Arc::new(Counters::default());
    let relay_stats = Arc::new(RelayStats::default());

    // The publishing thread and its watch.
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    let worker = {
        let stop2 = stop.clone();
        let wanted = wanted.clone();
        let pace = Pace::new(relay_stats.clone(), served.len());
        Worker::start("foxglove", stop, move || {
            let watch = Watch::for_current_thread();
            let _ = tx.send(watch.clone());
            publish_loop(served, world, &wanted, &watch, &stop2, pace);
        })
        .context("foxglove: cannot start its thread")?
    };
    let watch = rx.recv().context("foxglove: its thread did not start")?;
    let _ = relay_stats.taken.set(watch.clone());
    let mut me = Foxglove {
        _ctx: ctx.clone(),
        runtime: None,
        server: Arc::new(Mutex::new(None)),
        worker,
        watch: watch.clone(),
        wanted: wanted.clone(),
        addr: SocketAddr::new(s.bind, s.port),
        direct: None,
    };

    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(IO_THREADS)
        .thread_name("foxglove-io")
        .enable_all()
        .build()
        .context("foxglove: cannot start its tokio runtime")?;
    let listener = Arc::new(Listener {
        by_channel,
        wanted,
        actuators,
        rt: rt.arc(),
        drivers: Mutex::new(HashMap::new()),
        wake: watch,
        counters: counters.clone(),
    });
    let sdk = start_sdk(&ctx, runtime.handle(), rt, listener, s.limits.max_queue)?;
    *me.server.lock() = Some(sdk);
    raise_fd_limit();
    let slot = me.server.clone();
    let serve: relay::Serve = Arc::new(move |stream, peer| {
        slot.lock()
            .as_ref()
            .is_some_and(|server| server.serve_stream(stream, peer))
    });
    let door = relay::Door::new(serve, s.limits.clone(), relay_stats.clone());
    let addrs = listen(s, &runtime, &door)?;
    let addr = addrs[0];
    me.addr = addr;
    me.direct = addrs.get(1).copied();
    me.runtime = Some(runtime);
    let scheme = if s.tls.is_some() { "wss" } else { "ws" };
    // Without TLS and a token, `settings::guard_listen` said so when the conf was read.
    if !s.bind.is_loopback() && !s.insecure {
        tracing::info!(
            "foxglove: listening beyond loopback on {addr}; clients need the token (wss://HOST:PORT/?token=...)"
        );
    }
    tracing::info!("foxglove: listening on {scheme}://{addr}");
    if let Some(d) = me.direct {
        tracing::info!("foxglove: and on {scheme}://{d} (`sdk_port`)");
    }
    let _ = rt.names.export(
        "foxglove",
        STATUS_EXPORT,
        Status {
            scheme,
            addr,
            direct: me.direct,
            relay: relay_stats,
            counters,
        },
    );
    Ok(me)
}

/// Starts the SDK's server, which binds no port of its own (the vendored SDK's
/// `handed_streams_only`): it serves only the sockets the front door checked and
/// hands it, so nothing reaches it around the door's token and cap.
fn start_sdk(
    ctx: &Arc<Context>,
    io: &tokio::runtime::Handle,
    rt: &Runtime,
    listener: Arc<Listener>,
    backlog: usize,
) -> anyhow::Result<WebSocketServerHandle> {
    WebSocketServer::new()
        .name("jderobot")
        .context(ctx)
        .handed_streams_only()
        .tokio_runtime(io)
        .capabilities([
            Capability::ClientPublish,
            Capability::Services,
            Capability::Parameters,
        ])
        .supported_encodings(["json"])
        .services(control::services(&rt.arc()))
        .parameter_handler(Arc::new(Params { rt: rt.arc() }))
        .listener(listener)
        .message_backlog_size(backlog)
        .start_blocking()
        .map_err(|e| anyhow::anyhow!("foxglove: the SDK's server did not start: {e}"))
}

/// Image frames logged ahead of what the clients have taken: the SDK's queues and
/// the sockets hold them; more would only be dropped by the SDK's backlog.
const FRAMES_AHEAD: u64 = 4;
/// An image is logged at least this often even when no client takes anything
/// (a new or a stalled client still gets frames).
const PACE_FLOOR: Duration = Duration::from_millis(100);

/// Paces images to the clients: a frame is encoded and logged only while fewer
/// than [`FRAMES_AHEAD`] are on their way, counted by the door's `sent` (message
/// frames the clients' sockets took, every client and port). A camera faster
/// than the fastest client thus costs no encoding and no copy of the frames the
/// SDK's backlog would drop; a slow client next to a fast one still loses only
/// its own frames (the fast one's progress paces the logging).
struct Pace {
    sent: Arc<RelayStats>,
    seen: u64,
    credit: Vec<u64>,
    logged_at: Vec<Instant>,
}

impl Pace {
    fn new(sent: Arc<RelayStats>, n: usize) -> Pace {
        let seen = sent.sent.load(Ordering::Relaxed);
        Pace {
            sent,
            seen,
            credit: vec![FRAMES_AHEAD; n],
            logged_at: vec![Instant::now(); n],
        }
    }

    /// Adds what the clients took since the last call to every channel's credit.
    fn refill(&mut self) {
        let now = self.sent.sent.load(Ordering::Relaxed);
        let took = now.wrapping_sub(self.seen);
        self.seen = now;
        for c in &mut self.credit {
            *c = (*c + took).min(FRAMES_AHEAD);
        }
    }

    /// Whether served interface `i`'s new image may go now (then it is counted).
    fn take(&mut self, i: usize, greet: bool) -> bool {
        if self.credit[i] == 0 && !greet && self.logged_at[i].elapsed() < PACE_FLOOR {
            return false;
        }
        self.credit[i] = self.credit[i].saturating_sub(1);
        self.logged_at[i] = Instant::now();
        true
    }
}

/// Sends each wanted interface's new values, and the world, until `stop`.
fn publish_loop(
    served: Vec<Served>,
    world: Option<WorldOut>,
    wanted: &[Wanted],
    watch: &Arc<Watch>,
    stop: &AtomicBool,
    mut pace: Pace,
) {
    for s in &served {
        s.source.any().watch(watch.clone());
    }
    // An image channel out of credit is not watched: the camera's frames would
    // only wake this thread to skip them; the door wakes it when a client takes one.
    let mut watched = vec![true; served.len()];
    let mut last = vec![0u64; served.len()];
    let mut buf = Vec::new();
    let mut balls_at = Instant::now();
    while !stop.load(Ordering::Acquire) {
        watch.wait(Duration::from_millis(100));
        pace.refill();
        for (i, s) in served.iter().enumerate() {
            if !watched[i] && pace.credit[i] > 0 {
                s.source.any().watch(watch.clone());
                watched[i] = true;
            }
        }
        for (i, s) in served.iter().enumerate() {
            let w = &wanted[i];
            if w.subs.load(Ordering::Acquire) == 0 {
                continue;
            }
            let greet = w.greet.swap(false, Ordering::AcqRel);
            if greet {
                last[i] = 0;
            }
            let snap = s.source.snapshot();
            let clock = snap.clock();
            if clock == 0 || clock == last[i] {
                continue;
            }
            if matches!(snap, Snapshot::Image(_)) && !pace.take(i, greet) {
                if watched[i] {
                    s.source.any().unwatch(&**watch);
                    watched[i] = false;
                }
                continue;
            }
            last[i] = clock;
            s.out.log(&s.name, &snap, &mut buf);
        }
        if let Some(wo) = &world {
            send_world(wo, &wanted[served.len()], &mut balls_at);
        }
    }
    for (s, _) in served.iter().zip(&watched).filter(|(_, w)| **w) {
        s.source.any().unwatch(&**watch);
    }
}

/// The world's scene update: the map when a client subscribes, the balls at 10 Hz.
fn send_world(wo: &WorldOut, w: &Wanted, balls_at: &mut Instant) {
    if w.subs.load(Ordering::Acquire) == 0 {
        return;
    }
    let now = SystemTime::now();
    let mut entities = Vec::new();
    if w.greet.swap(false, Ordering::AcqRel)
        && let Some(m) = &wo.map
    {
        entities.push(channels::world_entity(now, m));
    }
    if let Some(b) = &wo.balls
        && (!entities.is_empty() || balls_at.elapsed() >= Duration::from_millis(100))
    {
        *balls_at = Instant::now();
        entities.push(channels::balls_entity(now, &b.load()));
    }
    if !entities.is_empty() {
        wo.channel.log(&channels::scene(entities));
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let s = parse(conf)?;
    let server = start(&s, rt)?;
    let _ = rt
        .names
        .export(&conf.name, ADDRESS_EXPORT, server.local_addr());
    if let Some(d) = server.sdk_addr() {
        let _ = rt.names.export(&conf.name, SDK_ADDRESS_EXPORT, d);
    }
    Ok(Box::new(server))
}

crate::register_driver!(
    Service,
    "foxglove",
    "a Foxglove WebSocket server (the official SDK): the app's 3D, image, plot and teleop panels on this robot",
    create,
    lines = Lines
);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conf::Kind;

    fn parse_text(text: &str) -> Result<Settings, String> {
        parse(&ComponentConf::from_text(Kind::Service, "foxglove", text).unwrap())
            .map_err(|e| e.to_string())
    }

    #[test]
    fn lines_are_read_with_defaults() {
        let d = parse_text("").unwrap();
        assert_eq!(d.bind, IpAddr::V4(Ipv4Addr::LOCALHOST));
        assert_eq!((d.port, d.jpeg, d.world), (8765, None, true));
        assert_eq!(d.sdk_port, None);
        assert_eq!(parse_text("sdk_port 8766\n").unwrap().sdk_port, Some(8766));
        assert!(d.serves.is_empty());
        assert_eq!((d.limits.max_queue, d.limits.max_message), (16, 65536));
        let s = parse_text(
            "bind 0.0.0.0\ninsecure\nport 0\nserves laser\nserves ptencoders\nimages jpeg 60\nworld off\nmax_queue 4\nmax_message 2048\n",
        )
        .unwrap();
        assert!(!s.bind.is_loopback());
        assert_eq!(s.serves, vec!["laser", "pantiltencoders"]);
        assert_eq!((s.port, s.jpeg, s.world), (0, Some(60), false));
        assert_eq!((s.limits.max_queue, s.limits.max_message), (4, 2048));
        assert!(
            parse_text("serves laser\nserves all\n")
                .unwrap()
                .serves
                .is_empty()
        );
    }

    #[test]
    fn images_are_paced_by_what_the_clients_took() {
        let stats = Arc::new(RelayStats::default());
        let mut p = Pace::new(stats.clone(), 2);
        // FRAMES_AHEAD frames go, then none until a client takes one.
        for _ in 0..FRAMES_AHEAD {
            assert!(p.take(0, false));
        }
        assert!(!p.take(0, false));
        // A new subscriber is greeted whatever the credit; the other channel has its own.
        assert!(p.take(0, true));
        assert!(p.take(1, false));
        stats.sent.fetch_add(1, Ordering::Relaxed);
        p.refill();
        assert!(p.take(0, false));
        assert!(!p.take(0, false));
        // Taken frames never give more than FRAMES_AHEAD of credit.
        stats.sent.fetch_add(100, Ordering::Relaxed);
        p.refill();
        assert_eq!(p.credit, vec![FRAMES_AHEAD; 2]);
    }

    #[test]
    fn bad_lines_name_the_line_and_the_fix() {
        for (text, want) in [
            ("bind localhost\n", "is not an IP address"),
            ("port 70000\n", "between 0 and 65535"),
            ("sdk_port 8765\n", "the relay's `port` too"),
            ("sdk_port x\n", "sdk_port"),
            ("images raw 50\n", "takes no quality"),
            ("images png\n", "raw, jpeg"),
            ("max_message 10\n", "between 1024"),
            ("colour red\n", "takes no `colour` line"),
            (
                "bind 0.0.0.0\n",
                "`tls CERT.pem KEY.pem` and `token SECRET`",
            ),
            (
                "bind 0.0.0.0\ntoken 7f3a9c2e5b8d4f16a0c3e9b2d7f14a68\n",
                "add `tls CERT.pem KEY.pem` too",
            ),
            ("tls /nonexistent.pem k.pem\n", "the certificate chain"),
        ] {
            let e = parse_text(text).unwrap_err();
            assert!(e.contains(want) && e.contains(':'), "{text:?}: {e}");
        }
    }
}
