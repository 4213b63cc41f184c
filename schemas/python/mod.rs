//! python: runs a student's Python program, written against JdeRobot's Robotics
//! Academy API in either of its shapes, as a schema, in an interpreter embedded in
//! the one binary, on whatever driver provides the robot.
//!
//! Conf (`file` is required; the other lines show their defaults):
//! ```text
//! schema python
//! file exercises/vacuum.py      # the program, relative to the conf file
//! cycle 50                      # ms: the 4.x loop's period (the Academy's "brain frequency")
//! venv none                     # a virtual environment's directory (default: $VIRTUAL_ENV)
//! watch on                      # reload the program when its file changes
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
//! command holds while the program lives (the watchdog publishes it again every
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
//! marks the line in the panel, stops this schema and zeroes its motors. Stopping
//! interrupts a running program within a few ms (a watchdog raises
//! `ProgramStopped` in its thread; `time.sleep` and `Frequency.tick` give up at
//! once), even one stuck in `while True: pass`, and zeroes the motors. Saving the
//! file reloads it (motors zeroed in between), as do the panel's Reload button and
//! the shell's `reload python`. See docs/python.md.
//!
//! Interfaces: writes `motors` (mm/s, deg/s); reads `encoders` (mm, rad), `laser`
//! (mm), `bumpers`, `colorA` (BGR) — each optional (a HAL call without it raises a
//! Python error naming the conf line). System: Debian `python3-dev` to build,
//! `python3-numpy` for `getImage`/`showImage`.

#[cfg(feature = "gui")]
pub mod highlight;
#[cfg(feature = "gui")]
mod panel;
mod program;

use parking_lot::Mutex;
use std::{
    path::PathBuf,
    sync::{
        Arc, Weak,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, Instant, SystemTime},
};

use crate::{
    conf::{
        ComponentConf,
        settings::{self, CYCLE, Setting, on_off, word},
    },
    interfaces::{Bumpers, Encoders, Image, Laser, Motors},
    runtime::{Context, Runtime, Schema, State},
};

pub use program::{CONSOLE_LINES, REFRESH, Shared, TICK_HZ, bumper_side, laser_geometry, shared};
use program::{Current, Outcome, Program, Robot};

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
    /// 4.x: the loop body runs each cycle; Academy 5: the program's thread runs.
    Loop,
    Finished,
}

/// A program in the Academy 5 shape, running in a thread of its own.
struct ProgramThread {
    /// Set to stop it (before it starts, or with an interrupt).
    cancel: Arc<AtomicBool>,
    /// Its outcome, once it ended.
    outcome: Arc<Mutex<Option<Outcome>>>,
    handle: std::thread::JoinHandle<()>,
}

/// The schema.
pub struct PythonSchema {
    shared: Arc<Shared>,
    robot: Arc<Robot>,
    path: PathBuf,
    program: Option<Arc<Program>>,
    phase: Phase,
    cycle: Duration,
    watch: bool,
    mtime: Option<SystemTime>,
    checked: Instant,
    /// The sensors resumed while running.
    children: Vec<String>,
    watchdog: Option<Watchdog>,
    /// The Academy 5 program's thread, while it runs (or would not end).
    thread: Option<ProgramThread>,
    #[cfg(feature = "gui")]
    panel: Option<Box<dyn crate::runtime::Panel>>,
}

/// How often the file's modification time is looked at.
const WATCH_EVERY: Duration = Duration::from_millis(250);
/// How often the watchdog looks for a stop while Python runs (and keeps the
/// command fresh).
const WATCHDOG_PERIOD: Duration = Duration::from_millis(5);
/// How long a living program may go without showing it is alive (a HAL, GUI or
/// Frequency call, the end of a 4.x pass; a `time.sleep` or `Frequency.tick`
/// counts as alive while it lasts) before its motors are stopped: a program
/// stuck computing, or waiting on something else, does not drive on blind.
pub const SILENCE: Duration = Duration::from_secs(5);
/// How long a stop waits for an Academy 5 program's thread to end.
const STOP_WAIT: Duration = Duration::from_secs(3);

fn mtime(p: &std::path::Path) -> Option<SystemTime> {
    std::fs::metadata(p).and_then(|m| m.modified()).ok()
}

impl PythonSchema {
    /// Reads and compiles the program; a failure is `FILE:LINE: message`.
    fn load(&mut self) -> Result<(), String> {
        self.mtime = mtime(&self.path);
        let source = std::fs::read_to_string(&self.path)
            .map_err(|e| format!("{}: cannot read the program: {e}", self.path.display()))?;
        *self.shared.source.lock() = Arc::new(source.clone());
        *self.shared.file.lock() = self.path.clone();
        let path = self.path.display().to_string();
        match Program::compile(&path, &source) {
            Ok(p) => {
                self.shared.academy5.store(p.academy5, Ordering::Release);
                self.program = Some(Arc::new(p));
                *self.shared.error.lock() = None;
                Ok(())
            }
            Err(f) => {
                self.program = None;
                *self.shared.error.lock() = Some((f.line, f.summary.clone()));
                Err(f.summary)
            }
        }
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
        self.stop_thread()?;
        self.shared.reload.store(false, Ordering::Release);
        self.robot.release();
        self.load()?;
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
        let academy5 = self.program.as_ref().is_some_and(|p| p.academy5);
        *self.shared.phase.lock() = match p {
            Phase::Init => "init",
            Phase::Loop if academy5 => "running",
            Phase::Loop => "loop",
            Phase::Finished => "finished",
        };
    }

    /// Waits (at most 2 s) for the first value of the sensors a program reads at
    /// once, so its init code never sees an empty scan.
    fn wait_for_sensors(&self) {
        let t = Instant::now();
        let have = |r: &Robot| {
            r.encoders.as_ref().is_none_or(|e| e.clock() > 0)
                && r.laser.as_ref().is_none_or(|l| l.clock() > 0)
                && r.bumpers.as_ref().is_none_or(|b| b.clock() > 0)
                && r.camera.as_ref().is_none_or(|c| c.clock() > 0)
        };
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
    }

    /// Starts an Academy 5 program in a thread of its own.
    fn start_thread(&mut self, program: Arc<Program>) -> anyhow::Result<()> {
        let cancel = Arc::new(AtomicBool::new(false));
        let outcome = Arc::new(Mutex::new(None));
        let (c, o, shared, robot) = (
            cancel.clone(),
            outcome.clone(),
            self.shared.clone(),
            self.robot.clone(),
        );
        let handle = std::thread::Builder::new()
            .name(format!("{}-program", self.shared.name))
            .spawn(move || {
                program::set_current(Some(Current {
                    shared: shared.clone(),
                    robot,
                }));
                let r = program.run(0, &shared, Some(&c));
                program::set_current(None);
                shared.flush();
                *o.lock() = Some(r);
            })?;
        self.thread = Some(ProgramThread {
            cancel,
            outcome,
            handle,
        });
        Ok(())
    }

    /// Stops the Academy 5 program's thread: interrupts it until it ends (at
    /// most [`STOP_WAIT`]). A thread that will not end (stuck in C code) is
    /// kept: the next run waits for it.
    fn stop_thread(&mut self) -> Result<(), String> {
        let Some(t) = self.thread.take() else {
            return Ok(());
        };
        t.cancel.store(true, Ordering::SeqCst);
        let since = Instant::now();
        while !t.handle.is_finished() {
            if since.elapsed() >= STOP_WAIT {
                self.thread = Some(t);
                return Err(format!(
                    "{}: the program's previous run does not end (it is stuck outside Python code); \
                     stop jderobot to end it",
                    self.shared.name
                ));
            }
            program::interrupt(&self.shared);
            std::thread::sleep(WATCHDOG_PERIOD);
        }
        let _ = t.handle.join();
        Ok(())
    }

    /// What a piece of the program's outcome means for the schema.
    fn conclude(&mut self, outcome: Outcome, next: Phase) -> anyhow::Result<()> {
        match outcome {
            Outcome::Done | Outcome::Broke => {
                if next == Phase::Finished {
                    if self.phase != Phase::Finished {
                        self.robot.release();
                        self.shared
                            .print("-- the program has ended; the motors are stopped\n");
                    }
                } else {
                    self.robot.end_of_pass();
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
                self.set_phase(Phase::Finished);
                Ok(())
            }
            // The runtime is stopping this schema (or a reload interrupted it).
            Outcome::Stopped => {
                self.robot.release();
                Ok(())
            }
            Outcome::Failed(f) => {
                self.robot.release();
                self.shared.print(&f.text);
                if !f.text.ends_with('\n') {
                    self.shared.print("\n");
                }
                self.shared.flush();
                *self.shared.error.lock() = Some((f.line, f.summary.clone()));
                self.set_phase(Phase::Finished);
                Err(anyhow::anyhow!(f.summary))
            }
        }
    }
}

impl Schema for PythonSchema {
    fn cycle(&self) -> Duration {
        self.cycle
    }

    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        // A previous run's thread that would not end blocks a new one.
        self.stop_thread().map_err(anyhow::Error::msg)?;
        ctx.run_children(&self.children, None)?;
        self.shared.clear_console();
        // Each run starts the program afresh (the file as it is now).
        self.load().map_err(anyhow::Error::msg)?;
        self.set_phase(Phase::Init);
        self.robot.zero();
        self.wait_for_sensors();
        Ok(())
    }

    fn iteration(&mut self, ctx: &Context) -> anyhow::Result<()> {
        if self.watchdog.is_none() {
            self.watchdog = Some(Watchdog::start(
                ctx.runtime(),
                self.shared.clone(),
                self.robot.clone(),
            ));
        }
        self.reload_if_asked().map_err(anyhow::Error::msg)?;
        let Some(program) = self.program.clone() else {
            return Ok(());
        };
        if self.phase == Phase::Init {
            self.shared.new_run();
            self.robot.start_holding();
        }
        if program.academy5 {
            return match self.phase {
                Phase::Init => {
                    self.start_thread(program)?;
                    self.set_phase(Phase::Loop);
                    Ok(())
                }
                Phase::Loop => {
                    let done = self.thread.as_ref().and_then(|t| t.outcome.lock().take());
                    let Some(outcome) = done else {
                        return Ok(());
                    };
                    if let Some(t) = self.thread.take() {
                        let _ = t.handle.join();
                    }
                    self.conclude(outcome, Phase::Finished)
                }
                Phase::Finished => Ok(()),
            };
        }
        let which = match self.phase {
            Phase::Init => 0,
            Phase::Loop => 1,
            Phase::Finished => return Ok(()),
        };
        program::set_current(Some(Current {
            shared: self.shared.clone(),
            robot: self.robot.clone(),
        }));
        let mut outcome = program.run(which, &self.shared, None);
        let mut next = match (which, &outcome) {
            (0, Outcome::Done) if program.has_loop() => Phase::Loop,
            (1, Outcome::Done) => Phase::Loop,
            _ => Phase::Finished,
        };
        if which == 1 && matches!(outcome, Outcome::Broke) {
            outcome = program.run(2, &self.shared, None);
            next = Phase::Finished;
        }
        program::set_current(None);
        self.shared.flush();
        self.conclude(outcome, next)
    }

    fn on_stop(&mut self, ctx: &Context) {
        let _ = ctx;
        self.robot.release();
        if let Err(e) = self.stop_thread() {
            self.shared.print(&format!("-- {e}\n"));
        }
        self.robot.release();
        self.set_phase(Phase::Init);
    }

    fn terminate(&mut self) {
        self.robot.release();
        let _ = self.stop_thread();
        if let Some(w) = self.watchdog.take() {
            w.stop();
        }
    }

    #[cfg(feature = "gui")]
    fn panel(&mut self) -> Option<Box<dyn crate::runtime::Panel>> {
        self.panel.take()
    }
}

/// A thread that interrupts the schema's Python code when the schema is stopped
/// (or asked to reload) while the program runs: it zeroes the motors at once and
/// raises `ProgramStopped` in the program's thread until it gives up. While the
/// program lives it also keeps its command fresh ([`Robot::refresh`]), and stops
/// the motors when it goes silent past [`SILENCE`].
struct Watchdog {
    alive: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Watchdog {
    fn start(rt: &Arc<Runtime>, shared: Arc<Shared>, robot: Arc<Robot>) -> Watchdog {
        let alive = Arc::new(AtomicBool::new(true));
        let a = alive.clone();
        let rt: Weak<Runtime> = Arc::downgrade(rt);
        let thread = std::thread::Builder::new()
            .name(format!("{}-watchdog", shared.name))
            .spawn(move || {
                while a.load(Ordering::Acquire) {
                    std::thread::sleep(WATCHDOG_PERIOD);
                    if robot.hold.load(Ordering::Acquire) {
                        keep(&shared, &robot);
                    }
                    if !shared.in_python.load(Ordering::Acquire) {
                        continue;
                    }
                    let Some(rt) = rt.upgrade() else { return };
                    let stopped = rt
                        .schema_status(&shared.name)
                        .is_none_or(|s| s.state == State::Slept);
                    drop(rt);
                    if stopped || shared.reload.load(Ordering::Acquire) {
                        robot.release();
                        program::interrupt(&shared);
                    }
                }
            })
            .ok();
        Watchdog { alive, thread }
    }

    fn stop(mut self) {
        self.alive.store(false, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The watchdog's care of a living program's command: fresh while it shows it
/// is alive, stopped (once, said in the console) when it goes silent.
fn keep(shared: &Shared, robot: &Robot) {
    let silent = !shared.sleeping.load(Ordering::Acquire) && shared.silent_for() > SILENCE;
    if !silent {
        robot.refresh();
    } else if !shared.silenced.swap(true, Ordering::AcqRel) {
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
    program::interpreter().map_err(anyhow::Error::msg)?;
    if lines.venv != "none" {
        let venv = conf
            .line("venv")
            .expect("a venv line gave the value")
            .path(0, "the virtual environment")?;
        program::add_venv(&venv).map_err(|e| {
            conf.line("venv")
                .expect("a venv line gave the value")
                .error(format!("venv: {e}"))
        })?;
    }
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
    // A re-init (the shell's `init`, `reload`) replaces a running program: ask the
    // old one to give way (its watchdog interrupts it); the new one starts afresh.
    if shared.loads.fetch_add(1, Ordering::AcqRel) > 0 {
        shared.reload.store(true, Ordering::Release);
    }
    let mut s = PythonSchema {
        shared: shared.clone(),
        robot,
        path,
        program: None,
        phase: Phase::Init,
        cycle: Duration::from_millis(lines.cycle),
        watch: lines.watch,
        mtime: None,
        checked: Instant::now(),
        children,
        watchdog: None,
        thread: None,
        #[cfg(feature = "gui")]
        panel: None,
    };
    // A syntax error stops the load (and `jderobot check`): FILE:LINE: message.
    s.load().map_err(anyhow::Error::msg)?;
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
