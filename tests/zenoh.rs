//! jderobot over Zenoh on loopback: a robot process (simulator + `zenoh`
//! publishing), a controller (introrob on `zenoh`-provided interfaces) in another
//! process or in this one, and a raw Zenoh session of the test's own that writes
//! what a foreign program could (garbage included).
#![cfg(all(feature = "zenoh", feature = "simulator", feature = "introrob"))]

use crate::common;

use std::{
    path::Path,
    time::{Duration, Instant},
};

use common::process::{Proc, free_port, number_after};
use jderobot::interfaces::{Encoders, Imu, Laser, Motors, Notify, PtMotors};
use zenoh::Wait;

fn robot_conf(dir: &Path, port: u16, extra: &str) -> std::path::PathBuf {
    let world = common::world_path("simple.world");
    let conf = dir.join("robot.conf");
    std::fs::write(
        &conf,
        format!(
            "driver simulator\nworld {world}\nrobot robot1 1000 1000 90\nprovides encoders\n\
             provides motors\nprovides laser 180 1\nprovides sonars\nprovides colorA\n\
             provides pantiltencoders\nprovides pantiltmotors\nprovides imu\nend_driver\n\
             service zenoh\nrobot pioneer\npublishes all\nlisten tcp/127.0.0.1:{port}\n\
             scouting off\n{extra}end_service\n\
             load_driver simulator\nload_service zenoh\n"
        ),
    )
    .unwrap();
    conf
}

/// The robot process (`robot_conf`), once its simulator publishes.
fn robot(dir: &Path, port: u16, extra: &str) -> Proc {
    let mut robot = Proc::start(&robot_conf(dir, port, extra));
    robot.ask_until("echo laser", "the simulator", |l| {
        l.starts_with("laser clock=")
    });
    robot
}

fn echo_v(line: &str) -> f64 {
    number_after(line, " v=")
}

/// A plain Zenoh session of the test's own, connected to the robot.
fn raw_session(port: u16) -> zenoh::Session {
    let mut config = zenoh::Config::default();
    config
        .insert_json5("connect/endpoints", &format!(r#"["tcp/127.0.0.1:{port}"]"#))
        .unwrap();
    config
        .insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    config.insert_json5("listen/endpoints", "[]").unwrap();
    zenoh::open(config).wait().unwrap()
}

#[test]
fn introrob_in_one_process_drives_the_simulator_in_another() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let world = common::world_path("simple.world");
    let mut robot = Proc::start(&robot_conf(dir.path(), port, ""));
    let start = robot.ask_until("echo encoders", "the robot's pose", |l| {
        l.starts_with("encoders clock=")
    });
    let gui_conf = dir.path().join("gui.conf");
    std::fs::write(
        &gui_conf,
        format!(
            "driver zenoh\nrobot pioneer\nprovides laser\nprovides encoders\nprovides motors\n\
             provides colorA\nprovides sonars\nconnect tcp/127.0.0.1:{port}\nscouting off\nend_driver\n\
             schema introrob\nbehaviour vff\ntarget 5000 2200\nmax_v 400\nworld {world}\nend_schema\n\
             load_driver zenoh\nload_schema introrob\nrun introrob\n"
        ),
    )
    .unwrap();
    let mut gui = Proc::start(&gui_conf);
    gui.send("run colorA");
    gui.send("run sonars");
    gui.expect_arriving(&["laser", "colorA", "encoders", "sonars"], "zenoh");
    robot.expect_moved(&start, 150.0);
    robot.ask_until("echo motors", "introrob's command", |l| {
        l.starts_with("motors clock=") && echo_v(l) > 0.0
    });
    // The controller is killed: its writer token goes, the robot's motors are
    // zeroed at once (motors_timeout would do it within 500 ms anyway).
    let t = Instant::now();
    let _ = gui.child.kill();
    let _ = gui.child.wait();
    robot.ask_until("echo motors", "motors zero", |l| {
        l.starts_with("motors clock=") && echo_v(l) == 0.0
    });
    eprintln!(
        "motors zero {:?} after the controller was killed",
        t.elapsed()
    );
    assert!(
        robot.text().contains("the last writer of `motors` left"),
        "{}",
        robot.text()
    );
    robot.quit();
}

#[test]
fn a_killed_robot_is_stale_within_a_second_and_comes_back_by_itself() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let conf = robot_conf(dir.path(), port, "");
    let mut robot = Proc::start(&conf);
    robot.ask_until("echo laser", "the simulator", |l| {
        l.starts_with("laser clock=")
    });
    let rt = common::start_conf(&format!(
        "driver zenoh\nrobot pioneer\nprovides laser\nprovides motors\n\
         connect tcp/127.0.0.1:{port}\nscouting off\nend_driver\nload_driver zenoh\n"
    ));
    let laser = rt.interfaces.get::<Laser>("laser").unwrap();
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    laser.resume();
    common::eventually("laser samples", || {
        laser.stale().is_none() && laser.read().readings.len() == 180
    });
    motors.publish(Motors { v: 100.0, w: 0.0 }).unwrap();

    let _ = robot.child.kill();
    let t = Instant::now();
    assert!(
        common::poll_until(10, || laser.stale().is_some()),
        "laser never went stale"
    );
    let took = t.elapsed();
    eprintln!(
        "stale {took:?} after kill -9 of the robot: {:?}",
        laser.stale()
    );
    assert!(took < Duration::from_secs(1), "stale after {took:?}");
    assert!(
        laser.stale().unwrap().contains("gone"),
        "{:?}",
        laser.stale()
    );
    // Each interface has its own presence watch: motors follows on its own.
    common::eventually("motors zeroed", || motors.read().value == Motors::default());

    // A new robot process on the same port: samples flow again without help.
    let mut robot = Proc::start(&conf);
    common::eventually("laser fresh again", || {
        laser.stale().is_none() && laser.read().stamp.elapsed() < Duration::from_millis(500)
    });
    robot.send("echo laser");
    robot.quit();
    rt.shutdown();
}

#[test]
fn garbage_on_a_subscribed_key_is_dropped_with_one_line_and_a_good_command_drives() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let mut robot = robot(dir.path(), port, "");
    let session = raw_session(port);
    let key = "jderobot/pioneer/motors";
    common::eventually("the robot's motors subscriber", || {
        session
            .declare_publisher(key)
            .wait()
            .unwrap()
            .matching_status()
            .wait()
            .unwrap()
            .matching()
    });
    for bad in [
        &b""[..],
        b"\x01\x02\x03",
        &[0xff; 9],
        &f32::NAN.to_le_bytes().repeat(2),
    ] {
        session.put(key, bad).wait().unwrap();
    }
    // A good command: v = 250 mm/s, w = 0 (two little-endian f32).
    let good: Vec<u8> = [250f32, 0.0].iter().flat_map(|f| f.to_le_bytes()).collect();
    robot.ask_until("echo motors", "the good command", |l| {
        session.put(key, good.clone()).wait().unwrap();
        l.starts_with("motors clock=") && echo_v(l) == 250.0
    });
    let log = robot.text();
    assert_eq!(
        log.matches("zenoh: `jderobot/pioneer/motors` (for `motors`): dropped a value")
            .count(),
        1,
        "one line for the garbage:\n{log}"
    );
    robot.quit();
}

#[test]
fn a_zenoh_config_file_passes_access_control_through() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    // Zenoh's own ACL: nobody on loopback may put on the robot's motors.
    std::fs::write(
        dir.path().join("acl.json5"),
        r#"{ access_control: { enabled: true, default_permission: "allow",
             rules: [{ id: "no-motors", permission: "deny", flows: ["ingress"],
                       messages: ["put"], key_exprs: ["jderobot/pioneer/motors"] }],
             subjects: [{ id: "loopback", interfaces: ["lo"] }],
             policies: [{ rules: ["no-motors"], subjects: ["loopback"] }] } }"#,
    )
    .unwrap();
    let mut robot = robot(dir.path(), port, "config acl.json5\n");
    let session = raw_session(port);
    // Data still flows out...
    let laser = session
        .declare_subscriber("jderobot/pioneer/laser")
        .wait()
        .unwrap();
    assert!(
        laser
            .recv_timeout(Duration::from_secs(20))
            .unwrap()
            .is_some(),
        "laser samples under the ACL"
    );
    // ...but commands are refused by Zenoh before they reach jderobot.
    let good: Vec<u8> = [250f32, 0.0].iter().flat_map(|f| f.to_le_bytes()).collect();
    for _ in 0..20 {
        session
            .put("jderobot/pioneer/motors", good.clone())
            .wait()
            .unwrap();
        std::thread::sleep(Duration::from_millis(50));
    }
    let l = robot.ask_until("echo motors", "motors", |l| l.starts_with("motors clock="));
    assert_eq!(echo_v(&l), 0.0, "the ACL let a command through: {l}");
    robot.quit();
}

#[test]
fn provides_all_takes_what_the_robot_serves_and_says_what_to_do_without_it() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let robot = robot(dir.path(), port, "");
    let rt = common::start_conf(&format!(
        "driver zenoh\nprovides all pioneer\nconnect tcp/127.0.0.1:{port}\nscouting off\n\
         end_driver\nload_driver zenoh\n"
    ));
    let mut names = rt.interfaces.names();
    names.sort();
    assert_eq!(
        names,
        [
            "colorA",
            "encoders",
            "imu",
            "laser",
            "motors",
            "pantiltencoders",
            "pantiltmotors",
            "sonars"
        ]
    );
    let enc = rt.interfaces.get_any("encoders").unwrap();
    enc.resume();
    common::eventually("encoders", || enc.clock() > 0 && enc.stale().is_none());
    assert_heading_90(&rt.interfaces.get::<Imu>("imu").unwrap());
    rt.shutdown();
    robot.quit();

    // No robot: the start fails and says how to start without it.
    let conf = jderobot::Conf::parse(
        &format!(
            "driver zenoh\nprovides all pioneer\ndiscover 300\nconnect tcp/127.0.0.1:{port}\n\
             scouting off\nend_driver\nload_driver zenoh\n"
        ),
        Path::new("gui.conf"),
    )
    .unwrap();
    let e = jderobot::loader::start(&conf)
        .err()
        .expect("no robot")
        .to_string();
    assert!(
        e.contains("robot `pioneer`") && e.contains("provides NAME"),
        "{e}"
    );
}

/// The simulated robot1 (heading 90°, standing) as its imu reads it.
fn assert_heading_90(imu: &jderobot::interfaces::Interface<Imu>) {
    imu.resume();
    common::eventually("imu", || imu.clock() > 0);
    let v = imu.read();
    let half = std::f32::consts::FRAC_PI_4;
    assert!(
        (v.qz - half.sin()).abs() < 1e-3 && (v.qw - half.cos()).abs() < 1e-3,
        "{v:?}"
    );
    assert!((v.az - 9.80665).abs() < 1e-4 && v.wz == 0.0, "{v:?}");
}

#[test]
fn imu_travels_as_a_ros2_sensor_msgs_imu_too() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let mut robot = Proc::start(&robot_conf(dir.path(), port, "format ros2\n"));
    robot.ask_until("echo imu", "the simulator", |l| l.starts_with("imu clock="));
    let rt = common::start_conf(&format!(
        "driver zenoh\nrobot pioneer\nprovides imu\nformat ros2\nconnect tcp/127.0.0.1:{port}\n\
         scouting off\nend_driver\nload_driver zenoh\n"
    ));
    assert_heading_90(&rt.interfaces.get::<Imu>("imu").unwrap());
    rt.shutdown();
    robot.quit();
}

#[test]
fn a_command_written_before_the_robot_came_reaches_it_when_it_does() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let rt = common::start_conf(&format!(
        "driver zenoh\nrobot pioneer\nprovides pantiltmotors\nlisten tcp/127.0.0.1:{port}\n\
         scouting off\nend_driver\nload_driver zenoh\n"
    ));
    let ptm = rt.interfaces.get::<PtMotors>("pantiltmotors").unwrap();
    assert!(
        ptm.stale().unwrap().contains("waiting"),
        "{:?}",
        ptm.stale()
    );
    // A position command, written once while nobody serves it.
    ptm.publish(PtMotors {
        longitude: 30.0,
        latitude: -10.0,
        longitude_speed: 50.0,
        latitude_speed: 50.0,
        max_longitude: 159.0,
        min_longitude: -159.0,
        max_latitude: 31.0,
        min_latitude: -47.0,
        max_longitude_speed: 100.0,
        max_latitude_speed: 100.0,
    })
    .unwrap();
    // The robot comes later, connecting to this side.
    let conf = robot_conf(dir.path(), free_port(), "")
        .to_string_lossy()
        .into_owned();
    let text = std::fs::read_to_string(&conf).unwrap().replace(
        "listen tcp/127.0.0.1:",
        &format!("connect tcp/127.0.0.1:{port}\n# was "),
    );
    std::fs::write(&conf, text).unwrap();
    let mut robot = Proc::start(Path::new(&conf));
    robot.ask_until("echo pantiltmotors", "the command", |l| {
        l.starts_with("pantiltmotors clock=") && l.contains("longitude=30.00 deg")
    });
    common::eventually("the robot seen", || ptm.stale().is_none());
    robot.quit();
    rt.shutdown();
}

/// Issue 52: a `jderobot` process driving a robot's `motors` over Zenoh from its
/// shell puts a zero command (its estop stop, straight on the session) when it
/// gets SIGTERM or SIGTSTP, before it ends or suspends. The robot is the test's
/// own session, which times each sample as it arrives.
#[test]
fn ending_and_suspending_signals_put_motors_zero_within_100_ms() {
    for signal in common::process::STOP_SIGNALS {
        let dir = tempfile::tempdir().unwrap();
        let port = free_port();
        let conf = dir.path().join("controller.conf");
        std::fs::write(
            &conf,
            format!(
                "driver zenoh\nrobot pioneer\nprovides motors\nlisten tcp/127.0.0.1:{port}\n\
                 scouting off\nend_driver\nload_driver zenoh\n"
            ),
        )
        .unwrap();
        let mut p = Proc::start_alone(&conf);
        let session = raw_session(port);
        let samples = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let _sub = {
            let samples = samples.clone();
            session
                .declare_subscriber("jderobot/pioneer/motors")
                .callback(move |s| {
                    let b = s.payload().to_bytes().into_owned();
                    samples.lock().unwrap().push((Instant::now(), b));
                })
                .wait()
                .unwrap()
        };
        let driving = common::poll_until(20, || {
            p.send("set motors v=150 w=10");
            std::thread::sleep(Duration::from_millis(200));
            let drive = floats(&[150.0, 10.0]);
            samples.lock().unwrap().iter().any(|s| s.1 == drive)
        });
        assert!(
            driving,
            "the robot never drove; jderobot said:\n{}",
            p.text()
        );
        common::process::signal_stops_within_100_ms(&mut p, "zenoh (motors zero)", signal, |t0| {
            let zero = floats(&[0.0, 0.0]);
            let s = samples.lock().unwrap();
            s.iter().find(|s| s.0 >= t0 && s.1 == zero).map(|s| s.0)
        });
    }
}

fn floats(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|f| f.to_le_bytes()).collect()
}

/// Waits until `key` has a subscriber (the other side's).
fn await_subscriber(session: &zenoh::Session, key: &str) {
    let publisher = session.declare_publisher(key.to_string()).wait().unwrap();
    common::eventually(&format!("a subscriber of {key}"), || {
        publisher.matching_status().wait().unwrap().matching()
    });
}

#[test]
fn nan_and_inf_commands_are_dropped_and_the_last_good_one_stays() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let mut robot = robot(dir.path(), port, "");
    let session = raw_session(port);
    let (motors, ptmotors) = ("jderobot/pioneer/motors", "jderobot/pioneer/pantiltmotors");
    await_subscriber(&session, motors);
    await_subscriber(&session, ptmotors);
    robot.ask_until("echo motors", "the good command", |l| {
        session.put(motors, floats(&[250.0, 0.0])).wait().unwrap();
        l.starts_with("motors clock=") && echo_v(l) == 250.0
    });
    session
        .put(motors, floats(&[f32::NAN, f32::INFINITY]))
        .wait()
        .unwrap();
    let mut pt = [
        10.0, 5.0, 50.0, 50.0, 159.0, -159.0, 31.0, -47.0, 100.0, 100.0,
    ];
    pt[0] = f32::NAN;
    session.put(ptmotors, floats(&pt)).wait().unwrap();
    common::eventually("both refusals logged", || {
        let log = robot.text();
        log.contains("zenoh: `jderobot/pioneer/motors` (for `motors`): dropped a value")
            && log.contains(
                "zenoh: `jderobot/pioneer/pantiltmotors` (for `pantiltmotors`): dropped a value",
            )
    });
    let m = robot.ask_until("echo motors", "motors", |l| l.starts_with("motors clock="));
    assert!(echo_v(&m) == 250.0, "the last good command stays: {m}");
    let p = robot.ask_until("echo pantiltmotors", "pantiltmotors", |l| {
        l.starts_with("pantiltmotors clock=")
    });
    assert!(!p.contains("NaN") && !p.contains("inf"), "{p}");
    robot.quit();
}

/// Counts the values published on an interface.
#[derive(Default)]
struct Count(std::sync::atomic::AtomicUsize);

impl Notify for Count {
    fn notify(&self) {
        self.0.fetch_add(1, std::sync::atomic::Ordering::AcqRel);
    }
}

#[test]
fn a_controller_drops_nan_and_absurd_encoders_and_its_clock_only_grows() {
    let port = free_port();
    let rt = common::start_conf(&format!(
        "driver zenoh\nrobot pioneer\nprovides encoders\nlisten tcp/127.0.0.1:{port}\n\
         scouting off\nend_driver\nload_driver zenoh\n"
    ));
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let count = std::sync::Arc::new(Count::default());
    enc.watch(count.clone());
    rt.run("encoders").unwrap();
    let session = raw_session(port);
    let key = "jderobot/pioneer/encoders";
    await_subscriber(&session, key);
    let put = |v: &[f32], clock: u64| {
        let mut a = clock.to_le_bytes().to_vec();
        a.extend_from_slice(&0u64.to_le_bytes());
        session.put(key, floats(v)).attachment(a).wait().unwrap();
    };
    let (c, s) = (1f32.cos(), 1f32.sin());
    put(&[f32::NAN, 0.0, 1.0, c, s], 1);
    put(&[1e38, 0.0, 1.0, c, s], 2);
    put(&[1000.0, 2000.0, 1.0, c, s], 3);
    common::eventually("the good value", || enc.clock() == 3);
    assert_eq!(enc.read().x, 1000.0);
    assert_eq!(
        count.0.load(std::sync::atomic::Ordering::Acquire),
        1,
        "only the good value was published"
    );
    // A sender's absurd clock does not become the interface's (it would wrap).
    put(&[1100.0, 2000.0, 1.0, c, s], u64::MAX);
    common::eventually("the next value", || enc.read().x == 1100.0);
    assert_eq!(enc.clock(), 4, "the next local clock");
    put(&[1200.0, 2000.0, 1.0, c, s], 2);
    common::eventually("a value with an older clock", || enc.read().x == 1200.0);
    assert_eq!(enc.clock(), 5, "the clock only grows");
    rt.shutdown();
}

/// How long a client with a valid certificate may take to get a session and a
/// laser sample, while 1,100 silent connections are open or just after they
/// closed (docs/zenoh.md, "TLS").
const ADMISSION_BOUND: Duration = Duration::from_secs(15);

/// Issue 52: the zenoh service on mutual TLS, in a process limited to 1024
/// descriptors, takes 1,100 TCP connections that never say a word. A client
/// with the `operator` certificate still gets a session and reads the laser
/// within [`ADMISSION_BOUND`] while they are open, and again after they closed;
/// the service stays up. Without vendor/tls-listener's patches 0002 and 0003 the
/// silent connections take every descriptor and the operator never gets in.
#[test]
fn zenoh_tls_with_1100_silent_connections_and_the_operator_admitted() {
    use std::os::unix::process::CommandExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    common::certs::ca(d, "ca");
    for who in ["robot", "operator"] {
        common::certs::signed(d, who, "ca");
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
    let mut c = common::jderobot([Path::new("--headless"), &conf]);
    // SAFETY: only setrlimit, async-signal-safe, between fork and exec.
    unsafe {
        c.pre_exec(|| {
            let lim = libc::rlimit {
                rlim_cur: 1024,
                rlim_max: 1024,
            };
            match libc::setrlimit(libc::RLIMIT_NOFILE, &lim) {
                0 => Ok(()),
                _ => Err(std::io::Error::last_os_error()),
            }
        });
    }
    let mut robot = Proc::spawn(c);
    robot.ask_until("echo laser", "the simulator", |l| {
        l.starts_with("laser clock=")
    });
    let first = operator_reads(d, port).expect("the operator, before any silent connection");
    eprintln!("admitted with no silent connection: {first:?}");

    let addr = std::net::SocketAddr::from(([127, 0, 0, 1], port));
    let (mut silent, mut failed) = (Vec::new(), 0);
    for _ in 0..1100 {
        match std::net::TcpStream::connect_timeout(&addr, Duration::from_millis(200)) {
            Ok(s) => silent.push(s),
            Err(_) => failed += 1,
        }
    }
    let open = Instant::now();
    let during = operator_reads(d, port);
    let closed_by_service = silent.iter().filter(|s| peer_closed(s)).count();
    eprintln!(
        "silent connections: {} made, {failed} failed; the operator admitted {during:?} \
         after them; {closed_by_service} closed by the service after {:?}",
        silent.len(),
        open.elapsed()
    );
    drop(silent);
    let after = operator_reads(d, port);
    eprintln!("the operator admitted {after:?} after they closed");
    let alive = robot.child.try_wait().unwrap().is_none();
    let text = robot.text();
    let tail: Vec<&str> = text.lines().rev().take(20).collect();
    assert!(
        during.is_some() && after.is_some() && alive,
        "the operator must get in within {ADMISSION_BOUND:?} (during: {during:?}, after: \
         {after:?}); service alive: {alive}; its last lines:\n{}",
        tail.join("\n")
    );
    robot.ask_until("echo laser", "the robot after all", |l| {
        l.starts_with("laser clock=")
    });
    robot.quit();
}

/// Whether the peer closed `s` (a read gives end of file at once).
fn peer_closed(s: &std::net::TcpStream) -> bool {
    use std::io::Read;
    s.set_nonblocking(true).unwrap();
    matches!((&*s).read(&mut [0]), Ok(0))
}

/// The time a client with the `operator` certificate of `dir` took to open a
/// session over TLS and read one laser sample, trying again until
/// [`ADMISSION_BOUND`]; `None` if it did not within it.
fn operator_reads(dir: &Path, port: u16) -> Option<Duration> {
    let mut config = zenoh::Config::default();
    let file = |f: &str| format!("{:?}", dir.join(f).display().to_string());
    let tls = "transport/link/tls";
    for (key, value) in [
        ("mode", r#""client""#.to_string()),
        ("connect/endpoints", format!(r#"["tls/127.0.0.1:{port}"]"#)),
        ("listen/endpoints", "[]".into()),
        ("scouting/multicast/enabled", "false".into()),
        (&*format!("{tls}/root_ca_certificate"), file("ca.pem")),
        (&*format!("{tls}/connect_certificate"), file("operator.pem")),
        (&*format!("{tls}/connect_private_key"), file("operator.key")),
        (&*format!("{tls}/enable_mtls"), "true".into()),
    ] {
        config.insert_json5(key, &value).unwrap();
    }
    let t0 = Instant::now();
    let (tx, rx) = std::sync::mpsc::channel();
    // In a thread: a handshake the service never answers must not hang the test.
    std::thread::spawn(move || {
        while t0.elapsed() < ADMISSION_BOUND {
            let Ok(s) = zenoh::open(config.clone()).wait() else {
                std::thread::sleep(Duration::from_millis(200));
                continue;
            };
            let sub = s
                .declare_subscriber("jderobot/pioneer/laser")
                .wait()
                .unwrap();
            if let Ok(Some(_)) = sub.recv_timeout(ADMISSION_BOUND.saturating_sub(t0.elapsed())) {
                let _ = tx.send(t0.elapsed());
            }
            let _ = s.close().wait();
            return;
        }
    });
    rx.recv_timeout(ADMISSION_BOUND + Duration::from_secs(1))
        .ok()
}
