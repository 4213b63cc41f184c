//! Pan-tilt benchmarks, medians. Run with
//! `cargo bench --features full --bench pantilt`.
//!
//! Goals (issue 18):
//! - followball, image in to pan-tilt command out: ≤ 2 ms at 320x240, ≤ 5 ms at
//!   640x480 (reference in the same run: one plain RGB-threshold centroid pass over
//!   the same image, the least any colour tracker does);
//! - serial drivers, command set to its bytes on the wire: ≤ 1 ms (pantilt and evi,
//!   against the pty emulators of the tests);
//! - the pantilt encoder poll keeps its period (300 ms) within 1 %.

#[path = "../tests/emulators/ptu.rs"]
mod ptu;
#[path = "../tests/emulators/visca.rs"]
mod visca;

mod common;
use common::median;

use std::{
    hint::black_box,
    path::Path,
    time::{Duration, Instant},
};

use jderobot::{
    interfaces::{Image, PtEncoders, PtMotors, ZoomMotors},
    schemas::followball::{Settings, Stop, Tracker, command},
};

/// A floor-like background with a shaded red ball of radius `r` at (cx, cy).
fn scene(w: u32, h: u32, cx: f32, cy: f32, r: f32) -> Image {
    let mut img = Image::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let i = ((y * w + x) * 3) as usize;
            let d = ((x as f32 - cx).powi(2) + (y as f32 - cy).powi(2)).sqrt();
            let px = if d < r {
                let k = 0.55 + 0.5 * (1.0 - d / r);
                [(30.0 * k) as u8, (30.0 * k) as u8, (220.0 * k) as u8]
            } else {
                let g = (120 + (x + y) % 40) as u8;
                [g, g, g.saturating_add(10)]
            };
            img.data[i..i + 3].copy_from_slice(&px);
        }
    }
    img
}

fn reference_pass(img: &Image) -> (f32, f32) {
    let (mut n, mut sx, mut sy) = (0u64, 0u64, 0u64);
    for (i, p) in img.data.chunks_exact(3).enumerate() {
        if p[2] as u32 > 2 * p[1] as u32 && p[2] as u32 > 2 * p[0] as u32 {
            n += 1;
            sx += (i % img.width as usize) as u64;
            sy += (i / img.width as usize) as u64;
        }
    }
    (sx as f32 / n.max(1) as f32, sy as f32 / n.max(1) as f32)
}

fn followball(w: u32, h: u32, goal_ms: f64) {
    let img = scene(w, h, w as f32 * 0.7, h as f32 * 0.6, w as f32 / 16.0);
    let mut t = Tracker::new(Settings::default());
    let here = PtEncoders::default();
    let lim = PtMotors::default();
    let (d, _) = t.decide(&img);
    assert!(
        d.centroid.is_some() && d.moving,
        "the bench scene has a ball"
    );
    let reps = 200;
    let mut ours = Vec::with_capacity(reps);
    let mut refs = Vec::with_capacity(reps);
    for _ in 0..reps {
        let t0 = Instant::now();
        let (d, mask) = t.decide(black_box(&img));
        black_box(command(&d, &here, &lim, Stop::Position));
        black_box(mask);
        ours.push(t0.elapsed().as_secs_f64() * 1e3);
        let t0 = Instant::now();
        black_box(reference_pass(black_box(&img)));
        refs.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    let (m, r) = (median(ours), median(refs));
    println!(
        "followball {w}x{h}: image -> command {m:.3} ms (goal <= {goal_ms} ms: {}), reference RGB centroid pass {r:.3} ms, ratio {:.2}x",
        if m <= goal_ms { "met" } else { "MISSED" },
        m / r
    );
}

fn start(text: &str) -> std::sync::Arc<jderobot::Runtime> {
    let conf = jderobot::Conf::parse(text, Path::new("bench.conf")).expect("conf");
    jderobot::loader::start(&conf).expect("start")
}

fn wait(what: &str, mut f: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !f() {
        assert!(t0.elapsed() < Duration::from_secs(20), "timed out: {what}");
        std::thread::sleep(Duration::from_millis(1));
    }
}

fn ptu_latency_and_poll() {
    let dir = tempfile::tempdir().unwrap();
    let port = dir.path().join("ptu");
    let unit = ptu::Ptu::start(&port);
    let rt = start(&format!(
        "driver pantilt\nserial {}\nprovides pantiltencoders\nprovides pantiltmotors\nend_driver\nload_driver pantilt\n",
        port.display()
    ));
    let enc = rt.interfaces.get::<PtEncoders>("pantiltencoders").unwrap();
    let mot = rt.interfaces.get::<PtMotors>("pantiltmotors").unwrap();
    wait("pantilt running", || enc.clock() > 1);
    // Command -> bytes.
    let mut lat = Vec::new();
    for k in 0..60 {
        let before = unit.state.lock().received.len();
        let mut v = mot.read().value;
        v.longitude = if k % 2 == 0 { 10.0 } else { 20.0 };
        let t0 = Instant::now();
        mot.publish(v).unwrap();
        wait("PP on the wire", || {
            let s = unit.state.lock();
            s.received[before..].windows(2).any(|w| w == b"PP")
                && s.received[before..].contains(&b'\n')
                && s.last_rx.is_some_and(|t| t > t0)
                && s.received[before..]
                    .split(|&c| c == b'\n')
                    .any(|l| l.starts_with(b"PP") && l.len() > 2)
        });
        let at = unit.state.lock().last_rx.unwrap();
        lat.push(at.duration_since(t0).as_secs_f64() * 1e3);
        std::thread::sleep(Duration::from_millis(17));
    }
    let m = median(lat);
    println!(
        "pantilt: command -> bytes on the wire {m:.3} ms (goal <= 1 ms: {})",
        if m <= 1.0 { "met" } else { "MISSED" }
    );
    // Poll period: the encoders' publish times over 20 periods.
    let mut stamps = Vec::new();
    let mut last = enc.clock();
    while stamps.len() < 21 {
        let s = enc.snapshot();
        if s.clock != last {
            last = s.clock;
            stamps.push(s.stamp);
        }
        std::thread::sleep(Duration::from_micros(200));
    }
    let periods: Vec<f64> = stamps
        .windows(2)
        .map(|w| w[1].duration_since(w[0]).as_secs_f64() * 1e3)
        .collect();
    let mean = stamps[20].duration_since(stamps[0]).as_secs_f64() * 1e3 / 20.0;
    let worst = periods
        .iter()
        .map(|p| (p - 300.0).abs() / 300.0 * 100.0)
        .fold(0.0, f64::max);
    let med = median(periods);
    println!(
        "pantilt: poll period median {med:.2} ms, mean {mean:.2} ms over 20 ({:.2} % off; goal within 1 %: {}), worst single period {worst:.2} % off",
        (mean - 300.0).abs() / 3.0,
        if (mean - 300.0).abs() / 300.0 <= 0.01 && (med - 300.0).abs() / 300.0 <= 0.01 {
            "met"
        } else {
            "MISSED"
        }
    );
    rt.shutdown();
}

fn evi_latency() {
    let dir = tempfile::tempdir().unwrap();
    let port = dir.path().join("evi");
    let cam = visca::Evi::start(&port);
    let rt = start(&format!(
        "driver evi\nserial {}\nprovides pantiltencoders\nprovides zoommotors\nend_driver\nload_driver evi\n",
        port.display()
    ));
    let enc = rt.interfaces.get::<PtEncoders>("pantiltencoders").unwrap();
    let zm = rt.interfaces.get::<ZoomMotors>("zoommotors").unwrap();
    wait("evi running", || enc.clock() > 1);
    let mut lat = Vec::new();
    for k in 0..60 {
        let before = cam.state.lock().received.len();
        let mut v = zm.read().value;
        v.zoom = if k % 2 == 0 { 10.0 } else { 11.0 };
        let t0 = Instant::now();
        zm.publish(v).unwrap();
        wait("zoom packet on the wire", || {
            let s = cam.state.lock();
            s.received[before..]
                .windows(4)
                .any(|w| w == [0x81, 0x01, 0x04, 0x47])
                && s.received.ends_with(&[0xFF])
        });
        let at = cam.state.lock().last_rx.unwrap();
        lat.push(at.duration_since(t0).as_secs_f64() * 1e3);
        std::thread::sleep(Duration::from_millis(17));
    }
    let m = median(lat);
    println!(
        "evi: command -> bytes on the wire {m:.3} ms (goal <= 1 ms: {})",
        if m <= 1.0 { "met" } else { "MISSED" }
    );
    rt.shutdown();
}

fn main() {
    followball(320, 240, 2.0);
    followball(640, 480, 5.0);
    ptu_latency_and_poll();
    evi_latency();
}
