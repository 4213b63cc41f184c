//! Foxglove's protobuf messages for images and laser scans, written and read on the
//! one protobuf wire ([`crate::protowire`]; the messages are small and fixed).
//!
//! The MCAP schema data (`protobuf` schema encoding) is Foxglove's own
//! `FileDescriptorSet` of each message, from the `foxglove-schemas-protobuf` package
//! (`assets/foxglove/`, see its README). Field numbers below are those descriptors':
//!
//! | message | fields |
//! |---|---|
//! | `foxglove.RawImage` | 1 timestamp, 7 frame_id, 2 width (fixed32), 3 height (fixed32), 4 encoding, 5 step (fixed32), 6 data (bytes) |
//! | `foxglove.CompressedImage` | 1 timestamp, 4 frame_id, 2 data (bytes), 3 format |
//! | `foxglove.LaserScan` | 1 timestamp, 2 frame_id, 3 pose, 4 start_angle, 5 end_angle (double), 6 ranges, 7 intensities (packed double) |
//! | `google.protobuf.Timestamp` | 1 seconds (int64), 2 nanos (int32) |
//! | `foxglove.Pose` | 1 position (`Vector3`: 1 x, 2 y, 3 z), 2 orientation (`Quaternion`: 1 x, 2 y, 3 z, 4 w), doubles |

use super::{FormatError, Recorded, bad};
use crate::{
    interfaces::{Image, Laser, Mount},
    protowire::{self, Value, Writer},
};

/// `foxglove.RawImage`'s FileDescriptorSet (Foxglove's, see `assets/foxglove`).
pub const RAW_IMAGE: &[u8] = include_bytes!("../../assets/foxglove/RawImage.fdset");
/// `foxglove.CompressedImage`'s FileDescriptorSet.
pub const COMPRESSED_IMAGE: &[u8] = include_bytes!("../../assets/foxglove/CompressedImage.fdset");
/// `foxglove.LaserScan`'s FileDescriptorSet.
pub const LASER_SCAN: &[u8] = include_bytes!("../../assets/foxglove/LaserScan.fdset");

/// A `google.protobuf.Timestamp` of `ns` nanoseconds since the Unix epoch.
fn write_timestamp(w: &mut Writer, field: u64, ns: u64) {
    w.message(field, |w| {
        w.uint(1, ns / 1_000_000_000);
        w.uint(2, ns % 1_000_000_000);
    });
}

/// Encodes a `foxglove.RawImage` (`bgr8`, the bytes as they are) into `out`.
pub fn raw_image(frame_id: &str, ns: u64, img: &Image, out: &mut Vec<u8>) {
    out.reserve(img.data.len() + 64 + frame_id.len());
    raw_image_head(frame_id, ns, img, out);
    out.extend_from_slice(&img.data);
}

/// [`raw_image`] but the pixels, which come last: the message is `out` followed by
/// `img.data`, so a writer can take the pixels from where they are.
pub fn raw_image_head(frame_id: &str, ns: u64, img: &Image, out: &mut Vec<u8>) {
    out.clear();
    let mut w = Writer(out);
    write_timestamp(&mut w, 1, ns);
    w.bytes(7, frame_id.as_bytes());
    w.fixed32(2, img.width);
    w.fixed32(3, img.height);
    w.bytes(4, b"bgr8");
    w.fixed32(5, img.width * 3);
    w.tag(6, protowire::LEN);
    w.varint(img.data.len() as u64);
}

/// Encodes a `foxglove.CompressedImage` (`format`, e.g. `jpeg`) into `out`.
pub fn compressed_image(frame_id: &str, ns: u64, format: &str, data: &[u8], out: &mut Vec<u8>) {
    out.clear();
    out.reserve(data.len() + 64 + frame_id.len());
    let mut w = Writer(out);
    write_timestamp(&mut w, 1, ns);
    w.bytes(4, frame_id.as_bytes());
    w.bytes(2, data);
    w.bytes(3, format.as_bytes());
}

/// The count of angle steps that `end_angle` spans: readings − 1, at least 1 (so
/// a scan of 0 or 1 readings still carries its resolution; Foxglove draws no angle
/// from `end_angle` then).
fn steps(n: usize) -> f64 {
    n.saturating_sub(1).max(1) as f64
}

/// Encodes a `foxglove.LaserScan` into `out`: ranges in m (the mm readings / 1000,
/// exact in a double), the pose the laser's mount on the robot (m, a yaw
/// quaternion), `start_angle` the scan's first angle and `end_angle` its last
/// (start + (n−1)/resolution deg, in rad), from which the resolution comes back
/// exactly (a resolution ≤ 0 is written as `end_angle` = `start_angle` and reads
/// back as 0). The one LaserScan encoder: the recorder, replay and Foxglove use it.
pub fn laser_scan(frame_id: &str, ns: u64, l: &Laser, out: &mut Vec<u8>) {
    out.clear();
    let mut w = Writer(out);
    write_timestamp(&mut w, 1, ns);
    w.bytes(2, frame_id.as_bytes());
    let half_yaw = (l.mount.yaw as f64).to_radians() / 2.0;
    w.message(3, |w| {
        w.message(1, |w| {
            w.double(1, l.mount.x as f64 / 1000.0);
            w.double(2, l.mount.y as f64 / 1000.0);
        });
        w.message(2, |w| {
            w.double(3, half_yaw.sin());
            w.double(4, half_yaw.cos());
        });
    });
    let start = (l.start as f64).to_radians();
    let end = if l.resolution > 0.0 && l.resolution.is_finite() {
        start + (steps(l.readings.len()) / l.resolution as f64).to_radians()
    } else {
        start
    };
    w.double(4, start);
    w.double(5, end);
    let ranges = l.readings.iter().map(|r| *r as f64 / 1000.0);
    w.packed_doubles(6, l.readings.len(), ranges);
}

/// The fields of a protobuf message, its errors naming `topic`.
fn each<'a>(
    topic: &'a str,
    data: &'a [u8],
) -> impl Iterator<Item = Result<(u64, Value<'a>), FormatError>> + 'a {
    protowire::fields(data).map(move |r| r.map_err(|e| bad(topic, e.0)))
}

fn wrong(topic: &str, message: &str, field: u64) -> FormatError {
    bad(
        topic,
        format!("{message} field {field} has the wrong protobuf wire type"),
    )
}

fn timestamp(topic: &str, data: &[u8]) -> Result<u64, FormatError> {
    let (mut sec, mut nsec) = (0u64, 0u64);
    for f in each(topic, data) {
        match f? {
            (1, Value::Varint(v)) => sec = v,
            (2, Value::Varint(v)) => nsec = v,
            (n @ (1 | 2), _) => return Err(wrong(topic, "Timestamp", n)),
            _ => {}
        }
    }
    // A negative int64 (before 1970) is not a time jderobot records.
    if sec > i64::MAX as u64 || nsec >= 1_000_000_000 {
        return Err(bad(topic, "a Timestamp out of range"));
    }
    Ok(sec.saturating_mul(1_000_000_000).saturating_add(nsec))
}

fn text<'a>(topic: &str, what: &str, b: &'a [u8]) -> Result<&'a str, FormatError> {
    std::str::from_utf8(b).map_err(|_| bad(topic, format!("`{what}` is not UTF-8")))
}

/// Decodes a `foxglove.RawImage` (bgr8) or `foxglove.CompressedImage` (jpeg, png;
/// back to BGR) message: (time ns, image). `log_time` stands for a missing timestamp.
pub fn decode_image(
    topic: &str,
    compressed: bool,
    data: &[u8],
    log_time: u64,
) -> Result<(u64, Recorded), FormatError> {
    let mut time = log_time;
    if compressed {
        let (mut bytes, mut format): (&[u8], &str) = (&[], "");
        for f in each(topic, data) {
            match f? {
                (1, Value::Len(b)) => time = timestamp(topic, b)?,
                (2, Value::Len(b)) => bytes = b,
                (3, Value::Len(b)) => format = text(topic, "format", b)?,
                (n @ (1..=4), Value::Varint(_) | Value::I32(_) | Value::I64(_)) => {
                    return Err(wrong(topic, "CompressedImage", n));
                }
                _ => {}
            }
        }
        return Ok((time, super::decode_compressed(topic, format, bytes)?));
    }
    let (mut width, mut height, mut encoding, mut pixels): (u32, u32, &str, &[u8]) =
        (0, 0, "", &[]);
    for f in each(topic, data) {
        match f? {
            (1, Value::Len(b)) => time = timestamp(topic, b)?,
            (2, Value::I32(b)) => width = u32::from_le_bytes(b),
            (3, Value::I32(b)) => height = u32::from_le_bytes(b),
            (4, Value::Len(b)) => encoding = text(topic, "encoding", b)?,
            (5, Value::I32(_)) => {}
            (6, Value::Len(b)) => pixels = b,
            (n @ 1..=7, _) if n != 7 => return Err(wrong(topic, "RawImage", n)),
            _ => {}
        }
    }
    if encoding != "bgr8" {
        return Err(bad(
            topic,
            format!("image encoding `{encoding}`; jderobot reads bgr8"),
        ));
    }
    // u64 and checked: a damaged width and height must not overflow.
    let need = (width as u64 * height as u64).saturating_mul(3);
    if pixels.len() as u64 != need {
        return Err(bad(
            topic,
            format!(
                "{width}x{height} bgr8 needs {need} bytes, the data has {}",
                pixels.len()
            ),
        ));
    }
    Ok((
        time,
        Recorded::Image(Image {
            width,
            height,
            data: pixels.to_vec(),
        }),
    ))
}

/// Decodes a `foxglove.LaserScan`: (time ns, the jderobot laser: readings in mm,
/// resolution in readings/deg from the angles).
pub fn decode_laser(
    topic: &str,
    data: &[u8],
    log_time: u64,
) -> Result<(u64, Recorded), FormatError> {
    let mut time = log_time;
    let (mut start, mut end) = (0.0f64, 0.0f64);
    let mut mount = Mount::default();
    let mut readings = Vec::new();
    for f in each(topic, data) {
        match f? {
            (1, Value::Len(b)) => time = timestamp(topic, b)?,
            (3, Value::Len(b)) => mount = pose(topic, b)?,
            (4, Value::I64(b)) => start = f64::from_le_bytes(b),
            (5, Value::I64(b)) => end = f64::from_le_bytes(b),
            (6, Value::Len(b)) => {
                if b.len() % 8 != 0 {
                    return Err(bad(
                        topic,
                        "packed `ranges` is not a whole number of doubles",
                    ));
                }
                readings.reserve(b.len() / 8);
                for c in b.chunks_exact(8) {
                    readings.push(mm(f64::from_le_bytes(c.try_into().expect("8 bytes"))));
                }
            }
            // Unpacked is valid protobuf too.
            (6, Value::I64(b)) => readings.push(mm(f64::from_le_bytes(b))),
            (n @ (1 | 4 | 5), _) => return Err(wrong(topic, "LaserScan", n)),
            _ => {}
        }
    }
    let span = (end - start).to_degrees();
    let resolution = if span > 0.0 && span.is_finite() {
        (steps(readings.len()) / span) as f32
    } else {
        0.0
    };
    let max_range = readings.iter().copied().max().unwrap_or(0) as f32;
    Ok((
        time,
        Recorded::Laser(Laser {
            readings,
            resolution,
            start: start.to_degrees() as f32,
            // foxglove.LaserScan has no range limits: 4.3's, or beyond the farthest reading.
            max_range: max_range.max(crate::interfaces::JDE43_LASER_MAX_RANGE),
            mount,
            ..Laser::default()
        }),
    ))
}

/// A `foxglove.Pose` as a mount on the robot: position in mm, the yaw of the
/// orientation quaternion in degrees.
fn pose(topic: &str, data: &[u8]) -> Result<Mount, FormatError> {
    let (mut p, mut q) = ([0.0f64; 3], [0.0, 0.0, 0.0, 1.0f64]);
    for f in each(topic, data) {
        match f? {
            (1, Value::Len(b)) => doubles(topic, "Vector3", b, &mut p)?,
            (2, Value::Len(b)) => doubles(topic, "Quaternion", b, &mut q)?,
            (n @ (1 | 2), _) => return Err(wrong(topic, "Pose", n)),
            _ => {}
        }
    }
    let yaw = (2.0 * (q[3] * q[2] + q[0] * q[1])).atan2(1.0 - 2.0 * (q[1] * q[1] + q[2] * q[2]));
    Ok(Mount {
        x: (p[0] * 1000.0) as f32,
        y: (p[1] * 1000.0) as f32,
        yaw: yaw.to_degrees() as f32,
    })
}

/// The double fields 1..=N of a message into `out`.
fn doubles(topic: &str, message: &str, data: &[u8], out: &mut [f64]) -> Result<(), FormatError> {
    for f in each(topic, data) {
        match f? {
            (n, Value::I64(b)) if (1..=out.len() as u64).contains(&n) => {
                out[n as usize - 1] = f64::from_le_bytes(b)
            }
            (n, _) if (1..=out.len() as u64).contains(&n) => return Err(wrong(topic, message, n)),
            _ => {}
        }
    }
    Ok(())
}

/// A range in m as jderobot's whole mm (out-of-range values saturate, NaN is 0).
fn mm(m: f64) -> i32 {
    (m * 1000.0).round() as i32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn laser_resolution_and_readings_come_back_exactly() {
        let mut out = Vec::new();
        for res in [
            1.0f32,
            2.0,
            4.0,
            0.5,
            0.25,
            1.0 / 3.0,
            0.352_112_7,
            2.844_444_4,
            10.0,
            100.0,
        ] {
            for (n, start, mount) in [
                (0usize, -90.0, Mount::default()),
                (1, -90.0, Mount::PIONEER_LASER),
                (2, -180.0, Mount::default()),
                (3, -45.0, Mount::default()),
                (90, -45.0, Mount::PIONEER_LASER),
                (181, -90.0, Mount::PIONEER_LASER),
                (361, -180.0, Mount::default()),
                (
                    683,
                    -120.0,
                    Mount {
                        x: 100.0,
                        y: -50.0,
                        yaw: 90.0,
                    },
                ),
                (
                    1081,
                    -135.0,
                    Mount {
                        x: -20.0,
                        y: 0.0,
                        yaw: -30.0,
                    },
                ),
            ] {
                let l = Laser {
                    readings: (0..n as i32)
                        .map(|i| i * 37 - 5 + i32::MAX / 2 * (i % 2))
                        .map(|r| r.max(0))
                        .collect(),
                    resolution: res,
                    start,
                    mount,
                    ..Laser::default()
                };
                laser_scan("laser", 5, &l, &mut out);
                let (t, back) = decode_laser("laser", &out, 0).unwrap();
                assert_eq!(t, 5);
                let Recorded::Laser(back) = back else {
                    panic!("not a laser")
                };
                let what = format!("resolution {res}, {n} readings");
                assert_eq!(back.readings, l.readings, "{what}");
                assert_eq!(back.resolution, l.resolution, "{what}");
                assert!((back.start - l.start).abs() < 1e-4, "{what}");
                assert!((back.mount.x - l.mount.x).abs() < 1e-3, "{what}");
                assert!((back.mount.y - l.mount.y).abs() < 1e-3, "{what}");
                assert!((back.mount.yaw - l.mount.yaw).abs() < 1e-3, "{what}");
            }
        }
        let l = Laser {
            readings: vec![1, 2],
            resolution: 0.0,
            ..Laser::default()
        };
        laser_scan("laser", 5, &l, &mut out);
        assert_eq!(
            decode_laser("laser", &out, 0).unwrap().1,
            Recorded::Laser(l)
        );
    }

    #[test]
    fn garbage_is_a_clear_error() {
        for data in [
            &[0x0au8, 0x05, 1][..],
            &[0xff; 11],
            &[0x0b],
            &[0x22, 0x02, 0xff, 0xfe],
        ] {
            let e = decode_image("cam", false, data, 0).unwrap_err().to_string();
            assert!(
                e.contains("cam") && e.contains("protobuf") || e.contains("UTF-8"),
                "{e}"
            );
        }
        let e = decode_laser("laser", &[0x32, 0x03, 1, 2, 3], 0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("doubles"), "{e}");
    }
}
