//! The iRobot Create 2 Open Interface as this driver speaks it (iRobot, *Create 2
//! Open Interface (OI) Specification based on the iRobot Roomba 600*): the
//! opcodes, Drive Direct, the sensor stream's framing and checksum, and the
//! packets the driver asks for. Pure functions, no I/O.

/// Start (128): starts the OI; the robot goes to Passive mode.
pub const START: u8 = 128;
/// Safe (131): Safe mode (the cliff, wheel-drop and charger safety stays on).
pub const SAFE: u8 = 131;
/// Full (132): Full mode (no safety: cliffs and wheel drops are ignored).
pub const FULL: u8 = 132;
/// Drive Direct (145): right then left wheel velocity, signed 16-bit big-endian mm/s.
pub const DRIVE_DIRECT: u8 = 145;
/// Stream (148): N packet ids; the robot then sends them every 15 ms.
pub const STREAM: u8 = 148;
/// Pause/Resume Stream (150): 0 pauses, 1 resumes.
pub const PAUSE_RESUME: u8 = 150;
/// Stop (173): stops the OI (Off mode).
pub const STOP: u8 = 173;
/// The first byte of every stream frame.
pub const HEADER: u8 = 19;
/// The wheels' top speed, mm/s (Drive Direct's range).
pub const MAX_WHEEL: f32 = 500.0;
/// The distance between the wheels, mm (the specification's 235 mm).
pub const WHEEL_BASE: f64 = 235.0;
/// Encoder counts per wheel revolution.
pub const COUNTS_PER_REV: f64 = 508.8;
/// Wheel diameter, mm.
pub const WHEEL_DIAMETER: f64 = 72.0;
/// mm per encoder count: π · 72 / 508.8.
pub const MM_PER_COUNT: f64 = std::f64::consts::PI * WHEEL_DIAMETER / COUNTS_PER_REV;
/// The stream period, s (the specification's 15 ms).
pub const STREAM_PERIOD_S: f64 = 0.015;

/// The packets the driver streams, with their data sizes (specification's
/// "Sensor Packets" table): 7 bumps and wheel drops, 21 charging state, 22
/// voltage, 23 current, 25 battery charge, 26 battery capacity, 35 OI mode, 43/44
/// left/right encoder counts, 45 light bumper, 46..51 light bump signals.
pub const PACKETS: &[(u8, usize)] = &[
    (7, 1),
    (21, 1),
    (22, 2),
    (23, 2),
    (25, 2),
    (26, 2),
    (35, 1),
    (43, 2),
    (44, 2),
    (45, 1),
    (46, 2),
    (47, 2),
    (48, 2),
    (49, 2),
    (50, 2),
    (51, 2),
];

/// The data size of packet `id` in [`PACKETS`].
pub fn packet_size(id: u8) -> Option<usize> {
    PACKETS.iter().find(|p| p.0 == id).map(|p| p.1)
}

/// The Stream command asking for [`PACKETS`].
pub fn stream_command() -> Vec<u8> {
    let mut c = vec![STREAM, PACKETS.len() as u8];
    c.extend(PACKETS.iter().map(|p| p.0));
    c
}

/// The `n` byte of a frame of [`PACKETS`]: each id and its data.
pub fn frame_n() -> usize {
    PACKETS.iter().map(|p| 1 + p.1).sum()
}

/// Drive Direct for (right, left) mm/s, each limited to ±500.
pub fn drive_direct(right: i16, left: i16) -> [u8; 5] {
    let r = right.clamp(-500, 500).to_be_bytes();
    let l = left.clamp(-500, 500).to_be_bytes();
    [DRIVE_DIRECT, r[0], r[1], l[0], l[1]]
}

/// The stop: Drive Direct with both wheels at 0 mm/s (as the driver drives with
/// Drive Direct; Drive 137 with velocity 0 stops the robot as well). The OI obeys
/// it in Safe and Full mode; in Passive mode the wheels are stopped already.
pub const STOP_WHEELS: [u8; 5] = [DRIVE_DIRECT, 0, 0, 0, 0];

/// The wheel speeds (right, left) mm/s for `v` mm/s forward and `w` deg/s
/// counter-clockwise; if one would exceed 500 mm/s both are scaled down so the
/// robot keeps its curve.
pub fn wheels(v: f32, w: f32) -> (i16, i16) {
    let half = (w as f64).to_radians() * WHEEL_BASE / 2.0;
    let (mut r, mut l) = (v as f64 + half, v as f64 - half);
    let top = r.abs().max(l.abs());
    if top > MAX_WHEEL as f64 {
        let k = MAX_WHEEL as f64 / top;
        r *= k;
        l *= k;
    }
    (r.round() as i16, l.round() as i16)
}

/// One decoded stream frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sensors {
    pub bump_right: bool,
    pub bump_left: bool,
    pub drop_right: bool,
    pub drop_left: bool,
    pub charging: u8,
    /// mV.
    pub voltage: u16,
    /// mA (negative: discharging).
    pub current: i16,
    /// mAh.
    pub charge: u16,
    /// mAh.
    pub capacity: u16,
    /// 0 Off, 1 Passive, 2 Safe, 3 Full.
    pub mode: u8,
    pub left_count: u16,
    pub right_count: u16,
    /// Packet 45's six bits (left, front left, centre left, centre right, front right, right).
    pub light_bumper: u8,
    /// Packets 46..51: the light bump signals, 0..4095.
    pub light: [u16; 6],
}

/// The name of OI mode `m` (packet 35).
pub fn mode_name(m: u8) -> &'static str {
    match m {
        0 => "Off",
        1 => "Passive",
        2 => "Safe",
        3 => "Full",
        _ => "unknown",
    }
}

/// What went wrong with the bytes on the line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// Bytes that are not a frame's header were skipped.
    Garbage(usize),
    /// A frame whose length is not what was asked for.
    Length(u8),
    /// A frame whose bytes do not sum to 0 mod 256.
    Checksum(u8),
    /// A frame with a packet that was not asked for, or out of order.
    Packet(u8),
    /// A good frame whose values no robot sends: an OI mode over 3 (packet 35)
    /// or a charging state over 5 (packet 21).
    Value { packet: u8, value: u8, max: u8 },
    /// A good frame whose wheel counts moved more than the wheels can turn
    /// (at most `max` counts since the last good frame at 500 mm/s): a counter
    /// reset, not motion. Odometry starts again from the new counts.
    Counts { left: i32, right: i32, max: i32 },
}

impl std::fmt::Display for FrameError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let want = frame_n();
        match self {
            FrameError::Garbage(n) => write!(
                f,
                "{n} byte(s) that are no stream frame (expected header 19, length {want}); another device, or a wrong baud rate?"
            ),
            FrameError::Length(n) => write!(
                f,
                "a stream frame of length {n} (expected header 19, length {want})"
            ),
            FrameError::Checksum(s) => write!(
                f,
                "a stream frame with a bad checksum (its bytes sum to {s}, expected 0 mod 256)"
            ),
            FrameError::Packet(id) => write!(
                f,
                "a stream frame with packet {id} where another was expected"
            ),
            FrameError::Value { packet, value, max } => write!(
                f,
                "a stream frame with packet {packet} = {value} (expected 0..{max})"
            ),
            FrameError::Counts { left, right, max } => write!(
                f,
                "wheel counts that jumped by {left} (left) and {right} (right) in one frame \
                 (expected at most {max} at 500 mm/s); odometry goes on from the new counts"
            ),
        }
    }
}

/// Takes the next frame from the front of `buf` (the bytes consumed are drained):
/// `Ok(Some)` a good frame, `Ok(None)` not enough bytes yet, `Err` bytes were
/// skipped (garbage, a bad frame: one byte after its header is dropped so the
/// next header is found).
pub fn take_frame(buf: &mut Vec<u8>) -> Result<Option<Sensors>, FrameError> {
    let n = frame_n();
    // Garbage before a header.
    if let Some(skip) = buf.iter().position(|&b| b == HEADER) {
        if skip > 0 {
            buf.drain(..skip);
            return Err(FrameError::Garbage(skip));
        }
    } else {
        let skip = buf.len();
        buf.clear();
        return if skip > 0 {
            Err(FrameError::Garbage(skip))
        } else {
            Ok(None)
        };
    }
    if buf.len() < 2 {
        return Ok(None);
    }
    if buf[1] as usize != n {
        let got = buf[1];
        buf.drain(..1);
        return Err(FrameError::Length(got));
    }
    if buf.len() < n + 3 {
        return Ok(None);
    }
    let sum = buf[..n + 3].iter().fold(0u8, |s, &b| s.wrapping_add(b));
    if sum != 0 {
        buf.drain(..1);
        return Err(FrameError::Checksum(sum));
    }
    let frame = &buf[2..2 + n];
    let mut s = Sensors::default();
    let mut i = 0;
    for &(id, size) in PACKETS {
        if frame[i] != id {
            let got = frame[i];
            buf.drain(..1);
            return Err(FrameError::Packet(got));
        }
        let d = &frame[i + 1..i + 1 + size];
        let u16be = || u16::from_be_bytes([d[0], d[1]]);
        match id {
            7 => {
                s.bump_right = d[0] & 1 != 0;
                s.bump_left = d[0] & 2 != 0;
                s.drop_right = d[0] & 4 != 0;
                s.drop_left = d[0] & 8 != 0;
            }
            21 => s.charging = d[0],
            22 => s.voltage = u16be(),
            23 => s.current = u16be() as i16,
            25 => s.charge = u16be(),
            26 => s.capacity = u16be(),
            35 => s.mode = d[0],
            43 => s.left_count = u16be(),
            44 => s.right_count = u16be(),
            45 => s.light_bumper = d[0],
            46..=51 => s.light[(id - 46) as usize] = u16be(),
            _ => {}
        }
        i += 1 + size;
    }
    buf.drain(..n + 3);
    for (packet, value, max) in [(35, s.mode, 3), (21, s.charging, 5)] {
        if value > max {
            return Err(FrameError::Value { packet, value, max });
        }
    }
    Ok(Some(s))
}

/// The most encoder counts a wheel can turn in `dt` (since the last good frame)
/// at its top speed, 500 mm/s, twice over and with two stream periods' slack.
pub fn max_counts(dt: std::time::Duration) -> i32 {
    ((dt.as_secs_f64() + 2.0 * STREAM_PERIOD_S) * MAX_WHEEL as f64 / MM_PER_COUNT * 2.0).ceil()
        as i32
}

/// Odometry from the wheel encoder counts (16-bit, wrapping).
#[derive(Clone, Copy, Debug, Default)]
pub struct Odometry {
    last: Option<(u16, u16)>,
    pub x: f64,
    pub y: f64,
    pub theta: f64,
}

impl Odometry {
    /// Advances by the counts of a new frame (the first frame only sets the origin).
    pub fn update(&mut self, left: u16, right: u16) {
        if let Some((l0, r0)) = self.last {
            let dl = left.wrapping_sub(l0) as i16 as f64 * MM_PER_COUNT;
            let dr = right.wrapping_sub(r0) as i16 as f64 * MM_PER_COUNT;
            let d = (dl + dr) / 2.0;
            let dth = (dr - dl) / WHEEL_BASE;
            let mid = self.theta + dth / 2.0;
            self.x += d * mid.cos();
            self.y += d * mid.sin();
            self.theta += dth;
        }
        self.last = Some((left, right));
    }
    /// The counts' step (left, right) from the last frame's, if there was one.
    pub fn step(&self, left: u16, right: u16) -> Option<(i32, i32)> {
        self.last.map(|(l0, r0)| {
            (
                left.wrapping_sub(l0) as i16 as i32,
                right.wrapping_sub(r0) as i16 as i32,
            )
        })
    }
    /// Forgets the last counts (a new session: the robot's counters may have moved).
    pub fn rebase(&mut self) {
        self.last = None;
    }
}

/// A light bump signal (0..4095) as an approximate range, mm: the sensors are
/// uncalibrated infrared reflectance, so this is a monotone guess,
/// `LIGHT_RANGE_K / √signal` capped at [`LIGHT_MAX_MM`] (no reflection).
pub fn light_range(signal: u16) -> f32 {
    if signal == 0 {
        return LIGHT_MAX_MM;
    }
    (LIGHT_RANGE_K / (signal as f32).sqrt()).min(LIGHT_MAX_MM)
}
/// See [`light_range`].
pub const LIGHT_RANGE_K: f32 = 1000.0;
/// The light bumper's "nothing seen", mm.
pub const LIGHT_MAX_MM: f32 = 250.0;

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(s: &Sensors) -> Vec<u8> {
        let mut f = vec![HEADER, frame_n() as u8];
        for &(id, size) in PACKETS {
            f.push(id);
            let v: u16 = match id {
                7 => s.bump_right as u16 | (s.bump_left as u16) << 1,
                35 => s.mode as u16,
                43 => s.left_count,
                44 => s.right_count,
                22 => s.voltage,
                _ => 0,
            };
            if size == 1 {
                f.push(v as u8);
            } else {
                f.extend(v.to_be_bytes());
            }
        }
        let sum = f.iter().fold(0u8, |a, &b| a.wrapping_add(b));
        f.push(0u8.wrapping_sub(sum));
        f
    }

    #[test]
    fn frames_decode_resync_and_refuse_bad_checksums() {
        let s = Sensors {
            bump_left: true,
            mode: 2,
            left_count: 65530,
            right_count: 7,
            voltage: 14_800,
            ..Sensors::default()
        };
        let f = frame(&s);
        let mut buf = vec![1, 2, 3];
        buf.extend(&f);
        assert_eq!(take_frame(&mut buf), Err(FrameError::Garbage(3)));
        assert_eq!(take_frame(&mut buf).unwrap().unwrap().left_count, 65530);
        assert!(buf.is_empty());
        let mut bad = f.clone();
        *bad.last_mut().unwrap() ^= 1;
        bad.extend(&f);
        assert!(matches!(take_frame(&mut bad), Err(FrameError::Checksum(_))));
        let mut got = None;
        for _ in 0..100 {
            if let Ok(Some(s)) = take_frame(&mut bad) {
                got = Some(s);
                break;
            }
        }
        assert_eq!(got.unwrap().voltage, 14_800);
        let mut half = f[..10].to_vec();
        assert_eq!(take_frame(&mut half), Ok(None));
        // A frame that sums right but says OI mode 9.
        let mut odd = frame(&Sensors { mode: 9, ..s });
        assert_eq!(
            take_frame(&mut odd),
            Err(FrameError::Value {
                packet: 35,
                value: 9,
                max: 3
            })
        );
        assert!(odd.is_empty());
        // 15 ms at 500 mm/s is 17 counts; the bound leaves room, a reset does not fit.
        let max = max_counts(std::time::Duration::from_millis(15));
        assert!((60..200).contains(&max), "{max}");
        let mut o = Odometry::default();
        o.update(100, 100);
        assert_eq!(o.step(117, 83), Some((17, -17)));
        assert_eq!(o.step(5, 65530), Some((-95, -106)));
    }

    #[test]
    fn wheels_and_odometry() {
        assert_eq!(wheels(200.0, 0.0), (200, 200));
        let (r, l) = wheels(0.0, 90.0);
        assert_eq!((r, -l), (185, 185));
        let (r, l) = wheels(500.0, 30.0);
        assert!(r == 500 && l < 500, "{r} {l}");
        assert_eq!(drive_direct(-1, 500), [145, 0xFF, 0xFF, 0x01, 0xF4]);
        let mut o = Odometry::default();
        o.update(65500, 65500);
        let c = (1000.0 / MM_PER_COUNT) as u16;
        o.update(65500u16.wrapping_add(c), 65500u16.wrapping_add(c));
        assert!((o.x - 1000.0).abs() < 1.0, "{}", o.x);
    }
}
