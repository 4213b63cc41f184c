//! Runs jderobot's vision, colour and fuzzy operations on inputs written by
//! `scripts/compare_opencv.py`, writes the outputs next to them and prints the median
//! time of each op (milliseconds, one thread) as JSON. The script runs it once per
//! input frame and round: its synthetic scene and each photograph in `assets/photos/`
//! (a directory of inputs each).
//!
//! ```text
//! cargo run --release --example vision_compare -- DIR WIDTH HEIGHT REPEATS
//! ```
//! Inputs in DIR: `a.bgr`, `b.bgr` (raw BGR frames), `points.txt` (`x y` per line),
//! `homography.txt` (`sx sy dx dy` per line), `hsv.txt` (`hmin hmax smin smax vmin
//! vmax`, H in degrees), `edges.raw` (u8 edges for the Hough transforms), `calib.txt`
//! (`X Y Z U V`: a 3D pattern and its noisy pixels, for calibrador's solver),
//! `fuzzy.txt` (`var1 var2` per line, for `assets/fuzzy/example.fzz`), `a.yuyv`
//! (YUYV 4:2:2), `a.bayer` (RGGB mosaic).
//! Outputs: `rs_*.raw` (u8 or little-endian i16),
//! `rs_*.txt`.

#[path = "vision_common/mod.rs"]
mod vision_common;

use jderobot::{
    colorspaces::{HsvRange, Lookup, hsv_mask},
    fuzzy::{Controller, Inference},
    interfaces::Image,
    schemas::calibrador::calibrate,
    vision::{
        self, GrayImage, Kernel,
        pixfmt::{self, Bayer, Yuv422Order, YuvMatrix},
    },
};
use vision_common::Run;

/// `d` as little-endian bytes.
fn le_bytes(d: &[i16]) -> Vec<u8> {
    d.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn main() -> anyhow::Result<()> {
    let mut run = Run::from_args("vision_compare")?;
    let bgr = |name: &str| -> anyhow::Result<Image> {
        Ok(Image {
            width: run.w,
            height: run.h,
            data: run.frame(name, 3)?,
        })
    };
    let (a, b) = (bgr("a.bgr")?, bgr("b.bgr")?);
    let g = colour_and_edges(&mut run, &a)?;
    hough(&mut run)?;
    calibration(&mut run)?;
    filters(&mut run, &a)?;
    run.optical_flow_lk(&g, &vision::grayscale(&b))?;
    homography(&mut run, &a)?;
    pixel_formats(&mut run)?;
    fuzzy(&mut run)?;
    run.print_times();
    Ok(())
}

/// Grey, the HSV mask, Sobel and Canny; gives the grey frame.
fn colour_and_edges(run: &mut Run, a: &Image) -> anyhow::Result<GrayImage> {
    let g = run.time("gray", || vision::grayscale(a));
    run.write("rs_gray.raw", &g.data)?;

    let hv = &run.numbers("hsv.txt")?[0];
    let range = HsvRange {
        hmin: hv[0] as f32,
        hmax: hv[1] as f32,
        smin: hv[2] as f32,
        smax: hv[3] as f32,
        vmin: hv[4] as f32,
        vmax: hv[5] as f32,
    };
    let m = run.time("hsv_filter", || hsv_mask(a, &range, Lookup::Exact));
    run.write("rs_hsv.raw", &m.data)?;

    let (dx, dy) = run.time("sobel_dx_dy", || vision::sobel(&g));
    run.write("rs_sobel_dx.raw", le_bytes(&dx.data))?;
    run.write("rs_sobel_dy.raw", le_bytes(&dy.data))?;

    let e = run.time("canny", || vision::canny(&g, 50.0, 150.0, false));
    run.write("rs_canny.raw", &e.data)?;
    Ok(g)
}

/// Hough on OpenCV's Canny edges (edges.raw), so both sides vote the same points.
fn hough(run: &mut Run) -> anyhow::Result<()> {
    let edges = run.gray("edges.raw")?;
    let theta = std::f64::consts::PI / 180.0;
    let lines = run.time("hough_lines", || {
        vision::hough_lines(&edges, 1.0, theta, 80)
    });
    let s: String = lines
        .iter()
        .map(|l| format!("{} {}\n", l.rho, l.theta))
        .collect();
    run.write("rs_hough.txt", s)?;
    run.hough_lines_p(&edges)
}

/// calibrador's solver on `calib.txt` (X Y Z U V per line: a 3D pattern, noisy pixels).
fn calibration(run: &mut Run) -> anyhow::Result<()> {
    let cal = run.numbers("calib.txt")?;
    let world: Vec<[f64; 3]> = cal.iter().map(|r| [r[0], r[1], r[2]]).collect();
    let pix: Vec<(f64, f64)> = cal.iter().map(|r| (r[3], r[4])).collect();
    let c = run.time("calibrate", || calibrate(&world, &pix));
    let c = c.map_err(|e| anyhow::anyhow!("calibrate: {e}"))?;
    let pos = c.position();
    run.write(
        "rs_calib.txt",
        format!(
            "{} {} {} {} {} {} {} {}\n",
            c.rms, c.fx, c.fy, c.cx, c.cy, pos.x, pos.y, pos.z
        ),
    )
}

/// pyrDown and the bundled kernels.
fn filters(run: &mut Run, a: &Image) -> anyhow::Result<()> {
    let p = run.time("pyrdown", || vision::pyr_down(a));
    run.write("rs_pyrdown.raw", &p.data)?;
    for name in ["sharpen", "gaussian5", "edge"] {
        let k = Kernel::load(format!("assets/kernels/{name}.kernel"))?;
        let c = run.time(&format!("filter2d_{name}"), || vision::convolve(a, &k));
        run.write(&format!("rs_conv_{name}.raw"), &c.data)?;
    }
    Ok(())
}

/// findHomography on `homography.txt` (`sx sy dx dy` a line), then the warp.
fn homography(run: &mut Run, a: &Image) -> anyhow::Result<()> {
    let hp = run.numbers("homography.txt")?;
    let src: Vec<(f64, f64)> = hp.iter().map(|r| (r[0], r[1])).collect();
    let dst: Vec<(f64, f64)> = hp.iter().map(|r| (r[2], r[3])).collect();
    let hm = run.time("find_homography", || vision::find_homography(&src, &dst));
    let hm = hm.ok_or_else(|| anyhow::anyhow!("homography failed"))?;
    run.write(
        "rs_homography.txt",
        hm.transpose()
            .iter()
            .map(|v| format!("{v:e}"))
            .collect::<Vec<_>>()
            .join(" "),
    )?;
    let (w, h) = (run.w, run.h);
    let wp = run.time("warp_perspective", || {
        vision::warp_perspective(a, &hm, w, h)
    });
    run.write("rs_warp.raw", &wp.data)
}

/// Camera pixel formats → BGR (the drivers' conversions), into a reused buffer.
fn pixel_formats(run: &mut Run) -> anyhow::Result<()> {
    let (w, h) = (run.w, run.h);
    let yuyv = run.frame("a.yuyv", 2)?;
    let mut out = Vec::new();
    run.time("yuyv_bgr", || {
        pixfmt::yuv422_to_bgr(&yuyv, w, h, Yuv422Order::Yuyv, YuvMatrix::Bt601, &mut out)
            .expect("YUYV frame")
    });
    run.write("rs_yuyv.raw", &out)?;
    let bayer = run.frame("a.bayer", 1)?;
    run.time("bayer_bgr", || {
        pixfmt::bayer_to_bgr(&bayer, w, h, Bayer::Rggb, &mut out).expect("Bayer frame")
    });
    run.write("rs_bayer.raw", &out)
}

/// `assets/fuzzy/example.fzz` on `fuzzy.txt` (`var1 var2` a line), both inferences.
fn fuzzy(run: &mut Run) -> anyhow::Result<()> {
    let mut fz = Controller::from_file("assets/fuzzy/example.fzz")?;
    let inputs = run.numbers("fuzzy.txt")?;
    for (mode, name) in [(Inference::Jde, "jde"), (Inference::Mamdani, "mamdani")] {
        fz.set_inference(mode);
        let outs = run.time(&format!("fuzzy_{name}"), || {
            inputs
                .iter()
                .map(|v| {
                    fz.set_input("fuzzyvar1", v[0] as f32);
                    fz.set_input("fuzzyvar2", v[1] as f32);
                    fz.output("fuzzyvar3")
                })
                .collect::<Vec<_>>()
        });
        let s: String = outs
            .iter()
            .map(|o| match o {
                Some((v, n)) => format!("{v} {n}\n"),
                None => "nan 0\n".into(),
            })
            .collect();
        run.write(&format!("rs_fuzzy_{name}.txt"), s)?;
    }
    Ok(())
}
