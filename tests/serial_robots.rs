//! The roomba and rplidar drivers against emulators of an iRobot Create 2
//! (tests/emulators/create2.rs, from the Create 2 Open Interface Specification) and
//! a Slamtec RPLIDAR A1 (tests/emulators/rplidar.rs, from the RPLIDAR Interface
//! Protocol) on pseudo-terminals, both in one room (tests/emulators/room.rs):
//! Drive Direct distances, bumps at a wall, checksums, 360° scans at the device's
//! rate with the walls where they are, faults, unplugging, and introrob's VFF
//! driving the two to a target.
#![cfg(all(feature = "roomba", feature = "rplidar"))]

use crate::{common, ptu};
#[path = "emulators/create2.rs"]
mod create2;
#[path = "emulators/room.rs"]
mod room;
#[path = "emulators/rplidar.rs"]
mod rplidar;

use std::{
    path::Path,
    sync::Arc,
    time::{Duration, Instant},
};

use common::{eventually, poll_until, process::Proc, start_conf};
use jderobot::interfaces::{Bumpers, Encoders, Interface, Laser, Motors};

fn roomba_conf(port: &Path, extra: &str) -> String {
    format!(
        "driver roomba\nserial {}\n{extra}provides motors\nprovides encoders\nprovides bumpers\n\
         end_driver\nload_driver roomba\n",
        port.display()
    )
}

fn lidar_conf(port: &Path, extra: &str) -> String {
    format!(
        "driver rplidar\nserial {}\n{extra}provides laser 360 1\nend_driver\nload_driver rplidar\n",
        port.display()
    )
}

/// Publishes `m` every 50 ms for `d` (a controller's cycle).
fn drive(mot: &Interface<Motors>, m: Motors, d: Duration) {
    let t0 = Instant::now();
    while t0.elapsed() < d {
        mot.publish(m).unwrap();
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn contains(hay: &[u8], needle: &[u8]) -> bool {
    hay.windows(needle.len()).any(|w| w == needle)
}

struct Robot {
    emu: create2::Create2,
    rt: Arc<jderobot::Runtime>,
    mot: Arc<Interface<Motors>>,
    enc: Arc<Interface<Encoders>>,
    bump: Arc<Interface<Bumpers>>,
}

fn robot(dir: &Path, room: room::Shared) -> Robot {
    let port = dir.join("create2");
    let emu = create2::Create2::start(&port, room);
    let rt = start_conf(&roomba_conf(&port, "reply_timeout 300\n"));
    let enc: Arc<Interface<Encoders>> = rt.interfaces.get("encoders").unwrap();
    eventually("the stream", || enc.clock() > 3 && enc.stale().is_none());
    Robot {
        mot: rt.interfaces.get("motors").unwrap(),
        bump: rt.interfaces.get("bumpers").unwrap(),
        enc,
        emu,
        rt,
    }
}

#[test]
fn drive_direct_moves_the_commanded_distance_and_odometry_follows() {
    let dir = tempfile::tempdir().unwrap();
    let room = room::Room::new(4000.0, 3000.0, 1000.0, 1500.0, 0.0);
    let r = robot(dir.path(), room.clone());
    let sent = r.emu.received();
    // Start, Safe, then the Stream of the driver's packets.
    assert_eq!(&sent[..3], &[128, 131, 148], "{sent:?}");
    // 200 mm/s for 2.5 s: 500 mm.
    drive(
        &r.mot,
        Motors { v: 200.0, w: 0.0 },
        Duration::from_millis(2500),
    );
    drive(&r.mot, Motors::default(), Duration::from_millis(300));
    let (x, y) = {
        let g = room.lock();
        (g.x, g.y)
    };
    assert!(
        (x - 1500.0).abs() < 60.0 && (y - 1500.0).abs() < 5.0,
        "moved to ({x:.0}, {y:.0})"
    );
    assert!(contains(&r.emu.received(), &[145, 0, 200, 0, 200]));
    let e = r.enc.read().value;
    assert!(
        (e.x as f64 - (x - 1000.0)).abs() < 10.0 && e.y.abs() < 5.0,
        "odometry {e:?} vs moved {:.0}",
        x - 1000.0
    );
    // A quarter turn at 45 deg/s (wheels ±92 mm/s).
    drive(
        &r.mot,
        Motors { v: 0.0, w: 45.0 },
        Duration::from_millis(2000),
    );
    drive(&r.mot, Motors::default(), Duration::from_millis(300));
    let th = room.lock().theta.to_degrees();
    let e = r.enc.read().value;
    assert!((th - 90.0).abs() < 8.0, "turned {th:.1}°");
    assert!(
        (e.theta.to_degrees() as f64 - th).abs() < 2.0,
        "odometry {:.1}° vs {th:.1}°",
        e.theta.to_degrees()
    );
    let status =
        r.rt.names
            .import::<jderobot::drivers::roomba::Status>("roomba", "status")
            .unwrap()
            .line();
    assert!(
        status.contains("OI mode Safe") && status.contains("15.80 V"),
        "{status}"
    );
    r.rt.shutdown();
}

#[test]
fn a_bump_arrives_when_the_robot_meets_a_wall() {
    let dir = tempfile::tempdir().unwrap();
    let room = room::Room::new(4000.0, 3000.0, 3400.0, 1500.0, 0.0);
    let r = robot(dir.path(), room.clone());
    assert_eq!(r.bump.read().value.bumpers, vec![0, 0, 0, 0]);
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(5) && r.bump.read().value.bumpers[..2] != [1, 1] {
        r.mot.publish(Motors { v: 300.0, w: 0.0 }).unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(
        r.bump.read().value.bumpers,
        vec![1, 1, 0, 0],
        "both bumps head-on"
    );
    let x = room.lock().x;
    assert!(
        (x - (4000.0 - room::ROBOT_RADIUS)).abs() < 10.0,
        "stopped at {x:.0}"
    );
    // Backing off releases the bumper.
    drive(
        &r.mot,
        Motors { v: -100.0, w: 0.0 },
        Duration::from_millis(500),
    );
    eventually("bump released", || {
        r.bump.read().value.bumpers == [0, 0, 0, 0]
    });
    r.rt.shutdown();
}

#[test]
fn motors_timeout_zeroes_the_wheels_and_stop_leaves_the_robot_passive() {
    let dir = tempfile::tempdir().unwrap();
    let room = room::Room::new(4000.0, 3000.0, 1000.0, 1500.0, 0.0);
    let r = robot(dir.path(), room.clone());
    r.mot.publish(Motors { v: 150.0, w: 0.0 }).unwrap();
    eventually("moving", || r.emu.state.lock().wheels == (150, 150));
    // No newer command: zero after motors_timeout (500 ms).
    let t0 = Instant::now();
    eventually("zeroed", || r.emu.state.lock().wheels == (0, 0));
    let took = t0.elapsed();
    assert!(took > Duration::from_millis(300), "zeroed after {took:?}");
    r.mot.publish(Motors { v: 150.0, w: 0.0 }).unwrap();
    eventually("moving", || r.emu.state.lock().wheels == (150, 150));
    r.rt.shutdown();
    poll_until(2, || r.emu.received().ends_with(&[128]));
    let sent = r.emu.received();
    assert!(
        sent.ends_with(&[145, 0, 0, 0, 0, 150, 0, 128]),
        "stop: wheels zero, stream paused, Start (Passive): {:?}",
        &sent[sent.len().saturating_sub(12)..]
    );
    assert_eq!(r.emu.state.lock().mode, 1, "Passive");
}

/// Publishes `m` every 50 ms on a thread until the returned flag is set.
fn keep_driving(
    mot: Arc<Interface<Motors>>,
    m: Motors,
) -> (
    Arc<std::sync::atomic::AtomicBool>,
    std::thread::JoinHandle<()>,
) {
    use std::sync::atomic::{AtomicBool, Ordering};
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let t = std::thread::spawn(move || {
        while !s.load(Ordering::Acquire) {
            let _ = mot.publish(m);
            std::thread::sleep(Duration::from_millis(50));
        }
    });
    (stop, t)
}

/// Issue 52: a robot that stops streaming, or whose stream turns to noise, is
/// lost after `reply_timeout`; the stop goes out on the port then, before it is
/// dropped (not a second later at the reopen), while the controller still
/// commands 150 mm/s.
#[test]
fn a_lost_stream_stops_the_wheels_within_100_ms_of_the_loss() {
    let dir = tempfile::tempdir().unwrap();
    let room = room::Room::new(6000.0, 3000.0, 1000.0, 1500.0, 0.0);
    let r = robot(dir.path(), room);
    let reply_timeout = Duration::from_millis(300);
    let (stop, t) = keep_driving(r.mot.clone(), Motors { v: 150.0, w: 0.0 });
    for fault in ["silent", "noise"] {
        eventually("driving", || r.emu.state.lock().wheels == (150, 150));
        let t0 = Instant::now();
        r.emu.faults(|f| match fault {
            "silent" => f.silent = true,
            _ => f.noise = true,
        });
        let last_frame = r.emu.state.lock().last_frame_at.unwrap();
        let mut stopped = None;
        poll_until(5, || {
            stopped = r.emu.stop_after(t0);
            stopped.is_some()
        });
        let stopped = stopped.unwrap_or_else(|| panic!("{fault}: no stop in 5 s"));
        // The driver counts the loss from the last good frame it read.
        let loss = last_frame + reply_timeout;
        assert!(
            stopped >= loss,
            "{fault}: a stop {:?} before the loss",
            loss - stopped
        );
        let after = stopped - loss;
        eprintln!(
            "{fault}: stop {:.1} ms after the loss ({:.1} ms after the fault began)",
            after.as_secs_f64() * 1e3,
            (stopped - t0).as_secs_f64() * 1e3
        );
        assert!(
            after < Duration::from_millis(100),
            "{fault}: the stop came {after:?} after the loss"
        );
        assert_eq!(r.emu.state.lock().wheels, (0, 0), "{fault}");
        r.emu.faults(|f| {
            f.silent = false;
            f.noise = false;
        });
        eventually("back", || r.enc.stale().is_none());
    }
    stop.store(true, std::sync::atomic::Ordering::Release);
    t.join().unwrap();
    r.rt.shutdown();
}

/// Starts the robot and a process driving it at 150 mm/s.
fn driven(dir: &Path) -> (create2::Create2, Proc) {
    let port = dir.join("create2");
    let emu = create2::Create2::start(
        &port,
        room::Room::new(20_000.0, 3000.0, 1000.0, 1500.0, 0.0),
    );
    let conf = dir.join("roomba.conf");
    std::fs::write(
        &conf,
        roomba_conf(&port, "reply_timeout 300\nmotors_timeout 60000\n"),
    )
    .unwrap();
    let mut p = Proc::start_alone(&conf);
    let moving = poll_until(20, || {
        p.send("set motors v=150 w=0");
        std::thread::sleep(Duration::from_millis(200));
        emu.state.lock().wheels == (150, 150)
    });
    assert!(
        moving,
        "the robot never drove; jderobot said:\n{}",
        p.text()
    );
    (emu, p)
}

/// How long after `t0` the first stop arrived (within 5 s).
fn time_to_stop(emu: &create2::Create2, t0: Instant, what: &str, p: &Proc) -> Duration {
    let mut stopped = None;
    poll_until(5, || {
        stopped = emu.stop_after(t0);
        stopped.is_some()
    });
    let at =
        stopped.unwrap_or_else(|| panic!("{what}: no stop in 5 s; jderobot said:\n{}", p.text()));
    at - t0
}

/// Issue 52: Ctrl+Z (SIGTSTP) sends the stop before the process suspends; the
/// process does suspend, the wheels stay stopped while it is, and after SIGCONT
/// it runs on (a new command drives again) and quits normally.
#[test]
fn sigtstp_stops_the_wheels_within_100_ms_then_suspends_and_sigcont_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let (emu, mut p) = driven(dir.path());
    let t0 = Instant::now();
    p.signal(libc::SIGTSTP);
    let took = time_to_stop(&emu, t0, "SIGTSTP", &p);
    eprintln!("SIGTSTP: stop after {:.1} ms", took.as_secs_f64() * 1e3);
    assert!(
        took < Duration::from_millis(100),
        "SIGTSTP: stop after {took:?}"
    );
    assert!(
        poll_until(5, || p.state() == 'T'),
        "not suspended (state {}); jderobot said:\n{}",
        p.state(),
        p.text()
    );
    std::thread::sleep(Duration::from_millis(700));
    assert_eq!(emu.state.lock().wheels, (0, 0), "stopped while suspended");
    assert_eq!(p.state(), 'T');
    p.signal(libc::SIGCONT);
    assert!(poll_until(5, || p.state() != 'T'), "not resumed");
    let driving = poll_until(10, || {
        p.send("set motors v=120 w=0");
        std::thread::sleep(Duration::from_millis(200));
        emu.state.lock().wheels == (120, 120)
    });
    assert!(
        driving,
        "no command after SIGCONT; jderobot said:\n{}",
        p.text()
    );
    p.send("quit");
    let status = p.wait(20).expect("quit after SIGCONT");
    assert!(status.success(), "{status}; jderobot said:\n{}", p.text());
    assert_eq!(emu.state.lock().wheels, (0, 0), "stopped at quit");
}

/// Issue 52: SIGTERM, SIGINT and SIGHUP send the stop before the shutdown (exit
/// code 128 + the signal); SIGALRM (a student's `signal.alarm`), SIGQUIT and
/// SIGABRT (an abort) before the process dies by them; and nothing the driver
/// sends afterwards moves the wheels again.
#[test]
fn ending_signals_stop_the_wheels_within_100_ms() {
    use std::os::unix::process::ExitStatusExt;
    for (sig, name) in [
        (libc::SIGTERM, "SIGTERM"),
        (libc::SIGINT, "SIGINT"),
        (libc::SIGHUP, "SIGHUP"),
        (libc::SIGALRM, "SIGALRM"),
        (libc::SIGQUIT, "SIGQUIT"),
        (libc::SIGABRT, "SIGABRT"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let (emu, mut p) = driven(dir.path());
        let t0 = Instant::now();
        p.signal(sig);
        let took = time_to_stop(&emu, t0, name, &p);
        eprintln!("{name}: stop after {:.1} ms", took.as_secs_f64() * 1e3);
        assert!(
            took < Duration::from_millis(100),
            "{name}: stop after {took:?}"
        );
        let status = p
            .wait(20)
            .unwrap_or_else(|| panic!("{name} did not end it"));
        if [libc::SIGALRM, libc::SIGQUIT, libc::SIGABRT].contains(&sig) {
            assert_eq!(
                status.signal(),
                Some(sig),
                "{name}; jderobot said:\n{}",
                p.text()
            );
        } else {
            assert_eq!(
                status.code(),
                Some(128 + sig),
                "{name}; jderobot said:\n{}",
                p.text()
            );
        }
        let st = emu.state.lock();
        let moved_again = st
            .commands
            .iter()
            .any(|(at, c)| *at >= t0 && c[0] == 145 && !create2::is_stop(c));
        assert!(!moved_again, "{name}: a drive command after the stop");
        assert_eq!(st.wheels, (0, 0), "{name}");
    }
}

#[test]
fn bad_checksums_garbage_half_frames_and_another_device_mark_stale_then_resync() {
    let dir = tempfile::tempdir().unwrap();
    let room = room::Room::new(4000.0, 3000.0, 1000.0, 1500.0, 0.0);
    let r = robot(dir.path(), room);
    let port = r.emu.link.display().to_string();
    let status = || {
        r.rt.names
            .import::<jderobot::drivers::roomba::Status>("roomba", "status")
            .unwrap()
    };
    let x0 = r.enc.read().value.x;
    for (what, expect) in [
        ("checksum", "bad checksum"),
        ("garbage", "no stream frame"),
        ("half", "expected"),
        ("jump", "wheel counts that jumped by 5000"),
    ] {
        // The last fault's aftermath is over: good frames again.
        let c = r.enc.clock();
        eventually("good frames", || {
            r.enc.clock() > c + 5 && r.enc.stale().is_none()
        });
        let before = status().last_refused();
        r.emu.faults(|f| match what {
            "checksum" => f.bad_checksum = true,
            "garbage" => f.garbage = 7,
            "jump" => f.jump = true,
            _ => f.half = true,
        });
        // A half frame is found out, and passed, when the next one arrives: the
        // driver's count of refused frames and its last reason say so.
        eventually(what, || {
            r.enc.stale().is_some() || status().last_refused() != before
        });
        let why = r
            .enc
            .stale()
            .or_else(|| status().last_refused())
            .unwrap_or_default();
        assert!(why.contains(&port) && why.contains(expect), "{what}: {why}");
        eventually("resynchronised", || r.enc.stale().is_none());
    }
    // The jump (2.2 m of counts) is not odometry: the robot stood still.
    let x = r.enc.read().value.x;
    assert!((x - x0).abs() < 5.0, "odometry moved {:.0} mm", x - x0);
    // Another device: NMEA text instead of frames; a loss after reply_timeout.
    r.emu.faults(|f| f.other = true);
    eventually("stale", || {
        r.enc
            .stale()
            .is_some_and(|w| w.contains("no good stream frame"))
    });
    r.emu.faults(|f| f.other = false);
    eventually("back", || r.enc.stale().is_none());
    r.rt.shutdown();
}

#[test]
fn missing_port_and_a_file_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("ttyUSB7");
    let rt = start_conf(&roomba_conf(&missing, ""));
    let enc: Arc<Interface<Encoders>> = rt.interfaces.get("encoders").unwrap();
    eventually("stale", || enc.stale().is_some());
    let why = enc.stale().unwrap();
    assert!(
        why.contains("ttyUSB7") && why.contains("does not exist"),
        "{why}"
    );
    rt.shutdown();
    let file = dir.path().join("notatty");
    std::fs::write(&file, "").unwrap();
    let rt = start_conf(&lidar_conf(&file, ""));
    let laser: Arc<Interface<Laser>> = rt.interfaces.get("laser").unwrap();
    eventually("stale", || laser.stale().is_some());
    let why = laser.stale().unwrap();
    assert!(
        why.contains("notatty") && why.contains("not a serial device"),
        "{why}"
    );
    rt.shutdown();
}

fn lidar(
    dir: &Path,
    room: room::Shared,
) -> (
    rplidar::Lidar,
    Arc<jderobot::Runtime>,
    Arc<Interface<Laser>>,
) {
    let port = dir.join("rplidar");
    let emu = rplidar::Lidar::start(&port, room);
    let rt = start_conf(&lidar_conf(&port, "reply_timeout 500\n"));
    let laser: Arc<Interface<Laser>> = rt.interfaces.get("laser").unwrap();
    eventually("scans", || laser.clock() > 2 && laser.stale().is_none());
    (emu, rt, laser)
}

/// The share of readings within 2 % (+10 mm) of the room's walls seen from `pose`.
fn match_room(l: &Laser, r: &room::Room) -> f64 {
    let mut good = 0;
    for (i, &d) in l.readings.iter().enumerate() {
        let dir = r.theta + (l.angle(i) + l.mount.yaw).to_radians() as f64;
        let want = r.ray(r.x, r.y, dir);
        if (d as f64 - want).abs() <= want * 0.02 + 10.0 {
            good += 1;
        }
    }
    good as f64 / l.readings.len() as f64
}

#[test]
fn scans_of_360_degrees_at_the_device_rate_with_the_walls_where_they_are() {
    let dir = tempfile::tempdir().unwrap();
    let room = room::Room::new(4000.0, 3000.0, 1000.0, 1000.0, 30.0);
    let (emu, rt, laser) = lidar(dir.path(), room.clone());
    let sent = emu.received();
    assert!(
        contains(&sent, &[0xA5, 0x50])
            && contains(&sent, &[0xA5, 0x52])
            && sent.ends_with(&[0xA5, 0x20])
    );
    let c0 = laser.clock();
    std::thread::sleep(Duration::from_secs(3));
    let hz = (laser.clock() - c0) as f64 / 3.0;
    assert!((hz - rplidar::RATE_HZ).abs() < 0.8, "{hz:.2} scans/s");
    let l = laser.read().value.clone();
    assert_eq!(l.readings.len(), 360);
    assert_eq!((l.start, l.resolution, l.max_range), (-180.0, 1.0, 12000.0));
    let share = match_room(&l, &room.lock());
    assert!(
        share > 0.95,
        "{:.1} % of the readings on the walls",
        share * 100.0
    );
    // Straight ahead is 30° from the east wall's normal: (4000-1000)/cos 30°.
    let ahead = l.readings[l.index_at(0.0).unwrap()] as f64;
    assert!(
        (ahead - 3000.0 / 30f64.to_radians().cos()).abs() < 60.0,
        "{ahead}"
    );
    // 90° left (counter-clockwise) points at 120°: the west wall, 1000/cos 60°.
    let left = l.readings[l.index_at(90.0).unwrap()] as f64;
    assert!((left - 2000.0).abs() < 40.0, "{left}");
    // 90° right points at −60°: the south wall, 1000/sin 60°.
    let right = l.readings[l.index_at(-90.0).unwrap()] as f64;
    assert!(
        (right - 1000.0 / 60f64.to_radians().sin()).abs() < 40.0,
        "{right}"
    );
    let status = rt
        .names
        .import::<jderobot::drivers::rplidar::Status>("rplidar", "status")
        .unwrap()
        .line();
    assert!(
        status.contains("RPLIDAR A1")
            && status.contains("firmware 1.29")
            && status.contains("health good")
            && status.contains("1011121314"),
        "{status}"
    );
    rt.shutdown();
    poll_until(2, || emu.received().ends_with(&[0xA5, 0x25]));
    assert!(emu.received().ends_with(&[0xA5, 0x25]), "STOP at the end");
    assert!(!emu.state.lock().scanning);
}

#[test]
fn a_health_error_garbage_and_another_device_are_said_and_resynchronised() {
    let dir = tempfile::tempdir().unwrap();
    let room = room::Room::new(4000.0, 3000.0, 1000.0, 1000.0, 0.0);
    let (emu, rt, laser) = lidar(dir.path(), room.clone());
    let port = emu.link.display().to_string();
    emu.faults(|f| f.garbage = 13);
    eventually("stale", || laser.stale().is_some());
    let why = laser.stale().unwrap();
    assert!(why.contains(&port) && why.contains("no scan node"), "{why}");
    eventually("resynchronised", || laser.stale().is_none());
    assert!(match_room(&laser.read().value, &room.lock()) > 0.95);
    // Another device: the scan stops; reopening finds no descriptor.
    emu.faults(|f| f.other = true);
    eventually("another device", || {
        laser
            .stale()
            .is_some_and(|w| w.contains("expected the descriptor A5 5A"))
    });
    emu.faults(|f| {
        f.other = false;
        f.health_error = true;
    });
    eventually("health error", || {
        laser
            .stale()
            .is_some_and(|w| w.contains("health code 0x8001"))
    });
    emu.faults(|f| f.health_error = false);
    eventually("back", || laser.stale().is_none());
    rt.shutdown();
}

/// Issue 52: uniformly random bytes on the lidar's line (11520 a second, the
/// line's rate) made ~430 "scans" a second, mostly 12 m. Now the laser is stale
/// within one revolution's time (182 ms at the A1's 5.5 Hz: the revolution the
/// noise lands in is ended by the noise's first start flag, a node or two away,
/// and fails the checks; the first byte that is no node marks it stale at once),
/// stays stale with no scan published while the noise lasts, and plausible
/// revolutions clear it once the noise stops (the revolution the noise ends in is
/// refused, the next whole one is good: within three revolutions).
#[test]
fn noise_on_the_lidar_line_is_stale_within_one_revolution_and_good_scans_clear_it() {
    let dir = tempfile::tempdir().unwrap();
    let room = room::Room::new(4000.0, 3000.0, 1000.0, 1000.0, 0.0);
    let (emu, rt, laser) = lidar(dir.path(), room.clone());
    let revolution = Duration::from_secs_f64(1.0 / rplidar::RATE_HZ);
    let port = emu.link.display().to_string();
    for round in 0..2 {
        let t0 = Instant::now();
        emu.faults(|f| f.noise = true);
        let mut stale_at = None;
        while t0.elapsed() < Duration::from_secs(2) {
            if laser.stale().is_some() {
                stale_at = Some(Instant::now());
                break;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        let took = stale_at.expect("never stale in 2 s of noise") - t0;
        eprintln!(
            "noise {round}: stale after {:.1} ms",
            took.as_secs_f64() * 1e3
        );
        assert!(took < revolution, "stale after {took:?}");
        // 1.5 s of noise: stale all along, no scan published.
        let c = laser.clock();
        let t1 = Instant::now();
        while t1.elapsed() < Duration::from_millis(1500) {
            assert!(
                laser.stale().is_some(),
                "believed the noise at {:?}",
                t1.elapsed()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(laser.clock(), c, "scans published from noise");
        let why = laser.stale().unwrap();
        assert!(
            why.contains(&port)
                && why.contains("scan not believed")
                && why.contains("revolutions/s"),
            "{why}"
        );
        let t2 = Instant::now();
        emu.faults(|f| f.noise = false);
        let good = poll_until(5, || laser.stale().is_none());
        let back = t2.elapsed();
        assert!(good, "still stale 5 s after the noise: {:?}", laser.stale());
        eprintln!(
            "noise {round}: good again after {:.1} ms",
            back.as_secs_f64() * 1e3
        );
        assert!(
            back < 3 * revolution + Duration::from_millis(100),
            "good again after {back:?}"
        );
        assert!(match_room(&laser.read().value, &room.lock()) > 0.95);
    }
    rt.shutdown();
}

#[test]
fn unplugging_and_plugging_back_both_recover() {
    let dir = tempfile::tempdir().unwrap();
    let room = room::Room::new(4000.0, 3000.0, 1000.0, 1000.0, 0.0);
    let mut r = robot(dir.path(), room.clone());
    let (mut lid, lrt, laser) = lidar(dir.path(), room);
    r.emu.unplug();
    lid.unplug();
    eventually("both stale", || {
        r.enc.stale().is_some() && laser.stale().is_some()
    });
    r.emu.plug();
    lid.plug();
    let c = laser.clock();
    eventually("both back", || {
        r.enc.stale().is_none() && laser.stale().is_none() && laser.clock() > c + 2
    });
    drive(
        &r.mot,
        Motors { v: 100.0, w: 0.0 },
        Duration::from_millis(300),
    );
    assert!(
        r.emu.state.lock().wheels == (100, 100),
        "commands after replug"
    );
    r.rt.shutdown();
    lrt.shutdown();
}

#[cfg(feature = "introrob")]
#[test]
fn introrob_vff_drives_the_create2_and_its_rplidar_to_the_target() {
    use jderobot::schemas::introrob::Dashboard;
    let dir = tempfile::tempdir().unwrap();
    // A Create 2 with an A1 on top, in a 5 m x 3.5 m room; the target is 3 m
    // ahead and 1.5 m left of where it starts (odometry's origin).
    let room = room::Room::new(5000.0, 3500.0, 800.0, 800.0, 0.0);
    let (rp, lp) = (dir.path().join("create2"), dir.path().join("rplidar"));
    let _robot = create2::Create2::start(&rp, room.clone());
    let _lidar = rplidar::Lidar::start(&lp, room.clone());
    let text = format!(
        "driver roomba\nserial {}\nprovides motors\nprovides encoders\nprovides bumpers\nend_driver\n\
         driver rplidar\nserial {}\nprovides laser 360 1\nend_driver\n\
         schema introrob\nbehaviour vff\ntarget 3000 1500\nmax_v 300\nmax_w 40\nsonars none\ncamera none\n\
         end_schema\nload_driver roomba\nload_driver rplidar\nload_schema introrob\nrun introrob\n",
        rp.display(),
        lp.display()
    );
    let rt = start_conf(&text);
    let dash = rt.names.import::<Dashboard>("introrob", "state").unwrap();
    let reached = poll_until(60, || dash.view.lock().status == "vff: target reached");
    let (x, y, touched) = {
        let g = room.lock();
        (g.x, g.y, g.touched)
    };
    let status = dash.view.lock().status.clone();
    rt.shutdown();
    assert!(
        reached,
        "not reached: at ({x:.0}, {y:.0}) in the room, status {status}"
    );
    let d = ((x - 3800.0).powi(2) + (y - 2300.0).powi(2)).sqrt();
    assert!(
        d < 300.0,
        "ended {d:.0} mm from the target, at ({x:.0}, {y:.0})"
    );
    assert!(!touched, "touched a wall");
}

/// Not a test: a Create 2 at `$CREATE2_PATH` (default /tmp/create2) and an A1 at
/// `$RPLIDAR_PATH` (default /tmp/rplidar) in one 5 m x 3.5 m room, for
/// `$SERIAL_SECONDS` s (default 600), to try the examples against:
/// `cargo test --features full --test robots -- --ignored --nocapture serial_robots::emulator`.
#[test]
#[ignore]
fn emulator() {
    let room = room::Room::new(5000.0, 3500.0, 800.0, 800.0, 0.0);
    let lidar_path = std::env::var("RPLIDAR_PATH").unwrap_or_else(|_| "/tmp/rplidar".into());
    let _ = std::fs::remove_file(&lidar_path);
    let _lidar = rplidar::Lidar::start(Path::new(&lidar_path), room.clone());
    println!("emulated RPLIDAR A1 at {lidar_path}");
    common::emulate_by_hand(
        "Create 2",
        ("CREATE2_PATH", "/tmp/create2"),
        "SERIAL_SECONDS",
        |p| create2::Create2::start(p, room.clone()),
    );
}

#[test]
fn conf_errors_name_the_line_and_the_range() {
    let e = common::start_error(
        "driver rplidar\nserial /tmp/x\nprovides laser 720 1\nend_driver\nload_driver rplidar\n",
    );
    assert!(
        e.contains("test.conf:3") && e.contains("spans 720.0°"),
        "{e}"
    );
    let e = common::start_error(
        "driver rplidar\nserial /tmp/x\nprovides sonars\nend_driver\nload_driver rplidar\n",
    );
    assert!(
        e.contains("test.conf:3") && e.contains("is `sonars`, expected one of laser"),
        "{e}"
    );
    let e = common::start_error("driver rplidar\nserial /tmp/x\nend_driver\nload_driver rplidar\n");
    assert!(e.contains("no `provides` line, and needs one"), "{e}");
    let e = common::start_error(
        "driver roomba\nserial /tmp/x\nmode turbo\nprovides motors\nend_driver\nload_driver roomba\n",
    );
    assert!(e.contains("test.conf:3") && e.contains("safe, full"), "{e}");
    let e = common::start_error(
        "driver roomba\nserial /tmp/x\nbaud 230400\nprovides motors\nend_driver\nload_driver roomba\n",
    );
    assert!(e.contains("between 1200 and 115200"), "{e}");
    let e = common::start_error("driver roomba\nprovides motors\nend_driver\nload_driver roomba\n");
    assert!(e.contains("no `serial` line"), "{e}");
}

/// The Academy's bump-and-go (`assets/exercises/vacuum_solution.py`) runs unchanged
/// on the Create 2: it drives to a wall, the bump arrives through the OI stream,
/// and the program backs off, turns and drives on, several times.
#[cfg(feature = "python")]
#[test]
fn the_academys_bump_and_go_runs_unchanged_on_the_roomba() {
    let dir = tempfile::tempdir().unwrap();
    let port = dir.path().join("create2");
    let room = room::Room::new(4000.0, 3000.0, 3000.0, 1500.0, 0.0);
    let _emu = create2::Create2::start(&port, room.clone());
    let program = common::root().join("assets/exercises/vacuum_solution.py");
    let rt = start_conf(&format!(
        "{}schema python\nfile {}\ncycle 50\nend_schema\nload_schema python\n",
        roomba_conf(&port, "reply_timeout 300\n"),
        program.display()
    ));
    rt.run("python").unwrap();
    let shared = jderobot::schemas::python::shared(&rt, "python");
    let bumps = || {
        shared
            .console
            .lock()
            .lines
            .iter()
            .filter(|l| l.contains("bump on the"))
            .count()
    };
    let t0 = Instant::now();
    let mut far = 0.0f64;
    while t0.elapsed() < Duration::from_secs(40) && bumps() < 3 {
        let r = room.lock().clone();
        far = far.max((r.x - 3000.0).hypot(r.y - 1500.0));
        std::thread::sleep(Duration::from_millis(100));
    }
    let console = shared
        .console
        .lock()
        .lines
        .iter()
        .cloned()
        .collect::<Vec<_>>()
        .join("\n");
    assert!(bumps() >= 3, "fewer than 3 bumps in 40 s:\n{console}");
    assert!(room.lock().touched, "the emulated robot never met a wall");
    assert!(far > 500.0, "it moved only {far:.0} mm:\n{console}");
    rt.shutdown();
}

/// Issue 52: a python program's worker process that dies (here `os._exit`)
/// stops the Create 2 it drove within 100 ms: the schema zeroes its motors when
/// it sees the process end, and the roomba driver sends Drive Direct 0.
#[cfg(feature = "python")]
#[test]
fn a_python_programs_process_ending_stops_the_create2_within_100_ms() {
    let dir = tempfile::tempdir().unwrap();
    let port = dir.path().join("create2");
    let room = room::Room::new(8000.0, 3000.0, 1000.0, 1500.0, 0.0);
    let emu = create2::Create2::start(&port, room);
    let program = dir.path().join("drive_then_exit.py");
    std::fs::write(
        &program,
        "from HAL import HAL\nimport os, time\nHAL.setV(0.15)\ntime.sleep(1.5)\n\
         print('end', repr(time.time()))\nos._exit(0)\n",
    )
    .unwrap();
    let rt = start_conf(&format!(
        "{}schema python\nfile {}\ncycle 50\ncamera none\nend_schema\nload_schema python\n",
        roomba_conf(&port, "reply_timeout 300\n"),
        program.display()
    ));
    // The emulator stamps commands with Instants; the program says when it
    // ended in Unix seconds.
    let (i0, s0) = (Instant::now(), std::time::SystemTime::now());
    rt.run("python").unwrap();
    let shared = jderobot::schemas::python::shared(&rt, "python");
    eventually("it drives", || emu.state.lock().wheels == (150, 150));
    eventually("its process ends", || {
        rt.schema_status("python").unwrap().state == jderobot::State::Slept
    });
    let console = shared
        .console
        .lock()
        .lines
        .iter()
        .cloned()
        .collect::<Vec<_>>()
        .join("\n");
    let t_end: f64 = console
        .lines()
        .find_map(|l| l.strip_prefix("end "))
        .expect(&console)
        .parse()
        .unwrap();
    let end = i0
        + (std::time::UNIX_EPOCH + Duration::from_secs_f64(t_end))
            .duration_since(s0)
            .unwrap_or_default();
    // The schema has stopped; the driver's Drive Direct 0 and the emulator's
    // record of it follow on their own threads.
    let mut stop = None;
    poll_until(5, || {
        stop = emu.stop_after(end);
        stop.is_some()
    });
    let stop = stop.unwrap_or_else(|| {
        panic!(
            "no stop after the program's end; the emulator got {:?}",
            emu.state
                .lock()
                .commands
                .iter()
                .rev()
                .take(5)
                .collect::<Vec<_>>()
        )
    });
    let took = stop.saturating_duration_since(end);
    eprintln!(
        "the worker's end: Drive Direct 0 after {:.1} ms",
        took.as_secs_f64() * 1e3
    );
    assert!(took < Duration::from_millis(100), "stop after {took:?}");
    assert_eq!(emu.state.lock().wheels, (0, 0));
    assert!(
        console.contains("the program's process ended (exit 0)"),
        "{console}"
    );
    rt.shutdown();
}
