//! Camera pixel formats → BGR (the layout of every jderobot [`Image`]): what the
//! firewire, video4linux2 and gige drivers get from their devices.
//!
//! | source | function | equal to |
//! |---|---|---|
//! | YUYV / UYVY 4:2:2, video range (V4L2, GigE) | [`yuv422_to_bgr`] with [`YuvMatrix::Bt601`] | OpenCV `cvtColor(COLOR_YUV2BGR_YUYV / _UYVY)` (same fixed point) |
//! | YUYV / UYVY 4:2:2, IIDC (FireWire) | [`yuv422_to_bgr`] with [`YuvMatrix::Iidc`] | libdc1394 `dc1394_convert_to_RGB8` (then R↔B) |
//! | YUV 4:1:1 (UYYVYY), 4:4:4 (UYV), IIDC | [`yuv411_to_bgr`], [`yuv444_to_bgr`] | libdc1394 `dc1394_convert_to_RGB8` |
//! | YUV 4:2:0 planar (I420 / YV12) | [`yuv420_to_bgr`] | OpenCV `COLOR_YUV2BGR_I420` (same formula, nearest chroma) |
//! | Bayer RGGB, GBRG, GRBG, BGGR (8 bit) | [`bayer_to_bgr`] | libdc1394 `dc1394_bayer_decoding_8bit(.., DC1394_BAYER_METHOD_BILINEAR)` (borders black) |
//! | RGB24 / BGR24 | [`rgb_to_bgr`], `copy_from_slice` | — |
//! | GREY / MONO8 | [`grey_to_bgr`] | — |
//! | any of those, BGRA32 / RGBA32, with row padding (ROS 2 `sensor_msgs/Image`'s `step`) | [`packed_to_bgr`] | — |
//!
//! Every function takes the source bytes, the size in pixels and the BGR
//! destination (`w*h*3` bytes), and checks the lengths: a short source (a
//! truncated frame) is an error, never a panic or a read past the end. Sizes are
//! in pixels; strides are `w*bytes_per_pixel` (no row padding) unless the function
//! takes a `stride`.
//!
//! The tests in `tests/cameras_dev.rs` check the IIDC and Bayer paths against the
//! system's libdc1394 byte for byte; `scripts/compare_opencv.py` compares the
//! BT.601 path and the Bayer path with OpenCV (time and agreement).
//!
//! [`Image`]: crate::interfaces::Image

use thiserror::Error;

/// A conversion that could not run.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum PixError {
    #[error("{format} frame of {w}x{h} needs {need} bytes, got {got} (truncated frame?)")]
    Short {
        format: &'static str,
        w: u32,
        h: u32,
        need: usize,
        got: usize,
    },
    #[error("{format}: size {w}x{h} is not allowed ({why})")]
    Size {
        format: &'static str,
        w: u32,
        h: u32,
        why: &'static str,
    },
}

/// Which YUV→RGB formula.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum YuvMatrix {
    /// ITU-R BT.601, video range (Y 16..235): V4L2's default for YUYV and what
    /// OpenCV's `COLOR_YUV2BGR_*` computes, bit for bit.
    Bt601,
    /// IIDC (FireWire) full range, as libdc1394 converts: R = Y + 1.402 V,
    /// G = Y − 0.344 U − 0.714 V, B = Y + 1.772 U in 10-bit fixed point.
    Iidc,
}

/// Byte order of packed 4:2:2.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Yuv422Order {
    /// Y0 U Y1 V (V4L2 `YUYV`, GenICam `YUV422_YUYV_Packed`).
    Yuyv,
    /// U Y0 V Y1 (IIDC's order, V4L2 `UYVY`, GenICam `YUV422Packed`).
    Uyvy,
}

/// A Bayer colour filter, named by its top-left 2x2 cell read row by row.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bayer {
    Rggb,
    Gbrg,
    Grbg,
    Bggr,
}

impl Bayer {
    /// From its name (`RGGB`, `rggb`, `BayerRG8`-style names are the gige driver's business).
    pub fn parse(s: &str) -> Option<Bayer> {
        Some(match s.to_ascii_uppercase().as_str() {
            "RGGB" => Bayer::Rggb,
            "GBRG" => Bayer::Gbrg,
            "GRBG" => Bayer::Grbg,
            "BGGR" => Bayer::Bggr,
            _ => return None,
        })
    }
}

fn check(
    format: &'static str,
    src: usize,
    need: usize,
    w: u32,
    h: u32,
    dst: &mut Vec<u8>,
) -> Result<(), PixError> {
    if src < need {
        return Err(PixError::Short {
            format,
            w,
            h,
            need,
            got: src,
        });
    }
    dst.resize(w as usize * h as usize * 3, 0);
    Ok(())
}

// OpenCV's BT.601 fixed point (modules/imgproc/src/color_yuv.simd.hpp).
const CY: i32 = 1_220_542;
const CUB: i32 = 2_116_026;
const CUG: i32 = -409_993;
const CVG: i32 = -852_492;
const CVR: i32 = 1_673_527;
const SHIFT: i32 = 20;
const HALF: i32 = 1 << (SHIFT - 1);

#[inline(always)]
fn sat(v: i32) -> u8 {
    v.clamp(0, 255) as u8
}

#[inline(always)]
fn put_iidc(y: u8, u: i32, v: i32, out: &mut [u8]) {
    let y = y as i32;
    out[2] = sat(y + ((v * 1436) >> 10));
    out[1] = sat(y - ((u * 352 + v * 731) >> 10));
    out[0] = sat(y + ((u * 1814) >> 10));
}

/// Packed 4:2:2 (2 bytes per pixel) → BGR. `w` must be even.
pub fn yuv422_to_bgr(
    src: &[u8],
    w: u32,
    h: u32,
    order: Yuv422Order,
    matrix: YuvMatrix,
    dst: &mut Vec<u8>,
) -> Result<(), PixError> {
    if !w.is_multiple_of(2) {
        return Err(PixError::Size {
            format: "YUV 4:2:2",
            w,
            h,
            why: "the width must be even",
        });
    }
    let n = w as usize * h as usize;
    check("YUV 4:2:2", src.len(), n * 2, w, h, dst)?;
    if n == 0 {
        return Ok(());
    }
    let rows = src[..n * 2]
        .chunks_exact(w as usize * 2)
        .zip(dst.chunks_exact_mut(w as usize * 3));
    let f = match (order, matrix) {
        (Yuv422Order::Yuyv, YuvMatrix::Bt601) => row_422::<true, false>,
        (Yuv422Order::Uyvy, YuvMatrix::Bt601) => row_422::<false, false>,
        (Yuv422Order::Yuyv, YuvMatrix::Iidc) => row_422::<true, true>,
        (Yuv422Order::Uyvy, YuvMatrix::Iidc) => row_422::<false, true>,
    };
    for (s, d) in rows {
        f(s, d);
    }
    Ok(())
}

/// One row of packed 4:2:2: dispatches to the AVX2 build when the CPU has it.
fn row_422<const YUYV: bool, const IIDC: bool>(src: &[u8], dst: &mut [u8]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { row_422_avx2::<YUYV, IIDC>(src, dst) };
    }
    row_422_portable::<YUYV, IIDC>(src, dst)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn row_422_avx2<const YUYV: bool, const IIDC: bool>(src: &[u8], dst: &mut [u8]) {
    row_422_portable::<YUYV, IIDC>(src, dst)
}

/// Pixels per block of the 4:2:2 rows: planar arrays of this length vectorise.
const YUV_BLOCK: usize = 128;

/// One row, in blocks of [`YUV_BLOCK`] pixels: de-interleave Y, U, V into
/// per-pixel arrays (U and V repeated for both pixels of a pair), compute B, G, R
/// planes, interleave them; the tail pair by pair with the same arithmetic.
#[inline(always)]
fn row_422_portable<const YUYV: bool, const IIDC: bool>(src: &[u8], dst: &mut [u8]) {
    const N: usize = YUV_BLOCK;
    let (iy0, iu, iy1, iv) = if YUYV { (0, 1, 2, 3) } else { (1, 0, 3, 2) };
    let mut sc = src.chunks_exact(N * 2);
    let mut dc = dst.chunks_exact_mut(N * 3);
    for (s, d) in (&mut sc).zip(&mut dc) {
        // De-interleave as bytes (cheap shuffles), widen in the arithmetic loop.
        let mut y = [0u8; N];
        let mut u = [0u8; N];
        let mut v = [0u8; N];
        for k in 0..N / 2 {
            y[2 * k] = s[4 * k + iy0];
            y[2 * k + 1] = s[4 * k + iy1];
            u[2 * k] = s[4 * k + iu];
            u[2 * k + 1] = s[4 * k + iu];
            v[2 * k] = s[4 * k + iv];
            v[2 * k + 1] = s[4 * k + iv];
        }
        yuv_block::<IIDC>(&y, &u, &v, d);
    }
    for (s, d) in sc
        .remainder()
        .chunks_exact(4)
        .zip(dc.into_remainder().chunks_exact_mut(6))
    {
        let (u, v) = (s[iu] as i32 - 128, s[iv] as i32 - 128);
        for (j, iy) in [iy0, iy1].into_iter().enumerate() {
            let px = if IIDC {
                iidc(s[iy] as i32, u, v)
            } else {
                bt601(s[iy] as i32, u, v)
            };
            d[3 * j..3 * j + 3].copy_from_slice(&px);
        }
    }
}

/// B, G, R of one block of per-pixel Y, U, V bytes, interleaved into `d`
/// (`3 * YUV_BLOCK` bytes).
#[inline(always)]
fn yuv_block<const IIDC: bool>(
    y: &[u8; YUV_BLOCK],
    u: &[u8; YUV_BLOCK],
    v: &[u8; YUV_BLOCK],
    d: &mut [u8],
) {
    const N: usize = YUV_BLOCK;
    let mut b = [0u8; N];
    let mut g = [0u8; N];
    let mut r = [0u8; N];
    for k in 0..N {
        let (yy, uu, vv) = (y[k] as i32, u[k] as i32 - 128, v[k] as i32 - 128);
        let px = if IIDC {
            iidc(yy, uu, vv)
        } else {
            bt601(yy, uu, vv)
        };
        b[k] = px[0];
        g[k] = px[1];
        r[k] = px[2];
    }
    let d = &mut d[..3 * N];
    for k in 0..N {
        d[3 * k] = b[k];
        d[3 * k + 1] = g[k];
        d[3 * k + 2] = r[k];
    }
}

/// One row of IIDC 4:1:1 (U Y0 Y1 V Y2 Y3), blocks as [`yuv_block`].
fn row_411(src: &[u8], dst: &mut [u8]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { row_411_avx2(src, dst) };
    }
    row_411_portable(src, dst)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn row_411_avx2(src: &[u8], dst: &mut [u8]) {
    row_411_portable(src, dst)
}

#[inline(always)]
fn row_411_portable(src: &[u8], dst: &mut [u8]) {
    const N: usize = YUV_BLOCK;
    let mut sc = src.chunks_exact(N * 3 / 2);
    let mut dc = dst.chunks_exact_mut(N * 3);
    for (s, d) in (&mut sc).zip(&mut dc) {
        let (mut y, mut u, mut v) = ([0u8; N], [0u8; N], [0u8; N]);
        for k in 0..N / 4 {
            let q = &s[6 * k..6 * k + 6];
            y[4 * k..4 * k + 4].copy_from_slice(&[q[1], q[2], q[4], q[5]]);
            u[4 * k..4 * k + 4].fill(q[0]);
            v[4 * k..4 * k + 4].fill(q[3]);
        }
        yuv_block::<true>(&y, &u, &v, d);
    }
    for (s, d) in sc
        .remainder()
        .chunks_exact(6)
        .zip(dc.into_remainder().chunks_exact_mut(12))
    {
        let (u, v) = (s[0] as i32 - 128, s[3] as i32 - 128);
        for (j, iy) in [1, 2, 4, 5].into_iter().enumerate() {
            d[3 * j..3 * j + 3].copy_from_slice(&iidc(s[iy] as i32, u, v));
        }
    }
}

/// One row of planar 4:2:0: the row's Y and its (half-width) U and V rows.
fn row_420(y: &[u8], u: &[u8], v: &[u8], dst: &mut [u8]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { row_420_avx2(y, u, v, dst) };
    }
    row_420_portable(y, u, v, dst)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn row_420_avx2(y: &[u8], u: &[u8], v: &[u8], dst: &mut [u8]) {
    row_420_portable(y, u, v, dst)
}

#[inline(always)]
fn row_420_portable(yr: &[u8], ur: &[u8], vr: &[u8], dst: &mut [u8]) {
    const N: usize = YUV_BLOCK;
    let w = yr.len();
    let mut x = 0;
    while x + N <= w {
        let mut y = [0u8; N];
        y.copy_from_slice(&yr[x..x + N]);
        let (mut u, mut v) = ([0u8; N], [0u8; N]);
        let (uh, vh) = (&ur[x / 2..x / 2 + N / 2], &vr[x / 2..x / 2 + N / 2]);
        for k in 0..N / 2 {
            u[2 * k] = uh[k];
            u[2 * k + 1] = uh[k];
            v[2 * k] = vh[k];
            v[2 * k + 1] = vh[k];
        }
        yuv_block::<false>(&y, &u, &v, &mut dst[3 * x..3 * (x + N)]);
        x += N;
    }
    for x in x..w {
        let px = bt601(yr[x] as i32, ur[x / 2] as i32 - 128, vr[x / 2] as i32 - 128);
        dst[3 * x..3 * x + 3].copy_from_slice(&px);
    }
}

/// BT.601 video range, OpenCV's fixed point: (b, g, r) of Y and centred U, V.
#[inline(always)]
fn bt601(y: i32, u: i32, v: i32) -> [u8; 3] {
    let y = (y - 16).max(0) * CY + HALF;
    [
        sat((y + CUB * u) >> SHIFT),
        sat((y + CVG * v + CUG * u) >> SHIFT),
        sat((y + CVR * v) >> SHIFT),
    ]
}

/// libdc1394's YUV2RGB: (b, g, r) of Y and centred U, V.
#[inline(always)]
fn iidc(y: i32, u: i32, v: i32) -> [u8; 3] {
    [
        sat(y + ((u * 1814) >> 10)),
        sat(y - ((u * 352 + v * 731) >> 10)),
        sat(y + ((v * 1436) >> 10)),
    ]
}

/// IIDC YUV 4:1:1 (U Y0 Y1 V Y2 Y3, 6 bytes per 4 pixels) → BGR, libdc1394's formula.
/// `w` must be a multiple of 4.
pub fn yuv411_to_bgr(src: &[u8], w: u32, h: u32, dst: &mut Vec<u8>) -> Result<(), PixError> {
    if !w.is_multiple_of(4) {
        return Err(PixError::Size {
            format: "YUV 4:1:1",
            w,
            h,
            why: "the width must be a multiple of 4",
        });
    }
    let n = w as usize * h as usize;
    check("YUV 4:1:1", src.len(), n * 3 / 2, w, h, dst)?;
    if n == 0 {
        return Ok(());
    }
    let rows = src[..n * 3 / 2]
        .chunks_exact(w as usize * 3 / 2)
        .zip(dst.chunks_exact_mut(w as usize * 3));
    for (s, d) in rows {
        row_411(s, d);
    }
    Ok(())
}

/// IIDC YUV 4:4:4 (U Y V per pixel) → BGR, libdc1394's formula.
pub fn yuv444_to_bgr(src: &[u8], w: u32, h: u32, dst: &mut Vec<u8>) -> Result<(), PixError> {
    let n = w as usize * h as usize;
    check("YUV 4:4:4", src.len(), n * 3, w, h, dst)?;
    for (s, d) in src[..n * 3].chunks_exact(3).zip(dst.chunks_exact_mut(3)) {
        put_iidc(s[1], s[0] as i32 - 128, s[2] as i32 - 128, d);
    }
    Ok(())
}

/// Planar 4:2:0 (Y plane, then U and V planes at half size: I420; `swap_uv` for
/// YV12) → BGR with BT.601 video range. `w` and `h` must be even.
pub fn yuv420_to_bgr(
    src: &[u8],
    w: u32,
    h: u32,
    swap_uv: bool,
    dst: &mut Vec<u8>,
) -> Result<(), PixError> {
    if !w.is_multiple_of(2) || !h.is_multiple_of(2) {
        return Err(PixError::Size {
            format: "YUV 4:2:0",
            w,
            h,
            why: "the width and height must be even",
        });
    }
    let (wu, hu) = (w as usize, h as usize);
    let n = wu * hu;
    let q = n / 4;
    check("YUV 4:2:0", src.len(), n + 2 * q, w, h, dst)?;
    let (yp, rest) = src.split_at(n);
    let (mut up, mut vp) = (&rest[..q], &rest[q..2 * q]);
    if swap_uv {
        std::mem::swap(&mut up, &mut vp);
    }
    for row in 0..hu {
        let yr = &yp[row * wu..(row + 1) * wu];
        let ur = &up[(row / 2) * (wu / 2)..(row / 2 + 1) * (wu / 2)];
        let vr = &vp[(row / 2) * (wu / 2)..(row / 2 + 1) * (wu / 2)];
        row_420(yr, ur, vr, &mut dst[row * wu * 3..(row + 1) * wu * 3]);
    }
    Ok(())
}

/// RGB24 → BGR (swaps the outer channels).
pub fn rgb_to_bgr(src: &[u8], w: u32, h: u32, dst: &mut Vec<u8>) -> Result<(), PixError> {
    let n = w as usize * h as usize;
    check("RGB24", src.len(), n * 3, w, h, dst)?;
    Packed8::Rgb.row(&src[..n * 3], dst);
    Ok(())
}

/// BGR24 → BGR (a copy, with the length check).
pub fn bgr_to_bgr(src: &[u8], w: u32, h: u32, dst: &mut Vec<u8>) -> Result<(), PixError> {
    let n = w as usize * h as usize * 3;
    check("BGR24", src.len(), n, w, h, dst)?;
    dst.copy_from_slice(&src[..n]);
    Ok(())
}

/// 8-bit grey → BGR (the same value in the three channels).
pub fn grey_to_bgr(src: &[u8], w: u32, h: u32, dst: &mut Vec<u8>) -> Result<(), PixError> {
    let n = w as usize * h as usize;
    check("GREY", src.len(), n, w, h, dst)?;
    Packed8::Grey.row(&src[..n], dst);
    Ok(())
}

/// A packed layout of 8-bit channels, one pixel after another (ROS's `bgr8`,
/// `rgb8`, `mono8`, `bgra8`, `rgba8`; gz-msgs' `*_INT8`; V4L2's RGB24, BGR24,
/// GREY, ...).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Packed8 {
    Bgr,
    Rgb,
    Grey,
    Bgra,
    Rgba,
}

impl Packed8 {
    /// Bytes per pixel.
    pub fn bytes(self) -> usize {
        match self {
            Packed8::Grey => 1,
            Packed8::Bgr | Packed8::Rgb => 3,
            Packed8::Bgra | Packed8::Rgba => 4,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Packed8::Bgr => "BGR24",
            Packed8::Rgb => "RGB24",
            Packed8::Grey => "GREY",
            Packed8::Bgra => "BGRA32",
            Packed8::Rgba => "RGBA32",
        }
    }

    /// One row (or a whole unpadded image): `src` pixels into `dst` BGR pixels,
    /// as many as both hold; alpha is dropped.
    fn row(self, src: &[u8], dst: &mut [u8]) {
        let d = dst.chunks_exact_mut(3);
        match self {
            Packed8::Bgr => {
                let n = dst.len().min(src.len()) / 3 * 3;
                dst[..n].copy_from_slice(&src[..n]);
            }
            Packed8::Grey => src.iter().zip(d).for_each(|(s, d)| d.fill(*s)),
            Packed8::Rgb => (src.chunks_exact(3).zip(d)).for_each(|(s, d)| {
                d.copy_from_slice(&[s[2], s[1], s[0]]);
            }),
            Packed8::Bgra => (src.chunks_exact(4).zip(d)).for_each(|(s, d)| {
                d.copy_from_slice(&s[..3]);
            }),
            Packed8::Rgba => (src.chunks_exact(4).zip(d)).for_each(|(s, d)| {
                d.copy_from_slice(&[s[2], s[1], s[0]]);
            }),
        }
    }
}

/// Packed 8-bit pixels with rows `stride` bytes apart (row padding, as ROS's
/// `step` and gz-msgs' `step` allow) → BGR, in one pass. The last row need not
/// carry its padding. A `stride` shorter than a row is an error, and so is a
/// source that ends before the last row does.
pub fn packed_to_bgr(
    src: &[u8],
    w: u32,
    h: u32,
    stride: usize,
    format: Packed8,
    dst: &mut Vec<u8>,
) -> Result<(), PixError> {
    let row = w as usize * format.bytes();
    if stride < row {
        return Err(PixError::Size {
            format: format.name(),
            w,
            h,
            why: "the row stride is shorter than a row",
        });
    }
    let need = match h {
        0 => 0,
        h => stride.saturating_mul(h as usize - 1).saturating_add(row),
    };
    check(format.name(), src.len(), need, w, h, dst)?;
    if stride == row {
        format.row(&src[..need], dst);
        return Ok(());
    }
    let out = w as usize * 3;
    if out == 0 {
        return Ok(());
    }
    for (y, d) in dst.chunks_exact_mut(out).enumerate() {
        format.row(&src[y * stride..y * stride + row], d);
    }
    Ok(())
}

/// 8-bit Bayer mosaic → BGR by bilinear interpolation, libdc1394's
/// `DC1394_BAYER_METHOD_BILINEAR` to the byte: at a red or blue site the other
/// of the two is the rounded mean of the 4 diagonal neighbours and green the
/// rounded mean of the 4 direct ones; at a green site red and blue are the rounded
/// means of the 2 horizontal or 2 vertical neighbours. The 1-pixel border is black
/// (libdc1394 clears it). `w` and `h` must be at least 3.
///
/// On x86-64 CPUs with AVX2, rows of at least 36 pixels go through a kernel in
/// AVX2 intrinsics (32 pixels per step, see `bayer_avx2`); elsewhere through
/// `bayer_row_portable`, which the compiler vectorises. Both give the same bytes.
pub fn bayer_to_bgr(
    src: &[u8],
    w: u32,
    h: u32,
    pattern: Bayer,
    dst: &mut Vec<u8>,
) -> Result<(), PixError> {
    if w < 3 || h < 3 {
        return Err(PixError::Size {
            format: "Bayer",
            w,
            h,
            why: "it must be at least 3x3",
        });
    }
    let (wu, hu) = (w as usize, h as usize);
    check("Bayer", src.len(), wu * hu, w, h, dst)?;
    // Top and bottom rows black.
    dst[..wu * 3].fill(0);
    dst[(hu - 1) * wu * 3..].fill(0);
    // The colour of the top-left site and its right neighbour (B 0, G 1, R 2).
    let cell = match pattern {
        Bayer::Rggb => [[2, 1], [1, 0]],
        Bayer::Gbrg => [[1, 0], [2, 1]],
        Bayer::Grbg => [[1, 2], [0, 1]],
        Bayer::Bggr => [[0, 1], [1, 2]],
    };
    #[cfg(target_arch = "x86_64")]
    if wu >= bayer_avx2::MIN_W && std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        unsafe { bayer_rows_avx2(src, wu, hu, cell, dst) };
        return Ok(());
    }
    bayer_rows(src, wu, hu, cell, dst, |gf, red, up, mid, dn, out| {
        let f = match (gf, red) {
            (false, false) => bayer_row_portable::<false, false>,
            (false, true) => bayer_row_portable::<false, true>,
            (true, false) => bayer_row_portable::<true, false>,
            (true, true) => bayer_row_portable::<true, true>,
        };
        f(up, mid, dn, out)
    });
    Ok(())
}

/// Rows 1..h-1 of a `w`-wide mosaic (`cell`: the colours of its top-left 2x2
/// cell, B 0, G 1, R 2): clears the row's first and last pixel and gives `row`
/// whether its even columns are green, whether its other colour is red, the rows
/// above, at and below, and the row's output.
#[inline(always)]
fn bayer_rows(
    src: &[u8],
    wu: usize,
    hu: usize,
    cell: [[u8; 2]; 2],
    dst: &mut [u8],
    mut row: impl FnMut(bool, bool, &[u8], &[u8], &[u8], &mut [u8]),
) {
    for y in 1..hu - 1 {
        let c = cell[y & 1];
        let green_first = c[0] == 1;
        let red = c[0] == 2 || c[1] == 2;
        let up = &src[(y - 1) * wu..y * wu];
        let mid = &src[y * wu..(y + 1) * wu];
        let dn = &src[(y + 1) * wu..(y + 2) * wu];
        let out = &mut dst[y * wu * 3..(y + 1) * wu * 3];
        out[..3].fill(0);
        out[(wu - 1) * 3..].fill(0);
        row(green_first, red, up, mid, dn, out);
    }
}

/// [`bayer_rows`] with the AVX2 row kernel ([`bayer_avx2::row`]); `wu` at least
/// [`bayer_avx2::MIN_W`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn bayer_rows_avx2(src: &[u8], wu: usize, hu: usize, cell: [[u8; 2]; 2], dst: &mut [u8]) {
    bayer_rows(src, wu, hu, cell, dst, |gf, red, up, mid, dn, out| {
        match (gf, red) {
            (false, false) => bayer_avx2::row::<false, false>(up, mid, dn, out),
            (false, true) => bayer_avx2::row::<false, true>(up, mid, dn, out),
            (true, false) => bayer_avx2::row::<true, false>(up, mid, dn, out),
            (true, true) => bayer_avx2::row::<true, true>(up, mid, dn, out),
        }
    })
}

/// One Bayer row: dispatches to the AVX2 kernel when the CPU has it and the row
/// is wide enough. `GF`: the row's even columns are green; `RED`: its other
/// colour is red.
#[cfg(test)]
fn bayer_row<const GF: bool, const RED: bool>(up: &[u8], mid: &[u8], dn: &[u8], out: &mut [u8]) {
    #[cfg(target_arch = "x86_64")]
    if mid.len() >= bayer_avx2::MIN_W && std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { bayer_avx2::row::<GF, RED>(up, mid, dn, out) };
    }
    bayer_row_portable::<GF, RED>(up, mid, dn, out)
}

/// One interior pixel `x` (1..w-1) of a Bayer row, as libdc1394 computes it.
#[inline(always)]
fn bayer_px<const GF: bool, const RED: bool>(
    up: &[u8],
    mid: &[u8],
    dn: &[u8],
    x: usize,
    out: &mut [u8],
) {
    let (nc, oc) = if RED { (2, 0) } else { (0, 2) };
    let (ul, uc, ur) = (up[x - 1] as u16, up[x] as u16, up[x + 1] as u16);
    let (ml, mc, mr) = (mid[x - 1] as u16, mid[x] as u16, mid[x + 1] as u16);
    let (dl, dc, dr) = (dn[x - 1] as u16, dn[x] as u16, dn[x + 1] as u16);
    let o = &mut out[x * 3..x * 3 + 3];
    if ((x & 1) == 0) == GF {
        o[1] = mc as u8;
        o[nc] = ((ml + mr + 1) >> 1) as u8;
        o[oc] = ((uc + dc + 1) >> 1) as u8;
    } else {
        o[nc] = mc as u8;
        o[1] = ((uc + dc + ml + mr + 2) >> 2) as u8;
        o[oc] = ((ul + ur + dl + dr + 2) >> 2) as u8;
    }
}

/// The Bayer row kernel in AVX2 intrinsics, 32 pixels per step.
///
/// A step starts at an even column `x0` and loads 32 bytes of each of the three
/// rows at `x0 - 2`, `x0` and `x0 + 2`. Seen as 16-bit lanes, lane `j` of the load
/// at `x0` holds columns `x0 + 2j` (low byte) and `x0 + 2j + 1` (high byte), and
/// the loads at ∓2 hold their left and right neighbours in the same lane: the
/// even and odd columns are computed apart, each with only its own site's
/// formulas (exact integer means: `avg_epu16` is `(a + b + 1) >> 1`), packed back
/// into 32 bytes per channel, and interleaved into 96 bytes of BGR by byte
/// shuffles within 128-bit lanes, blends and lane permutes.
#[cfg(target_arch = "x86_64")]
mod bayer_avx2 {
    use std::arch::x86_64::*;

    /// Narrowest row the kernel takes. A row is pixel 1 alone, then steps at
    /// x0 = 2, 34, 66, … up to the last even `x0 <= w - 34` (the last step may
    /// overlap the one before: it recomputes the same bytes), then the one or two
    /// pixels left before the border alone.
    pub(super) const MIN_W: usize = 36;

    /// `pshufb` table that puts byte `i` of a 16-byte lane of channel `c` where
    /// one of the three 16-byte thirds of the lane's 48 interleaved bytes wants it.
    const fn spread(c: usize) -> [u8; 32] {
        let mut t = [0u8; 32];
        let mut q = 0;
        while q < 16 {
            // Byte q of third k is channel (k + q) % 3 of pixel (16k + q) / 3.
            let k = (c + 3 - q % 3) % 3;
            let v = ((16 * k + q) / 3) as u8;
            t[q] = v;
            t[q + 16] = v;
            q += 1;
        }
        t
    }

    /// 0xFF where `q % 3 == r` in each 16-byte lane.
    const fn third(r: usize) -> [u8; 32] {
        let mut t = [0u8; 32];
        let mut q = 0;
        while q < 32 {
            if (q % 16) % 3 == r {
                t[q] = 0xFF;
            }
            q += 1;
        }
        t
    }

    const SPREAD: [[u8; 32]; 3] = [spread(0), spread(1), spread(2)];
    const THIRDS: [[u8; 32]; 2] = [third(1), third(2)];

    #[inline]
    #[target_feature(enable = "avx2")]
    fn table(t: &[u8; 32]) -> __m256i {
        // SAFETY: t has 32 bytes.
        unsafe { _mm256_loadu_si256(t.as_ptr() as *const __m256i) }
    }

    /// Interleaves 32 bytes each of B, G and R into 96 bytes of BGR.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn store_bgr(o: &mut [u8; 96], b: __m256i, g: __m256i, r: __m256i) {
        let b = _mm256_shuffle_epi8(b, table(&SPREAD[0]));
        let g = _mm256_shuffle_epi8(g, table(&SPREAD[1]));
        let r = _mm256_shuffle_epi8(r, table(&SPREAD[2]));
        let (m1, m2) = (table(&THIRDS[0]), table(&THIRDS[1]));
        // Third k of each lane: channel (k + q) % 3 at byte q.
        let t0 = _mm256_blendv_epi8(_mm256_blendv_epi8(b, g, m1), r, m2);
        let t1 = _mm256_blendv_epi8(_mm256_blendv_epi8(g, r, m1), b, m2);
        let t2 = _mm256_blendv_epi8(_mm256_blendv_epi8(r, b, m1), g, m2);
        let p = o.as_mut_ptr() as *mut __m256i;
        // SAFETY: o has 96 bytes: three 32-byte stores.
        unsafe {
            _mm256_storeu_si256(p, _mm256_permute2x128_si256::<0x20>(t0, t1));
            _mm256_storeu_si256(p.add(1), _mm256_permute2x128_si256::<0x30>(t2, t0));
            _mm256_storeu_si256(p.add(2), _mm256_permute2x128_si256::<0x31>(t1, t2));
        }
    }

    /// 32 pixels from column `x0` (even): `u`, `m`, `d` are the rows above, at and
    /// below from column `x0 - 2` (36 bytes), `o` the 96 output bytes.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn step<const GF: bool, const RED: bool>(
        u: &[u8; 36],
        m: &[u8; 36],
        d: &[u8; 36],
        o: &mut [u8; 96],
    ) {
        // SAFETY: offsets 0, 2 and 4 plus 32 bytes stay within the 36.
        let ld = |s: &[u8; 36], at: usize| unsafe {
            _mm256_loadu_si256(s.as_ptr().add(at) as *const __m256i)
        };
        let low = _mm256_set1_epi16(0x00FF);
        let two = _mm256_set1_epi16(2);
        let lo = |v| _mm256_and_si256(v, low);
        let hi = |v| _mm256_srli_epi16::<8>(v);
        let even_odd = |e, o| _mm256_or_si256(e, _mm256_slli_epi16::<8>(o));
        // (a + b + c + d + 2) >> 2 in 16-bit lanes.
        let mean4 = |a, b, c, e| {
            let s = _mm256_add_epi16(_mm256_add_epi16(a, b), _mm256_add_epi16(c, e));
            _mm256_srli_epi16::<2>(_mm256_add_epi16(s, two))
        };
        let (m0, mm) = (ld(m, 2), ld(m, 0));
        let (u0, d0) = (ld(u, 2), ld(d, 2));
        // The plane of each channel: green, the row's own colour, the other one.
        let (g, own, other) = if GF {
            // Even columns green: own = mean left/right, other = mean up/down.
            // Odd columns own: green = mean of the cross, other = of the diagonals.
            let (m1, u1, d1) = (ld(m, 4), ld(u, 4), ld(d, 4));
            let g_odd = mean4(hi(u0), hi(d0), lo(m0), lo(m1));
            let own_even = _mm256_avg_epu16(hi(mm), hi(m0));
            let other_even = _mm256_avg_epu16(lo(u0), lo(d0));
            let other_odd = mean4(lo(u0), lo(u1), lo(d0), lo(d1));
            (
                even_odd(lo(m0), g_odd),
                _mm256_or_si256(own_even, _mm256_andnot_si256(low, m0)),
                even_odd(other_even, other_odd),
            )
        } else {
            // Even columns own: green = mean of the cross, other = of the diagonals.
            // Odd columns green: own = mean left/right, other = mean up/down.
            let (m1, um, dm) = (ld(m, 4), ld(u, 0), ld(d, 0));
            let g_even = mean4(lo(u0), lo(d0), hi(mm), hi(m0));
            let own_odd = _mm256_avg_epu16(lo(m0), lo(m1));
            let other_even = mean4(hi(um), hi(u0), hi(dm), hi(d0));
            let other_odd = _mm256_avg_epu16(hi(u0), hi(d0));
            (
                _mm256_or_si256(g_even, _mm256_andnot_si256(low, m0)),
                even_odd(lo(m0), own_odd),
                even_odd(other_even, other_odd),
            )
        };
        if RED {
            store_bgr(o, other, g, own)
        } else {
            store_bgr(o, own, g, other)
        }
    }

    /// Interior pixels 1..w-1 of one row (`w = mid.len()`, at least [`MIN_W`]);
    /// the same bytes as [`super::bayer_row_portable`].
    #[target_feature(enable = "avx2")]
    pub(super) fn row<const GF: bool, const RED: bool>(
        up: &[u8],
        mid: &[u8],
        dn: &[u8],
        out: &mut [u8],
    ) {
        let w = mid.len();
        assert!(w >= MIN_W && up.len() == w && dn.len() == w && out.len() == 3 * w);
        super::bayer_px::<GF, RED>(up, mid, dn, 1, out);
        let last = (w - 34) & !1;
        let mut x0 = 2;
        loop {
            let x = x0.min(last);
            let at = x - 2..x + 34;
            step::<GF, RED>(
                up[at.clone()].try_into().unwrap(),
                mid[at.clone()].try_into().unwrap(),
                dn[at].try_into().unwrap(),
                (&mut out[3 * x..3 * x + 96]).try_into().unwrap(),
            );
            if x == last {
                break;
            }
            x0 += 32;
        }
        for x in last + 32..w - 1 {
            super::bayer_px::<GF, RED>(up, mid, dn, x, out);
        }
    }
}

/// Pixels per block of a Bayer row.
const BAYER_BLOCK: usize = 64;

/// Interior pixels 1..w-1 of one row, in blocks: every pixel computes the five
/// candidates (centre, 4-cross mean, 4-diagonal mean, 2-horizontal mean,
/// 2-vertical mean) and a mask picks per site (green or not), so the block
/// vectorises; then B, G, R are interleaved. The tail pixel by pixel. (The
/// path of CPUs without AVX2; the compiler's vectorisation of this loop ran at
/// 1.1x OpenCV's `cvtColor`; docs/benchmarks.md has the AVX2 kernel's figures.)
#[inline(always)]
fn bayer_row_portable<const GF: bool, const RED: bool>(
    up: &[u8],
    mid: &[u8],
    dn: &[u8],
    out: &mut [u8],
) {
    const N: usize = BAYER_BLOCK;
    let w = mid.len();
    // nc: channel of the row's non-green colour; oc: the colour of the rows above/below.
    let (nc, oc) = if RED { (2, 0) } else { (0, 2) };
    let mut x0 = 1;
    while x0 + N < w {
        let u = &up[x0 - 1..x0 + N + 1];
        let m = &mid[x0 - 1..x0 + N + 1];
        let d = &dn[x0 - 1..x0 + N + 1];
        let par0 = x0 & 1;
        let mut ch = [[0u8; N]; 3];
        for k in 0..N {
            let (ul, uc, ur) = (u[k] as u16, u[k + 1] as u16, u[k + 2] as u16);
            let (ml, mc, mr) = (m[k] as u16, m[k + 1] as u16, m[k + 2] as u16);
            let (dl, dc, dr) = (d[k] as u16, d[k + 1] as u16, d[k + 2] as u16);
            let center = mc as u8;
            let cross = ((uc + dc + ml + mr + 2) >> 2) as u8;
            let diag = ((ul + ur + dl + dr + 2) >> 2) as u8;
            let hor = ((ml + mr + 1) >> 1) as u8;
            let ver = ((uc + dc + 1) >> 1) as u8;
            // 0xFF at green sites.
            let gm = 0u8.wrapping_sub((((k + par0) & 1 == 0) == GF) as u8);
            let pick = |at_green: u8, other: u8| (at_green & gm) | (other & !gm);
            ch[1][k] = pick(center, cross);
            ch[nc][k] = pick(hor, center);
            ch[oc][k] = pick(ver, diag);
        }
        let o = &mut out[x0 * 3..(x0 + N) * 3];
        for k in 0..N {
            o[3 * k] = ch[0][k];
            o[3 * k + 1] = ch[1][k];
            o[3 * k + 2] = ch[2][k];
        }
        x0 += N;
    }
    for x in x0..w - 1 {
        bayer_px::<GF, RED>(up, mid, dn, x, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(n: usize) -> Vec<u8> {
        let mut rng = fastrand::Rng::with_seed(0x9e37_79b9);
        std::iter::repeat_with(|| rng.u8(..)).take(n).collect()
    }

    /// Every packed layout, with and without row padding, gives the same BGR
    /// pixels; a short source or a stride shorter than a row is an error.
    #[test]
    fn packed_layouts_with_row_padding_give_the_same_bgr() {
        let (w, h) = (3u32, 2u32);
        let bgr: Vec<[u8; 3]> = (0..6).map(|i| [10 * i, 10 * i + 1, 10 * i + 2]).collect();
        let want: Vec<u8> = bgr.iter().flatten().copied().collect();
        for f in [
            Packed8::Bgr,
            Packed8::Rgb,
            Packed8::Bgra,
            Packed8::Rgba,
            Packed8::Grey,
        ] {
            let px = |p: &[u8; 3]| -> Vec<u8> {
                match f {
                    Packed8::Bgr => p.to_vec(),
                    Packed8::Rgb => vec![p[2], p[1], p[0]],
                    Packed8::Bgra => vec![p[0], p[1], p[2], 255],
                    Packed8::Rgba => vec![p[2], p[1], p[0], 255],
                    Packed8::Grey => vec![p[0]],
                }
            };
            let want: Vec<u8> = match f {
                Packed8::Grey => bgr.iter().flat_map(|p| [p[0]; 3]).collect(),
                _ => want.clone(),
            };
            for pad in [0, 1, 5] {
                let stride = w as usize * f.bytes() + pad;
                let mut src = vec![];
                for y in 0..h as usize {
                    for x in 0..w as usize {
                        src.extend(px(&bgr[y * w as usize + x]));
                    }
                    if y + 1 < h as usize {
                        src.extend(vec![0xEE; pad]);
                    }
                }
                let mut out = vec![];
                packed_to_bgr(&src, w, h, stride, f, &mut out).unwrap();
                assert_eq!(out, want, "{f:?} padded {pad}");
                assert!(packed_to_bgr(&src[..src.len() - 1], w, h, stride, f, &mut out).is_err());
            }
            let short = w as usize * f.bytes() - 1;
            assert!(packed_to_bgr(&[0; 64], w, h, short, f, &mut vec![]).is_err());
        }
        let mut none = vec![1];
        assert!(packed_to_bgr(&[0; 28], 0, 5, 7, Packed8::Rgb, &mut none).is_ok());
        assert!(none.is_empty());
    }

    /// The portable build and the dispatched (AVX2 where the CPU has it) agree.
    #[test]
    fn portable_and_dispatched_rows_agree() {
        let w = 3 * YUV_BLOCK + 10;
        let src = noise(w * 2);
        let (mut a, mut b) = (vec![0; w * 3], vec![0; w * 3]);
        row_422::<true, false>(&src, &mut a);
        row_422_portable::<true, false>(&src, &mut b);
        assert_eq!(a, b);
        row_422::<false, true>(&src, &mut a);
        row_422_portable::<false, true>(&src, &mut b);
        assert_eq!(a, b);
        for w in [3 * BAYER_BLOCK + 7, 36, 37, 38, 66, 67, 640] {
            let src = noise(w * 3);
            let (up, mid, dn) = (&src[..w], &src[w..2 * w], &src[2 * w..]);
            let (mut a, mut b) = (vec![0; w * 3], vec![0; w * 3]);
            bayer_row::<true, false>(up, mid, dn, &mut a);
            bayer_row_portable::<true, false>(up, mid, dn, &mut b);
            assert_eq!(a[3..], b[3..], "{w}");
            bayer_row::<false, true>(up, mid, dn, &mut a);
            bayer_row_portable::<false, true>(up, mid, dn, &mut b);
            assert_eq!(a[3..], b[3..], "{w}");
            bayer_row::<true, true>(up, mid, dn, &mut a);
            bayer_row_portable::<true, true>(up, mid, dn, &mut b);
            assert_eq!(a[3..], b[3..], "{w}");
            bayer_row::<false, false>(up, mid, dn, &mut a);
            bayer_row_portable::<false, false>(up, mid, dn, &mut b);
            assert_eq!(a[3..], b[3..], "{w}");
        }
    }

    /// Every pattern at every width from 3 to 100 (and 640), odd and even
    /// heights: each pixel as libdc1394's bilinear method states it, computed
    /// here one pixel at a time; the 1-pixel border black.
    #[test]
    fn bayer_equals_per_pixel_bilinear_at_every_width() {
        let cells = [
            (Bayer::Rggb, [[2, 1], [1, 0]]),
            (Bayer::Gbrg, [[1, 0], [2, 1]]),
            (Bayer::Grbg, [[1, 2], [0, 1]]),
            (Bayer::Bggr, [[0, 1], [1, 2]]),
        ];
        let mut got = Vec::new();
        for w in (3..=100).chain([640]) {
            for h in [3, 4, 7] {
                let src = noise(w * h + w);
                let src = &src[w..];
                let at = |x: usize, y: usize| src[y * w + x] as u16;
                for (pat, cell) in cells {
                    bayer_to_bgr(src, w as u32, h as u32, pat, &mut got).unwrap();
                    assert_eq!(got.len(), w * h * 3);
                    for y in 0..h {
                        for x in 0..w {
                            let mut want = [0u8; 3];
                            if x > 0 && y > 0 && x < w - 1 && y < h - 1 {
                                let c = cell[y & 1][x & 1] as usize;
                                let cross =
                                    (at(x, y - 1) + at(x, y + 1) + at(x - 1, y) + at(x + 1, y) + 2)
                                        >> 2;
                                let diag = (at(x - 1, y - 1)
                                    + at(x + 1, y - 1)
                                    + at(x - 1, y + 1)
                                    + at(x + 1, y + 1)
                                    + 2)
                                    >> 2;
                                let hor = (at(x - 1, y) + at(x + 1, y) + 1) >> 1;
                                let ver = (at(x, y - 1) + at(x, y + 1) + 1) >> 1;
                                want[c] = at(x, y) as u8;
                                if c == 1 {
                                    // The row's other colour left/right, the column's up/down.
                                    want[cell[y & 1][(x + 1) & 1] as usize] = hor as u8;
                                    want[cell[(y + 1) & 1][x & 1] as usize] = ver as u8;
                                } else {
                                    want[1] = cross as u8;
                                    want[2 - c] = diag as u8;
                                }
                            }
                            let i = (y * w + x) * 3;
                            assert_eq!(got[i..i + 3], want, "{pat:?} {w}x{h} at {x},{y}");
                        }
                    }
                }
            }
        }
    }

    /// Planar 4:2:0 in blocks equals the per-pixel formula with nearest chroma.
    #[test]
    fn yuv420_blocks_equal_per_pixel() {
        let (w, h) = (2 * YUV_BLOCK + 6, 4);
        let src = noise(w * h * 3 / 2);
        let mut got = Vec::new();
        yuv420_to_bgr(&src, w as u32, h as u32, true, &mut got).unwrap();
        let (yp, up, vp) = (
            &src[..w * h],
            &src[w * h + w * h / 4..w * h + w * h / 2],
            &src[w * h..w * h + w * h / 4],
        );
        for y in 0..h {
            for x in 0..w {
                let c = (y / 2) * (w / 2) + x / 2;
                let want = bt601(yp[y * w + x] as i32, up[c] as i32 - 128, vp[c] as i32 - 128);
                assert_eq!(got[(y * w + x) * 3..(y * w + x) * 3 + 3], want, "{x},{y}");
            }
        }
    }

    #[test]
    fn short_frames_are_errors() {
        let mut d = Vec::new();
        let e = yuv422_to_bgr(&[0; 10], 4, 2, Yuv422Order::Yuyv, YuvMatrix::Bt601, &mut d);
        assert!(matches!(
            e,
            Err(PixError::Short {
                need: 16,
                got: 10,
                ..
            })
        ));
        assert!(bayer_to_bgr(&[0; 8], 3, 3, Bayer::Rggb, &mut d).is_err());
        assert!(grey_to_bgr(&[0; 3], 2, 2, &mut d).is_err());
        assert!(yuv420_to_bgr(&[0; 5], 2, 2, false, &mut d).is_err());
    }

    #[test]
    fn grey_and_rgb() {
        let mut d = Vec::new();
        grey_to_bgr(&[7, 9], 2, 1, &mut d).unwrap();
        assert_eq!(d, [7, 7, 7, 9, 9, 9]);
        rgb_to_bgr(&[1, 2, 3], 1, 1, &mut d).unwrap();
        assert_eq!(d, [3, 2, 1]);
    }

    #[test]
    fn bt601_black_white_and_red() {
        let mut d = Vec::new();
        // Y=16 black, Y=235 white, neutral chroma.
        yuv422_to_bgr(
            &[16, 128, 235, 128],
            2,
            1,
            Yuv422Order::Yuyv,
            YuvMatrix::Bt601,
            &mut d,
        )
        .unwrap();
        assert_eq!(d, [0, 0, 0, 255, 255, 255]);
        // BT.601 red (Y 81, U 90, V 240) → close to (0, 0, 255).
        yuv422_to_bgr(
            &[90, 81, 240, 81],
            2,
            1,
            Yuv422Order::Uyvy,
            YuvMatrix::Bt601,
            &mut d,
        )
        .unwrap();
        assert!(d[2] >= 250 && d[1] <= 3 && d[0] <= 3, "{d:?}");
    }

    #[test]
    fn bayer_flat_field_is_flat_inside() {
        // A mosaic of a uniform colour (R 200, G 100, B 50) in each pattern.
        for pat in [Bayer::Rggb, Bayer::Gbrg, Bayer::Grbg, Bayer::Bggr] {
            let (w, h) = (8usize, 6usize);
            let names = match pat {
                Bayer::Rggb => [[2, 1], [1, 0]],
                Bayer::Gbrg => [[1, 0], [2, 1]],
                Bayer::Grbg => [[1, 2], [0, 1]],
                Bayer::Bggr => [[0, 1], [1, 2]],
            };
            let val = [50u8, 100, 200];
            let src: Vec<u8> = (0..w * h)
                .map(|i| val[names[(i / w) % 2][(i % w) % 2]])
                .collect();
            let mut d = Vec::new();
            bayer_to_bgr(&src, w as u32, h as u32, pat, &mut d).unwrap();
            for y in 1..h - 1 {
                for x in 1..w - 1 {
                    assert_eq!(
                        &d[(y * w + x) * 3..(y * w + x) * 3 + 3],
                        &val,
                        "{pat:?} {x},{y}"
                    );
                }
            }
            assert_eq!(&d[..3], &[0, 0, 0]);
        }
    }
}
