//! The protobuf messages the driver reads and writes, on the one protobuf wire
//! ([`crate::protowire`]):
//! gz-transport's `Discovery` and the gz-msgs messages of the topics (field numbers
//! from gz-msgs 8's `.proto` files, the same in `gz.msgs` of Garden and later).
//!
//! | message | fields used |
//! |---|---|
//! | `Discovery` | 2 version, 3 process_uuid, 4 type, 5 flags, 6 sub (1 topic), 7 pub |
//! | `Discovery.Publisher` | 1 topic, 2 address, 3 process_uuid, 4 node_uuid, 5 scope, 6 msg_pub (1 ctrl, 2 msg_type, 3 throttled, 4 msgs_per_sec) |
//! | `Header` | 1 stamp (`Time`: 1 sec int64, 2 nsec int32) |
//! | `Twist` | 1 header, 2 linear, 3 angular (`Vector3d`: 2 x, 3 y, 4 z) |
//! | `Odometry` | 1 header, 2 pose (`Pose`: 4 position, 5 orientation `Quaternion` 2 x 3 y 4 z 5 w), 3 twist |
//! | `LaserScan` | 1 header, 4 angle_min, 5 angle_max, 6 angle_step, 7 range_min, 8 range_max, 9 count, 14 ranges (packed double) |
//! | `Image` | 1 header, 2 width, 3 height, 4 step, 5 data, 6 pixel_format_type |

use crate::protowire;
pub use crate::protowire::{Value as Val, WireError as PbError, Writer as W};

fn bad(m: impl Into<String>) -> PbError {
    PbError(m.into())
}

/// The fields of a message ([`protowire::fields`]).
fn fields(b: &[u8]) -> protowire::Fields<'_> {
    protowire::fields(b)
}

/// A string field.
trait Text<'a> {
    fn str(self) -> Result<&'a str, PbError>;
}

impl<'a> Text<'a> for Val<'a> {
    fn str(self) -> Result<&'a str, PbError> {
        std::str::from_utf8(self.bytes()).map_err(|_| bad("a string field is not UTF-8"))
    }
}

/// gz-transport's discovery message types.
pub mod disc {
    pub const ADVERTISE: u64 = 1;
    pub const SUBSCRIBE: u64 = 2;
    pub const UNADVERTISE: u64 = 3;
    pub const HEARTBEAT: u64 = 4;
    pub const BYE: u64 = 5;
    pub const NEW_CONNECTION: u64 = 6;
    pub const END_CONNECTION: u64 = 7;
}

/// A topic's publisher as discovery tells it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Publisher {
    /// Fully qualified: `@/PARTITION@/TOPIC`.
    pub topic: String,
    pub address: String,
    pub process_uuid: String,
    pub node_uuid: String,
    pub scope: u64,
    pub ctrl: String,
    pub msg_type: String,
}

/// One discovery message.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Discovery {
    pub version: u64,
    pub process_uuid: String,
    pub kind: u64,
    /// flags.relay
    pub relay: bool,
    /// SUBSCRIBE's topic.
    pub sub: Option<String>,
    pub publisher: Option<Publisher>,
}

impl Discovery {
    pub fn decode(b: &[u8]) -> Result<Discovery, PbError> {
        let mut d = Discovery::default();
        for f in fields(b) {
            match f? {
                (2, v) => d.version = v.u64(),
                (3, v) => d.process_uuid = v.str()?.into(),
                (4, v) => d.kind = v.u64(),
                (5, v) => {
                    for f in fields(v.bytes()) {
                        if let (1, v) = f? {
                            d.relay = v.u64() != 0;
                        }
                    }
                }
                (6, v) => {
                    for f in fields(v.bytes()) {
                        if let (1, v) = f? {
                            d.sub = Some(v.str()?.into());
                        }
                    }
                }
                (7, v) => {
                    let mut p = Publisher::default();
                    for f in fields(v.bytes()) {
                        match f? {
                            (1, v) => p.topic = v.str()?.into(),
                            (2, v) => p.address = v.str()?.into(),
                            (3, v) => p.process_uuid = v.str()?.into(),
                            (4, v) => p.node_uuid = v.str()?.into(),
                            (5, v) => p.scope = v.u64(),
                            (6, v) => {
                                for f in fields(v.bytes()) {
                                    match f? {
                                        (1, v) => p.ctrl = v.str()?.into(),
                                        (2, v) => p.msg_type = v.str()?.into(),
                                        _ => {}
                                    }
                                }
                            }
                            _ => {}
                        }
                    }
                    d.publisher = Some(p);
                }
                _ => {}
            }
        }
        Ok(d)
    }

    pub fn encode(&self, out: &mut Vec<u8>) {
        let mut w = W(out);
        w.uint(2, self.version);
        w.bytes(3, self.process_uuid.as_bytes());
        w.uint(4, self.kind);
        if let Some(t) = &self.sub {
            w.message(6, |w| w.bytes(1, t.as_bytes()));
        }
        if let Some(p) = &self.publisher {
            w.message(7, |w| {
                w.bytes(1, p.topic.as_bytes());
                w.bytes(2, p.address.as_bytes());
                w.bytes(3, p.process_uuid.as_bytes());
                w.bytes(4, p.node_uuid.as_bytes());
                w.uint(5, p.scope);
                w.message(6, |w| {
                    w.bytes(1, p.ctrl.as_bytes());
                    w.bytes(2, p.msg_type.as_bytes());
                    w.uint(4, u64::MAX);
                });
            });
        }
    }
}

/// A `Header`'s stamp in seconds (the simulation time for gz-sim's topics).
fn stamp(b: &[u8]) -> Result<Option<f64>, PbError> {
    for f in fields(b) {
        if let (1, t) = f? {
            let (mut s, mut ns) = (0i64, 0i32);
            for f in fields(t.bytes()) {
                match f? {
                    (1, v) => s = v.u64() as i64,
                    (2, v) => ns = v.u64() as i32,
                    _ => {}
                }
            }
            return Ok(Some(s as f64 + ns as f64 * 1e-9));
        }
    }
    Ok(None)
}

fn vec3(b: &[u8], first: u64) -> Result<[f64; 4], PbError> {
    let mut v = [0.0; 4];
    for f in fields(b) {
        let (k, x) = f?;
        if (first..first + 4).contains(&k) {
            v[(k - first) as usize] = x.f64();
        }
    }
    Ok(v)
}

/// An `Odometry`: pose x, y (m), yaw (rad), and the header's time (s).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Odometry {
    pub x: f64,
    pub y: f64,
    pub yaw: f64,
    pub time: Option<f64>,
}

pub fn decode_odometry(b: &[u8]) -> Result<Odometry, PbError> {
    let mut o = Odometry::default();
    for f in fields(b) {
        match f? {
            (1, v) => o.time = stamp(v.bytes())?,
            (2, v) => {
                let mut q = [0.0, 0.0, 0.0, 1.0];
                for f in fields(v.bytes()) {
                    match f? {
                        (4, p) => {
                            let p = vec3(p.bytes(), 2)?;
                            (o.x, o.y) = (p[0], p[1]);
                        }
                        (5, r) => q = vec3(r.bytes(), 2)?,
                        _ => {}
                    }
                }
                let [x, y, z, w] = q;
                o.yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
            }
            _ => {}
        }
    }
    Ok(o)
}

/// An `IMU` (imu.proto): orientation quaternion x y z w, angular velocity (rad/s)
/// and linear acceleration (m/s²) in the sensor's frame, and the header's time (s).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ImuReading {
    pub q: [f64; 4],
    pub w: [f64; 3],
    pub a: [f64; 3],
    pub time: Option<f64>,
}

pub fn decode_imu(b: &[u8]) -> Result<ImuReading, PbError> {
    let mut m = ImuReading {
        q: [0.0, 0.0, 0.0, 1.0],
        ..ImuReading::default()
    };
    let xyz = |v: [f64; 4]| [v[0], v[1], v[2]];
    for f in fields(b) {
        match f? {
            (1, v) => m.time = stamp(v.bytes())?,
            (3, v) => m.q = vec3(v.bytes(), 2)?,
            (4, v) => m.w = xyz(vec3(v.bytes(), 2)?),
            (5, v) => m.a = xyz(vec3(v.bytes(), 2)?),
            _ => {}
        }
    }
    Ok(m)
}

/// A `Twist` of a planar base: linear x (m/s) and angular z (rad/s).
pub fn encode_twist(v: f64, w: f64, out: &mut Vec<u8>) {
    out.clear();
    let mut m = W(out);
    m.message(2, |m| m.double(2, v));
    m.message(3, |m| m.double(4, w));
}

/// A `Twist`'s linear x and angular z.
pub fn decode_twist(b: &[u8]) -> Result<(f64, f64), PbError> {
    let (mut v, mut w) = (0.0, 0.0);
    for f in fields(b) {
        match f? {
            (2, l) => v = vec3(l.bytes(), 2)?[0],
            (3, a) => w = vec3(a.bytes(), 2)?[2],
            _ => {}
        }
    }
    Ok((v, w))
}

/// A `Double` (JointPositionController's cmd_pos): field 2 data.
pub fn encode_double(v: f64, out: &mut Vec<u8>) {
    out.clear();
    W(out).double(2, v);
}

/// Joint names and positions (rad).
pub type Joints = Vec<(String, f64)>;

/// A `Model`'s joints (JointStatePublisher): (name, axis1.position rad), at most 256,
/// and the header's time. `Model`: 1 header, 6 joint; `Joint`: 2 name, 10 axis1;
/// `Axis`: 10 position.
pub fn decode_joints(b: &[u8]) -> Result<(Option<f64>, Joints), PbError> {
    let (mut time, mut out) = (None, Vec::new());
    for f in fields(b) {
        match f? {
            (1, v) => time = stamp(v.bytes())?,
            (6, j) if out.len() < 256 => {
                let (mut name, mut pos) = (String::new(), 0.0);
                for f in fields(j.bytes()) {
                    match f? {
                        (2, v) => name = v.str()?.into(),
                        (10, a) => {
                            for f in fields(a.bytes()) {
                                if let (10, p) = f? {
                                    pos = p.f64();
                                }
                            }
                        }
                        _ => {}
                    }
                }
                out.push((name, pos));
            }
            _ => {}
        }
    }
    Ok((time, out))
}

/// A `LaserScan`'s geometry; the ranges stay in the message (packed doubles).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Scan<'a> {
    pub angle_min: f64,
    pub angle_step: f64,
    pub range_max: f64,
    pub count: usize,
    /// Packed little-endian doubles, metres.
    pub ranges: &'a [u8],
    pub time: Option<f64>,
}

impl Scan<'_> {
    /// Range `k` in metres (the caller checks `k < n()`).
    pub fn range(&self, k: usize) -> f64 {
        let b = &self.ranges[k * 8..k * 8 + 8];
        f64::from_le_bytes(b.try_into().expect("8"))
    }
    pub fn n(&self) -> usize {
        self.ranges.len() / 8
    }
}

pub fn decode_scan(b: &[u8]) -> Result<Scan<'_>, PbError> {
    let mut s = Scan::default();
    for f in fields(b) {
        match f? {
            (1, v) => s.time = stamp(v.bytes())?,
            (4, v) => s.angle_min = v.f64(),
            (6, v) => s.angle_step = v.f64(),
            (8, v) => s.range_max = v.f64(),
            (9, v) => s.count = v.u64() as usize,
            (14, Val::Len(r)) => {
                if r.len() % 8 != 0 {
                    return Err(bad("LaserScan.ranges is not whole doubles"));
                }
                s.ranges = r;
            }
            _ => {}
        }
    }
    Ok(s)
}

/// An `Image`: size, row step, pixel format and the pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Frame<'a> {
    pub width: u32,
    pub height: u32,
    pub step: u32,
    pub format: u64,
    pub data: &'a [u8],
    pub time: Option<f64>,
}

/// gz-msgs' `PixelFormatType` values the driver reads.
pub mod pixel {
    pub const L_INT8: u64 = 1;
    pub const RGB_INT8: u64 = 3;
    pub const RGBA_INT8: u64 = 4;
    pub const BGRA_INT8: u64 = 5;
    pub const BGR_INT8: u64 = 8;
}

/// An image dimension: a uint32 in gz-msgs (a larger varint is refused, not truncated).
fn dim(v: Val, what: &str) -> Result<u32, PbError> {
    u32::try_from(v.u64()).map_err(|_| bad(format!("Image.{what} is {}", v.u64())))
}

pub fn decode_image(b: &[u8]) -> Result<Frame<'_>, PbError> {
    let mut i = Frame::default();
    for f in fields(b) {
        match f? {
            (1, v) => i.time = stamp(v.bytes())?,
            (2, v) => i.width = dim(v, "width")?,
            (3, v) => i.height = dim(v, "height")?,
            (4, v) => i.step = dim(v, "step")?,
            (5, v) => i.data = v.bytes(),
            (6, v) => i.format = v.u64(),
            _ => {}
        }
    }
    Ok(i)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn discovery_round_trips_and_garbage_is_an_error() {
        let d = Discovery {
            version: 10,
            process_uuid: "p".into(),
            kind: disc::ADVERTISE,
            relay: false,
            sub: None,
            publisher: Some(Publisher {
                topic: "@/h:u@/model/r/cmd_vel".into(),
                address: "tcp://127.0.0.1:5".into(),
                process_uuid: "p".into(),
                node_uuid: "n".into(),
                scope: 2,
                ctrl: "unused".into(),
                msg_type: "ignition.msgs.Twist".into(),
            }),
        };
        let mut b = Vec::new();
        d.encode(&mut b);
        assert_eq!(Discovery::decode(&b).unwrap(), d);
        assert!(Discovery::decode(&[0x3a, 0xff, 0xff, 0x03]).is_err());
        assert!(Discovery::decode(&[0xff; 12]).is_err());
    }

    #[test]
    fn twist_round_trips() {
        let mut b = Vec::new();
        encode_twist(0.25, -0.5, &mut b);
        assert_eq!(decode_twist(&b).unwrap(), (0.25, -0.5));
    }
}
