//! VISCA for the Sony EVI-D100: packet framing, the commands and inquiries 4.3 used,
//! reply classification, 4.3's speed tables and the unit conversions.
//!
//! A packet is a header byte, a message and the terminator `FF`. From the
//! controller (address 0) to camera `x` the header is `8x`; the camera answers with
//! `(x+8)0` (`90` for camera 1): `90 4z FF` ACK (command accepted into socket z),
//! `90 5z FF` completion, `90 50 ... FF` an inquiry's answer, `90 6z ee FF` an error.

/// The terminator.
pub const END: u8 = 0xFF;

/// Pan speeds of modes 1..24, deg/s (4.3's table); tilt uses the first 20.
pub const SPEEDS: [f32; 24] = [
    2.0, 2.4, 3.0, 3.7, 4.7, 6.1, 7.4, 9.1, 11.0, 14.0, 18.0, 22.0, 27.0, 34.0, 42.0, 52.0, 65.0,
    81.0, 100.0, 125.0, 155.0, 190.0, 240.0, 300.0,
];
pub const PAN_MODES: u8 = 24;
pub const TILT_MODES: u8 = 20;

/// 4.3's limits, degrees and deg/s.
pub const PAN_LIMIT: f32 = 100.0;
pub const TILT_LIMIT: f32 = 25.0;
pub const PAN_MAX_SPEED: f32 = 300.0;
pub const TILT_MAX_SPEED: f32 = 125.0;
/// Device units at the limits: pan ±0x08DB, tilt ±0x0190 (EVI-D100 position table).
pub const PAN_UNITS: i32 = 0x08DB;
pub const TILT_UNITS: i32 = 0x0190;
/// Zoom: levels 0..40 (10x optical × 4x digital) over device units 0..0x7000.
pub const ZOOM_MAX: f32 = 40.0;
pub const ZOOM_UNITS: i32 = 0x7000;
pub const ZOOM_MAX_SPEED: f32 = 7.0;

/// The VISCA error codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ViscaError {
    /// 0x01: message length error.
    Length,
    /// 0x02: syntax error (not a command this camera knows).
    Syntax,
    /// 0x03: command buffer full (both sockets busy).
    BufferFull,
    /// 0x04: command cancelled.
    Cancelled,
    /// 0x05: no socket (to cancel).
    NoSocket,
    /// 0x41: command not executable now (power off, wrong mode).
    NotExecutable,
    Other(u8),
}

impl ViscaError {
    pub fn from_code(c: u8) -> Self {
        match c {
            0x01 => ViscaError::Length,
            0x02 => ViscaError::Syntax,
            0x03 => ViscaError::BufferFull,
            0x04 => ViscaError::Cancelled,
            0x05 => ViscaError::NoSocket,
            0x41 => ViscaError::NotExecutable,
            o => ViscaError::Other(o),
        }
    }
}

impl std::fmt::Display for ViscaError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ViscaError::Length => f.write_str("message length error (0x01)"),
            ViscaError::Syntax => f.write_str("syntax error (0x02)"),
            ViscaError::BufferFull => f.write_str("command buffer full (0x03)"),
            ViscaError::Cancelled => f.write_str("command cancelled (0x04)"),
            ViscaError::NoSocket => f.write_str("no socket (0x05)"),
            ViscaError::NotExecutable => f.write_str("command not executable (0x41)"),
            ViscaError::Other(c) => write!(f, "error 0x{c:02X}"),
        }
    }
}

/// A camera's packet, classified.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Reply {
    Ack(u8),
    Completion(u8),
    /// An inquiry's answer: the bytes between `90 50` and `FF`.
    Answer(Vec<u8>),
    Error(u8, ViscaError),
    /// A broadcast reply (`88 ...`): address set, IF_Clear.
    Broadcast(Vec<u8>),
}

impl std::fmt::Display for Reply {
    /// In words, for messages: `a broadcast reply (88 30 02 FF)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Reply::Ack(s) => write!(f, "an ACK (socket {s})"),
            Reply::Completion(s) => write!(f, "a completion (socket {s})"),
            Reply::Answer(a) => write!(f, "an inquiry answer (data {})", hex(a)),
            Reply::Error(s, e) => write!(f, "an error, {e} (socket {s})"),
            Reply::Broadcast(b) => write!(f, "a broadcast reply ({})", hex(b)),
        }
    }
}

/// The EVI-D100's range of a position or zoom answer, device units: pan ±0x08DB,
/// tilt ±0x0190, zoom 0..0x7000. A value outside it is refused.
pub fn unit_range(what: &str) -> (i32, i32) {
    match what {
        "pan" => (-PAN_UNITS, PAN_UNITS),
        "tilt" => (-TILT_UNITS, TILT_UNITS),
        _ => (0, ZOOM_UNITS),
    }
}

/// Classifies one packet (with its `FF`) from camera `addr`; None if it is not VISCA.
pub fn classify(addr: u8, p: &[u8]) -> Option<Reply> {
    if p.len() < 3 || *p.last()? != END || p[..p.len() - 1].contains(&END) {
        return None;
    }
    if p[0] == 0x88 {
        return Some(Reply::Broadcast(p.to_vec()));
    }
    if p[0] != (addr + 8) << 4 {
        return None;
    }
    let (kind, socket) = (p[1] & 0xF0, p[1] & 0x0F);
    match (kind, p.len()) {
        (0x40, 3) => Some(Reply::Ack(socket)),
        (0x50, 3) if socket != 0 => Some(Reply::Completion(socket)),
        (0x50, _) if socket == 0 => Some(Reply::Answer(p[2..p.len() - 1].to_vec())),
        (0x60, 4) => Some(Reply::Error(socket, ViscaError::from_code(p[2]))),
        _ => None,
    }
}

/// Four nibbles `0p 0q 0r 0s` of a 16-bit value (two's complement).
pub fn nibbles(v: i32) -> [u8; 4] {
    let u = v as u16;
    [
        ((u >> 12) & 0xF) as u8,
        ((u >> 8) & 0xF) as u8,
        ((u >> 4) & 0xF) as u8,
        (u & 0xF) as u8,
    ]
}

/// The signed 16-bit value of four nibbles; None unless each is 0..F.
pub fn from_nibbles(n: &[u8]) -> Option<i32> {
    if n.len() != 4 || n.iter().any(|&b| b > 0x0F) {
        return None;
    }
    let u = ((n[0] as u16) << 12) | ((n[1] as u16) << 8) | ((n[2] as u16) << 4) | n[3] as u16;
    Some(u as i16 as i32)
}

pub fn address_set() -> Vec<u8> {
    vec![0x88, 0x30, 0x01, END]
}
pub fn if_clear() -> Vec<u8> {
    vec![0x88, 0x01, 0x00, 0x01, END]
}
pub fn power(addr: u8, on: bool) -> Vec<u8> {
    vec![
        0x80 | addr,
        0x01,
        0x04,
        0x00,
        if on { 0x02 } else { 0x03 },
        END,
    ]
}
pub fn power_inquiry(addr: u8) -> Vec<u8> {
    vec![0x80 | addr, 0x09, 0x04, 0x00, END]
}
pub fn pantilt_inquiry(addr: u8) -> Vec<u8> {
    vec![0x80 | addr, 0x09, 0x06, 0x12, END]
}
pub fn zoom_inquiry(addr: u8) -> Vec<u8> {
    vec![0x80 | addr, 0x09, 0x04, 0x47, END]
}

/// Pan-tilt absolute position: `8x 01 06 02 VV WW 0Y 0Y 0Y 0Y 0Z 0Z 0Z 0Z FF`.
pub fn pantilt_absolute(addr: u8, pan_speed: u8, tilt_speed: u8, pan: i32, tilt: i32) -> Vec<u8> {
    let mut v = vec![0x80 | addr, 0x01, 0x06, 0x02, pan_speed, tilt_speed];
    v.extend_from_slice(&nibbles(pan));
    v.extend_from_slice(&nibbles(tilt));
    v.push(END);
    v
}

/// Zoom direct: `8x 01 04 47 0p 0q 0r 0s FF`.
pub fn zoom_direct(addr: u8, units: i32) -> Vec<u8> {
    let mut v = vec![0x80 | addr, 0x01, 0x04, 0x47];
    v.extend_from_slice(&nibbles(units));
    v.push(END);
    v
}

/// The speed mode for `speed` deg/s: the slowest mode at least that fast (so an
/// axis never moves slower than asked), at most `modes`; None for 0 (stop).
pub fn speed_mode(speed: f32, modes: u8) -> Option<u8> {
    if speed.is_nan() || speed <= 0.0 {
        return None;
    }
    let n = modes as usize;
    Some(
        SPEEDS[..n]
            .iter()
            .position(|&s| s >= speed)
            .map(|i| i as u8 + 1)
            .unwrap_or(modes),
    )
}

/// Degrees to device units (linear, 4.3's `convert`), clamped to the limits.
pub fn deg_to_units(deg: f32, limit_deg: f32, limit_units: i32) -> i32 {
    let d = crate::interfaces::limit(deg, -limit_deg, limit_deg);
    (d as f64 / limit_deg as f64 * limit_units as f64).round() as i32
}

pub fn units_to_deg(units: i32, limit_deg: f32, limit_units: i32) -> f32 {
    (units as f64 * limit_deg as f64 / limit_units as f64) as f32
}

/// Zoom level 0..40 to units 0..0x7000.
pub fn zoom_to_units(z: f32) -> i32 {
    let z = crate::interfaces::limit(z, 0.0, ZOOM_MAX);
    (z as f64 / ZOOM_MAX as f64 * ZOOM_UNITS as f64).round() as i32
}

pub fn units_to_zoom(u: i32) -> f32 {
    (u as f64 * ZOOM_MAX as f64 / ZOOM_UNITS as f64) as f32
}

/// Hex bytes for messages (`81 01 06 02 ...`).
pub fn hex(p: &[u8]) -> String {
    p.iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speed_tables() {
        assert_eq!(speed_mode(0.0, PAN_MODES), None);
        assert_eq!(speed_mode(2.0, PAN_MODES), Some(1));
        assert_eq!(speed_mode(2.1, PAN_MODES), Some(2));
        assert_eq!(speed_mode(300.0, PAN_MODES), Some(24));
        assert_eq!(speed_mode(1000.0, PAN_MODES), Some(24));
        assert_eq!(speed_mode(300.0, TILT_MODES), Some(20));
        assert_eq!(speed_mode(125.0, TILT_MODES), Some(20));
    }

    #[test]
    fn positions_and_packets() {
        assert_eq!(deg_to_units(100.0, PAN_LIMIT, PAN_UNITS), 0x08DB);
        assert_eq!(deg_to_units(-100.0, PAN_LIMIT, PAN_UNITS) as u16, 0xF725);
        assert_eq!(deg_to_units(-25.0, TILT_LIMIT, TILT_UNITS) as u16, 0xFE70);
        assert_eq!(
            pantilt_absolute(1, 0x18, 0x14, 680, -160),
            [
                0x81, 1, 6, 2, 0x18, 0x14, 0, 2, 0xA, 8, 0xF, 0xF, 6, 0, 0xFF
            ]
        );
        assert_eq!(from_nibbles(&[0xF, 0xF, 6, 0]), Some(-160));
        assert_eq!(from_nibbles(&[0x10, 0, 0, 0]), None);
        assert_eq!(zoom_to_units(20.0), 0x3800);
    }

    #[test]
    fn replies() {
        assert_eq!(classify(1, &[0x90, 0x41, 0xFF]), Some(Reply::Ack(1)));
        assert_eq!(classify(1, &[0x90, 0x52, 0xFF]), Some(Reply::Completion(2)));
        assert_eq!(
            classify(1, &[0x90, 0x60, 0x02, 0xFF]),
            Some(Reply::Error(0, ViscaError::Syntax))
        );
        assert_eq!(
            classify(1, &[0x90, 0x61, 0x41, 0xFF]),
            Some(Reply::Error(1, ViscaError::NotExecutable))
        );
        assert_eq!(
            classify(1, &[0x90, 0x50, 0x02, 0xFF]),
            Some(Reply::Answer(vec![2]))
        );
        for (code, e) in [
            (0x03, ViscaError::BufferFull),
            (0x04, ViscaError::Cancelled),
            (0x05, ViscaError::NoSocket),
        ] {
            assert_eq!(
                classify(1, &[0x90, 0x62, code, 0xFF]),
                Some(Reply::Error(2, e))
            );
        }
        assert_eq!(classify(1, &[0xA0, 0x41, 0xFF]), None);
        assert_eq!(
            Reply::Broadcast(vec![0x88, 0x30, 0x02, 0xFF]).to_string(),
            "a broadcast reply (88 30 02 FF)"
        );
        assert_eq!(classify(1, b"* ok\xFF"), None);
    }
}
