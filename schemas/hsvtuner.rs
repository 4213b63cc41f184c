//! hsvtuner: find the HSV ranges of a colour on a live image (4.3's hsvtuner).
//!
//! Pixels whose H, S and V are in range keep their colour; the others become black
//! (`toblack`) or grey at V·180/255. The hue test wraps through 0 when
//! `hmin > hmax` (H ≥ hmin or H ≤ hmax). The panel has the sliders (H 0..2π rad,
//! S 0..1, V 0..255), the filtered image, and the H–S "cheese": hue as angle, saturation
//! as radius, the selected sector outlined and the image's colour histogram under it
//! (drag on the cheese to select a sector). "Print" and "Copy" give the ranges as the
//! conf lines `hmin .. vmax` that opencvdemo (and followball) accept.
//!
//! Conf (every line optional; defaults are 4.3's):
//! ```text
//! schema hsvtuner
//! image colorA         # the image to tune on: colorA..D or varcolorA..D
//! hmin 0               # H range, radians 0..2π (wraps when hmin > hmax)
//! hmax 1
//! smin 0.2             # S range, 0..1
//! smax 0.4
//! vmin 0               # V range, 0..255 (V = max(R, G, B))
//! vmax 255
//! toblack off          # on: rejected pixels black; off: grey
//! output varcolorD     # optional: publish the filtered image on this (new)
//!                      #   image interface, so `echo varcolorD` shows it headless
//! cycle 100            # ms (4.3's 100)
//! end_schema
//! ```
//! `jderobot help hsvtuner` prints these lines with their ranges and defaults.
//! Interfaces used: the `image` (BGR); provided: `output` if given.
//!
//! Headless the schema filters every cycle and exports, component `hsvtuner`:
//! `state` ([`Tuner`]: the ranges as a [`HsvRange`], H in degrees; the toggle, the
//! image in use, the pixels that passed, the colour histogram). System packages:
//! none.

use crate::{
    colorspaces::{HsvRange, Lookup, hsv_mask, hsv_table},
    conf::{ComponentConf, settings::CYCLE},
    imagesource::{self, ColourTuner, RangeFilter},
    interfaces::Image,
    runtime::{Runtime, Schema},
};

const TAU: f32 = std::f32::consts::TAU;

/// The conf lines that opencvdemo and followball accept for `r`, one per key,
/// in 4.3's units (H radians).
pub fn conf_lines(r: &HsvRange) -> String {
    format!(
        "hmin {:.3}\nhmax {:.3}\nsmin {:.3}\nsmax {:.3}\nvmin {:.0}\nvmax {:.0}\n",
        r.hmin.to_radians(),
        r.hmax.to_radians(),
        r.smin,
        r.smax,
        r.vmin,
        r.vmax
    )
}

/// Hue bins (10° each) and saturation bins (0.1 each) of the colour histogram.
pub const HUE_BINS: usize = 36;
pub const SAT_BINS: usize = 10;

/// The state shared by the schema, its panel and the name space; its result's
/// `hist` counts pixels per (hue bin, saturation bin): `hist[h * SAT_BINS + s]`.
pub type Tuner = ColourTuner<HsvRange>;

impl RangeFilter for HsvRange {
    fn filter(&self, img: &Image, toblack: bool) -> (Image, usize, Vec<u32>) {
        filter(img, self, toblack)
    }
}

/// Filters `img`: the image with rejected pixels black or grey, the count that
/// passed and the H–S histogram.
pub fn filter(img: &Image, ranges: &HsvRange, toblack: bool) -> (Image, usize, Vec<u32>) {
    let mask = hsv_mask(img, ranges, Lookup::Exact);
    let mut out = img.clone();
    let n = (img.width as usize * img.height as usize).min(img.data.len() / 3);
    let mut passed = 0;
    let mut hist = vec![0u32; HUE_BINS * SAT_BINS];
    let t = hsv_table();
    for (p, &k) in out.data[..n * 3].chunks_exact_mut(3).zip(mask.data.iter()) {
        let c = t.get(p[2], p[1], p[0]);
        let hb = ((c.h / 360.0 * HUE_BINS as f32) as usize).min(HUE_BINS - 1);
        let sb = ((c.s * SAT_BINS as f32) as usize).min(SAT_BINS - 1);
        hist[hb * SAT_BINS + sb] += 1;
        if k == 0 {
            let g = if toblack {
                0
            } else {
                (p[0].max(p[1]).max(p[2]) as u32 * 180 / 255) as u8
            };
            p.fill(g);
        } else {
            passed += 1;
        }
    }
    (out, passed, hist)
}

crate::declare_lines! {
    /// hsvtuner's lines, declared once (`jderobot help hsvtuner`); defaults are 4.3's.
    struct Lines {
        image: String = imagesource::IMAGE,
        #[serde(deserialize_with = "imagesource::hsv_lines")]
        hsv: HsvRange = [
            imagesource::HMIN.default("0"),
            imagesource::HMAX.default("1"),
            imagesource::SMIN.default("0.2"),
            imagesource::SMAX.default("0.4"),
            imagesource::VMIN.default("0"),
            imagesource::VMAX.default("255"),
        ],
        toblack: bool = imagesource::TOBLACK,
        output: Option<String> = imagesource::OUTPUT,
        cycle: u64 = CYCLE.default("100"),
    }
}
fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let l: Lines = conf.read()?;
    let lines = imagesource::TunerLines {
        image: &l.image,
        output: l.output.as_deref(),
        toblack: l.toblack,
        cycle: l.cycle,
    };
    let schema = Tuner::schema(conf, rt, lines, l.hsv)?;
    #[cfg(feature = "gui")]
    let schema = {
        let state = schema.work.clone();
        schema.with_panel(panel::TunerPanel::new(state))
    };
    Ok(Box::new(schema))
}

crate::register_schema!(
    "hsvtuner",
    "HSV range tuning on a live image: sliders, H-S cheese map, filtered view, conf lines",
    create,
    lines = Lines
);

/// The H–S "cheese" geometry: hue as the angle (counter-clockwise from the right),
/// saturation as the radius.
pub mod cheese {
    use super::TAU;

    /// Screen offset (from the centre, y down) of (hue rad, saturation) on a
    /// cheese of `radius`.
    pub fn to_screen(h: f32, s: f32, radius: f32) -> (f32, f32) {
        (s * radius * h.cos(), -s * radius * h.sin())
    }

    /// (hue rad 0..2π, saturation 0..1, clamped) of a screen offset.
    pub fn from_screen(dx: f32, dy: f32, radius: f32) -> (f32, f32) {
        let h = (-dy).atan2(dx).rem_euclid(TAU);
        let s = ((dx * dx + dy * dy).sqrt() / radius.max(1e-6)).min(1.0);
        (h, s)
    }

    /// The sector dragged from `a` to `b` (screen offsets): hmin, hmax (counter-
    /// clockwise from a to b, so it may wrap), smin, smax.
    pub fn drag_sector(a: (f32, f32), b: (f32, f32), radius: f32) -> (f32, f32, f32, f32) {
        let (h0, s0) = from_screen(a.0, a.1, radius);
        let (h1, s1) = from_screen(b.0, b.1, radius);
        (h0, h1, s0.min(s1), s0.max(s1))
    }
}

#[cfg(feature = "gui")]
pub mod panel {
    //! hsvtuner's panel.
    use super::*;
    use crate::{colorspaces::Hsv, colorspaces::hsv2rgb_u8, output, widgets::ImageView};
    use egui::{Color32, Pos2, Sense, Shape, Stroke, pos2, vec2};
    use std::sync::Arc;

    pub struct TunerPanel {
        state: Arc<Tuner>,
        view: ImageView,
        drag_from: Option<(f32, f32)>,
    }

    impl TunerPanel {
        pub fn new(state: Arc<Tuner>) -> Self {
            TunerPanel {
                state,
                view: ImageView::new("hsvtuner image"),
                drag_from: None,
            }
        }

        /// The H-S cheese of `r` (its hue in degrees, drawn in radians).
        fn cheese(&mut self, ui: &mut egui::Ui, r: &mut HsvRange, hist: &[u32]) {
            let side = 220.0;
            let (rect, resp) = ui.allocate_exact_size(vec2(side, side), Sense::click_and_drag());
            crate::widgets::label_response(&resp, "hsvtuner cheese");
            let c = rect.center();
            let radius = side * 0.45;
            let p = ui.painter_at(rect);
            p.circle_filled(c, radius, Color32::from_gray(30));
            // The histogram: each populated (hue, sat) bin as a dot of its colour.
            let max = hist.iter().copied().max().unwrap_or(0).max(1) as f32;
            for (i, &n) in hist.iter().enumerate() {
                if n == 0 {
                    continue;
                }
                let (hb, sb) = (i / SAT_BINS, i % SAT_BINS);
                let h = (hb as f32 + 0.5) / HUE_BINS as f32 * TAU;
                let s = (sb as f32 + 0.5) / SAT_BINS as f32;
                let (dx, dy) = cheese::to_screen(h, s, radius);
                let (rr, gg, bb) = hsv2rgb_u8(Hsv {
                    h: h.to_degrees(),
                    s,
                    v: 255.0,
                });
                let size = 1.5 + 3.0 * (n as f32 / max).sqrt();
                p.circle_filled(
                    pos2(c.x + dx, c.y + dy),
                    size,
                    Color32::from_rgb(rr, gg, bb),
                );
            }
            // The selected sector, counter-clockwise from hmin to hmax.
            let (hmin, hmax) = (r.hmin.to_radians(), r.hmax.to_radians());
            let span = if hmax >= hmin {
                hmax - hmin
            } else {
                (hmax - hmin).rem_euclid(TAU)
            };
            let steps = 32;
            let mut pts: Vec<Pos2> = Vec::new();
            for k in 0..=steps {
                let h = hmin + span * k as f32 / steps as f32;
                let (dx, dy) = cheese::to_screen(h, r.smax, radius);
                pts.push(pos2(c.x + dx, c.y + dy));
            }
            for k in (0..=steps).rev() {
                let h = hmin + span * k as f32 / steps as f32;
                let (dx, dy) = cheese::to_screen(h, r.smin, radius);
                pts.push(pos2(c.x + dx, c.y + dy));
            }
            p.add(Shape::closed_line(pts, Stroke::new(2.0, Color32::WHITE)));
            if resp.drag_started()
                && let Some(pos) = ui.input(|i| i.pointer.press_origin())
            {
                self.drag_from = Some((pos.x - c.x, pos.y - c.y));
            }
            if resp.dragged()
                && let (Some(a), Some(pos)) = (self.drag_from, resp.interact_pointer_pos())
            {
                let (hmin, hmax, smin, smax) =
                    cheese::drag_sector(a, (pos.x - c.x, pos.y - c.y), radius);
                r.hmin = hmin.to_degrees();
                r.hmax = hmax.to_degrees();
                r.smin = smin;
                r.smax = smax;
            }
            if resp.drag_stopped() {
                self.drag_from = None;
            }
        }
    }

    /// A slider on a hue kept in degrees, shown in radians as 4.3's.
    fn hue_slider(ui: &mut egui::Ui, deg: &mut f32, text: &str) {
        let mut rad = deg.to_radians();
        if ui
            .add(egui::Slider::new(&mut rad, 0.0..=TAU).text(text))
            .changed()
        {
            *deg = rad.to_degrees();
        }
    }

    impl crate::runtime::Panel for TunerPanel {
        fn ui(&mut self, ui: &mut egui::Ui, _rt: &Runtime) {
            let state = self.state.clone();
            state.edit(|r, res| {
                ui.horizontal(|ui| {
                    self.state.source.picker(ui, "hsvtuner source");
                    self.state.toblack_checkbox(ui);
                    let total = (res.image.width * res.image.height).max(1) as f32;
                    ui.label(format!(
                        "passed {} px ({:.1} %)",
                        res.passed,
                        res.passed as f32 * 100.0 / total
                    ));
                });
                ui.horizontal_top(|ui| {
                    ui.vertical(|ui| {
                        ui.set_max_width(230.0);
                        hue_slider(ui, &mut r.hmin, "Hmin rad");
                        hue_slider(ui, &mut r.hmax, "Hmax rad");
                        ui.add(egui::Slider::new(&mut r.smin, 0.0..=1.0).text("Smin"));
                        ui.add(egui::Slider::new(&mut r.smax, 0.0..=1.0).text("Smax"));
                        ui.add(egui::Slider::new(&mut r.vmin, 0.0..=255.0).text("Vmin"));
                        ui.add(egui::Slider::new(&mut r.vmax, 0.0..=255.0).text("Vmax"));
                        self.cheese(ui, r, &res.hist);
                        ui.horizontal(|ui| {
                            if ui.button("Print").clicked() {
                                for line in conf_lines(r).lines() {
                                    output::println(line);
                                }
                            }
                            if ui.button("Copy").clicked() {
                                ui.ctx().copy_text(conf_lines(r));
                            }
                        });
                    });
                    ui.vertical(|ui| {
                        self.view.show(ui, &res.image, res.clock);
                    });
                });
            });
        }
    }
}
