//! naobody against a NAOqi stand-in on the real libqi (`qi` from PyPI, in the test
//! venv): `tests/emulators/naoqi.py` registers ALMotion, ALVideoDevice and ALMemory
//! with NAOqi's documented methods on a standalone qi session. The driver's own
//! qi client (Rust) talks to it over TCP. Without the venv's `qi` the tests skip,
//! and fail under `CI`.
#![cfg(feature = "naobody")]

use crate::common;

use std::{
    io::{Read, Write},
    net::TcpListener,
    path::{Path, PathBuf},
    process::{Child, Command, Stdio},
    sync::{
        Arc, Mutex,
        atomic::{AtomicUsize, Ordering},
    },
    time::{Duration, Instant},
};

use common::{eventually, poll_until, process::free_port, start_conf};
use jderobot::interfaces::{Bumpers, Encoders, Image, Motors, PtEncoders, PtMotors, Sonars};

/// The NAOqi stand-in, killed when dropped.
pub(crate) struct Peer {
    child: Child,
    out: Arc<Mutex<String>>,
    pub(crate) port: u16,
}

impl Peer {
    pub(crate) fn start(py: &Path, port: u16, extra: &[&str]) -> Peer {
        let mut child = Command::new(py)
            .arg(common::root().join("tests/emulators/naoqi.py"))
            .args(["--url", &format!("tcp://127.0.0.1:{port}"), "--trace"])
            .args(extra)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start the NAOqi stand-in");
        let out = common::process::collect_output(&mut child);
        let p = Peer { child, out, port };
        assert!(
            poll_until(20, || p.text().contains("READY tcp://")),
            "the stand-in did not start:\n{}",
            p.text()
        );
        p
    }

    pub(crate) fn text(&self) -> String {
        self.out.lock().unwrap().clone()
    }

    pub(crate) fn count(&self, what: &str) -> usize {
        self.text().lines().filter(|l| l.starts_with(what)).count()
    }

    fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Peer {
    fn drop(&mut self) {
        self.kill();
    }
}

pub(crate) fn python() -> Option<PathBuf> {
    common::python_with("qi")
}

pub(crate) fn naobody(port: u16, lines: &str) -> String {
    format!(
        "driver naobody\nurl tcp://127.0.0.1:{port}\npoll 50\n{lines}end_driver\nload_driver naobody\n"
    )
}

#[cfg(feature = "naooperator")]
#[test]
fn naooperator_drives_the_nao_from_the_shell() {
    let Some(py) = python() else { return };
    let peer = Peer::start(&py, free_port(), &[]);
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("nao.conf");
    std::fs::write(
        &conf,
        naobody(
            peer.port,
            "provides motors\nprovides encoders\nprovides ptmotors\nprovides ptencoders\n\
             provides varcolorA 0 320 240\nfps 10\n",
        ) + "schema naooperator\nwalk 80 0\nhead 20 -10\nend_schema\nload_schema naooperator\n",
    )
    .unwrap();
    let mut p = common::process::Proc::start(&conf);
    let start = p.ask_until("echo encoders", "odometry", |l| {
        l.starts_with("encoders clock=")
    });
    p.send("run naooperator");
    let moved = p.expect_moved(&start, 60.0);
    let (x, y) = common::process::xy(&moved);
    assert!(x > 60.0 && y.abs() < 10.0, "walks straight ahead: {moved}");
    p.ask_until("echo pantiltencoders", "the head at (20, -10)", |l| {
        l.starts_with("pantiltencoders clock=")
            && (common::process::number_after(l, "pan_angle=") - 20.0).abs() < 0.5
            && (common::process::number_after(l, "tilt_angle=") + 10.0).abs() < 0.5
    });
    p.send("stop naooperator");
    assert!(
        poll_until(10, || peer.text().lines().last() == Some("CALL stopMove")),
        "stopping naooperator stops the walk:\n{}",
        peer.text()
    );
    let t = peer.text();
    let wake = t.find("CALL wakeUp").expect("woken up before walking");
    assert!(
        wake < t.find("MOVE 0.080000").expect("walks at 80 mm/s"),
        "{t}"
    );
    assert!(p.text().contains("waking the robot up"), "{}", p.text());
    p.quit();
}

#[test]
fn the_walk_turns_and_stops_on_zero_and_on_timeout() {
    let Some(py) = python() else { return };
    let peer = Peer::start(&py, free_port(), &[]);
    let rt = start_conf(&naobody(
        peer.port,
        "provides motors\nprovides encoders\nmax_w 30\nmotors_timeout 300\n",
    ));
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    eventually("odometry", || enc.clock() > 0);
    // Turning in place, kept alive as a schema would, clamped to max_w.
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_millis(1500) {
        motors.publish(Motors { v: 0.0, w: 90.0 }).unwrap();
        std::thread::sleep(Duration::from_millis(50));
    }
    let theta = enc.read().theta;
    assert!(
        (0.3..0.9).contains(&theta),
        "about 30 deg/s for 1.5 s, counter-clockwise: {theta} rad"
    );
    assert!(
        peer.text()
            .contains(&format!("MOVE 0.000000 0.000000 {:.6}", 30f32.to_radians()))
    );
    // No new command: after motors_timeout the walk stops.
    let stops = peer.count("CALL stopMove");
    eventually("stopMove after motors_timeout", || {
        peer.count("CALL stopMove") > stops
    });
    // (a poll or two later, the odometry holds still)
    std::thread::sleep(Duration::from_millis(200));
    let a = enc.read().theta;
    std::thread::sleep(Duration::from_millis(400));
    assert!((enc.read().theta - a).abs() < 0.005, "stopped");
    // Zero stops at once, too.
    motors.publish(Motors { v: 50.0, w: 0.0 }).unwrap();
    eventually("walks", || peer.text().contains("MOVE 0.050000"));
    let stops = peer.count("CALL stopMove");
    motors.publish(Motors::default()).unwrap();
    eventually("stopMove on zero", || peer.count("CALL stopMove") > stops);
    rt.shutdown();
}

/// A `jderobot` process (signalled alone) walking the stand-in's NAO from its
/// shell at 80 mm/s, with a command that does not expire.
fn walking(py: &Path) -> (Peer, common::process::Proc, tempfile::TempDir) {
    let peer = Peer::start(py, free_port(), &[]);
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("nao.conf");
    std::fs::write(
        &conf,
        naobody(peer.port, "provides motors\nmotors_timeout 60000\n"),
    )
    .unwrap();
    let mut p = common::process::Proc::start_alone(&conf);
    let walks = poll_until(20, || {
        p.send("set motors v=80 w=0");
        std::thread::sleep(Duration::from_millis(200));
        peer.count("MOVE 0.080000") > 0
    });
    assert!(
        walks,
        "the robot never walked; jderobot said:\n{}\nthe stand-in:\n{}",
        p.text(),
        peer.text()
    );
    (peer, p, dir)
}

/// Issue 52: a `jderobot` process walking the NAO from its shell sends
/// `ALMotion.stopMove` (through its estop handle on the session's socket) when
/// it gets SIGTERM or SIGTSTP, before it ends or suspends. The time is when the
/// stand-in's trace line reached the test (an upper bound).
#[test]
fn ending_and_suspending_signals_send_stop_move_within_100_ms() {
    let Some(py) = python() else { return };
    for signal in common::process::STOP_SIGNALS {
        let (peer, mut p, _dir) = walking(&py);
        let stops = peer.count("CALL stopMove");
        common::process::signal_stops_within_100_ms(&mut p, "naobody (stopMove)", signal, |_| {
            (peer.count("CALL stopMove") > stops).then(Instant::now)
        });
    }
}

/// Issue 52: after Ctrl+Z (stopMove) and `fg`, the NAO stands until the
/// controller's next command: the one it had is not sent again.
#[test]
fn after_a_suspension_the_nao_walks_on_the_next_command_only() {
    let Some(py) = python() else { return };
    let (peer, mut p, _dir) = walking(&py);
    let stops = peer.count("CALL stopMove");
    p.signal(libc::SIGTSTP);
    eventually("stopMove", || peer.count("CALL stopMove") > stops);
    eventually("suspended", || p.state() == 'T');
    p.signal(libc::SIGCONT);
    eventually("resumed", || p.state() != 'T');
    let moves = peer.count("MOVE ");
    std::thread::sleep(Duration::from_millis(500));
    assert_eq!(peer.count("MOVE "), moves, "stands:\n{}", peer.text());
    p.send("set motors v=60 w=0");
    eventually("walks on the next command", || {
        peer.count("MOVE 0.060000") > 0
    });
    assert!(p.quit().success());
}

#[test]
fn the_head_follows_ptmotors_within_the_robots_limits() {
    let Some(py) = python() else { return };
    let peer = Peer::start(&py, free_port(), &[]);
    let rt = start_conf(&naobody(
        peer.port,
        "provides ptmotors\nprovides ptencoders\n",
    ));
    let ptm = rt.interfaces.get::<PtMotors>("pantiltmotors").unwrap();
    let pte = rt.interfaces.get::<PtEncoders>("pantiltencoders").unwrap();
    // The limits come from ALMotion.getLimits (NAO V5: HeadYaw ±119.5°, HeadPitch
    // -38.5° (up) .. 29.5° (down)).
    eventually("the robot's limits", || {
        (ptm.read().max_longitude - 119.5).abs() < 0.1
    });
    let m = ptm.read().value;
    assert!(
        (m.min_latitude + 29.5).abs() < 0.1 && (m.max_latitude - 38.5).abs() < 0.1,
        "{m:?}"
    );
    assert!((m.max_longitude_speed - 473.7).abs() < 0.5, "{m:?}");
    for (lon, lat, want) in [
        (45.0, 20.0, (45.0, 20.0)),
        (200.0, -80.0, (119.5, -29.5)),
        (-30.0, 60.0, (-30.0, 38.5)),
    ] {
        let mut c = ptm.read().value;
        (c.longitude, c.latitude) = (lon, lat);
        c.longitude_speed = 400.0;
        c.latitude_speed = 400.0;
        ptm.publish(c).unwrap();
        eventually(&format!("the head at {want:?}"), || {
            let p = pte.read().value;
            (p.pan_angle - want.0).abs() < 0.2 && (p.tilt_angle - want.1).abs() < 0.2
        });
    }
    rt.shutdown();
}

#[test]
fn frames_arrive_at_fps_in_size_and_colour() {
    let Some(py) = python() else { return };
    let peer = Peer::start(&py, free_port(), &[]);
    for (space, w, h, fps) in [
        ("bgr", 320, 240, 10),
        ("rgb", 160, 120, 5),
        ("yuv422", 640, 480, 10),
    ] {
        let rt = start_conf(&naobody(
            peer.port,
            &format!(
                "provides varcolorA 0 {w} {h}\nprovides colorB 1\nfps {fps}\ncolorspace {space}\n"
            ),
        ));
        let cam = rt.interfaces.get::<Image>("varcolorA").unwrap();
        let subscribed = peer.count("SUBSCRIBE jderobot_varcolorA");
        std::thread::sleep(Duration::from_millis(300));
        assert_eq!(
            peer.count("SUBSCRIBE jderobot_varcolorA"),
            subscribed,
            "not subscribed while unused"
        );
        cam.resume();
        eventually("a first frame", || cam.clock() > 0);
        let (c0, t0) = (cam.clock(), Instant::now());
        std::thread::sleep(Duration::from_secs(2));
        let n = (cam.clock() - c0) as f64 / t0.elapsed().as_secs_f64();
        // A new frame every 1/fps s; never more than the camera gives.
        assert!(
            n > fps as f64 * 0.4 && n < fps as f64 * 1.3,
            "{space}: {n} frames/s at fps {fps}"
        );
        let img = cam.read().value.clone();
        assert_eq!((img.width, img.height), (w, h), "{space}");
        let tol = |a: [u8; 3], b: [u8; 3]| a.iter().zip(b).all(|(x, y)| x.abs_diff(y) <= 12);
        let (red, blue) = (img.pixel(2, h / 2), img.pixel(w - 3, h / 2));
        assert!(
            tol(red, [0, 0, 255]),
            "{space}: left half red (BGR), got {red:?}"
        );
        assert!(
            tol(blue, [255, 0, 0]),
            "{space}: right half blue, got {blue:?}"
        );
        cam.suspend();
        eventually("unsubscribed when unused", || {
            peer.count("UNSUBSCRIBE jderobot_varcolorA")
                == peer.count("SUBSCRIBE jderobot_varcolorA")
        });
        rt.shutdown();
    }
}

#[test]
fn sonars_and_bumpers_come_from_almemory() {
    let Some(py) = python() else { return };
    let peer = Peer::start(&py, free_port(), &[]);
    let rt = start_conf(&naobody(peer.port, "provides sonars\nprovides bumpers\n"));
    let us = rt.interfaces.get::<Sonars>("sonars").unwrap();
    let b = rt.interfaces.get::<Bumpers>("bumpers").unwrap();
    eventually("sonars", || us.clock() > 0 && b.clock() > 0);
    assert_eq!(us.read().us, vec![800.0, 1250.0]);
    assert_eq!(b.read().bumpers, vec![0, 1, 0, 0]);
    rt.shutdown();
}

#[test]
fn killing_naoqi_turns_the_interfaces_stale_and_a_restart_brings_them_back() {
    let Some(py) = python() else { return };
    let port = free_port();
    let mut peer = Peer::start(&py, port, &[]);
    let rt = start_conf(&naobody(
        port,
        "provides motors\nprovides encoders\nprovides varcolorA 0 160 120\nfps 10\nreply_timeout 1000\n",
    ));
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let cam = rt.interfaces.get::<Image>("varcolorA").unwrap();
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    cam.resume();
    eventually("odometry and frames", || enc.clock() > 0 && cam.clock() > 0);
    peer.kill();
    eventually("stale", || enc.stale().is_some() && cam.stale().is_some());
    let why = enc.stale().unwrap();
    assert!(why.contains(&format!("127.0.0.1:{port}")), "{why}");
    let peer = Peer::start(&py, port, &[]);
    eventually("back", || {
        enc.stale().is_none() && cam.stale().is_none() && motors.stale().is_none()
    });
    let (e, c) = (enc.clock(), cam.clock());
    eventually("values again", || enc.clock() > e && cam.clock() > c);
    // The walk is stopped on reconnection, and the camera subscribed again.
    assert!(peer.text().contains("CALL stopMove"), "{}", peer.text());
    assert!(
        peer.text().contains("SUBSCRIBE jderobot_varcolorA"),
        "{}",
        peer.text()
    );
    assert_eq!(motors.read().value, Motors::default());
    rt.shutdown();
}

#[test]
fn no_naoqi_at_start_is_one_line_naming_the_url_and_what_to_start() {
    let port = free_port();
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("nao.conf");
    std::fs::write(
        &conf,
        naobody(
            port,
            "provides motors\nprovides encoders\nprovides varcolorA 0 320 240\n",
        ),
    )
    .unwrap();
    let out = common::run_for(&conf, 2.5);
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| l.contains("no NAOqi answers"))
        .collect();
    assert_eq!(lines.len(), 1, "{text}");
    assert!(
        lines[0].contains(&format!("tcp://127.0.0.1:{port}")) && lines[0].contains("start NAOqi"),
        "{text}"
    );
    // In process: every interface is stale with that reason.
    let rt = start_conf(&naobody(
        port,
        "provides motors\nprovides varcolorA 0 320 240\n",
    ));
    for name in ["motors", "varcolorA"] {
        let why = rt
            .interfaces
            .get_any(name)
            .unwrap()
            .stale()
            .unwrap_or_default();
        assert!(why.contains("no NAOqi answers"), "{name}: {why:?}");
    }
    rt.shutdown();
}

#[test]
fn a_missing_method_is_named_with_the_naoqi_version() {
    let Some(py) = python() else { return };
    let peer = Peer::start(&py, free_port(), &["--without", "ALMotion.setAngles"]);
    let rt = start_conf(&naobody(peer.port, "provides ptmotors\n"));
    let ptm = rt.interfaces.get::<PtMotors>("pantiltmotors").unwrap();
    eventually("stale with the reason", || ptm.stale().is_some());
    let why = ptm.stale().unwrap();
    assert!(
        why.contains("ALMotion.setAngles") && why.contains("NAOqi 2.5.5.5"),
        "{why}"
    );
    rt.shutdown();
    // A missing service too.
    let peer = Peer::start(&py, free_port(), &["--without", "ALVideoDevice."]);
    let rt = start_conf(&naobody(peer.port, "provides varcolorA 0 320 240\n"));
    let cam = rt.interfaces.get::<Image>("varcolorA").unwrap();
    cam.resume();
    eventually("stale with the reason", || {
        cam.stale().is_some_and(|w| w.contains("ALVideoDevice"))
    });
    assert!(
        cam.stale()
            .unwrap()
            .contains("has no ALVideoDevice service"),
        "{:?}",
        cam.stale()
    );
    rt.shutdown();
}

#[test]
fn without_move_the_walk_uses_move_toward() {
    let Some(py) = python() else { return };
    let peer = Peer::start(&py, free_port(), &["--without", "ALMotion.move"]);
    let rt = start_conf(&naobody(
        peer.port,
        "provides motors\nprovides encoders\nmax_v 100\n",
    ));
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    eventually("odometry", || enc.clock() > 0);
    motors.publish(Motors { v: 50.0, w: 0.0 }).unwrap();
    eventually("moveToward at half speed", || {
        peer.text()
            .contains("MOVETOWARD 0.500000 0.000000 0.000000")
    });
    eventually("walks", || enc.read().x > 5.0);
    rt.shutdown();
}

#[test]
fn services_of_another_process_are_reached_at_their_own_endpoint() {
    let Some(py) = python() else { return };
    let main = Peer::start(
        &py,
        free_port(),
        &["--without", "ALMemory.", "--without", "ALVideoDevice."],
    );
    let sd = format!("tcp://127.0.0.1:{}", main.port);
    let other = Peer::start(&py, free_port(), &["--join", &sd, "--without", "ALMotion."]);
    let rt = start_conf(&naobody(
        main.port,
        "provides encoders
provides sonars
provides varcolorA 0 160 120
",
    ));
    let (enc, us) = (
        rt.interfaces.get::<Encoders>("encoders").unwrap(),
        rt.interfaces.get::<Sonars>("sonars").unwrap(),
    );
    let cam = rt.interfaces.get::<Image>("varcolorA").unwrap();
    cam.resume();
    eventually(
        "odometry from one process, sonars and frames from the other",
        || enc.clock() > 0 && us.clock() > 0 && cam.clock() > 0,
    );
    assert!(other.text().contains("SUBSCRIBE jderobot_varcolorA"));
    rt.shutdown();
}

/// A server that is not NAOqi: garbage, or a header promising a huge payload.
fn bad_server(reply: &'static [u8]) -> (u16, Arc<AtomicUsize>) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    let accepted = Arc::new(AtomicUsize::new(0));
    let a = accepted.clone();
    std::thread::spawn(move || {
        for s in l.incoming() {
            let Ok(mut s) = s else { continue };
            a.fetch_add(1, Ordering::SeqCst);
            // Read what the client says (its authentication), answer, then close.
            let _ = s.set_read_timeout(Some(Duration::from_millis(200)));
            let mut b = [0u8; 256];
            while s.read(&mut b).is_ok_and(|n| n > 0) {}
            let _ = s.write_all(reply);
            std::thread::sleep(Duration::from_millis(100));
        }
    });
    (port, accepted)
}

#[test]
fn garbage_on_the_socket_is_dropped_and_the_driver_reconnects() {
    // A 28-byte header with qi's magic, a Reply, and a 32 MB payload that never comes.
    const HUGE: &[u8] = &[
        0x42, 0xde, 0xad, 0x42, 1, 0, 0, 0, 0, 0, 0, 2, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 8, 0,
        0, 0,
    ];
    for (reply, expect) in [
        (
            b"HTTP/1.1 400 Bad Request\r\n\r\nnot qi at all, but long enough".as_slice(),
            "magic",
        ),
        (HUGE, "into a 33554432-byte payload"),
    ] {
        let (port, accepted) = bad_server(reply);
        let rt = start_conf(&naobody(port, "provides encoders\nreply_timeout 500\n"));
        let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
        eventually("stale with the reason", || {
            enc.stale().is_some_and(|w| w.contains(expect))
        });
        eventually("reconnects", || accepted.load(Ordering::SeqCst) >= 2);
        rt.shutdown();
    }
}

#[cfg(feature = "introrob")]
#[test]
fn introrob_in_teleop_mode_drives_the_nao() {
    let Some(py) = python() else { return };
    let peer = Peer::start(&py, free_port(), &[]);
    // A NAO has no laser: `laser none`.
    let rt = start_conf(
        &(naobody(
            peer.port,
            "provides motors\nprovides encoders\nprovides sonars\nprovides bumpers\n",
        ) + "schema introrob\nbehaviour teleop\nteleop 90 0\nlaser none\ncamera none\nend_schema\n\
               load_schema introrob\nrun introrob\n"),
    );
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    eventually("walks ahead", || enc.read().x > 80.0);
    assert!(
        peer.text().contains("MOVE 0.090000 0.000000 0.000000"),
        "{}",
        peer.text()
    );
    rt.stop("introrob").unwrap();
    eventually("stops", || {
        peer.text().lines().last() == Some("CALL stopMove")
    });
    rt.shutdown();
}
