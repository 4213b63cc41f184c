//! Frame pacing against absolute deadlines: frame k is due at t0 + k/rate, so the
//! average rate is exact however long each frame takes to decode (no drift). After
//! a stall of more than half a second the schedule restarts instead of bursting.

use std::time::{Duration, Instant};

/// Paces frames at a rate, or not at all.
#[derive(Clone, Debug)]
pub struct Pacer {
    period: Option<Duration>,
    next: Option<Instant>,
}

impl Pacer {
    /// A pacer at `fps` frames per second; `None` (or a rate that is not positive
    /// and finite) does not pace.
    pub fn new(fps: Option<f64>) -> Self {
        let period = fps
            .filter(|f| f.is_finite() && *f > 0.0 && *f < 100_000.0)
            .map(|f| Duration::from_secs_f64(1.0 / f));
        Pacer { period, next: None }
    }

    pub fn period(&self) -> Option<Duration> {
        self.period
    }

    /// Starts a new schedule at the next frame (after a pause).
    pub fn reset(&mut self) {
        self.next = None;
    }

    /// Sleeps until the next frame is due (in slices of at most 50 ms, returning
    /// early when `stop()` says so).
    pub fn wait(&mut self, stop: impl Fn() -> bool) {
        let Some(period) = self.period else { return };
        let now = Instant::now();
        let due = *self.next.get_or_insert(now);
        if now > due + Duration::from_millis(500) {
            self.next = Some(now + period);
            return;
        }
        loop {
            let now = Instant::now();
            if now >= due || stop() {
                break;
            }
            std::thread::sleep((due - now).min(Duration::from_millis(50)));
        }
        self.next = Some(due + period);
    }
}
