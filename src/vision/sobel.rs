//! Sobel 3x3 derivatives and the Canny edge detector, with OpenCV's definitions.

use super::{Border, Gray16, GrayImage, multiversion, valid_len};

multiversion! {
    fn sobel_rows(a: &[u8], b: &[u8], c: &[u8], sm: &mut [i16], df: &mut [i16]) {
        // The row's vertical smoothing [1 2 1] and difference [-1 0 1], into
        // sm[1..=w], df[1..=w] (the caller fills the one-element borders).
        let w = sm.len() - 2;
        let (a, b, c) = (&a[..w], &b[..w], &c[..w]);
        let sm = &mut sm[1..w + 1];
        let df = &mut df[1..w + 1];
        for i in 0..w {
            sm[i] = a[i] as i16 + 2 * b[i] as i16 + c[i] as i16;
            df[i] = c[i] as i16 - a[i] as i16;
        }
    }
}

multiversion! {
    fn sobel_h(sm: &[i16], df: &[i16], dx: &mut [i16], dy: &mut [i16]) {
        let w = dx.len();
        let (s0, s2) = (&sm[..w], &sm[2..w + 2]);
        let (d0, d1, d2) = (&df[..w], &df[1..w + 1], &df[2..w + 2]);
        let dy = &mut dy[..w];
        for i in 0..w {
            dx[i] = s2[i] - s0[i];
            dy[i] = d0[i] + 2 * d1[i] + d2[i];
        }
    }
}

/// Both 3x3 Sobel derivatives of a grey image (`dx`: columns, `dy`: rows), as
/// OpenCV's `Sobel(src, CV_16S, 1, 0, 3)` and `Sobel(src, CV_16S, 0, 1, 3)` with
/// `BORDER_REFLECT_101`.
pub fn sobel(img: &GrayImage) -> (Gray16, Gray16) {
    sobel_with_border(img, Border::Reflect101)
}

/// [`sobel`] with another border rule.
pub fn sobel_with_border(img: &GrayImage, border: Border) -> (Gray16, Gray16) {
    let (w, h) = (img.width as usize, img.height as usize);
    if !valid_len(img.width, img.height, 1, img.data.len()) || w == 0 || h == 0 {
        return (Gray16::default(), Gray16::default());
    }
    // Outputs are filled row by row without zero-initialising them first.
    let (mut ox, mut oy) = (Vec::with_capacity(w * h), Vec::with_capacity(w * h));
    let (mut rx, mut ry) = (vec![0i16; w], vec![0i16; w]);
    let mut rows = SobelRows::new(img, border);
    for y in 0..h {
        rows.row(y, &mut rx, &mut ry);
        ox.extend_from_slice(&rx);
        oy.extend_from_slice(&ry);
    }
    let image = |data| Gray16 {
        width: img.width,
        height: img.height,
        data,
    };
    (image(ox), image(oy))
}

/// The Sobel derivatives one row at a time, for whole images ([`sobel`]) and for
/// Canny's rolling three-row window. `img` must be valid and non-empty.
struct SobelRows<'a> {
    img: &'a GrayImage,
    border: Border,
    /// Vertical smoothing and difference of the current row, with one element of
    /// border on each side.
    sm: Vec<i16>,
    df: Vec<i16>,
}

impl<'a> SobelRows<'a> {
    fn new(img: &'a GrayImage, border: Border) -> Self {
        let w = img.width as usize;
        SobelRows {
            img,
            border,
            sm: vec![0; w + 2],
            df: vec![0; w + 2],
        }
    }

    /// Row `y` of dx (columns) and dy (rows).
    fn row(&mut self, y: usize, dx: &mut [i16], dy: &mut [i16]) {
        let (w, h) = (self.img.width as usize, self.img.height as usize);
        let row = |y: isize| {
            let y = self.border.index(y, h);
            &self.img.data[y * w..(y + 1) * w]
        };
        let y = y as isize;
        sobel_rows(row(y - 1), row(y), row(y + 1), &mut self.sm, &mut self.df);
        let (l, r) = (self.border.index(-1, w), self.border.index(w as isize, w));
        self.sm[0] = self.sm[l + 1];
        self.df[0] = self.df[l + 1];
        self.sm[w + 1] = self.sm[r + 1];
        self.df[w + 1] = self.df[r + 1];
        sobel_h(&self.sm, &self.df, dx, dy);
    }
}

const CANNY_SHIFT: i32 = 15;
const TG22: i32 = 13573; // round(tan(22.5°) · 2^15)

multiversion! {
    fn magnitude(dx: &[i16], dy: &[i16], mag: &mut [i32], l2: bool) {
        let n = mag.len();
        let (dx, dy) = (&dx[..n], &dy[..n]);
        if l2 {
            for i in 0..n {
                let (a, b) = (dx[i] as i32, dy[i] as i32);
                mag[i] = a * a + b * b;
            }
        } else {
            for i in 0..n {
                mag[i] = (dx[i] as i32).abs() + (dy[i] as i32).abs();
            }
        }
    }
}

multiversion! {
    /// Non-maximum suppression of one row, without branches so that it runs as
    /// vector code (the gradient directions of a textured photograph are
    /// unpredictable): `map[x]` = 2 (local maximum above `high`), 0 (local maximum
    /// above `low`: a candidate) or 1 (not an edge). `prev`, `cur`, `next` are the
    /// magnitudes of rows y - 1, y, y + 1 (`mags`) with one element of border at each end.
    fn suppress_row(
        mags: [&[i32]; 3],
        dx: &[i16],
        dy: &[i16],
        low: i32,
        high: i32,
        map: &mut [u8],
    ) {
        let w = map.len();
        let [prev, cur, next] = mags;
        let (dx, dy) = (&dx[..w], &dy[..w]);
        let (p0, p1, p2) = (&prev[..w], &prev[1..w + 1], &prev[2..w + 2]);
        let (c0, c1, c2) = (&cur[..w], &cur[1..w + 1], &cur[2..w + 2]);
        let (n0, n1, n2) = (&next[..w], &next[1..w + 1], &next[2..w + 2]);
        for x in 0..w {
            let m = c1[x];
            let (xs, ys) = (dx[x] as i32, dy[x] as i32);
            let ax = xs.abs();
            let ay = ys.abs() << CANNY_SHIFT;
            let tg22x = ax * TG22;
            let tg67x = tg22x + (ax << (CANNY_SHIFT + 1));
            let (horizontal, vertical) = (ay < tg22x, ay > tg67x);
            let diagonal = !horizontal & !vertical;
            // Along a diagonal the column step down is -1 when dx and dy have
            // opposite signs: up-right and down-left, else up-left and down-right.
            let opposite = (xs ^ ys) < 0;
            // Every neighbour is loaded and the pair chosen by bit masks: a select
            // of loads would become a select of addresses (gathered, slow).
            let blend = |c: bool, a: i32, b: i32| {
                let k = -(c as i32);
                (a & k) | (b & !k)
            };
            let (q0, q1, q2) = (p0[x], p1[x], p2[x]);
            let (m0, m2) = (c0[x], c2[x]);
            let (r0, r1, r2) = (n0[x], n1[x], n2[x]);
            let up = blend(vertical, q1, blend(opposite, q2, q0));
            let down = blend(vertical, r1, blend(opposite, r0, r2));
            let before = blend(horizontal, m0, up);
            let after = blend(horizontal, m2, down);
            // OpenCV's ties: strict on the first neighbour, and on the second too
            // along a diagonal.
            let is_max =
                (m > low) & (m > before) & ((m > after) | ((m == after) & !diagonal));
            let strong = (m > high) as u8;
            map[x] = if is_max { 2 * strong } else { 1 };
        }
    }
}

multiversion! {
    /// Bit k of `mask[c]`: `row[32c + k] == 2` (32 comparisons a word, which the
    /// compiler turns into vector compares).
    fn strong_mask(row: &[u8], mask: &mut [u32]) {
        for (m, c) in mask.iter_mut().zip(row.chunks(32)) {
            *m = c
                .iter()
                .enumerate()
                .fold(0, |bits, (k, &v)| bits | (((v == 2) as u32) << k));
        }
    }
}

/// Canny's rolling window: slot `r % 3` holds row r's derivatives and magnitudes
/// (with a zero element at each end).
struct Window {
    dx: [Vec<i16>; 3],
    dy: [Vec<i16>; 3],
    mag: [Vec<i32>; 3],
}

impl Window {
    fn new(w: usize) -> Self {
        Window {
            dx: std::array::from_fn(|_| vec![0; w]),
            dy: std::array::from_fn(|_| vec![0; w]),
            mag: std::array::from_fn(|_| vec![0; w + 2]),
        }
    }

    /// Computes row `y` into its slot.
    fn fill(&mut self, y: usize, sobel: &mut SobelRows, l2: bool) {
        let k = y % 3;
        let w = self.dx[k].len();
        sobel.row(y, &mut self.dx[k], &mut self.dy[k]);
        magnitude(&self.dx[k], &self.dy[k], &mut self.mag[k][1..=w], l2);
    }
}

/// Canny edges (255 = edge) of a grey image, as OpenCV's `Canny(img, low, high, 3,
/// l2)`: 3x3 Sobel with `BORDER_REPLICATE`, L1 (`|dx|+|dy|`, OpenCV's default) or L2
/// magnitude, non-maximum suppression in 4 directions, hysteresis with 8-connected
/// neighbours. 4.3's opencvdemo used `low = 50`, `high = 150`.
pub fn canny(img: &GrayImage, low: f64, high: f64, l2: bool) -> GrayImage {
    let (w, h) = (img.width as usize, img.height as usize);
    if !valid_len(img.width, img.height, 1, img.data.len()) || w == 0 || h == 0 {
        return GrayImage::default();
    }
    let (mut low, mut high) = (low.max(0.0), high.max(0.0));
    if low > high {
        std::mem::swap(&mut low, &mut high);
    }
    if l2 {
        low = low.min(32767.0);
        high = high.min(32767.0);
        low *= low;
        high *= high;
    }
    let (low, high) = (low.floor() as i32, high.floor() as i32);
    // A rolling window of three rows (y - 1, y, y + 1), so nothing image-sized but
    // the map is written. The rows above the first and below the last are zeros, as
    // OpenCV's.
    let mw = w + 2;
    let mut sobel = SobelRows::new(img, Border::Replicate);
    let mut win = Window::new(w);
    let zeros = vec![0i32; mw];
    win.fill(0, &mut sobel, l2);
    // Map: 0 = candidate (weak local maximum), 1 = not an edge, 2 = edge. One-pixel
    // border of 1s.
    let mut map = vec![1u8; mw * (h + 2)];
    let mut stack: Vec<usize> = Vec::with_capacity(w * h / 8);
    // Bit k of strong[c]: pixel 32c + k of the row was marked 2 (to be pushed).
    let mut strong = vec![0u32; w.div_ceil(32)];
    for y in 0..h {
        if y + 1 < h {
            win.fill(y + 1, &mut sobel, l2);
        }
        let prev = if y > 0 { &win.mag[(y - 1) % 3] } else { &zeros };
        let next = if y + 1 < h {
            &win.mag[(y + 1) % 3]
        } else {
            &zeros
        };
        let (cur, dxr, dyr) = (&win.mag[y % 3], &win.dx[y % 3], &win.dy[y % 3]);
        let base = (y + 1) * mw + 1;
        let row = &mut map[base..base + w];
        suppress_row([prev, cur, next], dxr, dyr, low, high, row);
        strong_mask(row, &mut strong);
        for (c, &bits) in strong.iter().enumerate() {
            let mut bits = bits;
            while bits != 0 {
                stack.push(base + c * 32 + bits.trailing_zeros() as usize);
                bits &= bits - 1;
            }
        }
    }
    hysteresis(&mut map, stack, w, h)
}

/// Canny's last step: grows the edges on `stack` into 8-connected candidates of
/// `map` (0 = candidate, 1 = not an edge, 2 = edge; one-pixel border of 1s around a
/// `w` x `h` image) and returns the edges as 255s.
fn hysteresis(map: &mut [u8], mut stack: Vec<usize>, w: usize, h: usize) -> GrayImage {
    let mw = w + 2;
    while let Some(j) = stack.pop() {
        for k in [
            j - mw - 1,
            j - mw,
            j - mw + 1,
            j - 1,
            j + 1,
            j + mw - 1,
            j + mw,
            j + mw + 1,
        ] {
            if map[k] == 0 {
                map[k] = 2;
                stack.push(k);
            }
        }
    }
    let mut out = GrayImage::new(w as u32, h as u32);
    for y in 0..h {
        let src = &map[(y + 1) * mw + 1..(y + 1) * mw + 1 + w];
        for (d, &s) in out.data[y * w..(y + 1) * w].iter_mut().zip(src) {
            *d = if s == 2 { 255 } else { 0 };
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Canny as it reads in OpenCV's scalar code: whole-image Sobel and magnitudes,
    /// then suppression with branches, then hysteresis.
    fn canny_reference(img: &GrayImage, low: i32, high: i32, l2: bool) -> Vec<u8> {
        let (w, h) = (img.width as usize, img.height as usize);
        let (dx, dy) = sobel_with_border(img, Border::Replicate);
        let mw = w + 2;
        let mut mag = vec![0i32; mw * (h + 2)];
        for y in 0..h {
            for x in 0..w {
                let (a, b) = (dx.data[y * w + x] as i32, dy.data[y * w + x] as i32);
                mag[(y + 1) * mw + x + 1] = if l2 { a * a + b * b } else { a.abs() + b.abs() };
            }
        }
        let mut map = vec![1u8; mw * (h + 2)];
        let mut stack = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let j = (y + 1) * mw + x + 1;
                let m = mag[j];
                if m <= low {
                    continue;
                }
                let (xs, ys) = (dx.data[y * w + x] as i32, dy.data[y * w + x] as i32);
                let ax = xs.abs();
                let ay = ys.abs() << CANNY_SHIFT;
                let tg22x = ax * TG22;
                let tg67x = tg22x + (ax << (CANNY_SHIFT + 1));
                let is_max = if ay < tg22x {
                    m > mag[j - 1] && m >= mag[j + 1]
                } else if ay > tg67x {
                    m > mag[j - mw] && m >= mag[j + mw]
                } else {
                    let s: isize = if (xs ^ ys) < 0 { -1 } else { 1 };
                    m > mag[(j - mw).wrapping_add_signed(-s)]
                        && m > mag[(j + mw).wrapping_add_signed(s)]
                };
                if is_max {
                    if m > high {
                        map[j] = 2;
                        stack.push(j);
                    } else {
                        map[j] = 0;
                    }
                }
            }
        }
        hysteresis(&mut map, stack, w, h).data
    }

    /// A smooth pattern with noise and sharp steps: edges in every direction.
    fn scene(w: usize, h: usize, seed: u32) -> GrayImage {
        let mut s = seed;
        let data = (0..w * h)
            .map(|i| {
                s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let wave = 100.0 * ((x * 0.21).sin() * (y * 0.13).cos());
                let step = if (x - 0.7 * y).rem_euclid(23.0) < 11.0 {
                    60.0
                } else {
                    0.0
                };
                (120.0 + wave + step + (s >> 28) as f32).clamp(0.0, 255.0) as u8
            })
            .collect();
        GrayImage {
            width: w as u32,
            height: h as u32,
            data,
        }
    }

    #[test]
    fn canny_matches_the_plain_algorithm() {
        for (w, h) in [
            (1, 1),
            (1, 9),
            (9, 1),
            (2, 2),
            (31, 7),
            (33, 17),
            (64, 48),
            (97, 61),
        ] {
            for (k, (low, high, l2)) in [
                (50.0, 150.0, false),
                (10.0, 40.0, false),
                (20.0, 60.0, true),
            ]
            .into_iter()
            .enumerate()
            {
                let img = scene(w, h, (w * 31 + h + k) as u32);
                let (lo, hi) = if l2 {
                    ((low * low) as i32, (high * high) as i32)
                } else {
                    (low as i32, high as i32)
                };
                let got = canny(&img, low, high, l2);
                let want = canny_reference(&img, lo, hi, l2);
                assert_eq!(got.data, want, "{w}x{h} low {low} high {high} l2 {l2}");
                if w * h > 1000 {
                    assert!(want.contains(&255), "{w}x{h}: the scene has edges");
                }
            }
        }
    }
}
