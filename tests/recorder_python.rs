//! The Python `mcap` package (PyPI) reads what the recorder writes: the protobuf
//! messages (images, laser) parse with Foxglove's own classes and with the classes
//! `mcap-protobuf-support` builds from the file's schemas, the JSON ones validate
//! against their JSON schemas and Foxglove's definitions (scripts/check_mcap.py, in
//! the venv that .ci/run makes: target/py-venv); rosbags opens the `ros2` profile.
//! Without that venv the test skips with a note, but FAILS under `CI`.
#![cfg(all(feature = "recorder", feature = "simulator"))]

use crate::common;

use std::path::{Path, PathBuf};

use common::{root, world_path};
use jderobot::{
    interfaces::{Image, Laser},
    mcapfmt::{self, Recorded},
};

/// The venv's python, with the packages the check needs, or None (skip; CI fails).
fn python() -> Option<PathBuf> {
    common::python_with("mcap, mcap_protobuf, jsonschema, foxglove_schemas_protobuf")
}

/// Writes a conf at `conf`: the simulator and a recorder with `lines`.
fn write_recorder_conf(conf: &Path, lines: &str) {
    let text = format!(
        "driver simulator\nworld {}\nprovides encoders\nprovides motors\nprovides laser\n\
         provides sonars\nprovides colorA\nprovides imu\nend_driver\n\
         service recorder\n{lines}end_service\n\
         load_driver simulator\nload_service recorder\n",
        world_path("simple.world")
    );
    std::fs::write(conf, text).unwrap();
}

/// The first laser scan and image jderobot reads in a file's `bytes`; the laser
/// must equal the one Python read (`v["laser0"]`, mm).
fn first_laser_and_image(bytes: &[u8], v: &serde_json::Value) -> (Laser, Image) {
    let mut laser = None;
    let mut image = None;
    for m in mcap::MessageStream::new(bytes).unwrap() {
        let m = m.unwrap();
        let kind = mcapfmt::channel_kind(&m.channel.metadata, None).unwrap();
        match mcapfmt::decode_mcap(kind, &m).unwrap().value {
            Recorded::Laser(l) if laser.is_none() => laser = Some(l),
            Recorded::Image(i) if image.is_none() => image = Some(i),
            _ => {}
        }
    }
    let laser = laser.expect("a laser message");
    let py_laser: Vec<i64> = v["laser0"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_i64().unwrap())
        .collect();
    let ours: Vec<i64> = laser.readings.iter().map(|&r| r as i64).collect();
    assert_eq!(py_laser, ours, "the laser as Python and jderobot read it");
    (laser, image.expect("an image message"))
}

#[test]
fn python_mcap_reads_the_recording_by_the_documented_schemas() {
    let Some(py) = python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("r.conf");
    write_recorder_conf(&conf, "file p.mcap\ncompression lz4\n");
    common::run_for(&conf, 3.0);
    // The same with JPEG images (foxglove.CompressedImage).
    write_recorder_conf(&conf, "file j.mcap\nimages jpeg 80\ncompression lz4\n");
    common::run_for(&conf, 2.0);
    for file in [
        dir.path().join("j.mcap"),
        dir.path().join("p.mcap"),
        root().join("assets/recordings/simple.mcap"),
    ] {
        let v = common::python_json(&py, "check_mcap.py", &file);
        if v.get("jpeg0").is_some() {
            continue;
        }
        // What Python read equals what jderobot reads.
        let (summary, bytes) = mcapfmt::Summary::read(&file).unwrap();
        for c in &summary.channels {
            assert_eq!(
                v["channels"][&c.topic].as_u64(),
                Some(c.messages),
                "{}",
                c.topic
            );
        }
        let (laser, image) = first_laser_and_image(&bytes, &v);
        let py_res = v["resolution0"].as_f64().unwrap();
        assert!(
            (py_res - laser.resolution as f64).abs() < 1e-6,
            "resolution: Python {py_res}, jderobot {}",
            laser.resolution
        );
        let sum: u64 = image.data.iter().map(|&b| b as u64).sum();
        assert_eq!(v["image0"]["width"].as_u64(), Some(image.width as u64));
        assert_eq!(v["image0"]["sum"].as_u64(), Some(sum));
    }
}

/// The venv's python if it has `rosbags` too (else skip; CI fails).
fn python_rosbags() -> Option<PathBuf> {
    common::python_with(
        "mcap, mcap_protobuf, jsonschema, foxglove_schemas_protobuf, rosbags.rosbag2, rosbags.typesys",
    )
}

#[test]
fn rosbags_opens_the_ros2_profile_and_the_replay_reads_it_back() {
    let Some(py) = python_rosbags() else { return };
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("r.conf");
    write_recorder_conf(&conf, "file ros.mcap\nprofile ros2\n");
    common::run_for(&conf, 3.0);
    let file = dir.path().join("ros.mcap");
    let v = common::python_json(&py, "check_ros2.py", &file);
    assert_eq!(
        v["connections"]["/laser"][0], "sensor_msgs/msg/LaserScan",
        "{v}"
    );
    assert_eq!(
        v["connections"]["/colorA"][0], "sensor_msgs/msg/Image",
        "{v}"
    );
    assert_eq!(
        v["connections"]["/encoders"][0], "nav_msgs/msg/Odometry",
        "{v}"
    );
    assert_eq!(v["image0"]["encoding"], "bgr8");
    assert_eq!(v["connections"]["/imu"][0], "sensor_msgs/msg/Imu", "{v}");
    let az = v["imu0"]["az"].as_f64().unwrap();
    assert!((az - 9.80665).abs() < 1e-5, "gravity in m/s²: {v}");

    // jderobot's replay reads the same file: the first laser and image agree.
    let (summary, bytes) = mcapfmt::Summary::read(&file).unwrap();
    assert_eq!(summary.profile, "ros2");
    let (_, image) = first_laser_and_image(&bytes, &v);
    let sum: u64 = image.data.iter().map(|&b| b as u64).sum();
    assert_eq!(v["image0"]["sum"].as_u64(), Some(sum));

    // Replayed by the binary and recorded again (jderobot's profile): same laser.
    let replay = dir.path().join("replay.conf");
    std::fs::write(
        &replay,
        "driver replay\nfile ros.mcap\nspeed 2\nend_driver\n\
         service recorder\nfile back.mcap\nend_service\n\
         load_driver replay\nload_service recorder\n",
    )
    .unwrap();
    common::run_for(&replay, 3.0);
    let (back, _) = mcapfmt::Summary::read(&dir.path().join("back.mcap")).unwrap();
    let names: Vec<&str> = back.channels.iter().map(|c| c.topic.as_str()).collect();
    assert!(
        names.contains(&"laser") && names.contains(&"colorA") && names.contains(&"encoders"),
        "{names:?}"
    );
}
