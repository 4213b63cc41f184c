//! networkserver and networkclient on the 4.3 wire, over real loopback sockets:
//! a 4.3-style client (tests/emulators/jde43_client.rs) byte for byte against our
//! server, and our client against a 4.3-style server (jde43_server.rs), every
//! message kind of reference §4.
#![cfg(all(feature = "networkserver", feature = "networkclient"))]

use crate::common;
#[path = "emulators/jde43_client.rs"]
mod jde43_client;
#[path = "emulators/jde43_server.rs"]
mod jde43_server;

use std::{net::SocketAddr, sync::Arc, time::Duration};

use common::{eventually, poll_until};
use jde43_client::Client43;
use jde43_server::{Robot43, Server43};
use jderobot::{
    ComponentConf, Kind, Runtime,
    interfaces::{
        Encoders, Image, Imu, Interface, Laser, Motors, PtEncoders, PtMotors, Sonars, ZoomEncoders,
        ZoomMotors,
    },
    registry,
};

fn load(rt: &Runtime, kind: Kind, name: &str, text: &str) -> Result<(), String> {
    let comp = registry::find(name).expect("compiled in");
    let conf = ComponentConf::from_text(kind, name, text).unwrap();
    jderobot::loader::load_entry(rt, comp, &conf).map_err(|e| e.to_string())
}

/// A runtime with every servable interface (provider `robot`) and a networkserver.
fn served(extra: &str) -> (Arc<Runtime>, SocketAddr) {
    let rt = Runtime::new(std::path::Path::new("test.conf"));
    let i = &rt.interfaces;
    i.provide_value("colorA", "robot", Image::new(320, 240))
        .unwrap();
    i.provide_value("varcolorB", "robot", Image::new(640, 480))
        .unwrap();
    i.provide::<Laser>("laser", "robot").unwrap();
    i.provide::<Encoders>("encoders", "robot").unwrap();
    i.provide::<Sonars>("sonars", "robot").unwrap();
    i.provide::<Motors>("motors", "robot").unwrap();
    i.provide::<PtEncoders>("pantiltencoders", "robot").unwrap();
    i.provide::<PtMotors>("pantiltmotors", "robot").unwrap();
    i.provide::<ZoomEncoders>("zoomencoders", "robot").unwrap();
    i.provide::<ZoomMotors>("zoommotors", "robot").unwrap();
    i.provide::<Imu>("imu", "robot").unwrap();
    let text = format!(
        "socket 0\nserves colorA 0\nserves varcolorB 1\nserves laser\nserves encoders\nserves sonars\n\
         serves motors\nserves ptencoders\nserves ptmotors\nserves zencoders\nserves zmotors\n\
         serves imu\n{extra}"
    );
    load(&rt, Kind::Service, "networkserver", &text).unwrap();
    let addr = *rt
        .names
        .import::<SocketAddr>("networkserver", "address")
        .unwrap();
    (rt, addr)
}

/// Publishes a recognisable value on every sensor.
fn publish_all(rt: &Runtime, k: u8) {
    let i = &rt.interfaces;
    let mut a = Image::new(320, 240);
    for (n, b) in a.data.iter_mut().enumerate() {
        *b = (n % 253) as u8 ^ k;
    }
    i.get::<Image>("colorA").unwrap().publish(a).unwrap();
    let mut b = Image::new(640, 480);
    b.data[0] = k;
    i.get::<Image>("varcolorB").unwrap().publish(b).unwrap();
    i.get::<Laser>("laser")
        .unwrap()
        .publish(Laser {
            readings: (0..180).map(|r| 500 + r).collect(),
            resolution: 1.0,
            ..Laser::default()
        })
        .unwrap();
    i.get::<Encoders>("encoders")
        .unwrap()
        .publish(Encoders::from_pose(1234.5, -50.25, 90f32.to_radians()))
        .unwrap();
    i.get::<Sonars>("sonars")
        .unwrap()
        .publish(Sonars {
            us: (0..16).map(|u| 100.0 + u as f32).collect(),
        })
        .unwrap();
    i.get::<PtEncoders>("pantiltencoders")
        .unwrap()
        .publish(PtEncoders {
            pan_angle: 10.25,
            tilt_angle: -5.0,
        })
        .unwrap();
    i.get::<ZoomEncoders>("zoomencoders")
        .unwrap()
        .publish(ZoomEncoders { zoom_position: 2.5 })
        .unwrap();
    i.get::<Imu>("imu").unwrap().publish(IMU).unwrap();
}

/// A turning, accelerating IMU (heading 45°).
const IMU: Imu = Imu {
    qx: 0.0,
    qy: 0.0,
    qz: 0.38268343,
    qw: 0.9238795,
    wx: 0.0,
    wy: 0.0,
    wz: 0.25,
    ax: 0.1,
    ay: -0.2,
    az: 9.81,
};

/// Images: one connection per camera, each query answered with a new frame.
fn gets_images(rt: &Runtime, addr: SocketAddr) {
    let mut cam = Client43::connect(addr, None);
    let (h, px) = cam.image(0);
    assert_eq!(&h[2..], ["0", "320", "240", "3"], "{h:?}");
    assert_eq!(
        px,
        rt.interfaces.get::<Image>("colorA").unwrap().read().data
    );
    let clock0: u64 = h[1].parse().unwrap();
    cam.send("1019 0");
    std::thread::sleep(Duration::from_millis(50));
    publish_all(rt, 2);
    let (h2, px2) = cam.read_image();
    assert!(
        h2[1].parse::<u64>().unwrap() > clock0,
        "a new frame: {h2:?}"
    );
    assert_eq!((px[0], px2[0]), (1, 2), "the new frame's pixels");
    let mut var = Client43::connect(addr, None);
    let (h, px) = var.image(1);
    assert_eq!(&h[2..], ["1", "640", "480", "3"]);
    assert_eq!(px.len(), 640 * 480 * 3);
    var.send("1000");
    assert!(var.closed_within(5), "1000 (goodbye images) closes");
}

/// Subscriptions: pushes in 4.3's formats.
fn gets_pushes(robot: &mut Client43) {
    for s in ["27", "11", "2", "1001", "1025", "2001"] {
        robot.send(s);
    }
    let laser = robot.expect("26");
    assert_eq!(laser.len(), 2 + 180);
    assert_eq!(laser[2], "500");
    assert_eq!(laser[181], "679");
    let enc = robot.expect("10");
    assert_eq!(&enc[2..5], ["1234.5", "-50.2", "90.00000"], "{enc:?}");
    assert_eq!(enc.len(), 6);
    let son = robot.expect("1");
    // 4.3 sent laser.number (180) pairs; the sonars' own 16 now.
    assert_eq!(son.len(), 2 + 2 * 16, "{son:?}");
    assert_eq!(&son[2..6], ["0", "100.0", "1", "101.0"]);
    let pt = robot.expect("1003");
    assert_eq!(&pt[2..], ["10.2", "-5.0"]);
    let z = robot.expect("1021");
    assert_eq!(&z[2..], ["2.5"]);
    // jderobot's imu extension: every field, exactly (shortest round-trip form).
    let imu = robot.expect("2003");
    assert_eq!(
        &imu[2..],
        [
            "0",
            "0",
            "0.38268343",
            "0.9238795",
            "0",
            "0",
            "0.25",
            "0.1",
            "-0.2",
            "9.81"
        ]
    );
}

/// Commands reach the interfaces.
fn commands_arrive(rt: &Runtime, robot: &mut Client43) {
    robot.send("22 150.0 0.0");
    robot.send("23 -10.5 0.0");
    robot.send("1006 20.0 -10.0 30.0 40.0");
    robot.send("1024 5.0 1.0");
    robot.send("1004");
    let lim = robot.expect("1005");
    assert_eq!(
        &lim[1..],
        ["159.13", "30.00", "-159.13", "-46.00", "205.89", "205.89"]
    );
    robot.send("1022");
    assert_eq!(&robot.expect("1023")[1..], ["40.00", "0.00", "7.00"]);
    let m = rt.interfaces.get::<Motors>("motors").unwrap();
    assert_eq!((m.read().v, m.read().w), (150.0, -10.5));
    let p = rt
        .interfaces
        .get::<PtMotors>("pantiltmotors")
        .unwrap()
        .read()
        .value;
    assert_eq!(
        (p.longitude, p.latitude, p.longitude_speed, p.latitude_speed),
        (20.0, -10.0, 30.0, 40.0)
    );
    let zm = rt
        .interfaces
        .get::<ZoomMotors>("zoommotors")
        .unwrap()
        .read()
        .value;
    assert_eq!((zm.zoom, zm.zoom_speed), (5.0, 1.0));
    // The subscriptions resumed the served interfaces (a simulator computes them).
    assert!(rt.interfaces.get_any("laser").unwrap().users() >= 1);
}

/// Unsubscribe: no more laser lines once what was in flight is read.
fn unsubscribe_stops_the_laser(rt: &Runtime, robot: &mut Client43) {
    robot.send("28");
    robot.send("1004");
    robot.expect("1005");
    publish_all(rt, 3);
    robot.send("1022");
    let mut saw_laser = false;
    loop {
        let l = robot.line().unwrap();
        if l.starts_with("1023") {
            break;
        }
        saw_laser |= l.starts_with("26 ");
    }
    std::thread::sleep(Duration::from_millis(100));
    robot.send("1022");
    loop {
        let l = robot.line().unwrap();
        assert!(!l.starts_with("26 "), "laser after 28: {l}");
        if l.starts_with("1023") {
            break;
        }
    }
    let _ = saw_laser;
}

#[test]
fn a_4_3_client_gets_every_message_kind_from_our_server() {
    let (rt, addr) = served("");
    assert!(addr.ip().is_loopback(), "bound to {addr}, not loopback");
    publish_all(&rt, 1);

    gets_images(&rt, addr);
    let mut robot = Client43::connect(addr, None);
    gets_pushes(&mut robot);
    commands_arrive(&rt, &mut robot);
    unsubscribe_stops_the_laser(&rt, &mut robot);
    // Goodbye: the server closes, the motors the client drove go to zero.
    robot.send("0");
    assert!(robot.closed_within(5), "0 (goodbye) closes");
    let m = rt.interfaces.get::<Motors>("motors").unwrap();
    eventually("motors zeroed after the driving client left", || {
        m.read().value == Motors::default()
    });
    eventually("the laser suspended", || {
        rt.interfaces.get_any("laser").unwrap().users() == 0
    });
    rt.shutdown();
}

#[test]
fn zoom_needs_zoom_motors_not_pantilt_and_unserved_devices_get_1027() {
    // 4.3 obeyed 1024 only when pan-tilt motors were served.
    let rt = Runtime::new(std::path::Path::new("test.conf"));
    rt.interfaces
        .provide::<ZoomMotors>("zoommotors", "robot")
        .unwrap();
    load(
        &rt,
        Kind::Service,
        "networkserver",
        "socket 0\nserves zoommotors\n",
    )
    .unwrap();
    let addr = *rt
        .names
        .import::<SocketAddr>("networkserver", "address")
        .unwrap();
    let mut c = Client43::connect(addr, None);
    c.send("1024 7.0 2.0");
    c.send("27");
    let e = c.expect("1027");
    assert!(e.join(" ").contains("laser is not served"), "{e:?}");
    c.send("1004");
    let e = c.expect("1027");
    assert!(e.join(" ").contains("ptmotors"), "{e:?}");
    let z = rt.interfaces.get::<ZoomMotors>("zoommotors").unwrap();
    assert_eq!(z.read().zoom, 7.0);
    rt.shutdown();
}

#[test]
fn a_token_line_is_required_when_configured() {
    let (rt, addr) = served("token 7f3a9c2e5b8d4f16a0c3e9b2d7f14a68\n");
    let mut no = Client43::connect(addr, None);
    no.send("1022");
    let e = no.expect("1027");
    assert!(e.join(" ").contains("token"), "{e:?}");
    assert!(no.closed_within(5));
    let mut wrong = Client43::connect(addr, Some("guess-guess-guess-guess"));
    assert!(wrong.closed_within(5));
    let mut yes = Client43::connect(addr, Some("7f3a9c2e5b8d4f16a0c3e9b2d7f14a68"));
    yes.send("1022");
    yes.expect("1023");
    rt.shutdown();
}

#[test]
fn conf_errors_name_the_line() {
    let rt = Runtime::new(std::path::Path::new("test.conf"));
    let (server, client) = (
        (Kind::Service, "networkserver"),
        (Kind::Driver, "networkclient"),
    );
    // (component, its lines, what the error must say)
    let cases = [
        (
            server,
            "socket 0\nserves laser\n",
            &["serves laser", "before networkserver"][..],
        ),
        (server, "serves laser\n", &["socket PORT"]),
        (
            server,
            "socket 0\nserves colorA\n",
            &["<inline>:2", "network id"],
        ),
        (
            server,
            "socket 0\nbind nowhere\n",
            &["<inline>:2", "IP address"],
        ),
        (
            server,
            "socket 0\ntoken 0123456789abcdef b\n",
            &["token SECRET"],
        ),
        (
            server,
            "socket 0\ntoken s\n",
            &["<inline>:2", "too short", "at least 16 needed"],
        ),
        (
            client,
            "token 123456789012345\nprovides laser host 3001\n",
            &["<inline>:1", "too short", "at least 16 needed"],
        ),
        (
            client,
            "provides colorA host 3001\n",
            &["<inline>:1", "NETID"],
        ),
        (
            client,
            "provides laser host port\n",
            &["between 1 and 65535"],
        ),
        (
            client,
            "provides laser h 1 2\n",
            &["usage: provides INTERFACE HOST PORT"],
        ),
        (
            client,
            "initial_position 1 2\n",
            &["usage: initial_position X Y THETA"],
        ),
    ];
    for ((kind, name), lines, says) in cases {
        let e = load(&rt, kind, name, lines).unwrap_err();
        assert!(says.iter().all(|s| e.contains(s)), "{name} {lines:?}: {e}");
    }
}

fn robot43() -> Robot43 {
    Robot43 {
        sizes: vec![(320, 240), (640, 480), (160, 120)],
        laser_number: 180,
        sonars_number: 16,
    }
}

fn client_conf(port: u16, extra: &str) -> String {
    let h = format!("127.0.0.1 {port}");
    format!(
        "provides colorA {h} 0\nprovides varcolorA {h} 1\nprovides laser {h}\nprovides encoders {h}\n\
         provides sonars {h}\nprovides motors {h}\nprovides pantiltencoders {h}\nprovides pantiltmotors {h}\n\
         provides zoomencoders {h}\nprovides zoommotors {h}\ninitial_position 1000 2000 90\n{extra}"
    )
}

/// What the client provides that is read (images and pushed sensors).
const READ: [&str; 7] = [
    "colorA",
    "varcolorA",
    "laser",
    "encoders",
    "sonars",
    "pantiltencoders",
    "zoomencoders",
];

fn use_all(rt: &Runtime) {
    for n in READ {
        rt.interfaces.get_any(n).unwrap().resume();
    }
}

#[test]
fn our_client_against_a_4_3_server() {
    let emu = Server43::start(0, robot43());
    let rt = Runtime::new(std::path::Path::new("test.conf"));
    load(
        &rt,
        Kind::Driver,
        "networkclient",
        &client_conf(emu.addr.port(), ""),
    )
    .unwrap();
    use_all(&rt);
    let i = &rt.interfaces;
    eventually("every device subscribed and queried", || {
        [
            "1019 0", "1019 1", "27", "11", "2", "1001", "1025", "1004", "1022",
        ]
        .iter()
        .all(|l| emu.got(l))
    });
    // Names: `jdec` and NULs, one per connection (10 devices).
    eventually("ten connections", || emu.names.lock().unwrap().len() == 10);
    for n in emu.names.lock().unwrap().iter() {
        assert_eq!(n, b"jdec\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0");
    }
    eventually("frames and pushes arrive", || {
        READ.iter().all(|n| i.get_any(n).unwrap().clock() > 2)
    });
    let a = i.get::<Image>("colorA").unwrap().snapshot();
    assert_eq!((a.width, a.height), (320, 240));
    let off = a.data[0] as u64;
    for (k, b) in a.data.iter().enumerate().take(5000) {
        assert_eq!(*b as u64, (k as u64 + off) % 251, "pixel byte {k}");
    }
    let v = i.get::<Image>("varcolorA").unwrap().snapshot();
    assert_eq!((v.width, v.height), (640, 480));
    let l = i.get::<Laser>("laser").unwrap().snapshot();
    assert_eq!(l.readings.len(), 180);
    assert_eq!((l.readings[0], l.readings[179]), (1000, 1179));
    // Remote (1500, -250) at 90 deg, seen from an origin at (1000, 2000) turned 90 deg.
    let e = i.get::<Encoders>("encoders").unwrap().snapshot();
    assert!(
        (e.x - 1250.0).abs() < 0.5 && (e.y - 3500.0).abs() < 0.5,
        "{e:?}"
    );
    assert!((e.theta.to_degrees() - 180.0).abs() < 0.01, "{e:?}");
    let s = i.get::<Sonars>("sonars").unwrap().snapshot();
    assert_eq!(s.us.len(), 16);
    assert_eq!(s.us[15], 315.0);
    let p = i.get::<PtEncoders>("pantiltencoders").unwrap().snapshot();
    assert_eq!((p.pan_angle, p.tilt_angle), (12.5, -7.5));
    assert_eq!(
        i.get::<ZoomEncoders>("zoomencoders")
            .unwrap()
            .read()
            .zoom_position,
        3.0
    );
    // Limits from 1005 / 1023.
    eventually("pan-tilt limits", || {
        i.get::<PtMotors>("pantiltmotors")
            .unwrap()
            .read()
            .min_latitude
            == -46.0
    });
    eventually("zoom limits", || {
        i.get::<ZoomMotors>("zoommotors").unwrap().read().max_zoom == 40.0
    });
    // Commands, as 4.3 wrote them.
    assert!(emu.got("22 0.0 0.0") && emu.got("23 0.0 0.0"));
    i.get::<Motors>("motors")
        .unwrap()
        .publish(Motors { v: 120.0, w: -5.0 })
        .unwrap();
    eventually("22/23 carry the command", || {
        emu.got("22 120.0 0.0") && emu.got("23 -5.0 0.0")
    });
    let ptm = i.get::<PtMotors>("pantiltmotors").unwrap();
    let mut c = ptm.read().value;
    c.longitude = 30.0;
    c.latitude = -10.0;
    c.longitude_speed = 50.0;
    ptm.publish(c).unwrap();
    eventually("1006", || emu.got("1006 30.00 -10.00 50.00 0.00"));
    let zm = i.get::<ZoomMotors>("zoommotors").unwrap();
    let mut z = zm.read().value;
    z.zoom = 4.0;
    z.zoom_speed = 1.5;
    zm.publish(z).unwrap();
    eventually("1024", || emu.got("1024 4.00 1.50"));
    // Unused: the laser is unsubscribed.
    i.get_any("laser").unwrap().suspend();
    eventually("28", || emu.got("28"));
    // Terminate: zero speeds, then goodbye; images say 1000.
    rt.shutdown();
    eventually("goodbyes", || {
        emu.count("22 0.0 0.0") >= 2 && emu.got("0") && emu.got("1000")
    });
}

/// Issue 52: a `jderobot` process driving a 4.3 robot from its shell sends
/// `22 0.0 0.0` and `23 0.0 0.0` (through its estop handle on the motors
/// connection) when it gets SIGTERM or SIGTSTP, before it ends or suspends. The
/// time is when the test saw both lines at the server (polled every 2 ms: an
/// upper bound).
#[test]
fn ending_and_suspending_signals_send_motors_zero_within_100_ms() {
    for signal in common::process::STOP_SIGNALS {
        let emu = Server43::start(0, robot43());
        let dir = tempfile::tempdir().unwrap();
        let conf = dir.path().join("client.conf");
        std::fs::write(
            &conf,
            format!(
                "driver networkclient\nprovides motors 127.0.0.1 {}\nmotors_timeout 60000\n\
                 end_driver\nload_driver networkclient\n",
                emu.addr.port()
            ),
        )
        .unwrap();
        let mut p = common::process::Proc::start_alone(&conf);
        let driving = poll_until(20, || {
            p.send("set motors v=150 w=10");
            std::thread::sleep(Duration::from_millis(200));
            emu.got("22 150.0 0.0") && emu.got("23 10.0 0.0")
        });
        assert!(
            driving,
            "the robot never drove; jderobot said:\n{}",
            p.text()
        );
        let zeros = || (emu.count("22 0.0 0.0"), emu.count("23 0.0 0.0"));
        let before = zeros();
        common::process::signal_stops_within_100_ms(
            &mut p,
            "networkclient (22/23 zero)",
            signal,
            |_| {
                let now = zeros();
                (now.0 > before.0 && now.1 > before.1).then(std::time::Instant::now)
            },
        );
    }
}

#[test]
fn a_frame_of_the_wrong_size_is_an_error_naming_both_sizes() {
    // Network id 1 is 640x480, but colorA is 320x240 here.
    let emu = Server43::start(0, robot43());
    let rt = Runtime::new(std::path::Path::new("test.conf"));
    let h = format!("127.0.0.1 {}", emu.addr.port());
    load(
        &rt,
        Kind::Driver,
        "networkclient",
        &format!(
            "provides colorA {h} 1\nprovides varcolorB {h} 2 320 240\nprovides varcolorC {h} 2\n"
        ),
    )
    .unwrap();
    for n in ["colorA", "varcolorB", "varcolorC"] {
        rt.interfaces.get_any(n).unwrap().resume();
    }
    let a = rt.interfaces.get_any("colorA").unwrap();
    eventually("colorA stale with both sizes", || {
        a.stale()
            .is_some_and(|w| w.contains("640x480") && w.contains("320x240"))
    });
    let b = rt.interfaces.get_any("varcolorB").unwrap();
    eventually("varcolorB stale with both sizes", || {
        b.stale()
            .is_some_and(|w| w.contains("160x120") && w.contains("320x240"))
    });
    // varcolor without a size takes any size; the bad ones keep asking (no exit).
    let c = rt.interfaces.get::<Image>("varcolorC").unwrap();
    eventually("varcolorC any size", || c.read().width == 160);
    let n = emu.count("1019 1");
    eventually("colorA keeps asking", || emu.count("1019 1") > n + 3);
    assert_eq!(a.clock(), 0);
    rt.shutdown();
}

#[test]
fn the_client_reconnects_marks_stale_zeroes_motors_and_resubscribes() {
    let mut emu = Server43::start(0, robot43());
    let port = emu.addr.port();
    let rt = Runtime::new(std::path::Path::new("test.conf"));
    load(&rt, Kind::Driver, "networkclient", &client_conf(port, "")).unwrap();
    use_all(&rt);
    let i = &rt.interfaces;
    let laser = i.get_any("laser").unwrap();
    let motors = i.get::<Motors>("motors").unwrap();
    eventually("laser arrives", || laser.clock() > 2);
    motors.publish(Motors { v: 100.0, w: 0.0 }).unwrap();
    emu.shutdown();
    eventually("stale while the server is away", || {
        laser.stale().is_some_and(|w| w.contains(&port.to_string()))
    });
    for n in ["colorA", "encoders", "sonars", "pantiltencoders"] {
        eventually(n, || i.get_any(n).unwrap().stale().is_some());
    }
    eventually("motors zero", || {
        motors.read().value == Motors::default() && motors.stale().is_some()
    });
    // The server comes back on the same port.
    let emu2 = Server43::start(port, robot43());
    let c = laser.clock();
    assert!(
        poll_until(20, || laser.clock() > c + 2),
        "no laser after the server came back"
    );
    assert!(laser.stale().is_none());
    assert!(emu2.got("27") && emu2.got("11") && emu2.got("1019 0"));
    rt.shutdown();
}

#[test]
fn our_client_against_our_server_with_a_token() {
    let (srv, addr) = served("token 7f3a9c2e5b8d4f16a0c3e9b2d7f14a68\n");
    publish_all(&srv, 5);
    let h = format!("127.0.0.1 {}", addr.port());
    let good = Runtime::new(std::path::Path::new("test.conf"));
    load(
        &good,
        Kind::Driver,
        "networkclient",
        &format!(
            "token 7f3a9c2e5b8d4f16a0c3e9b2d7f14a68\nprovides varcolorB {h} 1\nprovides laser {h}\nprovides motors {h}\n\
             provides imu {h}\n"
        ),
    )
    .unwrap();
    let bad = Runtime::new(std::path::Path::new("test.conf"));
    load(
        &bad,
        Kind::Driver,
        "networkclient",
        &format!("token guess-guess-guess-guess\nprovides laser {h}\n"),
    )
    .unwrap();
    for rt in [&good, &bad] {
        rt.interfaces.get_any("laser").unwrap().resume();
    }
    good.interfaces.get_any("varcolorB").unwrap().resume();
    let img = good.interfaces.get::<Image>("varcolorB").unwrap();
    eventually("a 640x480 frame through our client", || {
        img.read().width == 640
    });
    let laser = good.interfaces.get::<Laser>("laser").unwrap();
    eventually("laser through our client", || {
        laser.read().readings.len() == 180
    });
    let imu = good.interfaces.get::<Imu>("imu").unwrap();
    imu.resume();
    eventually("the imu, exactly, through our client", || {
        imu.read().value == IMU
    });
    good.interfaces
        .get::<Motors>("motors")
        .unwrap()
        .publish(Motors { v: 80.0, w: 3.0 })
        .unwrap();
    let m = srv.interfaces.get::<Motors>("motors").unwrap();
    eventually("motors through our client", || {
        m.read().v == 80.0 && m.read().w == 3.0
    });
    // The wrong token: refused, so the laser stays stale and never arrives.
    let l = bad.interfaces.get_any("laser").unwrap();
    eventually("refused client stale", || l.stale().is_some());
    assert_eq!(l.clock(), 0);
    bad.shutdown();
    good.shutdown();
    eventually(
        "the server zeroes the motors when our client leaves",
        || m.read().value == Motors::default(),
    );
    srv.shutdown();
}

/// 4.3's wire says only 180° from −90°: a 360° scan (an RPLIDAR's) is resampled
/// by the server, so reading a at our client is the source's reading at a; a scan
/// narrower than the front half arrives with "nothing" (8000 mm, no return) where
/// it does not look (docs/network.md).
#[test]
fn a_360_scan_arrives_as_4_3_laser_with_each_angle_right() {
    let (srv, addr) = served("");
    let h = format!("127.0.0.1 {}", addr.port());
    let cli = Runtime::new(std::path::Path::new("test.conf"));
    load(
        &cli,
        Kind::Driver,
        "networkclient",
        &format!("provides laser {h}\n"),
    )
    .unwrap();
    let got = cli.interfaces.get::<Laser>("laser").unwrap();
    got.resume();
    let src = srv.interfaces.get::<Laser>("laser").unwrap();
    // 360 readings at 1° from −180°, 12 m, each reading its own.
    let round = Laser {
        readings: (0..360).map(|i| 1000 + 7 * i).collect(),
        resolution: 1.0,
        start: -180.0,
        min_range: 150.0,
        max_range: 12000.0,
        ..Laser::default()
    };
    src.publish(round.clone()).unwrap();
    eventually("the 360° scan at our client", || {
        got.read().readings.first() == Some(&(1000 + 7 * 90))
    });
    let l = got.read().value.clone();
    assert_eq!((l.readings.len(), l.start, l.resolution), (180, -90.0, 1.0));
    for i in 0..180 {
        let a = l.angle(i);
        let want = round.readings[round.index_at(a).unwrap()];
        assert_eq!(l.readings[i], want, "reading {i} at {a}°");
    }
    // 90° from −45°, 5.6 m, a no-return straight ahead: outside the scan and
    // at the no-return, "nothing" (8000 mm, which the client's laser does not
    // count as a return).
    let mut narrow = Laser {
        readings: (0..90).map(|i| 2000 + i).collect(),
        start: -45.0,
        max_range: 5600.0,
        ..Laser::default()
    };
    narrow.readings[45] = 5600;
    src.publish(narrow.clone()).unwrap();
    eventually("the 90° scan at our client", || {
        got.read().readings.get(45) == Some(&2000)
    });
    let l = got.read().value.clone();
    assert_eq!(l.readings.len(), 180);
    for i in 0..180 {
        let a = l.angle(i);
        match narrow.index_at(a) {
            Some(k) if narrow.is_return(narrow.readings[k]) => {
                assert_eq!(l.readings[i], narrow.readings[k], "reading {i} at {a}°");
                assert!(l.is_return(l.readings[i]));
            }
            _ => {
                assert_eq!(l.readings[i], 8000, "reading {i} at {a}°");
                assert!(!l.is_return(l.readings[i]), "nothing at {a}°");
            }
        }
    }
    cli.shutdown();
    srv.shutdown();
}

#[test]
fn our_client_drops_an_absurd_pose_from_a_server() {
    use std::io::{BufRead, BufReader, Read, Write};
    // A server of its own: it sends an encoders line with x = 1e38, then a good one.
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let server = std::thread::spawn(move || {
        let (s, _) = listener.accept().unwrap();
        let mut name = [0u8; 20];
        (&s).read_exact(&mut name).unwrap();
        let mut r = BufReader::new(&s);
        let mut line = String::new();
        // The subscription to encoders (`11`).
        while r.read_line(&mut line).unwrap() > 0 && !line.starts_with("11") {
            line.clear();
        }
        (&s).write_all(b"10 1 1e38 0.0 0.00000 1\n10 2 100.0 0.0 0.00000 2\n")
            .unwrap();
        std::thread::sleep(Duration::from_millis(500));
    });
    let rt = Runtime::new(std::path::Path::new("test.conf"));
    let h = format!("127.0.0.1 {port}");
    load(
        &rt,
        Kind::Driver,
        "networkclient",
        &format!("provides encoders {h}\n"),
    )
    .unwrap();
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let count = Arc::new(Count::default());
    enc.watch(count.clone());
    enc.resume();
    eventually("the good pose", || enc.read().x == 100.0);
    // Watchers are told right after the value is stored: wait for the notice.
    eventually("the good pose's notice", || {
        count.0.load(std::sync::atomic::Ordering::Acquire) >= 1
    });
    std::thread::sleep(Duration::from_millis(50));
    assert_eq!(
        count.0.load(std::sync::atomic::Ordering::Acquire),
        1,
        "only the good pose was published"
    );
    server.join().unwrap();
    rt.shutdown();
}

/// Counts the values published on an interface.
#[derive(Default)]
struct Count(std::sync::atomic::AtomicUsize);

impl jderobot::interfaces::Notify for Count {
    fn notify(&self) {
        self.0.fetch_add(1, std::sync::atomic::Ordering::AcqRel);
    }
}

/// A 4.3 server by hand, for one image connection: it takes the 20-byte name,
/// then answers each `1019 0` with frame k = 1..=`frames` (every pixel byte k),
/// its header at once and its pixels in `pieces` pieces `gap` apart (a slow
/// link). Returns its port and when each frame's last byte was written.
fn trickling_server(
    (w, h): (u32, u32),
    frames: u8,
    pieces: usize,
    gap: Duration,
) -> (u16, std::sync::mpsc::Receiver<std::time::Instant>) {
    use std::io::{BufRead, BufReader, Read, Write};
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    let (last_byte, sent) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let (mut out, _) = l.accept().unwrap();
        let mut r = BufReader::new(out.try_clone().unwrap());
        r.read_exact(&mut [0u8; 20]).unwrap();
        let bytes = (w * h * 3) as usize;
        for k in 1..=frames {
            let mut line = String::new();
            r.read_line(&mut line).unwrap();
            assert_eq!(line, "1019 0\n");
            out.write_all(format!("1020 {k} 0 {w} {h} 3\n").as_bytes())
                .unwrap();
            for piece in vec![k; bytes].chunks(bytes.div_ceil(pieces)) {
                std::thread::sleep(gap);
                if out.write_all(piece).is_err() {
                    return; // the client hung up: `sent` closes
                }
            }
            let _ = last_byte.send(std::time::Instant::now());
        }
        let _ = r.read_line(&mut String::new());
    });
    (port, sent)
}

/// Our client on `varcolorA` of size `w h` from a server on `port`.
fn image_client(port: u16, (w, h): (u32, u32)) -> (Arc<Runtime>, Arc<Interface<Image>>) {
    let rt = Runtime::new(std::path::Path::new("test.conf"));
    load(
        &rt,
        Kind::Driver,
        "networkclient",
        &format!("provides varcolorA 127.0.0.1 {port} 0 {w} {h}\n"),
    )
    .unwrap();
    let img = rt.interfaces.get::<Image>("varcolorA").unwrap();
    img.resume();
    (rt, img)
}

/// Whether the interface holds frame k whole.
fn whole(img: &Interface<Image>, (w, h): (u32, u32), k: u8) -> bool {
    let f = img.read();
    f.data.len() == (w * h * 3) as usize && f.data.iter().all(|&b| b == k)
}

/// A frame that comes in pieces is published whole as soon as its last byte is
/// in. The client waits for a frame's bytes with the socket's low-water mark
/// (`SO_RCVLOWAT`), which must not hold a read that has copied part of the frame:
/// the kernel would then wake it only at its read timeout (50 ms).
#[test]
fn a_frame_arriving_in_pieces_is_published_when_its_last_byte_is_in() {
    const FRAMES: u8 = 5;
    let size = (640, 480);
    let (port, sent) = trickling_server(size, FRAMES, 3, Duration::from_millis(80));
    let (rt, img) = image_client(port, size);
    let mut late = Vec::new();
    let mut clock = img.clock();
    for k in 1..=FRAMES {
        let t_sent = sent
            .recv_timeout(Duration::from_secs(20))
            .expect("the client hung up before the frame's last byte");
        assert!(
            poll_until(20, || img.clock() != clock),
            "frame {k} never published"
        );
        late.push(std::time::Instant::now().saturating_duration_since(t_sent));
        clock = img.clock();
        assert!(whole(&img, size, k), "frame {k} is not whole");
    }
    late.sort();
    assert!(
        late[late.len() / 2] < Duration::from_millis(15),
        "frames published long after their last byte: {late:?}"
    );
    rt.shutdown();
}

/// A slow link that keeps delivering may take longer for a frame than the
/// client's stall limit (10 s without a byte): the frame still arrives. Until
/// 2026-11-28 the limit ran from the first read timeout, so a frame slower than
/// 10 s in all was given up, and on such a link every frame.
#[test]
fn a_frame_slower_than_the_stall_limit_but_never_stalled_arrives() {
    let size = (160, 120);
    let (port, sent) = trickling_server(size, 1, 105, Duration::from_millis(100));
    let (rt, img) = image_client(port, size);
    sent.recv_timeout(Duration::from_secs(30))
        .expect("the client hung up before the frame's last byte");
    assert!(
        poll_until(5, || whole(&img, size, 1)),
        "the frame never arrived whole ({})",
        img.stale().unwrap_or_default()
    );
    rt.shutdown();
}

/// A server that sends a byte every 20 ms never lets the client's read time
/// out (50 ms), so only a deadline on the whole frame ends it: a frame must come
/// at 4 KB/s or faster, and any frame may take 10 s. Until 2026-11-28 this server
/// held the client's image connection for as long as it liked.
#[test]
fn a_server_trickling_a_frame_is_dropped_at_the_frame_deadline() {
    let size = (16, 16);
    let (port, _sent) = trickling_server(size, 1, 768, Duration::from_millis(20));
    let t0 = std::time::Instant::now();
    let (rt, img) = image_client(port, size);
    assert!(
        poll_until(20, || img
            .stale()
            .is_some_and(|why| why.contains("slower than 4 KB/s"))),
        "the trickle was not dropped ({:?})",
        img.stale()
    );
    let after = t0.elapsed();
    assert!(
        after < Duration::from_secs(14),
        "dropped after {after:?}, the deadline is 10 s"
    );
    assert_eq!(img.clock(), 0, "the trickled frame was published");
    rt.shutdown();
}
