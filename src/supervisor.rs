//! Threads and device supervision, for every driver and the media sources: a
//! [`Worker`] owns a thread and its stop flag; a [`Supervisor`] owns a device's
//! thread and its life, so a driver supplies only how to open its device and how
//! to serve one step of it. (Both are `runtime::Driver`s; they live here, below
//! the runtime, so `media` uses them too.)
//!
//! The supervisor's thread opens the device (only while somebody uses one of its
//! interfaces, for an on-demand device), serves it step by step until it is lost,
//! the driver stops, or nobody uses it any more; on a loss it hands the session to
//! the driver's `lost_session` (a last stop to the device), marks every interface
//! stale with the reason, runs the driver's `on_loss` (zeroing what moves), and
//! tries again after a bounded backoff. Each change of state (lost, still
//! unavailable for another reason, up again) is one line; a reason that repeats is not
//! logged again. Waits are interruptible: `terminate` returns within one step.

use std::{
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    thread::JoinHandle,
    time::{Duration, Instant},
};

use crate::interfaces::AnyInterface;

/// A device as the supervisor sees it.
pub trait Device: Send + 'static {
    /// An open device (a camera session, a connection, a port).
    type Session;
    /// Opens the device, or says why it cannot (the reason marks its interfaces
    /// stale, so it should name the device and what to do).
    fn open(&mut self) -> Result<Self::Session, String>;
    /// Serves one step (a frame, a poll), returning within about 200 ms so that a
    /// stop is seen promptly; an error is the reason the session is lost.
    fn step(&mut self, session: &mut Self::Session) -> Result<(), String>;
    /// Nobody uses the device's interfaces any more (an on-demand device): pause
    /// it (stop acquiring) and return true to keep the session open until somebody
    /// does, or false to have it closed (the default).
    fn idle(&mut self, _session: &mut Self::Session) -> bool {
        false
    }
    /// The session was lost (`step` failed): what can still be said to the
    /// device before the session is dropped, such as a stop to the wheels over a
    /// port that may still be writable. It must not wait for an answer. Runs
    /// before [`on_loss`](Device::on_loss); by default the session is just dropped.
    fn lost_session(&mut self, _session: Self::Session) {}
    /// The session was lost, or the driver stops: zero what moves. Runs before
    /// the interfaces are marked stale, so a zero published here keeps the reason.
    fn on_loss(&mut self) {}
    /// The driver stops (or the device went idle and was not kept) with a session
    /// open: say goodbye to the device. By default the session is just dropped.
    fn close(&mut self, _session: Self::Session) {}
}

/// A driver's worker thread. The thread polls its stop flag; [`Worker::stop`] (or
/// terminating or dropping the worker) sets it and waits for the thread to end. A
/// driver with nothing else to do at terminate is just its `Worker`.
pub struct Worker {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Worker {
    /// Starts `body` on a thread called `name`; `stop` is the flag it polls.
    pub fn start(
        name: &str,
        stop: Arc<AtomicBool>,
        body: impl FnOnce() + Send + 'static,
    ) -> anyhow::Result<Worker> {
        let thread = std::thread::Builder::new()
            .name(name.into())
            .spawn(body)
            .map_err(|e| anyhow::anyhow!("cannot start the {name} thread: {e}"))?;
        Ok(Worker {
            stop,
            thread: Some(thread),
        })
    }

    /// Asks the thread to stop and waits for it.
    pub fn stop(&mut self) {
        self.stop_waking(|| {});
    }

    /// [`Worker::stop`] for a thread that sleeps on something (a watch, a
    /// poll's waker): `wake` runs after the flag is set, so the thread cannot
    /// wake, find no flag and sleep again.
    pub fn stop_waking(&mut self, wake: impl FnOnce()) {
        self.stop.store(true, Ordering::Release);
        wake();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Waits between attempts to open: `first`, doubling up to `max`.
#[derive(Clone, Copy, Debug)]
pub struct Backoff {
    pub first: Duration,
    pub max: Duration,
}

impl Backoff {
    /// The same wait every time.
    pub const fn fixed(every: Duration) -> Backoff {
        Backoff {
            first: every,
            max: every,
        }
    }
}

/// How a device is supervised.
pub struct Supervision {
    /// For log lines and the thread's name: `firewire camera 0`.
    pub name: String,
    /// Its interfaces: marked stale with the reason while the device is down.
    pub interfaces: Vec<Arc<dyn AnyInterface>>,
    /// Open only while somebody uses one of the interfaces.
    pub on_demand: bool,
    pub backoff: Backoff,
    /// The reason it was found absent at start (already reported), if it was: the
    /// same reason is not logged again.
    pub absent: Option<String>,
}

/// How often a camera in use that cannot be opened is tried again.
pub const CAMERA_RETRY: Duration = Duration::from_secs(2);
/// How long a camera may send no frame before its interface counts as stale.
pub const CAMERA_NO_FRAME: Duration = Duration::from_secs(5);

/// A device not there at load: where its conf line is, the driver, why, and
/// what ends the wait (`the camera answers`).
pub struct Absent<'a> {
    pub at: &'a str,
    pub driver: &'a str,
    pub why: String,
    pub until: &'a str,
}

impl<'a> Absent<'a> {
    /// The device of `driver`'s conf line at `at` is absent for `why` until `until`.
    pub fn new(at: &'a str, driver: &'a str, why: String, until: &'a str) -> Absent<'a> {
        Absent {
            at,
            driver,
            why,
            until,
        }
    }
}

impl Supervision {
    /// A camera (or any on-demand device of one interface), retried every
    /// [`CAMERA_RETRY`] while used. When it was `absent` at load, that is said once
    /// (`AT: driver DRIVER: WHY; IFACE stays stale until UNTIL (tried every N s
    /// while used)`) and its interface is stale with the reason until it appears.
    pub fn camera(
        name: String,
        iface: Arc<dyn AnyInterface>,
        absent: Option<Absent>,
    ) -> Supervision {
        let retry = CAMERA_RETRY;
        let how = Supervision {
            name,
            interfaces: vec![iface.clone()],
            on_demand: true,
            backoff: Backoff::fixed(retry),
            absent: None,
        };
        match absent {
            None => how,
            Some(a) => {
                let line = format!(
                    "{}: driver {}: {}; {} stays stale until {} (tried every {} s while used)",
                    a.at,
                    a.driver,
                    a.why,
                    iface.name(),
                    a.until,
                    retry.as_secs()
                );
                how.absent_at_load(a.why, Some(line))
            }
        }
    }

    /// The device was absent at load: says `line` (once, if given), marks the
    /// interfaces stale with `why`, and the supervisor does not log that reason
    /// again; it says so when the device comes up.
    pub fn absent_at_load(mut self, why: String, line: Option<String>) -> Supervision {
        if let Some(line) = line {
            crate::output::println(line);
        }
        for i in &self.interfaces {
            i.set_stale(&why);
        }
        self.absent = Some(why);
        self
    }
}

/// A supervised device: its thread (a [`Worker`]) runs until [`Supervisor::stop`]
/// (or terminate, or drop).
pub struct Supervisor(Worker);

impl Supervisor {
    /// Starts supervising `device` on its own thread.
    pub fn start<D: Device>(how: Supervision, device: D) -> anyhow::Result<Supervisor> {
        let stop = Arc::new(AtomicBool::new(false));
        let s = stop.clone();
        let name: String = how.name.chars().take(15).collect();
        Ok(Supervisor(Worker::start(&name, stop, move || {
            run(how, device, &s)
        })?))
    }

    /// Asks the thread to stop and waits for it.
    pub fn stop(&mut self) {
        self.0.stop();
    }
}

/// Sleeps up to `d`, waking early on stop; false if stopping.
fn nap(stop: &AtomicBool, d: Duration) -> bool {
    let end = Instant::now() + d;
    while !stop.load(Ordering::Acquire) {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return true;
        }
        std::thread::sleep(left.min(Duration::from_millis(50)));
    }
    false
}

fn run<D: Device>(how: Supervision, mut device: D, stop: &AtomicBool) {
    let used = || !how.on_demand || how.interfaces.iter().any(|i| i.users() > 0);
    let stale = |why: &str| {
        for i in &how.interfaces {
            i.set_stale(why);
        }
    };
    // The last reason logged (None: up, or not tried yet).
    let mut down: Option<String> = how.absent.clone();
    let mut wait = how.backoff.first;
    while !stop.load(Ordering::Acquire) {
        if !used() {
            nap(stop, Duration::from_millis(50));
            continue;
        }
        let mut session = match device.open() {
            Ok(s) => s,
            Err(_) if stop.load(Ordering::Acquire) => break,
            Err(why) => {
                if down.as_deref() != Some(&why) {
                    tracing::warn!(
                        "{}: {why}; retrying every {} s while used",
                        how.name,
                        wait.as_secs_f64()
                    );
                }
                stale(&why);
                down = Some(why);
                nap(stop, wait);
                wait = (wait * 2).min(how.backoff.max);
                continue;
            }
        };
        // Back after a loss or an absence the user was told of: said as loudly.
        if down.take().is_some() {
            crate::output::println(format!("{}: up again", how.name));
        }
        wait = how.backoff.first;
        let lost = loop {
            if stop.load(Ordering::Acquire) {
                device.close(session);
                break None;
            }
            if !used() {
                if !device.idle(&mut session) {
                    device.close(session);
                    break Some(None);
                }
                while !used() && nap(stop, Duration::from_millis(50)) {}
                continue;
            }
            if let Err(why) = device.step(&mut session) {
                // A failure the stop caused (a killed child) is no loss.
                if stop.load(Ordering::Acquire) {
                    device.close(session);
                    break None;
                }
                break Some(Some((why, session)));
            }
        };
        match lost {
            None => break,
            Some(None) => {}
            Some(Some((why, session))) => {
                device.lost_session(session);
                tracing::warn!("{}: lost: {why}", how.name);
                device.on_loss();
                stale(&why);
                down = Some(why);
                nap(stop, wait);
            }
        }
    }
    device.on_loss();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::interfaces::{Interface, Laser};
    use std::sync::atomic::AtomicUsize;

    /// A device that opens on the third try, serves five steps, then is lost.
    struct Flaky {
        opens: Arc<AtomicUsize>,
        steps: usize,
        losses: Arc<AtomicUsize>,
        iface: Arc<Interface<Laser>>,
    }
    impl Device for Flaky {
        type Session = ();
        fn open(&mut self) -> Result<(), String> {
            if self.opens.fetch_add(1, Ordering::SeqCst) < 2 {
                Err("no device (plug it in)".into())
            } else {
                self.steps = 0;
                Ok(())
            }
        }
        fn step(&mut self, _: &mut ()) -> Result<(), String> {
            self.steps += 1;
            if self.steps > 5 {
                return Err("unplugged".into());
            }
            self.iface.write(|l| l.readings.push(1)).unwrap();
            std::thread::sleep(Duration::from_millis(2));
            Ok(())
        }
        fn on_loss(&mut self) {
            self.losses.fetch_add(1, Ordering::SeqCst);
        }
    }

    #[test]
    fn retries_marks_stale_with_the_reason_and_stops_promptly() {
        let iface: Arc<Interface<Laser>> = Arc::new(Interface::new("laser", "test"));
        let (opens, losses) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
        let mut s = Supervisor::start(
            Supervision {
                name: "flaky".into(),
                interfaces: vec![iface.clone()],
                on_demand: false,
                backoff: Backoff {
                    first: Duration::from_millis(5),
                    max: Duration::from_millis(20),
                },
                absent: None,
            },
            Flaky {
                opens: opens.clone(),
                steps: 0,
                losses: losses.clone(),
                iface: iface.clone(),
            },
        )
        .unwrap();
        let t0 = Instant::now();
        while losses.load(Ordering::SeqCst) < 2 && t0.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(losses.load(Ordering::SeqCst) >= 2, "lost and reopened");
        assert!(iface.read().clock >= 10, "served between losses");
        let stale = iface.stale();
        assert!(
            stale.as_deref() == Some("unplugged") || stale.is_none(),
            "{stale:?}"
        );
        s.stop();
        assert!(opens.load(Ordering::SeqCst) >= 4);
    }

    #[test]
    fn an_on_demand_device_opens_only_while_used() {
        let iface: Arc<Interface<Laser>> = Arc::new(Interface::new("laser", "test"));
        let opens = Arc::new(AtomicUsize::new(2)); // opens at once
        let mut s = Supervisor::start(
            Supervision {
                name: "lazy".into(),
                interfaces: vec![iface.clone()],
                on_demand: true,
                backoff: Backoff::fixed(Duration::from_millis(5)),
                absent: None,
            },
            Flaky {
                opens: opens.clone(),
                steps: 0,
                losses: Arc::new(AtomicUsize::new(0)),
                iface: iface.clone(),
            },
        )
        .unwrap();
        std::thread::sleep(Duration::from_millis(100));
        assert_eq!(opens.load(Ordering::SeqCst), 2, "not opened while unused");
        iface.resume();
        let t0 = Instant::now();
        while opens.load(Ordering::SeqCst) == 2 && t0.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(opens.load(Ordering::SeqCst) > 2, "opened once used");
        iface.suspend();
        s.stop();
    }
}
