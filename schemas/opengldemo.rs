//! opengldemo: 4.3's OpenGL demo schema, a 3D scene drawn with real OpenGL (egui's
//! glow backend, depth tested: [`crate::widgets::gl3d`]) from a camera the user
//! places.
//!
//! The scene is the world (walls, boxes, balls) from the name space's `world.map`
//! when a driver exports it (the simulator does), or from a `world` file, with a
//! ground grid and the axes; without a world it is 4.3's demo scene: two cubes with
//! red, green and blue faces spinning about the axis (1, 2, -3) (of 4.3's y-up
//! frame) in front of the axes, over a 61 x 61 m grid, on a light grey background.
//!
//! The camera is 4.3's xcam, ycam, zcam and focus of attention (foax, foay, foaz)
//! sliders, in mm, with a vertical aperture (4.3's `gluPerspective(45, ...)`);
//! dragging in the view orbits the camera about its focus, scrolling moves it
//! closer or further. The rotate toggle orbits the camera about the focus's
//! vertical axis at `rotate_speed` (the schema does it each iteration, so the
//! schema must run) and spins the demo cubes, as 4.3's `rotar` did.
//!
//! Conf (every line optional):
//! ```text
//! schema opengldemo
//! camera 9000 -7000 6000 2000 2000 0  # XCAM YCAM ZCAM FOAX FOAY FOAZ, mm; default:
//!                          #   framing the world (or 4.3's demo view)
//! fovy 45                  # vertical aperture, degrees
//! rotate on                # orbit the camera (4.3's rotate/stop buttons)
//! rotate_speed 20          # deg/s
//! world ../assets/worlds/simple.world  # default: the exported world.map; none: demo scene
//! cycle 33                 # ms: the orbit's step
//! end_schema
//! ```
//! Interfaces: none. Name space, component `opengldemo` (the schema's name): `view`
//! (`parking_lot::Mutex<DemoView>`: the camera and the rotate toggle, shared by the
//! schema, its panel and anyone else).
//! System packages: none beyond the GUI's (OpenGL 3.0 or ES 3.0, e.g. Mesa).

use std::{
    sync::Arc,
    time::{Duration, Instant},
};

use nalgebra::{Matrix4, Unit, Vector3};
use parking_lot::Mutex;

use crate::{
    conf::{
        ComponentConf,
        settings::{self, CYCLE, Setting, float, on_off},
    },
    runtime::{Context, Panel, Runtime, Schema},
    widgets::{
        Gl3dView,
        gl3d::{self, Draw, Frame3D, LookAtCamera, MeshBuilder},
    },
    world::World,
};

/// While rotating, the next frame in this long (the GUI host's ~30 fps pacing).
const REPAINT: Duration = Duration::from_millis(33);

/// A position or focus coordinate's slider range, mm (the `camera` line's).
pub const CAMERA_RANGE: f64 = settings::VIEW_RANGE;

crate::declare_lines! {
    /// opengldemo's lines, declared once (`jderobot help opengldemo`).
    struct Lines {
        camera: Option<(f64, f64, f64, f64, f64, f64)> = settings::look_at("the camera: position and focus of attention (default: framing the scene)"),
        fovy: f64 = Setting::new(
            "fovy",
            "vertical aperture of the camera",
            &[float("DEG", "deg", 5.0, 150.0)],
        )
        .default("45"),
        rotate: bool = Setting::new(
            "rotate",
            "orbit the camera about its focus",
            &[on_off("ROTATE")],
        )
        .default("off"),
        rotate_speed: f64 = Setting::new(
            "rotate_speed",
            "orbit speed",
            &[float("SPEED", "deg/s", -360.0, 360.0)],
        )
        .default("20"),
        world: Option<String> = settings::WORLD,
        cycle: u64 = CYCLE.default("33"),
    }
}
/// What the view shows from: shared by the schema (which orbits it), the panel
/// (sliders, drag, zoom) and the name space (`opengldemo.view`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DemoView {
    pub camera: LookAtCamera,
    pub rotate: bool,
    /// Orbit speed, deg/s.
    pub rotate_speed: f64,
    /// The demo cubes' spin, degrees (advances while rotating).
    pub spin_deg: f64,
    /// Increases at each change (the panel repaints when it moves).
    pub generation: u64,
}

/// The schema: orbits the camera while `rotate` is on.
pub struct OpenGlDemo {
    view: Arc<Mutex<DemoView>>,
    cycle: Duration,
    last: Option<Instant>,
    panel: Option<Box<dyn Panel>>,
}

impl Schema for OpenGlDemo {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn on_run(&mut self, _ctx: &Context) -> anyhow::Result<()> {
        self.last = None;
        Ok(())
    }
    fn iteration(&mut self, _ctx: &Context) -> anyhow::Result<()> {
        let now = Instant::now();
        let dt = self
            .last
            .map(|t| now.duration_since(t).as_secs_f64())
            .unwrap_or(0.0)
            .min(1.0);
        self.last = Some(now);
        let mut v = self.view.lock();
        if v.rotate && dt > 0.0 {
            v.camera = v.camera.orbited(v.rotate_speed * dt);
            v.spin_deg = (v.spin_deg + 30.0 * dt).rem_euclid(360.0 * 6.0);
            v.generation += 1;
        }
        Ok(())
    }
    fn panel(&mut self) -> Option<Box<dyn Panel>> {
        self.panel.take()
    }
}

/// A camera that frames `world` from the south-west, above.
pub fn framing(world: &World, fovy_deg: f64) -> LookAtCamera {
    let (lo, hi) = world
        .bounds()
        .unwrap_or(([-5000.0, -5000.0], [5000.0, 5000.0]));
    let c = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, 0.0];
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(2000.0);
    let d = span * 1.1 / (fovy_deg.to_radians() / 2.0).tan().max(0.1) * 0.5;
    let cam = LookAtCamera {
        position: [0.0; 3],
        foa: c,
        fovy_deg,
    };
    cam.with_spherical(d, (-120f64).to_radians(), 40f64.to_radians())
}

/// 4.3's demo view: behind the origin, looking at the cubes.
pub fn demo_camera(fovy_deg: f64) -> LookAtCamera {
    LookAtCamera {
        position: [9000.0, -9000.0, 7000.0],
        foa: [0.0, 10000.0, 1000.0],
        fovy_deg,
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let lines: Lines = conf.read()?;
    let world = settings::world(conf, lines.world.as_deref(), &rt.names)?;
    let camera = match lines.camera {
        Some((x, y, z, fx, fy, fz)) => {
            if (x, y, z) == (fx, fy, fz) {
                let l = conf.line("camera").expect("a camera line");
                anyhow::bail!(l.error(
                    "camera: the position equals the focus of attention, so the camera \
                     looks nowhere; move one of them"
                ));
            }
            LookAtCamera {
                position: [x, y, z],
                foa: [fx, fy, fz],
                fovy_deg: lines.fovy,
            }
        }
        None => match &world {
            Some(w) => framing(w, lines.fovy),
            None => demo_camera(lines.fovy),
        },
    };
    let view = DemoView {
        camera,
        rotate: lines.rotate,
        rotate_speed: lines.rotate_speed,
        spin_deg: 0.0,
        generation: 0,
    };
    let view = rt.names.export(&conf.name, "view", Mutex::new(view))?;
    let home = camera;
    let panel = DemoPanel {
        view: view.clone(),
        gl: Gl3dView::new(),
        scene: Scene::new(world.as_deref()),
        home,
        drawn: None,
    };
    Ok(Box::new(OpenGlDemo {
        view,
        cycle: Duration::from_millis(lines.cycle),
        last: None,
        panel: Some(Box::new(panel)),
    }))
}

crate::register_schema!(
    "opengldemo",
    "4.3's OpenGL demo: the world (or spinning cubes) in 3D from a camera you place; rotate orbits",
    create,
    lines = Lines
);

/// The static meshes of the scene, built once.
struct Scene {
    /// World walls, floor, boxes and balls; grid and axes.
    statics: Vec<Draw>,
    /// The demo cube (drawn twice, spinning) when there is no world.
    cube: Option<Vec<Draw>>,
    background: [f32; 3],
    walls: usize,
}

impl Scene {
    fn new(world: Option<&World>) -> Scene {
        match world {
            Some(w) => {
                let mut statics = gl3d::world_draws(w);
                let (lo, hi) = w.bounds().unwrap_or(([-5000.0; 2], [5000.0; 2]));
                let half = [lo[0].abs(), lo[1].abs(), hi[0].abs(), hi[1].abs()]
                    .into_iter()
                    .fold(5000.0f64, f64::max)
                    + 1000.0;
                statics.extend(gl3d::grid_and_axes(
                    1000.0,
                    (half / 1000.0).ceil() as f32 * 1000.0,
                    1000.0,
                    [0.45, 0.45, 0.42],
                ));
                Scene {
                    statics,
                    cube: None,
                    background: gl3d::rgb(w.sky_color),
                    walls: w.segments.len(),
                }
            }
            None => {
                // 4.3: a 61-line grid 1 unit apart (1 m here), axes 10 units long.
                let statics = gl3d::grid_and_axes(1000.0, 30_000.0, 10_000.0, [0.4; 3]);
                Scene {
                    statics,
                    cube: Some(demo_cube()),
                    background: [0.9, 0.9, 0.9],
                    walls: 0,
                }
            }
        }
    }

    fn draws(&self, spin_deg: f64) -> Vec<Draw> {
        let mut d = self.statics.clone();
        if let Some(cube) = &self.cube {
            // 4.3's cubes at (0, 0, -10) and (0, 4, -20) in its y-up frame, spinning
            // 1x and 2x about (1, 2, -3): here x, -z, y in metres.
            let axis = Unit::new_normalize(Vector3::new(1.0f32, 3.0, 2.0));
            for (pos, k) in [
                ([0.0f32, 10_000.0, 0.0], 1.0),
                ([0.0, 20_000.0, 4000.0], 2.0),
            ] {
                let m = Matrix4::new_translation(&Vector3::from(pos))
                    * Matrix4::from_axis_angle(&axis, (spin_deg * k).to_radians() as f32);
                d.extend(cube.iter().map(|c| Draw {
                    mesh: c.mesh.clone(),
                    model: m,
                }));
            }
        }
        d
    }
}

/// 4.3's cube: 2 units (2 m) a side, faces red, dark red, green, dark green, blue,
/// dark blue.
fn demo_cube() -> Vec<Draw> {
    let mut b = MeshBuilder::default();
    let h = 1000.0f32;
    let p = |x: f32, y: f32, z: f32| [x * h, y * h, z * h];
    let faces = [
        (
            [
                p(1., 1., 1.),
                p(1., -1., 1.),
                p(1., -1., -1.),
                p(1., 1., -1.),
            ],
            [1.0, 0.0, 0.0],
        ),
        (
            [
                p(-1., 1., 1.),
                p(-1., 1., -1.),
                p(-1., -1., -1.),
                p(-1., -1., 1.),
            ],
            [0.5, 0.0, 0.0],
        ),
        (
            [
                p(1., 1., 1.),
                p(1., 1., -1.),
                p(-1., 1., -1.),
                p(-1., 1., 1.),
            ],
            [0.0, 1.0, 0.0],
        ),
        (
            [
                p(1., -1., 1.),
                p(-1., -1., 1.),
                p(-1., -1., -1.),
                p(1., -1., -1.),
            ],
            [0.0, 0.5, 0.0],
        ),
        (
            [
                p(1., 1., 1.),
                p(-1., 1., 1.),
                p(-1., -1., 1.),
                p(1., -1., 1.),
            ],
            [0.0, 0.0, 1.0],
        ),
        (
            [
                p(1., 1., -1.),
                p(1., -1., -1.),
                p(-1., -1., -1.),
                p(-1., 1., -1.),
            ],
            [0.0, 0.0, 0.5],
        ),
    ];
    for (q, c) in faces {
        b.quad(q[0], q[1], q[2], q[3], c);
    }
    b.draws(Matrix4::identity())
}

/// The panel: the OpenGL view and the camera's sliders.
struct DemoPanel {
    view: Arc<Mutex<DemoView>>,
    gl: Gl3dView,
    scene: Scene,
    home: LookAtCamera,
    /// The view's generation drawn last.
    drawn: Option<u64>,
}

impl Panel for DemoPanel {
    fn ui(&mut self, ui: &mut egui::Ui, _rt: &Runtime) {
        let mut v = *self.view.lock();
        let before = v;
        let (rect, response) =
            ui.allocate_exact_size(gl3d::canvas_size(ui), egui::Sense::click_and_drag());
        crate::widgets::label_response(&response, "opengldemo view");
        v.camera.interact(ui, &response);
        let (cols, rows) = gl3d::pixels(ui, rect);
        let frame = Frame3D {
            camera: v.camera.progeo(cols, rows),
            near: 50.0,
            far: 2.0e5,
            clear: self.scene.background,
            draws: self.scene.draws(v.spin_deg),
        };
        self.gl.paint(ui, rect, frame);
        if let Some(e) = self.gl.stats().error {
            ui.colored_label(egui::Color32::RED, e);
        }
        ui.horizontal(|ui| {
            ui.checkbox(&mut v.rotate, "rotate");
            let l = ui.label("speed");
            ui.add(
                egui::DragValue::new(&mut v.rotate_speed)
                    .range(-360.0..=360.0)
                    .suffix(" deg/s"),
            )
            .labelled_by(l.id);
            if ui.button("home").clicked() {
                v.camera = self.home;
            }
            ui.label(if self.scene.cube.is_some() {
                "4.3's demo scene".to_string()
            } else {
                format!("world: {} wall faces", self.scene.walls)
            });
        });
        let r = CAMERA_RANGE;
        egui::Grid::new("opengldemo_camera").show(ui, |ui| {
            for (k, name) in ["xcam", "ycam", "zcam"].into_iter().enumerate() {
                let l = ui.label(name);
                ui.add(egui::Slider::new(&mut v.camera.position[k], -r..=r).suffix(" mm"))
                    .labelled_by(l.id);
                let l = ui.label(["foax", "foay", "foaz"][k]);
                ui.add(egui::Slider::new(&mut v.camera.foa[k], -r..=r).suffix(" mm"))
                    .labelled_by(l.id);
                ui.end_row();
            }
            let l = ui.label("fovy");
            ui.add(egui::Slider::new(&mut v.camera.fovy_deg, 5.0..=150.0).suffix(" deg"))
                .labelled_by(l.id);
            ui.end_row();
        });
        if v != before {
            let mut shared = self.view.lock();
            // Keep the schema's concurrent orbit step unless the user moved the camera.
            shared.rotate = v.rotate;
            shared.rotate_speed = v.rotate_speed;
            if v.camera != before.camera {
                shared.camera = v.camera;
            }
            shared.generation += 1;
        }
        let generation = self.view.lock().generation;
        // Repaint while the camera orbits, or once after a change; nothing when idle.
        if v.rotate || self.drawn != Some(generation) {
            ui.ctx().request_repaint_after(REPAINT);
        }
        self.drawn = Some(generation);
    }
}
