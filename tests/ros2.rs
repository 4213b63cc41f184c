//! The `ros2` service and driver against an independent DDS: Eclipse Cyclone DDS
//! through its Python binding (`cyclonedds` from PyPI), in `tests/ros2/cyclone_peer.py`,
//! whose types are ROS 2's message definitions under ROS 2's DDS names (`rt/scan`,
//! `sensor_msgs::msg::dds_::LaserScan_`, ...), as rmw_cyclonedds declares them.
//! Runs in the venv that .ci/run makes (target/py-venv, or `$JDEROBOT_PYTHON`);
//! without `cyclonedds` the tests skip with a note, but FAIL under `CI`.
#![cfg(all(feature = "ros2", feature = "simulator", feature = "introrob"))]

use crate::common;

use std::process::{Command, Stdio};

use common::{process::Proc, root};

/// A DDS domain of its own for each test (and each run), so tests running at
/// once and other DDS users on the machine stay apart.
fn domain(offset: u32) -> u32 {
    100 + (std::process::id() % 60) * 2 + offset
}

fn peer(py: &std::path::Path, mode: &str, domain: u32, secs: u32) -> std::process::Child {
    Command::new(py)
        .arg(root().join("tests/ros2/cyclone_peer.py"))
        .args([mode, &domain.to_string(), &secs.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the Cyclone peer")
}

fn json_of(child: std::process::Child, what: &str, robot: &Proc) -> serde_json::Value {
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{what} failed: {}\n{stdout}\njderobot:\n{}",
        String::from_utf8_lossy(&out.stderr),
        robot.text()
    );
    eprintln!("{what}: {stdout}");
    serde_json::from_str(stdout.lines().last().unwrap_or("")).expect("a JSON line")
}

fn f(v: &serde_json::Value, path: &[&str]) -> f64 {
    let mut x = v;
    for p in path {
        x = &x[*p];
    }
    x.as_f64()
        .unwrap_or_else(|| panic!("{path:?} is not a number in {v}"))
}

fn s<'a>(v: &'a serde_json::Value, path: &[&str]) -> &'a str {
    let mut x = v;
    for p in path {
        x = &x[*p];
    }
    x.as_str()
        .unwrap_or_else(|| panic!("{path:?} is not a string in {v}"))
}

#[test]
fn a_cyclone_subscriber_reads_every_type_and_drives_the_robot_on_cmd_vel() {
    let Some(py) = common::python_with("cyclonedds") else {
        return;
    };
    let d = domain(0);
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("robot.conf");
    std::fs::write(
        &conf,
        format!(
            "driver simulator\nworld {}\nrobot robot1 1000 1000 90\nprovides encoders\n\
             provides motors\nprovides laser 180 1\nprovides colorA\nprovides imu\nend_driver\n\
             service ros2\ninsecure\ndomain {d}\nend_service\n\
             load_driver simulator\nload_service ros2\n",
            common::world_path("simple.world")
        ),
    )
    .unwrap();
    let mut robot = Proc::start(&conf);
    let start = robot.ask_until("echo encoders", "the robot", |l| {
        l.starts_with("encoders clock=")
    });
    let got = json_of(peer(&py, "listen", d, 60), "the Cyclone subscriber", &robot);
    // LaserScan: 180 readings, 1 per degree from -90°, in metres and radians.
    assert_eq!(s(&got, &["scan", "frame"]), "laser");
    assert_eq!(f(&got, &["scan", "n"]), 180.0);
    assert!((f(&got, &["scan", "angle_min"]) + std::f64::consts::FRAC_PI_2).abs() < 1e-4);
    assert!((f(&got, &["scan", "angle_increment"]) - 1f64.to_radians()).abs() < 1e-5);
    assert!((f(&got, &["scan", "angle_max"]) - 89f64.to_radians()).abs() < 1e-4);
    assert!(f(&got, &["scan", "range_max"]) > 1.0 && f(&got, &["scan", "range_max"]) < 100.0);
    let r0 = got["scan"]["ranges"][0].as_f64().unwrap();
    assert!(r0 > 0.05 && r0 < 10.0, "a range in metres: {r0}");
    assert!(f(&got, &["scan", "stamp"]) > 1.6e9, "wall-clock stamps");
    // Odometry and /tf: odom → base_link, metres; the robot started at (1 m, 1 m).
    assert_eq!(s(&got, &["odom", "frame"]), "odom");
    assert_eq!(s(&got, &["odom", "child"]), "base_link");
    assert!((f(&got, &["odom_first", "x"]) - 1.0).abs() < 0.3, "{got}");
    assert!(
        (f(&got, &["odom_first", "yaw"]) - 90f64.to_radians()).abs() < 0.3,
        "{got}"
    );
    assert_eq!(s(&got, &["tf", "parent"]), "odom");
    assert_eq!(s(&got, &["tf", "child"]), "base_link");
    // /tf_static (transient local): base_link → laser, the laser's mount.
    assert_eq!(s(&got, &["tf_static", "parent"]), "base_link");
    assert_eq!(s(&got, &["tf_static", "child"]), "laser");
    // The camera: 320x240 bgr8, rows of 960 bytes.
    assert_eq!(f(&got, &["image", "width"]), 320.0);
    assert_eq!(f(&got, &["image", "height"]), 240.0);
    assert_eq!(s(&got, &["image", "encoding"]), "bgr8");
    assert_eq!(f(&got, &["image", "step"]), 960.0);
    assert_eq!(f(&got, &["image", "bytes"]), 320.0 * 240.0 * 3.0);
    assert!(got["imu"]["qw"].is_number(), "{got}");
    // /cmd_vel (0.3 m/s, 0.2 rad/s) drove the simulated robot.
    robot.expect_moved(&start, 100.0);
    let m = robot.ask_until("echo motors", "motors", |l| l.starts_with("motors clock="));
    eprintln!("{m}");
    // The peer left: motors_timeout later the motors are zero.
    robot.ask_until("echo motors", "motors zeroed", |l| {
        l.starts_with("motors clock=") && l.contains("v=0.0 mm/s")
    });
    robot.quit();
}

#[test]
fn introrob_drives_a_cyclone_robot_through_the_ros2_driver() {
    let Some(py) = common::python_with("cyclonedds") else {
        return;
    };
    let d = domain(1);
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("introrob.conf");
    std::fs::write(
        &conf,
        format!(
            "driver ros2\ninsecure\ndomain {d}\nprovides laser /scan\nprovides encoders /odom\n\
             provides motors /cmd_vel\nsilence 1000\nend_driver\n\
             schema introrob\nbehaviour vff\ntarget 4000 0\nmax_v 400\nmax_w 40\nworld none\nsonars none\nbumpers none\ncamera none\nend_schema\n\
             load_driver ros2\nload_schema introrob\nrun introrob\n"
        ),
    )
    .unwrap();
    let robot = Proc::start(&conf);
    // No publisher yet: one line naming the topics it waits for.
    assert!(
        common::poll_until(20, || robot
            .text()
            .contains("waiting for a publisher on /scan, /odom")),
        "no waiting line:\n{}",
        robot.text()
    );
    let got = json_of(peer(&py, "robot", d, 60), "the Cyclone robot", &robot);
    assert!(f(&got, &["cmds"]) > 0.0, "no /cmd_vel: {got}");
    assert!(f(&got, &["max_v"]) > 0.05, "{got}");
    assert!(
        f(&got, &["x"]) > 2.0,
        "VFF took the robot toward x = 4 m: {got}\n{}",
        robot.text()
    );
    // The robot went away: the driver says so and zeroes motors.
    assert!(
        common::poll_until(20, || robot.text().contains("no message on /scan")),
        "no loss line:\n{}",
        robot.text()
    );
    robot.quit();
}

#[test]
fn without_insecure_the_service_and_the_driver_refuse_to_start() {
    let e = common::start_error("service ros2\nend_service\nload_service ros2\n");
    assert!(e.contains("insecure") && e.contains("DDS Security"), "{e}");
    let e = common::start_error("driver ros2\nprovides laser\nend_driver\nload_driver ros2\n");
    assert!(e.contains("insecure"), "{e}");
}
