//! The worker that feeds one image interface from a stream of frames (a video file
//! through mplayer or ffmpeg, a capture device, a URL).
//!
//! - It works only while the interface is used: it waits (no child process, no
//!   CPU) until someone resumes the interface. When the last user suspends it, a
//!   file source is paused (the child blocks on the full pipe and keeps its place;
//!   `pause`), a live source is closed (the child is killed) and reopened on the
//!   next resume.
//! - Each new frame is one publish, so the interface's clock moves once per frame.
//! - Frames come at the source's rate ([`Pacer`]) or as fast as they decode.
//! - At the end of a file it starts again (`repeat`) or marks the interface stale
//!   ("end of ...") and starts again on the next resume.
//! - A source that fails (missing file, the child dies, a device unplugged, garbage
//!   on the pipe) marks the interface stale with the reason, logs it once, and is
//!   retried every 2 s while the interface is used, so a device that comes back
//!   is picked up again.
//! - [`Stream::stop`] kills the child (even one blocked on a stalled source) and
//!   joins the thread promptly.

use std::{
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::Duration,
};

use super::{MediaError, child::Killer, pace::Pacer};
use crate::{
    interfaces::{Image, Interface},
    supervisor::Worker,
};

/// A source of frames (one child process run, or one device session).
pub trait Frames: Send {
    /// Frames per second the source declares (for pacing).
    fn rate(&self) -> Option<f64>;
    /// Reads the next frame; `Ok(false)` at the end of the stream.
    fn read(&mut self) -> Result<bool, MediaError>;
    /// Writes the frame read last into `out` (setting its size).
    fn fill(&self, out: &mut Image);
    /// After the end of the stream: how the source ended.
    fn finish(self: Box<Self>) -> Result<(), MediaError>;
}

/// Opens a new run of the source; the [`Killer`] must be used for any child.
pub type Opener = Box<dyn FnMut(&Killer) -> Result<Box<dyn Frames>, MediaError> + Send>;

/// What a [`Stream`] plays and how.
pub struct StreamSpec {
    /// Names the source in messages (`mplayer clip.avi`).
    pub label: String,
    pub open: Opener,
    /// Publish at the source's rate (false: as fast as frames decode).
    pub pace: bool,
    /// Start again at the end.
    pub repeat: bool,
    /// Keep the source open and paused while the interface is unused (files);
    /// false closes it (live sources).
    pub pause: bool,
}

/// A running stream worker.
pub struct Stream {
    worker: Worker,
    killer: Killer,
    stop: Arc<AtomicBool>,
}

const RETRY: Duration = Duration::from_secs(2);
const POLL: Duration = Duration::from_millis(200);

impl Stream {
    /// Starts the worker thread for `iface`.
    pub fn start(spec: StreamSpec, iface: Arc<Interface<Image>>) -> anyhow::Result<Stream> {
        let stop = Arc::new(AtomicBool::new(false));
        let killer = Killer::default();
        let (s, k) = (stop.clone(), killer.clone());
        let name = format!("stream {}", iface.name());
        let worker = Worker::start(&name, stop.clone(), move || {
            Runner::new(spec, iface, s, k).run()
        })?;
        Ok(Stream {
            worker,
            killer,
            stop,
        })
    }

    /// Stops the worker: says stop, kills its child (so a blocked read ends
    /// and nothing restarts it) and joins the thread.
    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::Release);
        self.killer.kill_now();
        self.worker.stop();
    }
}

impl Drop for Stream {
    fn drop(&mut self) {
        self.stop();
    }
}

/// The stream's thread: runs the source, restarts it, publishes its frames.
struct Runner {
    spec: StreamSpec,
    iface: Arc<Interface<Image>>,
    stop: Arc<AtomicBool>,
    killer: Killer,
    last_error: Option<String>,
}

/// How a run of the source ended.
enum Outcome {
    Stop,
    /// Closed because nobody uses the interface.
    Unused,
    End,
    Failed(MediaError),
}

impl Runner {
    fn new(
        spec: StreamSpec,
        iface: Arc<Interface<Image>>,
        stop: Arc<AtomicBool>,
        killer: Killer,
    ) -> Self {
        Runner {
            spec,
            iface,
            stop,
            killer,
            last_error: None,
        }
    }

    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }

    /// Marks the interface stale and logs the reason (once while it repeats).
    fn report(&mut self, why: String) {
        if self.last_error.as_ref() != Some(&why) {
            tracing::error!("{}: {why}", self.iface.name());
        }
        self.iface.set_stale(why.clone());
        self.last_error = Some(why);
    }

    /// Sleeps `d` in short slices; false if stopped or the interface became unused.
    fn pause_for(&self, d: Duration) -> bool {
        let t0 = std::time::Instant::now();
        while t0.elapsed() < d {
            if self.stopped() || self.iface.users() == 0 {
                return false;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        true
    }

    fn run(mut self) {
        let mut pacer = Pacer::new(None);
        while !self.stopped() {
            if !self.iface.wait_used(POLL) {
                pacer.reset();
                continue;
            }
            let mut frames = match (self.spec.open)(&self.killer) {
                Ok(f) => f,
                Err(e) => {
                    if self.stopped() {
                        break;
                    }
                    self.report(e.to_string());
                    self.pause_for(RETRY);
                    continue;
                }
            };
            let rate = if self.spec.pace { frames.rate() } else { None };
            if pacer.period() != Pacer::new(rate).period() {
                pacer = Pacer::new(rate);
            }
            let mut count = 0u64;
            let outcome = loop {
                if self.stopped() {
                    break Outcome::Stop;
                }
                if self.iface.users() == 0 {
                    if !self.spec.pause {
                        break Outcome::Unused;
                    }
                    while !self.stopped() && !self.iface.wait_used(POLL) {}
                    pacer.reset();
                    continue;
                }
                match frames.read() {
                    Ok(true) => {
                        count += 1;
                        let stop = self.stop.clone();
                        pacer.wait(|| stop.load(Ordering::Acquire));
                        if let Err(e) = self.iface.write(|img| frames.fill(img)) {
                            break Outcome::Failed(MediaError::Child(e.to_string()));
                        }
                        self.last_error = None;
                    }
                    Ok(false) => break Outcome::End,
                    Err(e) => break Outcome::Failed(e),
                }
            };
            match outcome {
                Outcome::Stop => break,
                Outcome::Unused => {
                    pacer.reset();
                }
                Outcome::End => {
                    let ended = frames.finish();
                    if self.stopped() {
                        break;
                    }
                    match ended {
                        Err(e) => {
                            self.report(e.to_string());
                            self.pause_for(RETRY);
                        }
                        Ok(()) if count == 0 => {
                            let why = format!(
                                "{}: no frames (not a video it can play?)",
                                self.spec.label
                            );
                            self.report(why);
                            self.pause_for(RETRY);
                        }
                        Ok(()) if self.spec.repeat => {}
                        Ok(()) => {
                            self.iface.set_stale(format!(
                                "{}: end of the video (repeat off; stop and run again to replay)",
                                self.spec.label
                            ));
                            while self.pause_for(POLL) {}
                            pacer.reset();
                        }
                    }
                }
                Outcome::Failed(e) => {
                    drop(frames);
                    if self.stopped() {
                        break;
                    }
                    self.report(e.to_string());
                    self.pause_for(RETRY);
                    pacer.reset();
                }
            }
        }
    }
}
