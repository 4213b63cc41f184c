//! Emergency stop: one place that stops every actuator when the process ends, is
//! suspended, or panics.
//!
//! A driver that moves something registers how to stop it with [`register`]: a
//! closure that writes the stop straight to its device (the Create 2's zero Drive
//! Direct through its own handle on the port), holding no lock the driver's
//! thread may hold. The registration lasts as long as the returned
//! [`Registration`] (a driver keeps it in its open session). [`stop_all`] runs
//! every registered stop; [`halt`] does too and latches [`halted`], which a
//! driver checks before it sends a motion command, so that nothing it sends
//! after the stop undoes it while the process shuts down.
//!
//! [`install`] (the binary's `cli` calls it) makes the process use it:
//!
//! | what happens | what is done |
//! |---|---|
//! | SIGINT, SIGTERM, SIGHUP | [`halt`], then the caller's `quit` (shut down, exit 128+signal) on a thread of its own; a second one exits at once. SIGINT first asks `interrupt` (a shell command waiting): if it takes it, nothing else |
//! | SIGTSTP (Ctrl+Z), SIGTTIN, SIGTTOU | [`halted`] until the process runs on, [`stop_all`], then the process suspends as by default; after SIGCONT it runs on (the drivers send what their controllers command again). The thread the signal came to waits in its handler until then, as the default action would have it (rustyline sends itself SIGTSTP on Ctrl+Z and puts the terminal back in raw mode when that returns) |
//! | SIGQUIT, SIGALRM | [`halt`], then the default action (the process ends; SIGQUIT dumps core) |
//! | SIGABRT (`abort`, a failed allocation, a stack overflow, a panic while panicking) | [`halt`] before the process dies (the aborting thread waits for it, at most [`FATAL_WAIT`]) |
//! | a panic on any thread | [`stop_all`] before the panic is reported (the panicking thread waits, at most [`FATAL_WAIT`]); a panic on the `main` thread ends the process: [`halt`] |
//!
//! A signal disposition the process inherited as ignored (`nohup`, a background
//! job's SIGINT) is left ignored. The signal handlers only write the signal's
//! number to a pipe (async-signal-safe), and wait where the table says so; the
//! stops run on the thread `estop` that reads it, and the waits are bounded (but
//! for a suspension's own length), so a stop that hangs cannot keep the process
//! from ending. What no process can catch (SIGKILL, SIGSTOP,
//! power loss, `_exit` from a foreign library) sends nothing: see
//! docs/serial-robots.md for what the robot itself offers.

use std::{
    panic::{AssertUnwindSafe, catch_unwind},
    sync::{
        Arc, Condvar, Mutex, MutexGuard,
        atomic::{AtomicBool, AtomicU64, Ordering},
    },
    time::Duration,
};

type Stop = Arc<dyn Fn() + Send + Sync>;

struct Entry {
    id: u64,
    name: String,
    stop: Stop,
}

static REGISTRY: Mutex<Vec<Entry>> = Mutex::new(Vec::new());
static NEXT_ID: AtomicU64 = AtomicU64::new(1);
static HALTED: AtomicBool = AtomicBool::new(false);
/// Set from just before a suspension's stops until the process runs on.
static SUSPENDED: AtomicBool = AtomicBool::new(false);

/// How long a panicking or aborting thread waits for the stops.
pub const FATAL_WAIT: Duration = Duration::from_millis(300);

fn registry() -> MutexGuard<'static, Vec<Entry>> {
    REGISTRY.lock().unwrap_or_else(|p| p.into_inner())
}

/// A registered stop; dropping it unregisters the stop.
#[must_use = "the stop is unregistered when this is dropped"]
pub struct Registration(u64);

impl Drop for Registration {
    fn drop(&mut self) {
        registry().retain(|e| e.id != self.0);
    }
}

/// Registers `stop` under `name` (`roomba /dev/ttyUSB0`) until the returned
/// [`Registration`] drops. `stop` must return promptly (write the stop bytes,
/// with the device's write timeout), must not wait for a lock the driver's
/// thread may hold, and may run on any thread, several times, and concurrently
/// with the driver.
pub fn register(name: impl Into<String>, stop: impl Fn() + Send + Sync + 'static) -> Registration {
    let id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
    registry().push(Entry {
        id,
        name: name.into(),
        stop: Arc::new(stop),
    });
    Registration(id)
}

/// The names of the registered stops.
pub fn registered() -> Vec<String> {
    registry().iter().map(|e| e.name.clone()).collect()
}

thread_local! {
    /// Set while this thread runs the stops (a stop that panics must not wait for itself).
    static STOPPING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs every registered stop now, and says so in one line naming `why` and the
/// devices; returns their names.
pub fn stop_all(why: &str) -> Vec<String> {
    let all: Vec<(String, Stop)> = registry()
        .iter()
        .map(|e| (e.name.clone(), e.stop.clone()))
        .collect();
    STOPPING.with(|s| s.set(true));
    for (name, stop) in &all {
        if catch_unwind(AssertUnwindSafe(|| stop())).is_err() {
            tracing::error!("{why}: the emergency stop of {name} panicked");
        }
    }
    STOPPING.with(|s| s.set(false));
    let names: Vec<String> = all.into_iter().map(|(n, _)| n).collect();
    if !names.is_empty() {
        tracing::warn!("{why}: stop sent to {}", names.join(", "));
    }
    names
}

/// The process is ending: latches [`halted`] and runs every stop.
pub fn halt(why: &str) -> Vec<String> {
    HALTED.store(true, Ordering::Release);
    stop_all(why)
}

/// Whether the process is ending after [`halt`], or is being suspended (from
/// just before the stops until it runs on after SIGCONT): a driver sends no
/// motion command (zero instead), so nothing its thread sends in the moment
/// before the process stops undoes the stop.
pub fn halted() -> bool {
    HALTED.load(Ordering::Acquire) || SUSPENDED.load(Ordering::Acquire)
}

/// What the `estop` thread is asked to do: a signal's number, or a panic.
const PANIC: u8 = 0;
const PANIC_MAIN: u8 = 255;

/// Stops done by the `estop` thread, counted, for a panicking thread to wait on.
static DONE: (Mutex<u64>, Condvar) = (Mutex::new(0), Condvar::new());

fn done_count() -> u64 {
    *DONE.0.lock().unwrap_or_else(|p| p.into_inner())
}

fn count_done() {
    *DONE.0.lock().unwrap_or_else(|p| p.into_inner()) += 1;
    DONE.1.notify_all();
}

/// Waits until more than `before` stops were done, at most `d`.
fn wait_done(before: u64, d: Duration) {
    let g = DONE.0.lock().unwrap_or_else(|p| p.into_inner());
    let _ = DONE.1.wait_timeout_while(g, d, |n| *n <= before);
}

/// Installs the signal handlers and the panic hook described in the module's
/// documentation, and starts the `estop` thread. `interrupt` is asked on SIGINT
/// whether it only interrupts something (a shell command waiting): true, and
/// nothing else is done. `quit(code)` shuts the program down and exits with
/// `code` (128 + the signal's number). Call it once, from the binary.
#[cfg(unix)]
pub fn install(
    interrupt: impl Fn() -> bool + Send + 'static,
    quit: impl Fn(i32) + Send + Sync + 'static,
) -> std::io::Result<()> {
    signals::install(Box::new(interrupt), Arc::new(quit))?;
    let loud = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if !STOPPING.with(|s| s.get()) && signals::running() {
            let main = std::thread::current().name() == Some("main");
            let before = done_count();
            signals::wake(if main { PANIC_MAIN } else { PANIC });
            wait_done(before, FATAL_WAIT);
        }
        loud(info)
    }));
    Ok(())
}

#[cfg(unix)]
mod signals {
    use super::{PANIC, PANIC_MAIN, count_done, halt, stop_all};
    use libc::c_int;
    use std::sync::{
        Arc,
        atomic::{AtomicBool, AtomicI32, AtomicU64, Ordering},
    };

    /// The pipe the handlers write to (write end, non-blocking) and the thread
    /// reads (read end, blocking).
    static WAKE_W: AtomicI32 = AtomicI32::new(-1);
    /// The handlers of SIGABRT and the stop signals wait on this pipe (a wake-up
    /// only) until the thread counts their request done in `DONE`.
    static ACK_R: AtomicI32 = AtomicI32::new(-1);
    static ACK_W: AtomicI32 = AtomicI32::new(-1);
    static DONE: AtomicU64 = AtomicU64::new(0);
    /// The thread is suspending the process, or is suspended: keep waiting.
    static SUSPENDING: AtomicBool = AtomicBool::new(false);
    static RUNNING: AtomicBool = AtomicBool::new(false);

    const QUIT: &[c_int] = &[libc::SIGINT, libc::SIGTERM, libc::SIGHUP];
    const SUSPEND: &[c_int] = &[libc::SIGTSTP, libc::SIGTTIN, libc::SIGTTOU];
    const FATAL: &[c_int] = &[libc::SIGQUIT, libc::SIGALRM, libc::SIGABRT];

    pub fn running() -> bool {
        RUNNING.load(Ordering::Acquire)
    }

    fn name(sig: c_int) -> String {
        match sig {
            libc::SIGINT => "SIGINT".into(),
            libc::SIGTERM => "SIGTERM".into(),
            libc::SIGHUP => "SIGHUP".into(),
            libc::SIGTSTP => "SIGTSTP".into(),
            libc::SIGTTIN => "SIGTTIN".into(),
            libc::SIGTTOU => "SIGTTOU".into(),
            libc::SIGQUIT => "SIGQUIT".into(),
            libc::SIGALRM => "SIGALRM".into(),
            libc::SIGABRT => "SIGABRT".into(),
            s => format!("signal {s}"),
        }
    }

    /// Asks the thread to act on `what` (async-signal-safe).
    pub fn wake(what: u8) {
        let fd = WAKE_W.load(Ordering::Acquire);
        if fd >= 0 {
            // SAFETY: writes one byte from a live local to an fd we own; write is
            // async-signal-safe. A full pipe (EAGAIN) drops the byte: the thread
            // has a request of that kind queued already.
            unsafe { libc::write(fd, (&what as *const u8).cast(), 1) };
        }
    }

    extern "C" fn on_signal(sig: c_int) {
        // SAFETY: only async-signal-safe calls (write, poll, read, sigaction,
        // raise) and atomics; errno saved and restored around them.
        unsafe {
            let errno = *libc::__errno_location();
            let before = DONE.load(Ordering::Acquire);
            wake(sig as u8);
            if sig == libc::SIGABRT || SUSPEND.contains(&sig) {
                // SIGABRT: the process dies when this returns. A stop signal: the
                // thread that sent it (rustyline's Ctrl+Z sends SIGTSTP to its own
                // process and then puts the terminal back in raw mode) must go on
                // only after the suspension, as with the default action.
                wait_done(before);
            }
            if sig == libc::SIGABRT {
                // Pending (blocked in its own handler) until this returns, then
                // the default action: the process ends even when SIGABRT came
                // from kill, not from abort().
                set(sig, libc::SIG_DFL);
                libc::raise(sig);
            }
            *libc::__errno_location() = errno;
        }
    }

    /// Waits until the thread has done more than `before` requests: at most
    /// [`super::FATAL_WAIT`] for it to start, and then as long as it is
    /// suspending the process. (Async-signal-safe: poll, read, atomics.)
    fn wait_done(before: u64) {
        let fd = ACK_R.load(Ordering::Acquire);
        let mut idle_ms = 0;
        while DONE.load(Ordering::Acquire) <= before {
            let mut p = libc::pollfd {
                fd,
                events: libc::POLLIN,
                revents: 0,
            };
            // SAFETY: polls and drains a pipe we own, into a live local.
            unsafe {
                if libc::poll(&mut p, 1, 50) > 0 {
                    let mut b = [0u8; 16];
                    libc::read(fd, b.as_mut_ptr().cast(), b.len());
                }
            }
            if SUSPENDING.load(Ordering::Acquire) {
                idle_ms = 0;
            } else {
                idle_ms += 50;
                if idle_ms as u128 >= super::FATAL_WAIT.as_millis() {
                    return;
                }
            }
        }
    }

    /// Counts a request done and wakes the handlers waiting for it.
    fn done() {
        DONE.fetch_add(1, Ordering::AcqRel);
        let b = 1u8;
        // SAFETY: one byte from a live local to the non-blocking ack pipe.
        unsafe { libc::write(ACK_W.load(Ordering::Acquire), (&b as *const u8).cast(), 1) };
    }

    /// Blocks (`how` SIG_BLOCK) or unblocks the stop signals on this thread.
    fn mask_suspend(how: c_int) {
        // SAFETY: a signal set built and used locally.
        unsafe {
            let mut set: libc::sigset_t = std::mem::zeroed();
            libc::sigemptyset(&mut set);
            for &s in SUSPEND {
                libc::sigaddset(&mut set, s);
            }
            libc::pthread_sigmask(how, &set, std::ptr::null_mut());
        }
    }

    /// Sets `sig`'s handler; false if it was inherited as ignored (and stays so).
    fn catch(sig: c_int) -> bool {
        // SAFETY: plain sigaction calls on zeroed structs.
        unsafe {
            let mut old: libc::sigaction = std::mem::zeroed();
            if libc::sigaction(sig, std::ptr::null(), &mut old) == 0
                && old.sa_sigaction == libc::SIG_IGN
            {
                return false;
            }
            set(sig, on_signal as extern "C" fn(c_int) as libc::sighandler_t);
        }
        true
    }

    /// # Safety
    /// `handler` is SIG_DFL, SIG_IGN or an async-signal-safe `extern "C" fn(c_int)`.
    unsafe fn set(sig: c_int, handler: libc::sighandler_t) {
        // SAFETY: the caller's promise; the struct is zeroed then filled.
        unsafe {
            let mut sa: libc::sigaction = std::mem::zeroed();
            sa.sa_sigaction = handler;
            sa.sa_flags = libc::SA_RESTART;
            libc::sigemptyset(&mut sa.sa_mask);
            libc::sigaction(sig, &sa, std::ptr::null_mut());
        }
    }

    fn pipe(flags_w: c_int, flags_r: c_int) -> std::io::Result<(c_int, c_int)> {
        let mut fds = [0 as c_int; 2];
        // SAFETY: pipe2 fills the two-element array.
        if unsafe { libc::pipe2(fds.as_mut_ptr(), libc::O_CLOEXEC) } != 0 {
            return Err(std::io::Error::last_os_error());
        }
        for (fd, fl) in [(fds[0], flags_r), (fds[1], flags_w)] {
            if fl != 0 {
                // SAFETY: fcntl on an fd just created.
                unsafe {
                    let old = libc::fcntl(fd, libc::F_GETFL);
                    libc::fcntl(fd, libc::F_SETFL, old | fl);
                }
            }
        }
        Ok((fds[0], fds[1]))
    }

    /// Reads the next request; None if the pipe is gone.
    fn next(fd: c_int, block: bool) -> Option<u8> {
        loop {
            let mut b = 0u8;
            if !block {
                let mut p = libc::pollfd {
                    fd,
                    events: libc::POLLIN,
                    revents: 0,
                };
                // SAFETY: polls one fd we own, without waiting.
                if unsafe { libc::poll(&mut p, 1, 0) } <= 0 {
                    return None;
                }
            }
            // SAFETY: reads one byte into a live local.
            let n = unsafe { libc::read(fd, (&mut b as *mut u8).cast(), 1) };
            if n == 1 {
                return Some(b);
            }
            if n < 0 && std::io::Error::last_os_error().kind() == std::io::ErrorKind::Interrupted {
                continue;
            }
            return None;
        }
    }

    /// Suspends the process as `sig`'s default action would, then catches it
    /// again. The stop signals are blocked on this thread but here (so that no
    /// handler waits on the thread that must do the suspending).
    fn suspend(sig: c_int) {
        SUSPENDING.store(true, Ordering::Release);
        // SAFETY: SIG_DFL for `sig`, unblocked on this thread, raised on this
        // thread: the process stops before `raise` returns, and runs on after
        // SIGCONT; then the handler is set back.
        unsafe {
            set(sig, libc::SIG_DFL);
            mask_suspend(libc::SIG_UNBLOCK);
            libc::raise(sig);
            mask_suspend(libc::SIG_BLOCK);
            set(sig, on_signal as extern "C" fn(c_int) as libc::sighandler_t);
        }
        SUSPENDING.store(false, Ordering::Release);
    }

    /// Ends the process by `sig`'s default action.
    fn die_by(sig: c_int) {
        // SAFETY: as in `suspend`; the default action of these ends the process.
        unsafe {
            set(sig, libc::SIG_DFL);
            let mut only: libc::sigset_t = std::mem::zeroed();
            libc::sigemptyset(&mut only);
            libc::sigaddset(&mut only, sig);
            libc::pthread_sigmask(libc::SIG_UNBLOCK, &only, std::ptr::null_mut());
            libc::raise(sig);
        }
    }

    pub fn install(
        interrupt: Box<dyn Fn() -> bool + Send>,
        quit: Arc<dyn Fn(i32) + Send + Sync>,
    ) -> std::io::Result<()> {
        if RUNNING.load(Ordering::Acquire) {
            return Ok(());
        }
        let (wake_r, wake_w) = pipe(libc::O_NONBLOCK, 0)?;
        let (ack_r, ack_w) = pipe(libc::O_NONBLOCK, libc::O_NONBLOCK)?;
        WAKE_W.store(wake_w, Ordering::Release);
        ACK_R.store(ack_r, Ordering::Release);
        ACK_W.store(ack_w, Ordering::Release);
        std::thread::Builder::new()
            .name("estop".into())
            .spawn(move || serve(wake_r, interrupt, quit))?;
        RUNNING.store(true, Ordering::Release);
        for &sig in QUIT.iter().chain(SUSPEND).chain(FATAL) {
            if !catch(sig) {
                tracing::debug!("{} is ignored (inherited): left so", name(sig));
            }
        }
        Ok(())
    }

    fn serve(
        fd: c_int,
        interrupt: Box<dyn Fn() -> bool + Send>,
        quit: Arc<dyn Fn(i32) + Send + Sync>,
    ) {
        mask_suspend(libc::SIG_BLOCK);
        let mut quitting = false;
        let mut queued: Vec<u8> = Vec::new();
        loop {
            let what = if queued.is_empty() {
                match next(fd, true) {
                    Some(b) => b,
                    None => return,
                }
            } else {
                queued.remove(0)
            };
            let sig = what as c_int;
            match what {
                PANIC => {
                    stop_all("a panic");
                    count_done();
                }
                PANIC_MAIN => {
                    halt("a panic on the main thread");
                    count_done();
                }
                _ if sig == libc::SIGINT && !quitting && interrupt() => {}
                _ if QUIT.contains(&sig) => {
                    let n = name(sig);
                    halt(&n);
                    if quitting {
                        tracing::warn!("{n} again: exiting now");
                        std::process::exit(128 + sig);
                    }
                    quitting = true;
                    let quit = quit.clone();
                    let spawned = std::thread::Builder::new()
                        .name("quit".into())
                        .spawn(move || quit(128 + sig));
                    if spawned.is_err() {
                        std::process::exit(128 + sig);
                    }
                }
                _ if SUSPEND.contains(&sig) => {
                    super::SUSPENDED.store(true, Ordering::Release);
                    stop_all(&name(sig));
                    suspend(sig);
                    super::SUSPENDED.store(false, Ordering::Release);
                    done();
                    tracing::info!("continued after {}", name(sig));
                    // The requests that came before the suspension: a stop signal
                    // repeated (a background read retried) is passed over.
                    while let Some(b) = next(fd, false) {
                        if !SUSPEND.contains(&(b as c_int)) {
                            queued.push(b);
                        }
                    }
                }
                _ if sig == libc::SIGABRT => {
                    halt("SIGABRT (the process aborts)");
                    done();
                }
                _ if FATAL.contains(&sig) => {
                    halt(&name(sig));
                    die_by(sig);
                }
                _ => {}
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    #[test]
    fn registered_stops_run_until_their_registration_drops() {
        let n = Arc::new(AtomicUsize::new(0));
        let r = {
            let n = n.clone();
            register("test actuator", move || {
                n.fetch_add(1, Ordering::SeqCst);
            })
        };
        let p = register("panicking actuator", || panic!("broken stop"));
        assert!(registered().contains(&"test actuator".to_string()));
        let names = stop_all("a test");
        assert!(names.contains(&"test actuator".to_string()), "{names:?}");
        assert!(names.contains(&"panicking actuator".to_string()));
        assert_eq!(n.load(Ordering::SeqCst), 1);
        drop(r);
        drop(p);
        stop_all("a test");
        assert_eq!(n.load(Ordering::SeqCst), 1, "unregistered");
        assert!(!registered().contains(&"test actuator".to_string()));
    }
}
