//! The pan/tilt positioner.

use egui::{Color32, Response, Sense, Stroke, Ui, Vec2, pos2, vec2};

use super::*;
use crate::interfaces::PtMotors;

/// Limits of a pan/tilt unit, degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PanTiltLimits {
    pub min_longitude: f32,
    pub max_longitude: f32,
    pub min_latitude: f32,
    pub max_latitude: f32,
}

impl From<&PtMotors> for PanTiltLimits {
    fn from(m: &PtMotors) -> Self {
        PanTiltLimits {
            min_longitude: m.min_longitude,
            max_longitude: m.max_longitude,
            min_latitude: m.min_latitude,
            max_latitude: m.max_latitude,
        }
    }
}

/// Maps a pad position (`norm` in [-1, 1], x right, y down) to (longitude, latitude)
/// in degrees: left edge = max longitude (pan left is positive), top = max latitude.
pub fn pad_to_pantilt(norm: Vec2, l: &PanTiltLimits) -> (f32, f32) {
    let Vec2 { x, y } = clamp_unit(norm);
    let lerp = |lo: f32, hi: f32, t: f32| lo + (hi - lo) * t;
    (
        lerp(l.max_longitude, l.min_longitude, (x + 1.0) / 2.0),
        lerp(l.max_latitude, l.min_latitude, (y + 1.0) / 2.0),
    )
}

/// The inverse of [`pad_to_pantilt`].
pub fn pantilt_to_pad(longitude: f32, latitude: f32, l: &PanTiltLimits) -> Vec2 {
    let inv = |lo: f32, hi: f32, v: f32| {
        if hi == lo {
            0.0
        } else {
            ((v - hi) / (lo - hi) * 2.0 - 1.0).clamp(-1.0, 1.0)
        }
    };
    vec2(
        inv(l.min_longitude, l.max_longitude, longitude),
        inv(l.min_latitude, l.max_latitude, latitude),
    )
}

/// A pan/tilt positioner: a pad plus longitude and latitude sliders; the position
/// stays where it is put.
pub struct PanTiltPad {
    label: String,
    pub limits: PanTiltLimits,
    /// Commanded longitude (pan), deg.
    pub longitude: f32,
    /// Commanded latitude (tilt), deg.
    pub latitude: f32,
}

impl PanTiltPad {
    pub fn new(label: impl Into<String>, limits: PanTiltLimits) -> Self {
        PanTiltPad {
            label: label.into(),
            limits,
            longitude: 0.0,
            latitude: 0.0,
        }
    }

    /// Draws the pad (`size`) and sliders; `actual` (pan, tilt deg from the encoders)
    /// is drawn as a hollow marker. The response is `changed()` when the command changed.
    pub fn show(&mut self, ui: &mut Ui, size: Vec2, actual: Option<(f32, f32)>) -> Response {
        let before = (self.longitude, self.latitude);
        let (rect, mut response) = ui.allocate_exact_size(size, Sense::click_and_drag());
        label_response(&response, &self.label);
        if response.is_pointer_button_down_on()
            && let Some(p) = response.interact_pointer_pos()
        {
            let (lon, lat) = pad_to_pantilt(normalized_offset(rect, p), &self.limits);
            self.longitude = lon;
            self.latitude = lat;
        }
        let l = self.limits;
        ui.add(
            egui::Slider::new(&mut self.longitude, l.min_longitude..=l.max_longitude)
                .text("longitude (deg)"),
        );
        ui.add(
            egui::Slider::new(&mut self.latitude, l.min_latitude..=l.max_latitude)
                .text("latitude (deg)"),
        );
        if before != (self.longitude, self.latitude) {
            response.mark_changed();
        }
        let painter = ui.painter_at(rect);
        painter.rect_filled(rect, 4.0, Color32::from_gray(35));
        let to_screen = |n: Vec2| {
            pos2(
                rect.center().x + n.x * rect.width() * 0.5,
                rect.center().y + n.y * rect.height() * 0.5,
            )
        };
        let zero = to_screen(pantilt_to_pad(0.0, 0.0, &l));
        let axis = Stroke::new(1.0, Color32::from_gray(90));
        painter.line_segment(
            [pos2(rect.left(), zero.y), pos2(rect.right(), zero.y)],
            axis,
        );
        painter.line_segment(
            [pos2(zero.x, rect.top()), pos2(zero.x, rect.bottom())],
            axis,
        );
        if let Some((pan, tilt)) = actual {
            painter.circle_stroke(
                to_screen(pantilt_to_pad(pan, tilt, &l)),
                7.0,
                Stroke::new(2.0, Color32::from_rgb(90, 200, 90)),
            );
        }
        painter.circle_filled(
            to_screen(pantilt_to_pad(self.longitude, self.latitude, &l)),
            5.0,
            Color32::from_rgb(240, 160, 40),
        );
        response
    }
}

// ---------------------------------------------------------------------------
// 3D wireframe canvas
