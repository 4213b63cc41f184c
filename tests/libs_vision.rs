//! vision: each operation on a synthetic image with a known answer.

use jderobot::interfaces::Image;
use jderobot::vision::{
    self, Border, GrayImage, Kernel, LkParams, canny, convolve, find_homography, grayscale,
    optical_flow_pyr_lk, pyr_down, pyramid, sobel, sobel_with_border, warp_perspective,
};
use nalgebra::Matrix3;

fn gray_from(w: u32, h: u32, f: impl Fn(u32, u32) -> u8) -> GrayImage {
    let mut g = GrayImage::new(w, h);
    for y in 0..h {
        for x in 0..w {
            g.data[(y * w + x) as usize] = f(x, y);
        }
    }
    g
}

fn bgr_from(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) -> Image {
    let mut img = Image::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let i = ((y * w + x) * 3) as usize;
            img.data[i..i + 3].copy_from_slice(&f(x, y));
        }
    }
    img
}

#[test]
fn grayscale_weights() {
    let img = bgr_from(4, 1, |x, _| {
        [[255, 0, 0], [0, 255, 0], [0, 0, 255], [200, 200, 200]][x as usize]
    });
    // 0.114 B, 0.587 G, 0.299 R, rounded; greys stay.
    assert_eq!(grayscale(&img).data, vec![29, 150, 76, 200]);
    assert_eq!(
        grayscale(&Image {
            width: 5,
            height: 5,
            data: vec![1, 2]
        }),
        GrayImage::default()
    );
}

#[test]
fn sobel_on_a_ramp_and_a_step() {
    // Horizontal ramp of slope 2: dx = 2*(1+2+1)*2 = 16 inside, dy = 0.
    let g = gray_from(8, 6, |x, _| (x * 2) as u8);
    let (dx, dy) = sobel(&g);
    assert_eq!(dx.data[2 * 8 + 3], 16);
    assert!(dy.data.iter().all(|&v| v == 0));
    // Reflect-101 borders: the first and last columns see a symmetric neighbourhood.
    assert_eq!(dx.data[8], 0);
    assert_eq!(dx.data[8 + 7], 0);
    // Replicate border: the first column sees x-1 == x, so dx = (2-0)*4 = 8.
    let (rx, _) = sobel_with_border(&g, Border::Replicate);
    assert_eq!(rx.data[8], 8);
    // A vertical step of 100 between rows 2 and 3: dy = 100*4 at rows 2 and 3.
    let s = gray_from(5, 6, |_, y| if y < 3 { 0 } else { 100 });
    let (_, dy) = sobel(&s);
    assert_eq!(
        (dy.data[5 * 2 + 2], dy.data[5 * 3 + 2], dy.data[5 + 2]),
        (400, 400, 0)
    );
    assert_eq!(dy.to_abs_u8().data[5 * 2 + 2], 255);
}

#[test]
fn canny_finds_the_border_of_a_square() {
    let g = gray_from(40, 40, |x, y| {
        if (10..30).contains(&x) && (10..30).contains(&y) {
            200
        } else {
            20
        }
    });
    let e = canny(&g, 50.0, 150.0, false);
    let on = |x: u32, y: u32| e.get(x, y) == 255;
    // Edges on the square's sides, one pixel wide, nothing in flat areas.
    assert!(on(10, 20) || on(9, 20));
    assert!(on(29, 20) || on(30, 20));
    assert!(on(20, 10) || on(20, 9));
    assert!(!on(20, 20) && !on(2, 2) && !on(37, 37));
    let row: usize = (0..40).filter(|&x| on(x, 20)).count();
    assert_eq!(row, 2);
    // High thresholds above every gradient: nothing.
    assert!(canny(&g, 5000.0, 9000.0, true).data.iter().all(|&v| v == 0));
}

#[test]
fn pyr_down_of_flat_and_checker_images() {
    let flat = bgr_from(9, 7, |_, _| [10, 100, 250]);
    let p = pyr_down(&flat);
    assert_eq!((p.width, p.height), (5, 4));
    assert!(p.data.chunks(3).all(|c| c == [10, 100, 250]));
    // A fine checkerboard of 0/255 averages to grey ~128 (the 5x5 Gaussian of a
    // checker: (1-4+6-4+1)^2 = 0 deviation from the mean except at borders).
    let ch = bgr_from(
        16,
        16,
        |x, y| if (x + y) % 2 == 0 { [255; 3] } else { [0; 3] },
    );
    let p = pyr_down(&ch);
    let v = p.data[(2 * 8 + 3) * 3];
    assert!((v as i32 - 128).abs() <= 1, "{v}");
    let levels = pyramid(&ch, 3);
    let sizes: Vec<(u32, u32)> = levels.iter().map(|i| (i.width, i.height)).collect();
    assert_eq!(sizes, vec![(16, 16), (8, 8), (4, 4), (2, 2)]);
}

#[test]
fn convolution_with_the_seed_kernels() {
    let sharpen = Kernel::load("assets/kernels/sharpen.kernel").unwrap();
    assert_eq!(
        sharpen.values,
        vec![0.0, -1.0, 0.0, -1.0, 5.0, -1.0, 0.0, -1.0, 0.0]
    );
    let flat = bgr_from(6, 5, |_, _| [40, 80, 120]);
    // Kernels summing to 1 leave a flat image unchanged.
    for k in ["sharpen", "blur", "gaussian3", "gaussian5"] {
        let k = Kernel::load(format!("assets/kernels/{k}.kernel")).unwrap();
        assert_eq!(convolve(&flat, &k), flat, "{k:?}");
    }
    // The edge kernel sums to 0: a flat image becomes the offset (128).
    let edge = Kernel::load("assets/kernels/edge.kernel").unwrap();
    assert!(convolve(&flat, &edge).data.iter().all(|&v| v == 128));
    // A single bright pixel through sharpen: 5x at the centre (saturated), -v at
    // its 4 neighbours (clamped to 0), untouched elsewhere.
    let dot = bgr_from(5, 5, |x, y| {
        if (x, y) == (2, 2) {
            [40, 40, 40]
        } else {
            [0; 3]
        }
    });
    let out = convolve(&dot, &sharpen);
    assert_eq!(out.pixel(2, 2), [200, 200, 200]);
    assert_eq!(out.pixel(1, 2), [0, 0, 0]);
    let emboss = Kernel::load("assets/kernels/emboss.kernel").unwrap();
    assert_eq!(emboss.values.iter().sum::<f32>(), 1.0);
    // opencvdemo's default kernel when the conf has none.
    assert_eq!(
        Kernel::parse("hmax 4.5\n", std::path::Path::new("c")).unwrap(),
        Kernel::default()
    );
    let k = Kernel::parse(&sharpen.to_file_string(), std::path::Path::new("again")).unwrap();
    assert_eq!(k, sharpen);
}

#[test]
fn kernel_file_errors() {
    let p = std::path::Path::new("k.conf");
    let err = |t: &str| Kernel::parse(t, p).unwrap_err().to_string();
    assert_eq!(
        err("size 4\n"),
        "k.conf:1: `size 4`: must be odd, from 1 to 15 (4.3: 3 or 5)"
    );
    assert_eq!(
        err("size 3\nrow 1 1 2\n"),
        "k.conf:2: `row 1` has 2 values; `size 3` needs 3"
    );
    assert_eq!(
        err("size 3\nrow 4 1 2 3\n"),
        "k.conf:2: `row 4`: the kernel has only 3 rows"
    );
    assert_eq!(
        err("size 3\nrow 1 1 2 3\n"),
        "k.conf: missing `row` lines: 2, 3"
    );
    assert_eq!(
        err("modulo x\n"),
        "k.conf:1: `modulo x`: expected an integer divisor"
    );
    assert_eq!(
        err("row 1 1\n"),
        "k.conf: `row` lines without a `size` line"
    );
}

#[test]
fn optical_flow_tracks_a_known_shift() {
    // A smooth textured pattern moved by (1.5, -0.75) pixels.
    let f = |x: f32, y: f32| {
        (128.0 + 60.0 * (x / 7.0).sin() * (y / 9.0).cos() + 40.0 * ((x + y) / 13.0).sin()) as u8
    };
    let (w, h) = (120u32, 100u32);
    let prev = gray_from(w, h, |x, y| f(x as f32, y as f32));
    let next = gray_from(w, h, |x, y| f(x as f32 - 1.5, y as f32 + 0.75));
    let pts: Vec<(f32, f32)> = vec![(40.0, 40.0), (60.5, 50.25), (80.0, 60.0)];
    let out = optical_flow_pyr_lk(&prev, &next, &pts, &LkParams::default());
    for (p, t) in pts.iter().zip(&out) {
        assert!(t.found, "{t:?}");
        assert!(
            (t.x - (p.0 + 1.5)).abs() < 0.1 && (t.y - (p.1 - 0.75)).abs() < 0.1,
            "{p:?} -> {t:?}"
        );
    }
    // A point in a flat area has no gradient: lost. A point far outside: lost.
    let flat = GrayImage {
        data: vec![90; (w * h) as usize],
        ..prev.clone()
    };
    let out = optical_flow_pyr_lk(&flat, &flat, &[(50.0, 50.0)], &LkParams::default());
    assert!(!out[0].found);
    let out = optical_flow_pyr_lk(
        &prev,
        &next,
        &[(-500.0, 10.0), (f32::NAN, 1.0)],
        &LkParams::default(),
    );
    assert!(out.iter().all(|t| !t.found));
}

#[test]
fn homography_from_four_points_and_warp() {
    // imgrectifier: four clicked corners of a quadrilateral -> a rectangle.
    let src = [(10.0, 5.0), (50.0, 8.0), (55.0, 40.0), (6.0, 35.0)];
    let dst = [(0.0, 0.0), (63.0, 0.0), (63.0, 47.0), (0.0, 47.0)];
    let h = find_homography(&src, &dst).unwrap();
    for (s, d) in src.iter().zip(&dst) {
        let p = h * nalgebra::Vector3::new(s.0, s.1, 1.0);
        assert!((p.x / p.z - d.0).abs() < 1e-9 && (p.y / p.z - d.1).abs() < 1e-9);
    }
    assert!(find_homography(&src[..3], &dst[..3]).is_none());
    let collinear = [(0.0, 0.0), (1.0, 1.0), (2.0, 2.0), (3.0, 3.0)];
    assert!(find_homography(&collinear, &dst).is_none());
    // Warping by a pure translation of (+2, +1) moves the pixels exactly.
    let img = bgr_from(8, 6, |x, y| [(x * 10) as u8, (y * 20) as u8, 7]);
    let t = Matrix3::new(1.0, 0.0, 2.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0);
    let out = warp_perspective(&img, &t, 8, 6);
    assert_eq!(out.pixel(5, 4), img.pixel(3, 3));
    assert_eq!(out.pixel(0, 0), [0, 0, 0]); // outside the source: black
    // Half-pixel shift: the average of two neighbours.
    let half = Matrix3::new(1.0, 0.0, 0.5, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
    let out = warp_perspective(&img, &half, 8, 6);
    assert_eq!(out.pixel(4, 2)[0], 35);
    // A singular matrix gives a black image rather than a panic.
    assert!(
        warp_perspective(&img, &Matrix3::zeros(), 8, 6)
            .data
            .iter()
            .all(|&v| v == 0)
    );
}

#[test]
fn is_valid_checks_sizes() {
    assert!(vision::is_valid(&Image::new(3, 2)));
    assert!(!vision::is_valid(&Image {
        width: 3,
        height: 2,
        data: vec![0; 5]
    }));
}
