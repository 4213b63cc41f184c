//! Python on the other end: `scripts/zenoh_client.py` (the `eclipse-zenoh` package
//! from PyPI, and `rosbags` for CDR) reads laser, an image, odometry and the imu from a
//! simulated robot served by the `zenoh` service, decodes them from the layouts of
//! docs/zenoh.md (or as ROS 2 messages with `format ros2`), and drives `motors`
//! until the robot moved. Runs in the venv that .ci/run makes (target/py-venv);
//! without it the test skips with a note, but FAILS under `CI`.
#![cfg(all(feature = "zenoh", feature = "simulator"))]

use crate::common;

use std::process::{Command, Stdio};

use common::{
    process::{Proc, free_port},
    root,
};

/// Runs the Python client in `mode` against a robot served with `extra` lines;
/// returns its JSON line.
fn python_drives(mode: &str, extra: &str) -> Option<serde_json::Value> {
    let py = common::python_with("zenoh, rosbags")?;
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let conf = dir.path().join("robot.conf");
    std::fs::write(
        &conf,
        format!(
            "driver simulator\nworld {}\nrobot robot1 1000 1000 90\nprovides encoders\n\
             provides motors\nprovides laser 180 1\nprovides sonars\nprovides colorA\nprovides imu\n\
             end_driver\nservice zenoh\nrobot pioneer\npublishes all\nlisten tcp/127.0.0.1:{port}\n\
             scouting off\n{extra}end_service\nload_driver simulator\nload_service zenoh\n",
            common::world_path("simple.world")
        ),
    )
    .unwrap();
    let mut robot = Proc::start(&conf);
    let start = robot.ask_until("echo encoders", "the robot", |l| {
        l.starts_with("encoders clock=")
    });
    let mut child = Command::new(&py)
        .arg(root().join("scripts/zenoh_client.py"))
        .args([mode, &port.to_string(), "pioneer"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    if !common::poll_until(90, || child.try_wait().ok().flatten().is_some()) {
        let _ = child.kill();
    }
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "python ({mode}) failed: {}\n{stdout}\nrobot:\n{}",
        String::from_utf8_lossy(&out.stderr),
        robot.text()
    );
    eprintln!("{stdout}");
    // The robot moved, as its own process sees it.
    robot.expect_moved(&start, 100.0);
    robot.quit();
    let v: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    // The imu, in either format: gravity up, in m/s².
    let az = v["imu"]["az"].as_f64().unwrap();
    assert!((az - 9.80665).abs() < 1e-5, "imu: {v}");
    Some(v)
}

#[test]
fn python_reads_the_documented_layouts_and_drives_the_robot() {
    let Some(v) = python_drives("jderobot", "") else {
        return;
    };
    assert_eq!(v["laser"]["n"], 180, "{v}");
    assert_eq!(v["laser"]["resolution"], 1.0, "{v}");
    assert_eq!(v["image"]["w"], 320, "{v}");
    assert_eq!(v["image"]["h"], 240, "{v}");
    assert_eq!(v["image_encoding"], "zenoh/bytes;jderobot/image", "{v}");
    assert_eq!(v["attachment_len"], 16, "{v}");
    assert!(v["laser_clock"].as_u64().unwrap() >= 1, "{v}");
    let age = v["laser_age_s"].as_f64().unwrap();
    assert!(
        (0.0..5.0).contains(&age),
        "the attachment's time is the sample's: {v}"
    );
    for mm in v["laser_first_mm"].as_array().unwrap() {
        let mm = mm.as_i64().unwrap();
        assert!((100..=8000).contains(&mm), "laser in mm: {v}");
    }
}

#[test]
fn ros2_format_is_cdr_that_rosbags_decodes_on_rmw_zenoh_keys() {
    let Some(v) = python_drives("ros2", "format ros2\n") else {
        return;
    };
    // The keys were built by Python from rosbags' own RIHS01 type hashes: data
    // arriving on them means ours are the same.
    assert_eq!(v["laser"]["n"], 180, "{v}");
    let min = v["laser"]["angle_min"].as_f64().unwrap();
    assert!((min + std::f64::consts::FRAC_PI_2).abs() < 1e-6, "{v}");
    for m in v["laser"]["m"].as_array().unwrap() {
        let m = m.as_f64().unwrap();
        assert!((0.1..=8.0).contains(&m), "ranges in metres: {v}");
    }
    assert_eq!(v["image"]["encoding"], "bgr8", "{v}");
    assert_eq!(v["image"]["w"], 320, "{v}");
    assert_eq!(v["attachment_len"], 32, "rmw_zenoh's attachment: {v}");
}
