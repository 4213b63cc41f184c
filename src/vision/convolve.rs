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

multiversion! {
    /// `acc[i] += v · src[i]` with a fused multiply-add (as OpenCV's SIMD path).
    fn mul_add_row(acc: &mut [f32], src: &[f32], v: f32) {
        let n = acc.len();
        let src = &src[..n];
        for i in 0..n {
            acc[i] = v.mul_add(src[i], acc[i]);
        }
    }
}

multiversion! {
    fn saturate_row(acc: &[f32], dst: &mut [u8]) {
        for (d, &a) in dst.iter_mut().zip(acc) {
            // Adding 1.5·2²³ rounds half to even into the low mantissa bits (exact for
            // 0..=255); this form vectorises, `as u8` on a float does not.
            *d = (a.clamp(0.0, 255.0) + 12_582_912.0).to_bits() as u8;
        }
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
    let mut acc = vec![0f32; w * cn];
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
        // Taps in kernel row-major order, each added over the whole row.
        acc.fill(kernel.offset as f32);
        for &(ky, o, v) in &taps {
            let s = slots[ky] * pw + o;
            mul_add_row(&mut acc, &ring[s..s + w * cn], v);
        }
        saturate_row(&acc, &mut out.data[y * w * cn..(y + 1) * w * cn]);
    }
    out
}
