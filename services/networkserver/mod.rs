//! Service `networkserver`: serves this process's interfaces (cameras, laser,
//! encoders, sonars, motors, pan-tilt, zoom) over TCP with JDE 4.3's wire protocol
//! ([`crate::netwire`]), so a `networkclient` on another machine — ours or a 4.3
//! one — uses them as if they were local. See `docs/network.md`.
//!
//! # Conf (4.3's section is `driver networkserver`; `service networkserver` works too)
//! ```text
//! driver networkserver
//! socket 3001              # TCP port (0 = any free port)
//! bind 127.0.0.1           # address to listen on (default 127.0.0.1; 0.0.0.0 = every interface)
//! token 7f3a9c2e5b8d4f16a0c3e9b2d7f14a68  # 16 to 128 characters: refuse clients that do not send it (needed
//!                          #   beyond loopback)
//! insecure                 # beyond loopback with no token: say so (a network you trust)
//! serves colorA 0          # an image and its network id (colorA..D, varcolorA..D any size)
//! serves laser             # laser, sonars, encoders, motors, pantiltencoders,
//! serves encoders          #   pantiltmotors, zoomencoders, zoommotors (4.3 names
//! serves motors            #   ptencoders, ptmotors, zencoders, zmotors too), imu
//!                          #   (jderobot's extension of the wire)
//! max_clients 128          # connections at once (more are refused with a 1027 line)
//! max_line 1024            # bytes in a request line
//! max_queue 32             # image requests waiting per client (more close it)
//! timeout 5000             # ms: a client whose name takes longer (in all), holding
//!                          #   a partial line, or not reading what it is sent is disconnected
//! idle_timeout 60000       # ms: a client with no subscription, no image request, no
//!                          #   command ever and no line for this long is closed (0 = never)
//! end_driver
//! load_driver simulator
//! load_service networkserver   # after the drivers whose interfaces it serves
//! ```
//!
//! # Interfaces
//! Provides none; uses the served ones (looked up at load: a served interface that
//! nothing provides is an error naming the line). A subscription or an image
//! request resumes the interface for that client (so a simulator renders only while
//! someone watches); `22`/`23` set `motors` v (mm/s) and w (deg/s); `1006` sets the
//! pan-tilt command (deg, deg/s); `1024` the zoom; `2001` subscribes to the imu
//! (jderobot's extension, see [`crate::netwire`]). When a client that drove the
//! motors goes away, the motors are set to zero.
//!
//! # Differences from 4.3 (the wire is unchanged)
//! - Listens on 127.0.0.1 unless `bind` says otherwise (4.3: every interface).
//! - `token`: a shared secret in the client name (see [`crate::netwire`]). It
//!   keeps out clients that do not know it; it is not encryption (anyone who can
//!   watch the traffic reads it, and the data).
//! - Limits: line length, clients, queued requests, timeouts. A bad client is
//!   disconnected alone with one log line; the others and the schemas do not notice.
//!   The name must arrive within `timeout` in all; an idle client with no
//!   subscription that has sent no command is closed after `idle_timeout`; with
//!   the table full, a new connection closes one to make room: one that has
//!   waited over 250 ms for its name, else the one that has *sent* nothing for
//!   longest (over 2 s; those with no subscription first, and from the address
//!   holding the most connections first), which gets a `1027 closed to make
//!   room` line. So a client with the token gets in while strangers hold
//!   connections, and a good client gets in while 128 named ones sit on a
//!   sensor that does not change.
//! - Beyond loopback it needs `token` (or an `insecure` line): it refuses to
//!   start otherwise, saying how to add one (`settings::guard_listen`).
//! - Out of descriptors, `accept` fails (EMFILE): the accept loop closes the
//!   longest idle connection, pauses (50 ms doubling to 1 s, one log line) and
//!   goes on; it never ends while the service runs.
//! - Stopping needs no network: the accept thread polls its nonblocking listener
//!   with a stop flag (100 ms), where a self-connect would fail with loopback down.
//! - A laser scan of another geometry than 4.3's (180° from −90°) is resampled to
//!   180 readings at 1° from −90°, "nothing" outside its field of view
//!   ([`crate::interfaces::Laser::jde43_readings`], docs/network.md).
//! - 4.3 bug fixed: the sonars push carried `laser.number` readings; it carries the
//!   sonars' own count.
//! - 4.3 bug fixed: `1024` (zoom) was obeyed only when pan-tilt motors were
//!   served; it needs zoom motors.
//! - 4.3's name read took whatever the first read returned (lines sent right after
//!   the name were lost); we read exactly 20 bytes.
//! - Image queries may be pipelined: a client may send several `1019` before
//!   reading the answers; each answer is a newer frame than the last one sent.
//! - The encoders push's last field is the sample time in µs since the server
//!   started (documented so in 4.3, which sent the clock again).
//!
//! # Why plain threads (not tokio)
//! Each client gets one thread with a blocking socket for writes: it reads the
//! requests without waiting, writes what is due and sleeps in `ppoll(2)` on the
//! socket and on an eventfd that a new frame rings. A frame is written with one
//! `writev` straight from the interface's shared sample (no copy), pushes are
//! paced against absolute deadlines per client, and a client that stops reading
//! blocks only its own thread until the write timeout. With 100 clients that is
//! 100 mostly-sleeping threads. The benchmark (`benches/network.rs`, figures in
//! `docs/network.md`): 640x480 frames at 86-87 % of a raw TCP copy of the same
//! bytes measured in the same run (three runs), p50 frame latency 0.4 ms, p99
//! push lateness 0.3 ms and 10 % of one core for 100 clients on laser and
//! encoders. No tokio version was built to compare: an async runtime would add a
//! dependency and build time, and a client's thread already sleeps on its socket
//! and its frames together. Until 2026-11-28 a client had a reader thread and a
//! writer thread; alternated with this one on the same bench it served 65-85 %
//! of the raw copy against 86-87 % (each request cost a thread wake-up and
//! two cores had one more thread to share).
//!
//! System packages: none.
//!
//! # Code
//! - `conf.rs`: [`ServerConf`] and the declared lines.
//! - `clients.rs`: the accept loop, the table of connections, admission (the
//!   name, the token, eviction when full) and each connection's life.
//! - `serve.rs`: a client's thread (requests, the idle rule, replies, pushes).
//! - `frames.rs`: image frames (one `writev` from the shared sample, and the
//!   wake-up on a new frame).

mod clients;
mod conf;
mod frames;
mod serve;

use std::{
    net::{Shutdown, SocketAddr, TcpListener},
    sync::{
        Arc,
        atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering},
    },
    thread::JoinHandle,
    time::{Duration, Instant},
};

use anyhow::Context as _;
use parking_lot::Mutex;

use crate::{
    conf::ComponentConf,
    interfaces::{AnyInterface, Image, Interface, Interfaces, Kind, family, with_kind},
    netwire::{self, Net43, OnWire, Request},
    runtime::{Driver, Runtime},
};

use clients::{Conn, accept_loop};
use conf::Lines;
pub use conf::ServerConf;

/// The served interfaces.
#[derive(Clone, Default)]
pub struct Sources {
    /// (network id, image).
    pub images: Vec<(u32, Arc<Interface<Image>>)>,
    /// The served devices, one slot per kind of the table (4.3's wire has one
    /// device of a kind per server).
    devices: [Option<Arc<dyn Served>>; Kind::ALL.len()],
}

impl Sources {
    /// Looks up what `serves` names on `ifaces`.
    pub fn lookup(
        serves: &[(String, Option<u32>)],
        ifaces: &Interfaces,
    ) -> anyhow::Result<Sources> {
        let mut s = Sources::default();
        for (name, netid) in serves {
            let ctx = || {
                format!(
                    "networkserver: `serves {name}`: load the driver that provides `{name}` before networkserver"
                )
            };
            let Some(kind) = family(name) else {
                anyhow::bail!("networkserver: `serves {name}`: no interface kind has that name")
            };
            match netwire::on_wire(kind) {
                OnWire::Absent => {
                    anyhow::bail!("networkserver: cannot serve a {kind} interface")
                }
                OnWire::Frames => s
                    .images
                    .push((netid.unwrap_or(0), ifaces.get(name).with_context(ctx)?)),
                _ => s = with_kind!(kind, serve(s, ifaces, name, ctx))?,
            }
        }
        Ok(s)
    }

    /// These sources and image `iface` under network id `netid`.
    pub fn serving_image(mut self, netid: u32, iface: Arc<Interface<Image>>) -> Sources {
        self.images.push((netid, iface));
        self
    }

    /// These sources and device `iface` (a pushed or commanded kind).
    pub fn serving<T: Net43>(mut self, iface: Arc<Interface<T>>) -> Sources {
        self.devices[T::KIND.index()] = Some(Arc::new(iface));
        self
    }

    /// Zeroes the served commands that must be renewed (motors): their client left.
    fn zero_renewed(&self) {
        for (&k, dev) in Kind::ALL.iter().zip(&self.devices) {
            if let (
                Some(dev),
                OnWire::Commanded {
                    keep_alive: true, ..
                },
            ) = (dev, netwire::on_wire(k))
            {
                dev.zero();
            }
        }
    }

    /// The served device of kind `k`.
    fn device(&self, k: Kind) -> Option<&Arc<dyn Served>> {
        self.devices[k.index()].as_ref()
    }
}

/// `s` and the interface `name` of kind `T` on `ifaces`.
fn serve<T: Net43>(
    s: Sources,
    ifaces: &Interfaces,
    name: &str,
    ctx: impl FnOnce() -> String,
) -> anyhow::Result<Sources> {
    Ok(s.serving(ifaces.get::<T>(name).with_context(ctx)?))
}

/// A served device, whatever its kind: its interface and its kind's
/// [`Net43`] code.
trait Served: Send + Sync {
    fn interface(&self) -> Arc<dyn AnyInterface>;
    /// Appends its push if its sample is newer than `last` (the clock pushed last).
    fn push(&self, last: &mut u64, epoch: Instant, out: &mut Vec<u8>);
    /// Sets the value from a command request; Err: the value was refused.
    fn apply(&self, req: &Request) -> Result<(), String>;
    /// Appends its limits reply.
    fn write_limits(&self, out: &mut Vec<u8>);
    /// Sets the zero value (a renewed command whose client left).
    fn zero(&self);
}

impl<T: Net43> Served for Arc<Interface<T>> {
    fn interface(&self) -> Arc<dyn AnyInterface> {
        self.clone()
    }
    fn push(&self, last: &mut u64, epoch: Instant, out: &mut Vec<u8>) {
        let s = self.snapshot();
        if s.clock != *last {
            *last = s.clock;
            let us = s.stamp.saturating_duration_since(epoch).as_micros() as u64;
            s.value.write_push(s.clock, us, out);
        }
    }
    fn apply(&self, req: &Request) -> Result<(), String> {
        let mut v = self.read().value.clone();
        v.apply(req);
        self.publish(v).map(|_| ()).map_err(|e| e.to_string())
    }
    fn write_limits(&self, out: &mut Vec<u8>) {
        self.read().value.write_limits(out);
    }
    fn zero(&self) {
        let _ = self.publish(T::default());
    }
}

/// Push lateness histogram: 50 µs buckets up to 100 ms.
const BUCKET_US: u64 = 50;
const BUCKETS: usize = 2001;

/// Counters a running server keeps (for `ps`-like reports and the benchmark).
pub struct Stats {
    /// Clients connected now.
    pub clients: AtomicUsize,
    /// Connections accepted so far.
    pub accepted: AtomicU64,
    /// Connections closed because the client misbehaved (or was refused).
    pub dropped: AtomicU64,
    /// Frames sent.
    pub frames: AtomicU64,
    /// Push rounds (one per client per 33 ms with at least one subscription).
    pub pushes: AtomicU64,
    lateness: Vec<AtomicU64>,
}

impl Stats {
    fn new() -> Stats {
        Stats {
            clients: AtomicUsize::new(0),
            accepted: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            frames: AtomicU64::new(0),
            pushes: AtomicU64::new(0),
            lateness: (0..BUCKETS).map(|_| AtomicU64::new(0)).collect(),
        }
    }

    fn record_lateness(&self, late: Duration) {
        let b = ((late.as_micros() as u64) / BUCKET_US).min(BUCKETS as u64 - 1) as usize;
        self.lateness[b].fetch_add(1, Ordering::Relaxed);
        self.pushes.fetch_add(1, Ordering::Relaxed);
    }

    /// The `p`-th percentile (0..=100) of push lateness: how long after its 33 ms
    /// deadline a push round finished writing (to 50 µs; 100 ms and over count as 100 ms).
    pub fn push_lateness(&self, p: f64) -> Duration {
        let counts: Vec<u64> = self
            .lateness
            .iter()
            .map(|c| c.load(Ordering::Relaxed))
            .collect();
        let total: u64 = counts.iter().sum();
        if total == 0 {
            return Duration::ZERO;
        }
        let want = ((p / 100.0) * total as f64).ceil().max(1.0) as u64;
        let mut acc = 0;
        for (i, c) in counts.iter().enumerate() {
            acc += c;
            if acc >= want {
                return Duration::from_micros((i as u64 + 1) * BUCKET_US);
            }
        }
        Duration::from_micros(BUCKETS as u64 * BUCKET_US)
    }

    /// Forgets the lateness recorded so far.
    pub fn reset_lateness(&self) {
        for c in &self.lateness {
            c.store(0, Ordering::Relaxed);
        }
    }
}

struct Shared {
    conf: ServerConf,
    sources: Sources,
    stop: AtomicBool,
    stats: Stats,
    epoch: Instant,
    /// Live connections (to shut them down on terminate, and to evict one that
    /// has not sent its name when the table is full) and their threads.
    clients: Mutex<Vec<Conn>>,
    threads: Mutex<Vec<JoinHandle<()>>>,
    /// Wrong tokens per source address, and their back-off.
    refusals: crate::secret::Refusals,
}

/// A running server.
pub struct NetServer {
    shared: Arc<Shared>,
    addr: SocketAddr,
    accept: Option<JoinHandle<()>>,
}

impl NetServer {
    /// Binds and starts serving `sources`.
    pub fn start(conf: ServerConf, sources: Sources) -> anyhow::Result<NetServer> {
        let listener = TcpListener::bind((conf.bind, conf.port)).with_context(|| {
            format!(
                "networkserver: cannot listen on {}:{} (is another program using the port?)",
                conf.bind, conf.port
            )
        })?;
        let addr = listener.local_addr()?;
        // Accept polls the listener with a stop flag, so stopping needs no
        // connection to wake it (none can be made with the network down).
        listener
            .set_nonblocking(true)
            .context("networkserver: cannot make its listener nonblocking")?;
        let shared = Arc::new(Shared {
            conf,
            sources,
            stop: AtomicBool::new(false),
            stats: Stats::new(),
            epoch: Instant::now(),
            clients: Mutex::new(Vec::new()),
            threads: Mutex::new(Vec::new()),
            refusals: crate::secret::Refusals::new("networkserver"),
        });
        let sh = shared.clone();
        let accept = std::thread::Builder::new()
            .name("nsrv-accept".into())
            .spawn(move || accept_loop(listener, sh))
            .context("networkserver: cannot start its thread")?;
        tracing::info!("networkserver: listening on {addr}");
        Ok(NetServer {
            shared,
            addr,
            accept: Some(accept),
        })
    }

    /// The address it listens on (the port chosen when `socket 0`).
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    pub fn stats(&self) -> &Stats {
        &self.shared.stats
    }

    /// Stops accepting, disconnects every client and joins every thread.
    pub fn stop(&mut self) {
        if self.shared.stop.swap(true, Ordering::AcqRel) {
            return;
        }
        // The accept loop sees the flag within ACCEPT_TICK.
        if let Some(t) = self.accept.take() {
            let _ = t.join();
        }
        for c in self.shared.clients.lock().iter() {
            let _ = c.stream.shutdown(Shutdown::Both);
        }
        let threads = std::mem::take(&mut *self.shared.threads.lock());
        for t in threads {
            let _ = t.join();
        }
    }
}

impl Driver for NetServer {
    fn terminate(&mut self) {
        self.stop();
    }
}

impl Drop for NetServer {
    fn drop(&mut self) {
        self.stop();
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let sc = ServerConf::parse(conf)?;
    let sources = Sources::lookup(&sc.serves, &rt.interfaces)?;
    let server = NetServer::start(sc, sources)?;
    let _ = rt
        .names
        .export(&conf.name, ADDRESS_EXPORT, server.local_addr());
    Ok(Box::new(server))
}

/// The name under which the service exports the [`SocketAddr`] it listens on.
pub const ADDRESS_EXPORT: &str = "address";

crate::register_driver!(
    Service,
    "networkserver",
    "serves this process's interfaces over TCP with JDE 4.3's wire protocol",
    create,
    lines = Lines
);
