//! Schema pacing: period accuracy and jitter of the runtime's absolute-deadline
//! loop beside the seed's loop (`sleep(cycle - elapsed)`), measured in the same
//! run, for 1, 10 and 100 schemas at 1, 10 and 100 ms cycles; and the headless
//! start-up time of the binary to a schema's first iteration.
//!
//! `cargo bench --bench runtime` (set `JDEROBOT_BENCH_QUICK=1` for a short run).
//! Figures: mean period error = (mean period − cycle) / cycle; jitter = |period −
//! cycle| per period, median and 99th percentile over every schema's periods.

use std::{
    io::{BufRead, BufReader},
    path::Path,
    process::{Command, Stdio},
    sync::{Arc, Mutex},
    time::{Duration, Instant},
};

use jderobot::{
    Context, Runtime, Schema,
    runtime::pacer::{now_ns, precise_timers_for_this_thread},
};

/// Records the start time of each iteration.
struct Probe {
    cycle: Duration,
    starts: Arc<Mutex<Vec<u64>>>,
}

impl Schema for Probe {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn iteration(&mut self, _: &Context) -> anyhow::Result<()> {
        self.starts.lock().unwrap().push(now_ns());
        Ok(())
    }
}

struct Figures {
    error_pct: f64,
    p50_us: f64,
    p99_us: f64,
}

fn figures(all: &[Vec<u64>], cycle: Duration) -> Figures {
    let c = cycle.as_nanos() as f64;
    let mut periods = Vec::new();
    for starts in all {
        // Skip the first period of each schema (start-up).
        for w in starts.windows(2).skip(1) {
            periods.push((w[1] - w[0]) as f64);
        }
    }
    let mean = periods.iter().sum::<f64>() / periods.len().max(1) as f64;
    let mut jitter: Vec<f64> = periods.iter().map(|p| (p - c).abs()).collect();
    jitter.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let pct = |p: f64| jitter[((jitter.len() - 1) as f64 * p).round() as usize] / 1e3;
    Figures {
        error_pct: (mean - c) / c * 100.0,
        p50_us: pct(0.5),
        p99_us: pct(0.99),
    }
}

/// Our runtime: n schemas at `cycle` for `span`.
fn ours(n: usize, cycle: Duration, span: Duration) -> Figures {
    let rt = Runtime::new(Path::new("bench.conf"));
    let mut logs = Vec::new();
    for i in 0..n {
        let starts = Arc::new(Mutex::new(Vec::with_capacity(
            (span.as_nanos() / cycle.as_nanos()) as usize + 16,
        )));
        logs.push(starts.clone());
        rt.add_schema(&format!("probe{i}"), "", Box::new(Probe { cycle, starts }))
            .expect("add schema");
    }
    jderobot::output::set_sink(Some(Box::new(|_| {})));
    for i in 0..n {
        rt.run(&format!("probe{i}")).unwrap();
    }
    std::thread::sleep(span);
    rt.shutdown();
    jderobot::output::set_sink(None);
    let all: Vec<Vec<u64>> = logs.iter().map(|l| l.lock().unwrap().clone()).collect();
    figures(&all, cycle)
}

/// The seed's loop: iterate, then sleep `cycle - elapsed` (4.3's myschema template).
fn seed(n: usize, cycle: Duration, span: Duration) -> Figures {
    let end = Instant::now() + span;
    let threads: Vec<_> = (0..n)
        .map(|_| {
            std::thread::spawn(move || {
                precise_timers_for_this_thread();
                let mut starts = Vec::new();
                while Instant::now() < end {
                    let a = Instant::now();
                    starts.push(now_ns());
                    let diff = a.elapsed();
                    std::thread::sleep(cycle.saturating_sub(diff));
                }
                starts
            })
        })
        .collect();
    let all: Vec<Vec<u64>> = threads.into_iter().map(|t| t.join().unwrap()).collect();
    figures(&all, cycle)
}

fn startup_ms(runs: usize) -> Option<(f64, f64)> {
    let bin = env!("CARGO_BIN_EXE_jderobot");
    let dir = std::env::temp_dir().join(format!("jderobot-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).ok()?;
    let conf = dir.join("start.conf");
    std::fs::write(
        &conf,
        "schema myschema\ncycle 1000\nend_schema\nload_schema myschema\nrun myschema\n",
    )
    .ok()?;
    let mut times = Vec::new();
    for _ in 0..runs {
        let t0 = Instant::now();
        let mut child = Command::new(bin)
            .args(["--headless", "--no-shell"])
            .arg(&conf)
            .env_remove("DISPLAY")
            .env_remove("WAYLAND_DISPLAY")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .ok()?;
        let mut lines = BufReader::new(child.stdout.take()?).lines();
        while let Some(Ok(l)) = lines.next() {
            if l.contains("Hello world") {
                break;
            }
        }
        times.push(t0.elapsed().as_secs_f64() * 1e3);
        let _ = child.kill();
        let _ = child.wait();
    }
    times.sort_by(|a, b| a.partial_cmp(b).unwrap());
    Some((times[times.len() / 2], times[times.len() * 9 / 10]))
}

fn main() {
    let quick = std::env::var_os("JDEROBOT_BENCH_QUICK").is_some();
    println!("schema pacing: absolute deadlines (jderobot) vs the seed's sleep(cycle - elapsed)");
    println!(
        "{:>8} {:>8} | {:>10} {:>9} {:>9} | {:>10} {:>9} {:>9}",
        "schemas", "cycle", "ours err%", "p50 µs", "p99 µs", "seed err%", "p50 µs", "p99 µs"
    );
    for &cycle_ms in &[1u64, 10, 100] {
        for &n in &[1usize, 10, 100] {
            let cycle = Duration::from_millis(cycle_ms);
            let periods = if quick { 30 } else { 200 }.min(if cycle_ms == 100 { 40 } else { 1000 });
            let span = cycle * periods as u32;
            let o = ours(n, cycle, span);
            let s = seed(n, cycle, span);
            println!(
                "{:>8} {:>6}ms | {:>+10.4} {:>9.1} {:>9.1} | {:>+10.4} {:>9.1} {:>9.1}",
                n, cycle_ms, o.error_pct, o.p50_us, o.p99_us, s.error_pct, s.p50_us, s.p99_us
            );
        }
    }
    if let Some((p50, p90)) = startup_ms(if quick { 5 } else { 21 }) {
        println!("\nheadless start to first iteration: median {p50:.1} ms, p90 {p90:.1} ms");
    }
}
