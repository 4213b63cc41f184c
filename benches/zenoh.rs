//! jderobot over Zenoh against Zenoh alone, between two processes on loopback, in
//! the same run (harness = false; medians of 5 rounds, the order alternated):
//!
//! 1. Throughput of 640x480 BGR frames (921,608-byte payloads). Reference: Zenoh's
//!    throughput example (`z_pub_thr`: one publisher putting the same payload as
//!    fast as it can, a subscriber counting). Ours: a `zenoh` service publishing
//!    an image interface that a producer refreshes every 0.1 ms, and a
//!    `zenoh` driver providing it in the other process (frames published into the
//!    local interface per second). The reference publishes as ours does
//!    (blocking, not express, priority `DataLow`) with Zenoh's default queues;
//!    also Zenoh alone with the one copy an interface's frame takes on arrival
//!    (its pixels are a `Vec`), and Zenoh alone with the frame queue jderobot's
//!    sessions set (`data_low` 16 batches, `session::FRAME_QUEUE`).
//!    `BENCH_THREADS=1` prints CPU per frame by thread of both processes;
//!    `ZBENCH_ONLY=K` runs only case K, `ZBENCH_SECS` its window (to profile).
//! 2. `motors` round trips. Reference: Zenoh's `z_ping`/`z_pong` with the same
//!    payload (8 bytes) and attachment (16 bytes). Ours: a `zenoh` driver's
//!    `motors` → the other process's `zenoh` service → its `motors` interface → the
//!    echo → its `encoders` interface → back into this process's
//!    `encoders`: interface to interface, both ways. The echo answers either on
//!    the thread that publishes `motors` there (a `Notify`, as z_pong answers in
//!    its callback: the like-for-like figure) or from a thread it wakes (one
//!    thread hop more than the reference).
//! 3. Build time is measured by a clean build with and without the feature (see
//!    docs/zenoh.md), not here.
//!
//! Run: `cargo bench --features full --bench zenoh` (`-- frames` or `-- motors`:
//! only that part).

mod common;
use common::{Sched, free_port, median, percentile};

use std::{
    collections::BTreeMap,
    io::Read,
    process::{Child, Command, Stdio},
    sync::{
        Arc,
        atomic::{AtomicU64, Ordering},
    },
    time::{Duration, Instant},
};

use jderobot::{
    Conf, Runtime,
    conf::Kind,
    interfaces::{Encoders, Image, Interface, Motors, Notify, Watch},
    loader,
};
use zenoh::{
    Wait,
    qos::{CongestionControl, Priority},
};

const ROUNDS: usize = 5;
const PINGS: usize = 2000;

/// A measure and the name it is printed under.
type Named<T> = (&'static str, fn() -> T);
/// A Zenoh session with Zenoh's defaults but the endpoints (and, with
/// `frame_queue`, the queue jderobot's sessions give frames: `FRAME_QUEUE`).
fn session(listen: Option<u16>, connect: Option<u16>, frame_queue: bool) -> zenoh::Session {
    let mut c = zenoh::Config::default();
    let ep = |p: Option<u16>| match p {
        Some(p) => format!(r#"["tcp/127.0.0.1:{p}"]"#),
        None => "[]".into(),
    };
    c.insert_json5("listen/endpoints", &ep(listen)).unwrap();
    c.insert_json5("connect/endpoints", &ep(connect)).unwrap();
    c.insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    if frame_queue {
        c.insert_json5(
            "transport/link/tx/queue/size/data_low",
            &jderobot::services::zenoh::FRAME_QUEUE.to_string(),
        )
        .unwrap();
    }
    zenoh::open(c).wait().unwrap()
}

/// A runtime with `provided` interfaces and the `zenoh` component loaded from `lines`.
fn runtime(kind: Kind, lines: &str, provide: impl FnOnce(&Runtime)) -> Arc<Runtime> {
    let dir = std::env::temp_dir().join(format!("jderobot-zbench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("z.conf");
    let section = if kind == Kind::Driver {
        "driver"
    } else {
        "service"
    };
    std::fs::write(
        &path,
        format!("{section} zenoh\n{lines}scouting off\nend_{section}\n"),
    )
    .unwrap();
    let conf = Conf::load(&path).unwrap();
    let rt = Runtime::new(&path);
    provide(&rt);
    loader::load(&rt, &conf, Some(kind), "zenoh", None).unwrap();
    rt
}

fn payload_image() -> Image {
    let mut img = Image::new(640, 480);
    for (i, b) in img.data.iter_mut().enumerate() {
        *b = (i % 251) as u8;
    }
    img
}

// ---- the other process ----

/// The encoders value that answers a `motors` command of speed `v`.
fn echoed(v: f32) -> Encoders {
    Encoders {
        x: v,
        y: 0.0,
        theta: 1.0,
        cos: 1f32.cos(),
        sin: 1f32.sin(),
    }
}

/// Answers each new `motors` command on the publishing thread.
struct Echo {
    motors: Arc<Interface<Motors>>,
    encoders: Arc<Interface<Encoders>>,
    last: AtomicU64,
}

impl Notify for Echo {
    fn notify(&self) {
        let m = self.motors.snapshot();
        if self.last.swap(m.clock, Ordering::Relaxed) != m.clock {
            let _ = self.encoders.publish(echoed(m.v));
        }
    }
}

fn child_main(role: &str, port: u16) {
    match role {
        "pub-ref" | "pub-ref-queue" => {
            let s = session(None, Some(port), role == "pub-ref-queue");
            // As jderobot's frames go: blocking, not express, priority DataLow.
            let publisher = s
                .declare_publisher("bench/img")
                .congestion_control(CongestionControl::Block)
                .priority(Priority::DataLow)
                .wait()
                .unwrap();
            let mut payload = Vec::new();
            let img = payload_image();
            payload.extend_from_slice(&640u32.to_le_bytes());
            payload.extend_from_slice(&480u32.to_le_bytes());
            payload.extend_from_slice(&img.data);
            let z = zenoh::bytes::ZBytes::from(payload);
            loop {
                publisher.put(z.clone()).wait().unwrap();
            }
        }
        "pub-ours" => {
            let mut cam: Option<Arc<Interface<Image>>> = None;
            let _rt = runtime(
                Kind::Service,
                &format!("publishes varcolorA bench/img\nconnect tcp/127.0.0.1:{port}\n"),
                |rt| {
                    cam = Some(
                        rt.interfaces
                            .provide_value("varcolorA", "bench", payload_image())
                            .unwrap(),
                    );
                },
            );
            let cam = cam.unwrap();
            let mut k = 0u8;
            loop {
                k = k.wrapping_add(1);
                cam.write(|img| img.data[0] = k).unwrap();
                std::thread::sleep(Duration::from_micros(100));
            }
        }
        "pong-ref" => {
            let s = session(None, Some(port), false);
            let publisher = s
                .declare_publisher("bench/pong")
                .express(true)
                .wait()
                .unwrap();
            let _sub = s
                .declare_subscriber("bench/ping")
                .callback(move |sample| {
                    let att = sample.attachment().cloned().unwrap();
                    publisher
                        .put(sample.payload().clone())
                        .attachment(att)
                        .wait()
                        .unwrap();
                })
                .wait()
                .unwrap();
            std::thread::park();
        }
        "pong-ours" => {
            let mut ifs = None;
            let _rt = runtime(
                Kind::Service,
                &format!(
                    "publishes motors bench/motors\npublishes encoders bench/encoders\n\
                     connect tcp/127.0.0.1:{port}\n"
                ),
                |rt| {
                    let m: Arc<Interface<Motors>> =
                        rt.interfaces.provide("motors", "bench").unwrap();
                    let e: Arc<Interface<Encoders>> =
                        rt.interfaces.provide("encoders", "bench").unwrap();
                    ifs = Some((m, e));
                },
            );
            let (motors, encoders) = ifs.unwrap();
            if std::env::var("ZBENCH_ECHO").as_deref() == Ok("inline") {
                // Answered on the thread that publishes `motors` (Zenoh's), as
                // z_pong answers in its callback.
                let echo = Arc::new(Echo {
                    motors: motors.clone(),
                    encoders,
                    last: AtomicU64::new(0),
                });
                motors.watch(echo);
                std::thread::park();
                return;
            }
            let watch = Watch::for_current_thread();
            motors.watch(watch.clone());
            let mut last = 0;
            loop {
                watch.wait(Duration::from_secs(1));
                let m = motors.snapshot();
                if m.clock != last {
                    last = m.clock;
                    encoders.publish(echoed(m.v)).unwrap();
                }
            }
        }
        other => panic!("unknown role {other}"),
    }
}

fn spawn(role: &str, port: u16) -> Child {
    let (role, echo) = role.split_once(':').unwrap_or((role, ""));
    Command::new(std::env::current_exe().unwrap())
        .env("ZBENCH_ROLE", role)
        .env("ZBENCH_ECHO", echo)
        .env("ZBENCH_PORT", port.to_string())
        .env("RUST_LOG", "error")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn stop(mut c: Child) {
    let _ = c.kill();
    let _ = c.wait();
    let mut err = String::new();
    if let Some(mut e) = c.stderr.take() {
        let _ = e.read_to_string(&mut err);
    }
    if err.contains("panicked") {
        panic!("the other process failed:\n{err}");
    }
}

// ---- this process ----

/// Frames per second received over a 2 s window after 1.5 s of warm-up.
/// With `copy`, the callback also copies each payload into a recycled buffer, the
/// one copy an interface's frame (a `Vec`) takes on arrival.
fn throughput_ref(copy: bool, frame_queue: bool) -> f64 {
    let port = free_port();
    let s = session(Some(port), None, frame_queue);
    let count = Arc::new(AtomicU64::new(0));
    let _sub = {
        let count = count.clone();
        let mut frame: Vec<u8> = Vec::new();
        s.declare_subscriber("bench/img")
            .callback_mut(move |sample| {
                assert_eq!(sample.payload().len(), 921_608);
                if copy {
                    frame.clear();
                    for sl in sample.payload().slices() {
                        frame.extend_from_slice(sl);
                    }
                }
                count.fetch_add(1, Ordering::Relaxed);
            })
            .wait()
            .unwrap()
    };
    let child = spawn(
        if frame_queue {
            "pub-ref-queue"
        } else {
            "pub-ref"
        },
        port,
    );
    let fps = rate(&count, child.id());
    stop(child);
    s.close().wait().unwrap();
    fps
}

/// Each thread's scheduling so far in process `pid`, by thread name.
fn threads(pid: u32) -> BTreeMap<String, Sched> {
    Sched::by_thread_in(&pid.to_string())
}

/// Counts per second of `count` over 2 s (`ZBENCH_SECS`), after 1.5 s of
/// warm-up; `child` is the other process (for `BENCH_THREADS`).
fn rate(count: &AtomicU64, child: u32) -> f64 {
    std::thread::sleep(Duration::from_millis(1500));
    let secs: f64 = std::env::var("ZBENCH_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2.0);
    let (me0, ch0) = (threads(std::process::id()), threads(child));
    let c0 = count.load(Ordering::Relaxed);
    let t0 = Instant::now();
    std::thread::sleep(Duration::from_secs_f64(secs));
    let n = count.load(Ordering::Relaxed) - c0;
    let dt = t0.elapsed().as_secs_f64();
    Sched::print_threads(
        "subscriber, a frame",
        &me0,
        &threads(std::process::id()),
        n as f64,
    );
    Sched::print_threads("publisher, a frame", &ch0, &threads(child), n as f64);
    n as f64 / dt
}

fn throughput_ours() -> f64 {
    let port = free_port();
    let rt = runtime(
        Kind::Driver,
        &format!("provides varcolorA bench/img\nlisten tcp/127.0.0.1:{port}\n"),
        |_| {},
    );
    let cam: Arc<Interface<Image>> = rt.interfaces.get("varcolorA").unwrap();
    cam.resume();
    let child = spawn("pub-ours", port);
    // Count the frames published into the local interface.
    let count = Arc::new(AtomicU64::new(0));
    let stop_flag = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let counter = {
        let (cam, count, stop_flag) = (cam.clone(), count.clone(), stop_flag.clone());
        std::thread::spawn(move || {
            let w = Watch::for_current_thread();
            cam.watch(w.clone());
            let mut last = cam.read().stamp;
            while !stop_flag.load(Ordering::Relaxed) {
                w.wait(Duration::from_millis(100));
                let s = cam.read();
                if s.stamp != last {
                    last = s.stamp;
                    assert_eq!(s.data.len(), 921_600);
                    count.fetch_add(1, Ordering::Relaxed);
                }
            }
        })
    };
    let fps = rate(&count, child.id());
    stop(child);
    stop_flag.store(true, Ordering::Relaxed);
    counter.join().unwrap();
    cam.suspend();
    rt.shutdown();
    fps
}

/// Round-trip times in µs.
fn pings_ref() -> Vec<f64> {
    let port = free_port();
    let s = session(Some(port), None, false);
    let watch = Watch::for_current_thread();
    let got = Arc::new(AtomicU64::new(0));
    let _sub = {
        let (got, watch) = (got.clone(), watch.clone());
        s.declare_subscriber("bench/pong")
            .callback(move |sample| {
                let b = sample.payload().to_bytes();
                got.store(
                    f32::from_le_bytes(b[..4].try_into().unwrap()) as u64,
                    Ordering::Release,
                );
                watch.wake();
            })
            .wait()
            .unwrap()
    };
    let publisher = s
        .declare_publisher("bench/ping")
        .express(true)
        .wait()
        .unwrap();
    let child = spawn("pong-ref", port);
    let mut v = Vec::with_capacity(PINGS);
    let put = |i: usize| {
        let mut p = Vec::from((i as f32).to_le_bytes());
        p.extend_from_slice(&0f32.to_le_bytes());
        publisher.put(p).attachment(vec![0u8; 16]).wait().unwrap();
    };
    // Until the other side answers (with speeds past the measured ones but within
    // motors' range, ±10,000 mm/s, which jderobot's interface refuses beyond).
    let mut i = 9_000;
    while got.load(Ordering::Acquire) != i as u64 {
        i += 1;
        put(i);
        watch.wait(Duration::from_millis(50));
    }
    for i in 1..=PINGS {
        let t = Instant::now();
        put(i);
        while got.load(Ordering::Acquire) != i as u64 {
            watch.wait(Duration::from_secs(1));
        }
        v.push(t.elapsed().as_secs_f64() * 1e6);
    }
    stop(child);
    s.close().wait().unwrap();
    v
}

/// Round-trip times in µs; the other process answers on `echo`: `thread` (a
/// thread woken by `motors`) or `inline` (on the thread that publishes it).
fn pings_ours(echo: &str) -> Vec<f64> {
    let port = free_port();
    let rt = runtime(
        Kind::Driver,
        &format!(
            "provides motors bench/motors\nprovides encoders bench/encoders\n\
             listen tcp/127.0.0.1:{port}\n"
        ),
        |_| {},
    );
    let motors: Arc<Interface<Motors>> = rt.interfaces.get("motors").unwrap();
    let encoders: Arc<Interface<Encoders>> = rt.interfaces.get("encoders").unwrap();
    encoders.resume();
    let watch = Watch::for_current_thread();
    encoders.watch(watch.clone());
    let child = spawn(&format!("pong-ours:{echo}"), port);
    let mut v = Vec::with_capacity(PINGS);
    let mut i = 9_000usize;
    let answered = |i: usize| encoders.read().x == i as f32;
    while !answered(i) {
        i += 1;
        motors
            .publish(Motors {
                v: i as f32,
                w: 0.0,
            })
            .unwrap();
        watch.wait(Duration::from_millis(50));
    }
    for i in 1..=PINGS {
        let t = Instant::now();
        motors
            .publish(Motors {
                v: i as f32,
                w: 0.0,
            })
            .unwrap();
        while !answered(i) {
            watch.wait(Duration::from_secs(1));
        }
        v.push(t.elapsed().as_secs_f64() * 1e6);
    }
    stop(child);
    encoders.unwatch(&*watch);
    encoders.suspend();
    rt.shutdown();
    v
}

fn main() {
    if let (Ok(role), Ok(port)) = (std::env::var("ZBENCH_ROLE"), std::env::var("ZBENCH_PORT")) {
        child_main(&role, port.parse().unwrap());
        return;
    }
    // `frames` or `motors` as an argument runs only that part.
    let only = |part: &str| {
        let args: Vec<String> = std::env::args().skip(1).collect();
        !args.iter().any(|a| a == "frames" || a == "motors") || args.iter().any(|a| a == part)
    };
    if only("frames") {
        frames();
    }
    if only("motors") {
        motors();
    }
}

fn frames() {
    println!("== 640x480 BGR frames between two processes (frames/s received) ==");
    // Zenoh alone (its default queues), Zenoh alone with the one copy on
    // arrival, Zenoh alone with the frame queue jderobot's sessions set, and
    // ours; the order rotates every round so none always runs on a warmer machine.
    let runs: [Named<f64>; 4] = [
        (
            "zenoh alone",
            (|| throughput_ref(false, false)) as fn() -> f64,
        ),
        (
            "zenoh alone + one copy",
            (|| throughput_ref(true, false)) as fn() -> f64,
        ),
        (
            "zenoh alone, jderobot's frame queue",
            (|| throughput_ref(false, true)) as fn() -> f64,
        ),
        ("jderobot", throughput_ours as fn() -> f64),
    ];
    // `ZBENCH_ONLY=K`: only run case K (0 to 3, in `runs`' order), e.g. under a profiler.
    let only: Option<usize> = std::env::var("ZBENCH_ONLY")
        .ok()
        .and_then(|s| s.parse().ok());
    let mut fps = vec![Vec::new(); runs.len()];
    for round in 0..ROUNDS {
        let mut line = format!("round {round}:");
        for j in 0..runs.len() {
            let k = (j + round) % runs.len();
            if only.is_some_and(|o| o != k) {
                fps[k].push(f64::NAN);
                continue;
            }
            if std::env::var_os("BENCH_THREADS").is_some() {
                println!("  {}:", runs[k].0);
            }
            let f = (runs[k].1)();
            fps[k].push(f);
            line += &format!("  {} {f:.0}", runs[k].0);
        }
        println!("{line}");
    }
    println!(
        "median: zenoh alone {:.0} frames/s ({:.0} MB/s)",
        median(&fps[0]),
        median(&fps[0]) * 0.921_608
    );
    for k in 1..runs.len() {
        let ratios: Vec<f64> = fps[0].iter().zip(&fps[k]).map(|(a, b)| b / a).collect();
        println!(
            "  {} {:.0} frames/s: {:.0} % of zenoh alone (goal for jderobot >= 100 %), rounds {:.0}-{:.0} %",
            runs[k].0,
            median(&fps[k]),
            100.0 * median(&ratios),
            100.0 * percentile(&ratios, 0.0),
            100.0 * percentile(&ratios, 1.0)
        );
    }
    let same: Vec<f64> = fps[2].iter().zip(&fps[3]).map(|(a, b)| b / a).collect();
    println!(
        "  jderobot: {:.0} % of zenoh alone with the same frame queue, rounds {:.0}-{:.0} %",
        100.0 * median(&same),
        100.0 * percentile(&same, 0.0),
        100.0 * percentile(&same, 1.0)
    );
}

fn motors() {
    println!("== motors round trips between two processes (µs) ==");
    // The reference, ours answered inline (as z_pong answers in its callback) and
    // ours answered by a woken thread; the order rotates every round.
    let runs: [Named<Vec<f64>>; 3] = [
        ("zenoh alone", pings_ref as fn() -> Vec<f64>),
        (
            "jderobot, inline echo",
            (|| pings_ours("inline")) as fn() -> Vec<f64>,
        ),
        (
            "jderobot, echo thread",
            (|| pings_ours("thread")) as fn() -> Vec<f64>,
        ),
    ];
    let mut p50 = vec![Vec::new(); runs.len()];
    for round in 0..ROUNDS {
        let mut line = format!("round {round}:");
        for j in 0..runs.len() {
            let k = (j + round) % runs.len();
            let v = (runs[k].1)();
            p50[k].push(percentile(&v, 0.5));
            line += &format!(
                "  {} p50 {:.0} p90 {:.0}",
                runs[k].0,
                percentile(&v, 0.5),
                percentile(&v, 0.9)
            );
        }
        println!("{line}");
    }
    println!("median p50: {} {:.0} µs", runs[0].0, median(&p50[0]));
    for k in 1..runs.len() {
        let ratios: Vec<f64> = p50[0].iter().zip(&p50[k]).map(|(a, b)| b / a).collect();
        println!(
            "  {} {:.0} µs: {:.2}x (goal <= 1.1x), rounds {:.2}-{:.2}x",
            runs[k].0,
            median(&p50[k]),
            median(&ratios),
            percentile(&ratios, 0.0),
            percentile(&ratios, 1.0)
        );
    }
}
