//! Periodic pacing against absolute deadlines.
//!
//! The seed's loop slept `cycle - elapsed` after each iteration, so every wake-up
//! error accumulated and schemas ran 1-7 % slow. A [`Pacer`] instead sleeps until
//! `start + n * cycle` with `clock_nanosleep(TIMER_ABSTIME)`, so errors never add
//! up; with the thread's timer slack set to 1 ns the wake-up lands within a few
//! microseconds of the deadline on an idle core.

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

/// Longest single sleep, so a stop or terminate is noticed promptly even with long cycles.
const SLICE_NS: u64 = 50_000_000;

/// How many cycles behind a loop may fall and still catch up.
pub const CATCH_UP_CYCLES: u64 = 10;

/// Keeps a periodic loop on absolute deadlines.
#[derive(Debug)]
pub struct Pacer {
    cycle_ns: u64,
    next_ns: u64,
    overruns: u64,
}

impl Pacer {
    /// A pacer whose first deadline is now.
    pub fn new(cycle_ns: u64) -> Self {
        Pacer {
            cycle_ns: cycle_ns.max(1),
            next_ns: now_ns(),
            overruns: 0,
        }
    }

    /// Restarts the schedule from now (after a stop/run).
    pub fn restart(&mut self, cycle_ns: u64) {
        self.cycle_ns = cycle_ns.max(1);
        self.next_ns = now_ns();
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
        self.next_ns += self.cycle_ns;
        let now = now_ns();
        if now > self.next_ns {
            self.overruns += 1;
            if now > self.next_ns + CATCH_UP_CYCLES * self.cycle_ns {
                let missed = (now - self.next_ns) / self.cycle_ns + 1;
                self.next_ns += missed * self.cycle_ns;
            }
        }
        loop {
            let now = now_ns();
            if now >= self.next_ns {
                return true;
            }
            if interrupted() {
                return false;
            }
            sleep_until_ns(self.next_ns.min(now + SLICE_NS));
        }
    }
}
