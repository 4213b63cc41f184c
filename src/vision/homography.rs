//! Planar homographies for imgrectifier: estimation from point pairs and warping.

use nalgebra::{DMatrix, Matrix3, SMatrix, SymmetricEigen};

use super::{is_valid, multiversion};
use crate::interfaces::Image;

/// Hartley normalisation: translate the centroid to 0, scale the mean distance to √2.
fn normalisation(p: &[(f64, f64)]) -> Matrix3<f64> {
    let n = p.len() as f64;
    let (cx, cy) = p.iter().fold((0.0, 0.0), |(a, b), q| (a + q.0, b + q.1));
    let (cx, cy) = (cx / n, cy / n);
    let d = p
        .iter()
        .map(|q| ((q.0 - cx).powi(2) + (q.1 - cy).powi(2)).sqrt())
        .sum::<f64>()
        / n;
    let s = if d > 0.0 {
        std::f64::consts::SQRT_2 / d
    } else {
        1.0
    };
    Matrix3::new(s, 0.0, -s * cx, 0.0, s, -s * cy, 0.0, 0.0, 1.0)
}

/// The homography `H` (normalised so `H[2][2] = 1`) with `dst ~ H·src`, from 4 or
/// more point pairs (pixels), by the normalised DLT: the least-squares solution of
/// the 2n equations (smallest eigenvector of AᵀA). With 4 pairs it is exact
/// (imgrectifier's case). `None` with fewer than 4 pairs, mismatched lengths,
/// non-finite input or a degenerate configuration (3 collinear points).
pub fn find_homography(src: &[(f64, f64)], dst: &[(f64, f64)]) -> Option<Matrix3<f64>> {
    if src.len() < 4 || src.len() != dst.len() {
        return None;
    }
    if src
        .iter()
        .chain(dst)
        .any(|p| !p.0.is_finite() || !p.1.is_finite())
    {
        return None;
    }
    let (ts, td) = (normalisation(src), normalisation(dst));
    let mut a = DMatrix::<f64>::zeros(2 * src.len(), 9);
    for (i, (s, d)) in src.iter().zip(dst).enumerate() {
        let ps = ts * nalgebra::Vector3::new(s.0, s.1, 1.0);
        let pd = td * nalgebra::Vector3::new(d.0, d.1, 1.0);
        let (x, y, u, v) = (ps.x, ps.y, pd.x, pd.y);
        let r0 = [x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y, -u];
        let r1 = [0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y, -v];
        for j in 0..9 {
            a[(2 * i, j)] = r0[j];
            a[(2 * i + 1, j)] = r1[j];
        }
    }
    let ata: SMatrix<f64, 9, 9> = SMatrix::from_iterator((a.transpose() * &a).iter().copied());
    let eig = SymmetricEigen::new(ata);
    let (imin, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let hv = eig.eigenvectors.column(imin);
    let hn = Matrix3::new(
        hv[0], hv[1], hv[2], hv[3], hv[4], hv[5], hv[6], hv[7], hv[8],
    );
    let h = td.try_inverse()? * hn * ts;
    // Degenerate configurations give a rank-deficient H.
    if h.determinant().abs() < 1e-12 * h.norm().powi(3) || h[(2, 2)].abs() < 1e-300 {
        return None;
    }
    let h = h / h[(2, 2)];
    h.iter().all(|v| v.is_finite()).then_some(h)
}

multiversion! {
    fn map_row(m: &[f64; 9], y: f64, ix: &mut [i32], iy: &mut [i32], fx: &mut [f32], fy: &mut [f32]) {
        // Source position of each destination pixel of row y in f32 with FMA, as
        // OpenCV 5's warpPerspective: x' = (m0·x + (m1·y + m2)) / (m6·x + (m7·y + m8)).
        let (m0, m3, m6) = (m[0] as f32, m[3] as f32, m[6] as f32);
        let (mx, my, mw) = ((y * m[1] + m[2]) as f32, (y * m[4] + m[5]) as f32, (y * m[7] + m[8]) as f32);
        let n = ix.len();
        let (iy, fx, fy) = (&mut iy[..n], &mut fx[..n], &mut fy[..n]);
        for i in 0..n {
            let x = i as f32;
            let w = m6.mul_add(x, mw);
            let sx = m0.mul_add(x, mx) / w;
            let sy = m3.mul_add(x, my) / w;
            let (flx, fly) = (sx.floor(), sy.floor());
            // Non-finite or huge positions land far outside (the border).
            let ok = sx.is_finite() & sy.is_finite() & (flx.abs() < 1e9) & (fly.abs() < 1e9);
            ix[i] = if ok { flx as i32 } else { i32::MIN / 2 };
            iy[i] = if ok { fly as i32 } else { i32::MIN / 2 };
            fx[i] = sx - flx;
            fy[i] = sy - fly;
        }
    }
}

/// One destination pixel from source position (x0 + a, y0 + b): f32 bilinear with
/// black outside the source, as OpenCV 5.
#[inline(always)]
fn warp_pixel(
    src: &[u8],
    (sw, sh): (i32, i32),
    (x0, y0, a, b): (i32, i32, f32, f32),
    d: &mut [u8],
) {
    const CN: usize = 3;
    let stride = sw as usize * CN;
    let mut p = [[0f32; CN]; 4];
    if x0 >= 0 && y0 >= 0 && x0 < sw - 1 && y0 < sh - 1 {
        let o = y0 as usize * stride + x0 as usize * CN;
        let (r0, r1) = (&src[o..o + 2 * CN], &src[o + stride..o + stride + 2 * CN]);
        for c in 0..CN {
            p[0][c] = r0[c] as f32;
            p[1][c] = r0[c + CN] as f32;
            p[2][c] = r1[c] as f32;
            p[3][c] = r1[c + CN] as f32;
        }
    } else if x0 >= sw || x0 + 1 < 0 || y0 >= sh || y0 + 1 < 0 {
        d[..CN].fill(0);
        return;
    } else {
        for (k, (dx, dy)) in [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate() {
            let (x, y) = (x0 + dx, y0 + dy);
            if x >= 0 && y >= 0 && x < sw && y < sh {
                let o = y as usize * stride + x as usize * CN;
                for c in 0..CN {
                    p[k][c] = src[o + c] as f32;
                }
            }
        }
    }
    for c in 0..CN {
        let v0 = a.mul_add(p[1][c] - p[0][c], p[0][c]);
        let v1 = a.mul_add(p[3][c] - p[2][c], p[2][c]);
        let v = b.mul_add(v1 - v0, v0);
        d[c] = v.round_ties_even().clamp(0.0, 255.0) as u8;
    }
}

multiversion! {
    fn warp_row(src: &[u8], size: (i32, i32), pos: (&[i32], &[i32], &[f32], &[f32]), dst: &mut [u8]) {
        let (ix, iy, fx, fy) = pos;
        for (i, d) in dst.chunks_exact_mut(3).enumerate() {
            warp_pixel(src, size, (ix[i], iy[i], fx[i], fy[i]), d);
        }
    }
}

/// AVX2 path of one destination row: the same f32 arithmetic as [`map_row`] and
/// [`warp_pixel`] (so the same bytes), 8 pixels at a time with gathered loads;
/// blocks that touch the border go through [`warp_pixel`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn warp_row_avx2(src: &[u8], (sw, sh): (i32, i32), m: &[f64; 9], y: f64, dst: &mut [u8]) {
    use std::arch::x86_64::*;
    let (m0, m3, m6) = (m[0] as f32, m[3] as f32, m[6] as f32);
    let (mx, my, mw) = (
        (y * m[1] + m[2]) as f32,
        (y * m[4] + m[5]) as f32,
        (y * m[7] + m[8]) as f32,
    );
    let n = dst.len() / 3;
    let lanes = _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0);
    let (vm0, vm3, vm6) = (_mm256_set1_ps(m0), _mm256_set1_ps(m3), _mm256_set1_ps(m6));
    let (vmx, vmy, vmw) = (_mm256_set1_ps(mx), _mm256_set1_ps(my), _mm256_set1_ps(mw));
    let big = _mm256_set1_ps(1e9);
    let abs = _mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX));
    let mut i = 0;
    while i < n {
        let x = _mm256_add_ps(_mm256_set1_ps(i as f32), lanes);
        let w = _mm256_fmadd_ps(vm6, x, vmw);
        let sx = _mm256_div_ps(_mm256_fmadd_ps(vm0, x, vmx), w);
        let sy = _mm256_div_ps(_mm256_fmadd_ps(vm3, x, vmy), w);
        let (flx, fly) = (_mm256_floor_ps(sx), _mm256_floor_ps(sy));
        let (a, b) = (_mm256_sub_ps(sx, flx), _mm256_sub_ps(sy, fly));
        // |floor| < 1e9 is false for NaN and infinities (map_row's `ok`).
        let ok = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_and_ps(flx, abs), big),
            _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_and_ps(fly, abs), big),
        );
        let (x0, y0) = (_mm256_cvttps_epi32(flx), _mm256_cvttps_epi32(fly));
        let inside = _mm256_and_si256(
            _mm256_and_si256(
                _mm256_cmpgt_epi32(x0, _mm256_set1_epi32(-1)),
                _mm256_cmpgt_epi32(_mm256_set1_epi32(sw - 1), x0),
            ),
            _mm256_and_si256(
                _mm256_cmpgt_epi32(y0, _mm256_set1_epi32(-1)),
                _mm256_cmpgt_epi32(_mm256_set1_epi32(sh - 1), y0),
            ),
        );
        let inside = _mm256_and_si256(inside, _mm256_castps_si256(ok));
        if i + 8 <= n && _mm256_movemask_ps(_mm256_castsi256_ps(inside)) == 0xff {
            warp8_inside(src, sw * 3, (x0, y0, a, b), &mut dst[3 * i..3 * i + 24]);
        } else {
            // Border block (or the row's tail): go pixel by pixel.
            let k = 8.min(n - i);
            let pos = (x0, y0, a, b, _mm256_movemask_ps(ok));
            warp8_border(src, (sw, sh), pos, &mut dst[3 * i..3 * (i + k)]);
        }
        i += 8;
    }
}

/// 8 destination pixels whose source squares all lie inside the source: gathered
/// loads, bilinear blend in f32 with FMA, 24 BGR bytes into `d`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn warp8_inside(
    src: &[u8],
    stride: i32,
    pos: (
        std::arch::x86_64::__m256i,
        std::arch::x86_64::__m256i,
        std::arch::x86_64::__m256,
        std::arch::x86_64::__m256,
    ),
    d: &mut [u8],
) {
    use std::arch::x86_64::*;
    let (x0, y0, a, b) = pos;
    let (zero, max) = (_mm256_setzero_ps(), _mm256_set1_ps(255.0));
    let byte = _mm256_set1_epi32(0xff);
    // Packs 4 pixels of 0x00RRGGBB per 128-bit lane into 12 BGR bytes.
    let pack = _mm256_setr_epi8(
        0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, -1, -1, -1, -1, 0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13,
        14, -1, -1, -1, -1,
    );
    // Offsets fit in i32 (checked by warp_perspective), and an inside block reads
    // at most up to (y0 + 1)·stride + 3·sw <= src.len().
    let base = src.as_ptr() as *const i32;
    let o = _mm256_add_epi32(
        _mm256_mullo_epi32(y0, _mm256_set1_epi32(stride)),
        _mm256_mullo_epi32(x0, _mm256_set1_epi32(3)),
    );
    let o1 = _mm256_add_epi32(o, _mm256_set1_epi32(stride));
    let two = _mm256_set1_epi32(2);
    // SAFETY: every lane is an inside pixel, so each 4-byte load lies in
    // src (the bound above): (x0, y0) at o, (x0+1, y0) at o+2 (shifted by a
    // byte), the next row at o1.
    let (g0, g1, g2, g3) = unsafe {
        (
            _mm256_i32gather_epi32::<1>(base, o),
            _mm256_srli_epi32::<8>(_mm256_i32gather_epi32::<1>(base, _mm256_add_epi32(o, two))),
            _mm256_i32gather_epi32::<1>(base, o1),
            _mm256_srli_epi32::<8>(_mm256_i32gather_epi32::<1>(base, _mm256_add_epi32(o1, two))),
        )
    };
    let channel = |g: __m256i, c: i32| {
        _mm256_cvtepi32_ps(_mm256_and_si256(
            _mm256_srl_epi32(g, _mm_cvtsi32_si128(8 * c)),
            byte,
        ))
    };
    let mut px = _mm256_setzero_si256();
    for c in 0..3 {
        let (p0, p1, p2, p3) = (
            channel(g0, c),
            channel(g1, c),
            channel(g2, c),
            channel(g3, c),
        );
        let v0 = _mm256_fmadd_ps(a, _mm256_sub_ps(p1, p0), p0);
        let v1 = _mm256_fmadd_ps(a, _mm256_sub_ps(p3, p2), p2);
        let v = _mm256_fmadd_ps(b, _mm256_sub_ps(v1, v0), v0);
        let v = _mm256_round_ps::<{ _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC }>(v);
        let v = _mm256_cvtps_epi32(_mm256_min_ps(_mm256_max_ps(v, zero), max));
        px = _mm256_or_si256(px, _mm256_sll_epi32(v, _mm_cvtsi32_si128(8 * c)));
    }
    let mut t = [0u8; 32];
    // SAFETY: t has 32 bytes.
    unsafe {
        _mm256_storeu_si256(
            t.as_mut_ptr() as *mut __m256i,
            _mm256_shuffle_epi8(px, pack),
        )
    };
    d[..12].copy_from_slice(&t[..12]);
    d[12..24].copy_from_slice(&t[16..28]);
}

/// Up to 8 destination pixels (as many as `d` holds) that touch the source's
/// border: spilled lanes through [`warp_pixel`]; lanes not set in the `ok` bit
/// mask are far outside.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn warp8_border(
    src: &[u8],
    size: (i32, i32),
    pos: (
        std::arch::x86_64::__m256i,
        std::arch::x86_64::__m256i,
        std::arch::x86_64::__m256,
        std::arch::x86_64::__m256,
        i32,
    ),
    d: &mut [u8],
) {
    use std::arch::x86_64::*;
    let (x0, y0, a, b, okm) = pos;
    let (mut ax, mut ay, mut fa, mut fb) = ([0i32; 8], [0i32; 8], [0f32; 8], [0f32; 8]);
    // SAFETY: each array has 8 lanes.
    unsafe {
        _mm256_storeu_si256(ax.as_mut_ptr() as *mut __m256i, x0);
        _mm256_storeu_si256(ay.as_mut_ptr() as *mut __m256i, y0);
        _mm256_storeu_ps(fa.as_mut_ptr(), a);
        _mm256_storeu_ps(fb.as_mut_ptr(), b);
    }
    for (k, px) in d.chunks_exact_mut(3).enumerate() {
        let (x, y) = if okm >> k & 1 == 1 {
            (ax[k], ay[k])
        } else {
            (i32::MIN / 2, i32::MIN / 2)
        };
        warp_pixel(src, size, (x, y, fa[k], fb[k]), px);
    }
}

/// Warps a BGR image by the homography `h` (source → destination pixels, as
/// OpenCV's `warpPerspective` without `WARP_INVERSE_MAP`) into a `width` x `height`
/// image: bilinear interpolation in f32 (OpenCV 5's definition), black outside the
/// source (`BORDER_CONSTANT` 0). A singular `h` gives a black image.
pub fn warp_perspective(img: &Image, h: &Matrix3<f64>, width: u32, height: u32) -> Image {
    let mut out = Image::new(width, height);
    let Some(inv) = h.try_inverse().filter(|_| is_valid(img)) else {
        return out;
    };
    if img.width < 1 || img.height < 1 || width == 0 || img.width > i32::MAX as u32 / 4 {
        return out;
    }
    let m: [f64; 9] = std::array::from_fn(|i| inv[(i / 3, i % 3)]);
    let (sw, sh) = (img.width as i32, img.height as i32);
    let ow = width as usize;
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
        && img.data.len() < i32::MAX as usize - 8
    {
        for (y, dst) in out.data.chunks_exact_mut(ow * 3).enumerate() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above).
            unsafe { warp_row_avx2(&img.data, (sw, sh), &m, y as f64, dst) };
        }
        return out;
    }
    let (mut ix, mut iy) = (vec![0i32; ow], vec![0i32; ow]);
    let (mut fx, mut fy) = (vec![0f32; ow], vec![0f32; ow]);
    for y in 0..height as usize {
        map_row(&m, y as f64, &mut ix, &mut iy, &mut fx, &mut fy);
        let dst = &mut out.data[y * ow * 3..(y + 1) * ow * 3];
        warp_row(&img.data, (sw, sh), (&ix, &iy, &fx, &fy), dst);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The portable path (map_row + warp_row), which non-AVX2 machines run.
    fn portable(img: &Image, h: &Matrix3<f64>, width: u32, height: u32) -> Image {
        let inv = h.try_inverse().expect("invertible");
        let m: [f64; 9] = std::array::from_fn(|i| inv[(i / 3, i % 3)]);
        let mut out = Image::new(width, height);
        let ow = width as usize;
        let (mut ix, mut iy) = (vec![0i32; ow], vec![0i32; ow]);
        let (mut fx, mut fy) = (vec![0f32; ow], vec![0f32; ow]);
        for y in 0..height as usize {
            map_row(&m, y as f64, &mut ix, &mut iy, &mut fx, &mut fy);
            let dst = &mut out.data[y * ow * 3..(y + 1) * ow * 3];
            let size = (img.width as i32, img.height as i32);
            warp_row(&img.data, size, (&ix, &iy, &fx, &fy), dst);
        }
        out
    }

    #[test]
    fn vector_path_matches_portable_path_across_borders() {
        let (w, h) = (37u32, 29u32);
        let mut img = Image::new(w, h);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = (i * 7919 % 251) as u8;
        }
        // Rotation + perspective: the output crosses every border of the source,
        // widths that are not multiples of 8 leave tails, and the last matrix maps
        // some pixels to infinity (w = 0 on a line).
        let hs = [
            Matrix3::new(0.9, -0.3, 4.5, 0.25, 0.95, -3.2, 0.001, -0.002, 1.0),
            Matrix3::new(1.7, 0.1, -9.0, -0.05, 1.4, -5.0, 0.0, 0.0, 1.0),
            Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.05, 0.0, 1.0),
        ];
        for hm in &hs {
            for (ow, oh) in [(45, 31), (8, 3), (5, 40)] {
                let got = warp_perspective(&img, hm, ow, oh);
                assert_eq!(got.data, portable(&img, hm, ow, oh).data, "{hm} {ow}x{oh}");
            }
        }
    }
}
