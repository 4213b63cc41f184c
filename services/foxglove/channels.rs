//! Interfaces as Foxglove channels: each served interface's value in a Foxglove
//! schema (the SDK's `foxglove::schemas`, protobuf), or as JSON with a JSON schema.
//!
//! | kind | topic | schema |
//! |---|---|---|
//! | image | NAME | `foxglove.RawImage` (`bgr8`), or `foxglove.CompressedImage` (`jpeg`) with `images jpeg Q` |
//! | laser | NAME | `foxglove.LaserScan`: ranges m, −90° first, frame `base_link` |
//! | sonars | NAME | `foxglove.LaserScan`: sonar i at −180° + 360°·i/n (the ring drawn evenly), frame `base_link` |
//! | encoders | NAME, and `/tf` | `foxglove.PoseInFrame` (frame `odom`, m, quaternion), and `foxglove.FrameTransform` odom → base_link |
//! | pantiltencoders | NAME, and `/tf` | JSON, and `foxglove.FrameTransform` base_link → camera (pan = yaw, tilt = pitch) |
//! | world map | `world` | `foxglove.SceneUpdate`: walls and boxes as cubes, balls as spheres (frame `odom`, m) |
//! | others | NAME | JSON (`jderobot.KIND` JSON schema; the value under `jderobot` in its units) |

use std::{sync::Arc, time::SystemTime};

use ::foxglove::{
    Channel, ChannelBuilder, Context, RawChannel, Schema,
    bytes::Bytes,
    schemas::{
        Color, CompressedImage, CubePrimitive, FrameTransform, LaserScan, Pose, PoseInFrame,
        Quaternion, RawImage, SceneEntity, SceneUpdate, SpherePrimitive, Timestamp, Vector3,
    },
};

use crate::{
    interfaces::{Encoders, Image, Laser, PtEncoders, Sample, Sonars},
    mcapfmt::{self, Profile, Snapshot, Source},
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

/// How one interface is sent.
pub enum Out {
    Raw(Channel<RawImage>),
    Jpeg(Channel<CompressedImage>, u8),
    Scan(Channel<LaserScan>),
    Sonars(Channel<LaserScan>),
    Odometry(Channel<PoseInFrame>, Arc<Channel<FrameTransform>>),
    PanTilt(Arc<RawChannel>, Arc<Channel<FrameTransform>>),
    Json(Arc<RawChannel>),
}

fn json_channel(ctx: &Arc<Context>, name: &str, kind: &str) -> anyhow::Result<Arc<RawChannel>> {
    let (schema_name, text) = mcapfmt::json_schema(kind);
    ChannelBuilder::new(name)
        .context(ctx)
        .message_encoding("json")
        .schema(Schema::new(schema_name, "jsonschema", text.into_bytes()))
        .add_metadata("jderobot.kind", kind)
        .build_raw()
        .map_err(|e| anyhow::anyhow!("foxglove: cannot make channel `{name}`: {e}"))
}

impl Out {
    /// The channel(s) of interface `name` of kind `kind`.
    pub fn new(
        ctx: &Arc<Context>,
        name: &str,
        kind: &str,
        jpeg: Option<u8>,
        tf: &Arc<Channel<FrameTransform>>,
    ) -> anyhow::Result<Out> {
        let b = || ChannelBuilder::new(name).context(ctx);
        Ok(match (kind, jpeg) {
            ("image", None) => Out::Raw(b().build()),
            ("image", Some(q)) => Out::Jpeg(b().build(), q),
            ("laser", _) => Out::Scan(b().build()),
            ("sonars", _) => Out::Sonars(b().build()),
            ("encoders", _) => Out::Odometry(b().build(), tf.clone()),
            ("pantiltencoders", _) => Out::PanTilt(json_channel(ctx, name, kind)?, tf.clone()),
            _ => Out::Json(json_channel(ctx, name, kind)?),
        })
    }

    /// The ids of the channels whose subscribers want this interface.
    pub fn channel_ids(&self) -> Vec<::foxglove::ChannelId> {
        match self {
            Out::Raw(c) => vec![c.id()],
            Out::Jpeg(c, _) => vec![c.id()],
            Out::Scan(c) | Out::Sonars(c) => vec![c.id()],
            Out::Odometry(c, tf) => vec![c.id(), tf.id()],
            Out::PanTilt(c, tf) => vec![c.id(), tf.id()],
            Out::Json(c) => vec![c.id()],
        }
    }

    /// Logs a sample of the interface `name` (`buf` is scratch).
    pub fn log(&self, name: &str, snap: &Snapshot, buf: &mut Vec<u8>) {
        match (self, snap) {
            (Out::Raw(c), Snapshot::Image(s)) => c.log(&shared_raw_image(name, s)),
            (Out::Jpeg(c, q), Snapshot::Image(s)) => {
                if let Some(j) = mcapfmt::jpeg(&s.value, *q) {
                    c.log(&CompressedImage {
                        timestamp: stamp(s.time),
                        frame_id: name.to_string(),
                        data: Bytes::from(j),
                        format: "jpeg".into(),
                    });
                }
            }
            (Out::Scan(c), Snapshot::Laser(s)) => c.log(&laser_scan(s.time, &s.value)),
            (Out::Sonars(c), Snapshot::Sonars(s)) => c.log(&sonar_scan(s.time, &s.value)),
            (Out::Odometry(c, tf), Snapshot::Encoders(s)) => {
                let (pose, t) = odometry(s.time, &s.value);
                c.log(&pose);
                tf.log(&t);
            }
            (Out::PanTilt(c, tf), Snapshot::PtEncoders(s)) => {
                tf.log(&camera(s.time, &s.value));
                if mcapfmt::encode(Profile::Foxglove { jpeg: None }, name, snap, buf) {
                    c.log(buf);
                }
            }
            (Out::Json(c), _) => {
                if mcapfmt::encode(Profile::Foxglove { jpeg: None }, name, snap, buf) {
                    c.log(buf);
                }
            }
            _ => debug_assert!(false, "a channel of another kind than its interface"),
        }
    }
}

/// An image sample's bytes, shared with the interface (no copy).
struct Pixels(Arc<Sample<Image>>);

impl AsRef<[u8]> for Pixels {
    fn as_ref(&self) -> &[u8] {
        &self.0.value.data
    }
}

/// A `foxglove.RawImage` (`bgr8`) of an image sample, its bytes shared (not copied).
pub fn shared_raw_image(frame: &str, s: &Arc<Sample<Image>>) -> RawImage {
    RawImage {
        timestamp: stamp(s.time),
        frame_id: frame.to_string(),
        width: s.value.width,
        height: s.value.height,
        encoding: "bgr8".into(),
        step: s.value.width * 3,
        data: Bytes::from_owner(Pixels(s.clone())),
    }
}

/// A `foxglove.RawImage` (`bgr8`) of `img` (one copy of its bytes).
pub fn raw_image(frame: &str, t: SystemTime, img: &Image) -> RawImage {
    RawImage {
        timestamp: stamp(t),
        frame_id: frame.to_string(),
        width: img.width,
        height: img.height,
        encoding: "bgr8".into(),
        step: img.width * 3,
        data: Bytes::copy_from_slice(&img.data),
    }
}

/// A `foxglove.LaserScan` of jderobot's laser: ranges m, reading i at
/// start + i/resolution deg, the pose the laser's mount (the recorder's layout,
/// `mcapfmt::protobuf`).
pub fn laser_scan(t: SystemTime, l: &Laser) -> LaserScan {
    let start = (l.start as f64).to_radians();
    let steps = l.readings.len().saturating_sub(1).max(1) as f64;
    let end = if l.resolution > 0.0 && l.resolution.is_finite() {
        start + (steps / l.resolution as f64).to_radians()
    } else {
        start
    };
    LaserScan {
        timestamp: stamp(t),
        frame_id: BASE.into(),
        pose: Some(Pose {
            position: v3(l.mount.x as f64 / 1000.0, l.mount.y as f64 / 1000.0, 0.0),
            orientation: Some(yaw((l.mount.yaw as f64).to_radians())),
        }),
        start_angle: start,
        end_angle: end,
        ranges: l.readings.iter().map(|r| *r as f64 / 1000.0).collect(),
        intensities: Vec::new(),
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
        let l = laser_scan(
            t,
            &Laser {
                readings: vec![1000, 2500, 0],
                resolution: 1.0,
                ..Laser::default()
            },
        );
        assert_eq!(l.ranges, vec![1.0, 2.5, 0.0]);
        assert!(close(l.start_angle, -std::f64::consts::FRAC_PI_2));
        assert!(close(
            l.end_angle,
            -std::f64::consts::FRAC_PI_2 + 2f64.to_radians()
        ));
        assert_eq!(l.frame_id, BASE);
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
