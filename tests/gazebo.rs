//! The gazebo driver against the real gz-transport (Debian 12's libignition-transport11):
//! `tests/gazebo/peer.cc`, compiled here with g++ and pkg-config, is a scripted robot
//! that publishes what gz-sim's DiffDrive, gpu_lidar and camera systems publish (same
//! topics, types and rates), and `ign-transport-topic` is gz-transport's own echo
//! tool. Each test runs in its own partition on 127.0.0.1, so they run in parallel.
//! Without the peer's toolchain (g++, pkg-config, libignition-transport-dev) a test
//! skips with a note, or fails under `CI`.
#![cfg(feature = "gazebo")]

use crate::common;

use std::{
    io::{BufRead, BufReader},
    path::{Path, PathBuf},
    process::{Child, Command, Stdio},
    sync::atomic::{AtomicUsize, Ordering},
    time::{Duration, Instant, SystemTime},
};

#[path = "gazebo/compile.rs"]
mod compile;

use common::{eventually, poll_until, root, start_conf};
use jderobot::interfaces::{Encoders, Image, Imu, Laser, Motors, PtEncoders, PtMotors};

/// Skips (or fails under CI) with `note`.
fn missing(note: &str) -> Option<PathBuf> {
    assert!(std::env::var_os("CI").is_none(), "under CI: {note}");
    eprintln!("SKIPPED: {note}");
    None
}

/// The peer, compiled into target/gazebo-peer when its source is newer. The tests
/// of one binary ask for it at the same time: one compiles while the others wait
/// (an executable being written cannot be run: "Text file busy").
pub(crate) fn peer_bin() -> Option<PathBuf> {
    static BUILD: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let src = root().join("tests/gazebo/peer.cc");
    let bin = root().join("target/gazebo-peer/peer");
    let newer = |a: &Path, b: &Path| {
        let m = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
        m(a) > m(b)
    };
    if bin.exists() && !newer(&src, &bin) {
        return Some(bin);
    }
    compile::build_peer(&root(), "peer").map_or_else(|why| missing(&why), Some)
}

/// gz-transport's echo tool, where Debian puts it.
fn topic_tool() -> Option<PathBuf> {
    for p in [
        "/usr/libexec/ignition/transport11/ign-transport-topic",
        "/usr/lib/x86_64-linux-gnu/ignition/transport11/ign-transport-topic",
    ] {
        if Path::new(p).exists() {
            return Some(p.into());
        }
    }
    missing("no ign-transport-topic: apt-get install ignition-transport-cli")
}

/// A partition of this test alone.
pub(crate) fn partition() -> String {
    static N: AtomicUsize = AtomicUsize::new(0);
    format!(
        "jdetest{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::SeqCst)
    )
}

/// A child process killed when dropped.
pub(crate) struct Proc(pub(crate) Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

pub(crate) fn gz(cmd: &Path, part: &str) -> Command {
    let mut c = Command::new(cmd);
    c.env("IGN_IP", "127.0.0.1")
        .env("IGN_PARTITION", part)
        .stdin(Stdio::null());
    c
}

/// Starts the scripted robot and waits for it to say it is ready.
pub(crate) fn robot(bin: &Path, part: &str, args: &[&str]) -> Proc {
    let mut c = gz(bin, part);
    c.arg("robot").args(args).stdout(Stdio::piped());
    let mut child = c.spawn().expect("start the peer");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(line.starts_with("peer ready"), "peer said {line:?}");
    Proc(child)
}

pub(crate) fn head(part: &str, name: &str) -> String {
    format!("driver {name}\npartition {part}\nip 127.0.0.1\n")
}

#[test]
fn introrob_vff_drives_the_peer_robot_to_its_target() {
    let Some(bin) = peer_bin() else { return };
    let part = partition();
    let _peer = robot(&bin, &part, &["--model", "robot1", "--lidar", "/lidar"]);
    let rt = start_conf(&format!(
        "{}provides encoders robot1\nprovides motors robot1\nprovides laser lidar\nend_driver\n\
         schema introrob\nbehaviour vff\ntarget 2500 1500\nmax_v 400\nmax_w 40\nend_schema\n\
         load_driver gazebo\nload_schema introrob\nrun introrob\n",
        head(&part, "gazebo")
    ));
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let laser = rt.interfaces.get::<Laser>("laser").unwrap();
    eventually("odometry and a scan", || {
        enc.read().clock > 0 && laser.read().clock > 0
    });
    let l = laser.read();
    assert_eq!(l.readings.len(), 180);
    // Straight ahead from the room's centre: the wall at x = 5 m.
    assert!((l.readings[90] - 5000).abs() <= 30, "{:?}", l.readings[90]);
    drop(l);
    let d = |e: Encoders| ((e.x - 2500.0).powi(2) + (e.y - 1500.0).powi(2)).sqrt();
    let d0 = d(enc.read().value);
    let t = Instant::now();
    let mut best = d0;
    while t.elapsed() < Duration::from_secs(40) && best > 400.0 {
        std::thread::sleep(Duration::from_millis(100));
        best = best.min(d(enc.read().value));
    }
    rt.shutdown();
    assert!(
        best <= 400.0,
        "the peer robot did not reach the target: {d0:.0} → {best:.0} mm"
    );
}

#[test]
fn the_echo_tool_shows_our_twist_and_the_stop_sends_zero() {
    let (Some(bin), Some(tool)) = (peer_bin(), topic_tool()) else {
        return;
    };
    let part = partition();
    let rt = start_conf(&format!(
        "{}provides motors robot9\nmotors_timeout 5000\nend_driver\nload_driver gazebo\n",
        head(&part, "gazebo")
    ));
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    motors.publish(Motors { v: 500.0, w: 30.0 }).unwrap();
    let echo = gz(&tool, &part)
        .args(["-e", "-t", "/model/robot9/cmd_vel", "-n", "2"])
        .output()
        .expect("run ign-transport-topic");
    let text = String::from_utf8_lossy(&echo.stdout);
    assert!(
        text.contains("x: 0.5") && text.contains("z: 0.5235"),
        "ign-transport-topic echoed: {text}"
    );
    // The echo tool left: DiffDrive's place is empty, so the driver counts it lost
    // and zeroed the motors. A C++ subscriber sees a new command, then the zero sent
    // at stop.
    std::thread::sleep(Duration::from_millis(300));
    let mut sub = gz(&bin, &part)
        .args([
            "echo-twist",
            "--topic",
            "/model/robot9/cmd_vel",
            "--seconds",
            "20",
        ])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(sub.stdout.take().unwrap()).lines();
    // Commanded until the subscriber shows it (its discovery takes a moment).
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let pusher = {
        let (m, stop) = (motors.clone(), stop.clone());
        std::thread::spawn(move || {
            while !stop.load(Ordering::SeqCst) {
                let _ = m.publish(Motors { v: 500.0, w: 30.0 });
                std::thread::sleep(Duration::from_millis(100));
            }
        })
    };
    let mut seen = false;
    while let Some(Ok(l)) = lines.next() {
        if l == "twist 0.5000 0.5236" {
            seen = true;
            break;
        }
    }
    stop.store(true, Ordering::SeqCst);
    pusher.join().unwrap();
    assert!(seen, "the C++ subscriber got our Twist");
    rt.shutdown();
    let mut last = String::new();
    let t = Instant::now();
    while let Some(Ok(l)) = lines.next() {
        last = l;
        if last == "twist 0.0000 0.0000" || t.elapsed() > Duration::from_secs(10) {
            break;
        }
    }
    let _ = sub.kill();
    let _ = sub.wait();
    assert_eq!(last, "twist 0.0000 0.0000", "the stop sent zero");
}

#[test]
fn camera_frames_arrive_at_their_size_and_rate() {
    let Some(bin) = peer_bin() else { return };
    let part = partition();
    let _peer = robot(
        &bin,
        &part,
        &[
            "--model", "r", "--camera", "/camera", "--width", "640", "--height", "480", "--fps",
            "30",
        ],
    );
    let rt = start_conf(&format!(
        "{}provides varcolorA camera\nprovides colorA /camera\nend_driver\nload_driver gazebo\n",
        head(&part, "gazebo")
    ));
    let var = rt.interfaces.get::<Image>("varcolorA").unwrap();
    let col = rt.interfaces.get::<Image>("colorA").unwrap();
    eventually("frames", || var.read().clock > 2 && col.read().clock > 2);
    let s = var.read();
    assert_eq!((s.width, s.height), (640, 480));
    // RGB red on the left, blue on the right, as BGR.
    assert_eq!(s.pixel(10, 240), [0, 0, 200]);
    assert_eq!(s.pixel(600, 240), [200, 0, 0]);
    // Gazebo's simulation time rides on the value's time.
    assert!(s.time < SystemTime::UNIX_EPOCH + Duration::from_secs(86_400));
    drop(s);
    let c = col.read();
    assert_eq!((c.width, c.height), (320, 240));
    assert_eq!(c.pixel(300, 10), [200, 0, 0]);
    drop(c);
    let (c0, t0) = (var.read().clock, Instant::now());
    std::thread::sleep(Duration::from_secs(3));
    let rate = (var.read().clock - c0) as f64 / t0.elapsed().as_secs_f64();
    rt.shutdown();
    assert!(
        (15.0..=40.0).contains(&rate),
        "640x480 frames at {rate:.1}/s (the peer sends 30/s)"
    );
}

#[test]
fn killing_the_peer_marks_stale_and_zeroes_motors_and_a_restart_brings_it_back() {
    let Some(bin) = peer_bin() else { return };
    let part = partition();
    let args = ["--model", "robot1", "--lidar", "/lidar"];
    let peer = robot(&bin, &part, &args);
    let rt = start_conf(&format!(
        "{}provides encoders robot1\nprovides motors robot1\nprovides laser lidar\n\
         motors_timeout 60000\nend_driver\nload_driver gazebo08\n",
        head(&part, "gazebo08")
    ));
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    // Commanded as a schema does, every 100 ms.
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let pusher = {
        let (m, stop) = (motors.clone(), stop.clone());
        std::thread::spawn(move || {
            while !stop.load(Ordering::SeqCst) {
                let _ = m.publish(Motors { v: 200.0, w: 0.0 });
                std::thread::sleep(Duration::from_millis(100));
            }
        })
    };
    let state = |what: &str| {
        format!(
            "{what}: encoders {:?} stale {:?}; motors {:?} stale {:?}",
            enc.read().value,
            enc.stale(),
            motors.read().value,
            motors.stale()
        )
    };
    assert!(
        poll_until(20, || enc.read().x > 50.0),
        "{}",
        state("the robot did not move")
    );
    assert!(enc.stale().is_none());
    stop.store(true, Ordering::SeqCst);
    pusher.join().unwrap();
    drop(peer);
    assert!(
        poll_until(20, || enc.stale().is_some()
            && motors.read().value == Motors::default()),
        "{}",
        state("not stale with motors zero after the kill")
    );
    let why = enc.stale().unwrap();
    assert!(why.contains("lost Gazebo"), "{why}");
    let _peer = robot(&bin, &part, &args);
    let c = enc.read().clock;
    assert!(
        poll_until(20, || enc.stale().is_none() && enc.read().clock > c + 5),
        "{}",
        state("not back after the restart")
    );
    rt.shutdown();
}

#[test]
fn the_pan_tilt_head_follows_pantiltmotors() {
    let Some(bin) = peer_bin() else { return };
    let part = partition();
    let _peer = robot(&bin, &part, &["--model", "robot1", "--pantilt"]);
    let rt = start_conf(&format!(
        "{}provides pantiltencoders robot1\nprovides pantiltmotors robot1\nend_driver\n\
         load_driver gazebo\n",
        head(&part, "gazebo")
    ));
    let enc = rt.interfaces.get::<PtEncoders>("pantiltencoders").unwrap();
    let m = rt.interfaces.get::<PtMotors>("pantiltmotors").unwrap();
    let mut cmd = m.read().value;
    cmd.longitude = 30.0;
    cmd.latitude = -10.0;
    m.publish(cmd).unwrap();
    eventually("the head at 30, -10 deg", || {
        let e = enc.read();
        (e.pan_angle - 30.0).abs() < 0.5 && (e.tilt_angle + 10.0).abs() < 0.5
    });
    rt.shutdown();
}

#[test]
fn the_imu_gives_heading_turn_rate_and_gravity_in_si_units() {
    let Some(bin) = peer_bin() else { return };
    let part = partition();
    let _peer = robot(&bin, &part, &["--model", "robot1", "--imu", "/imu"]);
    let rt = start_conf(&format!(
        "{}provides imu imu\nprovides motors robot1\nmotors_timeout 60000\nend_driver\n\
         load_driver gazebo\n",
        head(&part, "gazebo")
    ));
    let imu = rt.interfaces.get::<Imu>("imu").unwrap();
    let m = rt.interfaces.get::<Motors>("motors").unwrap();
    eventually("IMU readings at rest: level, gravity up", || {
        let v = imu.read().value;
        imu.read().clock > 0 && (v.az - 9.80665).abs() < 1e-3 && v.qw > 0.999
    });
    // Turn in place at 30 deg/s: the turn rate in rad/s, the heading grows.
    let mut cmd = m.read().value;
    cmd.w = 30.0;
    m.publish(cmd).unwrap();
    eventually("the IMU's turn rate at 30 deg/s", || {
        let v = imu.read().value;
        (v.wz - 30f32.to_radians()).abs() < 1e-3 && v.euler().2 > 0.1
    });
    rt.shutdown();
}

/// The binary's output for `secs` with `conf`.
fn run(dir: &Path, conf: &str, secs: f64) -> String {
    let f = dir.join("gz.conf");
    std::fs::write(&f, conf).unwrap();
    let out = common::run_for(&f, secs);
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

#[test]
fn faults_say_what_is_awaited_what_exists_and_both_types() {
    let dir = tempfile::tempdir().unwrap();
    // No Gazebo: one line naming the topics awaited.
    let part = partition();
    let out = run(
        dir.path(),
        &format!(
            "{}provides encoders robot1\nprovides motors robot1\nend_driver\nload_driver gazebo\n",
            head(&part, "gazebo")
        ),
        0.5,
    );
    let want = format!(
        "gz.conf:4: gazebo: no Gazebo in partition `{part}` on 127.0.0.1: waiting for \
         /model/robot1/odometry (Odometry), /model/robot1/cmd_vel (a Twist subscriber: DiffDrive)"
    );
    assert!(out.contains(&want), "{out}");
    let Some(bin) = peer_bin() else { return };
    let _peer = robot(&bin, &part, &["--model", "robot1", "--lidar", "/lidar"]);
    // An unknown model: the topics that exist.
    let out = run(
        dir.path(),
        &format!(
            "{}provides encoders robot7\nwait 300\nend_driver\nload_driver gazebo\n",
            head(&part, "gazebo")
        ),
        0.5,
    );
    assert!(
        out.contains("still no /model/robot7/odometry (Odometry)")
            && out.contains("/model/robot1/odometry (ignition.msgs.Odometry)")
            && out.contains("/lidar (ignition.msgs.LaserScan)"),
        "{out}"
    );
    // A wrong type: both named.
    let out = run(
        dir.path(),
        &format!(
            "{}provides varcolorA /lidar\nend_driver\nload_driver gazebo\n",
            head(&part, "gazebo")
        ),
        0.5,
    );
    assert!(
        out.contains(
            "/lidar is published as ignition.msgs.LaserScan, but varcolorA reads \
             ignition.msgs.Image or gz.msgs.Image"
        ),
        "{out}"
    );
    // The lines the driver declares.
    let help = common::help("gazebo08");
    assert!(
        help.contains("partition") && help.contains("messages"),
        "{help}"
    );
    assert!(poll_until(1, || true));
}

/// Issue 52: a `jderobot` process driving a Gazebo robot from its shell sends a
/// zero Twist on its cmd_vel (estop, through each subscriber's connection) when
/// it gets SIGTERM or SIGTSTP, before it ends or suspends; the C++ gz-transport
/// subscriber (DiffDrive's place) timestamps each Twist as it comes.
#[test]
fn ending_and_suspending_signals_send_a_zero_twist_within_100_ms() {
    use common::process::{Proc as Jde, STOP_SIGNALS, timed_lines};
    let Some(bin) = peer_bin() else {
        return;
    };
    for signal in STOP_SIGNALS {
        let part = partition();
        let mut sub = gz(&bin, &part)
            .args([
                "echo-twist",
                "--topic",
                "/model/robot9/cmd_vel",
                "--seconds",
                "60",
            ])
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let lines = timed_lines(&mut sub);
        let _sub = Proc(sub);
        let dir = tempfile::tempdir().unwrap();
        let conf = dir.path().join("gazebo.conf");
        std::fs::write(
            &conf,
            format!(
                "{}provides motors robot9\nmotors_timeout 60000\nend_driver\nload_driver gazebo\n",
                head(&part, "gazebo")
            ),
        )
        .unwrap();
        let mut p = Jde::start_alone(&conf);
        common::process::drive_twist_peer_then_signal(
            &mut p,
            "gazebo (a zero Twist)",
            signal,
            &lines,
        );
    }
}
