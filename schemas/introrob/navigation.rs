//! **Your code goes here**: the student hook of introrob (4.3's `navegacion.c`).
//!
//! Choose the `yourcode` behaviour (in the panel, or `behaviour yourcode` in the
//! conf) and introrob calls [`your_code`] once per iteration (every 100 ms) with a
//! [`Robot`] holding fresh sensor copies. Set `robot.v` (mm/s, forward) and
//! `robot.w` (deg/s, counter-clockwise); introrob writes them to the motors,
//! clamped to its `max_v`/`max_w`.
//!
//! What you have, as 4.3's globals:
//!
//! | 4.3 | here | units |
//! |---|---|---|
//! | `v`, `w` | `robot.v`, `robot.w` | mm/s, deg/s |
//! | `robot[5]` | `robot.robot` (also `robot.x()`, `robot.y()`, `robot.theta()`) | x, y mm; θ rad in (0, 2π]; cos θ; sin θ |
//! | `laser[180]` | `robot.laser.readings` | mm; reading i at `robot.laser_angle(i)` deg (4.3's 180: −90 + i, index 90 straight ahead) |
//! | `us[16]` | `robot.sonars` | mm, Pioneer ring order |
//! | `bumpers` | `robot.bumpers` | 1 while touching |
//! | `imagenRGB` | `robot.image` | 320×240 BGR, when the robot has a camera |
//! | `introrob_mouse_x/_y` | `robot.target` | absolute mm (the target clicked in the world view) |
//! | `absolutas2relativas` | [`Robot::absolutas2relativas`] (alias `to_relative`) | mm |
//! | `relativas2absolutas` | [`Robot::relativas2absolutas`] (alias `to_absolute`) | mm |
//! | `pintaSegmento` | [`Robot::draw_relative`], [`Robot::draw_absolute`] | shown in the world view |
//!
//! Keep your own memory between iterations in [`YourState`] (add fields to it).
//! See docs/introrob.md for a short tutorial.

use crate::interfaces::{Image, Laser};

/// A colour for your drawings (RGB).
pub type Rgb = [u8; 3];

/// A segment you asked to draw, in absolute world mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Drawing {
    pub a: [f32; 2],
    pub b: [f32; 2],
    pub color: Rgb,
}

/// What your code sees and sets each iteration.
#[derive(Clone, Debug, Default)]
pub struct Robot {
    /// Translation speed to command, mm/s (starts at the last command).
    pub v: f32,
    /// Rotation speed to command, deg/s counter-clockwise (starts at the last command).
    pub w: f32,
    /// 4.3's `robot[5]`: x mm, y mm, θ rad in (0, 2π], cos θ, sin θ.
    pub robot: [f32; 5],
    /// The laser scan with its geometry: `laser.readings[i]` mm at
    /// `laser.angle(i)` degrees (4.3's 180 readings: −90 + i, index 90 straight ahead).
    pub laser: Laser,
    /// Sonar ranges, mm (empty when the robot has no sonars).
    pub sonars: Vec<f32>,
    /// Bumpers: 1 while touching (5 front left to right, then 5 rear); empty
    /// when the robot has none.
    pub bumpers: Vec<u8>,
    /// The camera image (BGR), when the robot has a camera.
    pub image: Option<Image>,
    /// The current target, absolute mm.
    pub target: [f32; 2],
    /// Seconds since introrob started iterating.
    pub time: f64,
    /// What you drew this iteration (the world view shows it).
    pub drawings: Vec<Drawing>,
}

impl Robot {
    pub fn x(&self) -> f32 {
        self.robot[0]
    }
    pub fn y(&self) -> f32 {
        self.robot[1]
    }
    /// Heading, radians in (0, 2π].
    pub fn theta(&self) -> f32 {
        self.robot[2]
    }

    /// 4.3's `absolutas2relativas`: an absolute point (world mm) in the robot's frame
    /// (x ahead, y to the left, mm).
    pub fn absolutas2relativas(&self, p: [f32; 2]) -> [f32; 2] {
        absolute_to_relative(&self.robot, p)
    }
    /// 4.3's `relativas2absolutas`: a point in the robot's frame to world mm.
    pub fn relativas2absolutas(&self, p: [f32; 2]) -> [f32; 2] {
        relative_to_absolute(&self.robot, p)
    }
    /// Same as [`absolutas2relativas`](Self::absolutas2relativas).
    pub fn to_relative(&self, p: [f32; 2]) -> [f32; 2] {
        self.absolutas2relativas(p)
    }
    /// Same as [`relativas2absolutas`](Self::relativas2absolutas).
    pub fn to_absolute(&self, p: [f32; 2]) -> [f32; 2] {
        self.relativas2absolutas(p)
    }

    /// The angle of laser reading `i` in the robot's frame, degrees (0 ahead,
    /// positive to the left; the scan's own geometry and mounting).
    pub fn laser_angle(&self, i: usize) -> f32 {
        self.laser.robot_angle(i)
    }
    /// Laser reading `i` as a point in the robot's frame (mm, from where the laser
    /// is mounted).
    pub fn laser_point(&self, i: usize) -> Option<[f32; 2]> {
        (i < self.laser.readings.len()).then(|| self.laser.robot_point(i))
    }
    /// The shortest laser range (mm) between angles `from_deg` and `to_deg`
    /// (0 ahead, positive to the left), or `None` without readings there.
    pub fn min_laser(&self, from_deg: f32, to_deg: f32) -> Option<f32> {
        let (lo, hi) = (from_deg.min(to_deg), from_deg.max(to_deg));
        (0..self.laser.readings.len())
            .filter(|&i| (lo..=hi).contains(&self.laser_angle(i)))
            .map(|i| self.laser.readings[i] as f32)
            .reduce(f32::min)
    }

    /// Draws a segment given in the robot's frame (4.3's `pintaSegmento` on
    /// relative points).
    pub fn draw_relative(&mut self, a: [f32; 2], b: [f32; 2], color: Rgb) {
        let (a, b) = (self.to_absolute(a), self.to_absolute(b));
        self.drawings.push(Drawing { a, b, color });
    }
    /// Draws a segment given in world mm.
    pub fn draw_absolute(&mut self, a: [f32; 2], b: [f32; 2], color: Rgb) {
        self.drawings.push(Drawing { a, b, color });
    }
}

/// 4.3's formula: x' = x·c + y·s − X·c − Y·s; y' = y·c − x·s + X·s − Y·c, with
/// (X, Y, c, s) = `robot[0]`, `robot[1]`, `robot[3]`, `robot[4]`.
pub fn absolute_to_relative(robot: &[f32; 5], p: [f32; 2]) -> [f32; 2] {
    let (x0, y0, c, s) = (robot[0], robot[1], robot[3], robot[4]);
    [
        p[0] * c + p[1] * s - x0 * c - y0 * s,
        p[1] * c - p[0] * s + x0 * s - y0 * c,
    ]
}

/// 4.3's formula: x = x'·c − y'·s + X; y = y'·c + x'·s + Y.
pub fn relative_to_absolute(robot: &[f32; 5], p: [f32; 2]) -> [f32; 2] {
    let (x0, y0, c, s) = (robot[0], robot[1], robot[3], robot[4]);
    [p[0] * c - p[1] * s + x0, p[1] * c + p[0] * s + y0]
}

/// Your memory between iterations: add the fields you need.
#[derive(Clone, Debug, Default)]
pub struct YourState {
    /// Iterations so far (an example field).
    pub iterations: u64,
    /// Whether the sample is turning away from an obstacle.
    pub turning: bool,
}

/// **Write your behaviour here.** Called every introrob iteration while the
/// `yourcode` behaviour is chosen.
///
/// The sample is simple and safe: it drives ahead at 200 mm/s while the way ahead
/// is clear, and turns in place to the left when something is within 800 mm in
/// front (it resumes once it sees 1200 mm of free space). Like 4.3's sample it
/// also draws a relative segment (500, 500)→(0, 0) in red and an absolute one
/// from the origin to the robot in blue.
pub fn your_code(robot: &mut Robot, state: &mut YourState) {
    state.iterations += 1;
    let ahead = robot.min_laser(-30.0, 30.0).unwrap_or(0.0);
    if state.turning {
        state.turning = ahead < 1200.0;
    } else {
        state.turning = ahead < 800.0;
    }
    if state.turning {
        robot.v = 0.0;
        robot.w = 30.0;
    } else {
        robot.v = 200.0;
        robot.w = 0.0;
    }
    robot.draw_relative([500.0, 500.0], [0.0, 0.0], [255, 0, 0]);
    let here = [robot.x(), robot.y()];
    robot.draw_absolute([0.0, 0.0], here, [0, 0, 255]);
}
