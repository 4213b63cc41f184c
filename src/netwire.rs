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
//! **Token.** 4.3's name is `jdec` and NUL bytes. With a shared secret, the name
//! is `jdec`, NUL, then the secret (at most [`MAX_TOKEN`] bytes) NUL-padded: a 4.3
//! server prints only `jdec` (its `strncpy`/`%s` stops at the first NUL), so the
//! wire stays 4.3's. See [`client_name`] and [`split_name`].

use std::{
    fmt::Write as _,
    io::{self, Read, Write},
};

/// Length of the client name that opens every connection (4.3's MAX_CLIENT_NAME).
pub const NAME_LEN: usize = 20;
/// The longest token that fits in the name after `jdec` and a NUL.
pub const MAX_TOKEN: usize = NAME_LEN - 5;
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
    /// Codes 4.3 declared but never handled (ir, bumpers, battery, sensed speeds,
    /// limp, replay, other image formats, pan-tilt relative/reset/origin/halt).
    pub const UNHANDLED: &[u32] = &[
        4, 5, 6, 7, 8, 9, 13, 14, 15, 16, 17, 18, 19, 20, 21, 24, 25, 1007, 1008, 1009, 1010, 1011,
        1012, 1013, 1014, 1015, 1016, 1017, 1018,
    ];
}

/// A feed: a device whose values are pushed to its subscribers (4.3 calls it a device).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Feed {
    Laser,
    Encoders,
    Sonars,
    PtEncoders,
    ZoomEncoders,
    Imu,
}

impl Feed {
    pub const ALL: [Feed; Feed::COUNT] = [
        Feed::Laser,
        Feed::Encoders,
        Feed::Sonars,
        Feed::PtEncoders,
        Feed::ZoomEncoders,
        Feed::Imu,
    ];
    pub const COUNT: usize = 6;
    /// Index in [`Feed::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
    /// (subscribe, unsubscribe, push) codes.
    pub fn codes(self) -> (u32, u32, u32) {
        match self {
            Feed::Laser => (code::SUBSCRIBE_LASER, code::UNSUBSCRIBE_LASER, code::LASER),
            Feed::Encoders => (
                code::SUBSCRIBE_ENCODERS,
                code::UNSUBSCRIBE_ENCODERS,
                code::ENCODERS,
            ),
            Feed::Sonars => (code::SUBSCRIBE_US, code::UNSUBSCRIBE_US, code::SONARS),
            Feed::PtEncoders => (
                code::SUBSCRIBE_PANTILT_ENCODERS,
                code::UNSUBSCRIBE_PANTILT_ENCODERS,
                code::PANTILT_ENCODERS,
            ),
            Feed::ZoomEncoders => (
                code::SUBSCRIBE_ZOOM_ENCODERS,
                code::UNSUBSCRIBE_ZOOM_ENCODERS,
                code::ZOOM_ENCODERS,
            ),
            Feed::Imu => (code::SUBSCRIBE_IMU, code::UNSUBSCRIBE_IMU, code::IMU),
        }
    }
    /// The interface family name.
    pub fn interface(self) -> &'static str {
        match self {
            Feed::Laser => "laser",
            Feed::Encoders => "encoders",
            Feed::Sonars => "sonars",
            Feed::PtEncoders => "pantiltencoders",
            Feed::ZoomEncoders => "zoomencoders",
            Feed::Imu => "imu",
        }
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
    /// `1004`.
    PtLimitsQuery,
    /// `1024 ZOOM SPEED`.
    ZoomPosition {
        zoom: f32,
        speed: f32,
    },
    /// `1022`.
    ZoomLimitsQuery,
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
        let dev = Feed::ALL
            .iter()
            .find(|d| d.codes().0 == c || d.codes().1 == c);
        if let Some(&d) = dev {
            count(c, &f, 0)?;
            return Ok(if d.codes().0 == c {
                Request::Subscribe(d)
            } else {
                Request::Unsubscribe(d)
            });
        }
        Ok(match c {
            GOODBYE | GOODBYE_IMAGES | PANTILT_LIMITS_QUERY | ZOOM_LIMITS_QUERY => {
                count(c, &f, 0)?;
                match c {
                    GOODBYE => Request::Goodbye,
                    GOODBYE_IMAGES => Request::GoodbyeImages,
                    PANTILT_LIMITS_QUERY => Request::PtLimitsQuery,
                    _ => Request::ZoomLimitsQuery,
                }
            }
            DRIVE_SPEED => {
                count(c, &f, 2)?;
                Request::DriveSpeed {
                    v: real(c, &f, 0)?,
                    ac: real(c, &f, 1)?,
                }
            }
            STEER_SPEED => {
                count(c, &f, 2)?;
                Request::SteerSpeed {
                    w: real(c, &f, 0)?,
                    ac: real(c, &f, 1)?,
                }
            }
            PANTILT_POSITION => {
                count(c, &f, 4)?;
                Request::PtPosition {
                    pan: real(c, &f, 0)?,
                    tilt: real(c, &f, 1)?,
                    pan_speed: real(c, &f, 2)?,
                    tilt_speed: real(c, &f, 3)?,
                }
            }
            ZOOM_POSITION => {
                count(c, &f, 2)?;
                Request::ZoomPosition {
                    zoom: real(c, &f, 0)?,
                    speed: real(c, &f, 1)?,
                }
            }
            RGB24BPP_IMAGE_QUERY => {
                count(c, &f, 1)?;
                Request::ImageQuery(num(c, &f, 0, "a network id (0, 1, 2 ...)")?)
            }
            c if code::UNHANDLED.contains(&c) => Request::Unhandled(c),
            c => return Err(WireError::UnknownCode(c)),
        })
    }

    /// Appends the line (with its `\n`) as a 4.3 client writes it (`%1.1f` speeds).
    pub fn write_to(&self, out: &mut Vec<u8>) {
        let mut s = String::new();
        let _ = match *self {
            Request::Goodbye => writeln!(s, "{}", code::GOODBYE),
            Request::GoodbyeImages => writeln!(s, "{}", code::GOODBYE_IMAGES),
            Request::Subscribe(d) => writeln!(s, "{}", d.codes().0),
            Request::Unsubscribe(d) => writeln!(s, "{}", d.codes().1),
            Request::DriveSpeed { v, ac } => writeln!(s, "{} {v:.1} {ac:.1}", code::DRIVE_SPEED),
            Request::SteerSpeed { w, ac } => writeln!(s, "{} {w:.1} {ac:.1}", code::STEER_SPEED),
            Request::PtPosition {
                pan,
                tilt,
                pan_speed,
                tilt_speed,
            } => writeln!(
                s,
                "{} {pan:.2} {tilt:.2} {pan_speed:.2} {tilt_speed:.2}",
                code::PANTILT_POSITION
            ),
            Request::PtLimitsQuery => writeln!(s, "{}", code::PANTILT_LIMITS_QUERY),
            Request::ZoomPosition { zoom, speed } => {
                writeln!(s, "{} {zoom:.2} {speed:.2}", code::ZOOM_POSITION)
            }
            Request::ZoomLimitsQuery => writeln!(s, "{}", code::ZOOM_LIMITS_QUERY),
            Request::ImageQuery(id) => writeln!(s, "{} {id}", code::RGB24BPP_IMAGE_QUERY),
            Request::Unhandled(c) => writeln!(s, "{c}"),
        };
        out.extend_from_slice(s.as_bytes());
    }
}

/// A server → client message (an image's pixels follow its header).
#[derive(Clone, Debug, PartialEq)]
pub enum Message {
    /// `26 CLOCK R0 ..`: mm.
    Laser { clock: u64, readings: Vec<i32> },
    /// `10 CLOCK X Y THETA_DEG TIME`: mm, mm, degrees; TIME is µs (4.3 sent the clock).
    Encoders {
        clock: u64,
        x: f32,
        y: f32,
        theta_deg: f32,
        time: u64,
    },
    /// `1 CLOCK I0 US0 I1 US1 ..`: (index, mm) pairs.
    Sonars { clock: u64, us: Vec<(usize, f32)> },
    /// `1003 CLOCK PAN TILT`: degrees.
    PtEncoders { clock: u64, pan: f32, tilt: f32 },
    /// `1021 CLOCK ZOOM`.
    ZoomEncoders { clock: u64, zoom: f32 },
    /// `2003 CLOCK QX QY QZ QW WX WY WZ AX AY AZ` (jderobot's): the [`Imu`] fields
    /// in order.
    ///
    /// [`Imu`]: crate::interfaces::Imu
    Imu { clock: u64, fields: [f32; 10] },
    /// `1005 MAXLON MAXLAT MINLON MINLAT MAXLONSPEED MAXLATSPEED`.
    PtLimits([f32; 6]),
    /// `1023 MAXZOOM MINZOOM MAXZOOMSPEED`.
    ZoomLimits([f32; 3]),
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

impl Message {
    /// Parses one line (without its `\n`).
    pub fn parse(line: &[u8]) -> Result<Message, WireError> {
        use code::*;
        let (c, f) = split(line)?;
        let many = |f: &[&str]| -> Result<(), WireError> {
            if f.len() > MAX_READINGS * 2 + 1 {
                return Err(WireError::Invalid {
                    code: c,
                    what: format!("{} fields is too many", f.len()),
                });
            }
            Ok(())
        };
        Ok(match c {
            LASER => {
                many(&f)?;
                if f.is_empty() {
                    return Err(WireError::FieldCount {
                        code: c,
                        expected: 1,
                        got: 0,
                    });
                }
                let clock = num(c, &f, 0, "a clock")?;
                let readings = (1..f.len())
                    .map(|i| num(c, &f, i, "a range in mm (integer)"))
                    .collect::<Result<_, _>>()?;
                Message::Laser { clock, readings }
            }
            ENCODERS => {
                count(c, &f, 5)?;
                Message::Encoders {
                    clock: num(c, &f, 0, "a clock")?,
                    x: real(c, &f, 1)?,
                    y: real(c, &f, 2)?,
                    theta_deg: real(c, &f, 3)?,
                    time: num(c, &f, 4, "a time stamp")?,
                }
            }
            SONARS => {
                many(&f)?;
                if f.is_empty() || f.len() % 2 != 1 {
                    return Err(WireError::Invalid {
                        code: c,
                        what: "expected a clock then (index, mm) pairs".into(),
                    });
                }
                let clock = num(c, &f, 0, "a clock")?;
                let mut us = Vec::with_capacity(f.len() / 2);
                for k in (1..f.len()).step_by(2) {
                    let i: usize = num(c, &f, k, "a sonar index")?;
                    if i >= MAX_READINGS {
                        return Err(WireError::Invalid {
                            code: c,
                            what: format!("sonar index {i} is too large"),
                        });
                    }
                    us.push((i, real(c, &f, k + 1)?));
                }
                Message::Sonars { clock, us }
            }
            PANTILT_ENCODERS => {
                count(c, &f, 3)?;
                Message::PtEncoders {
                    clock: num(c, &f, 0, "a clock")?,
                    pan: real(c, &f, 1)?,
                    tilt: real(c, &f, 2)?,
                }
            }
            ZOOM_ENCODERS => {
                count(c, &f, 2)?;
                Message::ZoomEncoders {
                    clock: num(c, &f, 0, "a clock")?,
                    zoom: real(c, &f, 1)?,
                }
            }
            IMU => {
                count(c, &f, 11)?;
                let mut fields = [0.0; 10];
                for (i, x) in fields.iter_mut().enumerate() {
                    *x = real(c, &f, i + 1)?;
                }
                Message::Imu {
                    clock: num(c, &f, 0, "a clock")?,
                    fields,
                }
            }
            PANTILT_LIMITS => {
                count(c, &f, 6)?;
                let mut v = [0.0; 6];
                for (i, x) in v.iter_mut().enumerate() {
                    *x = real(c, &f, i)?;
                }
                Message::PtLimits(v)
            }
            ZOOM_LIMITS => {
                count(c, &f, 3)?;
                let mut v = [0.0; 3];
                for (i, x) in v.iter_mut().enumerate() {
                    *x = real(c, &f, i)?;
                }
                Message::ZoomLimits(v)
            }
            RGB24BPP_IMAGE => {
                count(c, &f, 5)?;
                Message::Image {
                    clock: num(c, &f, 0, "a clock")?,
                    netid: num(c, &f, 1, "a network id")?,
                    width: num(c, &f, 2, "a width in pixels")?,
                    height: num(c, &f, 3, "a height in pixels")?,
                    depth: num(c, &f, 4, "a depth in bytes per pixel")?,
                }
            }
            ERROR => Message::Error(f.join(" ")),
            c => return Err(WireError::UnknownCode(c)),
        })
    }
}

/// Appends `26 CLOCK R0 .. RN-1\n`.
pub fn write_laser(out: &mut Vec<u8>, clock: u64, readings: &[i32]) {
    let mut s = String::with_capacity(16 + readings.len() * 5);
    let _ = write!(s, "{} {clock}", code::LASER);
    for r in readings {
        let _ = write!(s, " {r}");
    }
    s.push('\n');
    out.extend_from_slice(s.as_bytes());
}

/// Appends `10 CLOCK X Y THETA_DEG TIME\n` (`%1.1f %1.1f %1.5f`).
pub fn write_encoders(out: &mut Vec<u8>, clock: u64, x: f32, y: f32, theta_deg: f32, time: u64) {
    let _ = writeln!(
        Adapter(out),
        "{} {clock} {x:.1} {y:.1} {theta_deg:.5} {time}",
        code::ENCODERS
    );
}

/// Appends `1 CLOCK 0 US0 1 US1 ..\n` (`%1.1f`), one pair per sonar.
pub fn write_sonars(out: &mut Vec<u8>, clock: u64, us: &[f32]) {
    let mut s = String::with_capacity(16 + us.len() * 10);
    let _ = write!(s, "{} {clock}", code::SONARS);
    for (i, u) in us.iter().enumerate() {
        let _ = write!(s, " {i} {u:.1}");
    }
    s.push('\n');
    out.extend_from_slice(s.as_bytes());
}

/// Appends `1003 CLOCK PAN TILT\n` (`%1.1f`).
pub fn write_pt_encoders(out: &mut Vec<u8>, clock: u64, pan: f32, tilt: f32) {
    let _ = writeln!(
        Adapter(out),
        "{} {clock} {pan:.1} {tilt:.1}",
        code::PANTILT_ENCODERS
    );
}

/// Appends `1021 CLOCK ZOOM\n` (`%1.1f`).
pub fn write_zoom_encoders(out: &mut Vec<u8>, clock: u64, zoom: f32) {
    let _ = writeln!(Adapter(out), "{} {clock} {zoom:.1}", code::ZOOM_ENCODERS);
}

/// Appends `2003 CLOCK QX QY QZ QW WX WY WZ AX AY AZ\n`, each number in its
/// shortest round-trip form.
pub fn write_imu(out: &mut Vec<u8>, clock: u64, fields: [f32; 10]) {
    let mut s = String::with_capacity(128);
    let _ = write!(s, "{} {clock}", code::IMU);
    for v in fields {
        let _ = write!(s, " {v}");
    }
    s.push('\n');
    out.extend_from_slice(s.as_bytes());
}

/// Appends `1005 ..\n` (`%.2f` × 6): max_longitude, max_latitude, min_longitude,
/// min_latitude, max_longitude_speed, max_latitude_speed.
pub fn write_pt_limits(out: &mut Vec<u8>, v: [f32; 6]) {
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

/// Appends `1023 MAXZOOM MINZOOM MAXZOOMSPEED\n` (`%.2f`).
pub fn write_zoom_limits(out: &mut Vec<u8>, v: [f32; 3]) {
    let _ = writeln!(
        Adapter(out),
        "{} {:.2} {:.2} {:.2}",
        code::ZOOM_LIMITS,
        v[0],
        v[1],
        v[2]
    );
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

/// The 20-byte name a client opens each connection with: `jdec`, NUL, then the
/// token if any, NUL-padded. Fails if the token is longer than [`MAX_TOKEN`] or
/// not printable ASCII.
pub fn client_name(token: Option<&str>) -> Result<[u8; NAME_LEN], String> {
    let mut b = [0u8; NAME_LEN];
    b[..4].copy_from_slice(b"jdec");
    if let Some(t) = token {
        check_token(t)?;
        b[5..5 + t.len()].copy_from_slice(t.as_bytes());
    }
    Ok(b)
}

/// Checks a token: 1 to [`MAX_TOKEN`] printable ASCII characters, no spaces.
pub fn check_token(t: &str) -> Result<(), String> {
    if t.is_empty() || t.len() > MAX_TOKEN || !t.bytes().all(|b| b.is_ascii_graphic()) {
        return Err(format!(
            "a token is 1 to {MAX_TOKEN} printable ASCII characters without spaces (it travels in 4.3's 20-byte client name); got {} characters",
            t.len()
        ));
    }
    Ok(())
}

/// Splits a received name into the printable name (up to the first NUL) and the
/// token that follows that NUL (up to the next NUL; empty if none).
pub fn split_name(b: &[u8; NAME_LEN]) -> (String, &[u8]) {
    let end = b.iter().position(|&c| c == 0).unwrap_or(NAME_LEN);
    let name: String = b[..end]
        .iter()
        .map(|&c| if c.is_ascii_graphic() { c as char } else { '?' })
        .collect();
    let rest = if end < NAME_LEN { &b[end + 1..] } else { &[] };
    let tend = rest.iter().position(|&c| c == 0).unwrap_or(rest.len());
    (name, &rest[..tend])
}

/// Compares two byte strings in time independent of where they differ.
pub fn same_secret(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
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

    /// Fills `dst` from what is buffered, then straight from the stream. A timeout
    /// calls `on_timeout`, which says whether to keep waiting (false gives the
    /// timeout error; the bytes read so far are lost, so give up the stream then).
    pub fn read_exact<R: Read>(
        &mut self,
        r: &mut R,
        dst: &mut [u8],
        mut on_timeout: impl FnMut() -> bool,
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
                Ok(n) => done += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if is_timeout(&e) => {
                    if !on_timeout() {
                        return Err(e);
                    }
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }
}

/// Writes every slice (one `writev` when the socket takes it all).
pub fn write_all_vectored<W: Write>(w: &mut W, parts: &[&[u8]]) -> io::Result<()> {
    let mut slices: Vec<io::IoSlice<'_>> = parts.iter().map(|p| io::IoSlice::new(p)).collect();
    let mut bufs = &mut slices[..];
    while !bufs.is_empty() {
        match w.write_vectored(bufs) {
            Ok(0) => {
                return Err(io::Error::new(
                    io::ErrorKind::WriteZero,
                    "the connection took no more bytes",
                ));
            }
            Ok(n) => io::IoSlice::advance_slices(&mut bufs, n),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_round_trip_as_4_3_writes_them() {
        let reqs = [
            (Request::Goodbye, "0\n"),
            (Request::GoodbyeImages, "1000\n"),
            (Request::Subscribe(Feed::Laser), "27\n"),
            (Request::Unsubscribe(Feed::Sonars), "3\n"),
            (Request::DriveSpeed { v: 150.0, ac: 0.0 }, "22 150.0 0.0\n"),
            (Request::SteerSpeed { w: -12.5, ac: 0.0 }, "23 -12.5 0.0\n"),
            (Request::ImageQuery(2), "1019 2\n"),
            (Request::PtLimitsQuery, "1004\n"),
            (Request::ZoomLimitsQuery, "1022\n"),
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
        write_imu(&mut out, 12, fields);
        let text = String::from_utf8(out).unwrap();
        assert_eq!(
            text,
            "2003 12 0 0 0.38268343 0.9238795 0 0 0.25 0.1 -0.2 9.81\n"
        );
        assert_eq!(
            Message::parse(text.trim_end().as_bytes()).unwrap(),
            Message::Imu { clock: 12, fields }
        );
        assert!(
            Message::parse(b"2003 12 0 0 0 1 0 0 0 0 0").is_err(),
            "a field short"
        );
        assert!(Message::parse(b"2003 12 0 0 0 1 0 0 0 0 0 nan").is_err());
        assert_eq!(
            Request::parse(b"2001").unwrap(),
            Request::Subscribe(Feed::Imu)
        );
        assert_eq!(
            Request::parse(b"2002").unwrap(),
            Request::Unsubscribe(Feed::Imu)
        );
    }

    #[test]
    fn pushes_parse_back() {
        let mut out = Vec::new();
        write_laser(&mut out, 7, &[1, 2, 3]);
        write_encoders(&mut out, 8, 1.0, 2.0, 90.0, 123);
        write_sonars(&mut out, 9, &[100.0, 200.0]);
        let text = String::from_utf8(out).unwrap();
        assert_eq!(
            text,
            "26 7 1 2 3\n10 8 1.0 2.0 90.00000 123\n1 9 0 100.0 1 200.0\n"
        );
        let l: Vec<&str> = text.lines().collect();
        assert_eq!(
            Message::parse(l[2].as_bytes()).unwrap(),
            Message::Sonars {
                clock: 9,
                us: vec![(0, 100.0), (1, 200.0)]
            }
        );
    }

    #[test]
    fn names_carry_a_token_after_the_nul() {
        let n = client_name(Some("s3cret")).unwrap();
        assert_eq!(&n[..10], b"jdec\0s3cre");
        let (name, tok) = split_name(&n);
        assert_eq!(name, "jdec");
        assert_eq!(tok, b"s3cret");
        let plain = client_name(None).unwrap();
        let (_, none) = split_name(&plain);
        assert!(none.is_empty());
        assert!(client_name(Some("far too long a secret")).is_err());
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
