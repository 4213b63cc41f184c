//! extrinsics: fit a progeo camera to a live image by eye (4.3's extrinsics).
//!
//! The world's 3D lines are projected with the camera and drawn in red over the
//! image, with a green cross at the optical centre (u0, v0). Sliders move the
//! camera (position, FOA, roll in degrees, focal distance, u0, v0); with `fixed FOA`
//! moving the position keeps the point looked at, without it the FOA moves along;
//! `flip` turns the image 180°; the mouse wheel over the image moves the camera
//! along its optical axis. Save writes cameraOUTfile, Reload reads cameraINfile,
//! Undo reads cameraOUTfile (written at load, as 4.3 did, so Undo works at once).
//! Beside the image, an external virtual camera shows the world and the camera's
//! frustum (drag orbits, wheel zooms).
//!
//! Conf:
//! ```text
//! schema extrinsics
//! world ../assets/cameras/room.world   # required: the world file (4.3's format, see
//!                                      #   crate::progeo) naming cameraINfile and
//!                                      #   cameraOUTfile (relative to the world file,
//!                                      #   or to the current directory as 4.3)
//! image colorA                         # colorA..D or varcolorA..D
//! output varcolorD                     # optional: publish the drawn image here
//! cycle 100
//! end_schema
//! ```
//! `jderobot help extrinsics` prints these lines with their ranges and defaults.
//! Interfaces used: the `image` (BGR); provided: `output` if given.
//!
//! Headless it draws each new frame and exports, component `extrinsics`, `state`
//! ([`Extrinsics`]: the camera, the world, the toggles). System packages: none.

use std::{
    path::{Path, PathBuf},
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
};

use parking_lot::Mutex;

use crate::{
    conf::{
        ComponentConf,
        settings::{CYCLE, Setting, path},
    },
    imagesource::{self, Frame, Frames, Source, Work},
    interfaces::Image,
    progeo::{HPoint2D, HPoint3D, PinholeCamera, World},
    runtime::{Runtime, Schema},
    vision::draw_line,
};

/// The state shared by the schema, its panel and the name space.
pub struct Extrinsics {
    pub camera: Mutex<PinholeCamera>,
    pub world: World,
    pub camera_in: PathBuf,
    pub camera_out: PathBuf,
    pub fixed_foa: AtomicBool,
    pub flip: AtomicBool,
    /// The last drawn frame and its source clock.
    pub drawn: Mutex<(Image, u64)>,
    pub message: Mutex<String>,
}

impl Extrinsics {
    /// Save: writes the camera to cameraOUTfile.
    pub fn save(&self) {
        let c = self.camera.lock().clone();
        *self.message.lock() = match c.save(&self.camera_out) {
            Ok(()) => format!("saved {}", self.camera_out.display()),
            Err(e) => format!("{e}"),
        };
    }
    fn load_from(&self, p: &Path) {
        *self.message.lock() = match PinholeCamera::load(p) {
            Ok(c) => {
                *self.camera.lock() = c;
                format!("loaded {}", p.display())
            }
            Err(e) => format!("{e}"),
        };
    }
    /// Reload: reads cameraINfile.
    pub fn reload(&self) {
        self.load_from(&self.camera_in.clone());
    }
    /// Undo: reads cameraOUTfile (the last save, or the camera as loaded).
    pub fn undo(&self) {
        self.load_from(&self.camera_out.clone());
    }
    /// Moves the camera by `d` (mm); the FOA moves along unless it is fixed.
    pub fn translate(&self, d: [f64; 3]) {
        let fixed = self.fixed_foa.load(Ordering::Relaxed);
        let mut c = self.camera.lock();
        c.position = HPoint3D::point(
            c.position.x + d[0],
            c.position.y + d[1],
            c.position.z + d[2],
        );
        if !fixed {
            c.foa = HPoint3D::point(c.foa.x + d[0], c.foa.y + d[1], c.foa.z + d[2]);
        }
        c.update_camera_matrix();
    }
    /// Moves the camera `mm` along its optical axis (towards the FOA when positive).
    pub fn advance(&self, mm: f64) {
        let c = self.camera.lock().clone();
        let (p, f) = (c.position, c.foa);
        let v = [f.x - p.x, f.y - p.y, f.z - p.z];
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if n > 1e-9 && mm.is_finite() {
            self.translate([v[0] / n * mm, v[1] / n * mm, v[2] / n * mm]);
        }
    }
}

/// The world's segments as drawn by `cam` on an image of `width` x `height`
/// (graphic pixels, scaled from the camera's size), clipped to the image.
pub fn projected_lines(
    cam: &PinholeCamera,
    world: &World,
    width: u32,
    height: u32,
) -> Vec<((f64, f64), (f64, f64))> {
    let sx = width as f64 / cam.columns.max(1) as f64;
    let sy = height as f64 / cam.rows.max(1) as f64;
    world
        .lines
        .iter()
        .filter_map(|(a, b)| cam.displayline(cam.project(*a), cam.project(*b)))
        .map(|(p, q)| {
            let (pc, pr) = cam.optical_to_graphic(p);
            let (qc, qr) = cam.optical_to_graphic(q);
            ((pc * sx, pr * sy), (qc * sx, qr * sy))
        })
        .collect()
}

/// The image with the world in red and the optical centre as a green cross,
/// turned 180° first when `flip`.
pub fn draw(img: &Image, cam: &PinholeCamera, world: &World, flip: bool) -> Image {
    let mut out = img.clone();
    if flip {
        let n = (out.width as usize * out.height as usize).min(out.data.len() / 3);
        let px: Vec<[u8; 3]> = out.data[..n * 3]
            .chunks_exact(3)
            .rev()
            .map(|p| [p[0], p[1], p[2]])
            .collect();
        for (d, s) in out.data.chunks_exact_mut(3).zip(px) {
            d.copy_from_slice(&s);
        }
    }
    // Three pixels wide, so the lines survive the panel's downscaling.
    for (a, b) in projected_lines(cam, world, img.width, img.height) {
        let across_y = (b.0 - a.0).abs() >= (b.1 - a.1).abs();
        for o in [-1.0, 0.0, 1.0] {
            let (dx, dy) = if across_y { (0.0, o) } else { (o, 0.0) };
            draw_line(
                &mut out,
                (a.0 + dx, a.1 + dy),
                (b.0 + dx, b.1 + dy),
                [0, 0, 255],
            );
        }
    }
    let sx = img.width as f64 / cam.columns.max(1) as f64;
    let sy = img.height as f64 / cam.rows.max(1) as f64;
    let (c, r) = cam.optical_to_graphic(HPoint2D::new(cam.u0, cam.v0, 1.0));
    let (c, r) = (c * sx, r * sy);
    draw_line(&mut out, (c - 6.0, r), (c + 6.0, r), [0, 255, 0]);
    draw_line(&mut out, (c, r - 6.0), (c, r + 6.0), [0, 255, 0]);
    out
}

/// What extrinsics does with a frame: draws the world on it with the camera.
pub struct ExtrinsicsWork {
    pub state: Arc<Extrinsics>,
    source: Source,
}

impl Work for ExtrinsicsWork {
    /// The camera (as its file text) and the flip.
    type Key = (String, bool);
    fn source(&self) -> &Source {
        &self.source
    }
    fn key(&self) -> Self::Key {
        (
            self.state.camera.lock().to_file_string(),
            self.state.flip.load(Ordering::Relaxed),
        )
    }
    fn work(
        &mut self,
        f: &Frame,
        &(_, flip): &Self::Key,
        out: &Frames<Self::Key>,
    ) -> anyhow::Result<()> {
        let cam = self.state.camera.lock().clone();
        let drawn = draw(&f.sample.value, &cam, &self.state.world, flip);
        out.publish(&drawn)?;
        *self.state.drawn.lock() = (drawn, f.sample.clock);
        Ok(())
    }
}

crate::declare_lines! {
    /// extrinsics' lines, declared once (`jderobot help extrinsics`).
    struct Lines {
        world: Option<PathBuf> = Setting::new(
            "world",
            "required: the world file (4.3's format) naming cameraINfile and cameraOUTfile \
             (relative to the world file, or to the current directory as 4.3)",
            &[path("FILE")],
        ),
        image: String = imagesource::IMAGE,
        output: Option<String> = imagesource::OUTPUT.help("publish the drawn image on this new image interface"),
        cycle: u64 = CYCLE.default("100"),
    }
}
/// A camera file named in a world file: relative to the world file's directory if
/// it exists there, else as given (the current directory, as 4.3).
fn resolve(world_file: &Path, p: &Path) -> PathBuf {
    if p.is_absolute() {
        return p.to_path_buf();
    }
    let beside = world_file.parent().unwrap_or(Path::new(".")).join(p);
    if beside.exists() || !p.exists() {
        beside
    } else {
        p.to_path_buf()
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let l: Lines = conf.read()?;
    let (Some(_), Some(wl)) = (l.world, conf.line("world")) else {
        anyhow::bail!(
            "{}: schema {}: a `world FILE` line is required (a world file naming cameraINfile \
             and cameraOUTfile, e.g. assets/cameras/room.world)",
            conf.file.display(),
            conf.name
        );
    };
    let f = wl.existing_file(0, "the world file")?;
    let world = World::load(&f).map_err(|e| wl.error(format!("world: {e}")))?;
    let cin = world
        .camera_in
        .clone()
        .ok_or_else(|| wl.error(format!("world {}: no cameraINfile line", f.display())))?;
    let cout = world
        .camera_out
        .clone()
        .ok_or_else(|| wl.error(format!("world {}: no cameraOUTfile line", f.display())))?;
    let (camera_in, camera_out) = (resolve(&f, &cin), resolve(&f, &cout));
    let camera =
        PinholeCamera::load(&camera_in).map_err(|e| wl.error(format!("cameraINfile: {e}")))?;
    // As 4.3: write cameraOUTfile at once, so Undo works before any Save.
    camera
        .save(&camera_out)
        .map_err(|e| wl.error(format!("cameraOUTfile: {e}")))?;
    let image = imagesource::image(conf, &rt.interfaces, "image", &l.image)?;
    let output = imagesource::output(conf, &rt.interfaces, l.output.as_deref())?;
    let state = Arc::new(Extrinsics {
        camera: Mutex::new(camera),
        world,
        camera_in,
        camera_out,
        fixed_foa: AtomicBool::new(false),
        flip: AtomicBool::new(false),
        drawn: Mutex::new((Image::default(), 0)),
        message: Mutex::new(String::new()),
    });
    rt.names
        .export_arc(&conf.name, "state", state.clone())
        .map_err(anyhow::Error::msg)?;
    let work = ExtrinsicsWork {
        state: state.clone(),
        source: Source::fixed(image.name()),
    };
    let schema = imagesource::FrameSchema::new(work, output, l.cycle);
    #[cfg(feature = "gui")]
    let schema = schema.with_panel(panel::ExtrinsicsPanel::new(state));
    Ok(Box::new(schema))
}

crate::register_schema!(
    "extrinsics",
    "fit a progeo camera by eye: world lines over the live image, sliders, save/reload/undo",
    create,
    lines = Lines
);

#[cfg(feature = "gui")]
pub mod panel {
    //! extrinsics' panel: sliders and buttons, the drawn image, the external view.
    use super::*;
    use crate::widgets::{ImageView, OrbitCamera, Segment3D, Wireframe3D};
    use egui::{Color32, vec2};

    pub struct ExtrinsicsPanel {
        state: Arc<Extrinsics>,
        view: ImageView,
        external: Wireframe3D,
    }

    impl ExtrinsicsPanel {
        pub fn new(state: Arc<Extrinsics>) -> Self {
            // 4.3's virtual external camera looked from (14777, 1907, 6111) at
            // (0, 1975, -225): an orbit about that point at the same distance.
            let orbit = OrbitCamera {
                target: [0.0, 1975.0, -225.0],
                distance: 16_100.0,
                azimuth_deg: 0.5,
                elevation_deg: 23.0,
                fov_deg: 40.0,
            };
            ExtrinsicsPanel {
                state,
                view: ImageView::new("extrinsics image"),
                external: Wireframe3D::new("extrinsics external", orbit),
            }
        }
    }

    /// The world (grey) and the camera's frustum (red, 1 m deep) as 3D segments.
    pub fn scene(cam: &PinholeCamera, world: &World) -> Vec<Segment3D> {
        let e = |p: &HPoint3D| [p.x, p.y, p.z];
        let mut v: Vec<Segment3D> = world
            .lines
            .iter()
            .map(|(a, b)| (e(a), e(b), Color32::GRAY))
            .collect();
        let o = e(&cam.position);
        let (r, c) = (cam.rows as f64 - 1.0, cam.columns as f64 - 1.0);
        let corners: Vec<[f64; 3]> = [(0.0, 0.0), (r, 0.0), (r, c), (0.0, c)]
            .iter()
            .filter_map(|&(x, y)| cam.ray(HPoint2D::new(x, y, 1.0)))
            .map(|d| {
                let d = d.normalize() * 1000.0;
                [o[0] + d.x, o[1] + d.y, o[2] + d.z]
            })
            .collect();
        for (k, p) in corners.iter().enumerate() {
            v.push((o, *p, Color32::RED));
            v.push((*p, corners[(k + 1) % corners.len()], Color32::RED));
        }
        v.push((o, e(&cam.foa), Color32::YELLOW));
        v
    }

    impl crate::runtime::Panel for ExtrinsicsPanel {
        fn ui(&mut self, ui: &mut egui::Ui, _rt: &Runtime) {
            let mut cam = self.state.camera.lock().clone();
            let before = cam.to_file_string();
            let (img, clock) = self.state.drawn.lock().clone();
            ui.horizontal(|ui| {
                if ui.button("Save").clicked() {
                    self.state.save();
                }
                if ui.button("Reload").clicked() {
                    self.state.reload();
                }
                if ui.button("Undo").clicked() {
                    self.state.undo();
                }
                let mut fixed = self.state.fixed_foa.load(Ordering::Relaxed);
                if ui.checkbox(&mut fixed, "fixed FOA").changed() {
                    self.state.fixed_foa.store(fixed, Ordering::Relaxed);
                }
                let mut flip = self.state.flip.load(Ordering::Relaxed);
                if ui.checkbox(&mut flip, "flip").changed() {
                    self.state.flip.store(flip, Ordering::Relaxed);
                }
                ui.label(self.state.message.lock().clone());
            });
            if before != self.state.camera.lock().to_file_string() {
                return; // a button replaced the camera: draw it next frame
            }
            let mut moved = [0.0f64; 3];
            ui.horizontal_top(|ui| {
                ui.vertical(|ui| {
                    ui.set_max_width(260.0);
                    let mut pos = [cam.position.x, cam.position.y, cam.position.z];
                    for (k, n) in ["X", "Y", "Z"].iter().enumerate() {
                        let old = pos[k];
                        ui.add(
                            egui::Slider::new(&mut pos[k], -20_000.0..=20_000.0)
                                .text(format!("position {n} mm")),
                        );
                        moved[k] = pos[k] - old;
                    }
                    let mut foa = [cam.foa.x, cam.foa.y, cam.foa.z];
                    for (k, n) in ["X", "Y", "Z"].iter().enumerate() {
                        ui.add(
                            egui::Slider::new(&mut foa[k], -20_000.0..=20_000.0)
                                .text(format!("FOA {n} mm")),
                        );
                    }
                    cam.foa = HPoint3D::point(foa[0], foa[1], foa[2]);
                    let mut roll = cam.roll.to_degrees();
                    ui.add(egui::Slider::new(&mut roll, -180.0..=180.0).text("roll °"));
                    cam.roll = roll.to_radians();
                    let mut f = cam.fdistx;
                    ui.add(egui::Slider::new(&mut f, 50.0..=3000.0).text("focus fx px"));
                    cam.fdistx = f;
                    cam.fdisty = f;
                    ui.add(egui::Slider::new(&mut cam.u0, 0.0..=cam.rows as f64).text("u0 px"));
                    ui.add(egui::Slider::new(&mut cam.v0, 0.0..=cam.columns as f64).text("v0 px"));
                });
                ui.vertical(|ui| {
                    let r = self.view.show(ui, &img, clock);
                    if r.response.hovered() {
                        let scroll = ui.input(|i| i.smooth_scroll_delta.y);
                        if scroll != 0.0 {
                            // Wheel up: forward along the optical axis, 10 mm per point.
                            self.state.advance(scroll as f64 * 10.0);
                        }
                    }
                    self.external
                        .show(ui, vec2(0.0, 220.0), &scene(&cam, &self.state.world));
                });
            });
            if cam.to_file_string() != before || moved.iter().any(|&d| d != 0.0) {
                cam.update_camera_matrix();
                *self.state.camera.lock() = cam;
                if moved.iter().any(|&d| d != 0.0) {
                    self.state.translate(moved);
                }
            }
        }
    }
}
