//! The simulation proper: robots (discs with acceleration limits, odometry and a
//! pan-tilt unit), rolling balls and collisions, advanced by [`Sim::step`]. A plain
//! struct with no threads, deterministic for a given seed.

use crate::interfaces::{Encoders, Imu, Motors, Mount, PtEncoders, PtMotors};

use crate::world::{Ball, Point2, Rule, Score, Scorer, Segment, World, closest_on_segment};

/// A tiny deterministic random number generator (xorshift64*), with Gaussian draws.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        // splitmix64 of the seed, so that nearby seeds give unrelated streams.
        let mut z = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        Rng((z ^ (z >> 31)) | 1)
    }
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Normal with mean 0 and standard deviation `sigma` (0 draws nothing).
    pub fn gauss(&mut self, sigma: f64) -> f64 {
        if sigma <= 0.0 {
            return 0.0;
        }
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        sigma * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// Noise levels (all zero by default).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Noise {
    /// Odometry: standard deviation of the travelled distance, as a fraction of it.
    pub odometry_distance: f64,
    /// Odometry: standard deviation of the turned angle, as a fraction of it.
    pub odometry_angle: f64,
    /// Laser range standard deviation, mm.
    pub laser: f64,
    /// Sonar range standard deviation, mm.
    pub sonars: f64,
}

/// The robot model (a Pioneer 2/3-DX by default).
#[derive(Clone, Debug, PartialEq)]
pub struct RobotModel {
    /// The robot is a disc of this radius, mm.
    pub radius: f64,
    /// |v| limit, mm/s (the seed's MAX_VEL).
    pub max_v: f64,
    /// |w| limit, deg/s (the seed's MAX_RVEL).
    pub max_w: f64,
    /// Linear acceleration limit, mm/s².
    pub accel_v: f64,
    /// Angular acceleration limit, deg/s².
    pub accel_w: f64,
    /// Laser: readings, readings per degree, maximum range mm, position (x, y) mm on the robot.
    pub laser_count: usize,
    pub laser_resolution: f64,
    pub laser_range: f64,
    pub laser_pos: Point2,
    /// Sonars: (x mm, y mm, angle deg) on the robot; range mm; half-aperture deg.
    pub sonars: Vec<(f64, f64, f64)>,
    pub sonar_range: f64,
    pub sonar_aperture: f64,
    /// Camera (on the pan-tilt unit): position (x, y) on the robot and height, mm.
    pub camera_pos: Point2,
    pub camera_height: f64,
    /// Horizontal field of view, degrees.
    pub camera_fov: f64,
    /// Pan-tilt limits and speed limit, as in [`PtMotors::default`].
    pub pantilt: PtMotors,
}

/// The 16-sonar Pioneer ring (R430 libs/pioneer): (x mm, y mm, angle deg).
pub const PIONEER_SONARS: [(f64, f64, f64); 16] = [
    (115.0, 130.0, 90.0),
    (155.0, 115.0, 50.0),
    (190.0, 80.0, 30.0),
    (210.0, 25.0, 10.0),
    (210.0, -25.0, 350.0),
    (190.0, -80.0, 330.0),
    (155.0, -115.0, 310.0),
    (115.0, -130.0, 270.0),
    (-115.0, -130.0, 270.0),
    (-155.0, -115.0, 230.0),
    (-190.0, -80.0, 210.0),
    (-210.0, -25.0, 190.0),
    (-210.0, 25.0, 170.0),
    (-190.0, 80.0, 150.0),
    (-155.0, 115.0, 130.0),
    (-115.0, 130.0, 90.0),
];

/// Bumpers (the seed's NUM_BUMPERS): 5 front, 5 rear.
pub const NUM_BUMPERS: usize = 10;

impl Default for RobotModel {
    fn default() -> Self {
        RobotModel {
            radius: 250.0,
            max_v: 1000.0,
            max_w: 180.0,
            accel_v: 300.0,
            accel_w: 100.0,
            laser_count: 180,
            laser_resolution: 1.0,
            laser_range: 8000.0,
            laser_pos: [Mount::PIONEER_LASER.x as f64, Mount::PIONEER_LASER.y as f64],
            sonars: PIONEER_SONARS.to_vec(),
            sonar_range: 5000.0,
            sonar_aperture: 12.5,
            camera_pos: [190.0, 0.0],
            camera_height: 500.0,
            camera_fov: 65.0,
            pantilt: PtMotors::default(),
        }
    }
}

/// A 2D pose: x, y mm; theta radians.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pose {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
}

impl Pose {
    pub fn new(x: f64, y: f64, theta_deg: f64) -> Pose {
        Pose {
            x,
            y,
            theta: theta_deg.to_radians(),
        }
    }
    /// A point given in the robot's frame, in world coordinates.
    pub fn apply(&self, p: Point2) -> Point2 {
        let (s, c) = self.theta.sin_cos();
        [self.x + c * p[0] - s * p[1], self.y + s * p[0] + c * p[1]]
    }
}

/// One simulated robot.
#[derive(Clone, Debug)]
pub struct Robot {
    pub name: String,
    pub model: RobotModel,
    /// Where it really is.
    pub pose: Pose,
    /// Where its odometry thinks it is.
    pub odom: Pose,
    /// Current speeds: mm/s, deg/s.
    pub v: f64,
    pub w: f64,
    /// Forward acceleration in the last step, mm/s².
    pub accel: f64,
    /// The command being followed.
    pub cmd: Motors,
    pub pan: f64,
    pub tilt: f64,
    pub pt_cmd: PtMotors,
    /// Blocked by an obstacle in the last step.
    pub stalled: bool,
    /// Bumper flags from the last step.
    pub bumpers: [u8; NUM_BUMPERS],
    /// Total distance travelled, mm.
    pub odometer: f64,
}

impl Robot {
    /// Pan-tilt: towards the (clamped) target at the commanded speed; speed 0
    /// means the unit's maximum speed (as the EVI driver did).
    fn step_pantilt(&mut self, dt: f64) {
        let (lim, c) = (self.model.pantilt, self.pt_cmd);
        let pan = (
            lim.min_longitude,
            lim.max_longitude,
            lim.max_longitude_speed,
        );
        let tilt = (lim.min_latitude, lim.max_latitude, lim.max_latitude_speed);
        self.pan = pt_axis(self.pan, (c.longitude, c.longitude_speed), pan, dt);
        self.tilt = pt_axis(self.tilt, (c.latitude, c.latitude_speed), tilt, dt);
    }
}

/// One pan-tilt axis after `dt`: from `cur` towards the (target, speed) command
/// within the (min, max, max speed) limits.
fn pt_axis(
    cur: f64,
    (target, speed): (f32, f32),
    (lo, hi, max_speed): (f32, f32, f32),
    dt: f64,
) -> f64 {
    let target = if target.is_finite() {
        target.clamp(lo, hi) as f64
    } else {
        cur
    };
    let sp = if speed.is_finite() && speed > 0.0 {
        speed.min(max_speed)
    } else {
        max_speed
    } as f64;
    cur + (target - cur).clamp(-sp * dt, sp * dt)
}

/// Which bumper a contact at `c` (world direction from the robot) presses on a
/// robot heading `theta` radians.
fn bumper_at(c: Point2, theta: f64) -> usize {
    let a = (c[1].atan2(c[0]) - theta).to_degrees().rem_euclid(360.0);
    let a = if a > 180.0 { a - 360.0 } else { a };
    if a.abs() <= 90.0 {
        // Front: five sectors from left (+90) to right (-90).
        ((90.0 - a) / 36.0).floor().clamp(0.0, 4.0) as usize
    } else {
        // Rear: five sectors from right to left.
        let b = if a > 0.0 { a - 90.0 } else { a + 270.0 };
        5 + ((b / 36.0).floor().clamp(0.0, 4.0) as usize)
    }
}

/// Where one step takes a robot ([`Sim::plan_move`]).
struct Move {
    start: Pose,
    pose: Pose,
    /// Speeds after the acceleration limits: mm/s, deg/s.
    v: f64,
    w: f64,
    /// The fraction of the step it drove before a contact (1 without).
    frac: f64,
    /// The obstacle's direction at the contact.
    contact: Option<Point2>,
}

/// Restitution of ball bounces.
const RESTITUTION: f64 = 0.6;

/// The simulation: a world, its robots and balls, the time and the noise source.
#[derive(Clone, Debug)]
pub struct Sim {
    pub world: World,
    pub robots: Vec<Robot>,
    pub balls: Vec<Ball>,
    /// Simulated seconds since the start.
    pub time: f64,
    pub noise: Noise,
    pub rng: Rng,
    /// The exercise's score, kept from the first robot's true pose after each
    /// step ([`Sim::start_score`]).
    pub scorer: Option<Scorer>,
}

impl Sim {
    /// A simulation of `world` with no robots; `seed` drives all noise.
    pub fn new(mut world: World, seed: u64) -> Sim {
        world.finish();
        let balls = world.balls.iter().map(Ball::from).collect();
        Sim {
            world,
            robots: Vec::new(),
            balls,
            time: 0.0,
            noise: Noise::default(),
            rng: Rng::new(seed),
            scorer: None,
        }
    }

    /// Adds a robot at (x, y) mm heading `theta_deg`; returns its index. Its
    /// odometry starts at the same pose (like the player driver's `initial_position`).
    pub fn add_robot(
        &mut self,
        name: &str,
        model: RobotModel,
        x: f64,
        y: f64,
        theta_deg: f64,
    ) -> usize {
        let pose = Pose::new(x, y, theta_deg);
        self.robots.push(Robot {
            name: name.to_string(),
            pose,
            odom: pose,
            v: 0.0,
            w: 0.0,
            cmd: Motors::default(),
            // The unit starts where its command points (`camera_tilt`).
            pan: model.pantilt.longitude as f64,
            tilt: model.pantilt.latitude as f64,
            pt_cmd: PtMotors {
                longitude_speed: 0.0,
                latitude_speed: 0.0,
                ..model.pantilt
            },
            accel: 0.0,
            stalled: false,
            bumpers: [0; NUM_BUMPERS],
            odometer: 0.0,
            model,
        });
        self.robots.len() - 1
    }

    /// Keeps `rule`'s score from now on, for the first robot from where it stands
    /// (the clock counts from this time). Errors say what the world lacks for it
    /// (targets, a closed painted line, walls) or that there is no robot.
    pub fn start_score(&mut self, rule: Rule) -> Result<(), String> {
        let r = self.robots.first().ok_or("the score needs a robot")?;
        let p = [r.pose.x, r.pose.y];
        let mut s = Scorer::new(rule, &self.world, p, r.pose.theta, r.model.radius)?;
        s.update(p, self.time);
        self.scorer = Some(s);
        Ok(())
    }

    /// The score as it stands, if one is kept ([`Sim::start_score`]).
    pub fn score(&self) -> Option<&Score> {
        self.scorer.as_ref().map(Scorer::score)
    }

    /// Sets robot `i`'s base command (the motors interface).
    pub fn set_motors(&mut self, i: usize, m: Motors) {
        if let Some(r) = self.robots.get_mut(i) {
            r.cmd = m;
        }
    }

    /// Sets robot `i`'s pan-tilt command (the pantiltmotors interface); its limits
    /// are the unit's own, whatever the command says.
    pub fn set_pantilt(&mut self, i: usize, m: PtMotors) {
        if let Some(r) = self.robots.get_mut(i) {
            r.pt_cmd = m;
        }
    }

    /// Robot `i`'s odometry, in the seed's encoders layout.
    /// Robot `i`'s IMU, in SI units: its true heading (an IMU does not drift
    /// with the wheels, unlike odometry), its turn rate, and what an
    /// accelerometer on it reads: the forward acceleration, the centripetal v·ω
    /// to the left, and gravity (up, the ground pushing back).
    pub fn imu(&self, i: usize) -> Imu {
        let Some(r) = self.robots.get(i) else {
            return Imu::default();
        };
        let half = r.pose.theta / 2.0;
        let w = r.w.to_radians();
        Imu {
            qz: half.sin() as f32,
            qw: half.cos() as f32,
            wz: w as f32,
            ax: (r.accel / 1000.0) as f32,
            ay: (r.v / 1000.0 * w) as f32,
            az: 9.80665,
            ..Imu::default()
        }
    }

    pub fn encoders(&self, i: usize) -> Encoders {
        let o = self.robots.get(i).map(|r| r.odom).unwrap_or_default();
        Encoders::from_pose(o.x as f32, o.y as f32, o.theta as f32)
    }

    /// Robot `i`'s pan-tilt angles.
    pub fn pantilt_encoders(&self, i: usize) -> PtEncoders {
        self.robots
            .get(i)
            .map(|r| PtEncoders {
                pan_angle: r.pan as f32,
                tilt_angle: r.tilt as f32,
            })
            .unwrap_or_default()
    }

    /// Whether a disc at `p` of radius `r` overlaps a wall, a box or another robot.
    /// Returns the direction from `p` to the contact.
    fn blocked(&self, me: usize, p: Point2, r: f64) -> Option<Point2> {
        let mut hit: Option<(f64, Point2)> = None;
        self.world.near(p, r, |s: &Segment| {
            let q = closest_on_segment(p, s);
            let d2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
            if d2 < r * r && hit.is_none_or(|(h, _)| d2 < h) {
                hit = Some((d2, [q[0] - p[0], q[1] - p[1]]));
            }
        });
        for (k, o) in self.robots.iter().enumerate() {
            if k == me {
                continue;
            }
            let d = [o.pose.x - p[0], o.pose.y - p[1]];
            let d2 = d[0] * d[0] + d[1] * d[1];
            let rr = r + o.model.radius;
            if d2 < rr * rr && hit.is_none_or(|(h, _)| d2 < h) {
                hit = Some((d2, d));
            }
        }
        hit.map(|(_, d)| d)
    }

    /// Advances the world by `dt` seconds (use steps of 1-20 ms).
    pub fn step(&mut self, dt: f64) {
        if !(dt > 0.0 && dt.is_finite()) {
            return;
        }
        for i in 0..self.robots.len() {
            self.step_robot(i, dt);
        }
        self.step_balls(dt);
        self.time += dt;
        if let (Some(s), Some(r)) = (&mut self.scorer, self.robots.first()) {
            s.update([r.pose.x, r.pose.y], self.time);
        }
    }

    fn step_robot(&mut self, i: usize, dt: f64) {
        let mv = self.plan_move(i, dt);
        let noise = self.noise.clone();
        let rng = &mut self.rng;
        let r = &mut self.robots[i];
        let ds = mv.v * dt * mv.frac;
        let dth = mv.pose.theta - mv.start.theta;
        r.pose = Pose {
            theta: mv.pose.theta.rem_euclid(std::f64::consts::TAU),
            ..mv.pose
        };
        let new_v = if mv.contact.is_some() { 0.0 } else { mv.v };
        r.accel = (new_v - r.v) / dt;
        r.v = new_v;
        r.w = mv.w;
        r.stalled = mv.contact.is_some();
        r.odometer += ds.abs();
        r.bumpers = [0; NUM_BUMPERS];
        if let Some(c) = mv.contact {
            r.bumpers[bumper_at(c, r.pose.theta)] = 1;
        }
        // Odometry: integrate what really happened, with noise.
        let ds_n = ds * (1.0 + rng.gauss(noise.odometry_distance));
        let dth_n = dth * (1.0 + rng.gauss(noise.odometry_angle));
        let mid = r.odom.theta + dth_n / 2.0;
        r.odom.x += ds_n * mid.cos();
        r.odom.y += ds_n * mid.sin();
        r.odom.theta = (r.odom.theta + dth_n).rem_euclid(std::f64::consts::TAU);
        r.step_pantilt(dt);
    }

    /// Robot i's speeds after the acceleration limits, and where the arc they
    /// drive over `dt` ends: at the first contact when it meets an obstacle.
    fn plan_move(&self, i: usize, dt: f64) -> Move {
        let r = &self.robots[i];
        let m = &r.model;
        let finite = |x: f32| if x.is_finite() { x as f64 } else { 0.0 };
        let tv = finite(r.cmd.v).clamp(-m.max_v, m.max_v);
        let tw = finite(r.cmd.w).clamp(-m.max_w, m.max_w);
        let v = r.v + (tv - r.v).clamp(-m.accel_v * dt, m.accel_v * dt);
        let w = r.w + (tw - r.w).clamp(-m.accel_w * dt, m.accel_w * dt);
        let start = r.pose;
        let radius = m.radius;
        // Exact arc for constant (v, w) over a fraction f of the step.
        let at = |f: f64| -> Pose {
            let t = dt * f;
            let wr = w.to_radians();
            let th = start.theta + wr * t;
            let (x, y) = if wr.abs() < 1e-9 {
                (
                    start.x + v * t * start.theta.cos(),
                    start.y + v * t * start.theta.sin(),
                )
            } else {
                (
                    start.x + v / wr * (th.sin() - start.theta.sin()),
                    start.y - v / wr * (th.cos() - start.theta.cos()),
                )
            };
            Pose { x, y, theta: th }
        };
        let mut mv = Move {
            start,
            pose: at(1.0),
            v,
            w,
            frac: 1.0,
            contact: None,
        };
        // A robot that starts inside an obstacle may still move away from it.
        let escaping = |pose: Pose| {
            self.blocked(i, [start.x, start.y], radius)
                .is_some_and(|s| (pose.x - start.x) * s[0] + (pose.y - start.y) * s[1] < 0.0)
        };
        if v != 0.0
            && let Some(c) = self.blocked(i, [mv.pose.x, mv.pose.y], radius)
            && !escaping(mv.pose)
        {
            // Find how far it can go: bisect the free fraction of the step.
            mv.contact = Some(c);
            let (mut lo, mut hi) = (0.0, 1.0);
            for _ in 0..12 {
                let mid = 0.5 * (lo + hi);
                let p = at(mid);
                if self.blocked(i, [p.x, p.y], radius).is_some() {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            mv.frac = lo;
            let p = at(lo);
            // Stop there, but finish the turn in place (a disc can always turn).
            mv.pose = Pose {
                x: p.x,
                y: p.y,
                theta: start.theta + w.to_radians() * dt,
            };
        }
        mv
    }

    fn step_balls(&mut self, dt: f64) {
        let n = self.balls.len();
        if n == 0 {
            return;
        }
        // Robots push balls: the robot is much heavier, so only the ball's speed changes.
        for ri in 0..self.robots.len() {
            let rb = &self.robots[ri];
            let (rp, rr) = ([rb.pose.x, rb.pose.y], rb.model.radius);
            let rv = [rb.v * rb.pose.theta.cos(), rb.v * rb.pose.theta.sin()];
            for b in &mut self.balls {
                let min = rr + b.radius;
                let Some((nrm, _)) = overlap(rp, b.pos, min) else {
                    continue;
                };
                let rel = (rv[0] - b.vel[0]) * nrm[0] + (rv[1] - b.vel[1]) * nrm[1];
                if rel > 0.0 {
                    b.vel[0] += (1.0 + RESTITUTION) * rel * nrm[0];
                    b.vel[1] += (1.0 + RESTITUTION) * rel * nrm[1];
                }
                b.pos = [rp[0] + nrm[0] * (min + 0.1), rp[1] + nrm[1] * (min + 0.1)];
            }
        }
        // Ball-ball: equal masses.
        for a in 0..n {
            for c in a + 1..n {
                let (l, r) = self.balls.split_at_mut(c);
                let (p, q) = (&mut l[a], &mut r[0]);
                let min = p.radius + q.radius;
                let Some((nrm, dist)) = overlap(p.pos, q.pos, min) else {
                    continue;
                };
                let rel = (p.vel[0] - q.vel[0]) * nrm[0] + (p.vel[1] - q.vel[1]) * nrm[1];
                if rel > 0.0 {
                    let j = (1.0 + RESTITUTION) * rel / 2.0;
                    p.vel = [p.vel[0] - j * nrm[0], p.vel[1] - j * nrm[1]];
                    q.vel = [q.vel[0] + j * nrm[0], q.vel[1] + j * nrm[1]];
                }
                let push = (min - dist) / 2.0 + 0.05;
                p.pos = [p.pos[0] - push * nrm[0], p.pos[1] - push * nrm[1]];
                q.pos = [q.pos[0] + push * nrm[0], q.pos[1] + push * nrm[1]];
            }
        }
        for bi in 0..n {
            let b = &mut self.balls[bi];
            // Rolling friction, then motion in sub-steps short enough not to tunnel.
            let speed = (b.vel[0] * b.vel[0] + b.vel[1] * b.vel[1]).sqrt();
            if speed > 0.0 {
                let ns = (speed - b.friction * dt).max(0.0);
                b.vel = [b.vel[0] * ns / speed, b.vel[1] * ns / speed];
            }
            let travel = speed * dt;
            let subs = ((travel / (b.radius * 0.5)).ceil() as usize).clamp(1, 64);
            for _ in 0..subs {
                let b = &mut self.balls[bi];
                b.pos = [
                    b.pos[0] + b.vel[0] * dt / subs as f64,
                    b.pos[1] + b.vel[1] * dt / subs as f64,
                ];
                let (p, r) = (b.pos, b.radius);
                let mut fix: Vec<(Point2, Point2)> = Vec::new();
                self.world.near(p, r, |s: &Segment| {
                    let q = closest_on_segment(p, s);
                    let d = [p[0] - q[0], p[1] - q[1]];
                    let dist = (d[0] * d[0] + d[1] * d[1]).sqrt();
                    if dist < r {
                        let nrm = if dist > 1e-9 {
                            [d[0] / dist, d[1] / dist]
                        } else {
                            s.normal.unwrap_or([1.0, 0.0])
                        };
                        fix.push((q, nrm));
                    }
                });
                let b = &mut self.balls[bi];
                for (q, nrm) in fix {
                    let d = (b.pos[0] - q[0]) * nrm[0] + (b.pos[1] - q[1]) * nrm[1];
                    if d < b.radius {
                        b.pos = [
                            b.pos[0] + (b.radius - d + 0.05) * nrm[0],
                            b.pos[1] + (b.radius - d + 0.05) * nrm[1],
                        ];
                    }
                    let vn = b.vel[0] * nrm[0] + b.vel[1] * nrm[1];
                    if vn < 0.0 {
                        b.vel = [
                            b.vel[0] - (1.0 + RESTITUTION) * vn * nrm[0],
                            b.vel[1] - (1.0 + RESTITUTION) * vn * nrm[1],
                        ];
                    }
                }
            }
        }
        // A ball pinned between a robot and a wall blocks the robot: it backs off.
        for ri in 0..self.robots.len() {
            let (rp, rr) = (
                [self.robots[ri].pose.x, self.robots[ri].pose.y],
                self.robots[ri].model.radius,
            );
            for b in &self.balls {
                let d = [b.pos[0] - rp[0], b.pos[1] - rp[1]];
                let dist = (d[0] * d[0] + d[1] * d[1]).sqrt();
                let overlap = rr + b.radius - dist;
                if overlap > 0.5 && dist > 1e-9 {
                    let r = &mut self.robots[ri];
                    r.pose.x -= d[0] / dist * overlap;
                    r.pose.y -= d[1] / dist * overlap;
                    r.v = 0.0;
                    r.stalled = true;
                }
            }
        }
    }
}

/// When circle centres `a` and `b` are closer than `min` (the sum of the radii):
/// the unit normal from `a` to `b` ((1, 0) if they coincide) and their distance.
fn overlap(a: [f64; 2], b: [f64; 2], min: f64) -> Option<([f64; 2], f64)> {
    let d = [b[0] - a[0], b[1] - a[1]];
    let dist = (d[0] * d[0] + d[1] * d[1]).sqrt();
    if dist >= min {
        return None;
    }
    let normal = if dist > 1e-9 {
        [d[0] / dist, d[1] / dist]
    } else {
        [1.0, 0.0]
    };
    Some((normal, dist))
}
