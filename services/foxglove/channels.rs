//! Interfaces as Foxglove channels. Each kind's channel and message come from its
//! [`Serve`] impl (one per kind of the table `interfaces::kinds`; a kind without
//! one fails to compile), and where the recorder has the format, from the
//! recorder's encoders (`mcapfmt`): the same bytes live and in a recording.
//!
//! | kind | topic | schema |
//! |---|---|---|
//! | image | NAME | `foxglove.RawImage` (`bgr8`), or `foxglove.CompressedImage` (`jpeg`) with `images jpeg Q` (`mcapfmt::protobuf`) |
//! | laser | NAME | `foxglove.LaserScan` (`mcapfmt::protobuf::laser_scan`): ranges m, angles from the laser value, frame `base_link` |
//! | sonars | NAME | `foxglove.LaserScan`: sonar i at −180° + 360°·i/n (the ring drawn evenly), frame `base_link` |
//! | encoders | NAME, and `/tf` | `foxglove.PoseInFrame` (frame `odom`, m, quaternion), and `foxglove.FrameTransform` odom → base_link |
//! | pantiltencoders | NAME, and `/tf` | JSON, and `foxglove.FrameTransform` base_link → camera (pan = yaw, tilt = pitch) |
//! | world map | `world` | `foxglove.SceneUpdate`: walls and boxes as cubes, balls as spheres (frame `odom`, m) |
//! | others | NAME | JSON (the recorder's: `jderobot.KIND` JSON schema; the value under `jderobot` in its units) |

use std::{sync::Arc, time::SystemTime};

use ::foxglove::{
    Channel, ChannelBuilder, Context, Encode, RawChannel, Schema,
    schemas::{
        Color, CubePrimitive, FrameTransform, LaserScan, Pose, PoseInFrame, Quaternion,
        SceneEntity, SceneUpdate, SpherePrimitive, Timestamp, Vector3,
    },
};

use crate::{
    interfaces::{
        Bumpers, Encoders, Image, Imu, InterfaceValue, Kind, Laser, Motors, PtEncoders, PtMotors,
        Sample, Sonars, ZoomEncoders, ZoomMotors, for_each_kind,
    },
    mcapfmt::{self, Profile, Snapshot, Source, protobuf},
    world::{Ball, World},
};

/// The frame of the odometry (the world as the robot's encoders see it).
pub const ODOM: &str = "odom";
/// The robot's frame.
pub const BASE: &str = "base_link";
/// The pan-tilt camera's frame.
pub const CAMERA: &str = "camera";
/// The transforms topic.
pub const TF: &str = "/tf";
/// The world map's topic.
pub const WORLD: &str = "world";

fn stamp(t: SystemTime) -> Option<Timestamp> {
    let ns = mcapfmt::nanos(t);
    Some(Timestamp::new(
        (ns / 1_000_000_000).min(u32::MAX as u64) as u32,
        (ns % 1_000_000_000) as u32,
    ))
}

fn yaw(theta: f64) -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: (theta / 2.0).sin(),
        w: (theta / 2.0).cos(),
    }
}

fn v3(x: f64, y: f64, z: f64) -> Option<Vector3> {
    Some(Vector3 { x, y, z })
}

/// How the service's options shape a channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Opts {
    /// Images as JPEG of this quality, else raw.
    pub jpeg: Option<u8>,
}

impl Opts {
    fn profile(&self) -> Profile {
        Profile::Foxglove { jpeg: self.jpeg }
    }
}

/// A channel's schema and message encoding.
pub struct ChannelSchema {
    pub schema: Schema,
    pub encoding: String,
}

fn protobuf_schema(name: &str, fdset: &'static [u8]) -> ChannelSchema {
    ChannelSchema {
        schema: Schema::new(name, "protobuf", fdset),
        encoding: "protobuf".into(),
    }
}

fn sdk_schema<T: Encode>() -> ChannelSchema {
    ChannelSchema {
        schema: T::get_schema().expect("the SDK's schemas carry their schema"),
        encoding: T::get_message_encoding(),
    }
}

/// How one interface kind is served. One impl per kind of the table; the defaults
/// are the recorder's JSON channel and message.
pub trait Serve: InterfaceValue {
    /// The kind's channel schema.
    fn schema(opts: Opts) -> ChannelSchema {
        let _ = opts;
        let (name, text) = mcapfmt::json_schema(Self::KIND);
        ChannelSchema {
            schema: Schema::new(name, "jsonschema", text.into_bytes()),
            encoding: "json".into(),
        }
    }
    /// Encodes a sample (`snap` is the same sample, as the recorder takes it) into
    /// `buf`: false when there is nothing to send.
    fn message(
        name: &str,
        snap: &Snapshot,
        s: &Sample<Self>,
        opts: Opts,
        buf: &mut Vec<u8>,
    ) -> bool {
        let _ = s;
        mcapfmt::encode(opts.profile(), name, snap, buf)
    }
    /// The transform the sample gives on `/tf`, for kinds that move a frame.
    fn transform(s: &Sample<Self>) -> Option<FrameTransform> {
        let _ = s;
        None
    }
    /// Whether the kind sends on `/tf` (its subscribers want the interface too).
    const TF: bool = false;
}

impl Serve for Image {
    fn schema(opts: Opts) -> ChannelSchema {
        match opts.jpeg {
            None => protobuf_schema("foxglove.RawImage", protobuf::RAW_IMAGE),
            Some(_) => protobuf_schema("foxglove.CompressedImage", protobuf::COMPRESSED_IMAGE),
        }
    }
}

impl Serve for Laser {
    fn schema(_: Opts) -> ChannelSchema {
        protobuf_schema("foxglove.LaserScan", protobuf::LASER_SCAN)
    }
    fn message(_: &str, _: &Snapshot, s: &Sample<Self>, _: Opts, buf: &mut Vec<u8>) -> bool {
        laser_message(mcapfmt::nanos(s.time), &s.value, buf);
        true
    }
}

/// The `foxglove.LaserScan` the service sends for a laser value (time `ns`): the
/// recorder's encoder ([`protobuf::laser_scan`]) in frame `base_link`, so its angles
/// and mount are the value's.
pub fn laser_message(ns: u64, l: &Laser, buf: &mut Vec<u8>) {
    protobuf::laser_scan(BASE, ns, l, buf);
}

fn encode_sdk<T: Encode>(m: &T, buf: &mut Vec<u8>) -> bool {
    buf.clear();
    m.encode(buf).is_ok()
}

impl Serve for Sonars {
    fn schema(_: Opts) -> ChannelSchema {
        sdk_schema::<LaserScan>()
    }
    fn message(_: &str, _: &Snapshot, s: &Sample<Self>, _: Opts, buf: &mut Vec<u8>) -> bool {
        encode_sdk(&sonar_scan(s.time, &s.value), buf)
    }
}

impl Serve for Encoders {
    fn schema(_: Opts) -> ChannelSchema {
        sdk_schema::<PoseInFrame>()
    }
    fn message(_: &str, _: &Snapshot, s: &Sample<Self>, _: Opts, buf: &mut Vec<u8>) -> bool {
        encode_sdk(&odometry(s.time, &s.value).0, buf)
    }
    fn transform(s: &Sample<Self>) -> Option<FrameTransform> {
        Some(odometry(s.time, &s.value).1)
    }
    const TF: bool = true;
}

impl Serve for PtEncoders {
    fn transform(s: &Sample<Self>) -> Option<FrameTransform> {
        Some(camera(s.time, &s.value))
    }
    const TF: bool = true;
}

impl Serve for Motors {}
impl Serve for PtMotors {}
impl Serve for ZoomEncoders {}
impl Serve for ZoomMotors {}
impl Serve for Bumpers {}
impl Serve for Imu {}

/// How one interface is sent: its channel, and `/tf` for kinds that move a frame.
pub struct Out {
    channel: Arc<RawChannel>,
    tf: Option<Arc<Channel<FrameTransform>>>,
    opts: Opts,
}

fn channel_of<T: Serve>(
    ctx: &Arc<Context>,
    name: &str,
    opts: Opts,
) -> anyhow::Result<Arc<RawChannel>> {
    let ChannelSchema { schema, encoding } = T::schema(opts);
    ChannelBuilder::new(name)
        .context(ctx)
        .message_encoding(encoding)
        .schema(schema)
        .add_metadata(mcapfmt::KIND_KEY, T::KIND.name())
        .build_raw()
        .map_err(|e| anyhow::anyhow!("foxglove: cannot make channel `{name}`: {e}"))
}

/// The per-kind dispatch, from the table of kinds.
macro_rules! serve_kinds {
    (; $(($t:ident, $k:literal)),*) => {
        fn channel_of_kind(ctx: &Arc<Context>, name: &str, kind: Kind, opts: Opts) -> anyhow::Result<(Arc<RawChannel>, bool)> {
            match kind {
                $(Kind::$t => Ok((channel_of::<$t>(ctx, name, opts)?, <$t as Serve>::TF)),)*
            }
        }

        fn log_kind(out: &Out, name: &str, snap: &Snapshot, buf: &mut Vec<u8>) {
            match snap {
                $(Snapshot::$t(s) => {
                    if let Some(tf) = &out.tf
                        && let Some(t) = <$t as Serve>::transform(s)
                    {
                        tf.log(&t);
                    }
                    if <$t as Serve>::message(name, snap, s, out.opts, buf) {
                        out.channel.log(buf);
                    }
                })*
            }
        }
    };
}
for_each_kind!(serve_kinds! {});

impl Out {
    /// The channel(s) of interface `name` of kind `kind`.
    pub fn new(
        ctx: &Arc<Context>,
        name: &str,
        kind: Kind,
        opts: Opts,
        tf: &Arc<Channel<FrameTransform>>,
    ) -> anyhow::Result<Out> {
        let (channel, moves) = channel_of_kind(ctx, name, kind, opts)?;
        Ok(Out {
            channel,
            tf: moves.then(|| tf.clone()),
            opts,
        })
    }

    /// The ids of the channels whose subscribers want this interface.
    pub fn channel_ids(&self) -> Vec<::foxglove::ChannelId> {
        let mut ids = vec![self.channel.id()];
        ids.extend(self.tf.as_ref().map(|t| t.id()));
        ids
    }

    /// Logs a sample of the interface `name` (`buf` is scratch).
    pub fn log(&self, name: &str, snap: &Snapshot, buf: &mut Vec<u8>) {
        log_kind(self, name, snap, buf);
    }
}

/// The sonar ring as a `foxglove.LaserScan`: sonar i at −180° + 360°·i/n.
pub fn sonar_scan(t: SystemTime, s: &Sonars) -> LaserScan {
    let n = s.us.len().max(1) as f64;
    let pi = std::f64::consts::PI;
    LaserScan {
        timestamp: stamp(t),
        frame_id: BASE.into(),
        pose: Some(Pose {
            position: v3(0.0, 0.0, 0.0),
            orientation: Some(yaw(0.0)),
        }),
        start_angle: -pi,
        end_angle: -pi + 2.0 * pi * (n - 1.0) / n,
        ranges: s.us.iter().map(|u| *u as f64 / 1000.0).collect(),
        intensities: Vec::new(),
    }
}

/// The robot's pose in `odom` (m, rad) and the transform odom → base_link.
pub fn odometry(t: SystemTime, e: &Encoders) -> (PoseInFrame, FrameTransform) {
    let (x, y, th) = (e.x as f64 / 1000.0, e.y as f64 / 1000.0, e.theta as f64);
    (
        PoseInFrame {
            timestamp: stamp(t),
            frame_id: ODOM.into(),
            pose: Some(Pose {
                position: v3(x, y, 0.0),
                orientation: Some(yaw(th)),
            }),
        },
        FrameTransform {
            timestamp: stamp(t),
            parent_frame_id: ODOM.into(),
            child_frame_id: BASE.into(),
            translation: v3(x, y, 0.0),
            rotation: Some(yaw(th)),
        },
    )
}

/// The camera on the pan-tilt head: base_link → camera, 0.3 m up, pan about z,
/// tilt about the head's y (positive tilt looks up: a negative pitch).
pub fn camera(t: SystemTime, p: &PtEncoders) -> FrameTransform {
    let (pan, tilt) = (
        (p.pan_angle as f64).to_radians(),
        -(p.tilt_angle as f64).to_radians(),
    );
    let (cz, sz) = ((pan / 2.0).cos(), (pan / 2.0).sin());
    let (cy, sy) = ((tilt / 2.0).cos(), (tilt / 2.0).sin());
    // q = yaw(pan) * pitch(tilt)
    FrameTransform {
        timestamp: stamp(t),
        parent_frame_id: BASE.into(),
        child_frame_id: CAMERA.into(),
        translation: v3(0.0, 0.0, 0.3),
        rotation: Some(Quaternion {
            x: -sz * sy,
            y: cz * sy,
            z: sz * cy,
            w: cz * cy,
        }),
    }
}

fn color(c: [u8; 3], a: f64) -> Option<Color> {
    Some(Color {
        r: c[0] as f64 / 255.0,
        g: c[1] as f64 / 255.0,
        b: c[2] as f64 / 255.0,
        a,
    })
}

/// Walls thinner than this are drawn this thick, m.
const WALL: f64 = 0.02;

/// The static part of the world (walls, boxes) as one entity `map`, in `odom`, m.
pub fn world_entity(t: SystemTime, w: &World) -> SceneEntity {
    let mut cubes = Vec::with_capacity(w.segments.len() + w.boxes.len());
    for s in &w.segments {
        let (dx, dy) = ((s.b[0] - s.a[0]) / 1000.0, (s.b[1] - s.a[1]) / 1000.0);
        let len = dx.hypot(dy);
        if len <= 0.0 {
            continue;
        }
        let h = (s.height / 1000.0).max(0.01);
        cubes.push(CubePrimitive {
            pose: Some(Pose {
                position: v3(
                    (s.a[0] + s.b[0]) / 2000.0,
                    (s.a[1] + s.b[1]) / 2000.0,
                    h / 2.0,
                ),
                orientation: Some(yaw(dy.atan2(dx))),
            }),
            size: v3(len, WALL, h),
            color: color(s.color, 1.0),
        });
    }
    for b in &w.boxes {
        let h = (b.height / 1000.0).max(0.01);
        cubes.push(CubePrimitive {
            pose: Some(Pose {
                position: v3(b.center[0] / 1000.0, b.center[1] / 1000.0, h / 2.0),
                orientation: Some(yaw(b.theta)),
            }),
            size: v3(b.size[0] / 1000.0, b.size[1] / 1000.0, h),
            color: color(b.color, 1.0),
        });
    }
    SceneEntity {
        timestamp: stamp(t),
        frame_id: ODOM.into(),
        id: "map".into(),
        cubes,
        ..Default::default()
    }
}

/// The balls as they are now, one entity `balls`.
pub fn balls_entity(t: SystemTime, balls: &[Ball]) -> SceneEntity {
    SceneEntity {
        timestamp: stamp(t),
        frame_id: ODOM.into(),
        id: "balls".into(),
        spheres: balls
            .iter()
            .map(|b| {
                let d = 2.0 * b.radius / 1000.0;
                SpherePrimitive {
                    pose: Some(Pose {
                        position: v3(b.pos[0] / 1000.0, b.pos[1] / 1000.0, d / 2.0),
                        orientation: Some(yaw(0.0)),
                    }),
                    size: v3(d, d, d),
                    color: color(b.color, 1.0),
                }
            })
            .collect(),
        ..Default::default()
    }
}

/// A scene update of these entities.
pub fn scene(entities: Vec<SceneEntity>) -> SceneUpdate {
    SceneUpdate {
        deletions: Vec::new(),
        entities,
    }
}

/// One served interface: its typed handle and its channels.
pub struct Served {
    pub name: String,
    pub source: Source,
    pub out: Out,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn laser_angles_ranges_and_the_sonar_ring() {
        let t = SystemTime::UNIX_EPOCH;
        // A 90° scan turned to start at -45°: the angles come from the value.
        let l = Laser {
            readings: vec![1000, 2500, 0],
            resolution: 1.0,
            start: -45.0,
            ..Laser::default()
        };
        let mut buf = Vec::new();
        protobuf::laser_scan(BASE, 0, &l, &mut buf);
        let Ok((_, mcapfmt::Recorded::Laser(back))) = protobuf::decode_laser("laser", &buf, 0)
        else {
            panic!("not a laser");
        };
        assert_eq!(back.readings, l.readings);
        assert!((back.start + 45.0).abs() < 1e-4 && (back.resolution - 1.0).abs() < 1e-4);
        let s = sonar_scan(t, &Sonars { us: vec![500.0; 4] });
        assert!(close(s.start_angle, -std::f64::consts::PI));
        assert!(close(s.end_angle, std::f64::consts::FRAC_PI_2));
        assert_eq!(s.ranges, vec![0.5; 4]);
    }

    #[test]
    fn odometry_and_the_pan_tilt_camera_frames() {
        let t = SystemTime::UNIX_EPOCH;
        let (pose, tf) = odometry(
            t,
            &Encoders::from_pose(1500.0, -200.0, std::f32::consts::FRAC_PI_2),
        );
        let p = pose.pose.unwrap().position.unwrap();
        assert!(close(p.x, 1.5) && (p.y + 0.2).abs() < 1e-6);
        let q = tf.rotation.unwrap();
        // (θ is an f32.)
        assert!((q.z - std::f64::consts::FRAC_PI_4.sin()).abs() < 1e-6 && (q.w - q.z).abs() < 1e-6);
        assert_eq!(
            (tf.parent_frame_id.as_str(), tf.child_frame_id.as_str()),
            (ODOM, BASE)
        );
        // Pan 90 deg alone: a yaw of 90 deg.
        let c = camera(
            t,
            &PtEncoders {
                pan_angle: 90.0,
                tilt_angle: 0.0,
            },
        );
        let q = c.rotation.unwrap();
        assert!(close(q.x, 0.0) && close(q.y, 0.0) && close(q.z, q.w) && q.z > 0.0);
        // Tilt 30 deg up alone: a pitch of -30 deg about y.
        let c = camera(
            t,
            &PtEncoders {
                pan_angle: 0.0,
                tilt_angle: 30.0,
            },
        );
        let q = c.rotation.unwrap();
        assert!(close(q.y, (-15f64).to_radians().sin()) && close(q.x, 0.0) && close(q.z, 0.0));
        let n = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w).sqrt();
        assert!(close(n, 1.0));
    }
}
