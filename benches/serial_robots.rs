//! Serial robot benchmarks (issue 36), medians of alternated rounds. Run with
//! `cargo bench --features full --bench serial_robots`.
//!
//! - rplidar: decoding one revolution of an A1 (360 standard 5-byte nodes: checks,
//!   angle and distance, binning into 360 readings counter-clockwise) as a share of
//!   one core at the A1's 5.5 revolutions a second (goal: under 5 %); reference in
//!   the same run: one pass summing the revolution's 1800 bytes, the least any
//!   decoder does. Then the driver thread's whole CPU against the pty emulator of the
//!   tests (reads, decoding, publishing), as a share of one core.
//! - roomba: a motors command published → its Drive Direct applied by the
//!   emulated Create 2 (tests/emulators/create2.rs), against the line's own time
//!   for those 5 bytes at 115200 baud (434 µs; a pty has no baud rate, so this is
//!   the driver's and the pty's latency alone, compared with what the cable adds).

#[path = "../tests/emulators/create2.rs"]
mod create2;
#[path = "../tests/emulators/ptu.rs"]
mod ptu;
#[path = "../tests/emulators/room.rs"]
mod room;
#[path = "../tests/emulators/rplidar.rs"]
mod rplidar;

mod common;
use common::{median, threads_cpu};

use std::{
    hint::black_box,
    path::Path,
    sync::Arc,
    time::{Duration, Instant},
};

use jderobot::{
    conf::Conf,
    drivers::rplidar::protocol::{LIMITS, Revolution, node},
    interfaces::{Interface, Laser, Motors},
};

fn start(text: &str) -> Arc<jderobot::Runtime> {
    let conf = Conf::parse(text, Path::new("bench.conf")).expect("conf");
    jderobot::loader::start(&conf).expect("runtime")
}

/// Two revolutions of nodes from the emulator's encoder (a room seen from inside).
fn revolution_bytes() -> Vec<u8> {
    let r = room::Room::new(4000.0, 3000.0, 1000.0, 1200.0, 20.0);
    let r = r.lock().clone();
    let mut out = Vec::new();
    for k in 0..(2.0 * rplidar::SAMPLES) as usize + 1 {
        let a = (k as f64 * 360.0 / rplidar::SAMPLES) % 360.0;
        let start = k == 0 || a < 360.0 / rplidar::SAMPLES;
        out.extend(rplidar::node(
            start,
            a,
            r.ray(r.x, r.y, r.theta - a.to_radians()),
        ));
    }
    out
}

/// Decodes and checks (each finished revolution's plausibility, as the driver
/// does) as if the nodes came at the A1's rate, from `clock` on.
fn decode(
    bytes: &[u8],
    rev: &mut Revolution,
    out: &mut Vec<i32>,
    laser: &mut Laser,
    clock: &mut Instant,
) -> usize {
    let per_node = Duration::from_secs_f64(1.0 / (rplidar::RATE_HZ * rplidar::SAMPLES));
    let mut scans = 0;
    for c in bytes.chunks_exact(5) {
        *clock += per_node;
        if let Some(n) = node(c)
            && let Some(st) = rev.push(&n, *clock, out)
            && st.implausible(&LIMITS).is_none()
        {
            laser.readings.clear();
            laser.readings.extend_from_slice(out);
            scans += 1;
        }
    }
    scans
}

fn bench_decode() {
    let bytes = revolution_bytes();
    let per_rev = bytes.len() as f64 / 2.0;
    let mut rev = Revolution::new(360, 1.0, -180.0, 12_000);
    let mut out = Vec::new();
    let mut laser = Laser::default();
    let mut clock = Instant::now();
    assert!(
        decode(&bytes, &mut rev, &mut out, &mut laser, &mut clock) >= 1,
        "a whole revolution"
    );
    let reps = 2000;
    let (mut ours, mut refs) = (Vec::new(), Vec::new());
    for _ in 0..7 {
        let t0 = Instant::now();
        for _ in 0..reps {
            black_box(decode(
                black_box(&bytes),
                &mut rev,
                &mut out,
                &mut laser,
                &mut clock,
            ));
        }
        ours.push(t0.elapsed().as_secs_f64() / (2 * reps) as f64);
        let t0 = Instant::now();
        for _ in 0..reps {
            black_box(black_box(&bytes).iter().map(|&b| b as u64).sum::<u64>());
        }
        refs.push(t0.elapsed().as_secs_f64() / (2 * reps) as f64);
    }
    let (o, r) = (median(&ours), median(&refs));
    let share = o * rplidar::RATE_HZ * 100.0;
    println!(
        "rplidar decode: {:.1} µs per revolution ({per_rev:.0} bytes, 360 nodes) = {share:.3} % of one core at {} Hz (goal < 5 %: {}); \
         reference byte sum {:.2} µs, ratio {:.1}",
        o * 1e6,
        rplidar::RATE_HZ,
        if share < 5.0 { "met" } else { "NOT met" },
        r * 1e6,
        o / r
    );
}

fn bench_lidar_thread() {
    let dir = tempfile::tempdir().unwrap();
    let port = dir.path().join("rplidar");
    let room = room::Room::new(4000.0, 3000.0, 1000.0, 1000.0, 0.0);
    let _emu = rplidar::Lidar::start(&port, room);
    let rt = start(&format!(
        "driver rplidar\nserial {}\nprovides laser 360 1\nend_driver\nload_driver rplidar\n",
        port.display()
    ));
    let laser: Arc<Interface<Laser>> = rt.interfaces.get("laser").unwrap();
    let t0 = Instant::now();
    while laser.clock() < 3 && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(10));
    }
    let mut shares = Vec::new();
    for _ in 0..5 {
        let (c0, w0, k0) = (threads_cpu("rplidar"), Instant::now(), laser.clock());
        std::thread::sleep(Duration::from_secs(1));
        let cpu = threads_cpu("rplidar") - c0;
        let wall = w0.elapsed().as_secs_f64();
        shares.push(cpu / wall * 100.0);
        let _ = k0;
    }
    let hz = {
        let (k0, w0) = (laser.clock(), Instant::now());
        std::thread::sleep(Duration::from_secs(2));
        (laser.clock() - k0) as f64 / w0.elapsed().as_secs_f64()
    };
    println!(
        "rplidar driver thread on the emulator: {:.2} % of one core (median of 5 s), {hz:.2} scans/s",
        median(&shares)
    );
    rt.shutdown();
}

fn bench_roomba_latency() {
    let dir = tempfile::tempdir().unwrap();
    let port = dir.path().join("create2");
    let room = room::Room::new(40_000.0, 40_000.0, 20_000.0, 20_000.0, 0.0);
    let emu = create2::Create2::start(&port, room);
    let rt = start(&format!(
        "driver roomba\nserial {}\nprovides motors\nprovides encoders\nend_driver\nload_driver roomba\n",
        port.display()
    ));
    let mot: Arc<Interface<Motors>> = rt.interfaces.get("motors").unwrap();
    let enc: Arc<Interface<jderobot::interfaces::Encoders>> =
        rt.interfaces.get("encoders").unwrap();
    let t0 = Instant::now();
    while (enc.clock() < 3 || enc.stale().is_some()) && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(10));
    }
    let mut lat = Vec::new();
    for i in 0..60 {
        let v = 20 + (i % 2) * 10;
        let t0 = Instant::now();
        mot.publish(Motors {
            v: v as f32,
            w: 0.0,
        })
        .unwrap();
        loop {
            if let Some((at, w)) = emu.state.lock().last_drive
                && w == (v as i16, v as i16)
                && at >= t0
            {
                lat.push(at.duration_since(t0).as_secs_f64());
                break;
            }
            if t0.elapsed() > Duration::from_secs(2) {
                break;
            }
            std::hint::spin_loop();
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let byte_time = 5.0 * 10.0 / 115_200.0;
    let m = median(&lat);
    println!(
        "roomba command → wheels (emulated Create 2): median {:.0} µs, p90 {:.0} µs over {} commands; \
         the cable's own 5 bytes at 115200 baud: {:.0} µs (ratio {:.2})",
        m * 1e6,
        common::percentile(&lat, 90.0) * 1e6,
        lat.len(),
        byte_time * 1e6,
        m / byte_time
    );
    rt.shutdown();
}

fn main() {
    bench_decode();
    bench_lidar_thread();
    bench_roomba_latency();
}
