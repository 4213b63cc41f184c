//! colortuner: colour filters in HSV, RGB or YUV on any image interface (4.3.1's
//! colortuner).
//!
//! Min/max per channel; pixels inside keep their colour, the others become grey
//! (or black). A click on the image sets the ranges around that pixel's colour.
//! Under the sliders, the colour plane of the chosen space (HSV: H across, S up;
//! YUV: U across, V up; RGB: R across, G up) shows where the image's pixels fall
//! (bins with at least `threshold` pixels, a slider) and the selected box; drag on
//! the plane to draw a new box.
//!
//! Conf (every line optional):
//! ```text
//! schema colortuner
//! image colorA          # colorA..D or varcolorA..D (the panel can switch)
//! space hsv             # hsv | rgb | yuv
//! hsv 0 1 0.2 1 0 255   # hmin hmax (rad 0..2π, wraps) smin smax (0..1) vmin vmax (0..255)
//! rgb 0 255 0 255 0 255 # rmin rmax gmin gmax bmin bmax (0..255)
//! yuv 0 1 -0.436 0.436 -0.615 0.615  # Y 0..1, U ±0.436, V ±0.615
//! toblack off
//! threshold 5           # pixels a plane bin needs to be drawn
//! output varcolorD      # optional: publish the filtered image on this new interface
//! cycle 100
//! end_schema
//! ```
//! `jderobot help colortuner` prints these lines with their ranges and defaults.
//! Interfaces used: the `image` (BGR); provided: `output` if given.
//!
//! Headless it filters each new frame and exports, component `colortuner`, `state`
//! ([`ColorTuner`]: space, ranges, result). System packages: none.

use crate::{
    colorspaces::{
        Background, ColourFilter, HsvRange, Lookup, RgbRange, YuvRange, filter, hsv_table, mask,
        rgb2hsv, rgb2yuv, yuv_table,
    },
    conf::{
        ComponentConf,
        settings::{CYCLE, Setting, choice, float, int},
    },
    imagesource::{self, ColourTuner, RangeFilter},
    interfaces::Image,
    runtime::{Runtime, Schema},
};

const TAU: f32 = std::f32::consts::TAU;

/// The colour space filtered in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Space {
    Hsv,
    Rgb,
    Yuv,
}

impl Space {
    pub const ALL: [Space; 3] = [Space::Hsv, Space::Rgb, Space::Yuv];
    pub fn name(self) -> &'static str {
        match self {
            Space::Hsv => "hsv",
            Space::Rgb => "rgb",
            Space::Yuv => "yuv",
        }
    }
    /// Channel names and ranges (HSV's H in radians).
    pub fn channels(self) -> [(&'static str, f32, f32); 3] {
        match self {
            Space::Hsv => [("H rad", 0.0, TAU), ("S", 0.0, 1.0), ("V", 0.0, 255.0)],
            Space::Rgb => [("R", 0.0, 255.0), ("G", 0.0, 255.0), ("B", 0.0, 255.0)],
            Space::Yuv => [("Y", 0.0, 1.0), ("U", -0.436, 0.436), ("V", -0.615, 0.615)],
        }
    }
    /// A pixel's three channel values in this space (H in radians).
    pub fn of(self, bgr: [u8; 3]) -> [f32; 3] {
        let [b, g, r] = bgr;
        match self {
            Space::Hsv => {
                let c = rgb2hsv(r, g, b);
                [c.h.to_radians(), c.s, c.v]
            }
            Space::Rgb => [r as f32, g as f32, b as f32],
            Space::Yuv => {
                let c = rgb2yuv(r, g, b);
                [c.y, c.u, c.v]
            }
        }
    }
}

/// Min/max of the three channels of each space: `[c0min, c0max, c1min, ...]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ranges {
    pub space: Space,
    pub hsv: [f32; 6],
    pub rgb: [f32; 6],
    pub yuv: [f32; 6],
}

impl Default for Ranges {
    fn default() -> Self {
        Ranges {
            space: Space::Hsv,
            hsv: [0.0, 1.0, 0.2, 1.0, 0.0, 255.0],
            rgb: [0.0, 255.0, 0.0, 255.0, 0.0, 255.0],
            yuv: [0.0, 1.0, -0.436, 0.436, -0.615, 0.615],
        }
    }
}

impl Ranges {
    pub fn current(&self) -> &[f32; 6] {
        match self.space {
            Space::Hsv => &self.hsv,
            Space::Rgb => &self.rgb,
            Space::Yuv => &self.yuv,
        }
    }
    pub fn current_mut(&mut self) -> &mut [f32; 6] {
        match self.space {
            Space::Hsv => &mut self.hsv,
            Space::Rgb => &mut self.rgb,
            Space::Yuv => &mut self.yuv,
        }
    }
    /// The colorspaces filter of the current space.
    pub fn filter(&self) -> ColourFilter {
        match self.space {
            Space::Hsv => {
                let h = self.hsv;
                ColourFilter::Hsv(HsvRange::from_radians(h[0], h[1], h[2], h[3], h[4], h[5]))
            }
            Space::Rgb => {
                let c = self.rgb.map(|v| v.round().clamp(0.0, 255.0) as u8);
                ColourFilter::Rgb(RgbRange {
                    rmin: c[0],
                    rmax: c[1],
                    gmin: c[2],
                    gmax: c[3],
                    bmin: c[4],
                    bmax: c[5],
                })
            }
            Space::Yuv => {
                let y = self.yuv;
                ColourFilter::Yuv(YuvRange {
                    ymin: y[0],
                    ymax: y[1],
                    umin: y[2],
                    umax: y[3],
                    vmin: y[4],
                    vmax: y[5],
                })
            }
        }
    }
    /// Sets the current space's ranges around a pixel's colour (a click): ±10 % of
    /// each channel's span (H ±0.3 rad, wrapping).
    pub fn pick(&mut self, bgr: [u8; 3]) {
        let sp = self.space;
        let v = sp.of(bgr);
        let ch = sp.channels();
        let r = self.current_mut();
        for k in 0..3 {
            let (_, lo, hi) = ch[k];
            let d = if sp == Space::Hsv && k == 0 {
                0.3
            } else {
                (hi - lo) * 0.1
            };
            if sp == Space::Hsv && k == 0 {
                r[0] = (v[0] - d).rem_euclid(TAU);
                r[1] = (v[0] + d).rem_euclid(TAU);
            } else {
                r[2 * k] = (v[k] - d).max(lo);
                r[2 * k + 1] = (v[k] + d).min(hi);
            }
        }
    }
}

/// Side of the colour plane's histogram (bins per axis).
pub const PLANE: usize = 64;

/// The plane coordinates (0..1 across, 0..1 up) of a colour in `space`: its first
/// two channels, scaled to their ranges.
pub fn plane_xy(space: Space, bgr: [u8; 3]) -> (f32, f32) {
    let v = space.of(bgr);
    let ch = space.channels();
    let f = |k: usize| ((v[k] - ch[k].1) / (ch[k].2 - ch[k].1)).clamp(0.0, 1.0);
    (f(0), f(1))
}

/// The image's pixel counts on the plane of `space`: `hist[row * PLANE + col]`,
/// row 0 at the bottom.
pub fn plane_hist(img: &Image, space: Space) -> Vec<u32> {
    let mut hist = vec![0u32; PLANE * PLANE];
    let n = (img.width as usize * img.height as usize).min(img.data.len() / 3);
    let ch = space.channels();
    let scale = |v: f32, k: usize| {
        (((v - ch[k].1) / (ch[k].2 - ch[k].1) * PLANE as f32) as usize).min(PLANE - 1)
    };
    for p in img.data[..n * 3].chunks_exact(3) {
        let (a, b) = match space {
            Space::Hsv => {
                let c = hsv_table().get(p[2], p[1], p[0]);
                (c.h.to_radians(), c.s)
            }
            Space::Rgb => (p[2] as f32, p[1] as f32),
            Space::Yuv => {
                let c = yuv_table().get(p[2], p[1], p[0]);
                (c.y, c.u)
            }
        };
        hist[scale(b, 1) * PLANE + scale(a, 0)] += 1;
    }
    hist
}

/// The state shared by the schema, its panel and the name space; its result's
/// `hist` is the colour plane of the space filtered in ([`plane_hist`]).
pub type ColorTuner = ColourTuner<Ranges>;

impl RangeFilter for Ranges {
    fn filter(&self, img: &Image, toblack: bool) -> (Image, usize, Vec<u32>) {
        run_filter(img, self, toblack)
    }
}

/// Filters `img` with `ranges`: the view, the count that passed, the plane.
pub fn run_filter(img: &Image, ranges: &Ranges, toblack: bool) -> (Image, usize, Vec<u32>) {
    let f = ranges.filter();
    let bg = if toblack {
        Background::Black
    } else {
        Background::Grey
    };
    let out = filter(img, &f, Lookup::Exact, bg);
    let passed = mask(img, &f, Lookup::Exact)
        .data
        .iter()
        .filter(|&&m| m != 0)
        .count();
    (out, passed, plane_hist(img, ranges.space))
}

const TAU64: f64 = std::f64::consts::TAU;

crate::declare_lines! {
    /// colortuner's lines, declared once (`jderobot help colortuner`).
    struct Lines {
        image: String = imagesource::IMAGE,
        space: String = Setting::new(
            "space",
            "the colour space it filters in",
            &[choice("SPACE", &["hsv", "rgb", "yuv"])],
        )
        .default("hsv"),
        hsv: [f32; 6] = Setting::new(
            "hsv",
            "the HSV ranges: hue wraps through 0 when HMIN > HMAX",
            &[
                float("HMIN", "radians", 0.0, TAU64),
                float("HMAX", "radians", 0.0, TAU64),
                float("SMIN", "", 0.0, 1.0),
                float("SMAX", "", 0.0, 1.0),
                float("VMIN", "", 0.0, 255.0),
                float("VMAX", "", 0.0, 255.0),
            ],
        )
        .default("0 1 0.2 1 0 255"),
        rgb: [f32; 6] = Setting::new(
            "rgb",
            "the RGB ranges",
            &[
                float("RMIN", "", 0.0, 255.0),
                float("RMAX", "", 0.0, 255.0),
                float("GMIN", "", 0.0, 255.0),
                float("GMAX", "", 0.0, 255.0),
                float("BMIN", "", 0.0, 255.0),
                float("BMAX", "", 0.0, 255.0),
            ],
        )
        .default("0 255 0 255 0 255"),
        yuv: [f32; 6] = Setting::new(
            "yuv",
            "the YUV ranges",
            &[
                float("YMIN", "", 0.0, 1.0),
                float("YMAX", "", 0.0, 1.0),
                float("UMIN", "", -0.436, 0.436),
                float("UMAX", "", -0.436, 0.436),
                float("VMIN", "", -0.615, 0.615),
                float("VMAX", "", -0.615, 0.615),
            ],
        )
        .default("0 1 -0.436 0.436 -0.615 0.615"),
        toblack: bool = imagesource::TOBLACK,
        threshold: u32 = Setting::new(
            "threshold",
            "the pixels a bin of the colour plane needs to be drawn",
            &[int("PIXELS", "", 1, 1_000_000)],
        )
        .default("5"),
        output: Option<String> = imagesource::OUTPUT,
        cycle: u64 = CYCLE.default("100"),
    }
}
fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let l: Lines = conf.read()?;
    let r = Ranges {
        space: Space::ALL
            .into_iter()
            .find(|s| s.name() == l.space)
            .unwrap_or(Space::Hsv),
        hsv: l.hsv,
        rgb: l.rgb,
        yuv: l.yuv,
    };
    let lines = imagesource::TunerLines {
        image: &l.image,
        output: l.output.as_deref(),
        toblack: l.toblack,
        cycle: l.cycle,
    };
    let schema = ColorTuner::schema(conf, rt, lines, r)?;
    #[cfg(feature = "gui")]
    let schema = {
        let state = schema.work.clone();
        schema.with_panel(panel::ColorTunerPanel::new(state, l.threshold))
    };
    Ok(Box::new(schema))
}

crate::register_schema!(
    "colortuner",
    "colour filters in HSV, RGB or YUV: sliders, click to pick, colour plane with a draggable box",
    create,
    lines = Lines
);

#[cfg(feature = "gui")]
pub mod panel {
    //! colortuner's panel.
    use super::*;
    use crate::widgets::{ImageView, label_response};
    use egui::{Color32, Rect, Sense, Stroke, pos2, vec2};
    use std::sync::Arc;

    pub struct ColorTunerPanel {
        state: Arc<ColorTuner>,
        view: ImageView,
        /// The pixels a plane bin needs to be drawn.
        threshold: u32,
    }

    impl ColorTunerPanel {
        pub fn new(state: Arc<ColorTuner>, threshold: u32) -> Self {
            ColorTunerPanel {
                state,
                view: ImageView::new("colortuner image"),
                threshold,
            }
        }
    }

    /// The colour a plane bin stands for (for drawing).
    fn bin_colour(space: Space, x: f32, y: f32) -> Color32 {
        match space {
            Space::Hsv => {
                let (r, g, b) = crate::colorspaces::hsv2rgb_u8(crate::colorspaces::Hsv {
                    h: x * 360.0,
                    s: y,
                    v: 255.0,
                });
                Color32::from_rgb(r, g, b)
            }
            Space::Rgb => Color32::from_rgb((x * 255.0) as u8, (y * 255.0) as u8, 128),
            Space::Yuv => {
                let v = (x * 255.0) as u8;
                Color32::from_rgb(v, v, v)
            }
        }
    }

    fn plane(ui: &mut egui::Ui, r: &mut Ranges, hist: &[u32], threshold: u32) {
        let side = 200.0;
        let (rect, resp) = ui.allocate_exact_size(vec2(side, side), Sense::click_and_drag());
        label_response(&resp, "colortuner plane");
        let p = ui.painter_at(rect);
        p.rect_filled(rect, 0.0, Color32::from_gray(25));
        let cell = side / PLANE as f32;
        if hist.len() == PLANE * PLANE {
            for (i, &n) in hist.iter().enumerate() {
                if n >= threshold {
                    let (row, col) = (i / PLANE, i % PLANE);
                    let x = rect.min.x + col as f32 * cell;
                    let y = rect.max.y - (row + 1) as f32 * cell;
                    let c = bin_colour(
                        r.space,
                        col as f32 / PLANE as f32,
                        row as f32 / PLANE as f32,
                    );
                    p.rect_filled(Rect::from_min_size(pos2(x, y), vec2(cell, cell)), 0.0, c);
                }
            }
        }
        let ch = r.space.channels();
        let to_f = |k: usize, v: f32| (v - ch[k].1) / (ch[k].2 - ch[k].1);
        let cur = *r.current();
        let (x0, x1) = (to_f(0, cur[0]), to_f(0, cur[1]));
        let (y0, y1) = (to_f(1, cur[2]), to_f(1, cur[3]));
        let sx = |f: f32| rect.min.x + f * side;
        let sy = |f: f32| rect.max.y - f * side;
        let stroke = Stroke::new(2.0, Color32::WHITE);
        if x0 <= x1 {
            p.rect_stroke(
                Rect::from_two_pos(pos2(sx(x0), sy(y0)), pos2(sx(x1), sy(y1))),
                0.0,
                stroke,
                egui::StrokeKind::Middle,
            );
        } else {
            // A wrapping hue range: two boxes, to the right edge and from the left.
            for (a, b) in [(x0, 1.0), (0.0, x1)] {
                p.rect_stroke(
                    Rect::from_two_pos(pos2(sx(a), sy(y0)), pos2(sx(b), sy(y1))),
                    0.0,
                    stroke,
                    egui::StrokeKind::Middle,
                );
            }
        }
        if resp.dragged()
            && let (Some(a), Some(b)) = (
                ui.input(|i| i.pointer.press_origin()),
                resp.interact_pointer_pos(),
            )
        {
            let fx = |x: f32| ((x - rect.min.x) / side).clamp(0.0, 1.0);
            let fy = |y: f32| ((rect.max.y - y) / side).clamp(0.0, 1.0);
            let from = |k: usize, f: f32| ch[k].1 + f * (ch[k].2 - ch[k].1);
            let c = r.current_mut();
            c[0] = from(0, fx(a.x).min(fx(b.x)));
            c[1] = from(0, fx(a.x).max(fx(b.x)));
            c[2] = from(1, fy(a.y).min(fy(b.y)));
            c[3] = from(1, fy(a.y).max(fy(b.y)));
        }
    }

    impl crate::runtime::Panel for ColorTunerPanel {
        fn ui(&mut self, ui: &mut egui::Ui, rt: &Runtime) {
            let state = self.state.clone();
            state.edit(|r, res| {
                ui.horizontal(|ui| {
                    self.state.source.picker(ui, "colortuner source");
                    for s in Space::ALL {
                        ui.radio_value(&mut r.space, s, s.name());
                    }
                    self.state.toblack_checkbox(ui);
                    ui.label(format!("passed {} px", res.passed));
                });
                ui.horizontal_top(|ui| {
                    ui.vertical(|ui| {
                        ui.set_max_width(230.0);
                        let ch = r.space.channels();
                        let c = r.current_mut();
                        for (k, (name, lo, hi)) in ch.iter().enumerate() {
                            ui.add(
                                egui::Slider::new(&mut c[2 * k], *lo..=*hi)
                                    .text(format!("{name} min")),
                            );
                            ui.add(
                                egui::Slider::new(&mut c[2 * k + 1], *lo..=*hi)
                                    .text(format!("{name} max")),
                            );
                        }
                        let t = &mut self.threshold;
                        ui.add(egui::Slider::new(t, 1..=500).text("threshold"));
                        // The plane of the space the result was computed in.
                        if res.hist.len() == PLANE * PLANE {
                            plane(ui, r, &res.hist, *t);
                        }
                    });
                    ui.vertical(|ui| {
                        let shown = self.view.show(ui, &res.image, res.clock);
                        if let Some(pk) = shown.pick {
                            // The colour under the click in the source (not the filtered view).
                            let s = self.state.source.name.lock().clone();
                            if let Ok(src) = rt.interfaces.get::<Image>(&s) {
                                let v = src.snapshot();
                                let i =
                                    (pk.y as usize * v.value.width as usize + pk.x as usize) * 3;
                                if let Some(&[b, g, rr]) = v.value.data.get(i..i + 3) {
                                    r.pick([b, g, rr]);
                                }
                            }
                        }
                    });
                });
            });
        }
    }
}
