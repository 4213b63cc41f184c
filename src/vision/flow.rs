//! Pyramidal Lucas-Kanade optical flow on tracked points (OpenCV's
//! `calcOpticalFlowPyrLK`, Bouguet's algorithm with its fixed-point details).

use super::{GrayImage, multiversion, pyr_down_gray, reflect101, valid_len};

/// Parameters of [`optical_flow_pyr_lk`]; the defaults are OpenCV's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LkParams {
    /// Side of the square search window, pixels (odd, 3..=51; OpenCV default 21).
    pub win_size: usize,
    /// Number of pyramid levels above the image (0 = no pyramid; default 3).
    pub max_level: usize,
    /// Iterations per level (default 30).
    pub max_iter: usize,
    /// Stop when the update is smaller than this, pixels (default 0.01).
    pub epsilon: f32,
    /// Points whose window's minimum eigenvalue (per pixel) is below this are lost
    /// (default 1e-4).
    pub min_eig_threshold: f32,
}

impl Default for LkParams {
    fn default() -> Self {
        LkParams {
            win_size: 21,
            max_level: 3,
            max_iter: 30,
            epsilon: 0.01,
            min_eig_threshold: 1e-4,
        }
    }
}

/// Where a point went.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackedPoint {
    /// Position in the next image (x = column, y = row, pixels).
    pub x: f32,
    pub y: f32,
    /// Whether the point was found.
    pub found: bool,
    /// Mean absolute grey difference over the window (OpenCV's `err`).
    pub error: f32,
}

/// A pyramid level padded by `pad` pixels: image (reflect 101) and, for the first
/// image, its Scharr derivatives (zero outside).
struct Level {
    w: usize,
    h: usize,
    stride: usize,
    img: Vec<u8>,
    dx: Vec<i16>,
    dy: Vec<i16>,
}

multiversion! {
    fn scharr_rows(a: &[u8], b: &[u8], c: &[u8], t0: &mut [i16], t1: &mut [i16]) {
        let w = t0.len() - 2;
        let (a, b, c) = (&a[..w], &b[..w], &c[..w]);
        let t0 = &mut t0[1..w + 1];
        let t1 = &mut t1[1..w + 1];
        for i in 0..w {
            t0[i] = (a[i] as i16 + c[i] as i16) * 3 + b[i] as i16 * 10;
            t1[i] = c[i] as i16 - a[i] as i16;
        }
    }
}

multiversion! {
    fn scharr_h(t0: &[i16], t1: &[i16], dx: &mut [i16], dy: &mut [i16]) {
        let w = dx.len();
        let dy = &mut dy[..w];
        let (a0, a2) = (&t0[..w], &t0[2..w + 2]);
        let (b0, b1, b2) = (&t1[..w], &t1[1..w + 1], &t1[2..w + 2]);
        for i in 0..w {
            dx[i] = a2[i] - a0[i];
            dy[i] = (b0[i] + b2[i]) * 3 + b1[i] * 10;
        }
    }
}

fn level(src: &GrayImage, pad: usize, derivs: bool) -> Level {
    let (w, h) = (src.width as usize, src.height as usize);
    let stride = w + 2 * pad;
    let rows = h + 2 * pad;
    // Built by appending rows, not by filling zeroed buffers: on a large photo the
    // zeroing cost as much as the derivatives themselves (perf).
    let mut img = Vec::with_capacity(stride * rows);
    for py in 0..rows {
        let sy = reflect101(py as isize - pad as isize, h);
        let s = &src.data[sy * w..(sy + 1) * w];
        img.extend((0..pad).map(|i| s[reflect101(i as isize - pad as isize, w)]));
        img.extend_from_slice(s);
        img.extend((0..pad).map(|i| s[reflect101((w + i) as isize, w)]));
    }
    let (mut dx, mut dy) = (Vec::new(), Vec::new());
    if derivs {
        (dx, dy) = (
            Vec::with_capacity(stride * rows),
            Vec::with_capacity(stride * rows),
        );
        dx.resize(pad * stride + pad, 0);
        dy.resize(pad * stride + pad, 0);
        let (mut t0, mut t1) = (vec![0i16; w + 2], vec![0i16; w + 2]);
        let (mut rx, mut ry) = (vec![0i16; w], vec![0i16; w]);
        let (l, r) = (reflect101(-1, w), reflect101(w as isize, w));
        let row = |y: isize| {
            let y = reflect101(y, h);
            &src.data[y * w..(y + 1) * w]
        };
        for y in 0..h {
            scharr_rows(
                row(y as isize - 1),
                row(y as isize),
                row(y as isize + 1),
                &mut t0,
                &mut t1,
            );
            t0[0] = t0[l + 1];
            t1[0] = t1[l + 1];
            t0[w + 1] = t0[r + 1];
            t1[w + 1] = t1[r + 1];
            scharr_h(&t0, &t1, &mut rx, &mut ry);
            dx.extend_from_slice(&rx);
            dy.extend_from_slice(&ry);
            dx.resize(dx.len() + 2 * pad, 0);
            dy.resize(dy.len() + 2 * pad, 0);
        }
        dx.resize(stride * rows, 0);
        dy.resize(stride * rows, 0);
    }
    Level {
        w,
        h,
        stride,
        img,
        dx,
        dy,
    }
}

fn weights(a: f32, b: f32) -> [i32; 4] {
    const W: f32 = (1 << 14) as f32;
    let w00 = ((1.0 - a) * (1.0 - b) * W).round_ties_even() as i32;
    let w01 = (a * (1.0 - b) * W).round_ties_even() as i32;
    let w10 = ((1.0 - a) * b * W).round_ties_even() as i32;
    [w00, w01, w10, (1 << 14) - w00 - w01 - w10]
}

/// Bilinear interpolation of one window row with the 14-bit weights `wt`, rounded
/// and shifted right by `SHIFT` (OpenCV's `DESCALE`): grey levels (`u8`, SHIFT 9)
/// give 1/32 levels, derivatives (`i16`, SHIFT 14) their own units.
#[inline(always)]
fn bilinear_row<T: Copy + Into<i32>, const SHIFT: u32>(
    r0: &[T],
    r1: &[T],
    wt: [i32; 4],
    out: &mut [i32],
) {
    let n = out.len();
    let (a, b) = (&r0[..n + 1], &r1[..n + 1]);
    for x in 0..n {
        let v = a[x].into() * wt[0]
            + a[x + 1].into() * wt[1]
            + b[x].into() * wt[2]
            + b[x + 1].into() * wt[3];
        out[x] = (v + (1 << (SHIFT - 1))) >> SHIFT;
    }
}

/// A template's rows (or one row): samples `iv` (1/32 levels), derivatives `ix`,
/// `iy`.
type Tmpl<'a> = (&'a [i32], &'a [i32], &'a [i32]);

/// (Σ diff·ix, Σ diff·iy, Σ |diff|) of one window row.
#[inline(always)]
fn mismatch_row(r0: &[u8], r1: &[u8], wt: [i32; 4], (iv, ix, iy): Tmpl) -> (i32, i32, i32) {
    let n = iv.len();
    let (a, b) = (&r0[..n + 1], &r1[..n + 1]);
    let (ix, iy) = (&ix[..n], &iy[..n]);
    let (mut s1, mut s2, mut s3) = (0i32, 0i32, 0i32);
    for x in 0..n {
        let v = a[x] as i32 * wt[0]
            + a[x + 1] as i32 * wt[1]
            + b[x] as i32 * wt[2]
            + b[x + 1] as i32 * wt[3];
        let d = ((v + (1 << 8)) >> 9) - iv[x];
        s1 += d * ix[x];
        s2 += d * iy[x];
        s3 += d.abs();
    }
    (s1, s2, s3)
}

/// Template rows are stored `padded(win)` wide (a multiple of 8) with zero
/// derivatives past the window, so the iteration loop runs on whole 8-lane vectors.
fn padded(win: usize) -> usize {
    win.div_ceil(8) * 8
}

/// (Σ diff·ix, Σ diff·iy) of one padded template row: as [`mismatch_row`] over
/// `ix.len()` (a multiple of 8) lanes, whose lanes past the window add 0.
#[inline(always)]
fn gradient_row(r0: &[u8], r1: &[u8], wt: [i32; 4], (iv, ix, iy): Tmpl) -> (i32, i32) {
    let n = ix.len();
    let (a, b) = (&r0[..n + 1], &r1[..n + 1]);
    let (mut s1, mut s2) = ([0i32; 8], [0i32; 8]);
    for c in 0..n / 8 {
        let k = c * 8;
        let (a0, a1): (&[u8; 8], &[u8; 8]) = (
            a[k..k + 8].try_into().unwrap(),
            a[k + 1..k + 9].try_into().unwrap(),
        );
        let (b0, b1): (&[u8; 8], &[u8; 8]) = (
            b[k..k + 8].try_into().unwrap(),
            b[k + 1..k + 9].try_into().unwrap(),
        );
        let (tv, tx, ty): (&[i32; 8], &[i32; 8], &[i32; 8]) = (
            iv[k..k + 8].try_into().unwrap(),
            ix[k..k + 8].try_into().unwrap(),
            iy[k..k + 8].try_into().unwrap(),
        );
        for l in 0..8 {
            let v = a0[l] as i32 * wt[0]
                + a1[l] as i32 * wt[1]
                + b0[l] as i32 * wt[2]
                + b1[l] as i32 * wt[3];
            let d = ((v + (1 << 8)) >> 9) - tv[l];
            s1[l] += d * tx[l];
            s2[l] += d * ty[l];
        }
    }
    (s1.iter().sum(), s2.iter().sum())
}

/// [`gradient_row`] with 16-bit multiply-adds (as OpenCV): the bilinear sample
/// as (a[x], a[x+1])·(w00, w01) + (b[x], b[x+1])·(w10, w11), then diff·ix with
/// ix's high half masked off (diff and ix fit in i16: |diff| <= 8160, |ix| <= 4080).
/// Exact integer arithmetic, so the same sums.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn gradient_row_avx2(r0: &[u8], r1: &[u8], wt: [i32; 4], (iv, ix, iy): Tmpl) -> (i32, i32) {
    use std::arch::x86_64::*;
    let n = ix.len();
    assert!(n.is_multiple_of(8) && r0.len() > n && r1.len() > n && iv.len() >= n && iy.len() >= n);
    let wa = _mm256_set1_epi32(wt[0] | (wt[1] << 16));
    let wb = _mm256_set1_epi32(wt[2] | (wt[3] << 16));
    let (round, lo) = (_mm256_set1_epi32(1 << 8), _mm256_set1_epi32(0xffff));
    let (mut s1, mut s2) = (_mm256_setzero_si256(), _mm256_setzero_si256());
    for k in (0..n).step_by(8) {
        // SAFETY: k + 9 <= n + 1 <= r0.len(), r1.len(), and k + 8 <= n for the
        // template rows (asserted above); all loads are unaligned.
        let (pa, pb, tv, tx, ty) = unsafe {
            let p = |r: &[u8]| {
                let x0 = _mm_loadl_epi64(r.as_ptr().add(k) as *const __m128i);
                let x1 = _mm_loadl_epi64(r.as_ptr().add(k + 1) as *const __m128i);
                _mm256_cvtepu8_epi16(_mm_unpacklo_epi8(x0, x1))
            };
            let l = |t: &[i32]| _mm256_loadu_si256(t.as_ptr().add(k) as *const __m256i);
            (p(r0), p(r1), l(iv), l(ix), l(iy))
        };
        let v = _mm256_add_epi32(_mm256_madd_epi16(pa, wa), _mm256_madd_epi16(pb, wb));
        let d = _mm256_sub_epi32(_mm256_srai_epi32::<9>(_mm256_add_epi32(v, round)), tv);
        s1 = _mm256_add_epi32(s1, _mm256_madd_epi16(d, _mm256_and_si256(tx, lo)));
        s2 = _mm256_add_epi32(s2, _mm256_madd_epi16(d, _mm256_and_si256(ty, lo)));
    }
    let mut out = [[0i32; 8]; 2];
    // SAFETY: each array has 8 lanes.
    unsafe {
        _mm256_storeu_si256(out[0].as_mut_ptr() as *mut __m256i, s1);
        _mm256_storeu_si256(out[1].as_mut_ptr() as *mut __m256i, s2);
    }
    (out[0].iter().sum(), out[1].iter().sum())
}

type DerivRows<'a> = (&'a [i16], &'a [i16], &'a [i16], &'a [i16]);

/// What a template row is made of: the first image's two rows `i0`, `i1`
/// and their derivatives' (from the window row's offset on), the weights, the
/// window's side.
#[derive(Clone, Copy)]
struct TemplateSource<'a> {
    i0: &'a [u8],
    i1: &'a [u8],
    d: DerivRows<'a>,
    wt: [i32; 4],
    win: usize,
}

/// A template row being written: `iv`, `ix`, `iy`.
type TmplMut<'a> = (&'a mut [i32], &'a mut [i32], &'a mut [i32]);

/// One template row: samples `iv` (1/32 levels) and derivatives `ix`, `iy` of the
/// first `win` lanes (the padding lanes are left 0), and that row's
/// (Σ ix², Σ ix·iy, Σ iy²).
#[inline(always)]
fn template_row(src: TemplateSource, (iv, ix, iy): TmplMut) -> (i64, i64, i64) {
    let TemplateSource { i0, i1, d, wt, win } = src;
    bilinear_row::<_, 9>(i0, i1, wt, &mut iv[..win]);
    bilinear_row::<_, 14>(d.0, d.1, wt, &mut ix[..win]);
    bilinear_row::<_, 14>(d.2, d.3, wt, &mut iy[..win]);
    let (rx, ry) = (&ix[..win], &iy[..win]);
    (
        rx.iter().map(|v| (v * v) as i64).sum::<i64>(),
        rx.iter().zip(ry).map(|(a, b)| (a * b) as i64).sum::<i64>(),
        ry.iter().map(|v| (v * v) as i64).sum::<i64>(),
    )
}

/// [`template_row`] with 16-bit multiply-adds on (p[x], p[x+1]) pairs, over whole
/// 8-lane blocks with the lanes past `win` masked to 0. Exact integer arithmetic
/// (|derivative| <= 4080 fits in i16; 4080·2¹⁴ fits in i32), so the same values.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn template_row_avx2(src: TemplateSource, (iv, ix, iy): TmplMut) -> (i64, i64, i64) {
    use std::arch::x86_64::*;
    let TemplateSource { i0, i1, d, wt, win } = src;
    let n = ix.len();
    assert!(n.is_multiple_of(8) && win <= n && iv.len() >= n && iy.len() >= n);
    assert!(i0.len() > n && i1.len() > n && d.0.len() > n && d.1.len() > n);
    assert!(d.2.len() > n && d.3.len() > n);
    let wa = _mm256_set1_epi32(wt[0] | (wt[1] << 16));
    let wb = _mm256_set1_epi32(wt[2] | (wt[3] << 16));
    let lo = _mm256_set1_epi32(0xffff);
    let lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    let (mut sxx, mut sxy, mut syy) = (
        _mm256_setzero_si256(),
        _mm256_setzero_si256(),
        _mm256_setzero_si256(),
    );
    for k in (0..n).step_by(8) {
        let keep = _mm256_cmpgt_epi32(_mm256_set1_epi32((win - k) as i32), lanes);
        // SAFETY: reads end at k + 9 <= n + 1 <= each row's length, writes at
        // k + 8 <= n (asserted above); all accesses are unaligned.
        unsafe {
            let bytes = |r: &[u8]| {
                let x0 = _mm_loadl_epi64(r.as_ptr().add(k) as *const __m128i);
                let x1 = _mm_loadl_epi64(r.as_ptr().add(k + 1) as *const __m128i);
                _mm256_cvtepu8_epi16(_mm_unpacklo_epi8(x0, x1))
            };
            let words = |r: &[i16]| {
                let x0 = _mm_loadu_si128(r.as_ptr().add(k) as *const __m128i);
                let x1 = _mm_loadu_si128(r.as_ptr().add(k + 1) as *const __m128i);
                _mm256_set_m128i(_mm_unpackhi_epi16(x0, x1), _mm_unpacklo_epi16(x0, x1))
            };
            let v = _mm256_add_epi32(
                _mm256_madd_epi16(bytes(i0), wa),
                _mm256_madd_epi16(bytes(i1), wb),
            );
            let v = _mm256_srai_epi32::<9>(_mm256_add_epi32(v, _mm256_set1_epi32(1 << 8)));
            let deriv = |a: &[i16], b: &[i16]| {
                let v = _mm256_add_epi32(
                    _mm256_madd_epi16(words(a), wa),
                    _mm256_madd_epi16(words(b), wb),
                );
                let v = _mm256_srai_epi32::<14>(_mm256_add_epi32(v, _mm256_set1_epi32(1 << 13)));
                _mm256_and_si256(v, keep)
            };
            let (gx, gy) = (deriv(d.0, d.1), deriv(d.2, d.3));
            _mm256_storeu_si256(
                iv.as_mut_ptr().add(k) as *mut __m256i,
                _mm256_and_si256(v, keep),
            );
            _mm256_storeu_si256(ix.as_mut_ptr().add(k) as *mut __m256i, gx);
            _mm256_storeu_si256(iy.as_mut_ptr().add(k) as *mut __m256i, gy);
            let (gx, gy) = (_mm256_and_si256(gx, lo), _mm256_and_si256(gy, lo));
            sxx = _mm256_add_epi32(sxx, _mm256_madd_epi16(gx, gx));
            sxy = _mm256_add_epi32(sxy, _mm256_madd_epi16(gx, gy));
            syy = _mm256_add_epi32(syy, _mm256_madd_epi16(gy, gy));
        }
    }
    let mut out = [[0i32; 8]; 3];
    // SAFETY: each array has 8 lanes.
    unsafe {
        _mm256_storeu_si256(out[0].as_mut_ptr() as *mut __m256i, sxx);
        _mm256_storeu_si256(out[1].as_mut_ptr() as *mut __m256i, sxy);
        _mm256_storeu_si256(out[2].as_mut_ptr() as *mut __m256i, syy);
    }
    let sum = |a: &[i32; 8]| a.iter().map(|&v| v as i64).sum::<i64>();
    (sum(&out[0]), sum(&out[1]), sum(&out[2]))
}

/// A window of side `win` on a level padded by `pad`, at the whole pixel `p`
/// (top-left, unpadded) with the bilinear weights `wt` of the point's fraction.
#[derive(Clone, Copy)]
struct Window {
    p: (i32, i32),
    wt: [i32; 4],
    win: usize,
    pad: usize,
}

impl Window {
    /// The window whose top-left corner is the point `at` (pixels).
    #[inline(always)]
    fn at(at: (f32, f32), win: usize, pad: usize) -> Window {
        let p = (at.0.floor() as i32, at.1.floor() as i32);
        let wt = weights(at.0 - p.0 as f32, at.1 - p.1 as f32);
        Window { p, wt, win, pad }
    }
    /// Where its row `y` starts in `l`'s (padded) buffers.
    #[inline(always)]
    fn row(&self, l: &Level, y: usize) -> usize {
        let pad = self.pad as i32;
        (self.p.1 + pad + y as i32) as usize * l.stride + (self.p.0 + pad) as usize
    }
}

/// The template over the window `w` of the first image's level `li` (written to
/// `iv`, `ix`, `iy`, [`padded`] rows) and its (Σ ix², Σ ix·iy, Σ iy²).
#[inline(always)]
fn template_window(li: &Level, w: Window, (iv, ix, iy): TmplMut, avx2: bool) -> (i64, i64, i64) {
    let (mut a11, mut a12, mut a22) = (0i64, 0i64, 0i64);
    let wp = padded(w.win);
    for y in 0..w.win {
        let o = w.row(li, y);
        let r = y * wp..(y + 1) * wp;
        let src = TemplateSource {
            i0: &li.img[o..],
            i1: &li.img[o + li.stride..],
            d: (
                &li.dx[o..],
                &li.dx[o + li.stride..],
                &li.dy[o..],
                &li.dy[o + li.stride..],
            ),
            wt: w.wt,
            win: w.win,
        };
        let t = (&mut iv[r.clone()], &mut ix[r.clone()], &mut iy[r]);
        #[cfg(target_arch = "x86_64")]
        let sums = if avx2 {
            // SAFETY: the caller checked that the CPU has AVX2.
            unsafe { template_row_avx2(src, t) }
        } else {
            template_row(src, t)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let sums = {
            let _ = avx2;
            template_row(src, t)
        };
        a11 += sums.0;
        a12 += sums.1;
        a22 += sums.2;
    }
    (a11, a12, a22)
}

/// (Σ diff·ix, Σ diff·iy) over the window `w` of `lj` (the iteration's right-hand
/// side).
#[inline(always)]
fn gradient_window(lj: &Level, w: Window, (iv, ix, iy): Tmpl, avx2: bool) -> (i64, i64) {
    let wp = padded(w.win);
    let (mut b1, mut b2) = (0i64, 0i64);
    for y in 0..w.win {
        let o = w.row(lj, y);
        let r = y * wp..(y + 1) * wp;
        let (r0, r1) = (&lj.img[o..], &lj.img[o + lj.stride..]);
        let t = (&iv[r.clone()], &ix[r.clone()], &iy[r]);
        #[cfg(target_arch = "x86_64")]
        let (s1, s2) = if avx2 {
            // SAFETY: the caller checked that the CPU has AVX2.
            unsafe { gradient_row_avx2(r0, r1, w.wt, t) }
        } else {
            gradient_row(r0, r1, w.wt, t)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let (s1, s2) = {
            let _ = avx2;
            gradient_row(r0, r1, w.wt, t)
        };
        b1 += s1 as i64;
        b2 += s2 as i64;
    }
    (b1, b2)
}

/// (Σ diff·ix, Σ diff·iy, Σ |diff|) over the window `w` of `lj`.
#[inline(always)]
fn mismatch_window(lj: &Level, w: Window, (iv, ix, iy): Tmpl) -> (i64, i64, i64) {
    let wp = padded(w.win);
    let (mut b1, mut b2, mut e) = (0i64, 0i64, 0i64);
    for y in 0..w.win {
        let o = w.row(lj, y);
        let r = y * wp..y * wp + w.win;
        let t = (&iv[r.clone()], &ix[r.clone()], &iy[r]);
        let (s1, s2, s3) = mismatch_row(&lj.img[o..], &lj.img[o + lj.stride..], w.wt, t);
        b1 += s1 as i64;
        b2 += s2 as i64;
        e += s3 as i64;
    }
    (b1, b2, e)
}

/// Tracks `points` (x = column, y = row, pixels) from `prev` to `next` (same size)
/// with pyramidal Lucas-Kanade, OpenCV's `calcOpticalFlowPyrLK` without initial
/// flow. Returns one [`TrackedPoint`] per input point; mismatched images give every
/// point `found = false`.
pub fn optical_flow_pyr_lk(
    prev: &GrayImage,
    next: &GrayImage,
    points: &[(f32, f32)],
    params: &LkParams,
) -> Vec<TrackedPoint> {
    let lost = |&(x, y): &(f32, f32)| TrackedPoint {
        x,
        y,
        found: false,
        error: 0.0,
    };
    let win = params.win_size.clamp(3, 51) | 1;
    if prev.width != next.width
        || prev.height != next.height
        || !valid_len(prev.width, prev.height, 1, prev.data.len())
        || !valid_len(next.width, next.height, 1, next.data.len())
        || prev.width as usize <= win
        || prev.height as usize <= win
    {
        return points.iter().map(lost).collect();
    }
    // Pyramids; stop before a level gets smaller than the window (as OpenCV).
    // The padding also covers the reads of whole 8-lane template rows (`padded`).
    let pad = padded(win) + 1;
    let (mut li, mut lj) = (vec![level(prev, pad, true)], vec![level(next, pad, false)]);
    let (mut a, mut b): (Option<GrayImage>, Option<GrayImage>) = (None, None);
    while li.len() <= params.max_level {
        let na = pyr_down_gray(a.as_ref().unwrap_or(prev));
        let nb = pyr_down_gray(b.as_ref().unwrap_or(next));
        if na.width as usize <= win || na.height as usize <= win {
            break;
        }
        li.push(level(&na, pad, true));
        lj.push(level(&nb, pad, false));
        (a, b) = (Some(na), Some(nb));
    }
    track(&li, &lj, points, params, win, pad)
}

multiversion! {
    fn track(li: &[Level], lj: &[Level], points: &[(f32, f32)], params: &LkParams, win: usize, pad: usize) -> Vec<TrackedPoint> {
    let max_level = li.len() - 1;
    #[cfg(target_arch = "x86_64")]
    let avx2 = std::arch::is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    let avx2 = false;
    let half = (win as f32 - 1.0) * 0.5;
    let eps2 = params.epsilon.clamp(0.0, 10.0).powi(2);
    const FLT_SCALE: f32 = 1.0 / (1 << 20) as f32;
    let area = win * win;
    let tlen = win * padded(win);
    let (mut iv, mut ix, mut iy) = (vec![0i32; tlen], vec![0i32; tlen], vec![0i32; tlen]);
    let inside = |p: (i32, i32), l: &Level| {
        p.0 >= -(win as i32) && p.0 < l.w as i32 && p.1 >= -(win as i32) && p.1 < l.h as i32
    };
    let lost = |&(x, y): &(f32, f32)| TrackedPoint { x, y, found: false, error: 0.0 };
    let mut out = Vec::with_capacity(points.len());
    for &pt in points {
        let mut res = TrackedPoint {
            x: pt.0,
            y: pt.1,
            found: true,
            error: 0.0,
        };
        if !pt.0.is_finite() || !pt.1.is_finite() {
            out.push(lost(&pt));
            continue;
        }
        let mut next_pt = (0f32, 0f32);
        for lvl in (0..=max_level).rev() {
            let (li, lj) = (&li[lvl], &lj[lvl]);
            let s = 1.0 / (1u32 << lvl) as f32;
            let mut prev_pt = (pt.0 * s, pt.1 * s);
            next_pt = if lvl == max_level {
                prev_pt
            } else {
                (next_pt.0 * 2.0, next_pt.1 * 2.0)
            };
            prev_pt = (prev_pt.0 - half, prev_pt.1 - half);
            let w = Window::at(prev_pt, win, pad);
            // Lost at the finest level only; a coarser level is skipped.
            let lose = lvl == 0;
            if !inside(w.p, li) {
                res.found &= !lose;
                continue;
            }
            let (a11, a12, a22) = template_window(li, w, (&mut iv, &mut ix, &mut iy), avx2);
            let (a11, a12, a22) = (
                a11 as f32 * FLT_SCALE,
                a12 as f32 * FLT_SCALE,
                a22 as f32 * FLT_SCALE,
            );
            let d = a11 * a22 - a12 * a12;
            let min_eig = (a22 + a11 - ((a11 - a22) * (a11 - a22) + 4.0 * a12 * a12).sqrt())
                / (2.0 * area as f32);
            if min_eig < params.min_eig_threshold || d < f32::EPSILON {
                res.found &= !lose;
                continue;
            }
            let d = 1.0 / d;
            next_pt = (next_pt.0 - half, next_pt.1 - half);
            let mut prev_delta = (0f32, 0f32);
            let mut result = next_pt;
            for j in 0..params.max_iter.min(100) {
                let w = Window::at(next_pt, win, pad);
                if !inside(w.p, lj) {
                    res.found &= !lose;
                    break;
                }
                // A plain fn, not a closure: closures do not inherit the AVX2 target
                // feature of `track`, and this is the hot loop.
                let (b1, b2) = gradient_window(lj, w, (&iv, &ix, &iy), avx2);
                let (b1, b2) = (b1 as f32 * FLT_SCALE, b2 as f32 * FLT_SCALE);
                let delta = ((a12 * b2 - a22 * b1) * d, (a12 * b1 - a11 * b2) * d);
                next_pt = (next_pt.0 + delta.0, next_pt.1 + delta.1);
                result = next_pt;
                if delta.0 * delta.0 + delta.1 * delta.1 <= eps2 {
                    break;
                }
                if j > 0
                    && (delta.0 + prev_delta.0).abs() < 0.01
                    && (delta.1 + prev_delta.1).abs() < 0.01
                {
                    result = (next_pt.0 - delta.0 * 0.5, next_pt.1 - delta.1 * 0.5);
                    break;
                }
                prev_delta = delta;
            }
            next_pt = (result.0 + half, result.1 + half);
            if lvl == 0 && res.found {
                let w = Window::at(result, win, pad);
                if !inside(w.p, lj) {
                    res.found = false;
                } else {
                    let (_, _, e) = mismatch_window(lj, w, (&iv, &ix, &iy));
                    res.error = e as f32 / (32 * area) as f32;
                }
            }
        }
        res.x = next_pt.0;
        res.y = next_pt.1;
        out.push(res);
    }
    out
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;

    /// The AVX2 row kernels give the portable kernels' integers, on random rows with
    /// derivatives at Scharr's extremes and random bilinear weights.
    #[test]
    fn avx2_rows_match_portable_rows() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut seed = 12345u32;
        let mut rnd = move || {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            seed >> 8
        };
        for win in [3usize, 5, 8, 21, 31] {
            let n = padded(win);
            for _ in 0..50 {
                let img: Vec<Vec<u8>> = (0..2)
                    .map(|_| (0..=n).map(|_| rnd() as u8).collect())
                    .collect();
                let der: Vec<Vec<i16>> = (0..4)
                    .map(|_| (0..=n).map(|_| (rnd() % 8161) as i16 - 4080).collect())
                    .collect();
                let (a, b) = (
                    (rnd() % 1000) as f32 / 1000.0,
                    (rnd() % 1000) as f32 / 1000.0,
                );
                let wt = weights(a, b);
                let d = (&der[0][..], &der[1][..], &der[2][..], &der[3][..]);
                let mut t1 = [vec![0i32; n], vec![0i32; n], vec![0i32; n]];
                let mut t2 = t1.clone();
                let [v1, x1, y1] = &mut t1;
                let (i0, i1) = (&img[0][..], &img[1][..]);
                let src = TemplateSource { i0, i1, d, wt, win };
                let s1 = template_row(src, (v1, x1, y1));
                let [v2, x2, y2] = &mut t2;
                // SAFETY: AVX2 checked above.
                let s2 = unsafe { template_row_avx2(src, (v2, x2, y2)) };
                assert_eq!((s1, &t1), (s2, &t2), "win {win}");
                let next: Vec<Vec<u8>> = (0..2)
                    .map(|_| (0..=n).map(|_| rnd() as u8).collect())
                    .collect();
                let t = (&t1[0][..], &t1[1][..], &t1[2][..]);
                let g1 = gradient_row(&next[0], &next[1], wt, t);
                // SAFETY: AVX2 checked above.
                let g2 = unsafe { gradient_row_avx2(&next[0], &next[1], wt, t) };
                assert_eq!(g1, g2, "win {win}");
            }
        }
    }
}
