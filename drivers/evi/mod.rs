//! evi: the Sony EVI-D100 (and D100P) pan-tilt-zoom camera over VISCA on a serial
//! line, as JDE 4.3's `evi` driver drove it. The video goes through any image
//! driver (video4linux2, firewire ...); this driver moves the head and the zoom.
//!
//! # Conf
//! ```text
//! driver evi
//! serial /dev/ttyUSB0        # the serial port (required); 9600 baud, 8N1
//! camera 1                   # VISCA address 1..7 (default 1, after an address set)
//! poll 100                   # ms between position inquiries (default 100)
//! reply_timeout 1000         # ms to wait for an answer before the camera counts as silent
//! provides pantiltencoders
//! provides pantiltmotors
//! provides zoomencoders
//! provides zoommotors
//! end_driver
//! ```
//!
//! # Interfaces
//! | interface | fields and units |
//! |---|---|
//! | `pantiltencoders` | `pan_angle` (±100), `tilt_angle` (±25) deg, from the position inquiry; positive pan is VISCA's (to the right), as 4.3 |
//! | `pantiltmotors` | `longitude` ±100, `latitude` ±25 deg; `longitude_speed` ≤ 300, `latitude_speed` ≤ 125 deg/s, mapped to VISCA speed modes 1..24 / 1..20 by 4.3's table (the slowest mode at least as fast as asked); speed 0 = stop where the head is (4.3: current position at the axis' maximum speed) |
//! | `zoomencoders` | `zoom_position` 0..40 (10x optical × 4x digital; device units 0..0x7000 linear) |
//! | `zoommotors` | `zoom` 0..40; `zoom_speed` 0..7 is kept as 4.3 had it, but the D100's direct zoom runs at its own speed |
//!
//! # Behaviour
//! - Opening: VISCA address set (`88 30 01 FF`), IF_Clear (`88 01 00 01 FF`), power
//!   inquiry and power on if the camera is off; then position and zoom are
//!   inquired every `poll` ms. Power goes off on terminate (`81 01 04 00 03 FF`).
//! - A command goes out only when it changes, and waits for its ACK. Errors as the
//!   VISCA documents define them: 0x02 syntax error (a camera that is not an EVI, or
//!   a broken line: the port is reopened), 0x03 buffer full (sent again when a
//!   socket frees), 0x04 cancelled and 0x05 no socket (noted), 0x41 not executable
//!   (reported, the motors interface is marked stale with the reason until a new
//!   command comes).
//! - Silence, garbage or a vanished port: reported once naming the port, every
//!   provided interface marked stale, and the port reopened every second until the
//!   camera answers (the run goes on). Each session begins by discarding what waits
//!   on the line (until 50 ms of quiet), so the rest of a burst of garbage does not
//!   keep the camera stale after it is sane again. The camera is a [`Device`]
//!   under [`Supervisor`] (the thread, the retries, the stale marking, one log line
//!   per change); its shared lines and its port come from [`crate::serialhead`].
//! - Answers out of the EVI-D100's range (pan ±0x08DB, tilt ±0x0190, zoom
//!   0..0x7000) are refused as a broken line, never written into an interface.
//!
//! System packages: none (the `serialport` crate without libudev). Your user needs
//! access to the port (usually the `dialout` group).

pub mod protocol;

use std::{
    io::{Read, Write},
    sync::Arc,
    time::{Duration, Instant},
};

use crate::{
    conf::{
        ComponentConf,
        settings::{Setting, choice, int},
    },
    interfaces::{AnyInterface, Interface, PtEncoders, PtMotors, ZoomEncoders, ZoomMotors, limit},
    runtime::{Device, Driver, Runtime, Supervisor},
    serialhead::{
        self, HEAD, HeadConf, HeadLines, POLL, PollClock, PortError, REPLY_TIMEOUT, SERIAL,
        read_some,
    },
};
use protocol::{Reply, ViscaError};

/// The driver's settings.
#[derive(Clone, Debug)]
pub struct EviConf {
    /// `serial`, `poll`, `reply_timeout`, `provides`.
    pub head: HeadConf,
    pub camera: u8,
}

crate::declare_lines! {
    /// The lines `evi` takes (`jderobot help evi` prints them).
    struct Lines {
        head: HeadLines = [
            SERIAL.group(HEAD),
            POLL.default("100").group(HEAD),
            REPLY_TIMEOUT.group(HEAD),
            Setting::new(
            "provides",
            "an interface it provides: pantiltencoders, pantiltmotors, zoomencoders, zoommotors (4.3's ptencoders, ptmotors, zencoders, zmotors)",
            &[choice(
                "INTERFACE",
                &[
                    "pantiltencoders",
                    "pantiltmotors",
                    "zoomencoders",
                    "zoommotors",
                    "ptencoders",
                    "ptmotors",
                    "zencoders",
                    "zmotors",
                ],
            )],
        )
        .repeats()
        .group(HEAD),
        ],
        camera: u8 = Setting::new(
            "camera",
            "the camera's VISCA address (after an address set, the first camera is 1)",
            &[int("ADDRESS", "", 1, 7)],
        )
        .default("1"),
    }
}
impl EviConf {
    pub fn parse(conf: &ComponentConf) -> anyhow::Result<EviConf> {
        let offered = [
            "pantiltencoders",
            "pantiltmotors",
            "zoomencoders",
            "zoommotors",
        ];
        let l: Lines = conf.read()?;
        Ok(EviConf {
            head: HeadConf::new(conf, l.head, &offered)?,
            camera: l.camera,
        })
    }
}

/// Why the link to the camera failed.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    #[error(transparent)]
    Port(#[from] PortError),
    #[error(
        "{port}: no answer to `{command}` in {ms} ms (is the EVI powered (its standby lamp), on this port, at 9600 baud?)"
    )]
    Silent {
        port: String,
        command: String,
        ms: u128,
    },
    #[error(
        "{port}: unexpected bytes `{bytes}` in answer to `{command}` (not VISCA from camera {camera}: another device on this port, or a wrong address?)"
    )]
    Garbage {
        port: String,
        command: String,
        bytes: String,
        camera: u8,
    },
    #[error("{port}: the camera answered `{command}` with {got} where {expected} was expected")]
    Unexpected {
        port: String,
        command: String,
        got: String,
        expected: String,
    },
    #[error(
        "{port}: the camera answered `{command}` with {what} {value} (0x{hex}), out of the EVI-D100's range {lo}..{hi}; refused"
    )]
    OutOfRange {
        port: String,
        command: String,
        what: &'static str,
        value: i32,
        hex: String,
        lo: i32,
        hi: i32,
    },
    #[error("{port}: the camera answered `{command}` with {error}")]
    Visca {
        port: String,
        command: String,
        error: ViscaError,
    },
}

/// The longest VISCA packet is 16 bytes.
const MAX_PACKET: usize = 16;

/// A packet link to one camera.
pub struct Link {
    port: Box<dyn serialport::SerialPort>,
    name: String,
    addr: u8,
    timeout: Duration,
    buf: Vec<u8>,
    /// Sockets whose command has not completed yet.
    pub busy: [bool; 3],
}

impl Link {
    pub fn new(
        port: Box<dyn serialport::SerialPort>,
        name: &str,
        addr: u8,
        timeout: Duration,
    ) -> Link {
        Link {
            port,
            name: name.to_string(),
            addr,
            timeout,
            buf: Vec::with_capacity(64),
            busy: [false; 3],
        }
    }

    fn io(&self, e: std::io::Error) -> LinkError {
        LinkError::Port(PortError::Io {
            port: self.name.clone(),
            what: e.to_string(),
            device: "the camera",
        })
    }

    pub fn send(&mut self, p: &[u8]) -> Result<(), LinkError> {
        self.port.write_all(p).map_err(|e| self.io(e))?;
        self.port.flush().map_err(|e| self.io(e))
    }

    /// The next packet (up to and with `FF`) within `timeout`; None on timeout.
    fn packet(&mut self, command: &[u8], timeout: Duration) -> Result<Option<Vec<u8>>, LinkError> {
        let t0 = Instant::now();
        let mut b = [0u8; 64];
        loop {
            if let Some(i) = self.buf.iter().position(|&c| c == protocol::END) {
                return Ok(Some(self.buf.drain(..=i).collect()));
            }
            // Every VISCA packet starts with a byte of the form 1xxx xxxx.
            if self.buf.first().is_some_and(|&b| b & 0x80 == 0) {
                // Collect the rest of it for the message.
                let t1 = Instant::now();
                while t1.elapsed() < Duration::from_millis(20) && self.buf.len() < MAX_PACKET {
                    if let Ok(n) = self.port.read(&mut b)
                        && n > 0
                    {
                        self.buf.extend_from_slice(&b[..n]);
                    }
                }
                let bytes = protocol::hex(&self.buf[..self.buf.len().min(MAX_PACKET)]);
                self.buf.clear();
                return Err(self.garbage(command, bytes));
            }
            if self.buf.len() > MAX_PACKET {
                let bytes = protocol::hex(&self.buf[..MAX_PACKET]);
                self.buf.clear();
                return Err(self.garbage(command, bytes));
            }
            if t0.elapsed() > timeout {
                return Ok(None);
            }
            if let Some(n) = read_some(self.port.as_mut(), &mut b).map_err(|e| self.io(e))? {
                self.buf.extend_from_slice(&b[..n]);
            }
        }
    }

    fn garbage(&self, command: &[u8], bytes: String) -> LinkError {
        LinkError::Garbage {
            port: self.name.clone(),
            command: protocol::hex(command),
            bytes,
            camera: self.addr,
        }
    }

    fn unexpected(&self, command: &[u8], got: &Reply, expected: &str) -> LinkError {
        LinkError::Unexpected {
            port: self.name.clone(),
            command: protocol::hex(command),
            got: got.to_string(),
            expected: expected.to_string(),
        }
    }

    /// `value` answered to `command` if it is in the camera's range of `what`.
    fn in_range(&self, command: &[u8], what: &'static str, value: i32) -> Result<i32, LinkError> {
        let (lo, hi) = protocol::unit_range(what);
        if (lo..=hi).contains(&value) {
            return Ok(value);
        }
        Err(LinkError::OutOfRange {
            port: self.name.clone(),
            command: protocol::hex(command),
            what,
            value,
            hex: format!("{:04X}", value as u16),
            lo,
            hi,
        })
    }

    /// Resynchronises the line: discards whatever is waiting (the rest of a burst
    /// of garbage, late answers of the previous session) until the line has been
    /// quiet for 50 ms (1 s at most), so a session starts on a clean line.
    pub fn flush(&mut self) -> Result<(), LinkError> {
        let _ = self.port.clear(serialport::ClearBuffer::Input);
        self.buf.clear();
        let t0 = Instant::now();
        let mut quiet_since = Instant::now();
        let mut b = [0u8; 256];
        while quiet_since.elapsed() < Duration::from_millis(50)
            && t0.elapsed() < Duration::from_secs(1)
        {
            if read_some(self.port.as_mut(), &mut b)
                .map_err(|e| self.io(e))?
                .is_some()
            {
                quiet_since = Instant::now();
            }
        }
        Ok(())
    }

    fn silent(&self, command: &[u8]) -> LinkError {
        LinkError::Silent {
            port: self.name.clone(),
            command: protocol::hex(command),
            ms: self.timeout.as_millis(),
        }
    }

    /// The next classified reply to `command`; completions of earlier commands on
    /// the way free their sockets.
    fn reply(&mut self, command: &[u8], timeout: Duration) -> Result<Reply, LinkError> {
        let t0 = Instant::now();
        loop {
            let left = timeout.saturating_sub(t0.elapsed());
            let Some(p) = self.packet(command, left)? else {
                return Err(self.silent(command));
            };
            match protocol::classify(self.addr, &p) {
                None => return Err(self.garbage(command, protocol::hex(&p))),
                Some(Reply::Completion(s)) => self.free(s),
                Some(Reply::Error(s, ViscaError::Cancelled)) if s != 0 => self.free(s),
                Some(r) => return Ok(r),
            }
        }
    }

    fn free(&mut self, socket: u8) {
        if let Some(b) = self.busy.get_mut(socket as usize) {
            *b = false;
        }
    }

    /// Sends a broadcast and expects `expect` back.
    pub fn broadcast(&mut self, p: &[u8], expect: &[u8]) -> Result<(), LinkError> {
        self.send(p)?;
        match self.reply(p, self.timeout)? {
            Reply::Broadcast(b) if b == expect => Ok(()),
            other => Err(self.unexpected(
                p,
                &other,
                &format!("the broadcast reply {}", protocol::hex(expect)),
            )),
        }
    }

    /// Sends a command and waits for its ACK (not its completion); returns the
    /// socket it went into. A VISCA error is returned as such.
    pub fn command(&mut self, p: &[u8]) -> Result<u8, LinkError> {
        self.send(p)?;
        match self.reply(p, self.timeout)? {
            Reply::Ack(s) => {
                if let Some(b) = self.busy.get_mut(s as usize) {
                    *b = true;
                }
                Ok(s)
            }
            Reply::Error(_, error) => Err(LinkError::Visca {
                port: self.name.clone(),
                command: protocol::hex(p),
                error,
            }),
            other => Err(self.unexpected(p, &other, "an ACK")),
        }
    }

    /// Sends a command and waits for its ACK and its completion (power on/off).
    pub fn command_done(&mut self, p: &[u8], timeout: Duration) -> Result<(), LinkError> {
        let s = self.command(p)?;
        let t0 = Instant::now();
        while self.busy.get(s as usize).copied().unwrap_or(false) {
            let left = timeout.saturating_sub(t0.elapsed());
            let Some(packet) = self.packet(p, left)? else {
                return Err(self.silent(p));
            };
            match protocol::classify(self.addr, &packet) {
                Some(Reply::Completion(x)) => self.free(x),
                Some(Reply::Error(_, error)) => {
                    return Err(LinkError::Visca {
                        port: self.name.clone(),
                        command: protocol::hex(p),
                        error,
                    });
                }
                _ => return Err(self.garbage(p, protocol::hex(&packet))),
            }
        }
        Ok(())
    }

    /// Sends an inquiry; returns the answer's bytes.
    pub fn inquiry(&mut self, p: &[u8]) -> Result<Vec<u8>, LinkError> {
        self.send(p)?;
        match self.reply(p, self.timeout)? {
            Reply::Answer(a) => Ok(a),
            Reply::Error(_, error) => Err(LinkError::Visca {
                port: self.name.clone(),
                command: protocol::hex(p),
                error,
            }),
            other => Err(self.unexpected(p, &other, "an inquiry answer")),
        }
    }

    /// Pan and tilt, device units (refused outside the camera's range).
    pub fn pantilt(&mut self) -> Result<(i32, i32), LinkError> {
        let q = protocol::pantilt_inquiry(self.addr);
        let a = self.inquiry(&q)?;
        match (
            a.len(),
            protocol::from_nibbles(a.get(..4).unwrap_or(&[])),
            protocol::from_nibbles(a.get(4..8).unwrap_or(&[])),
        ) {
            (8, Some(p), Some(t)) => {
                Ok((self.in_range(&q, "pan", p)?, self.in_range(&q, "tilt", t)?))
            }
            _ => Err(self.garbage(&q, protocol::hex(&a))),
        }
    }

    /// Zoom, device units (refused outside the camera's range).
    pub fn zoom(&mut self) -> Result<i32, LinkError> {
        let q = protocol::zoom_inquiry(self.addr);
        let a = self.inquiry(&q)?;
        match (a.len(), protocol::from_nibbles(&a)) {
            (4, Some(z)) => self.in_range(&q, "zoom", z),
            _ => Err(self.garbage(&q, protocol::hex(&a))),
        }
    }
}

/// Resynchronises the line ([`Link::flush`]), then address set, IF_Clear, power
/// on if it is off.
pub fn init(link: &mut Link) -> Result<(), LinkError> {
    link.flush()?;
    link.broadcast(&protocol::address_set(), &[0x88, 0x30, 0x02, 0xFF])?;
    link.broadcast(&protocol::if_clear(), &protocol::if_clear())?;
    let q = protocol::power_inquiry(link.addr);
    let on = match link.inquiry(&q)?.as_slice() {
        [0x02] => true,
        [0x03] | [0x04] => false,
        other => return Err(link.garbage(&q, protocol::hex(other))),
    };
    if !on {
        link.command_done(&protocol::power(link.addr, true), Duration::from_secs(15))?;
    }
    Ok(())
}

/// The pan-tilt command for a `PtMotors` value, 4.3's way; `here` is the current
/// position (units) for speed 0. Returns (pan mode, tilt mode, pan, tilt).
pub fn pantilt_target(m: &PtMotors, here: (i32, i32)) -> (u8, u8, i32, i32) {
    let pan_speed = limit(m.longitude_speed, 0.0, protocol::PAN_MAX_SPEED);
    let tilt_speed = limit(m.latitude_speed, 0.0, protocol::TILT_MAX_SPEED);
    let (pm, pan) = match protocol::speed_mode(pan_speed, protocol::PAN_MODES) {
        Some(mode) => (
            mode,
            protocol::deg_to_units(m.longitude, protocol::PAN_LIMIT, protocol::PAN_UNITS),
        ),
        None => (protocol::PAN_MODES, here.0),
    };
    let (tm, tilt) = match protocol::speed_mode(tilt_speed, protocol::TILT_MODES) {
        Some(mode) => (
            mode,
            protocol::deg_to_units(m.latitude, protocol::TILT_LIMIT, protocol::TILT_UNITS),
        ),
        None => (protocol::TILT_MODES, here.1),
    };
    (pm, tm, pan, tilt)
}

/// The camera as the supervisor sees it.
struct Evi {
    conf: EviConf,
    provider: String,
    pte: Option<Arc<Interface<PtEncoders>>>,
    ptm: Option<Arc<Interface<PtMotors>>>,
    ze: Option<Arc<Interface<ZoomEncoders>>>,
    zm: Option<Arc<Interface<ZoomMotors>>>,
    /// The open session (kept here, not in the supervisor's hands, so that a stop
    /// can power the camera off as 4.3 did; a lost session is dropped first).
    session: Option<EviSession>,
}

/// One session with the camera.
struct EviSession {
    link: Link,
    /// Where the head was last seen (VISCA units).
    here: (i32, i32),
    pt: Pending<(u8, u8, i32, i32)>,
    zoom: Pending<i32>,
    poll: PollClock,
}

/// What was last sent for a command interface, and the interface clock it answered.
#[derive(Default)]
struct Pending<K> {
    sent: Option<K>,
    clock: Option<u64>,
}

/// Sends `p` unless a busy buffer says to try later; VISCA refusals are reported on
/// `refused` (an interface to mark stale). Returns whether it went out (or was
/// refused for good).
fn try_command<T: crate::interfaces::InterfaceValue>(
    provider: &str,
    link: &mut Link,
    p: &[u8],
    refused: Option<&Interface<T>>,
) -> Result<bool, LinkError> {
    match link.command(p) {
        Ok(_) => Ok(true),
        Err(LinkError::Visca {
            error: ViscaError::BufferFull,
            ..
        }) => Ok(false),
        Err(
            e @ LinkError::Visca {
                error: ViscaError::NotExecutable | ViscaError::NoSocket | ViscaError::Cancelled,
                ..
            },
        ) => {
            let why = format!("{provider}: {e}");
            crate::output::println(why.clone());
            if let Some(i) = refused {
                i.set_stale(why);
            }
            Ok(true)
        }
        Err(e) => Err(e),
    }
}

impl Evi {
    /// Opens the port, runs the init and reads where the head and the zoom are.
    fn open_session(&mut self) -> Result<EviSession, LinkError> {
        let head = &self.conf.head;
        let p = head.open(9600, "the camera (its VISCA cable)")?;
        let mut owned = Link::new(p, &head.serial, self.conf.camera, head.reply_timeout);
        let link = &mut owned;
        init(link)?;
        let here = link.pantilt()?;
        let mut pt: Pending<(u8, u8, i32, i32)> = Pending::default();
        let mut zoom: Pending<i32> = Pending::default();
        // The head is where it is: the initial command (clock 0) asks nothing of it.
        if let Some(m) = &self.ptm {
            let mut v = m.read().value;
            if m.clock() == 0 {
                v.longitude =
                    protocol::units_to_deg(here.0, protocol::PAN_LIMIT, protocol::PAN_UNITS);
                v.latitude =
                    protocol::units_to_deg(here.1, protocol::TILT_LIMIT, protocol::TILT_UNITS);
            }
            let _ = m.publish(v);
            pt.clock = Some(m.clock());
        }
        if let Some(z) = &self.zm {
            let mut v = z.read().value;
            if z.clock() == 0 {
                v.zoom = protocol::units_to_zoom(link.zoom()?);
            }
            let _ = z.publish(v);
            zoom.clock = Some(z.clock());
        }
        Ok(EviSession {
            link: owned,
            here,
            pt,
            zoom,
            poll: PollClock::new(self.conf.head.poll),
        })
    }

    /// Sends what changed (each command waits for its ACK), polls when due.
    fn serve(&mut self, s: &mut EviSession) -> Result<(), LinkError> {
        let EviSession {
            link,
            here,
            pt,
            zoom,
            poll,
        } = s;
        let addr = link.addr;
        if let Some(m) = &self.ptm {
            let c = m.clock();
            if pt.clock != Some(c) {
                let target = pantilt_target(&m.read().value, *here);
                if pt.sent != Some(target) {
                    let p =
                        protocol::pantilt_absolute(addr, target.0, target.1, target.2, target.3);
                    if try_command(&self.provider, link, &p, Some(m.as_ref()))? {
                        pt.sent = Some(target);
                        pt.clock = Some(c);
                    }
                } else {
                    pt.clock = Some(c);
                }
            }
        }
        if let Some(z) = &self.zm {
            let c = z.clock();
            if zoom.clock != Some(c) {
                let units = protocol::zoom_to_units(z.read().zoom);
                if zoom.sent != Some(units) {
                    let p = protocol::zoom_direct(addr, units);
                    if try_command(&self.provider, link, &p, Some(z.as_ref()))? {
                        zoom.sent = Some(units);
                        zoom.clock = Some(c);
                    }
                } else {
                    zoom.clock = Some(c);
                }
            }
        }
        if poll.due() {
            *here = link.pantilt()?;
            if let Some(e) = &self.pte {
                let _ = e.publish(PtEncoders {
                    pan_angle: protocol::units_to_deg(
                        here.0,
                        protocol::PAN_LIMIT,
                        protocol::PAN_UNITS,
                    ),
                    tilt_angle: protocol::units_to_deg(
                        here.1,
                        protocol::TILT_LIMIT,
                        protocol::TILT_UNITS,
                    ),
                });
            }
            if let Some(e) = &self.ze {
                let z = link.zoom()?;
                let _ = e.publish(ZoomEncoders {
                    zoom_position: protocol::units_to_zoom(z),
                });
            }
        }
        poll.pause();
        Ok(())
    }
}

impl Device for Evi {
    type Session = ();
    fn open(&mut self) -> Result<(), String> {
        self.session = Some(self.open_session().map_err(|e| e.to_string())?);
        Ok(())
    }
    fn step(&mut self, _: &mut ()) -> Result<(), String> {
        let Some(mut s) = self.session.take() else {
            return Err("no session".into());
        };
        self.serve(&mut s).map_err(|e| e.to_string())?;
        self.session = Some(s);
        Ok(())
    }
    /// On a stop with the camera answering: power off, as 4.3 did.
    fn on_loss(&mut self) {
        if let Some(mut s) = self.session.take() {
            let addr = s.link.addr;
            if let Err(e) = s
                .link
                .command_done(&protocol::power(addr, false), Duration::from_secs(2))
            {
                tracing::warn!("{}: {e}", self.provider);
            }
        }
    }
}

/// 4.3's limits on `pantiltmotors`, speeds at their maxima.
fn initial_pantilt() -> PtMotors {
    PtMotors {
        longitude: 0.0,
        latitude: 0.0,
        longitude_speed: protocol::PAN_MAX_SPEED,
        latitude_speed: protocol::TILT_MAX_SPEED,
        max_longitude: protocol::PAN_LIMIT,
        min_longitude: -protocol::PAN_LIMIT,
        max_latitude: protocol::TILT_LIMIT,
        min_latitude: -protocol::TILT_LIMIT,
        max_longitude_speed: protocol::PAN_MAX_SPEED,
        max_latitude_speed: protocol::TILT_MAX_SPEED,
    }
}

/// Provides the interfaces and starts the thread (a port that cannot be opened is
/// reported and retried; the rest of the run goes on).
pub fn start(conf: EviConf, rt: &Runtime, provider: &str) -> anyhow::Result<Supervisor> {
    let ifs = &rt.interfaces;
    let pte = (conf.head)
        .provides("pantiltencoders")
        .then(|| ifs.provide::<PtEncoders>("pantiltencoders", provider))
        .transpose()?;
    let ptm = (conf.head)
        .provides("pantiltmotors")
        .then(|| ifs.provide_value("pantiltmotors", provider, initial_pantilt()))
        .transpose()?;
    let ze = (conf.head)
        .provides("zoomencoders")
        .then(|| ifs.provide::<ZoomEncoders>("zoomencoders", provider))
        .transpose()?;
    let zm = (conf.head)
        .provides("zoommotors")
        .then(|| {
            ifs.provide_value(
                "zoommotors",
                provider,
                ZoomMotors {
                    zoom: 0.0,
                    zoom_speed: protocol::ZOOM_MAX_SPEED,
                    max_zoom: protocol::ZOOM_MAX,
                    min_zoom: 0.0,
                    max_zoom_speed: protocol::ZOOM_MAX_SPEED,
                },
            )
        })
        .transpose()?;
    let interfaces = [
        pte.clone().map(|i| i as Arc<dyn AnyInterface>),
        ptm.clone().map(|i| i as Arc<dyn AnyInterface>),
        ze.clone().map(|i| i as Arc<dyn AnyInterface>),
        zm.clone().map(|i| i as Arc<dyn AnyInterface>),
    ];
    serialhead::supervise(
        provider,
        interfaces,
        Evi {
            conf,
            provider: provider.to_string(),
            pte,
            ptm,
            ze,
            zm,
            session: None,
        },
    )
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let c = EviConf::parse(conf)?;
    Ok(Box::new(start(c, rt, &conf.name)?))
}

crate::register_driver!(
    Driver,
    "evi",
    "Sony EVI-D100 pan-tilt-zoom camera over VISCA: pantiltencoders, pantiltmotors, zoomencoders, zoommotors",
    create,
    lines = Lines
);
