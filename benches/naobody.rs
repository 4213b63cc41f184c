//! naobody against a Python `qi` client of the same services, in the same run
//! (harness = false; alternating rounds, medians), both talking to the NAOqi
//! stand-in on the real libqi (`tests/emulators/naoqi.py --bench`: a new frame
//! on every `getImageRemote`, so the rate is the client's and the transport's):
//!
//! 1. Camera frames per second at 320x240 and 640x480 (kBGRColorSpace): the
//!    Python client calls `getImageRemote` in a loop and counts frames; ours is
//!    `naobody` with `fps 10000` (unpaced) counting new values of `varcolorA`.
//! 2. A `motors` write to ALMotion: from the write (Python: just before
//!    `ALMotion.move(...)`; ours: `Interface::publish` on `motors`) to the
//!    moment the stand-in's `move` runs (its wall clock, same machine), p50 over
//!    200 writes 20 ms apart. The Python call's full round trip (call to reply)
//!    is printed too.
//!
//! Run: `cargo bench --no-default-features --features naobody --bench naobody`
//! (needs the test venv with `qi`: `target/py-venv`, or `JDEROBOT_PYTHON`).

mod common;
use common::{free_port, median};

use std::{
    io::{BufRead, BufReader},
    path::{Path, PathBuf},
    process::{Child, Command, Stdio},
    sync::{Arc, Mutex},
    time::{Duration, Instant, SystemTime, UNIX_EPOCH},
};

use jderobot::{
    Conf,
    interfaces::{Image, Motors},
    loader,
};

const ROUNDS: usize = 5;
const SECONDS: f64 = 3.0;
const WRITES: usize = 200;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
}

struct Peer {
    child: Child,
    lines: Arc<Mutex<Vec<String>>>,
}

impl Drop for Peer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Peer {
    fn start(py: &Path, port: u16) -> Peer {
        let mut child = Command::new(py)
            .arg(root().join("tests/emulators/naoqi.py"))
            .args([
                "--url",
                &format!("tcp://127.0.0.1:{port}"),
                "--bench",
                "--trace",
            ])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("start the stand-in");
        let lines = Arc::new(Mutex::new(Vec::new()));
        let l = lines.clone();
        let out = child.stdout.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                l.lock().unwrap().push(line);
            }
        });
        let p = Peer { child, lines };
        let t0 = Instant::now();
        while !p
            .lines
            .lock()
            .unwrap()
            .iter()
            .any(|l| l.starts_with("READY"))
        {
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "the stand-in did not start"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        p
    }

    /// The wall-clock times of the `move` calls traced since line `from`.
    fn moves_since(&self, from: usize) -> Vec<f64> {
        self.lines.lock().unwrap()[from..]
            .iter()
            .filter(|l| l.starts_with("MOVE "))
            .filter_map(|l| l.split(' ').nth(4)?.parse().ok())
            .collect()
    }

    fn len(&self) -> usize {
        self.lines.lock().unwrap().len()
    }
}

/// Runs the Python client with `args`; its output lines.
fn py_client(py: &Path, port: u16, args: &[&str]) -> Vec<String> {
    let out = Command::new(py)
        .arg(root().join("tests/emulators/naoqi.py"))
        .args(["--client", &format!("tcp://127.0.0.1:{port}")])
        .args(args)
        .stderr(Stdio::null())
        .output()
        .expect("run the Python client");
    assert!(out.status.success(), "the Python client failed");
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(String::from)
        .collect()
}

fn runtime(port: u16, lines: &str) -> Arc<jderobot::Runtime> {
    let text = format!(
        "driver naobody\nurl tcp://127.0.0.1:{port}\n{lines}end_driver\nload_driver naobody\n"
    );
    loader::start(&Conf::parse(&text, Path::new("bench.conf")).unwrap()).unwrap()
}

fn ours_fps(port: u16, w: u32, h: u32) -> f64 {
    let rt = runtime(port, &format!("provides varcolorA 0 {w} {h}\nfps 10000\n"));
    let cam = rt.interfaces.get::<Image>("varcolorA").unwrap();
    cam.resume();
    let t0 = Instant::now();
    while cam.clock() < 3 {
        assert!(t0.elapsed() < Duration::from_secs(20), "no frames");
        std::thread::sleep(Duration::from_millis(1));
    }
    let (c0, t0) = (cam.clock(), Instant::now());
    std::thread::sleep(Duration::from_secs_f64(SECONDS));
    let n = (cam.clock() - c0) as f64 / t0.elapsed().as_secs_f64();
    cam.suspend();
    rt.shutdown();
    n
}

fn py_fps(py: &Path, port: u16, w: u32, h: u32) -> f64 {
    let out = py_client(
        py,
        port,
        &[
            "--camera",
            &format!("{w}x{h}"),
            "--seconds",
            &SECONDS.to_string(),
        ],
    );
    out.iter()
        .find_map(|l| l.strip_prefix("FPS ")?.parse().ok())
        .expect("an FPS line")
}

/// Ours: publish → the stand-in's `move` runs, p50 in ms.
fn ours_write(peer: &Peer, port: u16) -> f64 {
    let rt = runtime(port, "provides motors\nmotors_timeout 60000\nmax_v 1000\n");
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    // The first command wakes the robot up: not measured.
    motors.publish(Motors { v: 1.0, w: 0.0 }).unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let from = peer.len();
    let mut sent = Vec::with_capacity(WRITES);
    for i in 0..WRITES {
        let v = 2.0 + (i % 50) as f32;
        sent.push(now());
        motors.publish(Motors { v, w: 0.0 }).unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(200));
    let got = peer.moves_since(from);
    rt.shutdown();
    assert_eq!(got.len(), WRITES, "one move per write");
    median(
        got.iter()
            .zip(&sent)
            .map(|(t1, t0)| (t1 - t0) * 1e3)
            .collect::<Vec<f64>>(),
    )
}

/// Python: just before the call → the stand-in's `move` runs, p50 in ms; and the
/// call's round trip p50 in ms.
fn py_write(py: &Path, peer: &Peer, port: u16) -> (f64, f64) {
    let from = peer.len();
    let out = py_client(py, port, &["--count", &WRITES.to_string()]);
    let sent: Vec<f64> = out
        .iter()
        .filter_map(|l| l.strip_prefix("SENT ")?.split(' ').nth(1)?.parse().ok())
        .collect();
    let rtt: f64 = out
        .iter()
        .find_map(|l| l.strip_prefix("RTT ")?.parse().ok())
        .expect("an RTT line");
    let got = peer.moves_since(from);
    assert_eq!(got.len(), sent.len());
    (
        median(
            got.iter()
                .zip(&sent)
                .map(|(t1, t0)| (t1 - t0) * 1e3)
                .collect::<Vec<f64>>(),
        ),
        rtt * 1e3,
    )
}

fn main() {
    let py = std::env::var_os("JDEROBOT_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target/py-venv/bin/python"));
    let has_qi = Command::new(&py)
        .args(["-c", "import qi"])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !has_qi {
        eprintln!(
            "{} cannot import qi: `pip install qi==3.1.5` in the test venv",
            py.display()
        );
        return;
    }
    let port = free_port();
    let peer = Peer::start(&py, port);
    println!("naobody vs a Python qi client, {ROUNDS} alternating rounds, medians");
    for (w, h) in [(320, 240), (640, 480)] {
        let (mut ours, mut theirs) = (Vec::new(), Vec::new());
        for r in 0..ROUNDS {
            let (o, p) = if r % 2 == 0 {
                let p = py_fps(&py, port, w, h);
                (ours_fps(port, w, h), p)
            } else {
                let o = ours_fps(port, w, h);
                (o, py_fps(&py, port, w, h))
            };
            println!("  {w}x{h} round {r}: naobody {o:.1} frames/s, Python {p:.1} frames/s");
            ours.push(o);
            theirs.push(p);
        }
        let (o, p) = (median(ours), median(theirs));
        println!(
            "camera {w}x{h} BGR: naobody {o:.1} frames/s, Python qi {p:.1} frames/s, ratio {:.2}",
            o / p
        );
    }
    let (mut ours, mut theirs, mut rtts) = (Vec::new(), Vec::new(), Vec::new());
    for r in 0..ROUNDS {
        let o = ours_write(&peer, port);
        let (p, rtt) = py_write(&py, &peer, port);
        println!(
            "  motors round {r}: naobody {o:.3} ms, Python {p:.3} ms (call round trip {rtt:.3} ms)"
        );
        ours.push(o);
        theirs.push(p);
        rtts.push(rtt);
    }
    let (o, p) = (median(ours), median(theirs));
    println!(
        "motors write -> ALMotion.move p50: naobody {o:.3} ms, Python qi {p:.3} ms, ratio {:.2} \
         (Python call round trip {:.3} ms)",
        o / p,
        median(rtts)
    );
}
