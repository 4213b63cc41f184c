//! roomba: an iRobot Create 2 (a Roomba 600; Roomba 500..900 speak the same) on a
//! serial line, through its Open Interface (iRobot, *Create 2 Open Interface
//! Specification*): 115200 baud 8N1, Start then Safe (or Full) mode, Drive Direct
//! for the wheels and a sensor stream (header 19, checksum) every 15 ms.
//!
//! # Conf
//! ```text
//! driver roomba
//! serial /dev/ttyUSB0        # the port (required; iRobot's cable is an FTDI: ttyUSB)
//! baud 115200                # line speed (default 115200, the Create 2's)
//! mode safe                  # safe (default) or full (warns: no cliff, wheel-drop safety)
//! motors_timeout 500         # ms: an older motors command counts as zero
//! reply_timeout 1000         # ms without a good stream frame: the robot counts as lost
//! provides motors            # v mm/s, w deg/s → wheel speeds (±500 mm/s)
//! provides encoders          # odometry from the wheel encoder counts
//! provides bumpers           # [left bump, right bump, left wheel drop, right wheel drop]
//! provides sonars            # the light bumper's six signals as approximate ranges
//! end_driver
//! ```
//!
//! # Interfaces
//! | interface | fields and units |
//! |---|---|
//! | `motors` | `v` mm/s forward, `w` deg/s counter-clockwise → Drive Direct (right, left) mm/s; a wheel over 500 mm/s scales both down (the curve kept) |
//! | `encoders` | `x`, `y` mm, `theta` rad from packets 43/44 (508.8 counts per turn of a 72 mm wheel, 235 mm wheel base; 16-bit wrap handled), from where the driver started |
//! | `bumpers` | 4 bytes: left bump, right bump, left wheel drop, right wheel drop (packet 7) |
//! | `sonars` | 6 readings, mm: the light bump signals (packets 46..51, left to right) as `1000/√signal` capped at 250 mm: a rough, uncalibrated guess |
//!
//! # Behaviour
//! - Opening: Start (128), Safe (131) or Full (132), Stream (148) of packets 7, 21,
//!   22, 23, 25, 26, 35, 43..51. The first good frame must come within
//!   `reply_timeout`, otherwise the robot is absent (one line naming the port).
//! - Every frame's checksum is verified (all its bytes sum to 0 mod 256), its
//!   length and its packet ids, then its values: an OI mode over 3, a charging
//!   state over 5, or wheel counts that moved more than the wheels can turn at
//!   500 mm/s since the last good frame (a counter reset: odometry goes on from
//!   the new counts) are not believed. Garbage,
//!   a wrong length, a bad checksum, a half frame or such a value make one line naming the port and
//!   what was expected, the interfaces stale, and the driver resynchronises on the
//!   next header; no good frame for `reply_timeout` is a loss: the supervisor reopens
//!   the port every second (a cable pulled and plugged back is found again).
//! - Motors: Drive Direct when the wheel speeds change (and every 500 ms); zero when
//!   the command is older than `motors_timeout`, and at stop; at stop the
//!   stream is paused and Start sent, leaving the robot in Passive mode.
//! - The stop (Drive Direct 0 0) is also sent on a loss, on the port before it is
//!   dropped (a robot that stopped streaming may still listen), and whenever the
//!   process ends or is suspended: the open port's stop is registered with
//!   [`crate::estop`], which SIGINT, SIGTERM, SIGHUP, Ctrl+Z, an abort and a panic
//!   run first. The Create 2 has no watchdog of its own: what nothing can catch
//!   (`kill -9`, the computer's power) leaves the last Drive running
//!   (docs/serial-robots.md).
//! - The battery (mV, mA, mAh of mAh) and the OI mode are kept as the driver's
//!   status line ([`Status`], exported as `NAME.status` in the name space, and `ps` prints it).
//!
//! System packages: none (the `serialport` crate). Your user needs the port's group
//! (usually `dialout`).

pub mod protocol;

use std::{
    io::{Read, Write},
    sync::Arc,
    time::{Duration, Instant},
};

use crate::{
    conf::{
        ComponentConf,
        settings::{MOTORS_TIMEOUT, Setting, choice, int},
    },
    estop,
    interfaces::{AnyInterface, Bumpers, Encoders, Interface, Motors, Sonars},
    runtime::{Backoff, Device, Driver, Runtime, Supervision, Supervisor},
    serialhead::{HeadConf, HeadLines, REPLY_TIMEOUT, SERIAL, open_port},
};
use protocol::{FrameError, Odometry, Sensors};

crate::declare_lines! {
    /// The lines `roomba` takes (`jderobot help roomba`).
    struct Lines {
        serial: String = SERIAL.help("the serial port the robot is on, e.g. /dev/ttyUSB0"),
        baud: u32 = Setting::new(
            "baud",
            "the line speed (the Create 2's is 115200; 19200 after its baud-rate change)",
            &[int("RATE", "baud", 1200, 115_200)],
        )
        .default("115200"),
        mode: String = Setting::new(
            "mode",
            "the OI mode: safe (the robot's safety stays on) or full (no cliff or wheel-drop safety)",
            &[choice("MODE", &["safe", "full"])],
        )
        .default("safe"),
        motors_timeout: u64 = MOTORS_TIMEOUT,
        reply_timeout: u64 = REPLY_TIMEOUT.help(
            "how long without a good stream frame (at 15 ms each) before the robot counts as lost",
        ),
        provides: Vec<String> = Setting::new(
            "provides",
            "an interface it provides: motors, encoders, bumpers, sonars (the light bumper)",
            &[choice(
                "INTERFACE",
                &["motors", "encoders", "bumpers", "sonars", "sonar"],
            )],
        )
        .repeats(),
    }
}
/// The driver's settings.
#[derive(Clone, Debug)]
pub struct RoombaConf {
    pub head: HeadConf,
    pub baud: u32,
    pub full: bool,
    pub motors_timeout: Duration,
}

impl RoombaConf {
    pub fn parse(conf: &ComponentConf) -> anyhow::Result<RoombaConf> {
        let l: Lines = conf.read()?;
        let lines = HeadLines {
            serial: l.serial,
            poll: 15,
            reply_timeout: l.reply_timeout,
            provides: l.provides,
        };
        let head = HeadConf::new(conf, lines, &["motors", "encoders", "bumpers", "sonars"])?;
        Ok(RoombaConf {
            head,
            baud: l.baud,
            full: l.mode == "full",
            motors_timeout: Duration::from_millis(l.motors_timeout),
        })
    }
}

/// The driver's status line (battery, OI mode, frames refused), as `ps` would show it.
#[derive(Default)]
pub struct Status {
    battery: parking_lot::Mutex<String>,
    /// Frames refused since start, and the last reason.
    refused: parking_lot::Mutex<(u64, Option<String>)>,
}

impl Status {
    pub fn line(&self) -> String {
        let mut s = self.battery.lock().clone();
        let r = self.refused.lock();
        if let (n @ 1.., Some(why)) = (r.0, &r.1) {
            s.push_str(&format!("; {n} stream frame(s) refused (last: {why})"));
        }
        s
    }
    /// The last refusal's reason (port and what was expected).
    pub fn last_refused(&self) -> Option<String> {
        self.refused.lock().1.clone()
    }
}

struct Roomba {
    conf: RoombaConf,
    mot: Option<Arc<Interface<Motors>>>,
    enc: Option<Arc<Interface<Encoders>>>,
    bump: Option<Arc<Interface<Bumpers>>>,
    son: Option<Arc<Interface<Sonars>>>,
    all: Vec<Arc<dyn AnyInterface>>,
    odo: Odometry,
    status: Arc<Status>,
}

struct Session {
    port: Box<dyn serialport::SerialPort>,
    buf: Vec<u8>,
    last_good: Instant,
    /// The line's trouble, said once until a good frame comes.
    trouble: Option<String>,
    sent: Option<(i16, i16)>,
    sent_at: Instant,
    /// The port's stop, registered with [`estop`] while the session lives.
    _estop: Option<estop::Registration>,
}

/// How often a robot that cannot be opened, or went silent, is tried again.
const RETRY: Duration = Duration::from_secs(1);
/// Drive Direct is repeated this often even when unchanged.
const RESEND: Duration = Duration::from_millis(500);

impl Roomba {
    fn port_err(&self, what: impl std::fmt::Display) -> String {
        format!("{}: {what}", self.conf.head.serial)
    }

    fn write(&self, s: &mut Session, bytes: &[u8]) -> Result<(), String> {
        s.port
            .write_all(bytes)
            .and_then(|_| s.port.flush())
            .map_err(|e| self.port_err(format!("the port failed ({e}); was the robot unplugged?")))
    }

    /// Reads what arrived; true if anything did.
    fn read(&self, s: &mut Session) -> Result<bool, String> {
        let mut b = [0u8; 512];
        match s.port.read(&mut b) {
            Ok(0) => Err(self.port_err("the port closed; was the robot unplugged?")),
            Ok(n) => {
                s.buf.extend_from_slice(&b[..n]);
                Ok(true)
            }
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Ok(false),
            Err(e) => {
                Err(self.port_err(format!("the port failed ({e}); was the robot unplugged?")))
            }
        }
    }

    /// Takes the frames in the buffer: publishes each good one; says the first
    /// trouble once and marks the interfaces stale.
    fn frames(&mut self, s: &mut Session) {
        loop {
            match protocol::take_frame(&mut s.buf) {
                Ok(None) => break,
                Ok(Some(f)) => {
                    if let Some((left, right)) = self.odo.step(f.left_count, f.right_count) {
                        let max = protocol::max_counts(s.last_good.elapsed());
                        if left.abs() > max || right.abs() > max {
                            // Not believed, and the counts' new origin.
                            self.odo.rebase();
                            self.odo.update(f.left_count, f.right_count);
                            self.trouble(s, &FrameError::Counts { left, right, max });
                            continue;
                        }
                    }
                    s.last_good = Instant::now();
                    if s.trouble.take().is_some() {
                        tracing::info!("{}: stream frames good again", self.conf.head.serial);
                    }
                    self.publish(&f);
                }
                Err(e) => self.trouble(s, &e),
            }
        }
        // A frame can be no longer than this: what is left must be a start.
        if s.buf.len() > 4 * (protocol::frame_n() + 3) {
            let n = s.buf.len();
            s.buf.clear();
            self.trouble(s, &FrameError::Garbage(n));
        }
    }

    fn trouble(&self, s: &mut Session, e: &FrameError) {
        {
            let mut r = self.status.refused.lock();
            r.0 += 1;
            r.1 = Some(self.port_err(e));
        }
        if s.trouble.is_none() {
            let why = self.port_err(e);
            tracing::warn!("{why}; resynchronising on the next frame");
            for i in &self.all {
                i.set_stale(&why);
            }
            s.trouble = Some(why);
        }
    }

    fn publish(&mut self, f: &Sensors) {
        self.odo.update(f.left_count, f.right_count);
        if let Some(e) = &self.enc {
            let o = &self.odo;
            let _ = e.publish(Encoders::from_pose(o.x as f32, o.y as f32, o.theta as f32));
        }
        if let Some(b) = &self.bump {
            let _ = b.publish(Bumpers {
                bumpers: vec![
                    f.bump_left as u8,
                    f.bump_right as u8,
                    f.drop_left as u8,
                    f.drop_right as u8,
                ],
            });
        }
        if let Some(so) = &self.son {
            let _ = so.publish(Sonars {
                us: f.light.iter().map(|&x| protocol::light_range(x)).collect(),
            });
        }
        let line = format!(
            "OI mode {}, battery {:.2} V {} mA {}/{} mAh{}",
            protocol::mode_name(f.mode),
            f.voltage as f32 / 1000.0,
            f.current,
            f.charge,
            f.capacity,
            if f.mode == 1 {
                " (Passive: the robot left Safe mode, a wheel dropped or a cliff; it ignores the wheels)"
            } else {
                ""
            }
        );
        let mut st = self.status.battery.lock();
        if *st != line {
            *st = line;
        }
    }

    fn open_session(&mut self) -> Result<Session, String> {
        let c = &self.conf;
        let port = open_port(&c.head.serial, c.baud, "the robot").map_err(|e| self.port_err(e))?;
        let _estop = self.register_stop(&*port);
        let mut s = Session {
            port,
            buf: Vec::with_capacity(1024),
            last_good: Instant::now(),
            trouble: None,
            sent: None,
            sent_at: Instant::now(),
            _estop,
        };
        self.write(&mut s, &[protocol::START])?;
        std::thread::sleep(Duration::from_millis(20));
        let mode = if c.full {
            protocol::FULL
        } else {
            protocol::SAFE
        };
        self.write(&mut s, &[mode])?;
        std::thread::sleep(Duration::from_millis(20));
        let _ = s.port.clear(serialport::ClearBuffer::Input);
        self.write(&mut s, &protocol::stream_command())?;
        self.write(&mut s, &protocol::drive_direct(0, 0))?;
        s.sent = Some((0, 0));
        self.odo.rebase();
        // The first good frame.
        let t0 = Instant::now();
        let mut first_err: Option<FrameError> = None;
        while t0.elapsed() < c.head.reply_timeout {
            self.read(&mut s)?;
            loop {
                match protocol::take_frame(&mut s.buf) {
                    Ok(None) => break,
                    Ok(Some(f)) => {
                        s.last_good = Instant::now();
                        self.publish(&f);
                        return Ok(s);
                    }
                    Err(e) => {
                        first_err.get_or_insert(e);
                    }
                }
            }
        }
        Err(match first_err {
            Some(e) => self.port_err(format!(
                "{e}; is this a Create 2 / Roomba at {} baud?",
                c.baud
            )),
            None => self.port_err(format!(
                "no sensor stream in {} ms (expected frames with header 19 after Start, Safe, Stream); \
                 is the robot on, awake (press Clean) and at {} baud?",
                c.head.reply_timeout.as_millis(),
                c.baud
            )),
        })
    }

    /// Registers the port's stop with [`estop`]: Drive Direct 0 0 written through a
    /// handle of its own (a second descriptor of the port: the kernel writes each
    /// 5-byte command whole, so it cannot split one of the driver's).
    fn register_stop(&self, port: &dyn serialport::SerialPort) -> Option<estop::Registration> {
        let serial = self.conf.head.serial.clone();
        match port.try_clone() {
            Ok(w) => {
                let w = parking_lot::Mutex::new(w);
                Some(estop::register(format!("roomba {serial}"), move || {
                    if let Some(mut p) = w.try_lock_for(Duration::from_millis(50)) {
                        let _ = p.write_all(&protocol::STOP_WHEELS).and_then(|_| p.flush());
                    }
                }))
            }
            Err(e) => {
                tracing::warn!(
                    "{serial}: no second handle on the port ({e}): a signal or a panic will not stop the wheels first"
                );
                None
            }
        }
    }

    fn serve(&mut self, s: &mut Session) -> Result<(), String> {
        if let Some(m) = &self.mot {
            // Once the process is ending (estop::halt), nothing but zero.
            let cmd = if estop::halted() {
                Motors::default()
            } else {
                m.command(self.conf.motors_timeout)
            };
            let w = protocol::wheels(cmd.v, cmd.w);
            if s.sent != Some(w) || s.sent_at.elapsed() >= RESEND {
                self.write(s, &protocol::drive_direct(w.0, w.1))?;
                s.sent = Some(w);
                s.sent_at = Instant::now();
            }
        }
        if self.read(s)? {
            self.frames(s);
        }
        if s.last_good.elapsed() > self.conf.head.reply_timeout {
            return Err(self.port_err(format!(
                "no good stream frame for {} ms (expected header 19, length {}); was the robot switched off?",
                self.conf.head.reply_timeout.as_millis(),
                protocol::frame_n()
            )));
        }
        Ok(())
    }
}

impl Device for Roomba {
    type Session = Session;
    fn open(&mut self) -> Result<Session, String> {
        self.open_session()
    }
    fn step(&mut self, s: &mut Session) -> Result<(), String> {
        self.serve(s)
    }
    fn lost_session(&mut self, mut s: Session) {
        // The stream stopped or went bad, but the robot may still listen: stop
        // its wheels before the port is dropped (it is reopened after RETRY).
        let _ = self.write(&mut s, &protocol::STOP_WHEELS);
    }
    fn on_loss(&mut self) {
        if let Some(m) = &self.mot {
            let _ = m.publish(Motors::default());
        }
    }
    fn close(&mut self, mut s: Session) {
        // Wheels zero, stream paused, then Start: Passive mode, the robot left safe.
        let _ = self.write(&mut s, &protocol::drive_direct(0, 0));
        let _ = self.write(&mut s, &[protocol::PAUSE_RESUME, 0]);
        let _ = self.write(&mut s, &[protocol::START]);
    }
}

/// Provides the interfaces and starts supervising the robot.
pub fn start(conf: RoombaConf, rt: &Runtime, provider: &str) -> anyhow::Result<Supervisor> {
    if conf.full {
        crate::output::println(format!(
            "{provider}: mode full: the robot's cliff, wheel-drop and charger safety is OFF; it will drive off a stair"
        ));
    }
    let h = &conf.head;
    let mot = h
        .provides("motors")
        .then(|| rt.interfaces.provide::<Motors>("motors", provider))
        .transpose()?;
    let enc = h
        .provides("encoders")
        .then(|| rt.interfaces.provide::<Encoders>("encoders", provider))
        .transpose()?;
    let bump = h
        .provides("bumpers")
        .then(|| rt.interfaces.provide::<Bumpers>("bumpers", provider))
        .transpose()?;
    let son = h
        .provides("sonars")
        .then(|| rt.interfaces.provide::<Sonars>("sonars", provider))
        .transpose()?;
    let mut all: Vec<Arc<dyn AnyInterface>> = Vec::new();
    // The motors are the controller's: not marked stale by the robot's trouble.
    for i in [
        enc.clone().map(|i| i as Arc<dyn AnyInterface>),
        bump.clone().map(|i| i as Arc<dyn AnyInterface>),
        son.clone().map(|i| i as Arc<dyn AnyInterface>),
    ]
    .into_iter()
    .flatten()
    {
        all.push(i);
    }
    let status = rt
        .names
        .export(provider, "status", Status::default())
        .map_err(|e| anyhow::anyhow!("{provider}: {e}"))?;
    Supervisor::start(
        Supervision {
            name: provider.to_string(),
            interfaces: all.clone(),
            on_demand: false,
            backoff: Backoff::fixed(RETRY),
            absent: None,
        },
        Roomba {
            conf,
            mot,
            enc,
            bump,
            son,
            all,
            odo: Odometry::default(),
            status,
        },
    )
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let c = RoombaConf::parse(conf)?;
    Ok(Box::new(start(c, rt, &conf.name)?))
}

// Its `ps` line: `roomba: ...` (the driver's [`Status`]).
crate::register_ps_line!("roomba", |rt| {
    rt.names
        .import::<Status>("roomba", "status")
        .ok()
        .map(|s| s.line())
        .filter(|l| !l.is_empty())
});

crate::register_driver!(
    Driver,
    "roomba",
    "iRobot Create 2 / Roomba on a serial line (Open Interface): motors, encoders, bumpers, sonars",
    create,
    lines = Lines
);
