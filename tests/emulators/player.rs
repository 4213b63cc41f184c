//! A Player 3.1 server emulator for tests, written from
//! `reference/player-protocol.md` (banner, 40-byte XDR header, the `player`
//! device's requests, PUSH and PULL data modes) and Player's `playerxdr.c` layouts.
//! It does not use the driver's codec.
//!
//! It serves a kinematic robot in a rectangular room (metres, counter-clockwise
//! radians, as Stage): position2d:0 (moves with CMD_VEL), laser:0 (180 floats over
//! −π/2…π/2 at π/180, 8 m), ranger:0 (16 sonars, doubles), ranger:1 (a 180-sample
//! laser as doubles), sonar:0 (16 floats), bumper:0 (10), ptz:0, camera:0
//! (RGB888 or JPEG), blobfinder:0 (the reference's captured blob). It answers
//! REQ_DEVLIST, REQ_DEV, REQ_DATAMODE, REQ_DATA (ACK, data, SYNCH), ranger and
//! laser GET_CONFIG, MOTOR_POWER; it sends no reply to a device it does not have,
//! and NACKs an unknown `player` subtype. On demand it misbehaves: goes down
//! (closes every connection and refuses new ones) and comes back on the same
//! port, stalls, sends garbage, oversized headers, counts that disagree with the
//! size, or NACKs every request.
#![allow(dead_code)]

use std::{
    collections::VecDeque,
    io::{Read, Write},
    net::{TcpListener, TcpStream},
    sync::{
        Arc, Mutex,
        atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering},
    },
    thread::JoinHandle,
    time::{Duration, Instant},
};

// The interface codes of the devices served (player.h, PLAYER_*_CODE).
/// PLAYER_POSITION2D_CODE
pub const POSITION2D: u32 = 4;
/// PLAYER_SONAR_CODE
pub const SONAR: u32 = 5;
/// PLAYER_LASER_CODE
pub const LASER: u32 = 6;
/// PLAYER_BLOBFINDER_CODE
pub const BLOBFINDER: u32 = 7;
/// PLAYER_PTZ_CODE
pub const PTZ: u32 = 8;
/// PLAYER_BUMPER_CODE
pub const BUMPER: u32 = 14;
/// PLAYER_CAMERA_CODE
pub const CAMERA: u32 = 40;
/// PLAYER_RANGER_CODE
pub const RANGER: u32 = 62;

/// What the robot and its world are.
#[derive(Clone, Debug)]
pub struct World {
    /// Room walls: x in [xmin, xmax], y in [ymin, ymax], metres.
    pub xmin: f64,
    pub xmax: f64,
    pub ymin: f64,
    pub ymax: f64,
    /// Robot pose (m, m, rad) and the commanded speeds (m/s, rad/s).
    pub x: f64,
    pub y: f64,
    pub a: f64,
    pub v: f64,
    pub w: f64,
    pub pan: f32,
    pub tilt: f32,
    /// Simulated seconds.
    pub time: f64,
    /// Every CMD_VEL received: (vx, va, when).
    pub commands: Vec<(f64, f64, Instant)>,
    pub ptz_commands: Vec<(f32, f32)>,
}

impl Default for World {
    fn default() -> Self {
        World {
            xmin: -2.0,
            xmax: 4.0,
            ymin: -3.0,
            ymax: 1.0,
            x: 0.0,
            y: 0.0,
            a: 0.0,
            v: 0.0,
            w: 0.0,
            pan: 0.0,
            tilt: 0.0,
            time: 0.0,
            commands: Vec::new(),
            ptz_commands: Vec::new(),
        }
    }
}

impl World {
    /// Distance from (x, y) along `dir` to the room's walls, capped at `max`.
    pub fn ray(&self, x: f64, y: f64, dir: f64, max: f64) -> f64 {
        let (dx, dy) = (dir.cos(), dir.sin());
        let mut best = max;
        for (t, ok) in [
            ((self.xmax - x) / dx, dx > 1e-12),
            ((self.xmin - x) / dx, dx < -1e-12),
            ((self.ymax - y) / dy, dy > 1e-12),
            ((self.ymin - y) / dy, dy < -1e-12),
        ] {
            if ok && t >= 0.0 && t < best {
                best = t;
            }
        }
        best
    }
    fn step(&mut self, dt: f64) {
        self.time += dt;
        self.a += self.w * dt;
        let r = 0.2;
        let nx = self.x + self.v * self.a.cos() * dt;
        let ny = self.y + self.v * self.a.sin() * dt;
        // The walls stop the robot (radius 0.2 m).
        if nx - r > self.xmin && nx + r < self.xmax && ny - r > self.ymin && ny + r < self.ymax {
            self.x = nx;
            self.y = ny;
        }
        while self.a > std::f64::consts::PI {
            self.a -= std::f64::consts::TAU;
        }
        while self.a < -std::f64::consts::PI {
            self.a += std::f64::consts::TAU;
        }
    }
    fn laser(&self) -> Vec<f64> {
        (0..180)
            .map(|i| {
                let b = -std::f64::consts::FRAC_PI_2 + i as f64 * std::f64::consts::PI / 180.0;
                self.ray(self.x, self.y, self.a + b, 8.0)
            })
            .collect()
    }
    fn sonars(&self) -> Vec<f64> {
        // The Pioneer ring's directions (deg), from the robot's centre.
        const DIRS: [f64; 16] = [
            90.0, 50.0, 30.0, 10.0, -10.0, -30.0, -50.0, -90.0, -90.0, -130.0, -150.0, -170.0,
            170.0, 150.0, 130.0, 90.0,
        ];
        DIRS.iter()
            .map(|d| self.ray(self.x, self.y, self.a + d.to_radians(), 5.0))
            .collect()
    }
}

/// Misbehaviour switches.
#[derive(Default)]
pub struct Faults {
    pub nack_all: AtomicBool,
    pub stall: AtomicBool,
    /// Send this many garbage bytes once (to every connection).
    pub garbage: AtomicU32,
    pub oversized: AtomicBool,
    pub bad_count: AtomicBool,
}

pub struct Shared {
    pub world: Mutex<World>,
    pub faults: Faults,
    /// The devices the server has.
    pub devices: Mutex<Vec<(u32, u32)>>,
    /// Down: no listener, every connection closed.
    down: AtomicBool,
    stop: AtomicBool,
    conns: Mutex<Vec<TcpStream>>,
    /// Connections accepted so far.
    pub accepted: AtomicU64,
    /// Subscriptions currently open (all connections).
    pub subscribed: Mutex<Vec<(u32, u32)>>,
    /// Data period.
    pub period: Mutex<Duration>,
    /// The camera frame: (width, height, format, compression, bytes).
    pub camera: Mutex<(u32, u32, u32, u32, Vec<u8>)>,
    /// When the latest laser:0 scan was written to a socket.
    pub last_scan_write: Mutex<Option<Instant>>,
    /// REQ_DEVLIST requests answered.
    pub devlists: AtomicU64,
}

pub struct Emulator {
    pub port: u16,
    pub shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
}

pub fn all_devices() -> Vec<(u32, u32)> {
    vec![
        (POSITION2D, 0),
        (LASER, 0),
        (RANGER, 0),
        (RANGER, 1),
        (SONAR, 0),
        (BUMPER, 0),
        (PTZ, 0),
        (CAMERA, 0),
        (BLOBFINDER, 0),
    ]
}

/// An 80x60 RGB888 test frame: left half red, right half blue.
pub fn test_frame() -> (u32, u32, u32, u32, Vec<u8>) {
    let (w, h) = (80u32, 60u32);
    let mut v = Vec::new();
    for _y in 0..h {
        for x in 0..w {
            if x < w / 2 {
                v.extend_from_slice(&[255, 0, 0]);
            } else {
                v.extend_from_slice(&[0, 0, 255]);
            }
        }
    }
    (w, h, 5, 0, v)
}

// ---- XDR writing (RFC 4506, big-endian; see the reference §2) ----

fn put_u32(b: &mut Vec<u8>, v: u32) {
    b.extend_from_slice(&v.to_be_bytes());
}
fn put_f32(b: &mut Vec<u8>, v: f32) {
    b.extend_from_slice(&v.to_bits().to_be_bytes());
}
fn put_f64(b: &mut Vec<u8>, v: f64) {
    b.extend_from_slice(&v.to_bits().to_be_bytes());
}
/// `count, count, bytes`, padded to 4.
fn put_opaque(b: &mut Vec<u8>, bytes: &[u8]) {
    put_u32(b, bytes.len() as u32);
    put_u32(b, bytes.len() as u32);
    b.extend_from_slice(bytes);
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
}

/// A server message: host 127.0.0.1 packed little-endian, robot = port.
#[allow(clippy::too_many_arguments)]
pub fn server_msg(
    port: u16,
    interf: u32,
    index: u32,
    mtype: u32,
    subtype: u32,
    time: f64,
    seq: u32,
    payload: &[u8],
) -> Vec<u8> {
    let mut b = Vec::with_capacity(40 + payload.len());
    b.extend_from_slice(&[1, 0, 0, 127]);
    put_u32(&mut b, port as u32);
    put_u32(&mut b, interf);
    put_u32(&mut b, index);
    put_u32(&mut b, mtype);
    put_u32(&mut b, subtype);
    put_f64(&mut b, time);
    put_u32(&mut b, seq);
    put_u32(&mut b, payload.len() as u32);
    b.extend_from_slice(payload);
    b
}

/// A laser DATA_SCAN payload (reference §7).
pub fn scan_payload(ranges: &[f64]) -> Vec<u8> {
    let mut p = Vec::new();
    put_f32(&mut p, -std::f32::consts::FRAC_PI_2);
    put_f32(&mut p, std::f32::consts::FRAC_PI_2);
    put_f32(&mut p, std::f32::consts::PI / 180.0);
    put_f32(&mut p, 8.0);
    put_u32(&mut p, ranges.len() as u32);
    put_u32(&mut p, ranges.len() as u32);
    for r in ranges {
        put_f32(&mut p, *r as f32);
    }
    put_opaque(&mut p, &[]);
    put_u32(&mut p, 0);
    p
}

fn doubles_payload(v: &[f64]) -> Vec<u8> {
    let mut p = Vec::new();
    put_u32(&mut p, v.len() as u32);
    put_u32(&mut p, v.len() as u32);
    for r in v {
        put_f64(&mut p, *r);
    }
    p
}

fn floats_payload(v: &[f64]) -> Vec<u8> {
    let mut p = Vec::new();
    put_u32(&mut p, v.len() as u32);
    put_u32(&mut p, v.len() as u32);
    for r in v {
        put_f32(&mut p, *r as f32);
    }
    p
}

/// The blobfinder payload captured from Stage (reference §9).
pub const BLOB_HEX: &str = "00000050 0000003c 00000001 00000001 a9a05d8a 00ff0000 000001a4 00000027 0000001e 0000001d 00000032 00000014 00000028 3fd7ee9a";

pub fn hex(s: &str) -> Vec<u8> {
    let s: String = s.chars().filter(|c| c.is_ascii_hexdigit()).collect();
    (0..s.len() / 2)
        .map(|i| u8::from_str_radix(&s[2 * i..2 * i + 2], 16).unwrap())
        .collect()
}

impl Emulator {
    /// Starts on a free loopback port with every device.
    pub fn start() -> Emulator {
        Self::with_devices(all_devices())
    }

    pub fn with_devices(devices: Vec<(u32, u32)>) -> Emulator {
        Self::on_port(devices, 0)
    }

    /// Starts on `port` (0: a free one).
    pub fn on_port(devices: Vec<(u32, u32)>, port: u16) -> Emulator {
        let listener = TcpListener::bind(("127.0.0.1", port)).expect("bind");
        let port = listener.local_addr().unwrap().port();
        let shared = Arc::new(Shared {
            world: Mutex::new(World::default()),
            faults: Faults::default(),
            devices: Mutex::new(devices),
            down: AtomicBool::new(false),
            stop: AtomicBool::new(false),
            conns: Mutex::new(Vec::new()),
            accepted: AtomicU64::new(0),
            subscribed: Mutex::new(Vec::new()),
            period: Mutex::new(Duration::from_millis(20)),
            camera: Mutex::new(test_frame()),
            last_scan_write: Mutex::new(None),
            devlists: AtomicU64::new(0),
        });
        let mut threads = Vec::new();
        let s = shared.clone();
        threads.push(std::thread::spawn(move || {
            acceptor(s, Some(listener), port)
        }));
        let s = shared.clone();
        threads.push(std::thread::spawn(move || {
            let mut last = Instant::now();
            while !s.stop.load(Ordering::Acquire) {
                std::thread::sleep(Duration::from_millis(5));
                let now = Instant::now();
                let dt = (now - last).as_secs_f64();
                last = now;
                s.world.lock().unwrap().step(dt);
            }
        }));
        Emulator {
            port,
            shared,
            threads,
        }
    }

    pub fn world(&self) -> std::sync::MutexGuard<'_, World> {
        self.shared.world.lock().unwrap()
    }

    /// The server goes away: every connection closed, new ones refused.
    pub fn go_down(&self) {
        self.shared.down.store(true, Ordering::Release);
        for c in self.shared.conns.lock().unwrap().drain(..) {
            let _ = c.shutdown(std::net::Shutdown::Both);
        }
        self.shared.subscribed.lock().unwrap().clear();
    }

    /// The server comes back on the same port.
    pub fn come_back(&self) {
        self.shared.down.store(false, Ordering::Release);
    }

    pub fn subscribed(&self, interf: u32, index: u32) -> bool {
        self.shared
            .subscribed
            .lock()
            .unwrap()
            .contains(&(interf, index))
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        self.go_down();
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

fn acceptor(s: Arc<Shared>, mut listener: Option<TcpListener>, port: u16) {
    let mut conns: Vec<JoinHandle<()>> = Vec::new();
    while !s.stop.load(Ordering::Acquire) {
        if s.down.load(Ordering::Acquire) {
            listener = None;
            std::thread::sleep(Duration::from_millis(5));
            continue;
        }
        let l = match &listener {
            Some(l) => l,
            None => match TcpListener::bind(("127.0.0.1", port)) {
                Ok(l) => {
                    listener = Some(l);
                    continue;
                }
                Err(_) => {
                    std::thread::sleep(Duration::from_millis(20));
                    continue;
                }
            },
        };
        l.set_nonblocking(true).unwrap();
        match l.accept() {
            Ok((stream, _)) => {
                stream.set_nonblocking(false).unwrap();
                s.accepted.fetch_add(1, Ordering::AcqRel);
                s.conns.lock().unwrap().push(stream.try_clone().unwrap());
                let s2 = s.clone();
                conns.push(std::thread::spawn(move || {
                    let _ = serve(&s2, stream, port);
                }));
            }
            Err(_) => std::thread::sleep(Duration::from_millis(2)),
        }
    }
    for c in conns {
        let _ = c.join();
    }
}

struct Client {
    subs: Vec<(u32, u32)>,
    pull: bool,
    queue: VecDeque<Vec<u8>>,
}

fn serve(s: &Shared, mut stream: TcpStream, port: u16) -> std::io::Result<()> {
    stream.set_nodelay(true)?;
    let mut banner = b"Player v.3.1.1-dev".to_vec();
    banner.resize(32, 0);
    stream.write_all(&banner)?;
    stream.set_read_timeout(Some(Duration::from_millis(2)))?;
    let mut c = Client {
        subs: Vec::new(),
        pull: false,
        queue: VecDeque::new(),
    };
    let mut buf: Vec<u8> = Vec::new();
    let mut next_data = Instant::now();
    let result = loop {
        if s.stop.load(Ordering::Acquire) || s.down.load(Ordering::Acquire) {
            break Ok(());
        }
        let mut chunk = [0u8; 4096];
        match stream.read(&mut chunk) {
            Ok(0) => break Ok(()),
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => break Err(e),
        }
        // Whole messages from the client.
        while buf.len() >= 40 {
            let w = |i: usize| u32::from_be_bytes([buf[i], buf[i + 1], buf[i + 2], buf[i + 3]]);
            let size = w(36) as usize;
            if buf.len() < 40 + size {
                break;
            }
            let (interf, index, mtype, subtype, seq) = (w(8), w(12), w(16), w(20), w(32));
            let payload = buf[40..40 + size].to_vec();
            buf.drain(..40 + size);
            if !s.faults.stall.load(Ordering::Acquire) {
                let r = Request {
                    port,
                    interf,
                    index,
                    mtype,
                    subtype,
                    seq,
                    time: s.world.lock().unwrap().time,
                    p: &payload,
                };
                for out in handle(s, &mut c, &r) {
                    stream.write_all(&out)?;
                }
            }
        }
        send_faults(s, &mut stream, port)?;
        let now = Instant::now();
        if now >= next_data {
            let period = *s.period.lock().unwrap();
            next_data = now + period;
            if !s.faults.stall.load(Ordering::Acquire) {
                let msgs = data_messages(s, &c, port);
                if c.pull {
                    c.queue.extend(msgs);
                    while c.queue.len() > 1024 {
                        c.queue.pop_front();
                    }
                } else {
                    for m in msgs {
                        if m.len() > 12 && m[8..12] == LASER.to_be_bytes() {
                            *s.last_scan_write.lock().unwrap() = Some(Instant::now());
                        }
                        stream.write_all(&m)?;
                    }
                }
            }
        }
    };
    let mut subs = s.subscribed.lock().unwrap();
    for d in &c.subs {
        if let Some(i) = subs.iter().position(|x| x == d) {
            subs.remove(i);
        }
    }
    result
}

/// The faults asked for since the last call: garbage bytes, an oversized
/// header, a scan with an absurd count.
fn send_faults(s: &Shared, stream: &mut TcpStream, port: u16) -> std::io::Result<()> {
    let g = s.faults.garbage.swap(0, Ordering::AcqRel);
    if g > 0 {
        let mut x: u32 = 0x1234_5678;
        let junk: Vec<u8> = (0..g)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                x as u8
            })
            .collect();
        stream.write_all(&junk)?;
    }
    if s.faults.oversized.swap(false, Ordering::AcqRel) {
        let mut m = server_msg(port, LASER, 0, 1, 1, 0.0, 0, &[]);
        m[36..40].copy_from_slice(&0x7fff_fff0u32.to_be_bytes());
        stream.write_all(&m)?;
    }
    if s.faults.bad_count.swap(false, Ordering::AcqRel) {
        // A scan that claims a million ranges in a 60-byte payload.
        let mut p = scan_payload(&[1.0; 4]);
        p[16..20].copy_from_slice(&1_000_000u32.to_be_bytes());
        p[20..24].copy_from_slice(&1_000_000u32.to_be_bytes());
        stream.write_all(&server_msg(port, LASER, 0, 1, 1, 0.0, 0, &p))?;
    }
    Ok(())
}

fn has(s: &Shared, interf: u32, index: u32) -> bool {
    s.devices.lock().unwrap().contains(&(interf, index))
}

/// One message from a client: its header's fields, its payload and the world's
/// time; it makes the replies addressed back to it.
struct Request<'a> {
    port: u16,
    interf: u32,
    index: u32,
    mtype: u32,
    subtype: u32,
    seq: u32,
    time: f64,
    p: &'a [u8],
}

impl Request<'_> {
    fn ack(&self, payload: &[u8]) -> Vec<u8> {
        let (port, interf, index, subtype) = (self.port, self.interf, self.index, self.subtype);
        server_msg(
            port, interf, index, 4, subtype, self.time, self.seq, payload,
        )
    }

    fn nack(&self) -> Vec<u8> {
        let (port, interf, index, subtype) = (self.port, self.interf, self.index, self.subtype);
        server_msg(port, interf, index, 6, subtype, self.time, self.seq, &[])
    }

    /// The XDR unsigned int, float or double at byte `i` of the payload (0 past its end).
    fn be(&self, i: usize) -> u32 {
        self.p
            .get(i..i + 4)
            .map(|b| u32::from_be_bytes([b[0], b[1], b[2], b[3]]))
            .unwrap_or(0)
    }

    fn bef32(&self, i: usize) -> f32 {
        f32::from_bits(self.be(i))
    }

    fn bef64(&self, i: usize) -> f64 {
        self.p
            .get(i..i + 8)
            .map(|b| f64::from_be_bytes(b.try_into().unwrap()))
            .unwrap_or(0.0)
    }
}

fn handle(s: &Shared, c: &mut Client, r: &Request) -> Vec<Vec<u8>> {
    if r.mtype == 3 && s.faults.nack_all.load(Ordering::Acquire) {
        return vec![r.nack()];
    }
    let (index, subtype, p) = (r.index, r.subtype, r.p);
    match (r.interf, r.mtype) {
        (1, 3) => player_request(s, c, r),
        (i, 3) if !has(s, i, index) => Vec::new(),
        (RANGER, 3) if subtype == 5 => vec![r.ack(&ranger_config(index))],
        (LASER, 3) if subtype == 3 => vec![r.ack(&laser_config())],
        (_, 3) if subtype == 1 => vec![r.ack(&[0u8; 72])],
        (POSITION2D, 3) if subtype == 2 => vec![r.ack(&[])],
        (_, 3) => vec![r.nack()],
        (POSITION2D, 2) if subtype == 1 && p.len() >= 28 => {
            let mut w = s.world.lock().unwrap();
            w.v = r.bef64(0);
            w.w = r.bef64(16);
            let (v, a) = (w.v, w.w);
            w.commands.push((v, a, Instant::now()));
            Vec::new()
        }
        (PTZ, 2) if subtype == 1 && p.len() >= 20 => {
            let mut w = s.world.lock().unwrap();
            w.pan = r.bef32(0);
            w.tilt = r.bef32(4);
            let (pa, ti) = (w.pan, w.tilt);
            w.ptz_commands.push((pa, ti));
            Vec::new()
        }
        _ => Vec::new(),
    }
}

/// A request to the `player` device: the device list, a subscription, a PULL,
/// the data mode.
fn player_request(s: &Shared, c: &mut Client, r: &Request) -> Vec<Vec<u8>> {
    let port = r.port;
    match r.subtype {
        1 => {
            s.devlists.fetch_add(1, Ordering::AcqRel);
            let devs = s.devices.lock().unwrap().clone();
            let mut out = Vec::new();
            put_u32(&mut out, devs.len() as u32);
            put_u32(&mut out, devs.len() as u32);
            for (i, k) in devs {
                out.extend_from_slice(&[1, 0, 0, 127]);
                put_u32(&mut out, port as u32);
                put_u32(&mut out, i);
                put_u32(&mut out, k);
            }
            vec![r.ack(&out)]
        }
        3 => {
            let (di, dk, access) = (r.be(8), r.be(12), r.be(16));
            let mut out = Vec::new();
            out.extend_from_slice(&[1, 0, 0, 127]);
            put_u32(&mut out, port as u32);
            put_u32(&mut out, di);
            put_u32(&mut out, dk);
            if !has(s, di, dk) {
                put_u32(&mut out, 3);
                put_opaque(&mut out, &[]);
                return vec![server_msg(port, 1, 0, 6, 3, r.time, r.seq, &out)];
            }
            put_u32(&mut out, access);
            put_opaque(&mut out, b"emulator\0");
            let mut subs = s.subscribed.lock().unwrap();
            if access == 1 && !c.subs.contains(&(di, dk)) {
                c.subs.push((di, dk));
                subs.push((di, dk));
            } else if access == 2
                && let Some(i) = c.subs.iter().position(|x| *x == (di, dk))
            {
                c.subs.remove(i);
                if let Some(j) = subs.iter().position(|x| *x == (di, dk)) {
                    subs.remove(j);
                }
            }
            vec![r.ack(&out)]
        }
        4 => {
            // PULL: the ACK, the queued data, then a SYNCH.
            let mut v = vec![r.ack(&[])];
            v.extend(c.queue.drain(..));
            let mut synch = server_msg(port, 1, 0, 5, 1, 0.0, 0, &[]);
            synch[0..8].fill(0);
            v.push(synch);
            v
        }
        5 => {
            c.pull = r.be(0) == 2;
            vec![r.ack(&[])]
        }
        _ => vec![r.nack()],
    }
}

/// A ranger's geometry and configuration (min and max angle, resolution, min
/// and max range, range resolution, frequency): ranger 1 is the laser.
fn ranger_config(index: u32) -> Vec<u8> {
    let mut out = Vec::new();
    let (lo, hi, res, max) = if index == 1 {
        (
            -std::f64::consts::FRAC_PI_2,
            std::f64::consts::FRAC_PI_2,
            std::f64::consts::PI / 180.0,
            8.0,
        )
    } else {
        (0.0, 0.0, 0.0, 5.0)
    };
    for v in [lo, hi, res, 0.0, max, 0.02, 10.0] {
        put_f64(&mut out, v);
    }
    out
}

/// The laser's configuration (min and max angle, resolution, max range, range
/// resolution, intensity off, frequency).
fn laser_config() -> Vec<u8> {
    let mut out = Vec::new();
    for v in [
        -std::f32::consts::FRAC_PI_2,
        std::f32::consts::FRAC_PI_2,
        0.017453292,
        8.0,
        0.02,
    ] {
        put_f32(&mut out, v);
    }
    put_u32(&mut out, 0);
    put_f32(&mut out, 10.0);
    out
}

fn data_messages(s: &Shared, c: &Client, port: u16) -> Vec<Vec<u8>> {
    let w = s.world.lock().unwrap().clone();
    let t = w.time;
    let mut out = Vec::new();
    for &(interf, index) in &c.subs {
        let d = |sub: u32, p: &[u8]| server_msg(port, interf, index, 1, sub, t, 0, p);
        match interf {
            POSITION2D => {
                let mut p = Vec::new();
                for v in [w.x, w.y, w.a, w.v, 0.0, w.w] {
                    put_f64(&mut p, v);
                }
                put_u32(&mut p, 0);
                out.push(d(1, &p));
            }
            LASER => out.push(d(1, &scan_payload(&w.laser()))),
            RANGER if index == 1 => out.push(d(1, &doubles_payload(&w.laser()))),
            RANGER => out.push(d(1, &doubles_payload(&w.sonars()))),
            SONAR => out.push(d(1, &floats_payload(&w.sonars()))),
            BUMPER => {
                let near = w.ray(w.x, w.y, w.a, 8.0) < 0.25;
                let mut b = [0u8; 10];
                if near {
                    b[..5].fill(1);
                }
                let mut p = Vec::new();
                put_opaque(&mut p, &b);
                out.push(d(1, &p));
            }
            PTZ => {
                let mut p = Vec::new();
                for v in [w.pan, w.tilt, 1.0, 0.0, 0.0] {
                    put_f32(&mut p, v);
                }
                put_u32(&mut p, 0);
                out.push(d(1, &p));
            }
            CAMERA => {
                let cam = s.camera.lock().unwrap();
                let mut p = Vec::new();
                for v in [cam.0, cam.1, 24, cam.2, 0, cam.3] {
                    put_u32(&mut p, v);
                }
                put_opaque(&mut p, &cam.4);
                out.push(d(1, &p));
            }
            BLOBFINDER => out.push(d(1, &hex(BLOB_HEX))),
            _ => {}
        }
    }
    out
}
