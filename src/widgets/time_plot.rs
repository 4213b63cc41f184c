//! Scalars plotted against time (egui_plot).

use std::collections::VecDeque;
use std::time::Instant;

use egui::{Response, Ui};

use super::*;

/// Scalars plotted against time over a sliding window (egui_plot).
#[derive(Clone)]
pub struct TimePlot {
    label: String,
    start: Instant,
    /// The window shown, seconds.
    pub window_s: f64,
    series: Vec<(String, VecDeque<[f64; 2]>)>,
}

impl TimePlot {
    pub fn new(label: impl Into<String>, window_s: f64) -> Self {
        TimePlot {
            label: label.into(),
            start: Instant::now(),
            window_s: window_s.max(0.1),
            series: Vec::new(),
        }
    }

    /// Adds `value` to series `name` now.
    pub fn push(&mut self, name: &str, value: f64) {
        let t = self.start.elapsed().as_secs_f64();
        self.push_at(name, t, value);
    }

    /// Adds `value` to series `name` at `t` seconds; drops points older than the window.
    pub fn push_at(&mut self, name: &str, t: f64, value: f64) {
        let i = match self.series.iter().position(|(n, _)| n == name) {
            Some(i) => i,
            None => {
                self.series.push((name.to_string(), VecDeque::new()));
                self.series.len() - 1
            }
        };
        let s = &mut self.series[i].1;
        s.push_back([t, value]);
        while s.front().is_some_and(|p| p[0] < t - self.window_s) {
            s.pop_front();
        }
    }

    /// Whether no point was pushed yet.
    pub fn is_empty(&self) -> bool {
        self.series.iter().all(|(_, s)| s.is_empty())
    }

    /// The points of series `name`.
    pub fn points(&self, name: &str) -> Vec<[f64; 2]> {
        self.series
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, s)| s.iter().copied().collect())
            .unwrap_or_default()
    }

    pub fn show(&self, ui: &mut Ui, height: f32) -> Response {
        let r = egui_plot::Plot::new(&self.label)
            .height(height)
            .legend(egui_plot::Legend::default())
            .x_axis_label("s")
            .allow_drag(false)
            .show(ui, |p| {
                for (name, s) in &self.series {
                    let pts: Vec<[f64; 2]> = s.iter().copied().collect();
                    p.line(egui_plot::Line::new(name.clone(), pts));
                }
            })
            .response;
        label_response(&r, &self.label);
        r
    }
}
