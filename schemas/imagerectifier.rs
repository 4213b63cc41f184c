//! imagerectifier: rectify a plane seen in perspective (4.3's imgrectifier).
//!
//! Click 4 points on the input in order (top-left, top-right, bottom-right,
//! bottom-left of the plane), then, in "rectangle mode", 2 opposite corners on the
//! output: the 8-parameter homography (h33 = 1) from the 4 pairs is solved by the
//! vision library's [`find_homography`] and the live image is warped with it
//! ([`warp_perspective`]). Buttons: Rectify, Undo (the last point), Discard (all),
//! Rectangle mode, Save (the 8 numbers to the `save` file); the 8 numbers are also
//! printed.
//!
//! Conf (every line optional):
//! ```text
//! schema imagerectifier
//! image colorA                 # colorA..D or varcolorA..D
//! points 60 40 250 50 270 200 40 190   # optional: the 4 input points (x y each,
//! rectangle 0 0 319 239        #   pixels) and the output rectangle (x1 y1 x2 y2):
//!                              #   with both the homography is solved at load
//! save homography.txt          # where Save writes the 8 numbers (relative to the conf)
//! output varcolorD             # optional: publish the rectified image here
//! cycle 100
//! end_schema
//! ```
//! `jderobot help imagerectifier` prints these lines with their ranges and defaults.
//! Interfaces used: the `image` (BGR); provided: `output` if given (the input's size).
//!
//! Headless it warps each new frame once a homography is known and exports,
//! component `imagerectifier`, `state` ([`Rectifier`]: points, homography, result).
//! System packages: none.

use std::{path::PathBuf, sync::Arc};

use nalgebra::Matrix3;
use parking_lot::Mutex;

use crate::{
    conf::{
        ComponentConf,
        settings::{Arg, CYCLE, Setting, float, path},
    },
    imagesource::{self, Frame, Frames, Source, Work},
    interfaces::{Image, Interface},
    runtime::{Runtime, Schema},
    vision::{find_homography, warp_perspective},
};

/// The clicks and the solution.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Points {
    /// Input points, in click order (at most 4).
    pub src: Vec<(f64, f64)>,
    /// Output rectangle corners (at most 2).
    pub rect: Vec<(f64, f64)>,
    /// Whether clicks go to the output (rectangle mode).
    pub rectangle_mode: bool,
    /// The homography (input → output pixels, h33 = 1), once solved.
    pub homography: Option<Matrix3<f64>>,
}

impl Points {
    /// Adds a click on the input (`output` false) or the output; ignores extra ones.
    pub fn click(&mut self, x: f64, y: f64, output: bool) {
        if output {
            if self.rectangle_mode && self.rect.len() < 2 {
                self.rect.push((x, y));
            }
        } else if !self.rectangle_mode && self.src.len() < 4 {
            self.src.push((x, y));
            if self.src.len() == 4 {
                self.rectangle_mode = true;
            }
        }
    }
    /// Removes the last point (the output's first, then the input's).
    pub fn undo(&mut self) {
        if self.rect.pop().is_none() {
            self.src.pop();
            self.rectangle_mode = false;
        }
        self.homography = None;
    }
    /// Forgets everything.
    pub fn discard(&mut self) {
        *self = Points::default();
    }
    /// The 4 output corners in the input points' order.
    pub fn corners(&self) -> Option<[(f64, f64); 4]> {
        let [(x1, y1), (x2, y2)] = self.rect[..] else {
            return None;
        };
        let (l, r) = (x1.min(x2), x1.max(x2));
        let (t, b) = (y1.min(y2), y1.max(y2));
        Some([(l, t), (r, t), (r, b), (l, b)])
    }
    /// Solves the homography; an error says what is missing.
    pub fn rectify(&mut self) -> Result<Matrix3<f64>, String> {
        if self.src.len() != 4 {
            return Err(format!("click 4 input points (have {})", self.src.len()));
        }
        let Some(dst) = self.corners() else {
            return Err(format!(
                "rectangle mode: click 2 output corners (have {})",
                self.rect.len()
            ));
        };
        let h = find_homography(&self.src, &dst)
            .ok_or("the 4 input points are degenerate (3 in a line?)")?;
        self.homography = Some(h);
        Ok(h)
    }
}

/// The 8 numbers h11 h12 h13 h21 h22 h23 h31 h32 (h33 = 1), one line.
pub fn eight_numbers(h: &Matrix3<f64>) -> String {
    let v = [
        h[(0, 0)],
        h[(0, 1)],
        h[(0, 2)],
        h[(1, 0)],
        h[(1, 1)],
        h[(1, 2)],
        h[(2, 0)],
        h[(2, 1)],
    ];
    v.iter()
        .map(|x| format!("{x:.9}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The last rectified frame.
#[derive(Clone, Debug, Default)]
pub struct Rectified {
    pub image: Image,
    pub clock: u64,
}

/// The state shared by the schema, its panel and the name space.
pub struct Rectifier {
    pub points: Mutex<Points>,
    pub result: Mutex<Rectified>,
    pub source: String,
    /// Where Save writes (None: no `save` line, Save says so).
    pub save: Option<PathBuf>,
    /// The last message (solved, saved, or what is missing).
    pub message: Mutex<String>,
}

impl Rectifier {
    /// Solves, prints the 8 numbers and sets the message.
    pub fn rectify(&self) {
        let r = self.points.lock().rectify();
        *self.message.lock() = match r {
            Ok(h) => {
                let s = eight_numbers(&h);
                crate::output::println(format!("imagerectifier: homography {s}"));
                s
            }
            Err(e) => e,
        };
    }
    /// Writes the 8 numbers to the `save` file.
    pub fn save(&self) {
        let h = self.points.lock().homography;
        *self.message.lock() = match (h, &self.save) {
            (None, _) => "nothing to save: rectify first".into(),
            (Some(_), None) => "no `save FILE` line in the conf".into(),
            (Some(h), Some(p)) => match std::fs::write(p, eight_numbers(&h) + "\n") {
                Ok(()) => format!("saved {}", p.display()),
                Err(e) => format!("save {}: {e}", p.display()),
            },
        };
    }
}

/// What imagerectifier does with a frame: warps it once a homography is known.
pub struct RectifierWork {
    pub state: Arc<Rectifier>,
    source: Source,
}

impl Work for RectifierWork {
    type Key = Option<Matrix3<f64>>;
    fn source(&self) -> &Source {
        &self.source
    }
    fn key(&self) -> Self::Key {
        self.state.points.lock().homography
    }
    fn work(&mut self, f: &Frame, h: &Self::Key, out: &Frames<Self::Key>) -> anyhow::Result<()> {
        if let Some(h) = h {
            let s = &f.sample.value;
            let image = warp_perspective(s, h, s.width, s.height);
            out.publish(&image)?;
            *self.state.result.lock() = Rectified {
                image,
                clock: f.sample.clock,
            };
        }
        Ok(())
    }
}

/// A pixel coordinate of `points` and `rectangle`.
const fn px(name: &'static str) -> Arg {
    float(name, "px", -100_000.0, 100_000.0)
}

crate::declare_lines! {
    /// imagerectifier's lines, declared once (`jderobot help imagerectifier`).
    struct Lines {
        image: String = imagesource::IMAGE,
        points: Option<[f64; 8]> = Setting::new(
            "points",
            "the 4 input points, in order: top-left, top-right, bottom-right, bottom-left \
             (with `rectangle`, the homography is solved at load)",
            &[
                px("X1"),
                px("Y1"),
                px("X2"),
                px("Y2"),
                px("X3"),
                px("Y3"),
                px("X4"),
                px("Y4"),
            ],
        ),
        rectangle: Option<[f64; 4]> = Setting::new(
            "rectangle",
            "the output rectangle's opposite corners",
            &[px("X1"), px("Y1"), px("X2"), px("Y2")],
        ),
        save: Option<PathBuf> = Setting::new(
            "save",
            "where Save writes the 8 numbers of the homography",
            &[path("FILE")],
        ),
        output: Option<String> = imagesource::OUTPUT.help("publish the rectified image on this new image interface"),
        cycle: u64 = CYCLE.default("100"),
    }
}
fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let l: Lines = conf.read()?;
    let mut points = Points::default();
    if let Some(v) = l.points {
        points.src = v.chunks(2).map(|p| (p[0], p[1])).collect();
        points.rectangle_mode = true;
    }
    if let Some(v) = l.rectangle {
        points.rect = vec![(v[0], v[1]), (v[2], v[3])];
    }
    // With either line the homography is solved now; an error names the later one.
    let solve_line = [conf.line("points"), conf.line("rectangle")]
        .into_iter()
        .flatten()
        .max_by_key(|l| l.at.line);
    if let Some(line) = solve_line {
        points
            .rectify()
            .map_err(|e| line.error(format!("points/rectangle: {e}")))?;
    }
    let image = imagesource::image(conf, &rt.interfaces, "image", &l.image)?;
    let output = imagesource::output(conf, &rt.interfaces, l.output.as_deref())?;
    let state = Arc::new(Rectifier {
        points: Mutex::new(points),
        result: Mutex::new(Rectified::default()),
        source: image.name().to_string(),
        save: l.save,
        message: Mutex::new(String::new()),
    });
    rt.names
        .export_arc(&conf.name, "state", state.clone())
        .map_err(anyhow::Error::msg)?;
    let work = RectifierWork {
        state: state.clone(),
        source: Source::fixed(image.name()),
    };
    let schema = imagesource::FrameSchema::new(work, output, l.cycle);
    #[cfg(feature = "gui")]
    let schema = schema.with_panel(panel::RectifierPanel::new(state, image));
    Ok(Box::new(schema))
}

crate::register_schema!(
    "imagerectifier",
    "click 4 points and a rectangle: the homography is solved and the live image rectified",
    create,
    lines = Lines
);

#[cfg(feature = "gui")]
pub mod panel {
    //! imagerectifier's panel: input and output side by side, the buttons.
    use super::*;
    use crate::widgets::{ImageView, pixel_rect};
    use egui::{Color32, Stroke};

    pub struct RectifierPanel {
        state: Arc<Rectifier>,
        image: Arc<Interface<Image>>,
        input: ImageView,
        output: ImageView,
        help: bool,
    }

    impl RectifierPanel {
        pub fn new(state: Arc<Rectifier>, image: Arc<Interface<Image>>) -> Self {
            RectifierPanel {
                state,
                image,
                input: ImageView::new("imagerectifier input"),
                output: ImageView::new("imagerectifier output"),
                help: false,
            }
        }
    }

    fn marks(ui: &egui::Ui, rect: egui::Rect, img: &Image, pts: &[(f64, f64)], c: Color32) {
        let p = ui.painter_at(rect);
        for (k, &(x, y)) in pts.iter().enumerate() {
            if x < 0.0 || y < 0.0 || x >= img.width as f64 || y >= img.height as f64 {
                continue;
            }
            let r = pixel_rect(rect, img.width, img.height, x as u32, y as u32).center();
            p.circle_stroke(r, 5.0, Stroke::new(2.0, c));
            p.text(
                r + egui::vec2(6.0, -6.0),
                egui::Align2::LEFT_BOTTOM,
                format!("{}", k + 1),
                egui::FontId::proportional(12.0),
                c,
            );
        }
    }

    impl crate::runtime::Panel for RectifierPanel {
        fn ui(&mut self, ui: &mut egui::Ui, _rt: &Runtime) {
            let s = self.image.snapshot();
            let res = self.state.result.lock().clone();
            let pts = self.state.points.lock().clone();
            ui.horizontal(|ui| {
                if ui.button("Rectify").clicked() {
                    self.state.rectify();
                }
                if ui.button("Undo").clicked() {
                    self.state.points.lock().undo();
                }
                if ui.button("Discard").clicked() {
                    self.state.points.lock().discard();
                }
                let mut mode = pts.rectangle_mode;
                if ui.toggle_value(&mut mode, "Rectangle mode").changed() {
                    self.state.points.lock().rectangle_mode = mode;
                }
                if ui.button("Save").clicked() {
                    self.state.save();
                }
                ui.toggle_value(&mut self.help, "Help");
            });
            if self.help {
                ui.label(
                    "Click 4 points on the input in order: top-left, top-right, \
                     bottom-right, bottom-left of the plane. Rectangle mode then takes 2 \
                     opposite corners on the output. Rectify solves the homography.",
                );
            }
            ui.label(self.state.message.lock().clone());
            let half = (ui.available_width() / 2.0 - 8.0).max(120.0);
            ui.horizontal_top(|ui| {
                ui.vertical(|ui| {
                    ui.set_max_width(half);
                    ui.label(format!(
                        "input {} ({} of 4 points)",
                        self.state.source,
                        pts.src.len()
                    ));
                    let r = self.input.show_sample(ui, &s);
                    marks(ui, r.rect, &s.value, &pts.src, Color32::RED);
                    if let Some(p) = r.pick {
                        self.state
                            .points
                            .lock()
                            .click(p.x as f64, p.y as f64, false);
                    }
                });
                ui.vertical(|ui| {
                    ui.set_max_width(half);
                    ui.label(format!("output ({} of 2 corners)", pts.rect.len()));
                    // The rectified frame once solved; the input until then.
                    let r = if pts.homography.is_some() && res.clock > 0 {
                        self.output.show(ui, &res.image, res.clock)
                    } else {
                        self.output.show_sample(ui, &s)
                    };
                    let shown = if pts.homography.is_some() && res.clock > 0 {
                        &res.image
                    } else {
                        &s.value
                    };
                    marks(ui, r.rect, shown, &pts.rect, Color32::GREEN);
                    if let Some(p) = r.pick {
                        self.state.points.lock().click(p.x as f64, p.y as f64, true);
                    }
                });
            });
        }
    }
}
