//! The player driver against real sockets: golden bytes captured from a real
//! Player 3.1 + Stage 4.3 server (reference/player-protocol.md), and a Player
//! server emulator (tests/emulators/player.rs) for the driver in a runtime and the
//! real binary with examples/player.conf.
#![cfg(feature = "player")]

use crate::common;
#[path = "emulators/player.rs"]
mod player_emulator;

use std::{
    io::{BufRead, BufReader, Write},
    path::{Path, PathBuf},
    process::Command,
    sync::{Arc, atomic::Ordering},
    time::{Duration, Instant},
};

use common::{eventually, poll_until, root};
use jderobot::{
    Conf, Runtime,
    drivers::player::{
        LaserMap, LiveBlobs, Offset, sinks,
        xdr::{self, Addr, Header},
    },
    interfaces::{
        Bumpers, Encoders, Image, Interface, Laser, Motors, PtEncoders, PtMotors, Sonars,
    },
};
use player_emulator::{Emulator, hex};

// ---- golden bytes (reference §5, §7, §9, §11) ----

#[test]
fn golden_cmd_vel_encodes_to_the_captured_bytes() {
    let want = hex(
        "00000000 00000000 00000004 00000000 00000002 00000001 00000000 00000000 \
         00000005 0000001c 3fd99999 9999999a 00000000 00000000 3fd33333 33333333 00000001",
    );
    let payload = xdr::cmd_vel(0.4, 0.0, 0.3, true);
    let h = Header::new(Addr::new(4, 0), 2, 1, 5, payload.len());
    assert_eq!(xdr::message(&h, &payload), want);
}

#[test]
fn golden_subscribe_request_and_its_ack() {
    let want = hex(
        "00000000 00000000 00000001 00000000 00000003 00000003 00000000 00000000 00000001 0000001c \
         00000000 00000000 00000004 00000000 00000001 00000000 00000000",
    );
    let p = xdr::device_req(Addr::new(4, 0), 1);
    let h = Header::new(Addr::PLAYER, 3, 3, 1, p.len());
    assert_eq!(xdr::message(&h, &p), want);
    let ack = hex(
        "0100007f 00001a09 00000001 00000000 00000004 00000003 4011d70a 3d70a3d7 00000001 00000024 \
         0100007f 00001a09 00000004 00000000 00000001 00000006 00000006 73746167 65000000",
    );
    let h = Header::decode(&ack[..40]).unwrap();
    assert_eq!(
        (h.addr, h.mtype, h.subtype, h.seq, h.size),
        (Addr::PLAYER, 4, 3, 1, 36)
    );
    assert!((h.timestamp - 4.46).abs() < 1e-9);
    let (addr, access, name) = xdr::decode_device_req(&ack[40..]).unwrap();
    assert_eq!((addr, access, name.as_str()), (Addr::new(4, 0), 1, "stage"));
}

#[test]
fn golden_pull_mode_messages() {
    // REQ_DATAMODE PULL, REQ_DATA (the client's timestamps are its own; we send 0).
    let dm = hex(
        "00000000 00000000 00000001 00000000 00000003 00000005 41dac096 44a7b9e0 00000000 00000004 00000002",
    );
    let h = Header::decode(&dm[..40]).unwrap();
    assert_eq!(
        (h.addr, h.mtype, h.subtype, h.size),
        (Addr::PLAYER, 3, 5, 4)
    );
    assert_eq!(xdr::datamode_req(2), dm[40..]);
    let synch = hex(
        "00000000 00000000 00000001 00000000 00000005 00000001 00005573 07992110 7e928bb7 00000000",
    );
    let h = Header::decode(&synch).unwrap();
    assert_eq!(
        (h.addr, h.mtype, h.subtype, h.size),
        (Addr::PLAYER, 5, 1, 0)
    );
    let mut ours = Vec::new();
    Header::new(Addr::PLAYER, 3, 4, 0, 0).encode(&mut ours);
    let theirs = hex(
        "00000000 00000000 00000001 00000000 00000003 00000004 41dac096 44a7f102 00000000 00000000",
    );
    assert_eq!(ours[..24], theirs[..24], "same address, type and subtype");
    assert_eq!(ours[32..], theirs[32..], "seq 0, size 0");
}

#[test]
fn golden_position2d_state_decodes_to_encoders() {
    let m = hex(
        "0100007f 00001a09 00000004 00000000 00000001 00000001 401dd70a 3d70a3d7 00000000 00000034 \
         c01a60c2 e1b80f68 c0195087 31f6f1c2 3ff534d4 b45f86fc 3fd99999 9999999a 00000000 00000000 \
         3fd33333 33333333 00000000",
    );
    let h = Header::decode(&m[..40]).unwrap();
    assert_eq!(
        (h.addr, h.mtype, h.subtype, h.size),
        (Addr::new(4, 0), 1, 1, 52)
    );
    let p = xdr::decode_position2d(&m[40..]).unwrap();
    assert!(
        (p.px + 6.5945).abs() < 1e-4
            && (p.py + 6.3286).abs() < 1e-4
            && (p.pa - 1.3254).abs() < 1e-4
    );
    assert_eq!((p.vx, p.vy, p.va, p.stall), (0.4, 0.0, 0.3, false));
    let e = sinks::encoders(&p, &Offset::default());
    assert!(
        (e.x + 6594.5).abs() < 0.1 && (e.y + 6328.6).abs() < 0.1,
        "{e:?}"
    );
    assert!((e.theta - 1.3254).abs() < 1e-4);
    // 4.3's offset formula: rotate by θ0, then add (X0, Y0); θ = pa + θ0 in (0, 2π].
    let o = Offset {
        x: 1000.0,
        y: -500.0,
        theta_deg: 90.0,
    };
    let e = sinks::encoders(&p, &o);
    assert!(
        (e.x - (6328.6 + 1000.0)).abs() < 0.2 && (e.y - (-6594.5 - 500.0)).abs() < 0.2,
        "{e:?}"
    );
    assert!((e.theta - (1.3254 + std::f32::consts::FRAC_PI_2)).abs() < 1e-4);
    assert!((e.cos - e.theta.cos()).abs() < 1e-6 && (e.sin - e.theta.sin()).abs() < 1e-6);
}

/// The captured 796-byte laser scan (§11.3).
pub const SCAN_HEX: &str = include_str!("data/player_scan.hex");

#[test]
fn golden_laser_scan_decodes_to_mm_at_the_right_angles() {
    let m = hex(SCAN_HEX);
    assert_eq!(m.len(), 796);
    let h = Header::decode(&m[..40]).unwrap();
    assert_eq!(
        (h.addr, h.mtype, h.subtype, h.size),
        (Addr::new(6, 0), 1, 1, 756)
    );
    let (info, ranges) = xdr::decode_scan(&m[40..]).unwrap();
    assert_eq!(info.count, 180);
    assert_eq!(
        (info.min_angle, info.max_angle, info.max_range),
        (-1.5707964, 1.5707964, 8.0)
    );
    assert_eq!(info.resolution, 0.017453292);
    let mut l = Laser::default();
    sinks::laser_f32(&mut LaserMap::new(180, 1.0), &info, ranges, &mut l);
    assert_eq!(l.readings.len(), 180);
    assert_eq!(l.resolution, 1.0);
    assert_eq!((l.readings[0], l.readings[179]), (1489, 1491));
    assert_eq!(l.readings[46], 8000, "0x41000000 = 8.0 m, no return");
    // Half the resolution: every other sample, the same field of view.
    let mut half = Laser::default();
    sinks::laser_f32(&mut LaserMap::new(90, 0.5), &info, ranges, &mut half);
    assert_eq!(half.readings.len(), 90);
    assert_eq!(half.readings[0], l.readings[0]);
    assert_eq!(half.readings[45], l.readings[90]);
    assert_eq!(half.readings[89], l.readings[178]);
}

#[test]
fn golden_blobfinder_and_sonar_payloads() {
    let (w, h, blobs) = xdr::decode_blobs(&hex(player_emulator::BLOB_HEX)).unwrap();
    assert_eq!((w, h, blobs.len()), (80, 60, 1));
    let b = blobs[0];
    assert_eq!((b.color, b.area, b.x, b.y), (0xff0000, 420, 39, 30));
    assert_eq!((b.left, b.right, b.top, b.bottom), (29, 50, 20, 40));
    assert!((b.range - 1687.0).abs() < 1.0, "1.687 m, in mm");
    let f = sinks::blob_frame(1, w, h, blobs);
    assert_eq!(f.blobs[0], b);
    // ranger:0 (sonar) RANGE: 16, 16, 1.436 m, 5.0 m, ...
    let mut p = hex("00000010 00000010 3ff6f823e2928f7f 4014000000000000");
    p.resize(8 + 16 * 8, 0);
    let (n, raw) = xdr::decode_ranger(&p).unwrap();
    let mut s = Sonars::default();
    sinks::sonars_f64(n, raw, &mut s);
    assert_eq!(s.us.len(), 16);
    assert!((s.us[0] - 1436.0).abs() < 1.0 && s.us[1] == 5000.0);
}

#[test]
#[allow(clippy::approx_constant)] // 0.7854 is the captured value, not π/4
fn golden_simulation_set_pose_request_layout() {
    // Not sent by the driver; checks our XDR writer on a captured request.
    let want =
        hex("00000003 00000003 72300000 c01bc8b4 39581062 c01bc9ba 5e353f7d 3fe921ff 2e48e8a7");
    let mut w = xdr::Writer::default();
    w.bytes(b"r0\0").f64(-6.946).f64(-6.947).f64(0.7854);
    assert_eq!(w.buf, want);
}

// ---- the driver in a runtime, against the emulator ----

fn start(port: u16, body: &str) -> Arc<Runtime> {
    let text = format!(
        "driver player\nhostname 127.0.0.1 port {port}\n{body}\nend_driver\nload_driver player\n"
    );
    let conf = Conf::parse(&text, Path::new("test.conf")).unwrap_or_else(|e| panic!("{e}"));
    jderobot::loader::start(&conf).unwrap_or_else(|e| panic!("{e}"))
}

fn start_err(port: u16, body: &str) -> String {
    let text = format!(
        "driver player\nhostname 127.0.0.1 port {port}\n{body}\nend_driver\nload_driver player\n"
    );
    let conf = Conf::parse(&text, Path::new("test.conf")).unwrap_or_else(|e| panic!("{e}"));
    match jderobot::loader::start(&conf) {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn motors_drive_the_robot_and_encoders_follow() {
    let emu = Emulator::start();
    let rt = start(
        emu.port,
        "provides encoders\nprovides motors\ninitial_position 1000 2000 90\n",
    );
    let enc: Arc<Interface<Encoders>> = rt.interfaces.get("encoders").unwrap();
    let motors: Arc<Interface<Motors>> = rt.interfaces.get("motors").unwrap();
    // Nobody uses position2d yet: not subscribed.
    std::thread::sleep(Duration::from_millis(200));
    assert!(!emu.subscribed(4, 0));
    assert_eq!(enc.clock(), 0);
    rt.run("encoders").unwrap();
    eventually("encoders from the server", || enc.clock() > 2);
    let e = enc.read();
    // Robot at the origin heading 0: with the offset, (1000, 2000) heading 90°.
    assert!(
        (e.x - 1000.0).abs() < 1.0 && (e.y - 2000.0).abs() < 1.0,
        "{e:?}"
    );
    assert!((e.theta - std::f32::consts::FRAC_PI_2).abs() < 1e-3);
    drop(e);
    // Forward in the robot's frame is +y in the offset frame.
    eventually("the robot moves", || {
        motors.publish(Motors { v: 300.0, w: 0.0 }).unwrap();
        std::thread::sleep(Duration::from_millis(20));
        enc.read().y > 2100.0
    });
    assert!((enc.read().x - 1000.0).abs() < 5.0);
    // What reached the server: v in m/s, w in rad/s, limited to the Pioneer's maxima.
    motors.publish(Motors { v: 5000.0, w: 90.0 }).unwrap();
    eventually("a clamped command", || {
        emu.world()
            .commands
            .iter()
            .any(|(v, w, _)| *v == 1.0 && (*w - 90f64.to_radians()).abs() < 1e-6)
    });
    motors.publish(Motors { v: 0.0, w: -500.0 }).unwrap();
    eventually("w clamped to -180 deg/s", || {
        emu.world()
            .commands
            .iter()
            .any(|(_, w, _)| (*w + std::f64::consts::PI).abs() < 1e-6)
    });
    // Commands keep coming every cycle (75 ms), each within a cycle of the last.
    let n0 = emu.world().commands.len();
    std::thread::sleep(Duration::from_millis(600));
    let n1 = emu.world().commands.len();
    assert!(n1 >= n0 + 3, "commands every cycle: {n0} -> {n1}");
    // No fresh command: zero after motors_timeout (500 ms).
    eventually("a stale command becomes zero", || {
        emu.world()
            .commands
            .last()
            .is_some_and(|(v, w, _)| *v == 0.0 && *w == 0.0)
    });
    motors.publish(Motors { v: 200.0, w: 0.0 }).unwrap();
    eventually("moving again", || emu.world().v == 0.2);
    rt.shutdown();
    eventually("terminate sends zero", || emu.world().v == 0.0);
    assert_eq!(motors.read().value, Motors::default());
}

#[test]
fn laser_is_in_mm_at_the_right_angles_from_laser_and_from_ranger() {
    let emu = Emulator::start();
    let rt = start(
        emu.port,
        "provides laser 180 1\nprovides laser 180 1 device ranger:1 r\nprovides sonars device ranger:0\nprovides sonars s\n",
    );
    let laser: Arc<Interface<Laser>> = rt.interfaces.get("laser").unwrap();
    let rlaser: Arc<Interface<Laser>> = rt.interfaces.get("laser.r").unwrap();
    let sonars: Arc<Interface<Sonars>> = rt.interfaces.get("sonars").unwrap();
    let fsonars: Arc<Interface<Sonars>> = rt.interfaces.get("sonars.s").unwrap();
    std::thread::sleep(Duration::from_millis(150));
    assert!(
        !emu.subscribed(6, 0),
        "laser:0 is subscribed only once used"
    );
    for i in ["laser", "laser.r", "sonars", "sonars.s"] {
        rt.run(i).unwrap();
    }
    eventually("scans", || {
        laser.clock() > 0 && rlaser.clock() > 0 && sonars.clock() > 0 && fsonars.clock() > 0
    });
    assert!(
        emu.subscribed(6, 0)
            && emu.subscribed(62, 1)
            && emu.subscribed(62, 0)
            && emu.subscribed(5, 0)
    );
    // The room: walls at x = 4 m ahead, y = -3 m on the right, y = +1 m on the left.
    for l in [laser.snapshot(), rlaser.snapshot()] {
        assert_eq!(l.readings.len(), 180);
        assert_eq!(l.readings[90], 4000, "straight ahead");
        assert_eq!(l.readings[0], 3000, "index 0 is the right (-90 deg)");
        assert_eq!(
            l.readings[179],
            (1000.0 / 1f64.to_radians().cos()).round() as i32,
            "89 deg left"
        );
        let a = (-45f64).to_radians();
        assert_eq!(
            l.readings[45],
            (3000.0 / a.sin().abs()).min(4000.0 / a.cos()).round() as i32
        );
    }
    for s in [sonars.snapshot(), fsonars.snapshot()] {
        assert_eq!(s.us.len(), 16);
        assert!(
            (s.us[0] - 1000.0).abs() < 0.5,
            "sonar 0 points left: {:?}",
            s.us
        );
        assert!(
            (s.us[7] - 3000.0).abs() < 0.5,
            "sonar 7 points right: {:?}",
            s.us
        );
    }
    // Suspended again: unsubscribed.
    rt.stop("laser").unwrap();
    eventually("laser:0 unsubscribed", || !emu.subscribed(6, 0));
    rt.shutdown();
}

#[test]
fn bumpers_pantilt_camera_and_blobs() {
    let emu = Emulator::start();
    let rt = start(
        emu.port,
        "provides bumpers\nprovides pantiltencoders\nprovides pantiltmotors\nprovides colorA\nprovides varcolorB\nprovides blobs\n",
    );
    let bump: Arc<Interface<Bumpers>> = rt.interfaces.get("bumpers").unwrap();
    let pte: Arc<Interface<PtEncoders>> = rt.interfaces.get("pantiltencoders").unwrap();
    let ptm: Arc<Interface<PtMotors>> = rt.interfaces.get("pantiltmotors").unwrap();
    let color: Arc<Interface<Image>> = rt.interfaces.get("colorA").unwrap();
    let var: Arc<Interface<Image>> = rt.interfaces.get("varcolorB").unwrap();
    let blobs = rt.names.import::<LiveBlobs>("player", "blobs").unwrap();
    for i in [
        "bumpers",
        "pantiltencoders",
        "pantiltmotors",
        "colorA",
        "varcolorB",
    ] {
        rt.run(i).unwrap();
    }
    eventually("blobs", || blobs.load().clock > 0);
    let f = blobs.load();
    assert_eq!((f.width, f.height, f.blobs.len()), (80, 60, 1));
    assert_eq!(
        (
            f.blobs[0].color,
            f.blobs[0].area,
            f.blobs[0].x,
            f.blobs[0].y
        ),
        (0xff0000, 420, 39, 30)
    );
    eventually("bumpers", || bump.clock() > 0);
    assert_eq!(bump.read().bumpers, vec![0; 10]);
    // Pan-tilt: degrees in, radians on the wire, degrees back.
    let mut c = ptm.read().value;
    c.longitude = 30.0;
    c.latitude = -10.0;
    ptm.publish(c).unwrap();
    eventually("the pan-tilt turns", || {
        (pte.read().pan_angle - 30.0).abs() < 0.01
    });
    assert!((pte.read().tilt_angle + 10.0).abs() < 0.01);
    // Camera RGB888 80x60: left red, right blue, to BGR; colorA is 320x240.
    eventually("frames", || color.clock() > 0 && var.clock() > 0);
    let v = var.snapshot();
    assert_eq!((v.width, v.height), (80, 60));
    assert_eq!((v.pixel(0, 0), v.pixel(79, 59)), ([0, 0, 255], [255, 0, 0]));
    let a = color.snapshot();
    assert_eq!((a.width, a.height, a.data.len()), (320, 240, 320 * 240 * 3));
    assert_eq!(
        (a.pixel(10, 10), a.pixel(300, 200)),
        ([0, 0, 255], [255, 0, 0])
    );
    // JPEG (made by ImageMagick, the real encoder): a green frame.
    if common::have("convert") {
        let out = Command::new("convert")
            .args(["-size", "64x48", "xc:#00ff00", "jpg:-"])
            .output()
            .expect("convert");
        assert!(out.status.success());
        *emu.shared.camera.lock().unwrap() = (64, 48, 5, 1, out.stdout);
        eventually("a JPEG frame", || var.read().width == 64);
        let px = var.read().pixel(32, 24);
        assert!(
            px[1] > 230 && px[0] < 30 && px[2] < 30,
            "green in BGR: {px:?}"
        );
        // A frame we cannot use (format 9) is skipped; the stream goes on.
        {
            let mut cam = emu.shared.camera.lock().unwrap();
            cam.2 = 9;
            cam.3 = 0;
        }
        // Frames already on their way still arrive; then none.
        std::thread::sleep(Duration::from_millis(300));
        let c = var.clock();
        std::thread::sleep(Duration::from_millis(300));
        assert_eq!(var.clock(), c, "no frame published from an unknown format");
        *emu.shared.camera.lock().unwrap() = player_emulator::test_frame();
        eventually("frames again", || var.clock() > c && var.read().width == 80);
        assert!(var.stale().is_none());
    } else {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI needs imagemagick's convert for the JPEG test"
        );
        eprintln!("skipped the JPEG part: no `convert` (imagemagick)");
    }
    rt.shutdown();
}

#[test]
fn device_indices_and_robot_suffixes_map_several_robots() {
    let emu = Emulator::with_devices(vec![(4, 0), (4, 1), (6, 0), (62, 0), (62, 1)]);
    let rt = start(
        emu.port,
        "provides encoders\nprovides encoders index 1 robot2\nprovides motors index 1 robot2\n\
         initial_position 500 0 0 robot2\nprovides laser 180 1 robot2\n",
    );
    let e2: Arc<Interface<Encoders>> = rt.interfaces.get("encoders.robot2").unwrap();
    assert!(rt.interfaces.get::<Motors>("motors.robot2").is_ok());
    assert!(rt.interfaces.get::<Laser>("laser.robot2").is_ok());
    rt.run("encoders.robot2").unwrap();
    eventually("position2d:1 subscribed", || {
        emu.subscribed(4, 1) && e2.clock() > 0
    });
    assert!(!emu.subscribed(4, 0), "robot 1's encoders are not used");
    assert!(
        (e2.read().x - 500.0).abs() < 1.0,
        "robot2's own initial_position"
    );
    // No index and laser:0 listed: laser:0 (the `rangertolaser` device).
    rt.run("laser.robot2").unwrap();
    eventually("laser:0 subscribed", || emu.subscribed(6, 0));
    rt.shutdown();
    // Without laser:0, a laser comes from the last ranger (Stage's ranger:1).
    let emu = Emulator::with_devices(vec![(4, 0), (62, 0), (62, 1)]);
    let rt = start(emu.port, "provides laser 180 1\n");
    let l: Arc<Interface<Laser>> = rt.interfaces.get("laser").unwrap();
    rt.run("laser").unwrap();
    eventually("ranger:1 scans", || emu.subscribed(62, 1) && l.clock() > 0);
    assert_eq!(l.read().readings[90], 4000);
    rt.shutdown();
}

#[test]
fn pull_mode_gets_data_on_request() {
    let emu = Emulator::start();
    let rt = start(
        emu.port,
        "provides encoders\nprovides laser 180 1\ndatamode pull\n",
    );
    let enc: Arc<Interface<Encoders>> = rt.interfaces.get("encoders").unwrap();
    let laser: Arc<Interface<Laser>> = rt.interfaces.get("laser").unwrap();
    rt.run("encoders").unwrap();
    rt.run("laser").unwrap();
    eventually("data in PULL mode", || enc.clock() > 3 && laser.clock() > 3);
    assert_eq!(laser.read().readings[90], 4000);
    rt.shutdown();
}

// ---- faults ----

fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    l.local_addr().unwrap().port()
}

#[test]
fn no_server_at_start_is_said_once_and_the_driver_connects_when_it_comes() {
    let port = free_port();
    let rt = start(
        port,
        "provides encoders\nprovides motors\nprovides bumpers\n",
    );
    let enc: Arc<Interface<Encoders>> = rt.interfaces.get("encoders").unwrap();
    let bump: Arc<Interface<Bumpers>> = rt.interfaces.get("bumpers").unwrap();
    let why = enc.stale().expect("stale while there is no server");
    assert!(why.contains(&format!("127.0.0.1:{port}")), "{why}");
    assert!(
        why.contains("Start one first") && why.contains("player "),
        "{why}"
    );
    rt.run("encoders").unwrap();
    rt.run("bumpers").unwrap();
    // The server comes, without a bumper: encoders work, bumpers say why not.
    let emu = Emulator::on_port(vec![(4, 0), (62, 0)], port);
    eventually("connected and subscribed", || {
        emu.subscribed(4, 0) && enc.clock() > 0 && enc.stale().is_none()
    });
    eventually("bumpers stale with the reason", || {
        bump.stale()
            .is_some_and(|w| w.contains("bumper:0") && w.contains("position2d:0, ranger:0"))
    });
    rt.shutdown();
}

#[test]
fn a_missing_device_names_it_and_the_servers_list() {
    let emu = Emulator::with_devices(vec![(4, 0), (62, 0)]);
    let e = start_err(emu.port, "provides encoders\nprovides bumpers\n");
    assert!(e.contains("test.conf:4"), "{e}");
    assert!(
        e.contains("bumper:0") && e.contains("position2d:0, ranger:0"),
        "{e}"
    );
    let e = start_err(emu.port, "provides laser 180 1 index 3\n");
    assert!(e.contains("laser:3 or ranger:3"), "{e}");
    assert!(emu.shared.devlists.load(Ordering::Acquire) >= 2);
}

#[test]
fn conf_errors_name_the_line() {
    let emu = Emulator::start();
    for (body, want) in [
        ("provides laser 180", "usage: provides laser [N R]"),
        ("provides laser 0 1", "between 1 and 720"),
        ("provides wheels", "not `wheels`"),
        (
            "provides encoders index x",
            "I (argument 3) is `x`, expected a whole number",
        ),
        (
            "provides laser 180 1 device tank:1",
            "expected a Player interface",
        ),
        ("initial_position 1 2", "takes 3 to 4 arguments"),
        ("datamode fast", "one of push, pull"),
        ("frobnicate 1", "takes no `frobnicate` line"),
        ("provides encoders\nprovides encoders", "already provided"),
    ] {
        let e = start_err(emu.port, body);
        assert!(e.contains("test.conf:"), "{body}: {e}");
        assert!(e.contains(want), "{body}: {e}");
    }
}

#[test]
fn a_server_that_goes_away_makes_interfaces_stale_stops_and_reconnects() {
    let emu = Emulator::start();
    let rt = start(
        emu.port,
        "provides encoders\nprovides motors\nprovides laser 180 1\n",
    );
    let enc: Arc<Interface<Encoders>> = rt.interfaces.get("encoders").unwrap();
    let laser: Arc<Interface<Laser>> = rt.interfaces.get("laser").unwrap();
    let motors: Arc<Interface<Motors>> = rt.interfaces.get("motors").unwrap();
    rt.run("encoders").unwrap();
    rt.run("laser").unwrap();
    rt.run("motors").unwrap();
    eventually("data", || enc.clock() > 0 && laser.clock() > 0);
    motors.publish(Motors { v: 100.0, w: 0.0 }).unwrap();
    emu.go_down();
    eventually("stale", || enc.stale().is_some() && laser.stale().is_some());
    let why = enc.stale().unwrap();
    assert!(
        why.contains(&format!("127.0.0.1:{}", emu.port)) && why.contains("reconnecting"),
        "{why}"
    );
    assert_eq!(motors.read().value, Motors::default(), "motors to zero");
    let c = enc.clock();
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(enc.clock(), c, "no data while the server is down");
    let accepted = emu.shared.accepted.load(Ordering::Acquire);
    emu.come_back();
    eventually("reconnected and resubscribed", || {
        emu.shared.accepted.load(Ordering::Acquire) > accepted
            && emu.subscribed(4, 0)
            && emu.subscribed(6, 0)
    });
    eventually("fresh data clears stale", || {
        enc.stale().is_none() && laser.stale().is_none() && enc.clock() > c
    });
    rt.shutdown();
}

#[test]
fn garbage_oversized_and_bad_counts_drop_the_connection_and_it_reopens() {
    let emu = Emulator::start();
    let rt = start(
        emu.port,
        "provides encoders\nprovides laser 180 1\ntimeout 1000\n",
    );
    let enc: Arc<Interface<Encoders>> = rt.interfaces.get("encoders").unwrap();
    let laser: Arc<Interface<Laser>> = rt.interfaces.get("laser").unwrap();
    rt.run("encoders").unwrap();
    rt.run("laser").unwrap();
    eventually("data", || enc.clock() > 0 && laser.clock() > 0);
    let f = &emu.shared.faults;
    for fault in ["oversized", "bad_count", "garbage", "stall"] {
        let accepted = emu.shared.accepted.load(Ordering::Acquire);
        match fault {
            "oversized" => f.oversized.store(true, Ordering::Release),
            "bad_count" => f.bad_count.store(true, Ordering::Release),
            "garbage" => f.garbage.store(4096, Ordering::Release),
            _ => f.stall.store(true, Ordering::Release),
        }
        eventually(&format!("{fault}: the driver reconnects"), || {
            emu.shared.accepted.load(Ordering::Acquire) > accepted
        });
        f.stall.store(false, Ordering::Release);
        let c = laser.clock();
        eventually(&format!("{fault}: data again"), || {
            laser.clock() > c + 2 && laser.stale().is_none()
        });
        assert_eq!(laser.read().readings.len(), 180);
    }
    rt.shutdown();
}

#[test]
fn nacked_subscriptions_leave_the_interface_stale_until_the_server_accepts() {
    let emu = Emulator::start();
    let rt = start(emu.port, "provides laser 180 1\n");
    let laser: Arc<Interface<Laser>> = rt.interfaces.get("laser").unwrap();
    emu.shared.faults.nack_all.store(true, Ordering::Release);
    rt.run("laser").unwrap();
    eventually("stale after a refused subscription", || {
        laser
            .stale()
            .is_some_and(|w| w.contains("refused to subscribe laser:0"))
    });
    assert_eq!(laser.clock(), 0);
    emu.shared.faults.nack_all.store(false, Ordering::Release);
    eventually("subscribed once the server accepts", || {
        laser.clock() > 0 && laser.stale().is_none()
    });
    rt.shutdown();
}

// ---- the real binary ----

/// examples/player.conf pointed at `port`, with `edit` applied to its text.
fn example_conf(dir: &Path, port: u16, edit: impl Fn(String) -> String) -> PathBuf {
    let text = std::fs::read_to_string(root().join("examples/player.conf")).unwrap();
    let text = text.replace(
        "hostname localhost port 6665",
        &format!("hostname 127.0.0.1 port {port}"),
    );
    let f = dir.join("player.conf");
    std::fs::write(&f, edit(text)).unwrap();
    f
}

/// The binary, headless, its stdout read line by line on a thread.
struct Bin {
    child: std::process::Child,
    lines: std::sync::mpsc::Receiver<String>,
    seen: Vec<String>,
}

impl Bin {
    fn start(conf: &Path) -> Bin {
        let mut child = common::jderobot([Path::new("--headless"), conf])
            .spawn()
            .expect("start jderobot");
        let out = child.stdout.take().unwrap();
        // Standard error (the log) is read too, so the child never blocks on it.
        let err = child.stderr.take().unwrap();
        std::thread::spawn(move || {
            for l in BufReader::new(err).lines().map_while(Result::ok) {
                eprintln!("jderobot: {l}");
            }
        });
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for l in BufReader::new(out).lines().map_while(Result::ok) {
                let _ = tx.send(l);
            }
        });
        Bin {
            child,
            lines: rx,
            seen: Vec::new(),
        }
    }
    fn send(&mut self, cmd: &str) {
        let stdin = self.child.stdin.as_mut().unwrap();
        stdin.write_all(cmd.as_bytes()).unwrap();
        stdin.write_all(b"\n").unwrap();
        stdin.flush().unwrap();
    }
    /// The next line that starts with `prefix` (20 s at most).
    fn line(&mut self, prefix: &str) -> String {
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(20) {
            if let Ok(l) = self.lines.recv_timeout(Duration::from_millis(100)) {
                self.seen.push(l.clone());
                if l.starts_with(prefix) {
                    return l;
                }
            }
        }
        panic!(
            "no line starting with `{prefix}`; saw:\n{}",
            self.seen.join("\n")
        );
    }
    /// Every line that arrives within `d`.
    fn collect(&mut self, d: Duration) -> Vec<String> {
        let t0 = Instant::now();
        let mut v = Vec::new();
        while t0.elapsed() < d {
            if let Ok(l) = self.lines.recv_timeout(Duration::from_millis(50)) {
                self.seen.push(l.clone());
                v.push(l);
            }
        }
        v
    }
    fn quit(mut self) {
        self.send("quit");
        let ok = poll_until(20, || self.child.try_wait().ok().flatten().is_some());
        if !ok {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
        assert!(ok, "jderobot did not quit");
    }
}

fn field(line: &str, key: &str) -> f32 {
    let s = line
        .split(key)
        .nth(1)
        .unwrap_or_else(|| panic!("no {key} in {line}"));
    s.split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn the_binary_with_the_example_conf_drives_from_the_shell() {
    let emu = Emulator::start();
    let dir = tempfile::tempdir().unwrap();
    // The shell drives; introrob stays loaded but stopped.
    let conf = example_conf(dir.path(), emu.port, |t| t.replace("run introrob\n", ""));
    let mut bin = Bin::start(&conf);
    bin.send("run encoders");
    bin.send("run laser");
    bin.send("echo encoders 3");
    let before = bin.line("encoders clock=");
    let x0 = field(&before, "x=");
    bin.send("echo laser 1");
    let laser = bin.line("laser clock=");
    assert!(
        laser.contains("number=180 resolution=1 readings/deg"),
        "{laser}"
    );
    let readings: Vec<i32> = laser
        .split("readings(mm)=[")
        .nth(1)
        .unwrap()
        .trim_end_matches(']')
        .split_whitespace()
        .map(|r| r.parse().unwrap())
        .collect();
    assert_eq!(
        (readings[0], readings[90]),
        (3000, 4000),
        "mm, index 0 on the right"
    );
    // Drive forward (commands last motors_timeout = 500 ms each).
    let t0 = Instant::now();
    let mut x = x0;
    while x < x0 + 50.0 && t0.elapsed() < Duration::from_secs(20) {
        bin.send("set motors v=300 w=0");
        bin.send("echo encoders 2");
        let _ = bin.line("motors clock=");
        x = field(&bin.line("encoders clock="), "x=");
    }
    assert!(x >= x0 + 50.0, "encoders did not move: {x0} -> {x}");
    assert!(emu.world().x > 0.04);
    bin.send("ps");
    let ps = bin.line("encoders: ");
    assert!(ps.contains("player"), "{ps}");
    bin.quit();
    eventually("quitting zeroes the motors", || emu.world().v == 0.0);
}

#[test]
fn the_binary_reports_a_missing_server_and_a_lost_one() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let conf = example_conf(dir.path(), port, |t| t);
    // No server: one error naming host:port and what to start; the program runs
    // on (introrob sees stale interfaces) and `check` passes.
    let out = Command::new(env!("CARGO_BIN_EXE_jderobot"))
        .args(["--headless", "--no-shell", "--for", "2"])
        .arg(&conf)
        .env_remove("DISPLAY")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains(&format!("127.0.0.1:{port}")) && err.contains("Start one first"),
        "{err}"
    );
    assert_eq!(
        err.matches("cannot reach a Player server").count(),
        1,
        "one error: {err}"
    );
    common::jderobot_ok([Path::new("check"), &conf]);

    let emu = Emulator::start();
    let conf = example_conf(dir.path(), emu.port, |t| t.replace("run introrob\n", ""));
    let mut bin = Bin::start(&conf);
    bin.send("run encoders");
    bin.send("echo encoders 1");
    bin.line("encoders clock=");
    emu.go_down();
    let mut ps = String::new();
    let stale = poll_until(20, || {
        bin.send("ps");
        ps = bin.line("encoders: ");
        ps.contains("STALE")
    });
    assert!(stale && ps.contains("lost the Player server"), "{ps}");
    emu.come_back();
    eventually("resubscribed", || emu.subscribed(4, 0));
    bin.send("echo encoders 1");
    let l = bin.line("encoders clock=");
    assert!(!l.contains("STALE"), "{l}");
    // A server that comes back but refuses every subscription for a while: the
    // driver keeps retrying, and says so once, not once per attempt.
    emu.shared.faults.nack_all.store(true, Ordering::Release);
    emu.go_down();
    let attempts0 = emu.shared.accepted.load(Ordering::Acquire);
    emu.come_back();
    let during = bin.collect(Duration::from_secs(4));
    let attempts = emu.shared.accepted.load(Ordering::Acquire) - attempts0;
    emu.shared.faults.nack_all.store(false, Ordering::Release);
    // 100 ms doubling to 2 s: about 5 attempts in 4 s, not a tight loop.
    assert!(
        (1..=12).contains(&attempts),
        "{attempts} connections in 4 s"
    );
    bin.line("player: reconnected");
    let lost = during
        .iter()
        .filter(|l| l.contains("lost the Player server"))
        .count();
    assert_eq!(lost, 1, "one line per change of state: {during:?}");
    assert!(
        !during.iter().any(|l| l.contains("reconnected")),
        "{during:?}"
    );
    bin.quit();
}

#[test]
fn introrob_vff_reaches_a_target_in_the_emulators_world() {
    let emu = Emulator::start();
    let dir = tempfile::tempdir().unwrap();
    // Target (3000, -2000) mm: 3 m ahead and 2 m to the right of the start.
    let conf = example_conf(dir.path(), emu.port, |t| {
        t.replace("behaviour teleop", "behaviour vff")
            .replace("# target 3000 -2000", "target 3000 -2000")
    });
    let mut bin = Bin::start(&conf);
    let mut last = Instant::now();
    let reached = poll_until(90, || {
        let w = emu.world();
        if last.elapsed() > Duration::from_secs(5) {
            last = Instant::now();
            eprintln!(
                "robot at ({:.2}, {:.2}, {:.2}) v={:.2} w={:.2} cmds={}",
                w.x,
                w.y,
                w.a,
                w.v,
                w.w,
                w.commands.len()
            );
        }
        (w.x - 3.0).hypot(w.y + 2.0) < 0.3
    });
    let (x, y) = {
        let w = emu.world();
        (w.x, w.y)
    };
    bin.send("ps");
    let _ = bin.line("introrob: ");
    bin.quit();
    assert!(
        reached,
        "introrob's VFF did not reach (3, -2) m; the robot is at ({x:.2}, {y:.2})"
    );
}

// ---- values from outside ----

/// The process's log lines (a global subscriber, installed on first use); tests
/// look for lines naming their own emulator's port.
fn log_lines() -> Arc<std::sync::Mutex<Vec<u8>>> {
    static LOG: std::sync::OnceLock<Arc<std::sync::Mutex<Vec<u8>>>> = std::sync::OnceLock::new();
    LOG.get_or_init(|| {
        let buf = Arc::new(std::sync::Mutex::new(Vec::new()));
        struct W(Arc<std::sync::Mutex<Vec<u8>>>);
        impl Write for W {
            fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
                self.0.lock().unwrap().extend_from_slice(b);
                Ok(b.len())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let b = buf.clone();
        let _ = tracing_subscriber::fmt()
            .with_max_level(tracing::Level::INFO)
            .with_ansi(false)
            .with_writer(move || W(b.clone()))
            .try_init();
        buf
    })
    .clone()
}

fn log_text() -> String {
    String::from_utf8_lossy(&log_lines().lock().unwrap()).into_owned()
}

#[test]
fn position2d_with_nan_or_inf_is_dropped_and_the_last_good_pose_stays() {
    let emu = Emulator::start();
    let rt = start(emu.port, "provides encoders\nprovides laser 180 1\n");
    let enc: Arc<Interface<Encoders>> = rt.interfaces.get("encoders").unwrap();
    let laser: Arc<Interface<Laser>> = rt.interfaces.get("laser").unwrap();
    rt.run("encoders").unwrap();
    rt.run("laser").unwrap();
    eventually("data", || enc.clock() > 0 && laser.clock() > 0);
    type Spoil = fn(&mut player_emulator::World);
    let spoils: [(&str, Spoil); 3] = [
        ("x NaN", |w| w.x = f64::NAN),
        ("y inf", |w| w.y = f64::INFINITY),
        ("a NaN", |w| w.a = f64::NAN),
    ];
    for (what, spoil) in spoils {
        spoil(&mut emu.world());
        // Rounds of data after the change (the laser comes in the same rounds).
        let c = laser.clock();
        eventually(&format!("{what}: rounds after it"), || {
            laser.clock() > c + 3
        });
        let e = enc.read();
        assert!(
            e.x.is_finite() && e.y.is_finite() && e.theta.is_finite(),
            "{what}: the pose stays finite: {e:?}"
        );
        drop(e);
        {
            let mut w = emu.world();
            (w.x, w.y, w.a) = (0.5, 0.25, 0.0);
        }
        eventually(&format!("{what}: good poses again"), || {
            (enc.read().x - 500.0).abs() < 1.0
        });
    }
    rt.shutdown();
}

#[test]
fn an_unusable_camera_frame_is_said_once_while_it_lasts() {
    let _ = log_lines();
    let emu = Emulator::start();
    let rt = start(emu.port, "provides varcolorA\n");
    let var: Arc<Interface<Image>> = rt.interfaces.get("varcolorA").unwrap();
    rt.run("varcolorA").unwrap();
    eventually("frames", || var.clock() > 0);
    let accepted = emu.shared.accepted.load(Ordering::Acquire);
    // Frames out of range (9000 pixels wide) between good ones, as a fuzzer or a
    // failing camera sends them.
    let lines = || {
        log_text()
            .lines()
            .filter(|l| l.contains("WARN") && l.contains("9000x60"))
            .count()
    };
    for k in 0..5 {
        emu.shared.camera.lock().unwrap().0 = 9000;
        if k == 0 {
            eventually("the line", || lines() > 0);
        } else {
            std::thread::sleep(Duration::from_millis(60));
        }
        let c = var.clock();
        emu.shared.camera.lock().unwrap().0 = 80;
        eventually("a good frame", || var.clock() > c);
    }
    assert_eq!(lines(), 1, "one line for the bad frames:\n{}", log_text());
    assert_eq!(
        emu.shared.accepted.load(Ordering::Acquire),
        accepted,
        "the connection stays"
    );
    rt.shutdown();
}

/// Issue 52: a `jderobot` process driving the robot from its shell sends
/// CMD_VEL 0 (through its estop handle on the connection) when it gets SIGTERM
/// or SIGTSTP, before it ends or suspends.
#[test]
fn ending_and_suspending_signals_send_cmd_vel_zero_within_100_ms() {
    for signal in common::process::STOP_SIGNALS {
        let emu = Emulator::start();
        let dir = tempfile::tempdir().unwrap();
        let conf = dir.path().join("player.conf");
        std::fs::write(
            &conf,
            format!(
                "driver player\nhostname 127.0.0.1 port {}\nprovides motors\nmotors_timeout 60000\n\
                 end_driver\nload_driver player\n",
                emu.port
            ),
        )
        .unwrap();
        let mut p = common::process::Proc::start_alone(&conf);
        let moving = poll_until(20, || {
            p.send("set motors v=150 w=0");
            std::thread::sleep(Duration::from_millis(200));
            emu.world()
                .commands
                .last()
                .is_some_and(|c| (c.0 - 0.15).abs() < 1e-6)
        });
        assert!(
            moving,
            "the robot never drove; jderobot said:\n{}",
            p.text()
        );
        let took = common::process::time_to_stop(&mut p, signal, |t0| {
            emu.world()
                .commands
                .iter()
                .find(|c| c.2 >= t0 && c.0 == 0.0 && c.1 == 0.0)
                .map(|c| c.2)
        });
        eprintln!(
            "player, {}: CMD_VEL 0 after {:.1} ms",
            signal.1,
            took.as_secs_f64() * 1e3
        );
        assert!(
            took < Duration::from_millis(100),
            "{}: stop after {took:?}",
            signal.1
        );
    }
}
