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

use std::{fs, path::Path, time::Instant};

use jderobot::{
    colorspaces::{HsvRange, Lookup, hsv_mask},
    fuzzy::{Controller, Inference},
    interfaces::Image,
    schemas::calibrador::calibrate,
    vision::{
        self, Kernel, LkParams,
        pixfmt::{self, Bayer, Yuv422Order, YuvMatrix},
    },
};

fn median_ms<T>(repeats: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut out = f(); // warm-up
    let mut times = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let t = Instant::now();
        out = std::hint::black_box(f());
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    (times[times.len() / 2], out)
}

fn numbers(path: &Path) -> anyhow::Result<Vec<Vec<f64>>> {
    let text = fs::read_to_string(path)?;
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split_whitespace()
                .map(|w| {
                    w.parse::<f64>()
                        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
                })
                .collect()
        })
        .collect()
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 5 {
        anyhow::bail!("usage: vision_compare DIR WIDTH HEIGHT REPEATS");
    }
    let dir = Path::new(&args[1]);
    let (w, h): (u32, u32) = (args[2].parse()?, args[3].parse()?);
    let repeats: usize = args[4].parse()?;
    let load = |name: &str| -> anyhow::Result<Image> {
        let data = fs::read(dir.join(name))?;
        anyhow::ensure!(data.len() == (w * h * 3) as usize, "{name}: wrong size");
        Ok(Image {
            width: w,
            height: h,
            data,
        })
    };
    let a = load("a.bgr")?;
    let b = load("b.bgr")?;
    let mut times: Vec<(String, f64)> = Vec::new();
    let write_u8 = |name: &str, d: &[u8]| fs::write(dir.join(name), d);
    let write_i16 = |name: &str, d: &[i16]| {
        fs::write(
            dir.join(name),
            d.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>(),
        )
    };

    let (t, g) = median_ms(repeats, || vision::grayscale(&a));
    times.push(("gray".into(), t));
    write_u8("rs_gray.raw", &g.data)?;

    let hv = &numbers(&dir.join("hsv.txt"))?[0];
    let range = HsvRange {
        hmin: hv[0] as f32,
        hmax: hv[1] as f32,
        smin: hv[2] as f32,
        smax: hv[3] as f32,
        vmin: hv[4] as f32,
        vmax: hv[5] as f32,
    };
    let (t, m) = median_ms(repeats, || hsv_mask(&a, &range, Lookup::Exact));
    times.push(("hsv_filter".into(), t));
    write_u8("rs_hsv.raw", &m.data)?;

    let (t, (dx, dy)) = median_ms(repeats, || vision::sobel(&g));
    times.push(("sobel_dx_dy".into(), t));
    write_i16("rs_sobel_dx.raw", &dx.data)?;
    write_i16("rs_sobel_dy.raw", &dy.data)?;

    let (t, e) = median_ms(repeats, || vision::canny(&g, 50.0, 150.0, false));
    times.push(("canny".into(), t));
    write_u8("rs_canny.raw", &e.data)?;

    // Hough on OpenCV's Canny edges (edges.raw), so both sides vote the same points.
    let edges = vision::GrayImage {
        width: w,
        height: h,
        data: fs::read(dir.join("edges.raw"))?,
    };
    anyhow::ensure!(
        edges.data.len() == (w * h) as usize,
        "edges.raw: wrong size"
    );
    let theta = std::f64::consts::PI / 180.0;
    let (t, lines) = median_ms(repeats, || vision::hough_lines(&edges, 1.0, theta, 80));
    times.push(("hough_lines".into(), t));
    let s: String = lines
        .iter()
        .map(|l| format!("{} {}\n", l.rho, l.theta))
        .collect();
    fs::write(dir.join("rs_hough.txt"), s)?;
    let (t, segs) = median_ms(repeats, || {
        vision::hough_lines_p(&edges, 1.0, theta, 50, 30, 5)
    });
    times.push(("hough_lines_p".into(), t));
    let s: String = segs
        .iter()
        .map(|l| format!("{} {} {} {}\n", l.x1, l.y1, l.x2, l.y2))
        .collect();
    fs::write(dir.join("rs_houghp.txt"), s)?;

    // calibrador's solver on `calib.txt` (X Y Z U V per line: a 3D pattern, noisy pixels).
    let cal = numbers(&dir.join("calib.txt"))?;
    let world: Vec<[f64; 3]> = cal.iter().map(|r| [r[0], r[1], r[2]]).collect();
    let pix: Vec<(f64, f64)> = cal.iter().map(|r| (r[3], r[4])).collect();
    let (t, c) = median_ms(repeats, || calibrate(&world, &pix));
    times.push(("calibrate".into(), t));
    let c = c.map_err(|e| anyhow::anyhow!("calibrate: {e}"))?;
    let pos = c.position();
    fs::write(
        dir.join("rs_calib.txt"),
        format!(
            "{} {} {} {} {} {} {} {}\n",
            c.rms, c.fx, c.fy, c.cx, c.cy, pos.x, pos.y, pos.z
        ),
    )?;

    let (t, p) = median_ms(repeats, || vision::pyr_down(&a));
    times.push(("pyrdown".into(), t));
    write_u8("rs_pyrdown.raw", &p.data)?;

    for name in ["sharpen", "gaussian5", "edge"] {
        let k = Kernel::load(format!("assets/kernels/{name}.kernel"))?;
        let (t, c) = median_ms(repeats, || vision::convolve(&a, &k));
        times.push((format!("filter2d_{name}"), t));
        write_u8(&format!("rs_conv_{name}.raw"), &c.data)?;
    }

    let pts: Vec<(f32, f32)> = numbers(&dir.join("points.txt"))?
        .iter()
        .map(|p| (p[0] as f32, p[1] as f32))
        .collect();
    let gb = vision::grayscale(&b);
    let (t, tracked) = median_ms(repeats, || {
        vision::optical_flow_pyr_lk(&g, &gb, &pts, &LkParams::default())
    });
    times.push(("optical_flow_lk".into(), t));
    let mut s = String::new();
    for p in &tracked {
        s += &format!("{} {} {} {}\n", p.x, p.y, p.found as u8, p.error);
    }
    fs::write(dir.join("rs_lk.txt"), s)?;

    let hp = numbers(&dir.join("homography.txt"))?;
    let src: Vec<(f64, f64)> = hp.iter().map(|r| (r[0], r[1])).collect();
    let dst: Vec<(f64, f64)> = hp.iter().map(|r| (r[2], r[3])).collect();
    let (t, hm) = median_ms(repeats, || vision::find_homography(&src, &dst));
    times.push(("find_homography".into(), t));
    let hm = hm.ok_or_else(|| anyhow::anyhow!("homography failed"))?;
    fs::write(
        dir.join("rs_homography.txt"),
        hm.transpose()
            .iter()
            .map(|v| format!("{v:e}"))
            .collect::<Vec<_>>()
            .join(" "),
    )?;
    let (t, wp) = median_ms(repeats, || vision::warp_perspective(&a, &hm, w, h));
    times.push(("warp_perspective".into(), t));
    write_u8("rs_warp.raw", &wp.data)?;

    // Camera pixel formats → BGR (the drivers' conversions), into a reused buffer.
    let yuyv = fs::read(dir.join("a.yuyv"))?;
    let mut out = Vec::new();
    let (t, ()) = median_ms(repeats, || {
        pixfmt::yuv422_to_bgr(&yuyv, w, h, Yuv422Order::Yuyv, YuvMatrix::Bt601, &mut out)
            .expect("YUYV frame")
    });
    times.push(("yuyv_bgr".into(), t));
    write_u8("rs_yuyv.raw", &out)?;
    let bayer = fs::read(dir.join("a.bayer"))?;
    let (t, ()) = median_ms(repeats, || {
        pixfmt::bayer_to_bgr(&bayer, w, h, Bayer::Rggb, &mut out).expect("Bayer frame")
    });
    times.push(("bayer_bgr".into(), t));
    write_u8("rs_bayer.raw", &out)?;

    let mut fz = Controller::from_file("assets/fuzzy/example.fzz")?;
    let inputs = numbers(&dir.join("fuzzy.txt"))?;
    for (mode, name) in [(Inference::Jde, "jde"), (Inference::Mamdani, "mamdani")] {
        fz.set_inference(mode);
        let (t, outs) = median_ms(repeats, || {
            inputs
                .iter()
                .map(|v| {
                    fz.set_input("fuzzyvar1", v[0] as f32);
                    fz.set_input("fuzzyvar2", v[1] as f32);
                    fz.output("fuzzyvar3")
                })
                .collect::<Vec<_>>()
        });
        times.push((format!("fuzzy_{name}"), t));
        let s: String = outs
            .iter()
            .map(|o| match o {
                Some((v, n)) => format!("{v} {n}\n"),
                None => "nan 0\n".into(),
            })
            .collect();
        fs::write(dir.join(format!("rs_fuzzy_{name}.txt")), s)?;
    }

    let json: Vec<String> = times
        .iter()
        .map(|(k, v)| format!("\"{k}\": {v:.4}"))
        .collect();
    println!("{{{}}}", json.join(", "));
    Ok(())
}
