//! The value types interfaces hold, with their fields' units.

use std::fmt::Write as _;

use super::Kind;

/// A value type that an interface can hold.
pub trait InterfaceValue: Clone + Default + Send + Sync + 'static {
    /// The interface family name (`laser`, `motors`, `image`...).
    const KIND: Kind;
    /// The documented range of each field, one line, that
    /// [`validate`](Self::validate) checks (listed together in [`RANGES`]).
    const RANGE: &'static str;
    /// Whether a schema writes it (motors) rather than a driver.
    const ACTUATOR: bool = false;
    /// The value's fields in their units, one line (for `echo`).
    fn describe(&self) -> String;
    /// Sets one field from text (for `set`); sensors refuse.
    fn set_field(&mut self, field: &str, _value: &str) -> Result<(), String> {
        Err(format!(
            "`{field}`: {} is a sensor interface; only actuators can be set",
            Self::KIND
        ))
    }
    /// A fingerprint of the value: equal values give equal fingerprints (what a
    /// viewer compares to tell a new value from a repeat). By default a hash of
    /// [`describe`](Self::describe).
    fn fingerprint(&self) -> u64 {
        fold_bytes(self.describe().as_bytes())
    }
    /// Checks a value before it is published on interface `name`: every number
    /// finite and within the documented range of its field (see [`RANGES`]). The
    /// one check every writer passes through ([`Interface::publish`],
    /// [`Interface::write`] and the recorded and received variants), so a
    /// driver, a transport, the shell and a schema refuse the same values.
    ///
    /// [`Interface::publish`]: super::Interface::publish
    /// [`Interface::write`]: super::Interface::write
    fn validate(&self, _name: &str) -> Result<(), String> {
        Ok(())
    }
}

/// The documented ranges that [`InterfaceValue::validate`] checks, per kind and
/// field (every number must also be finite): each kind's [`InterfaceValue::RANGE`],
/// in the kinds table's order.
pub const RANGES: &[(Kind, &str)] = super::for_each_kind!(kind_ranges! {});

/// `(KIND, RANGE)` of every kind of the table.
macro_rules! kind_ranges {
    (; $(($t:ident, $k:literal)),*) => {
        &[$((Kind::$t, <$t as InterfaceValue>::RANGE)),*]
    };
}
use kind_ranges;

/// The largest |x|, |y| an `encoders` value may hold, mm (1000 km: beyond it an
/// f32 in mm is a value no odometry gives).
pub const MAX_POSITION_MM: f32 = 1e9;
/// The largest |v| a `motors` command may hold, mm/s: 10 m/s, several times the
/// fastest base any driver here drives (a Pioneer 1.2 m/s, a NAO 0.1 m/s, Gazebo's
/// DiffDrive what the world says), so a real command always fits and a 1e30 from a
/// peer never reaches a driver that might not limit it.
pub const MAX_MOTOR_V: f32 = 10_000.0;
/// The largest |w| a `motors` command may hold, deg/s: 10 turns a second.
pub const MAX_MOTOR_W: f32 = 3_600.0;
/// The largest |angle| of a pan-tilt value, degrees.
pub const MAX_ANGLE_DEG: f32 = 360.0;
/// The largest |speed| of a pan-tilt command, deg/s.
pub const MAX_PT_SPEED: f32 = 1e4;

/// `field` of interface `name` is finite.
fn finite(name: &str, field: &str, v: f32) -> Result<(), String> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(format!("{name}: {field}={v} is not a finite number"))
    }
}

/// `field` of interface `name` is finite and in [lo, hi] (in `unit`).
fn within(name: &str, field: &str, v: f32, lo: f32, hi: f32, unit: &str) -> Result<(), String> {
    finite(name, field, v)?;
    if (lo..=hi).contains(&v) {
        Ok(())
    } else {
        Err(format!(
            "{name}: {field}={v} {unit} is out of its range [{lo}, {hi}] {unit}"
        ))
    }
}

fn set_f32(field: &str, value: &str, target: &mut f32) -> Result<(), String> {
    *target = value
        .parse::<f32>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| format!("`{field}={value}`: expected a number"))?;
    Ok(())
}

/// A BGR image, rows top to bottom, no padding: `data[(row*width+col)*3]` is blue.
#[derive(Clone, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

impl std::fmt::Debug for Image {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Image({}x{} BGR)", self.width, self.height)
    }
}

/// The fixed size of `colorA..D` (SIFNTSC).
pub const COLOR_WIDTH: u32 = 320;
pub const COLOR_HEIGHT: u32 = 240;

impl Image {
    /// An image from RGB bytes (as image libraries give them), turned BGR in place.
    pub fn from_rgb(width: u32, height: u32, mut rgb: Vec<u8>) -> Self {
        for p in rgb.chunks_exact_mut(3) {
            p.swap(0, 2);
        }
        Image {
            width,
            height,
            data: rgb,
        }
    }
    /// The pixels as RGB bytes (for image libraries and file formats).
    pub fn to_rgb(&self) -> Vec<u8> {
        let mut rgb = Vec::with_capacity(self.data.len());
        for p in self.data.chunks_exact(3) {
            rgb.extend_from_slice(&[p[2], p[1], p[0]]);
        }
        rgb
    }
    /// A black image.
    pub fn new(width: u32, height: u32) -> Self {
        Image {
            width,
            height,
            data: vec![0; width as usize * height as usize * 3],
        }
    }
    /// The (b, g, r) pixel at column `x`, row `y`.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        let i = (y as usize * self.width as usize + x as usize) * 3;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }
}

/// A fast fingerprint of bytes (a multiply-rotate fold over 8-byte words, several
/// GB/s): for telling a new value from a repeat, not for security.
pub fn fold_bytes(bytes: &[u8]) -> u64 {
    const K: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut h = bytes.len() as u64;
    let mut words = bytes.chunks_exact(8);
    for w in &mut words {
        let v = u64::from_le_bytes(w.try_into().expect("8 bytes"));
        h = (h ^ v).wrapping_mul(K).rotate_left(29);
    }
    for &b in words.remainder() {
        h = (h ^ b as u64).wrapping_mul(K).rotate_left(29);
    }
    h
}

impl InterfaceValue for Image {
    const KIND: Kind = Kind::Image;
    const RANGE: &'static str = "data is width x height x 3 bytes; colorA..D are 320x240";
    fn fingerprint(&self) -> u64 {
        fold_bytes(&self.data) ^ ((self.width as u64) << 32 | self.height as u64)
    }
    fn describe(&self) -> String {
        format!(
            "{}x{} BGR ({} bytes)",
            self.width,
            self.height,
            self.data.len()
        )
    }
    fn validate(&self, name: &str) -> Result<(), String> {
        if self.data.len() != self.width as usize * self.height as usize * 3 {
            return Err(format!(
                "{name}: image data is {} bytes, but {}x{} BGR needs {}",
                self.data.len(),
                self.width,
                self.height,
                self.width as usize * self.height as usize * 3
            ));
        }
        if name.starts_with("color") && (self.width, self.height) != (COLOR_WIDTH, COLOR_HEIGHT) {
            return Err(format!(
                "{name}: colorA..D images are {COLOR_WIDTH}x{COLOR_HEIGHT}, got {}x{}; use a varcolor interface for other sizes",
                self.width, self.height
            ));
        }
        Ok(())
    }
}

/// A laser scan and its geometry: ranges in mm, reading `i` at
/// [`angle(i)`](Laser::angle) = `start + i / resolution` degrees, counter-clockwise
/// from the laser's forward axis (REP 103's convention), the laser mounted on the
/// robot at [`mount`](Laser::mount). 4.3's laser is the default geometry: 180
/// readings at 1 per degree from −90°, so index 90 is straight ahead.
///
/// The value is the one owner of its geometry: every consumer (VFF, the views,
/// Foxglove, the recorder, ROS 2, the wires) takes angles from it and never assumes
/// 4.3's −90°.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Laser {
    /// Ranges, mm; a reading of `max_range` is "no return".
    pub readings: Vec<i32>,
    /// Readings per degree (4.3's field): the angle step is `1 / resolution` degrees.
    pub resolution: f32,
    /// The angle of reading 0, degrees counter-clockwise from the laser's forward axis.
    pub start: f32,
    /// The nearest range the laser measures, mm.
    pub min_range: f32,
    /// The farthest range the laser measures, mm.
    pub max_range: f32,
    /// Where the laser sits on the robot.
    pub mount: Mount,
}

/// Where a sensor sits on the robot: `x` mm forward and `y` mm to the left of the
/// robot's centre, turned `yaw` degrees counter-clockwise (REP 103's base_link).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Mount {
    pub x: f32,
    pub y: f32,
    pub yaw: f32,
}

impl Mount {
    /// A Pioneer's laser: 19 mm ahead of the robot's centre (R430 libs/pioneer),
    /// the simulator's robot and Player's default.
    pub const PIONEER_LASER: Mount = Mount {
        x: 19.0,
        y: 0.0,
        yaw: 0.0,
    };
}

/// 4.3's laser: reading 0 at −90°.
pub const JDE43_LASER_START: f32 = -90.0;
/// 4.3's laser (a SICK LMS): ranges up to 8 m.
pub const JDE43_LASER_MAX_RANGE: f32 = 8000.0;

impl Default for Laser {
    fn default() -> Self {
        Laser {
            readings: Vec::new(),
            resolution: 1.0,
            start: JDE43_LASER_START,
            min_range: 0.0,
            max_range: JDE43_LASER_MAX_RANGE,
            mount: Mount::default(),
        }
    }
}

impl Laser {
    /// Readings at `resolution` per degree in 4.3's geometry (from −90°, up to 8 m,
    /// at the robot's centre); set the other fields for any other laser.
    pub fn jde43(readings: Vec<i32>, resolution: f32) -> Laser {
        Laser {
            readings,
            resolution,
            ..Laser::default()
        }
    }

    /// The start angle (degrees) of `n` readings at `resolution` per degree centred
    /// on the laser's axis, as drivers declare them (`provides laser N R`): −90° for
    /// 4.3's 180 at 1 per degree, −180° for 360.
    pub fn centred_start(n: usize, resolution: f64) -> f32 {
        (-(n as f64) / (2.0 * resolution)) as f32
    }

    /// Degrees between two readings (1° for a resolution that is not positive).
    pub fn step(&self) -> f32 {
        if self.resolution > 0.0 && self.resolution.is_finite() {
            1.0 / self.resolution
        } else {
            1.0
        }
    }

    /// The angle of reading `i`, degrees counter-clockwise from the laser's axis.
    pub fn angle(&self, i: usize) -> f32 {
        self.start + i as f32 * self.step()
    }

    /// The angle of the last reading, degrees (`start` when there is none).
    pub fn end(&self) -> f32 {
        self.angle(self.readings.len().saturating_sub(1))
    }

    /// The angle of reading `i` in the robot's frame, degrees (the mount's yaw added).
    pub fn robot_angle(&self, i: usize) -> f32 {
        self.angle(i) + self.mount.yaw
    }

    /// Reading `i` as a point in the robot's frame, mm.
    pub fn robot_point(&self, i: usize) -> [f32; 2] {
        let r = self.readings.get(i).copied().unwrap_or(0) as f32;
        let a = self.robot_angle(i).to_radians();
        [self.mount.x + r * a.cos(), self.mount.y + r * a.sin()]
    }

    /// The reading nearest to `deg` degrees in the laser's frame, if the scan covers it.
    pub fn index_at(&self, deg: f32) -> Option<usize> {
        let k = ((deg - self.start) / self.step()).round();
        (k >= 0.0 && (k as usize) < self.readings.len()).then_some(k as usize)
    }

    /// The geometry as six numbers (start deg, min_range mm, max_range mm, mount x
    /// mm, y mm, yaw deg), the order byte layouts carry it in.
    pub fn geometry(&self) -> [f32; 6] {
        let m = self.mount;
        [self.start, self.min_range, self.max_range, m.x, m.y, m.yaw]
    }

    /// Sets the geometry from [`geometry`](Self::geometry)'s six numbers.
    pub fn set_geometry(&mut self, g: [f32; 6]) {
        let [start, min_range, max_range, x, y, yaw] = g;
        (self.start, self.min_range, self.max_range) = (start, min_range, max_range);
        self.mount = Mount { x, y, yaw };
    }

    /// Whether reading `r` (mm) is a return: within the laser's range and below its
    /// maximum ("no return" is reported as the maximum).
    pub fn is_return(&self, r: i32) -> bool {
        let r = r as f32;
        r >= self.min_range && r < self.max_range
    }
}

impl InterfaceValue for Laser {
    const KIND: Kind = Kind::Laser;
    const RANGE: &'static str = "readings >= 0 mm; resolution >= 0 readings/deg; start in [-360, 360] deg; \
         0 <= min_range <= max_range <= 1e6 mm; mount |x|, |y| <= 1e5 mm, yaw in [-360, 360] deg";
    fn describe(&self) -> String {
        let mut s = format!(
            "number={} resolution={} readings/deg start={} deg range=[{}, {}] mm mount=({}, {}) mm {} deg readings(mm)=[",
            self.readings.len(),
            self.resolution,
            self.start,
            self.min_range,
            self.max_range,
            self.mount.x,
            self.mount.y,
            self.mount.yaw
        );
        for (i, r) in self.readings.iter().enumerate() {
            if i > 0 {
                s.push(' ');
            }
            let _ = write!(s, "{r}");
        }
        s.push(']');
        s
    }
    fn validate(&self, name: &str) -> Result<(), String> {
        within(
            name,
            "resolution",
            self.resolution,
            0.0,
            f32::MAX,
            "readings/deg",
        )?;
        within(name, "start", self.start, -360.0, 360.0, "deg")?;
        within(name, "min_range", self.min_range, 0.0, MAX_RANGE_MM, "mm")?;
        within(
            name,
            "max_range",
            self.max_range,
            self.min_range,
            MAX_RANGE_MM,
            "mm",
        )?;
        within(
            name,
            "mount.x",
            self.mount.x,
            -MAX_MOUNT_MM,
            MAX_MOUNT_MM,
            "mm",
        )?;
        within(
            name,
            "mount.y",
            self.mount.y,
            -MAX_MOUNT_MM,
            MAX_MOUNT_MM,
            "mm",
        )?;
        within(name, "mount.yaw", self.mount.yaw, -360.0, 360.0, "deg")?;
        if let Some((i, r)) = self.readings.iter().enumerate().find(|(_, r)| **r < 0) {
            return Err(format!("{name}: reading {i} is {r} mm; a range is >= 0 mm"));
        }
        Ok(())
    }
}

/// The farthest range a laser value may carry, mm (1 km: beyond any lidar).
pub const MAX_RANGE_MM: f32 = 1e6;
/// The farthest a sensor may be mounted from the robot's centre, mm.
pub const MAX_MOUNT_MM: f32 = 1e5;

/// Sonar ranges in mm, one per sonar (Pioneer ring order).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sonars {
    pub us: Vec<f32>,
}

impl InterfaceValue for Sonars {
    const KIND: Kind = Kind::Sonars;
    const RANGE: &'static str = "us in [0, 1e6] mm";
    fn describe(&self) -> String {
        let v: Vec<String> = self.us.iter().map(|u| format!("{u:.0}")).collect();
        format!("number={} us(mm)=[{}]", self.us.len(), v.join(" "))
    }
    fn validate(&self, name: &str) -> Result<(), String> {
        for (i, u) in self.us.iter().enumerate() {
            within(name, &format!("us[{i}]"), *u, 0.0, MAX_RANGE_MM, "mm")?;
        }
        Ok(())
    }
}

/// A heading or yaw (rad, any number of turns) as it is printed: the same
/// direction in (−π, π], so that 0 and 2π both print as 0 (never −0, 2π or
/// 360°), 3π/2 as −π/2 (−90°) and π as π (180°). The one helper every printer of
/// a heading uses (`echo` and mastergui through `describe`, the panels, Python's
/// `Pose3d`): degrees are `heading(a).to_degrees()`. Values keep their own
/// convention (the encoders' θ is in (0, 2π], as 4.3's); only what is shown
/// changes. What is left of a whole turn by f32 rounding (under 1e-6 rad) is 0.
pub fn heading(rad: f32) -> f32 {
    use std::f32::consts::{PI, TAU};
    let mut a = rad.rem_euclid(TAU);
    if a > PI {
        a -= TAU;
    }
    if a.abs() < 1e-6 { 0.0 } else { a }
}

/// Robot pose from odometry: the seed's `robot[5]` = x, y (mm), θ (rad, (0, 2π]), cos θ, sin θ.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Encoders {
    pub x: f32,
    pub y: f32,
    pub theta: f32,
    pub cos: f32,
    pub sin: f32,
}

impl Default for Encoders {
    fn default() -> Self {
        Encoders::from_pose(0.0, 0.0, 0.0)
    }
}

impl Encoders {
    /// From a pose with θ in radians (any range); stores θ normalised to (0, 2π] as 4.3 did.
    pub fn from_pose(x: f32, y: f32, theta: f32) -> Self {
        let tau = std::f32::consts::TAU;
        let mut t = theta.rem_euclid(tau);
        if t <= 0.0 {
            t += tau;
        }
        Encoders {
            x,
            y,
            theta: t,
            cos: theta.cos(),
            sin: theta.sin(),
        }
    }
    /// The seed's `robot[5]` array.
    pub fn robot(&self) -> [f32; 5] {
        [self.x, self.y, self.theta, self.cos, self.sin]
    }
}

impl InterfaceValue for Encoders {
    const KIND: Kind = Kind::Encoders;
    const RANGE: &'static str =
        "|x|, |y| <= 1e9 mm (1000 km); |theta| <= 2π rad; cos, sin in [-1, 1]";
    /// θ printed as a [`heading`], in (−180°, 180°].
    fn describe(&self) -> String {
        let theta = heading(self.theta);
        format!(
            "x={:.1} mm y={:.1} mm theta={:.4} rad ({:.2} deg) cos={:.4} sin={:.4}",
            self.x,
            self.y,
            theta,
            theta.to_degrees(),
            self.cos,
            self.sin
        )
    }
    fn validate(&self, name: &str) -> Result<(), String> {
        let m = MAX_POSITION_MM;
        within(name, "x", self.x, -m, m, "mm")?;
        within(name, "y", self.y, -m, m, "mm")?;
        // A little slack for rounding to f32.
        let tau = std::f32::consts::TAU + 1e-3;
        within(name, "theta", self.theta, -tau, tau, "rad")?;
        within(name, "cos", self.cos, -1.001, 1.001, "")?;
        within(name, "sin", self.sin, -1.001, 1.001, "")
    }
}

/// Base velocity command: `v` mm/s forward, `w` deg/s counter-clockwise.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Motors {
    pub v: f32,
    pub w: f32,
}

impl Motors {
    /// The command (v, w) made safe to send: a non-finite speed counts as 0, and each
    /// is limited to ±its maximum. What every schema and panel that drives a base uses.
    pub fn limited(v: f32, w: f32, max_v: f32, max_w: f32) -> Motors {
        let finite = |x: f32| if x.is_finite() { x } else { 0.0 };
        Motors {
            v: limit(finite(v), -max_v, max_v),
            w: limit(finite(w), -max_w, max_w),
        }
    }
}

/// `x` limited to [lo, hi]; unlike `f32::clamp` it never panics (bad bounds or NaN:
/// a NaN counts as 0).
pub fn limit(x: f32, lo: f32, hi: f32) -> f32 {
    if x.is_nan() {
        0.0f32.max(lo).min(hi)
    } else {
        x.max(lo).min(hi)
    }
}

impl InterfaceValue for Motors {
    const KIND: Kind = Kind::Motors;
    const RANGE: &'static str = "|v| <= 10000 mm/s (10 m/s); |w| <= 3600 deg/s (10 turns/s); each driver limits them \
         further to its robot's maxima";
    const ACTUATOR: bool = true;
    fn describe(&self) -> String {
        format!("v={:.1} mm/s w={:.2} deg/s", self.v, self.w)
    }
    fn validate(&self, name: &str) -> Result<(), String> {
        within(name, "v", self.v, -MAX_MOTOR_V, MAX_MOTOR_V, "mm/s")?;
        within(name, "w", self.w, -MAX_MOTOR_W, MAX_MOTOR_W, "deg/s")
    }
    fn set_field(&mut self, field: &str, value: &str) -> Result<(), String> {
        match field {
            "v" => set_f32(field, value, &mut self.v),
            "w" => set_f32(field, value, &mut self.w),
            _ => Err(format!(
                "motors has no field `{field}`; fields: v (mm/s), w (deg/s)"
            )),
        }
    }
}

/// Pan-tilt angles in degrees.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PtEncoders {
    pub pan_angle: f32,
    pub tilt_angle: f32,
}

impl InterfaceValue for PtEncoders {
    const KIND: Kind = Kind::PtEncoders;
    const RANGE: &'static str = "pan_angle, tilt_angle in [-360, 360] deg";
    fn describe(&self) -> String {
        format!(
            "pan_angle={:.2} deg tilt_angle={:.2} deg",
            self.pan_angle, self.tilt_angle
        )
    }
    fn validate(&self, name: &str) -> Result<(), String> {
        let a = MAX_ANGLE_DEG;
        within(name, "pan_angle", self.pan_angle, -a, a, "deg")?;
        within(name, "tilt_angle", self.tilt_angle, -a, a, "deg")
    }
}

/// Pan-tilt command (deg, deg/s) and the unit's limits (read-only).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PtMotors {
    pub longitude: f32,
    pub latitude: f32,
    pub longitude_speed: f32,
    pub latitude_speed: f32,
    pub max_longitude: f32,
    pub min_longitude: f32,
    pub max_latitude: f32,
    pub min_latitude: f32,
    pub max_longitude_speed: f32,
    pub max_latitude_speed: f32,
}

impl Default for PtMotors {
    /// Limits of the Directed Perception PTU that 4.3 used.
    fn default() -> Self {
        PtMotors {
            longitude: 0.0,
            latitude: 0.0,
            longitude_speed: 0.0,
            latitude_speed: 0.0,
            max_longitude: 159.13,
            min_longitude: -159.13,
            max_latitude: 30.0,
            min_latitude: -46.0,
            max_longitude_speed: 205.89,
            max_latitude_speed: 205.89,
        }
    }
}

impl InterfaceValue for PtMotors {
    const KIND: Kind = Kind::PtMotors;
    const RANGE: &'static str = "longitude, latitude finite (each driver limits them); the limits in [-360, 360] deg, \
         min <= max; speeds in [-1e4, 1e4] deg/s";
    const ACTUATOR: bool = true;
    fn describe(&self) -> String {
        format!(
            "longitude={:.2} deg latitude={:.2} deg longitude_speed={:.2} deg/s latitude_speed={:.2} deg/s \
             limits: longitude [{:.2}, {:.2}] latitude [{:.2}, {:.2}] speed <= {:.2}/{:.2} deg/s",
            self.longitude,
            self.latitude,
            self.longitude_speed,
            self.latitude_speed,
            self.min_longitude,
            self.max_longitude,
            self.min_latitude,
            self.max_latitude,
            self.max_longitude_speed,
            self.max_latitude_speed
        )
    }
    fn validate(&self, name: &str) -> Result<(), String> {
        let (a, s) = (MAX_ANGLE_DEG, MAX_PT_SPEED);
        // A command beyond the limits is fine (the driver limits it); the limits
        // are the unit's.
        finite(name, "longitude", self.longitude)?;
        finite(name, "latitude", self.latitude)?;
        for (field, v) in [
            ("min_longitude", self.min_longitude),
            ("max_longitude", self.max_longitude),
            ("min_latitude", self.min_latitude),
            ("max_latitude", self.max_latitude),
        ] {
            within(name, field, v, -a, a, "deg")?;
        }
        for (field, v) in [
            ("longitude_speed", self.longitude_speed),
            ("latitude_speed", self.latitude_speed),
            ("max_longitude_speed", self.max_longitude_speed),
            ("max_latitude_speed", self.max_latitude_speed),
        ] {
            within(name, field, v, -s, s, "deg/s")?;
        }
        for (axis, lo, hi) in [
            ("longitude", self.min_longitude, self.max_longitude),
            ("latitude", self.min_latitude, self.max_latitude),
        ] {
            if lo > hi {
                return Err(format!(
                    "{name}: min_{axis}={lo} deg is above max_{axis}={hi} deg"
                ));
            }
        }
        Ok(())
    }
    fn set_field(&mut self, field: &str, value: &str) -> Result<(), String> {
        match field {
            "longitude" => set_f32(field, value, &mut self.longitude),
            "latitude" => set_f32(field, value, &mut self.latitude),
            "longitude_speed" => set_f32(field, value, &mut self.longitude_speed),
            "latitude_speed" => set_f32(field, value, &mut self.latitude_speed),
            _ => Err(format!(
                "pantiltmotors has no settable field `{field}`; fields: longitude, latitude (deg), \
                 longitude_speed, latitude_speed (deg/s)"
            )),
        }
    }
}

/// Zoom position.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ZoomEncoders {
    pub zoom_position: f32,
}

impl InterfaceValue for ZoomEncoders {
    const KIND: Kind = Kind::ZoomEncoders;
    const RANGE: &'static str = "zoom_position finite";
    fn describe(&self) -> String {
        format!("zoom_position={:.2}", self.zoom_position)
    }
    fn validate(&self, name: &str) -> Result<(), String> {
        finite(name, "zoom_position", self.zoom_position)
    }
}

/// Zoom command and limits (read-only).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ZoomMotors {
    pub zoom: f32,
    pub zoom_speed: f32,
    pub max_zoom: f32,
    pub min_zoom: f32,
    pub max_zoom_speed: f32,
}

impl Default for ZoomMotors {
    /// Limits of the Sony EVI-D100 that 4.3 used.
    fn default() -> Self {
        ZoomMotors {
            zoom: 0.0,
            zoom_speed: 0.0,
            max_zoom: 40.0,
            min_zoom: 0.0,
            max_zoom_speed: 7.0,
        }
    }
}

impl InterfaceValue for ZoomMotors {
    const KIND: Kind = Kind::ZoomMotors;
    const RANGE: &'static str = "zoom, zoom_speed and the limits finite, min_zoom <= max_zoom";
    const ACTUATOR: bool = true;
    fn describe(&self) -> String {
        format!(
            "zoom={:.2} zoom_speed={:.2} limits: zoom [{:.2}, {:.2}] speed <= {:.2}",
            self.zoom, self.zoom_speed, self.min_zoom, self.max_zoom, self.max_zoom_speed
        )
    }
    fn validate(&self, name: &str) -> Result<(), String> {
        for (field, v) in [
            ("zoom", self.zoom),
            ("zoom_speed", self.zoom_speed),
            ("min_zoom", self.min_zoom),
            ("max_zoom", self.max_zoom),
            ("max_zoom_speed", self.max_zoom_speed),
        ] {
            finite(name, field, v)?;
        }
        if self.min_zoom > self.max_zoom {
            return Err(format!(
                "{name}: min_zoom={} is above max_zoom={}",
                self.min_zoom, self.max_zoom
            ));
        }
        Ok(())
    }
    fn set_field(&mut self, field: &str, value: &str) -> Result<(), String> {
        match field {
            "zoom" => set_f32(field, value, &mut self.zoom),
            "zoom_speed" => set_f32(field, value, &mut self.zoom_speed),
            _ => Err(format!(
                "zoommotors has no settable field `{field}`; fields: zoom, zoom_speed"
            )),
        }
    }
}

/// Bumpers: one byte per bumper, 1 = pressed.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Bumpers {
    pub bumpers: Vec<u8>,
}

impl InterfaceValue for Bumpers {
    const KIND: Kind = Kind::Bumpers;
    const RANGE: &'static str = "any bytes";
    fn describe(&self) -> String {
        format!("number={} bumpers={:?}", self.bumpers.len(), self.bumpers)
    }
}

/// An inertial measurement unit, in SI units as Gazebo, NAOqi and ROS give them:
/// orientation a unit quaternion (x, y, z, w) of the body in the world frame,
/// angular velocity in rad/s and linear acceleration in m/s² (gravity included,
/// as an accelerometer reads it), both about and along the body's x (forward), y
/// (left) and z (up) axes.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Imu {
    pub qx: f32,
    pub qy: f32,
    pub qz: f32,
    pub qw: f32,
    /// rad/s
    pub wx: f32,
    pub wy: f32,
    pub wz: f32,
    /// m/s²
    pub ax: f32,
    pub ay: f32,
    pub az: f32,
}

/// The largest |angular velocity| an `imu` value may hold, rad/s (beyond any gyro).
pub const MAX_ANGULAR_VELOCITY: f32 = 1e3;
/// The largest |linear acceleration| an `imu` value may hold, m/s² (1000 g).
pub const MAX_ACCELERATION: f32 = 1e4;

impl Default for Imu {
    /// At rest and level: the identity orientation, no rotation, no acceleration.
    fn default() -> Self {
        Imu {
            qx: 0.0,
            qy: 0.0,
            qz: 0.0,
            qw: 1.0,
            wx: 0.0,
            wy: 0.0,
            wz: 0.0,
            ax: 0.0,
            ay: 0.0,
            az: 0.0,
        }
    }
}

impl Imu {
    /// The fields in order: qx qy qz qw wx wy wz ax ay az.
    pub fn fields(&self) -> [f32; 10] {
        [
            self.qx, self.qy, self.qz, self.qw, self.wx, self.wy, self.wz, self.ax, self.ay,
            self.az,
        ]
    }
    /// From the fields in the order of [`fields`](Self::fields).
    pub fn from_fields(f: [f32; 10]) -> Imu {
        let [qx, qy, qz, qw, wx, wy, wz, ax, ay, az] = f;
        Imu {
            qx,
            qy,
            qz,
            qw,
            wx,
            wy,
            wz,
            ax,
            ay,
            az,
        }
    }
    /// Roll, pitch and yaw (rad, about x, y, z) of the orientation.
    pub fn euler(&self) -> (f32, f32, f32) {
        let (x, y, z, w) = (self.qx, self.qy, self.qz, self.qw);
        let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
        let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
        let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
        (roll, pitch, yaw)
    }
}

impl InterfaceValue for Imu {
    const KIND: Kind = Kind::Imu;
    const RANGE: &'static str = "qx, qy, qz, qw a unit quaternion (length 1 ± 0.01); |wx|, |wy|, |wz| <= 1e3 rad/s; \
         |ax|, |ay|, |az| <= 1e4 m/s²";
    fn describe(&self) -> String {
        let (r, p, y) = self.euler();
        let (r, p, y) = (heading(r), heading(p), heading(y));
        format!(
            "roll={:.2} pitch={:.2} yaw={:.2} deg q=({:.4} {:.4} {:.4} {:.4}) \
             w=({:.3} {:.3} {:.3}) rad/s a=({:.3} {:.3} {:.3}) m/s²",
            r.to_degrees(),
            p.to_degrees(),
            y.to_degrees(),
            self.qx,
            self.qy,
            self.qz,
            self.qw,
            self.wx,
            self.wy,
            self.wz,
            self.ax,
            self.ay,
            self.az
        )
    }
    fn validate(&self, name: &str) -> Result<(), String> {
        for (field, v) in [
            ("qx", self.qx),
            ("qy", self.qy),
            ("qz", self.qz),
            ("qw", self.qw),
        ] {
            finite(name, field, v)?;
        }
        let norm =
            (self.qx * self.qx + self.qy * self.qy + self.qz * self.qz + self.qw * self.qw).sqrt();
        if (norm - 1.0).abs() > 0.01 {
            return Err(format!(
                "{name}: the orientation quaternion has length {norm}; it must be a unit quaternion"
            ));
        }
        let w = MAX_ANGULAR_VELOCITY;
        for (field, v) in [("wx", self.wx), ("wy", self.wy), ("wz", self.wz)] {
            within(name, field, v, -w, w, "rad/s")?;
        }
        let a = MAX_ACCELERATION;
        for (field, v) in [("ax", self.ax), ("ay", self.ay), ("az", self.az)] {
            within(name, field, v, -a, a, "m/s²")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::{PI, TAU};

    #[test]
    fn headings_print_in_minus_180_to_180_with_zero_as_zero() {
        let deg = |rad: f32| format!("{:.2}", heading(rad).to_degrees());
        assert_eq!(deg(0.0), "0.00");
        assert_eq!(deg(TAU), "0.00");
        assert_eq!(deg(-0.0), "0.00");
        assert!(heading(-0.0).is_sign_positive());
        assert_eq!(deg(3.0 * PI / 2.0), "-90.00");
        assert_eq!(deg(PI), "180.00");
        assert_eq!(deg(-PI), "180.00");
        assert_eq!(deg(-PI / 2.0), "-90.00");
        assert_eq!(deg(5.0 * TAU + 0.5), deg(0.5));
        // The encoders keep 4.3's (0, 2π]; `echo` prints a heading of zero as 0.
        let e = Encoders::from_pose(1.0, 2.0, 0.0);
        assert_eq!(e.theta, TAU);
        assert!(
            e.describe().contains("theta=0.0000 rad (0.00 deg)"),
            "{}",
            e.describe()
        );
        let e = Encoders::from_pose(0.0, 0.0, 270f32.to_radians());
        assert!(e.describe().contains("(-90.00 deg)"), "{}", e.describe());
        // A yaw a rounding below 0 (it printed as −0.00) prints as 0.
        let yaw = Imu {
            qz: -1e-8,
            ..Imu::default()
        };
        assert!(yaw.euler().2 < 0.0);
        assert!(
            yaw.describe()
                .starts_with("roll=0.00 pitch=0.00 yaw=0.00 deg"),
            "{}",
            yaw.describe()
        );
    }
}
