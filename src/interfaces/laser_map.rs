//! 4.3's laser from any scan: N readings at R per degree centred on the laser's
//! axis (reading i at −N/(2R) + i/R degrees, the value's `start` saying so), each
//! the nearest ray of the scan, in mm. The player and gazebo drivers resample their
//! scans through it; the value carries the geometry, so a 360° scan stays 360°.

use super::{Laser, Mount};

/// Maps a scan's rays to the asked N readings at R per degree, as 4.3 did, with
/// the ray of each reading cached per scan geometry.
#[derive(Clone, Debug)]
pub struct LaserMap {
    pub n: usize,
    pub per_deg: f64,
    /// Where the laser sits on the robot (the driver's knowledge).
    pub mount: Mount,
    /// The geometry the table is for: first angle, step (bits), ray count.
    key: (u64, u64, usize),
    /// The ray of each reading; `usize::MAX`: outside the scan.
    table: Vec<usize>,
}

impl LaserMap {
    pub fn new(n: usize, per_deg: f64) -> LaserMap {
        debug_assert!(per_deg > 0.0, "a declared resolution is positive");
        LaserMap {
            n,
            per_deg,
            mount: Mount::default(),
            key: (0, 0, usize::MAX),
            table: Vec::new(),
        }
    }

    /// The map for a laser mounted at `mount` on the robot.
    pub fn mounted(self, mount: Mount) -> LaserMap {
        LaserMap { mount, ..self }
    }

    /// The angle of reading 0, degrees: the N readings centred on the laser's axis.
    pub fn start(&self) -> f32 {
        Laser::centred_start(self.n, self.per_deg)
    }

    fn table(&mut self, min: f64, step: f64, count: usize) -> &[usize] {
        let key = (min.to_bits(), step.to_bits(), count);
        if key != self.key {
            self.key = key;
            self.table.clear();
            for i in 0..self.n {
                let deg = self.start() as f64 + i as f64 / self.per_deg;
                let k = if step.abs() > 0.0 && step.is_finite() {
                    ((deg.to_radians() - min) / step).round()
                } else {
                    -1.0
                };
                self.table.push(if k >= 0.0 && (k as usize) < count {
                    k as usize
                } else {
                    usize::MAX
                });
            }
        }
        &self.table
    }

    /// Fills `out` (mm) from a scan of `count` rays, the first at `min` rad and
    /// each `step` rad further, ray k being `range(k)` metres, and sets its
    /// geometry (start, resolution, range limits, the map's mount). A
    /// reading outside the scan, or whose ray has no return (inf, NaN, negative), is
    /// `max_range`.
    pub fn fill(
        &mut self,
        min: f64,
        step: f64,
        count: usize,
        max_range: f64,
        range: impl Fn(usize) -> f64,
        out: &mut Laser,
    ) {
        let mm = |m: f64| (m * 1000.0).round().min(i32::MAX as f64) as i32;
        let max_mm = if max_range.is_finite() && max_range > 0.0 {
            mm(max_range)
        } else {
            0
        };
        out.resolution = self.per_deg as f32;
        out.start = self.start();
        out.max_range = max_mm as f32;
        out.min_range = 0.0;
        out.mount = self.mount;
        let t = self.table(min, step, count);
        out.readings.clear();
        out.readings.extend(t.iter().map(|&k| {
            if k == usize::MAX {
                return max_mm;
            }
            let r = range(k);
            if r.is_finite() && r >= 0.0 {
                mm(r)
            } else {
                max_mm
            }
        }));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rays_in_mm_and_max_range_for_no_return_or_outside() {
        // 181 rays over the front half-plane, one per degree; ray k is k cm.
        let mut l = Laser::default();
        let mut m = LaserMap::new(180, 1.0);
        let step = 1f64.to_radians();
        m.fill(
            -90f64.to_radians(),
            step,
            181,
            8.0,
            |k| k as f64 / 100.0,
            &mut l,
        );
        assert_eq!(l.readings.len(), 180);
        assert_eq!(l.readings[0], 0);
        assert_eq!(l.readings[90], 900);
        // A narrower scan: readings outside it, and a ray with no return, are max range.
        m.fill(
            -10f64.to_radians(),
            step,
            21,
            8.0,
            |k| if k == 10 { f64::INFINITY } else { 1.0 },
            &mut l,
        );
        assert_eq!(l.readings[0], 8000);
        assert_eq!(l.readings[80], 1000);
        assert_eq!(l.readings[90], 8000);
        assert_eq!(l.readings[179], 8000);
    }
}
