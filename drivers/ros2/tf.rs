//! The robot's static transforms (`/tf_static`, as tf2's static listener reads
//! them) and the laser mount they give: the scan's frame placed in the root of
//! its static tree, the robot's base (`base_link`, or `base_footprint` on a
//! TurtleBot 3, whose `base_link` hangs from it).

use std::collections::HashMap;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::{
    interfaces::{Laser, Mount},
    mcapfmt::ros2::StampedTransform,
};

/// The static transforms heard so far, by child frame (a later one replaces an
/// earlier one of the same child, as in tf2's buffer).
#[derive(Default)]
pub struct Statics {
    parents: HashMap<String, (String, Isometry3<f64>)>,
}

impl Statics {
    /// At most this many frames are kept (a robot has tens): a flood of names
    /// does not grow the driver without bound.
    const MAX_FRAMES: usize = 10_000;
    /// The longest chain followed (a cycle ends there).
    const MAX_DEPTH: usize = 64;

    /// Takes a `TFMessage`'s transforms; those that are not a placement
    /// (a non-finite number, a zero quaternion) are left out and named.
    pub fn add(&mut self, transforms: Vec<StampedTransform>) -> Result<(), String> {
        let mut refused = vec![];
        for t in transforms {
            let [x, y, z] = t.translation;
            let [qx, qy, qz, qw] = t.rotation;
            let q = Quaternion::new(qw, qx, qy, qz);
            let finite = t
                .translation
                .iter()
                .chain(&t.rotation)
                .all(|v| v.is_finite());
            if !finite || q.norm() < 1e-9 {
                refused.push(format!(
                    "{} → {}: translation {:?}, rotation {:?}",
                    t.parent, t.child, t.translation, t.rotation
                ));
                continue;
            }
            if self.parents.len() >= Self::MAX_FRAMES && !self.parents.contains_key(&t.child) {
                refused.push(format!(
                    "{} → {}: over {} frames",
                    t.parent,
                    t.child,
                    Self::MAX_FRAMES
                ));
                continue;
            }
            let iso = Isometry3::from_parts(
                Translation3::new(x, y, z),
                UnitQuaternion::from_quaternion(q),
            );
            self.parents.insert(t.child, (t.parent, iso));
        }
        if refused.is_empty() {
            Ok(())
        } else {
            Err(format!("not a transform: {}", refused.join("; ")))
        }
    }

    /// Frame `frame` in the root of its static tree: (where, the root's name);
    /// None when no static transform has `frame` as its child.
    fn in_root(&self, frame: &str) -> Option<(Isometry3<f64>, &str)> {
        let (mut parent, mut iso) = self.parents.get(frame).map(|(p, i)| (p.as_str(), *i))?;
        for _ in 0..Self::MAX_DEPTH {
            match self.parents.get(parent) {
                Some((p, up)) if p != frame => {
                    iso = up * iso;
                    parent = p;
                }
                _ => break,
            }
        }
        Some((iso, parent))
    }

    /// The mount of a sensor in frame `frame` (x, y mm and yaw deg on the
    /// robot's plane; heights and tilts left out), and whether it is upside
    /// down (its z axis points down: its angles turn clockwise on the robot).
    pub fn mount(&self, frame: &str) -> Option<(Mount, bool)> {
        let (iso, _root) = self.in_root(frame)?;
        let ahead = iso.rotation * Vector3::x();
        let up = iso.rotation * Vector3::z();
        let round = |v: f64| (v * 1000.0).round() / 1000.0;
        let mut yaw = round(ahead.y.atan2(ahead.x).to_degrees());
        if yaw <= -180.0 {
            yaw += 360.0;
        }
        let mount = Mount {
            x: round(iso.translation.x * 1000.0) as f32,
            y: round(iso.translation.y * 1000.0) as f32,
            yaw: yaw as f32,
        };
        Some((mount, up.z < 0.0))
    }
}

/// Sets a scan's mount from the static transform of its frame, when there is
/// one (else it keeps its own: the robot's centre). An upside-down laser's
/// readings turn clockwise on the robot: they are read from the other end, so
/// the value's angles stay counter-clockwise.
pub fn mount_laser(laser: &mut Laser, statics: &Statics, frame: &str) {
    let Some((mount, upside_down)) = statics.mount(frame) else {
        return;
    };
    if upside_down {
        let end = laser.end();
        laser.readings.reverse();
        laser.start = -end;
    }
    laser.mount = mount;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tf(parent: &str, child: &str, xyz: [f64; 3], rpy: [f64; 3]) -> StampedTransform {
        let q = UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]);
        StampedTransform {
            parent: parent.into(),
            child: child.into(),
            translation: xyz,
            rotation: [q.i, q.j, q.k, q.w],
        }
    }

    #[test]
    fn a_chain_of_static_transforms_gives_the_mount_in_the_root() {
        let mut s = Statics::default();
        // A TurtleBot 3: base_footprint → base_link (up 1 cm) → base_scan.
        s.add(vec![
            tf("base_footprint", "base_link", [0.0, 0.0, 0.01], [0.0; 3]),
            tf("base_link", "base_scan", [-0.032, 0.0, 0.172], [0.0; 3]),
        ])
        .unwrap();
        let (m, flipped) = s.mount("base_scan").unwrap();
        assert_eq!((m.x, m.y, m.yaw, flipped), (-32.0, 0.0, 0.0, false));
        assert!(s.mount("camera").is_none());
        // Turned 180° about z, 10 cm ahead: yaw 180, not -180.
        s.add(vec![tf(
            "base_link",
            "laser",
            [0.1, 0.0, 0.0],
            [0.0, 0.0, std::f64::consts::PI],
        )])
        .unwrap();
        let (m, flipped) = s.mount("laser").unwrap();
        assert_eq!((m.x, m.y, m.yaw, flipped), (100.0, 0.0, 180.0, false));
        // Composed: 90° at (0.1, 0) then (0.2, 0) in that frame is (0.1, 0.2).
        s.add(vec![
            tf(
                "base_link",
                "mast",
                [0.1, 0.0, 0.3],
                [0.0, 0.0, std::f64::consts::FRAC_PI_2],
            ),
            tf("mast", "top", [0.2, 0.0, 0.0], [0.0, 0.0, -0.5]),
        ])
        .unwrap();
        let (m, _) = s.mount("top").unwrap();
        assert_eq!((m.x, m.y), (100.0, 200.0));
        assert!((m.yaw - (90.0 - 0.5f32.to_degrees())).abs() < 1e-3, "{m:?}");
        // A cycle ends.
        s.add(vec![
            tf("b", "a", [0.0; 3], [0.0; 3]),
            tf("a", "b", [0.0; 3], [0.0; 3]),
        ])
        .unwrap();
        assert!(s.mount("a").is_some());
        // Not a placement: refused and named.
        let bad = tf("base_link", "nan", [f64::NAN, 0.0, 0.0], [0.0; 3]);
        assert!(s.add(vec![bad]).unwrap_err().contains("base_link → nan"));
        assert!(s.mount("nan").is_none());
    }

    #[test]
    fn an_upside_down_laser_reads_from_the_other_end() {
        let mut s = Statics::default();
        s.add(vec![tf(
            "base_link",
            "laser",
            [0.05, 0.0, 0.2],
            [std::f64::consts::PI, 0.0, 0.0],
        )])
        .unwrap();
        let mut l = Laser {
            readings: vec![1, 2, 3],
            resolution: 1.0,
            start: -10.0,
            ..Laser::default()
        };
        mount_laser(&mut l, &s, "laser");
        // Reading 0 at -10° in the laser's frame is at +10° on the robot.
        assert_eq!((l.start, l.readings.clone()), (8.0, vec![3, 2, 1]));
        assert_eq!(l.robot_angle(2), 10.0);
        assert_eq!((l.mount.x, l.mount.yaw), (50.0, 0.0));
    }
}
