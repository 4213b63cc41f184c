//! The Player 3 wire format: XDR (RFC 4506, big-endian) message headers and the
//! payloads this driver uses, as `docs/player.md` and Player's generated
//! `playerxdr.c` define them.
//!
//! Decoding never panics and never allocates more than the bytes that are really
//! there: every read is bounds-checked, every count is checked against the bytes
//! left before anything is sized by it, and a message larger than
//! [`MAX_MESSAGE_SIZE`] is refused from its header.

use std::fmt;

use crate::blobs::Blob;

/// `PLAYER_IDENT_STRLEN`: the banner the server sends first.
pub const BANNER_LEN: usize = 32;
/// `PLAYERXDR_MSGHDR_SIZE`.
pub const HEADER_LEN: usize = 40;
/// `PLAYERXDR_MAX_MESSAGE_SIZE` (4 × 8 MiB): the largest payload a server accepts.
pub const MAX_MESSAGE_SIZE: u32 = 4 * 8 * 1024 * 1024;

/// Message types.
pub mod msg {
    pub const DATA: u32 = 1;
    pub const CMD: u32 = 2;
    pub const REQ: u32 = 3;
    pub const RESP_ACK: u32 = 4;
    pub const SYNCH: u32 = 5;
    pub const RESP_NACK: u32 = 6;
}

/// Interface codes.
pub mod interf {
    pub const PLAYER: u32 = 1;
    pub const POSITION2D: u32 = 4;
    pub const SONAR: u32 = 5;
    pub const LASER: u32 = 6;
    pub const BLOBFINDER: u32 = 7;
    pub const PTZ: u32 = 8;
    pub const BUMPER: u32 = 14;
    pub const SIMULATION: u32 = 31;
    pub const CAMERA: u32 = 40;
    pub const RANGER: u32 = 62;
}

/// Subtypes of the `player` device (interf 1).
pub mod player {
    pub const REQ_DEVLIST: u32 = 1;
    pub const REQ_DEV: u32 = 3;
    pub const REQ_DATA: u32 = 4;
    pub const REQ_DATAMODE: u32 = 5;
    pub const SYNCH_OK: u32 = 1;
    pub const OPEN_MODE: u32 = 1;
    pub const CLOSE_MODE: u32 = 2;
    pub const ERROR_MODE: u32 = 3;
    pub const DATAMODE_PUSH: u32 = 1;
    pub const DATAMODE_PULL: u32 = 2;
}

/// Other subtypes used here.
pub mod sub {
    pub const POSITION2D_DATA_STATE: u32 = 1;
    pub const POSITION2D_CMD_VEL: u32 = 1;
    pub const POSITION2D_REQ_MOTOR_POWER: u32 = 2;
    pub const LASER_DATA_SCAN: u32 = 1;
    pub const LASER_DATA_SCANPOSE: u32 = 2;
    pub const RANGER_DATA_RANGE: u32 = 1;
    pub const RANGER_REQ_GET_CONFIG: u32 = 5;
    pub const SONAR_DATA_RANGES: u32 = 1;
    pub const BUMPER_DATA_STATE: u32 = 1;
    pub const PTZ_DATA_STATE: u32 = 1;
    pub const PTZ_CMD_STATE: u32 = 1;
    pub const CAMERA_DATA_STATE: u32 = 1;
    pub const BLOBFINDER_DATA_BLOBS: u32 = 1;
}

/// Camera image formats and compression.
pub mod camera {
    pub const MONO8: u32 = 1;
    pub const MONO16: u32 = 2;
    pub const RGB565: u32 = 4;
    pub const RGB888: u32 = 5;
    pub const RAW: u32 = 0;
    pub const JPEG: u32 = 1;
}

/// The name of an interface code, for messages (`position2d`, `ranger`...).
pub fn interf_name(code: u32) -> &'static str {
    match code {
        1 => "player",
        2 => "power",
        3 => "gripper",
        4 => "position2d",
        5 => "sonar",
        6 => "laser",
        7 => "blobfinder",
        8 => "ptz",
        9 => "audio",
        10 => "fiducial",
        12 => "speech",
        13 => "gps",
        14 => "bumper",
        20 => "dio",
        21 => "aio",
        22 => "ir",
        23 => "wifi",
        25 => "localize",
        30 => "position3d",
        31 => "simulation",
        33 => "blinkenlight",
        40 => "camera",
        42 => "map",
        44 => "planner",
        45 => "log",
        49 => "joystick",
        51 => "opaque",
        52 => "position1d",
        53 => "actarray",
        54 => "limb",
        55 => "graphics2d",
        56 => "rfid",
        57 => "wsn",
        58 => "graphics3d",
        59 => "health",
        60 => "imu",
        61 => "pointcloud3d",
        62 => "ranger",
        63 => "vectormap",
        64 => "blackboard",
        65 => "stereo",
        66 => "coopobject",
        _ => "unknown",
    }
}

/// What went wrong decoding bytes from the server.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum XdrError {
    #[error("message ends early: needed {needed} more bytes at offset {at}")]
    Short { at: usize, needed: usize },
    #[error("{what}: count {count} needs {needs} bytes but only {left} are left")]
    Count {
        what: &'static str,
        count: u32,
        needs: u64,
        left: usize,
    },
    #[error("{what}: the two copies of the count differ ({a} and {b})")]
    CountMismatch { what: &'static str, a: u32, b: u32 },
    #[error("message size {0} is above the protocol maximum of {MAX_MESSAGE_SIZE} bytes")]
    TooBig(u32),
    #[error("{0}")]
    Bad(String),
}

/// A checked reader over an XDR payload.
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    pub fn new(buf: &'a [u8]) -> Self {
        Reader { buf, pos: 0 }
    }
    /// Bytes not read yet.
    pub fn left(&self) -> usize {
        self.buf.len() - self.pos
    }
    pub fn pos(&self) -> usize {
        self.pos
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], XdrError> {
        if self.left() < n {
            return Err(XdrError::Short {
                at: self.pos,
                needed: n - self.left(),
            });
        }
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    #[inline]
    pub fn u32(&mut self) -> Result<u32, XdrError> {
        let b = self.take(4)?;
        Ok(u32::from_be_bytes([b[0], b[1], b[2], b[3]]))
    }
    #[inline]
    pub fn i32(&mut self) -> Result<i32, XdrError> {
        Ok(self.u32()? as i32)
    }
    #[inline]
    pub fn f32(&mut self) -> Result<f32, XdrError> {
        Ok(f32::from_bits(self.u32()?))
    }
    #[inline]
    pub fn f64(&mut self) -> Result<f64, XdrError> {
        let b = self.take(8)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(f64::from_bits(u64::from_be_bytes(a)))
    }
    /// A variable array's count as the generated code writes it (the struct's own
    /// count, then the `xdr_array`/`xdr_bytes` length), checked: both equal and
    /// `count × elem` bytes (padded to 4) still in the message.
    pub fn count(&mut self, what: &'static str, elem: usize) -> Result<usize, XdrError> {
        let a = self.u32()?;
        let b = self.u32()?;
        if a != b {
            return Err(XdrError::CountMismatch { what, a, b });
        }
        let needs = pad4(a as u64 * elem as u64);
        if needs > self.left() as u64 {
            return Err(XdrError::Count {
                what,
                count: a,
                needs,
                left: self.left(),
            });
        }
        Ok(a as usize)
    }
    /// `n` opaque bytes and their padding.
    pub fn bytes(&mut self, n: usize) -> Result<&'a [u8], XdrError> {
        let s = self.take(n)?;
        let pad = (4 - n % 4) % 4;
        self.take(pad.min(self.left()))?;
        Ok(s)
    }
    /// The raw remaining slice of `n` bytes (no padding).
    pub fn raw(&mut self, n: usize) -> Result<&'a [u8], XdrError> {
        self.take(n)
    }
}

fn pad4(n: u64) -> u64 {
    n.div_ceil(4) * 4
}

/// An XDR writer appending to a buffer.
#[derive(Default)]
pub struct Writer {
    pub buf: Vec<u8>,
}

impl Writer {
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.buf.extend_from_slice(&v.to_be_bytes());
        self
    }
    pub fn f32(&mut self, v: f32) -> &mut Self {
        self.u32(v.to_bits())
    }
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.buf.extend_from_slice(&v.to_bits().to_be_bytes());
        self
    }
    /// `count, count, bytes padded to 4`.
    pub fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.u32(b.len() as u32).u32(b.len() as u32);
        self.buf.extend_from_slice(b);
        let pad = (4 - b.len() % 4) % 4;
        self.buf.extend(std::iter::repeat_n(0, pad));
        self
    }
}

/// A device address as the header carries it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Addr {
    pub interf: u32,
    pub index: u32,
}

impl Addr {
    pub const PLAYER: Addr = Addr {
        interf: interf::PLAYER,
        index: 0,
    };
    pub fn new(interf: u32, index: u32) -> Self {
        Addr { interf, index }
    }
}

impl fmt::Display for Addr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", interf_name(self.interf), self.index)
    }
}

/// `player_msghdr_t`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Header {
    pub host: u32,
    pub robot: u32,
    pub addr: Addr,
    pub mtype: u32,
    pub subtype: u32,
    pub timestamp: f64,
    pub seq: u32,
    pub size: u32,
}

impl Header {
    /// A client header: host, robot and timestamp 0.
    pub fn new(addr: Addr, mtype: u32, subtype: u32, seq: u32, size: usize) -> Self {
        Header {
            host: 0,
            robot: 0,
            addr,
            mtype,
            subtype,
            timestamp: 0.0,
            seq,
            size: size as u32,
        }
    }
    pub fn encode(&self, out: &mut Vec<u8>) {
        let mut w = Writer {
            buf: std::mem::take(out),
        };
        w.u32(self.host)
            .u32(self.robot)
            .u32(self.addr.interf)
            .u32(self.addr.index)
            .u32(self.mtype)
            .u32(self.subtype)
            .f64(self.timestamp)
            .u32(self.seq)
            .u32(self.size);
        *out = w.buf;
    }
    /// Decodes a header; refuses a size above [`MAX_MESSAGE_SIZE`].
    pub fn decode(b: &[u8]) -> Result<Header, XdrError> {
        let mut r = Reader::new(b);
        let h = Header {
            host: r.u32()?,
            robot: r.u32()?,
            addr: Addr {
                interf: r.u32()?,
                index: r.u32()?,
            },
            mtype: r.u32()?,
            subtype: r.u32()?,
            timestamp: r.f64()?,
            seq: r.u32()?,
            size: r.u32()?,
        };
        if h.size > MAX_MESSAGE_SIZE {
            return Err(XdrError::TooBig(h.size));
        }
        Ok(h)
    }
}

/// A whole message: header then payload.
pub fn message(h: &Header, payload: &[u8]) -> Vec<u8> {
    let mut h = *h;
    h.size = payload.len() as u32;
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len());
    h.encode(&mut out);
    out.extend_from_slice(payload);
    out
}

/// The banner's version text (`Player v.3.1.1-dev` → `3.1.1-dev`), if it is a
/// Player banner.
pub fn banner_version(b: &[u8]) -> Option<String> {
    let text: Vec<u8> = b.iter().copied().take_while(|c| *c != 0).collect();
    let text = String::from_utf8_lossy(&text);
    text.strip_prefix("Player v.").map(str::to_string)
}

// ---- payloads ----------------------------------------------------------------

/// `player_device_req_t` (subscribe / unsubscribe).
pub fn device_req(addr: Addr, access: u32) -> Vec<u8> {
    let mut w = Writer::default();
    w.u32(0)
        .u32(0)
        .u32(addr.interf)
        .u32(addr.index)
        .u32(access)
        .bytes(&[]);
    w.buf
}

/// The reply to a device request: (granted access, driver name).
pub fn decode_device_req(p: &[u8]) -> Result<(Addr, u32, String), XdrError> {
    let mut r = Reader::new(p);
    let _host = r.u32()?;
    let _robot = r.u32()?;
    let addr = Addr {
        interf: r.u32()?,
        index: r.u32()?,
    };
    let access = r.u32()?;
    let n = r.count("driver_name", 1)?;
    let name = r.bytes(n)?;
    let name: Vec<u8> = name.iter().copied().take_while(|c| *c != 0).collect();
    Ok((addr, access, String::from_utf8_lossy(&name).into_owned()))
}

/// A REQ_DEVLIST request (an empty list).
pub fn devlist_req() -> Vec<u8> {
    let mut w = Writer::default();
    w.u32(0).u32(0);
    w.buf
}

/// `player_device_devlist_t`: the devices a server has.
pub fn decode_devlist(p: &[u8]) -> Result<Vec<Addr>, XdrError> {
    let mut r = Reader::new(p);
    let n = r.count("devices", 16)?;
    let mut v = Vec::with_capacity(n);
    for _ in 0..n {
        let _host = r.u32()?;
        let _robot = r.u32()?;
        v.push(Addr {
            interf: r.u32()?,
            index: r.u32()?,
        });
    }
    Ok(v)
}

/// `player_device_datamode_req_t`.
pub fn datamode_req(mode: u32) -> Vec<u8> {
    mode.to_be_bytes().to_vec()
}

/// `player_position2d_cmd_vel_t`: forward m/s, lateral m/s, yaw rad/s, state.
pub fn cmd_vel(vx: f64, vy: f64, va: f64, state: bool) -> [u8; 28] {
    let mut out = [0u8; 28];
    out[0..8].copy_from_slice(&vx.to_bits().to_be_bytes());
    out[8..16].copy_from_slice(&vy.to_bits().to_be_bytes());
    out[16..24].copy_from_slice(&va.to_bits().to_be_bytes());
    out[24..28].copy_from_slice(&(state as u32).to_be_bytes());
    out
}

/// `player_position2d_data_t`: pose (m, m, rad), velocity, stall.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Position2d {
    pub px: f64,
    pub py: f64,
    pub pa: f64,
    pub vx: f64,
    pub vy: f64,
    pub va: f64,
    pub stall: bool,
}

pub fn decode_position2d(p: &[u8]) -> Result<Position2d, XdrError> {
    let mut r = Reader::new(p);
    Ok(Position2d {
        px: r.f64()?,
        py: r.f64()?,
        pa: r.f64()?,
        vx: r.f64()?,
        vy: r.f64()?,
        va: r.f64()?,
        stall: r.u32()? != 0,
    })
}

/// The header fields of `player_laser_data_t` and where its ranges are.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScanInfo {
    pub min_angle: f32,
    pub max_angle: f32,
    pub resolution: f32,
    pub max_range: f32,
    pub count: usize,
}

/// Decodes a laser scan's header and returns it with the raw big-endian ranges
/// (`count` × 4 bytes), so the caller converts them straight into its buffer.
/// The intensities and id that follow are checked for size too.
pub fn decode_scan(p: &[u8]) -> Result<(ScanInfo, &[u8]), XdrError> {
    let mut r = Reader::new(p);
    let min_angle = r.f32()?;
    let max_angle = r.f32()?;
    let resolution = r.f32()?;
    let max_range = r.f32()?;
    let count = r.count("ranges", 4)?;
    let ranges = r.raw(count * 4)?;
    let ni = r.count("intensity", 1)?;
    r.bytes(ni)?;
    let _id = r.u32()?;
    Ok((
        ScanInfo {
            min_angle,
            max_angle,
            resolution,
            max_range,
            count,
        },
        ranges,
    ))
}

/// A big-endian f32 array element.
#[inline]
pub fn be_f32(b: &[u8], i: usize) -> f32 {
    let j = i * 4;
    f32::from_bits(u32::from_be_bytes([b[j], b[j + 1], b[j + 2], b[j + 3]]))
}

/// A big-endian f64 array element.
#[inline]
pub fn be_f64(b: &[u8], i: usize) -> f64 {
    let j = i * 8;
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[j..j + 8]);
    f64::from_bits(u64::from_be_bytes(a))
}

/// `player_ranger_data_range_t`: the raw ranges (count × 8 bytes, doubles, m).
pub fn decode_ranger(p: &[u8]) -> Result<(usize, &[u8]), XdrError> {
    let mut r = Reader::new(p);
    let n = r.count("ranges", 8)?;
    Ok((n, r.raw(n * 8)?))
}

/// `player_sonar_data_t`: the raw ranges (count × 4 bytes, floats, m).
pub fn decode_sonar(p: &[u8]) -> Result<(usize, &[u8]), XdrError> {
    let mut r = Reader::new(p);
    let n = r.count("ranges", 4)?;
    Ok((n, r.raw(n * 4)?))
}

/// `player_bumper_data_t`: one byte per bumper.
pub fn decode_bumpers(p: &[u8]) -> Result<&[u8], XdrError> {
    let mut r = Reader::new(p);
    let n = r.count("bumpers", 1)?;
    r.bytes(n)
}

/// `player_ranger_config_t` (7 doubles): min_angle, max_angle, angular_res (rad),
/// min_range, max_range, range_res (m), frequency (Hz).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RangerConfig {
    pub min_angle: f64,
    pub max_angle: f64,
    pub angular_res: f64,
    pub min_range: f64,
    pub max_range: f64,
    pub range_res: f64,
    pub frequency: f64,
}

pub fn decode_ranger_config(p: &[u8]) -> Result<RangerConfig, XdrError> {
    let mut r = Reader::new(p);
    Ok(RangerConfig {
        min_angle: r.f64()?,
        max_angle: r.f64()?,
        angular_res: r.f64()?,
        min_range: r.f64()?,
        max_range: r.f64()?,
        range_res: r.f64()?,
        frequency: r.f64()?,
    })
}

/// `player_ptz_data_t`: pan, tilt, zoom (rad), panspeed, tiltspeed (rad/s), status.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Ptz {
    pub pan: f32,
    pub tilt: f32,
    pub zoom: f32,
    pub panspeed: f32,
    pub tiltspeed: f32,
}

pub fn decode_ptz(p: &[u8]) -> Result<Ptz, XdrError> {
    let mut r = Reader::new(p);
    Ok(Ptz {
        pan: r.f32()?,
        tilt: r.f32()?,
        zoom: r.f32()?,
        panspeed: r.f32()?,
        tiltspeed: r.f32()?,
    })
}

/// `player_ptz_cmd_t`.
pub fn ptz_cmd(c: &Ptz) -> Vec<u8> {
    let mut w = Writer::default();
    w.f32(c.pan)
        .f32(c.tilt)
        .f32(c.zoom)
        .f32(c.panspeed)
        .f32(c.tiltspeed);
    w.buf
}

/// `player_camera_data_t`'s fields and its image bytes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraInfo {
    pub width: u32,
    pub height: u32,
    pub bpp: u32,
    pub format: u32,
    pub fdiv: u32,
    pub compression: u32,
}

pub fn decode_camera(p: &[u8]) -> Result<(CameraInfo, &[u8]), XdrError> {
    let mut r = Reader::new(p);
    let info = CameraInfo {
        width: r.u32()?,
        height: r.u32()?,
        bpp: r.u32()?,
        format: r.u32()?,
        fdiv: r.u32()?,
        compression: r.u32()?,
    };
    let n = r.count("image", 1)?;
    Ok((info, r.bytes(n)?))
}

/// `player_blobfinder_data_t`: image width, height and the blobs (the range,
/// sent in m, in mm; the colour 0xRRGGBB).
pub fn decode_blobs(p: &[u8]) -> Result<(u32, u32, Vec<Blob>), XdrError> {
    let mut r = Reader::new(p);
    let w = r.u32()?;
    let h = r.u32()?;
    let n = r.count("blobs", 40)?;
    let mut v = Vec::with_capacity(n);
    for _ in 0..n {
        v.push(Blob {
            id: r.u32()?,
            color: r.u32()? & 0xff_ffff,
            area: r.u32()?,
            x: r.u32()?,
            y: r.u32()?,
            left: r.u32()?,
            right: r.u32()?,
            top: r.u32()?,
            bottom: r.u32()?,
            range: r.f32()? * 1000.0,
        });
    }
    Ok((w, h, v))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_are_checked_against_the_bytes() {
        // 1 000 000 ranges claimed, 8 bytes present: an error, no allocation.
        let mut w = Writer::default();
        w.u32(1_000_000).u32(1_000_000).f64(1.0);
        assert!(matches!(decode_ranger(&w.buf), Err(XdrError::Count { .. })));
        let mut w = Writer::default();
        w.u32(2).u32(3).f64(1.0).f64(2.0);
        assert!(matches!(
            decode_ranger(&w.buf),
            Err(XdrError::CountMismatch { .. })
        ));
        let mut w = Writer::default();
        w.u32(0).u32(0).u32(u32::MAX).u32(u32::MAX);
        assert!(decode_blobs(&w.buf).is_err());
    }

    #[test]
    fn oversized_header_is_refused() {
        let mut h = Vec::new();
        Header::new(Addr::PLAYER, 1, 1, 0, 0).encode(&mut h);
        h[36..40].copy_from_slice(&(MAX_MESSAGE_SIZE + 1).to_be_bytes());
        assert!(matches!(Header::decode(&h), Err(XdrError::TooBig(_))));
    }

    #[test]
    fn every_prefix_of_garbage_decodes_without_panic() {
        let mut x: u32 = 12345;
        let mut bytes = Vec::new();
        for _ in 0..512 {
            x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
            bytes.push((x >> 16) as u8);
        }
        for n in 0..bytes.len() {
            let b = &bytes[..n];
            let _ = Header::decode(b);
            let _ = decode_scan(b);
            let _ = decode_ranger(b);
            let _ = decode_sonar(b);
            let _ = decode_bumpers(b);
            let _ = decode_camera(b);
            let _ = decode_blobs(b);
            let _ = decode_devlist(b);
            let _ = decode_device_req(b);
            let _ = decode_position2d(b);
            let _ = decode_ptz(b);
            let _ = decode_ranger_config(b);
        }
    }
}
