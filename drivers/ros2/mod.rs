//! Driver `ros2`: drives a ROS 2 robot (a TurtleBot 3/4, a ROS 2 Gazebo world, any
//! robot whose ROS 2 driver publishes the standard topics) as a ROS 2 node speaking
//! DDS/RTPS itself (RustDDS and ros2-client, pure Rust: no ROS 2 installation), so
//! introrob, teleoperator and every schema run on it unchanged. See `docs/ros2.md`;
//! why these crates: the service `ros2`'s doc.
//!
//! # Conf
//! ```text
//! driver ros2
//! discovery subnet                # the robot is another machine: the LAN (default),
//!                                 #   or localhost (a simulator on this host)
//! insecure                        # for subnet (DDS here has no authentication; docs/ros2.md)
//! domain 0                        # ROS_DOMAIN_ID, 0..232 (default 0)
//! node jderobot_driver            # the node's name (default jderobot_driver)
//! namespace /                     # namespace of relative topic names (default /)
//! provides laser /scan            # sensor_msgs/msg/LaserScan, best effort (its mount
//!                                 #   from /tf_static, see below)
//! provides encoders /odom         # nav_msgs/msg/Odometry, reliable
//! provides motors /cmd_vel        # geometry_msgs/msg/Twist, written reliable
//! provides imu /imu               # sensor_msgs/msg/Imu, best effort
//! provides colorA /camera/image_raw   # sensor_msgs/msg/Image (bgr8, rgb8, mono8, bgra8,
//!                                 #   rgba8), best effort
//! provides varcolorA /camera/image_raw/compressed   # a topic ending in /compressed:
//!                                 #   sensor_msgs/msg/CompressedImage (JPEG or PNG)
//! silence 2000                    # ms without a message before the robot counts as lost
//! motors_timeout 500              # ms: a motors command older than this is sent as zero
//! end_driver
//! ```
//!
//! # Interfaces (the units of `crate::interfaces`)
//! `laser` (mm, the scan's own geometry: start, step, range limits; a scan whose
//! `angle_increment` is negative, from +angle to −angle, is read from its other
//! end, so it is the same value as the forward scan), `encoders` (x, y mm, θ
//! rad), `imu` (SI), `colorA..D`/`varcolorA..D` (BGR: `bgr8`, `rgb8`, `mono8`,
//! `bgra8` and `rgba8` Images, rows `step` bytes apart, converted once; or
//! JPEG/PNG CompressedImages of at most 8192x8192 pixels), `motors` (v mm/s, w
//! deg/s → Twist m/s, rad/s, sent every 100 ms and on each new command).
//!
//! The laser's mount: with a laser, the driver also reads `/tf_static` (as tf2's
//! static listener: reliable, transient local) and places the scan's frame
//! (its header's `frame_id`) in the root of the static tree it hangs from, the
//! robot's base (`base_link`; `base_footprint` on a TurtleBot 3): x, y mm and yaw
//! on the robot's plane (heights and small tilts left out). An upside-down laser
//! (its z axis down) is read from the other end, so angles stay counter-clockwise
//! on the robot. Without a static transform for the frame the mount is the
//! robot's centre.
//!
//! Sensor readers are best effort (they match best-effort and reliable writers:
//! real ROS 2 drivers publish sensor data best effort), the odometry reader is
//! reliable. The driver is a supervised device: until every topic has a message,
//! it says once which topics it waits for and its interfaces are stale; when one
//! falls silent for `silence` ms, they are stale with that reason and `motors`
//! goes to zero (also at stop). A topic whose publisher declares another type is
//! named with both types. A message that does not decode, or a value that is not
//! valid (NaN, infinite, an image whose size disagrees with its data), is refused
//! with one line and never reaches an interface.
//!
//! The stop: a zero Twist on the motors topic when the driver stops, when the
//! robot is lost (the topic is still written: a robot whose sensors fell silent
//! may still listen), and whenever the process ends or is suspended: it is
//! registered with [`crate::estop`] (SIGINT, SIGTERM, SIGHUP, Ctrl+Z, an abort
//! and a panic run it first) and written by a second writer of the topic; after
//! [`crate::estop::halted`] the driver sends only zero. What nothing can catch
//! (`kill -9`, power loss) sends nothing: the robot's base must time out a
//! silent `/cmd_vel` (docs/ros2.md).
//!
//! System packages: none.

use std::{
    sync::Arc,
    time::{Duration, Instant, SystemTime},
};

use rustdds::{
    DomainParticipant, QosPolicyBuilder, TopicKind,
    no_key::{DataReader, DataWriter},
    policy::{Durability, History, Reliability},
};

mod tf;
use tf::Statics;

use crate::{
    conf::{
        ComponentConf,
        settings::{self, MOTORS_TIMEOUT, Setting, int},
    },
    estop,
    interfaces::{AnyInterface, Encoders, Image, Imu, Interface, Kind, Laser, Motors, Source},
    mcapfmt::{
        dds::{
            self, Cdr, CdrAdapter, Graph, Readiness, Recycler, dds_topic, reliable_qos, ros_topic,
            sensor_qos,
        },
        ros2::{self, Ros2},
    },
    runtime::{Driver, Runtime},
    supervisor::{Backoff, Supervision, Supervisor},
};

crate::declare_lines! {
    struct Lines {
        provides: Vec<(String, Option<String>)> = settings::provides("provides laser|encoders|motors|imu|colorA..D|varcolorA..D [TOPIC]"),
        #[serde(default)]
        insecure: bool = settings::INSECURE,
        #[serde(default)]
        discovery: Option<String> = settings::ROS_DISCOVERY,
        domain: u16 = settings::ROS_DOMAIN,
        node: String = settings::ROS_NODE.default("jderobot_driver"),
        namespace: String = settings::ROS_NAMESPACE,
        silence: u64 = Setting::new(
            "silence",
            "a topic without a message this long makes the robot lost",
            &[int("MS", "ms", 100, 600_000)],
        )
        .default("2000"),
        motors_timeout: u64 = MOTORS_TIMEOUT,
    }
}
type Reader = DataReader<Cdr, CdrAdapter>;

/// One sensor topic read into one interface.
struct Input {
    topic: String,
    dds_type: &'static str,
    reader: Reader,
    source: Source,
    /// Decodes one message into the interface; false when refused.
    apply: Decode,
    last: Option<Instant>,
}

/// Decodes one CDR message into an interface (with the robot's static
/// transforms, for a laser's mount); false when the message is refused.
type Decode = Box<dyn FnMut(&Source, &[u8], &Statics) -> bool + Send>;

/// `motors` and the `/cmd_vel` writer it feeds, with the topic's name and
/// the stop registered with [`estop`].
struct CmdVelOut {
    iface: Arc<Interface<Motors>>,
    writer: DataWriter<Cdr, CdrAdapter>,
    topic: String,
    _estop: estop::Registration,
}

/// Decodes a message of `topic`: (wall time ns, value); the third argument is
/// the time of messages without a header, the last the robot's static transforms.
type DecodeFn<T> = fn(&str, &[u8], u64, &Statics) -> Result<(u64, T), crate::mcapfmt::FormatError>;

/// A reader of `topic` with its kind's ROS 2 message into `iface`.
fn input<T: Ros2 + Mounted>(
    dp: &DomainParticipant,
    sub: &rustdds::Subscriber,
    topic: String,
    reliable: bool,
    iface: Arc<Interface<T>>,
) -> anyhow::Result<Input> {
    let dds_type = T::MESSAGE.map(|m| m.dds).unwrap_or("");
    let dec: DecodeFn<T> = |topic, data, now, statics| {
        let (t, mut v) = ros2::decode::<T>(topic, data, now)?;
        v.mount(topic, data, statics);
        Ok((t, v))
    };
    input_as(dp, sub, topic, reliable, iface, dds_type, dec)
}

/// A value placed on the robot by the static transform of its message's frame.
trait Mounted {
    /// Sets the mount from `statics` for the frame of message `data`.
    fn mount(&mut self, _topic: &str, _data: &[u8], _statics: &Statics) {}
}

impl Mounted for Laser {
    fn mount(&mut self, topic: &str, data: &[u8], statics: &Statics) {
        if let Ok(frame) = ros2::header_frame(topic, data) {
            tf::mount_laser(self, statics, &frame);
        }
    }
}
impl Mounted for Encoders {}
impl Mounted for Imu {}
impl Mounted for Image {}

/// A topic ending in `/compressed` carries `sensor_msgs/msg/CompressedImage`
/// (image_transport's name for it), any other camera topic `sensor_msgs/msg/Image`.
fn camera_input(
    dp: &DomainParticipant,
    sub: &rustdds::Subscriber,
    topic: String,
    iface: Arc<Interface<Image>>,
) -> anyhow::Result<Input> {
    if topic.ends_with("/compressed") {
        let dec: DecodeFn<Image> = |t, d, _, _| ros2::decode_compressed(t, d);
        input_as(dp, sub, topic, false, iface, ros2::COMPRESSED_IMAGE, dec)
    } else {
        input(dp, sub, topic, false, iface)
    }
}

fn input_as<T: crate::interfaces::InterfaceValue>(
    dp: &DomainParticipant,
    sub: &rustdds::Subscriber,
    topic: String,
    reliable: bool,
    iface: Arc<Interface<T>>,
    dds_type: &'static str,
    decode: DecodeFn<T>,
) -> anyhow::Result<Input> {
    let t = dp
        .create_topic(
            dds_topic(&topic),
            dds_type.into(),
            &if reliable {
                reliable_qos(5)
            } else {
                sensor_qos()
            },
            TopicKind::NoKey,
        )
        .map_err(|e| anyhow::anyhow!("driver ros2: topic {topic}: {e}"))?;
    let reader = sub
        .create_datareader_no_key::<Cdr, CdrAdapter>(
            &t,
            Some(if reliable {
                reliable_qos(5)
            } else {
                sensor_qos()
            }),
        )
        .map_err(|e| anyhow::anyhow!("driver ros2: a reader of {topic}: {e}"))?;
    let name = topic.clone();
    Ok(Input {
        source: Source::new(format!("ros2: {topic}")),
        topic,
        dds_type,
        reader,
        apply: Box::new(move |source, data, statics| {
            let now = crate::mcapfmt::nanos(SystemTime::now());
            match decode(&name, data, now, statics) {
                Ok((_, v)) => iface.accept(source, v).is_some(),
                Err(e) => {
                    source.refused(e);
                    false
                }
            }
        }),
        last: None,
    })
}

/// `/tf_static`'s reader (when the driver provides a laser) and what it heard.
struct StaticsInput {
    reader: Reader,
    source: Source,
    statics: Statics,
}

impl StaticsInput {
    /// Takes the waiting `TFMessage`s into the static tree.
    fn take(&mut self) {
        loop {
            match self.reader.take_next_sample() {
                Ok(Some(sample)) => {
                    let r = ros2::decode_tf(TF_STATIC, &sample.value().0)
                        .map_err(|e| e.to_string())
                        .and_then(|t| self.statics.add(t));
                    if let Err(e) = r {
                        self.source.refused(e);
                    }
                }
                Ok(None) => break,
                Err(e) => {
                    self.source.refused(format!("{TF_STATIC}: {e}"));
                    break;
                }
            }
        }
    }
}

const TF_STATIC: &str = "/tf_static";

/// The reader of `/tf_static` as tf2's static listener makes it: reliable,
/// transient local (a late reader gets what was sent), keep last 100.
fn statics_input(
    dp: &DomainParticipant,
    sub: &rustdds::Subscriber,
) -> anyhow::Result<StaticsInput> {
    let qos = QosPolicyBuilder::new()
        .reliability(Reliability::Reliable {
            max_blocking_time: rustdds::Duration::from_millis(100),
        })
        .history(History::KeepLast { depth: 100 })
        .durability(Durability::TransientLocal)
        .build();
    let t = dp
        .create_topic(
            dds_topic(TF_STATIC),
            ros2::TF_MESSAGE.into(),
            &qos,
            TopicKind::NoKey,
        )
        .map_err(|e| anyhow::anyhow!("driver ros2: topic {TF_STATIC}: {e}"))?;
    let reader = sub
        .create_datareader_no_key::<Cdr, CdrAdapter>(&t, Some(qos))
        .map_err(|e| anyhow::anyhow!("driver ros2: a reader of {TF_STATIC}: {e}"))?;
    Ok(StaticsInput {
        reader,
        source: Source::new(format!("ros2: {TF_STATIC}")),
        statics: Statics::default(),
    })
}

struct Robot {
    inputs: Vec<Input>,
    /// `/tf_static`, read for the laser's mount.
    statics: Option<StaticsInput>,
    motors: Option<CmdVelOut>,
    silence: Duration,
    timeout: Duration,
    /// The node; dropping it leaves the graph.
    graph: Graph,
    bufs: Recycler,
    /// Wakes `step` when a reader has data (it also runs every 2 ms for motors).
    ready: Readiness,
}

struct Session {
    since: Instant,
    sent: Option<(u64, Instant)>,
}

/// Encodes `m` as a `geometry_msgs/Twist` into `buf`; false if it cannot be.
fn twist(m: Motors, buf: &mut Vec<u8>) -> bool {
    let s = crate::interfaces::Sample {
        clock: 1,
        stamp: Instant::now(),
        time: SystemTime::now(),
        value: m,
    };
    ros2::encode("", &s, buf)
}

impl Robot {
    fn send_motors(&mut self, m: Motors) {
        if let Some(o) = &self.motors {
            let mut buf = self.bufs.buffer();
            if twist(m, &mut buf) {
                let _ = o.writer.write(self.bufs.message(buf), None);
            }
        }
    }

    /// A topic whose writers declare another type: both names.
    fn wrong_type(&self) -> Option<String> {
        let topics = self.graph.dp.discovered_topics();
        self.inputs.iter().find_map(|i| {
            let dds = dds_topic(&i.topic);
            topics
                .iter()
                .find(|t| *t.topic_name() == dds && t.type_name() != i.dds_type)
                .map(|t| {
                    format!(
                        "{} carries {}, the driver reads {}",
                        i.topic,
                        t.type_name(),
                        i.dds_type
                    )
                })
        })
    }
}

impl crate::supervisor::Device for Robot {
    type Session = Session;
    fn open(&mut self) -> Result<Session, String> {
        for i in &mut self.inputs {
            i.last = None;
        }
        Ok(Session {
            since: Instant::now(),
            sent: None,
        })
    }

    fn step(&mut self, s: &mut Session) -> Result<(), String> {
        self.ready.wait(Some(Duration::from_millis(2)));
        if let Some(s) = &mut self.statics {
            s.take();
        }
        let none = Statics::default();
        let statics = self.statics.as_ref().map_or(&none, |s| &s.statics);
        for i in &mut self.inputs {
            loop {
                match i.reader.take_next_sample() {
                    Ok(Some(sample)) => {
                        if (i.apply)(&i.source, &sample.value().0, statics) {
                            i.last = Some(Instant::now());
                        }
                    }
                    Ok(None) => break,
                    Err(e) => {
                        i.source.refused(format!("{}: {e}", i.topic));
                        break;
                    }
                }
            }
        }
        // Motors: every new command at once, and again every 100 ms.
        if let Some(o) = &self.motors {
            let clock = o.iface.clock();
            // Once the process is ending (estop::halt), nothing but zero.
            let cmd = if estop::halted() {
                Motors::default()
            } else {
                o.iface.command(self.timeout)
            };
            let due = match s.sent {
                None => true,
                Some((c, t)) => c != clock || t.elapsed() >= Duration::from_millis(100),
            };
            if due {
                s.sent = Some((clock, Instant::now()));
                self.send_motors(cmd);
            }
        }
        // A topic still silent after `silence`: say why (a wrong type, or no
        // publisher). Only then is discovery's topic list looked at.
        if s.since.elapsed() >= self.silence && self.inputs.iter().any(|i| i.last.is_none()) {
            if let Some(e) = self.wrong_type() {
                return Err(e);
            }
            let waiting: Vec<&str> = self
                .inputs
                .iter()
                .filter(|i| i.last.is_none())
                .map(|i| i.topic.as_str())
                .collect();
            return Err(format!("waiting for a publisher on {}", waiting.join(", ")));
        }
        if let Some(i) = self
            .inputs
            .iter()
            .find(|i| i.last.is_some_and(|t| t.elapsed() >= self.silence))
        {
            return Err(format!(
                "no message on {} for {} ms",
                i.topic,
                self.silence.as_millis()
            ));
        }
        Ok(())
    }

    fn on_loss(&mut self) {
        if let Some(o) = &self.motors {
            let _ = o.iface.publish(Motors::default());
        }
        self.send_motors(Motors::default());
    }
}

/// The DDS type name of kind `T`'s ROS 2 message.
fn ros2_type<T: Ros2>() -> &'static str {
    T::MESSAGE.map(|m| m.dds).unwrap_or("")
}

/// The writer of the robot's velocity command (`/cmd_vel`, reliable) for
/// `motors`, and the stop registered with [`estop`]: a zero Twist written by a
/// second writer of the topic, which only the stop uses (RustDDS's own thread
/// sends it; nothing the driver's thread holds is waited for, the readers'
/// acknowledgements at most 50 ms).
fn motors_output(
    dp: &DomainParticipant,
    publ: &rustdds::Publisher,
    topic: String,
    motors: Arc<Interface<Motors>>,
) -> anyhow::Result<CmdVelOut> {
    let dds_type = Motors::MESSAGE.map(|m| m.dds).unwrap_or("");
    let t = dp
        .create_topic(
            dds_topic(&topic),
            dds_type.into(),
            &reliable_qos(5),
            TopicKind::NoKey,
        )
        .map_err(|e| anyhow::anyhow!("driver ros2: topic {topic}: {e}"))?;
    let writer = || {
        publ.create_datawriter_no_key::<Cdr, CdrAdapter>(&t, Some(reliable_qos(5)))
            .map_err(|e| anyhow::anyhow!("driver ros2: a writer of {topic}: {e}"))
    };
    let (w, stop) = (writer()?, parking_lot::Mutex::new(writer()?));
    let mut zero = Vec::new();
    if !twist(Motors::default(), &mut zero) {
        anyhow::bail!("driver ros2: cannot encode a zero Twist for {topic}");
    }
    let zero = bytes::Bytes::from(zero);
    let _estop = estop::register(format!("ros2 {topic}"), move || {
        if let Some(w) = stop.try_lock_for(Duration::from_millis(50)) {
            // RustDDS's thread sends it: wait (a little) for the readers' acks,
            // or a suspension (Ctrl+Z) right after could stop it unsent.
            if w.write(Cdr(zero.clone()), None).is_ok() {
                let _ = w.wait_for_acknowledgments(Duration::from_millis(50));
            }
        }
    });
    Ok(CmdVelOut {
        iface: motors,
        writer: w,
        topic,
        _estop,
    })
}

/// What the `provides` lines make: the readers that feed the interfaces, the
/// `/cmd_vel` writer, and the interfaces provided.
type Provided = (Vec<Input>, Option<CmdVelOut>, Vec<Arc<dyn AnyInterface>>);

/// Provides the interfaces of the `provides` lines ([`Provided`]).
fn provide(
    l: &Lines,
    conf: &ComponentConf,
    rt: &Runtime,
    graph: &Graph,
    sub: &rustdds::Subscriber,
    publ: &rustdds::Publisher,
) -> anyhow::Result<Provided> {
    let (ns, dp) = (&graph.ns, &graph.dp);
    let mut inputs = vec![];
    let mut motors = None;
    let mut ifaces: Vec<Arc<dyn AnyInterface>> = vec![];
    for (name, topic) in &l.provides {
        let kind = crate::interfaces::family(name);
        let default = match kind {
            Some(Kind::Laser) => "scan".to_string(),
            Some(Kind::Encoders) => "odom".to_string(),
            Some(Kind::Motors) => "cmd_vel".to_string(),
            Some(Kind::Imu) => "imu".to_string(),
            _ => format!("{name}/image_raw"),
        };
        let topic = ros_topic(ns, topic.as_deref().unwrap_or(&default));
        match kind {
            Some(Kind::Laser) => {
                let i = rt.interfaces.provide::<Laser>(name, &conf.name)?;
                ifaces.push(i.clone());
                inputs.push(input(dp, sub, topic, false, i)?);
            }
            Some(Kind::Encoders) => {
                let i = rt.interfaces.provide::<Encoders>(name, &conf.name)?;
                ifaces.push(i.clone());
                inputs.push(input(dp, sub, topic, true, i)?);
            }
            Some(Kind::Imu) => {
                let i = rt.interfaces.provide::<Imu>(name, &conf.name)?;
                ifaces.push(i.clone());
                inputs.push(input(dp, sub, topic, false, i)?);
            }
            Some(Kind::Image) => {
                let i = rt.interfaces.provide::<Image>(name, &conf.name)?;
                ifaces.push(i.clone());
                inputs.push(camera_input(dp, sub, topic, i)?);
            }
            Some(Kind::Motors) => {
                let i = rt.interfaces.provide::<Motors>(name, &conf.name)?;
                ifaces.push(i.clone());
                motors = Some(motors_output(dp, publ, topic, i)?);
            }
            Some(
                Kind::Sonars
                | Kind::Bumpers
                | Kind::PtEncoders
                | Kind::PtMotors
                | Kind::ZoomEncoders
                | Kind::ZoomMotors,
            )
            | None => anyhow::bail!(
                "driver ros2: provides {name}: this driver provides laser, encoders, motors, \
                 imu and cameras (colorA..D, varcolorA..D)"
            ),
        }
    }
    Ok((inputs, motors, ifaces))
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let l: Lines = conf.read()?;
    let range = dds::discovery_range(
        l.discovery.as_deref(),
        l.insecure,
        "driver ros2",
        "drive it",
    )?;
    if l.provides.is_empty() {
        anyhow::bail!(
            "driver ros2 has no `provides` line, and needs one: provides laser /scan, \
             provides encoders /odom, provides motors /cmd_vel, ..."
        );
    }
    let graph = Graph::join("driver ros2", range, l.domain, &l.namespace, &l.node)?;
    let dp = &graph.dp;
    let sub = dp
        .create_subscriber(&reliable_qos(5))
        .map_err(|e| anyhow::anyhow!("driver ros2: {e}"))?;
    let publ = dp
        .create_publisher(&reliable_qos(5))
        .map_err(|e| anyhow::anyhow!("driver ros2: {e}"))?;
    let (mut inputs, motors, ifaces) = provide(&l, conf, rt, &graph, &sub, &publ)?;
    // The laser's mount from the robot's static transforms, when it has a laser.
    let mut statics = if inputs.iter().any(|i| i.dds_type == ros2_type::<Laser>()) {
        Some(statics_input(dp, &sub)?)
    } else {
        None
    };
    let mut ready = Readiness::new("driver ros2")?;
    for i in &mut inputs {
        ready.add(&mut i.reader)?;
    }
    if let Some(s) = &mut statics {
        ready.add(&mut s.reader)?;
    }
    let waits: Vec<String> = inputs.iter().map(|i| i.topic.clone()).collect();
    tracing::info!(
        "ros2: node {} on domain {} ({}) reads {}{}",
        graph.full_name(),
        l.domain,
        graph.reach(),
        waits.join(", "),
        motors
            .as_ref()
            .map(|m| format!(", writes {}", m.topic))
            .unwrap_or_default()
    );
    let robot = Robot {
        inputs,
        statics,
        motors,
        silence: Duration::from_millis(l.silence),
        timeout: Duration::from_millis(l.motors_timeout),
        graph,
        bufs: Recycler::default(),
        ready,
    };
    let how = Supervision {
        name: "ros2".into(),
        interfaces: ifaces,
        on_demand: false,
        backoff: Backoff {
            first: Duration::from_millis(100),
            max: Duration::from_secs(1),
        },
        absent: None,
    };
    Ok(Box::new(Supervisor::start(how, robot)?))
}

crate::register_driver!(
    Driver,
    "ros2",
    "a ROS 2 robot over DDS: laser (/scan), encoders (/odom), motors (/cmd_vel), imu, cameras",
    create,
    lines = Lines
);
