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

multiversion! {
    fn warp_row(src: &[u8], size: (i32, i32), pos: (&[i32], &[i32], &[f32], &[f32]), dst: &mut [u8]) {
        let ((sw, sh), (ix, iy, fx, fy)) = (size, pos);
        const CN: usize = 3;
        let stride = sw as usize * CN;
        for (i, d) in dst.chunks_exact_mut(CN).enumerate() {
            let (x0, y0, a, b) = (ix[i], iy[i], fx[i], fy[i]);
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
                d.fill(0);
                continue;
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
    if img.width < 1 || img.height < 1 || img.width > i32::MAX as u32 / 4 {
        return out;
    }
    let m: [f64; 9] = std::array::from_fn(|i| inv[(i / 3, i % 3)]);
    let (sw, sh) = (img.width as i32, img.height as i32);
    let ow = width as usize;
    let (mut ix, mut iy) = (vec![0i32; ow], vec![0i32; ow]);
    let (mut fx, mut fy) = (vec![0f32; ow], vec![0f32; ow]);
    for y in 0..height as usize {
        map_row(&m, y as f64, &mut ix, &mut iy, &mut fx, &mut fy);
        let dst = &mut out.data[y * ow * 3..(y + 1) * ow * 3];
        warp_row(&img.data, (sw, sh), (&ix, &iy, &fx, &fy), dst);
    }
    out
}
