//! Where values from outside come from (a Zenoh key, a device, a server), for
//! one log line per change of state: the first refused value after good ones is
//! logged, then nothing until a good value comes again (logged too, with how many
//! were refused). A source that flaps between good and bad values (a fuzzer, a
//! broken camera every other frame) is said at most once per [`QUIET`]. See
//! [`Interface::accept`](super::Interface::accept) and
//! [`Interface::receive`](super::Interface::receive).

use std::{
    fmt::Display,
    time::{Duration, Instant},
};

use parking_lot::Mutex;

/// The least time between two "dropped" lines of one source.
pub const QUIET: Duration = Duration::from_secs(10);

/// One source of values and whether it is being refused.
#[derive(Debug)]
pub struct Source {
    name: String,
    quiet: Duration,
    state: Mutex<State>,
}

#[derive(Debug, Default)]
struct State {
    /// Values refused since the last good one (0: the source is good).
    refused: u64,
    /// Refused since the last "dropped" line (said with the next one).
    unsaid: u64,
    /// Whether this run of refusals was said (so its end is said too).
    said: bool,
    /// When the last "dropped" line was logged.
    last_line: Option<Instant>,
}

impl Source {
    /// A source named as its log lines begin (`zenoh: `jderobot/pioneer/motors``,
    /// `player: 127.0.0.1:6665 camera:0`).
    pub fn new(name: impl Into<String>) -> Source {
        Source {
            name: name.into(),
            quiet: QUIET,
            state: Mutex::new(State::default()),
        }
    }

    /// The same with another least time between two "dropped" lines.
    pub fn with_quiet(mut self, quiet: Duration) -> Source {
        self.quiet = quiet;
        self
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// Whether the latest value from this source was refused.
    pub fn refusing(&self) -> bool {
        self.state.lock().refused > 0
    }

    /// A value from this source was refused (`why` says what and where): logged
    /// if it is the first since a good one (and the last line is older than the
    /// quiet time). Returns whether it was logged.
    pub fn refused(&self, why: impl Display) -> bool {
        let mut s = self.state.lock();
        s.refused += 1;
        s.unsaid += 1;
        let quiet = s.last_line.is_some_and(|t| t.elapsed() < self.quiet);
        if s.refused > 1 || quiet {
            return false;
        }
        let earlier = match s.unsaid - 1 {
            0 => String::new(),
            n => format!(" ({n} more dropped since the last line)"),
        };
        tracing::warn!(
            "{}: dropped a value: {why}{earlier}; further ones are dropped without a line until a good one comes",
            self.name
        );
        s.unsaid = 0;
        s.said = true;
        s.last_line = Some(Instant::now());
        true
    }

    /// A value from this source was accepted: logged if the refusals before it
    /// were.
    pub fn accepted(&self) {
        let mut s = self.state.lock();
        if s.refused > 0 {
            if s.said {
                tracing::info!(
                    "{}: good values again ({} dropped before)",
                    self.name,
                    s.refused
                );
            }
            s.refused = 0;
            s.said = false;
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
