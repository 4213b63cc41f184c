//! The ports users connect to: a front door that checks each connection and
//! then hands its socket to the SDK's server.
//!
//! The SDK's server accepts only the subprotocols `foxglove.sdk.v1` and
//! `foxglove.sdk.v1.1`, while the official npm client `@foxglove/ws-protocol` 0.8.0
//! and Lichtblick offer only `foxglove.websocket.v1` (the same messages under the
//! protocol's older name; the client checks that the server answers with that exact
//! name). The SDK also has no connection cap and no limit on what a client sends.
//! So every port (`port`, `sdk_port`) is this front door, which for each connection
//!
//! 1. admits it under the cap `max_clients` (over both ports): when full, the
//!    connection that has been idle longest (no byte either way) is closed to make
//!    room, with one log line; a failed `accept` (EMFILE) closes the longest idle
//!    one too and the loop goes on;
//! 2. reads the HTTP upgrade request (at most [`MAX_HEAD`] bytes within
//!    [`HEAD_TIMEOUT`]; anything else is answered `400` and closed), checks the
//!    `token` when the conf sets one (`?token=` in the URL or `Authorization:
//!    Bearer`; else `401`);
//! 3. hands the socket to the SDK's server (the vendored SDK's `serve_stream`),
//!    wrapped in a [`DoorStream`]: the SDK reads the request (asking for
//!    `foxglove.sdk.v1` when the client offers only `foxglove.websocket.v1`; its
//!    answer then names `foxglove.websocket.v1` again; offers of `foxglove.sdk.v1*`
//!    pass unchanged), and then
//!    - server → client: the SDK writes its frames straight to the client's socket
//!      (no second connection, no copy); the wrapper follows the frame headers, so
//!      it knows where frames end and counts the message-data frames the socket
//!      took. A client that stops reading holds back only its own socket: the
//!      SDK's per-client backlog (`max_queue` message frames) then drops that
//!      client's oldest messages, and a client that takes no byte for
//!      [`WRITE_TIMEOUT`] while a frame waits is closed;
//!    - client → server: what the SDK reads passes the frame-header checks
//!      first: a message (all its fragments) over `max_message` bytes, a message
//!      left unfinished for [`MESSAGE_TIMEOUT`], or more than
//!      [`MAX_CONTROL_PER_SEC`] control frames (pings) in a second close the
//!      connection with status 1009 (too big) or 1008 (policy), sent after the
//!      frame in flight to the client; the SDK never sees the offending frame.
//!
//! Memory per connection: the socket's send buffer ([`SOCKET_BUFFER`]) and the
//! SDK's `max_queue` messages; the SDK never holds more of a client's unfinished
//! message than `max_message`.

use std::{
    collections::HashMap,
    net::SocketAddr,
    os::fd::AsRawFd,
    pin::Pin,
    sync::{
        Arc,
        atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering},
    },
    task::{Context, Poll, Waker, ready},
    time::{Duration, Instant},
};

use parking_lot::Mutex;
use tokio::{
    io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, ReadBuf},
    net::{TcpListener, TcpStream},
    sync::Notify,
    time::Sleep,
};

use crate::{
    secret::{Refusals, same_secret},
    sockets,
};

/// The longest HTTP upgrade request or response head.
pub const MAX_HEAD: usize = 16 * 1024;
/// How long a client may take to send its upgrade request.
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(5);
/// How long a client that reads nothing may hold a frame half-sent.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(15);
/// How long a client's message may stay unfinished (fragments, a partial frame).
pub const MESSAGE_TIMEOUT: Duration = Duration::from_secs(10);
/// Control frames (ping, pong) a client may send per second.
pub const MAX_CONTROL_PER_SEC: u32 = 100;
/// How long a close waits for the frame in flight to the client to end.
const CLOSE_GRACE: Duration = Duration::from_secs(1);

/// The protocol's older name, which `@foxglove/ws-protocol` and Lichtblick offer.
pub const LEGACY: &str = "foxglove.websocket.v1";
/// The SDK's name of the same protocol.
pub const SDK: &str = "foxglove.sdk.v1";

/// Counters of the front door (all clients, both ports), for `ps` and the benchmark.
#[derive(Default)]
pub struct RelayStats {
    /// Clients connected now (upgraded).
    pub clients: AtomicUsize,
    /// Connections accepted so far.
    pub accepted: AtomicU64,
    /// Connections refused or closed for a bad request, a bad token, an oversized
    /// or unfinished message or a ping flood.
    pub refused: AtomicU64,
    /// Message-data frames sent to clients.
    pub sent: AtomicU64,
    /// Woken when a client's socket took a message-data frame (the publishing
    /// thread, which paces images to the clients).
    pub taken: std::sync::OnceLock<Arc<crate::interfaces::Watch>>,
    /// Connections closed to admit another (the cap, or out of descriptors).
    pub evicted: AtomicU64,
}

/// The front door's limits.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Message frames the SDK keeps per client (its backlog).
    pub max_queue: usize,
    /// The longest message a client may send, bytes.
    pub max_message: usize,
    /// Connections at once, over both ports.
    pub max_clients: usize,
    /// The secret a client must present, if any.
    pub token: Option<String>,
}

impl Default for Limits {
    fn default() -> Limits {
        Limits {
            max_queue: 16,
            max_message: 65536,
            max_clients: 64,
            token: None,
        }
    }
}

/// One open connection, as the cap sees it.
struct Conn {
    /// Last byte either way, ms since the door opened.
    last: AtomicU64,
    kill: Notify,
    killed: AtomicBool,
}

/// Hands a checked connection to the SDK's server (the peer's address); false
/// when the server is stopped.
pub type Serve = Arc<dyn Fn(DoorStream, SocketAddr) -> bool + Send + Sync>;

/// The open connections over all ports, and the clock of their activity.
pub struct Door {
    serve: Serve,
    limits: Limits,
    stats: Arc<RelayStats>,
    conns: Mutex<Vec<Arc<Conn>>>,
    t0: Instant,
    /// When the cap was last logged (ms since t0), to log it once a minute.
    cap_logged: AtomicU64,
    /// Wrong tokens per source address, and their back-off.
    pub(crate) refusals: Refusals,
    /// The TLS bridges' local ports and the clients they carry (so the token's
    /// back-off sees the client's address, not loopback).
    bridged: Mutex<HashMap<u16, SocketAddr>>,
}

impl Door {
    /// A door in front of the SDK's server, which `serve` hands connections to.
    pub fn new(serve: Serve, limits: Limits, stats: Arc<RelayStats>) -> Arc<Door> {
        Arc::new(Door {
            serve,
            limits,
            stats,
            conns: Mutex::new(Vec::new()),
            t0: Instant::now(),
            cap_logged: AtomicU64::new(u64::MAX),
            refusals: Refusals::new("foxglove"),
            bridged: Mutex::new(HashMap::new()),
        })
    }

    /// A TLS bridge from local port `port` carries `client` (until [`Door::unbridge`]).
    pub(crate) fn bridge(&self, port: u16, client: SocketAddr) {
        self.bridged.lock().insert(port, client);
    }
    pub(crate) fn unbridge(&self, port: u16) {
        self.bridged.lock().remove(&port);
    }
    /// Who a connection from `peer` is: the TLS client it bridges, or itself.
    fn client_of(&self, peer: SocketAddr) -> SocketAddr {
        if !peer.ip().is_loopback() {
            return peer;
        }
        self.bridged
            .lock()
            .get(&peer.port())
            .copied()
            .unwrap_or(peer)
    }
    fn now(&self) -> u64 {
        self.t0.elapsed().as_millis() as u64
    }

    /// Closes the connection idle longest; false when there is none.
    pub(crate) fn evict_idle(&self, why: &str) -> bool {
        let victim = {
            let conns = self.conns.lock();
            conns
                .iter()
                .filter(|c| !c.killed.load(Ordering::Relaxed))
                .min_by_key(|c| c.last.load(Ordering::Relaxed))
                .cloned()
        };
        let Some(v) = victim else { return false };
        v.killed.store(true, Ordering::Relaxed);
        v.kill.notify_one();
        self.stats.evicted.fetch_add(1, Ordering::Relaxed);
        let now = self.now();
        let logged = self.cap_logged.load(Ordering::Relaxed);
        if logged == u64::MAX || now.saturating_sub(logged) > 60_000 {
            self.cap_logged.store(now, Ordering::Relaxed);
            tracing::warn!(
                "foxglove: {why}: closing the connection idle longest ({} s) to admit a new one \
                 (logged once a minute; raise `max_clients` if these are your clients)",
                now.saturating_sub(v.last.load(Ordering::Relaxed)) / 1000
            );
        }
        true
    }

    fn admit(&self) -> Arc<Conn> {
        let over = {
            let conns = self.conns.lock();
            conns
                .iter()
                .filter(|c| !c.killed.load(Ordering::Relaxed))
                .count()
                >= self.limits.max_clients
        };
        if over {
            self.evict_idle(&format!(
                "{} connections (`max_clients`)",
                self.limits.max_clients
            ));
        }
        let c = Arc::new(Conn {
            last: AtomicU64::new(self.now()),
            kill: Notify::new(),
            killed: AtomicBool::new(false),
        });
        self.conns.lock().push(c.clone());
        c
    }

    fn leave(&self, c: &Arc<Conn>) {
        self.conns.lock().retain(|o| !Arc::ptr_eq(o, c));
    }

    fn touch(&self, c: &Conn) {
        c.last.store(self.now(), Ordering::Relaxed);
    }
}

/// The kernel send buffer of each client's socket (asked for; Linux doubles it):
/// what a client that stops reading holds there before the SDK's backlog starts
/// dropping its oldest frames.
pub const SOCKET_BUFFER: u32 = 1 << 20;

/// Accepts on `listener` and hands each checked connection to the SDK's server,
/// for ever (a failed accept, e.g. out of descriptors, frees the longest idle one
/// and goes on).
pub async fn accept_loop(listener: TcpListener, door: Arc<Door>) {
    loop {
        let (client, peer) = match listener.accept().await {
            Ok(c) => c,
            Err(e) => {
                let fds = matches!(e.raw_os_error(), Some(libc::EMFILE | libc::ENFILE));
                if !(fds && door.evict_idle(&format!("accept failed ({e})"))) {
                    tracing::warn!("foxglove: accept failed: {e}; trying again");
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
                continue;
            }
        };
        door.stats.accepted.fetch_add(1, Ordering::Relaxed);
        let peer = door.client_of(peer);
        if let Some(left) = door.refusals.holds(peer.ip()) {
            door.stats.refused.fetch_add(1, Ordering::Relaxed);
            tokio::spawn(async move {
                let why = format!(
                    "too many wrong tokens from your address; try again in {} s",
                    left.as_secs() + 1
                );
                let _ = tokio::time::timeout(
                    Duration::from_millis(100),
                    refuse(&mut { client }, "429 Too Many Requests", &why),
                )
                .await;
            });
            continue;
        }
        let conn = door.admit();
        let door = door.clone();
        tokio::spawn(async move {
            // A killed connection's socket is shut down (`Handed`'s drop), which
            // ends the SDK's session too.
            let r = tokio::select! {
                r = connection(client, peer, &door, &conn) => r,
                () = conn.kill.notified() => Err("closed to admit a newer client (max_clients)".into()),
            };
            door.leave(&conn);
            match r {
                Ok(()) => {}
                // `refusals` says it (one line per burst, not per attempt).
                Err(why) if why == WRONG_TOKEN => {
                    door.stats.refused.fetch_add(1, Ordering::Relaxed);
                    door.refusals.failed(peer.ip());
                }
                Err(why) => {
                    door.stats.refused.fetch_add(1, Ordering::Relaxed);
                    tracing::info!("foxglove: client {peer}: {why}");
                }
            }
        });
    }
}

/// Reads an HTTP head (up to the empty line) from `r`: (head, bytes read past it).
async fn read_head<R: AsyncRead + Unpin>(r: &mut R) -> Result<(Vec<u8>, Vec<u8>), String> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    loop {
        if let Some(r) = split_head(&mut buf) {
            return Ok(r);
        }
        if buf.len() > MAX_HEAD {
            return Err(format!("an HTTP head over {MAX_HEAD} bytes"));
        }
        let n = r
            .read(&mut chunk)
            .await
            .map_err(|e| format!("read failed: {e}"))?;
        if n == 0 {
            return Err("closed before the end of its HTTP head".into());
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

/// When `buf` holds a whole HTTP head (up to the empty line): (head, the bytes
/// after it), and `buf` is left empty.
pub fn split_head(buf: &mut Vec<u8>) -> Option<(Vec<u8>, Vec<u8>)> {
    let end = find(buf, b"\r\n\r\n")?;
    let rest = buf.split_off(end + 4);
    Some((std::mem::take(buf), rest))
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// The values of every header line named `name` (case-insensitive), comma-split.
fn header_values<'a>(head: &'a str, name: &'a str) -> impl Iterator<Item = &'a str> + 'a {
    head.lines()
        .filter_map(|l| l.split_once(':'))
        .filter(move |(k, _)| k.trim().eq_ignore_ascii_case(name))
        .map(|(_, v)| v.trim())
}

/// The subprotocols a request head offers (every `Sec-WebSocket-Protocol` line).
pub fn offered(head: &str) -> Vec<String> {
    header_values(head, "sec-websocket-protocol")
        .flat_map(|v| v.split(',').map(|p| p.trim().to_string()))
        .filter(|p| !p.is_empty())
        .collect()
}

/// The token a request presents: `?token=` (or `&token=`) in its target, or
/// `Authorization: Bearer`.
pub fn presented_token(head: &str) -> Option<String> {
    let target = head.lines().next()?.split_whitespace().nth(1)?;
    if let Some((_, q)) = target.split_once('?') {
        for kv in q.split('&') {
            if let Some(v) = kv.strip_prefix("token=") {
                return Some(percent_decode(v));
            }
        }
    }
    header_values(head, "authorization")
        .find_map(|v| v.strip_prefix("Bearer ").map(|t| t.trim().to_string()))
}

fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%'
            && i + 2 < b.len()
            && let Ok(v) =
                u8::from_str_radix(std::str::from_utf8(&b[i + 1..i + 3]).unwrap_or(""), 16)
        {
            out.push(v);
            i += 3;
        } else {
            out.push(if b[i] == b'+' { b' ' } else { b[i] });
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Equal, in a time that does not depend on where they differ.
/// The request head to send the SDK, and whether the client speaks the legacy name.
pub fn rewrite_request(head: &str) -> (String, bool) {
    let offers = offered(head);
    let legacy = offers.iter().any(|p| p == LEGACY) && !offers.iter().any(|p| p.starts_with(SDK));
    if !legacy {
        return (head.to_string(), false);
    }
    (replace_protocol(head, SDK), true)
}

/// `head` with its `Sec-WebSocket-Protocol` lines replaced by one naming `protocol`.
pub fn replace_protocol(head: &str, protocol: &str) -> String {
    let mut out = String::with_capacity(head.len() + 32);
    let mut done = false;
    for line in head.split_inclusive("\r\n") {
        let is_proto = line
            .split_once(':')
            .is_some_and(|(k, _)| k.trim().eq_ignore_ascii_case("sec-websocket-protocol"));
        if is_proto {
            if !done {
                out.push_str("Sec-WebSocket-Protocol: ");
                out.push_str(protocol);
                out.push_str("\r\n");
                done = true;
            }
        } else {
            out.push_str(line);
        }
    }
    out
}

/// Why an upgrade request is refused: the HTTP status, the answer's text and
/// the log line's.
#[derive(Debug, PartialEq, Eq)]
pub struct Refusal {
    pub status: &'static str,
    pub answer: &'static str,
    pub log: &'static str,
}

/// The log of a refusal for a missing or wrong token.
const WRONG_TOKEN: &str = "no token or a wrong one";

/// Checks a client's upgrade request head (text, a GET, the token when `token`
/// is set): (the head, the head to send the SDK, whether the client speaks the
/// legacy name), or why it is refused. No I/O, so it is callable on bytes.
pub fn check_request(
    head: Vec<u8>,
    token: Option<&str>,
) -> Result<(String, String, bool), Refusal> {
    let bad = |answer, log| Refusal {
        status: "400 Bad Request",
        answer,
        log,
    };
    let Ok(head) = String::from_utf8(head) else {
        return Err(bad(
            "the HTTP head is not text",
            "sent a head that is not text",
        ));
    };
    if !head.starts_with("GET ") {
        return Err(bad(
            "expected a WebSocket upgrade request (GET)",
            "sent something that is not a WebSocket upgrade request",
        ));
    }
    if let Some(want) = token
        && !presented_token(&head).is_some_and(|t| same_secret(t.as_bytes(), want.as_bytes()))
    {
        return Err(Refusal {
            status: "401 Unauthorized",
            answer: "this server wants its token: ws[s]://HOST:PORT/?token=SECRET \
                     (or the header `Authorization: Bearer SECRET`)",
            log: WRONG_TOKEN,
        });
    }
    let (to_sdk, legacy) = rewrite_request(&head);
    Ok((head, to_sdk, legacy))
}

async fn refuse(client: &mut TcpStream, status: &str, why: &str) {
    let body = format!("{why}\n");
    let reply = format!(
        "HTTP/1.1 {status}\r\nContent-Type: text/plain\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    let _ = client.write_all(reply.as_bytes()).await;
    let _ = client.shutdown().await;
}

fn set_send_buffer(s: &TcpStream) {
    let size = SOCKET_BUFFER as libc::c_int;
    let _ = sockets::set_int_option(s, libc::SOL_SOCKET, libc::SO_SNDBUF, size);
}

/// A socket handed to the SDK: shut down when the door lets go of it before
/// the SDK is done (the connection was evicted), so the SDK's session ends too.
struct Handed {
    client: Arc<TcpStream>,
    end: Arc<End>,
    stats: Arc<RelayStats>,
}

impl Drop for Handed {
    fn drop(&mut self) {
        self.stats.clients.fetch_sub(1, Ordering::Relaxed);
        if !self.end.done.load(Ordering::Acquire) {
            // SAFETY: shutdown of a socket we hold open.
            unsafe { libc::shutdown(self.client.as_raw_fd(), libc::SHUT_RDWR) };
        }
    }
}

async fn connection(
    mut client: TcpStream,
    peer: SocketAddr,
    door: &Arc<Door>,
    conn: &Arc<Conn>,
) -> Result<(), String> {
    let _ = client.set_nodelay(true);
    set_send_buffer(&client);
    let (head, early) = match tokio::time::timeout(HEAD_TIMEOUT, read_head(&mut client)).await {
        Ok(Ok(h)) => h,
        Ok(Err(why)) => {
            refuse(&mut client, "400 Bad Request", &why).await;
            return Err(why);
        }
        Err(_) => {
            let why = format!("no HTTP upgrade request within {HEAD_TIMEOUT:?}");
            refuse(&mut client, "400 Bad Request", &why).await;
            return Err(why);
        }
    };
    let (head, to_sdk, legacy) = match check_request(head, door.limits.token.as_deref()) {
        Ok(r) => r,
        Err(r) => {
            refuse(&mut client, r.status, r.answer).await;
            return Err(r.log.into());
        }
    };
    door.touch(conn);
    let client = Arc::new(client);
    let end = Arc::new(End::default());
    let stream = DoorStream::new(
        client.clone(),
        to_sdk.into_bytes(),
        early,
        legacy,
        door.clone(),
        conn.clone(),
        end.clone(),
    );
    door.stats.clients.fetch_add(1, Ordering::Relaxed);
    let handed = Handed {
        client,
        end: end.clone(),
        stats: door.stats.clone(),
    };
    if !(door.serve)(stream, peer) {
        return Err("the SDK's server is stopped".into());
    }
    end.finished.notified().await;
    let how = std::mem::take(&mut *end.how.lock());
    match how {
        How::Open => Ok(()),
        How::Refused(status) => Err(format!(
            "refused by the SDK's server: {status} (offered subprotocols: {})",
            offered(&head).join(", ")
        )),
        How::Closed(code, why) => {
            let _ = tokio::time::timeout(CLOSE_GRACE, lingering_close(&handed.client, code, &why))
                .await;
            Err(format!("closed with {code}: {why}"))
        }
        How::ClosedMidFrame(code, why) => {
            Err(format!("closed ({code}: {why}) in the middle of a frame"))
        }
        How::Stuck => Err(format!(
            "took no byte for {WRITE_TIMEOUT:?} with a frame waiting; disconnected"
        )),
    }
}

/// Sends a close frame, then reads and drops what the client still sends until it
/// closes too (RFC 6455 §7.1.1): closing with unread bytes would reset the
/// connection and lose the close frame on the way.
async fn lingering_close(client: &TcpStream, code: u16, why: &str) {
    let frame = close_frame(code, why);
    let mut b: &[u8] = &frame;
    while !b.is_empty() {
        if client.writable().await.is_err() {
            return;
        }
        match client.try_write(b) {
            Ok(n) => b = &b[n..],
            Err(e) if would_block(&e) => {}
            Err(_) => return,
        }
    }
    // SAFETY: shutdown of writes on a socket we hold open.
    unsafe { libc::shutdown(client.as_raw_fd(), libc::SHUT_WR) };
    let mut b = vec![0u8; 16 * 1024];
    loop {
        if client.readable().await.is_err() {
            return;
        }
        match client.try_read(&mut b) {
            Ok(0) => return,
            Ok(_) => {}
            Err(e) if would_block(&e) => {}
            Err(_) => return,
        }
    }
}

fn would_block(e: &std::io::Error) -> bool {
    e.kind() == std::io::ErrorKind::WouldBlock
}

/// A frame header: (fin, opcode, masked, payload length, header length), or None
/// when `b` does not hold the whole header yet.
pub fn parse_header(b: &[u8]) -> Option<(bool, u8, bool, u64, usize)> {
    if b.len() < 2 {
        return None;
    }
    let fin = b[0] & 0x80 != 0;
    let opcode = b[0] & 0x0f;
    let masked = b[1] & 0x80 != 0;
    let (len, mut at) = match b[1] & 0x7f {
        126 => {
            if b.len() < 4 {
                return None;
            }
            (u16::from_be_bytes([b[2], b[3]]) as u64, 4)
        }
        127 => {
            if b.len() < 10 {
                return None;
            }
            (u64::from_be_bytes(b[2..10].try_into().ok()?), 10)
        }
        n => (n as u64, 2),
    };
    if masked {
        at += 4;
        if b.len() < at {
            return None;
        }
    }
    Some((fin, opcode, masked, len, at))
}

/// A close frame from the server side (unmasked) with `code` and `reason`.
pub fn close_frame(code: u16, reason: &str) -> Vec<u8> {
    let reason = &reason.as_bytes()[..reason.len().min(120)];
    let mut f = vec![0x88, (2 + reason.len()) as u8];
    f.extend_from_slice(&code.to_be_bytes());
    f.extend_from_slice(reason);
    f
}

/// Why the client side must be closed: (status code, reason).
type Close = (u16, String);

/// What the client → server parser has seen of the byte stream.
pub struct ClientFrames {
    max_message: usize,
    /// Header bytes of the frame being read (up to 14).
    hdr: Vec<u8>,
    /// Payload bytes of the current frame still to come.
    payload: u64,
    /// Bytes of the message in progress (data frames since its first).
    message: u64,
    /// A data message was started and not finished (FIN).
    open: bool,
    /// When the message or frame in progress began.
    since: Option<Instant>,
    control_window: Instant,
    controls: u32,
}

impl ClientFrames {
    pub fn new(max_message: usize) -> ClientFrames {
        ClientFrames {
            max_message,
            hdr: Vec::with_capacity(14),
            payload: 0,
            message: 0,
            open: false,
            since: None,
            control_window: Instant::now(),
            controls: 0,
        }
    }

    /// Bytes of `b` that may go to the server; an error is the close to send
    /// instead of the rest.
    pub fn feed(&mut self, b: &[u8], now: Instant) -> Result<usize, (usize, Close)> {
        let mut at = 0;
        while at < b.len() {
            if self.payload > 0 {
                let n = (self.payload.min((b.len() - at) as u64)) as usize;
                self.payload -= n as u64;
                at += n;
                if self.payload == 0 && !self.open {
                    self.since = None;
                }
                continue;
            }
            let frame_start = at - self.hdr.len().min(at);
            self.since.get_or_insert(now);
            self.hdr.push(b[at]);
            at += 1;
            let Some((fin, op, masked, len, hl)) = parse_header(&self.hdr) else {
                if self.hdr.len() >= 14 {
                    return Err((frame_start, (1002, "a bad frame header".into())));
                }
                continue;
            };
            debug_assert_eq!(hl, self.hdr.len());
            self.hdr.clear();
            if !masked {
                // RFC 6455 §5.1: a server closes on an unmasked client frame.
                return Err((frame_start, (1002, "an unmasked client frame".into())));
            }
            if op >= 0x8 {
                if now.duration_since(self.control_window) >= Duration::from_secs(1) {
                    self.control_window = now;
                    self.controls = 0;
                }
                self.controls += 1;
                if self.controls > MAX_CONTROL_PER_SEC {
                    return Err((
                        frame_start,
                        (1008, format!("over {MAX_CONTROL_PER_SEC} pings a second")),
                    ));
                }
            } else {
                if op != 0 {
                    self.message = 0;
                }
                self.message = self.message.saturating_add(len);
                if self.message > self.max_message as u64 {
                    return Err((
                        frame_start,
                        (1009, format!("a message over {} bytes", self.max_message)),
                    ));
                }
                self.open = !fin;
            }
            self.payload = len;
            if self.payload == 0 && !self.open {
                self.since = None;
            }
        }
        Ok(at)
    }

    /// When the message or frame in progress must be finished, if one is.
    pub fn deadline(&self) -> Option<Instant> {
        self.since.map(|t| t + MESSAGE_TIMEOUT)
    }
}

/// How a handed connection ended, as the door logs it.
#[derive(Default)]
enum How {
    /// The SDK or the client closed it.
    #[default]
    Open,
    /// The SDK refused the upgrade (its status line).
    Refused(String),
    /// A client-frame limit: the close to send (the stream was at a frame's end).
    Closed(u16, String),
    /// The same, the frame in flight not finished within [`CLOSE_GRACE`].
    ClosedMidFrame(u16, String),
    /// The client took no byte for [`WRITE_TIMEOUT`] while a frame waited.
    Stuck,
}

/// What a [`DoorStream`] tells the door when the SDK lets go of it.
#[derive(Default)]
pub struct End {
    done: AtomicBool,
    finished: Notify,
    how: Mutex<How>,
}

/// Where the server → client byte stream is: frame headers followed, so the
/// door knows where frames end and which were message data.
#[derive(Default)]
struct OutFrames {
    hdr: [u8; 14],
    hl: usize,
    /// Payload bytes of the current frame still to go.
    left: u64,
    /// The frame is binary and final, its first payload byte not seen yet.
    first: bool,
    /// The frame is message data (binary, first byte 0x01).
    data: bool,
}

impl OutFrames {
    /// Follows `b`: message-data frames it finished.
    fn feed(&mut self, b: &[u8]) -> u64 {
        let (mut at, mut done) = (0, 0);
        while at < b.len() {
            if self.left > 0 {
                if self.first {
                    self.data = b[at] == 0x01;
                    self.first = false;
                }
                let n = self.left.min((b.len() - at) as u64);
                self.left -= n;
                at += n as usize;
                if self.left == 0 && std::mem::take(&mut self.data) {
                    done += 1;
                }
                continue;
            }
            self.hdr[self.hl] = b[at];
            self.hl += 1;
            at += 1;
            if let Some((fin, op, _, len, _)) = parse_header(&self.hdr[..self.hl]) {
                self.hl = 0;
                self.left = len;
                self.first = fin && op == 0x2 && len > 0;
            } else if self.hl == self.hdr.len() {
                self.hl = 0; // not a header (the SDK writes none such): start again
            }
        }
        done
    }

    fn at_end(&self) -> bool {
        self.left == 0 && self.hl == 0
    }

    /// Bytes that may go without starting another frame.
    fn in_frame(&self) -> usize {
        if self.hl > 0 {
            1
        } else {
            usize::try_from(self.left).unwrap_or(usize::MAX)
        }
    }
}

/// A client's socket as the SDK's server sees it: the request head the door
/// read (rewritten for the SDK), then the client's bytes through the frame
/// checks ([`ClientFrames`]); the SDK's writes go straight to the socket, its
/// answer's protocol name rewritten for legacy clients.
pub struct DoorStream {
    client: Arc<TcpStream>,
    /// The request head for the SDK, then the bytes the client sent after it.
    head: Vec<u8>,
    head_at: usize,
    early: Vec<u8>,
    frames: ClientFrames,
    /// The SDK's answer head, collected until its end (None after).
    reply: Option<Vec<u8>>,
    /// Bytes of the rewritten answer still to write.
    pending: Vec<u8>,
    legacy: bool,
    out: OutFrames,
    /// A limit the client broke: the close to send at the next frame's end.
    closing: Option<(u16, String)>,
    /// Reads give end-of-stream, writes an error: the door closes the connection.
    ended: bool,
    read_waker: Option<Waker>,
    message_timer: Option<(Instant, Pin<Box<Sleep>>)>,
    grace: Option<Pin<Box<Sleep>>>,
    /// Armed while the client takes no byte.
    stuck: Option<Pin<Box<Sleep>>>,
    door: Arc<Door>,
    conn: Arc<Conn>,
    end: Arc<End>,
}

impl DoorStream {
    fn new(
        client: Arc<TcpStream>,
        head: Vec<u8>,
        early: Vec<u8>,
        legacy: bool,
        door: Arc<Door>,
        conn: Arc<Conn>,
        end: Arc<End>,
    ) -> DoorStream {
        DoorStream {
            client,
            head,
            head_at: 0,
            early,
            frames: ClientFrames::new(door.limits.max_message),
            reply: Some(Vec::new()),
            pending: Vec::new(),
            legacy,
            out: OutFrames::default(),
            closing: None,
            ended: false,
            read_waker: None,
            message_timer: None,
            grace: None,
            stuck: None,
            door,
            conn,
            end,
        }
    }

    fn finish(&mut self, how: How) {
        self.ended = true;
        *self.end.how.lock() = how;
    }

    /// At a frame's end (nothing of the answer head pending either).
    fn at_end(&self) -> bool {
        self.out.at_end() && self.pending.is_empty() && self.reply.is_none()
    }

    /// A limit was broken: end the stream at the frame's end (within the grace).
    fn poll_close(&mut self, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        let (code, why) = self.closing.clone().unwrap_or_default();
        if self.at_end() {
            self.finish(How::Closed(code, why));
            return Poll::Ready(Ok(()));
        }
        self.read_waker = Some(cx.waker().clone());
        let grace = self
            .grace
            .get_or_insert_with(|| Box::pin(tokio::time::sleep(CLOSE_GRACE)));
        ready!(grace.as_mut().poll(cx));
        self.finish(How::ClosedMidFrame(code, why));
        Poll::Ready(Ok(()))
    }

    /// Passes the client's bytes in `got` (just put in `buf`) through the frame
    /// checks: how many may go to the SDK.
    fn check(&mut self, got: &[u8]) -> usize {
        match self.frames.feed(got, Instant::now()) {
            Ok(n) => n,
            Err((n, close)) => {
                self.closing = Some(close);
                n
            }
        }
    }

    /// Pending when the client's unfinished message still has time; else the close.
    fn poll_message_timer(&mut self, cx: &mut Context<'_>) -> Poll<()> {
        let Some(d) = self.frames.deadline() else {
            self.message_timer = None;
            return Poll::Pending;
        };
        if self.message_timer.as_ref().is_none_or(|(at, _)| *at != d) {
            let t = Box::pin(tokio::time::sleep_until(d.into()));
            self.message_timer = Some((d, t));
        }
        let (_, t) = self.message_timer.as_mut().expect("set above");
        ready!(t.as_mut().poll(cx));
        self.closing = Some((
            1008,
            format!("a message left unfinished for {MESSAGE_TIMEOUT:?}"),
        ));
        Poll::Ready(())
    }

    /// Writes what is left of the answer head.
    fn poll_pending(&mut self, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        while !self.pending.is_empty() {
            let n = ready!(self.poll_socket_write(cx, None))?;
            self.pending.drain(..n);
        }
        Poll::Ready(Ok(()))
    }

    /// Writes `buf` (or the pending head) to the socket, closing a client that
    /// takes no byte for [`WRITE_TIMEOUT`].
    fn poll_socket_write(
        &mut self,
        cx: &mut Context<'_>,
        buf: Option<&[u8]>,
    ) -> Poll<std::io::Result<usize>> {
        loop {
            if self.client.poll_write_ready(cx).is_pending() {
                let stuck = self
                    .stuck
                    .get_or_insert_with(|| Box::pin(tokio::time::sleep(WRITE_TIMEOUT)));
                ready!(stuck.as_mut().poll(cx));
                self.finish(How::Stuck);
                // SAFETY: shutdown of a socket we hold open (wakes the SDK's reader).
                unsafe { libc::shutdown(self.client.as_raw_fd(), libc::SHUT_RDWR) };
                return Poll::Ready(Err(std::io::ErrorKind::TimedOut.into()));
            }
            let b = buf.unwrap_or(&self.pending);
            match self.client.try_write(b) {
                Ok(n) => {
                    self.stuck = None;
                    self.door.touch(&self.conn);
                    return Poll::Ready(Ok(n));
                }
                Err(e) if would_block(&e) => {}
                Err(e) => return Poll::Ready(Err(e)),
            }
        }
    }

    /// Collects the SDK's answer head; at its end, rewrites it for a legacy
    /// client and queues it (with any frame bytes after it).
    fn take_reply(&mut self, buf: &[u8]) -> std::io::Result<()> {
        let reply = self.reply.as_mut().expect("collecting the answer");
        reply.extend_from_slice(buf);
        let Some(end) = find(reply, b"\r\n\r\n") else {
            if reply.len() > MAX_HEAD {
                return Err(std::io::Error::other("the SDK's answer head is too long"));
            }
            return Ok(());
        };
        let rest = reply.split_off(end + 4);
        let head = String::from_utf8_lossy(reply).into_owned();
        self.reply = None;
        let upgraded = head.starts_with("HTTP/1.1 101");
        let head = if self.legacy && upgraded {
            replace_protocol(&head, LEGACY)
        } else {
            head
        };
        if !upgraded {
            let status = head.lines().next().unwrap_or("").to_string();
            *self.end.how.lock() = How::Refused(status);
        }
        self.pending = head.into_bytes();
        self.door
            .stats
            .sent
            .fetch_add(self.out.feed(&rest), Ordering::Relaxed);
        self.pending.extend_from_slice(&rest);
        Ok(())
    }
}

impl Drop for DoorStream {
    fn drop(&mut self) {
        self.end.done.store(true, Ordering::Release);
        self.end.finished.notify_one();
    }
}

impl AsyncRead for DoorStream {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        let me = self.get_mut();
        if me.head_at < me.head.len() {
            let n = buf.remaining().min(me.head.len() - me.head_at);
            buf.put_slice(&me.head[me.head_at..me.head_at + n]);
            me.head_at += n;
            return Poll::Ready(Ok(()));
        }
        if me.ended {
            return Poll::Ready(Ok(()));
        }
        if me.closing.is_some() {
            return me.poll_close(cx);
        }
        if !me.early.is_empty() {
            let k = buf.remaining().min(me.early.len());
            let early: Vec<u8> = me.early.drain(..k).collect();
            let n = me.check(&early);
            buf.put_slice(&early[..n]);
            return if n == 0 && me.closing.is_some() {
                me.poll_close(cx)
            } else {
                Poll::Ready(Ok(()))
            };
        }
        loop {
            if me.client.poll_read_ready(cx).is_pending() {
                ready!(me.poll_message_timer(cx));
                return me.poll_close(cx);
            }
            let unfilled = buf.initialize_unfilled();
            match me.client.try_read(unfilled) {
                Ok(0) => return Poll::Ready(Ok(())),
                Ok(got) => {
                    me.door.touch(&me.conn);
                    let n = me.check(&buf.initialize_unfilled()[..got]);
                    buf.advance(n);
                    if n == 0 && me.closing.is_some() {
                        return me.poll_close(cx);
                    }
                    return Poll::Ready(Ok(()));
                }
                Err(e) if would_block(&e) => {}
                Err(e) => return Poll::Ready(Err(e)),
            }
        }
    }
}

impl AsyncWrite for DoorStream {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        let me = self.get_mut();
        if me.ended {
            return Poll::Ready(Err(std::io::ErrorKind::BrokenPipe.into()));
        }
        if me.reply.is_some() {
            me.take_reply(buf)?;
            return Poll::Ready(Ok(buf.len()));
        }
        ready!(me.poll_pending(cx))?;
        let mut max = buf.len();
        if me.closing.is_some() {
            if me.out.at_end() {
                // The close goes next: no new frame; the reader ends the stream.
                if let Some(w) = me.read_waker.take() {
                    w.wake();
                }
                return Poll::Pending;
            }
            max = max.min(me.out.in_frame());
        }
        let n = ready!(me.poll_socket_write(cx, Some(&buf[..max])))?;
        let done = me.out.feed(&buf[..n]);
        if done > 0 {
            let stats = &me.door.stats;
            stats.sent.fetch_add(done, Ordering::Relaxed);
            if let Some(w) = stats.taken.get() {
                w.wake();
            }
        }
        if me.closing.is_some()
            && me.out.at_end()
            && let Some(w) = me.read_waker.take()
        {
            w.wake();
        }
        Poll::Ready(Ok(n))
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        self.get_mut().poll_pending(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        // The door closes the socket once the SDK lets go of it.
        self.get_mut().poll_pending(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legacy_offers_are_rewritten_and_sdk_offers_pass() {
        let h =
            "GET / HTTP/1.1\r\nHost: x\r\nsec-websocket-protocol: foxglove.websocket.v1\r\n\r\n";
        let (out, legacy) = rewrite_request(h);
        assert!(legacy);
        assert!(
            out.contains("Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n"),
            "{out}"
        );
        assert!(!out.contains("websocket.v1"));
        assert!(out.ends_with("\r\n\r\n"));
        let h2 = "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: foxglove.sdk.v1, foxglove.websocket.v1\r\n\r\n";
        assert_eq!(rewrite_request(h2), (h2.to_string(), false));
        let reply =
            "HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.sdk.v1\r\n\r\n";
        assert!(
            replace_protocol(reply, LEGACY)
                .contains("Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n")
        );
    }

    #[test]
    fn frame_headers_of_each_length_form() {
        assert_eq!(parse_header(&[0x82, 5]), Some((true, 2, false, 5, 2)));
        assert_eq!(
            parse_header(&[0x81, 0x80 | 126, 1, 0, 1, 2, 3, 4]),
            Some((true, 1, true, 256, 8))
        );
        let mut h = vec![0x02, 127];
        h.extend_from_slice(&(1u64 << 33).to_be_bytes());
        assert_eq!(parse_header(&h), Some((false, 2, false, 1 << 33, 10)));
        assert_eq!(parse_header(&[0x82]), None);
        assert_eq!(parse_header(&[0x82, 0x80 | 126, 1]), None);
    }

    /// A masked client frame (RFC 6455 §5.2) of `op` carrying `len` bytes.
    fn frame(fin: bool, op: u8, len: usize) -> Vec<u8> {
        let mut f = vec![(fin as u8) << 7 | op];
        match len {
            0..=125 => f.push(0x80 | len as u8),
            126..=65535 => {
                f.push(0x80 | 126);
                f.extend_from_slice(&(len as u16).to_be_bytes());
            }
            _ => {
                f.push(0x80 | 127);
                f.extend_from_slice(&(len as u64).to_be_bytes());
            }
        }
        f.extend_from_slice(&[1, 2, 3, 4]);
        f.extend(std::iter::repeat_n(0u8, len));
        f
    }

    #[test]
    fn client_messages_are_bounded_across_fragments_and_in_time() {
        let t = Instant::now();
        let mut p = ClientFrames::new(1000);
        let ok = frame(true, 2, 900);
        assert_eq!(p.feed(&ok, t), Ok(ok.len()));
        assert_eq!(p.deadline(), None);
        // Fragments of 600 + 600: the second one crosses the limit; what went before passes.
        let a = frame(false, 2, 600);
        let b = frame(true, 0, 600);
        let both = [a.clone(), b].concat();
        let e = p.feed(&both, t).unwrap_err();
        assert_eq!((e.0, e.1.0), (a.len(), 1009));
        // A frame split byte by byte keeps its start time as the deadline.
        let mut p = ClientFrames::new(1000);
        let f = frame(true, 1, 300);
        assert_eq!(p.feed(&f[..5], t), Ok(5));
        assert_eq!(p.deadline(), Some(t + MESSAGE_TIMEOUT));
        assert_eq!(p.feed(&f[5..], t + Duration::from_secs(1)), Ok(f.len() - 5));
        assert_eq!(p.deadline(), None);
        // An unfinished fragmented message keeps a deadline between its frames.
        assert!(p.feed(&frame(false, 2, 10), t).is_ok());
        assert!(p.deadline().is_some());
        // A ping flood.
        let mut p = ClientFrames::new(1000);
        let ping = frame(true, 9, 4);
        let flood: Vec<u8> = (0..=MAX_CONTROL_PER_SEC)
            .flat_map(|_| ping.clone())
            .collect();
        let e = p.feed(&flood, t).unwrap_err();
        assert_eq!(e.1.0, 1008);
        assert_eq!(e.0, ping.len() * MAX_CONTROL_PER_SEC as usize);
        // A header announcing 2^63 bytes.
        let mut p = ClientFrames::new(1000);
        let mut h = vec![0x82, 0x80 | 127];
        h.extend_from_slice(&(1u64 << 63).to_be_bytes());
        h.extend_from_slice(&[0; 4]);
        assert_eq!(p.feed(&h, t).unwrap_err().1.0, 1009);
    }

    #[test]
    fn server_frames_are_followed_across_split_writes() {
        // A message-data frame (binary, first byte 0x01, 300 bytes), a text
        // frame, a binary frame of another op byte: fed in pieces of every size.
        let mut bytes = vec![0x82, 126, 1, 44, 0x01];
        bytes.extend(std::iter::repeat_n(7u8, 299));
        bytes.extend([0x81, 3, b'{', b'}', b' ', 0x82, 2, 0x02, 0]);
        for piece in 1..bytes.len() {
            let mut o = OutFrames::default();
            let mut data = 0;
            for chunk in bytes.chunks(piece) {
                data += o.feed(chunk);
            }
            assert_eq!(data, 1, "pieces of {piece}");
            assert!(o.at_end());
        }
        let mut o = OutFrames::default();
        o.feed(&bytes[..3]);
        assert_eq!(o.in_frame(), 1);
        o.feed(&bytes[3..10]);
        assert_eq!((o.at_end(), o.in_frame()), (false, 294));
    }

    #[test]
    fn tokens_from_the_url_or_the_header() {
        let h = "GET /?a=1&token=s%20e+c HTTP/1.1\r\nHost: x\r\n\r\n";
        assert_eq!(presented_token(h).as_deref(), Some("s e c"));
        let h = "GET / HTTP/1.1\r\nauthorization: Bearer abc\r\n\r\n";
        assert_eq!(presented_token(h).as_deref(), Some("abc"));
        assert_eq!(presented_token("GET / HTTP/1.1\r\n\r\n"), None);
    }
}
