//! firewire driver and the IIDC/Bayer conversions, against the system's real
//! libdc1394 2.x: this machine has no IEEE 1394 bus, so the driver's
//! "no bus / no camera" path runs for real; the conversions are compared byte for
//! byte with libdc1394's own `dc1394_convert_to_RGB8` (the function
//! `dc1394_convert_frames` calls for YUV and RGB) and `dc1394_bayer_decoding_8bit`
//! (BILINEAR), called through the driver's FFI module.
#![cfg(feature = "firewire")]

use crate::common;

use std::{
    path::Path,
    sync::{Arc, Mutex},
    time::Duration,
};

use jderobot::{
    ComponentConf, Conf, Kind,
    drivers::firewire::{self, ffi},
    interfaces::Image,
    vision::pixfmt::{self, Bayer, Yuv422Order, YuvMatrix},
};

/// A deterministic pseudo-random frame of `n` bytes covering all byte values.
fn noise(n: usize, seed: u32) -> Vec<u8> {
    common::Rng::new(seed as u64).bytes(n)
}

fn rgb_to_bgr_inplace(v: &mut [u8]) {
    for p in v.chunks_exact_mut(3) {
        p.swap(0, 2);
    }
}

fn dc1394_rgb8(src: &[u8], w: u32, h: u32, order: u32, coding: i32) -> Vec<u8> {
    let mut s = src.to_vec();
    let mut out = vec![0u8; (w * h * 3) as usize];
    // SAFETY: buffers sized for the coding; libdc1394 reads w*h pixels of `coding`.
    let e = unsafe {
        ffi::dc1394_convert_to_RGB8(s.as_mut_ptr(), out.as_mut_ptr(), w, h, order, coding, 8)
    };
    assert_eq!(e, ffi::DC1394_SUCCESS, "{}", ffi::error_string(e));
    rgb_to_bgr_inplace(&mut out);
    out
}

#[test]
fn yuv422_iidc_equals_libdc1394() {
    for (w, h) in [(640u32, 480u32), (320, 240), (6, 3)] {
        let src = noise((w * h * 2) as usize, w + h);
        for (order, o) in [
            (ffi::DC1394_BYTE_ORDER_UYVY, Yuv422Order::Uyvy),
            (ffi::DC1394_BYTE_ORDER_YUYV, Yuv422Order::Yuyv),
        ] {
            let want = dc1394_rgb8(&src, w, h, order, ffi::DC1394_COLOR_CODING_YUV422);
            let mut got = Vec::new();
            pixfmt::yuv422_to_bgr(&src, w, h, o, YuvMatrix::Iidc, &mut got).unwrap();
            assert!(got == want, "YUV422 {o:?} {w}x{h} differs from libdc1394");
        }
    }
}

#[test]
fn yuv411_yuv444_rgb8_mono8_equal_libdc1394() {
    let (w, h) = (640u32, 480u32);
    let cases: [(i32, usize); 4] = [
        (ffi::DC1394_COLOR_CODING_YUV411, 3 * (w * h) as usize / 2),
        (ffi::DC1394_COLOR_CODING_YUV444, 3 * (w * h) as usize),
        (ffi::DC1394_COLOR_CODING_RGB8, 3 * (w * h) as usize),
        (ffi::DC1394_COLOR_CODING_MONO8, (w * h) as usize),
    ];
    for (coding, n) in cases {
        let src = noise(n, coding as u32);
        let want = dc1394_rgb8(&src, w, h, ffi::DC1394_BYTE_ORDER_UYVY, coding);
        let mut got = Vec::new();
        firewire::convert_frame(
            &src,
            w,
            h,
            coding,
            ffi::DC1394_BYTE_ORDER_UYVY,
            0,
            None,
            &mut got,
        )
        .unwrap();
        assert!(got == want, "coding {coding} differs from libdc1394");
    }
}

#[test]
fn bayer_equals_libdc1394_bilinear_in_all_four_patterns() {
    let pats = [
        (Bayer::Rggb, ffi::DC1394_COLOR_FILTER_RGGB),
        (Bayer::Gbrg, ffi::DC1394_COLOR_FILTER_GBRG),
        (Bayer::Grbg, ffi::DC1394_COLOR_FILTER_GRBG),
        (Bayer::Bggr, ffi::DC1394_COLOR_FILTER_BGGR),
    ];
    for (w, h) in [(640u32, 480u32), (320, 240), (8, 6)] {
        let src = noise((w * h) as usize, 7 * w + h);
        for (p, tile) in pats {
            let mut want = vec![0u8; (w * h * 3) as usize];
            // SAFETY: w*h bytes in, w*h*3 out.
            let e = unsafe {
                ffi::dc1394_bayer_decoding_8bit(
                    src.as_ptr(),
                    want.as_mut_ptr(),
                    w,
                    h,
                    tile,
                    ffi::DC1394_BAYER_METHOD_BILINEAR,
                )
            };
            assert_eq!(e, ffi::DC1394_SUCCESS);
            rgb_to_bgr_inplace(&mut want);
            let mut got = Vec::new();
            pixfmt::bayer_to_bgr(&src, w, h, p, &mut got).unwrap();
            if got != want {
                let i = got.iter().zip(&want).position(|(a, b)| a != b).unwrap();
                let px = i / 3;
                panic!(
                    "Bayer {p:?} {w}x{h}: first difference at x={} y={} channel {}: ours {} libdc1394 {}",
                    px % w as usize,
                    px / w as usize,
                    i % 3,
                    got[i],
                    want[i]
                );
            }
            // The driver's RAW8 path picks the pattern from the frame's filter.
            let mut raw = Vec::new();
            firewire::convert_frame(
                &src,
                w,
                h,
                ffi::DC1394_COLOR_CODING_RAW8,
                0,
                tile,
                None,
                &mut raw,
            )
            .unwrap();
            assert!(raw == want);
        }
    }
}

#[test]
fn conf_lines_are_checked() {
    let parse =
        |t: &str| firewire::parse(&ComponentConf::from_text(Kind::Driver, "firewire", t).unwrap());
    let c = parse("provides varcolorA 0 640 480 autofocus_off\nprovides colorB 1 autofocus_on\nbayer 1 gbrg\n")
        .unwrap();
    assert_eq!(
        (c[0].cam, c[0].width, c[0].height, c[0].autofocus),
        (0, 640, 480, Some(false))
    );
    assert_eq!(
        (c[1].cam, c[1].width, c[1].height, c[1].autofocus),
        (1, 320, 240, Some(true))
    );
    assert_eq!((c[0].bayer, c[1].bayer), (None, Some(Bayer::Gbrg)));
    for (bad, says) in [
        ("provides colorA zero\n", "camera number"),
        ("provides varcolorA 0 640\n", "usage"),
        (
            "provides colorA 0 autofocus_maybe\n",
            "autofocus_on or autofocus_off",
        ),
        ("provides laser 0\n", "colorA..D or varcolorA..D"),
        ("provides colorA 0\nbayer 0 RGBG\n", "not a Bayer pattern"),
        ("framerate 30\n", "takes no `framerate` line"),
        ("", "no `provides` line"),
    ] {
        let e = parse(bad).unwrap_err().to_string();
        assert!(e.contains(says), "`{bad}` gave: {e}");
    }
}

/// No IEEE 1394 bus here: the driver says so (conf line, camera number, what
/// libdc1394 found) and the interface is stale with that reason; jderobot runs on
/// and would pick the camera up when it appears. Through `firewire22` as well.
#[test]
fn no_bus_or_no_camera_is_a_clear_error_and_a_stale_interface() {
    let printed = Arc::new(Mutex::new(Vec::<String>::new()));
    let p2 = printed.clone();
    jderobot::output::set_sink(Some(Box::new(move |l| p2.lock().unwrap().push(l))));
    for name in ["firewire", "firewire22"] {
        let text = format!(
            "driver {name}\nprovides varcolorA 7 640 480 autofocus_off\nend_driver\nload_driver {name}\n"
        );
        let conf = Conf::parse(&text, Path::new("fw.conf")).unwrap();
        let rt = jderobot::loader::start(&conf).unwrap_or_else(|e| panic!("{e}"));
        let img = rt.interfaces.get::<Image>("varcolorA").unwrap();
        let why = img.stale().expect("stale from the start");
        println!("{name}: stale: {why}");
        assert!(why.contains("camera 7"), "{why}");
        assert!(
            why.contains("no IEEE 1394 bus") || why.contains("libdc1394 found"),
            "{why}"
        );
        // Used: the capture thread tries again, fails the same way, no frame, no panic.
        img.resume();
        std::thread::sleep(Duration::from_millis(600));
        assert_eq!(img.clock(), 0);
        assert!(img.stale().is_some_and(|w| w.contains("camera 7")));
        img.suspend();
        rt.shutdown();
    }
    jderobot::output::set_sink(None);
    let printed = printed.lock().unwrap().join("\n");
    println!("{printed}");
    assert!(
        printed.contains("fw.conf:2: driver firewire: camera 7"),
        "{printed}"
    );
    assert!(
        printed.contains("fw.conf:2: driver firewire22: camera 7"),
        "{printed}"
    );
    assert!(
        printed.contains("stays stale until camera 7 appears"),
        "{printed}"
    );
    // And the probe itself.
    let e = firewire::probe(0);
    println!("probe(0): {e:?}");
    if !Path::new("/dev/fw0").exists() {
        assert!(e.unwrap_err().contains("camera 0"));
    }
}

/// examples/firewire.conf parses and its driver lines are the driver's.
#[test]
fn the_example_conf_parses() {
    let conf = Conf::load(&common::root().join("examples/firewire.conf")).unwrap();
    let c = conf.component_conf(Kind::Driver, "firewire", None).unwrap();
    let cams = firewire::parse(&c).unwrap();
    assert_eq!((cams[0].iface.as_str(), cams[0].width), ("varcolorA", 640));
}
