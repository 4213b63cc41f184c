//! The worker: the process a python schema runs its program in (the jderobot
//! binary itself, started again with [`WORKER_ENV`] set), so that nothing the
//! program does (`os._exit`, a segfault in C code, the out-of-memory killer, a
//! thread that never ends) reaches jderobot: its schema sees the process end,
//! zeroes the motors and says why.
//!
//! Here live the embedded CPython, the Academy's `HAL`, `GUI`/`WebGUI` and
//! `Frequency` modules, and the program split into its init, loop body and
//! after-loop code (`runner.py`). The worker reads the sensors from the
//! [`Board`] jderobot writes (no system call), and sends what the program
//! prints, shows and commands over its socket ([`wire`]). Descriptors: 3 the
//! board, 4 the socket, 5 the lifeline (its end of a pipe jderobot holds: when
//! jderobot ends, however it ends, the worker ends too). stdin is /dev/null, so
//! `input()` ends the program with an EOFError instead of eating the shell's
//! commands; stdout and stderr go to the schema's console (a crash's report
//! included: `faulthandler` is on).

use std::{
    ffi::CString,
    io::Read,
    os::{fd::FromRawFd, unix::net::UnixStream},
    path::Path,
    process::ExitCode,
    sync::{
        OnceLock,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, Instant},
};

use parking_lot::Mutex;
use pyo3::{
    exceptions::{PyAttributeError, PyRuntimeError, PyValueError},
    prelude::*,
    types::{PyByteArray, PyBytes, PyDict, PyModule},
};

use super::{
    board::{Board, values},
    wire::{self, Failure, FromWorker, Outcome, ToWorker},
};
use crate::interfaces::{Laser, MAX_MOTOR_V, MAX_MOTOR_W, heading};

/// The environment variable that makes the binary a python worker.
pub const WORKER_ENV: &str = "JDEROBOT_PYTHON_WORKER";

/// The descriptors jderobot hands the worker.
pub const BOARD_FD: i32 = 3;
pub const SOCKET_FD: i32 = 4;
pub const LIFELINE_FD: i32 = 5;

/// The worker's one program and its link to jderobot.
struct Worker {
    board: Board,
    to_jderobot: Mutex<UnixStream>,
    /// (the `uses` line's key, the interface or `none`, whether it is there).
    /// Set by the (one) load of the worker's program.
    lines: OnceLock<Vec<(String, String, bool)>>,
    per_command: AtomicBool,
    /// The program's command (v mm/s, w deg/s) and the last one sent.
    command: Mutex<(f32, f32)>,
    sent: Mutex<Option<(f32, f32)>>,
    /// Whether the console was told that a setV / setW was clamped (once).
    clamped: [AtomicBool; 2],
    /// `Frequency.tick`'s next deadline and its last tick.
    next_tick: Mutex<Option<Instant>>,
    last_tick: Mutex<Option<Instant>>,
    /// Text printed but not yet sent (a partial line).
    printed: Mutex<String>,
}

static WORKER: OnceLock<Worker> = OnceLock::new();

fn worker() -> &'static Worker {
    WORKER
        .get()
        .expect("the worker is set up before any Python runs")
}

impl Worker {
    fn send(&self, msg: &FromWorker, payload: &[u8]) {
        // jderobot gone: the lifeline ends this process.
        let _ = wire::send(&mut *self.to_jderobot.lock(), msg, payload);
    }

    /// Any call shows the program is alive.
    fn touch(&self) {
        self.board.header().calls.fetch_add(1, Ordering::Relaxed);
    }

    fn print(&self, text: &str) {
        let mut p = self.printed.lock();
        p.push_str(text);
        if p.contains('\n') || p.len() >= 4096 {
            let text = std::mem::take(&mut *p);
            drop(p);
            self.send(&FromWorker::Print(text), &[]);
        }
    }

    fn flush(&self) {
        let text = std::mem::take(&mut *self.printed.lock());
        if !text.is_empty() {
            self.send(&FromWorker::Print(text), &[]);
        }
    }

    /// The error of a HAL call that needs the interface `key` the robot has not.
    fn missing(&self, key: &str, call: &str) -> PyErr {
        let name = self
            .lines
            .get()
            .into_iter()
            .flatten()
            .find(|(k, _, _)| k == key)
            .map(|(_, n, _)| n.as_str())
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

    fn has(&self, key: &str) -> bool {
        self.lines
            .get()
            .is_some_and(|l| l.iter().any(|(k, _, t)| k == key && *t))
    }

    /// Sets v (mm/s) and/or w (deg/s); a changed command is sent at once (on a
    /// per-command clock: at the pass's end, [`Worker::end_of_pass`]), as is
    /// any after the silence limit stopped the motors.
    fn set(&self, v: Option<f32>, w: Option<f32>) {
        let c = {
            let mut c = self.command.lock();
            c.0 = v.unwrap_or(c.0);
            c.1 = w.unwrap_or(c.1);
            *c
        };
        if self.per_command.load(Ordering::Relaxed) {
            return;
        }
        let mut sent = self.sent.lock();
        let silenced = self.board.header().silenced.load(Ordering::Acquire) != 0;
        if *sent != Some(c) || silenced {
            *sent = Some(c);
            self.send(
                &FromWorker::Command {
                    v: c.0,
                    w: c.1,
                    end_of_pass: false,
                },
                &[],
            );
        }
    }

    /// The forces a 4.x program set on `GUI.map` (`carx`, `obsx`, ...), for the
    /// panel to draw as `GUI.showForces` does.
    fn send_map_forces(&self) {
        let forces = Python::attach(|py| -> PyResult<Option<Vec<(f64, f64)>>> {
            runner(py)?.getattr("map_forces")?.call0()?.extract()
        });
        if let Ok(Some(f)) = forces
            && let [c, o, a] = f[..]
        {
            self.send(
                &FromWorker::Forces([[c.0, c.1], [o.0, o.1], [a.0, a.1]]),
                &[],
            );
        }
    }

    /// The end of a pass: on a per-command clock, the command goes out now.
    fn end_of_pass(&self) {
        if self.per_command.load(Ordering::Relaxed) {
            let (v, w) = *self.command.lock();
            self.send(
                &FromWorker::Command {
                    v,
                    w,
                    end_of_pass: true,
                },
                &[],
            );
        }
    }
}

/// Runs the worker if this process was started as one.
pub fn main_if_worker() -> Option<ExitCode> {
    std::env::var_os(WORKER_ENV)?;
    if std::env::args_os().nth(1).as_deref() != Some(super::process::WORKER_ARG.as_ref()) {
        return None;
    }
    // SAFETY: no other thread runs yet. The program's own subprocesses (a
    // jderobot it starts) are not workers.
    unsafe { std::env::remove_var(WORKER_ENV) };
    Some(match serve() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("python worker: {e}");
            ExitCode::FAILURE
        }
    })
}

/// The worker's life: set up, then load and run what jderobot asks, until
/// jderobot closes the socket (or ends: the lifeline).
fn serve() -> Result<(), String> {
    // SAFETY: descriptor 5 was handed to this process as the lifeline's end.
    let mut lifeline = unsafe { std::fs::File::from_raw_fd(LIFELINE_FD) };
    std::thread::Builder::new()
        .name("lifeline".into())
        .spawn(move || {
            let mut b = [0u8; 1];
            while matches!(lifeline.read(&mut b), Ok(n) if n > 0) {}
            // SAFETY: ends the process at once, as a lost jderobot must.
            unsafe { libc::_exit(0) };
        })
        .map_err(|e| e.to_string())?;
    let board = Board::open(BOARD_FD).map_err(|e| format!("the board: {e}"))?;
    // SAFETY: descriptor 4 was handed to this process as its socket.
    let socket = unsafe { UnixStream::from_raw_fd(SOCKET_FD) };
    let mut from_jderobot = socket.try_clone().map_err(|e| e.to_string())?;
    let _ = WORKER.set(Worker {
        board,
        to_jderobot: Mutex::new(socket),
        lines: Default::default(),
        per_command: AtomicBool::new(false),
        command: Default::default(),
        sent: Default::default(),
        clamped: Default::default(),
        next_tick: Default::default(),
        last_tick: Default::default(),
        printed: Default::default(),
    });
    interpreter()?;
    let mut program: Option<Program> = None;
    loop {
        let Some((msg, _)) =
            wire::receive::<ToWorker>(&mut from_jderobot).map_err(|e| e.to_string())?
        else {
            return Ok(());
        };
        match msg {
            ToWorker::Load {
                path,
                source,
                venv,
                per_command,
                lines,
                targets,
            } => {
                let w = worker();
                Python::attach(|py| -> PyResult<()> {
                    runner(py)?.getattr("set_targets")?.call1((targets,))?;
                    Ok(())
                })
                .map_err(|e| e.to_string())?;
                w.per_command.store(per_command, Ordering::Relaxed);
                let _ = w.lines.set(lines);
                let loaded = venv
                    .map_or(Ok(()), |v| add_venv(Path::new(&v)).map(|_| ()))
                    .map_err(|e| Failure {
                        line: 0,
                        summary: format!("venv: {e}"),
                        text: format!("venv: {e}"),
                    })
                    .and_then(|()| Program::compile(&path, &source));
                let reply = match loaded {
                    Ok(p) => {
                        let r = FromWorker::Loaded {
                            academy5: p.academy5,
                            has_loop: p.has_loop(),
                        };
                        program = Some(p);
                        r
                    }
                    Err(f) => FromWorker::Refused(f),
                };
                w.send(&reply, &[]);
            }
            ToWorker::Pass(which) => {
                let w = worker();
                let outcome = match &program {
                    Some(p) => p.run(which),
                    None => Outcome::Done,
                };
                w.flush();
                w.send_map_forces();
                if which == 1 || (which == 0 && program.as_ref().is_some_and(|p| !p.academy5)) {
                    w.end_of_pass();
                }
                w.send(&FromWorker::Outcome(outcome), &[]);
            }
        }
    }
}

/// Runs `f` for a HAL, GUI or Frequency call (it shows the program is alive).
fn hal<R>(f: impl FnOnce(&Worker) -> PyResult<R>) -> PyResult<R> {
    let w = worker();
    w.touch();
    f(w)
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

/// `HAL.setV` (`which` 0: m/s, forward) or `HAL.setW` (1: rad/s, positive
/// turns left): the speed in the motors' units (mm/s, deg/s), limited to what
/// the `motors` interface takes ([`MAX_MOTOR_V`], [`MAX_MOTOR_W`]; past it,
/// the limit, said once a run in the console), then commanded.
fn drive(which: usize, asked: f64) -> PyResult<()> {
    let (call, arg, unit, max, factor) = if which == 0 {
        ("setV", "v", "m/s", MAX_MOTOR_V as f64, 1000.0)
    } else {
        let per_rad = 180.0 / std::f64::consts::PI;
        ("setW", "w", "rad/s", MAX_MOTOR_W as f64, per_rad)
    };
    let asked = finite(call, arg, unit, asked)?;
    hal(|w| {
        if !w.has("motors") {
            return Err(w.missing("motors", call));
        }
        let units = asked * factor;
        let speed = if units.abs() <= max {
            units as f32
        } else {
            if !w.clamped[which].swap(true, Ordering::AcqRel) {
                w.print(&format!(
                    "-- HAL.{call}({asked}): past the motors' limit, {:.4} {unit}; clamped to \
                     it (the driver may limit it further to its robot's maximum; said once)\n",
                    max / factor
                ));
            }
            max.copysign(units) as f32
        };
        match which {
            0 => w.set(Some(speed), None),
            _ => w.set(None, Some(speed)),
        }
        Ok(())
    })
}

#[pymethods]
impl Hal {
    /// Forward speed, m/s.
    #[pyo3(name = "setV")]
    fn set_v(&self, v: f64) -> PyResult<()> {
        drive(0, v)
    }
    /// Turn speed, rad/s (positive turns left).
    #[pyo3(name = "setW")]
    fn set_w(&self, w: f64) -> PyResult<()> {
        drive(1, w)
    }
    #[pyo3(name = "getPose3d")]
    fn get_pose3d(&self) -> PyResult<Pose3d> {
        hal(|w| {
            if !w.has("encoders") {
                return Err(w.missing("encoders", "getPose3d"));
            }
            let (p, time) =
                values::encoders(&w.board).unwrap_or((Default::default(), std::time::UNIX_EPOCH));
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
                time_stamp: unix_seconds(time),
            })
        })
    }
    #[pyo3(name = "getLaserData")]
    fn get_laser_data(&self, py: Python<'_>) -> PyResult<LaserData> {
        let (values, (min_angle, max_angle, min_range, max_range), _) = latest_scan()?;
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
        hal(|w| {
            if !w.has("bumpers") {
                return Err(w.missing("bumpers", "getBumperData"));
            }
            let (state, bumper) = bumper_side(&values::bumpers(&w.board).unwrap_or_default());
            Ok(BumperData { state, bumper })
        })
    }
    /// The camera's image: a numpy uint8 array H x W x 3, BGR (one copy of the
    /// bytes, from the board into the array's buffer).
    #[pyo3(name = "getImage")]
    fn get_image<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let image = hal(|w| {
            if !w.has("camera") {
                return Err(w.missing("camera", "getImage"));
            }
            Ok(values::image(&w.board, |width, height, bgr| {
                (PyByteArray::new(py, bgr), height as usize, width as usize)
            }))
        })?;
        let (data, height, width) = image.unwrap_or_else(|| (PyByteArray::new(py, &[]), 0, 0));
        runner(py)?
            .getattr("image_array")?
            .call1((data, height, width, 3usize))
    }
    /// The run's time: the simulator's when it keeps its own (it exports
    /// `run.clock` when it does not run in real time), else the wall clock.
    #[pyo3(name = "getSimTime")]
    fn get_sim_time(&self) -> PyResult<SimTimeData> {
        let t = hal(|w| {
            let ns = w.board.header().sim_clock.load(Ordering::Acquire);
            Ok(if ns == 0 {
                std::time::SystemTime::now()
            } else {
                values::time(ns)
            })
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
    let (values, (min_angle, max_angle, min_range, max_range), time) = latest_scan()?;
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

fn latest_scan() -> PyResult<Scan> {
    hal(|w| {
        if !w.has("laser") {
            return Err(w.missing("laser", "getLaserData"));
        }
        // No scan yet: the interface's own first value, as before the worker.
        let (laser, time) =
            values::laser(&w.board).unwrap_or_else(|| (Laser::default(), std::time::UNIX_EPOCH));
        let values = laser.readings.iter().map(|&r| r as f64 / 1000.0).collect();
        Ok((values, laser_geometry(&laser), time))
    })
}

/// The Academy 5 `HAL.getBumperData()`: `state` 1 while touching; `bumper` 0
/// right, 1 centre, 2 left (1 when nothing touches), as its bumper interface.
#[pyfunction]
#[pyo3(name = "getBumperData")]
fn bumper_data_5(py: Python<'_>) -> PyResult<BumperData> {
    let _ = py;
    let b = Hal.get_bumper_data()?;
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
/// no drift; a pass longer than a period starts the count again), and sends the
/// command on a per-command clock (a lock-stepped simulator steps once per
/// tick). `hz` is the Academy's `ideal_cycle`, 50 by default.
#[pyfunction]
#[pyo3(name = "tick", signature = (ideal_cycle = None, *, hz = None))]
fn tick(py: Python<'_>, ideal_cycle: Option<f64>, hz: Option<f64>) -> PyResult<()> {
    let hz = hz.or(ideal_cycle).unwrap_or(TICK_HZ);
    if !hz.is_finite() || hz <= 0.0 {
        return Err(PyValueError::new_err(format!(
            "Frequency.tick: the frequency must be a positive number of Hz, not {hz}"
        )));
    }
    let w = worker();
    w.touch();
    w.end_of_pass();
    let period = Duration::from_secs_f64(1.0 / hz);
    let now = Instant::now();
    let until = {
        let mut next = w.next_tick.lock();
        let until = match *next {
            Some(t) if now < t + period => t,
            // The first tick, or a pass a period late: from now.
            _ => now,
        };
        *next = Some(until + period);
        until
    };
    wait_until(py, until);
    // The loop's rate, smoothed over about ten passes.
    let h = w.board.header();
    h.ticks.fetch_add(1, Ordering::AcqRel);
    let now = Instant::now();
    if let Some(last) = w.last_tick.lock().replace(now) {
        let dt = now.duration_since(last).as_secs_f64();
        if dt > 0.0 {
            let old = f64::from_bits(h.tick_rate.load(Ordering::Acquire));
            let rate = if old == 0.0 {
                1.0 / dt
            } else {
                0.9 * old + 0.1 / dt
            };
            h.tick_rate.store(rate.to_bits(), Ordering::Release);
        }
    }
    Ok(())
}

/// The Academy's default loop frequency, Hz (`Frequency.tick()`).
pub const TICK_HZ: f64 = 50.0;

/// Waits until `until` with the GIL released, marked on the board as alive
/// (sleeping).
fn wait_until(py: Python<'_>, until: Instant) {
    let h = worker().board.header();
    h.sleeping.store(1, Ordering::Release);
    py.detach(|| std::thread::sleep(until.saturating_duration_since(Instant::now())));
    h.sleeping.store(0, Ordering::Release);
    worker().touch();
}

// ---------------------------------------------------------------- GUI

/// What the GUI has, for the error of a call it has not.
const GUI_CALLS: &str = "showImage, showForces, showLocalTarget, map, getNextTarget";

/// `GUI.showForces(car, obstacle, average)`: the obstacle-avoidance exercise's
/// three force vectors, [x, y] each in the robot's frame (x ahead, y left), drawn
/// in the panel.
#[pyfunction]
#[pyo3(name = "showForces")]
fn show_forces(
    py: Python<'_>,
    car: Bound<'_, PyAny>,
    obstacle: Bound<'_, PyAny>,
    average: Bound<'_, PyAny>,
) -> PyResult<()> {
    let r = runner(py)?;
    let v = |o: Bound<'_, PyAny>| -> PyResult<[f64; 2]> {
        let (x, y): (f64, f64) = r.getattr("vec2")?.call1((o, "GUI.showForces"))?.extract()?;
        Ok([x, y])
    };
    let forces = [v(car)?, v(obstacle)?, v(average)?];
    hal(|w| {
        w.send(&FromWorker::Forces(forces), &[]);
        Ok(())
    })
}

/// `GUI.showLocalTarget([x, y])` (or `(x, y)`): the target in the robot's frame,
/// m, drawn in the panel.
#[pyfunction]
#[pyo3(name = "showLocalTarget", signature = (x, y = None))]
fn show_local_target(py: Python<'_>, x: Bound<'_, PyAny>, y: Option<f64>) -> PyResult<()> {
    let at = match y {
        Some(y) => [x.extract::<f64>()?, y],
        None => {
            let (x, y): (f64, f64) = runner(py)?
                .getattr("vec2")?
                .call1((x, "GUI.showLocalTarget"))?
                .extract()?;
            [x, y]
        }
    };
    hal(|w| {
        w.send(&FromWorker::LocalTarget(at), &[]);
        Ok(())
    })
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
        let grey;
        let bgr = if ch == 3 {
            raw
        } else {
            grey = raw.iter().flat_map(|&g| [g, g, g]).collect::<Vec<u8>>();
            &grey
        };
        hal(|worker| {
            worker.send(
                &FromWorker::Image {
                    width: w as u32,
                    height: h as u32,
                },
                bgr,
            );
            Ok(())
        })
    }
    /// The 4.x `GUI.GUI` object has the module's other calls too (`GUI.map`,
    /// `GUI.showForces`, ...).
    fn __getattr__(&self, py: Python<'_>, name: &str) -> PyResult<Py<PyAny>> {
        if ["map", "showForces", "showLocalTarget", "getNextTarget"].contains(&name) {
            return Ok(py.import("GUI")?.getattr(name)?.unbind());
        }
        Err(not_here("GUI", name, GUI_CALLS))
    }
}

/// `sys.stdout` and `sys.stderr`: a program's output goes to its console.
#[pyclass(frozen)]
struct Output;

#[pymethods]
impl Output {
    fn write(&self, text: &str) -> usize {
        worker().print(text);
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

/// `time.sleep`, replaced so that a sleeping program counts as alive (its
/// command held past the silence limit).
#[pyfunction]
fn sleep(py: Python<'_>, seconds: f64) -> PyResult<()> {
    if !seconds.is_finite() || seconds < 0.0 {
        return Err(PyValueError::new_err(
            "sleep length must be a non-negative number",
        ));
    }
    wait_until(
        py,
        Instant::now() + Duration::from_secs_f64(seconds.min(1e6)),
    );
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
                    gui.add_function(wrap_pyfunction!(show_forces, &gui)?)?;
                    gui.add_function(wrap_pyfunction!(show_local_target, &gui)?)?;
                    let map = r.getattr("MAP")?;
                    gui.add("getNextTarget", map.getattr("getNextTarget")?)?;
                    gui.add("map", map)?;
                    gui.add("GUI", &gui_object)?;
                    gui.add_function(wrap_pyfunction!(module_getattr, &gui)?)?;
                    modules.set_item(name, gui)?;
                }
                let frequency = PyModule::new(py, "Frequency")?;
                frequency.add_function(wrap_pyfunction!(tick, &frequency)?)?;
                frequency.add_function(wrap_pyfunction!(module_getattr, &frequency)?)?;
                modules.set_item("Frequency", frequency)?;
                // A crash's report (a segfault in C code) goes to the console.
                py.import("faulthandler")?
                    .call_method1("enable", (sys.getattr("__stderr__")?,))?;
                sys.setattr("stdout", Bound::new(py, Output)?)?;
                sys.setattr("stderr", Bound::new(py, Output)?)?;
                sys.setattr("argv", vec![String::from("jderobot")])?;
                py.import("time")?.setattr("sleep", r.getattr("sleep")?)?;
                r.getattr("install_rospy")?.call0()?;
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
    /// The Academy 5 shape: `init` is the whole program, with its own loop.
    pub academy5: bool,
    globals: Py<PyDict>,
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
    /// code (2).
    pub fn run(&self, which: u8) -> Outcome {
        let code = match which {
            0 => Some(&self.init),
            1 => self.loop_body.as_ref(),
            _ => self.after.as_ref(),
        };
        let Some(code) = code else {
            return Outcome::Done;
        };
        Python::attach(|py| {
            let g = self.globals.bind(py);
            let result = py
                .import("builtins")
                .and_then(|b| b.getattr("exec"))
                .and_then(|exec| exec.call1((code.bind(py), g)));
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
