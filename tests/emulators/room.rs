//! The room both serial-robot emulators share (tests/emulators/create2.rs moves the
//! robot in it, tests/emulators/rplidar.rs measures it): a rectangle `w` × `h` mm
//! with walls at x = 0, x = w, y = 0, y = h, and the robot, a disc of the Create
//! 2's 348 mm diameter, at a pose (mm, mm, rad counter-clockwise from +x). The
//! lidar sits at the robot's centre, its forward axis the robot's.
#![allow(dead_code)]

use std::{
    os::fd::{AsRawFd, FromRawFd, OwnedFd},
    path::PathBuf,
    sync::Arc,
    time::Duration,
};

use parking_lot::Mutex;

/// The Create 2's radius, mm (348 mm across, its specification's outline).
pub const ROBOT_RADIUS: f64 = 174.0;

#[derive(Clone, Debug)]
pub struct Room {
    pub w: f64,
    pub h: f64,
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    /// Whether the robot ever touched a wall.
    pub touched: bool,
}

pub type Shared = Arc<Mutex<Room>>;

impl Room {
    pub fn new(w: f64, h: f64, x: f64, y: f64, theta_deg: f64) -> Shared {
        Arc::new(Mutex::new(Room {
            w,
            h,
            x,
            y,
            theta: theta_deg.to_radians(),
            touched: false,
        }))
    }

    /// The distance from (x, y) along `dir` (rad, room frame) to the first wall, mm.
    pub fn ray(&self, x: f64, y: f64, dir: f64) -> f64 {
        let (c, s) = (dir.cos(), dir.sin());
        let mut best = f64::INFINITY;
        if c > 1e-12 {
            best = best.min((self.w - x) / c);
        } else if c < -1e-12 {
            best = best.min(-x / c);
        }
        if s > 1e-12 {
            best = best.min((self.h - y) / s);
        } else if s < -1e-12 {
            best = best.min(-y / s);
        }
        best.max(0.0)
    }

    /// The walls the robot's disc at (x, y), `margin` mm larger, touches: for each,
    /// the direction from the centre to the contact (rad, room frame).
    pub fn contacts(&self, x: f64, y: f64, margin: f64) -> Vec<f64> {
        let r = ROBOT_RADIUS + margin;
        let mut v = Vec::new();
        if x - r <= 0.0 {
            v.push(std::f64::consts::PI);
        }
        if x + r >= self.w {
            v.push(0.0);
        }
        if y - r <= 0.0 {
            v.push(-std::f64::consts::FRAC_PI_2);
        }
        if y + r >= self.h {
            v.push(std::f64::consts::FRAC_PI_2);
        }
        v
    }
}

/// `a` wrapped to (−π, π].
pub fn wrap(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    let mut a = a.rem_euclid(t);
    if a > std::f64::consts::PI {
        a -= t;
    }
    a
}

// The pty helpers, as the PTU emulator (tests/emulators/ptu.rs) has them.

/// A pseudo-terminal pair with the slave in raw mode.
pub struct Pty {
    pub master: OwnedFd,
    pub slave: OwnedFd,
    pub slave_path: PathBuf,
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
