//! The one protobuf wire (`src/protowire.rs`) against `prost`, in the same run:
//! a `foxglove.LaserScan` of 1081 readings (as the recorder and Foxglove write it,
//! `mcapfmt::protobuf::laser_scan`) and a 640x480 `foxglove.RawImage`, each
//! encoded and decoded by both. Medians of 7 alternated rounds; ratios
//! prost / ours (above 1: ours is faster). Prints figures, never fails on speed.
//! Run with `cargo bench --features recorder,gazebo --bench protowire`.

mod common;
use common::Case;

use std::{hint::black_box, time::Instant};

use jderobot::{
    interfaces::{Image, Laser, Mount},
    mcapfmt::protobuf,
    protowire::{self, Value},
};
use prost::Message;

#[derive(Clone, PartialEq, prost::Message)]
struct Timestamp {
    #[prost(int64, tag = "1")]
    seconds: i64,
    #[prost(int32, tag = "2")]
    nanos: i32,
}

#[derive(Clone, PartialEq, prost::Message)]
struct Vector3 {
    #[prost(double, tag = "1")]
    x: f64,
    #[prost(double, tag = "2")]
    y: f64,
    #[prost(double, tag = "3")]
    z: f64,
}

#[derive(Clone, PartialEq, prost::Message)]
struct Quaternion {
    #[prost(double, tag = "1")]
    x: f64,
    #[prost(double, tag = "2")]
    y: f64,
    #[prost(double, tag = "3")]
    z: f64,
    #[prost(double, tag = "4")]
    w: f64,
}

#[derive(Clone, PartialEq, prost::Message)]
struct Pose {
    #[prost(message, optional, tag = "1")]
    position: Option<Vector3>,
    #[prost(message, optional, tag = "2")]
    orientation: Option<Quaternion>,
}

/// `foxglove.LaserScan` (Foxglove's field numbers).
#[derive(Clone, PartialEq, prost::Message)]
struct LaserScan {
    #[prost(message, optional, tag = "1")]
    timestamp: Option<Timestamp>,
    #[prost(string, tag = "2")]
    frame_id: String,
    #[prost(message, optional, tag = "3")]
    pose: Option<Pose>,
    #[prost(double, tag = "4")]
    start_angle: f64,
    #[prost(double, tag = "5")]
    end_angle: f64,
    #[prost(double, repeated, tag = "6")]
    ranges: Vec<f64>,
}

/// `foxglove.RawImage`.
#[derive(Clone, PartialEq, prost::Message)]
struct RawImage {
    #[prost(message, optional, tag = "1")]
    timestamp: Option<Timestamp>,
    #[prost(fixed32, tag = "2")]
    width: u32,
    #[prost(fixed32, tag = "3")]
    height: u32,
    #[prost(string, tag = "4")]
    encoding: String,
    #[prost(fixed32, tag = "5")]
    step: u32,
    #[prost(bytes = "vec", tag = "6")]
    data: Vec<u8>,
    #[prost(string, tag = "7")]
    frame_id: String,
}

const NS: u64 = 1_700_000_000_123_456_789;

fn stamp() -> Option<Timestamp> {
    Some(Timestamp {
        seconds: (NS / 1_000_000_000) as i64,
        nanos: (NS % 1_000_000_000) as i32,
    })
}

fn our_scan(l: &Laser, out: &mut Vec<u8>) {
    protobuf::laser_scan("laser", NS, l, out)
}

fn prost_scan(l: &Laser, out: &mut Vec<u8>) {
    let half = (l.mount.yaw as f64).to_radians() / 2.0;
    let start = (l.start as f64).to_radians();
    let m = LaserScan {
        timestamp: stamp(),
        frame_id: "laser".into(),
        pose: Some(Pose {
            position: Some(Vector3 {
                x: l.mount.x as f64 / 1000.0,
                y: l.mount.y as f64 / 1000.0,
                z: 0.0,
            }),
            orientation: Some(Quaternion {
                x: 0.0,
                y: 0.0,
                z: half.sin(),
                w: half.cos(),
            }),
        }),
        start_angle: start,
        end_angle: start + ((l.readings.len() - 1) as f64 / l.resolution as f64).to_radians(),
        ranges: l.readings.iter().map(|r| *r as f64 / 1000.0).collect(),
    };
    out.clear();
    m.encode(out).unwrap();
}

/// Our read of a scan's ranges (what `decode_laser` does with field 6).
fn our_ranges(b: &[u8]) -> usize {
    let mut n = 0;
    for f in protowire::fields(b) {
        if let Ok((6, Value::Len(r))) = f {
            for c in r.chunks_exact(8) {
                n += (f64::from_le_bytes(c.try_into().unwrap()) * 1000.0).round() as i32 as usize;
            }
        }
    }
    n
}

fn prost_ranges(b: &[u8]) -> usize {
    let m = LaserScan::decode(b).unwrap();
    m.ranges
        .iter()
        .map(|r| (r * 1000.0).round() as i32 as usize)
        .sum()
}

fn our_image(b: &[u8]) -> usize {
    protowire::fields(b)
        .filter_map(|f| match f {
            Ok((6, Value::Len(d))) => Some(black_box(d.to_vec()).len()),
            _ => None,
        })
        .sum()
}

fn prost_image(b: &[u8]) -> usize {
    RawImage::decode(b).unwrap().data.len()
}

fn our_raw(img: &Image, out: &mut Vec<u8>) {
    protobuf::raw_image("camera", NS, img, out)
}

fn prost_raw(img: &Image, out: &mut Vec<u8>) {
    // The message owns its bytes: the copy is part of prost's encode.
    let m = RawImage {
        timestamp: stamp(),
        width: img.width,
        height: img.height,
        encoding: "bgr8".into(),
        step: img.width * 3,
        data: img.data.clone(),
        frame_id: "camera".into(),
    };
    out.clear();
    m.encode(out).unwrap();
}

/// ns per call of `f`, over `n` calls.
fn time(n: usize, mut f: impl FnMut()) -> f64 {
    let t = Instant::now();
    for _ in 0..n {
        f();
    }
    t.elapsed().as_nanos() as f64 / n as f64
}

fn main() {
    let l = Laser {
        readings: (0..1081).map(|i| 500 + i * 7).collect(),
        resolution: 4.0,
        start: -135.0,
        mount: Mount::PIONEER_LASER,
        ..Laser::default()
    };
    let img = Image::new(640, 480);
    let (mut ours, mut theirs) = (Vec::new(), Vec::new());
    protobuf::laser_scan("laser", NS, &l, &mut ours);
    prost_scan(&l, &mut theirs);
    assert_eq!(our_ranges(&ours), prost_ranges(&theirs), "the same ranges");
    assert_eq!(
        our_ranges(&theirs),
        prost_ranges(&ours),
        "each reads the other's"
    );
    let rounds = 7;
    let mut cases = Vec::new();
    cases.extend(message_cases(
        "LaserScan 1081",
        2000,
        &l,
        [our_scan, prost_scan],
        [our_ranges, prost_ranges],
    ));
    cases.extend(message_cases(
        "RawImage 640x480",
        200,
        &img,
        [our_raw, prost_raw],
        [our_image, prost_image],
    ));
    let medians = common::alternated(rounds, &mut cases);
    println!("protobuf wire: ours vs prost 0.14, medians of {rounds} alternated rounds");
    for ((name, ..), (o, p)) in cases.iter().zip(medians) {
        println!(
            "{name:<26} ours {:>9.1} µs   prost {:>9.1} µs   prost/ours {:.2}",
            o / 1e3,
            p / 1e3,
            p / o
        );
    }
}

/// The encode and the decode case of message `m`, ours (A) against prost's (B),
/// `n` calls a run; each decoder reads what its own encoder wrote.
fn message_cases<'a, M, R: 'a>(
    name: &str,
    n: usize,
    m: &'a M,
    [enc_a, enc_b]: [fn(&M, &mut Vec<u8>); 2],
    [dec_a, dec_b]: [fn(&[u8]) -> R; 2],
) -> [Case<'a>; 2] {
    let (mut a, mut b) = (Vec::new(), Vec::new());
    enc_a(m, &mut a);
    enc_b(m, &mut b);
    let (mut out_a, mut out_b) = (Vec::new(), Vec::new());
    [
        (
            format!("{name} encode"),
            Box::new(move || time(n, || enc_a(black_box(m), &mut out_a))),
            Box::new(move || time(n, || enc_b(black_box(m), &mut out_b))),
        ),
        (
            format!("{name} decode"),
            Box::new(move || time(n, || drop(black_box(dec_a(black_box(&a)))))),
            Box::new(move || time(n, || drop(black_box(dec_b(black_box(&b)))))),
        ),
    ]
}
