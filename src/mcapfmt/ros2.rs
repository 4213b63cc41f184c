//! The `ros2` profile: rosbag2-compatible MCAP (ros2msg schemas, CDR messages),
//! and the CDR of zenoh's `ros2` format. A kind with a ROS 2 message implements
//! [`Ros2`] with it: laser (`sensor_msgs/msg/LaserScan`), images
//! (`sensor_msgs/msg/Image`), encoders (`nav_msgs/msg/Odometry`), motors
//! (`geometry_msgs/msg/Twist`) and imu (`sensor_msgs/msg/Imu`); the other kinds
//! keep the trait's defaults (no message: the profile leaves them out). ROS
//! messages have no place for the interface's clock: it is the MCAP message's
//! `sequence` (mod 2³²).

use std::time::SystemTime;

use super::{FormatError, bad, nanos};
use crate::{
    interfaces::{
        Bumpers, Encoders, Image, Imu, InterfaceValue, Kind, Laser, Motors, PtEncoders, PtMotors,
        Sample, Sonars, ZoomEncoders, ZoomMotors, with_kind,
    },
    vision::pixfmt::{Packed8, packed_to_bgr},
};

const SEP: &str =
    "================================================================================\n";
const TIME: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
const HEADER: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
const VECTOR3: &str = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n";
const QUATERNION: &str =
    "MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n";

/// A ROS 2 message type.
pub struct Message {
    /// The type name (`sensor_msgs/msg/Imu`), as rosbag2 writes it in schemas.
    pub name: &'static str,
    /// The DDS type name as rmw_zenoh writes it in keys.
    pub dds: &'static str,
    /// The RIHS01 type hash of ROS 2 Jazzy (checked against rosbags' own
    /// computation in `tests/zenoh_python.rs` and this module's tests).
    pub hash: &'static str,
    /// The ros2msg definition with its dependencies.
    pub definition: fn() -> String,
}

/// A kind's ROS 2 message. Every kind of the table implements it; a kind
/// without a ROS message keeps the defaults.
pub trait Ros2: InterfaceValue {
    const MESSAGE: Option<&'static Message> = None;
    /// Writes the value as the message (after the encapsulation header).
    fn to_cdr(&self, _name: &str, _time: SystemTime, _w: &mut Writer) {}
    /// Reads the message: (wall time ns, value); `log_time` for a message
    /// without a header.
    fn from_cdr(r: &mut Reader, _log_time: u64) -> Result<(u64, Self), FormatError> {
        Err(FormatError::Kind {
            topic: r.topic.into(),
            kind: Self::KIND.to_string(),
        })
    }
}

/// The ROS 2 message of interface kind `kind`, if it has one.
pub fn message(kind: Kind) -> Option<&'static Message> {
    fn of<T: Ros2>() -> Option<&'static Message> {
        T::MESSAGE
    }
    with_kind!(kind, of())
}

/// The ROS 2 type and its ros2msg definition (with dependencies) for a kind, or
/// `None` for kinds the profile does not carry.
pub fn schema(kind: Kind) -> Option<(&'static str, String)> {
    message(kind).map(|m| (m.name, (m.definition)()))
}

/// The kinds with a ROS 2 message (what the profile carries).
pub fn kinds() -> Vec<Kind> {
    Kind::ALL
        .iter()
        .copied()
        .filter(|&k| message(k).is_some())
        .collect()
}

/// The interface kind of a ROS 2 type this profile reads.
pub fn kind_of(schema: &str) -> Option<Kind> {
    Kind::ALL
        .iter()
        .copied()
        .find(|&k| message(k).is_some_and(|m| m.name == schema))
}

/// A ROS topic for an interface name: `laser.robot2` → `/laser/robot2`.
pub fn topic(name: &str) -> String {
    format!("/{}", name.replace('.', "/"))
}

/// Little-endian CDR with its 4-byte encapsulation header.
pub struct Writer<'a>(&'a mut Vec<u8>);

impl Writer<'_> {
    fn align(&mut self, n: usize) {
        while !(self.0.len() - 4).is_multiple_of(n) {
            self.0.push(0);
        }
    }
    fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    fn u32(&mut self, v: u32) {
        self.align(4);
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn i32(&mut self, v: i32) {
        self.align(4);
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.align(4);
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.align(8);
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.0.extend_from_slice(s.as_bytes());
        self.0.push(0);
    }
    fn header(&mut self, t: SystemTime, frame: &str) {
        let ns = nanos(t);
        self.i32((ns / 1_000_000_000) as i32);
        self.u32((ns % 1_000_000_000) as u32);
        self.string(frame);
    }
}

/// Reads little-endian CDR after the encapsulation header; every read checks the length.
pub struct Reader<'a> {
    data: &'a [u8],
    at: usize,
    topic: &'a str,
}

impl Reader<'_> {
    fn take(&mut self, n: usize, align: usize) -> Result<&[u8], FormatError> {
        while !(self.at - 4).is_multiple_of(align) {
            self.at += 1;
        }
        let s = self
            .data
            .get(self.at..self.at + n)
            .ok_or_else(|| bad(self.topic, "the CDR message ends early"))?;
        self.at += n;
        Ok(s)
    }
    fn u32(&mut self) -> Result<u32, FormatError> {
        Ok(u32::from_le_bytes(self.take(4, 4)?.try_into().expect("4")))
    }
    fn i32(&mut self) -> Result<i32, FormatError> {
        Ok(i32::from_le_bytes(self.take(4, 4)?.try_into().expect("4")))
    }
    fn f32(&mut self) -> Result<f32, FormatError> {
        Ok(f32::from_le_bytes(self.take(4, 4)?.try_into().expect("4")))
    }
    fn f64(&mut self) -> Result<f64, FormatError> {
        Ok(f64::from_le_bytes(self.take(8, 8)?.try_into().expect("8")))
    }
    fn u8(&mut self) -> Result<u8, FormatError> {
        Ok(self.take(1, 1)?[0])
    }
    fn string(&mut self) -> Result<String, FormatError> {
        let n = self.u32()? as usize;
        let b = self.take(n, 1)?;
        Ok(String::from_utf8_lossy(b.strip_suffix(&[0]).unwrap_or(b)).into_owned())
    }
    fn header(&mut self) -> Result<u64, FormatError> {
        let sec = self.i32()?;
        let nsec = self.u32()?;
        let _frame = self.string()?;
        Ok(sec.max(0) as u64 * 1_000_000_000 + nsec as u64)
    }
}

/// Encodes a sample as CDR into `out` (cleared first); false for kinds without
/// a ROS message.
pub fn encode<T: Ros2>(name: &str, s: &Sample<T>, out: &mut Vec<u8>) -> bool {
    if T::MESSAGE.is_none() {
        return false;
    }
    out.clear();
    out.extend_from_slice(&[0, 1, 0, 0]);
    s.value.to_cdr(name, s.time, &mut Writer(out));
    true
}

/// Decodes a CDR message of a `T` interface on `topic`: (wall time ns, value);
/// `log_time` is the time of messages without a header (Twist).
pub fn decode<T: Ros2>(topic: &str, data: &[u8], log_time: u64) -> Result<(u64, T), FormatError> {
    if T::MESSAGE.is_none() {
        return Err(FormatError::Kind {
            topic: topic.into(),
            kind: T::KIND.to_string(),
        });
    }
    if data.len() < 4 || data[..2] != [0, 1] {
        return Err(bad(topic, "not little-endian CDR (encapsulation 0x0001)"));
    }
    T::from_cdr(&mut Reader { data, at: 4, topic }, log_time)
}

const LASER_SCAN: Message = Message {
    name: "sensor_msgs/msg/LaserScan",
    dds: "sensor_msgs::msg::dds_::LaserScan_",
    hash: "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
    definition: || {
        format!(
            "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n\
             float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n\
             float32[] ranges\nfloat32[] intensities\n{SEP}{HEADER}{SEP}{TIME}"
        )
    },
};

impl Ros2 for Laser {
    const MESSAGE: Option<&'static Message> = Some(&LASER_SCAN);
    /// REP 103: counter-clockwise radians and metres, from the value's geometry
    /// (the mount is the laser frame's transform, not part of the message).
    fn to_cdr(&self, name: &str, time: SystemTime, w: &mut Writer) {
        w.header(time, name);
        let inc = (self.step() as f64).to_radians();
        let min = (self.start as f64).to_radians();
        w.f32(min as f32);
        w.f32((min + inc * self.readings.len().saturating_sub(1) as f64) as f32);
        w.f32(inc as f32);
        w.f32(0.0);
        w.f32(0.0);
        w.f32(self.min_range / 1000.0);
        w.f32(self.max_range / 1000.0);
        w.u32(self.readings.len() as u32);
        for r in &self.readings {
            w.f32(*r as f32 / 1000.0);
        }
        w.u32(0);
    }
    fn from_cdr(r: &mut Reader, _log_time: u64) -> Result<(u64, Self), FormatError> {
        let t = r.header()?;
        let min = r.f32()?;
        let _max = r.f32()?;
        let inc = r.f32()?;
        let _time_increment = r.f32()?;
        let _scan_time = r.f32()?;
        let range_min = r.f32()?;
        let range_max = r.f32()?;
        let n = r.u32()? as usize;
        if n > r.data.len() / 4 {
            return Err(bad(r.topic, "a LaserScan with more ranges than bytes"));
        }
        // REP 117: +inf is no return, NaN an erroneous one (both: max_range, what
        // the interface calls no return), -inf too close to measure (min_range).
        let mut readings = Vec::with_capacity(n);
        for _ in 0..n {
            let v = match r.f32()? {
                v if v.is_nan() || v > range_max => range_max,
                f32::NEG_INFINITY => range_min,
                v => v,
            };
            readings.push((v as f64 * 1000.0).round() as i32);
        }
        if !inc.is_finite() || (inc == 0.0 && n > 1) {
            return Err(bad(
                r.topic,
                format!("a LaserScan of {n} readings with angle_increment {inc}"),
            ));
        }
        let resolution = if inc != 0.0 {
            ((1.0 / (inc.abs() as f64).to_degrees()) as f32 * 1000.0).round() / 1000.0
        } else {
            1.0
        };
        // A scan from +angle to −angle (a negative increment, as some lidars
        // publish it) is the same scan read from its other end: its last reading
        // is the first counter-clockwise.
        let first = if inc < 0.0 {
            readings.reverse();
            min as f64 + inc as f64 * n.saturating_sub(1) as f64
        } else {
            min as f64
        };
        let deg = |rad: f64| (rad.to_degrees() * 1000.0).round() as f32 / 1000.0;
        Ok((
            t,
            Laser {
                readings,
                resolution,
                start: deg(first),
                min_range: range_min * 1000.0,
                max_range: range_max * 1000.0,
                ..Laser::default()
            },
        ))
    }
}

/// An image's CDR fields up to its pixels' length; the pixels come last.
fn image_fields_but_pixels(img: &Image, name: &str, time: SystemTime, w: &mut Writer) {
    w.header(time, name);
    w.u32(img.height);
    w.u32(img.width);
    w.string("bgr8");
    w.u8(0);
    w.u32(img.width * 3);
    w.u32(img.data.len() as u32);
}

/// [`encode`] of an image but its pixels, which come last: the message is `out`
/// followed by `s.value.data`, so a writer can take the pixels from where they are.
pub fn image_head(name: &str, s: &Sample<Image>, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&[0, 1, 0, 0]);
    image_fields_but_pixels(&s.value, name, s.time, &mut Writer(out));
}

/// The `sensor_msgs/msg/Image` encodings jderobot reads.
pub const IMAGE_ENCODINGS: [&str; 5] = ["bgr8", "rgb8", "mono8", "bgra8", "rgba8"];

/// The pixel layout of a `sensor_msgs/msg/Image` encoding jderobot reads.
fn image_encoding(enc: &str) -> Option<Packed8> {
    Some(match enc {
        "bgr8" => Packed8::Bgr,
        "rgb8" => Packed8::Rgb,
        "mono8" => Packed8::Grey,
        "bgra8" => Packed8::Bgra,
        "rgba8" => Packed8::Rgba,
        _ => return None,
    })
}

const IMAGE: Message = Message {
    name: "sensor_msgs/msg/Image",
    dds: "sensor_msgs::msg::dds_::Image_",
    hash: "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47",
    definition: || {
        format!(
            "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n\
             uint32 step\nuint8[] data\n{SEP}{HEADER}{SEP}{TIME}"
        )
    },
};

impl Ros2 for Image {
    const MESSAGE: Option<&'static Message> = Some(&IMAGE);
    fn to_cdr(&self, name: &str, time: SystemTime, w: &mut Writer) {
        image_fields_but_pixels(self, name, time, w);
        w.0.extend_from_slice(&self.data);
    }
    /// `bgr8`, `rgb8`, `mono8`, `bgra8` and `rgba8` (sensor_msgs/image_encodings),
    /// rows `step` bytes apart, converted once to BGR (alpha dropped, grey in the
    /// three channels). `is_bigendian` says the byte order of multi-byte channels:
    /// these have one byte per channel, so it changes nothing.
    fn from_cdr(r: &mut Reader, _log_time: u64) -> Result<(u64, Self), FormatError> {
        let t = r.header()?;
        let height = r.u32()?;
        let width = r.u32()?;
        let enc = r.string()?;
        let _big_endian = r.u8()?;
        let step = r.u32()?;
        let n = r.u32()? as usize;
        let topic = r.topic;
        let refuse = |why: &str| {
            bad(
                topic,
                format!("a {width}x{height} `{enc}` image of {n} bytes (step {step}): {why}"),
            )
        };
        let Some(format) = image_encoding(&enc) else {
            return Err(refuse(&format!(
                "jderobot reads {}",
                IMAGE_ENCODINGS.join(", ")
            )));
        };
        if width == 0 || height == 0 {
            return Err(refuse("no pixels"));
        }
        let data = r
            .take(n, 1)
            .map_err(|_| refuse("the message ends before its data"))?;
        let mut bgr = Vec::new();
        packed_to_bgr(data, width, height, step as usize, format, &mut bgr)
            .map_err(|e| refuse(&e.to_string()))?;
        Ok((
            t,
            Image {
                width,
                height,
                data: bgr,
            },
        ))
    }
}

const ODOMETRY: Message = Message {
    name: "nav_msgs/msg/Odometry",
    dds: "nav_msgs::msg::dds_::Odometry_",
    hash: "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    definition: || {
        format!(
            "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n\
             geometry_msgs/TwistWithCovariance twist\n{SEP}{HEADER}{SEP}{TIME}\
             {SEP}MSG: geometry_msgs/PoseWithCovariance\ngeometry_msgs/Pose pose\nfloat64[36] covariance\n\
             {SEP}MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n\
             {SEP}MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n\
             {SEP}{QUATERNION}\
             {SEP}MSG: geometry_msgs/TwistWithCovariance\ngeometry_msgs/Twist twist\nfloat64[36] covariance\n\
             {SEP}MSG: geometry_msgs/Twist\ngeometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n\
             {SEP}{VECTOR3}"
        )
    },
};

/// Encodes `nav_msgs/msg/Odometry`: the robot's frame `child` in the odometry
/// frame `parent` (the service's `frames` line), into `out` (cleared first).
pub fn encode_odometry(
    time: SystemTime,
    parent: &str,
    child: &str,
    e: &Encoders,
    out: &mut Vec<u8>,
) {
    odometry(e, time, parent, child, &mut start(out));
}

fn odometry(e: &Encoders, time: SystemTime, parent: &str, child: &str, w: &mut Writer) {
    w.header(time, parent);
    w.string(child);
    w.f64(e.x as f64 / 1000.0);
    w.f64(e.y as f64 / 1000.0);
    w.f64(0.0);
    let half = e.theta as f64 / 2.0;
    w.f64(0.0);
    w.f64(0.0);
    w.f64(half.sin());
    w.f64(half.cos());
    for _ in 0..36 + 6 + 36 {
        w.f64(0.0);
    }
}

impl Ros2 for Encoders {
    const MESSAGE: Option<&'static Message> = Some(&ODOMETRY);
    /// REP 105's frames, `odom` → `base_link` (the recorder's and zenoh's; the
    /// service writes its `frames` line's with [`encode_odometry`]).
    fn to_cdr(&self, _name: &str, time: SystemTime, w: &mut Writer) {
        odometry(self, time, "odom", "base_link", w);
    }
    fn from_cdr(r: &mut Reader, _log_time: u64) -> Result<(u64, Self), FormatError> {
        let t = r.header()?;
        let _child = r.string()?;
        let x = r.f64()?;
        let y = r.f64()?;
        let _z = r.f64()?;
        let (_qx, _qy, qz, qw) = (r.f64()?, r.f64()?, r.f64()?, r.f64()?);
        let mut theta = 2.0 * qz.atan2(qw);
        while theta <= 0.0 {
            theta += std::f64::consts::TAU;
        }
        while theta > std::f64::consts::TAU {
            theta -= std::f64::consts::TAU;
        }
        Ok((
            t,
            Encoders {
                x: (x * 1000.0) as f32,
                y: (y * 1000.0) as f32,
                theta: theta as f32,
                cos: theta.cos() as f32,
                sin: theta.sin() as f32,
            },
        ))
    }
}

const TWIST: Message = Message {
    name: "geometry_msgs/msg/Twist",
    dds: "geometry_msgs::msg::dds_::Twist_",
    hash: "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
    definition: || {
        format!("geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n{SEP}{VECTOR3}")
    },
};

impl Ros2 for Motors {
    const MESSAGE: Option<&'static Message> = Some(&TWIST);
    fn to_cdr(&self, _name: &str, _time: SystemTime, w: &mut Writer) {
        w.f64(self.v as f64 / 1000.0);
        w.f64(0.0);
        w.f64(0.0);
        w.f64(0.0);
        w.f64(0.0);
        w.f64((self.w as f64).to_radians());
    }
    fn from_cdr(r: &mut Reader, log_time: u64) -> Result<(u64, Self), FormatError> {
        let vx = r.f64()?;
        for _ in 0..4 {
            r.f64()?;
        }
        let wz = r.f64()?;
        Ok((
            log_time,
            Motors {
                v: (vx * 1000.0) as f32,
                w: wz.to_degrees() as f32,
            },
        ))
    }
}

const IMU: Message = Message {
    name: "sensor_msgs/msg/Imu",
    dds: "sensor_msgs::msg::dds_::Imu_",
    hash: "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b",
    definition: || {
        format!(
            "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n\
             geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n\
             geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n\
             {SEP}{HEADER}{SEP}{TIME}{SEP}{QUATERNION}{SEP}{VECTOR3}"
        )
    },
};

/// sensor_msgs/Imu in the same SI units as [`Imu`]; the covariances are written
/// as zeros ("unknown", in ROS's convention) and ignored when read.
impl Ros2 for Imu {
    const MESSAGE: Option<&'static Message> = Some(&IMU);
    fn to_cdr(&self, name: &str, time: SystemTime, w: &mut Writer) {
        w.header(time, name);
        let f = self.fields();
        for g in [&f[..4], &f[4..7], &f[7..]] {
            for v in g {
                w.f64(*v as f64);
            }
            for _ in 0..9 {
                w.f64(0.0);
            }
        }
    }
    fn from_cdr(r: &mut Reader, _log_time: u64) -> Result<(u64, Self), FormatError> {
        let t = r.header()?;
        let mut v = [0f32; 10];
        for (i, n) in [(0, 4), (4, 3), (7, 3)] {
            for x in &mut v[i..i + n] {
                *x = r.f64()? as f32;
            }
            for _ in 0..9 {
                r.f64()?;
            }
        }
        Ok((t, Imu::from_fields(v)))
    }
}

/// The DDS type name of `tf2_msgs/msg/TFMessage` (`/tf`, `/tf_static`).
pub const TF_MESSAGE: &str = "tf2_msgs::msg::dds_::TFMessage_";

/// One `geometry_msgs/TransformStamped`: `child` in `parent`, metres and radians
/// (a planar pose with a height: REP 103).
#[derive(Clone, Debug, PartialEq)]
pub struct Transform {
    pub parent: String,
    pub child: String,
    pub x: f64,
    pub y: f64,
    pub z: f64,
    /// Counter-clockwise about z, radians.
    pub yaw: f64,
}

/// Encodes `tf2_msgs/msg/TFMessage` (its transforms stamped `time`) as CDR into
/// `out` (cleared first).
pub fn encode_tf(time: SystemTime, transforms: &[Transform], out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&[0, 1, 0, 0]);
    let mut w = Writer(out);
    w.u32(transforms.len() as u32);
    for t in transforms {
        w.header(time, &t.parent);
        w.string(&t.child);
        for v in [
            t.x,
            t.y,
            t.z,
            0.0,
            0.0,
            (t.yaw / 2.0).sin(),
            (t.yaw / 2.0).cos(),
        ] {
            w.f64(v);
        }
    }
}

/// One `geometry_msgs/TransformStamped` as read from `/tf` or `/tf_static`:
/// frame `child` in frame `parent`, its translation (m) and rotation (the
/// quaternion x, y, z, w).
#[derive(Clone, Debug, PartialEq)]
pub struct StampedTransform {
    pub parent: String,
    pub child: String,
    pub translation: [f64; 3],
    pub rotation: [f64; 4],
}

/// Decodes a `tf2_msgs/msg/TFMessage`.
pub fn decode_tf(topic: &str, data: &[u8]) -> Result<Vec<StampedTransform>, FormatError> {
    let mut r = cdr_reader(topic, data)?;
    // Each: a header (8 bytes and a string of 4 or more), a string, 7 f64s.
    let n = r.len(72, "TFMessage.transforms")?;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        r.i32()?;
        r.u32()?;
        let parent = r.string()?;
        let child = r.string()?;
        let mut v = [0f64; 7];
        for x in &mut v {
            *x = r.f64()?;
        }
        out.push(StampedTransform {
            parent,
            child,
            translation: [v[0], v[1], v[2]],
            rotation: [v[3], v[4], v[5], v[6]],
        });
    }
    Ok(out)
}

/// The `frame_id` of a message that starts with a `std_msgs/Header` (every
/// sensor message here).
pub fn header_frame(topic: &str, data: &[u8]) -> Result<String, FormatError> {
    let mut r = cdr_reader(topic, data)?;
    r.i32()?;
    r.u32()?;
    r.string()
}

/// A reader of a little-endian CDR message, past its encapsulation header.
fn cdr_reader<'a>(topic: &'a str, data: &'a [u8]) -> Result<Reader<'a>, FormatError> {
    if data.len() < 4 || data[..2] != [0, 1] {
        return Err(bad(topic, "not little-endian CDR (encapsulation 0x0001)"));
    }
    Ok(Reader { data, at: 4, topic })
}

/// The DDS type name of `rosgraph_msgs/msg/Clock` (`/clock`).
pub const CLOCK: &str = "rosgraph_msgs::msg::dds_::Clock_";

/// Encodes `rosgraph_msgs/msg/Clock` (a `builtin_interfaces/Time`) into `out`.
pub fn encode_clock(time: SystemTime, out: &mut Vec<u8>) {
    let mut w = start(out);
    let ns = nanos(time);
    w.i32((ns / 1_000_000_000) as i32);
    w.u32((ns % 1_000_000_000) as u32);
}

/// Sets the stamp of an encoded message that starts with a `std_msgs/Header`
/// (every sensor message here) to `time`.
pub fn restamp(msg: &mut [u8], time: SystemTime) {
    let ns = nanos(time);
    if let Some(b) = msg.get_mut(4..12) {
        b[..4].copy_from_slice(&((ns / 1_000_000_000) as i32).to_le_bytes());
        b[4..].copy_from_slice(&((ns % 1_000_000_000) as u32).to_le_bytes());
    }
}

fn start(out: &mut Vec<u8>) -> Writer<'_> {
    out.clear();
    out.extend_from_slice(&[0, 1, 0, 0]);
    Writer(out)
}

/// The DDS type name of `sensor_msgs/msg/Range` (one sonar).
pub const RANGE: &str = "sensor_msgs::msg::dds_::Range_";

/// One sonar's reading, what `sensor_msgs/msg/Range` carries (metres, radians).
pub struct RangeReading<'a> {
    pub frame: &'a str,
    pub field_of_view: f32,
    pub min_range: f32,
    pub max_range: f32,
    pub range: f32,
}

/// Encodes `sensor_msgs/msg/Range` (radiation type ULTRASOUND, as Humble's and
/// Jazzy's definition: no `variance`) into `out` (cleared first).
pub fn encode_range(time: SystemTime, r: &RangeReading, out: &mut Vec<u8>) {
    let mut w = start(out);
    w.header(time, r.frame);
    w.u8(0);
    for v in [r.field_of_view, r.min_range, r.max_range, r.range] {
        w.f32(v);
    }
}

/// The DDS type name of `irobot_create_msgs/msg/HazardDetectionVector`.
pub const HAZARDS: &str = "irobot_create_msgs::msg::dds_::HazardDetectionVector_";

/// Encodes `irobot_create_msgs/msg/HazardDetectionVector` (the iRobot Create 3's
/// `/hazard_detection`): one `HazardDetection` of type BUMP (1) per frame in
/// `bumped`, each stamped `time` in its own frame; `frame` is the vector's.
pub fn encode_hazards(time: SystemTime, frame: &str, bumped: &[String], out: &mut Vec<u8>) {
    let mut w = start(out);
    w.header(time, frame);
    w.u32(bumped.len() as u32);
    for b in bumped {
        w.header(time, b);
        w.u8(1);
    }
}

/// The DDS type name of `sensor_msgs/msg/JointState`.
pub const JOINT_STATE: &str = "sensor_msgs::msg::dds_::JointState_";

/// A `sensor_msgs/msg/JointState`: names, positions (rad), velocities (rad/s);
/// the efforts are not kept.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Joints {
    pub names: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
}

/// Encodes `sensor_msgs/msg/JointState` (no efforts) into `out` (cleared first).
pub fn encode_joints(time: SystemTime, j: &Joints, out: &mut Vec<u8>) {
    let mut w = start(out);
    w.header(time, "");
    w.u32(j.names.len() as u32);
    for n in &j.names {
        w.string(n);
    }
    for v in [&j.position, &j.velocity] {
        w.u32(v.len() as u32);
        for x in v.iter() {
            w.f64(*x);
        }
    }
    w.u32(0);
}

impl Reader<'_> {
    /// A sequence's length, refused when it could not fit in what is left
    /// (`size` bytes per element at least): a damaged length allocates nothing.
    fn len(&mut self, size: usize, what: &str) -> Result<usize, FormatError> {
        let n = self.u32()? as usize;
        if n.saturating_mul(size) > self.data.len().saturating_sub(self.at) {
            return Err(bad(
                self.topic,
                format!("{what}: {n} elements in {} bytes", self.data.len()),
            ));
        }
        Ok(n)
    }
    fn f64s(&mut self, what: &str) -> Result<Vec<f64>, FormatError> {
        let n = self.len(8, what)?;
        (0..n).map(|_| self.f64()).collect()
    }
}

/// Decodes a `sensor_msgs/msg/JointState` CDR message.
pub fn decode_joints(topic: &str, data: &[u8]) -> Result<Joints, FormatError> {
    if data.len() < 4 || data[..2] != [0, 1] {
        return Err(bad(topic, "not little-endian CDR (encapsulation 0x0001)"));
    }
    let mut r = Reader { data, at: 4, topic };
    r.header()?;
    let n = r.len(5, "JointState.name")?;
    let names = (0..n).map(|_| r.string()).collect::<Result<_, _>>()?;
    let position = r.f64s("JointState.position")?;
    let velocity = r.f64s("JointState.velocity")?;
    Ok(Joints {
        names,
        position,
        velocity,
    })
}

/// The DDS type name of `sensor_msgs/msg/CompressedImage`.
pub const COMPRESSED_IMAGE: &str = "sensor_msgs::msg::dds_::CompressedImage_";

/// Encodes `sensor_msgs/msg/CompressedImage` as image_transport's `compressed`
/// plugin writes it (format `bgr8; jpeg compressed bgr8`): the image as JPEG of
/// `quality` (1..=100). False when the encoder fails.
pub fn encode_compressed(frame: &str, s: &Sample<Image>, quality: u8, out: &mut Vec<u8>) -> bool {
    let Some(jpeg) = super::jpeg(&s.value, quality) else {
        return false;
    };
    let mut w = start(out);
    w.header(s.time, frame);
    w.string("bgr8; jpeg compressed bgr8");
    w.u32(jpeg.len() as u32);
    w.0.extend_from_slice(&jpeg);
    true
}

/// The largest image a CompressedImage may unpack to (pixels): 8192x8192, so a
/// small message cannot claim gigabytes.
const MAX_PIXELS: u64 = 8192 * 8192;

/// Decodes a `sensor_msgs/msg/CompressedImage` (JPEG or PNG, as image_transport's
/// `compressed` plugin sends) into a BGR image: (wall time ns, image).
pub fn decode_compressed(topic: &str, data: &[u8]) -> Result<(u64, Image), FormatError> {
    if data.len() < 4 || data[..2] != [0, 1] {
        return Err(bad(topic, "not little-endian CDR (encapsulation 0x0001)"));
    }
    let mut r = Reader { data, at: 4, topic };
    let t = r.header()?;
    let format = r.string()?;
    let n = r.len(1, "CompressedImage.data")?;
    let bytes = r.take(n, 1)?;
    let fail = |e: String| bad(topic, format!("a CompressedImage `{format}`: {e}"));
    let mut dec = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| fail(e.to_string()))?;
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(MAX_PIXELS * 4);
    dec.limits(limits);
    let img = dec.decode().map_err(|e| fail(e.to_string()))?.into_rgb8();
    let (w, h) = img.dimensions();
    if w as u64 * h as u64 > MAX_PIXELS || w == 0 || h == 0 {
        return Err(fail(format!("{w}x{h} pixels")));
    }
    Ok((t, Image::from_rgb(w, h, img.into_raw())))
}

/// The kinds without a ROS 2 message.
impl Ros2 for Sonars {}
impl Ros2 for Bumpers {}
impl Ros2 for PtEncoders {}
impl Ros2 for PtMotors {}
impl Ros2 for ZoomEncoders {}
impl Ros2 for ZoomMotors {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn imu_round_trips_and_a_kind_without_a_message_is_refused() {
        let imu = Imu {
            qx: 0.0,
            qy: 0.0,
            qz: 0.5f32.sin(),
            qw: 0.5f32.cos(),
            wx: 0.25,
            wy: -0.5,
            wz: 1.0,
            ax: 0.1,
            ay: 0.2,
            az: 9.81,
        };
        let s = Sample {
            clock: 3,
            stamp: std::time::Instant::now(),
            time: super::super::from_nanos(1_700_000_000_000_000_007),
            value: imu,
        };
        let mut b = Vec::new();
        assert!(encode("imu", &s, &mut b));
        // Header (4 + 4 + 4 + "imu\0" = 16 bytes after the encapsulation), then
        // 10 values and 27 covariances, 8-aligned.
        assert_eq!(b.len(), 4 + 16 + 37 * 8);
        assert_eq!(
            decode::<Imu>("imu", &b, 0).unwrap(),
            (1_700_000_000_000_000_007, imu)
        );
        for n in 0..b.len() {
            assert!(decode::<Imu>("imu", &b[..n], 0).is_err());
        }
        assert!(!encode(
            "sonars",
            &Sample {
                clock: 1,
                stamp: s.stamp,
                time: s.time,
                value: Sonars::default()
            },
            &mut b
        ));
        assert_eq!(kind_of("sensor_msgs/msg/Imu"), Some(Kind::Imu));
        assert_eq!(schema(Kind::Bumpers), None);
    }

    /// A LaserScan's CDR: `n` ranges from `min` rad by `inc` rad.
    fn scan(min: f32, inc: f32, ranges: &[f32]) -> Vec<u8> {
        let mut b = Vec::new();
        let mut w = start(&mut b);
        w.header(SystemTime::UNIX_EPOCH, "laser");
        let max = min + inc * ranges.len().saturating_sub(1) as f32;
        for v in [min, max, inc, 0.0, 0.0, 0.1, 8.0] {
            w.f32(v);
        }
        w.u32(ranges.len() as u32);
        ranges.iter().for_each(|r| w.f32(*r));
        w.u32(0);
        b
    }

    #[test]
    fn a_scan_with_a_negative_increment_reads_as_the_forward_one() {
        let ranges: Vec<f32> = (0..181).map(|i| 1.0 + i as f32 / 100.0).collect();
        let inc = 1f32.to_radians();
        let half = std::f32::consts::FRAC_PI_2;
        let forward = decode::<Laser>("s", &scan(-half, inc, &ranges), 0)
            .unwrap()
            .1;
        let back: Vec<f32> = ranges.iter().rev().copied().collect();
        let reversed = decode::<Laser>("s", &scan(half, -inc, &back), 0).unwrap().1;
        assert_eq!(reversed, forward);
        assert_eq!((forward.start, forward.resolution), (-90.0, 1.0));
        assert_eq!(forward.readings[0], 1000);
        // An increment of 0 for several readings, or not a number, is refused;
        // one reading needs none.
        assert!(decode::<Laser>("s", &scan(0.0, 0.0, &[1.0, 2.0]), 0).is_err());
        assert!(decode::<Laser>("s", &scan(0.0, f32::NAN, &[1.0, 2.0]), 0).is_err());
        assert!(decode::<Laser>("s", &scan(0.0, 0.0, &[1.0]), 0).is_ok());
        assert_eq!(header_frame("s", &scan(0.0, 0.0, &[1.0])).unwrap(), "laser");
    }

    /// An Image's CDR: `px` are the pixels of a `w`-wide image in `enc`, rows
    /// padded to `step` bytes.
    fn image(enc: &str, w: u32, h: u32, step: u32, data: &[u8]) -> Vec<u8> {
        let mut b = Vec::new();
        let mut wr = start(&mut b);
        wr.header(SystemTime::UNIX_EPOCH, "camera");
        wr.u32(h);
        wr.u32(w);
        wr.string(enc);
        wr.u8(1);
        wr.u32(step);
        wr.u32(data.len() as u32);
        wr.0.extend_from_slice(data);
        b
    }

    #[test]
    fn every_8_bit_encoding_reads_as_bgr_with_its_row_padding() {
        // 2x2: red, green / blue, white; rows padded to 12 bytes.
        let rgb = [[255u8, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 255]];
        let bgr: Vec<u8> = rgb.iter().flat_map(|p| [p[2], p[1], p[0]]).collect();
        // One pixel's bytes in an encoding.
        type Px = fn([u8; 3]) -> Vec<u8>;
        let padded = |bpp: usize, px: Px| -> Vec<u8> {
            let mut d = vec![];
            for row in rgb.chunks(2) {
                let mut r: Vec<u8> = row.iter().flat_map(|p| px(*p)).collect();
                r.resize(12, 0xAA);
                d.extend(r);
            }
            assert!(bpp * 2 <= 12);
            d
        };
        let cases: [(&str, usize, Px); 4] = [
            ("bgr8", 3, |p| vec![p[2], p[1], p[0]]),
            ("rgb8", 3, |p| p.to_vec()),
            ("bgra8", 4, |p| vec![p[2], p[1], p[0], 9]),
            ("rgba8", 4, |p| vec![p[0], p[1], p[2], 9]),
        ];
        for (enc, bpp, px) in cases {
            let img = decode::<Image>("c", &image(enc, 2, 2, 12, &padded(bpp, px)), 0)
                .unwrap()
                .1;
            assert_eq!((img.width, img.height, &img.data), (2, 2, &bgr), "{enc}");
        }
        let grey = decode::<Image>("c", &image("mono8", 3, 2, 4, &[1, 2, 3, 0, 4, 5, 6]), 0)
            .unwrap()
            .1;
        assert_eq!(
            grey.data,
            [1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4, 5, 5, 5, 6, 6, 6]
        );
        for (enc, step, n) in [
            ("yuv422", 4, 8),
            ("16UC1", 4, 8),
            ("rgb8", 5, 11),
            ("rgb8", 6, 11),
            ("mono8", 2, 3),
        ] {
            let e = decode::<Image>("c", &image(enc, 2, 2, step, &vec![0; n]), 0).unwrap_err();
            assert!(
                e.to_string()
                    .contains(&format!("`{enc}` image of {n} bytes")),
                "{e}"
            );
        }
    }

    #[test]
    fn odometry_takes_its_frames_and_tf_reads_back() {
        let e = Encoders::from_pose(1000.0, -500.0, 1.0);
        let mut b = Vec::new();
        encode_odometry(SystemTime::UNIX_EPOCH, "world", "robot", &e, &mut b);
        assert_eq!(header_frame("o", &b).unwrap(), "world");
        let (_, back) = decode::<Encoders>("o", &b, 0).unwrap();
        assert!((back.x - 1000.0).abs() < 1e-3 && (back.theta - 1.0).abs() < 1e-6);
        let t = Transform {
            parent: "base".into(),
            child: "laser".into(),
            x: 0.1,
            y: -0.2,
            z: 0.3,
            yaw: 0.5,
        };
        encode_tf(SystemTime::UNIX_EPOCH, &[t.clone(), t], &mut b);
        let got = decode_tf("tf", &b).unwrap();
        assert_eq!(got.len(), 2);
        assert_eq!(
            (got[0].parent.as_str(), got[0].child.as_str()),
            ("base", "laser")
        );
        assert_eq!(got[0].translation, [0.1, -0.2, 0.3]);
        assert!((got[1].rotation[2] - 0.25f64.sin()).abs() < 1e-12);
        for n in 0..b.len() {
            assert!(decode_tf("tf", &b[..n]).is_err());
        }
    }
}
