//! Still images into BGR [`Image`]s.
//!
//! PNM is read by our own parser, as JDE 4.3's imagefile read it and more: `P6`
//! (binary RGB, the only one 4.3 read), `P5` (binary grey), `P3` and `P2` (ASCII),
//! `#` comments anywhere in the header (4.3 only allowed whole comment lines),
//! maxval 1..65535 (16-bit samples are big-endian, scaled to 8 bits). PNG, JPEG
//! and BMP go through the `image` crate. A file that is none of these, or that is
//! truncated (a JPEG without its end-of-image marker after the last scan too), is
//! an error naming the file and what was wrong. Files are read with
//! [`crate::files::read_limited`] (regular files only, at most
//! [`crate::files::MAX_IMAGE_BYTES`]); every format has the same size limit,
//! [`MAX_PIXELS`], checked from the header before decoding.

use std::path::Path;

use super::MediaError;
use crate::interfaces::Image;

/// The largest image we accept, in pixels (bounds allocation on a bad header).
pub const MAX_PIXELS: u64 = 1 << 26;

/// Reads an image file (PNM, PNG, JPEG or BMP) into a BGR image.
pub fn load_image(path: &Path) -> Result<Image, MediaError> {
    let bytes =
        crate::files::read_limited(path, crate::files::MAX_IMAGE_BYTES).map_err(|e| match e {
            crate::files::FileError::Io { source, .. } => MediaError::Io {
                path: path.to_path_buf(),
                source,
            },
            other => MediaError::format(path, other.reason()),
        })?;
    decode_image(&bytes, path)
}

/// Decodes image file contents; `path` names it in errors.
pub fn decode_image(bytes: &[u8], path: &Path) -> Result<Image, MediaError> {
    if bytes.len() >= 2 && bytes[0] == b'P' && matches!(bytes[1], b'2' | b'3' | b'5' | b'6') {
        return decode_pnm(bytes, path);
    }
    if bytes.len() >= 2 && bytes[0] == b'P' && matches!(bytes[1], b'1' | b'4' | b'7') {
        return Err(MediaError::format(
            path,
            format!(
                "PNM type P{} (bitmap/PAM) is not supported; use P6, P5, P3 or P2",
                bytes[1] as char
            ),
        ));
    }
    let format = image::guess_format(bytes).map_err(|_| {
        MediaError::format(
            path,
            "not an image: expected PNM (P6, P5, P3, P2), PNG, JPEG or BMP",
        )
    })?;
    if !matches!(
        format,
        image::ImageFormat::Png | image::ImageFormat::Jpeg | image::ImageFormat::Bmp
    ) {
        return Err(MediaError::format(
            path,
            format!("{format:?} images are not supported; use PNM, PNG, JPEG or BMP"),
        ));
    }
    if format == image::ImageFormat::Jpeg && !jpeg_has_end(bytes) {
        // The decoder fills a cut-short scan with grey and calls it an image.
        return Err(MediaError::format(
            path,
            "truncated JPEG: the file ends before its end-of-image marker",
        ));
    }
    let reader = || {
        let mut reader = image::ImageReader::with_format(std::io::Cursor::new(bytes), format);
        let mut limits = image::Limits::default();
        limits.max_alloc = Some(MAX_PIXELS * 4 + (1 << 20));
        reader.limits(limits);
        reader
    };
    // The header's size first: the same pixel limit as PNM and y4m, before any
    // allocation.
    let (w, h) = reader().into_dimensions().map_err(|e| {
        MediaError::format(
            path,
            format!("cannot decode this {format:?} image's header ({e}); is it truncated?"),
        )
    })?;
    check_size(w as u64, h as u64, path)?;
    let img = reader().decode().map_err(|e| {
        MediaError::format(
            path,
            format!("cannot decode this {format:?} image ({e}); is it truncated?"),
        )
    })?;
    let rgb = img.to_rgb8();
    let (width, height) = rgb.dimensions();
    Ok(Image::from_rgb(width, height, rgb.into_raw()))
}

/// Refuses a header's size of no pixels or more than [`MAX_PIXELS`] (every
/// decoder here: PNM, PNG, JPEG, BMP; y4m checks the same limit).
fn check_size(width: u64, height: u64, path: &Path) -> Result<(), MediaError> {
    if width == 0 || height == 0 || width * height > MAX_PIXELS {
        return Err(MediaError::format(
            path,
            format!("bad image header: size {width}x{height} (expected 1..{MAX_PIXELS} pixels)"),
        ));
    }
    Ok(())
}

/// Whether a JPEG reaches its end-of-image marker (FF D9): walks the segments
/// (skipping each by its length, so an EXIF thumbnail's markers are not taken
/// for the image's) and the entropy-coded data (where an FF is followed by 00 or
/// a restart marker D0..D7). A file cut anywhere before its end never gets there;
/// data after the marker (a second picture, a video) is not looked at.
fn jpeg_has_end(b: &[u8]) -> bool {
    if !b.starts_with(&[0xFF, 0xD8]) {
        return false;
    }
    let mut i = 2;
    loop {
        while i < b.len() && b[i] != 0xFF {
            i += 1;
        }
        while i < b.len() && b[i] == 0xFF {
            i += 1;
        }
        let Some(&m) = b.get(i) else {
            return false;
        };
        i += 1;
        match m {
            0xD9 => return true,
            // Stuffed FF in scan data, restart markers, TEM: no length.
            0x00 | 0x01 | 0xD0..=0xD7 => {}
            _ => {
                let Some(len) = b.get(i..i + 2) else {
                    return false;
                };
                let len = u16::from_be_bytes([len[0], len[1]]) as usize;
                if len < 2 || i + len > b.len() {
                    return false;
                }
                i += len;
            }
        }
    }
}

/// A cursor over a PNM header.
struct Header<'a> {
    b: &'a [u8],
    i: usize,
}

impl Header<'_> {
    fn skip_space_and_comments(&mut self) {
        while self.i < self.b.len() {
            match self.b[self.i] {
                b'#' => {
                    while self.i < self.b.len()
                        && self.b[self.i] != b'\n'
                        && self.b[self.i] != b'\r'
                    {
                        self.i += 1;
                    }
                }
                c if c.is_ascii_whitespace() => self.i += 1,
                _ => break,
            }
        }
    }

    fn number(&mut self) -> Option<u64> {
        self.skip_space_and_comments();
        let start = self.i;
        while self.i < self.b.len() && self.b[self.i].is_ascii_digit() {
            self.i += 1;
        }
        if start == self.i || self.i - start > 9 {
            return None;
        }
        std::str::from_utf8(&self.b[start..self.i])
            .ok()?
            .parse()
            .ok()
    }
}

fn decode_pnm(bytes: &[u8], path: &Path) -> Result<Image, MediaError> {
    let kind = bytes[1];
    let mut h = Header { b: bytes, i: 2 };
    let what = ["width", "height", "maxval"];
    let mut v = [0u64; 3];
    for (k, name) in what.iter().enumerate() {
        v[k] = h.number().ok_or_else(|| {
            MediaError::format(
                path,
                format!("bad PNM header: expected the {name} as a number (truncated file?)"),
            )
        })?;
    }
    let [width, height, maxval] = v;
    check_size(width, height, path)?;
    if !(1..=65535).contains(&maxval) {
        return Err(MediaError::format(
            path,
            format!("bad PNM header: maxval {maxval} (expected 1..65535)"),
        ));
    }
    let channels: usize = if matches!(kind, b'3' | b'6') { 3 } else { 1 };
    let samples = (width * height) as usize * channels;
    let scale = |s: u32| -> u8 {
        if maxval == 255 {
            s.min(255) as u8
        } else {
            ((s.min(maxval as u32) as u64 * 255 + maxval / 2) / maxval) as u8
        }
    };
    let mut rgb = Vec::with_capacity(samples);
    if matches!(kind, b'5' | b'6') {
        // Exactly one whitespace byte after maxval, then the raster.
        if h.i >= bytes.len() || !bytes[h.i].is_ascii_whitespace() {
            return Err(MediaError::format(
                path,
                "bad PNM header: expected one whitespace byte after maxval (truncated file?)",
            ));
        }
        let raster = &bytes[h.i + 1..];
        let wide = maxval > 255;
        let need = samples * if wide { 2 } else { 1 };
        if raster.len() < need {
            return Err(MediaError::format(
                path,
                format!(
                    "truncated: a {width}x{height} P{} image needs {need} bytes of pixels, the file has {}",
                    kind as char,
                    raster.len()
                ),
            ));
        }
        if wide {
            rgb.extend(
                raster[..need]
                    .chunks_exact(2)
                    .map(|s| scale(u16::from_be_bytes([s[0], s[1]]) as u32)),
            );
        } else if maxval == 255 {
            rgb.extend_from_slice(&raster[..need]);
        } else {
            rgb.extend(raster[..need].iter().map(|&s| scale(s as u32)));
        }
    } else {
        for n in 0..samples {
            let s = h.number().ok_or_else(|| {
                MediaError::format(
                    path,
                    format!(
                        "truncated or bad ASCII PNM: sample {} of {samples} is missing or not a number",
                        n + 1
                    ),
                )
            })?;
            rgb.push(scale(s.min(u32::MAX as u64) as u32));
        }
    }
    let mut data = Vec::with_capacity((width * height * 3) as usize);
    if channels == 3 {
        for p in rgb.chunks_exact(3) {
            data.extend_from_slice(&[p[2], p[1], p[0]]);
        }
    } else {
        for &g in &rgb {
            data.extend_from_slice(&[g, g, g]);
        }
    }
    Ok(Image {
        width: width as u32,
        height: height as u32,
        data,
    })
}

/// Writes a BGR image as binary PPM (P6), the format 4.3's imagefile read.
pub fn encode_ppm(img: &Image) -> Vec<u8> {
    let mut out = format!("P6\n{} {}\n255\n", img.width, img.height).into_bytes();
    out.extend_from_slice(&img.to_rgb());
    out
}

/// Bilinear resize of a BGR image to `width` x `height` (a copy when the size is
/// the same).
pub fn resize(src: &Image, width: u32, height: u32) -> Image {
    if (src.width, src.height) == (width, height) || src.width == 0 || src.height == 0 {
        let mut out = src.clone();
        if src.width == 0 || src.height == 0 {
            out = Image::new(width, height);
        }
        return out;
    }
    let mut out = Image::new(width, height);
    let (sw, sh) = (src.width as usize, src.height as usize);
    // Pixel centres map onto pixel centres.
    let map = |d: usize, dn: u32, sn: usize| -> (usize, usize, u32) {
        let x = ((d as f64 + 0.5) * sn as f64 / dn as f64 - 0.5).max(0.0);
        let x0 = (x as usize).min(sn - 1);
        let x1 = (x0 + 1).min(sn - 1);
        let f = ((x - x0 as f64) * 256.0).round().clamp(0.0, 256.0) as u32;
        (x0, x1, f)
    };
    let cols: Vec<(usize, usize, u32)> = (0..width as usize).map(|x| map(x, width, sw)).collect();
    for y in 0..height as usize {
        let (y0, y1, fy) = map(y, height, sh);
        let r0 = &src.data[y0 * sw * 3..(y0 + 1) * sw * 3];
        let r1 = &src.data[y1 * sw * 3..(y1 + 1) * sw * 3];
        let row = &mut out.data[y * width as usize * 3..(y + 1) * width as usize * 3];
        for (x, &(x0, x1, fx)) in cols.iter().enumerate() {
            for c in 0..3 {
                let a = r0[x0 * 3 + c] as u32 * (256 - fx) + r0[x1 * 3 + c] as u32 * fx;
                let b = r1[x0 * 3 + c] as u32 * (256 - fx) + r1[x1 * 3 + c] as u32 * fx;
                row[x * 3 + c] = ((a * (256 - fy) + b * fy + (1 << 15)) >> 16) as u8;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(path: &str) -> &Path {
        Path::new(path)
    }

    #[test]
    fn p6_with_comments_is_bgr() {
        let mut f = b"P6\n# GIMP comment\n2 1 # trailing\n255\n".to_vec();
        f.extend_from_slice(&[255, 0, 0, 1, 2, 3]);
        let img = decode_image(&f, p("t.ppm")).unwrap();
        assert_eq!((img.width, img.height), (2, 1));
        assert_eq!(img.data, [0, 0, 255, 3, 2, 1]);
    }

    #[test]
    fn p3_p5_p2_and_16_bit() {
        let img = decode_image(b"P3 1 1 15\n15 0 5\n", p("a")).unwrap();
        assert_eq!(img.data, [85, 0, 255]);
        let img = decode_image(b"P5 2 1 255\n\x10\x20", p("a")).unwrap();
        assert_eq!(img.data, [16, 16, 16, 32, 32, 32]);
        let img = decode_image(b"P2\n1 1\n255\n7\n", p("a")).unwrap();
        assert_eq!(img.data, [7, 7, 7]);
        let img = decode_image(b"P5 1 1 65535\n\xff\xff", p("a")).unwrap();
        assert_eq!(img.data, [255, 255, 255]);
    }

    #[test]
    fn truncated_and_garbage_name_the_file() {
        let e = decode_image(b"P6 2 2 255\n\0\0\0", p("short.ppm")).unwrap_err();
        assert!(e.to_string().starts_with("short.ppm: truncated"), "{e}");
        let e = decode_image(b"P6 2", p("h.ppm")).unwrap_err().to_string();
        assert!(e.contains("h.ppm: bad PNM header"), "{e}");
        let e = decode_image(b"hello world", p("x.txt"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.txt: not an image"), "{e}");
        let e = decode_image(b"P6 99999 99999 255\n", p("big.ppm"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("size"), "{e}");
    }

    #[test]
    fn resize_keeps_flat_colours_and_sizes() {
        let mut img = Image::new(4, 2);
        for px in img.data.chunks_exact_mut(3) {
            px.copy_from_slice(&[10, 20, 30]);
        }
        let r = resize(&img, 7, 5);
        assert_eq!((r.width, r.height, r.data.len()), (7, 5, 105));
        assert!(r.data.chunks_exact(3).all(|p| p == [10, 20, 30]));
    }
}
