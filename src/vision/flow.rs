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
    let mut img = vec![0u8; stride * rows];
    for py in 0..rows {
        let sy = reflect101(py as isize - pad as isize, h);
        let s = &src.data[sy * w..(sy + 1) * w];
        let d = &mut img[py * stride..(py + 1) * stride];
        d[pad..pad + w].copy_from_slice(s);
        for i in 0..pad {
            d[i] = s[reflect101(i as isize - pad as isize, w)];
            d[pad + w + i] = s[reflect101((w + i) as isize, w)];
        }
    }
    let (mut dx, mut dy) = (Vec::new(), Vec::new());
    if derivs {
        dx = vec![0i16; stride * rows];
        dy = vec![0i16; stride * rows];
        let mut t0 = vec![0i16; w + 2];
        let mut t1 = vec![0i16; w + 2];
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
            let o = (y + pad) * stride + pad;
            let (ox, oy) = (&mut dx[o..o + w], &mut dy[o..o + w]);
            scharr_h(&t0, &t1, ox, oy);
        }
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

/// Bilinear samples of one window row in 1/32 grey levels.
#[inline(always)]
fn sample_row(r0: &[u8], r1: &[u8], wt: [i32; 4], out: &mut [i32]) {
    let n = out.len();
    let (a, b) = (&r0[..n + 1], &r1[..n + 1]);
    for x in 0..n {
        let v = a[x] as i32 * wt[0]
            + a[x + 1] as i32 * wt[1]
            + b[x] as i32 * wt[2]
            + b[x + 1] as i32 * wt[3];
        out[x] = (v + (1 << 8)) >> 9;
    }
}

#[inline(always)]
fn deriv_row(r0: &[i16], r1: &[i16], wt: [i32; 4], out: &mut [i32]) {
    let n = out.len();
    let (a, b) = (&r0[..n + 1], &r1[..n + 1]);
    for x in 0..n {
        let v = a[x] as i32 * wt[0]
            + a[x + 1] as i32 * wt[1]
            + b[x] as i32 * wt[2]
            + b[x + 1] as i32 * wt[3];
        out[x] = (v + (1 << 13)) >> 14;
    }
}

/// (Σ diff·ix, Σ diff·iy, Σ |diff|) of one window row.
#[inline(always)]
fn mismatch_row(
    r0: &[u8],
    r1: &[u8],
    wt: [i32; 4],
    iv: &[i32],
    ix: &[i32],
    iy: &[i32],
) -> (i32, i32, i32) {
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

/// (Σ diff·ix, Σ diff·iy, Σ |diff|) over the window at `p` (top-left, unpadded) of `lj`.
#[inline(always)]
fn mismatch_window(
    lj: &Level,
    p: (i32, i32),
    wt: [i32; 4],
    win: usize,
    pad: usize,
    tmpl: (&[i32], &[i32], &[i32]),
) -> (i64, i64, i64) {
    let (iv, ix, iy) = tmpl;
    let (mut b1, mut b2, mut e) = (0i64, 0i64, 0i64);
    for y in 0..win {
        let o = (p.1 + pad as i32 + y as i32) as usize * lj.stride + (p.0 + pad as i32) as usize;
        let r = y * win..(y + 1) * win;
        let (s1, s2, s3) = mismatch_row(
            &lj.img[o..],
            &lj.img[o + lj.stride..],
            wt,
            &iv[r.clone()],
            &ix[r.clone()],
            &iy[r],
        );
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
    let pad = win + 1;
    let mut pi = vec![prev.clone()];
    let mut pj = vec![next.clone()];
    while pi.len() <= params.max_level {
        let (a, b) = (
            pyr_down_gray(pi.last().expect("level")),
            pyr_down_gray(pj.last().expect("level")),
        );
        if a.width as usize <= win || a.height as usize <= win {
            break;
        }
        pi.push(a);
        pj.push(b);
    }
    let li: Vec<Level> = pi.iter().map(|g| level(g, pad, true)).collect();
    let lj: Vec<Level> = pj.iter().map(|g| level(g, pad, false)).collect();
    track(&li, &lj, points, params, win, pad)
}

multiversion! {
    fn track(li: &[Level], lj: &[Level], points: &[(f32, f32)], params: &LkParams, win: usize, pad: usize) -> Vec<TrackedPoint> {
    let max_level = li.len() - 1;
    let half = (win as f32 - 1.0) * 0.5;
    let eps2 = params.epsilon.clamp(0.0, 10.0).powi(2);
    const FLT_SCALE: f32 = 1.0 / (1 << 20) as f32;
    let area = win * win;
    let (mut iv, mut ix, mut iy) = (vec![0i32; area], vec![0i32; area], vec![0i32; area]);
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
            let ip = (prev_pt.0.floor() as i32, prev_pt.1.floor() as i32);
            if !inside(ip, li) {
                if lvl == 0 {
                    res.found = false;
                }
                continue;
            }
            let wt = weights(prev_pt.0 - ip.0 as f32, prev_pt.1 - ip.1 as f32);
            let (mut a11, mut a12, mut a22) = (0i64, 0i64, 0i64);
            for y in 0..win {
                let o = (ip.1 + pad as i32 + y as i32) as usize * li.stride + (ip.0 + pad as i32) as usize;
                let r = y * win..(y + 1) * win;
                sample_row(&li.img[o..], &li.img[o + li.stride..], wt, &mut iv[r.clone()]);
                deriv_row(&li.dx[o..], &li.dx[o + li.stride..], wt, &mut ix[r.clone()]);
                deriv_row(&li.dy[o..], &li.dy[o + li.stride..], wt, &mut iy[r.clone()]);
                let (rx, ry) = (&ix[r.clone()], &iy[r]);
                a11 += rx.iter().map(|v| (v * v) as i64).sum::<i64>();
                a12 += rx.iter().zip(ry).map(|(a, b)| (a * b) as i64).sum::<i64>();
                a22 += ry.iter().map(|v| (v * v) as i64).sum::<i64>();
            }
            let (a11, a12, a22) = (
                a11 as f32 * FLT_SCALE,
                a12 as f32 * FLT_SCALE,
                a22 as f32 * FLT_SCALE,
            );
            let d = a11 * a22 - a12 * a12;
            let min_eig = (a22 + a11 - ((a11 - a22) * (a11 - a22) + 4.0 * a12 * a12).sqrt())
                / (2.0 * area as f32);
            if min_eig < params.min_eig_threshold || d < f32::EPSILON {
                if lvl == 0 {
                    res.found = false;
                }
                continue;
            }
            let d = 1.0 / d;
            next_pt = (next_pt.0 - half, next_pt.1 - half);
            let mut prev_delta = (0f32, 0f32);
            let mut result = next_pt;
            for j in 0..params.max_iter.min(100) {
                let inp = (next_pt.0.floor() as i32, next_pt.1.floor() as i32);
                if !inside(inp, lj) {
                    if lvl == 0 {
                        res.found = false;
                    }
                    break;
                }
                let wt = weights(next_pt.0 - inp.0 as f32, next_pt.1 - inp.1 as f32);
                // A plain fn, not a closure: closures do not inherit the AVX2 target
                // feature of `track`, and this is the hot loop.
                let (b1, b2, _) = mismatch_window(lj, inp, wt, win, pad, (&iv, &ix, &iy));
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
                let p = (result.0.floor() as i32, result.1.floor() as i32);
                if !inside(p, lj) {
                    res.found = false;
                } else {
                    let wt = weights(result.0 - p.0 as f32, result.1 - p.1 as f32);
                    let (_, _, e) = mismatch_window(lj, p, wt, win, pad, (&iv, &ix, &iy));
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
