//! imagefile, opencv and mplayer against the real things: 4.3-style PNM files and
//! PNG/JPEG/BMP files written by ffmpeg, short clips made by the `ffmpeg` program,
//! the real `mplayer` and `ffmpeg` as child processes, and the real binary.
//!
//! ffmpeg and mplayer must be installed; without them a test says so and passes,
//! except under `CI`, where it fails.
#![cfg(all(feature = "imagefile", feature = "opencv", feature = "mplayer"))]

use crate::common;

use std::{
    path::{Path, PathBuf},
    process::{Command, Stdio},
    sync::Arc,
    time::{Duration, Instant},
};

use common::{eventually, have, need, poll_until, root};
use jderobot::{Conf, Interface, Runtime, interfaces::Image};

/// Writes `conf` as `dir/test.conf` and starts a runtime from it.
fn start_in(dir: &Path, conf: &str) -> Result<Arc<Runtime>, String> {
    let file = dir.join("test.conf");
    std::fs::write(&file, conf).unwrap();
    let conf = Conf::load(&file).map_err(|e| e.to_string())?;
    jderobot::loader::start(&conf).map_err(|e| e.to_string())
}

fn image(rt: &Runtime, name: &str) -> Arc<Interface<Image>> {
    rt.interfaces.get(name).unwrap()
}

/// Makes a clip with ffmpeg's lavfi source `src` (e.g. `color=c=red:size=320x240:rate=25`).
fn clip(dir: &Path, name: &str, src: &str, frames: u32) -> PathBuf {
    let out = dir.join(name);
    let st = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-f", "lavfi", "-i", src, "-frames:v"])
        .arg(frames.to_string())
        .args(["-pix_fmt", "yuv420p", "-c:v", "mpeg4", "-q:v", "2"])
        .arg(&out)
        .status()
        .expect("run ffmpeg");
    assert!(st.success(), "ffmpeg could not make {name}");
    out
}

/// Converts an image file with ffmpeg (PNG, BMP, JPEG from a PPM).
fn convert(from: &Path, to: &Path) {
    let st = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-i"])
        .arg(from)
        .args(["-q:v", "2"])
        .arg(to)
        .status()
        .expect("run ffmpeg");
    assert!(st.success(), "ffmpeg could not write {}", to.display());
}

/// The smooth test pattern: r = x*255/(w-1), g = y*255/(h-1), b = 128.
fn pattern(x: u32, y: u32, w: u32, h: u32) -> [u8; 3] {
    [(x * 255 / (w - 1)) as u8, (y * 255 / (h - 1)) as u8, 128]
}

/// A 4.3-style binary PPM (P6, with GIMP's comment line) of the pattern.
fn write_p6(path: &Path, w: u32, h: u32) {
    let mut f = format!("P6\n# CREATOR: GIMP PNM Filter Version 1.1\n{w} {h}\n255\n").into_bytes();
    for y in 0..h {
        for x in 0..w {
            f.extend_from_slice(&pattern(x, y, w, h));
        }
    }
    std::fs::write(path, f).unwrap();
}

/// Mean absolute difference between an image and the pattern (BGR vs RGB).
fn pattern_error(img: &Image) -> f64 {
    let (w, h) = (img.width, img.height);
    let mut sum = 0u64;
    for y in 0..h {
        for x in 0..w {
            let [b, g, r] = img.pixel(x, y);
            let [pr, pg, pb] = pattern(x, y, w, h);
            sum += (r as i64 - pr as i64).unsigned_abs()
                + (g as i64 - pg as i64).unsigned_abs()
                + (b as i64 - pb as i64).unsigned_abs();
        }
    }
    sum as f64 / (w * h * 3) as f64
}

/// Every pixel of `img` within `tol` of BGR `want`.
fn all_near(img: &Image, want: [u8; 3], tol: u8) -> bool {
    img.data
        .chunks_exact(3)
        .all(|p| (0..3).all(|c| p[c].abs_diff(want[c]) <= tol))
}

// ---------------------------------------------------------------- imagefile

#[test]
fn imagefile_reads_43_pnm_and_png_jpeg_bmp() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_p6(&d.join("casaleft.pnm"), 320, 240);
    write_p6(&d.join("wide.ppm"), 400, 300);
    // P5 (grey) and P3 (ASCII), comments where 4.3's sample files had them.
    let mut p5 = b"P5\n# grey\n320 240\n255\n".to_vec();
    p5.extend((0..320 * 240).map(|i| (i % 251) as u8));
    std::fs::write(d.join("grey.pgm"), p5).unwrap();
    std::fs::write(
        d.join("tiny.ppm"),
        "P3\n# ascii\n2 1\n255\n255 0 0  0 0 255\n",
    )
    .unwrap();
    if !need("ffmpeg") {
        return;
    }
    convert(&d.join("wide.ppm"), &d.join("wide.png"));
    convert(&d.join("wide.ppm"), &d.join("wide.bmp"));
    convert(&d.join("wide.ppm"), &d.join("wide.jpg"));
    let rt = start_in(
        d,
        "driver imagefile\n\
         provides colorA casaleft.pnm\n\
         provides colorB grey.pgm\n\
         provides colorC wide.png scale\n\
         provides varcolorA wide.png\n\
         provides varcolorB wide.bmp 640 480\n\
         provides varcolorC wide.jpg\n\
         provides varcolorD tiny.ppm\n\
         end_driver\nload_driver imagefile\n",
    )
    .unwrap();
    let names = [
        "colorA",
        "colorB",
        "colorC",
        "varcolorA",
        "varcolorB",
        "varcolorC",
        "varcolorD",
    ];
    std::thread::sleep(Duration::from_millis(250));
    for n in names {
        assert_eq!(
            image(&rt, n).clock(),
            0,
            "{n} published before anyone used it"
        );
        rt.run(n).unwrap();
    }
    for n in names {
        let i = image(&rt, n);
        eventually(n, || i.clock() == 1);
    }
    let a = image(&rt, "colorA").snapshot();
    assert_eq!((a.width, a.height), (320, 240));
    assert_eq!(pattern_error(&a), 0.0, "P6 read exactly, as BGR");
    let g = image(&rt, "colorB").snapshot();
    assert_eq!(g.pixel(7, 0), [7, 7, 7]);
    assert_eq!(g.pixel(0, 1), [(320 % 251) as u8; 3]);
    let c = image(&rt, "colorC").snapshot();
    assert_eq!((c.width, c.height), (320, 240));
    assert!(pattern_error(&c) < 2.0, "scaled PNG {}", pattern_error(&c));
    let png = image(&rt, "varcolorA").snapshot();
    assert_eq!((png.width, png.height), (400, 300), "autosize");
    assert_eq!(pattern_error(&png), 0.0, "PNG is lossless");
    let bmp = image(&rt, "varcolorB").snapshot();
    assert_eq!((bmp.width, bmp.height), (640, 480));
    assert!(
        pattern_error(&bmp) < 2.0,
        "BMP scaled to 640x480: {}",
        pattern_error(&bmp)
    );
    let jpg = image(&rt, "varcolorC").snapshot();
    assert_eq!((jpg.width, jpg.height), (400, 300));
    assert!(
        pattern_error(&jpg) < 6.0,
        "JPEG within its loss: {}",
        pattern_error(&jpg)
    );
    let t = image(&rt, "varcolorD").snapshot();
    assert_eq!(t.data, [0, 0, 255, 255, 0, 0]);
    rt.shutdown();
}

#[test]
fn imagefile_bad_files_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_p6(&d.join("big.ppm"), 640, 480);
    let mut short = b"P6\n320 240\n255\n".to_vec();
    short.extend(vec![0u8; 1000]);
    std::fs::write(d.join("short.ppm"), short).unwrap();
    std::fs::write(d.join("notes.txt"), "hello, I am not an image\n").unwrap();
    std::fs::write(d.join("broken.png"), b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR\0\0").unwrap();
    let cases = [
        (
            "provides colorA big.ppm",
            &[
                "test.conf:2",
                "big.ppm",
                "image size mismatch",
                "640x480",
                "scale",
            ][..],
        ),
        (
            "provides colorA short.ppm",
            &["test.conf:2", "short.ppm", "truncated"][..],
        ),
        (
            "provides varcolorA notes.txt",
            &["notes.txt", "not an image"][..],
        ),
        (
            "provides varcolorA broken.png",
            &["broken.png", "cannot decode"][..],
        ),
        (
            "provides varcolorA missing.ppm",
            &["missing.ppm", "cannot read"][..],
        ),
        (
            "provides varcolorA big.ppm 0 10",
            &["test.conf:2", "W (argument 3) is `0`"][..],
        ),
        (
            "provides colorA big.ppm 640 480",
            &["test.conf:2", "scale"][..],
        ),
        (
            "provides laser big.ppm",
            &["test.conf:2", "not `laser`"][..],
        ),
        ("frobnicate 1", &["test.conf:2", "frobnicate"][..]),
    ];
    for (line, want) in cases {
        let e = start_in(
            d,
            &format!("driver imagefile\n{line}\nend_driver\nload_driver imagefile\n"),
        )
        .err()
        .unwrap_or_else(|| panic!("`{line}` loaded"));
        for w in want {
            assert!(e.contains(w), "`{line}`: {w:?} missing in: {e}");
        }
    }
}

#[test]
fn imagefile_reloads_on_resume_and_when_the_file_changes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let f = d.join("a.ppm");
    let flat = |v: u8| {
        let mut b = b"P6\n4 2\n255\n".to_vec();
        b.extend(vec![v; 24]);
        b
    };
    std::fs::write(&f, flat(10)).unwrap();
    let rt = start_in(
        d,
        "driver imagefile\nprovides varcolorA a.ppm\nend_driver\nload_driver imagefile\n",
    )
    .unwrap();
    let i = image(&rt, "varcolorA");
    rt.run("varcolorA").unwrap();
    eventually("first image", || i.clock() == 1);
    assert_eq!(i.read().pixel(0, 0), [10, 10, 10]);
    rt.stop("varcolorA").unwrap();
    std::fs::write(&f, flat(20)).unwrap();
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(i.clock(), 1, "not read while unused");
    rt.run("varcolorA").unwrap();
    eventually("reloaded on resume", || {
        i.clock() == 2 && i.read().pixel(0, 0) == [20, 20, 20]
    });
    // While used: a changed file is published again (mtime granularity: wait a bit).
    std::thread::sleep(Duration::from_millis(1100));
    std::fs::write(&f, flat(30)).unwrap();
    eventually("reloaded on change", || {
        i.clock() == 3 && i.read().pixel(0, 0) == [30, 30, 30]
    });
    // A file that goes bad: the last image stays, the interface is stale with the reason.
    std::thread::sleep(Duration::from_millis(1100));
    std::fs::write(&f, b"P6\n4 2\n255\n\0\0").unwrap();
    eventually("stale", || {
        i.stale()
            .is_some_and(|s| s.contains("truncated") && s.contains("a.ppm"))
    });
    assert_eq!(i.read().pixel(0, 0), [30, 30, 30]);
    rt.shutdown();
}

// ------------------------------------------------------------------- opencv

#[test]
fn opencv_videofile_plays_every_frame_loops_and_pauses() {
    if !need("ffmpeg") || !need("ffprobe") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    clip(d, "red.avi", "color=c=red:size=320x240:rate=25", 20);
    clip(d, "blue.avi", "color=c=blue:size=160x120:rate=25", 10);
    write_p6(&d.join("still.ppm"), 320, 240);
    let rt = start_in(
        d,
        "driver opencv\n\
         provides varcolorA videofile red.avi autosize unpaced\n\
         provides colorB videofile blue.avi loop unpaced\n\
         provides varcolorC videofile blue.avi 64 48\n\
         provides varcolorD image still.ppm 160 120\n\
         end_driver\nload_driver opencv\n",
    )
    .unwrap();
    let (a, b, c, s) = (
        image(&rt, "varcolorA"),
        image(&rt, "colorB"),
        image(&rt, "varcolorC"),
        image(&rt, "varcolorD"),
    );
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(
        (a.clock(), b.clock(), c.clock(), s.clock()),
        (0, 0, 0, 0),
        "nothing decoded while unused"
    );
    // Unpaced, no loop: exactly the file's 20 frames, then stale "end of the video".
    rt.run("varcolorA").unwrap();
    eventually("end of red.avi", || {
        a.stale().is_some_and(|s| s.contains("end of the video"))
    });
    assert_eq!(a.clock(), 20, "one publish per frame");
    let f = a.snapshot();
    assert_eq!((f.width, f.height), (320, 240));
    assert!(
        all_near(&f, [0, 0, 254], 12),
        "red in BGR: {:?}",
        f.pixel(10, 10)
    );
    // Run again (the driver looks every 50 ms whether it is still used): it plays
    // again from the start.
    rt.stop("varcolorA").unwrap();
    std::thread::sleep(Duration::from_millis(300));
    rt.run("varcolorA").unwrap();
    eventually("replayed", || a.clock() == 40);
    // loop: past the end of the 10-frame clip; colorB is scaled to 320x240.
    rt.run("colorB").unwrap();
    eventually("looping", || b.clock() > 25);
    let f = b.snapshot();
    assert_eq!((f.width, f.height), (320, 240));
    assert!(
        all_near(&f, [254, 0, 0], 12),
        "blue in BGR: {:?}",
        f.pixel(10, 10)
    );
    // Paused while unused: the clock stops.
    rt.stop("colorB").unwrap();
    std::thread::sleep(Duration::from_millis(200));
    let k = b.clock();
    std::thread::sleep(Duration::from_millis(400));
    assert!(
        b.clock() <= k + 1,
        "decoding while unused: {k} -> {}",
        b.clock()
    );
    // Paced at the file's 25 fps: 10 frames take at least ~0.36 s.
    let t0 = Instant::now();
    rt.run("varcolorC").unwrap();
    eventually("paced clip ends", || c.stale().is_some());
    assert_eq!(c.clock(), 10);
    assert!(
        t0.elapsed() >= Duration::from_millis(340),
        "not paced: {:?}",
        t0.elapsed()
    );
    assert_eq!((c.read().width, c.read().height), (64, 48));
    // A still image, scaled.
    rt.run("varcolorD").unwrap();
    eventually("still image", || s.clock() == 1);
    assert!(pattern_error(&s.snapshot()) < 2.0);
    rt.shutdown();
}

#[test]
fn opencv_bad_sources_are_clear_errors() {
    if !need("ffmpeg") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("garbage.avi"), "this is not a video\n".repeat(100)).unwrap();
    let cases = [
        (
            "provides varcolorA videofile missing.avi 320 240",
            &["test.conf:2", "missing.avi", "no such video file"][..],
        ),
        (
            "provides varcolorA videofile garbage.avi",
            &["test.conf:2", "garbage.avi", "not a video"][..],
        ),
        (
            "provides colorA video /dev/video99",
            &["test.conf:2", "/dev/video99", "no such capture device"][..],
        ),
        (
            "provides varcolorA movie x.avi",
            &["test.conf:2", "`movie`"][..],
        ),
        (
            "provides varcolorA videofile x.avi 320 240 sometimes",
            &["test.conf:2", "`sometimes`"][..],
        ),
    ];
    for (line, want) in cases {
        let e = start_in(
            d,
            &format!("driver opencv\n{line}\nend_driver\nload_driver opencv\n"),
        )
        .err()
        .unwrap_or_else(|| panic!("`{line}` loaded"));
        for w in want {
            assert!(e.contains(w), "`{line}`: {w:?} missing in: {e}");
        }
    }
}

// ------------------------------------------------------------------ mplayer

/// Child processes of process `pid` whose command line contains `needle`.
fn children_with(pid: u32, needle: &str) -> Vec<u32> {
    let mut out = Vec::new();
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return out;
    };
    for t in tasks.flatten() {
        let Ok(list) = std::fs::read_to_string(t.path().join("children")) else {
            continue;
        };
        for c in list
            .split_whitespace()
            .filter_map(|c| c.parse::<u32>().ok())
        {
            let cmd = std::fs::read(format!("/proc/{c}/cmdline")).unwrap_or_default();
            if String::from_utf8_lossy(&cmd).contains(needle) {
                out.push(c);
            }
        }
    }
    out
}

fn alive(pid: u32) -> bool {
    // A zombie is dead too.
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|s| {
        s.rsplit(')')
            .next()
            .is_some_and(|r| !r.trim_start().starts_with('Z'))
    })
}

#[test]
fn mplayer_plays_files_repeats_and_reports_failures() {
    if !need("ffmpeg") || !need("mplayer") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    clip(d, "green.avi", "color=c=0x00ff00:size=320x240:rate=25", 12);
    clip(d, "loop.avi", "testsrc=size=320x240:rate=25", 8);
    std::fs::write(d.join("bad.avi"), "not a video at all\n".repeat(200)).unwrap();
    let rt = start_in(
        d,
        "driver mplayer\n\
         provides varcolorA green.avi 640 480 repeat_off unpaced\n\
         provides colorB loop.avi repeat_on unpaced\n\
         provides colorC bad.avi repeat_on\n\
         provides varcolorD green.avi 321 241 repeat_off\n\
         provides colorA v4l /dev/video99 cam\n\
         end_driver\nload_driver mplayer\n",
    )
    .unwrap();
    let (a, b, c, dd) = (
        image(&rt, "varcolorA"),
        image(&rt, "colorB"),
        image(&rt, "colorC"),
        image(&rt, "varcolorD"),
    );
    std::thread::sleep(Duration::from_millis(300));
    assert!(
        children_with(std::process::id(), "green.avi").is_empty(),
        "no mplayer while unused"
    );
    assert_eq!(a.clock(), 0);
    rt.run("varcolorA").unwrap();
    eventually("end of green.avi", || {
        a.stale().is_some_and(|s| s.contains("end of the video"))
    });
    assert_eq!(a.clock(), 12, "one publish per frame, every frame");
    let f = a.snapshot();
    assert_eq!((f.width, f.height), (640, 480));
    assert!(
        all_near(&f, [0, 255, 0], 14),
        "green in BGR: {:?}",
        f.pixel(5, 5)
    );
    // repeat_on: mplayer is started again at the end.
    rt.run("colorB").unwrap();
    eventually("repeating", || b.clock() > 20);
    assert!(b.stale().is_none());
    // An odd size is cropped from mplayer's even one.
    rt.run("varcolorD").unwrap();
    eventually("odd size", || dd.clock() > 0);
    assert_eq!(
        (dd.read().width, dd.read().height, dd.read().data.len()),
        (321, 241, 321 * 241 * 3)
    );
    // A file mplayer cannot play: stale with mplayer's own words, no frames.
    rt.run("colorC").unwrap();
    eventually("bad.avi is stale", || {
        c.stale()
            .is_some_and(|s| s.contains("bad.avi") && s.contains("mplayer said"))
    });
    assert_eq!(c.clock(), 0);
    // A v4l device that is not there: stale, naming it (mplayer is retried).
    let v = image(&rt, "colorA");
    rt.run("colorA").unwrap();
    eventually("/dev/video99 is stale", || {
        v.stale().is_some_and(|s| s.contains("/dev/video99"))
    });
    assert_eq!(v.clock(), 0);
    // The child dies while playing: stale with the reason, then a new mplayer.
    let loops = || children_with(std::process::id(), "loop.avi");
    eventually("an mplayer for loop.avi", || !loops().is_empty());
    let victim = loops()[0];
    unsafe {
        libc::kill(victim as i32, libc::SIGKILL);
    }
    eventually("stale after the kill", || {
        b.stale().is_some_and(|s| s.contains("mplayer"))
    });
    let k = b.clock();
    eventually("a new mplayer plays again", || {
        b.clock() > k + 3 && b.stale().is_none()
    });
    rt.shutdown();
    assert!(
        poll_until(10, || children_with(
            std::process::id(),
            d.to_str().unwrap()
        )
        .iter()
        .all(|p| !alive(*p))),
        "mplayer children left after shutdown"
    );
}

/// The real binary: mplayer children die with jderobot, even on SIGKILL.
#[test]
fn mplayer_never_outlives_jderobot() {
    if !need("ffmpeg") || !need("mplayer") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    clip(d, "long.avi", "testsrc=size=320x240:rate=25", 100);
    let conf = d.join("m.conf");
    std::fs::write(
        &conf,
        "driver mplayer\nprovides colorA long.avi repeat_on\nend_driver\nload_driver mplayer\n",
    )
    .unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_jderobot"))
        .arg("--headless")
        .arg(&conf)
        .env_remove("DISPLAY")
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    {
        use std::io::Write;
        child
            .stdin
            .as_mut()
            .unwrap()
            .write_all(b"run colorA\n")
            .unwrap();
    }
    let mut players = Vec::new();
    assert!(
        poll_until(20, || {
            players = children_with(child.id(), "long.avi");
            !players.is_empty()
        }),
        "no mplayer child"
    );
    child.kill().unwrap(); // SIGKILL: no destructor runs, only the kernel's PDEATHSIG
    child.wait().unwrap();
    assert!(
        poll_until(10, || players.iter().all(|p| !alive(*p))),
        "mplayer {players:?} outlived jderobot"
    );
}

/// The real binary without mplayer on PATH: one clear error naming the package.
#[test]
fn missing_mplayer_program_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("x.avi"), "x").unwrap();
    let conf = d.join("m.conf");
    std::fs::write(
        &conf,
        "driver mplayer\nprovides colorA x.avi repeat_on\nend_driver\nload_driver mplayer\n",
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_jderobot"))
        .arg("--headless")
        .arg(&conf)
        .env("PATH", d)
        .env_remove("DISPLAY")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("`mplayer` program is not installed") && err.contains("package `mplayer`"),
        "{err}"
    );
    assert!(err.contains("m.conf:4"), "names the load line: {err}");
}

// ----------------------------------------------------------------- examples

/// examples/cameras.conf through the real binary, headless: every camera gives
/// frames (`echo NAME N` waits for N new ones).
#[test]
fn the_cameras_example_runs_in_the_binary() {
    if !need("mplayer") {
        return;
    }
    let mut child = Command::new(env!("CARGO_BIN_EXE_jderobot"))
        .args(["--headless", "examples/cameras.conf"])
        .current_dir(root())
        .env_remove("DISPLAY")
        .env("RUST_LOG", "warn")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    {
        use std::io::Write;
        child
            .stdin
            .take()
            .unwrap()
            .write_all(
                b"run colorA\nrun varcolorA\nrun varcolorB\nrun varcolorC\n\
                  echo varcolorA 3\necho varcolorB 2\necho colorA\necho varcolorC\nps\nquit\n",
            )
            .unwrap();
    }
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    for (name, size) in [
        ("colorA", "320x240"),
        ("varcolorA", "320x240"),
        ("varcolorB", "640x480"),
        ("varcolorC", "320x240"),
    ] {
        // Streams: `echo NAME N` waited for new frames; stills: published once, at `run`.
        assert!(
            stdout
                .lines()
                .any(|l| l.starts_with(&format!("{name} clock="))
                    && !l.contains("clock=0 ")
                    && l.contains(size)),
            "no frame of {name} ({size}) in:\n{stdout}\n{stderr}"
        );
    }
    assert!(!stderr.contains("ERROR"), "{stderr}");
}

/// Every example conf of these drivers loads (paths relative to the example).
#[test]
fn the_example_confs_load() {
    let mut names = vec!["imagefile", "simulated3D"];
    if have("mplayer") || std::env::var_os("CI").is_some() {
        names.extend(["mplayer", "cameras"]);
    } else {
        eprintln!("skipped mplayer.conf and cameras.conf: `mplayer` is not installed");
    }
    if have("ffmpeg") || std::env::var_os("CI").is_some() {
        names.push("opencv");
    }
    for n in names {
        let file = root().join(format!("examples/{n}.conf"));
        let conf = Conf::load(&file).unwrap_or_else(|e| panic!("{e}"));
        let rt = jderobot::loader::start(&conf).unwrap_or_else(|e| panic!("{n}: {e}"));
        assert!(!rt.interfaces.names().is_empty(), "{n} provides nothing");
        rt.shutdown();
    }
}

// ------------------------------------------------------- 4:2:0 → BGR vs FFmpeg

/// Our YUV4MPEG2 reader and 4:2:0 → BGR conversion give what FFmpeg's own
/// conversion gives for the same frame (a colour test card).
#[test]
fn y4m_conversion_matches_ffmpeg() {
    if !need("ffmpeg") {
        return;
    }
    let run = |args: &[&str]| -> Vec<u8> {
        let out = Command::new("ffmpeg")
            .args([
                "-v",
                "error",
                "-f",
                "lavfi",
                "-i",
                "smptehdbars=size=320x240:rate=1",
                "-frames:v",
                "1",
            ])
            .args(args)
            .output()
            .expect("run ffmpeg");
        assert!(out.status.success());
        out.stdout
    };
    let y4m = run(&["-pix_fmt", "yuv420p", "-f", "yuv4mpegpipe", "pipe:1"]);
    let bgr = run(&["-pix_fmt", "bgr24", "-f", "rawvideo", "pipe:1"]);
    use jderobot::media::y4m;
    let mut r = &y4m[..];
    let h = y4m::read_header(&mut r).unwrap().unwrap();
    assert_eq!((h.width, h.height, h.rate), (320, 240, Some(1.0)));
    let mut planes = Vec::new();
    assert!(y4m::read_frame(&mut r, &h, &mut planes).unwrap());
    let mut ours = vec![0u8; 320 * 240 * 3];
    y4m::i420_to_bgr(&planes, 320, 240, 320, 240, &mut ours);
    assert_eq!(ours.len(), bgr.len());
    let diff: u64 = ours
        .iter()
        .zip(&bgr)
        .map(|(a, b)| a.abs_diff(*b) as u64)
        .sum();
    let mean = diff as f64 / ours.len() as f64;
    // Same matrix; chroma upsampling at colour edges may differ by a little.
    assert!(mean < 3.0, "mean difference {mean:.2} per channel");
}

#[test]
fn mplayer_conf_errors_name_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases = [
        (
            "provides colorA clip.avi",
            &[
                "test.conf:2",
                "takes 3 to 4 arguments",
                "repeat_on|repeat_off",
            ][..],
        ),
        (
            "provides colorA clip.avi repeat_maybe",
            &["test.conf:2", "`repeat_maybe`"][..],
        ),
        (
            "provides varcolorA clip.avi repeat_on",
            &["test.conf:2", "FILE|URL W H"][..],
        ),
        (
            "provides varcolorA clip.avi 640 x repeat_on",
            &["test.conf:2", "`x`"][..],
        ),
        (
            "provides varcolorA clip.avi 1 480 repeat_on",
            &["test.conf:2", "W (argument 3) is `1`"][..],
        ),
        (
            "provides colorA v4l /dev/video0 hdmi",
            &["test.conf:2", "`hdmi`", "s-video"][..],
        ),
        (
            "provides colorA clip.avi repeat_on fast",
            &["test.conf:2", "`fast`", "unpaced"][..],
        ),
        (
            "provides laser clip.avi",
            &["test.conf:2", "not `laser`"][..],
        ),
        ("volume 3", &["test.conf:2", "volume"][..]),
    ];
    for (line, want) in cases {
        let e = start_in(
            d,
            &format!("driver mplayer\n{line}\nend_driver\nload_driver mplayer\n"),
        )
        .err()
        .unwrap_or_else(|| panic!("`{line}` loaded"));
        for w in want {
            assert!(e.contains(w), "`{line}`: {w:?} missing in: {e}");
        }
    }
}

/// `bytes` with its JPEG frame header (SOF0..SOF2) saying `w` x `h`.
fn with_jpeg_size(mut bytes: Vec<u8>, w: u16, h: u16) -> Vec<u8> {
    let i = bytes
        .windows(2)
        .position(|m| m[0] == 0xFF && (0xC0..=0xC2).contains(&m[1]))
        .expect("a SOF marker");
    bytes[i + 5..i + 7].copy_from_slice(&h.to_be_bytes());
    bytes[i + 7..i + 9].copy_from_slice(&w.to_be_bytes());
    bytes
}

/// Issue 28, I1 and I2: a 70 KB JPEG whose header says 8193x8192 loaded as a
/// 201 MB image (PNM refused anything over 67 Mpx: every decoder now has that
/// limit), and JPEGs cut short loaded with no error (the decoder fills the rest
/// with grey): a truncated JPEG, PNG or BMP is an error.
#[test]
fn huge_headers_and_truncated_images_are_errors() {
    use jderobot::media::still::{MAX_PIXELS, decode_image};
    for photo in ["astronaut", "chelsea", "coffee", "gravel"] {
        let f = root().join(format!("assets/photos/{photo}.jpg"));
        let bytes = std::fs::read(&f).unwrap();
        decode_image(&bytes, &f).unwrap_or_else(|e| panic!("{e}"));
    }
    let jpeg = std::fs::read(root().join("assets/photos/astronaut.jpg")).unwrap();
    // Data after the end marker (a second picture, a motion photo's video) is fine.
    let mut tail = jpeg.clone();
    tail.extend_from_slice(&[0xFF, 0xDA, 0, 8, 1, 2, 0xFF, 0xD8, 0xFF, 0xDA, 9]);
    decode_image(&tail, Path::new("tail.jpg")).unwrap_or_else(|e| panic!("{e}"));
    let huge = with_jpeg_size(jpeg.clone(), 8193, 8192);
    const { assert!(8193 * 8192 > MAX_PIXELS) };
    let e = decode_image(&huge, Path::new("huge.jpg"))
        .expect_err("a 8193x8192 JPEG header was accepted");
    assert!(e.to_string().contains("8193x8192"), "{e}");
    // The same through imagefile, naming the conf line.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("huge.jpg"), &huge).unwrap();
    let e = start_in(
        dir.path(),
        "driver imagefile\nprovides varcolorA huge.jpg\nend_driver\nload_driver imagefile\n",
    )
    .err()
    .expect("imagefile loaded a 8193x8192 JPEG");
    assert!(e.contains("test.conf:2") && e.contains("8193x8192"), "{e}");

    // 35 cuts through the JPEG, and some through a PNG and a BMP.
    let mut loaded = Vec::new();
    for k in 1..=35 {
        let cut = jpeg.len() * k / 36;
        if decode_image(&jpeg[..cut], Path::new("cut.jpg")).is_ok() {
            loaded.push(cut);
        }
    }
    for cut in [jpeg.len() - 1, jpeg.len() - 2] {
        if decode_image(&jpeg[..cut], Path::new("cut.jpg")).is_ok() {
            loaded.push(cut);
        }
    }
    assert!(loaded.is_empty(), "JPEGs cut at {loaded:?} bytes loaded");
    let png = std::fs::read(root().join("assets/images/mandelbrot.png")).unwrap();
    let bmp = encode_bmp(&decode_image(&png, Path::new("m.png")).unwrap());
    assert!(decode_image(&bmp, Path::new("m.bmp")).is_ok());
    for (name, bytes) in [("cut.png", &png), ("cut.bmp", &bmp)] {
        for k in 1..=9 {
            let cut = bytes.len() * k / 10;
            assert!(
                decode_image(&bytes[..cut], Path::new(name)).is_err(),
                "{name} cut at {cut} of {} bytes loaded",
                bytes.len()
            );
        }
    }
}

/// A 24-bit BMP of `img` (BGR rows, bottom-up, padded to 4 bytes).
fn encode_bmp(img: &Image) -> Vec<u8> {
    let (w, h) = (img.width as usize, img.height as usize);
    let row = (w * 3).div_ceil(4) * 4;
    let size = 54 + row * h;
    let mut b = Vec::with_capacity(size);
    b.extend_from_slice(b"BM");
    b.extend_from_slice(&(size as u32).to_le_bytes());
    b.extend_from_slice(&[0; 4]);
    b.extend_from_slice(&54u32.to_le_bytes());
    b.extend_from_slice(&40u32.to_le_bytes());
    b.extend_from_slice(&(w as i32).to_le_bytes());
    b.extend_from_slice(&(h as i32).to_le_bytes());
    b.extend_from_slice(&1u16.to_le_bytes());
    b.extend_from_slice(&24u16.to_le_bytes());
    b.extend_from_slice(&[0; 24]);
    for y in (0..h).rev() {
        b.extend_from_slice(&img.data[y * w * 3..(y + 1) * w * 3]);
        b.resize(b.len() + row - w * 3, 0);
    }
    b
}
