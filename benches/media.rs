//! Video into `varcolorA`: the opencv driver's `videofile` (ffmpeg child) and the
//! mplayer driver (mplayer child, YUV4MPEG2, our 4:2:0 → BGR), on a 640x480 clip
//! the bench makes with the `ffmpeg` program.
//!
//! - unpaced: frames per second published on varcolorA (first to last frame, the
//!   child's start-up excluded), against the program alone writing the same raw
//!   frames to a pipe we only count (the reference, measured in the same run);
//!   target ≥ 300 frames/s.
//! - paced: the rate of published frames against the file's 30 fps; target within 1 %.
//! - the 640x480 4:2:0 → BGR conversion alone.
//!
//! `cargo bench --features full --bench media` (needs ffmpeg and mplayer).

mod common;
use common::median;

use std::{
    io::Read,
    path::Path,
    process::{Command, Stdio},
    sync::Arc,
    time::{Duration, Instant},
};

use jderobot::{Conf, Interface, Runtime, interfaces::Image};

const FRAMES: u64 = 300;
const FPS: f64 = 30.0;
const REPS: usize = 5;

fn make_clip(dir: &Path) -> std::path::PathBuf {
    let out = dir.join("bench640.avi");
    let st = Command::new("ffmpeg")
        .args([
            "-v",
            "error",
            "-y",
            "-f",
            "lavfi",
            "-i",
            "testsrc=size=640x480:rate=30",
            "-frames:v",
            &FRAMES.to_string(),
            "-pix_fmt",
            "yuv420p",
            "-c:v",
            "mpeg4",
            "-q:v",
            "5",
        ])
        .arg(&out)
        .status()
        .expect("ffmpeg (Debian package ffmpeg) is needed");
    assert!(st.success());
    out
}

fn start(dir: &Path, body: &str) -> Arc<Runtime> {
    let f = dir.join("bench.conf");
    std::fs::write(&f, body).unwrap();
    let conf = Conf::load(&f).unwrap_or_else(|e| panic!("{e}"));
    jderobot::loader::start(&conf).unwrap_or_else(|e| panic!("{e}"))
}

/// Plays the clip on varcolorA (to its end, or `min_frames`); returns the frames and
/// seconds from the first frame seen to the last frame's publish, and the last clock.
fn play(dir: &Path, body: &str, min_frames: u64) -> (u64, f64, u64) {
    let rt = start(dir, body);
    let i: Arc<Interface<Image>> = rt.interfaces.get("varcolorA").unwrap();
    rt.run("varcolorA").unwrap();
    let t0 = Instant::now();
    let (c0, s0) = loop {
        let s = i.snapshot();
        if s.clock >= 1 {
            break (s.clock, s.stamp);
        }
        assert!(t0.elapsed() < Duration::from_secs(30), "no frame");
        std::thread::yield_now();
    };
    while i.stale().is_none() && i.clock() < min_frames {
        assert!(t0.elapsed() < Duration::from_secs(60), "never ended");
        std::thread::sleep(Duration::from_millis(1));
    }
    let last = i.snapshot();
    rt.shutdown();
    (
        last.clock - c0,
        last.stamp.duration_since(s0).as_secs_f64(),
        last.clock,
    )
}

/// The program alone: raw frames to a pipe we count; frames per second after the
/// first byte.
fn reference(cmd: &mut Command, frame_bytes: usize) -> f64 {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut out = child.stdout.take().unwrap();
    let mut buf = vec![0u8; 1 << 20];
    let mut total = 0usize;
    let mut first = None;
    loop {
        let n = out.read(&mut buf).unwrap();
        if n == 0 {
            break;
        }
        first.get_or_insert_with(Instant::now);
        total += n;
    }
    let secs = first.map(|t| t.elapsed().as_secs_f64()).unwrap_or(1.0);
    child.wait().unwrap();
    (total / frame_bytes) as f64 / secs
}

fn main() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = make_clip(d);
    let clip = clip.display();
    println!("media: 640x480 mpeg4 clip, {FRAMES} frames at {FPS} fps; medians of {REPS} runs");

    // Unpaced throughput into varcolorA, and the program alone.
    let ff_conf = format!(
        "driver opencv\nprovides varcolorA videofile {clip} 640 480 unpaced\nend_driver\nload_driver opencv\n"
    );
    let mp_conf = format!(
        "driver mplayer\nprovides varcolorA {clip} 640 480 repeat_off unpaced\nend_driver\nload_driver mplayer\n"
    );
    let mut ours = [Vec::new(), Vec::new()];
    let mut refs = [Vec::new(), Vec::new()];
    for _ in 0..REPS {
        for (k, conf) in [&ff_conf, &mp_conf].into_iter().enumerate() {
            let (n, s, total) = play(d, conf, FRAMES);
            assert_eq!(total, FRAMES, "every frame published");
            ours[k].push(n as f64 / s);
        }
        refs[0].push(reference(
            Command::new("ffmpeg")
                .args(["-nostdin", "-v", "error", "-i"])
                .arg(clip.to_string())
                .args(["-f", "rawvideo", "-pix_fmt", "bgr24", "pipe:1"]),
            640 * 480 * 3,
        ));
        refs[1].push(reference(
            Command::new("sh").arg("-c").arg(format!(
                "mplayer -really-quiet -noconsolecontrols -nolirc -nosound -benchmark \
                 -vo yuv4mpeg:file=/dev/fd/3 '{clip}' 3>&1 >/dev/null 2>&1"
            )),
            640 * 480 * 3 / 2 + 6,
        ));
    }
    for (k, name) in ["opencv videofile (ffmpeg)", "mplayer"].iter().enumerate() {
        let (o, r) = (median(ours[k].clone()), median(refs[k].clone()));
        println!(
            "unpaced {name:<26} {o:8.0} frames/s into varcolorA | program alone {r:8.0} frames/s | ratio {:.2} | target >= 300: {}",
            o / r,
            if o >= 300.0 { "met" } else { "NOT MET" }
        );
    }

    // Paced: the published rate against the file's.
    for (name, conf) in [
        ("opencv videofile (ffmpeg)", ff_conf.replace(" unpaced", "")),
        ("mplayer", mp_conf.replace(" unpaced", "")),
    ] {
        let mut rates = Vec::new();
        for _ in 0..3 {
            let (n, s, _) = play(d, &conf, 91);
            rates.push(n as f64 / s);
        }
        let r = median(rates);
        let err = (r / FPS - 1.0) * 100.0;
        println!(
            "paced   {name:<26} {r:8.3} frames/s (file {FPS} fps) | error {err:+.3} % | target within 1 %: {}",
            if err.abs() <= 1.0 { "met" } else { "NOT MET" }
        );
    }

    // The conversion alone.
    let (w, h) = (640usize, 480usize);
    let src: Vec<u8> = (0..w * h * 3 / 2).map(|i| (i * 7 % 251) as u8).collect();
    let mut out = vec![0u8; w * h * 3];
    let mut times = Vec::new();
    for _ in 0..200 {
        let t = Instant::now();
        jderobot::media::y4m::i420_to_bgr(&src, w, h, w, h, &mut out);
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    std::hint::black_box(&out);
    println!(
        "i420_to_bgr 640x480: {:.3} ms (median of 200)",
        median(times)
    );
}
