//! Helpers the benchmarks share (each bench `mod common;`): medians and
//! percentiles of rounds, a free loopback port, CPU time of a process or of this
//! process's threads. One home, so every bench computes its figures the same way.
#![allow(dead_code)]

#[cfg(feature = "_mcap")]
pub mod load;

/// The median of `v` (the upper one of an even count; NaN when empty).
pub fn median(v: impl AsRef<[f64]>) -> f64 {
    percentile(v, 0.5)
}

/// The `p` quantile of `v`, `p` in [0, 1], nearest rank (NaN when empty).
pub fn percentile(v: impl AsRef<[f64]>, p: f64) -> f64 {
    let mut v = v.as_ref().to_vec();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    if p == 0.5 {
        return v[v.len() / 2];
    }
    v[((v.len() - 1) as f64 * p.clamp(0.0, 1.0)).round() as usize]
}

/// One case of an A/B comparison: its name and the two runs of a round, each
/// returning its figure (a time).
pub type Case<'a> = (
    String,
    Box<dyn FnMut() -> f64 + 'a>,
    Box<dyn FnMut() -> f64 + 'a>,
);

/// `rounds` alternated rounds (each case's A, then its B, case after case): the
/// medians (A, B) of each case.
pub fn alternated(rounds: usize, cases: &mut [Case]) -> Vec<(f64, f64)> {
    let mut t = vec![(Vec::new(), Vec::new()); cases.len()];
    for _ in 0..rounds {
        for ((_, a, b), t) in cases.iter_mut().zip(&mut t) {
            t.0.push(a());
            t.1.push(b());
        }
    }
    t.iter().map(|(a, b)| (median(a), median(b))).collect()
}

/// A TCP port on 127.0.0.1 that was free a moment ago.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free loopback port")
}

/// CPU time (user + system) of process `pid`, in clock ticks (`/proc/PID/stat`).
pub fn cpu_ticks(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Fields after the command name (which may hold spaces) start after ") ".
    let rest = stat.rsplit_once(") ")?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    Some(f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?)
}

/// CPU seconds run so far by the threads process `pid` has now (the sum of
/// their `/proc/PID/task/*/schedstat`): nanosecond resolution where
/// [`cpu_ticks`] counts 10-ms ticks, for figures of a few % of a core.
pub fn process_cpu(pid: u32) -> Option<f64> {
    let mut ns = 0u64;
    for task in std::fs::read_dir(format!("/proc/{pid}/task"))
        .ok()?
        .flatten()
    {
        let s = std::fs::read_to_string(task.path().join("schedstat")).unwrap_or_default();
        ns += s
            .split(' ')
            .next()
            .and_then(|n| n.parse().ok())
            .unwrap_or(0);
    }
    Some(ns as f64 / 1e9)
}

/// CPU seconds run so far by the calling thread (`/proc/thread-self/schedstat`).
pub fn thread_cpu() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split(' ').next()?.parse::<f64>().ok())
        .unwrap_or(0.0)
        / 1e9
}

/// % of one core that the process `cmd` starts uses (user + system, from /proc)
/// over `window` after `warmup`; its window (if any) under software GL, its
/// standard streams closed. The process is killed after.
pub fn cpu_percent(
    mut cmd: std::process::Command,
    warmup: std::time::Duration,
    window: std::time::Duration,
) -> f64 {
    use std::process::Stdio;
    let mut child = cmd
        .env("LIBGL_ALWAYS_SOFTWARE", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start the process");
    std::thread::sleep(warmup);
    // SAFETY: sysconf has no preconditions.
    let tick = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    let (t0, c0) = (
        std::time::Instant::now(),
        cpu_ticks(child.id()).expect("running"),
    );
    std::thread::sleep(window);
    let (t1, c1) = (
        std::time::Instant::now(),
        cpu_ticks(child.id()).expect("running"),
    );
    let _ = child.kill();
    let _ = child.wait();
    100.0 * (c1 - c0) as f64 / tick / (t1 - t0).as_secs_f64()
}

/// CPU seconds run so far by this process's threads whose name starts with
/// `prefix` (`/proc/self/task/*/schedstat`, nanosecond resolution).
pub fn threads_cpu(prefix: &str) -> f64 {
    let Ok(dir) = std::fs::read_dir("/proc/self/task") else {
        return 0.0;
    };
    let mut total = 0.0;
    for t in dir.flatten() {
        let Ok(comm) = std::fs::read_to_string(t.path().join("comm")) else {
            continue;
        };
        if !comm.starts_with(prefix) {
            continue;
        }
        let Ok(st) = std::fs::read_to_string(t.path().join("schedstat")) else {
            continue;
        };
        total += st
            .split(' ')
            .next()
            .and_then(|n| n.parse::<f64>().ok())
            .unwrap_or(0.0)
            / 1e9;
    }
    total
}

/// CPU seconds run so far by each of this process's threads, summed by thread
/// name (`/proc/self/task/*/comm` and `schedstat`): a breakdown of where a
/// benchmark's time goes, kernel time included.
pub fn cpu_by_thread() -> std::collections::BTreeMap<String, f64> {
    cpu_by_thread_of("self")
}

/// [`cpu_by_thread`] of process `pid` (a number, or `self`).
pub fn cpu_by_thread_of(pid: &str) -> std::collections::BTreeMap<String, f64> {
    let mut by = std::collections::BTreeMap::new();
    let Ok(dir) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return by;
    };
    for t in dir.flatten() {
        let (Ok(comm), Ok(st)) = (
            std::fs::read_to_string(t.path().join("comm")),
            std::fs::read_to_string(t.path().join("schedstat")),
        ) else {
            continue;
        };
        let ns = st.split(' ').next().and_then(|n| n.parse::<f64>().ok());
        *by.entry(comm.trim().to_string()).or_insert(0.0) += ns.unwrap_or(0.0) / 1e9;
    }
    by
}

/// This process's scheduling so far, all threads summed (`/proc/self/task/*/schedstat`):
/// CPU seconds run, seconds spent runnable but waiting for a CPU, and time slices.
/// Deltas over a part of a bench say what it cost beyond its useful work: the wait
/// is contention for the cores, the slices are context switches.
#[derive(Clone, Copy, Default)]
pub struct Sched {
    pub run: f64,
    pub wait: f64,
    pub slices: f64,
}

impl Sched {
    pub fn now() -> Sched {
        Sched::by_thread()
            .into_values()
            .fold(Sched::default(), |a, t| Sched {
                run: a.run + t.run,
                wait: a.wait + t.wait,
                slices: a.slices + t.slices,
            })
    }

    /// The same, summed by thread name (`/proc/self/task/*/comm`).
    pub fn by_thread() -> std::collections::BTreeMap<String, Sched> {
        Sched::by_thread_in("self")
    }

    /// [`by_thread`](Self::by_thread) of process `pid` (a number, or `self`).
    pub fn by_thread_in(pid: &str) -> std::collections::BTreeMap<String, Sched> {
        let mut by = std::collections::BTreeMap::<String, Sched>::new();
        let Ok(dir) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
            return by;
        };
        for t in dir.flatten() {
            let (Ok(comm), Ok(st)) = (
                std::fs::read_to_string(t.path().join("comm")),
                std::fs::read_to_string(t.path().join("schedstat")),
            ) else {
                continue;
            };
            let f: Vec<f64> = st
                .split_whitespace()
                .filter_map(|n| n.parse().ok())
                .collect();
            if let [run, wait, slices] = f[..] {
                let s = by.entry(comm.trim().to_string()).or_default();
                s.run += run / 1e9;
                s.wait += wait / 1e9;
                s.slices += slices;
            }
        }
        by
    }

    /// With `BENCH_THREADS` set, prints what `who`'s threads did per `n` (e.g.
    /// frames) from `before` to `after` (both from [`by_thread_in`](Self::by_thread_in)):
    /// the total, then each thread above 1 µs, as µs run / µs waiting for a core /
    /// time slices.
    pub fn print_threads(
        who: &str,
        before: &std::collections::BTreeMap<String, Sched>,
        after: &std::collections::BTreeMap<String, Sched>,
        n: f64,
    ) {
        if std::env::var_os("BENCH_THREADS").is_none() {
            return;
        }
        let mut total = [0.0; 3];
        let mut each = String::new();
        for (name, a) in after {
            let (run, wait, slices) = a.per(before.get(name).unwrap_or(&Sched::default()), n);
            total = [total[0] + run, total[1] + wait, total[2] + slices];
            if run >= 1.0 {
                each += &format!(" {name} {run:.0}/{wait:.0}/{slices:.2}");
            }
        }
        println!(
            "    {who}: all {:.0} µs run/{:.0} waiting/{:.2} slices;{each}",
            total[0], total[1], total[2]
        );
    }

    /// What happened since `before`, per `n` (e.g. frames): (µs run, µs waiting, slices).
    pub fn per(&self, before: &Sched, n: f64) -> (f64, f64, f64) {
        let n = n.max(1.0);
        (
            (self.run - before.run) * 1e6 / n,
            (self.wait - before.wait) * 1e6 / n,
            (self.slices - before.slices) / n,
        )
    }
}
