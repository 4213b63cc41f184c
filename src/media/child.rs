//! A child process that writes raw frames to a pipe, and never outlives jderobot.
//!
//! - The frames come on the child's standard output ([`FramePipe::Stdout`]) or on
//!   its file descriptor 3 ([`FramePipe::Fd3`], for programs such as mplayer that
//!   print on standard output and write frames to a file name: `/dev/fd/3`).
//! - Standard input is /dev/null (mplayer would otherwise read the terminal the
//!   shell uses); the child runs in its own process group, so Ctrl+C in the shell
//!   does not kill it behind the driver's back.
//! - `PR_SET_PDEATHSIG(SIGKILL)` is set between fork and exec: if jderobot dies
//!   (even by SIGKILL) the kernel kills the child. Linux sends it when the *thread*
//!   that spawned the child ends, so the thread that spawns a child must own it
//!   until it is done with it (the stream worker does).
//! - Dropping a [`Child`] kills and reaps the process. A [`Killer`] kills it from
//!   another thread (e.g. `terminate` while the reader is blocked on the pipe).
//! - Its standard error (and standard output with `Fd3`) is kept: the last lines go
//!   into error messages.

use std::{
    collections::VecDeque,
    io::Read,
    os::{fd::AsRawFd, unix::process::CommandExt},
    process::{Command, Stdio},
    sync::Arc,
    thread::JoinHandle,
};

use parking_lot::Mutex;

use super::MediaError;

/// Where the child writes its frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FramePipe {
    Stdout,
    /// File descriptor 3 (name it `/dev/fd/3` on the child's command line).
    Fd3,
}

#[derive(Default)]
struct KillerState {
    pid: Option<u32>,
    stopped: bool,
}

/// Kills the child a worker is running, from any thread; after [`kill_now`](Killer::kill_now)
/// no new child can be spawned with it.
#[derive(Clone, Default)]
pub struct Killer(Arc<Mutex<KillerState>>);

impl Killer {
    /// Kills the current child (if any) and refuses new ones.
    pub fn kill_now(&self) {
        let mut s = self.0.lock();
        s.stopped = true;
        if let Some(pid) = s.pid {
            // The pid cannot have been reused: the owner reaps only after taking it
            // out of here under this lock.
            unsafe {
                libc::kill(pid as libc::pid_t, libc::SIGKILL);
            }
        }
    }

    pub fn stopped(&self) -> bool {
        self.0.lock().stopped
    }
}

/// The last lines a child printed.
#[derive(Clone, Default)]
pub struct Tail(Arc<Mutex<VecDeque<String>>>);

const TAIL_LINES: usize = 12;
const LINE_MAX: usize = 300;

impl Tail {
    fn push(&self, line: &str) {
        let line = line.trim();
        if line.is_empty() {
            return;
        }
        let mut t = self.0.lock();
        if t.len() == TAIL_LINES {
            t.pop_front();
        }
        t.push_back(line.chars().take(LINE_MAX).collect());
    }

    /// The kept lines that pass `keep`, joined with " | ".
    pub fn text(&self, keep: impl Fn(&str) -> bool) -> String {
        let t = self.0.lock();
        t.iter()
            .filter(|l| keep(l))
            .cloned()
            .collect::<Vec<_>>()
            .join(" | ")
    }

    fn collect(self, mut r: impl Read + Send + 'static) -> JoinHandle<()> {
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            let mut line = Vec::new();
            loop {
                let n = match r.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => n,
                };
                for &b in &buf[..n] {
                    if b == b'\n' || b == b'\r' {
                        self.push(&String::from_utf8_lossy(&line));
                        line.clear();
                    } else if line.len() < LINE_MAX * 4 {
                        line.push(b);
                    }
                }
            }
            self.push(&String::from_utf8_lossy(&line));
        })
    }
}

/// A running child process and the read end of its frame pipe.
pub struct Child {
    child: std::process::Child,
    killer: Killer,
    frames: std::io::PipeReader,
    tail: Tail,
    collector: Option<JoinHandle<()>>,
    program: String,
}

impl Child {
    /// Starts `cmd`; the frames come from `pipe`. `package` names the Debian package
    /// to install when the program is missing.
    pub fn spawn(
        mut cmd: Command,
        pipe: FramePipe,
        killer: &Killer,
        package: &'static str,
    ) -> Result<Child, MediaError> {
        let program = cmd.get_program().to_string_lossy().into_owned();
        let (frames, frames_w) = std::io::pipe()
            .map_err(|e| MediaError::Child(format!("{program}: cannot create a pipe: {e}")))?;
        let (log, log_w) = std::io::pipe()
            .map_err(|e| MediaError::Child(format!("{program}: cannot create a pipe: {e}")))?;
        let log_w2 = log_w
            .try_clone()
            .map_err(|e| MediaError::Child(format!("{program}: {e}")))?;
        cmd.stdin(Stdio::null()).stderr(log_w);
        let fd3 = match pipe {
            FramePipe::Stdout => {
                cmd.stdout(frames_w);
                None
            }
            FramePipe::Fd3 => {
                cmd.stdout(log_w2);
                Some(frames_w)
            }
        };
        let fd3_raw = fd3.as_ref().map(|f| f.as_raw_fd());
        let parent = std::process::id() as libc::pid_t;
        cmd.process_group(0);
        // SAFETY: only async-signal-safe calls between fork and exec.
        unsafe {
            cmd.pre_exec(move || {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                // jderobot died before prctl took effect: do not run orphaned.
                if libc::getppid() != parent {
                    libc::_exit(1);
                }
                if let Some(fd) = fd3_raw {
                    if fd == 3 {
                        let flags = libc::fcntl(3, libc::F_GETFD);
                        if flags < 0 || libc::fcntl(3, libc::F_SETFD, flags & !libc::FD_CLOEXEC) < 0
                        {
                            return Err(std::io::Error::last_os_error());
                        }
                    } else if libc::dup2(fd, 3) < 0 {
                        return Err(std::io::Error::last_os_error());
                    }
                }
                Ok(())
            });
        }
        let child = {
            let mut k = killer.0.lock();
            if k.stopped {
                return Err(MediaError::Child(format!("{program}: stopping")));
            }
            let child = cmd.spawn().map_err(|e| {
                if e.kind() == std::io::ErrorKind::NotFound {
                    MediaError::Missing {
                        program: program.clone(),
                        package,
                    }
                } else {
                    MediaError::Child(format!("cannot start {program}: {e}"))
                }
            })?;
            k.pid = Some(child.id());
            child
        };
        // Our copies of the write ends must close, so EOF comes when the child ends.
        drop(cmd);
        drop(fd3);
        let tail = Tail::default();
        let collector = Some(tail.clone().collect(log));
        Ok(Child {
            child,
            killer: killer.clone(),
            frames,
            tail,
            collector,
            program,
        })
    }

    /// The frame pipe.
    pub fn frames(&mut self) -> &mut std::io::PipeReader {
        &mut self.frames
    }

    /// What the child printed last (lines that pass `keep`).
    pub fn said(&self, keep: impl Fn(&str) -> bool) -> String {
        self.tail.text(keep)
    }

    /// Waits for the child to end (after its frames reached EOF) and describes how it
    /// ended: `Ok(())` for a clean exit, else an error with what it printed.
    pub fn finish(mut self) -> Result<(), MediaError> {
        let t0 = std::time::Instant::now();
        let st = loop {
            {
                let mut k = self.killer.0.lock();
                // Reap under the lock, so a Killer never signals a reused pid.
                match self.child.try_wait() {
                    Ok(Some(s)) => {
                        k.pid = None;
                        break Ok(s);
                    }
                    Ok(None) if k.stopped || t0.elapsed() > std::time::Duration::from_secs(5) => {
                        // Closed its output but does not end: end it.
                        k.pid = None;
                        let _ = self.child.kill();
                        break self.child.wait();
                    }
                    Ok(None) => {}
                    Err(e) => {
                        k.pid = None;
                        break Err(e);
                    }
                }
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        };
        if let Some(c) = self.collector.take() {
            let _ = c.join();
        }
        let said = self.tail.text(|_| true);
        match st {
            Ok(s) if s.success() => Ok(()),
            Ok(s) => Err(MediaError::Child(format!(
                "{} ended with {s}{}",
                self.program,
                if said.is_empty() {
                    String::new()
                } else {
                    format!(": {said}")
                }
            ))),
            Err(e) => Err(MediaError::Child(format!("{}: {e}", self.program))),
        }
    }
}

impl Drop for Child {
    fn drop(&mut self) {
        let pid = self.killer.0.lock().pid.take();
        if pid.is_some() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
        if let Some(c) = self.collector.take() {
            let _ = c.join();
        }
    }
}
