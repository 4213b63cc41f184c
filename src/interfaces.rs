//! Interfaces: the seed's named, typed sensor and actuator variables ("virtual
//! schemas" in 4.3).
//!
//! | name | type | fields and units |
//! |---|---|---|
//! | `colorA..D` | [`Image`] | 320x240, BGR bytes, rows top to bottom |
//! | `varcolorA..D` | [`Image`] | any size, BGR |
//! | `laser` | [`Laser`] | `readings` mm (index 0 = right, centre = ahead), `resolution` readings/deg |
//! | `sonars` | [`Sonars`] | `us` mm, one per sonar |
//! | `encoders` | [`Encoders`] | `x`, `y` mm, `theta` rad in (0, 2π], `cos`, `sin` (the seed's `robot[5]`) |
//! | `motors` | [`Motors`] | `v` mm/s, `w` deg/s (counter-clockwise positive) |
//! | `pantiltencoders` | [`PtEncoders`] | `pan_angle`, `tilt_angle` deg |
//! | `pantiltmotors` | [`PtMotors`] | `longitude`, `latitude` deg; speeds deg/s; limits |
//! | `zoomencoders` | [`ZoomEncoders`] | `zoom_position` |
//! | `zoommotors` | [`ZoomMotors`] | `zoom`, `zoom_speed`; limits |
//! | `bumpers` | [`Bumpers`] | one byte per bumper, 1 = pressed |
//!
//! 4.3's export names `ptencoders`, `ptmotors`, `zencoders`, `zmotors` are accepted
//! as aliases. A driver serving several robots names them with a suffix
//! (`laser robot2` provides `laser.robot2`, see [`interface_name`]).
//!
//! Every interface holds its latest [`Sample`]: a clock that increases with every
//! new value, a timestamp and the value. A read ([`Interface::read`]) is an atomic
//! pointer load: no copy of an image, no lock held while the reader works on it. A
//! write ([`Interface::publish`], [`Interface::write`]) swaps in a new sample and
//! never waits for readers; [`Interface::write`] recycles the previous buffer when
//! no reader still holds it, so a steady stream of frames allocates nothing.
//!
//! Resume/suspend reference counting ([`Interface::resume`]) tells a driver whether
//! anybody uses an interface, so it works only while someone does.

use std::{
    any::Any,
    collections::{BTreeMap, VecDeque},
    fmt::Write as _,
    sync::{
        Arc,
        atomic::{AtomicU64, AtomicUsize, Ordering},
    },
    time::{Duration, Instant, SystemTime},
};

use arc_swap::{ArcSwap, Guard};
use parking_lot::{Condvar, Mutex, RwLock};

/// One value of an interface.
#[derive(Debug)]
pub struct Sample<T> {
    /// Increases by one with every new value; 0 is the initial default value.
    pub clock: u64,
    /// When the value was published (monotonic).
    pub stamp: Instant,
    /// When the value was published (wall clock).
    pub time: SystemTime,
    pub value: T,
}

impl<T> std::ops::Deref for Sample<T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.value
    }
}

/// A value type that an interface can hold.
pub trait InterfaceValue: Clone + Default + Send + Sync + 'static {
    /// The interface family name (`laser`, `motors`, `image`...).
    const KIND: &'static str;
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
    /// Checks a value before it is published on interface `name`.
    fn validate(&self, _name: &str) -> Result<(), String> {
        Ok(())
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
#[derive(Clone, Default, PartialEq, Eq)]
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

impl InterfaceValue for Image {
    const KIND: &'static str = "image";
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

/// Laser ranges in mm, counter-clockwise from the robot's right; with 180 readings
/// at 1 per degree, index 90 is straight ahead (reading i is at −90 + i/resolution deg).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Laser {
    pub readings: Vec<i32>,
    /// Readings per degree.
    pub resolution: f32,
}

impl InterfaceValue for Laser {
    const KIND: &'static str = "laser";
    fn describe(&self) -> String {
        let mut s = format!(
            "number={} resolution={} readings/deg readings(mm)=[",
            self.readings.len(),
            self.resolution
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
}

/// Sonar ranges in mm, one per sonar (Pioneer ring order).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sonars {
    pub us: Vec<f32>,
}

impl InterfaceValue for Sonars {
    const KIND: &'static str = "sonars";
    fn describe(&self) -> String {
        let v: Vec<String> = self.us.iter().map(|u| format!("{u:.0}")).collect();
        format!("number={} us(mm)=[{}]", self.us.len(), v.join(" "))
    }
}

/// Robot pose from odometry: the seed's `robot[5]` = x, y (mm), θ (rad, (0, 2π]), cos θ, sin θ.
#[derive(Clone, Copy, Debug, PartialEq)]
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
    const KIND: &'static str = "encoders";
    fn describe(&self) -> String {
        format!(
            "x={:.1} mm y={:.1} mm theta={:.4} rad ({:.2} deg) cos={:.4} sin={:.4}",
            self.x,
            self.y,
            self.theta,
            self.theta.to_degrees(),
            self.cos,
            self.sin
        )
    }
}

/// Base velocity command: `v` mm/s forward, `w` deg/s counter-clockwise.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
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
    const KIND: &'static str = "motors";
    const ACTUATOR: bool = true;
    fn describe(&self) -> String {
        format!("v={:.1} mm/s w={:.2} deg/s", self.v, self.w)
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
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PtEncoders {
    pub pan_angle: f32,
    pub tilt_angle: f32,
}

impl InterfaceValue for PtEncoders {
    const KIND: &'static str = "pantiltencoders";
    fn describe(&self) -> String {
        format!(
            "pan_angle={:.2} deg tilt_angle={:.2} deg",
            self.pan_angle, self.tilt_angle
        )
    }
}

/// Pan-tilt command (deg, deg/s) and the unit's limits (read-only).
#[derive(Clone, Copy, Debug, PartialEq)]
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
    const KIND: &'static str = "pantiltmotors";
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
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ZoomEncoders {
    pub zoom_position: f32,
}

impl InterfaceValue for ZoomEncoders {
    const KIND: &'static str = "zoomencoders";
    fn describe(&self) -> String {
        format!("zoom_position={:.2}", self.zoom_position)
    }
}

/// Zoom command and limits (read-only).
#[derive(Clone, Copy, Debug, PartialEq)]
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
    const KIND: &'static str = "zoommotors";
    const ACTUATOR: bool = true;
    fn describe(&self) -> String {
        format!(
            "zoom={:.2} zoom_speed={:.2} limits: zoom [{:.2}, {:.2}] speed <= {:.2}",
            self.zoom, self.zoom_speed, self.min_zoom, self.max_zoom, self.max_zoom_speed
        )
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
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bumpers {
    pub bumpers: Vec<u8>,
}

impl InterfaceValue for Bumpers {
    const KIND: &'static str = "bumpers";
    fn describe(&self) -> String {
        format!("number={} bumpers={:?}", self.bumpers.len(), self.bumpers)
    }
}

/// The interface family a standard name belongs to (`varcolorB` → image,
/// `laser.robot2` → laser), after resolving 4.3's aliases.
pub fn family(name: &str) -> Option<&'static str> {
    let base = canonical(name.split('.').next().unwrap_or(name));
    Some(match base.as_str() {
        "colorA" | "colorB" | "colorC" | "colorD" | "varcolorA" | "varcolorB" | "varcolorC"
        | "varcolorD" => "image",
        "laser" => "laser",
        "sonars" => "sonars",
        "encoders" => "encoders",
        "motors" => "motors",
        "pantiltencoders" => "pantiltencoders",
        "pantiltmotors" => "pantiltmotors",
        "zoomencoders" => "zoomencoders",
        "zoommotors" => "zoommotors",
        "bumpers" => "bumpers",
        _ => return None,
    })
}

/// Resolves 4.3's export names to the manual's interface names.
pub fn canonical(name: &str) -> String {
    let (base, suffix) = match name.split_once('.') {
        Some((b, s)) => (b, Some(s)),
        None => (name, None),
    };
    let base = match base {
        "ptencoders" => "pantiltencoders",
        "ptmotors" => "pantiltmotors",
        "zencoders" => "zoomencoders",
        "zmotors" => "zoommotors",
        "us" => "sonars",
        other => other,
    };
    match suffix {
        Some(s) => format!("{base}.{s}"),
        None => base.to_string(),
    }
}

/// The name of interface `base` for robot/device `suffix` (`laser`, `robot2` →
/// `laser.robot2`); no suffix gives the plain name.
pub fn interface_name(base: &str, suffix: Option<&str>) -> String {
    match suffix {
        Some(s) if !s.is_empty() => format!("{}.{s}", canonical(base)),
        _ => canonical(base),
    }
}

/// What writers share: a recycled buffer and recent publish times (for the rate).
struct Writer<T> {
    spare: Option<T>,
    recent: VecDeque<Instant>,
    first: Option<Instant>,
}

const RATE_WINDOW: Duration = Duration::from_secs(2);

impl<T> Writer<T> {
    fn published(&mut self, at: Instant) {
        self.first.get_or_insert(at);
        self.recent.push_back(at);
        while self
            .recent
            .front()
            .is_some_and(|t| at.duration_since(*t) > RATE_WINDOW)
        {
            self.recent.pop_front();
        }
    }

    fn rate(&self) -> f64 {
        let Some(first) = self.first else { return 0.0 };
        let now = Instant::now();
        let window = now.duration_since(first).min(RATE_WINDOW).as_secs_f64();
        let n = self
            .recent
            .iter()
            .filter(|t| now.duration_since(**t) <= RATE_WINDOW)
            .count();
        if window < 0.05 {
            0.0
        } else {
            n as f64 / window
        }
    }
}

/// One named, typed interface.
pub struct Interface<T> {
    name: String,
    provider: String,
    slot: ArcSwap<Sample<T>>,
    /// Serialises writers (readers never take it).
    writer: Mutex<Writer<T>>,
    users: AtomicUsize,
    wake: (Mutex<()>, Condvar),
    /// The clock of the last sample, for cheap checks.
    clock: AtomicU64,
    /// Why the value is stale (its source is gone), until the next publish.
    stale: Mutex<Option<String>>,
}

impl<T: InterfaceValue> Interface<T> {
    /// A new interface holding `T::default()` at clock 0.
    pub fn new(name: &str, provider: &str) -> Self {
        Self::with_value(name, provider, T::default())
    }

    /// A new interface holding `initial` at clock 0.
    pub fn with_value(name: &str, provider: &str, initial: T) -> Self {
        Interface {
            name: name.to_string(),
            provider: provider.to_string(),
            slot: ArcSwap::from_pointee(Sample {
                clock: 0,
                stamp: Instant::now(),
                time: SystemTime::now(),
                value: initial,
            }),
            writer: Mutex::new(Writer {
                spare: None,
                recent: VecDeque::new(),
                first: None,
            }),
            users: AtomicUsize::new(0),
            wake: (Mutex::new(()), Condvar::new()),
            clock: AtomicU64::new(0),
            stale: Mutex::new(None),
        }
    }

    /// The latest sample, as cheap as reading a local variable: an atomic load, no
    /// copy and no lock. Hold the guard only while you work on this sample; use
    /// [`snapshot`](Self::snapshot) to keep it longer.
    #[inline]
    pub fn read(&self) -> Guard<Arc<Sample<T>>> {
        self.slot.load()
    }

    /// The latest sample, owned (one reference-count increment).
    pub fn snapshot(&self) -> Arc<Sample<T>> {
        self.slot.load_full()
    }

    /// The latest sample if it is younger than `max_age`.
    pub fn fresh(&self, max_age: Duration) -> Option<Arc<Sample<T>>> {
        let s = self.snapshot();
        (s.clock > 0 && s.stamp.elapsed() <= max_age).then_some(s)
    }

    /// Publishes a new value; returns its clock. Never waits for readers.
    pub fn publish(&self, value: T) -> Result<u64, String> {
        value.validate(&self.name)?;
        let mut w = self.writer.lock();
        Ok(self.store(&mut w, value).0)
    }

    /// Fills a recycled value in place and publishes it. `fill` gets the buffer of a
    /// sample no reader holds any more (or a copy of the latest value), so steady
    /// streams of large values allocate nothing.
    pub fn write(&self, fill: impl FnOnce(&mut T)) -> Result<u64, String> {
        let mut w = self.writer.lock();
        let mut value = w.spare.take().unwrap_or_else(|| self.read().value.clone());
        fill(&mut value);
        if let Err(e) = value.validate(&self.name) {
            w.spare = Some(value);
            return Err(e);
        }
        let (clock, old) = self.store(&mut w, value);
        if let Some(s) = Arc::into_inner(old) {
            w.spare = Some(s.value);
        }
        Ok(clock)
    }

    /// Swaps in a new sample (the caller holds the writer lock); returns its clock
    /// and the previous sample.
    fn store(&self, w: &mut Writer<T>, value: T) -> (u64, Arc<Sample<T>>) {
        let clock = self.clock.load(Ordering::Relaxed) + 1;
        let stamp = Instant::now();
        let old = self.slot.swap(Arc::new(Sample {
            clock,
            stamp,
            time: SystemTime::now(),
            value,
        }));
        self.clock.store(clock, Ordering::Release);
        w.published(stamp);
        if self.stale.lock().is_some() {
            *self.stale.lock() = None;
        }
        (clock, old)
    }

    /// The clock of the latest sample.
    pub fn clock(&self) -> u64 {
        self.clock.load(Ordering::Acquire)
    }

    /// Someone starts using this interface (4.3's `run` of a virtual schema).
    pub fn resume(&self) -> usize {
        let n = self.users.fetch_add(1, Ordering::AcqRel) + 1;
        if n == 1 {
            let _g = self.wake.0.lock();
            self.wake.1.notify_all();
        }
        n
    }

    /// Someone stops using it (4.3's `stop`); never goes below zero.
    pub fn suspend(&self) -> usize {
        self.users
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                Some(n.saturating_sub(1))
            })
            .map(|n| n.saturating_sub(1))
            .unwrap_or(0)
    }

    /// How many users have resumed it.
    pub fn users(&self) -> usize {
        self.users.load(Ordering::Acquire)
    }

    /// Blocks until someone uses the interface or `timeout` passes; returns whether
    /// it is in use. Drivers sleep here while nobody needs their data.
    pub fn wait_used(&self, timeout: Duration) -> bool {
        let mut g = self.wake.0.lock();
        if self.users() > 0 {
            return true;
        }
        self.wake.1.wait_for(&mut g, timeout);
        self.users() > 0
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// Marks the value stale: its source is gone (a device unplugged, a server
    /// down), so the latest value is old and will stay so. `ps`, `echo` and
    /// mastergui show the reason and the growing age; the next publish clears it.
    pub fn set_stale(&self, why: impl Into<String>) {
        *self.stale.lock() = Some(why.into());
    }

    /// Why the value is stale, if it is.
    pub fn stale(&self) -> Option<String> {
        self.stale.lock().clone()
    }
}

impl Interface<Motors> {
    /// The motors command a driver should apply: the latest one, or zero if it is
    /// older than `timeout` (the controller may have died: a robot must not keep
    /// driving on a stale command).
    pub fn command(&self, timeout: Duration) -> Motors {
        self.fresh(timeout).map(|s| s.value).unwrap_or_default()
    }
}

/// What every interface offers whatever its type (for the shell, the GUI, `ps`).
pub trait AnyInterface: Any + Send + Sync {
    fn name(&self) -> &str;
    /// The interface family (`laser`, `image`, ...).
    fn kind(&self) -> &'static str;
    /// The component that provides it.
    fn provider(&self) -> &str;
    fn is_actuator(&self) -> bool;
    fn clock(&self) -> u64;
    /// Seconds since the latest value was published.
    fn age(&self) -> Duration;
    /// New values per second over the last ~2 s.
    fn rate(&self) -> f64;
    /// Why the value is stale (its source is gone), if it is.
    fn stale(&self) -> Option<String>;
    fn users(&self) -> usize;
    fn resume(&self) -> usize;
    fn suspend(&self) -> usize;
    /// The latest value in its units, one line.
    fn describe(&self) -> String;
    /// Sets fields (`v=200 w=10`) on a copy of the latest value and publishes it.
    fn set_fields(&self, fields: &[(&str, &str)]) -> Result<u64, String>;
}

impl<T: InterfaceValue> AnyInterface for Interface<T> {
    fn name(&self) -> &str {
        &self.name
    }
    fn kind(&self) -> &'static str {
        T::KIND
    }
    fn provider(&self) -> &str {
        &self.provider
    }
    fn is_actuator(&self) -> bool {
        T::ACTUATOR
    }
    fn clock(&self) -> u64 {
        Interface::clock(self)
    }
    fn age(&self) -> Duration {
        self.read().stamp.elapsed()
    }
    fn rate(&self) -> f64 {
        self.writer.lock().rate()
    }
    fn stale(&self) -> Option<String> {
        Interface::stale(self)
    }
    fn users(&self) -> usize {
        Interface::users(self)
    }
    fn resume(&self) -> usize {
        Interface::resume(self)
    }
    fn suspend(&self) -> usize {
        Interface::suspend(self)
    }
    fn describe(&self) -> String {
        self.read().value.describe()
    }
    fn set_fields(&self, fields: &[(&str, &str)]) -> Result<u64, String> {
        let mut v = self.read().value.clone();
        for (f, val) in fields {
            v.set_field(f, val)?;
        }
        self.publish(v)
    }
}

/// Errors looking up an interface.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum InterfaceError {
    #[error("no interface `{name}` is provided; provided: {available}")]
    Missing { name: String, available: String },
    #[error("interface `{name}` is a {found} interface, not {expected}")]
    WrongType {
        name: String,
        expected: &'static str,
        found: &'static str,
    },
    #[error("interface `{name}` is already provided by {provider}")]
    Duplicate { name: String, provider: String },
}

/// An interface and the order it was provided in.
type Entry = (usize, Arc<dyn AnyInterface>);

/// The table of every provided interface, by name, in the order they were provided.
#[derive(Default)]
pub struct Interfaces {
    table: RwLock<BTreeMap<String, Entry>>,
}

impl Interfaces {
    /// Creates interface `name` for `provider` and returns it. A name can be
    /// provided once.
    pub fn provide<T: InterfaceValue>(
        &self,
        name: &str,
        provider: &str,
    ) -> Result<Arc<Interface<T>>, InterfaceError> {
        self.provide_value(name, provider, T::default())
    }

    /// Like [`provide`](Self::provide) with an initial value (e.g. an image of the right size).
    pub fn provide_value<T: InterfaceValue>(
        &self,
        name: &str,
        provider: &str,
        initial: T,
    ) -> Result<Arc<Interface<T>>, InterfaceError> {
        let name = canonical(name);
        let mut t = self.table.write();
        if let Some((_, i)) = t.get(&name) {
            return Err(InterfaceError::Duplicate {
                name,
                provider: i.provider().to_string(),
            });
        }
        let iface = Arc::new(Interface::with_value(&name, provider, initial));
        let n = t.len();
        t.insert(name, (n, iface.clone()));
        Ok(iface)
    }

    /// The typed interface `name` (aliases accepted).
    pub fn get<T: InterfaceValue>(&self, name: &str) -> Result<Arc<Interface<T>>, InterfaceError> {
        let any = self.get_any(name)?;
        let found = any.kind();
        let any_arc: Arc<dyn Any + Send + Sync> = any;
        any_arc
            .downcast::<Interface<T>>()
            .map_err(|_| InterfaceError::WrongType {
                name: canonical(name),
                expected: T::KIND,
                found,
            })
    }

    /// The interface `name` whatever its type.
    pub fn get_any(&self, name: &str) -> Result<Arc<dyn AnyInterface>, InterfaceError> {
        let name = canonical(name);
        let t = self.table.read();
        t.get(&name)
            .map(|(_, i)| i.clone())
            .ok_or_else(|| InterfaceError::Missing {
                available: if t.is_empty() {
                    "none (load a driver that provides it)".into()
                } else {
                    t.keys().cloned().collect::<Vec<_>>().join(", ")
                },
                name,
            })
    }

    /// Every interface, in the order provided.
    pub fn all(&self) -> Vec<Arc<dyn AnyInterface>> {
        let t = self.table.read();
        let mut v: Vec<_> = t.values().cloned().collect();
        v.sort_by_key(|(i, _)| *i);
        v.into_iter().map(|(_, i)| i).collect()
    }

    /// Names of every interface, in the order provided.
    pub fn names(&self) -> Vec<String> {
        self.all().iter().map(|i| i.name().to_string()).collect()
    }

    pub fn contains(&self, name: &str) -> bool {
        self.table.read().contains_key(&canonical(name))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_increases_and_read_sees_latest() {
        let i: Interface<Motors> = Interface::new("motors", "test");
        assert_eq!(i.read().clock, 0);
        i.publish(Motors { v: 1.0, w: 2.0 }).unwrap();
        i.write(|m| m.v = 5.0).unwrap();
        let s = i.read();
        assert_eq!(s.clock, 2);
        assert_eq!(s.v, 5.0);
        assert_eq!(s.w, 2.0);
    }

    #[test]
    fn color_must_be_320x240() {
        let t = Interfaces::default();
        let c = t
            .provide_value("colorA", "t", Image::new(320, 240))
            .unwrap();
        assert!(
            c.publish(Image::new(640, 480))
                .unwrap_err()
                .contains("320x240")
        );
        let v = t.provide::<Image>("varcolorA", "t").unwrap();
        v.publish(Image::new(640, 480)).unwrap();
    }

    #[test]
    fn typed_lookup_and_aliases() {
        let t = Interfaces::default();
        t.provide::<PtMotors>("pantiltmotors", "t").unwrap();
        assert!(t.get::<PtMotors>("ptmotors").is_ok());
        assert!(matches!(
            t.get::<Laser>("ptmotors"),
            Err(InterfaceError::WrongType { .. })
        ));
        assert!(matches!(
            t.get::<Laser>("laser"),
            Err(InterfaceError::Missing { .. })
        ));
        assert!(matches!(
            t.provide::<PtMotors>("ptmotors", "u"),
            Err(InterfaceError::Duplicate { .. })
        ));
    }

    #[test]
    fn stale_motor_command_is_zero() {
        let m: Interface<Motors> = Interface::new("motors", "t");
        m.publish(Motors { v: 300.0, w: 0.0 }).unwrap();
        assert_eq!(m.command(Duration::from_secs(10)).v, 300.0);
        std::thread::sleep(Duration::from_millis(20));
        assert_eq!(m.command(Duration::from_millis(5)), Motors::default());
    }

    #[test]
    fn stale_until_next_publish() {
        let l: Interface<Laser> = Interface::new("laser", "t");
        assert_eq!(l.stale(), None);
        l.set_stale("player: localhost:6665 closed the connection");
        assert!(AnyInterface::stale(&l).unwrap().contains("6665"));
        l.publish(Laser::default()).unwrap();
        assert_eq!(l.stale(), None);
    }
}
