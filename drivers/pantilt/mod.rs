//! pantilt: the Directed Perception pan-tilt unit (PTU-46) on a serial line, with
//! its ASCII command set, as JDE 4.3's `pantilt` driver drove it.
//!
//! # Conf
//! ```text
//! driver pantilt
//! serial /dev/ttyUSB0        # the serial port (required)
//! baud 9600                  # line speed (default 9600, the unit's default)
//! poll 300                   # ms between position queries (default 300, as 4.3)
//! reply_timeout 1000         # ms to wait for a reply before the unit counts as silent
//! provides pantiltencoders
//! provides pantiltmotors
//! end_driver
//! ```
//!
//! # Interfaces
//! | interface | fields and units |
//! |---|---|
//! | `pantiltencoders` | `pan_angle`, `tilt_angle` deg (encoder steps × 3.086/60, 4.3's `ENCOD_TO_DEG`), polled every `poll` ms |
//! | `pantiltmotors` | `longitude`, `latitude` deg (clamped to the limits the unit reports: `PN PX TN TX`); `longitude_speed`, `latitude_speed` deg/s in [0, 205.89]; speed 0 stops the axis (`PS0`, as 4.3); limits read-only |
//!
//! # Behaviour
//! - Opening: 4.3's init sequence (`\xFF\xFF`, `I`, `CI`, `PB1000` ... `PP0`, `TP0`,
//!   `LE`), then the limits are queried (`PN`, `PX`, `TN`, `TX`) and published on
//!   `pantiltmotors`; its speeds start at the init's 2900 steps/s (149.15 deg/s).
//! - A command goes out only when it changes (`PS`/`TS` before `PP`/`TP`), within a
//!   millisecond of being set; positions are polled with `PP` and `TP`.
//! - Every reply is parsed strictly (optional echo, then `*` or `!`), and numbers are
//!   checked: limits within a PTU-46's widest range (pan ±180°, tilt ±90°), positions
//!   within the unit's limits (half a degree of slack). An error reply (`!`), silence,
//!   garbage (another device, a wrong baud rate), a number out of range or a vanished port
//!   is reported once, naming the port and what to check; both interfaces are marked
//!   stale with the reason, and the driver reopens the port every second until the
//!   unit answers again (then runs the init again). The rest of the run goes on.
//!   The unit is a [`Device`] under [`Supervisor`], which owns the thread, the
//!   retries, the stale marking and the log line per change; its shared lines and
//!   its port come from [`crate::serialhead`].
//!
//! System packages: none (the `serialport` crate without libudev). Your user needs
//! access to the port (usually the `dialout` group).

pub mod protocol;

use std::{
    io::Write,
    sync::Arc,
    time::{Duration, Instant},
};

use crate::{
    conf::{
        ComponentConf,
        settings::{Setting, choice, int},
    },
    interfaces::{AnyInterface, Interface, PtEncoders, PtMotors, limit},
    runtime::{Device, Driver, Runtime, Supervisor},
    serialhead::{
        self, HEAD, HeadConf, HeadLines, POLL, PollClock, PortError, REPLY_TIMEOUT, SERIAL,
        read_some,
    },
};
use protocol::{Axis, ENCOD_TO_DEG, Query, ReplyError};

/// The driver's settings.
#[derive(Clone, Debug)]
pub struct PtuConf {
    /// `serial`, `poll`, `reply_timeout`, `provides`.
    pub head: HeadConf,
    pub baud: u32,
}

crate::declare_lines! {
    /// The lines `pantilt` takes (`jderobot help pantilt` prints them).
    struct Lines {
        head: HeadLines = [
            SERIAL.group(HEAD),
            POLL.default("300").group(HEAD),
            REPLY_TIMEOUT.group(HEAD),
            Setting::new(
            "provides",
            "an interface it provides: pantiltencoders and/or pantiltmotors (4.3's ptencoders, ptmotors)",
            &[choice(
                "INTERFACE",
                &["pantiltencoders", "pantiltmotors", "ptencoders", "ptmotors"],
            )],
        )
        .repeats()
        .group(HEAD),
        ],
        baud: u32 = Setting::new(
            "baud",
            "the line speed (the unit's default is 9600)",
            &[int("RATE", "baud", 300, 115_200)],
        )
        .default("9600"),
    }
}
impl PtuConf {
    /// Parses the driver's lines (errors name file:line).
    pub fn parse(conf: &ComponentConf) -> anyhow::Result<PtuConf> {
        let l: Lines = conf.read()?;
        let offered = ["pantiltencoders", "pantiltmotors"];
        Ok(PtuConf {
            head: HeadConf::new(conf, l.head, &offered)?,
            baud: l.baud,
        })
    }
}

/// Why the link to the unit failed.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    #[error(transparent)]
    Port(#[from] PortError),
    #[error(
        "{port}: no reply to `{command}` in {ms} ms (is the PTU powered, on this port, at {baud} baud?)"
    )]
    Silent {
        port: String,
        command: String,
        ms: u128,
        baud: u32,
    },
    #[error("{port}: {source}")]
    Reply {
        port: String,
        #[source]
        source: ReplyError,
    },
}

/// A line-oriented link to the unit.
pub struct Link {
    port: Box<dyn serialport::SerialPort>,
    name: String,
    baud: u32,
    timeout: Duration,
    buf: Vec<u8>,
}

/// The longest reply line accepted (a PTU's longest is ~50 characters).
const MAX_LINE: usize = 256;

impl Link {
    pub fn new(
        port: Box<dyn serialport::SerialPort>,
        name: &str,
        baud: u32,
        timeout: Duration,
    ) -> Link {
        Link {
            port,
            name: name.to_string(),
            baud,
            timeout,
            buf: Vec::with_capacity(MAX_LINE),
        }
    }

    fn io(&self, e: std::io::Error) -> LinkError {
        LinkError::Port(PortError::Io {
            port: self.name.clone(),
            what: e.to_string(),
            device: "the unit",
        })
    }

    /// Writes `cmd` and its `\n`.
    pub fn send(&mut self, cmd: &[u8]) -> Result<(), LinkError> {
        let mut out = Vec::with_capacity(cmd.len() + 1);
        out.extend_from_slice(cmd);
        out.push(b'\n');
        self.port.write_all(&out).map_err(|e| self.io(e))?;
        self.port.flush().map_err(|e| self.io(e))
    }

    /// Discards what arrives for `wait`.
    pub fn drain(&mut self, wait: Duration) -> Result<(), LinkError> {
        let t0 = Instant::now();
        let mut b = [0u8; 256];
        while t0.elapsed() < wait {
            read_some(self.port.as_mut(), &mut b).map_err(|e| self.io(e))?;
        }
        self.buf.clear();
        Ok(())
    }

    /// Reads one line (without `\r\n`) answering `command`.
    pub fn read_line(&mut self, command: &str) -> Result<Vec<u8>, LinkError> {
        let t0 = Instant::now();
        let mut b = [0u8; 64];
        loop {
            if let Some(i) = self.buf.iter().position(|&c| c == b'\n') {
                let mut line: Vec<u8> = self.buf.drain(..=i).collect();
                while matches!(line.last(), Some(b'\n' | b'\r')) {
                    line.pop();
                }
                if line.iter().all(|c| c.is_ascii_whitespace()) {
                    continue;
                }
                return Ok(line);
            }
            if self.buf.len() > MAX_LINE {
                let reply = protocol::printable(&self.buf[..MAX_LINE.min(60)]);
                self.buf.clear();
                return Err(LinkError::Reply {
                    port: self.name.clone(),
                    source: ReplyError::Garbage {
                        command: command.to_string(),
                        reply: format!("{reply}... (a line of over {MAX_LINE} bytes)"),
                    },
                });
            }
            if t0.elapsed() > self.timeout {
                return Err(LinkError::Silent {
                    port: self.name.clone(),
                    command: command.to_string(),
                    ms: self.timeout.as_millis(),
                    baud: self.baud,
                });
            }
            if let Some(n) = read_some(self.port.as_mut(), &mut b).map_err(|e| self.io(e))? {
                self.buf.extend_from_slice(&b[..n]);
            }
        }
    }

    /// The reply line to `cmd`, skipping a line that only echoes the command (a
    /// unit in echo mode may end the echo with its own line end).
    fn reply_line(&mut self, cmd: &str) -> Result<Vec<u8>, LinkError> {
        loop {
            let line = self.read_line(cmd)?;
            if line.trim_ascii() != cmd.as_bytes() {
                return Ok(line);
            }
        }
    }

    /// Sends `cmd` and checks its `*` reply; returns the reply's text.
    pub fn command(&mut self, cmd: &str) -> Result<String, LinkError> {
        self.send(cmd.as_bytes())?;
        let line = self.reply_line(cmd)?;
        protocol::parse_reply(cmd, &line)
            .map(str::to_string)
            .map_err(|source| LinkError::Reply {
                port: self.name.clone(),
                source,
            })
    }

    /// `steps` answered to `q` on `axis` if they lie in `range` (of `what`).
    pub fn checked(
        &self,
        axis: Axis,
        q: Query,
        steps: i64,
        range: (i64, i64),
        what: &str,
    ) -> Result<i64, LinkError> {
        protocol::check_range(&protocol::query(axis, q).0, steps, range, what).map_err(|source| {
            LinkError::Reply {
                port: self.name.clone(),
                source,
            }
        })
    }

    /// The position of `axis` in steps, refused outside the unit's `limits` (with
    /// [`protocol::POSITION_SLACK`]).
    pub fn position(&mut self, axis: Axis, limits: (i64, i64)) -> Result<i64, LinkError> {
        let steps = self.query(axis, Query::Position)?;
        let what = format!("the unit's {} limits", axis.word().to_lowercase());
        self.checked(axis, Query::Position, steps, with_slack(limits), &what)
    }

    /// Asks `q` of `axis`; returns the steps.
    pub fn query(&mut self, axis: Axis, q: Query) -> Result<i64, LinkError> {
        let (cmd, _) = protocol::query(axis, q);
        self.send(cmd.as_bytes())?;
        let line = self.reply_line(&cmd)?;
        protocol::parse_query_line(axis, q, &line).map_err(|source| LinkError::Reply {
            port: self.name.clone(),
            source,
        })
    }
}

/// The unit's limits in steps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    pub pan: (i64, i64),
    pub tilt: (i64, i64),
}

/// Runs 4.3's init sequence and queries the limits.
pub fn init(link: &mut Link) -> Result<Limits, LinkError> {
    link.send(protocol::FLUSH)?;
    link.drain(Duration::from_millis(100))?;
    for c in protocol::INIT {
        link.command(std::str::from_utf8(c).unwrap_or_default())?;
    }
    let mut limit = |axis: Axis, q: Query| -> Result<i64, LinkError> {
        let steps = link.query(axis, q)?;
        let what = format!("a PTU-46's {}", axis.word().to_lowercase());
        link.checked(axis, q, steps, protocol::device_range(axis), &what)
    };
    let pan = (limit(Axis::Pan, Query::Min)?, limit(Axis::Pan, Query::Max)?);
    let tilt = (
        limit(Axis::Tilt, Query::Min)?,
        limit(Axis::Tilt, Query::Max)?,
    );
    Ok(Limits { pan, tilt })
}

/// `limits` widened by [`protocol::POSITION_SLACK`]: where a reported position
/// may lie.
fn with_slack(limits: (i64, i64)) -> (i64, i64) {
    (
        limits.0.saturating_sub(protocol::POSITION_SLACK),
        limits.1.saturating_add(protocol::POSITION_SLACK),
    )
}

/// What was last sent on an axis (steps, steps/s).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Sent {
    pub position: Option<i64>,
    pub speed: Option<i64>,
}

/// The commands that take an axis from `sent` to the command (`deg`, `speed` deg/s),
/// 4.3's way: speed clamped to [0, 205.89]; speed 0 sends `PS0` alone; otherwise the
/// position is clamped to the unit's limits; only what changed is sent, the speed
/// before the position.
pub fn axis_commands(
    axis: Axis,
    deg: f32,
    speed: f32,
    limits: (i64, i64),
    sent: &mut Sent,
    out: &mut Vec<String>,
) {
    let speed = limit(speed, 0.0, protocol::MAX_SPEED);
    let speed_steps = (speed as f64 / ENCOD_TO_DEG).round() as i64;
    if sent.speed != Some(speed_steps) {
        out.push(protocol::speed_command(axis, speed_steps));
        sent.speed = Some(speed_steps);
        if speed_steps == 0 {
            // The axis stops where it is: the next non-zero speed resends the position.
            sent.position = None;
        }
    }
    if speed_steps == 0 {
        return;
    }
    let lo = protocol::steps_to_deg(limits.0) as f32;
    let hi = protocol::steps_to_deg(limits.1) as f32;
    let pos = protocol::deg_to_steps(limit(deg, lo, hi) as f64).clamp(limits.0, limits.1);
    if sent.position != Some(pos) {
        out.push(protocol::position_command(axis, pos));
        sent.position = Some(pos);
    }
}

/// The initial `pantiltmotors` value: home, the init's speed, 4.3's limits until
/// the unit's are read.
fn initial_motors() -> PtMotors {
    let s = (protocol::INIT_SPEED_STEPS as f64 * ENCOD_TO_DEG) as f32;
    PtMotors {
        longitude_speed: s,
        latitude_speed: s,
        max_longitude_speed: protocol::MAX_SPEED,
        max_latitude_speed: protocol::MAX_SPEED,
        ..PtMotors::default()
    }
}

/// The unit as the supervisor sees it.
struct Ptu {
    conf: PtuConf,
    enc: Option<Arc<Interface<PtEncoders>>>,
    mot: Option<Arc<Interface<PtMotors>>>,
}

/// One session with the unit: its link, its limits, what was sent.
struct Session {
    link: Link,
    limits: Limits,
    sent: [Sent; 2],
    seen_clock: Option<u64>,
    cmds: Vec<String>,
    poll: PollClock,
}

impl Ptu {
    /// Opens the port and runs the init; publishes the unit's limits.
    fn open_session(&mut self) -> Result<Session, LinkError> {
        let head = &self.conf.head;
        let p = head.open(self.conf.baud, "the unit")?;
        let mut link = Link::new(p, &head.serial, self.conf.baud, head.reply_timeout);
        let limits = init(&mut link)?;
        if let Some(m) = &self.mot {
            // A copy of the latest command with the unit's limits (not `write`, whose
            // recycled buffer may hold an older command).
            let mut v = m.read().value;
            (v.min_longitude, v.max_longitude) = (
                protocol::steps_to_deg(limits.pan.0) as f32,
                protocol::steps_to_deg(limits.pan.1) as f32,
            );
            (v.min_latitude, v.max_latitude) = (
                protocol::steps_to_deg(limits.tilt.0) as f32,
                protocol::steps_to_deg(limits.tilt.1) as f32,
            );
            v.max_longitude_speed = protocol::MAX_SPEED;
            v.max_latitude_speed = protocol::MAX_SPEED;
            let _ = m.publish(v);
        }
        // What the init sequence left on the unit.
        let home = Sent {
            position: Some(0),
            speed: Some(protocol::INIT_SPEED_STEPS),
        };
        Ok(Session {
            link,
            limits,
            sent: [home, home],
            seen_clock: None,
            cmds: Vec::new(),
            poll: PollClock::new(self.conf.head.poll),
        })
    }

    /// Sends what changed, polls when due.
    fn serve(&mut self, s: &mut Session) -> Result<(), LinkError> {
        if let Some(m) = &self.mot {
            let c = m.clock();
            if s.seen_clock != Some(c) {
                s.seen_clock = Some(c);
                let v = m.read().value;
                s.cmds.clear();
                axis_commands(
                    Axis::Pan,
                    v.longitude,
                    v.longitude_speed,
                    s.limits.pan,
                    &mut s.sent[0],
                    &mut s.cmds,
                );
                axis_commands(
                    Axis::Tilt,
                    v.latitude,
                    v.latitude_speed,
                    s.limits.tilt,
                    &mut s.sent[1],
                    &mut s.cmds,
                );
                for c in &s.cmds {
                    s.link.command(c)?;
                }
            }
        }
        if s.poll.due() {
            // A position outside the unit's own limits is a broken reply:
            // refused (the session ends and the line is resynchronised).
            let pan = s.link.position(Axis::Pan, s.limits.pan)?;
            let tilt = s.link.position(Axis::Tilt, s.limits.tilt)?;
            if let Some(e) = &self.enc {
                let _ = e.publish(PtEncoders {
                    pan_angle: protocol::steps_to_deg(pan) as f32,
                    tilt_angle: protocol::steps_to_deg(tilt) as f32,
                });
            }
        }
        s.poll.pause();
        Ok(())
    }
}

impl Device for Ptu {
    type Session = Session;
    fn open(&mut self) -> Result<Session, String> {
        self.open_session().map_err(|e| e.to_string())
    }
    fn step(&mut self, s: &mut Session) -> Result<(), String> {
        self.serve(s).map_err(|e| e.to_string())
    }
}

/// Provides the interfaces and starts supervising the unit (a port that cannot be
/// opened is reported and retried every second; the rest of the run goes on).
pub fn start(conf: PtuConf, rt: &Runtime, provider: &str) -> anyhow::Result<Supervisor> {
    let enc = (conf.head)
        .provides("pantiltencoders")
        .then(|| {
            rt.interfaces
                .provide::<PtEncoders>("pantiltencoders", provider)
        })
        .transpose()?;
    let mot = (conf.head)
        .provides("pantiltmotors")
        .then(|| {
            rt.interfaces
                .provide_value("pantiltmotors", provider, initial_motors())
        })
        .transpose()?;
    let interfaces = [
        enc.clone().map(|i| i as Arc<dyn AnyInterface>),
        mot.clone().map(|i| i as Arc<dyn AnyInterface>),
    ];
    serialhead::supervise(provider, interfaces, Ptu { conf, enc, mot })
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let c = PtuConf::parse(conf)?;
    Ok(Box::new(start(c, rt, &conf.name)?))
}

crate::register_driver!(
    Driver,
    "pantilt",
    "Directed Perception pan-tilt unit on a serial line: pantiltencoders, pantiltmotors",
    create,
    lines = Lines
);
