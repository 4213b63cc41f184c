//! 4.3's laser from any scan: N readings at R per degree centred on the laser's
//! axis (reading i at −N/(2R) + i/R degrees, the value's `start` saying so), each
//! the nearest ray of the scan, in mm. The player and gazebo drivers resample their
//! scans through it; the value carries the geometry, so a 360° scan stays 360°.
//! [`Laser::jde43_readings`] maps a scan of any geometry to what 4.3's wire can say.

use std::borrow::Cow;

use super::{JDE43_LASER_MAX_RANGE, JDE43_LASER_START, Laser, Mount};

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
            // A scan that goes all the way round: an angle past its last ray is
            // one of its first (a 360° scan from 0° covers −90°).
            let round = step.is_finite()
                && (count as f64 * step).abs() >= std::f64::consts::TAU - step.abs() / 2.0;
            for i in 0..self.n {
                let deg = self.start() as f64 + i as f64 / self.per_deg;
                let mut k = if step.abs() > 0.0 && step.is_finite() {
                    ((deg.to_radians() - min) / step).round()
                } else {
                    -1.0
                };
                if round && k.is_finite() {
                    k = k.rem_euclid(count as f64);
                }
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

impl Laser {
    /// The readings 4.3's wire can say (`26 CLOCK R0 ..`, mm): N readings spread
    /// over 180° from −90° in the robot's frame, read by the other end as 4.3's
    /// laser (range 0..8000 mm, at the robot's centre). A scan already in that
    /// geometry (from −90°, N = 180 × resolution, not turned on the robot) goes as
    /// it is; any other is resampled to 180 readings at 1° from −90°, reading `a`
    /// being the scan's reading nearest to `a` degrees in the robot's frame (the
    /// mount's yaw taken off; its x, y offset cannot be said and is dropped).
    ///
    /// "Nothing" is 4.3's: a reading at the laser's maximum range. Since the
    /// other end takes 8000 mm as the maximum, a reading with no return, and a
    /// reading outside the scan's field of view, goes as the larger of the scan's
    /// `max_range` and 8000 mm, so that it never reads as an obstacle.
    pub fn jde43_readings(&self) -> Cow<'_, [i32]> {
        let nothing = self.max_range.max(JDE43_LASER_MAX_RANGE).round() as i32;
        let n = self.readings.len();
        let as_wire = self.start == JDE43_LASER_START
            && self.mount.yaw == 0.0
            && n > 0
            && (n as f64 - 180.0 * self.resolution as f64).abs() < 1e-3;
        if as_wire {
            if self.max_range >= JDE43_LASER_MAX_RANGE {
                return Cow::Borrowed(&self.readings);
            }
            let max = self.max_range;
            return Cow::Owned(
                self.readings
                    .iter()
                    .map(|&r| if r as f32 >= max { nothing } else { r })
                    .collect(),
            );
        }
        let mut out = Laser::default();
        let max = self.max_range;
        LaserMap::new(180, 1.0).fill(
            ((self.start + self.mount.yaw) as f64).to_radians(),
            (self.step() as f64).to_radians(),
            n,
            nothing as f64 / 1000.0,
            |k| {
                let r = self.readings[k];
                if r as f32 >= max {
                    f64::INFINITY
                } else {
                    r as f64 / 1000.0
                }
            },
            &mut out,
        );
        Cow::Owned(out.readings)
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

    /// A scan of `n` readings at 1° from `start`, reading i being 1000 + i mm.
    fn scan(n: usize, start: f32, max: f32) -> Laser {
        Laser {
            readings: (0..n as i32).map(|i| 1000 + i).collect(),
            start,
            max_range: max,
            ..Laser::default()
        }
    }

    #[test]
    fn the_4_3_wire_gets_180_readings_from_minus_90_whatever_the_scan() {
        // 4.3's own geometry goes as it is (not copied).
        let l = scan(180, -90.0, 8000.0);
        assert!(matches!(l.jde43_readings(), Cow::Borrowed(_)));
        // 360° from −180°: reading a is the source's at a.
        let l = scan(360, -180.0, 12000.0);
        let w = l.jde43_readings();
        assert_eq!(w.len(), 180);
        for (i, &r) in w.iter().enumerate() {
            let a = -90.0 + i as f32;
            assert_eq!(r, l.readings[l.index_at(a).unwrap()], "at {a}°");
        }
        // 360° from 0° (an RPLIDAR): −90° is 270°, round the back.
        let l = scan(360, 0.0, 12000.0);
        let w = l.jde43_readings();
        assert_eq!((w[0], w[90], w[179]), (1270, 1000, 1089));
        // Turned on the robot by 90°: the robot's −90° is the laser's −180°.
        let mut l = scan(360, -180.0, 12000.0);
        l.mount.yaw = 90.0;
        assert_eq!(l.jde43_readings()[0], 1000);
        // Half a scan (from −45°): outside it, and a reading with no return, are
        // "nothing", at least 8000 mm.
        let mut l = scan(90, -45.0, 5600.0);
        l.readings[45] = 5600;
        let w = l.jde43_readings();
        assert_eq!((w[44], w[45], w[134]), (8000, 1000, 1089));
        assert_eq!(w[90], 8000);
        assert_eq!(w[135], 8000);
        // 4.3's geometry with a shorter range: a no-return reading goes as 8000.
        let mut l = scan(180, -90.0, 5600.0);
        l.readings[3] = 5600;
        let w = l.jde43_readings();
        assert_eq!((w[2], w[3]), (1002, 8000));
        // 360 readings over 180° (2 per degree, as 4.3's `provides laser 360 2`) go as they are.
        let l = Laser {
            resolution: 2.0,
            ..scan(360, -90.0, 8000.0)
        };
        assert_eq!(l.jde43_readings().len(), 360);
    }
}
