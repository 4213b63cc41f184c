//! opencvdemo's panel: the filter buttons, their parameters, the view and the ms.

use std::sync::Arc;

use super::{Demo, Filter};
use crate::{runtime::Runtime, widgets::ImageView};

pub struct DemoPanel {
    state: Arc<Demo>,
    view: ImageView,
}

impl DemoPanel {
    pub fn new(state: Arc<Demo>) -> Self {
        DemoPanel {
            state,
            view: ImageView::new("opencvdemo image"),
        }
    }
}

impl crate::runtime::Panel for DemoPanel {
    fn ui(&mut self, ui: &mut egui::Ui, _rt: &Runtime) {
        let view = self.state.view.lock().clone();
        let mut filter = *self.state.filter.lock();
        let mut p = self.state.params.lock().clone();
        let before = p.clone();
        let times = self.state.times.lock().clone();
        ui.horizontal(|ui| {
            self.state.source.picker(ui, "opencvdemo source");
            let (done, dropped) = *self.state.frames.lock();
            ui.label(format!("{done} frames, {dropped} dropped"));
        });
        ui.horizontal_top(|ui| {
            ui.vertical(|ui| {
                ui.set_max_width(200.0);
                for f in Filter::ALL {
                    let t = times
                        .get(&f)
                        .map(|ms| format!("{ms:.2} ms"))
                        .unwrap_or_default();
                    ui.horizontal(|ui| {
                        ui.radio_value(&mut filter, f, f.name());
                        ui.weak(t);
                    });
                }
                ui.separator();
                match filter {
                    Filter::Canny | Filter::HoughStandard | Filter::HoughProbabilistic => {
                        ui.add(egui::Slider::new(&mut p.canny, 1.0..=300.0).text("canny"));
                    }
                    _ => {}
                }
                match filter {
                    Filter::HoughStandard => {
                        ui.add(egui::Slider::new(&mut p.hough_votes, 10..=400).text("votes"));
                    }
                    Filter::HoughProbabilistic => {
                        ui.add(egui::Slider::new(&mut p.houghp.0, 10..=400).text("votes"));
                        ui.add(egui::Slider::new(&mut p.houghp.1, 0..=300).text("min length"));
                        ui.add(egui::Slider::new(&mut p.houghp.2, 0..=50).text("max gap"));
                    }
                    Filter::Convolution => {
                        let k = &p.kernel;
                        ui.label(format!(
                            "kernel {}x{} (/{}, offset {})",
                            k.size, k.size, k.modulo, k.offset
                        ));
                    }
                    _ => {}
                }
            });
            ui.vertical(|ui| {
                ui.label(match view.filter {
                    Some(f) => format!("{}: {:.2} ms", f.name(), view.ms),
                    None => "waiting for an image".into(),
                });
                self.view.show(ui, &view.image, view.clock);
            });
        });
        *self.state.filter.lock() = filter;
        if p != before {
            *self.state.params.lock() = p;
        }
    }
}
