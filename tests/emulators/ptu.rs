//! An emulator of the Directed Perception pan-tilt unit (PTU-46) on a pseudo-terminal,
//! written from the unit's command reference (PTU-46 user's manual, "Command
//! Reference"), not from the driver:
//!
//! - Commands are ASCII, delimited by a space, `\r` or `\n`; a letter names the axis
//!   (`P` pan, `T` tilt) and a second the operation: `PP<n>` position, `PS<n>` speed,
//!   `PA<n>` acceleration, `PB<n>` base speed, `PU<n>`/`PL<n>` upper/lower speed,
//!   `PH<L|R|O>` hold power, `PM<L|R|H>` move power; without a number `PP`, `PS`
//!   query; `PN`/`PX` the minimum/maximum position. Unit-wide: `I` immediate mode,
//!   `S` slaved mode, `CI`/`CV` control mode, `LE`/`LD` limits, `EE`/`ED` echo, `H` halt.
//! - Each command is answered by one line ending `\r\n`: `*` (and, for a query, a
//!   sentence such as `* Current Pan position is 583`) on success, `!` and the
//!   reason on an error (`! Maximum allowable Pan position is 3090`,
//!   `! Illegal Command`). With echo on (the default) the command's text comes first.
//! - Positions are steps of 185.1428 arc seconds (3.086 arc min); the PTU-46-17.5's
//!   limits: pan −3090..3090, tilt −907..604. Axes move at the commanded speed
//!   (steps/s) in immediate mode. A speed of 0 halts the axis where it is (what 4.3
//!   relied on).
//!
//! Faults the tests inject: `silent` (reads, never answers), `garbage` (answers like
//! a GPS receiver), `refuse` (answers `!` to everything), and `unplug` (the device
//! goes away: the pty closes and its path disappears).
#![allow(dead_code)]

use std::{
    os::fd::{AsRawFd, FromRawFd, OwnedFd},
    path::{Path, PathBuf},
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    thread::JoinHandle,
    time::{Duration, Instant},
};

use parking_lot::Mutex;

/// A pseudo-terminal pair with the slave in raw mode.
pub struct Pty {
    pub master: OwnedFd,
    pub slave: OwnedFd,
    pub slave_path: PathBuf,
}

/// A serial cable into an emulated device: a pty whose slave is linked at `link`,
/// and the thread that serves its master side. Dropping it pulls the cable: the
/// thread stops and the link disappears.
pub struct Cable {
    link: PathBuf,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Cable {
    /// Plugs a new pty in at `link` (replacing what is there) and runs `serve` on
    /// it until the cable is pulled (`serve` returns when its flag is set).
    pub fn plug(link: &Path, serve: impl FnOnce(Pty, &AtomicBool) + Send + 'static) -> Cable {
        let pty = open_pty();
        let _ = std::fs::remove_file(link);
        std::os::unix::fs::symlink(&pty.slave_path, link).expect("symlink to the pty");
        let stop = Arc::new(AtomicBool::new(false));
        let sp = stop.clone();
        Cable {
            link: link.to_path_buf(),
            stop,
            thread: Some(std::thread::spawn(move || serve(pty, &sp))),
        }
    }
}

impl Drop for Cable {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        let _ = std::fs::remove_file(&self.link);
    }
}

/// Opens a pty pair (raw slave), like a serial cable into the device.
pub fn open_pty() -> Pty {
    let (mut m, mut s) = (0, 0);
    let mut name = [0 as libc::c_char; 128];
    // SAFETY: openpty writes two fds and a NUL-terminated name into our buffers.
    let r = unsafe {
        libc::openpty(
            &mut m,
            &mut s,
            name.as_mut_ptr(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert_eq!(r, 0, "openpty failed: {}", std::io::Error::last_os_error());
    // SAFETY: openpty returned two open fds that we now own.
    let (master, slave) = unsafe { (OwnedFd::from_raw_fd(m), OwnedFd::from_raw_fd(s)) };
    // SAFETY: termios is plain data; tcgetattr/tcsetattr on a valid fd.
    unsafe {
        let mut t: libc::termios = std::mem::zeroed();
        libc::tcgetattr(slave.as_raw_fd(), &mut t);
        libc::cfmakeraw(&mut t);
        libc::tcsetattr(slave.as_raw_fd(), libc::TCSANOW, &t);
    }
    // SAFETY: `name` is NUL-terminated by openpty.
    let path = unsafe { std::ffi::CStr::from_ptr(name.as_ptr()) }
        .to_string_lossy()
        .into_owned();
    Pty {
        master,
        slave,
        slave_path: PathBuf::from(path),
    }
}

/// Reads what is available on `fd` within `timeout`.
pub fn read_fd(fd: &OwnedFd, timeout: Duration, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut p = libc::pollfd {
        fd: fd.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    // SAFETY: one valid pollfd.
    let r = unsafe { libc::poll(&mut p, 1, timeout.as_millis() as i32) };
    if r <= 0 {
        return Ok(0);
    }
    // SAFETY: reading into a valid buffer of its length.
    let n = unsafe { libc::read(fd.as_raw_fd(), buf.as_mut_ptr().cast(), buf.len()) };
    if n < 0 {
        Err(std::io::Error::last_os_error())
    } else {
        Ok(n as usize)
    }
}

/// Writes all of `data` to `fd`.
pub fn write_fd(fd: &OwnedFd, mut data: &[u8]) {
    while !data.is_empty() {
        // SAFETY: writing from a valid buffer of its length.
        let n = unsafe { libc::write(fd.as_raw_fd(), data.as_ptr().cast(), data.len()) };
        if n <= 0 {
            return;
        }
        data = &data[n as usize..];
    }
}

/// Faults to inject.
#[derive(Clone, Copy, Debug, Default)]
pub struct Faults {
    pub silent: bool,
    pub garbage: bool,
    pub refuse: bool,
    /// The answer to the pan position query (`PP`), whatever the position.
    pub pan_position: Option<i64>,
}

#[derive(Clone, Copy, Debug)]
struct AxisState {
    pos: f64,
    target: f64,
    speed: f64,
    min: i64,
    max: i64,
    upper: i64,
    lower: i64,
}

impl AxisState {
    fn new(min: i64, max: i64) -> Self {
        AxisState {
            pos: 0.0,
            target: 0.0,
            speed: 1000.0,
            min,
            max,
            upper: 6000,
            lower: 31,
        }
    }
    fn step(&mut self, dt: f64) {
        let d = self.target - self.pos;
        let m = self.speed * dt;
        self.pos = if d.abs() <= m {
            self.target
        } else {
            self.pos + m * d.signum()
        };
    }
}

/// The unit's state.
pub struct State {
    pan: AxisState,
    tilt: AxisState,
    echo: bool,
    limits: bool,
    /// Every byte the unit received.
    pub received: Vec<u8>,
    /// When the latest bytes arrived.
    pub last_rx: Option<Instant>,
    pub faults: Faults,
}

impl State {
    fn axis(&mut self, c: u8) -> Option<(&mut AxisState, &'static str)> {
        match c {
            b'P' => Some((&mut self.pan, "Pan")),
            b'T' => Some((&mut self.tilt, "Tilt")),
            _ => None,
        }
    }

    /// The answer to one command token (without echo and line end).
    fn answer(&mut self, tok: &[u8]) -> String {
        let illegal = "! Illegal Command".to_string();
        let Ok(t) = std::str::from_utf8(tok) else {
            return illegal;
        };
        let t = t.to_ascii_uppercase();
        match t.as_str() {
            "I" | "S" | "CI" | "CV" => return "*".into(),
            "LE" => {
                self.limits = true;
                return "*".into();
            }
            "LD" => {
                self.limits = false;
                return "*".into();
            }
            "EE" => {
                self.echo = true;
                return "*".into();
            }
            "ED" => {
                self.echo = false;
                return "*".into();
            }
            "H" => {
                self.pan.target = self.pan.pos;
                self.tilt.target = self.tilt.pos;
                return "*".into();
            }
            _ => {}
        }
        let b = t.as_bytes();
        if b.len() < 2 {
            return illegal;
        }
        let limits = self.limits;
        let Some((ax, word)) = self.axis(b[0]) else {
            return illegal;
        };
        let op = b[1];
        let arg = &t[2..];
        let num = if arg.is_empty() {
            None
        } else {
            match arg.parse::<i64>() {
                Ok(n) => Some(n),
                Err(_) if matches!(op, b'H' | b'M') => None,
                Err(_) => return "! Illegal Command Argument".into(),
            }
        };
        match (op, num) {
            (b'P', None) => format!("* Current {word} position is {}", ax.pos.round() as i64),
            (b'P', Some(n)) => {
                if limits && n > ax.max {
                    format!("! Maximum allowable {word} position is {}", ax.max)
                } else if limits && n < ax.min {
                    format!("! Minimum allowable {word} position is {}", ax.min)
                } else {
                    ax.target = n as f64;
                    "*".into()
                }
            }
            (b'N', None) => format!("* Minimum {word} position is {}", ax.min),
            (b'X', None) => format!("* Maximum {word} position is {}", ax.max),
            (b'S', None) => format!("* Target {word} speed is {}", ax.speed as i64),
            (b'S', Some(0)) => {
                ax.target = ax.pos;
                "*".into()
            }
            (b'S', Some(n)) => {
                if n > ax.upper {
                    format!("! Maximum allowable {word} speed is {}", ax.upper)
                } else if n < ax.lower {
                    format!("! Minimum allowable {word} speed is {}", ax.lower)
                } else {
                    ax.speed = n as f64;
                    "*".into()
                }
            }
            (b'U', Some(n)) => {
                ax.upper = n;
                "*".into()
            }
            (b'L', Some(n)) => {
                ax.lower = n;
                "*".into()
            }
            (b'A' | b'B', Some(_)) => "*".into(),
            (b'H', None) if arg.is_empty() => {
                ax.target = ax.pos;
                "*".into()
            }
            (b'H', None) if matches!(arg, "L" | "R" | "O") => "*".into(),
            (b'M', None) if matches!(arg, "L" | "R" | "H") => "*".into(),
            _ => illegal,
        }
    }
}

/// A running emulated unit, reachable at a path (a symlink to its pty).
pub struct Ptu {
    pub link: PathBuf,
    pub state: Arc<Mutex<State>>,
    _cable: Cable,
}

const GPS: &str = "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47";

impl Ptu {
    /// Plugs a unit in at `link` (which must not exist).
    pub fn start(link: &Path) -> Ptu {
        let state = Arc::new(Mutex::new(State {
            pan: AxisState::new(-3090, 3090),
            tilt: AxisState::new(-907, 604),
            echo: true,
            limits: false,
            received: Vec::new(),
            last_rx: None,
            faults: Faults::default(),
        }));
        let st = state.clone();
        Ptu {
            link: link.to_path_buf(),
            state,
            _cable: Cable::plug(link, move |pty, stop| serve(pty, &st, stop)),
        }
    }

    /// Every byte received so far.
    pub fn received(&self) -> Vec<u8> {
        self.state.lock().received.clone()
    }

    /// Forgets what was received.
    pub fn clear_received(&self) {
        self.state.lock().received.clear();
    }

    /// The axes' positions, steps.
    pub fn position(&self) -> (i64, i64) {
        let s = self.state.lock();
        (s.pan.pos.round() as i64, s.tilt.pos.round() as i64)
    }

    pub fn set_faults(&self, f: Faults) {
        self.state.lock().faults = f;
    }

    /// The unit goes away: its pty closes and its path disappears.
    pub fn unplug(self) {}
}

fn serve(pty: Pty, state: &Mutex<State>, stop: &AtomicBool) {
    let mut tok: Vec<u8> = Vec::new();
    let mut buf = [0u8; 256];
    let mut last = Instant::now();
    while !stop.load(Ordering::Acquire) {
        let n = read_fd(&pty.master, Duration::from_millis(5), &mut buf).unwrap_or(0);
        let mut st = state.lock();
        let now = Instant::now();
        let dt = now.duration_since(last).as_secs_f64();
        last = now;
        st.pan.step(dt);
        st.tilt.step(dt);
        st.received.extend_from_slice(&buf[..n]);
        if n > 0 {
            st.last_rx = Some(Instant::now());
        }
        let mut out = Vec::new();
        for &c in &buf[..n] {
            if matches!(c, b' ' | b'\r' | b'\n') {
                if tok.is_empty() {
                    continue;
                }
                let f = st.faults;
                if f.silent {
                    tok.clear();
                    continue;
                }
                let answer = if f.garbage {
                    GPS.to_string()
                } else if f.refuse {
                    "! Illegal Command".to_string()
                } else if let Some(p) = f.pan_position
                    && tok.eq_ignore_ascii_case(b"PP")
                {
                    format!("* Current Pan position is {p}")
                } else {
                    st.answer(&tok)
                };
                if st.echo && !f.garbage && tok.iter().all(|c| c.is_ascii_graphic()) {
                    out.extend_from_slice(&tok);
                    out.push(b' ');
                }
                out.extend_from_slice(answer.as_bytes());
                out.extend_from_slice(b"\r\n");
                tok.clear();
            } else if tok.len() < 64 {
                tok.push(c);
            }
        }
        drop(st);
        if !out.is_empty() {
            write_fd(&pty.master, &out);
        }
    }
    // Dropping the pty closes both ends: the device is gone.
}
