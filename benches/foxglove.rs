//! The `foxglove` service against the Foxglove SDK's own server, in one run
//! (harness = false; medians of alternating rounds). One client, written here
//! from RFC 6455 and the ws-protocol spec, reads on loopback in both cases.
//!
//! 1. 640x480 BGR frames per second to one client. Reference: the SDK alone (a
//!    `WebSocketServer` and a `Channel<RawImage>`; a producer makes a fresh frame
//!    (a copy) every 0.25 ms on absolute deadlines, 4000 frames/s when it keeps
//!    up, and logs it, its bytes moved into the message; the client connects with
//!    `foxglove.sdk.v1`). Ours: the same producer, same pace, publishes into an
//!    image interface that the service serves, measured on both of its ports
//!    (both through the front door, which hands the socket to the service's SDK
//!    server): `port` (the client with `foxglove.websocket.v1`) and `sdk_port`
//!    (`foxglove.sdk.v1`). The three alternate in each round, their order
//!    rotating. The camera is the same on both sides (a fresh frame every
//!    0.25 ms); what differs is each program's shape: with the SDK alone the
//!    producer encodes inline (`log`), so it makes only the frames its encoding
//!    lets it (about as many as the client gets); ours publishes at the camera's
//!    pace and the service encodes on its own thread, paced to the client.
//!    `-- frames only=N` runs one server alone (0 SDK, 1 `port`, 2 `sdk_port`),
//!    7 rounds, for a profiler (`perf record -g`, `strace -c -f`). Each run also prints the frames the producer made per
//!    second and the CPU time per delivered frame of each thread (`producer`,
//!    `client`, the SDK's `tokio-rt-worker`, our `foxglove` publisher and
//!    `foxglove-io`), kernel time included (`/proc/self/task/*/schedstat`).
//! 2. Twist → `motors`: a client publishes a Twist on `/cmd_vel`; the time until
//!    the `motors` interface's clock moves (p50, p99).
//! 3. CPU of the service's threads (`foxglove`, `foxglove-io`) with 10 clients on
//!    laser (180 readings) and encoders published at 20 Hz, % of one core.
//! 4. The recorder's Foxglove encoding: our hand-written protobuf
//!    (`jderobot::mcapfmt::encode`) against the SDK's `foxglove::schemas` (prost)
//!    for the same 640x480 image and 180-reading laser samples, encodes per second;
//!    and the recorder's writer path raw to disk (benches/recorder.rs's load) with
//!    each, x real time, alternating rounds.
//!
//! Run: `cargo bench --features full --bench foxglove` (`-- frames`: part 1 only).

mod common;
use common::{cpu_by_thread, load::one_second, median, percentile};

use std::{
    collections::BTreeMap,
    io::{Read, Write},
    net::{SocketAddr, TcpStream},
    path::Path,
    sync::{
        Arc,
        atomic::{AtomicBool, AtomicU64, Ordering},
    },
    time::{Duration, Instant, SystemTime},
};

use foxglove::{
    ChannelBuilder, Context, Encode, WebSocketServer,
    bytes::Bytes,
    schemas::{LaserScan, RawImage},
};
use jderobot::{
    Runtime,
    interfaces::{Encoders, Image, Interface, Laser, Motors, Sample},
    mcapfmt::{self, Profile, Snapshot},
    services::foxglove::{Settings, relay::Limits, start},
};

const W: u32 = 640;
const H: u32 = 480;
const ROUNDS: usize = 7;
const SECS: f64 = 2.0;
/// The camera's period in part 1 (4000 frames/s, above what either server
/// delivers): both producers keep it on absolute deadlines, so both are fed alike.
const PERIOD: Duration = Duration::from_micros(250);

/// Sleeps until the next frame's deadline (a late producer starts afresh).
fn pace(next: &mut Instant) {
    *next += PERIOD;
    let now = Instant::now();
    if *next > now {
        std::thread::sleep(*next - now);
    } else if now - *next > 4 * PERIOD {
        *next = now;
    }
}

/// A minimal WebSocket client (RFC 6455) speaking the Foxglove protocol.
struct Ws {
    s: TcpStream,
    buf: Vec<u8>,
    at: usize,
}

impl Ws {
    fn connect(a: SocketAddr, protocol: &str) -> Ws {
        let mut s = TcpStream::connect(a).unwrap();
        s.set_nodelay(true).unwrap();
        write!(
            s,
            "GET / HTTP/1.1\r\nHost: {a}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
             Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\
             Sec-WebSocket-Protocol: {protocol}\r\n\r\n"
        )
        .unwrap();
        let mut head = Vec::new();
        let mut b = [0u8; 1];
        while !head.ends_with(b"\r\n\r\n") {
            s.read_exact(&mut b).unwrap();
            head.push(b[0]);
        }
        assert!(
            head.starts_with(b"HTTP/1.1 101"),
            "{}",
            String::from_utf8_lossy(&head)
        );
        Ws {
            s,
            buf: Vec::new(),
            at: 0,
        }
    }

    fn send(&mut self, op: u8, payload: &[u8]) {
        let mask = [7u8, 1, 3, 5];
        let mut f = vec![0x80 | op];
        match payload.len() {
            n if n < 126 => f.push(0x80 | n as u8),
            n => {
                f.push(0x80 | 126);
                f.extend_from_slice(&(n as u16).to_be_bytes());
            }
        }
        f.extend_from_slice(&mask);
        f.extend(payload.iter().enumerate().map(|(i, b)| b ^ mask[i % 4]));
        self.s.write_all(&f).unwrap();
    }

    fn fill(&mut self, n: usize) {
        if self.at > 0 && self.buf.len() - self.at < n {
            self.buf.drain(..self.at);
            self.at = 0;
        }
        let mut chunk = [0u8; 256 * 1024];
        while self.buf.len() - self.at < n {
            let k = self.s.read(&mut chunk).unwrap();
            assert!(k > 0, "closed");
            self.buf.extend_from_slice(&chunk[..k]);
        }
    }

    /// The next frame's opcode and payload (valid until the next call).
    fn recv(&mut self) -> (u8, &[u8]) {
        self.fill(2);
        let b = &self.buf[self.at..];
        let op = b[0] & 0x0f;
        let (len, hl) = match b[1] & 0x7f {
            126 => {
                self.fill(4);
                let b = &self.buf[self.at..];
                (u16::from_be_bytes([b[2], b[3]]) as usize, 4)
            }
            127 => {
                self.fill(10);
                let b = &self.buf[self.at..];
                (
                    u64::from_be_bytes(b[2..10].try_into().unwrap()) as usize,
                    10,
                )
            }
            n => (n as usize, 2),
        };
        self.fill(hl + len);
        let start = self.at + hl;
        self.at = start + len;
        (op, &self.buf[start..start + len])
    }

    fn subscribe_all(&mut self, topics: &[&str]) {
        let mut left: Vec<&str> = topics.to_vec();
        let mut n = 0;
        while !left.is_empty() {
            let (op, p) = self.recv();
            if op != 1 {
                continue;
            }
            let j: serde_json::Value = serde_json::from_slice(p).unwrap();
            if j["op"] != "advertise" {
                continue;
            }
            let mut subs = Vec::new();
            for c in j["channels"].as_array().unwrap() {
                let t = c["topic"].as_str().unwrap();
                if let Some(i) = left.iter().position(|x| *x == t) {
                    left.remove(i);
                    n += 1;
                    subs.push(serde_json::json!({"id": n, "channelId": c["id"]}));
                }
            }
            let m = serde_json::json!({"op": "subscribe", "subscriptions": subs});
            self.send(1, m.to_string().as_bytes());
        }
    }

    /// Message-data frames received within `secs`.
    fn count_for(&mut self, secs: f64) -> f64 {
        let t0 = Instant::now();
        let mut n = 0u64;
        while t0.elapsed().as_secs_f64() < secs {
            let (op, p) = self.recv();
            if op == 2 && p.first() == Some(&1) {
                n += 1;
            }
        }
        n as f64 / t0.elapsed().as_secs_f64()
    }
}

fn frame() -> Image {
    let mut img = Image::new(W, H);
    for (i, b) in img.data.iter_mut().enumerate() {
        *b = (i % 251) as u8;
    }
    img
}

/// One measurement: frames/s the client got, frames/s the producer made, and the
/// CPU seconds each thread name used over the counting window.
struct Run {
    fps: f64,
    made: f64,
    cpu: BTreeMap<String, f64>,
}

/// Spawns a thread named `name` (its CPU shows under that name).
fn named<T: Send + 'static>(
    name: &str,
    f: impl FnOnce() -> T + Send + 'static,
) -> std::thread::JoinHandle<T> {
    std::thread::Builder::new()
        .name(name.into())
        .spawn(f)
        .unwrap()
}

/// Counts what `ws` receives for [`SECS`] on a thread named `client`, after 0.3 s
/// of warm-up; `made` says how many frames the producer has made so far.
fn count(mut ws: Ws, made: impl Fn() -> u64 + Send + 'static) -> Run {
    named("client", move || {
        ws.count_for(0.3);
        let (c0, m0, t0) = (cpu_by_thread(), made(), Instant::now());
        let fps = ws.count_for(SECS);
        let (c1, m1) = (cpu_by_thread(), made());
        let cpu = c1
            .into_iter()
            .map(|(k, v)| (k.clone(), v - c0.get(&k).copied().unwrap_or(0.0)))
            .collect();
        Run {
            fps,
            made: (m1 - m0) as f64 / t0.elapsed().as_secs_f64(),
            cpu,
        }
    })
    .join()
    .unwrap()
}

/// The SDK alone: frames/s to one client.
fn sdk_fps() -> Run {
    let ctx = Context::new();
    let server = WebSocketServer::new()
        .context(&ctx)
        .bind("127.0.0.1", 0)
        .start_blocking()
        .unwrap();
    let a: SocketAddr = format!("127.0.0.1:{}", server.port()).parse().unwrap();
    let ch = ChannelBuilder::new("camera")
        .context(&ctx)
        .build::<RawImage>();
    let img = frame();
    let stop = Arc::new(AtomicBool::new(false));
    let made = Arc::new(AtomicU64::new(0));
    let producer = {
        let (stop, made) = (stop.clone(), made.clone());
        named("producer", move || {
            let mut next = Instant::now();
            while !stop.load(Ordering::Acquire) {
                // The same camera as ours (a fresh frame each time), its bytes
                // handed to the SDK without a copy, encoded and logged.
                let frame = img.clone();
                ch.log(&RawImage {
                    timestamp: None,
                    frame_id: "camera".into(),
                    width: frame.width,
                    height: frame.height,
                    encoding: "bgr8".into(),
                    step: frame.width * 3,
                    data: Bytes::from(frame.data),
                });
                made.fetch_add(1, Ordering::Relaxed);
                pace(&mut next);
            }
        })
    };
    let mut ws = Ws::connect(a, "foxglove.sdk.v1");
    ws.subscribe_all(&["camera"]);
    let run = count(ws, move || made.load(Ordering::Relaxed));
    stop.store(true, Ordering::Release);
    producer.join().unwrap();
    server.stop().wait_blocking();
    run
}

fn settings(serves: &[&str]) -> Settings {
    Settings {
        bind: "127.0.0.1".parse().unwrap(),
        port: 0,
        sdk_port: Some(0),
        serves: serves.iter().map(|s| s.to_string()).collect(),
        jpeg: None,
        world: false,
        limits: Limits::default(),
        insecure: false,
        tls: None,
    }
}

/// The service: frames/s of an image interface to one client.
fn ours_fps(a: SocketAddr, protocol: &str, cam: &Arc<Interface<Image>>) -> Run {
    let stop = Arc::new(AtomicBool::new(false));
    let producer = {
        let stop = stop.clone();
        let cam = cam.clone();
        let img = frame();
        named("producer", move || {
            let mut next = Instant::now();
            while !stop.load(Ordering::Acquire) {
                cam.publish(img.clone()).unwrap();
                pace(&mut next);
            }
        })
    };
    let mut ws = Ws::connect(a, protocol);
    ws.subscribe_all(&["varcolorA"]);
    let clock = cam.clone();
    let run = count(ws, move || clock.clock());
    stop.store(true, Ordering::Release);
    producer.join().unwrap();
    run
}

fn twist_latency(a: SocketAddr, motors: &Arc<Interface<Motors>>) -> (f64, f64) {
    let mut ws = Ws::connect(a, "foxglove.websocket.v1");
    let adv = serde_json::json!({"op": "advertise", "channels": [
        {"id": 1, "topic": "/cmd_vel", "encoding": "json", "schemaName": "geometry_msgs/msg/Twist"}]});
    ws.send(1, adv.to_string().as_bytes());
    std::thread::sleep(Duration::from_millis(200));
    let mut lat = Vec::new();
    for i in 0..400 {
        let before = motors.clock();
        let body = format!(
            r#"{{"linear":{{"x":{}}},"angular":{{"z":0.1}}}}"#,
            0.1 + i as f64 * 1e-4
        );
        let mut msg = vec![1u8, 1, 0, 0, 0];
        msg.extend_from_slice(body.as_bytes());
        let t0 = Instant::now();
        ws.send(2, &msg);
        while motors.clock() == before {
            std::hint::spin_loop();
            assert!(t0.elapsed() < Duration::from_secs(2), "no motors write");
        }
        lat.push(t0.elapsed().as_secs_f64() * 1e3);
        std::thread::sleep(Duration::from_millis(2));
    }
    (percentile(&lat, 0.5), percentile(&lat, 0.99))
}

fn cpu_ten_clients(
    a: SocketAddr,
    laser: &Arc<Interface<Laser>>,
    enc: &Arc<Interface<Encoders>>,
) -> f64 {
    let stop = Arc::new(AtomicBool::new(false));
    let producer = {
        let (stop, laser, enc) = (stop.clone(), laser.clone(), enc.clone());
        named("producer", move || {
            let mut k = 0.0f32;
            while !stop.load(Ordering::Acquire) {
                k += 1.0;
                laser
                    .publish(Laser {
                        readings: (0..180)
                            .map(|i| 1000 + ((i as f32 + k) % 50.0) as i32)
                            .collect(),
                        resolution: 1.0,
                        ..Laser::default()
                    })
                    .unwrap();
                enc.publish(Encoders::from_pose(k, 2.0 * k, 0.01 * k))
                    .unwrap();
                std::thread::sleep(Duration::from_millis(50));
            }
        })
    };
    let readers: Vec<_> = (0..10)
        .map(|_| {
            let stop = stop.clone();
            named("client", move || {
                let mut ws = Ws::connect(a, "foxglove.websocket.v1");
                ws.subscribe_all(&["laser", "encoders", "/tf"]);
                ws.s.set_read_timeout(Some(Duration::from_millis(200)))
                    .unwrap();
                let mut n = 0u64;
                while !stop.load(Ordering::Acquire) {
                    let mut b = [0u8; 65536];
                    match ws.s.read(&mut b) {
                        Ok(0) => break,
                        Ok(k) => n += k as u64,
                        Err(_) => {}
                    }
                }
                n
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    let (c0, t0) = (common::threads_cpu("foxglove"), Instant::now());
    std::thread::sleep(Duration::from_secs(5));
    let pct = (common::threads_cpu("foxglove") - c0) / t0.elapsed().as_secs_f64() * 100.0;
    stop.store(true, Ordering::Release);
    producer.join().unwrap();
    let bytes: u64 = readers.into_iter().map(|r| r.join().unwrap()).sum();
    assert!(bytes > 0, "the clients read nothing");
    pct
}

/// Encodes per second of `f` over ~0.5 s.
/// The SDK's own `RawImage` of an image (the reference encoding: prost).
fn sdk_raw_image(frame: &str, img: &Image) -> RawImage {
    RawImage {
        timestamp: None,
        frame_id: frame.into(),
        width: img.width,
        height: img.height,
        encoding: "bgr8".into(),
        step: img.width * 3,
        data: Bytes::copy_from_slice(&img.data),
    }
}

/// The SDK's own `LaserScan` of a laser (the reference encoding: prost).
fn sdk_laser_scan(l: &Laser) -> LaserScan {
    LaserScan {
        timestamp: None,
        frame_id: "base_link".into(),
        pose: None,
        start_angle: -std::f64::consts::FRAC_PI_2,
        end_angle: std::f64::consts::FRAC_PI_2,
        ranges: l.readings.iter().map(|r| *r as f64 / 1000.0).collect(),
        intensities: Vec::new(),
    }
}

fn rate(mut f: impl FnMut()) -> f64 {
    let t0 = Instant::now();
    let mut n = 0u64;
    while t0.elapsed() < Duration::from_millis(500) {
        f();
        n += 1;
    }
    n as f64 / t0.elapsed().as_secs_f64()
}

fn recorder_encodings() {
    let sample = |value| Sample {
        clock: 1,
        stamp: Instant::now(),
        time: SystemTime::now(),
        value,
    };
    let img = Arc::new(sample(frame()));
    let laser = Laser {
        readings: (0..180).map(|i| 1000 + i).collect(),
        resolution: 1.0,
        ..Laser::default()
    };
    let ls = Arc::new(Sample {
        clock: 1,
        stamp: Instant::now(),
        time: SystemTime::now(),
        value: laser,
    });
    let (mut ours_i, mut sdk_i, mut ours_l, mut sdk_l) = (vec![], vec![], vec![], vec![]);
    let mut buf = Vec::new();
    let mut out = Vec::new();
    for _ in 0..ROUNDS {
        let snap = Snapshot::Image(img.clone());
        ours_i.push(rate(|| {
            mcapfmt::encode(Profile::Foxglove { jpeg: None }, "colorA", &snap, &mut buf);
        }));
        sdk_i.push(rate(|| {
            out.clear();
            sdk_raw_image("colorA", &img.value)
                .encode(&mut out)
                .unwrap();
        }));
        let snap = Snapshot::Laser(ls.clone());
        ours_l.push(rate(|| {
            mcapfmt::encode(Profile::Foxglove { jpeg: None }, "laser", &snap, &mut buf);
        }));
        sdk_l.push(rate(|| {
            out.clear();
            let m: LaserScan = sdk_laser_scan(&ls.value);
            m.encode(&mut out).unwrap();
        }));
    }
    let (oi, si, ol, sl) = (
        median(&ours_i),
        median(&sdk_i),
        median(&ours_l),
        median(&sdk_l),
    );
    println!(
        "recorder encoding, 640x480 RawImage: ours {oi:.0}/s, SDK schemas {si:.0}/s (SDK/ours {:.2}); 180-reading LaserScan: ours {ol:.0}/s, SDK {sl:.0}/s ({:.2})",
        si / oi,
        sl / ol
    );
}

/// The recorder's writer path to a file, images and laser encoded by ours
/// (`mcapfmt::encode`, `assets/foxglove/*.fdset`) or by the SDK's schemas (their
/// own descriptors); the rest JSON either way.
fn write_load(path: &Path, sdk: bool, load: &[Vec<(&str, Snapshot)>]) {
    let profile = Profile::Foxglove { jpeg: None };
    let mut w = mcapfmt::write_options(None, profile)
        .create(std::fs::File::create(path).unwrap())
        .unwrap();
    let mut ids = std::collections::HashMap::new();
    let mut buf = Vec::new();
    for sec in load {
        for (name, snap) in sec {
            let id = *ids.entry(*name).or_insert_with(|| {
                let schema = match snap {
                    Snapshot::Image(_) if sdk => RawImage::get_schema(),
                    Snapshot::Laser(_) if sdk => LaserScan::get_schema(),
                    _ => None,
                };
                match schema {
                    Some(sc) => {
                        let sid = w.add_schema(&sc.name, &sc.encoding, &sc.data).unwrap();
                        w.add_channel(sid, name, "protobuf", &Default::default())
                            .unwrap()
                    }
                    None => mcapfmt::add_channel(&mut w, name, snap.kind(), profile)
                        .unwrap()
                        .unwrap(),
                }
            });
            buf.clear();
            match snap {
                Snapshot::Image(s) if sdk => {
                    sdk_raw_image(name, &s.value).encode(&mut buf).unwrap()
                }
                Snapshot::Laser(s) if sdk => sdk_laser_scan(&s.value).encode(&mut buf).unwrap(),
                _ => {
                    mcapfmt::encode(profile, name, snap, &mut buf);
                }
            }
            w.write_to_known_channel(&snap.header(id), &buf).unwrap();
        }
    }
    w.finish().unwrap();
}

fn recorder_write() {
    let dir = tempfile::tempdir().unwrap();
    let shm = tempfile::tempdir_in("/dev/shm").ok();
    let targets: Vec<(&str, std::path::PathBuf)> =
        std::iter::once(("disk", dir.path().join("w.mcap")))
            .chain(shm.as_ref().map(|d| ("memory", d.path().join("w.mcap"))))
            .collect();
    let secs = 5u64;
    let t0 = SystemTime::now();
    let load: Vec<_> = (0..secs).map(|s| one_second(t0, s)).collect();
    for (to, file) in &targets {
        let (mut ours, mut sdk, mut ratio) = (vec![], vec![], vec![]);
        for r in 0..ROUNDS {
            let run = |use_sdk| {
                let t = Instant::now();
                write_load(file, use_sdk, &load);
                secs as f64 / t.elapsed().as_secs_f64()
            };
            let (o, s) = if r % 2 == 0 {
                let o = run(false);
                (o, run(true))
            } else {
                let s = run(true);
                (run(false), s)
            };
            ours.push(o);
            sdk.push(s);
            ratio.push(s / o);
        }
        let _ = std::fs::remove_file(file);
        println!(
            "recorder, raw to {to} (640x480 30 fps + laser + encoders + sonars), x real time: ours {:.1}, SDK schemas {:.1}; SDK/ours median {:.2}",
            median(&ours),
            median(&sdk),
            median(&ratio)
        );
    }
}

/// Part 1: the three servers in rotating order each round; the frame rates, their
/// ratios, and where the CPU went per delivered frame.
fn frames(relay: SocketAddr, direct: SocketAddr, cam: &Arc<Interface<Image>>) {
    println!("foxglove service vs the Foxglove SDK's own server, loopback, {W}x{H} BGR RawImage");
    const NAMES: [&str; 3] = ["SDK alone", "relay (port)", "direct (sdk_port)"];
    let mut runs: [Vec<Run>; 3] = Default::default();
    // `-- frames only=N` (0 SDK, 1 port, 2 sdk_port): that server alone, for a profiler.
    let only: Option<usize> = std::env::args().find_map(|a| a.strip_prefix("only=")?.parse().ok());
    if let Some(w) = only {
        let fps: Vec<f64> = (0..ROUNDS)
            .map(|_| match w {
                0 => sdk_fps(),
                1 => ours_fps(relay, "foxglove.websocket.v1", cam),
                _ => ours_fps(direct, "foxglove.sdk.v1", cam),
            }.fps)
            .collect();
        println!(
            "{}: frames/s median {:.0} (rounds {fps:.0?})",
            NAMES[w],
            median(&fps)
        );
        return;
    }
    for r in 0..ROUNDS {
        for k in 0..3 {
            let which = (r + k) % 3;
            runs[which].push(match which {
                0 => sdk_fps(),
                1 => ours_fps(relay, "foxglove.websocket.v1", cam),
                _ => ours_fps(direct, "foxglove.sdk.v1", cam),
            });
        }
        let f = |w: usize| runs[w][r].fps;
        println!(
            "  round {r}: SDK alone {:.0} frames/s, jderobot relay {:.0} ({:.0} %), direct {:.0} ({:.0} %)",
            f(0),
            f(1),
            f(1) / f(0) * 100.0,
            f(2),
            f(2) / f(0) * 100.0
        );
    }
    let fps = |w: usize| runs[w].iter().map(|r| r.fps).collect::<Vec<_>>();
    let ratio = |w: usize| {
        let v: Vec<f64> = (0..ROUNDS)
            .map(|r| runs[w][r].fps / runs[0][r].fps)
            .collect();
        median(&v) * 100.0
    };
    println!(
        "frames/s to one client: median SDK {:.0}, jderobot relay (port) {:.0}, direct (sdk_port) {:.0}; \
         ratio medians: relay {:.0} %, direct {:.0} % (goal >= 95 %)",
        median(fps(0)),
        median(fps(1)),
        median(fps(2)),
        ratio(1),
        ratio(2)
    );
    println!("  CPU per delivered frame, medians of the rounds, us (thread: us):");
    for (w, name) in NAMES.iter().enumerate() {
        let made = median(runs[w].iter().map(|r| r.made).collect::<Vec<_>>());
        let mut threads: Vec<&String> = runs[w].iter().flat_map(|r| r.cpu.keys()).collect();
        threads.sort();
        threads.dedup();
        let per = |t: &str| {
            let v: Vec<f64> = runs[w]
                .iter()
                .map(|r| r.cpu.get(t).copied().unwrap_or(0.0) / (r.fps * SECS) * 1e6)
                .collect();
            median(v)
        };
        let total = median(
            runs[w]
                .iter()
                .map(|r| r.cpu.values().sum::<f64>() / (r.fps * SECS) * 1e6)
                .collect::<Vec<_>>(),
        );
        let parts: Vec<String> = threads
            .iter()
            .map(|t| (t, per(t)))
            .filter(|(_, us)| *us >= 1.0)
            .map(|(t, us)| format!("{t} {us:.0}"))
            .collect();
        println!(
            "    {name}: total {total:.0} ({}); frames made {made:.0}/s",
            parts.join(", ")
        );
    }
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return;
    }
    let rt = Runtime::new(Path::new("bench.conf"));
    let cam = rt
        .interfaces
        .provide::<Image>("varcolorA", "bench")
        .unwrap();
    let motors = rt.interfaces.provide::<Motors>("motors", "bench").unwrap();
    let laser = rt.interfaces.provide::<Laser>("laser", "bench").unwrap();
    let enc = rt
        .interfaces
        .provide::<Encoders>("encoders", "bench")
        .unwrap();
    let server = start(
        &settings(&["varcolorA", "motors", "laser", "encoders"]),
        &rt,
    )
    .unwrap();
    let a = server.local_addr();
    let direct = server.sdk_addr().expect("sdk_port is set");
    frames(a, direct, &cam);
    if std::env::args().any(|a| a == "frames") {
        return;
    }
    let (p50, p99) = twist_latency(a, &motors);
    println!("Twist -> motors: p50 {p50:.3} ms, p99 {p99:.3} ms (goal p50 <= 1 ms)");
    let cpu: Vec<f64> = (0..3).map(|_| cpu_ten_clients(a, &laser, &enc)).collect();
    println!(
        "CPU of the service's threads, 10 clients on laser + encoders (+/tf) at 20 Hz: median {:.1} % of one core",
        median(&cpu)
    );
    recorder_encodings();
    recorder_write();
    drop(server);
}
