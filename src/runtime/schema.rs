//! The schema trait (a periodic unit of behaviour) and its states.

use std::time::Duration;

use super::Context;

/// A schema's state (4.3's enum, same names and order).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum State {
    Slept,
    Active,
    NotReady,
    Ready,
    Forced,
    Winner,
}

impl State {
    pub fn as_str(self) -> &'static str {
        match self {
            State::Slept => "slept",
            State::Active => "active",
            State::NotReady => "notready",
            State::Ready => "ready",
            State::Forced => "forced",
            State::Winner => "winner",
        }
    }
    /// Whether the schema iterates in this state.
    pub fn iterates(self) -> bool {
        matches!(self, State::Winner | State::Forced)
    }
}

impl std::fmt::Display for State {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A periodic unit of behaviour.
///
/// The factory registered with [`register_schema!`](crate::register_schema) is the
/// seed's `init`: it reads the schema's conf lines and looks up the interfaces it
/// needs. All other methods are called on the schema's own thread.
pub trait Schema: Send {
    /// Period between iteration starts (the seed's `cycle`, 100 ms by default).
    fn cycle(&self) -> Duration {
        Duration::from_millis(100)
    }
    /// Called when the schema is run: activate children here.
    fn on_run(&mut self, _ctx: &Context) -> anyhow::Result<()> {
        Ok(())
    }
    /// Whether the schema may iterate now (checked every cycle while running).
    fn preconditions(&mut self, _ctx: &Context) -> bool {
        true
    }
    /// One iteration.
    fn iteration(&mut self, ctx: &Context) -> anyhow::Result<()>;
    /// Called when the schema is stopped (its children are stopped for it).
    fn on_stop(&mut self, _ctx: &Context) {}
    /// Called once before the schema is unloaded.
    fn terminate(&mut self) {}
    /// The schema's GUI panel, taken once when the schema is loaded.
    #[cfg(feature = "gui")]
    fn panel(&mut self) -> Option<Box<dyn super::Panel>> {
        None
    }
}
