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

/// Issue 38: a Python `eclipse-zenoh` client over Zenoh's TLS transport with
/// mutual authentication (certificates made here with openssl). The robot
/// listens on `tls/` with `tls CA CERT KEY` and `writers operator`: a client
/// with the `operator` certificate reads the laser and drives the motors; one
/// with the CA's `stranger` certificate reads but its motors never arrive; one
/// whose certificate another CA signed is not let in at all.
#[test]
fn python_over_mutual_tls_reads_and_only_the_writer_drives() {
    let Some(py) = common::python_with("zenoh") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    common::certs::ca(d, "ca");
    common::certs::ca(d, "otherca");
    for (who, ca) in [
        ("robot", "ca"),
        ("operator", "ca"),
        ("stranger", "ca"),
        ("outsider", "otherca"),
    ] {
        common::certs::signed(d, who, ca);
    }
    let port = free_port();
    let conf = d.join("robot.conf");
    std::fs::write(
        &conf,
        format!(
            "driver simulator\nworld {}\nrobot robot1 1000 1000 90\nprovides encoders\n\
             provides motors\nprovides laser 180 1\nend_driver\nservice zenoh\nrobot pioneer\n\
             publishes all\nlisten tls/127.0.0.1:{port}\nscouting off\n\
             tls ca.pem robot.pem robot.key\nwriters operator\nend_service\n\
             load_driver simulator\nload_service zenoh\n",
            common::world_path("simple.world")
        ),
    )
    .unwrap();
    let script = d.join("tls_client.py");
    std::fs::write(&script, TLS_CLIENT).unwrap();
    let mut robot = Proc::start(&conf);
    robot.ask_until("echo encoders", "the robot", |l| {
        l.starts_with("encoders clock=")
    });
    let spawn = |who: &str| {
        Command::new(&py)
            .arg(&script)
            .args([
                &port.to_string(),
                "ca.pem",
                &format!("{who}.pem"),
                &format!("{who}.key"),
            ])
            .current_dir(d)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let finish = |who: &str, child: std::process::Child| -> serde_json::Value {
        let out = child.wait_with_output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "python ({who}): {}\n{stdout}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_str(stdout.lines().last().unwrap_or("{}")).unwrap()
    };
    let v_now = |robot: &mut Proc| {
        let l = robot.ask_until("echo motors", "motors", |l| l.starts_with("motors "));
        common::process::number_after(&l, "v=")
    };
    // The stranger: the CA signed it, so it is let in and reads; its motors
    // are refused by the access rule all the while it puts them.
    let mut child = spawn("stranger");
    let mut max_v: f64 = 0.0;
    while running(&mut child) {
        max_v = max_v.max(v_now(&mut robot));
        std::thread::sleep(std::time::Duration::from_millis(200));
    }
    let v = finish("stranger", child);
    assert!(v["laser_bytes"].as_u64().unwrap() >= 180 * 4, "{v}");
    assert_eq!(max_v, 0.0, "the stranger's motors arrived");
    // Another CA's certificate: no session at all.
    let v = finish("outsider", spawn("outsider"));
    assert_eq!(v["laser_bytes"], 0, "{v}");
    // The operator reads and drives (the script puts v=123 for 3 s).
    let mut child = spawn("operator");
    let mut drove = false;
    while running(&mut child) && !drove {
        drove = v_now(&mut robot) == 123.0;
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let v = finish("operator", child);
    assert!(v["laser_bytes"].as_u64().unwrap() >= 180 * 4, "{v}");
    assert!(drove, "the operator's motors never arrived");
    robot.quit();
}

fn running(c: &mut std::process::Child) -> bool {
    c.try_wait().ok().flatten().is_none()
}

/// The Python side: connects over TLS with the given CA, certificate and key,
/// waits up to 5 s for one laser sample, then puts motors v=123 mm/s for 3 s
/// (docs/zenoh.md: two little-endian f32, attachment clock u64, time u64 ns).
const TLS_CLIENT: &str = r#"
import json, struct, sys, time, zenoh
port, ca, cert, key = sys.argv[1:5]
conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("connect/endpoints", json.dumps([f"tls/127.0.0.1:{port}"]))
conf.insert_json5("listen/endpoints", "[]")
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(ca))
conf.insert_json5("transport/link/tls/connect_certificate", json.dumps(cert))
conf.insert_json5("transport/link/tls/connect_private_key", json.dumps(key))
conf.insert_json5("transport/link/tls/enable_mtls", "true")
conf.insert_json5("transport/link/tls/verify_name_on_connect", "true")
try:
    session = zenoh.open(conf)
except Exception as e:
    print(json.dumps({"laser_bytes": 0, "error": str(e)}))
    sys.exit(0)
got = []
sub = session.declare_subscriber("jderobot/pioneer/laser", lambda s: got.append(len(s.payload.to_bytes())))
t0 = time.time()
while not got and time.time() - t0 < 5:
    time.sleep(0.05)
pub = session.declare_publisher("jderobot/pioneer/motors")
seq = 0
t0 = time.time()
while time.time() - t0 < 3:
    seq += 1
    pub.put(struct.pack("<ff", 123.0, 0.0), attachment=struct.pack("<QQ", seq, time.time_ns()))
    time.sleep(0.05)
print(json.dumps({"laser_bytes": got[0] if got else 0}))
session.close()
"#;

/// Issue 52: a Python controller that declares the driving token
/// (`<key>/driven/<zid>`, docs/zenoh.md) drives, then closes its session: the
/// robot's motors are zero at once, long before its `motors_timeout` (5000 ms
/// here). A raw one that never declared the token keeps the `motors_timeout` rule.
#[test]
fn motors_zero_when_the_driving_python_session_closes() {
    let Some(py) = common::python_with("zenoh") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let conf = dir.path().join("robot.conf");
    std::fs::write(
        &conf,
        format!(
            "driver simulator\nworld {}\nrobot robot1 1000 1000 90\nprovides encoders\n\
             provides motors\nprovides laser 180 1\nmotors_timeout 5000\nend_driver\n\
             service zenoh\nrobot pioneer\npublishes all\nlisten tcp/127.0.0.1:{port}\n\
             scouting off\nend_service\nload_driver simulator\nload_service zenoh\n",
            common::world_path("simple.world")
        ),
    )
    .unwrap();
    let mut robot = Proc::start(&conf);
    robot.ask_until("echo encoders", "the robot", |l| {
        l.starts_with("encoders clock=")
    });
    let v = |l: &str| common::process::number_after(l, " v=");
    for declares in [true, false] {
        let script = format!(
            "import struct, time, zenoh\n\
             c = zenoh.Config()\n\
             c.insert_json5('connect/endpoints', '[\"tcp/127.0.0.1:{port}\"]')\n\
             c.insert_json5('scouting/multicast/enabled', 'false')\n\
             s = zenoh.open(c)\n\
             key = 'jderobot/pioneer/motors'\n\
             tok = s.liveliness().declare_token(f'{{key}}/driven/{{s.zid()}}') if {} else None\n\
             pub = s.declare_publisher(key)\n\
             for _ in range(10):\n    pub.put(struct.pack('<ff', 300.0, 0.0)); time.sleep(0.1)\n\
             s.close()\n",
            if declares { "True" } else { "False" }
        );
        let out = Command::new(&py).args(["-c", &script]).output().unwrap();
        assert!(
            out.status.success(),
            "python: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let closed = std::time::Instant::now();
        if declares {
            let l = robot.ask_until("echo motors", "motors zero", |l| {
                l.starts_with("motors clock=") && v(l) == 0.0
            });
            let took = closed.elapsed();
            eprintln!("motors zero {took:?} after the driving session closed: {l}");
            assert!(took < std::time::Duration::from_millis(2500), "{took:?}");
        } else {
            let l = robot.ask_until("echo motors", "motors", |l| l.starts_with("motors clock="));
            assert_eq!(
                v(&l),
                300.0,
                "a raw client's command stands until motors_timeout"
            );
            // It counts as zero after motors_timeout: the robot stops.
            let mut last = String::new();
            let stopped = common::poll_until(20, || {
                std::thread::sleep(std::time::Duration::from_millis(500));
                let e = robot.ask_until("echo encoders", "encoders", |l| {
                    l.starts_with("encoders clock=")
                });
                let e = e.split(" x=").nth(1).unwrap_or("").to_string();
                std::mem::replace(&mut last, e) == last
            });
            assert!(stopped, "the robot never stopped after a raw client left");
            eprintln!(
                "a raw client's command: robot still {:?} after it closed (motors_timeout 5000 ms)",
                closed.elapsed()
            );
        }
    }
    robot.quit();
}
