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
    exceptions::{PyRuntimeError, PyValueError},
    prelude::*,
    types::{PyByteArray, PyBytes, PyDict, PyModule},
};

use crate::{
    interfaces::{Bumpers, Encoders, Image, Interface, Laser, Motors, heading},
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
pub struct Robot {
    pub motors: Option<Arc<Interface<Motors>>>,
    pub encoders: Option<Arc<Interface<Encoders>>>,
    pub laser: Option<Arc<Interface<Laser>>>,
    pub bumpers: Option<Arc<Interface<Bumpers>>>,
    pub camera: Option<Arc<Interface<Image>>>,
    /// Which line names each, for errors: (key, interface name or `none`).
    pub names: Vec<(&'static str, String)>,
    /// v mm/s, w deg/s, and whether a program has set them since the last publish.
    pub command: Mutex<(f32, f32, bool)>,
}

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

    /// Publishes the command if a program changed it (once per iteration).
    pub fn publish_command(&self) {
        let mut c = self.command.lock();
        if let Some(m) = &self.motors {
            let _ = m.publish(Motors { v: c.0, w: c.1 });
        }
        c.2 = false;
    }

    /// Zeroes the motors (stop, error, reload).
    pub fn zero(&self) {
        *self.command.lock() = (0.0, 0.0, false);
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

fn with_current<R>(call: &str, f: impl FnOnce(&Current) -> PyResult<R>) -> PyResult<R> {
    CURRENT.with(|c| match &*c.borrow() {
        Some(c) => f(c),
        None => Err(PyRuntimeError::new_err(format!(
            "{call}: called outside a python schema's own thread (HAL and GUI work only in the program's thread)"
        ))),
    })
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

/// `HAL.getBumperData()`: `state` 1 while touching; `bumper` 0 left, 1 centre,
/// 2 right (-1 when nothing touches).
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

/// The Academy's `HAL` object.
#[pyclass(name = "HAL", frozen)]
pub struct Hal;

fn finite(call: &str, what: &str, unit: &str, x: f64) -> PyResult<f64> {
    if x.is_finite() {
        Ok(x)
    } else {
        Err(PyValueError::new_err(format!(
            "HAL.{call}: {what} must be a finite number ({unit}), not {x}"
        )))
    }
}

#[pymethods]
impl Hal {
    /// Forward speed, m/s.
    #[allow(non_snake_case)]
    #[pyo3(name = "setV")]
    fn set_v(&self, v: f64) -> PyResult<()> {
        let v = finite("setV", "v", "m/s", v)?;
        with_current("HAL.setV", |c| {
            if c.robot.motors.is_none() {
                return Err(c.robot.missing("motors", "setV"));
            }
            let mut m = c.robot.command.lock();
            m.0 = (v * 1000.0) as f32;
            m.2 = true;
            Ok(())
        })
    }
    /// Turn speed, rad/s (positive turns left).
    #[pyo3(name = "setW")]
    fn set_w(&self, w: f64) -> PyResult<()> {
        let w = finite("setW", "w", "rad/s", w)?;
        with_current("HAL.setW", |c| {
            if c.robot.motors.is_none() {
                return Err(c.robot.missing("motors", "setW"));
            }
            let mut m = c.robot.command.lock();
            m.1 = w.to_degrees() as f32;
            m.2 = true;
            Ok(())
        })
    }
    #[pyo3(name = "getPose3d")]
    fn get_pose3d(&self) -> PyResult<Pose3d> {
        with_current("HAL.getPose3d", |c| {
            let e = c
                .robot
                .encoders
                .as_ref()
                .ok_or_else(|| c.robot.missing("encoders", "getPose3d"))?;
            let p = e.read().value;
            Ok(Pose3d {
                x: p.x as f64 / 1000.0,
                y: p.y as f64 / 1000.0,
                z: 0.0,
                yaw: heading(p.theta) as f64,
                roll: 0.0,
                pitch: 0.0,
            })
        })
    }
    #[pyo3(name = "getLaserData")]
    fn get_laser_data(&self, py: Python<'_>) -> PyResult<LaserData> {
        let laser = with_current("HAL.getLaserData", |c| {
            c.robot
                .laser
                .as_ref()
                .map(|l| l.snapshot())
                .ok_or_else(|| c.robot.missing("laser", "getLaserData"))
        })?;
        let (min_angle, max_angle, min_range, max_range) = laser_geometry(&laser.value);
        let values: Vec<f64> = laser
            .value
            .readings
            .iter()
            .map(|&r| r as f64 / 1000.0)
            .collect();
        Ok(LaserData {
            values: values.into_pyobject(py)?.into_any().unbind(),
            min_angle,
            max_angle,
            min_range,
            max_range,
        })
    }
    #[pyo3(name = "getBumperData")]
    fn get_bumper_data(&self) -> PyResult<BumperData> {
        with_current("HAL.getBumperData", |c| {
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
        let cam = with_current("HAL.getImage", |c| {
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
}

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
        with_current("GUI.showImage", |c| {
            *c.shared.image.lock() = Some(Arc::new(image));
            c.shared.images.fetch_add(1, Ordering::AcqRel);
            Ok(())
        })
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

/// `time.sleep`, replaced so a stop interrupts a sleeping program at once and a
/// command set before sleeping reaches the motors.
#[pyfunction]
fn sleep(py: Python<'_>, seconds: f64) -> PyResult<()> {
    if !seconds.is_finite() || seconds < 0.0 {
        return Err(PyValueError::new_err(
            "sleep length must be a non-negative number",
        ));
    }
    let current = CURRENT.with(|c| {
        c.borrow()
            .as_ref()
            .map(|c| (c.shared.clone(), c.robot.clone()))
    });
    let until = Instant::now() + Duration::from_secs_f64(seconds.min(1e6));
    let Some((shared, robot)) = current else {
        py.detach(|| std::thread::sleep(until.saturating_duration_since(Instant::now())));
        return Ok(());
    };
    if robot.command.lock().2 {
        robot.publish_command();
    }
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
    if stopped {
        let t = runner(py)?.getattr("ProgramStopped")?;
        return Err(PyErr::from_type(t.cast_into()?, "stopped"));
    }
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
                let hal = PyModule::new(py, "HAL")?;
                hal.add("HAL", Bound::new(py, Hal)?)?;
                hal.add_class::<Pose3d>()?;
                hal.add_class::<LaserData>()?;
                hal.add_class::<BumperData>()?;
                modules.set_item("HAL", hal)?;
                let gui = PyModule::new(py, "GUI")?;
                gui.add("GUI", Bound::new(py, Gui)?)?;
                modules.set_item("GUI", gui)?;
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
    Failed(Failure),
}

impl Program {
    /// Compiles `source` (from `path`); a syntax error is `FILE:LINE: message`.
    pub fn compile(path: &str, source: &str) -> Result<Program, Failure> {
        Python::attach(|py| {
            let r = runner(py).map_err(|e| internal(py, e))?;
            match r.getattr("split").and_then(|f| f.call1((source, path))) {
                Ok(t) => {
                    let (init, lp, after, _line): (Py<PyAny>, Py<PyAny>, Py<PyAny>, usize) =
                        t.extract().map_err(|e| internal(py, e))?;
                    let opt = |o: Py<PyAny>| (!o.is_none(py)).then_some(o);
                    Ok(Program {
                        path: path.to_string(),
                        init,
                        loop_body: opt(lp),
                        after: opt(after),

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
    pub fn run(&self, which: u8, shared: &Shared) -> Outcome {
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
            shared.interrupted.store(false, Ordering::Release);
            shared.in_python.store(true, Ordering::Release);
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
    shared.interrupted.store(true, Ordering::Release);
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
