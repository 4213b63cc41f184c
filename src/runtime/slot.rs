//! A loaded schema: its slot (state, father, brothers, children, statistics,
//! panel), its status for `ps` and the GUI, and the body of its thread.

use std::{
    panic::{AssertUnwindSafe, catch_unwind},
    sync::{
        Arc,
        atomic::{AtomicBool, AtomicU64, Ordering},
    },
    thread::JoinHandle,
    time::Duration,
};

use parking_lot::{Condvar, Mutex};

use super::{
    BrotherGroup, Context, Father, Runtime, Schema, State,
    cronos::{Timing, TimingStats},
    pacer::{self, Pacer, now_ns},
};

pub(super) struct Control {
    pub(super) state: State,
    pub(super) father: Father,
    pub(super) group: Option<(Arc<BrotherGroup>, usize)>,
    /// Schemas and interfaces this schema ran (stopped with it).
    pub(super) children: Vec<String>,
    /// Pending requests for the schema thread.
    pub(super) pending_on_run: bool,
    pub(super) pending_on_stop: bool,
    pub(super) reinit: Option<Box<dyn Schema>>,
    pub(super) terminate: bool,
    pub(super) last_error: Option<String>,
}

/// A loaded schema.
pub struct SchemaSlot {
    pub name: String,
    pub id: usize,
    pub summary: &'static str,
    pub(super) ctl: Mutex<Control>,
    pub(super) cond: Condvar,
    /// Bumped by every run/stop/terminate so a sleeping thread notices at once.
    pub(super) generation: AtomicU64,
    pub(super) cycle_ns: AtomicU64,
    pub(super) stats: Mutex<TimingStats>,
    pub(super) shown: AtomicBool,
    pub(super) thread: Mutex<Option<JoinHandle<()>>>,
    /// The schema's panel; only the GUI thread locks it.
    #[cfg(feature = "gui")]
    pub panel: Mutex<Option<Box<dyn super::Panel>>>,
}

/// What `ps`, `ls` and the GUI show of a schema.
#[derive(Clone, Debug)]
pub struct SchemaStatus {
    pub name: String,
    pub id: usize,
    pub state: State,
    pub shown: bool,
    pub father: Father,
    pub children: Vec<String>,
    pub timing: Timing,
    pub cycle: Duration,
    pub last_error: Option<String>,
}

impl SchemaStatus {
    /// 4.3's `ps` line: `NAME: N ips, winner (child child)`, plus jitter for running schemas.
    pub fn ps_line(&self) -> String {
        let state = match self.state {
            State::Winner | State::Forced => {
                format!("{} ({})", self.state, self.children.join(" "))
            }
            s => s.to_string(),
        };
        let mut line = format!("{}: {:.0} ips, {state}", self.name, self.timing.ips);
        if self.state.iterates() && self.timing.iterations > 1 {
            line.push_str(&format!(
                ", jitter p50 {:.3} ms p99 {:.3} ms",
                self.timing.jitter_p50 * 1e3,
                self.timing.jitter_p99 * 1e3
            ));
        }
        if let Some(e) = &self.last_error {
            line.push_str(&format!(", last error: {e}"));
        }
        line
    }
}

impl SchemaSlot {
    pub(super) fn status(&self) -> SchemaStatus {
        let c = self.ctl.lock();
        // Between two of its cycles a brother's own state may lag the group's latest
        // decision; report the group's winner so at most one brother shows `winner`.
        let state = match (&c.group, c.state) {
            (Some((g, i)), State::Winner | State::Ready) => {
                if g.winner_index() == Some(*i) {
                    State::Winner
                } else {
                    State::Ready
                }
            }
            (_, s) => s,
        };
        SchemaStatus {
            name: self.name.clone(),
            id: self.id,
            state,
            shown: self.shown.load(Ordering::Acquire),
            father: c.father.clone(),
            children: c.children.clone(),
            timing: self
                .stats
                .lock()
                .timing(state.iterates() || c.state.iterates()),
            cycle: Duration::from_nanos(self.cycle_ns.load(Ordering::Relaxed)),
            last_error: c.last_error.clone(),
        }
    }

    /// Whether the panel is shown.
    pub fn shown(&self) -> bool {
        self.shown.load(Ordering::Acquire)
    }
}

/// The body of a schema's thread: sleep while slept; while running, check
/// preconditions and arbitration each cycle and iterate if winner or forced.
pub(super) fn schema_thread(rt: Arc<Runtime>, slot: Arc<SchemaSlot>, mut schema: Box<dyn Schema>) {
    pacer::precise_timers_for_this_thread();
    let ctx = Context {
        runtime: rt.clone(),
        slot: slot.clone(),
    };
    let mut pacer = Pacer::new(slot.cycle_ns.load(Ordering::Relaxed));
    let mut seen_generation = u64::MAX;
    loop {
        // Take pending requests; sleep while slept.
        let (on_run, on_stop, reinit) = {
            let mut c = slot.ctl.lock();
            loop {
                if c.terminate {
                    drop(c);
                    if slot.ctl.lock().pending_on_stop {
                        schema.on_stop(&ctx);
                    }
                    schema.terminate();
                    rt.names.remove_component(&slot.name);
                    return;
                }
                if c.state != State::Slept || c.pending_on_stop || c.reinit.is_some() {
                    break;
                }
                slot.cond.wait(&mut c);
            }
            let r = (c.pending_on_run, c.pending_on_stop, c.reinit.take());
            c.pending_on_run = false;
            c.pending_on_stop = false;
            r
        };
        if let Some(new) = reinit {
            schema.terminate();
            schema = new;
        }
        if on_stop {
            schema.on_stop(&ctx);
        }
        let generation = slot.generation.load(Ordering::Acquire);
        if on_run
            && let Err(e) = catch_unwind(AssertUnwindSafe(|| schema.on_run(&ctx)))
                .map_err(|p| format!("panicked: {}", crate::output::panic_text(&*p)))
                .and_then(|r| r.map_err(|e| format!("{e:#}")))
        {
            let _ = rt.stop_with(&slot.name, Some(e));
            continue;
        }
        if generation != seen_generation {
            seen_generation = generation;
            pacer.restart(slot.cycle_ns.load(Ordering::Relaxed));
        }

        // Preconditions and arbitration.
        let pre = catch_unwind(AssertUnwindSafe(|| schema.preconditions(&ctx))).unwrap_or(false);
        let state = {
            let mut c = slot.ctl.lock();
            if c.state == State::Slept || c.terminate {
                continue;
            }
            if c.state != State::Forced {
                c.state = match (&c.group, pre) {
                    (Some((g, i)), _) => {
                        if g.decide(*i, pre) {
                            State::Winner
                        } else if pre {
                            State::Ready
                        } else {
                            State::NotReady
                        }
                    }
                    (None, true) => State::Winner,
                    (None, false) => State::NotReady,
                };
            }
            c.state
        };

        if state.iterates() {
            let start = now_ns();
            slot.stats.lock().record(start, pacer.deadline_ns());
            let result = catch_unwind(AssertUnwindSafe(|| schema.iteration(&ctx)))
                .map_err(|p| format!("panicked: {}", crate::output::panic_text(&*p)))
                .and_then(|r| r.map_err(|e| format!("{e:#}")));
            if let Err(e) = result {
                let _ = rt.stop_with(&slot.name, Some(e));
                continue;
            }
        }
        let gen_now = || slot.generation.load(Ordering::Acquire) != seen_generation;
        pacer.wait(&gen_now);
    }
}
