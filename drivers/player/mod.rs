//! player: a robot (a real Pioneer, or one simulated in Stage) through a Player 3
//! server, with a pure-Rust client of Player's TCP protocol (no libplayerc, no
//! system package). See `docs/player.md` and `examples/player.conf`.
//!
//! # Conf (the seed's lines, plus device indices and robot suffixes)
//! ```text
//! driver player
//! hostname localhost port 6665        # the Player server (defaults shown)
//! initial_position 1000 1000 90       # X mm, Y mm, THETA deg: the odometry offset [ROBOT]
//! provides encoders                   # position2d:0
//! provides motors                     # position2d:0
//! provides laser 180 1                # N readings at R per degree: laser:0, or Stage 4's ranger
//! provides sonars                     # sonar:0, or Stage 4's ranger:0
//! provides bumpers                    # bumper:0
//! provides pantiltencoders            # ptz:0
//! provides pantiltmotors              # ptz:0
//! provides colorA                     # camera:0 at 320x240 (varcolorA..D: the camera's size)
//! provides blobs                      # blobfinder:0, exported in the name space
//! provides laser 180 1 index 1        # any line: `index I` (device index), `device ranger:1`
//!                                     #   (the Player device, explicitly), a robot suffix:
//! provides encoders index 1 robot2    #   interface encoders.robot2 from position2d:1
//! datamode pull                       # push (the server's default) or pull
//! end_driver
//! ```
//!
//! Every line, with its arguments, ranges and defaults (`motors_timeout`,
//! `timeout`, `cycle`...), is declared once in [`conf::LINES`]: `jderobot help
//! player` prints it and `docs/player.md` shows that text.
//!
//! # Interfaces (units of the seed)
//! | interface | Player device | conversion |
//! |---|---|---|
//! | `encoders` | position2d DATA_STATE | x, y mm; θ rad in (0, 2π]; cos, sin. 4.3's offset: x = 1000(px cos θ0 − py sin θ0) + X0, y = 1000(py cos θ0 + px sin θ0) + Y0, θ = pa + θ0 |
//! | `motors` | position2d CMD_VEL | v mm/s → m/s, w deg/s → rad/s; limited to ±1000 mm/s, ±180 deg/s; sent every `cycle`; zero when older than `motors_timeout`, when the driver stops and when the server is lost |
//! | `laser` | laser SCAN (floats) or ranger RANGE (doubles) | mm; reading i at −N/(2R) + i/R deg (the nearest sample; outside the scan: max range) |
//! | `sonars` | sonar RANGES or ranger RANGE | mm, one per sonar |
//! | `bumpers` | bumper STATE | one byte per bumper, 1 = pressed |
//! | `pantiltencoders` | ptz STATE | pan, tilt rad → deg |
//! | `pantiltmotors` | ptz CMD_STATE | longitude, latitude deg → pan, tilt rad (limited); speeds deg/s → rad/s (0 = the maximum); sent when the command changes |
//! | `colorA..D`, `varcolorA..D` | camera STATE | RGB888, MONO8, MONO16, RGB565 or JPEG → BGR |
//!
//! # Name space
//! `player.blobs` (`player.blobs.ROBOT` for a suffix): [`LiveBlobs`], the latest
//! blobfinder frame ([`BlobFrame`]: image size, blobs with colour 0xRRGGBB, area,
//! centroid and box in pixels, range in mm).
//!
//! # Behaviour
//! A device is subscribed only while one of its interfaces is used (resume/suspend),
//! or while a fresh non-zero motors command is pending; blobfinders stay subscribed.
//! At start the driver connects and asks the server for its device list
//! (REQ_DEVLIST); a device the server lacks is a start error naming the line, the
//! device and the server's list. A server that is not there is one error naming
//! host:port and what to start; the interfaces stay stale and the driver keeps
//! trying, then binds the lines once the server answers (so `jderobot check` and a
//! run without the server still work, as for the other device drivers). If the
//! server goes away later, every interface is marked stale, the motors are set to
//! zero and the driver reconnects with backoff and subscribes again; it says so
//! once per change. The connection is a [`Supervisor`]'s session (open, step,
//! on loss, close), as every device driver's is. A malformed or oversized message drops the connection, which is
//! then reopened. A well-formed value an interface refuses (a NaN or an inf, a
//! number out of its documented range: `interfaces::RANGES`) or a camera frame it
//! cannot use is dropped, the last good value staying, with one log line per
//! device and change of state.
//!
//! # The stop
//! Each position2d with `motors` gets CMD_VEL 0 when the driver stops, on a
//! loss the connection may still carry (no data, a malformed message: before
//! the socket closes; a closed socket carries nothing), and whenever the
//! process ends or is suspended: while connected, the stop is registered with
//! [`crate::estop`] (SIGINT, SIGTERM, SIGHUP, Ctrl+Z, an abort and a panic run
//! it first), written through a second handle on the socket; after
//! [`crate::estop::halted`] the driver sends only zero. What nothing can catch
//! (`kill -9`, power loss) sends nothing: see docs/player.md for the server's side.

pub mod client;
pub mod conf;
pub mod sinks;
pub mod xdr;

use std::{
    collections::BTreeMap,
    io::Write,
    sync::Arc,
    time::{Duration, Instant},
};

use crate::{
    conf::ComponentConf,
    estop,
    interfaces::{Image, Interface, Interfaces, Motors, Mount, PtMotors, Source, limit},
    runtime::{self, Backoff, Driver, Runtime, Supervision, Supervisor},
};

use client::{Conn, ConnError, Reply};
pub use conf::{DataMode, Offset, PlayerConf, Provided};
pub use sinks::{Blob, BlobFrame, LaserMap, LiveBlobs, Sink};
use xdr::{Addr, Header, XdrError, interf, msg, player, sub};

/// 4.3's Pioneer limits.
pub const MAX_V: f32 = 1000.0;
pub const MAX_W: f32 = 180.0;

/// One Player device and what it feeds.
struct Device {
    addr: Addr,
    sinks: Vec<Sink>,
    motors: Option<Arc<Interface<Motors>>>,
    ptmotors: Option<Arc<Interface<PtMotors>>>,
    subscribed: bool,
    ranger: Option<xdr::RangerConfig>,
    /// Last ptz zoom seen (sent back unchanged with pan-tilt commands).
    zoom: f32,
    ptm_sent: u64,
    scratch: Vec<u8>,
    /// The latest camera frame, converted before it is swapped into the interface.
    frame: Image,
    /// Its values, refused (a NaN, out of range, an unusable frame) with one log
    /// line per change of state.
    source: Source,
    blob_clock: u64,
}

impl Device {
    fn used(&self, motors_timeout: Duration) -> bool {
        self.sinks.iter().any(Sink::used)
            || self
                .motors
                .as_ref()
                .is_some_and(|m| m.users() > 0 || m.command(motors_timeout) != Motors::default())
            || self.ptmotors.as_ref().is_some_and(|m| m.users() > 0)
    }

    fn set_stale(&self, why: &str) {
        // Motors to zero first: whoever sees a stale sensor sees stopped motors.
        if let Some(m) = &self.motors {
            let _ = m.publish(Motors::default());
            m.set_stale(why);
        }
        for s in &self.sinks {
            s.set_stale(why);
        }
        if let Some(m) = &self.ptmotors {
            m.set_stale(why);
        }
    }

    /// Feeds one DATA message to the sinks.
    fn data(&mut self, h: &Header, p: &[u8]) -> Result<(), XdrError> {
        let interf = self.addr.interf;
        let (ranger, zoom, scratch) = (&self.ranger, &mut self.zoom, &mut self.scratch);
        let (frame, from) = (&mut self.frame, &self.source);
        let blob_clock = &mut self.blob_clock;
        for s in &mut self.sinks {
            match (interf, h.subtype, s) {
                (interf::POSITION2D, sub::POSITION2D_DATA_STATE, Sink::Encoders(i, o)) => {
                    let p = xdr::decode_position2d(p)?;
                    i.accept(from, sinks::encoders(&p, o));
                }
                (
                    interf::LASER,
                    sub::LASER_DATA_SCAN | sub::LASER_DATA_SCANPOSE,
                    Sink::Laser(i, m),
                ) => {
                    let (info, ranges) = xdr::decode_scan(p)?;
                    // rangertolaser's first scans can carry an all-zero geometry.
                    if info.resolution > 0.0
                        && info.resolution.is_finite()
                        && info.min_angle.is_finite()
                    {
                        i.accept_with(from, |l| sinks::laser_f32(m, &info, ranges, l));
                    }
                }
                (interf::RANGER, sub::RANGER_DATA_RANGE, Sink::Laser(i, m)) => {
                    let (n, raw) = xdr::decode_ranger(p)?;
                    let cfg = ranger.unwrap_or_else(|| sinks::default_ranger_config(n));
                    if cfg.angular_res > 0.0
                        && cfg.angular_res.is_finite()
                        && cfg.min_angle.is_finite()
                    {
                        i.accept_with(from, |l| sinks::laser_f64(m, &cfg, n, raw, l));
                    }
                }
                (interf::RANGER, sub::RANGER_DATA_RANGE, Sink::Sonars(i)) => {
                    let (n, raw) = xdr::decode_ranger(p)?;
                    i.accept_with(from, |s| sinks::sonars_f64(n, raw, s));
                }
                (interf::SONAR, sub::SONAR_DATA_RANGES, Sink::Sonars(i)) => {
                    let (n, raw) = xdr::decode_sonar(p)?;
                    i.accept_with(from, |s| sinks::sonars_f32(n, raw, s));
                }
                (interf::BUMPER, sub::BUMPER_DATA_STATE, Sink::Bumpers(i)) => {
                    let raw = xdr::decode_bumpers(p)?;
                    i.accept_with(from, |b| sinks::bumpers(raw, b));
                }
                (interf::PTZ, sub::PTZ_DATA_STATE, Sink::PtEncoders(i)) => {
                    let p = xdr::decode_ptz(p)?;
                    *zoom = p.zoom;
                    i.accept(from, sinks::pantilt(&p));
                }
                (interf::CAMERA, sub::CAMERA_DATA_STATE, Sink::Camera(i, fixed)) => {
                    // A well-formed message whose image we cannot use (an unknown
                    // format, a broken JPEG, out of range) is skipped, said once per
                    // change of state; the connection stays.
                    let (info, data) = xdr::decode_camera(p)?;
                    match sinks::camera_image(&info, data, *fixed, scratch, frame) {
                        Ok(()) => {
                            i.accept_with(from, |img| std::mem::swap(img, frame));
                        }
                        Err(e) => {
                            from.refused(format_args!("camera frame skipped: {e}"));
                        }
                    }
                }
                (interf::BLOBFINDER, sub::BLOBFINDER_DATA_BLOBS, Sink::Blobs(b)) => {
                    let (w, hh, blobs) = xdr::decode_blobs(p)?;
                    *blob_clock += 1;
                    b.store(Arc::new(sinks::blob_frame(*blob_clock, w, hh, blobs)));
                }
                _ => {}
            }
        }
        if interf == interf::PTZ && h.subtype == sub::PTZ_DATA_STATE && self.ptmotors.is_some() {
            // Without pantiltencoders, still learn the zoom to send back unchanged.
            self.zoom = xdr::decode_ptz(p)?.zoom;
        }
        Ok(())
    }
}

/// A pan-tilt speed (deg/s): 0 (or less) means the unit's maximum, as 4.3's
/// pantilt drivers did.
fn speed(v: f32, max: f32) -> f32 {
    if v > 0.0 { limit(v, 0.0, max) } else { max }
}

/// The driver's state shared by the thread.
struct Session {
    pc: PlayerConf,
    devices: Vec<Device>,
    /// Lines waiting for the server's device list (it was not there at start).
    pending: Vec<Pending>,
    /// Lines the server has no device for (said once, left stale).
    unbound: Vec<Pending>,
}

fn server(pc: &PlayerConf) -> String {
    format!("{}:{}", pc.host, pc.port)
}

/// Feeds a message to the device it comes from.
fn dispatch(devices: &mut [Device], h: &Header, p: &[u8]) -> Result<(), XdrError> {
    if h.mtype != msg::DATA {
        return Ok(());
    }
    for d in devices.iter_mut() {
        if d.addr == h.addr {
            d.data(h, p)?;
        }
    }
    Ok(())
}

impl Session {
    /// CMD_VEL 0 to each position2d with motors, as the bytes of whole messages.
    fn stop_bytes(&self) -> Vec<u8> {
        let z = xdr::cmd_vel(0.0, 0.0, 0.0, true);
        let mut out = Vec::new();
        for d in self.devices.iter().filter(|d| d.motors.is_some()) {
            Header::new(d.addr, msg::CMD, sub::POSITION2D_CMD_VEL, 0, z.len()).encode(&mut out);
            out.extend_from_slice(&z);
        }
        out
    }

    fn timeout(&self) -> Duration {
        self.pc.timeout
    }

    /// Subscribes or unsubscribes each device as its use changed.
    fn sync_subscriptions(&mut self, c: &mut Conn) -> Result<(), ConnError> {
        let t = self.timeout();
        let mt = self.pc.motors_timeout;
        for k in 0..self.devices.len() {
            let want = self.devices[k].used(mt);
            if want == self.devices[k].subscribed {
                continue;
            }
            let addr = self.devices[k].addr;
            if !want && let Some(_m) = &self.devices[k].motors {
                let z = xdr::cmd_vel(0.0, 0.0, 0.0, true);
                c.send(addr, msg::CMD, sub::POSITION2D_CMD_VEL, &z)?;
            }
            let access = if want {
                player::OPEN_MODE
            } else {
                player::CLOSE_MODE
            };
            let devices = &mut self.devices;
            let reply = c.request(
                Addr::PLAYER,
                player::REQ_DEV,
                &xdr::device_req(addr, access),
                t,
                &mut |h, p| dispatch(devices, h, p),
            )?;
            let granted = match reply {
                Reply::Ack(p) => xdr::decode_device_req(&p)?.1,
                Reply::Nack => player::ERROR_MODE,
            };
            if want && granted != player::OPEN_MODE {
                return Err(ConnError::Protocol(format!(
                    "the server refused to subscribe {addr} (access {granted})"
                )));
            }
            self.devices[k].subscribed = want;
            if want && addr.interf == interf::RANGER {
                let devices = &mut self.devices;
                let r = c.request(addr, sub::RANGER_REQ_GET_CONFIG, &[], t, &mut |h, p| {
                    dispatch(devices, h, p)
                });
                self.devices[k].ranger = match r {
                    Ok(Reply::Ack(p)) => xdr::decode_ranger_config(&p).ok(),
                    Ok(Reply::Nack) | Err(ConnError::Timeout { .. }) => None,
                    Err(e) => return Err(e),
                };
            }
        }
        Ok(())
    }

    /// Sends the motors and pan-tilt commands.
    fn commands(&mut self, c: &mut Conn) -> Result<(), ConnError> {
        for d in &mut self.devices {
            if let Some(m) = &d.motors
                && d.subscribed
            {
                // Once the process is ending (estop::halt), nothing but zero.
                let cmd = if estop::halted() {
                    Motors::default()
                } else {
                    m.command(self.pc.motors_timeout)
                };
                let cmd = Motors::limited(cmd.v, cmd.w, MAX_V, MAX_W);
                let p = xdr::cmd_vel(
                    cmd.v as f64 / 1000.0,
                    0.0,
                    (cmd.w as f64).to_radians(),
                    true,
                );
                c.send(d.addr, msg::CMD, sub::POSITION2D_CMD_VEL, &p)?;
            }
            if let Some(m) = &d.ptmotors
                && d.subscribed
                && m.clock() != d.ptm_sent
            {
                let s = m.snapshot();
                d.ptm_sent = s.clock;
                let cmd = xdr::Ptz {
                    pan: limit(s.longitude, s.min_longitude, s.max_longitude).to_radians(),
                    tilt: limit(s.latitude, s.min_latitude, s.max_latitude).to_radians(),
                    zoom: d.zoom,
                    panspeed: speed(s.longitude_speed, s.max_longitude_speed).to_radians(),
                    tiltspeed: speed(s.latitude_speed, s.max_latitude_speed).to_radians(),
                };
                c.send(d.addr, msg::CMD, sub::PTZ_CMD_STATE, &xdr::ptz_cmd(&cmd))?;
            }
        }
        Ok(())
    }
}

/// The server as the [`Supervisor`] sees it: open = connect, bind the lines,
/// subscribe what is used; a step = commands, a pull, what arrives. On the shell
/// it says once per change of state that the server was lost (every interface
/// stale with the reason, the motors zero) and that it is back (once the devices
/// are subscribed again); the Supervisor logs each change and retries what
/// fails in between (no server, a refused subscription), 100 ms doubling to 2 s.
struct Link {
    session: Session,
    srv: String,
    /// The connection made at start, if the server was there.
    first: Option<Conn>,
    /// Since when the server is lost (said), if it is.
    lost_since: Option<Instant>,
    /// Why the last session ended, for `on_loss`.
    lost: Option<String>,
}

/// An open connection and what its loop keeps between steps.
struct Live {
    conn: Conn,
    next_cmd: Instant,
    awaiting_synch: bool,
    last_pull: Instant,
    silent_since: Instant,
    /// The connection's stop, registered with [`estop`] while it is open.
    _estop: Option<estop::Registration>,
}

impl runtime::Device for Link {
    type Session = Live;

    fn open(&mut self) -> Result<Live, String> {
        let pc = &self.session.pc;
        let mut conn = match self.first.take() {
            Some(c) => c,
            None => Conn::open(&pc.host, pc.port, pc.timeout)
                .map_err(|e| format!("cannot reach the Player server at {}: {e}", self.srv))?,
        };
        if let Err(e) = self.begin(&mut conn) {
            // Connected but not served (a refused subscription): a loss like any.
            conn.close();
            self.lost = Some(format!(
                "player: lost the Player server at {}: {e}; reconnecting",
                self.srv
            ));
            runtime::Device::on_loss(self);
            return Err(e.to_string());
        }
        if let Some(t) = self.lost_since.take() {
            let m = format!(
                "player: reconnected to the Player server at {} after {:.1} s; subscribed again",
                self.srv,
                t.elapsed().as_secs_f64()
            );
            crate::output::println(m);
        }
        let now = Instant::now();
        Ok(Live {
            _estop: self.register_stop(&conn),
            conn,
            next_cmd: now,
            awaiting_synch: false,
            last_pull: now - Duration::from_secs(1),
            silent_since: now,
        })
    }

    fn step(&mut self, live: &mut Live) -> Result<(), String> {
        self.session.step(live).map_err(|e| {
            self.lost = Some(format!(
                "player: lost the Player server at {}: {e}; reconnecting",
                self.srv
            ));
            e.to_string()
        })
    }

    /// The connection failed: a last CMD_VEL 0 (it may still carry one: a
    /// server that fell silent or sent garbage; a closed one carries nothing),
    /// then it closes.
    fn lost_session(&mut self, live: Live) {
        if let Ok(mut s) = live.conn.stop_handle() {
            let _ = s.write_all(&self.session.stop_bytes());
        }
        live.conn.close();
    }

    /// The session ended: nothing is subscribed, the motors are zero, and every
    /// interface is stale with the reason (said once per loss).
    fn on_loss(&mut self) {
        for d in &mut self.session.devices {
            d.subscribed = false;
        }
        let Some(why) = self.lost.take() else {
            return;
        };
        for d in &self.session.devices {
            d.set_stale(&why);
        }
        if self.lost_since.is_none() {
            crate::output::println(why);
            self.lost_since = Some(Instant::now());
        }
    }

    /// The driver stops: motors to zero, unsubscribe, close.
    fn close(&mut self, mut live: Live) {
        let c = &mut live.conn;
        for d in &mut self.session.devices {
            if d.motors.is_some() {
                let z = xdr::cmd_vel(0.0, 0.0, 0.0, true);
                let _ = c.send(d.addr, msg::CMD, sub::POSITION2D_CMD_VEL, &z);
            }
            if d.subscribed {
                let _ = c.send(
                    Addr::PLAYER,
                    msg::REQ,
                    player::REQ_DEV,
                    &xdr::device_req(d.addr, player::CLOSE_MODE),
                );
                d.subscribed = false;
            }
        }
        live.conn.finish();
    }
}

impl Link {
    /// Registers the connection's stop with [`estop`]: CMD_VEL 0 to each
    /// position2d with motors, written through a second handle on the socket
    /// (within the connection's write timeout).
    fn register_stop(&self, conn: &Conn) -> Option<estop::Registration> {
        let bytes = self.session.stop_bytes();
        if bytes.is_empty() {
            return None;
        }
        match conn.stop_handle() {
            Ok(s) => {
                let s = parking_lot::Mutex::new(s);
                Some(estop::register(format!("player {}", self.srv), move || {
                    if let Some(mut s) = s.try_lock_for(Duration::from_millis(50)) {
                        let _ = s.write_all(&bytes);
                    }
                }))
            }
            Err(e) => {
                tracing::warn!(
                    "player: no second handle on the connection to {} ({e}): a signal or a panic will not stop the robot first",
                    self.srv
                );
                None
            }
        }
    }

    /// A new connection: binds the lines still waiting, sets the data mode and
    /// subscribes what is used.
    fn begin(&mut self, c: &mut Conn) -> Result<(), ConnError> {
        let s = &mut self.session;
        s.bind_pending(c)?;
        if s.pc.mode == DataMode::Pull {
            let devices = &mut s.devices;
            c.request(
                Addr::PLAYER,
                player::REQ_DATAMODE,
                &xdr::datamode_req(player::DATAMODE_PULL),
                s.pc.timeout,
                &mut |h, p| dispatch(devices, h, p),
            )?;
        }
        s.sync_subscriptions(c)
    }
}

impl Session {
    /// One turn of a connection's loop: (un)subscribe as use changed, send the
    /// commands when due, pull (in pull mode), and take what arrives within 20 ms.
    fn step(&mut self, live: &mut Live) -> Result<(), ConnError> {
        let c = &mut live.conn;
        self.sync_subscriptions(c)?;
        let now = Instant::now();
        if now >= live.next_cmd {
            self.commands(c)?;
            live.next_cmd += self.pc.cycle;
            if live.next_cmd < now {
                live.next_cmd = now + self.pc.cycle;
            }
        }
        let any = self.devices.iter().any(|d| d.subscribed);
        if self.pc.mode == DataMode::Pull
            && any
            && (!live.awaiting_synch || live.last_pull.elapsed() > self.pc.timeout)
            && live.last_pull.elapsed() >= Duration::from_millis(10)
        {
            c.send(Addr::PLAYER, msg::REQ, player::REQ_DATA, &[])?;
            live.awaiting_synch = true;
            live.last_pull = Instant::now();
        }
        let wait = live
            .next_cmd
            .saturating_duration_since(Instant::now())
            .min(Duration::from_millis(20));
        let devices = &mut self.devices;
        let mut synch = false;
        let n = c.poll(wait, &mut |h, p| {
            if h.addr == Addr::PLAYER && h.mtype == msg::SYNCH {
                synch = true;
            }
            dispatch(devices, h, p)
        })?;
        if synch {
            live.awaiting_synch = false;
        }
        if n > 0 || !any {
            live.silent_since = Instant::now();
        } else if live.silent_since.elapsed() > self.pc.timeout {
            return Err(ConnError::Protocol(format!(
                "no data for {:.1} s while subscribed",
                live.silent_since.elapsed().as_secs_f64()
            )));
        }
        Ok(())
    }
}

/// The running driver.
pub struct PlayerDriver {
    link: Supervisor,
    motors: Vec<Arc<Interface<Motors>>>,
}

impl Driver for PlayerDriver {
    fn terminate(&mut self) {
        self.link.stop();
        for m in &self.motors {
            let _ = m.publish(Motors::default());
        }
    }
}

impl Drop for PlayerDriver {
    fn drop(&mut self) {
        self.terminate();
    }
}

/// Asks the server for its devices.
pub fn device_list(c: &mut Conn, timeout: Duration) -> Result<Vec<Addr>, ConnError> {
    match c.request(
        Addr::PLAYER,
        player::REQ_DEVLIST,
        &xdr::devlist_req(),
        timeout,
        &mut |_, _| Ok(()),
    )? {
        Reply::Ack(p) => Ok(xdr::decode_devlist(&p)?),
        Reply::Nack => Err(ConnError::Protocol("the server refused REQ_DEVLIST".into())),
    }
}

/// One `provides` line's interface, before it is bound to a Player device.
enum Binding {
    Sink(Sink),
    Motors(Arc<Interface<Motors>>),
    PtMotors(Arc<Interface<PtMotors>>),
}

/// A `provides` line waiting for the server's device list.
struct Pending {
    want: conf::Want,
    binding: Binding,
}

impl Pending {
    fn set_stale(&self, why: &str) {
        match &self.binding {
            Binding::Sink(s) => s.set_stale(why),
            Binding::Motors(m) => {
                let _ = m.publish(Motors::default());
                m.set_stale(why);
            }
            Binding::PtMotors(m) => m.set_stale(why),
        }
    }
}

/// Binds each pending line to a device of `list`; the lines that find none come
/// back with their error (naming the line, the device and the server's list).
fn bind(pending: Vec<Pending>, list: &[Addr], srv: &str) -> (Vec<Device>, Vec<(Pending, String)>) {
    let mut devices: BTreeMap<Addr, Device> = BTreeMap::new();
    let mut failed = Vec::new();
    for p in pending {
        let addr = match conf::choose(&p.want, list, srv) {
            Ok(a) => a,
            Err(e) => {
                failed.push((p, format!("player: {e:#}")));
                continue;
            }
        };
        let d = devices.entry(addr).or_insert_with(|| Device {
            addr,
            sinks: Vec::new(),
            motors: None,
            ptmotors: None,
            subscribed: false,
            ranger: None,
            zoom: 0.0,
            ptm_sent: 0,
            scratch: Vec::new(),
            frame: Image::default(),
            source: Source::new(format!("player: {srv} {addr}")),
            blob_clock: 0,
        });
        match p.binding {
            Binding::Sink(s) => d.sinks.push(s),
            Binding::Motors(m) => d.motors = Some(m),
            Binding::PtMotors(m) => d.ptmotors = Some(m),
        }
    }
    (devices.into_values().collect(), failed)
}

impl Session {
    /// Binds the lines still waiting for a device list (the server was not there
    /// at start); a line the server cannot serve is said once and left stale.
    fn bind_pending(&mut self, c: &mut Conn) -> Result<(), ConnError> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let list = device_list(c, self.pc.timeout)?;
        let srv = server(&self.pc);
        let (devices, failed) = bind(std::mem::take(&mut self.pending), &list, &srv);
        self.devices = devices;
        for (p, why) in failed {
            tracing::error!("{why}");
            crate::output::println(why.clone());
            p.set_stale(&why);
            self.unbound.push(p);
        }
        Ok(())
    }
}

impl PlayerDriver {
    /// Provides the interfaces, connects to the server, binds each line to one of
    /// its devices and starts the thread. A device the server lacks is an error.
    /// A server that is not there is said once; the interfaces stay stale and the
    /// thread keeps trying (and binds the lines once it answers).
    pub fn start(
        pc: PlayerConf,
        ifaces: &Interfaces,
        names: &crate::namespace::Namespace,
        provider: &str,
    ) -> anyhow::Result<PlayerDriver> {
        let srv = server(&pc);
        let (pending, motors_all) = provide(&pc, ifaces, names, provider)?;
        let (conn, devices, pending) = first_connect(&pc, pending, &srv)?;
        let lost_since = conn.is_none().then(Instant::now);
        let link = Link {
            session: Session {
                pc,
                devices,
                pending,
                unbound: Vec::new(),
            },
            srv,
            first: conn,
            lost_since,
            lost: None,
        };
        // The Link marks its interfaces stale itself (the loss's reason stays
        // while it retries), so the Supervisor is given none.
        let how = Supervision {
            name: "player".into(),
            interfaces: Vec::new(),
            on_demand: false,
            backoff: Backoff {
                first: Duration::from_millis(100),
                max: Duration::from_secs(2),
            },
            absent: None,
        };
        Ok(PlayerDriver {
            link: Supervisor::start(how, link)?,
            motors: motors_all,
        })
    }
}

/// Every `motors` interface the driver provides.
type AllMotors = Vec<Arc<Interface<Motors>>>;

/// Provides the interfaces of every `provides` line (each waiting for its
/// device), and the motors among them.
fn provide(
    pc: &PlayerConf,
    ifaces: &Interfaces,
    names: &crate::namespace::Namespace,
    provider: &str,
) -> anyhow::Result<(Vec<Pending>, AllMotors)> {
    let mut pending = Vec::new();
    let mut motors_all = Vec::new();
    for w in &pc.wants {
        let off = pc.offset(&w.robot);
        let binding = match &w.kind {
            Provided::Encoders => Binding::Sink(Sink::Encoders(
                ifaces.provide_value(
                    &w.name,
                    provider,
                    sinks::encoders(&Default::default(), &off),
                )?,
                off,
            )),
            Provided::Motors => {
                let m = ifaces.provide::<Motors>(&w.name, provider)?;
                motors_all.push(m.clone());
                Binding::Motors(m)
            }
            Provided::Laser(n, r) => Binding::Sink(Sink::Laser(
                ifaces.provide(&w.name, provider)?,
                LaserMap::new(*n, *r).mounted(Mount::PIONEER_LASER),
            )),
            Provided::Sonars => Binding::Sink(Sink::Sonars(ifaces.provide(&w.name, provider)?)),
            Provided::Bumpers => Binding::Sink(Sink::Bumpers(ifaces.provide(&w.name, provider)?)),
            Provided::PanTiltEncoders => {
                Binding::Sink(Sink::PtEncoders(ifaces.provide(&w.name, provider)?))
            }
            Provided::PanTiltMotors => Binding::PtMotors(ifaces.provide(&w.name, provider)?),
            Provided::Camera(fixed) => {
                let init = if *fixed {
                    Image::new(320, 240)
                } else {
                    Image::default()
                };
                Binding::Sink(Sink::Camera(
                    ifaces.provide_value(&w.name, provider, init)?,
                    *fixed,
                ))
            }
            Provided::Blobs => {
                let b = names.export(
                    provider,
                    &w.name,
                    LiveBlobs::from_pointee(BlobFrame::default()),
                )?;
                Binding::Sink(Sink::Blobs(b))
            }
        };
        pending.push(Pending {
            want: w.clone(),
            binding,
        });
    }
    Ok((pending, motors_all))
}

/// The first connection: the lines bound to the server's devices (a device it
/// lacks is an error), or, with no server there, every line still pending and
/// stale with the reason.
fn first_connect(
    pc: &PlayerConf,
    pending: Vec<Pending>,
    srv: &str,
) -> anyhow::Result<(Option<Conn>, Vec<Device>, Vec<Pending>)> {
    Ok(match Conn::open(&pc.host, pc.port, pc.timeout) {
        Ok(mut c) => {
            let list = device_list(&mut c, pc.timeout).map_err(|e| {
                anyhow::anyhow!("the Player server at {srv} did not list its devices: {e}")
            })?;
            let (devices, failed) = bind(pending, &list, srv);
            if let Some((_, why)) = failed.into_iter().next() {
                c.close();
                return Err(anyhow::anyhow!("{}", why.trim_start_matches("player: ")));
            }
            tracing::info!(
                "player: connected to Player {} at {srv}; devices used: {}",
                c.version,
                devices
                    .iter()
                    .map(|d| d.addr.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            (Some(c), devices, Vec::new())
        }
        Err(e) => {
            let why = format!(
                "player: cannot reach a Player server at {srv} ({e}). Start one first: for \
                 Stage, `player /usr/share/stage/worlds/simple.cfg` (or your robot's .cfg); or \
                 fix `hostname H port P` in the player driver's conf. Retrying in the background"
            );
            tracing::error!("{why}");
            for p in &pending {
                p.set_stale(&why);
            }
            (None, Vec::new(), pending)
        }
    })
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let pc = PlayerConf::parse(conf)?;
    Ok(Box::new(PlayerDriver::start(
        pc,
        &rt.interfaces,
        &rt.names,
        &conf.name,
    )?))
}

crate::register_driver!(
    Driver,
    "player",
    "a robot or Stage through a Player 3 server (TCP): encoders, motors, laser, sonars, bumpers, pan-tilt, cameras, blobs",
    create,
    lines = conf::Lines
);
