//! cronos: per-schema timing statistics.
//!
//! 4.3's cronos thread computed each schema's iterations per second every 2 s.
//! Here every iteration records its start time; iterations per second are counted
//! over the last 2 s (or since the schema was run, if that is shorter), and jitter
//! — how late each iteration started after its absolute deadline — is kept for the
//! last [`WINDOW`] iterations to report its median and 99th percentile.

use std::collections::VecDeque;

use super::pacer::now_ns;

/// Periods kept for jitter percentiles.
pub const WINDOW: usize = 512;
const IPS_WINDOW_NS: u64 = 2_000_000_000;

/// Timing statistics of one schema.
#[derive(Debug, Default)]
pub struct Cronos {
    since_ns: u64,
    starts: VecDeque<u64>,
    jitter_ns: VecDeque<u64>,
    iterations: u64,
    overruns: u64,
    cycle_ns: u64,
}

/// A summary for `ps` and the GUI.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Timing {
    /// Iterations per second over the last 2 s.
    pub ips: f64,
    /// Median lateness of iteration starts after their deadlines, seconds.
    pub jitter_p50: f64,
    /// 99th percentile of that lateness, seconds.
    pub jitter_p99: f64,
    /// Iterations since loaded.
    pub iterations: u64,
    /// Iterations that started more than a cycle late.
    pub overruns: u64,
}

impl Cronos {
    /// Starts a new activation (the schema was run).
    pub fn activate(&mut self, cycle_ns: u64) {
        self.since_ns = now_ns();
        self.starts.clear();
        self.jitter_ns.clear();
        self.cycle_ns = cycle_ns;
    }

    /// Records an iteration that started at `start_ns` for the deadline `deadline_ns`.
    pub fn record(&mut self, start_ns: u64, deadline_ns: u64) {
        if self.jitter_ns.len() == WINDOW {
            self.jitter_ns.pop_front();
        }
        self.jitter_ns.push_back(start_ns.abs_diff(deadline_ns));
        if start_ns > deadline_ns + self.cycle_ns {
            self.overruns += 1;
        }
        self.starts.push_back(start_ns);
        while self
            .starts
            .front()
            .is_some_and(|&s| start_ns.saturating_sub(s) > IPS_WINDOW_NS)
        {
            self.starts.pop_front();
        }
        self.iterations += 1;
    }

    /// The summary now; `running` is false for a schema that is not iterating.
    pub fn timing(&self, running: bool) -> Timing {
        let now = now_ns();
        let ips = if running && self.since_ns > 0 {
            let window = (now - self.since_ns).min(IPS_WINDOW_NS);
            let n = self
                .starts
                .iter()
                .filter(|&&s| now.saturating_sub(s) <= window)
                .count();
            if window < 1_000_000 {
                0.0
            } else {
                n as f64 * 1e9 / window as f64
            }
        } else {
            0.0
        };
        let mut j: Vec<u64> = self.jitter_ns.iter().copied().collect();
        j.sort_unstable();
        let pct = |p: f64| -> f64 {
            if j.is_empty() {
                0.0
            } else {
                j[((j.len() - 1) as f64 * p).round() as usize] as f64 / 1e9
            }
        };
        Timing {
            ips,
            jitter_p50: pct(0.5),
            jitter_p99: pct(0.99),
            iterations: self.iterations,
            overruns: self.overruns,
        }
    }
}
