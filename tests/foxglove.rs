//! The `foxglove` service against clients that are not ours: the official
//! Foxglove client `@foxglove/ws-protocol` 0.8.0 in Node (tests/foxglove_node), and
//! a minimal WebSocket client written here from RFC 6455 and the ws-protocol spec
//! (docs/spec.md of foxglove/ws-protocol) for the faults: garbage, oversized
//! messages, a client that stops reading, and 100 connect/disconnect cycles.
#![cfg(all(feature = "foxglove", feature = "simulator", feature = "introrob"))]

use crate::common;

use std::{
    io::{Read, Write},
    net::{SocketAddr, TcpStream},
    path::PathBuf,
    process::Command,
    sync::Arc,
    time::{Duration, Instant},
};

use jderobot::{
    Runtime,
    interfaces::{Encoders, Motors},
};
use serde_json::Value;

fn conf(extra: &str) -> String {
    format!(
        "driver simulator\nworld {}\nrobot robot1 1000 1000 90\nprovides encoders\nprovides motors\n\
         provides laser 180 1\nprovides sonars\nprovides bumpers\nprovides colorA\nend_driver\n\
         schema introrob\nbehaviour vff\ntarget 5000 2200\nend_schema\n\
         service foxglove\nport 0\n{extra}end_service\n\
         load_driver simulator\nload_schema introrob\nload_service foxglove\nrun introrob\n",
        common::world_path("simple.world")
    )
}

fn addr(rt: &Runtime) -> SocketAddr {
    *rt.names
        .import::<SocketAddr>("foxglove", "address")
        .expect("foxglove exports its address")
}

fn ps(rt: &Runtime) -> String {
    let mut out = Vec::new();
    jderobot::shell::ps(rt, &mut out);
    String::from_utf8(out).unwrap()
}

/// Node with the pinned client installed, or None (skipped; a failure under CI).
fn node_client() -> Option<PathBuf> {
    let dir = common::root().join("tests/foxglove_node");
    let node_ok = Command::new("node")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    let installed = dir
        .join("node_modules/@foxglove/ws-protocol/package.json")
        .exists()
        && dir.join("node_modules/protobufjs/package.json").exists();
    if node_ok && installed {
        return Some(dir);
    }
    let note = format!(
        "node {} and {} {}; run `npm ci` there as .ci/run does",
        if node_ok { "found" } else { "missing" },
        dir.join("node_modules").display(),
        if installed { "installed" } else { "missing" }
    );
    assert!(std::env::var_os("CI").is_none(), "under CI: {note}");
    eprintln!("SKIPPED: {note}");
    None
}

/// The capabilities and the channels, with Foxglove's schemas.
fn assert_channels(r: &Value) {
    for cap in ["clientPublish", "services", "parameters"] {
        assert!(
            r["capabilities"]
                .as_array()
                .unwrap()
                .iter()
                .any(|c| c == cap),
            "{cap}: {r}"
        );
    }
    let schema = |topic: &str| {
        r["channels"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["topic"] == topic)
            .map(|c| {
                (
                    c["encoding"].as_str().unwrap().to_string(),
                    c["schemaName"].as_str().unwrap().to_string(),
                )
            })
            .unwrap_or_else(|| panic!("no channel {topic}: {r}"))
    };
    for (topic, encoding, name) in [
        ("laser", "protobuf", "foxglove.LaserScan"),
        ("sonars", "protobuf", "foxglove.LaserScan"),
        ("colorA", "protobuf", "foxglove.RawImage"),
        ("encoders", "protobuf", "foxglove.PoseInFrame"),
        ("/tf", "protobuf", "foxglove.FrameTransform"),
        ("world", "protobuf", "foxglove.SceneUpdate"),
        ("motors", "json", "jderobot.motors"),
        ("bumpers", "json", "jderobot.bumpers"),
    ] {
        assert_eq!(schema(topic), (encoding.into(), name.into()));
    }
}

/// What the client decoded with the advertised schemas.
fn assert_decoded(d: &Value) {
    assert_eq!(d["laser"]["ranges"], 180);
    assert_eq!(d["laser"]["frame_id"], "base_link");
    assert!(
        (d["laser"]["start_angle"].as_f64().unwrap() + std::f64::consts::FRAC_PI_2).abs() < 1e-9
    );
    assert!(d["laser"]["first"].as_f64().unwrap() > 0.0);
    assert_eq!(
        (
            &d["colorA"]["width"],
            &d["colorA"]["height"],
            &d["colorA"]["encoding"],
            &d["colorA"]["bytes"]
        ),
        (
            &Value::from(320),
            &Value::from(240),
            &Value::from("bgr8"),
            &Value::from(320 * 240 * 3)
        )
    );
    assert_eq!(d["/tf"]["parent_frame_id"], "odom");
    assert_eq!(d["/tf"]["child_frame_id"], "base_link");
    assert_eq!(d["encoders"]["frame_id"], "odom");
    let map = d["world"]["entities"].as_array().unwrap();
    assert!(
        map.iter()
            .any(|e| e["id"] == "map" && e["cubes"].as_u64().unwrap() > 4),
        "{map:?}"
    );
    assert!(d["motors"]["jderobot"]["v"].is_number());
}

#[test]
fn the_official_client_lists_decodes_drives_and_stops_a_schema() {
    let Some(dir) = node_client() else { return };
    let rt = common::start_conf(&conf(""));
    let a = addr(&rt);
    assert!(a.ip().is_loopback(), "loopback by default: {a}");
    let r = run_node_client(&dir, &format!("ws://{a}"), None);
    // The legacy subprotocol, answered under its own name.
    assert_eq!(r["protocol"], "foxglove.websocket.v1");
    assert_channels(&r);
    assert_decoded(&r["decoded"]);
    // `stop introrob` slept it.
    assert_eq!(r["stop"]["ok"], true);
    let p = ps(&rt);
    assert!(
        p.lines()
            .any(|l| l.starts_with("introrob:") && l.contains("slept")),
        "{p}"
    );
    assert!(
        r["parameters"][0]["value"].as_str().unwrap().contains("x="),
        "{r}"
    );
    // The Twist (0.3 m/s ahead) moved the robot.
    let poses = r["posesDuringTwist"].as_array().unwrap();
    assert!(poses.len() > 3, "{r}");
    let (first, last) = (&poses[0], &poses[poses.len() - 1]);
    let moved = (last["x"].as_f64().unwrap() - first["x"].as_f64().unwrap())
        .hypot(last["y"].as_f64().unwrap() - first["y"].as_f64().unwrap());
    assert!(moved > 0.15, "moved {moved} m under 15 Twists of 0.3 m/s");
    // It left without unadvertising: the motors are zero.
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    common::eventually("motors zeroed after the client left", || {
        let m = motors.snapshot();
        m.v == 0.0 && m.w == 0.0
    });
    assert!(ps(&rt).contains("foxglove: ws://"), "{}", ps(&rt));
    rt.shutdown();
}

/// A minimal WebSocket client (RFC 6455) speaking the Foxglove protocol.
struct Ws {
    s: TcpStream,
    buf: Vec<u8>,
}

fn handshake(a: SocketAddr, protocol: Option<&str>) -> (TcpStream, String) {
    handshake_at(a, "/", protocol)
}

/// The upgrade request (RFC 6455 §4.1) for `path` (where a token may ride).
fn handshake_at(a: SocketAddr, path: &str, protocol: Option<&str>) -> (TcpStream, String) {
    let mut s = TcpStream::connect(a).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let proto = protocol
        .map(|p| format!("Sec-WebSocket-Protocol: {p}\r\n"))
        .unwrap_or_default();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {a}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n{proto}\r\n"
    )
    .unwrap();
    let mut head = Vec::new();
    let mut b = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        match s.read(&mut b) {
            Ok(1) => head.push(b[0]),
            _ => break,
        }
    }
    (s, String::from_utf8_lossy(&head).into_owned())
}

impl Ws {
    fn connect(a: SocketAddr) -> Ws {
        let (s, head) = handshake(a, Some("foxglove.websocket.v1"));
        assert!(head.starts_with("HTTP/1.1 101"), "{head}");
        Ws { s, buf: Vec::new() }
    }

    fn send(&mut self, op: u8, payload: &[u8]) {
        let mask = [1u8, 2, 3, 4];
        let mut f = vec![0x80 | op];
        match payload.len() {
            n if n < 126 => f.push(0x80 | n as u8),
            n if n < 65536 => {
                f.push(0x80 | 126);
                f.extend_from_slice(&(n as u16).to_be_bytes());
            }
            n => {
                f.push(0x80 | 127);
                f.extend_from_slice(&(n as u64).to_be_bytes());
            }
        }
        f.extend_from_slice(&mask);
        f.extend(payload.iter().enumerate().map(|(i, b)| b ^ mask[i % 4]));
        self.s.write_all(&f).unwrap();
    }

    fn text(&mut self, j: &Value) {
        self.send(1, j.to_string().as_bytes());
    }

    fn fill(&mut self, n: usize) -> bool {
        let mut chunk = vec![0u8; 64 * 1024];
        while self.buf.len() < n {
            match self.s.read(&mut chunk) {
                Ok(0) | Err(_) => return false,
                Ok(k) => self.buf.extend_from_slice(&chunk[..k]),
            }
        }
        true
    }

    /// The next frame: (opcode, payload); None when the connection ends.
    fn recv(&mut self) -> Option<(u8, Vec<u8>)> {
        if !self.fill(2) {
            return None;
        }
        let op = self.buf[0] & 0x0f;
        let (len, at) = match self.buf[1] & 0x7f {
            126 => {
                self.fill(4);
                (u16::from_be_bytes([self.buf[2], self.buf[3]]) as usize, 4)
            }
            127 => {
                self.fill(10);
                (
                    u64::from_be_bytes(self.buf[2..10].try_into().unwrap()) as usize,
                    10,
                )
            }
            n => (n as usize, 2),
        };
        if !self.fill(at + len) {
            return None;
        }
        let payload = self.buf[at..at + len].to_vec();
        self.buf.drain(..at + len);
        Some((op, payload))
    }

    /// JSON messages until `f` says done (binary ones skipped), within 5 s.
    fn until(&mut self, mut f: impl FnMut(&Value) -> bool) -> Value {
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(5) {
            let (op, p) = self.recv().expect("a message");
            if op == 1 {
                let j: Value = serde_json::from_slice(&p).unwrap();
                if f(&j) {
                    return j;
                }
            }
        }
        panic!("no such message within 5 s");
    }

    /// Subscribes to `topic` (from the advertise message): the channel id.
    fn subscribe(&mut self, topic: &str, sub: u32) -> u64 {
        let adv = self.until(|j| {
            j["op"] == "advertise"
                && j["channels"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|c| c["topic"] == topic)
        });
        let id = adv["channels"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["topic"] == topic)
            .unwrap()["id"]
            .as_u64()
            .unwrap();
        self.text(&serde_json::json!({"op": "subscribe", "subscriptions": [{"id": sub, "channelId": id}]}));
        id
    }
}

fn start(extra: &str) -> (Arc<Runtime>, SocketAddr) {
    let rt = common::start_conf(&conf(extra));
    let a = addr(&rt);
    (rt, a)
}

#[test]
fn subprotocols_garbage_and_oversized_messages() {
    let (rt, a) = start("max_message 4096\n");
    // The SDK's own name passes unchanged.
    let (_s, head) = handshake(a, Some("foxglove.sdk.v1"));
    assert!(head.starts_with("HTTP/1.1 101"), "{head}");
    assert!(
        head.to_ascii_lowercase()
            .contains("sec-websocket-protocol: foxglove.sdk.v1"),
        "{head}"
    );
    // No subprotocol: the SDK's 400.
    let (_s, head) = handshake(a, None);
    assert!(head.starts_with("HTTP/1.1 400"), "{head}");
    // Not HTTP at all: 400 from the relay.
    let mut s = TcpStream::connect(a).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    s.write_all(b"\x00\x01garbage\r\n\r\n").unwrap();
    let mut reply = String::new();
    let _ = s.read_to_string(&mut reply);
    assert!(reply.starts_with("HTTP/1.1 400"), "{reply}");
    // Garbage JSON: told by an error status, connection kept.
    let mut ws = Ws::connect(a);
    ws.text(&Value::from("not an op"));
    ws.send(1, b"{{{ not json");
    let st = ws.until(|j| j["op"] == "status");
    assert_eq!(st["level"], 2, "{st}");
    // A binary message of an unknown opcode and data on a channel never advertised.
    ws.send(2, &[0x7f, 1, 2, 3]);
    ws.send(2, &[0x01, 9, 9, 9, 9, 1, 2]);
    let st = ws.until(|j| {
        j["op"] == "status"
            && j["message"]
                .as_str()
                .unwrap_or("")
                .contains("nknown channel")
    });
    assert_eq!(st["level"], 2, "{st}");
    // Oversized: closed with 1009.
    ws.send(2, &vec![1u8; 8192]);
    let mut closed = None;
    while let Some((op, p)) = ws.recv() {
        if op == 8 {
            closed = Some(u16::from_be_bytes([p[0], p[1]]));
            break;
        }
    }
    assert_eq!(closed, Some(1009));
    common::eventually("refused in ps", || {
        ps(&rt).contains("refused") && !ps(&rt).contains(" 0 refused")
    });
    // A Twist in a foreign encoding, and a Twist that is not one: told, motors untouched.
    let mut ws = Ws::connect(a);
    ws.text(&serde_json::json!({"op": "advertise", "channels": [
        {"id": 1, "topic": "/cmd_vel", "encoding": "cdr", "schemaName": "geometry_msgs/msg/Twist"},
        {"id": 2, "topic": "/cmd_vel", "encoding": "json", "schemaName": "geometry_msgs/msg/Twist"}]}));
    std::thread::sleep(Duration::from_millis(200));
    ws.send(2, &[&[1u8, 1, 0, 0, 0][..], b"\x00\x01"].concat());
    let st =
        ws.until(|j| j["op"] == "status" && j["message"].as_str().unwrap().contains("only json"));
    assert_eq!(st["level"], 2);
    ws.send(2, &[&[1u8, 2, 0, 0, 0][..], br#"{"linear": 5}"#].concat());
    ws.until(|j| j["op"] == "status" && j["message"].as_str().unwrap().contains("Twist"));
    rt.shutdown();
}

#[test]
fn jpeg_images_and_parameters_set_an_actuator() {
    let (rt, a) = start("images jpeg 50\n");
    rt.stop("introrob").unwrap();
    let mut ws = Ws::connect(a);
    let adv = ws.until(|j| j["op"] == "advertise");
    let cam = adv["channels"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["topic"] == "colorA")
        .unwrap()
        .clone();
    assert_eq!(cam["schemaName"], "foxglove.CompressedImage", "{cam}");
    let id = cam["id"].as_u64().unwrap();
    ws.text(&serde_json::json!({"op": "subscribe", "subscriptions": [{"id": 3, "channelId": id}]}));
    let t0 = Instant::now();
    let frame = loop {
        assert!(t0.elapsed() < Duration::from_secs(5), "no JPEG frame");
        let (op, p) = ws.recv().unwrap();
        if op == 2 && p[0] == 1 && u32::from_le_bytes(p[1..5].try_into().unwrap()) == 3 {
            break p;
        }
    };
    // The message carries a JPEG (SOI marker) inside its protobuf.
    assert!(
        frame.windows(3).any(|w| w == [0xff, 0xd8, 0xff]),
        "no JPEG in the message"
    );
    // Parameters: set motors.v as `set motors v=...` does; read encoders as `echo` does.
    ws.text(&serde_json::json!({"op": "setParameters", "id": "s1", "parameters": [{"name": "motors.v", "value": 123.0}]}));
    let pv = ws.until(|j| j["op"] == "parameterValues" && j["id"] == "s1");
    assert!(
        pv["parameters"][0]["value"]
            .as_str()
            .unwrap()
            .contains("v=123.0"),
        "{pv}"
    );
    let m = rt.interfaces.get::<Motors>("motors").unwrap();
    assert_eq!(m.snapshot().v, 123.0);
    ws.text(&serde_json::json!({"op": "setParameters", "id": "s2", "parameters": [{"name": "laser.v", "value": 1.0}]}));
    let pv = ws.until(|j| j["op"] == "parameterValues" && j["id"] == "s2");
    assert_eq!(
        pv["parameters"].as_array().map(Vec::len),
        Some(0),
        "a sensor is not set: {pv}"
    );
    ws.text(
        &serde_json::json!({"op": "getParameters", "id": "g1", "parameterNames": ["encoders"]}),
    );
    let pv = ws.until(|j| j["op"] == "parameterValues" && j["id"] == "g1");
    assert!(
        pv["parameters"][0]["value"]
            .as_str()
            .unwrap()
            .contains("theta="),
        "{pv}"
    );
    rt.shutdown();
}

fn rss_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .unwrap()
        .lines()
        .find(|l| l.starts_with("VmRSS:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(0)
}

/// The log times (ns) of the message-data frames of subscription `sub` read
/// within `secs` (ws-protocol spec: Message Data is opcode 0x01, subscription id
/// u32, log time u64, little endian).
fn frame_times(ws: &mut Ws, sub: u32, secs: f64) -> Vec<u64> {
    let t0 = Instant::now();
    let mut times = Vec::new();
    ws.s.set_read_timeout(Some(Duration::from_millis(500)))
        .unwrap();
    while t0.elapsed().as_secs_f64() < secs {
        let Some((op, p)) = ws.recv() else { break };
        if op == 2 && p[0] == 1 && u32::from_le_bytes(p[1..5].try_into().unwrap()) == sub {
            times.push(u64::from_le_bytes(p[5..13].try_into().unwrap()));
        }
    }
    times
}

fn max_gap_s(times: &[u64]) -> f64 {
    times
        .windows(2)
        .map(|w| w[1].saturating_sub(w[0]) as f64 / 1e9)
        .fold(0.0, f64::max)
}

#[test]
fn a_client_that_stops_reading_loses_only_its_own_frames() {
    if common::ran_in_own_process("foxglove::a_client_that_stops_reading_loses_only_its_own_frames")
    {
        return;
    }
    let (rt, a) = start("max_queue 4\nserves colorA\nserves encoders\nserves motors\n");
    rt.stop("introrob").unwrap();
    // The slow client subscribes to the camera and stops reading for 8 s (longer
    // than the kernel's buffers on the way take at the camera's rate).
    let mut slow = Ws::connect(a);
    slow.subscribe("colorA", 1);
    // A fast one reads the camera meanwhile.
    let mut fast = Ws::connect(a);
    fast.subscribe("colorA", 7);
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let clock0 = enc.clock();
    let rss0 = rss_kb();
    let secs = 8.0;
    let fast_times = frame_times(&mut fast, 7, secs);
    let rss1 = rss_kb();
    assert!(
        fast_times.len() as f64 > 4.0 * secs,
        "the fast client got {} frames in {secs:.1} s",
        fast_times.len()
    );
    assert!(
        max_gap_s(&fast_times) < 1.0,
        "the fast client lost frames: a gap of {:.2} s",
        max_gap_s(&fast_times)
    );
    // The slow one now reads: what waited in the buffers, then a jump over the
    // frames its backlog dropped (only its own), then live frames.
    let slow_times = frame_times(&mut slow, 1, 1.5);
    assert!(
        max_gap_s(&slow_times) > 1.0,
        "the slow client's frames show no loss ({} frames, widest gap {:.2} s)",
        slow_times.len(),
        max_gap_s(&slow_times)
    );
    // Its memory is bounded: the backlog (4 frames of 230 kB), a pipe and sockets.
    assert!(
        rss1 < rss0 + 64 * 1024,
        "RSS {rss0} kB -> {rss1} kB with a client that does not read"
    );
    // The robot's own clocks went on (the simulator at its rate).
    assert!(
        enc.clock() > clock0 + 20,
        "encoders {} -> {}",
        clock0,
        enc.clock()
    );
    rt.shutdown();
}

#[test]
fn connect_cycles_leave_memory_where_it_was() {
    if common::ran_in_own_process("foxglove::connect_cycles_leave_memory_where_it_was") {
        return;
    }
    let (rt, a) = start("serves laser\nserves encoders\n");
    let laser = rt.interfaces.get_any("laser").unwrap();
    let cycle = || {
        let mut ws = Ws::connect(a);
        ws.subscribe("laser", 1);
        let _ = ws.recv();
    };
    for _ in 0..20 {
        cycle();
    }
    std::thread::sleep(Duration::from_millis(300));
    let before = rss_kb();
    let users0 = laser.users();
    // 300 cycles under 8 MB: a leak of 27 kB a connection shows.
    for _ in 0..300 {
        cycle();
    }
    common::eventually("every client gone", || ps(&rt).contains(": 0 client(s)"));
    std::thread::sleep(Duration::from_millis(300));
    let after = rss_kb();
    assert!(
        after < before + 8192,
        "RSS {before} kB -> {after} kB after 300 connect/disconnect cycles"
    );
    // The laser is suspended again once nobody subscribes.
    common::eventually("laser back to its own users", || laser.users() == users0);
    rt.shutdown();
}

/// A non-loopback address of this machine (the route's source address), if any.
fn non_loopback_ip() -> Option<std::net::IpAddr> {
    let u = std::net::UdpSocket::bind("0.0.0.0:0").ok()?;
    u.connect("10.255.255.254:9").ok()?;
    let ip = u.local_addr().ok()?.ip();
    (!ip.is_loopback() && !ip.is_unspecified()).then_some(ip)
}

#[test]
fn sdk_port_is_a_second_door_to_the_same_server() {
    let (rt, relay) = start("sdk_port 0\n");
    rt.stop("introrob").unwrap();
    let a = *rt
        .names
        .import::<SocketAddr>("foxglove", "sdk_address")
        .expect("with sdk_port, foxglove exports the SDK server's address");
    assert_ne!(a.port(), relay.port());
    assert!(a.ip().is_loopback(), "{a}");
    assert!(
        ps(&rt).contains(&format!("also ws://{a} (sdk_port)")),
        "{}",
        ps(&rt)
    );
    // The spec's subprotocol, answered by the SDK.
    let (s, head) = handshake(a, Some("foxglove.sdk.v1"));
    assert!(head.starts_with("HTTP/1.1 101"), "{head}");
    assert!(
        head.to_ascii_lowercase()
            .contains("sec-websocket-protocol: foxglove.sdk.v1"),
        "{head}"
    );
    let mut ws = Ws { s, buf: Vec::new() };
    let info = ws.until(|j| j["op"] == "serverInfo");
    assert_eq!(info["name"], "jderobot", "{info}");
    // Channels listed; a subscription gets frames (and resumes the camera).
    let id = ws.subscribe("colorA", 7);
    assert!(id > 0);
    let t0 = Instant::now();
    let mut frames = 0;
    while frames < 3 {
        assert!(t0.elapsed() < Duration::from_secs(10), "{frames} frame(s)");
        let (op, p) = ws.recv().expect("a frame");
        if op == 2 && p[0] == 1 && u32::from_le_bytes(p[1..5].try_into().unwrap()) == 7 {
            assert!(p.len() > 320 * 240 * 3, "a RawImage of {} bytes", p.len());
            frames += 1;
        }
    }
    // Teleop the same as through the relay; leaving zeroes the motors.
    ws.text(&serde_json::json!({"op": "advertise", "channels": [
        {"id": 1, "topic": "/cmd_vel", "encoding": "json", "schemaName": "geometry_msgs/msg/Twist"}]}));
    std::thread::sleep(Duration::from_millis(200));
    let twist = br#"{"linear":{"x":0.3,"y":0,"z":0},"angular":{"x":0,"y":0,"z":0.1}}"#;
    ws.send(2, &[&[1u8, 1, 0, 0, 0][..], twist].concat());
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    common::eventually("the Twist drove the motors", || {
        (motors.snapshot().v - 300.0).abs() < 1e-6
    });
    drop(ws);
    common::eventually("motors zeroed after the direct client left", || {
        let m = motors.snapshot();
        m.v == 0.0 && m.w == 0.0
    });
    // The default loopback `bind`: the direct port is not reachable from outside it.
    match non_loopback_ip() {
        Some(ip) => assert!(
            TcpStream::connect_timeout(&SocketAddr::new(ip, a.port()), Duration::from_secs(2))
                .is_err(),
            "the SDK's port answered on {ip}, beyond loopback"
        ),
        None => eprintln!("note: no non-loopback address here; the reachability check is skipped"),
    }
    rt.shutdown();
}

// ---- Hostile peers (issue 38): caps, bounds in time and memory, absurd values, tokens.

/// Advertises `/cmd_vel` (client publish, ws-protocol spec "Client Advertise").
fn advertise_twist(ws: &mut Ws) {
    ws.text(&serde_json::json!({"op": "advertise", "channels": [
        {"id": 1, "topic": "/cmd_vel", "encoding": "json", "schemaName": "geometry_msgs/msg/Twist"}]}));
    std::thread::sleep(Duration::from_millis(200));
}

/// Publishes a Twist of linear.x `x` m/s on the advertised `/cmd_vel`.
fn twist(ws: &mut Ws, x: f64) {
    let body = serde_json::json!({"linear": {"x": x, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0}});
    ws.send(
        2,
        &[&[1u8, 1, 0, 0, 0][..], body.to_string().as_bytes()].concat(),
    );
}

/// The robot's `motors_timeout` plus one cycle of its driver: how soon a stop must land.
const STOP_WITHIN: Duration = Duration::from_millis(500 + 100);

/// A good client drives and then stops the robot: the time the stop took to reach `motors`.
fn drive_then_stop(a: SocketAddr, rt: &Runtime) -> Duration {
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    let mut ws = Ws::connect(a);
    ws.until(|j| j["op"] == "serverInfo");
    advertise_twist(&mut ws);
    twist(&mut ws, 0.25);
    common::eventually("the Twist drove the motors", || {
        (motors.snapshot().v - 250.0).abs() < 1e-3
    });
    let t0 = Instant::now();
    twist(&mut ws, 0.0);
    while motors.snapshot().v != 0.0 {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "the stop never came"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
    t0.elapsed()
}

#[test]
fn idle_clients_cannot_lock_out_a_good_one() {
    let (rt, a) = start("max_clients 8\n");
    rt.stop("introrob").unwrap();
    // Strangers: 20 TCP connections that say nothing, 10 WebSocket clients that
    // upgrade and then idle.
    let mut idle: Vec<TcpStream> = (0..20).map(|_| TcpStream::connect(a).unwrap()).collect();
    for _ in 0..10 {
        idle.push(handshake(a, Some("foxglove.sdk.v1")).0);
    }
    std::thread::sleep(Duration::from_millis(300));
    // A good client still gets in, drives, and its stop lands in time.
    let took = drive_then_stop(a, &rt);
    assert!(took <= STOP_WITHIN, "the stop took {took:?}");
    assert!(
        !ps(&rt).contains(" 0 evicted"),
        "the cap closed idle ones: {}",
        ps(&rt)
    );
    // Of the strangers, at most the cap's worth are still open.
    let still_open = |s: &mut TcpStream| {
        s.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
        let mut b = [0u8; 4096];
        loop {
            match s.read(&mut b) {
                Ok(0) => return false,
                Ok(_) => continue,
                Err(e) => return e.kind() == std::io::ErrorKind::WouldBlock,
            }
        }
    };
    let open = idle.iter_mut().map(still_open).filter(|o| *o).count();
    assert!(
        open <= 8,
        "{open} idle connections still open over a cap of 8"
    );
    rt.shutdown();
}

/// Open descriptors of this process.
fn open_fds() -> u64 {
    std::fs::read_dir("/proc/self/fd")
        .map(|d| d.count() as u64)
        .unwrap_or(0)
}

#[test]
fn the_door_and_the_sdk_keep_accepting_after_running_out_of_descriptors() {
    // In a child process of its own: it lowers the limit of open files.
    if std::env::var_os("JDEROBOT_FOXGLOVE_FD_CHILD").is_none() {
        // This test's name as the harness knows it (a module of a suite, or alone).
        let me = "the_door_and_the_sdk_keep_accepting_after_running_out_of_descriptors";
        let name = match module_path!().split_once("::") {
            Some((_, m)) => format!("{m}::{me}"),
            None => me.to_string(),
        };
        let out = Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                name.as_str(),
                "--nocapture",
                "--test-threads",
                "1",
            ])
            .env("JDEROBOT_FOXGLOVE_FD_CHILD", "1")
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout).into_owned()
            + &String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "the child failed:\n{text}");
        assert!(text.contains("1 passed"), "{text}");
        return;
    }
    let (rt, a) = start("max_clients 4096\n");
    rt.stop("introrob").unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let limit = |n: u64| {
        let l = libc::rlimit {
            rlim_cur: n,
            rlim_max: n.max(20000),
        };
        // SAFETY: setrlimit with a struct we own.
        unsafe { libc::setrlimit(libc::RLIMIT_NOFILE, &l) };
    };
    let mut hard = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit into a struct we own.
    unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut hard) };
    limit(open_fds() + 60);
    // Upgraded clients until the process runs out: each takes four descriptors
    // (ours, the door's, the door's to the SDK, the SDK's).
    let mut strangers = Vec::new();
    for _ in 0..200 {
        match TcpStream::connect(a) {
            Ok(mut s) => {
                s.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
                let _ = write!(
                    s,
                    "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
                     Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\
                     Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
                );
                strangers.push(s);
            }
            Err(_) => break,
        }
    }
    std::thread::sleep(Duration::from_secs(1));
    drop(strangers);
    limit(hard.rlim_cur.max(1024));
    std::thread::sleep(Duration::from_millis(500));
    // A good client gets in on the same port and drives the robot.
    let took = drive_then_stop(a, &rt);
    assert!(took <= STOP_WITHIN, "the stop took {took:?}");
    rt.shutdown();
}

#[test]
fn unfinished_messages_and_ping_floods_are_bounded_in_time_and_memory() {
    if common::ran_in_own_process(
        "foxglove::unfinished_messages_and_ping_floods_are_bounded_in_time_and_memory",
    ) {
        return;
    }
    let (rt, a) = start("max_message 65536\n");
    rt.stop("introrob").unwrap();
    let rss0 = rss_kb();
    // 10 clients each start a fragmented message (a 60 kB first fragment, RFC 6455
    // §5.4: FIN clear) and never finish it.
    let mut stuck: Vec<Ws> = (0..10)
        .map(|_| {
            let mut ws = Ws::connect(a);
            let mut f = vec![0x02u8, 0x80 | 126];
            f.extend_from_slice(&60_000u16.to_be_bytes());
            f.extend_from_slice(&[0, 0, 0, 0]);
            f.extend(std::iter::repeat_n(0u8, 60_000));
            ws.s.write_all(&f).unwrap();
            ws
        })
        .collect();
    // 4 clients flood pings (§5.5.2) without reading.
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flooders: Vec<_> = (0..4)
        .map(|_| {
            let mut ws = Ws::connect(a);
            let stop = stop.clone();
            std::thread::spawn(move || {
                let ping = [0x89u8, 0x80 | 4, 0, 0, 0, 0, 1, 2, 3, 4];
                let burst: Vec<u8> = ping
                    .iter()
                    .copied()
                    .cycle()
                    .take(ping.len() * 100)
                    .collect();
                let mut sent = 0u64;
                while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                    if ws.s.write_all(&burst).is_err() {
                        return (sent, true);
                    }
                    sent += 100;
                }
                (sent, false)
            })
        })
        .collect();
    // Meanwhile a good client's stop lands in time.
    let took = drive_then_stop(a, &rt);
    assert!(
        took <= STOP_WITHIN,
        "the stop took {took:?} during the attack"
    );
    // The flooders are closed (1008), each after at most a second's worth of pings.
    std::thread::sleep(Duration::from_secs(2));
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    for f in flooders {
        let (sent, closed) = f.join().unwrap();
        assert!(closed, "a ping flood of {sent} pings was not closed");
    }
    // The unfinished messages are closed (1008) within 10 s and a little.
    let t0 = Instant::now();
    for ws in &mut stuck {
        ws.s.set_read_timeout(Some(Duration::from_secs(15)))
            .unwrap();
        let mut code = None;
        while let Some((op, p)) = ws.recv() {
            if op == 8 {
                code = Some(u16::from_be_bytes([p[0], p[1]]));
                break;
            }
        }
        assert_eq!(code, Some(1008), "an unfinished message was not closed");
    }
    assert!(t0.elapsed() < Duration::from_secs(13), "{:?}", t0.elapsed());
    let rss1 = rss_kb();
    assert!(
        rss1 < rss0 + 48 * 1024,
        "RSS {rss0} kB -> {rss1} kB during the attack"
    );
    rt.shutdown();
}

#[test]
fn absurd_motor_values_are_refused_on_every_path() {
    let (rt, a) = start("");
    rt.stop("introrob").unwrap();
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    let mut ws = Ws::connect(a);
    advertise_twist(&mut ws);
    twist(&mut ws, 0.2);
    common::eventually("a sane Twist drives", || {
        (motors.snapshot().v - 200.0).abs() < 1e-3
    });
    // A Twist of 1e30 m/s, and a jderobot value of ±3.4e38: told, motors untouched.
    twist(&mut ws, 1e30);
    ws.until(|j| {
        j["op"] == "status" && j["level"] == 2 && j["message"].as_str().unwrap().contains("motors")
    });
    ws.text(&serde_json::json!({"op": "advertise", "channels": [
        {"id": 2, "topic": "motors", "encoding": "json", "schemaName": "jderobot.motors"}]}));
    std::thread::sleep(Duration::from_millis(200));
    let v = br#"{"v":-3.4e38,"w":3.4e38}"#;
    ws.send(2, &[&[1u8, 2, 0, 0, 0][..], v].concat());
    ws.until(|j| {
        j["op"] == "status" && j["level"] == 2 && j["message"].as_str().unwrap().contains("motors")
    });
    // The parameter path.
    ws.text(&serde_json::json!({"op": "setParameters", "id": "p", "parameters": [{"name": "motors.v", "value": 1e38}]}));
    let pv = ws.until(|j| j["op"] == "parameterValues" && j["id"] == "p");
    assert_eq!(pv["parameters"].as_array().map(Vec::len), Some(0), "{pv}");
    let m = motors.snapshot();
    assert!(
        (m.v - 200.0).abs() < 1e-3 && m.w == 0.0,
        "motors {m:?} after absurd commands"
    );
    rt.shutdown();
}

#[test]
fn a_token_is_asked_for_and_a_bind_beyond_loopback_needs_one() {
    let (rt, a) = start("token 7f3a9c2e5b8d4f16a0c3e9b2d7f14a68\nsdk_port 0\n");
    let (_s, head) = handshake_at(a, "/", Some("foxglove.sdk.v1"));
    assert!(head.starts_with("HTTP/1.1 401"), "{head}");
    let (_s, head) = handshake_at(a, "/?token=wrong", Some("foxglove.sdk.v1"));
    assert!(head.starts_with("HTTP/1.1 401"), "{head}");
    let (_s, head) = handshake_at(
        a,
        "/?token=7f3a9c2e5b8d4f16a0c3e9b2d7f14a68",
        Some("foxglove.websocket.v1"),
    );
    assert!(head.starts_with("HTTP/1.1 101"), "{head}");
    // The second port asks for it too.
    let b = *rt
        .names
        .import::<SocketAddr>("foxglove", "sdk_address")
        .unwrap();
    let (_s, head) = handshake_at(b, "/", Some("foxglove.sdk.v1"));
    assert!(head.starts_with("HTTP/1.1 401"), "{head}");
    rt.shutdown();
    // Beyond loopback without a token: the service does not start, and says how.
    let e = common::start_error(&conf("bind 0.0.0.0\n"));
    assert!(e.contains("token SECRET") && e.contains("insecure"), "{e}");
}

/// Runs the official client (`tests/foxglove_node/client.js`, in `dir`) against
/// `url`, trusting `ca` for wss; it must succeed and print one JSON report.
fn run_node_client(dir: &std::path::Path, url: &str, ca: Option<&std::path::Path>) -> Value {
    let mut node = Command::new("node");
    node.arg(dir.join("client.js")).arg(url).current_dir(dir);
    if let Some(ca) = ca {
        node.env("NODE_EXTRA_CA_CERTS", ca);
    }
    let out = node.output().expect("run node");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "client.js {url} failed: {}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(stdout.trim()).expect("one JSON report")
}

/// A CA and a server certificate for 127.0.0.1 signed by it, made with openssl
/// in `d`: (ca.pem, server.pem, server.key).
fn make_certs(d: &std::path::Path) -> (PathBuf, PathBuf, PathBuf) {
    common::certs::ca(d, "ca");
    common::certs::signed(d, "robot", "ca");
    (d.join("ca.pem"), d.join("robot.pem"), d.join("robot.key"))
}

/// A TLS client (rustls, trusting only `ca`) connected to `a` as `127.0.0.1`.
fn tls_connect(
    a: SocketAddr,
    ca: &std::path::Path,
) -> std::io::Result<
    tokio_rustls::rustls::StreamOwned<tokio_rustls::rustls::ClientConnection, TcpStream>,
> {
    use tokio_rustls::rustls::{
        self, ClientConfig, RootCertStore,
        pki_types::{CertificateDer, ServerName, pem::PemObject},
    };
    let mut roots = RootCertStore::empty();
    for c in CertificateDer::pem_file_iter(ca).unwrap() {
        roots.add(c.unwrap()).unwrap();
    }
    let config =
        ClientConfig::builder_with_provider(Arc::new(rustls::crypto::ring::default_provider()))
            .with_safe_default_protocol_versions()
            .unwrap()
            .with_root_certificates(roots)
            .with_no_client_auth();
    let name = ServerName::try_from("127.0.0.1").unwrap();
    let conn = rustls::ClientConnection::new(Arc::new(config), name).unwrap();
    let s = TcpStream::connect(a)?;
    s.set_read_timeout(Some(Duration::from_secs(5)))?;
    let mut tls = rustls::StreamOwned::new(conn, s);
    while tls.conn.is_handshaking() {
        tls.conn.complete_io(&mut tls.sock)?;
    }
    Ok(tls)
}

/// The upgrade request for `path` over any stream, and the answer's head with
/// what came after it within 2 s.
fn upgrade_over<S: Read + Write>(s: &mut S, path: &str, protocol: &str) -> (String, Vec<u8>) {
    // A write may fail: a TLS port closes on a plain request.
    let _ = write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\
         Sec-WebSocket-Protocol: {protocol}\r\n\r\n"
    );
    let _ = s.flush();
    let mut got = Vec::new();
    let mut b = [0u8; 4096];
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(2) && !got.windows(10).any(|w| w == b"serverInfo") {
        match s.read(&mut b) {
            Ok(0) | Err(_) => break,
            Ok(n) => got.extend_from_slice(&b[..n]),
        }
    }
    let end = got
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .map_or(got.len(), |i| i + 4);
    let rest = got.split_off(end);
    (String::from_utf8_lossy(&got).into_owned(), rest)
}

/// Issue 38: Foxglove over TLS. Beyond loopback the service wants `tls` and
/// `token` both; with them, both ports speak wss:// only: a rustls client that
/// trusts the test's CA upgrades with the token and gets serverInfo, without it
/// gets 401; a plain ws:// client gets no upgrade; and the official client
/// (`@foxglove/ws-protocol` on Node's `ws`, trusting the CA through
/// NODE_EXTRA_CA_CERTS) lists, decodes and drives over wss://.
#[test]
fn wss_with_a_token_serves_beyond_loopback_and_plain_ws_gets_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (ca, cert, key) = make_certs(dir.path());
    let tls = format!("tls {} {}\n", cert.display(), key.display());
    // Beyond loopback: a token alone, or TLS alone, is not enough.
    let e = common::start_error(&conf(
        "bind 0.0.0.0\ntoken 7f3a9c2e5b8d4f16a0c3e9b2d7f14a68\n",
    ));
    assert!(e.contains("add `tls CERT.pem KEY.pem` too"), "{e}");
    let e = common::start_error(&conf(&format!("bind 0.0.0.0\n{tls}")));
    assert!(e.contains("add `token SECRET` too"), "{e}");
    // A key that does not go with the certificate is said at the `tls` line.
    let bad = format!(
        "tls {} {}\n",
        cert.display(),
        dir.path().join("ca.key").display()
    );
    let e = common::start_error(&conf(&bad));
    assert!(
        e.contains("test.conf:") && e.contains("does not go with"),
        "{e}"
    );

    let rt = common::start_conf(&conf(&format!(
        "bind 0.0.0.0\ntoken 7f3a9c2e5b8d4f16a0c3e9b2d7f14a68\n{tls}sdk_port 0\n"
    )));
    let port = addr(&rt).port();
    let a = SocketAddr::from(([127, 0, 0, 1], port));
    assert!(ps(&rt).contains("foxglove: wss://"), "{}", ps(&rt));
    // Plain ws:// on the TLS port: no upgrade.
    let mut plain = TcpStream::connect(a).unwrap();
    plain
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    let (head, _) = upgrade_over(
        &mut plain,
        "/?token=7f3a9c2e5b8d4f16a0c3e9b2d7f14a68",
        "foxglove.websocket.v1",
    );
    assert!(!head.contains(" 101 "), "plain ws on the TLS port: {head}");
    // wss:// without the token: 401; with it: 101 and serverInfo, on both ports.
    let mut t = tls_connect(a, &ca).expect("a TLS handshake");
    let (head, _) = upgrade_over(&mut t, "/", "foxglove.websocket.v1");
    assert!(head.starts_with("HTTP/1.1 401"), "{head}");
    let b = *rt
        .names
        .import::<SocketAddr>("foxglove", "sdk_address")
        .unwrap();
    for port in [port, b.port()] {
        let at = SocketAddr::from(([127, 0, 0, 1], port));
        let mut t = tls_connect(at, &ca).expect("a TLS handshake");
        let (head, rest) = upgrade_over(
            &mut t,
            "/?token=7f3a9c2e5b8d4f16a0c3e9b2d7f14a68",
            "foxglove.websocket.v1",
        );
        assert!(head.starts_with("HTTP/1.1 101"), "{at}: {head}");
        assert!(
            String::from_utf8_lossy(&rest).contains("\"serverInfo\""),
            "{at}: no serverInfo over TLS"
        );
    }
    // The official client over wss://.
    if let Some(dir) = node_client() {
        let r = run_node_client(
            &dir,
            &format!("wss://127.0.0.1:{port}/?token=7f3a9c2e5b8d4f16a0c3e9b2d7f14a68"),
            Some(&ca),
        );
        assert_eq!(r["protocol"], "foxglove.websocket.v1", "{r}");
        assert!(r["counts"]["laser"].as_u64().unwrap_or(0) > 0, "{r}");
        assert!(r["twists"].as_u64().unwrap_or(0) > 0, "{r}");
    }
    rt.shutdown();
}

/// TCP ports this process listens on (`/proc/self/net/tcp{,6}` rows in state LISTEN
/// whose socket is one of this process's descriptors).
fn listening_ports() -> Vec<u16> {
    let mine: std::collections::HashSet<String> = common::socket_inodes(std::process::id())
        .into_iter()
        .collect();
    let mut ports = Vec::new();
    for table in ["/proc/self/net/tcp", "/proc/self/net/tcp6"] {
        for row in std::fs::read_to_string(table)
            .unwrap_or_default()
            .lines()
            .skip(1)
        {
            let f: Vec<&str> = row.split_whitespace().collect();
            // local_address is ADDR:PORT in hex; state 0A is LISTEN; the inode is field 9.
            if f.len() > 9 && f[3] == "0A" && mine.contains(f[9]) {
                let port = f[1].rsplit(':').next().unwrap();
                ports.push(u16::from_str_radix(port, 16).unwrap());
            }
        }
    }
    ports.sort_unstable();
    ports
}

/// The SDK's server binds no port of its own (the vendored SDK's
/// `handed_streams_only`): the only ports are the door's, `port` and `sdk_port`,
/// so no connection reaches the SDK around the door's token and cap. In a process
/// of its own, so the listening sockets are this service's only.
#[test]
fn the_sdk_listens_on_no_port_of_its_own() {
    if common::ran_in_own_process("foxglove::the_sdk_listens_on_no_port_of_its_own") {
        return;
    }
    let (rt, a) = start("token 7f3a9c2e5b8d4f16a0c3e9b2d7f14a68\nsdk_port 0\n");
    let direct = *rt
        .names
        .import::<SocketAddr>("foxglove", "sdk_address")
        .expect("with sdk_port, foxglove exports its address");
    let mut doors = vec![a.port(), direct.port()];
    doors.sort_unstable();
    assert_eq!(
        listening_ports(),
        doors,
        "the door's two ports and no other"
    );
    rt.shutdown();
}
