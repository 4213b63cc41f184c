//! Hostile peers against the gazebo and naobody drivers (issue 38), each on the
//! real path: the real gz-transport peer (`tests/gazebo/peer.cc` on Debian's
//! libignition-transport11) or the NAOqi stand-in on the real libqi
//! (`tests/emulators/naoqi.py`), plus a hostile node written here from the
//! documented wires, on loopback (each gazebo test in its own partition; the
//! discovery flood in a private network namespace of its own, `unshare -rn`):
//!
//! - gz-transport discovery: UDP multicast 239.255.0.7:10317, a 2-byte
//!   little-endian length and a `Discovery` protobuf (gz-transport 11's
//!   `ign_transport/msgs/discovery.proto`: 2 version, 3 process_uuid, 4 type
//!   (1 ADVERTISE .. 7 END_CONNECTION), 6 sub {1 topic}, 7 pub {1 topic, 2
//!   address, 3 process_uuid, 4 node_uuid, 5 scope, 6 msg_pub {1 ctrl, 2
//!   msg_type}}), wire version 10;
//! - ZMTP 3.0 (rfc.zeromq.org/spec/23): the 64-byte greeting, the READY command,
//!   frames (flags bit 0 MORE, bit 1 LONG: a u64 big-endian size); a gz message
//!   is the frames [topic, address, data, type name];
//! - gz-msgs 8's `.proto` field numbers for LaserScan, Odometry and Image;
//! - libqi's messaging (the 28-byte header, magic 42 de ad 42; the
//!   ServiceDirectory's `service` (action 100), `metaObject` (action 2),
//!   `authenticate` (service 0, action 8)), for a hostile NAOqi.
//!
//! Each test asserts what must hold during the attack: the stop reaches the
//! robot within `motors_timeout` plus one cycle (with a stated scheduling
//! margin), memory stays under a stated bound, and the good peer is bound again.
#![cfg(all(feature = "gazebo", feature = "naobody"))]

use crate::{common, gazebo, naobody};

use std::{
    io::{BufRead, BufReader, Read, Write},
    net::{Ipv4Addr, SocketAddr, TcpListener, TcpStream, UdpSocket},
    process::Stdio,
    sync::{
        Arc, Mutex,
        atomic::{AtomicBool, AtomicUsize, Ordering},
    },
    time::{Duration, Instant},
};

use common::{eventually, poll_until, process::free_port, start_conf};
use jderobot::interfaces::{Encoders, Image, Interface, Laser, Motors, PtMotors, Sonars};

// ------------------------------------------------------------ protobuf by hand

fn varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push(v as u8 | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn uint(out: &mut Vec<u8>, field: u64, v: u64) {
    varint(out, field << 3);
    varint(out, v);
}

fn bytes(out: &mut Vec<u8>, field: u64, b: &[u8]) {
    varint(out, field << 3 | 2);
    varint(out, b.len() as u64);
    out.extend_from_slice(b);
}

fn double(out: &mut Vec<u8>, field: u64, v: f64) {
    varint(out, field << 3 | 1);
    out.extend_from_slice(&v.to_le_bytes());
}

/// A discovery packet (length prefix included).
#[allow(clippy::too_many_arguments)]
fn discovery(
    kind: u64,
    process: &str,
    sub: Option<&str>,
    publ: Option<(&str, &str, &str, &str, &str)>,
) -> Vec<u8> {
    let mut m = Vec::new();
    uint(&mut m, 2, 10);
    bytes(&mut m, 3, process.as_bytes());
    uint(&mut m, 4, kind);
    if let Some(t) = sub {
        let mut s = Vec::new();
        bytes(&mut s, 1, t.as_bytes());
        bytes(&mut m, 6, &s);
    }
    // (topic, address, node uuid, ctrl, msg type)
    if let Some((topic, addr, node, ctrl, ty)) = publ {
        let mut p = Vec::new();
        bytes(&mut p, 1, topic.as_bytes());
        bytes(&mut p, 2, addr.as_bytes());
        bytes(&mut p, 3, process.as_bytes());
        bytes(&mut p, 4, node.as_bytes());
        uint(&mut p, 5, 2);
        let mut mp = Vec::new();
        bytes(&mut mp, 1, ctrl.as_bytes());
        bytes(&mut mp, 2, ty.as_bytes());
        bytes(&mut p, 6, &mp);
        bytes(&mut m, 7, &p);
    }
    let mut out = (m.len() as u16).to_le_bytes().to_vec();
    out.extend_from_slice(&m);
    out
}

const ADVERTISE: u64 = 1;
const HEARTBEAT: u64 = 4;
const NEW_CONNECTION: u64 = 6;

/// A hostile gz-transport node: sends discovery packets to the group on loopback.
struct Hostile {
    udp: UdpSocket,
    part: String,
}

impl Hostile {
    fn new(part: &str) -> Hostile {
        let udp = UdpSocket::bind("127.0.0.1:0").unwrap();
        udp.set_multicast_loop_v4(true).unwrap();
        udp.set_multicast_ttl_v4(0).unwrap();
        Hostile {
            udp,
            part: part.into(),
        }
    }
    fn fq(&self, topic: &str) -> String {
        format!("@/{}@{topic}", self.part)
    }
    fn send(&self, p: &[u8]) {
        let _ = self
            .udp
            .send_to(p, SocketAddr::from((Ipv4Addr::new(239, 255, 0, 7), 10317)));
    }
    fn advertise(&self, process: &str, node: &str, topic: &str, addr: &str, ty: &str) {
        let t = self.fq(topic);
        self.send(&discovery(
            ADVERTISE,
            process,
            None,
            Some((&t, addr, node, "unused", ty)),
        ));
    }
    fn heartbeat(&self, process: &str) {
        self.send(&discovery(HEARTBEAT, process, None, None));
    }
}

/// Our process id as the driver advertises it on the group (`cmd_vel`), sniffed
/// as any node on the network can.
fn sniff_driver_process(part: &str, topic_end: &str) -> Option<String> {
    use socket2::{Domain, Protocol, Socket, Type};
    let s = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP)).ok()?;
    s.set_reuse_address(true).ok()?;
    s.set_reuse_port(true).ok()?;
    s.bind(&SocketAddr::from((Ipv4Addr::new(239, 255, 0, 7), 10317)).into())
        .ok()?;
    s.join_multicast_v4(&Ipv4Addr::new(239, 255, 0, 7), &Ipv4Addr::LOCALHOST)
        .ok()?;
    s.set_read_timeout(Some(Duration::from_millis(200))).ok()?;
    let u: UdpSocket = s.into();
    let want = format!("@/{part}@{topic_end}");
    let end = Instant::now() + Duration::from_secs(5);
    let mut buf = [0u8; 65536];
    while Instant::now() < end {
        let Ok(n) = u.recv(&mut buf) else { continue };
        let b = &buf[..n];
        // The ADVERTISE of our topic carries the topic and the process id as strings;
        // the process id is field 3 of the Discovery: 0x1a LEN UUID.
        if b.windows(want.len()).any(|w| w == want.as_bytes())
            && let Some(k) = b.windows(2).position(|w| w == [0x1a, 36])
            && let Ok(p) = std::str::from_utf8(&b[k + 2..k + 38])
        {
            return Some(p.to_string());
        }
    }
    None
}

fn uuid(n: u64) -> String {
    format!(
        "{:08x}-0000-4000-8000-{:012x}",
        (n >> 32) as u32,
        n & 0xffff_ffff_ffff
    )
}

/// Held by the tests that measure this process's memory, so they do not
/// measure each other's attacks.
static MEMORY: Mutex<()> = Mutex::new(());

/// Resident memory of this process, MB.
fn rss_mb() -> f64 {
    let s = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    s.lines()
        .find(|l| l.starts_with("VmRSS:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|k| k.parse::<f64>().ok())
        .unwrap_or(0.0)
        / 1024.0
}

/// The twists a C++ gz-transport subscriber of `topic` receives, with their times.
struct TwistLog {
    _proc: gazebo::Proc,
    log: Arc<Mutex<Vec<(Instant, String)>>>,
}

impl TwistLog {
    fn start(bin: &std::path::Path, part: &str, topic: &str) -> TwistLog {
        let mut child = gazebo::gz(bin, part)
            .args(["echo-twist", "--topic", topic, "--seconds", "120"])
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let out = child.stdout.take().unwrap();
        let log = Arc::new(Mutex::new(Vec::new()));
        let l = log.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines() {
                let Ok(line) = line else { break };
                l.lock().unwrap().push((Instant::now(), line));
            }
        });
        TwistLog {
            _proc: gazebo::Proc(child),
            log,
        }
    }
    /// The first zero twist after `t`.
    fn zero_after(&self, t: Instant) -> Option<Instant> {
        self.log
            .lock()
            .unwrap()
            .iter()
            .find(|(at, l)| *at >= t && l == "twist 0.0000 0.0000")
            .map(|(at, _)| *at)
    }
    /// The longest gap between twists in [a, b].
    fn longest_gap(&self, a: Instant, b: Instant) -> Duration {
        let log = self.log.lock().unwrap();
        let times: Vec<Instant> = std::iter::once(a)
            .chain(log.iter().map(|(t, _)| *t).filter(|t| *t >= a && *t <= b))
            .chain(std::iter::once(b))
            .collect();
        times
            .windows(2)
            .map(|w| w[1] - w[0])
            .max()
            .unwrap_or_default()
    }
    fn seen(&self, what: &str) -> bool {
        self.log.lock().unwrap().iter().any(|(_, l)| l == what)
    }
}

/// A schema's commands: `v` every 100 ms while `on`.
fn pusher(
    m: Arc<jderobot::interfaces::Interface<Motors>>,
    on: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
) {
    std::thread::spawn(move || {
        while !stop.load(Ordering::SeqCst) {
            if on.load(Ordering::SeqCst) {
                let _ = m.publish(Motors { v: 300.0, w: 0.0 });
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    });
}

const MOTORS_TIMEOUT: u64 = 500;
const CYCLE: u64 = 100;
/// What the stop may take beyond `motors_timeout` + one cycle: scheduling on a
/// shared 2-core machine and the C++ subscriber's own thread hop.
const MARGIN: Duration = Duration::from_millis(250);

/// Stops commanding (the schema stops) and checks that a zero twist reaches the
/// C++ subscriber within motors_timeout + cycle + MARGIN.
fn assert_stop_arrives(on: &AtomicBool, log: &TwistLog, what: &str) {
    on.store(false, Ordering::SeqCst);
    // The last command was published at most 100 ms ago; its age counts from then.
    let t = Instant::now();
    let bound = Duration::from_millis(MOTORS_TIMEOUT + CYCLE) + MARGIN;
    assert!(
        poll_until(10, || log.zero_after(t).is_some()),
        "{what}: the stop never reached the robot"
    );
    let took = log.zero_after(t).unwrap() - t;
    assert!(
        took <= bound,
        "{what}: the stop reached the robot {took:?} after the last command (at most {bound:?})"
    );
    on.store(true, Ordering::SeqCst);
}

/// True when this process only launched `test` again in a private network
/// namespace (`unshare -rn`), where the run does the test.
fn launched_in_netns(test: &str) -> bool {
    common::in_private_netns(&format!("hostile_gz_nao::{test}")) == common::Netns::Done
}

/// The C++ gz peer for `test` inside its private network namespace; None when this
/// process only launched it there, or the peer is missing (skipped).
fn peer_in_netns(test: &str) -> Option<std::path::PathBuf> {
    if launched_in_netns(test) {
        return None;
    }
    gazebo::peer_bin()
}

/// The gazebo driver on robot1's encoders and motors and the /lidar laser, stopping
/// within MOTORS_TIMEOUT + CYCLE, and those interfaces.
struct GzRobot {
    rt: Arc<jderobot::Runtime>,
    enc: Arc<Interface<Encoders>>,
    laser: Arc<Interface<Laser>>,
    motors: Arc<Interface<Motors>>,
}

impl GzRobot {
    fn start(part: &str) -> GzRobot {
        let rt = start_conf(&format!(
            "{}provides encoders robot1\nprovides motors robot1\nprovides laser lidar\n\
             motors_timeout {MOTORS_TIMEOUT}\ncycle {CYCLE}\nend_driver\nload_driver gazebo\n",
            gazebo::head(part, "gazebo")
        ));
        GzRobot {
            enc: rt.interfaces.get::<Encoders>("encoders").unwrap(),
            laser: rt.interfaces.get::<Laser>("laser").unwrap(),
            motors: rt.interfaces.get::<Motors>("motors").unwrap(),
            rt,
        }
    }
}

/// The real room's scan from the real /lidar: the wall ahead at x = 5 m from where
/// the robot is.
fn assert_wall_ahead(laser: &Interface<Laser>, enc: &Interface<Encoders>) {
    let ahead = laser.read().readings[90] as f32;
    let x = enc.read().x;
    assert!(
        (ahead - (5000.0 - x)).abs() < 600.0,
        "ahead {ahead} mm at x = {x} mm"
    );
}

/// The gz message types and the odometry topic the hostile ends use.
const SCAN: &str = "ignition.msgs.LaserScan";
const ODOMETRY: &str = "ignition.msgs.Odometry";
const IMAGE: &str = "ignition.msgs.Image";
const ODOM: &str = "/model/robot1/odometry";

/// One advertisement a hostile process repeats: node, topic, address, type.
type Ad = (u64, &'static str, String, &'static str);

/// A hostile process (`process` makes its id) advertising `ads` and sending a
/// heartbeat every `every` until `stop` is set.
fn advertiser(
    part: &str,
    process: u64,
    ads: Vec<Ad>,
    every: Duration,
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<()> {
    let part = part.to_string();
    std::thread::spawn(move || {
        let h = Hostile::new(&part);
        let p = uuid(process);
        while !stop.load(Ordering::SeqCst) {
            for (node, topic, addr, ty) in &ads {
                h.advertise(&p, &uuid(*node), topic, addr, ty);
            }
            h.heartbeat(&p);
            std::thread::sleep(every);
        }
    })
}

/// In the namespace, loopback is the only interface: the host's is not reached.
fn assert_only_loopback() {
    if std::env::var_os("JDE_TEST_IN_NETNS").is_some() {
        let dev = std::fs::read_to_string("/proc/self/net/dev").unwrap();
        let ifaces: Vec<&str> = dev
            .lines()
            .skip(2)
            .filter_map(|l| l.split(':').next().map(str::trim))
            .collect();
        assert_eq!(
            ifaces,
            ["lo"],
            "only loopback in the test's network namespace"
        );
    }
}

/// The flood: ADVERTISE of the driver's topics with a new node id each (and a
/// new process every 8), the decoy topics it could pick, and NEW_CONNECTION
/// registrations to our cmd_vel: about 3,000 packets a second for 8 s.
fn flood(
    part: String,
    ours: Option<String>,
    flooding: Arc<AtomicBool>,
    sent: Arc<AtomicUsize>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let h = Hostile::new(&part);
        let mut n = 0u64;
        while flooding.load(Ordering::SeqCst) {
            for _ in 0..30 {
                n += 1;
                let process = uuid(0xbad0_0000_0000 + n / 8);
                let node = uuid(n);
                let addr = "tcp://127.0.0.1:1";
                h.advertise(
                    &process,
                    &node,
                    "/model/robot1/odometry",
                    addr,
                    "ignition.msgs.Odometry",
                );
                h.advertise(&process, &node, "/lidar", addr, "ignition.msgs.LaserScan");
                h.advertise(
                    &process,
                    &node,
                    &format!("/decoy{n}/lidar"),
                    addr,
                    "ignition.msgs.LaserScan",
                );
                if let Some(o) = &ours {
                    let t = h.fq("/model/robot1/cmd_vel");
                    h.send(&discovery(
                        NEW_CONNECTION,
                        &process,
                        None,
                        Some((&t, addr, &node, o, "ignition.msgs.Twist")),
                    ));
                }
                sent.fetch_add(4, Ordering::SeqCst);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    })
}

/// In a private network namespace (`unshare -rn`): the flood never reaches the
/// host's network, and no other test's gz-transport nodes see it.
#[test]
fn gz_a_discovery_flood_does_not_hold_the_stop_and_gazebo_stays_bound() {
    let Some(bin) =
        peer_in_netns("gz_a_discovery_flood_does_not_hold_the_stop_and_gazebo_stays_bound")
    else {
        return;
    };
    assert_only_loopback();
    let part = gazebo::partition();
    let _peer = gazebo::robot(&bin, &part, &["--model", "robot1", "--lidar", "/lidar"]);
    let log = TwistLog::start(&bin, &part, "/model/robot1/cmd_vel");
    let GzRobot {
        rt,
        enc,
        laser,
        motors,
    } = GzRobot::start(&part);
    let (on, stop) = (
        Arc::new(AtomicBool::new(true)),
        Arc::new(AtomicBool::new(false)),
    );
    pusher(motors.clone(), on.clone(), stop.clone());
    eventually("our twist at the C++ subscriber", || {
        log.seen("twist 0.3000 0.0000")
    });
    eventually("odometry and scans", || {
        enc.read().clock > 0 && laser.read().clock > 0
    });
    let ours = sniff_driver_process(&part, "/model/robot1/cmd_vel");
    let _memory = MEMORY.lock().unwrap_or_else(|e| e.into_inner());
    let rss0 = rss_mb();
    let flooding = Arc::new(AtomicBool::new(true));
    let sent = Arc::new(AtomicUsize::new(0));
    let flood = flood(part.clone(), ours.clone(), flooding.clone(), sent.clone());
    let t0 = Instant::now();
    std::thread::sleep(Duration::from_secs(2));
    assert_stop_arrives(&on, &log, "during the flood");
    std::thread::sleep(Duration::from_secs(2));
    assert_stop_arrives(&on, &log, "during the flood, again");
    std::thread::sleep(Duration::from_secs(2));
    let t1 = Instant::now();
    let gap = log.longest_gap(t0, t1);
    let rss1 = rss_mb();
    flooding.store(false, Ordering::SeqCst);
    flood.join().unwrap();
    eprintln!(
        "flood: {} packets in {:.1} s; longest cmd_vel gap {gap:?}; RSS {rss0:.0} -> {rss1:.0} MB",
        sent.load(Ordering::SeqCst),
        (t1 - t0).as_secs_f64()
    );
    // cmd_vel kept going (the gap was 32 s before the caps): never longer than
    // the stop may take.
    assert!(
        gap <= Duration::from_millis(MOTORS_TIMEOUT + CYCLE) + MARGIN,
        "cmd_vel stopped for {gap:?} during the flood"
    );
    // Memory: the caps hold what a flood can add under 64 MB.
    assert!(rss1 - rss0 < 64.0, "RSS grew {rss0:.0} -> {rss1:.0} MB");
    // Gazebo stays bound: odometry and the real /lidar keep coming, not stale.
    let (e, l) = (enc.read().clock, laser.read().clock);
    eventually("odometry and scans after the flood", || {
        enc.read().clock > e + 5 && laser.read().clock > l + 3 && enc.stale().is_none()
    });
    assert_wall_ahead(&laser, &enc);
    stop.store(true, Ordering::SeqCst);
    rt.shutdown();
}

/// A ZMTP 3.0 PUB end (the hostile publisher): greets and says READY, then
/// `serve(stream)` does the rest.
fn zmtp_publisher(serve: impl Fn(TcpStream) + Send + Sync + 'static) -> (u16, Arc<AtomicUsize>) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    let accepted = Arc::new(AtomicUsize::new(0));
    let a = accepted.clone();
    let serve = Arc::new(serve);
    std::thread::spawn(move || {
        for s in l.incoming() {
            let Ok(mut s) = s else { continue };
            a.fetch_add(1, Ordering::SeqCst);
            let serve = serve.clone();
            std::thread::spawn(move || {
                let mut g = [0u8; 64];
                g[0] = 0xff;
                g[9] = 0x7f;
                g[10] = 3;
                g[12..16].copy_from_slice(b"NULL");
                let _ = s.write_all(&g);
                let mut body = vec![5];
                body.extend_from_slice(b"READY");
                body.push(11);
                body.extend_from_slice(b"Socket-Type");
                body.extend_from_slice(&3u32.to_be_bytes());
                body.extend_from_slice(b"PUB");
                let mut f = vec![0x04, body.len() as u8];
                f.extend_from_slice(&body);
                let _ = s.write_all(&f);
                // Whatever the subscriber says is read and dropped.
                let mut r = s.try_clone().unwrap();
                std::thread::spawn(move || {
                    let mut b = [0u8; 4096];
                    while r.read(&mut b).is_ok_and(|n| n > 0) {}
                });
                std::thread::sleep(Duration::from_millis(200));
                serve(s);
            });
        }
    });
    (port, accepted)
}

/// One ZMTP 3.0 frame (rfc.zeromq.org/spec/23 §2.3: a flags byte with MORE in
/// bit 0 and LONG in bit 1, then the size in one byte, or eight big-endian).
fn zframe(out: &mut Vec<u8>, more: bool, data: &[u8]) {
    let size = (data.len() as u64).to_be_bytes();
    let long = data.len() > 255;
    out.push(u8::from(more) | (u8::from(long) << 1));
    out.extend_from_slice(if long { &size } else { &size[7..] });
    out.extend_from_slice(data);
}

/// A gz message: [topic, address, data, type].
fn gz_message(topic: &str, addr: &str, data: &[u8], ty: &str) -> Vec<u8> {
    let mut out = Vec::new();
    zframe(&mut out, true, topic.as_bytes());
    zframe(&mut out, true, addr.as_bytes());
    zframe(&mut out, true, data);
    zframe(&mut out, false, ty.as_bytes());
    out
}

#[test]
fn gz_decoys_silent_publishers_and_bad_addresses_do_not_hold_the_driver() {
    let Some(bin) =
        peer_in_netns("gz_decoys_silent_publishers_and_bad_addresses_do_not_hold_the_driver")
    else {
        return;
    };
    let part = gazebo::partition();
    // A decoy that greets and heartbeats but never sends data, advertised before
    // Gazebo as `/decoy/lidar` and as the pan-tilt's joint state.
    let (silent, _) = zmtp_publisher(|s| {
        std::thread::sleep(Duration::from_secs(120));
        drop(s);
    });
    let stop = Arc::new(AtomicBool::new(false));
    let decoy = advertiser(
        &part,
        0xdec0,
        vec![
            (1, "/decoy/lidar", format!("tcp://127.0.0.1:{silent}"), SCAN),
            // A name to resolve (never resolved: IP literals only) and a port
            // nobody listens on, for the odometry.
            (2, ODOM, "tcp://gazebo.invalid:5555".into(), ODOMETRY),
            (3, ODOM, "tcp://127.0.0.1:1".into(), ODOMETRY),
        ],
        Duration::from_millis(200),
        stop.clone(),
    );
    std::thread::sleep(Duration::from_millis(800));
    let log = TwistLog::start(&bin, &part, "/model/robot1/cmd_vel");
    let GzRobot {
        rt,
        enc,
        laser,
        motors,
    } = GzRobot::start(&part);
    // The decoy alone: a publisher with no data is marked stale, not kept.
    std::thread::sleep(Duration::from_secs(5));
    assert!(
        laser.stale().is_some(),
        "a silent decoy left the laser not stale"
    );
    // Gazebo comes: the driver moves to it.
    let _peer = gazebo::robot(&bin, &part, &["--model", "robot1", "--lidar", "/lidar"]);
    let on = Arc::new(AtomicBool::new(true));
    pusher(motors.clone(), on.clone(), stop.clone());
    assert!(
        poll_until(20, || enc.read().clock > 5
            && laser.read().clock > 3
            && laser.stale().is_none()
            && motors.stale().is_none()),
        "Gazebo not bound with the decoys about: laser {:?}, encoders {:?}, motors {:?}",
        laser.stale(),
        enc.stale(),
        motors.stale()
    );
    assert_wall_ahead(&laser, &enc);
    eventually("our twist at the robot", || log.seen("twist 0.3000 0.0000"));
    assert_stop_arrives(&on, &log, "with the decoys about");
    stop.store(true, Ordering::SeqCst);
    decoy.join().unwrap();
    // `quit` is prompt: no connect or lookup holds the thread.
    let t = Instant::now();
    rt.shutdown();
    assert!(
        t.elapsed() < Duration::from_secs(3),
        "shutdown took {:?}",
        t.elapsed()
    );
}

#[test]
fn gz_unfinished_more_frames_are_capped_per_message_and_gazebo_is_bound_after() {
    let Some(bin) =
        peer_in_netns("gz_unfinished_more_frames_are_capped_per_message_and_gazebo_is_bound_after")
    else {
        return;
    };
    let part = gazebo::partition();
    // The hostile publisher of /lidar: MORE frames of 16 MiB that never end.
    let (port, accepted) = zmtp_publisher(|mut s| {
        let chunk = vec![0x55u8; 16 << 20];
        for _ in 0..15 {
            let mut head = vec![0x01 | 0x02];
            head.extend_from_slice(&(chunk.len() as u64).to_be_bytes());
            if s.write_all(&head).is_err() || s.write_all(&chunk).is_err() {
                return;
            }
        }
        std::thread::sleep(Duration::from_secs(60));
    });
    let stop = Arc::new(AtomicBool::new(false));
    let addr = format!("tcp://127.0.0.1:{port}");
    let hostile = advertiser(
        &part,
        0xf00d,
        vec![(9, "/lidar", addr, SCAN)],
        Duration::from_millis(300),
        stop.clone(),
    );
    std::thread::sleep(Duration::from_millis(700));
    let conf = format!(
        "{}provides laser lidar\nend_driver\nload_driver gazebo\n",
        gazebo::head(&part, "gazebo")
    );
    // The memory of a driver in its own process (other tests share this one).
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("gz.conf");
    std::fs::write(&file, &conf).unwrap();
    let p = common::process::Proc::start(&file);
    eventually("the driver connects to the hostile publisher", || {
        accepted.load(Ordering::SeqCst) > 0
    });
    std::thread::sleep(Duration::from_secs(6));
    let (rss, peak) = rss_of(p.child.id());
    p.quit();
    eprintln!("MORE frames: RSS {rss:.0} MB, peak {peak:.0} MB");
    // One message at most (64 MiB) and its buffer: under 250 MB at peak (15 frames
    // of 64 MiB took 1.1 GB before).
    assert!(peak < 250.0, "peak RSS {peak:.0} MB");
    let rt = start_conf(&conf);
    let laser = rt.interfaces.get::<Laser>("laser").unwrap();
    let _peer = gazebo::robot(&bin, &part, &["--model", "robot1", "--lidar", "/lidar"]);
    assert!(
        poll_until(20, || laser.read().clock > 3 && laser.stale().is_none()),
        "the real /lidar not bound after the hostile publisher: {:?}",
        laser.stale()
    );
    stop.store(true, Ordering::SeqCst);
    hostile.join().unwrap();
    rt.shutdown();
}

/// A LaserScan (gz-msgs 8: 4 angle_min, 6 angle_step, 8 range_max, 9 count, 14 ranges).
fn scan(min: f64, step: f64, range_max: f64, ranges: &[f64]) -> Vec<u8> {
    let mut m = Vec::new();
    double(&mut m, 4, min);
    double(&mut m, 6, step);
    double(&mut m, 8, range_max);
    uint(&mut m, 9, ranges.len() as u64);
    let packed: Vec<u8> = ranges.iter().flat_map(|r| r.to_le_bytes()).collect();
    bytes(&mut m, 14, &packed);
    m
}

/// An Odometry at (x, y) m (2 pose {4 position {2 x, 3 y}}).
fn odometry(x: f64, y: f64) -> Vec<u8> {
    let mut pos = Vec::new();
    double(&mut pos, 2, x);
    double(&mut pos, 3, y);
    let mut pose = Vec::new();
    bytes(&mut pose, 4, &pos);
    let mut m = Vec::new();
    bytes(&mut m, 2, &pose);
    m
}

/// An Image (2 width, 3 height, 4 step, 5 data, 6 pixel format: 3 RGB_INT8).
fn image(w: u64, h: u64, data: &[u8]) -> Vec<u8> {
    let mut m = Vec::new();
    uint(&mut m, 2, w);
    uint(&mut m, 3, h);
    uint(&mut m, 4, w * 3);
    bytes(&mut m, 5, data);
    uint(&mut m, 6, 3);
    m
}

/// A publisher of /lidar, the odometry and /camera that sends absurd values
/// (twice, in case the subscription is not in yet), then good ones; its port.
fn absurd_then_good_publisher(part: &str) -> u16 {
    let lidar = format!("@/{part}@/lidar");
    let odom = format!("@/{part}@/model/robot1/odometry");
    let cam = format!("@/{part}@/camera");
    let (l2, o2, c2) = (lidar.clone(), odom.clone(), cam.clone());
    zmtp_publisher(move |mut s| {
        let me = "tcp://127.0.0.1:1";
        let rays = vec![1.0; 360];
        let step = std::f64::consts::TAU / 360.0;
        let mut huge = rays.clone();
        huge[90] = 1e300;
        let bad: Vec<(String, Vec<u8>, &str)> = vec![
            (
                l2.clone(),
                scan(-std::f64::consts::PI, step, 10.0, &huge),
                "ignition.msgs.LaserScan",
            ),
            (
                l2.clone(),
                scan(-std::f64::consts::PI, step, 1e300, &rays),
                "ignition.msgs.LaserScan",
            ),
            (
                l2.clone(),
                scan(-std::f64::consts::PI, step, 10.0, &[]),
                "ignition.msgs.LaserScan",
            ),
            (l2.clone(), odometry(1.0, 2.0), "ignition.msgs.Odometry"),
            (o2.clone(), image(2, 2, &[9; 12]), "ignition.msgs.Image"),
            (o2.clone(), odometry(1e300, 0.0), "ignition.msgs.Odometry"),
            (
                c2.clone(),
                image((1 << 40) + 2, 1, &[7; 6]),
                "ignition.msgs.Image",
            ),
            (c2.clone(), image(1, 0, &[]), "ignition.msgs.Image"),
        ];
        // Twice (in case the subscription is not in yet), then good values.
        for _ in 0..2 {
            for (t, d, ty) in &bad {
                let _ = s.write_all(&gz_message(t, me, d, ty));
            }
            std::thread::sleep(Duration::from_millis(300));
        }
        loop {
            let good = [
                (
                    l2.clone(),
                    scan(-std::f64::consts::PI, step, 10.0, &rays),
                    "ignition.msgs.LaserScan",
                ),
                (o2.clone(), odometry(1.5, 0.5), "ignition.msgs.Odometry"),
                (c2.clone(), image(2, 2, &[9; 12]), "ignition.msgs.Image"),
            ];
            for (t, d, ty) in &good {
                if s.write_all(&gz_message(t, me, d, ty)).is_err() {
                    return;
                }
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    })
    .0
}

#[test]
fn gz_absurd_values_are_refused_and_never_reach_an_interface() {
    if launched_in_netns("gz_absurd_values_are_refused_and_never_reach_an_interface") {
        return;
    }
    let part = gazebo::partition();
    let port = absurd_then_good_publisher(&part);
    let stop = Arc::new(AtomicBool::new(false));
    let addr = format!("tcp://127.0.0.1:{port}");
    let ads = [("/lidar", SCAN), (ODOM, ODOMETRY), ("/camera", IMAGE)];
    let hostile = advertiser(
        &part,
        0xabad,
        ads.map(|(topic, ty)| (1, topic, addr.clone(), ty)).to_vec(),
        Duration::from_millis(300),
        stop.clone(),
    );
    let rt = start_conf(&format!(
        "{}provides laser lidar\nprovides encoders robot1\nprovides varcolorA camera\n\
         end_driver\nload_driver gazebo\n",
        gazebo::head(&part, "gazebo")
    ));
    let laser = rt.interfaces.get::<Laser>("laser").unwrap();
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let img = rt.interfaces.get::<Image>("varcolorA").unwrap();
    // The first values to arrive are the good ones: nothing bad got through.
    eventually("the good values", || {
        laser.read().clock > 0 && enc.read().clock > 0 && img.read().clock > 0
    });
    let l = laser.read();
    assert!(
        l.readings.iter().all(|r| *r == 1000),
        "{:?}",
        &l.readings[..10]
    );
    assert_eq!(l.max_range, 10_000.0);
    drop(l);
    let e = enc.read().value;
    assert!(
        (e.x - 1500.0).abs() < 1.0 && (e.y - 500.0).abs() < 1.0,
        "{e:?}"
    );
    let i = img.read();
    assert_eq!((i.width, i.height), (2, 2));
    drop(i);
    stop.store(true, Ordering::SeqCst);
    hostile.join().unwrap();
    rt.shutdown();
}

// ------------------------------------------------------------------ naobody

#[test]
fn nao_a_trickled_reply_times_out_as_one_call_and_the_stop_follows_the_reconnect() {
    // A hostile NAOqi whose replies can come one byte every 1.5 s: each byte within
    // reply_timeout, the whole reply far beyond it. (The libqi stand-in lists its
    // own endpoint for ALMotion, so a proxy in front of it could not hold the
    // calls: this NAOqi serves ALMotion on the ServiceDirectory's connection.)
    let nao = fake_naoqi(Vec::new(), 0);
    let rt = start_conf(&naobody::naobody(
        nao.port,
        "provides motors\nprovides encoders\nreply_timeout 1000\nmotors_timeout 500\n",
    ));
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    eventually("odometry", || enc.clock() > 0);
    motors.publish(Motors { v: 50.0, w: 0.0 }).unwrap();
    let count = |what: &str| {
        nao.log
            .lock()
            .unwrap()
            .iter()
            .filter(|l| *l == what)
            .count()
    };
    eventually("walks", || count("move") > 0);
    // The attack. The whole call has one deadline (reply_timeout, 1 s): the body
    // is stale within it plus a poll (50 ms) and a margin of one trickled byte,
    // where it stayed 45 s before.
    nao.trickle.store(true, Ordering::SeqCst);
    let t = Instant::now();
    assert!(
        poll_until(10, || enc.stale().is_some()),
        "encoders not stale during the trickle"
    );
    let took = t.elapsed();
    assert!(
        took < Duration::from_millis(1000 + 50 + 1500),
        "stale after {took:?}"
    );
    assert_eq!(
        motors.read().value,
        Motors::default(),
        "motors zeroed on the loss"
    );
    // Still trickling: reconnects, each given up within reply_timeout, never wedged.
    std::thread::sleep(Duration::from_secs(3));
    assert!(enc.stale().is_some());
    // The trickle ends: the session is opened again and its first act stops the walk.
    let stops = count("stopMove");
    nao.trickle.store(false, Ordering::SeqCst);
    assert!(
        poll_until(20, || enc.stale().is_none()
            && motors.stale().is_none()
            && count("stopMove") > stops),
        "not back with the walk stopped: {:?}",
        enc.stale()
    );
    let t = Instant::now();
    rt.shutdown();
    assert!(
        t.elapsed() < Duration::from_secs(3),
        "shutdown took {:?}",
        t.elapsed()
    );
}

/// A hostile NAOqi written from libqi's protocol: it authenticates clients, has a
/// ServiceDirectory with `service(s)` and one service, ALMotion (id 7: `move`,
/// `stopMove`, `getRobotPosition`), listed with `endpoints` (none: served on the
/// ServiceDirectory's connection). With `error_bytes`, `service` answers an
/// error of that many bytes; while `trickle` is set, every reply goes out one
/// byte every 1.5 s. The calls it got are in `log`.
struct FakeNao {
    port: u16,
    trickle: Arc<AtomicBool>,
    log: Arc<Mutex<Vec<String>>>,
}

/// What the fake NAOqi serves each connection from.
struct NaoState {
    endpoints: Vec<String>,
    /// The error `service` answers, when it is asked to.
    error: Option<Vec<u8>>,
    trickle: Arc<AtomicBool>,
    log: Arc<Mutex<Vec<String>>>,
}

fn fake_naoqi(endpoints: Vec<String>, error_bytes: usize) -> FakeNao {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    let error = (error_bytes > 0).then(|| {
        let mut out = Vec::new();
        qi_str(&mut out, "s");
        qi_str(&mut out, &"x".repeat(error_bytes));
        out
    });
    let state = Arc::new(NaoState {
        endpoints,
        error,
        trickle: Arc::new(AtomicBool::new(false)),
        log: Arc::new(Mutex::new(Vec::new())),
    });
    let (trickle, log) = (state.trickle.clone(), state.log.clone());
    std::thread::spawn(move || {
        for c in l.incoming() {
            let Ok(c) = c else { continue };
            let state = state.clone();
            std::thread::spawn(move || nao_connection(c, &state));
        }
    });
    FakeNao { port, trickle, log }
}

/// One client of the fake NAOqi: reads each call's header and payload and
/// answers it (one byte every 1.5 s while `trickle` is set).
fn nao_connection(mut c: TcpStream, state: &NaoState) {
    loop {
        let mut h = [0u8; 28];
        if c.read_exact(&mut h).is_err() {
            return;
        }
        let w = |i: usize| u32::from_le_bytes(h[i..i + 4].try_into().unwrap());
        let (id, size, svc, act) = (w(4), w(8) as usize, w(16), w(24));
        let mut p = vec![0u8; size];
        if c.read_exact(&mut p).is_err() {
            return;
        }
        let reply = nao_reply(state, id, svc, act);
        if state.trickle.load(Ordering::SeqCst) {
            for b in reply {
                std::thread::sleep(Duration::from_millis(1500));
                if c.write_all(&[b]).is_err() {
                    return;
                }
            }
        } else if c.write_all(&reply).is_err() {
            return;
        }
    }
}

/// The fake NAOqi's answer to call `id` of action `act` on service `svc`.
fn nao_reply(state: &NaoState, id: u32, svc: u32, act: u32) -> Vec<u8> {
    let (s, u) = (qi_str, qi_u32);
    let msg = |ty: u8, p: &[u8]| qi_msg(id, ty, svc, act, p);
    let mut out = Vec::new();
    match (svc, act) {
        (0, 8) => {
            // {sm}: __qi_auth_state -> 3 (done)
            u(&mut out, 1);
            s(&mut out, "__qi_auth_state");
            s(&mut out, "I");
            u(&mut out, 3);
            msg(2, &out)
        }
        (1, 2) => msg(2, &qi_meta(&[(100, "(sIsI[s]s)", "service", "(s)")])),
        (7, 2) => msg(
            2,
            &qi_meta(&[
                (100, "v", "move", "(fff)"),
                (101, "v", "stopMove", "()"),
                (102, "[f]", "getRobotPosition", "(b)"),
            ]),
        ),
        (1, 100) if state.error.is_some() => msg(3, state.error.as_deref().unwrap_or_default()),
        (1, 100) => {
            // ServiceInfo (s I s I [s] s)
            s(&mut out, "ALMotion");
            u(&mut out, 7);
            s(&mut out, "machine");
            u(&mut out, 1);
            u(&mut out, state.endpoints.len() as u32);
            for e in &state.endpoints {
                s(&mut out, e);
            }
            s(&mut out, "session");
            msg(2, &out)
        }
        (7, 100) | (7, 101) => {
            state
                .log
                .lock()
                .unwrap()
                .push(if act == 100 { "move" } else { "stopMove" }.into());
            msg(2, &[])
        }
        (7, 102) => {
            u(&mut out, 3);
            for x in [0.25f32, 0.0, 0.0] {
                out.extend_from_slice(&x.to_le_bytes());
            }
            msg(2, &out)
        }
        _ => {
            s(&mut out, "s");
            s(&mut out, "no such thing");
            msg(3, &out)
        }
    }
}

/// A libqi message: the header (magic, id, size, version, type, flags, service,
/// object 1, action) and the payload.
fn qi_msg(id: u32, ty: u8, svc: u32, act: u32, p: &[u8]) -> Vec<u8> {
    let mut b = vec![0x42, 0xde, 0xad, 0x42];
    b.extend_from_slice(&id.to_le_bytes());
    b.extend_from_slice(&(p.len() as u32).to_le_bytes());
    b.extend_from_slice(&0u16.to_le_bytes());
    b.push(ty);
    b.push(0);
    for x in [svc, 1, act] {
        b.extend_from_slice(&x.to_le_bytes());
    }
    b.extend_from_slice(p);
    b
}

/// A libqi string: its length, then its bytes.
fn qi_str(out: &mut Vec<u8>, t: &str) {
    out.extend_from_slice(&(t.len() as u32).to_le_bytes());
    out.extend_from_slice(t.as_bytes());
}

fn qi_u32(out: &mut Vec<u8>, x: u32) {
    out.extend_from_slice(&x.to_le_bytes());
}

/// A MetaObject of `methods` (uid, return, name, parameters).
fn qi_meta(methods: &[(u32, &str, &str, &str)]) -> Vec<u8> {
    let (s, u) = (qi_str, qi_u32);
    let mut out = Vec::new();
    u(&mut out, methods.len() as u32);
    for (uid, ret, name, params) in methods {
        u(&mut out, *uid);
        u(&mut out, *uid);
        s(&mut out, ret);
        s(&mut out, name);
        s(&mut out, params);
        s(&mut out, "");
        u(&mut out, 0);
        s(&mut out, "");
    }
    u(&mut out, 0);
    u(&mut out, 0);
    s(&mut out, "");
    out
}

#[test]
fn nao_a_service_with_3000_hanging_endpoints_is_given_up_within_one_call() {
    // Endpoints that accept the connection and never answer (the listener's
    // backlog takes the connect; nobody reads).
    let silent = TcpListener::bind("127.0.0.1:0").unwrap();
    let sp = silent.local_addr().unwrap().port();
    let eps: Vec<String> = (0..3000).map(|_| format!("tcp://127.0.0.1:{sp}")).collect();
    let port = fake_naoqi(eps, 0).port;
    let rt = start_conf(&naobody::naobody(
        port,
        "provides motors\nprovides encoders\nreply_timeout 1000\n",
    ));
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    eventually("the endpoints given up", || {
        enc.stale()
            .is_some_and(|w| w.contains("none of its endpoints answers"))
    });
    let why = enc.stale().unwrap();
    assert!(why.contains("3000 listed"), "{why}");
    assert_eq!(motors.read().value, Motors::default());
    // `quit` returns promptly (each attempt is bounded by reply_timeout).
    let t = Instant::now();
    rt.shutdown();
    assert!(
        t.elapsed() < Duration::from_secs(4),
        "shutdown took {:?}",
        t.elapsed()
    );
    drop(silent);
}

/// A process's resident memory now and at its peak (VmRSS, VmHWM), MB.
fn rss_of(pid: u32) -> (f64, f64) {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    let kb = |key: &str| {
        s.lines()
            .find(|l| l.starts_with(key))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|k| k.parse::<f64>().ok())
            .unwrap_or(0.0)
            / 1024.0
    };
    (kb("VmRSS:"), kb("VmHWM:"))
}

#[test]
fn nao_a_huge_error_reply_is_shown_short() {
    if common::ran_in_own_process("hostile_gz_nao::nao_a_huge_error_reply_is_shown_short") {
        return;
    }
    let port = fake_naoqi(Vec::new(), 30 << 20).port;
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("nao.conf");
    std::fs::write(
        &conf,
        naobody::naobody(port, "provides encoders\nreply_timeout 5000\n"),
    )
    .unwrap();
    // In its own process: its peak memory is the driver's alone.
    let p = common::process::Proc::start(&conf);
    let pid = p.child.id();
    assert!(
        poll_until(20, || p.text().contains("xxxx")),
        "no error line: {}",
        p.text()
    );
    // Several polls and reconnects with the 30 MiB error each time.
    std::thread::sleep(Duration::from_secs(3));
    let (rss, peak) = rss_of(pid);
    let text = p.text();
    let longest = text
        .lines()
        .filter(|l| l.contains("xxx"))
        .map(str::len)
        .max()
        .unwrap_or(0);
    p.quit();
    eprintln!("huge error: RSS {rss:.0} MB, peak {peak:.0} MB; longest line {longest} bytes");
    assert!(longest < 600, "an error line of {longest} bytes");
    // The 30 MiB reply is read and decoded (its bytes and one copy), then dropped;
    // never formatted whole (1 s of CPU and 167 MB before): under 160 MB at peak.
    assert!(peak < 160.0, "peak RSS {peak:.0} MB");
}

#[test]
fn nao_absurd_sonars_and_head_limits_are_refused() {
    let Some(py) = naobody::python() else { return };
    let peer = naobody::Peer::start(&py, free_port(), &["--absurd"]);
    // A sonar of 1e35 m: refused (the bumpers of the same reply are taken).
    let rt = start_conf(&naobody::naobody(
        peer.port,
        "provides sonars\nprovides bumpers\n",
    ));
    let us = rt.interfaces.get::<Sonars>("sonars").unwrap();
    let b = rt
        .interfaces
        .get::<jderobot::interfaces::Bumpers>("bumpers")
        .unwrap();
    eventually("bumpers", || b.clock() > 2);
    assert_eq!(
        us.clock(),
        0,
        "a sonar of 1e35 m reached the interface: {:?}",
        us.read().us
    );
    rt.shutdown();
    // HeadYaw limits of ±1e30 rad: refused with the range, never applied.
    let rt = start_conf(&naobody::naobody(peer.port, "provides ptmotors\n"));
    let ptm = rt.interfaces.get::<PtMotors>("pantiltmotors").unwrap();
    eventually("the limits refused with the range", || {
        ptm.stale()
            .is_some_and(|w| w.contains("getLimits") && w.contains("2π"))
    });
    assert!(ptm.read().max_longitude <= 360.0);
    rt.shutdown();
    drop(peer);
}
