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
    let mut sm = vec![0i16; w + 2];
    let mut df = vec![0i16; w + 2];
    let row = |y: isize| {
        let y = border.index(y, h);
        &img.data[y * w..(y + 1) * w]
    };
    let (l, r) = (border.index(-1, w), border.index(w as isize, w));
    for y in 0..h {
        let yy = y as isize;
        sobel_rows(row(yy - 1), row(yy), row(yy + 1), &mut sm, &mut df);
        sm[0] = sm[l + 1];
        df[0] = df[l + 1];
        sm[w + 1] = sm[r + 1];
        df[w + 1] = df[r + 1];
        sobel_h(&sm, &df, &mut rx, &mut ry);
        ox.extend_from_slice(&rx);
        oy.extend_from_slice(&ry);
    }
    let (dx, dy) = (
        Gray16 {
            width: img.width,
            height: img.height,
            data: ox,
        },
        Gray16 {
            width: img.width,
            height: img.height,
            data: oy,
        },
    );
    (dx, dy)
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
    let (dx, dy) = sobel_with_border(img, Border::Replicate);
    // Magnitudes with a zero border of one pixel all around.
    let mw = w + 2;
    let mut mag = vec![0i32; mw * (h + 2)];
    for y in 0..h {
        let o = (y + 1) * mw + 1;
        magnitude(
            &dx.data[y * w..(y + 1) * w],
            &dy.data[y * w..(y + 1) * w],
            &mut mag[o..o + w],
            l2,
        );
    }
    // Map: 0 = candidate (weak local maximum), 1 = not an edge, 2 = edge. One-pixel
    // border of 1s.
    let mut map = vec![1u8; mw * (h + 2)];
    let mut stack: Vec<usize> = Vec::with_capacity(w * h / 8);
    for y in 0..h {
        let base = (y + 1) * mw + 1;
        let (dxr, dyr) = (&dx.data[y * w..(y + 1) * w], &dy.data[y * w..(y + 1) * w]);
        for x in 0..w {
            let j = base + x;
            let m = mag[j];
            if m <= low {
                continue;
            }
            let (xs, ys) = (dxr[x] as i32, dyr[x] as i32);
            let ax = xs.abs();
            let ay = ys.abs() << CANNY_SHIFT;
            let tg22x = ax * TG22;
            let is_max = if ay < tg22x {
                m > mag[j - 1] && m >= mag[j + 1]
            } else {
                let tg67x = tg22x + (ax << (CANNY_SHIFT + 1));
                if ay > tg67x {
                    m > mag[j - mw] && m >= mag[j + mw]
                } else {
                    let s: isize = if (xs ^ ys) < 0 { -1 } else { 1 };
                    m > mag[(j - mw).wrapping_add_signed(-s)]
                        && m > mag[(j + mw).wrapping_add_signed(s)]
                }
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
    // Hysteresis: grow edges into 8-connected candidates.
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
    let mut out = GrayImage::new(img.width, img.height);
    for y in 0..h {
        let src = &map[(y + 1) * mw + 1..(y + 1) * mw + 1 + w];
        for (d, &s) in out.data[y * w..(y + 1) * w].iter_mut().zip(src) {
            *d = if s == 2 { 255 } else { 0 };
        }
    }
    out
}
