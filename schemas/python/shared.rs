//! What a python schema keeps in jderobot's process: the console its program's
//! `print` goes to, the state its panel shows ([`Shared`]), and the robot the
//! program drives ([`Robot`]): the interfaces, the command the worker sends, and
//! the sensors' values it writes on the worker's [`Board`].

use std::{
    collections::VecDeque,
    path::PathBuf,
    sync::{
        Arc, OnceLock,
        atomic::{AtomicBool, AtomicU64, Ordering},
        mpsc::{SyncSender, TrySendError, sync_channel},
    },
    time::{Duration, Instant},
};

use parking_lot::Mutex;

use super::board::{Board, Sensor, values};
use crate::world::{Drawings, LiveDrawings};
use crate::{
    interfaces::{
        AnyInterface, Bumpers, Encoders, Image, Interface, InterfaceValue, Laser, Motors, Sample,
    },
    output,
};

/// Lines the panel's console keeps.
pub const CONSOLE_LINES: usize = 500;
/// Lines waiting for the shell at most; more are counted and dropped, so a
/// program that floods `print` never waits on a terminal.
const SHELL_QUEUE: usize = 256;

/// What a schema shares with its panel, its keeper and its worker's reader.
/// One per schema name, kept across re-inits ([`shared`]).
#[derive(Default)]
pub struct Shared {
    pub name: String,
    /// The program's path and text as last loaded.
    pub file: Mutex<PathBuf>,
    pub source: Mutex<Arc<String>>,
    pub console: Mutex<Console>,
    /// The last error: its line in the program (0: none) and its text.
    pub error: Mutex<Option<(usize, String)>>,
    /// What `GUI.showImage` showed last, and a counter of shown images.
    pub image: Mutex<Option<Arc<Image>>>,
    pub images: AtomicU64,
    /// Asked from the panel or the shell: reload the program at the next cycle.
    pub reload: AtomicBool,
    /// While the program's code runs in its worker (a pass, or an Academy 5
    /// program's own loop).
    pub in_python: AtomicBool,
    /// How many times a schema of this name was built (a re-init is the second).
    pub loads: AtomicU64,
    /// The program's phase for the panel ("init", "loop", "finished", ...).
    pub phase: Mutex<&'static str>,
    /// The program's shape: the Academy 5 one (its own loop, `Frequency.tick`).
    pub academy5: AtomicBool,
    /// When the program last showed it is alive ([`Shared::touch`]), ns after
    /// [`epoch`]: the keeper sees the worker's HAL, GUI or Frequency calls
    /// counted on the board, or a pass ends.
    pub last_call: AtomicU64,
    /// What the program drew with `GUI.showForces` and `GUI.showLocalTarget`:
    /// the run's `world.drawings` (the world views, introrob's, draw them too),
    /// or its own where none could be exported ([`Shared::drawings`]).
    drawings: OnceLock<Arc<LiveDrawings>>,
    /// `Frequency.tick` calls and the loop's rate it measured (Hz, as f64
    /// bits), for the panel (the keeper copies them from the board).
    pub ticks: AtomicU64,
    pub tick_rate: AtomicU64,
}

/// The instant the schema's times count from.
pub fn epoch() -> Instant {
    static EPOCH: OnceLock<Instant> = OnceLock::new();
    *EPOCH.get_or_init(Instant::now)
}

fn since_epoch() -> u64 {
    epoch().elapsed().as_nanos() as u64
}

/// The console: the last lines a program printed.
#[derive(Default)]
pub struct Console {
    pub lines: VecDeque<String>,
    partial: String,
    /// Lines printed since loaded (the panel scrolls when it grows).
    pub total: u64,
}

impl Console {
    fn push_line(&mut self, line: String) {
        if self.lines.len() == CONSOLE_LINES {
            self.lines.pop_front();
        }
        self.lines.push_back(line);
        self.total += 1;
    }
    /// Appends text; returns the complete lines it ended.
    fn write(&mut self, text: &str) -> Vec<String> {
        let mut done = Vec::new();
        self.partial.push_str(text);
        while let Some(i) = self.partial.find('\n') {
            let line: String = self.partial.drain(..=i).collect();
            let line = line.trim_end_matches(['\n', '\r']).to_string();
            self.push_line(line.clone());
            done.push(line);
        }
        // A line that never ends is cut, so the buffer stays bounded.
        if self.partial.len() > 4096 {
            let line = std::mem::take(&mut self.partial);
            self.push_line(line.clone());
            done.push(line);
        }
        done
    }
    /// Ends a partial line (at the end of an iteration).
    fn flush(&mut self) -> Option<String> {
        (!self.partial.is_empty()).then(|| {
            let line = std::mem::take(&mut self.partial);
            self.push_line(line.clone());
            line
        })
    }
}

impl Shared {
    /// Writes program output (or our own messages) to the console and the shell.
    pub fn print(&self, text: &str) {
        let lines = self.console.lock().write(text);
        for l in lines {
            to_shell(&self.name, l);
        }
    }
    /// Ends a partial line.
    pub fn flush(&self) {
        let line = self.console.lock().flush();
        if let Some(l) = line {
            to_shell(&self.name, l);
        }
    }
    /// The program shows it is alive (see [`SILENCE`](super::SILENCE)).
    pub fn touch(&self) {
        self.last_call.store(since_epoch(), Ordering::Release);
    }
    /// Shares its drawings through `d` (the run's `world.drawings`); before
    /// the first drawing only.
    pub fn draw_into(&self, d: Arc<LiveDrawings>) {
        let _ = self.drawings.set(d);
    }
    /// The program's drawings.
    pub fn drawings(&self) -> &Arc<LiveDrawings> {
        self.drawings.get_or_init(Default::default)
    }
    /// Changes the program's drawings.
    pub fn draw(&self, change: impl FnOnce(&mut Drawings)) {
        let d = self.drawings();
        let mut now = **d.load();
        change(&mut now);
        d.store(Arc::new(now));
    }
    /// How long since the program last showed it is alive.
    pub fn silent_for(&self) -> Duration {
        Duration::from_nanos(since_epoch().saturating_sub(self.last_call.load(Ordering::Acquire)))
    }
    /// A new run: the clock of the silence limit and the ticks start afresh.
    pub fn new_run(&self) {
        self.touch();
        self.draw(|o| *o = Drawings::default());
        self.ticks.store(0, Ordering::Release);
        self.tick_rate.store(0, Ordering::Release);
    }
    /// The loop's rate as `Frequency.tick` measured it (Hz; 0 before two ticks).
    pub fn tick_rate(&self) -> f64 {
        f64::from_bits(self.tick_rate.load(Ordering::Acquire))
    }
    /// Clears the console (a new run).
    pub fn clear_console(&self) {
        let mut c = self.console.lock();
        c.lines.clear();
        c.partial.clear();
    }
}

/// The one [`Shared`] of schema `name` in runtime `rt` (a re-init keeps the panel's).
pub fn shared(rt: &crate::runtime::Runtime, name: &str) -> Arc<Shared> {
    type Entry = (std::sync::Weak<crate::runtime::Runtime>, Arc<Shared>);
    static ALL: OnceLock<Mutex<Vec<Entry>>> = OnceLock::new();
    let me = Arc::downgrade(&rt.arc());
    let mut all = ALL.get_or_init(Default::default).lock();
    all.retain(|(r, _)| r.strong_count() > 0);
    if let Some((_, s)) = all.iter().find(|(r, s)| r.ptr_eq(&me) && s.name == name) {
        return s.clone();
    }
    let s = Arc::new(Shared {
        name: name.to_string(),
        ..Shared::default()
    });
    all.push((me, s.clone()));
    s
}

/// Sends a line to the shell through a bounded queue and a printer thread.
fn to_shell(name: &str, line: String) {
    static QUEUE: OnceLock<(SyncSender<String>, AtomicU64)> = OnceLock::new();
    let (tx, dropped) = QUEUE.get_or_init(|| {
        let (tx, rx) = sync_channel::<String>(SHELL_QUEUE);
        let _ = std::thread::Builder::new()
            .name("python-print".into())
            .spawn(move || {
                while let Ok(l) = rx.recv() {
                    output::println(l);
                }
            });
        (tx, AtomicU64::new(0))
    });
    match tx.try_send(format!("{name}> {line}")) {
        Ok(()) => {
            let n = dropped.swap(0, Ordering::AcqRel);
            if n > 0 {
                let _ = tx.try_send(format!(
                    "{name}> ({n} lines not shown here: too many; the panel's console keeps the last {CONSOLE_LINES})"
                ));
            }
        }
        Err(TrySendError::Full(_)) => {
            dropped.fetch_add(1, Ordering::AcqRel);
        }
        Err(TrySendError::Disconnected(_)) => {}
    }
}

/// The robot a program drives: the interfaces its `uses` lines name (`None`:
/// `none`, or not provided), and the command `HAL.setV`/`setW` set.
///
/// The command reaches the motors when a call changes it, and is held: while the
/// program lives ([`Robot::hold`]) the keeper publishes it again whenever the
/// motors' latest value is [`REFRESH`] old, so a driver's `motors_timeout` never
/// zeroes a living program's command; it is zeroed when the program ends, fails,
/// is stopped or goes silent ([`SILENCE`](super::SILENCE)).
pub struct Robot {
    pub motors: Option<Arc<Interface<Motors>>>,
    pub encoders: Option<Arc<Interface<Encoders>>>,
    pub laser: Option<Arc<Interface<Laser>>>,
    pub bumpers: Option<Arc<Interface<Bumpers>>>,
    pub camera: Option<Arc<Interface<Image>>>,
    /// Which line names each, for errors: (key, interface name or `none`).
    pub names: Vec<(&'static str, String)>,
    /// The command: v mm/s, w deg/s.
    pub command: Mutex<Command>,
    /// While the program lives: its command is kept fresh.
    pub hold: AtomicBool,
    /// The run, for its clock (`HAL.getSimTime`).
    pub runtime: std::sync::Weak<crate::runtime::Runtime>,
    /// Whether the run's clock advances per motors command (a lock-stepped
    /// simulator, a `stepped motors` replay), read at the first command: then the
    /// command goes out once per pass, at its end, and never on the wall clock's
    /// account (no refresh): the simulator steps once per pass and the run is the
    /// same every time whatever the machine's load (two commands in one pass
    /// could reach it as one step or two).
    pub per_command: std::sync::OnceLock<bool>,
}

/// The program's command and whether it reached the motors during the current
/// pass (a pass without one publishes it at its end, so a lock-stepped simulator
/// steps once per pass).
#[derive(Clone, Copy, Default, Debug)]
pub struct Command {
    pub v: f32,
    pub w: f32,
    pub sent: bool,
}

/// How old the motors' latest value may get while a program lives before its
/// command is published again: well inside the drivers' `motors_timeout`
/// (500 ms by default).
pub const REFRESH: Duration = Duration::from_millis(100);

impl Robot {
    /// What the worker is told of each interface: (the `uses` line's key, the
    /// interface's name or `none`, whether it is there), for its errors.
    pub fn lines(&self) -> Vec<(String, String, bool)> {
        let there = [
            self.motors.is_some(),
            self.encoders.is_some(),
            self.laser.is_some(),
            self.bumpers.is_some(),
            self.camera.is_some(),
        ];
        self.names
            .iter()
            .zip(there)
            .map(|((k, n), t)| (k.to_string(), n.clone(), t))
            .collect()
    }

    /// The targets of the world the robot is in (`world.map`'s, whoever exported
    /// it), m, for `GUI.map`.
    pub fn targets(&self) -> Vec<(f64, f64)> {
        self.runtime
            .upgrade()
            .and_then(|rt| crate::world::map(&rt.names))
            .map(|w| {
                w.targets
                    .iter()
                    .map(|t| (t[0] / 1000.0, t[1] / 1000.0))
                    .collect()
            })
            .unwrap_or_default()
    }

    /// Writes on `board` every sensor value newer than the one it has
    /// (`last`: the clocks written so far, in [`Sensor`] order).
    pub fn feed(&self, board: &Board, last: &mut [u64; 4]) {
        fn newer<T>(i: &Option<Arc<Interface<T>>>, last: &mut u64) -> Option<Arc<Sample<T>>>
        where
            T: InterfaceValue,
        {
            let i = i.as_ref()?;
            if i.clock() == *last {
                return None;
            }
            let s = i.snapshot();
            *last = s.clock;
            (s.clock > 0).then_some(s)
        }
        if let Some(s) = newer(&self.encoders, &mut last[Sensor::Encoders as usize]) {
            values::put_encoders(board, s.clock, s.time, &s.value);
        }
        if let Some(s) = newer(&self.laser, &mut last[Sensor::Laser as usize]) {
            values::put_laser(board, s.clock, s.time, &s.value);
        }
        if let Some(s) = newer(&self.bumpers, &mut last[Sensor::Bumpers as usize]) {
            values::put_bumpers(board, s.clock, s.time, &s.value.bumpers);
        }
        if let Some(s) = newer(&self.camera, &mut last[Sensor::Camera as usize]) {
            values::put_image(board, s.clock, s.time, &s.value);
        }
    }

    /// The sensor interfaces (the keeper watches them).
    pub fn sensors(&self) -> Vec<&dyn AnyInterface> {
        let mut v: Vec<&dyn AnyInterface> = Vec::new();
        if let Some(i) = &self.encoders {
            v.push(i.as_ref());
        }
        if let Some(i) = &self.laser {
            v.push(i.as_ref());
        }
        if let Some(i) = &self.bumpers {
            v.push(i.as_ref());
        }
        if let Some(i) = &self.camera {
            v.push(i.as_ref());
        }
        v
    }

    fn publish(&self, m: &Interface<Motors>, c: &Command) {
        if let Err(e) = m.publish(Motors { v: c.v, w: c.w }) {
            tracing::warn!("python: the motors refused the command: {e}");
        }
    }

    /// See [`Robot::per_command`].
    pub fn per_command(&self) -> bool {
        *self.per_command.get_or_init(|| {
            self.runtime
                .upgrade()
                .and_then(|rt| crate::runtime::RunClock::import(&rt.names))
                .is_some_and(|clock| clock.per_command)
        })
    }

    /// Sets v (mm/s) and/or w (deg/s); the command reaches the motors at once
    /// unless they already have it, fresh (on a per-command clock: at the pass's
    /// end, [`Robot::end_of_pass`]).
    pub fn set(&self, v: Option<f32>, w: Option<f32>) {
        let Some(m) = &self.motors else { return };
        let mut c = self.command.lock();
        if let Some(v) = v {
            c.v = v;
        }
        if let Some(w) = w {
            c.w = w;
        }
        if self.per_command() {
            return;
        }
        let latest = m.read();
        let have = latest.clock > 0
            && latest.value == (Motors { v: c.v, w: c.w })
            && latest.stamp.elapsed() < REFRESH / 2;
        drop(latest);
        if !have {
            self.publish(m, &c);
            c.sent = true;
        }
    }

    /// A command from the program's worker: set (`HAL.setV`/`setW`), or the
    /// command at a pass's end on a per-command clock.
    pub fn command_from_program(&self, v: f32, w: f32, end_of_pass: bool) {
        self.set(Some(v), Some(w));
        if end_of_pass {
            self.end_of_pass();
        }
    }

    /// The end of a pass on a per-command clock (4.x: the loop body's end;
    /// Academy 5: `Frequency.tick`): publishes the command if nothing reached
    /// the motors during the pass.
    fn end_of_pass(&self) {
        let Some(m) = &self.motors else { return };
        let mut c = self.command.lock();
        if !c.sent {
            self.publish(m, &c);
        }
        c.sent = false;
    }

    /// Publishes the command again if the motors' latest value is [`REFRESH`]
    /// old (the keeper, while the program lives).
    pub fn refresh(&self) {
        let Some(m) = &self.motors else { return };
        if self.per_command() {
            return;
        }
        let c = self.command.lock();
        if m.read().stamp.elapsed() >= REFRESH {
            self.publish(m, &c);
        }
    }

    /// The program starts: its command (zero) is held.
    pub fn start_holding(&self) {
        self.zero();
        self.hold.store(true, Ordering::Release);
    }

    /// The program ends, fails or is stopped: the motors are zeroed and no
    /// longer refreshed.
    pub fn release(&self) {
        self.hold.store(false, Ordering::Release);
        self.zero();
    }

    /// Zeroes the command and the motors (stop, error, reload, silence).
    pub fn zero(&self) {
        let mut c = self.command.lock();
        *c = Command::default();
        if let Some(m) = &self.motors {
            let _ = m.publish(Motors::default());
        }
    }
}
