//! The `ros2` profile: rosbag2-compatible MCAP (ros2msg schemas, CDR messages)
//! for laser (`sensor_msgs/msg/LaserScan`), images (`sensor_msgs/msg/Image`),
//! encoders (`nav_msgs/msg/Odometry`) and motors (`geometry_msgs/msg/Twist`).
//! ROS messages have no place for the interface's clock: it is the MCAP message's
//! `sequence` (mod 2³²).

use std::time::SystemTime;

use super::{Decoded, FormatError, Recorded, Snapshot, bad, nanos};
use crate::interfaces::{Encoders, Image, Laser, Motors};

const SEP: &str =
    "================================================================================\n";
const TIME: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
const HEADER: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
const VECTOR3: &str = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n";

/// The ROS 2 type and its ros2msg definition (with dependencies) for a kind, or
/// `None` for kinds the profile does not carry.
pub fn schema(kind: &str) -> Option<(&'static str, String)> {
    Some(match kind {
        "laser" => (
            "sensor_msgs/msg/LaserScan",
            format!(
                "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n\
                 float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n\
                 float32[] ranges\nfloat32[] intensities\n{SEP}{HEADER}{SEP}{TIME}"
            ),
        ),
        "image" => (
            "sensor_msgs/msg/Image",
            format!(
                "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n\
                 uint32 step\nuint8[] data\n{SEP}{HEADER}{SEP}{TIME}"
            ),
        ),
        "encoders" => (
            "nav_msgs/msg/Odometry",
            format!(
                "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n\
                 geometry_msgs/TwistWithCovariance twist\n{SEP}{HEADER}{SEP}{TIME}\
                 {SEP}MSG: geometry_msgs/PoseWithCovariance\ngeometry_msgs/Pose pose\nfloat64[36] covariance\n\
                 {SEP}MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n\
                 {SEP}MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n\
                 {SEP}MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n\
                 {SEP}MSG: geometry_msgs/TwistWithCovariance\ngeometry_msgs/Twist twist\nfloat64[36] covariance\n\
                 {SEP}MSG: geometry_msgs/Twist\ngeometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n\
                 {SEP}{VECTOR3}"
            ),
        ),
        "motors" => (
            "geometry_msgs/msg/Twist",
            format!("geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n{SEP}{VECTOR3}"),
        ),
        _ => return None,
    })
}

/// The interface kind of a ROS 2 type this profile reads.
pub fn kind_of(schema: &str) -> Option<&'static str> {
    Some(match schema {
        "sensor_msgs/msg/LaserScan" => "laser",
        "sensor_msgs/msg/Image" => "image",
        "nav_msgs/msg/Odometry" => "encoders",
        "geometry_msgs/msg/Twist" => "motors",
        _ => return None,
    })
}

/// A ROS topic for an interface name: `laser.robot2` → `/laser/robot2`.
pub fn topic(name: &str) -> String {
    format!("/{}", name.replace('.', "/"))
}

/// Little-endian CDR with its 4-byte encapsulation header.
struct Writer<'a>(&'a mut Vec<u8>);

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

/// Encodes a sample as CDR into `out`; false for kinds the profile does not carry.
pub fn encode(name: &str, snap: &Snapshot, out: &mut Vec<u8>) -> bool {
    out.clear();
    out.extend_from_slice(&[0, 1, 0, 0]);
    let mut w = Writer(out);
    match snap {
        Snapshot::Laser(l) => {
            w.header(l.time, name);
            let res = if l.resolution > 0.0 {
                l.resolution
            } else {
                1.0
            };
            let inc = (1.0 / res as f64).to_radians();
            let min = -std::f64::consts::FRAC_PI_2;
            w.f32(min as f32);
            w.f32((min + inc * (l.readings.len().max(1) - 1) as f64) as f32);
            w.f32(inc as f32);
            w.f32(0.0);
            w.f32(0.0);
            w.f32(0.0);
            w.f32(8.0);
            w.u32(l.readings.len() as u32);
            for r in &l.readings {
                w.f32(*r as f32 / 1000.0);
            }
            w.u32(0);
        }
        Snapshot::Image(i) => {
            w.header(i.time, name);
            w.u32(i.height);
            w.u32(i.width);
            w.string("bgr8");
            w.u8(0);
            w.u32(i.width * 3);
            w.u32(i.data.len() as u32);
            w.0.extend_from_slice(&i.data);
        }
        Snapshot::Encoders(e) => {
            w.header(e.time, "odom");
            w.string("base_link");
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
        Snapshot::Motors(m) => {
            w.f64(m.v as f64 / 1000.0);
            w.f64(0.0);
            w.f64(0.0);
            w.f64(0.0);
            w.f64(0.0);
            w.f64((m.w as f64).to_radians());
        }
        _ => return false,
    }
    true
}

struct Reader<'a> {
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

/// Decodes a CDR message of interface kind `kind`; `clock` is the MCAP sequence
/// and `log_time` the time for messages without a header (Twist).
pub fn decode(
    topic: &str,
    kind: &str,
    data: &[u8],
    clock: u64,
    log_time: u64,
) -> Result<Decoded, FormatError> {
    if data.len() < 4 || data[..2] != [0, 1] {
        return Err(bad(topic, "not little-endian CDR (encapsulation 0x0001)"));
    }
    let mut r = Reader { data, at: 4, topic };
    let (time_ns, value) = match kind {
        "laser" => {
            let t = r.header()?;
            let _min = r.f32()?;
            let _max = r.f32()?;
            let inc = r.f32()?;
            for _ in 0..4 {
                r.f32()?;
            }
            let n = r.u32()? as usize;
            if n > data.len() / 4 {
                return Err(bad(topic, "a LaserScan with more ranges than bytes"));
            }
            let mut readings = Vec::with_capacity(n);
            for _ in 0..n {
                readings.push((r.f32()? as f64 * 1000.0).round() as i32);
            }
            let resolution = if inc > 0.0 {
                ((1.0 / (inc as f64).to_degrees()) as f32 * 1000.0).round() / 1000.0
            } else {
                1.0
            };
            (
                t,
                Recorded::Laser(Laser {
                    readings,
                    resolution,
                }),
            )
        }
        "image" => {
            let t = r.header()?;
            let height = r.u32()?;
            let width = r.u32()?;
            let enc = r.string()?;
            let _be = r.u8()?;
            let _step = r.u32()?;
            let n = r.u32()? as usize;
            // u64 and checked: a damaged width and height must not overflow.
            let need = (width as u64 * height as u64).checked_mul(3);
            if enc != "bgr8" || need != Some(n as u64) {
                return Err(bad(
                    topic,
                    format!("a {width}x{height} `{enc}` image of {n} bytes; jderobot reads bgr8"),
                ));
            }
            let bytes = r.take(n, 1)?.to_vec();
            (
                t,
                Recorded::Image(Image {
                    width,
                    height,
                    data: bytes,
                }),
            )
        }
        "encoders" => {
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
            let e = Encoders {
                x: (x * 1000.0) as f32,
                y: (y * 1000.0) as f32,
                theta: theta as f32,
                cos: theta.cos() as f32,
                sin: theta.sin() as f32,
            };
            (t, Recorded::Encoders(e))
        }
        "motors" => {
            let vx = r.f64()?;
            for _ in 0..4 {
                r.f64()?;
            }
            let wz = r.f64()?;
            (
                log_time,
                Recorded::Motors(Motors {
                    v: (vx * 1000.0) as f32,
                    w: wz.to_degrees() as f32,
                }),
            )
        }
        other => {
            return Err(FormatError::Kind {
                topic: topic.into(),
                kind: other.into(),
            });
        }
    };
    Ok(Decoded {
        clock,
        time_ns,
        value,
    })
}
