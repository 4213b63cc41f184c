//! The port users connect to: a thin WebSocket relay in front of the SDK's server.
//!
//! The SDK's server (bound to an ephemeral loopback port) accepts only the
//! subprotocols `foxglove.sdk.v1` and `foxglove.sdk.v1.1`, while the official npm
//! client `@foxglove/ws-protocol` 0.8.0 and Lichtblick offer only
//! `foxglove.websocket.v1` (the same messages under the protocol's older name; the
//! client checks that the server answers with that exact name). For each connection
//! the relay
//!
//! 1. reads the HTTP upgrade request (at most [`MAX_HEAD`] bytes within
//!    [`HEAD_TIMEOUT`]; anything else is answered `400` and closed);
//! 2. when the client offers `foxglove.websocket.v1` and no `foxglove.sdk.v1*`,
//!    asks the SDK for `foxglove.sdk.v1` and answers the client with
//!    `foxglove.websocket.v1` (the frames that follow are the same protocol);
//!    offers of `foxglove.sdk.v1*` pass unchanged;
//! 3. relays frames both ways, frame by frame (RFC 6455 headers are parsed, payloads
//!    copied):
//!    - client → server: a frame (or a fragmented message) over `max_message` bytes
//!      closes the connection with status 1009 ("message too big") and a log line;
//!    - server → client: frames wait in a bounded queue per client. When a client
//!      does not read and `max_queue` message-data frames are waiting, the oldest
//!      message-data frame is dropped and counted (the client's and the service's
//!      `dropped`, shown by `ps`); control frames (advertise, status, service
//!      responses) are never dropped, and a client whose queue holds over
//!      [`MAX_QUEUED_BYTES`] of them is disconnected. The SDK, the robot and the
//!      other clients never wait for a slow client.

use std::{
    collections::VecDeque,
    net::SocketAddr,
    sync::{
        Arc,
        atomic::{AtomicU64, AtomicUsize, Ordering},
    },
    time::Duration,
};

use parking_lot::Mutex;
use tokio::{
    io::{AsyncRead, AsyncReadExt, AsyncWriteExt},
    net::{TcpListener, TcpStream},
    sync::Notify,
};

/// The longest HTTP upgrade request or response head.
pub const MAX_HEAD: usize = 16 * 1024;
/// How long a client may take to send its upgrade request.
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(5);
/// How long one frame's write to a client that reads nothing may take.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(30);
/// Control frames (never dropped) a client may leave unread before it is closed.
pub const MAX_QUEUED_BYTES: usize = 64 * 1024 * 1024;

/// The protocol's older name, which `@foxglove/ws-protocol` and Lichtblick offer.
pub const LEGACY: &str = "foxglove.websocket.v1";
/// The SDK's name of the same protocol.
pub const SDK: &str = "foxglove.sdk.v1";

/// Counters of the relay (all clients), for `ps` and the benchmark.
#[derive(Default)]
pub struct RelayStats {
    /// Clients connected now (upgraded).
    pub clients: AtomicUsize,
    /// Connections accepted so far.
    pub accepted: AtomicU64,
    /// Connections refused or closed for a bad request or an oversized message.
    pub refused: AtomicU64,
    /// Message-data frames sent to clients.
    pub sent: AtomicU64,
    /// Message-data frames dropped for slow clients.
    pub dropped: AtomicU64,
}

/// The relay's limits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    pub max_queue: usize,
    pub max_message: usize,
}

/// Accepts on `listener` and relays each connection to the SDK's server at `inner`.
pub async fn accept_loop(
    listener: TcpListener,
    inner: SocketAddr,
    limits: Limits,
    stats: Arc<RelayStats>,
) {
    loop {
        let (client, peer) = match listener.accept().await {
            Ok(c) => c,
            Err(e) => {
                tracing::warn!("foxglove: accept failed: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        stats.accepted.fetch_add(1, Ordering::Relaxed);
        let stats = stats.clone();
        tokio::spawn(async move {
            if let Err(why) = connection(client, inner, limits, &stats).await {
                stats.refused.fetch_add(1, Ordering::Relaxed);
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
        if let Some(end) = find(&buf, b"\r\n\r\n") {
            let rest = buf.split_off(end + 4);
            return Ok((buf, rest));
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

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// The subprotocols a request head offers (every `Sec-WebSocket-Protocol` line).
pub fn offered(head: &str) -> Vec<String> {
    head.lines()
        .filter_map(|l| l.split_once(':'))
        .filter(|(k, _)| k.trim().eq_ignore_ascii_case("sec-websocket-protocol"))
        .flat_map(|(_, v)| v.split(',').map(|p| p.trim().to_string()))
        .filter(|p| !p.is_empty())
        .collect()
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

async fn refuse(client: &mut TcpStream, why: &str) {
    let body = format!("{why}\n");
    let reply = format!(
        "HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    let _ = client.write_all(reply.as_bytes()).await;
    let _ = client.shutdown().await;
}

async fn connection(
    mut client: TcpStream,
    inner: SocketAddr,
    limits: Limits,
    stats: &RelayStats,
) -> Result<(), String> {
    let _ = client.set_nodelay(true);
    let (head, early) = match tokio::time::timeout(HEAD_TIMEOUT, read_head(&mut client)).await {
        Ok(Ok(h)) => h,
        Ok(Err(why)) => {
            refuse(&mut client, &why).await;
            return Err(why);
        }
        Err(_) => {
            let why = format!("no HTTP upgrade request within {HEAD_TIMEOUT:?}");
            refuse(&mut client, &why).await;
            return Err(why);
        }
    };
    let Ok(head) = String::from_utf8(head) else {
        refuse(&mut client, "the HTTP head is not text").await;
        return Err("sent a head that is not text".into());
    };
    if !head.starts_with("GET ") {
        refuse(&mut client, "expected a WebSocket upgrade request (GET)").await;
        return Err("sent something that is not a WebSocket upgrade request".into());
    }
    let (to_sdk, legacy) = rewrite_request(&head);
    let mut server = TcpStream::connect(inner)
        .await
        .map_err(|e| format!("cannot reach the SDK's server at {inner}: {e}"))?;
    let _ = server.set_nodelay(true);
    server
        .write_all(to_sdk.as_bytes())
        .await
        .map_err(|e| e.to_string())?;
    server.write_all(&early).await.map_err(|e| e.to_string())?;
    let (reply, server_early) = read_head(&mut server).await?;
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
        let _ = server.read_to_end(&mut rest).await;
        let _ = client.write_all(&rest).await;
        let _ = client.shutdown().await;
        return Err(format!(
            "refused by the SDK's server: {} (offered subprotocols: {})",
            reply.lines().next().unwrap_or(""),
            offered(&head).join(", ")
        ));
    }
    stats.clients.fetch_add(1, Ordering::Relaxed);
    let r = relay(client, server, server_early, limits, stats).await;
    stats.clients.fetch_sub(1, Ordering::Relaxed);
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

/// Reads one whole frame header from `r` into `hdr` (cleared first).
async fn read_header<R: AsyncRead + Unpin>(
    r: &mut R,
    hdr: &mut Vec<u8>,
    pending: &mut Vec<u8>,
) -> std::io::Result<Option<(bool, u8, bool, u64)>> {
    loop {
        if let Some((fin, op, masked, len, at)) = parse_header(pending) {
            hdr.clear();
            hdr.extend_from_slice(&pending[..at]);
            pending.drain(..at);
            return Ok(Some((fin, op, masked, len)));
        }
        let mut b = [0u8; 14];
        let n = r.read(&mut b).await?;
        if n == 0 {
            return Ok(None);
        }
        pending.extend_from_slice(&b[..n]);
    }
}

/// Reads `len` payload bytes (some may be in `pending` already) onto `out`.
async fn read_payload<R: AsyncRead + Unpin>(
    r: &mut R,
    pending: &mut Vec<u8>,
    len: usize,
    out: &mut Vec<u8>,
) -> std::io::Result<()> {
    let have = pending.len().min(len);
    out.extend_from_slice(&pending[..have]);
    pending.drain(..have);
    // Read into spare capacity (no zero-filling of a frame's bytes first).
    let end = out.len() + (len - have);
    out.reserve(end - out.len());
    while out.len() < end {
        let want = end - out.len();
        let n = (&mut *r).take(want as u64).read_buf(out).await?;
        if n == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
    }
    Ok(())
}

/// A close frame from the server side (unmasked) with `code` and `reason`.
fn close_frame(code: u16, reason: &str) -> Vec<u8> {
    let reason = &reason.as_bytes()[..reason.len().min(120)];
    let mut f = vec![0x88, (2 + reason.len()) as u8];
    f.extend_from_slice(&code.to_be_bytes());
    f.extend_from_slice(reason);
    f
}

/// A frame waiting for its client.
struct Queued {
    bytes: Vec<u8>,
    /// A message-data frame (may be dropped for a slow client).
    data: bool,
}

#[derive(Default)]
struct Outbox {
    frames: VecDeque<Queued>,
    /// Message-data frames waiting.
    data: usize,
    /// Bytes of the other frames waiting.
    control: usize,
    closed: bool,
    /// Written frames' buffers, kept for the next frames (no allocation and no
    /// fresh pages for each 900 kB image).
    spare: Vec<Vec<u8>>,
}

/// Buffers kept per connection for reuse.
const SPARE: usize = 4;

/// Relays an upgraded connection until either side closes.
async fn relay(
    client: TcpStream,
    server: TcpStream,
    server_early: Vec<u8>,
    limits: Limits,
    stats: &RelayStats,
) -> Result<(), String> {
    let (mut crd, mut cwr) = client.into_split();
    let (mut srd, mut swr) = server.into_split();
    let outbox = Arc::new(Mutex::new(Outbox::default()));
    let wake = Arc::new(Notify::new());

    // Server → outbox.
    let from_server = {
        let outbox = outbox.clone();
        let wake = wake.clone();
        async move {
            let mut pending = server_early;
            let mut hdr = Vec::with_capacity(14);
            loop {
                let Some((fin, op, _, len)) = read_header(&mut srd, &mut hdr, &mut pending)
                    .await
                    .map_err(|e| e.to_string())?
                else {
                    return Ok::<_, String>(());
                };
                let mut frame = outbox.lock().spare.pop().unwrap_or_default();
                frame.clear();
                frame.extend_from_slice(&hdr);
                read_payload(&mut srd, &mut pending, len as usize, &mut frame)
                    .await
                    .map_err(|e| e.to_string())?;
                // Binary opcode 0x01 is the protocol's Message Data; only whole
                // (unfragmented) ones are dropped.
                let data = fin && op == 0x2 && frame.get(hdr.len()) == Some(&0x01);
                let mut o = outbox.lock();
                if o.closed {
                    return Ok(());
                }
                if data
                    && o.data >= limits.max_queue
                    && let Some(i) = o.frames.iter().position(|f| f.data)
                {
                    o.frames.remove(i);
                    o.data -= 1;
                    stats.dropped.fetch_add(1, Ordering::Relaxed);
                }
                if data {
                    o.data += 1;
                } else {
                    o.control += frame.len();
                    if o.control > MAX_QUEUED_BYTES {
                        o.closed = true;
                        drop(o);
                        wake.notify_one();
                        return Err(format!(
                            "left over {MAX_QUEUED_BYTES} bytes of control messages unread; disconnected"
                        ));
                    }
                }
                o.frames.push_back(Queued { bytes: frame, data });
                drop(o);
                wake.notify_one();
            }
        }
    };

    // Outbox → client.
    let to_client = {
        let outbox = outbox.clone();
        let wake = wake.clone();
        async move {
            loop {
                let next = {
                    let mut o = outbox.lock();
                    match o.frames.pop_front() {
                        Some(f) => {
                            if f.data {
                                o.data -= 1;
                            } else {
                                o.control = o.control.saturating_sub(f.bytes.len());
                            }
                            Some(f)
                        }
                        None if o.closed => return Ok::<_, String>(()),
                        None => None,
                    }
                };
                match next {
                    Some(f) => {
                        match tokio::time::timeout(WRITE_TIMEOUT, cwr.write_all(&f.bytes)).await {
                            Ok(r) => r.map_err(|e| e.to_string())?,
                            Err(_) => {
                                return Err(format!(
                                    "read nothing for {WRITE_TIMEOUT:?}; disconnected"
                                ));
                            }
                        }
                        if f.data {
                            stats.sent.fetch_add(1, Ordering::Relaxed);
                        }
                        let mut o = outbox.lock();
                        if o.spare.len() < SPARE && f.bytes.capacity() <= 16 << 20 {
                            o.spare.push(f.bytes);
                        }
                    }
                    None => wake.notified().await,
                }
            }
        }
    };

    // Client → server, with the message size limit.
    let from_client = {
        let outbox = outbox.clone();
        let wake = wake.clone();
        async move {
            let mut pending = Vec::new();
            let mut hdr = Vec::with_capacity(14);
            let mut message = 0u64;
            let mut buf = Vec::new();
            loop {
                let Some((fin, op, masked, len)) = read_header(&mut crd, &mut hdr, &mut pending)
                    .await
                    .map_err(|e| e.to_string())?
                else {
                    return Ok::<_, String>(());
                };
                if !masked {
                    let why = "sent an unmasked frame (RFC 6455 5.1)";
                    outbox.lock().frames.push_back(Queued {
                        bytes: close_frame(1002, why),
                        data: false,
                    });
                    outbox.lock().closed = true;
                    wake.notify_one();
                    return Err(why.into());
                }
                if op < 0x8 {
                    message = if op == 0 { message + len } else { len };
                }
                if message > limits.max_message as u64 || len > limits.max_message as u64 {
                    let why = format!(
                        "sent a message of over {} bytes (the `max_message` line); disconnected",
                        limits.max_message
                    );
                    {
                        let mut o = outbox.lock();
                        o.frames.push_back(Queued {
                            bytes: close_frame(1009, "message too big"),
                            data: false,
                        });
                        o.closed = true;
                    }
                    wake.notify_one();
                    return Err(why);
                }
                if fin && op < 0x8 {
                    message = 0;
                }
                buf.clear();
                buf.extend_from_slice(&hdr);
                read_payload(&mut crd, &mut pending, len as usize, &mut buf)
                    .await
                    .map_err(|e| e.to_string())?;
                swr.write_all(&buf).await.map_err(|e| e.to_string())?;
            }
        }
    };

    let readers = async {
        let r = tokio::select! {
            r = from_server => r,
            r = from_client => r,
        };
        outbox.lock().closed = true;
        wake.notify_one();
        r
    };
    tokio::pin!(readers);
    tokio::pin!(to_client);
    tokio::select! {
        r = &mut to_client => r,
        r = &mut readers => {
            // Let a close frame queued by a reader go out, briefly.
            let _ = tokio::time::timeout(Duration::from_secs(1), &mut to_client).await;
            r
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
}
