//! The embedded interpreter: one CPython per process, the Academy's `HAL` and `GUI`
//! modules, the console every program's `print` goes to, and a student's program
//! split into its init, loop body and after-loop code (`runner.py`).
//!
//! Every schema thread that runs a program sets [`Current`] (its console and robot)
//! for the time it runs Python; `HAL`, `GUI`, `print` and `time.sleep` find their
//! schema through it, so several python schemas share one interpreter and each
//! drives its own robot.

use std::{
    cell::RefCell,
    collections::VecDeque,
    ffi::CString,
    path::{Path, PathBuf},
    sync::{
        Arc, OnceLock,
        atomic::{AtomicBool, AtomicU64, Ordering},
        mpsc::{SyncSender, TrySendError, sync_channel},
    },
    time::{Duration, Instant},
};

use parking_lot::Mutex;
use pyo3::{
    exceptions::{PyAttributeError, PyRuntimeError, PyValueError},
    prelude::*,
    types::{PyByteArray, PyBytes, PyDict, PyModule},
};

use crate::{
    interfaces::{
        Bumpers, Encoders, Image, Interface, Laser, MAX_MOTOR_V, MAX_MOTOR_W, Motors, heading,
    },
    output,
};

/// Lines the panel's console keeps.
pub const CONSOLE_LINES: usize = 500;
/// Lines waiting for the shell at most; more are counted and dropped, so a
/// program that floods `print` never waits on a terminal.
const SHELL_QUEUE: usize = 256;

/// What a schema shares with its panel, its watchdog and the interpreter's
/// callbacks. One per schema name, kept across re-inits ([`shared`]).
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
    /// While Python code of this schema runs (the watchdog may interrupt it).
    pub in_python: AtomicBool,
    /// Set by the watchdog when it interrupts: `time.sleep` gives up at once.
    pub interrupted: AtomicBool,
    /// The Python thread id of the schema's thread.
    pub thread_ident: AtomicU64,
    /// How many times a schema of this name was built (a re-init is the second).
    pub loads: AtomicU64,
    /// The program's phase for the panel ("init", "loop", "finished", ...).
    pub phase: Mutex<&'static str>,
    /// The program's shape: the Academy 5 one (its own loop, `Frequency.tick`).
    pub academy5: AtomicBool,
    /// When the program last showed it is alive ([`Shared::touch`]), ns after
    /// [`epoch`]: a HAL, GUI or Frequency call, the end of a pass.
    pub last_call: AtomicU64,
    /// While the program waits in `time.sleep` or `Frequency.tick` (alive).
    pub sleeping: AtomicBool,
    /// Set when the silence limit stopped the motors (said once).
    pub silenced: AtomicBool,
    /// `Frequency.tick` calls, its next deadline, and the loop's rate it measured
    /// (Hz, as f64 bits) for the panel.
    pub ticks: AtomicU64,
    pub next_tick: Mutex<Option<Instant>>,
    pub last_tick: Mutex<Option<Instant>>,
    pub tick_rate: AtomicU64,
    /// Whether the console was told that a setV / setW was clamped (once a run).
    pub clamped: [AtomicBool; 2],
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
    #[inline]
    pub fn touch(&self) {
        self.last_call.store(since_epoch(), Ordering::Release);
        if self.silenced.load(Ordering::Relaxed) {
            self.silenced.store(false, Ordering::Release);
        }
    }
    /// How long since the program last showed it is alive.
    pub fn silent_for(&self) -> Duration {
        Duration::from_nanos(since_epoch().saturating_sub(self.last_call.load(Ordering::Acquire)))
    }
    /// A new run: the clock of the silence limit, the ticks and the clamp
    /// messages start afresh.
    pub fn new_run(&self) {
        self.touch();
        self.sleeping.store(false, Ordering::Release);
        self.ticks.store(0, Ordering::Release);
        self.tick_rate.store(0, Ordering::Release);
        *self.next_tick.lock() = None;
        *self.last_tick.lock() = None;
        for c in &self.clamped {
            c.store(false, Ordering::Release);
        }
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
/// program lives ([`Robot::hold`]) the watchdog publishes it again whenever the
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
    fn missing(&self, key: &str, call: &str) -> PyErr {
        let name = self
            .names
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, n)| n.as_str())
            .unwrap_or("none");
        PyRuntimeError::new_err(if name == "none" {
            format!(
                "HAL.{call}: this robot has no {key} (the python schema's conf says `{key} none`)"
            )
        } else {
            format!(
                "HAL.{call}: no driver provides `{name}` (the python schema's `{key}` line; \
                 add `provides {name}` to the driver, or name another interface)"
            )
        })
    }

    fn publish(&self, m: &Interface<Motors>, c: &Command) {
        if let Err(e) = m.publish(Motors { v: c.v, w: c.w }) {
            tracing::warn!("python: the motors refused the command: {e}");
        }
    }

    /// See [`Robot::per_command`].
    fn per_command(&self) -> bool {
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

    /// The end of a pass (4.x: the loop body's end; Academy 5: `Frequency.tick`):
    /// publishes the command if nothing reached the motors during the pass.
    pub fn end_of_pass(&self) {
        let Some(m) = &self.motors else { return };
        let mut c = self.command.lock();
        if !c.sent {
            self.publish(m, &c);
        }
        c.sent = false;
    }

    /// Publishes the command again if the motors' latest value is [`REFRESH`]
    /// old (the watchdog, while the program lives).
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

/// The schema whose program this thread runs.
pub struct Current {
    pub shared: Arc<Shared>,
    pub robot: Arc<Robot>,
}

thread_local! {
    static CURRENT: RefCell<Option<Current>> = const { RefCell::new(None) };
}

/// Sets (or clears) this thread's current program.
pub fn set_current(c: Option<Current>) {
    CURRENT.with(|x| *x.borrow_mut() = c);
}

/// Runs `f` with the calling thread's program: a call outside a program's
/// thread is an error; a call after the schema was stopped raises
/// `ProgramStopped`; any call shows the program is alive.
fn with_current<R>(
    py: Python<'_>,
    call: &str,
    f: impl FnOnce(&Current) -> PyResult<R>,
) -> PyResult<R> {
    CURRENT.with(|c| match &*c.borrow() {
        Some(c) => {
            if c.shared.interrupted.load(Ordering::Acquire) {
                return Err(stopped(py));
            }
            c.shared.touch();
            f(c)
        }
        None => Err(PyRuntimeError::new_err(format!(
            "{call}: called outside a python schema's own thread (HAL and GUI work only in the program's thread)"
        ))),
    })
}

/// `ProgramStopped`, raised in a program whose schema stops.
fn stopped(py: Python<'_>) -> PyErr {
    match runner(py).and_then(|r| r.getattr("ProgramStopped")) {
        Ok(t) => match t.cast_into() {
            Ok(t) => PyErr::from_type(t, "stopped"),
            Err(e) => e.into(),
        },
        Err(e) => e,
    }
}

// ---------------------------------------------------------------- HAL

/// `HAL.getPose3d()`: the robot's pose from odometry (m, rad).
#[pyclass(name = "Pose3d", frozen)]
#[derive(Clone)]
pub struct Pose3d {
    #[pyo3(get)]
    x: f64,
    #[pyo3(get)]
    y: f64,
    #[pyo3(get)]
    z: f64,
    #[pyo3(get)]
    yaw: f64,
    #[pyo3(get)]
    roll: f64,
    #[pyo3(get)]
    pitch: f64,
    /// The Academy's `h` (always 1).
    #[pyo3(get)]
    h: f64,
    /// The orientation as a quaternion [w, x, y, z] (about z).
    #[pyo3(get)]
    q: [f64; 4],
    /// When the pose was measured, s (wall clock).
    #[pyo3(get, name = "timeStamp")]
    time_stamp: f64,
}

#[pymethods]
impl Pose3d {
    fn __repr__(&self) -> String {
        format!(
            "Pose3d: x={:.3} y={:.3} z={:.3} yaw={:.3} roll={:.3} pitch={:.3}",
            self.x, self.y, self.z, self.yaw, self.roll, self.pitch
        )
    }
}

/// `HAL.getLaserData()`: ranges in m, index 0 at `minAngle` (rad, counter-clockwise
/// from ahead), one step `(maxAngle - minAngle) / (len(values) - 1)`.
#[pyclass(name = "LaserData", frozen)]
pub struct LaserData {
    #[pyo3(get)]
    values: Py<PyAny>,
    #[pyo3(get, name = "minAngle")]
    min_angle: f64,
    #[pyo3(get, name = "maxAngle")]
    max_angle: f64,
    #[pyo3(get, name = "minRange")]
    min_range: f64,
    #[pyo3(get, name = "maxRange")]
    max_range: f64,
}

#[pymethods]
impl LaserData {
    fn __repr__(&self, py: Python<'_>) -> String {
        let n = self.values.bind(py).len().unwrap_or(0);
        format!(
            "LaserData: {n} values, minAngle={:.4} maxAngle={:.4} rad, minRange={} maxRange={} m",
            self.min_angle, self.max_angle, self.min_range, self.max_range
        )
    }
}

/// `HAL.getBumperData()`: `state` 1 while touching; `bumper` which side (4.x:
/// 0 left, 1 centre, 2 right, -1 when nothing touches; Academy 5: 0 right,
/// 1 centre, 2 left, 1 when nothing touches).
#[pyclass(name = "BumperData", frozen)]
pub struct BumperData {
    #[pyo3(get)]
    state: i32,
    #[pyo3(get)]
    bumper: i32,
}

#[pymethods]
impl BumperData {
    fn __repr__(&self) -> String {
        format!("BumperData: state={} bumper={}", self.state, self.bumper)
    }
}

/// `HAL.getSimTime()`: the run's time (s and ns).
#[pyclass(name = "SimTimeData", frozen)]
pub struct SimTimeData {
    #[pyo3(get)]
    seconds: u64,
    #[pyo3(get)]
    nanoseconds: u32,
}

#[pymethods]
impl SimTimeData {
    fn __repr__(&self) -> String {
        format!(
            "SimTimeData: seconds={} nanoseconds={}",
            self.seconds, self.nanoseconds
        )
    }
    fn __float__(&self) -> f64 {
        self.seconds as f64 + self.nanoseconds as f64 * 1e-9
    }
}

/// The laser's geometry in the Academy's units, from the scan itself: (minAngle,
/// maxAngle rad, counter-clockwise from the robot's forward axis, the mount's yaw
/// included; minRange, maxRange m).
pub fn laser_geometry(l: &Laser) -> (f64, f64, f64, f64) {
    let n = l.readings.len().max(1);
    (
        (l.robot_angle(0) as f64).to_radians(),
        (l.robot_angle(n - 1) as f64).to_radians(),
        l.min_range as f64 / 1000.0,
        l.max_range as f64 / 1000.0,
    )
}

/// Which side a bumper array's pressed bumper is on: (state, bumper). A Pioneer's
/// 10 bumpers are 5 front (left to right) then 5 rear; the front ones count (0..2
/// left, 2 centre, 3..5 right); any other array is split in thirds, left to right.
pub fn bumper_side(b: &[u8]) -> (i32, i32) {
    let front = if b.len() == 10 { &b[..5] } else { b };
    let n = front.len();
    match front.iter().position(|&x| x != 0) {
        None => (0, -1),
        Some(i) => {
            let side = if n == 5 {
                match i {
                    0 | 1 => 0,
                    2 => 1,
                    _ => 2,
                }
            } else {
                (i * 3 / n.max(1)) as i32
            };
            (1, side)
        }
    }
}

/// The Academy's `HAL` object (4.x: `from HAL import HAL`). The Academy 5
/// module functions (`import HAL`) are its methods, but for `getLaserData` and
/// `getBumperData`, which follow the Academy 5's conventions ([`laser_values`],
/// [`bumper_data_5`]).
#[pyclass(name = "HAL", frozen)]
pub struct Hal;

/// What the HAL has, for the error of a call it has not.
const HAL_CALLS: &str = "setV, setW, getPose3d, getLaserData, getBumperData, getImage, getSimTime";

fn finite(call: &str, what: &str, unit: &str, x: f64) -> PyResult<f64> {
    if x.is_finite() {
        Ok(x)
    } else {
        Err(PyValueError::new_err(format!(
            "HAL.{call}: {what} must be a finite number ({unit}), not {x}"
        )))
    }
}

/// A speed in the motors' units, limited to what the `motors` interface takes
/// ([`MAX_MOTOR_V`], [`MAX_MOTOR_W`]): past it, the limit, said once a run in the
/// console.
fn clamp_speed(c: &Current, which: usize, asked: f64, shown: &str) -> f32 {
    let (max, call, unit, factor) = if which == 0 {
        (MAX_MOTOR_V as f64, "setV", "m/s", 1000.0)
    } else {
        (
            MAX_MOTOR_W as f64,
            "setW",
            "rad/s",
            180.0 / std::f64::consts::PI,
        )
    };
    let units = asked * factor;
    if units.abs() <= max {
        return units as f32;
    }
    let limit = max.copysign(units);
    if !c.shared.clamped[which].swap(true, Ordering::AcqRel) {
        c.shared.print(&format!(
            "-- HAL.{call}({shown}): past the motors' limit, {:.4} {unit}; clamped to it \
             (the driver may limit it further to its robot's maximum; said once)\n",
            max / factor
        ));
    }
    limit as f32
}

#[pymethods]
impl Hal {
    /// Forward speed, m/s.
    #[pyo3(name = "setV")]
    fn set_v(&self, py: Python<'_>, v: f64) -> PyResult<()> {
        let v = finite("setV", "v", "m/s", v)?;
        with_current(py, "HAL.setV", |c| {
            if c.robot.motors.is_none() {
                return Err(c.robot.missing("motors", "setV"));
            }
            let mm = clamp_speed(c, 0, v, &format!("{v}"));
            c.robot.set(Some(mm), None);
            Ok(())
        })
    }
    /// Turn speed, rad/s (positive turns left).
    #[pyo3(name = "setW")]
    fn set_w(&self, py: Python<'_>, w: f64) -> PyResult<()> {
        let w = finite("setW", "w", "rad/s", w)?;
        with_current(py, "HAL.setW", |c| {
            if c.robot.motors.is_none() {
                return Err(c.robot.missing("motors", "setW"));
            }
            let deg = clamp_speed(c, 1, w, &format!("{w}"));
            c.robot.set(None, Some(deg));
            Ok(())
        })
    }
    #[pyo3(name = "getPose3d")]
    fn get_pose3d(&self, py: Python<'_>) -> PyResult<Pose3d> {
        with_current(py, "HAL.getPose3d", |c| {
            let e = c
                .robot
                .encoders
                .as_ref()
                .ok_or_else(|| c.robot.missing("encoders", "getPose3d"))?;
            let s = e.read();
            let p = &s.value;
            let yaw = heading(p.theta) as f64;
            Ok(Pose3d {
                x: p.x as f64 / 1000.0,
                y: p.y as f64 / 1000.0,
                z: 0.0,
                yaw,
                roll: 0.0,
                pitch: 0.0,
                h: 1.0,
                q: [(yaw / 2.0).cos(), 0.0, 0.0, (yaw / 2.0).sin()],
                time_stamp: unix_seconds(s.time),
            })
        })
    }
    #[pyo3(name = "getLaserData")]
    fn get_laser_data(&self, py: Python<'_>) -> PyResult<LaserData> {
        let (values, (min_angle, max_angle, min_range, max_range), _) = latest_scan(py)?;
        Ok(LaserData {
            values: values.into_pyobject(py)?.into_any().unbind(),
            min_angle,
            max_angle,
            min_range,
            max_range,
        })
    }
    #[pyo3(name = "getBumperData")]
    fn get_bumper_data(&self, py: Python<'_>) -> PyResult<BumperData> {
        with_current(py, "HAL.getBumperData", |c| {
            let b = c
                .robot
                .bumpers
                .as_ref()
                .ok_or_else(|| c.robot.missing("bumpers", "getBumperData"))?;
            let (state, bumper) = bumper_side(&b.read().value.bumpers);
            Ok(BumperData { state, bumper })
        })
    }
    /// The camera's image: a numpy uint8 array H x W x 3, BGR (one copy of the bytes).
    #[pyo3(name = "getImage")]
    fn get_image<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let cam = with_current(py, "HAL.getImage", |c| {
            c.robot
                .camera
                .clone()
                .ok_or_else(|| c.robot.missing("camera", "getImage"))
        })?;
        let frame = cam.snapshot();
        let img = &frame.value;
        let data = PyByteArray::new(py, &img.data);
        runner(py)?.getattr("image_array")?.call1((
            data,
            img.height as usize,
            img.width as usize,
            3usize,
        ))
    }
    /// The run's time: the simulator's when it keeps its own (it exports
    /// `run.clock` when it does not run in real time), else the wall clock.
    #[pyo3(name = "getSimTime")]
    fn get_sim_time(&self, py: Python<'_>) -> PyResult<SimTimeData> {
        let t = with_current(py, "HAL.getSimTime", |c| {
            Ok(c.robot
                .runtime
                .upgrade()
                .and_then(|rt| crate::runtime::RunClock::import(&rt.names))
                .and_then(|clock| clock.now())
                .unwrap_or_else(std::time::SystemTime::now))
        })?;
        let d = t.duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        Ok(SimTimeData {
            seconds: d.as_secs(),
            nanoseconds: d.subsec_nanos(),
        })
    }
    fn __getattr__(&self, name: &str) -> PyResult<()> {
        Err(not_here("HAL", name, HAL_CALLS))
    }
}

fn unix_seconds(t: std::time::SystemTime) -> f64 {
    t.duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// The error of a call the Academy has and jderobot has not: an AttributeError
/// that names it and says what is here.
fn not_here(module: &str, name: &str, here: &str) -> PyErr {
    PyAttributeError::new_err(format!(
        "{module}.{name} is not here: jderobot's {module} has {here} \
         (docs/python.md, \"How it differs from the Academy\")"
    ))
}

/// The Academy 5 `HAL.getLaserData()`: a list of the ranges in m that also has
/// the LaserData fields, with the Academy 5's angles (0 to the robot's right,
/// π/2 ahead: the angle from ahead plus π/2).
#[pyfunction]
#[pyo3(name = "getLaserData")]
fn laser_values(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
    let (values, (min_angle, max_angle, min_range, max_range), time) = latest_scan(py)?;
    let half = std::f64::consts::FRAC_PI_2;
    runner(py)?.getattr("laser_values")?.call1((
        values,
        min_angle + half,
        max_angle + half,
        min_range,
        max_range,
        unix_seconds(time),
    ))
}

/// The robot's latest scan, for both generations' `HAL.getLaserData`: its
/// ranges in m, its geometry ([`laser_geometry`]) and when it was taken.
type Scan = (Vec<f64>, (f64, f64, f64, f64), std::time::SystemTime);

fn latest_scan(py: Python<'_>) -> PyResult<Scan> {
    let laser = with_current(py, "HAL.getLaserData", |c| {
        c.robot
            .laser
            .as_ref()
            .map(|l| l.snapshot())
            .ok_or_else(|| c.robot.missing("laser", "getLaserData"))
    })?;
    let values = laser
        .value
        .readings
        .iter()
        .map(|&r| r as f64 / 1000.0)
        .collect();
    Ok((values, laser_geometry(&laser.value), laser.time))
}

/// The Academy 5 `HAL.getBumperData()`: `state` 1 while touching; `bumper` 0
/// right, 1 centre, 2 left (1 when nothing touches), as its bumper interface.
#[pyfunction]
#[pyo3(name = "getBumperData")]
fn bumper_data_5(py: Python<'_>) -> PyResult<BumperData> {
    let b = Hal.get_bumper_data(py)?;
    Ok(match (b.state, b.bumper) {
        (0, _) => BumperData {
            state: 0,
            bumper: 1,
        },
        (s, side) => BumperData {
            state: s,
            bumper: 2 - side,
        },
    })
}

/// `__getattr__` of the Academy's modules: a name they do not have is a call
/// that is not here.
#[pyfunction]
#[pyo3(pass_module, name = "__getattr__")]
fn module_getattr(module: &Bound<'_, PyModule>, name: &str) -> PyResult<()> {
    let m = module.name()?.to_string();
    let here = match m.as_str() {
        "HAL" => HAL_CALLS,
        "Frequency" => "tick",
        _ => GUI_CALLS,
    };
    Err(not_here(&m, name, here))
}

// ---------------------------------------------------------------- Frequency

/// `Frequency.tick(hz)`: the Academy 5's pacing of a program's own loop. Sleeps
/// what is left of the period 1/hz since the previous tick (absolute deadlines:
/// no drift; a pass longer than a period starts the count again), publishes the
/// command if the pass did not (a lock-stepped simulator steps once per tick),
/// and raises `ProgramStopped` when the schema stops. `hz` is the Academy's
/// `ideal_cycle`, 50 by default.
#[pyfunction]
#[pyo3(name = "tick", signature = (ideal_cycle = None, *, hz = None))]
fn tick(py: Python<'_>, ideal_cycle: Option<f64>, hz: Option<f64>) -> PyResult<()> {
    let hz = hz.or(ideal_cycle).unwrap_or(TICK_HZ);
    if !hz.is_finite() || hz <= 0.0 {
        return Err(PyValueError::new_err(format!(
            "Frequency.tick: the frequency must be a positive number of Hz, not {hz}"
        )));
    }
    let (shared, robot) = with_current(py, "Frequency.tick", |c| {
        Ok((c.shared.clone(), c.robot.clone()))
    })?;
    robot.end_of_pass();
    let period = Duration::from_secs_f64(1.0 / hz);
    let now = Instant::now();
    let until = {
        let mut next = shared.next_tick.lock();
        let until = match *next {
            Some(t) if now < t + period => t,
            // The first tick, or a pass a period late: from now.
            _ => now,
        };
        *next = Some(until + period);
        until
    };
    if wait_until(py, &shared, until) {
        return Err(stopped(py));
    }
    // The loop's rate, smoothed over about ten passes.
    shared.ticks.fetch_add(1, Ordering::AcqRel);
    let now = Instant::now();
    if let Some(last) = shared.last_tick.lock().replace(now) {
        let dt = now.duration_since(last).as_secs_f64();
        if dt > 0.0 {
            let old = shared.tick_rate();
            let rate = if old == 0.0 {
                1.0 / dt
            } else {
                0.9 * old + 0.1 / dt
            };
            shared.tick_rate.store(rate.to_bits(), Ordering::Release);
        }
    }
    Ok(())
}

/// The Academy's default loop frequency, Hz (`Frequency.tick()`).
pub const TICK_HZ: f64 = 50.0;

/// Waits until `until` (the GIL released), counting as alive; true if the schema
/// was stopped meanwhile.
fn wait_until(py: Python<'_>, shared: &Shared, until: Instant) -> bool {
    shared.sleeping.store(true, Ordering::Release);
    let stopped = py.detach(|| {
        loop {
            if shared.interrupted.load(Ordering::Acquire) {
                return true;
            }
            let left = until.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            std::thread::sleep(left.min(Duration::from_millis(5)));
        }
    });
    shared.sleeping.store(false, Ordering::Release);
    shared.touch();
    stopped
}

// ---------------------------------------------------------------- GUI

/// What the GUI has, for the error of a call it has not.
const GUI_CALLS: &str = "showImage";

/// The Academy's `GUI` object.
#[pyclass(name = "GUI", frozen)]
pub struct Gui;

#[pymethods]
impl Gui {
    /// Shows an image (numpy H x W grey or H x W x 3 BGR) in the schema's panel.
    #[pyo3(name = "showImage")]
    fn show_image(&self, py: Python<'_>, img: Bound<'_, PyAny>) -> PyResult<()> {
        let (h, w, ch, bytes): (usize, usize, usize, Bound<'_, PyBytes>) = runner(py)?
            .getattr("image_bytes")?
            .call1((img,))?
            .extract()?;
        let raw = bytes.as_bytes();
        let data = if ch == 3 {
            raw.to_vec()
        } else {
            raw.iter().flat_map(|&g| [g, g, g]).collect()
        };
        let image = Image {
            width: w as u32,
            height: h as u32,
            data,
        };
        with_current(py, "GUI.showImage", |c| {
            *c.shared.image.lock() = Some(Arc::new(image));
            c.shared.images.fetch_add(1, Ordering::AcqRel);
            Ok(())
        })
    }
    fn __getattr__(&self, name: &str) -> PyResult<()> {
        Err(not_here("GUI", name, GUI_CALLS))
    }
}

/// `sys.stdout` and `sys.stderr`: a program's output goes to its console.
#[pyclass(frozen)]
struct Output;

#[pymethods]
impl Output {
    fn write(&self, text: &str) -> usize {
        let handled = CURRENT.with(|c| match &*c.borrow() {
            Some(c) => {
                c.shared.print(text);
                true
            }
            None => false,
        });
        if !handled {
            for l in text.lines().filter(|l| !l.is_empty()) {
                output::println(format!("python> {l}"));
            }
        }
        text.len()
    }
    fn flush(&self) {}
    fn isatty(&self) -> bool {
        false
    }
    #[getter]
    fn encoding(&self) -> &'static str {
        "utf-8"
    }
}

/// `time.sleep`, replaced so a stop interrupts a sleeping program at once; a
/// sleeping program is alive (its command held).
#[pyfunction]
fn sleep(py: Python<'_>, seconds: f64) -> PyResult<()> {
    if !seconds.is_finite() || seconds < 0.0 {
        return Err(PyValueError::new_err(
            "sleep length must be a non-negative number",
        ));
    }
    let shared = CURRENT.with(|c| c.borrow().as_ref().map(|c| c.shared.clone()));
    let until = Instant::now() + Duration::from_secs_f64(seconds.min(1e6));
    let Some(shared) = shared else {
        py.detach(|| std::thread::sleep(until.saturating_duration_since(Instant::now())));
        return Ok(());
    };
    if shared.interrupted.load(Ordering::Acquire) || wait_until(py, &shared, until) {
        return Err(stopped(py));
    }
    shared.touch();
    Ok(())
}

/// The helper module (`runner.py`).
pub fn runner(py: Python<'_>) -> PyResult<Bound<'_, PyModule>> {
    py.import("_jderobot")
}

/// Starts the interpreter once: `HAL`, `GUI` and `_jderobot` importable, the
/// consoles in place of `sys.stdout`/`sys.stderr`, `time.sleep` replaced, and
/// `$VIRTUAL_ENV`'s site-packages on the path.
pub fn interpreter() -> Result<(), String> {
    static READY: OnceLock<Result<(), String>> = OnceLock::new();
    READY
        .get_or_init(|| {
            Python::initialize();
            Python::attach(|py| -> PyResult<()> {
                let sys = py.import("sys")?;
                let modules = sys.getattr("modules")?;
                let code = CString::new(include_str!("runner.py")).expect("no NUL in runner.py");
                let r = PyModule::from_code(py, &code, c"<jderobot runner>", c"_jderobot")?;
                r.add_function(wrap_pyfunction!(sleep, &r)?)?;
                modules.set_item("_jderobot", &r)?;
                // HAL: the 4.x object `HAL.HAL` and the Academy 5 functions.
                let hal = PyModule::new(py, "HAL")?;
                let hal_object = Bound::new(py, Hal)?;
                for f in ["setV", "setW", "getPose3d", "getImage", "getSimTime"] {
                    hal.add(f, hal_object.getattr(f)?)?;
                }
                hal.add_function(wrap_pyfunction!(laser_values, &hal)?)?;
                hal.add_function(wrap_pyfunction!(bumper_data_5, &hal)?)?;
                hal.add("HAL", hal_object)?;
                hal.add_class::<Pose3d>()?;
                hal.add_class::<LaserData>()?;
                hal.add_class::<BumperData>()?;
                hal.add_class::<SimTimeData>()?;
                hal.add_function(wrap_pyfunction!(module_getattr, &hal)?)?;
                modules.set_item("HAL", hal)?;
                // GUI (4.x `GUI.GUI`, Academy 5 `GUI.showImage`) and WebGUI, its
                // Academy 5 name.
                let gui_object = Bound::new(py, Gui)?;
                for name in ["GUI", "WebGUI"] {
                    let gui = PyModule::new(py, name)?;
                    gui.add("showImage", gui_object.getattr("showImage")?)?;
                    gui.add("GUI", &gui_object)?;
                    gui.add_function(wrap_pyfunction!(module_getattr, &gui)?)?;
                    modules.set_item(name, gui)?;
                }
                let frequency = PyModule::new(py, "Frequency")?;
                frequency.add_function(wrap_pyfunction!(tick, &frequency)?)?;
                frequency.add_function(wrap_pyfunction!(module_getattr, &frequency)?)?;
                modules.set_item("Frequency", frequency)?;
                sys.setattr("stdout", Bound::new(py, Output)?)?;
                sys.setattr("stderr", Bound::new(py, Output)?)?;
                sys.setattr("argv", vec![String::from("jderobot")])?;
                py.import("time")?.setattr("sleep", r.getattr("sleep")?)?;
                if let Some(v) = std::env::var_os("VIRTUAL_ENV") {
                    r.getattr("add_venv")?
                        .call1((v.to_string_lossy().to_string(),))?;
                }
                Ok(())
            })
            .map_err(|e| format!("cannot start the Python interpreter: {e}"))
        })
        .clone()
}

/// Adds a virtual environment; Err if it has no site-packages.
pub fn add_venv(venv: &Path) -> Result<Vec<String>, String> {
    Python::attach(|py| -> PyResult<Vec<String>> {
        runner(py)?
            .getattr("add_venv")?
            .call1((venv.display().to_string(),))?
            .extract()
    })
    .map_err(|e| e.to_string())
    .and_then(|dirs: Vec<String>| {
        if dirs.is_empty() {
            Err(format!(
                "venv `{}` has no lib/python3*/site-packages (make one with `python3 -m venv {}`)",
                venv.display(),
                venv.display()
            ))
        } else {
            Ok(dirs)
        }
    })
}

/// A compiled program.
pub struct Program {
    pub path: String,
    init: Py<PyAny>,
    loop_body: Option<Py<PyAny>>,
    after: Option<Py<PyAny>>,
    /// The Academy 5 shape: `init` is the whole program, run in a thread of its
    /// own with its own loop.
    pub academy5: bool,
    globals: Py<PyDict>,
}

/// A program's failure: the line (0: unknown), a one-line `FILE:LINE: what`, and
/// the full text (a traceback) to print.
pub struct Failure {
    pub line: usize,
    pub summary: String,
    pub text: String,
}

/// How running a piece of the program went.
pub enum Outcome {
    Done,
    /// `break` out of the main loop.
    Broke,
    /// Interrupted because the schema stops.
    Stopped,
    /// `sys.exit(...)` / `exit()`: the program ended itself (its argument).
    Exited(String),
    Failed(Failure),
}

impl Program {
    /// Compiles `source` (from `path`); a syntax error is `FILE:LINE: message`.
    pub fn compile(path: &str, source: &str) -> Result<Program, Failure> {
        Python::attach(|py| {
            let r = runner(py).map_err(|e| internal(py, e))?;
            match r.getattr("split").and_then(|f| f.call1((source, path))) {
                Ok(t) => {
                    let (init, lp, after, _line, shape): (
                        Py<PyAny>,
                        Py<PyAny>,
                        Py<PyAny>,
                        usize,
                        u8,
                    ) = t.extract().map_err(|e| internal(py, e))?;
                    let opt = |o: Py<PyAny>| (!o.is_none(py)).then_some(o);
                    Ok(Program {
                        path: path.to_string(),
                        init,
                        loop_body: opt(lp),
                        after: opt(after),
                        academy5: shape == 5,
                        globals: fresh_globals(py, path).map_err(|e| internal(py, e))?,
                    })
                }
                Err(e) if e.is_instance_of::<pyo3::exceptions::PySyntaxError>(py) => {
                    let (summary, line): (String, usize) = r
                        .getattr("syntax_error")
                        .and_then(|f| f.call1((e.value(py), path)))
                        .and_then(|t| t.extract())
                        .map_err(|e| internal(py, e))?;
                    Err(Failure {
                        line,
                        text: summary.clone(),
                        summary,
                    })
                }
                Err(e) => Err(describe(py, &e, path)),
            }
        })
    }

    /// Whether the program has a main loop.
    pub fn has_loop(&self) -> bool {
        self.loop_body.is_some()
    }

    /// Runs the init code (`which` 0), one loop iteration (1) or the after-loop
    /// code (2) on this thread, marking `shared.in_python` for the watchdog.
    /// With `cancel` set before the code starts, it does not start.
    pub fn run(&self, which: u8, shared: &Shared, cancel: Option<&AtomicBool>) -> Outcome {
        let code = match which {
            0 => Some(&self.init),
            1 => self.loop_body.as_ref(),
            _ => self.after.as_ref(),
        };
        let Some(code) = code else {
            return Outcome::Done;
        };
        Python::attach(|py| {
            // SAFETY: clears a stop request left for this thread after its last run
            // (null clears); the GIL is held.
            let ident = unsafe { pyo3::ffi::PyThread_get_thread_ident() };
            shared.thread_ident.store(ident as u64, Ordering::Release);
            unsafe {
                pyo3::ffi::PyThreadState_SetAsyncExc(
                    ident as std::ffi::c_long,
                    std::ptr::null_mut(),
                )
            };
            shared.interrupted.store(false, Ordering::SeqCst);
            shared.in_python.store(true, Ordering::SeqCst);
            if cancel.is_some_and(|c| c.load(Ordering::SeqCst)) {
                shared.in_python.store(false, Ordering::SeqCst);
                return Outcome::Stopped;
            }
            let g = self.globals.bind(py);
            let result = py
                .import("builtins")
                .and_then(|b| b.getattr("exec"))
                .and_then(|exec| exec.call1((code.bind(py), g)));
            shared.in_python.store(false, Ordering::Release);
            match result {
                Ok(_) => {
                    if which == 1
                        && g.get_item("__jderobot_broke__")
                            .ok()
                            .flatten()
                            .is_some_and(|b| b.is_truthy().unwrap_or(false))
                    {
                        Outcome::Broke
                    } else {
                        Outcome::Done
                    }
                }
                Err(e) if is_stop(py, &e) => Outcome::Stopped,
                Err(e) if e.is_instance_of::<pyo3::exceptions::PySystemExit>(py) => {
                    let code = e
                        .value(py)
                        .getattr("code")
                        .ok()
                        .filter(|c| !c.is_none())
                        .map(|c| c.to_string())
                        .unwrap_or_default();
                    Outcome::Exited(code)
                }
                Err(e) => Outcome::Failed(describe(py, &e, &self.path)),
            }
        })
    }
}

fn fresh_globals<'py>(py: Python<'py>, path: &str) -> PyResult<Py<PyDict>> {
    let g = PyDict::new(py);
    g.set_item("__name__", "__main__")?;
    g.set_item("__file__", path)?;
    g.set_item("__builtins__", py.import("builtins")?)?;
    Ok(g.unbind())
}

fn is_stop(py: Python<'_>, e: &PyErr) -> bool {
    runner(py)
        .and_then(|r| r.getattr("ProgramStopped"))
        .map(|t| e.get_type(py).is(&t))
        .unwrap_or(false)
}

fn describe(py: Python<'_>, e: &PyErr, path: &str) -> Failure {
    let r = runner(py).and_then(|r| r.getattr("describe"));
    match r
        .and_then(|f| f.call1((e.value(py), e.traceback(py), path)))
        .and_then(|t| {
            let (text, line, summary): (String, usize, String) = t.extract()?;
            Ok((text, line, summary))
        }) {
        Ok((text, line, summary)) => Failure {
            line,
            summary,
            text,
        },
        Err(e2) => internal(py, e2),
    }
}

fn internal(py: Python<'_>, e: PyErr) -> Failure {
    let summary = format!("python: {}", e.value(py));
    Failure {
        line: 0,
        text: summary.clone(),
        summary,
    }
}

/// Interrupts the program running on `shared`'s thread with `ProgramStopped`
/// (the watchdog calls it; a program stuck in `while True: pass` stops too).
pub fn interrupt(shared: &Shared) {
    shared.interrupted.store(true, Ordering::SeqCst);
    Python::attach(|py| {
        if !shared.in_python.load(Ordering::Acquire) {
            return;
        }
        let Ok(t) = runner(py).and_then(|r| r.getattr("ProgramStopped")) else {
            return;
        };
        let ident = shared.thread_ident.load(Ordering::Acquire);
        // SAFETY: the GIL is held; the exception type is a live class object; the
        // call takes its own reference.
        unsafe {
            pyo3::ffi::PyThreadState_SetAsyncExc(ident as _, t.as_ptr());
        }
    });
}
