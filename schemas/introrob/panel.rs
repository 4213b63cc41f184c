//! introrob's panel: behaviour choice, teleoperation joystick and stop, the robot
//! in its world (walls, floor paint, targets, laser points, path, forces, your
//! drawings, the exercise's score; a click sets the target), laser and sonar views and the camera image.

use std::sync::Arc;

use egui::{Color32, vec2};

use crate::{
    interfaces::{Encoders, Image, Interface, Laser, Sonars},
    runtime::{Panel, Runtime},
    widgets::{
        ImageView, Joystick, PolarStyle, WorldScene, WorldView, laser_points, polar_view,
        relative_to_world, sonar_points,
    },
    world::{LiveBalls, LiveScore, World},
};

use super::{Behaviour, Dashboard};

/// The panel; it shares the [`Dashboard`] with the brain and reads the interfaces.
pub struct IntrorobPanel {
    dashboard: Arc<Dashboard>,
    encoders: Arc<Interface<Encoders>>,
    laser: Arc<Interface<Laser>>,
    sonars: Option<Arc<Interface<Sonars>>>,
    camera: Option<Arc<Interface<Image>>>,
    walls: Vec<[f32; 4]>,
    /// The map's floor paint and targets, as coloured segments.
    marks: Vec<([f32; 4], Color32)>,
    /// The exercise's score (`world.score`), said under the world view.
    score: Option<Arc<LiveScore>>,
    /// The balls (`world.balls`), drawn in the world view.
    balls: Option<Arc<LiveBalls>>,
    world: WorldView,
    joystick: Joystick,
    image: ImageView,
    placed: bool,
}

impl IntrorobPanel {
    pub fn new(
        dashboard: Arc<Dashboard>,
        encoders: Arc<Interface<Encoders>>,
        laser: Arc<Interface<Laser>>,
        sonars: Option<Arc<Interface<Sonars>>>,
        camera: Option<Arc<Interface<Image>>>,
        balls: Option<Arc<LiveBalls>>,
        score: Option<Arc<LiveScore>>,
    ) -> IntrorobPanel {
        let walls = dashboard
            .world
            .as_ref()
            .map(|w| {
                w.segments
                    .iter()
                    .map(|s| [s.a[0] as f32, s.a[1] as f32, s.b[0] as f32, s.b[1] as f32])
                    .collect()
            })
            .unwrap_or_default();
        let mut world = WorldView::new("introrob world");
        if let Some((lo, hi)) = dashboard.world.as_ref().and_then(|w| w.bounds()) {
            world.center = [
                ((lo[0] + hi[0]) / 2.0) as f32,
                ((lo[1] + hi[1]) / 2.0) as f32,
            ];
            world.width_mm =
                ((hi[0] - lo[0]).max((hi[1] - lo[1]) * 1.4) as f32 + 1000.0).clamp(500.0, 20000.0);
        }
        let joystick = Joystick::new("introrob joystick", dashboard.max_v, dashboard.max_w);
        let marks = dashboard.world.as_deref().map(marks).unwrap_or_default();
        IntrorobPanel {
            dashboard,
            encoders,
            laser,
            sonars,
            camera,
            walls,
            marks,
            score,
            balls,
            world,
            joystick,
            image: ImageView::new("introrob camera"),
            placed: false,
        }
    }

    fn controls(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            ui.label("behaviour:");
            let mut b = *self.dashboard.behaviour.lock();
            let before = b;
            for x in Behaviour::ALL {
                ui.selectable_value(&mut b, x, x.as_str());
            }
            if b != before {
                self.dashboard.set_behaviour(b);
            }
            if ui.button("STOP").clicked() {
                self.dashboard.set_teleop(0.0, 0.0);
                self.dashboard.set_behaviour(Behaviour::Stop);
            }
        });
        let view = self.dashboard.view.lock().clone();
        ui.label(format!(
            "{}   |   v {:.0} mm/s  w {:.1} deg/s",
            view.status, view.command.v, view.command.w
        ));
    }
}

/// The map's floor paint (in its colour) and its targets (blue diamonds of
/// 250 mm, the score's reach radius is 500 mm), as segments for the world view.
fn marks(w: &World) -> Vec<([f32; 4], Color32)> {
    let mut out = Vec::new();
    for p in &w.paint {
        let [r, g, b] = p.color;
        for (a, e) in p.segments() {
            let seg = [a[0] as f32, a[1] as f32, e[0] as f32, e[1] as f32];
            out.push((seg, Color32::from_rgb(r, g, b)));
        }
    }
    let k = 250.0;
    for t in &w.targets {
        let (x, y) = (t[0] as f32, t[1] as f32);
        let c = [[x + k, y], [x, y + k], [x - k, y], [x, y - k]];
        for i in 0..4 {
            let (a, e) = (c[i], c[(i + 1) % 4]);
            out.push(([a[0], a[1], e[0], e[1]], Color32::from_rgb(30, 60, 220)));
        }
    }
    out
}

impl Panel for IntrorobPanel {
    fn title(&self) -> Option<String> {
        Some("introrob".into())
    }

    fn ui(&mut self, ui: &mut egui::Ui, rt: &Runtime) {
        self.controls(ui);
        let pose = self.encoders.read().value;
        let laser = self.laser.snapshot();
        if !self.placed && self.walls.is_empty() {
            self.world.center = [pose.x, pose.y];
        }
        self.placed = true;
        // The target shows as the view's cross (set by conf, shell or click).
        self.world.target = *self.dashboard.target.lock();
        let view = self.dashboard.view.lock().clone();
        let mut segs = self.marks.clone();
        let path_c = Color32::from_rgb(230, 140, 0);
        for w in view.path.windows(2) {
            segs.push(([w[0][0], w[0][1], w[1][0], w[1][1]], path_c));
        }
        if let Some(c) = view.carrot {
            let k = 80.0;
            segs.push(([c[0] - k, c[1], c[0] + k, c[1]], path_c));
            segs.push(([c[0], c[1] - k, c[0], c[1] + k], path_c));
        }
        if let Some(f) = view.forces {
            let arrow = |v: [f32; 2]| {
                let a = relative_to_world(&pose, [0.0, 0.0]);
                let b = relative_to_world(&pose, [v[0] * 800.0, v[1] * 800.0]);
                [a[0], a[1], b[0], b[1]]
            };
            segs.push((arrow(f.attractive), Color32::from_rgb(0, 160, 0)));
            segs.push((arrow(f.repulsive), Color32::from_rgb(220, 0, 0)));
            segs.push((arrow(f.resultant), Color32::from_rgb(0, 60, 220)));
        }
        // A robot program's own (the python schema's GUI.showForces and
        // showLocalTarget, `world.drawings`): forces as arrows, the longest
        // 1 m; the local target as a cross.
        if let Some(d) = crate::world::drawings(&rt.names).map(|d| **d.load()) {
            program_drawings(&d, &pose, &mut segs);
        }
        for d in &view.drawings {
            let [r, g, b] = d.color;
            segs.push(([d.a[0], d.a[1], d.b[0], d.b[1]], Color32::from_rgb(r, g, b)));
        }
        let balls: Vec<_> = self
            .balls
            .as_ref()
            .map(|b| b.load_full())
            .unwrap_or_default()
            .iter()
            .map(|b| {
                let [r, g, bl] = b.color;
                let centre = [b.pos[0] as f32, b.pos[1] as f32];
                (centre, b.radius as f32, Color32::from_rgb(r, g, bl))
            })
            .collect();
        ui.horizontal_top(|ui| {
            ui.vertical(|ui| {
                let scene = WorldScene {
                    robot: Some(pose),
                    walls: &self.walls,
                    laser: Some(&laser.value),
                    segments: &segs,
                    robot_radius: Some(250.0),
                    balls: &balls,
                };
                let r = self.world.show(ui, vec2(440.0, 330.0), &scene);
                if let Some(t) = r.clicked {
                    self.dashboard.set_target(Some(t));
                }
                if let Some(s) = &self.score {
                    ui.label(s.load().summary());
                }
                ui.small("click: target · drag: pan · wheel: zoom · right click: the robot");
            });
            ui.vertical(|ui| {
                ui.label("teleoperation");
                let r = self.joystick.show(ui, 140.0);
                if r.changed() {
                    self.dashboard.set_teleop(self.joystick.v, self.joystick.w);
                    if self.joystick.v != 0.0 || self.joystick.w != 0.0 {
                        self.dashboard.set_behaviour(Behaviour::Teleop);
                    }
                }
                ui.label("laser");
                polar_view(
                    ui,
                    "introrob laser",
                    vec2(140.0, 140.0),
                    &laser_points(&laser.value),
                    8000.0,
                    PolarStyle::Laser,
                );
            });
            ui.vertical(|ui| {
                if let Some(c) = &self.camera {
                    let s = c.snapshot();
                    ui.label("camera");
                    ui.allocate_ui(vec2(240.0, 180.0), |ui| {
                        if s.clock > 0 {
                            self.image.show_sample(ui, &s);
                        } else {
                            ui.small("(no image yet)");
                        }
                    });
                }
                if let Some(s) = &self.sonars {
                    ui.label("sonars");
                    let s = s.snapshot();
                    polar_view(
                        ui,
                        "introrob sonars",
                        vec2(140.0, 140.0),
                        &sonar_points(&s.value),
                        5000.0,
                        PolarStyle::Sonar,
                    );
                }
            });
        });
    }
}

/// A robot program's drawings (`world.drawings`) as world segments at the
/// robot's pose: the car, obstacle and average forces (green, red, blue; the
/// longest 1 m long) and the local target (m) as a purple cross.
fn program_drawings(
    d: &crate::world::Drawings,
    pose: &Encoders,
    segs: &mut Vec<([f32; 4], Color32)>,
) {
    if let Some(forces) = d.forces {
        let longest = forces.iter().map(|f| f[0].hypot(f[1])).fold(1e-9, f64::max);
        let o = relative_to_world(pose, [0.0, 0.0]);
        for (f, c) in forces.iter().zip([
            Color32::from_rgb(0, 160, 0),
            Color32::from_rgb(220, 0, 0),
            Color32::from_rgb(0, 60, 220),
        ]) {
            let k = 1000.0 / longest;
            let tip = relative_to_world(pose, [(f[0] * k) as f32, (f[1] * k) as f32]);
            segs.push(([o[0], o[1], tip[0], tip[1]], c));
        }
    }
    if let Some(t) = d.local_target {
        let c = relative_to_world(pose, [(t[0] * 1000.0) as f32, (t[1] * 1000.0) as f32]);
        let (k, purple) = (120.0, Color32::from_rgb(160, 60, 200));
        segs.push(([c[0] - k, c[1] - k, c[0] + k, c[1] + k], purple));
        segs.push(([c[0] - k, c[1] + k, c[0] + k, c[1] - k], purple));
    }
}
