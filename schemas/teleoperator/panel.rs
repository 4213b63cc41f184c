//! The teleoperator's panel: the 3D canvas, the base joystick and stop, the
//! pan-tilt positioner and the camera image.

use std::sync::Arc;

use egui::{Color32, vec2};

use crate::{
    interfaces::{Encoders, Laser},
    operator::controls::{self, Controls},
    runtime::{Panel, Runtime},
    widgets::{ImageView, OrbitCamera, Segment3D, Wireframe3D, laser_to_world, relative_to_world},
    world::{Ball, LiveBalls, World},
};

use super::Devices;
use crate::operator::Commands;

/// Robot radius and body height in the 3D view, mm.
const RADIUS: f64 = 250.0;
const HEIGHT: f64 = 400.0;
/// Laser and camera heights, mm.
const LASER_Z: f64 = 300.0;
const CAMERA_Z: f64 = 500.0;

/// The world's walls and boxes as 3D wireframe edges (bottom, top and ends).
pub fn world_segments(world: &World) -> Vec<Segment3D> {
    let mut out = Vec::new();
    for s in &world.segments {
        let [r, g, b] = s.color;
        let c = Color32::from_rgb(r, g, b);
        let (a, e, h) = (s.a, s.b, s.height);
        out.push(([a[0], a[1], 0.0], [e[0], e[1], 0.0], c));
        out.push(([a[0], a[1], h], [e[0], e[1], h], c));
        out.push(([a[0], a[1], 0.0], [a[0], a[1], h], c));
        out.push(([e[0], e[1], 0.0], [e[0], e[1], h], c));
    }
    out
}

/// The robot (a cylinder with a nose), its laser points and its camera's
/// viewing direction (pan, tilt in degrees).
pub fn robot_segments(
    pose: &Encoders,
    laser: Option<&Laser>,
    pantilt: Option<(f32, f32)>,
) -> Vec<Segment3D> {
    let mut out = Vec::new();
    let body = Color32::from_rgb(220, 60, 50);
    let (x, y, th) = (pose.x as f64, pose.y as f64, pose.theta as f64);
    let ring = |k: usize| {
        let a = k as f64 * std::f64::consts::TAU / 16.0;
        [x + RADIUS * a.cos(), y + RADIUS * a.sin()]
    };
    for k in 0..16 {
        let (p, q) = (ring(k), ring(k + 1));
        out.push(([p[0], p[1], 0.0], [q[0], q[1], 0.0], body));
        out.push(([p[0], p[1], HEIGHT], [q[0], q[1], HEIGHT], body));
        if k % 4 == 0 {
            out.push(([p[0], p[1], 0.0], [p[0], p[1], HEIGHT], body));
        }
    }
    let nose = [x + 1.4 * RADIUS * th.cos(), y + 1.4 * RADIUS * th.sin()];
    out.push(([x, y, HEIGHT], [nose[0], nose[1], HEIGHT], body));
    if let Some(l) = laser {
        let c = Color32::from_rgb(80, 160, 255);
        for p in laser_to_world(pose, l) {
            let (px, py) = (p[0] as f64, p[1] as f64);
            out.push(([px - 30.0, py, LASER_Z], [px + 30.0, py, LASER_Z], c));
            out.push(([px, py - 30.0, LASER_Z], [px, py + 30.0, LASER_Z], c));
        }
    }
    if let Some((pan, tilt)) = pantilt {
        let cam = relative_to_world(pose, [190.0, 0.0]);
        let (a, t) = (th + (pan as f64).to_radians(), (tilt as f64).to_radians());
        let l = 1000.0;
        let (cx, cy) = (cam[0] as f64, cam[1] as f64);
        out.push((
            [cx, cy, CAMERA_Z],
            [
                cx + l * t.cos() * a.cos(),
                cy + l * t.cos() * a.sin(),
                CAMERA_Z + l * t.sin(),
            ],
            Color32::from_rgb(240, 200, 40),
        ));
    }
    out
}

/// Balls as wireframe spheres: the equator and two meridians, 16 edges each.
pub fn ball_segments(balls: &[Ball]) -> Vec<Segment3D> {
    let mut out = Vec::new();
    for b in balls {
        let [r, g, bl] = b.color;
        let c = Color32::from_rgb(r, g, bl);
        let (x, y, rad) = (b.pos[0], b.pos[1], b.radius);
        let circle = |k: usize, plane: usize| {
            let a = k as f64 * std::f64::consts::TAU / 16.0;
            let (u, v) = (rad * a.cos(), rad * a.sin());
            match plane {
                0 => [x + u, y + v, rad],
                1 => [x + u, y, rad + v],
                _ => [x, y + u, rad + v],
            }
        };
        for plane in 0..3 {
            for k in 0..16 {
                out.push((circle(k, plane), circle(k + 1, plane), c));
            }
        }
    }
    out
}

/// The panel.
pub struct TeleoperatorPanel {
    dev: Devices,
    walls: Vec<Segment3D>,
    /// The balls (`world.balls`), drawn as spheres.
    balls: Option<Arc<LiveBalls>>,
    canvas: Wireframe3D,
    controls: Controls,
    image: ImageView,
    follow: bool,
    show_laser: bool,
}

impl TeleoperatorPanel {
    pub fn new(
        commands: Arc<Commands>,
        dev: Devices,
        world: Option<Arc<World>>,
        balls: Option<Arc<LiveBalls>>,
    ) -> Self {
        let walls = world.as_deref().map(world_segments).unwrap_or_default();
        let orbit = OrbitCamera {
            distance: 9000.0,
            elevation_deg: 40.0,
            ..OrbitCamera::default()
        };
        let labels = ("teleoperator joystick", "teleoperator pantilt");
        let controls = Controls::new(commands, labels, dev.pantilt_motors.as_deref());
        TeleoperatorPanel {
            dev,
            walls,
            balls,
            canvas: Wireframe3D::new("teleoperator 3d", orbit),
            controls,
            image: ImageView::new("teleoperator camera"),
            follow: true,
            show_laser: true,
        }
    }
}

impl Panel for TeleoperatorPanel {
    fn title(&self) -> Option<String> {
        Some("teleoperator".into())
    }

    fn ui(&mut self, ui: &mut egui::Ui, _rt: &Runtime) {
        let pose = self.dev.encoders.as_ref().map(|e| e.read().value);
        let laser = self.dev.laser.as_ref().map(|l| l.snapshot());
        let pt = self
            .dev
            .pantilt_encoders
            .as_ref()
            .map(|p| p.read().value)
            .map(|p| (p.pan_angle, p.tilt_angle));
        let mut segs = self.walls.clone();
        if let Some(balls) = &self.balls {
            segs.extend(ball_segments(&balls.load()));
        }
        if let Some(p) = &pose {
            if self.follow {
                self.canvas.orbit.target = [p.x as f64, p.y as f64, 0.0];
            }
            let l = laser.as_ref().filter(|_| self.show_laser).map(|s| &s.value);
            segs.extend(robot_segments(p, l, pt));
        }
        ui.horizontal(|ui| {
            ui.checkbox(&mut self.follow, "follow the robot");
            ui.checkbox(&mut self.show_laser, "laser");
            self.controls.speeds_and_stop(ui, "", &self.dev.motors);
        });
        ui.horizontal_top(|ui| {
            ui.vertical(|ui| {
                self.canvas.show(ui, vec2(480.0, 340.0), &segs);
                ui.small("drag: orbit · wheel: zoom");
            });
            ui.vertical(|ui| self.controls.show(ui, ("base", "pan-tilt"), pt));
            if let Some(c) = &self.dev.camera {
                ui.vertical(|ui| {
                    ui.label("camera");
                    controls::camera(ui, &mut self.image, c, vec2(240.0, 180.0));
                });
            }
        });
    }
}
