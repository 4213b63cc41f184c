//! The room both serial-robot emulators share (tests/emulators/create2.rs moves the
//! robot in it, tests/emulators/rplidar.rs measures it): a rectangle `w` × `h` mm
//! with walls at x = 0, x = w, y = 0, y = h, and the robot, a disc of the Create
//! 2's 348 mm diameter, at a pose (mm, mm, rad counter-clockwise from +x). The
//! lidar sits at the robot's centre, its forward axis the robot's.
#![allow(dead_code)]

use std::{
    path::{Path, PathBuf},
    sync::{Arc, atomic::AtomicBool},
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

/// The pty helpers of the PTU emulator (a serial cable into the device).
pub use super::ptu::{Cable, Pty, read_fd, write_fd};

/// How a device answers on its pty: with its state, in the room, until the flag is set.
pub type Serve<S> = fn(Pty, &Mutex<S>, &Shared, &AtomicBool);

/// A serial device in the room: its state, and the pty at `link` (a symlink) that
/// `serve` answers on while the cable is plugged in.
pub struct Device<S> {
    pub link: PathBuf,
    pub state: Arc<Mutex<S>>,
    pub room: Shared,
    serve: Serve<S>,
    cable: Option<Cable>,
}

impl<S: Send + 'static> Device<S> {
    /// The device, plugged in.
    pub fn new(link: &Path, room: Shared, state: S, serve: Serve<S>) -> Device<S> {
        let mut d = Device {
            link: link.to_path_buf(),
            state: Arc::new(Mutex::new(state)),
            room,
            serve,
            cable: None,
        };
        d.plug();
        d
    }

    /// (Re)connects the cable: a new pty at the link. The device keeps its state.
    pub fn plug(&mut self) {
        self.cable = None;
        let (st, room, serve) = (self.state.clone(), self.room.clone(), self.serve);
        self.cable = Some(Cable::plug(&self.link, move |pty, stop| {
            serve(pty, &st, &room, stop)
        }));
    }

    /// Pulls the cable: the pty closes and its path disappears.
    pub fn unplug(&mut self) {
        self.cable = None;
    }
}
