//! rplidar: a Slamtec RPLIDAR (A1, A2, A3, S-series) on a serial line, through its
//! documented protocol (Slamtec, *RPLIDAR Interface Protocol and Application
//! Notes*): GET_INFO and GET_HEALTH at start, then SCAN's standard 5-byte nodes,
//! each revolution one 360° scan.
//!
//! # Conf
//! ```text
//! driver rplidar
//! serial /dev/ttyUSB0        # the port (required; the A1's adapter is a CP2102: ttyUSB)
//! baud 115200                # 115200 for A1/A2 (default), 256000 for A3/S1
//! max_range 12000            # mm: the model's range (A1 12 m); no return reads this
//! mount 0 0 0                # X Y mm, YAW deg: where the lidar sits on the robot
//! reply_timeout 1000         # ms without a good node: the lidar counts as lost
//! provides laser 360 1       # N RESOLUTION (default 360 1: one reading a degree)
//! end_driver
//! ```
//!
//! # Interfaces
//! | interface | fields and units |
//! |---|---|
//! | `laser` | N readings, mm, at RESOLUTION per degree from −N/(2R)°, counter-clockwise (the device's clockwise angles turned), each the node nearest its angle in one revolution; no return → `max_range`; one scan per revolution (≈5.5 Hz on an A1) |
//!
//! # Behaviour
//! - Opening: the motor started (DTR cleared, as on the common USB adapter; the
//!   motor-speed command too on an A2 or later), STOP, GET_INFO (model, firmware,
//!   hardware, serial number) and GET_HEALTH (an error health is a loss naming its
//!   code: the scan is not started), then SCAN.
//! - Each node is checked (S ≠ !S, C = 1, angle < 360°); a bad one, garbage, a
//!   wrong descriptor or another device make one line naming the port and what was
//!   expected, the laser stale, and the driver resynchronises byte by byte on the
//!   next good nodes. No good node for `reply_timeout` is a loss; the supervisor
//!   reopens the port every second (a cable pulled and plugged back is found again).
//! - Each revolution is checked as a whole before it is published
//!   ([`protocol::LIMITS`]): 1..25 revolutions a second, 64 nodes or more round
//!   320° or more, no byte skipped while it was gathered, at most 10 % of its
//!   angles going backwards and 20 % of its distances with quality 0. Random bytes pass the node checks one window in
//!   six, and would make hundreds of "scans" a second; they make no revolution
//!   that passes these, so the laser is stale (the reason says which check failed,
//!   one line when the trouble starts) until plausible revolutions come again. A
//!   revolution that lasts over a second (a stalled motor) is stale too.
//! - At stop: STOP and the motor stopped (DTR set).
//! - Model, firmware, serial number and health are the driver's status line
//!   ([`Status`], exported as `NAME.status`, and `ps` prints it). Express scans are not used.
//!
//! System packages: none (the `serialport` crate). Your user needs the port's group
//! (usually `dialout`).

pub mod protocol;

use std::{
    sync::Arc,
    time::{Duration, Instant},
};

use crate::{
    conf::{
        ComponentConf,
        settings::{Setting, float, int, kinds},
    },
    interfaces::{AnyInterface, Interface, Kind, Laser, Mount},
    runtime::{Backoff, Device, Driver, Runtime, Supervision, Supervisor},
    serialhead::{REPLY_TIMEOUT, SERIAL, open_port},
};
use protocol::{Info, Revolution};

const USAGE: &str = "provides laser [N RESOLUTION] (default 360 1)";

crate::declare_lines! {
    /// The lines `rplidar` takes (`jderobot help rplidar`).
    struct Lines {
        serial: String = SERIAL.help("the serial port the lidar is on, e.g. /dev/ttyUSB0"),
        baud: u32 = Setting::new(
            "baud",
            "the line speed: 115200 for an A1 or A2, 256000 for an A3 or S1",
            &[int("RATE", "baud", 9600, 1_000_000)],
        )
        .default("115200"),
        max_range: i32 = Setting::new(
            "max_range",
            "the model's farthest range; a reading without a return reads this",
            &[int("MM", "mm", 100, 100_000)],
        )
        .default("12000"),
        mount: (f64, f64, f64) = Setting::new(
            "mount",
            "where the lidar sits on the robot: X forward, Y left (mm), YAW counter-clockwise (deg)",
            &[
                float("X", "mm", -10_000.0, 10_000.0),
                float("Y", "mm", -10_000.0, 10_000.0),
                float("YAW", "deg", -360.0, 360.0),
            ],
        )
        .default("0 0 0"),
        reply_timeout: u64 = REPLY_TIMEOUT
            .help("how long an answer, or a good scan node, may take before the lidar counts as lost"),
        /// `provides laser [N RESOLUTION]`: the scan's readings and readings/deg.
        provides: (Kind, Option<usize>, Option<f64>) = Setting::new(
            "provides",
            USAGE,
            &[
                kinds("laser", &[Kind::Laser]),
                int("N", "", 1, 7200).optional(),
                float("RESOLUTION", "readings/deg", 0.01, 20.0),
            ],
        )
        .required(),
    }
}
/// The driver's settings.
#[derive(Clone, Debug)]
pub struct LidarConf {
    pub serial: String,
    pub baud: u32,
    pub max_range: i32,
    pub mount: Mount,
    pub reply_timeout: Duration,
    pub n: usize,
    pub per_deg: f64,
}

impl LidarConf {
    pub fn parse(conf: &ComponentConf) -> anyhow::Result<LidarConf> {
        let l: Lines = conf.read()?;
        let (_, n, per_deg) = l.provides;
        let (n, per_deg) = (n.unwrap_or(360), per_deg.unwrap_or(1.0));
        if n as f64 / per_deg > 360.0 + 1e-9 {
            let p = conf.lines_with("provides").next().expect("read above");
            return Err(p
                .error(format!(
                    "`provides laser {n} {per_deg}` spans {:.1}°; a revolution is 360° (N / RESOLUTION must be 360 or less)",
                    n as f64 / per_deg
                ))
                .into());
        }
        Ok(LidarConf {
            serial: l.serial,
            baud: l.baud,
            max_range: l.max_range,
            mount: Mount {
                x: l.mount.0 as f32,
                y: l.mount.1 as f32,
                yaw: l.mount.2 as f32,
            },
            reply_timeout: Duration::from_millis(l.reply_timeout),
            n,
            per_deg,
        })
    }
}

/// The lidar's status line (model, firmware, serial number, health).
#[derive(Default)]
pub struct Status(pub parking_lot::Mutex<String>);

impl Status {
    pub fn line(&self) -> String {
        self.0.lock().clone()
    }
}

struct Lidar {
    conf: LidarConf,
    laser: Arc<Interface<Laser>>,
    status: Arc<Status>,
    /// Reused scan buffer.
    out: Vec<i32>,
}

struct Session {
    port: Box<dyn serialport::SerialPort>,
    buf: Vec<u8>,
    rev: Revolution,
    last_good: Instant,
    /// The stream's trouble, said once until a plausible revolution comes.
    trouble: Option<Trouble>,
    pwm: bool,
}

const RETRY: Duration = Duration::from_secs(1);
/// The motor duty the SDK uses by default on A2/A3.
const DEFAULT_PWM: u16 = 660;

impl Lidar {
    fn port_err(&self, what: impl std::fmt::Display) -> String {
        format!("{}: {what}", self.conf.serial)
    }

    fn write(&self, port: &mut dyn serialport::SerialPort, b: &[u8]) -> Result<(), String> {
        port.write_all(b)
            .and_then(|_| port.flush())
            .map_err(|e| self.port_err(format!("the port failed ({e}); was the lidar unplugged?")))
    }

    fn read_into(
        &self,
        port: &mut dyn serialport::SerialPort,
        buf: &mut Vec<u8>,
    ) -> Result<bool, String> {
        let mut b = [0u8; 1024];
        match port.read(&mut b) {
            Ok(0) => Err(self.port_err("the port closed; was the lidar unplugged?")),
            Ok(n) => {
                buf.extend_from_slice(&b[..n]);
                Ok(true)
            }
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Ok(false),
            Err(e) => {
                Err(self.port_err(format!("the port failed ({e}); was the lidar unplugged?")))
            }
        }
    }

    /// Sends `cmd` and reads its descriptor and (single) answer of `len` bytes of `kind`.
    fn ask(
        &self,
        port: &mut dyn serialport::SerialPort,
        cmd: u8,
        name: &str,
        kind: u8,
        len: usize,
    ) -> Result<Vec<u8>, String> {
        self.write(port, &protocol::request(cmd))?;
        let mut buf = Vec::new();
        let t0 = Instant::now();
        while buf.len() < 7 + len {
            if t0.elapsed() > self.conf.reply_timeout {
                return Err(self.port_err(if buf.is_empty() {
                    format!(
                        "no answer to {name} in {} ms (expected A5 5A ...); is the lidar powered, on this port, at {} baud?",
                        self.conf.reply_timeout.as_millis(),
                        self.conf.baud
                    )
                } else {
                    format!(
                        "a half answer to {name} ({} of {} bytes: {})",
                        buf.len(),
                        7 + len,
                        hex(&buf)
                    )
                }));
            }
            self.read_into(port, &mut buf)?;
        }
        let d: [u8; 7] = buf[..7].try_into().unwrap_or_default();
        match protocol::descriptor(&d) {
            Some(d) if d.kind == kind && d.len as usize == len => Ok(buf[7..7 + len].to_vec()),
            _ => Err(self.port_err(format!(
                "the answer to {name} is {} (expected the descriptor A5 5A {:02X} 00 00 00 {:02X}); another device on the port, or a wrong baud rate?",
                hex(&buf[..buf.len().min(12)]),
                len,
                kind
            ))),
        }
    }

    fn open_session(&mut self) -> Result<Session, String> {
        let c = &self.conf;
        let mut port = open_port(&c.serial, c.baud, "the lidar").map_err(|e| self.port_err(e))?;
        // The A1's adapter drives the motor from DTR: cleared runs it.
        let _ = port.write_data_terminal_ready(false);
        self.write(&mut *port, &protocol::request(protocol::STOP))?;
        // The protocol asks for ≥1 ms after STOP; drop the rest of an old scan.
        std::thread::sleep(Duration::from_millis(20));
        let _ = port.clear(serialport::ClearBuffer::Input);
        let info = self.ask(
            &mut *port,
            protocol::GET_INFO,
            "GET_INFO",
            protocol::TYPE_INFO,
            20,
        )?;
        let info = Info::parse(&info)
            .ok_or_else(|| self.port_err("a GET_INFO answer that is not 20 bytes"))?;
        let h = self.ask(
            &mut *port,
            protocol::GET_HEALTH,
            "GET_HEALTH",
            protocol::TYPE_HEALTH,
            3,
        )?;
        let (health, code) = protocol::health(&h).unwrap_or((2, 0xFFFF));
        let health_word = match health {
            0 => "good".to_string(),
            1 => format!("warning (code 0x{code:04X})"),
            _ => format!("ERROR (code 0x{code:04X})"),
        };
        *self.status.0.lock() = format!(
            "RPLIDAR {} (model 0x{:02X}) firmware {}.{:02} hardware {} serial {}, health {}",
            info.family(),
            info.model,
            info.firmware.0,
            info.firmware.1,
            info.hardware,
            info.serial_hex(),
            health_word
        );
        if health >= 2 {
            let _ = port.write_data_terminal_ready(true);
            return Err(self.port_err(format!(
                "the lidar reports a hardware error (health code 0x{code:04X}); the scan is not started (power it off and on, or send RESET)"
            )));
        }
        // A2 and later have a motor-speed command.
        let pwm = info.model >> 4 >= 2;
        if pwm {
            self.write(
                &mut *port,
                &protocol::request_with(protocol::SET_MOTOR_PWM, &DEFAULT_PWM.to_le_bytes()),
            )?;
        }
        self.write(&mut *port, &protocol::request(protocol::SCAN))?;
        let mut buf = Vec::with_capacity(4096);
        let t0 = Instant::now();
        while buf.len() < 7 {
            if t0.elapsed() > c.reply_timeout {
                return Err(self.port_err("no answer to SCAN (expected A5 5A 05 00 00 40 81)"));
            }
            self.read_into(&mut *port, &mut buf)?;
        }
        let d: [u8; 7] = buf[..7].try_into().unwrap_or_default();
        match protocol::descriptor(&d) {
            Some(d) if d.kind == protocol::TYPE_SCAN && d.len == 5 && d.mode == 1 => {}
            _ => {
                return Err(self.port_err(format!(
                    "the answer to SCAN is {} (expected A5 5A 05 00 00 40 81)",
                    hex(&buf[..7])
                )));
            }
        }
        buf.drain(..7);
        let start = Laser::centred_start(c.n, c.per_deg) as f64;
        Ok(Session {
            port,
            buf,
            rev: Revolution::new(c.n, c.per_deg, start, c.max_range),
            last_good: Instant::now(),
            trouble: None,
            pwm,
        })
    }

    /// Decodes the nodes in the buffer, read at `now`; publishes each finished
    /// revolution that is plausible ([`protocol::LIMITS`]).
    pub fn nodes(&mut self, s: &mut Session, now: Instant) {
        let mut i = 0;
        while i + 5 <= s.buf.len() {
            match protocol::node(&s.buf[i..i + 5]) {
                Some(nd) => {
                    s.last_good = now;
                    if let Some(st) = s.rev.push(&nd, now, &mut self.out) {
                        match st.implausible(&protocol::LIMITS) {
                            None => self.publish(s),
                            Some(why) => self.trouble(s, Trouble::Revolutions, &why),
                        }
                    }
                    i += 5;
                }
                None => {
                    s.rev.skipped(1);
                    if s.trouble.is_none() {
                        self.trouble(
                            s,
                            Trouble::Bytes,
                            "bytes that are no scan node (expected 5-byte nodes with S ≠ !S and C = 1)",
                        );
                    }
                    i += 1;
                }
            }
        }
        s.buf.drain(..i);
        // A revolution that never ends: the motor stalled, or nodes without start flags.
        let longest = Duration::from_secs_f64(1.0 / protocol::LIMITS.min_hz);
        if let Some(d) = s.rev.going_for(now)
            && d > longest
            && s.trouble.is_none_or(|t| t != Trouble::Revolutions)
        {
            let why = format!(
                "no start flag for {} ms (expected a revolution at {} revolutions/s or more); the motor stalled?",
                d.as_millis(),
                protocol::LIMITS.min_hz
            );
            self.trouble(s, Trouble::Revolutions, &why);
        }
    }

    /// Publishes the revolution just finished (in `self.out`); the laser is good again.
    fn publish(&mut self, s: &mut Session) {
        let (c, out) = (&self.conf, &self.out);
        let start = Laser::centred_start(c.n, c.per_deg);
        let _ = self.laser.write(|l| {
            l.readings.clear();
            l.readings.extend_from_slice(out);
            l.resolution = c.per_deg as f32;
            l.start = start;
            l.min_range = 0.0;
            l.max_range = c.max_range as f32;
            l.mount = c.mount;
        });
        if s.trouble.take().is_some() {
            tracing::info!("{}: plausible revolutions again", self.conf.serial);
        }
    }

    /// Marks the laser stale with `what` (the port named); one line when the
    /// kind of trouble changes.
    fn trouble(&self, s: &mut Session, kind: Trouble, what: &str) {
        let why = match kind {
            Trouble::Bytes => {
                self.port_err(format!("{what}; another device, or a wrong baud rate?"))
            }
            Trouble::Revolutions => self.port_err(format!(
                "scan not believed: {what}; noise on the line, a wrong baud rate or another device?"
            )),
        };
        if s.trouble != Some(kind) {
            tracing::warn!("{why}; the laser is stale until plausible revolutions come");
            s.trouble = Some(kind);
        }
        self.laser.set_stale(&why);
    }

    fn serve(&mut self, s: &mut Session) -> Result<(), String> {
        if self.read_into(&mut *s.port, &mut s.buf)? {
            self.nodes(s, Instant::now());
        }
        if s.last_good.elapsed() > self.conf.reply_timeout {
            return Err(self.port_err(format!(
                "no good scan node for {} ms; was the lidar switched off or its motor stalled?",
                self.conf.reply_timeout.as_millis()
            )));
        }
        Ok(())
    }
}

/// What is wrong with the scan stream, as said once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Trouble {
    /// Bytes that are no node (a glitch, until the revolution is checked).
    Bytes,
    /// Revolutions that cannot be a lidar's.
    Revolutions,
}

fn hex(b: &[u8]) -> String {
    b.iter()
        .map(|x| format!("{x:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

impl Device for Lidar {
    type Session = Session;
    fn open(&mut self) -> Result<Session, String> {
        self.open_session()
    }
    fn step(&mut self, s: &mut Session) -> Result<(), String> {
        self.serve(s)
    }
    fn close(&mut self, mut s: Session) {
        let _ = self.write(&mut *s.port, &protocol::request(protocol::STOP));
        if s.pwm {
            let _ = self.write(
                &mut *s.port,
                &protocol::request_with(protocol::SET_MOTOR_PWM, &[0, 0]),
            );
        }
        let _ = s.port.write_data_terminal_ready(true);
    }
}

/// Provides the laser and starts supervising the lidar.
pub fn start(conf: LidarConf, rt: &Runtime, provider: &str) -> anyhow::Result<Supervisor> {
    let start = Laser::centred_start(conf.n, conf.per_deg);
    let laser = rt.interfaces.provide_value(
        "laser",
        provider,
        Laser {
            readings: vec![conf.max_range; conf.n],
            resolution: conf.per_deg as f32,
            start,
            min_range: 0.0,
            max_range: conf.max_range as f32,
            mount: conf.mount,
        },
    )?;
    let status = rt
        .names
        .export(provider, "status", Status::default())
        .map_err(|e| anyhow::anyhow!("{provider}: {e}"))?;
    let all: Vec<Arc<dyn AnyInterface>> = vec![laser.clone()];
    Supervisor::start(
        Supervision {
            name: provider.to_string(),
            interfaces: all,
            on_demand: false,
            backoff: Backoff::fixed(RETRY),
            absent: None,
        },
        Lidar {
            conf,
            laser,
            status,
            out: Vec::new(),
        },
    )
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let c = LidarConf::parse(conf)?;
    Ok(Box::new(start(c, rt, &conf.name)?))
}

// Its `ps` line: `rplidar: ...` (the driver's [`Status`]).
crate::register_ps_line!("rplidar", |rt| {
    rt.names
        .import::<Status>("rplidar", "status")
        .ok()
        .map(|s| s.line())
        .filter(|l| !l.is_empty())
});

crate::register_driver!(
    Driver,
    "rplidar",
    "Slamtec RPLIDAR (A1/A2/A3/S) on a serial line: a 360° laser, one scan per revolution",
    create,
    lines = Lines
);
