//! Range sensors: the laser, the sonar ring and the bumpers. In this 2D world
//! every obstacle (walls, boxes, balls, other robots) is seen at any height.

use crate::interfaces::{Bumpers, Laser, Mount, Sonars};

use crate::world::{Point2, ray_circle};

use super::physics::Sim;

impl Sim {
    /// The nearest obstacle along the ray from `o` in unit direction `d`, within
    /// `max` mm, ignoring robot `me` itself.
    pub fn cast(&self, me: usize, o: Point2, d: Point2, max: f64) -> f64 {
        let mut best = self.world.cast(o, d, max).map_or(max, |(t, _)| t);
        for b in &self.balls {
            if let Some(t) = ray_circle(o, d, b.pos, b.radius) {
                best = best.min(t);
            }
        }
        for (k, r) in self.robots.iter().enumerate() {
            if k != me
                && let Some(t) = ray_circle(o, d, [r.pose.x, r.pose.y], r.model.radius)
            {
                best = best.min(t);
            }
        }
        best
    }

    /// Robot `i`'s laser scan into `out` (mm; N readings at R per degree centred
    /// on the laser's axis, counter-clockwise, the geometry in the value; readings
    /// with nothing in range give the maximum range).
    pub fn laser(&mut self, i: usize, out: &mut Laser) {
        let Some(r) = self.robots.get(i) else { return };
        let m = &r.model;
        let o = r.pose.apply(m.laser_pos);
        let (n, res, max, theta) = (
            m.laser_count,
            m.laser_resolution,
            m.laser_range,
            r.pose.theta,
        );
        let sigma = self.noise.laser;
        out.readings.resize(n, 0);
        out.resolution = res as f32;
        out.start = Laser::centred_start(n, res);
        out.min_range = 0.0;
        out.max_range = max as f32;
        out.mount = Mount {
            x: m.laser_pos[0] as f32,
            y: m.laser_pos[1] as f32,
            yaw: 0.0,
        };
        let start = out.start as f64;
        for k in 0..n {
            let a = theta + (start + k as f64 / res).to_radians();
            let t = self.cast(i, o, [a.cos(), a.sin()], max);
            let t = (t + self.rng.gauss(sigma)).clamp(0.0, max);
            out.readings[k] = t.round() as i32;
        }
    }

    /// Robot `i`'s sonars (mm): each reads the nearest echo within its cone.
    pub fn sonars(&mut self, i: usize, out: &mut Sonars) {
        let Some(r) = self.robots.get(i) else { return };
        let m = &r.model;
        let (max, half, pose) = (m.sonar_range, m.sonar_aperture, r.pose);
        let sigma = self.noise.sonars;
        let n = m.sonars.len();
        out.us.resize(n, 0.0);
        for k in 0..n {
            let (x, y, ang) = self.robots[i].model.sonars[k];
            let o = pose.apply([x, y]);
            let mut best = max;
            for j in -2..=2 {
                let a = pose.theta + (ang + half * j as f64 / 2.0).to_radians();
                best = best.min(self.cast(i, o, [a.cos(), a.sin()], max));
            }
            out.us[k] = (best + self.rng.gauss(sigma)).clamp(0.0, max) as f32;
        }
    }

    /// Robot `i`'s bumpers: 1 where it touched something in the last step.
    pub fn bumpers(&self, i: usize, out: &mut Bumpers) {
        out.bumpers.clear();
        if let Some(r) = self.robots.get(i) {
            out.bumpers.extend_from_slice(&r.bumpers);
        }
    }
}
