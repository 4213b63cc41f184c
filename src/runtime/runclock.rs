//! The run's clock when it is not the wall clock: a simulator running faster or
//! slower than real time (or lock-stepped), or a replay. The component that owns
//! that time exports a [`RunClock`] in the name space as `run.clock`
//! ([`RunClock::export`]); a service that tells the outside world the time (the
//! `ros2` service's `/clock`) imports it. Without one, the run's time is wall time.

use std::{
    sync::{
        Arc,
        atomic::{AtomicU64, Ordering},
    },
    time::{Duration, SystemTime, UNIX_EPOCH},
};

use crate::namespace::{Namespace, NamespaceError};

/// The name-space key of the run's clock: (component, name).
pub const KEY: (&str, &str) = ("run", "clock");

/// The run's time, as a date: the wall time when its owner started plus the
/// time its owner has run since (simulated seconds), or a replay's recorded time.
#[derive(Debug)]
pub struct RunClock {
    base: SystemTime,
    /// Nanoseconds since the Unix epoch; 0 until the owner first sets it.
    ns: AtomicU64,
    /// The time advances once per motors command (a lock-stepped simulator): a
    /// controller then commands once per pass of its loop, and never on the wall
    /// clock's account, or the run is no longer the same every time.
    pub per_command: bool,
}

impl RunClock {
    /// A clock whose time 0 is now, exported as `run.clock` (one per run);
    /// `per_command`: see [`RunClock::per_command`].
    pub fn export(names: &Namespace, per_command: bool) -> Result<Arc<RunClock>, NamespaceError> {
        names.export(
            KEY.0,
            KEY.1,
            RunClock {
                base: SystemTime::now(),
                ns: AtomicU64::new(0),
                per_command,
            },
        )
    }

    /// The clock of this run, if a component exports one.
    pub fn import(names: &Namespace) -> Option<Arc<RunClock>> {
        names.import::<RunClock>(KEY.0, KEY.1).ok()
    }

    /// Sets the time to `secs` (simulated seconds) after the clock's start.
    pub fn set_elapsed(&self, secs: f64) {
        self.set(self.base + Duration::from_secs_f64(secs.max(0.0)));
    }

    /// Sets the time (a replay's recorded time).
    pub fn set(&self, t: SystemTime) {
        let ns = t.duration_since(UNIX_EPOCH).unwrap_or_default().as_nanos() as u64;
        self.ns.store(ns.max(1), Ordering::Release);
    }

    /// The time now, once the owner has set it.
    pub fn now(&self) -> Option<SystemTime> {
        match self.ns.load(Ordering::Acquire) {
            0 => None,
            ns => Some(UNIX_EPOCH + Duration::from_nanos(ns)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_clock_is_unset_until_its_owner_sets_it_and_then_advances() {
        let names = Namespace::default();
        let c = RunClock::export(&names, false).unwrap();
        assert!(RunClock::import(&names).unwrap().now().is_none());
        c.set_elapsed(2.5);
        let t = RunClock::import(&names).unwrap().now().unwrap();
        assert_eq!(
            t.duration_since(c.base).unwrap(),
            Duration::from_millis(2500)
        );
        assert!(RunClock::export(&names, true).is_err(), "one clock per run");
    }
}
