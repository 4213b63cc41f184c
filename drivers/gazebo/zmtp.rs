//! A minimal ZMTP 3.0 (ZeroMQ's wire, rfc.zeromq.org/spec/23) over TCP with the NULL
//! mechanism: the two ends gz-transport's topics need, a SUB connection to a
//! publisher and a PUB listener for subscribers. Non-blocking sockets polled by the
//! caller; every message is bounded as a whole ([`MAX_MESSAGE`]: all its frames
//! together) and the buffer grows only with bytes that arrived, so a peer sending
//! garbage is dropped with the reason, never allowed to make us allocate without
//! limit. Connects are non-blocking to IP literals only (no name resolution: a
//! gz-transport node advertises its IP address), and a connection not greeted
//! within [`GREETING_TIME`] is given up.

use std::{
    io::{self, Read, Write},
    net::{TcpListener, TcpStream},
    os::fd::{AsRawFd, RawFd},
};

/// The largest message accepted, all its frames together (a 4K RGBA image is 33 MB).
pub const MAX_MESSAGE: u64 = 64 << 20;
/// How long a connection may take to connect and greet.
pub const GREETING_TIME: std::time::Duration = std::time::Duration::from_secs(2);
/// The most subscribers our PUB socket keeps, and topic prefixes per subscriber.
pub const MAX_SUBS: usize = 64;
const MAX_PREFIXES: usize = 32;
/// The most frames of one message (gz-transport sends 4 or 5).
const MAX_PARTS: usize = 16;

/// Our greeting: signature, version 3.0, NULL mechanism, as-server 0, filler.
pub fn greeting() -> [u8; 64] {
    let mut g = [0u8; 64];
    g[0] = 0xff;
    g[9] = 0x7f;
    g[10] = 3;
    g[11] = 0;
    g[12..16].copy_from_slice(b"NULL");
    g
}

/// A READY command with `Socket-Type`.
pub fn ready(socket_type: &str) -> Vec<u8> {
    let mut body = vec![5];
    body.extend_from_slice(b"READY");
    body.push(11);
    body.extend_from_slice(b"Socket-Type");
    body.extend_from_slice(&(socket_type.len() as u32).to_be_bytes());
    body.extend_from_slice(socket_type.as_bytes());
    let mut f = vec![0x04, body.len() as u8];
    f.extend_from_slice(&body);
    f
}

/// Appends one frame.
pub fn frame(out: &mut Vec<u8>, more: bool, data: &[u8]) {
    let m = if more { 1 } else { 0 };
    if data.len() < 256 {
        out.push(m);
        out.push(data.len() as u8);
    } else {
        out.push(m | 2);
        out.extend_from_slice(&(data.len() as u64).to_be_bytes());
    }
    out.extend_from_slice(data);
}

/// What one connection read: whole messages (or commands).
pub enum Item {
    Message(Vec<Vec<u8>>),
    Command(Vec<u8>),
}

/// The reading half of a connection: bytes in, whole messages out, with no
/// socket, so the framing is also callable on bytes (the fuzz target of
/// `tests/fuzz.rs` feeds it). The buffer grows only with bytes that arrived,
/// to one whole message at most.
pub struct Framer {
    /// Received bytes: `inbuf[start..end]` is not parsed yet.
    inbuf: Vec<u8>,
    start: usize,
    end: usize,
    greeted: bool,
    ready: bool,
    parts: Vec<Vec<u8>>,
    /// The bytes of `parts` so far (the message's size is capped as a whole).
    parts_bytes: u64,
    /// The peer's address (for messages).
    peer: String,
}

/// One ZMTP connection, either end; reading is incremental.
pub struct Conn {
    pub stream: TcpStream,
    framer: Framer,
    outbuf: Vec<u8>,
    /// Until when the peer may take to connect and greet (None: greeted).
    pub greet_by: Option<std::time::Instant>,
    /// The peer's address (for messages).
    pub peer: String,
}

impl Conn {
    fn new(stream: TcpStream, socket_type: &str, peer: String) -> io::Result<Conn> {
        stream.set_nodelay(true)?;
        stream.set_nonblocking(true)?;
        let mut c = Conn {
            stream,
            framer: Framer::new(peer.clone()),
            outbuf: Vec::new(),
            greet_by: Some(std::time::Instant::now() + GREETING_TIME),
            peer,
        };
        c.outbuf.extend_from_slice(&greeting());
        c.outbuf.extend_from_slice(&ready(socket_type));
        c.flush()?;
        Ok(c)
    }

    /// Starts connecting to `tcp://IP:PORT` as a SUB socket, without waiting: the
    /// caller's poll sees it connect (or fail), and [`GREETING_TIME`] bounds it.
    /// Only IP literals: no name is resolved (that could block for seconds).
    pub fn connect_sub(endpoint: &str) -> io::Result<Conn> {
        let sa = endpoint_addr(endpoint)?;
        let s = socket2::Socket::new(
            socket2::Domain::for_address(sa),
            socket2::Type::STREAM,
            Some(socket2::Protocol::TCP),
        )?;
        s.set_nonblocking(true)?;
        match s.connect(&sa.into()) {
            Ok(()) => {}
            Err(e)
                if e.raw_os_error() == Some(libc::EINPROGRESS)
                    || e.kind() == io::ErrorKind::WouldBlock => {}
            Err(e) => return Err(e),
        }
        Conn::new(s.into(), "SUB", endpoint.into())
    }

    /// Whether the peer has not connected and greeted in time.
    pub fn greeting_late(&self, now: std::time::Instant) -> bool {
        self.greet_by.is_some_and(|t| now > t)
    }

    pub fn fd(&self) -> RawFd {
        self.stream.as_raw_fd()
    }

    pub fn wants_write(&self) -> bool {
        !self.outbuf.is_empty()
    }

    /// Writes what is queued, as far as the socket takes it.
    pub fn flush(&mut self) -> io::Result<()> {
        while !self.outbuf.is_empty() {
            match self.stream.write(&self.outbuf) {
                Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
                Ok(n) => {
                    self.outbuf.drain(..n);
                }
                // Still connecting (a non-blocking connect): written once it is.
                Err(e)
                    if e.kind() == io::ErrorKind::WouldBlock
                        || e.kind() == io::ErrorKind::NotConnected =>
                {
                    return Ok(());
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// Queues a message of several frames. A subscriber that cannot keep up
    /// (over `cap` bytes queued) loses the message, as ZeroMQ's high-water mark does.
    pub fn send(&mut self, parts: &[&[u8]], cap: usize) -> io::Result<()> {
        if !self.framer.ready || self.outbuf.len() > cap {
            return Ok(());
        }
        for (i, p) in parts.iter().enumerate() {
            frame(&mut self.outbuf, i + 1 < parts.len(), p);
        }
        self.flush()
    }

    /// A SUB's subscription to a topic prefix (ZMTP 3.0: a message `\x01PREFIX`).
    pub fn subscribe(&mut self, prefix: &[u8]) -> io::Result<()> {
        let mut m = vec![1];
        m.extend_from_slice(prefix);
        frame(&mut self.outbuf, false, &m);
        self.flush()
    }

    /// Reads what has arrived; `Ok(false)` when the peer closed.
    pub fn read_some(&mut self) -> io::Result<bool> {
        loop {
            let room = self.framer.room();
            if room.is_empty() {
                // The rest waits in the socket until next_item took what is here.
                return Ok(true);
            }
            match self.stream.read(room) {
                Ok(0) => return Ok(false),
                Ok(n) => self.framer.filled(n),
                Err(e) => {
                    return match e.kind() {
                        io::ErrorKind::WouldBlock | io::ErrorKind::NotConnected => Ok(true),
                        io::ErrorKind::Interrupted => continue,
                        _ => Err(e),
                    };
                }
            }
        }
    }

    /// The next whole message or command read, if any.
    pub fn next_item(&mut self) -> io::Result<Option<Item>> {
        let item = self.framer.next_item();
        if self.framer.greeted {
            self.greet_by = None;
        }
        item
    }
}

impl Framer {
    /// A framer for bytes from `peer` (named in its errors), before the greeting.
    pub fn new(peer: String) -> Framer {
        Framer {
            inbuf: Vec::new(),
            start: 0,
            end: 0,
            greeted: false,
            ready: false,
            parts: Vec::new(),
            parts_bytes: 0,
            peer,
        }
    }

    /// Where the next bytes go: empty when one whole message and its frame heads
    /// are buffered already.
    fn room(&mut self) -> &mut [u8] {
        if self.end == self.inbuf.len() {
            self.compact();
            if self.end == self.inbuf.len() {
                let most = MAX_MESSAGE as usize + (1 << 20);
                let n = (self.inbuf.len() * 2).clamp(1 << 16, most);
                self.inbuf.resize(n, 0);
            }
        }
        &mut self.inbuf[self.end..]
    }

    /// `n` bytes were written into [`room`](Self::room).
    fn filled(&mut self, n: usize) {
        self.end += n;
    }

    /// Takes what fits of `b` (all of it, unless a whole message is waiting to be
    /// read with [`next_item`](Self::next_item)): the bytes taken.
    pub fn feed(&mut self, b: &[u8]) -> usize {
        let mut taken = 0;
        while taken < b.len() {
            let room = self.room();
            if room.is_empty() {
                break;
            }
            let n = room.len().min(b.len() - taken);
            room[..n].copy_from_slice(&b[taken..taken + n]);
            self.filled(n);
            taken += n;
        }
        taken
    }

    /// Moves the unparsed bytes to the front.
    fn compact(&mut self) {
        if self.start > 0 {
            self.inbuf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
        }
    }

    fn bad(m: String) -> io::Error {
        io::Error::new(io::ErrorKind::InvalidData, m)
    }

    /// The next whole message or command in the bytes fed, if any.
    pub fn next_item(&mut self) -> io::Result<Option<Item>> {
        loop {
            if self.start == self.end {
                (self.start, self.end) = (0, 0);
                // A big message passed: give its memory back.
                if self.inbuf.len() > 8 << 20 {
                    self.inbuf = Vec::new();
                }
            }
            let buf = &self.inbuf[self.start..self.end];
            if !self.greeted {
                if buf.len() < 64 {
                    return Ok(None);
                }
                if buf[0] != 0xff || buf[9] & 1 != 1 {
                    return Err(Self::bad(format!("{}: not a ZeroMQ peer", self.peer)));
                }
                if buf[10] < 3 {
                    return Err(Self::bad(format!(
                        "{}: ZMTP {}.x is too old (3.0 or later wanted)",
                        self.peer, buf[10]
                    )));
                }
                if &buf[12..16] != b"NULL" {
                    return Err(Self::bad(format!(
                        "{}: the peer wants a security mechanism (only NULL is spoken; unset IGN_TRANSPORT_USERNAME/PASSWORD)",
                        self.peer
                    )));
                }
                self.greeted = true;
                self.start += 64;
                continue;
            }
            if buf.len() < 2 {
                return Ok(None);
            }
            let flags = buf[0];
            if flags & 0xf8 != 0 {
                return Err(Self::bad(format!(
                    "{}: bad frame flags {flags:#x}",
                    self.peer
                )));
            }
            let (size, head) = if flags & 2 != 0 {
                if buf.len() < 9 {
                    return Ok(None);
                }
                (u64::from_be_bytes(buf[1..9].try_into().expect("8")), 9)
            } else {
                (buf[1] as u64, 2)
            };
            // The whole message is capped, not each frame: unfinished MORE frames
            // count together.
            let total = self.parts_bytes.saturating_add(size);
            if total > MAX_MESSAGE {
                return Err(Self::bad(format!(
                    "{}: a message of {total} bytes or more (at most {MAX_MESSAGE})",
                    self.peer
                )));
            }
            let size = size as usize;
            if buf.len() < head + size {
                // The buffer grows as the bytes arrive (read_some), never ahead of them.
                return Ok(None);
            }
            let body = buf[head..head + size].to_vec();
            self.start += head + size;
            if flags & 4 != 0 {
                if body.starts_with(b"\x05READY") {
                    self.ready = true;
                }
                return Ok(Some(Item::Command(body)));
            }
            self.parts_bytes += body.len() as u64;
            self.parts.push(body);
            if self.parts.len() > MAX_PARTS {
                return Err(Self::bad(format!(
                    "{}: a message of more than {MAX_PARTS} frames",
                    self.peer
                )));
            }
            if flags & 1 == 0 {
                self.parts_bytes = 0;
                return Ok(Some(Item::Message(std::mem::take(&mut self.parts))));
            }
        }
    }
}

/// `tcp://IP:PORT` as an address: an IP literal (v4 or `[v6]`), never a name.
pub fn endpoint_addr(endpoint: &str) -> io::Result<std::net::SocketAddr> {
    let invalid = |m: String| io::Error::new(io::ErrorKind::InvalidInput, m);
    let addr = endpoint
        .strip_prefix("tcp://")
        .ok_or_else(|| invalid(format!("{endpoint}: not a tcp:// endpoint")))?;
    addr.parse().map_err(|_| {
        invalid(format!(
            "{endpoint}: not an IP address and port (names are not resolved)"
        ))
    })
}

/// A PUB socket: a listener and the subscribers connected to it, each with the
/// prefixes it subscribed to.
pub struct Pub {
    pub listener: TcpListener,
    pub endpoint: String,
    pub subs: Vec<(Conn, Vec<Vec<u8>>)>,
    /// The cap was said (again once it has room).
    full_said: bool,
    /// Counts changes of the subscribers and their prefixes.
    pub changes: u64,
}

impl Pub {
    pub fn bind(ip: &str) -> io::Result<Pub> {
        let listener = TcpListener::bind((ip, 0))?;
        listener.set_nonblocking(true)?;
        let endpoint = format!("tcp://{}", listener.local_addr()?);
        Ok(Pub {
            listener,
            endpoint,
            subs: Vec::new(),
            full_said: false,
            changes: 0,
        })
    }

    /// Accepts new subscribers and reads their subscriptions; drops the broken.
    /// At most [`MAX_SUBS`]: when full, the oldest one that subscribed to nothing
    /// makes room, else the newcomer is refused (one line each time it fills).
    pub fn serve(&mut self) {
        let mut accepted = 0;
        while let Ok((s, a)) = self.listener.accept() {
            accepted += 1;
            if self.subs.len() >= MAX_SUBS {
                match self.subs.iter().position(|(_, ps)| ps.is_empty()) {
                    Some(k) => {
                        self.subs.remove(k);
                    }
                    None => {
                        if !self.full_said {
                            self.full_said = true;
                            tracing::warn!(
                                "gazebo: {MAX_SUBS} subscribers are connected to our topics; refusing {a} and more"
                            );
                        }
                        continue;
                    }
                }
            }
            if let Ok(c) = Conn::new(s, "PUB", a.to_string()) {
                self.subs.push((c, Vec::new()));
                self.changes += 1;
            }
            // A connect flood does not hold the thread: the rest wait for the next call.
            if accepted >= 16 {
                break;
            }
        }
        if self.subs.len() < MAX_SUBS / 2 {
            self.full_said = false;
        }
        let now = std::time::Instant::now();
        let before = self.subs.iter().map(|(_, ps)| ps.len()).sum::<usize>() + self.subs.len();
        self.subs.retain_mut(|(c, prefixes)| {
            if c.flush().is_err() || c.greeting_late(now) {
                return false;
            }
            let open = matches!(c.read_some(), Ok(true));
            loop {
                match c.next_item() {
                    Ok(Some(Item::Message(m))) => {
                        if let Some(f) = m.first() {
                            match f.first() {
                                Some(1) if prefixes.len() < MAX_PREFIXES => {
                                    prefixes.push(f[1..].to_vec())
                                }
                                Some(0) => prefixes.retain(|p| p[..] != f[1..]),
                                _ => {}
                            }
                        }
                    }
                    Ok(Some(Item::Command(b))) => {
                        // ZMTP 3.1's SUBSCRIBE / CANCEL commands.
                        if let Some(t) = b.strip_prefix(b"\x09SUBSCRIBE") {
                            if prefixes.len() < MAX_PREFIXES {
                                prefixes.push(t.to_vec());
                            }
                        } else if let Some(t) = b.strip_prefix(b"\x06CANCEL") {
                            prefixes.retain(|p| p[..] != *t);
                        }
                    }
                    Ok(None) => return open,
                    Err(_) => return false,
                }
            }
        });
        let after = self.subs.iter().map(|(_, ps)| ps.len()).sum::<usize>() + self.subs.len();
        if after != before {
            self.changes += 1;
        }
    }

    /// For each greeted subscriber of one of `msgs`' topics (each message's
    /// first frame): a second handle on its connection and those messages,
    /// framed, for a write of their own (the emergency stop).
    pub fn stop_targets(&self, msgs: &[Vec<&[u8]>]) -> Vec<(TcpStream, Vec<u8>)> {
        let mut out = Vec::new();
        for (c, ps) in &self.subs {
            let mut bytes = Vec::new();
            for m in msgs {
                let topic = m.first().copied().unwrap_or_default();
                if c.framer.ready && ps.iter().any(|p| topic.starts_with(p)) {
                    for (i, part) in m.iter().enumerate() {
                        frame(&mut bytes, i + 1 < m.len(), part);
                    }
                }
            }
            if !bytes.is_empty()
                && let Ok(s) = c.stream.try_clone()
            {
                out.push((s, bytes));
            }
        }
        out
    }

    /// Whether some subscriber subscribed to a prefix of `topic`.
    pub fn has_subscriber(&self, topic: &[u8]) -> bool {
        self.subs
            .iter()
            .any(|(_, ps)| ps.iter().any(|p| topic.starts_with(p)))
    }

    /// Sends a message whose first frame is `parts[0]` to the subscribers of it.
    pub fn send(&mut self, parts: &[&[u8]]) {
        let topic = parts.first().copied().unwrap_or_default();
        for (c, ps) in &mut self.subs {
            if ps.iter().any(|p| topic.starts_with(p)) {
                let _ = c.send(parts, 8 << 20);
            }
        }
    }
}
