//! Fuzzing every parser of outside bytes, in-process: structure-aware random inputs
//! (mutations of real seeds: bit flips, byte runs, splices, cut-offs, and for text
//! the word-level ones: extreme numbers, repeated and dropped words, long tokens).
//! Stable Rust here has no coverage-guided fuzzer that builds offline (cargo-fuzz
//! needs nightly; cargo-afl builds AFL++ with LLVM plugins), so this is a seeded,
//! reproducible random fuzzer; each target runs the same public entry point the
//! program uses on those bytes.
//!
//! For every input it checks: no panic (caught and counted, the first message and
//! input kept), no hang (a watchdog aborts the run naming the target if one input
//! takes over 10 s), and no single allocation above [`ALLOC_BOUND`] (a counting
//! global allocator records the largest).
//!
//! CI runs a smoke pass (`FUZZ_INPUTS`, default 10,000 per target); longer runs:
//! `scripts/fuzz.sh SECONDS` (release build, `FUZZ_SECONDS` per target, prints the
//! counts). `FUZZ_SEED` changes the random sequence; `FUZZ_TARGET` picks targets
//! whose name contains it.

use crate::common;

use common::Rng;
use std::{
    alloc::{GlobalAlloc, Layout, System},
    panic::{AssertUnwindSafe, catch_unwind},
    path::{Path, PathBuf},
    sync::{
        Arc,
        atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering},
    },
    time::{Duration, Instant},
};

/// No input may make the program ask for more than this at once.
const ALLOC_BOUND: usize = 256 << 20;

struct Counting;
static LARGEST: AtomicUsize = AtomicUsize::new(0);
static OVER_BOUND: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        note(l.size());
        unsafe { System.alloc(l) }
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        note(l.size());
        unsafe { System.alloc_zeroed(l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        note(new);
        unsafe { System.realloc(p, l, new) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
}

fn note(size: usize) {
    LARGEST.fetch_max(size, Ordering::Relaxed);
    if size > ALLOC_BOUND {
        OVER_BOUND.fetch_add(1, Ordering::Relaxed);
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// Words that break number parsers and length checks.
const NASTY: &[&str] = &[
    "0",
    "-1",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e-320",
    "18446744073709551616",
    "-9223372036854775809",
    "4294967296",
    "65536",
    "2147483648",
    "",
    "#",
    "end_driver",
    "provides",
    "/dev/zero",
    "/",
];

/// One mutation of `seed`; `text` adds the word-level ones.
fn mutate(rng: &mut Rng, seed: &[u8], corpus: &[Vec<u8>], text: bool) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        match rng.below(if text { 10 } else { 7 }) {
            0 if !b.is_empty() => {
                let i = rng.below(b.len());
                b[i] ^= 1 << rng.below(8);
            }
            1 if !b.is_empty() => {
                let i = rng.below(b.len());
                b[i] = [0, 0xFF, 0x7F, 0x80, b'\n', b' ', b'-', b'9'][rng.below(8)];
            }
            2 => {
                let i = rng.below(b.len() + 1);
                let n = 1 + rng.below(16);
                let ins: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
                b.splice(i..i, ins);
            }
            3 if !b.is_empty() => {
                let i = rng.below(b.len());
                let n = rng.below((b.len() - i).min(64) + 1);
                b.drain(i..i + n);
            }
            4 if !b.is_empty() => b.truncate(rng.below(b.len())),
            5 if !corpus.is_empty() => {
                let other = &corpus[rng.below(corpus.len())];
                let i = rng.below(b.len() + 1);
                let j = rng.below(other.len() + 1);
                b.truncate(i);
                b.extend_from_slice(&other[j..]);
            }
            6 if b.len() >= 4 => {
                // A big-endian or little-endian length field set to something large.
                let i = rng.below(b.len() - 3);
                let v: u32 = [u32::MAX, 0x7FFF_FFFF, 0x0100_0000, 0xFFFF][rng.below(4)];
                let bytes = if rng.below(2) == 0 {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                };
                b[i..i + 4].copy_from_slice(&bytes);
            }
            7..=9 => {
                let s = String::from_utf8_lossy(&b).into_owned();
                let mut words: Vec<String> = s.split(' ').map(String::from).collect();
                if words.is_empty() {
                    continue;
                }
                let i = rng.below(words.len());
                match rng.below(4) {
                    0 => words[i] = NASTY[rng.below(NASTY.len())].into(),
                    1 => words.insert(i, words[i].clone()),
                    2 => {
                        words.remove(i);
                    }
                    _ => words[i] = "9".repeat(1 + rng.below(4096)),
                }
                b = words.join(" ").into_bytes();
            }
            _ => {}
        }
    }
    b
}

/// A parser under test: its name, its seeds, whether its input is text, and the
/// call (errors are fine; panics, hangs and huge allocations are not).
struct Target {
    name: &'static str,
    seeds: Vec<Vec<u8>>,
    text: bool,
    run: fn(&[u8]),
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn files(dir: &str, ext: &[&str]) -> Vec<Vec<u8>> {
    let mut v: Vec<Vec<u8>> = std::fs::read_dir(root().join(dir))
        .map(|d| {
            d.flatten()
                .map(|e| e.path())
                .filter(|p| {
                    p.is_file()
                        && (ext.is_empty()
                            || p.extension()
                                .is_some_and(|x| ext.contains(&x.to_str().unwrap_or(""))))
                })
                .filter_map(|p| std::fs::read(p).ok())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn text(b: &[u8]) -> std::borrow::Cow<'_, str> {
    String::from_utf8_lossy(b)
}

fn targets() -> Vec<Target> {
    let mut t = text_targets();
    t.extend(byte_targets());
    t.extend(driver_targets(Path::new("fuzz")));
    t
}

/// The text formats: conf files, fuzzy controllers, worlds, cameras, kernels.
fn text_targets() -> Vec<Target> {
    use jderobot::{conf::Conf, fuzzy, progeo, vision, world::World};
    vec![
        Target {
            name: "conf",
            seeds: files("examples", &["conf"]),
            text: true,
            run: |b| {
                if let Ok(c) = Conf::parse(&text(b), Path::new("fuzz.conf")) {
                    // Every declared component's lines, checked as `check` does.
                    let _ = jderobot::loader::check(&c);
                }
            },
        },
        Target {
            name: "fzz",
            seeds: files("assets/fuzzy", &["fzz"]),
            text: true,
            run: |b| {
                let _ = fuzzy::Controller::parse(&text(b), Path::new("f.fzz"));
                let _ = fuzzy::Controller::parse_lenient(&text(b), Path::new("f.fzz"));
            },
        },
        Target {
            name: "world",
            seeds: files("assets/worlds", &["world"]),
            text: true,
            run: |b| {
                let _ = World::parse(&text(b), Path::new("f.world"));
            },
        },
        Target {
            name: "camera",
            seeds: [
                files("assets/cameras", &[]),
                files("assets/simulated3D", &[]),
            ]
            .concat(),
            text: true,
            run: |b| {
                let _ = progeo::PinholeCamera::parse(&text(b), Path::new("cam"));
                let _ = progeo::World::parse(&text(b), Path::new("room.world"));
            },
        },
        Target {
            name: "kernel",
            seeds: files("assets/kernels", &["kernel"]),
            text: true,
            run: |b| {
                let _ = vision::Kernel::parse(&text(b), Path::new("k.kernel"));
            },
        },
    ]
}

/// The 4.3 wire and the image formats.
fn byte_targets() -> Vec<Target> {
    use jderobot::netwire;
    vec![
        Target {
            name: "netwire",
            seeds: [
                "1000 laser\n",
                "1001 encoders 5\n",
                "2000 motors 100 -20\n",
                "1003 17 12.5 -7.5\n",
                "1010 3 320 240\n",
                "1027 too many clients\n",
                "1004 4 1000 1000 1000 1000\n",
                "1005 90 0 10 0\n",
                "2003 12 0 0 0.38268343 0.9238795 0 0 0.25 0.1 -0.2 9.81\n",
                "2001\n",
            ]
            .iter()
            .map(|s| s.as_bytes().to_vec())
            .collect(),
            text: true,
            run: |b| {
                let _ = netwire::Request::parse(b);
                let _ = netwire::Message::parse(b);
                let mut r = netwire::LineReader::new(4096);
                let mut input = std::io::Cursor::new(b);
                for _ in 0..64 {
                    match r.read_line(&mut input) {
                        Ok(netwire::LineEvent::Line(l)) => {
                            let _ = netwire::Message::parse(l);
                        }
                        Ok(_) | Err(_) => break,
                    }
                }
            },
        },
        Target {
            name: "pnm_y4m",
            seeds: vec![
                std::fs::read(root().join("assets/images/testcard.pnm")).unwrap_or_default(),
                b"P6\n4 2\n255\n012345678901234567890123".to_vec(),
                b"P5 2 2 255 abcd".to_vec(),
                b"YUV4MPEG2 W4 H2 F25:1 C420jpeg\nFRAME\n012345678901".to_vec(),
            ],
            text: false,
            run: |b| {
                let _ = jderobot::media::still::decode_image(b, Path::new("f.ppm"));
                let mut r = std::io::Cursor::new(b);
                if let Ok(Some(h)) = jderobot::media::y4m::read_header(&mut r) {
                    let mut buf = Vec::new();
                    for _ in 0..4 {
                        if !matches!(
                            jderobot::media::y4m::read_frame(&mut r, &h, &mut buf),
                            Ok(true)
                        ) {
                            break;
                        }
                    }
                }
            },
        },
        Target {
            name: "jpeg_png",
            seeds: small_images(),
            text: false,
            run: |b| {
                let _ = jderobot::media::still::decode_image(b, Path::new("f.jpg"));
                let _ = jderobot::media::still::decode_image(b, Path::new("f.png"));
            },
        },
    ]
}

/// Small JPEG and PNG files (the bundled photos are too big to decode 10,000 times
/// in a debug build).
fn small_images() -> Vec<Vec<u8>> {
    let mut img = jderobot::interfaces::Image::new(16, 12);
    for (i, b) in img.data.iter_mut().enumerate() {
        *b = (i * 37 % 251) as u8;
    }
    let mut png_file = Vec::new();
    {
        let mut e = png::Encoder::new(&mut png_file, 16, 12);
        e.set_color(png::ColorType::Rgb);
        let mut w = e.write_header().expect("png header");
        w.write_image_data(&img.to_rgb()).expect("png data");
    }
    vec![
        jderobot::mcapfmt::jpeg(&img, 90).expect("a jpeg"),
        jderobot::mcapfmt::jpeg(&img, 20).expect("a jpeg"),
        png_file,
    ]
}

#[allow(unused_variables, unused_mut)]
fn driver_targets(p: &Path) -> Vec<Target> {
    let mut t = Vec::new();
    #[cfg(feature = "player")]
    t.push(player_xdr_target());
    #[cfg(feature = "gazebo")]
    t.push(gazebo_protobuf_target());
    #[cfg(feature = "gazebo")]
    t.extend(gazebo_wire_targets());
    #[cfg(feature = "foxglove")]
    t.push(relay_target());
    #[cfg(feature = "opengl_viewer")]
    t.push(obj_mtl_target());
    #[cfg(feature = "ros2")]
    t.push(ros2_dds_target());
    #[cfg(feature = "ros2")]
    t.extend(rtps_targets());
    #[cfg(feature = "evi")]
    t.push(visca_target());
    #[cfg(feature = "pantilt")]
    t.push(ptu_target());
    #[cfg(feature = "zenoh")]
    t.push(zenoh_wire_target());
    #[cfg(feature = "naobody")]
    t.push(qi_target());
    #[cfg(feature = "_mcap")]
    t.push(mcap_messages_target());
    #[cfg(feature = "rplidar")]
    t.push(rplidar_target());
    #[cfg(feature = "roomba")]
    t.push(roomba_target());
    t
}

#[cfg(feature = "player")]
fn player_xdr_target() -> Target {
    use jderobot::drivers::player::xdr;
    let mut seeds = Vec::new();
    for size in [0u32, 8, 24, 52, 200] {
        let mut m = vec![0u8; 40];
        m[36..40].copy_from_slice(&size.to_be_bytes());
        m.extend((0..size).map(|i| (i * 7) as u8));
        seeds.push(m);
    }
    Target {
        name: "player_xdr",
        seeds,
        text: false,
        run: |b| {
            if let Ok(h) = xdr::Header::decode(b) {
                let _ = h.size;
            }
            let body = b.get(40..).unwrap_or(&[]);
            let _ = xdr::decode_device_req(body);
            let _ = xdr::decode_devlist(body);
            let _ = xdr::decode_position2d(body);
            let _ = xdr::decode_scan(body);
            let _ = xdr::decode_ranger(body);
            let _ = xdr::decode_sonar(body);
            let _ = xdr::decode_bumpers(body);
            let _ = xdr::decode_ranger_config(body);
            let _ = xdr::decode_ptz(body);
            let _ = xdr::decode_camera(body);
            let _ = xdr::decode_blobs(body);
        },
    }
}

#[cfg(feature = "gazebo")]
fn gazebo_protobuf_target() -> Target {
    use jderobot::drivers::gazebo::{fill_image, laser, pb};
    use jderobot::interfaces::LaserMap;
    let mut seeds = Vec::new();
    let mut scan = Vec::new();
    let mut w = pb::W(&mut scan);
    w.message(1, |w| w.message(1, |w| w.uint(1, 3)));
    w.double(4, -1.5);
    w.double(6, 0.01);
    w.double(8, 10.0);
    w.uint(9, 4);
    w.bytes(14, &[0x3f; 32]);
    seeds.push(scan);
    let mut img = Vec::new();
    let mut w = pb::W(&mut img);
    w.uint(2, 2);
    w.uint(3, 2);
    w.uint(4, 6);
    w.bytes(5, &[7; 12]);
    w.uint(6, 3);
    seeds.push(img);
    let mut d = vec![0, 0];
    pb::Discovery {
        version: 10,
        process_uuid: "p".into(),
        kind: pb::disc::ADVERTISE,
        publisher: Some(pb::Publisher::default()),
        ..Default::default()
    }
    .encode(&mut d);
    seeds.push(d);
    Target {
        name: "gazebo_protobuf",
        seeds,
        text: false,
        run: |b| {
            let _ = pb::Discovery::decode(b);
            let _ = pb::decode_odometry(b);
            let _ = pb::decode_twist(b);
            let _ = pb::decode_joints(b);
            if let Ok(s) = pb::decode_scan(b) {
                let mut l = jderobot::interfaces::Laser::default();
                laser(&mut LaserMap::new(180, 1.0), &s, &mut l);
                // What the driver checks before a scan reaches `laser`.
                if jderobot::drivers::gazebo::check_scan(&s).is_ok() {
                    use jderobot::interfaces::InterfaceValue;
                    assert!(l.validate("laser").is_ok(), "a checked scan is in range");
                }
            }
            if let Ok(f) = pb::decode_image(b) {
                let mut i = jderobot::interfaces::Image::default();
                let _ = fill_image(&f, true, &mut i);
                let _ = fill_image(&f, false, &mut i);
            }
        },
    }
}

#[cfg(feature = "evi")]
fn visca_target() -> Target {
    Target {
        name: "visca",
        seeds: vec![
            vec![0x90, 0x41, 0xFF],
            vec![0x90, 0x51, 0xFF],
            vec![
                0x90, 0x50, 0x0F, 0x0F, 0x0F, 0x0F, 0x00, 0x00, 0x01, 0x02, 0xFF,
            ],
            vec![0x90, 0x60, 0x02, 0xFF],
            vec![0x88, 0x30, 0x02, 0xFF],
        ],
        text: false,
        run: |b| {
            use jderobot::drivers::evi::protocol;
            if let Some(protocol::Reply::Answer(a)) = protocol::classify(1, b) {
                let _ = protocol::from_nibbles(&a);
            }
            let _ = protocol::from_nibbles(b);
        },
    }
}

#[cfg(feature = "pantilt")]
fn ptu_target() -> Target {
    Target {
        name: "ptu",
        seeds: [
            "* Current Pan position is 1000\r\n",
            "* Maximum Pan position is 3090\r\n",
            "* -900\r\n",
            "! Illegal command\r\n",
            "*\r\n",
        ]
        .iter()
        .map(|s| s.as_bytes().to_vec())
        .collect(),
        text: true,
        run: |b| {
            use jderobot::drivers::pantilt::protocol::{self, Axis, Query};
            let _ = protocol::parse_reply("PP", b);
            for axis in [Axis::Pan, Axis::Tilt] {
                for q in [Query::Position, Query::Min, Query::Max] {
                    let _ = protocol::parse_query_line(axis, q, b);
                }
            }
        },
    }
}

#[cfg(feature = "zenoh")]
fn zenoh_wire_target() -> Target {
    Target {
        name: "zenoh_wire",
        seeds: vec![vec![0u8; 16], vec![1u8; 32], vec![0u8; 8], vec![7u8; 200]],
        text: false,
        run: |b| {
            use jderobot::{
                interfaces::{
                    Bumpers, Encoders, Image, Imu, Kind, Laser, Motors, PtEncoders, PtMotors,
                    Sonars, ZoomEncoders, ZoomMotors,
                },
                services::zenoh::wire::{self, Wire},
            };
            let _ = wire::read_attachment(b);
            let _ = wire::read_rmw_attachment(b);
            let _ = Image::take(b);
            let _ = Laser::take(b);
            let _ = Sonars::take(b);
            let _ = Bumpers::take(b);
            let _ = Encoders::take(b);
            let _ = Motors::take(b);
            let _ = PtEncoders::take(b);
            let _ = PtMotors::take(b);
            let _ = ZoomEncoders::take(b);
            let _ = ZoomMotors::take(b);
            let _ = Imu::take(b);
            for &kind in Kind::ALL {
                let _ = jderobot::mcapfmt::decode_message("t", kind, "", "cdr", 0, 0, b);
            }
        },
    }
}

#[cfg(feature = "naobody")]
fn qi_target() -> Target {
    Target {
        name: "qi",
        seeds: {
            use jderobot::drivers::naobody::qi::{self, Header, Sig, Value};
            // Whole messages (header and payload) as NAOqi sends them: a capability
            // map, a frame from getImageRemote, a ServiceInfo, an error.
            let msg = |ty: u8, v: Value, sig: &str| {
                let mut p = Vec::new();
                qi::encode(&v, &Sig::parse(sig).unwrap(), &mut p).unwrap();
                let h = Header {
                    id: 1,
                    size: p.len() as u32,
                    ty,
                    service: 1,
                    object: 1,
                    action: 100,
                    ..Header::default()
                };
                let mut b = h.encode().to_vec();
                b.extend_from_slice(&p);
                b
            };
            vec![
                msg(
                    2,
                    Value::Map(vec![(Value::str("__qi_auth_state"), Value::UInt(3))]),
                    "{sm}",
                ),
                msg(
                    2,
                    Value::List(vec![
                        Value::Int(2),
                        Value::Int(1),
                        Value::Int(3),
                        Value::Int(13),
                        Value::Int(0),
                        Value::Int(0),
                        Value::Raw(vec![1, 2, 3, 4, 5, 6]),
                    ]),
                    "m",
                ),
                msg(
                    2,
                    Value::Tuple(vec![
                        Value::str("ALMotion"),
                        Value::UInt(2),
                        Value::str("m"),
                        Value::UInt(7),
                        Value::List(vec![Value::str("tcp://127.0.0.1:9559")]),
                        Value::str("s"),
                    ]),
                    "(sIsI[s]s)",
                ),
                msg(3, Value::str("Cannot find service 'X' in index"), "m"),
            ]
        },
        text: false,
        run: |b| {
            use jderobot::drivers::naobody::qi::{self, Sig};
            let Ok(m) = qi::read_message(&mut &b[..]) else {
                return;
            };
            for sig in [
                "m",
                "{sm}",
                "(sIsI[s]ss)",
                qi::METAOBJECT_SIG,
                "(iiiiiiriffff)",
                "[f]",
            ] {
                if let Ok(v) = qi::decode(&m.payload, &Sig::parse(sig).unwrap()) {
                    let _ = qi::methods_of(&v);
                    let _ = jderobot::drivers::naobody::frame(&v);
                }
            }
        },
    }
}

#[cfg(feature = "_mcap")]
fn mcap_messages_target() -> Target {
    Target {
        name: "mcap_messages",
        seeds: vec![
            br#"{"timestamp":{"sec":1,"nsec":2},"v":100,"w":-20}"#.to_vec(),
            br#"{"timestamp":{"sec":1,"nsec":2},"pose":{"position":{"x":1,"y":2,"z":0}}}"#.to_vec(),
            br#"{"timestamp":{"sec":1,"nsec":2},"clock":3,"jderobot":{"qx":0,"qy":0,"qz":0,"qw":1,"wx":0.5,"wy":0,"wz":0,"ax":0,"ay":0,"az":9.8}}"#.to_vec(),
            vec![0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0],
        ],
        text: false,
        run: |b| {
            for &kind in jderobot::interfaces::Kind::ALL {
                let _ = jderobot::mcapfmt::decode("t", kind, b);
                let _ = jderobot::mcapfmt::decode_message("t", kind, "", "cdr", 0, 0, b);
            }
            let _ = jderobot::mcapfmt::decompress("jpeg", b);
        },
    }
}

#[cfg(feature = "rplidar")]
fn rplidar_target() -> Target {
    Target {
        name: "rplidar",
        // A SCAN descriptor, then nodes as the RPLIDAR protocol lays them out
        // (quality and S/!S, angle·64 with C = 1, distance·4): a start node at 0°
        // and one at 90°, 1 m; and a GET_INFO reply.
        seeds: vec![
            vec![
                0xA5, 0x5A, 0x05, 0, 0, 0x40, 0x81, 0x3D, 0x01, 0x00, 0xA0, 0x0F, 0x3E, 0x01, 0x2D,
                0xA0, 0x0F,
            ],
            [
                vec![0xA5, 0x5A, 0x14, 0, 0, 0, 0x04, 0x18, 29, 1, 7],
                vec![0x10; 16],
            ]
            .concat(),
        ],
        text: false,
        run: |b| {
            use jderobot::drivers::rplidar::protocol::{self, Revolution};
            if let Ok(d) = <&[u8; 7]>::try_from(b.get(..7).unwrap_or(&[])) {
                let _ = protocol::descriptor(d);
            }
            let _ = protocol::Info::parse(b.get(7..27).unwrap_or(&[]));
            let _ = protocol::health(b.get(7..10).unwrap_or(&[]));
            let (mut rev, mut out) = (Revolution::new(360, 1.0, -180.0, 12000), Vec::new());
            let t0 = std::time::Instant::now();
            for (i, c) in b.windows(5).enumerate() {
                let at = t0 + std::time::Duration::from_micros(500 * i as u64);
                match protocol::node(c) {
                    Some(n) => {
                        if let Some(st) = rev.push(&n, at, &mut out) {
                            let _ = st.implausible(&protocol::LIMITS);
                        }
                    }
                    None => rev.skipped(1),
                }
            }
        },
    }
}

#[cfg(feature = "roomba")]
fn roomba_target() -> Target {
    Target {
        name: "roomba",
        // Two sensor-stream frames of the packets the driver asks for (header 19, n,
        // each id and its data, a checksum that makes the sum 0), as the Create 2
        // Open Interface streams them.
        seeds: {
            use jderobot::drivers::roomba::protocol;
            let ids = protocol::stream_command()[2..].to_vec();
            let mut f = vec![19, protocol::frame_n() as u8];
            for (k, id) in ids.iter().enumerate() {
                f.push(*id);
                let size = protocol::packet_size(*id).unwrap_or(0);
                f.extend((0..size).map(|i| (i + k) as u8));
            }
            let sum = f.iter().fold(0u8, |a, b| a.wrapping_add(*b));
            f.push(0u8.wrapping_sub(sum));
            vec![[f.clone(), f].concat()]
        },
        text: false,
        run: |b| {
            let mut buf = b.to_vec();
            for _ in 0..b.len() + 1 {
                // Ok(None): the rest is a partial frame.
                if let Ok(None) = jderobot::drivers::roomba::protocol::take_frame(&mut buf) {
                    break;
                }
            }
        },
    }
}

#[cfg(feature = "gazebo")]
thread_local! {
    /// The discovery target's node: one for the whole run, so what the packets
    /// build up (publishers, processes, subscribers) meets the caps. It wants no
    /// topic and advertises none, so it connects to nothing and sends nothing.
    static GZ_NODE: std::cell::RefCell<Option<jderobot::drivers::gazebo::node::Node>> =
        const { std::cell::RefCell::new(None) };
    static GZ_PACKETS: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}

/// gz-transport's discovery packets (a 2-byte length and a `Discovery`, as
/// gz-transport's Discovery.hh lays them out) into a node's real handler, and
/// ZMTP 3.0 byte streams (rfc.zeromq.org/spec/23: greeting, READY, frames with
/// MORE and long sizes) into the framer every connection reads with.
#[cfg(feature = "gazebo")]
fn gazebo_wire_targets() -> Vec<Target> {
    vec![gazebo_discovery_target(), gazebo_zmtp_target()]
}

/// Discovery packets into a node's real handler.
#[cfg(feature = "gazebo")]
fn gazebo_discovery_target() -> Target {
    use jderobot::drivers::gazebo::{
        node::{self, Node},
        pb::{Discovery, Publisher, disc},
    };
    let puuid = GZ_NODE.with(|n| {
        let mut n = n.borrow_mut();
        let node = n.get_or_insert_with(|| {
            Node::new("127.0.0.1", "fuzz").expect("a gz-transport node on loopback")
        });
        node.puuid.clone()
    });
    let packet = |kind: u64, sub: Option<&str>, ctrl: &str| {
        let d = Discovery {
            version: node::WIRE_VERSION,
            process_uuid: "0c3d2f5e-5bd0-4a4a-9a1e-6a1b6c7d8e9f".into(),
            kind,
            relay: false,
            sub: sub.map(String::from),
            publisher: (kind != disc::SUBSCRIBE && kind != disc::BYE).then(|| Publisher {
                topic: node::qualify("fuzz", "/model/robot1/cmd_vel"),
                address: "tcp://127.0.0.1:1".into(),
                process_uuid: "0c3d2f5e-5bd0-4a4a-9a1e-6a1b6c7d8e9f".into(),
                node_uuid: "9f8e7d6c-1b6a-4e1a-8a4a-5e5f2d3c0b1a".into(),
                scope: 2,
                ctrl: ctrl.into(),
                msg_type: "gz.msgs.Twist".into(),
            }),
        };
        let mut body = Vec::new();
        d.encode(&mut body);
        let mut b = (body.len() as u16).to_le_bytes().to_vec();
        b.extend_from_slice(&body);
        b
    };
    let discovery_seeds = vec![
        packet(disc::ADVERTISE, None, ""),
        packet(disc::UNADVERTISE, None, ""),
        packet(disc::SUBSCRIBE, Some("@/fuzz@/model/robot1/cmd_vel"), ""),
        packet(disc::HEARTBEAT, None, ""),
        packet(disc::NEW_CONNECTION, None, &puuid),
        packet(disc::END_CONNECTION, None, &puuid),
        packet(disc::BYE, None, ""),
    ];
    Target {
        name: "gazebo_discovery",
        seeds: discovery_seeds,
        text: false,
        run: |b| {
            let _ = node::parse_packet(b);
            // The same message with its length field made to fit, so the
            // mutations of the message itself reach the node.
            let body = b.get(2..).unwrap_or_default();
            let body = &body[..body.len().min(65535)];
            let mut fixed = (body.len() as u16).to_le_bytes().to_vec();
            fixed.extend_from_slice(body);
            GZ_NODE.with(|n| {
                if let Some(node) = n.borrow_mut().as_mut() {
                    node.discovery(b);
                    node.discovery(&fixed);
                    let k = GZ_PACKETS.with(|c| {
                        c.set(c.get() + 1);
                        c.get()
                    });
                    if k.is_multiple_of(1024) {
                        let (topics, most, processes, subs) = node.remembered();
                        assert!(
                            topics <= node::MAX_TOPICS
                                && most <= node::MAX_PUBLISHERS
                                && processes <= node::MAX_KNOWN
                                && subs <= node::MAX_SUBSCRIBERS,
                            "over a cap: {topics} topics, {most} publishers of one, \
                             {processes} processes, {subs} subscribers"
                        );
                        if k == 1 << 20 {
                            // What the packets reached (one line per run).
                            println!(
                                "fuzz gazebo_discovery: after {k} packets the node remembers \
                                 {topics} topics (at most {most} publishers of one), \
                                 {processes} processes, {subs} subscribers"
                            );
                        }
                    }
                }
            });
        },
    }
}

/// ZMTP 3.0 byte streams into the framer every connection reads with.
#[cfg(feature = "gazebo")]
fn gazebo_zmtp_target() -> Target {
    use jderobot::drivers::gazebo::zmtp;
    let mut stream = zmtp::greeting().to_vec();
    stream.extend_from_slice(&zmtp::ready("PUB"));
    let message = |out: &mut Vec<u8>, data: &[u8]| {
        for (i, part) in [
            &b"@/fuzz@/scan"[..],
            b"tcp://127.0.0.1:40000",
            data,
            b"gz.msgs.LaserScan",
        ]
        .iter()
        .enumerate()
        {
            zmtp::frame(out, i < 3, part);
        }
    };
    let mut small = stream.clone();
    message(&mut small, &[0x3f; 40]);
    message(&mut small, b"");
    let mut long = stream.clone();
    message(&mut long, &[7; 300]);
    let mut subscribe = stream.clone();
    zmtp::frame(&mut subscribe, false, b"\x01@/fuzz@/scan");
    Target {
        name: "gazebo_zmtp",
        seeds: vec![small, long, subscribe],
        text: false,
        run: |b| {
            // Whole, then in pieces of the sizes the first byte says (a
            // stream arrives cut anywhere).
            let step = 1 + b.first().copied().unwrap_or(0) as usize % 97;
            for chunks in [b.len().max(1), step] {
                let mut f = zmtp::Framer::new("fuzz".into());
                'feed: for c in b.chunks(chunks) {
                    let mut at = 0;
                    while at < c.len() {
                        let n = f.feed(&c[at..]);
                        at += n;
                        loop {
                            match f.next_item() {
                                Ok(Some(_)) => {}
                                Ok(None) => break,
                                Err(_) => break 'feed,
                            }
                        }
                        // Full with no whole message in it cannot happen (a
                        // message fits); if it did, stop rather than spin.
                        if n == 0 {
                            break 'feed;
                        }
                    }
                }
            }
        },
    }
}

/// The Foxglove relay's front door on a client's bytes: the upgrade request
/// (RFC 6455 §4.1: its head, the token, the subprotocol rename) and the frames
/// after it (§5.2: headers, masks, fragments, control frames, the message cap).
#[cfg(feature = "foxglove")]
fn relay_target() -> Target {
    let head = |path: &str, proto: &str| {
        format!(
            "GET {path} HTTP/1.1\r\nHost: 127.0.0.1:8765\r\nUpgrade: websocket\r\n\
             Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\
             Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: {proto}\r\n\r\n"
        )
        .into_bytes()
    };
    // A masked text frame, a masked ping, and a fragment with its continuation.
    let frame = |fin: bool, op: u8, payload: &[u8]| {
        let mut f = vec![(fin as u8) << 7 | op];
        if payload.len() < 126 {
            f.push(0x80 | payload.len() as u8);
        } else {
            f.push(0x80 | 126);
            f.extend_from_slice(&(payload.len() as u16).to_be_bytes());
        }
        let mask = [1u8, 2, 3, 4];
        f.extend_from_slice(&mask);
        f.extend(payload.iter().enumerate().map(|(i, b)| b ^ mask[i % 4]));
        f
    };
    let sub = br#"{"op":"subscribe","subscriptions":[{"id":1,"channelId":1}]}"#;
    let mut a = head(
        "/?token=7f3a9c2e5b8d4f16a0c3e9b2d7f14a68",
        "foxglove.websocket.v1",
    );
    a.extend(frame(true, 1, sub));
    a.extend(frame(true, 9, b"ping"));
    let mut b = head("/", "foxglove.sdk.v1, foxglove.sdk.v1.1");
    b.extend(frame(false, 1, &sub[..20]));
    b.extend(frame(true, 0, &sub[20..]));
    b.extend(frame(true, 2, &[7; 300]));
    let mut c =
        b"GET / HTTP/1.1\r\nAuthorization: Bearer 7f3a9c2e5b8d4f16a0c3e9b2d7f14a68\r\n".to_vec();
    c.extend(b"Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n");
    c.extend(frame(true, 8, &[3, 232]));
    Target {
        name: "foxglove_relay",
        seeds: vec![a, b, c],
        text: false,
        run: |b| {
            use jderobot::services::foxglove::relay;
            let mut buf = b.to_vec();
            let (head, rest) = match relay::split_head(&mut buf) {
                Some(r) => r,
                None => (buf, Vec::new()),
            };
            for token in [None, Some("7f3a9c2e5b8d4f16a0c3e9b2d7f14a68")] {
                if let Ok((head, to_sdk, _legacy)) = relay::check_request(head.clone(), token) {
                    let _ = relay::offered(&head);
                    let _ = relay::replace_protocol(&to_sdk, relay::LEGACY);
                }
            }
            let _ = relay::presented_token(&String::from_utf8_lossy(&head));
            let t0 = std::time::Instant::now();
            for max in [1024, 65536] {
                let mut frames = relay::ClientFrames::new(max);
                let mut at = 0;
                for (k, c) in rest.chunks(1 + rest.len() / 3).enumerate() {
                    let now = t0 + std::time::Duration::from_millis(4000 * k as u64);
                    match frames.feed(c, now) {
                        Ok(n) => at += n,
                        Err((n, _)) => {
                            assert!(n <= c.len());
                            break;
                        }
                    }
                    let _ = frames.deadline();
                }
                assert!(at <= rest.len());
            }
            // The server's frames as the relay peeks them.
            let _ = relay::parse_header(&rest);
        },
    }
}

/// OBJ and MTL text (the Wavefront formats, through tobj, as the opengl_viewer
/// model loader reads them): the input is the OBJ, a NUL, then the MTL.
#[cfg(feature = "opengl_viewer")]
fn obj_mtl_target() -> Target {
    let obj = std::fs::read(root().join("assets/models/pioneer.obj")).unwrap_or_default();
    let mtl = std::fs::read(root().join("assets/models/pioneer.mtl")).unwrap_or_default();
    let cube = b"mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nvn 0 0 1\n\
                 vt 0 0\nusemtl red\nf 1/1/1 2/1/1 3/1/1 4/1/1\nf -1 -2 -3\ng side\nf 1 2 5\n\0\
                 newmtl red\nKd 1 0 0\nKa 0.1 0.1 0.1\nNs 10\nd 1\nillum 2\n"
        .to_vec();
    Target {
        name: "obj_mtl",
        seeds: vec![[obj, vec![0], mtl].concat(), cube],
        text: true,
        run: |b| {
            let (obj, mtl) = match b.iter().position(|&c| c == 0) {
                Some(i) => (&b[..i], &b[i + 1..]),
                None => (b, &b[..0]),
            };
            let (obj, mtl) = (text(obj), text(mtl));
            let _ = jderobot::schemas::opengl_viewer::load_model_text(
                &obj,
                Path::new("fuzz/m.obj"),
                Some(&mtl),
                1.0,
            );
        },
    }
}

/// What `obj_mtl` found: tobj 4.0.5 panicked on a colour line with fewer than
/// three numbers (`Kd 0`); the loader now refuses it, naming the file and line.
#[cfg(feature = "opengl_viewer")]
#[test]
fn a_short_colour_line_is_an_error_at_its_line_not_a_panic() {
    let obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\n";
    for (mtl, line) in [
        ("newmtl red\nKd 0\n", 2),
        ("newmtl red\nKa 0.1 0.1 0.1\n\tKs\n", 3),
        ("newmtl red\nKe 1 1\n", 2),
    ] {
        let e = jderobot::schemas::opengl_viewer::load_model_text(
            obj,
            Path::new("models/m.obj"),
            Some(mtl),
            1.0,
        )
        .err()
        .unwrap_or_else(|| panic!("{mtl:?} was taken"));
        let shown = e.to_string();
        assert!(
            shown.starts_with(&format!("models/m.mtl:{line}: ")) && shown.contains("three numbers"),
            "{mtl:?}: {shown}"
        );
    }
}

/// An RTPS datagram (DDSI-RTPS 2.3, 8.3.3 and 9.4): the header, then `subs`.
#[cfg(feature = "ros2")]
fn rtps(subs: &[Vec<u8>]) -> Vec<u8> {
    let mut d = b"RTPS\x02\x03\x01\xaa".to_vec();
    d.extend_from_slice(&[7; 12]);
    subs.iter().for_each(|s| d.extend_from_slice(s));
    d
}

/// A submessage: id, flags E (little endian) plus `flags`, its length, `body`.
#[cfg(feature = "ros2")]
fn submessage(id: u8, flags: u8, body: &[u8]) -> Vec<u8> {
    let mut s = vec![id, 1 | flags];
    s.extend_from_slice(&(body.len() as u16).to_le_bytes());
    s.extend_from_slice(body);
    s
}

/// DATA_FRAG `k` (from 1) of a `size`-byte sample in `frag`-byte fragments,
/// writer SN `sn`, from the SPDP writer to the SPDP reader.
#[cfg(feature = "ros2")]
fn data_frag(sn: u32, k: u32, frag: u16, size: u32) -> Vec<u8> {
    let mut b = vec![0, 0, 28, 0];
    b.extend_from_slice(&[0, 1, 0, 0xc7, 0, 1, 0, 0xc2]);
    b.extend_from_slice(&0i32.to_le_bytes());
    b.extend_from_slice(&sn.to_le_bytes());
    b.extend_from_slice(&k.to_le_bytes());
    b.extend_from_slice(&1u16.to_le_bytes());
    b.extend_from_slice(&frag.to_le_bytes());
    b.extend_from_slice(&size.to_le_bytes());
    let from = (k - 1) as usize * frag as usize;
    let n = (size as usize - from).min(frag as usize);
    let mut payload = vec![0, 3, 0, 0];
    payload.resize(size as usize, 0x5a);
    b.extend_from_slice(&payload[from..from + n]);
    submessage(0x16, 0, &b)
}

/// Valid datagrams: an SPDP DATA (as tests/ros2/rtps_probe.py sends), a
/// HEARTBEAT, an ACKNACK, INFO_TS and INFO_DST before a DATA, a GAP, and
/// samples in 2 and 3 DATA_FRAGs.
#[cfg(feature = "ros2")]
fn rtps_seeds() -> Vec<Vec<u8>> {
    let ids = [0, 1, 0, 0xc7, 0, 1, 0, 0xc2];
    let sn = |n: u32| [0i32.to_le_bytes(), n.to_le_bytes()].concat();
    let mut spdp = vec![0, 0, 16, 0];
    spdp.extend_from_slice(&ids);
    spdp.extend_from_slice(&sn(1));
    spdp.extend_from_slice(&[0, 3, 0, 0]);
    spdp.extend_from_slice(&[0x15, 0, 4, 0, 2, 3, 0, 0, 0x50, 0, 16, 0]);
    spdp.extend_from_slice(&[7; 12]);
    spdp.extend_from_slice(&[
        0, 0, 1, 0xc1, 2, 0, 8, 0, 100, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0,
    ]);
    let data = submessage(0x15, 4, &spdp);
    let hb = submessage(
        0x07,
        0,
        &[ids.as_slice(), &sn(1), &sn(5), &1u32.to_le_bytes()].concat(),
    );
    let acknack = [
        ids.as_slice(),
        &sn(1),
        &32u32.to_le_bytes(),
        &[0xff; 4],
        &1u32.to_le_bytes(),
    ];
    let gap = [ids.as_slice(), &sn(2), &sn(4), &0u32.to_le_bytes()].concat();
    vec![
        rtps(std::slice::from_ref(&data)),
        rtps(&[hb.clone(), submessage(0x06, 0, &acknack.concat())]),
        rtps(&[
            submessage(0x09, 0, &[1, 0, 0, 0, 0, 0, 0, 0]),
            submessage(0x0e, 0, &[9; 12]),
            data,
        ]),
        rtps(&[submessage(0x08, 0, &gap), hb]),
        rtps(&[data_frag(1, 1, 8, 16), data_frag(1, 2, 8, 16)]),
        rtps(&[
            data_frag(2, 3, 8, 20),
            data_frag(2, 1, 8, 20),
            data_frag(2, 2, 8, 20),
        ]),
    ]
}

/// The vendored RustDDS's parser of a peer's datagrams, and its fragment
/// assembly (the DATA_FRAGs of a datagram, then the same again: a sample
/// completed twice, fragments repeated).
#[cfg(feature = "ros2")]
fn rtps_targets() -> Vec<Target> {
    vec![
        Target {
            name: "rtps_datagram",
            seeds: rtps_seeds(),
            text: false,
            run: |b| {
                let _ = rustdds::fuzzing::parse(b);
            },
        },
        Target {
            name: "rtps_fragments",
            seeds: rtps_seeds(),
            text: false,
            run: |b| {
                let _ = rustdds::fuzzing::assemble(&[b, b]);
            },
        },
    ]
}

/// ROS 2 messages as DDS hands them over: the CDR body after RTPS's
/// encapsulation header, through the DataReader's decoder, then each message the
/// service and the driver read (Twist, LaserScan, Odometry, Image, Imu),
/// checked in range as `Interface::accept` does.
#[cfg(feature = "ros2")]
fn ros2_dds_target() -> Target {
    use jderobot::interfaces::{Encoders, Image, Imu, Laser, Motors, Sample};
    use jderobot::mcapfmt::ros2;
    fn body<T: ros2::Ros2>(v: T) -> Vec<u8> {
        let s = Sample {
            clock: 1,
            stamp: std::time::Instant::now(),
            time: std::time::SystemTime::UNIX_EPOCH + std::time::Duration::from_secs(7),
            value: v,
        };
        let mut out = Vec::new();
        ros2::encode("fuzz", &s, &mut out);
        out.split_off(4)
    }
    let seeds = vec![
        body(Motors { v: 100.0, w: -20.0 }),
        body(Laser {
            readings: vec![1000; 8],
            ..Default::default()
        }),
        body(Encoders::default()),
        body(Image::new(4, 2)),
        body(Imu::default()),
    ];
    Target {
        name: "ros2_dds",
        seeds,
        text: false,
        run: |b| {
            use jderobot::mcapfmt::dds::CdrDecoder;
            use rustdds::{RepresentationIdentifier, no_key::Decode};
            fn read<T: ros2::Ros2>(data: &[u8]) {
                if let Ok((_, v)) = ros2::decode::<T>("fuzz", data, 0) {
                    let _ = v.validate("fuzz");
                }
            }
            for enc in [
                RepresentationIdentifier::CDR_LE,
                RepresentationIdentifier::CDR_BE,
            ] {
                let Ok(m) = CdrDecoder.decode_bytes(b, enc) else {
                    continue;
                };
                read::<Motors>(&m.0);
                read::<Laser>(&m.0);
                read::<Encoders>(&m.0);
                read::<Image>(&m.0);
                read::<Imu>(&m.0);
            }
        },
    }
}

/// What one target's run found.
#[derive(Debug, Default)]
struct Found {
    inputs: u64,
    panics: u64,
    first_panic: Option<(String, Vec<u8>)>,
    slowest: Duration,
}

fn fuzz(target: &Target, seed: u64, inputs: u64, seconds: Option<f64>) -> Found {
    let mut rng = Rng::new(seed ^ (target.name.len() as u64) << 32);
    let mut found = Found::default();
    let started = Instant::now();
    let busy = Arc::new(AtomicU64::new(0));
    let done = Arc::new(AtomicBool::new(false));
    let current = Arc::new(std::sync::Mutex::new(Vec::new()));
    // The watchdog: one input over 10 s is a hang.
    let watchdog = {
        let (busy, done, name) = (busy.clone(), done.clone(), target.name);
        let current = current.clone();
        std::thread::spawn(move || {
            let mut last = (0, Instant::now());
            while !done.load(Ordering::Relaxed) {
                std::thread::sleep(Duration::from_millis(200));
                let n = busy.load(Ordering::Relaxed);
                if n != last.0 {
                    last = (n, Instant::now());
                } else if last.1.elapsed() > Duration::from_secs(10) {
                    let input = current.lock().map(|c| c.clone()).unwrap_or_default();
                    eprintln!(
                        "fuzz {name}: input {n} hangs (over 10 s): {:?}",
                        String::from_utf8_lossy(&input[..input.len().min(512)])
                    );
                    std::process::abort();
                }
            }
        })
    };
    let empty = Vec::new();
    loop {
        let out_of_time = seconds.is_some_and(|s| started.elapsed().as_secs_f64() > s);
        if (seconds.is_none() && found.inputs >= inputs) || out_of_time {
            break;
        }
        let seed_input = if target.seeds.is_empty() {
            &empty
        } else {
            &target.seeds[rng.below(target.seeds.len())]
        };
        let input = mutate(&mut rng, seed_input, &target.seeds, target.text);
        if let Ok(mut c) = current.lock() {
            c.clone_from(&input);
        }
        busy.fetch_add(1, Ordering::Relaxed);
        let t0 = Instant::now();
        let r = catch_unwind(AssertUnwindSafe(|| (target.run)(&input)));
        found.slowest = found.slowest.max(t0.elapsed());
        found.inputs += 1;
        if let Err(e) = r {
            found.panics += 1;
            if found.first_panic.is_none() {
                let msg = e
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                found.first_panic = Some((msg, input));
            }
        }
    }
    done.store(true, Ordering::Relaxed);
    let _ = watchdog.join();
    found
}

fn env<T: std::str::FromStr>(name: &str) -> Option<T> {
    std::env::var(name).ok().and_then(|v| v.parse().ok())
}

/// Two tests share the targets, each taking the next one not yet taken: a debug
/// build fuzzes at about 1,000 inputs a second, and one test for all of them made
/// the core suite wait 25 s on one core while the other idled (docs/benchmarks.md,
/// CI). Run alone (a filter), one of them takes every target.
#[test]
fn every_parser_survives_random_inputs_1() {
    survive_random_inputs();
}

/// See [`every_parser_survives_random_inputs_1`].
#[test]
fn every_parser_survives_random_inputs_2() {
    survive_random_inputs();
}

/// The next target index for [`survive_random_inputs`].
static NEXT_TARGET: AtomicUsize = AtomicUsize::new(0);

/// Fuzzes the targets no other test has taken yet. The counting allocator is
/// process-wide, so a target's largest allocation may be the other test's.
fn survive_random_inputs() {
    let inputs: u64 = env("FUZZ_INPUTS").unwrap_or(10_000);
    let seconds: Option<f64> = env("FUZZ_SECONDS");
    let seed: u64 = env("FUZZ_SEED").unwrap_or(1);
    let only: Option<String> = std::env::var("FUZZ_TARGET").ok();
    // Panics are caught and counted; keep their messages off the output.
    let quiet = common::quiet_panics();
    let mut failures = Vec::new();
    let all = targets();
    while let Some(t) = all.get(NEXT_TARGET.fetch_add(1, Ordering::Relaxed)) {
        if only.as_deref().is_some_and(|o| !t.name.contains(o)) {
            continue;
        }
        assert!(!t.seeds.is_empty(), "target {} has no seeds", t.name);
        LARGEST.store(0, Ordering::Relaxed);
        let over_before = OVER_BOUND.load(Ordering::Relaxed);
        let started = Instant::now();
        let f = fuzz(t, seed, inputs, seconds);
        let over = OVER_BOUND.load(Ordering::Relaxed) - over_before;
        println!(
            "fuzz {:<14} {:>10} inputs in {:>6.1} s, {} panics, largest allocation {:.1} MiB, \
             slowest input {:.1} ms",
            t.name,
            f.inputs,
            started.elapsed().as_secs_f64(),
            f.panics,
            LARGEST.load(Ordering::Relaxed) as f64 / (1 << 20) as f64,
            f.slowest.as_secs_f64() * 1e3
        );
        if let Some((msg, input)) = &f.first_panic {
            let shown: String = input.iter().take(256).map(|b| format!("{b:02x}")).collect();
            failures.push(format!(
                "{}: {} panics; first: {msg}; input (hex, first 256 bytes): {shown}",
                t.name, f.panics
            ));
        }
        if over > 0 {
            failures.push(format!(
                "{}: {over} allocations above {} MiB",
                t.name,
                ALLOC_BOUND >> 20
            ));
        }
    }
    drop(quiet);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
