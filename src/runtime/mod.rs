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

pub mod cronos;
pub mod pacer;

use std::{
    panic::{AssertUnwindSafe, catch_unwind},
    path::{Path, PathBuf},
    sync::{
        Arc, Weak,
        atomic::{AtomicBool, AtomicU64, Ordering},
    },
    thread::JoinHandle,
    time::Duration,
};

use parking_lot::{Condvar, Mutex, RwLock};

use crate::{
    conf::{Action, ComponentConf, Conf, ConfError, Location},
    interfaces::{self, Interfaces},
    namespace::Namespace,
    output,
    registry::{self, Factory, Kind},
};
use cronos::{Cronos, Timing};
use pacer::{Pacer, now_ns};

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
    fn panel(&mut self) -> Option<Box<dyn crate::gui::Panel>> {
        None
    }
}

/// A driver or service: the factory provides its interfaces and starts its work;
/// [`Driver::terminate`] stops it (e.g. zeroes the motors, closes the device).
pub trait Driver: Send {
    fn terminate(&mut self) {}
}

/// Picks the winner among ready brothers: gets their names in brother order and
/// returns the index of the winner.
pub type Arbitration = Arc<dyn Fn(&[&str]) -> usize + Send + Sync>;

/// Brothers: schemas run together by one father, of which one iterates at a time.
pub struct BrotherGroup {
    names: Vec<String>,
    arbitration: Option<Arbitration>,
    state: Mutex<(Vec<bool>, Option<usize>)>,
}

impl BrotherGroup {
    fn new(names: Vec<String>, arbitration: Option<Arbitration>) -> Arc<Self> {
        let n = names.len();
        Arc::new(BrotherGroup {
            names,
            arbitration,
            state: Mutex::new((vec![false; n], None)),
        })
    }

    /// Records whether brother `me` is ready and returns whether it is the winner.
    fn decide(&self, me: usize, ready: bool) -> bool {
        let mut s = self.state.lock();
        s.0[me] = ready;
        let candidates: Vec<usize> = (0..self.names.len()).filter(|&i| s.0[i]).collect();
        s.1 = if candidates.is_empty() {
            None
        } else {
            let names: Vec<&str> = candidates.iter().map(|&i| self.names[i].as_str()).collect();
            let pick = match &self.arbitration {
                Some(f) => catch_unwind(AssertUnwindSafe(|| f(&names))).unwrap_or(0),
                None => 0,
            };
            Some(candidates[pick.min(candidates.len() - 1)])
        };
        s.1 == Some(me)
    }

    /// The current winner's name.
    pub fn winner(&self) -> Option<String> {
        self.winner_index().map(|i| self.names[i].clone())
    }

    fn winner_index(&self) -> Option<usize> {
        self.state.lock().1
    }
}

/// Who ran a schema.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Father {
    /// The shell, the GUI or the conf file.
    Human,
    Schema(String),
}

/// Errors of run-time operations, each a one-line explanation.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum RuntimeError {
    #[error("`{name}` is not loaded; loaded: {loaded}")]
    NotLoaded { name: String, loaded: String },
    #[error("`{0}` is not running")]
    NotRunning(String),
    #[error("`{0}` is already running")]
    AlreadyRunning(String),
    #[error("`{0}` is already loaded")]
    AlreadyLoaded(String),
    #[error("`{0}` is an interface; only schemas can be {1}")]
    NotASchema(String, &'static str),
    #[error("{0}")]
    Load(String),
}

struct Control {
    state: State,
    father: Father,
    group: Option<(Arc<BrotherGroup>, usize)>,
    /// Schemas and interfaces this schema ran (stopped with it).
    children: Vec<String>,
    /// Pending requests for the schema thread.
    pending_on_run: bool,
    pending_on_stop: bool,
    reinit: Option<Box<dyn Schema>>,
    terminate: bool,
    last_error: Option<String>,
}

/// A loaded schema.
pub struct SchemaSlot {
    pub name: String,
    pub id: usize,
    pub summary: &'static str,
    ctl: Mutex<Control>,
    cond: Condvar,
    /// Bumped by every run/stop/terminate so a sleeping thread notices at once.
    generation: AtomicU64,
    cycle_ns: AtomicU64,
    stats: Mutex<Cronos>,
    shown: AtomicBool,
    thread: Mutex<Option<JoinHandle<()>>>,
    /// The schema's panel; only the GUI thread locks it.
    #[cfg(feature = "gui")]
    pub panel: Mutex<Option<Box<dyn crate::gui::Panel>>>,
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

/// What a schema sees of the runtime.
pub struct Context {
    runtime: Arc<Runtime>,
    slot: Arc<SchemaSlot>,
}

impl Context {
    /// This schema's name.
    pub fn name(&self) -> &str {
        &self.slot.name
    }
    /// The runtime (interfaces, name space, other schemas).
    pub fn runtime(&self) -> &Arc<Runtime> {
        &self.runtime
    }
    /// The interface table.
    pub fn interfaces(&self) -> &Interfaces {
        &self.runtime.interfaces
    }
    /// Iterations done since loaded.
    pub fn iterations(&self) -> u64 {
        self.slot.stats.lock().timing(false).iterations
    }
    /// Prints a line without garbling the shell.
    pub fn println(&self, line: impl Into<String>) {
        output::println(line);
    }
    /// Runs children (schemas or interfaces) as brothers under this schema, with an
    /// optional arbitration among them. They are stopped when this schema stops.
    pub fn run_children(
        &self,
        names: &[impl AsRef<str>],
        arbitration: Option<Arbitration>,
    ) -> Result<(), RuntimeError> {
        let names: Vec<&str> = names.iter().map(AsRef::as_ref).collect();
        let schema_names: Vec<String> = names
            .iter()
            .filter(|n| self.runtime.schema(n).is_some())
            .map(|n| n.to_string())
            .collect();
        let group = (schema_names.len() > 1 || arbitration.is_some())
            .then(|| BrotherGroup::new(schema_names.clone(), arbitration));
        for name in names {
            let g = group.as_ref().and_then(|g| {
                schema_names
                    .iter()
                    .position(|s| s == name)
                    .map(|i| (g.clone(), i))
            });
            self.runtime
                .run_as(name, Father::Schema(self.slot.name.clone()), g)?;
            self.slot.ctl.lock().children.push(name.to_string());
        }
        Ok(())
    }
}

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

    /// Loads every component of a conf and carries out its `run` and `show` lines, in
    /// file order. Stops at the first failure with an error naming its line.
    pub fn start(conf: &Conf) -> Result<Arc<Runtime>, ConfError> {
        let rt = Runtime::new(&conf.file);
        rt.apply(conf, true)?;
        Ok(rt)
    }

    /// Carries out a conf's directives in file order: its loads, and its `run` and
    /// `show` lines if `run_and_show`.
    fn apply(&self, conf: &Conf, run_and_show: bool) -> Result<(), ConfError> {
        for d in &conf.directives {
            let at = |e: RuntimeError| ConfError {
                at: d.at.clone(),
                message: e.to_string(),
            };
            match &d.action {
                Action::Load { kind, name, file } => {
                    self.load(conf, *kind, name, file.as_deref()).map_err(at)?
                }
                Action::Run(name) if run_and_show => self.run(name).map_err(at)?,
                Action::Show(name) if run_and_show => self.show(name).map_err(at)?,
                Action::Run(_) | Action::Show(_) => {}
            }
        }
        Ok(())
    }

    /// The main conf file.
    pub fn conf_file(&self) -> &Path {
        &self.conf_file
    }

    fn arc(&self) -> Arc<Runtime> {
        self.me.upgrade().expect("runtime alive")
    }

    /// Loads component `name` (of `kind`, or any kind for `None`) with its lines from
    /// `own_file` or its section in `conf`.
    pub fn load(
        &self,
        conf: &Conf,
        kind: Option<Kind>,
        name: &str,
        own_file: Option<&Path>,
    ) -> Result<(), RuntimeError> {
        let comp = registry::lookup(kind, name).map_err(RuntimeError::Load)?;
        if self.is_loaded(name) {
            return Err(RuntimeError::AlreadyLoaded(name.into()));
        }
        if let Some(f) = own_file
            && !f.exists()
        {
            return Err(RuntimeError::Load(format!(
                "conf file `{}` of {} `{name}` does not exist",
                f.display(),
                comp.kind
            )));
        }
        let cconf = conf
            .component_conf(comp.kind, name, own_file)
            .map_err(|e| RuntimeError::Load(e.to_string()))?;
        self.load_component(comp, &cconf)
    }

    /// Loads a component from a ready-made conf (for tests and embedding).
    pub fn load_component(
        &self,
        comp: &registry::Component,
        cconf: &ComponentConf,
    ) -> Result<(), RuntimeError> {
        let fail = |e: anyhow::Error| {
            RuntimeError::Load(format!(
                "{} `{}` failed to start: {e:#}",
                comp.kind, comp.name
            ))
        };
        match comp.factory {
            Factory::Schema(make) => {
                let schema = make(cconf, self).map_err(fail)?;
                self.add_schema(comp.name, comp.summary, schema)?;
            }
            Factory::Driver(make) => {
                let driver = make(cconf, self).map_err(fail)?;
                let mut d = self.drivers.lock();
                tracing::info!(
                    "{} {} loaded ({} {})",
                    comp.name,
                    comp.kind,
                    comp.kind,
                    d.len()
                );
                d.push(LoadedDriver {
                    name: comp.name.to_string(),
                    kind: comp.kind,
                    driver,
                });
            }
        }
        Ok(())
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
            stats: Mutex::new(Cronos::default()),
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
            .map_err(|e| RuntimeError::Load(format!("{name}: cannot start its thread: {e}")))?;
        *slot.thread.lock() = Some(handle);
        all.push(slot);
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

    fn not_loaded(&self, name: &str) -> RuntimeError {
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

    /// Re-creates a schema from a conf file (the shell's `init [conf]`); it keeps its
    /// slot, state and statistics.
    pub fn reinit(&self, name: &str, conf_file: Option<&Path>) -> Result<(), RuntimeError> {
        let slot = self.schema(name).ok_or_else(|| self.not_loaded(name))?;
        let comp = registry::lookup(Some(Kind::Schema), name).map_err(RuntimeError::Load)?;
        let file = conf_file.unwrap_or(&self.conf_file);
        let conf = Conf::load(file).map_err(|e| RuntimeError::Load(e.to_string()))?;
        let cconf = conf
            .component_conf(Kind::Schema, name, None)
            .map_err(|e| RuntimeError::Load(e.to_string()))?;
        let Factory::Schema(make) = comp.factory else {
            return Err(RuntimeError::Load(format!("`{name}` is not a schema")));
        };
        let schema = make(&cconf, self).map_err(|e| RuntimeError::Load(format!("{e:#}")))?;
        slot.cycle_ns
            .store(schema.cycle().as_nanos().max(1) as u64, Ordering::Relaxed);
        let mut c = slot.ctl.lock();
        c.reinit = Some(schema);
        slot.generation.fetch_add(1, Ordering::AcqRel);
        slot.cond.notify_all();
        Ok(())
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

impl SchemaSlot {
    fn status(&self) -> SchemaStatus {
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

/// Describes a panic payload.
fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        format!("panicked: {s}")
    } else if let Some(s) = p.downcast_ref::<String>() {
        format!("panicked: {s}")
    } else {
        "panicked".into()
    }
}

/// The body of a schema's thread: sleep while slept; while running, check
/// preconditions and arbitration each cycle and iterate if winner or forced.
fn schema_thread(rt: Arc<Runtime>, slot: Arc<SchemaSlot>, mut schema: Box<dyn Schema>) {
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
                .map_err(|p| panic_message(&*p))
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
                .map_err(|p| panic_message(&*p))
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

/// Checks a conf without running it: every load names a compiled-in component of
/// the right kind whose own file exists, no component is loaded twice, and every
/// `run`/`show` names something loaded before it. Returns every problem found.
pub fn check(conf: &Conf) -> Vec<ConfError> {
    let mut errors = Vec::new();
    let mut loaded: Vec<(String, Kind)> = Vec::new();
    let mut provided: Vec<String> = Vec::new();
    let err = |at: &Location, m: String| ConfError {
        at: at.clone(),
        message: m,
    };
    for d in &conf.directives {
        match &d.action {
            Action::Load { kind, name, file } => match registry::lookup(*kind, name) {
                Ok(c) => {
                    if loaded.iter().any(|(n, _)| n == name) {
                        errors.push(err(&d.at, format!("`{name}` is loaded twice")));
                    }
                    loaded.push((name.clone(), c.kind));
                    if let Some(f) = file
                        && !f.exists()
                    {
                        errors.push(err(
                            &d.at,
                            format!(
                                "conf file `{}` of {} `{name}` does not exist",
                                f.display(),
                                c.kind
                            ),
                        ));
                    }
                    if let Ok(cc) = conf.component_conf(c.kind, name, file.as_deref()) {
                        for l in cc.provides() {
                            if let Some(i) = l.args().first() {
                                provided.push(interfaces::canonical(i));
                            }
                        }
                    }
                }
                Err(m) => errors.push(err(&d.at, m)),
            },
            Action::Run(name) | Action::Show(name) => {
                let is_schema = loaded.iter().any(|(n, k)| n == name && *k == Kind::Schema);
                let base = interfaces::canonical(name.split('.').next().unwrap_or(name));
                let is_iface = provided.contains(&base)
                    || (interfaces::family(name).is_some()
                        && loaded.iter().any(|(_, k)| *k != Kind::Schema));
                let show = matches!(d.action, Action::Show(_));
                if !(is_schema || (!show && is_iface)) {
                    let verb = if show { "show" } else { "run" };
                    errors.push(err(
                        &d.at,
                        format!(
                            "`{verb} {name}`: no schema `{name}` is loaded before this line; \
                             add `load_schema {name}` above it"
                        ),
                    ));
                }
            }
        }
    }
    errors
}

/// Builds every component of a conf as a run would (each reads its lines and
/// files, and a driver opens its device), without running or showing anything,
/// then shuts them down: what `jderobot check` does once [`check`] finds nothing.
/// Returns the first component that fails, with its line.
pub fn check_loads(conf: &Conf) -> Result<(), ConfError> {
    let rt = Runtime::new(&conf.file);
    let result = rt.apply(conf, false);
    rt.shutdown();
    result
}

/// Whether a graphical display is reachable (X11 or Wayland).
pub fn display_available() -> bool {
    std::env::var_os("DISPLAY").is_some_and(|d| !d.is_empty())
        || std::env::var_os("WAYLAND_DISPLAY").is_some_and(|d| !d.is_empty())
}
