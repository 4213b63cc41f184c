//! The schema runtime: loads components, runs each schema on its own thread at its
//! cycle, and keeps the seed's states, hierarchy and arbitration.
//!
//! **States** (4.3's names; 4.3 used only slept/notready/ready/winner):
//!
//! | state | meaning |
//! |---|---|
//! | `slept` | not running |
//! | `active` | just run; preconditions not yet checked |
//! | `notready` | running, but its preconditions do not hold |
//! | `ready` | preconditions hold, but a brother won the arbitration |
//! | `winner` | iterating |
//! | `forced` | iterating because it was forced, whatever its preconditions and brothers |
//!
//! Each cycle a running schema checks [`Schema::preconditions`]; if they hold and it
//! has brothers, the group's arbitration function picks one winner among the ready
//! brothers (the first one by default). Only winners and forced schemas iterate.
//!
//! **Hierarchy.** A schema activates children from [`Schema::on_run`] with
//! [`Context::run_children`] (schemas and interfaces alike, as 4.3 ran its "virtual
//! schemas"); stopping a parent stops every child it ran.
//!
//! **Timing.** Iterations are paced against absolute deadlines ([`pacer`]);
//! [`cronos`] measures iterations per second and period jitter.
//!
//! **Faults.** A schema whose iteration panics or returns an error is stopped and
//! reported (`NAME: stopped: ...`); the others run on.

//!
//! The runtime knows nothing of the registry, the conf grammar's directives or the
//! GUI host: [`crate::loader`] turns a conf into a running `Runtime` through
//! [`Runtime::add_schema`] and [`Runtime::add_driver`].

mod arbitration;
mod context;
pub mod cronos;
mod driver;
mod error;
pub mod pacer;
#[cfg(feature = "gui")]
mod panel;
pub mod runclock;
mod schema;
mod slot;

use std::{
    path::{Path, PathBuf},
    sync::{
        Arc, Weak,
        atomic::{AtomicBool, AtomicU64, Ordering},
    },
};

use parking_lot::{Condvar, Mutex, RwLock};

pub use crate::supervisor::{Backoff, Device, Supervision, Supervisor, Worker};
pub use arbitration::{Arbitration, BrotherGroup, Father};
pub use context::Context;
pub use driver::Driver;
pub use error::RuntimeError;
#[cfg(feature = "gui")]
pub use panel::Panel;
pub use runclock::RunClock;
pub use schema::{Schema, State};
pub use slot::{SchemaSlot, SchemaStatus};

use crate::{
    conf::{ConfError, ConfLine, Kind},
    interfaces::{Image, InterfaceValue, Interfaces},
    namespace::Namespace,
    output,
};
use cronos::TimingStats;
use slot::{Control, schema_thread};

struct LoadedDriver {
    name: String,
    kind: Kind,
    driver: Box<dyn Driver>,
}

/// The running suite: interfaces, name space, schemas and drivers.
pub struct Runtime {
    me: Weak<Runtime>,
    conf_file: PathBuf,
    pub interfaces: Interfaces,
    pub names: Namespace,
    schemas: RwLock<Vec<Arc<SchemaSlot>>>,
    drivers: Mutex<Vec<LoadedDriver>>,
    shut_down: AtomicBool,
}

impl Runtime {
    /// An empty runtime; `conf_file` is what components get when loaded with no file.
    pub fn new(conf_file: &Path) -> Arc<Runtime> {
        Arc::new_cyclic(|me| Runtime {
            me: me.clone(),
            conf_file: conf_file.to_path_buf(),
            interfaces: Interfaces::default(),
            names: Namespace::default(),
            schemas: RwLock::new(Vec::new()),
            drivers: Mutex::new(Vec::new()),
            shut_down: AtomicBool::new(false),
        })
    }

    /// The main conf file.
    pub fn conf_file(&self) -> &Path {
        &self.conf_file
    }

    /// The shared handle of this runtime (for a component whose callbacks outlive
    /// its `create`, such as the foxglove service's WebSocket services).
    pub fn arc(&self) -> Arc<Runtime> {
        self.me.upgrade().expect("runtime alive")
    }

    /// Adds a schema object under `name` and starts its (sleeping) thread.
    #[allow(unused_mut)]
    pub fn add_schema(
        &self,
        name: &str,
        summary: &'static str,
        mut schema: Box<dyn Schema>,
    ) -> Result<(), RuntimeError> {
        if self.is_loaded(name) {
            return Err(RuntimeError::AlreadyLoaded(name.into()));
        }
        #[cfg(feature = "gui")]
        let panel = schema.panel();
        let mut all = self.schemas.write();
        let cycle = schema.cycle().as_nanos().max(1) as u64;
        let slot = Arc::new(SchemaSlot {
            name: name.to_string(),
            id: all.len(),
            summary,
            ctl: Mutex::new(Control {
                state: State::Slept,
                father: Father::Human,
                group: None,
                children: Vec::new(),
                pending_on_run: false,
                pending_on_stop: false,
                reinit: None,
                terminate: false,
                last_error: None,
            }),
            cond: Condvar::new(),
            generation: AtomicU64::new(0),
            cycle_ns: AtomicU64::new(cycle),
            stats: Mutex::new(TimingStats::default()),
            shown: AtomicBool::new(false),
            thread: Mutex::new(None),
            #[cfg(feature = "gui")]
            panel: Mutex::new(panel),
        });
        tracing::info!("{name} schema loaded (id {})", slot.id);
        let rt = self.arc();
        let s = slot.clone();
        let handle = std::thread::Builder::new()
            .name(name.to_string())
            .spawn(move || schema_thread(rt, s, schema))
            .map_err(|e| RuntimeError::Thread {
                name: name.into(),
                message: e.to_string(),
            })?;
        *slot.thread.lock() = Some(handle);
        all.push(slot);
        Ok(())
    }

    /// Adds a loaded driver or service; it is terminated at shutdown, in reverse
    /// load order.
    pub fn add_driver(
        &self,
        name: &str,
        kind: Kind,
        driver: Box<dyn Driver>,
    ) -> Result<(), RuntimeError> {
        if self.is_loaded(name) {
            return Err(RuntimeError::AlreadyLoaded(name.into()));
        }
        let mut d = self.drivers.lock();
        tracing::info!("{name} {kind} loaded ({kind} {})", d.len());
        d.push(LoadedDriver {
            name: name.to_string(),
            kind,
            driver,
        });
        Ok(())
    }

    /// Replaces a loaded schema's object by a new one (the shell's `init [conf]`);
    /// the schema keeps its slot, state and statistics.
    pub fn replace_schema(&self, name: &str, schema: Box<dyn Schema>) -> Result<(), RuntimeError> {
        let slot = self.schema(name).ok_or_else(|| self.not_loaded(name))?;
        slot.cycle_ns
            .store(schema.cycle().as_nanos().max(1) as u64, Ordering::Relaxed);
        let mut c = slot.ctl.lock();
        c.reinit = Some(schema);
        slot.generation.fetch_add(1, Ordering::AcqRel);
        slot.cond.notify_all();
        Ok(())
    }

    /// Whether a schema, driver or service of this name is loaded.
    pub fn is_loaded(&self, name: &str) -> bool {
        self.schema(name).is_some() || self.drivers.lock().iter().any(|d| d.name == name)
    }

    /// The loaded schema `name`.
    pub fn schema(&self, name: &str) -> Option<Arc<SchemaSlot>> {
        self.schemas.read().iter().find(|s| s.name == name).cloned()
    }

    /// Names of loaded schemas, in load order.
    pub fn schema_names(&self) -> Vec<String> {
        self.schemas.read().iter().map(|s| s.name.clone()).collect()
    }

    /// Loaded drivers and services: (name, kind), in load order.
    pub fn drivers(&self) -> Vec<(String, Kind)> {
        self.drivers
            .lock()
            .iter()
            .map(|d| (d.name.clone(), d.kind))
            .collect()
    }

    /// The provided image interface (`colorA..D`, `varcolorA..D`) that argument `i` of
    /// a component's conf line names (canonical name), or an error at that line
    /// saying what is wrong: not an interface, not provided, not an image.
    pub fn image_interface(&self, line: &ConfLine, i: usize) -> Result<String, ConfError> {
        let name = line.interface(i)?;
        match self.interfaces.get_any(&name) {
            Ok(a) if a.kind() == Image::KIND => Ok(name),
            Ok(a) => Err(line.error(format!("{name} is a {} interface, not an image", a.kind()))),
            Err(e) => Err(line.error(format!("{}: {e}", line.keyword()))),
        }
    }

    /// The error for a name that is not loaded, listing what is.
    pub fn not_loaded(&self, name: &str) -> RuntimeError {
        let mut loaded = self.schema_names();
        loaded.extend(self.interfaces.names());
        RuntimeError::NotLoaded {
            name: name.into(),
            loaded: if loaded.is_empty() {
                "nothing".into()
            } else {
                loaded.join(", ")
            },
        }
    }

    /// Runs a schema (or resumes an interface) on behalf of a human.
    pub fn run(&self, name: &str) -> Result<(), RuntimeError> {
        self.run_as(name, Father::Human, None)
    }

    fn run_as(
        &self,
        name: &str,
        father: Father,
        group: Option<(Arc<BrotherGroup>, usize)>,
    ) -> Result<(), RuntimeError> {
        let Some(slot) = self.schema(name) else {
            let iface = self
                .interfaces
                .get_any(name)
                .map_err(|_| self.not_loaded(name))?;
            if father == Father::Human && iface.users() > 0 {
                return Err(RuntimeError::AlreadyRunning(name.into()));
            }
            iface.resume();
            return Ok(());
        };
        {
            let mut c = slot.ctl.lock();
            if c.state != State::Slept {
                if father == Father::Human {
                    return Err(RuntimeError::AlreadyRunning(name.into()));
                }
                // A parent takes over a running schema: it keeps running under it.
                c.father = father;
                c.group = group;
                return Ok(());
            }
            c.state = State::Active;
            c.father = father;
            c.group = group;
            c.children.clear();
            c.pending_on_run = true;
            c.pending_on_stop = false;
            c.last_error = None;
            slot.generation.fetch_add(1, Ordering::AcqRel);
            slot.stats
                .lock()
                .activate(slot.cycle_ns.load(Ordering::Relaxed));
            slot.cond.notify_all();
        }
        output::println(format!("{name}: on"));
        Ok(())
    }

    /// Forces a schema to iterate whatever its preconditions and brothers.
    pub fn force(&self, name: &str) -> Result<(), RuntimeError> {
        let slot = self.schema(name).ok_or_else(|| self.not_loaded(name))?;
        if slot.ctl.lock().state == State::Slept {
            self.run(name)?;
        }
        let mut c = slot.ctl.lock();
        c.state = State::Forced;
        Ok(())
    }

    /// Stops a schema (and every child it ran) or suspends an interface.
    pub fn stop(&self, name: &str) -> Result<(), RuntimeError> {
        self.stop_with(name, None)
    }

    fn stop_with(&self, name: &str, error: Option<String>) -> Result<(), RuntimeError> {
        let Some(slot) = self.schema(name) else {
            let iface = self
                .interfaces
                .get_any(name)
                .map_err(|_| self.not_loaded(name))?;
            if iface.users() == 0 {
                return Err(RuntimeError::NotRunning(name.into()));
            }
            iface.suspend();
            return Ok(());
        };
        let (children, group) = {
            let mut c = slot.ctl.lock();
            if c.state == State::Slept {
                return Err(RuntimeError::NotRunning(name.into()));
            }
            c.state = State::Slept;
            c.pending_on_run = false;
            c.pending_on_stop = true;
            c.last_error = error.clone();
            slot.generation.fetch_add(1, Ordering::AcqRel);
            slot.cond.notify_all();
            (std::mem::take(&mut c.children), c.group.take())
        };
        if let Some((g, i)) = group {
            g.decide(i, false);
        }
        for child in children.iter().rev() {
            // A child may already have stopped on its own (or failed).
            let _ = self.stop(child);
        }
        match error {
            Some(e) => output::println(format!("{name}: stopped: {e}")),
            None => output::println(format!("{name}: off")),
        }
        Ok(())
    }

    /// Shows a schema's panel (the GUI draws shown panels).
    pub fn show(&self, name: &str) -> Result<(), RuntimeError> {
        self.set_shown(name, true)
    }

    /// Hides a schema's panel.
    pub fn hide(&self, name: &str) -> Result<(), RuntimeError> {
        self.set_shown(name, false)
    }

    fn set_shown(&self, name: &str, shown: bool) -> Result<(), RuntimeError> {
        match self.schema(name) {
            Some(s) => {
                s.shown.store(shown, Ordering::Release);
                Ok(())
            }
            None if self.interfaces.contains(name) => Err(RuntimeError::NotASchema(
                name.into(),
                if shown { "shown" } else { "hidden" },
            )),
            None => Err(self.not_loaded(name)),
        }
    }

    /// Stops a schema and ends its thread (the shell's `terminate`); it stays listed
    /// as slept and can be brought back with `init`.
    pub fn terminate_schema(&self, name: &str) -> Result<(), RuntimeError> {
        let slot = self.schema(name).ok_or_else(|| self.not_loaded(name))?;
        let _ = self.stop(name);
        {
            let mut c = slot.ctl.lock();
            c.terminate = true;
            slot.generation.fetch_add(1, Ordering::AcqRel);
            slot.cond.notify_all();
        }
        let handle = slot.thread.lock().take();
        if let Some(h) = handle
            && h.thread().id() != std::thread::current().id()
        {
            let _ = h.join();
        }
        Ok(())
    }

    /// Every schema's status, in load order.
    pub fn status(&self) -> Vec<SchemaStatus> {
        self.schemas.read().iter().map(|s| s.status()).collect()
    }

    /// One schema's status.
    pub fn schema_status(&self, name: &str) -> Option<SchemaStatus> {
        self.schema(name).map(|s| s.status())
    }

    /// Stops everything: schemas stop, then schemas terminate in reverse load order,
    /// then drivers and services terminate in reverse load order. Safe to call twice.
    pub fn shutdown(&self) {
        if self.shut_down.swap(true, Ordering::AcqRel) {
            return;
        }
        let names = self.schema_names();
        for n in names.iter().rev() {
            let _ = self.stop(n);
        }
        for n in names.iter().rev() {
            let _ = self.terminate_schema(n);
        }
        let mut drivers = std::mem::take(&mut *self.drivers.lock());
        while let Some(mut d) = drivers.pop() {
            d.driver.terminate();
            tracing::info!("{} {} terminated", d.name, d.kind);
        }
    }
}
