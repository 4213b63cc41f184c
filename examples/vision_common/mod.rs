//! What `vision_compare` and `vision_photos` share: the command line (DIR WIDTH
//! HEIGHT REPEATS), reading the inputs the scripts write, timing each op (the
//! median of REPEATS runs after a warm-up, in ms) and printing the times as JSON.

use std::{fs, path::PathBuf, time::Instant};

use jderobot::vision::{self, GrayImage, LkParams};

/// One run of an example on one directory of inputs.
pub struct Run {
    pub dir: PathBuf,
    pub w: u32,
    pub h: u32,
    pub repeats: usize,
    /// Each op's median time so far (ms), in the order they ran.
    pub times: Vec<(String, f64)>,
}

impl Run {
    /// From the command line `example DIR WIDTH HEIGHT REPEATS`.
    pub fn from_args(example: &str) -> anyhow::Result<Run> {
        let args: Vec<String> = std::env::args().collect();
        anyhow::ensure!(args.len() == 5, "usage: {example} DIR WIDTH HEIGHT REPEATS");
        Ok(Run {
            dir: PathBuf::from(&args[1]),
            w: args[2].parse()?,
            h: args[3].parse()?,
            repeats: args[4].parse()?,
            times: Vec::new(),
        })
    }

    /// Runs `f` once to warm up, then `repeats` times; keeps the median time as
    /// `op`'s and gives the last result.
    pub fn time<T>(&mut self, op: &str, mut f: impl FnMut() -> T) -> T {
        let mut out = f();
        let mut times = Vec::with_capacity(self.repeats);
        for _ in 0..self.repeats {
            let t = Instant::now();
            out = std::hint::black_box(f());
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        times.sort_by(f64::total_cmp);
        self.times.push((op.into(), times[times.len() / 2]));
        out
    }

    /// The bytes of input `name`, checked to be `per_pixel` bytes a pixel.
    pub fn frame(&self, name: &str, per_pixel: u32) -> anyhow::Result<Vec<u8>> {
        let path = self.dir.join(name);
        let data = fs::read(&path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        let (w, h) = (self.w, self.h);
        anyhow::ensure!(
            data.len() == (w * h * per_pixel) as usize,
            "{}: {} bytes, expected {w}x{h}x{per_pixel}",
            path.display(),
            data.len()
        );
        Ok(data)
    }

    /// Input `name` as a grey frame.
    pub fn gray(&self, name: &str) -> anyhow::Result<GrayImage> {
        Ok(GrayImage {
            width: self.w,
            height: self.h,
            data: self.frame(name, 1)?,
        })
    }

    /// The numbers of input `name`, one row a line.
    pub fn numbers(&self, name: &str) -> anyhow::Result<Vec<Vec<f64>>> {
        let path = self.dir.join(name);
        let text = fs::read_to_string(&path)?;
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

    /// `points.txt`: `x y` a line.
    pub fn points(&self) -> anyhow::Result<Vec<(f32, f32)>> {
        self.numbers("points.txt")?
            .iter()
            .map(|p| {
                anyhow::ensure!(p.len() == 2, "points.txt: {p:?} is not `x y`");
                Ok((p[0] as f32, p[1] as f32))
            })
            .collect()
    }

    /// Writes output `name` next to the inputs.
    pub fn write(&self, name: &str, data: impl AsRef<[u8]>) -> anyhow::Result<()> {
        Ok(fs::write(self.dir.join(name), data)?)
    }

    /// HoughLinesP on `edges` (OpenCV's Canny edges, so both sides vote the same
    /// points) into `rs_houghp.txt`, `x1 y1 x2 y2` a segment.
    pub fn hough_lines_p(&mut self, edges: &GrayImage) -> anyhow::Result<()> {
        let theta = std::f64::consts::PI / 180.0;
        let segs = self.time("hough_lines_p", || {
            vision::hough_lines_p(edges, 1.0, theta, 50, 30, 5)
        });
        let s: String = segs
            .iter()
            .map(|l| format!("{} {} {} {}\n", l.x1, l.y1, l.x2, l.y2))
            .collect();
        self.write("rs_houghp.txt", s)
    }

    /// Pyramidal LK from `a` to `b` of `points.txt` into `rs_lk.txt`, `x y found
    /// error` a point.
    pub fn optical_flow_lk(&mut self, a: &GrayImage, b: &GrayImage) -> anyhow::Result<()> {
        let pts = self.points()?;
        let tracked = self.time("optical_flow_lk", || {
            vision::optical_flow_pyr_lk(a, b, &pts, &LkParams::default())
        });
        let s: String = tracked
            .iter()
            .map(|p| format!("{} {} {} {}\n", p.x, p.y, p.found as u8, p.error))
            .collect();
        self.write("rs_lk.txt", s)
    }

    /// The times as one JSON object, on stdout.
    pub fn print_times(&self) {
        let json: Vec<String> = self
            .times
            .iter()
            .map(|(k, v)| format!("\"{k}\": {v:.4}"))
            .collect();
        println!("{{{}}}", json.join(", "));
    }
}
