//! python: runs a student's Python program, written against JdeRobot's Robotics
//! Academy API in either of its shapes, as a schema, on whatever driver provides
//! the robot. Each program runs in a worker process of its own (the binary
//! itself, started again: still one file to install), so nothing it does can
//! take jderobot or another schema down, and two programs never share a GIL.
//!
//! Conf (`file` is required; the other lines show their defaults):
//! ```text
//! schema python
//! file exercises/vacuum.py      # the program, relative to the conf file
//! cycle 50                      # ms: the 4.x loop's period (the Academy's "brain frequency")
//! venv none                     # a virtual environment's directory (default: $VIRTUAL_ENV)
//! watch on                      # reload the program when its file changes
//! memory 4096                   # MiB: the worker's address space (0: no limit)
//! motors motors                 # the interfaces HAL reads and writes (`none`: without)
//! encoders encoders
//! laser laser
//! bumpers bumpers
//! camera colorA
//! end_schema
//! ```
//!
//! **The program's shapes**, seen from its imports. 4.x (`from HAL import HAL`,
//! `from GUI import GUI`): the code before the first top-level `while True:` runs
//! once when the schema runs; the loop's body is one pass, run every `cycle` ms by
//! the runtime's pacer; a `break` ends the loop (the code after it runs once); a
//! program with no such loop runs once. Academy 5 (`import HAL`, `import GUI` /
//! `import WebGUI`, `import Frequency`): the whole program runs in a thread of its
//! own, its own loop paced by `Frequency.tick(hz=50)`; the schema's iteration
//! watches it. Line numbers in tracebacks are the program's own.
//!
//! **HAL** (the Academy's wheeled-robot API; units converted from the interfaces'):
//! `setV(v)` m/s and `setW(w)` rad/s (positive turns left) write `motors` (mm/s,
//! deg/s) when called (past the interface's range: clamped, said once) and the
//! command holds while the program lives (the keeper publishes it again every
//! [`REFRESH`]); it is zeroed when the program ends, fails, is stopped or goes
//! silent for [`SILENCE`]. `getPose3d()` `.x .y` m, `.yaw` rad in (−π, π] (from
//! `encoders`); `getLaserData()` `.values` m (from `laser`, its own geometry);
//! `getBumperData()` `.state`, `.bumper` (from `bumpers`); `getImage()` a numpy
//! uint8 array H×W×3 BGR (from `camera`; one copy of the bytes); `getSimTime()`
//! the run's clock. The Academy 5 module functions follow the Academy 5's laser
//! angles and bumper sides. A call that is not here raises an error naming it.
//! **GUI** / **WebGUI**: `showImage(img)` shows a grey or BGR array in the panel.
//! `print` goes to the panel's console and to the shell (`python> ...`, bounded: a
//! flood is counted, not waited for).
//!
//! **Faults never take the suite down.** A syntax error stops the load (and
//! `jderobot check`) with `FILE:LINE: message`; an exception prints its traceback,
//! marks the line in the panel, stops this schema and zeroes its motors. A
//! program whose process ends (`os._exit`, a segfault, the memory limit's
//! killer, `kill -9`) stops this schema with `the program's process ended (HOW)`
//! and its motors zeroed at once; the other schemas run on. Stopping ends the
//! worker (`SIGKILL` to its process group: its threads and children too) and
//! zeroes the motors within a few ms, whatever the program is doing; each run
//! starts a fresh worker. Saving the file reloads it (motors zeroed in
//! between), as do the panel's Reload button and the shell's `reload python`.
//! See docs/python.md; [`worker`] and [`process`] say how the two processes
//! talk.
//!
//! Interfaces: writes `motors` (mm/s, deg/s); reads `encoders` (mm, rad), `laser`
//! (mm), `bumpers`, `colorA` (BGR) — each optional (a HAL call without it raises a
//! Python error naming the conf line). System: Debian `python3-dev` to build,
//! `python3-numpy` for `getImage`/`showImage`, `python3-opencv` for `cv2`.

pub mod board;
#[cfg(feature = "gui")]
pub mod highlight;
#[cfg(feature = "gui")]
mod panel;
pub mod process;
mod shared;
mod wire;
pub mod worker;

use parking_lot::Mutex;
use std::{
    path::PathBuf,
    sync::{
        Arc, Weak,
        atomic::{AtomicBool, AtomicI32, Ordering},
    },
    time::{Duration, Instant, SystemTime},
};

use crate::{
    conf::{
        ComponentConf,
        settings::{self, CYCLE, Setting, int, on_off, word},
    },
    interfaces::{Bumpers, Encoders, Image, Laser, Motors, Watch},
    runtime::{Context, RunClock, Runtime, Schema, State},
};

use board::Board;
pub use process::set_worker_exe;
use process::{Event, WorkerProcess};
use shared::Robot;
pub use shared::{CONSOLE_LINES, REFRESH, Shared, shared};
use wire::{Failure, Outcome, ToWorker};
pub use worker::{TICK_HZ, main_if_worker};

crate::declare_lines! {
    /// python's lines, declared once (`jderobot help python`).
    struct Lines {
        file: String = Setting::new(
            "file",
            "the program (Python, the Robotics Academy's HAL and GUI), relative to the conf file",
            &[settings::path("FILE")],
        )
        .required(),
        cycle: u64 = CYCLE.default("50"),
        venv: String = Setting::new(
            "venv",
            "a virtual environment whose packages the program may import (none: only $VIRTUAL_ENV's)",
            &[word("DIR|none")],
        )
        .default("none"),
        watch: bool = Setting::new(
            "watch",
            "reload the program when its file changes",
            &[on_off("SWITCH")],
        )
        .default("on"),
        memory: u64 = Setting::new(
            "memory",
            "the program's memory limit (its worker process's address space; past it Python raises MemoryError), MiB; 0: none",
            &[int("MIB", "MiB", 0, 1 << 20)],
        )
        .default("4096"),
        motors: String = settings::uses("motors", "the base HAL.setV/setW drive (none: none)"),
        encoders: String = settings::uses("encoders", "HAL.getPose3d's odometry (none: none)"),
        laser: String = settings::uses("laser", "HAL.getLaserData's scan (none: none)"),
        bumpers: String = settings::uses("bumpers", "HAL.getBumperData's bumpers (none: none)"),
        camera: String = settings::uses("camera", "HAL.getImage's camera (none: none)").default("colorA"),
    }
}

/// Which piece of the program runs next.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Phase {
    Init,
    /// 4.x: the loop body runs each cycle; Academy 5: the program runs.
    Loop,
    Finished,
}

/// What the schema shares with its keeper: the running worker.
#[derive(Default)]
struct Live {
    /// The running worker's board (None between runs).
    board: Mutex<Option<Arc<Board>>>,
    /// The clocks of the sensor values written on it, in `board::Sensor` order.
    fed: Mutex<[u64; 4]>,
    /// The running worker's process id (0: none).
    pid: AtomicI32,
    /// Set when the keeper ended the worker because the schema stops.
    killed: AtomicBool,
}

impl Live {
    /// Writes the sensors' new values on the worker's board.
    fn feed(&self, robot: &Robot) {
        let board = self.board.lock().clone();
        if let Some(b) = board {
            robot.feed(&b, &mut self.fed.lock());
        }
    }
}

/// What a program's worker said when it loaded the program.
#[derive(Clone, Copy)]
struct Loaded {
    academy5: bool,
    has_loop: bool,
}

/// The schema.
pub struct PythonSchema {
    shared: Arc<Shared>,
    robot: Arc<Robot>,
    path: PathBuf,
    venv: Option<PathBuf>,
    /// The worker's memory limit, bytes.
    memory: Option<u64>,
    phase: Phase,
    cycle: Duration,
    watch: bool,
    mtime: Option<SystemTime>,
    checked: Instant,
    /// The sensors resumed while running.
    children: Vec<String>,
    live: Arc<Live>,
    keeper: Option<Keeper>,
    /// The running program's worker and what it loaded.
    worker: Option<(WorkerProcess, Loaded)>,
    #[cfg(feature = "gui")]
    panel: Option<Box<dyn crate::runtime::Panel>>,
}

/// How often the file's modification time is looked at.
const WATCH_EVERY: Duration = Duration::from_millis(250);
/// How often the keeper looks for a stop and keeps the command fresh, at the
/// latest (it also wakes when a sensor publishes).
const KEEPER_PERIOD: Duration = Duration::from_millis(5);
/// How long a living program may go without showing it is alive (a HAL, GUI or
/// Frequency call, the end of a 4.x pass; a `time.sleep` or `Frequency.tick`
/// counts as alive while it lasts) before its motors are stopped: a program
/// stuck computing, or waiting on something else, does not drive on blind.
pub const SILENCE: Duration = Duration::from_secs(5);
/// How long a worker may take to start and compile the program.
const LOAD_WAIT: Duration = Duration::from_secs(30);

fn mtime(p: &std::path::Path) -> Option<SystemTime> {
    std::fs::metadata(p).and_then(|m| m.modified()).ok()
}

impl PythonSchema {
    /// Reads the program and starts a worker that compiles it; a failure is
    /// `FILE:LINE: message`.
    fn start_worker(&mut self) -> Result<(), String> {
        self.end_worker();
        self.mtime = mtime(&self.path);
        let source = std::fs::read_to_string(&self.path)
            .map_err(|e| format!("{}: cannot read the program: {e}", self.path.display()))?;
        *self.shared.source.lock() = Arc::new(source.clone());
        *self.shared.file.lock() = self.path.clone();
        let (worker, loaded) = load(
            &self.shared,
            &self.robot,
            &self.path,
            source,
            self.venv.as_ref(),
            self.memory,
        )?;
        self.shared
            .academy5
            .store(loaded.academy5, Ordering::Release);
        *self.shared.error.lock() = None;
        *self.live.board.lock() = Some(worker.board.clone());
        *self.live.fed.lock() = [0; 4];
        self.live.killed.store(false, Ordering::Release);
        self.live.pid.store(worker.pid(), Ordering::Release);
        self.worker = Some((worker, loaded));
        Ok(())
    }

    /// Ends the running worker, if any (its reader zeroes the motors if it drove).
    fn end_worker(&mut self) {
        self.live.pid.store(0, Ordering::Release);
        if let Some((w, _)) = self.worker.take() {
            w.kill();
        }
        *self.live.board.lock() = None;
        self.shared.in_python.store(false, Ordering::Release);
    }

    /// Reloads when the file changed or a reload was asked for: motors zeroed, the
    /// program compiled again and started from its init code.
    fn reload_if_asked(&mut self) -> Result<(), String> {
        let asked = self.shared.reload.load(Ordering::Acquire);
        let changed = self.watch && self.checked.elapsed() >= WATCH_EVERY && {
            self.checked = Instant::now();
            mtime(&self.path) != self.mtime
        };
        if !asked && !changed {
            return Ok(());
        }
        self.shared.reload.store(false, Ordering::Release);
        self.robot.release();
        if let Err(e) = self.start_worker() {
            self.set_phase(Phase::Finished);
            return Err(e);
        }
        self.set_phase(Phase::Init);
        self.shared.clear_console();
        self.shared.print(&format!(
            "-- reloaded {}\n",
            crate::files::shorten(&self.path.display().to_string())
        ));
        Ok(())
    }

    fn set_phase(&mut self, p: Phase) {
        self.phase = p;
        let academy5 = self.worker.as_ref().is_some_and(|(_, l)| l.academy5);
        *self.shared.phase.lock() = match p {
            Phase::Init => "init",
            Phase::Loop if academy5 => "running",
            Phase::Loop => "loop",
            Phase::Finished => "finished",
        };
    }

    /// Waits (at most 2 s) for the first value of the sensors a program reads at
    /// once, so its init code never sees an empty scan; then writes them on the
    /// worker's board.
    fn wait_for_sensors(&self) {
        let t = Instant::now();
        let have = |r: &Robot| r.sensors().iter().all(|s| s.clock() > 0);
        let mut nudged = Instant::now();
        while !have(&self.robot)
            && t.elapsed() < Duration::from_secs(2)
            && !self.shared.reload.load(Ordering::Acquire)
        {
            // A (zero) command lets a lock-stepped simulator step to its sensors.
            if nudged.elapsed() >= Duration::from_millis(20) {
                self.robot.zero();
                nudged = Instant::now();
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        self.live.feed(&self.robot);
    }

    /// Sends a piece of the program to the worker (0 init, 1 a pass, 2 after the
    /// loop).
    fn send_pass(&mut self, which: u8) -> Result<(), String> {
        let Some((w, _)) = self.worker.as_mut() else {
            return Err("no program is loaded".into());
        };
        self.shared.in_python.store(true, Ordering::Release);
        w.send(&ToWorker::Pass(which))
            .map_err(|e| format!("the program's process does not listen: {e}"))
    }

    /// What the worker answers: the outcome of a pass, or how its process ended
    /// (None: nothing yet within `wait`).
    fn answer(&mut self, wait: Option<Duration>) -> Option<Result<Outcome, String>> {
        let (w, _) = self.worker.as_ref()?;
        loop {
            let event = match wait {
                Some(d) => Some(w.next(d)?),
                None => w.next(Duration::from_millis(50)),
            };
            match event {
                Some(Event::Outcome(o)) => return Some(Ok(o)),
                Some(Event::Ended(how)) => return Some(Err(how)),
                Some(other) => tracing::debug!("python: unexpected {other:?}"),
                None => {}
            }
        }
    }

    /// What a piece of the program's outcome means for the schema.
    fn conclude(&mut self, answer: Result<Outcome, String>, next: Phase) -> anyhow::Result<()> {
        self.shared.in_python.store(false, Ordering::Release);
        let outcome = match answer {
            Ok(o) => o,
            Err(how) => return self.ended(how),
        };
        match outcome {
            Outcome::Done | Outcome::Broke => {
                if next == Phase::Finished {
                    if self.phase != Phase::Finished {
                        self.robot.release();
                        self.shared
                            .print("-- the program has ended; the motors are stopped\n");
                        self.end_worker();
                    }
                } else {
                    self.shared.touch();
                }
                self.set_phase(next);
                Ok(())
            }
            Outcome::Exited(code) => {
                self.robot.release();
                self.shared.print(&format!(
                    "-- the program has ended (sys.exit({code})); the motors are stopped\n"
                ));
                self.end_worker();
                self.set_phase(Phase::Finished);
                Ok(())
            }
            Outcome::Failed(f) => self.failed(f),
        }
    }

    fn failed(&mut self, f: Failure) -> anyhow::Result<()> {
        self.robot.release();
        self.shared.print(&f.text);
        if !f.text.ends_with('\n') {
            self.shared.print("\n");
        }
        self.shared.flush();
        *self.shared.error.lock() = Some((f.line, f.summary.clone()));
        self.end_worker();
        self.set_phase(Phase::Finished);
        Err(anyhow::anyhow!(f.summary))
    }

    /// The worker's process ended: a stop's doing, or the program's (then the
    /// schema stops, saying how).
    fn ended(&mut self, how: String) -> anyhow::Result<()> {
        self.robot.release();
        let stopped = self.live.killed.swap(false, Ordering::AcqRel);
        self.end_worker();
        if stopped {
            self.set_phase(Phase::Init);
            return Ok(());
        }
        let what = format!("the program's process ended ({how})");
        self.shared
            .print(&format!("-- {what}; the motors are stopped\n"));
        *self.shared.error.lock() = Some((0, what.clone()));
        self.set_phase(Phase::Finished);
        Err(anyhow::anyhow!(what))
    }

    /// One iteration of a program in the 4.x shape: its init, or one pass of its
    /// loop (and what follows the loop after a `break`).
    fn run_4x(&mut self, has_loop: bool) -> anyhow::Result<()> {
        let which = match self.phase {
            Phase::Init => 0,
            Phase::Loop => 1,
            Phase::Finished => return Ok(()),
        };
        self.send_pass(which).map_err(anyhow::Error::msg)?;
        let Some(mut answer) = self.answer(None) else {
            return Ok(());
        };
        let mut next = match (which, &answer) {
            (0, Ok(Outcome::Done)) if has_loop => Phase::Loop,
            (1, Ok(Outcome::Done)) => Phase::Loop,
            _ => Phase::Finished,
        };
        if which == 1 && matches!(answer, Ok(Outcome::Broke)) {
            self.send_pass(2).map_err(anyhow::Error::msg)?;
            answer = self.answer(None).unwrap_or(Ok(Outcome::Done));
            next = Phase::Finished;
        }
        self.conclude(answer, next)
    }

    /// One iteration of a program in the Academy 5 shape: start it, or see
    /// whether it ended.
    fn run_5(&mut self) -> anyhow::Result<()> {
        match self.phase {
            Phase::Init => {
                self.send_pass(0).map_err(anyhow::Error::msg)?;
                self.set_phase(Phase::Loop);
                Ok(())
            }
            Phase::Loop => match self.answer(Some(Duration::ZERO)) {
                Some(answer) => self.conclude(answer, Phase::Finished),
                None => Ok(()),
            },
            Phase::Finished => Ok(()),
        }
    }
}

/// Starts a worker and has it compile `source`: the worker and what it loaded,
/// or the failure (`FILE:LINE: message`; also kept for the panel).
fn load(
    shared: &Arc<Shared>,
    robot: &Arc<Robot>,
    path: &std::path::Path,
    source: String,
    venv: Option<&PathBuf>,
    memory: Option<u64>,
) -> Result<(WorkerProcess, Loaded), String> {
    let mut worker = WorkerProcess::start(shared.clone(), robot.clone(), memory)
        .map_err(|e| format!("{}: {e}", shared.name))?;
    worker
        .send(&ToWorker::Load {
            path: path.display().to_string(),
            source,
            venv: venv.map(|v| v.display().to_string()),
            per_command: robot.per_command(),
            lines: robot.lines(),
            targets: robot.targets(),
        })
        .map_err(|e| {
            format!(
                "{}: the program's process does not listen: {e}",
                shared.name
            )
        })?;
    let since = Instant::now();
    loop {
        let left = LOAD_WAIT.saturating_sub(since.elapsed());
        match worker.next(left) {
            Some(Event::Loaded { academy5, has_loop }) => {
                return Ok((worker, Loaded { academy5, has_loop }));
            }
            Some(Event::Refused(f)) => {
                *shared.error.lock() = Some((f.line, f.summary.clone()));
                return Err(f.summary);
            }
            Some(Event::Ended(how)) => {
                return Err(format!(
                    "{}: the python worker ended before it loaded the program ({how}); \
                     its output is in the console",
                    shared.name
                ));
            }
            Some(_) => {}
            None => {
                return Err(format!(
                    "{}: the python worker did not load the program within {} s",
                    shared.name,
                    LOAD_WAIT.as_secs()
                ));
            }
        }
    }
}

impl Schema for PythonSchema {
    fn cycle(&self) -> Duration {
        self.cycle
    }

    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        ctx.run_children(&self.children, None)?;
        self.shared.clear_console();
        // Each run starts the program afresh (the file as it is now), in a
        // fresh worker.
        self.start_worker().map_err(anyhow::Error::msg)?;
        self.set_phase(Phase::Init);
        self.robot.zero();
        self.wait_for_sensors();
        Ok(())
    }

    fn iteration(&mut self, ctx: &Context) -> anyhow::Result<()> {
        if self.keeper.is_none() {
            self.keeper = Some(Keeper::start(
                ctx.runtime(),
                self.shared.clone(),
                self.robot.clone(),
                self.live.clone(),
            ));
        }
        self.reload_if_asked().map_err(anyhow::Error::msg)?;
        let Some(loaded) = self.worker.as_ref().map(|(_, l)| *l) else {
            return Ok(());
        };
        if self.phase == Phase::Init {
            self.shared.new_run();
            self.robot.start_holding();
        }
        if loaded.academy5 {
            self.run_5()
        } else {
            self.run_4x(loaded.has_loop)
        }
    }

    fn on_stop(&mut self, _ctx: &Context) {
        self.robot.release();
        self.end_worker();
        self.robot.release();
        self.set_phase(Phase::Init);
    }

    fn terminate(&mut self) {
        self.robot.release();
        self.end_worker();
        if let Some(k) = self.keeper.take() {
            k.stop();
        }
    }

    #[cfg(feature = "gui")]
    fn panel(&mut self) -> Option<Box<dyn crate::runtime::Panel>> {
        self.panel.take()
    }
}

/// A thread that looks after a running program from jderobot's side: it writes
/// the sensors' new values on the worker's board as they are published; keeps
/// the program's command fresh while it lives ([`Robot::refresh`]) and stops
/// the motors when it goes silent past [`SILENCE`]; and when the schema is
/// stopped (or asked to reload) while the program runs, zeroes the motors and
/// ends the worker at once.
struct Keeper {
    alive: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Keeper {
    fn start(rt: &Arc<Runtime>, shared: Arc<Shared>, robot: Arc<Robot>, live: Arc<Live>) -> Keeper {
        let alive = Arc::new(AtomicBool::new(true));
        let a = alive.clone();
        let rt: Weak<Runtime> = Arc::downgrade(rt);
        let thread = std::thread::Builder::new()
            .name(format!("{}-keeper", shared.name))
            .spawn(move || {
                let watch = Watch::for_current_thread();
                for s in robot.sensors() {
                    s.watch(watch.clone());
                }
                let mut calls = 0;
                let mut clock: Option<Arc<RunClock>> = None;
                while a.load(Ordering::Acquire) {
                    watch.wait(KEEPER_PERIOD);
                    let Some(rt) = rt.upgrade() else { break };
                    live.feed(&robot);
                    let board = live.board.lock().clone();
                    if let Some(b) = &board {
                        let h = b.header();
                        let now = h.calls.load(Ordering::Acquire);
                        if now != calls {
                            calls = now;
                            shared.touch();
                        }
                        shared
                            .ticks
                            .store(h.ticks.load(Ordering::Acquire), Ordering::Release);
                        shared
                            .tick_rate
                            .store(h.tick_rate.load(Ordering::Acquire), Ordering::Release);
                        if clock.is_none() {
                            clock = RunClock::import(&rt.names);
                        }
                        if let Some(t) = clock.as_ref().and_then(|c| c.now()) {
                            let ns = t
                                .duration_since(std::time::UNIX_EPOCH)
                                .map_or(0, |d| d.as_nanos() as u64);
                            h.sim_clock.store(ns, Ordering::Release);
                        }
                        if robot.hold.load(Ordering::Acquire) {
                            keep(&shared, &robot, b);
                        }
                    }
                    let pid = live.pid.load(Ordering::Acquire);
                    if pid == 0 || !shared.in_python.load(Ordering::Acquire) {
                        continue;
                    }
                    let stopped = rt
                        .schema_status(&shared.name)
                        .is_none_or(|s| s.state == State::Slept);
                    if stopped || shared.reload.load(Ordering::Acquire) {
                        robot.release();
                        if !live.killed.swap(true, Ordering::AcqRel) {
                            process::kill_group(pid);
                        }
                    }
                }
                for s in robot.sensors() {
                    s.unwatch(watch.as_ref());
                }
            })
            .ok();
        Keeper { alive, thread }
    }

    fn stop(mut self) {
        self.alive.store(false, Ordering::Release);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

/// The keeper's care of a living program's command: fresh while it shows it
/// is alive, stopped (once, said in the console) when it goes silent.
fn keep(shared: &Shared, robot: &Robot, board: &Board) {
    let h = board.header();
    let sleeping = h.sleeping.load(Ordering::Acquire) != 0;
    let silent = !sleeping && shared.silent_for() > SILENCE;
    if !silent {
        robot.refresh();
    } else if h.silenced.swap(1, Ordering::AcqRel) == 0 {
        robot.zero();
        shared.print(&format!(
            "-- no HAL call for {} s: the motors are stopped (the next setV/setW drives again)\n",
            SILENCE.as_secs()
        ));
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let lines: Lines = conf.read()?;
    let file_line = conf.line("file").expect("file is required");
    let path = file_line.existing_file(0, "the program")?;
    let _ = &lines.file;
    let venv = if lines.venv != "none" {
        let venv_line = conf.line("venv").expect("a venv line gave the value");
        let venv = venv_line.path(0, "the virtual environment")?;
        if !venv.is_dir() {
            return Err(venv_line
                .error(format!(
                    "venv: `{}` is not a directory (make one with `python3 -m venv {}`)",
                    venv.display(),
                    venv.display()
                ))
                .into());
        }
        Some(venv)
    } else {
        None
    };
    let ifs = &rt.interfaces;
    let pick = |n: &str| (n != "none" && ifs.contains(n)).then(|| n.to_string());
    let motors = pick(&lines.motors)
        .map(|n| ifs.get::<Motors>(&n))
        .transpose()?;
    let encoders = pick(&lines.encoders)
        .map(|n| ifs.get::<Encoders>(&n))
        .transpose()?;
    let laser = pick(&lines.laser)
        .map(|n| ifs.get::<Laser>(&n))
        .transpose()?;
    let bumpers = pick(&lines.bumpers)
        .map(|n| ifs.get::<Bumpers>(&n))
        .transpose()?;
    let camera = pick(&lines.camera)
        .map(|n| ifs.get::<Image>(&n))
        .transpose()?;
    let mut children = Vec::new();
    for n in [&lines.encoders, &lines.laser, &lines.bumpers, &lines.camera] {
        if let Some(n) = pick(n) {
            children.push(n);
        }
    }
    let robot = Arc::new(Robot {
        motors,
        encoders,
        laser,
        bumpers,
        camera,
        names: vec![
            ("motors", lines.motors.clone()),
            ("encoders", lines.encoders.clone()),
            ("laser", lines.laser.clone()),
            ("bumpers", lines.bumpers.clone()),
            ("camera", lines.camera.clone()),
        ],
        command: Default::default(),
        hold: AtomicBool::new(false),
        runtime: Arc::downgrade(&rt.arc()),
        per_command: Default::default(),
    });
    let shared = shared(rt, &conf.name);
    if let Ok(d) = crate::world::export_drawings(&rt.names) {
        shared.draw_into(d);
    }
    // A re-init (the shell's `init`, `reload`) replaces a running program: ask the
    // old one to give way (its keeper ends it); the new one starts afresh.
    if shared.loads.fetch_add(1, Ordering::AcqRel) > 0 {
        shared.reload.store(true, Ordering::Release);
    }
    let mut s = PythonSchema {
        shared: shared.clone(),
        robot,
        path,
        venv,
        memory: (lines.memory > 0).then_some(lines.memory << 20),
        phase: Phase::Init,
        cycle: Duration::from_millis(lines.cycle),
        watch: lines.watch,
        mtime: None,
        checked: Instant::now(),
        children,
        live: Default::default(),
        keeper: None,
        worker: None,
        #[cfg(feature = "gui")]
        panel: None,
    };
    // A syntax error stops the load (and `jderobot check`): FILE:LINE: message.
    // The worker that compiled it ends here; each run starts its own.
    s.start_worker().map_err(|e| {
        if let (Some(v), true) = (conf.line("venv"), e.starts_with("venv:")) {
            anyhow::Error::from(v.error(e))
        } else {
            anyhow::Error::msg(e)
        }
    })?;
    s.end_worker();
    #[cfg(feature = "gui")]
    {
        s.panel = Some(Box::new(panel::PythonPanel::new(shared)));
    }
    Ok(Box::new(s))
}

crate::register_schema!(
    "python",
    "runs a Python program written against the Robotics Academy's HAL and GUI",
    create,
    lines = Lines
);
