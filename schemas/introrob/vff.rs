//! Virtual Force Field navigation: the target pulls the robot, laser points near
//! it push it away, and the resultant direction gives v and w.
//!
//! All forces are in the robot's frame (x ahead, y to the left). The attractive
//! force is a unit vector toward the target. Each laser reading whose obstacle is
//! closer than `influence` mm to the robot's edge pushes with magnitude
//! `((influence − clearance) / influence)²`, summed per degree of scan and scaled by
//! `k_rep / 30` (a wall filling 30° at the robot's edge pushes about as hard as
//! `k_rep` times the target pulls). The command turns toward the resultant (w
//! proportional to its angle), and drives ahead only when the resultant is within
//! `turn_in_place` degrees of the heading, slower near the target and when the
//! way ahead is short.

use crate::interfaces::{Encoders, Laser, Motors, limit};

use super::navigation::absolute_to_relative;

/// Tuning of the controller (all lengths in mm, speeds in mm/s and deg/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VffParams {
    pub max_v: f32,
    pub max_w: f32,
    /// Robot radius.
    pub radius: f32,
    /// Obstacles farther than this from the robot's edge do not push.
    pub influence: f32,
    /// Weight of the repulsive force against the unit attractive force.
    pub k_rep: f32,
    /// deg/s of w per degree of heading error.
    pub k_w: f32,
    /// The target counts as reached within this distance.
    pub arrive: f32,
    /// Start slowing down within this distance of the target.
    pub slow: f32,
    /// Above this heading error (deg) the robot turns in place.
    pub turn_in_place: f32,
    /// Free space ahead (from the robot's edge) below which it does not advance.
    pub stop_gap: f32,
}

impl Default for VffParams {
    fn default() -> Self {
        VffParams {
            max_v: 400.0,
            max_w: 40.0,
            radius: 250.0,
            influence: 800.0,
            k_rep: 1.5,
            k_w: 1.2,
            arrive: 150.0,
            slow: 700.0,
            turn_in_place: 60.0,
            stop_gap: 80.0,
        }
    }
}

/// The forces of one VFF step, robot frame (for drawing and tests).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Forces {
    pub attractive: [f32; 2],
    pub repulsive: [f32; 2],
    pub resultant: [f32; 2],
    /// The target in the robot's frame, mm.
    pub target: [f32; 2],
}

/// The result of one VFF step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VffOutput {
    pub motors: Motors,
    pub forces: Forces,
    /// Whether the target is reached (the command is then zero).
    pub arrived: bool,
}

/// The laser reading `i`'s obstacle in the robot's frame, mm (the scan's own
/// geometry and mounting).
pub fn laser_point(laser: &Laser, i: usize) -> [f32; 2] {
    laser.robot_point(i)
}

/// Smallest clearance (mm from the robot's edge) of the laser obstacles within
/// `half_width` of the robot's path ahead (a corridor as wide as the robot plus a
/// margin), or `f32::INFINITY` when none.
pub fn gap_ahead(laser: &Laser, radius: f32, half_width: f32) -> f32 {
    (0..laser.readings.len())
        .map(|i| laser_point(laser, i))
        .filter(|p| p[0] > 0.0 && p[1].abs() < half_width)
        .map(|p| p[0] - radius)
        .fold(f32::INFINITY, f32::min)
}

/// The VFF forces toward `target` (world mm) from `pose` with this scan.
pub fn forces(pose: &Encoders, laser: &Laser, target: [f32; 2], p: &VffParams) -> Forces {
    let t = absolute_to_relative(&pose.robot(), target);
    let d = (t[0] * t[0] + t[1] * t[1]).sqrt();
    let attractive = if d > 1e-3 {
        [t[0] / d, t[1] / d]
    } else {
        [0.0, 0.0]
    };
    // Each reading weighs its angular width, so any resolution gives the same force.
    let per_degree = laser.step();
    let mut rep = [0.0f32, 0.0];
    let influence = p.influence.max(1.0);
    for i in 0..laser.readings.len() {
        let q = laser_point(laser, i);
        let dist = (q[0] * q[0] + q[1] * q[1]).sqrt();
        if dist < 1e-3 {
            continue;
        }
        let clearance = (dist - p.radius).max(0.0);
        if clearance >= influence {
            continue;
        }
        let m = ((influence - clearance) / influence).powi(2) * per_degree;
        rep[0] -= m * q[0] / dist;
        rep[1] -= m * q[1] / dist;
    }
    let k = p.k_rep / 30.0;
    let repulsive = [rep[0] * k, rep[1] * k];
    Forces {
        attractive,
        repulsive,
        resultant: [attractive[0] + repulsive[0], attractive[1] + repulsive[1]],
        target: t,
    }
}

/// Turns a desired direction (robot frame) into v/w, given the distance still to
/// go and the scan (for the free space ahead).
pub fn steer(dir: [f32; 2], dist: f32, laser: &Laser, p: &VffParams) -> Motors {
    let err = dir[1].atan2(dir[0]).to_degrees();
    let err = if err.is_finite() { err } else { 0.0 };
    let w = limit(p.k_w * err, -p.max_w, p.max_w);
    let mut v = 0.0;
    let mut w = w;
    if err.abs() < p.turn_in_place {
        let align = (err.to_radians().cos()).max(0.0).powi(2);
        let near = (dist / p.slow.max(1.0)).clamp(0.15, 1.0);
        let gap = gap_ahead(laser, p.radius, p.radius + 50.0);
        let room = ((gap - p.stop_gap) / 600.0).clamp(0.0, 1.0);
        v = p.max_v * align * near * room;
        if room < 0.05 {
            // Blocked ahead while the forces say "ahead" (a local minimum): turn
            // toward the freer side until the way is clear.
            v = 0.0;
            w = 0.6 * p.max_w * freer_side(laser);
        }
    }
    Motors { v, w }
}

/// +1 if the front-left quadrant has more free space than the front-right one
/// (nearest obstacle farther away), else −1.
pub fn freer_side(laser: &Laser) -> f32 {
    let (mut left, mut right) = (f32::INFINITY, f32::INFINITY);
    for i in 0..laser.readings.len() {
        let q = laser_point(laser, i);
        if q[0] < -50.0 {
            continue;
        }
        let d = (q[0] * q[0] + q[1] * q[1]).sqrt();
        if q[1] >= 0.0 {
            left = left.min(d);
        } else {
            right = right.min(d);
        }
    }
    if left >= right { 1.0 } else { -1.0 }
}

/// One VFF step toward `target` (world mm).
pub fn command(pose: &Encoders, laser: &Laser, target: [f32; 2], p: &VffParams) -> VffOutput {
    let f = forces(pose, laser, target, p);
    let dist = (f.target[0].powi(2) + f.target[1].powi(2)).sqrt();
    if dist < p.arrive {
        return VffOutput {
            motors: Motors::default(),
            forces: f,
            arrived: true,
        };
    }
    VffOutput {
        motors: steer(f.resultant, dist, laser, p),
        forces: f,
        arrived: false,
    }
}
