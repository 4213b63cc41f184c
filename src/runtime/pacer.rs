//! Periodic pacing against absolute deadlines.
//!
//! The seed's loop slept `cycle - elapsed` after each iteration, so every wake-up
//! error accumulated and schemas ran 1-7 % slow. A [`Pacer`] instead sleeps until
//! `start + n * cycle` with `clock_nanosleep(TIMER_ABSTIME)`, so errors never add
//! up; with the thread's timer slack set to 1 ns the wake-up lands within a few
//! microseconds of the deadline on an idle core. Schedules started together are
//! shifted apart (after their first iteration, which runs at once) so that they
//! do not all wake at the same instant.

use std::sync::atomic::{AtomicU64, Ordering};

/// Nanoseconds on the monotonic clock.
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into a valid timespec.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleeps until the monotonic clock reads `deadline_ns`.
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: ts is a valid timespec; a null remainder is allowed with TIMER_ABSTIME.
        let r = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if r != libc::EINTR {
            return;
        }
    }
}

/// Asks the kernel to wake this thread as close to its deadlines as it can
/// (the default timer slack is 50 µs).
pub fn precise_timers_for_this_thread() {
    // SAFETY: PR_SET_TIMERSLACK takes an integer argument; it affects only this thread.
    unsafe {
        libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0);
    }
}

/// The pacer stops sleeping a little before a deadline and spins the rest: twice
/// the machine's average wake-up lateness (learnt as it runs), at most
/// [`MAX_SPIN_NS`] (1 % of a core per schema at 10 ms). Cycles shorter than
/// [`SPIN_FROM_CYCLE_NS`] do not spin: their spinning would add up.
const MAX_SPIN_NS: u64 = 100_000;
const SPIN_FROM_CYCLE_NS: u64 = 5_000_000;

/// Longest single sleep, so a stop or terminate is noticed promptly even with long cycles.
const SLICE_NS: u64 = 50_000_000;

/// How many cycles behind a loop may fall and still catch up.
pub const CATCH_UP_CYCLES: u64 = 10;

/// Loops started together (a conf that runs ten schemas) would otherwise wake
/// together for ever and queue for the same cores. Each new schedule is shifted by
/// a different fraction of its cycle, at most this much, so they spread out.
const MAX_PHASE_NS: u64 = 10_000_000;

/// The shift of the next schedule: the golden-ratio sequence `frac(k·φ)` spreads
/// any number of loops evenly over `min(cycle, MAX_PHASE_NS)`.
fn next_phase_ns(cycle_ns: u64) -> u64 {
    static SCHEDULES: AtomicU64 = AtomicU64::new(0);
    let k = SCHEDULES.fetch_add(1, Ordering::Relaxed);
    let fraction = (k as f64 * 0.618_033_988_749_894_9).fract();
    (fraction * cycle_ns.min(MAX_PHASE_NS) as f64) as u64
}

/// Keeps a periodic loop on absolute deadlines.
#[derive(Debug)]
pub struct Pacer {
    cycle_ns: u64,
    next_ns: u64,
    overruns: u64,
    /// Added once to the second deadline (see [`MAX_PHASE_NS`]).
    phase_ns: u64,
    /// Average lateness of wake-ups from sleep, ns.
    wake_late_ns: u64,
}

impl Pacer {
    /// A pacer whose first deadline is now; later ones are shifted by the phase
    /// this schedule is given (at most one cycle, at most 10 ms).
    pub fn new(cycle_ns: u64) -> Self {
        let cycle_ns = cycle_ns.max(1);
        Pacer {
            cycle_ns,
            next_ns: now_ns(),
            overruns: 0,
            phase_ns: next_phase_ns(cycle_ns),
            wake_late_ns: 0,
        }
    }

    /// Restarts the schedule from now (after a stop/run), with a new phase.
    pub fn restart(&mut self, cycle_ns: u64) {
        self.cycle_ns = cycle_ns.max(1);
        self.next_ns = now_ns();
        self.phase_ns = next_phase_ns(self.cycle_ns);
    }

    /// The deadline of the iteration about to run.
    pub fn deadline_ns(&self) -> u64 {
        self.next_ns
    }

    /// Iterations that ended after the next deadline had passed.
    pub fn overruns(&self) -> u64 {
        self.overruns
    }

    /// Sleeps until the next deadline. A loop that fell behind by a few cycles
    /// (a slow iteration, a busy machine) catches up by starting at once, so the mean
    /// rate stays exact; one that fell more than [`CATCH_UP_CYCLES`] behind skips the
    /// missed deadlines instead of bursting, keeping its phase. `interrupted` is
    /// polled between slices of long sleeps; if it returns true the wait ends early
    /// and `false` is returned.
    pub fn wait(&mut self, interrupted: &dyn Fn() -> bool) -> bool {
        self.next_ns += self.cycle_ns + std::mem::take(&mut self.phase_ns);
        let now = now_ns();
        if now > self.next_ns {
            self.overruns += 1;
            if now > self.next_ns + CATCH_UP_CYCLES * self.cycle_ns {
                let missed = (now - self.next_ns) / self.cycle_ns + 1;
                self.next_ns += missed * self.cycle_ns;
            }
        }
        // Sleep until just before the deadline, then spin the last few microseconds:
        // waking from a long sleep costs the kernel tens of microseconds more than a
        // short one, and that delay would be the jitter.
        let spin = if self.cycle_ns >= SPIN_FROM_CYCLE_NS {
            (2 * self.wake_late_ns + 5_000).min(MAX_SPIN_NS)
        } else {
            0
        };
        loop {
            let now = now_ns();
            if now >= self.next_ns {
                return true;
            }
            if interrupted() {
                return false;
            }
            if now + spin >= self.next_ns {
                while now_ns() < self.next_ns {
                    std::hint::spin_loop();
                }
                return true;
            }
            let target = (self.next_ns - spin).min(now + SLICE_NS);
            sleep_until_ns(target);
            // Learn how late this machine wakes (moving average, 1/8 weight).
            let late = now_ns().saturating_sub(target).min(MAX_SPIN_NS);
            self.wake_late_ns = (7 * self.wake_late_ns + late) / 8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedules_started_together_get_distinct_phases_within_a_cycle() {
        let cycle = 1_000_000;
        let mut phases: Vec<u64> = (0..100).map(|_| Pacer::new(cycle).phase_ns).collect();
        assert!(phases.iter().all(|&p| p < cycle));
        phases.sort_unstable();
        phases.dedup();
        assert_eq!(phases.len(), 100, "phases collide");
        // Long cycles are shifted by at most MAX_PHASE_NS.
        assert!((0..20).all(|_| Pacer::new(1_000_000_000).phase_ns < MAX_PHASE_NS));
    }

    #[test]
    fn the_phase_delays_only_the_second_deadline() {
        // Long enough that a loaded machine never makes the pacer skip deadlines.
        let cycle = 20_000_000;
        let mut p = Pacer::new(cycle);
        let (first, phase) = (p.deadline_ns(), p.phase_ns);
        assert!(p.wait(&|| false));
        assert_eq!(p.deadline_ns(), first + cycle + phase);
        assert!(p.wait(&|| false));
        assert_eq!(p.deadline_ns(), first + 2 * cycle + phase);
    }
}
