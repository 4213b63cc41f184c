//! Service `foxglove`: a Foxglove WebSocket server (ws-protocol v1) on the official
//! Foxglove SDK (the `foxglove` crate), so the Foxglove app or Lichtblick shows a
//! running robot live (laser in 3D, the camera, the path, plots) and its Teleop
//! panel drives it. See `docs/foxglove.md`.
//!
//! # Conf
//! ```text
//! service foxglove
//! bind 127.0.0.1        # the address it listens on (default loopback; beyond it
//!                       #   only when said here, e.g. 0.0.0.0)
//! port 8765             # the TCP port (default 8765; 0 = any free port)
//! sdk_port 8766         # off by default: the SDK's own server also listens here, at
//!                       #   the same `bind`, for `foxglove.sdk.v1` clients (no relay)
//! serves all            # every interface (the default when no `serves` line), or
//! serves laser          #   one by one
//! images raw            # raw (RawImage bgr8, default) | jpeg [QUALITY 1..100, default 80]
//! world on              # the world map (name-space `world.map`, `world.balls`) as a SceneUpdate
//! max_queue 16          # message frames waiting per client; a slow client loses the oldest
//! max_message 65536     # bytes: a longer client message closes its connection
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
//! deg/s); a jderobot value on a served actuator's name writes it. When a client
//! that drove the motors leaves (or unadvertises), the motors are set to zero.
//! Services `run`, `stop`, `show`, `hide` (`{"name": "introrob"}`) do what the
//! shell's commands do; parameters are the interfaces as `echo` prints them, and
//! setting `motors.v` (or `motors` = `"v=100 w=5"`) does what `set` does.
//!
//! # Subprotocols and the relay
//! The SDK's server accepts `foxglove.sdk.v1`/`v1.1` only; `@foxglove/ws-protocol`
//! 0.8.0 and Lichtblick offer `foxglove.websocket.v1` only. The port users connect
//! to is a thin relay ([`relay`]) in front of the SDK's server (on an ephemeral
//! loopback port): it renames the subprotocol for legacy clients, keeps a bounded
//! queue per client (a client that stops reading loses its oldest message frames,
//! counted in `ps`; the robot and other clients do not wait), and refuses client
//! messages over `max_message` (close 1009). Garbage JSON gets an error status from
//! the SDK; a request that is not a WebSocket upgrade gets `400`.
//!
//! With `sdk_port N` the SDK's server itself listens on N (same `bind`, same
//! loopback rule): clients that speak `foxglove.sdk.v1` (the current Foxglove app,
//! Lichtblick after its PR #819) connect to it without the relay's second loopback
//! crossing. Gating, teleop, services and parameters are the SDK listener's, so the
//! same on both ports; the queues and limits there are the SDK's own (1024 message
//! frames per client, oldest dropped and logged by the SDK, not counted in `ps`; no
//! `max_message`). `port` keeps the relay for both subprotocols.
//!
//! System packages: none (tokio and the SDK are compiled in; no TLS).

pub mod channels;
pub mod control;
pub mod relay;

use std::{
    collections::HashMap,
    net::{IpAddr, Ipv4Addr, SocketAddr},
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    thread::JoinHandle,
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
        settings::{self, Setting, choice, int, on_off, word},
    },
    interfaces::{self, AnyInterface, Watch},
    mcapfmt::Source,
    runtime::{Driver, Runtime},
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
    /// The port where the SDK's server listens itself (no relay), if any.
    pub sdk_port: Option<u16>,
    /// Interface names; empty: all.
    pub serves: Vec<String>,
    pub jpeg: Option<u8>,
    pub world: bool,
    pub limits: Limits,
}

const LINES: &[Setting] = &[
    settings::BIND,
    Setting::new(
        "port",
        "the TCP port (0: any free port)",
        &[int("PORT", "", 0, 65_535)],
    )
    .default("8765"),
    Setting::new(
        "sdk_port",
        "also serve `foxglove.sdk.v1` clients straight from the SDK's server on this port, \
         at the same `bind` (no relay: faster; the SDK's own queues; 0: any free port)",
        &[int("PORT", "", 0, 65_535)],
    ),
    Setting::new(
        "serves",
        "an interface to serve as a channel; `serves all` (the default when none): every one",
        &[word("NAME")],
    )
    .repeats(),
    Setting::new(
        "images",
        "images as raw BGR (foxglove.RawImage), or JPEG of QUALITY (foxglove.CompressedImage, default 80)",
        &[choice("ENCODING", &["raw", "jpeg"]), int("QUALITY", "", 1, 100).optional()],
    )
    .default("raw"),
    Setting::new(
        "world",
        "the world map (walls, boxes, balls) as a foxglove.SceneUpdate on `world`",
        &[on_off("WORLD")],
    )
    .default("on"),
    Setting::new(
        "max_queue",
        "message frames waiting per client; a client that does not read loses the oldest",
        &[int("N", "", 1, 4096)],
    )
    .default("16"),
    Setting::new(
        "max_message",
        "the longest message a client may send; a longer one closes its connection",
        &[int("BYTES", "bytes", 1024, 16 << 20)],
    )
    .default("65536"),
];

#[derive(serde::Deserialize)]
struct Lines {
    bind: String,
    port: u16,
    sdk_port: Option<u16>,
    serves: Vec<String>,
    images: (String, Option<u8>),
    world: bool,
    max_queue: usize,
    max_message: usize,
}

/// Reads the conf (every error names file:line and the fix).
pub fn parse(conf: &ComponentConf) -> Result<Settings, ConfError> {
    let lines: Lines = conf.settings(LINES)?;
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
        },
    })
}

/// What `ps` shows of a running server (exported as `<name>.status`).
pub struct Status {
    pub addr: SocketAddr,
    /// Where the SDK's server listens itself (`sdk_port`), if it was asked to.
    pub direct: Option<SocketAddr>,
    pub relay: Arc<RelayStats>,
    pub counters: Arc<Counters>,
}

impl Status {
    /// One line: `ws://127.0.0.1:8765: 2 client(s), 1234 sent, 5 dropped (slow clients), ...`.
    pub fn line(&self) -> String {
        let r = &self.relay;
        let direct = self
            .direct
            .map(|d| format!("; direct (SDK, foxglove.sdk.v1): ws://{d}"))
            .unwrap_or_default();
        format!(
            "ws://{}: {} client(s), {} message(s) sent, {} dropped (slow clients), {} command(s), {} refused{direct}",
            self.addr,
            r.clients.load(Ordering::Relaxed),
            r.sent.load(Ordering::Relaxed),
            r.dropped.load(Ordering::Relaxed),
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
    server: Option<WebSocketServerHandle>,
    stop: Arc<AtomicBool>,
    watch: Arc<Watch>,
    thread: Option<JoinHandle<()>>,
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
        self.stop.store(true, Ordering::Release);
        self.watch.wake();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        if let Some(s) = self.server.take() {
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

/// Starts the server with settings `s` on the interfaces of `rt`.
pub fn start(s: &Settings, rt: &Runtime) -> anyhow::Result<Foxglove> {
    let ifaces = served_interfaces(s, rt)?;
    let ctx = Context::new();
    let tf = Arc::new(
        ChannelBuilder::new(channels::TF)
            .context(&ctx)
            .build::<FrameTransform>(),
    );
    let mut served = Vec::new();
    let mut wanted = Vec::new();
    let mut by_channel: HashMap<::foxglove::ChannelId, Vec<usize>> = HashMap::new();
    let mut actuators = HashMap::new();
    for i in ifaces {
        let Some(source) = Source::find(&rt.interfaces, i.name()) else {
            continue;
        };
        if i.is_actuator() {
            actuators.insert(i.name().to_string(), i.clone());
        }
        let out = Out::new(&ctx, i.name(), i.kind(), s.jpeg, &tf)?;
        for id in out.channel_ids() {
            by_channel.entry(id).or_default().push(served.len());
        }
        wanted.push(Wanted::new(Some(i.clone())));
        served.push(Served {
            name: i.name().to_string(),
            source,
            out,
        });
    }
    let world = if s.world {
        let map = world::map(&rt.names);
        let balls = world::balls(&rt.names);
        (map.is_some() || balls.is_some()).then(|| {
            let channel = ChannelBuilder::new(channels::WORLD)
                .context(&ctx)
                .build::<SceneUpdate>();
            by_channel
                .entry(channel.id())
                .or_default()
                .push(wanted.len());
            wanted.push(Wanted::new(None));
            WorldOut {
                channel,
                map,
                balls,
            }
        })
    } else {
        None
    };
    let wanted = Arc::new(wanted);
    let counters = Arc::new(Counters::default());
    let relay_stats = Arc::new(RelayStats::default());

    // The publishing thread and its watch.
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    let thread = {
        let stop = stop.clone();
        let wanted = wanted.clone();
        std::thread::Builder::new()
            .name("foxglove".into())
            .spawn(move || {
                let watch = Watch::for_current_thread();
                let _ = tx.send(watch.clone());
                publish_loop(served, world, &wanted, &watch, &stop);
            })
            .context("foxglove: cannot start its thread")?
    };
    let watch = rx.recv().context("foxglove: its thread did not start")?;
    let mut me = Foxglove {
        _ctx: ctx.clone(),
        runtime: None,
        server: None,
        stop,
        watch: watch.clone(),
        thread: Some(thread),
        wanted: wanted.clone(),
        addr: SocketAddr::new(s.bind, s.port),
        direct: None,
    };

    // One I/O thread: the relay's frame copies stay on one core's caches (measured:
    // 64 % of the SDK alone's frame rate against 59 % with two, benches/foxglove.rs).
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("foxglove-io")
        .enable_all()
        .build()
        .context("foxglove: cannot start its tokio runtime")?;
    let listener = Listener {
        by_channel,
        wanted,
        actuators,
        rt: rt.arc(),
        drivers: Mutex::new(HashMap::new()),
        wake: watch,
        counters: counters.clone(),
    };
    // Without `sdk_port` the SDK's server is the relay's alone (an ephemeral loopback
    // port); with it, it listens where clients reach it, at the conf's `bind`.
    let sdk_host = match (s.sdk_port, s.bind) {
        (None, _) => Ipv4Addr::LOCALHOST.to_string(),
        (Some(_), IpAddr::V6(a)) => format!("[{a}]"),
        (Some(_), IpAddr::V4(a)) => a.to_string(),
    };
    let server = WebSocketServer::new()
        .name("jderobot")
        .context(&ctx)
        .bind(sdk_host, s.sdk_port.unwrap_or(0))
        .tokio_runtime(runtime.handle())
        .capabilities([
            Capability::ClientPublish,
            Capability::Services,
            Capability::Parameters,
        ])
        .supported_encodings(["json"])
        .services(control::services(&rt.arc()))
        .parameter_handler(Arc::new(Params { rt: rt.arc() }))
        .listener(Arc::new(listener))
        .message_backlog_size(1024)
        .start_blocking()
        .map_err(|e| anyhow::anyhow!("foxglove: the SDK's server did not start: {e}"))?;
    let inner_ip = match s.bind {
        _ if s.sdk_port.is_none() => IpAddr::V4(Ipv4Addr::LOCALHOST),
        IpAddr::V4(a) if a.is_unspecified() => IpAddr::V4(Ipv4Addr::LOCALHOST),
        IpAddr::V6(a) if a.is_unspecified() => IpAddr::V6(std::net::Ipv6Addr::LOCALHOST),
        a => a,
    };
    let inner = SocketAddr::new(inner_ip, server.port());
    if s.sdk_port.is_some() {
        me.direct = Some(SocketAddr::new(s.bind, server.port()));
    }
    me.server = Some(server);

    let std_listener = std::net::TcpListener::bind((s.bind, s.port)).with_context(|| {
        format!(
            "foxglove: cannot listen on {}:{} (is another program using the port? `port 0` takes any free one)",
            s.bind, s.port
        )
    })?;
    std_listener.set_nonblocking(true)?;
    let addr = std_listener.local_addr()?;
    me.addr = addr;
    let listener = {
        let _g = runtime.enter();
        tokio::net::TcpListener::from_std(std_listener)?
    };
    runtime.spawn(relay::accept_loop(
        listener,
        inner,
        s.limits,
        relay_stats.clone(),
    ));
    me.runtime = Some(runtime);
    if !s.bind.is_loopback() {
        tracing::warn!(
            "foxglove: listening beyond loopback on {addr} (the `bind` line): anyone who reaches it can drive the robot"
        );
    }
    tracing::info!("foxglove: listening on ws://{addr}");
    if let Some(d) = me.direct {
        if !s.bind.is_loopback() {
            tracing::warn!(
                "foxglove: the SDK's server listening beyond loopback on {d} (the `bind` line): anyone who reaches it can drive the robot"
            );
        }
        tracing::info!("foxglove: the SDK's server itself on ws://{d} (foxglove.sdk.v1, no relay)");
    }
    let _ = rt.names.export(
        "foxglove",
        STATUS_EXPORT,
        Status {
            addr,
            direct: me.direct,
            relay: relay_stats,
            counters,
        },
    );
    Ok(me)
}

/// Sends each wanted interface's new values, and the world, until `stop`.
fn publish_loop(
    served: Vec<Served>,
    world: Option<WorldOut>,
    wanted: &[Wanted],
    watch: &Arc<Watch>,
    stop: &AtomicBool,
) {
    for s in &served {
        s.source.any().watch(watch.clone());
    }
    let mut last = vec![0u64; served.len()];
    let mut buf = Vec::new();
    let mut balls_at = Instant::now();
    while !stop.load(Ordering::Acquire) {
        watch.wait(Duration::from_millis(100));
        for (i, s) in served.iter().enumerate() {
            let w = &wanted[i];
            if w.subs.load(Ordering::Acquire) == 0 {
                continue;
            }
            if w.greet.swap(false, Ordering::AcqRel) {
                last[i] = 0;
            }
            let snap = s.source.snapshot();
            let clock = snap.clock();
            if clock == 0 || clock == last[i] {
                continue;
            }
            last[i] = clock;
            s.out.log(&s.name, &snap, &mut buf);
        }
        if let Some(wo) = &world {
            let w = &wanted[served.len()];
            if w.subs.load(Ordering::Acquire) > 0 {
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
                    balls_at = Instant::now();
                    entities.push(channels::balls_entity(now, &b.load()));
                }
                if !entities.is_empty() {
                    wo.channel.log(&channels::scene(entities));
                }
            }
        }
    }
    for s in &served {
        s.source.any().unwatch(&**watch);
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
    lines = LINES
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
            "bind 0.0.0.0\nport 0\nserves laser\nserves ptencoders\nimages jpeg 60\nworld off\nmax_queue 4\nmax_message 2048\n",
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
        ] {
            let e = parse_text(text).unwrap_err();
            assert!(e.contains(want) && e.contains(':'), "{text:?}: {e}");
        }
    }
}
