//! calibrador: intrinsic and extrinsic calibration from a known 3D pattern.
//!
//! The pattern's 3D points (mm; at least 6, not all in one plane: e.g. two faces of
//! a box) get image points, from the conf (`point X Y Z U V`) or by clicking them on
//! the live image in order. Calibrate runs a normalised DLT, an RQ decomposition and
//! a Levenberg-Marquardt refinement of fx, fy, cx, cy and the pose (nalgebra; no
//! GSL) and shows K, the camera position and the reprojection error; Save writes
//! the result as a progeo camera file (4.3's format, see [`crate::progeo`]).
//! Automatic corner detection is not done: points are given or clicked.
//!
//! Conf:
//! ```text
//! schema calibrador
//! image colorA               # colorA..D or varcolorA..D (its size goes in the file)
//! point 0 0 0                # X Y Z (mm) of a pattern point, in clicking order;
//! point 100 0 0 412.5 230.1  #   with U V (graphic pixels: column, row) it is given
//! pattern pattern.txt        # or a file of `X Y Z [U V]` lines (# comments)
//! camera_out /tmp/calibrated # where Save writes the progeo camera file
//! end_schema
//! ```
//! `jderobot help calibrador` prints these lines with their ranges and defaults.
//! With every point's U V given, it calibrates at load (headless). Interfaces used:
//! the `image` (BGR). Name space, component `calibrador`: `state` ([`Calibrador`]).
//! System packages: none.

pub mod solve;

use std::{path::PathBuf, sync::Arc, time::Duration};

use parking_lot::Mutex;

pub use solve::{Calibration, CalibrationError, calibrate};

use crate::{
    conf::{
        ComponentConf, ConfLine,
        settings::{Arg, Setting, float, path},
    },
    imagesource,
    interfaces::{Image, Interface},
    runtime::{Context, Runtime, Schema},
};

/// A pattern point and its pixel (graphic: column, row), once given.
#[derive(Clone, Debug, PartialEq)]
pub struct PatternPoint {
    pub world: [f64; 3],
    pub image: Option<(f64, f64)>,
}

/// The state shared by the schema, its panel and the name space.
pub struct Calibrador {
    pub points: Mutex<Vec<PatternPoint>>,
    pub result: Mutex<Option<Calibration>>,
    pub message: Mutex<String>,
    pub camera_out: Option<PathBuf>,
    /// The image size (columns, rows) for the camera file.
    pub size: Mutex<(u32, u32)>,
}

impl Calibrador {
    /// Gives the next point without a pixel this one.
    pub fn click(&self, u: f64, v: f64) {
        if let Some(p) = self.points.lock().iter_mut().find(|p| p.image.is_none()) {
            p.image = Some((u, v));
        }
    }
    /// Forgets the last given pixel.
    pub fn undo(&self) {
        if let Some(p) = self
            .points
            .lock()
            .iter_mut()
            .rev()
            .find(|p| p.image.is_some())
        {
            p.image = None;
        }
    }
    /// Forgets every pixel.
    pub fn clear(&self) {
        for p in self.points.lock().iter_mut() {
            p.image = None;
        }
        *self.result.lock() = None;
    }
    /// Calibrates with the points that have pixels; sets the message.
    pub fn calibrate(&self) -> Result<Calibration, CalibrationError> {
        let (w, i): (Vec<[f64; 3]>, Vec<(f64, f64)>) = self
            .points
            .lock()
            .iter()
            .filter_map(|p| p.image.map(|i| (p.world, i)))
            .unzip();
        let r = calibrate(&w, &i);
        *self.message.lock() = match &r {
            Ok(c) => {
                let p = c.position();
                let s = format!(
                    "fx {:.2} fy {:.2} cx {:.2} cy {:.2}; position ({:.1}, {:.1}, {:.1}) mm; \
                     reprojection error {:.3} px ({} points)",
                    c.fx,
                    c.fy,
                    c.cx,
                    c.cy,
                    p.x,
                    p.y,
                    p.z,
                    c.rms,
                    w.len()
                );
                crate::output::println(format!("calibrador: {s}"));
                s
            }
            Err(e) => e.to_string(),
        };
        *self.result.lock() = r.clone().ok();
        r
    }
    /// Writes the progeo camera file.
    pub fn save(&self) {
        let (cols, rows) = *self.size.lock();
        *self.message.lock() = match (self.result.lock().clone(), &self.camera_out) {
            (None, _) => "nothing to save: calibrate first".into(),
            (Some(_), None) => "no `camera_out FILE` line in the conf".into(),
            (Some(c), Some(p)) => match c.to_progeo(cols, rows).save(p) {
                Ok(()) => format!("saved {}", p.display()),
                Err(e) => e.to_string(),
            },
        };
    }
}

/// The schema: keeps the image size and makes the image used.
pub struct CalibradorSchema {
    pub state: Arc<Calibrador>,
    image: Arc<Interface<Image>>,
    #[cfg(feature = "gui")]
    panel: Option<Box<dyn crate::runtime::Panel>>,
}

impl Schema for CalibradorSchema {
    fn cycle(&self) -> Duration {
        Duration::from_millis(100)
    }
    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        ctx.run_children(&[self.image.name()], None)?;
        Ok(())
    }
    fn iteration(&mut self, _ctx: &Context) -> anyhow::Result<()> {
        let s = self.image.read();
        if s.clock > 0 {
            *self.state.size.lock() = (s.value.width, s.value.height);
        }
        Ok(())
    }
    #[cfg(feature = "gui")]
    fn panel(&mut self) -> Option<Box<dyn crate::runtime::Panel>> {
        self.panel.take()
    }
}

fn point_from(words: &[f64]) -> Option<PatternPoint> {
    match words {
        [x, y, z] => Some(PatternPoint {
            world: [*x, *y, *z],
            image: None,
        }),
        [x, y, z, u, v] => Some(PatternPoint {
            world: [*x, *y, *z],
            image: Some((*u, *v)),
        }),
        _ => None,
    }
}

/// A pattern coordinate of `point`.
const fn mm(name: &'static str) -> Arg {
    float(name, "mm", -1e9, 1e9)
}
/// A pixel of `point`.
const fn px(name: &'static str) -> Arg {
    float(name, "px", -1e9, 1e9)
}

crate::declare_lines! {
    /// calibrador's lines, declared once (`jderobot help calibrador`).
    struct Lines {
        image: String = imagesource::IMAGE.help("the image it calibrates (its size goes in the camera file)"),
        point: Vec<PointLine> = Setting::new(
            "point",
            "a pattern point, in clicking order; with U V (column, row) its pixel is given",
            &[mm("X"), mm("Y"), mm("Z"), px("U").optional(), px("V")],
        )
        .repeats(),
        pattern: Vec<PathBuf> = Setting::new(
            "pattern",
            "a file of `X Y Z [U V]` lines (# comments): more points, in order",
            &[path("FILE")],
        )
        .repeats(),
        camera_out: Option<PathBuf> = Setting::new(
            "camera_out",
            "where Save writes the progeo camera file",
            &[path("FILE")],
        ),
    }
}
/// A `point X Y Z [U V]` line.
type PointLine = (f64, f64, f64, Option<f64>, Option<f64>);

/// The points of a pattern file (an error names the conf line and the file's line).
fn pattern(line: &ConfLine, f: &std::path::Path) -> anyhow::Result<Vec<PatternPoint>> {
    let text = crate::files::FileError::read(f).map_err(|e| line.error(format!("pattern {e}")))?;
    let mut points = Vec::new();
    for (n, raw) in text.lines().enumerate() {
        let words = raw.split('#').next().unwrap_or_default().trim();
        if words.is_empty() {
            continue;
        }
        let v: Option<Vec<f64>> = words
            .split_whitespace()
            .map(|w| w.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect();
        let p = v.as_deref().and_then(point_from).ok_or_else(|| {
            line.error(format!(
                "pattern {}:{}: expected `X Y Z [U V]` numbers, got `{words}`",
                f.display(),
                n + 1
            ))
        })?;
        points.push(p);
    }
    Ok(points)
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let l: Lines = conf.read()?;
    // `point` and `pattern` lines give the points in the order they are written.
    let (mut given, mut files) = (l.point.into_iter(), l.pattern.into_iter());
    let mut points = Vec::new();
    let mut last_point: Option<&ConfLine> = None;
    for line in &conf.lines {
        match line.keyword() {
            "point" => {
                let Some((x, y, z, u, v)) = given.next() else {
                    break;
                };
                let image = match (u, v) {
                    (Some(u), Some(v)) => Some((u, v)),
                    (None, None) => None,
                    _ => return Err(line.error("point X Y Z [U V]: U needs V").into()),
                };
                points.push(PatternPoint {
                    world: [x, y, z],
                    image,
                });
            }
            "pattern" => {
                let Some(f) = files.next() else { break };
                points.extend(pattern(line, &f)?);
            }
            _ => continue,
        }
        last_point = Some(line);
    }
    let source = l.image;
    let image = imagesource::image(conf, &rt.interfaces, "image", &source)?;
    let all_given = !points.is_empty() && points.iter().all(|p| p.image.is_some());
    let state = Arc::new(Calibrador {
        points: Mutex::new(points),
        result: Mutex::new(None),
        message: Mutex::new(String::new()),
        camera_out: l.camera_out,
        size: Mutex::new((320, 240)),
    });
    if all_given {
        state.calibrate().map_err(|e| {
            last_point
                .as_ref()
                .map(|l| l.error(format!("calibration: {e}")))
                .map(anyhow::Error::from)
                .unwrap_or_else(|| anyhow::anyhow!("calibration: {e}"))
        })?;
    }
    rt.names
        .export_arc(&conf.name, "state", state.clone())
        .map_err(anyhow::Error::msg)?;
    Ok(Box::new(CalibradorSchema {
        #[cfg(feature = "gui")]
        panel: Some(Box::new(panel::CalibradorPanel::new(
            state.clone(),
            image.clone(),
        ))),
        state,
        image,
    }))
}

crate::register_schema!(
    "calibrador",
    "camera calibration from a known 3D pattern: DLT + refinement, K, pose, progeo camera file",
    create,
    lines = Lines
);

#[cfg(feature = "gui")]
pub mod panel {
    //! calibrador's panel: the image with the given (red) and reprojected (green)
    //! points, the next point to click, the buttons and the result.
    use super::*;
    use crate::widgets::ImageView;
    use egui::{Color32, Stroke, pos2};

    pub struct CalibradorPanel {
        state: Arc<Calibrador>,
        image: Arc<Interface<Image>>,
        view: ImageView,
    }

    impl CalibradorPanel {
        pub fn new(state: Arc<Calibrador>, image: Arc<Interface<Image>>) -> Self {
            CalibradorPanel {
                state,
                image,
                view: ImageView::new("calibrador image"),
            }
        }
    }

    impl crate::runtime::Panel for CalibradorPanel {
        fn ui(&mut self, ui: &mut egui::Ui, _rt: &Runtime) {
            ui.horizontal(|ui| {
                if ui.button("Calibrate").clicked() {
                    let _ = self.state.calibrate();
                }
                if ui.button("Undo").clicked() {
                    self.state.undo();
                }
                if ui.button("Clear").clicked() {
                    self.state.clear();
                }
                if ui.button("Save").clicked() {
                    self.state.save();
                }
            });
            let pts = self.state.points.lock().clone();
            let given = pts.iter().filter(|p| p.image.is_some()).count();
            match pts.iter().find(|p| p.image.is_none()) {
                Some(p) => ui.label(format!(
                    "click point {} of {}: ({}, {}, {}) mm",
                    given + 1,
                    pts.len(),
                    p.world[0],
                    p.world[1],
                    p.world[2]
                )),
                None => ui.label(format!("all {} points given", pts.len())),
            };
            ui.label(self.state.message.lock().clone());
            let s = self.image.snapshot();
            let r = self.view.show_sample(ui, &s);
            if let Some(p) = r.pick {
                self.state.click(p.x as f64 + 0.5, p.y as f64 + 0.5);
            }
            let (w, h) = (s.value.width.max(1) as f32, s.value.height.max(1) as f32);
            let to_screen = |u: f64, v: f64| {
                pos2(
                    r.rect.min.x + u as f32 / w * r.rect.width(),
                    r.rect.min.y + v as f32 / h * r.rect.height(),
                )
            };
            let painter = ui.painter_at(r.rect);
            let result = self.state.result.lock().clone();
            for p in &pts {
                if let Some((u, v)) = p.image {
                    painter.circle_stroke(to_screen(u, v), 4.0, Stroke::new(1.5, Color32::RED));
                }
                if let Some(c) = &result
                    && let Some((u, v)) = c.project(p.world)
                {
                    painter.circle_filled(to_screen(u, v), 2.0, Color32::GREEN);
                }
            }
        }
    }
}
