//! vision: the image operations of 4.3's opencvdemo and imgrectifier, on BGR
//! [`Image`]s, with OpenCV's definitions so results can be compared with it
//! (`scripts/compare_opencv.py`, table in `docs/libraries.md`).
//!
//! | op | function | OpenCV equivalent |
//! |---|---|---|
//! | grayscale | [`grayscale`] | `cvtColor(BGR2GRAY)` (bit-exact: 15-bit fixed point) |
//! | colour filter | [`crate::colorspaces::hsv_mask`] | `cvtColor(BGR2HSV)` on floats + `inRange` |
//! | Sobel 3x3 | [`sobel`] | `Sobel(CV_16S, 1,0 / 0,1, 3)`, `BORDER_REFLECT_101` |
//! | Canny | [`canny`] | `Canny(img, low, high, 3, L2gradient)` |
//! | pyramid | [`pyr_down`], [`pyramid`] | `pyrDown`, `buildPyramid` |
//! | convolution | [`convolve`] with a [`Kernel`] | `filter2D(.., delta = offset)` |
//! | optical flow | [`optical_flow_pyr_lk`] | `calcOpticalFlowPyrLK` |
//! | homography | [`find_homography`], [`warp_perspective`] | `findHomography(.., 0)`, `warpPerspective` |
//! | Hough lines | [`hough_lines`], [`hough_lines_p`] | `HoughLines`, `HoughLinesP` (same RNG visiting order) |
//! | camera pixel formats | [`pixfmt`] (YUYV, UYVY, YUV 4:2:0/4:1:1, Bayer, RGB, GREY → BGR) | `cvtColor(YUV2BGR_YUYV, BayerBG2BGR, ...)`, libdc1394's conversions |
//!
//! Units: pixels; graphic coordinates (x = column to the right, y = row down) in
//! this module. Images are BGR bytes, rows top to bottom, no padding; single-channel
//! results are [`GrayImage`] (u8) or [`Gray16`] (i16). Borders are
//! `BORDER_REFLECT_101` (…cb|abcd|cb…) unless said otherwise.
//!
//! # Kernel files (opencvdemo's conf lines)
//! ```text
//! #Sharpening
//! size 3            # 3 or 5 in 4.3; any odd size 1..15 here
//! modulo 1          # the rows are divided by modulo when it is > 1
//! offset 0          # added to every result before saturation (OpenCV's delta)
//! row 1 0 -1 0      # row N (1-based) then `size` numbers
//! row 2 -1 5 -1
//! row 3 0 -1 0
//! ```
//! Other lines (opencvdemo's `hmax`, `hmin`, ...) are ignored, so an opencvdemo
//! conf is a kernel file. Samples: `assets/kernels/*.kernel`. 4.3 added the offset
//! after a first saturation (`cvFilter2D` then `cvAddS`), which made offsets useless
//! for kernels with negative responses (edge, emboss); we add it before.
//!
//! Hot loops are written over slices so they auto-vectorise, and compiled twice
//! (AVX2+FMA and baseline) with a runtime switch. Hand-written AVX2 loops, each
//! checked against its portable twin by a unit test, are `warp_perspective`'s
//! (gathers, same f32 arithmetic), LK's window rows and `grayscale` (16-bit
//! multiply-adds, exact integers); their `unsafe` is the loads and stores.

mod convolve;
mod draw;
mod flow;
mod homography;
mod hough;
pub mod pixfmt;
mod sobel;

pub use convolve::{Kernel, KernelError, convolve};
pub use draw::draw_line;
pub use flow::{LkParams, TrackedPoint, optical_flow_pyr_lk};
pub use homography::{find_homography, warp_perspective};
pub use hough::{PolarLine, Segment, hough_lines, hough_lines_p};
pub use sobel::{canny, sobel, sobel_with_border};

use crate::interfaces::Image;

/// Compiles a function twice, for AVX2+FMA and for the baseline, and picks one at
/// run time. FMA is allowed but Rust never contracts `a * b + c`, so results are
/// identical on both paths.
macro_rules! multiversion {
    ($(#[$m:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? $body:block) => {
        $(#[$m])* $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[inline(always)]
            fn inner($($arg: $ty),*) $(-> $ret)? $body
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2,fma")]
                fn avx2($($arg: $ty),*) $(-> $ret)? { inner($($arg),*) }
                if std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                {
                    // SAFETY: the CPU has AVX2 and FMA (checked just above).
                    return unsafe { avx2($($arg),*) };
                }
            }
            inner($($arg),*)
        }
    };
}
pub(crate) use multiversion;

/// A single-channel 8-bit image (masks, grey levels, edges), rows top to bottom.
#[derive(Clone, Default, PartialEq, Eq)]
pub struct GrayImage {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

impl std::fmt::Debug for GrayImage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "GrayImage({}x{})", self.width, self.height)
    }
}

impl GrayImage {
    pub fn new(width: u32, height: u32) -> Self {
        GrayImage {
            width,
            height,
            data: vec![0; width as usize * height as usize],
        }
    }
    /// The value at column `x`, row `y`.
    pub fn get(&self, x: u32, y: u32) -> u8 {
        self.data[y as usize * self.width as usize + x as usize]
    }
    /// A BGR image with the grey level in all three channels (for display).
    pub fn to_bgr(&self) -> Image {
        let mut out = Image::new(self.width, self.height);
        for (p, &g) in out.data.chunks_exact_mut(3).zip(&self.data) {
            p.fill(g);
        }
        out
    }
}

/// A single-channel signed 16-bit image (derivatives).
#[derive(Clone, Default, PartialEq, Eq, Debug)]
pub struct Gray16 {
    pub width: u32,
    pub height: u32,
    pub data: Vec<i16>,
}

impl Gray16 {
    pub fn new(width: u32, height: u32) -> Self {
        Gray16 {
            width,
            height,
            data: vec![0; width as usize * height as usize],
        }
    }
    /// `saturate(|v|)` as 8 bits, OpenCV's `convertScaleAbs` (for display).
    pub fn to_abs_u8(&self) -> GrayImage {
        GrayImage {
            width: self.width,
            height: self.height,
            data: self
                .data
                .iter()
                .map(|v| v.unsigned_abs().min(255) as u8)
                .collect(),
        }
    }
}

/// Index `i` reflected into `0..n` with OpenCV's `BORDER_REFLECT_101` (gfedcb|abcdefgh|gfedcba).
#[inline]
pub(crate) fn reflect101(mut i: isize, n: usize) -> usize {
    let n = n as isize;
    if n == 1 {
        return 0;
    }
    loop {
        if i < 0 {
            i = -i;
        } else if i >= n {
            i = 2 * n - 2 - i;
        } else {
            return i as usize;
        }
    }
}

/// Index `i` clamped into `0..n` (`BORDER_REPLICATE`).
#[inline]
pub(crate) fn replicate(i: isize, n: usize) -> usize {
    i.clamp(0, n as isize - 1) as usize
}

/// The border rule of an operation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Border {
    /// OpenCV's default `BORDER_REFLECT_101`.
    #[default]
    Reflect101,
    /// `BORDER_REPLICATE` (what OpenCV's Canny uses for its Sobel).
    Replicate,
}

impl Border {
    #[inline]
    pub(crate) fn index(self, i: isize, n: usize) -> usize {
        match self {
            Border::Reflect101 => reflect101(i, n),
            Border::Replicate => replicate(i, n),
        }
    }
}

fn valid_len(w: u32, h: u32, cn: usize, len: usize) -> bool {
    (w as usize)
        .checked_mul(h as usize)
        .and_then(|n| n.checked_mul(cn))
        .is_some_and(|n| n == len)
}

/// Whether `img.data` has exactly width·height·3 bytes.
pub fn is_valid(img: &Image) -> bool {
    valid_len(img.width, img.height, 3, img.data.len())
}

multiversion! {
    fn gray_row(src: &[u8], dst: &mut [std::mem::MaybeUninit<u8>]) {
        // OpenCV's BGR2GRAY for 8 bits: 0.114, 0.587, 0.299 in 15-bit fixed point.
        for (p, d) in src.chunks_exact(3).zip(dst.iter_mut()) {
            let v = p[0] as u32 * 3735 + p[1] as u32 * 19235 + p[2] as u32 * 9798 + (1 << 14);
            d.write((v >> 15) as u8);
        }
    }
}

/// [`gray_row`] 32 pixels at a time, as OpenCV: 16-bit multiply-adds of (B, G)
/// pairs by (3735, 19235) and (R, 0) by (9798, 0), then `+ 2¹⁴ >> 15` (exact
/// integers, the same bytes). Returns how many pixels it wrote (the rest are the
/// caller's).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn gray_avx2(src: &[u8], dst: &mut [std::mem::MaybeUninit<u8>]) -> usize {
    use std::arch::x86_64::*;
    let n = dst.len().min(src.len() / 3);
    // Each 16-byte load starts on a pixel and uses 4 pixels (12 bytes) of it.
    let bg = _mm256_setr_epi8(
        0, -1, 1, -1, 3, -1, 4, -1, 6, -1, 7, -1, 9, -1, 10, -1, //
        0, -1, 1, -1, 3, -1, 4, -1, 6, -1, 7, -1, 9, -1, 10, -1,
    );
    let r = _mm256_setr_epi8(
        2, -1, -1, -1, 5, -1, -1, -1, 8, -1, -1, -1, 11, -1, -1, -1, //
        2, -1, -1, -1, 5, -1, -1, -1, 8, -1, -1, -1, 11, -1, -1, -1,
    );
    let wbg = _mm256_set1_epi32(3735 | (19235 << 16));
    let (wr, half) = (_mm256_set1_epi32(9798), _mm256_set1_epi32(1 << 14));
    let order = _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7);
    let mut i = 0;
    // The last load of a block reads 4 bytes past its 32 pixels.
    while i + 32 <= n && 3 * i + 100 <= src.len() {
        let p = src[3 * i..3 * i + 100].as_ptr();
        // SAFETY: loads at p + 12k, k < 8, end at p + 100 (in the slice above).
        let eight = |k: usize| unsafe {
            let v = _mm256_loadu2_m128i(
                p.add(24 * k + 12) as *const __m128i,
                p.add(24 * k) as *const __m128i,
            );
            let s = _mm256_add_epi32(
                _mm256_madd_epi16(_mm256_shuffle_epi8(v, bg), wbg),
                _mm256_madd_epi16(_mm256_shuffle_epi8(v, r), wr),
            );
            _mm256_srli_epi32::<15>(_mm256_add_epi32(s, half))
        };
        let (a, b) = (
            _mm256_packus_epi32(eight(0), eight(1)),
            _mm256_packus_epi32(eight(2), eight(3)),
        );
        let v = _mm256_permutevar8x32_epi32(_mm256_packus_epi16(a, b), order);
        let d = &mut dst[i..i + 32];
        // SAFETY: d has 32 bytes.
        unsafe { _mm256_storeu_si256(d.as_mut_ptr() as *mut __m256i, v) };
        i += 32;
    }
    i
}

/// Grey levels of a BGR image, exactly OpenCV's `cvtColor(BGR2GRAY)` (0.114 B +
/// 0.587 G + 0.299 R in 15-bit fixed point): `(3735·B + 19235·G + 9798·R + 2¹⁴) >> 15`. An image whose data does not match
/// its size gives an empty image.
pub fn grayscale(img: &Image) -> GrayImage {
    if !is_valid(img) {
        return GrayImage::default();
    }
    // Written into uninitialised capacity: zeroing the output first cost as much
    // as a tenth of the conversion (which is bound by memory bandwidth).
    let n = img.width as usize * img.height as usize;
    let mut data = Vec::with_capacity(n);
    let dst = &mut data.spare_capacity_mut()[..n];
    #[cfg(target_arch = "x86_64")]
    let done = if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        unsafe { gray_avx2(&img.data, dst) }
    } else {
        0
    };
    #[cfg(not(target_arch = "x86_64"))]
    let done = 0;
    gray_row(&img.data[3 * done..], &mut dst[done..]);
    // SAFETY: gray_row wrote all n values (src has exactly 3·n bytes).
    unsafe { data.set_len(n) };
    GrayImage {
        width: img.width,
        height: img.height,
        data,
    }
}

multiversion! {
    fn pyr_vertical(r: [&[u8]; 5], v: &mut [u16]) {
        let n = v.len();
        let (r0, r1, r2, r3, r4) = (&r[0][..n], &r[1][..n], &r[2][..n], &r[3][..n], &r[4][..n]);
        for i in 0..n {
            v[i] = r0[i] as u16
                + 4 * (r1[i] as u16 + r3[i] as u16)
                + 6 * r2[i] as u16
                + r4[i] as u16;
        }
    }
}

/// One output row of the horizontal pass: output pixel j is the 1-4-6-4-1 sum of
/// padded vertical sums at pixels 2j..2j+4, rounded (`+128 >> 8`), written straight
/// to the destination (only the kept half of the columns is computed).
macro_rules! pyr_horizontal {
    ($name:ident, $cn:expr) => {
        multiversion! {
            fn $name(v: &[u16], dst: &mut [u8]) {
                const CN: usize = $cn;
                let n = dst.len() / CN;
                let v = &v[..(2 * n + 3) * CN];
                for (j, d) in dst.chunks_exact_mut(CN).enumerate() {
                    let s = &v[2 * j * CN..(2 * j + 5) * CN];
                    for c in 0..CN {
                        let t = s[c] + 4 * (s[CN + c] + s[3 * CN + c]) + 6 * s[2 * CN + c] + s[4 * CN + c];
                        d[c] = (t.wrapping_add(128) >> 8) as u8;
                    }
                }
            }
        }
    };
}
pyr_horizontal!(pyr_horizontal1, 1);
pyr_horizontal!(pyr_horizontal3, 3);

/// Halves a `cn`-channel image with OpenCV's `pyrDown` (5x5 Gaussian
/// [1 4 6 4 1]²/256, rounded, `BORDER_REFLECT_101`); output ⌈w/2⌉ x ⌈h/2⌉.
fn pyr_down_raw(src: &[u8], w: u32, h: u32, cn: usize) -> (Vec<u8>, u32, u32) {
    let (w, h) = (w as usize, h as usize);
    let (dw, dh) = (w.div_ceil(2), h.div_ceil(2));
    let mut out = vec![0u8; dw * dh * cn];
    if w == 0 || h == 0 {
        return (out, dw as u32, dh as u32);
    }
    let row = |y: isize| {
        let y = reflect101(y, h);
        &src[y * w * cn..(y + 1) * w * cn]
    };
    // Vertical sums at full width, padded by 2 pixels each side (reflect 101).
    let mut vp = vec![0u16; (w + 4) * cn];
    for y in 0..dh {
        let yy = 2 * y as isize;
        let rows = [row(yy - 2), row(yy - 1), row(yy), row(yy + 1), row(yy + 2)];
        pyr_vertical(rows, &mut vp[2 * cn..(w + 2) * cn]);
        for k in [-2isize, -1, w as isize, w as isize + 1] {
            let s = reflect101(k, w);
            let d = (k + 2) as usize;
            for c in 0..cn {
                vp[d * cn + c] = vp[(s + 2) * cn + c];
            }
        }
        let dst = &mut out[y * dw * cn..(y + 1) * dw * cn];
        match cn {
            1 => pyr_horizontal1(&vp, dst),
            3 => pyr_horizontal3(&vp, dst),
            _ => unreachable!("pyrDown of 1 or 3 channels"),
        }
    }
    (out, dw as u32, dh as u32)
}

/// OpenCV's `pyrDown` of a BGR image.
pub fn pyr_down(img: &Image) -> Image {
    let mut out = Image::default();
    if is_valid(img) {
        (out.data, out.width, out.height) = pyr_down_raw(&img.data, img.width, img.height, 3);
    }
    out
}

/// OpenCV's `pyrDown` of a grey image.
pub fn pyr_down_gray(img: &GrayImage) -> GrayImage {
    let mut out = GrayImage::default();
    if valid_len(img.width, img.height, 1, img.data.len()) {
        (out.data, out.width, out.height) = pyr_down_raw(&img.data, img.width, img.height, 1);
    }
    out
}

/// The multiresolution pyramid: `img` then `levels` successive [`pyr_down`]s
/// (stops early when an image would be empty).
pub fn pyramid(img: &Image, levels: usize) -> Vec<Image> {
    let mut out = vec![img.clone()];
    for _ in 0..levels {
        let last = out.last().expect("non-empty");
        if last.width <= 1 && last.height <= 1 {
            break;
        }
        out.push(pyr_down(last));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// pyrDown straight from its definition (5x5 [1 4 6 4 1]²/256, reflect 101).
    fn pyr_down_reference(src: &[u8], w: usize, h: usize, cn: usize) -> Vec<u8> {
        let k = [1u32, 4, 6, 4, 1];
        let (dw, dh) = (w.div_ceil(2), h.div_ceil(2));
        let mut out = Vec::new();
        for y in 0..dh {
            for x in 0..dw {
                for c in 0..cn {
                    let mut s = 0;
                    for (i, ki) in k.iter().enumerate() {
                        let sy = reflect101(2 * y as isize + i as isize - 2, h);
                        for (j, kj) in k.iter().enumerate() {
                            let sx = reflect101(2 * x as isize + j as isize - 2, w);
                            s += ki * kj * src[(sy * w + sx) * cn + c] as u32;
                        }
                    }
                    out.push(((s + 128) >> 8) as u8);
                }
            }
        }
        out
    }

    #[test]
    fn pyr_down_matches_its_definition_at_odd_sizes() {
        for (w, h) in [(1, 1), (2, 3), (3, 2), (5, 7), (13, 9), (40, 17)] {
            for cn in [1, 3] {
                let src: Vec<u8> = (0..w * h * cn).map(|i| (i * 7919 % 256) as u8).collect();
                let (got, dw, dh) = pyr_down_raw(&src, w as u32, h as u32, cn);
                assert_eq!((dw as usize, dh as usize), (w.div_ceil(2), h.div_ceil(2)));
                assert_eq!(got, pyr_down_reference(&src, w, h, cn), "{w}x{h}x{cn}");
            }
        }
    }

    #[test]
    fn grayscale_vector_blocks_and_tails_match_the_formula() {
        for (w, h) in [(1, 1), (31, 1), (32, 1), (33, 2), (40, 3), (97, 5)] {
            let data: Vec<u8> = (0..w * h * 3).map(|i| (i * 7919 % 256) as u8).collect();
            let want: Vec<u8> = data
                .chunks_exact(3)
                .map(|p| {
                    let v = p[0] as u32 * 3735 + p[1] as u32 * 19235 + p[2] as u32 * 9798;
                    ((v + (1 << 14)) >> 15) as u8
                })
                .collect();
            let img = Image {
                width: w,
                height: h,
                data,
            };
            assert_eq!(grayscale(&img).data, want, "{w}x{h}");
        }
    }

    #[test]
    fn reflect101_matches_opencv() {
        let got: Vec<usize> = (-3..8).map(|i| reflect101(i, 5)).collect();
        assert_eq!(got, vec![3, 2, 1, 0, 1, 2, 3, 4, 3, 2, 1]);
    }
}
