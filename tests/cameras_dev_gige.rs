//! gige against Aravis's own fake camera: the library's `Fake` interface (camera
//! `Fake_1`, the same camera, stream and buffer path as a real device) and, where
//! it answers on loopback, the fake GigE Vision camera program
//! `arv-fake-gv-camera-0.8` (Debian `aravis-tools`) by address.
#![cfg(feature = "gige")]

use crate::common;

use std::{path::Path, sync::Arc, time::Duration};

use common::{eventually, poll_until};
use jderobot::{
    ComponentConf, Conf, Kind, Runtime,
    drivers::gige::{self, GigeConf, Setting},
    interfaces::Image,
};

fn parse(text: &str) -> anyhow::Result<Vec<GigeConf>> {
    gige::parse(&ComponentConf::from_text(Kind::Driver, "gige", text).unwrap())
}

#[test]
fn conf_lines_are_checked() {
    let c = parse(
        "provides varcolorA Fake_1 640 480 Mono8\nprovides colorB cam2 BayerRG8\nprovides varcolorC cam3\n\
         exposure Fake_1 10000\ngain cam2 auto\nframerate Fake_1 30\n",
    )
    .unwrap();
    assert_eq!(c[0].size, Some((640, 480)));
    assert_eq!(c[0].pixel_format.as_deref(), Some("Mono8"));
    assert_eq!(c[0].exposure, Some(Setting::Value(10000.0)));
    assert_eq!(c[0].framerate, Some(30.0));
    assert_eq!(c[1].size, Some((320, 240)));
    assert_eq!(c[1].gain, Some(Setting::Auto));
    assert_eq!(c[2].size, None);
    for (bad, says) in [
        (
            "provides varcolorA Fake_1 640\n",
            "got 3; usage: provides varcolorA..D CAMERA_ID [W H]",
        ),
        (
            "provides varcolorA Fake_1 640 480 Mono12p\n",
            "PIXEL_FORMAT (argument 5) is `Mono12p`",
        ),
        ("provides varcolorA Fake_1 0 480\n", "between 1 and 16384"),
        ("provides sonars Fake_1\n", "not `sonars`"),
        (
            "provides varcolorA Fake_1\nexposure Fake_1 -3\n",
            "is `-3`, expected a number between 0",
        ),
        (
            "provides varcolorA Fake_1\ngain other 3\n",
            "no `provides` line uses",
        ),
        (
            "provides varcolorA Fake_1\nframerate Fake_1 0\n",
            "between 0.001 and 10000 frames/s",
        ),
        ("trigger Fake_1\n", "takes no `trigger` line"),
        ("", "no `provides` line"),
    ] {
        let e = parse(bad).unwrap_err().to_string();
        assert!(e.contains(says), "`{bad}` gave: {e}");
    }
}

fn start(body: &str) -> Result<Arc<Runtime>, String> {
    let text = format!("driver gige\n{body}end_driver\nload_driver gige\n");
    let conf = Conf::parse(&text, Path::new("gige.conf")).unwrap();
    jderobot::loader::start(&conf).map_err(|e| e.to_string())
}

/// An unknown camera: a stale interface whose reason names it and lists what
/// Aravis sees; jderobot runs on.
#[test]
fn an_unknown_camera_is_a_stale_interface_with_the_reason() {
    let rt =
        start("provides varcolorA No-Such-Camera-42 320 240\n").unwrap_or_else(|e| panic!("{e}"));
    let img = rt.interfaces.get::<Image>("varcolorA").unwrap();
    let why = img.stale().expect("stale from the start");
    println!("{why}");
    assert!(
        why.contains("`No-Such-Camera-42`") && why.contains("Aravis sees"),
        "{why}"
    );
    img.resume();
    std::thread::sleep(Duration::from_millis(500));
    assert_eq!(img.clock(), 0);
    assert!(img.stale().is_some());
    img.suspend();
    rt.shutdown();
}

#[test]
fn fake_camera_frames_arrive_only_while_used() {
    let rt = start("provides varcolorA Fake_1 640 480 Mono8\nframerate Fake_1 30\n")
        .unwrap_or_else(|e| panic!("{e}"));
    let img = rt.interfaces.get::<Image>("varcolorA").unwrap();
    // Nobody uses it: no acquisition, no frames.
    std::thread::sleep(Duration::from_millis(600));
    assert_eq!(img.clock(), 0, "frames while unused");
    img.resume();
    eventually("frames from Fake_1", || img.clock() >= 5);
    let s = img.snapshot();
    assert_eq!((s.value.width, s.value.height), (640, 480));
    // Grey: B = G = R, and the fake camera's pattern is not flat.
    let d = &s.value.data;
    assert!(d.chunks_exact(3).all(|p| p[0] == p[1] && p[1] == p[2]));
    assert!(d.iter().any(|&v| v != d[0]), "a flat image");
    img.suspend();
    std::thread::sleep(Duration::from_millis(500));
    let c = img.clock();
    std::thread::sleep(Duration::from_millis(800));
    assert_eq!(img.clock(), c, "frames after suspend");
    rt.shutdown();
}

#[test]
fn fake_camera_bayer_and_size_errors() {
    // The fake camera's Bayer format, converted.
    let rt = start("provides varcolorB Fake_1 320 240 BayerGR8\n");
    match rt {
        Ok(rt) => {
            let img = rt.interfaces.get::<Image>("varcolorB").unwrap();
            img.resume();
            eventually("Bayer frames", || img.clock() >= 2);
            assert_eq!(img.snapshot().value.width, 320);
            rt.shutdown();
        }
        Err(e) => assert!(
            e.contains("BayerGR8 refused") && e.contains("offers"),
            "{e}"
        ),
    }
    // A size beyond the sensor.
    let e = start("provides varcolorA Fake_1 9000 9000\n")
        .err()
        .expect("too big");
    println!("{e}");
    assert!(e.contains("9000x9000") && e.contains("width"), "{e}");
}

fn spawn_fake_gv() -> std::process::Child {
    std::process::Command::new("arv-fake-gv-camera-0.8")
        .args(["-i", "127.0.0.1"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap()
}

/// Kills the child when the test ends, however it ends.
struct Reap(std::process::Child);

impl Drop for Reap {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// arv-fake-gv-camera-0.8 on loopback, opened by address: frames arrive; when the
/// camera program dies the interface turns stale (the other schemas go on), and
/// when it comes back the driver reopens it and frames flow again.
#[test]
fn fake_gv_camera_program_by_address_unplug_and_back() {
    if !common::have("arv-fake-gv-camera-0.8") {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI: aravis-tools is not installed"
        );
        println!("skipped: no arv-fake-gv-camera-0.8");
        return;
    }
    let mut cam = Reap(spawn_fake_gv());
    let c = GigeConf {
        iface: "varcolorA".into(),
        camera: "127.0.0.1".into(),
        size: Some((640, 480)),
        pixel_format: None,
        exposure: None,
        gain: None,
        framerate: None,
        at: "test".into(),
    };
    // The program needs a moment to listen.
    let mut r = Err(String::new());
    for _ in 0..20 {
        r = gige::check(&c).map_err(|e| format!("{e:?}"));
        if r.is_ok() {
            break;
        }
        std::thread::sleep(Duration::from_millis(250));
    }
    println!("arv-fake-gv-camera-0.8 by address 127.0.0.1: {r:?}");
    if let Err(e) = r {
        // Loopback is not a GigE network: say so rather than pass silently.
        assert!(
            std::env::var_os("CI").is_none(),
            "CI: the fake GigE camera did not answer on 127.0.0.1: {e}"
        );
        println!("note: the fake GigE camera did not answer on loopback; Fake_1 tests ran");
        return;
    }
    let rt = start("provides varcolorA 127.0.0.1 640 480\n").unwrap();
    let img = rt.interfaces.get::<Image>("varcolorA").unwrap();
    img.resume();
    assert!(
        poll_until(20, || img.clock() >= 3),
        "no frames from the GV fake camera"
    );
    // Unplug.
    let _ = cam.0.kill();
    let _ = cam.0.wait();
    assert!(
        poll_until(30, || img.stale().is_some()),
        "the interface did not turn stale"
    );
    println!("stale: {:?}", img.stale());
    // Back.
    cam = Reap(spawn_fake_gv());
    let c0 = img.clock();
    assert!(
        poll_until(40, || img.clock() > c0 + 2),
        "no frames after the camera came back"
    );
    assert!(img.stale().is_none());
    // Stop while the camera still answers: with it gone, stopping its acquisition
    // waits out Aravis's timeouts (12.7 s here, docs/benchmarks.md, CI).
    rt.shutdown();
    drop(cam);
}

/// examples/gige.conf's driver section runs against the fake camera.
#[test]
fn the_example_conf_runs() {
    let conf = Conf::load(&common::root().join("examples/gige.conf")).unwrap();
    let c = conf.component_conf(Kind::Driver, "gige", None).unwrap();
    let cams = gige::parse(&c).unwrap();
    assert_eq!(cams[0].camera, "Fake_1");
    let body: String = c.lines.iter().map(|l| l.words.join(" ") + "\n").collect();
    let rt = start(&body).unwrap_or_else(|e| panic!("{e}"));
    let img = rt.interfaces.get::<Image>("varcolorA").unwrap();
    img.resume();
    eventually("frames", || img.clock() >= 2);
    rt.shutdown();
}
