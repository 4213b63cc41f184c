//! Service `ros2`: serves this process's robot to ROS 2, as a ROS 2 node speaking
//! DDS/RTPS itself (no ROS 2 installation): RViz2, `ros2 topic echo`, rosbag2 and
//! Nav2 see its topics, and `/cmd_vel` drives its motors. See `docs/ros2.md`.
//!
//! # Why RustDDS and ros2-client
//! Both are pure Rust (no C/C++ toolchain, no system package), maintained (RustDDS
//! 0.11, ros2-client 0.8, 2025), and interoperate with Fast DDS and Cyclone DDS,
//! the DDS of ROS 2's Tier-1 middlewares. ros2-client puts the node in the ROS 2
//! graph (`ros_discovery_info`, so `ros2 node list` shows it); the topics are plain
//! RustDDS writers and readers of the CDR bytes of `mcapfmt::ros2`, the one
//! encoder per message that zenoh's `format ros2` and the recorder also use
//! ([`crate::mcapfmt::dds`]). Their clean debug build adds about a minute
//! (docs/ros2.md has the measure), so `ros2` is in `full`, not in `default`.
//!
//! # Conf
//! ```text
//! service ros2
//! discovery localhost      # this host only (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST),
//!                          #   or subnet (the LAN, the default: needs `insecure`)
//! insecure                 # for subnet: DDS here has no authentication (see below)
//! node jderobot            # the node's name (default jderobot)
//! namespace /              # the node's namespace and its relative topics' (default /)
//! domain 0                 # ROS_DOMAIN_ID, 0..232 (default 0)
//! serves laser             # what is served (default: every interface with a
//! serves encoders odom     #   ROS 2 message); an optional ROS 2 topic name
//! frames odom base_link laser camera   # frame ids ODOM BASE LASER CAMERA (the defaults):
//!                          #   /odom and /tf ODOM → BASE, /tf_static BASE → LASER,
//!                          #   /scan LASER, images CAMERA, /imu and /hazard_detection BASE
//! compressed colorA 80     # also colorA as CompressedImage, JPEG quality 80 (repeatable)
//! sonar 25 100 5000        # each sonar's field of view (deg), min and max range (mm)
//! joints pan tilt          # the pan-tilt's joint names
//! clock auto               # stamps and /clock: auto (the run's clock if there is
//!                          #   one, else wall), sim (the run's clock), wall (no /clock)
//! motors_timeout 500       # ms: /cmd_vel older than this counts as zero
//! end_service
//! ```
//!
//! # Topics (REP 103 units: m, rad, m/s, rad/s; REP 105 frames)
//! | interface | topic (default) | type | QoS |
//! |---|---|---|---|
//! | laser | `scan` | `sensor_msgs/msg/LaserScan`, the scan's own geometry | best effort, keep last 5 |
//! | encoders | `odom` | `nav_msgs/msg/Odometry` ODOM → BASE (`frames`: odom → base_link) | reliable, keep last 10 |
//! | encoders | `/tf` | `tf2_msgs/msg/TFMessage` ODOM → BASE, the same two frames | reliable, keep last 100 |
//! | laser | `/tf_static` | BASE → LASER (the laser's mount) | reliable, transient local, keep last 1 |
//! | imu | `imu` | `sensor_msgs/msg/Imu` | best effort, keep last 5 |
//! | colorA..D, varcolorA..D | `NAME/image_raw` | `sensor_msgs/msg/Image` `bgr8` | best effort, keep last 5 |
//! | sonars | `sonar_0`..`sonar_N` | `sensor_msgs/msg/Range` ULTRASOUND, frame `sonar_I` | best effort, keep last 5 |
//! | bumpers | `hazard_detection` | `irobot_create_msgs/msg/HazardDetectionVector` (the Create 3's): a BUMP per pressed bumper, frame `bumper_I` | best effort, keep last 5 |
//! | pantiltencoders | `joint_states` | `sensor_msgs/msg/JointState` `pan`, `tilt`, rad | reliable, keep last 10 |
//! | pantiltmotors | `joint_command` (read) | `sensor_msgs/msg/JointState`: positions rad, velocities rad/s | best-effort reader |
//! | `compressed` cameras | `NAME/image_raw/compressed` | `sensor_msgs/msg/CompressedImage` JPEG | best effort, keep last 5 |
//! | motors | `cmd_vel` (read) | `geometry_msgs/msg/Twist` → v mm/s, w deg/s | reliable (a best-effort writer matches too) |
//! | (the run's clock) | `/clock` | `rosgraph_msgs/msg/Clock` | reliable, keep last 1 |
//!
//! # Time
//! With `clock auto` (the default) or `sim`, when the run's time is not wall time
//! (a replay, or the simulator with `speed` other than 1, `max` or `stepped`:
//! they export [`RunClock`] as `run.clock`), the service publishes that time on
//! `/clock` (when it moved, every 10 ms at most) and stamps every message with
//! it, so ROS 2 nodes run with `use_sim_time:=true`. Otherwise stamps are the
//! samples' own (wall) times and there is no `/clock`.
//!
//! # Threads
//! One thread sends the sensor topics as their interfaces change; `/cmd_vel` and
//! `joint_command` are read on a thread of their own (`ros2-cmd`), woken by the
//! data or the stop, so a reliable write to a slow subscriber of `/odom` or `/tf` (which can
//! block up to 100 ms) never delays a command or a stop.
//!
//! A Twist that is not a valid motors value (NaN, infinite, out of motors' range)
//! is refused with one line. Motors are set to zero `motors_timeout` after the
//! last `/cmd_vel` (so also when its writer leaves), and when the service stops;
//! the pan-tilt is then held where its encoders say it is (0° would swing it).
//!
//! # Security
//! With `discovery localhost` (or, without the line, ROS 2's
//! `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` / `ROS_LOCALHOST_ONLY=1`) DDS stays on
//! this host: multicast on the loopback interface, sockets on 127.0.0.1, nothing
//! sent elsewhere (the vendored RustDDS's `set_localhost_only`; one range per
//! process). With `subnet` it speaks on every multicast-capable interface, and
//! anyone on the LAN could read the robot and drive it: DDS Security would be
//! needed to prevent it, and it is not set up here. So `subnet` starts only with
//! `insecure`, which says so.
//!
//! Provides no interface; uses the served ones.

use std::{
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, Instant, SystemTime},
};

use rustdds::{
    DomainParticipant, Publisher, QosPolicies, QosPolicyBuilder, Subscriber, TopicKind,
    no_key::{DataReader, DataWriter},
    policy::{History, Reliability},
};

use crate::{
    conf::{
        ComponentConf,
        settings::{self, MOTORS_TIMEOUT, Setting, choice, float, int, interface, word},
    },
    interfaces::{
        Bumpers, Encoders, Image, Imu, Interface, InterfaceValue, Kind, Laser, Motors, Mount,
        PtEncoders, PtMotors, Sample, Sonars, Source, Watch,
    },
    mcapfmt::{
        dds::{
            self, Cdr, CdrAdapter, Graph, Readiness, Recycler, dds_topic, reliable_qos, ros_topic,
            sensor_qos, static_qos,
        },
        ros2::{self, Joints, RangeReading, Ros2, Transform},
    },
    runtime::{Driver, RunClock, Runtime},
    supervisor::Worker,
};

crate::declare_lines! {
    struct Lines {
        #[serde(default)]
        insecure: bool = settings::INSECURE,
        #[serde(default)]
        discovery: Option<String> = settings::ROS_DISCOVERY,
        node: String = settings::ROS_NODE.default("jderobot"),
        namespace: String = settings::ROS_NAMESPACE,
        domain: u16 = settings::ROS_DOMAIN,
        serves: Vec<(String, Option<String>)> = Setting::new(
            "serves",
            "an interface served, on its default topic or TOPIC (default: all with a ROS 2 message)",
            &[interface("INTERFACE"), word("TOPIC").optional()],
        )
        .repeats(),
        frames: (String, String, String, String) = Setting::new(
            "frames",
            "frame ids: odometry, robot base, laser, camera",
            &[word("ODOM"), word("BASE"), word("LASER"), word("CAMERA")],
        )
        .default("odom base_link laser camera"),
        compressed: Vec<(String, Option<u8>)> = Setting::new(
            "compressed",
            "also serve camera INTERFACE as sensor_msgs/msg/CompressedImage (JPEG of QUALITY) \
             on NAME/image_raw/compressed",
            &[
                interface("INTERFACE"),
                int("QUALITY", "", 1, 100).optional(),
            ],
        )
        .repeats(),
        sonar: (f32, f32, f32) = Setting::new(
            "sonar",
            "each sonar's field of view and range limits (sensor_msgs/msg/Range)",
            &[
                float("FOV", "deg", 0.0, 180.0),
                float("MIN", "mm", 0.0, 1e6),
                float("MAX", "mm", 0.0, 1e6),
            ],
        )
        .default("25 100 5000"),
        joints: (String, String) = Setting::new(
            "joints",
            "the pan-tilt's joint names on joint_states and joint_command",
            &[word("PAN"), word("TILT")],
        )
        .default("pan tilt"),
        clock: String = Setting::new(
            "clock",
            "the time of the stamps and of /clock: auto (the run's clock when a replay or a \
             simulator not in real time keeps one, else wall), sim (the run's clock; an error \
             without one) or wall (no /clock)",
            &[choice("MODE", &["auto", "sim", "wall"])],
        )
        .default("auto"),
        motors_timeout: u64 = MOTORS_TIMEOUT,
    }
}
type Writer = DataWriter<Cdr, CdrAdapter>;
type Reader = DataReader<Cdr, CdrAdapter>;

/// Whether a sample written now would reach anyone. The sensor topics are
/// volatile (a reader that comes later gets the next sample, not this one), so
/// with no reader the service neither encodes nor writes: each write wakes
/// RustDDS's event loop, and /tf at 20 Hz to nobody was a tenth of the
/// service's CPU (benches/ros2.rs `cpu`, whose subscribers read /scan and
/// /odom). `/tf_static` (transient local) is always written.
fn read_by_anyone(w: &Writer) -> bool {
    w.matched_readers() > 0
}

fn writer(
    dp: &DomainParticipant,
    publisher: &Publisher,
    topic: &str,
    dds_type: &str,
    qos: QosPolicies,
) -> anyhow::Result<Writer> {
    let t = dp
        .create_topic(dds_topic(topic), dds_type.into(), &qos, TopicKind::NoKey)
        .map_err(|e| anyhow::anyhow!("ros2: topic {topic}: {e}"))?;
    publisher
        .create_datawriter_no_key::<Cdr, CdrAdapter>(&t, Some(qos))
        .map_err(|e| anyhow::anyhow!("ros2: a writer of {topic}: {e}"))
}

fn dds_name<T: Ros2>() -> &'static str {
    T::MESSAGE.map(|m| m.dds).unwrap_or("")
}

/// Writes a sample's message into the buffer (frame, sample); false: nothing to send.
type Encode<T> = Box<dyn Fn(&str, &Sample<T>, &mut Vec<u8>) -> bool + Send>;

/// One served sensor: its interface, its writer, the last clock sent.
struct Served<T> {
    iface: Arc<Interface<T>>,
    topic: String,
    frame: String,
    writer: Writer,
    encode: Encode<T>,
    bufs: Recycler,
    clock: u64,
}

impl<T: InterfaceValue> Served<T> {
    /// Sends the interface's value if it is new, stamped `stamp` (the run's
    /// clock) or else with its own time.
    fn send(&mut self, stamp: Option<SystemTime>) -> Option<Arc<Sample<T>>> {
        let s = self.iface.snapshot();
        if s.clock == self.clock || s.clock == 0 {
            return None;
        }
        self.clock = s.clock;
        if !read_by_anyone(&self.writer) {
            return Some(s);
        }
        let mut buf = self.bufs.buffer();
        if !(self.encode)(&self.frame, &s, &mut buf) {
            return Some(s);
        }
        if let Some(t) = stamp {
            ros2::restamp(&mut buf, t);
        }
        if let Err(e) = self.writer.write(self.bufs.message(buf), None) {
            tracing::debug!("ros2: {}: {e}", self.topic);
        }
        Some(s)
    }
}

/// What the serving thread sends on each new value of an interface.
trait Out: Send {
    /// Sends a new value, stamped `stamp` if given (else its own time).
    fn send(&mut self, stamp: Option<SystemTime>);
    /// Watches and resumes the interface; the closure lets it go.
    fn use_it(&self, watch: &Arc<Watch>) -> Box<dyn FnOnce()>;
}

impl<T: InterfaceValue> Out for Served<T> {
    fn send(&mut self, stamp: Option<SystemTime>) {
        Served::send(self, stamp);
    }
    fn use_it(&self, watch: &Arc<Watch>) -> Box<dyn FnOnce()> {
        in_use(&self.iface, watch)
    }
}

/// The sonar ring: one `sensor_msgs/msg/Range` topic per sonar (`BASE_I`, frame
/// `FRAME_I`), each writer made when its sonar first reports.
struct SonarsOut {
    iface: Arc<Interface<Sonars>>,
    topic: String,
    frame: String,
    geometry: (f32, f32, f32),
    writers: Vec<Writer>,
    dp: DomainParticipant,
    publisher: Publisher,
    bufs: Recycler,
    clock: u64,
}

impl Out for SonarsOut {
    fn send(&mut self, stamp: Option<SystemTime>) {
        let s = self.iface.snapshot();
        if s.clock == self.clock || s.clock == 0 {
            return;
        }
        self.clock = s.clock;
        let (fov, min, max) = self.geometry;
        for (i, us) in s.value.us.iter().enumerate() {
            if i == self.writers.len() {
                let topic = format!("{}_{i}", self.topic);
                match writer(&self.dp, &self.publisher, &topic, ros2::RANGE, sensor_qos()) {
                    Ok(w) => self.writers.push(w),
                    Err(e) => {
                        tracing::warn!("service ros2: {e}");
                        return;
                    }
                }
            }
            if !read_by_anyone(&self.writers[i]) {
                continue;
            }
            let frame = format!("{}_{i}", self.frame);
            let r = RangeReading {
                frame: &frame,
                field_of_view: fov.to_radians(),
                min_range: min / 1000.0,
                max_range: max / 1000.0,
                range: us / 1000.0,
            };
            let mut buf = self.bufs.buffer();
            ros2::encode_range(stamp.unwrap_or(s.time), &r, &mut buf);
            let _ = self.writers[i].write(self.bufs.message(buf), None);
        }
    }
    fn use_it(&self, watch: &Arc<Watch>) -> Box<dyn FnOnce()> {
        in_use(&self.iface, watch)
    }
}

#[derive(Default)]
struct Plan {
    sensors: Vec<Box<dyn Out>>,
    odom: Vec<(Served<Encoders>, Writer)>,
    commands: Commands,
    /// The robot's frame (`frames` line), the child of odom on `/tf`.
    base_frame: String,
    /// `/tf_static`'s writer, and the mounts it sends.
    tf_static: Option<Writer>,
    statics: Vec<Transform>,
    /// The run's clock and `/clock`'s writer (`clock` auto or sim, with a clock).
    clock: Option<(Arc<RunClock>, Writer)>,
}

/// What drives the robot: `/cmd_vel` and `joint_command`, read on a thread of
/// their own.
#[derive(Default)]
struct Commands {
    cmd: Option<Command<Motors>>,
    pantilt: Option<Command<PtMotors>>,
    /// The pan-tilt's encoders (to hold it where it is), and its joint names.
    pt_encoders: Option<Arc<Interface<PtEncoders>>>,
    joints: (String, String),
}

/// A commanded interface, the reader of the topic that drives it, and when the
/// last accepted command came.
struct Command<T> {
    iface: Arc<Interface<T>>,
    reader: Reader,
    topic: String,
    source: Source,
    last: Option<Instant>,
}

impl<T> Command<T> {
    fn new(iface: Arc<Interface<T>>, reader: Reader, topic: String) -> Command<T> {
        let source = Source::new(format!("ros2: {topic}"));
        Command {
            iface,
            reader,
            topic,
            source,
            last: None,
        }
    }

    /// Takes every waiting message; `apply` turns one into a value or says why not.
    fn drain(&mut self, mut apply: impl FnMut(&str, &[u8]) -> Result<T, String>)
    where
        T: InterfaceValue,
    {
        loop {
            match self.reader.take_next_sample() {
                Ok(Some(sample)) => match apply(&self.topic, &sample.value().0) {
                    Ok(v) => {
                        if self.iface.accept(&self.source, v).is_some() {
                            self.last = Some(Instant::now());
                        }
                    }
                    Err(e) => {
                        self.source.refused(e);
                    }
                },
                Ok(None) => break,
                Err(e) => {
                    self.source.refused(format!("{}: {e}", self.topic));
                    break;
                }
            }
        }
    }

    /// How long until the last command is `timeout` old (None: no command held).
    fn expires_in(&self, timeout: Duration) -> Option<Duration> {
        self.last.map(|t| timeout.saturating_sub(t.elapsed()))
    }

    /// True once when the last command is `timeout` old (or at stop: `timeout` 0).
    fn expired(&mut self, timeout: Duration) -> bool {
        let old = self.last.is_some_and(|t| t.elapsed() >= timeout);
        if old {
            self.last = None;
        }
        old
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let l: Lines = conf.read()?;
    let range = dds::discovery_range(
        l.discovery.as_deref(),
        l.insecure,
        "service ros2",
        "serve it",
    )?;
    let d = Dds::join(&l, range)?;
    let serves = served_names(&l, rt);
    let mut plan = Plan::new(rt, &d, &l, &serves)?;
    if !plan.statics.is_empty() {
        let w = writer(
            &d.graph.dp,
            &d.publisher,
            "/tf_static",
            ros2::TF_MESSAGE,
            static_qos(),
        )?;
        plan.tf_static = Some(w);
    }
    plan.clock = run_clock(&l, rt, &d)?;
    let timeout = Duration::from_millis(l.motors_timeout);
    let stop = Arc::new(AtomicBool::new(false));
    let stop2 = stop.clone();
    let ready = Readiness::new("service ros2")?;
    let commands_waker = ready.waker();
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    let keep_name = format!("{} ({})", d.graph.full_name(), d.graph.reach());
    let keep = d.graph;
    let worker = Worker::start("ros2", stop.clone(), move || {
        let watch = Watch::for_current_thread();
        let _ = tx.send(watch.clone());
        serve(plan, watch, ready, timeout, stop2, keep);
    })?;
    let watch = rx.recv().ok();
    tracing::info!(
        "ros2: node {} on domain {}: {}",
        keep_name,
        l.domain,
        serves
            .iter()
            .map(|s| s.0.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(Box::new(Ros2Service {
        worker,
        watch,
        commands_waker,
    }))
}

/// The run's clock and `/clock`'s writer, per the `clock` line.
fn run_clock(l: &Lines, rt: &Runtime, d: &Dds) -> anyhow::Result<Option<(Arc<RunClock>, Writer)>> {
    let clock = match l.clock.as_str() {
        "wall" => None,
        "sim" => Some(RunClock::import(&rt.names).ok_or_else(|| {
            anyhow::anyhow!(
                "service ros2: clock sim: no run's clock (`run.clock`) to serve; load a replay \
                 or a simulator with `speed` other than 1 before the service, or say `clock wall`"
            )
        })?),
        _ => RunClock::import(&rt.names),
    };
    let Some(clock) = clock else {
        return Ok(None);
    };
    // Reliable, keep last 1: rclcpp's ClockQoS readers (best effort) and
    // default-QoS readers (reliable) both match it.
    let qos = QosPolicyBuilder::new()
        .reliability(Reliability::Reliable {
            max_blocking_time: rustdds::Duration::from_millis(100),
        })
        .history(History::KeepLast { depth: 1 })
        .build();
    let w = writer(&d.graph.dp, &d.publisher, "/clock", ros2::CLOCK, qos)?;
    Ok(Some((clock, w)))
}

/// The kinds this service has a ROS 2 topic for.
const SERVED_KINDS: &[Kind] = &[
    Kind::Laser,
    Kind::Encoders,
    Kind::Motors,
    Kind::Imu,
    Kind::Image,
    Kind::Sonars,
    Kind::Bumpers,
    Kind::PtEncoders,
    Kind::PtMotors,
];

/// What is served: the serves lines, or every interface with a ROS 2 topic.
fn served_names(l: &Lines, rt: &Runtime) -> Vec<(String, Option<String>)> {
    if !l.serves.is_empty() {
        return l.serves.clone();
    }
    rt.interfaces
        .all()
        .iter()
        .filter(|i| SERVED_KINDS.contains(&i.kind()))
        .map(|i| (i.name().to_string(), None))
        .collect()
}

/// The node in the ROS 2 graph and the DDS entities its topics hang from.
struct Dds {
    graph: Graph,
    publisher: Publisher,
    subscriber: Subscriber,
}

impl Dds {
    fn join(l: &Lines, range: dds::Range) -> anyhow::Result<Dds> {
        let graph = Graph::join("service ros2", range, l.domain, &l.namespace, &l.node)?;
        let publisher = graph
            .dp
            .create_publisher(&reliable_qos(10))
            .map_err(|e| anyhow::anyhow!("service ros2: {e}"))?;
        let subscriber = graph
            .dp
            .create_subscriber(&reliable_qos(10))
            .map_err(|e| anyhow::anyhow!("service ros2: {e}"))?;
        Ok(Dds {
            graph,
            publisher,
            subscriber,
        })
    }

    /// `iface` served on `topic` with its kind's ROS 2 message.
    fn served<T: Ros2>(
        &self,
        iface: Arc<Interface<T>>,
        topic: String,
        frame: String,
        qos: QosPolicies,
    ) -> anyhow::Result<Served<T>> {
        let enc: Encode<T> = Box::new(|f, s, b| ros2::encode(f, s, b));
        self.served_as(iface, topic, frame, qos, dds_name::<T>(), enc)
    }

    /// `iface` served on `topic` as DDS type `dds_type`, written by `encode`.
    fn served_as<T>(
        &self,
        iface: Arc<Interface<T>>,
        topic: String,
        frame: String,
        qos: QosPolicies,
        dds_type: &str,
        encode: Encode<T>,
    ) -> anyhow::Result<Served<T>> {
        let writer = writer(&self.graph.dp, &self.publisher, &topic, dds_type, qos)?;
        Ok(Served {
            iface,
            topic,
            frame,
            writer,
            encode,
            bufs: Recycler::default(),
            clock: 0,
        })
    }

    /// The reader of a command topic of DDS type `dds_type`.
    fn reader(&self, topic: &str, dds_type: &str) -> anyhow::Result<Reader> {
        let t = self
            .graph
            .dp
            .create_topic(
                dds_topic(topic),
                dds_type.into(),
                &reliable_qos(10),
                TopicKind::NoKey,
            )
            .map_err(|e| anyhow::anyhow!("service ros2: topic {topic}: {e}"))?;
        // A best-effort reader matches reliable and best-effort writers.
        let qos = QosPolicyBuilder::new()
            .reliability(Reliability::BestEffort)
            .history(History::KeepLast { depth: 10 })
            .build();
        self.subscriber
            .create_datareader_no_key::<Cdr, CdrAdapter>(&t, Some(qos))
            .map_err(|e| anyhow::anyhow!("service ros2: a reader of {topic}: {e}"))
    }
}

/// The static transform `parent` → `child` of a sensor's mount (mm, deg → m, rad).
fn mount_transform(parent: &str, child: &str, m: Mount) -> Transform {
    Transform {
        parent: parent.to_string(),
        child: child.to_string(),
        x: m.x as f64 / 1000.0,
        y: m.y as f64 / 1000.0,
        z: 0.0,
        yaw: (m.yaw as f64).to_radians(),
    }
}

/// What `add` needs besides the plan: the conf, the runtime, the DDS entities.
struct Ctx<'a> {
    rt: &'a Runtime,
    d: &'a Dds,
    l: &'a Lines,
}

impl Ctx<'_> {
    /// The frame (or frame prefix) of interface `name`: `first` (the kind's own
    /// interface) gets `own`, another robot's its name with `_`.
    fn frame(&self, name: &str, first: bool, own: &str) -> String {
        if first {
            own.to_string()
        } else {
            format!("{}_{own}", name.replace('.', "_"))
        }
    }
}

impl Plan {
    fn new(
        rt: &Runtime,
        d: &Dds,
        l: &Lines,
        serves: &[(String, Option<String>)],
    ) -> anyhow::Result<Plan> {
        let mut plan = Plan {
            base_frame: l.frames.1.clone(),
            ..Plan::default()
        };
        plan.commands.joints = l.joints.clone();
        let c = Ctx { rt, d, l };
        for (name, topic) in serves {
            plan.add(&c, name, topic.as_deref())?;
        }
        for (name, quality) in &l.compressed {
            plan.add_compressed(&c, name, quality.unwrap_or(80))?;
        }
        Ok(plan)
    }

    /// Adds interface `name` on `topic` (or its kind's usual topic) to what is served.
    fn add(&mut self, c: &Ctx, name: &str, topic: Option<&str>) -> anyhow::Result<()> {
        let (rt, d, f) = (c.rt, c.d, &c.l.frames);
        let iface = rt
            .interfaces
            .get_any(name)
            .map_err(|e| anyhow::anyhow!("service ros2: serves {name}: {e}"))?;
        let kind = iface.kind();
        // The interface of the kind's own name (`laser`, not `laser.robot2`).
        let first = name == kind.name();
        let sub = name.replace('.', "/");
        let default = match kind {
            Kind::Laser if first => "scan".to_string(),
            Kind::Encoders => "odom".to_string(),
            Kind::Motors => "cmd_vel".to_string(),
            Kind::Imu => "imu".to_string(),
            Kind::Image => format!("{sub}/image_raw"),
            Kind::Sonars if first => "sonar".to_string(),
            Kind::Sonars => format!("{sub}/sonar"),
            Kind::Bumpers if first => "hazard_detection".to_string(),
            Kind::PtEncoders if first => "joint_states".to_string(),
            Kind::PtMotors if first => "joint_command".to_string(),
            Kind::Laser
            | Kind::Bumpers
            | Kind::PtEncoders
            | Kind::PtMotors
            | Kind::ZoomEncoders
            | Kind::ZoomMotors => sub,
        };
        let topic = ros_topic(&d.graph.ns, topic.unwrap_or(&default));
        let sensor = sensor_qos();
        match kind {
            Kind::Laser => {
                let iface = rt.interfaces.get::<Laser>(name)?;
                let frame = if first {
                    f.2.clone()
                } else {
                    name.replace('.', "_")
                };
                self.statics
                    .push(mount_transform(&f.1, &frame, iface.read().value.mount));
                self.sensors
                    .push(Box::new(d.served(iface, topic, frame, sensor)?));
            }
            Kind::Encoders => {
                let iface = rt.interfaces.get::<Encoders>(name)?;
                let tf = writer(
                    &d.graph.dp,
                    &d.publisher,
                    "/tf",
                    ros2::TF_MESSAGE,
                    reliable_qos(100),
                )?;
                // Odometry and /tf name the same two frames, the `frames` line's.
                let base = f.1.clone();
                let enc: Encode<Encoders> = Box::new(move |odom, s, buf| {
                    ros2::encode_odometry(s.time, odom, &base, &s.value, buf);
                    true
                });
                let (qos, dds) = (reliable_qos(10), dds_name::<Encoders>());
                let odom = d.served_as(iface, topic, f.0.clone(), qos, dds, enc)?;
                self.odom.push((odom, tf));
            }
            Kind::Imu => {
                let iface = rt.interfaces.get::<Imu>(name)?;
                self.sensors
                    .push(Box::new(d.served(iface, topic, f.1.clone(), sensor)?));
            }
            Kind::Image => {
                let iface = rt.interfaces.get::<Image>(name)?;
                self.sensors
                    .push(Box::new(d.served(iface, topic, f.3.clone(), sensor)?));
            }
            Kind::Motors => {
                let iface = rt.interfaces.get::<Motors>(name)?;
                let r = d.reader(&topic, dds_name::<Motors>())?;
                self.commands.cmd = Some(Command::new(iface, r, topic));
            }
            other => return self.add_other(c, name, other, first, topic),
        }
        Ok(())
    }

    /// Sonars, bumpers and the pan-tilt, the kinds without a `Ros2` message of their own.
    fn add_other(
        &mut self,
        c: &Ctx,
        name: &str,
        kind: Kind,
        first: bool,
        topic: String,
    ) -> anyhow::Result<()> {
        let (rt, d) = (c.rt, c.d);
        match kind {
            Kind::Sonars => {
                self.sensors.push(Box::new(SonarsOut {
                    iface: rt.interfaces.get::<Sonars>(name)?,
                    topic,
                    frame: c.frame(name, first, "sonar"),
                    geometry: c.l.sonar,
                    writers: vec![],
                    dp: d.graph.dp.clone(),
                    publisher: d.publisher.clone(),
                    bufs: Recycler::default(),
                    clock: 0,
                }));
            }
            Kind::Bumpers => {
                let iface = rt.interfaces.get::<Bumpers>(name)?;
                let prefix = c.frame(name, first, "bumper");
                let enc: Encode<Bumpers> = Box::new(move |frame, s, buf| {
                    let bumped: Vec<String> = (s.value.bumpers.iter().enumerate())
                        .filter(|(_, b)| **b != 0)
                        .map(|(i, _)| format!("{prefix}_{i}"))
                        .collect();
                    ros2::encode_hazards(s.time, frame, &bumped, buf);
                    true
                });
                let base = c.l.frames.1.clone();
                let s = d.served_as(iface, topic, base, sensor_qos(), ros2::HAZARDS, enc)?;
                self.sensors.push(Box::new(s));
            }
            Kind::PtEncoders => {
                let iface = rt.interfaces.get::<PtEncoders>(name)?;
                self.commands.pt_encoders = Some(iface.clone());
                let (pan, tilt) = self.commands.joints.clone();
                let enc: Encode<PtEncoders> = Box::new(move |_, s, buf| {
                    let j = Joints {
                        names: vec![pan.clone(), tilt.clone()],
                        position: vec![
                            (s.value.pan_angle as f64).to_radians(),
                            (s.value.tilt_angle as f64).to_radians(),
                        ],
                        velocity: vec![],
                    };
                    ros2::encode_joints(s.time, &j, buf);
                    true
                });
                let qos = reliable_qos(10);
                let s = d.served_as(iface, topic, String::new(), qos, ros2::JOINT_STATE, enc)?;
                self.sensors.push(Box::new(s));
            }
            Kind::PtMotors => {
                let iface = rt.interfaces.get::<PtMotors>(name)?;
                let r = d.reader(&topic, ros2::JOINT_STATE)?;
                self.commands.pantilt = Some(Command::new(iface, r, topic));
            }
            Kind::ZoomEncoders
            | Kind::ZoomMotors
            | Kind::Laser
            | Kind::Encoders
            | Kind::Imu
            | Kind::Image
            | Kind::Motors => anyhow::bail!(
                "service ros2: serves {name}: a {kind} interface has no ROS 2 message here; \
                 serve laser, encoders, imu, motors, sonars, bumpers, pantiltencoders, \
                 pantiltmotors or a camera"
            ),
        }
        Ok(())
    }

    /// `compressed NAME QUALITY`: camera `NAME` as JPEG on `NAME/image_raw/compressed`.
    fn add_compressed(&mut self, c: &Ctx, name: &str, quality: u8) -> anyhow::Result<()> {
        let iface =
            c.rt.interfaces
                .get::<Image>(name)
                .map_err(|e| anyhow::anyhow!("service ros2: compressed {name}: {e}"))?;
        let topic = ros_topic(
            &c.d.graph.ns,
            &format!("{}/image_raw/compressed", name.replace('.', "/")),
        );
        let enc: Encode<Image> =
            Box::new(move |frame, s, buf| ros2::encode_compressed(frame, s, quality, buf));
        let frame = c.l.frames.3.clone();
        let qos = sensor_qos();
        let s =
            c.d.served_as(iface, topic, frame, qos, ros2::COMPRESSED_IMAGE, enc)?;
        self.sensors.push(Box::new(s));
        Ok(())
    }
}

struct Ros2Service {
    worker: Worker,
    watch: Option<Arc<Watch>>,
    /// Wakes the commands' thread, which sleeps until a command or a stop.
    commands_waker: Arc<mio::Waker>,
}

impl Driver for Ros2Service {
    fn terminate(&mut self) {
        let (watch, waker) = (&self.watch, &self.commands_waker);
        self.worker.stop_waking(|| {
            if let Some(w) = watch {
                w.wake();
            }
            let _ = waker.wake();
        });
    }
}

/// Watches and resumes a served interface; the returned closure lets it go.
fn in_use<T: InterfaceValue>(iface: &Arc<Interface<T>>, watch: &Arc<Watch>) -> Box<dyn FnOnce()> {
    iface.watch(watch.clone());
    iface.resume();
    let (i, w) = (iface.clone(), watch.clone());
    Box::new(move || {
        i.unwatch(&*w);
        i.suspend();
    })
}

/// A `sensor_msgs/msg/JointState` command applied to the pan-tilt: the joints
/// it names move to their positions (rad → deg), at their velocities when
/// given (rad/s → deg/s), else at the unit's maximum speed.
fn pantilt_command(
    now: PtMotors,
    joints: &(String, String),
    topic: &str,
    data: &[u8],
) -> Result<PtMotors, String> {
    let j = ros2::decode_joints(topic, data).map_err(|e| e.to_string())?;
    let mut m = now;
    for (i, n) in j.names.iter().enumerate() {
        let Some(p) = j.position.get(i) else {
            return Err(format!("{topic}: joint `{n}` has no position"));
        };
        let p = p.to_degrees() as f32;
        let v = j.velocity.get(i).map(|v| v.abs().to_degrees() as f32);
        if *n == joints.0 {
            m.longitude = p;
            m.longitude_speed = v.unwrap_or(m.max_longitude_speed);
        } else if *n == joints.1 {
            m.latitude = p;
            m.latitude_speed = v.unwrap_or(m.max_latitude_speed);
        } else {
            return Err(format!(
                "{topic}: no joint `{n}` (the pan-tilt's are `{}` and `{}`)",
                joints.0, joints.1
            ));
        }
    }
    Ok(m)
}

/// Holds the pan-tilt where its encoders say it is (a position unit has no
/// "zero" that is safe: it stays put, as a ROS 2 controller does when commands stop).
fn hold(pt: &Command<PtMotors>, enc: Option<&Arc<Interface<PtEncoders>>>) {
    if let Some(e) = enc {
        let at = e.read().value;
        let mut m = pt.iface.read().value;
        m.longitude = at.pan_angle.clamp(m.min_longitude, m.max_longitude);
        m.latitude = at.tilt_angle.clamp(m.min_latitude, m.max_latitude);
        let _ = pt.iface.publish(m);
    }
}

/// The longest the serving thread sleeps with nothing to do (new data and
/// `terminate` wake it sooner).
const IDLE_WAKE: Duration = Duration::from_millis(100);

/// The thread: sends each new sensor value; the commands have their own.
fn serve(
    mut plan: Plan,
    watch: Arc<Watch>,
    ready: Readiness,
    timeout: Duration,
    stop: Arc<AtomicBool>,
    _keep: Graph,
) {
    let commands = std::mem::take(&mut plan.commands);
    let stop2 = stop.clone();
    let cmd_thread = std::thread::Builder::new()
        .name("ros2-cmd".into())
        .spawn(move || commands.run(ready, timeout, &stop2));
    if let Err(e) = &cmd_thread {
        tracing::warn!("service ros2: no thread for /cmd_vel: {e}");
    }
    let mut users: Vec<Box<dyn FnOnce()>> = vec![];
    users.extend(plan.sensors.iter().map(|s| s.use_it(&watch)));
    users.extend(plan.odom.iter().map(|(s, _)| in_use(&s.iface, &watch)));
    let mut bufs = Recycler::default();
    if let Some(w) = &plan.tf_static {
        let mut buf = bufs.buffer();
        ros2::encode_tf(SystemTime::now(), &plan.statics, &mut buf);
        let _ = w.write(bufs.message(buf), None);
    }
    let mut clock_sent = (None, Instant::now());
    // With a run clock to publish, 20 ms (it moves without the watched
    // interfaces); else data wakes the loop, and the timeout only sees a stop.
    let idle = if plan.clock.is_some() {
        Duration::from_millis(20)
    } else {
        IDLE_WAKE
    };
    while !stop.load(Ordering::Acquire) {
        watch.wait(idle);
        let stamp = plan.clock.as_ref().and_then(|(c, _)| c.now());
        if let Some((_, w)) = &plan.clock {
            send_clock(w, stamp, &mut clock_sent, &mut bufs);
        }
        for s in &mut plan.sensors {
            s.send(stamp);
        }
        for (s, tf) in &mut plan.odom {
            if let Some(sample) = s.send(stamp).filter(|_| read_by_anyone(tf)) {
                let e = sample.value;
                let t = Transform {
                    parent: s.frame.clone(),
                    child: plan.base_frame.clone(),
                    x: e.x as f64 / 1000.0,
                    y: e.y as f64 / 1000.0,
                    z: 0.0,
                    yaw: e.theta as f64,
                };
                let mut buf = bufs.buffer();
                ros2::encode_tf(stamp.unwrap_or(sample.time), &[t], &mut buf);
                let _ = tf.write(bufs.message(buf), None);
            }
        }
    }
    if let Ok(t) = cmd_thread {
        let _ = t.join();
    }
    users.into_iter().for_each(|f| f());
}

/// Publishes the run's clock on `/clock` when it moved, every 10 ms at most.
fn send_clock(
    w: &Writer,
    now: Option<SystemTime>,
    sent: &mut (Option<SystemTime>, Instant),
    bufs: &mut Recycler,
) {
    let Some(t) = now else { return };
    if sent.0 == Some(t) || (sent.0.is_some() && sent.1.elapsed() < Duration::from_millis(10)) {
        return;
    }
    *sent = (Some(t), Instant::now());
    if !read_by_anyone(w) {
        return;
    }
    let mut buf = bufs.buffer();
    ros2::encode_clock(t, &mut buf);
    let _ = w.write(bufs.message(buf), None);
}

impl Commands {
    /// Applies each command as it comes (a reliable write of a sensor topic to
    /// a slow reader blocks up to 100 ms: it must not delay a stop), zeroes
    /// motors `timeout` after the last one and at stop.
    fn run(mut self, mut ready: Readiness, timeout: Duration, stop: &AtomicBool) {
        let readers = [
            self.cmd.as_mut().map(|c| &mut c.reader),
            self.pantilt.as_mut().map(|c| &mut c.reader),
        ];
        for r in readers.into_iter().flatten() {
            if let Err(e) = ready.add(r) {
                tracing::warn!("service ros2: {e}");
            }
        }
        while !stop.load(Ordering::Acquire) {
            ready.wait(self.next_wake(timeout));
            self.step(timeout);
        }
        self.step(Duration::ZERO);
    }

    /// How long the thread may sleep: until the first held command expires;
    /// with none, until a command comes or the service stops (its waker). It
    /// woke every 100 ms to look at its stop flag: 4 % of the service's CPU
    /// while serving (benches/ros2.rs `cpu`).
    fn next_wake(&self, timeout: Duration) -> Option<Duration> {
        let cmd = self.cmd.as_ref().and_then(|c| c.expires_in(timeout));
        let pt = self.pantilt.as_ref().and_then(|c| c.expires_in(timeout));
        [cmd, pt].into_iter().flatten().min()
    }

    /// Takes the waiting commands; motors to zero, the pan-tilt held, when the
    /// last command is `timeout` old.
    fn step(&mut self, timeout: Duration) {
        if let Some(c) = &mut self.cmd {
            c.drain(|t, d| {
                ros2::decode::<Motors>(t, d, 0)
                    .map(|x| x.1)
                    .map_err(|e| e.to_string())
            });
            if c.expired(timeout) {
                let _ = c.iface.publish(Motors::default());
            }
        }
        if let Some(pt) = &mut self.pantilt {
            let joints = &self.joints;
            let now = pt.iface.read().value;
            pt.drain(|t, d| pantilt_command(now, joints, t, d));
            if pt.expired(timeout) {
                hold(pt, self.pt_encoders.as_ref());
            }
        }
    }
}

crate::register_driver!(
    Service,
    "ros2",
    "a ROS 2 node over DDS serving the robot: /scan, /odom, /tf, /imu, images, sonars, bumpers, pan-tilt; /cmd_vel drives motors",
    create,
    lines = Lines
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topics_take_the_namespace_and_the_rt_prefix() {
        assert_eq!(dds_topic(&ros_topic("/", "scan")), "rt/scan");
        assert_eq!(dds_topic(&ros_topic("/robot1", "scan")), "rt/robot1/scan");
        assert_eq!(dds_topic(&ros_topic("/robot1", "/tf")), "rt/tf");
    }
}
