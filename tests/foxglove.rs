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

#[test]
fn the_official_client_lists_decodes_drives_and_stops_a_schema() {
    let Some(dir) = node_client() else { return };
    let rt = common::start_conf(&conf(""));
    let a = addr(&rt);
    assert!(a.ip().is_loopback(), "loopback by default: {a}");
    let out = Command::new("node")
        .arg(dir.join("client.js"))
        .arg(format!("ws://{a}"))
        .current_dir(&dir)
        .output()
        .expect("run node");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "client.js failed: {}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: Value = serde_json::from_str(stdout.trim()).expect("one JSON report");
    // The legacy subprotocol, answered under its own name.
    assert_eq!(r["protocol"], "foxglove.websocket.v1");
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
    // Channels with Foxglove's schemas.
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
    assert_eq!(
        schema("laser"),
        ("protobuf".into(), "foxglove.LaserScan".into())
    );
    assert_eq!(
        schema("sonars"),
        ("protobuf".into(), "foxglove.LaserScan".into())
    );
    assert_eq!(
        schema("colorA"),
        ("protobuf".into(), "foxglove.RawImage".into())
    );
    assert_eq!(
        schema("encoders"),
        ("protobuf".into(), "foxglove.PoseInFrame".into())
    );
    assert_eq!(
        schema("/tf"),
        ("protobuf".into(), "foxglove.FrameTransform".into())
    );
    assert_eq!(
        schema("world"),
        ("protobuf".into(), "foxglove.SceneUpdate".into())
    );
    assert_eq!(schema("motors"), ("json".into(), "jderobot.motors".into()));
    assert_eq!(
        schema("bumpers"),
        ("json".into(), "jderobot.bumpers".into())
    );
    // Decoded with the advertised schemas.
    let d = &r["decoded"];
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
    let mut s = TcpStream::connect(a).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let proto = protocol
        .map(|p| format!("Sec-WebSocket-Protocol: {p}\r\n"))
        .unwrap_or_default();
    write!(
        s,
        "GET / HTTP/1.1\r\nHost: {a}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
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

#[test]
fn a_client_that_stops_reading_loses_only_its_own_frames() {
    let (rt, a) = start("max_queue 4\nserves colorA\nserves encoders\nserves motors\n");
    rt.stop("introrob").unwrap();
    // The slow client subscribes to the camera and never reads again.
    let mut slow = Ws::connect(a);
    slow.subscribe("colorA", 1);
    slow.s.set_read_timeout(None).unwrap();
    // A fast one reads the camera meanwhile.
    let mut fast = Ws::connect(a);
    fast.subscribe("colorA", 7);
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let clock0 = enc.clock();
    let dropped = || -> u64 {
        let p = ps(&rt);
        let line = p
            .lines()
            .find(|l| l.starts_with("foxglove:"))
            .unwrap()
            .to_string();
        line.split(", ")
            .find(|f| f.contains("dropped"))
            .and_then(|f| f.split_whitespace().next())
            .and_then(|n| n.parse().ok())
            .unwrap()
    };
    // The fast client reads until the slow one's queue has overflowed for a while
    // (its kernel buffers take a few frames first), 20 s at most.
    let t0 = Instant::now();
    let mut frames = 0;
    while (dropped() < 5 || t0.elapsed() < Duration::from_secs(2))
        && t0.elapsed() < Duration::from_secs(20)
    {
        let (op, p) = fast.recv().expect("frames keep coming");
        if op == 2 && p[0] == 1 {
            frames += 1;
        }
    }
    let secs = t0.elapsed().as_secs_f64();
    assert!(dropped() >= 5, "dropped for the slow client: {}", ps(&rt));
    assert!(
        frames as f64 > 4.0 * secs,
        "the fast client got {frames} frames in {secs:.1} s"
    );
    // The robot's own clocks went on (the simulator at its rate).
    assert!(
        enc.clock() > clock0 + 20,
        "encoders {} -> {}",
        clock0,
        enc.clock()
    );
    drop(slow);
    rt.shutdown();
}

#[test]
fn connect_cycles_leave_memory_where_it_was() {
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
    for _ in 0..100 {
        cycle();
    }
    common::eventually("every client gone", || ps(&rt).contains(": 0 client(s)"));
    std::thread::sleep(Duration::from_millis(300));
    let after = rss_kb();
    assert!(
        after < before + 4096,
        "RSS {before} kB -> {after} kB after 100 connect/disconnect cycles"
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
fn sdk_port_serves_sdk_clients_straight_from_the_sdk() {
    let (rt, relay) = start("sdk_port 0\n");
    rt.stop("introrob").unwrap();
    let a = *rt
        .names
        .import::<SocketAddr>("foxglove", "sdk_address")
        .expect("with sdk_port, foxglove exports the SDK server's address");
    assert_ne!(a.port(), relay.port());
    assert!(a.ip().is_loopback(), "{a}");
    assert!(ps(&rt).contains(&format!("direct (SDK, foxglove.sdk.v1): ws://{a}")));
    // The spec's subprotocol, answered by the SDK itself.
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
