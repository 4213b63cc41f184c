//! One interface on Zenoh, either way: [`Outbound`] puts every new local value on
//! a key (sensors of a robot, actuators written by a remote controller);
//! [`inbound`] subscribes a key and publishes what arrives into a local interface.
//! Liveliness tokens say who is there: the serving side declares `<key>/served`,
//! a controller writing an actuator declares `<key>/driven/<session id>`.

use parking_lot::Mutex;
use std::{
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, Instant, SystemTime},
};

use zenoh::{
    Session, Wait,
    bytes::{Encoding, ZBytes},
    matching::MatchingListener,
    pubsub::{Publisher, Subscriber},
    qos::{CongestionControl, Priority},
    sample::{Locality, Sample as ZSample, SampleKind},
};

use super::wire::{self, Fill, Format, Wire};
use crate::{
    estop,
    interfaces::{AnyInterface, Interface, Kind, Motors, Notify, Sample, Source, Watch},
    mcapfmt,
};

/// How one interface travels.
#[derive(Clone, Debug)]
pub struct Route {
    pub key: String,
    pub format: Format,
    /// Images as JPEG of this quality (`images jpeg Q`); raw BGR when `None`.
    pub jpeg: Option<u8>,
}

impl Route {
    /// Whether this kind goes as a ROS 2 message on this route.
    fn ros2(&self, kind: Kind) -> bool {
        self.format == Format::Ros2 && wire::ros2_type(kind).is_some()
    }
}

/// Puts every new value of a local interface on its key. Small values go at once
/// on the publishing thread ([`Notify`]: a Zenoh put of a few bytes does not
/// block); images are sent by the component's thread, woken by a [`Watch`].
pub trait Outbound: Notify {
    fn interface(&self) -> Arc<dyn AnyInterface>;
    /// Sent on the publishing thread (not by the component's thread).
    fn inline(&self) -> bool;
    /// Sends the latest value if it is new and somebody listens; errors are
    /// logged once per key until a put succeeds again.
    fn send_if_new(&self);
    /// Sends the latest value again if a subscriber appeared since the last call
    /// (called by the component's thread), so a late joiner — a controller, or a
    /// robot that restarted — has the current value without waiting for the next.
    fn greet_newcomers(&self);
}

struct Out<T: Wire> {
    iface: Arc<Interface<T>>,
    /// Dropped before the publisher it listens on (fields drop in order).
    _listener: MatchingListener<()>,
    publisher: Publisher<'static>,
    route: Route,
    /// A subscriber matches the key (kept by Zenoh's matching listener).
    matching: Arc<AtomicBool>,
    /// Subscribers appeared since the last [`Outbound::greet_newcomers`].
    newcomers: Arc<AtomicBool>,
    gid: [u8; 16],
    /// The clock last sent, and whether the last put failed.
    state: Mutex<(u64, bool)>,
}

impl<T: Wire> Notify for Out<T> {
    fn notify(&self) {
        self.send_if_new();
    }
}

impl<T: Wire> Outbound for Out<T> {
    fn interface(&self) -> Arc<dyn AnyInterface> {
        self.iface.clone()
    }

    fn inline(&self) -> bool {
        T::KIND != Kind::Image
    }

    fn greet_newcomers(&self) {
        if self.newcomers.swap(false, Ordering::AcqRel) {
            self.state.lock().0 = 0;
            self.send_if_new();
        }
    }

    fn send_if_new(&self) {
        // Once the process is ending (estop::halt), an actuator's last word is
        // its stop's ([`register_stop`]).
        if !self.matching.load(Ordering::Acquire) || (estop::halted() && self.iface.is_actuator()) {
            return;
        }
        let mut state = self.state.lock();
        let s = self.iface.snapshot();
        if s.clock == state.0 || s.clock == 0 {
            return;
        }
        state.0 = s.clock;
        let (payload, encoding, attachment) =
            message(&self.route, self.iface.name(), &self.gid, &s);
        let put = self
            .publisher
            .put(payload)
            .encoding(encoding)
            .attachment(attachment)
            .wait();
        match put {
            Ok(()) => state.1 = false,
            Err(e) if !state.1 => {
                state.1 = true;
                tracing::warn!(
                    "zenoh: cannot put `{}` on {}: {e}",
                    self.iface.name(),
                    self.route.key
                );
            }
            Err(_) => {}
        }
    }
}

/// Sample `s` of interface `name` as it travels on `route`: payload, encoding
/// and attachment.
fn message<T: Wire>(
    route: &Route,
    name: &str,
    gid: &[u8; 16],
    s: &Arc<Sample<T>>,
) -> (ZBytes, Encoding, Vec<u8>) {
    if route.ros2(T::KIND) {
        let mut cdr = Vec::new();
        mcapfmt::ros2::encode(name, s, &mut cdr);
        let a = wire::rmw_attachment(s.clock, s.time, gid);
        return (cdr.into(), Encoding::ZENOH_BYTES, a.to_vec());
    }
    let a = wire::attachment(s.clock, s.time).to_vec();
    match route.jpeg.and_then(|q| s.value.to_jpeg(q)) {
        Some(jpeg) => (jpeg.into(), Encoding::IMAGE_JPEG, a),
        None => (
            T::payload(s),
            Encoding::ZENOH_BYTES.with_schema(wire::encoding(T::KIND)),
            a,
        ),
    }
}

/// The rmw_zenoh publisher id of this session's samples.
fn gid(session: &Session) -> [u8; 16] {
    let mut gid = [0u8; 16];
    let zid = session.zid().to_le_bytes();
    gid[..zid.len().min(16)].copy_from_slice(&zid[..zid.len().min(16)]);
    gid
}

/// How long the emergency stop leaves Zenoh's own threads to write its zero:
/// a put returns once the sample is queued, and a suspension (Ctrl+Z) that
/// came right after would leave it unsent (seen under load: 3 runs in 6 with
/// no wait). Zenoh offers no flush nor acknowledgement to wait for instead.
const STOP_GRACE: Duration = Duration::from_millis(20);

/// Registers with [`estop`] the stop of a remote robot's `motors` written here:
/// a zero command put on `route.key` straight on the session (not through the
/// interface's [`Outbound`], whose lock the publishing thread may hold), with
/// the interface's next clock and the motors publisher's QoS (in order behind a
/// command already queued, never waiting for room); then [`STOP_GRACE`].
pub fn register_stop(
    session: &Session,
    motors: Arc<Interface<Motors>>,
    route: Route,
) -> estop::Registration {
    let session = session.clone();
    let gid = gid(&session);
    estop::register(format!("zenoh {}", route.key), move || {
        let zero = Arc::new(Sample {
            clock: motors.clock() + 1,
            stamp: Instant::now(),
            time: SystemTime::now(),
            value: Motors::default(),
        });
        let (payload, encoding, attachment) = message(&route, motors.name(), &gid, &zero);
        let put = session
            .put(route.key.clone(), payload)
            .encoding(encoding)
            .attachment(attachment)
            .congestion_control(CongestionControl::Drop)
            .priority(Priority::Data)
            .express(true)
            .wait();
        if put.is_ok() {
            std::thread::sleep(STOP_GRACE);
        }
    })
}

/// An [`Outbound`] for interface `iface` (of value type `T`) on `route`. While a
/// subscriber matches, a sensor is resumed (its driver computes it) and
/// suspended again when the last one leaves.
pub fn outbound<T: Wire>(
    session: &Session,
    iface: Arc<dyn AnyInterface>,
    route: Route,
    interfaces: &crate::interfaces::Interfaces,
) -> anyhow::Result<Arc<dyn Outbound>> {
    let typed: Arc<Interface<T>> = interfaces.get(iface.name())?;
    // Small values go on the publisher's thread: never wait, drop instead. Frames
    // go from the component's own thread, which waits for room: the link then
    // carries whole frames back to back (the latest each time), not fragments of
    // frames dropped halfway. Frames go at a lower priority than everything else,
    // in their own queue (deep enough for a whole frame, see
    // `session::FRAME_QUEUE`): a `motors` command never waits behind a frame's
    // fragments.
    let image = T::KIND == Kind::Image;
    let publisher = session
        .declare_publisher(route.key.clone())
        .congestion_control(if image {
            CongestionControl::Block
        } else {
            CongestionControl::Drop
        })
        .priority(if image {
            Priority::DataLow
        } else {
            Priority::Data
        })
        .express(!image)
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: cannot publish on `{}`: {e}", route.key))?;
    let matching = Arc::new(AtomicBool::new(false));
    let newcomers = Arc::new(AtomicBool::new(false));
    let listener = {
        let (matching, newcomers) = (matching.clone(), newcomers.clone());
        let iface = iface.clone();
        publisher
            .matching_listener()
            .callback(move |status| {
                let now = status.matching();
                if now {
                    newcomers.store(true, Ordering::Release);
                }
                if matching.swap(now, Ordering::AcqRel) != now && !iface.is_actuator() {
                    if now {
                        iface.resume();
                    } else {
                        iface.suspend();
                    }
                }
            })
            .wait()
            .map_err(|e| {
                anyhow::anyhow!("zenoh: cannot watch subscribers of `{}`: {e}", route.key)
            })?
    };
    let gid = gid(session);
    Ok(Arc::new(Out {
        iface: typed,
        _listener: listener,
        publisher,
        route,
        matching,
        newcomers,
        gid,
        state: Mutex::new((0, false)),
    }))
}

/// Decodes a sample for an interface of type `T` on `route`: (clock, wall time,
/// fill); the clock is 0 when the sample carries none.
fn decode<T: Wire>(route: &Route, sample: &ZSample) -> Result<(u64, SystemTime, Fill<T>), String> {
    if route.ros2(T::KIND) {
        let (clock, time) = sample
            .attachment()
            .and_then(|a| wire::read_rmw_attachment(&a.to_bytes()))
            .unwrap_or((0, SystemTime::now()));
        let payload = sample.payload().to_bytes();
        let (time_ns, v) = mcapfmt::ros2::decode::<T>(&route.key, &payload, mcapfmt::nanos(time))
            .map_err(|e| e.to_string())?;
        return Ok((
            clock,
            mcapfmt::from_nanos(time_ns),
            Box::new(move |d: &mut T| *d = v),
        ));
    }
    let (clock, time) = sample
        .attachment()
        .and_then(|a| wire::read_attachment(&a.to_bytes()))
        .unwrap_or((0, SystemTime::now()));
    let fill: Fill<T> = if *sample.encoding() == Encoding::IMAGE_JPEG {
        let v = T::from_jpeg(&sample.payload().to_bytes())?;
        Box::new(move |d: &mut T| *d = v)
    } else {
        T::fill_from(sample.payload())?
    };
    Ok((clock, time, fill))
}

/// Subscribes `route.key` and publishes what arrives into `iface`, with the
/// sender's clock when it is ahead of the local one ([`Interface::receive`]: so
/// `ps` shows the robot's clocks and a gap is a lost sample; the clock never goes
/// back or wraps). A payload that is not a value of its kind, or a value the
/// interface refuses (a NaN, an inf, out of range), is dropped with one log line
/// (until a good one arrives again).
pub fn inbound<T: Wire>(
    session: &Session,
    iface: Arc<Interface<T>>,
    route: Route,
) -> anyhow::Result<Subscriber<()>> {
    let key = route.key.clone();
    let from = Source::new(format!("zenoh: `{}` (for `{}`)", route.key, iface.name()));
    session
        .declare_subscriber(route.key.clone())
        .allowed_origin(Locality::Remote)
        .callback(move |sample| {
            if sample.kind() != SampleKind::Put {
                return;
            }
            match decode::<T>(&route, &sample) {
                Ok((clock, time, fill)) => {
                    iface.receive(&from, clock, time, fill);
                }
                Err(e) => {
                    from.refused(format_args!("{e} (see docs/zenoh.md for the layout)"));
                }
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: cannot subscribe `{key}`: {e}"))
}

/// Watches the serving side of `key` (its `<key>/served` token): while it is
/// absent `iface` is stale, and a `motors` interface is zeroed.
pub fn watch_server(
    session: &Session,
    key: &str,
    iface: Arc<dyn AnyInterface>,
    interfaces: &crate::interfaces::Interfaces,
) -> anyhow::Result<Box<dyn Send>> {
    let token = format!("{key}/served");
    let motors: Option<Arc<Interface<Motors>>> = (iface.kind() == Kind::Motors)
        .then(|| interfaces.get(iface.name()).ok())
        .flatten();
    iface.set_stale(&format!(
        "zenoh: waiting for `{key}` (nobody serves it yet)"
    ));
    let gone = {
        let key = key.to_string();
        move |iface: &dyn AnyInterface| {
            iface.set_stale(&format!("zenoh: `{key}` is gone (its robot left)"));
            if let Some(m) = &motors {
                let _ = m.publish(Motors::default());
            }
        }
    };
    let sub = session
        .liveliness()
        .declare_subscriber(token.clone())
        .history(true)
        .callback(move |s| match s.kind() {
            SampleKind::Put if iface.is_actuator() => iface.clear_stale(),
            SampleKind::Put if iface.users() == 0 => iface.set_stale(&format!(
                "zenoh: served by its robot; not subscribed while nobody uses it (`run {}`)",
                iface.name()
            )),
            SampleKind::Put => tracing::info!("zenoh: `{}` is served", s.key_expr()),
            SampleKind::Delete => {
                tracing::warn!(
                    "zenoh: `{}` went away; `{}` is stale",
                    s.key_expr(),
                    iface.name()
                );
                gone(&*iface);
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: cannot watch `{token}`: {e}"))?;
    Ok(Box::new(sub))
}

/// On the serving side of `motors`: zeroes the local command when the last
/// remote writer (a `<key>/driven/*` token) leaves, so a killed controller stops
/// the robot at once rather than after `motors_timeout`.
pub fn watch_writers(
    session: &Session,
    key: &str,
    motors: Arc<Interface<Motors>>,
) -> anyhow::Result<Box<dyn Send>> {
    let writers = parking_lot::Mutex::new(std::collections::BTreeSet::<String>::new());
    let sub = session
        .liveliness()
        .declare_subscriber(format!("{key}/driven/*"))
        .history(true)
        .callback(move |s| {
            let mut w = writers.lock();
            match s.kind() {
                SampleKind::Put => {
                    w.insert(s.key_expr().to_string());
                }
                SampleKind::Delete => {
                    w.remove(s.key_expr().as_str());
                    if w.is_empty() {
                        tracing::warn!(
                            "zenoh: the last writer of `{}` left: motors stop",
                            motors.name()
                        );
                        let _ = motors.publish(Motors::default());
                    }
                }
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: cannot watch the writers of `{key}`: {e}"))?;
    Ok(Box::new(sub))
}

/// Declares a liveliness token (kept alive as long as the returned value).
pub fn token(session: &Session, key: String) -> anyhow::Result<Box<dyn Send>> {
    let t = session
        .liveliness()
        .declare_token(key.clone())
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: cannot declare `{key}`: {e}"))?;
    Ok(Box::new(t))
}

/// The names served under `prefix` (`jderobot/<robot>` or `<domain>/<robot>`),
/// read from their tokens; waits up to `wait` for the first answers.
pub fn discover(session: &Session, prefix: &str, wait: Duration) -> Vec<String> {
    let deadline = std::time::Instant::now() + wait;
    loop {
        let mut names = std::collections::BTreeSet::new();
        for pattern in [
            format!("{prefix}/*/served"),
            format!("{prefix}/*/*/*/served"),
        ] {
            let Ok(replies) = session
                .liveliness()
                .get(pattern)
                .timeout(Duration::from_millis(500))
                .wait()
            else {
                continue;
            };
            while let Ok(reply) = replies.recv() {
                if let Ok(s) = reply.result() {
                    let key = s.key_expr().as_str();
                    if let Some(name) = key
                        .strip_prefix(prefix)
                        .and_then(|k| k.strip_prefix('/'))
                        .and_then(|k| k.split('/').next())
                    {
                        names.insert(name.to_string());
                    }
                }
            }
        }
        if !names.is_empty() || std::time::Instant::now() >= deadline {
            return names.into_iter().collect();
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The component's thread: it sends the images (sleeping on a [`Watch`] of them
/// until one publishes, or `stop` is set) and calls `tick` at least every 100 ms
/// (on-demand subscriptions). Inline outbounds are told by their interfaces.
pub fn run_outbound(
    outs: Vec<Arc<dyn Outbound>>,
    watch: &Arc<Watch>,
    stop: &AtomicBool,
    mut tick: impl FnMut(),
) {
    let (inline, threaded): (Vec<_>, Vec<_>) = outs.into_iter().partition(|o| o.inline());
    for o in &inline {
        o.interface().watch(o.clone());
        o.send_if_new();
    }
    for o in &threaded {
        o.interface().watch(watch.clone());
    }
    while !stop.load(Ordering::Acquire) {
        for o in &threaded {
            o.send_if_new();
        }
        for o in inline.iter().chain(&threaded) {
            o.greet_newcomers();
        }
        tick();
        watch.wait(Duration::from_millis(100));
    }
    for o in &threaded {
        o.interface().unwatch(&**watch);
    }
    for o in &inline {
        o.interface().unwatch(&**o);
    }
}

/// Keeps anything alive (subscribers, tokens, listeners) until dropped.
pub type Keep = Vec<Box<dyn Send>>;
