//! Pixel-format conversions to BGR at 640x480 (what the camera drivers do per
//! frame): medians of repeated runs, and, with the `firewire` feature, the ratio to
//! libdc1394's own conversion of the same frame measured in the same run. Run with
//! `cargo bench --features full --bench pixfmt`. The OpenCV comparison of YUYV and
//! Bayer (goal: ≤ 1.0x `cvtColor`) is `scripts/compare_opencv.py`.

use std::{hint::black_box, time::Instant};

use jderobot::vision::pixfmt::{self, Bayer, Yuv422Order, YuvMatrix};

const W: u32 = 640;
const H: u32 = 480;
const REPS: usize = 301;

fn median_ms(mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..REPS)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

/// `n` reproducible pseudo-random bytes (every value).
fn noise(n: usize) -> Vec<u8> {
    let mut rng = fastrand::Rng::with_seed(0x2545_f491);
    std::iter::repeat_with(|| rng.u8(..)).take(n).collect()
}

#[cfg(feature = "firewire")]
fn dc1394_rgb8(src: &mut [u8], out: &mut [u8], order: u32, coding: i32) {
    use jderobot::drivers::firewire::ffi;
    // SAFETY: buffers sized for a 640x480 frame of `coding`.
    unsafe {
        ffi::dc1394_convert_to_RGB8(src.as_mut_ptr(), out.as_mut_ptr(), W, H, order, coding, 8)
    };
}

/// libdc1394's UYVY → RGB8 of the same frame, ms (the `firewire` feature links it).
fn libdc1394_yuv422(_src: &[u8]) -> Option<f64> {
    #[cfg(feature = "firewire")]
    {
        use jderobot::drivers::firewire::ffi;
        let mut s = _src.to_vec();
        let mut o = vec![0u8; (W * H * 3) as usize];
        return Some(median_ms(|| {
            dc1394_rgb8(
                &mut s,
                &mut o,
                ffi::DC1394_BYTE_ORDER_UYVY,
                ffi::DC1394_COLOR_CODING_YUV422,
            );
            black_box(&o);
        }));
    }
    #[allow(unreachable_code)]
    None
}

/// libdc1394's bilinear demosaicing of the same mosaic, ms.
fn libdc1394_bayer(_src: &[u8], _tile: i32) -> Option<f64> {
    #[cfg(feature = "firewire")]
    {
        use jderobot::drivers::firewire::ffi;
        let mut o = vec![0u8; (W * H * 3) as usize];
        return Some(median_ms(|| {
            // SAFETY: a 640x480 mosaic in, 640x480x3 out.
            unsafe {
                ffi::dc1394_bayer_decoding_8bit(
                    _src.as_ptr(),
                    o.as_mut_ptr(),
                    W,
                    H,
                    _tile,
                    ffi::DC1394_BAYER_METHOD_BILINEAR,
                )
            };
            black_box(&o);
        }));
    }
    #[allow(unreachable_code)]
    None
}

fn main() {
    let n = (W * H) as usize;
    let src = noise(n * 3);
    let mut out = Vec::new();
    let row = |name: &str, ms: f64, reference: Option<(&str, f64)>| match reference {
        Some((r, rms)) => println!(
            "{name:<32} {ms:>7.3} ms   {r}: {rms:.3} ms   ratio {:.2}x",
            ms / rms
        ),
        None => println!("{name:<32} {ms:>7.3} ms"),
    };
    println!("pixfmt, {W}x{H} -> BGR, median of {REPS} runs");

    let t = median_ms(|| {
        pixfmt::yuv422_to_bgr(
            &src[..n * 2],
            W,
            H,
            Yuv422Order::Yuyv,
            YuvMatrix::Bt601,
            &mut out,
        )
        .unwrap();
        black_box(&out);
    });
    row("YUYV (BT.601, V4L2)", t, None);
    let t = median_ms(|| {
        pixfmt::yuv422_to_bgr(
            &src[..n * 2],
            W,
            H,
            Yuv422Order::Uyvy,
            YuvMatrix::Bt601,
            &mut out,
        )
        .unwrap();
        black_box(&out);
    });
    row("UYVY (BT.601)", t, None);

    let reference = libdc1394_yuv422(&src[..n * 2]).map(|t| ("libdc1394", t));
    let t = median_ms(|| {
        pixfmt::yuv422_to_bgr(
            &src[..n * 2],
            W,
            H,
            Yuv422Order::Uyvy,
            YuvMatrix::Iidc,
            &mut out,
        )
        .unwrap();
        black_box(&out);
    });
    row("UYVY (IIDC, FireWire)", t, reference);

    for (name, p, _tile) in [
        ("Bayer RGGB (bilinear)", Bayer::Rggb, 512),
        ("Bayer GBRG (bilinear)", Bayer::Gbrg, 513),
        ("Bayer GRBG (bilinear)", Bayer::Grbg, 514),
        ("Bayer BGGR (bilinear)", Bayer::Bggr, 515),
    ] {
        let reference = libdc1394_bayer(&src[..n], _tile).map(|t| ("libdc1394", t));
        let t = median_ms(|| {
            pixfmt::bayer_to_bgr(&src[..n], W, H, p, &mut out).unwrap();
            black_box(&out);
        });
        row(name, t, reference);
    }
    let t = median_ms(|| {
        pixfmt::yuv420_to_bgr(&src[..n * 3 / 2], W, H, false, &mut out).unwrap();
        black_box(&out);
    });
    row("YUV420 (I420, BT.601)", t, None);
    let t = median_ms(|| {
        pixfmt::yuv411_to_bgr(&src[..n * 3 / 2], W, H, &mut out).unwrap();
        black_box(&out);
    });
    row("YUV411 (IIDC)", t, None);
    let t = median_ms(|| {
        pixfmt::rgb_to_bgr(&src, W, H, &mut out).unwrap();
        black_box(&out);
    });
    row("RGB24", t, None);
    let t = median_ms(|| {
        pixfmt::grey_to_bgr(&src[..n], W, H, &mut out).unwrap();
        black_box(&out);
    });
    row("GREY", t, None);
}
