//! networkserver → networkclient over loopback, against references measured in the
//! same run (a harness that prints medians and ratios):
//!
//! 1. 640x480 BGR frames per second from a server interface to a client interface,
//!    against a raw TCP copy of the same bytes (a thread writing header + pixels
//!    back to back, another reading them; goal ≥ 90 %) and against the same copy
//!    paced by the 4.3 protocol's requests (`1019` lines, two ahead; no camera, no
//!    interfaces): what the protocol itself allows; and against that paced copy
//!    double-buffered (two source and two destination buffers in turn, as a
//!    camera's frames must be; one buffer stays in a core's cache), and that copy
//!    taking its frames from an interface fed by the same camera stand-in as
//!    ours (the camera's and the interface's cost, none of the link's). In rotating
//!    order; per frame, all threads' CPU, time runnable but waiting for a core,
//!    time slices.
//! 2. Frame latency at 100 frames/s: from the publish on the server's interface to
//!    the publish on the client's (both stamps taken by the interfaces). Goal p50 ≤ 1 ms.
//! 3. 100 clients subscribed to laser and encoders (new values at 100 Hz): push
//!    lateness after each 33 ms deadline (p50, p99; goal p99 ≤ 5 ms) and the server
//!    threads' CPU time.
//!
//! Run: `cargo bench --features full --bench network` (`-- frames`: only 1;
//! `BENCH_THREADS=1`: also each thread's share of a frame in 1).

mod common;
use common::{Sched, median, percentile, thread_cpu, threads_cpu};

use std::{
    io::{BufRead, BufReader, Read, Write},
    net::{TcpListener, TcpStream},
    sync::{
        Arc,
        atomic::{AtomicBool, AtomicU64, Ordering, fence},
    },
    thread,
    time::{Duration, Instant},
};

use jderobot::{
    drivers::networkclient::{ClientConf, NetClient, Remote},
    interfaces::{Encoders, Image, Interface, Interfaces, Laser, Notify},
    services::networkserver::{NetServer, ServerConf, Sources},
};

const W: u32 = 640;
const H: u32 = 480;
const FRAME: usize = (W * H * 3) as usize;
const ROUNDS: usize = 9;
const SECS: f64 = 1.0;

/// Where the raw copy's sender takes its pixels.
#[derive(Clone, Copy, PartialEq)]
enum Pixels {
    /// One buffer, sent again and again (it stays in the sender's L2 cache).
    OneBuffer,
    /// Two buffers in turn, and two on the reader's side, as a camera's frames must
    /// be (one is sent while the next is filled; one is published while the next
    /// is read): the same copies, but 1.8 MB each side where one 900-KB buffer
    /// stays in a core's L2 cache (1 MiB a core here).
    TwoBuffers,
    /// An interface that the camera stand-in of [`net_fps`] refreshes: for each
    /// request the sender waits for a frame it has not sent (woken by the
    /// interface's publish, as the server's writer is) and writes the sample's
    /// pixels. The camera's and the interface's cost with none of the link's.
    Camera,
}

/// Raw TCP: frames (a 1020 header and the pixels) written back to back for `SECS`.
/// With `requests`, as the 4.3 protocol asks for frames: the reader sends a `1019 0`
/// line for each frame (two ahead, as the client's `depth 2`) and the writer sends
/// a frame for each line it reads (one thread): the protocol's own cost.
/// Returns (frames/s, the process's scheduling per frame).
fn raw_fps(requests: bool, pixels: Pixels) -> (f64, (f64, f64, f64)) {
    let buffers = if pixels == Pixels::OneBuffer { 1 } else { 2 };
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let src = Arc::new(Interface::with_value(
        "varcolorA",
        "robot",
        Image::new(W, H),
    ));
    let sent = Arc::new(AtomicU64::new(0));
    let wake = Arc::new(Wake::default());
    src.watch(wake.clone());
    let arrived = Arc::new(Wake::default());
    let camera = (pixels == Pixels::Camera).then(|| {
        let (src, sent, stop) = (src.clone(), sent.clone(), stop.clone());
        let arrived = arrived.clone();
        thread::Builder::new()
            .name("camera".into())
            .spawn(move || camera(&src, &sent, &arrived, &stop, &AtomicBool::new(true)))
            .unwrap()
    });
    let (st, src2) = (stop.clone(), src.clone());
    let sender = thread::Builder::new()
        .name("raw-sender".into())
        .spawn(move || {
            let (mut s, _) = l.accept().unwrap();
            s.set_nodelay(true).unwrap();
            let mut asks = BufReader::new(s.try_clone().unwrap());
            let (px, mut ask) = (vec![vec![7u8; FRAME]; buffers], String::new());
            let (mut k, mut last) = (0u64, 0u64);
            while !st.load(Ordering::Relaxed) {
                k += 1;
                if requests && !matches!(asks.read_line(&mut ask), Ok(n) if n > 0) {
                    break;
                }
                ask.clear();
                let hdr = format!("1020 {k} 0 {W} {H} 3\n");
                let frame = (pixels == Pixels::Camera).then(|| {
                    let new = || src2.clock() != last || st.load(Ordering::Relaxed);
                    while !new() {
                        wake.sleep(Duration::from_millis(10), new);
                    }
                    let f = src2.snapshot();
                    last = f.clock;
                    f
                });
                let px = match &frame {
                    Some(f) => &f.data,
                    None => &px[k as usize % buffers],
                };
                if s.write_all(hdr.as_bytes()).is_err() || s.write_all(px).is_err() {
                    break;
                }
                drop(frame);
                sent.fetch_add(1, Ordering::Relaxed);
            }
        });
    let s = TcpStream::connect(addr).unwrap();
    s.set_nodelay(true).unwrap();
    let mut ask = s.try_clone().unwrap();
    let mut r = BufReader::new(s);
    let mut px = vec![vec![0u8; FRAME]; buffers];
    let mut line = String::new();
    let mut k = 0;
    if requests {
        ask.write_all(b"1019 0\n").unwrap();
    }
    let mut frame = |r: &mut BufReader<TcpStream>| {
        if requests {
            ask.write_all(b"1019 0\n").unwrap();
        }
        line.clear();
        r.read_line(&mut line).unwrap();
        k += 1;
        r.read_exact(&mut px[k % buffers]).unwrap();
        if pixels == Pixels::Camera {
            arrived.notify();
        }
    };
    // Warm up, then count.
    for _ in 0..20 {
        frame(&mut r);
    }
    let (t0, s0, t0s) = (Instant::now(), Sched::now(), Sched::by_thread());
    let mut n = 0;
    while t0.elapsed().as_secs_f64() < SECS {
        frame(&mut r);
        n += 1;
    }
    let fps = n as f64 / t0.elapsed().as_secs_f64();
    let sched = Sched::now().per(&s0, n as f64);
    Sched::print_threads("a frame", &t0s, &Sched::by_thread(), n as f64);
    stop.store(true, Ordering::Relaxed);
    // Both directions: a writer waiting for a request sees the end too.
    let _ = r.get_ref().shutdown(std::net::Shutdown::Both);
    sender.unwrap().join().unwrap();
    if let Some(c) = camera {
        c.join().unwrap();
    }
    (fps, sched)
}

/// Wakes a thread that waits on it, only while it waits (the flag, set under the
/// lock before a last look; the SeqCst fences pair), so telling a busy thread
/// costs one atomic load: the raw copy's sender on a new frame (as the server's
/// `FrameWake` wakes its client's thread), and the camera stand-in when a frame
/// arrives.
#[derive(Default)]
struct Wake {
    lock: parking_lot::Mutex<()>,
    cv: parking_lot::Condvar,
    waiting: AtomicBool,
}

impl Wake {
    /// Sleeps until notified or `timeout` passes, unless `done` holds when looked
    /// at after the flag shows (so a notify just before the sleep is not lost).
    fn sleep(&self, timeout: Duration, done: impl Fn() -> bool) {
        let mut g = self.lock.lock();
        self.waiting.store(true, Ordering::Relaxed);
        fence(Ordering::SeqCst);
        if !done() {
            self.cv.wait_for(&mut g, timeout);
        }
        self.waiting.store(false, Ordering::Relaxed);
    }
}

impl Notify for Wake {
    fn notify(&self) {
        fence(Ordering::SeqCst);
        if self.waiting.load(Ordering::Relaxed) {
            let _g = self.lock.lock();
            self.cv.notify_all();
        }
    }
}

/// The camera's stand-in: it always has the next frame ready. As soon as the
/// sender takes the latest frame (holds it to send it: `src`'s slot, `cur` and
/// the sender hold it) or has sent one (`sent` changed), it writes the next one.
/// It produces no pixels (it marks one byte): what is measured is the link.
/// `Interface::write` hands it the buffer of a frame the sender has sent, so no
/// frame is copied on the way (until 2026-11-25 a write after a frame the server
/// still held copied the latest 900 KB frame). It looks every 100 µs and whenever
/// a frame reaches the receiver (`arrived`, rung by the receiving side): by then
/// the sender has usually taken the next frame, so the one after is written while
/// that one is sent. Until 2026-11-28 it only looked every 100 µs, and so came
/// late for a sender faster than that: the raw copy fed by it ran at 72–86 % of
/// the plain raw copy, and it capped what the server could show. Waking it only
/// on arrival (tried 2026-11-27) halves the rate: the next frame is then written
/// after the sender needs it. Returns its CPU seconds from when `counting` is set.
fn camera(
    src: &Interface<Image>,
    sent: &AtomicU64,
    arrived: &Wake,
    stop: &AtomicBool,
    counting: &AtomicBool,
) -> f64 {
    let mut cpu0 = None;
    let mut k = 0u8;
    let _ = src.write(|i| i.data[0] = 255);
    let mut cur = src.snapshot();
    let mut seen = sent.load(Ordering::Relaxed);
    let mut at = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        if cpu0.is_none() && counting.load(Ordering::Relaxed) {
            cpu0 = Some(thread_cpu());
        }
        let done = sent.load(Ordering::Relaxed);
        // (And at least every millisecond, as a camera would.)
        if Arc::strong_count(&cur) > 2 || done != seen || at.elapsed().as_micros() > 1000 {
            seen = done;
            at = Instant::now();
            drop(cur);
            k = k.wrapping_add(1);
            let _ = src.write(|i| i.data[0] = k);
            cur = src.snapshot();
        } else {
            arrived.sleep(Duration::from_micros(100), || {
                Arc::strong_count(&cur) > 2 || sent.load(Ordering::Relaxed) != seen
            });
        }
    }
    thread_cpu() - cpu0.unwrap_or_else(thread_cpu)
}

/// A server with a 640x480 `varcolorA` (network id 0) and a client interface fed by it.
struct Link {
    src: Arc<Interface<Image>>,
    dst: Arc<Interface<Image>>,
    server: NetServer,
    client: NetClient,
    _ifaces: Interfaces,
}

fn link() -> Link {
    let src = Arc::new(Interface::with_value(
        "varcolorA",
        "robot",
        Image::new(W, H),
    ));
    let server = NetServer::start(
        ServerConf::default(),
        Sources::default().serving_image(0, src.clone()),
    )
    .unwrap();
    let port = server.local_addr().port();
    let ifaces = Interfaces::default();
    let cc = ClientConf {
        remotes: vec![Remote {
            name: "varcolorA".into(),
            host: "127.0.0.1".into(),
            port,
            netid: Some(0),
            size: Some((W, H)),
        }],
        initial: (0.0, 0.0, 0.0),
        token: None,
        motors_timeout: Duration::from_millis(500),
        depth: 2,
    };
    let client = NetClient::start(cc, &ifaces, "bench").unwrap();
    let dst = ifaces.get::<Image>("varcolorA").unwrap();
    dst.resume();
    Link {
        src,
        dst,
        server,
        client,
        _ifaces: ifaces,
    }
}

/// Frames per second through server and client, the server's image refreshed by
/// [`camera`].
/// Returns (frames/s, the producer's CPU µs per frame delivered, the process's
/// scheduling per frame).
fn net_fps(l: &Link) -> (f64, f64, (f64, f64, f64)) {
    let stop = AtomicBool::new(false);
    let counting = AtomicBool::new(false);
    let arrived = Arc::new(Wake::default());
    l.dst.watch(arrived.clone());
    let out = thread::scope(|sc| {
        let producer = thread::Builder::new()
            .name("camera".into())
            .spawn_scoped(sc, || {
                camera(&l.src, &l.server.stats().frames, &arrived, &stop, &counting)
            });
        thread::sleep(Duration::from_millis(300));
        counting.store(true, Ordering::Relaxed);
        let (c0, s0, t0s) = (l.dst.clock(), Sched::now(), Sched::by_thread());
        let t0 = Instant::now();
        let (mut last, mut since, mut gap) = (c0, Instant::now(), Duration::ZERO);
        while t0.elapsed().as_secs_f64() < SECS {
            thread::sleep(Duration::from_millis(1));
            let c = l.dst.clock();
            if c != last {
                (last, since) = (c, Instant::now());
            }
            gap = gap.max(since.elapsed());
        }
        let frames = (l.dst.clock() - c0) as f64;
        let fps = frames / t0.elapsed().as_secs_f64();
        let sched = Sched::now().per(&s0, frames);
        Sched::print_threads("a frame", &t0s, &Sched::by_thread(), frames);
        stop.store(true, Ordering::Relaxed);
        let cpu = producer.unwrap().join().unwrap_or(0.0);
        if gap > Duration::from_millis(100) {
            println!(
                "    (no frame for {:.0} ms in this round)",
                gap.as_secs_f64() * 1e3
            );
        }
        (fps, cpu * 1e6 / frames.max(1.0), sched)
    });
    l.dst.unwatch(&*arrived);
    out
}

/// Latencies (ms) of `n` frames published at 100 Hz.
fn latencies(l: &Link, n: usize) -> Vec<f64> {
    let mut sent = Vec::with_capacity(n);
    let mut out = Vec::with_capacity(n);
    let mut last_dst = l.dst.clock();
    let mut next = Instant::now();
    for k in 1..=n as u64 {
        next += Duration::from_millis(10);
        l.src
            .write(|i| i.data[..8].copy_from_slice(&k.to_le_bytes()))
            .unwrap();
        sent.push(l.src.read().stamp);
        // Collect what arrived meanwhile.
        while Instant::now() < next {
            let c = l.dst.clock();
            if c != last_dst {
                last_dst = c;
                let s = l.dst.snapshot();
                let id = u64::from_le_bytes(s.data[..8].try_into().unwrap()) as usize;
                if (1..=sent.len()).contains(&id) {
                    out.push(s.stamp.duration_since(sent[id - 1]).as_secs_f64() * 1e3);
                }
            }
            thread::sleep(Duration::from_micros(20));
        }
    }
    out
}

/// 100 clients on laser + encoders for `secs`: (p50 ms, p99 ms, pushes, server CPU %).
fn hundred_clients(secs: f64) -> (f64, f64, u64, f64) {
    let laser = Arc::new(Interface::<Laser>::new("laser", "robot"));
    let enc = Arc::new(Interface::<Encoders>::new("encoders", "robot"));
    let server = NetServer::start(
        ServerConf::default(),
        Sources::default()
            .serving(laser.clone())
            .serving(enc.clone()),
    )
    .unwrap();
    let addr = server.local_addr();
    let stop = Arc::new(AtomicBool::new(false));
    let producer = {
        let (st, laser, enc) = (stop.clone(), laser.clone(), enc.clone());
        thread::spawn(move || {
            let mut k = 0;
            while !st.load(Ordering::Relaxed) {
                k += 1;
                let _ = laser.write(|l| {
                    l.readings.clear();
                    l.readings.extend((0..180).map(|i| 1000 + (i + k) % 7000));
                    l.resolution = 1.0;
                });
                let _ = enc.publish(Encoders::from_pose(k as f32, 0.0, 1.0));
                thread::sleep(Duration::from_millis(10));
            }
        })
    };
    let clients: Vec<_> = (0..100)
        .map(|_| {
            let st = stop.clone();
            thread::spawn(move || {
                let mut s = TcpStream::connect(addr).unwrap();
                s.set_read_timeout(Some(Duration::from_millis(200)))
                    .unwrap();
                s.write_all(b"jdec\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\x0027\n11\n")
                    .unwrap();
                let mut b = vec![0u8; 1 << 16];
                while !st.load(Ordering::Relaxed) {
                    let _ = s.read(&mut b);
                }
            })
        })
        .collect();
    thread::sleep(Duration::from_millis(500));
    server.stats().reset_lateness();
    let p0 = server.stats().pushes.load(Ordering::Relaxed);
    let cpu0 = threads_cpu("nsrv");
    let t0 = Instant::now();
    thread::sleep(Duration::from_secs_f64(secs));
    let cpu = (threads_cpu("nsrv") - cpu0) / t0.elapsed().as_secs_f64() * 100.0;
    let pushes = server.stats().pushes.load(Ordering::Relaxed) - p0;
    let p50 = server.stats().push_lateness(50.0).as_secs_f64() * 1e3;
    let p99 = server.stats().push_lateness(99.0).as_secs_f64() * 1e3;
    stop.store(true, Ordering::Relaxed);
    for c in clients {
        c.join().unwrap();
    }
    producer.join().unwrap();
    drop(server);
    (p50, p99, pushes, cpu)
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return;
    }
    println!("networkserver -> networkclient, loopback, {W}x{H} BGR ({FRAME} bytes a frame)");
    let mut l = link();
    // Warm up the link.
    net_fps(&l);
    const NAMES: [&str; 5] = [
        "raw TCP copy",
        "raw TCP with the 4.3 requests",
        "raw TCP with the 4.3 requests, double-buffered",
        "raw TCP with the 4.3 requests, from the camera's interface",
        "networkserver->networkclient",
    ];
    const OURS: usize = NAMES.len() - 1;
    // fps, then (CPU µs, runnable-waiting µs, time slices) per frame, by case.
    let (mut fps, mut prod): ([Vec<f64>; 5], _) = (Default::default(), vec![]);
    let mut sched: [[Vec<f64>; 3]; 5] = Default::default();
    for r in 0..ROUNDS {
        // The order rotates so no case always runs on a warmer machine.
        for k in 0..NAMES.len() {
            let case = (r + k) % NAMES.len();
            let (f, s) = match case {
                0 => raw_fps(false, Pixels::OneBuffer),
                1 => raw_fps(true, Pixels::OneBuffer),
                2 => raw_fps(true, Pixels::TwoBuffers),
                3 => raw_fps(true, Pixels::Camera),
                _ => {
                    let (f, p, s) = net_fps(&l);
                    prod.push(p);
                    (f, s)
                }
            };
            fps[case].push(f);
            for (k, v) in [s.0, s.1, s.2].into_iter().enumerate() {
                sched[case][k].push(v);
            }
        }
        let f = |c: usize| fps[c][r];
        println!(
            "  round {r}: raw TCP {:.0} frames/s, with requests {:.0}, double-buffered {:.0}, from the camera {:.0}, server->client interface {:.0} ({:.0} %, {:.0} %, {:.0} %, {:.0} % of them), producer {:.1} µs CPU a frame",
            f(0),
            f(1),
            f(2),
            f(3),
            f(OURS),
            f(OURS) / f(0) * 100.0,
            f(OURS) / f(1) * 100.0,
            f(OURS) / f(2) * 100.0,
            f(OURS) / f(3) * 100.0,
            prod[r]
        );
    }
    println!(
        "producer (the camera's stand-in) CPU: median {:.1} µs a frame delivered",
        median(&prod)
    );
    for (case, name) in NAMES.iter().enumerate() {
        let [run, wait, slices] = &sched[case];
        println!(
            "per frame, all threads (schedstat), medians: {name}: {:.0} µs of CPU, {:.0} µs runnable waiting for a core, {:.1} time slices",
            median(run),
            median(wait),
            median(slices)
        );
    }
    println!(
        "frames/s: networkserver->networkclient median {:.0} (goal >= 90 % of the raw TCP copy)",
        median(&fps[OURS])
    );
    for (case, name) in NAMES[..OURS].iter().enumerate() {
        let of: Vec<f64> = (0..ROUNDS).map(|r| fps[OURS][r] / fps[case][r]).collect();
        println!(
            "  {:.0} % of the {name} (median {:.0}; rounds {:.0}-{:.0} %)",
            median(&of) * 100.0,
            median(&fps[case]),
            percentile(&of, 0.0) * 100.0,
            percentile(&of, 1.0) * 100.0
        );
    }
    // `frames` as an argument: only the frame rate.
    if std::env::args().any(|a| a == "frames") {
        return;
    }
    let mut lat = latencies(&l, 300);
    println!(
        "frame latency at 100 frames/s ({} frames): p50 {:.3} ms, p90 {:.3} ms, p99 {:.3} ms (goal p50 <= 1 ms)",
        lat.len(),
        percentile(&mut lat, 0.50),
        percentile(&mut lat, 0.90),
        percentile(&mut lat, 0.99)
    );
    l.client.stop();
    l.server.stop();
    let mut p50s = Vec::new();
    let mut p99s = Vec::new();
    let mut cpus = Vec::new();
    for r in 0..3 {
        let (p50, p99, pushes, cpu) = hundred_clients(3.0);
        println!(
            "  round {r}: 100 clients, {pushes} push rounds: lateness p50 {p50:.2} ms p99 {p99:.2} ms, server CPU {cpu:.1} % of a core"
        );
        p50s.push(p50);
        p99s.push(p99);
        cpus.push(cpu);
    }
    println!(
        "100 clients on laser+encoders every 33 ms: push lateness median p50 {:.2} ms, median p99 {:.2} ms (goal p99 <= 5 ms); server CPU median {:.1} % of one core",
        median(&mut p50s),
        median(&mut p99s),
        median(&mut cpus)
    );
}
