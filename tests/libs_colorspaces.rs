//! colorspaces: conversions at primaries and greys, tables, filters.

use jderobot::colorspaces::{
    Background, ColourFilter, Hsv, HsvRange, Lookup, RgbRange, Yuv, YuvRange, filter, hsv_mask,
    hsv_table, hsv2rgb, hsv2rgb_u8, mask, rgb2hsv, rgb2yuv, yuv_table, yuv2rgb,
};
use jderobot::interfaces::Image;

fn hsv(h: f32, s: f32, v: f32) -> Hsv {
    Hsv { h, s, v }
}

#[test]
fn hsv_at_primaries_secondaries_and_greys() {
    assert_eq!(rgb2hsv(255, 0, 0), hsv(0.0, 1.0, 255.0));
    assert_eq!(rgb2hsv(0, 255, 0), hsv(120.0, 1.0, 255.0));
    assert_eq!(rgb2hsv(0, 0, 255), hsv(240.0, 1.0, 255.0));
    assert_eq!(rgb2hsv(255, 255, 0), hsv(60.0, 1.0, 255.0));
    assert_eq!(rgb2hsv(0, 255, 255), hsv(180.0, 1.0, 255.0));
    assert_eq!(rgb2hsv(255, 0, 255), hsv(300.0, 1.0, 255.0));
    for g in [0u8, 1, 128, 255] {
        assert_eq!(rgb2hsv(g, g, g), hsv(0.0, 0.0, g as f32));
    }
    // Half-saturated orange: H = 60*(g-b)/(max-min) = 60*64/128 = 30.
    assert_eq!(rgb2hsv(200, 136, 72), hsv(30.0, 0.64, 200.0));
    // max == r and g < b: the +360 branch.
    assert_eq!(rgb2hsv(255, 0, 51).h, 348.0);
}

#[test]
fn hsv_round_trips() {
    for (r, g, b) in [
        (255, 0, 0),
        (0, 255, 0),
        (0, 0, 255),
        (12, 200, 99),
        (250, 250, 250),
        (7, 3, 200),
    ] {
        assert_eq!(hsv2rgb_u8(rgb2hsv(r, g, b)), (r, g, b));
    }
    let (r, g, b) = hsv2rgb(hsv(0.0, 0.0, 100.0));
    assert_eq!((r, g, b), (100.0, 100.0, 100.0));
}

#[test]
fn yuv_at_primaries_and_greys() {
    let close = |a: Yuv, b: Yuv| {
        (a.y - b.y).abs() < 1e-6 && (a.u - b.u).abs() < 1e-6 && (a.v - b.v).abs() < 1e-6
    };
    assert!(close(
        rgb2yuv(255, 0, 0),
        Yuv {
            y: 0.299,
            u: -0.14713,
            v: 0.615
        }
    ));
    assert!(close(
        rgb2yuv(0, 255, 0),
        Yuv {
            y: 0.587,
            u: -0.289,
            v: -0.515
        }
    ));
    assert!(close(
        rgb2yuv(0, 0, 255),
        Yuv {
            y: 0.114,
            u: 0.436,
            v: -0.100
        }
    ));
    // 4.3's coefficients leave white at U = 0.00013 (they do not sum to exactly 0).
    let white = rgb2yuv(255, 255, 255);
    assert!((white.y - 1.0).abs() < 1e-6 && white.u.abs() < 2e-4 && white.v.abs() < 1e-6);
    let grey = rgb2yuv(128, 128, 128);
    assert!((grey.y - 128.0 / 255.0).abs() < 1e-6 && grey.u.abs() < 1e-4 && grey.v.abs() < 1e-6);
    let (r, g, b) = yuv2rgb(rgb2yuv(200, 100, 50));
    assert!(
        (r * 255.0 - 200.0).abs() < 1.0
            && (g * 255.0 - 100.0).abs() < 1.0
            && (b * 255.0 - 50.0).abs() < 1.0
    );
    assert_eq!(
        yuv2rgb(Yuv {
            y: 2.0,
            u: 0.0,
            v: 0.0
        }),
        (1.0, 1.0, 1.0)
    );
}

#[test]
fn tables_hold_the_lower_corner_of_each_bin_and_are_shared() {
    let t = hsv_table();
    assert!(std::ptr::eq(t, hsv_table()));
    assert_eq!(t.get(255, 0, 0), rgb2hsv(252, 0, 0));
    assert_eq!(t.get(130, 66, 3), rgb2hsv(128, 64, 0));
    assert_eq!(yuv_table().get(7, 7, 7), rgb2yuv(4, 4, 4));
    // Built once even when many threads ask at the same time.
    let ptrs: Vec<usize> = std::thread::scope(|s| {
        let hs: Vec<_> = (0..4)
            .map(|_| s.spawn(|| hsv_table() as *const _ as usize))
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert!(ptrs.iter().all(|&p| p == ptrs[0]));
}

fn strip() -> Image {
    // Pixels (BGR): red, green, blue, grey, dark red, orange.
    let px: [[u8; 3]; 6] = [
        [0, 0, 255],
        [0, 255, 0],
        [255, 0, 0],
        [128, 128, 128],
        [0, 0, 60],
        [0, 128, 255],
    ];
    Image {
        width: 6,
        height: 1,
        data: px.concat(),
    }
}

#[test]
fn hsv_filter_with_wrapping_hue() {
    let img = strip();
    // Reds: hue 340..20 degrees wraps through 0; saturated; bright.
    let reds = HsvRange {
        hmin: 340.0,
        hmax: 20.0,
        smin: 0.5,
        smax: 1.0,
        vmin: 100.0,
        vmax: 255.0,
    };
    assert_eq!(
        hsv_mask(&img, &reds, Lookup::Exact).data,
        vec![255, 0, 0, 0, 0, 0]
    );
    assert_eq!(
        hsv_mask(&img, &reds, Lookup::Table).data,
        vec![255, 0, 0, 0, 0, 0]
    );
    // Not wrapping: 100..140 keeps green.
    let greens = HsvRange {
        hmin: 100.0,
        hmax: 140.0,
        ..reds
    };
    assert_eq!(
        hsv_mask(&img, &greens, Lookup::Exact).data,
        vec![0, 255, 0, 0, 0, 0]
    );
    // hsvtuner's views: others black, or grey at V*180/255.
    let out = filter(
        &img,
        &ColourFilter::Hsv(reds),
        Lookup::Exact,
        Background::Black,
    );
    assert_eq!(&out.data[..6], &[0, 0, 255, 0, 0, 0]);
    let out = filter(
        &img,
        &ColourFilter::Hsv(reds),
        Lookup::Exact,
        Background::Grey,
    );
    assert_eq!(&out.data[9..12], &[90, 90, 90]); // grey 128 -> 128*180/255 = 90
    assert_eq!(&out.data[15..18], &[180, 180, 180]); // orange, V = 255
    // From 4.3's radians (opencvdemo conf: hmin 3.3 .. hmax 4.5 rad).
    let r = HsvRange::from_radians(3.3, 4.5, 0.2, 1.0, 80.0, 255.0);
    assert!((r.hmin - 189.076).abs() < 1e-3 && (r.hmax - 257.831).abs() < 1e-3);
    assert_eq!(
        hsv_mask(&img, &r, Lookup::Exact).data,
        vec![0, 0, 255, 0, 0, 0]
    );
}

#[test]
fn rgb_and_yuv_filters() {
    let img = strip();
    let bright_red = RgbRange {
        rmin: 200,
        rmax: 255,
        gmin: 0,
        gmax: 50,
        bmin: 0,
        bmax: 50,
    };
    assert_eq!(
        mask(&img, &ColourFilter::Rgb(bright_red), Lookup::Exact).data,
        vec![255, 0, 0, 0, 0, 0]
    );
    // Greys: |U|, |V| small.
    let greys = YuvRange {
        ymin: 0.0,
        ymax: 1.0,
        umin: -0.02,
        umax: 0.02,
        vmin: -0.02,
        vmax: 0.02,
    };
    assert_eq!(
        mask(&img, &ColourFilter::Yuv(greys), Lookup::Exact).data,
        vec![0, 0, 0, 255, 0, 0]
    );
    assert_eq!(
        mask(&img, &ColourFilter::Yuv(greys), Lookup::Table).data,
        vec![0, 0, 0, 255, 0, 0]
    );
}
