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
//!
//! The thread is a [`Supervisor`]'s: the source is a [`Device`] whose session is
//! one run of it (open = start the child or the device, a step = one frame).

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
    supervisor::{Backoff, Device, Supervision, Supervisor},
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

/// A running stream: its supervised source.
pub struct Stream {
    source: Supervisor,
    killer: Killer,
    stop: Arc<AtomicBool>,
}

/// How long a failed source waits before it is opened again.
const RETRY: Duration = Duration::from_secs(2);
/// How long a step waits at the end of a video that does not repeat.
const ENDED: Duration = Duration::from_millis(50);

impl Stream {
    /// Starts feeding `iface` from `spec`'s source.
    pub fn start(spec: StreamSpec, iface: Arc<Interface<Image>>) -> anyhow::Result<Stream> {
        let stop = Arc::new(AtomicBool::new(false));
        let killer = Killer::default();
        let how = Supervision {
            name: format!("{} ({})", spec.label, iface.name()),
            interfaces: vec![iface.clone()],
            on_demand: true,
            backoff: Backoff::fixed(RETRY),
            absent: None,
        };
        let source = Source {
            spec,
            iface,
            stop: stop.clone(),
            killer: killer.clone(),
            pacer: Pacer::new(None),
        };
        Ok(Stream {
            source: Supervisor::start(how, source)?,
            killer,
            stop,
        })
    }

    /// Stops the stream: says stop, kills its child (so a blocked read ends
    /// and nothing restarts it) and joins the thread.
    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::Release);
        self.killer.kill_now();
        self.source.stop();
    }
}

impl Drop for Stream {
    fn drop(&mut self) {
        self.stop();
    }
}

/// The source as its [`Supervisor`] runs it: open = start a run of the source,
/// a step = one frame, paced.
struct Source {
    spec: StreamSpec,
    iface: Arc<Interface<Image>>,
    stop: Arc<AtomicBool>,
    killer: Killer,
    pacer: Pacer,
}

/// One run of the source.
struct Run {
    /// None after the end of a video that does not repeat: nothing more until
    /// the interface is used again.
    frames: Option<Box<dyn Frames>>,
    /// Frames read in this run.
    count: u64,
}

impl Source {
    fn stopping(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }

    /// A new run of the source, paced at its rate.
    fn start_run(&mut self) -> Result<Run, String> {
        let frames = (self.spec.open)(&self.killer).map_err(|e| e.to_string())?;
        let rate = if self.spec.pace { frames.rate() } else { None };
        if self.pacer.period() != Pacer::new(rate).period() {
            self.pacer = Pacer::new(rate);
        }
        self.pacer.reset();
        Ok(Run {
            frames: Some(frames),
            count: 0,
        })
    }

    /// The end of a run: an error if the source failed or gave no frame; else
    /// again (`repeat`), or the interface stale until it is used again.
    fn end_of_run(&mut self, run: &mut Run) -> Result<(), String> {
        if let Some(f) = run.frames.take() {
            f.finish().map_err(|e| e.to_string())?;
        }
        if run.count == 0 {
            return Err(format!(
                "{}: no frames (not a video it can play?)",
                self.spec.label
            ));
        }
        if self.spec.repeat {
            *run = self.start_run()?;
        } else {
            self.iface.set_stale(format!(
                "{}: end of the video (repeat off; stop and run again to replay)",
                self.spec.label
            ));
        }
        Ok(())
    }
}

impl Device for Source {
    type Session = Run;

    fn open(&mut self) -> Result<Run, String> {
        self.start_run()
    }

    fn step(&mut self, run: &mut Run) -> Result<(), String> {
        let Some(frames) = &mut run.frames else {
            std::thread::sleep(ENDED);
            return Ok(());
        };
        let r = match frames.read() {
            Ok(true) => {
                run.count += 1;
                let stop = self.stop.clone();
                self.pacer.wait(|| stop.load(Ordering::Acquire));
                self.iface
                    .write(|img| frames.fill(img))
                    .map(|_| ())
                    .map_err(|e| e.to_string())
            }
            Ok(false) => self.end_of_run(run),
            Err(e) => Err(e.to_string()),
        };
        // A run killed because the stream stops is no failure.
        if self.stopping() { Ok(()) } else { r }
    }

    /// Unused: a file source stays open, paused (its child blocks on the full
    /// pipe and keeps its place); a live one, or a video at its end, is closed
    /// and opened again on the next use.
    fn idle(&mut self, run: &mut Run) -> bool {
        self.pacer.reset();
        self.spec.pause && run.frames.is_some()
    }
}
