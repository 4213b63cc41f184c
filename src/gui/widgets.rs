//! Widgets for schema panels: the views robotics users expect.
//!
//! | widget | shows | interaction |
//! |---|---|---|
//! | [`ImageView`] | a BGR [`Image`] of any size, scaled to fit | click → [`PixelPick`] (pixel coordinates and colour) |
//! | [`polar_view`] | laser or sonar ranges around the robot | none |
//! | [`WorldView`] | robot pose, walls, laser points, a target, a 1 m grid | drag pans, scroll zooms, click sets the target (world mm), right click recentres on the robot |
//! | [`TimePlot`] | scalars against time (egui_plot) | egui_plot's zoom and pan |
//! | [`Joystick`] | a v/w pad | drag gives v (mm/s) and w (deg/s) within the maxima; release → 0 |
//! | [`PanTiltPad`] | a pan/tilt positioner with sliders | drag or slide sets longitude/latitude (deg) within limits |
//! | [`Wireframe3D`] | 3D segments (mm) seen through a [`progeo`](crate::progeo) camera | drag orbits, scroll zooms |
//!
//! Each widget's mathematics lives in small pure functions (pixel picking, joystick
//! mapping, world↔screen transforms, orbit camera) so it can be tested without a
//! window. Every custom widget gives its response an accessibility label (its
//! `label`), so tests can find it by name.

use std::collections::VecDeque;
use std::time::Instant;

use egui::{
    Color32, ColorImage, Pos2, Rect, Response, Sense, Stroke, TextureHandle, TextureOptions, Ui,
    Vec2, WidgetInfo, pos2, vec2,
};

use crate::interfaces::{Encoders, Image, Laser, PtMotors, Sample, Sonars};
use crate::progeo::{HPoint3D, PinholeCamera, focal_from_fov};

/// Gives a custom widget's response an accessibility label (so tests find it).
fn label_response(response: &Response, label: &str) {
    let label = label.to_string();
    response.widget_info(move || WidgetInfo::labeled(egui::Role::Canvas, true, label.clone()));
}

// ---------------------------------------------------------------------------
// Image view

/// The largest size with the image's aspect ratio that fits in `avail` (never
/// larger than `max_scale` times the image). A zero-sized image gives zero.
pub fn fit_size(width: u32, height: u32, avail: Vec2, max_scale: f32) -> Vec2 {
    let positive = |v: f32| v > 0.0; // false for NaN
    if width == 0 || height == 0 || !positive(avail.x) || !positive(avail.y) {
        return Vec2::ZERO;
    }
    let (w, h) = (width as f32, height as f32);
    let scale = (avail.x / w)
        .min(avail.y / h)
        .min(max_scale.max(f32::MIN_POSITIVE));
    vec2(w * scale, h * scale)
}

/// The pixel (column, row) of a `width`×`height` image drawn in `rect` under screen
/// point `pos`, or `None` outside the image.
pub fn pick_pixel(rect: Rect, width: u32, height: u32, pos: Pos2) -> Option<(u32, u32)> {
    if width == 0 || height == 0 || rect.width() <= 0.0 || rect.height() <= 0.0 {
        return None;
    }
    let u = (pos.x - rect.min.x) / rect.width();
    let v = (pos.y - rect.min.y) / rect.height();
    if !(0.0..1.0).contains(&u) || !(0.0..1.0).contains(&v) {
        return None;
    }
    let x = ((u * width as f32) as u32).min(width - 1);
    let y = ((v * height as f32) as u32).min(height - 1);
    Some((x, y))
}

/// The screen rectangle of pixel (x, y) of a `width`×`height` image drawn in `rect`.
pub fn pixel_rect(rect: Rect, width: u32, height: u32, x: u32, y: u32) -> Rect {
    let sx = rect.width() / width.max(1) as f32;
    let sy = rect.height() / height.max(1) as f32;
    Rect::from_min_size(
        pos2(rect.min.x + x as f32 * sx, rect.min.y + y as f32 * sy),
        vec2(sx, sy),
    )
}

/// Converts a BGR image to an egui image (opaque). Short or malformed data gives
/// black pixels rather than a panic.
pub fn bgr_to_color_image(image: &Image) -> ColorImage {
    let (w, h) = (image.width as usize, image.height as usize);
    let mut pixels = Vec::with_capacity(w * h);
    for i in 0..w * h {
        let p = image.data.get(i * 3..i * 3 + 3);
        pixels.push(match p {
            Some(&[b, g, r]) => Color32::from_rgb(r, g, b),
            _ => Color32::BLACK,
        });
    }
    ColorImage::new([w, h], pixels)
}

/// A clicked pixel: column `x`, row `y` (from the top-left) and its colour.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelPick {
    pub x: u32,
    pub y: u32,
    /// Blue, green, red, as stored in the image.
    pub bgr: [u8; 3],
}

/// Shows BGR images scaled to fit; keeps one texture and uploads a new image only
/// when its clock changes.
pub struct ImageView {
    label: String,
    texture: Option<TextureHandle>,
    clock: Option<u64>,
    size: (u32, u32),
    /// The largest zoom factor (default 4).
    pub max_scale: f32,
    /// The last clicked pixel, drawn as a marker.
    pub last_pick: Option<PixelPick>,
    uploads: u64,
}

/// What [`ImageView::show`] gives back.
pub struct ImageResponse {
    pub response: Response,
    /// The pixel clicked this frame.
    pub pick: Option<PixelPick>,
    /// Where the image was drawn.
    pub rect: Rect,
}

impl ImageView {
    /// `label` names the view (its texture and accessibility label).
    pub fn new(label: impl Into<String>) -> Self {
        ImageView {
            label: label.into(),
            texture: None,
            clock: None,
            size: (0, 0),
            max_scale: 4.0,
            last_pick: None,
            uploads: 0,
        }
    }

    /// How many times an image was uploaded to the GPU (one per new clock).
    pub fn uploads(&self) -> u64 {
        self.uploads
    }

    /// Shows an interface sample (uploads only when its clock changed).
    pub fn show_sample(&mut self, ui: &mut Ui, sample: &Sample<Image>) -> ImageResponse {
        self.show(ui, &sample.value, sample.clock)
    }

    /// Shows `image`, whose version is `clock`: the texture is updated only when the
    /// clock or the size changes. Fits the available width (and height, if bounded).
    pub fn show(&mut self, ui: &mut Ui, image: &Image, clock: u64) -> ImageResponse {
        let size = (image.width, image.height);
        if self.clock != Some(clock) || self.size != size || self.texture.is_none() {
            let ci = bgr_to_color_image(image);
            match &mut self.texture {
                Some(t) => t.set(ci, TextureOptions::NEAREST),
                None => {
                    self.texture = Some(ui.ctx().load_texture(
                        format!("imageview:{}", self.label),
                        ci,
                        TextureOptions::NEAREST,
                    ))
                }
            }
            self.clock = Some(clock);
            self.size = size;
            self.uploads += 1;
        }
        let mut avail = ui.available_size();
        if !avail.y.is_finite() || avail.y <= 1.0 {
            avail.y = avail.x;
        }
        let mut want = fit_size(image.width, image.height, avail, self.max_scale);
        if want == Vec2::ZERO {
            want = vec2(avail.x.clamp(16.0, 320.0), 16.0);
        }
        let (rect, response) = ui.allocate_exact_size(want, Sense::click());
        label_response(&response, &self.label);
        let painter = ui.painter_at(rect);
        match &self.texture {
            Some(t) if image.width > 0 && image.height > 0 => {
                painter.image(
                    t.id(),
                    rect,
                    Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0)),
                    Color32::WHITE,
                );
            }
            _ => {
                painter.rect_filled(rect, 0.0, Color32::DARK_GRAY);
                painter.text(
                    rect.center(),
                    egui::Align2::CENTER_CENTER,
                    "no image",
                    egui::FontId::proportional(12.0),
                    Color32::LIGHT_GRAY,
                );
            }
        }
        let mut pick = None;
        if response.clicked()
            && let Some(pos) = response.interact_pointer_pos()
            && let Some((x, y)) = pick_pixel(rect, image.width, image.height, pos)
        {
            let i = (y as usize * image.width as usize + x as usize) * 3;
            let bgr = match image.data.get(i..i + 3) {
                Some(&[b, g, r]) => [b, g, r],
                _ => [0, 0, 0],
            };
            pick = Some(PixelPick { x, y, bgr });
            self.last_pick = pick;
        }
        if let Some(p) = self.last_pick
            && p.x < image.width
            && p.y < image.height
        {
            let r = pixel_rect(rect, image.width, image.height, p.x, p.y);
            let c = r.center();
            let s = Stroke::new(1.5, Color32::YELLOW);
            painter.line_segment([pos2(c.x - 6.0, c.y), pos2(c.x + 6.0, c.y)], s);
            painter.line_segment([pos2(c.x, c.y - 6.0), pos2(c.x, c.y + 6.0)], s);
        }
        ImageResponse {
            response,
            pick,
            rect,
        }
    }
}

// ---------------------------------------------------------------------------
// Polar view (laser, sonars)

/// Screen point of a range reading: `angle_deg` counter-clockwise from straight
/// ahead (0 = up on screen, +90 = left), `range_mm` from `center`.
pub fn polar_to_screen(center: Pos2, px_per_mm: f32, angle_deg: f32, range_mm: f32) -> Pos2 {
    let a = angle_deg.to_radians();
    pos2(
        center.x - range_mm * a.sin() * px_per_mm,
        center.y - range_mm * a.cos() * px_per_mm,
    )
}

/// Laser readings as (angle from straight ahead in degrees, range mm): reading i is
/// at −90 + i/resolution degrees.
pub fn laser_points(laser: &Laser) -> Vec<(f32, f32)> {
    let res = if laser.resolution > 0.0 {
        laser.resolution
    } else {
        1.0
    };
    laser
        .readings
        .iter()
        .enumerate()
        .map(|(i, &r)| (-90.0 + i as f32 / res, r as f32))
        .collect()
}

/// Angles (deg from straight ahead, counter-clockwise) of a Pioneer's sonar ring:
/// 8 front sonars from left to right, then 8 rear ones from right to left. Other
/// counts are spread evenly around the robot.
pub fn sonar_angles(n: usize) -> Vec<f32> {
    const PIONEER: [f32; 16] = [
        90.0, 50.0, 30.0, 10.0, -10.0, -30.0, -50.0, -90.0, -90.0, -130.0, -150.0, -170.0, 170.0,
        150.0, 130.0, 90.0,
    ];
    if (8..=16).contains(&n) {
        PIONEER[..n].to_vec()
    } else {
        (0..n).map(|i| i as f32 * 360.0 / n.max(1) as f32).collect()
    }
}

/// Sonar readings as (angle deg, range mm).
pub fn sonar_points(sonars: &Sonars) -> Vec<(f32, f32)> {
    sonar_angles(sonars.us.len())
        .into_iter()
        .zip(sonars.us.iter().copied())
        .collect()
}

/// How to draw a polar view's readings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PolarStyle {
    /// A closed outline with rays (laser).
    Laser,
    /// A 15° wedge per reading (sonars).
    Sonar,
}

/// Draws range readings `(angle deg, range mm)` around a robot at the centre (ahead
/// is up), with range rings every metre up to `max_range_mm`.
pub fn polar_view(
    ui: &mut Ui,
    label: &str,
    size: Vec2,
    points: &[(f32, f32)],
    max_range_mm: f32,
    style: PolarStyle,
) -> Response {
    let (rect, response) = ui.allocate_exact_size(size, Sense::hover());
    label_response(&response, label);
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 2.0, Color32::from_gray(20));
    let max_range = if max_range_mm > 0.0 {
        max_range_mm
    } else {
        8000.0
    };
    let radius = rect.width().min(rect.height()) * 0.5 - 4.0;
    let center = rect.center();
    let k = radius.max(1.0) / max_range;
    let ring = Stroke::new(1.0, Color32::from_gray(60));
    let mut m = 1000.0;
    while m <= max_range {
        painter.circle_stroke(center, m * k, ring);
        m += 1000.0;
    }
    let clamp = |r: f32| r.clamp(0.0, max_range);
    match style {
        PolarStyle::Laser => {
            let pts: Vec<Pos2> = points
                .iter()
                .map(|&(a, r)| polar_to_screen(center, k, a, clamp(r)))
                .collect();
            let ray = Stroke::new(1.0, Color32::from_rgb(60, 60, 120));
            for p in &pts {
                painter.line_segment([center, *p], ray);
            }
            if pts.len() > 1 {
                painter.line(pts, Stroke::new(1.5, Color32::from_rgb(80, 160, 255)));
            }
        }
        PolarStyle::Sonar => {
            for &(a, r) in points {
                let r = clamp(r);
                let arc: Vec<Pos2> = (0..=6)
                    .map(|j| polar_to_screen(center, k, a - 7.5 + j as f32 * 2.5, r))
                    .collect();
                let mut wedge = vec![center];
                wedge.extend(arc.iter().copied());
                wedge.push(center);
                painter.line(wedge, Stroke::new(1.0, Color32::from_rgb(90, 200, 90)));
            }
        }
    }
    // The robot, pointing up.
    let s = 6.0;
    painter.add(egui::Shape::convex_polygon(
        vec![
            pos2(center.x, center.y - s * 1.5),
            pos2(center.x - s, center.y + s),
            pos2(center.x + s, center.y + s),
        ],
        Color32::from_rgb(230, 80, 60),
        Stroke::NONE,
    ));
    response
}

// ---------------------------------------------------------------------------
// World view

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

/// Laser hits in world coordinates (mm) for a robot at `pose`.
pub fn laser_to_world(pose: &Encoders, laser: &Laser) -> Vec<[f32; 2]> {
    laser_points(laser)
        .into_iter()
        .map(|(a, r)| {
            let a = a.to_radians();
            relative_to_world(pose, [r * a.cos(), r * a.sin()])
        })
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

// ---------------------------------------------------------------------------
// Time plot

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

// ---------------------------------------------------------------------------
// Joystick

/// `norm` with each coordinate limited to [-1, 1]; a non-finite one (a degenerate
/// pad size) counts as 0, so a bad frame never sends a wild command.
fn clamp_unit(norm: Vec2) -> Vec2 {
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

// ---------------------------------------------------------------------------
// Pan/tilt positioner

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

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f32, b: f32, eps: f32) -> bool {
        (a - b).abs() <= eps
    }

    #[test]
    fn fit_keeps_aspect_and_limits_zoom() {
        assert_eq!(
            fit_size(320, 240, vec2(640.0, 1000.0), 4.0),
            vec2(640.0, 480.0)
        );
        assert_eq!(
            fit_size(320, 240, vec2(1000.0, 240.0), 4.0),
            vec2(320.0, 240.0)
        );
        assert_eq!(fit_size(4, 2, vec2(1000.0, 1000.0), 4.0), vec2(16.0, 8.0));
        assert_eq!(fit_size(0, 240, vec2(100.0, 100.0), 4.0), Vec2::ZERO);
    }

    #[test]
    fn pick_maps_screen_to_pixels() {
        let r = Rect::from_min_size(pos2(10.0, 20.0), vec2(640.0, 480.0));
        assert_eq!(pick_pixel(r, 320, 240, pos2(10.0, 20.0)), Some((0, 0)));
        assert_eq!(
            pick_pixel(r, 320, 240, pos2(649.9, 499.9)),
            Some((319, 239))
        );
        assert_eq!(pick_pixel(r, 320, 240, pos2(12.5, 23.9)), Some((1, 1)));
        assert_eq!(pick_pixel(r, 320, 240, pos2(650.0, 30.0)), None);
        assert_eq!(pick_pixel(r, 320, 240, pos2(9.0, 30.0)), None);
        let p = pixel_rect(r, 320, 240, 7, 9);
        assert_eq!(pick_pixel(r, 320, 240, p.center()), Some((7, 9)));
    }

    #[test]
    fn bgr_becomes_rgb_and_bad_data_is_black() {
        let img = Image {
            width: 2,
            height: 1,
            data: vec![1, 2, 3, 4, 5, 6],
        };
        let c = bgr_to_color_image(&img);
        assert_eq!(
            c.pixels,
            vec![Color32::from_rgb(3, 2, 1), Color32::from_rgb(6, 5, 4)]
        );
        let short = Image {
            width: 2,
            height: 1,
            data: vec![1, 2, 3],
        };
        assert_eq!(bgr_to_color_image(&short).pixels[1], Color32::BLACK);
    }

    #[test]
    fn polar_ahead_is_up_and_left_is_left() {
        let c = pos2(100.0, 100.0);
        let up = polar_to_screen(c, 0.01, 0.0, 1000.0);
        assert!(close(up.x, 100.0, 1e-3) && close(up.y, 90.0, 1e-3));
        let left = polar_to_screen(c, 0.01, 90.0, 1000.0);
        assert!(close(left.x, 90.0, 1e-3) && close(left.y, 100.0, 1e-3));
        let laser = Laser {
            readings: vec![1000; 361],
            resolution: 2.0,
        };
        let pts = laser_points(&laser);
        assert_eq!(pts[0].0, -90.0);
        assert_eq!(pts[180].0, 0.0);
        assert_eq!(pts[360].0, 90.0);
        assert_eq!(sonar_angles(16)[0], 90.0);
        assert_eq!(sonar_angles(4), vec![0.0, 90.0, 180.0, 270.0]);
    }

    #[test]
    fn world_transform_round_trips_and_y_is_up() {
        let r = Rect::from_min_size(pos2(0.0, 0.0), vec2(400.0, 300.0));
        let t = WorldTransform::new(r, [1000.0, -500.0], 4000.0);
        assert_eq!(t.mm_per_px, 10.0);
        assert_eq!(t.to_screen([1000.0, -500.0]), r.center());
        let p = t.to_screen([2000.0, 0.0]);
        assert_eq!(p, pos2(300.0, 100.0));
        let w = t.to_world(pos2(37.0, 211.0));
        let back = t.to_screen(w);
        assert!(close(back.x, 37.0, 1e-3) && close(back.y, 211.0, 1e-3));
    }

    #[test]
    fn zoom_keeps_the_point_under_the_cursor() {
        let r = Rect::from_min_size(pos2(0.0, 0.0), vec2(400.0, 300.0));
        let t = WorldTransform::new(r, [0.0, 0.0], 4000.0);
        let anchor = pos2(300.0, 50.0);
        let before = t.to_world(anchor);
        let (c, w) = zoom_about(&t, anchor, 2.0);
        assert_eq!(w, 2000.0);
        let after = WorldTransform::new(r, c, w).to_world(anchor);
        assert!(close(before[0], after[0], 1e-2) && close(before[1], after[1], 1e-2));
        // Limits.
        assert_eq!(zoom_about(&t, anchor, 1000.0).1, WORLD_WIDTH_RANGE.0);
        assert_eq!(zoom_about(&t, anchor, 0.0001).1, WORLD_WIDTH_RANGE.1);
    }

    #[test]
    fn relative_and_absolute_coordinates_are_inverse() {
        let pose = Encoders::from_pose(1000.0, 2000.0, std::f32::consts::FRAC_PI_2);
        // 1 m ahead of a robot facing +y is at (1000, 3000).
        let w = relative_to_world(&pose, [1000.0, 0.0]);
        assert!(close(w[0], 1000.0, 1e-2) && close(w[1], 3000.0, 1e-2));
        let r = world_to_relative(&pose, [500.0, 2500.0]);
        let w2 = relative_to_world(&pose, r);
        assert!(close(w2[0], 500.0, 1e-2) && close(w2[1], 2500.0, 1e-2));
        // The laser reading straight ahead lands ahead of the robot.
        let laser = Laser {
            readings: vec![800; 181],
            resolution: 1.0,
        };
        let hits = laser_to_world(&pose, &laser);
        assert!(close(hits[90][0], 1000.0, 1e-2) && close(hits[90][1], 2800.0, 1e-2));
        // Reading 0 is on the robot's right: facing +y, right is +x.
        assert!(close(hits[0][0], 1800.0, 1e-2) && close(hits[0][1], 2000.0, 1e-2));
    }

    #[test]
    fn joystick_maps_offsets_to_v_and_w() {
        assert_eq!(joystick_to_vw(vec2(0.0, 0.0), 500.0, 30.0), (-0.0, -0.0));
        assert_eq!(joystick_to_vw(vec2(0.0, -1.0), 500.0, 30.0), (500.0, -0.0));
        assert_eq!(joystick_to_vw(vec2(-1.0, 0.5), 500.0, 30.0), (-250.0, 30.0));
        assert_eq!(joystick_to_vw(vec2(3.0, -9.0), 500.0, 30.0), (500.0, -30.0));
        assert_eq!(joystick_to_vw(vec2(f32::NAN, 0.0), 500.0, 30.0).1, -0.0);
        let n = vw_to_joystick(250.0, -15.0, 500.0, 30.0);
        assert_eq!(joystick_to_vw(n, 500.0, 30.0), (250.0, -15.0));
        let r = Rect::from_min_size(pos2(0.0, 0.0), vec2(200.0, 100.0));
        assert_eq!(normalized_offset(r, pos2(200.0, 0.0)), vec2(1.0, -1.0));
    }

    #[test]
    fn pantilt_pad_maps_to_limits_and_back() {
        let l = PanTiltLimits::from(&PtMotors::default());
        let (lon, lat) = pad_to_pantilt(vec2(-1.0, -1.0), &l);
        assert_eq!((lon, lat), (l.max_longitude, l.max_latitude));
        let (lon, lat) = pad_to_pantilt(vec2(1.0, 1.0), &l);
        assert_eq!((lon, lat), (l.min_longitude, l.min_latitude));
        let n = pantilt_to_pad(10.0, -20.0, &l);
        let (lon, lat) = pad_to_pantilt(n, &l);
        assert!(close(lon, 10.0, 1e-3) && close(lat, -20.0, 1e-3));
    }

    #[test]
    fn time_plot_keeps_its_window() {
        let mut p = TimePlot::new("t", 10.0);
        assert!(p.is_empty());
        for i in 0..30 {
            p.push_at("a", i as f64, i as f64);
        }
        let pts = p.points("a");
        assert_eq!(pts.first(), Some(&[19.0, 19.0]));
        assert_eq!(pts.len(), 11);
        assert!(p.points("b").is_empty());
    }

    #[test]
    fn orbit_camera_sees_its_target_at_the_image_centre() {
        let o = OrbitCamera {
            target: [1000.0, 2000.0, 500.0],
            ..Default::default()
        };
        let p = o.position();
        let d = ((p[0] - 1000.0).powi(2) + (p[1] - 2000.0).powi(2) + (p[2] - 500.0).powi(2)).sqrt();
        assert!((d - o.distance).abs() < 1e-6);
        let cam = o.camera(400, 300);
        let seg = project_segment(&cam, [1000.0, 2000.0, 500.0], [1000.0, 2000.0, 600.0])
            .expect("visible");
        assert!(
            close(seg.0.x, 200.0, 1.5) && close(seg.0.y, 150.0, 1.5),
            "{seg:?}"
        );
        // "Up" in the world is up on the screen.
        assert!(seg.1.y < seg.0.y, "{seg:?}");
        // A segment behind the camera is not drawn.
        let behind = [
            p[0] + (p[0] - 1000.0),
            p[1] + (p[1] - 2000.0),
            p[2] + (p[2] - 500.0),
        ];
        assert!(project_segment(&cam, behind, [behind[0] + 1.0, behind[1], behind[2]]).is_none());
        // Orbiting and zooming stay within limits.
        let o2 = o.dragged(vec2(20.0, 1000.0)).zoomed(1.0e6);
        assert_eq!(o2.elevation_deg, 89.0);
        assert_eq!(o2.distance, ORBIT_DISTANCE_RANGE.0);
        assert!(close(
            o2.azimuth_deg as f32,
            (o.azimuth_deg - 10.0).rem_euclid(360.0) as f32,
            1e-4
        ));
    }
}
