//! colorspaces: JDE 4.3's libcolorspaces — RGB→HSV and RGB→YUV, exact and through a
//! precomputed 64x64x64 table, and the colour filters of hsvtuner and colortuner.
//!
//! Units and conventions (4.3's, reference §6):
//! - **HSV**: H in **degrees** [0, 360), S in [0, 1], V in **0..255** (= max(r,g,b)).
//!   GUIs and conf files of 4.3 give H in radians: use [`HsvRange::from_radians`].
//! - **YUV**: inputs divided by 255; Y in [0, 1], U in ±0.436, V in ±0.615
//!   (Y = 0.299r + 0.587g + 0.114b, U = −0.14713r − 0.289g + 0.436b,
//!   V = 0.615r − 0.515g − 0.100b).
//! - Images ([`Image`]) are **B, G, R** per pixel, rows top to bottom; the scalar
//!   functions take `(r, g, b)`.
//! - The tables ([`hsv_table`], [`yuv_table`]) hold, at `[r>>2][g>>2][b>>2]`, the
//!   exact value of the colour `(4i, 4j, 4k)` (the lower corner of its bin, as 4.3).
//!   They are built once on first use ([`std::sync::OnceLock`]) and shared by every
//!   thread.
//!
//! Example: keep the orange of a ball, grey out the rest (hsvtuner's view):
//! ```
//! use jderobot::colorspaces::{HsvRange, Lookup, Background, hsv_filter};
//! use jderobot::interfaces::Image;
//! let img = Image::new(320, 240);
//! let range = HsvRange::from_radians(0.0, 0.6, 0.4, 1.0, 80.0, 255.0);
//! let out = hsv_filter(&img, &range, Lookup::Exact, Background::Grey);
//! assert_eq!(out.width, 320);
//! ```

use std::sync::OnceLock;

use crate::{interfaces::Image, vision::GrayImage};

/// H degrees [0,360), S 0..1, V 0..255.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Hsv {
    pub h: f32,
    pub s: f32,
    pub v: f32,
}

/// Y 0..1, U ±0.436, V ±0.615.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Yuv {
    pub y: f32,
    pub u: f32,
    pub v: f32,
}

/// The HSV formula on floats (r, g, b in 0..255); branch-free so image loops
/// vectorise.
#[inline(always)]
fn hsv_f32(r: f32, g: f32, b: f32) -> (f32, f32, f32) {
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let d = max - min;
    let (num, off) = if max == r {
        (g - b, if g < b { 360.0 } else { 0.0 })
    } else if max == g {
        (b - r, 120.0)
    } else {
        (r - g, 240.0)
    };
    let h = if d > 0.0 { 60.0 * num / d + off } else { 0.0 };
    let s = if max > 0.0 { 1.0 - min / max } else { 0.0 };
    (h, s, max)
}

/// Exact RGB→HSV (H degrees, S 0..1, V 0..255).
pub fn rgb2hsv(r: u8, g: u8, b: u8) -> Hsv {
    let (h, s, v) = hsv_f32(r as f32, g as f32, b as f32);
    Hsv { h, s, v }
}

/// HSV→RGB (the Wikipedia sector formula of 4.3): returns (r, g, b) in V's scale.
pub fn hsv2rgb(hsv: Hsv) -> (f32, f32, f32) {
    let Hsv { h, s, v } = hsv;
    let h = h.rem_euclid(360.0);
    let sector = (h / 60.0).floor();
    let f = h / 60.0 - sector;
    let p = v * (1.0 - s);
    let q = v * (1.0 - f * s);
    let t = v * (1.0 - (1.0 - f) * s);
    match sector as i32 % 6 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    }
}

/// HSV→RGB rounded to bytes (V in 0..255).
pub fn hsv2rgb_u8(hsv: Hsv) -> (u8, u8, u8) {
    let (r, g, b) = hsv2rgb(hsv);
    let c = |x: f32| x.round().clamp(0.0, 255.0) as u8;
    (c(r), c(g), c(b))
}

#[inline(always)]
fn yuv_f32(r: f32, g: f32, b: f32) -> (f32, f32, f32) {
    let (r, g, b) = (r / 255.0, g / 255.0, b / 255.0);
    (
        0.299 * r + 0.587 * g + 0.114 * b,
        -0.14713 * r - 0.289 * g + 0.436 * b,
        0.615 * r - 0.515 * g - 0.100 * b,
    )
}

/// Exact RGB→YUV (inputs 0..255; Y 0..1).
pub fn rgb2yuv(r: u8, g: u8, b: u8) -> Yuv {
    let (y, u, v) = yuv_f32(r as f32, g as f32, b as f32);
    Yuv { y, u, v }
}

/// YUV→RGB, each channel clamped to [0, 1] (4.3's `yuv2rgb`).
pub fn yuv2rgb(yuv: Yuv) -> (f32, f32, f32) {
    let Yuv { y, u, v } = yuv;
    (
        (y + 1.13983 * v).clamp(0.0, 1.0),
        (y - 0.39465 * u - 0.58060 * v).clamp(0.0, 1.0),
        (y + 2.03211 * u).clamp(0.0, 1.0),
    )
}

/// A 64x64x64 table indexed `[r>>2][g>>2][b>>2]`.
pub struct Table<T> {
    data: Vec<T>,
}

impl<T: Copy> Table<T> {
    fn build(f: impl Fn(u8, u8, u8) -> T) -> Self {
        let mut data = Vec::with_capacity(1 << 18);
        for i in 0..64u8 {
            for j in 0..64u8 {
                for k in 0..64u8 {
                    data.push(f(i * 4, j * 4, k * 4));
                }
            }
        }
        Table { data }
    }

    /// The value of the lower corner of `(r, g, b)`'s bin.
    #[inline]
    pub fn get(&self, r: u8, g: u8, b: u8) -> T {
        self.data[((r as usize >> 2) << 12) | ((g as usize >> 2) << 6) | (b as usize >> 2)]
    }
}

/// The shared RGB→HSV table (built on first call; 262144 entries).
pub fn hsv_table() -> &'static Table<Hsv> {
    static T: OnceLock<Table<Hsv>> = OnceLock::new();
    T.get_or_init(|| {
        tracing::debug!("Table 'LUT_RGB2HSV' create with 6 bits (262144 values)");
        Table::build(rgb2hsv)
    })
}

/// The shared RGB→YUV table (built on first call).
pub fn yuv_table() -> &'static Table<Yuv> {
    static T: OnceLock<Table<Yuv>> = OnceLock::new();
    T.get_or_init(|| Table::build(rgb2yuv))
}

/// Whether filters convert each pixel exactly or through the 4.3 table.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Lookup {
    #[default]
    Exact,
    Table,
}

/// What a filtered image shows where a pixel does not pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Background {
    /// Black (hsvtuner's `toblack`).
    Black,
    /// Grey at V·180/255 (hsvtuner's default), V = max(r, g, b).
    #[default]
    Grey,
}

/// HSV pass ranges: H in degrees (wraps through 0 when `hmin > hmax`, like
/// hsvtuner), S 0..1, V 0..255. Bounds are inclusive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HsvRange {
    pub hmin: f32,
    pub hmax: f32,
    pub smin: f32,
    pub smax: f32,
    pub vmin: f32,
    pub vmax: f32,
}

impl Default for HsvRange {
    /// hsvtuner's defaults: H 0..1 rad, S 0.2..0.4, V 0..255.
    fn default() -> Self {
        HsvRange::from_radians(0.0, 1.0, 0.2, 0.4, 0.0, 255.0)
    }
}

impl HsvRange {
    /// From 4.3's GUI/conf units: H in radians (0..2π), S 0..1, V 0..255.
    pub fn from_radians(hmin: f32, hmax: f32, smin: f32, smax: f32, vmin: f32, vmax: f32) -> Self {
        HsvRange {
            hmin: hmin.to_degrees(),
            hmax: hmax.to_degrees(),
            smin,
            smax,
            vmin,
            vmax,
        }
    }

    #[inline(always)]
    fn pass(&self, h: f32, s: f32, v: f32) -> bool {
        let wrap = self.hmin > self.hmax;
        let lo = h >= self.hmin;
        let hi = h <= self.hmax;
        let hue = (lo & hi) | (wrap & (lo | hi));
        hue & (s >= self.smin) & (s <= self.smax) & (v >= self.vmin) & (v <= self.vmax)
    }

    /// Whether a colour passes.
    pub fn contains(&self, c: Hsv) -> bool {
        self.pass(c.h, c.s, c.v)
    }
}

/// RGB pass ranges, 0..255 inclusive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RgbRange {
    pub rmin: u8,
    pub rmax: u8,
    pub gmin: u8,
    pub gmax: u8,
    pub bmin: u8,
    pub bmax: u8,
}

impl RgbRange {
    pub fn contains(&self, r: u8, g: u8, b: u8) -> bool {
        (self.rmin..=self.rmax).contains(&r)
            && (self.gmin..=self.gmax).contains(&g)
            && (self.bmin..=self.bmax).contains(&b)
    }
}

/// YUV pass ranges (Y 0..1, U ±0.436, V ±0.615), inclusive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YuvRange {
    pub ymin: f32,
    pub ymax: f32,
    pub umin: f32,
    pub umax: f32,
    pub vmin: f32,
    pub vmax: f32,
}

impl YuvRange {
    pub fn contains(&self, c: Yuv) -> bool {
        (c.y >= self.ymin)
            & (c.y <= self.ymax)
            & (c.u >= self.umin)
            & (c.u <= self.umax)
            & (c.v >= self.vmin)
            & (c.v <= self.vmax)
    }
}

/// A colour filter of any of the three spaces (colortuner's choice).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ColourFilter {
    Hsv(HsvRange),
    Rgb(RgbRange),
    Yuv(YuvRange),
}

#[inline(always)]
fn hsv_mask_rows(src: &[u8], dst: &mut [u8], range: &HsvRange) {
    for (p, m) in src.chunks_exact(3).zip(dst.iter_mut()) {
        let (h, s, v) = hsv_f32(p[2] as f32, p[1] as f32, p[0] as f32);
        *m = if range.pass(h, s, v) { 255 } else { 0 };
    }
}

crate::vision::multiversion! {
    fn hsv_mask_exact(src: &[u8], dst: &mut [u8], range: &HsvRange) {
        hsv_mask_rows(src, dst, range)
    }
}

/// The 255/0 mask of the pixels of `img` (BGR) inside `range`.
pub fn hsv_mask(img: &Image, range: &HsvRange, lookup: Lookup) -> GrayImage {
    let mut out = GrayImage::new(img.width, img.height);
    let n = pixel_count(img);
    match lookup {
        Lookup::Exact => hsv_mask_exact(&img.data[..n * 3], &mut out.data, range),
        Lookup::Table => {
            let t = hsv_table();
            for (p, m) in img.data[..n * 3].chunks_exact(3).zip(out.data.iter_mut()) {
                *m = if range.contains(t.get(p[2], p[1], p[0])) {
                    255
                } else {
                    0
                };
            }
        }
    }
    out
}

fn pixel_count(img: &Image) -> usize {
    (img.width as usize * img.height as usize).min(img.data.len() / 3)
}

/// The mask of any [`ColourFilter`].
pub fn mask(img: &Image, filter: &ColourFilter, lookup: Lookup) -> GrayImage {
    match filter {
        ColourFilter::Hsv(r) => hsv_mask(img, r, lookup),
        ColourFilter::Rgb(r) => {
            let mut out = GrayImage::new(img.width, img.height);
            let n = pixel_count(img);
            for (p, m) in img.data[..n * 3].chunks_exact(3).zip(out.data.iter_mut()) {
                *m = if r.contains(p[2], p[1], p[0]) { 255 } else { 0 };
            }
            out
        }
        ColourFilter::Yuv(r) => {
            let mut out = GrayImage::new(img.width, img.height);
            let n = pixel_count(img);
            let t = (lookup == Lookup::Table).then(yuv_table);
            for (p, m) in img.data[..n * 3].chunks_exact(3).zip(out.data.iter_mut()) {
                let c = match t {
                    Some(t) => t.get(p[2], p[1], p[0]),
                    None => rgb2yuv(p[2], p[1], p[0]),
                };
                *m = if r.contains(c) { 255 } else { 0 };
            }
            out
        }
    }
}

/// The filtered view: pixels inside `filter` keep their colour, the others become
/// `background`.
pub fn filter(img: &Image, filter: &ColourFilter, lookup: Lookup, background: Background) -> Image {
    let m = mask(img, filter, lookup);
    let mut out = img.clone();
    let n = pixel_count(img);
    for (p, &k) in out.data[..n * 3].chunks_exact_mut(3).zip(m.data.iter()) {
        if k == 0 {
            let g = match background {
                Background::Black => 0,
                Background::Grey => (p[0].max(p[1]).max(p[2]) as u32 * 180 / 255) as u8,
            };
            p.fill(g);
        }
    }
    out
}

/// hsvtuner's filtered view with an HSV range.
pub fn hsv_filter(img: &Image, range: &HsvRange, lookup: Lookup, background: Background) -> Image {
    filter(img, &ColourFilter::Hsv(*range), lookup, background)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primaries() {
        assert_eq!(
            rgb2hsv(255, 0, 0),
            Hsv {
                h: 0.0,
                s: 1.0,
                v: 255.0
            }
        );
        assert_eq!(
            rgb2hsv(0, 255, 0),
            Hsv {
                h: 120.0,
                s: 1.0,
                v: 255.0
            }
        );
        assert_eq!(
            rgb2hsv(0, 0, 255),
            Hsv {
                h: 240.0,
                s: 1.0,
                v: 255.0
            }
        );
    }
}
