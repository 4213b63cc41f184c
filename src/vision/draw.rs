//! Drawing on images.

use crate::interfaces::Image;

/// Draws a line from (column, row) `(x0, y0)` to `(x1, y1)` in colour `bgr`,
/// clipped to the image: Bresenham on the rounded ends, as 4.3's line drawer. A
/// non-finite or absurd end (beyond ±10⁶ px) draws nothing.
pub fn draw_line(img: &mut Image, (x0, y0): (f64, f64), (x1, y1): (f64, f64), bgr: [u8; 3]) {
    if ![x0, y0, x1, y1]
        .iter()
        .all(|v| v.is_finite() && v.abs() < 1e6)
    {
        return;
    }
    let (mut x, mut y) = (x0.round() as i64, y0.round() as i64);
    let (xe, ye) = (x1.round() as i64, y1.round() as i64);
    let (dx, dy) = ((xe - x).abs(), -(ye - y).abs());
    let (sx, sy) = (if x < xe { 1 } else { -1 }, if y < ye { 1 } else { -1 });
    let mut err = dx + dy;
    let (w, h) = (img.width as i64, img.height as i64);
    // Bounded: at most |dx| + |dy| + 1 steps.
    for _ in 0..=(dx - dy) {
        if (0..w).contains(&x) && (0..h).contains(&y) {
            let i = ((y * w + x) * 3) as usize;
            if let Some(p) = img.data.get_mut(i..i + 3) {
                p.copy_from_slice(&bgr);
            }
        }
        if x == xe && y == ye {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x += sx;
        }
        if e2 <= dx {
            err += dx;
            y += sy;
        }
    }
}
