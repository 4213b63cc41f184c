//! video4linux2 / video4linux: there is no capture device on this machine, so the
//! tests run the driver's error paths for real (a missing node, nodes that are not
//! V4L2 capture devices) and its conversions (MJPEG frames made by the real
//! `ffmpeg` program and checked against ffmpeg's own decoding).
#![cfg(feature = "video4linux2")]

use crate::common;

use std::{path::Path, process::Command};

use jderobot::{ComponentConf, Conf, Kind, drivers::video4linux2 as v4l2, interfaces::Image};

fn parse(name: &str, text: &str) -> anyhow::Result<Vec<v4l2::DevConf>> {
    v4l2::parse(
        &ComponentConf::from_text(Kind::Driver, name, text).unwrap(),
        name == "video4linux",
    )
}

#[test]
fn conf_lines_of_both_names() {
    let c = parse(
        "video4linux2",
        "provides colorA /dev/video1 0\nprovides varcolorB /dev/video0 2 176 144\n",
    )
    .unwrap();
    assert_eq!((c[0].input, c[0].width, c[0].height), (0, 320, 240));
    assert_eq!(c[0].device, Path::new("/dev/video1"));
    assert_eq!((c[1].input, c[1].width, c[1].height), (2, 176, 144));
    // 4.3's video4linux lines: no input.
    let c = parse(
        "video4linux",
        "provides varcolorA /dev/video0 640 480\nprovides colorA /dev/video1\n",
    )
    .unwrap();
    assert_eq!((c[0].input, c[0].width, c[0].height), (0, 640, 480));
    assert_eq!((c[1].input, c[1].width), (0, 320));
    for (name, bad, says) in [
        ("video4linux2", "provides colorA /dev/video0\n", "usage"),
        (
            "video4linux2",
            "provides varcolorA /dev/video0 0 640\n",
            "usage",
        ),
        (
            "video4linux2",
            "provides varcolorA /dev/video0 x 640 480\n",
            "input number",
        ),
        (
            "video4linux2",
            "provides varcolorA /dev/video0 0 0 480\n",
            "out of range",
        ),
        (
            "video4linux2",
            "provides laser /dev/video0 0\n",
            "colorA..D or varcolorA..D",
        ),
        (
            "video4linux2",
            "device /dev/video0\n",
            "takes no `device` line",
        ),
        ("video4linux", "provides colorA\n", "needs a device"),
        ("video4linux2", "", "no `provides` line"),
    ] {
        let e = parse(name, bad).unwrap_err().to_string();
        assert!(e.contains(says), "{name} `{bad}` gave: {e}");
    }
}

fn start_error(driver: &str, provides: &str) -> String {
    let text = format!("driver {driver}\n{provides}\nend_driver\nload_driver {driver}\n");
    let conf = Conf::parse(&text, Path::new("cam.conf")).unwrap();
    match jderobot::loader::start(&conf) {
        Ok(rt) => {
            rt.shutdown();
            panic!("{driver} started with `{provides}`");
        }
        Err(e) => e.to_string(),
    }
}

/// A missing node: a message naming the conf line and the device, a stale
/// interface, and jderobot runs on (the driver would open it when it appears).
#[test]
fn a_missing_device_is_a_message_and_a_stale_interface() {
    for (driver, provides, iface) in [
        (
            "video4linux2",
            "provides varcolorA /dev/video97 0 640 480",
            "varcolorA",
        ),
        ("video4linux", "provides colorB /dev/video97", "colorB"),
    ] {
        let text = format!("driver {driver}\n{provides}\nend_driver\nload_driver {driver}\n");
        let conf = Conf::parse(&text, Path::new("cam.conf")).unwrap();
        let rt = jderobot::loader::start(&conf).unwrap_or_else(|e| panic!("{e}"));
        let img = rt.interfaces.get::<Image>(iface).unwrap();
        let why = img.stale().expect("stale from the start");
        println!("{driver}: {why}");
        assert!(why.contains("/dev/video97: no such device"), "{why}");
        img.resume();
        std::thread::sleep(std::time::Duration::from_millis(500));
        assert_eq!(img.clock(), 0);
        assert!(img.stale().is_some());
        img.suspend();
        rt.shutdown();
    }
    let c = &parse("video4linux2", "provides colorA /dev/video97 0\n").unwrap()[0];
    assert!(matches!(v4l2::check(c), Err(v4l2::CheckError::Absent(_))));
}

#[test]
fn a_node_that_is_not_a_capture_device_is_a_clear_error() {
    // A character device that is not V4L2 (/dev/null) and a plain file.
    let e = start_error("video4linux2", "provides colorA /dev/null 0");
    println!("{e}");
    assert!(e.contains("/dev/null: not a video4linux2 device"), "{e}");
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("video0");
    std::fs::write(&f, b"not a camera").unwrap();
    let e = start_error(
        "video4linux2",
        &format!("provides colorA {} 0", f.display()),
    );
    assert!(e.contains("not a video4linux2 device"), "{e}");
}

#[test]
fn packed_formats_with_row_padding() {
    let (mut out, mut scratch) = (Vec::new(), Vec::new());
    // 2x2 RGB24 with 2 bytes of padding per row.
    let src = [1, 2, 3, 4, 5, 6, 0, 0, 7, 8, 9, 10, 11, 12];
    v4l2::convert(b"RGB3", &src, 2, 2, 8, &mut out, &mut scratch).unwrap();
    assert_eq!(out, [3, 2, 1, 6, 5, 4, 9, 8, 7, 12, 11, 10]);
    // YUYV black/white.
    v4l2::convert(
        b"YUYV",
        &[16, 128, 235, 128],
        2,
        1,
        0,
        &mut out,
        &mut scratch,
    )
    .unwrap();
    assert_eq!(out, [0, 0, 0, 255, 255, 255]);
    // GREY.
    v4l2::convert(b"GREY", &[9, 10], 2, 1, 2, &mut out, &mut scratch).unwrap();
    assert_eq!(out, [9, 9, 9, 10, 10, 10]);
    // Truncated frames and unknown formats are errors, never panics.
    assert!(v4l2::convert(b"RGB3", &src[..10], 2, 2, 8, &mut out, &mut scratch).is_err());
    assert!(v4l2::convert(b"YUYV", &[0; 7], 2, 2, 0, &mut out, &mut scratch).is_err());
    let e = v4l2::convert(b"H264", &[0; 7], 2, 2, 0, &mut out, &mut scratch).unwrap_err();
    assert!(e.contains("H264 is not supported"), "{e}");
}

/// ffmpeg must be there (Debian `ffmpeg`); with CI set, its absence fails.
fn have_ffmpeg() -> bool {
    if common::have("ffmpeg") {
        return true;
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "CI: ffmpeg is not installed"
    );
    println!("skipped: no ffmpeg on this machine");
    false
}

#[test]
fn mjpeg_frames_decode_like_ffmpeg() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let jpg = dir.path().join("f.jpg");
    let raw = dir.path().join("f.bgr");
    let (w, h) = (320u32, 240u32);
    let ok = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-f", "lavfi", "-i"])
        .arg(format!("testsrc=size={w}x{h}:rate=1"))
        .args(["-frames:v", "1", "-q:v", "3", "-pix_fmt", "yuvj422p"])
        .arg(&jpg)
        .status()
        .unwrap()
        .success();
    assert!(ok, "ffmpeg could not write a JPEG");
    let ok = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-i"])
        .arg(&jpg)
        .args(["-f", "rawvideo", "-pix_fmt", "bgr24"])
        .arg(&raw)
        .status()
        .unwrap()
        .success();
    assert!(ok);
    let data = std::fs::read(&jpg).unwrap();
    let want = std::fs::read(&raw).unwrap();
    let (mut out, mut scratch) = (Vec::new(), Vec::new());
    v4l2::convert(b"MJPG", &data, w, h, 0, &mut out, &mut scratch).unwrap();
    assert_eq!(out.len(), want.len());
    let mean: f64 = out
        .iter()
        .zip(&want)
        .map(|(a, b)| (*a as f64 - *b as f64).abs())
        .sum::<f64>()
        / out.len() as f64;
    println!("MJPEG {w}x{h}: mean |ours - ffmpeg| = {mean:.3}");
    assert!(mean < 3.0, "mean difference {mean}");
    // A frame of another size, a truncated frame and garbage: errors, no panic.
    let e = v4l2::convert(b"MJPG", &data, 640, 480, 0, &mut out, &mut scratch).unwrap_err();
    assert!(e.contains("320x240"), "{e}");
    let _ = v4l2::convert(
        b"MJPG",
        &data[..data.len() / 3],
        w,
        h,
        0,
        &mut out,
        &mut scratch,
    );
    assert!(v4l2::convert(b"MJPG", b"garbage", w, h, 0, &mut out, &mut scratch).is_err());
}

/// examples/video4linux2.conf parses and its driver lines are the driver's.
#[test]
fn the_example_conf_parses() {
    let conf = Conf::load(&common::root().join("examples/video4linux2.conf")).unwrap();
    let c = conf
        .component_conf(Kind::Driver, "video4linux2", None)
        .unwrap();
    let devs = v4l2::parse(&c, false).unwrap();
    assert_eq!(devs[0].device, Path::new("/dev/video0"));
}
