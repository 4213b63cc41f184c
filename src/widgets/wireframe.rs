//! 3D segments through a progeo camera orbiting a target.

use egui::{Color32, Pos2, Response, Sense, Stroke, Ui, Vec2, pos2, vec2};

use super::*;
use crate::progeo::{HPoint3D, PinholeCamera, focal_from_fov};

/// A virtual camera orbiting a target point (z up), as in 4.3's extrinsics and
/// opengl viewers: drag orbits, scroll zooms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrbitCamera {
    /// The point looked at (the camera's focus of attention), mm.
    pub target: [f64; 3],
    /// Distance from the target, mm.
    pub distance: f64,
    /// Angle around the z axis from +x, degrees.
    pub azimuth_deg: f64,
    /// Angle above the xy plane, degrees (kept within ±89 so "up" is defined).
    pub elevation_deg: f64,
    /// Vertical field of view, degrees.
    pub fov_deg: f64,
}

impl Default for OrbitCamera {
    fn default() -> Self {
        OrbitCamera {
            target: [0.0, 0.0, 0.0],
            distance: 8000.0,
            azimuth_deg: -60.0,
            elevation_deg: 30.0,
            fov_deg: 60.0,
        }
    }
}

/// The orbit's distance limits, mm.
pub const ORBIT_DISTANCE_RANGE: (f64, f64) = (100.0, 1.0e6);

impl OrbitCamera {
    /// The camera position, mm.
    pub fn position(&self) -> [f64; 3] {
        let (az, el) = (
            self.azimuth_deg.to_radians(),
            self.elevation_deg.clamp(-89.0, 89.0).to_radians(),
        );
        let d = self.distance;
        [
            self.target[0] + d * el.cos() * az.cos(),
            self.target[1] + d * el.cos() * az.sin(),
            self.target[2] + d * el.sin(),
        ]
    }

    /// The orbit after a drag of `delta` screen points (0.5 deg per point): dragging
    /// right turns the camera clockwise around the target, dragging down raises it.
    pub fn dragged(&self, delta: Vec2) -> OrbitCamera {
        let mut o = *self;
        o.azimuth_deg = (o.azimuth_deg - delta.x as f64 * 0.5).rem_euclid(360.0);
        o.elevation_deg = (o.elevation_deg + delta.y as f64 * 0.5).clamp(-89.0, 89.0);
        o
    }

    /// The orbit after scrolling `scroll` points (positive = closer).
    pub fn zoomed(&self, scroll: f32) -> OrbitCamera {
        let mut o = *self;
        o.distance = (o.distance * (-(scroll as f64) / 200.0).exp())
            .clamp(ORBIT_DISTANCE_RANGE.0, ORBIT_DISTANCE_RANGE.1);
        o
    }

    /// The progeo pinhole camera of this orbit for a `columns` x `rows` image.
    pub fn camera(&self, columns: u32, rows: u32) -> PinholeCamera {
        let [x, y, z] = self.position();
        let [tx, ty, tz] = self.target;
        let rows = rows.max(2);
        let f = focal_from_fov(rows as f64, self.fov_deg.clamp(1.0, 170.0).to_radians());
        PinholeCamera::new(
            HPoint3D::point(x, y, z),
            HPoint3D::point(tx, ty, tz),
            f,
            columns.max(2),
            rows,
        )
    }
}

/// The visible part of 3D segment `a`–`b` (mm) in graphic pixel coordinates
/// (column, row from the top-left) of `cam`'s image, or `None`.
pub fn project_segment(cam: &PinholeCamera, a: [f64; 3], b: [f64; 3]) -> Option<(Pos2, Pos2)> {
    let p1 = cam.project(HPoint3D::point(a[0], a[1], a[2]));
    let p2 = cam.project(HPoint3D::point(b[0], b[1], b[2]));
    let (q1, q2) = cam.displayline(p1, p2)?;
    let (c1, r1) = cam.optical_to_graphic(q1);
    let (c2, r2) = cam.optical_to_graphic(q2);
    let ok = |v: f64| v.is_finite();
    (ok(c1) && ok(r1) && ok(c2) && ok(r2))
        .then(|| (pos2(c1 as f32, r1 as f32), pos2(c2 as f32, r2 as f32)))
}

/// A 3D segment (mm) with its colour.
pub type Segment3D = ([f64; 3], [f64; 3], Color32);

/// A wireframe canvas: segments seen through a progeo camera orbiting a target.
pub struct Wireframe3D {
    label: String,
    pub orbit: OrbitCamera,
    /// Draw x (red), y (green), z (blue) axes of this length (mm) at the origin; 0 = none.
    pub axes_mm: f64,
}

impl Wireframe3D {
    pub fn new(label: impl Into<String>, orbit: OrbitCamera) -> Self {
        Wireframe3D {
            label: label.into(),
            orbit,
            axes_mm: 1000.0,
        }
    }

    /// Draws `segments` in a `size` area (fills the available width if `size.x` is 0).
    pub fn show(&mut self, ui: &mut Ui, size: Vec2, segments: &[Segment3D]) -> Response {
        let size = if size.x <= 0.0 {
            vec2(ui.available_width(), size.y.max(100.0))
        } else {
            size
        };
        let (rect, response) = ui.allocate_exact_size(size, Sense::drag());
        label_response(&response, &self.label);
        if response.dragged() {
            self.orbit = self.orbit.dragged(response.drag_delta());
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                self.orbit = self.orbit.zoomed(scroll);
            }
        }
        let painter = ui.painter_at(rect);
        painter.rect_filled(rect, 0.0, Color32::from_gray(15));
        let cam = self
            .orbit
            .camera(rect.width().round() as u32, rect.height().round() as u32);
        let draw = |a: [f64; 3], b: [f64; 3], c: Color32| {
            if let Some((p, q)) = project_segment(&cam, a, b) {
                painter.line_segment(
                    [rect.min + p.to_vec2(), rect.min + q.to_vec2()],
                    Stroke::new(1.0, c),
                );
            }
        };
        if self.axes_mm > 0.0 {
            let l = self.axes_mm;
            draw([0.0; 3], [l, 0.0, 0.0], Color32::RED);
            draw([0.0; 3], [0.0, l, 0.0], Color32::GREEN);
            draw([0.0; 3], [0.0, 0.0, l], Color32::from_rgb(80, 120, 255));
        }
        for &(a, b, c) in segments {
            draw(a, b, c);
        }
        response
    }
}
