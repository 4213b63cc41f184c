//! opencvdemo's pipeline: one filter on one BGR frame, into a BGR view.

use std::time::Instant;

use crate::{
    colorspaces::{Background, HsvRange, Lookup, hsv_filter},
    interfaces::Image,
    vision::{self, GrayImage, Kernel, LkParams},
};

/// The filters of 4.3's opencvdemo (its radio buttons), in their order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Filter {
    Original,
    Gray,
    ColorFilter,
    Canny,
    Sobel,
    OpticalFlow,
    Pyramid,
    Convolution,
    HoughStandard,
    HoughProbabilistic,
}

impl Filter {
    pub const ALL: [Filter; 10] = [
        Filter::Original,
        Filter::Gray,
        Filter::ColorFilter,
        Filter::Canny,
        Filter::Sobel,
        Filter::OpticalFlow,
        Filter::Pyramid,
        Filter::Convolution,
        Filter::HoughStandard,
        Filter::HoughProbabilistic,
    ];
    /// The conf words (and the panel's labels), in [`Filter::ALL`]'s order.
    pub const NAMES: [&'static str; 10] = [
        "original",
        "gray",
        "color",
        "canny",
        "sobel",
        "flow",
        "pyramid",
        "convolution",
        "hough",
        "houghp",
    ];
    /// The conf word (and the panel's label).
    pub fn name(self) -> &'static str {
        Filter::NAMES[self as usize]
    }
    pub fn from_name(s: &str) -> Option<Filter> {
        Filter::ALL.into_iter().find(|f| f.name() == s)
    }
}

/// The parameters a filter reads.
#[derive(Clone, Debug, PartialEq)]
pub struct Params {
    /// HSV ranges (H degrees, as [`HsvRange`]).
    pub hsv: HsvRange,
    /// Canny's low threshold; the high one is three times it (4.3: 50).
    pub canny: f64,
    /// Votes a standard Hough line needs.
    pub hough_votes: u32,
    /// Probabilistic Hough: votes, minimum length, maximum gap (pixels).
    pub houghp: (u32, i32, i32),
    pub kernel: Kernel,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            hsv: HsvRange::from_radians(3.3, 4.5, 0.2, 1.0, 80.0, 255.0),
            canny: 50.0,
            hough_votes: 100,
            houghp: (50, 30, 10),
            kernel: Kernel::default(),
        }
    }
}

/// What the pipeline keeps between frames (optical flow's previous frame).
#[derive(Default)]
pub struct Pipeline {
    prev: Option<GrayImage>,
}

/// Draws a line in colour `bgr` between pixel positions, clipped to the image
/// ([`vision::draw_line`](crate::vision::draw_line)).
pub fn draw_line(img: &mut Image, (x0, y0): (i32, i32), (x1, y1): (i32, i32), bgr: [u8; 3]) {
    crate::vision::draw_line(img, (x0 as f64, y0 as f64), (x1 as f64, y1 as f64), bgr);
}

/// The end points of the polar line (ρ, θ) extended 2000 px each way (OpenCV's
/// sample drawing), for [`draw_line`] (which clips).
pub fn polar_ends(rho: f32, theta: f32) -> ((i32, i32), (i32, i32)) {
    let (a, b) = (theta.cos(), theta.sin());
    let (x0, y0) = (a * rho, b * rho);
    let far = |k: f32| ((x0 - k * b).round() as i32, (y0 + k * a).round() as i32);
    (far(2000.0), far(-2000.0))
}

const RED: [u8; 3] = [0, 0, 255];

/// A line three pixels wide (so it survives the panel's downscaling).
pub fn draw_thick(img: &mut Image, a: (i32, i32), b: (i32, i32), bgr: [u8; 3]) {
    let across_y = (b.0 - a.0).abs() >= (b.1 - a.1).abs();
    for o in [-1, 0, 1] {
        let (dx, dy) = if across_y { (0, o) } else { (o, 0) };
        draw_line(img, (a.0 + dx, a.1 + dy), (b.0 + dx, b.1 + dy), bgr);
    }
}
const GREEN: [u8; 3] = [0, 255, 0];

impl Pipeline {
    /// Runs `filter` on `img`; returns the view and the milliseconds it took.
    pub fn run(&mut self, filter: Filter, img: &Image, p: &Params) -> (Image, f64) {
        let t = Instant::now();
        let out = self.apply(filter, img, p);
        (out, t.elapsed().as_secs_f64() * 1e3)
    }

    fn apply(&mut self, filter: Filter, img: &Image, p: &Params) -> Image {
        if !vision::is_valid(img) || img.width == 0 || img.height == 0 {
            return img.clone();
        }
        let edges =
            |img: &Image| vision::canny(&vision::grayscale(img), p.canny, p.canny * 3.0, false);
        match filter {
            Filter::Original => img.clone(),
            Filter::Gray => vision::grayscale(img).to_bgr(),
            Filter::ColorFilter => hsv_filter(img, &p.hsv, Lookup::Exact, Background::Black),
            Filter::Canny => edges(img).to_bgr(),
            Filter::Sobel => {
                let (dx, dy) = vision::sobel(&vision::grayscale(img));
                let mut g = GrayImage::new(img.width, img.height);
                for ((o, &a), &b) in g.data.iter_mut().zip(&dx.data).zip(&dy.data) {
                    *o = (a.unsigned_abs() as u32 + b.unsigned_abs() as u32).min(255) as u8;
                }
                g.to_bgr()
            }
            Filter::OpticalFlow => {
                let g = vision::grayscale(img);
                let mut out = img.clone();
                if let Some(prev) = self
                    .prev
                    .as_ref()
                    .filter(|q| q.width == g.width && q.height == g.height)
                {
                    let step = 16;
                    let pts: Vec<(f32, f32)> = (step / 2..img.height)
                        .step_by(step as usize)
                        .flat_map(|y| {
                            (step / 2..img.width)
                                .step_by(step as usize)
                                .map(move |x| (x as f32, y as f32))
                        })
                        .collect();
                    let tracked = vision::optical_flow_pyr_lk(prev, &g, &pts, &LkParams::default());
                    for (&(x, y), t) in pts.iter().zip(&tracked) {
                        if t.found && ((t.x - x).powi(2) + (t.y - y).powi(2)) > 0.25 {
                            let a = (x.round() as i32, y.round() as i32);
                            let b = (t.x.round() as i32, t.y.round() as i32);
                            draw_line(&mut out, a, b, GREEN);
                            draw_line(&mut out, b, b, RED);
                        }
                    }
                }
                self.prev = Some(g);
                out
            }
            Filter::Pyramid => vision::pyr_down(img),
            Filter::Convolution => vision::convolve(img, &p.kernel),
            Filter::HoughStandard => {
                let e = edges(img);
                let mut out = img.clone();
                let lines =
                    vision::hough_lines(&e, 1.0, std::f64::consts::PI / 180.0, p.hough_votes);
                for l in lines.iter().take(100) {
                    let (a, b) = polar_ends(l.rho, l.theta);
                    draw_thick(&mut out, a, b, RED);
                }
                out
            }
            Filter::HoughProbabilistic => {
                let e = edges(img);
                let mut out = img.clone();
                let (v, len, gap) = p.houghp;
                for s in vision::hough_lines_p(&e, 1.0, std::f64::consts::PI / 180.0, v, len, gap) {
                    draw_thick(&mut out, (s.x1, s.y1), (s.x2, s.y2), RED);
                }
                out
            }
        }
    }
}
