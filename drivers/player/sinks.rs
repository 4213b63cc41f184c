//! Where each Player device's data goes: conversions into the interfaces' units.

use std::sync::Arc;

pub use crate::blobs::{Blob, BlobFrame, LiveBlobs};
pub use crate::interfaces::LaserMap;
use crate::interfaces::{
    Bumpers, COLOR_HEIGHT, COLOR_WIDTH, Encoders, Image, Interface, Laser, PtEncoders, Sonars,
};

use super::conf::Offset;
use super::xdr::{self, RangerConfig, ScanInfo, XdrError, be_f32, be_f64, camera};

/// Fills `out` from a laser scan's big-endian float ranges in metres.
pub fn laser_f32(map: &mut LaserMap, info: &ScanInfo, ranges: &[u8], out: &mut Laser) {
    let (min, step) = (info.min_angle as f64, info.resolution as f64);
    let range = |k| be_f32(ranges, k) as f64;
    map.fill(min, step, info.count, info.max_range as f64, range, out);
}

/// Fills `out` from a ranger's big-endian double ranges in metres.
pub fn laser_f64(
    map: &mut LaserMap,
    cfg: &RangerConfig,
    count: usize,
    ranges: &[u8],
    out: &mut Laser,
) {
    let range = |k| be_f64(ranges, k);
    map.fill(
        cfg.min_angle,
        cfg.angular_res,
        count,
        cfg.max_range,
        range,
        out,
    );
}

/// A ranger's geometry when the server does not say: `count` samples over the
/// front half-plane, 8 m (a Stage laser).
pub fn default_ranger_config(count: usize) -> RangerConfig {
    let n = count.max(1) as f64;
    RangerConfig {
        min_angle: -std::f64::consts::FRAC_PI_2,
        max_angle: std::f64::consts::FRAC_PI_2,
        angular_res: std::f64::consts::PI / n,
        min_range: 0.0,
        max_range: 8.0,
        range_res: 0.0,
        frequency: 10.0,
    }
}

/// Odometry in the seed's frame: 4.3's formula with the `initial_position` offset.
pub fn encoders(p: &xdr::Position2d, o: &Offset) -> Encoders {
    let t0 = o.theta_deg.to_radians();
    let (c, s) = (t0.cos(), t0.sin());
    let (px, py) = (p.px * 1000.0, p.py * 1000.0);
    let x = px * c - py * s + o.x;
    let y = py * c + px * s + o.y;
    Encoders::from_pose(x as f32, y as f32, (p.pa + t0) as f32)
}

pub fn sonars_f32(n: usize, raw: &[u8], out: &mut Sonars) {
    out.us.clear();
    out.us.extend((0..n).map(|i| be_f32(raw, i) * 1000.0));
}

pub fn sonars_f64(n: usize, raw: &[u8], out: &mut Sonars) {
    out.us.clear();
    out.us
        .extend((0..n).map(|i| (be_f64(raw, i) * 1000.0) as f32));
}

pub fn bumpers(raw: &[u8], out: &mut Bumpers) {
    out.bumpers.clear();
    out.bumpers.extend(raw.iter().map(|b| (*b != 0) as u8));
}

pub fn pantilt(p: &xdr::Ptz) -> PtEncoders {
    PtEncoders {
        pan_angle: p.pan.to_degrees(),
        tilt_angle: p.tilt.to_degrees(),
    }
}

/// Largest camera image accepted (pixels per side).
pub const MAX_SIDE: u32 = 8192;

/// Converts a camera frame to BGR at its own size (`out` resized), or at 320x240
/// when `fixed` (nearest neighbour).
pub fn camera_image(
    info: &xdr::CameraInfo,
    data: &[u8],
    fixed: bool,
    scratch: &mut Vec<u8>,
    out: &mut Image,
) -> Result<(), XdrError> {
    let (w, h) = (info.width, info.height);
    if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
        return Err(XdrError::Bad(format!(
            "camera image size {w}x{h} is out of 1..{MAX_SIDE}"
        )));
    }
    let px = w as usize * h as usize;
    // The frame in BGR at its own size, in `scratch`.
    scratch.clear();
    match info.compression {
        camera::RAW => {
            let need = |bytes: usize| -> Result<(), XdrError> {
                if data.len() < px * bytes {
                    Err(XdrError::Bad(format!(
                        "camera image is {} bytes; {w}x{h} format {} needs {}",
                        data.len(),
                        info.format,
                        px * bytes
                    )))
                } else {
                    Ok(())
                }
            };
            match info.format {
                camera::RGB888 => {
                    need(3)?;
                    scratch.reserve(px * 3);
                    for p in data[..px * 3].chunks_exact(3) {
                        scratch.extend_from_slice(&[p[2], p[1], p[0]]);
                    }
                }
                camera::MONO8 => {
                    need(1)?;
                    for &g in &data[..px] {
                        scratch.extend_from_slice(&[g, g, g]);
                    }
                }
                camera::MONO16 => {
                    need(2)?;
                    for p in data[..px * 2].chunks_exact(2) {
                        let g = p[0];
                        scratch.extend_from_slice(&[g, g, g]);
                    }
                }
                camera::RGB565 => {
                    need(2)?;
                    for p in data[..px * 2].chunks_exact(2) {
                        let v = u16::from_le_bytes([p[0], p[1]]);
                        let r = ((v >> 11) & 0x1f) as u8;
                        let g = ((v >> 5) & 0x3f) as u8;
                        let b = (v & 0x1f) as u8;
                        scratch.extend_from_slice(&[
                            b << 3 | b >> 2,
                            g << 2 | g >> 4,
                            r << 3 | r >> 2,
                        ]);
                    }
                }
                f => {
                    return Err(XdrError::Bad(format!(
                        "camera format {f} is not supported (1, 2, 4 or 5)"
                    )));
                }
            }
        }
        camera::JPEG => {
            use zune_jpeg::zune_core::{colorspace::ColorSpace, options::DecoderOptions};
            let opts = DecoderOptions::default()
                .jpeg_set_out_colorspace(ColorSpace::BGR)
                .set_max_width(MAX_SIDE as usize)
                .set_max_height(MAX_SIDE as usize);
            let mut d = zune_jpeg::JpegDecoder::new_with_options(std::io::Cursor::new(data), opts);
            d.decode_headers()
                .map_err(|e| XdrError::Bad(format!("camera JPEG: {e:?}")))?;
            let (jw, jh) = d.dimensions().unwrap_or((0, 0));
            if (jw as u32, jh as u32) != (w, h) {
                return Err(XdrError::Bad(format!(
                    "camera JPEG is {jw}x{jh} but the message says {w}x{h}"
                )));
            }
            scratch.resize(px * 3, 0);
            d.decode_into(scratch)
                .map_err(|e| XdrError::Bad(format!("camera JPEG: {e:?}")))?;
        }
        c => {
            return Err(XdrError::Bad(format!(
                "camera compression {c} is not supported (0 raw, 1 JPEG)"
            )));
        }
    }
    if !fixed {
        out.width = w;
        out.height = h;
        std::mem::swap(&mut out.data, scratch);
        return Ok(());
    }
    out.width = COLOR_WIDTH;
    out.height = COLOR_HEIGHT;
    out.data
        .resize((COLOR_WIDTH * COLOR_HEIGHT * 3) as usize, 0);
    for y in 0..COLOR_HEIGHT as usize {
        let sy = y * h as usize / COLOR_HEIGHT as usize;
        for x in 0..COLOR_WIDTH as usize {
            let sx = x * w as usize / COLOR_WIDTH as usize;
            let s = (sy * w as usize + sx) * 3;
            let d = (y * COLOR_WIDTH as usize + x) * 3;
            out.data[d..d + 3].copy_from_slice(&scratch[s..s + 3]);
        }
    }
    Ok(())
}

/// A blobfinder frame in our units (range mm).
pub fn blob_frame(clock: u64, w: u32, h: u32, blobs: Vec<Blob>) -> BlobFrame {
    BlobFrame {
        clock,
        width: w,
        height: h,
        blobs,
    }
}

/// Where one device's data goes.
pub enum Sink {
    Encoders(Arc<Interface<Encoders>>, Offset),
    Laser(Arc<Interface<Laser>>, LaserMap),
    Sonars(Arc<Interface<Sonars>>),
    Bumpers(Arc<Interface<Bumpers>>),
    PtEncoders(Arc<Interface<PtEncoders>>),
    Camera(Arc<Interface<Image>>, bool),
    Blobs(Arc<LiveBlobs>),
}

impl Sink {
    /// Whether someone uses it.
    pub fn used(&self) -> bool {
        match self {
            Sink::Encoders(i, _) => i.users() > 0,
            Sink::Laser(i, _) => i.users() > 0,
            Sink::Sonars(i) => i.users() > 0,
            Sink::Bumpers(i) => i.users() > 0,
            Sink::PtEncoders(i) => i.users() > 0,
            Sink::Camera(i, _) => i.users() > 0,
            Sink::Blobs(_) => true,
        }
    }

    pub fn set_stale(&self, why: &str) {
        match self {
            Sink::Encoders(i, _) => i.set_stale(why),
            Sink::Laser(i, _) => i.set_stale(why),
            Sink::Sonars(i) => i.set_stale(why),
            Sink::Bumpers(i) => i.set_stale(why),
            Sink::PtEncoders(i) => i.set_stale(why),
            Sink::Camera(i, _) => i.set_stale(why),
            Sink::Blobs(_) => {}
        }
    }
}
