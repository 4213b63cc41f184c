//! The python schema's panel, the Academy's editor page in the one window: the
//! program's text highlighted with its line numbers (the failing line marked),
//! Play / Stop / Reload, the real loop frequency (the runtime's iterations per
//! second, or `Frequency.tick`'s measured rate in the Academy 5 shape), the
//! console and the image the program shows with `GUI.showImage`. It shares state with the schema only through
//! [`Shared`] (short locks), so drawing never waits on a running program.

use std::sync::{Arc, atomic::Ordering};

use super::{Shared, highlight};
use crate::{
    runtime::{Panel, Runtime, State},
    widgets::ImageView,
};

/// The panel.
pub struct PythonPanel {
    shared: Arc<Shared>,
    view: ImageView,
    /// The console's line count when last drawn (scroll to the end on growth).
    seen: u64,
}

impl PythonPanel {
    pub fn new(shared: Arc<Shared>) -> Self {
        let view = ImageView::new(format!("{} GUI.showImage", shared.name));
        PythonPanel {
            shared,
            view,
            seen: 0,
        }
    }
}

impl Panel for PythonPanel {
    fn title(&self) -> Option<String> {
        Some(format!("{} (Python)", self.shared.name))
    }

    fn ui(&mut self, ui: &mut egui::Ui, rt: &Runtime) {
        let name = self.shared.name.clone();
        let status = rt.schema_status(&name);
        let running = status.as_ref().is_some_and(|s| s.state != State::Slept);
        let file = self.shared.file.lock().display().to_string();
        ui.horizontal(|ui| {
            if ui
                .add_enabled(!running, egui::Button::new("Play"))
                .clicked()
            {
                let _ = rt.run(&name);
            }
            if ui.add_enabled(running, egui::Button::new("Stop")).clicked() {
                let _ = rt.stop(&name);
            }
            if ui.button("Reload").clicked() {
                if running {
                    self.shared.reload.store(true, Ordering::Release);
                } else if let Ok(text) = std::fs::read_to_string(&file) {
                    *self.shared.source.lock() = Arc::new(text);
                    *self.shared.error.lock() = None;
                    self.shared.clear_console();
                }
            }
            let phase = *self.shared.phase.lock();
            match &status {
                // The Academy 5 shape paces its own loop with Frequency.tick.
                Some(s) if running && self.shared.academy5.load(Ordering::Acquire) => {
                    ui.label(format!(
                        "{} · {:.1} Hz (Frequency.tick) · {phase}",
                        s.state,
                        self.shared.tick_rate()
                    ));
                }
                Some(s) if running => {
                    ui.label(format!(
                        "{} · {:.1} Hz (cycle {} ms) · {phase}",
                        s.state,
                        s.timing.ips,
                        s.cycle.as_millis()
                    ));
                }
                _ => {
                    ui.label("stopped");
                }
            }
        });
        ui.label(egui::RichText::new(crate::files::shorten(&file)).weak());
        let error = self.shared.error.lock().clone();
        if let Some((_, msg)) = &error {
            ui.colored_label(egui::Color32::from_rgb(240, 90, 90), msg);
        }
        let error_line = error.as_ref().map_or(0, |e| e.0);
        let source = self.shared.source.lock().clone();
        let font = egui::TextStyle::Monospace.resolve(ui.style());
        let avail = ui.available_height();
        egui::ScrollArea::both()
            .id_salt("program")
            .max_height((avail * 0.5).max(120.0))
            .show(ui, |ui| {
                ui.horizontal_top(|ui| {
                    let n = source.lines().count().max(1);
                    let numbers: String = (1..=n).map(|i| format!("{i:>3}\n")).collect();
                    ui.label(
                        egui::RichText::new(numbers.trim_end())
                            .font(font.clone())
                            .color(egui::Color32::GRAY),
                    );
                    let job = highlight::layout(&source, error_line, font.clone());
                    ui.label(job);
                });
            });
        ui.separator();
        ui.label("Console");
        let (lines, total) = {
            let c = self.shared.console.lock();
            (c.lines.iter().cloned().collect::<Vec<_>>(), c.total)
        };
        let grew = total != self.seen;
        self.seen = total;
        egui::ScrollArea::vertical()
            .id_salt("console")
            .max_height(140.0)
            .stick_to_bottom(true)
            .show(ui, |ui| {
                let text = lines.join("\n");
                ui.label(egui::RichText::new(text).font(font.clone()));
                if grew {
                    ui.scroll_to_cursor(Some(egui::Align::BOTTOM));
                }
            });
        if let Some(score) = crate::world::score(&rt.names) {
            ui.separator();
            ui.label(format!("Score: {}", score.load().summary()));
        }
        let overlay = **self.shared.drawings().load();
        if overlay.forces.is_some() || overlay.local_target.is_some() {
            ui.separator();
            ui.label("Forces (robot's frame: ahead up, left to the left)");
            draw_forces(ui, &overlay);
        }
        let image = self.shared.image.lock().clone();
        if let Some(img) = image {
            ui.separator();
            let clock = self.shared.images.load(Ordering::Acquire);
            self.view.show(ui, &img, clock);
        }
    }
}

/// The obstacle-avoidance exercise's drawing: the robot at the centre heading
/// up, the car (attraction, green), obstacle (repulsion, red) and average
/// (white) forces as arrows, the local target as a blue dot; scaled so the
/// longest fits.
fn draw_forces(ui: &mut egui::Ui, o: &crate::world::Drawings) {
    let size = egui::vec2(180.0, 180.0);
    let (rect, _) = ui.allocate_exact_size(size, egui::Sense::hover());
    let p = ui.painter_at(rect);
    p.rect_filled(rect, 4.0, egui::Color32::from_gray(30));
    let c = rect.center();
    let mut longest: f64 = 1e-9;
    for v in o.forces.iter().flatten().chain(o.local_target.iter()) {
        longest = longest.max(v[0].hypot(v[1]));
    }
    let scale = (size.x as f64 * 0.42) / longest;
    // Robot frame (x ahead, y left) to the screen (ahead up, left left).
    let at = |v: [f64; 2]| c + egui::vec2((-v[1] * scale) as f32, (-v[0] * scale) as f32);
    p.circle_stroke(c, 6.0, egui::Stroke::new(1.5, egui::Color32::GRAY));
    if let Some([car, obstacle, average]) = o.forces {
        for (v, color) in [
            (car, egui::Color32::from_rgb(80, 200, 80)),
            (obstacle, egui::Color32::from_rgb(230, 70, 70)),
            (average, egui::Color32::WHITE),
        ] {
            p.arrow(c, at(v) - c, egui::Stroke::new(2.0, color));
        }
    }
    if let Some(t) = o.local_target {
        p.circle_filled(at(t), 4.0, egui::Color32::from_rgb(80, 140, 250));
    }
}
