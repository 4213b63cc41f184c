//! The 2D world view: pose, walls, laser points, target; pan, zoom, click.

use egui::{Color32, Pos2, Rect, Response, Sense, Stroke, Ui, Vec2, pos2, vec2};

use super::*;
use crate::interfaces::{Encoders, Laser};

/// World (mm, x right, y up) ↔ screen transform of a [`WorldView`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldTransform {
    pub rect: Rect,
    /// World point at the centre of `rect`, mm.
    pub center: [f32; 2],
    /// Millimetres per screen point.
    pub mm_per_px: f32,
}

impl WorldTransform {
    /// A transform showing `width_mm` across `rect`, centred on `center`.
    pub fn new(rect: Rect, center: [f32; 2], width_mm: f32) -> Self {
        WorldTransform {
            rect,
            center,
            mm_per_px: width_mm / rect.width().max(1.0),
        }
    }
    pub fn to_screen(&self, p: [f32; 2]) -> Pos2 {
        let c = self.rect.center();
        pos2(
            c.x + (p[0] - self.center[0]) / self.mm_per_px,
            c.y - (p[1] - self.center[1]) / self.mm_per_px,
        )
    }
    pub fn to_world(&self, p: Pos2) -> [f32; 2] {
        let c = self.rect.center();
        [
            self.center[0] + (p.x - c.x) * self.mm_per_px,
            self.center[1] - (p.y - c.y) * self.mm_per_px,
        ]
    }
}

/// A robot-relative point (x ahead, y left, mm) in world coordinates (the seed's
/// `relativas2absolutas`).
pub fn relative_to_world(pose: &Encoders, rel: [f32; 2]) -> [f32; 2] {
    let (c, s) = (pose.theta.cos(), pose.theta.sin());
    [
        rel[0] * c - rel[1] * s + pose.x,
        rel[1] * c + rel[0] * s + pose.y,
    ]
}

/// A world point in robot-relative coordinates (the seed's `absolutas2relativas`).
pub fn world_to_relative(pose: &Encoders, p: [f32; 2]) -> [f32; 2] {
    let (c, s) = (pose.theta.cos(), pose.theta.sin());
    let (dx, dy) = (p[0] - pose.x, p[1] - pose.y);
    [dx * c + dy * s, dy * c - dx * s]
}

/// Laser hits in world coordinates (mm) for a robot at `pose`, from where the
/// laser is mounted.
pub fn laser_to_world(pose: &Encoders, laser: &Laser) -> Vec<[f32; 2]> {
    (0..laser.readings.len())
        .map(|i| relative_to_world(pose, laser.robot_point(i)))
        .collect()
}

/// What a [`WorldView`] draws this frame.
#[derive(Default)]
pub struct WorldScene<'a> {
    /// The robot's pose.
    pub robot: Option<Encoders>,
    /// Walls: segments `[x1, y1, x2, y2]` in mm.
    pub walls: &'a [[f32; 4]],
    /// Laser readings, drawn as points around the robot.
    pub laser: Option<&'a Laser>,
    /// Extra segments in world mm with their colours (a student's drawings).
    pub segments: &'a [([f32; 4], Color32)],
    /// Robot radius in mm (default 225, a Pioneer).
    pub robot_radius: Option<f32>,
    /// Balls: centre (mm), radius (mm) and colour, drawn as filled discs.
    pub balls: &'a [([f32; 2], f32, Color32)],
}

/// A 2D world view: drag pans, scroll zooms, click sets the target.
pub struct WorldView {
    label: String,
    /// World point at the centre of the view, mm.
    pub center: [f32; 2],
    /// Width of the view in mm (500..=20000, initially 4000 as in introrob).
    pub width_mm: f32,
    /// The clicked target, world mm.
    pub target: Option<[f32; 2]>,
    /// Grid spacing, mm (1 m).
    pub grid_mm: f32,
    last: Option<WorldTransform>,
}

/// What [`WorldView::show`] gives back.
pub struct WorldResponse {
    pub response: Response,
    /// A target clicked this frame (world mm).
    pub clicked: Option<[f32; 2]>,
    pub transform: WorldTransform,
}

/// The view's width limits in mm.
pub const WORLD_WIDTH_RANGE: (f32, f32) = (500.0, 20000.0);

/// Zooms a view about a fixed screen point: returns the new (center, width) so that
/// the world point under `anchor` stays under it. `factor` > 1 zooms in.
pub fn zoom_about(t: &WorldTransform, anchor: Pos2, factor: f32) -> ([f32; 2], f32) {
    let width = (t.mm_per_px * t.rect.width() / factor.max(1e-3))
        .clamp(WORLD_WIDTH_RANGE.0, WORLD_WIDTH_RANGE.1);
    let w = t.to_world(anchor);
    let mm_per_px = width / t.rect.width().max(1.0);
    let c = t.rect.center();
    let center = [
        w[0] - (anchor.x - c.x) * mm_per_px,
        w[1] + (anchor.y - c.y) * mm_per_px,
    ];
    (center, width)
}

impl WorldView {
    pub fn new(label: impl Into<String>) -> Self {
        WorldView {
            label: label.into(),
            center: [0.0, 0.0],
            width_mm: 4000.0,
            target: None,
            grid_mm: 1000.0,
            last: None,
        }
    }

    /// The transform used in the last frame.
    pub fn transform(&self) -> Option<WorldTransform> {
        self.last
    }

    /// Draws the scene in a `size` area (fills the available width if `size.x` is 0).
    pub fn show(&mut self, ui: &mut Ui, size: Vec2, scene: &WorldScene<'_>) -> WorldResponse {
        let size = if size.x <= 0.0 {
            vec2(ui.available_width(), size.y.max(100.0))
        } else {
            size
        };
        let (rect, response) = ui.allocate_exact_size(size, Sense::click_and_drag());
        label_response(&response, &self.label);
        // Interaction.
        if response.dragged_by(egui::PointerButton::Primary)
            || response.dragged_by(egui::PointerButton::Middle)
        {
            let d = response.drag_delta();
            let k = self.width_mm / rect.width().max(1.0);
            self.center[0] -= d.x * k;
            self.center[1] += d.y * k;
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0
                && let Some(p) = response.hover_pos()
            {
                let t = WorldTransform::new(rect, self.center, self.width_mm);
                let (c, w) = zoom_about(&t, p, (scroll / 200.0).exp());
                self.center = c;
                self.width_mm = w;
            }
        }
        self.width_mm = self
            .width_mm
            .clamp(WORLD_WIDTH_RANGE.0, WORLD_WIDTH_RANGE.1);
        let t = WorldTransform::new(rect, self.center, self.width_mm);
        let mut clicked = None;
        if (response.clicked() || response.middle_clicked())
            && let Some(p) = response.interact_pointer_pos()
        {
            let w = t.to_world(p);
            self.target = Some(w);
            clicked = Some(w);
        }
        if response.secondary_clicked()
            && let Some(r) = scene.robot
        {
            self.center = [r.x, r.y];
        }
        self.draw(ui, &t, scene);
        self.last = Some(t);
        WorldResponse {
            response,
            clicked,
            transform: t,
        }
    }

    fn draw(&self, ui: &Ui, t: &WorldTransform, scene: &WorldScene<'_>) {
        let painter = ui.painter_at(t.rect);
        painter.rect_filled(t.rect, 0.0, Color32::from_gray(245));
        // Grid.
        let g = self.grid_mm.max(10.0);
        let lo = t.to_world(t.rect.left_bottom());
        let hi = t.to_world(t.rect.right_top());
        let grid = Stroke::new(1.0, Color32::from_gray(215));
        if (hi[0] - lo[0]) / g < 400.0 && (hi[1] - lo[1]) / g < 400.0 {
            let mut x = (lo[0] / g).floor() * g;
            while x <= hi[0] {
                let a = t.to_screen([x, lo[1]]);
                let b = t.to_screen([x, hi[1]]);
                painter.line_segment([a, b], grid);
                x += g;
            }
            let mut y = (lo[1] / g).floor() * g;
            while y <= hi[1] {
                let a = t.to_screen([lo[0], y]);
                let b = t.to_screen([hi[0], y]);
                painter.line_segment([a, b], grid);
                y += g;
            }
        }
        let axes = Stroke::new(1.0, Color32::from_gray(160));
        painter.line_segment([t.to_screen([lo[0], 0.0]), t.to_screen([hi[0], 0.0])], axes);
        painter.line_segment([t.to_screen([0.0, lo[1]]), t.to_screen([0.0, hi[1]])], axes);
        // Walls.
        let wall = Stroke::new(2.0, Color32::from_rgb(40, 40, 40));
        for w in scene.walls {
            painter.line_segment([t.to_screen([w[0], w[1]]), t.to_screen([w[2], w[3]])], wall);
        }
        for (s, c) in scene.segments {
            painter.line_segment(
                [t.to_screen([s[0], s[1]]), t.to_screen([s[2], s[3]])],
                Stroke::new(1.5, *c),
            );
        }
        for (c, r, colour) in scene.balls {
            let p = t.to_screen(*c);
            let radius = (r / t.mm_per_px).max(2.0);
            painter.circle_filled(p, radius, *colour);
            painter.circle_stroke(p, radius, Stroke::new(1.0, Color32::from_gray(60)));
        }
        if let Some(pose) = scene.robot {
            if let Some(laser) = scene.laser {
                for p in laser_to_world(&pose, laser) {
                    painter.circle_filled(t.to_screen(p), 1.5, Color32::from_rgb(30, 90, 220));
                }
            }
            let r = scene.robot_radius.unwrap_or(225.0);
            let c = t.to_screen([pose.x, pose.y]);
            painter.circle_stroke(
                c,
                (r / t.mm_per_px).max(3.0),
                Stroke::new(2.0, Color32::from_rgb(200, 40, 40)),
            );
            let nose = t.to_screen(relative_to_world(&pose, [r * 1.4, 0.0]));
            painter.line_segment([c, nose], Stroke::new(2.0, Color32::from_rgb(200, 40, 40)));
        }
        if let Some(tg) = self.target {
            let p = t.to_screen(tg);
            let s = Stroke::new(2.0, Color32::from_rgb(0, 150, 0));
            painter.line_segment([pos2(p.x - 6.0, p.y - 6.0), pos2(p.x + 6.0, p.y + 6.0)], s);
            painter.line_segment([pos2(p.x - 6.0, p.y + 6.0), pos2(p.x + 6.0, p.y - 6.0)], s);
        }
        painter.text(
            t.rect.left_top() + vec2(4.0, 2.0),
            egui::Align2::LEFT_TOP,
            format!(
                "{:.1} m wide, grid {:.1} m",
                self.width_mm / 1000.0,
                g / 1000.0
            ),
            egui::FontId::proportional(11.0),
            Color32::from_gray(90),
        );
    }
}
