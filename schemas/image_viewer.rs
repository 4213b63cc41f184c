//! image_viewer: every image interface of the run side by side, with its size,
//! rate (new images per second), clock and age; a click on a pixel gives its BGR
//! and HSV values; a button saves the frame shown to a PNG file.
//!
//! Conf (every line optional):
//! ```text
//! schema image_viewer
//! images colorA varcolorB  # the image interfaces to show (any of colorA..D,
//!                          #   varcolorA..D); default: every image interface the
//!                          #   run provides when the schema is loaded
//! cycle 100                # ms between statistics updates
//! save_dir .               # where the panel's Save button writes NAME-CLOCK.png
//!                          #   (relative to the conf file); default: the current dir
//! end_schema
//! load_schema image_viewer
//! run image_viewer         # uses (runs) its interfaces, so their drivers publish
//! show image_viewer
//! ```
//! `jderobot help image_viewer` prints these lines with their ranges and defaults.
//! Interfaces used: the image interfaces named (BGR, 8 bits per channel).
//!
//! Headless the schema still computes each view's statistics and exports them in
//! the name space, component `image_viewer`, name `views`
//! (`parking_lot::Mutex<Vec<ViewStats>>`); [`save_png`] writes a frame.
//! System packages: none.

use std::{
    path::{Path, PathBuf},
    sync::Arc,
    time::{Duration, Instant},
};

use parking_lot::Mutex;

use crate::{
    conf::{
        ComponentConf,
        settings::{CYCLE, Setting, path, rest},
    },
    imagesource,
    interfaces::{Image, Interface},
    runtime::{Context, Runtime, Schema},
};

/// One view's statistics.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ViewStats {
    /// The interface name.
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// The interface clock (number of images published).
    pub clock: u64,
    /// New images per second over the last second or so.
    pub fps: f32,
    /// Time since the shown image was published, in ms (`None` before the first).
    pub age_ms: Option<f32>,
    /// Why the interface is stale, if it is.
    pub stale: Option<String>,
}

/// Rate meter: clock deltas over a window of about one second.
struct Meter {
    from: Option<(Instant, u64)>,
    fps: f32,
}

impl Meter {
    fn update(&mut self, now: Instant, clock: u64) -> f32 {
        match self.from {
            None => self.from = Some((now, clock)),
            Some((t0, c0)) => {
                let dt = now.duration_since(t0).as_secs_f32();
                if dt >= 1.0 {
                    self.fps = clock.saturating_sub(c0) as f32 / dt;
                    self.from = Some((now, clock));
                }
            }
        }
        self.fps
    }
}

/// The schema.
pub struct ImageViewer {
    images: Vec<Arc<Interface<Image>>>,
    meters: Vec<Meter>,
    /// The statistics, shared with the panel and the name space.
    pub views: Arc<Mutex<Vec<ViewStats>>>,
    cycle: Duration,
    #[cfg(feature = "gui")]
    panel: Option<Box<dyn crate::runtime::Panel>>,
}

/// Computes the statistics of `iface` (rate from `meter`).
fn stats(iface: &Interface<Image>, meter: &mut Meter, now: Instant) -> ViewStats {
    let s = iface.read();
    ViewStats {
        name: iface.name().to_string(),
        width: s.value.width,
        height: s.value.height,
        clock: s.clock,
        fps: meter.update(now, s.clock),
        age_ms: (s.clock > 0).then(|| s.stamp.elapsed().as_secs_f32() * 1000.0),
        stale: iface.stale(),
    }
}

impl Schema for ImageViewer {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        let names: Vec<&str> = self.images.iter().map(|i| i.name()).collect();
        ctx.run_children(&names, None)?;
        Ok(())
    }
    fn iteration(&mut self, _ctx: &Context) -> anyhow::Result<()> {
        let now = Instant::now();
        let v: Vec<ViewStats> = self
            .images
            .iter()
            .zip(self.meters.iter_mut())
            .map(|(i, m)| stats(i, m, now))
            .collect();
        *self.views.lock() = v;
        Ok(())
    }
    #[cfg(feature = "gui")]
    fn panel(&mut self) -> Option<Box<dyn crate::runtime::Panel>> {
        self.panel.take()
    }
}

/// Writes a BGR image as an 8-bit RGB PNG.
pub fn save_png(image: &Image, path: &Path) -> anyhow::Result<()> {
    use anyhow::Context as _;
    let (w, h) = (image.width as usize, image.height as usize);
    if w == 0 || h == 0 || image.data.len() < w * h * 3 {
        anyhow::bail!("save {}: no image to save ({}x{})", path.display(), w, h);
    }
    let mut rgb = Vec::with_capacity(w * h * 3);
    for p in image.data[..w * h * 3].chunks_exact(3) {
        rgb.extend_from_slice(&[p[2], p[1], p[0]]);
    }
    let file = std::fs::File::create(path).with_context(|| format!("save {}", path.display()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w as u32, h as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut wr = enc
        .write_header()
        .with_context(|| format!("save {}", path.display()))?;
    wr.write_image_data(&rgb)
        .with_context(|| format!("save {}", path.display()))?;
    wr.finish()
        .with_context(|| format!("save {}", path.display()))?;
    Ok(())
}

crate::declare_lines! {
    /// image_viewer's lines, declared once (`jderobot help image_viewer`).
    struct Lines {
        images: Option<Vec<String>> = Setting::new(
            "images",
            "up to 8 image interfaces to show (colorA..D, varcolorA..D); default: every image \
             interface the run provides when the schema is loaded",
            &[rest("INTERFACE")],
        ),
        cycle: u64 = CYCLE
            .default("100")
            .help("the period between statistics updates"),
        save_dir: Option<PathBuf> = Setting::new(
            "save_dir",
            "where the panel's Save button writes NAME-CLOCK.png (default: the current directory)",
            &[path("DIRECTORY")],
        ),
    }
}
fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let l: Lines = conf.read()?;
    let images = match l.images {
        Some(names) if names.len() > 8 => {
            return Err(imagesource::error_at(
                conf,
                "images",
                format!("at most 8 interfaces, got {}", names.len()),
            ));
        }
        Some(names) => names
            .iter()
            .map(|n| imagesource::image(conf, &rt.interfaces, "images", n))
            .collect::<anyhow::Result<Vec<_>>>()?,
        None => rt
            .interfaces
            .names_of::<Image>()
            .iter()
            .map(|n| rt.interfaces.get::<Image>(n))
            .collect::<Result<Vec<_>, _>>()?,
    };
    let save_dir = l.save_dir.unwrap_or_else(|| PathBuf::from("."));
    let views = Arc::new(Mutex::new(Vec::new()));
    rt.names
        .export_arc(&conf.name, "views", views.clone())
        .map_err(anyhow::Error::msg)?;
    let _ = &save_dir;
    Ok(Box::new(ImageViewer {
        meters: images
            .iter()
            .map(|_| Meter {
                from: None,
                fps: 0.0,
            })
            .collect(),
        #[cfg(feature = "gui")]
        panel: Some(Box::new(panel::ViewerPanel::new(
            images.clone(),
            views.clone(),
            save_dir,
        ))),
        images,
        views,
        cycle: Duration::from_millis(l.cycle),
    }))
}

crate::register_schema!(
    "image_viewer",
    "every image interface side by side: size, fps, clock, age, pixel BGR/HSV, save PNG",
    create,
    lines = Lines
);

#[cfg(feature = "gui")]
pub mod panel {
    //! image_viewer's panel.
    use super::*;
    use crate::{
        colorspaces::rgb2hsv,
        widgets::{ImageView, PixelPick},
    };

    /// One image per column; under each its statistics, the picked pixel, Save.
    pub struct ViewerPanel {
        images: Vec<Arc<Interface<Image>>>,
        views: Vec<ImageView>,
        stats: Arc<Mutex<Vec<ViewStats>>>,
        save_dir: PathBuf,
        picks: Vec<Option<PixelPick>>,
        /// The last save's outcome, shown under the views.
        pub message: Option<String>,
    }

    impl ViewerPanel {
        pub fn new(
            images: Vec<Arc<Interface<Image>>>,
            stats: Arc<Mutex<Vec<ViewStats>>>,
            save_dir: PathBuf,
        ) -> Self {
            ViewerPanel {
                views: images
                    .iter()
                    .map(|i| ImageView::new(format!("image_viewer {}", i.name())))
                    .collect(),
                picks: vec![None; images.len()],
                images,
                stats,
                save_dir,
                message: None,
            }
        }
    }

    /// The text of a picked pixel: position, BGR and HSV (H in degrees and radians).
    pub fn pick_text(p: &PixelPick) -> String {
        let [b, g, r] = p.bgr;
        let hsv = rgb2hsv(r, g, b);
        format!(
            "({}, {}) B {b} G {g} R {r}  H {:.1}° ({:.3} rad) S {:.3} V {:.0}",
            p.x,
            p.y,
            hsv.h,
            hsv.h.to_radians(),
            hsv.s,
            hsv.v
        )
    }

    impl crate::runtime::Panel for ViewerPanel {
        fn ui(&mut self, ui: &mut egui::Ui, _rt: &Runtime) {
            if self.images.is_empty() {
                ui.label(
                    "no image interface (load a driver that provides colorA..D or varcolorA..D)",
                );
                return;
            }
            let stats = self.stats.lock().clone();
            let width = (ui.available_width() / self.images.len() as f32 - 8.0).max(160.0);
            egui::ScrollArea::horizontal().show(ui, |ui| {
                ui.horizontal_top(|ui| {
                    for (k, iface) in self.images.iter().enumerate() {
                        ui.vertical(|ui| {
                            ui.set_max_width(width);
                            let s = iface.snapshot();
                            let st = stats.get(k);
                            let fps = st.map(|s| s.fps).unwrap_or(0.0);
                            ui.strong(iface.name());
                            ui.label(format!(
                                "{}x{}  {:.1} fps  clock {}  age {}",
                                s.value.width,
                                s.value.height,
                                fps,
                                s.clock,
                                if s.clock > 0 {
                                    format!("{:.0} ms", s.stamp.elapsed().as_secs_f32() * 1e3)
                                } else {
                                    "-".into()
                                }
                            ));
                            if let Some(why) = iface.stale() {
                                ui.colored_label(egui::Color32::YELLOW, format!("stale: {why}"));
                            }
                            let r = self.views[k].show_sample(ui, &s);
                            if let Some(p) = r.pick {
                                self.picks[k] = Some(p);
                            }
                            if let Some(p) = &self.picks[k] {
                                ui.label(pick_text(p));
                            }
                            if ui
                                .button(format!("Save {}", iface.name()))
                                .on_hover_text("write the frame shown to NAME-CLOCK.png")
                                .clicked()
                            {
                                let path =
                                    self.save_dir
                                        .join(format!("{}-{}.png", iface.name(), s.clock));
                                self.message = Some(match save_png(&s.value, &path) {
                                    Ok(()) => format!("saved {}", path.display()),
                                    Err(e) => format!("{e:#}"),
                                });
                            }
                        });
                    }
                });
            });
            if let Some(m) = &self.message {
                ui.label(m);
            }
        }
    }
}
