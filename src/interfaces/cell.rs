//! One named, typed interface: the latest sample behind an atomic pointer, the
//! writer's recycled buffer, resume/suspend counting, staleness; every write
//! validated, and a clock that only grows.

use std::{
    any::Any,
    collections::VecDeque,
    sync::{
        Arc,
        atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering},
    },
    thread::Thread,
    time::{Duration, Instant, SystemTime},
};

use arc_swap::{ArcSwap, ArcSwapOption, Guard};
use parking_lot::{Condvar, Mutex};

use super::{
    kinds::Kind,
    source::Source,
    table::InterfaceError,
    values::{Image, InterfaceValue, Motors, PtMotors, limit},
};

/// The largest clock an interface takes from outside (a recording, a sender's
/// attachment): 2^53, what a JSON number holds exactly. A clock above it is
/// absurd (a million values a second for 285 years) and is refused, so a sender
/// cannot push the clock to where it would wrap.
pub const MAX_CLOCK: u64 = 1 << 53;

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

/// What writers share: a recycled buffer and recent publish times (for the rate).
struct Writer<T> {
    spare: Option<T>,
    /// Samples replaced while a reader still held them (a frame a network writer
    /// was sending, another waiting for room to be sent): the next write takes the
    /// buffer of the first one its readers have let go, so a writer that outruns
    /// its readers does not copy the latest value every time. At most [`HELD`],
    /// oldest first.
    held: VecDeque<Arc<Sample<T>>>,
    recent: VecDeque<Instant>,
    first: Option<Instant>,
    /// The latest samples, newest last, kept while someone needs every sample and
    /// not only the latest (see [`Interface::keep_history`]); empty otherwise.
    history: VecDeque<Arc<Sample<T>>>,
    /// How many readers asked for the history.
    historians: usize,
}

/// How many samples [`Interface::since`] can give back: at 20 Hz, a reader that
/// did not run for 0.8 s still misses nothing.
pub const HISTORY: usize = 16;

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

/// Which clock a write takes.
enum At {
    /// The next local clock.
    Next,
    /// This one, which must be after the current one (a recording).
    Recorded(u64, SystemTime),
    /// This one if it is after the current one and not absurd, else the next.
    Received(u64, SystemTime),
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
    /// An atomic pointer like the sample, so a publish never waits for a reader.
    stale: ArcSwapOption<String>,
    /// Told of every new value (see [`Interface::watch`]); none on most interfaces.
    watches: ArcSwapOption<Vec<Arc<dyn Notify>>>,
}

/// Something told of every new value of an interface it watches
/// ([`Interface::watch`]): a [`Watch`] waking a thread, or a forwarder that sends
/// small values on at once.
pub trait Notify: Send + Sync {
    /// Called on the publishing thread, after the new sample is visible and the
    /// interface's writer lock is released: keep it short and never block (the
    /// publisher may be a schema or a driver).
    fn notify(&self);
}

/// Wakes one thread when any interface it watches gets a new value, so a thread
/// that forwards values (a network publisher) sleeps until there is something to
/// send instead of polling clocks. A publish pays one atomic load when nobody
/// watches, and an unpark per watching thread otherwise.
pub struct Watch {
    thread: Thread,
    woken: AtomicBool,
}

impl Watch {
    /// A watch that wakes the calling thread (only that thread may [`wait`](Self::wait)).
    pub fn for_current_thread() -> Arc<Watch> {
        Arc::new(Watch {
            thread: std::thread::current(),
            woken: AtomicBool::new(false),
        })
    }

    /// Sleeps until a watched interface publishes or `timeout` passes; true when
    /// something was published since the previous call.
    pub fn wait(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        loop {
            if self.woken.swap(false, Ordering::AcqRel) {
                return true;
            }
            let now = Instant::now();
            if now >= deadline {
                return false;
            }
            std::thread::park_timeout(deadline - now);
        }
    }

    /// Wakes the thread now (for a stop request).
    pub fn wake(&self) {
        if !self.woken.swap(true, Ordering::AcqRel) {
            self.thread.unpark();
        }
    }
}

impl Notify for Watch {
    fn notify(&self) {
        self.wake();
    }
}

/// How many replaced samples a writer waits for readers to let go of (a frame
/// on the wire and one waiting for room: a Zenoh publisher holds two).
const HELD: usize = 3;

/// The value of the oldest held sample no reader holds any more, taken out.
fn let_go<T>(held: &mut VecDeque<Arc<Sample<T>>>) -> Option<T> {
    let i = held.iter().position(|s| Arc::strong_count(s) == 1)?;
    Arc::try_unwrap(held.remove(i)?).ok().map(|s| s.value)
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
                held: VecDeque::new(),
                recent: VecDeque::new(),
                first: None,
                history: VecDeque::new(),
                historians: 0,
            }),
            users: AtomicUsize::new(0),
            wake: (Mutex::new(()), Condvar::new()),
            clock: AtomicU64::new(0),
            stale: ArcSwapOption::empty(),
            watches: ArcSwapOption::empty(),
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
    pub fn publish(&self, value: T) -> Result<u64, InterfaceError> {
        value
            .validate(&self.name)
            .map_err(InterfaceError::Rejected)?;
        let clock = self.store(&mut self.writer.lock(), value).0;
        self.tell_watchers();
        Ok(clock)
    }

    /// Fills a recycled value in place and publishes it. `fill` gets the buffer of
    /// an *older* sample that no reader holds any more (also one a reader held
    /// when it was replaced and has let go since), or a copy of the latest value
    /// when every older one is still held; so steady streams of large values
    /// allocate and copy nothing. `fill` must set
    /// the whole value (a frame, a scan); for a partial update, copy the latest value
    /// (`read().value.clone()`), change it and [`publish`](Self::publish) it.
    pub fn write(&self, fill: impl FnOnce(&mut T)) -> Result<u64, InterfaceError> {
        self.write_at(At::Next, fill)
    }

    /// Publishes a recorded value with its recorded clock and wall time (for a
    /// replay driver, so that a schema sees the clocks of the original run). The
    /// clock must be greater than the current one.
    pub fn publish_recorded(
        &self,
        clock: u64,
        time: SystemTime,
        value: T,
    ) -> Result<u64, InterfaceError> {
        value
            .validate(&self.name)
            .map_err(InterfaceError::Rejected)?;
        let mut w = self.writer.lock();
        self.check_after(clock)?;
        let clock = self.store_at(&mut w, clock, time, value).0;
        drop(w);
        self.tell_watchers();
        Ok(clock)
    }

    /// [`write`](Self::write) with a recorded clock and time (see
    /// [`publish_recorded`](Self::publish_recorded)): a received frame is copied
    /// into a recycled buffer.
    pub fn write_recorded(
        &self,
        clock: u64,
        time: SystemTime,
        fill: impl FnOnce(&mut T),
    ) -> Result<u64, InterfaceError> {
        self.write_at(At::Recorded(clock, time), fill)
    }

    fn write_at(&self, at: At, fill: impl FnOnce(&mut T)) -> Result<u64, InterfaceError> {
        let mut w = self.writer.lock();
        let at = match at {
            At::Next => None,
            At::Recorded(clock, time) => {
                self.check_after(clock)?;
                Some((clock, time))
            }
            At::Received(clock, time) => self.check_after(clock).ok().map(|()| (clock, time)),
        };
        let mut value = match w.spare.take().or_else(|| let_go(&mut w.held)) {
            Some(v) => v,
            None => self.read().value.clone(),
        };
        fill(&mut value);
        if let Err(e) = value.validate(&self.name) {
            w.spare = Some(value);
            return Err(InterfaceError::Rejected(e));
        }
        let (clock, old) = match at {
            Some((clock, time)) => self.store_at(&mut w, clock, time, value),
            None => self.store(&mut w, value),
        };
        match Arc::try_unwrap(old) {
            Ok(s) => w.spare = Some(s.value),
            Err(old) => {
                if w.held.len() == HELD {
                    w.held.pop_front();
                }
                w.held.push_back(old);
            }
        }
        drop(w);
        self.tell_watchers();
        Ok(clock)
    }

    /// Publishes a value from outside (a device, a network peer): refused with
    /// one log line per change of state of `from` when it is not valid
    /// ([`InterfaceValue::validate`]). Returns the clock when it was published.
    pub fn accept(&self, from: &Source, value: T) -> Option<u64> {
        from.note(self.publish(value))
    }

    /// [`write`](Self::write) of a value from outside, checked and logged as
    /// [`accept`](Self::accept) does.
    pub fn accept_with(&self, from: &Source, fill: impl FnOnce(&mut T)) -> Option<u64> {
        from.note(self.write(fill))
    }

    /// Publishes a value received with its sender's clock: with that clock when
    /// it is ahead of the local one and not absurd (at most [`MAX_CLOCK`]), so
    /// `ps` shows the sender's clocks and a gap is a lost value; otherwise with the
    /// next local clock (the sender restarted, or sent nonsense). The clock only
    /// grows. An invalid value is refused as [`accept`](Self::accept) does.
    pub fn receive(
        &self,
        from: &Source,
        clock: u64,
        time: SystemTime,
        fill: impl FnOnce(&mut T),
    ) -> Option<u64> {
        let r = self.write_at(At::Received(clock, time), fill);
        from.note(r)
    }

    /// A recorded clock must come after the current one and be at most
    /// [`MAX_CLOCK`] (the caller holds the writer lock).
    fn check_after(&self, clock: u64) -> Result<(), InterfaceError> {
        let current = self.clock.load(Ordering::Relaxed);
        if clock <= current {
            return Err(InterfaceError::Clock(format!(
                "{}: recorded clock {clock} is not after the current clock {current}",
                self.name
            )));
        }
        if clock > MAX_CLOCK {
            return Err(InterfaceError::Clock(format!(
                "{}: clock {clock} is absurd (over 2^53); a clock counts values from 1",
                self.name
            )));
        }
        Ok(())
    }

    /// Swaps in a new sample (the caller holds the writer lock); returns its clock
    /// and the previous sample.
    fn store(&self, w: &mut Writer<T>, value: T) -> (u64, Arc<Sample<T>>) {
        let clock = self.clock.load(Ordering::Relaxed).saturating_add(1);
        self.store_at(w, clock, SystemTime::now(), value)
    }

    fn store_at(
        &self,
        w: &mut Writer<T>,
        clock: u64,
        time: SystemTime,
        value: T,
    ) -> (u64, Arc<Sample<T>>) {
        let stamp = Instant::now();
        let new = Arc::new(Sample {
            clock,
            stamp,
            time,
            value,
        });
        if w.historians > 0 {
            if w.history.len() == HISTORY {
                w.history.pop_front();
            }
            w.history.push_back(new.clone());
        }
        let old = self.slot.swap(new);
        self.clock.store(clock, Ordering::Release);
        w.published(stamp);
        if self.stale.load().is_some() {
            self.stale.store(None);
        }
        (clock, old)
    }

    /// Tells the watchers of a new value, after the writer lock is released (a
    /// watcher may publish elsewhere or send on a network).
    fn tell_watchers(&self) {
        if let Some(watches) = &*self.watches.load() {
            watches.iter().for_each(|w| w.notify());
        }
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
    pub fn set_stale(&self, why: impl std::fmt::Display) {
        self.stale.store(Some(Arc::new(why.to_string())));
    }

    /// Why the value is stale, if it is.
    pub fn stale(&self) -> Option<String> {
        self.stale.load_full().map(|why| why.as_ref().clone())
    }

    /// The source is back though no new value came: for an actuator whose
    /// receiver (a remote robot) reappeared. A sensor waits for its next publish.
    pub fn clear_stale(&self) {
        self.stale.store(None);
    }

    /// Keeps the last [`HISTORY`] samples from now on (`true`) for
    /// [`since`](Self::since), or stops when every reader that asked says `false`.
    /// For a reader that must see every sample, not only the latest (the recorder):
    /// a thread that wakes late would otherwise find only the newest one.
    pub fn keep_history(&self, on: bool) {
        let mut w = self.writer.lock();
        w.historians = if on {
            w.historians + 1
        } else {
            w.historians.saturating_sub(1)
        };
        if w.historians == 0 {
            w.history.clear();
        }
    }

    /// The samples after clock `after`, oldest first, from the history (or the
    /// latest alone when none is kept), and how many of them are gone: published
    /// and replaced more than [`HISTORY`] samples ago.
    pub fn since(&self, after: u64, out: &mut Vec<Arc<Sample<T>>>) -> u64 {
        let latest = self.snapshot();
        if latest.clock <= after {
            return 0;
        }
        let w = self.writer.lock();
        let kept = w.history.iter().filter(|s| s.clock > after);
        let first = match w.history.iter().find(|s| s.clock > after) {
            Some(s) => {
                out.extend(kept.cloned());
                s.clock
            }
            None => {
                drop(w);
                out.push(latest.clone());
                latest.clock
            }
        };
        first - after - 1
    }

    /// Tells `watcher` of every new value from now on.
    pub fn watch(&self, watcher: Arc<dyn Notify>) {
        self.watches.rcu(|ws| {
            let mut v: Vec<Arc<dyn Notify>> = ws.as_deref().cloned().unwrap_or_default();
            v.push(watcher.clone());
            Some(Arc::new(v))
        });
    }

    /// Stops telling `watcher`.
    pub fn unwatch(&self, watcher: &dyn Notify) {
        self.watches.rcu(|ws| {
            let v: Vec<Arc<dyn Notify>> = ws
                .iter()
                .flat_map(|v| v.iter())
                .filter(|w| !std::ptr::addr_eq(Arc::as_ptr(w), watcher as *const dyn Notify))
                .cloned()
                .collect();
            (!v.is_empty()).then(|| Arc::new(v))
        });
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

impl Interface<Image> {
    /// Publishes a captured `width` x `height` frame by swapping `data` in (the
    /// old buffer comes back in `data` for the next frame, so capture allocates
    /// nothing); a frame that cannot be published marks the interface stale.
    pub fn publish_frame(&self, width: u32, height: u32, data: &mut Vec<u8>) {
        if let Err(e) = self.write(|img| {
            img.width = width;
            img.height = height;
            std::mem::swap(&mut img.data, data);
        }) {
            self.set_stale(e);
        }
    }
}

impl Interface<PtMotors> {
    /// Points the unit at (`longitude`, `latitude`) degrees, limited to its range,
    /// keeping the latest speeds and limits: the partial update every pan-tilt
    /// operator makes (see [`write`](Self::write) for why it is not one).
    pub fn point(&self, longitude: f32, latitude: f32) -> Result<u64, InterfaceError> {
        let mut m = self.read().value;
        m.longitude = limit(longitude, m.min_longitude, m.max_longitude);
        m.latitude = limit(latitude, m.min_latitude, m.max_latitude);
        self.publish(m)
    }
}

/// What every interface offers whatever its type (for the shell, the GUI, `ps`).
pub trait AnyInterface: Any + Send + Sync {
    fn name(&self) -> &str;
    /// The interface family (`laser`, `image`, ...).
    fn kind(&self) -> Kind;
    /// The component that provides it.
    fn provider(&self) -> &str;
    fn is_actuator(&self) -> bool;
    fn clock(&self) -> u64;
    /// A fingerprint of the latest value: equal values give equal fingerprints, so
    /// a viewer can tell a new value from a repeat (the GUI repaints on it).
    fn fingerprint(&self) -> u64;
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
    fn set_fields(&self, fields: &[(&str, &str)]) -> Result<u64, InterfaceError>;
    /// See [`Interface::set_stale`].
    fn set_stale(&self, why: &str);
    /// See [`Interface::clear_stale`].
    fn clear_stale(&self);
    /// See [`Interface::watch`].
    fn watch(&self, watcher: Arc<dyn Notify>);
    /// See [`Interface::unwatch`].
    fn unwatch(&self, watcher: &dyn Notify);
}

impl<T: InterfaceValue> AnyInterface for Interface<T> {
    fn name(&self) -> &str {
        &self.name
    }
    fn kind(&self) -> Kind {
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
    fn fingerprint(&self) -> u64 {
        self.read().value.fingerprint()
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
    fn set_fields(&self, fields: &[(&str, &str)]) -> Result<u64, InterfaceError> {
        let mut v = self.read().value.clone();
        for (f, val) in fields {
            v.set_field(f, val).map_err(InterfaceError::Field)?;
        }
        self.publish(v)
    }
    fn set_stale(&self, why: &str) {
        Interface::set_stale(self, why)
    }
    fn clear_stale(&self) {
        Interface::clear_stale(self)
    }
    fn watch(&self, watcher: Arc<dyn Notify>) {
        Interface::watch(self, watcher)
    }
    fn unwatch(&self, watcher: &dyn Notify) {
        Interface::unwatch(self, watcher)
    }
}
