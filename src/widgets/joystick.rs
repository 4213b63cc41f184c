//! The v/w joystick.

use egui::{Color32, Pos2, Rect, Response, Sense, Stroke, Ui, Vec2, pos2, vec2};

use super::*;

/// `norm` with each coordinate limited to [-1, 1]; a non-finite one (a degenerate
/// pad size) counts as 0, so a bad frame never sends a wild command.
pub(crate) fn clamp_unit(norm: Vec2) -> Vec2 {
    let c = |t: f32| {
        if t.is_finite() {
            t.clamp(-1.0, 1.0)
        } else {
            0.0
        }
    };
    Vec2::new(c(norm.x), c(norm.y))
}

/// Maps a joystick offset to (v mm/s, w deg/s): `norm` is the offset from the pad's
/// centre in units of its half size (x right, y down), clamped to [-1, 1]. Up is
/// forward (+v), left is a counter-clockwise turn (+w).
pub fn joystick_to_vw(norm: Vec2, max_v: f32, max_w: f32) -> (f32, f32) {
    let Vec2 { x, y } = clamp_unit(norm);
    (-y * max_v, -x * max_w)
}

/// The inverse of [`joystick_to_vw`]: where the knob is drawn for (v, w).
pub fn vw_to_joystick(v: f32, w: f32, max_v: f32, max_w: f32) -> Vec2 {
    let nx = if max_w != 0.0 { -w / max_w } else { 0.0 };
    let ny = if max_v != 0.0 { -v / max_v } else { 0.0 };
    vec2(nx.clamp(-1.0, 1.0), ny.clamp(-1.0, 1.0))
}

/// Offset of `pos` from the centre of `rect` in units of its half size.
pub fn normalized_offset(rect: Rect, pos: Pos2) -> Vec2 {
    let c = rect.center();
    let h = rect.size() * 0.5;
    vec2((pos.x - c.x) / h.x.max(1.0), (pos.y - c.y) / h.y.max(1.0))
}

/// A v/w joystick: drag gives v (mm/s) and w (deg/s) within the maxima; release → 0.
pub struct Joystick {
    label: String,
    pub max_v: f32,
    pub max_w: f32,
    /// Current command, mm/s.
    pub v: f32,
    /// Current command, deg/s.
    pub w: f32,
}

impl Joystick {
    /// introrob's maxima are 500 mm/s and 30 deg/s.
    pub fn new(label: impl Into<String>, max_v: f32, max_w: f32) -> Self {
        Joystick {
            label: label.into(),
            max_v,
            max_w,
            v: 0.0,
            w: 0.0,
        }
    }

    /// Draws the pad (`side` points square); the response is `changed()` when v or w changed.
    pub fn show(&mut self, ui: &mut Ui, side: f32) -> Response {
        let (rect, mut response) = ui.allocate_exact_size(vec2(side, side), Sense::drag());
        label_response(&response, &self.label);
        let before = (self.v, self.w);
        if response.is_pointer_button_down_on()
            && let Some(p) = response.interact_pointer_pos()
        {
            let (v, w) = joystick_to_vw(normalized_offset(rect, p), self.max_v, self.max_w);
            self.v = v;
            self.w = w;
        } else {
            // Released (or never pressed): stop.
            self.v = 0.0;
            self.w = 0.0;
        }
        if before != (self.v, self.w) {
            response.mark_changed();
        }
        let painter = ui.painter_at(rect);
        painter.rect_filled(rect, 6.0, Color32::from_gray(40));
        let c = rect.center();
        let axis = Stroke::new(1.0, Color32::from_gray(90));
        painter.line_segment([pos2(rect.left(), c.y), pos2(rect.right(), c.y)], axis);
        painter.line_segment([pos2(c.x, rect.top()), pos2(c.x, rect.bottom())], axis);
        let n = vw_to_joystick(self.v, self.w, self.max_v, self.max_w);
        let knob = pos2(
            c.x + n.x * rect.width() * 0.5,
            c.y + n.y * rect.height() * 0.5,
        );
        painter.line_segment([c, knob], Stroke::new(2.0, Color32::from_gray(150)));
        painter.circle_filled(knob, 8.0, Color32::from_rgb(240, 160, 40));
        painter.text(
            rect.left_bottom() + vec2(4.0, -2.0),
            egui::Align2::LEFT_BOTTOM,
            format!("v {:.0} mm/s  w {:.1} deg/s", self.v, self.w),
            egui::FontId::proportional(11.0),
            Color32::from_gray(220),
        );
        response
    }
}
