//! The python schema's costs, each against a reference measured in the same run
//! (medians of 7 alternated rounds):
//! - one loop of `getLaserData`, `getPose3d`, `setV`, `setW` beyond an empty Python
//!   loop (goal ≤ 20 µs);
//! - `getImage` at 640×480 against a numpy copy of the same bytes (goal ≤ 0.2 ms);
//! - the pacing error of a python schema at 20 ms against a Rust schema's
//!   (myschema) in the same runtime (goal within 0.5 %), once both loops turn;
//! - a run's start: a fresh worker process to the program's first pass.
//!
//! `cargo bench --features full --bench python`

mod common;
use common::median;

use std::{
    path::Path,
    time::{Duration, Instant},
};

use jderobot::{Conf, schemas::python::shared};

const PROGRAM: &str = r#"
import time
import statistics
import numpy as np
from HAL import HAL

N = 5000
empty, hal, image, copy = [], [], [], []
for r in range(7):
    t = time.perf_counter()
    for i in range(N):
        pass
    empty.append((time.perf_counter() - t) / N)
    t = time.perf_counter()
    for i in range(N):
        HAL.getLaserData()
        HAL.getPose3d()
        HAL.setV(0.0)
        HAL.setW(0.0)
    hal.append((time.perf_counter() - t) / N)
    img = HAL.getImage()
    t = time.perf_counter()
    for i in range(200):
        HAL.getImage()
    image.append((time.perf_counter() - t) / 200)
    t = time.perf_counter()
    for i in range(200):
        img.copy()
    copy.append((time.perf_counter() - t) / 200)
m = statistics.median
print(f"RESULT {m(empty)*1e6:.3f} {m(hal)*1e6:.3f} {m(image)*1e3:.4f} {m(copy)*1e3:.4f} {img.shape[1]}x{img.shape[0]}")
"#;

fn main() {
    let dir = std::env::temp_dir().join(format!("jderobot-bench-python-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let prog = dir.join("bench.py");
    std::fs::write(&prog, PROGRAM).unwrap();
    let idle = dir.join("idle.py");
    std::fs::write(&idle, "from HAL import HAL\nwhile True:\n    HAL.setV(0)\n").unwrap();
    let world = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/worlds/simple.world");
    let conf = |file: &Path, cycle: u32, extra: &str| {
        format!(
            "driver simulator\nworld {}\nprovides encoders\nprovides motors\nprovides laser 180 1\n\
             provides bumpers\nprovides varcolorA 640 480\nend_driver\n\
             schema python\nfile {}\ncycle {cycle}\ncamera varcolorA\nend_schema\n{extra}\
             load_driver simulator\nload_schema python\n",
            world.display(),
            file.display()
        )
    };

    // 1 and 2: the program times itself.
    let text = conf(&prog, 50, "");
    let rt = jderobot::loader::start(&Conf::parse(&text, &dir.join("b.conf")).unwrap()).unwrap();
    rt.run("python").unwrap();
    let s = shared(&rt, "python");
    let t = Instant::now();
    let line = loop {
        let found = s
            .console
            .lock()
            .lines
            .iter()
            .find(|l| l.starts_with("RESULT"))
            .cloned();
        if let Some(l) = found {
            break l;
        }
        if let Some(e) = rt.schema_status("python").and_then(|s| s.last_error) {
            panic!("the benchmark program failed: {e}");
        }
        assert!(t.elapsed() < Duration::from_secs(300), "no result");
        std::thread::sleep(Duration::from_millis(50));
    };
    rt.shutdown();
    let f: Vec<&str> = line.split_whitespace().collect();
    let (empty, hal, image, copy) = (
        f[1].parse::<f64>().unwrap(),
        f[2].parse::<f64>().unwrap(),
        f[3].parse::<f64>().unwrap(),
        f[4].parse::<f64>().unwrap(),
    );
    println!("python: one loop of getLaserData+getPose3d+setV+setW");
    println!(
        "  {hal:.2} µs per loop, empty Python loop {empty:.3} µs: {:.2} µs beyond Python's own (goal ≤ 20 µs)",
        hal - empty
    );
    println!(
        "python: getImage at {}: {image:.4} ms, numpy copy of the same bytes {copy:.4} ms, ratio {:.2} (goal ≤ 0.2 ms)",
        f[5],
        image / copy
    );

    // 3: pacing at 20 ms, the python schema beside a Rust schema.
    pacing(
        &conf(
            &idle,
            20,
            "schema myschema\ncycle 20\nend_schema\nload_schema myschema\n",
        ),
        &dir,
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The pacing of a python schema at 20 ms beside a Rust schema (myschema) in
/// the same runtime (conf `text`), once both loops turn; and a run's start (a
/// fresh worker process) to its first pass.
fn pacing(text: &str, dir: &Path) {
    let rt = jderobot::loader::start(&Conf::parse(text, &dir.join("p.conf")).unwrap()).unwrap();
    jderobot::output::set_sink(Some(Box::new(|_| {})));
    let mut py_err: Vec<f64> = Vec::new();
    let mut rs_err: Vec<f64> = Vec::new();
    let mut py_j: Vec<f64> = Vec::new();
    let mut starts: Vec<f64> = Vec::new();
    for round in 0..7 {
        let names = if round % 2 == 0 {
            ["python", "myschema"]
        } else {
            ["myschema", "python"]
        };
        let iterations = |n: &str| rt.schema_status(n).unwrap().timing.iterations;
        let before: Vec<u64> = names.iter().map(|n| iterations(n)).collect();
        for (n, b) in names.iter().zip(&before) {
            let t = Instant::now();
            rt.run(n).unwrap();
            if *n == "python" {
                // Each run starts a fresh worker process: measured apart, and the
                // pacing counted once both loops turn.
                while iterations(n) <= *b {
                    std::thread::sleep(Duration::from_micros(200));
                }
                starts.push(t.elapsed().as_secs_f64() * 1e3);
            }
        }
        while names
            .iter()
            .zip(&before)
            .any(|(n, b)| iterations(n) < b + 3)
        {
            std::thread::sleep(Duration::from_millis(1));
        }
        let start: Vec<u64> = names
            .iter()
            .map(|n| rt.schema_status(n).unwrap().timing.iterations)
            .collect();
        let t = Instant::now();
        std::thread::sleep(Duration::from_secs(3));
        let secs = t.elapsed().as_secs_f64();
        for (i, n) in names.iter().enumerate() {
            let st = rt.schema_status(n).unwrap();
            let rate = (st.timing.iterations - start[i]) as f64 / secs;
            let err = (rate - 50.0).abs() / 50.0 * 100.0;
            if *n == "python" {
                py_err.push(err);
                py_j.push(st.timing.jitter_p99 * 1e3);
            } else {
                rs_err.push(err);
            }
        }
        for n in names {
            rt.stop(n).unwrap();
        }
    }
    rt.shutdown();
    println!(
        "python: pacing at 20 ms: rate error {:.3} % (Rust schema {:.3} %; goal within 0.5 %), jitter p99 {:.3} ms",
        median(&py_err),
        median(&rs_err),
        median(&py_j)
    );
    println!(
        "python: a run's start (a fresh worker process, the program compiled) to its first pass: {:.1} ms",
        median(&starts)
    );
}
