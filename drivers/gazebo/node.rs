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
//!
//! # Bounded against hostile peers
//! Everything a peer can grow has a cap, said in one line when hit: publishers per
//! topic ([`MAX_PUBLISHERS`], [`MAX_PER_PROCESS`] of one process), topics
//! ([`MAX_TOPICS`]), processes ([`MAX_KNOWN`]), remote subscribers
//! ([`MAX_SUBSCRIBERS`]), our PUB socket's connections (`zmtp::MAX_SUBS`). Each
//! discovery packet costs bounded work, and one [`pump`](Node::pump) reads at most
//! [`MAX_DISCOVERY_PER_PUMP`] of them (the rest wait in the socket, or the kernel
//! drops them), so the caller's motors commands go out on time during a flood.
//! Advertised addresses are IP literals, connected without blocking (no name is
//! resolved). A bound publisher that sends no data for [`DATA_SILENCE`] (a decoy
//! that only heartbeats) is dropped, and the subscription moves to another
//! publisher of the topic; an address that failed waits (1 s doubling to 30 s)
//! before it is tried again, and its failure is said once. Discovery is read on
//! the multicast group's address only, and with a loopback `ip` only from loopback.

use std::{
    collections::{BTreeMap, HashMap, HashSet},
    io,
    net::{Ipv4Addr, SocketAddr, SocketAddrV4, TcpStream, UdpSocket},
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
/// The most processes remembered.
pub const MAX_KNOWN: usize = 10_000;
/// The most topics remembered.
pub const MAX_TOPICS: usize = 1024;
/// The most publishers remembered per topic, and of those, from one process.
pub const MAX_PUBLISHERS: usize = 16;
pub const MAX_PER_PROCESS: usize = 4;
/// The most remote subscribers of our topics remembered.
pub const MAX_SUBSCRIBERS: usize = 256;
/// The most discovery packets handled by one pump.
pub const MAX_DISCOVERY_PER_PUMP: usize = 64;
/// A bound publisher silent this long (no data) is given up for another.
pub const DATA_SILENCE: Duration = Duration::from_secs(3);
/// The longest wait before a failed address is tried again.
const MAX_BACKOFF: Duration = Duration::from_secs(30);
/// The most topics remembered per process (beyond: a process gone costs a look at all).
const MAX_TOPICS_OF: usize = 64;
/// The most failed addresses remembered.
const MAX_FAILED: usize = 256;

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
    /// When it was bound, or last got data.
    pub heard: Instant,
    /// Whether data came since it was bound.
    pub got_data: bool,
    /// Times a publisher of it was given up (silent, closed, bad).
    pub failures: u64,
}

/// An address that failed: not tried again before `until`.
struct Failed {
    until: Instant,
    wait: Duration,
    said: bool,
}

/// The node.
pub struct Node {
    udp: UdpSocket,
    group: SocketAddr,
    pub ip: String,
    /// Discovery only from loopback (`ip` is a loopback address).
    loopback_only: bool,
    pub puuid: String,
    nuuid: String,
    /// `@/PARTITION@`
    prefix: String,
    publ: Pub,
    /// Remote publishers by topic, oldest first.
    remote: BTreeMap<String, Vec<Publisher>>,
    /// The topics each process advertised (at most [`MAX_TOPICS_OF`]; None: more,
    /// look at every topic), so a process gone costs its own topics, not all.
    topics_of: HashMap<String, Option<HashSet<String>>>,
    /// Counts changes of what is known and bound (publishers, bindings), so a
    /// user of [`known`](Self::known) looks again only when it moved.
    pub changes: u64,
    activity: HashMap<String, Instant>,
    advertised: Vec<(String, String)>,
    /// When each advertised topic was last advertised in answer to a SUBSCRIBE.
    answered: HashMap<String, Instant>,
    pub wants: Vec<Want>,
    conns: Vec<Conn>,
    next_heartbeat: Instant,
    buf: Vec<u8>,
    dbuf: Vec<u8>,
    /// Remote subscribers registered to our topics: (topic, process uuid, type).
    pub subscribers: Vec<(String, String, String)>,
    /// Connections reopened in a row, by publisher address (reset by data).
    reopened: HashMap<String, u32>,
    /// Addresses that failed, by address.
    failed: HashMap<String, Failed>,
    /// The caps said already (one line each).
    caps_said: HashSet<String>,
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
        // The group's address, not 0.0.0.0: no unicast reaches this socket.
        s.bind(&SocketAddr::V4(SocketAddrV4::new(GROUP, MSG_PORT)).into())?;
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
            loopback_only: addr.is_loopback(),
            puuid: uuid(),
            nuuid: uuid(),
            prefix: qualify(partition, "/").trim_end_matches('/').to_string(),
            publ,
            remote: BTreeMap::new(),
            topics_of: HashMap::new(),
            changes: 0,
            activity: HashMap::new(),
            advertised: Vec::new(),
            answered: HashMap::new(),
            wants: Vec::new(),
            conns: Vec::new(),
            next_heartbeat: now,
            buf: Vec::new(),
            dbuf: vec![0u8; 65536],
            subscribers: Vec::new(),
            reopened: HashMap::new(),
            failed: HashMap::new(),
            caps_said: HashSet::new(),
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
            heard: Instant::now(),
            got_data: false,
            failures: 0,
        });
        self.next_heartbeat = Instant::now();
        let i = self.wants.len() - 1;
        self.rebind(i);
        i
    }

    /// Moves subscription `i` to another topic (the driver chose again).
    pub fn retopic(&mut self, i: usize, topic: &str) {
        let topic = self.qualify(topic);
        if self.wants[i].topic == topic {
            return;
        }
        self.unbind(i, None);
        let w = &mut self.wants[i];
        w.topic = topic;
        w.mismatch = None;
        w.failures = 0;
        self.changes += 1;
        self.next_heartbeat = Instant::now();
        self.rebind(i);
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

    /// For each subscriber of one of `msgs` (topic, type, data): a second handle
    /// on its connection and those messages as we would publish them
    /// ([`Pub::stop_targets`]).
    pub fn stop_targets(&self, msgs: &[(String, String, Vec<u8>)]) -> Vec<(TcpStream, Vec<u8>)> {
        let addr = self.publ.endpoint.as_bytes();
        let parts: Vec<Vec<&[u8]>> = msgs
            .iter()
            .map(|(t, ty, d)| vec![t.as_bytes(), addr, d.as_slice(), ty.as_bytes()])
            .collect();
        self.publ.stop_targets(&parts)
    }

    /// Counts changes of our subscribers (connected, gone, their topics).
    pub fn subscriber_changes(&self) -> u64 {
        self.publ.changes
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
                types.sort();
                types.dedup();
                Some((short, types))
            })
            .collect()
    }

    /// What the node remembers of other processes: (topics, the most publishers
    /// of one topic, processes, remote subscribers), each under its cap.
    pub fn remembered(&self) -> (usize, usize, usize, usize) {
        let most = self.remote.values().map(Vec::len).max().unwrap_or(0);
        (
            self.remote.len(),
            most,
            self.activity.len(),
            self.subscribers.len(),
        )
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

    /// Says a cap was hit, once per `key`.
    fn cap_hit(&mut self, key: String, line: impl FnOnce() -> String) {
        if self.caps_said.len() < 1024 && self.caps_said.insert(key) {
            tracing::warn!("gazebo: {}", line());
        }
    }

    fn heartbeat(&mut self) {
        self.send(disc::HEARTBEAT, None, None);
        for (t, ty) in self.advertised.clone() {
            let p = self.our_publisher(&t, &ty);
            self.send(disc::ADVERTISE, None, Some(p));
        }
        let now = Instant::now();
        for i in 0..self.wants.len() {
            // A publisher that heartbeats but sends nothing is given up.
            let silent = self.wants[i].bound.is_some()
                && now.duration_since(self.wants[i].heard) > DATA_SILENCE;
            if silent {
                let addr = self.wants[i]
                    .bound
                    .as_ref()
                    .map(|b| b.address.clone())
                    .unwrap_or_default();
                let why = format!(
                    "no data on {} from {addr} for {} s",
                    self.short(&self.wants[i].topic).unwrap_or("?"),
                    DATA_SILENCE.as_secs()
                );
                self.fail(&addr, &why);
                self.unbind(i, Some(why));
                self.drop_conn_if_unused(&addr);
            }
            if self.wants[i].bound.is_none() {
                self.rebind(i);
            }
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
        self.failed.retain(|_, f| now < f.until + MAX_BACKOFF * 2);
        self.answered.retain(|_, t| t.elapsed() < HEARTBEAT);
        if self.caps_said.len() >= 1024 {
            self.caps_said.clear();
        }
        self.next_heartbeat = Instant::now() + HEARTBEAT;
    }

    /// Reads at most [`MAX_DISCOVERY_PER_PUMP`] discovery packets.
    fn read_discovery(&mut self) {
        let mut buf = std::mem::take(&mut self.dbuf);
        for _ in 0..MAX_DISCOVERY_PER_PUMP {
            let Ok((len, from)) = self.udp.recv_from(&mut buf) else {
                break;
            };
            if self.loopback_only && !from.ip().is_loopback() {
                continue;
            }
            self.discovery(&buf[..len]);
        }
        self.dbuf = buf;
    }

    /// Unbinds subscription `i` (saying why, when it was bound).
    fn unbind(&mut self, i: usize, why: Option<String>) {
        if self.wants[i].bound.take().is_some() {
            self.changes += 1;
            self.wants[i].failures += 1;
            if let Some(why) = why {
                tracing::debug!("gazebo: {why}");
                self.last_loss = why;
            }
        }
    }

    /// Closes our connection to `addr` when no subscription is bound to it.
    fn drop_conn_if_unused(&mut self, addr: &str) {
        let used = self
            .wants
            .iter()
            .any(|w| w.bound.as_ref().is_some_and(|b| b.address == addr));
        if !used {
            self.conns.retain(|c| c.peer != addr);
        }
    }

    /// Notes that `addr` failed: not tried again for a while (1 s doubling to 30 s),
    /// said once.
    fn fail(&mut self, addr: &str, why: &str) {
        if !self.failed.contains_key(addr) && self.failed.len() >= MAX_FAILED {
            return;
        }
        let f = self.failed.entry(addr.to_string()).or_insert(Failed {
            until: Instant::now(),
            wait: Duration::ZERO,
            said: false,
        });
        f.wait = (f.wait * 2).clamp(HEARTBEAT, MAX_BACKOFF);
        f.until = Instant::now() + f.wait;
        if !f.said {
            f.said = true;
            tracing::warn!("gazebo: {why}; trying another publisher ({addr} again after a while)");
        }
    }

    /// Whether `addr` failed lately.
    fn failing(&self, addr: &str) -> bool {
        self.failed
            .get(addr)
            .is_some_and(|f| Instant::now() < f.until)
    }

    /// A process is gone: its publishers and the subscriptions bound to them.
    fn forget(&mut self, puuid: &str) {
        if self.activity.remove(puuid).is_none() {
            return;
        }
        self.changes += 1;
        tracing::debug!("gazebo: process {puuid} is gone");
        match self.topics_of.remove(puuid) {
            Some(Some(topics)) => {
                for t in topics {
                    if let Some(ps) = self.remote.get_mut(&t) {
                        ps.retain(|p| p.process_uuid != puuid);
                        if ps.is_empty() {
                            self.remote.remove(&t);
                        }
                    }
                }
            }
            Some(None) => {
                for ps in self.remote.values_mut() {
                    ps.retain(|p| p.process_uuid != puuid);
                }
                self.remote.retain(|_, ps| !ps.is_empty());
            }
            None => {}
        }
        self.subscribers.retain(|s| s.1 != puuid);
        let mut addrs = Vec::new();
        for i in 0..self.wants.len() {
            if let Some(b) = self.wants[i]
                .bound
                .as_ref()
                .filter(|b| b.process_uuid == puuid)
            {
                addrs.push(b.address.clone());
                let why = format!("its process {puuid} said goodbye or fell silent for 3 s");
                self.unbind(i, Some(why));
            }
        }
        for a in addrs {
            self.drop_conn_if_unused(&a);
        }
        for i in 0..self.wants.len() {
            if self.wants[i].bound.is_none() {
                self.rebind(i);
            }
        }
    }

    /// A connection to a publisher closed (`bad`: it spoke garbage or did not greet
    /// in time). If it closed cleanly and its process still heartbeats (a
    /// publisher can drop a connection made while it was starting up), it is
    /// reopened at once, up to 20 times before data flows; otherwise the address
    /// waits (backoff) and the subscriptions bound to it move to another publisher.
    fn conn_lost(&mut self, peer: &str, bad: Option<String>) {
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
        if bad.is_none()
            && alive
            && *tries <= 20
            && let Ok(mut c) = Conn::connect_sub(peer)
        {
            tracing::debug!("gazebo: {peer} closed our connection; reopening it");
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
        self.reopened.remove(peer);
        let why = match &bad {
            Some(e) => e.clone(),
            None => format!("the connection to {peer} closed"),
        };
        if !bound.is_empty() || bad.is_some() {
            self.fail(peer, &why);
        }
        for &i in &bound {
            self.unbind(i, Some(why.clone()));
        }
        for i in bound {
            self.rebind(i);
        }
    }

    /// Adds or refreshes publisher `p` in its topic's list, within the caps;
    /// whether the list changed.
    fn remember(&mut self, p: &Publisher) -> bool {
        if !self.remote.contains_key(&p.topic) && self.remote.len() >= MAX_TOPICS {
            let n = self.remote.len();
            self.cap_hit("topics".into(), || {
                format!("{n} topics are known; more are not kept (a flood?)")
            });
            return false;
        }
        let bound: Vec<(String, String)> = self
            .wants
            .iter()
            .filter_map(|w| w.bound.as_ref())
            .map(|b| (b.process_uuid.clone(), b.node_uuid.clone()))
            .collect();
        let is_bound = |q: &Publisher| {
            bound
                .iter()
                .any(|(pu, nu)| *pu == q.process_uuid && *nu == q.node_uuid)
        };
        let list = self.remote.entry(p.topic.clone()).or_default();
        if let Some(q) = list
            .iter_mut()
            .find(|q| q.process_uuid == p.process_uuid && q.node_uuid == p.node_uuid)
        {
            if q == p {
                return false;
            }
            *q = p.clone();
            return true;
        }
        let same = list
            .iter()
            .filter(|q| q.process_uuid == p.process_uuid)
            .count();
        let evict = if same >= MAX_PER_PROCESS {
            list.iter()
                .position(|q| q.process_uuid == p.process_uuid && !is_bound(q))
        } else if list.len() >= MAX_PUBLISHERS {
            list.iter().position(|q| !is_bound(q))
        } else {
            None
        };
        let full = same >= MAX_PER_PROCESS || list.len() >= MAX_PUBLISHERS;
        match (full, evict) {
            (true, Some(k)) => {
                list.remove(k);
            }
            (true, None) => return false,
            _ => {}
        }
        list.push(p.clone());
        let entry = self
            .topics_of
            .entry(p.process_uuid.clone())
            .or_insert_with(|| Some(HashSet::new()));
        if let Some(set) = entry {
            if set.len() < MAX_TOPICS_OF {
                set.insert(p.topic.clone());
            } else if !set.contains(&p.topic) {
                *entry = None;
            }
        }
        if full {
            let topic = p.topic.clone();
            self.cap_hit(format!("publishers {topic}"), || {
                format!(
                    "{topic}: more than {MAX_PUBLISHERS} publishers (or {MAX_PER_PROCESS} of one \
                     process) advertise it; the oldest are forgotten (a flood?)"
                )
            });
        }
        true
    }

    /// Handles one discovery packet as it came from the socket (public so the
    /// fuzz target of `tests/fuzz.rs` drives the same path on bytes; a node that
    /// wants no topic and advertises none sends nothing in answer).
    pub fn discovery(&mut self, b: &[u8]) {
        let Some(d) = parse_packet(b) else {
            return;
        };
        if d.process_uuid == self.puuid || d.relay {
            return;
        }
        // A flood of made-up processes or topics is not kept without bound.
        if self.activity.len() >= MAX_KNOWN && !self.activity.contains_key(&d.process_uuid) {
            let n = self.activity.len();
            self.cap_hit("processes".into(), || {
                format!("{n} processes are known; more are not kept (a flood?)")
            });
            return;
        }
        if d.kind == disc::BYE {
            self.forget(&d.process_uuid);
            return;
        }
        self.activity.insert(d.process_uuid.clone(), Instant::now());
        match d.kind {
            disc::ADVERTISE => {
                let Some(p) = d.publisher else { return };
                if !p.topic.starts_with(&self.prefix) {
                    return;
                }
                if self.remember(&p) {
                    self.changes += 1;
                    self.bind_new(&p);
                }
            }
            disc::UNADVERTISE => {
                let Some(p) = d.publisher else { return };
                let Some(list) = self.remote.get_mut(&p.topic) else {
                    return;
                };
                let n = list.len();
                list.retain(|q| !(q.process_uuid == p.process_uuid && q.node_uuid == p.node_uuid));
                if list.len() == n {
                    return;
                }
                self.changes += 1;
                tracing::debug!("gazebo: {} unadvertised", p.topic);
                self.remote.retain(|_, ps| !ps.is_empty());
                for i in 0..self.wants.len() {
                    let hit = self.wants[i].bound.as_ref().is_some_and(|b| {
                        b.topic == p.topic
                            && b.process_uuid == p.process_uuid
                            && b.node_uuid == p.node_uuid
                    });
                    if hit {
                        let addr = p.address.clone();
                        self.unbind(i, Some(format!("{} was unadvertised", p.topic)));
                        self.drop_conn_if_unused(&addr);
                        self.rebind(i);
                    }
                }
            }
            disc::SUBSCRIBE => {
                let Some(t) = d.sub else { return };
                if let Some((t, ty)) = self.advertised.iter().find(|(a, _)| *a == t).cloned() {
                    // At most one answer per topic per 100 ms, however many ask.
                    let recent = self
                        .answered
                        .get(&t)
                        .is_some_and(|a| a.elapsed() < Duration::from_millis(100));
                    if !recent {
                        self.answered.insert(t.clone(), Instant::now());
                        let p = self.our_publisher(&t, &ty);
                        self.send(disc::ADVERTISE, None, Some(p));
                    }
                }
            }
            disc::NEW_CONNECTION => {
                if let Some(p) = d.publisher
                    && p.ctrl == self.puuid
                {
                    let s = (p.topic, p.process_uuid, p.msg_type);
                    if !self.subscribers.contains(&s) {
                        if self.subscribers.len() >= MAX_SUBSCRIBERS {
                            self.cap_hit("subscribers".into(), || {
                                format!(
                                    "{MAX_SUBSCRIBERS} subscribers registered to our topics; more \
                                     are not kept (a flood?)"
                                )
                            });
                            return;
                        }
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
            _ => {}
        }
    }

    /// A publisher advertised (anew): binds the unbound subscriptions of its topic.
    fn bind_new(&mut self, p: &Publisher) {
        for i in 0..self.wants.len() {
            let w = &self.wants[i];
            if w.topic != p.topic || w.bound.is_some() {
                continue;
            }
            if !w.types.contains(&p.msg_type) {
                if self.wants[i].mismatch.is_none() {
                    self.changes += 1;
                }
                self.wants[i].mismatch = Some(p.msg_type.clone());
                continue;
            }
            if self.failing(&p.address) {
                continue;
            }
            self.bind(i, p);
        }
    }

    /// Binds unbound subscription `i` to a publisher of its topic: of a type it
    /// reads, not failing, the newest first (else the one whose wait ends first).
    fn rebind(&mut self, i: usize) {
        if self.wants[i].bound.is_some() {
            return;
        }
        let Some(list) = self.remote.get(&self.wants[i].topic) else {
            return;
        };
        let fits: Vec<&Publisher> = list
            .iter()
            .filter(|p| self.wants[i].types.contains(&p.msg_type))
            .collect();
        let choice = fits
            .iter()
            .rev()
            .find(|p| !self.failing(&p.address))
            .copied()
            .cloned();
        let Some(p) = choice else {
            if fits.is_empty()
                && let Some(p) = list.first()
                && self.wants[i].mismatch.is_none()
            {
                self.wants[i].mismatch = Some(p.msg_type.clone());
                self.changes += 1;
            }
            return;
        };
        self.bind(i, &p);
    }

    /// Binds subscription `i` to `p`: connects (without waiting) and subscribes.
    fn bind(&mut self, i: usize, p: &Publisher) {
        let k = match self.conns.iter().position(|c| c.peer == p.address) {
            Some(k) => k,
            None => match Conn::connect_sub(&p.address) {
                Ok(c) => {
                    tracing::debug!("gazebo: connecting to {} for {}", p.address, p.topic);
                    self.conns.push(c);
                    self.conns.len() - 1
                }
                Err(e) => {
                    let why = format!("cannot connect to {}: {e}", p.address);
                    self.fail(&p.address, &why);
                    return;
                }
            },
        };
        let topic = p.topic.clone();
        if self.conns[k].subscribe(topic.as_bytes()).is_err() {
            self.conns.remove(k);
            return;
        }
        let w = &mut self.wants[i];
        w.bound = Some(p.clone());
        w.mismatch = None;
        w.heard = Instant::now();
        w.got_data = false;
        self.changes += 1;
        let reg = self.registration(p);
        self.send(disc::NEW_CONNECTION, None, Some(reg));
    }

    /// Waits up to `timeout` for traffic and handles it: discovery (at most
    /// [`MAX_DISCOVERY_PER_PUMP`] packets), subscribers of ours, and topic data
    /// (`on_data(want index, data, type name)`); heartbeats when due.
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
        let now = Instant::now();
        let mut lost: Vec<(String, Option<String>)> = Vec::new();
        for c in &self.conns {
            if c.greeting_late(now) {
                lost.push((
                    c.peer.clone(),
                    Some(format!(
                        "{} did not connect and greet (ZMTP) within {} s",
                        c.peer,
                        super::zmtp::GREETING_TIME.as_secs()
                    )),
                ));
            }
        }
        if n > 0 {
            if fds[0].revents != 0 {
                self.read_discovery();
            }
            self.publ.serve();
            for c in &mut self.conns {
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
                            for (i, w) in self.wants.iter_mut().enumerate() {
                                if w.topic.as_bytes() == m[0].as_slice()
                                    && w.bound.as_ref().is_some_and(|b| b.address == c.peer)
                                {
                                    let ty = std::str::from_utf8(&m[3]).unwrap_or("");
                                    w.heard = now;
                                    w.got_data = true;
                                    on_data(i, &m[2], ty);
                                    self.reopened.remove(&c.peer);
                                }
                            }
                        }
                        Ok(Some(_)) => {}
                        Ok(None) => break,
                        Err(e) => {
                            lost.push((
                                c.peer.clone(),
                                Some(format!("dropped the publisher at {}: {e}", c.peer)),
                            ));
                            break;
                        }
                    }
                }
                if !open {
                    lost.push((c.peer.clone(), None));
                }
            }
        }
        let mut seen = HashSet::new();
        for (peer, bad) in lost {
            if !seen.insert(peer.clone()) {
                continue;
            }
            self.conns.retain(|c| c.peer != peer);
            self.conn_lost(&peer, bad);
        }
    }
}

/// A discovery packet: a 2-byte little-endian length, then a `Discovery` of our
/// wire version; None for anything else.
pub fn parse_packet(b: &[u8]) -> Option<Discovery> {
    if b.len() < 2 || u16::from_le_bytes([b[0], b[1]]) as usize + 2 != b.len() {
        return None;
    }
    Discovery::decode(&b[2..])
        .ok()
        .filter(|d| d.version == WIRE_VERSION)
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
