//! The ports users connect to: a splicing front door to the SDK's server.
//!
//! The SDK's server (bound to an ephemeral loopback port) accepts only the
//! subprotocols `foxglove.sdk.v1` and `foxglove.sdk.v1.1`, while the official npm
//! client `@foxglove/ws-protocol` 0.8.0 and Lichtblick offer only
//! `foxglove.websocket.v1` (the same messages under the protocol's older name; the
//! client checks that the server answers with that exact name). The SDK's own
//! accept loop also ends for good on the first failed `accept` (out of file
//! descriptors), and it has no connection cap. So every port (`port`, `sdk_port`)
//! is this front door, which for each connection
//!
//! 1. admits it under the cap `max_clients` (over both ports): when full, the
//!    connection that has been idle longest (no byte either way) is closed to make
//!    room, with one log line; a failed `accept` (EMFILE) closes the longest idle
//!    one too and the loop goes on;
//! 2. reads the HTTP upgrade request (at most [`MAX_HEAD`] bytes within
//!    [`HEAD_TIMEOUT`]; anything else is answered `400` and closed), checks the
//!    `token` when the conf sets one (`?token=` in the URL or `Authorization:
//!    Bearer`; else `401`);
//! 3. when the client offers `foxglove.websocket.v1` and no `foxglove.sdk.v1*`,
//!    asks the SDK for `foxglove.sdk.v1` and answers the client with
//!    `foxglove.websocket.v1` (the frames that follow are the same protocol);
//!    offers of `foxglove.sdk.v1*` pass unchanged;
//! 4. then moves bytes, not messages:
//!    - server → client: spliced through a pipe in the kernel (`splice(2)`, no copy
//!      in user space), one RFC 6455 frame at a time (the relay peeks each frame's
//!      header, so it knows where frames end). A client that stops reading holds
//!      back only its own socket: the SDK's per-client backlog (`max_queue`
//!      message frames) then drops that client's oldest messages, and a client
//!      that takes no byte for [`WRITE_TIMEOUT`] while a frame waits is closed;
//!    - client → server: copied as read, its frame headers parsed: a message (all
//!      its fragments) over `max_message` bytes, a message left unfinished for
//!      [`MESSAGE_TIMEOUT`], or more than [`MAX_CONTROL_PER_SEC`] control frames
//!      (pings) in a second close the connection with status 1009 (too big) or
//!      1008 (policy), sent after the frame in flight to the client.
//!
//! Memory per connection: one pipe (at most [`PIPE_BYTES`] in the kernel), a
//! 16 KiB read buffer, the SDK's `max_queue` messages; the SDK never holds more of a
//! client's unfinished message than `max_message`.

use std::{
    net::SocketAddr,
    os::fd::{AsRawFd, FromRawFd, OwnedFd, RawFd},
    sync::{
        Arc,
        atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering},
    },
    time::{Duration, Instant},
};

use parking_lot::Mutex;
use tokio::{
    io::{AsyncRead, AsyncReadExt, AsyncWriteExt, Interest},
    net::{TcpListener, TcpStream},
    sync::Notify,
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
/// The kernel pipe each connection splices through (asked for; the kernel may give less).
pub const PIPE_BYTES: usize = 1 << 20;

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

/// Starts the SDK's server again (its address), for when its accept loop ended.
pub type Respawn = Arc<dyn Fn() -> Result<SocketAddr, String> + Send + Sync>;

/// The open connections over all ports, and the clock of their activity.
pub struct Door {
    inner: Mutex<SocketAddr>,
    respawn: Respawn,
    /// One restart at a time.
    respawning: tokio::sync::Mutex<()>,
    limits: Limits,
    stats: Arc<RelayStats>,
    conns: Mutex<Vec<Arc<Conn>>>,
    t0: Instant,
    /// When the cap was last logged (ms since t0), to log it once a minute.
    cap_logged: AtomicU64,
}

impl Door {
    /// A door in front of the SDK's server at `inner`.
    pub fn new(
        inner: SocketAddr,
        respawn: Respawn,
        limits: Limits,
        stats: Arc<RelayStats>,
    ) -> Arc<Door> {
        Arc::new(Door {
            inner: Mutex::new(inner),
            respawn,
            respawning: tokio::sync::Mutex::new(()),
            limits,
            stats,
            conns: Mutex::new(Vec::new()),
            t0: Instant::now(),
            cap_logged: AtomicU64::new(u64::MAX),
        })
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

    /// A connection to the SDK's server; when it refuses (its accept loop ended,
    /// e.g. out of descriptors, which the SDK never recovers from), it is started
    /// again, once, with a log line.
    async fn reach_sdk(&self) -> Result<TcpStream, String> {
        let at = *self.inner.lock();
        match connect_bounded(at).await {
            Ok(s) => return Ok(s),
            Err(e) if e.kind() != std::io::ErrorKind::ConnectionRefused => {
                return Err(format!("cannot reach the SDK's server at {at}: {e}"));
            }
            Err(_) => {}
        }
        {
            let _one = self.respawning.lock().await;
            if *self.inner.lock() == at {
                tracing::warn!(
                    "foxglove: the SDK's server at {at} stopped accepting (out of descriptors?); starting it again"
                );
                let respawn = self.respawn.clone();
                let new = tokio::task::spawn_blocking(move || respawn())
                    .await
                    .map_err(|e| e.to_string())??;
                *self.inner.lock() = new;
            }
        }
        let at = *self.inner.lock();
        connect_bounded(at)
            .await
            .map_err(|e| format!("cannot reach the SDK's server at {at}: {e}"))
    }

    fn touch(&self, c: &Conn) {
        c.last.store(self.now(), Ordering::Relaxed);
    }
}

/// The kernel buffers on the door's side of each connection (asked for; Linux
/// doubles them): what a client that stops reading holds there, besides the pipe,
/// before the SDK's backlog starts dropping its oldest frames.
pub const SOCKET_BUFFER: u32 = 1 << 20;

/// A connection to the SDK's server with a bounded receive buffer (set before the
/// handshake, so the window is sized by it).
async fn connect_bounded(at: SocketAddr) -> std::io::Result<TcpStream> {
    let s = if at.is_ipv4() {
        tokio::net::TcpSocket::new_v4()?
    } else {
        tokio::net::TcpSocket::new_v6()?
    };
    s.set_recv_buffer_size(SOCKET_BUFFER)?;
    s.connect(at).await
}

/// Accepts on `listener` and relays each connection to the SDK's server, for ever
/// (a failed accept, e.g. out of descriptors, frees the longest idle one and goes on).
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
        let conn = door.admit();
        let door = door.clone();
        tokio::spawn(async move {
            let r = tokio::select! {
                r = connection(client, &door, &conn) => r,
                () = conn.kill.notified() => Err("closed to admit a newer client (max_clients)".into()),
            };
            door.leave(&conn);
            if let Err(why) = r {
                door.stats.refused.fetch_add(1, Ordering::Relaxed);
                tracing::info!("foxglove: client {peer}: {why}");
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

/// Copies what `s` has queued into `buf` without taking it (`MSG_PEEK`), without
/// blocking: the bytes stay for the next read or splice.
fn peek(s: &TcpStream, buf: &mut [u8]) -> std::io::Result<usize> {
    // SAFETY: recv into a valid buffer of its length, peeking.
    let n = unsafe {
        libc::recv(
            s.as_raw_fd(),
            buf.as_mut_ptr().cast(),
            buf.len(),
            libc::MSG_PEEK | libc::MSG_DONTWAIT,
        )
    };
    if n < 0 {
        Err(std::io::Error::last_os_error())
    } else {
        Ok(n as usize)
    }
}

/// Reads exactly an HTTP head from `s` (peeking for its end), so that the frames
/// after it start at the socket's next byte: (head, nothing).
async fn read_head_exact(s: &TcpStream) -> Result<(Vec<u8>, Vec<u8>), String> {
    let mut buf = vec![0u8; MAX_HEAD];
    loop {
        s.readable().await.map_err(|e| e.to_string())?;
        let got = s.try_io(Interest::READABLE, || peek(s, &mut buf));
        let n = match got {
            Ok(0) => return Err("the SDK's server closed before its HTTP head".into()),
            Ok(n) => n,
            Err(e) if would_block(&e) => continue,
            Err(e) => return Err(e.to_string()),
        };
        if let Some(end) = find(&buf[..n], b"\r\n\r\n") {
            let mut head = vec![0u8; end + 4];
            let mut at = 0;
            while at < head.len() {
                s.readable().await.map_err(|e| e.to_string())?;
                match s.try_read(&mut head[at..]) {
                    Ok(0) => return Err("the SDK's server closed in its HTTP head".into()),
                    Ok(k) => at += k,
                    Err(e) if would_block(&e) => {}
                    Err(e) => return Err(e.to_string()),
                }
            }
            return Ok((head, Vec::new()));
        }
        if n >= MAX_HEAD {
            return Err(format!("the SDK's HTTP head is over {MAX_HEAD} bytes"));
        }
        // The head's end has not come yet (it comes in one piece in practice).
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
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
fn same_secret(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    let mut d = (a.len() != b.len()) as u8;
    for i in 0..a.len().max(b.len()) {
        d |= a.get(i).copied().unwrap_or(0) ^ b.get(i).copied().unwrap_or(0);
    }
    d == 0
}

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
        && !presented_token(&head).is_some_and(|t| same_secret(&t, want))
    {
        return Err(Refusal {
            status: "401 Unauthorized",
            answer: "this server wants its token: ws[s]://HOST:PORT/?token=SECRET \
                     (or the header `Authorization: Bearer SECRET`)",
            log: "no token or a wrong one",
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

async fn connection(mut client: TcpStream, door: &Door, conn: &Conn) -> Result<(), String> {
    let _ = client.set_nodelay(true);
    let size = SOCKET_BUFFER as libc::c_int;
    // SAFETY: setsockopt on a socket we hold open, with an int we own.
    unsafe {
        libc::setsockopt(
            client.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_SNDBUF,
            (&size as *const libc::c_int).cast(),
            std::mem::size_of::<libc::c_int>() as libc::socklen_t,
        )
    };
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
    let mut server = door.reach_sdk().await?;
    let _ = server.set_nodelay(true);
    server
        .write_all(to_sdk.as_bytes())
        .await
        .map_err(|e| e.to_string())?;
    let (reply, server_early) =
        match tokio::time::timeout(HEAD_TIMEOUT, read_head_exact(&server)).await {
            Ok(r) => r?,
            Err(_) => {
                return Err(format!(
                    "the SDK's server did not answer within {HEAD_TIMEOUT:?}"
                ));
            }
        };
    let reply = String::from_utf8_lossy(&reply).into_owned();
    let upgraded = reply.starts_with("HTTP/1.1 101");
    let reply = if legacy && upgraded {
        replace_protocol(&reply, LEGACY)
    } else {
        reply
    };
    client
        .write_all(reply.as_bytes())
        .await
        .map_err(|e| e.to_string())?;
    if !upgraded {
        // The SDK refused (e.g. no subprotocol it knows): pass its answer on.
        let mut rest = server_early;
        let _ = tokio::time::timeout(HEAD_TIMEOUT, server.read_to_end(&mut rest)).await;
        let _ = client.write_all(&rest).await;
        let _ = client.shutdown().await;
        return Err(format!(
            "refused by the SDK's server: {} (offered subprotocols: {})",
            reply.lines().next().unwrap_or(""),
            offered(&head).join(", ")
        ));
    }
    // Bytes the SDK sent right after its head (its serverInfo) go first.
    client
        .write_all(&server_early)
        .await
        .map_err(|e| e.to_string())?;
    door.stats.clients.fetch_add(1, Ordering::Relaxed);
    let r = relay(&client, &server, early, door, conn).await;
    door.stats.clients.fetch_sub(1, Ordering::Relaxed);
    r
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

/// A kernel pipe, both ends non-blocking.
struct Pipe {
    r: OwnedFd,
    w: OwnedFd,
    cap: usize,
}

impl Pipe {
    fn new() -> std::io::Result<Pipe> {
        let mut fds = [0 as RawFd; 2];
        // SAFETY: pipe2 writes two descriptors into the array we own.
        if unsafe { libc::pipe2(fds.as_mut_ptr(), libc::O_NONBLOCK | libc::O_CLOEXEC) } != 0 {
            return Err(std::io::Error::last_os_error());
        }
        // SAFETY: both are fresh descriptors nobody else owns.
        let (r, w) = unsafe { (OwnedFd::from_raw_fd(fds[0]), OwnedFd::from_raw_fd(fds[1])) };
        // SAFETY: fcntl on our own descriptor; failure leaves the default size.
        let got = unsafe { libc::fcntl(w.as_raw_fd(), libc::F_SETPIPE_SZ, PIPE_BYTES as i32) };
        let cap = if got > 0 { got as usize } else { 64 * 1024 };
        Ok(Pipe { r, w, cap })
    }
}

fn splice(from: RawFd, to: RawFd, len: usize) -> std::io::Result<usize> {
    // SAFETY: splice between descriptors we hold open; null offsets (streams).
    let n = unsafe {
        libc::splice(
            from,
            std::ptr::null_mut(),
            to,
            std::ptr::null_mut(),
            len,
            libc::SPLICE_F_MOVE | libc::SPLICE_F_NONBLOCK,
        )
    };
    if n < 0 {
        Err(std::io::Error::last_os_error())
    } else {
        Ok(n as usize)
    }
}

fn would_block(e: &std::io::Error) -> bool {
    e.kind() == std::io::ErrorKind::WouldBlock
}

/// Relays an upgraded connection until either side closes.
async fn relay(
    client: &TcpStream,
    server: &TcpStream,
    early: Vec<u8>,
    door: &Door,
    conn: &Conn,
) -> Result<(), String> {
    let close: Mutex<Option<Close>> = Mutex::new(None);
    let closing = Notify::new();
    let up = async {
        let r = client_to_server(client, server, early, door, conn).await;
        match r {
            Err(UpEnd::Close(c)) => {
                *close.lock() = Some(c);
                closing.notify_one();
                std::future::pending::<Result<(), String>>().await
            }
            Err(UpEnd::Io(e)) => Err(e),
            Ok(()) => Ok(()),
        }
    };
    let down = server_to_client(client, server, door, conn, &close, &closing);
    tokio::select! {
        r = up => r,
        r = down => r,
    }
}

enum UpEnd {
    Close(Close),
    Io(String),
}

async fn client_to_server(
    client: &TcpStream,
    server: &TcpStream,
    early: Vec<u8>,
    door: &Door,
    conn: &Conn,
) -> Result<(), UpEnd> {
    let mut frames = ClientFrames::new(door.limits.max_message);
    let mut buf = vec![0u8; 16 * 1024];
    let mut pending = early;
    loop {
        if !pending.is_empty() {
            let ok = frames.feed(&pending, Instant::now());
            let n = match &ok {
                Ok(n) => *n,
                Err((n, _)) => *n,
            };
            write_all(server, &pending[..n]).await.map_err(UpEnd::Io)?;
            if let Err((_, c)) = ok {
                return Err(UpEnd::Close(c));
            }
            pending.clear();
        }
        let read = async {
            loop {
                client.readable().await?;
                match client.try_read(&mut buf) {
                    Err(e) if would_block(&e) => continue,
                    r => return r,
                }
            }
        };
        let n = match frames.deadline() {
            Some(d) => match tokio::time::timeout_at(d.into(), read).await {
                Ok(r) => r,
                Err(_) => {
                    return Err(UpEnd::Close((
                        1008,
                        format!("a message left unfinished for {MESSAGE_TIMEOUT:?}"),
                    )));
                }
            },
            None => read.await,
        }
        .map_err(|e| UpEnd::Io(e.to_string()))?;
        if n == 0 {
            return Ok(());
        }
        door.touch(conn);
        pending.extend_from_slice(&buf[..n]);
    }
}

async fn write_all(s: &TcpStream, mut b: &[u8]) -> Result<(), String> {
    while !b.is_empty() {
        s.writable().await.map_err(|e| e.to_string())?;
        match s.try_write(b) {
            Ok(n) => b = &b[n..],
            Err(e) if would_block(&e) => {}
            Err(e) => return Err(e.to_string()),
        }
    }
    Ok(())
}

/// Sends a close frame, then reads and drops what the client still sends until it
/// closes too (RFC 6455 §7.1.1): closing with unread bytes would reset the
/// connection and lose the close frame on the way.
async fn lingering_close(client: &TcpStream, code: u16, why: &str) {
    if write_all(client, &close_frame(code, why)).await.is_err() {
        return;
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

/// Peeks the next frame's header (and its first payload byte): (frame length,
/// a message-data frame), None at the end of the stream.
async fn peek_frame(server: &TcpStream) -> std::io::Result<Option<(usize, bool)>> {
    let mut b = [0u8; 15];
    loop {
        server.readable().await?;
        let got = server.try_io(Interest::READABLE, || peek(server, &mut b));
        let n = match got {
            Ok(0) => return Ok(None),
            Ok(n) => n,
            Err(e) if would_block(&e) => continue,
            Err(e) => return Err(e),
        };
        if let Some((fin, op, _, len, hl)) = parse_header(&b[..n]) {
            let data = fin && op == 0x2 && (n > hl && b[hl] == 0x01);
            let total = (hl as u64).saturating_add(len);
            return usize::try_from(total)
                .map(|t| Some((t, data)))
                .map_err(|_| std::io::Error::other("a frame longer than memory"));
        }
        // Part of a header only (rare: the SDK writes a frame at once): wait a little.
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
}

async fn server_to_client(
    client: &TcpStream,
    server: &TcpStream,
    door: &Door,
    conn: &Conn,
    close: &Mutex<Option<Close>>,
    closing: &Notify,
) -> Result<(), String> {
    let pipe = Pipe::new().map_err(|e| format!("no pipe: {e}"))?;
    let (sfd, cfd) = (server.as_raw_fd(), client.as_raw_fd());
    loop {
        // At a frame boundary: a close the client side asked for goes now.
        let asked = close.lock().take();

        if let Some((code, why)) = asked {
            let _ = tokio::time::timeout(CLOSE_GRACE, lingering_close(client, code, &why)).await;
            return Err(format!("closed with {code}: {why}"));
        }
        let next = tokio::select! {
            f = peek_frame(server) => f.map_err(|e| e.to_string())?,
            () = closing.notified() => continue,
        };
        let Some((mut left, data)) = next else {
            return Ok(());
        };
        let mut in_pipe = 0usize;
        let mut stuck_since: Option<Instant> = None;
        while left > 0 || in_pipe > 0 {
            let mut moved = false;
            if left > 0 && in_pipe < pipe.cap {
                let want = left.min(pipe.cap - in_pipe);
                // With the pipe empty, "would block" can only mean the socket is
                // empty (tokio's readiness is cleared); with bytes in the pipe it may
                // mean a full pipe, so the readiness is left alone and the pipe drained.
                let got = if in_pipe == 0 {
                    server.try_io(Interest::READABLE, || splice(sfd, pipe.w.as_raw_fd(), want))
                } else {
                    splice(sfd, pipe.w.as_raw_fd(), want)
                };
                match got {
                    Ok(0) => return Ok(()),
                    Ok(n) => {
                        left -= n;
                        in_pipe += n;
                        moved = true;
                    }
                    Err(e) if would_block(&e) => {}
                    Err(e) => return Err(e.to_string()),
                }
            }
            if in_pipe > 0 {
                match client.try_io(Interest::WRITABLE, || {
                    splice(pipe.r.as_raw_fd(), cfd, in_pipe)
                }) {
                    Ok(n) => {
                        in_pipe -= n;
                        moved = true;
                        stuck_since = None;
                        door.touch(conn);
                    }
                    Err(e) if would_block(&e) => {
                        stuck_since.get_or_insert_with(Instant::now);
                    }
                    Err(e) => return Err(e.to_string()),
                }
            }
            if moved {
                continue;
            }
            // A close asked for mid-frame waits for the frame's end a second at most.
            let closing_by = close.lock().is_some().then(|| Instant::now() + CLOSE_GRACE);
            let stuck_by = *stuck_since.get_or_insert_with(Instant::now) + WRITE_TIMEOUT;
            let deadline = closing_by.map_or(stuck_by, |c| c.min(stuck_by));
            let need_out = in_pipe > 0;
            let wait = async {
                tokio::select! {
                    r = async {
                        if need_out {
                            client.writable().await
                        } else {
                            server.readable().await
                        }
                    } => r.map(|_| true),
                    () = closing.notified(), if closing_by.is_none() => Ok(false),
                }
            };
            match tokio::time::timeout_at(deadline.into(), wait).await {
                Ok(r) => {
                    r.map_err(|e| e.to_string())?;
                }
                Err(_) if closing_by.is_some() => {
                    let asked = close.lock().take();
                    let (code, why) = asked.unwrap_or_default();
                    return Err(format!("closed ({code}: {why}) in the middle of a frame"));
                }
                Err(_) => {
                    return Err(format!(
                        "took no byte for {WRITE_TIMEOUT:?} with a frame waiting; disconnected"
                    ));
                }
            }
        }
        if data {
            door.stats.sent.fetch_add(1, Ordering::Relaxed);
        }
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
    fn tokens_from_the_url_or_the_header() {
        let h = "GET /?a=1&token=s%20e+c HTTP/1.1\r\nHost: x\r\n\r\n";
        assert_eq!(presented_token(h).as_deref(), Some("s e c"));
        let h = "GET / HTTP/1.1\r\nauthorization: Bearer abc\r\n\r\n";
        assert_eq!(presented_token(h).as_deref(), Some("abc"));
        assert_eq!(presented_token("GET / HTTP/1.1\r\n\r\n"), None);
        assert!(
            same_secret("abc", "abc") && !same_secret("abc", "abd") && !same_secret("ab", "abc")
        );
    }
}
