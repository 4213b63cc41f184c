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

/// A pyramid level padded by `pad` pixels (reflect 101), which covers every read
/// of a window that [`track`] keeps: the image only. The template's derivatives
/// are computed per window ([`scharr_block`]) instead of over the whole level:
/// on a 1411x1411 photo the derivative images (zeroed padding, Scharr over
/// 2 Mpx, their copies, and the template's cache misses on 8 MB of them) took 40 %
/// of the run (perf), for windows covering a few percent of the image.
struct Level {
    w: usize,
    h: usize,
    stride: usize,
    pad: usize,
    img: Vec<u8>,
}

impl Level {
    fn new(src: &GrayImage, pad: usize) -> Level {
        let (w, h) = (src.width as usize, src.height as usize);
        let stride = w + 2 * pad;
        // Built by appending rows, not by filling a zeroed buffer (perf).
        let mut img = Vec::with_capacity(stride * (h + 2 * pad));
        let left: Vec<usize> = (0..pad)
            .map(|i| reflect101(i as isize - pad as isize, w))
            .collect();
        let right: Vec<usize> = (0..pad).map(|i| reflect101((w + i) as isize, w)).collect();
        for py in 0..h + 2 * pad {
            let sy = reflect101(py as isize - pad as isize, h);
            let s = &src.data[sy * w..(sy + 1) * w];
            img.extend(left.iter().map(|&x| s[x]));
            img.extend_from_slice(s);
            img.extend(right.iter().map(|&x| s[x]));
        }
        Level {
            w,
            h,
            stride,
            pad,
            img,
        }
    }

    /// The pixels from (x0, y0) on (at most `pad` outside the level), as (the
    /// buffer from that pixel on, row stride).
    #[inline(always)]
    fn block(&self, (x0, y0): (i32, i32)) -> (&[u8], usize) {
        let (x, y) = (x0 + self.pad as i32, y0 + self.pad as i32);
        (
            &self.img[y as usize * self.stride + x as usize..],
            self.stride,
        )
    }
}

/// Columns of a window's derivative rows: the template reads `padded(win) + 1`,
/// rounded up to whole 16-lane vectors.
fn deriv_cols(win: usize) -> usize {
    (padded(win) + 1).next_multiple_of(16)
}

/// Scharr derivatives as OpenCV's `calcScharrDeriv` (dx: [3 10 3]ᵀ·[−1 0 1], dy its
/// transpose; |value| <= 4080, exact in i16) of `rows` rows of `cols` pixels,
/// from the block `src` (row stride `stride`) that starts one row above and one
/// column left of the first pixel; `dx`, `dy` get `cols` a row. Each value straight
/// from the nine pixels: storing the vertical sums and loading them again at
/// offsets 1 and 2 stalled on store forwarding (perf).
#[inline(always)]
fn scharr_block(
    (src, stride): (&[u8], usize),
    (cols, rows): (usize, usize),
    dx: &mut [i16],
    dy: &mut [i16],
) {
    for y in 0..rows {
        let a = &src[y * stride..][..cols + 2];
        let b = &src[(y + 1) * stride..][..cols + 2];
        let c = &src[(y + 2) * stride..][..cols + 2];
        let (rx, ry) = (&mut dx[y * cols..][..cols], &mut dy[y * cols..][..cols]);
        for x in 0..cols {
            let p = |r: &[u8], k: usize| r[x + k] as i16;
            let (t0l, t0r) = (
                (p(a, 0) + p(c, 0)) * 3 + p(b, 0) * 10,
                (p(a, 2) + p(c, 2)) * 3 + p(b, 2) * 10,
            );
            let t1 = |k: usize| p(c, k) - p(a, k);
            rx[x] = t0r - t0l;
            ry[x] = (t1(0) + t1(2)) * 3 + t1(1) * 10;
        }
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

/// [`gradient_window`]'s sums over `win` rows of the second image's block `src`
/// (row stride `stride`) with 16-bit multiply-adds (as OpenCV): the bilinear
/// sample as (a[x], a[x+1])·(w00, w01) + (b[x], b[x+1])·(w10, w11), then diff·ix
/// with ix's high half masked off (diff and ix fit in i16: |diff| <= 8160, |ix| <=
/// 4080). A lane adds one product a block, so `blocks · 8160 · 4080` a row; the
/// lanes are summed into i64 every `i32::MAX` / that many rows (all 21 rows of a
/// 21x21 window; the sums of each row cost as much as the row). Exact integers, so
/// the same sums as [`gradient_row`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn gradient_window_avx2(
    (src, stride): (&[u8], usize),
    wt: [i32; 4],
    (iv, ix, iy): Tmpl,
    win: usize,
) -> (i64, i64) {
    use std::arch::x86_64::*;
    let n = padded(win);
    assert!(src.len() > win * stride + n && stride > n);
    assert!(iv.len() >= win * n && ix.len() >= win * n && iy.len() >= win * n);
    let flush = (i32::MAX as usize / (n / 8 * 8160 * 4080)).max(1);
    let wa = _mm256_set1_epi32(wt[0] | (wt[1] << 16));
    let wb = _mm256_set1_epi32(wt[2] | (wt[3] << 16));
    let (round, lo) = (_mm256_set1_epi32(1 << 8), _mm256_set1_epi32(0xffff));
    let (mut s1, mut s2) = (_mm256_setzero_si256(), _mm256_setzero_si256());
    let (mut b1, mut b2) = (0i64, 0i64);
    let lanes = |v: __m256i| {
        let mut a = [0i32; 8];
        // SAFETY: `a` has 8 lanes.
        unsafe { _mm256_storeu_si256(a.as_mut_ptr() as *mut __m256i, v) };
        a.iter().map(|&x| x as i64).sum::<i64>()
    };
    for y in 0..win {
        for k in (0..n).step_by(8) {
            // SAFETY: the image reads end at (y + 1)·stride + k + 9 <= win·stride +
            // n + 1 <= src.len(), the template's at y·n + k + 8 <= win·n (asserted
            // above); all loads are unaligned.
            let (pa, pb, tv, tx, ty) = unsafe {
                let p = |o: usize| {
                    let x0 = _mm_loadl_epi64(src.as_ptr().add(o) as *const __m128i);
                    let x1 = _mm_loadl_epi64(src.as_ptr().add(o + 1) as *const __m128i);
                    _mm256_cvtepu8_epi16(_mm_unpacklo_epi8(x0, x1))
                };
                let t = y * n + k;
                let l = |v: &[i32]| _mm256_loadu_si256(v.as_ptr().add(t) as *const __m256i);
                (
                    p(y * stride + k),
                    p((y + 1) * stride + k),
                    l(iv),
                    l(ix),
                    l(iy),
                )
            };
            let v = _mm256_add_epi32(_mm256_madd_epi16(pa, wa), _mm256_madd_epi16(pb, wb));
            let d = _mm256_sub_epi32(_mm256_srai_epi32::<9>(_mm256_add_epi32(v, round)), tv);
            s1 = _mm256_add_epi32(s1, _mm256_madd_epi16(d, _mm256_and_si256(tx, lo)));
            s2 = _mm256_add_epi32(s2, _mm256_madd_epi16(d, _mm256_and_si256(ty, lo)));
        }
        if (y + 1) % flush == 0 || y + 1 == win {
            (b1, b2) = (b1 + lanes(s1), b2 + lanes(s2));
            (s1, s2) = (_mm256_setzero_si256(), _mm256_setzero_si256());
        }
    }
    (b1, b2)
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

/// A window of side `win` at the whole pixel `p` (top-left) with the bilinear
/// weights `wt` of the point's fraction.
#[derive(Clone, Copy)]
struct Window {
    p: (i32, i32),
    wt: [i32; 4],
    win: usize,
}

impl Window {
    /// The window whose top-left corner is the point `at` (pixels).
    #[inline(always)]
    fn at(at: (f32, f32), win: usize) -> Window {
        let p = (at.0.floor() as i32, at.1.floor() as i32);
        let wt = weights(at.0 - p.0 as f32, at.1 - p.1 as f32);
        Window { p, wt, win }
    }
}

/// The per-point buffers, allocated once per call: the template (`iv`, `ix`, `iy`,
/// [`padded`] rows) and its derivatives.
struct Scratch {
    iv: Vec<i32>,
    ix: Vec<i32>,
    iy: Vec<i32>,
    /// The template's derivatives, [`deriv_cols`] a row.
    dx: Vec<i16>,
    dy: Vec<i16>,
}

impl Scratch {
    fn new(win: usize) -> Scratch {
        let tlen = win * padded(win);
        let (cols, rows) = (deriv_cols(win), win + 1);
        Scratch {
            iv: vec![0; tlen],
            ix: vec![0; tlen],
            iy: vec![0; tlen],
            dx: vec![0; cols * rows],
            dy: vec![0; cols * rows],
        }
    }
}

/// The first image's derivatives over the `win + 1` rows and [`deriv_cols`]
/// columns from the window's corner into `dx`, `dy` (0 outside the level, as
/// OpenCV's zero-bordered derivative image), from `block`: the level's pixels from
/// one row above and one column left of the corner.
#[inline(always)]
fn window_derivs(li: &Level, w: Window, block: (&[u8], usize), (dx, dy): (&mut [i16], &mut [i16])) {
    let (cols, rows) = (deriv_cols(w.win), w.win + 1);
    scharr_block(block, (cols, rows), dx, dy);
    // The rows and columns inside the level: ys, xs.
    let inside = |p: i32, n: usize, len: usize| {
        (-p).clamp(0, n as i32) as usize..(len as i32 - p).clamp(0, n as i32) as usize
    };
    let (xs, ys) = (inside(w.p.0, cols, li.w), inside(w.p.1, rows, li.h));
    if xs.len() == cols && ys.len() == rows {
        return;
    }
    for (y, (rx, ry)) in dx.chunks_mut(cols).zip(dy.chunks_mut(cols)).enumerate() {
        for r in [rx, ry] {
            if ys.contains(&y) && xs.start < xs.end {
                r[..xs.start].fill(0);
                r[xs.end..].fill(0);
            } else {
                r.fill(0);
            }
        }
    }
}

/// The template over the window `w` of the first image's level `li` (written to
/// `s.iv`, `s.ix`, `s.iy`, [`padded`] rows) and its (Σ ix², Σ ix·iy, Σ iy²).
#[inline(always)]
fn template_window(li: &Level, w: Window, s: &mut Scratch, avx2: bool) -> (i64, i64, i64) {
    let Scratch { iv, ix, iy, dx, dy } = s;
    let (cols, wp) = (deriv_cols(w.win), padded(w.win));
    let (src, stride) = li.block((w.p.0 - 1, w.p.1 - 1));
    window_derivs(li, w, (src, stride), (dx, dy));
    let (mut a11, mut a12, mut a22) = (0i64, 0i64, 0i64);
    for y in 0..w.win {
        let o = (y + 1) * stride + 1;
        let r = y * wp..(y + 1) * wp;
        let src = TemplateSource {
            i0: &src[o..],
            i1: &src[o + stride..],
            d: (
                &dx[y * cols..],
                &dx[(y + 1) * cols..],
                &dy[y * cols..],
                &dy[(y + 1) * cols..],
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

/// (Σ diff·ix, Σ diff·iy) over the window `w` of the second image's `block`
/// (the iteration's right-hand side).
#[inline(always)]
fn gradient_window(block: (&[u8], usize), w: Window, (iv, ix, iy): Tmpl, avx2: bool) -> (i64, i64) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: the caller checked that the CPU has AVX2.
        return unsafe { gradient_window_avx2(block, w.wt, (iv, ix, iy), w.win) };
    }
    let _ = avx2;
    let ((src, stride), wp) = (block, padded(w.win));
    let (mut b1, mut b2) = (0i64, 0i64);
    for y in 0..w.win {
        let r = y * wp..(y + 1) * wp;
        let t = (&iv[r.clone()], &ix[r.clone()], &iy[r]);
        let (s1, s2) = gradient_row(&src[y * stride..], &src[(y + 1) * stride..], w.wt, t);
        b1 += s1 as i64;
        b2 += s2 as i64;
    }
    (b1, b2)
}

/// (Σ diff·ix, Σ diff·iy, Σ |diff|) over the window `w` of the second image's
/// `block`.
#[inline(always)]
fn mismatch_window(block: (&[u8], usize), w: Window, (iv, ix, iy): Tmpl) -> (i64, i64, i64) {
    let ((src, stride), wp) = (block, padded(w.win));
    let (mut b1, mut b2, mut e) = (0i64, 0i64, 0i64);
    for y in 0..w.win {
        let r = y * wp..y * wp + w.win;
        let t = (&iv[r.clone()], &ix[r.clone()], &iy[r]);
        let (s1, s2, s3) = mismatch_row(&src[y * stride..], &src[(y + 1) * stride..], w.wt, t);
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
    // The padding covers the template's blocks (`deriv_cols` + 2 wide, from one
    // pixel left of a window that starts at most `win` left of the level).
    let pad = deriv_cols(win) + 1;
    let (mut li, mut lj) = (vec![Level::new(prev, pad)], vec![Level::new(next, pad)]);
    let (mut a, mut b): (Option<GrayImage>, Option<GrayImage>) = (None, None);
    while li.len() <= params.max_level {
        let na = pyr_down_gray(a.as_ref().unwrap_or(prev));
        let nb = pyr_down_gray(b.as_ref().unwrap_or(next));
        if na.width as usize <= win || na.height as usize <= win {
            break;
        }
        li.push(Level::new(&na, pad));
        lj.push(Level::new(&nb, pad));
        (a, b) = (Some(na), Some(nb));
    }
    track(&li, &lj, points, params, win)
}

multiversion! {
    fn track(li: &[Level], lj: &[Level], points: &[(f32, f32)], params: &LkParams, win: usize) -> Vec<TrackedPoint> {
    let max_level = li.len() - 1;
    #[cfg(target_arch = "x86_64")]
    let avx2 = std::arch::is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    let avx2 = false;
    let half = (win as f32 - 1.0) * 0.5;
    let eps2 = params.epsilon.clamp(0.0, 10.0).powi(2);
    const FLT_SCALE: f32 = 1.0 / (1 << 20) as f32;
    let area = win * win;
    let mut s = Scratch::new(win);
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
            let sc = 1.0 / (1u32 << lvl) as f32;
            let mut prev_pt = (pt.0 * sc, pt.1 * sc);
            next_pt = if lvl == max_level {
                prev_pt
            } else {
                (next_pt.0 * 2.0, next_pt.1 * 2.0)
            };
            prev_pt = (prev_pt.0 - half, prev_pt.1 - half);
            let w = Window::at(prev_pt, win);
            // Lost at the finest level only; a coarser level is skipped.
            let lose = lvl == 0;
            if !inside(w.p, li) {
                res.found &= !lose;
                continue;
            }
            let (a11, a12, a22) = template_window(li, w, &mut s, avx2);
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
            let tmpl = (&s.iv[..], &s.ix[..], &s.iy[..]);
            for j in 0..params.max_iter.min(100) {
                let w = Window::at(next_pt, win);
                if !inside(w.p, lj) {
                    res.found &= !lose;
                    break;
                }
                // A plain fn, not a closure: closures do not inherit the AVX2 target
                // feature of `track`, and this is the hot loop.
                let block = lj.block(w.p);
                let (b1, b2) = gradient_window(block, w, tmpl, avx2);
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
                let w = Window::at(result, win);
                if !inside(w.p, lj) {
                    res.found = false;
                } else {
                    let block = lj.block(w.p);
                    let (_, _, e) = mismatch_window(block, w, tmpl);
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

    /// The AVX2 template rows give the portable kernel's integers, on random rows
    /// with derivatives at Scharr's extremes and random bilinear weights.
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
            }
        }
    }

    /// The AVX2 iteration sums over a whole window give the portable rows' sums:
    /// random windows, and windows where every product is at its extreme
    /// (|diff| = 8160, |ix| = |iy| = 4080), whose sums need i64.
    #[test]
    fn avx2_window_sums_match_portable_rows() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut seed = 777u32;
        let mut rnd = move || {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            seed >> 8
        };
        for win in [3usize, 5, 8, 21, 31, 51] {
            let (n, stride) = (padded(win), padded(win) + 5);
            for case in 0..20 {
                let extreme = case < 2;
                // Extremes: image 255 against a template of 0, or 0 against 8160.
                let img: Vec<u8> = (0..(win + 1) * stride)
                    .map(|_| {
                        if extreme {
                            255 * (1 - case as u8)
                        } else {
                            rnd() as u8
                        }
                    })
                    .collect();
                let mut t: [Vec<i32>; 3] = std::array::from_fn(|_| vec![0; win * n]);
                for y in 0..win {
                    for x in 0..win {
                        let k = y * n + x;
                        if extreme {
                            (t[0][k], t[1][k], t[2][k]) = (8160 * case, 4080, -4080);
                        } else {
                            t[0][k] = (rnd() % 8161) as i32;
                            t[1][k] = (rnd() % 8161) as i32 - 4080;
                            t[2][k] = (rnd() % 8161) as i32 - 4080;
                        }
                    }
                }
                let wt = if extreme {
                    [1 << 14, 0, 0, 0]
                } else {
                    weights(
                        (rnd() % 1000) as f32 / 1000.0,
                        (rnd() % 1000) as f32 / 1000.0,
                    )
                };
                let w = Window { p: (0, 0), wt, win };
                let tm = (&t[0][..], &t[1][..], &t[2][..]);
                let portable = gradient_window((&img, stride), w, tm, false);
                let vector = gradient_window((&img, stride), w, tm, true);
                assert_eq!(portable, vector, "win {win} case {case}");
                if extreme {
                    let sum = (win * win * 8160 * 4080) as i64;
                    let sign = 1 - 2 * case as i64;
                    assert_eq!(portable, (sign * sum, -sign * sum), "win {win}");
                }
            }
        }
    }

    /// Scharr over the whole image straight from its definition: reflect 101 at
    /// the borders, 0 outside the image.
    fn scharr_reference(img: &[u8], w: usize, h: usize, x: i32, y: i32) -> (i16, i16) {
        if x < 0 || y < 0 || x >= w as i32 || y >= h as i32 {
            return (0, 0);
        }
        let p = |dx: i32, dy: i32| {
            let (sx, sy) = (
                reflect101((x + dx) as isize, w),
                reflect101((y + dy) as isize, h),
            );
            img[sy * w + sx] as i16
        };
        let gx =
            3 * (p(1, -1) + p(1, 1)) + 10 * p(1, 0) - 3 * (p(-1, -1) + p(-1, 1)) - 10 * p(-1, 0);
        let gy =
            3 * (p(-1, 1) + p(1, 1)) + 10 * p(0, 1) - 3 * (p(-1, -1) + p(1, -1)) - 10 * p(0, -1);
        (gx, gy)
    }

    /// A window's derivatives (computed per window on the padded level) are the
    /// whole image's Scharr derivatives, inside the image, at its borders and past
    /// them, for windows anywhere `track` keeps them.
    #[test]
    fn window_derivatives_are_the_image_derivatives() {
        let mut seed = 99u32;
        let mut rnd = move || {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            seed >> 8
        };
        let win = 21;
        for (w, h) in [(40usize, 30usize), (23, 64), (97, 41)] {
            let img: Vec<u8> = (0..w * h).map(|_| rnd() as u8).collect();
            let g = GrayImage {
                width: w as u32,
                height: h as u32,
                data: img.clone(),
            };
            let level = Level::new(&g, deriv_cols(win) + 1);
            let (cols, rows) = (deriv_cols(win), win + 1);
            let (mut dx, mut dy) = (vec![0i16; cols * rows], vec![0i16; cols * rows]);
            for _ in 0..60 {
                let p = (
                    (rnd() % (w + win) as u32) as i32 - win as i32,
                    (rnd() % (h + win) as u32) as i32 - win as i32,
                );
                let wnd = Window {
                    p,
                    wt: [1 << 14, 0, 0, 0],
                    win,
                };
                let block = level.block((p.0 - 1, p.1 - 1));
                window_derivs(&level, wnd, block, (&mut dx, &mut dy));
                for y in 0..rows {
                    for x in 0..cols {
                        let want = scharr_reference(&img, w, h, p.0 + x as i32, p.1 + y as i32);
                        let got = (dx[y * cols + x], dy[y * cols + x]);
                        assert_eq!(got, want, "{w}x{h} window {p:?} at ({x}, {y})");
                    }
                }
            }
        }
    }
}
