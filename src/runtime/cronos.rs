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

/// Timing statistics of one schema (what 4.3's cronos thread kept): iteration starts
/// for ips, lateness after each deadline for jitter.
#[derive(Debug, Default)]
pub struct TimingStats {
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

impl TimingStats {
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
        self.timing_at(now_ns(), running)
    }

    fn timing_at(&self, now: u64, running: bool) -> Timing {
        let ips = if running && self.since_ns > 0 {
            let window = now.saturating_sub(self.since_ns).min(IPS_WINDOW_NS);
            let n = self
                .starts
                .iter()
                .filter(|&&s| now.saturating_sub(s) <= window)
                .count();
            // Each iteration stands for a cycle: just after a run the window holds the
            // first iteration and a fraction of a cycle, and n / window would read
            // high (2 iterations 120 ms into a 100 ms schema: 17 ips, not 10).
            let span = window.max(n as u64 * self.cycle_ns);
            if window < 1_000_000 {
                0.0
            } else {
                n as f64 * 1e9 / span as f64
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

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn cronos_run_at(t0: u64, cycle: u64) -> TimingStats {
        let mut c = TimingStats::default();
        c.activate(cycle);
        c.since_ns = t0;
        c
    }

    #[test]
    fn ips_is_right_from_the_first_cycles_on() {
        let t0 = 1_000 * MS;
        let mut c = cronos_run_at(t0, 100 * MS);
        c.record(t0, t0);
        assert_eq!(c.timing_at(t0 + 50 * MS, true).ips, 10.0);
        c.record(t0 + 100 * MS, t0 + 100 * MS);
        assert_eq!(c.timing_at(t0 + 120 * MS, true).ips, 10.0);
        for k in 2..=40 {
            c.record(t0 + k * 100 * MS, t0 + k * 100 * MS);
        }
        let ips = c.timing_at(t0 + 4_050 * MS, true).ips;
        assert!((ips - 10.0).abs() < 0.01, "{ips}");
        // A schema stuck in one long iteration: the rate falls.
        let stuck = c.timing_at(t0 + 5_500 * MS, true).ips;
        assert!(stuck <= 3.0, "{stuck}");
        assert_eq!(c.timing_at(t0 + 4_050 * MS, false).ips, 0.0);
    }

    #[test]
    fn jitter_percentiles_and_overruns() {
        let t0 = 1_000 * MS;
        let mut c = cronos_run_at(t0, 10 * MS);
        for k in 0..100u64 {
            let late = if k == 99 { 25 * MS } else { k * 1_000 };
            c.record(t0 + k * 10 * MS + late, t0 + k * 10 * MS);
        }
        let t = c.timing_at(t0 + 1_000 * MS, true);
        assert_eq!(t.iterations, 100);
        assert_eq!(
            t.overruns, 1,
            "one iteration started more than a cycle late"
        );
        assert!((t.jitter_p50 - 50e-6).abs() < 1.5e-6, "{}", t.jitter_p50);
        assert!(t.jitter_p99 >= 98e-6, "{}", t.jitter_p99);
    }
}
