//! A gz-transport node in pure Rust: discovery (UDP multicast on 239.255.0.7:10317,
//! a 2-byte little-endian length and a `Discovery` protobuf, wire version 10 as in
//! gz-transport 8 to 13), topic data over ZeroMQ (our [`zmtp`](super::zmtp)): a
//! SUB connection to each publisher of a topic we want, and one PUB listener for
//! the topics we advertise. A message is the frames `[topic, sender address, data,
//! type name]`, the topic fully qualified as `@/PARTITION@/TOPIC`.
//!
//! As gz-transport's NodeShared does, a subscriber connects to the publisher's
//! address, subscribes to the topic and then registers with the publisher through
//! a NEW_CONNECTION discovery message carrying the publisher's type; a gz
//! publisher sends only to registered subscribers of the same type. Heartbeats
//! every second; a process silent for 3 s (or saying BYE) is gone.

use std::{
    collections::{BTreeMap, HashMap},
    io,
    net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket},
    os::fd::AsRawFd,
    time::{Duration, Instant},
};

use super::pb::{Discovery, Publisher, disc};
use super::zmtp::{Conn, Item, Pub};

pub const GROUP: Ipv4Addr = Ipv4Addr::new(239, 255, 0, 7);
pub const MSG_PORT: u16 = 10317;
pub const WIRE_VERSION: u64 = 10;
const HEARTBEAT: Duration = Duration::from_secs(1);
const SILENCE: Duration = Duration::from_secs(3);
/// The most processes and topics remembered.
const MAX_KNOWN: usize = 10_000;

/// A random version-4 UUID as text (gz-transport's process and node ids).
pub fn uuid() -> String {
    let mut b = [0u8; 16];
    let ok = std::fs::File::open("/dev/urandom")
        .and_then(|mut f| io::Read::read_exact(&mut f, &mut b))
        .is_ok();
    if !ok {
        let t = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default()
            .as_nanos()
            ^ (std::process::id() as u128) << 64;
        b = t.to_le_bytes();
    }
    b[6] = b[6] & 0x0f | 0x40;
    b[8] = b[8] & 0x3f | 0x80;
    let h: String = b.iter().map(|x| format!("{x:02x}")).collect();
    format!(
        "{}-{}-{}-{}-{}",
        &h[0..8],
        &h[8..12],
        &h[12..16],
        &h[16..20],
        &h[20..32]
    )
}

/// gz-transport's default partition: `HOSTNAME:USERNAME`.
pub fn default_partition() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: gethostname writes at most buf.len() bytes into buf.
    let host = if unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) } == 0 {
        let n = buf.iter().position(|&c| c == 0).unwrap_or(buf.len());
        String::from_utf8_lossy(&buf[..n]).into_owned()
    } else {
        String::new()
    };
    // SAFETY: getpwuid returns null or a pointer to a static passwd entry, read at once.
    let user = unsafe {
        let pw = libc::getpwuid(libc::getuid());
        if pw.is_null() || (*pw).pw_name.is_null() {
            None
        } else {
            Some(
                std::ffi::CStr::from_ptr((*pw).pw_name)
                    .to_string_lossy()
                    .into_owned(),
            )
        }
    }
    .or_else(|| std::env::var("USER").ok())
    .unwrap_or_default();
    format!("{host}:{user}")
}

/// `@/PARTITION@/TOPIC`, as gz-transport's TopicUtils::FullyQualifiedName.
pub fn qualify(partition: &str, topic: &str) -> String {
    let mut p = partition.to_string();
    if !p.is_empty() && !p.starts_with('/') {
        p.insert(0, '/');
    }
    if p.ends_with('/') {
        p.pop();
    }
    let mut t = topic.trim_end_matches('/').to_string();
    if !t.starts_with('/') {
        t.insert(0, '/');
    }
    format!("@{p}@{t}")
}

/// The topic of a fully qualified name (`@/P@/T` → `/T`), if it is in `partition`.
pub fn unqualify<'a>(fq: &'a str, qualified_partition: &str) -> Option<&'a str> {
    fq.strip_prefix(qualified_partition)
}

/// A topic we subscribe to.
pub struct Want {
    pub topic: String,
    /// The type names accepted (`ignition.msgs.X`, `gz.msgs.X`).
    pub types: Vec<String>,
    /// The publisher it is bound to.
    pub bound: Option<Publisher>,
    /// A publisher of it under another type (said once per type).
    pub mismatch: Option<String>,
}

/// The node.
pub struct Node {
    udp: UdpSocket,
    group: SocketAddr,
    pub ip: String,
    pub puuid: String,
    nuuid: String,
    /// `@/PARTITION@`
    prefix: String,
    publ: Pub,
    /// Remote publishers by topic.
    remote: BTreeMap<String, Vec<Publisher>>,
    /// Counts changes of what is known and bound (publishers, bindings), so a
    /// user of [`known`](Self::known) looks again only when it moved.
    pub changes: u64,
    activity: HashMap<String, Instant>,
    advertised: Vec<(String, String)>,
    pub wants: Vec<Want>,
    conns: Vec<Conn>,
    next_heartbeat: Instant,
    buf: Vec<u8>,
    /// Remote subscribers registered to our topics: (topic, process uuid, type).
    pub subscribers: Vec<(String, String, String)>,
    /// Connections reopened in a row, by publisher address (reset by data).
    reopened: HashMap<String, u32>,
    /// Why a bound subscription was last lost.
    pub last_loss: String,
}

/// The address to use: `ip`, else IGN_IP (Fortress), else GZ_IP (Garden and later),
/// else the one the route to the group leaves from.
pub fn choose_ip(ip: Option<&str>) -> String {
    if let Some(ip) = ip {
        return ip.to_string();
    }
    for var in ["IGN_IP", "GZ_IP"] {
        if let Ok(ip) = std::env::var(var)
            && !ip.is_empty()
        {
            return ip;
        }
    }
    UdpSocket::bind("0.0.0.0:0")
        .and_then(|s| {
            s.connect((GROUP, MSG_PORT))?;
            s.local_addr()
        })
        .ok()
        .map(|a| a.ip().to_string())
        .filter(|a| a != "0.0.0.0")
        .unwrap_or_else(|| "127.0.0.1".into())
}

impl Node {
    /// A node on `ip` (see [`choose_ip`]) in `partition`.
    pub fn new(ip: &str, partition: &str) -> io::Result<Node> {
        use socket2::{Domain, Protocol, Socket, Type};
        let addr: Ipv4Addr = ip.parse().map_err(|_| {
            io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("`{ip}` is not an IPv4 address of this host"),
            )
        })?;
        let s = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))?;
        s.set_reuse_address(true)?;
        s.set_reuse_port(true)?;
        s.bind(&SocketAddr::V4(SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, MSG_PORT)).into())?;
        s.join_multicast_v4(&GROUP, &addr)
            .map_err(|e| io::Error::new(e.kind(), format!("joining {GROUP} on {ip}: {e}")))?;
        s.set_multicast_if_v4(&addr)?;
        s.set_multicast_loop_v4(true)?;
        s.set_nonblocking(true)?;
        let publ = Pub::bind(ip)?;
        let now = Instant::now();
        Ok(Node {
            udp: s.into(),
            group: SocketAddr::V4(SocketAddrV4::new(GROUP, MSG_PORT)),
            ip: ip.into(),
            puuid: uuid(),
            nuuid: uuid(),
            prefix: qualify(partition, "/").trim_end_matches('/').to_string(),
            publ,
            remote: BTreeMap::new(),
            changes: 0,
            activity: HashMap::new(),
            advertised: Vec::new(),
            wants: Vec::new(),
            conns: Vec::new(),
            next_heartbeat: now,
            buf: Vec::new(),
            subscribers: Vec::new(),
            reopened: HashMap::new(),
            last_loss: String::new(),
        })
    }

    pub fn qualify(&self, topic: &str) -> String {
        format!(
            "{}{}",
            self.prefix,
            qualify("", topic).trim_start_matches('@')
        )
    }

    /// The topic part of a fully qualified name of our partition.
    pub fn short<'a>(&self, fq: &'a str) -> Option<&'a str> {
        unqualify(fq, &self.prefix)
    }

    /// Subscribes to `topic` under any of `types`; returns its index.
    pub fn want(&mut self, topic: &str, types: Vec<String>) -> usize {
        let topic = self.qualify(topic);
        self.wants.push(Want {
            topic,
            types,
            bound: None,
            mismatch: None,
        });
        self.next_heartbeat = Instant::now();
        self.wants.len() - 1
    }

    /// Advertises `topic` with `msg_type` (again, with a new type: the latest wins).
    pub fn advertise(&mut self, topic: &str, msg_type: &str) {
        let topic = self.qualify(topic);
        match self.advertised.iter_mut().find(|(t, _)| *t == topic) {
            Some(a) => {
                if a.1 == msg_type {
                    return;
                }
                a.1 = msg_type.into();
            }
            None => self.advertised.push((topic.clone(), msg_type.into())),
        }
        let p = self.our_publisher(&topic, msg_type);
        self.send(disc::ADVERTISE, None, Some(p));
    }

    fn our_publisher(&self, topic: &str, msg_type: &str) -> Publisher {
        Publisher {
            topic: topic.into(),
            address: self.publ.endpoint.clone(),
            process_uuid: self.puuid.clone(),
            node_uuid: self.nuuid.clone(),
            scope: 2,
            ctrl: "unused".into(),
            msg_type: msg_type.into(),
        }
    }

    /// Publishes `data` on an advertised topic (to the subscribers that asked).
    pub fn publish(&mut self, topic_fq: &str, msg_type: &str, data: &[u8]) {
        let addr = self.publ.endpoint.clone();
        self.publ.send(&[
            topic_fq.as_bytes(),
            addr.as_bytes(),
            data,
            msg_type.as_bytes(),
        ]);
    }

    /// Whether a subscriber is connected to `topic_fq`.
    pub fn has_subscriber(&self, topic_fq: &str) -> bool {
        self.publ.has_subscriber(topic_fq.as_bytes())
    }

    /// The publishers discovered in our partition: (topic, types).
    pub fn known(&self) -> Vec<(String, Vec<String>)> {
        self.remote
            .iter()
            .filter_map(|(t, ps)| {
                let short = self.short(t)?.to_string();
                let mut types: Vec<String> = ps.iter().map(|p| p.msg_type.clone()).collect();
                types.dedup();
                Some((short, types))
            })
            .collect()
    }

    /// Says goodbye (BYE; END_CONNECTION for each registration).
    pub fn bye(&mut self) {
        for i in 0..self.wants.len() {
            if let Some(p) = self.wants[i].bound.clone() {
                let reg = self.registration(&p);
                self.send(disc::END_CONNECTION, None, Some(reg));
            }
        }
        self.send(disc::BYE, None, None);
    }

    fn send(&mut self, kind: u64, sub: Option<String>, publisher: Option<Publisher>) {
        let d = Discovery {
            version: WIRE_VERSION,
            process_uuid: self.puuid.clone(),
            kind,
            relay: false,
            sub,
            publisher,
        };
        self.buf.clear();
        self.buf.extend_from_slice(&[0, 0]);
        d.encode(&mut self.buf);
        let n = (self.buf.len() - 2) as u16;
        self.buf[..2].copy_from_slice(&n.to_le_bytes());
        let _ = self.udp.send_to(&self.buf, self.group);
    }

    /// Our NEW_CONNECTION to publisher `p`: our ids, its process id in `ctrl`.
    fn registration(&self, p: &Publisher) -> Publisher {
        Publisher {
            topic: p.topic.clone(),
            address: p.address.clone(),
            process_uuid: self.puuid.clone(),
            node_uuid: self.nuuid.clone(),
            scope: p.scope,
            ctrl: p.process_uuid.clone(),
            msg_type: p.msg_type.clone(),
        }
    }

    fn heartbeat(&mut self) {
        self.send(disc::HEARTBEAT, None, None);
        for (t, ty) in self.advertised.clone() {
            let p = self.our_publisher(&t, &ty);
            self.send(disc::ADVERTISE, None, Some(p));
        }
        for i in 0..self.wants.len() {
            match self.wants[i].bound.clone() {
                None => {
                    let t = self.wants[i].topic.clone();
                    self.send(disc::SUBSCRIBE, Some(t), None);
                }
                Some(p) => {
                    let reg = self.registration(&p);
                    self.send(disc::NEW_CONNECTION, None, Some(reg));
                }
            }
        }
        // Processes silent too long are gone.
        let gone: Vec<String> = self
            .activity
            .iter()
            .filter(|(_, t)| t.elapsed() > SILENCE)
            .map(|(p, _)| p.clone())
            .collect();
        for p in gone {
            self.forget(&p);
        }
        self.next_heartbeat = Instant::now() + HEARTBEAT;
    }

    fn read_discovery(&mut self) {
        let mut buf = vec![0u8; 65536];
        while let Ok((len, _)) = self.udp.recv_from(&mut buf) {
            self.discovery(&buf[..len]);
        }
    }

    /// A process is gone: its publishers and the subscriptions bound to them.
    fn forget(&mut self, puuid: &str) {
        self.changes += 1;
        tracing::debug!("gazebo: process {puuid} is gone");
        if self
            .wants
            .iter()
            .any(|w| w.bound.as_ref().is_some_and(|b| b.process_uuid == puuid))
        {
            self.last_loss = format!("its process {puuid} said goodbye or fell silent for 3 s");
        }
        self.activity.remove(puuid);
        for ps in self.remote.values_mut() {
            ps.retain(|p| p.process_uuid != puuid);
        }
        self.remote.retain(|_, ps| !ps.is_empty());
        self.subscribers.retain(|s| s.1 != puuid);
        let mut addrs = Vec::new();
        for w in &mut self.wants {
            if w.bound.as_ref().is_some_and(|b| b.process_uuid == puuid) {
                addrs.push(w.bound.take().map(|b| b.address).unwrap_or_default());
            }
        }
        self.conns.retain(|c| !addrs.contains(&c.peer));
    }

    /// Unbinds the subscriptions of a connection that closed.
    /// A connection to a publisher closed. If its process still heartbeats (a
    /// publisher can drop a connection made while it was starting up), it is
    /// reopened at once, up to 20 times before data flows; otherwise, or when that
    /// fails, the subscriptions bound to it wait for a new advertisement.
    fn conn_lost(&mut self, peer: &str) {
        let bound: Vec<usize> = (0..self.wants.len())
            .filter(|&i| {
                self.wants[i]
                    .bound
                    .as_ref()
                    .is_some_and(|b| b.address == peer)
            })
            .collect();
        let alive = bound.first().is_some_and(|&i| {
            let p = self.wants[i].bound.as_ref().map(|b| b.process_uuid.clone());
            p.and_then(|p| self.activity.get(&p).copied())
                .is_some_and(|t| t.elapsed() < HEARTBEAT + HEARTBEAT / 2)
        });
        let tries = self.reopened.entry(peer.to_string()).or_insert(0);
        *tries += 1;
        if alive
            && *tries <= 20
            && let Ok(mut c) = Conn::connect_sub(peer, Duration::from_millis(500))
        {
            tracing::debug!("gazebo: {peer} closed our connection; reopened it");
            let ok = bound.iter().all(|&i| {
                let t = self.wants[i].topic.clone();
                c.subscribe(t.as_bytes()).is_ok()
            });
            if ok {
                self.conns.push(c);
                return;
            }
        }
        tracing::debug!("gazebo: the connection to {peer} closed");
        self.changes += 1;
        if !bound.is_empty() {
            self.last_loss = format!("the connection to {peer} closed");
        }
        self.reopened.remove(peer);
        for i in bound {
            self.wants[i].bound = None;
        }
        for ps in self.remote.values_mut() {
            ps.retain(|p| p.address != peer);
        }
        self.remote.retain(|_, ps| !ps.is_empty());
    }

    fn discovery(&mut self, b: &[u8]) {
        if b.len() < 2 || u16::from_le_bytes([b[0], b[1]]) as usize + 2 != b.len() {
            return;
        }
        let Ok(d) = Discovery::decode(&b[2..]) else {
            return;
        };
        if d.version != WIRE_VERSION || d.process_uuid == self.puuid || d.relay {
            return;
        }
        // A flood of made-up processes or topics is not kept without bound.
        if self.activity.len() >= MAX_KNOWN && !self.activity.contains_key(&d.process_uuid) {
            return;
        }
        self.activity.insert(d.process_uuid.clone(), Instant::now());
        match d.kind {
            disc::ADVERTISE => {
                let Some(p) = d.publisher else { return };
                self.changes += 1;
                if !p.topic.starts_with(&self.prefix)
                    || (self.remote.len() >= MAX_KNOWN && !self.remote.contains_key(&p.topic))
                {
                    return;
                }
                let list = self.remote.entry(p.topic.clone()).or_default();
                if !list.contains(&p) {
                    list.retain(|q| {
                        !(q.process_uuid == p.process_uuid && q.node_uuid == p.node_uuid)
                    });
                    list.push(p.clone());
                }
                self.bind(&p);
            }
            disc::UNADVERTISE => {
                let Some(p) = d.publisher else { return };
                self.changes += 1;
                tracing::debug!("gazebo: {} unadvertised", p.topic);
                self.last_loss = format!("{} was unadvertised", p.topic);
                if let Some(list) = self.remote.get_mut(&p.topic) {
                    list.retain(|q| {
                        !(q.process_uuid == p.process_uuid && q.node_uuid == p.node_uuid)
                    });
                }
                self.remote.retain(|_, ps| !ps.is_empty());
                for w in &mut self.wants {
                    if w.bound
                        .as_ref()
                        .is_some_and(|b| b.topic == p.topic && b.process_uuid == p.process_uuid)
                    {
                        w.bound = None;
                    }
                }
            }
            disc::SUBSCRIBE => {
                let Some(t) = d.sub else { return };
                if let Some((t, ty)) = self.advertised.iter().find(|(a, _)| *a == t).cloned() {
                    let p = self.our_publisher(&t, &ty);
                    self.send(disc::ADVERTISE, None, Some(p));
                }
            }
            disc::NEW_CONNECTION => {
                if let Some(p) = d.publisher
                    && p.ctrl == self.puuid
                {
                    let s = (p.topic, p.process_uuid, p.msg_type);
                    if !self.subscribers.contains(&s) {
                        self.subscribers.push(s);
                    }
                }
            }
            disc::END_CONNECTION => {
                if let Some(p) = d.publisher
                    && p.ctrl == self.puuid
                {
                    self.subscribers
                        .retain(|s| !(s.0 == p.topic && s.1 == p.process_uuid));
                }
            }
            disc::BYE => self.forget(&d.process_uuid),
            _ => {}
        }
    }

    /// Binds the unbound subscriptions of `p`'s topic to it.
    fn bind(&mut self, p: &Publisher) {
        self.changes += 1;
        for i in 0..self.wants.len() {
            let w = &mut self.wants[i];
            if w.topic != p.topic || w.bound.is_some() {
                continue;
            }
            if !w.types.contains(&p.msg_type) {
                w.mismatch = Some(p.msg_type.clone());
                continue;
            }
            let k = match self.conns.iter().position(|c| c.peer == p.address) {
                Some(k) => k,
                None => match Conn::connect_sub(&p.address, Duration::from_millis(500)) {
                    Ok(c) => {
                        tracing::debug!("gazebo: connected to {} for {}", p.address, p.topic);
                        self.conns.push(c);
                        self.conns.len() - 1
                    }
                    Err(e) => {
                        tracing::debug!("gazebo: cannot connect to {}: {e}", p.address);
                        continue;
                    }
                },
            };
            let topic = p.topic.clone();
            if self.conns[k].subscribe(topic.as_bytes()).is_err() {
                self.conns.remove(k);
                continue;
            }
            self.wants[i].bound = Some(p.clone());
            self.wants[i].mismatch = None;
            let reg = self.registration(p);
            self.send(disc::NEW_CONNECTION, None, Some(reg));
        }
    }

    /// Waits up to `timeout` for traffic and handles it: discovery, subscribers of
    /// ours, and topic data (`on_data(want index, data, type name)`); heartbeats
    /// when due.
    pub fn pump(&mut self, timeout: Duration, on_data: &mut dyn FnMut(usize, &[u8], &str)) {
        if Instant::now() >= self.next_heartbeat {
            // What arrived while we were busy counts before anyone is found silent.
            self.read_discovery();
            self.heartbeat();
        }
        let wait = timeout.min(
            self.next_heartbeat
                .saturating_duration_since(Instant::now()),
        );
        let mut fds = vec![
            libc::pollfd {
                fd: self.udp.as_raw_fd(),
                events: libc::POLLIN,
                revents: 0,
            },
            libc::pollfd {
                fd: self.publ.listener.as_raw_fd(),
                events: libc::POLLIN,
                revents: 0,
            },
        ];
        for c in self
            .conns
            .iter()
            .chain(self.publ.subs.iter().map(|(c, _)| c))
        {
            let mut events = libc::POLLIN;
            if c.wants_write() {
                events |= libc::POLLOUT;
            }
            fds.push(libc::pollfd {
                fd: c.fd(),
                events,
                revents: 0,
            });
        }
        // SAFETY: fds is a live array of pollfd of the given length.
        let n = unsafe {
            libc::poll(
                fds.as_mut_ptr(),
                fds.len() as libc::nfds_t,
                wait.as_millis().min(1000) as libc::c_int,
            )
        };
        if n <= 0 {
            return;
        }
        self.read_discovery();
        self.publ.serve();
        let mut lost = Vec::new();
        for c in &mut self.conns {
            let mut got_data = false;
            let open = match c.flush().and_then(|()| c.read_some()) {
                Ok(open) => open,
                Err(e) => {
                    tracing::debug!("gazebo: {}: {e}", c.peer);
                    false
                }
            };
            loop {
                match c.next_item() {
                    Ok(Some(Item::Message(m))) if m.len() >= 4 => {
                        for (i, w) in self.wants.iter().enumerate() {
                            if w.topic.as_bytes() == m[0].as_slice()
                                && w.bound.as_ref().is_some_and(|b| b.address == c.peer)
                            {
                                let ty = std::str::from_utf8(&m[3]).unwrap_or("");
                                on_data(i, &m[2], ty);
                                got_data = true;
                            }
                        }
                    }
                    Ok(Some(_)) => {}
                    Ok(None) => break,
                    Err(e) => {
                        tracing::warn!("gazebo: dropped the publisher at {}: {e}", c.peer);
                        lost.push(c.peer.clone());
                        break;
                    }
                }
            }
            if got_data {
                self.reopened.remove(&c.peer);
            }
            if !open {
                lost.push(c.peer.clone());
            }
        }
        lost.dedup();
        for peer in lost {
            self.conns.retain(|c| c.peer != peer);
            self.conn_lost(&peer);
        }
    }
}

/// The message types the driver accepts for a gz-msgs message name (`Twist`):
/// Fortress's `ignition.msgs.Twist` and Garden's and later `gz.msgs.Twist`.
pub fn both(name: &str) -> Vec<String> {
    vec![format!("ignition.msgs.{name}"), format!("gz.msgs.{name}")]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_qualified_as_gz_transport_does() {
        assert_eq!(
            qualify("vm:root", "/model/r1/cmd_vel"),
            "@/vm:root@/model/r1/cmd_vel"
        );
        assert_eq!(qualify("/p/", "t/"), "@/p@/t");
        let u = uuid();
        assert_eq!(u.len(), 36);
        assert_eq!(u.matches('-').count(), 4);
    }
}
