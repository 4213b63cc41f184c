//! A Player 3 TCP connection: the banner, message framing, sends, and requests
//! answered by ACK or NACK within a timeout.

use std::{
    io::{self, Read, Write},
    net::{SocketAddr, TcpStream, ToSocketAddrs},
    time::{Duration, Instant},
};

use super::xdr::{self, Addr, HEADER_LEN, Header, XdrError, msg};

/// Why a connection is no good any more (it is dropped and reopened).
#[derive(Debug, thiserror::Error)]
pub enum ConnError {
    #[error("cannot connect: {0}")]
    Connect(io::Error),
    #[error("{0}")]
    Io(#[from] io::Error),
    #[error("the server closed the connection")]
    Closed,
    #[error("malformed message from the server: {0}")]
    Malformed(#[from] XdrError),
    #[error("{0}")]
    Protocol(String),
    #[error("no reply to {what} within {ms} ms")]
    Timeout { what: String, ms: u128 },
}

/// The answer to a request.
pub enum Reply {
    Ack(Vec<u8>),
    Nack,
}

/// A received message: header and payload (borrowed from the read buffer).
pub type OnMessage<'a> = &'a mut dyn FnMut(&Header, &[u8]) -> Result<(), XdrError>;

pub struct Conn {
    stream: TcpStream,
    buf: Vec<u8>,
    /// Start of the unread bytes in `buf`.
    off: usize,
    seq: u32,
    out: Vec<u8>,
    pub version: String,
    /// When the last whole message arrived.
    pub last_message: Instant,
    read_timeout: Option<Duration>,
}

/// Resolves `host:port`.
pub fn resolve(host: &str, port: u16) -> io::Result<Vec<SocketAddr>> {
    Ok((host, port).to_socket_addrs()?.collect())
}

impl Conn {
    /// Connects and reads the 32-byte banner.
    pub fn open(host: &str, port: u16, timeout: Duration) -> Result<Conn, ConnError> {
        let addrs = resolve(host, port).map_err(ConnError::Connect)?;
        let mut last = io::Error::new(io::ErrorKind::NotFound, "the name has no address");
        let mut stream = None;
        for a in addrs {
            match TcpStream::connect_timeout(&a, timeout) {
                Ok(s) => {
                    stream = Some(s);
                    break;
                }
                Err(e) => last = e,
            }
        }
        let stream = stream.ok_or(ConnError::Connect(last))?;
        stream.set_nodelay(true)?;
        stream.set_read_timeout(Some(timeout))?;
        stream.set_write_timeout(Some(timeout))?;
        let mut banner = [0u8; xdr::BANNER_LEN];
        (&stream).read_exact(&mut banner).map_err(|e| {
            if matches!(
                e.kind(),
                io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
            ) {
                ConnError::Protocol(format!(
                    "no Player banner within {} ms (is it a Player server?)",
                    timeout.as_millis()
                ))
            } else if e.kind() == io::ErrorKind::UnexpectedEof {
                ConnError::Closed
            } else {
                ConnError::Io(e)
            }
        })?;
        let version = xdr::banner_version(&banner).ok_or_else(|| {
            ConnError::Protocol(format!(
                "the server's first 32 bytes are not a Player banner (`Player v.…`): {:?}",
                String::from_utf8_lossy(&banner)
            ))
        })?;
        Ok(Conn {
            stream,
            buf: Vec::with_capacity(64 * 1024),
            off: 0,
            seq: 0,
            out: Vec::with_capacity(256),
            version,
            last_message: Instant::now(),
            read_timeout: Some(timeout),
        })
    }

    /// Sends one message.
    pub fn send(
        &mut self,
        addr: Addr,
        mtype: u32,
        subtype: u32,
        payload: &[u8],
    ) -> Result<u32, ConnError> {
        self.seq = self.seq.wrapping_add(1);
        let seq = self.seq;
        self.out.clear();
        Header::new(addr, mtype, subtype, seq, payload.len()).encode(&mut self.out);
        self.out.extend_from_slice(payload);
        self.stream.write_all(&self.out)?;
        Ok(seq)
    }

    fn set_timeout(&mut self, t: Duration) -> io::Result<()> {
        let t = Some(t.max(Duration::from_micros(100)));
        if self.read_timeout != t {
            self.stream.set_read_timeout(t)?;
            self.read_timeout = t;
        }
        Ok(())
    }

    /// Hands every whole message in the buffer to `on`; returns how many.
    fn drain(&mut self, on: OnMessage) -> Result<usize, ConnError> {
        let mut n = 0;
        loop {
            let avail = self.buf.len() - self.off;
            if avail < HEADER_LEN {
                break;
            }
            let h = Header::decode(&self.buf[self.off..self.off + HEADER_LEN])?;
            let total = HEADER_LEN + h.size as usize;
            if avail < total {
                break;
            }
            let start = self.off + HEADER_LEN;
            on(&h, &self.buf[start..start + h.size as usize])?;
            self.off += total;
            n += 1;
        }
        if n > 0 {
            self.last_message = Instant::now();
        }
        if self.off == self.buf.len() {
            self.buf.clear();
            self.off = 0;
        } else if self.off > 0 && self.off >= self.buf.len() / 2 {
            self.buf.drain(..self.off);
            self.off = 0;
        }
        Ok(n)
    }

    /// Reads what arrives within `wait` (at least one read) and hands whole
    /// messages to `on`. Returns how many messages were handled (0 on timeout).
    /// The buffer grows only with bytes that really arrived, so a header that
    /// announces a huge size costs nothing until the bytes come.
    pub fn poll(&mut self, wait: Duration, on: OnMessage) -> Result<usize, ConnError> {
        let n = self.drain(on)?;
        if n > 0 {
            return Ok(n);
        }
        self.set_timeout(wait)?;
        let mut chunk = [0u8; 16 * 1024];
        match self.stream.read(&mut chunk) {
            Ok(0) => Err(ConnError::Closed),
            Ok(k) => {
                self.buf.extend_from_slice(&chunk[..k]);
                self.drain(on)
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                Ok(0)
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => Ok(0),
            Err(e) => Err(e.into()),
        }
    }

    /// Sends a request and waits up to `timeout` for its ACK or NACK; messages
    /// that arrive meanwhile go to `on`.
    pub fn request(
        &mut self,
        addr: Addr,
        subtype: u32,
        payload: &[u8],
        timeout: Duration,
        on: OnMessage,
    ) -> Result<Reply, ConnError> {
        let seq = self.send(addr, msg::REQ, subtype, payload)?;
        let deadline = Instant::now() + timeout;
        let mut reply: Option<Reply> = None;
        loop {
            let mut handler = |h: &Header, p: &[u8]| {
                if reply.is_none()
                    && h.addr == addr
                    && h.subtype == subtype
                    && (h.mtype == msg::RESP_ACK || h.mtype == msg::RESP_NACK)
                    && h.seq == seq
                {
                    reply = Some(if h.mtype == msg::RESP_ACK {
                        Reply::Ack(p.to_vec())
                    } else {
                        Reply::Nack
                    });
                    Ok(())
                } else {
                    on(h, p)
                }
            };
            let now = Instant::now();
            if now >= deadline {
                break;
            }
            self.poll(deadline - now, &mut handler)?;
            if reply.is_some() {
                break;
            }
        }
        reply.ok_or_else(|| ConnError::Timeout {
            what: format!("request {subtype} to {addr}"),
            ms: timeout.as_millis(),
        })
    }

    /// A second handle on the socket, for the emergency stop ([`crate::estop`]):
    /// it writes whole messages of its own (each in one write, which the kernel
    /// does not split while the send buffer has room) without the connection's
    /// buffers.
    pub fn stop_handle(&self) -> io::Result<TcpStream> {
        self.stream.try_clone()
    }

    /// Closes the socket.
    pub fn close(&self) {
        let _ = self.stream.shutdown(std::net::Shutdown::Both);
    }

    /// Ends a session politely: no more writes (a FIN after the last commands),
    /// then what the server still sends is read and dropped until it closes too
    /// (at most 300 ms). Closing with unread data resets the connection, and a
    /// server may then lose the commands still in its receive buffer, such as
    /// the zero CMD_VEL that stops the robot.
    pub fn finish(&mut self) {
        let _ = self.stream.shutdown(std::net::Shutdown::Write);
        let _ = self
            .stream
            .set_read_timeout(Some(Duration::from_millis(20)));
        let t0 = Instant::now();
        let mut sink = [0u8; 4096];
        while t0.elapsed() < Duration::from_millis(300) {
            match self.stream.read(&mut sink) {
                Ok(0) => break,
                Ok(_) => {}
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) => {}
                Err(_) => break,
            }
        }
        self.close();
    }
}
