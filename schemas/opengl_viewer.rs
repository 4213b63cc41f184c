//! opengl_viewer: the robot as a 3D model (an OBJ file) in its world, drawn with
//! real OpenGL (egui's glow backend, depth tested: [`crate::widgets::gl3d`]), at
//! its encoders pose, with its laser readings as a fan of lines, its sonars as
//! cones and the pan-tilt camera's frustum.
//!
//! - The model: a small Pioneer 3-DX built into the binary
//!   (`assets/models/pioneer.obj` and `pioneer.mtl`, GPL-3.0-or-later like the
//!   project), or any OBJ file a `model` line names (with its MTL materials; a face
//!   without one is grey). It is loaded with the `tobj` crate; a bad file is an
//!   error naming the file and the line (counted in the same pass). Model and
//!   material files go through the one checked open (`crate::files`): regular
//!   files only (not `/dev/zero`, not a FIFO), a model at most 64 MiB, a material
//!   library 16 MiB and 64 MiB of them in all.
//!   Units: the model's, times `model_scale`, in mm, x ahead, y left, z up, the
//!   origin where the encoders pose is.
//! - The frustum: the pan-tilt camera is an OpenGL camera (`robot_camera`: where it
//!   sits on the robot and its horizontal aperture, as the simulator's
//!   `camera_height`/`camera_fov`) pointed by `pantiltencoders`; the manual's
//!   OpenGL → progeo mapping ([`GlCamera::to_progeo`]) gives the progeo camera, and
//!   the frustum's edges are its image corners back-projected
//!   ([`PinholeCamera::backproject`](crate::progeo::PinholeCamera::backproject)).
//! - The world: `world.map` from the name space when a driver exports it (the
//!   simulator does), or a `world` file; a ground grid and the axes.
//! - The view: a camera that follows the robot (`follow on`) or stays put; drag
//!   orbits, scroll zooms.
//!
//! Conf (every line optional):
//! ```text
//! schema opengl_viewer
//! model ../assets/models/pioneer.obj  # an OBJ file (default: the built-in Pioneer)
//! model_scale 1            # model units to mm
//! camera -3000 -3000 3000 0 0 200   # XCAM YCAM ZCAM FOAX FOAY FOAZ, mm (default:
//!                          #   behind the robot, or framing the world when not following)
//! follow on                # keep the view's focus on the robot
//! fovy 45                  # the view's vertical aperture, degrees
//! robot_camera 190 0 500 65  # X Y HEIGHT mm, horizontal FOV deg: the pan-tilt camera
//! frustum 1500             # length of the frustum's edges, mm
//! world ../assets/worlds/simple.world  # default: the exported world.map; none: no world
//! encoders encoders        # interface names (defaults shown); none: not drawn
//! laser laser
//! sonars sonars
//! pantiltencoders pantiltencoders
//! cycle 100                # ms
//! end_schema
//! ```
//! Interfaces used (read, and run as children while the schema runs so their
//! drivers publish): encoders (x, y mm, theta rad), laser (mm, 1 reading per
//! 1/resolution degree from -90°), sonars (mm, the Pioneer ring), pantiltencoders
//! (deg); each is skipped when nothing provides it.
//! System packages: none beyond the GUI's (OpenGL 3.0 or ES 3.0, e.g. Mesa).

use std::{
    path::{Path, PathBuf},
    sync::Arc,
    time::Duration,
};

use nalgebra::{Matrix4, Vector3};

use crate::{
    conf::{
        ComponentConf,
        settings::{self, CYCLE, Setting, float, on_off, path},
    },
    files,
    interfaces::{Encoders, Interface, InterfaceValue, Laser, PtEncoders, Sonars, heading},
    progeo::{GlCamera, HPoint2D, PinholeCamera},
    runtime::{Context, Panel, Runtime, Schema},
    widgets::{
        Gl3dView,
        gl3d::{self, Draw, Frame3D, LookAtCamera, MeshBuilder},
        sonar_angles,
    },
};

crate::declare_lines! {
    /// opengl_viewer's lines, declared once (`jderobot help opengl_viewer`).
    struct Lines {
        model: Option<String> = Setting::new(
            "model",
            "the robot's OBJ model (default: the built-in Pioneer)",
            &[path("FILE")],
        ),
        model_scale: f64 = Setting::new(
            "model_scale",
            "model units to mm",
            &[float("SCALE", "", 1e-4, 1e4)],
        )
        .default("1"),
        camera: Option<(f64, f64, f64, f64, f64, f64)> = settings::look_at("the view: position and focus of attention (default: behind the robot)"),
        follow: bool = Setting::new(
            "follow",
            "keep the view's focus on the robot",
            &[on_off("FOLLOW")],
        )
        .default("on"),
        fovy: f64 = Setting::new(
            "fovy",
            "the view's vertical aperture",
            &[float("DEG", "deg", 5.0, 150.0)],
        )
        .default("45"),
        robot_camera: (f64, f64, f64, f64) = Setting::new(
            "robot_camera",
            "the pan-tilt camera on the robot: position, height and horizontal aperture",
            &[
                float("X", "mm", -5000.0, 5000.0),
                float("Y", "mm", -5000.0, 5000.0),
                float("HEIGHT", "mm", 0.0, 10000.0),
                float("FOV", "deg", 1.0, 170.0),
            ],
        )
        .default("190 0 500 65"),
        frustum: f64 = Setting::new(
            "frustum",
            "length of the camera frustum's edges",
            &[float("LENGTH", "mm", 0.0, 100_000.0)],
        )
        .default("1500"),
        world: Option<String> = settings::WORLD,
        encoders: String = settings::uses("encoders", "the robot's pose (none: at the origin)"),
        laser: String = settings::uses("laser", "the laser fan (none: none)"),
        sonars: String = settings::uses("sonars", "the sonar cones (none: none)"),
        pantiltencoders: String = settings::uses(
            "pantiltencoders",
            "where the camera points (none: straight ahead)",
        ),
        cycle: u64 = CYCLE.default("100"),
    }
}
/// The built-in Pioneer model.
const PIONEER_OBJ: &str = include_str!("../assets/models/pioneer.obj");
const PIONEER_MTL: &str = include_str!("../assets/models/pioneer.mtl");

/// A bad OBJ or MTL file: where and what.
#[derive(Debug, thiserror::Error)]
#[error("{}:{line}: {message}", file.display())]
pub struct ModelError {
    pub file: PathBuf,
    /// 1-based line (0: the file as a whole, e.g. it cannot be read).
    pub line: usize,
    pub message: String,
}

fn load_options() -> tobj::LoadOptions {
    tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    }
}

/// A reader over text that counts the lines the parser has taken: when tobj's
/// line-by-line parser fails, the line it was on is known in the same pass (the
/// old search re-parsed ever longer prefixes: a 100 MB OBJ bad on its last line
/// took over 300 s).
struct Counting<'a> {
    text: &'a [u8],
    at: usize,
    newlines: usize,
}

impl<'a> Counting<'a> {
    fn new(text: &'a str) -> Self {
        Counting {
            text: text.as_bytes(),
            at: 0,
            newlines: 0,
        }
    }
    /// The 1-based line the parser was on: the last line it took (an error at
    /// the end of the file, such as a face index beyond the vertices, is
    /// reported on the last line).
    fn line(&self) -> usize {
        let cut_last = self.at == self.text.len() && !self.text.ends_with(b"\n");
        (self.newlines + usize::from(cut_last)).max(1)
    }
}

impl std::io::Read for Counting<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = buf.len().min(self.text.len() - self.at);
        buf[..n].copy_from_slice(&self.text[self.at..self.at + n]);
        std::io::BufRead::consume(self, n);
        Ok(n)
    }
}

impl std::io::BufRead for Counting<'_> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        Ok(&self.text[self.at..])
    }
    fn consume(&mut self, amt: usize) {
        let end = (self.at + amt).min(self.text.len());
        self.newlines += self.text[self.at..end]
            .iter()
            .filter(|b| **b == b'\n')
            .count();
        self.at = end;
    }
}

type MtlResult = tobj::MTLLoadResult;

/// A colour line (`Ka`, `Kd`, `Ks`, `Ke`) with fewer than three numbers: its
/// 1-based line and what is wrong. tobj 4.0.5 panics on one (its `parse_float3`
/// unwraps), so the loader refuses it first (found by `tests/fuzz.rs`).
fn short_colour_line(text: &str) -> Option<(usize, String)> {
    text.lines().enumerate().find_map(|(i, l)| {
        let mut words = l.split_whitespace();
        let key = words.next()?;
        (matches!(key, "Ka" | "Kd" | "Ks" | "Ke") && words.count() < 3)
            .then(|| (i + 1, format!("`{key}` wants three numbers (R G B)")))
    })
}

/// Parses MTL text; on an error, the line it was found on.
fn parse_mtl(text: &str) -> (MtlResult, usize) {
    let mut r = Counting::new(text);
    let result = tobj::load_mtl_buf(&mut r);
    (result, r.line())
}

/// The most bytes of material libraries one model may read in all (each file
/// is at most `files::MAX_TEXT_BYTES`; an OBJ of many `mtllib` lines must not
/// read one library thousands of times).
pub const MAX_MTL_TOTAL_BYTES: u64 = 64 << 20;

/// Loads an OBJ model given as text (`file` names it, and its directory is where
/// `mtllib` files are read from, unless `mtl` supplies the one material text).
pub fn load_model_text(
    text: &str,
    file: &Path,
    mtl: Option<&str>,
    scale: f32,
) -> Result<Vec<Draw>, ModelError> {
    let dir = file.parent().map(Path::to_path_buf).unwrap_or_default();
    let mtl_bytes = std::cell::Cell::new(0u64);
    let read_mtl = |p: &Path| -> Result<(String, PathBuf), ModelError> {
        let f = dir.join(p);
        match mtl {
            Some(t) => Ok((t.to_string(), f)),
            None => {
                // The one checked open: a regular file (not /dev/zero, not a
                // FIFO that would hang `check`), at most MAX_TEXT_BYTES.
                let t = files::FileError::read(&f).map_err(|e| ModelError {
                    file: f.clone(),
                    line: 0,
                    message: format!("cannot read the material library: {}", e.reason()),
                })?;
                mtl_bytes.set(mtl_bytes.get() + t.len() as u64);
                if mtl_bytes.get() > MAX_MTL_TOTAL_BYTES {
                    return Err(ModelError {
                        file: file.to_path_buf(),
                        line: 0,
                        message: format!(
                            "its material libraries add up to more than {MAX_MTL_TOTAL_BYTES} bytes"
                        ),
                    });
                }
                Ok((t, f))
            }
        }
    };
    let mtl_error = std::cell::RefCell::new(None::<ModelError>);
    let loader = |p: &Path| -> MtlResult {
        if mtl_error.borrow().is_some() {
            return Err(tobj::LoadError::OpenFileFailed);
        }
        match read_mtl(p) {
            Ok((t, f)) => {
                if let Some((line, what)) = short_colour_line(&t) {
                    *mtl_error.borrow_mut() = Some(ModelError {
                        file: f,
                        line,
                        message: format!("bad material library: {what}"),
                    });
                    return Err(tobj::LoadError::MaterialParseError);
                }
                let (r, line) = parse_mtl(&t);
                if let Err(e) = &r {
                    *mtl_error.borrow_mut() = Some(ModelError {
                        file: f,
                        line,
                        message: format!("bad material library: {e}"),
                    });
                }
                r
            }
            Err(e) => {
                *mtl_error.borrow_mut() = Some(e);
                Err(tobj::LoadError::OpenFileFailed)
            }
        }
    };
    let mut reader = Counting::new(text);
    let (models, materials) = match tobj::load_obj_buf(&mut reader, &load_options(), loader) {
        Ok(r) => r,
        Err(e) => {
            return Err(ModelError {
                file: file.to_path_buf(),
                line: reader.line(),
                message: format!("bad OBJ: {e}"),
            });
        }
    };
    if let Some(e) = mtl_error.into_inner() {
        return Err(e);
    }
    let materials = materials.unwrap_or_default();
    if models.iter().all(|m| m.mesh.indices.is_empty()) {
        return Err(ModelError {
            file: file.to_path_buf(),
            line: 0,
            message: "no faces: the model draws nothing".into(),
        });
    }
    let mut b = MeshBuilder::default();
    for m in &models {
        let mesh = &m.mesh;
        let color = mesh
            .material_id
            .and_then(|i| materials.get(i))
            .and_then(|mat| mat.diffuse)
            .unwrap_or([0.6, 0.6, 0.6]);
        let p = |i: u32| -> Option<[f32; 3]> {
            let i = i as usize * 3;
            let v = mesh.positions.get(i..i + 3)?;
            Some([v[0] * scale, v[1] * scale, v[2] * scale])
        };
        for t in mesh.indices.chunks_exact(3) {
            let (Some(a), Some(c), Some(d)) = (p(t[0]), p(t[1]), p(t[2])) else {
                continue;
            };
            let n =
                (Vector3::from(c) - Vector3::from(a)).cross(&(Vector3::from(d) - Vector3::from(a)));
            b.triangle(a, c, d, gl3d::shade(color, n));
        }
    }
    Ok(b.draws(Matrix4::identity()))
}

/// Loads an OBJ model file (and the MTL files it names), through the one
/// checked open: a regular file of at most [`files::MAX_MODEL_BYTES`].
pub fn load_model(file: &Path, scale: f32) -> Result<Vec<Draw>, ModelError> {
    let bytes = files::read_limited(file, files::MAX_MODEL_BYTES).map_err(|e| ModelError {
        file: file.to_path_buf(),
        line: 0,
        message: format!("cannot read the model: {}", e.reason()),
    })?;
    let text = String::from_utf8(bytes).map_err(|e| ModelError {
        file: file.to_path_buf(),
        line: 0,
        message: format!("cannot read the model: not UTF-8 text ({})", e.utf8_error()),
    })?;
    load_model_text(&text, file, None, scale)
}

/// The built-in Pioneer.
pub fn pioneer_model() -> Vec<Draw> {
    load_model_text(
        PIONEER_OBJ,
        Path::new("assets/models/pioneer.obj"),
        Some(PIONEER_MTL),
        1.0,
    )
    .expect("the built-in Pioneer model loads")
}

/// The interfaces the viewer reads (each optional).
#[derive(Clone, Default)]
struct Devices {
    encoders: Option<Arc<Interface<Encoders>>>,
    laser: Option<Arc<Interface<Laser>>>,
    sonars: Option<Arc<Interface<Sonars>>>,
    pantilt: Option<Arc<Interface<PtEncoders>>>,
}

/// The schema: keeps its interfaces running while it runs; the panel draws.
pub struct OpenGlViewer {
    names: Vec<String>,
    cycle: Duration,
    panel: Option<Box<dyn Panel>>,
}

impl Schema for OpenGlViewer {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        ctx.run_children(&self.names, None)?;
        Ok(())
    }
    fn iteration(&mut self, _ctx: &Context) -> anyhow::Result<()> {
        Ok(())
    }
    fn panel(&mut self) -> Option<Box<dyn Panel>> {
        self.panel.take()
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let lines: Lines = conf.read()?;
    let world = settings::world(conf, lines.world.as_deref(), &rt.names)?;
    let model = match &lines.model {
        None => pioneer_model(),
        Some(_) => {
            let l = conf.line("model").expect("a model line");
            let file = l.existing_file(0, "the OBJ model")?;
            load_model(&file, lines.model_scale as f32)
                .map_err(|e| l.error(format!("model: {e}")))?
        }
    };
    let name = |n: &str| (n != "none" && rt.interfaces.contains(n)).then(|| n.to_string());
    let names: Vec<String> = [
        &lines.encoders,
        &lines.laser,
        &lines.sonars,
        &lines.pantiltencoders,
    ]
    .into_iter()
    .filter_map(|n| name(n))
    .collect();
    let ifs = &rt.interfaces;
    let dev = Devices {
        encoders: name(&lines.encoders).map(|n| ifs.get(&n)).transpose()?,
        laser: name(&lines.laser).map(|n| ifs.get(&n)).transpose()?,
        sonars: name(&lines.sonars).map(|n| ifs.get(&n)).transpose()?,
        pantilt: name(&lines.pantiltencoders)
            .map(|n| ifs.get(&n))
            .transpose()?,
    };
    let follow = lines.follow;
    let view = match lines.camera {
        Some((x, y, z, fx, fy, fz)) => {
            if (x, y, z) == (fx, fy, fz) {
                let l = conf.line("camera").expect("a camera line");
                anyhow::bail!(
                    l.error("camera: the position equals the focus of attention; move one of them")
                );
            }
            LookAtCamera {
                position: [x, y, z],
                foa: [fx, fy, fz],
                fovy_deg: lines.fovy,
            }
        }
        None => LookAtCamera {
            position: [0.0; 3],
            foa: [0.0, 0.0, 200.0],
            fovy_deg: lines.fovy,
        }
        .with_spherical(4500.0, (-135f64).to_radians(), 35f64.to_radians()),
    };
    let (cx, cy, ch, cfov) = lines.robot_camera;
    let statics = match &world {
        Some(w) => {
            let mut s = gl3d::world_draws(w);
            let (lo, hi) = w.bounds().unwrap_or(([-5000.0; 2], [5000.0; 2]));
            let half = [lo[0].abs(), lo[1].abs(), hi[0].abs(), hi[1].abs()]
                .into_iter()
                .fold(5000.0f64, f64::max)
                + 1000.0;
            s.extend(gl3d::grid_and_axes(
                1000.0,
                (half / 1000.0).ceil() as f32 * 1000.0,
                1000.0,
                [0.45, 0.45, 0.42],
            ));
            s
        }
        None => gl3d::grid_and_axes(1000.0, 10_000.0, 1000.0, [0.6, 0.6, 0.6]),
    };
    let background = world
        .as_ref()
        .map(|w| gl3d::rgb(w.sky_color))
        .unwrap_or([0.95, 0.95, 0.95]);
    let panel = ViewerPanel {
        dev,
        gl: Gl3dView::new(),
        model,
        statics,
        background,
        view,
        follow,
        robot_camera: RobotCamera {
            x: cx,
            y: cy,
            height: ch,
            fov_deg: cfov,
            frustum: lines.frustum,
        },
        dynamic: None,
        last_pose: None,
    };
    Ok(Box::new(OpenGlViewer {
        names,
        cycle: Duration::from_millis(lines.cycle),
        panel: Some(Box::new(panel)),
    }))
}

crate::register_schema!(
    "opengl_viewer",
    "the robot as a 3D model (OBJ) in its world, with laser fan, sonar cones and camera frustum",
    create,
    lines = Lines
);

/// The pan-tilt camera on the robot.
#[derive(Clone, Copy, Debug, Default)]
pub struct RobotCamera {
    /// Position on the robot (x ahead, y left) and height, mm.
    pub x: f64,
    pub y: f64,
    pub height: f64,
    /// Horizontal aperture, degrees.
    pub fov_deg: f64,
    /// Frustum edge length, mm.
    pub frustum: f64,
}

impl RobotCamera {
    /// The progeo camera (320x240) of the pan-tilt camera of a robot at `pose`,
    /// panned and tilted by `pt` (degrees): an OpenGL camera with this horizontal
    /// aperture, through the manual's mapping.
    pub fn progeo(&self, pose: &Encoders, pt: Option<PtEncoders>) -> PinholeCamera {
        let (pan, tilt) = pt
            .map(|p| (p.pan_angle as f64, p.tilt_angle as f64))
            .unwrap_or((0.0, 0.0));
        let (s, c) = (pose.theta as f64).sin_cos();
        let p = [
            pose.x as f64 + c * self.x - s * self.y,
            pose.y as f64 + s * self.x + c * self.y,
            self.height,
        ];
        let az = pose.theta as f64 + pan.to_radians();
        let el = tilt.to_radians();
        let foa = [
            p[0] + 1000.0 * el.cos() * az.cos(),
            p[1] + 1000.0 * el.cos() * az.sin(),
            p[2] + 1000.0 * el.sin(),
        ];
        GlCamera::from_horizontal_fov(p, foa, self.fov_deg.to_radians(), 320.0 / 240.0)
            .to_progeo(320, 240)
    }

    /// The frustum's segments (world mm): the four corner rays and the far
    /// rectangle.
    pub fn frustum(&self, cam: &PinholeCamera) -> Vec<([f32; 3], [f32; 3])> {
        let o = cam.position;
        let (r, c) = (cam.rows as f64 - 1.0, cam.columns as f64 - 1.0);
        let corners: Vec<[f32; 3]> = [(0.0, 0.0), (0.0, c), (r, c), (r, 0.0)]
            .into_iter()
            .filter_map(|(x, y)| cam.ray(HPoint2D::new(x, y, 1.0)))
            .map(|d| {
                [
                    (o.x + d.x * self.frustum) as f32,
                    (o.y + d.y * self.frustum) as f32,
                    (o.z + d.z * self.frustum) as f32,
                ]
            })
            .collect();
        let o = [o.x as f32, o.y as f32, o.z as f32];
        let mut s = Vec::new();
        for (k, p) in corners.iter().enumerate() {
            s.push((o, *p));
            s.push((*p, corners[(k + 1) % corners.len()]));
        }
        s
    }
}

/// Colours of the sensors.
const LASER: [f32; 3] = [30.0 / 255.0, 90.0 / 255.0, 220.0 / 255.0];
const SONAR: [f32; 3] = [0.95, 0.6, 0.1];
const FRUSTUM: [f32; 3] = [0.1, 0.75, 0.2];
/// Height of the laser's beam plane and of the sonar ring, mm.
const LASER_HEIGHT: f32 = 305.0;
const SONAR_HEIGHT: f32 = 180.0;

/// The panel's cached sensor meshes and what they were built from.
#[derive(Default)]
struct Dynamic {
    clocks: (u64, u64, u64, u64),
    prints: (u64, u64, u64, u64),
    draws: Vec<Draw>,
}

struct ViewerPanel {
    dev: Devices,
    gl: Gl3dView,
    model: Vec<Draw>,
    statics: Vec<Draw>,
    background: [f32; 3],
    view: LookAtCamera,
    follow: bool,
    robot_camera: RobotCamera,
    dynamic: Option<Dynamic>,
    /// Where the robot was last frame (to move a following view with it).
    last_pose: Option<[f64; 2]>,
}

impl ViewerPanel {
    /// Laser fan, sonar cones and frustum for this pose (world mm).
    fn sensors(&self, pose: &Encoders, pt: Option<PtEncoders>) -> Vec<Draw> {
        let mut b = MeshBuilder::default();
        let local = |rx: f32, ry: f32, z: f32| {
            let (s, c) = pose.theta.sin_cos();
            [pose.x + c * rx - s * ry, pose.y + s * rx + c * ry, z]
        };
        if let Some(l) = &self.dev.laser {
            let laser = l.read().value.clone();
            let o = local(laser.mount.x, laser.mount.y, LASER_HEIGHT);
            let mut tri = Vec::new();
            for i in 0..laser.readings.len() {
                let [x, y] = laser.robot_point(i);
                let p = local(x, y, LASER_HEIGHT);
                b.line(o, p, LASER);
                tri.push(p);
            }
            for w in tri.windows(2) {
                b.line(w[0], w[1], LASER);
            }
        }
        if let Some(sn) = &self.dev.sonars {
            let us = sn.read().value.us.clone();
            let angles = sonar_angles(us.len());
            let half = 12.5f32.to_radians();
            for (u, a) in us.iter().zip(angles) {
                let a = a.to_radians();
                let base = [200.0 * a.cos(), 200.0 * a.sin()];
                let o = local(base[0], base[1], SONAR_HEIGHT);
                let r = u.max(0.0);
                let q = |da: f32| {
                    local(
                        base[0] + r * (a + da).cos(),
                        base[1] + r * (a + da).sin(),
                        SONAR_HEIGHT,
                    )
                };
                b.line(o, q(-half), SONAR);
                b.line(o, q(half), SONAR);
                let n = 4;
                for k in 0..n {
                    let t0 = -half + 2.0 * half * k as f32 / n as f32;
                    let t1 = -half + 2.0 * half * (k + 1) as f32 / n as f32;
                    b.line(q(t0), q(t1), SONAR);
                }
            }
        }
        let cam = self.robot_camera.progeo(pose, pt);
        for (a, c) in self.robot_camera.frustum(&cam) {
            b.line(a, c, FRUSTUM);
        }
        b.draws(Matrix4::identity())
    }
}

impl Panel for ViewerPanel {
    fn ui(&mut self, ui: &mut egui::Ui, _rt: &Runtime) {
        let pose = self
            .dev
            .encoders
            .as_ref()
            .map(|e| e.read().value)
            .unwrap_or_default();
        let pt = self.dev.pantilt.as_ref().map(|p| p.read().value);
        // The sensors' meshes are rebuilt only when a value changed (a clock that
        // moved with the same value keeps them, so an unchanged scene is not drawn
        // again: see gl3d's offscreen picture).
        let clock = |c: Option<u64>| c.unwrap_or(0);
        let clocks = (
            clock(self.dev.encoders.as_ref().map(|i| i.clock())),
            clock(self.dev.laser.as_ref().map(|i| i.clock())),
            clock(self.dev.sonars.as_ref().map(|i| i.clock())),
            clock(self.dev.pantilt.as_ref().map(|i| i.clock())),
        );
        if self.dynamic.as_ref().is_none_or(|d| d.clocks != clocks) {
            let print = |v: Option<u64>| v.unwrap_or(0);
            let prints = (
                print(
                    self.dev
                        .encoders
                        .as_ref()
                        .map(|i| i.read().value.fingerprint()),
                ),
                print(
                    self.dev
                        .laser
                        .as_ref()
                        .map(|i| i.read().value.fingerprint()),
                ),
                print(
                    self.dev
                        .sonars
                        .as_ref()
                        .map(|i| i.read().value.fingerprint()),
                ),
                print(pt.map(|p| p.fingerprint())),
            );
            match self.dynamic.as_mut() {
                Some(d) if d.prints == prints => d.clocks = clocks,
                _ => {
                    self.dynamic = Some(Dynamic {
                        clocks,
                        prints,
                        draws: self.sensors(&pose, pt),
                    })
                }
            }
        }
        let here = [pose.x as f64, pose.y as f64];
        if self.follow
            && let Some(last) = self.last_pose
        {
            let d = [here[0] - last[0], here[1] - last[1]];
            for (k, dk) in d.into_iter().enumerate() {
                self.view.position[k] += dk;
                self.view.foa[k] += dk;
            }
        }
        self.last_pose = Some(here);

        let (rect, response) =
            ui.allocate_exact_size(gl3d::canvas_size(ui), egui::Sense::click_and_drag());
        crate::widgets::label_response(&response, "opengl_viewer view");
        self.view.interact(ui, &response);
        let (cols, rows) = gl3d::pixels(ui, rect);
        let model = gl3d::pose_matrix(pose.x, pose.y, pose.theta);
        let mut draws = self.statics.clone();
        draws.extend(self.model.iter().map(|d| Draw {
            mesh: d.mesh.clone(),
            model: model * d.model,
        }));
        if let Some(d) = &self.dynamic {
            draws.extend(d.draws.iter().cloned());
        }
        self.gl.paint(
            ui,
            rect,
            Frame3D {
                camera: self.view.progeo(cols, rows),
                near: 50.0,
                far: 2.0e5,
                clear: self.background,
                draws,
            },
        );
        if let Some(e) = self.gl.stats().error {
            ui.colored_label(egui::Color32::RED, e);
        }
        ui.horizontal(|ui| {
            ui.checkbox(&mut self.follow, "follow the robot");
            ui.label(format!(
                "robot at ({:.0}, {:.0}) mm, {:.0} deg",
                pose.x,
                pose.y,
                heading(pose.theta).to_degrees()
            ));
        });
        ui.horizontal(|ui| {
            let l = ui.label("view fovy");
            ui.add(egui::Slider::new(&mut self.view.fovy_deg, 5.0..=150.0).suffix(" deg"))
                .labelled_by(l.id);
        });
        // The window repaints when an interface changes (the GUI host watches
        // them) and on input: nothing to ask for here.
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_pioneer_loads_with_its_colours() {
        let m = pioneer_model();
        let tris: usize = m.iter().map(|d| d.mesh.vertices.len()).sum::<usize>() / 3;
        assert!(tris > 100, "{tris} triangles");
        // Some vertex is the chassis red (0.8, 0.1, 0.1) shaded by 0.65..1.0.
        assert!(m.iter().flat_map(|d| &d.mesh.vertices).any(|v| {
            v.color[0] > 0.5 && v.color[1] < 0.11 && (v.color[0] / v.color[1] - 8.0).abs() < 0.01
        }));
    }

    #[test]
    fn a_bad_obj_names_the_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("robot.obj");
        std::fs::write(
            &f,
            "# a triangle\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nv 1 x 2\nf 1 2 4\n",
        )
        .unwrap();
        let e = load_model(&f, 1.0).expect_err("an error").to_string();
        assert!(e.contains("robot.obj:6:"), "{e}");
        std::fs::write(&f, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n").unwrap();
        let e = load_model(&f, 1.0).expect_err("an error").to_string();
        assert!(e.contains("robot.obj:4:"), "{e}");
        // A material library that is missing, then bad.
        std::fs::write(
            &f,
            "mtllib robot.mtl\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        )
        .unwrap();
        let e = load_model(&f, 1.0).expect_err("an error").to_string();
        assert!(e.contains("robot.mtl") && e.contains("cannot read"), "{e}");
        std::fs::write(
            dir.path().join("robot.mtl"),
            "newmtl a\nKd 1 0 0\nKd 0.5 zz 1\n",
        )
        .unwrap();
        let e = load_model(&f, 1.0).expect_err("an error").to_string();
        assert!(e.contains("robot.mtl:3:"), "{e}");
        // No faces at all.
        std::fs::write(&f, "v 0 0 0\n").unwrap();
        let e = load_model(&f, 1.0).expect_err("an error").to_string();
        assert!(e.contains("no faces"), "{e}");
        // A file that is not there.
        let e = load_model(&dir.path().join("none.obj"), 1.0)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("none.obj") && e.contains("cannot read"), "{e}");
    }

    #[test]
    fn the_frustum_comes_from_the_progeo_camera() {
        let rc = RobotCamera {
            x: 190.0,
            y: 0.0,
            height: 500.0,
            fov_deg: 65.0,
            frustum: 1000.0,
        };
        let pose = Encoders::from_pose(1000.0, 2000.0, 0.0);
        let cam = rc.progeo(&pose, None);
        // The OpenGL aperture on the width maps to f = 320 / (2 tan 32.5°).
        let f = crate::progeo::focal_from_fov(320.0, 65f64.to_radians());
        assert!((cam.fdisty - f).abs() < 1e-9 && (cam.fdistx - f).abs() < 1e-9);
        let s = rc.frustum(&cam);
        assert_eq!(s.len(), 8);
        // Corner rays start at the camera and end 1 m away, ahead of the robot,
        // spread ±32.5° (less the half pixel) sideways.
        for (a, b) in s.iter().step_by(2) {
            assert_eq!(*a, [1190.0, 2000.0, 500.0]);
            let d = Vector3::from(*b) - Vector3::from(*a);
            assert!((d.norm() - 1000.0).abs() < 1e-2, "{d:?}");
            assert!(d.x > 700.0);
            let side = (d.y / d.x).atan().to_degrees().abs();
            assert!((side - 32.5).abs() < 0.5, "{side}");
        }
    }
}
