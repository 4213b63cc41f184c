//! Convolution with opencvdemo's kernels (see the module doc of [`super`] for the
//! file format).

pub use crate::files::FileError as KernelError;
use std::path::Path;

use super::{is_valid, multiversion, reflect101};
use crate::interfaces::Image;

/// A square convolution kernel with opencvdemo's `size`, `modulo` and `offset`.
#[derive(Clone, Debug, PartialEq)]
pub struct Kernel {
    /// Odd side length.
    pub size: usize,
    /// Row-major coefficients, already divided by `modulo` (when it is > 1).
    pub values: Vec<f32>,
    /// The divisor the file gave (1 when none).
    pub modulo: i32,
    /// Added to every result before saturation to 0..255.
    pub offset: i32,
}

impl Default for Kernel {
    /// opencvdemo's default: `[1 1 1; 1 -7 1; 1 1 1]`.
    fn default() -> Self {
        Kernel {
            size: 3,
            values: vec![1.0, 1.0, 1.0, 1.0, -7.0, 1.0, 1.0, 1.0, 1.0],
            modulo: 1,
            offset: 0,
        }
    }
}

impl Kernel {
    /// A kernel from rows of coefficients (divided by `modulo` when > 1).
    pub fn from_rows(rows: &[&[f32]], modulo: i32, offset: i32) -> Option<Self> {
        let size = rows.len();
        if size.is_multiple_of(2) || rows.iter().any(|r| r.len() != size) {
            return None;
        }
        let div = if modulo > 1 { modulo as f32 } else { 1.0 };
        Some(Kernel {
            size,
            values: rows
                .iter()
                .flat_map(|r| r.iter().map(|v| v / div))
                .collect(),
            modulo: modulo.max(1),
            offset,
        })
    }

    /// Reads a kernel file (or an opencvdemo conf).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, KernelError> {
        let path = path.as_ref();
        let text = KernelError::read(path)?;
        Self::parse(&text, path)
    }

    /// Parses kernel lines; `file` names them in errors. Without any `size`/`row`
    /// line the result is [`Kernel::default`].
    pub fn parse(text: &str, file: &Path) -> Result<Self, KernelError> {
        let mut size: Option<usize> = None;
        let mut modulo = 1i32;
        let mut offset = 0i32;
        let mut rows: Vec<(usize, usize, Vec<f32>)> = Vec::new(); // (line, row, values)
        for (n, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or_default().trim();
            let mut w = line.split_whitespace();
            let Some(key) = w.next() else { continue };
            let args: Vec<&str> = w.collect();
            let err = |message: String| KernelError::Syntax {
                file: file.to_path_buf(),
                line: n + 1,
                message,
            };
            let int = |what: &str| -> Result<i32, KernelError> {
                match args[..] {
                    [v] => v
                        .parse::<i32>()
                        .map_err(|_| err(format!("`{key} {v}`: expected {what}"))),
                    _ => Err(err(format!("`{key}` takes one value: {what}"))),
                }
            };
            match key {
                "size" => {
                    let s = int("an odd size from 1 to 15 (3 or 5 in 4.3)")?;
                    if !(1..=15).contains(&s) || s % 2 == 0 {
                        return Err(err(format!(
                            "`size {s}`: must be odd, from 1 to 15 (4.3: 3 or 5)"
                        )));
                    }
                    size = Some(s as usize);
                }
                "modulo" => modulo = int("an integer divisor")?,
                "offset" => offset = int("an integer added to every result")?,
                "row" => {
                    let Some((idx, vals)) = args.split_first() else {
                        return Err(err("expected `row N v1 .. vsize`".into()));
                    };
                    let idx: usize =
                        idx.parse().ok().filter(|i| *i >= 1).ok_or_else(|| {
                            err(format!("`row {idx}`: expected a row number from 1"))
                        })?;
                    let vals: Vec<f32> = vals
                        .iter()
                        .map(|v| v.parse::<f32>().ok().filter(|v| v.is_finite()))
                        .collect::<Option<_>>()
                        .ok_or_else(|| err(format!("`row {idx}`: expected numbers")))?;
                    rows.push((n + 1, idx, vals));
                }
                _ => {}
            }
        }
        if size.is_none() && rows.is_empty() {
            return Ok(Kernel::default());
        }
        let incomplete = |message: String| KernelError::Invalid {
            file: file.to_path_buf(),
            message,
        };
        let size = size.ok_or_else(|| incomplete("`row` lines without a `size` line".into()))?;
        let mut grid: Vec<Option<Vec<f32>>> = vec![None; size];
        for (line, idx, vals) in rows {
            let err = |message: String| KernelError::Syntax {
                file: file.to_path_buf(),
                line,
                message,
            };
            if idx > size {
                return Err(err(format!("`row {idx}`: the kernel has only {size} rows")));
            }
            if vals.len() != size {
                return Err(err(format!(
                    "`row {idx}` has {} values; `size {size}` needs {size}",
                    vals.len()
                )));
            }
            grid[idx - 1] = Some(vals);
        }
        let missing: Vec<String> = (1..=size)
            .filter(|i| grid[i - 1].is_none())
            .map(|i| i.to_string())
            .collect();
        if !missing.is_empty() {
            return Err(incomplete(format!(
                "missing `row` lines: {}",
                missing.join(", ")
            )));
        }
        let rows: Vec<Vec<f32>> = grid.into_iter().flatten().collect();
        let refs: Vec<&[f32]> = rows.iter().map(Vec::as_slice).collect();
        Kernel::from_rows(&refs, modulo, offset)
            .ok_or_else(|| incomplete("the kernel is not square".into()))
    }

    /// The kernel as file lines (parses back to the same kernel).
    pub fn to_file_string(&self) -> String {
        let mut s = format!(
            "size {}\nmodulo {}\noffset {}\n",
            self.size, self.modulo, self.offset
        );
        let m = if self.modulo > 1 {
            self.modulo as f32
        } else {
            1.0
        };
        for (i, r) in self.values.chunks(self.size).enumerate() {
            let vals: Vec<String> = r.iter().map(|v| format!("{:?}", v * m)).collect();
            s += &format!("row {} {}\n", i + 1, vals.join(" "));
        }
        s
    }
}

multiversion! {
    fn to_f32(src: &[u8], dst: &mut [f32]) {
        for (d, &s) in dst.iter_mut().zip(src) {
            *d = s as f32;
        }
    }
}

/// Elements of an output row computed together, kept in vector registers while
/// every tap is added.
const BLOCK: usize = 64;

multiversion! {
    /// One output row: each element starts at `offset`, gets every tap's
    /// `v · src` with a fused multiply-add in kernel order (as OpenCV's SIMD path),
    /// and saturates to 0..255 rounding half to even. `taps` are (start in `ring`,
    /// value).
    fn filter_row(ring: &[f32], taps: &[(usize, f32)], offset: f32, dst: &mut [u8]) {
        let n = dst.len();
        let full = n - n % BLOCK;
        for x in (0..full).step_by(BLOCK) {
            let mut acc = [offset; BLOCK];
            for &(s, v) in taps {
                let src: &[f32; BLOCK] = ring[s + x..s + x + BLOCK].try_into().unwrap();
                for i in 0..BLOCK {
                    acc[i] = v.mul_add(src[i], acc[i]);
                }
            }
            saturate(&acc, &mut dst[x..x + BLOCK]);
        }
        let m = n - full;
        if m > 0 {
            let mut acc = [offset; BLOCK];
            for &(s, v) in taps {
                let src = &ring[s + full..s + n];
                for i in 0..m {
                    acc[i] = v.mul_add(src[i], acc[i]);
                }
            }
            saturate(&acc[..m], &mut dst[full..]);
        }
    }
}

#[inline(always)]
fn saturate(acc: &[f32], dst: &mut [u8]) {
    for (d, &a) in dst.iter_mut().zip(acc) {
        // Adding 1.5·2²³ rounds half to even into the low mantissa bits (exact for
        // 0..=255); this form vectorises, `as u8` on a float does not.
        *d = (a.clamp(0.0, 255.0) + 12_582_912.0).to_bits() as u8;
    }
}

/// Convolves a BGR image with `kernel` (each channel, anchor at the centre,
/// `BORDER_REFLECT_101`), adds `kernel.offset` and saturates to 0..255 rounding half
/// to even — OpenCV's `filter2D(src, -1, kernel, delta = offset)` (a correlation, as
/// OpenCV's; opencvdemo's kernels are symmetric or meant that way).
pub fn convolve(img: &Image, kernel: &Kernel) -> Image {
    if !is_valid(img)
        || kernel.values.len() != kernel.size * kernel.size
        || kernel.size.is_multiple_of(2)
    {
        return Image::default();
    }
    let (w, h) = (img.width as usize, img.height as usize);
    let k = kernel.size;
    let r = k / 2;
    let cn = 3;
    let pw = (w + 2 * r) * cn;
    // A ring of k padded float rows: source row sy lives in slot sy % k (the rows one
    // output row needs are k consecutive ones, reflected at the borders).
    let mut ring = vec![0f32; pw * k];
    let mut held = vec![usize::MAX; k];
    let taps: Vec<(usize, usize, f32)> = (0..k * k)
        .filter(|&i| kernel.values[i] != 0.0)
        .map(|i| (i / k, (i % k) * cn, kernel.values[i]))
        .collect();
    let mut out = Image::new(img.width, img.height);
    let mut row_taps = Vec::with_capacity(taps.len());
    for y in 0..h {
        let mut slots = vec![0usize; k];
        for (ky, slot) in slots.iter_mut().enumerate().take(k) {
            let sy = reflect101(y as isize + ky as isize - r as isize, h);
            let s = sy % k;
            if held[s] != sy {
                held[s] = sy;
                let src = &img.data[sy * w * cn..(sy + 1) * w * cn];
                let dst = &mut ring[s * pw..(s + 1) * pw];
                to_f32(src, &mut dst[r * cn..(r + w) * cn]);
                for i in 0..r {
                    let (l, rr) = (
                        reflect101(i as isize - r as isize, w),
                        reflect101((w + i) as isize, w),
                    );
                    for c in 0..cn {
                        dst[i * cn + c] = src[l * cn + c] as f32;
                        dst[(r + w + i) * cn + c] = src[rr * cn + c] as f32;
                    }
                }
            }
            *slot = s;
        }
        // Taps in kernel row-major order, each where its source row is in the ring.
        row_taps.clear();
        row_taps.extend(taps.iter().map(|&(ky, o, v)| (slots[ky] * pw + o, v)));
        let dst = &mut out.data[y * w * cn..(y + 1) * w * cn];
        filter_row(&ring, &row_taps, kernel.offset as f32, dst);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// filter2D from its definition: per output value, the offset, then every tap
    /// in kernel row-major order with a fused multiply-add, reflect-101 borders.
    fn convolve_reference(img: &Image, kernel: &Kernel) -> Vec<u8> {
        let (w, h, k) = (img.width as usize, img.height as usize, kernel.size);
        let r = (k / 2) as isize;
        let mut out = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    let mut acc = kernel.offset as f32;
                    for ky in 0..k {
                        let sy = reflect101(y as isize + ky as isize - r, h);
                        for kx in 0..k {
                            let v = kernel.values[ky * k + kx];
                            if v != 0.0 {
                                let sx = reflect101(x as isize + kx as isize - r, w);
                                acc = v.mul_add(img.data[(sy * w + sx) * 3 + c] as f32, acc);
                            }
                        }
                    }
                    out.push(acc.clamp(0.0, 255.0).round_ties_even() as u8);
                }
            }
        }
        out
    }

    #[test]
    fn convolve_matches_its_definition_at_any_width() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/kernels");
        let mut kernels: Vec<Kernel> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| Kernel::load(e.unwrap().path()).unwrap())
            .collect();
        let row: &[f32] = &[0.5, -1.0, 0.25];
        kernels.push(Kernel::from_rows(&[row; 3], 1, 17).unwrap());
        assert!(kernels.len() >= 7);
        // Widths whose rows (3 values a pixel) end inside a 64-value block and on one.
        for (w, h) in [
            (1, 1),
            (2, 3),
            (5, 4),
            (21, 6),
            (22, 5),
            (43, 3),
            (64, 2),
            (65, 7),
        ] {
            let data = (0..w * h * 3).map(|i| (i * 7919 % 256) as u8).collect();
            let img = Image {
                width: w as u32,
                height: h as u32,
                data,
            };
            for k in &kernels {
                if k.size <= w.min(h) || k.size == 3 {
                    assert_eq!(
                        convolve(&img, k).data,
                        convolve_reference(&img, k),
                        "{w}x{h}, {k:?}"
                    );
                }
            }
        }
    }
}
