//! jderobot's side of a program's worker process ([`worker`](super::worker)):
//! starting it with its board, socket and lifeline, reading what it sends, and
//! ending it.
//!
//! The worker runs in a process group of its own (a program's children end
//! with it; the terminal's Ctrl+C and Ctrl+Z reach jderobot, which stops the
//! robot, not the program) under a memory limit (`RLIMIT_AS`: past it Python
//! raises `MemoryError` in the program), with no core dumps, and, where
//! jderobot may make one (root, a pids controller: cgroup v2 or v1), in a
//! control group of its own that holds at most [`MAX_PROCESSES`] processes and
//! threads (a fork bomb's `os.fork()` fails there with `BlockingIOError`).
//! Ending it is `SIGKILL` to the group, so a stop never waits for the program.

use std::{
    io::{self, BufRead, BufReader},
    os::{
        fd::AsRawFd,
        unix::{net::UnixStream, process::CommandExt},
    },
    path::PathBuf,
    process::{Child, Command, Stdio},
    sync::{
        Arc, OnceLock,
        atomic::{AtomicBool, Ordering},
        mpsc::{Receiver, RecvTimeoutError, Sender, channel},
    },
    thread::JoinHandle,
    time::Duration,
};

use super::{
    board::Board,
    shared::{Robot, Shared},
    wire::{self, Failure, FromWorker, Outcome, ToWorker},
    worker::{BOARD_FD, LIFELINE_FD, SOCKET_FD, WORKER_ENV},
};
use crate::interfaces::Image;

/// The binary started as the worker (see [`set_worker_exe`]).
static WORKER_EXE: OnceLock<PathBuf> = OnceLock::new();

/// Names the binary to start as the worker: any binary whose `main` calls
/// `jderobot::cli::main` with the `python` feature. Without it: `$JDEROBOT_EXE`;
/// else this process's own binary if it is `jderobot`; else a `jderobot` beside
/// it or one folder up (cargo's tests, benchmarks and examples run from
/// `target/*/deps` and `target/*/examples`, the binary is in `target/*`); else
/// this process's own (a user's crate that calls `jderobot::cli::main`).
pub fn set_worker_exe(path: impl Into<PathBuf>) {
    let _ = WORKER_EXE.set(path.into());
}

fn worker_exe() -> io::Result<PathBuf> {
    if let Some(p) = WORKER_EXE.get() {
        return Ok(p.clone());
    }
    if let Some(p) = std::env::var_os("JDEROBOT_EXE") {
        return Ok(p.into());
    }
    let me = std::env::current_exe()?;
    if me.file_stem().is_some_and(|s| s == "jderobot") {
        return Ok(me);
    }
    let beside = me
        .parent()
        .into_iter()
        .flat_map(|d| [d.join("jderobot"), d.join("../jderobot")]);
    Ok(beside.into_iter().find(|p| p.is_file()).unwrap_or(me))
}

/// The argument the worker is started with (beside [`WORKER_ENV`]): a binary
/// that is not jderobot's refuses it instead of running as something else.
pub const WORKER_ARG: &str = "--python-worker";

/// What the schema hears from its worker (prints, images and commands are
/// dealt with as they come, by the reader).
#[derive(Debug)]
pub enum Event {
    Loaded {
        academy5: bool,
        has_loop: bool,
    },
    Refused(Failure),
    Outcome(Outcome),
    /// The process ended: how (`exit 0`, `killed by SIGSEGV (a segmentation
    /// fault)`, ...).
    Ended(String),
}

/// The most processes and threads a worker and all it starts may hold at once
/// (its control group's `pids.max`).
pub const MAX_PROCESSES: u32 = 256;

/// A worker's control group (pids controller), removed when dropped.
struct PidsGroup(PathBuf);

impl PidsGroup {
    /// Puts process `pid` in a new control group of at most [`MAX_PROCESSES`],
    /// under cgroup v2's or v1's pids hierarchy; None where jderobot cannot
    /// (not root, no pids controller).
    fn limit(pid: i32) -> Option<PidsGroup> {
        for root in ["/sys/fs/cgroup", "/sys/fs/cgroup/pids"] {
            let root = std::path::Path::new(root);
            if !root.join("cgroup.procs").exists() {
                continue; // not a cgroup hierarchy (v1 mounts a tmpfs here)
            }
            let group = PidsGroup(root.join(format!("jderobot-python-{pid}")));
            if std::fs::create_dir(&group.0).is_err() {
                continue;
            }
            // cgroup v2 gives a child the pids controller only where its parent
            // hands it down: asked for once, where it is missing.
            if !group.0.join("pids.max").exists() {
                let _ = std::fs::write(root.join("cgroup.subtree_control"), "+pids");
            }
            if std::fs::write(group.0.join("pids.max"), MAX_PROCESSES.to_string()).is_ok()
                && std::fs::write(group.0.join("cgroup.procs"), pid.to_string()).is_ok()
            {
                return Some(group);
            }
        }
        None
    }
}

impl Drop for PidsGroup {
    /// Kills what is left in the group (a process that left the worker's
    /// process group), then removes it.
    fn drop(&mut self) {
        if let Ok(procs) = std::fs::read_to_string(self.0.join("cgroup.procs")) {
            for pid in procs.lines().filter_map(|l| l.trim().parse::<i32>().ok()) {
                // SAFETY: a signal to a process of the worker's own group.
                unsafe { libc::kill(pid, libc::SIGKILL) };
            }
        }
        for _ in 0..100 {
            if std::fs::remove_dir(&self.0).is_ok() || !self.0.exists() {
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// A running worker.
pub struct WorkerProcess {
    pid: i32,
    to_worker: UnixStream,
    pub board: Arc<Board>,
    events: Receiver<Event>,
    reader: Option<JoinHandle<()>>,
    /// Set once a program runs: from then the worker's end zeroes the motors.
    driving: Arc<AtomicBool>,
    _lifeline: std::io::PipeWriter,
    /// Its control group, if one could be made (dropped after the process).
    pids: Option<PidsGroup>,
}

/// Moves `fds` to descriptors 3, 4, 5... of the child (between fork and exec:
/// only async-signal-safe calls).
fn place_fds(fds: &[i32]) -> io::Result<()> {
    let mut high = [0i32; 8];
    for (i, &fd) in fds.iter().enumerate() {
        // SAFETY: fcntl and dup2 are async-signal-safe.
        high[i] = unsafe { libc::fcntl(fd, libc::F_DUPFD, 16) };
        if high[i] < 0 {
            return Err(io::Error::last_os_error());
        }
    }
    for (i, &h) in high[..fds.len()].iter().enumerate() {
        // SAFETY: as above; dup2 leaves the new descriptor open across exec.
        if unsafe { libc::dup2(h, BOARD_FD + i as i32) } < 0 {
            return Err(io::Error::last_os_error());
        }
        unsafe { libc::close(h) };
    }
    Ok(())
}

fn set_limit(resource: libc::__rlimit_resource_t, bytes: u64) -> io::Result<()> {
    let l = libc::rlimit {
        rlim_cur: bytes,
        rlim_max: bytes,
    };
    // SAFETY: async-signal-safe; the struct lives across the call.
    if unsafe { libc::setrlimit(resource, &l) } != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

impl WorkerProcess {
    /// Starts a worker for `shared`'s program, driving `robot`; `memory`: its
    /// address-space limit in bytes (None: none).
    pub fn start(
        shared: Arc<Shared>,
        robot: Arc<Robot>,
        memory: Option<u64>,
    ) -> io::Result<WorkerProcess> {
        // A binary that is not jderobot's, started as a worker, runs its own
        // main: it must not start workers in turn (each would start another).
        if std::env::var_os(WORKER_ENV).is_some() {
            return Err(io::Error::other(format!(
                "this process was started as a python worker but its binary ({}) does not run \
                 jderobot::cli::main; name the jderobot binary with \
                 jderobot::schemas::python::set_worker_exe or $JDEROBOT_EXE",
                std::env::current_exe().unwrap_or_default().display()
            )));
        }
        let board = Arc::new(Board::create()?);
        let (ours, theirs) = UnixStream::pair()?;
        let (life_r, life_w) = std::io::pipe()?;
        let (out_r, out_w) = std::io::pipe()?;
        let exe = worker_exe()?;
        let mut cmd = Command::new(&exe);
        cmd.arg(WORKER_ARG)
            .env(WORKER_ENV, "1")
            .stdin(Stdio::null())
            .stdout(out_w.try_clone()?)
            .stderr(out_w);
        let fds = [board.fd(), theirs.as_raw_fd(), life_r.as_raw_fd()];
        debug_assert_eq!((SOCKET_FD, LIFELINE_FD), (BOARD_FD + 1, BOARD_FD + 2));
        // SAFETY: the closure makes only async-signal-safe calls.
        unsafe {
            cmd.pre_exec(move || {
                place_fds(&fds)?;
                libc::setpgid(0, 0);
                set_limit(libc::RLIMIT_CORE, 0)?;
                if let Some(m) = memory {
                    set_limit(libc::RLIMIT_AS, m)?;
                }
                Ok(())
            });
        }
        let child = cmd.spawn().map_err(|e| {
            io::Error::new(
                e.kind(),
                format!("cannot start {} as the python worker: {e}", exe.display()),
            )
        })?;
        drop(cmd);
        drop((theirs, life_r));
        let pid = child.id() as i32;
        // Before it loads a program, so nothing it starts escapes the limit.
        let pids = PidsGroup::limit(pid);
        let console = shared.clone();
        std::thread::Builder::new()
            .name(format!("{}-output", shared.name))
            .spawn(move || {
                for line in BufReader::new(out_r).lines() {
                    let Ok(line) = line else { break };
                    console.print(&format!("{line}\n"));
                }
            })?;
        let (tx, events) = channel();
        let driving = Arc::new(AtomicBool::new(false));
        let reader = {
            let (socket, board, driving) = (ours.try_clone()?, board.clone(), driving.clone());
            std::thread::Builder::new()
                .name(format!("{}-worker", shared.name))
                .spawn(move || read(socket, child, shared, robot, board, driving, tx))?
        };
        Ok(WorkerProcess {
            pid,
            to_worker: ours,
            board,
            events,
            reader: Some(reader),
            driving,
            _lifeline: life_w,
            pids,
        })
    }

    /// Sends a message; a pass marks the worker as driving.
    pub fn send(&mut self, msg: &ToWorker) -> io::Result<()> {
        if matches!(msg, ToWorker::Pass(_)) {
            self.driving.store(true, Ordering::Release);
        }
        wire::send(&mut self.to_worker, msg, &[])
    }

    /// The next event, waiting at most `timeout`.
    pub fn next(&self, timeout: Duration) -> Option<Event> {
        match self.events.recv_timeout(timeout) {
            Ok(e) => Some(e),
            Err(RecvTimeoutError::Timeout) => None,
            Err(RecvTimeoutError::Disconnected) => Some(Event::Ended("gone".into())),
        }
    }

    /// The process's id (its group's too).
    pub fn pid(&self) -> i32 {
        self.pid
    }

    /// Ends the worker and everything it started (its process group), and
    /// waits for its reader to see it gone.
    pub fn kill(mut self) {
        self.end();
    }

    fn end(&mut self) {
        let Some(reader) = self.reader.take() else {
            return;
        };
        kill_group(self.pid);
        let _ = reader.join();
        self.pids.take();
    }
}

impl Drop for WorkerProcess {
    fn drop(&mut self) {
        self.end();
    }
}

/// SIGKILL to a worker's process group (the worker leads it).
pub fn kill_group(pid: i32) {
    // SAFETY: plain system calls on a group we made.
    unsafe {
        libc::kill(-pid, libc::SIGKILL);
        libc::kill(pid, libc::SIGKILL);
    }
}

/// The reader: deals with prints, images and commands as they come, passes the
/// rest to the schema, and when the socket closes reaps the process, zeroes the
/// motors (if a program ran) and says how it ended.
fn read(
    mut socket: UnixStream,
    mut child: Child,
    shared: Arc<Shared>,
    robot: Arc<Robot>,
    board: Arc<Board>,
    driving: Arc<AtomicBool>,
    tx: Sender<Event>,
) {
    loop {
        let msg = match wire::receive::<FromWorker>(&mut socket) {
            Ok(Some(m)) => m,
            Ok(None) => break,
            Err(e) => {
                // A worker that says what cannot be read is not trusted on.
                tracing::warn!("{}: the worker's message: {e}; ending it", shared.name);
                kill_group(child.id() as i32);
                break;
            }
        };
        let event = match msg {
            (FromWorker::Print(text), _) => {
                shared.print(&text);
                continue;
            }
            (FromWorker::Image { width, height }, bgr) => {
                if bgr.len() == width as usize * height as usize * 3 {
                    *shared.image.lock() = Some(Arc::new(Image {
                        width,
                        height,
                        data: bgr,
                    }));
                    shared.images.fetch_add(1, Ordering::AcqRel);
                }
                continue;
            }
            (FromWorker::Forces(f), _) => {
                shared.draw(|o| o.forces = Some(f));
                continue;
            }
            (FromWorker::LocalTarget(t), _) => {
                shared.draw(|o| o.local_target = Some(t));
                continue;
            }
            (FromWorker::Command { v, w, end_of_pass }, _) => {
                board.header().silenced.store(0, Ordering::Release);
                robot.command_from_program(v, w, end_of_pass);
                continue;
            }
            (FromWorker::Loaded { academy5, has_loop }, _) => Event::Loaded { academy5, has_loop },
            (FromWorker::Refused(f), _) => Event::Refused(f),
            (FromWorker::Outcome(o), _) => Event::Outcome(o),
        };
        if tx.send(event).is_err() {
            break;
        }
    }
    if driving.load(Ordering::Acquire) {
        robot.release();
    }
    let how = match child.wait() {
        Ok(status) => ended(status),
        Err(e) => format!("its status is unknown: {e}"),
    };
    shared.flush();
    let _ = tx.send(Event::Ended(how));
}

/// How a process ended, in words.
fn ended(status: std::process::ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    if let Some(code) = status.code() {
        return format!("exit {code}");
    }
    let Some(sig) = status.signal() else {
        return status.to_string();
    };
    let what = match sig {
        libc::SIGSEGV => {
            "SIGSEGV (a segmentation fault: the program, or C code it called, read memory it has not)"
        }
        libc::SIGBUS => "SIGBUS (a bus error in C code)",
        libc::SIGABRT => "SIGABRT (aborted: a failed assertion or allocation in C code)",
        libc::SIGFPE => "SIGFPE (an arithmetic fault in C code)",
        libc::SIGKILL => "SIGKILL (the out-of-memory killer, `kill -9`, or a stop)",
        libc::SIGTERM => "SIGTERM",
        libc::SIGINT => "SIGINT",
        libc::SIGALRM => "SIGALRM (signal.alarm)",
        _ => return format!("killed by signal {sig}"),
    };
    format!("killed by {what}")
}
