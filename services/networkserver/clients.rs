//! The accept loop, the table of connections, admission (the 20-byte name within
//! `timeout`, the token, eviction of the longest idle connection when the table
//! is full or descriptors run out) and each connection's life from its name to
//! its last suspend.
//!
//! **Idle** is judged by what a client sent, never by what it was sent: a
//! client subscribed to a sensor that does not change is as idle as one that
//! says nothing. With the table full (or `accept` failing for want of
//! descriptors) a new connection closes, in this order of preference:
//! 1. a connection that has not sent its name after [`EVICT_AFTER`];
//! 2. a named one that sent nothing for [`EVICT_IDLE`] and has no
//!    subscription, image request or command;
//! 3. a named one that sent nothing for [`EVICT_IDLE`];
//!
//! within a class the one from the address holding the most connections, then
//! the one silent longest. So a crowd from one host makes room for a client from
//! another, and a crowd that sends nothing makes room for anyone. A subscriber
//! that wants to keep its place when the table is full sends a line now and then
//! (subscribing again is harmless, on 4.3 servers too).

use std::{
    io::{self, Write},
    net::{IpAddr, Shutdown, SocketAddr, TcpListener, TcpStream},
    sync::{
        Arc,
        atomic::{AtomicBool, AtomicU64, Ordering},
    },
    time::{Duration, Instant},
};

use crate::{
    interfaces::{Notify, Source},
    netwire, secret, sockets,
};

use super::{
    Shared,
    frames::Bell,
    frames::FrameWake,
    serve::{Client, Resumed, serve},
};

/// A connection in the server's table.
pub(super) struct Conn {
    pub(super) id: u64,
    pub(super) stream: TcpStream,
    since: Instant,
    peer: IpAddr,
    slot: Arc<Slot>,
}

/// What the accept loop and a connection's thread share.
#[derive(Default)]
pub(super) struct Slot {
    /// It sent its 20-byte name (and the token, if one is set).
    named: AtomicBool,
    /// The accept loop closed it to make room for a new connection.
    evicted: AtomicBool,
    /// When it last sent a line (or its name): ms since the server started.
    heard_ms: AtomicU64,
    /// It has a subscription or an image request, or sent a command.
    engaged: AtomicBool,
}

impl Slot {
    /// It sent a line now (`engaged`: it is subscribed, asks for images or has
    /// sent a command).
    pub(super) fn heard(&self, sh: &Shared, engaged: bool) {
        self.heard_ms
            .store(sh.epoch.elapsed().as_millis() as u64, Ordering::Release);
        self.engaged.store(engaged, Ordering::Release);
    }
}

/// How long a connection may have been waiting for its name before a new
/// connection may evict it from a full table (so a burst of connections does
/// not evict good clients that have not been read yet).
pub(super) const EVICT_AFTER: Duration = Duration::from_millis(250);

/// How long a named connection must have sent nothing before a new connection
/// may evict it from a full table (so a crowd of fresh connections does not
/// evict each other, nor a client that has just subscribed).
pub(super) const EVICT_IDLE: Duration = Duration::from_secs(2);

/// The longest pause of the accept loop after `accept` failed for want of
/// descriptors (it starts at 50 ms and doubles).
const ACCEPT_BACKOFF_MAX: Duration = Duration::from_secs(1);

/// How often the accept loop looks at the stop flag while no one connects.
const ACCEPT_TICK: Duration = Duration::from_millis(100);

/// Closes one connection to make room (see the module's doc for which), telling
/// a named one why with a `1027` line. True if one was closed.
fn evict_one(sh: &Shared, reason: &str) -> bool {
    let clients = sh.clients.lock();
    let now_ms = sh.epoch.elapsed().as_millis() as u64;
    let mut counts: std::collections::HashMap<IpAddr, usize> = Default::default();
    for c in clients.iter() {
        *counts.entry(c.peer).or_default() += 1;
    }
    let per_ip = |ip: IpAddr| counts.get(&ip).copied().unwrap_or(0);
    let victim = clients
        .iter()
        .filter(|c| !c.slot.evicted.load(Ordering::Acquire))
        .filter_map(|c| {
            if !c.slot.named.load(Ordering::Acquire) {
                let waited = c.since.elapsed();
                (waited >= EVICT_AFTER).then_some((2u8, per_ip(c.peer), waited, c))
            } else {
                let idle = Duration::from_millis(
                    now_ms.saturating_sub(c.slot.heard_ms.load(Ordering::Acquire)),
                );
                let class = if c.slot.engaged.load(Ordering::Acquire) {
                    0
                } else {
                    1
                };
                (idle >= EVICT_IDLE).then_some((class, per_ip(c.peer), idle, c))
            }
        })
        .max_by_key(|(class, n, idle, _)| (*class, *n, *idle));
    let Some((class, _, idle, c)) = victim else {
        return false;
    };
    c.slot.evicted.store(true, Ordering::Release);
    if class < 2 {
        let mut out = Vec::new();
        netwire::write_error(
            &mut out,
            &format!(
                "closed to make room ({reason}): it had sent nothing for {} ms",
                idle.as_millis()
            ),
        );
        send_now(&c.stream, &out);
    }
    let _ = c.stream.shutdown(Shutdown::Both);
    true
}

/// Writes what the socket takes at once (never blocks: the accept loop calls it).
fn send_now(stream: &TcpStream, bytes: &[u8]) {
    use std::os::fd::AsRawFd;
    // SAFETY: a valid socket and buffer for the duration of the call; the flags
    // make it return at once and never raise SIGPIPE.
    unsafe {
        libc::send(
            stream.as_raw_fd(),
            bytes.as_ptr().cast(),
            bytes.len(),
            libc::MSG_DONTWAIT | libc::MSG_NOSIGNAL,
        )
    };
}

/// Whether an `accept` error means this process is out of descriptors (or the
/// kernel out of memory for one): a condition that passes when connections close.
fn out_of_descriptors(e: &io::Error) -> bool {
    matches!(
        e.raw_os_error(),
        Some(libc::EMFILE | libc::ENFILE | libc::ENOBUFS | libc::ENOMEM)
    )
}

/// While `accept` (or the descriptors a new connection needs) fails: the
/// current pause, and when the last line about it was said.
#[derive(Default)]
struct Failing {
    pause: Option<Duration>,
    said: Option<Instant>,
    unsaid: u64,
}

/// The least time between two lines about running out of descriptors (an
/// attacker can make it flap between failing and working many times a second).
const FAILING_QUIET: Duration = Duration::from_secs(10);

/// After `accept` (or the descriptors a new connection needs) failed: the loop
/// goes on, pausing 50 ms doubling to 1 s, with one log line per episode (at
/// most one per FAILING_QUIET); out of descriptors, it frees one by closing the
/// longest idle connection.
fn failed(sh: &Shared, e: &io::Error, what: &str, f: &mut Failing) {
    let pause_for = match f.pause {
        None => Duration::from_millis(50),
        Some(d) => (d * 2).min(ACCEPT_BACKOFF_MAX),
    };
    if f.pause.is_none() {
        if f.said.is_none_or(|t| t.elapsed() >= FAILING_QUIET) {
            tracing::warn!(
                "networkserver: {what}: {e}{}; pausing and trying again{}",
                if out_of_descriptors(e) {
                    " (out of file descriptors: closing the longest idle connection)"
                } else {
                    ""
                },
                match f.unsaid {
                    0 => String::new(),
                    n => format!(" ({n} more times since the last line)"),
                }
            );
            f.said = Some(Instant::now());
            f.unsaid = 0;
        } else {
            f.unsaid += 1;
        }
    }
    f.pause = Some(pause_for);
    if out_of_descriptors(e) {
        evict_one(sh, "out of file descriptors");
    }
    pause(sh, pause_for);
}

/// Sleeps `d` in slices of at most ACCEPT_TICK, returning early on stop.
fn pause(sh: &Shared, d: Duration) {
    let end = Instant::now() + d;
    while !sh.stop.load(Ordering::Acquire) {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return;
        }
        std::thread::sleep(left.min(ACCEPT_TICK));
    }
}

pub(super) fn accept_loop(listener: TcpListener, sh: Arc<Shared>) {
    let mut next_id = 0u64;
    let mut failing = Failing::default();
    loop {
        if sh.stop.load(Ordering::Acquire) {
            return;
        }
        let (stream, peer) = match listener.accept() {
            Ok(x) => x,
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                sockets::wait_readable(&listener, ACCEPT_TICK);
                continue;
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => {
                failed(&sh, &e, "accept failed", &mut failing);
                continue;
            }
        };

        if sh.stop.load(Ordering::Acquire) {
            return;
        }
        if let Some(left) = sh.refusals.holds(peer.ip()) {
            // Unread, from the nonblocking socket: a guesser costs no thread and
            // no wait, and holds up no one else.
            sh.stats.dropped.fetch_add(1, Ordering::Relaxed);
            let mut out = Vec::new();
            let why = format!(
                "refused: too many wrong tokens from your address; try again in {} s",
                left.as_secs() + 1
            );
            netwire::write_error(&mut out, &why);
            let _ = (&stream).write(&out);
            continue;
        }
        if let Err(e) = stream.set_nonblocking(false) {
            tracing::warn!("networkserver: cannot set up the connection from {peer}: {e}");
            continue;
        }
        sh.threads.lock().retain(|t| !t.is_finished());
        sh.stats.accepted.fetch_add(1, Ordering::Relaxed);
        let n = sh.stats.clients.load(Ordering::Acquire);
        if n >= sh.conf.max_clients
            && !evict_one(&sh, &format!("max_clients {}", sh.conf.max_clients))
        {
            sh.stats.dropped.fetch_add(1, Ordering::Relaxed);
            tracing::warn!(
                "networkserver: refused {peer}: {n} clients already connected (max_clients {})",
                sh.conf.max_clients
            );
            let mut out = Vec::new();
            netwire::write_error(
                &mut out,
                &format!("too many clients (max {})", sh.conf.max_clients),
            );
            let mut s = stream;
            let _ = s.set_write_timeout(Some(Duration::from_millis(100)));
            let _ = s.write_all(&out);
            continue;
        }
        next_id += 1;
        let id = next_id;
        let reg = match stream.try_clone() {
            Ok(r) => r,
            Err(e) => {
                drop(stream);
                failed(&sh, &e, "cannot take a new connection", &mut failing);
                continue;
            }
        };
        if failing.pause.take().is_some() && failing.unsaid == 0 {
            tracing::info!("networkserver: accepting connections again");
        }
        let slot = Arc::new(Slot::default());
        sh.clients.lock().push(Conn {
            id,
            stream: reg,
            since: Instant::now(),
            peer: peer.ip(),
            slot: slot.clone(),
        });
        sh.stats.clients.fetch_add(1, Ordering::AcqRel);
        let sh2 = sh.clone();
        let t = std::thread::Builder::new()
            .name(format!("nsrv-{id}"))
            .spawn(move || {
                client(stream, peer, id, &slot, &sh2);
                sh2.stats.clients.fetch_sub(1, Ordering::AcqRel);
            });
        match t {
            Ok(t) => sh.threads.lock().push(t),
            Err(e) => {
                sh.clients.lock().retain(|c| c.id != id);
                sh.stats.clients.fetch_sub(1, Ordering::AcqRel);
                tracing::warn!("networkserver: cannot start a thread for {peer}: {e}");
            }
        }
    }
}

fn client(stream: TcpStream, peer: SocketAddr, id: u64, slot: &Slot, sh: &Arc<Shared>) {
    let conf = &sh.conf;
    let _ = stream.set_nodelay(true);
    // `why` None: said elsewhere (a wrong token: `refusals`, one line a burst).
    let finish = |why: Option<String>, bad: bool| {
        sh.clients.lock().retain(|c| c.id != id);
        let Some(why) = why else {
            sh.stats.dropped.fetch_add(1, Ordering::Relaxed);
            return;
        };
        if bad {
            sh.stats.dropped.fetch_add(1, Ordering::Relaxed);
            tracing::warn!("networkserver: client {peer} disconnected: {why}");
        } else {
            tracing::info!("networkserver: client {peer} left: {why}");
        }
    };
    // The 20-byte name and its token line, within `timeout` in all (not per
    // read: a byte every few seconds must not hold the connection for minutes).
    let _ = stream.set_write_timeout(Some(conf.timeout));
    let (cname, token) = match read_hello(&stream, conf.timeout) {
        Ok(h) => h,
        Err(e) => {
            let why = if slot.evicted.load(Ordering::Acquire) {
                format!(
                    "closed to make room: {} connections, and it had sent no name after {} ms",
                    conf.max_clients,
                    EVICT_AFTER.as_millis()
                )
            } else if netwire::is_timeout(&e) {
                format!(
                    "sent no 20-byte name (and token line) within {} ms",
                    conf.timeout.as_millis()
                )
            } else {
                format!("closed before sending its name ({e})")
            };
            return finish(Some(why), true);
        }
    };
    if let Some(t) = &conf.token {
        if !token.is_some_and(|got| secret::same_secret(t.as_bytes(), &got)) {
            let mut out = Vec::new();
            netwire::write_error(&mut out, "refused: wrong or missing token");
            let _ = (&stream).write_all(&out);
            let _ = stream.shutdown(Shutdown::Both);
            sh.refusals.failed(peer.ip());
            return finish(None, true);
        }
        sh.refusals.passed(peer.ip());
    }
    if sh.stop.load(Ordering::Acquire) {
        return finish(Some("server stopping".into()), false);
    }
    slot.heard(sh, false);
    slot.named.store(true, Ordering::Release);
    if slot.evicted.load(Ordering::Acquire) {
        return finish(
            Some("closed to make room before its name was read".into()),
            true,
        );
    }
    tracing::info!("networkserver: new client {cname} from {peer}");
    let bell = match Bell::new() {
        Ok(b) => b,
        Err(e) => {
            return finish(
                Some(format!("cannot make its wake-up descriptor: {e}")),
                true,
            );
        }
    };
    let cl = Arc::new(Client {
        bell,
        waiting_frame: AtomicBool::new(false),
    });
    let wake: Arc<dyn Notify> = Arc::new(FrameWake(Arc::downgrade(&cl)));
    for (_, img) in &sh.sources.images {
        img.watch(wake.clone());
    }
    let mut resumed = Resumed {
        images: vec![false; sh.sources.images.len()],
        ..Default::default()
    };
    let mut drove = false;
    let from = Source::new(format!("networkserver: client {cname} from {peer}"));
    let ended = serve(&stream, &cl, sh, slot, from, &mut resumed, &mut drove);
    for (_, img) in &sh.sources.images {
        img.unwatch(&*wake);
    }
    for i in resumed.subs.iter().flatten() {
        i.suspend();
    }
    for (k, on) in resumed.images.iter().enumerate() {
        if *on {
            sh.sources.images[k].1.suspend();
        }
    }
    if drove {
        sh.sources.zero_renewed();
    }
    let (why, bad) = if slot.evicted.load(Ordering::Acquire) {
        (
            "closed to make room for a new connection: the table was full (or descriptors \
             ran out) and it had sent nothing for longest"
                .to_string(),
            false,
        )
    } else {
        ended
    };
    finish(Some(why), bad);
}

/// Reads a client's 20-byte name and, when the name says one follows
/// ([`netwire::TOKEN_MARK`]), its token line, within `limit` in all: (the
/// printable name, the token if one came). Bytes after them stay unread.
fn read_hello(stream: &TcpStream, limit: Duration) -> io::Result<(String, Option<Vec<u8>>)> {
    let deadline = Instant::now() + limit;
    let mut name = [0u8; netwire::NAME_LEN];
    read_until(stream, &mut name, deadline, None)?;
    let (cname, marked) = netwire::split_name(&name);
    if !marked {
        return Ok((cname, None));
    }
    let mut line = [0u8; netwire::MAX_TOKEN_LINE];
    let n = read_until(stream, &mut line, deadline, Some(b'\n'))?;
    if line[n - 1] != b'\n' {
        return Err(netwire::too_long(netwire::MAX_TOKEN_LINE));
    }
    let token = netwire::token_of(&line[..n - 1]).map(<[u8]>::to_vec);
    Ok((cname, Some(token.unwrap_or_default())))
}

/// Reads into `buf` until it is full or, with `end`, up to and with that byte,
/// by `deadline`: the bytes read. With `end` it reads a byte at a time, so
/// nothing after it is taken from the socket.
fn read_until(
    stream: &TcpStream,
    buf: &mut [u8],
    deadline: Instant,
    end: Option<u8>,
) -> io::Result<usize> {
    let mut got = 0;
    let mut r = stream;
    let step = if end.is_some() { 1 } else { buf.len() };
    while got < buf.len() {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(io::ErrorKind::TimedOut.into());
        }
        stream.set_read_timeout(Some(left))?;
        let want = (got + step).min(buf.len());
        match io::Read::read(&mut r, &mut buf[got..want]) {
            Ok(0) => return Err(io::ErrorKind::UnexpectedEof.into()),
            Ok(n) => {
                got += n;
                if end == Some(buf[got - 1]) {
                    return Ok(got);
                }
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}
