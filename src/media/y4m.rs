//! YUV4MPEG2 (`.y4m`), the stream mplayer's `-vo yuv4mpeg` writes: one header line
//! `YUV4MPEG2 W640 H480 F30:1 Ip A1:1 [C420jpeg]`, then per frame a line
//! `FRAME[ params]` and the Y, U and V planes (4:2:0: U and V are
//! ⌈W/2⌉ x ⌈H/2⌉). Converted to BGR with BT.601 limited-range coefficients, the
//! matrix mplayer and FFmpeg use for standard-definition video.

use std::io::Read;

/// The stream header.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Y4mHeader {
    pub width: u32,
    pub height: u32,
    /// Frames per second, if the header gives a rate.
    pub rate: Option<f64>,
}

impl Y4mHeader {
    /// Bytes of one frame's planes.
    pub fn frame_bytes(&self) -> usize {
        let (w, h) = (self.width as usize, self.height as usize);
        w * h + 2 * w.div_ceil(2) * h.div_ceil(2)
    }
}

/// Reads one `\n`-terminated line of at most `max` bytes; None at EOF before any byte.
fn read_line(r: &mut impl Read, max: usize) -> Result<Option<Vec<u8>>, String> {
    let mut line = Vec::new();
    let mut b = [0u8; 1];
    loop {
        match r.read(&mut b) {
            Ok(0) if line.is_empty() => return Ok(None),
            Ok(0) => return Err("the stream ended inside a header line".into()),
            Ok(_) if b[0] == b'\n' => return Ok(Some(line)),
            Ok(_) => {
                if line.len() >= max {
                    return Err(format!(
                        "a header line longer than {max} bytes: not a YUV4MPEG2 stream"
                    ));
                }
                line.push(b[0]);
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e.to_string()),
        }
    }
}

/// Reads the stream header; None if the stream is empty (the writer produced nothing).
pub fn read_header(r: &mut impl Read) -> Result<Option<Y4mHeader>, String> {
    let Some(line) = read_line(r, 1024)? else {
        return Ok(None);
    };
    let line = String::from_utf8_lossy(&line).into_owned();
    let mut words = line.split(' ');
    if words.next() != Some("YUV4MPEG2") {
        return Err(format!(
            "not a YUV4MPEG2 stream (it starts with `{}`)",
            line.chars().take(40).collect::<String>()
        ));
    }
    let (mut width, mut height, mut rate) = (0u32, 0u32, None);
    for w in words {
        // The tag is the first character (split at a char boundary: the line was
        // made valid UTF-8 with replacement characters, which take 3 bytes).
        let (tag, val) = w.split_at(w.chars().next().map_or(0, char::len_utf8));
        match tag {
            "W" => width = val.parse().unwrap_or(0),
            "H" => height = val.parse().unwrap_or(0),
            "F" => {
                rate = val.split_once(':').and_then(|(n, d)| {
                    let (n, d) = (n.parse::<f64>().ok()?, d.parse::<f64>().ok()?);
                    (n > 0.0 && d > 0.0).then_some(n / d)
                })
            }
            "C" if !val.starts_with("420") => {
                return Err(format!(
                    "YUV4MPEG2 colour space C{val} is not supported (expected 4:2:0)"
                ));
            }
            _ => {}
        }
    }
    if width == 0 || height == 0 || width as u64 * height as u64 > super::still::MAX_PIXELS {
        return Err(format!(
            "YUV4MPEG2 header with a bad size: `{}`",
            crate::files::shorten(&line)
        ));
    }
    Ok(Some(Y4mHeader {
        width,
        height,
        rate,
    }))
}

/// Reads the next frame's planes into `buf`; false at a clean end of stream.
pub fn read_frame(r: &mut impl Read, h: &Y4mHeader, buf: &mut Vec<u8>) -> Result<bool, String> {
    let Some(line) = read_line(r, 1024)? else {
        return Ok(false);
    };
    if !line.starts_with(b"FRAME") {
        return Err("YUV4MPEG2 stream out of step: expected `FRAME`".into());
    }
    buf.resize(h.frame_bytes(), 0);
    r.read_exact(buf).map_err(|e| {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            "the stream ended in the middle of a frame".to_string()
        } else {
            e.to_string()
        }
    })?;
    Ok(true)
}

#[inline(always)]
fn clamp8(v: i32) -> u8 {
    v.clamp(0, 255) as u8
}

/// Converts 4:2:0 planes (`src` as [`read_frame`] leaves them, of a `sw` x `sh`
/// stream) to BGR `out` of `w` x `h` (`w <= sw`, `h <= sh`: extra columns and rows,
/// e.g. mplayer's rounding of odd sizes up to even, are cropped).
pub fn i420_to_bgr(src: &[u8], sw: usize, sh: usize, w: usize, h: usize, out: &mut [u8]) {
    let cw = sw.div_ceil(2);
    let ch = sh.div_ceil(2);
    let (yp, rest) = src.split_at(sw * sh);
    let (up, vp) = rest.split_at(cw * ch);
    let (w, h) = (w.min(sw), h.min(sh));
    for row in 0..h {
        let yrow = &yp[row * sw..row * sw + w];
        let urow = &up[(row / 2) * cw..(row / 2) * cw + w.div_ceil(2)];
        let vrow = &vp[(row / 2) * cw..(row / 2) * cw + w.div_ceil(2)];
        let orow = &mut out[row * w * 3..(row + 1) * w * 3];
        // Two pixels share one chroma sample: its terms are computed once.
        let pairs = orow
            .chunks_mut(6)
            .zip(yrow.chunks(2))
            .zip(urow.iter().zip(vrow));
        for ((px, ys), (&u, &v)) in pairs {
            let d = u as i32 - 128;
            let e = v as i32 - 128;
            let (bu, guv, rv) = (516 * d + 128, -100 * d - 208 * e + 128, 409 * e + 128);
            for (p, &y) in px.chunks_exact_mut(3).zip(ys) {
                let c = 298 * (y as i32 - 16);
                p[0] = clamp8((c + bu) >> 8);
                p[1] = clamp8((c + guv) >> 8);
                p[2] = clamp8((c + rv) >> 8);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_frames_and_colours() {
        // 2x2, one frame: limited-range red is Y=81 U=90 V=240.
        let mut s = b"YUV4MPEG2 W2 H2 F30000:1001 Ip A1:1 C420jpeg\nFRAME\n".to_vec();
        s.extend_from_slice(&[81, 81, 81, 81, 90, 240]);
        let mut r = &s[..];
        let h = read_header(&mut r).unwrap().unwrap();
        assert_eq!((h.width, h.height), (2, 2));
        assert!((h.rate.unwrap() - 29.97).abs() < 0.01);
        let mut buf = Vec::new();
        assert!(read_frame(&mut r, &h, &mut buf).unwrap());
        let mut out = vec![0; 12];
        i420_to_bgr(&buf, 2, 2, 2, 2, &mut out);
        for px in out.chunks_exact(3) {
            assert!(px[0] < 3 && px[1] < 3 && px[2] > 252, "{px:?}");
        }
        assert!(!read_frame(&mut r, &h, &mut buf).unwrap());
    }

    #[test]
    fn bad_streams_are_errors() {
        assert!(read_header(&mut &b"hello\n"[..]).is_err());
        assert_eq!(read_header(&mut &b""[..]).unwrap(), None);
        assert!(read_header(&mut &b"YUV4MPEG2 W2 H2 C444\n"[..]).is_err());
        let h = Y4mHeader {
            width: 2,
            height: 2,
            rate: None,
        };
        assert!(read_frame(&mut &b"FRAME\n\x01"[..], &h, &mut Vec::new()).is_err());
    }
}
