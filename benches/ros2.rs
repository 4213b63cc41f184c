//! The `ros2` service and driver against Eclipse Cyclone DDS ↔ Cyclone DDS, in
//! the same run. The Cyclone side is `benches/ros2/cyclone_bench.c` on Debian's
//! libddsc 0.10.2 (the DDS of rmw_cyclonedds), with ROS 2's types under their DDS
//! names (`benches/ros2/ros2_msgs.idl`), built here once with `idlc` and `cc`
//! into `target/cyclone-bench/`. Medians of alternated rounds (which side goes
//! first alternates); each side has its own DDS domain.
//!
//! (a) 640x480 `bgr8` Images per second a Cyclone subscriber receives (sensor
//!     QoS: best effort, keep last 5): from the service serving `varcolorA`
//!     (fed one frame per ms at most; `JDEROBOT_BENCH_FEED_MS=33` feeds a
//!     camera's 30 Hz) vs from a Cyclone publisher (one per ms at most).
//!     Goal >= 90 %.
//! (b) LaserScan (180 ranges, 50 Hz) publish → `laser` of the driver, p50 of
//!     the wall-clock delay, vs a Cyclone subscriber's (publish stamp → take).
//!     Goal <= 1.1x.
//! (c) `/cmd_vel` Twist (100 Hz, reliable) from Cyclone → the service's
//!     `motors`, p50, vs a Cyclone subscriber's. Goal p50 <= 1 ms.
//! (d) CPU (process ticks) of the service serving laser + odom (and a 640x480
//!     image) at 20 Hz to 10 Cyclone subscriber processes, vs a Cyclone
//!     publisher of the same topics to the same 10 subscribers.
//!     `JDEROBOT_BENCH_THREADS=1` also prints each side's CPU by thread.
//!
//! Run: `cargo bench --no-default-features --features ros2,simulator --bench ros2`
//! (docs/benchmarks.md). Without idlc, cc or libddsc it prints SKIPPED.

mod common;
use common::{cpu_by_thread_of, median, process_cpu};

use std::{
    collections::HashMap,
    path::{Path, PathBuf},
    process::{Child, Command, Stdio},
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, Instant, SystemTime, UNIX_EPOCH},
};

use jderobot::{
    Conf, Runtime,
    conf::Kind,
    interfaces::{Encoders, Image, Interface, InterfaceValue, Laser, Motors, Watch},
};

const ROUNDS: usize = 5;
const SECS: u32 = 3;

/// Builds the Cyclone peer (idlc, then cc -lddsc) into target/cyclone-bench.
fn peer() -> Option<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("target/cyclone-bench");
    std::fs::create_dir_all(&dir).ok()?;
    let idl = Command::new("idlc")
        .arg("-o")
        .arg(&dir)
        .arg(root.join("benches/ros2/ros2_msgs.idl"))
        .status()
        .ok()?;
    let bin = dir.join("cyclone_bench");
    let cc = Command::new("cc")
        .args(["-O2", "-Wall", "-I"])
        .arg(&dir)
        .arg(root.join("benches/ros2/cyclone_bench.c"))
        .arg(dir.join("ros2_msgs.c"))
        .args(["-lddsc", "-o"])
        .arg(&bin)
        .status()
        .ok()?;
    (idl.success() && cc.success()).then_some(bin)
}

/// A Cyclone process, killed when dropped.
struct Peer(Option<Child>);
impl Drop for Peer {
    fn drop(&mut self) {
        if let Some(c) = &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

impl Peer {
    fn ended(&mut self) -> bool {
        self.0
            .as_mut()
            .is_none_or(|c| c.try_wait().ok().flatten().is_some())
    }
    fn id(&self) -> u32 {
        self.0.as_ref().map_or(0, |c| c.id())
    }
}

fn cyclone(bin: &Path, args: &[&str]) -> Peer {
    Peer(Some(
        Command::new(bin)
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start the Cyclone peer"),
    ))
}

/// What a peer printed once it ended.
fn output(mut p: Peer) -> String {
    let Some(c) = p.0.take() else {
        return String::new();
    };
    let out = c.wait_with_output().expect("the Cyclone peer's output");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A number of the JSON line a peer printed last.
fn num(out: &str, key: &str) -> f64 {
    out.lines()
        .rev()
        .find_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .and_then(|v| v[key].as_f64())
        .unwrap_or(f64::NAN)
}

/// "K NS" lines of a publisher: K → the wall time it was sent (ns).
fn sent(out: &str) -> HashMap<i64, i64> {
    out.lines()
        .filter_map(|l| {
            let (k, t) = l.split_once(' ')?;
            Some((k.parse().ok()?, t.parse().ok()?))
        })
        .collect()
}

fn wall_ns() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_nanos() as i64
}

/// A DDS domain per use, apart from other runs and tests.
fn domain(k: u32) -> String {
    (200 + (std::process::id() % 6) * 5 + k).to_string()
}

/// A runtime whose interfaces the bench feeds, with the service `ros2` on them.
struct Served {
    rt: Arc<Runtime>,
    cam: Arc<Interface<Image>>,
    laser: Arc<Interface<Laser>>,
    enc: Arc<Interface<Encoders>>,
    motors: Arc<Interface<Motors>>,
}

fn served(domain: &str) -> Served {
    let rt = Runtime::new(Path::new("bench.conf"));
    let i = &rt.interfaces;
    let cam = i
        .provide_value("varcolorA", "bench", Image::new(640, 480))
        .unwrap();
    let laser = i.provide::<Laser>("laser", "bench").unwrap();
    let enc = i.provide::<Encoders>("encoders", "bench").unwrap();
    let motors = i.provide::<Motors>("motors", "bench").unwrap();
    let text = format!(
        "service ros2\ninsecure\ndomain {domain}\nserves varcolorA\nserves laser\n\
         serves encoders\nserves motors\nend_service\n"
    );
    let conf = Conf::parse(&text, Path::new("bench.conf")).unwrap();
    jderobot::loader::load(&rt, &conf, Some(Kind::Service), "ros2", None).unwrap();
    Served {
        rt,
        cam,
        laser,
        enc,
        motors,
    }
}

/// Runs `feed(k)` every `period` on a thread until the returned flag is set.
fn feeder(period: Duration, mut feed: impl FnMut(u64) + Send + 'static) -> Feeder {
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let t = std::thread::spawn(move || {
        let mut next = Instant::now();
        let mut k = 0;
        while !s.load(Ordering::Acquire) {
            feed(k);
            k += 1;
            next += period;
            let now = Instant::now();
            if next > now {
                std::thread::sleep(next - now);
            } else {
                next = now;
            }
        }
    });
    Feeder(stop, Some(t))
}

struct Feeder(Arc<AtomicBool>, Option<std::thread::JoinHandle<()>>);
impl Drop for Feeder {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Release);
        if let Some(t) = self.1.take() {
            let _ = t.join();
        }
    }
}

/// How often the images' producer writes a frame: 1 ms (as fast as the service
/// can take them), or `JDEROBOT_BENCH_FEED_MS` ms (30 Hz is 33: a camera's pace).
fn image_period() -> Duration {
    let ms = std::env::var("JDEROBOT_BENCH_FEED_MS").ok();
    Duration::from_millis(ms.and_then(|v| v.parse().ok()).unwrap_or(1))
}

/// (a) Images/s from the service to a Cyclone subscriber.
fn ours_images(bin: &Path, d: &str, s: &Served) -> f64 {
    let sub = cyclone(
        bin,
        &["sub-image", d, &SECS.to_string(), "rt/varcolorA/image_raw"],
    );
    let cam = s.cam.clone();
    let _feed = feeder(image_period(), move |k| {
        let _ = cam.write(|img| img.data[0] = k as u8);
    });
    num(&output(sub), "rate")
}

/// (a) Images/s from a Cyclone publisher to a Cyclone subscriber.
fn cyclone_images(bin: &Path, d: &str) -> f64 {
    let sub = cyclone(bin, &["sub-image", d, &SECS.to_string(), "rt/img"]);
    let _publ = cyclone(bin, &["pub-image", d, "60", "rt/img"]);
    num(&output(sub), "rate")
}

/// (b) LaserScan publish → the driver's `laser`.
fn ours_laser(bin: &Path, d: &str, laser: &Arc<Interface<Laser>>) -> Arrivals {
    let publ = cyclone(bin, &["pub-scan", d, &SECS.to_string(), "50"]);
    arrivals(publ, laser, |l| l.readings[0] as i64)
}

/// The p50 ms from a message's publication to its arrival in an interface: when
/// it is stored (`Sample::stamp`: the moment any reader can read it, what a
/// Cyclone subscriber's take is) and when a reader woken by a watch has it (one
/// more thread wake-up); how many arrived.
struct Arrivals {
    stored: f64,
    woken: f64,
    n: usize,
}

/// The [`Arrivals`] of each message the Cyclone publisher `publ` sent (numbered
/// by `number` of the value, as the publisher numbered it) in `iface`, until the
/// publisher ends.
fn arrivals<T: InterfaceValue>(
    mut publ: Peer,
    iface: &Arc<Interface<T>>,
    number: impl Fn(&T) -> i64,
) -> Arrivals {
    let w = Watch::for_current_thread();
    iface.watch(w.clone());
    let mut got = vec![];
    let mut seen = iface.clock();
    while !publ.ended() {
        if !w.wait(Duration::from_millis(50)) {
            continue;
        }
        let s = iface.read();
        if s.clock != seen {
            seen = s.clock;
            let at = wall_ns();
            got.push((
                number(&s.value),
                at - s.stamp.elapsed().as_nanos() as i64,
                at,
            ));
        }
    }
    iface.unwatch(&*w);
    let sent = sent(&output(publ));
    let (mut stored, mut woken) = (vec![], vec![]);
    for (k, at_store, at_wake) in got {
        if let Some(t) = sent.get(&k) {
            stored.push((at_store - t) as f64 / 1e6);
            woken.push((at_wake - t) as f64 / 1e6);
        }
    }
    Arrivals {
        n: stored.len(),
        stored: median(&stored),
        woken: median(&woken),
    }
}

/// (b), (c): a Cyclone subscriber's p50 ms for publisher mode `publ`.
fn cyclone_latency(bin: &Path, d: &str, sub: &str, publ: &str, hz: &str) -> (f64, usize) {
    let s = cyclone(bin, &[sub, d, &SECS.to_string()]);
    let _p = cyclone(bin, &[publ, d, "60", hz]);
    let out = output(s);
    (num(&out, "p50_ms"), num(&out, "n") as usize)
}

/// (c) `/cmd_vel` → the service's `motors`.
fn ours_cmd_vel(bin: &Path, d: &str, motors: &Arc<Interface<Motors>>) -> Arrivals {
    let publ = cyclone(bin, &["pub-twist", d, &SECS.to_string(), "100"]);
    arrivals(publ, motors, |m| m.v.round() as i64)
}

/// Starts 10 Cyclone subscribers of scan, odom (and the image) for SECS + 4 s
/// (~140 scans at 20 Hz), measures process `pid`'s CPU over SECS once they
/// receive; returns (% of a core, the scans of the subscriber that got fewest).
fn ten_subscribers(bin: &Path, d: &str, pid: u32, image: bool) -> (f64, f64) {
    let img = if image { "1" } else { "0" };
    let subs: Vec<Peer> = (0..10)
        .map(|_| cyclone(bin, &["sub-many", d, &(SECS + 4).to_string(), img]))
        .collect();
    std::thread::sleep(Duration::from_secs(3));
    let by0 = cpu_by_thread_of(&pid.to_string());
    let (t0, c0) = (Instant::now(), process_cpu(pid).unwrap_or(0.0));
    std::thread::sleep(Duration::from_secs(SECS as u64));
    let cpu = process_cpu(pid).unwrap_or(0.0) - c0;
    let secs = t0.elapsed().as_secs_f64();
    if std::env::var_os("JDEROBOT_BENCH_THREADS").is_some() {
        show_threads(pid, &by0, secs);
    }
    let scans: Vec<f64> = subs.into_iter().map(|s| num(&output(s), "scan")).collect();
    let fewest = scans.iter().copied().fold(f64::INFINITY, f64::min);
    (cpu / secs * 100.0, fewest)
}

/// Where a process's CPU went since `by0` (`JDEROBOT_BENCH_THREADS=1`): % of a
/// core by thread name, the largest first.
fn show_threads(pid: u32, by0: &std::collections::BTreeMap<String, f64>, secs: f64) {
    let mut by: Vec<(f64, String)> = cpu_by_thread_of(&pid.to_string())
        .into_iter()
        .map(|(name, s)| ((s - by0.get(&name).unwrap_or(&0.0)) / secs * 100.0, name))
        .collect();
    by.sort_by(|a, b| b.0.total_cmp(&a.0));
    let top: Vec<String> = by
        .iter()
        .take(6)
        .map(|(p, n)| format!("{n} {p:.3}"))
        .collect();
    println!("    threads of {pid}: {}", top.join(", "));
}

/// (d) Ours: the service (this process) at 20 Hz.
fn ours_cpu(bin: &Path, d: &str, s: &Served, image: bool) -> (f64, f64) {
    let (laser, enc, cam) = (s.laser.clone(), s.enc.clone(), s.cam.clone());
    let _feed = feeder(Duration::from_millis(50), move |k| {
        let _ = laser.publish(scan(k));
        let _ = enc.publish(Encoders::from_pose(k as f32, 0.0, 0.0));
        if image {
            let _ = cam.write(|img| img.data[0] = k as u8);
        }
    });
    ten_subscribers(bin, d, std::process::id(), image)
}

/// (d) Reference: a Cyclone publisher of the same topics at 20 Hz.
fn cyclone_cpu(bin: &Path, d: &str, image: bool) -> (f64, f64) {
    let img = if image { "1" } else { "0" };
    let p = cyclone(bin, &["pub-many", d, "60", "20", img]);
    ten_subscribers(bin, d, p.id(), image)
}

fn scan(k: u64) -> Laser {
    Laser {
        readings: (0..180).map(|i| 1000 + i * 10 + (k % 7) as i32).collect(),
        ..Laser::default()
    }
}

fn show_arrivals((a, c): &(Arrivals, (f64, usize))) -> String {
    format!(
        "jderobot stored {:.3} woken {:.3} (n {}), Cyclone {:.3} (n {})",
        a.stored, a.woken, a.n, c.0, c.1
    )
}

/// Medians over the rounds: stored, woken, Cyclone's, and of the rounds' ratios
/// stored / Cyclone's.
fn latencies(r: &[(Arrivals, (f64, usize))]) -> (f64, f64, f64, f64) {
    (
        median(r.iter().map(|x| x.0.stored).collect::<Vec<_>>()),
        median(r.iter().map(|x| x.0.woken).collect::<Vec<_>>()),
        median(r.iter().map(|x| x.1.0).collect::<Vec<_>>()),
        median(r.iter().map(|x| x.0.stored / x.1.0).collect::<Vec<_>>()),
    )
}

/// Runs `ours` and `theirs` alternately ROUNDS times: (ours, theirs) per round.
fn rounds<O, T>(
    what: &str,
    mut ours: impl FnMut() -> O,
    mut theirs: impl FnMut() -> T,
    show: impl Fn(&(O, T)) -> String,
) -> Vec<(O, T)> {
    (0..ROUNDS)
        .map(|r| {
            let (o, t) = if r % 2 == 0 {
                let o = ours();
                (o, theirs())
            } else {
                let t = theirs();
                (ours(), t)
            };
            let x = (o, t);
            println!("  {what} round {r}: {}", show(&x));
            x
        })
        .collect()
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return;
    }
    let Some(bin) = peer() else {
        println!("SKIPPED: the ros2 bench needs idlc, cc and cyclonedds-dev (see .ci/run)");
        return;
    };
    let only = std::env::args().nth(1).filter(|a| !a.starts_with('-'));
    let part = |p: &str| only.as_deref().is_none_or(|o| o == p);
    println!("ros2 vs Cyclone DDS 0.10.2 <-> Cyclone, {ROUNDS} alternated rounds of {SECS} s");
    if part("images") {
        let s = served(&domain(0));
        let d = domain(1);
        let r = rounds(
            "images/s",
            || ours_images(&bin, &domain(0), &s),
            || cyclone_images(&bin, &d),
            |(o, t)| format!("jderobot {o:.0}, Cyclone {t:.0}"),
        );
        let o = median(r.iter().map(|x| x.0).collect::<Vec<_>>());
        let t = median(r.iter().map(|x| x.1).collect::<Vec<_>>());
        let ratio = median(r.iter().map(|x| x.0 / x.1).collect::<Vec<_>>());
        println!(
            "(a) 640x480 bgr8 Images/s to a Cyclone subscriber: service {o:.0}, Cyclone \
             publisher {t:.0} (ratio {:.0} %, goal >= 90 %)",
            ratio * 100.0
        );
        s.rt.shutdown();
    }
    if part("laser") {
        let d = domain(2);
        let text = format!(
            "driver ros2\ninsecure\ndomain {d}\nprovides laser /scan\nend_driver\nload_driver ros2\n"
        );
        let rt =
            jderobot::loader::start(&Conf::parse(&text, Path::new("b.conf")).unwrap()).unwrap();
        let laser = rt.interfaces.get::<Laser>("laser").unwrap();
        let d2 = domain(3);
        let r = rounds(
            "laser p50 ms",
            || ours_laser(&bin, &d, &laser),
            || cyclone_latency(&bin, &d2, "sub-scan", "pub-scan", "50"),
            show_arrivals,
        );
        let (o, w, t, ratio) = latencies(&r);
        println!(
            "(b) LaserScan publish -> driver's laser p50: stored {o:.3} ms, woken reader \
             {w:.3} ms; Cyclone -> Cyclone {t:.3} ms (ratio stored {ratio:.2}x, goal <= 1.1x; \
             woken {:.2}x)",
            w / t
        );
        rt.shutdown();
    }
    if part("cmd_vel") {
        let s = served(&domain(0));
        let d2 = domain(3);
        let r = rounds(
            "cmd_vel p50 ms",
            || ours_cmd_vel(&bin, &domain(0), &s.motors),
            || cyclone_latency(&bin, &d2, "sub-twist", "pub-twist", "100"),
            show_arrivals,
        );
        let (o, w, t, ratio) = latencies(&r);
        println!(
            "(c) /cmd_vel -> service's motors p50: stored {o:.3} ms (goal <= 1 ms), woken \
             reader {w:.3} ms; Cyclone -> Cyclone {t:.3} ms (ratio stored {ratio:.2}x)"
        );
        s.rt.shutdown();
    }
    if part("cpu") {
        let s = served(&domain(0));
        let d2 = domain(4);
        for image in [false, true] {
            let what = if image {
                "laser + odom + image"
            } else {
                "laser + odom"
            };
            let r = rounds(
                "CPU % of a core",
                || ours_cpu(&bin, &domain(0), &s, image),
                || cyclone_cpu(&bin, &d2, image),
                |(o, t)| {
                    format!(
                        "jderobot {:.2} (fewest scans {:.0}), Cyclone {:.2} (fewest {:.0})",
                        o.0, o.1, t.0, t.1
                    )
                },
            );
            let o = median(r.iter().map(|x| x.0.0).collect::<Vec<_>>());
            let t = median(r.iter().map(|x| x.1.0).collect::<Vec<_>>());
            println!(
                "(d) CPU, {what} at 20 Hz to 10 Cyclone subscribers: service process {o:.2} % \
                 of a core, Cyclone publisher {t:.2} % (ratio {:.2}x, goal <= 1.5x); fewest \
                 scans a subscriber got: jderobot {:.0}, Cyclone {:.0} of ~140",
                o / t,
                r.iter().map(|x| x.0.1).fold(f64::INFINITY, f64::min),
                r.iter().map(|x| x.1.1).fold(f64::INFINITY, f64::min),
            );
        }
        s.rt.shutdown();
    }
}
