//! zenoh: this process's interfaces on Zenoh (the pub/sub engine of dora-rs,
//! copper-rs and ROS 2's rmw_zenoh), and remote ones provided here as if local.
//! Both halves live in one component with one Zenoh session: load it as a service
//! on the robot (`publishes`) and as a driver beside the schemas (`provides`), or
//! both at once. See `docs/zenoh.md` for keys, byte layouts and Python examples.
//!
//! # Conf
//! ```text
//! service zenoh
//! robot pioneer                 # the robot's name in default keys (default `robot`)
//! publishes all                 # every local interface of a kind that travels, or one by one:
//! publishes colorA              #   on jderobot/<robot>/colorA
//! publishes laser lab/front     #   on a key of your own
//! provides all pioneer          # every interface robot `pioneer` serves (asked at start), or:
//! provides laser                #   robot <robot>'s laser (key jderobot/<robot>/laser) as `laser`
//! provides laser2 lab/front     #   a key of your own; a non-standard name takes the kind of
//!                               #   the key's last chunk (`laser2` from .../front: say
//!                               #   `provides laser2 lab/front laser`)
//! format jderobot               # jderobot (default): docs/zenoh.md layouts; ros2: CDR on
//!                               #   rmw_zenoh keys for laser, images, encoders, motors
//! domain 0                      # ROS 2 domain id of `format ros2` keys (0..232)
//! images raw                    # raw BGR (default) | jpeg [QUALITY 1..100, default 80]
//! mode peer                     # peer (default) | client | router
//! listen tcp/0.0.0.0:7447       # repeatable; default tcp/127.0.0.1:0 (loopback, any port)
//! connect tcp/10.0.0.2:7447     # repeatable
//! scouting loopback             # loopback (default) | lan | off: multicast discovery of peers
//! config zenoh.json5            # a Zenoh config file (ACL, TLS, timeouts), applied first
//! tls ca.pem robot.pem robot.key  # TLS with mutual authentication on tls/ endpoints (PEM:
//!                               #   the CA that signs every peer, this side's cert and key)
//! writers operator              # only peers whose certificate's CN is listed may put
//!                               #   values here (actuators); others only read (needs tls)
//! insecure                      # beyond loopback without TLS: say so (a network you trust)
//! discover 3000                 # ms that `provides all` waits for the robot (default 3000)
//! end_service
//! ```
//!
//! # Interfaces
//! `publishes`: sensors (`colorA..D`, `varcolorA..D`, `laser`, `sonars`, `encoders`,
//! `bumpers`, `pantiltencoders`, `zoomencoders`) are put on their key with every new
//! value, while some subscriber matches (the interface is resumed meanwhile, so a
//! driver that computes on demand computes); actuators (`motors`, `pantiltmotors`,
//! `zoommotors`) are subscribed, and what a remote controller writes goes to the local
//! one (whose driver still applies its `motors_timeout`; when the last remote writer
//! leaves, motors are zeroed at once).
//!
//! `provides`: the remote interfaces are created here with the sender's clocks and
//! times, in the units of `crate::interfaces`. Sensors are subscribed while a local
//! user uses them; local writes to an actuator are put on its key. Each is stale
//! (and `motors` zeroed) while its robot is absent: the serving side holds a Zenoh
//! liveliness token `<key>/served`, which disappears within the session's lease
//! when the robot's process dies (at once when its connection closes).
//!
//! A process that provides `motors` registers a stop with [`crate::estop`]: a
//! zero command put straight on the session when the process ends, is
//! suspended or panics ([`links::register_stop`]); after
//! [`crate::estop::halted`] no actuator value is put.
//!
//! A subscriber that appears gets the latest value within 100 ms (a robot that
//! restarts gets the pan-tilt command written while it was away). A payload that
//! is not a value of its kind is dropped with one log line per key.
//!
//! # Beyond loopback
//! Every `listen` and `connect` endpoint beyond loopback (also those of a
//! `config` file) must be `tls/` with mutual authentication (a `tls` line), or the
//! conf must say `insecure`: otherwise the service does not start, and says how
//! (`settings::guard_listen`, the suite's one rule).
//!
//! System packages: none (Zenoh is compiled in, with its TCP and TLS transports).

mod links;
mod session;
pub mod wire;

use std::{
    sync::{Arc, atomic::AtomicBool, mpsc::sync_channel},
    time::Duration,
};

use zenoh::{Session, Wait, key_expr::KeyExpr, pubsub::Subscriber};

use crate::interfaces::{Kind, with_kind};
use crate::{
    conf::{
        ComponentConf, ConfError,
        settings::{Arg, Setting, choice, custom, int, word},
    },
    interfaces::{self, AnyInterface, Interface, Interfaces, Watch},
    runtime::{Driver, Runtime},
    supervisor::Worker,
};
use links::{Keep, Outbound, Route};
pub use session::{FRAME_QUEUE, Scouting, SessionConf};
use wire::{Format, Wire};

/// What to publish or provide: one interface, or all.
#[derive(Clone, Debug, PartialEq)]
pub enum Which {
    All,
    /// The interface name and its key (`None`: the default key).
    One {
        name: String,
        key: Option<String>,
        /// The interface kind when the name is not a standard one (`provides`).
        kind: Option<Kind>,
    },
}

/// The component's conf.
#[derive(Clone, Debug)]
pub struct Settings {
    pub robot: String,
    pub publishes: Vec<Which>,
    /// `provides all ROBOT` is `(All, ROBOT)`; `provides NAME [KEY]` is `(One, robot)`.
    pub provides: Vec<(Which, String)>,
    pub format: Format,
    pub domain: u32,
    pub jpeg: Option<u8>,
    pub session: SessionConf,
    pub discover: Duration,
}

const USAGE_PUBLISHES: &str = "publishes all | publishes NAME [KEY]";
const USAGE_PROVIDES: &str = "provides all ROBOT | provides NAME [KEY [KIND]]";

/// A key chunk (a robot's name): no `/` and none of Zenoh's special characters.
fn check_chunk(w: &str) -> Result<(), String> {
    if w.is_empty() || w.contains(['/', '*', '$', '#', '?', '@']) {
        return Err("it cannot be a key chunk: no / * $ # ? @".into());
    }
    Ok(())
}

/// One Zenoh key, without wildcards (e.g. lab/robot1/laser).
fn check_key(w: &str) -> Result<(), String> {
    match KeyExpr::try_from(w) {
        Ok(k) if !k.as_str().contains('*') && !k.as_str().contains('$') => Ok(()),
        Ok(_) => Err("it has a wildcard; name one key, e.g. lab/robot1/laser".into()),
        Err(e) => Err(format!("not a Zenoh key: {e}")),
    }
}

/// A robot's name in keys.
const ROBOT: Arg = custom("NAME", "a key chunk", check_chunk);
/// A key of one interface.
const KEY: Arg = custom("KEY", "a Zenoh key without wildcards", check_key);

crate::declare_lines! {
    /// The lines `zenoh` takes (`jderobot help zenoh` prints them), its session's
    /// included (the group [`session::GROUP`]).
    struct Lines {
        robot: String = Setting::new(
            "robot",
            "the robot's name in default keys (jderobot/<robot>/laser)",
            &[ROBOT],
        )
        .default("robot"),
        publishes: Vec<(String, Option<String>)> = Setting::new(
            "publishes",
            "a local interface to put on Zenoh (on jderobot/<robot>/NAME, or on KEY); `publishes all`: every local interface of a kind that travels",
            &[word("NAME"), KEY.optional()],
        )
        .repeats(),
        provides: Vec<(String, Option<String>, Option<Kind>)> = Setting::new(
            "provides",
            "a remote interface to provide here (robot <robot>'s, or the one on KEY; a non-standard NAME says its KIND); `provides all ROBOT`: every interface robot ROBOT serves",
            &[word("NAME"), KEY.optional(), choice("KIND", Kind::NAMES).optional()],
        )
        .repeats(),
        format: String = Setting::new(
            "format",
            "jderobot: the layouts of docs/zenoh.md; ros2: CDR on rmw_zenoh keys (laser, images, encoders, motors)",
            &[choice("FORMAT", &["jderobot", "ros2"])],
        )
        .default("jderobot"),
        domain: u32 = Setting::new(
            "domain",
            "the ROS 2 domain id of `format ros2` keys",
            &[int("ID", "", 0, 232)],
        )
        .default("0"),
        images: (String, Option<u8>) = Setting::new(
            "images",
            "how images travel: raw BGR, or JPEG of QUALITY (default 80)",
            &[choice("ENCODING", &["raw", "jpeg"]), int("QUALITY", "", 1, 100).optional()],
        )
        .default("raw"),
        discover: u64 = Setting::new(
            "discover",
            "how long `provides all` waits for the robot to answer",
            &[int("MS", "ms", 0, 600_000)],
        )
        .default("3000"),
        session: session::SessionLines = [
            session::MODE,
            session::LISTEN,
            session::CONNECT,
            session::SCOUTING,
            session::CONFIG,
            session::TLS,
            session::WRITERS,
            session::INSECURE,
        ],
    }
}
/// Reads the conf (every error names file:line and the fix).
pub fn parse(conf: &ComponentConf) -> Result<Settings, ConfError> {
    let lines: Lines = conf.read()?;
    let robot = lines.robot;
    let images = conf.line("images");
    let jpeg = match lines.images {
        (e, Some(q)) if e == "jpeg" => Some(q),
        (e, None) if e == "jpeg" => Some(80),
        (_, None) => None,
        (_, Some(_)) => {
            let l = images.expect("a quality comes from a line");
            return Err(l.error(
                "`images raw` takes no quality; usage: images raw | images jpeg [QUALITY]",
            ));
        }
    };
    let mut s = Settings {
        robot: robot.clone(),
        publishes: Vec::new(),
        provides: Vec::new(),
        format: if lines.format == "ros2" {
            Format::Ros2
        } else {
            Format::Jderobot
        },
        domain: lines.domain,
        jpeg,
        session: SessionConf::new(conf, lines.session)?,
        discover: Duration::from_millis(lines.discover),
    };
    for (l, (name, k)) in conf.lines_with("publishes").zip(lines.publishes) {
        s.publishes.push(if name == "all" {
            if k.is_some() {
                return Err(l.error(format!(
                    "`publishes all` takes no key; usage: {USAGE_PUBLISHES}"
                )));
            }
            Which::All
        } else {
            Which::One {
                name: interfaces::canonical(&name),
                key: k,
                kind: None,
            }
        });
    }
    for (l, (name, k, kind)) in conf.lines_with("provides").zip(lines.provides) {
        if name == "all" {
            if k.is_none() || kind.is_some() {
                return Err(l.error(format!(
                    "`provides all` takes the robot's name and nothing else; usage: {USAGE_PROVIDES}"
                )));
            }
            let robot = k.unwrap_or_default();
            check_chunk(&robot)
                .map_err(|e| l.error(format!("`provides all {robot}`: the robot's name: {e}")))?;
            s.provides.push((Which::All, robot));
        } else {
            let name = interfaces::canonical(&name);
            if kind.is_none() && interfaces::family(&name).is_none() {
                return Err(l.error(format!(
                    "`provides {name}`: `{name}` is not a standard interface name, so \
                     say its kind: provides {name} KEY KIND (KIND: image, laser, encoders, ...)"
                )));
            }
            s.provides
                .push((Which::One { name, key: k, kind }, robot.clone()));
        }
    }
    Ok(s)
}

struct Zenoh {
    session: Session,
    worker: Worker,
    watch: Option<Arc<Watch>>,
    keep: Keep,
}

impl Driver for Zenoh {
    fn terminate(&mut self) {
        let watch = &self.watch;
        self.worker
            .stop_waking(|| watch.iter().for_each(|w| w.wake()));
        self.keep.clear();
        let _ = self.session.close().wait();
    }
}

impl Drop for Zenoh {
    fn drop(&mut self) {
        self.terminate();
    }
}

/// A remote sensor subscribed only while a local user uses it.
struct OnDemand {
    iface: Arc<dyn AnyInterface>,
    subscribe: Box<dyn Fn() -> anyhow::Result<Subscriber<()>> + Send>,
    sub: Option<Subscriber<()>>,
}

impl OnDemand {
    fn update(&mut self) {
        let used = self.iface.users() > 0;
        if used && self.sub.is_none() {
            match (self.subscribe)() {
                Ok(s) => self.sub = Some(s),
                Err(e) => tracing::warn!("{e}"),
            }
        } else if !used && self.sub.is_some() {
            self.sub = None;
        }
    }
}

/// Everything create() sets up, before the thread starts.
#[derive(Default)]
struct Plan {
    outs: Vec<Arc<dyn Outbound>>,
    on_demand: Vec<OnDemand>,
    keep: Keep,
}

fn route(s: &Settings, robot: &str, name: &str, kind: Kind, key: &Option<String>) -> Route {
    Route {
        key: key
            .clone()
            .unwrap_or_else(|| wire::default_key(s.format, s.domain, robot, name, kind)),
        format: s.format,
        jpeg: s.jpeg,
    }
}

/// Serves a local interface: a sensor is put, an actuator subscribed.
fn serve<T: Wire>(
    session: &Session,
    rt: &Runtime,
    iface: Arc<dyn AnyInterface>,
    route: Route,
    plan: &mut Plan,
) -> anyhow::Result<()> {
    plan.keep
        .push(links::token(session, format!("{}/served", route.key))?);
    if iface.is_actuator() {
        let typed: Arc<Interface<T>> = rt.interfaces.get(iface.name())?;
        if T::KIND == Kind::Motors {
            let motors = rt.interfaces.get(iface.name())?;
            plan.keep
                .push(links::watch_writers(session, &route.key, motors)?);
        }
        plan.keep
            .push(Box::new(links::inbound(session, typed, route)?));
    } else {
        plan.outs
            .push(links::outbound::<T>(session, iface, route, &rt.interfaces)?);
    }
    Ok(())
}

/// Provides a remote interface here: a sensor is subscribed on demand, an
/// actuator's local writes are put.
fn provide<T: Wire>(
    session: &Session,
    rt: &Runtime,
    name: &str,
    route: Route,
    plan: &mut Plan,
) -> anyhow::Result<()> {
    let typed: Arc<Interface<T>> = rt
        .interfaces
        .provide(name, "zenoh")
        .map_err(|e| anyhow::anyhow!("zenoh: cannot provide `{name}`: {e}"))?;
    let any: Arc<dyn AnyInterface> = typed.clone();
    plan.keep.push(links::watch_server(
        session,
        &route.key,
        any.clone(),
        &rt.interfaces,
    )?);
    if T::ACTUATOR {
        plan.keep.push(links::token(
            session,
            format!("{}/driven/{}", route.key, session.zid()),
        )?);
        if T::KIND == Kind::Motors {
            let motors = rt.interfaces.get(name)?;
            plan.keep.push(Box::new(links::register_stop(
                session,
                motors,
                route.clone(),
            )));
        }
        plan.outs
            .push(links::outbound::<T>(session, any, route, &rt.interfaces)?);
    } else {
        let session = session.clone();
        plan.on_demand.push(OnDemand {
            iface: any,
            subscribe: Box::new(move || links::inbound(&session, typed.clone(), route.clone())),
            sub: None,
        });
    }
    Ok(())
}

/// The local interfaces to serve, each with its key (`None`: the default).
type Served = Vec<(Arc<dyn AnyInterface>, Option<String>)>;

fn publishes(s: &Settings, interfaces: &Interfaces) -> anyhow::Result<Served> {
    let mut v: Served = Vec::new();
    for w in &s.publishes {
        match w {
            Which::All => {
                for i in interfaces.all() {
                    if i.provider() != "zenoh" && !v.iter().any(|(j, _)| j.name() == i.name()) {
                        v.push((i, None));
                    }
                }
            }
            Which::One { name, key, .. } => {
                let i = interfaces.get_any(name).map_err(|_| {
                    anyhow::anyhow!(
                        "zenoh: `publishes {name}`: no such interface here (have: {}); load the \
                         driver that provides it before zenoh",
                        interfaces.names().join(", ")
                    )
                })?;
                v.retain(|(j, _)| j.name() != name);
                v.push((i, key.clone()));
            }
        }
    }
    Ok(v)
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let s = parse(conf)?;
    let served = publishes(&s, &rt.interfaces)?;
    let session = s.session.open()?;
    let mut plan = Plan::default();
    for (iface, key) in served {
        let kind = iface.kind();
        let r = route(&s, &s.robot, iface.name(), kind, &key);
        tracing::info!("zenoh: serving `{}` on {}", iface.name(), r.key);
        with_kind!(kind, serve(&session, rt, iface, r, &mut plan))?;
    }
    for (which, robot) in &s.provides {
        let wanted: Vec<(String, Option<String>, Option<Kind>)> = match which {
            Which::One { name, key, kind } => vec![(name.clone(), key.clone(), *kind)],
            Which::All => {
                let prefix = match s.format {
                    Format::Jderobot => format!("jderobot/{robot}"),
                    Format::Ros2 => format!("{}/{robot}", s.domain),
                };
                let names = links::discover(&session, &prefix, s.discover);
                if names.is_empty() {
                    anyhow::bail!(
                        "zenoh: `provides all {robot}`: no interface of robot `{robot}` answered \
                         within {} ms (is its jderobot running with `robot {robot}` and \
                         `publishes all`? this side listens on {} and connects to {}); name the \
                         interfaces with `provides NAME` lines to start without it",
                        s.discover.as_millis(),
                        if s.session.listen.is_empty() {
                            "loopback".into()
                        } else {
                            s.session.listen.join(" ")
                        },
                        if s.session.connect.is_empty() {
                            "nothing (scouting only)".into()
                        } else {
                            s.session.connect.join(" ")
                        },
                    );
                }
                names
                    .into_iter()
                    .filter(|n| {
                        let known = interfaces::family(n).is_some();
                        if !known {
                            tracing::warn!(
                                "zenoh: robot `{robot}` serves `{n}`, not a standard name: add \
                                 `provides {n} KEY KIND` to take it"
                            );
                        }
                        known
                    })
                    .map(|n| (n, None, None))
                    .collect()
            }
        };
        for (name, key, kind) in wanted {
            let Some(kind) = kind.or_else(|| interfaces::family(&name)) else {
                anyhow::bail!("zenoh: `provides {name}`: say its kind: provides {name} KEY KIND");
            };
            let r = route(&s, robot, &name, kind, &key);
            tracing::info!("zenoh: providing `{name}` from {}", r.key);
            with_kind!(kind, provide(&session, rt, &name, r, &mut plan))?;
        }
    }
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = sync_channel(1);
    let worker = {
        let stop2 = stop.clone();
        let outs = std::mem::take(&mut plan.outs);
        let mut on_demand = std::mem::take(&mut plan.on_demand);
        Worker::start("zenoh", stop, move || {
            let watch = Watch::for_current_thread();
            let _ = tx.send(watch.clone());
            links::run_outbound(outs, &watch, &stop2, || {
                on_demand.iter_mut().for_each(OnDemand::update)
            });
        })?
    };
    let watch = rx.recv().ok();
    Ok(Box::new(Zenoh {
        session,
        worker,
        watch,
        keep: plan.keep,
    }))
}

crate::register_driver!(
    Service,
    "zenoh",
    "publishes interfaces on Zenoh and provides remote ones (Python and ROS 2 can join)",
    create,
    lines = Lines
);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conf::Kind;

    fn parse_text(text: &str) -> Result<Settings, String> {
        parse(&ComponentConf::from_text(Kind::Service, "zenoh", text).unwrap())
            .map_err(|e| e.to_string())
    }

    #[test]
    fn lines_are_read_with_defaults() {
        let s = parse_text(
            "robot pioneer\npublishes all\npublishes laser lab/front\nprovides all r2\n\
             provides laser2 lab/r2/laser laser\nformat ros2\ndomain 7\nimages jpeg 60\n",
        )
        .unwrap();
        assert_eq!(s.robot, "pioneer");
        assert_eq!(s.publishes.len(), 2);
        assert_eq!(s.provides[0], (Which::All, "r2".into()));
        assert_eq!(
            s.provides[1].0,
            Which::One {
                name: "laser2".into(),
                key: Some("lab/r2/laser".into()),
                kind: Some(crate::interfaces::Kind::Laser)
            }
        );
        assert_eq!((s.format, s.domain, s.jpeg), (Format::Ros2, 7, Some(60)));
        let d = parse_text("").unwrap();
        assert_eq!(
            (d.robot.as_str(), d.format, d.jpeg),
            ("robot", Format::Jderobot, None)
        );
        assert_eq!(
            wire::default_key(
                d.format,
                0,
                "robot",
                "laser",
                crate::interfaces::Kind::Laser
            ),
            "jderobot/robot/laser"
        );
    }

    #[test]
    fn bad_lines_name_the_line_and_the_fix() {
        for (text, want) in [
            ("provides laser2 lab/front\n", "say its kind"),
            ("publishes laser lab/*\n", "wildcard"),
            ("robot a/b\n", "cannot be a key chunk"),
            (
                "images jpeg 200\n",
                "QUALITY (argument 2) is `200`, expected a whole number between 1 and 100",
            ),
            ("format dds\n", "jderobot, ros2"),
            ("provides all\n", "provides all ROBOT"),
            ("provides laser a b laser\n", "provides NAME [KEY] [KIND]"),
            (
                "provides laser2 a/b wheel\n",
                "KIND (argument 3) is `wheel`, expected one of image",
            ),
            (
                "colour red\n",
                "takes no `colour` line; its lines: robot, publishes",
            ),
        ] {
            let e = parse_text(text).unwrap_err();
            assert!(e.contains(want) && e.contains(':'), "{text:?}: {e}");
        }
    }
}
