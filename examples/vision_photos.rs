//! Times jderobot's HoughLinesP and pyramidal LK flow on one photograph written by
//! `scripts/compare_photos.py` (any size), writes the outputs next to the inputs and
//! prints the median time of each op (milliseconds, one thread) as JSON. The script
//! runs it once per photograph and round, alternating with OpenCV.
//!
//! ```text
//! cargo run --release --example vision_photos -- DIR WIDTH HEIGHT REPEATS
//! ```
//! Inputs in DIR: `a.gray`, `b.gray` (u8 grey frames, `b` shifted), `edges.raw` (u8
//! Canny edges), `points.txt` (`x y` per line). Outputs: `rs_houghp.txt` (`x1 y1 x2
//! y2` per segment), `rs_lk.txt` (`x y found error` per point).

use std::{fs, path::Path, time::Instant};

use jderobot::vision::{self, GrayImage, LkParams};

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

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    anyhow::ensure!(
        args.len() == 5,
        "usage: vision_photos DIR WIDTH HEIGHT REPEATS"
    );
    let dir = Path::new(&args[1]);
    let (w, h): (u32, u32) = (args[2].parse()?, args[3].parse()?);
    let repeats: usize = args[4].parse()?;
    let load = |name: &str| -> anyhow::Result<GrayImage> {
        let data = fs::read(dir.join(name))?;
        anyhow::ensure!(
            data.len() == (w * h) as usize,
            "{}: {} bytes, expected {w}x{h}",
            dir.join(name).display(),
            data.len()
        );
        Ok(GrayImage {
            width: w,
            height: h,
            data,
        })
    };
    let (a, b, edges) = (load("a.gray")?, load("b.gray")?, load("edges.raw")?);

    let theta = std::f64::consts::PI / 180.0;
    let (t_hough, segs) = median_ms(repeats, || {
        vision::hough_lines_p(&edges, 1.0, theta, 50, 30, 5)
    });
    let s: String = segs
        .iter()
        .map(|l| format!("{} {} {} {}\n", l.x1, l.y1, l.x2, l.y2))
        .collect();
    fs::write(dir.join("rs_houghp.txt"), s)?;

    let text = fs::read_to_string(dir.join("points.txt"))?;
    let mut pts = Vec::new();
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let v: Vec<f32> = line
            .split_whitespace()
            .map(str::parse)
            .collect::<Result<_, _>>()?;
        anyhow::ensure!(v.len() == 2, "points.txt: `{line}` is not `x y`");
        pts.push((v[0], v[1]));
    }
    let (t_lk, tracked) = median_ms(repeats, || {
        vision::optical_flow_pyr_lk(&a, &b, &pts, &LkParams::default())
    });
    let mut s = String::new();
    for p in &tracked {
        s += &format!("{} {} {} {}\n", p.x, p.y, p.found as u8, p.error);
    }
    fs::write(dir.join("rs_lk.txt"), s)?;
    println!("{{\"hough_lines_p\": {t_hough:.4}, \"optical_flow_lk\": {t_lk:.4}}}");
    Ok(())
}
