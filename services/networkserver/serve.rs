//! A client's two threads: the reader (requests, with the partial-line and idle
//! rules) and the writer (replies, image frames, pushes paced every 33 ms).

use std::{
    collections::VecDeque,
    io::{self, Write},
    net::{Shutdown, TcpStream},
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering, fence},
    },
    time::{Duration, Instant},
};

use parking_lot::{Condvar, Mutex};

use crate::{
    interfaces::{AnyInterface, KINDS, Source},
    netwire::{self, Feed, LineEvent, LineReader, OnWire, Request},
};

use super::{Shared, Sources, clients::Slot, frames};

/// What a client's reader and writer share.
pub(super) struct ClientState {
    pub(super) closed: bool,
    /// Why the connection ends (the first reason wins) and whether it was the
    /// client's fault.
    pub(super) why: Option<(String, bool)>,
    pub(super) subs: [bool; Feed::COUNT],
    /// Outstanding image requests per served image (index in `Sources::images`).
    pub(super) images: Vec<u32>,
    pub(super) replies: VecDeque<Vec<u8>>,
}

pub(super) struct Client {
    pub(super) st: Mutex<ClientState>,
    pub(super) cv: Condvar,
    pub(super) stream: TcpStream,
    /// The writer sleeps waiting for a frame (so a new frame must wake it).
    pub(super) waiting_frame: AtomicBool,
    /// Its commands, refused with one log line per change of state when out of
    /// their interface's range (`interfaces::RANGES`).
    pub(super) from: Source,
}

impl Client {
    pub(super) fn close(&self, why: impl Into<String>, bad: bool) {
        let mut st = self.st.lock();
        if st.why.is_none() {
            st.why = Some((why.into(), bad));
        }
        st.closed = true;
        drop(st);
        self.cv.notify_all();
        let _ = self.stream.shutdown(Shutdown::Both);
    }
}

/// Interfaces a client resumed, to suspend when it leaves.
#[derive(Default)]
pub(super) struct Resumed {
    pub(super) subs: [Option<Arc<dyn AnyInterface>>; Feed::COUNT],
    pub(super) images: Vec<bool>,
}

pub(super) fn reader(
    stream: &TcpStream,
    cl: &Client,
    sh: &Shared,
    slot: &Slot,
    resumed: &mut Resumed,
    drove: &mut bool,
) {
    let conf = &sh.conf;
    let tick = Duration::from_millis(100).min(conf.timeout);
    let _ = stream.set_read_timeout(Some(tick));
    let mut lr = LineReader::new(conf.max_line);
    let mut r = stream;
    let mut partial_since: Option<Instant> = None;
    let mut last_line = Instant::now();
    // It sent a motors, pan-tilt or zoom command: a controller, which may send
    // nothing while the command stands (4.3's pan-tilt client sends on change).
    let mut commanded = false;
    loop {
        if cl.st.lock().closed || sh.stop.load(Ordering::Acquire) {
            return;
        }
        match lr.read_line(&mut r) {
            Ok(LineEvent::Line(line)) => {
                partial_since = None;
                last_line = Instant::now();
                match Request::parse(line) {
                    Ok(req) => {
                        commanded |= netwire::commanded_kind(req.code()).is_some();
                        if let Err((why, bad)) = handle(req, cl, sh, resumed, drove) {
                            cl.close(why, bad);
                            return;
                        }
                        let engaged = commanded || {
                            let st = cl.st.lock();
                            st.subs.iter().any(|s| *s) || st.images.iter().any(|n| *n > 0)
                        };
                        slot.heard(sh, engaged);
                    }
                    Err(e) => {
                        let shown: String = String::from_utf8_lossy(&line[..line.len().min(40)])
                            .chars()
                            .map(|c| {
                                if c.is_ascii_graphic() || c == ' ' {
                                    c
                                } else {
                                    '?'
                                }
                            })
                            .collect();
                        cl.close(format!("sent a bad line `{shown}`: {e}"), true);
                        return;
                    }
                }
            }
            Ok(LineEvent::Closed) => {
                cl.close("closed the connection", false);
                return;
            }
            Err(e) if netwire::is_timeout(&e) => {
                if lr.pending() > 0 {
                    let t0 = *partial_since.get_or_insert_with(Instant::now);
                    if t0.elapsed() >= conf.timeout {
                        cl.close(
                            format!(
                                "sent a partial line and no newline for {} ms",
                                conf.timeout.as_millis()
                            ),
                            true,
                        );
                        return;
                    }
                }
                if !conf.idle_timeout.is_zero()
                    && !commanded
                    && last_line.elapsed() >= conf.idle_timeout
                {
                    let st = cl.st.lock();
                    let busy = st.subs.iter().any(|s| *s)
                        || st.images.iter().any(|n| *n > 0)
                        || !st.replies.is_empty();
                    drop(st);
                    if !busy {
                        cl.close(
                            format!(
                                "idle for {} ms with no subscription (idle_timeout)",
                                conf.idle_timeout.as_millis()
                            ),
                            false,
                        );
                        return;
                    }
                }
            }
            Err(e) if e.kind() == io::ErrorKind::InvalidData => {
                cl.close(format!("sent a {e}"), true);
                return;
            }
            Err(e) => {
                cl.close(format!("connection error: {e}"), false);
                return;
            }
        }
    }
}

/// Carries out one request; Err((why, bad)) ends the connection.
fn handle(
    req: Request,
    cl: &Client,
    sh: &Shared,
    resumed: &mut Resumed,
    drove: &mut bool,
) -> Result<(), (String, bool)> {
    let src = &sh.sources;
    match req {
        Request::Goodbye | Request::GoodbyeImages => Err(("said goodbye".into(), false)),
        Request::Subscribe(d) => subscribe(cl, sh, resumed, d, true),
        Request::Unsubscribe(d) => subscribe(cl, sh, resumed, d, false),
        Request::ImageQuery(netid) => image_query(cl, sh, resumed, netid),
        Request::LimitsQuery(c) => {
            let (k, limits) = netwire::limits_kind(c).expect("parsed as a limits query");
            let Some(dev) = src.device(k) else {
                return error(cl, sh, limits.unserved.into());
            };
            let mut out = Vec::new();
            dev.write_limits(&mut out);
            reply(cl, sh, out)
        }
        Request::Unhandled(c) => {
            error(cl, sh, format!("message {c} is not handled by this server"))
        }
        command => {
            let Some(k) = netwire::commanded_kind(command.code()) else {
                return error(
                    cl,
                    sh,
                    format!("message {} is not handled by this server", command.code()),
                );
            };
            let Some(dev) = src.device(k) else {
                return error(cl, sh, format!("{} are not served", KINDS[k]));
            };
            if matches!(
                netwire::WIRE[k],
                OnWire::Commanded {
                    keep_alive: true,
                    ..
                }
            ) {
                *drove = true;
            }
            if let Err(e) = dev.apply(&command) {
                cl.from.refused(&e);
                return error(cl, sh, format!("refused: {e}"));
            }
            cl.from.accepted();
            Ok(())
        }
    }
}

/// The error of a client with more than `max_queue` requests waiting, if it has.
fn over_queue(st: &ClientState, sh: &Shared) -> Result<(), (String, bool)> {
    let queued = st.replies.len() + st.images.iter().sum::<u32>() as usize;
    if queued >= sh.conf.max_queue {
        return Err((
            format!(
                "more than {} requests waiting (it does not read what it asks for)",
                sh.conf.max_queue
            ),
            true,
        ));
    }
    Ok(())
}

/// Queues a reply for the writer.
fn reply(cl: &Client, sh: &Shared, bytes: Vec<u8>) -> Result<(), (String, bool)> {
    let mut st = cl.st.lock();
    over_queue(&st, sh)?;
    st.replies.push_back(bytes);
    drop(st);
    cl.cv.notify_all();
    Ok(())
}

/// Queues a `1027 TEXT` reply.
fn error(cl: &Client, sh: &Shared, text: String) -> Result<(), (String, bool)> {
    let mut out = Vec::new();
    netwire::write_error(&mut out, &text);
    reply(cl, sh, out)
}

/// (Un)subscribes the client to feed `d`, resuming its interface for it.
fn subscribe(
    cl: &Client,
    sh: &Shared,
    resumed: &mut Resumed,
    d: Feed,
    on: bool,
) -> Result<(), (String, bool)> {
    let Some(dev) = sh.sources.device(d.index()) else {
        return error(cl, sh, format!("{} is not served", d.interface()));
    };
    let slot = &mut resumed.subs[d.index()];
    if on && slot.is_none() {
        let iface = dev.interface();
        iface.resume();
        *slot = Some(iface);
    } else if !on && let Some(i) = slot.take() {
        i.suspend();
    }
    cl.st.lock().subs[d.index()] = on;
    cl.cv.notify_all();
    Ok(())
}

/// Queues a request for the next new frame of image `netid`.
fn image_query(
    cl: &Client,
    sh: &Shared,
    resumed: &mut Resumed,
    netid: u32,
) -> Result<(), (String, bool)> {
    let src = &sh.sources;
    let Some(k) = src.images.iter().position(|(id, _)| *id == netid) else {
        return error(cl, sh, format!("no image has network id {netid}"));
    };
    if !resumed.images[k] {
        src.images[k].1.resume();
        resumed.images[k] = true;
    }
    let mut st = cl.st.lock();
    over_queue(&st, sh)?;
    st.images[k] += 1;
    drop(st);
    cl.cv.notify_all();
    Ok(())
}

pub(super) fn writer(cl: &Client, sh: &Shared) {
    let period = Duration::from_millis(netwire::PUSH_PERIOD_MS);
    let mut next_push = Instant::now() + period;
    let mut last_push = [0u64; Feed::COUNT];
    let mut last_img = vec![0u64; sh.sources.images.len()];
    let mut out: Vec<u8> = Vec::with_capacity(8192);
    let mut w = &cl.stream;
    loop {
        let mut st = cl.st.lock();
        if st.closed {
            return;
        }
        if let Some(r) = st.replies.pop_front() {
            drop(st);
            if let Err(e) = w.write_all(&r) {
                return write_failed(cl, sh, e);
            }
            continue;
        }
        let ready = (0..st.images.len())
            .find(|&k| st.images[k] > 0 && sh.sources.images[k].1.clock() != last_img[k]);
        if let Some(k) = ready {
            st.images[k] -= 1;
            drop(st);
            let (netid, iface) = &sh.sources.images[k];
            if let Err(e) = frames::send(&mut w, &mut out, *netid, iface, &mut last_img[k]) {
                return write_failed(cl, sh, e);
            }
            sh.stats.frames.fetch_add(1, Ordering::Relaxed);
            continue;
        }
        let now = Instant::now();
        if now >= next_push {
            let subs = st.subs;
            drop(st);
            let deadline = next_push;
            next_push += period;
            if next_push <= now {
                next_push = now + period;
            }
            if !subs.iter().any(|s| *s) {
                continue;
            }
            out.clear();
            push(&sh.sources, subs, &mut last_push, &mut out, sh.epoch);
            if !out.is_empty()
                && let Err(e) = w.write_all(&out)
            {
                return write_failed(cl, sh, e);
            }
            sh.stats
                .record_lateness(Instant::now().saturating_duration_since(deadline));
            continue;
        }
        // Until a new frame of a served image (FrameWake), a request, or the next
        // push. The flag, set before a last look at the clocks, tells FrameWake to
        // wake this thread; a frame published before the flag shows is seen by
        // that look (the SeqCst fences pair with FrameWake's).
        let wants_frame = st.images.iter().any(|n| *n > 0);
        cl.waiting_frame.store(wants_frame, Ordering::Relaxed);
        fence(Ordering::SeqCst);
        let arrived = (0..st.images.len())
            .any(|k| st.images[k] > 0 && sh.sources.images[k].1.clock() != last_img[k]);
        if !arrived {
            cl.cv.wait_until(&mut st, next_push);
        }
        cl.waiting_frame.store(false, Ordering::Relaxed);
    }
}

pub(super) fn write_failed(cl: &Client, sh: &Shared, e: io::Error) {
    if netwire::is_timeout(&e) {
        cl.close(
            format!(
                "does not read what it is sent (a write waited {} ms)",
                sh.conf.timeout.as_millis()
            ),
            true,
        );
    } else {
        cl.close(format!("connection error: {e}"), false);
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
    for k in Feed::all().iter().map(|d| d.index()).filter(|&k| subs[k]) {
        if let Some(dev) = src.device(k) {
            dev.push(&mut last[k], epoch, out);
        }
    }
}
