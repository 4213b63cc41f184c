//! What travels on Zenoh: each interface's payload (the `jderobot` format, one
//! fixed little-endian layout per kind, documented in `docs/zenoh.md`), the
//! attachment (the interface's clock and wall time), and the `ros2` format (CDR
//! messages on rmw_zenoh's key expressions, with rmw_zenoh's attachment).

use std::{
    sync::Arc,
    time::{Duration, SystemTime, UNIX_EPOCH},
};

use zenoh::bytes::ZBytes;

use crate::{
    interfaces::{
        Bumpers, Encoders, Image, Imu, Kind, Laser, Motors, PtEncoders, PtMotors, Sample, Sonars,
        ZoomEncoders, ZoomMotors,
    },
    mcapfmt::{self, ros2::Ros2},
};

/// How values are written on the wire (`format` line).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// The layouts of `docs/zenoh.md`, on `jderobot/<robot>/<interface>`.
    Jderobot,
    /// CDR (sensor_msgs/LaserScan, Image, Imu, nav_msgs/Odometry, geometry_msgs/Twist)
    /// on rmw_zenoh's keys; kinds without a ROS message stay in `Jderobot`.
    Ros2,
}

/// The Zenoh encoding of `jderobot` payloads: `jderobot/<kind>`.
pub fn encoding(kind: Kind) -> String {
    format!("jderobot/{kind}")
}

/// The attachment of a `jderobot` sample: clock (u64) and wall time (u64 ns since
/// the Unix epoch), little-endian.
pub fn attachment(clock: u64, time: SystemTime) -> [u8; 16] {
    let mut a = [0u8; 16];
    a[..8].copy_from_slice(&clock.to_le_bytes());
    a[8..].copy_from_slice(&mcapfmt::nanos(time).to_le_bytes());
    a
}

/// Reads a `jderobot` attachment: (clock, wall time).
pub fn read_attachment(a: &[u8]) -> Option<(u64, SystemTime)> {
    let a: &[u8; 16] = a.try_into().ok()?;
    let clock = u64::from_le_bytes(a[..8].try_into().ok()?);
    let ns = u64::from_le_bytes(a[8..].try_into().ok()?);
    Some((clock, UNIX_EPOCH + Duration::from_nanos(ns)))
}

/// rmw_zenoh's attachment (Jazzy): sequence number (i64), source timestamp (i64
/// ns), source GID (16 bytes), in zenoh-ext's serialization (little-endian
/// integers, a fixed array without length).
pub fn rmw_attachment(sequence: u64, time: SystemTime, gid: &[u8; 16]) -> [u8; 32] {
    let mut a = [0u8; 32];
    a[..8].copy_from_slice(&(sequence as i64).to_le_bytes());
    a[8..16].copy_from_slice(&(mcapfmt::nanos(time) as i64).to_le_bytes());
    a[16..].copy_from_slice(gid);
    a
}

/// Reads rmw_zenoh's attachment: (sequence number, source time).
pub fn read_rmw_attachment(a: &[u8]) -> Option<(u64, SystemTime)> {
    let a: &[u8; 32] = a.try_into().ok()?;
    let seq = i64::from_le_bytes(a[..8].try_into().ok()?);
    let ns = i64::from_le_bytes(a[8..16].try_into().ok()?);
    Some((
        seq.max(0) as u64,
        UNIX_EPOCH + Duration::from_nanos(ns.max(0) as u64),
    ))
}

/// The ROS 2 type of a kind in the `ros2` format: (DDS type name as rmw_zenoh
/// writes it in keys, RIHS01 type hash of ROS 2 Jazzy), from the kind's
/// [`Ros2`] message.
pub fn ros2_type(kind: Kind) -> Option<(&'static str, &'static str)> {
    mcapfmt::ros2::message(kind).map(|m| (m.dds, m.hash))
}

/// The default key of interface `name` of robot `robot`: `jderobot/<robot>/<name>`
/// (`jderobot` format), or rmw_zenoh's `<domain>/<robot>/<name>/<type>/<hash>`
/// (the ROS 2 topic `/<robot>/<name>`) in the `ros2` format for kinds with a ROS
/// message. A suffixed name `laser.robot2` keeps its dot (a valid key chunk).
pub fn default_key(format: Format, domain: u32, robot: &str, name: &str, kind: Kind) -> String {
    match (format, ros2_type(kind)) {
        (Format::Ros2, Some((ty, hash))) => format!("{domain}/{robot}/{name}/{ty}/{hash}"),
        _ => format!("jderobot/{robot}/{name}"),
    }
}

/// Why a payload was not a value.
pub type WireError = String;

/// What a received payload does to the interface's recycled value.
pub type Fill<T> = Box<dyn FnOnce(&mut T)>;

/// A value that travels on Zenoh.
pub trait Wire: Ros2 + Sized {
    /// Appends the `jderobot` layout of the value.
    fn put(&self, out: &mut Vec<u8>);
    /// Reads the `jderobot` layout (the whole payload).
    fn take(b: &[u8]) -> Result<Self, WireError>;
    /// The `jderobot` payload of a sample.
    fn payload(s: &Arc<Sample<Self>>) -> ZBytes {
        let mut b = Vec::new();
        s.value.put(&mut b);
        b.into()
    }
    /// Reads a payload as what it does to the interface's recycled value.
    fn fill_from(z: &ZBytes) -> Result<Fill<Self>, WireError> {
        let v = Self::take(&z.to_bytes())?;
        Ok(Box::new(move |d: &mut Self| *d = v))
    }
    /// JPEG bytes of the value (images, `images jpeg`); `None` for other kinds.
    fn to_jpeg(&self, _quality: u8) -> Option<Vec<u8>> {
        None
    }
    /// A value from a JPEG payload (images only).
    fn from_jpeg(_b: &[u8]) -> Result<Self, WireError> {
        Err(format!("a JPEG image on a {} key", Self::KIND))
    }
}

/// A little-endian reader that fails with what was short.
struct Bytes<'a>(&'a [u8]);

impl<'a> Bytes<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], WireError> {
        if self.0.len() < n {
            return Err(format!(
                "payload too short: {what} needs {n} bytes, {} left",
                self.0.len()
            ));
        }
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        Ok(a)
    }
    fn u32(&mut self, what: &str) -> Result<u32, WireError> {
        Ok(u32::from_le_bytes(
            self.take(4, what)?.try_into().expect("4"),
        ))
    }
    fn f32(&mut self, what: &str) -> Result<f32, WireError> {
        Ok(f32::from_le_bytes(
            self.take(4, what)?.try_into().expect("4"),
        ))
    }
    /// A u32 count of `size`-byte items that must fill the rest exactly.
    fn count(&mut self, size: usize, what: &str) -> Result<usize, WireError> {
        let n = self.u32(&format!("the {what} count"))? as usize;
        if n.checked_mul(size) != Some(self.0.len()) {
            return Err(format!(
                "{n} {what} announced but {} bytes follow ({} expected)",
                self.0.len(),
                n.saturating_mul(size)
            ));
        }
        Ok(n)
    }
    fn end(&self) -> Result<(), WireError> {
        if self.0.is_empty() {
            Ok(())
        } else {
            Err(format!("{} bytes too many", self.0.len()))
        }
    }
}

/// Values made of f32 fields only: the fields in order.
macro_rules! floats {
    ($t:ident: $($f:ident),+) => {
        impl Wire for $t {
            fn put(&self, out: &mut Vec<u8>) {
                $(out.extend_from_slice(&self.$f.to_le_bytes());)+
            }
            fn take(b: &[u8]) -> Result<Self, WireError> {
                let mut r = Bytes(b);
                let v = Self { $($f: r.f32(stringify!($f))?,)+ };
                r.end()?;
                Ok(v)
            }
        }
    };
}

floats!(Encoders: x, y, theta, cos, sin);
floats!(Motors: v, w);
floats!(PtEncoders: pan_angle, tilt_angle);
floats!(PtMotors: longitude, latitude, longitude_speed, latitude_speed, max_longitude,
    min_longitude, max_latitude, min_latitude, max_longitude_speed, max_latitude_speed);
floats!(ZoomEncoders: zoom_position);
floats!(ZoomMotors: zoom, zoom_speed, max_zoom, min_zoom, max_zoom_speed);
floats!(Imu: qx, qy, qz, qw, wx, wy, wz, ax, ay, az);

/// The width and height at the start of an image payload; the size they give
/// must fit in memory.
fn image_size(b: &[u8]) -> Result<(u32, u32), WireError> {
    let mut r = Bytes(b);
    let width = r.u32("width")?;
    let height = r.u32("height")?;
    (width as usize)
        .checked_mul(height as usize)
        .and_then(|p| p.checked_mul(3))
        .filter(|n| *n <= 1 << 30)
        .ok_or_else(|| format!("a {width}x{height} image is too large"))?;
    Ok((width, height))
}

/// An image's pixels shared with its sample, so a frame goes to Zenoh uncopied.
struct Pixels(Arc<Sample<Image>>);

impl AsRef<[u8]> for Pixels {
    fn as_ref(&self) -> &[u8] {
        &self.0.data
    }
}

impl Wire for Image {
    /// The width and height, then the pixels themselves (not copied).
    fn payload(s: &Arc<Sample<Self>>) -> ZBytes {
        let mut head = Vec::with_capacity(8);
        head.extend_from_slice(&s.width.to_le_bytes());
        head.extend_from_slice(&s.height.to_le_bytes());
        let mut w = ZBytes::writer();
        w.append(head.into());
        w.append(bytes::Bytes::from_owner(Pixels(s.clone())).into());
        w.finish()
    }
    /// One copy, from Zenoh's buffers into the interface's recycled frame.
    fn fill_from(z: &ZBytes) -> Result<Fill<Self>, WireError> {
        let mut head = [0u8; 8];
        let mut got = 0;
        for s in z.slices() {
            let n = (8 - got).min(s.len());
            head[got..got + n].copy_from_slice(&s[..n]);
            got += n;
            if got == 8 {
                break;
            }
        }
        let (width, height) = image_size(&head[..got])?;
        let n = width as usize * height as usize * 3;
        if z.len() != 8 + n {
            return Err(format!(
                "a {width}x{height} BGR image needs {n} bytes, {} follow",
                z.len().saturating_sub(8)
            ));
        }
        let z = z.clone();
        Ok(Box::new(move |img: &mut Image| {
            img.width = width;
            img.height = height;
            img.data.clear();
            img.data.reserve(n);
            let mut skip = 8;
            for s in z.slices() {
                let k = skip.min(s.len());
                img.data.extend_from_slice(&s[k..]);
                skip -= k;
            }
        }))
    }
    fn put(&self, out: &mut Vec<u8>) {
        out.reserve(8 + self.data.len());
        out.extend_from_slice(&self.width.to_le_bytes());
        out.extend_from_slice(&self.height.to_le_bytes());
        out.extend_from_slice(&self.data);
    }
    fn take(b: &[u8]) -> Result<Self, WireError> {
        let (width, height) = image_size(b)?;
        let mut r = Bytes(&b[8..]);
        let n = width as usize * height as usize * 3;
        if r.0.len() != n {
            return Err(format!(
                "a {width}x{height} BGR image needs {n} bytes, {} follow",
                r.0.len()
            ));
        }
        let data = r.take(n, "pixels")?.to_vec();
        Ok(Image {
            width,
            height,
            data,
        })
    }
    fn to_jpeg(&self, quality: u8) -> Option<Vec<u8>> {
        mcapfmt::jpeg(self, quality)
    }
    fn from_jpeg(b: &[u8]) -> Result<Self, WireError> {
        mcapfmt::decompress("jpeg", b)
    }
}

/// u32 n, f32 resolution, n × i32 mm, then the geometry: f32 start (deg), min_range,
/// max_range (mm), mount x, y (mm), yaw (deg). A sample without the geometry (an
/// older peer) reads as 4.3's.
impl Wire for Laser {
    fn put(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&(self.readings.len() as u32).to_le_bytes());
        out.extend_from_slice(&self.resolution.to_le_bytes());
        for r in &self.readings {
            out.extend_from_slice(&r.to_le_bytes());
        }
        for g in self.geometry() {
            out.extend_from_slice(&g.to_le_bytes());
        }
    }
    fn take(b: &[u8]) -> Result<Self, WireError> {
        let mut r = Bytes(b);
        let n = r.u32("the reading count")? as usize;
        let resolution = r.f32("resolution")?;
        let size = n.checked_mul(4);
        let geometry = match size {
            Some(s) if s == r.0.len() => None,
            Some(s) if s.checked_add(GEOMETRY_BYTES) == Some(r.0.len()) => {
                Some(r.0.split_off(s..).unwrap_or_default())
            }
            _ => {
                return Err(format!(
                    "{n} laser readings announced but {} bytes follow",
                    r.0.len()
                ));
            }
        };
        let readings =
            r.0.chunks_exact(4)
                .map(|c| i32::from_le_bytes(c.try_into().expect("4")))
                .collect();
        let mut l = Laser {
            readings,
            resolution,
            ..Laser::default()
        };
        if let Some(g) = geometry {
            let f: Vec<f32> = g
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("4")))
                .collect();
            l.set_geometry(f.try_into().expect("6 floats"));
        }
        Ok(l)
    }
}

/// The bytes of a laser sample's geometry trailer: 6 f32.
const GEOMETRY_BYTES: usize = 24;

impl Wire for Sonars {
    fn put(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&(self.us.len() as u32).to_le_bytes());
        for u in &self.us {
            out.extend_from_slice(&u.to_le_bytes());
        }
    }
    fn take(b: &[u8]) -> Result<Self, WireError> {
        let mut r = Bytes(b);
        r.count(4, "sonars")?;
        let us =
            r.0.chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("4")))
                .collect();
        Ok(Sonars { us })
    }
}

impl Wire for Bumpers {
    fn put(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&(self.bumpers.len() as u32).to_le_bytes());
        out.extend_from_slice(&self.bumpers);
    }
    fn take(b: &[u8]) -> Result<Self, WireError> {
        let mut r = Bytes(b);
        r.count(1, "bumpers")?;
        Ok(Bumpers {
            bumpers: r.0.to_vec(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip<T: Wire + PartialEq + std::fmt::Debug>(v: T) {
        let mut b = Vec::new();
        v.put(&mut b);
        assert_eq!(T::take(&b).unwrap(), v);
        // Any cut is an error, never a panic.
        for n in 0..b.len() {
            // A laser without its geometry trailer is an older peer's, and valid.
            let old_laser = T::KIND == Kind::Laser && n == b.len() - GEOMETRY_BYTES;
            assert!(
                T::take(&b[..n]).is_err()
                    || T::KIND == Kind::Bumpers
                    || T::KIND == Kind::Sonars
                    || old_laser
            );
        }
        b.push(0);
        assert!(T::take(&b).is_err(), "{}: a byte too many", T::KIND);
    }

    #[test]
    fn every_kind_round_trips_and_rejects_cut_payloads() {
        round_trip(Image {
            width: 2,
            height: 1,
            data: vec![1, 2, 3, 4, 5, 6],
        });
        round_trip(Laser {
            readings: vec![1, -2, 30000],
            resolution: 1.0,
            ..Laser::default()
        });
        round_trip(Sonars { us: vec![1.5, 2.5] });
        round_trip(Bumpers {
            bumpers: vec![0, 1],
        });
        round_trip(Encoders {
            x: 1.0,
            y: 2.0,
            theta: 3.0,
            cos: 0.5,
            sin: 0.25,
        });
        round_trip(Motors { v: 100.0, w: -5.0 });
        round_trip(PtMotors {
            longitude: 10.0,
            ..PtMotors::default()
        });
        round_trip(Imu {
            wz: 0.5,
            az: 9.81,
            ..Imu::default()
        });
    }

    #[test]
    fn the_kinds_with_a_ros_type_are_the_documented_ones() {
        let ros: Vec<Kind> = Kind::ALL
            .iter()
            .copied()
            .filter(|&k| ros2_type(k).is_some())
            .collect();
        assert_eq!(
            ros,
            [
                Kind::Image,
                Kind::Laser,
                Kind::Encoders,
                Kind::Motors,
                Kind::Imu
            ]
        );
    }

    #[test]
    fn layouts_are_the_documented_bytes() {
        let mut b = Vec::new();
        Motors { v: 1.0, w: 2.0 }.put(&mut b);
        assert_eq!(b, [0, 0, 0x80, 0x3f, 0, 0, 0, 0x40]);
        b.clear();
        Laser {
            readings: vec![1000],
            resolution: 1.0,
            ..Laser::default()
        }
        .put(&mut b);
        assert_eq!(&b[..12], [1, 0, 0, 0, 0, 0, 0x80, 0x3f, 0xe8, 3, 0, 0]);
        // The geometry: start −90°, 0 to 8000 mm, mounted at the centre.
        let floats: Vec<u8> = [-90.0f32, 0.0, 8000.0, 0.0, 0.0, 0.0]
            .iter()
            .flat_map(|f| f.to_le_bytes())
            .collect();
        assert_eq!(&b[12..], floats);
        assert_eq!(
            Laser::take(&b[..12]).unwrap(),
            Laser::jde43(vec![1000], 1.0)
        );
        let t = UNIX_EPOCH + Duration::from_nanos(5);
        assert_eq!(read_attachment(&attachment(7, t)), Some((7, t)));
        assert_eq!(
            read_rmw_attachment(&rmw_attachment(9, t, &[1; 16])),
            Some((9, t))
        );
    }

    #[test]
    fn garbage_is_an_error_naming_what_was_wrong() {
        let e = Image::take(&[2, 0, 0, 0, 2, 0, 0, 0, 1]).unwrap_err();
        assert!(e.contains("2x2") && e.contains("12 bytes"), "{e}");
        let e = Image::take(&[0xff; 8]).unwrap_err();
        assert!(!e.is_empty());
        let e = Laser::take(&[0xff, 0xff, 0xff, 0xff, 0, 0, 0x80, 0x3f]).unwrap_err();
        assert!(e.contains("laser readings"), "{e}");
    }
}
