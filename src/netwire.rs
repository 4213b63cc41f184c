//! The JDE 4.3 networkserver/networkclient wire protocol (R430
//! `services/networkserver/jdemessages.h`), shared by the `networkserver` service
//! and the `networkclient` driver.
//!
//! Every message is one ASCII line of space-separated fields ending in `\n`; the
//! first field is the message code. The only binary data are image pixels, which
//! follow their `1020` header line. A client opens one TCP connection per device
//! and first writes a 20-byte name (`jdec` NUL-padded).
//!
//! | client → server | | server → client | |
//! |---|---|---|---|
//! | `1019 NETID` | image query | `1020 CLOCK NETID W H 3` + W·H·3 BGR bytes | image |
//! | `27` / `28` | (un)subscribe laser | `26 CLOCK R0 .. RN-1` (mm) | laser push |
//! | `11` / `12` | (un)subscribe encoders | `10 CLOCK X Y THETA_DEG TIME` | encoders push |
//! | `2` / `3` | (un)subscribe sonars | `1 CLOCK 0 US0 1 US1 ..` (mm) | sonars push |
//! | `1001` / `1002` | (un)subscribe pan-tilt encoders | `1003 CLOCK PAN TILT` (deg) | push |
//! | `1025` / `1026` | (un)subscribe zoom encoders | `1021 CLOCK ZOOM` | push |
//! | `22 V AC` / `23 W AC` | motors v (mm/s), w (deg/s) | | |
//! | `1006 PAN TILT PAN_SPEED TILT_SPEED` | pan-tilt command (deg, deg/s) | | |
//! | `1004` | pan-tilt limits query | `1005 MAXLON MAXLAT MINLON MINLAT MAXLONSPEED MAXLATSPEED` | |
//! | `1024 ZOOM SPEED` | zoom command | | |
//! | `1022` | zoom limits query | `1023 MAXZOOM MINZOOM MAXZOOMSPEED` | |
//! | `0` / `1000` | goodbye (robot / images) | `1027 TEXT` | error |
//! | `2001` / `2002` | (un)subscribe imu (jderobot) | `2003 CLOCK QX QY QZ QW WX WY WZ AX AY AZ` (rad/s, m/s²) | push |
//!
//! The imu messages are jderobot's extension: 4.3 had no IMU. Their codes are
//! outside 4.3's range (a 4.3 server answers them with nothing, a 4.3 client never
//! sends them), and their numbers are written in Rust's shortest round-trip form,
//! so an f32 arrives exactly.
//! Subscribed devices are pushed every 33 ms when their value changed.
//!
//! **Token.** 4.3's name is `jdec` and NUL bytes, and a 4.3 client sends nothing
//! else before its requests. With a shared secret ([`crate::secret`]: 16 to 128
//! characters, too long for the 15 bytes a 20-byte name has after `jdec` and its
//! NUL), the name is `jdec`, NUL, the marker [`TOKEN_MARK`] (`token-line`),
//! NUL-padded, and a token line follows it: `2100 SECRET\n` ([`code::TOKEN`],
//! jderobot's extension). A 4.3 server prints only `jdec` (its `strncpy`/`%s`
//! stops at the first NUL) and ignores the `2100` line as it ignores every code
//! it does not know, so the wire stays 4.3's; a name without the marker (every
//! 4.3 client's) carries no token. See [`hello`] and [`split_name`].

use std::{
    fmt::Write as _,
    io::{self, Read},
};

use crate::interfaces::{
    Bumpers, Encoders, Image, Imu, InterfaceValue, Kind, Laser, Motors, PtEncoders, PtMotors,
    Sonars, ZoomEncoders, ZoomMotors, for_each_kind,
};

/// Length of the client name that opens every connection (4.3's MAX_CLIENT_NAME).
pub const NAME_LEN: usize = 20;
/// What a client name holds after `jdec` and its NUL when a token line follows.
pub const TOKEN_MARK: &[u8] = b"token-line";
/// The longest token line: `2100 `, the longest token, `\n`.
pub const MAX_TOKEN_LINE: usize = 5 + crate::secret::MAX_TOKEN + 1;
/// The period of subscription pushes (4.3: 33 ms).
pub const PUSH_PERIOD_MS: u64 = 33;

/// 4.3's message codes (the C enum values).
pub mod code {
    pub const GOODBYE: u32 = 0;
    pub const SONARS: u32 = 1;
    pub const SUBSCRIBE_US: u32 = 2;
    pub const UNSUBSCRIBE_US: u32 = 3;
    pub const ENCODERS: u32 = 10;
    pub const SUBSCRIBE_ENCODERS: u32 = 11;
    pub const UNSUBSCRIBE_ENCODERS: u32 = 12;
    pub const DRIVE_SPEED: u32 = 22;
    pub const STEER_SPEED: u32 = 23;
    pub const LASER: u32 = 26;
    pub const SUBSCRIBE_LASER: u32 = 27;
    pub const UNSUBSCRIBE_LASER: u32 = 28;
    pub const GOODBYE_IMAGES: u32 = 1000;
    pub const SUBSCRIBE_PANTILT_ENCODERS: u32 = 1001;
    pub const UNSUBSCRIBE_PANTILT_ENCODERS: u32 = 1002;
    pub const PANTILT_ENCODERS: u32 = 1003;
    pub const PANTILT_LIMITS_QUERY: u32 = 1004;
    pub const PANTILT_LIMITS: u32 = 1005;
    pub const PANTILT_POSITION: u32 = 1006;
    pub const RGB24BPP_IMAGE_QUERY: u32 = 1019;
    pub const RGB24BPP_IMAGE: u32 = 1020;
    pub const ZOOM_ENCODERS: u32 = 1021;
    pub const ZOOM_LIMITS_QUERY: u32 = 1022;
    pub const ZOOM_LIMITS: u32 = 1023;
    pub const ZOOM_POSITION: u32 = 1024;
    pub const SUBSCRIBE_ZOOM_ENCODERS: u32 = 1025;
    pub const UNSUBSCRIBE_ZOOM_ENCODERS: u32 = 1026;
    pub const ERROR: u32 = 1027;
    /// jderobot's extension: the imu device (4.3 had none).
    pub const SUBSCRIBE_IMU: u32 = 2001;
    pub const UNSUBSCRIBE_IMU: u32 = 2002;
    pub const IMU: u32 = 2003;
    /// jderobot's extension: the token line that follows a name marked with
    /// [`super::TOKEN_MARK`] (`2100 SECRET`).
    pub const TOKEN: u32 = 2100;
    /// Codes 4.3 declared but never handled (ir, bumpers, battery, sensed speeds,
    /// limp, replay, other image formats, pan-tilt relative/reset/origin/halt).
    pub const UNHANDLED: &[u32] = &[
        4, 5, 6, 7, 8, 9, 13, 14, 15, 16, 17, 18, 19, 20, 21, 24, 25, 1007, 1008, 1009, 1010, 1011,
        1012, 1013, 1014, 1015, 1016, 1017, 1018,
    ];
}

/// Where a kind stands on 4.3's wire: its [`Net43::ON_WIRE`], one row per kind
/// of the table in [`WIRE`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OnWire {
    /// Not on the wire (4.3 declared the bumper codes but never sent them).
    Absent,
    /// Frames on request: `1019 NETID`, answered by a `1020` header and the pixels.
    Frames,
    /// Pushed to its subscribers every 33 ms when it changed.
    Pushed {
        subscribe: u32,
        unsubscribe: u32,
        push: u32,
    },
    /// Set by its command requests (their codes).
    Commanded {
        commands: &'static [u32],
        /// The query the server answers with the unit's limits.
        limits: Option<Limits>,
        /// A command that must be renewed: the client sends it every 100 ms (a
        /// stale one as zero), the server zeroes it when its client leaves.
        keep_alive: bool,
    },
}

/// A commanded kind's limits query.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    pub query: u32,
    pub reply: u32,
    /// The `1027` text when the kind is not served.
    pub unserved: &'static str,
}

/// Every kind's [`OnWire`], in the table's order ([`Kind::ALL`]).
pub const WIRE: &[OnWire] = for_each_kind!(kind_wire! {});

/// `<T as Net43>::ON_WIRE` of every kind of the table.
macro_rules! kind_wire {
    (; $(($t:ident, $k:literal)),*) => {
        &[$(<$crate::interfaces::$t as Net43>::ON_WIRE),*]
    };
}
use kind_wire;

/// The [`OnWire`] of kind `kind`.
pub fn on_wire(kind: Kind) -> OnWire {
    WIRE[kind.index()]
}

/// A pushed kind (4.3 calls it a device).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Feed(Kind);

impl Feed {
    /// Slots for feeds: one per kind of the table (only pushed kinds use theirs).
    pub const COUNT: usize = Kind::ALL.len();
    /// The feed of kind `kind`, if it is pushed.
    pub fn of(kind: Kind) -> Option<Feed> {
        matches!(on_wire(kind), OnWire::Pushed { .. }).then_some(Feed(kind))
    }
    /// Every pushed kind, in the order a push round writes them: 4.3's server's
    /// ([`PUSH_ORDER`]), then any other in the table's order.
    pub fn all() -> &'static [Feed] {
        static ALL: std::sync::LazyLock<Vec<Feed>> = std::sync::LazyLock::new(|| {
            let mut feeds: Vec<Feed> = pushed().collect();
            feeds.sort_by_key(|d| {
                PUSH_ORDER
                    .iter()
                    .position(|c| *c == d.codes().2)
                    .unwrap_or(usize::MAX)
            });
            feeds
        });
        &ALL
    }
    /// Index in the kinds table (and in arrays of [`Feed::COUNT`] slots).
    pub fn index(self) -> usize {
        self.0.index()
    }
    /// (subscribe, unsubscribe, push) codes.
    pub fn codes(self) -> (u32, u32, u32) {
        match on_wire(self.0) {
            OnWire::Pushed {
                subscribe,
                unsubscribe,
                push,
            } => (subscribe, unsubscribe, push),
            _ => unreachable!("a feed is a pushed kind"),
        }
    }
    /// The interface kind.
    pub fn interface(self) -> Kind {
        self.0
    }
}

/// The push codes in the order 4.3's server wrote a round of pushes (laser,
/// encoders, sonars, pan-tilt, zoom), jderobot's imu last: a round's bytes stay 4.3's.
pub const PUSH_ORDER: &[u32] = &[
    code::LASER,
    code::ENCODERS,
    code::SONARS,
    code::PANTILT_ENCODERS,
    code::ZOOM_ENCODERS,
    code::IMU,
];

/// Every pushed kind, in the table's order.
fn pushed() -> impl Iterator<Item = Feed> {
    Kind::ALL.iter().filter_map(|&k| Feed::of(k))
}

/// The kind that command request `code` sets.
pub fn commanded_kind(code: u32) -> Option<Kind> {
    Kind::ALL.iter().copied().find(
        |&k| matches!(on_wire(k), OnWire::Commanded { commands, .. } if commands.contains(&code)),
    )
}

/// The kind whose limits query is `code`, and the query.
pub fn limits_kind(code: u32) -> Option<(Kind, Limits)> {
    Kind::ALL.iter().find_map(|&k| match on_wire(k) {
        OnWire::Commanded {
            limits: Some(l), ..
        } if l.query == code || l.reply == code => Some((k, l)),
        _ => None,
    })
}

/// The client's origin (`initial_position`): x, y mm, θ deg.
pub type Origin = (f32, f32, f32);

/// How a kind travels on 4.3's wire: the one place, per kind, that says how it
/// is written and read (its codes in [`ON_WIRE`](Self::ON_WIRE), its lines in
/// the methods). Every kind of the table implements it ([`WIRE`] names them all,
/// so a kind missing it fails to compile); `networkserver` and `networkclient`
/// are generic over it.
pub trait Net43: InterfaceValue {
    const ON_WIRE: OnWire;
    /// Pushed: appends the push line of the value with its clock (`time_us`: the
    /// sample's time since the server started).
    fn write_push(&self, _clock: u64, _time_us: u64, _out: &mut Vec<u8>) {}
    /// Pushed: reads a push line's fields (`f[0]` the clock) into a value, placed
    /// at the client's `origin`.
    fn read_push(_code: u32, _f: &[&str], _origin: Origin) -> Result<Self, WireError> {
        Ok(Self::default())
    }
    /// The value a client's interface holds before the first push.
    fn initial(_origin: Origin) -> Self {
        Self::default()
    }
    /// Commanded: sets the value from one of its command requests (server).
    fn apply(&mut self, _req: &Request) {}
    /// Commanded: the requests that send the value (client).
    fn requests(&self) -> Vec<Request> {
        Vec::new()
    }
    /// Commanded: what a client sends when it stops, before its goodbye.
    fn farewell(&self) -> Vec<Request> {
        Vec::new()
    }
    /// Commanded with limits: appends the limits reply (server).
    fn write_limits(&self, _out: &mut Vec<u8>) {}
    /// Commanded with limits: takes the limits reply's fields (client).
    fn read_limits(&mut self, _code: u32, _f: &[&str]) -> Result<(), WireError> {
        Ok(())
    }
}

/// A malformed or unexpected line.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WireError {
    #[error("line is not printable ASCII text")]
    NotText,
    #[error("empty line")]
    Empty,
    #[error("`{0}` is not a message code (a number)")]
    BadCode(String),
    #[error("message code {0} is not a 4.3 message")]
    UnknownCode(u32),
    #[error("message {code} takes {expected} field(s) after the code, got {got}")]
    FieldCount {
        code: u32,
        expected: usize,
        got: usize,
    },
    #[error("message {code}: field {index} is `{word}`, expected {what}")]
    BadField {
        code: u32,
        index: usize,
        word: String,
        what: &'static str,
    },
    #[error("message {code}: {what}")]
    Invalid { code: u32, what: String },
}

/// A client → server message.
#[derive(Clone, Debug, PartialEq)]
pub enum Request {
    /// `0`: the robot connection ends.
    Goodbye,
    /// `1000`: the image connection ends.
    GoodbyeImages,
    Subscribe(Feed),
    Unsubscribe(Feed),
    /// `22 V AC`: mm/s (AC, an acceleration, is ignored as in 4.3).
    DriveSpeed {
        v: f32,
        ac: f32,
    },
    /// `23 W AC`: deg/s.
    SteerSpeed {
        w: f32,
        ac: f32,
    },
    /// `1006 PAN TILT PAN_SPEED TILT_SPEED`: deg, deg/s.
    PtPosition {
        pan: f32,
        tilt: f32,
        pan_speed: f32,
        tilt_speed: f32,
    },
    /// `1024 ZOOM SPEED`.
    ZoomPosition {
        zoom: f32,
        speed: f32,
    },
    /// A commanded kind's limits query (`1004`, `1022`: its [`Limits::query`]).
    LimitsQuery(u32),
    /// `1019 NETID`: the next new frame of image NETID.
    ImageQuery(u32),
    /// A 4.3 code that 4.3's server did not handle either.
    Unhandled(u32),
}

/// Splits a line (without its `\n`; a trailing `\r` is dropped) into its code and fields.
fn split(line: &[u8]) -> Result<(u32, Vec<&str>), WireError> {
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    if !line
        .iter()
        .all(|&b| b == b' ' || b == b'\t' || b.is_ascii_graphic())
    {
        return Err(WireError::NotText);
    }
    let text = std::str::from_utf8(line).map_err(|_| WireError::NotText)?;
    let mut words = text.split_ascii_whitespace();
    let first = words.next().ok_or(WireError::Empty)?;
    let code: u32 = first
        .parse()
        .map_err(|_| WireError::BadCode(first.chars().take(32).collect()))?;
    Ok((code, words.collect()))
}

fn count(code: u32, f: &[&str], n: usize) -> Result<(), WireError> {
    if f.len() != n {
        return Err(WireError::FieldCount {
            code,
            expected: n,
            got: f.len(),
        });
    }
    Ok(())
}

fn num<T: std::str::FromStr>(
    code: u32,
    f: &[&str],
    i: usize,
    what: &'static str,
) -> Result<T, WireError> {
    f[i].parse().map_err(|_| WireError::BadField {
        code,
        index: i + 1,
        word: f[i].chars().take(32).collect(),
        what,
    })
}

fn real(code: u32, f: &[&str], i: usize) -> Result<f32, WireError> {
    let v: f32 = num(code, f, i, "a number")?;
    if !v.is_finite() {
        return Err(WireError::BadField {
            code,
            index: i + 1,
            word: f[i].chars().take(32).collect(),
            what: "a finite number",
        });
    }
    Ok(v)
}

impl Request {
    /// Parses one line (without its `\n`).
    pub fn parse(line: &[u8]) -> Result<Request, WireError> {
        use code::*;
        let (c, f) = split(line)?;
        if let Some(d) = pushed().find(|d| d.codes().0 == c || d.codes().1 == c) {
            count(c, &f, 0)?;
            return Ok(if d.codes().0 == c {
                Request::Subscribe(d)
            } else {
                Request::Unsubscribe(d)
            });
        }
        if limits_kind(c).is_some_and(|(_, l)| l.query == c) {
            count(c, &f, 0)?;
            return Ok(Request::LimitsQuery(c));
        }
        Ok(match c {
            GOODBYE | GOODBYE_IMAGES => {
                count(c, &f, 0)?;
                if c == GOODBYE {
                    Request::Goodbye
                } else {
                    Request::GoodbyeImages
                }
            }
            DRIVE_SPEED => {
                count(c, &f, 2)?;
                let [v, ac] = reals(c, &f, 0)?;
                Request::DriveSpeed { v, ac }
            }
            STEER_SPEED => {
                count(c, &f, 2)?;
                let [w, ac] = reals(c, &f, 0)?;
                Request::SteerSpeed { w, ac }
            }
            PANTILT_POSITION => {
                count(c, &f, 4)?;
                let [pan, tilt, pan_speed, tilt_speed] = reals(c, &f, 0)?;
                Request::PtPosition {
                    pan,
                    tilt,
                    pan_speed,
                    tilt_speed,
                }
            }
            ZOOM_POSITION => {
                count(c, &f, 2)?;
                let [zoom, speed] = reals(c, &f, 0)?;
                Request::ZoomPosition { zoom, speed }
            }
            RGB24BPP_IMAGE_QUERY => {
                count(c, &f, 1)?;
                Request::ImageQuery(num(c, &f, 0, "a network id (0, 1, 2 ...)")?)
            }
            c if code::UNHANDLED.contains(&c) => Request::Unhandled(c),
            c => return Err(WireError::UnknownCode(c)),
        })
    }

    /// The message code.
    pub fn code(&self) -> u32 {
        match *self {
            Request::Goodbye => code::GOODBYE,
            Request::GoodbyeImages => code::GOODBYE_IMAGES,
            Request::Subscribe(d) => d.codes().0,
            Request::Unsubscribe(d) => d.codes().1,
            Request::DriveSpeed { .. } => code::DRIVE_SPEED,
            Request::SteerSpeed { .. } => code::STEER_SPEED,
            Request::PtPosition { .. } => code::PANTILT_POSITION,
            Request::ZoomPosition { .. } => code::ZOOM_POSITION,
            Request::LimitsQuery(c) | Request::Unhandled(c) => c,
            Request::ImageQuery(_) => code::RGB24BPP_IMAGE_QUERY,
        }
    }

    /// Appends the line (with its `\n`) as a 4.3 client writes it (`%1.1f` speeds).
    pub fn write_to(&self, out: &mut Vec<u8>) {
        let mut a = Adapter(out);
        let c = self.code();
        let _ = match *self {
            Request::DriveSpeed { v: x, ac } | Request::SteerSpeed { w: x, ac } => {
                writeln!(a, "{c} {x:.1} {ac:.1}")
            }
            Request::PtPosition {
                pan,
                tilt,
                pan_speed,
                tilt_speed,
            } => writeln!(a, "{c} {pan:.2} {tilt:.2} {pan_speed:.2} {tilt_speed:.2}"),
            Request::ZoomPosition { zoom, speed } => writeln!(a, "{c} {zoom:.2} {speed:.2}"),
            Request::ImageQuery(id) => writeln!(a, "{c} {id}"),
            _ => writeln!(a, "{c}"),
        };
    }
}

/// A server → client message (an image's pixels follow its header).
#[derive(Clone, Debug, PartialEq)]
pub enum Message<'a> {
    /// A push of a pushed kind: its fields after the code (`fields[0]` the
    /// clock), read by the kind's [`Net43::read_push`].
    Push { feed: Feed, fields: Vec<&'a str> },
    /// A limits reply: its code and fields, read by the kind's
    /// [`Net43::read_limits`].
    Limits { code: u32, fields: Vec<&'a str> },
    /// `1020 CLOCK NETID W H DEPTH`, followed by W·H·DEPTH bytes.
    Image {
        clock: u64,
        netid: u32,
        width: u32,
        height: u32,
        depth: u32,
    },
    /// `1027 TEXT`.
    Error(String),
}

/// The most sonars / laser readings a push may carry.
pub const MAX_READINGS: usize = 4096;

impl<'a> Message<'a> {
    /// Parses one line (without its `\n`): the code, the clock of a push and an
    /// image's header; a push's and a limits reply's fields are the kind's to read.
    pub fn parse(line: &'a [u8]) -> Result<Message<'a>, WireError> {
        let (c, f) = split(line)?;
        if f.len() > MAX_READINGS * 2 + 1 {
            return Err(WireError::Invalid {
                code: c,
                what: format!("{} fields is too many", f.len()),
            });
        }
        if let Some(feed) = pushed().find(|d| d.codes().2 == c) {
            if f.is_empty() {
                return Err(WireError::FieldCount {
                    code: c,
                    expected: 1,
                    got: 0,
                });
            }
            let _: u64 = num(c, &f, 0, "a clock")?;
            return Ok(Message::Push { feed, fields: f });
        }
        if limits_kind(c).is_some_and(|(_, l)| l.reply == c) {
            return Ok(Message::Limits { code: c, fields: f });
        }
        Ok(match c {
            code::RGB24BPP_IMAGE => {
                count(c, &f, 5)?;
                Message::Image {
                    clock: num(c, &f, 0, "a clock")?,
                    netid: num(c, &f, 1, "a network id")?,
                    width: num(c, &f, 2, "a width in pixels")?,
                    height: num(c, &f, 3, "a height in pixels")?,
                    depth: num(c, &f, 4, "a depth in bytes per pixel")?,
                }
            }
            code::ERROR => Message::Error(f.join(" ")),
            c => return Err(WireError::UnknownCode(c)),
        })
    }
}

/// Appends `1020 CLOCK NETID W H 3\n` (the pixels follow).
pub fn write_image_header(out: &mut Vec<u8>, clock: u64, netid: u32, width: u32, height: u32) {
    let _ = writeln!(
        Adapter(out),
        "{} {clock} {netid} {width} {height} 3",
        code::RGB24BPP_IMAGE
    );
}

/// Appends `1027 TEXT\n` (newlines in TEXT become spaces).
pub fn write_error(out: &mut Vec<u8>, text: &str) {
    let t: String = text
        .chars()
        .map(|c| if c.is_ascii_graphic() { c } else { ' ' })
        .collect();
    let _ = writeln!(Adapter(out), "{} {t}", code::ERROR);
}

struct Adapter<'a>(&'a mut Vec<u8>);
impl std::fmt::Write for Adapter<'_> {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        self.0.extend_from_slice(s.as_bytes());
        Ok(())
    }
}

/// Appends `CODE CLOCK` and ` V` for each value (`V` as `show` writes it), `\n`.
fn write_values<V>(
    out: &mut Vec<u8>,
    code: u32,
    clock: u64,
    values: impl IntoIterator<Item = V>,
    show: impl Fn(&mut Adapter<'_>, V) -> std::fmt::Result,
) {
    let mut a = Adapter(out);
    let _ = write!(a, "{code} {clock}");
    for v in values {
        let _ = show(&mut a, v);
    }
    a.0.push(b'\n');
}

/// The `N` finite numbers `f[from..from + N]` of message `c`.
fn reals<const N: usize>(c: u32, f: &[&str], from: usize) -> Result<[f32; N], WireError> {
    let mut v = [0.0; N];
    for (i, x) in v.iter_mut().enumerate() {
        *x = real(c, f, from + i)?;
    }
    Ok(v)
}

impl Net43 for Image {
    const ON_WIRE: OnWire = OnWire::Frames;
}

impl Net43 for Bumpers {
    const ON_WIRE: OnWire = OnWire::Absent;
}

/// `26 CLOCK R0 .. RN-1`: mm.
impl Net43 for Laser {
    const ON_WIRE: OnWire = OnWire::Pushed {
        subscribe: code::SUBSCRIBE_LASER,
        unsubscribe: code::UNSUBSCRIBE_LASER,
        push: code::LASER,
    };
    /// What 4.3's wire can say: N readings over 180° from −90°; a scan of any
    /// other geometry is resampled to 180 at 1° ([`Laser::jde43_readings`]).
    fn write_push(&self, clock: u64, _: u64, out: &mut Vec<u8>) {
        write_values(out, code::LASER, clock, &*self.jde43_readings(), |a, r| {
            write!(a, " {r}")
        });
    }
    fn read_push(c: u32, f: &[&str], _: Origin) -> Result<Self, WireError> {
        let readings: Vec<i32> = (1..f.len())
            .map(|i| num(c, f, i, "a range in mm (integer)"))
            .collect::<Result<_, _>>()?;
        // 4.3's wire carries only the readings, of 4.3's laser: 180° from −90°
        // (docs/network.md).
        let resolution = (readings.len() as f32 / 180.0).max(f32::MIN_POSITIVE);
        Ok(Laser::jde43(readings, resolution))
    }
}

/// `10 CLOCK X Y THETA_DEG TIME` (`%1.1f %1.1f %1.5f`): mm, mm, degrees; TIME is
/// µs (4.3 sent the clock). The client places it at its origin.
impl Net43 for Encoders {
    const ON_WIRE: OnWire = OnWire::Pushed {
        subscribe: code::SUBSCRIBE_ENCODERS,
        unsubscribe: code::UNSUBSCRIBE_ENCODERS,
        push: code::ENCODERS,
    };
    fn write_push(&self, clock: u64, time_us: u64, out: &mut Vec<u8>) {
        let (x, y, theta_deg) = (self.x, self.y, self.theta.to_degrees());
        let _ = writeln!(
            Adapter(out),
            "{} {clock} {x:.1} {y:.1} {theta_deg:.5} {time_us}",
            code::ENCODERS
        );
    }
    fn read_push(c: u32, f: &[&str], (x0, y0, t0): Origin) -> Result<Self, WireError> {
        count(c, f, 5)?;
        let [x, y, theta_deg] = reals(c, f, 1)?;
        let _: u64 = num(c, f, 4, "a time stamp")?;
        let (s, co) = t0.to_radians().sin_cos();
        let gx = x0 + co * x - s * y;
        let gy = y0 + s * x + co * y;
        Ok(Encoders::from_pose(gx, gy, (theta_deg + t0).to_radians()))
    }
    fn initial((x, y, t): Origin) -> Self {
        Encoders::from_pose(x, y, t.to_radians())
    }
}

/// `1 CLOCK 0 US0 1 US1 ..` (`%1.1f`): (index, mm) pairs, one per sonar.
impl Net43 for Sonars {
    const ON_WIRE: OnWire = OnWire::Pushed {
        subscribe: code::SUBSCRIBE_US,
        unsubscribe: code::UNSUBSCRIBE_US,
        push: code::SONARS,
    };
    fn write_push(&self, clock: u64, _: u64, out: &mut Vec<u8>) {
        write_values(
            out,
            code::SONARS,
            clock,
            self.us.iter().enumerate(),
            |a, (i, u)| write!(a, " {i} {u:.1}"),
        );
    }
    fn read_push(c: u32, f: &[&str], _: Origin) -> Result<Self, WireError> {
        if f.is_empty() || f.len() % 2 != 1 {
            return Err(WireError::Invalid {
                code: c,
                what: "expected a clock then (index, mm) pairs".into(),
            });
        }
        let mut pairs = Vec::with_capacity(f.len() / 2);
        for k in (1..f.len()).step_by(2) {
            let i: usize = num(c, f, k, "a sonar index")?;
            if i >= MAX_READINGS {
                return Err(WireError::Invalid {
                    code: c,
                    what: format!("sonar index {i} is too large"),
                });
            }
            pairs.push((i, real(c, f, k + 1)?));
        }
        let n = pairs.iter().map(|(k, _)| k + 1).max().unwrap_or(0);
        let mut us = vec![0.0; n];
        for (k, u) in pairs {
            us[k] = u;
        }
        Ok(Sonars { us })
    }
}

/// `1003 CLOCK PAN TILT` (`%1.1f`): degrees.
impl Net43 for PtEncoders {
    const ON_WIRE: OnWire = OnWire::Pushed {
        subscribe: code::SUBSCRIBE_PANTILT_ENCODERS,
        unsubscribe: code::UNSUBSCRIBE_PANTILT_ENCODERS,
        push: code::PANTILT_ENCODERS,
    };
    fn write_push(&self, clock: u64, _: u64, out: &mut Vec<u8>) {
        let (pan, tilt) = (self.pan_angle, self.tilt_angle);
        let _ = writeln!(
            Adapter(out),
            "{} {clock} {pan:.1} {tilt:.1}",
            code::PANTILT_ENCODERS
        );
    }
    fn read_push(c: u32, f: &[&str], _: Origin) -> Result<Self, WireError> {
        count(c, f, 3)?;
        let [pan_angle, tilt_angle] = reals(c, f, 1)?;
        Ok(PtEncoders {
            pan_angle,
            tilt_angle,
        })
    }
}

/// `1021 CLOCK ZOOM` (`%1.1f`).
impl Net43 for ZoomEncoders {
    const ON_WIRE: OnWire = OnWire::Pushed {
        subscribe: code::SUBSCRIBE_ZOOM_ENCODERS,
        unsubscribe: code::UNSUBSCRIBE_ZOOM_ENCODERS,
        push: code::ZOOM_ENCODERS,
    };
    fn write_push(&self, clock: u64, _: u64, out: &mut Vec<u8>) {
        let zoom = self.zoom_position;
        let _ = writeln!(Adapter(out), "{} {clock} {zoom:.1}", code::ZOOM_ENCODERS);
    }
    fn read_push(c: u32, f: &[&str], _: Origin) -> Result<Self, WireError> {
        count(c, f, 2)?;
        let [zoom_position] = reals(c, f, 1)?;
        Ok(ZoomEncoders { zoom_position })
    }
}

/// `2003 CLOCK QX QY QZ QW WX WY WZ AX AY AZ` (jderobot's): the fields in
/// order, each in its shortest round-trip form.
impl Net43 for Imu {
    const ON_WIRE: OnWire = OnWire::Pushed {
        subscribe: code::SUBSCRIBE_IMU,
        unsubscribe: code::UNSUBSCRIBE_IMU,
        push: code::IMU,
    };
    fn write_push(&self, clock: u64, _: u64, out: &mut Vec<u8>) {
        write_values(out, code::IMU, clock, self.fields(), |a, v| {
            write!(a, " {v}")
        });
    }
    fn read_push(c: u32, f: &[&str], _: Origin) -> Result<Self, WireError> {
        count(c, f, 11)?;
        Ok(Imu::from_fields(reals(c, f, 1)?))
    }
}

/// `22 V AC` (mm/s) and `23 W AC` (deg/s).
impl Net43 for Motors {
    const ON_WIRE: OnWire = OnWire::Commanded {
        commands: &[code::DRIVE_SPEED, code::STEER_SPEED],
        limits: None,
        keep_alive: true,
    };
    fn apply(&mut self, req: &Request) {
        match *req {
            Request::DriveSpeed { v, .. } => self.v = v,
            Request::SteerSpeed { w, .. } => self.w = w,
            _ => {}
        }
    }
    fn requests(&self) -> Vec<Request> {
        vec![
            Request::DriveSpeed { v: self.v, ac: 0.0 },
            Request::SteerSpeed { w: self.w, ac: 0.0 },
        ]
    }
    fn farewell(&self) -> Vec<Request> {
        Motors::default().requests()
    }
}

/// `1006 PAN TILT PAN_SPEED TILT_SPEED` (deg, deg/s); `1004` asks for the limits,
/// `1005 MAXLON MAXLAT MINLON MINLAT MAXLONSPEED MAXLATSPEED` (`%.2f`) answers.
impl Net43 for PtMotors {
    const ON_WIRE: OnWire = OnWire::Commanded {
        commands: &[code::PANTILT_POSITION],
        limits: Some(Limits {
            query: code::PANTILT_LIMITS_QUERY,
            reply: code::PANTILT_LIMITS,
            // 4.3's text, typo included.
            unserved: "Error importing 'ptmotors' varialbes",
        }),
        keep_alive: false,
    };
    fn apply(&mut self, req: &Request) {
        if let Request::PtPosition {
            pan,
            tilt,
            pan_speed,
            tilt_speed,
        } = *req
        {
            self.longitude = pan;
            self.latitude = tilt;
            self.longitude_speed = pan_speed;
            self.latitude_speed = tilt_speed;
        }
    }
    fn requests(&self) -> Vec<Request> {
        vec![Request::PtPosition {
            pan: self.longitude,
            tilt: self.latitude,
            pan_speed: self.longitude_speed,
            tilt_speed: self.latitude_speed,
        }]
    }
    /// 4.3's client sent a last position when it stopped.
    fn farewell(&self) -> Vec<Request> {
        self.requests()
    }
    fn write_limits(&self, out: &mut Vec<u8>) {
        let v = [
            self.max_longitude,
            self.max_latitude,
            self.min_longitude,
            self.min_latitude,
            self.max_longitude_speed,
            self.max_latitude_speed,
        ];
        let _ = writeln!(
            Adapter(out),
            "{} {:.2} {:.2} {:.2} {:.2} {:.2} {:.2}",
            code::PANTILT_LIMITS,
            v[0],
            v[1],
            v[2],
            v[3],
            v[4],
            v[5]
        );
    }
    fn read_limits(&mut self, c: u32, f: &[&str]) -> Result<(), WireError> {
        count(c, f, 6)?;
        let v: [f32; 6] = reals(c, f, 0)?;
        self.max_longitude = v[0];
        self.max_latitude = v[1];
        self.min_longitude = v[2];
        self.min_latitude = v[3];
        self.max_longitude_speed = v[4];
        self.max_latitude_speed = v[5];
        Ok(())
    }
}

/// `1024 ZOOM SPEED`; `1022` asks for the limits, `1023 MAXZOOM MINZOOM
/// MAXZOOMSPEED` (`%.2f`) answers.
impl Net43 for ZoomMotors {
    const ON_WIRE: OnWire = OnWire::Commanded {
        commands: &[code::ZOOM_POSITION],
        limits: Some(Limits {
            query: code::ZOOM_LIMITS_QUERY,
            reply: code::ZOOM_LIMITS,
            unserved: "zoommotors are not served",
        }),
        keep_alive: false,
    };
    fn apply(&mut self, req: &Request) {
        if let Request::ZoomPosition { zoom, speed } = *req {
            self.zoom = zoom;
            self.zoom_speed = speed;
        }
    }
    fn requests(&self) -> Vec<Request> {
        vec![Request::ZoomPosition {
            zoom: self.zoom,
            speed: self.zoom_speed,
        }]
    }
    fn write_limits(&self, out: &mut Vec<u8>) {
        let _ = writeln!(
            Adapter(out),
            "{} {:.2} {:.2} {:.2}",
            code::ZOOM_LIMITS,
            self.max_zoom,
            self.min_zoom,
            self.max_zoom_speed
        );
    }
    fn read_limits(&mut self, c: u32, f: &[&str]) -> Result<(), WireError> {
        count(c, f, 3)?;
        [self.max_zoom, self.min_zoom, self.max_zoom_speed] = reals(c, f, 0)?;
        Ok(())
    }
}

/// What a client opens each connection with: the 20-byte name (`jdec`, NUL,
/// then [`TOKEN_MARK`] with a token, NUL-padded) and, with a token, the token
/// line `2100 SECRET\n`. Fails if the token is not a valid one
/// ([`crate::secret::check_token`]).
pub fn hello(token: Option<&str>) -> Result<Vec<u8>, String> {
    let mut b = vec![0u8; NAME_LEN];
    b[..4].copy_from_slice(b"jdec");
    if let Some(t) = token {
        crate::secret::check_token(t)?;
        b[5..5 + TOKEN_MARK.len()].copy_from_slice(TOKEN_MARK);
        let _ = writeln!(Adapter(&mut b), "{} {t}", code::TOKEN);
    }
    Ok(b)
}

/// Splits a received name into the printable name (up to the first NUL) and
/// whether a token line follows it (the name carries [`TOKEN_MARK`] after that NUL).
pub fn split_name(b: &[u8; NAME_LEN]) -> (String, bool) {
    let end = b.iter().position(|&c| c == 0).unwrap_or(NAME_LEN);
    let name: String = b[..end]
        .iter()
        .map(|&c| if c.is_ascii_graphic() { c as char } else { '?' })
        .collect();
    let rest = if end < NAME_LEN { &b[end + 1..] } else { &[] };
    let marked = rest.starts_with(TOKEN_MARK) && rest[TOKEN_MARK.len()..].iter().all(|&c| c == 0);
    (name, marked)
}

/// The secret of a token line (`2100 SECRET`, without its `\n`), if it is one.
pub fn token_of(line: &[u8]) -> Option<&[u8]> {
    line.strip_prefix(format!("{} ", code::TOKEN).as_bytes())
}

/// What [`LineReader::read_line`] gives.
#[derive(Debug)]
pub enum LineEvent<'a> {
    /// A whole line, without its `\n`.
    Line(&'a [u8]),
    /// The peer closed the connection (any partial line is dropped).
    Closed,
}

/// Reads `\n`-terminated lines of at most `max_line` bytes and the raw bytes that
/// follow a header, from a stream with a read timeout. A timeout keeps what was
/// read so far, so a line may arrive in pieces over several calls.
pub struct LineReader {
    buf: Vec<u8>,
    start: usize,
    end: usize,
    max_line: usize,
}

/// The error kind of a line longer than the limit.
pub fn too_long(max: usize) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidData,
        format!("line longer than {max} bytes"),
    )
}

/// Whether an I/O error is a read/write timeout.
pub fn is_timeout(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
    )
}

impl LineReader {
    pub fn new(max_line: usize) -> Self {
        LineReader {
            buf: vec![0; (max_line + 1).max(4096)],
            start: 0,
            end: 0,
            max_line,
        }
    }

    /// Bytes of an incomplete line (or of raw data) held.
    pub fn pending(&self) -> usize {
        self.end - self.start
    }

    /// The next line. Errors: the stream's (timeouts included: call again later) or
    /// InvalidData for a line longer than the limit.
    pub fn read_line<R: Read>(&mut self, r: &mut R) -> io::Result<LineEvent<'_>> {
        let mut scanned = 0;
        loop {
            if let Some(p) = self.buf[self.start + scanned..self.end]
                .iter()
                .position(|&b| b == b'\n')
            {
                let at = self.start + scanned + p;
                let line_start = self.start;
                self.start = at + 1;
                if self.start == self.end {
                    self.start = 0;
                    self.end = 0;
                }
                if at - line_start > self.max_line {
                    return Err(too_long(self.max_line));
                }
                return Ok(LineEvent::Line(&self.buf[line_start..at]));
            }
            scanned = self.end - self.start;
            if scanned > self.max_line {
                return Err(too_long(self.max_line));
            }
            if self.end == self.buf.len() {
                self.buf.copy_within(self.start..self.end, 0);
                self.end -= self.start;
                self.start = 0;
            }
            let n = r.read(&mut self.buf[self.end..])?;
            if n == 0 {
                return Ok(LineEvent::Closed);
            }
            self.end += n;
        }
    }

    /// Fills `dst` from what is buffered, then straight from the stream. After
    /// each read that leaves `dst` short (some bytes came, or the stream's timeout
    /// passed), `keep_going` gets the bytes read so far and says whether to go on:
    /// false gives a timeout error (the bytes read so far are lost, so give up the
    /// stream then). It is how a caller puts one deadline on the whole read: a
    /// peer sending a byte now and then never lets the stream's timeout pass.
    pub fn read_exact<R: Read>(
        &mut self,
        r: &mut R,
        dst: &mut [u8],
        mut keep_going: impl FnMut(usize) -> bool,
    ) -> io::Result<()> {
        let k = self.pending().min(dst.len());
        dst[..k].copy_from_slice(&self.buf[self.start..self.start + k]);
        self.start += k;
        if self.start == self.end {
            self.start = 0;
            self.end = 0;
        }
        let mut done = k;
        while done < dst.len() {
            match r.read(&mut dst[done..]) {
                Ok(0) => {
                    return Err(io::Error::new(
                        io::ErrorKind::UnexpectedEof,
                        format!("the connection closed after {done} of {} bytes", dst.len()),
                    ));
                }
                Ok(n) => {
                    done += n;
                    if done < dst.len() && !keep_going(done) {
                        return Err(io::ErrorKind::TimedOut.into());
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if is_timeout(&e) => {
                    if !keep_going(done) {
                        return Err(e);
                    }
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed(kind: Kind) -> Feed {
        Feed::of(kind).unwrap()
    }

    /// A kind's push read back from its line.
    fn read_back<T: Net43>(line: &str) -> Result<T, WireError> {
        match Message::parse(line.trim_end().as_bytes())? {
            Message::Push { feed: d, fields } => {
                assert_eq!(d.interface(), T::KIND);
                T::read_push(d.codes().2, &fields, (0.0, 0.0, 0.0))
            }
            m => panic!("not a push: {m:?}"),
        }
    }

    #[test]
    fn requests_round_trip_as_4_3_writes_them() {
        let reqs = [
            (Request::Goodbye, "0\n"),
            (Request::GoodbyeImages, "1000\n"),
            (Request::Subscribe(feed(Laser::KIND)), "27\n"),
            (Request::Unsubscribe(feed(Sonars::KIND)), "3\n"),
            (Request::DriveSpeed { v: 150.0, ac: 0.0 }, "22 150.0 0.0\n"),
            (Request::SteerSpeed { w: -12.5, ac: 0.0 }, "23 -12.5 0.0\n"),
            (Request::ImageQuery(2), "1019 2\n"),
            (Request::LimitsQuery(code::PANTILT_LIMITS_QUERY), "1004\n"),
            (Request::LimitsQuery(code::ZOOM_LIMITS_QUERY), "1022\n"),
        ];
        for (r, text) in reqs {
            let mut out = Vec::new();
            r.write_to(&mut out);
            assert_eq!(String::from_utf8(out).unwrap(), text);
            assert_eq!(Request::parse(text.trim_end().as_bytes()).unwrap(), r);
        }
    }

    #[test]
    fn bad_lines_are_errors() {
        for bad in [
            &b""[..],
            b"abc",
            b"22 1.0",
            b"22 nan 0.0",
            b"1019 x",
            b"99999",
            b"27 junk",
            b"\x00\x01",
            b"-1",
        ] {
            assert!(Request::parse(bad).is_err(), "{bad:?}");
        }
        assert_eq!(Request::parse(b"5").unwrap(), Request::Unhandled(5));
    }

    #[test]
    fn the_imu_extension_round_trips_exactly() {
        let fields = [
            0.0, 0.0, 0.38268343, 0.9238795, 0.0, 0.0, 0.25, 0.1, -0.2, 9.81,
        ];
        let mut out = Vec::new();
        Imu::from_fields(fields).write_push(12, 0, &mut out);
        let text = String::from_utf8(out).unwrap();
        assert_eq!(
            text,
            "2003 12 0 0 0.38268343 0.9238795 0 0 0.25 0.1 -0.2 9.81\n"
        );
        assert_eq!(read_back::<Imu>(&text).unwrap().fields(), fields);
        assert!(
            read_back::<Imu>("2003 12 0 0 0 1 0 0 0 0 0").is_err(),
            "a field short"
        );
        assert!(read_back::<Imu>("2003 12 0 0 0 1 0 0 0 0 0 nan").is_err());
        assert_eq!(
            Request::parse(b"2001").unwrap(),
            Request::Subscribe(feed(Imu::KIND))
        );
        assert_eq!(
            Request::parse(b"2002").unwrap(),
            Request::Unsubscribe(feed(Imu::KIND))
        );
    }

    #[test]
    fn pushes_parse_back() {
        let mut out = Vec::new();
        // Three readings over 180° (4.3's wire geometry) go as they are.
        Laser::jde43(vec![1, 2, 3], 3.0 / 180.0).write_push(7, 0, &mut out);
        Encoders::from_pose(1.0, 2.0, 90f32.to_radians()).write_push(8, 123, &mut out);
        Sonars {
            us: vec![100.0, 200.0],
        }
        .write_push(9, 0, &mut out);
        let text = String::from_utf8(out).unwrap();
        assert_eq!(
            text,
            "26 7 1 2 3\n10 8 1.0 2.0 90.00000 123\n1 9 0 100.0 1 200.0\n"
        );
        let l: Vec<&str> = text.lines().collect();
        assert_eq!(read_back::<Sonars>(l[2]).unwrap().us, [100.0, 200.0]);
        assert_eq!(read_back::<Laser>(l[0]).unwrap().readings, [1, 2, 3]);
    }

    #[test]
    fn a_marked_name_says_a_token_line_follows() {
        let secret = "0123456789abcdef0123456789abcdef";
        let h = hello(Some(secret)).unwrap();
        let name: [u8; NAME_LEN] = h[..NAME_LEN].try_into().unwrap();
        assert_eq!(&name[..15], b"jdec\0token-line");
        assert_eq!(split_name(&name), ("jdec".into(), true));
        let line = &h[NAME_LEN..];
        assert_eq!(line, format!("2100 {secret}\n").as_bytes());
        assert_eq!(token_of(&line[..line.len() - 1]), Some(secret.as_bytes()));
        let plain = hello(None).unwrap();
        assert_eq!(plain, b"jdec\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0");
        assert_eq!(
            split_name(&plain[..].try_into().unwrap()),
            ("jdec".into(), false)
        );
        // A pre-marker short token in the name is no token.
        let mut old = [0u8; NAME_LEN];
        old[..11].copy_from_slice(b"jdec\0s3cret");
        assert!(!split_name(&old).1);
        assert!(hello(Some("short")).is_err());
    }

    #[test]
    fn line_reader_limits_and_pieces() {
        let data = b"27\n1019 0\nxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx\n";
        let mut r = &data[..];
        let mut lr = LineReader::new(16);
        assert!(matches!(
            lr.read_line(&mut r).unwrap(),
            LineEvent::Line(b"27")
        ));
        assert!(matches!(
            lr.read_line(&mut r).unwrap(),
            LineEvent::Line(b"1019 0")
        ));
        assert!(lr.read_line(&mut r).is_err());
    }
}
