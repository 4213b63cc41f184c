//! Where values from outside come from (a Zenoh key, a device, a server), for
//! one log line per change of state: the first refused value after good ones is
//! logged, then nothing until a good value comes again (logged too, with how many
//! were refused). See [`Interface::accept`](super::Interface::accept) and
//! [`Interface::receive`](super::Interface::receive).

use std::fmt::Display;

use parking_lot::Mutex;

/// One source of values and whether it is being refused.
#[derive(Debug)]
pub struct Source {
    name: String,
    /// Values refused since the last good one (0: the source is good).
    refused: Mutex<u64>,
}

impl Source {
    /// A source named as its log lines begin (`zenoh: `jderobot/pioneer/motors``,
    /// `player: localhost:6665 camera:0`).
    pub fn new(name: impl Into<String>) -> Source {
        Source {
            name: name.into(),
            refused: Mutex::new(0),
        }
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// Whether the latest value from this source was refused.
    pub fn refusing(&self) -> bool {
        *self.refused.lock() > 0
    }

    /// A value from this source was refused (`why` says what and where): logged
    /// if it is the first since a good one. Returns whether it was logged.
    pub fn refused(&self, why: impl Display) -> bool {
        let mut n = self.refused.lock();
        *n += 1;
        if *n == 1 {
            tracing::warn!(
                "{}: dropped a value: {why}; further ones are dropped without a line until a good one comes",
                self.name
            );
            true
        } else {
            false
        }
    }

    /// A value from this source was accepted: logged if values had been refused.
    pub fn accepted(&self) {
        let mut n = self.refused.lock();
        if *n > 0 {
            tracing::info!("{}: good values again ({} dropped before)", self.name, *n);
            *n = 0;
        }
    }

    /// Notes the outcome of a write from this source; the value when accepted.
    pub fn note<T, E: Display>(&self, r: Result<T, E>) -> Option<T> {
        match r {
            Ok(v) => {
                self.accepted();
                Some(v)
            }
            Err(e) => {
                self.refused(e);
                None
            }
        }
    }
}
