//! Occupancy bitmaps (Stage-like PNG floor plans) and the wall faces they become:
//! only the boundaries between occupied and free cells, merged into runs.

use std::path::Path;

use super::{Point2, Rgb, Segment, World};

/// An occupancy bitmap: `dark[j * width + i]` is cell (i, j), rows from the bottom.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Bitmap {
    pub dark: Vec<bool>,
    pub width: usize,
    pub height: usize,
}

/// Decodes a PNG into an occupancy bitmap.
pub fn load_bitmap(file: &Path) -> Result<Bitmap, String> {
    let bytes = crate::files::read_limited(file, crate::files::MAX_IMAGE_BYTES)
        .map_err(|e| format!("cannot read: {}", e.reason()))?;
    let mut dec = png::Decoder::new(std::io::Cursor::new(bytes));
    dec.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = dec
        .read_info()
        .map_err(|e| format!("not a readable PNG: {e}"))?;
    let (w, h) = (reader.info().width as usize, reader.info().height as usize);
    if w == 0 || h == 0 || w * h > 16_000_000 {
        return Err(format!(
            "{w}x{h} pixels: expected a non-empty image of at most 16 Mpixels"
        ));
    }
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| "image too large".to_string())?;
    let mut buf = vec![0u8; size];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| format!("cannot decode PNG: {e}"))?;
    let channels = info.color_type.samples();
    let mut dark = vec![false; w * h];
    for py in 0..h {
        let row = &buf[py * info.line_size..];
        let j = h - 1 - py;
        for i in 0..w {
            let px = &row[i * channels..(i + 1) * channels];
            let (lum, alpha) = match channels {
                1 => (px[0] as u32, 255),
                2 => (px[0] as u32, px[1] as u32),
                3 => (
                    (px[0] as u32 * 30 + px[1] as u32 * 59 + px[2] as u32 * 11) / 100,
                    255,
                ),
                _ => (
                    (px[0] as u32 * 30 + px[1] as u32 * 59 + px[2] as u32 * 11) / 100,
                    px[3] as u32,
                ),
            };
            dark[j * w + i] = lum < 128 && alpha >= 128;
        }
    }
    Ok(Bitmap {
        dark,
        width: w,
        height: h,
    })
}

impl World {
    /// Adds the walls of an occupancy bitmap; cell (i, j) covers
    /// [x0 + i·pixel, x0 + (i+1)·pixel] × [y0 + j·pixel, ...]. Only the boundaries
    /// between occupied and free cells become (one-sided) wall faces, merged into runs.
    pub fn add_occupancy(
        &mut self,
        map: &Bitmap,
        pixel: f64,
        origin: Point2,
        height: f64,
        color: Rgb,
    ) {
        let (dark, w, h) = (&map.dark, map.width, map.height);
        let occ = |i: isize, j: isize| -> bool {
            i >= 0
                && j >= 0
                && (i as usize) < w
                && (j as usize) < h
                && dark[j as usize * w + i as usize]
        };
        let x = |i: usize| origin[0] + i as f64 * pixel;
        let y = |j: usize| origin[1] + j as f64 * pixel;
        let mut push = |a: Point2, b: Point2, n: Point2| {
            self.segments.push(Segment {
                a,
                b,
                height,
                color,
                normal: Some(n),
            })
        };
        // Horizontal boundaries at y(j), j in 0..=h: between row j-1 (below) and row j (above).
        for j in 0..=h {
            for dir in [1.0f64, -1.0] {
                // dir 1: solid below, free above (normal +y); dir -1: the reverse.
                let mut run: Option<usize> = None;
                for i in 0..=w {
                    let edge = i < w && {
                        let below = occ(i as isize, j as isize - 1);
                        let above = occ(i as isize, j as isize);
                        if dir > 0.0 {
                            below && !above
                        } else {
                            above && !below
                        }
                    };
                    match (edge, run) {
                        (true, None) => run = Some(i),
                        (false, Some(s)) => {
                            push([x(s), y(j)], [x(i), y(j)], [0.0, dir]);
                            run = None;
                        }
                        _ => {}
                    }
                }
            }
        }
        // Vertical boundaries at x(i), i in 0..=w: between column i-1 (left) and i (right).
        for i in 0..=w {
            for dir in [1.0f64, -1.0] {
                let mut run: Option<usize> = None;
                for j in 0..=h {
                    let edge = j < h && {
                        let left = occ(i as isize - 1, j as isize);
                        let right = occ(i as isize, j as isize);
                        if dir > 0.0 {
                            left && !right
                        } else {
                            right && !left
                        }
                    };
                    match (edge, run) {
                        (true, None) => run = Some(j),
                        (false, Some(s)) => {
                            push([x(i), y(s)], [x(i), y(j)], [dir, 0.0]);
                            run = None;
                        }
                        _ => {}
                    }
                }
            }
        }
        self.grid.dirty = true;
    }

    /// Loads a PNG floor plan: pixels darker than 50 % grey (and not transparent)
    /// are walls. The image's bottom-left corner is at `origin`.
    pub fn add_floorplan(
        &mut self,
        file: &Path,
        pixel: f64,
        origin: Point2,
        height: f64,
        color: Rgb,
    ) -> Result<(), String> {
        let map = load_bitmap(file)?;
        self.add_occupancy(&map, pixel, origin, height, color);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn occupancy_boundaries_merge() {
        let mut w = World::new();
        // A 3x2 solid block: 4 merged faces.
        let map = Bitmap {
            dark: vec![true; 6],
            width: 3,
            height: 2,
        };
        w.add_occupancy(&map, 100.0, [0.0, 0.0], 500.0, [0, 0, 0]);
        assert_eq!(w.segments.len(), 4);
        w.finish();
        let (t, _) = w.cast([-500.0, 100.0], [1.0, 0.0], 10000.0).unwrap();
        assert!((t - 500.0).abs() < 1e-9);
    }
}
