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
//! insecure                 # required: DDS here has no authentication (see below)
//! node jderobot            # the node's name (default jderobot)
//! namespace /              # the node's namespace and its relative topics' (default /)
//! domain 0                 # ROS_DOMAIN_ID, 0..232 (default 0)
//! serves laser             # what is served (default: every interface with a
//! serves encoders odom     #   ROS 2 message); an optional ROS 2 topic name
//! frames odom base_link laser camera   # frame ids (these are the defaults)
//! motors_timeout 500       # ms: /cmd_vel older than this counts as zero
//! end_service
//! ```
//!
//! # Topics (REP 103 units: m, rad, m/s, rad/s; REP 105 frames)
//! | interface | topic (default) | type | QoS |
//! |---|---|---|---|
//! | laser | `scan` | `sensor_msgs/msg/LaserScan`, the scan's own geometry | best effort, keep last 5 |
//! | encoders | `odom` | `nav_msgs/msg/Odometry` (odom → base_link) | reliable, keep last 10 |
//! | encoders | `/tf` | `tf2_msgs/msg/TFMessage` odom → base_link | reliable, keep last 100 |
//! | laser | `/tf_static` | base_link → laser (the laser's mount) | reliable, transient local, keep last 1 |
//! | imu | `imu` | `sensor_msgs/msg/Imu` | best effort, keep last 5 |
//! | colorA..D, varcolorA..D | `NAME/image_raw` | `sensor_msgs/msg/Image` `bgr8` | best effort, keep last 5 |
//! | motors | `cmd_vel` (read) | `geometry_msgs/msg/Twist` → v mm/s, w deg/s | reliable (a best-effort writer matches too) |
//!
//! A Twist that is not a valid motors value (NaN, infinite, out of motors' range)
//! is refused with one line. Motors are set to zero `motors_timeout` after the
//! last `/cmd_vel` (so also when its writer leaves), and when the service stops.
//!
//! # Security
//! RustDDS 0.11 speaks on every multicast-capable interface; it cannot keep
//! discovery to this host as ROS 2's `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`
//! does. Anyone on the LAN could then read the robot and drive it: DDS Security
//! would be needed to prevent it, and it is not set up here. So the service
//! starts only with `insecure`, which says so.
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
        settings::{self, MOTORS_TIMEOUT, Setting, int, interface, word},
    },
    interfaces::{
        Encoders, Image, Imu, Interface, InterfaceValue, Laser, Motors, Mount, Source, Watch,
    },
    mcapfmt::{
        dds::{Cdr, CdrAdapter, Graph, dds_topic, reliable_qos, ros_topic, sensor_qos, static_qos},
        ros2::{self, Ros2, Transform},
    },
    runtime::{Driver, Runtime},
    supervisor::Worker,
};

const LINES: &[Setting] = &[
    settings::INSECURE,
    Setting::new("node", "the ROS 2 node's name", &[word("NAME")]).default("jderobot"),
    Setting::new(
        "namespace",
        "the node's namespace, also its relative topics'",
        &[word("NS")],
    )
    .default("/"),
    Setting::new("domain", "ROS_DOMAIN_ID", &[int("ID", "", 0, 232)]).default("0"),
    Setting::new(
        "serves",
        "an interface served, on its default topic or TOPIC (default: all with a ROS 2 message)",
        &[interface("INTERFACE"), word("TOPIC").optional()],
    )
    .repeats(),
    Setting::new(
        "frames",
        "frame ids: odometry, robot base, laser, camera",
        &[word("ODOM"), word("BASE"), word("LASER"), word("CAMERA")],
    )
    .default("odom base_link laser camera"),
    MOTORS_TIMEOUT,
];

#[derive(serde::Deserialize)]
struct Lines {
    #[serde(default)]
    insecure: bool,
    node: String,
    namespace: String,
    domain: u16,
    serves: Vec<(String, Option<String>)>,
    frames: (String, String, String, String),
    motors_timeout: u64,
}

type Writer = DataWriter<Cdr, CdrAdapter>;

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

/// One served sensor: its interface, its writer, the last clock sent.
struct Served<T> {
    iface: Arc<Interface<T>>,
    topic: String,
    frame: String,
    writer: Writer,
    clock: u64,
}

impl<T: Ros2> Served<T> {
    fn send(&mut self, buf: &mut Vec<u8>) -> Option<Arc<crate::interfaces::Sample<T>>> {
        let s = self.iface.snapshot();
        if s.clock == self.clock || s.clock == 0 {
            return None;
        }
        self.clock = s.clock;
        if ros2::encode(&self.frame, &s, buf)
            && let Err(e) = self.writer.write(Cdr(std::mem::take(buf)), None)
        {
            tracing::debug!("ros2: {}: {e}", self.topic);
        }
        Some(s)
    }
}

#[derive(Default)]
struct Plan {
    lasers: Vec<Served<Laser>>,
    odom: Vec<(Served<Encoders>, Writer)>,
    imus: Vec<Served<Imu>>,
    images: Vec<Served<Image>>,
    cmd: Option<CmdVelIn>,
    /// The robot's frame (`frames` line), the child of odom on `/tf`.
    base_frame: String,
    /// `/tf_static`'s writer, and the mounts it sends.
    tf_static: Option<Writer>,
    statics: Vec<Transform>,
}

/// `motors` and the `/cmd_vel` reader that drives it, with the topic's name.
type CmdVelIn = (Arc<Interface<Motors>>, DataReader<Cdr, CdrAdapter>, String);

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let l: Lines = conf.settings(LINES)?;
    if !l.insecure {
        anyhow::bail!(
            "service ros2: DDS here has no authentication and RustDDS reaches every \
             multicast interface (it cannot keep discovery to this host): anyone on the \
             LAN could read and drive the robot; DDS Security would be needed. Add an \
             `insecure` line to serve it anyway"
        );
    }
    let d = Dds::join(&l)?;
    let ns = d.graph.ns.clone();
    // What is served: the serves lines, or every interface with a ROS 2 message.
    let serves: Vec<(String, Option<String>)> = if l.serves.is_empty() {
        rt.interfaces
            .all()
            .iter()
            .filter(|i| ros2::message(i.kind()).is_some())
            .map(|i| (i.name().to_string(), None))
            .collect()
    } else {
        l.serves.clone()
    };
    let frames = Frames::from(&l);
    let mut plan = Plan {
        base_frame: frames.base.clone(),
        ..Plan::default()
    };
    for (name, topic) in &serves {
        plan.add(rt, &d, &ns, &frames, name, topic.as_deref())?;
    }
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
    let timeout = Duration::from_millis(l.motors_timeout);
    let stop = Arc::new(AtomicBool::new(false));
    let stop2 = stop.clone();
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    let keep_name = d.graph.full_name();
    let keep = d.graph;
    let worker = Worker::start("ros2", stop.clone(), move || {
        let watch = Watch::for_current_thread();
        let _ = tx.send(watch.clone());
        serve(plan, watch, timeout, stop2, keep);
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
    Ok(Box::new(Ros2Service { worker, watch }))
}

/// The node in the ROS 2 graph and the DDS entities its topics hang from.
struct Dds {
    graph: Graph,
    publisher: Publisher,
    subscriber: Subscriber,
}

impl Dds {
    fn join(l: &Lines) -> anyhow::Result<Dds> {
        let graph = Graph::join("service ros2", l.domain, &l.namespace, &l.node)?;
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
}

impl Dds {
    /// `iface` served on `topic` with its kind's ROS 2 type.
    fn served<T: Ros2>(
        &self,
        iface: Arc<Interface<T>>,
        topic: String,
        frame: String,
        qos: QosPolicies,
    ) -> anyhow::Result<Served<T>> {
        let writer = writer(
            &self.graph.dp,
            &self.publisher,
            &topic,
            dds_name::<T>(),
            qos,
        )?;
        Ok(Served {
            iface,
            topic,
            frame,
            writer,
            clock: 0,
        })
    }

    /// The reader of a `geometry_msgs/msg/Twist` topic that drives `motors`.
    fn cmd_vel_reader(&self, topic: &str) -> anyhow::Result<DataReader<Cdr, CdrAdapter>> {
        let t = self
            .graph
            .dp
            .create_topic(
                dds_topic(topic),
                dds_name::<Motors>().into(),
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

/// The frame ids of the `frames` line.
struct Frames {
    odom: String,
    base: String,
    laser: String,
    camera: String,
}

impl From<&Lines> for Frames {
    fn from(l: &Lines) -> Frames {
        let (odom, base, laser, camera) = l.frames.clone();
        Frames {
            odom,
            base,
            laser,
            camera,
        }
    }
}

impl Plan {
    /// Adds interface `name` on `topic` (or its kind's usual topic) to what is served.
    fn add(
        &mut self,
        rt: &Runtime,
        d: &Dds,
        ns: &str,
        f: &Frames,
        name: &str,
        topic: Option<&str>,
    ) -> anyhow::Result<()> {
        let plan = self;
        let iface = rt
            .interfaces
            .get_any(name)
            .map_err(|e| anyhow::anyhow!("service ros2: serves {name}: {e}"))?;
        let first = name == iface.kind() || name == "laser";
        let kind = iface.kind();
        let default = match kind {
            "laser" if first => "scan".to_string(),
            "encoders" => "odom".to_string(),
            "motors" => "cmd_vel".to_string(),
            "imu" => "imu".to_string(),
            "image" => format!("{name}/image_raw"),
            _ => name.replace('.', "/"),
        };
        let topic = ros_topic(ns, topic.unwrap_or(&default));
        let sensor = sensor_qos();
        match kind {
            "laser" => {
                let iface = rt.interfaces.get::<Laser>(name)?;
                let frame = if first {
                    f.laser.clone()
                } else {
                    name.replace('.', "_")
                };
                plan.statics
                    .push(mount_transform(&f.base, &frame, iface.read().value.mount));
                plan.lasers.push(d.served(iface, topic, frame, sensor)?);
            }
            "encoders" => {
                let iface = rt.interfaces.get::<Encoders>(name)?;
                let tf = writer(
                    &d.graph.dp,
                    &d.publisher,
                    "/tf",
                    ros2::TF_MESSAGE,
                    reliable_qos(100),
                )?;
                let odom = d.served(iface, topic, f.odom.clone(), reliable_qos(10))?;
                plan.odom.push((odom, tf));
            }
            "imu" => {
                let iface = rt.interfaces.get::<Imu>(name)?;
                plan.imus
                    .push(d.served(iface, topic, f.base.clone(), sensor)?);
            }
            "image" => {
                let iface = rt.interfaces.get::<Image>(name)?;
                plan.images
                    .push(d.served(iface, topic, f.camera.clone(), sensor)?);
            }
            "motors" => {
                let iface = rt.interfaces.get::<Motors>(name)?;
                let r = d.cmd_vel_reader(&topic)?;
                plan.cmd = Some((iface, r, topic));
            }
            other => anyhow::bail!(
                "service ros2: serves {name}: a {other} interface has no ROS 2 message here; \
                 serve laser, encoders, imu, motors or a camera"
            ),
        }
        Ok(())
    }
}

struct Ros2Service {
    worker: Worker,
    watch: Option<Arc<Watch>>,
}

impl Driver for Ros2Service {
    fn terminate(&mut self) {
        if let Some(w) = &self.watch {
            w.wake();
        }
        self.worker.stop();
    }
}

/// The thread: sends each new sensor value, applies /cmd_vel.
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

fn serve(
    mut plan: Plan,
    watch: Arc<Watch>,
    timeout: Duration,
    stop: Arc<AtomicBool>,
    _keep: Graph,
) {
    let mut users: Vec<Box<dyn FnOnce()>> = vec![];
    users.extend(plan.lasers.iter().map(|s| in_use(&s.iface, &watch)));
    users.extend(plan.odom.iter().map(|(s, _)| in_use(&s.iface, &watch)));
    users.extend(plan.imus.iter().map(|s| in_use(&s.iface, &watch)));
    users.extend(plan.images.iter().map(|s| in_use(&s.iface, &watch)));
    let mut buf = Vec::new();
    if let Some(w) = &plan.tf_static {
        let tfs = &plan.statics;
        ros2::encode_tf(SystemTime::now(), tfs, &mut buf);
        let _ = w.write(Cdr(std::mem::take(&mut buf)), None);
    }
    let source = plan
        .cmd
        .as_ref()
        .map(|(_, _, t)| Source::new(format!("ros2: {t}")));
    let mut last_cmd: Option<Instant> = None;
    while !stop.load(Ordering::Acquire) {
        watch.wait(Duration::from_millis(2));
        for s in &mut plan.lasers {
            s.send(&mut buf);
        }
        for (s, tf) in &mut plan.odom {
            if let Some(sample) = s.send(&mut buf) {
                let e = sample.value;
                let t = Transform {
                    parent: s.frame.clone(),
                    child: plan.base_frame.clone(),
                    x: e.x as f64 / 1000.0,
                    y: e.y as f64 / 1000.0,
                    z: 0.0,
                    yaw: e.theta as f64,
                };
                ros2::encode_tf(sample.time, &[t], &mut buf);
                let _ = tf.write(Cdr(std::mem::take(&mut buf)), None);
            }
        }
        for s in &mut plan.imus {
            s.send(&mut buf);
        }
        for s in &mut plan.images {
            s.send(&mut buf);
        }
        if let (Some((motors, reader, topic)), Some(source)) = (&mut plan.cmd, &source) {
            loop {
                match reader.take_next_sample() {
                    Ok(Some(sample)) => match ros2::decode::<Motors>(topic, &sample.value().0, 0) {
                        Ok((_, m)) => {
                            if motors.accept(source, m).is_some() {
                                last_cmd = Some(Instant::now());
                            }
                        }
                        Err(e) => {
                            source.refused(e);
                        }
                    },
                    Ok(None) => break,
                    Err(e) => {
                        source.refused(format!("{topic}: {e}"));
                        break;
                    }
                }
            }
            if last_cmd.is_some_and(|t| t.elapsed() >= timeout) {
                last_cmd = None;
                let _ = motors.publish(Motors::default());
            }
        }
    }
    if let Some((motors, _, _)) = &plan.cmd
        && last_cmd.is_some()
    {
        let _ = motors.publish(Motors::default());
    }
    users.into_iter().for_each(|f| f());
}

crate::register_driver!(
    Service,
    "ros2",
    "a ROS 2 node over DDS serving the robot: /scan, /odom, /tf, /imu, images; /cmd_vel drives motors",
    create,
    lines = LINES
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
