//! A client's thread, from its name to its goodbye: it reads the client's requests
//! (with the partial-line and idle rules) and writes what they ask for (replies,
//! image frames, pushes paced every 33 ms). Between the two it sleeps in `ppoll(2)`
//! on the socket and on the client's [`Bell`], which a served image's publish rings
//! while the thread waits for a frame ([`super::frames::FrameWake`]).
//!
//! One thread, not a reader thread and a writer thread (as until 2026-11-28): a
//! request then costs no thread wake-up, and two cores have fewer threads to
//! share (640x480 frames, alternated on the same bench: 86-87 % of a raw TCP copy
//! against 65-85 % with two threads; `docs/network.md`). Requests are read
//! without waiting (`recv` with `MSG_DONTWAIT`) before each write; writes block,
//! up to `timeout`, so a client that stops reading holds only its own thread, and
//! its requests wait in the kernel's buffer meanwhile.

use std::{
    io::{self, Read},
    net::TcpStream,
    os::fd::AsRawFd,
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering, fence},
    },
    time::{Duration, Instant},
};

use crate::{
    interfaces::{AnyInterface, Source},
    netwire::{self, Feed, LineEvent, LineReader, OnWire, Request},
};

use super::{
    Shared, Sources,
    clients::Slot,
    frames::{self, Bell},
};

/// Why a connection ends, and whether it was the client's fault.
pub(super) type End = (String, bool);

/// What a client's thread shares with the publishes of the images it serves.
pub(super) struct Client {
    pub(super) bell: Bell,
    /// The thread sleeps waiting for a frame (so a new frame must ring the bell).
    pub(super) waiting_frame: AtomicBool,
}

/// Interfaces a client resumed, to suspend when it leaves.
#[derive(Default)]
pub(super) struct Resumed {
    pub(super) subs: [Option<Arc<dyn AnyInterface>>; Feed::COUNT],
    pub(super) images: Vec<bool>,
}

/// Lines read in one go before the thread writes what is due: a client that sends
/// without pause still gets its frames and pushes.
const LINES_PER_PASS: usize = 64;

/// What a client's thread keeps.
struct Session<'a> {
    stream: &'a TcpStream,
    cl: &'a Client,
    sh: &'a Shared,
    slot: &'a Slot,
    resumed: &'a mut Resumed,
    /// It drove the motors (set them to zero when it leaves).
    drove: &'a mut bool,
    /// Its commands, refused with one log line per change of state when out of
    /// their interface's range (`interfaces::RANGES`).
    from: Source,
    subs: [bool; Feed::COUNT],
    /// Image requests not answered yet, per served image (index in
    /// `Sources::images`).
    images: Vec<u32>,
    /// Replies to the requests read in this pass, written after them.
    replies: Vec<u8>,
    lr: LineReader,
    /// The pass stopped at `LINES_PER_PASS` with lines left in `lr`.
    more_lines: bool,
    /// The last wait's poll found nothing to read, and no frame went out since:
    /// reading now would only cost a syscall (a push to a hundred idle clients
    /// would cost two each). Whatever arrives meanwhile is found by the next
    /// wait's poll, which looks at the socket before sleeping.
    quiet: bool,
    partial_since: Option<Instant>,
    last_line: Instant,
    /// It sent a motors, pan-tilt or zoom command: a controller, which may send
    /// nothing while the command stands (4.3's pan-tilt client sends on change).
    commanded: bool,
    next_push: Instant,
    last_push: [u64; Feed::COUNT],
    last_img: Vec<u64>,
    /// Scratch space for a frame's header and the pushes.
    out: Vec<u8>,
}

/// Serves a named client until the connection ends; returns why it ended.
pub(super) fn serve(
    stream: &TcpStream,
    cl: &Client,
    sh: &Shared,
    slot: &Slot,
    from: Source,
    resumed: &mut Resumed,
    drove: &mut bool,
) -> End {
    let period = Duration::from_millis(netwire::PUSH_PERIOD_MS);
    let n_images = sh.sources.images.len();
    let mut s = Session {
        stream,
        cl,
        sh,
        slot,
        resumed,
        drove,
        from,
        subs: [false; Feed::COUNT],
        images: vec![0; n_images],
        replies: Vec::new(),
        lr: LineReader::new(sh.conf.max_line),
        more_lines: false,
        quiet: false,
        partial_since: None,
        last_line: Instant::now(),
        commanded: false,
        next_push: Instant::now() + period,
        last_push: [0; Feed::COUNT],
        last_img: vec![0; n_images],
        out: Vec::with_capacity(8192),
    };
    loop {
        if let Err(end) = s.step(period) {
            return end;
        }
    }
}

impl Session<'_> {
    /// Reads what the client sent, then writes one thing that is due (replies
    /// first, then a frame, then the pushes) or, with nothing due, waits.
    fn step(&mut self, period: Duration) -> Result<(), End> {
        if self.sh.stop.load(Ordering::Acquire) {
            return Err(("the server stops".into(), false));
        }
        if !self.quiet {
            self.read_requests()?;
        }
        if !self.replies.is_empty() {
            let r = std::mem::take(&mut self.replies);
            self.write(&r)?;
            self.replies = r;
            self.replies.clear();
        }
        if let Some(k) = self.ready_image() {
            self.images[k] -= 1;
            let sh = self.sh;
            let (netid, iface) = &sh.sources.images[k];
            frames::send(
                self.stream,
                self.sh.conf.timeout,
                &mut self.out,
                *netid,
                iface,
                &mut self.last_img[k],
            )
            .map_err(|e| self.write_failed(e))?;
            self.sh.stats.frames.fetch_add(1, Ordering::Relaxed);
            self.quiet = false;
            return Ok(());
        }
        let now = Instant::now();
        if now >= self.next_push {
            let deadline = self.next_push;
            self.next_push += period;
            if self.next_push <= now {
                self.next_push = now + period;
            }
            if self.subs.iter().any(|s| *s) {
                self.out.clear();
                push(
                    &self.sh.sources,
                    self.subs,
                    &mut self.last_push,
                    &mut self.out,
                    self.sh.epoch,
                );
                if !self.out.is_empty() {
                    let out = std::mem::take(&mut self.out);
                    let written = self.write(&out);
                    self.out = out;
                    written?;
                }
                self.sh
                    .stats
                    .record_lateness(Instant::now().saturating_duration_since(deadline));
            }
            return Ok(());
        }
        self.check_silence(now)?;
        if !self.more_lines {
            self.wait(now);
        }
        Ok(())
    }

    /// Carries out the complete lines the socket holds now (at most
    /// `LINES_PER_PASS`), without waiting for more.
    fn read_requests(&mut self) -> Result<(), End> {
        self.more_lines = false;
        let mut socket = DontWait {
            stream: self.stream,
            drained: false,
        };
        for _ in 0..LINES_PER_PASS {
            let req = match self.lr.read_line(&mut socket) {
                Ok(LineEvent::Line(line)) => Request::parse(line)
                    .map_err(|e| (format!("sent a bad line `{}`: {e}", shown(line)), true))?,
                Ok(LineEvent::Closed) => return Err(("closed the connection".into(), false)),
                Err(e) if netwire::is_timeout(&e) => return Ok(()),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) if e.kind() == io::ErrorKind::InvalidData => {
                    return Err((format!("sent a {e}"), true));
                }
                Err(e) => return Err((format!("connection error: {e}"), false)),
            };
            self.partial_since = None;
            self.last_line = Instant::now();
            self.commanded |= netwire::commanded_kind(req.code()).is_some();
            self.handle(req)?;
            let engaged = self.commanded || self.engaged();
            self.slot.heard(self.sh, engaged);
        }
        self.more_lines = true;
        Ok(())
    }

    /// It has a subscription or an image request.
    fn engaged(&self) -> bool {
        self.subs.iter().any(|s| *s) || self.images.iter().any(|n| *n > 0)
    }

    /// Ends a connection that holds a partial line for `timeout`, or that is
    /// idle for `idle_timeout` (no line, no subscription, no image request, no
    /// command ever).
    fn check_silence(&mut self, now: Instant) -> Result<(), End> {
        let conf = &self.sh.conf;
        if self.lr.pending() > 0 {
            let t0 = *self.partial_since.get_or_insert(now);
            if now - t0 >= conf.timeout {
                return Err((
                    format!(
                        "sent a partial line and no newline for {} ms",
                        conf.timeout.as_millis()
                    ),
                    true,
                ));
            }
        }
        if !conf.idle_timeout.is_zero()
            && !self.commanded
            && !self.engaged()
            && now - self.last_line >= conf.idle_timeout
        {
            return Err((
                format!(
                    "idle for {} ms with no subscription (idle_timeout)",
                    conf.idle_timeout.as_millis()
                ),
                false,
            ));
        }
        Ok(())
    }

    /// Sleeps until the client sends something, a frame it waits for is
    /// published, or the next push is due. The flag, set before a last look at
    /// the clocks, tells `FrameWake` to ring the bell; a frame published before
    /// the flag shows is seen by that look (the SeqCst fences pair with
    /// `FrameWake`'s), and a ring after it stays in the bell until read.
    fn wait(&mut self, now: Instant) {
        let wants_frame = self.images.iter().any(|n| *n > 0);
        self.cl.waiting_frame.store(wants_frame, Ordering::Relaxed);
        fence(Ordering::SeqCst);
        if self.ready_image().is_none() {
            let left = self.next_push.saturating_duration_since(now);
            let (rang, readable) = self.cl.bell.wait_with(self.stream.as_raw_fd(), left);
            if rang {
                self.cl.bell.clear();
            }
            self.quiet = !readable;
        } else {
            self.quiet = false;
        }
        self.cl.waiting_frame.store(false, Ordering::Relaxed);
    }

    /// A served image with a request waiting and a frame not sent yet.
    fn ready_image(&self) -> Option<usize> {
        let src = &self.sh.sources.images;
        (0..self.images.len()).find(|&k| self.images[k] > 0 && src[k].1.clock() != self.last_img[k])
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), End> {
        frames::write_all_within(self.stream, &[bytes], self.sh.conf.timeout)
            .map_err(|e| self.write_failed(e))
    }

    fn write_failed(&self, e: io::Error) -> End {
        if netwire::is_timeout(&e) {
            (
                format!(
                    "does not read what it is sent (a write took more than {} ms)",
                    self.sh.conf.timeout.as_millis()
                ),
                true,
            )
        } else {
            (format!("connection error: {e}"), false)
        }
    }

    /// Carries out one request.
    fn handle(&mut self, req: Request) -> Result<(), End> {
        let sh = self.sh;
        let src = &sh.sources;
        match req {
            Request::Goodbye | Request::GoodbyeImages => Err(("said goodbye".into(), false)),
            Request::Subscribe(d) => self.subscribe(d, true),
            Request::Unsubscribe(d) => self.subscribe(d, false),
            Request::ImageQuery(netid) => self.image_query(netid),
            Request::LimitsQuery(c) => {
                let (k, limits) = netwire::limits_kind(c).expect("parsed as a limits query");
                match src.device(k) {
                    Some(dev) => dev.write_limits(&mut self.replies),
                    None => self.error(limits.unserved),
                }
                Ok(())
            }
            Request::Unhandled(c) => {
                self.error(&format!("message {c} is not handled by this server"));
                Ok(())
            }
            command => {
                let Some(k) = netwire::commanded_kind(command.code()) else {
                    self.error(&format!(
                        "message {} is not handled by this server",
                        command.code()
                    ));
                    return Ok(());
                };
                let Some(dev) = src.device(k) else {
                    self.error(&format!("{k} are not served"));
                    return Ok(());
                };
                if matches!(
                    netwire::on_wire(k),
                    OnWire::Commanded {
                        keep_alive: true,
                        ..
                    }
                ) {
                    *self.drove = true;
                }
                match dev.apply(&command) {
                    Ok(()) => self.from.accepted(),
                    Err(e) => {
                        self.from.refused(&e);
                        self.error(&format!("refused: {e}"));
                    }
                }
                Ok(())
            }
        }
    }

    /// Queues a `1027 TEXT` reply.
    fn error(&mut self, text: &str) {
        netwire::write_error(&mut self.replies, text);
    }

    /// (Un)subscribes the client to feed `d`, resuming its interface for it.
    fn subscribe(&mut self, d: Feed, on: bool) -> Result<(), End> {
        let sh = self.sh;
        let Some(dev) = sh.sources.device(d.interface()) else {
            self.error(&format!("{} is not served", d.interface()));
            return Ok(());
        };
        let slot = &mut self.resumed.subs[d.index()];
        if on && slot.is_none() {
            let iface = dev.interface();
            iface.resume();
            *slot = Some(iface);
        } else if !on && let Some(i) = slot.take() {
            i.suspend();
        }
        self.subs[d.index()] = on;
        Ok(())
    }

    /// Counts a request for the next new frame of image `netid`.
    fn image_query(&mut self, netid: u32) -> Result<(), End> {
        let sh = self.sh;
        let src = &sh.sources;
        let Some(k) = src.images.iter().position(|(id, _)| *id == netid) else {
            self.error(&format!("no image has network id {netid}"));
            return Ok(());
        };
        if !self.resumed.images[k] {
            src.images[k].1.resume();
            self.resumed.images[k] = true;
        }
        let max = self.sh.conf.max_queue;
        if self.images.iter().sum::<u32>() as usize >= max {
            return Err((
                format!(
                    "more than {max} image requests waiting (it does not read what it asks for)"
                ),
                true,
            ));
        }
        self.images[k] += 1;
        Ok(())
    }
}

/// The start of a bad line as a log can show it: 40 bytes, the unprintable ones
/// as `?`.
fn shown(line: &[u8]) -> String {
    String::from_utf8_lossy(&line[..line.len().min(40)])
        .chars()
        .map(|c| {
            if c.is_ascii_graphic() || c == ' ' {
                c
            } else {
                '?'
            }
        })
        .collect()
}

/// Reads what the socket holds now, without waiting (`recv` with
/// `MSG_DONTWAIT`: the socket stays blocking for the writes). A read that got
/// less than it asked for emptied the socket, so the next one answers
/// `WouldBlock` without a syscall (one `recv` a frame instead of two); the next
/// pass asks the kernel again.
struct DontWait<'a> {
    stream: &'a TcpStream,
    drained: bool,
}

impl Read for DontWait<'_> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.drained {
            return Err(io::ErrorKind::WouldBlock.into());
        }
        // SAFETY: `buf` is valid for writes of `buf.len()` bytes during the call.
        let n = unsafe {
            libc::recv(
                self.stream.as_raw_fd(),
                buf.as_mut_ptr().cast(),
                buf.len(),
                libc::MSG_DONTWAIT,
            )
        };
        if n < 0 {
            return Err(io::Error::last_os_error());
        }
        self.drained = (n as usize) < buf.len();
        Ok(n as usize)
    }
}

/// Appends the push of every subscribed device whose value changed.
fn push(
    src: &Sources,
    subs: [bool; Feed::COUNT],
    last: &mut [u64; Feed::COUNT],
    out: &mut Vec<u8>,
    epoch: Instant,
) {
    for d in Feed::all().iter().filter(|d| subs[d.index()]) {
        if let Some(dev) = src.device(d.interface()) {
            dev.push(&mut last[d.index()], epoch, out);
        }
    }
}
